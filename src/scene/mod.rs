//! The scene: everything a run needs, in SI units and triangles, checked once at load time.
//! Nothing here knows about sampling or the BVH's internals; `load` turns TOML into a `Scene`.

pub mod catalog;
mod doc;
pub mod farfield;
mod gltf;
pub mod ies;
pub mod ldt;
mod load;
pub mod map;
mod obj;
pub mod plane;
mod ply;
pub mod rays;
pub(crate) mod shapes;
mod stl;
pub mod volume;

use std::path::PathBuf;

use glam::DVec3;

use crate::geometry::Geometry;
use crate::spectrum::Spectrum;

pub use load::{load, load_str};
pub use shapes::icosphere;

#[derive(Clone, Debug)]
pub struct Simulation {
    pub photons: u64,
    pub seed: u64,
    pub max_bounces: u32,
    pub wavelength_range_nm: (f64, f64),
    /// Which estimator makes the camera image (`light`, `path` or `bdpt`).
    pub integrator: Integrator,
}

/// Most photons one run may trace (2^48): `run` keeps every total as an exact sum with room for
/// 2^35 batches, and this leaves room to merge two full runs.
pub const MAX_PHOTONS: u64 = 1 << 48;

/// GGX α below which a surface is smooth (a delta lobe): the lobe is then narrower than a
/// direction's f32 resolution, and microfacet sampling loses its precision.
pub const SMOOTH_ROUGHNESS: f64 = 1e-4;

/// GGX roughness: α along the surface tangent (`u`, see `Geometry::tangent`) and across it in
/// the surface plane (`v`). Equal: isotropic (the tangent is never needed); both 0: smooth. The
/// loader gives either both zero or both ≥ `SMOOTH_ROUGHNESS`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Roughness {
    pub u: f64,
    pub v: f64,
}

impl Roughness {
    pub const SMOOTH: Roughness = Roughness { u: 0.0, v: 0.0 };

    pub fn isotropic(alpha: f64) -> Self {
        Roughness { u: alpha, v: alpha }
    }

    /// A microfacet surface, not a smooth (delta) one.
    #[inline]
    pub fn is_rough(&self) -> bool {
        self.u > 0.0 || self.v > 0.0
    }

    /// Whether the lobe turns with the surface tangent.
    #[inline]
    pub fn is_anisotropic(&self) -> bool {
        self.u != self.v
    }
}

impl From<f64> for Roughness {
    fn from(alpha: f64) -> Self {
        Roughness::isotropic(alpha)
    }
}

#[derive(Clone, Debug)]
pub enum Material {
    Absorber,
    /// Diffuse reflection and optional diffuse transmission; ρ + τ ≤ 1 at every wavelength.
    Lambertian {
        reflectance: Spectrum,
        transmittance: Spectrum,
    },
    /// A smooth mirror, optionally with ABg `scatter`.
    Mirror {
        reflectance: Spectrum,
        scatter: Option<Abg>,
    },
    /// A metal of complex index `eta` + i`k` (against an outside of index 1), times a factor;
    /// GGX `roughness` (0: smooth); a smooth one may have ABg `scatter`.
    Conductor {
        eta: Spectrum,
        k: Spectrum,
        specular_reflectance: Spectrum,
        roughness: Roughness,
        scatter: Option<Abg>,
    },
    /// A diffuse base of albedo `diffuse_reflectance` under a dielectric coat of index `ior`
    /// (against 1 outside), smooth or rough (GGX `roughness`).
    Plastic {
        diffuse_reflectance: Spectrum,
        ior: f64,
        roughness: Roughness,
    },
    /// Boundary between `outside_ior` (front, the normals' side) and `ior` (inside), smooth or
    /// rough (GGX `roughness`); a smooth one may have ABg `scatter`.
    Dielectric {
        ior: Spectrum,
        outside_ior: Spectrum,
        absorption_per_m: Option<Spectrum>,
        roughness: Roughness,
        scatter: Option<Abg>,
    },
}

/// ABg surface scatter (`scatter = { abg = [A, B, g] }`), the stray-light model of TracePro and
/// Zemax OpticStudio: BSDF = A/(B + |β − β₀|^g) sr⁻¹, β the tangent-plane projection of the
/// scattered direction and β₀ that of the specular one. `bsdf::abg` tabulates and samples it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Abg {
    pub a: f64,
    pub b: f64,
    pub g: f64,
}

