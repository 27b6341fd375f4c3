//! Per-surface tallies with standard errors, and the energy ledger.
//!
//! Estimator: each photon history i scores x_i (its weight arriving at, or absorbed by, a surface,
//! summed over the history, times Φ_total). The tally is x̄ = (1/N)Σx_i with standard error
//! s = sqrt((⟨x²⟩ − x̄²)/(N − 1)). Histories are independent, so s falls as 1/√N.

use super::exact::{self, ExactSum};

/// Channels in a `Tallies` (see `Tallies::channels`).
pub const CHANNELS: usize = 13;

/// Σx and Σx² over histories, in units of the photon's emitted weight.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moments {
    pub sum: f64,
    pub sum_sq: f64,
}

impl Moments {
    #[inline]
    pub fn add_history(&mut self, x: f64) {
        self.sum += x;
        self.sum_sq += x * x;
    }

    pub fn merge(&mut self, other: &Moments) {
        self.sum += other.sum;
        self.sum_sq += other.sum_sq;
    }

    /// (mean, standard error of the mean) of the per-history score times `scale`.
    pub fn estimate(&self, n: u64, scale: f64) -> (f64, f64) {
        if n == 0 {
            return (0.0, 0.0);
        }
        let nf = n as f64;
        let mean = self.sum / nf;
        let var = if n > 1 { ((self.sum_sq / nf - mean * mean).max(0.0)) / (nf - 1.0) } else { 0.0 };
        (mean * scale, var.sqrt() * scale)
    }
}

/// Rows up to which `HistoryScores` folds every row at a history's end instead of listing the
/// touched ones.
const DENSE_ROWS: usize = 16;

/// Accumulates one history's scores per surface, then folds them into `Moments` when the history
/// ends, so Σx² is over whole histories (a photon hitting a surface twice scores 2, not 1 + 1).
pub struct HistoryScores {
    value: Vec<f64>,
    touched: Vec<u32>,
    /// Few rows (a box's surfaces): `add` marks its row in `dense_touched` (a bit a row) instead
    /// of pushing to a list, and `flush` folds the marked rows.
    dense: bool,
    dense_touched: u32,
    /// Where a history's wavelength can change (fluorescence), each score times the luminous
    /// efficacy when it was added (`set_efficacy`); empty otherwise, and the history's one
    /// efficacy is applied at `flush_scaled`.
    luminous: Vec<f64>,
    efficacy: f64,
}

impl HistoryScores {
    pub fn new(surfaces: usize) -> Self {
        HistoryScores {
            value: vec![0.0; surfaces],
            touched: if surfaces <= DENSE_ROWS { Vec::new() } else { Vec::with_capacity(64) },
            dense: surfaces <= DENSE_ROWS,
            dense_touched: 0,
            luminous: Vec::new(),
            efficacy: 0.0,
        }
    }

    /// This history's score so far in `slot`.
    #[inline]
    pub fn value(&self, slot: u32) -> f64 {
        self.value[slot as usize]
    }

    /// As `new`, also keeping each score's lumens at the efficacy current when it was added.
    pub fn with_luminous(surfaces: usize) -> Self {
        HistoryScores {
            luminous: vec![0.0; surfaces],
            dense: false,
            touched: Vec::with_capacity(64),
            ..HistoryScores::new(surfaces)
        }
    }

    /// The luminous efficacy (lm/W) of the scores added from now on (`with_luminous` only).
    #[inline]
    pub fn set_efficacy(&mut self, lm_per_w: f64) {
        self.efficacy = lm_per_w;
    }

    #[inline]
    pub fn add(&mut self, surface: u32, x: f64) {
        let v = &mut self.value[surface as usize];
        if self.dense {
            *v += x;
            self.dense_touched |= 1 << surface;
            return;
        }
        if *v == 0.0 {
            self.touched.push(surface);
        }
        *v += x;
        if !self.luminous.is_empty() {
            self.luminous[surface as usize] += x * self.efficacy;
        }
    }

    /// Ends the history: each touched surface's score goes into `into`, and the buffer is cleared.
    #[inline]
    pub fn flush(&mut self, into: &mut [Moments]) {
        self.flush_scaled(into, None);
    }

