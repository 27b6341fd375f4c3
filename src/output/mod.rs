//! Output files: flux.json/csv, run.json, image.exr/png, maps and far-field files (`maps`,
//! `farfield`), staged in a hidden folder and moved into place whole (`OutputDir`).

pub mod converge;
pub mod farfield;
pub mod info;
pub mod luminaire;
pub mod maps;
pub mod rays;
pub mod state;
pub mod volume;

use std::io::Write;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::detectors::tally::Ledger;
use crate::error::Error;
use crate::run::{RunResult, StopReason, BATCH_PHOTONS};
use crate::scene::Scene;

#[derive(Serialize, Clone, Debug)]
pub struct SurfaceRow {
    pub name: String,
    pub area_m2: f64,
    pub incident_w: f64,
    pub incident_w_stderr: f64,
    pub absorbed_w: f64,
    pub absorbed_w_stderr: f64,
    /// Relative standard error of incident_w (0 when nothing arrived).
    pub rel_error: f64,
    /// The same in lumens: 683 lm/W × ∫Φ(λ)ȳ(λ)dλ (see `photometry`).
    pub incident_lm: f64,
    pub incident_lm_stderr: f64,
    pub absorbed_lm: f64,
    pub absorbed_lm_stderr: f64,
    /// Mean incident flux per unit area over the surface: W/m² and lm/m² = lx.
    pub irradiance_w_m2: f64,
    pub irradiance_w_m2_stderr: f64,
    pub illuminance_lx: f64,
    pub illuminance_lx_stderr: f64,
}

/// A participating medium's row of flux.json: the power that ended in its volume.
#[derive(Serialize, Clone, Debug)]
pub struct MediumRow {
    pub name: String,
    pub volume_m3: f64,
    pub absorbed_w: f64,
    pub absorbed_w_stderr: f64,
    /// With fluorescence: the power its luminophore re-emitted at new wavelengths (its absorbed
    /// power is then net of it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reemitted_w: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reemitted_w_stderr: Option<f64>,
}

/// The flux.csv columns, in order.
const CSV_COLUMNS: &str = "name,area_m2,incident_w,incident_w_stderr,absorbed_w,absorbed_w_stderr,rel_error,\
incident_lm,incident_lm_stderr,absorbed_lm,absorbed_lm_stderr,irradiance_w_m2,irradiance_w_m2_stderr,\
illuminance_lx,illuminance_lx_stderr";

impl SurfaceRow {
    fn csv_values(&self) -> [f64; 14] {
        [
            self.area_m2,
            self.incident_w,
            self.incident_w_stderr,
            self.absorbed_w,
            self.absorbed_w_stderr,
            self.rel_error,
            self.incident_lm,
            self.incident_lm_stderr,
            self.absorbed_lm,
            self.absorbed_lm_stderr,
            self.irradiance_w_m2,
            self.irradiance_w_m2_stderr,
            self.illuminance_lx,
            self.illuminance_lx_stderr,
        ]
    }
}

#[derive(Serialize, Clone, Debug)]
pub struct Flux {
    pub photons: u64,
    pub emitted_w: f64,
    /// Σ over lights of power × luminous efficacy of its spectrum.
    pub emitted_lm: f64,
    pub surfaces: Vec<SurfaceRow>,
    /// `[media]`, after the surfaces in the absorbed tallies (absent without media).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub media: Vec<MediumRow>,
    /// Surface maps' and work planes' minimum, mean, maximum and uniformity (absent without).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub maps: Vec<maps::MapRow>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub planes: Vec<maps::MapRow>,
    pub ledger: Ledger,
}

#[derive(Serialize, Clone, Debug)]
pub struct SurfaceFom {
    pub name: String,
    pub fom: f64,
}

