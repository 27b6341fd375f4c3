//! Throughput benchmarks: photons/s and rays/s of the photon loop.
//!
//! `cargo bench --bench throughput` runs criterion groups (photons/s per scene, and thread scaling
//! 1 → 2 threads), then prints a summary table measured side by side in one run: every
//! configuration is timed `PHOTON_BENCH_REPS` times (default 7), the configurations interleaved
//! round-robin so that a shared machine's drift hits them all alike, and the median is reported;
//! each ratio is the median over rounds of the per-round ratio. The ratios are what the README
//! quotes. A filter that matches no criterion benchmark (`cargo bench --bench throughput --
//! summary`) skips the criterion groups and prints only the summary.
//!
//! On a shared machine other processes take CPU from the run; the summary shows how much (on
//! Linux, from /proc): the CPU this process and the rest of the machine used, and the share of the
//! wall time the worker threads stood runnable but preempted, with an idle-machine estimate of the
//! contended ratios (each wall time less its workers' mean preempted time).
//!
//! Configurations (2 threads unless said otherwise):
//! * `cornell_no_image`: the bundled measured Cornell box (spectral reflectances), `--no-image`;
//! * `cornell_image`: the same with its 512×512 light-traced image;
//! * `cornell_grey`: the same box with each spectral reflectance replaced by its constant mean
//!   under the light's spectrum (white 0.7355, red 0.3446, green 0.2045), so the path length is
//!   about the same (the summary prints both: grey paths come out ≈ 7 % longer) but the transport
//!   is grey; `--no-image`;
//! * `cornell_camera_less`: a copy of the box with its `[camera]` section removed (compare with
//!   `cornell_no_image`: switching the image off must cost nothing);
//! * `furnace_0.9`: the bundled furnace (point light in a closed Lambertian sphere, ρ = 0.9);
//! * `million_triangles`: the Cornell box with its two blocks replaced by one sphere of
//!   `subdivisions = 8` (1 310 720 triangles, radius 160 mm, spectral white): the same open box,
//!   materials and light as `cornell_no_image`, so a photon does about the same work (≈ 3
//!   scatterings, 4 rays) and the per-photon cost ratio isolates the cost of the triangle count;
//! * `glass` (summary only): the bundled glass scene, to show Fresnel evaluations counted where
//!   there are dielectrics (all the other scenes must show 0).

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use criterion::{BenchmarkId, Criterion, SamplingMode, Throughput};
use photon::integrators::particle::{Estimator, TransportOptions};
use photon::run::{apply_options, simulate, RunOptions, RunResult};
use photon::scene::{load, load_str, Scene};

const SCENES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");

/// Photons per iteration: whole batches of 16 384, a multiple of 4 batches so 2 threads end together.
const CORNELL_PHOTONS: u64 = 262_144;
const FURNACE_PHOTONS: u64 = 65_536;
const MILLION_PHOTONS: u64 = 262_144;
const GLASS_PHOTONS: u64 = 65_536;

/// Light-weighted means of the measured Cornell reflectances over 400–700 nm.
const GREY_WHITE: &str = "0.7355";
const GREY_RED: &str = "0.3446";
const GREY_GREEN: &str = "0.2045";

struct Case {
    name: &'static str,
    scene: Scene,
    opts: RunOptions,
    chosen: Vec<usize>,
    photons: u64,
}

impl Case {
    fn new(name: &'static str, mut scene: Scene, photons: u64, threads: usize, no_image: bool) -> Case {
        let opts = RunOptions {
            photons: Some(photons),
            seed: Some(1),
            threads: Some(threads),
            no_image,
            // One estimator for every case, so that ratios compare the same work (`auto` would
            // pick analog in the Cornell box and expected-value absorption in the furnace).
            transport: TransportOptions { estimator: Estimator::Expected, ..TransportOptions::default() },
            ..RunOptions::default()
        };
        let chosen = apply_options(&mut scene, &opts).expect("bench options");
        Case { name, scene, opts, chosen, photons }
    }

