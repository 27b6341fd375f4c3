//! ABg scatter on a smooth mirror, metal or dielectric boundary: the stray-light model of
//! TracePro and Zemax OpticStudio. In direction-cosine space β (the tangent-plane projection of
//! a unit direction, so d²β = |cosθ| dω) the scattered lobe is BSDF = A/(B + |β − β₀|^g) sr⁻¹
//! about β₀, the projection of the specular direction. Its total integrated scatter at that
//! incidence, TIS(|β₀|) = ∫_{|β|<1} BSDF d²β (what lies outside the unit disk is evanescent and
//! does not exist), is taken from the specular share: a surface of specular reflectance R
//! reflects R·(1 − TIS) specularly and scatters R·BSDF, so it conserves R at every angle.
//! A dielectric scatters its Fresnel-reflected part about the mirror direction and its refracted
//! part about the refracted direction, in the β of the side the light leaves into.
//!
//! The reflectance R (mirror ρ, metal Fresnel, dielectric R or 1 − R) is the one at the angle the
//! light arrives from: `wo` for particles (importance), `wi` for camera paths (radiance).
//!
//! The lobe is tabulated once per run (`Table`), piecewise linear in s = |β − β₀|² over a first
//! cell in the flat core and 2047 log-spaced ones (about 10⁻⁴ of the formula for g ≤ 2.5, 10⁻³
//! at g = 8), and that table *is* the model: f, its sampling by inverse CDF and its TIS all use
//! it, so sampling is exact (each sample weighs R) and the energy split is exact to the TIS
//! table's interpolation (tests/abg.rs holds it to 2·10⁻⁴).

use glam::Vec3A;
use std::f64::consts::PI;

use super::conductor::Conductor;
use super::dielectric::{etas, fresnel_dielectric, refract};
use super::microfacet::Frame;
use super::{reflect, Factored, Lobe, Mode, Sample};
use crate::sampling::Sampler;
use crate::scene::Abg;
use crate::spectrum::Lanes;

/// Cells of the lobe table in s, and of the TIS table in 1 − |β₀|.
const LOBE_CELLS: usize = 2048;
const TIS_CELLS: usize = 512;
/// Draws of the offset before a sample is given up (each lands in the disk with probability ≥ 1/4,
/// so giving up happens with probability below 1e-32).
const MAX_DRAWS: usize = 256;
/// The least share of a camera path's samples at a dielectric that go to the refracted side:
/// from inside beyond the critical angle wo's own Fresnel gives that side nothing, yet light the
/// glass scatters in from outside still reaches wo.
const DEFENSIVE_REFRACTION: f64 = 0.1;

/// The ABg lobe of one material, tabulated (see the module's notes).
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    a: f64,
    /// s nodes: 0, then geometric from `s[1]` to 4 (|β − β₀| ≤ 2) with ratio e^`ln_ratio`.
    s: Vec<f64>,
    ln_ratio: f64,
    /// The shape 1/(B + s^{g/2}) at the nodes, and its integral in s from 0 (W).
    shape: Vec<f64>,
    cumulative: Vec<f64>,
    /// M(|β₀|) = ∫_{|β|<1} shape d²β at d = 1 − |β₀|: 0, then geometric from `d[1]` to 1.
    d: Vec<f64>,
    ln_d_ratio: f64,
    mass: Vec<f64>,
}

impl Table {
    pub fn new(abg: &Abg) -> Table {
        // From inside the flat core to s = 4.
        let s_min = abg.flat_below();
        let ln_ratio = (4.0 / s_min).ln() / (LOBE_CELLS - 1) as f64;
        let mut s: Vec<f64> =
            std::iter::once(0.0).chain((0..LOBE_CELLS).map(|k| s_min * (k as f64 * ln_ratio).exp())).collect();
        s[LOBE_CELLS] = 4.0;
        let shape: Vec<f64> = s.iter().map(|&x| abg.shape(x)).collect();
        let mut cumulative = vec![0.0; s.len()];
        for k in 1..s.len() {
            cumulative[k] = cumulative[k - 1] + 0.5 * (s[k] - s[k - 1]) * (shape[k] + shape[k - 1]);
        }
        let d_min = (abg.knee() * 1e-2).clamp(1e-9, 1e-3);
        let ln_d_ratio = (1.0 / d_min).ln() / (TIS_CELLS - 1) as f64;
        let mut d: Vec<f64> =
            std::iter::once(0.0).chain((0..TIS_CELLS).map(|j| d_min * (j as f64 * ln_d_ratio).exp())).collect();
        d[TIS_CELLS] = 1.0;
        let mut table = Table { a: abg.a, s, ln_ratio, shape, cumulative, d, ln_d_ratio, mass: Vec::new() };
        table.mass = table.d.iter().map(|&d| table.disk_mass(1.0 - d)).collect();
        table
    }

