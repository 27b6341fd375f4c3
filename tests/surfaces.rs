//! Surface models against closed forms and against numerical integration of their own BSDF:
//! the conductor's Fresnel term, reciprocity, the white furnace (a rough metal of reflectance 1
//! loses exactly the single-scattering energy its BSDF integrates to, and never gains any), the
//! smooth limit, and the particle tracer's ledger on those surfaces. χ² tests of the samplers
//! are in tests/chi2.rs.
//!
//! Statistical bounds: each comparison of a Monte Carlo mean with an independent number is a
//! z-score with the sample's own standard error, |z| < 4 (false failure 6e-5 per comparison at
//! a fixed seed); a quadrature's error, bounded by halving its grid, is kept below the Monte
//! Carlo error and added to it.

mod common;
use common::{assert_z, run, run_with, surface, ANALOG};

use glam::Vec3A;
use photon::bsdf::{fresnel_conductor, Bsdf, Mode, Prepared};
use photon::sampling::Sampler;
use photon::scene::Material;
use photon::spectrum::Spectrum;
use std::f64::consts::PI;

/// A material's run-wide constants, kept for the test's lifetime.
fn prepared(m: &Material) -> &'static Prepared {
    Box::leak(Box::new(Prepared::of(m, (400.0, 700.0))))
}

fn conductor(n: f64, k: f64, alpha: impl Into<photon::scene::Roughness>) -> Material {
    Material::Conductor {
        eta: Spectrum::Constant(n),
        k: Spectrum::Constant(k),
        specular_reflectance: Spectrum::Constant(1.0),
        roughness: alpha.into(),
        scatter: None,
    }
}

fn grey(m: &Material) -> Bsdf<'static, 1> {
    Bsdf::<1>::new::<false>(m, prepared(m), &[f64::NAN], Vec3A::Z, || Vec3A::ZERO)
}

fn at(theta_deg: f64, phi_deg: f64) -> Vec3A {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    Vec3A::new((st * cp) as f32, (st * sp) as f32, ct as f32)
}

/// ∫ f(wo, wi) cosθ_i dωi, by the midpoint rule over the sphere in polar coordinates about the
/// mirror direction of `wo` (where a narrow lobe peaks), with 1 − cosθ' = 2s² so the grid is
/// densest at the pole.
fn directional_albedo(b: &Bsdf<1>, wo: Vec3A, n_s: usize, n_phi: usize) -> f64 {
    let mirror = Vec3A::new(-wo.x, -wo.y, wo.z);
    lobe_integral(b, wo, mirror, Mode::Importance, n_s, n_phi, |wi| wi.z * wo.z > 0.0)
}

/// ∫ f(wo, wi) |cosθ_i| dωi over the directions `keep` accepts, in polar coordinates about `axis`.
fn lobe_integral(
    b: &Bsdf<1>,
    wo: Vec3A,
    axis: Vec3A,
    mode: Mode,
    n_s: usize,
    n_phi: usize,
    keep: impl Fn(Vec3A) -> bool,
) -> f64 {
    let frame = photon::bsdf::microfacet::Frame::new(axis, Vec3A::X);
    let mut sum = 0.0;
    for i in 0..n_s {
        let s = (i as f64 + 0.5) / n_s as f64;
        let c = 1.0 - 2.0 * s * s;
        let dc = 4.0 * s / n_s as f64;
        let st = (1.0 - c * c).max(0.0).sqrt();
        for j in 0..n_phi {
            let phi = 2.0 * PI * (j as f64 + 0.5) / n_phi as f64;
            let wi = frame.to_world(Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, c as f32));
            if keep(wi) {
                sum += b.f(wo, wi, mode).value().0[0] * (wi.z as f64).abs() * dc * 2.0 * PI / n_phi as f64;
            }
        }
    }
    sum
}

/// Mean and standard error of the sample weight f|cos|/pdf (0 for a lost sample), and its largest value.
fn sampled_albedo(b: &Bsdf<1>, wo: Vec3A, n: usize, seed: u64) -> (f64, f64, f64) {
    let mut s = Sampler::for_batch(seed, 0);
    let (mut sum, mut sum2, mut max) = (0.0, 0.0, 0.0f64);
    for _ in 0..n {
        let w = b.sample(wo, Mode::Importance, &mut s).map_or(0.0, |x| x.weight().0[0]);
        sum += w;
        sum2 += w * w;
        max = max.max(w);
    }
    let mean = sum / n as f64;
    (mean, ((sum2 / n as f64 - mean * mean) / (n as f64 - 1.0)).sqrt(), max)
}

#[test]
fn a_conductor_of_imaginary_index_reflects_everything_at_every_angle() {
    for deg in [0.0f64, 30.0, 60.0, 85.0, 89.9] {
        let r = fresnel_conductor(deg.to_radians().cos(), 0.0, 5.0);
        assert!((r - 1.0).abs() < 1e-12, "{deg}°: R = {r}");
    }
}

#[test]
fn rough_conductor_is_reciprocal() {
    let mut s = Sampler::for_batch(5, 0);
    for alpha in [0.05, 0.3, 0.8] {
        let b = grey(&conductor(0.2, 3.0, alpha));
        for _ in 0..2000 {
            let wo = photon::sampling::uniform_hemisphere(Vec3A::Z, s.uniform_f32(), s.uniform_f32());
            let wi = photon::sampling::uniform_hemisphere(Vec3A::Z, s.uniform_f32(), s.uniform_f32());
            let (a, c) = (b.f(wo, wi, Mode::Importance).value().0[0], b.f(wi, wo, Mode::Importance).value().0[0]);
            assert!((a - c).abs() <= 1e-5 * a.max(c) + 1e-12, "α = {alpha}: f(wo, wi) = {a}, f(wi, wo) = {c}");
            // From below, the same (both sides reflect alike).
            let (ob, ib) = (-wo, -wi);
            let d = b.f(ob, ib, Mode::Importance).value().0[0];
            assert!((a - d).abs() <= 1e-5 * a + 1e-12, "α = {alpha}: from below {d} vs {a}");
        }
    }
}

