//! The light tracer's image of the emitters the camera sees directly, estimated from the camera.
//!
//! A photon's emission vertex connected to the camera (the emission splat) lands in a random
//! pixel of the lamp's image: those pixels, the brightest, read a count of random arrivals, and
//! in the Cornell box they held 46 % of the image's squared error. For area lights in the open
//! the same part of the image, radiance seen directly, is estimated from the camera instead: a
//! ray through a uniform point of a pixel reads L_e where it first hits such a light (pixel value
//! = mean radiance over the footprint, `film`). Every emitter → camera path is counted by exactly
//! one of the two strategies (the light tracer skips these lights' emission splats), so the image
//! stays unbiased; a lamp's inner pixels read its exact radiance with zero variance, and only its
//! edge pixels vary (partly covered footprints).
//!
//! Eligible: area lights (not points, ray sets or collimated beams) that emit into no dielectric,
//! in scenes without index-matched boundaries (which emission splats look through). The colour is
//! the light's exact mean (x̄, ȳ, z̄) under its spectrum, as for a point light in view
//! (`camera::PointView`), so no wavelength is drawn.
//!
//! Samples. Only pixels an eligible light projects into are sampled (`pixels`, M of them). The
//! run's samples form one sequence, sample k going to listed pixel k mod M: batch 0 takes M of
//! them first, so every listed pixel has a sample however short the run, and each batch of n
//! photons takes ⌈n/VIEW_EVERY⌉ more. A pixel's samples, in run order, are the points of one
//! scrambled 2-D Sobol sequence over its footprint (`owen_sobol_2d`, seeded by the run's seed
//! and the pixel; the photons' random numbers are untouched): each point is uniform, so the
//! pixel's mean is unbiased, and together they cover the footprint evenly, so a lamp's edge
//! pixels vary far less than with independent points. The film's camera part keeps their mean
//! and the variance of independent samples over their count, which for such points is usually
//! larger than the true one (Owen's bound allows up to 3× for 2-D nets).
//!
//! A sample that comes out non-finite (a lamp whose radiance overflows f32) is counted as black,
//! as the camera integrators' samples are.

use glam::Vec3A;

use crate::detectors::film::{CameraModel, FilmBatch};
use crate::detectors::tally::Counters;
use crate::geometry::{Geometry, RayEnd, NO_PRIM};
use crate::integrators::batch::{cancelled, BATCH_PHOTONS};
use crate::integrators::passage::is_passable;
use crate::lights::Emitter;
use crate::sampling::owen_sobol_2d;
use crate::scene::{LightShape, Scene};

/// Photons per camera sample of the emitters (after batch 0's first pass): at 1/4 of a closest
/// hit per photon, ~3 % of a Cornell-box image run's time.
pub const VIEW_EVERY: u64 = 4;

/// How far on either side of a camera ray's nearest hit, relative to its distance, a light is
/// looked for (`emission_seen`): coplanar hits differ by the rounding of t (~1e-6 of it); whether
/// such a light is seen is then decided by a visibility test, so a wider reach costs rays, not
/// accuracy.
const COPLANAR_REACH: f32 = 1.0 / 16384.0;

/// The scrambling seed of a pixel's sequence: distinct for the pixels of one run, and changed
/// by every bit of the run's seed (`owen_sobol_2d` hashes it before use).
fn pixel_seed(run_seed: u64, pixel: u32) -> u32 {
    (run_seed ^ (run_seed >> 32)) as u32 ^ pixel.wrapping_mul(0x9E37_79B9)
}

pub struct EmitterView {
    /// Per light: whether its directly seen emission comes from here (and not from its splats).
    from_camera: Vec<bool>,
    /// Per surface: the eligible light it belongs to.
    surface_light: Vec<Option<usize>>,
    /// The pixels an eligible light may project into, ascending.
    pixels: Vec<u32>,
    /// The eligible lights' bounding box (lowest, highest corner).
    light_box: (Vec3A, Vec3A),
}

