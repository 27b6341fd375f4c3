//! A partial run's mergeable state (`state.photon`, written by `photon run --batches A..B`), and
//! `photon merge`: the union of parts covering batches 0..N writes the files `photon run` writes
//! for those N batches, byte for byte (run.json's timings aside), because a run's totals are
//! exact sums (`detectors::exact`) that any grouping of its batches adds up alike.
//!
//! Format, version 1 (integers and floats little-endian):
//!
//! | bytes | what |
//! | --- | --- |
//! | 16 | magic `photon-state\n` and three zero bytes |
//! | 4 | format version (u32) |
//! | 4 + n | header length n (u32), then the header: UTF-8 JSON, `StateHeader` |
//! | … | body: 12 counts (u64: photons, batches, scatterings, scatterings², eight work counters), trace seconds (f64), escaped and truncated (sums), the channel count (u32) and per channel its rows (u64) and each row's Σx, Σx², Σ_b S_b²/n_b; then 0 or 1 (u8) and the film: width, height, photons, film batches (u64), the image's Σ_b S_b²/n_b, per pixel X, Y, Z, Y²-term; then 0, 1 or 2 (u8) and the camera part: with 2 (the light tracer's lamps in view) its pixel count (u64) and pixels (u32, ascending), then per pixel (every pixel with 1) X, Y, Z, ΣY², then per pixel its sample count (u32) |
//! | 8 | FNV-1a 64 of every byte before it |
//!
//! A sum is 28 bytes (`ExactSum::to_bytes`). Reading checks the magic, version, length and
//! checksum before anything else; merging checks that the parts' scene (the digest of its text
//! and every file it read), seed and options agree and that their batches neither overlap nor
//! leave a gap.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::detectors::exact::ExactSum;
use crate::detectors::film::{Film, FilmState, PixelSums};
use crate::detectors::tally::{ChannelSums, Counters, Tallies, TallySums, CHANNELS};
use crate::error::{Error, InputError};
use crate::integrators::camera::Integrator;
use crate::integrators::particle::TransportOptions;
use crate::run::{EstimatorPilot, RunResult, StopReason, BATCH_PHOTONS};
use crate::scene::Scene;

/// The state file's name in a part's output folder.
pub const STATE_FILE: &str = "state.photon";
const MAGIC: &[u8; 16] = b"photon-state\n\0\0\0";
/// 2: the light tracer's lamps in view are in the film's camera part (`EmitterView`), not its
/// splats; a version-1 part's lamp would be counted twice beside them.
pub const FORMAT_VERSION: u32 = 2;
/// Largest header accepted: a corrupt length must not allocate gigabytes.
const MAX_HEADER_BYTES: u32 = 1 << 20;

/// The header: what a part is of (these must agree across parts), and which batches it holds.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct StateHeader {
    pub photon_version: String,
    /// The scene file as the run named it, and as an absolute path (what `merge` loads).
    pub scene: String,
    pub scene_absolute: String,
    /// FNV-1a 64 of the scene text and every file it read, in hex.
    pub input_digest: String,
    pub seed: u64,
    pub batch_photons: u64,
    pub emitted_w: f64,
    pub max_bounces: u32,
    pub image: bool,
    pub integrator: Integrator,
    /// The transport options in force (the estimator resolved), the pilot that resolved it.
    pub transport: TransportOptions,
    pub pilot: Option<EstimatorPilot>,
    pub hero: bool,
    /// Batches first_batch..end_batch.
    pub first_batch: u64,
    pub end_batch: u64,
    pub threads: usize,
    pub wall_seconds: f64,
    pub stop_reason: StopReason,
}

impl StateHeader {
    /// The fields every part of one run shares, with their names, for messages.
    fn identity(&self) -> Vec<(&'static str, String)> {
        vec![
            ("photon_version", self.photon_version.clone()),
            ("input_digest (the scene and the files it reads)", self.input_digest.clone()),
            ("seed", self.seed.to_string()),
            ("batch_photons", self.batch_photons.to_string()),
            ("emitted_w", format!("{:?}", self.emitted_w.to_bits())),
            ("max_bounces", self.max_bounces.to_string()),
            ("image", self.image.to_string()),
            ("integrator", format!("{:?}", self.integrator)),
            ("transport", format!("{:?}", self.transport)),
            ("pilot", format!("{:?}", self.pilot)),
            ("hero", self.hero.to_string()),
        ]
    }
}

/// A part's header and where it was read from: what `check_parts` needs, without the part's
/// tallies and film (`photon merge` holds one part's arrays at a time).
#[derive(Clone, Debug)]
pub struct PartHeader {
    pub path: PathBuf,
    pub header: StateHeader,
}