#[derive(Serialize, Clone, Debug)]
pub struct RunInfo {
    pub version: String,
    pub scene: String,
    pub seed: u64,
    pub photons: u64,
    pub threads: usize,
    pub wall_seconds: f64,
    pub photons_per_second: f64,
    pub effects: Vec<String>,
    pub stop_reason: StopReason,
    pub transport: String,
    pub batch_photons: u64,
    /// The batches this run holds, first to last + 1: [0, n] but for a partial run
    /// (`--batches`), or the merge of parts that start past 0.
    pub batches: [u64; 2],
    /// MPI ranks that traced the run (1 without MPI), and what coordinating them cost.
    pub ranks: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mpi: Option<crate::run::MpiStats>,
    pub max_bounces: u32,
    pub mean_scatterings: f64,
    pub mean_scatterings_stderr: f64,
    /// Per surface, the figure of merit 1/(rel_error² · seconds): the accuracy a second buys.
    /// Here rather than in flux.json, whose numbers must not depend on timing.
    pub fom: Vec<SurfaceFom>,
    /// Work done: rays, visibility rays, Fresnel evaluations, splats; and rays per second.
    pub counters: crate::detectors::tally::Counters,
    pub rays_per_second: f64,
    /// The transport options and whether the image used hero wavelengths.
    pub transport_options: crate::integrators::particle::TransportOptions,
    /// With `--estimator auto`: the pilot's figures for each estimator and the one chosen.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimator_pilot: Option<crate::run::EstimatorPilot>,
    pub hero_wavelengths: bool,
    /// What made the image (flux always comes from the particle tracer).
    pub integrator: crate::integrators::camera::Integrator,
    /// Mean Y over the image and its standard error, when an image was made.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image_mean_y: Option<(f64, f64)>,
    /// Relative RMS pixel noise sqrt(mean(Y_var))/mean(Y): the image's typical relative error.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub image_pixel_rel_error: Option<f64>,
    /// The files this run wrote, relative to the output folder (run.json last): a later run
    /// into the same folder removes those it does not write again, and nothing else.
    pub files: Vec<String>,
}

pub fn flux(scene: &Scene, r: &RunResult) -> Flux {
    flux_with_maps(scene, r, &maps::estimates(scene, r))
}

/// flux.json's numbers, given the run's maps (`maps::estimates`).
pub fn flux_with_maps(scene: &Scene, r: &RunResult, map_estimates: &[maps::MapEstimate]) -> Flux {
    let t = &r.tallies;
    let surfaces = scene
        .surfaces
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let (incident_w, incident_w_stderr) = r.incident(i);
            let (absorbed_w, absorbed_w_stderr) = r.absorbed(i);
            let (incident_lm, incident_lm_stderr) = r.incident_lm(i);
            let (absorbed_lm, absorbed_lm_stderr) = r.absorbed_lm(i);
            let rel_error = if incident_w > 0.0 { incident_w_stderr / incident_w } else { 0.0 };
            let per_m2 = if s.area_m2 > 0.0 { 1.0 / s.area_m2 } else { 0.0 };
            SurfaceRow {
                name: s.name.clone(),
                area_m2: s.area_m2,
                incident_w,
                incident_w_stderr,
                absorbed_w,
                absorbed_w_stderr,
                rel_error,
                incident_lm,
                incident_lm_stderr,
                absorbed_lm,
                absorbed_lm_stderr,
                irradiance_w_m2: incident_w * per_m2,
                irradiance_w_m2_stderr: incident_w_stderr * per_m2,
                illuminance_lx: incident_lm * per_m2,
                illuminance_lx_stderr: incident_lm_stderr * per_m2,
            }
        })
        .collect();
    let media = scene
        .media
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let (absorbed_w, absorbed_w_stderr) = r.absorbed(scene.surfaces.len() + k);
            let reemitted = m.fluorescence.as_ref().map(|_| r.reemitted(k));
            MediumRow {
                name: m.name.clone(),
                volume_m3: m.volume_m3,
                absorbed_w,
                absorbed_w_stderr,
                reemitted_w: reemitted.map(|x| x.0),
                reemitted_w_stderr: reemitted.map(|x| x.1),
            }
        })
        .collect();
    let emitted_lm = scene.lights.iter().map(|l| l.power_w * l.lm_per_w).sum();
    let rows = |kind: maps::MapKind| map_estimates.iter().filter(|m| m.kind == kind).map(|m| m.row()).collect();
    Flux {
        photons: t.photons,
        emitted_w: r.emitted_w,
        emitted_lm,
        surfaces,
        media,
        maps: rows(maps::MapKind::Surface),
        planes: rows(maps::MapKind::Plane),
        ledger: t.ledger(r.emitted_w),
    }
}

