//! ABg scatter (`scatter = { abg = [A, B, g] }`): its TIS against closed forms and against an
//! independent quadrature of the formula; energy at every angle; a χ² test of its sampler in
//! direction-cosine bins (its lobes can be far narrower than tests/chi2.rs's sphere bins); the
//! particle tracer's far field against the closed form; the loader's refusals.
//!
//! Statistical bounds: χ² upper-tail probability above 10⁻³ (a correct sampler fails one such
//! test in a thousand; seeds fixed); far-field bins as Σz² within the χ² distribution's 10⁻⁴
//! tails and every |z| < 4.5.

mod common;
use common::chi2_tail;

use glam::Vec3A;
use photon::bsdf::abg::Table;
use photon::bsdf::{Bsdf, Lobe, Mode, Prepared};
use photon::sampling::Sampler;
use photon::scene::{Abg, Material, Roughness};
use photon::spectrum::Spectrum;
use std::f64::consts::PI;

const NARROW: Abg = Abg { a: 0.05, b: 0.01, g: 2.0 };
const BROAD: Abg = Abg { a: 0.2, b: 0.5, g: 1.0 };
const SHARP: Abg = Abg { a: 0.01, b: 1e-4, g: 2.5 };
const FLAT: Abg = Abg { a: 0.1, b: 1.0, g: 0.0 };

fn prepared(m: &Material) -> &'static Prepared {
    Box::leak(Box::new(Prepared::of(m, (400.0, 700.0))))
}

fn mirror(rho: f64, abg: Abg) -> Material {
    Material::Mirror { reflectance: Spectrum::Constant(rho), scatter: Some(abg) }
}

fn metal(abg: Abg) -> Material {
    Material::Conductor {
        eta: Spectrum::Constant(1.2),
        k: Spectrum::Constant(7.0),
        specular_reflectance: Spectrum::Constant(1.0),
        roughness: Roughness::SMOOTH,
        scatter: Some(abg),
    }
}

fn glass(abg: Abg) -> Material {
    Material::Dielectric {
        ior: Spectrum::Constant(1.5),
        outside_ior: Spectrum::Constant(1.0),
        absorption_per_m: None,
        roughness: Roughness::SMOOTH,
        scatter: Some(abg),
    }
}

fn grey(m: &Material, n: Vec3A) -> Bsdf<'static, 1> {
    Bsdf::<1>::new::<false>(m, prepared(m), &[f64::NAN], n, || Vec3A::X)
}

/// A unit direction at `theta_deg` from +z in the xz plane, turned by `phi_deg` about z.
fn at(theta_deg: f64, phi_deg: f64) -> Vec3A {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    Vec3A::new((st * cp) as f32, (st * sp) as f32, ct as f32)
}

/// ∫₀^ρ h(r) r dr by Gauss–Legendre panels uniform in ln r from `r_lo` (below which h is taken
/// as h(0)).
fn radial(h: impl Fn(f64) -> f64, rho: f64, r_lo: f64, panels: usize) -> f64 {
    if rho <= r_lo {
        return 0.5 * rho * rho * h(0.0);
    }
    let (x0, x1) = (r_lo.ln(), rho.ln());
    let step = (x1 - x0) / panels as f64;
    let mut sum = 0.5 * r_lo * r_lo * h(0.0);
    for p in 0..panels {
        let mid = x0 + (p as f64 + 0.5) * step;
        for (x, w) in photon::scene::GAUSS_LEGENDRE_8 {
            let r = (mid + 0.5 * step * x).exp();
            sum += 0.5 * step * w * r * r * h(r);
        }
    }
    sum
}

/// ∫ over the unit disk of h(|β − β₀|) d²β, |β₀| = b, in polar coordinates about β₀: the disk's
/// edge at ρ(φ) = −b cosφ + √(1 − b² sin²φ); midpoint rule in φ (symmetric: [0, π], doubled).
fn over_disk(h: impl Fn(f64) -> f64 + Copy, b: f64, knee: f64, n_phi: usize) -> f64 {
    let mut sum = 0.0;
    for j in 0..n_phi {
        let phi = PI * (j as f64 + 0.5) / n_phi as f64;
        let rho = -b * phi.cos() + (1.0 - b * b * phi.sin().powi(2)).max(0.0).sqrt();
        sum += radial(h, rho, knee * 1e-5, 60);
    }
    2.0 * sum * PI / n_phi as f64
}

