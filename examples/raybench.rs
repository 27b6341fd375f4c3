//! Incoherent single-ray casting rates of photon's own BVH, on the geometry and ray distribution
//! of `../shared/bench/embree/raybench.cpp`, so that `bench/embree.sh` can print the two side by
//! side: the Cornell box (5 walls, the light quad and the two OBJ blocks: 32 triangles) or the
//! same box with an icosphere of 8 subdivisions (1 310 732 triangles); ray origins uniform by area
//! over all triangles, 1e-3 mm along the data's normal, cosine-distributed about it; shadow rays
//! from the camera-facing origins inside the camera's frustum to the camera, trimmed by 1e-5.
//!
//! `cargo run --release --example raybench -- cornell|sphere [rays_millions] [rounds]`
//!
//! Each ray skips the triangle it starts on, and a closest-hit ray the flat leaf of it too
//! (`Geometry::intersect_leaving`: its origin lies off that plane, on the side it leaves by), as
//! the photon loop does. The closest-hit rays are cast once one by one and once 32 at a time
//! (`Geometry::intersect_many`: walked in turns in a tree that outgrows the caches, with the same
//! hits). Then a minimal grey photon loop on the same geometry (`grey_loop`) runs one photon at a
//! time and with 32 in flight, their rays cast as one group: what a wavefront loop would buy.
//! CPU time is this thread's (from /proc/thread-self/schedstat on Linux, else wall time).

use glam::{DVec3, Vec3A};
use photon::geometry::{Geometry, Hit, RayQuery, INTERLEAVE, NO_PRIM};
use rand_xoshiro::rand_core::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::time::Instant;

fn quad(t: &mut Vec<[DVec3; 3]>, c: [[f64; 3]; 4]) {
    let [a, b, c, d] = c.map(DVec3::from_array);
    t.push([a, b, c]);
    t.push([a, c, d]);
}

fn load_obj(t: &mut Vec<[DVec3; 3]>, path: &str) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {path}: {e}"));
    let mut v = Vec::new();
    for line in text.lines() {
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let p: Vec<f64> = w.map(|x| x.parse().expect("vertex")).collect();
                v.push(DVec3::new(p[0], p[1], p[2]));
            }
            Some("f") => {
                let idx: Vec<usize> =
                    w.map(|x| x.split('/').next().unwrap().parse::<usize>().expect("face") - 1).collect();
                for i in 1..idx.len() - 1 {
                    t.push([v[idx[0]], v[idx[i]], v[idx[i + 1]]]);
                }
            }
            _ => {}
        }
    }
}

