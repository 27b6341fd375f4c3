//! Photometric units, irradiance maps, IES sources and the far-field and spectral detectors,
//! each against a closed form with a z-score bound of 4 at a fixed seed (false-failure chance
//! 6e-5 per comparison; the photon counts make a 1–2 % bias fail).

mod common;
use common::{assert_z, chi_square_bounds, cornell_toml, farfield_z, run, run_farfield, scene, surface};

use std::sync::atomic::AtomicBool;

use photon::output::maps::{self, MapEstimate};
use photon::output::{self, Flux};
use photon::run::{apply_options, simulate, RunOptions};

/// Runs `toml` on 2 threads; returns the flux table and the irradiance maps.
fn run_maps(toml: &str, photons: u64, seed: u64) -> (Flux, Vec<MapEstimate>) {
    let mut s = scene(toml);
    let opts = RunOptions { photons: Some(photons), seed: Some(seed), threads: Some(2), ..Default::default() };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap();
    (output::flux(&s, &r), maps::estimates(&s, &r))
}

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

#[test]
fn illuminance_under_a_point_source_is_intensity_over_height_squared_at_the_map_centre() {
    // E = I/h² on the axis, I = Φ_v/(4π) for an isotropic source. The centre texel (side s = 0.1 m
    // at h = 1 m) averages E over its square: exactly I·Ω_texel/s², which is I/h² × (1 − 0.25 %)
    // (E falls off as cos³θ). With ~8000 photons in that texel its error is ~1.1 %, so both
    // comparisons at 4σ are decisive and the 0.25 % does not matter to the first.
    let (lumens, h, n) = (1000.0, 1.0, 11usize);
    let side = 0.1 * n as f64;
    let toml = plate_under_bulb(side, h, lumens, "1.0", "0.0")
        .replace("[[lights]]", &format!("map = {{ resolution = [{n}, {n}] }}\n[[lights]]"));
    let (_, maps) = run_maps(&toml, 10_000_000, 7);
    let centre = n / 2 * n + n / 2;
    let (e, se) = maps[0].illuminance_lx()[centre];
    let intensity = lumens / (4.0 * std::f64::consts::PI);
    assert_z("centre illuminance vs I/h²", e, intensity / (h * h), se, 4.0);
    assert_z("centre illuminance vs I·Ω/s²", e, intensity * square_solid_angle(0.1, h) / 0.01, se, 4.0);
    assert!(se / e < 0.015, "relative error {}", se / e);
}

#[test]
fn a_maps_texels_add_up_to_its_surface_tally() {
    // The Cornell floor is a trapezoid, so the map's last column is only partly covered; every
    // arrival still lands in exactly one texel, so the sums agree to rounding (W and lm alike).
    let toml =
        cornell_toml().replace("[549.6, 0, 559.2]] }\n", "[549.6, 0, 559.2]] }\nmap = { resolution = [40, 30] }\n");
    assert!(toml.contains("map = "));
    let (f, maps) = run_maps(&toml, 300_000, 2);
    let floor = surface(&f, "floor");
    let m = &maps[0];
    assert_eq!(m.surface, "floor");
    let w: f64 = m.flux_w.iter().map(|x| x.0).sum();
    let lm: f64 = m.flux_lm.iter().map(|x| x.0).sum();
    assert!((w - floor.incident_w).abs() < 1e-9 * floor.incident_w, "{w} vs {}", floor.incident_w);
    assert!((lm - floor.incident_lm).abs() < 1e-9 * floor.incident_lm, "{lm} vs {}", floor.incident_lm);
    let area: f64 = m.texel_area_m2.iter().sum();
    assert!((area - floor.area_m2).abs() < 1e-6 * floor.area_m2);
}

