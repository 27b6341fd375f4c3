//! A rough dielectric boundary (Walter, Marschner, Li & Torrance 2007, "Microfacet Models for
//! Refraction through Rough Surfaces"), GGX with Smith height-correlated masking–shadowing,
//! sampled by visible normals; laid out as pbrt-v4's rough DielectricBxDF. In the frame turned
//! to the side of `wo` with η' = η_t/η_i (the index beyond the boundary over the index on `wo`'s
//! side), reflection about m is Fresnel's R(wo·m), refraction through m its 1 − R:
//!   f_r = D(m) G2 R / (4 |cosθ_o cosθ_i|),  m = (wo + wi)/|wo + wi|;
//!   f_t = D(m) G2 (1 − R) |wi·m| |wo·m| / (|cosθ_o cosθ_i| (wi·m + wo·m/η')²),  m ∝ wo + η' wi,
//! times 1/η'² for radiance only: power is not compressed into the narrower cone, radiance is
//! (so f_t in importance mode is the radiance f_t with its arguments swapped, and
//! f_t(wo, wi)/η_o² = f_t(wi, wo)/η_i² in radiance mode). Sampling m from the visible normals,
//! then reflection with probability R, gives the weight G2/G1(wo) ≤ 1 for power.

use glam::Vec3A;

use super::dielectric::{etas, fresnel_dielectric, refract};
use super::microfacet::{Frame, Ggx};
use super::{Factored, Lobe, Mode, Sample};
use crate::sampling::Sampler;
use crate::spectrum::Lanes;

#[derive(Clone, Copy, Debug)]
pub struct RoughDielectric {
    pub ior: f64,
    pub outside_ior: f64,
    pub ggx: Ggx,
    /// The unit surface tangent, α_x's axis; zero for an isotropic lobe.
    pub tangent: Vec3A,
}

/// `wo` and `wi` in the frame on `wo`'s side, with the indices on each side.
struct Local {
    o: Vec3A,
    i: Vec3A,
    eta_o: f64,
    eta_t: f64,
}

