//! Scattering media (`[media]`) against published radiative-transfer results: the van de Hulst /
//! MCML slabs, Chandrasekhar's semi-infinite medium (its H-function computed here), and Prahl's
//! adding-doubling with a refractive boundary; the ledger with media rows; Beer–Lambert through
//! a purely absorbing medium; a scene without media draws no free flights.
//!
//! Geometry: a slab is a box of the medium (a dielectric naming it with `medium`), wide enough
//! that no photon reaches its sides, under a collimated beam at normal incidence; two absorbing
//! planes far above and below it catch what leaves (reflectance = absorbed above, transmittance
//! = absorbed below; the beam's 20 µm source quad catches what returns straight back, which is
//! the specular reflection, and is counted in the reflectance).
//!
//! Statistical bounds: |z| < 4 against the reference, z from the run's own standard error (the
//! references are given to 5 digits, far below it); a false failure has probability 6·10⁻⁵ per
//! comparison; the seeds are fixed.

mod common;
use common::surface;

use photon::output::Flux;

/// A slab of `medium` (a `[media]` body) of thickness `d` (the file's unit, cm) and index `n`
/// in air, under a normal collimated beam of 1 W, between absorbing planes.
fn slab(medium: &str, d: f64, n: f64, half_width: f64) -> String {
    format!(
        r#"[scene]
unit = "cm"

[simulation]
max_bounces = 1000000

[media.tissue]
{medium}

[materials.slab]
type = "dielectric"
ior = {n}
outside_ior = 1.0
medium = "tissue"

[[surfaces]]
name = "slab"
material = "slab"
shape = {{ type = "box", min = [-{half_width}, -{half_width}, -{d}], max = [{half_width}, {half_width}, 0] }}

[[surfaces]]
name = "above"
material = "absorber"
shape = {{ type = "quad", corners = [[-1e5, -1e5, 1], [1e5, -1e5, 1], [1e5, 1e5, 1], [-1e5, 1e5, 1]] }}

[[surfaces]]
name = "below"
material = "absorber"
shape = {{ type = "quad", corners = [[-1e5, -1e5, -{below}], [1e5, -1e5, -{below}], [1e5, 1e5, -{below}], [-1e5, 1e5, -{below}]] }}

[[lights]]
name = "beam"
shape = {{ type = "quad", corners = [[-0.001, -0.001, 0.1], [-0.001, 0.001, 0.1], [0.001, 0.001, 0.1], [0.001, -0.001, 0.1]] }}
distribution = "collimated"
power_w = 1
"#,
        below = d + 1.0
    )
}

/// Reflectance and transmittance with their standard errors, after checking the ledger and that
/// nothing was truncated or escaped past the planes.
fn reflectance_transmittance(f: &Flux) -> ((f64, f64), (f64, f64)) {
    let l = &f.ledger;
    assert!(l.relative_residual() < 1e-12, "ledger {l:?}");
    assert!(l.truncated_w == 0.0, "{l:?}");
    assert!(l.escaped_w < 1e-4, "{l:?}");
    let (above, beam, below) = (surface(f, "above"), surface(f, "beam"), surface(f, "below"));
    let r = (above.absorbed_w + beam.absorbed_w, above.absorbed_w_stderr.hypot(beam.absorbed_w_stderr));
    (r, (below.absorbed_w, below.absorbed_w_stderr))
}

fn assert_near(what: &str, got: (f64, f64), want: f64) {
    let z = (got.0 - want) / got.1;
    println!("{what}: {:.5} ± {:.5} against {want} (z = {z:+.2})", got.0, got.1);
    assert!(got.1 > 0.0 && z.abs() < 4.0, "{what}: {} ± {} against {want}: z = {z:.2}", got.0, got.1);
}

/// The MCML test slab's tissue: μa = 10 cm⁻¹, μs = 90 cm⁻¹, g = 0.75.
const MCML_TISSUE: &str = "absorption_per_m = 1000\nscattering_per_m = 9000\nphase = { henyey_greenstein = 0.75 }";

/// `toml` run through the library with `photons`, `seed` and `transport` on 2 threads: the scene
/// and the whole result (counters, spectra, hero), where `common::run`'s flux table is not enough.
fn simulate(
    toml: &str,
    photons: u64,
    seed: u64,
    transport: photon::integrators::particle::TransportOptions,
) -> (photon::scene::Scene, photon::run::RunResult) {
    use photon::run::{apply_options, RunOptions};
    let mut s = common::scene(toml);
    let opts =
        RunOptions { photons: Some(photons), seed: Some(seed), threads: Some(2), transport, ..Default::default() };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = photon::run::simulate(&s, &opts, &chosen, &std::sync::atomic::AtomicBool::new(false)).unwrap();
    (s, r)
}

