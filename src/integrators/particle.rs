//! The photon loop: first hit → tally the arrival → absorb or scatter → next ray, until the
//! photon is absorbed, escapes, or reaches the bounce cap. Monomorphised over the effects and
//! estimator a run calls for, so a grey scene never draws a wavelength, a run without a film
//! never splats, and neither pays a branch per photon for the other's work.

use std::sync::atomic::AtomicBool;

use glam::{DVec3, Vec3A};

use crate::bsdf::{Bsdf, Mode, Prepared};
use crate::detectors::film::{CameraModel, FilmBatch};
use crate::detectors::tally::{HistoryScores, RayArrival, Tallies};
use crate::geometry::{Geometry, RayEnd, NO_PRIM};
use crate::integrators::clear_view::{ClearView, Sight};
use crate::integrators::emitter_view::EmitterView;
use crate::integrators::passage::{self, is_passable, Through};
use crate::lights::{Birth, EmitSample, Emitter, EMIT_DIMS};
use crate::media;
use crate::sampling::Sampler;
use crate::scene::map::SurfaceMap;
use crate::scene::plane::WorkPlane;
use crate::scene::{Material, Scene};
use crate::spectrum::{map_array, photometry};

/// How absorption is estimated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    // The doc comments are the command line's help: they speak to users.
    /// A short pilot of each picks the one that reaches a given accuracy sooner in this scene
    #[default]
    Auto,
    /// A photon survives each hit with probability equal to the albedo
    Analog,
    /// At each hit the absorbed share of the weight is tallied and the rest carried on
    /// (Russian roulette below weight 0.1)
    // Below `ROULETTE_WEIGHT` the photon survives with the albedo as probability, so the lost
    // weight is booked as absorbed where it dies and the ledger stays exact.
    Expected,
}

/// Weight below which the expected-value estimator switches to roulette.
pub const ROULETTE_WEIGHT: f64 = 0.1;

/// Options of the transport itself (the defaults were chosen by measurement; see the README).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TransportOptions {
    pub estimator: Estimator,
    /// Latin-hypercube stratification of each batch's emission samples.
    pub stratified: bool,
    /// Hero-wavelength spectral sampling for the image (spectral scenes without dispersion).
    pub hero: bool,
}

impl TransportOptions {
    /// Stratified batches correlate their histories: errors must come from the batches' spread.
    pub fn error_model(&self) -> crate::detectors::tally::ErrorModel {
        if self.stratified {
            crate::detectors::tally::ErrorModel::Batches
        } else {
            crate::detectors::tally::ErrorModel::Histories
        }
    }
}

impl Default for TransportOptions {
    fn default() -> Self {
        TransportOptions { estimator: Estimator::Auto, stratified: false, hero: true }
    }
}

/// What a batch needs besides the scene: the emitter, the camera when the light tracer makes
/// the image, the camera integrator when one does, and options.
pub struct Kernel<'a> {
    pub scene: &'a Scene,
    pub emitter: &'a Emitter,
    pub camera: Option<&'a CameraModel>,
    pub image: Option<&'a crate::integrators::camera::ImageKernel<'a>>,
    pub options: TransportOptions,
    /// Set when the run has stopped: a batch in hand then ends early, and is discarded.
    pub cancel: Option<&'a AtomicBool>,
    /// Per surface, its material's run-wide constants (`Prepared::for_scene`).
    pub prepared: &'a [Prepared],
    /// The emitters the light tracer images from the camera (`EmitterView`), if any: their
    /// emission splats are skipped.
    pub view: Option<&'a EmitterView>,
    /// Which surface points in view the camera sees unblocked, so their splats need no shadow
    /// ray (`ClearView`), if built.
    pub clear: Option<&'a ClearView>,
    /// Whether batches also trace the view's camera samples (the estimator pilot leaves them
    /// out: they are the same under either estimator, and in the film's absolute units).
    pub view_samples: bool,
}

/// Under this seed, test builds panic in batch 3 (to test that a failed batch fails the run).
#[cfg(test)]
pub const PANIC_TEST_SEED: u64 = 0xDEAD_BEEF;

