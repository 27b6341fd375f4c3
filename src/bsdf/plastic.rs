//! Plastic: a diffuse base of albedo ρ under a smooth dielectric coat of index η (Mitsuba's
//! `plastic` with `nonlinear = true`). The coat reflects F(θ_o) specularly; the rest enters,
//! bounces between base and coat (each bounce the base keeps ρ, the coat returns the internal
//! diffuse reflectance F̄_int), and leaves through the coat:
//!   f_d(wo, wi) = ρ/(1 − ρ F̄_int) · (1 − F(θ_i))(1 − F(θ_o)) / (π η²),
//! whose albedo is (1 − F(θ_o))·A(ρ) with A(ρ) = ρ (1 − F̄_ext) / (η² (1 − ρ F̄_int)); since
//! 1 − F̄_int = (1 − F̄_ext)/η², A(1) = 1 and a white plastic returns everything. Both sides
//! reflect alike (Mitsuba's `twosided`).
//!
//! Sampling is the same at every wavelength: the specular lobe with probability
//! p_s = F_o/(F_o + t_o A_max), A_max the base's largest A over the spectrum, t_o = 1 − F_o; else
//! a direction ∝ (1 − F(θ_i)) cosθ_i (cosine-weighted, kept with probability t_i/t(0)). Every
//! weight is then ≤ 1: F_o + t_o A_max for the coat, (A(ρ_λ)/A_max)(F_o + t_o A_max) for the base.

use glam::Vec3A;
use std::f64::consts::FRAC_1_PI;

use super::dielectric::fresnel_dielectric;
use super::{reflect, Factored, Lobe, Sample};
use crate::sampling::{cosine_hemisphere, Sampler};
use crate::spectrum::Lanes;

/// A coat's constants, worked out once per run (`super::Prepared`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Coat {
    pub eta: f64,
    /// Cosine-weighted hemispherical averages of the coat's Fresnel reflectance, 2∫F(μ)μ dμ, seen
    /// from outside and from inside (the latter with total internal reflection).
    pub fdr_ext: f64,
    pub fdr_int: f64,
    /// A(ρ) at the base's largest albedo over the simulated range.
    pub a_max: f64,
}

impl Coat {
    pub fn new(eta: f64, rho_max: f64) -> Self {
        let average = |eta_i: f64, eta_t: f64| {
            // Below the critical cosine μ_c everything is reflected (∫₀^μc 2μ dμ = μ_c²). Above
            // it F has a square-root edge at μ_c, which μ = μ_c + (1 − μ_c)v² smooths out for
            // the midpoint rule in v.
            let mu_c = if eta_i > eta_t { (1.0 - (eta_t / eta_i).powi(2)).sqrt() } else { 0.0 };
            const N: usize = 4096;
            let rest: f64 = (0..N)
                .map(|k| {
                    let v = (k as f64 + 0.5) / N as f64;
                    let mu = mu_c + (1.0 - mu_c) * v * v;
                    fresnel_dielectric(mu, eta_i, eta_t).0 * mu * 2.0 * (1.0 - mu_c) * v
                })
                .sum::<f64>()
                / N as f64;
            mu_c * mu_c + 2.0 * rest
        };
        let mut coat = Coat { eta, fdr_ext: average(1.0, eta), fdr_int: average(eta, 1.0), a_max: 0.0 };
        coat.a_max = coat.base_albedo(rho_max);
        coat
    }

    /// A(ρ): the share of the power entering the coat that comes back out through it; at most 1
    /// (the quadratures of F̄ leave A(1) within 10⁻⁸ of 1, to either side).
    #[inline]
    pub fn base_albedo(&self, rho: f64) -> f64 {
        (rho * (1.0 - self.fdr_ext) / (self.eta * self.eta * (1.0 - rho * self.fdr_int))).min(1.0)
    }

