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
//! Most samples need no ray: where a pixel's footprint, widened by rounding, misses every
//! eligible light's image, or lies inside one light triangle's image with nothing in front of it
//! (the camera's `ClearView`), the ray's result is known (`in_view`), and is used. It is bit for
//! bit what the ray finds, except where a lamp lies flush with a surface split into triangles
//! (a ceiling's quad): a ray within ~10⁻⁷ px of that split may meet one of its triangles first and
//! the second look (below) the other, and read zero where the known sample reads the lamp.
//!
//! A sample that comes out non-finite (a lamp whose radiance overflows f32) is counted as black,
//! as the camera integrators' samples are.

use glam::Vec3A;

use crate::detectors::film::{CameraModel, FilmBatch, PolygonImage};
use crate::detectors::tally::Counters;
use crate::geometry::{Geometry, RayEnd, NO_PRIM};
use crate::integrators::batch::{cancelled, BATCH_PHOTONS};
use crate::integrators::clear_view::{bounds, contains, meets, ClearView};
use crate::integrators::passage::is_passable;
use crate::lights::Emitter;
use crate::sampling::owen_sobol_2d;
use crate::scene::{LightShape, Scene};

/// Photons per camera sample of the emitters (after batch 0's first pass). In the Cornell box
/// 86 % of the samples need no ray (`in_view`); cast, they took ~3 % of an image run's time.
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
    /// Per listed pixel: what its rays see, where known without casting them (`in_view`).
    seen: Vec<Seen>,
}

impl EmitterView {
    /// The view of `scene`'s eligible lights through `camera`; None when no eligible light
    /// projects into the image.
    /// `clear`, the camera's clear view where the run has one, lets pixels that lie wholly on a
    /// light with nothing in front of it skip their rays.
    pub fn new(scene: &Scene, emitter: &Emitter, camera: &CameraModel, clear: Option<&ClearView>) -> Option<Self> {
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
        if pixels.is_empty() {
            return None;
        }
        let seen = in_view(geo, camera, clear, &surface_light, &pixels);
        Some(EmitterView { from_camera, surface_light, pixels, light_box, seen })
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
            let (pixel, seen) = (self.pixels[listed], self.seen[listed]);
            let sample_point = point;
            listed += 1;
            if listed == m as usize {
                (listed, point) = (0, point.wrapping_add(1));
            }
            let (_, acc, n) = &mut film.view[slot];
            // A sample known to be zero adds nothing to the sums (which start at +0).
            if seen != Seen::Nothing {
                let (u, v) = owen_sobol_2d(sample_point, pixel_seed(run_seed, pixel));
                let dir = camera.ray_direction(pixel as usize, u, v);
                let xyz = match seen {
                    Seen::Light { prim, light } => radiance_from(geo, emitter, light as usize, prim, dir),
                    _ => self.emission_seen(geo, emitter, camera.position, dir, counters),
                };
                let xyz = if xyz.is_finite() { xyz } else { Vec3A::ZERO };
                let (x, y, z) = (xyz.x as f64, xyz.y as f64, xyz.z as f64);
                for (a, value) in acc.iter_mut().zip([x, y, z, y * y]) {
                    *a += value;
                }
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
        radiance_from(geo, emitter, light, hit.prim, dir)
    }

    /// The eligible light whose surface primitive `prim` lies on.
    #[inline]
    fn light_of(&self, geo: &Geometry, prim: u32) -> Option<usize> {
        self.surface_light[geo.surface_of(prim as usize) as usize]
    }
}

/// XYZ radiance along `dir` from triangle `prim` of light `light`, met by a camera ray.
#[inline]
fn radiance_from(geo: &Geometry, emitter: &Emitter, light: usize, prim: u32, dir: Vec3A) -> Vec3A {
    let radiance = emitter.radiance::<false, 1>(light, geo.normal(prim as usize), -dir, &[f64::NAN]).0[0];
    emitter.grey_xyz(light) * radiance as f32
}

/// What every camera ray through a listed pixel sees of the eligible lights, where that is known
/// without casting it (`in_view`).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Seen {
    /// Unknown: cast the ray.
    Cast,
    /// No eligible light: the sample is zero.
    Nothing,
    /// Triangle `prim` of light `light`, first.
    Light { prim: u32, light: u32 },
}