#[test]
fn a_uniformly_lit_plate_maps_flat_within_noise() {
    // A collimated beam wider than the plate lights it uniformly, so every texel's irradiance
    // estimates the same value: Σ (E_k − Ē)²/σ_k² over the 100 texels is χ² with 99 degrees of
    // freedom (Ē is their inverse-variance mean). Its 1e-4 tails bound it from both sides: a
    // pattern in the map fails the upper bound, and standard errors that are too large fail the
    // lower one.
    let toml = r#"
        [[surfaces]]
        name = "plate"
        material = "absorber"
        shape = { type = "quad", corners = [[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]] }
        map = { resolution = [20, 5] }
        [[lights]]
        name = "sun"
        shape = { type = "quad", corners = [[-1, -1, 1], [-1, 2, 1], [3, 2, 1], [3, -1, 1]] }
        power_w = 12
        distribution = "collimated"
    "#;
    let (f, maps) = run_maps(toml, 400_000, 5);
    let e = maps[0].irradiance_w_m2();
    let weights: Vec<f64> = e.iter().map(|x| 1.0 / (x.1 * x.1)).collect();
    let mean = e.iter().zip(&weights).map(|(x, w)| x.0 * w).sum::<f64>() / weights.iter().sum::<f64>();
    let chi2: f64 = e.iter().map(|x| ((x.0 - mean) / x.1).powi(2)).sum();
    let (lo, hi) = chi_square_bounds(99.0);
    assert!(chi2 > lo && chi2 < hi, "chi-square {chi2} outside [{lo}, {hi}]");
    // And the flat value is the beam's irradiance: 12 W over the 4 × 3 m² lamp = 1 W/m².
    let plate = surface(&f, "plate");
    assert_z("mean irradiance", plate.irradiance_w_m2, 1.0, plate.irradiance_w_m2_stderr, 4.0);
}

/// An IES point light alone in empty space, seen by a far-field detector. `frame`'s lines: the
/// light's `direction = …`, then optionally its C0 vector, then the detector's keys.
fn ies_alone(file: &str, frame: &str, resolution: [usize; 2]) -> String {
    let root = env!("CARGO_MANIFEST_DIR");
    format!(
        r#"
        [[lights]]
        name = "luminaire"
        shape = {{ type = "point", position = [0, 0, 0] }}
        {frame_light}
        distribution = {{ ies = "{root}/tests/data/ies/{file}"{c0} }}
        [[detectors]]
        type = "farfield"
        name = "far"
        resolution = [{}, {}]
        {frame_detector}
        "#,
        resolution[0],
        resolution[1],
        frame_light = frame.lines().next().unwrap_or(""),
        c0 = frame.lines().nth(1).map(|c| format!(", c0 = {c}")).unwrap_or_default(),
        frame_detector = frame.lines().skip(2).collect::<Vec<_>>().join("\n"),
    )
}

#[test]
fn isotropic_ies_file_gives_its_lumens_and_a_flat_far_field() {
    // 100 cd everywhere: Φ = 400π lm taken from the file (no power given), and every far-field
    // bin reads 100 cd: Σz² is χ² with as many degrees of freedom as bins.
    let toml = ies_alone("isotropic.ies", "direction = [0, 0, -1]", [12, 8]);
    let (f, e) = run_farfield(&toml, 1_000_000, 11);
    let lm = 400.0 * std::f64::consts::PI;
    assert!((f.emitted_lm - lm).abs() < 1e-9 * lm, "emitted {} lm", f.emitted_lm);
    let (chi2, k, worst) = farfield_z(&e, |_, _, _| 100.0, |_, _| false);
    let (lo, hi) = chi_square_bounds(k as f64);
    assert!(chi2 > lo && chi2 < hi && worst < 4.5, "χ² {chi2} over {k} bins (bounds {lo}–{hi}), worst |z| {worst}");
}