impl Kernel<'_> {
    /// Whether hero wavelengths are used: spectral transport with a film, no dispersion, no
    /// scattering medium (whose free flights follow the hero's own μt: each photon keeps one
    /// wavelength there), no fluorescence (which changes it) and no absorbing medium behind an
    /// index-matched boundary (which splats look through at the photon's wavelength).
    pub fn uses_hero(&self) -> bool {
        let fx = &self.scene.effects;
        let absorber_seen_through = fx.absorbing_media
            && self.scene.surfaces.iter().any(|s| is_passable(&self.scene.materials[s.material].material));
        self.options.hero
            && fx.spectral
            && !fx.dispersion
            && !fx.volume_scattering
            && !fx.fluorescence
            && !absorber_seen_through
            && self.camera.is_some()
            // Shading normals reweight each event apart from the lanes' terms.
            && !self.scene.geometry.has_shading_normals()
            // A ray set ties each direction to its own wavelength: no lane may borrow its path.
            && !self.scene.lights.iter().any(|l| matches!(l.shape, crate::scene::LightShape::Rays { .. }))
    }

    /// Traces one batch, dispatching once to the kernel specialised for the run.
    pub fn trace_batch(&self, batch: u64, count: u64) -> (Tallies, Option<FilmBatch>) {
        #[cfg(test)]
        if self.scene.simulation.seed == PANIC_TEST_SEED && batch == 3 {
            panic!("a test's deliberate panic");
        }
        let start = std::time::Instant::now();
        let mut film = self.camera.map(|_| FilmBatch::for_photons(count));
        let fx = &self.scene.effects;
        let flags = Flags {
            spectral: fx.spectral,
            camera: self.camera.is_some(),
            expected: match self.options.estimator {
                Estimator::Expected => true,
                Estimator::Analog => false,
                Estimator::Auto => unreachable!("`auto` is resolved before the run's first batch"),
            },
            hero: self.uses_hero(),
            dielectric: fx.refraction,
        };
        let mut tallies = self.dispatch_spectral(flags, batch, count, film.as_mut());
        if let Some(f) = &film {
            tallies.counters.shadow_rays = f.shadow_rays;
            tallies.counters.splats = f.splats.len() as u64;
        }
        if let (true, Some(view), Some(cam), Some(f)) = (self.view_samples, self.view, self.camera, film.as_mut()) {
            view.trace_batch(self.scene, self.emitter, cam, batch, count, f, &mut tallies.counters, self.cancel);
        }
        if let Some(image) = self.image {
            // The camera samples share the batch's indices, so a stop at a batch boundary stops both.
            film = Some(image.trace_batch(batch, count, &mut tallies.counters, self.cancel));
        }
        // Reduced here, on the worker, not on the thread that merges the batches in order.
        if let Some(f) = film.as_mut() {
            f.digest(count);
        }
        tallies.counters.trace_seconds = start.elapsed().as_secs_f64();
        (tallies, film)
    }

    // One runtime flag at a time becomes a const parameter, so `trace` is compiled once per effect
    // set and chosen once per batch: no per-photon branch on what the scene lacks.
    fn dispatch_spectral(&self, f: Flags, batch: u64, count: u64, film: Option<&mut FilmBatch>) -> Tallies {
        if f.spectral {
            self.dispatch_camera::<true>(f, batch, count, film)
        } else {
            self.dispatch_camera::<false>(f, batch, count, film)
        }
    }

    fn dispatch_camera<const S: bool>(
        &self,
        f: Flags,
        batch: u64,
        count: u64,
        film: Option<&mut FilmBatch>,
    ) -> Tallies {
        if f.camera {
            self.dispatch_estimator::<S, true>(f, batch, count, film)
        } else {
            self.dispatch_estimator::<S, false>(f, batch, count, film)
        }
    }

    fn dispatch_estimator<const S: bool, const C: bool>(
        &self,
        f: Flags,
        batch: u64,
        count: u64,
        film: Option<&mut FilmBatch>,
    ) -> Tallies {
        if f.expected {
            self.dispatch_hero::<S, C, true>(f, batch, count, film)
        } else {
            self.dispatch_hero::<S, C, false>(f, batch, count, film)
        }
    }

    fn dispatch_hero<const S: bool, const C: bool, const E: bool>(
        &self,
        f: Flags,
        batch: u64,
        count: u64,
        film: Option<&mut FilmBatch>,
    ) -> Tallies {
        // Hero wavelengths need spectral transport and a film.
        if S && C && f.hero {
            self.dispatch_dielectric::<S, C, E, true>(f, batch, count, film)
        } else {
            self.dispatch_dielectric::<S, C, E, false>(f, batch, count, film)
        }
    }

    fn dispatch_dielectric<const S: bool, const C: bool, const E: bool, const H: bool>(
        &self,
        f: Flags,
        batch: u64,
        count: u64,
        film: Option<&mut FilmBatch>,
    ) -> Tallies {
        if f.dielectric {
            self.trace::<S, C, E, H, true>(batch, count, film)
        } else {
            self.trace::<S, C, E, H, false>(batch, count, film)
        }
    }

    /// Traces the photons of one batch with the batch's own random stream. Buffers are allocated
    /// once per batch; nothing inside the photon loop allocates.
    fn trace<
        const SPECTRAL: bool,
        const CAMERA: bool,
        const EXPECTED: bool,
        const HERO: bool,
        const DIELECTRIC: bool,
    >(
        &self,
        batch: u64,
        count: u64,
        mut film: Option<&mut FilmBatch>,
    ) -> Tallies {
        let scene = self.scene;
        let geo = &scene.geometry;
        let n_surfaces = scene.surfaces.len();
        let max_bounces = scene.simulation.max_bounces;
        let range = scene.simulation.wavelength_range_nm;
        let materials: Vec<&Material> = (0..n_surfaces).map(|s| scene.material_of(s)).collect();
        let prepared = self.prepared;
        let mut s = Sampler::for_batch(scene.simulation.seed, batch);
        let strata = self.options.stratified.then(|| latin_hypercube(count as usize, &mut s));
        let mut out = Tallies::for_scene(scene);
        // Re-emission changes a photon's wavelength and with it the luminous efficacy of what it
        // scores later: with fluorescence the lumens are kept score by score.
        let fluorescent = SPECTRAL && scene.effects.fluorescence;
        let scores = |n: usize| if fluorescent { HistoryScores::with_luminous(n) } else { HistoryScores::new(n) };
        let mut incident = scores(n_surfaces);
        // A row per surface, then one per medium (`[media]`).
        let mut absorbed = scores(n_surfaces + scene.media.len());
        let mut reemitted = HistoryScores::new(if fluorescent { scene.media.len() } else { 0 });
        let surface_medium = &scene.surface_medium;
        // Irradiance maps: one branch per arrival, not taken in scenes without maps.
        let maps: Vec<Option<&SurfaceMap>> = scene.surfaces.iter().map(|s| s.map.as_ref()).collect();
        let has_maps = maps.iter().any(|m| m.is_some());
        // Work planes: every straight stretch of a path is tested against them.
        let planes = &scene.planes;
        let has_planes = !planes.is_empty();
        let has_texels = has_maps || has_planes;
        // Ray-set detectors: each arrival on their surfaces is kept (a push per arrival, off
        // unless asked for).
        let has_rays = !scene.ray_detectors.is_empty();
        let smooth = geo.has_shading_normals();
        let mut texels = scores(if has_texels { scene.map_texels() } else { 0 });
        // Far-field detectors and surface spectra, likewise off unless asked for.
        let detectors = &scene.detectors;
        let mut farfield = scores(scene.farfield_bins());
        let spectrum_bins: Vec<Option<(usize, usize)>> = scene.surfaces.iter().map(|s| s.spectrum_bins).collect();
        let has_spectra = spectrum_bins.iter().any(|b| b.is_some());
        let mut spectra = HistoryScores::new(scene.spectrum_bins());
        let mut spectra_absorbed = HistoryScores::new(scene.spectrum_bins());
        // Absorbed weight to its surface (or medium row), and to the surface's wavelength bin
        // when it has one.
        let absorb =
            |surface: u32, x: f64, lambda: f64, absorbed: &mut HistoryScores, spectra_absorbed: &mut HistoryScores| {
                absorbed.add(surface, x);
                if SPECTRAL && has_spectra {
                    if let Some(&Some((bins, first))) = spectrum_bins.get(surface as usize) {
                        let k = (((lambda - range.0) / (range.1 - range.0) * bins as f64) as usize).min(bins - 1);
                        spectra_absorbed.add((first + k) as u32, x);
                    }
                }
            };
        let (range_lo, range_width) = (range.0, range.1 - range.0);
        // Index-matched smooth dielectric boundaries, which a connection to the camera passes
        // (nothing reflects or bends there), and the extinction per metre inside a dielectric.
        let passable: Vec<bool> = materials.iter().map(|m| is_passable(m)).collect();
        // With such boundaries in the scene, splats look through them (`splat_through`).
        let see_through = DIELECTRIC && passable.iter().any(|&p| p);
        let boundaries =
            Through { passable: &passable, inside: &scene.surface_inside, outside: &scene.surface_outside };
        let through = see_through.then_some(boundaries);
        let mu_t_at = |m: Option<u32>, lambda: f64| -> f64 {
            let Some(m) = m else { return 0.0 };
            match surface_medium[m as usize] {
                Some(v) => {
                    let med = &scene.media[v as usize];
                    let dye = med.fluorescence.as_ref().map_or(0.0, |f| f.absorption_per_m.eval(lambda));
                    med.absorption_per_m.eval(lambda) + med.scattering_per_m.eval(lambda) + dye
                }
                None => media::absorption(materials[m as usize]).map_or(0.0, |a| a.eval(lambda)),
            }
        };
        // Volume detectors: track lengths and deposits per voxel, off unless asked for.
        let volumes = &scene.volumes;
        let has_volumes = !volumes.is_empty();
        let mut volume_track = HistoryScores::new(scene.volume_voxels());
        let mut volume_absorbed = HistoryScores::new(scene.volume_voxels());

        for photon in 0..count as u32 {
            if crate::integrators::batch::cancelled(self.cancel, photon as u64) {
                out.photons = photon as u64;
                return out;
            }
            let u: EmitSample = match &strata {
                Some(table) => table[photon as usize],
                None => std::array::from_fn(|_| s.uniform()),
            };
            let birth = self.emitter.emit::<SPECTRAL>(geo, &u);
            // The photon's wavelength and colour weights (changed only by re-emission).
            let mut lambda = birth.lambda_nm;
            let mut xyz = birth.xyz;
            // Luminous efficacy of the history: K_m ȳ(λ) at its wavelength, or its light's
            // spectrum-averaged efficacy in grey transport (see `photometry`).
            let lm_per_w = if SPECTRAL { photometry::efficacy_at(lambda) } else { scene.lights[birth.light].lm_per_w };
            if fluorescent {
                for h in [&mut incident, &mut absorbed, &mut texels, &mut farfield] {
                    h.set_efficacy(lm_per_w);
                }
            }
            // Counted from what emission returned (grey births carry NaN), not from the flag.
            out.counters.wavelength_samples += lambda.is_finite() as u64;
            let mut hero = if HERO { Hero::new(self.emitter, &birth, range) } else { Hero::default() };
            let mut weight = 1.0f64;
            if let (true, Some(film)) = (CAMERA, film.as_deref_mut()) {
                film.photon = photon;
            }
            // The emission splat, unless the camera images this light itself (`EmitterView`).
            let splat_birth = CAMERA && !self.view.is_some_and(|v| v.from_camera(birth.light));
            if let (true, Some(cam), Some(film)) = (splat_birth, self.camera, film.as_deref_mut()) {
                let colour = if HERO { hero.emission_xyz() } else { birth.xyz };
                let value = |w| colour * self.emitter.direction_pdf(birth.light, birth.axis, w);
                let start = RayEnd { p: birth.point, err: birth.point_err, n: birth.normal, prim: birth.prim };
                let m = || self.emitter.medium_at(birth.light, birth.prim);
                splat_seen(cam, self.clear, geo, film, start, through, m, |m| mu_t_at(m, lambda), value);
            }
            let mut origin = birth.origin;
            // How far the ray's origin lies ahead of the surface point it left, along the ray:
            // a spawned origin is offset off the surface by its error bound, and inside a medium
            // that stretch is medium too (at 50 m from the scene's centre it is 20 µm, a fifth of
            // a tissue mean free path). Zero from a free point (emission, a volume collision).
            let mut head_start = 0.0f64;
            // μs, μa and the luminophore's μf of the medium the photon is in, at its wavelength:
            // looked up when it enters a medium or changes wavelength, not at every collision.
            let mut coefficients: Option<(u32, f64, f64, f64)> = None;
            let mut dir = birth.dir;
            let mut skip = birth.prim;
            let mut scatterings = 0u32;
            // Index-matched boundaries passed since the last scattering.
            let mut crossings = 0;
            // A light inside glass or water emits into it.
            let mut medium: Option<u32> =
                if DIELECTRIC { self.emitter.medium_at(birth.light, birth.prim) } else { None };
            loop {
                out.counters.rays += 1;
                let next = geo.intersect_leaving(origin, dir, f32::INFINITY, skip);
                // The medium is the dielectric the photon last refracted into, or the one its light
                // sits in (`Emitter::medium_at`); without dielectrics none of this is compiled in.
                // A `[media]` medium that scatters: a free flight t ~ μt e^{−μt t}; a collision
                // before the next surface absorbs the share μa/μt there (expected value; analog:
                // survives with the albedo μs/μt) and scatters by the phase function. Between
                // collisions nothing is lost, so reaching the surface costs nothing more.
                let volume = if DIELECTRIC { medium.and_then(|m| surface_medium[m as usize]) } else { None };
                let mut absorbing = None;
                if let Some(v) = volume {
                    let med = &scene.media[v as usize];
                    let (mu_s, mu_a, mu_f) = match coefficients {
                        Some((w, mu_s, mu_a, mu_f)) if w == v => (mu_s, mu_a, mu_f),
                        _ => {
                            let mu_f = match &med.fluorescence {
                                Some(f) if fluorescent => f.absorption_per_m.eval(lambda),
                                _ => 0.0,
                            };
                            let (mu_s, mu_a) = (med.scattering_per_m.eval(lambda), med.absorption_per_m.eval(lambda));
                            coefficients = Some((v, mu_s, mu_a, mu_f));
                            (mu_s, mu_a, mu_f)
                        }
                    };
                    if mu_s > 0.0 || mu_f > 0.0 {
                        out.counters.free_flights += 1;
                        let mu_t = mu_a + mu_s + mu_f;
                        let t = media::free_flight(mu_t, s.uniform());
                        // A collision needs the boundary ahead (with none, the photon has left).
                        if let Some(h) = next.filter(|h| t < h.t as f64 + head_start) {
                            let row = (n_surfaces + v as usize) as u32;
                            let (seg_origin, seg_dir, seg_start) = (origin, dir, head_start);
                            // Within the head start the collision is at the origin (a shift of at
                            // most the error bound), which is safely inside.
                            let at = if t >= head_start {
                                collision_point(geo, &h, dir, h.t as f64 + head_start - t)
                            } else {
                                origin
                            };
                            let (w_in, before) = (weight, absorbed.value(row));
                            let alive = 'collision: {
                                // The medium's own absorption first; what survives is scattered or
                                // taken by the luminophore.
                                let albedo = (mu_s + mu_f) / mu_t;
                                let expected_here = EXPECTED && weight >= ROULETTE_WEIGHT;
                                if expected_here {
                                    absorb(row, weight * (1.0 - albedo), lambda, &mut absorbed, &mut spectra_absorbed);
                                    weight *= albedo;
                                } else if !(s.uniform() < albedo) {
                                    absorb(row, weight, lambda, &mut absorbed, &mut spectra_absorbed);
                                    break 'collision false;
                                }
                                if scatterings == max_bounces {
                                    out.truncated += weight;
                                    break 'collision false;
                                }
                                scatterings += 1;
                                crossings = 0;
                                origin = at;
                                head_start = 0.0;
                                skip = NO_PRIM;
                                let luminophore = match &med.fluorescence {
                                    Some(f)
                                        if mu_f > 0.0
                                            && media::fluorescence::luminophore_absorbs(mu_s, mu_f, s.uniform()) =>
                                    {
                                        f
                                    }
                                    _ => {
                                        if let (true, Some(cam), Some(film)) =
                                            (CAMERA, self.camera, film.as_deref_mut())
                                        {
                                            // Next event to the camera: p(cos) toward it, through the media.
                                            let value = |w: Vec3A| {
                                                xyz * (weight * media::phase::pdf(med.phase, dir.dot(w) as f64)) as f32
                                            };
                                            splat_through(
                                                cam,
                                                geo,
                                                film,
                                                RayEnd::free(at),
                                                medium,
                                                |m| mu_t_at(m, lambda),
                                                &boundaries,
                                                value,
                                            );
                                        }
                                        out.counters.phase_samples += 1;
                                        dir = media::phase::sample(med.phase, dir, s.uniform(), s.uniform());
                                        break 'collision true;
                                    }
                                };
                                // Absorbed by the luminophore: re-emitted with probability q (expected
                                // value: the share 1 − q stays in the medium).
                                let q = luminophore.quantum_yield;
                                if expected_here {
                                    absorb(row, weight * (1.0 - q), lambda, &mut absorbed, &mut spectra_absorbed);
                                    weight *= q;
                                    if weight == 0.0 {
                                        break 'collision false;
                                    }
                                } else if !(s.uniform() < q) {
                                    absorb(row, weight, lambda, &mut absorbed, &mut spectra_absorbed);
                                    break 'collision false;
                                }
                                let (new_lambda, new_dir, energy) = media::fluorescence::reemit(
                                    luminophore,
                                    lambda,
                                    s.uniform(),
                                    s.uniform(),
                                    s.uniform(),
                                );
                                // The Stokes loss (1 − λ/λ') of the weight is heat in the medium.
                                absorb(row, weight * (1.0 - energy), lambda, &mut absorbed, &mut spectra_absorbed);
                                weight *= energy;
                                reemitted.add(v, weight);
                                out.counters.reemissions += 1;
                                lambda = new_lambda;
                                xyz = self.emitter.colour(lambda);
                                for h in [&mut incident, &mut absorbed, &mut texels, &mut farfield] {
                                    h.set_efficacy(photometry::efficacy_at(lambda));
                                }
                                coefficients = None;
                                if let (true, Some(cam), Some(film)) = (CAMERA, self.camera, film.as_deref_mut()) {
                                    // Re-emitted isotropically: 1/(4π) toward the camera, at λ'.
                                    let value = |_: Vec3A| xyz * (weight / (4.0 * std::f64::consts::PI)) as f32;
                                    splat_through(
                                        cam,
                                        geo,
                                        film,
                                        RayEnd::free(at),
                                        medium,
                                        |m| mu_t_at(m, lambda),
                                        &boundaries,
                                        value,
                                    );
                                }
                                dir = new_dir;
                                break 'collision true;
                            };
                            if has_planes {
                                let flight = (t - seg_start).max(0.0);
                                let (o, d) = (seg_origin.as_dvec3(), seg_dir.as_dvec3());
                                cross_planes(planes, o, d, flight, w_in, 0.0, &mut texels);
                            }
                            if has_volumes {
                                // The free flight's track, and what this collision deposited.
                                let p = at.as_dvec3();
                                let flight = (t - seg_start).max(0.0);
                                let (o, d) = (seg_origin.as_dvec3(), seg_dir.as_dvec3());
                                track(volumes, o, d, flight, w_in, 0.0, &mut volume_track, &mut volume_absorbed);
                                if let Some(vx) = volumes.iter().find_map(|g| g.voxel_of(p)) {
                                    volume_absorbed.add(vx as u32, absorbed.value(row) - before);
                                }
                            }
                            if alive {
                                continue;
                            }
                            break;
                        }
                    } else if mu_a > 0.0 {
                        absorbing = Some((&med.absorption_per_m, (n_surfaces + v as usize) as u32));
                    }
                }
                let Some(hit) = next else {
                    if has_volumes {
                        let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
                        track(volumes, o, d, f64::INFINITY, weight, 0.0, &mut volume_track, &mut volume_absorbed);
                    }
                    if has_planes {
                        let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
                        cross_planes(planes, o, d, f64::INFINITY, weight, 0.0, &mut texels);
                    }
                    out.escaped += weight;
                    for d in detectors {
                        farfield.add(d.bin_of(dir) as u32, weight);
                    }
                    break;
                };
                let prim = hit.prim as usize;
                let surface = geo.surface_of(prim);
                let material = materials[surface as usize];
                let n = geo.normal(prim);
                // Without dielectrics in the scene, no refraction, Fresnel or media code is compiled in.
                let is_dielectric = DIELECTRIC && matches!(material, Material::Dielectric { .. });

                // Beer–Lambert: crossing an absorbing medium over distance t, a photon keeps the
                // fraction exp(−α t) (analog: survives with that probability); the rest is
                // absorbed by the medium: tallied to its `[media]` row, or for a dielectric's own
                // `absorption_per_m` to its surface.
                if volume.is_none() {
                    absorbing = medium.and_then(|m| media::absorption(materials[m as usize]).map(|a| (a, m)));
                }
                if has_volumes || has_planes {
                    // The segment to the surface; across an absorbing medium its weight decays as
                    // w·e^{−α s} from the surface it left (the head start already behind it): the
                    // expected weight at each point, whichever estimator decides below.
                    let alpha = absorbing.map_or(0.0, |(a, _)| a.eval(lambda));
                    let w0 = if alpha > 0.0 { weight * (-alpha * head_start).exp() } else { weight };
                    let (o, d) = (origin.as_dvec3(), dir.as_dvec3());
                    if has_volumes {
                        track(volumes, o, d, hit.t as f64, w0, alpha, &mut volume_track, &mut volume_absorbed);
                    }
                    if has_planes {
                        cross_planes(planes, o, d, hit.t as f64, w0, alpha, &mut texels);
                    }
                }
                if let Some((alpha, row)) = absorbing {
                    let t = hit.t as f64 + head_start;
                    let keep = media::transmittance::<SPECTRAL, 1>(alpha, &[lambda], t).0[0];
                    if EXPECTED && weight >= ROULETTE_WEIGHT {
                        absorb(row, weight * (1.0 - keep), lambda, &mut absorbed, &mut spectra_absorbed);
                        weight *= keep;
                        if weight == 0.0 {
                            // exp(−αt) underflowed: the medium took everything.
                            break;
                        }
                    } else if s.uniform() >= keep {
                        absorb(row, weight, lambda, &mut absorbed, &mut spectra_absorbed);
                        break;
                    }
                    if HERO {
                        let k = media::transmittance::<true, 4>(alpha, &hero.lambda, t);
                        hero.event::<EXPECTED>(|i| (k.0[i], k.0[i], k.0[i]));
                    }
                }

                incident.add(surface, weight);
                let (p, err) = geo.hit_point(&hit);
                if has_rays {
                    if let Some(detector) = scene.surface_rays[surface as usize] {
                        let q = p.as_dvec3();
                        out.rays.push(RayArrival {
                            detector,
                            position: [q.x, q.y, q.z],
                            direction: dir.to_array(),
                            lambda_nm: lambda,
                            weight,
                        });
                    }
                }
                if has_maps {
                    if let Some(map) = maps[surface as usize] {
                        texels.add(map.texel_of(p, hit.b, geo.local[hit.prim as usize]) as u32, weight);
                    }
                }
                if SPECTRAL && has_spectra {
                    if let Some((bins, first)) = spectrum_bins[surface as usize] {
                        let k = (((lambda - range_lo) / range_width * bins as f64) as usize).min(bins - 1);
                        spectra.add((first + k) as u32, weight);
                    }
                }
                // The material at the photon's wavelength, and at the hero lanes for the image; read
                // once here for both the camera splat and the scattering event.
                let wo = -dir;
                let prep = &prepared[surface as usize];
                // The tangent is read only for an anisotropic material (from the line `n` came from).
                let tangent = || geo.tangent(prim);
                // Smooth shading: the model's frame on the interpolated normal, sides on `n`.
                let ns = if smooth { geo.shading_normal(prim, hit.b) } else { n };
                let bsdf = Bsdf::<1>::new::<SPECTRAL>(material, prep, &[lambda], ns, tangent);
                // Flat triangles (ns = n) skip the normals' comparison.
                let bsdf = if smooth { bsdf.shaded(n) } else { bsdf };
                let hero_bsdf = HERO.then(|| Bsdf::<4>::new::<true>(material, prep, &hero.lambda, ns, tangent));
                if let (true, Some(cam), Some(film)) = (CAMERA, self.camera, film.as_deref_mut()) {
                    if bsdf.is_connectible() {
                        // f(wo, ω)·|cosθ_ω| toward the camera: the lanes' part in f64, the angular in f32.
                        let value = |w: Vec3A| {
                            let geometric = w.dot(n).abs();
                            match &hero_bsdf {
                                Some(hb) => {
                                    let f = hb.f(wo, w, Mode::Importance);
                                    hero.splat_xyz(f.spectral.0) * (geometric * f.angular as f32)
                                }
                                None => {
                                    let f = bsdf.f(wo, w, Mode::Importance);
                                    xyz * (weight * f.spectral.0[0]) as f32 * (geometric * f.angular as f32)
                                }
                            }
                        };
                        let start = RayEnd { p, err, n, prim: hit.prim };
                        // Toward the camera the photon is in its medium, or beyond the (rough)
                        // dielectric it is on.
                        let m = || {
                            let to_camera = cam.project(p).map_or(Vec3A::ZERO, |proj| proj.to_camera);
                            if is_dielectric {
                                media::after_crossing(
                                    surface,
                                    n,
                                    to_camera,
                                    &scene.surface_inside,
                                    &scene.surface_outside,
                                )
                            } else {
                                medium
                            }
                        };
                        splat_seen(cam, self.clear, geo, film, start, through, m, |m| mu_t_at(m, lambda), value);
                    }
                }

                // Absorb or carry on. One estimator decision serves both absorptions of this hit.
                let a = bsdf.albedo(wo).0[0];
                let expected_here = EXPECTED && weight >= ROULETTE_WEIGHT;
                if expected_here {
                    if a < 1.0 {
                        absorb(surface, weight * (1.0 - a), lambda, &mut absorbed, &mut spectra_absorbed);
                    }
                    if a <= 0.0 {
                        break;
                    }
                    weight *= a;
                } else if !(s.uniform() < a) {
                    absorb(surface, weight, lambda, &mut absorbed, &mut spectra_absorbed);
                    break;
                }
                out.counters.fresnel_evaluations += is_dielectric as u64;
                let Some(sampled) = bsdf.sample(wo, Mode::Importance, &mut s) else {
                    // A zero density, or a microfacet reflection that left below the surface.
                    absorb(surface, weight, lambda, &mut absorbed, &mut spectra_absorbed);
                    break;
                };
                if !bsdf.samples_exactly() {
                    // What the albedo did not account for, t = (f|cos|/pdf)/albedo, is a second
                    // absorption: the share 1 − t stays here (expected value), or the photon survives
                    // with probability t. t ≤ 1 for rough metals, glass and smooth plastic by their
                    // sampling; a rough plastic's coat lobe can exceed 1, and the weight then grows,
                    // booked as negative absorption, so the ledger stays exact.
                    let t = sampled.weight().0[0] / a;
                    if expected_here || t >= 1.0 {
                        absorb(surface, weight * (1.0 - t), lambda, &mut absorbed, &mut spectra_absorbed);
                        weight *= t;
                        if !(weight > 0.0) {
                            break;
                        }
                    } else if !(s.uniform() < t) {
                        absorb(surface, weight, lambda, &mut absorbed, &mut spectra_absorbed);
                        break;
                    }
                }
                let new_dir = sampled.wi;
                if let Some(hb) = &hero_bsdf {
                    let e = hb.event_terms(sampled.lobe, wo, new_dir, Mode::Importance);
                    hero.event::<EXPECTED>(|k| (e.factor.0[k], e.albedo.0[k], e.analog.0[k]));
                }
                if DIELECTRIC && passable[surface as usize] {
                    // Through an index-matched boundary: no scattering event (`passage`).
                    crossings += 1;
                    if crossings > passage::MAX_CROSSINGS {
                        out.truncated += weight;
                        break;
                    }
                } else {
                    if scatterings == max_bounces {
                        out.truncated += weight;
                        break;
                    }
                    scatterings += 1;
                    crossings = 0;
                }
                if is_dielectric {
                    medium = media::after_crossing(
                        surface,
                        n,
                        new_dir,
                        &self.scene.surface_inside,
                        &self.scene.surface_outside,
                    );
                }
                origin = geo.spawn_from(p, err, hit.prim, hit.b, new_dir);
                if DIELECTRIC {
                    // Along new_dir from the surface's plane to the spawned origin.
                    let along = new_dir.dot(n);
                    head_start =
                        if medium.is_some() && along != 0.0 { ((origin - p).dot(n) / along) as f64 } else { 0.0 };
                }
                dir = new_dir;
                skip = hit.prim;
            }
            out.scatterings += scatterings as u64;
            out.scatterings_sq += (scatterings as u64).pow(2);
            incident.flush_scaled(&mut out.incident.moments, Some((&mut out.incident_lm.moments, lm_per_w)));
            absorbed.flush_scaled(&mut out.absorbed.moments, Some((&mut out.absorbed_lm.moments, lm_per_w)));
            if has_texels {
                texels.flush_scaled(&mut out.texels.moments, Some((&mut out.texels_lm.moments, lm_per_w)));
            }
            if !detectors.is_empty() {
                farfield.flush_scaled(&mut out.farfield.moments, Some((&mut out.farfield_lm.moments, lm_per_w)));
            }
            if SPECTRAL && has_spectra {
                spectra.flush(&mut out.spectra.moments);
                spectra_absorbed.flush(&mut out.spectra_absorbed.moments);
            }
            if fluorescent {
                reemitted.flush(&mut out.reemitted.moments);
            }
            if has_volumes {
                volume_track.flush(&mut out.volume_track.moments);
                volume_absorbed.flush(&mut out.volume_absorbed.moments);
            }
        }
        out.photons = count;
        out
    }
}