#[test]
fn mcml_slab_matches_van_de_hulst() {
    // μa = 10 cm⁻¹, μs = 90 cm⁻¹, g = 0.75, d = 0.02 cm, matched boundary (n = 1), normal
    // collimated beam: diffuse reflectance 0.09739 and total transmittance 0.66096 (van de Hulst
    // 1980, as tabulated by Wang, Jacques & Zheng 1995, "MCML — Monte Carlo modeling of light
    // transport in multi-layered tissues", Comput. Methods Programs Biomed. 47, Table 2).
    let toml = slab(MCML_TISSUE, 0.02, 1.0, 2.0);
    let f = common::run(&toml, 1_000_000, 1);
    let (r, t) = reflectance_transmittance(&f);
    assert_near("MCML slab R_d", r, 0.09739);
    assert_near("MCML slab T_t", t, 0.66096);
    // The rest is the medium's: its row, and its volume 4 × 4 × 0.02 cm³.
    let m = &f.media[0];
    assert_eq!(m.name, "tissue");
    assert!((m.volume_m3 - 3.2e-7).abs() < 1e-12, "volume {}", m.volume_m3);
    let rest = 1.0 - r.0 - t.0 - f.ledger.escaped_w;
    assert!((m.absorbed_w - rest).abs() < 1e-9, "medium {} against 1 − R − T = {rest}", m.absorbed_w);
    assert!(surface(&f, "slab").absorbed_w == 0.0, "an index-matched boundary absorbs nothing");
}

#[test]
fn conservative_isotropic_slab_matches_van_de_hulst() {
    // Optical depth 1, albedo 1, isotropic, matched boundaries, normal incidence: R = 0.34133,
    // T = 0.65867 (van de Hulst 1980, "Multiple Light Scattering"; Prahl's adding-doubling,
    // iadpython 0.6 with 16 quadrature points, gives UR1 = 0.341329, UT1 = 0.658671).
    let toml = slab("scattering_per_m = 5000\nphase = \"isotropic\"", 0.02, 1.0, 2.0);
    let f = common::run(&toml, 1_000_000, 2);
    let (r, t) = reflectance_transmittance(&f);
    assert_near("isotropic slab R", r, 0.34133);
    assert_near("isotropic slab T", t, 0.65867);
    assert!(f.media[0].absorbed_w == 0.0, "albedo 1 absorbs nothing");
}

/// Chandrasekhar's H-function for isotropic scattering of albedo `a` at μ = 1, by iterating
/// 1/H(μ) = √(1 − a) + (a/2) ∫₀¹ μ' H(μ')/(μ + μ') dμ' on 16 Gauss–Legendre panels of 8 nodes
/// (Chandrasekhar 1960, "Radiative Transfer", ch. V, eq. 11 form), to 10⁻¹³.
fn h_at_one(a: f64) -> f64 {
    let nodes: Vec<(f64, f64)> = (0..16)
        .flat_map(|p| {
            photon::scene::GAUSS_LEGENDRE_8.iter().map(move |&(x, w)| ((p as f64 + 0.5 + 0.5 * x) / 16.0, w / 32.0))
        })
        .collect();
    let integral =
        |mu: f64, h: &[f64]| -> f64 { nodes.iter().zip(h).map(|(&(m, w), &hm)| w * m * hm / (mu + m)).sum::<f64>() };
    let mut h = vec![1.0; nodes.len()];
    for _ in 0..10_000 {
        let next: Vec<f64> =
            nodes.iter().map(|&(mu, _)| 1.0 / ((1.0 - a).sqrt() + 0.5 * a * integral(mu, &h))).collect();
        let change = next.iter().zip(&h).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        h = next;
        if change < 1e-13 {
            break;
        }
    }
    // Its zeroth moment is known in closed form, ∫₀¹ H dμ = (2/a)(1 − √(1 − a)) (ch. V, eq. 21).
    let moment: f64 = nodes.iter().zip(&h).map(|(&(_, w), &hm)| w * hm).sum();
    let want = 2.0 / a * (1.0 - (1.0 - a).sqrt());
    assert!((moment - want).abs() < 1e-9, "a = {a}: ∫H dμ = {moment}, closed form {want}");
    1.0 / ((1.0 - a).sqrt() + 0.5 * a * integral(1.0, &h))
}