#[test]
fn tis_table_matches_closed_forms_and_a_quadrature_of_the_formula() {
    // g = 0: a flat lobe, TIS = πA/(B + 1) (the disk's area π) whatever the incidence.
    let flat = Table::new(&FLAT);
    for b in [0.0, 0.5, 0.99, 1.0] {
        let want = PI * FLAT.a / (FLAT.b + 1.0);
        assert!((flat.tis(b) - want).abs() < 1e-9 * want, "g = 0, |β₀| = {b}: {} vs {want}", flat.tis(b));
    }
    // g = 0 with a tiny B, and with B = 0: still πA/(B + 1).
    for b in [1e-10, 0.0] {
        let p = Abg { b, ..FLAT };
        let want = PI * p.a / (p.b + 1.0);
        let (table, bound) = (Table::new(&p).tis(0.7), p.normal_incidence_tis());
        assert!((table - want).abs() < 1e-9 * want && (bound - want).abs() < 1e-9 * want, "B = {b}: {table}, {bound}");
    }
    // g = 2 at normal incidence: πA ln(1 + 1/B).
    let want = PI * NARROW.a * (1.0 + 1.0 / NARROW.b).ln();
    let got = Table::new(&NARROW).tis(0.0);
    assert!((got - want).abs() < 1e-4 * want, "g = 2: {got} vs {want}");
    for p in [NARROW, BROAD, SHARP, FLAT] {
        let table = Table::new(&p);
        // The loader's bound (its own quadrature) is the table's value at normal incidence.
        let (t0, bound) = (table.tis(0.0), p.normal_incidence_tis());
        assert!((t0 - bound).abs() < 1e-4 * bound, "{p:?}: table {t0} vs normal_incidence_tis {bound}");
        // Off normal incidence, against the formula A/(B + r^g) integrated over the disk. The
        // table is the formula to 1e-4; the quadrature's own error is far below that.
        for b in [0.5, 0.9, 0.999, 1.0] {
            let quad = p.a * over_disk(|r| 1.0 / (p.b + r.powf(p.g)), b, p.knee(), 4000);
            let got = table.tis(b);
            assert!((got - quad).abs() < 2e-4 * quad, "{p:?}, |β₀| = {b}: table {got} vs quadrature {quad}");
            // Largest at normal incidence.
            assert!(got <= t0 * (1.0 + 1e-9), "{p:?}, |β₀| = {b}: {got} above TIS(0) = {t0}");
        }
    }
}

/// ∫ f(wo, wi) |cosθ_i| dω_i = ∫ f d²β over one side of the surface (`side` the sign of wi.z),
/// in polar coordinates about that side's specular β₀, by the f of the model itself.
fn scattered(b: &Bsdf<1>, wo: Vec3A, side: f32, beta0: [f64; 2], knee: f64) -> f64 {
    let centre = (beta0[0] * beta0[0] + beta0[1] * beta0[1]).sqrt();
    // Rotate so β₀ lies on +x, as `over_disk` assumes.
    let (c, s) = if centre > 0.0 { (beta0[0] / centre, beta0[1] / centre) } else { (1.0, 0.0) };
    let n_phi = 600;
    let mut sum = 0.0;
    for j in 0..2 * n_phi {
        let phi = PI * (j as f64 + 0.5) / n_phi as f64;
        let (sp, cp) = phi.sin_cos();
        let rho = -centre * cp + (1.0 - centre * centre * sp * sp).max(0.0).sqrt();
        let (dx, dy) = (c * cp - s * sp, s * cp + c * sp);
        let h = |r: f64| {
            let beta = [beta0[0] + r * dx, beta0[1] + r * dy];
            let z2 = 1.0 - beta[0] * beta[0] - beta[1] * beta[1];
            if !(z2 > 0.0) {
                return 0.0;
            }
            let wi = Vec3A::new(beta[0] as f32, beta[1] as f32, side * z2.sqrt() as f32);
            b.f(wo, wi, Mode::Importance).value().0[0]
        };
        sum += radial(h, rho * (1.0 - 1e-9), knee * 1e-5, 30);
    }
    sum * PI / n_phi as f64
}

