//! Unidirectional path tracing from the camera (Kajiya 1986) with next-event estimation: at each
//! diffuse vertex one light point is sampled (light by power, point uniform by area) and
//! connected, and a path that hits an emitter after a diffuse bounce counts its emission too.
//! The two estimates of the same light are combined by multiple importance sampling with Veach's
//! power heuristic, w_a = p_a²/(p_a² + p_b²) (Veach 1997, §9.2.4), both pdfs per solid angle.
//! After the camera or a specular bounce (mirror, glass) only the hit counts: no light sample can
//! pass a delta BSDF. An index-matched boundary is no bounce: paths and light samples pass it
//! straight (`passage`), so a medium behind one is lit by light samples. Russian roulette on the
//! albedo (see `scatter`) ends paths. A point light in view, which no camera ray can hit, is
//! connected to the camera directly: its pixel's samples each carry its exact share, the light
//! tracer's emission splat (`PointView`).

use glam::Vec3A;

use super::medium::Event;
use super::{scatter, Arrival, ImageKernel, LaneXyz, Lanes, Onward, Wavelengths, LANES};
use crate::bsdf::{Bsdf, Mode};
use crate::detectors::tally::Counters;
use crate::geometry::{RayEnd, NO_PRIM};
use crate::media;
use crate::sampling::Sampler;

/// Power heuristic weight of technique a against b.
#[inline]
fn power_heuristic(a: f64, b: f64) -> f64 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