/// A part read back: its header and its exact tallies and film (views not yet sized to a scene).
pub struct Part {
    pub path: PathBuf,
    pub header: StateHeader,
    counts: Counts,
    sums: TallySums,
    film: Option<FilmState>,
}

struct Counts {
    photons: u64,
    batches: u64,
    scatterings: u64,
    scatterings_sq: u64,
    counters: Counters,
}

/// The state of run `r` of `scene` (a `--batches` run).
pub fn encode(scene: &Scene, r: &RunResult) -> Result<Vec<u8>, Error> {
    let sums = r.tallies.sums.as_deref().ok_or_else(|| Error::Other("the run kept no exact sums".into()))?;
    let header = StateHeader {
        photon_version: env!("CARGO_PKG_VERSION").to_string(),
        scene: scene.path.display().to_string(),
        scene_absolute: std::path::absolute(&scene.path).unwrap_or_else(|_| scene.path.clone()).display().to_string(),
        input_digest: format!("{:016x}", scene.input_digest),
        seed: r.seed,
        batch_photons: BATCH_PHOTONS,
        emitted_w: r.emitted_w,
        max_bounces: scene.simulation.max_bounces,
        image: r.film.is_some(),
        integrator: r.integrator,
        transport: r.transport,
        pilot: r.pilot,
        hero: r.hero,
        first_batch: r.batches.0,
        end_batch: r.batches.1,
        threads: r.threads,
        wall_seconds: r.wall_seconds,
        stop_reason: r.stop_reason,
    };
    let json = serde_json::to_vec(&header).map_err(|e| Error::Other(format!("cannot write the state header: {e}")))?;
    let mut w = Vec::new();
    w.extend_from_slice(MAGIC);
    w.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    w.extend_from_slice(&(json.len() as u32).to_le_bytes());
    w.extend_from_slice(&json);
    let t = &r.tallies;
    let c = &t.counters;
    for v in [t.photons, t.batches, t.scatterings, t.scatterings_sq].into_iter().chain(c.counts()) {
        w.extend_from_slice(&v.to_le_bytes());
    }
    w.extend_from_slice(&c.trace_seconds.to_le_bytes());
    w.extend_from_slice(&sums.escaped.to_bytes());
    w.extend_from_slice(&sums.truncated.to_bytes());
    w.extend_from_slice(&(sums.channels.len() as u32).to_le_bytes());
    for ch in &sums.channels {
        w.extend_from_slice(&(ch.sum.len() as u64).to_le_bytes());
        for i in 0..ch.sum.len() {
            for s in [&ch.sum[i], &ch.sum_sq[i], &ch.batch_sq[i]] {
                w.extend_from_slice(&s.to_bytes());
            }
        }
    }
    match &r.film {
        None => w.push(0),
        Some(film) => {
            w.push(1);
            let f = film.state();
            for v in [f.width as u64, f.height as u64, f.photons, f.film_batches] {
                w.extend_from_slice(&v.to_le_bytes());
            }
            w.extend_from_slice(&f.image_y_sq_over_n.to_bytes());
            put_pixels(&mut w, &f.pixels);
            match &f.camera {
                None => w.push(0),
                Some((listed, sums, count)) => {
                    match listed {
                        None => w.push(1),
                        Some(l) => {
                            w.push(2);
                            w.extend_from_slice(&(l.len() as u64).to_le_bytes());
                            for p in l {
                                w.extend_from_slice(&p.to_le_bytes());
                            }
                        }
                    }
                    put_pixels(&mut w, sums);
                    for n in count {
                        w.extend_from_slice(&n.to_le_bytes());
                    }
                }
            }
        }
    }
    let check = crate::error::fnv1a(crate::error::FNV_OFFSET, &w);
    w.extend_from_slice(&check.to_le_bytes());
    Ok(w)
}

fn put_pixels(w: &mut Vec<u8>, pixels: &[PixelSums]) {
    for p in pixels {
        for s in &p.lanes() {
            w.extend_from_slice(&s.to_bytes());
        }
    }
}

