//! Bidirectional path tracing (Veach & Guibas 1995; Veach 1997, ch. 10), laid out as in pbrt-v3
//! §16.3. Each sample traces a light subpath y₀…y_{nL−1} (y₀ on a light chosen by power) and a
//! camera subpath z₀…z_{nC−1} (z₀ the pinhole). Every pair (s, t) of s light and t camera
//! vertices with s + t − 2 ≤ the scattering cap is a strategy for the path y₀…y_{s−1} z_{t−1}…z₀:
//! - s = 0: the camera subpath itself ends on an emitter;
//! - t = 1: y_{s−1} is connected to the camera and splatted where it projects (the light tracer);
//! - otherwise y_{s−1} and z_{t−1} are joined by a visibility ray (s = 1: next-event estimation,
//!   here with y₀ itself rather than a fresh light sample).
//!
//! Every strategy is weighted by the balance heuristic, w_s = p_s / Σᵢ pᵢ over the strategies i
//! that could have sampled the same path (Veach 1997, §9.2.2; pbrt-v3 uses the same), computed by
//! pbrt's ratio walk over each vertex's area densities: pdf_fwd as its own subpath sampled it, and
//! pdf_rev as the opposite subpath would have. Delta vertices (mirror, glass, a collimated light's
//! direction, a point light's position) cannot be connected, and strategies needing that are left
//! out of the sum. Index-matched boundaries make no vertex: subpaths and connections pass them
//! straight (`passage`), so each vertex's densities are measured from the last real one and a
//! medium behind such a boundary is reached by every strategy. Roulette probabilities are left
//! out of the densities: any weights that sum to one over the strategies keep the estimate
//! unbiased.

use glam::Vec3A;

use super::medium::Event;
use super::{scatter, Arrival, ImageKernel, LaneXyz, Lanes, Onward, Wavelengths, LANES};
use crate::bsdf::{Bsdf, Mode};
use crate::detectors::film::FilmBatch;
use crate::detectors::tally::Counters;
use crate::geometry::{RayEnd, NO_PRIM};
use crate::integrators::clear_view::Sight;
use crate::media;
use crate::media::fluorescence;
use crate::sampling::Sampler;
use crate::scene::Phase;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Camera,
    Light(usize),
    Surface,
    /// A collision in a medium: a free point, no normal, no cosines.
    Medium,
}

#[derive(Clone, Copy, Debug)]
struct Vertex<'a> {
    kind: Kind,
    p: Vec3A,
    err: Vec3A,
    /// Unit geometric normal; zero for the camera and point lights.
    n: Vec3A,
    prim: u32,
    surface: u32,
    /// Unit direction toward the previous vertex of its own subpath.
    wo: Vec3A,
    beta: Lanes,
    pdf_fwd: f64,
    pdf_rev: f64,
    delta: bool,
    /// The BSDF of a connectible vertex (None for specular and absorbing ones).
    bsdf: Option<Bsdf<'a>>,
    /// A light vertex's emission axis.
    axis: Vec3A,
    /// The absorbing or clear dielectric a surface vertex was reached through (None outside any).
    medium: Option<u32>,
    /// A surface vertex on a dielectric boundary: the media on its two sides differ.
    on_dielectric: bool,
    /// A medium vertex's phase function and μs(λ) per lane (its factor when connected).
    phase: Phase,
    mu_s: Lanes,
    /// Its own subpath went on from it by re-emission (isotropic, at a new wavelength), and did
    /// so onto `reemit`'s point mass, which only the light-tracing strategy can reach.
    reemitted: bool,
    singular: bool,
    /// The wavelengths the subpath arrived with, and its lanes' path densities (`medium`).
    lambda: [f64; LANES],
    lane_pdf: Lanes,
}

impl Vertex<'_> {
    fn end(&self) -> RayEnd {
        RayEnd { p: self.p, err: self.err, n: self.n, prim: self.prim }
    }

    fn endpoint(kind: Kind, p: Vec3A, err: Vec3A, n: Vec3A, prim: u32, beta: Lanes, pdf_fwd: f64) -> Self {
        Vertex {
            kind,
            p,
            err,
            n,
            prim,
            surface: u32::MAX,
            wo: Vec3A::ZERO,
            beta,
            pdf_fwd,
            pdf_rev: 0.0,
            delta: false,
            bsdf: None,
            axis: n,
            medium: None,
            on_dielectric: false,
            phase: Phase::Isotropic,
            mu_s: Lanes::ZERO,
            reemitted: false,
            singular: false,
            lambda: [f64::NAN; LANES],
            lane_pdf: Lanes::ONE,
        }
    }
}

