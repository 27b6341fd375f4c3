//! Photometric units, irradiance maps, IES sources and the far-field and spectral detectors,
//! each against a closed form with a z-score bound of 4 at a fixed seed (false-failure chance
//! 6e-5 per comparison; the photon counts make a 1–2 % bias fail).

mod common;
use common::{assert_z, run, surface};

/// A square plate of side `a` (m) at distance `h` below an isotropic point source of `lumens`,
/// with the source's spectrum and the plate's reflectance given as TOML values.
fn plate_under_bulb(a: f64, h: f64, lumens: f64, spectrum: &str, reflectance: &str) -> String {
    let r = a / 2.0;
    let root = env!("CARGO_MANIFEST_DIR");
    format!(
        r#"
        [simulation]
        wavelength_range_nm = [380, 780]
        [materials.plate]
        type = "lambertian"
        reflectance = {reflectance}
        [[surfaces]]
        name = "plate"
        material = "plate"
        shape = {{ type = "quad", corners = [[-{r}, -{r}, 0], [{r}, -{r}, 0], [{r}, {r}, 0], [-{r}, {r}, 0]] }}
        [[lights]]
        name = "bulb"
        shape = {{ type = "point", position = [0, 0, {h}] }}
        power_lm = {lumens}
        spectrum = {spectrum}
        distribution = "isotropic"
        "#
    )
    .replace("SPECTRA/", &format!("{root}/spectra/"))
}

/// Solid angle of an a×a square seen from distance h on its axis: 4·asin(a²/(a² + 4h²)).
fn square_solid_angle(a: f64, h: f64) -> f64 {
    4.0 * (a * a / (a * a + 4.0 * h * h)).asin()
}

#[test]
fn plate_under_a_bulb_of_known_lumens_receives_its_solid_angle_share() {
    // Φ_plate = Φ_v · Ω/(4π) for an isotropic source. Grey: flat spectrum, grey plate; spectral:
    // the Cornell lamp's spectrum and the red wall's reflectance (so each photon carries λ and
    // is weighted by 683·ȳ(λ)). Either way the light's lumens are exact and the plate's share is
    // the closed form.
    let (a, h, lumens) = (1.0, 0.6, 1200.0);
    let expected = lumens * square_solid_angle(a, h) / (4.0 * std::f64::consts::PI);
    for (spectrum, reflectance) in
        [("1.0", "0.5"), (r#"{ file = "SPECTRA/cornell_light.csv" }"#, r#"{ file = "SPECTRA/cornell_red.csv" }"#)]
    {
        let f = run(&plate_under_bulb(a, h, lumens, spectrum, reflectance), 400_000, 3);
        assert!((f.emitted_lm - lumens).abs() < 1e-9 * lumens, "emitted {} lm", f.emitted_lm);
        let p = surface(&f, "plate");
        assert_z("plate lumens", p.incident_lm, expected, p.incident_lm_stderr, 4.0);
        assert_z("plate mean illuminance", p.illuminance_lx, expected / (a * a), p.illuminance_lx_stderr, 4.0);
        assert!((p.irradiance_w_m2 * p.area_m2 - p.incident_w).abs() < 1e-12 * p.incident_w);
        // Absorbed light is the complement of the reflected share, in lumens too.
        assert!(p.absorbed_lm > 0.0 && p.absorbed_lm < p.incident_lm);
    }
}

#[test]
fn grey_lumens_are_watts_times_the_spectrum_efficacy() {
    // In grey transport every photon of a light has that light's efficacy K = 683∫Sȳ/∫S, so
    // lm/W is exactly K on every row: 683·106.86/400 ≈ 182.5 lm/W for flat white over 380–780 nm.
    let f = run(&plate_under_bulb(1.0, 0.6, 500.0, "1.0", "0.3"), 50_000, 1);
    let p = surface(&f, "plate");
    let k = f.emitted_lm / f.emitted_w;
    assert!((k - 683.0 * 106.86 / 400.0).abs() < 0.5, "efficacy {k}");
    assert!((p.incident_lm / p.incident_w - k).abs() < 1e-9 * k);
}