#[test]
fn abg_conserves_energy_at_every_angle() {
    // What a surface returns, specular share plus the integral of its scattered f, is its
    // specular reflectance (ρ, the metal's Fresnel F(θ), 1 for glass, which divides it) at every
    // incidence: the scatter is taken from the specular share. The quadrature is of f, the
    // shares are the sampler's own lobe factors: this ties the model's f to its TIS table.
    for p in [NARROW, BROAD, SHARP, FLAT] {
        for deg in [0.0, 60.0, 89.0, 89.9] {
            let wo = at(deg, 20.0);
            let beta_r = [-wo.x as f64, -wo.y as f64];
            for (name, m, n) in [
                ("mirror ρ = 0.9", mirror(0.9, p), Vec3A::Z),
                ("metal from below", metal(p), -Vec3A::Z),
                ("glass from outside", glass(p), Vec3A::Z),
                ("glass from inside", glass(p), -Vec3A::Z),
            ] {
                let b = grey(&m, n);
                let specular = |lobe| b.event_terms(lobe, wo, wo, Mode::Importance).factor.0[0];
                let mut total = specular(Lobe::SpecularReflection) + scattered(&b, wo, 1.0, beta_r, p.knee());
                if let Material::Dielectric { .. } = m {
                    let (eta_o, eta_t) = if n.z > 0.0 { (1.0, 1.5) } else { (1.5, 1.0) };
                    let k = eta_o / eta_t;
                    let beta_t = [-k * wo.x as f64, -k * wo.y as f64];
                    if beta_t[0].hypot(beta_t[1]) < 1.0 {
                        total += specular(Lobe::SpecularTransmission) + scattered(&b, wo, -1.0, beta_t, p.knee());
                    }
                }
                let albedo = b.albedo(wo).0[0];
                assert!(
                    (total - albedo).abs() < 2e-4 * albedo,
                    "{name}, {p:?}, θ = {deg}°: returns {total}, its specular reflectance is {albedo}"
                );
            }
        }
    }
}

/// ∫ h(β) d²β over the disk |β − c| < r_max, in polar coordinates about c (where a lobe
/// peaks): `radial`'s log panels in r, midpoint rule in φ.
fn about(h: impl Fn([f64; 2]) -> f64 + Copy, c: [f64; 2], r_max: f64, knee: f64) -> f64 {
    let n_phi = 720;
    let mut sum = 0.0;
    for j in 0..n_phi {
        let (sp, cp) = (2.0 * PI * (j as f64 + 0.5) / n_phi as f64).sin_cos();
        sum += radial(|r| h([c[0] + r * cp, c[1] + r * sp]), r_max, knee * 1e-5, 400);
    }
    sum * 2.0 * PI / n_phi as f64
}