    fn run(&self) -> RunResult {
        let stop = AtomicBool::new(false);
        let r = simulate(&self.scene, &self.opts, &self.chosen, &stop).expect("simulate");
        assert_eq!(r.tallies.photons, self.photons);
        r
    }
}

fn scene_path(file: &str) -> PathBuf {
    Path::new(SCENES).join(file)
}

fn cornell_text() -> String {
    std::fs::read_to_string(scene_path("cornell_box.toml")).expect("read cornell_box.toml")
}

/// Replaces `from` by `to` in `text`, insisting that it was there.
fn rewrite(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "the Cornell box no longer contains {from:?}");
    text.replace(from, to)
}

/// Loads TOML text as if it were a file in scenes/ (so relative mesh and spectrum paths resolve).
fn load_variant(file: &str, text: &str) -> Scene {
    load_str(&scene_path(file), text).expect("load bench scene")
}

fn cornell() -> Scene {
    let s = load(&scene_path("cornell_box.toml")).expect("load cornell_box.toml");
    assert!(s.effects.spectral && s.camera.is_some());
    s
}

fn cornell_grey() -> Scene {
    let mut t = cornell_text();
    for (colour, value) in [("white", GREY_WHITE), ("red", GREY_RED), ("green", GREY_GREEN)] {
        t = rewrite(&t, &format!("{{ file = \"../spectra/cornell_{colour}.csv\" }}"), value);
    }
    let s = load_variant("cornell_box_grey.toml", &t);
    assert!(!s.effects.spectral, "the grey Cornell box must be traced grey");
    s
}

fn cornell_camera_less() -> Scene {
    let mut out = String::new();
    let mut in_camera = false;
    for line in cornell_text().lines() {
        let header = line.trim_start().starts_with('[');
        if header {
            in_camera = line.trim() == "[camera]";
        }
        if !in_camera {
            out.push_str(line);
            out.push('\n');
        }
    }
    let s = load_variant("cornell_box_camera_less.toml", &out);
    assert!(s.camera.is_none() && !s.effects.camera);
    s
}

fn million_triangles() -> Scene {
    let mut t = cornell_text();
    t = rewrite(
        &t,
        "shape = { type = \"mesh\", file = \"meshes/cornell_short_block.obj\" }",
        "shape = { type = \"sphere\", center = [278, 160.5, 280], radius = 160, subdivisions = 8 }",
    );
    t = rewrite(&t, "name = \"short_block\"", "name = \"sphere\"");
    // Drop the tall block's entry (the sphere stands where both blocks were).
    let tall = "[[surfaces]]\nname = \"tall_block\"\nmaterial = \"white\"\nshape = { type = \"mesh\", file = \"meshes/cornell_tall_block.obj\" }\n";
    t = rewrite(&t, tall, "");
    let s = load_variant("cornell_box_million.toml", &t);
    let triangles: usize = s.surfaces.iter().map(|s| s.triangles).sum();
    assert!(triangles >= 1_000_000, "only {triangles} triangles");
    s
}

/// The configurations, in the order of the summary table.
fn cases() -> Vec<Case> {
    vec![
        Case::new("cornell_no_image", cornell(), CORNELL_PHOTONS, 2, true),
        Case::new("cornell_no_image_1t", cornell(), CORNELL_PHOTONS, 1, true),
        Case::new("cornell_image", cornell(), CORNELL_PHOTONS, 2, false),
        Case::new("cornell_grey", cornell_grey(), CORNELL_PHOTONS, 2, true),
        Case::new("cornell_camera_less", cornell_camera_less(), CORNELL_PHOTONS, 2, false),
        Case::new("furnace_0.9", load(&scene_path("furnace.toml")).expect("furnace"), FURNACE_PHOTONS, 2, true),
        Case::new("million_triangles", million_triangles(), MILLION_PHOTONS, 2, true),
        Case::new("glass", load(&scene_path("glass.toml")).expect("glass"), GLASS_PHOTONS, 2, true),
    ]
}

