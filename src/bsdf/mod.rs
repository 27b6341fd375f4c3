//! Every scattering model, one file each, behind the one interface all integrators call: the
//! particle tracer and its camera splats (light → camera, carrying power) and the path tracer
//! and BDPT (camera → light, carrying radiance). A `Bsdf` is a material at one hit, evaluated
//! once at the hit's wavelength lanes: one lane for a particle's own wavelength, four for hero
//! wavelengths or a camera sample; grey transport evaluates each spectrum once.
//!
//! Conventions as in pbrt-v4: unit directions point away from the surface, `wo` back along the
//! path and `wi` onward; f(wo, wi) and pdf(wo, wi) are per solid angle; `n` is the unit
//! geometric normal, either side. Adding a model means one file here and one arm per match.

pub mod abg;
mod conductor;
mod dielectric;
mod lambertian;
pub mod microfacet;
mod mirror;
mod plastic;
mod rough_dielectric;

use glam::Vec3A;

pub use conductor::fresnel_conductor;
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

impl Mode {
    /// The mode of a path that runs the other way (a BDPT subpath's reverse density).
    #[inline]
    pub fn reversed(self) -> Mode {
        match self {
            Mode::Radiance => Mode::Importance,
            Mode::Importance => Mode::Radiance,
        }
    }
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
    /// Microfacet reflection (a rough metal, dielectric or plastic coat, with a rough plastic's
    /// base: its sample is weighted by the whole f), or ABg scatter about the mirror direction.
    GlossyReflection,
    /// Microfacet refraction (a rough dielectric), or ABg scatter about the refracted direction.
    GlossyTransmission,
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
    /// a mirror's ρ, Fresnel's R or 1 − R; refraction in radiance mode times (η_i/η_t)²; a
    /// microfacet lobe's F·G2/G1-type weight; for overlapping lobes, with `lobe_pdf` 1, the
    /// whole f·|cosθ_i| over the mixture density).
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
enum Model<'a, const N: usize> {
    Absorber,
    Lambertian(lambertian::Lambertian<N>),
    Mirror(mirror::Mirror<N>),
    Conductor(conductor::Conductor<N>),
    Dielectric(dielectric::Dielectric),
    RoughDielectric(rough_dielectric::RoughDielectric),
    Plastic(plastic::Plastic<'a, N>),
    Abg(abg::AbgSurface<'a, N>),
}

/// What a model needs worked out once per run rather than at every hit: a plastic's coat
/// averages, an ABg lobe's tables. Built per material by `Prepared::of`; the default serves
/// every other model.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Prepared {
    coat: Option<plastic::Coat>,
    abg: Option<abg::Table>,
}

impl Prepared {
    /// For every surface of `scene`, in surface order: once per run (a rough coat's tables take
    /// a few tenths of a second).
    pub fn for_scene(scene: &crate::scene::Scene) -> Vec<Prepared> {
        let range = scene.simulation.wavelength_range_nm;
        // Once per material, however many surfaces share it.
        let mut by_material: Vec<Option<Prepared>> = vec![None; scene.materials.len()];
        scene
            .surfaces
            .iter()
            .map(|s| {
                by_material[s.material]
                    .get_or_insert_with(|| Prepared::of(&scene.materials[s.material].material, range))
                    .clone()
            })
            .collect()
    }

    /// For `material` over the simulated wavelength range `range` (nm).
    pub fn of(material: &Material, range: (f64, f64)) -> Self {
        match material {
            Material::Plastic { diffuse_reflectance, ior, roughness } => {
                let rho_max = diffuse_reflectance.min_max_over(range).1;
                Prepared { coat: Some(plastic::Coat::new(*ior, rho_max, roughness)), abg: None }
            }
            Material::Mirror { scatter: Some(s), .. }
            | Material::Conductor { scatter: Some(s), .. }
            | Material::Dielectric { scatter: Some(s), .. } => Prepared { coat: None, abg: Some(abg::Table::new(s)) },
            _ => Prepared::default(),
        }
    }
}

#[inline]
fn abg_table(prepared: &Prepared) -> &abg::Table {
    prepared.abg.as_ref().expect("an ABg surface is prepared (Prepared::of) before it is traced")
}

/// A material at one hit and its wavelength lanes, borrowing its run-wide constants.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf<'a, const N: usize = 4> {
    model: Model<'a, N>,
    /// The normal the model's frame is built on: the shading normal.
    n: Vec3A,
    /// The geometric normal, when it differs (smooth shading; `shaded`).
    ng: Option<Vec3A>,
}

