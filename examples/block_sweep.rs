//! Whether two image integrators' block comparisons behave as their z-scores claim, over many
//! seeds: the check behind the bounds of tests/integrators.rs. Each integrator renders the scene
//! once per seed; run k of the first is compared with run k+1 of the second (independent
//! streams), block by block, as the tests do: z = (a − b)/√(var_a + var_b), each block's
//! variance Σ Y_var / n⁴ from its run's own pixel errors. Printed: how many |z| exceed 3, 4 and
//! 5 against what a normal z would give, the spread of z, the worst blocks, and per block the
//! ratio of the spread of its mean over seeds to its mean reported variance.
//!
//! `cargo run --release --example block_sweep -- SCENE.toml BLOCK A:PHOTONS B:PHOTONS SEEDS [OFF]`
//!
//! A and B are `light`, `path` or `bdpt`; OFF is a comma-separated list of surface names whose
//! blocks (those any pixel's central camera ray meets first) are left out. The seeds are
//! 1000, 1001, …; runs use 2 threads. Relative paths in the scene resolve from its folder.

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

fn integrator(spec: &str) -> (Integrator, u64) {
    let (name, photons) = spec.split_once(':').expect("A and B are integrator:photons");
    let i = match name {
        "light" => Integrator::Light,
        "path" => Integrator::Path,
        "bdpt" => Integrator::Bdpt,
        _ => panic!("unknown integrator {name}: light, path or bdpt"),
    };
    (i, photons.parse().expect("photons: a number"))
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 6 {
        eprintln!("usage: block_sweep SCENE.toml BLOCK A:PHOTONS B:PHOTONS SEEDS [OFF,OFF]");
        std::process::exit(2);
    }
    let scene = load(Path::new(&args[1])).unwrap_or_else(|e| panic!("{e}"));
    let block: usize = args[2].parse().expect("BLOCK: a number");
    let (a, b) = (integrator(&args[3]), integrator(&args[4]));
    let seeds: u64 = args[5].parse().expect("SEEDS: a number");
    assert!(seeds >= 2, "at least two seeds");
    let off: Vec<&str> = args.get(6).map_or(Vec::new(), |s| s.split(',').collect());
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
                let chosen = apply_options(&mut s, &opts).unwrap_or_else(|e| panic!("{e}"));
                let r = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap_or_else(|e| panic!("{e}"));
                eprint!(".");
                blocks(&r.film.as_ref().expect("the scene has a camera").image(r.emitted_w), block)
            })
            .collect()
    };
    let (ra, rb) = (runs(a), runs(b));
    eprintln!();

    let mut zs: Vec<(f64, usize, u64)> = Vec::new();
    for k in 0..seeds as usize {
        let (x, y) = (&ra[k], &rb[(k + 1) % seeds as usize]);
        for j in (0..x.len()).filter(|&j| !skip[j]) {
            zs.push(((x[j].0 - y[j].0) / (x[j].1 + y[j].1).sqrt(), j, 1000 + k as u64));
        }
    }
    let n = zs.len() as f64;
    println!(
        "{} vs {}: {} block comparisons ({} blocks left out)",
        args[3],
        args[4],
        zs.len(),
        skip.iter().filter(|&&s| s).count()
    );
    for bound in [3.0f64, 4.0, 5.0] {
        let count = zs.iter().filter(|z| z.0.abs() > bound).count();
        // P(|Z| > b) = erfc(b/√2) ≈ √(2/π)·e^{−b²/2}/b·(1 − 1/b² + 3/b⁴) for a normal Z (the
        // asymptotic series; within 2 % for b ≥ 3).
        let tail = (2.0 / std::f64::consts::PI).sqrt() * (-bound * bound / 2.0).exp() / bound
            * (1.0 - 1.0 / bound.powi(2) + 3.0 / bound.powi(4));
        println!("  |z| > {bound}: {count} (a normal z: {:.2})", n * tail);
    }
    println!("  spread of z: {:.3}", (zs.iter().map(|z| z.0 * z.0).sum::<f64>() / n).sqrt());
    zs.sort_by(|p, q| q.0.abs().total_cmp(&p.0.abs()));
    let worst: Vec<String> = zs.iter().take(6).map(|(z, j, s)| format!("{z:.2} (block {j}, seed {s})")).collect();
    println!("  worst: {}", worst.join(", "));
    // Per block: the spread of its mean over seeds against its mean reported variance (about 1
    // where a run's own error is right; its own noise over S seeds is about √(2/(S−1))).
    for (name, r) in [(&args[3], &ra), (&args[4], &rb)] {
        let s = seeds as f64;
        let ratios: Vec<(f64, usize)> = (0..r[0].len())
            .filter(|&j| !skip[j])
            .map(|j| {
                let mean = r.iter().map(|x| x[j].0).sum::<f64>() / s;
                let spread = r.iter().map(|x| (x[j].0 - mean).powi(2)).sum::<f64>() / (s - 1.0);
                (spread / (r.iter().map(|x| x[j].1).sum::<f64>() / s), j)
            })
            .collect();
        let top = ratios.iter().copied().fold((0.0, 0), |m, x| if x.0 > m.0 { x } else { m });
        let avg = ratios.iter().map(|x| x.0).sum::<f64>() / ratios.len() as f64;
        println!(
            "  {name}: spread over seeds / reported variance, mean {avg:.2}, largest {:.2} (block {})",
            top.0, top.1
        );
    }
}
