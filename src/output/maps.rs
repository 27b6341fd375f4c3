//! Irradiance map outputs: per-texel estimates of a finished run, and their EXR and PNG files.

use crate::scene::map::file_name;

/// One surface's map as estimates per texel, row-major with j (v) increasing.
pub struct MapEstimate {
    pub surface: String,
    pub resolution: [usize; 2],
    /// Extent in metres of a planar map; None for a map over texture coordinates.
    pub size_m: Option<[f64; 2]>,
    pub texel_area_m2: Vec<f64>,
    /// (value, standard error) per texel: incident W and lm.
    pub flux_w: Vec<(f64, f64)>,
    pub flux_lm: Vec<(f64, f64)>,
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
}

/// The maps of every mapped surface of a finished run.
pub fn estimates(scene: &crate::scene::Scene, r: &crate::run::RunResult) -> Vec<MapEstimate> {
    let t = &r.tallies;
    let model = r.transport.error_model();
    scene
        .surfaces
        .iter()
        .filter_map(|s| s.map.as_ref().map(|m| (s, m)))
        .map(|(s, m)| {
            let range = m.offset..m.offset + m.texels();
            MapEstimate {
                surface: s.name.clone(),
                resolution: m.resolution,
                size_m: m.size_m,
                texel_area_m2: crate::detectors::maps::texel_areas(m),
                flux_w: range.clone().map(|k| t.estimate(&t.texels, k, r.emitted_w, model)).collect(),
                flux_lm: range.map(|k| t.estimate(&t.texels_lm, k, r.emitted_w, model)).collect(),
            }
        })
        .collect()
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
    match v {
        v if v == 0.0 => "0".into(),
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
        let root = root
            .titled(&format!("{scene_name}: illuminance on \"{}\" (lx)", m.surface), ("sans-serif", 22))
            .map_err(|e| err(&e))?;
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