    /// The cell k with s[k] ≤ x < s[k+1] of a node list that is 0 then geometric from `nodes[1]`.
    #[inline]
    fn cell(nodes: &[f64], ln_ratio: f64, x: f64) -> usize {
        let last = nodes.len() - 2;
        if !(x >= nodes[1]) {
            return 0;
        }
        let mut k = (1 + ((x / nodes[1]).ln() / ln_ratio) as usize).min(last);
        // The logarithm can land one cell off.
        while k > 1 && x < nodes[k] {
            k -= 1;
        }
        while k < last && x >= nodes[k + 1] {
            k += 1;
        }
        k
    }

    /// The tabulated shape at s = |β − β₀|²: the BSDF is A times it.
    #[inline]
    pub fn shape(&self, s: f64) -> f64 {
        let k = Self::cell(&self.s, self.ln_ratio, s);
        let t = ((s - self.s[k]) / (self.s[k + 1] - self.s[k])).clamp(0.0, 1.0);
        self.shape[k] + t * (self.shape[k + 1] - self.shape[k])
    }

    /// W(s) = ∫₀^s shape ds': the lobe's power within |β − β₀| < √s is πA·W(s).
    fn cumulative(&self, s: f64) -> f64 {
        let s = s.clamp(0.0, 4.0);
        let k = Self::cell(&self.s, self.ln_ratio, s);
        let x = s - self.s[k];
        // In the cell's own fraction t, so that a steep cell (huge shape, tiny width) cannot overflow.
        let t = (x / (self.s[k + 1] - self.s[k])).clamp(0.0, 1.0);
        self.cumulative[k] + x * (self.shape[k] + 0.5 * (self.shape[k + 1] - self.shape[k]) * t)
    }

    /// W(4): the lobe's whole power over |β − β₀| ≤ 2 is πA·W(4).
    #[inline]
    fn total(&self) -> f64 {
        self.cumulative[self.cumulative.len() - 1]
    }

    /// The s with W(s) = w (inverse CDF): a linear density within a cell gives a quadratic.
    fn inverse_cumulative(&self, w: f64) -> f64 {
        let k = self.cumulative.partition_point(|&c| c <= w).clamp(1, self.s.len() - 1) - 1;
        let (s0, s1) = (self.s[k], self.s[k + 1]);
        let (f0, f1) = (self.shape[k], self.shape[k + 1]);
        // With x = t·(s1 − s0): t + d·t²/2 = c, d = (f1 − f0)/f0 ∈ [−1, 0] and c the rest of w
        // over the cell's f0·(s1 − s0), solved without cancellation and scaled so nothing overflows.
        let c = ((w - self.cumulative[k]).max(0.0) / (f0 * (s1 - s0))).min(1.0);
        let d = (f1 - f0) / f0;
        let t = 2.0 * c / (1.0 + (1.0 + 2.0 * d * c).max(0.0).sqrt());
        (s0 + t.clamp(0.0, 1.0) * (s1 - s0)).min(s1)
    }

    /// M(b) = ∫_{|β|<1} shape(|β − β₀|²) d²β for |β₀| = b: in polar coordinates about β₀ the disk
    /// reaches ρ(φ) = −b cosφ + √(1 − b² sin²φ), so M = ∫₀^π W(ρ²) dφ (adaptive Simpson).
    fn disk_mass(&self, b: f64) -> f64 {
        let f = |phi: f64| {
            let (sin, cos) = phi.sin_cos();
            let rho = -b * cos + (1.0 - b * b * sin * sin).max(0.0).sqrt();
            self.cumulative(rho * rho)
        };
        let tolerance = 1e-9 * self.total();
        let (fa, fm, fb) = (f(0.0), f(0.5 * PI), f(PI));
        adaptive_simpson(&f, 0.0, PI, fa, fm, fb, simpson(0.0, PI, fa, fm, fb), tolerance, 18)
    }