impl<'a, const N: usize> Bsdf<'a, N> {
    /// `material` (with its `prepared` constants) at wavelengths `lambda` on a surface with unit
    /// geometric normal `n`. A dielectric's index is taken at lane 0: without dispersion every
    /// lane has the same, and with it a camera path keeps lane 0 alone. `tangent` gives the
    /// surface's tangent there (`Geometry::tangent`), the u axis of an anisotropic roughness; it is
    /// called only for one, so an isotropic material never fetches it.
    #[inline]
    pub fn new<const SPECTRAL: bool>(
        material: &Material,
        prepared: &'a Prepared,
        lambda: &[f64; N],
        n: Vec3A,
        tangent: impl FnOnce() -> Vec3A,
    ) -> Self {
        // α_x's axis, made unit and perpendicular to n; zero (any axis) for an isotropic lobe.
        let axis = |r: &crate::scene::Roughness| {
            if r.is_anisotropic() {
                microfacet::Frame::new(n, tangent()).t
            } else {
                Vec3A::ZERO
            }
        };
        let model = match material {
            Material::Plastic { diffuse_reflectance, roughness, .. } => Model::Plastic(plastic::Plastic::new(
                Lanes::eval::<SPECTRAL>(diffuse_reflectance, lambda),
                prepared.coat.as_ref().expect("a plastic is prepared (Prepared::of) before it is traced"),
                axis(roughness),
            )),
            Material::Absorber => Model::Absorber,
            Material::Lambertian { reflectance, transmittance } => Model::Lambertian(lambertian::Lambertian::new(
                Lanes::eval::<SPECTRAL>(reflectance, lambda),
                Lanes::eval::<SPECTRAL>(transmittance, lambda),
            )),
            Material::Mirror { reflectance, scatter } => {
                let reflectance = Lanes::eval::<SPECTRAL>(reflectance, lambda);
                match scatter {
                    None => Model::Mirror(mirror::Mirror { reflectance }),
                    Some(_) => {
                        Model::Abg(abg::AbgSurface { base: abg::Base::Mirror(reflectance), table: abg_table(prepared) })
                    }
                }
            }
            Material::Conductor { eta, k, specular_reflectance, roughness, scatter } => {
                let metal = conductor::Conductor {
                    eta: Lanes::eval::<SPECTRAL>(eta, lambda),
                    k: Lanes::eval::<SPECTRAL>(k, lambda),
                    tint: Lanes::eval::<SPECTRAL>(specular_reflectance, lambda),
                    ggx: microfacet::Ggx::of(roughness),
                    tangent: axis(roughness),
                };
                match scatter {
                    None => Model::Conductor(metal),
                    Some(_) => {
                        Model::Abg(abg::AbgSurface { base: abg::Base::Conductor(metal), table: abg_table(prepared) })
                    }
                }
            }
            Material::Dielectric { ior, outside_ior, roughness, scatter, .. } => {
                let (ior, outside_ior) = (ior.eval(lambda[0]), outside_ior.eval(lambda[0]));
                if scatter.is_some() {
                    let base = abg::Base::Dielectric { ior, outside_ior };
                    Model::Abg(abg::AbgSurface { base, table: abg_table(prepared) })
                } else if let Some(ggx) = microfacet::Ggx::of(roughness) {
                    let tangent = axis(roughness);
                    Model::RoughDielectric(rough_dielectric::RoughDielectric { ior, outside_ior, ggx, tangent })
                } else {
                    Model::Dielectric(dielectric::Dielectric { ior, outside_ior })
                }
            }
        };
        Bsdf { model, n, ng: None }
    }

