//! Where photons are born: a light chosen in proportion to its power, a wavelength by inverse
//! CDF of its spectral power, an origin uniform by area, a direction from its distribution.
//! Every photon carries the same power, Φ_total/N, so the emission estimator has zero variance
//! in power and all the noise is in where the photons go.

use glam::Vec3A;

use crate::geometry::NO_PRIM;
use crate::sampling::{
    cosine_hemisphere, cosine_power_lobe, uniform_hemisphere, uniform_sphere, uniform_triangle, Discrete,
};
use crate::scene::{Distribution, LightShape, Scene};
use crate::spectrum::{Lanes, SpectralSampler};

enum Origin {
    /// Triangles of the light's surface, chosen by area.
    Area {
        prims: Vec<u32>,
        pick: Discrete,
    },
    Point {
        position: Vec3A,
        axis: Vec3A,
    },
    /// A ray set's points and unit directions, picked by power; wavelengths (nm) when the set
    /// carries them, else empty.
    Rays {
        positions: Vec<Vec3A>,
        directions: Vec<Vec3A>,
        lambda_nm: Vec<f64>,
        pick: Discrete,
    },
}

struct EmitLight {
    origin: Origin,
    distribution: Distribution,
    /// An IES light's table and C = 0 direction (the nadir is the emission axis).
    ies: Option<(std::sync::Arc<crate::scene::ies::IesProfile>, Option<Vec3A>)>,
    spectrum: Option<SpectralSampler>,
    spectrum_shape: crate::spectrum::Spectrum,
    /// Grey transport's colour weights: ∫S·(x̄,ȳ,z̄)dλ / (∫S dλ · ∫ȳ dλ) for the light's spectrum S.
    grey_xyz: Vec3A,
    power_w: f64,
    /// Total emitting area (0 for a point light).
    area_m2: f64,
    /// ∫S dλ over the wavelength range.
    spectrum_integral: f64,
    /// The dielectric the light sits inside (emits into), if any: its photons' first medium.
    medium: LightMedium,
}

/// Which dielectric a light emits into: one for the whole light, or one per emitting triangle
/// (parallel to `Origin::Area::prims`) when its parts lie in different media.
enum LightMedium {
    Uniform(Option<u32>),
    PerTriangle(Vec<Option<u32>>),
}

/// A photon at birth.
#[derive(Clone, Copy, Debug)]
pub struct Birth {
    pub light: usize,
    /// Exact sampled point on the light (for splatting), and the ray origin offset off its surface.
    pub point: Vec3A,
    pub origin: Vec3A,
    pub dir: Vec3A,
    /// Front normal of the emitting triangle; zero for a point light.
    pub normal: Vec3A,
    /// The emitting triangle, which the first ray must not hit again.
    pub prim: u32,
    /// Wavelength in nm (spectral transport only; NaN in grey transport).
    pub lambda_nm: f64,
    /// Colour weights (x̄,ȳ,z̄)/∫ȳ that turn a splat of this photon into XYZ.
    pub xyz: Vec3A,
    /// Rounding-error bound of `point`.
    pub point_err: Vec3A,
    /// Emission axis: the triangle's front normal, or a point light's axis.
    pub axis: Vec3A,
}

impl LightPoint {
    pub fn end(&self) -> crate::geometry::RayEnd {
        crate::geometry::RayEnd { p: self.point, err: self.err, n: self.normal, prim: self.prim }
    }
}

/// The uniform numbers one emission consumes: light, wavelength, triangle, two barycentric, two
/// direction. Drawn plainly or stratified across a batch (see `transport`).
pub const EMIT_DIMS: usize = 7;
pub type EmitSample = [f64; EMIT_DIMS];

pub struct Emitter {
    pick: Discrete,
    lights: Vec<EmitLight>,
    pub total_power_w: f64,
    /// 1/∫ȳ dλ over the wavelength range.
    y_norm: f64,
    cmf: &'static crate::spectrum::color::Cmf,
}

