//! A metal: exact unpolarised Fresnel reflectance of a complex index η = n + ik (against an
//! outside of index 1), smooth (a delta lobe) or rough (GGX with height-correlated Smith
//! masking–shadowing, sampled by visible normals), times a `specular_reflectance` factor.
//! Rough: f = D(m) F(wo·m) G2(wo, wi) / (4 cosθ_o cosθ_i), m the half vector; sampling m from
//! the visible normals gives the weight f cosθ_i / pdf = F(wo·m) G2/G1(wo) ≤ 1. Both sides
//! reflect alike (Mitsuba's `twosided`): the frame is turned to the side `wo` lies on, its x
//! along the surface tangent (anisotropic α: α_x along it, α_y across).

use glam::Vec3A;

use super::microfacet::{Frame, Ggx};
use super::{reflect, Factored, Lobe, Sample};
use crate::sampling::Sampler;
use crate::spectrum::Lanes;

#[derive(Clone, Copy, Debug)]
struct Complex {
    re: f64,
    im: f64,
}

impl Complex {
    fn new(re: f64, im: f64) -> Self {
        Complex { re, im }
    }
    fn add(self, o: Complex) -> Complex {
        Complex::new(self.re + o.re, self.im + o.im)
    }
    fn sub(self, o: Complex) -> Complex {
        Complex::new(self.re - o.re, self.im - o.im)
    }
    fn mul(self, o: Complex) -> Complex {
        Complex::new(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
    }
    fn scale(self, s: f64) -> Complex {
        Complex::new(self.re * s, self.im * s)
    }
    fn norm(self) -> f64 {
        self.re * self.re + self.im * self.im
    }
    fn div(self, o: Complex) -> Complex {
        let d = o.norm();
        Complex::new((self.re * o.re + self.im * o.im) / d, (self.im * o.re - self.re * o.im) / d)
    }
    /// Principal square root.
    fn sqrt(self) -> Complex {
        let r = self.norm().sqrt();
        if r == 0.0 {
            return Complex::new(0.0, 0.0);
        }
        let re = (0.5 * (r + self.re)).max(0.0).sqrt();
        let im = (0.5 * (r - self.re)).max(0.0).sqrt();
        Complex::new(re, if self.im < 0.0 { -im } else { im })
    }
}

/// Unpolarised Fresnel reflectance of a conductor with η = n + ik at incidence cosθ_i:
/// sin²θ_t = sin²θ_i/η², r_∥ = (η cosθ_i − cosθ_t)/(η cosθ_i + cosθ_t),
/// r_⊥ = (cosθ_i − η cosθ_t)/(cosθ_i + η cosθ_t), R = (|r_∥|² + |r_⊥|²)/2 (pbrt-v4's FrComplex).
pub fn fresnel_conductor(cos_i: f64, n: f64, k: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let eta = Complex::new(n, k);
    let sin2_i = Complex::new(1.0 - cos_i * cos_i, 0.0);
    let sin2_t = sin2_i.div(eta.mul(eta));
    let cos_t = Complex::new(1.0, 0.0).sub(sin2_t).sqrt();
    let ci = Complex::new(cos_i, 0.0);
    let r_parl = eta.scale(cos_i).sub(cos_t).div(eta.scale(cos_i).add(cos_t));
    let r_perp = ci.sub(eta.mul(cos_t)).div(ci.add(eta.mul(cos_t)));
    let r = 0.5 * (r_parl.norm() + r_perp.norm());
    if r.is_finite() {
        r
    } else {
        1.0
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Conductor<const N: usize> {
    pub eta: Lanes<N>,
    pub k: Lanes<N>,
    pub tint: Lanes<N>,
    /// None: smooth.
    pub ggx: Option<Ggx>,
    /// The unit surface tangent, α_x's axis; zero for an isotropic lobe.
    pub tangent: Vec3A,
}

impl<const N: usize> Conductor<N> {
    /// F(cosθ)·tint per lane.
    #[inline]
    pub(super) fn reflectance(&self, cos: f64) -> Lanes<N> {
        Lanes(std::array::from_fn(|i| fresnel_conductor(cos, self.eta.0[i], self.k.0[i]) * self.tint.0[i]))
    }

    /// A smooth metal reflects F(cosθ_o)·tint; a rough one's albedo is not known in closed form,
    /// and its sample's weight carries the loss instead (see `samples_exactly`).
    #[inline]
    pub fn albedo(&self, wo: Vec3A, n: Vec3A) -> Lanes<N> {
        match self.ggx {
            None => self.reflectance(wo.dot(n).abs() as f64),
            Some(_) => Lanes::ONE,
        }
    }

    #[inline]
    pub fn f(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> Factored<N> {
        let Some(ggx) = self.ggx else { return Factored::ZERO };
        let frame = Frame::facing_along(n, self.tangent, wo);
        let (o, i) = (frame.to_local(wo), frame.to_local(wi));
        if !(o.z > 0.0 && i.z > 0.0) {
            return Factored::ZERO;
        }
        let m = (o + i).normalize();
        let angular = ggx.d(m) * ggx.g2(o, i) / (4.0 * o.z as f64 * i.z as f64);
        Factored { spectral: self.reflectance(o.dot(m) as f64), angular }
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> f64 {
        let Some(ggx) = self.ggx else { return 0.0 };
        let frame = Frame::facing_along(n, self.tangent, wo);
        let (o, i) = (frame.to_local(wo), frame.to_local(wi));
        if !(o.z > 0.0 && i.z > 0.0) {
            return 0.0;
        }
        let m = (o + i).normalize();
        // dω_m/dω_i = 1/(4 |wo·m|) for reflection.
        ggx.visible_pdf(o, m) / (4.0 * o.dot(m) as f64)
    }

    #[inline]
    pub fn sample(&self, wo: Vec3A, n: Vec3A, s: &mut Sampler) -> Option<Sample<N>> {
        let Some(ggx) = self.ggx else {
            let factor = self.reflectance(wo.dot(n).abs() as f64);
            return Some(Sample {
                wi: reflect(-wo, n),
                lobe: Lobe::SpecularReflection,
                factor,
                lobe_pdf: 1.0,
                pdf: 0.0,
            });
        };
        let frame = Frame::facing_along(n, self.tangent, wo);
        let o = frame.to_local(wo);
        if !(o.z > 0.0) {
            return None;
        }
        let m = ggx.sample_visible(o, [s.uniform_f32(), s.uniform_f32()]);
        let i = (2.0 * o.dot(m) * m - o).normalize();
        if !(i.z > 0.0) {
            // Reflected below the surface: a path the masking function counts as lost.
            return None;
        }
        let pdf = ggx.visible_pdf(o, m) / (4.0 * o.dot(m) as f64);
        if !(pdf > 0.0) {
            return None;
        }
        let factor = self.reflectance(o.dot(m) as f64) * (ggx.g2(o, i) / ggx.g1(o));
        Some(Sample { wi: frame.to_world(i), lobe: Lobe::GlossyReflection, factor, lobe_pdf: 1.0, pdf })
    }

    /// Throughput and albedo per lane of the reflection to `wi` chosen at another lane: for the
    /// smooth metal F·tint for both (its sampling is exact); for the rough one the weight
    /// F(wo·m)·tint·G2/G1, which is also the probability a particle survives it.
    #[inline]
    pub fn event_terms(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> (Lanes<N>, Lanes<N>) {
        match self.ggx {
            None => {
                let r = self.reflectance(wo.dot(n).abs() as f64);
                (r, r)
            }
            Some(ggx) => {
                let frame = Frame::facing_along(n, self.tangent, wo);
                let (o, i) = (frame.to_local(wo), frame.to_local(wi));
                let m = (o + i).normalize();
                let t = self.reflectance(o.dot(m) as f64) * (ggx.g2(o, i) / ggx.g1(o));
                (t, t)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_reflectance_is_the_closed_form() {
        // R(0) = ((n − 1)² + k²)/((n + 1)² + k²).
        for (n, k) in [(0.96, 6.69), (0.05, 3.4), (1.5, 0.0), (0.27, 2.78)] {
            let expect = ((n - 1.0f64).powi(2) + k * k) / ((n + 1.0f64).powi(2) + k * k);
            assert!((fresnel_conductor(1.0, n, k) - expect).abs() < 1e-12, "n = {n}, k = {k}");
        }
    }

    #[test]
    fn a_conductor_with_no_extinction_is_a_dielectric() {
        // k = 0: the dielectric Fresnel term of index n, at every angle below the critical one.
        for deg in [0.0f64, 20.0, 45.0, 70.0, 85.0, 89.5] {
            let c = deg.to_radians().cos();
            let (r, _) = super::super::fresnel_dielectric(c, 1.0, 1.7);
            assert!((fresnel_conductor(c, 1.7, 0.0) - r).abs() < 1e-12, "{deg}°");
        }
        // Grazing incidence reflects everything.
        assert!((fresnel_conductor(0.0, 0.96, 6.69) - 1.0).abs() < 1e-12);
    }
}
