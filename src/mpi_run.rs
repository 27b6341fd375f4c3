//! `mpirun -n K photon run SCENE [flags]` (cargo feature `mpi`): rank k traces batches k, k + K,
//! k + 2K, … with all its cores, and the ranks' exact states (`output::state`) are added up in a
//! binary tree to rank 0, which writes the outputs. Exact sums make the result the bits of a
//! one-process run for any K.
//!
//! Stopping is collective. Every `ROUND_BATCHES` batches of its own, each rank sends rank 0 the
//! exact sums the stopping rules read (incident and absorbed rows) and whether it was signalled;
//! rank 0 judges `--rel-error`, `--time` and signals on the merged sums of exactly the batches
//! 0..m·ROUND_BATCHES·K and broadcasts the verdict, so all ranks stop after the same batch, and
//! the decision depends on merged results only: a rerun with the recorded photon count
//! reproduces the run. MPI is called from the main thread only (`Threading::Funneled`); the
//! worker threads trace on meanwhile.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use mpi::traits::*;

use photon::detectors::exact::ExactSum;
use photon::detectors::tally::{ChannelSums, Counters, Tallies, TallySums, CHANNELS};
use photon::error::Error;
use photon::output;
use photon::run::{
    apply_options, photon_cap, simulate_controlled, MpiStats, RunOptions, StopReason, BATCH_PHOTONS,
    MAX_BATCHES_WITHOUT_SIGNAL, MIN_BATCHES_FOR_REL_ERROR, MIN_BATCHES_FOR_REL_ERROR_BETWEEN_BATCHES,
};

/// A rank's batches between two collective decisions.
pub const ROUND_BATCHES: u64 = 8;

/// Whether this process was started by an MPI launcher (mpirun, mpiexec, srun): only then is
/// MPI initialised, so a plain `photon run` of an MPI build stays a plain run.
pub fn launched_by_mpi() -> bool {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMI_RANK", "PMIX_RANK", "MV2_COMM_WORLD_SIZE"]
        .iter()
        .any(|v| std::env::var_os(v).is_some())
}

/// The verdicts rank 0 broadcasts.
const CONTINUE: u8 = 0;

fn verdict_code(s: StopReason) -> u8 {
    match s {
        StopReason::Photons => 1,
        StopReason::RelError => 2,
        StopReason::Time => 3,
        StopReason::Interrupted => 4,
        StopReason::NoSignal => 5,
    }
}

fn verdict(code: u8) -> Option<StopReason> {
    Some(match code {
        1 => StopReason::Photons,
        2 => StopReason::RelError,
        3 => StopReason::Time,
        4 => StopReason::Interrupted,
        5 => StopReason::NoSignal,
        _ => return None,
    })
}

/// A rank's message for a round: signalled (u8), then its decision tallies (photons, batches,
/// and the incident and absorbed rows' exact sums).
fn round_message(t: &Tallies, signalled: bool) -> Vec<u8> {
    let part = t.decision_part().expect("a run keeps exact sums");
    let sums = part.sums.as_deref().expect("decision tallies keep exact sums");
    let mut m = vec![signalled as u8];
    m.extend_from_slice(&part.photons.to_le_bytes());
    m.extend_from_slice(&part.batches.to_le_bytes());
    for c in &sums.channels[..2] {
        m.extend_from_slice(&(c.sum.len() as u64).to_le_bytes());
        for i in 0..c.sum.len() {
            for s in [&c.sum[i], &c.sum_sq[i], &c.batch_sq[i]] {
                m.extend_from_slice(&s.to_bytes());
            }
        }
    }
    m
}

