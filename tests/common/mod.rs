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

/// A fresh, empty folder for one test, unique to this process.
pub fn temp_dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("photon-test-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
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