    /// The same model on a smooth-shaded surface: its frame stays on the shading normal given to
    /// `new`, and `ng` (the geometric normal) decides sides. Against geometric cosines, which
    /// every integrator uses, the shading BSDF f_s is (Veach 1997, §5.3)
    ///   f(ωo, ωi) = f_s(ωo, ωi)·|ωi·n_s|/|ωi·n_g| (radiance) and its adjoint
    ///   f*(ωo, ωi) = f_s(ωo, ωi)·|ωo·n_s|/|ωo·n_g| (importance: photons, light subpaths),
    /// zero where the two normals disagree on whether ωi is a reflection or a transmission of ωo
    /// (so nothing crosses a surface the geometry says it reflected from). The light tracer, the
    /// path tracer and BDPT then integrate the same transport.
    #[inline]
    pub fn shaded(mut self, ng: Vec3A) -> Self {
        if ng != self.n {
            self.ng = Some(ng);
        }
        self
    }

    /// f (or its adjoint) over f_s against geometric cosines, or None where the normals
    /// disagree about the sides (`shaded`).
    #[inline]
    fn shading_scale(&self, wo: Vec3A, wi: Vec3A, mode: Mode) -> Option<f64> {
        let Some(ng) = self.ng else { return Some(1.0) };
        let ns = self.n;
        let (og, ig, os, is) = (wo.dot(ng), wi.dot(ng), wo.dot(ns), wi.dot(ns));
        if (og * ig > 0.0) != (os * is > 0.0) || og == 0.0 || ig == 0.0 {
            return None;
        }
        Some(match mode {
            Mode::Radiance => (is.abs() / ig.abs()) as f64,
            Mode::Importance => (os.abs() / og.abs()) as f64,
        })
    }

    /// Probability per lane that a path arriving from `wo` is scattered at all, as far as it is
    /// known before sampling (for the particle tracer's estimators): ρ + τ, a mirror's ρ, a
    /// smooth metal's F·tint, 1 for a smooth dielectric. Where it is not known in closed form
    /// (rough models: `samples_exactly` is false) it is 1 and the sample's weight carries the loss.
    #[inline]
    pub fn albedo(&self, wo: Vec3A) -> Lanes<N> {
        match &self.model {
            Model::Absorber => Lanes::ZERO,
            Model::Lambertian(m) => m.albedo(),
            Model::Mirror(m) => m.reflectance,
            Model::Conductor(m) => m.albedo(wo, self.n),
            Model::Plastic(m) => m.albedo_bound(wo, self.n),
            Model::Dielectric(_) | Model::RoughDielectric(_) => Lanes::ONE,
            Model::Abg(m) => m.albedo(wo, self.n),
        }
    }

    /// The directional albedo ∫f|cosθ_i|dω_i per lane where it has a closed form (every smooth
    /// model, Lambertian and plastic); None for the microfacet models.
    pub fn closed_form_albedo(&self, wo: Vec3A) -> Option<Lanes<N>> {
        match &self.model {
            Model::Plastic(m) if m.is_rough() => None,
            Model::Plastic(m) => Some(m.albedo(wo, self.n)),
            Model::RoughDielectric(_) => None,
            Model::Conductor(m) if m.ggx.is_some() => None,
            _ => Some(self.albedo(wo)),
        }
    }

    /// The albedo over the lanes, for a camera path's Russian roulette.
    #[inline]
    pub fn mean_albedo(&self, wo: Vec3A) -> f64 {
        match &self.model {
            Model::Absorber => 0.0,
            Model::Lambertian(m) => m.mean_albedo(),
            Model::Mirror(m) => m.reflectance.mean(),
            Model::Conductor(m) => m.albedo(wo, self.n).mean(),
            Model::Plastic(m) => m.albedo_bound(wo, self.n).0[0],
            Model::Dielectric(_) | Model::RoughDielectric(_) => 1.0,
            Model::Abg(m) => m.albedo(wo, self.n).mean(),
        }
    }

