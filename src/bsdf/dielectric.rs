//! A smooth dielectric boundary between `outside_ior` (the normals' side) and `ior` (inside):
//! Fresnel reflection with probability R, Snell refraction with 1 − R, so power is divided and
//! none absorbed. Absorption inside is the medium's (`media`), not the boundary's.

use glam::Vec3A;

use super::{reflect, Lobe, Mode, Sample};
use crate::sampling::Sampler;
use crate::spectrum::Lanes;

/// Unpolarised Fresnel reflectance of a smooth boundary, (R_s + R_p)/2 with
/// r_s = (η_i cosθ_i − η_t cosθ_t)/(η_i cosθ_i + η_t cosθ_t), r_p = (η_t cosθ_i − η_i cosθ_t)/(η_t cosθ_i + η_i cosθ_t);
/// 1 beyond the critical angle. Returns (R, cosθ_t).
#[inline]
pub fn fresnel_dielectric(cos_i: f64, eta_i: f64, eta_t: f64) -> (f64, f64) {
    let sin_i2 = (1.0 - cos_i * cos_i).max(0.0);
    let sin_t2 = (eta_i / eta_t).powi(2) * sin_i2;
    if sin_t2 >= 1.0 {
        return (1.0, 0.0);
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let rs = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t);
    let rp = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t);
    (0.5 * (rs * rs + rp * rp), cos_t)
}

/// Snell refraction of travel direction `d` into the side opposite `n_in` (the unit normal on
/// the side `d` comes from): t = η d + (η cosθ_i − cosθ_t) n_in, η = η_i/η_t.
#[inline]
pub fn refract(d: Vec3A, n_in: Vec3A, eta_i: f64, eta_t: f64, cos_i: f64, cos_t: f64) -> Vec3A {
    let eta = (eta_i / eta_t) as f32;
    (eta * d + (eta * cos_i as f32 - cos_t as f32) * n_in).normalize()
}

/// Indices of refraction (incident side, transmitted side) for travel direction `d`: the inside
/// is the side opposite the normal.
#[inline]
pub fn etas(ior: f64, outside: f64, d: Vec3A, n: Vec3A) -> (f64, f64) {
    if d.dot(n) < 0.0 {
        (outside, ior)
    } else {
        (ior, outside)
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Dielectric {
    pub ior: f64,
    pub outside_ior: f64,
}

/// The Fresnel split of a path arriving along travel direction `d`.
struct Split {
    eta_i: f64,
    eta_t: f64,
    cos_i: f64,
    r: f64,
    cos_t: f64,
}

impl Dielectric {
    #[inline]
    fn split(&self, d: Vec3A, n: Vec3A) -> Split {
        let (eta_i, eta_t) = etas(self.ior, self.outside_ior, d, n);
        let cos_i = (d.dot(n).abs() as f64).min(1.0);
        let (r, cos_t) = fresnel_dielectric(cos_i, eta_i, eta_t);
        Split { eta_i, eta_t, cos_i, r, cos_t }
    }

    /// Refraction's factor besides 1 − R: (η_i/η_t)² for radiance, 1 for power.
    #[inline]
    fn refraction_scale(split: &Split, mode: Mode) -> f64 {
        match mode {
            Mode::Radiance => (split.eta_i / split.eta_t).powi(2),
            Mode::Importance => 1.0,
        }
    }

    /// Reflect with probability R, refract with 1 − R: the Fresnel factors cancel in the weight.
    #[inline]
    pub fn sample<const N: usize>(&self, wo: Vec3A, n: Vec3A, mode: Mode, s: &mut Sampler) -> Sample<N> {
        let d = -wo;
        let split = self.split(d, n);
        let r = split.r;
        if s.uniform() < r {
            Sample { wi: reflect(d, n), lobe: Lobe::SpecularReflection, factor: Lanes::splat(r), lobe_pdf: r, pdf: 0.0 }
        } else {
            let n_in = if d.dot(n) < 0.0 { n } else { -n };
            let wi = refract(d, n_in, split.eta_i, split.eta_t, split.cos_i, split.cos_t);
            let factor = Lanes::splat((1.0 - r) * Self::refraction_scale(&split, mode));
            Sample { wi, lobe: Lobe::SpecularTransmission, factor, lobe_pdf: 1.0 - r, pdf: 0.0 }
        }
    }

    #[inline]
    pub fn lobe_factor<const N: usize>(&self, lobe: Lobe, wo: Vec3A, n: Vec3A, mode: Mode) -> Lanes<N> {
        let split = self.split(-wo, n);
        match lobe {
            Lobe::SpecularReflection => Lanes::splat(split.r),
            Lobe::SpecularTransmission => Lanes::splat((1.0 - split.r) * Self::refraction_scale(&split, mode)),
            _ => Lanes::ZERO,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_normal_incidence_and_tir() {
        // R(0) = ((n−1)/(n+1))², 0.04 for n = 1.5.
        let (r, _) = fresnel_dielectric(1.0, 1.0, 1.5);
        assert!((r - 0.04).abs() < 1e-12);
        // Beyond the critical angle asin(1/1.5) = 41.8° from glass to air: total reflection.
        let (r, _) = fresnel_dielectric(45f64.to_radians().cos(), 1.5, 1.0);
        assert_eq!(r, 1.0);
    }

    #[test]
    fn reflection_and_refraction_factors_sum_to_one_for_power() {
        let glass = Dielectric { ior: 1.5, outside_ior: 1.0 };
        let (wo, n) = (Vec3A::new(-0.6, 0.8, 0.0), Vec3A::Y);
        let r: Lanes<1> = glass.lobe_factor(Lobe::SpecularReflection, wo, n, Mode::Importance);
        let t: Lanes<1> = glass.lobe_factor(Lobe::SpecularTransmission, wo, n, Mode::Importance);
        assert!((r.0[0] + t.0[0] - 1.0).abs() < 1e-15);
        // Radiance entering glass is compressed into a smaller solid angle: (1/1.5)² of power's factor.
        let t_rad: Lanes<1> = glass.lobe_factor(Lobe::SpecularTransmission, wo, n, Mode::Radiance);
        assert!((t_rad.0[0] - t.0[0] / 2.25).abs() < 1e-15);
    }
}
