//! Shared helpers for the integration tests: run a scene given as TOML text through the library.
#![allow(dead_code)]

use std::path::Path;
use std::sync::atomic::AtomicBool;

use photon::integrators::particle::{Estimator, TransportOptions};
use photon::output::{self, Flux, SurfaceRow};
use photon::run::{apply_options, simulate, RunOptions};
use photon::scene::{load_str, Scene};

pub const ANALOG: TransportOptions = TransportOptions { estimator: Estimator::Analog, stratified: false, hero: true };

pub fn scene(toml: &str) -> Scene {
    load_str(Path::new("tests/inline.toml"), toml).unwrap_or_else(|e| panic!("scene should load: {e}"))
}

/// Expected-value absorption, fixed: with the default (`auto`) a pilot would choose per scene,
/// and which estimator a test exercises could change unnoticed.
pub const EXPECTED: TransportOptions =
    TransportOptions { estimator: Estimator::Expected, stratified: false, hero: true };

/// Runs `toml` with `photons` photons and `seed` on 2 threads, expected-value absorption; returns
/// the flux table.
pub fn run(toml: &str, photons: u64, seed: u64) -> Flux {
    run_with(toml, photons, seed, EXPECTED)
}

/// The same with the given transport options.
pub fn run_with(toml: &str, photons: u64, seed: u64, transport: TransportOptions) -> Flux {
    let mut s = scene(toml);
    let opts =
        RunOptions { photons: Some(photons), seed: Some(seed), threads: Some(2), transport, ..Default::default() };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let result = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap();
    output::flux(&s, &result)
}

pub fn surface<'a>(f: &'a Flux, name: &str) -> &'a SurfaceRow {
    f.surfaces.iter().find(|s| s.name == name).unwrap_or_else(|| panic!("no surface {name}"))
}

/// z = (measured − expected)/stderr; panics with context when |z| > bound.
pub fn assert_z(what: &str, measured: f64, expected: f64, stderr: f64, bound: f64) {
    assert!(stderr > 0.0, "{what}: zero standard error, the test cannot judge");
    let z = (measured - expected) / stderr;
    assert!(z.abs() <= bound, "{what}: measured {measured}, expected {expected}, stderr {stderr}, z = {z:.2}");
}

