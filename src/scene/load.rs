//! TOML → `Scene`: every key checked, every length converted to metres once, every shape
//! turned into triangles. Each error names the file, the key path and the line.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3A};
use toml::de::DeTable;

use super::doc::{child_path, index_path, Node, Source, Table, R};
use super::shapes::{self, ShapeSpec};
use super::*;
use crate::error::{Error, InputError};
use crate::geometry::Geometry;
use crate::spectrum::photometry;
use crate::spectrum::{SpectralSampler, Spectrum};

const ROOT_KEYS: &[&str] =
    &["simulation", "camera", "scene", "materials", "media", "surfaces", "lights", "reference", "detectors"];

/// Largest coordinate accepted, in metres: far beyond any real scene, and small enough that
/// the BVH's single-precision bounds and surface areas cannot overflow.
const MAX_COORD_M: f64 = 1e15;

/// Largest film (16.7 megapixels): its f64 accumulators then take 0.5 GiB.
/// Largest side of an irradiance map, in texels.
const MAX_MAP_SIDE: u64 = 1024;
/// Most wavelength bins of a surface's spectrum.
const MAX_SPECTRUM_BINS: u64 = 10_000;
/// Voxels of one volume detector.
const MAX_VOXELS: u64 = 4_000_000;
const MAX_PIXELS: u64 = 4096 * 4096;
/// Largest power of a light, and of all lights together, in W: 2.6 million Suns. Below it the
/// f64 tallies and their standard errors stay finite; the f32 images and maps are checked when
/// written (a small scene can overflow them at far lower powers).
pub const MAX_POWER_W: f64 = 1e33;
/// Longest name of a surface, light or detector, in bytes: names become file names, and file
/// systems allow 255 bytes for `farfield_<name>.png`.
const MAX_NAME_BYTES: usize = 200;
/// Hottest blackbody, in K: far past any thermal source, and Planck's law stays finite.
pub const MAX_BLACKBODY_K: f64 = 1e9;

/// Loads and checks a scene file.
pub fn load(path: &Path) -> Result<Scene, Error> {
    let text = crate::error::read_utf8(path, "the scene file")?;
    load_str(path, &text)
}

/// Loads a scene from text; `path` names it in messages and anchors relative file paths.
pub fn load_str(path: &Path, text: &str) -> Result<Scene, Error> {
    let src = Source::new(path, text);
    if text.trim().is_empty() {
        return Err(src.error("", None, "the scene file is empty: it needs at least one light").into());
    }
    let root = DeTable::parse(text).map_err(|e| {
        let byte = e.span().map(|s| s.start);
        src.error("", byte, format!("TOML syntax error: {}", e.message().trim()))
    })?;
    let base_dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let loader = Loader { src: &src, base_dir };
    let table = Table { src: &src, path: "", table: root.get_ref(), start: root.span().start };
    let (scene, digest) = crate::error::digest_inputs(text, || loader.scene(table, path));
    let mut scene = scene?;
    scene.input_digest = digest;
    Ok(scene)
}

/// Peak memory a triangle costs from loading to tracing (the 1.3 M-triangle sphere box peaks
/// at 420 bytes a triangle: f64 shapes, f32 records, the tree and its build), rounded up.
const BYTES_PER_TRIANGLE: u64 = 512;

/// The most triangles a scene may have, and why: what the tree can index, or what fits in the
/// memory this machine has available now (Linux's MemAvailable) at `BYTES_PER_TRIANGLE`.
/// `PHOTON_MAX_SCENE_TRIANGLES` lowers it (never raises it), so tests can reach it cheaply.
fn max_scene_triangles() -> (u64, String) {
    let lowered = std::env::var("PHOTON_MAX_SCENE_TRIANGLES").ok().and_then(|v| {
        let n = v.trim().parse::<u64>().ok();
        if n.is_none() {
            eprintln!("warning: PHOTON_MAX_SCENE_TRIANGLES={v:?} is not a whole number of triangles; ignored");
        }
        n
    });
    let (cap, why) = machine_max_scene_triangles();
    match lowered {
        Some(n) if n < cap => (n, "the limit PHOTON_MAX_SCENE_TRIANGLES sets".to_string()),
        _ => (cap, why),
    }
}

fn machine_max_scene_triangles() -> (u64, String) {
    let index = crate::geometry::MAX_TRIANGLES as u64 - 1;
    let available = std::fs::read_to_string("/proc/meminfo").ok().and_then(|m| {
        let line = m.lines().find(|l| l.starts_with("MemAvailable:"))?;
        line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kib| kib.saturating_mul(1024))
    });
    match available {
        Some(bytes) if bytes / BYTES_PER_TRIANGLE < index => (
            bytes / BYTES_PER_TRIANGLE,
            format!(
                "at about {BYTES_PER_TRIANGLE} bytes a triangle they would not fit in the {:.1} GB of memory available",
                bytes as f64 / 1e9
            ),
        ),
        _ => (index, "the most a scene's tree can index".to_string()),
    }
}

/// The most triangles with the same three corners a scene may hold (`check_stacked_triangles`).
const MOST_STACKED: usize = 32;
/// Per light: a point light's position and axis, and a ray set's rays (None where not such).
type PlacedLights = (Vec<Option<(DVec3, DVec3)>>, Vec<Option<crate::scene::rays::RaySet>>);
/// An edge by its two end points' exact f32 bits.
type EdgeKey = [[u32; 3]; 2];

/// The scene's triangles counted against `max_scene_triangles`: first every shape of known
/// size, then each mesh as its file is read.
struct TriangleBudget {
    cap: u64,
    why: String,
    total: u64,
}

impl TriangleBudget {
    /// Counts `n` more triangles, those of the shape at `key`; refuses past the cap. `ahead`:
    /// counting the shapes of known size, in file order (else a mesh, after all of those).
    fn add(&mut self, file: &Path, n: u64, key: &str, line: usize, ahead: bool) -> R<()> {
        self.total = self.total.saturating_add(n);
        if self.total > self.cap {
            let (total, cap, why) = (self.total, self.cap, &self.why);
            let made = if ahead {
                format!("the scene's shapes make {total} triangles up to this one")
            } else {
                format!("the scene's generated shapes and the meshes read so far make {total} triangles")
            };
            return Err(InputError::new(file, key.to_string(), Some(line), format!("{made}, more than {cap}: {why}")));
        }
        Ok(())
    }

    /// Counts the `n` triangles of a shape whose count was not known ahead (a mesh, once its file
    /// is read); the others were counted ahead (`ShapeSpec::triangle_count`).
    fn add_mesh(&mut self, file: &Path, shape: &ShapeSpec, n: usize, key: &str, line: usize) -> R<()> {
        match shape.triangle_count() {
            None => self.add(file, n as u64, key, line, false),
            Some(_) => Ok(()),
        }
    }
}

struct Loader<'s> {
    src: &'s Source<'s>,
    base_dir: PathBuf,
}

/// Shapes of one `[[surfaces]]` or `[[lights]]` entry, before triangulation.
struct Entry {
    name: String,
    material: usize,
    shape: ShapeSpec,
    /// `map = { resolution = [nu, nv] }`: the resolution and the map's frame in scene units
    /// (None for a mesh, mapped by its texture coordinates).
    map: Option<([usize; 2], Option<[DVec3; 3]>)>,
    spectrum_bins: Option<usize>,
    line: usize,
    shape_line: usize,
    map_line: usize,
}

/// The names surfaces and lights have taken: each must be unique, and so must the output file
/// name it becomes.
#[derive(Default)]
struct Names {
    /// Each name and the key that took it.
    keys: HashMap<String, String>,
    /// Output files (maps/<name>.exr, spectrum_<name>.csv) use the name made file-safe.
    stems: HashMap<String, String>,
}

impl Names {
    /// Takes `name` for the entry at `key` (its `name` on `node_line`), or says why it cannot.
    fn claim(&mut self, file: &Path, name: &str, key: &str, node_line: usize) -> R<()> {
        let error = |m: String| InputError::new(file, key, Some(node_line), m);
        if crate::scene::map::file_stem(name).len() > MAX_NAME_BYTES {
            return Err(error(format!(
                "a name of {} bytes is too long: names become output file names (maps/<name>.exr, \
                 spectrum_<name>.csv), so they are at most {MAX_NAME_BYTES}",
                name.len()
            )));
        }
        if let Some(prev) = self.keys.insert(name.to_string(), key.to_string()) {
            return Err(error(format!(
                "duplicate name \"{name}\": `{prev}` already uses it; surface and light names must be unique"
            )));
        }
        if let Some(prev) = self.stems.insert(crate::scene::map::file_stem(name), name.to_string()) {
            return Err(error(format!(
                "names \"{prev}\" and \"{name}\" give the same output file name \"{}\" (characters other \
                 than letters, digits, '-' and '_' become '_'): rename one",
                crate::scene::map::file_stem(name)
            )));
        }
        Ok(())
    }
}

