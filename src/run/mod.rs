//! The driver: fixed-size photon batches traced in parallel, merged in batch-index order, with
//! stopping on photon count, relative error, time budget or Ctrl-C at batch boundaries.

pub mod converge;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use crate::detectors::film::{CameraModel, Film, PixelNoise};
use crate::detectors::tally::Tallies;
use crate::error::Error;
use crate::integrators::camera::{ImageKernel, Integrator};
use crate::integrators::clear_view::ClearView;
use crate::integrators::emitter_view::EmitterView;
use crate::integrators::particle::{Estimator, Kernel, TransportOptions};
use crate::lights::Emitter;
use crate::scene::Scene;

pub use crate::integrators::batch::BATCH_PHOTONS;

/// Longest the merge waits for a batch before it looks at the clock and for Ctrl-C again.
const POLL: std::time::Duration = std::time::Duration::from_millis(10);
/// A relative-error stop is judged only after this many batches, so the variance estimate is
/// sound: with per-history errors 4 batches (65 536 histories) suffice; errors from the spread
/// between batches (stratified runs) need about 30 degrees of freedom not to stop on a lucky draw.
pub const MIN_BATCHES_FOR_REL_ERROR: u64 = 4;
pub const MIN_BATCHES_FOR_REL_ERROR_BETWEEN_BATCHES: u64 = 30;
/// An open-ended `--rel-error` run whose chosen tallies are still all zero after this many
/// batches (16.4 million photons) stops: no photon reaches them, and none ever may.
pub const MAX_BATCHES_WITHOUT_SIGNAL: u64 = 1000;
pub use crate::scene::MAX_PHOTONS;
// No exact sum may take more than `exact::MAX_VALUES` values (one per batch), even when two
// full runs are merged.
const _: () = assert!(2 * MAX_PHOTONS / BATCH_PHOTONS <= crate::detectors::exact::MAX_VALUES);
/// Most worker threads accepted.
pub const MAX_THREADS: usize = 1024;

#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub photons: Option<u64>,
    pub seed: Option<u64>,
    pub threads: Option<usize>,
    pub max_bounces: Option<u32>,
    pub rel_error: Option<f64>,
    /// Surfaces the relative-error target applies to; empty means every surface with a non-zero result.
    pub tallies: Vec<String>,
    pub time_s: Option<f64>,
    pub progress: bool,
    /// Skip the camera film entirely.
    pub no_image: bool,
    /// Overrides the scene's `[simulation] integrator`.
    pub integrator: Option<crate::integrators::camera::Integrator>,
    pub transport: TransportOptions,
    /// Trace only batches A..B (a partial run, to be merged with others); `photons` and the
    /// stopping targets then do not apply.
    pub batches: Option<(u64, u64)>,
    /// (k, K): trace only every K-th batch from the k-th on, this process's share of a run split
    /// over K (MPI ranks).
    pub share: Option<(u64, u64)>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    Photons,
    RelError,
    Time,
    Interrupted,
    /// A `--rel-error` run without a photon cap whose targets no photon reached in
    /// `MAX_BATCHES_WITHOUT_SIGNAL` batches.
    NoSignal,
}

impl StopReason {
    /// What stopped the run, in words.
    pub fn describe(self) -> &'static str {
        match self {
            StopReason::Photons => "the photon count",
            StopReason::RelError => "the relative-error target",
            StopReason::Time => "the time budget",
            StopReason::Interrupted => "a signal (interrupted)",
            StopReason::NoSignal => "giving up: no photon reached the targeted tallies",
        }
    }
}

pub struct RunResult {
    pub tallies: Tallies,
    pub emitted_w: f64,
    pub seed: u64,
    pub threads: usize,
    pub wall_seconds: f64,
    pub stop_reason: StopReason,
    /// The light-traced film, when the scene has a camera and the image was not switched off.
    pub film: Option<Film>,
    /// The options the run used (`Estimator::Auto` resolved).
    pub transport: TransportOptions,
    /// What the pilot measured, when the estimator was chosen by one.
    pub pilot: Option<EstimatorPilot>,
    /// Whether the film used hero wavelengths.
    pub hero: bool,
    /// Which integrator made the image (flux always comes from the particle tracer).
    pub integrator: Integrator,
    /// The batches traced: 0..n for a whole run, A..B for a partial one (`--batches`).
    pub batches: (u64, u64),
    /// A partial run (`--batches`), whose exact state is written for `photon merge`.
    pub partial: bool,
    /// MPI ranks that traced it (1 without MPI), and what their coordination cost.
    pub ranks: u32,
    pub mpi: Option<MpiStats>,
}