#[test]
fn semi_infinite_isotropic_medium_reflects_one_minus_h_root_one_minus_albedo() {
    // A half-space of isotropic scatterers of albedo a under a normal beam reflects
    // 1 − H(1)√(1 − a) (Chandrasekhar 1960, ch. IX). Here 150 mean free paths deep (the diffuse
    // light of a = 0.99 decays over 5.8 of them: e⁻²⁶ is left at the bottom) and 2000 wide.
    // The H computed here is held to its zeroth moment's closed form (`h_at_one`).
    for (k, a) in [0.5, 0.9, 0.99].into_iter().enumerate() {
        // μt = 10 cm⁻¹ (one mean free path is 1 mm).
        let medium = format!("absorption_per_m = {}\nscattering_per_m = {}", 1000.0 * (1.0 - a), 1000.0 * a);
        let toml = slab(&medium, 15.0, 1.0, 100.0);
        let photons = if a > 0.95 { 200_000 } else { 400_000 };
        let f = common::run(&toml, photons, 10 + k as u64);
        let (r, t) = reflectance_transmittance(&f);
        assert!(t.0 < 1e-6, "a = {a}: {} transmitted through 150 mean free paths", t.0);
        let want = 1.0 - h_at_one(a) * (1.0 - a).sqrt();
        assert_near(&format!("semi-infinite a = {a}"), r, want);
    }
}

#[test]
fn semi_infinite_medium_under_a_refractive_boundary_matches_adding_doubling() {
    // a = 0.8, g = 0, n = 1.4 in air, normal beam: total reflectance UR1 = 0.18095 including the
    // specular reflection ((n − 1)/(n + 1))² = 0.0278 (Prahl's adding-doubling: iadpython's
    // test_06_scattering, a = 0.8, b = 10⁵, g = 0, to its tolerance of 10⁻⁴).
    let toml = slab("absorption_per_m = 200\nscattering_per_m = 800", 15.0, 1.4, 100.0);
    let f = common::run(&toml, 400_000, 20);
    let (r, _) = reflectance_transmittance(&f);
    assert_near("semi-infinite a = 0.8 under n = 1.4", r, 0.18095);
}

#[test]
fn a_purely_absorbing_medium_is_beer_lambert_and_books_to_its_row() {
    // μa = 50 m⁻¹ through 2 cm, matched boundary: T = e⁻¹, and the medium row holds 1 − e⁻¹. The
    // expected-value estimator weights every photon by exp(−μa t) alike: T is exact to the f32
    // path length (10⁻⁵); the analog one lets a photon through with that probability (|z| < 4).
    let toml = slab("absorption_per_m = 50", 2.0, 1.0, 5.0);
    let f = common::run(&toml, 200_000, 3);
    let (r, t) = reflectance_transmittance(&f);
    assert!(r.0 == 0.0, "reflectance {r:?}");
    assert!((t.0 / (-1.0f64).exp() - 1.0).abs() < 1e-5, "T = {t:?}");
    let analog = common::run_with(&toml, 200_000, 3, common::ANALOG);
    assert_near("absorbing medium T, analog", reflectance_transmittance(&analog).1, (-1.0f64).exp());
    assert!((f.media[0].absorbed_w - (1.0 - t.0)).abs() < 1e-12, "{:?}", f.media[0]);
}

#[test]
fn only_a_scattering_medium_draws_free_flights_and_samples_a_phase_function() {
    let counters = |medium: &str| {
        let (s, r) = simulate(&slab(medium, 0.02, 1.0, 2.0), 10_000, 4, common::EXPECTED);
        (s.effects, r.tallies.counters)
    };
    let (fx, c) = counters("absorption_per_m = 1000\nscattering_per_m = 9000");
    assert!(fx.volume_scattering && fx.absorbing_media);
    assert!(c.free_flights > 10_000 && c.phase_samples > 10_000, "{c:?}");
    let (fx, c) = counters("absorption_per_m = 1000");
    assert!(!fx.volume_scattering && fx.absorbing_media);
    assert!(c.free_flights == 0 && c.phase_samples == 0, "{c:?}");
}