impl ImageKernel<'_> {
    /// One path-traced sample of `pixel`: its XYZ radiance estimate.
    pub(super) fn path_sample<const SPECTRAL: bool, const DIELECTRIC: bool>(
        &self,
        pixel: usize,
        s: &mut Sampler,
        counters: &mut Counters,
    ) -> Vec3A {
        let range = self.scene.simulation.wavelength_range_nm;
        let mut wl = Wavelengths::sample::<SPECTRAL>(self.emitter, range, s.uniform());
        let geo = self.geo();
        let mut acc = LaneXyz::default();
        // A point light the camera sees (a delta in position: no ray hits it) gives every sample
        // of its pixel its exact part I(ω)/(d² A_pix cos³θ_c) of the pixel's value, integrated
        // over λ. Without point lights in view the list is empty.
        for v in self.point_views.iter().filter(|v| v.pixel == pixel) {
            match &v.attenuated {
                None => acc.add_exact(v.xyz),
                Some(a) => {
                    let mut t = self.emitter.share_lanes::<SPECTRAL, LANES>(a.light, &wl.lambda) * a.value;
                    for &(m, len) in &a.stretches {
                        if let Some(tm) = self.medium_transmittance::<SPECTRAL>(m, len, &wl) {
                            t *= tm;
                        }
                    }
                    acc.add::<SPECTRAL>(self.emitter, &wl, a.light, t);
                }
            }
        }
        let mut origin = self.camera.position;
        let mut dir = self.camera.ray_direction(pixel, s.uniform_f32(), s.uniform_f32());
        let mut skip = NO_PRIM;
        let mut beta = Lanes::ONE;
        // Each lane's path density over lane 0's (`medium`); contributions are divided by its mean.
        let mut lane_pdf = Lanes::ONE;
        if self.fluorescent {
            wl.terminate_secondary();
        }
        // Solid-angle pdf of the last diffuse bounce; None after the camera or a specular bounce.
        let mut bsdf_pdf: Option<f64> = None;
        // Distance from that vertex to the ray's origin, and the passable boundaries crossed since.
        let (mut travelled, mut crossings) = (0.0f64, 0);
        let mut medium: Option<u32> = None;
        let mut scatterings = 0usize;
        loop {
            counters.rays += 1;
            let next = geo.intersect_leaving(origin, dir, f32::INFINITY, skip);
            if DIELECTRIC {
                let t_hit = next.map_or(f64::INFINITY, |h| h.t as f64);
                if let Some((t, c)) =
                    self.fly::<SPECTRAL>(medium, t_hit, &mut wl, &mut beta, &mut lane_pdf, s, counters)
                {
                    // A collision in the medium: scattering or re-emission, next-event estimation
                    // with the event's phase function, then a direction from it.
                    if scatterings == self.max_scatterings {
                        break;
                    }
                    scatterings += 1;
                    let x = origin + dir * t as f32;
                    let Some(event) = self.collide::<SPECTRAL>(&c, Mode::Radiance, &mut wl, &mut beta, s) else {
                        break;
                    };
                    let scatterer = Scatterer::Medium(event);
                    let vertex = RayEnd::free(x);
                    self.next_event::<SPECTRAL>(
                        scatterer,
                        vertex,
                        (medium, None),
                        -dir,
                        beta,
                        lane_pdf,
                        &wl,
                        &mut acc,
                        s,
                        counters,
                    );
                    counters.phase_samples += 1;
                    let new_dir = media::phase::sample(event.phase(), dir, s.uniform(), s.uniform());
                    bsdf_pdf = Some(event.phase_pdf(-dir, new_dir));
                    (travelled, crossings) = (0.0, 0);
                    origin = x;
                    dir = new_dir;
                    skip = NO_PRIM;
                    continue;
                }
            }
            let Some(hit) = next else { break };
            let Arrival { surface, material, n, is_dielectric } = self.arrive::<DIELECTRIC>(&hit);

            // Emission seen along the ray, MIS-weighted against next-event estimation.
            if let Some(light) = self.surface_light[surface as usize] {
                let le = self.emitter.radiance::<SPECTRAL, LANES>(light, n, -dir, &wl.lambda);
                if !le.is_zero() {
                    let weight = match bsdf_pdf {
                        None => 1.0,
                        Some(p_bsdf) => {
                            // Light sampling's density of the same direction: pick · (1/A) · t²/cosθ_l.
                            let cos_l = (-dir).dot(n) as f64;
                            let t = travelled + hit.t as f64;
                            let p_light =
                                self.emitter.pick_pdf(light) * self.emitter.position_pdf(light) * t * t / cos_l;
                            power_heuristic(p_bsdf, p_light)
                        }
                    };
                    acc.add::<SPECTRAL>(self.emitter, &wl, light, beta * le * (weight / lane_pdf.mean()));
                }
            }
            let (p, err) = geo.hit_point(&hit);
            match self.at_boundary::<DIELECTRIC>(&hit, surface, n, (p, err), dir, &mut crossings) {
                Onward::Vertex => {}
                Onward::Pass { origin: o, medium: m } => {
                    // Nothing scattered (no bounce is counted), so the last vertex's direction
                    // density stands, as light samples from it see through the boundary.
                    travelled += hit.t as f64;
                    (origin, medium, skip) = (o, m, hit.prim);
                    continue;
                }
                Onward::End => break,
            }
            if scatterings == self.max_scatterings {
                break;
            }
            scatterings += 1;

            let tangent = || geo.tangent(hit.prim as usize);
            let ns = geo.shading_normal(hit.prim as usize, hit.b);
            let bsdf =
                Bsdf::new::<SPECTRAL>(material, &self.prepared[surface as usize], &wl.lambda, ns, tangent).shaded(n);
            if bsdf.is_absorber() {
                break;
            }
            if self.dispersive[surface as usize] {
                wl.terminate_secondary();
            }
            if bsdf.is_connectible() {
                let vertex = RayEnd { p, err, n, prim: hit.prim };
                // Through a rough dielectric the light may lie on the other side, in the other medium.
                let crossing = is_dielectric.then_some(surface);
                let media = (medium, crossing);
                let scatterer = Scatterer::Surface(&bsdf);
                self.next_event::<SPECTRAL>(scatterer, vertex, media, -dir, beta, lane_pdf, &wl, &mut acc, s, counters);
            }
            let Some(sampled) = scatter(&bsdf, -dir, Mode::Radiance, &mut beta, s) else { break };
            bsdf_pdf = (!sampled.lobe.is_delta()).then_some(sampled.pdf);
            travelled = 0.0;
            let new_dir = sampled.wi;
            if is_dielectric {
                medium =
                    media::after_crossing(surface, n, new_dir, &self.scene.surface_inside, &self.scene.surface_outside);
            }
            origin = geo.spawn_from(p, err, hit.prim, hit.b, new_dir);
            dir = new_dir;
            skip = hit.prim;
        }
        acc.resolve::<SPECTRAL>(&wl)
    }

    /// Next-event estimation from a diffuse surface vertex or a medium collision at `p`: one
    /// light point, its emission toward `p` times the scatterer's factor (f·|cosθ| at a surface,
    /// the phase function in a medium), through the medium between, over the solid-angle density
    /// of having sampled it, MIS-weighted. For a point or area light alike the ratio
    /// Le·cosθ_l/(d² · pick · pdf_position) reduces to Φ_λ · p_dir(ω)/(pick · d²), with Φ_λ the
    /// light's power per nm and p_dir its direction pdf.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn next_event<const SPECTRAL: bool>(
        &self,
        scatterer: Scatterer,
        vertex: RayEnd,
        (medium, crossing): (Option<u32>, Option<u32>),
        wo: Vec3A,
        beta: Lanes,
        lane_pdf: Lanes,
        wl: &Wavelengths,
        acc: &mut LaneXyz,
        s: &mut Sampler,
        counters: &mut Counters,
    ) {
        let RayEnd { p, n, .. } = vertex;
        let (light, pick) = self.emitter.pick_light(s.uniform());
        let lp = self.emitter.sample_point(self.geo(), light, [s.uniform(), s.uniform(), s.uniform()]);
        if self.emitter.is_collimated(light) {
            return;
        }
        let to = lp.point - p;
        let d2 = to.length_squared() as f64;
        let wi = to.normalize();
        let p_dir = self.emitter.direction_pdf(light, lp.axis, -wi) as f64;
        if !(p_dir > 0.0 && d2 > 0.0) {
            return;
        }
        let (f, cos_x, pdf) = match scatterer {
            Scatterer::Surface(bsdf) => {
                (bsdf.f(wo, wi, Mode::Radiance).value(), wi.dot(n).abs() as f64, bsdf.pdf(wo, wi, Mode::Radiance))
            }
            Scatterer::Medium(event) => {
                let phase = event.phase_pdf(wo, wi);
                (Lanes::splat(phase), 1.0, phase)
            }
        };
        if f.is_zero() {
            return;
        }
        let weight = if self.emitter.is_point(light) {
            1.0
        } else {
            let cos_l = (-wi).dot(lp.normal) as f64;
            let p_light = pick * self.emitter.position_pdf(light) * d2 / cos_l;
            power_heuristic(p_light, pdf)
        };
        counters.shadow_rays += 1;
        // The segment starts in the medium on `wi`'s side: the vertex's own, or beyond the
        // dielectric boundary it sits on (`crossing`).
        let medium = crossing.map_or(medium, |surface| {
            media::after_crossing(surface, n, wi, &self.scene.surface_inside, &self.scene.surface_outside)
        });
        let transmittance = match self.through() {
            // A visible light lies in that medium: its transmittance over the segment.
            None => {
                if !self.geo().visible(vertex, lp.end()) {
                    return;
                }
                medium.and_then(|m| self.medium_transmittance::<SPECTRAL>(m, d2.sqrt(), wl)).unwrap_or(Lanes::ONE)
            }
            // Through index-matched boundaries, each stretch in its own medium.
            Some(through) => {
                let Some(t) = self.transmittance_through::<SPECTRAL>(through, vertex, lp.end(), medium, wl) else {
                    return;
                };
                t
            }
        };
        let radiance_term = self.emitter.share_lanes::<SPECTRAL, LANES>(light, &wl.lambda)
            * (self.emitter.power_w(light) * p_dir / (pick * d2) * cos_x * weight / lane_pdf.mean());
        acc.add::<SPECTRAL>(self.emitter, wl, light, beta * f * radiance_term * transmittance);
    }
}

/// What scatters at a path vertex: a surface's BSDF or a medium collision's event.
#[derive(Clone, Copy)]
enum Scatterer<'b, 'a> {
    Surface(&'b Bsdf<'a>),
    Medium(Event),
}
