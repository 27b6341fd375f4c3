//! Plastic: a diffuse base of albedo ρ under a dielectric coat of index η, smooth or rough
//! (Mitsuba's `plastic` and `roughplastic` with `nonlinear = true`). Smooth, the coat reflects
//! F(θ_o) specularly; the rest enters,
//! bounces between base and coat (each bounce the base keeps ρ, the coat returns the internal
//! diffuse reflectance F̄_int), and leaves through the coat:
//!   f_d(wo, wi) = ρ/(1 − ρ F̄_int) · (1 − F(θ_i))(1 − F(θ_o)) / (π η²),
//! whose albedo is (1 − F(θ_o))·A(ρ) with A(ρ) = ρ (1 − F̄_ext) / (η² (1 − ρ F̄_int)); since
//! 1 − F̄_int = (1 − F̄_ext)/η², A(1) = 1 and a white plastic returns everything. Both sides
//! reflect alike (Mitsuba's `twosided`).
//!
//!
//! Rough (GGX α), the coat's reflection is the rough dielectric's, f_s = F(wo·m) D G2/(4 cosθ_o
//! cosθ_i), and 1 − F becomes the coat's transmittance t(θ) = 1 − E_r(θ), E_r the directional
//! albedo of f_s, tabulated at μ = k/63 and interpolated as Mitsuba does; F̄_ext = 1 − 2∫t μ dμ
//! and F̄_int = 2∫E_r,int μ dμ (E_r,int from inside, index 1/η) replace the smooth averages. The
//! masking loss of f_s is not recovered, so a rough white plastic returns a little less than 1.
//!
//! Anisotropic (α_x along the surface tangent, α_y across), E_r also depends on the azimuth φ
//! from the tangent. t is even about both axes and follows mostly the roughness wo sees,
//! α(φ) = √(α_x² cos²φ + α_y² sin²φ) (its masking's): it is tabulated over μ and 17 values of
//! α(φ) evenly spaced from α_x to α_y (so densest in φ where α(φ) turns fastest, near the
//! narrow axis), and interpolated bilinearly in (μ, α(φ)); F̄_ext is the integral of that
//! interpolant itself, and F̄_int averages E_r,int over φ at 4 Gauss–Chebyshev nodes in sin²φ.
//! Between its azimuths the table is within 3·10⁻³ of the quadrature at [0.05, 0.4] and 10⁻³
//! at [0.3, 0.1] (worst at grazing incidence; evenly in sin²φ the first was 1.5·10⁻², and the
//! quadrature's own noise there is 5·10⁻⁴); for α_x as small as 0.02 it reaches 2·10⁻² below
//! 1° from grazing, as the isotropic table's μ interpolation does (8·10⁻³ at α = 0.02).
//!
//! Sampling is the same at every wavelength: the coat's lobe with probability
//! p_s = E_o/(E_o + t_o A_max), E_o = 1 − t_o its albedo and A_max the base's largest A over the
//! spectrum; else a direction ∝ t(θ_i) cosθ_i (cosine-weighted, kept with probability t_i/t_max).
//! Smooth, every weight is ≤ 1: E_o + t_o A_max for the coat, (A(ρ_λ)/A_max)(E_o + t_o A_max) for
//! the base. Rough, a sample is weighted by the whole f over the mixture density.

use glam::Vec3A;
use std::f64::consts::FRAC_1_PI;

use super::dielectric::fresnel_dielectric;
use super::microfacet::{Frame, Ggx};
use super::{reflect, Factored, Lobe, Sample};
use crate::sampling::{cosine_hemisphere, Sampler};
use crate::scene::Roughness;
use crate::spectrum::Lanes;

/// Points of a rough coat's transmittance table, at μ = k/(TABLE − 1) (Mitsuba's 64).
const TABLE: usize = 64;

/// An anisotropic coat's table points in azimuth, at α(φ) = α_x + (α_y − α_x)·j/(AZIMUTHS − 1).
const AZIMUTHS: usize = 17;

