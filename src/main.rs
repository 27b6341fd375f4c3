//! The `photon` command line: a thin shell over the library.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use clap::{Parser, Subcommand};

use photon::error::Error;
use photon::output;
use photon::run::{apply_options, simulate, RunOptions};
use photon::scene::{self, LightShape, Scene};
use photon::transport::{Estimator, TransportOptions};

#[derive(Parser)]
#[command(name = "photon", version, about = "Forward Monte Carlo photon tracer: how much light lands where")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a scene and write flux.json, flux.csv and run.json.
    Run {
        scene: PathBuf,
        /// Output folder (default out/<scene-stem>/).
        #[arg(long)]
        out: Option<PathBuf>,
        #[arg(long)]
        photons: Option<u64>,
        #[arg(long)]
        seed: Option<u64>,
        /// Worker threads (default: all cores). Results do not depend on it.
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
        #[arg(long = "max-bounces")]
        max_bounces: Option<u32>,
        /// Skip the camera image.
        #[arg(long = "no-image")]
        no_image: bool,
        #[command(flatten)]
        transport: TransportArgs,
        /// No progress bar and no table.
        #[arg(long)]
        quiet: bool,
    },
    /// Load and check a scene; print its surfaces, lights, triangle count, power and effects.
    Info { scene: PathBuf },
    /// Run a scene at doubling photon counts within a time budget: error against photons and seconds.
    Converge {
        scene: PathBuf,
        /// Surface to follow (default: the scene's [reference] surface, else the one receiving most).
        #[arg(long)]
        tally: Option<String>,
        /// Wall-clock budget in seconds.
        #[arg(long, default_value_t = 20.0)]
        budget: f64,
        /// Known incident power of the tally (W), overriding the scene's [reference].
        #[arg(long)]
        reference: Option<f64>,
        /// Output folder for convergence.csv and convergence.png (default out/<scene-stem>/).
        #[arg(long)]
        out: Option<PathBuf>,
        #[arg(long)]
        seed: Option<u64>,
        #[arg(long)]
        threads: Option<usize>,
        #[command(flatten)]
        transport: TransportArgs,
        /// Skip the camera image.
        #[arg(long = "no-image")]
        no_image: bool,
    },
    /// Run the built-in closed-form cases; exit 0 only if every case passes.
    Validate {
        /// Smaller runs (under a minute on 2 cores) with looser error targets.
        #[arg(long)]
        quick: bool,
        #[arg(long)]
        threads: Option<usize>,
    },
}

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
    integrator: Option<photon::camera_paths::Integrator>,
}

impl TransportArgs {
    fn options(&self) -> TransportOptions {
        TransportOptions { estimator: self.estimator, stratified: self.stratified, hero: !self.no_hero }
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            // clap's help and version are successes; every other parse failure is bad arguments.
            return if e.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
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
            };
            run(&scene, out, &opts, quiet)
        }
        Command::Info { scene } => info(&scene),
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
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

fn run(scene_path: &Path, out: Option<PathBuf>, opts: &RunOptions, quiet: bool) -> Result<(), Error> {
    let mut scene = load_warn(scene_path)?;
    let chosen = apply_options(&mut scene, opts)?;
    // The scene and options are sound: only now is anything created on disk.
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(scene.stem()));
    std::fs::create_dir_all(&out_dir).map_err(|e| Error::Other(format!("cannot create {}: {e}", out_dir.display())))?;

    let interrupt = Arc::new(AtomicBool::new(false));
    let flag = interrupt.clone();
    // A second Ctrl-C is not caught again: the handler only sets the flag once per process.
    let _ = ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed));

    let result = simulate(&scene, opts, &chosen, &interrupt)?;
    let flux = output::flux(&scene, &result);
    let mut info = output::run_info(&scene, &result, &flux);
    output::write_json(&out_dir, "flux.json", &flux)?;
    output::write_atomic(&out_dir, "flux.csv", output::flux_csv(&flux).as_bytes())?;
    if let Some(film) = &result.film {
        let image = film.image(result.emitted_w);
        output::write_exr(&out_dir, &image)?;
        output::write_png(&out_dir, &image)?;
        info.image_mean_y = Some(film.mean_y(result.emitted_w));
        info.image_pixel_rel_error = Some(output::pixel_rel_error(&image));
        if film.film_batches() < 2 {
            eprintln!(
                "warning: fewer than 2 film batches (<= 1024 photons): Y_var cannot be estimated and is written as 0"
            );
        }
        if let Some(spp) = film.min_samples_per_pixel().filter(|&n| n < 2) {
            eprintln!(
                "warning: some pixels have {spp} camera sample(s) (photons < 2 × pixels): their Y_var is written as 0"
            );
        }
    }
    let maps = photon::maps::estimates(&scene, &result);
    if !maps.is_empty() {
        let dir = out_dir.join("maps");
        std::fs::create_dir_all(&dir).map_err(|e| Error::Other(format!("cannot create {}: {e}", dir.display())))?;
        for m in &maps {
            photon::maps::write_exr(&dir, m)?;
            photon::maps::write_png(&dir, m, &scene.stem())?;
        }
    }
    for e in photon::farfield::estimates(&scene, &result) {
        photon::farfield::write_csv(&out_dir, &e)?;
        photon::farfield::write_png(&out_dir, &e, &scene.stem())?;
    }
    output::write_spectra(&out_dir, &scene, &result)?;
    output::write_json(&out_dir, "run.json", &info)?;
    if !quiet {
        print!("{}", output::summary_table(&flux, &info));
        println!("wrote {}", out_dir.display());
    }
    Ok(())
}

