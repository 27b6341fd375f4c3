//! What `photon info` prints, and the same facts as data (`scene_info`, the Python module's
//! `Scene.info()`).

use crate::scene::{LightShape, Scene};

/// The text of `photon info`.
pub fn describe(scene: &Scene) -> String {
    let mut s = format!("scene {}\n", scene.path.display());
    s.push_str(&format!("surfaces ({}):\n", scene.surfaces.len()));
    let name_w =
        scene.surfaces.iter().map(|x| x.name.len()).chain(scene.lights.iter().map(|l| l.name.len())).max().unwrap_or(4);
    let materials: Vec<String> = scene
        .surfaces
        .iter()
        .map(|x| format!("{} ({})", scene.materials[x.material].name, scene.materials[x.material].material.kind()))
        .collect();
    let mat_w = materials.iter().map(String::len).max().unwrap_or(8);
    for (surf, material) in scene.surfaces.iter().zip(&materials) {
        s.push_str(&format!(
            "  {:<name_w$}  {:<mat_w$}  {:>8} triangles  {:>12.6} m²{}\n",
            surf.name,
            material,
            surf.triangles,
            surf.area_m2,
            if surf.light.is_some() { "  [light]" } else { "" }
        ));
    }
    s.push_str(&format!("lights ({}):\n", scene.lights.len()));
    for l in &scene.lights {
        let shape = match &l.shape {
            LightShape::Area { surface } => {
                format!("area, {:.6} m²", scene.surfaces[*surface].area_m2)
            }
            LightShape::Rays { set } => format!("ray set, {} rays", set.rays.len()),
            LightShape::Point { position, .. } => {
                let p = scene.file_coordinates(*position);
                let unit = if scene.unit_m == 0.01 {
                    "cm"
                } else if scene.unit_m == 0.001 {
                    "mm"
                } else {
                    "m"
                };
                format!("point at [{}, {}, {}] {unit}", round_shown(p.x), round_shown(p.y), round_shown(p.z))
            }
        };
        let distribution = match &l.ies {
            Some(ies) => format!("ies {}", ies.file.display()),
            None => l.distribution.describe(),
        };
        s.push_str(&format!(
            "  {:<name_w$}  {:>12.6} W  {:>10.1} lm  {}  {}\n",
            l.name,
            l.power_w,
            l.power_w * l.lm_per_w,
            distribution,
            shape
        ));
    }
    if !scene.media.is_empty() {
        s.push_str(&format!("media ({}):\n", scene.media.len()));
        let (lo, hi) = scene.simulation.wavelength_range_nm;
        for m in &scene.media {
            // Six significant digits at most: a fitted table's tails reach 1e-13.
            let sig = |v: f64| {
                if v == 0.0 || (1e-3..1e6).contains(&v.abs()) {
                    format!("{}", (v * 1e4).round() / 1e4)
                } else {
                    format!("{v:.3e}")
                }
            };
            let range = |x: &crate::spectrum::Spectrum| {
                let (a, b) = x.min_max_over((lo, hi));
                if a == b {
                    sig(a)
                } else {
                    format!("{}–{}", sig(a), sig(b))
                }
            };
            let phase = match m.phase {
                crate::scene::Phase::Isotropic => "isotropic".to_string(),
                crate::scene::Phase::HenyeyGreenstein { g } => format!("Henyey–Greenstein g = {g}"),
            };
            s.push_str(&format!(
                "  {}  μa {} /m, μs {} /m, {phase}, {:.6e} m³\n",
                m.name,
                range(&m.absorption_per_m),
                range(&m.scattering_per_m),
                m.volume_m3
            ));
            if let Some(f) = &m.fluorescence {
                s.push_str(&format!(
                    "    luminophore μf {} /m, quantum yield {}, emission peak {} nm{}\n",
                    range(&f.absorption_per_m),
                    f.quantum_yield,
                    peak_nm(&f.emission, (lo, hi)),
                    if f.redshift { " (redshift only)" } else { "" }
                ));
            }
        }
    }
    s.push_str(&format!("triangles: {}\n", scene.geometry.len()));
    s.push_str(&format!("total power: {:.6} W\n", scene.total_power_w()));
    let (lo, hi) = scene.simulation.wavelength_range_nm;
    s.push_str(&format!("wavelength range: {lo}–{hi} nm\n"));
    s.push_str(&format!("transport: {}\n", scene.effects.transport()));
    s.push_str(&format!("effects: {}\n", scene.effects.names().join(", ")));
    if let Some(c) = &scene.camera {
        s.push_str(&format!("camera: {}×{} pixels, fov {}°\n", c.resolution[0], c.resolution[1], c.fov_deg));
    }
    for surface in &scene.surfaces {
        if let Some(m) = &surface.map {
            s.push_str(&format!("map: {} {}×{} texels\n", surface.name, m.resolution[0], m.resolution[1]));
        }
        if let Some((bins, _)) = surface.spectrum_bins {
            s.push_str(&format!("spectrum: {} in {bins} wavelength bins\n", surface.name));
        }
    }
    for d in &scene.detectors {
        s.push_str(&format!("detector: farfield {} {}×{} (gamma × C)\n", d.name, d.resolution[0], d.resolution[1]));
    }
    for p in &scene.planes {
        let [nu, nv] = p.resolution;
        let area = p.area_m2() / (scene.unit_m * scene.unit_m);
        s.push_str(&format!("detector: work plane {} {nu}×{nv} texels over {area:.6} square units\n", p.name));
    }
    s
}