    /// 1 − F(θ) for light crossing the coat at cosθ (from outside; the same from inside at the
    /// matching refracted angle).
    #[inline]
    fn transmittance(&self, cos: f64) -> f64 {
        1.0 - fresnel_dielectric(cos.clamp(0.0, 1.0), 1.0, self.eta).0
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Plastic<const N: usize> {
    /// ρ/(1 − ρ F̄_int)/η² per lane: the base's factor of f_d.
    base: Lanes<N>,
    /// A(ρ) per lane.
    albedo: Lanes<N>,
    coat: Coat,
}

impl<const N: usize> Plastic<N> {
    #[inline]
    pub fn new(rho: Lanes<N>, coat: Coat) -> Self {
        let eta2 = coat.eta * coat.eta;
        Plastic {
            base: Lanes(rho.0.map(|r| r / (1.0 - r * coat.fdr_int) / eta2)),
            albedo: Lanes(rho.0.map(|r| coat.base_albedo(r))),
            coat,
        }
    }

    /// The probability of the coat's specular lobe from `cos_o`, and t_o.
    #[inline]
    fn p_specular(&self, cos_o: f64) -> (f64, f64) {
        let t_o = self.coat.transmittance(cos_o);
        let f_o = 1.0 - t_o;
        let total = f_o + t_o * self.coat.a_max;
        (if total > 0.0 { f_o / total } else { 1.0 }, t_o)
    }

    /// The upper bound F_o + t_o A_max of the albedo, the same at every lane (the particle
    /// tracer's first absorption; the base's A(ρ_λ)/A_max is the sample's weight).
    #[inline]
    pub fn albedo_bound(&self, wo: Vec3A, n: Vec3A) -> Lanes<N> {
        let t_o = self.coat.transmittance(wo.dot(n).abs() as f64);
        Lanes::splat((1.0 - t_o) + t_o * self.coat.a_max)
    }

    /// The albedo per lane: F_o + t_o A(ρ).
    #[inline]
    pub fn albedo(&self, wo: Vec3A, n: Vec3A) -> Lanes<N> {
        let t_o = self.coat.transmittance(wo.dot(n).abs() as f64);
        Lanes(self.albedo.0.map(|a| (1.0 - t_o) + t_o * a))
    }

    /// The diffuse part (the coat's specular lobe is a delta).
    #[inline]
    pub fn f(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> Factored<N> {
        let (co, ci) = (wo.dot(n), wi.dot(n));
        if !(co * ci > 0.0) {
            return Factored::ZERO;
        }
        let t = self.coat.transmittance(co.abs() as f64) * self.coat.transmittance(ci.abs() as f64);
        Factored { spectral: self.base, angular: t * FRAC_1_PI }
    }

    /// Density of the diffuse lobe: (1 − p_s) t_i cosθ_i / (π (1 − F̄_ext)).
    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> f64 {
        let (co, ci) = (wo.dot(n), wi.dot(n));
        if !(co * ci > 0.0) {
            return 0.0;
        }
        let (p_s, _) = self.p_specular(co.abs() as f64);
        let ci = ci.abs() as f64;
        (1.0 - p_s) * self.coat.transmittance(ci) * ci * FRAC_1_PI / (1.0 - self.coat.fdr_ext)
    }

    /// A sample's weight per lane in `lobe`: F_o/p_s = F_o + t_o A_max for the coat, t_o A(ρ_λ)/(1 − p_s)
    /// for the base. The lanes share the sampling, so this is also each lane's survival (hero weights).
    #[inline]
    pub fn weight(&self, lobe: Lobe, wo: Vec3A, n: Vec3A) -> Lanes<N> {
        let (p_s, t_o) = self.p_specular(wo.dot(n).abs() as f64);
        match lobe {
            Lobe::SpecularReflection => Lanes::splat((1.0 - t_o) / p_s),
            Lobe::DiffuseReflection => Lanes(self.albedo.0.map(|a| t_o * a / (1.0 - p_s))),
            _ => Lanes::ZERO,
        }
    }

    #[inline]
    pub fn sample(&self, wo: Vec3A, n: Vec3A, s: &mut Sampler) -> Option<Sample<N>> {
        let co = wo.dot(n);
        let (p_s, t_o) = self.p_specular(co.abs() as f64);
        if s.uniform() < p_s {
            let factor = Lanes::splat(1.0 - t_o);
            return Some(Sample {
                wi: reflect(-wo, n),
                lobe: Lobe::SpecularReflection,
                factor,
                lobe_pdf: p_s,
                pdf: 0.0,
            });
        }
        let n_out = if co > 0.0 { n } else { -n };
        // Cosine-weighted, kept with probability t_i / t(normal): density ∝ t_i cosθ_i. A try is
        // kept with probability (1 − F̄_ext)/t(normal), above 0.8 for η ≤ 3, so 64 tries all fail
        // (and the last is kept untested) with probability below 10⁻⁴⁴.
        let t_max = self.coat.transmittance(1.0);
        let mut wi = cosine_hemisphere(n_out, s.uniform_f32(), s.uniform_f32());
        for _ in 0..64 {
            if s.uniform() * t_max < self.coat.transmittance(wi.dot(n_out) as f64) {
                break;
            }
            wi = cosine_hemisphere(n_out, s.uniform_f32(), s.uniform_f32());
        }
        let pdf = self.pdf(wo, wi, n);
        if !(pdf > 0.0) {
            return None;
        }
        // f cos / (t_i cos/(π(1 − F̄_ext))) = t_o A(ρ).
        let factor = Lanes(self.albedo.0.map(|a| t_o * a));
        Some(Sample { wi, lobe: Lobe::DiffuseReflection, factor, lobe_pdf: 1.0 - p_s, pdf })
    }
}