fn validate(quick: bool, threads: Option<usize>) -> Result<(), Error> {
    if threads == Some(0) {
        return Err(Error::Usage("--threads must be at least 1".into()));
    }
    let start = std::time::Instant::now();
    let cases = photon::validate::run_all(quick, threads)?;
    print!("{}", photon::validate::report(&cases, start.elapsed().as_secs_f64()));
    if cases.iter().all(|c| c.passed()) {
        Ok(())
    } else {
        Err(Error::Other("some validation cases failed".into()))
    }
}

fn converge(
    scene_path: &Path,
    out: Option<PathBuf>,
    opts: &RunOptions,
    tally: Option<&str>,
    reference: Option<f64>,
    budget: f64,
) -> Result<(), Error> {
    if !(budget > 0.0 && budget.is_finite()) {
        return Err(Error::Usage(format!("--budget must be a positive number of seconds, found {budget}")));
    }
    let mut scene = load_warn(scene_path)?;
    if let Some(name) = tally {
        if !scene.surfaces.iter().any(|s| s.name == name) {
            return Err(Error::Usage(format!("--tally {name}: no surface of that name")));
        }
    }
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(scene.stem()));
    let c = photon::converge::converge(&mut scene, opts, tally, reference, budget)?;
    std::fs::create_dir_all(&out_dir).map_err(|e| Error::Other(format!("cannot create {}: {e}", out_dir.display())))?;
    print!("{}", c.table());
    output::write_atomic(&out_dir, "convergence.csv", c.csv().as_bytes())?;
    let tmp = out_dir.join(format!(".convergence.tmp{}.png", std::process::id()));
    c.plot(&tmp, &format!("{}: error against time", scene.stem()))?;
    std::fs::rename(&tmp, out_dir.join("convergence.png"))
        .map_err(|e| Error::Other(format!("cannot write convergence.png: {e}")))?;
    println!("wrote {}", out_dir.display());
    Ok(())
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
    print!("{}", describe(&scene));
    Ok(())
}

fn describe(scene: &Scene) -> String {
    let mut s = format!("scene {}\n", scene.path.display());
    s.push_str(&format!("surfaces ({}):\n", scene.surfaces.len()));
    let name_w =
        scene.surfaces.iter().map(|x| x.name.len()).chain(scene.lights.iter().map(|l| l.name.len())).max().unwrap_or(4);
    let materials: Vec<String> = scene
        .surfaces
        .iter()
        .map(|x| format!("{} ({})", scene.materials[x.material].name, scene.materials[x.material].material.kind()))
        .collect();
    let mat_w = materials.iter().map(String::len).max().unwrap_or(8);
    for (surf, material) in scene.surfaces.iter().zip(&materials) {
        s.push_str(&format!(
            "  {:<name_w$}  {:<mat_w$}  {:>8} triangles  {:>12.6} m²{}\n",
            surf.name,
            material,
            surf.triangles,
            surf.area_m2,
            if surf.light.is_some() { "  [light]" } else { "" }
        ));
    }
    s.push_str(&format!("lights ({}):\n", scene.lights.len()));
    for l in &scene.lights {
        let shape = match &l.shape {
            LightShape::Area { surface } => {
                format!("area, {:.6} m²", scene.surfaces[*surface].area_m2)
            }
            LightShape::Point { position, .. } => {
                format!("point at [{}, {}, {}] m", position.x, position.y, position.z)
            }
        };
        let distribution = match &l.ies {
            Some(ies) => format!("ies {}", ies.file.display()),
            None => l.distribution.describe(),
        };
        s.push_str(&format!(
            "  {:<name_w$}  {:>12.6} W  {:>10.1} lm  {}  {}\n",
            l.name,
            l.power_w,
            l.power_w * l.lm_per_w,
            distribution,
            shape
        ));
    }
    s.push_str(&format!("triangles: {}\n", scene.geometry.len()));
    s.push_str(&format!("total power: {:.6} W\n", scene.total_power_w()));
    let (lo, hi) = scene.simulation.wavelength_range_nm;
    s.push_str(&format!("wavelength range: {lo}–{hi} nm\n"));
    s.push_str(&format!("transport: {}\n", scene.effects.transport()));
    s.push_str(&format!("effects: {}\n", scene.effects.names().join(", ")));
    if let Some(c) = &scene.camera {
        s.push_str(&format!("camera: {}×{} pixels, fov {}°\n", c.resolution[0], c.resolution[1], c.fov_deg));
    }
    for surface in &scene.surfaces {
        if let Some(m) = &surface.map {
            s.push_str(&format!("map: {} {}×{} texels\n", surface.name, m.resolution[0], m.resolution[1]));
        }
        if let Some((bins, _)) = surface.spectrum_bins {
            s.push_str(&format!("spectrum: {} in {bins} wavelength bins\n", surface.name));
        }
    }
    for d in &scene.detectors {
        s.push_str(&format!("detector: farfield {} {}×{} (gamma × C)\n", d.name, d.resolution[0], d.resolution[1]));
    }
    s
}