/// What splitting a run over MPI ranks cost (run.json `mpi`): timings, so nothing any result
/// depends on.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct MpiStats {
    /// Decision rounds held (every `round_batches` batches of each rank), the bytes rank 0
    /// received for them in all, and the seconds rank 0 spent in them.
    pub rounds: u64,
    pub round_batches: u64,
    pub round_bytes: u64,
    pub round_seconds: f64,
    /// The final tree reduction of the ranks' exact states: bytes sent in all, rank 0's seconds.
    pub reduce_bytes: u64,
    pub reduce_seconds: f64,
    /// Each rank's seconds from start to the end of its share (load balance).
    pub rank_seconds: Vec<f64>,
}

/// The most photons a run of `scene` may trace: `MAX_PHOTONS`, and where a camera integrator
/// makes the image (one camera sample a photon, sample k in pixel k mod pixels), no more than
/// 2³² − 1 samples a pixel, which its film and state files count in u32.
pub fn max_photons(scene: &Scene) -> u64 {
    match (&scene.camera, scene.simulation.integrator) {
        (Some(c), Integrator::Path | Integrator::Bdpt) if scene.effects.camera => {
            let pixels = c.resolution[0] as u64 * c.resolution[1] as u64;
            MAX_PHOTONS.min(pixels.saturating_mul(u32::MAX as u64))
        }
        _ => MAX_PHOTONS,
    }
}

/// The photons a run traces at most: its `--batches` end, `--photons`, `max_photons` for an
/// open-ended run (a command-line accuracy or time target is obeyed: only a command-line photon
/// count caps it), else the scene file's `photons`.
pub fn photon_cap(scene: &Scene, opts: &RunOptions) -> u64 {
    let open_ended = opts.rel_error.is_some() || opts.time_s.is_some();
    match (opts.batches, opts.photons) {
        (Some((_, end)), _) => end * BATCH_PHOTONS,
        (None, Some(p)) => p,
        (None, None) if open_ended => max_photons(scene),
        (None, None) => scene.simulation.photons,
    }
}