impl EmitterView {
    /// The view of `scene`'s eligible lights through `camera`; None when no eligible light
    /// projects into the image.
    pub fn new(scene: &Scene, emitter: &Emitter, camera: &CameraModel) -> Option<Self> {
        let looks_through = (0..scene.surfaces.len()).any(|s| is_passable(scene.material_of(s)));
        let from_camera: Vec<bool> = (0..emitter.light_count())
            .map(|l| {
                !looks_through
                    && !emitter.is_point(l)
                    && !emitter.is_collimated(l)
                    && emitter.emits_into_the_open(l)
                    && matches!(scene.lights[l].shape, LightShape::Area { .. })
            })
            .collect();
        let surface_light: Vec<Option<usize>> =
            scene.surfaces.iter().map(|s| s.light.filter(|&l| from_camera[l])).collect();
        let geo = &scene.geometry;
        let mut marked = vec![false; camera.pixels()];
        let whole = ([0, camera.width - 1], [0, camera.height - 1]);
        for prim in 0..geo.len() {
            if surface_light[geo.surface_of(prim) as usize].is_none() {
                continue;
            }
            match camera.pixel_box(&geo.verts(prim)) {
                // Nothing more to mark (a lamp around the camera would otherwise fill the image
                // once for each of its triangles that reach behind it).
                Some(b) if b == whole => {
                    marked.fill(true);
                    break;
                }
                Some(([c0, c1], [r0, r1])) => {
                    for row in r0..=r1 {
                        marked[row * camera.width + c0..=row * camera.width + c1].fill(true);
                    }
                }
                None => {}
            }
        }
        let pixels: Vec<u32> = (0..marked.len() as u32).filter(|&p| marked[p as usize]).collect();
        let light_box = (0..geo.len())
            .filter(|&prim| surface_light[geo.surface_of(prim) as usize].is_some())
            .flat_map(|prim| geo.verts(prim))
            .fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        (!pixels.is_empty()).then_some(EmitterView { from_camera, surface_light, pixels, light_box })
    }

    /// Whether light `light`'s emission splats are replaced by this view.
    #[inline]
    pub fn from_camera(&self, light: usize) -> bool {
        self.from_camera[light]
    }

    /// The pixels it samples, ascending: the film's listed camera part
    /// (`Film::with_listed_camera_pixels`), whose entries `FilmBatch::view` refers to.
    pub fn pixels(&self) -> &[u32] {
        &self.pixels
    }

    /// The samples of transport batch `batch` of `count` photons, summed per pixel into
    /// `film.view` (by the pixel's place in `pixels`); their rays are added to `counters`. Ends
    /// early, to be discarded, once `cancel` is set.
    #[allow(clippy::too_many_arguments)]
    pub fn trace_batch(
        &self,
        scene: &Scene,
        emitter: &Emitter,
        camera: &CameraModel,
        batch: u64,
        count: u64,
        film: &mut FilmBatch,
        counters: &mut Counters,
        cancel: Option<&std::sync::atomic::AtomicBool>,
    ) {
        let geo = &scene.geometry;
        let m = self.pixels.len() as u64;
        let samples = if batch == 0 { m } else { 0 } + count.div_ceil(VIEW_EVERY);
        // The run's sequence: batch 0 from 0; batch b ≥ 1 after batch 0's M and b full batches'
        // share (u128: the estimator pilot's batch indices are near 2⁶⁴).
        let per_batch = BATCH_PHOTONS.div_ceil(VIEW_EVERY) as u128;
        let first = if batch == 0 { 0 } else { m as u128 + batch as u128 * per_batch };
        let run_seed = scene.simulation.seed;
        // The batch's list has one entry per pixel it samples, accumulated in place: sample k's
        // is entry k mod M (consecutive samples take distinct pixels).
        let slots = samples.min(m);
        // Sample k is the run's sample g = first + k: listed pixel g mod M, the (g div M)-th
        // point of that pixel's sequence (wrapping at 2³², past the ~4·10⁹ samples a pixel keeps).
        let (mut listed, mut point) = ((first % m as u128) as usize, (first / m as u128) as u32);
        film.view.clear();
        film.view.extend((0..slots as usize).map(|k| (((listed + k) % m as usize) as u32, [0.0f64; 4], 0u32)));
        let mut slot = 0usize;
        for k in 0..samples {
            if cancelled(cancel, k) {
                return;
            }
            let pixel = self.pixels[listed];
            let (u, v) = owen_sobol_2d(point, pixel_seed(run_seed, pixel));
            listed += 1;
            if listed == m as usize {
                (listed, point) = (0, point.wrapping_add(1));
            }
            let dir = camera.ray_direction(pixel as usize, u, v);
            let xyz = self.emission_seen(geo, emitter, camera.position, dir, counters);
            let xyz = if xyz.is_finite() { xyz } else { Vec3A::ZERO };
            let (x, y, z) = (xyz.x as f64, xyz.y as f64, xyz.z as f64);
            let (_, acc, n) = &mut film.view[slot];
            for (a, value) in acc.iter_mut().zip([x, y, z, y * y]) {
                *a += value;
            }
            *n += 1;
            slot = if slot + 1 == slots as usize { 0 } else { slot + 1 };
        }
    }