fn read_round_message(m: &[u8]) -> Option<(bool, Tallies)> {
    let mut at = 0;
    let mut take = |n: usize| -> Option<&[u8]> {
        let s = m.get(at..at + n)?;
        at += n;
        Some(s)
    };
    let signalled = take(1)?[0] != 0;
    let photons = u64::from_le_bytes(take(8)?.try_into().ok()?);
    let batches = u64::from_le_bytes(take(8)?.try_into().ok()?);
    let mut channels = Vec::with_capacity(CHANNELS);
    for _ in 0..2 {
        let rows = u64::from_le_bytes(take(8)?.try_into().ok()?) as usize;
        let mut c = ChannelSums { sum: Vec::new(), sum_sq: Vec::new(), batch_sq: Vec::new() };
        for _ in 0..rows {
            c.sum.push(ExactSum::from_bytes(take(28)?.try_into().ok()?)?);
            c.sum_sq.push(ExactSum::from_bytes(take(28)?.try_into().ok()?)?);
            c.batch_sq.push(ExactSum::from_bytes(take(28)?.try_into().ok()?)?);
        }
        channels.push(c);
    }
    while channels.len() < CHANNELS {
        channels.push(ChannelSums { sum: Vec::new(), sum_sq: Vec::new(), batch_sq: Vec::new() });
    }
    let sums = TallySums { channels, escaped: ExactSum::default(), truncated: ExactSum::default() };
    Some((signalled, Tallies::from_sums(sums, photons, batches, [0, 0], Counters::default())))
}

/// `photon run` as one rank of an MPI job. Every rank loads and checks the scene alike; only
/// rank 0 prints, writes and reports errors.
pub fn run(
    scene_path: &Path,
    out: Option<PathBuf>,
    opts: &RunOptions,
    quiet: bool,
    interrupt: &AtomicBool,
) -> ExitCode {
    let Some((universe, threading)) = mpi::initialize_with_threading(mpi::Threading::Funneled) else {
        eprintln!("error: MPI could not be initialised");
        return ExitCode::from(1);
    };
    // Worker threads run beside the main thread's MPI calls.
    if threading < mpi::Threading::Funneled {
        eprintln!("error: this MPI library does not support threads (MPI_THREAD_FUNNELED)");
        return ExitCode::from(1);
    }
    let world = universe.world();
    let (rank, ranks) = (world.rank() as u64, world.size() as u64);
    let code = match run_rank(&world, rank, ranks, scene_path, out, opts, quiet, interrupt) {
        Ok(Some(StopReason::Interrupted)) => 3,
        Ok(_) => 0,
        Err(f) => {
            if let Some(m) = f.message {
                eprintln!("error: {m}");
            }
            f.code
        }
    };
    drop(universe);
    ExitCode::from(code)
}

/// How a rank ends early: a message to print here (None where another rank's says it) and the
/// exit status.
struct Failure {
    message: Option<String>,
    code: u8,
}

impl From<Error> for Failure {
    fn from(e: Error) -> Self {
        Failure { message: Some(e.to_string()), code: e.exit_code() as u8 }
    }
}

