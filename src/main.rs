//! The `photon` command line: a thin shell over the library.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::{Parser, Subcommand};

use photon::error::Error;
use photon::integrators::particle::{Estimator, TransportOptions};
use photon::output;
use photon::run::{apply_options, simulate, RunOptions, StopReason};
use photon::scene::{self, Scene};

#[cfg(feature = "mpi")]
mod mpi_run;

#[derive(Parser)]
#[command(name = "photon", version, about = "Forward Monte Carlo photon tracer: how much light lands where")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
#[command(after_help = EXIT_STATUS)]
enum Command {
    /// Simulate a scene and write flux.json, flux.csv, run.json (and the image, maps, far field).
    #[command(after_help = EXIT_STATUS)]
    Run {
        /// The scene file (TOML).
        scene: PathBuf,
        /// Output folder [default: out/<scene-stem>/].
        #[arg(long)]
        out: Option<PathBuf>,
        /// Photons to trace [default: the scene's `[simulation] photons`, else 1000000]; with
        /// --rel-error or --time, the most to trace (the scene's count then caps nothing).
        #[arg(long)]
        photons: Option<u64>,
        /// Seed of the random streams [default: the scene's, else 1].
        #[arg(long)]
        seed: Option<u64>,
        /// Worker threads [default: all cores]. Results do not depend on it.
        #[arg(long)]
        threads: Option<usize>,
        /// Stop when every tallied surface (or each --tally) reaches this relative standard error.
        #[arg(long = "rel-error")]
        rel_error: Option<f64>,
        /// Surface whose error --rel-error targets (repeatable).
        #[arg(long = "tally")]
        tally: Vec<String>,
        /// Stop at this time budget, in seconds.
        #[arg(long = "time")]
        time: Option<f64>,
        /// Scatterings after which a photon is dropped and counted as truncated [default: the
        /// scene's, else 100000].
        #[arg(long = "max-bounces")]
        max_bounces: Option<u32>,
        /// Skip the camera image.
        #[arg(long = "no-image")]
        no_image: bool,
        /// Trace only batches A to B−1 (of 16384 photons each) and write, beside the usual
        /// files, their mergeable state.photon for `photon merge`.
        #[arg(long, value_name = "A..B", value_parser = parse_batches)]
        batches: Option<(u64, u64)>,
        #[command(flatten)]
        transport: TransportArgs,
        /// No progress bar and no table.
        #[arg(long)]
        quiet: bool,
    },
    /// Merge partial runs (`photon run --batches A..B`) into the outputs of one run: parts
    /// covering batches 0..N write what `photon run --photons N·16384` writes.
    #[command(after_help = EXIT_STATUS)]
    Merge {
        /// The parts: their output folders (or their state.photon files), in any order.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
        /// Output folder [default: out/<scene-stem>/].
        #[arg(long)]
        out: Option<PathBuf>,
        /// The scene file, if it has moved since the parts ran [default: the path they recorded].
        #[arg(long)]
        scene: Option<PathBuf>,
        /// No table.
        #[arg(long)]
        quiet: bool,
    },
    /// Load and check a scene; print its surfaces, lights, triangle count, power and effects.
    Info {
        /// The scene file (TOML).
        scene: PathBuf,
    },
    /// Run a scene at doubling photon counts within a time budget: error against photons and seconds.
    #[command(after_help = EXIT_STATUS)]
    Converge {
        /// The scene file (TOML).
        scene: PathBuf,
        /// Surface to follow [default: the scene's [reference] surface, else the one receiving most].
        #[arg(long)]
        tally: Option<String>,
        /// Wall-clock budget in seconds for the whole command: the run and, when the scene gives
        /// no closed form or has a camera, an independent reference run share it.
        #[arg(long, default_value_t = 20.0)]
        budget: f64,
        /// Known incident power of the tally (W), overriding the scene's [reference].
        #[arg(long)]
        reference: Option<f64>,
        /// Output folder for convergence.csv and convergence.png [default: out/<scene-stem>/].
        #[arg(long)]
        out: Option<PathBuf>,
        /// Seed of the random streams [default: the scene's, else 1]; the reference run uses seed + 1.
        #[arg(long)]
        seed: Option<u64>,
        /// Worker threads [default: all cores].
        #[arg(long)]
        threads: Option<usize>,
        #[command(flatten)]
        transport: TransportArgs,
        /// Skip the camera image.
        #[arg(long = "no-image")]
        no_image: bool,
    },
    /// Run the built-in closed-form cases; exit 0 only if every case passes.
    #[command(after_help = EXIT_STATUS)]
    Validate {
        /// Smaller runs (about 10 s on 2 cores) with looser error targets.
        #[arg(long)]
        quick: bool,
        /// Worker threads [default: all cores].
        #[arg(long)]
        threads: Option<usize>,
    },
}