pub fn run_info(scene: &Scene, r: &RunResult, flux: &Flux) -> RunInfo {
    let photons = r.tallies.photons;
    let fom = flux
        .surfaces
        .iter()
        .map(|s| {
            let fom = if s.rel_error > 0.0 && r.wall_seconds > 0.0 {
                1.0 / (s.rel_error * s.rel_error * r.wall_seconds)
            } else {
                0.0
            };
            SurfaceFom { name: s.name.clone(), fom }
        })
        .collect();
    RunInfo {
        version: env!("CARGO_PKG_VERSION").to_string(),
        scene: scene.path.display().to_string(),
        seed: r.seed,
        photons,
        threads: r.threads,
        wall_seconds: r.wall_seconds,
        photons_per_second: if r.wall_seconds > 0.0 { photons as f64 / r.wall_seconds } else { 0.0 },
        effects: scene.effects.names().iter().map(|s| s.to_string()).collect(),
        stop_reason: r.stop_reason,
        transport: scene.effects.transport().to_string(),
        batch_photons: BATCH_PHOTONS,
        batches: [r.batches.0, r.batches.1],
        ranks: r.ranks,
        mpi: r.mpi.clone(),
        max_bounces: scene.simulation.max_bounces,
        fom,
        image_mean_y: None,
        image_pixel_rel_error: None,
        counters: r.tallies.counters,
        rays_per_second: if r.wall_seconds > 0.0 {
            (r.tallies.counters.rays + r.tallies.counters.shadow_rays) as f64 / r.wall_seconds
        } else {
            0.0
        },
        transport_options: r.transport,
        estimator_pilot: r.pilot,
        hero_wavelengths: r.hero,
        integrator: r.integrator,
        mean_scatterings: r.tallies.mean_scatterings().0,
        mean_scatterings_stderr: r.tallies.mean_scatterings().1,
        files: Vec::new(),
    }
}

pub fn flux_csv(f: &Flux) -> String {
    let mut s = format!("{CSV_COLUMNS}\n");
    for r in &f.surfaces {
        let name = if r.name.contains([',', '"', '\n']) {
            format!("\"{}\"", r.name.replace('"', "\"\""))
        } else {
            r.name.clone()
        };
        s.push_str(&name);
        for v in r.csv_values() {
            s.push_str(&format!(",{v}"));
        }
        s.push('\n');
    }
    s
}

/// Writes `bytes` to `dir/name` through a temporary file in the same folder and a rename.
pub fn write_atomic(dir: &Path, name: &str, bytes: &[u8]) -> Result<PathBuf, Error> {
    let path = dir.join(name);
    let tmp = dir.join(format!(".{name}.tmp{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, &path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::Other(format!("cannot write {}: {e}", path.display()))
    })?;
    Ok(path)
}

pub fn write_json<T: Serialize>(dir: &Path, name: &str, value: &T) -> Result<PathBuf, Error> {
    let mut text =
        serde_json::to_string_pretty(value).map_err(|e| Error::Other(format!("cannot encode {name}: {e}")))?;
    text.push('\n');
    write_atomic(dir, name, text.as_bytes())
}

/// The per-surface table printed at the end of a run.
pub fn summary_table(f: &Flux, info: &RunInfo) -> String {
    let width =
        f.surfaces.iter().map(|r| r.name.len()).chain(f.media.iter().map(|m| m.name.len())).max().unwrap_or(4).max(7);
    let mut s = String::new();
    if f.surfaces.is_empty() {
        s.push_str("no surfaces to tally (the scene has only point lights and detectors)\n");
    } else {
        s.push_str(&format!(
            "{:<width$}  {:>12}  {:>10}  {:>12}  {:>10}  {:>8}  {:>12}\n",
            "surface", "incident W", "± stderr", "absorbed W", "± stderr", "rel err", "mean lx"
        ));
    }
    for r in &f.surfaces {
        // Nothing arrived: there is no relative error, and 0 would read as converged.
        let rel = if r.incident_w > 0.0 { format!("{:.2e}", r.rel_error) } else { "-".into() };
        s.push_str(&format!(
            "{:<width$}  {:>12.6}  {:>10.3e}  {:>12.6}  {:>10.3e}  {:>8}  {:>12.5e}\n",
            r.name, r.incident_w, r.incident_w_stderr, r.absorbed_w, r.absorbed_w_stderr, rel, r.illuminance_lx
        ));
    }
    for m in &f.media {
        s.push_str(&format!(
            "{:<width$}  {:>12}  {:>10}  {:>12.6}  {:>10.3e}  (medium, {:.4e} m³)\n",
            m.name, "-", "", m.absorbed_w, m.absorbed_w_stderr, m.volume_m3
        ));
        if let (Some(w), Some(se)) = (m.reemitted_w, m.reemitted_w_stderr) {
            s.push_str(&format!("{:<width$}  re-emitted {w:.6} ± {se:.3e} W by its luminophore\n", ""));
        }
    }
    for (what, rows) in [("map", &f.maps), ("work plane", &f.planes)] {
        for m in rows {
            let u = &m.illuminance_lx;
            s.push_str(&format!(
                "{what} {}: E_min {:.5e} ± {:.2e}  E_mean {:.5e} ± {:.2e}  E_max {:.5e} ± {:.2e} lx  U0 {:.4} ± {:.4}\n",
                m.name, u.min, u.min_stderr, u.mean, u.mean_stderr, u.max, u.max_stderr, u.u0, u.u0_stderr
            ));
        }
    }
    let l = &f.ledger;
    s.push_str(&format!(
        "ledger: emitted {:.6} W = absorbed {:.6} + escaped {:.6} + truncated {:.6} (residual {:.1e})\n",
        l.emitted_w,
        l.absorbed_w,
        l.escaped_w,
        l.truncated_w,
        l.relative_residual()
    ));
    if let (Some((y, se)), Some(px)) = (info.image_mean_y, info.image_pixel_rel_error) {
        s.push_str(&format!(
            "image: mean Y {y:.6e} ± {se:.2e} W m^-2 sr^-1 nm^-1; pixel noise {px:.3e} (relative RMS)\n"
        ));
    }
    let estimator = format!("{:?} estimator", info.transport_options.estimator).to_lowercase();
    let estimator = match &info.estimator_pilot {
        Some(_) => format!("{estimator}, chosen by a pilot run"),
        None => estimator,
    };
    s.push_str(&format!(
        "{} photons in {:.2} s ({} photons/s, {} threads, {} transport, {estimator}); stopped by {}\n",
        info.photons,
        info.wall_seconds,
        crate::run::si(info.photons_per_second),
        info.threads,
        info.transport,
        info.stop_reason.describe()
    ));
    s
}