#[test]
fn cosine_ies_file_reproduces_a_lambertian_far_field() {
    // I = 1000 cos γ below the horizontal: a band's mean intensity is
    // 1000 (sin²γ₁ − sin²γ₀) / (2 (cos γ₀ − cos γ₁)), none above. The file samples cos γ every 5°,
    // and linear interpolation between samples is within 0.1 % of it, far below the ~1 % noise.
    let toml = ies_alone("cosine.ies", "direction = [0, 0, -1]", [36, 4]);
    let (f, e) = run_farfield(&toml, 2_000_000, 12);
    let lm = 1000.0 * std::f64::consts::PI;
    assert!((f.emitted_lm - lm).abs() < 2e-3 * lm, "emitted {} lm", f.emitted_lm);
    let (chi2, k, worst) = farfield_z(
        &e,
        |g0, g1, _| {
            if g0 >= 90.0 {
                return 0.0;
            }
            let (a, b) = (g0.to_radians(), g1.to_radians());
            1000.0 * (b.sin().powi(2) - a.sin().powi(2)) / (2.0 * (a.cos() - b.cos()))
        },
        |_, _| false,
    );
    let (lo, hi) = chi_square_bounds(k as f64);
    assert!(chi2 > lo && chi2 < hi && worst < 4.5, "χ² {chi2} over {k} bins (bounds {lo}–{hi}), worst |z| {worst}");
}

#[test]
fn bilateral_ies_file_round_trips_through_the_far_field_in_a_turned_frame() {
    // An asymmetric table given for C 0–180 (mirrored to 180–360), with a multiplier, light
    // upward, numbers wrapped over lines with commas; the luminaire aimed along +x with C0 along
    // +y, the detector in the same frame. Each bin must read the table's mean over the bin (by
    // quadrature of the interpolated table): the bin edges fall on the sampler's sub-cell edges,
    // so the expected flux per bin is exact and Σz² is χ².
    let path = format!("{}/tests/data/ies/bilateral.ies", env!("CARGO_MANIFEST_DIR"));
    let table = photon::scene::ies::IesProfile::read(std::path::Path::new(&path)).unwrap();
    let frame = "direction = [1, 0, 0]\n[0, 1, 0]\nnadir = [1, 0, 0]\nc0 = [0, 1, 0]";
    let toml = ies_alone("bilateral.ies", frame, [12, 8]);
    let (f, e) = run_farfield(&toml, 2_000_000, 13);
    assert!((f.emitted_lm - table.total_lm).abs() < 1e-9 * table.total_lm);
    let mean_over_bin = |g0: f64, g1: f64, c: f64| {
        // Midpoint rule in (cos γ, C): uniform in solid angle.
        let (m, half) = (24, 22.5);
        let (u0, u1) = (g0.to_radians().cos(), g1.to_radians().cos());
        let mut sum = 0.0;
        for a in 0..m {
            let g = (u0 + (a as f64 + 0.5) / m as f64 * (u1 - u0)).acos().to_degrees();
            for b in 0..m {
                sum += table.intensity_cd(g, c - half + (b as f64 + 0.5) / m as f64 * 2.0 * half);
            }
        }
        sum / (m * m) as f64
    };
    // The file's C90 plane at γ = 30° is 2 × 300 cd (multiplier 2), mirrored to C270.
    assert!((table.intensity_cd(30.0, 90.0) - 600.0).abs() < 1e-9);
    assert!((table.intensity_cd(30.0, 270.0) - 600.0).abs() < 1e-9);
    let (chi2, k, worst) = farfield_z(&e, mean_over_bin, |_, _| false);
    let (lo, hi) = chi_square_bounds(k as f64);
    assert!(chi2 > lo && chi2 < hi && worst < 4.5, "χ² {chi2} over {k} bins (bounds {lo}–{hi}), worst |z| {worst}");
}

