//! Whether two image integrators' block comparisons behave as their z-scores claim, over many
//! seeds: the check behind the bounds of tests/integrators.rs. Each integrator renders the scene
//! once per seed; run k of the first is compared with run k+1 of the second (independent
//! streams), block by block, as the tests do: z = (a − b)/√(var_a + var_b), each block's
//! variance Σ Y_var / n⁴ from its run's own pixel errors. Printed: how many |z| exceed 3, 4 and
//! 5 against what a normal z would give, the mean and RMS of z, the worst blocks, and per block the
//! ratio of the spread of its mean over seeds to its mean reported variance.
//!
//! `cargo run --release --example block_sweep -- SCENE.toml BLOCK A:PHOTONS B:PHOTONS SEEDS [OFF,…]`
//!
//! A and B are `light`, `path` or `bdpt`; OFF is a comma-separated list of surface names whose
//! blocks (those any pixel's central camera ray meets first) are left out. The seeds are
//! 1000, 1001, …; runs use 2 threads. Relative paths in the scene resolve from its folder; the
//! tests' own scenes are written by `SAVE_SCENES=dir cargo test --release --test integrators`.
//! A tail and a bias both raise the |z| counts; a bias also moves the mean z away from 0.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use photon::detectors::film::{CameraModel, Image};
use photon::geometry::NO_PRIM;
use photon::integrators::camera::Integrator;
use photon::run::{apply_options, simulate, RunOptions};
use photon::scene::{load, Scene};

/// Each block's mean Y and its variance (Σ Y_var / n⁴), row-major.
fn blocks(img: &Image, block: usize) -> Vec<(f64, f64)> {
    let (bw, bh) = (img.width / block, img.height / block);
    let mut out = vec![(0.0, 0.0); bw * bh];
    for p in 0..img.width * img.height {
        let b = (p / img.width / block) * bw + (p % img.width) / block;
        out[b].0 += img.xyz[[p, 1]] as f64;
        out[b].1 += img.y_var[p] as f64;
    }
    let n = (block * block) as f64;
    out.iter().map(|&(s, v)| (s / n, v / (n * n))).collect()
}

/// The blocks in which some pixel's central camera ray first meets a surface named in `off`.
fn excluded(scene: &Scene, block: usize, off: &[&str]) -> Vec<bool> {
    let cam = CameraModel::new(scene.camera.as_ref().expect("the scene has a camera"));
    let (w, h) = (cam.width, cam.height);
    let mut out = vec![false; (w / block) * (h / block)];
    for p in 0..cam.pixels() {
        let (row, col) = (p / w, p % w);
        if row / block >= h / block || col / block >= w / block {
            continue;
        }
        let d = cam.ray_direction(p, 0.5, 0.5);
        if let Some(hit) = scene.geometry.intersect(cam.position, d, f32::INFINITY, NO_PRIM) {
            let name = &scene.surfaces[scene.geometry.surface[hit.prim as usize] as usize].name;
            if off.contains(&name.as_str()) {
                out[(row / block) * (w / block) + col / block] = true;
            }
        }
    }
    out
}

fn fail(message: &str) -> ! {
    eprintln!("block_sweep: {message}");
    eprintln!("usage: block_sweep SCENE.toml BLOCK A:PHOTONS B:PHOTONS SEEDS [OFF,…]");
    std::process::exit(2)
}