/// Buffers one batch reuses for every sample.
#[derive(Default)]
pub struct Scratch<'a> {
    light: Vec<Vertex<'a>>,
    camera: Vec<Vertex<'a>>,
    splats: Vec<(usize, LaneXyz)>,
}

/// Turns a solid-angle density at `from` toward vertex `to` into an area density at `to`:
/// p_A = p_ω · |cosθ_to| / d² (no cosine at the camera or a point light).
#[inline]
fn to_area(pdf: f64, from: Vec3A, to: &Vertex) -> f64 {
    let w = to.p - from;
    let d2 = w.length_squared() as f64;
    if !(d2 > 0.0) {
        return 0.0;
    }
    let cos = if to.n == Vec3A::ZERO { 1.0 } else { (to.n.dot(w).abs() as f64) / d2.sqrt() };
    pdf * cos / d2
}

/// Whether a subpath re-emitted before reaching its vertex k − 1 (at vertices 1..k − 2, the
/// ones whose continuation the strategy keeps), so that it arrives there at a new wavelength.
#[inline]
fn reemitted_before(path: &[Vertex], k: usize) -> bool {
    path[..k.saturating_sub(1)].iter().any(|v| v.reemitted)
}

/// 0 → 1, so a delta vertex's zero density drops out of the ratios (pbrt's remap0).
#[inline]
fn remap0(f: f64) -> f64 {
    if f != 0.0 {
        f
    } else {
        1.0
    }
}

