//! The camera integrators: path tracing and bidirectional path tracing (BDPT) of the same image
//! the light tracer makes, on the same film with the same normalisation (a pixel reads the mean
//! radiance over its footprint; see `film`). `flux.json` still comes from the particle tracer.
//!
//! A run of N samples gives sample k (k = 0..N−1, in batch order) to pixel k mod P; its value
//! is that pixel's radiance estimate, and BDPT's light-tracing strategy (t = 1) also splats into
//! other pixels, scaled by 1/N like the light tracer's photons.
//!
//! Wavelengths. A spectral sample carries four wavelengths: λ₀ uniform over the range and λ₁..λ₃
//! rotated from it by quarters of the range, so each is uniform. Every path is sampled
//! independently of λ (lobe choices use the lanes' mean albedos), so each lane is an unbiased
//! estimate L(λₖ)·(x̄,ȳ,z̄)(λₖ)/(∫ȳ · p(λₖ)) and the sample's value is their mean. A dispersive
//! refraction bends the path for λ₀ alone; the sample then keeps lane 0 only (pbrt-v4's
//! "terminate secondary wavelengths"), which is unbiased too because the decision does not depend
//! on λ₁..λ₃. Grey transport uses one value per light and that light's mean colour.

// `!(x > 0.0)` is meant: it is also true for NaN, which must stop a path as zero would.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod bdpt;
mod medium;
mod path;

use glam::Vec3A;

use crate::bsdf::{Bsdf, Mode, Prepared, Sample};
use crate::detectors::film::{CameraModel, FilmBatch};
use crate::detectors::tally::Counters;
use crate::geometry::{shadow_segment, Geometry, RayEnd};
use crate::integrators::clear_view::ClearView;
use crate::integrators::passage::{is_passable, Through};
use crate::lights::Emitter;
use crate::sampling::{Sampler, BDPT_STREAM, PATH_STREAM};
use crate::scene::{Material, Scene};

pub use crate::scene::Integrator;

pub const LANES: usize = 4;

/// A value per wavelength lane of a camera sample (`LANES` of them, the default).
pub use crate::spectrum::Lanes;

/// The wavelengths of one camera sample (see the module comment).
#[derive(Clone, Copy)]
pub struct Wavelengths {
    pub lambda: [f64; LANES],
    /// (x̄, ȳ, z̄)(λₖ)/(∫ȳ · p(λₖ)) with p = 1/width: the lane's radiance-to-XYZ factor.
    colour: [Vec3A; LANES],
    /// A dispersive event bent the path for λ₀ only: lanes 1..3 are dropped at the end.
    terminated: bool,
    /// 1/p(λ) of the uniform wavelength density (the range's width in nm).
    width: f64,
}

impl Wavelengths {
    pub fn sample<const SPECTRAL: bool>(emitter: &Emitter, range: (f64, f64), u: f64) -> Self {
        if !SPECTRAL {
            return Wavelengths {
                lambda: [f64::NAN; LANES],
                colour: [Vec3A::ZERO; LANES],
                terminated: false,
                width: 1.0,
            };
        }
        let width = range.1 - range.0;
        let lambda: [f64; LANES] =
            std::array::from_fn(|k| range.0 + (u * width + k as f64 * width / LANES as f64).rem_euclid(width));
        Wavelengths { lambda, colour: lambda.map(|l| emitter.colour(l) * width as f32), terminated: false, width }
    }

    /// These wavelengths with lane 0 at `lambda` and seen by the sensor there: a light
    /// subpath's re-emitted wavelength reaching the camera (its density is already in the
    /// subpath's weight; the width stands for the first wavelength's, drawn uniformly).
    fn seen_at(&self, emitter: &Emitter, lambda: [f64; LANES]) -> Wavelengths {
        let mut wl = Wavelengths { lambda, ..*self };
        wl.colour[0] = emitter.colour(lambda[0]) * wl.width as f32;
        wl
    }

    pub fn terminate_secondary(&mut self) {
        self.terminated = true;
    }
}