#[test]
fn camera_path_samples_average_to_the_whole_radiance_f_on_both_sides_of_glass() {
    // A camera path's sample weight f|cosθ_i|/pdf (0 for a lost sample) averages to what the
    // radiance f returns over every wi: the delta shares plus ∫ f d²β over both sides, here by
    // quadrature of the model's f about each side's peak (the other side's, −(η_o/η_t)β_o, lies
    // outside the disk from inside beyond the critical angle, 41.8°: light from outside still
    // scatters into wo there). This holds the sampler's support, not only its pdf: a sampler
    // that never refracted under total reflection would miss that light and fail by far.
    // Bound: |z| < 4 on 400 000 samples, z from the weights' own spread (they are bounded).
    for p in [NARROW, BROAD] {
        let m = glass(p);
        for (deg, inside) in [(0.0, false), (70.0, false), (30.0, true), (50.0, true), (75.0, true)] {
            let wo = at(deg, 75.0);
            let (n, k) = if inside { (-Vec3A::Z, 1.5) } else { (Vec3A::Z, 1.0 / 1.5) };
            let b = grey(&m, n);
            let f_on = |side: f32| {
                move |beta: [f64; 2]| {
                    let z2 = 1.0 - beta[0] * beta[0] - beta[1] * beta[1];
                    if !(z2 > 0.0) {
                        return 0.0;
                    }
                    let wi = Vec3A::new(beta[0] as f32, beta[1] as f32, side * z2.sqrt() as f32);
                    b.f(wo, wi, Mode::Radiance).value().0[0]
                }
            };
            let delta = |lobe| b.event_terms(lobe, wo, wo, Mode::Radiance).factor.0[0];
            let reflected = about(f_on(1.0), [-wo.x as f64, -wo.y as f64], 2.0, p.knee());
            let refracted = about(f_on(-1.0), [-k * wo.x as f64, -k * wo.y as f64], 3.0, p.knee() * k);
            let want = delta(Lobe::SpecularReflection) + delta(Lobe::SpecularTransmission) + reflected + refracted;

            let mut s = Sampler::for_batch(400 + deg as u64, inside as u64);
            let samples = 400_000;
            let (mut sum, mut sum2) = (0.0, 0.0);
            for _ in 0..samples {
                let w = b.sample(wo, Mode::Radiance, &mut s).map_or(0.0, |x| x.weight().0[0]);
                assert!(w.is_finite() && w >= 0.0, "weight {w}");
                sum += w;
                sum2 += w * w;
            }
            let mean = sum / samples as f64;
            let se = ((sum2 / samples as f64 - mean * mean) / samples as f64).sqrt();
            let z = (mean - want) / se;
            println!("{p:?}, θ = {deg}°, inside {inside}: mean weight {mean:.5} ± {se:.5}, quadrature {want:.5} (refracted scatter {refracted:.5}), z = {z:.2}");
            assert!(
                z.abs() < 4.0,
                "{p:?}, θ = {deg}°, inside {inside}: samples average {mean} ± {se}, f integrates to {want}"
            );
        }
    }
}