/// A coordinate as the user wrote it: 12 significant digits drop the rounding of the
/// recentring (1.2999999999999998 -> 1.3).
fn round_shown(x: f64) -> f64 {
    format!("{x:.11e}").parse().unwrap_or(x)
}

/// Where a spectrum peaks inside `range` (nm), among its breakpoints.
fn peak_nm(s: &crate::spectrum::Spectrum, range: (f64, f64)) -> f64 {
    s.breakpoints(range)
        .into_iter()
        .fold((range.0, f64::NEG_INFINITY), |best, x| {
            let v = s.eval(x);
            if v > best.1 {
                (x, v)
            } else {
                best
            }
        })
        .0
}

/// The facts of `describe` as data: surfaces, lights, media, triangles, power, wavelength range,
/// transport, effects, camera, maps, spectra and detectors. Lengths in the file's units where the
/// text shows them so (point light positions), SI otherwise.
pub fn scene_info(scene: &Scene) -> serde_json::Value {
    use serde_json::json;
    let (lo, hi) = scene.simulation.wavelength_range_nm;
    let surfaces: Vec<_> = scene
        .surfaces
        .iter()
        .map(|x| {
            let m = &scene.materials[x.material];
            json!({
                "name": x.name,
                "material": m.name,
                "kind": m.material.kind(),
                "triangles": x.triangles,
                "area_m2": x.area_m2,
                "light": x.light.is_some(),
            })
        })
        .collect();
    let lights: Vec<_> = scene
        .lights
        .iter()
        .map(|l| {
            let (shape, surface, position) = match &l.shape {
                LightShape::Area { surface } => ("area", Some(scene.surfaces[*surface].name.clone()), None),
                LightShape::Rays { .. } => ("rays", None, None),
                LightShape::Point { position, .. } => {
                    let p = scene.file_coordinates(*position);
                    ("point", None, Some([round_shown(p.x), round_shown(p.y), round_shown(p.z)]))
                }
            };
            json!({
                "name": l.name,
                "power_w": l.power_w,
                "power_lm": l.power_w * l.lm_per_w,
                "distribution": match &l.ies {
                    Some(ies) => format!("ies {}", ies.file.display()),
                    None => l.distribution.describe(),
                },
                "shape": shape,
                "surface": surface,
                "position": position,
            })
        })
        .collect();
    let media: Vec<_> = scene
        .media
        .iter()
        .map(|m| {
            let range = |x: &crate::spectrum::Spectrum| {
                let (a, b) = x.min_max_over((lo, hi));
                [a, b]
            };
            let (phase, g) = match m.phase {
                crate::scene::Phase::Isotropic => ("isotropic", 0.0),
                crate::scene::Phase::HenyeyGreenstein { g } => ("henyey_greenstein", g),
            };
            json!({
                "name": m.name,
                "absorption_per_m": range(&m.absorption_per_m),
                "scattering_per_m": range(&m.scattering_per_m),
                "phase": phase,
                "g": g,
                "volume_m3": m.volume_m3,
                "fluorescence": m.fluorescence.as_ref().map(|f| json!({
                    "absorption_per_m": range(&f.absorption_per_m),
                    "quantum_yield": f.quantum_yield,
                    "emission_peak_nm": peak_nm(&f.emission, (lo, hi)),
                    "redshift": f.redshift,
                })),
            })
        })
        .collect();
    let maps: Vec<_> = scene
        .surfaces
        .iter()
        .filter_map(|s| s.map.as_ref().map(|m| json!({"surface": s.name, "resolution": m.resolution})))
        .collect();
    let spectra: Vec<_> = scene
        .surfaces
        .iter()
        .filter_map(|s| s.spectrum_bins.map(|(bins, _)| json!({"surface": s.name, "bins": bins})))
        .collect();
    let detectors: Vec<_> = scene
        .detectors
        .iter()
        .map(|d| json!({"name": d.name, "type": "farfield", "resolution": d.resolution}))
        .collect();
    let planes: Vec<_> = scene
        .planes
        .iter()
        .map(|p| json!({"name": p.name, "resolution": p.resolution, "area_m2": p.area_m2()}))
        .collect();
    let volumes: Vec<_> = scene.volumes.iter().map(|v| json!({"name": v.name, "resolution": v.resolution})).collect();
    json!({
        "scene": scene.path.display().to_string(),
        "surfaces": surfaces,
        "lights": lights,
        "media": media,
        "triangles": scene.geometry.len(),
        "total_power_w": scene.total_power_w(),
        "wavelength_range_nm": [lo, hi],
        "transport": scene.effects.transport(),
        "effects": scene.effects.names(),
        "camera": scene.camera.as_ref().map(|c| json!({"resolution": c.resolution, "fov_deg": c.fov_deg})),
        "maps": maps,
        "spectra": spectra,
        "detectors": detectors,
        "volumes": volumes,
        "planes": planes,
    })
}