#[test]
fn a_medium_whose_scattering_varies_with_wavelength_scatters_each_photon_at_its_own() {
    // μs steps from 50 to 150 cm⁻¹ at 550 nm (optical depth 1 and 3 in the 0.2 mm slab), albedo
    // 1, isotropic, under a beam of flat spectrum over 400–700 nm. Each photon flies at its own
    // wavelength's μt, so the reflected power per wavelength bin is half the beam's power times
    // that depth's reflectance: 0.34133 below 550 nm (as above) and 0.62245 above it (Prahl's
    // adding-doubling, iadpython 0.6: a = 1, b = 3, g = 0, n = 1, 16 quadrature points). Both
    // estimators. The 2 pm ramp of the step carries 10⁻⁵ of the power.
    let spectral = slab(
        "scattering_per_m = { table = [[400, 5000], [549.999, 5000], [550.001, 15000], [700, 15000]] }",
        0.02,
        1.0,
        2.0,
    )
    .replace("max_bounces = 1000000", "max_bounces = 1000000\nwavelength_range_nm = [400, 700]")
    .replace(
        "name = \"above\"\nmaterial = \"absorber\"",
        "name = \"above\"\nmaterial = \"absorber\"\nspectrum_bins = 2",
    );
    assert!(spectral.contains("spectrum_bins = 2") && spectral.contains("[400, 700]"));
    for (k, transport) in [common::EXPECTED, common::ANALOG].into_iter().enumerate() {
        let (s, r) = simulate(&spectral, 800_000, 32 + k as u64, transport);
        assert!(s.effects.spectral && s.effects.volume_scattering);
        assert!(!r.hero, "no hero wavelengths in a scattering medium");
        let bin = |b: usize| r.tallies.estimate(&r.tallies.spectra, b, r.emitted_w, r.transport.error_model());
        let (thin, thin_se) = bin(0);
        assert_near(
            &format!("{:?}: reflectance below 550 nm", transport.estimator),
            (2.0 * thin, 2.0 * thin_se),
            0.34133,
        );
        let (thick, thick_se) = bin(1);
        assert_near(
            &format!("{:?}: reflectance above 550 nm", transport.estimator),
            (2.0 * thick, 2.0 * thick_se),
            0.62245,
        );
    }
}

#[test]
fn a_slab_far_from_the_scene_centre_keeps_its_photons_inside() {
    // The MCML slab with a marker 10 m above it moves the scene's centre 5 m away, where an f32
    // collision point has 0.5 µm steps, a two-hundredth of a mean free path: a point rounded past
    // the face must not leave the photon colliding in air (it would read low R and T, and trace
    // up to max_bounces rays). Same references as `mcml_slab_matches_van_de_hulst`.
    let toml = slab(MCML_TISSUE, 0.02, 1.0, 2.0) + "\n[[surfaces]]\nname = \"marker\"\nmaterial = \"absorber\"\nshape = { type = \"quad\", corners = [[0, 0, 1000], [0.1, 0, 1000], [0.1, 0.1, 1000], [0, 0.1, 1000]] }\n";
    let (s, r) = simulate(&toml, 1_000_000, 5, common::EXPECTED);
    assert!(s.origin_m.z > 4.9, "the scene's centre is {} m up", s.origin_m.z);
    let f = photon::output::flux(&s, &r);
    let (r_d, t_t) = reflectance_transmittance(&f);
    assert_near("off-centre MCML slab R_d", r_d, 0.09739);
    assert_near("off-centre MCML slab T_t", t_t, 0.66096);
    // The centred slab traces about 9 rays per photon (collisions and crossings).
    let rays = r.tallies.counters.rays as f64 / 1e6;
    assert!(rays < 20.0, "{rays} rays per photon");
}