/// Pearson χ² of `b.sample` from `wo` against `b.pdf`, in direction-cosine bins about each side's
/// specular β₀ (`centres`: reflection side, then transmission side if any): a core disk of radius
/// knee/8, then 24 log-spaced annuli to 2 (the last out to the disk's far edge), each cut into 16 sectors; plus one cell for the
/// specular (delta) share and lost samples, expected 1 − ∫pdf. A bin's expected count is N ∫pdf
/// d²β over it, pdf per d²β being pdf/|cosθ_i|, by a 12 × 12 midpoint rule in (r, φ).
/// Returns (χ², degrees of freedom, upper-tail probability, ∫pdf).
fn chi2_beta(
    b: &Bsdf<1>,
    judge: &Bsdf<1>,
    wo: Vec3A,
    mode: Mode,
    centres: &[[f64; 2]],
    knee: f64,
    seed: u64,
) -> (f64, f64, f64, f64) {
    const SAMPLES: usize = 200_000;
    const RINGS: usize = 24;
    const SECTORS: usize = 16;
    const SUB: usize = 12;
    let r_core = knee / 8.0;
    let ratio = (2.0 / r_core).ln() / RINGS as f64;
    let edge = |k: usize| if k == 0 { 0.0 } else { r_core * ((k - 1) as f64 * ratio).exp() };
    let per_side = (RINGS + 1) * SECTORS;
    let cells = centres.len() * per_side + 1;
    let side_sign = |k: usize| if k == 0 { 1.0f32 } else { -1.0 };
    let bin = |wi: Vec3A| -> usize {
        let k = if wi.z > 0.0 { 0 } else { 1 };
        if k >= centres.len() {
            return cells - 1;
        }
        let (dx, dy) = (wi.x as f64 - centres[k][0], wi.y as f64 - centres[k][1]);
        let r = dx.hypot(dy);
        let ring = if r < r_core { 0 } else { (1 + ((r / r_core).ln() / ratio) as usize).min(RINGS) };
        let sector = ((dy.atan2(dx).rem_euclid(2.0 * PI) / (2.0 * PI) * SECTORS as f64) as usize).min(SECTORS - 1);
        k * per_side + ring * SECTORS + sector
    };
    let mut s = Sampler::for_batch(seed, 0);
    let mut observed = vec![0.0f64; cells];
    for _ in 0..SAMPLES {
        match b.sample(wo, mode, &mut s).filter(|x| !x.lobe.is_delta()) {
            Some(x) => observed[bin(x.wi)] += 1.0,
            None => observed[cells - 1] += 1.0,
        }
    }
    let mut expected = vec![0.0f64; cells];
    for (k, c) in centres.iter().enumerate() {
        for ring in 0..=RINGS {
            // The last ring reaches every β of the disk (|c| < 2 from a centre outside it).
            let (r0, r1) = (edge(ring), if ring == RINGS { 3.0 } else { edge(ring + 1) });
            for sector in 0..SECTORS {
                let mut integral = 0.0;
                for q in 0..SUB {
                    let phi = 2.0 * PI * (sector as f64 + (q as f64 + 0.5) / SUB as f64) / SECTORS as f64;
                    let (sin, cos) = phi.sin_cos();
                    // The ring cut to the disk |c + r·e| < 1 along this φ, r in (near, far) (a
                    // centre outside the disk, a camera path's light beyond the critical
                    // angle, has near > 0): the pdf is 0 beyond, and a midpoint rule across
                    // that step would be off.
                    let along = c[0] * cos + c[1] * sin;
                    let disc = along * along + 1.0 - c[0] * c[0] - c[1] * c[1];
                    if !(disc > 0.0) {
                        continue;
                    }
                    let (near, far) = (-along - disc.sqrt(), -along + disc.sqrt());
                    let (bottom, top) = (r0.max(near), r1.min(far));
                    if !(top > bottom) {
                        continue;
                    }
                    let dr = (top - bottom) / SUB as f64;
                    for a in 0..SUB {
                        let r = bottom + (a as f64 + 0.5) * dr;
                        let beta = [c[0] + r * cos, c[1] + r * sin];
                        let z2 = 1.0 - beta[0] * beta[0] - beta[1] * beta[1];
                        if !(z2 > 0.0) {
                            continue;
                        }
                        let wi = Vec3A::new(beta[0] as f32, beta[1] as f32, side_sign(k) * z2.sqrt() as f32);
                        integral += judge.pdf(wo, wi, mode) / (wi.z as f64).abs() * r * dr;
                    }
                }
                expected[k * per_side + ring * SECTORS + sector] = integral * 2.0 * PI / (SECTORS * SUB) as f64;
            }
        }
    }
    let total: f64 = expected.iter().sum();
    expected[cells - 1] = (1.0 - total).max(0.0);
    let common::Pearson { mut stat, cells: mut used, pooled_observed: pooled_o, pooled_expected: pooled_e } =
        common::pearson(&observed, &expected, SAMPLES);
    // The pooled cell counts even when it expects little, so that samples where the pdf expects
    // none fail the test.
    if pooled_e > 0.0 {
        stat += (pooled_o - pooled_e) * (pooled_o - pooled_e) / pooled_e.max(1.0);
        used += 1;
    } else {
        assert!(pooled_o == 0.0, "{pooled_o} samples where the pdf expects none");
    }
    let dof = (used - 1) as f64;
    (stat, dof, chi2_tail(stat, dof), total)
}

fn assert_samples_match(what: &str, b: &Bsdf<1>, wo: Vec3A, mode: Mode, centres: &[[f64; 2]], knee: f64, seed: u64) {
    let (stat, dof, p, total) = chi2_beta(b, b, wo, mode, centres, knee, seed);
    println!("{what}: χ² = {stat:.1}, {dof} dof, p = {p:.3}, ∫pdf = {total:.6}");
    assert!(total <= 1.0 + 1e-3, "{what}: the pdf integrates to {total} > 1");
    assert!(p > 1e-3, "{what}: χ² = {stat:.1} for {dof} degrees of freedom, p = {p:.2e}");
}