/// Where an azimuth of s = sin²φ falls among an anisotropic table's points, in [0, 1]:
/// (α(φ) − α_x)/(α_y − α_x), α(φ)² = α_x² + s(α_y² − α_x²).
#[inline]
fn azimuth_position(ggx: &Ggx, s: f64) -> f64 {
    let (ax, ay) = (ggx.alpha_x, ggx.alpha_y);
    let alpha = (ax * ax + s.clamp(0.0, 1.0) * (ay * ay - ax * ax)).sqrt();
    ((alpha - ax) / (ay - ax)).clamp(0.0, 1.0)
}

/// The s = sin²φ of an anisotropic table's point at `position` (the inverse of `azimuth_position`).
fn azimuth_at(ggx: &Ggx, position: f64) -> f64 {
    let (ax, ay) = (ggx.alpha_x, ggx.alpha_y);
    let alpha = ax + position * (ay - ax);
    ((alpha * alpha - ax * ax) / (ay * ay - ax * ax)).clamp(0.0, 1.0)
}

/// A rough coat's transmittance t = 1 − E_r: over μ, or over (μ, s) when anisotropic.
#[derive(Clone, Debug, PartialEq)]
enum Table {
    Isotropic(Box<[f64; TABLE]>),
    Anisotropic(Box<[[f64; AZIMUTHS]; TABLE]>),
}

/// A coat's constants, worked out once per run (`super::Prepared`).
#[derive(Clone, Debug, PartialEq)]
pub struct Coat {
    pub eta: f64,
    /// Cosine-weighted hemispherical averages of the coat's Fresnel reflectance, 2∫F(μ)μ dμ, seen
    /// from outside and from inside (the latter with total internal reflection).
    pub fdr_ext: f64,
    pub fdr_int: f64,
    /// A(ρ) at the base's largest albedo over the simulated range.
    pub a_max: f64,
    /// A rough coat: its GGX distribution and its transmittance 1 − E_r at μ = k/63 (and at
    /// 17 azimuths when anisotropic).
    rough: Option<(Ggx, Table)>,
    /// The largest transmittance (of the table, or at normal incidence when smooth).
    t_max: f64,
}

/// Directional albedo E_r(μ) of the coat's GGX reflection for light arriving at cosθ = μ on the
/// side of index `eta_i`: ∫ D(m) F(wo·m) G2 |wo·m|/cosθ_o dm, by the midpoint rule over the
/// distribution's own variables (tanθ_m = α√(v/(1 − v)), φ), in which D(m) cosθ_m dm is uniform.
fn rough_reflectance(ggx: &Ggx, mu: f64, eta_i: f64, eta_t: f64) -> f64 {
    let wo = Vec3A::new((1.0 - mu * mu).max(0.0).sqrt() as f32, 0.0, mu as f32);
    let mut sum = 0.0;
    for i in 0..NV {
        let v = (i as f64 + 0.5) / NV as f64;
        let tan_m = ggx.alpha_x * (v / (1.0 - v)).sqrt();
        let cos_m = 1.0 / (1.0 + tan_m * tan_m).sqrt();
        let sin_m = tan_m * cos_m;
        for j in 0..NPHI {
            let phi = std::f64::consts::PI * 2.0 * (j as f64 + 0.5) / NPHI as f64;
            let m = Vec3A::new((sin_m * phi.cos()) as f32, (sin_m * phi.sin()) as f32, cos_m as f32);
            sum += reflected(ggx, wo, mu, m, cos_m, eta_i, eta_t);
        }
    }
    sum / (NV * NPHI) as f64
}