/// Per-lane XYZ of one sample's contributions, resolved into one XYZ when the sample ends.
#[derive(Clone, Copy, Default)]
pub struct LaneXyz([Vec3A; LANES]);

impl LaneXyz {
    /// Adds radiance `v` (per lane, per nm in spectral transport; W-based in grey) that came from
    /// light `light`.
    #[inline]
    pub fn add<const SPECTRAL: bool>(&mut self, emitter: &Emitter, wl: &Wavelengths, light: usize, v: Lanes) {
        if SPECTRAL {
            for k in 0..LANES {
                self.0[k] += wl.colour[k] * v.0[k] as f32;
            }
        } else {
            self.0[0] += emitter.grey_xyz(light) * v.0[0] as f32;
        }
    }

    /// Adds an XYZ that does not depend on the wavelengths to every lane, so that it comes out of
    /// `resolve` whole whether or not secondary lanes are dropped.
    #[inline]
    pub fn add_exact(&mut self, xyz: Vec3A) {
        for lane in &mut self.0 {
            *lane += xyz;
        }
    }

    /// The sample's XYZ: the mean over the lanes, or lane 0 alone after a dispersive event.
    pub fn resolve<const SPECTRAL: bool>(&self, wl: &Wavelengths) -> Vec3A {
        if !SPECTRAL || wl.terminated {
            self.0[0]
        } else {
            (self.0[0] + self.0[1] + self.0[2] + self.0[3]) * (1.0 / LANES as f32)
        }
    }
}

/// Russian roulette on the vertex's mean albedo, independent of λ (none at a lossless
/// boundary), then the BSDF's own sample; `beta` takes its weight over the survival
/// probability. None ends the path.
#[inline]
fn scatter(bsdf: &Bsdf, wo: Vec3A, mode: Mode, beta: &mut Lanes, s: &mut Sampler) -> Option<Sample<LANES>> {
    let survival = if bsdf.absorbs() { bsdf.mean_albedo(wo).min(1.0) } else { 1.0 };
    if bsdf.absorbs() && !(s.uniform() < survival) {
        return None;
    }
    let sampled = bsdf.sample(wo, mode, s)?;
    // A sample can carry nothing (ABg glass: light from beyond the critical angle); a lossless
    // boundary has no roulette to end such a path.
    if sampled.factor.is_zero() {
        return None;
    }
    *beta *= sampled.weight() * (1.0 / survival);
    Some(sampled)
}

/// What one image batch needs: the scene, its lights, the camera, and per-surface lookups.
pub struct ImageKernel<'a> {
    pub scene: &'a Scene,
    pub emitter: &'a Emitter,
    pub camera: &'a CameraModel,
    pub integrator: Integrator,
    materials: Vec<&'a Material>,
    /// Per surface: its material's constants worked out once (`bsdf::Prepared`).
    prepared: &'a [Prepared],
    /// Per surface: the light it belongs to, and whether it is a dispersive dielectric.
    surface_light: Vec<Option<usize>>,
    dispersive: Vec<bool>,
    /// Most scattering vertices on a path (the particle tracer's max_bounces + 1).
    max_scatterings: usize,
    /// Path tracing: the point lights the camera sees directly (empty for BDPT, whose t = 1
    /// strategy images them, and for scenes without point lights).
    point_views: Vec<PointView>,
    /// Fluorescent transport: samples keep lane 0 alone, whose wavelength re-emission changes.
    fluorescent: bool,
    /// Free flights weight the lanes by the one-sample MIS of `medium` (no lane is ever dropped).
    lane_mis: bool,
    /// BDPT: the surface points the camera sees unblocked, whose t = 1 connections need no ray.
    clear: Option<ClearView>,
    /// Per surface: an index-matched boundary (`passage`), which paths and connections go
    /// straight through: no vertex is made there.
    passable: Vec<bool>,
    /// Some surface is passable.
    see_through: bool,
}