#[test]
fn white_furnace_a_rough_mirror_loses_exactly_what_its_bsdf_integrates_to() {
    // F = 1 (n = 0, k = 5): what the sampler's mean weight E(ωo) falls short of 1 is the energy
    // single-scattering GGX does not return; the quadrature of the same f must agree, and no
    // sample may carry more than it received.
    let mut seed = 100;
    for alpha in [0.05, 0.2, 0.5, 0.9] {
        let b = grey(&conductor(0.0, 5.0, alpha));
        for deg in [0.0, 40.0, 70.0, 85.0] {
            let wo = at(deg, 20.0);
            seed += 1;
            let (mc, se, max) = sampled_albedo(&b, wo, 400_000, seed);
            let quad = directional_albedo(&b, wo, 3000, 512);
            let coarse = directional_albedo(&b, wo, 1500, 256);
            // The horizon cuts a grazing lobe: the rule converges as the step there, so the
            // halved grid's difference bounds its error, which joins the z-score's.
            let quad_err = (quad - coarse).abs();
            assert!(quad_err < se, "α = {alpha}, θ = {deg}°: quadrature error {quad_err} not below {se}");
            println!(
                "α = {alpha}, θ_o = {deg}°: E = {mc:.5} ± {se:.5} (sampled), {quad:.5} ± {quad_err:.5} (quadrature)"
            );
            assert_z(&format!("E(α = {alpha}, θ = {deg}°)"), mc, quad, se.hypot(quad_err), 4.0);
            assert!(max <= 1.0 + 1e-6, "α = {alpha}, θ = {deg}°: a sample weight {max} > 1");
            assert!(quad <= 1.0 + 1e-4, "α = {alpha}, θ = {deg}°: E = {quad} > 1");
        }
    }
}

#[test]
fn roughness_to_zero_converges_to_the_smooth_metal() {
    let (n, k) = (1.0972, 6.7943); // aluminium near 550 nm
    let smooth = grey(&conductor(n, k, 0.0));
    let rough = grey(&conductor(n, k, 1e-3));
    for deg in [0.0, 30.0, 60.0, 80.0] {
        let wo = at(deg, 0.0);
        let f_smooth = smooth.albedo(wo).0[0];
        assert!((f_smooth - fresnel_conductor(wo.z as f64, n, k)).abs() < 1e-12);
        let (mc, _, _) = sampled_albedo(&rough, wo, 20_000, 7);
        assert!((mc - f_smooth).abs() < 2e-3, "θ = {deg}°: α = 0.001 reflects {mc}, smooth {f_smooth}");
        // The lobe closes on the mirror direction: at normal incidence the visible normals have
        // P(tanθ_m < t) = t²/(α² + t²), so 95 % of reflections lie within 0.5° (θ_m = 0.25°);
        // GGX's long tail puts a few farther out, at any α.
        let mirror = Vec3A::new(-wo.x, -wo.y, wo.z);
        let mut s = Sampler::for_batch(8, 0);
        let near = (0..2000)
            .filter(|_| {
                rough.sample(wo, Mode::Importance, &mut s).is_some_and(|x| x.wi.dot(mirror) > 0.5f32.to_radians().cos())
            })
            .count();
        assert!(near > 1800, "θ = {deg}°: only {near} of 2000 reflections within 0.5° of the mirror direction");
    }
}

#[test]
fn bundled_aluminium_reflects_its_closed_form_at_normal_incidence() {
    // R = ((n − 1)² + k²)/((n + 1)² + k²) from the table at 550 nm; shared/data/materials/SOURCES.md
    // gives ≈ 0.91–0.92 for aluminium.
    let s = common::scene(&common::BASE.replace(
        "[materials.white]\ntype = \"lambertian\"\nreflectance = 0.5",
        "[materials.white]\ntype = \"conductor\"\nmetal = \"Al\"",
    ));
    let m = s.material_of(0);
    let Material::Conductor { eta, k, .. } = m else { panic!("{m:?}") };
    let (n, k) = (eta.eval(550.0), k.eval(550.0));
    let closed = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
    let r = Bsdf::<1>::new::<true>(m, prepared(m), &[550.0], Vec3A::Z, || Vec3A::ZERO).albedo(Vec3A::Z).0[0];
    assert!((r - closed).abs() < 1e-12, "{r} vs {closed}");
    assert!((r - 0.92).abs() < 0.01, "Al at 550 nm: R = {r}");
}

/// A collimated beam straight down onto a metal plate; what the plate does not reflect it absorbs.
fn beam_on_plate(material: &str) -> String {
    format!(
        r#"[materials.metal]
{material}

[[surfaces]]
name = "plate"
material = "metal"
shape = {{ type = "quad", corners = [[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]] }}

[[lights]]
name = "beam"
shape = {{ type = "quad", corners = [[-0.5, 1, -0.5], [0.5, 1, -0.5], [0.5, 1, 0.5], [-0.5, 1, 0.5]] }}
distribution = "collimated"
power_w = 10
"#
    )
}