fn criterion_groups(c: &mut Criterion, cases: &[Case]) {
    let by_name = |n: &str| cases.iter().find(|c| c.name == n).expect("case");

    let mut g = c.benchmark_group("photons_per_second");
    g.sampling_mode(SamplingMode::Flat).sample_size(10).warm_up_time(Duration::from_secs(1));
    for name in
        ["cornell_no_image", "cornell_image", "cornell_grey", "cornell_camera_less", "furnace_0.9", "million_triangles"]
    {
        let case = by_name(name);
        g.throughput(Throughput::Elements(case.photons));
        g.measurement_time(Duration::from_secs(4));
        g.bench_function(name, |b| b.iter(|| case.run()));
    }
    g.finish();

    let mut g = c.benchmark_group("thread_scaling_cornell_no_image");
    g.sampling_mode(SamplingMode::Flat).sample_size(10).warm_up_time(Duration::from_secs(1));
    g.measurement_time(Duration::from_secs(5));
    for (threads, name) in [(1, "cornell_no_image_1t"), (2, "cornell_no_image")] {
        let case = by_name(name);
        g.throughput(Throughput::Elements(case.photons));
        g.bench_with_input(BenchmarkId::new("threads", threads), case, |b, case| b.iter(|| case.run()));
    }
    g.finish();
}

/// CPU ticks (USER_HZ) used so far by this process (all its threads, live or exited) and by the
/// whole machine (non-idle), from /proc; `None` off Linux.
fn cpu_ticks() -> Option<(u64, u64)> {
    let own = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the ")" that closes the command name, from the 3rd (state): utime and stime
    // are the 14th and 15th.
    let f: Vec<&str> = own[own.rfind(')')? + 1..].split_whitespace().collect();
    let own_ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
    let stat = std::fs::read_to_string("/proc/stat").ok()?;
    let cpu: Vec<u64> = stat.lines().next()?.split_whitespace().skip(1).filter_map(|x| x.parse().ok()).collect();
    // user nice system idle iowait irq softirq steal: busy = all but idle and iowait.
    let busy = cpu.iter().take(8).sum::<u64>() - cpu.get(3)? - cpu.get(4)?;
    Some((own_ticks, busy))
}

/// This thread's id, from /proc/thread-self ("PID/task/TID").
fn own_tid() -> Option<u64> {
    std::fs::read_link("/proc/thread-self").ok()?.file_name()?.to_str()?.parse().ok()
}

/// (time on a CPU, time runnable but waiting for one) in ns of every thread of this process but
/// `except`, from /proc/self/task/*/schedstat.
fn thread_schedstats(except: &[u64]) -> Vec<(u64, u64, u64)> {
    let Ok(dir) = std::fs::read_dir("/proc/self/task") else { return Vec::new() };
    dir.filter_map(|e| {
        let e = e.ok()?;
        let tid: u64 = e.file_name().to_str()?.parse().ok()?;
        if except.contains(&tid) {
            return None;
        }
        let text = std::fs::read_to_string(e.path().join("schedstat")).ok()?;
        let mut f = text.split_whitespace().map(|x| x.parse::<u64>().ok());
        Some((tid, f.next()??, f.next()??))
    })
    .collect()
}