/// One `[[lights]]` entry, parsed now; its power is resolved after triangulation (radiance
/// needs the area).
struct LightSpec {
    name: String,
    material: usize,
    shape: ShapeSpec,
    power: PowerSpec,
    spectrum: Spectrum,
    distribution: Distribution,
    ies: Option<IesLight>,
    axis: Option<DVec3>,
    /// `spectrum_bins` of an area light (the light as a surface: what arrives on it).
    spectrum_bins: Option<usize>,
    path: String,
    line: usize,
    shape_line: usize,
    /// The key that set the power (the IES file's lumens: `distribution`) and its line.
    power_key: (&'static str, usize),
}

/// A light's power as the scene gives it.
enum PowerSpec {
    Watts(f64),
    Lumens(f64),
    Radiance(Spectrum),
}

/// A dielectric material's `medium` and `outside_medium` (indices into `[media]`), and the
/// line of `outside_medium` for messages.
#[derive(Clone, Copy, Debug, Default)]
struct MediumSides {
    inside: Option<u32>,
    outside: Option<u32>,
    outside_line: usize,
}

/// What `check_dielectrics` finds: each surface's enclosed volume (m³; 0 but for dielectrics)
/// and, for a dielectric nested in another, the one directly around it.
struct Dielectrics {
    volume: Vec<f64>,
    outside: Vec<Option<u32>>,
    /// The dielectric whose interior lies behind each surface (itself, but for an interface).
    inside: Vec<u32>,
}

/// The face two adjacent dielectrics share (`join_shared_faces`): its own surface, whose
/// triangles are `inner`'s (normals toward `outer`) and whose two sides are their interiors.
struct Interface {
    surface: usize,
    inner: usize,
    outer: usize,
}

/// One surface or area light triangulated in metres (f64), before recentring.
struct Shaped {
    name: String,
    material: usize,
    tris: Vec<[DVec3; 3]>,
    /// Each triangle's surface tangent (`shapes::Triangles::tangents`).
    tangents: Vec<DVec3>,
    /// A mesh's vertex normals per triangle (`shapes::Triangles::normals`).
    normals: Option<Vec<Option<[DVec3; 3]>>>,
    light: Option<usize>,
    /// Resolution and frame (m) of its irradiance map, and a mesh's texture coordinates.
    map: Option<([usize; 2], Option<[DVec3; 3]>)>,
    uvs: Option<Vec<[glam::DVec2; 3]>>,
    spectrum_bins: Option<usize>,
    key: String,
    line: usize,
}

/// The surfaces as the tracer takes them: recentred, single-precision triangles, each tagged
/// with its surface.
struct Assembled {
    tris: Vec<[Vec3A; 3]>,
    tri_surface: Vec<u32>,
    /// Each triangle's unit surface tangent (zero where it has none).
    tri_tangent: Vec<Vec3A>,
    /// Each triangle's unit vertex normals for smooth shading (zero where it is flat).
    tri_shading: Vec<[Vec3A; 3]>,
    surfaces: Vec<Surface>,
    /// Each light's surface and its area (m²); None for a point light.
    light_surface: Vec<Option<(usize, f64)>>,
    /// Each surface's key and line, for the checks on the finished geometry.
    surface_keys: Vec<(String, usize)>,
}

/// The centre of the box around every triangle and point light (m), and the box's largest
/// side. Physics does not care where the scene sits, but f32 precision does: moved to this
/// origin, a scene 100 km out is traced as finely as one at home.
fn bounding_centre(shaped: &[Shaped], point_positions: &[Option<(DVec3, DVec3)>]) -> (DVec3, f64) {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for v in shaped.iter().flat_map(|s| s.tris.iter().flatten()).chain(point_positions.iter().flatten().map(|(p, _)| p))
    {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    ((lo + hi) * 0.5, (hi - lo).max_element())
}

/// The spectral power of a ray set that carries wavelengths, as 1 nm bins over the range (linear
/// between bin centres): the shape its light's colour and efficacy are taken from.
fn ray_spectrum(set: &crate::scene::rays::RaySet, range: (f64, f64)) -> Result<Spectrum, String> {
    if let Some(r) = set.rays.iter().find(|r| r.lambda_nm < range.0 || r.lambda_nm > range.1) {
        return Err(format!(
            "a ray of {} nm lies outside the wavelength range {}–{} nm",
            r.lambda_nm, range.0, range.1
        ));
    }
    let bins = ((range.1 - range.0).ceil() as usize).max(1);
    let width = (range.1 - range.0) / bins as f64;
    let mut power = vec![0.0; bins];
    for r in &set.rays {
        power[(((r.lambda_nm - range.0) / width) as usize).min(bins - 1)] += r.power_w;
    }
    let mut points: Vec<(f64, f64)> =
        power.iter().enumerate().map(|(k, p)| (range.0 + (k as f64 + 0.5) * width, p / width)).collect();
    // The ends of the range hold the outer bins' densities, so nothing of them is lost.
    points.insert(0, (range.0, points[0].1));
    points.push((range.1, points[points.len() - 1].1));
    Ok(Spectrum::Table(crate::spectrum::Table::new(points)))
}

/// The effects of the materials some surface uses; spectral also when a surface asks for its
/// spectrum, since each photon must then carry a wavelength.
fn effects_in_use(materials: &[NamedMaterial], surfaces: &[Surface], range: (f64, f64), camera: bool) -> Effects {
    let mut used = vec![false; materials.len()];
    for s in surfaces {
        used[s.material] = true;
    }
    let mut effects = effects_of(materials, &used, range, camera);
    effects.spectral |= surfaces.iter().any(|s| s.spectrum_bins.is_some());
    effects
}

impl<'s> Loader<'s> {
    /// The whole scene, stage by stage. The order of the stages is the order of the checks, so
    /// it decides which error a bad file reports first.
    fn scene(&self, root: Table<'s, '_>, path: &Path) -> R<Scene> {
        root.allow(ROOT_KEYS)?;
        let unit_m = self.unit(root)?;
        let simulation = self.simulation(root)?;
        let range = simulation.wavelength_range_nm;

        let mut media = self.media(root, range)?;
        let (mut materials, material_index, mut material_medium) = self.materials(root, range, &media)?;
        let mut names = Names::default();
        let entries = self.surface_entries(root, &material_index, &mut names)?;
        let mut light_specs = self.light_specs(root, &material_index, range, &mut names)?;
        let camera = root.with("camera", |n| self.camera(n.table()?, unit_m))?;
        let shapes = entries.iter().enumerate().map(|(i, e)| (index_path("surfaces", i), &e.shape, e.shape_line));
        let mut budget = self.check_triangle_budget(
            shapes.chain(light_specs.iter().map(|l| (l.path.clone(), &l.shape, l.shape_line))),
        )?;

        // Triangulate in metres (f64): surfaces first, then area lights.
        let mut warnings = Vec::new();
        let mut shaped = self.triangulate_surfaces(&entries, unit_m, &mut budget, &mut warnings)?;
        let (point_positions, ray_sets) =
            self.place_lights(&mut light_specs, unit_m, &mut shaped, &mut budget, &mut warnings)?;
        // Ray sets count toward the scene's box by their extremes.
        let ray_box: Vec<Option<(DVec3, DVec3)>> = ray_sets
            .iter()
            .flatten()
            .flat_map(|set| {
                let lo = set.rays.iter().fold(DVec3::INFINITY, |a, r| a.min(r.position));
                let hi = set.rays.iter().fold(DVec3::NEG_INFINITY, |a, r| a.max(r.position));
                [Some((lo, DVec3::Z)), Some((hi, DVec3::Z))]
            })
            .collect();
        let boxed: Vec<Option<(DVec3, DVec3)>> = point_positions.iter().copied().chain(ray_box).collect();
        let (origin_m, span_m) = bounding_centre(&shaped, &boxed);
        let mut assembled =
            self.single_precision_surfaces(shaped, origin_m, span_m, light_specs.len(), &mut warnings)?;
        let interfaces = self.join_shared_faces(&mut assembled, &mut materials, &mut material_medium)?;
        let Assembled { tris, tri_surface, tri_tangent, tri_shading, surfaces, light_surface, surface_keys } =
            assembled;
        let (lights, light_lines) =
            self.lights(light_specs, &point_positions, ray_sets, &light_surface, origin_m, range)?;
        let camera = camera.map(|c| Camera { position: c.position - origin_m, look_at: c.look_at - origin_m, ..c });

        let surface_medium: Vec<Option<u32>> = surfaces.iter().map(|s| material_medium[s.material].inside).collect();
        let mut effects = effects_in_use(&materials, &surfaces, range, camera.is_some());
        for m in surface_medium.iter().flatten().map(|&m| &media[m as usize]) {
            let positive = |s: &Spectrum| s.min_max_over(range).1 > 0.0;
            let varies = |s: &Spectrum| s.constant_over(range).is_none();
            effects.absorbing_media |= positive(&m.absorption_per_m);
            effects.volume_scattering |= positive(&m.scattering_per_m);
            effects.spectral |= varies(&m.absorption_per_m) || varies(&m.scattering_per_m);
            // Re-emission changes a photon's wavelength: only spectral transport carries one.
            if m.fluorescence.as_ref().is_some_and(|f| positive(&f.absorption_per_m)) {
                effects.fluorescence = true;
                effects.spectral = true;
            }
        }
        // A medium behind a boundary that bends light: the light tracer's image cannot look in.
        let refracting = surfaces.iter().zip(&surface_medium).any(|(s, m)| {
            m.is_some()
                && match &materials[s.material].material {
                    Material::Dielectric { ior, outside_ior, roughness, scatter, .. } => {
                        ior != outside_ior || roughness.is_rough() || scatter.is_some()
                    }
                    _ => false,
                }
        });
        let integrator = simulation.integrator;
        if (effects.volume_scattering || effects.fluorescence)
            && camera.is_some()
            && refracting
            && integrator == Integrator::Light
        {
            warnings.push(
                "the light-traced image shows the light scattered inside a medium only where its way to the camera \
                 crosses index-matched boundaries (ior = outside_ior); behind a refracting boundary it is missing \
                 (--integrator path or bdpt image it)"
                    .to_string(),
            );
        }
        let (detectors, volumes, planes, ray_detectors) = self.detectors(root, origin_m, unit_m, &surfaces)?;
        let mut surface_rays = vec![None; surfaces.len()];
        for (k, d) in ray_detectors.iter().enumerate() {
            surface_rays[d.surface] = Some(k as u32);
        }
        // Constant-over-range spectra become constants, so grey transport never evaluates a table.
        for m in &mut materials {
            simplify_material(&mut m.material, range);
        }
        for m in &mut media {
            simplify(&mut m.absorption_per_m, range);
            simplify(&mut m.scattering_per_m, range);
            if let Some(f) = &mut m.fluorescence {
                simplify(&mut f.absorption_per_m, range);
            }
        }

        self.check_stacked_triangles(&tris, &tri_surface, &surfaces, &surface_keys)?;
        self.check_point_lights_off_surfaces(&lights, &light_lines, &tris, &tri_surface, &surfaces)?;
        self.warn_of_lights_flush_with_surfaces(&lights, &light_lines, &tris, &tri_surface, &surfaces, &mut warnings);
        self.check_ies_c0_planes(&lights, &tris, &tri_surface)?;
        let reference = self.reference(root, &surfaces)?;
        let smooth = tri_shading.iter().any(|n| n[0] != Vec3A::ZERO);
        let geometry =
            Geometry::build_with_shading(tris, tri_surface, tri_tangent, if smooth { tri_shading } else { Vec::new() })
                .map_err(|m| InputError::new(self.src.file, "", None, m))?;
        let camera_line = root.with("camera", |n| Ok(n.table()?.line_of_key("position")))?.unwrap_or(0);
        let sides: Vec<&MediumSides> = surfaces.iter().map(|s| &material_medium[s.material]).collect();
        let Dielectrics { volume, outside: surface_outside, inside: surface_inside } = self.check_dielectrics(
            &geometry,
            &surfaces,
            &materials,
            &surface_keys,
            &sides,
            &media,
            &interfaces,
            camera.as_ref(),
            camera_line,
        )?;
        // A medium fills its dielectrics less the dielectrics nested in them.
        for (s, m) in surface_medium.iter().enumerate() {
            if let Some(m) = m {
                media[*m as usize].volume_m3 += volume[s];
            }
            if let Some(m) = surface_outside[s].and_then(|o| surface_medium[o as usize]) {
                media[m as usize].volume_m3 -= volume[s];
            }
        }
        Ok(Scene {
            path: path.to_path_buf(),
            simulation,
            materials,
            surfaces,
            lights,
            camera,
            geometry: std::sync::Arc::new(geometry),
            media,
            surface_medium,
            surface_inside,
            surface_outside,
            effects,
            detectors,
            volumes,
            planes,
            ray_detectors,
            surface_rays,
            warnings,
            reference,
            origin_m,
            unit_m,
            input_digest: 0,
        })
    }

    /// `[materials]`: the built-in absorber at index 0, then each material in file order, the
    /// index of each name, and per material the media on its two sides (a dielectric's `medium`
    /// and `outside_medium`).
    #[allow(clippy::type_complexity)]
    fn materials(
        &self,
        root: Table<'s, '_>,
        range: (f64, f64),
        media: &[Medium],
    ) -> R<(Vec<NamedMaterial>, HashMap<String, usize>, Vec<MediumSides>)> {
        let mut materials = vec![NamedMaterial { name: "absorber".into(), material: Material::Absorber }];
        let mut material_index: HashMap<String, usize> = HashMap::from([("absorber".to_string(), 0)]);
        let mut material_medium = vec![MediumSides::default()];
        root.with("materials", |n| {
            let t = n.table()?;
            for key in t.keys() {
                let m = t.require(key, |n| self.material(n, range))?;
                let medium = t.require(key, |n| self.material_media(n.table()?, media))?;
                if key == "absorber" {
                    // A user's own "absorber" replaces the built-in one.
                    materials[0].material = m;
                } else {
                    material_index.insert(key.to_string(), materials.len());
                    materials.push(NamedMaterial { name: key.to_string(), material: m });
                    material_medium.push(medium);
                }
            }
            Ok(())
        })?;
        Ok((materials, material_index, material_medium))
    }

    /// A dielectric's `medium = "NAME"` and `outside_medium = "NAME"`: the `[media]` entries
    /// filling its inside and around it (where it sits inside another dielectric's medium).
    fn material_media(&self, t: Table<'s, '_>, media: &[Medium]) -> R<MediumSides> {
        let find = |key: &str| -> R<Option<u32>> {
            let Some(name) = t.str(key)? else { return Ok(None) };
            match media.iter().position(|m| m.name == name) {
                Some(i) => Ok(Some(i as u32)),
                None => {
                    let known: Vec<&str> = media.iter().map(|m| m.name.as_str()).collect();
                    Err(t.err_at(
                        key,
                        if known.is_empty() {
                            format!("unknown medium \"{name}\": the file has no [media] entries")
                        } else {
                            format!("unknown medium \"{name}\"; the [media] entries are: {}", known.join(", "))
                        },
                    ))
                }
            }
        };
        let inside = find("medium")?;
        if inside.is_some() && t.has("absorption_per_m") {
            return Err(t.err_at(
                "medium",
                "give either medium or absorption_per_m, not both: absorption_per_m is shorthand for a purely \
                 absorbing medium, so put the absorption in the [media] entry",
            ));
        }
        let outside = find("outside_medium")?;
        Ok(MediumSides { inside, outside, outside_line: t.line_of_key("outside_medium") })
    }

    /// `[media]`: each homogeneous medium, μa and μs (spectra, per metre), its phase function and
    /// its luminophore.
    fn media(&self, root: Table<'s, '_>, range: (f64, f64)) -> R<Vec<Medium>> {
        let mut media = Vec::new();
        root.with("media", |n| {
            let t = n.table()?;
            for key in t.keys() {
                let m = t.require(key, |n| {
                    let t = n.table()?;
                    t.allow(&["absorption_per_m", "scattering_per_m", "phase", "fluorescence"])?;
                    let coefficient = |k: &str| -> R<Spectrum> {
                        Ok(t.with(k, |n| self.spectrum(n, SpectrumUse::NonNegative))?
                            .unwrap_or(Spectrum::Constant(0.0)))
                    };
                    let absorption_per_m = coefficient("absorption_per_m")?;
                    let scattering_per_m = coefficient("scattering_per_m")?;
                    let phase = t.with("phase", |n| self.phase(n))?.unwrap_or(Phase::Isotropic);
                    let fluorescence = t.with("fluorescence", |n| self.fluorescence(n.table()?, range))?;
                    Ok(Medium {
                        name: key.to_string(),
                        absorption_per_m,
                        scattering_per_m,
                        phase,
                        fluorescence,
                        volume_m3: 0.0,
                    })
                })?;
                media.push(m);
            }
            Ok(())
        })?;
        Ok(media)
    }

    /// `fluorescence = { absorption_per_m, emission, quantum_yield, emission_sampling }`: the
    /// luminophore's own absorption coefficient (per metre), its emission spectrum (photon
    /// numbers per nm, any scale), the share of absorbed photons it re-emits, and which part of
    /// the emission spectrum a re-emission draws from.
    fn fluorescence(&self, t: Table<'s, '_>, range: (f64, f64)) -> R<Fluorescence> {
        t.allow(&["absorption_per_m", "emission", "quantum_yield", "emission_sampling"])?;
        let absorption_per_m = t.require("absorption_per_m", |n| self.spectrum(n, SpectrumUse::NonNegative))?;
        let emission = t.require("emission", |n| self.spectrum(n, SpectrumUse::NonNegative))?;
        let Some(emission_sampler) = SpectralSampler::new(&emission, range) else {
            return Err(t.err_at(
                "emission",
                format!(
                    "the emission spectrum has no power inside the simulated wavelengths {}–{} nm \
                     (simulation.wavelength_range_nm)",
                    range.0, range.1
                ),
            ));
        };
        let quantum_yield = t.require("quantum_yield", |n| {
            let q = n.f64()?;
            if !(0.0..=1.0).contains(&q) {
                return Err(n.err(format!(
                    "quantum_yield is the share of absorbed photons re-emitted and must lie in [0, 1], found {q}"
                )));
            }
            Ok(q)
        })?;
        let redshift = t
            .with("emission_sampling", |n| match n.str()? {
                "full" => Ok(false),
                "redshift" => Ok(true),
                other => Err(n.err(format!(
                    "unknown emission_sampling \"{other}\"; use \"full\" (the whole emission spectrum) or \
                     \"redshift\" (its part at or above the absorbed wavelength)"
                ))),
            })?
            .unwrap_or(false);
        let absorption_sampler = SpectralSampler::new(&absorption_per_m, range);
        Ok(Fluorescence { absorption_per_m, emission, emission_sampler, absorption_sampler, quantum_yield, redshift })
    }

    /// `phase = "isotropic"` or `{ henyey_greenstein = g }`, −1 < g < 1.
    fn phase(&self, n: Node<'s, '_>) -> R<Phase> {
        if let Ok(name) = n.str() {
            return match name {
                "isotropic" => Ok(Phase::Isotropic),
                other => Err(n.err(format!(
                    "unknown phase function \"{other}\"; use \"isotropic\" or {{ henyey_greenstein = g }}"
                ))),
            };
        }
        if !n.is_table() {
            return Err(n.err("expected \"isotropic\" or { henyey_greenstein = g }"));
        }
        let t = n.table()?;
        t.allow(&["henyey_greenstein"])?;
        let g = t.require("henyey_greenstein", |n| {
            let g = n.f64()?;
            if !(g.abs() < 1.0) {
                return Err(n.err(format!(
                    "the Henyey–Greenstein g is the mean cosine of scattering and must lie strictly between −1 and 1, \
                     found {g}"
                )));
            }
            Ok(g)
        })?;
        Ok(Phase::HenyeyGreenstein { g })
    }

    /// `[[surfaces]]`: every entry parsed, then their names taken in order.
    fn surface_entries(
        &self,
        root: Table<'s, '_>,
        material_index: &HashMap<String, usize>,
        names: &mut Names,
    ) -> R<Vec<Entry>> {
        let entries = root
            .with("surfaces", |n| n.each(|item| self.surface_entry(item.table()?, material_index)))?
            .unwrap_or_default();
        for (i, e) in entries.iter().enumerate() {
            names.claim(self.src.file, &e.name, &index_path("surfaces", i), e.line)?;
        }
        Ok(entries)
    }

    /// `spectrum_bins = N` on a surface or an area light.
    fn spectrum_bins(&self, t: Table<'s, '_>) -> R<Option<usize>> {
        t.with("spectrum_bins", |n| {
            let k = n.u64()?;
            if !(1..=MAX_SPECTRUM_BINS).contains(&k) {
                return Err(n.err(format!("spectrum_bins must be between 1 and {MAX_SPECTRUM_BINS}, found {k}")));
            }
            Ok(k as usize)
        })
    }

    /// One `[[surfaces]]` entry: its keys, material, shape (not yet triangulated) and map.
    fn surface_entry(&self, t: Table<'s, '_>, material_index: &HashMap<String, usize>) -> R<Entry> {
        t.allow(&["name", "material", "shape", "map", "spectrum_bins"])?;
        let spectrum_bins = self.spectrum_bins(t)?;
        let name = self.name(t)?;
        let material = self.material_ref(t, material_index)?;
        let shape = t.require("shape", |n| shapes::parse_shape(n, &self.base_dir, false))?;
        let map = t.with("map", |n| {
            let m = n.table()?;
            m.allow(&["resolution"])?;
            let resolution = m.require("resolution", |n| {
                let r = n.each(|x| x.u64())?;
                if r.len() != 2 || r.iter().any(|&k| !(1..=MAX_MAP_SIDE).contains(&k)) {
                    return Err(n.err(format!("expected [nu, nv], each between 1 and {MAX_MAP_SIDE} texels")));
                }
                Ok([r[0] as usize, r[1] as usize])
            })?;
            let frame = crate::scene::map::frame(&shape);
            if frame.is_none() && !matches!(shape, ShapeSpec::Mesh { .. }) {
                return Err(n.err(
                    "an irradiance map needs a surface of type \"quad\" or \"disk\", or a mesh with \
                     texture coordinates",
                ));
            }
            if let Some([_, u, v]) = frame {
                // The map's axes are the quad's edges from its first corner: they must span a plane.
                if !(u.cross(v).length() > 1e-9 * u.length() * v.length()) {
                    return Err(n.err(
                        "the quad's edges from its first corner (to the second and the fourth corner) are \
                         parallel, so they span no map: list the corners around the quad",
                    ));
                }
            }
            Ok((resolution, frame))
        })?;
        Ok(Entry {
            name,
            material,
            shape,
            map,
            spectrum_bins,
            line: t.line_of_key("name"),
            shape_line: t.line_of_key("shape"),
            map_line: t.line_of_key("map"),
        })
    }

    /// `[[lights]]`: every entry parsed, then their names taken after the surfaces'; a scene
    /// needs at least one light.
    fn light_specs(
        &self,
        root: Table<'s, '_>,
        material_index: &HashMap<String, usize>,
        range: (f64, f64),
        names: &mut Names,
    ) -> R<Vec<LightSpec>> {
        let light_specs = root
            .with("lights", |n| n.each(|item| self.light_spec(item.table()?, material_index, range)))?
            .unwrap_or_default();
        for spec in &light_specs {
            names.claim(self.src.file, &spec.name, &spec.path, spec.line)?;
        }
        if light_specs.is_empty() {
            return Err(self.src.error("lights", None, "the scene has no light: add a [[lights]] entry"));
        }
        Ok(light_specs)
    }

    /// One `[[lights]]` entry: its shape, distribution, power, spectrum and direction, checked
    /// against each other.
    fn light_spec(&self, t: Table<'s, '_>, material_index: &HashMap<String, usize>, range: (f64, f64)) -> R<LightSpec> {
        t.allow(&[
            "name",
            "shape",
            "power_w",
            "power_lm",
            "radiance",
            "spectrum",
            "distribution",
            "material",
            "direction",
            "spectrum_bins",
        ])?;
        let name = self.name(t)?;
        let shape = t.require("shape", |n| shapes::parse_shape(n, &self.base_dir, true))?;
        let material = if t.has("material") { self.material_ref(t, material_index)? } else { 0 };
        let ray_set = match &shape {
            ShapeSpec::Rays { set, .. } => Some(set.clone()),
            _ => None,
        };
        if ray_set.is_some() {
            for (key, why) in [
                ("distribution", "a ray set's rays carry their own directions"),
                ("direction", "a ray set's rays carry their own directions"),
                ("radiance", "a ray set has no area: give `power_w` or `power_lm`, or neither (the file's power)"),
            ] {
                if t.has(key) {
                    return Err(t.err_at(key, format!("{why}: drop `{key}`")));
                }
            }
        }
        let is_point = matches!(shape, ShapeSpec::Point { .. }) || ray_set.is_some();
        let spectrum_bins = self.spectrum_bins(t)?;
        if is_point && spectrum_bins.is_some() {
            return Err(t.err_at(
                "spectrum_bins",
                "a point light is not a surface: nothing arrives on it, so it has no spectrum to tally",
            ));
        }
        // SPEC: area lights default to lambertian; a point light has no surface to be
        // Lambertian about, so it defaults to isotropic.
        let default_distribution = match (&ray_set, is_point) {
            // Each ray leaves along its own direction: a delta in direction, as a collimated beam.
            (Some(_), _) => Distribution::Collimated,
            (None, true) => Distribution::Isotropic,
            (None, false) => Distribution::Lambertian,
        };
        let (distribution, ies) =
            t.with("distribution", |n| self.distribution(n))?.unwrap_or((default_distribution, None));
        if let (Some(ies), false) = (&ies, is_point) {
            if ies.profile.emits_upward() {
                return Err(t.err_at(
                    "distribution",
                    format!(
                        "{} sends light above the horizontal (gamma > 90 degrees), which an area light \
                         cannot emit from its front side: use a point light",
                        ies.file.display()
                    ),
                ));
            }
        }
        let power = match &ray_set {
            Some(set) if !t.has("power_w") && !t.has("power_lm") => PowerSpec::Watts(set.total_w),
            _ => self.light_power(t, ies.as_ref(), range)?,
        };
        if matches!(power, PowerSpec::Radiance(_)) && ies.is_some() {
            return Err(t.err_at(
                "radiance",
                "an IES light takes `power_w`, `power_lm`, or neither (the file's lumens), not `radiance`",
            ));
        }
        if matches!(power, PowerSpec::Radiance(_)) && t.has("spectrum") {
            return Err(t.err_at(
                "spectrum",
                "`radiance` is already a spectrum (a number or a spectrum table): drop `spectrum`, or give `power_w`",
            ));
        }
        let spectrum = match ray_set.as_deref().filter(|set| set.has_wavelengths) {
            Some(set) => {
                if t.has("spectrum") {
                    return Err(t.err_at("spectrum", "the rays carry their own wavelengths: drop `spectrum`"));
                }
                ray_spectrum(set, range).map_err(|m| t.err_at("shape", m))?
            }
            None => t.with("spectrum", |n| self.spectrum(n, SpectrumUse::Emission))?.unwrap_or(Spectrum::Constant(1.0)),
        };
        if !matches!(power, PowerSpec::Radiance(_)) && spectrum.integral(range) <= 0.0 {
            return Err(t.err_at("spectrum", "the spectrum is zero over the whole wavelength range"));
        }
        if matches!(power, PowerSpec::Lumens(_)) && photometry::efficacy_of(&spectrum, range) <= 0.0 {
            return Err(t.err_at(
                if t.has("power_lm") { "power_lm" } else { "spectrum" },
                "this light's spectrum has no visible power in the wavelength range, so lumens cannot set it",
            ));
        }
        let axis = t.with("direction", |n| {
            let d = DVec3::from(n.vec3()?);
            if d.length() == 0.0 {
                return Err(n.err("direction must not be the zero vector"));
            }
            Ok(d.normalize())
        })?;
        if !is_point && axis.is_some() {
            return Err(
                t.err_at("direction", "`direction` is for point lights; an area light emits about its front normal")
            );
        }
        if is_point {
            if matches!(power, PowerSpec::Radiance(_)) {
                return Err(t.err_at(
                    "radiance",
                    "a point light has no area, so it needs `power_w` or `power_lm`, not `radiance`",
                ));
            }
            if t.has("material") {
                return Err(t.err_at("material", "a point light is not a surface and takes no material"));
            }
            if distribution != Distribution::Isotropic && axis.is_none() && ray_set.is_none() {
                return Err(t.err(format!(
                    "a point light with distribution {} needs `direction = [x, y, z]`",
                    distribution.describe()
                )));
            }
        }
        if let PowerSpec::Radiance(_) = power {
            if distribution == Distribution::Collimated {
                return Err(
                    t.err_at("radiance", "a collimated beam has no finite radiance: give `power_w` or `power_lm`")
                );
            }
        }
        let power_key = ["power_w", "power_lm", "radiance"].into_iter().find(|k| t.has(k)).unwrap_or("distribution");
        Ok(LightSpec {
            power_key: (power_key, t.line_of_key(power_key)),
            name,
            material,
            shape,
            power,
            spectrum,
            distribution,
            ies,
            axis,
            spectrum_bins,
            path: t.path.to_string(),
            line: t.line_of_key("name"),
            shape_line: t.line_of_key("shape"),
        })
    }

    /// A light's power as given: exactly one of `power_w`, `power_lm` and `radiance`, or none
    /// for an IES light (the file's lumens).
    fn light_power(&self, t: Table<'s, '_>, ies: Option<&IesLight>, range: (f64, f64)) -> R<PowerSpec> {
        let given: Vec<&str> = ["power_w", "power_lm", "radiance"].into_iter().filter(|k| t.has(k)).collect();
        let power = match given.as_slice() {
            [] if ies.is_some() => PowerSpec::Lumens(ies.map_or(0.0, |i| i.profile.total_lm)),
            [] => {
                return Err(t.err(
                    "missing `power_w` (radiant flux, W), `power_lm` (luminous flux, lm) or `radiance` \
                     (W m^-2 sr^-1 nm^-1)",
                ))
            }
            ["power_w"] | ["power_lm"] => {
                let key = given[0];
                let p = t.req_f64(key)?;
                if !(p > 0.0) {
                    return Err(t.err_at(key, format!("power must be positive, found {p}")));
                }
                if key == "power_w" {
                    PowerSpec::Watts(p)
                } else {
                    PowerSpec::Lumens(p)
                }
            }
            ["radiance"] => {
                let s = t.require("radiance", |n| self.spectrum(n, SpectrumUse::Emission))?;
                if s.integral(range) <= 0.0 {
                    return Err(t.err_at("radiance", "radiance must be positive somewhere in the wavelength range"));
                }
                PowerSpec::Radiance(s)
            }
            _ => return Err(t.err_at(given[1], format!("give only one of {}", given.join(", ")))),
        };
        Ok(power)
    }

    /// Refuses, before any is made, a scene whose shapes of known size (all but meshes) make more
    /// triangles than `max_scene_triangles` allows: 100 spheres of 5·10⁶ triangles must not fill
    /// the memory on their way to a refusal. The budget it returns counts meshes as they are read
    /// (`TriangleBudget::add_mesh`): one file is bounded by its size, but not the same file used
    /// by a thousand surfaces.
    fn check_triangle_budget<'e>(
        &self,
        shapes: impl Iterator<Item = (String, &'e ShapeSpec, usize)>,
    ) -> R<TriangleBudget> {
        let (cap, why) = max_scene_triangles();
        let mut budget = TriangleBudget { cap, why, total: 0 };
        for (entry, shape, line) in shapes {
            if let Some(n) = shape.triangle_count() {
                budget.add(self.src.file, n, &child_path(&entry, "shape"), line, true)?;
            }
        }
        Ok(budget)
    }

    /// Each surface's shape as triangles in metres (f64); a map over a mesh needs texture
    /// coordinates that enclose area on every face.
    fn triangulate_surfaces(
        &self,
        entries: &[Entry],
        unit_m: f64,
        budget: &mut TriangleBudget,
        warnings: &mut Vec<String>,
    ) -> R<Vec<Shaped>> {
        let mut shaped: Vec<Shaped> = Vec::new();
        for (i, e) in entries.iter().enumerate() {
            let key = child_path(&index_path("surfaces", i), "shape");
            let shapes::Triangles { tris: t, tangents, uvs, normals } =
                shapes::triangulate(&e.shape, self.src, &key, e.shape_line, warnings)?;
            budget.add_mesh(self.src.file, &e.shape, t.len(), &key, e.shape_line)?;
            let tris = self.in_metres(t, unit_m, &key, e.shape_line)?;
            if let (Some((_, None)), None) = (&e.map, &uvs) {
                return Err(InputError::new(
                    self.src.file,
                    child_path(&index_path("surfaces", i), "map"),
                    Some(e.map_line),
                    "an irradiance map over a mesh needs texture coordinates (`vt`, and `f v/vt`) on every face",
                ));
            }
            if let (Some((_, None)), Some(uvs)) = (&e.map, &uvs) {
                // A face whose texture coordinates enclose no area has no texels to take its light.
                // Relative to the square of the longest UV edge: rounding noise is not an area.
                let flat = tris.iter().zip(uvs).position(|(t, q)| {
                    let area = (t[1] - t[0]).cross(t[2] - t[0]).length();
                    let edge = (q[1] - q[0]).length().max((q[2] - q[1]).length()).max((q[0] - q[2]).length());
                    area > 0.0 && !(crate::scene::map::polygon_area(q) > 1e-9 * edge * edge)
                });
                if let Some(k) = flat {
                    return Err(InputError::new(
                        self.src.file,
                        child_path(&index_path("surfaces", i), "map"),
                        Some(e.map_line),
                        format!(
                            "triangle {k} (0-based, after splitting faces) of the mesh has texture coordinates that \
                             enclose no area (repeated or collinear `vt`), so its light cannot be mapped"
                        ),
                    ));
                }
            }
            shaped.push(Shaped {
                name: e.name.clone(),
                material: e.material,
                tris,
                tangents,
                normals,
                light: None,
                map: e.map.map(|(r, f)| (r, f.map(|f| f.map(|v| v * unit_m)))),
                uvs,
                spectrum_bins: e.spectrum_bins,
                key,
                line: e.shape_line,
            });
        }
        Ok(shaped)
    }

    /// Each light in metres: an area light's triangles join `shaped`, a point light gives its
    /// position and axis (None for an area light). An IES light's c0 turns with its light.
    fn place_lights(
        &self,
        light_specs: &mut [LightSpec],
        unit_m: f64,
        shaped: &mut Vec<Shaped>,
        budget: &mut TriangleBudget,
        warnings: &mut Vec<String>,
    ) -> R<PlacedLights> {
        let mut point_positions: Vec<Option<(DVec3, DVec3)>> = Vec::with_capacity(light_specs.len());
        let mut ray_sets: Vec<Option<crate::scene::rays::RaySet>> = vec![None; light_specs.len()];
        for (i, spec) in light_specs.iter_mut().enumerate() {
            let key = child_path(&spec.path, "shape");
            // The luminaire turns with its light: c0 is rotated like the point light's direction
            // or the area light's normals.
            let turn = spec.shape.transform().clone();
            if let Some(ies) = &mut spec.ies {
                ies.c0 = ies.c0.map(|c| turn.apply_dir(c).normalize());
            }
            match &spec.shape {
                ShapeSpec::Point { position, transform } => {
                    let p = transform.apply_point(DVec3::from(*position)) * unit_m;
                    if !(p.abs().max_element() <= MAX_COORD_M) {
                        return Err(InputError::new(
                            self.src.file,
                            &key,
                            Some(spec.shape_line),
                            format!("the point light lies at {p:?} m; every point must lie within {MAX_COORD_M:e} m of the origin"),
                        ));
                    }
                    let axis = spec.axis.map(|a| transform.apply_dir(a).normalize()).unwrap_or(DVec3::Z);
                    point_positions.push(Some((p, axis)));
                }
                ShapeSpec::Rays { set, transform, .. } => {
                    let mut moved = (**set).clone();
                    for r in &mut moved.rays {
                        r.position = transform.apply_point(r.position) * unit_m;
                        r.direction = transform.apply_dir(r.direction).normalize();
                    }
                    if let Some(r) = moved.rays.iter().find(|r| !(r.position.abs().max_element() <= MAX_COORD_M)) {
                        return Err(InputError::new(
                            self.src.file,
                            &key,
                            Some(spec.shape_line),
                            format!(
                                "a ray starts at {:?} m; every point must lie within {MAX_COORD_M:e} m of the origin",
                                r.position
                            ),
                        ));
                    }
                    ray_sets[i] = Some(moved);
                    point_positions.push(None);
                }
                other => {
                    let shapes::Triangles { tris: t, tangents, normals, .. } =
                        shapes::triangulate(other, self.src, &key, spec.shape_line, warnings)?;
                    budget.add_mesh(self.src.file, other, t.len(), &key, spec.shape_line)?;
                    let tris = self.in_metres(t, unit_m, &key, spec.shape_line)?;
                    let (name, material, line) = (spec.name.clone(), spec.material, spec.shape_line);
                    shaped.push(Shaped {
                        name,
                        material,
                        tris,
                        tangents,
                        normals,
                        light: Some(i),
                        map: None,
                        uvs: None,
                        spectrum_bins: spec.spectrum_bins,
                        key,
                        line,
                    });
                    point_positions.push(None);
                }
            }
        }
        Ok((point_positions, ray_sets))
    }

    /// Adjacent dielectrics: two closed dielectric surfaces that share a face meet at coincident
    /// triangles (the same three vertices, wound oppositely). Each such pair becomes one triangle
    /// of a new surface "inner|outer" (the lower-numbered dielectric is inner; the triangle is
    /// its, its normal toward the other), a dielectric with ior = inner's and outside_ior =
    /// outer's, inner's medium behind it and outer's in front: light crossing it refracts by the
    /// two indices and changes medium directly. Both must be smooth, untextured and unmapped.
    fn join_shared_faces(
        &self,
        a: &mut Assembled,
        materials: &mut Vec<NamedMaterial>,
        sides: &mut Vec<MediumSides>,
    ) -> R<Vec<Interface>> {
        let is_dielectric =
            |s: usize| matches!(materials[a.surfaces[s].material].material, Material::Dielectric { .. });
        let key = |t: &[Vec3A; 3]| {
            let mut k = t.map(|v| v.to_array().map(f32::to_bits));
            k.sort();
            k
        };
        let mut by_vertices: HashMap<[[u32; 3]; 3], Vec<usize>> = HashMap::new();
        for (prim, t) in a.tris.iter().enumerate() {
            if is_dielectric(a.tri_surface[prim] as usize) {
                by_vertices.entry(key(t)).or_default().push(prim);
            }
        }
        // (inner, outer) → the inner triangles kept; the outer ones are dropped.
        let mut pairs: std::collections::BTreeMap<(usize, usize), Vec<usize>> = Default::default();
        let mut dropped = vec![false; a.tris.len()];
        for prims in by_vertices.values() {
            let &[p, q] = prims.as_slice() else { continue };
            let (sp, sq) = (a.tri_surface[p] as usize, a.tri_surface[q] as usize);
            let normal = |t: &[Vec3A; 3]| (t[1] - t[0]).cross(t[2] - t[0]);
            // Wound the same way the two overlap: left to the shared-face check to refuse.
            if sp == sq || normal(&a.tris[p]).dot(normal(&a.tris[q])) >= 0.0 {
                continue;
            }
            let (inner, outer, keep, drop) = if sp < sq { (sp, sq, p, q) } else { (sq, sp, q, p) };
            pairs.entry((inner, outer)).or_default().push(keep);
            dropped[drop] = true;
        }
        let mut interfaces = Vec::new();
        for ((inner, outer), kept) in pairs {
            let fail = |s: usize, m: String| {
                InputError::new(self.src.file, &a.surface_keys[s].0, Some(a.surface_keys[s].1), m)
            };
            let (
                Material::Dielectric { ior, absorption_per_m, roughness, scatter, .. },
                Material::Dielectric { ior: outer_ior, roughness: r2, scatter: s2, .. },
            ) = (&materials[a.surfaces[inner].material].material, &materials[a.surfaces[outer].material].material)
            else {
                unreachable!("both are dielectrics")
            };
            let (name_in, name_out) = (a.surfaces[inner].name.clone(), a.surfaces[outer].name.clone());
            if roughness.is_rough() || r2.is_rough() || scatter.is_some() || s2.is_some() {
                return Err(fail(
                    inner,
                    format!(
                        "dielectric surfaces \"{name_in}\" and \"{name_out}\" share a face, and adjacent dielectrics must \
                         both be smooth (no roughness, no scatter) for now"
                    ),
                ));
            }
            for s in [inner, outer] {
                if a.surfaces[s].triangles == kept.len() || a.surfaces[s].light.is_some() {
                    return Err(fail(
                        s,
                        format!(
                            "dielectric surfaces \"{name_in}\" and \"{name_out}\" share all of \"{}\"'s faces: a dielectric \
                             wholly inside another is nested, not adjacent (give it its own faces, clear of the other's)",
                            a.surfaces[s].name
                        ),
                    ));
                }
                if a.surfaces[s].map.is_some() || a.surfaces[s].spectrum_bins.is_some() {
                    return Err(fail(
                        s,
                        format!(
                            "dielectric surfaces \"{name_in}\" and \"{name_out}\" share a face, so \"{}\" cannot carry a map \
                             or spectrum_bins (its shared face becomes the surface \"{name_in}|{name_out}\")",
                            a.surfaces[s].name
                        ),
                    ));
                }
            }
            let material = Material::Dielectric {
                ior: ior.clone(),
                outside_ior: outer_ior.clone(),
                absorption_per_m: absorption_per_m.clone(),
                roughness: *roughness,
                scatter: None,
            };
            let name = format!("{name_in}|{name_out}");
            materials.push(NamedMaterial { name: name.clone(), material });
            let (behind, ahead) = (sides[a.surfaces[inner].material].inside, sides[a.surfaces[outer].material].inside);
            sides.push(MediumSides { inside: behind, outside: ahead, outside_line: 0 });
            let surface = a.surfaces.len();
            let area: f64 = kept
                .iter()
                .map(|&p| {
                    let t = a.tris[p].map(|v| v.as_dvec3());
                    0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()
                })
                .sum();
            for &p in &kept {
                a.tri_surface[p] = surface as u32;
            }
            a.surfaces[inner].area_m2 -= area;
            a.surfaces[inner].triangles -= kept.len();
            a.surfaces[outer].area_m2 -= area;
            a.surfaces[outer].triangles -= kept.len();
            a.surfaces.push(Surface {
                name,
                material: materials.len() - 1,
                area_m2: area,
                triangles: kept.len(),
                light: None,
                map: None,
                spectrum_bins: None,
            });
            a.surface_keys.push(a.surface_keys[inner].clone());
            interfaces.push(Interface { surface, inner, outer });
        }
        if dropped.iter().any(|&d| d) {
            let mut k = 0;
            a.tris.retain(|_| (!dropped[k], k += 1).0);
            k = 0;
            a.tri_surface.retain(|_| (!dropped[k], k += 1).0);
            k = 0;
            a.tri_tangent.retain(|_| (!dropped[k], k += 1).0);
            k = 0;
            a.tri_shading.retain(|_| (!dropped[k], k += 1).0);
        }
        Ok(interfaces)
    }

    /// Each shape moved to the recentred origin and into single precision (triangles too thin
    /// for an f32 normal dropped), with its area, irradiance map and spectrum bins.
    fn single_precision_surfaces(
        &self,
        shaped: Vec<Shaped>,
        origin_m: DVec3,
        span_m: f64,
        light_count: usize,
        warnings: &mut Vec<String>,
    ) -> R<Assembled> {
        let mut tris: Vec<[Vec3A; 3]> = Vec::new();
        let mut tri_surface: Vec<u32> = Vec::new();
        let mut tri_tangent: Vec<Vec3A> = Vec::new();
        let mut tri_shading: Vec<[Vec3A; 3]> = Vec::new();
        let mut surfaces: Vec<Surface> = Vec::new();
        let mut light_surface: Vec<Option<(usize, f64)>> = vec![None; light_count];
        let (mut texels, mut spectrum_bins) = (0, 0);
        let mut surface_keys: Vec<(String, usize)> = Vec::new();
        for sh in shaped {
            surface_keys.push((sh.key.clone(), sh.line));
            let local: Vec<[DVec3; 3]> = sh.tris.iter().map(|t| t.map(|v| v - origin_m)).collect();
            let (kept, kept_index) = self.single_precision(local, &sh.key, sh.line, span_m, warnings)?;
            let id = surfaces.len();
            let area: f64 = kept.iter().map(|m| 0.5 * (m[1] - m[0]).cross(m[2] - m[0]).length()).sum();
            for (m, &k) in kept.iter().zip(&kept_index) {
                tris.push(m.map(|v| v.as_vec3a()));
                tri_surface.push(id as u32);
                // Unit in f64 first: a tangent scaled by a tiny or huge transform stays representable.
                tri_tangent.push(sh.tangents[k].normalize_or_zero().as_vec3a());
                let flat = [Vec3A::ZERO; 3];
                let ng = (m[1] - m[0]).cross(m[2] - m[0]).normalize_or_zero();
                // A normal the transform left without length shades nothing, and vertex normals
                // that are the face's own (a CAD export's) change nothing: the triangle is flat.
                let vn =
                    sh.normals.as_ref().and_then(|n| n[k]).filter(|n| {
                        n.iter().all(|v| v.length_squared() > 0.0) && n.iter().any(|v| v.dot(ng) < 1.0 - 1e-9)
                    });
                tri_shading.push(vn.map_or(flat, |n| n.map(|v| v.as_vec3a())));
            }
            let map = sh.map.map(|(resolution, frame)| {
                let map = match (frame, &sh.uvs) {
                    (Some([o, u, v]), _) => {
                        crate::scene::map::SurfaceMap::planar(resolution, o - origin_m, u, v, &kept, texels)
                    }
                    (None, Some(uvs)) => {
                        let uvs: Vec<_> = kept_index.iter().map(|&k| uvs[k]).collect();
                        crate::scene::map::SurfaceMap::textured(resolution, &kept, &uvs, texels)
                    }
                    (None, None) => unreachable!("checked when triangulated"),
                };
                texels += map.texels();
                map
            });
            surfaces.push(Surface {
                name: sh.name,
                material: sh.material,
                area_m2: area,
                triangles: kept.len(),
                light: sh.light,
                map,
                spectrum_bins: sh.spectrum_bins.map(|n| {
                    spectrum_bins += n;
                    (n, spectrum_bins - n)
                }),
            });
            if let Some(l) = sh.light {
                light_surface[l] = Some((id, area));
            }
        }
        Ok(Assembled { tris, tri_surface, tri_tangent, tri_shading, surfaces, light_surface, surface_keys })
    }

    /// Each light at the recentred origin with its power in watts (from watts, lumens, or
    /// radiance over its area), each one and all together within `MAX_POWER_W`; and the line of
    /// each light's shape, for later messages.
    fn lights(
        &self,
        light_specs: Vec<LightSpec>,
        point_positions: &[Option<(DVec3, DVec3)>],
        mut ray_sets: Vec<Option<crate::scene::rays::RaySet>>,
        light_surface: &[Option<(usize, f64)>],
        origin_m: DVec3,
        range: (f64, f64),
    ) -> R<(Vec<Light>, Vec<usize>)> {
        let mut lights = Vec::with_capacity(light_specs.len());
        let mut total_power_w = 0.0;
        let mut light_lines = Vec::with_capacity(light_specs.len());
        for (i, spec) in light_specs.into_iter().enumerate() {
            let (shape, area_m2) = match (point_positions[i], light_surface[i], ray_sets[i].take()) {
                (Some((p, axis)), _, _) => (LightShape::Point { position: p - origin_m, axis }, 0.0),
                (None, Some((surface, area)), _) => (LightShape::Area { surface }, area),
                (None, None, Some(mut set)) => {
                    set.rays.iter_mut().for_each(|r| r.position -= origin_m);
                    (LightShape::Rays { set: std::sync::Arc::new(set) }, 0.0)
                }
                (None, None, None) => unreachable!("every light is a point, a surface or a ray set"),
            };
            let (power_w, spectrum) = match spec.power {
                PowerSpec::Watts(p) => (p, spec.spectrum),
                PowerSpec::Lumens(lm) => (lm / photometry::efficacy_of(&spec.spectrum, range), spec.spectrum),
                PowerSpec::Radiance(radiance) => {
                    // Φ = A ∫∫ L(λ) g(θ) cosθ dω dλ with L(θ) = L·g(θ) along the normal:
                    // ∫ g cosθ dω = π (lambertian), 2π (isotropic: g = 1/cosθ), 2π/(n+1) (cosⁿ: g = cosⁿ⁻¹θ).
                    let projected_sr = match spec.distribution {
                        Distribution::Lambertian => std::f64::consts::PI,
                        Distribution::Isotropic => 2.0 * std::f64::consts::PI,
                        Distribution::CosinePower(n) => 2.0 * std::f64::consts::PI / (n + 1.0),
                        Distribution::Collimated | Distribution::Ies => unreachable!("rejected above"),
                    };
                    (area_m2 * projected_sr * radiance.integral(range), radiance)
                }
            };
            light_lines.push(spec.shape_line);
            // Each light, and all of them together, must keep the tallies finite.
            total_power_w += power_w;
            let too_much = if !(power_w <= MAX_POWER_W) {
                Some(format!("light \"{}\" would emit {power_w:e} W", spec.name))
            } else if !(total_power_w <= MAX_POWER_W) {
                Some(format!("the lights together would emit {total_power_w:e} W"))
            } else {
                None
            };
            if let Some(what) = too_much {
                let (key, line) = spec.power_key;
                return Err(InputError::new(
                    self.src.file,
                    child_path(&spec.path, key),
                    Some(line),
                    format!(
                        "{what}; photon accepts up to {MAX_POWER_W:e} W in all (the Sun emits 3.8e26 W), \
                         beyond which its tallies cannot stay finite"
                    ),
                ));
            }
            let lm_per_w = photometry::efficacy_of(&spectrum, range);
            lights.push(Light {
                name: spec.name,
                shape,
                power_w,
                spectrum,
                lm_per_w,
                distribution: spec.distribution,
                ies: spec.ies,
            });
        }
        Ok((lights, light_lines))
    }

    /// Refuses a scene where more than `MOST_STACKED` triangles lie exactly on one another (the
    /// same three corners, in any order): a mesh that repeats a face. Copies share one box,
    /// which no tree can split: a few hundred made the tree deeper than the traversal allows,
    /// after a build whose time grew as the square of their number (20 000 copies: 10 s).
    fn check_stacked_triangles(
        &self,
        tris: &[[Vec3A; 3]],
        tri_surface: &[u32],
        surfaces: &[Surface],
        surface_keys: &[(String, usize)],
    ) -> R<()> {
        // The corners' bits, sorted (−0 taken as +0): one key for every order of one triangle.
        let corners = |t: &[Vec3A; 3]| {
            let mut c = t.map(|v| (v + Vec3A::ZERO).to_array().map(f32::to_bits));
            c.sort_unstable();
            c
        };
        // Sorted by a 64-bit hash of the key (16 bytes a triangle, not the key's 36); a run of
        // equal hashes is then counted by its exact keys.
        let hash = |c: &[[u32; 3]; 3]| {
            c.iter().flatten().fold(0x9E37_79B9_7F4A_7C15u64, |h, &w| {
                (h ^ w as u64).wrapping_mul(0xFF51_AFD7_ED55_8CCD).rotate_left(29)
            })
        };
        let mut hashes: Vec<(u64, u32)> = tris.iter().enumerate().map(|(i, t)| (hash(&corners(t)), i as u32)).collect();
        hashes.sort_unstable();
        for run in hashes.chunk_by(|a, b| a.0 == b.0).filter(|run| run.len() > MOST_STACKED) {
            let mut copies: HashMap<[[u32; 3]; 3], Vec<u32>> = HashMap::new();
            for &(_, i) in run {
                copies.entry(corners(&tris[i as usize])).or_default().push(i);
            }
            if let Some(stack) = copies.values().find(|stack| stack.len() > MOST_STACKED) {
                let s = tri_surface[stack[0] as usize] as usize;
                let mut names: Vec<&str> =
                    stack.iter().map(|&i| surfaces[tri_surface[i as usize] as usize].name.as_str()).collect();
                names.dedup();
                let whose = match names.as_slice() {
                    [one] => format!("surface \"{one}\""),
                    [a, b] => format!("surfaces \"{a}\" and \"{b}\""),
                    [a, .., z] => format!("{} surfaces from \"{a}\" to \"{z}\"", names.len()),
                    [] => unreachable!("a stack holds more than MOST_STACKED triangles"),
                };
                return Err(InputError::new(
                    self.src.file,
                    &surface_keys[s].0,
                    Some(surface_keys[s].1),
                    format!(
                        "{} triangles of {whose} lie exactly on one another (the same three corners: a face \
                         repeated), and photon traces at most {MOST_STACKED} copies of one triangle; remove the \
                         repeats",
                        stack.len()
                    ),
                ));
            }
        }
        Ok(())
    }

    /// A point light on a surface would shoot half its rays from inside the surface's rounding
    /// band, where no hit can be resolved: they would leak through. Refuse it.
    fn check_point_lights_off_surfaces(
        &self,
        lights: &[Light],
        light_lines: &[usize],
        tris: &[[Vec3A; 3]],
        tri_surface: &[u32],
        surfaces: &[Surface],
    ) -> R<()> {
        for (i, (l, spec_line)) in lights.iter().zip(light_lines).enumerate() {
            if let LightShape::Point { position, .. } = l.shape {
                for (t, &s) in tris.iter().zip(tri_surface) {
                    let tri = t.map(|v| v.as_dvec3());
                    let scale = tri.iter().chain([&position]).map(|v| v.abs().max_element()).fold(0.0, f64::max);
                    let d = point_triangle_distance(position, &tri);
                    if d <= 1e-6 * scale {
                        return Err(InputError::new(
                            self.src.file,
                            child_path(&index_path("lights", i), "shape"),
                            Some(*spec_line),
                            format!(
                                "point light \"{}\" lies on surface \"{}\" ({d:.1e} m away): move it off the surface",
                                l.name, surfaces[s as usize].name
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// An area light lying in another surface's plane and overlapping it (a lamp quad on the
    /// ceiling, as the Cornell box's is published): rays meet both at the same distance and
    /// rounding picks either, so every integrator sees part of the lamp as the other surface.
    /// Warned once for each such pair; skipped when the light's triangles times the scene's would
    /// exceed `FLUSH_CHECK_PAIRS` tests.
    fn warn_of_lights_flush_with_surfaces(
        &self,
        lights: &[Light],
        light_lines: &[usize],
        tris: &[[Vec3A; 3]],
        tri_surface: &[u32],
        surfaces: &[Surface],
        warnings: &mut Vec<String>,
    ) {
        for (l, line) in lights.iter().zip(light_lines) {
            let LightShape::Area { surface } = l.shape else { continue };
            let own: Vec<[DVec3; 3]> = tris
                .iter()
                .zip(tri_surface)
                .filter(|(_, &s)| s as usize == surface)
                .map(|(t, _)| t.map(|v| v.as_dvec3()))
                .collect();
            if own.len().saturating_mul(tris.len()) > FLUSH_CHECK_PAIRS {
                continue;
            }
            let mut flush_with = vec![false; surfaces.len()];
            for (t, &s) in tris.iter().zip(tri_surface) {
                if s as usize == surface || flush_with[s as usize] {
                    continue;
                }
                let other = t.map(|v| v.as_dvec3());
                flush_with[s as usize] = own.iter().any(|lamp| coplanar_overlap(lamp, &other));
            }
            for (s, _) in flush_with.iter().enumerate().filter(|(_, &f)| f) {
                warnings.push(format!(
                    "{}:{line}: light \"{}\" lies in the plane of surface \"{}\" and overlaps it: rays meet both at \
                     the same distance and either may be hit, so images show part of the lamp as that surface and \
                     photons arriving there may reflect off it; move the light off the surface by a small gap (the \
                     Cornell box lowers its lamp 0.1 mm)",
                    self.src.file.display(),
                    l.name,
                    surfaces[s].name
                ));
            }
        }
    }

    /// An IES table's C = 0 plane is c0 projected off the light's axis: parallel, it has no
    /// projection. Checked against a point light's direction and each of an area light's normals.
    fn check_ies_c0_planes(&self, lights: &[Light], tris: &[[Vec3A; 3]], tri_surface: &[u32]) -> R<()> {
        for (i, l) in lights.iter().enumerate() {
            let Some(c0) = l.ies.as_ref().and_then(|ies| ies.c0.map(|c| (c, ies.c0_line))) else { continue };
            let (c0, c0_line) = c0;
            let axes: Vec<DVec3> = match &l.shape {
                LightShape::Point { axis, .. } => vec![*axis],
                LightShape::Rays { .. } => vec![],
                LightShape::Area { surface } => tris
                    .iter()
                    .zip(tri_surface)
                    .filter(|(_, &s)| s as usize == *surface)
                    .map(|(t, _)| {
                        let [a, b, c] = t.map(|v| v.as_dvec3());
                        (b - a).cross(c - a).normalize()
                    })
                    .collect(),
            };
            if let Some(k) = axes.iter().position(|a| a.cross(c0).length() < 1e-3) {
                let whose = match l.shape {
                    LightShape::Point { .. } | LightShape::Rays { .. } => {
                        "the light's direction (its nadir)".to_string()
                    }
                    LightShape::Area { .. } if axes.iter().all(|a| (*a - axes[0]).length() < 1e-9) => {
                        "the light's normal (its nadir)".to_string()
                    }
                    LightShape::Area { .. } => format!("the normal (the nadir) of the light's triangle {k}"),
                };
                return Err(InputError::new(
                    self.src.file,
                    child_path(&child_path(&index_path("lights", i), "distribution"), "c0"),
                    Some(c0_line),
                    format!(
                        "c0 of light \"{}\" is parallel to {whose}, so it picks no C = 0 plane: give a \
                         direction across the axis",
                        l.name
                    ),
                ));
            }
        }
        Ok(())
    }

    /// `[reference]`: an optional known answer, for `photon converge` to measure the observed
    /// error against.
    fn reference(&self, root: Table<'s, '_>, surfaces: &[Surface]) -> R<Option<Reference>> {
        root.with("reference", |n| {
            let t = n.table()?;
            t.allow(&["surface", "incident_w", "note"])?;
            let name = t.req_str("surface")?;
            let surface = surfaces
                .iter()
                .position(|s| s.name == name)
                .ok_or_else(|| t.err_at("surface", format!("no surface named \"{name}\"")))?;
            let incident_w = t.req_f64("incident_w")?;
            if !(incident_w > 0.0) {
                return Err(t.err_at("incident_w", format!("a reference power must be positive, found {incident_w}")));
            }
            let note = t.str("note")?.unwrap_or_default();
            Ok(Reference { surface, incident_w, note })
        })
    }

    /// A dielectric has an inside (the side its normals point away from), so it must be a closed,
    /// consistently oriented surface with outward normals; one inside another (nested) must say
    /// so (its `outside_ior` the other's `ior`, its `outside_medium` the other's `medium`); no two
    /// share a face; and the camera must be outside them all (camera paths start in air): each
    /// is checked here, where the README's promise can be kept, rather than misjudged photons
    /// later.
    #[allow(clippy::too_many_arguments)]
    fn check_dielectrics(
        &self,
        geo: &Geometry,
        surfaces: &[Surface],
        materials: &[NamedMaterial],
        keys: &[(String, usize)],
        sides: &[&MediumSides],
        media: &[Medium],
        interfaces: &[Interface],
        camera: Option<&Camera>,
        camera_line: usize,
    ) -> R<Dielectrics> {
        // Per surface: the interface it is, if it is one.
        let mut interface_of: Vec<Option<&Interface>> = vec![None; surfaces.len()];
        for i in interfaces {
            interface_of[i.surface] = Some(i);
        }
        let is_dielectric = |s: usize| {
            interface_of[s].is_none() && matches!(materials[surfaces[s].material].material, Material::Dielectric { .. })
        };
        let dielectrics: Vec<usize> = (0..surfaces.len()).filter(|&s| is_dielectric(s)).collect();
        let mut volume = vec![0.0f64; surfaces.len()];
        let mut outside = vec![None; surfaces.len()];
        let mut inside: Vec<u32> = (0..surfaces.len() as u32).collect();
        for i in interfaces {
            inside[i.surface] = i.inner as u32;
            outside[i.surface] = Some(i.outer as u32);
        }
        if dielectrics.is_empty() {
            return Ok(Dielectrics { volume, outside, inside });
        }
        // A ray's crossings of an interface are crossings of both dielectrics it parts.
        let crossings_of = |start: Vec3A, skip: u32| {
            let mut c = geo.crossings(start, skip, surfaces.len());
            for i in interfaces {
                let k = c[i.surface];
                c[i.inner] += k;
                c[i.outer] += k;
            }
            c
        };
        let fail = |s: usize, m: String| InputError::new(self.src.file, &keys[s].0, Some(keys[s].1), m);
        // Edges by their end points' exact f32 bits: each must be used twice, once each way.
        let mut first_prim = vec![u32::MAX; surfaces.len()];
        // (surface, the edge's two end points) → (its uses, uses one way minus the other).
        let mut edges: HashMap<(usize, EdgeKey), (u32, i32)> = HashMap::new();
        for prim in 0..geo.len() {
            let s = geo.surface_of(prim) as usize;
            // An interface's triangle bounds both its dielectrics, the outer one reversed.
            let bounds: [(usize, i32); 2] = match interface_of[s] {
                Some(i) => [(i.inner, 1), (i.outer, -1)],
                None if is_dielectric(s) => [(s, 1), (usize::MAX, 0)],
                None => continue,
            };
            if interface_of[s].is_none() && first_prim[s] == u32::MAX {
                first_prim[s] = prim as u32;
            }
            let v = geo.verts(prim);
            let d = v.map(|p| p.as_dvec3());
            for (s, sign) in bounds.into_iter().filter(|b| b.1 != 0) {
                volume[s] += sign as f64 * d[0].dot(d[1].cross(d[2])) / 6.0;
                for k in 0..3 {
                    let (a, b) = (v[k].to_array().map(f32::to_bits), v[(k + 1) % 3].to_array().map(f32::to_bits));
                    let (key, way) = if a < b { ([a, b], sign) } else { ([b, a], -sign) };
                    let e = edges.entry((s, key)).or_insert((0, 0));
                    e.0 += 1;
                    e.1 += way;
                }
            }
        }
        let bad: Vec<(usize, &'static str)> = edges
            .iter()
            .filter_map(|(&(s, _), &(count, way))| match (count, way) {
                (2, 0) => None,
                (1, _) => Some((s, "is not closed: some edges belong to one triangle only")),
                (2, _) => Some((
                    s,
                    "has faces of opposite orientation: neighbouring triangles list a shared edge the same way",
                )),
                _ => Some((s, "is not a manifold: some edges are shared by more than two triangles")),
            })
            .collect();
        if let Some(&(s, what)) = bad.iter().min() {
            return Err(fail(
                s,
                format!(
                    "dielectric surface \"{}\" {what}; a dielectric bounds a volume, so it must be a closed surface \
                     (a box, a sphere, a closed mesh)",
                    surfaces[s].name
                ),
            ));
        }
        for &s in &dielectrics {
            if volume[s] < 0.0 {
                return Err(fail(
                    s,
                    format!(
                        "the normals of dielectric surface \"{}\" point inward (a negative scale, or a mesh wound \
                         the other way), so its inside would be the world outside it: flip it",
                        surfaces[s].name
                    ),
                ));
            }
        }
        // Two dielectrics sharing a face (adjacent volumes) meet at coincident triangles, and which
        // one a ray hits there is arbitrary: a short ray through each dielectric triangle's
        // centroid, along its normal, finds another dielectric's triangle within the
        // centroid's own rounding distance of its plane.
        if dielectrics.len() > 1 {
            for prim in 0..geo.len() {
                let s = geo.surface_of(prim) as usize;
                if !is_dielectric(s) {
                    continue;
                }
                let (c, err) = geo.hit_point(&crate::geometry::Hit { t: 0.0, prim: prim as u32, b: [1.0 / 3.0; 3] });
                let n = geo.normal(prim);
                let reach = 4.0 * (n.abs().dot(err + c.abs() * f32::EPSILON) + f32::MIN_POSITIVE);
                let hit = geo.intersect(c - n * reach, n, 2.0 * reach, prim as u32);
                if let Some(other) =
                    hit.map(|h| geo.surface_of(h.prim as usize) as usize).filter(|&o| o != s && is_dielectric(o))
                {
                    return Err(fail(
                        s,
                        format!(
                            "dielectric surfaces \"{}\" and \"{}\" share a face, but their triangles there do not match \
                             vertex for vertex, wound oppositely: adjacent dielectrics must meet at the same \
                             triangles (or nest one inside the other, clear of its faces)",
                            surfaces[other].name, surfaces[s].name
                        ),
                    ));
                }
            }
        }
        // The dielectrics around each one's first triangle, by ray parity (one probe point per
        // surface: it finds nesting, not every partial overlap).
        let around: Vec<Vec<usize>> = (0..surfaces.len())
            .map(|s| {
                if !is_dielectric(s) {
                    return Vec::new();
                }
                let prim = first_prim[s];
                let (p, _) = geo.hit_point(&crate::geometry::Hit { t: 0.0, prim, b: [1.0 / 3.0; 3] });
                let crossings = crossings_of(p, prim);
                dielectrics.iter().copied().filter(|&d| d != s && crossings[d] % 2 == 1).collect()
            })
            .collect();
        for &s in &dielectrics {
            // Directly around s: the deepest of those around it, whose own surroundings must be
            // the rest (else the two cross).
            let Some(&parent) = around[s].iter().max_by_key(|&&d| around[d].len()) else { continue };
            let name = |d: usize| &surfaces[d].name;
            if around[parent].len() + 1 != around[s].len()
                || around[s].iter().any(|&d| d != parent && !around[parent].contains(&d))
            {
                return Err(fail(
                    s,
                    format!(
                        "dielectric surface \"{}\" crosses dielectric \"{}\": dielectrics may nest but not overlap",
                        name(s),
                        name(parent)
                    ),
                ));
            }
            let (Material::Dielectric { outside_ior, .. }, Material::Dielectric { ior: parent_ior, .. }) =
                (&materials[surfaces[s].material].material, &materials[surfaces[parent].material].material)
            else {
                unreachable!("both are dielectrics")
            };
            let material = &materials[surfaces[s].material].name;
            if outside_ior != parent_ior {
                return Err(fail(
                    s,
                    format!(
                        "dielectric surface \"{}\" lies inside dielectric \"{}\", so its outside is that one's inside: \
                         material \"{material}\" needs outside_ior equal to the ior of material \"{}\"",
                        name(s),
                        name(parent),
                        materials[surfaces[parent].material].name
                    ),
                ));
            }
            if sides[s].outside != sides[parent].inside {
                let medium =
                    |m: Option<u32>| m.map_or("none".to_string(), |m| format!("\"{}\"", media[m as usize].name));
                return Err(fail(
                    s,
                    format!(
                        "dielectric surface \"{}\" lies inside dielectric \"{}\", which is filled with medium {}, but \
                         material \"{material}\" has outside_medium {}: the media on a boundary's two sides must be \
                         declared as they are",
                        name(s),
                        name(parent),
                        medium(sides[parent].inside),
                        medium(sides[s].outside)
                    ),
                ));
            }
            outside[s] = Some(parent as u32);
        }
        for &s in &dielectrics {
            if let (None, Some(m)) = (outside[s], sides[s].outside) {
                return Err(fail(
                    s,
                    format!(
                        "material \"{}\" (line {}) has outside_medium \"{}\", but dielectric surface \"{}\" lies in \
                         no other dielectric: its outside is the world, with no medium",
                        materials[surfaces[s].material].name,
                        sides[s].outside_line,
                        media[m as usize].name,
                        surfaces[s].name
                    ),
                ));
            }
        }
        let inside_of = |point: Vec3A, skip: u32, not: usize| -> Option<usize> {
            let crossings = crossings_of(point, skip);
            dielectrics.iter().copied().find(|&d| d != not && crossings[d] % 2 == 1)
        };
        if let Some(c) = camera {
            if let Some(d) = inside_of(c.position.as_vec3a(), crate::geometry::NO_PRIM, usize::MAX) {
                return Err(InputError::new(
                    self.src.file,
                    "camera.position",
                    Some(camera_line),
                    format!(
                        "the camera is inside dielectric surface \"{}\"; camera paths start in air, so the camera \
                         must be outside every dielectric",
                        surfaces[d].name
                    ),
                ));
            }
        }
        Ok(Dielectrics { volume, outside, inside })
    }

    /// Scales a shape's triangles to metres. Coordinates too far out for the BVH's f32 bounds
    /// are an error (it would panic on them).
    fn in_metres(&self, tris: Vec<[DVec3; 3]>, unit_m: f64, key: &str, line: usize) -> R<Vec<[DVec3; 3]>> {
        let tris: Vec<[DVec3; 3]> = tris.into_iter().map(|t| t.map(|v| v * unit_m)).collect();
        if let Some(c) = tris.iter().flatten().map(|v| v.abs().max_element()).find(|c| !(*c <= MAX_COORD_M)) {
            return Err(InputError::new(
                self.src.file,
                key,
                Some(line),
                format!("a coordinate reaches {c:e} m; every point must lie within {MAX_COORD_M:e} m of the origin"),
            ));
        }
        Ok(tris)
    }

    /// Checks triangles at the single precision the tracer uses: one too thin to have an f32
    /// normal is dropped with a warning (it would give NaN directions); a shape left with no
    /// triangle is an error.
    fn single_precision(
        &self,
        tris: Vec<[DVec3; 3]>,
        key: &str,
        line: usize,
        scene_span_m: f64,
        warnings: &mut Vec<String>,
    ) -> R<(Vec<[DVec3; 3]>, Vec<usize>)> {
        let total = tris.len();
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for v in tris.iter().flatten() {
            (lo, hi) = (lo.min(*v), hi.max(*v));
        }
        let (size_m, reach_m) = ((hi - lo).max_element(), lo.abs().max(hi.abs()).max_element());
        let (kept_index, kept): (Vec<usize>, Vec<[DVec3; 3]>) = tris
            .into_iter()
            .enumerate()
            .filter(|(_, t)| {
                let [a, b, c] = t.map(|v| v.as_vec3a());
                let n = (b - a).cross(c - a);
                n.is_finite() && n.length_squared() > 0.0 && n.normalize().is_finite()
            })
            .unzip();
        if kept.is_empty() {
            // Far from the scene's centre, f32 cannot resolve a small shape: that is the scene's
            // extent at fault (often one far-off light or object), not the shape.
            let message = if size_m < 1e-5 * reach_m {
                format!(
                    "the shape is {size_m:.3e} m across but lies {reach_m:.3e} m from the centre of the scene, \
                     which spans {scene_span_m:.3e} m: single precision cannot resolve it there; bring the \
                     scene's surfaces and lights closer together"
                )
            } else {
                "the shape has no area at single precision: it is too thin for its size".to_string()
            };
            return Err(InputError::new(self.src.file, key, Some(line), message));
        }
        if kept.len() < total {
            warnings.push(format!(
                "{}:{line}: `{key}`: {} of {total} triangles are too thin to have a normal at single precision; skipped",
                self.src.file.display(),
                total - kept.len()
            ));
        }
        Ok((kept, kept_index))
    }

    fn unit(&self, root: Table<'s, '_>) -> R<f64> {
        let unit = root.with("scene", |n| {
            let t = n.table()?;
            t.allow(&["unit"])?;
            t.with("unit", |u| match u.str()? {
                "m" => Ok(1.0),
                "cm" => Ok(0.01),
                "mm" => Ok(0.001),
                other => Err(u.err(format!("unknown unit \"{other}\"; use \"m\", \"cm\" or \"mm\""))),
            })
        })?;
        Ok(unit.flatten().unwrap_or(1.0))
    }

    fn simulation(&self, root: Table<'s, '_>) -> R<Simulation> {
        let mut sim = Simulation {
            photons: 1_000_000,
            seed: 1,
            max_bounces: 100_000,
            wavelength_range_nm: (360.0, 830.0),
            integrator: Integrator::Light,
        };
        root.with("simulation", |n| {
            let t = n.table()?;
            t.allow(&["photons", "seed", "max_bounces", "wavelength_range_nm", "integrator"])?;
            if let Some(i) = t.with("integrator", |n| {
                let name = n.str()?;
                Integrator::parse(name)
                    .ok_or_else(|| n.err(format!("unknown integrator \"{name}\"; use \"light\", \"path\" or \"bdpt\"")))
            })? {
                sim.integrator = i;
            }
            if let Some(p) = t.with("photons", |n| n.u64())? {
                if p == 0 {
                    return Err(t.err_at("photons", "photons must be at least 1"));
                }
                if p > super::MAX_PHOTONS {
                    return Err(t.err_at("photons", format!("photons must be at most {} (2^48)", super::MAX_PHOTONS)));
                }
                sim.photons = p;
            }
            if let Some(s) = t.with("seed", |n| n.u64())? {
                sim.seed = s;
            }
            if let Some(b) = t.with("max_bounces", |n| n.u64())? {
                sim.max_bounces = b.min(u32::MAX as u64) as u32;
            }
            if let Some(r) = t.with("wavelength_range_nm", |n| {
                let items = n.each(|x| x.f64())?;
                if items.len() != 2 || !(items[0] >= 1.0 && items[0] < items[1] && items[1] <= 100_000.0) {
                    return Err(n.err("expected [min, max] in nm with 1 <= min < max <= 100000"));
                }
                Ok((items[0], items[1]))
            })? {
                sim.wavelength_range_nm = r;
            }
            Ok(())
        })?;
        Ok(sim)
    }

    fn name(&self, t: Table<'s, '_>) -> R<String> {
        let name = t.req_str("name")?;
        if name.trim().is_empty() {
            return Err(t.err_at("name", "name must not be empty"));
        }
        Ok(name)
    }

    fn material_ref(&self, t: Table<'s, '_>, index: &HashMap<String, usize>) -> R<usize> {
        t.require("material", |n| {
            let name = n.str()?;
            index.get(name).copied().ok_or_else(|| {
                let mut known: Vec<&str> = index.keys().map(String::as_str).collect();
                known.sort();
                n.err(format!("no material named \"{name}\"; defined materials: {}", known.join(", ")))
            })
        })
    }

    fn material(&self, n: Node<'s, '_>, range: (f64, f64)) -> R<Material> {
        let t = n.table()?;
        let kind = t.req_str("type")?;
        let fraction = |key: &str, default: f64| -> R<Spectrum> {
            let s = t.with(key, |n| {
                let s = self.spectrum(n, SpectrumUse::Fraction)?;
                let (lo, hi) = s.min_max_over(range);
                if lo < 0.0 || hi > 1.0 {
                    return Err(
                        n.err(format!("{key} must lie in [0, 1] at every wavelength; found values from {lo} to {hi}"))
                    );
                }
                Ok(s)
            })?;
            Ok(s.unwrap_or(Spectrum::Constant(default)))
        };
        match kind.as_str() {
            "absorber" => {
                t.allow(&["type"])?;
                Ok(Material::Absorber)
            }
            "lambertian" => {
                t.allow(&["type", "reflectance", "transmittance"])?;
                let reflectance = fraction("reflectance", 0.5)?;
                let transmittance = fraction("transmittance", 0.0)?;
                let (r, tr) = (&reflectance, &transmittance);
                let mut xs = r.breakpoints(range);
                xs.extend(tr.breakpoints(range));
                if let Some(&x) = xs.iter().find(|&&x| r.eval(x) + tr.eval(x) > 1.0 + 1e-12) {
                    return Err(t.err(format!(
                        "reflectance + transmittance must not exceed 1; at {x} nm it is {} + {} = {}",
                        r.eval(x),
                        tr.eval(x),
                        r.eval(x) + tr.eval(x)
                    )));
                }
                Ok(Material::Lambertian { reflectance, transmittance })
            }
            "mirror" => {
                t.allow(&["type", "reflectance", "scatter"])?;
                Ok(Material::Mirror {
                    reflectance: fraction("reflectance", 1.0)?,
                    scatter: self.scatter(t, Roughness::SMOOTH)?,
                })
            }
            "conductor" => {
                t.allow(&["type", "metal", "eta", "k", "roughness", "specular_reflectance", "scatter"])?;
                let named = t.with("metal", |n| {
                    let name = n.str()?;
                    let (eta, k, cover) = crate::scene::catalog::metal(name).ok_or_else(|| {
                        let known: Vec<&str> = crate::scene::catalog::METALS.iter().map(|m| m.0).collect();
                        n.err(format!("unknown metal \"{name}\"; bundled metals: {}", known.join(", ")))
                    })?;
                    if range.0 < cover.0 || range.1 > cover.1 {
                        return Err(n.err(format!(
                            "the table of {name} covers {} to {} nm, but the simulation's wavelength_range_nm is \
                             [{}, {}]: narrow the range or give `eta` and `k`",
                            cover.0, cover.1, range.0, range.1
                        )));
                    }
                    Ok((eta, k))
                })?;
                let (eta, k) = match named {
                    Some(nk) => {
                        if let Some(key) = ["eta", "k"].into_iter().find(|key| t.has(key)) {
                            return Err(t.err_at(key, "give either `metal` or `eta` and `k`, not both"));
                        }
                        nk
                    }
                    None => {
                        let eta = t.require("eta", |n| {
                            let s = self.spectrum(n, SpectrumUse::Ior)?;
                            let (lo, _) = s.min_max_over(range);
                            if !(lo > 0.0) {
                                return Err(n.err(format!("eta must be positive at every wavelength; found {lo}")));
                            }
                            Ok(s)
                        })?;
                        let k = t.require("k", |n| self.spectrum(n, SpectrumUse::NonNegative))?;
                        (eta, k)
                    }
                };
                let roughness = self.roughness(t)?;
                let scatter = self.scatter(t, roughness)?;
                let specular_reflectance = fraction("specular_reflectance", 1.0)?;
                Ok(Material::Conductor { eta, k, specular_reflectance, roughness, scatter })
            }
            "plastic" => {
                t.allow(&["type", "diffuse_reflectance", "ior", "roughness"])?;
                let diffuse_reflectance = fraction("diffuse_reflectance", 0.5)?;
                let ior = t
                    .with("ior", |n| {
                        let x = n.f64()?;
                        if !(1.0..=3.0).contains(&x) {
                            return Err(n.err(format!("a plastic's coat index must lie in [1, 3], found {x}")));
                        }
                        Ok(x)
                    })?
                    .unwrap_or(1.5);
                let roughness = self.roughness(t)?;
                Ok(Material::Plastic { diffuse_reflectance, ior, roughness })
            }
            "dielectric" => {
                t.allow(&[
                    "type",
                    "ior",
                    "outside_ior",
                    "absorption_per_m",
                    "roughness",
                    "scatter",
                    "medium",
                    "outside_medium",
                ])?;
                let ior_of = |key: &str, default: f64| -> R<Spectrum> {
                    let s = t.with(key, |n| {
                        let s = self.spectrum(n, SpectrumUse::DielectricIor { range })?;
                        let (lo, _) = s.min_max_over(range);
                        if !(lo > 0.0) {
                            return Err(n.err(format!("{key} must be positive at every wavelength; found {lo}")));
                        }
                        Ok(s)
                    })?;
                    Ok(s.unwrap_or(Spectrum::Constant(default)))
                };
                let ior = ior_of("ior", 1.5)?;
                let outside_ior = ior_of("outside_ior", 1.0)?;
                let absorption_per_m = t.with("absorption_per_m", |n| self.spectrum(n, SpectrumUse::NonNegative))?;
                let roughness = self.roughness(t)?;
                let scatter = self.scatter(t, roughness)?;
                Ok(Material::Dielectric { ior, outside_ior, absorption_per_m, roughness, scatter })
            }
            other => Err(t.err_at(
                "type",
                format!(
                    "unknown material type \"{other}\"; known types: absorber, lambertian, mirror, conductor, plastic, \
                     dielectric"
                ),
            )),
        }
    }

    /// `roughness`: the GGX α, or `[αu, αv]` along and across the surface tangent; each in
    /// [0, 1], 0 (smooth) by default. An α below `SMOOTH_ROUGHNESS` is smooth: both of them, and
    /// so is the surface; one alone (a perfect brush, `[0, 0.3]`), and it is raised to
    /// `SMOOTH_ROUGHNESS`, since a microfacet lobe cannot be a delta along one axis only (at
    /// 10⁻⁴ it is far narrower than any detector resolves).
    fn roughness(&self, t: Table<'s, '_>) -> R<Roughness> {
        let alpha = |n: Node<'s, '_>| -> R<f64> {
            let a = n.f64()?;
            if !(0.0..=1.0).contains(&a) {
                return Err(n.err(format!("roughness (GGX α) must lie in [0, 1], found {a}")));
            }
            Ok(a)
        };
        let roughness = t
            .with("roughness", |n| {
                if n.is_number() {
                    return Ok(Roughness::isotropic(alpha(n)?));
                }
                if n.array().is_err() {
                    return Err(
                        n.err("expected a number (the GGX α) or [αu, αv] (along and across the surface tangent)")
                    );
                }
                match n.each(alpha)?[..] {
                    [u, v] => Ok(Roughness { u, v }),
                    ref other => Err(n.err(format!(
                        "anisotropic roughness is [αu, αv], two numbers (along and across the surface tangent); \
                         found {}",
                        other.len()
                    ))),
                }
            })?
            .unwrap_or(Roughness::SMOOTH);
        let smooth = |a: f64| a < crate::scene::SMOOTH_ROUGHNESS;
        Ok(match (smooth(roughness.u), smooth(roughness.v)) {
            (true, true) => Roughness::SMOOTH,
            (false, false) => roughness,
            _ => Roughness {
                u: roughness.u.max(crate::scene::SMOOTH_ROUGHNESS),
                v: roughness.v.max(crate::scene::SMOOTH_ROUGHNESS),
            },
        })
    }

    /// `scatter = { abg = [A, B, g] }` on a smooth surface: A > 0, 0 < B ≤ 1e100 (or B = 0 with
    /// g = 0), 0 ≤ g ≤ 8, and at most all of the specular power scattered at any incidence.
    fn scatter(&self, t: Table<'s, '_>, roughness: Roughness) -> R<Option<Abg>> {
        t.with("scatter", |n| {
            if roughness.is_rough() {
                return Err(n.err(
                    "ABg scatter applies to a smooth surface (it takes its power from the specular reflection); \
                     give either `roughness` or `scatter`",
                ));
            }
            let st = n.table()?;
            st.allow(&["abg"])?;
            st.require("abg", |n| {
                let v = n.each(|x| x.f64())?;
                let [a, b, g] = v[..] else {
                    return Err(n.err(format!("expected [A, B, g], three numbers; found {} values", v.len())));
                };
                if !(a > 0.0 && a.is_finite()) {
                    return Err(n.err(format!("A must be positive and finite, found {a}")));
                }
                if !(0.0..=8.0).contains(&g) {
                    return Err(n.err(format!("g must lie in [0, 8], found {g}")));
                }
                // B = 0 is a finite, flat lobe for g = 0 and an infinite peak otherwise.
                if !((b > 0.0 || (b == 0.0 && g == 0.0)) && b <= 1e100) {
                    return Err(
                        n.err(format!("B must be positive (0 allowed only with g = 0) and at most 1e100, found {b}"))
                    );
                }
                let abg = Abg { a, b, g };
                let tis = abg.normal_incidence_tis();
                if tis > 1.0 {
                    return Err(n.err(format!(
                        "these A, B, g scatter {tis:.4} of the specular power at normal incidence (TIS = \
                         ∫ BSDF cosθ dω over the hemisphere); it must not exceed 1: lower A to at most {:.6e}",
                        a / tis
                    )));
                }
                Ok(abg)
            })
        })
    }

    fn distribution(&self, n: Node<'s, '_>) -> R<(Distribution, Option<IesLight>)> {
        if n.is_table() {
            let t = n.table()?;
            t.allow(&["cosine_power", "ies", "ldt", "c0"])?;
            if let Some(key) = ["ies", "ldt"].into_iter().find(|k| t.has(k)) {
                for other in ["cosine_power", "ldt"] {
                    if other != key && t.has(other) {
                        return Err(t.err_at(
                            other,
                            format!("give one of `ies`, `ldt` and `cosine_power`, not both `{key}` and `{other}`"),
                        ));
                    }
                }
                let rel = t.req_str(key)?;
                let file = self.base_dir.join(rel);
                let line = t.line_of_key(key);
                let read = match key {
                    "ies" => crate::scene::ies::IesProfile::read(&file),
                    _ => crate::scene::ldt::read(&file),
                };
                let kind = if key == "ies" { "IES" } else { "EULUMDAT" };
                let profile = read.map_err(|mut e| {
                    e.message = format!(
                        "{} ({kind} file named by `{}` at {}:{line})",
                        e.message,
                        child_path(t.path, key),
                        self.src.file.display()
                    );
                    e
                })?;
                let c0 = t.with("c0", |n| {
                    let d = DVec3::from(n.vec3()?);
                    if !(d.length() > 0.0) {
                        return Err(n.err("c0 must not be the zero vector"));
                    }
                    Ok(d.normalize())
                })?;
                let c0_line = t.line_of_key("c0");
                return Ok((
                    Distribution::Ies,
                    Some(IesLight { profile: std::sync::Arc::new(profile), c0, c0_line, file }),
                ));
            }
            if t.has("c0") {
                return Err(t.err_at(
                    "c0",
                    "`c0` orients an intensity table: it needs `ies = \"file.ies\"` or `ldt = \"file.ldt\"`",
                ));
            }
            let p = t.require("cosine_power", |n| {
                let p = n.f64()?;
                if p < 0.0 {
                    return Err(n.err(format!("cosine_power must be >= 0, found {p}")));
                }
                Ok(p)
            })?;
            return Ok((Distribution::CosinePower(p), None));
        }
        let d = match n.str()? {
            "lambertian" => Distribution::Lambertian,
            "isotropic" => Distribution::Isotropic,
            "collimated" => Distribution::Collimated,
            other => {
                return Err(n.err(format!(
                    "unknown distribution \"{other}\"; known: \"lambertian\", \"isotropic\", \"collimated\", \
                     {{ cosine_power = n }}, {{ ies = \"file.ies\" }}, {{ ldt = \"file.ldt\" }}"
                )))
            }
        };
        Ok((d, None))
    }

    /// `[[detectors]]`: far-field detectors, `type = "farfield"`, `resolution = [n_gamma, n_c]`,
    /// optional `name`, `nadir` (default [0, 0, -1]) and `c0` (see `ies::Frame`); volume
    /// detectors and work planes (`volume_detector`, `work_plane`).
    #[allow(clippy::type_complexity)]
    fn detectors(
        &self,
        root: Table<'s, '_>,
        origin_m: DVec3,
        unit_m: f64,
        surfaces: &[Surface],
    ) -> R<(
        Vec<crate::scene::farfield::FarField>,
        Vec<crate::scene::volume::VolumeGrid>,
        Vec<crate::scene::plane::WorkPlane>,
        Vec<crate::scene::rays::RayDetector>,
    )> {
        let mut out: Vec<crate::scene::farfield::FarField> = Vec::new();
        let mut volumes: Vec<crate::scene::volume::VolumeGrid> = Vec::new();
        let mut planes: Vec<crate::scene::plane::WorkPlane> = Vec::new();
        let mut ray_detectors: Vec<crate::scene::rays::RayDetector> = Vec::new();
        root.with("detectors", |n| {
            n.each(|item| {
                let t = item.table()?;
                let kind = t.req_str("type")?;
                if kind == "volume" {
                    volumes.push(self.volume_detector(t, origin_m, unit_m, &volumes)?);
                    return Ok(());
                }
                if kind == "plane" {
                    planes.push(self.work_plane(t, origin_m, unit_m, surfaces, &planes)?);
                    return Ok(());
                }
                if kind == "rays" {
                    ray_detectors.push(self.ray_detector(t, surfaces, &ray_detectors)?);
                    return Ok(());
                }
                t.allow(&["type", "name", "resolution", "nadir", "c0"])?;
                if kind != "farfield" {
                    return Err(t.err_at(
                        "type",
                        format!(
                            "unknown detector type \"{kind}\"; known: \"farfield\", \"plane\", \"rays\", \"volume\""
                        ),
                    ));
                }
                let name = t.str("name")?.unwrap_or_else(|| format!("farfield{}", out.len()));
                if out.iter().any(|d| d.name == name) {
                    return Err(t.err_at("name", format!("a detector named \"{name}\" already exists")));
                }
                let stem = crate::scene::map::file_stem(&name);
                if stem.len() > MAX_NAME_BYTES {
                    return Err(t.err_at(
                        "name",
                        format!(
                            "a name of {} bytes is too long: it names farfield_<name>.csv; at most {MAX_NAME_BYTES}",
                            name.len()
                        ),
                    ));
                }
                if let Some(d) = out.iter().find(|d| crate::scene::map::file_stem(&d.name) == stem) {
                    return Err(t.err_at(
                        "name",
                        format!(
                            "detectors \"{}\" and \"{name}\" would both write farfield_{stem}.csv: rename one",
                            d.name
                        ),
                    ));
                }
                let resolution = t.require("resolution", |n| {
                    let r = n.each(|x| x.u64())?;
                    if r.len() != 2 || r.iter().any(|&k| !(1..=MAX_MAP_SIDE).contains(&k)) {
                        return Err(n.err(format!("expected [n_gamma, n_c], each between 1 and {MAX_MAP_SIDE}")));
                    }
                    Ok([r[0] as usize, r[1] as usize])
                })?;
                let unit = |key: &str| {
                    t.with(key, |n| {
                        let d = DVec3::from(n.vec3()?);
                        if !(d.length() > 0.0) {
                            return Err(n.err(format!("{key} must not be the zero vector")));
                        }
                        Ok(d.normalize().as_vec3a())
                    })
                };
                let nadir = unit("nadir")?.unwrap_or(Vec3A::NEG_Z);
                let c0 = unit("c0")?;
                if let Some(c) = c0 {
                    if c.cross(nadir).length() < 1e-6 {
                        return Err(t.err_at("c0", "c0 must not be parallel to the nadir"));
                    }
                }
                let offset = out.iter().map(|d| d.bins()).sum();
                out.push(crate::scene::farfield::FarField {
                    name,
                    resolution,
                    frame: crate::scene::ies::Frame::new(nadir, c0),
                    offset,
                });
                Ok(())
            })
        })?;
        Ok((out, volumes, planes, ray_detectors))
    }

    /// `type = "rays"`: `name`, `surface` (a surface's name), `max_rays` (default 10⁷).
    fn ray_detector(
        &self,
        t: Table<'s, '_>,
        surfaces: &[Surface],
        earlier: &[crate::scene::rays::RayDetector],
    ) -> R<crate::scene::rays::RayDetector> {
        t.allow(&["type", "name", "surface", "max_rays"])?;
        let name = t.str("name")?.unwrap_or_else(|| format!("rays{}", earlier.len()));
        let stem = crate::scene::map::file_stem(&name);
        if stem.len() > MAX_NAME_BYTES {
            return Err(t.err_at(
                "name",
                format!(
                    "a name of {} bytes is too long: it names rays_<name>.npy; at most {MAX_NAME_BYTES}",
                    name.len()
                ),
            ));
        }
        if let Some(d) = earlier.iter().find(|d| crate::scene::map::file_stem(&d.name) == stem) {
            return Err(t.err_at(
                "name",
                format!("ray-set detectors \"{}\" and \"{name}\" would both write rays_{stem}.npy: rename one", d.name),
            ));
        }
        let wanted = t.req_str("surface")?;
        let Some(surface) = surfaces.iter().position(|s| s.name == wanted) else {
            let known: Vec<&str> = surfaces.iter().map(|s| s.name.as_str()).collect();
            return Err(
                t.err_at("surface", format!("no surface is named \"{wanted}\"; surfaces: {}", known.join(", ")))
            );
        };
        if let Some(d) = earlier.iter().find(|d| d.surface == surface) {
            return Err(t.err_at("surface", format!("ray-set detector \"{}\" already records \"{wanted}\"", d.name)));
        }
        let max_rays = t
            .with("max_rays", |n| {
                let v = n.u64()?;
                if !(1..=crate::scene::rays::MAX_RAYS).contains(&v) {
                    return Err(n.err(format!("max_rays must be between 1 and {}", crate::scene::rays::MAX_RAYS)));
                }
                Ok(v)
            })?
            .unwrap_or(10_000_000);
        Ok(crate::scene::rays::RayDetector { name, surface, max_rays })
    }

    /// `type = "plane"`: `name`, `corners = [a, b, c, d]` (the file's unit; a parallelogram,
    /// c = b + d − a, its front the side (b − a) × (c − a) points to), `resolution = [nu, nv]`.
    fn work_plane(
        &self,
        t: Table<'s, '_>,
        origin_m: DVec3,
        unit_m: f64,
        surfaces: &[Surface],
        earlier: &[crate::scene::plane::WorkPlane],
    ) -> R<crate::scene::plane::WorkPlane> {
        t.allow(&["type", "name", "corners", "resolution"])?;
        let name = t.str("name")?.unwrap_or_else(|| format!("plane{}", earlier.len()));
        let stem = crate::scene::map::file_stem(&name);
        if stem.len() > MAX_NAME_BYTES {
            return Err(t.err_at(
                "name",
                format!(
                    "a name of {} bytes is too long: it names maps/<name>.exr; at most {MAX_NAME_BYTES}",
                    name.len()
                ),
            ));
        }
        let mapped = surfaces.iter().filter(|s| s.map.is_some()).map(|s| ("surface", &s.name));
        let named = earlier.iter().map(|p| ("work plane", &p.name)).chain(mapped);
        if let Some((what, other)) = named.into_iter().find(|(_, n)| crate::scene::map::file_stem(n) == stem) {
            return Err(t.err_at(
                "name",
                format!("{what} \"{other}\" and work plane \"{name}\" would both write maps/{stem}.exr: rename one"),
            ));
        }
        let corners = t.require("corners", |n| {
            let points = n.each(|p| Ok(DVec3::from(p.vec3()?) * unit_m))?;
            let [a, b, c, d]: [DVec3; 4] =
                points.try_into().map_err(|_| n.err("expected four corners [a, b, c, d]"))?;
            if [a, b, c, d].iter().any(|p| !(p.abs().max_element() <= MAX_COORD_M)) {
                return Err(n.err(format!("every corner must lie within {MAX_COORD_M:e} m of the origin")));
            }
            let (u, v) = (b - a, d - a);
            let size = u.length().max(v.length());
            if !(u.cross(v).length() > 1e-9 * size * size) {
                return Err(n.err("the corners span no area (a, b and d lie on one line)"));
            }
            if !((c - (b + d - a)).length() <= 1e-6 * size) {
                return Err(n.err(
                    "the corners must form a parallelogram, c = b + d − a (a rectangle in order around its edge)",
                ));
            }
            Ok([a - origin_m, b - origin_m, d - origin_m])
        })?;
        let resolution = t.require("resolution", |n| {
            let r = n.each(|x| x.u64())?;
            if r.len() != 2 || r.iter().any(|&k| !(1..=MAX_MAP_SIDE).contains(&k)) {
                return Err(n.err(format!("expected [nu, nv], each between 1 and {MAX_MAP_SIDE} texels")));
            }
            Ok([r[0] as usize, r[1] as usize])
        })?;
        let offset = surfaces.iter().filter_map(|s| s.map.as_ref()).map(|m| m.texels()).sum::<usize>()
            + earlier.iter().map(|p| p.slots()).sum::<usize>();
        Ok(crate::scene::plane::WorkPlane::new(name, resolution, corners, offset))
    }

    /// `type = "volume"`: `name`, `min`, `max` (the file's unit), `resolution = [nx, ny, nz]`.
    fn volume_detector(
        &self,
        t: Table<'s, '_>,
        origin_m: DVec3,
        unit_m: f64,
        earlier: &[crate::scene::volume::VolumeGrid],
    ) -> R<crate::scene::volume::VolumeGrid> {
        t.allow(&["type", "name", "min", "max", "resolution"])?;
        let name = t.str("name")?.unwrap_or_else(|| format!("volume{}", earlier.len()));
        let stem = crate::scene::map::file_stem(&name);
        if stem.len() > MAX_NAME_BYTES {
            return Err(t.err_at(
                "name",
                format!(
                    "a name of {} bytes is too long: it names volume_<name>.npy; at most {MAX_NAME_BYTES}",
                    name.len()
                ),
            ));
        }
        if let Some(d) = earlier.iter().find(|d| crate::scene::map::file_stem(&d.name) == stem) {
            return Err(t.err_at(
                "name",
                format!(
                    "volume detectors \"{}\" and \"{name}\" would both write volume_{stem}.npy: rename one",
                    d.name
                ),
            ));
        }
        let corner = |key: &str| -> R<DVec3> {
            let p = DVec3::from(t.req_vec3(key)?) * unit_m;
            if !(p.abs().max_element() <= MAX_COORD_M) {
                return Err(t.err_at(key, format!("every point must lie within {MAX_COORD_M:e} m of the origin")));
            }
            Ok(p)
        };
        let (min, max) = (corner("min")?, corner("max")?);
        if !(max.cmpgt(min).all()) {
            return Err(t.err_at("max", "every coordinate of max must exceed min's"));
        }
        let resolution = t.require("resolution", |n| {
            let r = n.each(|x| x.u64())?;
            if r.len() != 3 || r.iter().any(|&k| !(1..=MAX_MAP_SIDE).contains(&k)) {
                return Err(n.err(format!("expected [nx, ny, nz], each between 1 and {MAX_MAP_SIDE} voxels")));
            }
            if r.iter().product::<u64>() > MAX_VOXELS {
                return Err(n.err(format!(
                    "{} voxels are too many: at most {MAX_VOXELS} (each keeps four f64 tallies per thread)",
                    r.iter().product::<u64>()
                )));
            }
            Ok([r[0] as usize, r[1] as usize, r[2] as usize])
        })?;
        let offset = earlier.iter().map(|v| v.voxels()).sum();
        Ok(crate::scene::volume::VolumeGrid { name, min: min - origin_m, max: max - origin_m, resolution, offset })
    }

    fn camera(&self, t: Table<'s, '_>, unit_m: f64) -> R<Camera> {
        t.allow(&["position", "look_at", "up", "fov_deg", "resolution"])?;
        let point = |key: &str| -> R<DVec3> {
            let p = DVec3::from(t.req_vec3(key)?) * unit_m;
            if !(p.abs().max_element() <= MAX_COORD_M) {
                return Err(t.err_at(key, format!("every point must lie within {MAX_COORD_M:e} m of the origin")));
            }
            Ok(p)
        };
        let (position, look_at) = (point("position")?, point("look_at")?);
        let up = DVec3::from(t.vec3("up")?.unwrap_or([0.0, 1.0, 0.0]));
        let forward = look_at - position;
        if forward.length() == 0.0 {
            return Err(t.err_at("look_at", "look_at equals position: the camera has a zero-length view direction"));
        }
        if up.length() == 0.0 || forward.normalize().cross(up.normalize()).length() < 1e-9 {
            let message = if t.has("up") {
                "up must be non-zero and not parallel to the view direction"
            } else {
                "the default up [0, 1, 0] is parallel to the view direction: give `up`"
            };
            return Err(t.err_at("up", message));
        }
        let fov_deg = t.req_f64("fov_deg")?;
        if !(fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(t.err_at("fov_deg", format!("fov_deg must be in (0, 180), found {fov_deg}")));
        }
        let resolution = t
            .with("resolution", |n| {
                let r = n.each(|x| x.u64())?;
                if r.len() != 2 || r[0] == 0 || r[1] == 0 || r[0].checked_mul(r[1]).is_none_or(|n| n > MAX_PIXELS) {
                    return Err(n.err(format!(
                        "expected [width, height] of at least 1 pixel each and at most {MAX_PIXELS} pixels in all"
                    )));
                }
                Ok([r[0] as u32, r[1] as u32])
            })?
            .unwrap_or([512, 512]);
        Ok(Camera { position, look_at, up, fov_deg, resolution })
    }

    /// A spectrum: a number, `{ blackbody_k }`, `{ file }`, `{ table }`, or (ior only) `{ cauchy }`;
    /// a dielectric's index also a bundled glass's name or `{ sellmeier }`.
    fn spectrum(&self, n: Node<'s, '_>, usage: SpectrumUse) -> R<Spectrum> {
        if n.is_number() {
            let v = n.f64()?;
            if v < 0.0 {
                return Err(n.err(format!("must not be negative, found {v}")));
            }
            return Ok(Spectrum::Constant(v));
        }
        if let (SpectrumUse::DielectricIor { range }, Ok(name)) = (usage, n.str()) {
            return named_glass(n, name, range);
        }
        if !n.is_table() {
            if let SpectrumUse::DielectricIor { .. } = usage {
                return Err(n.err(format!(
                    "expected a number, a bundled glass ({}) or a spectrum table: {{ file = \"x.csv\" }}, {{ table = \
                     [[nm, n], ...] }}, {{ cauchy = [A, B_um2] }}, {{ sellmeier = {{ B = [...], C = [...] }} }}",
                    glass_names()
                )));
            }
            return Err(n.err("expected a number or a spectrum table: { blackbody_k = T }, { file = \"x.csv\" }, { table = [[nm, value], ...] }"));
        }
        let t = n.table()?;
        let keys: Vec<&str> = t.keys().collect();
        let allowed: &[&str] = match usage {
            SpectrumUse::Emission => &["blackbody_k", "file", "table"],
            SpectrumUse::Ior => &["file", "table", "cauchy"],
            SpectrumUse::DielectricIor { .. } => &["file", "table", "cauchy", "sellmeier"],
            SpectrumUse::Fraction | SpectrumUse::NonNegative => &["file", "table"],
        };
        t.allow(allowed)?;
        if keys.len() != 1 {
            return Err(t.err(format!("a spectrum table takes exactly one of: {}", allowed.join(", "))));
        }
        match keys[0] {
            "blackbody_k" => {
                let k = t.req_f64("blackbody_k")?;
                if !(k > 0.0 && k <= MAX_BLACKBODY_K) {
                    return Err(t.err_at(
                        "blackbody_k",
                        format!("temperature must be positive and at most {MAX_BLACKBODY_K:e} K, found {k}"),
                    ));
                }
                Ok(Spectrum::Blackbody { kelvin: k })
            }
            "cauchy" => t.require("cauchy", |n| {
                let c = n.each(|x| x.f64())?;
                if c.len() != 2 {
                    return Err(n.err("expected cauchy = [A, B_um2]"));
                }
                Ok(Spectrum::Cauchy { a: c[0], b_um2: c[1] })
            }),
            "sellmeier" => {
                let SpectrumUse::DielectricIor { range } = usage else { unreachable!("allowed for dielectrics only") };
                t.require("sellmeier", |n| sellmeier(n, range))
            }
            "table" => t.require("table", |n| {
                let points = n.each(|row| {
                    let v = row.each(|x| x.f64())?;
                    if v.len() != 2 {
                        return Err(row.err("expected a [wavelength_nm, value] pair"));
                    }
                    Ok((v[0], v[1]))
                })?;
                // An empty table has no row to point at: the table itself is at fault.
                crate::spectrum::check_table(&points).map_err(|(i, m)| match n.array().unwrap().get(i) {
                    Some(item) => Node { src: n.src, path: &index_path(n.path, i), value: item }.err(m),
                    None => n.err(m),
                })?;
                Ok(Spectrum::Table(crate::spectrum::Table::new(points)))
            }),
            "file" => t.require("file", |n| {
                let rel = n.str()?;
                let path = self.base_dir.join(rel);
                crate::spectrum::read_csv(&path).map_err(|mut e| {
                    e.message = format!(
                        "{} (spectrum file named by `{}` at {}:{})",
                        e.message,
                        n.path,
                        self.src.file.display(),
                        self.src.line_of(n.value.span().start)
                    );
                    e
                })
            }),
            _ => unreachable!(),
        }
    }
}

#[derive(Clone, Copy)]
enum SpectrumUse {
    Emission,
    Fraction,
    Ior,
    /// A dielectric's `ior` or `outside_ior`, which may also name a bundled glass or give
    /// Sellmeier terms, both checked over the simulated wavelength range.
    DielectricIor {
        range: (f64, f64),
    },
    NonNegative,
}

/// The bundled glasses' names, for messages.
fn glass_names() -> String {
    crate::scene::catalog::GLASSES.iter().map(|g| format!("\"{}\"", g.0)).collect::<Vec<_>>().join(", ")
}

/// `ior = "BK7"`: a bundled glass, whose table or formula must cover the simulated range.
fn named_glass(n: Node<'_, '_>, name: &str, range: (f64, f64)) -> R<Spectrum> {
    let (s, cover) = crate::scene::catalog::glass(name)
        .ok_or_else(|| n.err(format!("unknown glass \"{name}\"; bundled glasses: {}", glass_names())))?;
    if range.0 < cover.0 || range.1 > cover.1 {
        let what = if matches!(s, Spectrum::Table(_)) { "table" } else { "dispersion formula" };
        return Err(n.err(format!(
            "the {what} of {name} covers {} to {} nm, but the simulation's wavelength_range_nm is [{}, {}]: narrow \
             the range or give the index as a spectrum (`table`, `file`, `cauchy` or `sellmeier`)",
            cover.0, cover.1, range.0, range.1
        )));
    }
    Ok(s)
}

/// `sellmeier = { B = [...], C = [...] }`: n² = 1 + Σ Bᵢλ²/(λ² − Cᵢ), λ in µm, Cᵢ in µm²; 1 to 6
/// terms, C ≥ 0, no pole λ² = Cᵢ in the simulated range and n² > 0 throughout it.
fn sellmeier(n: Node<'_, '_>, range: (f64, f64)) -> R<Spectrum> {
    const MAX_TERMS: usize = 6;
    let t = n.table()?;
    t.allow(&["B", "C"])?;
    let terms_of = |key: &str| {
        t.require(key, |n| {
            let v = n.each(|x| {
                let v = x.f64()?;
                if key == "C" {
                    if v < 0.0 {
                        return Err(x.err(format!(
                            "C (a resonance wavelength squared, in µm²) must not be negative, found {v}"
                        )));
                    }
                    if let Some(pole) = crate::spectrum::sellmeier_pole_in(v, range) {
                        return Err(x.err(format!(
                            "C = {v} µm² puts a pole of n² (λ² = C, at {pole:.1} nm) inside the simulated \
                             wavelength_range_nm [{}, {}], where the index would be infinite",
                            range.0, range.1
                        )));
                    }
                }
                Ok(v)
            })?;
            if v.is_empty() || v.len() > MAX_TERMS {
                return Err(n.err(format!("expected 1 to {MAX_TERMS} Sellmeier terms, found {}", v.len())));
            }
            Ok(v)
        })
    };
    let b = terms_of("B")?;
    let c = terms_of("C")?;
    if b.len() != c.len() {
        return Err(t.err(format!(
            "B and C must have one entry per Sellmeier term, the same number each; found {} B and {} C",
            b.len(),
            c.len()
        )));
    }
    let terms: Vec<(f64, f64)> = b.into_iter().zip(c).collect();
    crate::spectrum::check_sellmeier(&terms, range).map_err(|m| t.err(m))?;
    Ok(Spectrum::Sellmeier { terms })
}

fn simplify(s: &mut Spectrum, range: (f64, f64)) {
    if let Some(c) = s.constant_over(range) {
        *s = Spectrum::Constant(c);
    }
}

fn simplify_material(m: &mut Material, range: (f64, f64)) {
    match m {
        Material::Absorber => {}
        Material::Lambertian { reflectance, transmittance } => {
            simplify(reflectance, range);
            simplify(transmittance, range);
        }
        Material::Mirror { reflectance, .. } => simplify(reflectance, range),
        Material::Plastic { diffuse_reflectance, .. } => simplify(diffuse_reflectance, range),
        Material::Conductor { eta, k, specular_reflectance, .. } => {
            simplify(eta, range);
            simplify(k, range);
            simplify(specular_reflectance, range);
        }
        Material::Dielectric { ior, outside_ior, absorption_per_m, .. } => {
            simplify(ior, range);
            simplify(outside_ior, range);
            if let Some(a) = absorption_per_m {
                simplify(a, range);
            }
        }
    }
}

/// Light triangles × scene triangles above which the check for lights flush with surfaces is
/// skipped (about a second's work).
const FLUSH_CHECK_PAIRS: usize = 100_000_000;

/// Whether the triangles lie in one plane, to single precision (the smaller's vertices within a
/// few f32 roundings of the coordinates of the larger's plane: a small triangle's own normal,
/// tilted by its rounding, would miss a large one's far vertices), and overlap with some area:
/// touching along an edge (a lamp set into a hole of the ceiling) is no overlap.
/// Separating-axis test in the larger's plane.
fn coplanar_overlap(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    let area = |t: &[DVec3; 3]| (t[1] - t[0]).cross(t[2] - t[0]).length_squared();
    let (a, b) = if area(b) > area(a) { (b, a) } else { (a, b) };
    let scale = a.iter().chain(b).map(|v| v.abs().max_element()).fold(0.0, f64::max);
    let tol = 4.0 * f32::EPSILON as f64 * scale;
    let (lo, hi) = (a[0].min(a[1]).min(a[2]), a[0].max(a[1]).max(a[2]));
    let (blo, bhi) = (b[0].min(b[1]).min(b[2]), b[0].max(b[1]).max(b[2]));
    if (blo - hi).max_element() > tol || (lo - bhi).max_element() > tol {
        return false;
    }
    let normal = (a[1] - a[0]).cross(a[2] - a[0]);
    let Some(n) = normal.try_normalize() else { return false };
    if b.iter().any(|v| n.dot(*v - a[0]).abs() > tol) {
        return false;
    }
    // In-plane coordinates, then each edge's outward normal as a candidate separating axis.
    let u = (a[1] - a[0]).normalize();
    let w = n.cross(u);
    let flat = |t: &[DVec3; 3]| t.map(|v| glam::DVec2::new(u.dot(v - a[0]), w.dot(v - a[0])));
    let (fa, fb) = (flat(a), flat(b));
    let separated_along = |axis: glam::DVec2| {
        let span = |t: &[glam::DVec2; 3]| {
            t.iter().map(|p| axis.dot(*p)).fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| (l.min(x), h.max(x)))
        };
        let ((la, ha), (lb, hb)) = (span(&fa), span(&fb));
        // Overlapping by no more than the tolerance: touching, not overlapping.
        ha.min(hb) - la.max(lb) <= tol * axis.length()
    };
    let edges = |t: [glam::DVec2; 3]| (0..3).map(move |k| (t[(k + 1) % 3] - t[k]).perp());
    !edges(fa).chain(edges(fb)).any(separated_along)
}

/// Distance from `p` to the closest point of triangle `t` (Ericson, Real-Time Collision
/// Detection, §5.1.5: classify p against the triangle's Voronoi regions).
fn point_triangle_distance(p: DVec3, t: &[DVec3; 3]) -> f64 {
    let [a, b, c] = *t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (p - (a + ab * (d1 / (d1 - d3)))).length();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (p - (a + ac * (d2 / (d2 - d6)))).length();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return (p - (b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))))).length();
    }
    let denom = 1.0 / (va + vb + vc);
    (p - (a + ab * (vb * denom) + ac * (vc * denom))).length()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lamp triangle on a 550 mm ceiling: overlapping it in its plane, 0.1 mm below it, beside
    /// it sharing an edge, apart in the plane, across it, and overlapping by a sliver.
    #[test]
    fn coplanar_overlap_needs_one_plane_and_some_area() {
        let v = |x: f64, y: f64, z: f64| DVec3::new(x, y, z);
        let ceiling = [v(0.0, 548.8, 0.0), v(556.0, 548.8, 0.0), v(0.0, 548.8, 559.2)];
        let lamp = |y: f64| [v(213.0, y, 227.0), v(343.0, y, 227.0), v(213.0, y, 332.0)];
        assert!(coplanar_overlap(&lamp(548.8), &ceiling) && coplanar_overlap(&ceiling, &lamp(548.8)));
        assert!(!coplanar_overlap(&lamp(548.7), &ceiling), "0.1 mm apart");
        // The ceiling's other half shares the diagonal with it: touching, not overlapping.
        let other_half = [v(556.0, 548.8, 0.0), v(556.0, 548.8, 559.2), v(0.0, 548.8, 559.2)];
        assert!(!coplanar_overlap(&other_half, &ceiling));
        let apart = [v(600.0, 548.8, 0.0), v(700.0, 548.8, 0.0), v(600.0, 548.8, 100.0)];
        assert!(!coplanar_overlap(&apart, &ceiling));
        let across = [v(100.0, 500.0, 100.0), v(100.0, 600.0, 100.0), v(200.0, 500.0, 100.0)];
        assert!(!coplanar_overlap(&across, &ceiling));
        // A triangle beyond the diagonal with one corner 2 mm across it.
        let sliver = [v(277.0, 548.8, 278.0), v(556.0, 548.8, 559.2), v(556.0, 548.8, 300.0)];
        assert!(coplanar_overlap(&sliver, &ceiling));
    }

    #[test]
    fn point_triangle_distance_in_each_region() {
        let t = [DVec3::ZERO, DVec3::X, DVec3::Y];
        assert_eq!(point_triangle_distance(DVec3::new(0.2, 0.2, 3.0), &t), 3.0); // face
        assert_eq!(point_triangle_distance(DVec3::new(-1.0, -1.0, 0.0), &t), 2f64.sqrt()); // vertex a
        assert_eq!(point_triangle_distance(DVec3::new(0.5, -2.0, 0.0), &t), 2.0); // edge ab
        assert!((point_triangle_distance(DVec3::new(1.0, 1.0, 0.0), &t) - 0.5f64.sqrt()).abs() < 1e-15);
        // edge bc
    }
}
