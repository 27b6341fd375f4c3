//! The photon loop: first hit → tally the arrival → absorb or scatter → next ray, until the
//! photon is absorbed, escapes, or reaches the bounce cap. Generic over the effects a scene
//! calls for: a grey scene never draws a wavelength, a run without a film never splats.

use glam::Vec3A;

use crate::emitter::Emitter;
use crate::film::{CameraModel, FilmBatch};
use crate::geometry::{offset_ray_origin, Geometry};
use crate::material::{interact, Interaction};
use crate::sampling::Sampler;
use crate::scene::{Material, Scene};
use crate::tally::{HistoryScores, Tallies};

/// What a batch needs besides the scene: the emitter, and the camera when the film is on.
pub struct Kernel<'a> {
    pub scene: &'a Scene,
    pub emitter: &'a Emitter,
    pub camera: Option<&'a CameraModel>,
}

impl Kernel<'_> {
    /// Traces one batch, dispatching once to the kernel specialised for the scene's effects.
    pub fn trace_batch(&self, batch: u64, count: u64) -> (Tallies, Option<FilmBatch>) {
        let mut film = self.camera.map(|_| FilmBatch::default());
        let tallies = match (self.scene.effects.spectral, film.as_mut()) {
            (false, None) => self.trace::<false, false>(batch, count, None),
            (true, None) => self.trace::<true, false>(batch, count, None),
            (false, Some(f)) => self.trace::<false, true>(batch, count, Some(f)),
            (true, Some(f)) => self.trace::<true, true>(batch, count, Some(f)),
        };
        (tallies, film)
    }

    /// Traces photons of one batch with the batch's own random stream. Score buffers are
    /// allocated once per batch; nothing inside the photon loop allocates.
    fn trace<const SPECTRAL: bool, const CAMERA: bool>(
        &self,
        batch: u64,
        count: u64,
        mut film: Option<&mut FilmBatch>,
    ) -> Tallies {
        let scene = self.scene;
        let geo = &scene.geometry;
        let n_surfaces = scene.surfaces.len();
        let max_bounces = scene.simulation.max_bounces;
        let materials: Vec<&Material> = (0..n_surfaces).map(|s| scene.material_of(s)).collect();
        let mut s = Sampler::for_batch(scene.simulation.seed, batch);
        let mut out = Tallies::new(n_surfaces);
        let mut incident = HistoryScores::new(n_surfaces);
        let mut absorbed = HistoryScores::new(n_surfaces);

        for photon in 0..count as u32 {
            let birth = self.emitter.emit::<SPECTRAL>(geo, &mut s);
            if let Some(f) = film.as_deref_mut() {
                f.photon = photon;
            }
            let lambda = birth.lambda_nm;
            let weight = 1.0;
            if CAMERA {
                if let (Some(cam), Some(film)) = (self.camera, film.as_deref_mut()) {
                    splat(
                        cam,
                        geo,
                        film,
                        birth.point,
                        birth.point_err,
                        birth.normal,
                        birth.prim,
                        birth.xyz * weight as f32,
                        |w| self.emitter.direction_pdf(birth.light, birth.axis, w),
                    );
                }
            }
            let mut origin = birth.origin;
            let mut dir = birth.dir;
            let mut skip = birth.prim;
            let mut scatterings = 0u32;
            let mut medium: Option<u32> = None;
            loop {
                let Some(hit) = geo.intersect(origin, dir, f32::INFINITY, skip) else {
                    out.escaped += weight;
                    break;
                };
                let prim = hit.prim as usize;
                let surface = geo.surface[prim];
                let material = materials[surface as usize];
                let n = geo.normals[prim];
                // Beer–Lambert: a photon crossing an absorbing medium over distance t survives with
                // probability exp(−α t); otherwise the medium absorbs it (tallied to its surface).
                // The medium is the dielectric the photon last refracted into, or, for a photon born
                // inside one, the dielectric it now reaches from inside.
                let is_dielectric = matches!(material, Material::Dielectric { .. });
                let segment_medium = medium.or((is_dielectric && dir.dot(n) > 0.0).then_some(surface));
                if let Some(m) = segment_medium {
                    if let Material::Dielectric { absorption_per_m: Some(alpha), .. } = materials[m as usize] {
                        if s.uniform() >= (-alpha.eval(lambda) * hit.t as f64).exp() {
                            absorbed.add(m, weight);
                            break;
                        }
                    }
                }
                incident.add(surface, weight);
                let (p, err) = geo.hit_point(&hit);
                if CAMERA {
                    if let (Some(cam), Some(film), Material::Lambertian { reflectance, transmittance }) =
                        (self.camera, film.as_deref_mut(), material)
                    {
                        // f = ρ/π toward the side the photon came from, τ/π through; times |cosθ_x|.
                        let n_in = if dir.dot(n) < 0.0 { n } else { -n };
                        splat(cam, geo, film, p, err, n, hit.prim, birth.xyz * weight as f32, |w| {
                            let cos = w.dot(n_in);
                            let f = if cos > 0.0 { reflectance.eval(lambda) } else { transmittance.eval(lambda) };
                            f as f32 * std::f32::consts::FRAC_1_PI * cos.abs()
                        });
                    }
                }
                match interact(material, lambda, dir, n, &mut s) {
                    Interaction::Absorbed => {
                        absorbed.add(surface, weight);
                        break;
                    }
                    Interaction::Scattered(new_dir) => {
                        if scatterings == max_bounces {
                            out.truncated += weight;
                            break;
                        }
                        scatterings += 1;
                        if is_dielectric {
                            // Inside is the side opposite the normal.
                            medium = (new_dir.dot(n) < 0.0).then_some(surface);
                        }
                        origin = offset_ray_origin(p, err, n, new_dir);
                        dir = new_dir;
                        skip = hit.prim;
                    }
                }
            }
            out.scatterings += scatterings as u64;
            out.scatterings_sq += (scatterings as u64).pow(2);
            incident.flush(&mut out.incident);
            absorbed.flush(&mut out.absorbed);
        }
        out.photons = count;
        out
    }
}

/// Connects a photon vertex at `p` (error bound `err`, normal `n`, zero for a point light) to the
/// camera and adds `colour · value(ω) · importance` to its pixel when nothing is in between.
/// `value(ω)` is the emission pdf or BSDF·|cos| toward the camera (see `film` for the estimator).
#[inline]
#[allow(clippy::too_many_arguments)]
fn splat(
    cam: &CameraModel,
    geo: &Geometry,
    film: &mut FilmBatch,
    p: Vec3A,
    err: Vec3A,
    n: Vec3A,
    prim: u32,
    colour: Vec3A,
    value: impl Fn(Vec3A) -> f32,
) {
    let Some(proj) = cam.project(p) else { return };
    let v = value(proj.to_camera);
    if !(v > 0.0) {
        return;
    }
    let origin = if n == Vec3A::ZERO { p } else { offset_ray_origin(p, err, n, proj.to_camera) };
    let distance = (cam.position - origin).length();
    if geo.unoccluded(origin, proj.to_camera, distance, prim) {
        film.add(proj.pixel, colour * (v * proj.importance));
    }
}