    /// As `flush`, also adding the history's lumens to `luminous`: score × `lm_per_w` (a history's
    /// luminous efficacy is fixed: one wavelength, or one light's spectrum in grey transport), or
    /// with `with_luminous` the lumens kept score by score.
    #[inline]
    pub fn flush_scaled(&mut self, into: &mut [Moments], mut luminous: Option<(&mut [Moments], f64)>) {
        if self.dense {
            // The marked rows only (an unmarked row holds 0, and adding 0 to Σx and Σx² changes
            // no bit), the lumens decided once: every row, indexed, with the choice inside the
            // loop, took ~250 instructions a history (7 % of the grey Cornell box's).
            let rows = self.value.len();
            let (into, value) = (&mut into[..rows], &mut self.value[..rows]);
            let mut touched = std::mem::take(&mut self.dense_touched);
            match luminous {
                Some((lum, k)) => {
                    let lum = &mut lum[..rows];
                    while touched != 0 {
                        let s = (touched.trailing_zeros() as usize).min(rows - 1);
                        touched &= touched - 1;
                        into[s].add_history(value[s]);
                        lum[s].add_history(value[s] * k);
                        value[s] = 0.0;
                    }
                }
                None => {
                    while touched != 0 {
                        let s = (touched.trailing_zeros() as usize).min(rows - 1);
                        touched &= touched - 1;
                        into[s].add_history(value[s]);
                        value[s] = 0.0;
                    }
                }
            }
            return;
        }
        for &s in &self.touched {
            let v = &mut self.value[s as usize];
            into[s as usize].add_history(*v);
            if let Some((lum, k)) = luminous.as_mut() {
                if self.luminous.is_empty() {
                    lum[s as usize].add_history(*v * *k);
                } else {
                    lum[s as usize].add_history(self.luminous[s as usize]);
                }
            }
            if !self.luminous.is_empty() {
                self.luminous[s as usize] = 0.0;
            }
            *v = 0.0;
        }
        self.touched.clear();
    }
}

/// One quantity tallied per surface: per-history moments, and Σ_b S_b²/n_b over merged batches
/// (S_b a batch's sum, n_b its photons) for the between-batch error that stratified emission
/// needs (its histories are not independent).
#[derive(Clone, Debug, PartialEq)]
pub struct Channel {
    pub moments: Vec<Moments>,
    pub batch_sq: Vec<f64>,
}

impl Channel {
    pub fn new(surfaces: usize) -> Self {
        Channel { moments: vec![Moments::default(); surfaces], batch_sq: vec![0.0; surfaces] }
    }

    pub fn len(&self) -> usize {
        self.moments.len()
    }

    pub fn is_empty(&self) -> bool {
        self.moments.is_empty()
    }

    fn merge(&mut self, b: &Channel, batch_photons: u64) {
        if batch_photons > 0 {
            let n = batch_photons as f64;
            for (acc, m) in self.batch_sq.iter_mut().zip(&b.moments) {
                *acc += m.sum * m.sum / n;
            }
        }
        for (a, x) in self.moments.iter_mut().zip(&b.moments) {
            a.merge(x);
        }
    }
}

/// Everything one batch (or a whole run, once batches are merged in order) has tallied.
#[derive(Clone, Debug, PartialEq)]
pub struct Tallies {
    pub photons: u64,
    /// Weight arriving at and absorbed by each surface; the same times the history's luminous
    /// efficacy 683·ȳ(λ) lm/W (for photometric units).
    pub incident: Channel,
    pub absorbed: Channel,
    pub incident_lm: Channel,
    pub absorbed_lm: Channel,
    /// Incident weight per texel of the scene's irradiance maps (W and lm, as above).
    pub texels: Channel,
    pub texels_lm: Channel,
    /// Weight leaving the scene per far-field bin (W and lm).
    pub farfield: Channel,
    pub farfield_lm: Channel,
    /// Incident and absorbed weight per wavelength bin of the surfaces that ask for a spectrum.
    pub spectra: Channel,
    pub spectra_absorbed: Channel,
    /// Weight re-emitted by each medium's luminophore (a row per medium; empty without media).
    pub reemitted: Channel,
    /// Per voxel of the volume detectors: weight absorbed there, and weight × path length (m)
    /// inside it (the track-length estimator of fluence).
    pub volume_absorbed: Channel,
    pub volume_track: Channel,
    /// Weight that left the scene, and weight still in flight at the bounce cap.
    pub escaped: f64,
    pub truncated: f64,
    /// Scattering events per history: Σk and Σk², for the mean path length and its error.
    pub scatterings: u64,
    pub scatterings_sq: u64,
    pub counters: Counters,
    pub batches: u64,
    /// A run's exact totals, which every f64 above (but the counters' seconds) is rounded from;
    /// None in a batch's own tallies, whose sums are plain f64 in photon order.
    pub sums: Option<Box<TallySums>>,
    /// Arrivals on the surfaces of ray-set detectors, in photon order within a batch and batch
    /// order within a run (empty without such detectors).
    pub rays: Vec<RayArrival>,
}

