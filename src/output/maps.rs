//! Irradiance map outputs: per-texel estimates of a finished run (surface maps and work planes),
//! their uniformity figures, and their EXR and PNG files.

use crate::scene::map::file_name;

/// What a map lies on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MapKind {
    Surface,
    /// A work plane (`[[detectors]] type = "plane"`), which photons pass through.
    Plane,
}

/// One map as estimates per texel, row-major with j (v) increasing.
pub struct MapEstimate {
    /// The surface's or work plane's name (the file stem of maps/<name>.exr).
    pub surface: String,
    pub kind: MapKind,
    pub resolution: [usize; 2],
    /// Extent in metres of a planar map; None for a map over texture coordinates.
    pub size_m: Option<[f64; 2]>,
    pub texel_area_m2: Vec<f64>,
    /// (value, standard error) per texel: incident W and lm.
    pub flux_w: Vec<(f64, f64)>,
    pub flux_lm: Vec<(f64, f64)>,
    /// The whole map's area and its incident W and lm with their standard errors: the surface's
    /// own tally, or a work plane's whole-plane slot.
    pub area_m2: f64,
    pub total_w: (f64, f64),
    pub total_lm: (f64, f64),
}

/// Minimum, mean and maximum of a map and the uniformity U₀ = E_min/E_mean (EN 12464-1), each
/// with its standard error.
#[derive(serde::Serialize, Clone, Copy, Debug, PartialEq)]
pub struct Uniformity {
    pub min: f64,
    pub min_stderr: f64,
    pub mean: f64,
    pub mean_stderr: f64,
    pub max: f64,
    pub max_stderr: f64,
    pub u0: f64,
    pub u0_stderr: f64,
}

/// A map's row in flux.json (`maps` for surfaces, `planes` for work planes).
#[derive(serde::Serialize, Clone, Debug)]
pub struct MapRow {
    pub name: String,
    pub area_m2: f64,
    pub resolution: [usize; 2],
    /// Texels the figures are taken over: those at least half covered by the surface.
    pub texels_counted: usize,
    pub incident_w: f64,
    pub incident_w_stderr: f64,
    pub incident_lm: f64,
    pub incident_lm_stderr: f64,
    pub illuminance_lx: Uniformity,
    pub irradiance_w_m2: Uniformity,
}

impl MapEstimate {
    /// Per texel flux over area (0 where the surface does not reach into the texel).
    fn per_area(&self, flux: &[(f64, f64)]) -> Vec<(f64, f64)> {
        flux.iter()
            .zip(&self.texel_area_m2)
            .map(|(&(f, s), &a)| if a > 0.0 { (f / a, s / a) } else { (0.0, 0.0) })
            .collect()
    }

    pub fn irradiance_w_m2(&self) -> Vec<(f64, f64)> {
        self.per_area(&self.flux_w)
    }

    pub fn illuminance_lx(&self) -> Vec<(f64, f64)> {
        self.per_area(&self.flux_lm)
    }

    /// The texels the uniformity figures count: at least half as large as the largest (a texel
    /// the surface barely reaches into, along a disk's rim, holds few photons and its noise would
    /// be read as the minimum). Every texel of a work plane counts.
    fn counted(&self) -> Vec<usize> {
        let full = self.texel_area_m2.iter().copied().fold(0.0, f64::max);
        (0..self.texel_area_m2.len()).filter(|&k| full > 0.0 && self.texel_area_m2[k] >= 0.5 * full).collect()
    }

    /// E_min, E_mean, E_max and U₀ of per-texel values `e` (W/m² or lx), the mean from the whole
    /// map's flux `total` over its area. E_min's and E_max's standard errors are those of the
    /// texels holding them (a minimum over noisy texels is biased low by about the texels' noise:
    /// run until that is small against the spread). U₀'s follows to first order,
    /// σ_U/U = √((σ_min/E_min)² + (σ_mean/E_mean)²), as if the two were independent (they are
    /// correlated positively, so this errs large).
    fn uniformity(&self, e: &[(f64, f64)], total: (f64, f64)) -> Uniformity {
        let counted = self.counted();
        let pick = |better: fn(f64, f64) -> bool| {
            counted.iter().map(|&k| e[k]).reduce(|a, b| if better(b.0, a.0) { b } else { a }).unwrap_or((0.0, 0.0))
        };
        let (min, min_stderr) = pick(|b, a| b < a);
        let (max, max_stderr) = pick(|b, a| b > a);
        let per_m2 = if self.area_m2 > 0.0 { 1.0 / self.area_m2 } else { 0.0 };
        let (mean, mean_stderr) = (total.0 * per_m2, total.1 * per_m2);
        let (u0, u0_stderr) = if mean > 0.0 && min > 0.0 {
            let u = min / mean;
            (u, u * ((min_stderr / min).powi(2) + (mean_stderr / mean).powi(2)).sqrt())
        } else if mean > 0.0 {
            // E_min = 0: U₀ = 0, and its error is that of a zero minimum over the mean.
            (0.0, min_stderr / mean)
        } else {
            (0.0, 0.0)
        };
        Uniformity { min, min_stderr, mean, mean_stderr, max, max_stderr, u0, u0_stderr }
    }