/// The work planes that the stretch o + s·ω, s ≤ s_max, crosses toward their front: the weight
/// there (w·e^{−α s} across an absorbing medium) goes to the texel and to the plane's whole.
#[inline]
fn cross_planes(
    planes: &[WorkPlane],
    o: DVec3,
    w: DVec3,
    s_max: f64,
    weight: f64,
    alpha: f64,
    texels: &mut HistoryScores,
) {
    for plane in planes {
        if let Some((slot, s)) = plane.crossing(o, w, s_max) {
            let x = if alpha > 0.0 { weight * (-alpha * s).exp() } else { weight };
            texels.add(slot as u32, x);
            texels.add(plane.total_slot() as u32, x);
        }
    }
}

/// The effect set and estimator a batch is compiled for.
#[derive(Clone, Copy)]
struct Flags {
    spectral: bool,
    camera: bool,
    expected: bool,
    hero: bool,
    dielectric: bool,
}

/// A Latin hypercube over one batch: in every emission dimension the n photons take one sample
/// from each of n equal strata, in an independent random order per dimension. Each sample is
/// still uniform, so every estimator stays unbiased; batches stay independent of each other.
fn latin_hypercube(n: usize, s: &mut Sampler) -> Vec<EmitSample> {
    let mut table = vec![[0.0; EMIT_DIMS]; n];
    let mut order: Vec<u32> = (0..n as u32).collect();
    for d in 0..EMIT_DIMS {
        // Fisher–Yates shuffle.
        for i in (1..n).rev() {
            let j = (s.uniform() * (i + 1) as f64) as usize;
            order.swap(i, j.min(i));
        }
        for (row, &stratum) in table.iter_mut().zip(&order) {
            row[d] = (stratum as f64 + s.uniform()) / n as f64;
        }
    }
    table
}