impl Abg {
    /// The BSDF over A at |β − β₀|² = `s`: 1/(B + s^{g/2}).
    #[inline]
    pub fn shape(&self, s: f64) -> f64 {
        1.0 / (self.b + s.powf(0.5 * self.g))
    }

    /// |β − β₀| at which the BSDF has fallen to half its peak, B^{1/g} (1 for g = 0, a flat lobe).
    pub fn knee(&self) -> f64 {
        if self.g > 0.0 {
            self.b.powf(1.0 / self.g)
        } else {
            1.0
        }
    }

    /// An s below which the shape is flat: s^{g/2} ≤ 10⁻⁴·B (the cusp of a small g included),
    /// and at most (10⁻³·knee)² and 10⁻⁸; at least 10⁻³⁰⁰.
    // min/max rather than clamp: a NaN cusp gives a bound, not a NaN.
    #[allow(clippy::manual_clamp)]
    pub fn flat_below(&self) -> f64 {
        let cusp = if self.g > 0.0 { (1e-4 * self.b).powf(2.0 / self.g) } else { 1.0 };
        cusp.min((self.knee() * 1e-3).powi(2)).min(1e-8).max(1e-300)
    }

    /// Total integrated scatter at normal incidence, ∫_{|β|<1} BSDF d²β = πA ∫₀¹ ds/(B + s^{g/2}),
    /// by Gauss–Legendre panels uniform in ln s. It is the largest at any incidence: the disk
    /// |β| < 1 is centred on the lobe there, and the overlap of two centred, radially decreasing
    /// functions is greatest when they are concentric.
    pub fn normal_incidence_tis(&self) -> f64 {
        // Below s_lo the shape is within 1e-4 of shape(0) (s^{g/2} ≤ 1e-4·B): ∫₀^{s_lo} ≈ s_lo·shape(0).
        let s_lo = self.flat_below();
        let (x0, panels) = (s_lo.ln(), 400);
        let h = -x0 / panels as f64;
        let mut sum = s_lo * self.shape(0.0);
        for p in 0..panels {
            let mid = x0 + (p as f64 + 0.5) * h;
            for (x, w) in GAUSS_LEGENDRE_8 {
                let s = (mid + 0.5 * h * x).exp();
                sum += 0.5 * h * w * s * self.shape(s);
            }
        }
        std::f64::consts::PI * self.a * sum
    }
}

/// 8-point Gauss–Legendre nodes and weights on [−1, 1].
pub const GAUSS_LEGENDRE_8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_47),
    (0.960_289_856_497_536_2, 0.101_228_536_290_376_26),
];

impl Material {
    pub fn kind(&self) -> &'static str {
        match self {
            Material::Absorber => "absorber",
            Material::Lambertian { .. } => "lambertian",
            Material::Mirror { .. } => "mirror",
            Material::Conductor { .. } => "conductor",
            Material::Plastic { .. } => "plastic",
            Material::Dielectric { .. } => "dielectric",
        }
    }
}

#[derive(Clone, Debug)]
pub struct NamedMaterial {
    pub name: String,
    pub material: Material,
}

/// The angular distribution of a medium's scattering (`phase`); `media::phase` samples it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    Isotropic,
    /// Henyey–Greenstein with mean cosine g, |g| < 1 (g > 0 forward).
    HenyeyGreenstein {
        g: f64,
    },
}

/// A homogeneous participating medium (`[media.NAME]`), filling the inside of the dielectrics
/// that name it with `medium = "NAME"`.
#[derive(Clone, Debug, PartialEq)]
pub struct Medium {
    pub name: String,
    /// μa and μs per metre.
    pub absorption_per_m: Spectrum,
    pub scattering_per_m: Spectrum,
    pub phase: Phase,
    /// A luminophore dissolved in it (`fluorescence`), absorbing on top of μa and re-emitting.
    pub fluorescence: Option<Fluorescence>,
    /// The volume it fills (m³): the enclosed volumes of its dielectrics.
    pub volume_m3: f64,
}

/// A medium's luminophore (a dye, a phosphor): it absorbs with its own coefficient μf(λ) per
/// metre; each absorbed photon is re-emitted with probability `quantum_yield`, isotropically, at
/// a wavelength drawn from `emission` (a photon-number spectrum, as spectrofluorometers report
/// it and pvtrace samples it). `media::fluorescence` holds the physics.
#[derive(Clone, Debug)]
pub struct Fluorescence {
    pub absorption_per_m: Spectrum,
    pub emission: Spectrum,
    pub emission_sampler: crate::spectrum::SpectralSampler,
    /// Draws an absorbed wavelength in proportion to μf(λ) (the camera integrators' adjoint
    /// re-emission); None where the luminophore absorbs nothing in the simulated range.
    pub absorption_sampler: Option<crate::spectrum::SpectralSampler>,
    pub quantum_yield: f64,
    /// `emission_sampling = "redshift"`: λ' only from the emission spectrum at or above the
    /// absorbed λ (where none lies above, its longest wavelength); `"full"` (false): all of it.
    pub redshift: bool,
}

