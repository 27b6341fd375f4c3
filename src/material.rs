//! What happens at a hit. A material answers three questions at wavelength λ: its albedo (the
//! probability that a photon is scattered at all), how a scattered photon leaves (a lobe and a
//! direction), and each lobe's throughput factor. The estimators in `transport` combine them:
//! analog survival with probability = albedo, or expected-value weighting by the albedo.

use glam::Vec3A;

use crate::sampling::{cosine_hemisphere, Sampler};
use crate::scene::Material;

/// How a scattered photon left the surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lobe {
    DiffuseReflection,
    DiffuseTransmission,
    /// Mirror reflection, or Fresnel reflection at a dielectric.
    SpecularReflection,
    /// Refraction through a dielectric.
    SpecularTransmission,
}

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

/// Mirror reflection of `d` about the plane with normal `n`: d − 2(d·n)n.
#[inline]
pub fn reflect(d: Vec3A, n: Vec3A) -> Vec3A {
    (d - 2.0 * d.dot(n) * n).normalize()
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

/// Probability that a photon of wavelength λ arriving along `d` is scattered rather than absorbed.
#[inline]
pub fn albedo(m: &Material, lambda_nm: f64) -> f64 {
    match m {
        Material::Absorber => 0.0,
        Material::Lambertian { reflectance, transmittance } => {
            reflectance.eval(lambda_nm) + transmittance.eval(lambda_nm)
        }
        Material::Mirror { reflectance } => reflectance.eval(lambda_nm),
        // A smooth dielectric boundary absorbs nothing: Fresnel only splits reflection and refraction.
        Material::Dielectric { .. } => 1.0,
    }
}

/// Throughput factor of `lobe` at λ: the share of power that leaves in that lobe (ρ, τ, the
/// mirror's ρ, R or 1 − R). A lobe's probability given survival is factor/albedo.
#[inline]
pub fn lobe_factor(m: &Material, lobe: Lobe, lambda_nm: f64, d: Vec3A, n: Vec3A) -> f64 {
    match (m, lobe) {
        (Material::Lambertian { reflectance, .. }, Lobe::DiffuseReflection) => reflectance.eval(lambda_nm),
        (Material::Lambertian { transmittance, .. }, Lobe::DiffuseTransmission) => transmittance.eval(lambda_nm),
        (Material::Mirror { reflectance }, _) => reflectance.eval(lambda_nm),
        (Material::Dielectric { ior, outside_ior, .. }, lobe) => {
            let (eta_i, eta_t) = etas(ior.eval(lambda_nm), outside_ior.eval(lambda_nm), d, n);
            let (r, _) = fresnel_dielectric((d.dot(n).abs() as f64).min(1.0), eta_i, eta_t);
            if lobe == Lobe::SpecularReflection {
                r
            } else {
                1.0 - r
            }
        }
        _ => 0.0,
    }
}

/// Samples how a photon that survived leaves: the lobe with probability factor/albedo, and its
/// direction (cosine-weighted for diffuse lobes, mirror or Snell direction for specular ones).
/// `d` is the travel direction, `n` the unit geometric normal.
#[inline]
pub fn sample_scatter(m: &Material, lambda_nm: f64, d: Vec3A, n: Vec3A, s: &mut Sampler) -> (Vec3A, Lobe) {
    // Normal on the side the photon arrives from.
    let n_in = if d.dot(n) < 0.0 { n } else { -n };
    match m {
        Material::Lambertian { reflectance, transmittance } => {
            let rho = reflectance.eval(lambda_nm);
            let tau = transmittance.eval(lambda_nm);
            let u = s.uniform() * (rho + tau);
            let (u1, u2) = (s.uniform_f32(), s.uniform_f32());
            if u < rho {
                (cosine_hemisphere(n_in, u1, u2), Lobe::DiffuseReflection)
            } else {
                (cosine_hemisphere(-n_in, u1, u2), Lobe::DiffuseTransmission)
            }
        }
        Material::Mirror { .. } => (reflect(d, n), Lobe::SpecularReflection),
        Material::Dielectric { ior, outside_ior, .. } => {
            let (eta_i, eta_t) = etas(ior.eval(lambda_nm), outside_ior.eval(lambda_nm), d, n);
            let cos_i = (d.dot(n).abs() as f64).min(1.0);
            let (r, cos_t) = fresnel_dielectric(cos_i, eta_i, eta_t);
            if s.uniform() < r {
                (reflect(d, n), Lobe::SpecularReflection)
            } else {
                (refract(d, n_in, eta_i, eta_t, cos_i, cos_t), Lobe::SpecularTransmission)
            }
        }
        Material::Absorber => unreachable!("an absorber scatters nothing (albedo 0)"),
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
    fn lobe_factors_sum_to_the_albedo() {
        use crate::spectrum::Spectrum;
        let (d, n) = (Vec3A::new(0.6, -0.8, 0.0), Vec3A::Y);
        let lam = Material::Lambertian { reflectance: Spectrum::Constant(0.3), transmittance: Spectrum::Constant(0.5) };
        let sum = lobe_factor(&lam, Lobe::DiffuseReflection, 500.0, d, n)
            + lobe_factor(&lam, Lobe::DiffuseTransmission, 500.0, d, n);
        assert!((sum - albedo(&lam, 500.0)).abs() < 1e-15);
        let glass = Material::Dielectric {
            ior: Spectrum::Constant(1.5),
            outside_ior: Spectrum::Constant(1.0),
            absorption_per_m: None,
        };
        let sum = lobe_factor(&glass, Lobe::SpecularReflection, 500.0, d, n)
            + lobe_factor(&glass, Lobe::SpecularTransmission, 500.0, d, n);
        assert!((sum - 1.0).abs() < 1e-15);
    }
}