    /// Whether `sample` draws directions in exact proportion to f·|cosθ|/albedo, so a particle
    /// that survived the albedo keeps its weight. Otherwise (microfacet models) the particle
    /// tracer applies the sample's weight, ≤ 1, as a second absorption.
    #[inline]
    pub fn samples_exactly(&self) -> bool {
        if self.ng.is_some() {
            // Shading normals reweight and reject samples: the weight is no longer the albedo.
            return false;
        }
        match &self.model {
            Model::Conductor(m) => m.ggx.is_none(),
            Model::RoughDielectric(_) | Model::Plastic(_) => false,
            _ => true,
        }
    }

    /// Whether any power is lost here before sampling: a dielectric only divides it between
    /// reflection and refraction (a rough one's masking loss is in its sample's weight), so its
    /// paths need no roulette.
    #[inline]
    pub fn absorbs(&self) -> bool {
        match &self.model {
            Model::Dielectric(_) | Model::RoughDielectric(_) => false,
            Model::Abg(m) => !m.is_dielectric(),
            _ => true,
        }
    }

    #[inline]
    pub fn is_absorber(&self) -> bool {
        matches!(self.model, Model::Absorber)
    }

    /// Whether f has a part other directions can be connected to (light samples, camera splats,
    /// BDPT connections): false for mirrors, smooth metals and dielectrics (without ABg scatter),
    /// and absorbers.
    #[inline]
    pub fn is_connectible(&self) -> bool {
        match &self.model {
            Model::Lambertian(_) => true,
            Model::Conductor(m) => m.ggx.is_some(),
            Model::RoughDielectric(_) | Model::Plastic(_) | Model::Abg(_) => true,
            _ => false,
        }
    }

    /// f(wo, wi); zero for delta lobes. Reflection models are symmetric, so `mode` matters only
    /// for refraction.
    #[inline]
    pub fn f(&self, wo: Vec3A, wi: Vec3A, mode: Mode) -> Factored<N> {
        let Some(scale) = self.shading_scale(wo, wi, mode) else { return Factored::ZERO };
        let f = match &self.model {
            Model::Lambertian(m) => m.f(wo, wi, self.n),
            Model::Conductor(m) => m.f(wo, wi, self.n),
            Model::RoughDielectric(m) => m.f(wo, wi, self.n, mode),
            Model::Plastic(m) => m.f(wo, wi, self.n),
            Model::Abg(m) => m.f(wo, wi, self.n, mode),
            _ => Factored::ZERO,
        };
        Factored { spectral: f.spectral, angular: f.angular * scale }
    }