impl PartialEq for Fluorescence {
    // The sampler is a function of the emission spectrum and the range.
    fn eq(&self, o: &Self) -> bool {
        self.absorption_per_m == o.absorption_per_m
            && self.emission == o.emission
            && self.quantum_yield == o.quantum_yield
            && self.redshift == o.redshift
    }
}

/// A named, tallied surface: the triangles of one `[[surfaces]]` entry or of one area light.
#[derive(Clone, Debug)]
pub struct Surface {
    pub name: String,
    pub material: usize,
    pub area_m2: f64,
    pub triangles: usize,
    /// Index into `Scene::lights` when this surface is an area light's.
    pub light: Option<usize>,
    /// Its irradiance map, when the scene asks for one (`map = { resolution = [nu, nv] }`).
    pub map: Option<map::SurfaceMap>,
    /// `spectrum_bins = N`: N equal wavelength bins of incident flux, starting at this index of
    /// the scene's spectral-bin array.
    pub spectrum_bins: Option<(usize, usize)>,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Distribution {
    /// Radiance constant over the hemisphere: intensity ∝ cosθ.
    Lambertian,
    /// Intensity constant: over the sphere for a point light, the front hemisphere for an area light.
    Isotropic,
    /// Every photon leaves along one direction (the area light's normal, or a point light's `direction`).
    Collimated,
    /// Intensity ∝ cosⁿθ about the axis.
    CosinePower(f64),
    /// Intensity from an IES LM-63 candela table (`Light::ies`), nadir along the axis.
    Ies,
}

impl Distribution {
    pub fn describe(&self) -> String {
        match self {
            Distribution::Lambertian => "lambertian".into(),
            Distribution::Isotropic => "isotropic".into(),
            Distribution::Collimated => "collimated".into(),
            Distribution::CosinePower(n) => format!("cosine_power {n}"),
            Distribution::Ies => "ies".into(),
        }
    }
}

#[derive(Clone, Debug)]
pub enum LightShape {
    /// Emits from the front of surface `surface`'s triangles.
    Area { surface: usize },
    /// Emits from a point; `axis` is the direction of collimated or cosine-power emission.
    Point { position: DVec3, axis: DVec3 },
    /// Emits a ray set (`rays`): positions in the tracer's recentred frame (m), unit directions,
    /// picked in proportion to their power.
    Rays { set: std::sync::Arc<rays::RaySet> },
}

#[derive(Clone, Debug)]
pub struct Light {
    pub name: String,
    pub shape: LightShape,
    pub power_w: f64,
    /// Shape of the spectral power over the wavelength range (its scale is irrelevant).
    pub spectrum: Spectrum,
    /// Luminous efficacy of that spectrum over the wavelength range, lm/W (`photometry`).
    pub lm_per_w: f64,
    /// The candela table and the C = 0 direction of an IES light.
    pub ies: Option<IesLight>,
    pub distribution: Distribution,
}

/// An IES light's table, and its C = 0 direction (scene axes) when the scene gives one.
#[derive(Clone, Debug)]
pub struct IesLight {
    pub profile: std::sync::Arc<crate::scene::ies::IesProfile>,
    pub c0: Option<DVec3>,
    /// Line of the `c0` key, for messages.
    pub c0_line: usize,
    pub file: PathBuf,
}

#[derive(Clone, Debug)]
pub struct Camera {
    pub position: DVec3,
    pub look_at: DVec3,
    pub up: DVec3,
    pub fov_deg: f64,
    pub resolution: [u32; 2],
}

/// The physical effects a scene calls for: what the simulator must pay for.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Effects {
    /// Some material varies with wavelength: each photon carries a sampled wavelength.
    pub spectral: bool,
    pub diffuse_reflection: bool,
    pub diffuse_transmission: bool,
    pub specular_reflection: bool,
    /// A rough (microfacet) reflection, or ABg scatter on a reflection.
    pub glossy_reflection: bool,
    /// A rough refraction, or ABg scatter on a refraction.
    pub glossy_transmission: bool,
    pub refraction: bool,
    pub dispersion: bool,
    pub absorbing_media: bool,
    /// A medium scatters: photons draw free-flight distances and sample its phase function.
    pub volume_scattering: bool,
    /// A medium's luminophore absorbs and re-emits at new wavelengths (forces spectral transport).
    pub fluorescence: bool,
    pub camera: bool,
}