/// Mitsuba 3's rough-coat transmittance (its `eval_transmittance`), for a build with the
/// `mitsuba-conventions` feature (bench/mitsuba only): ∫ D_wo(m) (1 − F(wo·m)) G1(w_t) dm over
/// the visible normals, w_t the direction refracted at m, so that the refracted ray's masking
/// is lost (photon's own t = 1 − E_r sends it on into the base). The midpoint rule over the
/// visible-normal sampler's square.
fn mitsuba_transmittance(ggx: &Ggx, mu: f64, eta: f64) -> f64 {
    let wo = Vec3A::new((1.0 - mu * mu).max(0.0).sqrt() as f32, 0.0, mu as f32);
    let k = 1.0 / eta;
    let mut sum = 0.0;
    for i in 0..NV {
        for j in 0..NPHI {
            let u = [(i as f32 + 0.5) / NV as f32, (j as f32 + 0.5) / NPHI as f32];
            let m = ggx.sample_visible(wo, u);
            let cos_i = wo.dot(m) as f64;
            let sin2_t = k * k * (1.0 - cos_i * cos_i);
            if !(cos_i > 0.0) || sin2_t >= 1.0 {
                continue;
            }
            let cos_t = (1.0 - sin2_t).sqrt();
            let wt = -(k as f32) * wo + ((k * cos_i - cos_t) as f32) * m;
            if wt.z < 0.0 {
                sum += (1.0 - fresnel_dielectric(cos_i.min(1.0), 1.0, eta).0) * ggx.g1(wt);
            }
        }
    }
    sum / (NV * NPHI) as f64
}

/// Quadrature points of `rough_reflectance` in v and in φ.
const NV: usize = 256;
const NPHI: usize = 64;

/// One quadrature point of E_r: F G2 |wo·m|/(cosθ_o cosθ_m) for the microfacet `m`, zero where
/// it faces away or reflects below the surface.
#[inline]
fn reflected(ggx: &Ggx, wo: Vec3A, mu: f64, m: Vec3A, cos_m: f64, eta_i: f64, eta_t: f64) -> f64 {
    let cos_om = wo.dot(m) as f64;
    if cos_om <= 0.0 {
        return 0.0;
    }
    let wi = 2.0 * wo.dot(m) * m - wo;
    if wi.z <= 0.0 {
        return 0.0;
    }
    let f = fresnel_dielectric(cos_om.min(1.0), eta_i, eta_t).0;
    f * ggx.g2(wo, wi) * cos_om / (cos_m * mu)
}

/// The microfacet normals of an anisotropic GGX's quadrature, with their cosθ_m: the same
/// rule as `rough_reflectance`'s over the slopes (α_x r cos φ, α_y r sin φ), r = √(v/(1 − v)),
/// over which D(m) cosθ_m dm is again uniform (dv dφ/2π), m ∝ (slope, 1). Shared by every
/// direction of the table.
fn facets(ggx: &Ggx) -> Vec<(Vec3A, f64)> {
    let mut out = Vec::with_capacity(NV * NPHI);
    for i in 0..NV {
        let v = (i as f64 + 0.5) / NV as f64;
        let r = (v / (1.0 - v)).sqrt();
        for j in 0..NPHI {
            let phi = std::f64::consts::PI * 2.0 * (j as f64 + 0.5) / NPHI as f64;
            let (px, py) = (ggx.alpha_x * r * phi.cos(), ggx.alpha_y * r * phi.sin());
            let cos_m = 1.0 / (1.0 + px * px + py * py).sqrt();
            out.push((Vec3A::new((px * cos_m) as f32, (py * cos_m) as f32, cos_m as f32), cos_m));
        }
    }
    out
}

/// E_r(wo) of an anisotropic GGX (`wo` unit, z > 0) over its `facets`.
fn rough_reflectance_towards(ggx: &Ggx, facets: &[(Vec3A, f64)], wo: Vec3A, eta_i: f64, eta_t: f64) -> f64 {
    let mu = wo.z as f64;
    facets.iter().map(|&(m, cos_m)| reflected(ggx, wo, mu, m, cos_m, eta_i, eta_t)).sum::<f64>() / facets.len() as f64
}