/// Applies command-line overrides to the scene and checks them; errors are usage errors (exit 2).
pub fn apply_options(scene: &mut Scene, opts: &RunOptions) -> Result<Vec<usize>, Error> {
    if let Some(p) = opts.photons {
        if p == 0 {
            return Err(Error::Usage("--photons must be at least 1".into()));
        }
        if p > MAX_PHOTONS {
            return Err(Error::Usage(format!("--photons must be at most {MAX_PHOTONS} (2^48)")));
        }
        scene.simulation.photons = p;
    }
    if let Some(s) = opts.seed {
        scene.simulation.seed = s;
    }
    if opts.no_image {
        scene.effects.camera = false;
    }
    if let Some(i) = opts.integrator {
        scene.simulation.integrator = i;
    }
    if let Some(b) = opts.max_bounces {
        scene.simulation.max_bounces = b;
    }
    if let Some(e) = opts.rel_error {
        if !(e > 0.0 && e.is_finite()) {
            return Err(Error::Usage(format!("--rel-error must be a positive number, found {e}")));
        }
    }
    if let Some(t) = opts.time_s {
        if !(t > 0.0 && t.is_finite()) {
            return Err(Error::Usage(format!("--time must be a positive number of seconds, found {t}")));
        }
    }
    if let (Some(_), Some(d)) = (opts.batches, scene.ray_detectors.first()) {
        return Err(Error::Usage(format!(
            "ray-set detector \"{}\" records its rays in one whole run: --batches (and MPI) cannot split it",
            d.name
        )));
    }
    if let Some((a, b)) = opts.batches {
        if a >= b {
            return Err(Error::Usage(format!("--batches {a}..{b} holds no batch: the end must exceed the start")));
        }
        if b > MAX_PHOTONS / BATCH_PHOTONS {
            return Err(Error::Usage(format!("--batches must end at most at batch {}", MAX_PHOTONS / BATCH_PHOTONS)));
        }
        for (set, flag) in [
            (opts.photons.is_some(), "--photons"),
            (opts.rel_error.is_some(), "--rel-error"),
            (opts.time_s.is_some(), "--time"),
        ] {
            if set {
                return Err(Error::Usage(format!(
                    "--batches fixes the photons ({BATCH_PHOTONS} per batch): it cannot be combined with {flag}"
                )));
            }
        }
    }
    let (cap, max) = (photon_cap(scene, opts), max_photons(scene));
    if cap > max {
        let c = scene.camera.as_ref().map_or([0, 0], |c| c.resolution);
        return Err(Error::Usage(format!(
            "{cap} photons would give the {}×{} image's pixels more than 2^32 − 1 samples each \
             (one camera sample a photon, in turn over the pixels): at most {max} photons with the {} integrator",
            c[0],
            c[1],
            scene.simulation.integrator.name()
        )));
    }
    if opts.threads.is_some_and(|t| t == 0 || t > MAX_THREADS) {
        return Err(Error::Usage(format!("--threads must be between 1 and {MAX_THREADS}")));
    }
    let mut chosen = Vec::new();
    // Surfaces, then media (their absorbed rows follow the surfaces').
    let n_surfaces = scene.surfaces.len();
    for name in &opts.tallies {
        let medium = || scene.media.iter().position(|m| &m.name == name).map(|k| n_surfaces + k);
        match scene.surfaces.iter().position(|s| &s.name == name).or_else(medium) {
            Some(i) => chosen.push(i),
            None => {
                let known: Vec<&str> = scene.surfaces.iter().map(|s| s.name.as_str()).collect();
                let media: Vec<&str> = scene.media.iter().map(|m| m.name.as_str()).collect();
                let media = if media.is_empty() { String::new() } else { format!("; media: {}", media.join(", ")) };
                return Err(Error::Usage(format!(
                    "--tally {name}: no surface or medium of that name; surfaces: {}{media}",
                    known.join(", ")
                )));
            }
        }
    }
    if !opts.tallies.is_empty() && opts.rel_error.is_none() {
        return Err(Error::Usage("--tally only makes sense with --rel-error".into()));
    }
    if chosen.is_empty() {
        chosen = (0..n_surfaces + scene.media.len()).collect();
    }
    Ok(chosen)
}

/// Runs the simulation. `interrupt` is polled between rounds of batches.
pub fn simulate(
    scene: &Scene,
    opts: &RunOptions,
    rel_error_surfaces: &[usize],
    interrupt: &AtomicBool,
) -> Result<RunResult, Error> {
    simulate_observed(scene, opts, rel_error_surfaces, interrupt, &mut |_| {})
}

/// The state of a run after one more batch was merged, for observers such as `converge`.
pub struct Progress<'a> {
    pub tallies: &'a Tallies,
    /// The film so far: `flushed()` before reading it.
    pub film: Option<&'a mut Film>,
    pub emitted_w: f64,
    pub threads: usize,
}

impl Progress<'_> {
    /// The batches' trace time shared out over the threads: the wall time these photons cost,
    /// free of the granularity of rounds (batches merged in one round finish together).
    pub fn seconds(&self) -> f64 {
        self.tallies.counters.trace_seconds / self.threads as f64
    }
}

/// `simulate`, calling `observer` after every merged batch (in batch order).
pub fn simulate_observed(
    scene: &Scene,
    opts: &RunOptions,
    rel_error_surfaces: &[usize],
    interrupt: &AtomicBool,
    observer: &mut dyn FnMut(Progress),
) -> Result<RunResult, Error> {
    simulate_controlled(scene, opts, rel_error_surfaces, interrupt, &mut |p| {
        observer(p);
        None
    })
}

