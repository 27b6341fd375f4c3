//! Every scattering model, one file each, behind the one interface all integrators call: the
//! particle tracer and its camera splats (light → camera, carrying power) and the path tracer
//! and BDPT (camera → light, carrying radiance). A `Bsdf` is a material at one hit, evaluated
//! once at the hit's wavelength lanes: one lane for a particle's own wavelength, four for hero
//! wavelengths or a camera sample; grey transport evaluates each spectrum once.
//!
//! Conventions as in pbrt-v4: unit directions point away from the surface, `wo` back along the
//! path and `wi` onward; f(wo, wi) and pdf(wo, wi) are per solid angle; `n` is the unit
//! geometric normal, either side. Adding a model means one file here and one arm per match.

mod dielectric;
mod lambertian;
mod mirror;

use glam::Vec3A;

pub use dielectric::{etas, fresnel_dielectric, refract};

use crate::sampling::Sampler;
use crate::scene::Material;
use crate::spectrum::Lanes;

/// Which way a path carries its quantity: camera paths carry radiance, light paths power.
/// Refraction scales radiance by (η_i/η_t)² but not power (Veach 1997, §5.2; pbrt's TransportMode).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Radiance,
    Importance,
}

/// How a scattered path left the surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lobe {
    DiffuseReflection,
    DiffuseTransmission,
    /// Mirror reflection, or Fresnel reflection at a dielectric.
    SpecularReflection,
    /// Refraction through a dielectric.
    SpecularTransmission,
}

impl Lobe {
    /// A delta lobe: no other direction can be connected to it.
    #[inline]
    pub fn is_delta(self) -> bool {
        matches!(self, Lobe::SpecularReflection | Lobe::SpecularTransmission)
    }
}

/// Mirror reflection of travel direction `d` about the plane with normal `n`: d − 2(d·n)n.
#[inline]
pub fn reflect(d: Vec3A, n: Vec3A) -> Vec3A {
    (d - 2.0 * d.dot(n) * n).normalize()
}

/// f(wo, wi) as a per-lane factor times an angular one (ρ times 1/π for a Lambertian), so the
/// lanes share the angular work and each integrator multiplies in the order its precision wants.
#[derive(Clone, Copy, Debug)]
pub struct Factored<const N: usize> {
    pub spectral: Lanes<N>,
    pub angular: f64,
}

impl<const N: usize> Factored<N> {
    pub const ZERO: Factored<N> = Factored { spectral: Lanes::ZERO, angular: 0.0 };

    #[inline]
    pub fn value(&self) -> Lanes<N> {
        self.spectral * self.angular
    }
}

/// One sampled scattering.
#[derive(Clone, Copy, Debug)]
pub struct Sample<const N: usize> {
    pub wi: Vec3A,
    pub lobe: Lobe,
    /// The lobe's throughput per lane: f·|cosθ_i| over the lobe's own direction density (ρ, τ,
    /// a mirror's ρ, Fresnel's R or 1 − R; refraction in radiance mode times (η_i/η_t)²).
    pub factor: Lanes<N>,
    /// Probability that this lobe was the one chosen.
    pub lobe_pdf: f64,
    /// Solid-angle density of `wi` (lobe choice included); 0 for a delta lobe.
    pub pdf: f64,
}

impl<const N: usize> Sample<N> {
    /// f·|cosθ_i|/pdf: what a path's throughput is multiplied by.
    #[inline]
    pub fn weight(&self) -> Lanes<N> {
        self.factor * (1.0 / self.lobe_pdf)
    }
}

#[derive(Clone, Copy, Debug)]
enum Model<const N: usize> {
    Absorber,
    Lambertian(lambertian::Lambertian<N>),
    Mirror(mirror::Mirror<N>),
    Dielectric(dielectric::Dielectric),
}

/// A material at one hit and its wavelength lanes.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf<const N: usize = 4> {
    model: Model<N>,
    n: Vec3A,
}