/// A fresh, empty folder for one test, unique to this process, removed when the test passes
/// (kept when it fails, for a look at what the run wrote).
pub fn temp_dir(name: &str) -> TempDir {
    let d = std::env::temp_dir().join(format!("photon-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    TempDir(d)
}

/// A test's folder (`temp_dir`): a path, removed on drop unless the test is failing.
pub struct TempDir(pub std::path::PathBuf);

impl std::ops::Deref for TempDir {
    type Target = std::path::PathBuf;
    fn deref(&self) -> &std::path::PathBuf {
        &self.0
    }
}

impl AsRef<std::path::Path> for TempDir {
    fn as_ref(&self) -> &std::path::Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// The bundled Cornell box with its spectrum and mesh paths made absolute, so the text can be
/// loaded from anywhere or changed by a test.
pub fn cornell_toml() -> String {
    bundled_toml("cornell_box.toml")
}

/// A bundled scene's TOML with its relative paths made absolute.
#[allow(dead_code)]
pub fn bundled_toml(name: &str) -> String {
    let root = env!("CARGO_MANIFEST_DIR");
    std::fs::read_to_string(format!("{root}/scenes/{name}"))
        .unwrap()
        .replace("../spectra/", &format!("{root}/spectra/"))
        .replace("meshes/", &format!("{root}/scenes/meshes/"))
}

/// A minimal valid scene: one Lambertian quad floor under one quad light.
pub const BASE: &str = r#"[materials.white]
type = "lambertian"
reflectance = 0.5

[[surfaces]]
name = "floor"
material = "white"
shape = { type = "quad", corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]] }

[[lights]]
name = "lamp"
shape = { type = "quad", corners = [[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]] }
power_w = 10
"#;

/// Upper-tail probability of χ² with `k` degrees of freedom (Wilson–Hilferty: (χ²/k)^(1/3) is
/// close to normal with mean 1 − 2/(9k) and variance 2/(9k); ample for k ≥ 10 and α = 10⁻³).
pub fn chi2_tail(chi2: f64, k: f64) -> f64 {
    let v = 2.0 / (9.0 * k);
    let z = ((chi2 / k).cbrt() - (1.0 - v)) / v.sqrt();
    0.5 * erfc(z / 2f64.sqrt())
}

/// Complementary error function (Numerical Recipes' erfcc, fractional error below 1.2e-7).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let r = t
        * (-z * z - 1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277)))))))))
            .exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Upper and lower 1e-4 tail points of χ² with k degrees of freedom (Wilson–Hilferty:
/// (χ²/k)^(1/3) is nearly normal with mean 1 − 2/(9k) and variance 2/(9k); z = 3.72).
pub fn chi_square_bounds(k: f64) -> (f64, f64) {
    let (m, s) = (1.0 - 2.0 / (9.0 * k), (2.0 / (9.0 * k)).sqrt());
    (k * (m - 3.72 * s).powi(3), k * (m + 3.72 * s).powi(3))
}

/// Runs `toml` (default transport options) and returns its flux table and first far field.
pub fn run_farfield(toml: &str, photons: u64, seed: u64) -> (Flux, photon::output::farfield::FarFieldEstimate) {
    run_farfield_with(toml, photons, seed, RunOptions::default().transport)
}

/// The same with the given transport options.
pub fn run_farfield_with(
    toml: &str,
    photons: u64,
    seed: u64,
    transport: TransportOptions,
) -> (Flux, photon::output::farfield::FarFieldEstimate) {
    let mut s = scene(toml);
    let opts =
        RunOptions { photons: Some(photons), seed: Some(seed), threads: Some(2), transport, ..Default::default() };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap();
    (output::flux(&s, &r), photon::output::farfield::estimates(&s, &r).remove(0))
}

/// Σ z² over the bins with a non-zero standard error, their count, and the largest |z|, of the
/// far-field intensity (cd) against `expected(γ₀, γ₁, C)` in degrees; bins `skip` accepts are left out.
pub fn farfield_z(
    e: &photon::output::farfield::FarFieldEstimate,
    expected: impl Fn(f64, f64, f64) -> f64,
    skip: impl Fn(usize, usize) -> bool,
) -> (f64, usize, f64) {
    let [ng, nc] = e.detector.resolution;
    let (mut chi2, mut k, mut worst) = (0.0, 0, 0.0f64);
    for j in 0..nc {
        for i in 0..ng {
            if skip(i, j) {
                continue;
            }
            let (g0, g1, c) = e.detector.bin_angles(i, j);
            let (_, (cd, se)) = e.intensity(i, j);
            let want = expected(g0, g1, c);
            if se == 0.0 {
                assert!(cd == 0.0 && want < 1e-9, "bin γ {g0}–{g1}, C {c}: {cd} cd with no spread, expected {want}");
                continue;
            }
            let z = (cd - want) / se;
            chi2 += z * z;
            k += 1;
            worst = worst.max(z.abs());
        }
    }
    (chi2, k, worst)
}

/// Pearson's statistic over the cells expecting at least 5 of `n` samples (`expected` as
/// probabilities), with how many cells that is, and the observed and expected counts of the rest
/// pooled, for the caller to judge as its test requires.
pub struct Pearson {
    pub stat: f64,
    pub cells: usize,
    pub pooled_observed: f64,
    pub pooled_expected: f64,
}

pub fn pearson(observed: &[f64], expected: &[f64], n: usize) -> Pearson {
    let mut out = Pearson { stat: 0.0, cells: 0, pooled_observed: 0.0, pooled_expected: 0.0 };
    for (o, e) in observed.iter().zip(expected) {
        let e = e * n as f64;
        if e < 5.0 {
            out.pooled_observed += o;
            out.pooled_expected += e;
        } else {
            out.stat += (o - e) * (o - e) / e;
            out.cells += 1;
        }
    }
    out
}