#[test]
fn particle_tracer_on_metal_plates_matches_fresnel_and_the_quadrature() {
    let (n, k) = (1.0972, 6.7943);
    // Smooth: every photon deposits 1 − R(0) (expected value: exactly; analog: binomially).
    let r0 = fresnel_conductor(1.0, n, k);
    let smooth = beam_on_plate(&format!("type = \"conductor\"\neta = {n}\nk = {k}"));
    let f = run(&smooth, 200_000, 1);
    let plate = surface(&f, "plate");
    assert!((plate.absorbed_w - 10.0 * (1.0 - r0)).abs() < 1e-9, "{} vs {}", plate.absorbed_w, 10.0 * (1.0 - r0));
    let f = run_with(&smooth, 200_000, 2, ANALOG);
    let plate = surface(&f, "plate");
    assert_z("smooth, analog", plate.absorbed_w, 10.0 * (1.0 - r0), plate.absorbed_w_stderr, 4.0);
    // Rough: the plate absorbs 1 − E(0), E from the quadrature of the BSDF (an independent number).
    for alpha in [0.2, 0.6] {
        let e0 = directional_albedo(&grey(&conductor(n, k, alpha)), Vec3A::Z, 3000, 512);
        let rough = beam_on_plate(&format!("type = \"conductor\"\neta = {n}\nk = {k}\nroughness = {alpha}"));
        for (transport, seed) in [(common::EXPECTED, 3), (ANALOG, 4)] {
            let f = run_with(&rough, 400_000, seed, transport);
            let plate = surface(&f, "plate");
            let what = format!("α = {alpha}, {:?}", transport.estimator);
            assert_z(&what, plate.absorbed_w, 10.0 * (1.0 - e0), plate.absorbed_w_stderr, 4.0);
            let l = &f.ledger;
            let sum = l.absorbed_w + l.escaped_w + l.truncated_w;
            assert!((sum - l.emitted_w).abs() < 1e-9 * l.emitted_w, "{what}: ledger {l:?}");
        }
    }
}

#[test]
fn the_ledger_is_exact_in_the_cornell_box_with_metal_blocks() {
    let toml = common::bundled_toml("cornell_metals.toml");
    for (transport, seed) in [(common::EXPECTED, 1), (ANALOG, 2)] {
        let f = run_with(&toml, 100_000, seed, transport);
        let l = &f.ledger;
        let sum = l.absorbed_w + l.escaped_w + l.truncated_w;
        assert!((sum - l.emitted_w).abs() < 1e-9 * l.emitted_w, "{:?}: ledger {l:?}", transport.estimator);
        let block = surface(&f, "tall_block");
        assert!(block.absorbed_w > 0.0 && block.incident_w > block.absorbed_w, "{block:?}");
    }
}

fn rough_glass(alpha: impl Into<photon::scene::Roughness>) -> Material {
    Material::Dielectric {
        ior: Spectrum::Constant(1.5),
        outside_ior: Spectrum::Constant(1.0),
        absorption_per_m: None,
        roughness: alpha.into(),
        scatter: None,
    }
}

#[test]
fn rough_dielectric_is_reciprocal_in_reflection_and_in_the_generalised_sense_in_refraction() {
    // Reflection: f(wo, wi) = f(wi, wo). Refraction between indices η_o (wo's side) and η_i:
    // f_rad(wo, wi)/η_o² = f_rad(wi, wo)/η_i² (Veach 1997, §5.2), and the importance-mode BSDF
    // is the adjoint, f_imp(wo, wi) = f_rad(wi, wo).
    let mut s = Sampler::for_batch(9, 0);
    for alpha in [0.1, 0.4] {
        let b = grey(&rough_glass(alpha));
        let mut checked = 0;
        for _ in 0..4000 {
            let wo = photon::sampling::uniform_sphere(s.uniform_f32(), s.uniform_f32());
            let wi = photon::sampling::uniform_sphere(s.uniform_f32(), s.uniform_f32());
            let f = |a: Vec3A, c: Vec3A, m: Mode| b.f(a, c, m).value().0[0];
            let (fr, rf) = (f(wo, wi, Mode::Radiance), f(wi, wo, Mode::Radiance));
            if fr == 0.0 && rf == 0.0 {
                continue;
            }
            // Directions are f32: where one side grazes its microfacet (cosine below 0.02, near
            // the critical angle on the other side), 1 − R comes from a difference of nearly equal
            // numbers and keeps only a few digits; those pairs are skipped.
            let etap = if wo.z > 0.0 { 1.5f32 } else { 1.0 / 1.5 };
            let m = if wo.z * wi.z > 0.0 { (wo + wi).normalize() } else { (wo + wi * etap).normalize() };
            if wo.dot(m).abs() < 0.02 || wi.dot(m).abs() < 0.02 {
                continue;
            }
            checked += 1;
            let tol = |x: f64| 1e-3 * x + 1e-9;
            if wo.z * wi.z > 0.0 {
                assert!((fr - rf).abs() <= tol(fr.max(rf)), "α = {alpha}: reflection {fr} vs {rf}");
            } else {
                let (eta_o, eta_i) = if wo.z > 0.0 { (1.0, 1.5) } else { (1.5, 1.0) };
                assert!((fr / (eta_o * eta_o) - rf / (eta_i * eta_i)).abs() <= tol(fr), "α = {alpha}: {fr} vs {rf}");
            }
            let fi = f(wo, wi, Mode::Importance);
            assert!((fi - rf).abs() <= tol(fi.max(rf)), "α = {alpha}: importance {fi} vs adjoint {rf}");
        }
        assert!(checked > 500, "only {checked} pairs with f > 0");
    }
}

