//! Ray sets: a `type = "rays"` detector records every arrival on its surface as
//! `rays_<name>.npy`, whose total power equals that surface's incident tally; a light with
//! `shape = { type = "rays" }` emits the set again, and the floor map it makes equals the one the
//! original source made, within noise; malformed ray files are refused naming the byte.

use std::path::Path;
use std::process::Command;

mod common;
use common::{chi_square_bounds, temp_dir};

const BIN: &str = env!("CARGO_BIN_EXE_photon");

/// An absorbing 3 m × 3 m floor with a 10 × 10 map, and `light`; with `window`, a 20 m × 20 m
/// absorbing sheet at z = 0.8 that catches every photon bound for the floor, recorded as rays.
fn scene(light: &str, window: bool) -> String {
    let mut s = format!(
        "[simulation]\nseed = 5\n\n{light}\n[[surfaces]]\nname = \"floor\"\nmaterial = \"absorber\"\n\
         shape = {{ type = \"quad\", corners = [[-1.5, -1.5, 0], [1.5, -1.5, 0], [1.5, 1.5, 0], [-1.5, 1.5, 0]] }}\n\
         map = {{ resolution = [10, 10] }}\n"
    );
    if window {
        s.push_str(
            "\n[[surfaces]]\nname = \"window\"\nmaterial = \"absorber\"\n\
             shape = { type = \"quad\", corners = [[-10, -10, 0.8], [10, -10, 0.8], [10, 10, 0.8], [-10, 10, 0.8]] }\n\
             \n[[detectors]]\ntype = \"rays\"\nname = \"window\"\nsurface = \"window\"\n",
        );
    }
    s
}

const SOURCE: &str = "[[lights]]\nname = \"lamp\"\nshape = { type = \"point\", position = [0.2, -0.1, 1] }\n\
                      direction = [0.2, 0, -1]\ndistribution = { cosine_power = 2 }\npower_w = 3\n";

/// Runs `toml` in `dir` (as scene.toml) with `photons`, returning the output folder.
fn run(dir: &Path, toml: &str, photons: u64, seed: u64) -> std::path::PathBuf {
    std::fs::write(dir.join("scene.toml"), toml).unwrap();
    let out = dir.join(format!("out{seed}"));
    let o = Command::new(BIN)
        .args(["run", "scene.toml", "--photons", &photons.to_string(), "--seed", &seed.to_string()])
        .args(["--threads", "2", "--quiet", "--out", out.to_str().unwrap()])
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    out
}

fn flux(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("flux.json")).unwrap()).unwrap()
}

/// The rows of a ray set written by photon (its own .npy layout: a 128-byte header).
fn read_rows(path: &Path) -> Vec<[f64; 8]> {
    let bytes = std::fs::read(path).unwrap();
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    assert!(header.contains("'descr': '<f8'") && header.contains("'fortran_order': False"), "{header}");
    bytes[10 + header_len..]
        .chunks_exact(64)
        .map(|r| std::array::from_fn(|i| f64::from_le_bytes(r[8 * i..8 * i + 8].try_into().unwrap())))
        .collect()
}

/// The floor map's flux per texel (W) with its standard error, from maps/floor.exr's
/// irradiance channels (f32) times the texel area (0.09 m²).
fn floor_map(out: &Path) -> Vec<(f64, f64)> {
    use exr::prelude::*;
    let image = read_all_flat_layers_from_file(out.join("maps/floor.exr")).unwrap();
    let layer = &image.layer_data[0];
    let channel = |name: &str| -> Vec<f64> {
        let c = layer.channel_data.list.iter().find(|c| c.name.to_string() == name).unwrap();
        c.sample_data.values_as_f32().map(|v| v as f64 * 0.09).collect()
    };
    channel("irradiance_w_m2").into_iter().zip(channel("irradiance_w_m2_stderr")).collect()
}