    /// XYZ radiance reaching the camera along `dir` from an eligible light it hits first (zero
    /// for anything else, which the light tracer's splats image): L_e = Φ p(ω)/(A cosθ) times the
    /// light's mean colour.
    ///
    /// A lamp flush with another surface (a quad on the ceiling's plane) is met at the distance
    /// of that surface, and rounding decides which hit comes out nearer. Such a lamp is seen as
    /// its emission splats saw it: from its point offset toward the camera, which a coplanar
    /// surface does not hide (`Geometry::visible`). So where the nearest hit is not a light, a
    /// light met within `COPLANAR_REACH` of it is tested that way (a short ray across the hit,
    /// cast only where the hit lies within that reach of the lights' bounding box).
    #[inline]
    fn emission_seen(
        &self,
        geo: &Geometry,
        emitter: &Emitter,
        eye: Vec3A,
        dir: Vec3A,
        counters: &mut Counters,
    ) -> Vec3A {
        counters.rays += 1;
        let Some(first) = geo.intersect(eye, dir, f32::INFINITY, NO_PRIM) else { return Vec3A::ZERO };
        let (hit, light) = match self.light_of(geo, first.prim) {
            Some(light) => (first, light),
            None => {
                let reach = first.t * COPLANAR_REACH;
                let at = eye + dir * first.t;
                let (lo, hi) = self.light_box;
                if (at + reach).cmplt(lo).any() || (at - reach).cmpgt(hi).any() {
                    return Vec3A::ZERO;
                }
                counters.rays += 1;
                let from = eye + dir * (first.t - reach);
                let Some(behind) = geo.intersect(from, dir, 2.0 * reach, first.prim) else { return Vec3A::ZERO };
                let Some(light) = self.light_of(geo, behind.prim) else { return Vec3A::ZERO };
                let (p, err) = geo.hit_point(&behind);
                let lamp = RayEnd { p, err, n: geo.normal(behind.prim as usize), prim: behind.prim };
                counters.shadow_rays += 1;
                if !geo.visible(lamp, RayEnd::free(eye)) {
                    return Vec3A::ZERO;
                }
                (behind, light)
            }
        };
        let radiance = emitter.radiance::<false, 1>(light, geo.normal(hit.prim as usize), -dir, &[f64::NAN]).0[0];
        emitter.grey_xyz(light) * radiance as f32
    }

    /// The eligible light whose surface primitive `prim` lies on.
    #[inline]
    fn light_of(&self, geo: &Geometry, prim: u32) -> Option<usize> {
        self.surface_light[geo.surface_of(prim as usize) as usize]
    }
}