/// Reads bytes off a state file, each shortfall an error naming what was being read.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        if self.bytes.len() - self.at < n {
            return Err(format!("it ends inside {what} (byte {})", self.at));
        }
        let s = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }

    fn u8(&mut self, what: &str) -> Result<u8, String> {
        Ok(self.take(1, what)?[0])
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }

    fn u64(&mut self, what: &str) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }

    fn f64(&mut self, what: &str) -> Result<f64, String> {
        Ok(f64::from_bits(self.u64(what)?))
    }

    fn sum(&mut self, what: &str) -> Result<ExactSum, String> {
        let at = self.at;
        ExactSum::from_bytes(self.take(28, what)?.try_into().expect("28 bytes"))
            .ok_or_else(|| format!("{what} at byte {at} is no valid sum"))
    }

    /// A count of items of `item_bytes` each that must fit in what is left (so a corrupt count
    /// cannot allocate more than the file holds).
    fn count(&mut self, item_bytes: usize, what: &str) -> Result<usize, String> {
        let at = self.at;
        let n = self.u64(what)?;
        let left = (self.bytes.len() - self.at) as u64;
        if n.checked_mul(item_bytes as u64).is_none_or(|b| b > left) {
            return Err(format!("{what} at byte {at} is {n}, more than the file holds"));
        }
        Ok(n as usize)
    }

    fn pixels(&mut self, n: usize, what: &str) -> Result<Vec<PixelSums>, String> {
        (0..n)
            .map(|_| Ok(PixelSums::from_lanes([self.sum(what)?, self.sum(what)?, self.sum(what)?, self.sum(what)?])))
            .collect()
    }
}