/// The unit direction at cosθ = `mu` and azimuth φ from the x axis.
fn direction(mu: f64, phi: f64) -> Vec3A {
    let st = (1.0 - mu * mu).max(0.0).sqrt();
    Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, mu as f32)
}

impl Coat {
    pub fn new(eta: f64, rho_max: f64, roughness: &Roughness) -> Self {
        if let Some(ggx) = Ggx::of(roughness) {
            return if roughness.is_anisotropic() {
                Self::rough_anisotropic(eta, rho_max, ggx)
            } else {
                Self::rough(eta, rho_max, ggx)
            };
        }
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
        let mut coat =
            Coat { eta, fdr_ext: average(1.0, eta), fdr_int: average(eta, 1.0), a_max: 0.0, rough: None, t_max: 0.0 };
        coat.t_max = coat.transmittance(1.0);
        coat.a_max = coat.base_albedo(rho_max);
        coat
    }

    fn rough(eta: f64, rho_max: f64, ggx: Ggx) -> Self {
        let mu = |k: usize| (k as f64 / (TABLE - 1) as f64).max(1e-6);
        let mitsuba = cfg!(feature = "mitsuba-conventions");
        let t: [f64; TABLE] = std::array::from_fn(|k| {
            if mitsuba {
                mitsuba_transmittance(&ggx, mu(k), eta)
            } else {
                1.0 - rough_reflectance(&ggx, mu(k), 1.0, eta)
            }
        });
        let e_int: [f64; TABLE] = std::array::from_fn(|k| rough_reflectance(&ggx, mu(k), eta, 1.0));
        // 2∫ g(μ) μ dμ by the trapezoid rule on the table's points.
        let average = |g: &dyn Fn(usize) -> f64| {
            let h = 1.0 / (TABLE - 1) as f64;
            (0..TABLE).map(|k| g(k) * (k as f64 * h) * if k == 0 || k == TABLE - 1 { 0.5 } else { 1.0 }).sum::<f64>()
                * 2.0
                * h
        };
        // Mitsuba 3's rule, 2·mean of E_r,int(μ_k) μ_k over the points (the end points at full
        // weight: about 1/64 low).
        let fdr_int = if mitsuba {
            2.0 * (0..TABLE).map(|k| e_int[k] * mu(k)).sum::<f64>() / TABLE as f64
        } else {
            average(&|k| e_int[k])
        };
        let t_max = t.iter().copied().fold(0.0, f64::max);
        let mut coat = Coat {
            eta,
            fdr_ext: 1.0 - average(&|k| t[k]),
            fdr_int,
            a_max: 0.0,
            rough: Some((ggx, Table::Isotropic(Box::new(t)))),
            t_max,
        };
        coat.a_max = coat.base_albedo(rho_max);
        coat
    }