/// A box of medium "inner" (μa 1.2 cm⁻¹) nested in a box of medium "outer" (μa 1 cm⁻¹), both
/// index-matched (n = 1), and a beam: from above (`light_z` = 0.1) or from inside the inner box.
fn nested_boxes(light_z: f64) -> String {
    format!(
        r#"[scene]
unit = "cm"

[media.outer]
absorption_per_m = 100

[media.inner]
absorption_per_m = 120

[materials.outer]
type = "dielectric"
ior = 1.0
medium = "outer"

[materials.inner]
type = "dielectric"
ior = 1.0
outside_ior = 1.0
medium = "inner"
outside_medium = "outer"

[[surfaces]]
name = "outer"
material = "outer"
shape = {{ type = "box", min = [-2, -2, -3], max = [2, 2, 0] }}

[[surfaces]]
name = "inner"
material = "inner"
shape = {{ type = "box", min = [-1, -1, -2], max = [1, 1, -1] }}

[[surfaces]]
name = "below"
material = "absorber"
shape = {{ type = "quad", corners = [[-1e3, -1e3, -4], [1e3, -1e3, -4], [1e3, 1e3, -4], [-1e3, 1e3, -4]] }}

[[lights]]
name = "beam"
shape = {{ type = "quad", corners = [[-0.001, -0.001, {light_z}], [-0.001, 0.001, {light_z}], [0.001, 0.001, {light_z}], [0.001, -0.001, {light_z}]] }}
distribution = "collimated"
power_w = 1
"#
    )
}

#[test]
fn nested_media_book_each_stretch_to_the_medium_it_crosses() {
    // A beam down the axis crosses 1 cm of outer, 1 cm of inner, 1 cm of outer: with
    // expected-value absorption every share is exact (Beer–Lambert, no randomness while the
    // weight stays above the roulette's 0.1: it ends at e^{−2.2} = 0.11):
    //   outer: (1 − e⁻¹) + e^{−2.2}(1 − e⁻¹),  inner: e⁻¹(1 − e^{−1.2}),  below: e^{−3.2}.
    // From a beam inside the inner box (0.5 cm above its floor): inner 1 − e^{−0.6},
    // outer e^{−0.6}(1 − e⁻¹), below e^{−1.6} (the light emits into the innermost medium).
    // The outer medium fills its box less the inner one: 48 − 4 = 44 cm³ (to f32 rounding).
    let e = |x: f64| (-x).exp();
    for (light_z, want_outer, want_inner, want_below) in [
        (0.1, (1.0 - e(1.0)) + e(2.2) * (1.0 - e(1.0)), e(1.0) * (1.0 - e(1.2)), e(3.2)),
        (-1.5, e(0.6) * (1.0 - e(1.0)), 1.0 - e(0.6), e(1.6)),
    ] {
        let (s, r) = simulate(&nested_boxes(light_z), 2000, 3, common::EXPECTED);
        let f = photon::output::flux(&s, &r);
        assert!(f.ledger.relative_residual() < 1e-12 && f.ledger.escaped_w == 0.0, "{:?}", f.ledger);
        let medium = |n: &str| f.media.iter().find(|m| m.name == n).unwrap();
        // To 10⁻⁶: the path lengths are the f32 tracer's.
        assert!((medium("outer").absorbed_w - want_outer).abs() < 1e-6, "beam at {light_z}: {:?}", medium("outer"));
        assert!(
            (medium("inner").absorbed_w - want_inner).abs() < 1e-6,
            "beam at {light_z}: {:?} against {want_inner}",
            medium("inner")
        );
        assert!((surface(&f, "below").absorbed_w - want_below).abs() < 1e-6, "beam at {light_z}");
        assert!((medium("outer").volume_m3 / 44e-6 - 1.0).abs() < 1e-6, "{:?}", medium("outer"));
        assert!((medium("inner").volume_m3 / 4e-6 - 1.0).abs() < 1e-6, "{:?}", medium("inner"));
    }
}

#[test]
fn the_mcml_slab_inside_a_clear_dielectric_matches_van_de_hulst() {
    // The MCML tissue slab nested in an index-matched clear box (no medium): a photon leaving
    // the slab is inside the box, not in the world, and nothing changes: R_d 0.09739, T_t 0.66096.
    let toml = slab(MCML_TISSUE, 0.02, 1.0, 2.0).replace(
        "[[surfaces]]\nname = \"above\"",
        "[materials.clear]\ntype = \"dielectric\"\nior = 1.0\n\n[[surfaces]]\nname = \"case\"\nmaterial = \"clear\"\n\
             shape = { type = \"box\", min = [-3, -3, -0.5], max = [3, 3, 0.05] }\n\n[[surfaces]]\nname = \"above\"",
    );
    assert!(toml.contains("name = \"case\""));
    let (s, r) = simulate(&toml, 200_000, 21, common::EXPECTED);
    assert_eq!(s.surface_outside[s.surfaces.iter().position(|x| x.name == "slab").unwrap()], Some(1));
    let (rd, tt) = reflectance_transmittance(&photon::output::flux(&s, &r));
    assert_near("nested MCML R_d", rd, 0.09739);
    assert_near("nested MCML T_t", tt, 0.66096);
}