/// `simulate_observed` with an observer that can stop the run after the batch it was shown (an
/// MPI driver's collective decision): the run then holds exactly the batches merged so far.
pub fn simulate_controlled(
    scene: &Scene,
    opts: &RunOptions,
    rel_error_surfaces: &[usize],
    interrupt: &AtomicBool,
    observer: &mut dyn FnMut(Progress) -> Option<StopReason>,
) -> Result<RunResult, Error> {
    // However the run ends (a failed batch, an error, a panic unwinding), its spare digest lists
    // are freed when this returns (`release_spare_pixel_lists`).
    struct ReleaseSpareLists;
    impl Drop for ReleaseSpareLists {
        fn drop(&mut self) {
            crate::detectors::film::release_spare_pixel_lists();
        }
    }
    let _release = ReleaseSpareLists;
    let threads = opts.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Other(format!("cannot start threads: {e}")))?;
    let emitter = Emitter::new(scene);
    let seed = scene.simulation.seed;
    let camera = scene.camera.as_ref().filter(|_| scene.effects.camera).map(CameraModel::new);
    let integrator = scene.simulation.integrator;
    let prepared = crate::bsdf::Prepared::for_scene(scene);
    let image_kernel = match (&camera, integrator) {
        (Some(cam), Integrator::Path | Integrator::Bdpt) => {
            Some(ImageKernel::new(scene, &emitter, cam, integrator, &prepared))
        }
        _ => None,
    };
    let light_camera = camera.as_ref().filter(|_| integrator == Integrator::Light);
    let clear = light_camera.and_then(|c| ClearView::new(&scene.geometry, c));
    let view = light_camera.and_then(|c| EmitterView::new(scene, &emitter, c, clear.as_ref()));
    // The pilot's time is part of the run's.
    let start = Instant::now();
    let (transport, pilot) = match opts.transport.estimator {
        Estimator::Auto => {
            // Judged on the particle tracer's outputs as the light tracer makes them, whichever
            // integrator makes this run's image and whether or not it makes one: flux.json must
            // not depend on that choice.
            let pilot_camera = scene.camera.as_ref().map(CameraModel::new);
            let pilot = pool.install(|| {
                choose_estimator(scene, &emitter, &prepared, pilot_camera.as_ref(), opts.transport, rel_error_surfaces)
            });
            (TransportOptions { estimator: pilot.chosen, ..opts.transport }, Some(pilot))
        }
        _ => (opts.transport, None),
    };
    let quit = AtomicBool::new(false);
    let kernel = Kernel {
        scene,
        emitter: &emitter,
        camera: light_camera,
        image: image_kernel.as_ref(),
        options: transport,
        cancel: Some(&quit),
        prepared: &prepared,
        view: view.as_ref(),
        clear: clear.as_ref(),
        view_samples: true,
    };
    let hero = kernel.uses_hero();
    let mut film = camera.as_ref().map(|c| {
        let film = pool.install(|| Film::new(c.width, c.height));
        match &view {
            Some(v) => film.with_listed_camera_pixels(v.pixels().to_vec()),
            None => film,
        }
    });

    let cap = photon_cap(scene, opts);
    let (first_batch, end_batch) = opts.batches.unwrap_or((0, cap.div_ceil(BATCH_PHOTONS)));
    let photons_in = |b: u64| BATCH_PHOTONS.min(cap - b * BATCH_PHOTONS);
    // This process traces batches `batch_at(0), batch_at(1), …`: its local sequence, merged in
    // that order (every batch of first..end, or one share of them).
    let (share, shares) = opts.share.unwrap_or((0, 1));
    let batch_at = |i: u64| first_batch + share + shares * i;
    let local_batches = (end_batch - first_batch).saturating_sub(share).div_ceil(shares);

    let progress = opts
        .progress
        .then(|| {
            RunProgress::new(
                opts,
                (cap != max_photons(scene) || opts.photons.is_some())
                    .then_some((cap - first_batch * BATCH_PHOTONS).div_ceil(shares)),
                start,
            )
        })
        .flatten();
    let mut tallies = Tallies::for_run(scene);
    let mut stop = StopReason::Photons;
    // Workers take batch indices in order and send results back; this thread merges them in
    // index order as they arrive, so tracing never waits for merging and the merge order (hence
    // every number) is the same for any thread count. Workers stay at most `window` batches
    // ahead of the merge, which bounds memory; a stop (target met, time, Ctrl-C) cuts the batches
    // in hand short (within CANCEL_CHECK_PHOTONS photons), and only the unbroken run of batches
    // merged before it counts.
    let window = 2 * threads as u64;
    let workers = (threads as u64).min(local_batches).max(1) as usize;
    let min_batches = match opts.transport.error_model() {
        crate::detectors::tally::ErrorModel::Histories => MIN_BATCHES_FOR_REL_ERROR,
        crate::detectors::tally::ErrorModel::Batches => MIN_BATCHES_FOR_REL_ERROR_BETWEEN_BATCHES,
    };
    let mut failure: Option<String> = None;
    let mut ray_counts = vec![0u64; scene.ray_detectors.len()];
    let next = AtomicU64::new(0);
    let merged = AtomicU64::new(0);
    let (tx, rx) = std::sync::mpsc::channel();
    pool.in_place_scope(|scope| {
        for _ in 0..workers {
            let tx = tx.clone();
            let (next, merged, quit, kernel) = (&next, &merged, &quit, &kernel);
            scope.spawn(move |_| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= local_batches || quit.load(Ordering::Relaxed) {
                    break;
                }
                while i >= merged.load(Ordering::Acquire) + window && !quit.load(Ordering::Relaxed) {
                    std::thread::sleep(std::time::Duration::from_micros(100));
                }
                if quit.load(Ordering::Relaxed) {
                    break;
                }
                // A panic in a batch must end the run with an error, not leave the merge waiting
                // for a batch that never comes.
                let traced = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    let b = batch_at(i);
                    kernel.trace_batch(b, photons_in(b))
                }))
                .map_err(|e| {
                    quit.store(true, Ordering::Relaxed);
                    let what =
                        e.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| e.downcast_ref::<String>().cloned());
                    format!("batch {} failed: {}", batch_at(i), what.unwrap_or_else(|| "panic".into()))
                });
                // A batch cut short by the stop is never merged; a failure is always reported.
                if (traced.is_ok() && quit.load(Ordering::Relaxed)) || tx.send((i, traced)).is_err() {
                    break;
                }
            });
        }
        drop(tx);
        let mut pending = std::collections::BTreeMap::new();
        let mut want = 0u64;
        // A time budget or Ctrl-C ends the run when it comes, not when the next batch does: the
        // merge waits at most POLL for a batch, and once one batch is in, a stop cancels the
        // batches in hand (they end within CANCEL_CHECK_PHOTONS photons and are dropped).
        let stop_now = |want: u64| -> Option<StopReason> {
            if want == 0 {
                None
            } else if interrupt.load(Ordering::Relaxed) {
                Some(StopReason::Interrupted)
            } else if opts.time_s.is_some_and(|t| start.elapsed().as_secs_f64() >= t) {
                Some(StopReason::Time)
            } else {
                None
            }
        };
        'merge: while want < local_batches {
            let (b, result) = match rx.recv_timeout(POLL) {
                Ok(received) => received,
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                    if let Some(p) = &progress {
                        p.update(&tallies, None);
                    }
                    if let Some(reason) = stop_now(want) {
                        stop = reason;
                        break 'merge;
                    }
                    continue;
                }
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
            };
            match result {
                Ok(r) => {
                    pending.insert(b, r);
                }
                Err(e) => {
                    failure = Some(e);
                    break 'merge;
                }
            }
            while let Some((t, mut f)) = pending.remove(&want) {
                tallies.merge(&t);
                for r in &t.rays {
                    ray_counts[r.detector as usize] += 1;
                }
                if let Some((d, _)) = scene.ray_detectors.iter().zip(&ray_counts).find(|(d, &n)| n > d.max_rays) {
                    failure = Some(format!(
                        "ray-set detector \"{}\" recorded more than its max_rays = {} arrivals after {} photons: \
                         raise `max_rays` (each ray takes 64 bytes) or trace fewer photons",
                        d.name, d.max_rays, tallies.photons
                    ));
                    break 'merge;
                }
                if let (Some(film), Some(f)) = (film.as_mut(), f.as_mut()) {
                    film.merge(f, t.photons);
                }
                want += 1;
                merged.store(want, Ordering::Release);
                if let Some(reason) = observer(Progress {
                    tallies: &tallies,
                    film: film.as_mut(),
                    emitted_w: emitter.total_power_w,
                    threads,
                }) {
                    stop = reason;
                    break 'merge;
                }
                let worst = opts
                    .rel_error
                    .and_then(|_| tallies.worst_rel_error(rel_error_surfaces, opts.transport.error_model()));
                if let Some(p) = &progress {
                    p.update(&tallies, worst);
                }
                if let Some(target) = opts.rel_error {
                    if worst.is_none() && opts.photons.is_none() && want >= MAX_BATCHES_WITHOUT_SIGNAL {
                        eprintln!(
                            "warning: after {} photons no photon has reached the tallies --rel-error targets; stopping",
                            tallies.photons
                        );
                        stop = StopReason::NoSignal;
                        break 'merge;
                    }
                    if want >= min_batches && worst.is_some_and(|e| e <= target) {
                        stop = StopReason::RelError;
                        break 'merge;
                    }
                }
                if let Some(reason) = stop_now(want) {
                    stop = reason;
                    break 'merge;
                }
            }
        }
        quit.store(true, Ordering::Relaxed);
        // Drain, so no worker blocks on a send; its batches are past the stop and are dropped.
        drop(rx);
    });
    if let Some(e) = failure {
        return Err(Error::Other(e));
    }
    if let Some(f) = film.as_mut() {
        f.flush();
    }
    if let Some(p) = progress {
        p.bar.finish_and_clear();
    }
    Ok(RunResult {
        emitted_w: emitter.total_power_w,
        seed,
        threads,
        wall_seconds: start.elapsed().as_secs_f64(),
        stop_reason: stop,
        film,
        transport,
        pilot,
        hero,
        integrator,
        // The merged batches are an unbroken run from the first.
        batches: (first_batch, first_batch + tallies.batches),
        partial: opts.batches.is_some(),
        ranks: 1,
        mpi: None,
        tallies,
    })
}