#[test]
fn rough_dielectric_white_furnace_reflection_and_refraction_lose_only_what_the_bsdf_integrates_to() {
    // Power (importance mode): the sampled mean weight E(ωo) equals ∫ f |cosθ_i| over both
    // hemispheres (reflection about the mirror direction, refraction about the refracted one),
    // E ≤ 1, and no sample carries more than it received. From outside and from inside (total
    // internal reflection beyond 41.8°).
    let mut seed = 200;
    for alpha in [0.1, 0.3, 0.7] {
        let b = grey(&rough_glass(alpha));
        for (deg, side) in [(0.0f64, 1.0f32), (45.0, 1.0), (80.0, 1.0), (30.0, -1.0), (60.0, -1.0)] {
            let (st, ct) = deg.to_radians().sin_cos();
            let wo = Vec3A::new(st as f32, 0.0, side * ct as f32);
            seed += 1;
            let (mc, se, max) = sampled_albedo(&b, wo, 400_000, seed);
            let (eta_o, eta_t) = if side > 0.0 { (1.0, 1.5) } else { (1.5, 1.0) };
            // The smooth refraction direction, or straight through beyond the critical angle.
            let sin_t = eta_o / eta_t * st;
            let refracted = if sin_t < 1.0 {
                Vec3A::new((-sin_t) as f32, 0.0, -side * (1.0 - sin_t * sin_t).sqrt() as f32)
            } else {
                -Vec3A::new(0.0, 0.0, side)
            };
            let mirror = Vec3A::new(-wo.x, -wo.y, wo.z);
            let quad = |n_s, n_phi| {
                lobe_integral(&b, wo, mirror, Mode::Importance, n_s, n_phi, |wi| wi.z * wo.z > 0.0)
                    + lobe_integral(&b, wo, refracted, Mode::Importance, n_s, n_phi, |wi| wi.z * wo.z < 0.0)
            };
            let (fine, coarse) = (quad(3000, 512), quad(1500, 256));
            let quad_err = (fine - coarse).abs();
            println!(
                "α = {alpha}, θ_o = {deg}° side {side}: E = {mc:.5} ± {se:.5} (sampled), {fine:.5} ± {quad_err:.5}"
            );
            // A narrow refracted lobe converges slowly (as h²: 3.8e-4, 9.6e-5, 2.4e-5 at α = 0.1
            // for grids doubling from 750 × 128); its error estimate joins the z-score's.
            assert!(quad_err < 2.0 * se, "α = {alpha}, θ = {deg}°: quadrature error {quad_err} not below 2 × {se}");
            assert_z(&format!("E(α = {alpha}, θ = {deg}°, side {side})"), mc, fine, se.hypot(quad_err), 4.0);
            assert!(max <= 1.0 + 1e-6, "a sample weight {max} > 1");
            assert!(fine <= 1.0 + 1e-4, "E = {fine} > 1");
        }
    }
}

fn plastic(rho: f64, eta: f64) -> Material {
    Material::Plastic { diffuse_reflectance: Spectrum::Constant(rho), ior: eta, roughness: 0.0.into() }
}

#[test]
fn plastic_conserves_energy_at_every_angle_and_a_white_one_returns_everything() {
    // Closed form: albedo = F(θ_o) + (1 − F(θ_o)) A(ρ), A(1) = 1. Checked three ways: the closed
    // form itself, the quadrature of its diffuse f plus the coat's F, and the mean sample weight.
    let mut seed = 300;
    for (rho, eta) in [(1.0, 1.5), (0.5, 1.5), (1.0, 2.0), (0.8, 1.33)] {
        let b = grey(&plastic(rho, eta));
        for deg in [0.0, 30.0, 60.0, 80.0, 89.0] {
            let wo = at(deg, 10.0);
            let closed = b.closed_form_albedo(wo).unwrap().0[0];
            let f_o = photon::bsdf::fresnel_dielectric(wo.z as f64, 1.0, eta).0;
            let quad = f_o + lobe_integral(&b, wo, Vec3A::Z, Mode::Importance, 2000, 256, |wi| wi.z > 0.0);
            assert!((quad - closed).abs() < 1e-5, "ρ = {rho}, η = {eta}, θ = {deg}°: {quad} vs {closed}");
            assert!(closed <= 1.0 + 1e-9, "ρ = {rho}, η = {eta}, θ = {deg}°: albedo {closed} > 1");
            if rho == 1.0 {
                assert!((closed - 1.0).abs() < 1e-6, "a white plastic returns {closed} at {deg}°");
            }
            seed += 1;
            let (mc, se, max) = sampled_albedo(&b, wo, 100_000, seed);
            assert!(max <= 1.0 + 1e-9, "a sample weight {max} > 1");
            if se > 0.0 {
                assert_z(&format!("plastic ρ = {rho}, η = {eta}, θ = {deg}°"), mc, closed, se, 4.0);
            } else {
                assert!((mc - closed).abs() < 1e-9, "{mc} vs {closed}");
            }
        }
    }
}

#[test]
fn plastic_is_reciprocal() {
    let b = grey(&plastic(0.6, 1.5));
    let mut s = Sampler::for_batch(10, 0);
    for _ in 0..2000 {
        let wo = photon::sampling::uniform_hemisphere(Vec3A::Z, s.uniform_f32(), s.uniform_f32());
        let wi = photon::sampling::uniform_hemisphere(Vec3A::Z, s.uniform_f32(), s.uniform_f32());
        let (a, c) = (b.f(wo, wi, Mode::Importance).value().0[0], b.f(wi, wo, Mode::Radiance).value().0[0]);
        assert!((a - c).abs() <= 1e-12 * a.max(c), "{a} vs {c}");
    }
}