impl ImageKernel<'_> {
    /// One BDPT sample of `pixel`: its own-pixel XYZ; t = 1 splats go to `film`.
    pub(super) fn bdpt_sample<'s, const SPECTRAL: bool, const DIELECTRIC: bool>(
        &'s self,
        pixel: usize,
        s: &mut Sampler,
        counters: &mut Counters,
        scratch: &mut Scratch<'s>,
        film: &mut FilmBatch,
    ) -> Vec3A {
        let range = self.scene.simulation.wavelength_range_nm;
        let mut wl = Wavelengths::sample::<SPECTRAL>(self.emitter, range, s.uniform());
        if self.fluorescent {
            wl.terminate_secondary();
        }
        let Scratch { light: lv, camera: cv, splats } = scratch;
        // Each subpath carries its own wavelengths: re-emission changes them on one side only.
        let (mut wl_light, mut wl_camera) = (wl, wl);
        let light = self.light_subpath::<SPECTRAL, DIELECTRIC>(&mut wl_light, s, lv, counters);
        self.camera_subpath::<SPECTRAL, DIELECTRIC>(pixel, &mut wl_camera, s, cv, counters);
        if wl_light.terminated || wl_camera.terminated {
            wl.terminate_secondary();
        }
        let mut acc = LaneXyz::default();
        splats.clear();
        for t in 1..=cv.len() {
            for s_count in 0..=lv.len() {
                if s_count + t < 2 || s_count + t - 2 > self.max_scatterings {
                    continue;
                }
                let Some((c, c_light, to_pixel)) = self.connect::<SPECTRAL>(lv, cv, s_count, t, light, &wl, counters)
                else {
                    continue;
                };
                let c = c * self.mis_weight(lv, cv, s_count, t);
                match to_pixel {
                    None => acc.add::<SPECTRAL>(self.emitter, &wl, c_light, c),
                    Some(p) => {
                        // The camera sees the light vertex's wavelength.
                        let seen = if self.fluorescent { wl.seen_at(self.emitter, lv[s_count - 1].lambda) } else { wl };
                        let mut one = LaneXyz::default();
                        one.add::<SPECTRAL>(self.emitter, &seen, c_light, c);
                        splats.push((p, one));
                    }
                }
            }
        }
        // Splats join the light-traced part of the film, in units of the emitted power.
        let scale = 1.0 / self.emitter.total_power_w as f32;
        for (p, one) in splats.iter() {
            let xyz = one.resolve::<SPECTRAL>(&wl) * scale;
            if xyz.is_finite() && xyz != Vec3A::ZERO {
                film.add(*p, xyz);
                counters.splats += 1;
            }
        }
        acc.resolve::<SPECTRAL>(&wl)
    }

    fn light_subpath<'s, const SPECTRAL: bool, const DIELECTRIC: bool>(
        &'s self,
        wl: &mut Wavelengths,
        s: &mut Sampler,
        path: &mut Vec<Vertex<'s>>,
        counters: &mut Counters,
    ) -> usize {
        path.clear();
        let e = self.emitter;
        let (light, pick) = e.pick_light(s.uniform());
        let lp = e.sample_point(self.geo(), light, [s.uniform(), s.uniform(), s.uniform()]);
        let (dir, pdf_dir) = e.sample_direction(light, lp.axis, s.uniform_f32(), s.uniform_f32());
        // β₀ = Φ_λ/pick: power per nm. With the emission factor p(ω)/|cosθ| of `vertex_f`, the
        // direction sampled by p(ω) leaves β unchanged.
        let beta = e.share_lanes::<SPECTRAL, LANES>(light, &wl.lambda) * (e.power_w(light) / pick);
        let mut y0 = Vertex::endpoint(
            Kind::Light(light),
            lp.point,
            lp.err,
            lp.normal,
            lp.prim,
            beta,
            pick * e.position_pdf(light),
        );
        y0.axis = lp.axis;
        y0.delta = e.is_collimated(light);
        y0.medium = e.medium_at(light, lp.prim);
        y0.lambda = wl.lambda;
        path.push(y0);
        let origin = if lp.normal == Vec3A::ZERO {
            lp.point
        } else {
            self.geo().spawn_from(lp.point, lp.err, lp.prim, lp.b, dir)
        };
        self.random_walk::<SPECTRAL, DIELECTRIC>(
            Mode::Importance,
            path,
            origin,
            dir,
            lp.prim,
            y0.medium,
            beta,
            pdf_dir,
            self.max_scatterings + 1,
            wl,
            s,
            counters,
        );
        light
    }

    fn camera_subpath<'s, const SPECTRAL: bool, const DIELECTRIC: bool>(
        &'s self,
        pixel: usize,
        wl: &mut Wavelengths,
        s: &mut Sampler,
        path: &mut Vec<Vertex<'s>>,
        counters: &mut Counters,
    ) {
        path.clear();
        let cam = self.camera;
        let mut z0 = Vertex::endpoint(Kind::Camera, cam.position, Vec3A::ZERO, Vec3A::ZERO, NO_PRIM, Lanes::ONE, 1.0);
        z0.lambda = wl.lambda;
        path.push(z0);
        let dir = cam.ray_direction(pixel, s.uniform_f32(), s.uniform_f32());
        let pdf = cam.direction_pdf(dir);
        // z₀ … z_{max+1}: the last may be an emitter ending a path of `max_scatterings` bounces.
        self.random_walk::<SPECTRAL, DIELECTRIC>(
            Mode::Radiance,
            path,
            cam.position,
            dir,
            NO_PRIM,
            None,
            Lanes::ONE,
            pdf,
            self.max_scatterings + 2,
            wl,
            s,
            counters,
        );
    }

    /// Extends `path` (which holds its endpoint, in `medium`) by sampling until it escapes, is
    /// absorbed or has `max_len` vertices, recording each vertex's forward density and its predecessor's
    /// reverse density.
    #[allow(clippy::too_many_arguments)]
    fn random_walk<'s, const SPECTRAL: bool, const DIELECTRIC: bool>(
        &'s self,
        mode: Mode,
        path: &mut Vec<Vertex<'s>>,
        mut origin: Vec3A,
        mut dir: Vec3A,
        mut skip: u32,
        mut medium: Option<u32>,
        mut beta: Lanes,
        mut pdf_dir: f64,
        max_len: usize,
        wl: &mut Wavelengths,
        s: &mut Sampler,
        counters: &mut Counters,
    ) {
        let geo = self.geo();
        let mut lane_pdf = Lanes::ONE;
        // Passable boundaries crossed since the last vertex (`passage`).
        let mut crossings = 0;
        while path.len() < max_len {
            counters.rays += 1;
            let next = geo.intersect_leaving(origin, dir, f32::INFINITY, skip);
            if DIELECTRIC {
                let t_hit = next.map_or(f64::INFINITY, |h| h.t as f64);
                if let Some((t, c)) = self.fly::<SPECTRAL>(medium, t_hit, wl, &mut beta, &mut lane_pdf, s, counters) {
                    let x = origin + dir * t as f32;
                    let index = path.len();
                    let mut v = Vertex::endpoint(Kind::Medium, x, Vec3A::ZERO, Vec3A::ZERO, NO_PRIM, beta, 0.0);
                    v.wo = -dir;
                    v.medium = medium;
                    v.phase = c.medium.phase;
                    v.mu_s = c.mu_s;
                    v.lambda = wl.lambda;
                    v.lane_pdf = lane_pdf;
                    v.pdf_fwd = to_area(pdf_dir, path[index - 1].p, &v);
                    path.push(v);
                    if path.len() >= max_len {
                        break;
                    }
                    let lambda_in = wl.lambda[0];
                    let Some(event) = self.collide::<SPECTRAL>(&c, mode, wl, &mut beta, s) else { break };
                    counters.phase_samples += 1;
                    let new_dir = media::phase::sample(event.phase(), dir, s.uniform(), s.uniform());
                    if event == Event::Reemitted {
                        path[index].reemitted = true;
                        path[index].singular = mode == Mode::Importance
                            && c.medium
                                .fluorescence
                                .as_ref()
                                .is_some_and(|f| fluorescence::reemits_at_point_mass(f, lambda_in));
                    }
                    // Phase functions are symmetric: the reverse density is the forward one.
                    let pdf = event.phase_pdf(-dir, new_dir);
                    path[index - 1].pdf_rev = to_area(pdf, x, &path[index - 1]);
                    pdf_dir = pdf;
                    origin = x;
                    dir = new_dir;
                    skip = NO_PRIM;
                    crossings = 0;
                    continue;
                }
            }
            let Some(hit) = next else { break };
            let Arrival { surface, material, n, is_dielectric } = self.arrive::<DIELECTRIC>(&hit);
            let (p, err) = geo.hit_point(&hit);
            match self.at_boundary::<DIELECTRIC>(&hit, surface, n, (p, err), dir, &mut crossings) {
                Onward::Vertex => {}
                Onward::Pass { origin: o, medium: m } => {
                    (origin, medium, skip) = (o, m, hit.prim);
                    continue;
                }
                Onward::End => break,
            }
            let index = path.len();
            let mut v = Vertex::endpoint(Kind::Surface, p, err, n, hit.prim, beta, 0.0);
            v.surface = surface;
            v.wo = -dir;
            v.medium = medium;
            v.on_dielectric = is_dielectric;
            v.lambda = wl.lambda;
            v.lane_pdf = lane_pdf;
            v.pdf_fwd = to_area(pdf_dir, path[index - 1].p, &v);
            let tangent = || geo.tangent(hit.prim as usize);
            let ns = geo.shading_normal(hit.prim as usize, hit.b);
            let bsdf =
                Bsdf::new::<SPECTRAL>(material, &self.prepared[surface as usize], &wl.lambda, ns, tangent).shaded(n);
            if bsdf.is_connectible() {
                v.bsdf = Some(bsdf);
            }
            path.push(v);
            if path.len() >= max_len || bsdf.is_absorber() {
                break;
            }
            if self.dispersive[surface as usize] {
                wl.terminate_secondary();
            }
            let Some(sampled) = scatter(&bsdf, -dir, mode, &mut beta, s) else { break };
            let new_dir = sampled.wi;
            let (pdf_fwd, pdf_rev) = if sampled.lobe.is_delta() {
                path[index].delta = true;
                (0.0, 0.0)
            } else {
                (sampled.pdf, bsdf.pdf(new_dir, -dir, mode.reversed()))
            };
            path[index - 1].pdf_rev = to_area(pdf_rev, p, &path[index - 1]);
            pdf_dir = pdf_fwd;
            if is_dielectric {
                medium =
                    media::after_crossing(surface, n, new_dir, &self.scene.surface_inside, &self.scene.surface_outside);
            }
            origin = geo.spawn_from(p, err, hit.prim, hit.b, new_dir);
            dir = new_dir;
            skip = hit.prim;
        }
    }

    fn connectible(&self, v: &Vertex) -> bool {
        match v.kind {
            Kind::Camera => true,
            Kind::Light(l) => !self.emitter.is_collimated(l),
            Kind::Surface => v.bsdf.is_some_and(|b| b.mean_albedo(v.wo) > 0.0),
            Kind::Medium => !v.mu_s.is_zero(),
        }
    }

    fn is_delta_light(&self, y0: &Vertex) -> bool {
        match y0.kind {
            Kind::Light(l) => self.emitter.is_point(l) || self.emitter.is_collimated(l),
            _ => false,
        }
    }

    /// The light a light vertex, or a surface vertex lying on an area light, belongs to.
    fn light_of(&self, v: &Vertex) -> Option<usize> {
        match v.kind {
            Kind::Light(l) => Some(l),
            Kind::Surface => self.surface_light[v.surface as usize],
            Kind::Camera | Kind::Medium => None,
        }
    }

    /// Scattering factor at `v` toward unit `w`: the BSDF at a surface; at a light vertex its
    /// emission pattern p(ω)/|cosθ| (p(ω) at a point light), so that β₀ · factor · G is the
    /// emitted power per solid angle and area reaching the next vertex.
    /// `mode` is the subpath's: importance on the light side, radiance on the camera side.
    fn vertex_f(&self, v: &Vertex, w: Vec3A, mode: Mode) -> Lanes {
        match v.kind {
            Kind::Light(l) => {
                let pdf = self.emitter.direction_pdf(l, v.axis, w) as f64;
                if v.n == Vec3A::ZERO {
                    Lanes::splat(pdf)
                } else {
                    let cos = v.n.dot(w) as f64;
                    if cos > 0.0 {
                        Lanes::splat(pdf / cos)
                    } else {
                        Lanes::ZERO
                    }
                }
            }
            Kind::Surface => v.bsdf.map_or(Lanes::ZERO, |b| b.f(v.wo, w, mode).value()),
            // Connected, a medium vertex scatters: μs(λ)·p(cosθ).
            Kind::Medium => v.mu_s * Event::Scattered(v.phase).phase_pdf(v.wo, w),
            Kind::Camera => Lanes::ZERO,
        }
    }

    /// Area density with which `v`, reached from `prev`, samples `next` (pbrt's Vertex::Pdf), as
    /// a subpath of `mode` would: importance walking toward the camera, radiance toward the light.
    fn pdf_area(&self, v: &Vertex, prev: Option<&Vertex>, next: &Vertex, mode: Mode) -> f64 {
        match v.kind {
            Kind::Light(_) => self.pdf_light(v, next),
            Kind::Camera => to_area(self.camera.direction_pdf((next.p - v.p).normalize()), v.p, next),
            Kind::Surface => {
                let (Some(b), Some(prev)) = (v.bsdf, prev) else { return 0.0 };
                let wp = (prev.p - v.p).normalize();
                let wn = (next.p - v.p).normalize();
                to_area(b.pdf(wp, wn, mode), v.p, next)
            }
            Kind::Medium => {
                let Some(prev) = prev else { return 0.0 };
                let wp = (prev.p - v.p).normalize();
                let wn = (next.p - v.p).normalize();
                to_area(Event::Scattered(v.phase).phase_pdf(wp, wn), v.p, next)
            }
        }
    }

    /// Area density at `next` of the emission direction from light point `v`.
    fn pdf_light(&self, v: &Vertex, next: &Vertex) -> f64 {
        let Some(l) = self.light_of(v) else { return 0.0 };
        let axis = if v.kind == Kind::Surface { v.n } else { v.axis };
        let w = (next.p - v.p).normalize();
        to_area(self.emitter.direction_pdf(l, axis, w) as f64, v.p, next)
    }

    /// Density of `v` as the light subpath's origin: pick · 1/A.
    fn pdf_light_origin(&self, v: &Vertex) -> f64 {
        self.light_of(v).map_or(0.0, |l| self.emitter.pick_pdf(l) * self.emitter.position_pdf(l))
    }

    /// The unweighted contribution of strategy (s, t), the light its power came from, and for
    /// t = 1 the pixel it lands in. Each part is evaluated at the wavelengths its subpath
    /// arrived with; with fluorescence a connection joining two subpaths (s, t ≥ 2) needs both
    /// still at the sample's first wavelength (a re-emitted one matches the other side's with
    /// probability zero), and a light connected at s = 1 is evaluated at the camera side's.
    #[allow(clippy::too_many_arguments)]
    fn connect<const SPECTRAL: bool>(
        &self,
        lv: &[Vertex],
        cv: &[Vertex],
        s: usize,
        t: usize,
        light: usize,
        wl: &Wavelengths,
        counters: &mut Counters,
    ) -> Option<(Lanes, usize, Option<usize>)> {
        if s == 0 {
            let pt = &cv[t - 1];
            if pt.kind != Kind::Surface {
                return None;
            }
            let l = self.surface_light[pt.surface as usize]?;
            let le = self.emitter.radiance::<SPECTRAL, LANES>(l, pt.n, pt.wo, &pt.lambda);
            return (!le.is_zero()).then_some((pt.beta * le * (1.0 / pt.lane_pdf.mean()), l, None));
        }
        let qs = &lv[s - 1];
        if !self.connectible(qs) {
            return None;
        }
        if t == 1 {
            let proj = self.camera.project(qs.p)?;
            let w = proj.to_camera;
            let cos = if qs.n == Vec3A::ZERO { 1.0 } else { qs.n.dot(w).abs() as f64 };
            let c =
                qs.beta * self.vertex_f(qs, w, Mode::Importance) * (cos * proj.importance as f64 / qs.lane_pdf.mean());
            if c.is_zero() {
                return None;
            }
            counters.shadow_rays += 1;
            let cam = self.camera.position;
            let end = qs.end();
            // Seen clear, the segment crosses nothing: it lies in the camera's medium (none).
            let sight = self.clear.as_ref().map_or(Sight::Unknown, |v| v.judge(&proj, end.prim));
            if sight == Sight::Clear {
                return Some((c, light, Some(proj.pixel)));
            }
            if let Some(through) = self.through() {
                let medium = if qs.on_dielectric {
                    media::after_crossing(qs.surface, qs.n, w, &self.scene.surface_inside, &self.scene.surface_outside)
                } else {
                    qs.medium
                };
                let at = Wavelengths { lambda: qs.lambda, ..*wl };
                let t = self.transmittance_through::<SPECTRAL>(through, end, RayEnd::free(cam), medium, &at)?;
                return Some((c * t, light, Some(proj.pixel)));
            }
            // Hidden holds for a plain visibility test (the blocker may be a boundary that the
            // way through above passes).
            let seen = sight != Sight::Hidden && self.geo().visible(end, RayEnd::free(cam));
            seen.then_some((c, light, Some(proj.pixel)))
        } else {
            let pt = &cv[t - 1];
            if !self.connectible(pt) {
                return None;
            }
            if self.fluorescent && (reemitted_before(lv, s) || reemitted_before(cv, t)) && s >= 2 {
                return None;
            }
            let d = pt.p - qs.p;
            let d2 = d.length_squared() as f64;
            if !(d2 > 0.0) {
                return None;
            }
            let w = d.normalize();
            let cos_of = |v: &Vertex| if v.n == Vec3A::ZERO { 1.0 } else { v.n.dot(w).abs() as f64 };
            let beta_q = match qs.kind {
                Kind::Light(l) if self.fluorescent => {
                    let e = self.emitter;
                    e.share_lanes::<SPECTRAL, LANES>(l, &pt.lambda) * (e.power_w(l) / e.pick_pdf(l))
                }
                _ => qs.beta,
            };
            let lane_pdf = (qs.lane_pdf * pt.lane_pdf).mean();
            let mut c = beta_q
                * self.vertex_f(qs, w, Mode::Importance)
                * self.vertex_f(pt, -w, Mode::Radiance)
                * pt.beta
                * (cos_of(qs) * cos_of(pt) / (d2 * lane_pdf));
            // A visible segment crosses no dielectric boundary, so it lies in the medium on the
            // camera vertex's side toward the light vertex (beyond the boundary when the camera
            // vertex sits on a rough dielectric); its transmittance, as on the sampled segments.
            let medium = if pt.on_dielectric {
                media::after_crossing(pt.surface, pt.n, -w, &self.scene.surface_inside, &self.scene.surface_outside)
            } else {
                pt.medium
            };
            let at = Wavelengths { lambda: pt.lambda, ..*wl };
            if let Some(through) = self.through() {
                // Through index-matched boundaries, each stretch in its own medium.
                if c.is_zero() {
                    return None;
                }
                counters.shadow_rays += 1;
                let t = self.transmittance_through::<SPECTRAL>(through, pt.end(), qs.end(), medium, &at)?;
                return Some((c * t, light, None));
            }
            if let Some(t) = medium.and_then(|m| self.medium_transmittance::<SPECTRAL>(m, d2.sqrt(), &at)) {
                c *= t;
            }
            if c.is_zero() {
                return None;
            }
            counters.shadow_rays += 1;
            self.geo().visible(qs.end(), pt.end()).then_some((c, light, None))
        }
    }

    /// Balance-heuristic weight of strategy (s, t): 1/(1 + Σ_{i≠s} p_i/p_s), the ratios walked
    /// outward from the connection as in pbrt-v3's MISWeight, with the four densities next to the
    /// connection recomputed for this strategy's path.
    fn mis_weight(&self, lv: &[Vertex], cv: &[Vertex], s: usize, t: usize) -> f64 {
        let qs = (s > 0).then(|| &lv[s - 1]);
        let qs_minus = (s > 1).then(|| &lv[s - 2]);
        let pt = &cv[t - 1];
        let pt_minus = (t > 1).then(|| &cv[t - 2]);
        let pt_rev = match qs {
            Some(q) => self.pdf_area(q, qs_minus, pt, Mode::Importance),
            None => self.pdf_light_origin(pt),
        };
        let pt_minus_rev = pt_minus.map_or(0.0, |pm| match qs {
            Some(q) => self.pdf_area(pt, Some(q), pm, Mode::Importance),
            None => self.pdf_light(pt, pm),
        });
        let qs_rev = qs.map_or(0.0, |q| self.pdf_area(pt, pt_minus, q, Mode::Radiance));
        let qs_minus_rev = match (qs, qs_minus) {
            (Some(q), Some(qm)) => self.pdf_area(q, Some(pt), qm, Mode::Radiance),
            _ => 0.0,
        };

        // With fluorescence, a path re-emitted at some vertex (other than this strategy's two
        // connection ends, which scatter) is sampled only by the strategies that connect no
        // two subpaths: s = 0, s = 1 and t = 1 (see `connect`), and only by those whose
        // connection ends are not re-emission vertices; onto `reemit`'s point mass only by t = 1.
        let n = s + t;
        let x = |j: usize| if j < s { &lv[j] } else { &cv[n - 1 - j] };
        let reemits_at = |j: usize| self.fluorescent && j + 1 != s && j != s && x(j).reemitted;
        let reemitted = self.fluorescent && (0..n).any(reemits_at);
        if reemitted && (0..n).any(|j| reemits_at(j) && x(j).singular) {
            return 1.0;
        }
        let allowed = |s2: usize| {
            !reemitted || ((s2 <= 1 || s2 + 1 == n) && (s2 == 0 || !reemits_at(s2 - 1)) && (s2 == n || !reemits_at(s2)))
        };

        let mut sum = 0.0;
        // Camera side: z_i generated by the light subpath instead.
        let cam_rev = |i: usize| {
            if i == t - 1 {
                pt_rev
            } else if i + 2 == t {
                pt_minus_rev
            } else {
                cv[i].pdf_rev
            }
        };
        let cam_delta = |i: usize| i != t - 1 && cv[i].delta;
        let mut ratio = 1.0;
        for i in (1..t).rev() {
            ratio *= remap0(cam_rev(i)) / remap0(cv[i].pdf_fwd);
            if !cam_delta(i) && !cam_delta(i - 1) && allowed(n - i) {
                sum += ratio;
            }
        }
        // Light side: y_i generated by the camera subpath instead.
        let light_rev = |i: usize| {
            if i + 1 == s {
                qs_rev
            } else if i + 2 == s {
                qs_minus_rev
            } else {
                lv[i].pdf_rev
            }
        };
        let light_delta = |i: usize| i + 1 != s && lv[i].delta;
        ratio = 1.0;
        for i in (0..s).rev() {
            ratio *= remap0(light_rev(i)) / remap0(lv[i].pdf_fwd);
            let before_is_delta = if i > 0 { light_delta(i - 1) } else { self.is_delta_light(&lv[0]) };
            if !light_delta(i) && !before_is_delta && allowed(i) {
                sum += ratio;
            }
        }
        1.0 / (1.0 + sum)
    }
}