/// Hero-wavelength bookkeeping (Wilkie et al. 2014, "Hero Wavelength Spectral Sampling"): the
/// photon's path is sampled at its hero wavelength λ₀; it also carries λ₁..λ₃, rotated by a
/// quarter of the range. Each λₖ is a sampling technique (as if it had been the hero), and the
/// balance heuristic gives the contribution of wavelength j as
///   f(x, λⱼ) / Σₖ p(x, λₖ),  with  f(x, λ) ∝ S(λ)·Π throughput(λ)  and  p(x, λ) ∝ S(λ)·Π probability(λ),
/// where each event's probability is what technique k's own estimator would have used (albedo
/// for a survival, factor/albedo for a lobe choice). So each weight is bounded and sums to ≈ 1.
#[derive(Default)]
struct Hero {
    lambda: [f64; 4],
    /// S(λₖ): the light's relative spectral power.
    power: [f64; 4],
    /// Π throughput factors and Π event probabilities at λₖ, and technique k's own weight.
    throughput: [f64; 4],
    probability: [f64; 4],
    technique_weight: [f64; 4],
    /// Colour weights (x̄, ȳ, z̄)(λₖ)/∫ȳ.
    colour: [Vec3A; 4],
}

impl Hero {
    fn new(emitter: &Emitter, birth: &Birth, range: (f64, f64)) -> Self {
        let width = range.1 - range.0;
        let lambda: [f64; 4] = std::array::from_fn(|k| {
            // In [0, 1.75·width]: one subtraction wraps it, exactly (Sterbenz), as fmod would.
            let x = birth.lambda_nm - range.0 + k as f64 * width / 4.0;
            range.0 + if x >= width { x - width } else { x }
        });
        Hero {
            lambda,
            power: emitter.spectral_power(birth.light, &lambda),
            throughput: [1.0; 4],
            probability: [1.0; 4],
            technique_weight: [1.0; 4],
            colour: map_array(lambda, |l| emitter.colour(l)),
        }
    }