#[test]
fn rough_plastic_never_gains_energy_and_its_samples_weigh_what_its_bsdf_integrates_to() {
    // A white rough plastic loses only the coat lobe's masking (a few per cent at grazing); the
    // mean sample weight equals the quadrature of its f (coat lobe about the mirror direction
    // plus the base about the normal).
    let mut seed = 400;
    for (rho, alpha) in [(1.0, 0.1), (1.0, 0.4), (0.5, 0.2)] {
        let m = Material::Plastic { diffuse_reflectance: Spectrum::Constant(rho), ior: 1.5, roughness: alpha.into() };
        let b = grey(&m);
        for deg in [0.0, 45.0, 75.0, 88.0] {
            let wo = at(deg, 0.0);
            let mirror = Vec3A::new(-wo.x, -wo.y, wo.z);
            let quad = |n_s, n_phi| lobe_integral(&b, wo, mirror, Mode::Importance, n_s, n_phi, |wi| wi.z > 0.0);
            let (fine, coarse) = (quad(3000, 512), quad(1500, 256));
            let quad_err = (fine - coarse).abs();
            seed += 1;
            let (mc, se, _) = sampled_albedo(&b, wo, 200_000, seed);
            println!("ρ = {rho}, α = {alpha}, θ = {deg}°: E = {mc:.5} ± {se:.5} (sampled), {fine:.5} ± {quad_err:.5}");
            // The base's transmittance comes from a 64-point table interpolated linearly, so the
            // albedo may exceed the exact model's by the table's error (≈ 1e-4); 1e-3 allows that
            // and still fails a gain of a tenth of a per cent.
            assert!(fine <= 1.0 + 1e-3, "ρ = {rho}, α = {alpha}, θ = {deg}°: albedo {fine} > 1");
            assert!(quad_err < 2.0 * se, "quadrature error {quad_err} vs {se}");
            assert_z(&format!("rough plastic ρ = {rho}, α = {alpha}, θ = {deg}°"), mc, fine, se.hypot(quad_err), 4.0);
        }
    }
}

// ---------------------------------------------------------------- anisotropic roughness

/// The anisotropic roughnesses tested, [αu, αv] (as in tests/chi2.rs).
const ANISOTROPIC: [(f64, f64); 2] = [(0.05, 0.4), (0.3, 0.1)];

fn aniso(au: f64, av: f64) -> photon::scene::Roughness {
    photon::scene::Roughness { u: au, v: av }
}

/// `m` on the plane z = 0 with its surface tangent along `tangent`.
fn grey_along(m: &Material, tangent: Vec3A) -> Bsdf<'static, 1> {
    Bsdf::<1>::new::<false>(m, prepared(m), &[f64::NAN], Vec3A::Z, move || tangent)
}

/// The in-plane tangent at `deg` from x, the tangent every anisotropic test below turns its
/// directions about (so no lobe lines up with the quadrature's axes by accident).
fn tangent_at(deg: f64) -> Vec3A {
    let (s, c) = deg.to_radians().sin_cos();
    Vec3A::new(c as f32, s as f32, 0.0)
}