/// raybench.cpp's icosphere: the unit icosahedron, each face split into 4 per level, projected
/// onto the sphere.
fn icosphere(level: u32, c: DVec3, r: f64) -> Vec<[DVec3; 3]> {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let raw = [
        [-1.0, phi, 0.0],
        [1.0, phi, 0.0],
        [-1.0, -phi, 0.0],
        [1.0, -phi, 0.0],
        [0.0, -1.0, phi],
        [0.0, 1.0, phi],
        [0.0, -1.0, -phi],
        [0.0, 1.0, -phi],
        [phi, 0.0, -1.0],
        [phi, 0.0, 1.0],
        [-phi, 0.0, -1.0],
        [-phi, 0.0, 1.0],
    ];
    let faces = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let v: Vec<DVec3> = raw.iter().map(|p| DVec3::from_array(*p).normalize()).collect();
    let mut t: Vec<[DVec3; 3]> = faces.iter().map(|f| [v[f[0]], v[f[1]], v[f[2]]]).collect();
    for _ in 0..level {
        let mut n = Vec::with_capacity(t.len() * 4);
        for &[a, b, c] in &t {
            let (ab, bc, ca) = ((0.5 * (a + b)).normalize(), (0.5 * (b + c)).normalize(), (0.5 * (c + a)).normalize());
            n.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        t = n;
    }
    t.into_iter().map(|q| q.map(|p| c + r * p)).collect()
}

fn scene(which: &str) -> Vec<[DVec3; 3]> {
    let mut t = Vec::new();
    quad(&mut t, [[552.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 559.2], [549.6, 0.0, 559.2]]);
    quad(&mut t, [[556.0, 548.8, 0.0], [556.0, 548.8, 559.2], [0.0, 548.8, 559.2], [0.0, 548.8, 0.0]]);
    quad(&mut t, [[549.6, 0.0, 559.2], [0.0, 0.0, 559.2], [0.0, 548.8, 559.2], [556.0, 548.8, 559.2]]);
    quad(&mut t, [[0.0, 0.0, 559.2], [0.0, 0.0, 0.0], [0.0, 548.8, 0.0], [0.0, 548.8, 559.2]]);
    quad(&mut t, [[552.8, 0.0, 0.0], [549.6, 0.0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0.0]]);
    quad(&mut t, [[343.0, 548.7, 227.0], [343.0, 548.7, 332.0], [213.0, 548.7, 332.0], [213.0, 548.7, 227.0]]);
    let meshes = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/meshes");
    if which == "cornell" {
        load_obj(&mut t, &format!("{meshes}/cornell_short_block.obj"));
        load_obj(&mut t, &format!("{meshes}/cornell_tall_block.obj"));
    } else {
        t.extend(icosphere(sphere_level(), DVec3::new(278.0, 160.5, 280.0), 160.0));
    }
    t
}

struct Ray {
    o: Vec3A,
    d: Vec3A,
    t_max: f32,
    /// The triangle the ray starts on, as given (before the BVH's reordering).
    from: usize,
}

fn uniform(rng: &mut Xoshiro256PlusPlus) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// raybench.cpp's make_rays, with this crate's generator.
fn rays(tris: &[[DVec3; 3]], n: usize, seed: u64) -> (Vec<Ray>, Vec<Ray>) {
    let mut cdf = Vec::with_capacity(tris.len());
    let mut acc = 0.0;
    for [a, b, c] in tris {
        acc += 0.5 * (*b - *a).cross(*c - *a).length();
        cdf.push(acc);
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let (mut bounce, mut shadow) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let cam = DVec3::new(278.0, 273.0, -800.0);
    let tan_half = (0.5 * 39.3077f64).to_radians().tan();
    for _ in 0..n {
        let u = uniform(&mut rng) * acc;
        let i = cdf.partition_point(|&c| c < u).min(tris.len() - 1);
        let [a, b, c] = tris[i];
        let (su, v) = (uniform(&mut rng).sqrt(), uniform(&mut rng));
        let p = (1.0 - su) * a + su * (1.0 - v) * b + su * v * c;
        let nrm = (b - a).cross(c - a).normalize();
        let sgn = 1f64.copysign(nrm.z);
        let aa = -1.0 / (sgn + nrm.z);
        let bb = nrm.x * nrm.y * aa;
        let tx = DVec3::new(1.0 + sgn * nrm.x * nrm.x * aa, sgn * bb, -sgn * nrm.x);
        let ty = DVec3::new(bb, sgn + nrm.y * nrm.y * aa, -nrm.y);
        let (r, ph) = (uniform(&mut rng).sqrt(), 2.0 * std::f64::consts::PI * uniform(&mut rng));
        let (x, y) = (r * ph.cos(), r * ph.sin());
        let z = (1.0 - x * x - y * y).max(0.0).sqrt();
        let d = (x * tx + y * ty + z * nrm).normalize();
        let o = p + 1e-3 * nrm;
        bounce.push(Ray { o: o.as_vec3a(), d: d.as_vec3a(), t_max: f32::INFINITY, from: i });
        let tc = cam - p;
        if tc.z < 0.0 && (tc.x / tc.z).abs() <= tan_half && (tc.y / tc.z).abs() <= tan_half && nrm.dot(tc) > 0.0 {
            let sd = (cam - o).normalize();
            let len = ((cam - o).length() * (1.0 - 1e-5)) as f32;
            shadow.push(Ray { o: o.as_vec3a(), d: sd.as_vec3a(), t_max: len, from: i });
        }
    }
    (bounce, shadow)
}

/// This thread's CPU time in seconds.
fn thread_cpu() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    Some(s.split_whitespace().next()?.parse::<u64>().ok()? as f64 * 1e-9)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Seconds of this thread's CPU time (else wall time) that `f` takes.
fn timed(f: impl FnOnce()) -> f64 {
    let (wall0, cpu0) = (Instant::now(), thread_cpu());
    f();
    let wall = wall0.elapsed().as_secs_f64();
    match (cpu0, thread_cpu()) {
        (Some(a), Some(b)) => b - a,
        _ => wall,
    }
}

/// Per-round figures in seconds as "median [min, max]" in ns.
fn spread_ns(xs: &[f64]) -> String {
    let (lo, hi) = xs.iter().fold((f64::INFINITY, 0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    format!("{:8.1} [{:.1}, {:.1}]", median(xs.to_vec()) * 1e9, lo * 1e9, hi * 1e9)
}

/// The sphere's subdivision level: 8 (as the reference programs build it), or `LEVEL` from the
/// environment, to compare a sphere that fits the caches with one that does not
/// (bench/embree.sh passes the same level to Embree's programs).
fn sphere_level() -> u32 {
    match std::env::var("LEVEL") {
        Ok(v) => match v.parse() {
            Ok(level) if level <= 10 => level,
            _ => {
                eprintln!("raybench: LEVEL must be a whole number from 0 to 10, not {v:?}");
                std::process::exit(2);
            }
        },
        Err(_) => 8,
    }
}

/// A photon of the minimal grey loop (`grey_loop`): its ray, weight and own random stream.
struct Photon {
    o: Vec3A,
    d: Vec3A,
    leaving: u32,
    weight: f32,
    rng: Xoshiro256PlusPlus,
}

/// Albedo of every surface of the minimal loop but the lamp's (which absorbs all).
const ALBEDO: f32 = 0.7;

/// Photon `index` leaving the lamp (the given triangles 10 and 11, facing down): uniform by
/// area, cosine-distributed, from its own stream.
fn emit(geo: &Geometry, lamp: [u32; 2], index: u64) -> Photon {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(index);
    let mut u = || uniform(&mut rng) as f32;
    let prim = lamp[(u() < 0.5) as usize];
    let [a, b, c] = geo.verts(prim as usize);
    let (su, v) = (u().sqrt(), u());
    let bary = [1.0 - su, su * (1.0 - v), su * v];
    let p = a * bary[0] + b * bary[1] + c * bary[2];
    let d = photon::sampling::cosine_hemisphere(Vec3A::NEG_Y, u(), u());
    let o = geo.spawn_from(p, p.abs() * 1e-6, prim, bary, d);
    Photon { o, d, leaving: prim, weight: 1.0, rng }
}

/// One hit (or escape) of a photon: expected-value absorption into `absorbed`, roulette below
/// 0.1, a cosine bounce. False when the photon's history has ended.
fn bounce(geo: &Geometry, lamp: [u32; 2], ph: &mut Photon, hit: Option<Hit>, absorbed: &mut f64) -> bool {
    let Some(hit) = hit else { return false };
    if lamp.contains(&hit.prim) {
        // The lamp absorbs all.
        *absorbed += ph.weight as f64;
        return false;
    }
    *absorbed += (ph.weight * (1.0 - ALBEDO)) as f64;
    ph.weight *= ALBEDO;
    if ph.weight < 0.1 {
        if uniform(&mut ph.rng) < 0.5 {
            return false;
        }
        ph.weight *= 2.0;
    }
    let (p, err) = geo.hit_point(&hit);
    let n = geo.normal(hit.prim as usize);
    let n = if n.dot(ph.d) > 0.0 { -n } else { n };
    let (u1, u2) = (uniform(&mut ph.rng) as f32, uniform(&mut ph.rng) as f32);
    ph.d = photon::sampling::cosine_hemisphere(n, u1, u2);
    ph.o = geo.spawn_from(p, err, hit.prim, hit.b, ph.d);
    ph.leaving = hit.prim;
    true
}

/// The minimal grey loop over `photons` photons, one photon at a time (`together` = 1) or with
/// `together` photons in flight whose rays are cast as one group (`Geometry::intersect_many`):
/// the same photons either way (each its own stream), so the same absorbed total up to the
/// order of the sums. Returns the absorbed weight.
fn grey_loop(geo: &Geometry, lamp: [u32; 2], photons: u64, together: usize) -> f64 {
    let mut absorbed = 0.0;
    if together == 1 {
        for index in 0..photons {
            let mut ph = emit(geo, lamp, index);
            loop {
                let hit = geo.intersect_leaving(ph.o, ph.d, f32::INFINITY, ph.leaving);
                if !bounce(geo, lamp, &mut ph, hit, &mut absorbed) {
                    break;
                }
            }
        }
        return absorbed;
    }
    let mut next = 0u64;
    let mut flight: Vec<Photon> = Vec::with_capacity(together);
    let mut rays = Vec::with_capacity(together);
    let mut hits = vec![None; together];
    loop {
        while flight.len() < together && next < photons {
            flight.push(emit(geo, lamp, next));
            next += 1;
        }
        if flight.is_empty() {
            return absorbed;
        }
        rays.clear();
        rays.extend(flight.iter().map(|p| RayQuery {
            origin: p.o,
            dir: p.d,
            t_max: f32::INFINITY,
            leaving: p.leaving,
        }));
        geo.intersect_many(&rays, &mut hits[..rays.len()]);
        let mut hit = hits.iter();
        flight.retain_mut(|p| bounce(geo, lamp, p, *hit.next().expect("a hit each"), &mut absorbed));
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let which = args.get(1).map(String::as_str).unwrap_or("cornell");
    if which != "cornell" && which != "sphere" {
        eprintln!("usage: raybench cornell|sphere [rays_millions] [rounds]");
        std::process::exit(2);
    }
    let n = (args.get(2).map_or(4.0, |s| s.parse::<f64>().expect("rays_millions")) * 1e6) as usize;
    let rounds: usize = args.get(3).map_or(7, |s| s.parse().expect("rounds"));
    let tris = scene(which);
    let built = Instant::now();
    // Each triangle its own surface, so that a BVH primitive tells its given index.
    let geo = Geometry::build(tris.iter().map(|t| t.map(|p| p.as_vec3a())).collect(), (0..tris.len() as u32).collect())
        .expect("build");
    let build_s = built.elapsed().as_secs_f64();
    let mut prim_of = vec![NO_PRIM; tris.len()];
    for prim in 0..geo.len() {
        prim_of[geo.surface_of(prim) as usize] = prim as u32;
    }
    let (bounce, shadow) = rays(&tris, n, 12345);
    println!(
        "scene {which}: {} triangles; {} rays, {} shadow rays; photon BVH built in {build_s:.3} s",
        tris.len(),
        bounce.len(),
        shadow.len()
    );
    // Each case casts all its rays and counts those that hit (closest) or are blocked (shadow).
    type Case<'a> = (&'a str, &'a [Ray], Box<dyn Fn(&[Ray]) -> usize + 'a>);
    let query = |r: &Ray| RayQuery { origin: r.o, dir: r.d, t_max: r.t_max, leaving: prim_of[r.from] };
    let cases: [Case; 3] = [
        (
            "photon intersect (closest)",
            &bounce,
            Box::new(|rays: &[Ray]| {
                rays.iter().filter(|r| geo.intersect_leaving(r.o, r.d, r.t_max, prim_of[r.from]).is_some()).count()
            }),
        ),
        (
            "photon intersect_many (closest)",
            &bounce,
            // The same rays, INTERLEAVE at a time walked in turns (`Geometry::intersect_many`).
            Box::new(|rays: &[Ray]| {
                let mut hits = [None; INTERLEAVE];
                let unset = RayQuery { origin: Vec3A::ZERO, dir: Vec3A::Z, t_max: 0.0, leaving: NO_PRIM };
                let mut queries = [unset; INTERLEAVE];
                let mut count = 0;
                for group in rays.chunks(INTERLEAVE) {
                    for (q, r) in queries.iter_mut().zip(group) {
                        *q = query(r);
                    }
                    let n = group.len();
                    geo.intersect_many(&queries[..n], &mut hits[..n]);
                    count += hits[..n].iter().filter(|h| h.is_some()).count();
                }
                count
            }),
        ),
        (
            "photon unoccluded (shadow)",
            &shadow,
            Box::new(|rays: &[Ray]| {
                rays.iter().filter(|r| !geo.unoccluded(r.o, r.d, r.t_max, [prim_of[r.from], NO_PRIM])).count()
            }),
        ),
    ];
    let mut cpu = vec![Vec::new(); cases.len()];
    let mut hits = vec![0usize; cases.len()];
    for round in 0..=rounds {
        for (k, (_, rays, cast)) in cases.iter().enumerate() {
            let secs = timed(|| hits[k] = cast(rays));
            // Round 0 warms the caches and is not counted.
            if round > 0 {
                cpu[k].push(secs / rays.len() as f64);
            }
        }
    }
    println!("{rounds} rounds; CPU ns per ray (median [min, max]) and the share of rays that hit / are blocked");
    for (k, (name, rays, _)) in cases.iter().enumerate() {
        println!(
            "{name:<32} ns/ray {}  hit/blk% {:6.2}",
            spread_ns(&cpu[k]),
            100.0 * hits[k] as f64 / rays.len() as f64
        );
    }
    // The minimal grey loop, one photon at a time and INTERLEAVE in flight, alternated.
    let lamp = [prim_of[10], prim_of[11]];
    let photons = (n / 4) as u64;
    let mut loop_cpu = [Vec::new(), Vec::new()];
    let mut totals = [0.0; 2];
    for round in 0..=rounds {
        for (k, together) in [1, INTERLEAVE].into_iter().enumerate() {
            let secs = timed(|| totals[k] = grey_loop(&geo, lamp, photons, together));
            if round > 0 {
                loop_cpu[k].push(secs / photons as f64);
            }
        }
    }
    for (k, name) in ["grey loop, 1 photon at a time".to_string(), format!("grey loop, {INTERLEAVE} photons in flight")]
        .into_iter()
        .enumerate()
    {
        println!("{name:<32} ns/photon {}  absorbed {:.6}", spread_ns(&loop_cpu[k]), totals[k] / photons as f64);
    }
    assert!((totals[0] - totals[1]).abs() <= 1e-9 * totals[0], "the two loops traced different photons");
}