#[test]
fn abg_samples_match_their_pdf_on_mirrors_metals_and_both_sides_of_glass() {
    let mut seed = 200;
    for p in [NARROW, BROAD, SHARP, FLAT] {
        for deg in [0.0, 60.0, 89.5] {
            let wo = at(deg, 30.0);
            let centre = [-wo.x as f64, -wo.y as f64];
            seed += 1;
            let m = mirror(1.0, p);
            assert_samples_match(
                &format!("mirror {p:?}, θ = {deg}°"),
                &grey(&m, Vec3A::Z),
                wo,
                Mode::Importance,
                &[centre],
                p.knee(),
                seed,
            );
        }
    }
    let wo = at(60.0, -40.0);
    let m = metal(NARROW);
    for mode in [Mode::Importance, Mode::Radiance] {
        seed += 1;
        let what = format!("metal from below, {mode:?}");
        assert_samples_match(
            &what,
            &grey(&m, -Vec3A::Z),
            wo,
            mode,
            &[[-wo.x as f64, -wo.y as f64]],
            NARROW.knee(),
            seed,
        );
    }
    // Glass: from outside, and from inside up to and beyond the critical angle (41.8°), where
    // a particle has no transmitted side but a camera path does: light from outside scatters
    // into wo there, and its lobe's peak, β = −1.5·β_o, lies outside the disk.
    for p in [NARROW, BROAD] {
        let m = glass(p);
        for (deg, inside) in [(0.0, false), (85.0, false), (40.0, true), (60.0, true), (80.0, true)] {
            let wo = at(deg, 75.0);
            let (n, k) = if inside { (-Vec3A::Z, 1.5) } else { (Vec3A::Z, 1.0 / 1.5) };
            let beta_t = [-k * wo.x as f64, -k * wo.y as f64];
            for mode in [Mode::Importance, Mode::Radiance] {
                let mut centres = vec![[-wo.x as f64, -wo.y as f64]];
                if beta_t[0].hypot(beta_t[1]) < 1.0 || mode == Mode::Radiance {
                    centres.push(beta_t);
                }
                seed += 1;
                let what = format!("glass {p:?}, θ = {deg}°, inside {inside}, {mode:?}");
                assert_samples_match(&what, &grey(&m, n), wo, mode, &centres, p.knee(), seed);
            }
        }
    }
}

#[test]
fn the_direction_cosine_harness_rejects_a_neighbouring_lobe() {
    // Samples of B = 0.01 judged against the pdf of B = 0.0125: the lobe's width and its TIS differ.
    let sampled = mirror(1.0, NARROW);
    let judged = mirror(1.0, Abg { b: 0.0125, ..NARROW });
    let wo = at(30.0, 0.0);
    let (_, _, p, _) = chi2_beta(
        &grey(&sampled, Vec3A::Z),
        &grey(&judged, Vec3A::Z),
        wo,
        Mode::Importance,
        &[[-wo.x as f64, -wo.y as f64]],
        NARROW.knee(),
        300,
    );
    assert!(p < 1e-9, "p = {p}");
}

#[test]
fn every_sample_weighs_the_specular_reflectance() {
    // Exact sampling: a particle that survived the albedo keeps its weight (no second absorption).
    let mut s = Sampler::for_batch(9, 0);
    for m in [mirror(0.8, NARROW), metal(BROAD), glass(NARROW)] {
        let b = grey(&m, Vec3A::Z);
        assert!(b.samples_exactly() && b.is_connectible());
        for deg in [0.0, 50.0, 88.0] {
            let wo = at(deg, 10.0);
            let albedo = b.albedo(wo).0[0];
            for _ in 0..20_000 {
                let x = b.sample(wo, Mode::Importance, &mut s).expect("an ABg sample");
                let w = x.weight().0[0];
                assert!((w - albedo).abs() < 1e-12 * albedo, "{m:?}, θ = {deg}°: weight {w}, albedo {albedo}");
                if !x.lobe.is_delta() {
                    let f = b.f(wo, x.wi, Mode::Importance).value().0[0];
                    let via_f = f * (x.wi.z as f64).abs() / x.pdf;
                    // f from the f32 direction, the pdf from its f64 β.
                    assert!((via_f - albedo).abs() < 1e-6 * albedo, "f|cos|/pdf = {via_f}, albedo {albedo}");
                }
            }
        }
    }
}