    /// One event whose throughput factor, albedo and analog probability at λₖ are `at(k)`
    /// (`Bsdf::event_terms`).
    #[inline]
    fn event<const EXPECTED: bool>(&mut self, at: impl Fn(usize) -> (f64, f64, f64)) {
        for k in 0..4 {
            let (factor, albedo, analog) = at(k);
            self.throughput[k] *= factor;
            // Selected, not branched on: lanes fall below the roulette weight at different
            // events. Survival with probability = albedo, then the lobe with factor/albedo, is
            // `analog` (= factor where the model samples exactly); × 1 changes no weight.
            let expected = EXPECTED && self.technique_weight[k] >= ROULETTE_WEIGHT;
            let kept = if albedo > 0.0 { factor / albedo } else { 0.0 };
            self.probability[k] *= if expected { kept } else { analog };
            self.technique_weight[k] *= if expected { albedo } else { 1.0 };
        }
    }

    fn denominator(&self) -> f64 {
        (0..4).map(|k| self.power[k] * self.probability[k]).sum()
    }

    /// XYZ of the emission vertex (before the emission pdf and camera importance).
    fn emission_xyz(&self) -> Vec3A {
        let inv_d = 1.0 / self.denominator();
        (0..4).fold(Vec3A::ZERO, |acc, k| acc + self.colour[k] * (self.power[k] * inv_d) as f32)
    }