impl Emitter {
    pub fn new(scene: &Scene) -> Self {
        let range = scene.simulation.wavelength_range_nm;
        let geo = &scene.geometry;
        let lights = scene
            .lights
            .iter()
            .map(|l| {
                let mut area_m2 = 0.0;
                let origin = match &l.shape {
                    LightShape::Area { surface } => {
                        let prims: Vec<u32> =
                            (0..geo.len() as u32).filter(|&p| geo.surface[p as usize] == *surface as u32).collect();
                        let areas: Vec<f64> = prims.iter().map(|&p| geo.area(p as usize)).collect();
                        area_m2 = areas.iter().sum();
                        Origin::Area { pick: Discrete::new(&areas), prims }
                    }
                    LightShape::Point { position, axis } => {
                        Origin::Point { position: position.as_vec3a(), axis: axis.as_vec3a().normalize() }
                    }
                    LightShape::Rays { set } => Origin::Rays {
                        positions: set.rays.iter().map(|r| r.position.as_vec3a()).collect(),
                        directions: set.rays.iter().map(|r| r.direction.as_vec3a().normalize()).collect(),
                        lambda_nm: if set.has_wavelengths {
                            set.rays.iter().map(|r| r.lambda_nm).collect()
                        } else {
                            vec![]
                        },
                        pick: Discrete::new(&set.rays.iter().map(|r| r.power_w).collect::<Vec<_>>()),
                    },
                };
                let cie = crate::spectrum::color::cmf();
                let xyz = cie.integrate(&l.spectrum, range);
                let norm = l.spectrum.integral(range) * cie.y_integral(range);
                let grey_xyz = Vec3A::new((xyz[0] / norm) as f32, (xyz[1] / norm) as f32, (xyz[2] / norm) as f32);
                let medium =
                    if scene.effects.refraction { light_medium(scene, &origin) } else { LightMedium::Uniform(None) };
                EmitLight {
                    medium,
                    origin,
                    distribution: l.distribution,
                    ies: l.ies.as_ref().map(|i| (i.profile.clone(), i.c0.map(|c| c.as_vec3a()))),
                    spectrum: SpectralSampler::new(&l.spectrum, range),
                    spectrum_shape: l.spectrum.clone(),
                    grey_xyz,
                    power_w: l.power_w,
                    area_m2,
                    spectrum_integral: l.spectrum.integral(range),
                }
            })
            .collect();
        let y_norm = 1.0 / crate::spectrum::color::cmf().y_integral(range);
        let powers: Vec<f64> = scene.lights.iter().map(|l| l.power_w).collect();
        Emitter {
            pick: Discrete::new(&powers),
            lights,
            total_power_w: powers.iter().sum(),
            y_norm,
            cmf: crate::spectrum::color::cmf(),
        }
    }

    /// The dielectric that light `light` emits into from its triangle `prim` (NO_PRIM for a point
    /// light), if any: the medium of its photons' first segment.
    #[inline]
    pub fn medium_at(&self, light: usize, prim: u32) -> Option<u32> {
        let l = &self.lights[light];
        match (&l.medium, &l.origin) {
            (LightMedium::Uniform(m), _) => *m,
            // `prims` is ascending (collected in index order).
            (LightMedium::PerTriangle(media), Origin::Area { prims, .. }) => {
                prims.binary_search(&prim).ok().and_then(|i| media[i])
            }
            (LightMedium::PerTriangle(_), _) => None,
        }
    }

    /// Whether light `light` emits into no dielectric from any of its points.
    pub fn emits_into_the_open(&self, light: usize) -> bool {
        match &self.lights[light].medium {
            LightMedium::Uniform(m) => m.is_none(),
            LightMedium::PerTriangle(media) => media.iter().all(|m| m.is_none()),
        }
    }

    /// Samples one photon from the uniform numbers `u` (see `EmitSample`). With `SPECTRAL` false
    /// the wavelength number is ignored.
    #[inline]
    pub fn emit<const SPECTRAL: bool>(&self, geo: &crate::geometry::Geometry, u: &EmitSample) -> Birth {
        let light = self.pick.sample(u[0]);
        let l = &self.lights[light];
        let (lambda_nm, xyz) = if SPECTRAL {
            // The loader guarantees a positive spectral integral, so a sampler exists.
            let lambda = l.spectrum.as_ref().map_or(f64::NAN, |sp| sp.sample(u[1]));
            (lambda, self.colour(lambda))
        } else {
            (f64::NAN, l.grey_xyz)
        };
        let lp = self.sample_point(geo, light, [u[2], u[3], u[4]]);
        // A ray set's own wavelength, of the ray `sample_point` picked with the same number.
        let (lambda_nm, xyz) = match &l.origin {
            Origin::Rays { lambda_nm: own, pick, .. } if SPECTRAL && !own.is_empty() => {
                let lambda = own[pick.sample(u[2])];
                (lambda, self.colour(lambda))
            }
            _ => (lambda_nm, xyz),
        };
        let dir = self.direction_of(light, lp.axis, u[5] as f32, u[6] as f32);
        let origin =
            if lp.normal == Vec3A::ZERO { lp.point } else { geo.spawn_from(lp.point, lp.err, lp.prim, lp.b, dir) };
        Birth {
            light,
            point: lp.point,
            origin,
            dir,
            normal: lp.normal,
            prim: lp.prim,
            lambda_nm,
            xyz,
            point_err: lp.err,
            axis: lp.axis,
        }
    }