/// Reflectance and transmittance at normal incidence of the lossless incoherent stack of the
/// interfaces between successive indices `n`: each Fresnel R = ((n₁ − n₂)/(n₁ + n₂))², combined
/// as R = R₁ + T₁²R₂/(1 − R₁R₂), T = T₁T₂/(1 − R₁R₂) (lossless, so each part is symmetric).
fn incoherent_stack(n: &[f64]) -> (f64, f64) {
    let interface = |a: f64, b: f64| {
        let r = ((a - b) / (a + b)).powi(2);
        (r, 1.0 - r)
    };
    let combine = |(r1, t1): (f64, f64), (r2, t2): (f64, f64)| {
        let d = 1.0 - r1 * r2;
        (r1 + t1 * t1 * r2 / d, t1 * t2 / d)
    };
    n.windows(2).map(|w| interface(w[0], w[1])).reduce(combine).unwrap()
}

#[test]
fn glass_in_water_transmits_what_the_incoherent_stack_of_four_interfaces_does() {
    // A glass plate (n 1.5, 1 cm) nested in a water box (n 1.33, 3 cm), a normal beam: every
    // reflection stays on the axis, so transmittance is that of the incoherent stack
    // air|water|glass|water|air. Interfaces combine as R = R₁ + T₁²R₂/(1 − R₁R₂),
    // T = T₁T₂/(1 − R₁R₂) (lossless, symmetric), with Fresnel R = ((n₁ − n₂)/(n₁ + n₂))².
    // Analog transport: each photon either passes or not, so s.e. = √(T(1 − T)/N) (z < 4).
    let stack = incoherent_stack(&[1.0, 1.33, 1.5, 1.33, 1.0]);
    let toml = r#"[scene]
unit = "cm"

[materials.water]
type = "dielectric"
ior = 1.33

[materials.glass]
type = "dielectric"
ior = 1.5
outside_ior = 1.33

[[surfaces]]
name = "water"
material = "water"
shape = { type = "box", min = [-3, -3, -3], max = [3, 3, 0] }

[[surfaces]]
name = "glass"
material = "glass"
shape = { type = "box", min = [-2, -2, -2], max = [2, 2, -1] }

[[surfaces]]
name = "below"
material = "absorber"
shape = { type = "quad", corners = [[-1e3, -1e3, -4], [1e3, -1e3, -4], [1e3, 1e3, -4], [-1e3, 1e3, -4]] }

[[lights]]
name = "beam"
shape = { type = "quad", corners = [[-0.001, -0.001, 0.1], [-0.001, 0.001, 0.1], [0.001, 0.001, 0.1], [0.001, -0.001, 0.1]] }
distribution = "collimated"
power_w = 1
"#;
    let n = 400_000;
    let (s, r) = simulate(toml, n, 8, common::ANALOG);
    let f = photon::output::flux(&s, &r);
    assert!(f.ledger.relative_residual() < 1e-12, "{:?}", f.ledger);
    let t = surface(&f, "below").absorbed_w;
    let se = (stack.1 * (1.0 - stack.1) / n as f64).sqrt();
    println!("glass in water: T = {t:.5} against the stack's {:.5} (s.e. {se:.1e})", stack.1);
    common::assert_z("glass-in-water transmittance", t, stack.1, se, 4.0);
    // And the same glass declared as if in air is refused (its outside is the water).
    let air = toml.replace("outside_ior = 1.33\n", "");
    let err =
        photon::scene::load_str(std::path::Path::new("tests/inline.toml"), &air).err().expect("refused").to_string();
    assert!(err.contains("needs outside_ior equal to the ior of material \"water\""), "{err}");
}

#[test]
fn media_declared_unlike_the_geometry_are_refused_naming_the_surface() {
    // Each edit of the nested boxes makes the declaration disagree with where the inner box is.
    let cases = [
        // The inner box sits in the outer medium but says nothing of it.
        (
            "outside_medium = \"outer\"\n",
            "",
            "which is filled with medium \"outer\", but material \"inner\" has outside_medium none",
        ),
        // It names a medium that is not around it.
        ("outside_medium = \"outer\"", "outside_medium = \"inner\"", "has outside_medium \"inner\""),
        // The outer box says it sits in a medium, but it is in the world.
        (
            "ior = 1.0\nmedium = \"outer\"",
            "ior = 1.0\nmedium = \"outer\"\noutside_medium = \"inner\"",
            "lies in no other dielectric",
        ),
    ];
    for (from, to, message) in cases {
        let toml = nested_boxes(0.1);
        assert_eq!(toml.matches(from).count(), 1, "{from}");
        let bad = toml.replacen(from, to, 1);
        let err = photon::scene::load_str(std::path::Path::new("tests/inline.toml"), &bad)
            .err()
            .expect("refused")
            .to_string();
        assert!(err.contains(message) && err.contains("surfaces["), "{err}");
    }
}