/// One photon's arrival on a ray-set detector's surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayArrival {
    pub detector: u32,
    /// The hit point in the tracer's recentred frame (m), and the direction of travel.
    pub position: [f64; 3],
    pub direction: [f32; 3],
    /// nm; NaN in grey transport.
    pub lambda_nm: f64,
    /// The photon's weight on arrival (× the run's watts per weight = its power).
    pub weight: f64,
}

/// The exact totals behind a run's `Tallies` (see `exact`): what partial runs and MPI ranks
/// exchange, so that any grouping of the batches gives the same bits.
#[derive(Clone, Debug, PartialEq)]
pub struct TallySums {
    /// One per channel, in `Tallies::channels` order.
    pub channels: Vec<ChannelSums>,
    pub escaped: ExactSum,
    pub truncated: ExactSum,
}

/// Exact Σx, Σx² and Σ_b S_b²/n_b of one channel, per row.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelSums {
    pub sum: Vec<ExactSum>,
    pub sum_sq: Vec<ExactSum>,
    pub batch_sq: Vec<ExactSum>,
}

impl ChannelSums {
    fn new(rows: usize) -> Self {
        ChannelSums {
            sum: vec![ExactSum::default(); rows],
            sum_sq: vec![ExactSum::default(); rows],
            batch_sq: vec![ExactSum::default(); rows],
        }
    }

    /// Adds a batch's rows (`batch_photons` photons) and rounds the rows it touched into `view`.
    fn add_batch(&mut self, view: &mut Channel, b: &Channel, batch_photons: u64) {
        let n = batch_photons as f64;
        for (i, m) in b.moments.iter().enumerate() {
            if m.sum == 0.0 && m.sum_sq == 0.0 {
                continue;
            }
            self.sum[i].add(m.sum);
            self.sum_sq[i].add(m.sum_sq);
            if batch_photons > 0 {
                self.batch_sq[i].add(m.sum * m.sum / n);
            }
            view.moments[i] = Moments { sum: self.sum[i].value(), sum_sq: self.sum_sq[i].value() };
            view.batch_sq[i] = self.batch_sq[i].value();
        }
    }

    fn add_sums(&mut self, o: &ChannelSums) -> Result<(), exact::Overflow> {
        exact::add_all(&mut self.sum, &o.sum)?;
        exact::add_all(&mut self.sum_sq, &o.sum_sq)?;
        exact::add_all(&mut self.batch_sq, &o.batch_sq)
    }

    fn round_into(&self, view: &mut Channel) {
        for i in 0..self.sum.len() {
            view.moments[i] = Moments { sum: self.sum[i].value(), sum_sq: self.sum_sq[i].value() };
            view.batch_sq[i] = self.batch_sq[i].value();
        }
    }
}

/// Which spread a standard error is computed from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorModel {
    /// Independent photon histories (plain sampling).
    Histories,
    /// Independent batches (stratified sampling correlates histories within a batch).
    Batches,
}