impl<const N: usize> Bsdf<N> {
    /// `material` at wavelengths `lambda` on a surface with unit geometric normal `n`. A
    /// dielectric's index is taken at lane 0: without dispersion every lane has the same, and
    /// with it a camera path keeps lane 0 alone.
    #[inline]
    pub fn new<const SPECTRAL: bool>(material: &Material, lambda: &[f64; N], n: Vec3A) -> Self {
        let model = match material {
            Material::Absorber => Model::Absorber,
            Material::Lambertian { reflectance, transmittance } => Model::Lambertian(lambertian::Lambertian::new(
                Lanes::eval::<SPECTRAL>(reflectance, lambda),
                Lanes::eval::<SPECTRAL>(transmittance, lambda),
            )),
            Material::Mirror { reflectance } => {
                Model::Mirror(mirror::Mirror { reflectance: Lanes::eval::<SPECTRAL>(reflectance, lambda) })
            }
            Material::Dielectric { ior, outside_ior, .. } => Model::Dielectric(dielectric::Dielectric {
                ior: ior.eval(lambda[0]),
                outside_ior: outside_ior.eval(lambda[0]),
            }),
        };
        Bsdf { model, n }
    }

    /// Probability per lane that a path arriving here is scattered at all (for the particle
    /// tracer's estimators and the hero weights): ρ + τ, a mirror's ρ, 1 for a smooth dielectric.
    #[inline]
    pub fn albedo(&self) -> Lanes<N> {
        match &self.model {
            Model::Absorber => Lanes::ZERO,
            Model::Lambertian(m) => m.albedo(),
            Model::Mirror(m) => m.reflectance,
            Model::Dielectric(_) => Lanes::ONE,
        }
    }

    /// The albedo over the lanes, for a camera path's Russian roulette.
    #[inline]
    pub fn mean_albedo(&self) -> f64 {
        match &self.model {
            Model::Absorber => 0.0,
            Model::Lambertian(m) => m.mean_albedo(),
            Model::Mirror(m) => m.reflectance.mean(),
            Model::Dielectric(_) => 1.0,
        }
    }

    /// Whether any power is lost here: a smooth dielectric only divides it between reflection and
    /// refraction, so its paths need no roulette.
    #[inline]
    pub fn absorbs(&self) -> bool {
        !matches!(self.model, Model::Dielectric(_))
    }

    #[inline]
    pub fn is_absorber(&self) -> bool {
        matches!(self.model, Model::Absorber)
    }

    /// Whether f has a part other directions can be connected to (light samples, camera splats,
    /// BDPT connections): false for mirrors, smooth dielectrics and absorbers.
    #[inline]
    pub fn is_connectible(&self) -> bool {
        matches!(self.model, Model::Lambertian(_))
    }

    /// f(wo, wi); zero for delta lobes. Reflection models are symmetric, so `mode` matters only
    /// for refraction.
    #[inline]
    pub fn f(&self, wo: Vec3A, wi: Vec3A, _mode: Mode) -> Factored<N> {
        match &self.model {
            Model::Lambertian(m) => m.f(wo, wi, self.n),
            _ => Factored::ZERO,
        }
    }

    /// Solid-angle density with which `sample` from `wo` returns `wi`; zero for delta lobes.
    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A) -> f64 {
        match &self.model {
            Model::Lambertian(m) => m.pdf(wo, wi, self.n),
            _ => 0.0,
        }
    }

    /// Samples `wi` from `wo`, drawing from `s` only what the model needs (a lobe choice, a
    /// direction). None when nothing can leave (an absorber, a zero density).
    #[inline]
    pub fn sample(&self, wo: Vec3A, mode: Mode, s: &mut Sampler) -> Option<Sample<N>> {
        match &self.model {
            Model::Absorber => None,
            Model::Lambertian(m) => m.sample(wo, self.n, s),
            Model::Mirror(m) => Some(m.sample(wo, self.n)),
            Model::Dielectric(m) => Some(m.sample::<N>(wo, self.n, mode, s)),
        }
    }

    /// The throughput per lane of `lobe` from `wo` to `wi` when another lane's model chose it
    /// (hero wavelengths): what `Sample::factor` would be at these lanes.
    #[inline]
    pub fn lobe_factor(&self, lobe: Lobe, wo: Vec3A, mode: Mode) -> Lanes<N> {
        match &self.model {
            Model::Absorber => Lanes::ZERO,
            Model::Lambertian(m) => m.lobe_factor(lobe),
            Model::Mirror(m) => m.reflectance,
            Model::Dielectric(m) => m.lobe_factor(lobe, wo, self.n, mode),
        }
    }
}