#[test]
fn a_surface_spectrum_follows_the_lamp_spectrum_it_receives() {
    // A grey plate (ρ = 0.3) under a bulb with a stepped spectrum over 400–700 nm: 1 from 400 to 500 nm, 3
    // from 500 to 600 nm, 0 above (tabulated with steep steps). The plate receives the fraction
    // Ω/4π of the power, shared over the wavelength bins as ∫_bin S / ∫ S. Each of the 6 bins
    // within 4σ, and the bins add up to the surface's incident tally (to rounding). Asking for a
    // spectrum makes transport spectral even though nothing in the scene varies with wavelength.
    // Each photon hits the plate once, and the expected-value estimator books 70 % of it as
    // absorbed: the absorbed spectrum is 0.7 × the incident one in every bin, exactly.
    let dir = common::temp_dir("spectrum");
    std::fs::create_dir_all(&dir).unwrap();
    let table = dir.join("step.csv");
    std::fs::write(&table, "wavelength_nm,value\n400,1\n499.999,1\n500,3\n599.999,3\n600,0\n700,0\n").unwrap();
    let toml = plate_under_bulb(1.0, 0.6, 1000.0, &format!("{{ file = \"{}\" }}", table.display()), "0.3")
        .replace("[380, 780]", "[400, 700]")
        .replace("[[lights]]", "spectrum_bins = 6\n[[lights]]");
    let mut s = scene(&toml);
    assert!(s.effects.spectral, "spectrum_bins must make transport spectral");
    let opts = RunOptions { photons: Some(400_000), seed: Some(9), threads: Some(2), ..Default::default() };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap();
    let f = output::flux(&s, &r);
    let plate = surface(&f, "plate");
    let share = square_solid_angle(1.0, 0.6) / (4.0 * std::f64::consts::PI);
    // ∫S = 100·1 + 100·3 (the 1 nm ramps are negligible at 1e-5 of it): 1/4 and 3/4 of the power.
    let per_bin = [0.125, 0.125, 0.375, 0.375, 0.0, 0.0];
    let mut total = 0.0;
    for (k, want) in per_bin.iter().enumerate() {
        let (w, se) = r.tallies.estimate(&r.tallies.spectra, k, r.emitted_w, r.transport.error_model());
        let (a, _) = r.tallies.estimate(&r.tallies.spectra_absorbed, k, r.emitted_w, r.transport.error_model());
        assert!((a - 0.7 * w).abs() <= 1e-9 * w, "bin {k}: absorbed {a} of {w}");
        total += w;
        if *want == 0.0 {
            assert_eq!(w, 0.0, "bin {k}");
        } else {
            assert_z(&format!("bin {k}"), w, want * share * r.emitted_w, se, 4.0);
        }
    }
    assert!((total - plate.incident_w).abs() < 1e-9 * plate.incident_w);
    let out = photon::output::write_spectra(&dir, &s, &r).unwrap();
    let csv = std::fs::read_to_string(&out[0]).unwrap();
    assert!(csv.starts_with("lambda_lo_nm,lambda_hi_nm,incident_w,") && csv.lines().count() == 7, "{csv}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_area_light_with_a_cosine_ies_table_lights_like_a_lambertian_one() {
    // cosine.ies is I ∝ cos γ, a Lambertian emitter's pattern: a quad lamp with that table (γ = 0
    // along its front normal) must put the same share of its power on a plate below as the same
    // lamp declared lambertian. Independent seeds, 4 combined standard errors (the table's linear
    // interpolation of cos γ is within 0.1 %, below the ~0.3 % errors).
    let root = env!("CARGO_MANIFEST_DIR");
    let lamp = |distribution: &str| {
        format!(
            r#"
            [[surfaces]]
            name = "plate"
            material = "absorber"
            shape = {{ type = "quad", corners = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]] }}
            [[lights]]
            name = "panel"
            shape = {{ type = "quad", corners = [[-0.5, -0.5, 1], [-0.5, 0.5, 1], [0.5, 0.5, 1], [0.5, -0.5, 1]] }}
            power_w = 10
            distribution = {distribution}
            "#
        )
    };
    let ies = run(&lamp(&format!("{{ ies = \"{root}/tests/data/ies/cosine.ies\" }}")), 400_000, 21);
    let lambertian = run(&lamp("\"lambertian\""), 400_000, 22);
    let (a, b) = (surface(&ies, "plate"), surface(&lambertian, "plate"));
    assert!(a.incident_w > 3.0, "the panel faces the plate: {}", a.incident_w);
    assert_z(
        "plate under an IES cosine panel vs a Lambertian one",
        a.incident_w,
        b.incident_w,
        (a.incident_w_stderr.powi(2) + b.incident_w_stderr.powi(2)).sqrt(),
        4.0,
    );
}