#[test]
fn a_ray_set_reproduces_the_floor_map_of_its_source() {
    let dir = temp_dir("rays-round-trip");
    let photons = 400_000;
    // 1. The source with the window: every photon bound for the floor ends on the window, and
    //    each arrival is a ray (one per history: the window absorbs).
    let recorded = run(&dir, &scene(SOURCE, true), photons, 1);
    let rows = read_rows(&recorded.join("rays_window.npy"));
    let f = flux(&recorded);
    let window = f["surfaces"].as_array().unwrap().iter().find(|s| s["name"] == "window").unwrap();
    // Summed compensated (Neumaier), so 4·10⁵ additions add no rounding of their own: each
    // ray's power is its weight × W per weight, rounded once (~10⁻¹⁶ each, √N of them).
    let (mut total, mut carry) = (0.0f64, 0.0f64);
    for r in &rows {
        let t = total + r[7];
        carry += if total.abs() >= r[7].abs() { (total - t) + r[7] } else { (r[7] - t) + total };
        total = t;
    }
    let total = total + carry;
    let tally = window["incident_w"].as_f64().unwrap();
    assert!((total - tally).abs() <= 1e-12 * tally, "the rays carry {total} W, the window's tally {tally} W");
    assert!(rows.len() as f64 > 0.99 * photons as f64, "{} rays", rows.len());
    for r in &rows {
        assert!((r[2] - 0.8).abs() < 1e-6, "a ray off the window: {r:?}");
        assert!(((r[3] * r[3] + r[4] * r[4] + r[5] * r[5]).sqrt() - 1.0).abs() < 1e-6 && r[5] < 0.0);
        assert_eq!(r[6], 0.0, "grey transport records no wavelength");
    }
    // The set's own floor map, F_t = Σ P_k over the rays whose straight line lands in texel t,
    // and its variance as an estimate from the first run's histories (one arrival each at
    // most): Σ P_k² − F_t²/N.
    let mut set_flux = vec![(0.0f64, 0.0f64); 100];
    for r in &rows {
        let s = -r[2] / r[5];
        let (x, y) = (r[0] + s * r[3], r[1] + s * r[4]);
        if x.abs() < 1.5 && y.abs() < 1.5 {
            let (i, j) = (((x + 1.5) / 0.3) as usize, ((y + 1.5) / 0.3) as usize);
            // EXR row 0 is the largest v (y): the same order as `floor_map`.
            let k = (9 - j) * 10 + i;
            set_flux[k].0 += r[7];
            set_flux[k].1 += r[7] * r[7];
        }
    }
    let set_var: Vec<f64> = set_flux.iter().map(|&(f, f2)| (f2 - f * f / photons as f64).max(0.0)).collect();
    // 2. The set emitted again, and 3. the source alone, each onto the floor.
    let dir2 = temp_dir("rays-emitted");
    std::fs::copy(recorded.join("rays_window.npy"), dir2.join("window.npy")).unwrap();
    let emitted = floor_map(&run(
        &dir2,
        &scene("[[lights]]\nname = \"set\"\nshape = { type = \"rays\", file = \"window.npy\" }\n", false),
        photons,
        2,
    ));
    let original = floor_map(&run(&dir, &scene(SOURCE, false), photons, 3));
    // Three independent errors: each run's own and the ray set's sampling of the source. The
    // maps are f32 (7 digits), far finer than their ~1.5 % noise.
    let (mut chi2, mut worst) = (0.0, 0.0f64);
    for k in 0..100 {
        let ((a, sa), (b, sb)) = (emitted[k], original[k]);
        let z = (a - b) / (sa * sa + sb * sb + set_var[k]).sqrt();
        chi2 += z * z;
        worst = worst.max(z.abs());
    }
    let (lo, hi) = chi_square_bounds(100.0);
    assert!(chi2 > lo && chi2 < hi, "χ² = {chi2:.1} over 100 texels, bounds ({lo:.1}, {hi:.1})");
    assert!(worst < 4.5, "a texel at |z| = {worst:.2}");
}