/// Watches the worker threads of one run: every 5 ms it records each thread's schedstat, so the
/// figures of threads that exit with the run's thread pool are known (up to their last 5 ms).
/// Returns the mean time a worker spent runnable but preempted, and the workers' total CPU time,
/// in seconds.
fn watch_workers<T>(f: impl FnOnce() -> T) -> (T, f64, f64) {
    use std::collections::HashMap;
    use std::sync::atomic::Ordering;
    let main = own_tid().unwrap_or(0);
    let baseline: HashMap<u64, (u64, u64)> =
        thread_schedstats(&[main]).into_iter().map(|(t, r, w)| (t, (r, w))).collect();
    let stop = AtomicBool::new(false);
    std::thread::scope(|scope| {
        let watcher = scope.spawn(|| {
            let me = own_tid().unwrap_or(0);
            let mut last: HashMap<u64, (u64, u64)> = HashMap::new();
            loop {
                for (t, r, w) in thread_schedstats(&[main, me]) {
                    last.insert(t, (r, w));
                }
                if stop.load(Ordering::Relaxed) {
                    break;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            last
        });
        let out = f();
        stop.store(true, Ordering::Relaxed);
        let last = watcher.join().expect("watcher");
        // Workers: threads that ran during the run (not idle threads of other pools).
        let workers: Vec<(f64, f64)> = last
            .iter()
            .filter_map(|(t, &(r, w))| {
                let (r0, w0) = baseline.get(t).copied().unwrap_or((0, 0));
                (r > r0 + 1_000_000).then(|| ((r - r0) as f64 * 1e-9, (w - w0) as f64 * 1e-9))
            })
            .collect();
        if workers.is_empty() {
            return (out, f64::NAN, f64::NAN);
        }
        let mean_wait = workers.iter().map(|w| w.1).sum::<f64>() / workers.len() as f64;
        (out, mean_wait, workers.iter().map(|w| w.0).sum())
    })
}

/// One timed run: wall seconds, cores this process used, cores everything else used meanwhile,
/// and the mean time a worker thread was runnable but preempted (by other processes).
#[derive(Clone, Copy)]
struct Sample {
    seconds: f64,
    own_cores: f64,
    background_cores: f64,
    preempted: f64,
    /// CPU time of the worker threads.
    cpu: f64,
}

impl Sample {
    /// Share of the wall time a worker thread neither ran nor stood preempted.
    fn idle(&self, threads: usize) -> f64 {
        1.0 - (self.cpu / threads as f64 + self.preempted) / self.seconds
    }

    /// Estimate of the wall time on an idle machine: minus the time the workers stood preempted.
    fn unpreempted(&self) -> f64 {
        if self.preempted.is_finite() {
            self.seconds - self.preempted
        } else {
            self.seconds
        }
    }
}

fn timed(case: &Case) -> (Sample, RunResult) {
    let before = cpu_ticks();
    let t = Instant::now();
    let (r, preempted, cpu) = watch_workers(|| case.run());
    let seconds = t.elapsed().as_secs_f64();
    let (own_cores, background_cores) = match (before, cpu_ticks()) {
        (Some((o0, b0)), Some((o1, b1))) => {
            let hz = 100.0; // USER_HZ on every Linux platform Rust supports
            let own = (o1 - o0) as f64 / hz / seconds;
            let all = (b1 - b0) as f64 / hz / seconds;
            (own, (all - own).max(0.0))
        }
        _ => (f64::NAN, f64::NAN),
    };
    (Sample { seconds, own_cores, background_cores, preempted, cpu }, r)
}

struct Measured {
    samples: Vec<Sample>,
    result: RunResult,
}

impl Measured {
    fn seconds(&self) -> f64 {
        median(self.samples.iter().map(|s| s.seconds).collect())
    }
    fn photons_per_s(&self) -> f64 {
        self.result.tallies.photons as f64 / self.seconds()
    }
    fn ns_per_photon(&self) -> f64 {
        1e9 / self.photons_per_s()
    }
    fn per_photon(&self, x: u64) -> f64 {
        x as f64 / self.result.tallies.photons as f64
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// A ratio of wall times measured in the same rounds: the median over rounds of the per-round
/// ratio (paired, so slow drift of a shared machine cancels), with its range.
fn paired(a: &Measured, b: &Measured) -> (f64, f64, f64) {
    paired_by(a, b, |s| s.seconds)
}

fn paired_by(a: &Measured, b: &Measured, time: impl Fn(&Sample) -> f64) -> (f64, f64, f64) {
    let r: Vec<f64> = a.samples.iter().zip(&b.samples).map(|(x, y)| time(x) / time(y)).collect();
    let lo = r.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = r.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (median(r), lo, hi)
}

/// Times every case `reps` times, the cases interleaved round-robin, and prints the table and ratios.
fn summary(cases: &[Case], reps: usize) {
    for case in cases {
        case.run(); // warm-up
    }
    let mut samples: Vec<Vec<Sample>> = vec![Vec::new(); cases.len()];
    let mut results: Vec<Option<RunResult>> = (0..cases.len()).map(|_| None).collect();
    for _ in 0..reps {
        for (i, case) in cases.iter().enumerate() {
            let (s, r) = timed(case);
            samples[i].push(s);
            results[i] = Some(r);
        }
    }
    let m: Vec<Measured> =
        samples.into_iter().zip(results).map(|(samples, r)| Measured { samples, result: r.expect("ran") }).collect();
    let get = |n: &str| &m[cases.iter().position(|c| c.name == n).expect("case")];

    println!();
    println!("Summary: median of {reps} interleaved runs per configuration (wall time of simulate()).");
    println!("`cores` = CPU this process used per wall second; `bg` = CPU the rest of the machine used meanwhile;");
    println!(
        "`CPU ns/ph` = CPU time of the worker threads per photon (robust to other processes, not to their cache use);"
    );
    println!("`preempt` = share of the wall time a worker thread stood runnable but preempted (shared machine);");
    println!("`idle` = share of the wall time a worker neither ran nor stood preempted (waiting on the run itself).");
    println!(
        "{:<20} {:>3} {:>7} {:>9} {:>10} {:>10} {:>7} {:>7} {:>9} {:>9} {:>8} {:>5} {:>5} {:>8} {:>5}",
        "configuration",
        "thr",
        "photons",
        "triangles",
        "photons/s",
        "rays/s",
        "rays/ph",
        "shad/ph",
        "ns/photon",
        "CPU ns/ph",
        "Fresnel",
        "cores",
        "bg",
        "preempt",
        "idle"
    );
    for (case, x) in cases.iter().zip(&m) {
        let c = &x.result.tallies.counters;
        let triangles: usize = case.scene.surfaces.iter().map(|s| s.triangles).sum();
        println!(
            "{:<20} {:>3} {:>7} {:>9} {:>10.0} {:>10.0} {:>7.2} {:>7.2} {:>9.0} {:>9.0} {:>8} {:>5.2} {:>5.2} {:>7.0}% {:>4.0}%",
            case.name,
            x.result.threads,
            x.result.tallies.photons,
            triangles,
            x.photons_per_s(),
            (c.rays + c.shadow_rays) as f64 / x.seconds(),
            x.per_photon(c.rays),
            x.per_photon(c.shadow_rays),
            x.ns_per_photon(),
            1e9 * median(x.samples.iter().map(|s| s.cpu).collect()) / x.result.tallies.photons as f64,
            c.fresnel_evaluations,
            median(x.samples.iter().map(|s| s.own_cores).collect()),
            median(x.samples.iter().map(|s| s.background_cores).collect()),
            100.0 * median(x.samples.iter().map(|s| s.preempted / s.seconds).collect()),
            100.0 * median(x.samples.iter().map(|s| s.idle(x.result.threads)).collect()),
        );
    }

    let one = get("cornell_no_image_1t");
    let two = get("cornell_no_image");
    let million = get("million_triangles");
    let grey = get("cornell_grey");
    let image = get("cornell_image");
    let camless = get("cornell_camera_less");
    let rays = |x: &Measured| x.result.tallies.counters.rays as f64;
    let scat = |x: &Measured| x.per_photon(x.result.tallies.scatterings);

    println!();
    println!("Ratios: median over rounds of the per-round ratio, [min, max] over rounds. `wall` from wall times;");
    println!("`CPU` from the worker threads' CPU time (blind to preemption by other processes); for thread");
    println!("scaling instead an idle-machine estimate: each wall time less its workers' mean preempted time.");
    println!("{:<46} {:>20} {:>22}  note", "ratio", "wall", "CPU / idle estimate");
    let cpu = |s: &Sample| s.cpu;
    let scale = |r: (f64, f64, f64), k: f64| (r.0 * k, r.1 * k, r.2 * k);
    let line = |name: &str, wall: (f64, f64, f64), other: (f64, f64, f64), note: String| {
        let f = |r: (f64, f64, f64)| format!("{:.2}× [{:.2}, {:.2}]", r.0, r.1, r.2);
        println!("{name:<46} {:>20} {:>22}  {note}", f(wall), f(other));
    };
    let (w, e) = (paired(one, two), paired_by(one, two, Sample::unpreempted));
    line(
        "thread scaling, 1-thread / 2-thread time",
        w,
        e,
        format!("target ≥ 1.80: wall {}, idle estimate {}", verdict(w.0 >= 1.8), verdict(e.0 >= 1.8)),
    );
    let (w, c) = (paired(million, two), paired_by(million, two, cpu));
    line(
        "million-triangle / Cornell, time per photon",
        w,
        c,
        format!("target ≤ 2.00: wall {}, CPU {}", verdict(w.0 <= 2.0), verdict(c.0 <= 2.0)),
    );
    let k = rays(two) / rays(million);
    line(
        "million-triangle / Cornell, time per ray",
        scale(w, k),
        scale(c, k),
        format!(
            "{:.2} vs {:.2} rays per photon",
            million.per_photon(rays(million) as u64),
            two.per_photon(rays(two) as u64)
        ),
    );
    let (w, c) = (paired(two, grey), paired_by(two, grey, cpu));
    line(
        "spectral / grey Cornell, time per photon",
        w,
        c,
        format!("grey paths are longer: {:.3} vs {:.3} scatterings per photon", scat(grey), scat(two)),
    );
    let k = rays(grey) / rays(two);
    line("spectral / grey Cornell, time per ray", scale(w, k), scale(c, k), "grey must be > 1".into());
    line(
        "--no-image / camera-less copy, time per photon",
        paired(two, camless),
        paired_by(two, camless, cpu),
        "should be ≈ 1".into(),
    );
    line(
        "image / no-image, time per photon",
        paired(image, two),
        paired_by(image, two, cpu),
        format!(
            "{:.2} shadow rays, {:.2} splats per photon",
            image.per_photon(image.result.tallies.counters.shadow_rays),
            image.per_photon(image.result.tallies.counters.splats)
        ),
    );
    let others: Vec<(&Case, &Measured)> = cases.iter().zip(&m).filter(|(c, _)| c.name != "glass").collect();
    let total: u64 = others.iter().map(|(_, x)| x.result.tallies.counters.fresnel_evaluations).sum();
    println!(
        "Fresnel evaluations in the scenes without dielectrics: {total} ({})",
        others.iter().map(|(c, _)| c.name).collect::<Vec<_>>().join(", ")
    );
    println!(
        "Wavelengths sampled per photon: {}",
        cases
            .iter()
            .zip(&m)
            .map(|(c, x)| format!("{} {}", c.name, x.per_photon(x.result.tallies.counters.wavelength_samples)))
            .collect::<Vec<_>>()
            .join(", ")
    );
}

fn verdict(ok: bool) -> &'static str {
    if ok {
        "met"
    } else {
        "MISSED"
    }
}

fn main() {
    // `cargo bench` passes `--bench`; without it (`cargo test --benches`) criterion runs each
    // benchmark once as a test, and the summary is skipped too.
    let args: Vec<String> = std::env::args().collect();
    let benching = args.iter().any(|a| a == "--bench") && !args.iter().any(|a| a == "--list" || a == "--test");
    let cases = cases();
    let mut c = Criterion::default().configure_from_args();
    criterion_groups(&mut c, &cases);
    c.final_summary();
    if benching {
        let reps = std::env::var("PHOTON_BENCH_REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(7);
        summary(&cases, reps);
    }
}