    /// Total integrated scatter about a specular direction of projection length `b`: A·M(b),
    /// interpolated from the table (at most 1: the loader refuses larger A).
    #[inline]
    pub fn tis(&self, b: f64) -> f64 {
        let d = (1.0 - b).clamp(0.0, 1.0);
        let j = Self::cell(&self.d, self.ln_d_ratio, d);
        let t = ((d - self.d[j]) / (self.d[j + 1] - self.d[j])).clamp(0.0, 1.0);
        (self.a * (self.mass[j] + t * (self.mass[j + 1] - self.mass[j]))).min(1.0)
    }

    /// BSDF density of scattering from β₀ to β, per d²β: A·shape(|β − β₀|²).
    #[inline]
    fn bsdf(&self, beta: [f64; 2], beta0: [f64; 2]) -> f64 {
        self.a * self.shape((beta[0] - beta0[0]).powi(2) + (beta[1] - beta0[1]).powi(2))
    }

    /// A β inside the unit disk with density ∝ shape(|β − β₀|²): the offset's length by inverse
    /// CDF within the circle of radius 1 + |β₀| (which holds the disk), its angle uniform, drawn
    /// again while it lands outside the disk. None (probability < 1e-32) if it never does.
    #[inline]
    pub fn sample_about(&self, beta0: [f64; 2], s: &mut Sampler) -> Option<[f64; 2]> {
        let b = (beta0[0] * beta0[0] + beta0[1] * beta0[1]).sqrt().min(1.0);
        let total = self.cumulative((1.0 + b) * (1.0 + b));
        for _ in 0..MAX_DRAWS {
            let r = self.inverse_cumulative(s.uniform() * total).sqrt();
            let (sin, cos) = (2.0 * PI * s.uniform()).sin_cos();
            let beta = [beta0[0] + r * cos, beta0[1] + r * sin];
            if beta[0] * beta[0] + beta[1] * beta[1] < 1.0 {
                return Some(beta);
            }
        }
        None
    }
}

fn simpson(a: f64, b: f64, fa: f64, fm: f64, fb: f64) -> f64 {
    (b - a) / 6.0 * (fa + 4.0 * fm + fb)
}

#[allow(clippy::too_many_arguments)]
fn adaptive_simpson(
    f: &impl Fn(f64) -> f64,
    a: f64,
    b: f64,
    fa: f64,
    fm: f64,
    fb: f64,
    whole: f64,
    tolerance: f64,
    depth: u32,
) -> f64 {
    let m = 0.5 * (a + b);
    let (lm, rm) = (f(0.5 * (a + m)), f(0.5 * (m + b)));
    let (left, right) = (simpson(a, m, fa, lm, fm), simpson(m, b, fm, rm, fb));
    let delta = left + right - whole;
    // A non-finite or unresolvable piece stops refining (no input can make this run for ever).
    if depth == 0 || !(delta.abs() > 15.0 * tolerance) {
        left + right + delta / 15.0
    } else {
        adaptive_simpson(f, a, m, fa, lm, fm, left, 0.5 * tolerance, depth - 1)
            + adaptive_simpson(f, m, b, fm, rm, fb, right, 0.5 * tolerance, depth - 1)
    }
}

/// The smooth surface the lobe scatters from.
#[derive(Clone, Copy, Debug)]
pub enum Base<const N: usize> {
    Mirror(Lanes<N>),
    Conductor(Conductor<N>),
    /// Indices inside and outside (lane 0's, as for the smooth dielectric).
    Dielectric {
        ior: f64,
        outside_ior: f64,
    },
}

#[derive(Clone, Copy, Debug)]
pub struct AbgSurface<'a, const N: usize> {
    pub base: Base<N>,
    pub table: &'a Table,
}

