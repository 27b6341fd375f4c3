//! What each layer of photon's grey photon loop costs (issue #23): the loop of
//! `../shared/bench/embree/mini_ptracer.cpp` written on photon's own emission and ray cast, then
//! photon's layers added one at a time, each level timed on one thread.
//!
//! `cargo run --release --example layer_costs -- SCENE.toml [photons] [rounds]`
//!
//! Levels (each includes the ones before):
//! * `emission`: photon's `Emitter::emit` alone, no tracing;
//! * `mini`: emission, photon's ray cast, and the mini tracer's scattering: the hit point
//!   o + t·d, a cosine direction about the side the photon came from, the origin 10⁻³ along the
//!   normal, expected-value absorption with roulette below 0.1, f32 per-history tallies;
//! * `robust`: the hit point from barycentrics with its error bound and `Geometry::spawn`;
//! * `bsdf`: the material through `Bsdf::new`, `albedo` and `sample`;
//! * `tallies`: `HistoryScores` per history, as the photon loop keeps them.
//!
//! Compare with `photon run SCENE --no-image --estimator expected --threads 1` on the same
//! machine (bench/embree.sh's grey box, `cornell_grey.toml`, is what the mini tracer traces).

use std::path::Path;
use std::time::Instant;

use glam::Vec3A;
use photon::bsdf::{Bsdf, Mode, Prepared};
use photon::detectors::tally::{HistoryScores, Moments};
use photon::lights::{EmitSample, Emitter};
use photon::sampling::{cosine_hemisphere, Sampler};
use photon::scene::{load, Material, Scene};

#[derive(Clone, Copy, PartialEq, PartialOrd)]
enum Level {
    Emission,
    Mini,
    Robust,
    Bsdf,
    Tallies,
}

/// Traces `photons` at `level`; returns ns per photon, rays per photon and the absorbed share.
fn trace(scene: &Scene, photons: u64, level: Level) -> (f64, f64, f64) {
    let geo = &scene.geometry;
    let emitter = Emitter::new(scene);
    let prepared = Prepared::for_scene(scene);
    let ns = scene.surfaces.len();
    let materials: Vec<&Material> = (0..ns).map(|s| scene.material_of(s)).collect();
    let grey = |s: usize, n: Vec3A| Bsdf::<1>::new::<false>(materials[s], &prepared[s], &[f64::NAN], n, || Vec3A::X);
    let albedo: Vec<f64> = (0..ns).map(|s| grey(s, Vec3A::Z).albedo(Vec3A::Z).0[0]).collect();
    let mut s = Sampler::for_batch(1, 0);
    let (mut inc, mut ab) = (vec![0f32; ns], vec![0f32; ns]);
    let (mut inc_m, mut ab_m) = (vec![Moments::default(); ns], vec![Moments::default(); ns]);
    let (mut incident, mut absorbed) = (HistoryScores::new(ns), HistoryScores::new(ns));
    let (mut rays, mut born) = (0u64, Vec3A::ZERO);
    let start = Instant::now();
    for _ in 0..photons {
        let u: EmitSample = std::array::from_fn(|_| s.uniform());
        let birth = emitter.emit::<false>(geo, &u);
        if level == Level::Emission {
            born += birth.origin + birth.dir;
            continue;
        }
        let (mut origin, mut dir, mut skip, mut w) = (birth.origin, birth.dir, birth.prim, 1.0f64);
        let mut score = |surface: u32, x: f64, incident_score: bool| {
            let (scores, plain) = if incident_score { (&mut incident, &mut inc) } else { (&mut absorbed, &mut ab) };
            if level >= Level::Tallies {
                scores.add(surface, x);
            } else {
                plain[surface as usize] += x as f32;
            }
        };
        loop {
            rays += 1;
            let Some(hit) = geo.intersect(origin, dir, f32::INFINITY, skip) else { break };
            let surface = geo.surface_of(hit.prim as usize);
            let n = geo.normal(hit.prim as usize);
            score(surface, w, true);
            let (p, err) =
                if level >= Level::Robust { geo.hit_point(&hit) } else { (origin + hit.t * dir, Vec3A::ZERO) };
            let (a, bsdf) = if level >= Level::Bsdf {
                let bsdf = grey(surface as usize, n).shaded(n);
                (bsdf.albedo(-dir).0[0], Some(bsdf))
            } else {
                (albedo[surface as usize], None)
            };
            if w >= 0.1 {
                score(surface, w * (1.0 - a), false);
                if a <= 0.0 {
                    break;
                }
                w *= a;
            } else if !(s.uniform() < a) {
                score(surface, w, false);
                break;
            }
            let new_dir = match &bsdf {
                Some(b) => match b.sample(-dir, Mode::Importance, &mut s) {
                    Some(sampled) => sampled.wi,
                    None => break,
                },
                None => cosine_hemisphere(if dir.dot(n) > 0.0 { -n } else { n }, s.uniform_f32(), s.uniform_f32()),
            };
            origin = if level >= Level::Robust {
                geo.spawn(p, err, hit.prim, new_dir)
            } else {
                p + 1e-3 * if new_dir.dot(n) > 0.0 { n } else { -n }
            };
            (dir, skip) = (new_dir, hit.prim);
        }
        if level >= Level::Tallies {
            incident.flush(&mut inc_m);
            absorbed.flush(&mut ab_m);
        } else {
            for k in 0..ns {
                inc_m[k].add_history(std::mem::take(&mut inc[k]) as f64);
                ab_m[k].add_history(std::mem::take(&mut ab[k]) as f64);
            }
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    // Keeps the emission level's births from being optimised away.
    std::hint::black_box(born);
    let absorbed_share = ab_m.iter().map(|m| m.sum).sum::<f64>() / photons as f64;
    (seconds * 1e9 / photons as f64, rays as f64 / photons as f64, absorbed_share)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: layer_costs SCENE.toml [photons] [rounds]");
        std::process::exit(2);
    };
    let scene = load(Path::new(path)).unwrap_or_else(|e| {
        eprintln!("{e}");
        std::process::exit(2)
    });
    let number = |k: usize, default: u64| args.get(k).map_or(Ok(default), |s| s.parse::<u64>());
    let (Ok(photons), Ok(rounds)) = (number(2, 2_000_000), number(3, 3)) else {
        eprintln!("photons and rounds are whole numbers");
        std::process::exit(2);
    };
    let levels = [
        ("emission", Level::Emission),
        ("mini", Level::Mini),
        ("robust", Level::Robust),
        ("bsdf", Level::Bsdf),
        ("tallies", Level::Tallies),
    ];
    for round in 0..rounds {
        for (name, level) in levels {
            let (ns, rays, absorbed) = trace(&scene, photons, level);
            println!("round {round} {name:9} {ns:7.1} ns/photon  {rays:.3} rays/photon  absorbed {absorbed:.5}");
        }
    }
}