#[test]
fn a_mesh_maps_over_its_texture_coordinates() {
    // The plate of the flatness test as an OBJ of four triangles around a centre vertex, with
    // texture coordinates that turn it a quarter and squeeze it (u runs along y, v along x): the
    // map must still be flat within noise (χ²), add up to the tally, and cover the plate's area.
    let dir = common::temp_dir("uvmesh");
    std::fs::create_dir_all(&dir).unwrap();
    let obj = "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nv 1 0.5 0\n\
               vt 0 0\nvt 0 1\nvt 1 1\nvt 1 0\nvt 0.5 0.5\n\
               f 1/1 2/2 5/5\nf 2/2 3/3 5/5\nf 3/3 4/4 5/5\nf 4/4 1/1 5/5\n";
    std::fs::write(dir.join("plate.obj"), obj).unwrap();
    let toml = format!(
        r#"
        [[surfaces]]
        name = "plate"
        material = "absorber"
        shape = {{ type = "mesh", file = "{}" }}
        map = {{ resolution = [6, 12] }}
        [[lights]]
        name = "sun"
        shape = {{ type = "quad", corners = [[-1, -1, 1], [-1, 2, 1], [3, 2, 1], [3, -1, 1]] }}
        power_w = 12
        distribution = "collimated"
        "#,
        dir.join("plate.obj").display()
    );
    let (f, maps) = run_maps(&toml, 400_000, 6);
    let m = &maps[0];
    assert!(m.size_m.is_none());
    let area: f64 = m.texel_area_m2.iter().sum();
    assert!((area - 2.0).abs() < 1e-9, "texel areas add up to {area}");
    let plate = surface(&f, "plate");
    let w: f64 = m.flux_w.iter().map(|x| x.0).sum();
    assert!((w - plate.incident_w).abs() < 1e-9 * plate.incident_w);
    let e = m.irradiance_w_m2();
    let chi2: f64 = e.iter().map(|x| ((x.0 - 1.0) / x.1).powi(2)).sum();
    let (lo, hi) = chi_square_bounds(72.0);
    assert!(chi2 > lo && chi2 < hi, "χ² {chi2} against 1 W/m² outside [{lo}, {hi}]");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_c_angle_turns_counterclockwise_seen_from_above() {
    // LM-63/LM-75: C increases counterclockwise seen from above the luminaire. A lobe tabulated
    // only at C = 90° (0 < C < 180 after interpolation), aimed down (−z) with C0 along +x, must
    // light only the +y side: two plates below, on either side of the y = 0 plane. Exact, not
    // statistical: the −y plate can receive no photon at all.
    let root = env!("CARGO_MANIFEST_DIR");
    let plate = |name: &str, y0: f64, y1: f64| {
        format!(
            "[[surfaces]]\nname = \"{name}\"\nmaterial = \"absorber\"\n\
             shape = {{ type = \"quad\", corners = [[-1, {y0}, -1], [1, {y0}, -1], [1, {y1}, -1], [-1, {y1}, -1]] }}\n"
        )
    };
    let toml = format!(
        "{}{}[[lights]]\nname = \"luminaire\"\nshape = {{ type = \"point\", position = [0, 0, 0] }}\n\
         direction = [0, 0, -1]\ndistribution = {{ ies = \"{root}/tests/data/ies/c90_lobe.ies\", c0 = [1, 0, 0] }}\n",
        plate("plus_y", 0.05, 2.0),
        plate("minus_y", -2.0, -0.05),
    );
    let f = run(&toml, 100_000, 5);
    let (plus, minus) = (surface(&f, "plus_y"), surface(&f, "minus_y"));
    assert!(plus.incident_w > 0.2 * f.emitted_w, "+y plate got {} of {} W", plus.incident_w, f.emitted_w);
    assert_eq!(minus.incident_w, 0.0, "light reached the −y side: C turns the wrong way");
}