/// Photons that `Estimator::Auto` traces with each estimator, unless `PILOT_MAX_RAYS` comes first.
pub const PILOT_PHOTONS: u64 = BATCH_PHOTONS;
/// Rays after which a pilot stops (at a round's end): about half a second on 2 threads, so a
/// scene of albedo near 1, with thousands of expected-value bounces per photon, pays no more.
/// The pilot depends on the scene and seed only, never on the run's photon count or time.
pub const PILOT_MAX_RAYS: u64 = 1_000_000;
/// Photons per pilot round, cut into `PILOT_PARTS` batches that run in parallel. Fixed, so that
/// the pilot's numbers do not depend on the thread count.
const PILOT_ROUND: u64 = 1024;
const PILOT_PARTS: u64 = 8;

/// What the pilot measured of one estimator: the largest relative variance per photon,
/// N·(σ/x̄)², over the tallies the run targets, and the rays each photon cost.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PilotFigures {
    /// Photons the pilot traced with this estimator.
    pub photons: u64,
    pub rel_variance_per_photon: f64,
    pub rays_per_photon: f64,
    /// Predicted time per unit of accuracy, ∝ 1/FOM: variance per photon × rays per photon.
    pub cost: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EstimatorPilot {
    pub chosen: Estimator,
    /// None (left out of run.json) when the pilot saw no tally and no image scored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub analog: Option<PilotFigures>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub expected: Option<PilotFigures>,
}