/// Per listed pixel (`pixels`, ascending), what its camera rays see (`Seen`), judged from the
/// pixel's footprint widened by what rounding may move a ray: its direction's
/// (`direction_rounding`) and its hit test's (`ClearView::spread`). Where no eligible light
/// triangle's image meets the widened footprint, the exact ray misses them all by that margin, so
/// the rounded one (and `emission_seen`'s second look along the same line) does too: Nothing.
/// Where exactly one, T, meets it, contains it, and is clear in the pixel's tile (nothing on the
/// eye's side of T's plane above the shadow margin is seen there, `ClearView`), every ray meets
/// T's interior with nothing in front: Light. A surface within the shadow margin of T's plane (a
/// lamp flush with its ceiling) may still come out nearer; `emission_seen` then finds T behind it
/// and tests it as the splats would, which the clear view has already vouched for, unless its
/// second look meets another such triangle first (the module comment's exception). Without a
/// clear view (a scene too large for one) every pixel casts.
fn in_view(
    geo: &Geometry,
    camera: &CameraModel,
    clear: Option<&ClearView>,
    surface_light: &[Option<usize>],
    pixels: &[u32],
) -> Vec<Seen> {
    let Some(clear) = clear else { return vec![Seen::Cast; pixels.len()] };
    let mut seen = vec![Seen::Nothing; pixels.len()];
    // Per listed pixel: the one eligible triangle whose image meets its widened footprint, if
    // exactly one does; None once two do.
    let mut meeting: Vec<Option<Option<u32>>> = vec![Some(None); pixels.len()];
    // Twice each bound: the direction's is stated with about 2× to spare, and a flush lamp's
    // second look adds a hit point's rounding to the segment's.
    let [mx, my] = camera.direction_rounding().map(|r| 2.0 * (r + clear.spread()));
    let footprint = |col: usize, row: usize| -> ([f64; 2], [f64; 2]) {
        ([col as f64 - mx, col as f64 + 1.0 + mx], [row as f64 - my, row as f64 + 1.0 + my])
    };
    // The eligible light triangles' images, each made once.
    let images: Vec<Option<PolygonImage>> = (0..geo.len())
        .map(|prim| {
            surface_light[geo.surface_of(prim) as usize]
                .and_then(|_| camera.polygon_image(&geo.verts(prim).map(|v| v.as_dvec3())))
        })
        .collect();
    for (prim, image) in images.iter().enumerate() {
        let Some(image) = image else { continue };
        let ([c0, c1], [r0, r1]) = match image {
            PolygonImage::Anywhere => ([0, camera.width - 1], [0, camera.height - 1]),
            PolygonImage::Corners(corners, _) => {
                let (lo, hi) = bounds(corners);
                let index = |x: f64, n: usize| (x.floor().max(0.0) as usize).min(n - 1);
                (
                    [index(lo[0] - mx - 1.0, camera.width), index(hi[0] + mx + 1.0, camera.width)],
                    [index(lo[1] - my - 1.0, camera.height), index(hi[1] + my + 1.0, camera.height)],
                )
            }
        };
        for row in r0..=r1 {
            let (Ok(a) | Err(a)) = pixels.binary_search(&((row * camera.width + c0) as u32));
            let (Ok(b) | Err(b)) = pixels.binary_search(&((row * camera.width + c1 + 1) as u32));
            for k in a..b {
                let col = pixels[k] as usize % camera.width;
                if meets(image, &footprint(col, row)) {
                    meeting[k] = match meeting[k] {
                        Some(None) => Some(Some(prim as u32)),
                        _ => None,
                    };
                }
            }
        }
    }
    for (k, m) in meeting.iter().enumerate() {
        let (col, row) = (pixels[k] as usize % camera.width, pixels[k] as usize / camera.width);
        seen[k] = match *m {
            Some(None) => Seen::Nothing,
            Some(Some(prim)) => {
                let light = surface_light[geo.surface_of(prim as usize) as usize];
                match (&images[prim as usize], light) {
                    (Some(PolygonImage::Corners(corners, _)), Some(light))
                        if contains(corners, &footprint(col, row)) && clear.is_clear_in(col, row, prim) =>
                    {
                        Seen::Light { prim, light: light as u32 }
                    }
                    _ => Seen::Cast,
                }
            }
            None => Seen::Cast,
        };
    }
    seen
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;

    /// The bundled Cornell box's scene file with `edit` applied to its text.
    fn cornell(edit: impl Fn(&str) -> String) -> Scene {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");
        let text = std::fs::read_to_string(format!("{dir}/cornell_box.toml")).unwrap();
        let edited = edit(&text);
        crate::scene::load_str(std::path::Path::new(&format!("{dir}/edited.toml")), &edited).unwrap()
    }

    /// Pixels whose rays `in_view` knows (seen a light, seen nothing) and pixels that cast. Panics
    /// where a sample known without a ray differs in any bit from what the ray finds: 64 points
    /// per such pixel, its four corners (the farthest a footprint reaches) and 60 uniform ones.
    fn check(scene: &Scene) -> (usize, usize, usize) {
        let emitter = Emitter::new(scene);
        let cam = CameraModel::new(scene.camera.as_ref().unwrap());
        let clear = ClearView::new(&scene.geometry, &cam).expect("the box gets a clear view");
        let view = EmitterView::new(scene, &emitter, &cam, Some(&clear)).expect("the lamp is in view");
        let mut rng = Sampler::for_batch(5, 0);
        let mut counters = Counters::default();
        let below_one = 1.0 - f32::EPSILON / 2.0;
        let (mut light, mut nothing, mut cast) = (0, 0, 0);
        for (&pixel, &seen) in view.pixels.iter().zip(&view.seen) {
            match seen {
                Seen::Cast => cast += 1,
                Seen::Nothing => nothing += 1,
                Seen::Light { .. } => light += 1,
            }
            if seen == Seen::Cast {
                continue;
            }
            for j in 0..64 {
                let (u, v) = match j {
                    0 => (0.0, 0.0),
                    1 => (below_one, 0.0),
                    2 => (0.0, below_one),
                    3 => (below_one, below_one),
                    _ => (rng.uniform_f32(), rng.uniform_f32()),
                };
                let dir = cam.ray_direction(pixel as usize, u, v);
                let by_ray = view.emission_seen(&scene.geometry, &emitter, cam.position, dir, &mut counters);
                let known = match seen {
                    Seen::Light { prim, light } => radiance_from(&scene.geometry, &emitter, light as usize, prim, dir),
                    _ => Vec3A::ZERO,
                };
                assert_eq!(
                    by_ray.to_array().map(f32::to_bits),
                    known.to_array().map(f32::to_bits),
                    "pixel {pixel} ({seen:?}) at ({u}, {v}): the ray sees {by_ray}, known {known}"
                );
            }
        }
        (light, nothing, cast)
    }

    /// A lamp in view is imaged without rays where that is known: the pixels its triangles'
    /// images miss, widened by rounding, read zero, and those wholly on one triangle with nothing
    /// in front read its radiance, bit for bit what the rays find. Checked on the bundled box, with
    /// the lamp flush with the ceiling (rays may meet either), with a shade hiding part of it (its
    /// pixels must cast), and with the lamp turned to face up (the camera sees its back: zero).
    #[test]
    fn pixels_known_without_rays_read_what_their_rays_find() {
        let (light, nothing, cast) = check(&cornell(|t| t.to_string()));
        println!("bundled: {light} on the lamp, {nothing} off it, {cast} cast");
        // The lamp's image is ~86 × 18 pixels, cut along its diagonal: most of its pixels are
        // known, and so are most of the two triangles' boxes around it.
        assert!(light > 900 && nothing > 500 && cast > 100, "{light} {nothing} {cast}");

        let (flush, _, _) = check(&cornell(|t| t.replace("548.7", "548.8")));
        assert!(flush + 10 > light, "{flush} pixels on the flush lamp: its image hardly moves by 0.1 mm");

        // A 100 × 60 mm plate 2 cm below the lamp, hiding most of it from the camera.
        let shade = "\n[[surfaces]]\nname = \"shade\"\nmaterial = \"white\"\n\
            shape = { type = \"quad\", corners = [[228, 528, 180], [328, 528, 180], [328, 528, 240], [228, 528, 240]] }\n";
        let (shaded, _, shaded_cast) = check(&cornell(|t| format!("{t}{shade}")));
        println!("shaded: {shaded} on the lamp, {shaded_cast} cast");
        assert!(shaded + 300 < light && shaded_cast > cast + 300, "the shade hides {} pixels", light - shaded);

        let up = "corners = [[343, 548.7, 227], [213, 548.7, 227], [213, 548.7, 332], [343, 548.7, 332]]";
        let facing_up = cornell(|t| {
            let e =
                t.replace("corners = [[343, 548.7, 227], [343, 548.7, 332], [213, 548.7, 332], [213, 548.7, 227]]", up);
            assert!(e.contains(up));
            e
        });
        let (back, _, _) = check(&facing_up);
        assert!(back > 900, "{back} pixels on the lamp's back");
    }

    /// Batches traced with the known samples sum to the same bits as batches that cast every
    /// ray (no clear view): the known values are the rays', and a zero sample's skipped add would
    /// have added +0 to sums that start at +0. 200 000 photons' samples (50 000) in batches 0 (with
    /// one sample a listed pixel first), 1 and 7, on the bundled box and the lamp flush with the
    /// ceiling; the known ones must also save most rays.
    #[test]
    fn batches_with_known_samples_sum_what_cast_rays_sum() {
        for scene in [cornell(|t| t.to_string()), cornell(|t| t.replace("548.7", "548.8"))] {
            let emitter = Emitter::new(&scene);
            let cam = CameraModel::new(scene.camera.as_ref().unwrap());
            let clear = ClearView::new(&scene.geometry, &cam).unwrap();
            let cast = EmitterView::new(&scene, &emitter, &cam, None).unwrap();
            let known = EmitterView::new(&scene, &emitter, &cam, Some(&clear)).unwrap();
            assert!(cast.seen.iter().all(|&s| s == Seen::Cast));
            for batch in [0u64, 1, 7] {
                let (mut a, mut b) = (FilmBatch::default(), FilmBatch::default());
                let (mut rays_a, mut rays_b) = (Counters::default(), Counters::default());
                cast.trace_batch(&scene, &emitter, &cam, batch, 200_000, &mut a, &mut rays_a, None);
                known.trace_batch(&scene, &emitter, &cam, batch, 200_000, &mut b, &mut rays_b, None);
                assert_eq!(a.view.len(), b.view.len());
                for (x, y) in a.view.iter().zip(&b.view) {
                    assert_eq!((x.0, x.2), (y.0, y.2));
                    assert_eq!(x.1.map(f64::to_bits), y.1.map(f64::to_bits), "batch {batch}, entry {}", x.0);
                }
                assert!(5 * rays_b.rays < rays_a.rays, "batch {batch}: {} rays against {}", rays_b.rays, rays_a.rays);
            }
        }
    }
}