    /// XYZ of a diffuse vertex whose BSDF factor toward the camera at λₖ is `bsdf[k]`.
    #[inline]
    fn splat_xyz(&self, bsdf: [f64; 4]) -> Vec3A {
        let d = self.denominator();
        if !(d > 0.0) {
            return Vec3A::ZERO;
        }
        let inv_d = 1.0 / d;
        (0..4).fold(Vec3A::ZERO, |acc, k| {
            acc + self.colour[k] * (self.power[k] * self.throughput[k] * bsdf[k] * inv_d) as f32
        })
    }
}

/// A surface or emission splat: through index-matched boundaries (`splat_through`, starting in
/// the medium `medium()`) where the scene has any, else by a plain visibility test (`splat`).
#[inline]
#[allow(clippy::too_many_arguments)]
fn splat_seen(
    cam: &CameraModel,
    clear: Option<&ClearView>,
    geo: &Geometry,
    film: &mut FilmBatch,
    start: RayEnd,
    through: Option<Through>,
    medium: impl Fn() -> Option<u32>,
    mu_t: impl Fn(Option<u32>) -> f64,
    value: impl Fn(Vec3A) -> Vec3A,
) {
    match through {
        Some(t) => splat_through(cam, geo, film, start, medium(), mu_t, &t, value),
        None => splat(cam, clear, geo, film, start, value),
    }
}