/// Resolves `Estimator::Auto`: traces a pilot with each estimator (rounds of `PILOT_ROUND`
/// photons until `PILOT_PHOTONS` or `PILOT_MAX_RAYS`), on common random numbers (the same batch
/// indices, ones the run never reaches), and picks the one with
/// the smaller variance × work, the inverse of the figure of merit with time counted in rays
/// (closest-hit and shadow) rather than seconds, so the choice depends only on the scene and
/// seed. Rays are a fair clock: in the Cornell box a ray, with its share of the photon's other
/// work, took 370–475 ns under either estimator, with and without the image. The variance is
/// that of the run's noisiest output: the worst relative one over `surfaces` (incident and
/// absorbed, as `--rel-error` judges), and the light-traced image's pixel noise when the scene
/// has a camera (it is usually far the noisier, so it decides there); a tally one estimator
/// reached and the other did not counts, for the one that missed it, as if a single photon had
/// scored (relative variance per photon N). The camera is judged as the light tracer's image
/// whichever integrator makes the run's image, and with `--no-image` too, so that flux.json
/// depends on neither.
/// Expected-value absorption wins closed, bright scenes (the furnace: 30× the FOM); analog
/// survival wins open or dark ones, where expected-value photons pay for long paths that carry
/// little (the Cornell box).
pub fn choose_estimator(
    scene: &Scene,
    emitter: &Emitter,
    prepared: &[crate::bsdf::Prepared],
    camera: Option<&CameraModel>,
    transport: TransportOptions,
    surfaces: &[usize],
) -> EstimatorPilot {
    use rayon::prelude::*;
    let part = PILOT_ROUND / PILOT_PARTS;
    // The light-traced image without the lamps a run images from the camera: their camera
    // samples do not depend on the estimator, and their splats' noise is not in a run's image.
    let clear = camera.and_then(|c| ClearView::new(&scene.geometry, c));
    let view = camera.and_then(|c| EmitterView::new(scene, emitter, c, clear.as_ref()));
    let pilot = |estimator| {
        let options = TransportOptions { estimator, ..transport };
        let (view, clear) = (view.as_ref(), clear.as_ref());
        let kernel = Kernel {
            scene,
            emitter,
            camera,
            image: None,
            options,
            cancel: None,
            prepared,
            view,
            clear,
            view_samples: false,
        };
        let mut total = Tallies::for_scene(scene);
        let mut noise = camera.map(|c| PixelNoise::new(c.width, c.height));
        let mut round = 0;
        while total.photons < PILOT_PHOTONS && total.counters.rays + total.counters.shadow_rays < PILOT_MAX_RAYS {
            let mut parts: Vec<_> = (0..PILOT_PARTS)
                .into_par_iter()
                .map(|k| kernel.trace_batch(u64::MAX - (round * PILOT_PARTS + k), part))
                .collect();
            for (t, f) in &mut parts {
                total.merge(t);
                if let (Some(noise), Some(f)) = (noise.as_mut(), f.as_mut()) {
                    noise.add(f, t.photons);
                }
            }
            round += 1;
        }
        // The light-traced image's relative variance per photon: N × (pixel noise)².
        let image = noise.map(|n| n.rel_error().powi(2) * total.photons as f64);
        (total, image.filter(|v| v.is_finite()))
    };
    let (analog, expected) = rayon::join(|| pilot(Estimator::Analog), || pilot(Estimator::Expected));
    let model = transport.error_model();
    let worst = |t: &Tallies, other: &Tallies| -> Option<f64> {
        let mut worst: Option<f64> = None;
        for &s in surfaces {
            for (a, b) in [
                (t.incident_estimate(s, 1.0, model), other.incident_estimate(s, 1.0, model)),
                (t.absorbed_estimate(s, 1.0, model), other.absorbed_estimate(s, 1.0, model)),
            ] {
                let v = if a.0 > 0.0 {
                    (a.1 / a.0).powi(2) * t.photons as f64
                } else if b.0 > 0.0 {
                    t.photons as f64
                } else {
                    continue;
                };
                worst = Some(worst.map_or(v, |w: f64| w.max(v)));
            }
        }
        worst
    };
    let figures = |(t, image): &(Tallies, Option<f64>), (other, _): &(Tallies, Option<f64>)| {
        let v = match (worst(t, other), *image) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
        v.map(|v| {
            let rays = (t.counters.rays + t.counters.shadow_rays) as f64 / t.photons as f64;
            PilotFigures { photons: t.photons, rel_variance_per_photon: v, rays_per_photon: rays, cost: v * rays }
        })
    };
    let (a, e) = (figures(&analog, &expected), figures(&expected, &analog));
    let chosen = match (a, e) {
        (Some(a), Some(e)) if a.cost < e.cost => Estimator::Analog,
        _ => Estimator::Expected,
    };
    EstimatorPilot { chosen, analog: a, expected: e }
}