/// `wo` and `wi` in the frame turned to `wo`'s side (their x, y are their β), and the indices.
struct Local {
    o: Vec3A,
    i: Vec3A,
    /// Index on `wo`'s side and on the other.
    eta_o: f64,
    eta_t: f64,
}

impl Local {
    #[inline]
    fn beta(w: Vec3A) -> [f64; 2] {
        [w.x as f64, w.y as f64]
    }
}

impl<'a, const N: usize> AbgSurface<'a, N> {
    /// Specular reflectance at incidence cosθ: ρ, F·tint, or the dielectric's Fresnel R for
    /// light arriving on the side of index `eta_from`.
    #[inline]
    fn reflectance(&self, cos: f64, eta_from: f64, eta_to: f64) -> Lanes<N> {
        match &self.base {
            Base::Mirror(rho) => *rho,
            Base::Conductor(c) => c.reflectance(cos),
            Base::Dielectric { .. } => Lanes::splat(fresnel_dielectric(cos, eta_from, eta_to).0),
        }
    }

    pub fn is_dielectric(&self) -> bool {
        matches!(self.base, Base::Dielectric { .. })
    }

    #[inline]
    fn local(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> (Frame, Local) {
        let frame = Frame::facing(n, wo);
        let (eta_o, eta_t) = match self.base {
            Base::Dielectric { ior, outside_ior } => etas(ior, outside_ior, -wo, n),
            _ => (1.0, 1.0),
        };
        (frame, Local { o: frame.to_local(wo), i: frame.to_local(wi), eta_o, eta_t })
    }

    /// The specular reflectance for a path from `wo`: the power the surface returns at all
    /// (1 for a dielectric, which divides it).
    #[inline]
    pub fn albedo(&self, wo: Vec3A, n: Vec3A) -> Lanes<N> {
        match self.base {
            Base::Dielectric { .. } => Lanes::ONE,
            _ => self.reflectance(wo.dot(n).abs() as f64, 1.0, 1.0),
        }
    }

    /// Where the refracted direction of light arriving along −w (local, side index `from`)
    /// projects, for a boundary into index `to`: −(η_from/η_to)·β_w; None under total reflection.
    #[inline]
    fn refracted_beta(w: Vec3A, from: f64, to: f64) -> Option<[f64; 2]> {
        let k = from / to;
        let beta = [-k * w.x as f64, -k * w.y as f64];
        (beta[0] * beta[0] + beta[1] * beta[1] < 1.0).then_some(beta)
    }

    /// The scattered part of f (the specular part is a delta).
    #[inline]
    pub fn f(&self, wo: Vec3A, wi: Vec3A, n: Vec3A, mode: Mode) -> Factored<N> {
        let (_, l) = self.local(wo, wi, n);
        if !(l.o.z > 0.0) || l.i.z == 0.0 {
            return Factored::ZERO;
        }
        let (bo, bi) = (Local::beta(l.o), Local::beta(l.i));
        if l.i.z > 0.0 {
            // Reflection about the mirror direction, whose β is −β_o.
            let light = if mode == Mode::Importance { l.o } else { l.i };
            let r = self.reflectance(light.z as f64, l.eta_o, l.eta_t);
            return Factored { spectral: r, angular: self.table.bsdf(bi, [-bo[0], -bo[1]]) };
        }
        if !self.is_dielectric() {
            return Factored::ZERO;
        }
        match mode {
            // Power from wo refracts about its refracted direction, in wi's β.
            Mode::Importance => {
                let Some(beta0) = Self::refracted_beta(l.o, l.eta_o, l.eta_t) else { return Factored::ZERO };
                let t = 1.0 - fresnel_dielectric(l.o.z as f64, l.eta_o, l.eta_t).0;
                Factored { spectral: Lanes::splat(t), angular: self.table.bsdf(bi, beta0) }
            }
            // Light from wi refracts about its own refracted direction, in wo's β. The lobe is
            // the power scattered per projected solid angle of the side it leaves into, which is
            // also the radiance BSDF f(wi → wo): no (η_o/η_i)² here. That factor belongs to the
            // delta lobe's weight alone, where a density in ω_o is taken per ω_i.
            Mode::Radiance => {
                let Some(beta0) = Self::refracted_beta(l.i, l.eta_t, l.eta_o) else { return Factored::ZERO };
                let t = 1.0 - fresnel_dielectric(-l.i.z as f64, l.eta_t, l.eta_o).0;
                Factored { spectral: Lanes::splat(t), angular: self.table.bsdf(bo, beta0) }
            }
        }
    }

    /// Solid-angle density of `sample`'s scattered directions in `mode`: the lobe choice times
    /// the offset's density per d²β times |cosθ_i|. About a specular direction that is
    /// R·TIS · A·shape/(A·M)·|cosθ_i|: the M's cancel. A camera path's refraction is drawn in the
    /// light's variables (`sample_refraction_of_light`): there it is
    /// (1 − p_reflect)·q · shape(|Δ|²)/(πW(4)) · (η_t/η_o)² · |cosθ_i|.
    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, n: Vec3A, mode: Mode) -> f64 {
        let (_, l) = self.local(wo, wi, n);
        if !(l.o.z > 0.0) || l.i.z == 0.0 {
            return 0.0;
        }
        let (bo, bi) = (Local::beta(l.o), Local::beta(l.i));
        let p_reflect = self.reflection_share(&l, mode);
        let cos = (l.i.z as f64).abs();
        if l.i.z > 0.0 {
            return p_reflect * self.table.bsdf(bi, [-bo[0], -bo[1]]) * cos;
        }
        if !self.is_dielectric() {
            return 0.0;
        }
        match mode {
            Mode::Importance => match Self::refracted_beta(l.o, l.eta_o, l.eta_t) {
                Some(beta0) => (1.0 - p_reflect) * self.table.bsdf(bi, beta0) * cos,
                None => 0.0,
            },
            Mode::Radiance => {
                // Δ = β_o − β₀(wi), β₀(wi) = −(η_t/η_o)·β_i the light's refracted direction.
                let k = l.eta_t / l.eta_o;
                let s = (bo[0] + k * bi[0]).powi(2) + (bo[1] + k * bi[1]).powi(2);
                if !(s <= 4.0) {
                    return 0.0;
                }
                let q = self.glossy_share_of_light(&l);
                (1.0 - p_reflect) * q * self.table.shape(s) / (PI * self.table.total()) * k * k * cos
            }
        }
    }