/// Connects `start` (a free point in a medium, or a surface point) to the camera and adds
/// `value(ω)·T·importance` to its pixel, T = exp(−∫μt) along the way, `medium` being the
/// dielectric the way starts in: the connection passes index-matched boundaries (`passage`),
/// changing medium there, and anything else blocks it. `mu_t(m)`: the extinction per metre
/// inside dielectric m (0 outside all).
#[inline]
#[allow(clippy::too_many_arguments)]
fn splat_through(
    cam: &CameraModel,
    geo: &Geometry,
    film: &mut FilmBatch,
    start: RayEnd,
    medium: Option<u32>,
    mu_t: impl Fn(Option<u32>) -> f64,
    through: &Through,
    value: impl Fn(Vec3A) -> Vec3A,
) {
    let Some(proj) = cam.project(start.p) else { return };
    let v = value(proj.to_camera);
    if v == Vec3A::ZERO || !v.is_finite() {
        return;
    }
    film.shadow_rays += 1;
    let w = proj.to_camera;
    let origin = if start.prim == NO_PRIM { start.p } else { geo.spawn(start.p, start.err, start.prim, w) };
    let mut optical_depth = 0.0f64;
    let stretch = |m: Option<u32>, len: f32| optical_depth += mu_t(m) * len as f64;
    if through.walk(geo, origin, w, cam.position, (start.prim, NO_PRIM), medium, stretch) {
        film.add(proj.pixel, v * ((-optical_depth).exp() as f32 * proj.importance));
    }
}