/// The progress bar on a terminal. The share of the run done is the largest of photons/cap,
/// elapsed/time budget and (target/worst relative error)², the last because the error falls as
/// N^(-1/2); so the bar and its ETA follow whichever budget will stop the run.
struct RunProgress {
    bar: indicatif::ProgressBar,
    cap: Option<u64>,
    time_s: Option<f64>,
    rel_error: Option<f64>,
    start: Instant,
    /// The latest worst relative error, kept for the updates between batches.
    worst: std::cell::Cell<Option<f64>>,
}

/// Steps of the bar: per mille.
const PROGRESS_STEPS: u64 = 1000;

impl RunProgress {
    fn new(opts: &RunOptions, cap: Option<u64>, start: Instant) -> Option<Self> {
        use std::io::IsTerminal;
        if !std::io::stderr().is_terminal() {
            return None;
        }
        let style = indicatif::ProgressStyle::with_template("{bar:30} {percent:>3}%  {msg}  eta {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
        let bar = indicatif::ProgressBar::new(PROGRESS_STEPS).with_style(style);
        bar.enable_steady_tick(std::time::Duration::from_millis(250));
        let worst = std::cell::Cell::new(None);
        Some(RunProgress { bar, cap, time_s: opts.time_s, rel_error: opts.rel_error, start, worst })
    }

    /// `worst`: the worst relative error after a merged batch, or None between batches.
    fn update(&self, tallies: &Tallies, worst: Option<f64>) {
        if worst.is_some() {
            self.worst.set(worst);
        }
        let worst = self.worst.get();
        let elapsed = self.start.elapsed().as_secs_f64();
        let mut done: f64 = 0.0;
        if let Some(cap) = self.cap {
            done = done.max(tallies.photons as f64 / cap as f64);
        }
        if let Some(t) = self.time_s {
            done = done.max(elapsed / t);
        }
        if let (Some(target), Some(worst)) = (self.rel_error, worst) {
            done = done.max((target / worst).powi(2));
        }
        self.bar.set_position((done.min(1.0) * PROGRESS_STEPS as f64) as u64);
        let rate = if elapsed > 0.0 { tallies.photons as f64 / elapsed } else { 0.0 };
        let mut msg = format!("{} photons, {}/s", si(tallies.photons as f64), si(rate));
        if let (Some(target), Some(worst)) = (self.rel_error, worst) {
            msg.push_str(&format!(", rel. error {worst:.2e} (target {target:.1e})"));
        }
        self.bar.set_message(msg);
    }
}

/// `x` with three significant digits and an SI prefix: 1.23 M.
pub fn si(x: f64) -> String {
    let (v, prefix) = match x.abs() {
        a if a >= 1e9 => (x / 1e9, " G"),
        a if a >= 1e6 => (x / 1e6, " M"),
        a if a >= 1e3 => (x / 1e3, " k"),
        _ => (x, ""),
    };
    let digits = if v.abs() >= 100.0 {
        0
    } else if v.abs() >= 10.0 {
        1
    } else {
        2
    };
    format!("{v:.digits$}{prefix}")
}

impl RunResult {
    /// (incident W, standard error) of surface `i`.
    pub fn incident(&self, i: usize) -> (f64, f64) {
        self.tallies.incident_estimate(i, self.emitted_w, self.transport.error_model())
    }

