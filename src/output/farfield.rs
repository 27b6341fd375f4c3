//! Far-field detector outputs: intensities per (γ, C) bin of a finished run, as CSV and a polar
//! candela plot.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use crate::error::Error;
use crate::scene::farfield::FarField;

/// A detector's result: (value, standard error) of the flux per bin, W and lm, index j·n_γ + i.
pub struct FarFieldEstimate {
    pub detector: FarField,
    pub flux_w: Vec<(f64, f64)>,
    pub flux_lm: Vec<(f64, f64)>,
}

impl FarFieldEstimate {
    /// Intensity of bin (i, j): (W/sr, s.e.) and (cd, s.e.).
    pub fn intensity(&self, i: usize, j: usize) -> ((f64, f64), (f64, f64)) {
        let k = j * self.detector.resolution[0] + i;
        let sr = self.detector.solid_angle_sr(i);
        let per = |x: (f64, f64)| (x.0 / sr, x.1 / sr);
        (per(self.flux_w[k]), per(self.flux_lm[k]))
    }
}

pub fn estimates(scene: &crate::scene::Scene, r: &crate::run::RunResult) -> Vec<FarFieldEstimate> {
    let t = &r.tallies;
    let model = r.transport.error_model();
    scene
        .detectors
        .iter()
        .map(|d| {
            let range = d.offset..d.offset + d.bins();
            FarFieldEstimate {
                detector: d.clone(),
                flux_w: range.clone().map(|k| t.estimate(&t.farfield, k, r.emitted_w, model)).collect(),
                flux_lm: range.map(|k| t.estimate(&t.farfield_lm, k, r.emitted_w, model)).collect(),
            }
        })
        .collect()
}

/// `farfield_<stem>.<ext>`, the detector's output file.
pub fn file_name(detector: &str, ext: &str) -> String {
    format!("farfield_{}.{ext}", crate::scene::map::file_stem(detector))
}

/// farfield_<name>.csv: one row per bin.
pub fn write_csv(dir: &Path, e: &FarFieldEstimate) -> Result<PathBuf, Error> {
    let [ng, nc] = e.detector.resolution;
    let mut s = String::from(
        "gamma_lo_deg,gamma_hi_deg,c_deg,solid_angle_sr,intensity_w_sr,intensity_w_sr_stderr,intensity_cd,intensity_cd_stderr\n",
    );
    for j in 0..nc {
        for i in 0..ng {
            let (g0, g1, c) = e.detector.bin_angles(i, j);
            let ((w, ws), (cd, cds)) = e.intensity(i, j);
            s.push_str(&format!("{g0},{g1},{c},{},{w},{ws},{cd},{cds}\n", e.detector.solid_angle_sr(i)));
        }
    }
    crate::output::write_atomic(dir, &file_name(&e.detector.name, "csv"), s.as_bytes())
}

/// farfield_<name>.png: a polar candela diagram of the C0–C180 and C90–C270 planes (γ = 0, the
/// nadir, pointing down; C0 and C90 to the right, C180 and C270 to the left).
pub fn write_png(dir: &Path, e: &FarFieldEstimate, scene_name: &str) -> Result<PathBuf, Error> {
    use plotters::prelude::*;
    let name = file_name(&e.detector.name, "png");
    let err = |x: &dyn std::fmt::Display| Error::Other(format!("cannot draw {name}: {x}"));
    crate::output::register_plot_font();
    let [ng, nc] = e.detector.resolution;
    // Sector nearest to a C angle.
    let sector = |c: f64| ((c / 360.0 * nc as f64).round() as usize) % nc;
    let curve = |right: f64, left: f64| -> Vec<(f64, f64)> {
        let mut pts = Vec::new();
        // Left half from the zenith down to the nadir, then the right half back up.
        for i in (0..ng).rev() {
            let g = (e.detector.bin_angles(i, 0).0 + e.detector.bin_angles(i, 0).1) / 2.0;
            let cd = e.intensity(i, sector(left)).1 .0;
            pts.push((-cd * g.to_radians().sin(), -cd * g.to_radians().cos()));
        }
        for i in 0..ng {
            let g = (e.detector.bin_angles(i, 0).0 + e.detector.bin_angles(i, 0).1) / 2.0;
            let cd = e.intensity(i, sector(right)).1 .0;
            pts.push((cd * g.to_radians().sin(), -cd * g.to_radians().cos()));
        }
        pts
    };
    let planes = [(curve(0.0, 180.0), "C0-C180", RED), (curve(90.0, 270.0), "C90-C270", BLUE)];
    let top = planes.iter().flat_map(|p| p.0.iter()).map(|(x, y)| x.hypot(*y)).fold(0.0, f64::max);
    let top = if top > 0.0 { top * 1.1 } else { 1.0 };
    let (w, h) = (760u32, 800u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| err(&x))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("{scene_name}: far-field intensity \"{}\" (cd)", e.detector.name), ("sans-serif", 22))
            .margin(15)
            .x_label_area_size(40)
            .y_label_area_size(80)
            .build_cartesian_2d(-top..top, -top..top)
            .map_err(|x| err(&x))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("cd (C0 / C90 side to the right)")
            .y_desc("cd (nadir down)")
            // Distances from the centre: intensities are never negative on either side.
            .x_label_formatter(&|v| format!("{}", v.abs()))
            .y_label_formatter(&|v| format!("{}", v.abs()))
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 15))
            .draw()
            .map_err(|x| err(&x))?;
        // Polar grid: circles at round intensities, rays every 30°.
        let step = nice_step(top / 4.0);
        let mut r = step;
        while r < top {
            let circle: Vec<(f64, f64)> =
                (0..=120).map(|k| (k as f64 / 120.0 * 2.0 * PI).sin_cos()).map(|(s, c)| (r * s, r * c)).collect();
            chart.draw_series(LineSeries::new(circle, BLACK.mix(0.15))).map_err(|x| err(&x))?;
            chart
                .draw_series(std::iter::once(Text::new(format!("{r}"), (r * 0.05, -r), ("sans-serif", 13))))
                .map_err(|x| err(&x))?;
            r += step;
        }
        for k in 0..12 {
            let a = (k as f64 * 30.0).to_radians();
            let ray = vec![(0.0, 0.0), (top * a.sin(), -top * a.cos())];
            chart.draw_series(LineSeries::new(ray, BLACK.mix(0.15))).map_err(|x| err(&x))?;
            // γ from the nadir, on each side: 0° down, 90° level, 180° up.
            let gamma = if k <= 6 { k * 30 } else { 360 - k * 30 };
            let at = (0.9 * top * a.sin() - 0.03 * top, -0.9 * top * a.cos());
            chart
                .draw_series(std::iter::once(Text::new(format!("{gamma}°"), at, ("sans-serif", 13))))
                .map_err(|x| err(&x))?;
        }
        for (pts, label, colour) in planes {
            chart
                .draw_series(LineSeries::new(pts, colour.stroke_width(2)))
                .map_err(|x| err(&x))?
                .label(label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()
            .map_err(|x| err(&x))?;
        root.present().map_err(|x| err(&x))?;
    }
    let mut bytes = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut bytes, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut wr = enc.write_header().map_err(|x| err(&x))?;
        wr.write_image_data(&rgb).map_err(|x| err(&x))?;
    }
    crate::output::write_atomic(dir, &name, &bytes)
}

/// 1, 2 or 5 times a power of ten, at least `x`.
fn nice_step(x: f64) -> f64 {
    let p = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * p).find(|&s| s >= x).unwrap_or(10.0 * p)
}