#[test]
fn a_ray_light_emits_the_sets_power_or_the_given_power() {
    let dir = temp_dir("rays-power");
    // Two rays straight down onto the floor: 1 W and 3 W.
    let rows = [[0.1, 0.2, 0.5, 0.0, 0.0, -2.0, 0.0, 1.0], [-0.4, 0.3, 0.5, 0.0, 0.0, -1.0, 0.0, 3.0]];
    std::fs::write(dir.join("two.npy"), npy(&rows)).unwrap();
    let light = "[[lights]]\nname = \"set\"\nshape = { type = \"rays\", file = \"two.npy\" }\n";
    let f = flux(&run(&dir, &scene(light, false), 10_000, 1));
    assert!((f["emitted_w"].as_f64().unwrap() - 4.0).abs() < 1e-12);
    let floor = &f["surfaces"][0];
    assert!((floor["incident_w"].as_f64().unwrap() - 4.0).abs() < 1e-9, "every ray lands on the floor");
    let scaled = format!("{light}power_w = 8\n");
    let f = flux(&run(&dir, &scene(&scaled, false), 10_000, 2));
    assert!((f["surfaces"][0]["incident_w"].as_f64().unwrap() - 8.0).abs() < 1e-9);
}

/// A .npy file of float64 rows [N, 8].
fn npy(rows: &[[f64; 8]]) -> Vec<u8> {
    npy_with(&format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({}, 8), }}", rows.len()), rows)
}

fn npy_with(header: &str, rows: &[[f64; 8]]) -> Vec<u8> {
    let mut h = header.to_string();
    h.push_str(&" ".repeat((64 - (10 + h.len() + 1) % 64) % 64));
    h.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(h.len() as u16).to_le_bytes());
    out.extend_from_slice(h.as_bytes());
    for r in rows {
        for x in r {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    out
}

#[test]
fn malformed_ray_sets_exit_2_naming_the_byte() {
    let good = [0.0, 0.0, 0.5, 0.0, 0.0, -1.0, 0.0, 1.0];
    let with = |i: usize, v: f64| {
        let mut r = good;
        r[i] = v;
        npy(&[good, r])
    };
    let mut truncated = npy(&[good, good]);
    truncated.truncate(truncated.len() - 5);
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"PK\x03\x04 not numpy".to_vec(), "byte 0: not a NumPy .npy file"),
        (npy_with("{'descr': '<f4', 'fortran_order': False, 'shape': (1, 8), }", &[good]), "little-endian float64"),
        (npy_with("{'descr': '<f8', 'fortran_order': True, 'shape': (1, 8), }", &[good]), "C order"),
        (npy_with("{'descr': '<f8', 'fortran_order': False, 'shape': (1, 7), }", &[good]), "shape must be (N, 8)"),
        (npy_with("{'descr': '<f8', 'fortran_order': False, 'shape': (0, 8), }", &[]), "holds no rays"),
        (truncated, "need 128 bytes of data, the file has 123"),
        (with(1, f64::NAN), "row 1: value 1 is not finite"),
        (with(5, 0.0), "row 1: the direction (dx, dy, dz) is zero"),
        (with(7, -1.0), "row 1: the power must be within 0"),
        (with(6, -3.0), "row 1: the wavelength must be >= 0"),
        (with(6, 500.0), "1 of 2 rays carry a wavelength and the rest 0"),
        (npy(&[[0.0, 0.0, 0.5, 0.0, 0.0, -1.0, 0.0, 0.0]]), "total power must be positive"),
    ];
    for (k, (bytes, message)) in cases.iter().enumerate() {
        let dir = temp_dir(&format!("rays-bad-{k}"));
        std::fs::write(dir.join("set.npy"), bytes).unwrap();
        let toml = scene("[[lights]]\nname = \"set\"\nshape = { type = \"rays\", file = \"set.npy\" }\n", false);
        std::fs::write(dir.join("scene.toml"), toml).unwrap();
        let o = Command::new(BIN)
            .args(["run", "scene.toml", "--photons", "1000", "--quiet", "--out", "out"])
            .current_dir(&dir)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "case {k}: {stderr}");
        assert!(stderr.contains("set.npy: byte "), "case {k} names no byte: {stderr}");
        assert!(stderr.contains(message), "case {k}: expected `{message}` in {stderr}");
        assert!(stderr.contains("lights[0].shape.file"), "case {k} names no key: {stderr}");
        assert!(!dir.join("out").exists());
    }
}

