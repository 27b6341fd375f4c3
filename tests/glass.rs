//! The glass catalog (`ior = "BK7"`, …) and Sellmeier indices (`{ sellmeier = { B, C } }`):
//! each bundled glass gives its published n_d, N-BK7 its Abbe number, Schott's N-BK7 Sellmeier
//! terms reproduce the bundled N-BK7 table, and a scene with a named glass runs end to end with
//! dispersion. Bad input (unknown names, poles, malformed terms, ranges a glass does not cover)
//! is in `tests/bad_input.rs`.

use std::path::Path;

use photon::scene::catalog::{glass, GLASSES};
use photon::scene::{load_str, Material};
use photon::spectrum::Spectrum;

mod common;
use common::{assert_z, run, surface};

/// Fraunhofer lines (nm): d (helium), F (hydrogen), C (hydrogen).
const D_LINE: f64 = 587.56;
const F_LINE: f64 = 486.13;
const C_LINE: f64 = 656.27;

/// Schott's catalog 2017-01-20 (via refractiveindex.info's copies of its data sheets); the tables
/// of "SF5", "SF10", "SF11" follow the lead-free N-SF5, N-SF10, N-SF11 (see `catalog::GLASSES`),
/// whose n_d are given, the lead SF5, SF10, SF11 differing by ≤ 3e-5 (1.67270, 1.72825, 1.78472).
/// Fused silica: Malitson (1965). PMMA and polycarbonate: Sultanova et al. (2009), Table 1,
/// measured at 587.6 nm to ±0.001. Water: Daimon & Masumura (2007), 20.0 °C, relative to vacuum
/// (1.33299 relative to air at 589.3 nm, times n_air = 1.00027, is 1.33335).
const PUBLISHED_ND: &[(&str, f64)] = &[
    ("BK7", 1.5168),
    ("BAF10", 1.67003),
    ("FK51A", 1.48656),
    ("LASF9", 1.85025),
    ("SF5", 1.67271),
    ("SF10", 1.72828),
    ("SF11", 1.78472),
    ("fused_silica", 1.45846),
    ("PMMA", 1.491),
    ("polycarbonate", 1.585),
    ("water", 1.3334),
];

fn n_of(name: &str, nm: f64) -> f64 {
    glass(name).unwrap_or_else(|| panic!("no glass {name}")).0.eval(nm)
}

#[test]
fn every_bundled_glass_gives_its_published_index_at_the_d_line() {
    let mut names: Vec<&str> = GLASSES.iter().map(|g| g.0).collect();
    let mut checked: Vec<&str> = PUBLISHED_ND.iter().map(|g| g.0).collect();
    names.sort();
    checked.sort();
    assert_eq!(names, checked, "every bundled glass needs its published n_d here");
    for &(name, nd) in PUBLISHED_ND {
        let n = n_of(name, D_LINE);
        // The tables step ~21 nm and depart from Schott's fits by up to 4e-4 between steps; the
        // polymers' n_d is measured to ±0.001 and their one-term fit lies within 4e-4 of it.
        assert!((n - nd).abs() < 5e-4, "{name}: n_d = {n:.5}, published {nd}");
    }
}

#[test]
fn n_bk7_has_its_abbe_number() {
    // V_d = (n_d − 1)/(n_F − n_C); Schott gives 64.17 for N-BK7. Linear interpolation of the
    // 21 nm table costs about 0.2 of it.
    let v = (n_of("BK7", D_LINE) - 1.0) / (n_of("BK7", F_LINE) - n_of("BK7", C_LINE));
    assert!((v - 64.17).abs() < 0.5, "V_d = {v:.2}");
    // Water, Daimon & Masumura's 20.0 °C fit: refractiveindex.info lists V_d = 55.76.
    let v = (n_of("water", D_LINE) - 1.0) / (n_of("water", F_LINE) - n_of("water", C_LINE));
    assert!((v - 55.76).abs() < 0.05, "water V_d = {v:.2}");
}

/// A glass box under a point light; the material text goes in `[materials.glass]`.
fn glass_box(material: &str, range: &str) -> String {
    format!(
        "{range}\n[materials.glass]\ntype = \"dielectric\"\n{material}\n\n[[surfaces]]\nname = \"block\"\n\
         material = \"glass\"\nshape = {{ type = \"box\", min = [0, 0, 0], max = [1, 1, 1] }}\n\n[[lights]]\n\
         name = \"lamp\"\nshape = {{ type = \"point\", position = [3, 3, 3] }}\npower_w = 1\n"
    )
}

fn ior_of_loaded(toml: &str) -> Spectrum {
    let s = load_str(Path::new("glass.toml"), toml).unwrap_or_else(|e| panic!("should load: {e}\n{toml}"));
    match s.material_of(0) {
        Material::Dielectric { ior, .. } => ior.clone(),
        m => panic!("{m:?}"),
    }
}