/// A point light in the camera's view with nothing in between: no camera ray can hit it, so its
/// pixel gets the light tracer's emission splat deterministically (`ImageKernel::point_views`).
#[derive(Clone, Debug)]
struct PointView {
    pixel: usize,
    /// The light's part of the pixel's value (mean radiance over its footprint, see `film`):
    /// Φ · p(ω)/(d² A_pix cos³θ_c), ω toward the camera, times the light's colour weights
    /// ∫S·(x̄,ȳ,z̄)/(∫S·∫ȳ). Nothing on the segment depends on λ, so this is exactly what the
    /// wavelength lanes would estimate, in spectral transport as in grey.
    xyz: Vec3A,
    /// Seen through index-matched boundaries (`xyz` is then unused).
    attenuated: Option<Attenuated>,
}

/// A point light seen through index-matched boundaries, with media between.
#[derive(Clone, Debug)]
struct Attenuated {
    light: usize,
    /// Φ·p(ω)/(d² A_pix cos³θ_c), as `PointView::xyz` before the light's colour.
    value: f64,
    /// (medium, length) of each stretch in a medium: their transmittance depends on λ, so each
    /// sample applies it at its own wavelengths.
    stretches: Vec<(u32, f64)>,
}

/// The point lights that project into the image with a clear line to the camera, once per run:
/// nothing in between, or only index-matched boundaries (`through`). Like the light tracer's
/// emission splat: with nothing in between no medium attenuates the segment, since the camera is
/// outside every dielectric.
fn point_views(scene: &Scene, emitter: &Emitter, camera: &CameraModel, through: Option<Through>) -> Vec<PointView> {
    let geo = &scene.geometry;
    (0..emitter.light_count())
        .filter(|&l| emitter.is_point(l))
        .filter_map(|light| {
            let lp = emitter.sample_point(geo, light, [0.0; 3]);
            let proj = camera.project(lp.point)?;
            // Zero behind a directional lamp's lobe and for a collimated beam.
            let p_dir = emitter.direction_pdf(light, lp.axis, proj.to_camera) as f64;
            let value = emitter.power_w(light) * p_dir * proj.importance as f64;
            if !(value > 0.0 && value.is_finite()) {
                return None;
            }
            let (end, cam) = (lp.end(), RayEnd::free(camera.position));
            let xyz = emitter.grey_xyz(light) * value as f32;
            if geo.visible(end, cam) {
                return Some(PointView { pixel: proj.pixel, xyz, attenuated: None });
            }
            let mut stretches = Vec::new();
            let medium = emitter.medium_at(light, lp.prim);
            let seen = walk_stretches(geo, through?, end, cam, medium, |m, len| stretches.extend(m.map(|m| (m, len))));
            let attenuated = Some(Attenuated { light, value, stretches });
            seen.then_some(PointView { pixel: proj.pixel, xyz, attenuated })
        })
        .collect()
}

/// Walks the stretch `Geometry::visible` tests between `a` and `b` through passable boundaries
/// (`Through::walk`), starting in dielectric `medium` on `a`'s side, reporting each stretch as
/// `stretch(medium, length)` with the trimmed ends (offsets, 10⁻⁵ of the length each) added to
/// the first and the last. False if anything else lies in between.
#[inline]
fn walk_stretches(
    geo: &Geometry,
    through: Through,
    a: RayEnd,
    b: RayEnd,
    medium: Option<u32>,
    mut stretch: impl FnMut(Option<u32>, f64),
) -> bool {
    let Some((from, dir, len)) = shadow_segment(a, b) else { return false };
    let head = (from - a.p).length();
    let tail = ((b.p - a.p).length() - head - len).max(0.0);
    let mut first = true;
    let mut last = medium;
    let inner = |m: Option<u32>, len: f32| {
        let len = if first { head + len } else { len };
        stretch(m, len as f64);
        (first, last) = (false, m);
    };
    if !through.walk(geo, from, dir, from + dir * len, (a.prim, b.prim), medium, inner) {
        return false;
    }
    stretch(last, tail as f64);
    true
}