    pub fn row(&self) -> MapRow {
        MapRow {
            name: self.surface.clone(),
            area_m2: self.area_m2,
            resolution: self.resolution,
            texels_counted: self.counted().len(),
            incident_w: self.total_w.0,
            incident_w_stderr: self.total_w.1,
            incident_lm: self.total_lm.0,
            incident_lm_stderr: self.total_lm.1,
            illuminance_lx: self.uniformity(&self.illuminance_lx(), self.total_lm),
            irradiance_w_m2: self.uniformity(&self.irradiance_w_m2(), self.total_w),
        }
    }
}

/// The maps of a finished run: every mapped surface's, then every work plane's.
pub fn estimates(scene: &crate::scene::Scene, r: &crate::run::RunResult) -> Vec<MapEstimate> {
    let t = &r.tallies;
    let model = r.transport.error_model();
    let texel =
        |k: usize| (t.estimate(&t.texels, k, r.emitted_w, model), t.estimate(&t.texels_lm, k, r.emitted_w, model));
    let surfaces =
        scene.surfaces.iter().enumerate().filter_map(|(i, s)| s.map.as_ref().map(|m| (i, s, m))).map(|(i, s, m)| {
            let (flux_w, flux_lm) = (m.offset..m.offset + m.texels()).map(texel).unzip();
            MapEstimate {
                surface: s.name.clone(),
                kind: MapKind::Surface,
                resolution: m.resolution,
                size_m: m.size_m,
                texel_area_m2: crate::detectors::maps::texel_areas(m),
                flux_w,
                flux_lm,
                area_m2: s.area_m2,
                total_w: r.incident(i),
                total_lm: r.incident_lm(i),
            }
        });
    let planes = scene.planes.iter().map(|p| {
        let [nu, nv] = p.resolution;
        let (flux_w, flux_lm) = (p.offset..p.offset + nu * nv).map(texel).unzip();
        let (total_w, total_lm) = texel(p.total_slot());
        MapEstimate {
            surface: p.name.clone(),
            kind: MapKind::Plane,
            resolution: p.resolution,
            size_m: Some(p.size_m()),
            texel_area_m2: vec![p.area_m2() / (nu * nv) as f64; nu * nv],
            flux_w,
            flux_lm,
            area_m2: p.area_m2(),
            total_w,
            total_lm,
        }
    });
    surfaces.chain(planes).collect()
}

/// maps/<surface>.exr: irradiance (W/m²), illuminance (lx) and their standard errors, f32, one
/// pixel per texel, u to the right and v up (row 0 is the largest v).
pub fn write_exr(dir: &std::path::Path, m: &MapEstimate) -> Result<std::path::PathBuf, crate::error::Error> {
    use exr::prelude::*;
    let [nu, nv] = m.resolution;
    let flip = |values: &[(f64, f64)], pick: fn(&(f64, f64)) -> f64| -> Vec<f32> {
        (0..nv).rev().flat_map(|j| (0..nu).map(move |i| j * nu + i)).map(|k| pick(&values[k]) as f32).collect()
    };
    let (e, ev) = (m.irradiance_w_m2(), m.illuminance_lx());
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![
        AnyChannel::new("irradiance_w_m2", FlatSamples::F32(flip(&e, |x| x.0))),
        AnyChannel::new("irradiance_w_m2_stderr", FlatSamples::F32(flip(&e, |x| x.1))),
        AnyChannel::new("illuminance_lx", FlatSamples::F32(flip(&ev, |x| x.0))),
        AnyChannel::new("illuminance_lx_stderr", FlatSamples::F32(flip(&ev, |x| x.1))),
    ]));
    // An EXR name holds Latin-1 only: a name beyond it is written as its file stem (ASCII).
    let layer_name = exr::meta::attribute::Text::new_or_none(&m.surface)
        .or_else(|| exr::meta::attribute::Text::new_or_none(crate::scene::map::file_stem(&m.surface)))
        .unwrap_or_default();
    let layer = Layer::new((nu, nv), LayerAttributes::named(layer_name), Encoding::FAST_LOSSLESS, channels);
    let mut bytes = std::io::Cursor::new(Vec::new());
    let name = file_name(&m.surface, "exr");
    Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(&mut bytes)
        .map_err(|e| crate::error::Error::Other(format!("cannot encode {name}: {e}")))?;
    crate::output::write_atomic(dir, &name, bytes.get_ref())
}

/// Viridis-like false colour for t in [0, 1] (matplotlib's viridis at 5 stops, linear between).
pub(crate) fn false_colour(t: f64) -> plotters::style::RGBColor {
    const STOPS: [[f64; 3]; 5] =
        [[68.0, 1.0, 84.0], [59.0, 82.0, 139.0], [33.0, 145.0, 140.0], [94.0, 201.0, 98.0], [253.0, 231.0, 37.0]];
    let x = t.clamp(0.0, 1.0) * 4.0;
    let k = (x as usize).min(3);
    let f = x - k as f64;
    let c = |i: usize| (STOPS[k][i] + f * (STOPS[k + 1][i] - STOPS[k][i])).round() as u8;
    plotters::style::RGBColor(c(0), c(1), c(2))
}