const EXIT_STATUS: &str = "Exit status: 0 done; 1 failure; 2 bad scene or arguments (nothing is written); \
3 stopped early by Ctrl-C, SIGTERM or SIGHUP, with the results so far written.";

/// The transport options `run` and `converge` share.
#[derive(clap::Args)]
struct TransportArgs {
    /// Absorption estimator: expected-value weighting, analog survival, or auto (the one a pilot
    /// batch of each predicts to give the tallies the higher figure of merit).
    #[arg(long, value_enum, default_value_t = TransportOptions::default().estimator)]
    estimator: Estimator,
    /// Stratify each batch's emission samples (Latin hypercube).
    #[arg(long)]
    stratified: bool,
    /// One wavelength per photon in the image instead of four hero wavelengths.
    #[arg(long = "no-hero")]
    no_hero: bool,
    /// What makes the image: light tracing, path tracing or BDPT (default: the scene's
    /// `[simulation] integrator`, else light). flux.json always comes from the particle tracer.
    #[arg(long, value_enum)]
    integrator: Option<photon::integrators::camera::Integrator>,
}

impl TransportArgs {
    fn options(&self) -> TransportOptions {
        TransportOptions { estimator: self.estimator, stratified: self.stratified, hero: !self.no_hero }
    }
}

/// `A..B`: batches A (inclusive) to B (exclusive).
fn parse_batches(s: &str) -> Result<(u64, u64), String> {
    let (a, b) = s.split_once("..").ok_or_else(|| format!("expected A..B (e.g. 0..64), found \"{s}\""))?;
    let number = |x: &str| x.trim().parse::<u64>().map_err(|_| format!("\"{x}\" is not a batch number in \"{s}\""));
    Ok((number(a)?, number(b)?))
}

/// Set by Ctrl-C, SIGTERM or SIGHUP: the run stops and writes what it has.
static INTERRUPT: AtomicBool = AtomicBool::new(false);

/// How a command that did its work ended.
enum Outcome {
    Complete,
    /// Stopped early by a signal; what it had is written.
    Interrupted,
}

/// Exit status of a command stopped early by a signal, with its results written.
const EXIT_INTERRUPTED: u8 = 3;

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            // clap's help and version are successes; every other parse failure is bad arguments.
            return if e.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
    // The first signal asks the command to stop and write what it has; a second one, to stop now.
    let _ = ctrlc::set_handler(|| {
        if INTERRUPT.swap(true, Ordering::Relaxed) {
            eprintln!("\nstopped at once: nothing more is written");
            output::remove_staging_folders();
            std::process::exit(130);
        }
    });
    let result = match cli.command {
        Command::Run {
            scene,
            out,
            photons,
            seed,
            threads,
            rel_error,
            tally,
            time,
            max_bounces,
            no_image,
            batches,
            quiet,
            transport,
        } => {
            let opts = RunOptions {
                photons,
                seed,
                threads,
                max_bounces,
                rel_error,
                tallies: tally,
                time_s: time,
                progress: !quiet,
                no_image,
                integrator: transport.integrator,
                transport: transport.options(),
                batches,
                share: None,
            };
            #[cfg(feature = "mpi")]
            if mpi_run::launched_by_mpi() {
                return mpi_run::run(&scene, out, &opts, quiet, &INTERRUPT);
            }
            run(&scene, out, &opts, quiet)
        }
        Command::Info { scene } => info(&scene).map(|()| Outcome::Complete),
        Command::Merge { parts, out, scene, quiet } => merge(&parts, out, scene, quiet),
        Command::Validate { quick, threads } => validate(quick, threads),
        Command::Converge { scene, tally, budget, reference, out, seed, threads, transport, no_image } => {
            let opts = RunOptions {
                seed,
                threads,
                no_image,
                progress: false,
                integrator: transport.integrator,
                transport: transport.options(),
                ..Default::default()
            };
            converge(&scene, out, &opts, tally.as_deref(), reference, budget)
        }
    };
    match result {
        Ok(Outcome::Complete) => ExitCode::SUCCESS,
        Ok(Outcome::Interrupted) => ExitCode::from(EXIT_INTERRUPTED),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

fn run(scene_path: &Path, out: Option<PathBuf>, opts: &RunOptions, quiet: bool) -> Result<Outcome, Error> {
    let mut scene = load_warn(scene_path)?;
    let chosen = apply_options(&mut scene, opts)?;
    // Everything that can be checked is checked before the first photon: the scene, the options,
    // and every output file's name in the output folder.
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(scene.stem()));
    let image = scene.camera.is_some() && scene.effects.camera;
    let staged = output::OutputDir::prepare(&out_dir, &output::run_file_names(&scene, image, opts.batches.is_some()))?;
    let result = simulate(&scene, opts, &chosen, &INTERRUPT)?;
    let report = output::write_run(staged.path(), &scene, &result)?;
    staged.commit(&output::previous_run_files(&out_dir))?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    if !quiet {
        print!("{}", output::summary_table(&report.flux, &report.info));
        println!("wrote {}: {}", out_dir.display(), report.files.join(", "));
    }
    Ok(match result.stop_reason {
        StopReason::Interrupted => Outcome::Interrupted,
        _ => Outcome::Complete,
    })
}