/// image.exr: linear R, G, B (sRGB primaries, D65), Y (CIE 1931) and Y_var, f32.
pub fn write_exr(dir: &Path, image: &crate::detectors::film::Image, layer_name: &str) -> Result<PathBuf, Error> {
    use exr::prelude::*;
    let (w, h) = (image.width, image.height);
    let plane = |c: usize| -> Vec<f32> { image.rgb.index_axis(ndarray::Axis(2), c).iter().copied().collect() };
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![
        AnyChannel::new("R", FlatSamples::F32(plane(0))),
        AnyChannel::new("G", FlatSamples::F32(plane(1))),
        AnyChannel::new("B", FlatSamples::F32(plane(2))),
        AnyChannel::new("Y", FlatSamples::F32(image.xyz.column(1).to_vec())),
        AnyChannel::new("Y_var", FlatSamples::F32(image.y_var.clone())),
    ]));
    let layer = Layer::new((w, h), LayerAttributes::named(layer_name), Encoding::FAST_LOSSLESS, channels);
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(&mut bytes)
        .map_err(|e| crate::error::Error::Other(format!("cannot encode image.exr: {e}")))?;
    write_atomic(dir, "image.exr", bytes.get_ref())
}

/// Exposure of the PNG preview: the log-average luminance of the lit pixels maps to middle grey
/// 0.18 (Reinhard et al. 2002, "key" 0.18), then L/(1 + L) compresses highlights such as the
/// lamp itself, and the sRGB curve encodes.
pub fn preview_exposure(image: &crate::detectors::film::Image) -> f32 {
    let ys: Vec<f64> = image.xyz.column(1).iter().filter(|&&y| y > 0.0).map(|&y| y as f64).collect();
    if ys.is_empty() {
        return 1.0;
    }
    let log_avg = (ys.iter().map(|y| y.ln()).sum::<f64>() / ys.len() as f64).exp();
    (0.18 / log_avg) as f32
}

pub fn write_png(dir: &Path, image: &crate::detectors::film::Image) -> Result<PathBuf, Error> {
    let exposure = preview_exposure(image);
    let mut data = Vec::with_capacity(image.width * image.height * 3);
    for p in 0..image.width * image.height {
        let (row, col) = (p / image.width, p % image.width);
        let y = image.xyz[[p, 1]] * exposure;
        let compress = if y > 0.0 { 1.0 / (1.0 + y) } else { 1.0 };
        for c in 0..3 {
            let v = (image.rgb[[row, col, c]] * exposure * compress).clamp(0.0, 1.0);
            data.push((crate::spectrum::color::srgb_encode(v) * 255.0 + 0.5) as u8);
        }
    }
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, image.width as u32, image.height as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        // fdeflate's PNG-tuned mode: at 512² the default (zlib level 6) took ~0.1 s, a fifth of a
        // million-photon run, for a preview 15 % smaller.
        enc.set_compression(png::Compression::Fast);
        let mut w = enc.write_header().map_err(|e| Error::Other(format!("cannot encode image.png: {e}")))?;
        w.write_image_data(&data).map_err(|e| Error::Other(format!("cannot encode image.png: {e}")))?;
    }
    write_atomic(dir, "image.png", &bytes)
}