    fn rough_anisotropic(eta: f64, rho_max: f64, ggx: Ggx) -> Self {
        let mu = |k: usize| (k as f64 / (TABLE - 1) as f64).max(1e-6);
        let phi = |s: f64| s.sqrt().asin();
        let facets = facets(&ggx);
        let mut t = Box::new([[0.0; AZIMUTHS]; TABLE]);
        for (k, row) in t.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                let s = azimuth_at(&ggx, j as f64 / (AZIMUTHS - 1) as f64);
                let w = direction(mu(k), phi(s));
                *x = 1.0 - rough_reflectance_towards(&ggx, &facets, w, 1.0, eta);
            }
        }
        // F̄_int = 2∫E_r,int μ dμ with E_r,int averaged over φ ∈ [0, π/2] at the Chebyshev
        // nodes φ_j = (j + ½)π/8 (equal weights), then the trapezoid rule in μ as when isotropic.
        const NODES: usize = 4;
        let e_int: Vec<f64> = (0..TABLE)
            .map(|k| {
                (0..NODES)
                    .map(|j| {
                        let w = direction(mu(k), (j as f64 + 0.5) * std::f64::consts::FRAC_PI_2 / NODES as f64);
                        rough_reflectance_towards(&ggx, &facets, w, eta, 1.0)
                    })
                    .sum::<f64>()
                    / NODES as f64
            })
            .collect();
        let h = 1.0 / (TABLE - 1) as f64;
        let fdr_int = (0..TABLE)
            .map(|k| e_int[k] * (k as f64 * h) * if k == 0 || k == TABLE - 1 { 0.5 } else { 1.0 })
            .sum::<f64>()
            * 2.0
            * h;
        let t_max = t.iter().flatten().copied().fold(0.0, f64::max);
        let mut coat =
            Coat { eta, fdr_ext: 0.0, fdr_int, a_max: 0.0, rough: Some((ggx, Table::Anisotropic(t))), t_max };
        // 1 − F̄_ext = (1/π)∫t cosθ dω of the interpolated table itself, which the base's
        // sampling draws from (so its density integrates to 1): the midpoint rule over μ and over
        // a quarter turn of φ (t is even about both axes), fine enough that the table's kinks
        // leave an error below 10⁻⁶.
        const NMU: usize = 2048;
        const NQ: usize = 128;
        let mut sum = 0.0;
        for i in 0..NMU {
            let m = (i as f64 + 0.5) / NMU as f64;
            for j in 0..NQ {
                let s = ((j as f64 + 0.5) * std::f64::consts::FRAC_PI_2 / NQ as f64).sin().powi(2);
                sum += coat.transmittance_at(m, s) * m;
            }
        }
        coat.fdr_ext = 1.0 - 2.0 * sum / (NMU * NQ) as f64;
        coat.a_max = coat.base_albedo(rho_max);
        coat
    }

    /// A(ρ): the share of the power entering the coat that comes back out through it; at most 1
    /// (the quadratures of F̄ leave A(1) within 10⁻⁸ of 1, to either side).
    #[inline]
    pub fn base_albedo(&self, rho: f64) -> f64 {
        (rho * (1.0 - self.fdr_ext) / (self.eta * self.eta * (1.0 - rho * self.fdr_int))).min(1.0)
    }

    /// t(θ): 1 − F(θ) for a smooth coat, the interpolated table for a rough one (an
    /// anisotropic one's at s = 0).
    #[inline]
    fn transmittance(&self, cos: f64) -> f64 {
        let cos = cos.clamp(0.0, 1.0);
        match &self.rough {
            None => 1.0 - fresnel_dielectric(cos, 1.0, self.eta).0,
            Some((_, Table::Isotropic(table))) => {
                let x = cos * (TABLE - 1) as f64;
                let k = (x as usize).min(TABLE - 2);
                let w = x - k as f64;
                table[k] * (1.0 - w) + table[k + 1] * w
            }
            Some((_, Table::Anisotropic(_))) => self.transmittance_at(cos, 0.0),
        }
    }

    /// t(θ, φ) of an anisotropic coat at cosθ = `cos` and s = sin²φ (φ from the tangent),
    /// bilinear in (μ, α(φ)); the isotropic t(θ) otherwise.
    #[inline]
    fn transmittance_at(&self, cos: f64, s: f64) -> f64 {
        let Some((ggx, Table::Anisotropic(table))) = &self.rough else { return self.transmittance(cos) };
        let x = cos.clamp(0.0, 1.0) * (TABLE - 1) as f64;
        let k = (x as usize).min(TABLE - 2);
        let w = x - k as f64;
        let y = azimuth_position(ggx, s) * (AZIMUTHS - 1) as f64;
        let j = (y as usize).min(AZIMUTHS - 2);
        let v = y - j as f64;
        let row = |k: usize| table[k][j] * (1.0 - v) + table[k][j + 1] * v;
        row(k) * (1.0 - w) + row(k + 1) * w
    }

    fn is_anisotropic(&self) -> bool {
        matches!(self.rough, Some((_, Table::Anisotropic(_))))
    }
}