fn merge(
    part_paths: &[PathBuf],
    out: Option<PathBuf>,
    scene_path: Option<PathBuf>,
    quiet: bool,
) -> Result<Outcome, Error> {
    // Each part read whole (its checksum verified) but only its header kept: `state::merge` reads
    // them again one at a time.
    let parts = part_paths
        .iter()
        .map(|p| output::state::read_part(p).map(|p| p.into_header()))
        .collect::<Result<Vec<_>, _>>()?;
    let parts = output::state::check_parts(parts)?;
    let h = parts[0].header.clone();
    let scene_path = scene_path.unwrap_or_else(|| PathBuf::from(&h.scene_absolute));
    let mut scene = load_warn(&scene_path)?;
    // run.json names the scene as the parts' runs did (as given), wherever it was loaded from.
    scene.path = PathBuf::from(&h.scene);
    // The parts' options, as `apply_options` set them for their runs.
    scene.simulation.seed = h.seed;
    scene.simulation.max_bounces = h.max_bounces;
    scene.simulation.integrator = h.integrator;
    scene.effects.camera &= h.image;
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(scene.stem()));
    let image = scene.camera.is_some() && scene.effects.camera;
    let staged = output::OutputDir::prepare(&out_dir, &output::run_file_names(&scene, image, false))?;
    let result = output::state::merge(&scene, &parts)?;
    let report = output::write_run(staged.path(), &scene, &result)?;
    staged.commit(&output::previous_run_files(&out_dir))?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    if !quiet {
        println!("merged {} parts: batches {}..{}", parts.len(), result.batches.0, result.batches.1);
        print!("{}", output::summary_table(&report.flux, &report.info));
        println!("wrote {}: {}", out_dir.display(), report.files.join(", "));
    }
    Ok(Outcome::Complete)
}

fn validate(quick: bool, threads: Option<usize>) -> Result<Outcome, Error> {
    if threads.is_some_and(|t| t == 0 || t > photon::run::MAX_THREADS) {
        return Err(Error::Usage(format!("--threads must be between 1 and {}", photon::run::MAX_THREADS)));
    }
    let start = std::time::Instant::now();
    use std::io::Write as _;
    print!("{}", photon::validate::header());
    let _ = std::io::stdout().flush();
    let (cases, complete) = photon::validate::run_all(quick, threads, &INTERRUPT, &mut |c| {
        print!("{}", photon::validate::line(c));
        let _ = std::io::stdout().flush();
    })?;
    print!("{}", photon::validate::footer(&cases, start.elapsed().as_secs_f64(), complete));
    // A failed case outweighs the interruption.
    if !cases.iter().all(|c| c.passed()) {
        Err(Error::Other("some validation cases failed".into()))
    } else if !complete {
        Ok(Outcome::Interrupted)
    } else {
        Ok(Outcome::Complete)
    }
}

fn converge(
    scene_path: &Path,
    out: Option<PathBuf>,
    opts: &RunOptions,
    tally: Option<&str>,
    reference: Option<f64>,
    budget: f64,
) -> Result<Outcome, Error> {
    if !(budget > 0.0 && budget.is_finite()) {
        return Err(Error::Usage(format!("--budget must be a positive number of seconds, found {budget}")));
    }
    if let Some(r) = reference {
        if !(r > 0.0 && r.is_finite()) {
            return Err(Error::Usage(format!("--reference must be a positive power in W, found {r}")));
        }
    }
    let mut scene = load_warn(scene_path)?;
    photon::run::converge::check(&scene, tally)?;
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(scene.stem()));
    const FILES: [&str; 2] = ["convergence.csv", "convergence.png"];
    let staged = output::OutputDir::prepare(&out_dir, &FILES.map(String::from))?;
    let c = photon::run::converge::converge(&mut scene, opts, tally, reference, budget, &INTERRUPT)?;
    print!("{}", c.table());
    output::write_atomic(staged.path(), FILES[0], c.csv().as_bytes())?;
    output::converge::plot(&c, &staged.path().join(FILES[1]), &format!("{}: error against time", scene.stem()))?;
    staged.commit(&[])?;
    println!("wrote {}: {}", out_dir.display(), FILES.join(", "));
    Ok(if c.interrupted { Outcome::Interrupted } else { Outcome::Complete })
}

/// Loads a scene and prints its warnings to stderr.
fn load_warn(path: &Path) -> Result<Scene, Error> {
    let scene = scene::load(path)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

fn info(scene_path: &Path) -> Result<(), Error> {
    let scene = load_warn(scene_path)?;
    print!("{}", output::info::describe(&scene));
    Ok(())
}