/// The plots' font, embedded (DejaVu Sans, see assets/fonts/) so no system font is needed.
pub fn register_plot_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let font: &'static [u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
        let _ = plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, font);
    });
}

/// spectrum_<surface>.csv for each surface with `spectrum_bins`: incident and absorbed flux per
/// wavelength bin (W, and W/nm over the bin's width), with standard errors. What the surface sends
/// back out is incident − absorbed.
pub fn write_spectra(dir: &Path, scene: &Scene, r: &RunResult) -> Result<Vec<PathBuf>, Error> {
    let t = &r.tallies;
    let model = r.transport.error_model();
    let (lo, hi) = scene.simulation.wavelength_range_nm;
    let mut written = Vec::new();
    for s in &scene.surfaces {
        let Some((bins, first)) = s.spectrum_bins else { continue };
        let width = (hi - lo) / bins as f64;
        let mut text = String::from(
            "lambda_lo_nm,lambda_hi_nm,incident_w,incident_w_stderr,incident_w_per_nm,incident_w_per_nm_stderr,\
             absorbed_w,absorbed_w_stderr,absorbed_w_per_nm,absorbed_w_per_nm_stderr\n",
        );
        for k in 0..bins {
            let (w, se) = t.estimate(&t.spectra, first + k, r.emitted_w, model);
            let (aw, ase) = t.estimate(&t.spectra_absorbed, first + k, r.emitted_w, model);
            let a = lo + k as f64 * width;
            text.push_str(&format!(
                "{a},{},{w},{se},{},{},{aw},{ase},{},{}\n",
                a + width,
                w / width,
                se / width,
                aw / width,
                ase / width
            ));
        }
        written.push(write_atomic(dir, &spectrum_file_name(&s.name), text.as_bytes())?);
    }
    Ok(written)
}

/// The files `photon run` writes for `scene`, relative to the output folder: known before any
/// photon is traced, so every name can be tried first (a name too long for the file system, a
/// folder that cannot be written) instead of failing after the work. A partial run (`partial`)
/// adds its state file.
pub fn run_file_names(scene: &Scene, image: bool, partial: bool) -> Vec<String> {
    let mut names: Vec<String> = ["flux.json", "flux.csv", "run.json"].map(String::from).into();
    if partial {
        names.push(state::STATE_FILE.into());
    }
    if image {
        names.extend(["image.exr", "image.png"].map(String::from));
    }
    for s in &scene.surfaces {
        if s.map.is_some() {
            names.extend(["exr", "png"].map(|ext| format!("maps/{}", crate::scene::map::file_name(&s.name, ext))));
        }
        if s.spectrum_bins.is_some() {
            names.push(spectrum_file_name(&s.name));
        }
    }
    for p in &scene.planes {
        names.extend(["exr", "png"].map(|ext| format!("maps/{}", crate::scene::map::file_name(&p.name, ext))));
    }
    for d in &scene.detectors {
        names.extend(["csv", "png", "ies", "ldt"].map(|ext| crate::output::farfield::file_name(&d.name, ext)));
    }
    for v in &scene.volumes {
        names.extend(["npy", "png"].map(|ext| crate::output::volume::file_name(&v.name, ext)));
    }
    names.extend(scene.ray_detectors.iter().map(|d| rays::file_name(&d.name)));
    names
}

/// The files an earlier run listed in `dir/run.json` (its `files`): the only ones a new run
/// may remove as stale. A folder without such a list loses nothing.
pub fn previous_run_files(dir: &Path) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(dir.join("run.json")) else { return Vec::new() };
    let Ok(json) = serde_json::from_str::<serde_json::Value>(&text) else { return Vec::new() };
    json["files"]
        .as_array()
        .map(|a| a.iter().filter_map(|v| v.as_str()).filter(|f| is_output_name(f)).map(String::from).collect())
        .unwrap_or_default()
}

/// A relative path photon could have written: a plain name, or one inside `maps/` (so a
/// tampered list cannot point outside the folder).
fn is_output_name(f: &str) -> bool {
    let plain = |n: &str| !n.is_empty() && n != "." && n != ".." && !n.contains(['/', '\\']);
    match f.split_once('/') {
        Some(("maps", n)) => plain(n),
        Some(_) => false,
        None => plain(f),
    }
}

pub fn spectrum_file_name(surface: &str) -> String {
    format!("spectrum_{}.csv", crate::scene::map::file_stem(surface))
}