/// Work done, for benchmarks and for showing which physics ran (not for any estimate).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Counters {
    /// Closest-hit rays traced (emission and scattering).
    pub rays: u64,
    /// Visibility rays toward the camera.
    pub shadow_rays: u64,
    /// Fresnel terms evaluated (one per dielectric hit).
    pub fresnel_evaluations: u64,
    /// Wavelengths drawn from a light's spectrum at emission (one per photon in spectral
    /// transport; none in grey transport, which carries no wavelength).
    pub wavelength_samples: u64,
    /// Splats that reached the film.
    pub splats: u64,
    /// Free-flight distances drawn in scattering media, and phase-function samples taken there
    /// (none in a scene without scattering media).
    pub free_flights: u64,
    pub phase_samples: u64,
    /// Photons a luminophore absorbed and re-emitted at a new wavelength (none without
    /// fluorescence).
    pub reemissions: u64,
    /// Seconds the batches took to trace, summed over batches (thread time, not wall time).
    pub trace_seconds: f64,
}

impl Counters {
    /// The counts, in the state file's order.
    pub fn counts(&self) -> [u64; 8] {
        [
            self.rays,
            self.shadow_rays,
            self.fresnel_evaluations,
            self.wavelength_samples,
            self.splats,
            self.free_flights,
            self.phase_samples,
            self.reemissions,
        ]
    }

    fn counts_mut(&mut self) -> [&mut u64; 8] {
        [
            &mut self.rays,
            &mut self.shadow_rays,
            &mut self.fresnel_evaluations,
            &mut self.wavelength_samples,
            &mut self.splats,
            &mut self.free_flights,
            &mut self.phase_samples,
            &mut self.reemissions,
        ]
    }

    pub fn merge(&mut self, o: &Counters) {
        for (a, b) in self.counts_mut().into_iter().zip(o.counts()) {
            *a += b;
        }
        self.trace_seconds += o.trace_seconds;
    }

    /// `merge` for another run's counters (a state file's): None where a count would wrap.
    fn checked_merge(&self, o: &Counters) -> Option<Counters> {
        let mut sum = *self;
        for (a, b) in sum.counts_mut().into_iter().zip(o.counts()) {
            *a = a.checked_add(b)?;
        }
        sum.trace_seconds += o.trace_seconds;
        Some(sum)
    }
}

impl Tallies {
    /// Empty tallies sized for a scene's surfaces (and media, for absorption), map texels,
    /// far-field bins and spectral bins.
    pub fn for_scene(scene: &crate::scene::Scene) -> Self {
        let mut t = Tallies::new(scene.surfaces.len(), scene.map_texels());
        // Absorbed power has a row per surface, then one per medium.
        t.absorbed = Channel::new(scene.surfaces.len() + scene.media.len());
        t.absorbed_lm = Channel::new(scene.surfaces.len() + scene.media.len());
        t.farfield = Channel::new(scene.farfield_bins());
        t.farfield_lm = Channel::new(scene.farfield_bins());
        t.spectra = Channel::new(scene.spectrum_bins());
        t.spectra_absorbed = Channel::new(scene.spectrum_bins());
        t.reemitted = Channel::new(scene.media.len());
        t.volume_absorbed = Channel::new(scene.volume_voxels());
        t.volume_track = Channel::new(scene.volume_voxels());
        t
    }

    pub fn new(surfaces: usize, texels: usize) -> Self {
        Tallies {
            photons: 0,
            incident: Channel::new(surfaces),
            absorbed: Channel::new(surfaces),
            incident_lm: Channel::new(surfaces),
            absorbed_lm: Channel::new(surfaces),
            texels: Channel::new(texels),
            texels_lm: Channel::new(texels),
            farfield: Channel::new(0),
            farfield_lm: Channel::new(0),
            spectra: Channel::new(0),
            spectra_absorbed: Channel::new(0),
            reemitted: Channel::new(0),
            volume_absorbed: Channel::new(0),
            volume_track: Channel::new(0),
            escaped: 0.0,
            truncated: 0.0,
            scatterings: 0,
            scatterings_sq: 0,
            counters: Counters::default(),
            batches: 0,
            sums: None,
            rays: Vec::new(),
        }
    }