/// Reads and checks a part's state file (a folder holding `state.photon`, or the file itself).
pub fn read_part(path: &Path) -> Result<Part, Error> {
    let file = if path.is_dir() { path.join(STATE_FILE) } else { path.to_path_buf() };
    let bad = |m: String| Error::Input(InputError::new(&file, "", None, m));
    // A regular file, read to its length only: a device or a pipe must not fill the memory.
    let meta = std::fs::metadata(&file).map_err(|e| bad(format!("cannot read the partial run's state: {e}")))?;
    if !meta.is_file() {
        return Err(bad("cannot read the partial run's state: it is not a regular file".into()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    std::io::Read::read_to_end(
        &mut std::io::Read::take(
            std::fs::File::open(&file).map_err(|e| bad(format!("cannot read the partial run's state: {e}")))?,
            meta.len(),
        ),
        &mut bytes,
    )
    .map_err(|e| bad(format!("cannot read the partial run's state: {e}")))?;
    part_from_bytes(&bytes, &file)
}

/// A part from the bytes of a state (a file's, or another rank's); `origin` names it in messages.
pub fn part_from_bytes(bytes: &[u8], origin: &Path) -> Result<Part, Error> {
    decode(bytes)
        .map(|(header, counts, sums, film)| Part { path: origin.to_path_buf(), header, counts, sums, film })
        .map_err(|m| {
            let m = format!("{m}; it is not a complete {STATE_FILE} of photon {}", env!("CARGO_PKG_VERSION"));
            Error::Input(InputError::new(origin, "", None, m))
        })
}

/// A part's time in seconds: the sum over any number of parts must stay finite (run.json
/// writes it), so a part's is bounded, at 10¹² s (32 000 years), far above any run's.
fn plausible_seconds(s: f64) -> bool {
    (0.0..=1e12).contains(&s)
}

type Decoded = (StateHeader, Counts, TallySums, Option<FilmState>);

fn decode(bytes: &[u8]) -> Result<Decoded, String> {
    if bytes.len() < MAGIC.len() + 8 + 8 || &bytes[..MAGIC.len()] != MAGIC {
        return Err("it does not start as a photon state file does".into());
    }
    let (body, check) = bytes.split_at(bytes.len() - 8);
    let mut r = Reader { bytes: body, at: MAGIC.len() };
    let version = r.u32("the format version")?;
    if version != FORMAT_VERSION {
        return Err(format!("its format version is {version}; this photon reads version {FORMAT_VERSION}"));
    }
    if crate::error::fnv1a(crate::error::FNV_OFFSET, body).to_le_bytes() != check {
        return Err("its checksum does not match: the file is truncated or corrupt".into());
    }
    let n = r.u32("the header length")?;
    if n > MAX_HEADER_BYTES {
        return Err(format!("its header length {n} is implausible"));
    }
    let header: StateHeader = serde_json::from_slice(r.take(n as usize, "the header")?)
        .map_err(|e| format!("its header is not valid: {e}"))?;
    let mut next = |what: &str| r.u64(what);
    let counts = Counts {
        photons: next("the photon count")?,
        batches: next("the batch count")?,
        scatterings: next("the scattering count")?,
        scatterings_sq: next("the scattering count")?,
        counters: Counters {
            rays: next("the counters")?,
            shadow_rays: next("the counters")?,
            fresnel_evaluations: next("the counters")?,
            wavelength_samples: next("the counters")?,
            splats: next("the counters")?,
            free_flights: next("the counters")?,
            phase_samples: next("the counters")?,
            reemissions: next("the counters")?,
            trace_seconds: 0.0,
        },
    };
    let mut counts = counts;
    let at = r.at;
    counts.counters.trace_seconds = r.f64("the trace seconds")?;
    if !plausible_seconds(counts.counters.trace_seconds) {
        return Err(format!("the trace seconds at byte {at} are {}, not a run's time", counts.counters.trace_seconds));
    }
    if !plausible_seconds(header.wall_seconds) {
        return Err(format!("its header's wall_seconds is {}, not a run's time", header.wall_seconds));
    }
    let escaped = r.sum("the escaped sum")?;
    let truncated = r.sum("the truncated sum")?;
    let channels = r.u32("the channel count")? as usize;
    if channels != CHANNELS {
        return Err(format!("it has {channels} tally channels, not {CHANNELS}"));
    }
    let mut sums = TallySums { channels: Vec::with_capacity(CHANNELS), escaped, truncated };
    for _ in 0..channels {
        let rows = r.count(3 * 28, "a channel's row count")?;
        let mut ch = ChannelSums {
            sum: Vec::with_capacity(rows),
            sum_sq: Vec::with_capacity(rows),
            batch_sq: Vec::with_capacity(rows),
        };
        for _ in 0..rows {
            ch.sum.push(r.sum("a tally row")?);
            ch.sum_sq.push(r.sum("a tally row")?);
            ch.batch_sq.push(r.sum("a tally row")?);
        }
        sums.channels.push(ch);
    }
    let film = match r.u8("the film flag")? {
        0 => None,
        1 => {
            let at = r.at;
            let (width, height) = (r.u64("the film width")?, r.u64("the film height")?);
            let pixels = width
                .checked_mul(height)
                .filter(|&p| p.checked_mul(4 * 28).is_some_and(|b| b <= (body.len() - at) as u64))
                .ok_or_else(|| format!("the film size {width}×{height} at byte {at} is more than the file holds"))?
                as usize;
            let photons = r.u64("the film's photon count")?;
            let film_batches = r.u64("the film's batch count")?;
            let image_y_sq_over_n = r.sum("the film's image sum")?;
            let pixel_sums = r.pixels(pixels, "the film's pixels")?;
            let camera = match r.u8("the camera-part flag")? {
                0 => None,
                flag @ (1 | 2) => {
                    let listed = if flag == 2 {
                        let at = r.at;
                        let n = r.u64("the camera part's pixel count")?;
                        if n > pixels as u64 {
                            return Err(format!("the camera part at byte {at} lists {n} pixels, more than the film's"));
                        }
                        let l = (0..n).map(|_| r.u32("the camera part's pixel list")).collect::<Result<Vec<_>, _>>()?;
                        Some(l)
                    } else {
                        None
                    };
                    let entries = listed.as_ref().map_or(pixels, |l| l.len());
                    let sums = r.pixels(entries, "the camera part's pixels")?;
                    let count =
                        (0..entries).map(|_| r.u32("the camera part's counts")).collect::<Result<Vec<_>, _>>()?;
                    Some((listed, sums, count))
                }
                f => return Err(format!("the camera-part flag is {f}, not 0, 1 or 2")),
            };
            Some(FilmState {
                width: width as usize,
                height: height as usize,
                pixels: pixel_sums,
                image_y_sq_over_n,
                photons,
                film_batches,
                camera,
            })
        }
        f => return Err(format!("the film flag is {f}, not 0 or 1")),
    };
    if r.at != body.len() {
        return Err(format!("{} bytes follow its end", body.len() - r.at));
    }
    if header.end_batch < header.first_batch || header.end_batch - header.first_batch != counts.batches {
        return Err(format!(
            "its header says batches {}..{} but its tallies hold {} batches",
            header.first_batch, header.end_batch, counts.batches
        ));
    }
    Ok((header, counts, sums, film))
}

/// Checks that `parts` are of one run (scene, seed, options) and cover an unbroken range of
/// batches once each; returns them sorted by their first batch.
pub fn check_parts(mut parts: Vec<PartHeader>) -> Result<Vec<PartHeader>, Error> {
    let usage = |m: String| Error::Usage(m);
    if parts.is_empty() {
        return Err(usage("photon merge needs at least one part".into()));
    }
    let first = &parts[0];
    for p in &parts[1..] {
        for ((key, a), (_, b)) in first.header.identity().iter().zip(p.header.identity()) {
            if *a != b {
                return Err(usage(format!(
                    "{} and {} are not parts of one run: their {key} differs ({a} against {b})",
                    first.path.display(),
                    p.path.display()
                )));
            }
        }
    }
    parts.sort_by_key(|p| (p.header.first_batch, p.header.end_batch));
    for w in parts.windows(2) {
        let (a, b) = (&w[0].header, &w[1].header);
        if b.first_batch < a.end_batch {
            return Err(usage(format!(
                "{} (batches {}..{}) and {} (batches {}..{}) overlap: every batch must be in one part only",
                w[0].path.display(),
                a.first_batch,
                a.end_batch,
                w[1].path.display(),
                b.first_batch,
                b.end_batch
            )));
        }
        if b.first_batch > a.end_batch {
            return Err(usage(format!(
                "batches {}..{} are in no part (between {} and {}): run them with --batches {}..{}",
                a.end_batch,
                b.first_batch,
                w[0].path.display(),
                w[1].path.display(),
                a.end_batch,
                b.first_batch
            )));
        }
    }
    Ok(parts)
}

impl Part {
    /// Its header alone, the tallies and film dropped.
    pub fn into_header(self) -> PartHeader {
        PartHeader { path: self.path, header: self.header }
    }
}

/// The run the parts (checked by `check_parts`) make together, for `write_run`: each part is read
/// again and added, one at a time, so the memory a merge takes is one part's, however many.
pub fn merge(scene: &Scene, parts: &[PartHeader]) -> Result<RunResult, Error> {
    let h = &parts[0].header;
    if format!("{:016x}", scene.input_digest) != h.input_digest {
        return Err(Error::Usage(format!(
            "{} is not the scene the parts were run on: it, or a file it reads, changed since",
            scene.path.display()
        )));
    }
    let mut r = RunResult {
        tallies: Tallies::for_run(scene),
        emitted_w: h.emitted_w,
        seed: h.seed,
        threads: parts.iter().map(|p| p.header.threads).max().unwrap_or(1),
        // The parts' own times: what the run cost, wherever it ran.
        wall_seconds: parts.iter().map(|p| p.header.wall_seconds).sum(),
        stop_reason: StopReason::Photons,
        film: None,
        transport: h.transport,
        pilot: h.pilot,
        hero: h.hero,
        integrator: h.integrator,
        batches: (parts[0].header.first_batch, parts[parts.len() - 1].header.end_batch),
        partial: false,
        ranks: 1,
        mpi: None,
    };
    for ph in parts {
        let p = read_part(&ph.path)?;
        if p.header != ph.header {
            return Err(Error::Input(InputError::new(&ph.path, "", None, "changed while it was being merged")));
        }
        add_part(scene, &mut r, p)?;
    }
    if let (Some(f), Some(cam)) = (&r.film, &scene.camera) {
        if (f.width, f.height) != (cam.resolution[0] as usize, cam.resolution[1] as usize) {
            return Err(Error::Usage(format!(
                "the parts' film is {}×{} pixels, the scene's camera {}×{}",
                f.width, f.height, cam.resolution[0], cam.resolution[1]
            )));
        }
    }
    Ok(r)
}

/// Adds a part's tallies and film to `r` (a run of `scene` that keeps exact sums).
pub fn add_part(scene: &Scene, r: &mut RunResult, p: Part) -> Result<(), Error> {
    let bad = |m: String| {
        Error::Input(InputError::new(&p.path, "", None, format!("does not fit {}: {m}", scene.path.display())))
    };
    let mut part = Tallies::for_run(scene);
    let expected: Vec<usize> = part.channels().iter().map(|c| c.len()).collect();
    let found: Vec<usize> = p.sums.channels.iter().map(|c| c.sum.len()).collect();
    if expected != found {
        return Err(bad(format!("its tallies have {found:?} rows, the scene's {expected:?}")));
    }
    part.sums = Some(Box::new(p.sums));
    part.photons = p.counts.photons;
    part.batches = p.counts.batches;
    part.scatterings = p.counts.scatterings;
    part.scatterings_sq = p.counts.scatterings_sq;
    part.counters = p.counts.counters;
    r.tallies.merge_run(&part).map_err(bad)?;
    if let Some(state) = p.film {
        let f = Film::from_state(state).ok_or_else(|| bad("its film's arrays do not fit its size".into()))?;
        match r.film.as_mut() {
            None => r.film = Some(f),
            Some(acc) => acc.merge_run(&f).map_err(bad)?,
        }
    }
    Ok(())
}