/// Staging folders of the `OutputDir`s not yet committed or dropped, so that a process ending at
/// once (a second Ctrl-C) can still take them away: `remove_staging_folders`.
static STAGING: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Removes every staging folder still open: for a process about to exit without unwinding.
pub fn remove_staging_folders() {
    if let Ok(mut open) = STAGING.lock() {
        for d in open.drain(..) {
            let _ = std::fs::remove_dir_all(d);
        }
    }
}

fn forget_staging(dir: &Path) {
    if let Ok(mut open) = STAGING.lock() {
        open.retain(|d| d != dir);
    }
}

/// An output folder being written. Files go into a hidden staging folder first (inside the
/// target when it exists, else beside it, so the final renames stay on one file system), and
/// `commit` moves them into place: a new folder appears whole by one rename; into an existing
/// one each file is renamed into place (file by file, not at once), and then the files an
/// earlier run listed that this one did not write are removed. Dropped uncommitted, nothing is
/// left behind, not even the parent folders it had to create.
pub struct OutputDir {
    target: PathBuf,
    staging: PathBuf,
    target_existed: bool,
    /// Folders `prepare` created above the target, deepest first.
    created: Vec<PathBuf>,
    committed: bool,
}

impl OutputDir {
    /// Creates the staging folder and tries every file name in it (`names`, relative, '/'
    /// separated). Any failure here is the user's to fix (a file where the folder should be, no
    /// permission, a name too long), so it is a usage error, reported before any work.
    pub fn prepare(target: &Path, names: &[String]) -> Result<Self, Error> {
        let usage = |what: String| Error::Usage(format!("--out {}: {what}", target.display()));
        if target.file_name().is_none() && !target.is_dir() {
            return Err(usage("names no folder".into()));
        }
        let target_existed = match std::fs::metadata(target) {
            Ok(m) if m.is_dir() => true,
            Ok(_) => return Err(usage("is a file, not a folder".into())),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
            Err(e) => return Err(usage(format!("cannot be read: {e}"))),
        };
        // The counter keeps two saves of one process (threads of a Python program) apart.
        static SAVES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = SAVES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let tag = format!(".photon-staging-{}-{n}", std::process::id());
        let mut created = Vec::new();
        let staging = if target_existed {
            target.join(tag)
        } else {
            let parent = match target.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => PathBuf::from("."),
            };
            let mut missing = parent.as_path();
            while !missing.exists() {
                created.push(missing.to_path_buf());
                match missing.parent() {
                    Some(p) if !p.as_os_str().is_empty() => missing = p,
                    _ => break,
                }
            }
            std::fs::create_dir_all(&parent)
                .map_err(|e| usage(format!("cannot create the folder {}: {e}", parent.display())))?;
            parent.join(tag)
        };
        let _ = std::fs::remove_dir_all(&staging);
        let mut dir = OutputDir { target: target.to_path_buf(), staging, target_existed, created, committed: false };
        if let Err(e) = std::fs::create_dir(&dir.staging) {
            dir.staging = PathBuf::new();
            return Err(usage(format!("cannot write there: {e}")));
        }
        if let Ok(mut open) = STAGING.lock() {
            open.push(dir.staging.clone());
        }
        for name in names {
            let probe = dir.staging.join(name);
            let tried = (|| {
                if let Some(p) = probe.parent() {
                    std::fs::create_dir_all(p)?;
                }
                std::fs::File::create(&probe)?;
                std::fs::remove_file(&probe)
            })();
            tried.map_err(|e| usage(format!("cannot write {name} there: {e}")))?;
            // The same name must be free to take in the target: not a folder, its folder not a file.
            let at = target.join(name);
            if at.is_dir() || at.parent().is_some_and(|p| p.exists() && !p.is_dir()) {
                return Err(usage(format!("{name} cannot be written there: a folder or file is in its way")));
            }
        }
        Ok(dir)
    }

    /// Where to write the files now.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Moves the staged files into place (see the type's comment); `previous` lists the files an
    /// earlier run wrote there (`previous_run_files`), of which those not written now go.
    pub fn commit(mut self, previous: &[String]) -> Result<(), Error> {
        let fail =
            |e: std::io::Error| Error::Other(format!("cannot move the outputs into {}: {e}", self.target.display()));
        // Empty subfolders from the name probes go; a folder appears only with files in it.
        remove_empty_dirs(&self.staging);
        if !self.target_existed {
            match std::fs::rename(&self.staging, &self.target) {
                Ok(()) => {
                    self.committed = true;
                    forget_staging(&self.staging);
                    return Ok(());
                }
                // Another process made the folder meanwhile: move the files in one by one.
                Err(_) if self.target.is_dir() => {}
                Err(e) => return Err(fail(e)),
            }
        }
        let new = output_files(&self.staging).map_err(fail)?;
        for f in &new {
            let to = self.target.join(f);
            if let Some(p) = to.parent() {
                std::fs::create_dir_all(p).map_err(fail)?;
            }
            std::fs::rename(self.staging.join(f), to).map_err(fail)?;
        }
        self.committed = true;
        let _ = std::fs::remove_dir_all(&self.staging);
        forget_staging(&self.staging);
        for f in previous.iter().filter(|f| !new.contains(f)) {
            let _ = std::fs::remove_file(self.target.join(f));
        }
        if let Ok(maps) = std::fs::read_dir(self.target.join("maps")) {
            if maps.count() == 0 {
                let _ = std::fs::remove_dir(self.target.join("maps"));
            }
        }
        Ok(())
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        if !self.committed {
            if !self.staging.as_os_str().is_empty() {
                let _ = std::fs::remove_dir_all(&self.staging);
                forget_staging(&self.staging);
            }
            for d in &self.created {
                let _ = std::fs::remove_dir(d);
            }
        }
    }
}