/// What a camera or light subpath does at a surface it arrived at (`ImageKernel::at_boundary`).
enum Onward {
    /// A vertex: the surface scatters.
    Vertex,
    /// An index-matched boundary: straight on from `origin`, just beyond it, in `medium`.
    Pass { origin: Vec3A, medium: Option<u32> },
    /// More than `passage::MAX_CROSSINGS` boundaries in a row: the subpath ends.
    End,
}

/// A surface a camera or light subpath arrived at.
struct Arrival<'m> {
    surface: u32,
    material: &'m Material,
    n: Vec3A,
    is_dielectric: bool,
}

impl<'a> ImageKernel<'a> {
    pub fn new(
        scene: &'a Scene,
        emitter: &'a Emitter,
        camera: &'a CameraModel,
        integrator: Integrator,
        prepared: &'a [Prepared],
    ) -> Self {
        let range = scene.simulation.wavelength_range_nm;
        let materials: Vec<&Material> = (0..scene.surfaces.len()).map(|s| scene.material_of(s)).collect();
        let dispersive: Vec<bool> = materials
            .iter()
            .map(|m| match m {
                Material::Dielectric { ior, outside_ior, .. } => {
                    ior.constant_over(range).is_none() || outside_ior.constant_over(range).is_none()
                }
                _ => false,
            })
            .collect();
        let fluorescent = scene.effects.fluorescence;
        let lane_mis = !fluorescent && !dispersive.iter().any(|&d| d);
        let clear = (integrator == Integrator::Bdpt).then(|| ClearView::new(&scene.geometry, camera)).flatten();
        // An emitting boundary stays a vertex: its emission is met there.
        let passable: Vec<bool> =
            materials.iter().zip(&scene.surfaces).map(|(m, s)| is_passable(m) && s.light.is_none()).collect();
        let see_through = passable.iter().any(|&p| p);
        let through = see_through.then_some(Through {
            passable: &passable,
            inside: &scene.surface_inside,
            outside: &scene.surface_outside,
        });
        let point_views =
            if integrator == Integrator::Path { point_views(scene, emitter, camera, through) } else { Vec::new() };
        ImageKernel {
            clear,
            scene,
            emitter,
            camera,
            integrator,
            point_views,
            prepared,
            materials,
            surface_light: scene.surfaces.iter().map(|s| s.light).collect(),
            dispersive,
            fluorescent,
            lane_mis,
            max_scatterings: scene.simulation.max_bounces as usize + 1,
            passable,
            see_through,
        }
    }

