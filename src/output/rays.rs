//! Ray-set outputs: `rays_<name>.npy`, every arrival on a ray-set detector's surface as a row
//! x, y, z (the scene's unit and frame), dx, dy, dz (unit), wavelength_nm (0 in grey transport)
//! and power_w (the photon's weight × the run's watts per weight), in photon order: the file a
//! light with `shape = { type = "rays" }` emits again (`scene::rays`).

use std::path::{Path, PathBuf};

use crate::error::Error;
use crate::run::RunResult;
use crate::scene::Scene;

pub fn file_name(detector: &str) -> String {
    format!("rays_{}.npy", crate::scene::map::file_stem(detector))
}

/// Detector `k`'s rows.
pub fn rows(scene: &Scene, r: &RunResult, k: usize) -> Vec<[f64; 8]> {
    let w = r.tallies.watts_per_weight(r.emitted_w);
    r.tallies
        .rays
        .iter()
        .filter(|a| a.detector as usize == k)
        .map(|a| {
            let p = scene.file_coordinates(glam::DVec3::from(a.position));
            let d = a.direction.map(f64::from);
            let lambda = if a.lambda_nm.is_finite() { a.lambda_nm } else { 0.0 };
            [p.x, p.y, p.z, d[0], d[1], d[2], lambda, a.weight * w]
        })
        .collect()
}

pub fn write_npy(dir: &Path, scene: &Scene, r: &RunResult, k: usize) -> Result<PathBuf, Error> {
    let rows = rows(scene, r, k);
    let bytes = crate::output::volume::npy(&[rows.len(), 8], rows.iter().flatten().copied());
    crate::output::write_atomic(dir, &file_name(&scene.ray_detectors[k].name), &bytes)
}