#[derive(Clone, Copy, Debug)]
pub struct Plastic<'a, const N: usize> {
    /// ρ/(1 − ρ F̄_int)/η² per lane: the base's factor of f_d.
    base: Lanes<N>,
    /// A(ρ) per lane.
    albedo: Lanes<N>,
    coat: &'a Coat,
    /// The unit surface tangent, an anisotropic coat's α_x axis; zero for an isotropic one.
    tangent: Vec3A,
}

impl<'a, const N: usize> Plastic<'a, N> {
    #[inline]
    pub fn new(rho: Lanes<N>, coat: &'a Coat, tangent: Vec3A) -> Self {
        let eta2 = coat.eta * coat.eta;
        Plastic {
            base: Lanes(rho.0.map(|r| r / (1.0 - r * coat.fdr_int) / eta2)),
            albedo: Lanes(rho.0.map(|r| coat.base_albedo(r))),
            coat,
            tangent,
        }
    }

    /// The coat's transmittance t toward `w` (either side of `n`): at cosθ = |w·n|, and for an
    /// anisotropic coat at s = sin²φ = 1 − (w·t)²/sin²θ, φ the azimuth from the tangent.
    #[inline]
    fn t(&self, w: Vec3A, n: Vec3A) -> f64 {
        let cos = w.dot(n).abs() as f64;
        if !self.coat.is_anisotropic() {
            return self.coat.transmittance(cos);
        }
        let sin2 = 1.0 - cos * cos;
        let along = w.dot(self.tangent) as f64;
        let s = if sin2 > 0.0 { 1.0 - along * along / sin2 } else { 0.0 };
        self.coat.transmittance_at(cos, s)
    }

    /// The probability of the coat's lobe given t_o.
    #[inline]
    fn p_specular(&self, t_o: f64) -> f64 {
        let e_o = 1.0 - t_o;
        let total = e_o + t_o * self.coat.a_max;
        if total > 0.0 {
            e_o / total
        } else {
            1.0
        }
    }

    /// E_o + t_o A_max, the same at every lane: the particle tracer's first absorption (exact
    /// for a smooth coat and a grey base; the rest is the sample's weight).
    #[inline]
    pub fn albedo_bound(&self, wo: Vec3A, n: Vec3A) -> Lanes<N> {
        let t_o = self.t(wo, n);
        Lanes::splat((1.0 - t_o) + t_o * self.coat.a_max)
    }

    /// The albedo per lane, E_o + t_o A(ρ) (exact for the smooth coat; for the rough one E_o is
    /// the interpolated table).
    #[inline]
    pub fn albedo(&self, wo: Vec3A, n: Vec3A) -> Lanes<N> {
        let t_o = self.t(wo, n);
        Lanes(self.albedo.0.map(|a| (1.0 - t_o) + t_o * a))
    }

    pub fn is_rough(&self) -> bool {
        self.coat.rough.is_some()
    }

    /// The frame on `wo`'s side and the rough coat's lobe f_s(wo, wi) with its sampling density
    /// (visible normals, reflected); zero below the surface.
    #[inline]
    fn coat_lobe(&self, ggx: &Ggx, wo: Vec3A, wi: Vec3A, n: Vec3A) -> (f64, f64) {
        let frame = Frame::facing_along(n, self.tangent, wo);
        let (o, i) = (frame.to_local(wo), frame.to_local(wi));
        if !(o.z > 0.0 && i.z > 0.0) {
            return (0.0, 0.0);
        }
        let m = (o + i).normalize();
        let cos_om = (o.dot(m) as f64).min(1.0);
        let f = fresnel_dielectric(cos_om, 1.0, self.coat.eta).0 * ggx.d(m) * ggx.g2(o, i)
            / (4.0 * o.z as f64 * i.z as f64);
        (f, ggx.visible_pdf(o, m) / (4.0 * cos_om))
    }