    /// Reflect or refract (a dielectric: with probability `reflection_share`), then scatter with
    /// probability TIS about that specular direction or keep it.
    #[inline]
    pub fn sample(&self, wo: Vec3A, n: Vec3A, mode: Mode, s: &mut Sampler) -> Option<Sample<N>> {
        let (frame, mut l) = self.local(wo, wo, n);
        if !(l.o.z > 0.0) {
            return None;
        }
        let p_reflect = self.reflection_share(&l, mode);
        let reflection = !self.is_dielectric() || s.uniform() < p_reflect;
        if !reflection && mode == Mode::Radiance {
            return self.sample_refraction_of_light(wo, n, frame, l, 1.0 - p_reflect, s);
        }
        let (beta0, choice) = if reflection {
            ([-l.o.x as f64, -l.o.y as f64], p_reflect)
        } else {
            // R < 1 here, so the refracted direction exists (in f32 it may not: then nothing leaves).
            (Self::refracted_beta(l.o, l.eta_o, l.eta_t)?, 1.0 - p_reflect)
        };
        let tis = self.table.tis(length(beta0));
        let (lobe, wi, pdf) = if s.uniform() < tis {
            let beta = self.table.sample_about(beta0, s)?;
            let z = (1.0 - beta[0] * beta[0] - beta[1] * beta[1]).max(0.0).sqrt();
            l.i = Vec3A::new(beta[0] as f32, beta[1] as f32, if reflection { z } else { -z } as f32);
            let pdf = choice * self.table.bsdf(beta, beta0) * z;
            let lobe = if reflection { Lobe::GlossyReflection } else { Lobe::GlossyTransmission };
            (lobe, frame.to_world(l.i), pdf)
        } else if reflection {
            (Lobe::SpecularReflection, reflect(-wo, n), 0.0)
        } else {
            (Lobe::SpecularTransmission, Self::specular_refraction(wo, n, &l, beta0), 0.0)
        };
        let lobe_pdf = choice * if lobe.is_delta() { 1.0 - tis } else { tis };
        let factor = self.lobe_factor(lobe, &l, mode);
        (lobe_pdf > 0.0).then_some(Sample { wi, lobe, factor, lobe_pdf, pdf })
    }