    /// `for_scene`, keeping exact totals: a run's accumulator, whose results do not depend on the
    /// order or grouping in which its batches are merged.
    pub fn for_run(scene: &crate::scene::Scene) -> Self {
        let mut t = Tallies::for_scene(scene);
        t.sums = Some(Box::new(TallySums {
            channels: t.channels().iter().map(|c| ChannelSums::new(c.len())).collect(),
            escaped: ExactSum::default(),
            truncated: ExactSum::default(),
        }));
        t
    }

    /// The channels, in a fixed order (the order of `TallySums::channels` and of state files).
    pub fn channels(&self) -> [&Channel; CHANNELS] {
        [
            &self.incident,
            &self.absorbed,
            &self.incident_lm,
            &self.absorbed_lm,
            &self.texels,
            &self.texels_lm,
            &self.farfield,
            &self.farfield_lm,
            &self.spectra,
            &self.spectra_absorbed,
            &self.reemitted,
            &self.volume_absorbed,
            &self.volume_track,
        ]
    }

    fn channels_mut(&mut self) -> [&mut Channel; CHANNELS] {
        [
            &mut self.incident,
            &mut self.absorbed,
            &mut self.incident_lm,
            &mut self.absorbed_lm,
            &mut self.texels,
            &mut self.texels_lm,
            &mut self.farfield,
            &mut self.farfield_lm,
            &mut self.spectra,
            &mut self.spectra_absorbed,
            &mut self.reemitted,
            &mut self.volume_absorbed,
            &mut self.volume_track,
        ]
    }

    /// Adds a batch. A run's tallies (`for_run`) add it exactly, so the result is the same for any
    /// order; a batch's own f64 tallies are merged in batch-index order, so their sums are the
    /// same for any thread count.
    pub fn merge(&mut self, b: &Tallies) {
        if let Some(mut sums) = self.sums.take() {
            for ((a, x), s) in self.channels_mut().into_iter().zip(b.channels()).zip(&mut sums.channels) {
                s.add_batch(a, x, b.photons);
            }
            sums.escaped.add(b.escaped);
            sums.truncated.add(b.truncated);
            self.escaped = sums.escaped.value();
            self.truncated = sums.truncated.value();
            self.sums = Some(sums);
        } else {
            for (a, x) in self.channels_mut().into_iter().zip(b.channels()) {
                a.merge(x, b.photons);
            }
            self.escaped += b.escaped;
            self.truncated += b.truncated;
        }
        if b.photons > 0 {
            self.batches += 1;
        }
        self.rays.extend_from_slice(&b.rays);
        self.add_counts(b);
    }

    /// Adds another run's tallies (a partial run, another rank's share): both must keep exact
    /// totals (`for_run`) over the same scene; every view is rounded again.
    pub fn merge_run(&mut self, b: &Tallies) -> Result<(), String> {
        let (Some(sums), Some(other)) = (self.sums.as_deref_mut(), b.sums.as_deref()) else {
            return Err("only a run's exact tallies can be merged".into());
        };
        if !b.rays.is_empty() || !self.rays.is_empty() {
            return Err("ray sets are recorded by one whole run and cannot be merged".into());
        }
        if sums.channels.len() != other.channels.len()
            || sums.channels.iter().zip(&other.channels).any(|(a, o)| a.sum.len() != o.sum.len())
        {
            return Err("the tallies are sized for different scenes".into());
        }
        // Only a state that no run wrote makes a count or a sum overflow: refused, not wrapped
        // (a refused merge writes nothing, so what was added before the error does not matter).
        let wrapped = || "its counts overflow when added to the others': no run of photon writes such a state";
        let photons = self.photons.checked_add(b.photons).ok_or_else(wrapped)?;
        let batches = self.batches.checked_add(b.batches).ok_or_else(wrapped)?;
        let scatterings = self.scatterings.checked_add(b.scatterings).ok_or_else(wrapped)?;
        let scatterings_sq = self.scatterings_sq.checked_add(b.scatterings_sq).ok_or_else(wrapped)?;
        let counters = self.counters.checked_merge(&b.counters).ok_or_else(wrapped)?;
        for (a, o) in sums.channels.iter_mut().zip(&other.channels) {
            a.add_sums(o).map_err(|e| e.to_string())?;
        }
        sums.escaped.add_sum(&other.escaped).map_err(|e| e.to_string())?;
        sums.truncated.add_sum(&other.truncated).map_err(|e| e.to_string())?;
        (self.photons, self.batches, self.scatterings, self.scatterings_sq) =
            (photons, batches, scatterings, scatterings_sq);
        self.counters = counters;
        self.round_views();
        Ok(())
    }