    /// The passable boundaries, if the scene has any (`passage`).
    #[inline]
    fn through(&self) -> Option<Through<'_>> {
        self.see_through.then_some(Through {
            passable: &self.passable,
            inside: &self.scene.surface_inside,
            outside: &self.scene.surface_outside,
        })
    }

    /// Through the passable boundaries between `a` and `b` (the stretch `Geometry::visible`
    /// tests), starting in dielectric `medium` on `a`'s side: the transmittance per lane at `wl`,
    /// each stretch in its own medium, or None if anything else lies in between.
    #[inline]
    fn transmittance_through<const SPECTRAL: bool>(
        &self,
        through: Through,
        a: RayEnd,
        b: RayEnd,
        medium: Option<u32>,
        wl: &Wavelengths,
    ) -> Option<Lanes> {
        let mut t = Lanes::ONE;
        let attenuate = |m: Option<u32>, len: f64| {
            if let Some(tm) = m.and_then(|m| self.medium_transmittance::<SPECTRAL>(m, len, wl)) {
                t *= tm;
            }
        };
        walk_stretches(self.geo(), through, a, b, medium, attenuate).then_some(t)
    }

    fn geo(&self) -> &Geometry {
        &self.scene.geometry
    }

    /// Traces the camera samples of transport batch `batch` (`count` of them, the same indices
    /// as its photons) with the batch's own random stream, compiled for the scene's effect set.
    /// Rays, visibility rays and splats are added to `counters`. Ends early, to be discarded,
    /// once `cancel` is set.
    pub fn trace_batch(
        &self,
        batch: u64,
        count: u64,
        counters: &mut Counters,
        cancel: Option<&std::sync::atomic::AtomicBool>,
    ) -> FilmBatch {
        let fx = &self.scene.effects;
        match (fx.spectral, fx.refraction) {
            (true, true) => self.trace::<true, true>(batch, count, counters, cancel),
            (true, false) => self.trace::<true, false>(batch, count, counters, cancel),
            (false, true) => self.trace::<false, true>(batch, count, counters, cancel),
            (false, false) => self.trace::<false, false>(batch, count, counters, cancel),
        }
    }

    fn trace<const SPECTRAL: bool, const DIELECTRIC: bool>(
        &self,
        batch: u64,
        count: u64,
        counters: &mut Counters,
        cancel: Option<&std::sync::atomic::AtomicBool>,
    ) -> FilmBatch {
        // Each integrator its own stream, so that at one seed the three images are independent
        // estimates (the tests' z-scores compare them as such).
        let stream = match self.integrator {
            Integrator::Path => PATH_STREAM,
            _ => BDPT_STREAM,
        };
        let mut s = Sampler::for_stream(self.scene.simulation.seed, stream, batch);
        let first = batch * crate::integrators::batch::BATCH_PHOTONS;
        let pixels = self.camera.pixels() as u64;
        let mut film = FilmBatch::default();
        film.first_sample = first;
        film.samples.reserve(count as usize);
        let mut bdpt = bdpt::Scratch::default();
        for i in 0..count {
            if crate::integrators::batch::cancelled(cancel, i) {
                break;
            }
            let pixel = ((first + i) % pixels) as usize;
            film.photon = i as u32;
            let xyz = match self.integrator {
                Integrator::Path => self.path_sample::<SPECTRAL, DIELECTRIC>(pixel, &mut s, counters),
                _ => self.bdpt_sample::<SPECTRAL, DIELECTRIC>(pixel, &mut s, counters, &mut bdpt, &mut film),
            };
            // A NaN or infinite sample would poison its pixel for good: count it as black.
            let xyz = if xyz.is_finite() { xyz } else { Vec3A::ZERO };
            film.samples.push([xyz.x, xyz.y, xyz.z]);
        }
        film
    }

    /// Whether a subpath along `dir` makes a vertex at `hit` (on `surface`, normal `n`, hit point
    /// `p` with error `err`) or passes it as an index-matched boundary (`passage`): no vertex, so
    /// connections pass it too and densities are measured between the vertices either side.
    /// `crossings` counts the boundaries passed since the last vertex.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    fn at_boundary<const DIELECTRIC: bool>(
        &self,
        hit: &crate::geometry::Hit,
        surface: u32,
        n: Vec3A,
        (p, err): (Vec3A, Vec3A),
        dir: Vec3A,
        crossings: &mut usize,
    ) -> Onward {
        if !(DIELECTRIC && self.passable[surface as usize]) {
            *crossings = 0;
            return Onward::Vertex;
        }
        *crossings += 1;
        if *crossings > crate::integrators::passage::MAX_CROSSINGS {
            return Onward::End;
        }
        let (inside, outside) = (&self.scene.surface_inside, &self.scene.surface_outside);
        let medium = crate::media::after_crossing(surface, n, dir, inside, outside);
        Onward::Pass { origin: self.geo().spawn_from(p, err, hit.prim, hit.b, dir), medium }
    }

    /// The surface `hit` lies on (what the segment to it cost is `fly`'s).
    #[inline]
    fn arrive<const DIELECTRIC: bool>(&self, hit: &crate::geometry::Hit) -> Arrival<'_> {
        let geo = self.geo();
        let prim = hit.prim as usize;
        let surface = geo.surface_of(prim);
        let material = self.materials[surface as usize];
        let n = geo.normal(prim);
        let is_dielectric = DIELECTRIC && matches!(material, Material::Dielectric { .. });
        Arrival { surface, material, n, is_dielectric }
    }
}
