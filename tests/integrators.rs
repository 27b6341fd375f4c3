//! The three image integrators (light tracing, path tracing, BDPT) estimate the same image: they
//! are checked against each other on the Cornell box, on a mirror seen by the camera, and on a
//! glass sphere's caustic.
//!
//! Statistical bounds. Each comparison is a z-score of a difference of two independent estimates
//! (different integrators use different random streams), with the standard error from the
//! images' Y_var. A block's mean over 256 pixels is close to normal; |z| < 4 has a false-failure
//! chance of 6e-5 per comparison, so the 3 × 64 block comparisons of one image fail falsely
//! with probability about 1e-2 at worst; the seeds are fixed, so a pass is reproducible.

mod common;
use common::{cornell_toml, scene};

use std::sync::atomic::AtomicBool;

use photon::camera_paths::Integrator;
use photon::film::Image;
use photon::run::{apply_options, simulate, RunOptions};

/// Renders `toml` with `integrator` and returns the image and its mean Y with standard error.
fn render(toml: &str, integrator: Integrator, photons: u64, seed: u64) -> (Image, (f64, f64), f64) {
    let mut s = scene(toml);
    let opts = RunOptions {
        photons: Some(photons),
        seed: Some(seed),
        threads: Some(2),
        integrator: Some(integrator),
        ..Default::default()
    };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap();
    let film = r.film.as_ref().expect("the scene has a camera");
    (film.image(r.emitted_w), film.mean_y(r.emitted_w), r.wall_seconds)
}

/// Mean Y and its variance over each `block`×`block` tile, in row-major tile order. The
/// variance is Σ Y_var / block⁴, treating pixels as independent.
fn blocks(img: &Image, block: usize) -> Vec<(f64, f64)> {
    let (bw, bh) = (img.width / block, img.height / block);
    let mut out = vec![(0.0, 0.0); bw * bh];
    for p in 0..img.width * img.height {
        let (row, col) = (p / img.width, p % img.width);
        let b = (row / block) * bw + col / block;
        out[b].0 += img.xyz[[p, 1]] as f64;
        out[b].1 += img.y_var[p] as f64;
    }
    let n = (block * block) as f64;
    out.iter().map(|&(s, v)| (s / n, v / (n * n))).collect()
}

fn cornell(res: u32) -> String {
    cornell_toml().replace("resolution = [512, 512]", &format!("resolution = [{res}, {res}]"))
}

#[test]
fn cornell_box_light_path_and_bdpt_images_agree() {
    // 128² pixels: 64 blocks of 16×16. The light tracer gets twice the photons: its splats are
    // heavy-tailed near the camera (the floor's bottom rows), and a single photon splats into
    // several pixels of one block, so its Y_var-based block error is slightly optimistic.
    let toml = cornell(128);
    let photons = 2_000_000;
    let runs: Vec<(Integrator, Image, (f64, f64))> = [Integrator::Light, Integrator::Path, Integrator::Bdpt]
        .into_iter()
        .map(|i| {
            let n = if i == Integrator::Light { 2 * photons } else { photons };
            let (img, mean, _) = render(&toml, i, n, 11);
            (i, img, mean)
        })
        .collect();
    for a in 0..3 {
        for b in a + 1..3 {
            let (ia, img_a, mean_a) = &runs[a];
            let (ib, img_b, mean_b) = &runs[b];
            let z = (mean_a.0 - mean_b.0) / (mean_a.1.powi(2) + mean_b.1.powi(2)).sqrt();
            assert!(z.abs() < 4.0, "{ia:?} mean Y {mean_a:?} vs {ib:?} {mean_b:?}: z = {z:.2}");
            assert!(mean_a.0 > 0.0 && mean_a.1 > 0.0, "{ia:?}: {mean_a:?}");
            for (k, (x, y)) in blocks(img_a, 16).iter().zip(&blocks(img_b, 16)).enumerate() {
                let z = (x.0 - y.0) / (x.1 + y.1).sqrt();
                assert!(z.abs() < 4.0, "block {k}: {ia:?} {x:?} vs {ib:?} {y:?}: z = {z:.2}");
            }
        }
    }
}