    /// f(wo, wi): the base, and for a rough coat its lobe (a smooth coat's is a delta).
    #[inline]
    pub fn f(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> Factored<N> {
        let (co, ci) = (wo.dot(n), wi.dot(n));
        if !(co * ci > 0.0) {
            return Factored::ZERO;
        }
        let t = self.t(wo, n) * self.t(wi, n);
        match &self.coat.rough {
            None => Factored { spectral: self.base, angular: t * FRAC_1_PI },
            Some((ggx, _)) => {
                let (f_s, _) = self.coat_lobe(ggx, wo, wi, n);
                Factored { spectral: Lanes(self.base.0.map(|b| b * t * FRAC_1_PI + f_s)), angular: 1.0 }
            }
        }
    }

    /// The base's density (1 − p_s) t_i cosθ_i / (π (1 − F̄_ext)), plus p_s times the rough coat's.
    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, n: Vec3A) -> f64 {
        let (co, ci) = (wo.dot(n), wi.dot(n));
        if !(co * ci > 0.0) {
            return 0.0;
        }
        let p_s = self.p_specular(self.t(wo, n));
        let c = ci.abs() as f64;
        let base = (1.0 - p_s) * self.t(wi, n) * c * FRAC_1_PI / (1.0 - self.coat.fdr_ext);
        match &self.coat.rough {
            None => base,
            Some((ggx, _)) => base + p_s * self.coat_lobe(ggx, wo, wi, n).1,
        }
    }

    /// A rough plastic's sample weight f|cosθ_i|/pdf per lane, given the mixture density `pdf` > 0.
    #[inline]
    fn mixture_weight(&self, wo: Vec3A, wi: Vec3A, n: Vec3A, pdf: f64) -> Lanes<N> {
        let value = self.f(wo, wi, n).value() * (wi.dot(n).abs() as f64);
        Lanes(value.0.map(|v| v / pdf))
    }

    /// A sample's weight per lane in `lobe` toward `wi`. The lanes share the sampling, so this is
    /// also each lane's factor for the hero weights.
    #[inline]
    pub fn weight(&self, lobe: Lobe, wo: Vec3A, wi: Vec3A, n: Vec3A) -> Lanes<N> {
        let t_o = self.t(wo, n);
        let p_s = self.p_specular(t_o);
        if self.is_rough() {
            let pdf = self.pdf(wo, wi, n);
            return if pdf > 0.0 { self.mixture_weight(wo, wi, n, pdf) } else { Lanes::ZERO };
        }
        match lobe {
            Lobe::SpecularReflection => Lanes::splat((1.0 - t_o) / p_s),
            Lobe::DiffuseReflection => Lanes(self.albedo.0.map(|a| t_o * a / (1.0 - p_s))),
            _ => Lanes::ZERO,
        }
    }