/// The files photon may have written in an output folder: those at its top level and in its
/// `maps/` folder, as '/'-separated relative paths. Nothing deeper is looked at (an `--out .`
/// must not walk the user's tree).
fn output_files(dir: &Path) -> std::io::Result<Vec<String>> {
    let mut out = Vec::new();
    for (sub, prefix) in [(dir.to_path_buf(), ""), (dir.join("maps"), "maps/")] {
        let entries = match std::fs::read_dir(&sub) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound && !prefix.is_empty() => continue,
            Err(e) => return Err(e),
        };
        for entry in entries {
            let entry = entry?;
            if !entry.file_type()?.is_dir() {
                out.push(format!("{prefix}{}", entry.file_name().to_string_lossy()));
            }
        }
    }
    Ok(out)
}

fn remove_empty_dirs(dir: &Path) {
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            if e.file_type().is_ok_and(|t| t.is_dir()) {
                remove_empty_dirs(&e.path());
                let _ = std::fs::remove_dir(e.path());
            }
        }
    }
}

/// What `write_run` wrote and found.
pub struct RunReport {
    pub flux: Flux,
    pub info: RunInfo,
    /// The files written, relative to the output folder.
    pub files: Vec<String>,
    pub warnings: Vec<String>,
}

/// Everything a finished run reports, computed and checked finite (f64 for the tables, f32 for
/// the image and maps), before any file is written: what `write_run` writes and what the Python
/// module hands out as arrays.
pub struct RunEstimates<'a> {
    pub flux: Flux,
    /// run.json's contents; its `files` are filled in by `write_run`.
    pub info: RunInfo,
    pub image: Option<crate::detectors::film::Image>,
    pub maps: Vec<crate::output::maps::MapEstimate>,
    pub farfields: Vec<crate::output::farfield::FarFieldEstimate>,
    pub volumes: Vec<crate::output::volume::VolumeEstimate<'a>>,
    pub warnings: Vec<String>,
}