    /// A camera path's refraction (chosen with probability `choice`), drawn in the light's
    /// variables: the light from wi scatters about its own refracted direction β₀(wi), so wi is
    /// found from an offset Δ drawn from the whole lobe (|Δ| ≤ 2, density shape(|Δ|²)/(πW(4))
    /// per d²Δ) as β_i = −(η_o/η_t)(β_o − Δ), with d²Δ = (η_t/η_o)² d²β_i. This reaches every wi
    /// the light can come from, also when wo, inside beyond the critical angle, has no
    /// refracted direction of its own; a Δ that puts β_i outside the unit disk is lost. With
    /// probability 1 − q (q = TIS about wo) the light comes along wo's own refraction instead.
    #[inline]
    fn sample_refraction_of_light(
        &self,
        wo: Vec3A,
        n: Vec3A,
        frame: Frame,
        mut l: Local,
        choice: f64,
        s: &mut Sampler,
    ) -> Option<Sample<N>> {
        let q = self.glossy_share_of_light(&l);
        let (lobe, wi, lobe_pdf, pdf) = if s.uniform() < q {
            let bo = Local::beta(l.o);
            let r2 = self.table.inverse_cumulative(s.uniform() * self.table.total());
            let (sin, cos) = (2.0 * PI * s.uniform()).sin_cos();
            let (r, k) = (r2.sqrt(), l.eta_o / l.eta_t);
            let beta = [-k * (bo[0] - r * cos), -k * (bo[1] - r * sin)];
            let z2 = 1.0 - beta[0] * beta[0] - beta[1] * beta[1];
            if !(z2 > 0.0) {
                return None;
            }
            let z = z2.sqrt();
            l.i = Vec3A::new(beta[0] as f32, beta[1] as f32, -z as f32);
            let pdf = choice * q * self.table.shape(r2) / (PI * self.table.total()) / (k * k) * z;
            (Lobe::GlossyTransmission, frame.to_world(l.i), choice * q, pdf)
        } else {
            // q < 1 only where wo refracts.
            let beta0 = Self::refracted_beta(l.o, l.eta_o, l.eta_t)?;
            (Lobe::SpecularTransmission, Self::specular_refraction(wo, n, &l, beta0), choice * (1.0 - q), 0.0)
        };
        // Light from a wi inside glass beyond the critical angle cannot reach wo: such a sample
        // carries nothing and is still returned, so `pdf` stays its density.
        let factor = self.lobe_factor(lobe, &l, Mode::Radiance);
        (lobe_pdf > 0.0).then_some(Sample { wi, lobe, factor, lobe_pdf, pdf })
    }

    /// The refracted direction of travel along −wo, whose β is `beta0`.
    #[inline]
    fn specular_refraction(wo: Vec3A, n: Vec3A, l: &Local, beta0: [f64; 2]) -> Vec3A {
        let d = -wo;
        let n_in = if d.dot(n) < 0.0 { n } else { -n };
        let cos_t = (1.0 - length(beta0).powi(2)).max(0.0).sqrt();
        refract(d, n_in, l.eta_o, l.eta_t, l.o.z as f64, cos_t)
    }

    /// A dielectric's Fresnel reflectance for light from `wo`; 1 for a reflector.
    #[inline]
    fn split(&self, l: &Local) -> f64 {
        match self.base {
            Base::Dielectric { .. } => fresnel_dielectric(l.o.z as f64, l.eta_o, l.eta_t).0,
            _ => 1.0,
        }
    }