impl Effects {
    pub fn names(&self) -> Vec<&'static str> {
        let all = [
            (self.spectral, "spectral"),
            (self.diffuse_reflection, "diffuse_reflection"),
            (self.diffuse_transmission, "diffuse_transmission"),
            (self.specular_reflection, "specular_reflection"),
            (self.glossy_reflection, "glossy_reflection"),
            (self.glossy_transmission, "glossy_transmission"),
            (self.refraction, "refraction"),
            (self.dispersion, "dispersion"),
            (self.absorbing_media, "absorbing_media"),
            (self.volume_scattering, "volume_scattering"),
            (self.fluorescence, "fluorescence"),
            (self.camera, "camera"),
        ];
        all.iter().filter(|(on, _)| *on).map(|(_, n)| *n).collect()
    }

    pub fn transport(&self) -> &'static str {
        if self.spectral {
            "spectral"
        } else {
            "grey"
        }
    }
}

/// Cloned cheaply: the geometry (BVH and triangles) is shared.
#[derive(Clone)]
pub struct Scene {
    pub path: PathBuf,
    pub simulation: Simulation,
    pub materials: Vec<NamedMaterial>,
    pub surfaces: Vec<Surface>,
    pub lights: Vec<Light>,
    pub camera: Option<Camera>,
    pub geometry: std::sync::Arc<Geometry>,
    /// Participating media (`[media]`), and per surface the one filling a dielectric's inside.
    pub media: Vec<Medium>,
    pub surface_medium: Vec<Option<u32>>,
    /// Per dielectric surface nested in another, that one (directly around it): where a path
    /// that leaves it is. None for the others (their outside is the world).
    pub surface_outside: Vec<Option<u32>>,
    /// Per surface: the dielectric whose interior lies behind it (against its normal): itself,
    /// but for the shared face of two adjacent dielectrics (`surface_outside` the other).
    pub surface_inside: Vec<u32>,
    pub effects: Effects,
    /// Far-field intensity detectors (`[[detectors]] type = "farfield"`).
    pub detectors: Vec<farfield::FarField>,
    /// Volume detectors (`[[detectors]] type = "volume"`).
    pub volumes: Vec<volume::VolumeGrid>,
    /// Work planes (`[[detectors]] type = "plane"`): their slots follow the surface maps' texels.
    pub planes: Vec<plane::WorkPlane>,
    /// Ray-set detectors (`[[detectors]] type = "rays"`), and per surface the one recording it.
    pub ray_detectors: Vec<rays::RayDetector>,
    pub surface_rays: Vec<Option<u32>>,
    /// Problems that did not stop the load (skipped degenerate mesh faces), to show the user.
    pub warnings: Vec<String>,
    /// A known answer for one surface's incident power (`[reference]`), if the file gives one.
    pub reference: Option<Reference>,
    /// Where the scene's own origin lies in the recentred frame the tracer uses (m), and the
    /// file's length unit (m): to show positions in the file's coordinates again.
    pub origin_m: glam::DVec3,
    pub unit_m: f64,
    /// FNV-1a digest of the scene text and every file it read (`error::digest_inputs`).
    pub input_digest: u64,
}

/// Which integrator makes the camera image (`[simulation] integrator`, `--integrator`): the
/// scene's plain description of the choice; the integrators live in `camera_paths`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// Light tracing: every visible photon vertex splatted to the camera (the particle tracer's
    /// own film), lamps in view imaged from the camera.
    #[default]
    Light,
    /// Path tracing from the camera with next-event estimation and MIS.
    Path,
    /// Bidirectional path tracing: all connection strategies, MIS-weighted.
    Bdpt,
}

impl Integrator {
    pub fn name(&self) -> &'static str {
        match self {
            Integrator::Light => "light",
            Integrator::Path => "path",
            Integrator::Bdpt => "bdpt",
        }
    }

    pub fn parse(s: &str) -> Option<Integrator> {
        <Integrator as clap::ValueEnum>::from_str(s, false).ok()
    }
}