/// A collimated beam of 10 W straight down onto a 4 m plate of `material` at the origin, the
/// beam's 0.1 m source 50 m above it (it takes back 4·10⁻⁶ sr, inside the first band), and a
/// far field of 2° bands of γ from straight up.
fn beam_on_plate(material: &str) -> String {
    format!(
        r#"[materials.finish]
{material}

[[surfaces]]
name = "plate"
material = "finish"
shape = {{ type = "quad", corners = [[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]] }}

[[lights]]
name = "beam"
shape = {{ type = "quad", corners = [[-0.05, 50, -0.05], [0.05, 50, -0.05], [0.05, 50, 0.05], [-0.05, 50, 0.05]] }}
distribution = "collimated"
power_w = 10

[[detectors]]
type = "farfield"
name = "far"
resolution = [90, 1]
nadir = [0, 1, 0]
"#
    )
}

#[test]
fn particle_tracer_far_field_of_an_abg_mirror_and_glass_is_the_closed_form() {
    // At normal incidence β₀ = 0 and s = |β|² = sin²γ, so the power scattered into the band
    // [γ₀, γ₁] is R·πA ∫ ds/(B + s^{g/2}) over [sin²γ₀, sin²γ₁]: for g = 2,
    // πA ln((B + s₁)/(B + s₀)); for g = 1, 2πA [u − B ln(B + u)] from u₀ = sinγ₀ to u₁. A band's
    // intensity is that power (lm) over its solid angle 2π(cosγ₀ − cosγ₁). The glass is a slab
    // so absorbing (10⁶ m⁻¹) that all refracted light ends in it: above it is the reflected
    // share R₀ = 0.04 alone, and the slab absorbs 1 − R₀. The first band holds the specular
    // beam and is left out.
    let band_power = |p: Abg, g0: f64, g1: f64| {
        let (u0, u1) = (g0.to_radians().sin().abs(), g1.to_radians().sin().abs());
        let (u0, u1) = (u0.min(u1), u0.max(u1));
        if p.g == 2.0 {
            PI * p.a * ((p.b + u1 * u1) / (p.b + u0 * u0)).ln()
        } else {
            assert_eq!(p.g, 1.0);
            2.0 * PI * p.a * ((u1 - u0) - p.b * ((p.b + u1) / (p.b + u0)).ln())
        }
    };
    let r0 = 0.04; // ((1.5 − 1)/(1.5 + 1))²
    let cases = [
        ("mirror", NARROW, "type = \"mirror\"\nscatter = { abg = [0.05, 0.01, 2] }", 1.0, false),
        (
            "glass",
            BROAD,
            "type = \"dielectric\"\nior = 1.5\nabsorption_per_m = 1e6\nscatter = { abg = [0.2, 0.5, 1] }",
            r0,
            true,
        ),
    ];
    for (name, p, material, up, slab) in cases {
        let mut toml = beam_on_plate(material);
        if slab {
            toml = toml.replace(
                "{ type = \"quad\", corners = [[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]] }",
                "{ type = \"box\", min = [-2, -1, -2], max = [2, 0, 2] }",
            );
        }
        for (transport, seed) in [(common::EXPECTED, 21), (common::ANALOG, 22)] {
            let (f, e) = common::run_farfield_with(&toml, 1_000_000, seed, transport);
            let lm = f.emitted_lm;
            let expected = |g0: f64, g1: f64, _c: f64| {
                let share = if g1 <= 90.0 { up } else { 0.0 };
                let solid_angle = 2.0 * PI * (g0.to_radians().cos() - g1.to_radians().cos());
                lm * share * band_power(p, g0, g1) / solid_angle
            };
            let (chi2, k, worst) = common::farfield_z(&e, expected, |i, _| i == 0);
            let (lo, hi) = common::chi_square_bounds(k as f64);
            let what = format!("{name}, {:?}", transport.estimator);
            println!("{what}: Σz² = {chi2:.1} over {k} bands, worst |z| {worst:.2}");
            assert!(k >= 40, "{what}: only {k} bands with light");
            assert!(
                chi2 > lo && chi2 < hi && worst < 4.5,
                "{what}: Σz² {chi2} over {k} bands ({lo}–{hi}), worst |z| {worst}"
            );
            let l = &f.ledger;
            let sum = l.absorbed_w + l.escaped_w + l.truncated_w;
            assert!((sum - l.emitted_w).abs() < 1e-9 * l.emitted_w, "{what}: ledger {l:?}");
            let plate = common::surface(&f, "plate");
            let absorbed = 10.0 * (1.0 - up);
            if plate.absorbed_w_stderr > 0.0 {
                common::assert_z(&what, plate.absorbed_w, absorbed, plate.absorbed_w_stderr, 4.0);
            } else {
                // Expected values: every photon leaves exactly 1 − R₀ (or nothing) behind.
                assert!((plate.absorbed_w - absorbed).abs() < 1e-9, "{what}: absorbed {} W", plate.absorbed_w);
            }
        }
    }
}