    /// Colour weights (x̄, ȳ, z̄)(λ)/∫ȳ of a photon of wavelength λ.
    #[inline]
    pub fn colour(&self, lambda_nm: f64) -> Vec3A {
        let c = self.cmf.at(lambda_nm);
        Vec3A::new((c[0] * self.y_norm) as f32, (c[1] * self.y_norm) as f32, (c[2] * self.y_norm) as f32)
    }

    /// Power per nm share of light `light` at wavelength lanes `lambda`: S(λ)/∫S (spectral) or
    /// 1 (grey, where a light's power is carried whole).
    #[inline]
    pub fn share_lanes<const SPECTRAL: bool, const N: usize>(&self, light: usize, lambda: &[f64; N]) -> Lanes<N> {
        if SPECTRAL {
            Lanes(crate::spectrum::map_array(*lambda, |l| self.spectral_share(light, l)))
        } else {
            Lanes::ONE
        }
    }

    /// Radiance an area light's surface emits along unit `w` from a triangle with front normal
    /// `n`, per lane: L = Φ_λ · p(ω)/(A cosθ) (uniform over the area A, direction pdf p); zero behind.
    #[inline]
    pub fn radiance<const SPECTRAL: bool, const N: usize>(
        &self,
        light: usize,
        n: Vec3A,
        w: Vec3A,
        lambda: &[f64; N],
    ) -> Lanes<N> {
        let cos = n.dot(w) as f64;
        let pdf = self.direction_pdf(light, n, w) as f64;
        if cos <= 0.0 || pdf <= 0.0 {
            return Lanes::ZERO;
        }
        self.share_lanes::<SPECTRAL, N>(light, lambda) * (self.power_w(light) * pdf * self.position_pdf(light) / cos)
    }

    /// Relative spectral power S(λ) of light `light` (the shape its wavelengths are drawn from)
    /// at each of the lanes' wavelengths.
    #[inline]
    pub fn spectral_power<const N: usize>(&self, light: usize, lambda: &[f64; N]) -> [f64; N] {
        Lanes::eval::<true>(&self.lights[light].spectrum_shape, lambda).0
    }
}

/// A point sampled on a light, for connecting a camera path to it.
#[derive(Clone, Copy, Debug)]
pub struct LightPoint {
    pub point: Vec3A,
    pub err: Vec3A,
    /// Front normal of the triangle; zero for a point light.
    pub normal: Vec3A,
    pub prim: u32,
    /// Its barycentrics on `prim` (`Geometry::spawn_from`); zero off any triangle.
    pub b: [f32; 3],
    /// The axis its direction pdf is measured about (`direction_pdf`).
    pub axis: Vec3A,
}

/// What the camera integrators ask of the lights: where they are, how they emit, and with which
/// probabilities the emitter samples them (light by power, point uniform by area).
impl Emitter {
    pub fn light_count(&self) -> usize {
        self.lights.len()
    }

    /// Light chosen by power from `u`, and the probability of that choice.
    #[inline]
    pub fn pick_light(&self, u: f64) -> (usize, f64) {
        let l = self.pick.sample(u);
        (l, self.pick_pdf(l))
    }

    #[inline]
    pub fn pick_pdf(&self, light: usize) -> f64 {
        self.lights[light].power_w / self.total_power_w
    }

    #[inline]
    pub fn is_point(&self, light: usize) -> bool {
        matches!(self.lights[light].origin, Origin::Point { .. } | Origin::Rays { .. })
    }

    /// A collimated light emits along a single direction: no pinhole and no connection sees it.
    #[inline]
    pub fn is_collimated(&self, light: usize) -> bool {
        self.lights[light].distribution == Distribution::Collimated
    }

    /// Density of a light's points: 1/A per area, or 1 (a delta) for a point light.
    #[inline]
    pub fn position_pdf(&self, light: usize) -> f64 {
        let a = self.lights[light].area_m2;
        if a > 0.0 {
            1.0 / a
        } else {
            1.0
        }
    }

    pub fn power_w(&self, light: usize) -> f64 {
        self.lights[light].power_w
    }

    /// S(λ)/∫S dλ: the share of the light's power per nm at λ.
    #[inline]
    pub fn spectral_share(&self, light: usize, lambda_nm: f64) -> f64 {
        let l = &self.lights[light];
        l.spectrum_shape.eval(lambda_nm) / l.spectrum_integral
    }