/// `[reference] surface = "…", incident_w = …, note = "…"`: a closed-form value to converge to.
#[derive(Clone, Debug)]
pub struct Reference {
    pub surface: usize,
    pub incident_w: f64,
    pub note: String,
}

impl Scene {
    /// A point of the tracer's frame (m) in the scene file's own coordinates and unit.
    pub fn file_coordinates(&self, p: glam::DVec3) -> glam::DVec3 {
        (p + self.origin_m) / self.unit_m
    }

    /// Bins of all far-field detectors together.
    pub fn farfield_bins(&self) -> usize {
        self.detectors.iter().map(|d| d.bins()).sum()
    }

    /// Voxels of all volume detectors together (each grid's `offset` indexes into them).
    pub fn volume_voxels(&self) -> usize {
        self.volumes.iter().map(|v| v.voxels()).sum()
    }

    /// Wavelength bins of all surfaces' spectra together.
    pub fn spectrum_bins(&self) -> usize {
        self.surfaces.iter().filter_map(|s| s.spectrum_bins).map(|(n, _)| n).sum()
    }

    /// Texels of all irradiance maps together (each map's `offset` indexes into them), then
    /// the work planes' slots.
    pub fn map_texels(&self) -> usize {
        self.surface_map_texels() + self.planes.iter().map(|p| p.slots()).sum::<usize>()
    }

    /// Texels of the surfaces' irradiance maps alone.
    pub fn surface_map_texels(&self) -> usize {
        self.surfaces.iter().filter_map(|s| s.map.as_ref()).map(|m| m.texels()).sum()
    }

    /// The file name without extension: the default output folder's name.
    pub fn stem(&self) -> String {
        self.path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into())
    }

    pub fn total_power_w(&self) -> f64 {
        self.lights.iter().map(|l| l.power_w).sum()
    }

    pub fn material_of(&self, surface: usize) -> &Material {
        &self.materials[self.surfaces[surface].material].material
    }
}

/// Which effects the scene's materials and camera call for. A spectrum constant over the
/// wavelength range counts as grey.
pub fn effects_of(materials: &[NamedMaterial], used: &[bool], range: (f64, f64), camera: bool) -> Effects {
    let mut fx = Effects { camera, ..Effects::default() };
    let varies = |s: &Spectrum| s.constant_over(range).is_none();
    let positive = |s: &Spectrum| s.min_max_over(range).1 > 0.0;
    for (m, _) in materials.iter().zip(used).filter(|(_, u)| **u) {
        match &m.material {
            Material::Absorber => {}
            Material::Lambertian { reflectance, transmittance } => {
                fx.diffuse_reflection |= positive(reflectance);
                fx.diffuse_transmission |= positive(transmittance);
                fx.spectral |= varies(reflectance) || varies(transmittance);
            }
            Material::Mirror { reflectance, scatter } => {
                fx.specular_reflection |= positive(reflectance);
                fx.glossy_reflection |= scatter.is_some() && positive(reflectance);
                fx.spectral |= varies(reflectance);
            }
            Material::Plastic { diffuse_reflectance, roughness, .. } => {
                if roughness.is_rough() {
                    fx.glossy_reflection = true;
                } else {
                    fx.specular_reflection = true;
                }
                fx.diffuse_reflection |= positive(diffuse_reflectance);
                fx.spectral |= varies(diffuse_reflectance);
            }
            Material::Conductor { eta, k, specular_reflectance, roughness, scatter } => {
                if positive(specular_reflectance) {
                    if roughness.is_rough() {
                        fx.glossy_reflection = true;
                    } else {
                        fx.specular_reflection = true;
                        fx.glossy_reflection |= scatter.is_some();
                    }
                }
                fx.spectral |= varies(eta) || varies(k) || varies(specular_reflectance);
            }
            Material::Dielectric { ior, outside_ior, absorption_per_m, roughness, scatter } => {
                if roughness.is_rough() {
                    fx.glossy_reflection = true;
                    fx.glossy_transmission = true;
                } else {
                    fx.specular_reflection = true;
                    if scatter.is_some() {
                        fx.glossy_reflection = true;
                        fx.glossy_transmission = true;
                    }
                }
                fx.refraction = true;
                let dispersive = varies(ior) || varies(outside_ior);
                fx.dispersion |= dispersive;
                fx.spectral |= dispersive;
                if let Some(a) = absorption_per_m {
                    if positive(a) {
                        fx.absorbing_media = true;
                        fx.spectral |= varies(a);
                    }
                }
            }
        }
    }
    fx
}