#[test]
fn the_light_traced_image_of_a_thin_slab_is_its_single_scattering_radiance() {
    // A 1 cm index-matched slab, μs = 0.1 /m (optical depth τ = 0.001), isotropic, no
    // absorption, lit from below by a 1 m² collimated beam of 1 W (irradiance E = 1 W/m², flat
    // over 360–830 nm: E_λ = E/470 nm). Seen from above at θ = 45° (μ = cos θ), the radiance
    // leaving the top is single scattering, integrated along the line of sight:
    //   L_λ = E_λ/(4π(1 − μ)) · (e^{−τ} − e^{−τ/μ})
    // (multiple scattering adds a share of order τ, 10⁻³). Y of a flat spectral radiance is that
    // radiance (film.rs), so the mean pixel Y must match, |z| < 4. Each splat passes the slab's
    // top face (index-matched) with its transmittance along the way.
    let toml = r#"[media.haze]
scattering_per_m = 0.1

[materials.slab]
type = "dielectric"
ior = 1.0
medium = "haze"

[[surfaces]]
name = "slab"
material = "slab"
shape = { type = "box", min = [-1, -1, -0.01], max = [1, 1, 0] }

[[lights]]
name = "beam"
shape = { type = "quad", corners = [[-0.5, -0.5, -0.05], [0.5, -0.5, -0.05], [0.5, 0.5, -0.05], [-0.5, 0.5, -0.05]] }
distribution = "collimated"
power_w = 1

[camera]
position = [0, -2.1213203, 2.1213203]
look_at = [0, 0, 0]
up = [0, 1, 0]
fov_deg = 10
resolution = [8, 8]
"#;
    let (s, r) = simulate(toml, 20_000_000, 9, common::EXPECTED);
    assert!(s.effects.volume_scattering && s.camera.is_some());
    let (tau, mu) = (0.001f64, std::f64::consts::FRAC_1_SQRT_2);
    let want = 1.0 / 470.0 / (4.0 * std::f64::consts::PI * (1.0 - mu)) * ((-tau).exp() - (-tau / mu).exp());
    let (y, se) = r.film.as_ref().unwrap().mean_y(r.emitted_w);
    println!("thin slab: Y = {y:.4e} ± {se:.1e} against {want:.4e} (z = {:+.2})", (y - want) / se);
    common::assert_z("single-scattering radiance", y, want, se, 4.0);
}

