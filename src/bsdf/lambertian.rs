//! Lambertian reflection ρ/π and diffuse transmission τ/π (ρ + τ ≤ 1), sampled cosine-weighted
//! on the chosen side. The lobe is chosen with the lanes' mean ρ and τ, independent of λ, so one
//! direction serves every lane.

// `!(x > 0.0)` is meant: it is also true for NaN, which must end a sample as zero would.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::Vec3A;
use std::f64::consts::FRAC_1_PI;

use super::{Factored, Lobe, Sample};
use crate::sampling::{cosine_hemisphere, Sampler};
use crate::spectrum::Lanes;

#[derive(Clone, Copy, Debug)]
pub struct Lambertian<const N: usize> {
    rho: Lanes<N>,
    tau: Lanes<N>,
    /// Lane means of ρ and τ.
    mean_rho: f64,
    mean_tau: f64,
}

impl<const N: usize> Lambertian<N> {
    #[inline]
    pub fn new(rho: Lanes<N>, tau: Lanes<N>) -> Self {
        Lambertian { rho, tau, mean_rho: rho.mean(), mean_tau: tau.mean() }
    }

    #[inline]
    pub fn albedo(&self) -> Lanes<N> {
        self.rho + self.tau
    }

    #[inline]
    pub fn mean_albedo(&self) -> f64 {
        self.mean_rho + self.mean_tau
    }

    /// Probability of choosing reflection: exactly 1 without transmission (most surfaces), as the
    /// division gives, but without it (5 % of the grey Cornell box's photon loop).
    #[inline]
    fn p_reflect(&self) -> f64 {
        let a = self.mean_albedo();
        if self.mean_tau == 0.0 {
            1.0
        } else if a > 0.0 {
            self.mean_rho / a
        } else {
            1.0
        }
    }

    /// ρ/π with `wo` and `wi` on the same side, τ/π through: symmetric in its arguments.
    #[inline]
    pub fn f(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> Factored<N> {
        let same_side = wo.dot(n) * wi.dot(n) > 0.0;
        Factored { spectral: if same_side { self.rho } else { self.tau }, angular: FRAC_1_PI }
    }

    /// P(lobe) · |cosθ_i|/π.
    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> f64 {
        let cos_i = wi.dot(n);
        let p = self.p_reflect();
        let lobe = if wo.dot(n) * cos_i > 0.0 { p } else { 1.0 - p };
        lobe * cos_i.abs() as f64 * FRAC_1_PI
    }

    /// The lobe with probability mean ρ : mean τ, then a cosine-weighted direction on its side;
    /// the lobe's factor f|cos|/(|cos|/π) is ρ or τ.
    #[inline(always)]
    pub fn sample(&self, wo: Vec3A, n: Vec3A, s: &mut Sampler) -> Option<Sample<N>> {
        let a = self.mean_albedo();
        if !(a > 0.0) {
            return None;
        }
        let n_out = if wo.dot(n) > 0.0 { n } else { -n };
        // Without transmission the lobe is certain, and no number is drawn for it.
        let reflect = self.mean_tau == 0.0 || s.uniform() * a < self.mean_rho;
        let (u1, u2) = (s.uniform_f32(), s.uniform_f32());
        let wi = cosine_hemisphere(if reflect { n_out } else { -n_out }, u1, u2);
        let pdf = self.pdf(wo, wi, n);
        if !(pdf > 0.0) {
            return None;
        }
        let p = self.p_reflect();
        Some(if reflect {
            Sample { wi, lobe: Lobe::DiffuseReflection, factor: self.rho, lobe_pdf: p, pdf }
        } else {
            Sample { wi, lobe: Lobe::DiffuseTransmission, factor: self.tau, lobe_pdf: 1.0 - p, pdf }
        })
    }

    #[inline]
    pub fn lobe_factor(&self, lobe: Lobe) -> Lanes<N> {
        match lobe {
            Lobe::DiffuseReflection => self.rho,
            Lobe::DiffuseTransmission => self.tau,
            _ => Lanes::ZERO,
        }
    }
}