/// The estimates of a finished run. A scene whose magnitudes leave no finite answer is an error
/// here, so a run either reports finite results or nothing.
pub fn estimates<'a>(scene: &'a Scene, r: &RunResult) -> Result<RunEstimates<'a>, Error> {
    let maps = crate::output::maps::estimates(scene, r);
    let flux = flux_with_maps(scene, r, &maps);
    let mut info = run_info(scene, r, &flux);
    let mut warnings = Vec::new();
    let too_large = |what: &str, limit: &str| {
        Error::Usage(format!(
            "{}: {what} of this scene are not finite{limit}: its lights' power is too large for its \
             size; lower `power_w` (or `power_lm`, `radiance`)",
            scene.path.display()
        ))
    };
    let json = serde_json::to_value(&flux).map_err(|e| Error::Other(format!("cannot encode flux.json: {e}")))?;
    if !json_finite(&json) {
        return Err(too_large("the tallies", ""));
    }
    let image = r.film.as_ref().map(|f| f.image(r.emitted_w));
    let f32_limit = " in 32-bit floats (at most 3.4e38)";
    if let (Some(film), Some(image)) = (&r.film, &image) {
        let finite = |v: &f32| v.is_finite();
        if !(image.rgb.iter().all(finite) && image.xyz.iter().all(finite) && image.y_var.iter().all(finite)) {
            return Err(too_large("the image's values (or their variances)", f32_limit));
        }
        info.image_mean_y = Some(film.mean_y(r.emitted_w));
        info.image_pixel_rel_error = Some(image.pixel_rel_error()).filter(|v| v.is_finite());
        if film.film_batches() < 2 {
            warnings.push(
                "fewer than 2 film batches (<= 1024 photons): Y_var cannot be estimated and is written as 0".into(),
            );
        }
        if let Some(spp) = film.min_samples_per_pixel().filter(|&n| n < 2) {
            // The light tracer's camera part covers only the pixels its lamps project into.
            let which = match r.integrator {
                crate::integrators::camera::Integrator::Light => "pixels of the lamps in view",
                _ => "pixels (photons < 2 × pixels)",
            };
            warnings.push(format!("some {which} have {spp} camera sample(s): their Y_var is written as 0"));
        }
    }
    for m in &maps {
        let fits = |v: &[(f64, f64)]| v.iter().all(|&(x, se)| (x as f32).is_finite() && (se as f32).is_finite());
        if !(fits(&m.irradiance_w_m2()) && fits(&m.illuminance_lx())) {
            return Err(too_large(&format!("the irradiance map of \"{}\"", m.surface), f32_limit));
        }
    }
    let farfields = crate::output::farfield::estimates(scene, r);
    let volumes = crate::output::volume::estimates(scene, r);
    if let Some(v) = volumes.iter().find(|v| !v.finite()) {
        return Err(too_large(&format!("the volume detector \"{}\"", v.grid.name), ""));
    }
    Ok(RunEstimates { flux, info, image, maps, farfields, volumes, warnings })
}

/// Every output file of a run, into `dir` (the staging folder of an `OutputDir`), after
/// `estimates` has checked every number finite.
pub fn write_run(dir: &Path, scene: &Scene, r: &RunResult) -> Result<RunReport, Error> {
    let RunEstimates { flux, mut info, image, maps, farfields, volumes, warnings } = estimates(scene, r)?;
    let mut files = Vec::new();
    let mut wrote = |p: PathBuf| files.push(p.strip_prefix(dir).unwrap_or(&p).to_string_lossy().replace('\\', "/"));
    wrote(write_json(dir, "flux.json", &flux)?);
    wrote(write_atomic(dir, "flux.csv", flux_csv(&flux).as_bytes())?);
    if let Some(image) = &image {
        wrote(write_exr(dir, image, r.integrator.name())?);
        wrote(write_png(dir, image)?);
    }
    if !maps.is_empty() {
        let maps_dir = dir.join("maps");
        std::fs::create_dir_all(&maps_dir)
            .map_err(|e| Error::Other(format!("cannot create {}: {e}", maps_dir.display())))?;
        for m in &maps {
            wrote(crate::output::maps::write_exr(&maps_dir, m)?);
            wrote(crate::output::maps::write_png(&maps_dir, m, &scene.stem())?);
        }
    }
    let label = luminaire::RunLabel { scene, photons: r.tallies.photons, seed: r.seed };
    for e in &farfields {
        wrote(crate::output::farfield::write_csv(dir, e)?);
        wrote(crate::output::farfield::write_png(dir, e, &scene.stem())?);
        wrote(luminaire::write_ies(dir, e, &label)?);
        wrote(luminaire::write_ldt(dir, e, &label)?);
    }
    for k in 0..scene.ray_detectors.len() {
        wrote(rays::write_npy(dir, scene, r, k)?);
    }
    for v in &volumes {
        wrote(crate::output::volume::write_npy(dir, v)?);
        wrote(crate::output::volume::write_png(dir, v, scene)?);
    }
    for p in write_spectra(dir, scene, r)? {
        wrote(p);
    }
    if r.partial {
        wrote(write_atomic(dir, state::STATE_FILE, &state::encode(scene, r)?)?);
    }
    info.files = files.iter().cloned().chain(["run.json".to_string()]).collect();
    write_json(dir, "run.json", &info)?;
    let files = info.files.clone();
    Ok(RunReport { flux, info, files, warnings })
}

/// No number of `v` is null (serde_json's NaN and infinity) or non-finite.
fn json_finite(v: &serde_json::Value) -> bool {
    match v {
        serde_json::Value::Null => false,
        serde_json::Value::Number(n) => n.as_f64().is_some_and(f64::is_finite),
        serde_json::Value::Array(a) => a.iter().all(json_finite),
        serde_json::Value::Object(o) => o.values().all(json_finite),
        _ => true,
    }
}