/// A scale-bar value: whole lux from 100 lx up, one decimal from 1 lx, else three.
fn lux_label(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    match v {
        v if v >= 100.0 => format!("{v:.0}"),
        v if v >= 1.0 => format!("{v:.1}"),
        v => format!("{v:.3}"),
    }
}

/// maps/<surface>.png: the illuminance map in false colour with a scale bar in lux, axes in
/// metres along the map's u and v edges, and a title naming the scene and the surface.
pub fn write_png(
    dir: &std::path::Path,
    m: &MapEstimate,
    scene_name: &str,
) -> Result<std::path::PathBuf, crate::error::Error> {
    use plotters::prelude::*;
    let name = file_name(&m.surface, "png");
    let err = |e: &dyn std::fmt::Display| crate::error::Error::Other(format!("cannot draw {name}: {e}"));
    crate::output::register_plot_font();
    let (w, h) = (900u32, 720u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let on = match m.kind {
            MapKind::Surface => format!("\"{}\"", m.surface),
            MapKind::Plane => format!("work plane \"{}\"", m.surface),
        };
        let root =
            root.titled(&format!("{scene_name}: illuminance on {on} (lx)"), ("sans-serif", 22)).map_err(|e| err(&e))?;
        let u = m.row().illuminance_lx;
        let figures = format!(
            "E_min {} lx, E_mean {} lx, E_max {} lx, U0 = E_min/E_mean {:.3} ± {:.3}",
            lux_label(u.min),
            lux_label(u.mean),
            lux_label(u.max),
            u.u0,
            u.u0_stderr
        );
        let root = root.titled(&figures, ("sans-serif", 16)).map_err(|e| err(&e))?;
        let (left, right) = root.split_horizontally(w - 190);
        let ev = m.illuminance_lx();
        // The scale spans the texels on the surface, lowest to highest: from 0 it would hide a
        // desk's 300–420 lx variation in one colour.
        let lit = || ev.iter().zip(&m.texel_area_m2).filter(|(_, &a)| a > 0.0).map(|(x, _)| x.0);
        let (lo, hi) = (lit().fold(f64::INFINITY, f64::min), lit().fold(0.0, f64::max));
        let (lo, hi) = match (lo, hi) {
            (lo, hi) if hi > lo => (lo, hi),
            (_, hi) if hi > 0.0 => (0.0, hi),
            _ => (0.0, 1.0),
        };
        let shade = |v: f64| false_colour((v - lo) / (hi - lo));
        let [nu, nv] = m.resolution;
        let [su, sv] = m.size_m.unwrap_or([1.0, 1.0]);
        let (x_desc, y_desc) = match m.size_m {
            Some(_) => ("u (m, along the first edge)", "v (m)"),
            None => ("u (texture coordinate)", "v (texture coordinate)"),
        };
        let mut chart = ChartBuilder::on(&left)
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(65)
            .build_cartesian_2d(0.0..su, 0.0..sv)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 16))
            .draw()
            .map_err(|e| err(&e))?;
        chart
            .draw_series((0..nv).flat_map(|j| (0..nu).map(move |i| (i, j))).map(|(i, j)| {
                let k = j * nu + i;
                let colour = if m.texel_area_m2[k] > 0.0 { shade(ev[k].0) } else { RGBColor(220, 220, 220) };
                let (du, dv) = (su / nu as f64, sv / nv as f64);
                Rectangle::new(
                    [(i as f64 * du, j as f64 * dv), ((i + 1) as f64 * du, (j + 1) as f64 * dv)],
                    colour.filled(),
                )
            }))
            .map_err(|e| err(&e))?;
        // Scale bar: a column of colour with its values in lux.
        let mut bar = ChartBuilder::on(&right)
            .margin_top(15)
            .margin_bottom(60)
            .margin_right(20)
            .y_label_area_size(110)
            .build_cartesian_2d(0.0..1.0, lo..hi)
            .map_err(|e| err(&e))?;
        bar.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc("illuminance (lx)")
            .y_label_formatter(&|v| lux_label(*v))
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 16))
            .draw()
            .map_err(|e| err(&e))?;
        let steps = 200;
        bar.draw_series((0..steps).map(|s| {
            let at = |s: usize| lo + s as f64 / steps as f64 * (hi - lo);
            Rectangle::new([(0.0, at(s)), (1.0, at(s + 1))], shade((at(s) + at(s + 1)) / 2.0).filled())
        }))
        .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().map_err(|e| err(&e))?;
        wr.write_image_data(&rgb).map_err(|e| err(&e))?;
    }
    crate::output::write_atomic(dir, &name, &bytes)
}