    /// Tallies holding exact totals `sums` (channels in `channels` order) and these counts, their
    /// views rounded: a state file's or another rank's tallies.
    pub fn from_sums(sums: TallySums, photons: u64, batches: u64, scatterings: [u64; 2], counters: Counters) -> Self {
        let mut t = Tallies::new(0, 0);
        for (view, s) in t.channels_mut().into_iter().zip(&sums.channels) {
            *view = Channel::new(s.sum.len());
        }
        t.photons = photons;
        t.batches = batches;
        t.scatterings = scatterings[0];
        t.scatterings_sq = scatterings[1];
        t.counters = counters;
        t.sums = Some(Box::new(sums));
        t.round_views();
        t
    }

    /// The exact totals the stopping rules read (incident and absorbed rows, photons, batches),
    /// every other channel empty: what MPI ranks send each round for a collective decision.
    pub fn decision_part(&self) -> Option<Tallies> {
        let sums = self.sums.as_deref()?;
        let channels = sums
            .channels
            .iter()
            .enumerate()
            .map(|(i, c)| if i < 2 { c.clone() } else { ChannelSums::new(0) })
            .collect();
        let part = TallySums { channels, escaped: ExactSum::default(), truncated: ExactSum::default() };
        Some(Tallies::from_sums(part, self.photons, self.batches, [0, 0], Counters::default()))
    }

    /// Rounds every f64 view from the exact totals (after `merge_run`, or a state file's read).
    pub fn round_views(&mut self) {
        if let Some(sums) = self.sums.take() {
            for (view, s) in self.channels_mut().into_iter().zip(&sums.channels) {
                s.round_into(view);
            }
            self.escaped = sums.escaped.value();
            self.truncated = sums.truncated.value();
            self.sums = Some(sums);
        }
    }

    fn add_counts(&mut self, b: &Tallies) {
        self.photons += b.photons;
        self.scatterings += b.scatterings;
        self.scatterings_sq += b.scatterings_sq;
        self.counters.merge(&b.counters);
    }

    /// Power per unit of photon weight: every photon is born with weight 1 and power Φ/N.
    pub fn watts_per_weight(&self, emitted_w: f64) -> f64 {
        if self.photons == 0 {
            0.0
        } else {
            emitted_w / self.photons as f64
        }
    }

    /// (mean, standard error) of a per-history score times `scale`, under `model`. With fewer than
    /// two batches the batch model has no spread to use and falls back to histories (conservative
    /// for stratified sampling).
    pub fn estimate(&self, c: &Channel, surface: usize, scale: f64, model: ErrorModel) -> (f64, f64) {
        let m = &c.moments[surface];
        let (mean, se) = m.estimate(self.photons, scale);
        if model == ErrorModel::Histories || self.batches < 2 {
            return (mean, se);
        }
        // Per-photon variance from batch means m_b = S_b/n_b: Σ n_b (m_b − m)²/(K − 1).
        let (n, k) = (self.photons as f64, self.batches as f64);
        let m_hat = m.sum / n;
        let var = ((c.batch_sq[surface] - n * m_hat * m_hat) / (k - 1.0)).max(0.0) / n;
        (mean, var.sqrt() * scale)
    }

    /// A medium's row (past the surfaces) has no incident power: (0, 0).
    pub fn incident_estimate(&self, surface: usize, scale: f64, model: ErrorModel) -> (f64, f64) {
        if surface >= self.incident.moments.len() {
            return (0.0, 0.0);
        }
        self.estimate(&self.incident, surface, scale, model)
    }

    pub fn absorbed_estimate(&self, surface: usize, scale: f64, model: ErrorModel) -> (f64, f64) {
        self.estimate(&self.absorbed, surface, scale, model)
    }