fn integrator(spec: &str) -> (Integrator, u64) {
    let Some((name, photons)) = spec.split_once(':') else { fail(&format!("{spec}: not integrator:photons")) };
    let i = match name {
        "light" => Integrator::Light,
        "path" => Integrator::Path,
        "bdpt" => Integrator::Bdpt,
        _ => fail(&format!("unknown integrator {name}: light, path or bdpt")),
    };
    match photons.parse() {
        Ok(n) if n > 0 => (i, n),
        _ => fail(&format!("{spec}: photons must be a positive whole number")),
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if !(6..=7).contains(&args.len()) {
        fail("five or six arguments");
    }
    let scene = load(Path::new(&args[1])).unwrap_or_else(|e| fail(&e.to_string()));
    let Some(camera) = scene.camera.as_ref() else { fail("the scene has no camera") };
    let (width, height) = (camera.resolution[0] as usize, camera.resolution[1] as usize);
    let block: usize = match args[2].parse() {
        Ok(b) if b > 0 && width % b == 0 && height % b == 0 => b,
        _ => fail(&format!("BLOCK {} must divide the image's {width} × {height} pixels", args[2])),
    };
    let (a, b) = (integrator(&args[3]), integrator(&args[4]));
    let seeds: u64 = match args[5].parse() {
        Ok(n) if n >= 2 => n,
        _ => fail("SEEDS: a whole number, at least 2"),
    };
    let off: Vec<&str> = args.get(6).map_or(Vec::new(), |s| s.split(',').collect());
    if let Some(name) = off.iter().find(|&&n| !scene.surfaces.iter().any(|s| s.name == n)) {
        fail(&format!("OFF: the scene has no surface {name}"));
    }
    let skip = excluded(&scene, block, &off);

    let runs = |(integrator, photons): (Integrator, u64)| -> Vec<Vec<(f64, f64)>> {
        (0..seeds)
            .map(|k| {
                let mut s = scene.clone();
                let opts = RunOptions {
                    photons: Some(photons),
                    seed: Some(1000 + k),
                    threads: Some(2),
                    integrator: Some(integrator),
                    ..Default::default()
                };
                let chosen = apply_options(&mut s, &opts).unwrap_or_else(|e| fail(&e.to_string()));
                let r = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap_or_else(|e| fail(&e.to_string()));
                eprint!(".");
                blocks(&r.film.as_ref().expect("the scene has a camera").image(r.emitted_w), block)
            })
            .collect()
    };
    let (ra, rb) = (runs(a), runs(b));
    eprintln!();

    let (mut zs, mut dark): (Vec<(f64, usize, u64)>, usize) = (Vec::new(), 0);
    for k in 0..seeds as usize {
        let (x, y) = (&ra[k], &rb[(k + 1) % seeds as usize]);
        for j in (0..x.len()).filter(|&j| !skip[j]) {
            // Two black blocks (no error either) make no comparison.
            if x[j].1 + y[j].1 > 0.0 {
                zs.push(((x[j].0 - y[j].0) / (x[j].1 + y[j].1).sqrt(), j, 1000 + k as u64));
            } else {
                dark += 1;
            }
        }
    }
    if zs.is_empty() {
        fail("no block has an error to compare by");
    }
    let n = zs.len() as f64;
    let left_out = skip.iter().filter(|&&s| s).count();
    println!("{} vs {}: {} block comparisons ({left_out} blocks left out, {dark} black)", args[3], args[4], zs.len());
    for bound in [3.0f64, 4.0, 5.0] {
        let count = zs.iter().filter(|z| z.0.abs() > bound).count();
        // P(|Z| > b) = erfc(b/√2) ≈ √(2/π)·e^{−b²/2}/b·(1 − 1/b² + 3/b⁴) for a normal Z (the
        // asymptotic series; within 2 % for b ≥ 3).
        let tail = (2.0 / std::f64::consts::PI).sqrt() * (-bound * bound / 2.0).exp() / bound
            * (1.0 - 1.0 / bound.powi(2) + 3.0 / bound.powi(4));
        println!("  |z| > {bound}: {count} (a normal z: {:.2})", n * tail);
    }
    let mean = zs.iter().map(|z| z.0).sum::<f64>() / n;
    println!("  z: mean {mean:.3}, spread (RMS) {:.3}", (zs.iter().map(|z| z.0 * z.0).sum::<f64>() / n).sqrt());
    zs.sort_by(|p, q| q.0.abs().total_cmp(&p.0.abs()));
    let worst: Vec<String> = zs.iter().take(6).map(|(z, j, s)| format!("{z:.2} (block {j}, seed {s})")).collect();
    println!("  worst: {}", worst.join(", "));
    // Per block: the spread of its mean over seeds against its mean reported variance: about 1
    // where a run's own error is right, give or take √(2/(S−1)), so the largest of many blocks
    // exceeds 1 by two or three times that by chance.
    for (name, r) in [(&args[3], &ra), (&args[4], &rb)] {
        let s = seeds as f64;
        let ratios: Vec<(f64, usize)> = (0..r[0].len())
            .filter(|&j| !skip[j])
            .map(|j| {
                let mean = r.iter().map(|x| x[j].0).sum::<f64>() / s;
                let spread = r.iter().map(|x| (x[j].0 - mean).powi(2)).sum::<f64>() / (s - 1.0);
                (spread / (r.iter().map(|x| x[j].1).sum::<f64>() / s), j)
            })
            .filter(|x| x.0.is_finite())
            .collect();
        let Some(&top) = ratios.iter().max_by(|p, q| p.0.total_cmp(&q.0)) else { continue };
        let avg = ratios.iter().map(|x| x.0).sum::<f64>() / ratios.len() as f64;
        let noise = (2.0 / (s - 1.0)).sqrt();
        println!(
            "  {name}: spread over seeds / reported variance, mean {avg:.2}, largest {:.2} (block {}; ±{noise:.2} by chance)",
            top.0, top.1
        );
    }
}