#[test]
fn schotts_n_bk7_sellmeier_terms_reproduce_the_bundled_table() {
    // Schott's N-BK7 coefficients (shared/data/materials/SOURCES.md), given in a scene.
    let terms = "ior = { sellmeier = { B = [1.03961212, 0.231792344, 1.01046945], \
                 C = [0.00600069867, 0.0200179144, 103.560653] } }";
    let sellmeier = ior_of_loaded(&glass_box(terms, ""));
    assert!(matches!(sellmeier, Spectrum::Sellmeier { .. }), "{sellmeier:?}");
    let table = ior_of_loaded(&glass_box("ior = \"BK7\"", ""));
    assert!(matches!(table, Spectrum::Table(_)), "{table:?}");
    for nm in (400..=700).map(f64::from) {
        let (a, b) = (sellmeier.eval(nm), table.eval(nm));
        assert!((a - b).abs() < 1e-4, "{nm} nm: Sellmeier {a:.6}, table {b:.6}");
    }
    assert!((sellmeier.eval(D_LINE) - 1.5168).abs() < 1e-5, "{}", sellmeier.eval(D_LINE));
}

#[test]
fn named_glasses_work_on_both_sides_and_make_the_scene_dispersive() {
    let fx = |material: &str| {
        load_str(Path::new("glass.toml"), &glass_box(material, "")).unwrap().effects.names().join(", ")
    };
    let dispersive = "spectral, specular_reflection, refraction, dispersion";
    for (name, _) in
        GLASSES.iter().filter(|g| !["PMMA", "polycarbonate", "LASF9", "SF5", "SF10", "SF11"].contains(&g.0))
    {
        assert_eq!(fx(&format!("ior = \"{name}\"")), dispersive, "{name}");
    }
    // A glass block in water: a named glass on the outside too.
    let s = load_str(Path::new("glass.toml"), &glass_box("ior = \"BK7\"\noutside_ior = \"water\"", "")).unwrap();
    let Material::Dielectric { ior, outside_ior, .. } = s.material_of(0) else { panic!() };
    assert!((ior.eval(D_LINE) - 1.5168).abs() < 1e-4 && (outside_ior.eval(D_LINE) - 1.3334).abs() < 1e-4);
    assert_eq!(s.effects.names().join(", "), dispersive);
    // Glasses whose data start above 360 nm load once the range lies inside them.
    let narrow = "[simulation]\nwavelength_range_nm = [440, 830]\n";
    for name in ["PMMA", "polycarbonate", "LASF9", "SF5", "SF10", "SF11"] {
        let s = load_str(Path::new("glass.toml"), &glass_box(&format!("ior = \"{name}\""), narrow)).unwrap();
        assert_eq!(s.effects.names().join(", "), dispersive, "{name}");
    }
    // Sellmeier terms that do not vary (C = 0) are a constant index: grey transport.
    assert_eq!(fx("ior = { sellmeier = { B = [1.25], C = [0] } }"), "specular_reflection, refraction");
    let n = ior_of_loaded(&glass_box("ior = { sellmeier = { B = [1.25], C = [0] } }", ""));
    assert_eq!(n, Spectrum::Constant(1.5));
}

/// A collimated beam straight down through a BK7 plate onto an absorbing floor.
const BEAM_THROUGH_BK7: &str = r#"
[materials.glass]
type = "dielectric"
ior = "BK7"

[materials.black]
type = "absorber"

[[surfaces]]
name = "plate"
material = "glass"
shape = { type = "box", min = [-2, 1, -2], max = [2, 2, 2] }

[[surfaces]]
name = "floor"
material = "black"
shape = { type = "quad", corners = [[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]] }

[[lights]]
name = "beam"
shape = { type = "quad", corners = [[-0.5, 3, -0.5], [0.5, 3, -0.5], [0.5, 3, 0.5], [-0.5, 3, 0.5]] }
distribution = "collimated"
power_w = 10
"#;

#[test]
fn a_beam_through_a_bk7_plate_transmits_what_fresnel_says_at_each_wavelength() {
    // At normal incidence each face reflects R = ((n − 1)/(n + 1))²; a clear plate with all its
    // internal reflections transmits (1 − R)/(1 + R). The light is flat over 360–830 nm, so the
    // floor receives the mean of that over the range, n from the bundled table.
    let s = common::scene(BEAM_THROUGH_BK7);
    assert_eq!(s.effects.names().join(", "), "spectral, specular_reflection, refraction, dispersion");
    let steps = 47_000;
    let mean_t = (0..steps)
        .map(|i| {
            let n = n_of("BK7", 360.0 + (i as f64 + 0.5) * 470.0 / steps as f64);
            let r = ((n - 1.0) / (n + 1.0)).powi(2);
            (1.0 - r) / (1.0 + r)
        })
        .sum::<f64>()
        / steps as f64;
    let f = run(BEAM_THROUGH_BK7, 200_000, 7);
    let floor = surface(&f, "floor");
    assert_z("floor under BK7", floor.absorbed_w, 10.0 * mean_t, floor.absorbed_w_stderr, 4.0);
    let l = &f.ledger;
    let sum = l.absorbed_w + l.escaped_w + l.truncated_w;
    assert!((sum - l.emitted_w).abs() < 1e-9 * l.emitted_w, "ledger {l:?}");
    // The plate itself is clear: it absorbs nothing.
    assert_eq!(surface(&f, "plate").absorbed_w, 0.0);
}
