//! The photon loop: first hit → tally the arrival → absorb or scatter → next ray, until the
//! photon is absorbed, escapes, or reaches the bounce cap. Generic over the effects a scene
//! calls for, so a grey scene never draws a wavelength.

use crate::emitter::Emitter;
use crate::geometry::offset_ray_origin;
use crate::material::{interact, Interaction};
use crate::sampling::Sampler;
use crate::scene::{Material, Scene};
use crate::tally::{HistoryScores, Tallies};

/// Traces photons `first .. first + count` of one batch with the batch's own random stream.
/// Allocates its score buffers once per batch; nothing inside the photon loop allocates.
pub fn trace_batch<const SPECTRAL: bool>(
    scene: &Scene,
    emitter: &Emitter,
    seed: u64,
    batch: u64,
    count: u64,
) -> Tallies {
    let geo = &scene.geometry;
    let n_surfaces = scene.surfaces.len();
    let max_bounces = scene.simulation.max_bounces;
    let materials: Vec<&Material> = (0..n_surfaces).map(|s| scene.material_of(s)).collect();
    let mut s = Sampler::for_batch(seed, batch);
    let mut out = Tallies::new(n_surfaces);
    let mut incident = HistoryScores::new(n_surfaces);
    let mut absorbed = HistoryScores::new(n_surfaces);

    for _ in 0..count {
        let birth = emitter.emit::<SPECTRAL>(geo, &mut s);
        let lambda = birth.lambda_nm;
        let mut origin = birth.origin;
        let mut dir = birth.dir;
        let mut skip = birth.prim;
        let mut scatterings = 0u32;
        let weight = 1.0;
        loop {
            let Some(hit) = geo.intersect(origin, dir, f32::INFINITY, skip) else {
                out.escaped += weight;
                break;
            };
            let prim = hit.prim as usize;
            let surface = geo.surface[prim];
            let material = materials[surface as usize];
            let n = geo.normals[prim];
            // Beer–Lambert: a photon reaching a dielectric from inside crossed its medium over
            // distance t and survived with probability exp(−α t); otherwise the medium absorbed it.
            if let Material::Dielectric { absorption_per_m: Some(alpha), .. } = material {
                if dir.dot(n) > 0.0 && s.uniform() >= (-alpha.eval(lambda) * hit.t as f64).exp() {
                    absorbed.add(surface, weight);
                    break;
                }
            }
            incident.add(surface, weight);
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
                    let (p, err) = geo.hit_point(&hit);
                    origin = offset_ray_origin(p, err, n, new_dir);
                    dir = new_dir;
                    skip = hit.prim;
                }
            }
        }
        out.scatterings += scatterings as u64;
        incident.flush(&mut out.incident);
        absorbed.flush(&mut out.absorbed);
    }
    out.photons = count;
    out
}

/// Dispatches once per batch to the kernel specialised for the scene's effects.
pub fn trace_batch_for(scene: &Scene, emitter: &Emitter, seed: u64, batch: u64, count: u64) -> Tallies {
    if scene.effects.spectral {
        trace_batch::<true>(scene, emitter, seed, batch, count)
    } else {
        trace_batch::<false>(scene, emitter, seed, batch, count)
    }
}