/// Books the segment o + s·d, s ∈ [0, len], carrying weight w·e^{−α s}, to the volume grids it
/// crosses: Σ ∫w ds per voxel (track length) and, where α > 0, the weight it loses there.
#[allow(clippy::too_many_arguments)]
fn track(
    grids: &[crate::scene::volume::VolumeGrid],
    o: glam::DVec3,
    d: glam::DVec3,
    len: f64,
    w: f64,
    alpha: f64,
    track: &mut HistoryScores,
    absorbed: &mut HistoryScores,
) {
    for g in grids {
        g.traverse(o, d, len, |voxel, a, b| {
            if alpha > 0.0 {
                let lost = w * ((-alpha * a).exp() - (-alpha * b).exp());
                track.add(voxel as u32, lost / alpha);
                absorbed.add(voxel as u32, lost);
            } else {
                track.add(voxel as u32, w * (b - a));
            }
        });
    }
}

/// The collision point `gap` short of boundary hit `h` along travel direction `dir`, measured
/// back from the hit point so that it is as precise as the hit point itself. Within that point's
/// error bound (and its own rounding) of the face it is put just inside it instead, as a ray
/// origin leaving a surface is (`offset_ray_origin`): a shift of at most the bound, where a
/// point rounded through the face would have left the medium.
#[inline]
fn collision_point(geo: &Geometry, h: &crate::geometry::Hit, dir: Vec3A, gap: f64) -> Vec3A {
    let (hp, err) = geo.hit_point(h);
    let n = geo.normal(h.prim as usize);
    let p = hp - dir * gap as f32;
    let bound = n.abs().dot(err + p.abs() * f32::EPSILON) as f64;
    if gap * (dir.dot(n).abs() as f64) > 2.0 * bound {
        p
    } else {
        crate::geometry::offset_ray_origin(hp, err + hp.abs() * f32::EPSILON, n, -dir)
    }
}

/// Connects a photon vertex at `p` (error bound `err`, normal `n`, zero for a point light) to the
/// camera and adds `value(ω)·importance` to its pixel when nothing is in between. `value(ω)` is
/// the XYZ-weighted emission pdf or BSDF·|cos| toward the camera (see `film` for the estimator).
/// Where the camera's clear view knows the point seen or hidden no ray is cast; `shadow_rays`
/// counts the connections tested either way.
#[inline]
fn splat(
    cam: &CameraModel,
    clear: Option<&ClearView>,
    geo: &Geometry,
    film: &mut FilmBatch,
    start: RayEnd,
    value: impl Fn(Vec3A) -> Vec3A,
) {
    let Some(proj) = cam.project(start.p) else { return };
    let v = value(proj.to_camera);
    if v == Vec3A::ZERO || !v.is_finite() {
        return;
    }
    film.shadow_rays += 1;
    let seen = match clear.map_or(Sight::Unknown, |c| c.judge(&proj, start.prim)) {
        Sight::Clear => true,
        Sight::Hidden => false,
        Sight::Unknown => geo.visible(start, RayEnd::free(cam.position)),
    };
    if seen {
        film.add(proj.pixel, v * proj.importance);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latin_hypercube_fills_every_stratum_once() {
        let mut s = Sampler::for_batch(3, 0);
        let n = 257;
        let table = latin_hypercube(n, &mut s);
        for d in 0..EMIT_DIMS {
            let mut seen = vec![false; n];
            for row in &table {
                let k = (row[d] * n as f64) as usize;
                assert!(!seen[k], "stratum {k} of dimension {d} used twice");
                seen[k] = true;
            }
        }
    }
}