#[test]
fn two_adjacent_layers_of_the_mcml_tissue_make_the_mcml_slab() {
    // The MCML slab (van de Hulst 1980; Wang, Jacques & Zheng 1995, Table 2: R_d 0.09739,
    // T_t 0.66096) as two 0.01 cm layers sharing a face, each its own dielectric and medium
    // entry: the loader joins the coincident faces into one interface ("upper|lower"), and a
    // photon crossing it changes medium without meeting anything. Same bounds as the one-slab
    // test (|z| < 4 against the run's standard error).
    let layer = |name: &str, z0: f64, z1: f64| {
        format!(
            "[media.{name}]\n{MCML_TISSUE}\n\n[materials.{name}]\ntype = \"dielectric\"\nior = 1.0\nmedium = \"{name}\"\n\n\
             [[surfaces]]\nname = \"{name}\"\nmaterial = \"{name}\"\nshape = {{ type = \"box\", min = [-2, -2, {z0}], max = [2, 2, {z1}] }}\n"
        )
    };
    let catchers = r#"[[surfaces]]
name = "above"
material = "absorber"
shape = { type = "quad", corners = [[-1e5, -1e5, 1], [1e5, -1e5, 1], [1e5, 1e5, 1], [-1e5, 1e5, 1]] }

[[surfaces]]
name = "below"
material = "absorber"
shape = { type = "quad", corners = [[-1e5, -1e5, -1], [1e5, -1e5, -1], [1e5, 1e5, -1], [-1e5, 1e5, -1]] }

[[lights]]
name = "beam"
shape = { type = "quad", corners = [[-0.001, -0.001, 0.1], [-0.001, 0.001, 0.1], [0.001, 0.001, 0.1], [0.001, -0.001, 0.1]] }
distribution = "collimated"
power_w = 1
"#;
    let toml =
        format!("[scene]\nunit = \"cm\"\n\n{}{}{catchers}", layer("upper", -0.01, 0.0), layer("lower", -0.02, -0.01));
    let s = common::scene(&toml);
    let names: Vec<&str> = s.surfaces.iter().map(|s| s.name.as_str()).collect();
    assert!(names.contains(&"upper|lower"), "{names:?}");
    let vol = |m: &str| s.media.iter().find(|x| x.name == m).unwrap().volume_m3;
    assert!(
        (vol("upper") - 1.6e-7).abs() < 1e-12 && (vol("lower") - 1.6e-7).abs() < 1e-12,
        "{} {}",
        vol("upper"),
        vol("lower")
    );
    let f = common::run(&toml, 1_000_000, 1);
    assert!(f.ledger.relative_residual() < 1e-12, "{:?}", f.ledger);
    let (r, t) = reflectance_transmittance(&f);
    assert_near("two-layer R_d", r, 0.09739);
    assert_near("two-layer T_t", t, 0.66096);
    // Both layers absorb: the beam's side more.
    let absorbed = |m: &str| f.media.iter().find(|x| x.name == m).unwrap().absorbed_w;
    let (up, low) = (absorbed("upper"), absorbed("lower"));
    assert!(up > low && low > 0.05, "upper {up}, lower {low}");
}

#[test]
fn a_glass_plate_on_water_transmits_what_the_incoherent_stack_of_three_interfaces_does() {
    // A 1 cm glass plate (n 1.5) lying on a 2 cm water layer (n 1.33), the two sharing a face,
    // under a normal beam: the incoherent stack air|glass|water|air (R = R₁ + T₁²R₂/(1 − R₁R₂),
    // T = T₁T₂/(1 − R₁R₂), Fresnel at normal incidence). Without the joined interface the
    // glass would meet air below it (two more reflections): T would be that of air|glass|air|
    // water|air instead, 0.8% lower. Analog: s.e. = √(T(1 − T)/N), |z| < 4.
    let stack = incoherent_stack(&[1.0, 1.5, 1.33, 1.0]);
    let separate = incoherent_stack(&[1.0, 1.5, 1.0, 1.33, 1.0]);
    let toml = r#"[scene]
unit = "cm"

[materials.glass]
type = "dielectric"
ior = 1.5

[materials.water]
type = "dielectric"
ior = 1.33

[[surfaces]]
name = "glass"
material = "glass"
shape = { type = "box", min = [-3, -3, -1], max = [3, 3, 0] }

[[surfaces]]
name = "water"
material = "water"
shape = { type = "box", min = [-3, -3, -3], max = [3, 3, -1] }

[[surfaces]]
name = "below"
material = "absorber"
shape = { type = "quad", corners = [[-1e3, -1e3, -4], [1e3, -1e3, -4], [1e3, 1e3, -4], [-1e3, 1e3, -4]] }

[[lights]]
name = "beam"
shape = { type = "quad", corners = [[-0.001, -0.001, 0.1], [-0.001, 0.001, 0.1], [0.001, 0.001, 0.1], [0.001, -0.001, 0.1]] }
distribution = "collimated"
power_w = 1
"#;
    let n = 400_000;
    let (s, r) = simulate(toml, n, 9, common::ANALOG);
    let f = photon::output::flux(&s, &r);
    assert!(f.ledger.relative_residual() < 1e-12, "{:?}", f.ledger);
    let t = surface(&f, "below").absorbed_w;
    let se = (stack.1 * (1.0 - stack.1) / n as f64).sqrt();
    println!(
        "glass on water: T = {t:.5} against the stack's {:.5} (s.e. {se:.1e}); separated {:.5}",
        stack.1, separate.1
    );
    assert!((stack.1 - separate.1) / se > 10.0, "the test must tell the joined interface from two");
    common::assert_z("glass-on-water transmittance", t, stack.1, se, 4.0);
    assert!(surface(&f, "glass|water").incident_w > 0.9, "{:?}", surface(&f, "glass|water").incident_w);
}