    /// Colour weights of grey transport (see `EmitLight::grey_xyz`).
    #[inline]
    pub fn grey_xyz(&self, light: usize) -> Vec3A {
        self.lights[light].grey_xyz
    }

    /// A point on light `light`, uniform by area, from three uniform numbers.
    #[inline]
    pub fn sample_point(&self, geo: &crate::geometry::Geometry, light: usize, u: [f64; 3]) -> LightPoint {
        match &self.lights[light].origin {
            Origin::Area { prims, pick } => {
                let prim = prims[pick.sample(u[0])];
                let b = uniform_triangle(u[1] as f32, u[2] as f32);
                let (point, err) = geo.hit_point(&crate::geometry::Hit { t: 0.0, prim, b });
                let normal = geo.normal(prim as usize);
                LightPoint { point, err, normal, prim, b, axis: normal }
            }
            Origin::Point { position, axis } => LightPoint {
                point: *position,
                err: Vec3A::ZERO,
                normal: Vec3A::ZERO,
                prim: NO_PRIM,
                b: [0.0; 3],
                axis: *axis,
            },
            // The ray picked by power, its direction as the axis a collimated beam leaves along.
            Origin::Rays { positions, directions, pick, .. } => {
                let k = pick.sample(u[0]);
                LightPoint {
                    point: positions[k],
                    err: Vec3A::ZERO,
                    normal: Vec3A::ZERO,
                    prim: NO_PRIM,
                    b: [0.0; 3],
                    axis: directions[k],
                }
            }
        }
    }

    /// An emission direction about `axis` from the light's distribution (over the whole sphere
    /// for an isotropic point light).
    #[inline]
    fn direction_of(&self, light: usize, axis: Vec3A, u1: f32, u2: f32) -> Vec3A {
        let l = &self.lights[light];
        match (&l.origin, l.distribution, &l.ies) {
            (Origin::Point { .. }, Distribution::Isotropic, _) => uniform_sphere(u1, u2),
            (_, Distribution::Ies, Some((profile, c0))) => {
                let (gamma, c) = profile.sample(u1 as f64, u2 as f64);
                crate::scene::ies::Frame::new(axis, *c0).direction(gamma, c)
            }
            (_, d, _) => direction(d, axis, u1, u2),
        }
    }

    /// `direction_of` and its solid-angle pdf (1 as a placeholder for a collimated light's delta).
    #[inline]
    pub fn sample_direction(&self, light: usize, axis: Vec3A, u1: f32, u2: f32) -> (Vec3A, f64) {
        let dir = self.direction_of(light, axis, u1, u2);
        let pdf = if self.is_collimated(light) { 1.0 } else { self.direction_pdf(light, axis, dir) as f64 };
        (dir, pdf)
    }
}

impl Emitter {
    /// Solid-angle pdf with which light `light` emits toward unit `w` from a birth with axis `axis`
    /// (zero behind an area light and for collimated beams, which no pinhole can see).
    #[inline]
    pub fn direction_pdf(&self, light: usize, axis: Vec3A, w: Vec3A) -> f32 {
        use std::f32::consts::PI;
        let l = &self.lights[light];
        let is_point = matches!(l.origin, Origin::Point { .. } | Origin::Rays { .. });
        let cos = axis.dot(w);
        match l.distribution {
            Distribution::Isotropic if is_point => 1.0 / (4.0 * PI),
            Distribution::Ies => l.ies.as_ref().map_or(0.0, |(profile, c0)| {
                let (gamma, c) = crate::scene::ies::Frame::new(axis, *c0).angles(w);
                profile.pdf(gamma, c) as f32
            }),
            _ if cos <= 0.0 => 0.0,
            Distribution::Lambertian => cos / PI,
            Distribution::Isotropic => 1.0 / (2.0 * PI),
            Distribution::CosinePower(e) => (e as f32 + 1.0) / (2.0 * PI) * cos.powf(e as f32),
            Distribution::Collimated => 0.0,
        }
    }
}

/// Direction about the axis `n` with the distribution's pdf.
#[inline]
fn direction(d: Distribution, n: Vec3A, u1: f32, u2: f32) -> Vec3A {
    match d {
        Distribution::Lambertian => cosine_hemisphere(n, u1, u2),
        Distribution::Isotropic => uniform_hemisphere(n, u1, u2),
        Distribution::Collimated => n,
        Distribution::CosinePower(e) => cosine_power_lobe(n, e as f32, u1, u2),
        Distribution::Ies => unreachable!("IES directions come from the light's table"),
    }
}