/// The three anisotropic models: a metal, glass and a plastic.
fn anisotropic_models(au: f64, av: f64) -> [(&'static str, Material); 3] {
    [
        ("conductor", conductor(0.2, 3.0, aniso(au, av))),
        ("dielectric", rough_glass(aniso(au, av))),
        (
            "plastic",
            Material::Plastic { diffuse_reflectance: Spectrum::Constant(0.6), ior: 1.5, roughness: aniso(au, av) },
        ),
    ]
}

#[test]
fn anisotropic_reflection_is_reciprocal() {
    // f(wo, wi) = f(wi, wo) for reflection from either side (refraction: generalised, as for the
    // isotropic glass), with the tangent at an arbitrary angle.
    let mut s = Sampler::for_batch(11, 0);
    let t = tangent_at(25.0);
    for (au, av) in ANISOTROPIC {
        for (name, m) in anisotropic_models(au, av) {
            let b = grey_along(&m, t);
            let mut checked = 0;
            for _ in 0..4000 {
                let wo = photon::sampling::uniform_sphere(s.uniform_f32(), s.uniform_f32());
                let wi = photon::sampling::uniform_sphere(s.uniform_f32(), s.uniform_f32());
                let f = |a: Vec3A, c: Vec3A| b.f(a, c, Mode::Radiance).value().0[0];
                let (fr, rf) = (f(wo, wi), f(wi, wo));
                if fr == 0.0 && rf == 0.0 {
                    continue;
                }
                checked += 1;
                if wo.z * wi.z > 0.0 {
                    // Plastic's base mixes a μ·s table lookup on each side: symmetric too.
                    assert!((fr - rf).abs() <= 1e-4 * fr.max(rf) + 1e-9, "{name} [{au}, {av}]: {fr} vs {rf}");
                } else {
                    // Refraction: f(wo, wi)/η_o² = f(wi, wo)/η_i². Pairs grazing a microfacet are
                    // skipped, as in the isotropic test.
                    let etap = if wo.z > 0.0 { 1.5f32 } else { 1.0 / 1.5 };
                    let mh = (wo + wi * etap).normalize();
                    if wo.dot(mh).abs() < 0.02 || wi.dot(mh).abs() < 0.02 {
                        continue;
                    }
                    let (eta_o, eta_i) = if wo.z > 0.0 { (1.0, 1.5) } else { (1.5, 1.0) };
                    let (x, y) = (fr / (eta_o * eta_o), rf / (eta_i * eta_i));
                    assert!((x - y).abs() <= 1e-3 * x.max(y) + 1e-9, "{name} [{au}, {av}]: {fr} vs {rf}");
                }
            }
            assert!(checked > 500, "{name}: only {checked} pairs with f > 0");
        }
    }
}

#[test]
fn swapping_alpha_u_and_alpha_v_is_turning_the_tangent_by_a_right_angle() {
    // f and pdf with [a, b] and tangent t equal those with [b, a] and t turned 90° about n. For
    // the plastic the two coats' tables are worked out separately, at mirrored azimuths.
    let mut s = Sampler::for_batch(12, 0);
    let t = tangent_at(25.0);
    let turned = Vec3A::Z.cross(t);
    for (au, av) in ANISOTROPIC {
        for ((name, m), (_, swapped)) in anisotropic_models(au, av).into_iter().zip(anisotropic_models(av, au)) {
            let (a, b) = (grey_along(&m, t), grey_along(&swapped, turned));
            let tol = if name == "plastic" { 1e-4 } else { 1e-5 };
            for _ in 0..3000 {
                let wo = photon::sampling::uniform_sphere(s.uniform_f32(), s.uniform_f32());
                let wi = photon::sampling::uniform_sphere(s.uniform_f32(), s.uniform_f32());
                for mode in [Mode::Radiance, Mode::Importance] {
                    let (x, y) = (a.f(wo, wi, mode).value().0[0], b.f(wo, wi, mode).value().0[0]);
                    assert!((x - y).abs() <= tol * x.max(y) + 1e-12, "{name} [{au}, {av}] f: {x} vs {y}");
                }
                let (x, y) = (a.pdf(wo, wi, Mode::Importance), b.pdf(wo, wi, Mode::Importance));
                assert!((x - y).abs() <= tol * x.max(y) + 1e-12, "{name} [{au}, {av}] pdf: {x} vs {y}");
            }
            // A turn by any other angle does change the lobe.
            let c = grey_along(&m, tangent_at(70.0));
            let (wo, wi) = (at(50.0, 40.0), at(40.0, 240.0));
            let (x, y) = (a.f(wo, wi, Mode::Radiance).value().0[0], c.f(wo, wi, Mode::Radiance).value().0[0]);
            assert!((x - y).abs() > 1e-3 * x.max(y), "{name}: turning the tangent by 45° changed nothing ({x})");
        }
    }
}

#[test]
fn anisotropic_white_furnace_at_every_azimuth_energy_is_never_gained() {
    // A perfect reflector (F = 1), white plastic and clear glass with [αu, αv]: at each incidence
    // and azimuth from the tangent, the mean sample weight is the quadrature of f, at most 1, and
    // no sample weight of the metal or glass exceeds 1.
    let t0 = 25.0;
    let mut seed = 700;
    for (au, av) in ANISOTROPIC {
        let metal = conductor(0.0, 5.0, aniso(au, av));
        let glass = rough_glass(aniso(au, av));
        let white =
            Material::Plastic { diffuse_reflectance: Spectrum::Constant(1.0), ior: 1.5, roughness: aniso(au, av) };
        for (name, m) in [("metal", &metal), ("glass", &glass), ("white plastic", &white)] {
            let b = grey_along(m, tangent_at(t0));
            for (deg, phi, side) in
                [(0.0, 0.0, 1.0f32), (45.0, 30.0, 1.0), (70.0, 90.0, 1.0), (85.0, 135.0, 1.0), (60.0, 60.0, -1.0)]
            {
                let w = at(deg, t0 + phi);
                let wo = Vec3A::new(w.x, w.y, side * w.z);
                seed += 1;
                let (mc, se, max) = sampled_albedo(&b, wo, 400_000, seed);
                let mirror = Vec3A::new(-wo.x, -wo.y, wo.z);
                let quad = |n_s, n_phi| {
                    let reflected = lobe_integral(&b, wo, mirror, Mode::Importance, n_s, n_phi, |wi| wi.z * wo.z > 0.0);
                    if name != "glass" {
                        return reflected;
                    }
                    // Refraction about the smooth refraction direction (straight through beyond
                    // the critical angle), as in the isotropic furnace.
                    let (eta_o, eta_t) = if side > 0.0 { (1.0, 1.5) } else { (1.5, 1.0) };
                    let tangential = Vec3A::new(wo.x, wo.y, 0.0) * (eta_o / eta_t) as f32;
                    let sin2 = tangential.length_squared();
                    let refracted = if sin2 < 1.0 {
                        Vec3A::new(-tangential.x, -tangential.y, -side * (1.0 - sin2).sqrt())
                    } else {
                        -Vec3A::new(0.0, 0.0, side)
                    };
                    reflected + lobe_integral(&b, wo, refracted, Mode::Importance, n_s, n_phi, |wi| wi.z * wo.z < 0.0)
                };
                let (fine, coarse) = (quad(3000, 768), quad(1500, 384));
                let quad_err = (fine - coarse).abs();
                println!(
                    "{name} [{au}, {av}], θ_o = {deg}°, φ_o = {phi}°, side {side}: E = {mc:.5} ± {se:.5} (sampled), \
                     {fine:.5} ± {quad_err:.5} (quadrature), largest weight {max:.4}"
                );
                let what = format!("{name} [{au}, {av}], θ = {deg}°, φ = {phi}°, side {side}");
                assert!(quad_err < 2.0 * se, "{what}: quadrature error {quad_err} not below 2 × {se}");
                assert_z(&what, mc, fine, se.hypot(quad_err), 4.0);
                // The plastic's table may overestimate its coat's transmittance by up to 3e-3
                // (bsdf::plastic); the microfacet models integrate to ≤ 1 exactly.
                let bound = if name == "white plastic" { 1e-3 } else { 1e-4 };
                assert!(fine <= 1.0 + bound, "{what}: E = {fine} > 1");
                if name != "white plastic" {
                    assert!(max <= 1.0 + 1e-6, "{what}: a sample weight {max} > 1");
                }
            }
        }
    }
}

/// A beam straight down onto a plate of `material` (the `shape` given) at y = 0, with absorbing
/// walls 3 units out on every side: those at x = ±3 catch what the plate spreads along x, those
/// at z = ±3 what it spreads along z.
fn beam_between_walls(material: &str, shape: &str) -> String {
    let wall = |name: &str, corners: &str| {
        format!("[[surfaces]]\nname = \"{name}\"\nmaterial = \"absorber\"\nshape = {{ type = \"quad\", corners = {corners} }}\n\n")
    };
    format!(
        "[materials.metal]\n{material}\n\n[[surfaces]]\nname = \"plate\"\nmaterial = \"metal\"\nshape = {shape}\n\n{}{}{}{}\
         [[lights]]\nname = \"beam\"\n\
         shape = {{ type = \"quad\", corners = [[-0.1, 1, -0.1], [0.1, 1, -0.1], [0.1, 1, 0.1], [-0.1, 1, 0.1]] }}\n\
         distribution = \"collimated\"\npower_w = 10\n",
        wall("x+", "[[3, 0, -3], [3, 0, 3], [3, 3, 3], [3, 3, -3]]"),
        wall("x-", "[[-3, 0, -3], [-3, 3, -3], [-3, 3, 3], [-3, 0, 3]]"),
        wall("z+", "[[-3, 0, 3], [-3, 3, 3], [3, 3, 3], [3, 0, 3]]"),
        wall("z-", "[[-3, 0, -3], [3, 0, -3], [3, 3, -3], [-3, 3, -3]]"),
    )
}

/// The power the walls across x and those across z receive from the plate.
fn spread_along_x_and_z(toml: &str, seed: u64) -> (f64, f64) {
    let f = run(toml, 100_000, seed);
    let l = &f.ledger;
    assert!((l.absorbed_w + l.escaped_w + l.truncated_w - l.emitted_w).abs() < 1e-9 * l.emitted_w, "ledger {l:?}");
    let w = |name| surface(&f, name).incident_w;
    (w("x+") + w("x-"), w("z+") + w("z-"))
}

const BRUSHED: &str = "type = \"conductor\"\neta = 1.0972\nk = 6.7943\nroughness = [0.02, 0.5]";

#[test]
fn brushed_metal_spreads_light_across_its_tangent_a_quads_first_edge() {
    // αu = 0.02 along the tangent, αv = 0.5 across it: the reflected beam fans out across the
    // tangent and stays narrow along it. The quad's first edge runs along z, and with its corners
    // taken one further round (the same plate) along x; an isotropic plate spreads both ways alike.
    let along_z = "{ type = \"quad\", corners = [[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]] }";
    let along_x = "{ type = \"quad\", corners = [[-2, 0, 2], [2, 0, 2], [2, 0, -2], [-2, 0, -2]] }";
    let (x, z) = spread_along_x_and_z(&beam_between_walls(BRUSHED, along_z), 1);
    println!("first edge along z: {x:.4} W across x, {z:.4} W across z");
    assert!(x > 1.0 && x > 20.0 * z, "first edge along z: {x} W reach the x walls, {z} W the z walls");
    let (x, z) = spread_along_x_and_z(&beam_between_walls(BRUSHED, along_x), 2);
    println!("first edge along x: {x:.4} W across x, {z:.4} W across z");
    assert!(z > 1.0 && z > 20.0 * x, "first edge along x: {x} W reach the x walls, {z} W the z walls");
    let iso = BRUSHED.replace("[0.02, 0.5]", "0.3");
    let (x, z) = spread_along_x_and_z(&beam_between_walls(&iso, along_z), 3);
    println!("isotropic α = 0.3: {x:.4} W across x, {z:.4} W across z");
    // About 0.9 W each way, some 10⁴ photons: each sum has a relative standard error near 1 %.
    assert!((x / z - 1.0).abs() < 0.06, "isotropic: {x} W reach the x walls, {z} W the z walls");
}

/// An OBJ square plate at y = 0 (−2 to 2), its face's first edge along +z, with texture
/// coordinates `vt` (four `u v` pairs, one per corner) or none.
fn obj_plate(vt: Option<[[f64; 2]; 4]>) -> String {
    let v = "v -2 0 -2\nv -2 0 2\nv 2 0 2\nv 2 0 -2\n";
    match vt {
        None => format!("{v}f 1 2 3 4\n"),
        Some(q) => {
            let vt: String = q.iter().map(|[u, w]| format!("vt {u} {w}\n")).collect();
            format!("{v}{vt}f 1/1 2/2 3/3 4/4\n")
        }
    }
}

#[test]
fn a_brushed_mesh_takes_its_tangent_from_its_texture_coordinates_else_its_first_edge() {
    // The plate's first edge runs along z; its u coordinate grows along x (u = (x + 2)/4).
    let dir = common::temp_dir("brushed-mesh");
    let with_vt = dir.join("uv.obj");
    let without = dir.join("plain.obj");
    std::fs::write(&with_vt, obj_plate(Some([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]]))).unwrap();
    std::fs::write(&without, obj_plate(None)).unwrap();
    let mesh = |p: &std::path::Path| format!("{{ type = \"mesh\", file = \"{}\" }}", p.display());
    let (x, z) = spread_along_x_and_z(&beam_between_walls(BRUSHED, &mesh(&with_vt)), 4);
    println!("vt with u along x: {x:.4} W across x, {z:.4} W across z");
    assert!(z > 1.0 && z > 20.0 * x, "u along x: {x} W reach the x walls, {z} W the z walls");
    let (x, z) = spread_along_x_and_z(&beam_between_walls(BRUSHED, &mesh(&without)), 5);
    println!("no vt, first edge along z: {x:.4} W across x, {z:.4} W across z");
    assert!(x > 1.0 && x > 20.0 * z, "first edge along z: {x} W reach the x walls, {z} W the z walls");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn every_shape_has_its_documented_tangent() {
    // The u axis of `roughness = [αu, αv]` per shape (docs/reference.md, 3.8), read back from the
    // traced triangles.
    let dir = common::temp_dir("tangents");
    let obj = |name: &str, text: String| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        format!("{{ type = \"mesh\", file = \"{}\" }}", p.display())
    };
    // u = x + z, v = z − x: ∂P/∂u = (1, 0, 1)/2, at 45° between the axes.
    let skewed = obj("skewed.obj", obj_plate(Some([[-4.0, 0.0], [0.0, 4.0], [4.0, 0.0], [0.0, -4.0]])));
    let shapes = [
        ("quad", "{ type = \"quad\", corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]] }".to_string()),
        (
            "turned_quad",
            "{ type = \"quad\", corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]], transform = { rotate_deg = [0, 90, 0] } }"
                .to_string(),
        ),
        ("disk_z", "{ type = \"disk\", center = [0, 0, 5], normal = [0, 0, 1], radius = 1 }".to_string()),
        ("disk_y", "{ type = \"disk\", center = [0, 5, 0], normal = [0, 1, 0], radius = 1 }".to_string()),
        ("disk_x", "{ type = \"disk\", center = [5, 0, 0], normal = [1, 0, 0], radius = 1 }".to_string()),
        ("sphere", "{ type = \"sphere\", center = [10, 0, 0], radius = 1, subdivisions = 2 }".to_string()),
        ("box", "{ type = \"box\", min = [-10, -1, -1], max = [-8, 1, 1] }".to_string()),
        ("mesh_uv", obj("uv.obj", obj_plate(Some([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0]])))),
        ("mesh_plain", obj("plain.obj", obj_plate(None))),
        ("mesh_skewed", skewed),
    ];
    let mut toml =
        String::from("[materials.brushed]\ntype = \"conductor\"\nmetal = \"Al\"\nroughness = [0.1, 0.3]\n\n");
    for (name, shape) in &shapes {
        toml += &format!("[[surfaces]]\nname = \"{name}\"\nmaterial = \"brushed\"\nshape = {shape}\n\n");
    }
    toml += "[[lights]]\nname = \"lamp\"\nshape = { type = \"point\", position = [0, 20, 0] }\npower_w = 1\n";
    let scene = common::scene(&toml);
    let geo = &scene.geometry;
    // |t · expected| ≈ 1 (the lobe is symmetric, so the sign is immaterial).
    let check = |name: &str, expected: &dyn Fn(usize) -> Vec3A| {
        let s = scene.surfaces.iter().position(|x| x.name == name).unwrap();
        let mut count = 0;
        for p in (0..geo.len()).filter(|&p| geo.surface_of(p) as usize == s) {
            let n = geo.normal(p);
            let e = expected(p);
            let (t, e) = (geo.tangent(p), (e - n * n.dot(e)).normalize());
            assert!(t.dot(n).abs() < 1e-5 && (t.length() - 1.0).abs() < 1e-5, "{name}: tangent {t}");
            assert!(t.dot(e).abs() > 0.999, "{name}, triangle {p}: tangent {t}, expected ±{e}");
            count += 1;
        }
        assert!(count > 0, "{name}: no triangles");
    };
    check("quad", &|_| Vec3A::Z);
    check("turned_quad", &|_| Vec3A::X);
    check("disk_z", &|_| Vec3A::X);
    check("disk_y", &|_| Vec3A::X);
    check("disk_x", &|_| Vec3A::Z);
    // Along the parallels about the sphere's z axis at each triangle's centroid (in the
    // tracer's recentred frame).
    let centre = (glam::DVec3::new(10.0, 0.0, 0.0) * scene.unit_m - scene.origin_m).as_vec3a();
    check("sphere", &|p| {
        let v = geo.verts(p);
        Vec3A::Z.cross((v[0] + v[1] + v[2]) / 3.0 - centre)
    });
    check("box", &|p| if geo.normal(p).x.abs() > 0.5 { Vec3A::Y } else { Vec3A::X });
    check("mesh_uv", &|_| Vec3A::X);
    check("mesh_plain", &|_| Vec3A::Z);
    check("mesh_skewed", &|_| Vec3A::new(1.0, 0.0, 1.0));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn roughness_reads_as_one_number_or_as_along_and_across_the_tangent() {
    // A number is isotropic, as is [α, α]; [αu, αv] keeps its order; an α below 10⁻⁴ is smooth,
    // both together or, alone, raised to 10⁻⁴ (a perfect brush).
    let read = |value: &str| {
        let s = common::scene(&common::BASE.replace(
            "type = \"lambertian\"\nreflectance = 0.5",
            &format!("type = \"conductor\"\nmetal = \"Al\"\nroughness = {value}"),
        ));
        match s.material_of(0) {
            Material::Conductor { roughness, .. } => *roughness,
            m => panic!("{m:?}"),
        }
    };
    use photon::scene::Roughness;
    assert_eq!(read("0.2"), Roughness::isotropic(0.2));
    assert_eq!(read("[0.2, 0.2]"), Roughness::isotropic(0.2));
    assert!(!read("[0.2, 0.2]").is_anisotropic());
    assert_eq!(read("[0.1, 0.3]"), Roughness { u: 0.1, v: 0.3 });
    assert!(read("[0.1, 0.3]").is_anisotropic() && read("[0.1, 0.3]").is_rough());
    assert_eq!(read("[0, 0.3]"), Roughness { u: 1e-4, v: 0.3 });
    assert_eq!(read("[0.3, 1e-6]"), Roughness { u: 0.3, v: 1e-4 });
    assert_eq!(read("[0, 5e-5]"), Roughness::SMOOTH);
    assert_eq!(read("[1, 1]"), Roughness::isotropic(1.0));
}