#[allow(clippy::too_many_arguments)]
fn run_rank(
    world: &mpi::topology::SimpleCommunicator,
    rank: u64,
    ranks: u64,
    scene_path: &Path,
    out: Option<PathBuf>,
    opts: &RunOptions,
    quiet: bool,
    interrupt: &AtomicBool,
) -> Result<Option<StopReason>, Failure> {
    let start = Instant::now();
    let root = world.process_at_rank(0);
    // Every rank loads and checks alike, and rank 0 tries the output folder; no rank goes on
    // unless all can (a rank that returned alone would leave the others waiting for it).
    let ready = (|| {
        let mut scene = photon::scene::load(scene_path)?;
        let chosen = apply_options(&mut scene, opts)?;
        if let (true, Some(d)) = (ranks > 1, scene.ray_detectors.first()) {
            return Err(Error::Usage(format!(
                "ray-set detector \"{}\" records its rays in one whole run: run it without MPI (or with one rank)",
                d.name
            )));
        }
        let out_dir = out.unwrap_or_else(|| Path::new("out").join(scene.stem()));
        let image = scene.camera.is_some() && scene.effects.camera;
        let staged = if rank == 0 {
            let names = output::run_file_names(&scene, image, opts.batches.is_some());
            Some(output::OutputDir::prepare(&out_dir, &names)?)
        } else {
            None
        };
        Ok::<_, Error>((scene, chosen, out_dir, staged))
    })();
    let mut all_ready = 0u8;
    world.all_reduce_into(&(ready.is_ok() as u8), &mut all_ready, mpi::collective::SystemOperation::min());
    let mut root_ready = ready.is_ok() as u8;
    root.broadcast_into(&mut root_ready);
    let (scene, chosen, out_dir, staged) = match ready {
        Ok(r) if all_ready == 1 => r,
        Ok(_) if rank == 0 => {
            return Err(Error::Usage("some ranks cannot run the scene: see their messages".into()).into())
        }
        Ok(_) => return Err(Failure { message: None, code: 2 }),
        Err(e) if rank == 0 => return Err(e.into()),
        // Rank 0's message speaks for all when it failed too (the usual case: a bad scene).
        Err(e) if root_ready == 0 => return Err(Failure { message: None, code: e.exit_code() as u8 }),
        Err(e) => return Err(Failure { message: Some(format!("rank {rank}: {e}")), code: e.exit_code() as u8 }),
    };
    if rank == 0 {
        for w in &scene.warnings {
            eprintln!("warning: {w}");
        }
    }

    // Each rank's share, with no stopping rule of its own: the rounds decide.
    let cap = opts.batches.is_none().then(|| photon_cap(&scene, &opts));
    let total_batches = match (opts.batches, cap) {
        (Some((a, b)), _) => b - a,
        (None, Some(p)) => p.div_ceil(BATCH_PHOTONS),
        (None, None) => 0,
    };
    let local = RunOptions {
        photons: cap,
        rel_error: None,
        time_s: None,
        tallies: Vec::new(),
        progress: opts.progress && rank == 0,
        share: Some((rank, ranks)),
        ..opts.clone()
    };
    // Rounds of up to ROUND_BATCHES (fewer in a short run, so that it holds one), as many as
    // every rank can hold in full: past them the ranks finish their shares undisturbed.
    let round = (total_batches / ranks).clamp(1, ROUND_BATCHES);
    let full_rounds = total_batches / (round * ranks);
    let min_batches = match opts.transport.error_model() {
        photon::detectors::tally::ErrorModel::Histories => MIN_BATCHES_FOR_REL_ERROR,
        photon::detectors::tally::ErrorModel::Batches => MIN_BATCHES_FOR_REL_ERROR_BETWEEN_BATCHES,
    };
    let mut stats = MpiStats { round_batches: round, ..MpiStats::default() };
    let never = AtomicBool::new(false);
    let mut observer = |p: photon::run::Progress| -> Option<StopReason> {
        let mine = p.tallies.batches;
        if mine % round != 0 || mine / round > full_rounds {
            return None;
        }
        let t0 = Instant::now();
        let message = round_message(p.tallies, interrupt.load(Ordering::Relaxed));
        let mut code = CONTINUE;
        if rank == 0 {
            let (mut signalled, mut global) = read_round_message(&message).expect("its own message");
            for r in 1..ranks {
                let (bytes, _) = world.process_at_rank(r as i32).receive_vec::<u8>();
                stats.round_bytes += bytes.len() as u64;
                match read_round_message(&bytes) {
                    Some((s, t)) => {
                        signalled |= s;
                        if global.merge_run(&t).is_err() {
                            world.abort(1);
                        }
                    }
                    None => world.abort(1),
                }
            }
            let batches = global.batches;
            let worst = opts.rel_error.and_then(|_| global.worst_rel_error(&chosen, opts.transport.error_model()));
            let stop = if signalled {
                Some(StopReason::Interrupted)
            } else if opts.rel_error.is_some()
                && worst.is_none()
                && opts.photons.is_none()
                && batches >= MAX_BATCHES_WITHOUT_SIGNAL
            {
                eprintln!(
                    "warning: after {} photons no photon has reached the tallies --rel-error targets; stopping",
                    global.photons
                );
                Some(StopReason::NoSignal)
            } else if opts.rel_error.is_some_and(|e| batches >= min_batches && worst.is_some_and(|w| w <= e)) {
                Some(StopReason::RelError)
            } else if opts.time_s.is_some_and(|t| start.elapsed().as_secs_f64() >= t) {
                Some(StopReason::Time)
            } else {
                None
            };
            code = stop.map_or(CONTINUE, verdict_code);
        } else {
            root.send(&message[..]);
        }
        root.broadcast_into(&mut code);
        stats.rounds += 1;
        stats.round_seconds += t0.elapsed().as_secs_f64();
        verdict(code)
    };
    let mut result = match simulate_controlled(&scene, &local, &chosen, &never, &mut observer) {
        Ok(r) => r,
        // The other ranks wait in a collective that this one will never join.
        Err(e) => {
            eprintln!("error: rank {rank}: {e}");
            world.abort(e.exit_code())
        }
    };
    let stop = result.stop_reason;
    let my_seconds = start.elapsed().as_secs_f64();
    let mut rank_seconds = vec![0.0f64; if rank == 0 { ranks as usize } else { 0 }];
    if rank == 0 {
        root.gather_into_root(&my_seconds, &mut rank_seconds[..]);
    } else {
        root.gather_into(&my_seconds);
    }

    // Binary-tree reduction of the exact states: rank r adds r + 1, r + 2, r + 4, … while its
    // low bits are clear, then sends its sum to its parent. Exact sums make the tree's shape
    // irrelevant to the result.
    let t0 = Instant::now();
    let mut step = 1;
    while step < ranks {
        if rank % (2 * step) == step {
            // The batches it holds, by count (a state's check): its own and its subtree's.
            result.batches = (0, result.tallies.batches);
            let bytes = match output::state::encode(&scene, &result) {
                Ok(b) => b,
                Err(_) => world.abort(1),
            };
            stats.reduce_bytes += bytes.len() as u64;
            send_chunked(&world.process_at_rank((rank - step) as i32), &bytes);
            break;
        }
        if rank + step < ranks {
            let bytes = receive_chunked(&world.process_at_rank((rank + step) as i32));
            let from = PathBuf::from(format!("rank {}", rank + step));
            let added = output::state::part_from_bytes(&bytes, &from)
                .and_then(|part| output::state::add_part(&scene, &mut result, part));
            if let Err(e) = added {
                eprintln!("error: rank {rank}: {e}");
                world.abort(1);
            }
        }
        step *= 2;
    }
    // The bytes each rank sent up the tree, summed at rank 0.
    let mut total_bytes = 0u64;
    if rank == 0 {
        let mut all = vec![0u64; ranks as usize];
        root.gather_into_root(&stats.reduce_bytes, &mut all[..]);
        total_bytes = all.iter().sum();
    } else {
        root.gather_into(&stats.reduce_bytes);
    }
    if rank != 0 {
        // Not before rank 0 has written: a launcher may end the job when any rank exits.
        world.barrier();
        return Ok(Some(stop));
    }
    stats.reduce_seconds = t0.elapsed().as_secs_f64();
    stats.reduce_bytes = total_bytes;
    stats.rank_seconds = rank_seconds;
    let first = opts.batches.map_or(0, |(a, _)| a);
    result.batches = (first, first + result.tallies.batches);
    result.ranks = ranks as u32;
    result.wall_seconds = start.elapsed().as_secs_f64();
    result.mpi = Some(stats);
    let staged = staged.expect("rank 0 prepared the output folder");
    let written = output::write_run(staged.path(), &scene, &result)
        .and_then(|report| staged.commit(&output::previous_run_files(&out_dir)).map(|()| report));
    world.barrier();
    let report = written?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    if !quiet {
        print!("{}", output::summary_table(&report.flux, &report.info));
        println!("wrote {} ({} ranks): {}", out_dir.display(), ranks, report.files.join(", "));
    }
    Ok(Some(stop))
}

/// Largest piece of a state sent in one message: MPI counts elements in a C int, so one send of
/// 2³¹ bytes or more (a film of ~19 M pixels) would fail.
const MESSAGE_BYTES: usize = 1 << 30;

/// Sends `bytes` as its length, then pieces of at most `MESSAGE_BYTES`.
fn send_chunked(to: &impl Destination, bytes: &[u8]) {
    to.send(&(bytes.len() as u64));
    for piece in bytes.chunks(MESSAGE_BYTES) {
        to.send(piece);
    }
}

/// Receives what `send_chunked` sent (messages from one sender arrive in the order sent).
fn receive_chunked(from: &impl Source) -> Vec<u8> {
    let (len, _) = from.receive::<u64>();
    let mut bytes = Vec::with_capacity(len as usize);
    while bytes.len() < len as usize {
        let (piece, _) = from.receive_vec::<u8>();
        bytes.extend_from_slice(&piece);
    }
    bytes
}