    /// Mean scatterings per photon and its standard error.
    pub fn mean_scatterings(&self) -> (f64, f64) {
        Moments { sum: self.scatterings as f64, sum_sq: self.scatterings_sq as f64 }.estimate(self.photons, 1.0)
    }

    pub fn ledger(&self, emitted_w: f64) -> Ledger {
        let w = self.watts_per_weight(emitted_w);
        Ledger {
            emitted_w,
            absorbed_w: (self.absorbed.moments.iter().map(|m| m.sum).sum::<f64>() + 0.0) * w,
            escaped_w: self.escaped * w,
            truncated_w: self.truncated * w,
        }
    }

    /// Largest relative standard error over the chosen surfaces' (and media's) non-zero
    /// estimates (incident and absorbed); None when none is non-zero yet.
    pub fn worst_rel_error(&self, surfaces: &[usize], model: ErrorModel) -> Option<f64> {
        let mut worst: Option<f64> = None;
        for &s in surfaces {
            for (mean, se) in [self.incident_estimate(s, 1.0, model), self.absorbed_estimate(s, 1.0, model)] {
                if mean > 0.0 {
                    worst = Some(worst.map_or(se / mean, |w: f64| w.max(se / mean)));
                }
            }
        }
        worst
    }
}

#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct Ledger {
    pub emitted_w: f64,
    pub absorbed_w: f64,
    pub escaped_w: f64,
    pub truncated_w: f64,
}

impl Ledger {
    /// |emitted − (absorbed + escaped + truncated)| / emitted.
    pub fn relative_residual(&self) -> f64 {
        ((self.emitted_w - (self.absorbed_w + self.escaped_w + self.truncated_w)) / self.emitted_w).abs()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn history_scores_square_whole_histories() {
        let mut m = vec![Moments::default(); 2];
        let mut h = HistoryScores::new(2);
        h.add(0, 1.0);
        h.add(0, 1.0);
        h.flush(&mut m);
        h.add(1, 1.0);
        h.flush(&mut m);
        assert_eq!(m[0], Moments { sum: 2.0, sum_sq: 4.0 });
        assert_eq!(m[1], Moments { sum: 1.0, sum_sq: 1.0 });
    }

    #[test]
    fn dense_and_listed_history_scores_give_the_same_bits() {
        // The same histories into DENSE_ROWS rows (folded whole) and into one row more (touched
        // rows listed), with repeats, cancelling scores and histories that touch nothing.
        let rows = DENSE_ROWS;
        let (mut dense, mut listed) = (HistoryScores::new(rows), HistoryScores::new(rows + 1));
        assert!(dense.dense && !listed.dense);
        let (mut md, mut ml) = (vec![Moments::default(); rows], vec![Moments::default(); rows + 1]);
        let (mut ld, mut ll) = (md.clone(), ml.clone());
        let mut s = crate::sampling::Sampler::for_batch(7, 0);
        for _ in 0..2000 {
            for _ in 0..(s.uniform() * 6.0) as usize {
                let row = (s.uniform() * rows as f64) as u32;
                let x = if s.uniform() < 0.1 { -dense.value(row) } else { s.uniform() };
                dense.add(row, x);
                listed.add(row, x);
            }
            dense.flush_scaled(&mut md, Some((&mut ld, 683.0)));
            listed.flush_scaled(&mut ml, Some((&mut ll, 683.0)));
        }
        for r in 0..rows {
            for (a, b) in [(md[r], ml[r]), (ld[r], ll[r])] {
                assert_eq!((a.sum.to_bits(), a.sum_sq.to_bits()), (b.sum.to_bits(), b.sum_sq.to_bits()), "row {r}");
            }
        }
        assert!(md.iter().all(|m| m.sum > 0.0));
    }

    #[test]
    fn standard_error_of_bernoulli_scores() {
        // Scores 1 with probability 1/4 over N = 4: mean 1/4, sample variance (1/4 − 1/16)/(N−1).
        let m = Moments { sum: 1.0, sum_sq: 1.0 };
        let (mean, se) = m.estimate(4, 1.0);
        assert_eq!(mean, 0.25);
        assert!((se - ((0.25f64 - 0.0625) / 3.0).sqrt()).abs() < 1e-15);
    }
}