    /// (absorbed W, standard error) of surface `i`.
    pub fn absorbed(&self, i: usize) -> (f64, f64) {
        self.tallies.absorbed_estimate(i, self.emitted_w, self.transport.error_model())
    }

    /// (re-emitted W, standard error) of medium `k`'s luminophore.
    pub fn reemitted(&self, k: usize) -> (f64, f64) {
        self.tallies.estimate(&self.tallies.reemitted, k, self.emitted_w, self.transport.error_model())
    }

    /// (incident lm, standard error) of surface `i`.
    pub fn incident_lm(&self, i: usize) -> (f64, f64) {
        self.tallies.estimate(&self.tallies.incident_lm, i, self.emitted_w, self.transport.error_model())
    }

    /// (absorbed lm, standard error) of surface `i`.
    pub fn absorbed_lm(&self, i: usize) -> (f64, f64) {
        self.tallies.estimate(&self.tallies.absorbed_lm, i, self.emitted_w, self.transport.error_model())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panic_in_a_batch_fails_the_run() {
        // Kernel::trace_batch panics in batch 3 under this seed (test builds only).
        let toml = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/furnace.toml")).unwrap();
        let mut scene = crate::scene::load_str(std::path::Path::new("furnace.toml"), &toml).unwrap();
        let opts = RunOptions {
            photons: Some(20 * BATCH_PHOTONS),
            seed: Some(crate::integrators::particle::PANIC_TEST_SEED),
            threads: Some(2),
            transport: TransportOptions { estimator: Estimator::Analog, ..Default::default() },
            ..Default::default()
        };
        let chosen = apply_options(&mut scene, &opts).unwrap();
        match simulate(&scene, &opts, &chosen, &AtomicBool::new(false)) {
            Err(Error::Other(message)) => assert!(message.contains("batch 3 failed"), "{message}"),
            Err(e) => panic!("wrong error: {e}"),
            Ok(r) => panic!("the run succeeded with {} photons", r.tallies.photons),
        }
    }
}