    #[inline]
    pub fn sample(&self, wo: Vec3A, n: Vec3A, s: &mut Sampler) -> Option<Sample<N>> {
        let co = wo.dot(n);
        let t_o = self.t(wo, n);
        let p_s = self.p_specular(t_o);
        let n_out = if co > 0.0 { n } else { -n };
        let wi = if s.uniform() < p_s {
            let Some((ggx, _)) = &self.coat.rough else {
                let factor = Lanes::splat(1.0 - t_o);
                return Some(Sample {
                    wi: reflect(-wo, n),
                    lobe: Lobe::SpecularReflection,
                    factor,
                    lobe_pdf: p_s,
                    pdf: 0.0,
                });
            };
            let frame = Frame::facing_along(n, self.tangent, wo);
            let o = frame.to_local(wo);
            let m = ggx.sample_visible(o, [s.uniform_f32(), s.uniform_f32()]);
            let i = (2.0 * o.dot(m) * m - o).normalize();
            if !(i.z > 0.0) {
                return None;
            }
            frame.to_world(i)
        } else {
            // Cosine-weighted, kept with probability t_i / t_max: density ∝ t_i cosθ_i. A try is
            // kept with probability (1 − F̄_ext)/t_max, above 0.8 for η ≤ 3, so 64 tries all fail
            // (and the last is kept untested) with probability below 10⁻⁴⁴.
            let mut wi = cosine_hemisphere(n_out, s.uniform_f32(), s.uniform_f32());
            for _ in 0..64 {
                if s.uniform() * self.coat.t_max < self.t(wi, n) {
                    break;
                }
                wi = cosine_hemisphere(n_out, s.uniform_f32(), s.uniform_f32());
            }
            wi
        };
        let pdf = self.pdf(wo, wi, n);
        if !(pdf > 0.0) {
            return None;
        }
        if self.is_rough() {
            // Two overlapping lobes: the whole f over the mixture density.
            let factor = self.mixture_weight(wo, wi, n, pdf);
            return Some(Sample { wi, lobe: Lobe::GlossyReflection, factor, lobe_pdf: 1.0, pdf });
        }
        // f cos / (t_i cos/(π(1 − F̄_ext))) = t_o A(ρ).
        let factor = Lanes(self.albedo.0.map(|a| t_o * a));
        Some(Sample { wi, lobe: Lobe::DiffuseReflection, factor, lobe_pdf: 1.0 - p_s, pdf })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(feature = "mitsuba-conventions")]
    #[test]
    fn mitsuba_conventions_reproduce_mitsubas_own_coat_tables() {
        // Mitsuba 3.9.1's roughplastic (GGX α = 0.1, η = 1.5), read back from its `eval` by
        // bench/mitsuba/plastic_coat.py: T(μ) at table points and F̄_int. Different quadratures
        // of one integral (Mitsuba's 32² Gauss–Legendre over its visible-normal square in f32,
        // photon's 256 × 64 midpoint rule): they agree to 10⁻³.
        let mitsuba = [(1, 0.569286), (8, 0.637014), (16, 0.767430), (32, 0.908957), (48, 0.951172), (63, 0.959560)];
        let coat = Coat::new(1.5, 0.9, &Roughness::from(0.1));
        let Some((_, Table::Isotropic(t))) = &coat.rough else { panic!("a rough isotropic coat") };
        for (k, want) in mitsuba {
            assert!((t[k] - want).abs() < 1e-3, "T(μ = {k}/63): photon {} vs Mitsuba {want}", t[k]);
        }
        assert!((coat.fdr_int - 0.551894).abs() < 1e-3, "F̄_int: photon {} vs Mitsuba 0.551894", coat.fdr_int);
    }

    #[test]
    fn an_anisotropic_coat_interpolates_its_transmittance_between_azimuths_to_its_quadrature() {
        // Halfway between the table's points in μ and in azimuth, the bilinear table against the
        // quadrature itself; an overestimate of t is what could make a white plastic gain energy.
        for (ax, ay, bound) in [(0.05, 0.4, 3e-3), (0.3, 0.1, 1e-3)] {
            let coat = Coat::new(1.5, 1.0, &Roughness { u: ax, v: ay });
            let ggx = Ggx::new(ax, ay);
            let facets = facets(&ggx);
            let (mut over, mut under) = (0.0f64, 0.0f64);
            for k in (0..TABLE - 1).step_by(3) {
                let mu = (k as f64 + 0.5) / (TABLE - 1) as f64;
                for j in 0..AZIMUTHS - 1 {
                    let s = azimuth_at(&ggx, (j as f64 + 0.5) / (AZIMUTHS - 1) as f64);
                    let w = direction(mu, s.sqrt().asin());
                    let exact = 1.0 - rough_reflectance_towards(&ggx, &facets, w, 1.0, 1.5);
                    let e = coat.transmittance_at(mu, s) - exact;
                    (over, under) = (over.max(e), under.min(e));
                }
            }
            println!("α = [{ax}, {ay}]: table − quadrature from {under:.2e} to {over:.2e}");
            assert!(over < bound && -under < 2.0 * bound, "α = [{ax}, {ay}]: {under:.2e} to {over:.2e}");
        }
    }
}