#[test]
fn radiance_f_is_the_importance_f_of_the_reversed_path_and_weights_follow_it() {
    // Both modes evaluate one physical BSDF f(light's direction → onward): a camera path's
    // f(wo, wi) is the light's f(wi → wo), which a particle arriving from wi evaluates as
    // f(wi, wo). The model need not be reciprocal (R is taken at the light's incidence, and a
    // refracted lobe lies in the β of the side it leaves into), but the modes must agree.
    let mut s = Sampler::for_batch(17, 0);
    for m in [metal(NARROW), glass(NARROW), glass(BROAD)] {
        for n in [Vec3A::Z, -Vec3A::Z] {
            let b = grey(&m, n);
            let mut compared = 0;
            for _ in 0..20_000 {
                let wo = photon::sampling::uniform_sphere(s.uniform_f32(), s.uniform_f32());
                let wi = photon::sampling::uniform_sphere(s.uniform_f32(), s.uniform_f32());
                let radiance = b.f(wo, wi, Mode::Radiance).value().0[0];
                let importance = b.f(wi, wo, Mode::Importance).value().0[0];
                assert!(
                    (radiance - importance).abs() <= 1e-9 * radiance.max(importance),
                    "{m:?}, n = {n}: f(wo, wi, radiance) = {radiance}, f(wi, wo, importance) = {importance}"
                );
                compared += (radiance > 0.0) as usize;
                // A camera path's scattered sample weighs f|cos|/pdf of the radiance f.
                let Some(x) = b.sample(wo, Mode::Radiance, &mut s) else { continue };
                if !x.lobe.is_delta() {
                    let via_f = b.f(wo, x.wi, Mode::Radiance).value().0[0] * (x.wi.dot(n).abs() as f64) / x.pdf;
                    let w = x.weight().0[0];
                    assert!((w - via_f).abs() <= 1e-5 * via_f.max(1e-3), "{m:?}: weight {w}, f|cos|/pdf {via_f}");
                }
            }
            assert!(compared > 5000, "{m:?}: only {compared} pairs with f > 0");
        }
    }
}

#[test]
fn extreme_lobes_build_finite_tables_and_sample_finite_directions() {
    // The loader's extremes: a lobe narrower than any direction's precision with a peak of
    // 10³⁰⁰, a flat lobe with B = 0, a cusp (g = 0.2) on a tiny B, a huge B. Each table must
    // build (a steep cell once overflowed its slope and made the TIS quadrature recurse without
    // end), and every sample be a unit vector carrying the mirror's ρ.
    let mut s = Sampler::for_batch(23, 0);
    for p in [
        Abg { a: 1e-300, b: 1e-300, g: 8.0 },
        Abg { a: 0.3, b: 0.0, g: 0.0 },
        Abg { a: 0.05, b: 1e-12, g: 0.2 },
        Abg { a: 1e-3, b: 1e100, g: 0.5 },
    ] {
        let table = Table::new(&p);
        for b in [0.0, 0.5, 0.999, 1.0] {
            let t = table.tis(b);
            assert!(t.is_finite() && (0.0..=1.0).contains(&t), "{p:?}: TIS({b}) = {t}");
        }
        let b = grey(&mirror(0.7, p), Vec3A::Z);
        for deg in [0.0, 70.0, 89.9] {
            let wo = at(deg, 0.0);
            for _ in 0..2000 {
                let x = b.sample(wo, Mode::Importance, &mut s).expect("a sample");
                assert!((x.wi.length() - 1.0).abs() < 1e-5 && x.wi.z >= 0.0, "{p:?}: {:?}", x.wi);
                assert!((x.weight().0[0] - 0.7).abs() < 1e-12 && x.pdf.is_finite(), "{p:?}: {x:?}");
            }
        }
    }
}