#[test]
fn a_ray_set_keeps_each_photons_wavelength_in_spectral_transport() {
    let dir = temp_dir("rays-spectral");
    // The floor's spectrum makes transport spectral; a 3000 K lamp.
    let toml = scene(&format!("{SOURCE}spectrum = {{ blackbody_k = 3000 }}\n"), true)
        .replace("map = { resolution = [10, 10] }", "map = { resolution = [10, 10] }\nspectrum_bins = 8");
    let recorded = run(&dir, &toml, 50_000, 1);
    let rows = read_rows(&recorded.join("rays_window.npy"));
    // The default wavelength range is 360–830 nm.
    assert!(rows.iter().all(|r| (360.0..=830.0).contains(&r[6])), "every ray carries a wavelength in range");
    // The window's lumens are Σ P·K_m·ȳ(λ) over its arrivals, photon by photon: the rays carry
    // the same wavelengths and powers.
    let f = flux(&recorded);
    let window = f["surfaces"].as_array().unwrap().iter().find(|s| s["name"] == "window").unwrap();
    let lm: f64 = rows.iter().map(|r| r[7] * photon::spectrum::photometry::efficacy_at(r[6])).sum();
    let tally = window["incident_lm"].as_f64().unwrap();
    assert!((lm - tally).abs() < 1e-9 * tally, "{lm} lm from the rays, {tally} lm tallied");
    // Emitted again, the light's lumens follow its rays' wavelengths (binned to 1 nm).
    let dir2 = temp_dir("rays-spectral-emitted");
    std::fs::copy(recorded.join("rays_window.npy"), dir2.join("w.npy")).unwrap();
    let light = "[[lights]]\nname = \"set\"\nshape = { type = \"rays\", file = \"w.npy\" }\n";
    let toml2 = scene(light, false).replace("map = { resolution = [10, 10] }", "spectrum_bins = 8");
    let emitted = flux(&run(&dir2, &toml2, 50_000, 2));
    let emitted_lm = emitted["emitted_lm"].as_f64().unwrap();
    assert!((emitted_lm / lm - 1.0).abs() < 2e-3, "{emitted_lm} lm emitted, the rays hold {lm} lm");
}

#[test]
fn a_ray_light_takes_no_distribution_direction_or_radiance() {
    let dir = temp_dir("rays-keys");
    std::fs::write(dir.join("one.npy"), npy(&[[0.0, 0.0, 0.5, 0.0, 0.0, -1.0, 0.0, 1.0]])).unwrap();
    for (key, value) in [("distribution", "\"lambertian\""), ("direction", "[0, 0, -1]"), ("radiance", "1")] {
        let light =
            format!("[[lights]]\nname = \"set\"\nshape = {{ type = \"rays\", file = \"one.npy\" }}\n{key} = {value}\n");
        std::fs::write(dir.join("scene.toml"), scene(&light, false)).unwrap();
        let o = Command::new(BIN).args(["info", "scene.toml"]).current_dir(&dir).output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{key}: {stderr}");
        assert!(
            stderr.contains(&format!("`lights[0].{key}`")) && stderr.contains(&format!("drop `{key}`")),
            "{stderr}"
        );
    }
}