    /// Solid-angle density with which `sample` from `wo` in `mode` returns `wi`; zero for delta
    /// lobes. Only ABg glass samples the two modes differently.
    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, mode: Mode) -> f64 {
        match &self.model {
            Model::Lambertian(m) => m.pdf(wo, wi, self.n),
            Model::Conductor(m) => m.pdf(wo, wi, self.n),
            Model::RoughDielectric(m) => m.pdf(wo, wi, self.n),
            Model::Plastic(m) => m.pdf(wo, wi, self.n),
            Model::Abg(m) => m.pdf(wo, wi, self.n, mode),
            _ => 0.0,
        }
    }

    /// Samples `wi` from `wo`, drawing from `s` only what the model needs (a lobe choice, a
    /// direction). None when nothing can leave (an absorber, a zero density).
    #[inline(always)]
    pub fn sample(&self, wo: Vec3A, mode: Mode, s: &mut Sampler) -> Option<Sample<N>> {
        // The commonest surface, a flat Lambertian one, inline in the caller's loop: out of
        // line, the call passed the sampler and the sample through memory on every bounce.
        if let (Model::Lambertian(m), None) = (&self.model, self.ng) {
            return m.sample(wo, self.n, s);
        }
        // A copy for the call, made on this path only: were `self` passed, the caller would
        // keep its whole Bsdf in memory on every bounce (26 stores), not in registers.
        let general = *self;
        general.sample_general(wo, mode, s)
    }

    #[inline(never)]
    fn sample_general(&self, wo: Vec3A, mode: Mode, s: &mut Sampler) -> Option<Sample<N>> {
        let sampled = self.sample_model(wo, mode, s)?;
        if self.ng.is_none() {
            return Some(sampled);
        }
        // The model's weight is f_s·|ωi·n_s|/pdf; against the geometric cosine |ωi·n_g| the
        // throughput is f·|ωi·n_g|/pdf with f from `shaded`: × |ωi·n_g|/|ωi·n_s| × the scale.
        let scale = self.shading_scale(wo, sampled.wi, mode)?;
        let (ig, is) = (sampled.wi.dot(self.ng?).abs() as f64, sampled.wi.dot(self.n).abs() as f64);
        if !(is > 0.0) {
            return None;
        }
        Some(Sample { factor: sampled.factor * (scale * ig / is), ..sampled })
    }

    #[inline]
    fn sample_model(&self, wo: Vec3A, mode: Mode, s: &mut Sampler) -> Option<Sample<N>> {
        match &self.model {
            Model::Absorber => None,
            Model::Lambertian(m) => m.sample(wo, self.n, s),
            Model::Mirror(m) => Some(m.sample(wo, self.n)),
            Model::Conductor(m) => m.sample(wo, self.n, s),
            Model::Dielectric(m) => Some(m.sample::<N>(wo, self.n, mode, s)),
            Model::RoughDielectric(m) => m.sample::<N>(wo, self.n, mode, s),
            Model::Plastic(m) => m.sample(wo, self.n, s),
            Model::Abg(m) => m.sample(wo, self.n, mode, s),
        }
    }

    /// Per lane, for a scattering from `wo` into `lobe` toward `wi` that another lane's model
    /// sampled (hero wavelengths; `Hero::event`): the throughput factor relative to a direction
    /// density the lanes share; the albedo the lane's expected-value estimator would weight by
    /// (its lobe probability is factor/albedo); and the probability its analog estimator would
    /// have given the event (survivals and lobe choice).
    #[inline]
    pub fn event_terms(&self, lobe: Lobe, wo: Vec3A, wi: Vec3A, mode: Mode) -> EventTerms<N> {
        let exact = |factor: Lanes<N>, albedo: Lanes<N>| EventTerms { factor, albedo, analog: factor };
        // Sampled alike at every lane: the sample's weight w is the throughput; the expected-value
        // estimator weights by it (lobe probability 1 relative to the shared density) and the
        // analog one survives the first absorption a and then min(1, w/a).
        let shared = |w: Lanes<N>, a: f64| EventTerms {
            factor: w,
            albedo: w,
            analog: Lanes(crate::spectrum::map_array(w.0, |x| x.min(a))),
        };
        match &self.model {
            Model::Absorber => exact(Lanes::ZERO, Lanes::ZERO),
            Model::Lambertian(m) => exact(m.lobe_factor(lobe), m.albedo()),
            Model::Mirror(m) => exact(m.reflectance, m.reflectance),
            Model::Conductor(m) => {
                let (w, a) = m.event_terms(wo, wi, self.n);
                if m.ggx.is_none() {
                    exact(w, a)
                } else {
                    shared(w, 1.0)
                }
            }
            Model::Dielectric(m) => exact(m.lobe_factor(lobe, wo, self.n, mode), Lanes::ONE),
            Model::RoughDielectric(m) => shared(m.event_terms(wo, wi, self.n).0, 1.0),
            Model::Plastic(m) => shared(m.weight(lobe, wo, wi, self.n), m.albedo_bound(wo, self.n).0[0]),
            Model::Abg(m) => {
                let (factor, albedo) = m.event_terms(lobe, wo, wi, self.n, mode);
                exact(factor, albedo)
            }
        }
    }
}

/// What `Bsdf::event_terms` answers for each lane.
#[derive(Clone, Copy, Debug)]
pub struct EventTerms<const N: usize> {
    pub factor: Lanes<N>,
    pub albedo: Lanes<N>,
    pub analog: Lanes<N>,
}