    /// Probability that `sample` reflects: the Fresnel R of wo for particles (exact sampling);
    /// for camera paths at most 1 − `DEFENSIVE_REFRACTION`, so that the refracted side, which
    /// light reaches wo from even where wo itself totally reflects, is always sampled.
    #[inline]
    fn reflection_share(&self, l: &Local, mode: Mode) -> f64 {
        let r = self.split(l);
        match (mode, self.is_dielectric()) {
            (Mode::Radiance, true) => r.min(1.0 - DEFENSIVE_REFRACTION),
            _ => r,
        }
    }

    /// Within a camera path's refraction, the share drawn from the scattered lobe: TIS about wo
    /// (the specular share's complement, so that the specular weight is T·(η_o/η_t)²/choice),
    /// or all of it where wo has no refracted direction.
    #[inline]
    fn glossy_share_of_light(&self, l: &Local) -> f64 {
        match Self::refracted_beta(l.o, l.eta_o, l.eta_t) {
            Some(_) => self.table.tis(length(Local::beta(l.o))),
            None => 1.0,
        }
    }

    /// f·|cosθ_i| of `lobe` toward `l.i` over the lobe's own direction density (that of the
    /// scattered offset, or the delta): R·TIS, R·(1 − TIS); for a camera path's scattered
    /// refraction, drawn in the light's variables, T(θ_i)·πA·W(4)·(η_o/η_t)².
    #[inline]
    fn lobe_factor(&self, lobe: Lobe, l: &Local, mode: Mode) -> Lanes<N> {
        let bo = Local::beta(l.o);
        // Evaluated only by the lobes that take them (a metal's is four complex Fresnel terms).
        let r_o = || self.reflectance(l.o.z as f64, l.eta_o, l.eta_t);
        let t_o = || 1.0 - self.split(l);
        let refracted = || Self::refracted_beta(l.o, l.eta_o, l.eta_t);
        match lobe {
            Lobe::SpecularReflection => r_o() * (1.0 - self.table.tis(length(bo))),
            Lobe::GlossyReflection => {
                let tis = self.table.tis(length(bo));
                match mode {
                    Mode::Importance => r_o() * tis,
                    Mode::Radiance => self.reflectance(l.i.z as f64, l.eta_o, l.eta_t) * tis,
                }
            }
            Lobe::SpecularTransmission => {
                // TIS about the direction the light leaves along: wi for power, wo for radiance,
                // whose delta refraction alone takes the radiance factor (η_o/η_t)² (see `f`).
                let (leaving, scale) = match mode {
                    Mode::Importance => (refracted().map_or(1.0, length), 1.0),
                    Mode::Radiance => (length(bo), (l.eta_o / l.eta_t).powi(2)),
                };
                Lanes::splat(t_o() * (1.0 - self.table.tis(leaving)) * scale)
            }
            Lobe::GlossyTransmission => match mode {
                Mode::Importance => {
                    let Some(beta0) = refracted() else { return Lanes::ZERO };
                    Lanes::splat(t_o() * self.table.tis(length(beta0)))
                }
                Mode::Radiance => {
                    // f = T(θ_i)·A·shape(|Δ|²) over the density shape(|Δ|²)(η_t/η_o)²/(πW(4)).
                    if Self::refracted_beta(l.i, l.eta_t, l.eta_o).is_none() {
                        return Lanes::ZERO;
                    }
                    let t_light = 1.0 - fresnel_dielectric(-l.i.z as f64, l.eta_t, l.eta_o).0;
                    let k = l.eta_o / l.eta_t;
                    Lanes::splat(t_light * self.table.a * PI * self.table.total() * k * k)
                }
            },
            _ => Lanes::ZERO,
        }
    }

    /// Per lane, for the scattering into `lobe` toward `wi` that another lane sampled: the factor
    /// (as in `sample`) and the albedo; the sampling is exact, so the analog probability is the factor.
    #[inline]
    pub fn event_terms(&self, lobe: Lobe, wo: Vec3A, wi: Vec3A, n: Vec3A, mode: Mode) -> (Lanes<N>, Lanes<N>) {
        let (_, l) = self.local(wo, wi, n);
        (self.lobe_factor(lobe, &l, mode), self.albedo(wo, n))
    }
}

/// |β|.
#[inline]
fn length(beta: [f64; 2]) -> f64 {
    (beta[0] * beta[0] + beta[1] * beta[1]).sqrt()
}