impl RoughDielectric {
    #[inline]
    fn local(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> Local {
        let frame = Frame::facing_along(n, self.tangent, wo);
        let (eta_o, eta_t) = etas(self.ior, self.outside_ior, -wo, n);
        Local { o: frame.to_local(wo), i: frame.to_local(wi), eta_o, eta_t }
    }

    /// The microfacet normal joining `o` to `i` (upper side), and whether `i` is a reflection;
    /// None where no microfacet facing both can join them.
    #[inline]
    fn half_vector(l: &Local) -> Option<(Vec3A, bool)> {
        let (o, i) = (l.o, l.i);
        if o.z == 0.0 || i.z == 0.0 {
            return None;
        }
        let reflect = i.z > 0.0;
        let etap = (l.eta_t / l.eta_o) as f32;
        let m = if reflect { o + i } else { o + i * etap };
        if m.length_squared() == 0.0 {
            return None;
        }
        let m = m.normalize();
        let m = if m.z < 0.0 { -m } else { m };
        // Back-facing microfacets contribute nothing.
        if m.dot(i) * i.z < 0.0 || m.dot(o) * o.z < 0.0 {
            return None;
        }
        Some((m, reflect))
    }

    /// Refraction's (wi·m + wo·m/η')² and the radiance factor 1/η'².
    #[inline]
    fn refraction_terms(l: &Local, m: Vec3A, mode: Mode) -> (f64, f64) {
        let etap = l.eta_t / l.eta_o;
        let denom = (l.i.dot(m) as f64 + l.o.dot(m) as f64 / etap).powi(2);
        let scale = if mode == Mode::Radiance { 1.0 / (etap * etap) } else { 1.0 };
        (denom, scale)
    }

    #[inline]
    pub fn f<const N: usize>(&self, wo: Vec3A, wi: Vec3A, n: Vec3A, mode: Mode) -> Factored<N> {
        let l = self.local(wo, wi, n);
        let Some((m, reflect)) = Self::half_vector(&l) else { return Factored::ZERO };
        let cos_om = l.o.dot(m) as f64;
        let (r, _) = fresnel_dielectric(cos_om.min(1.0), l.eta_o, l.eta_t);
        let (co, ci) = (l.o.z as f64, (l.i.z as f64).abs());
        let dg = self.ggx.d(m) * self.ggx.g2(l.o, l.i);
        if reflect {
            Factored { spectral: Lanes::splat(r), angular: dg / (4.0 * co * ci) }
        } else {
            let (denom, scale) = Self::refraction_terms(&l, m, mode);
            let angular = dg * (l.i.dot(m) as f64 * cos_om).abs() / (co * ci * denom) * scale;
            Factored { spectral: Lanes::splat(1.0 - r), angular }
        }
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> f64 {
        let l = self.local(wo, wi, n);
        let Some((m, reflect)) = Self::half_vector(&l) else { return 0.0 };
        let cos_om = l.o.dot(m) as f64;
        let (r, _) = fresnel_dielectric(cos_om.min(1.0), l.eta_o, l.eta_t);
        let pdf_m = self.ggx.visible_pdf(l.o, m);
        if reflect {
            pdf_m / (4.0 * cos_om) * r
        } else {
            let (denom, _) = Self::refraction_terms(&l, m, Mode::Importance);
            // dω_m/dω_i = |wi·m| / (wi·m + wo·m/η')².
            pdf_m * (l.i.dot(m) as f64).abs() / denom * (1.0 - r)
        }
    }

    #[inline]
    pub fn sample<const N: usize>(&self, wo: Vec3A, n: Vec3A, mode: Mode, s: &mut Sampler) -> Option<Sample<N>> {
        let frame = Frame::facing_along(n, self.tangent, wo);
        let (eta_o, eta_t) = etas(self.ior, self.outside_ior, -wo, n);
        let o = frame.to_local(wo);
        if !(o.z > 0.0) {
            return None;
        }
        let m = self.ggx.sample_visible(o, [s.uniform_f32(), s.uniform_f32()]);
        let cos_om = (o.dot(m) as f64).min(1.0);
        if !(cos_om > 0.0) {
            return None;
        }
        let (r, cos_t) = fresnel_dielectric(cos_om, eta_o, eta_t);
        let pdf_m = self.ggx.visible_pdf(o, m);
        let reflect = s.uniform() < r;
        let i =
            if reflect { (2.0 * o.dot(m) * m - o).normalize() } else { refract(-o, m, eta_o, eta_t, cos_om, cos_t) };
        // A reflection below the surface or a refraction above it: lost, as the masking counts it.
        if reflect != (i.z > 0.0) || i.z == 0.0 {
            return None;
        }
        let g = self.ggx.g2(o, i) / self.ggx.g1(o);
        let l = Local { o, i, eta_o, eta_t };
        let wi = frame.to_world(i);
        if reflect {
            let pdf = pdf_m / (4.0 * cos_om) * r;
            (pdf > 0.0).then_some(Sample {
                wi,
                lobe: Lobe::GlossyReflection,
                factor: Lanes::splat(r * g),
                lobe_pdf: r,
                pdf,
            })
        } else {
            let (denom, scale) = Self::refraction_terms(&l, m, mode);
            let pdf = pdf_m * (i.dot(m) as f64).abs() / denom * (1.0 - r);
            let factor = Lanes::splat((1.0 - r) * g * scale);
            (pdf > 0.0).then_some(Sample { wi, lobe: Lobe::GlossyTransmission, factor, lobe_pdf: 1.0 - r, pdf })
        }
    }

    /// The weight per lane G2/G1 of the scattering to `wi` (the lanes share one index: a
    /// dispersive boundary keeps lane 0 alone), which is also a particle's survival probability.
    #[inline]
    pub fn event_terms<const N: usize>(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> (Lanes<N>, Lanes<N>) {
        let l = self.local(wo, wi, n);
        let g = self.ggx.g2(l.o, l.i) / self.ggx.g1(l.o);
        (Lanes::splat(g), Lanes::splat(g))
    }
}