/// The dielectric enclosing each emitting point of a light, by parity: a ray from a point just
/// in front of it crosses a closed surface an odd number of times only if the point is inside.
/// Area lights are judged triangle by triangle (a lamp may straddle a water surface). Of nested
/// dielectrics the innermost is taken.
fn light_medium(scene: &Scene, origin: &Origin) -> LightMedium {
    let geo = &scene.geometry;
    match origin {
        Origin::Point { position, .. } => LightMedium::Uniform(enclosing_dielectric(scene, *position, NO_PRIM)),
        // Rays start in the world outside every dielectric (documented for `type = "rays"`).
        Origin::Rays { .. } => LightMedium::Uniform(None),
        Origin::Area { prims, .. } => {
            let media: Vec<Option<u32>> = prims
                .iter()
                .map(|&prim| {
                    // The centroid with its rounding bound, stepped off the triangle's front.
                    let b = [1.0 / 3.0; 3];
                    let (centroid, err) = geo.hit_point(&crate::geometry::Hit { t: 0.0, prim, b });
                    let front = geo.spawn(centroid, err, prim, geo.normal(prim as usize));
                    enclosing_dielectric(scene, front, prim)
                })
                .collect();
            match media.first() {
                Some(&first) if media.iter().all(|&m| m == first) => LightMedium::Uniform(first),
                Some(_) => LightMedium::PerTriangle(media),
                None => LightMedium::Uniform(None),
            }
        }
    }
}

/// The innermost dielectric surface that `start` lies inside, if any (ray parity; `skip` is the
/// triangle the point sits on): of those around it, the one nested deepest
/// (`Scene::surface_outside`).
fn enclosing_dielectric(scene: &Scene, start: Vec3A, skip: u32) -> Option<u32> {
    let mut crossings = scene.geometry.crossings(start, skip, scene.surfaces.len());
    // A crossing of the face two adjacent dielectrics share crosses both.
    let is_interface = |s: usize| scene.surface_inside[s] as usize != s;
    for s in (0..scene.surfaces.len()).filter(|&s| is_interface(s)) {
        let k = crossings[s];
        crossings[scene.surface_inside[s] as usize] += k;
        if let Some(o) = scene.surface_outside[s] {
            crossings[o as usize] += k;
        }
    }
    let depth = |mut s: u32| {
        let mut d = 0;
        while let Some(o) = scene.surface_outside[s as usize] {
            (s, d) = (o, d + 1);
        }
        d
    };
    (0..scene.surfaces.len() as u32)
        .filter(|&s| {
            crossings[s as usize] % 2 == 1
                && !is_interface(s as usize)
                && matches!(scene.material_of(s as usize), crate::scene::Material::Dielectric { .. })
        })
        .max_by_key(|&s| depth(s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_triangle_of_a_lamp_straddling_a_water_surface_emits_into_its_own_side() {
        // A box lamp half under a water surface (y = 0): the triangles below emit into the water,
        // those above into the air; the side faces are split at their diagonals, so a face may
        // have one triangle each way (judged by its centroid).
        let toml = r#"
            [materials.water]
            type = "dielectric"
            ior = 1.33
            absorption_per_m = 1.0
            [[surfaces]]
            name = "tank"
            material = "water"
            shape = { type = "box", min = [-1, -1, -1], max = [1, 0, 1] }
            [[lights]]
            name = "lamp"
            shape = { type = "box", min = [-0.2, -0.3, -0.2], max = [0.2, 0.3, 0.2] }
            power_w = 1
        "#;
        let scene = crate::scene::load_str(std::path::Path::new("straddle.toml"), toml).unwrap();
        let emitter = Emitter::new(&scene);
        let geo = &scene.geometry;
        // The geometry is stored recentred: find the water level there, as the tank's top.
        let tank = (0..geo.len()).filter(|&p| geo.surface_of(p) == 0);
        let level = tank.flat_map(|p| geo.verts(p)).map(|v| v.y).fold(f32::MIN, f32::max);
        let (mut under, mut over) = (0, 0);
        for prim in (0..geo.len() as u32).filter(|&p| geo.surface_of(p as usize) == 1) {
            let v = geo.verts(prim as usize);
            let centroid_y = (v[0].y + v[1].y + v[2].y) / 3.0;
            let expected = (centroid_y < level).then_some(0);
            assert_eq!(emitter.medium_at(0, prim), expected, "triangle {prim}, centroid y {centroid_y}");
            if expected.is_some() {
                under += 1
            } else {
                over += 1
            }
        }
        assert!(under >= 2 && over >= 2, "{under} under, {over} over");
    }
}
