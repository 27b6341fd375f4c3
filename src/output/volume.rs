//! Volume detector outputs: per-voxel absorbed power density (W/m³) and fluence rate (W/m²)
//! with standard errors as `volume_<name>.npy` (float64, shape [4, nz, ny, nx]: absorbed,
//! absorbed s.e., fluence rate, fluence rate s.e.), and the fluence rate's middle z slice as
//! `volume_<name>.png`.

use std::path::{Path, PathBuf};

use crate::error::Error;
use crate::scene::volume::VolumeGrid;

pub struct VolumeEstimate<'a> {
    pub grid: &'a VolumeGrid,
    /// (value, standard error) per voxel, x fastest: W/m³ and W/m².
    pub absorbed_w_m3: Vec<(f64, f64)>,
    pub fluence_w_m2: Vec<(f64, f64)>,
}

pub fn file_name(detector: &str, ext: &str) -> String {
    format!("volume_{}.{ext}", crate::scene::map::file_stem(detector))
}

pub fn estimates<'a>(scene: &'a crate::scene::Scene, r: &crate::run::RunResult) -> Vec<VolumeEstimate<'a>> {
    let t = &r.tallies;
    let model = r.transport.error_model();
    scene
        .volumes
        .iter()
        .map(|g| {
            let v = g.voxel_volume_m3();
            let per_volume = |c: &crate::detectors::tally::Channel| -> Vec<(f64, f64)> {
                (g.offset..g.offset + g.voxels())
                    .map(|k| {
                        let (m, se) = t.estimate(c, k, r.emitted_w, model);
                        (m / v, se / v)
                    })
                    .collect()
            };
            VolumeEstimate {
                grid: g,
                absorbed_w_m3: per_volume(&t.volume_absorbed),
                fluence_w_m2: per_volume(&t.volume_track),
            }
        })
        .collect()
}

impl VolumeEstimate<'_> {
    /// Every value fits a finite f64 (they always do unless the power is absurd).
    pub fn finite(&self) -> bool {
        self.absorbed_w_m3.iter().chain(&self.fluence_w_m2).all(|(a, b)| a.is_finite() && b.is_finite())
    }
}

/// A NumPy .npy (format 1.0) of little-endian f64 in C order.
pub fn npy(shape: &[usize], data: impl Iterator<Item = f64>) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = if dims.len() == 1 { format!("{},", dims[0]) } else { dims.join(", ") };
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({tuple}), }}");
    // Magic (6) + version (2) + length (2) + header, padded with spaces to a multiple of 64, '\n'.
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for x in data {
        out.extend_from_slice(&x.to_le_bytes());
    }
    out
}

pub fn write_npy(dir: &Path, e: &VolumeEstimate) -> Result<PathBuf, Error> {
    let [nx, ny, nz] = e.grid.resolution;
    let planes = [
        e.absorbed_w_m3.iter().map(|x| x.0).collect::<Vec<_>>(),
        e.absorbed_w_m3.iter().map(|x| x.1).collect(),
        e.fluence_w_m2.iter().map(|x| x.0).collect(),
        e.fluence_w_m2.iter().map(|x| x.1).collect(),
    ];
    let bytes = npy(&[4, nz, ny, nx], planes.iter().flatten().copied());
    crate::output::write_atomic(dir, &file_name(&e.grid.name, "npy"), &bytes)
}

/// volume_<name>.png: the fluence rate in the middle z layer, false colour with a scale bar,
/// axes in metres of the scene's own frame.
pub fn write_png(dir: &Path, e: &VolumeEstimate, scene: &crate::scene::Scene) -> Result<PathBuf, Error> {
    use plotters::prelude::*;
    let name = file_name(&e.grid.name, "png");
    let err = |x: &dyn std::fmt::Display| Error::Other(format!("cannot draw {name}: {x}"));
    crate::output::register_plot_font();
    let [nx, ny, nz] = e.grid.resolution;
    let k = nz / 2;
    // Back to the file's frame and unit for the axes.
    let (lo, hi) = ((e.grid.min + scene.origin_m) / scene.unit_m, (e.grid.max + scene.origin_m) / scene.unit_m);
    let z_mid = lo.z + (k as f64 + 0.5) / nz as f64 * (hi.z - lo.z);
    let layer: Vec<f64> = (0..nx * ny).map(|i| e.fluence_w_m2[k * nx * ny + i].0).collect();
    let top = layer.iter().copied().fold(0.0, f64::max);
    let top = if top > 0.0 { top } else { 1.0 };
    let (w, h) = (900u32, 720u32);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|x| err(&x))?;
        let title = format!("{}: fluence rate in \"{}\" at z = {z_mid:.4} (W/m²)", scene.stem(), e.grid.name);
        let root = root.titled(&title, ("sans-serif", 20)).map_err(|x| err(&x))?;
        let (left, right) = root.split_horizontally(w - 190);
        let mut chart = ChartBuilder::on(&left)
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(65)
            .build_cartesian_2d(lo.x..hi.x, lo.y..hi.y)
            .map_err(|x| err(&x))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("x (scene units)")
            .y_desc("y (scene units)")
            .label_style(("sans-serif", 15))
            .draw()
            .map_err(|x| err(&x))?;
        let (dx, dy) = ((hi.x - lo.x) / nx as f64, (hi.y - lo.y) / ny as f64);
        chart
            .draw_series((0..ny).flat_map(|j| (0..nx).map(move |i| (i, j))).map(|(i, j)| {
                let c = crate::output::maps::false_colour(layer[j * nx + i] / top);
                let (x0, y0) = (lo.x + i as f64 * dx, lo.y + j as f64 * dy);
                Rectangle::new([(x0, y0), (x0 + dx, y0 + dy)], c.filled())
            }))
            .map_err(|x| err(&x))?;
        let mut bar = ChartBuilder::on(&right)
            .margin_top(15)
            .margin_bottom(60)
            .margin_right(20)
            .y_label_area_size(110)
            .build_cartesian_2d(0.0..1.0, 0.0..top)
            .map_err(|x| err(&x))?;
        bar.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc("fluence rate (W/m²)")
            .y_label_formatter(&|v| format!("{v:.3e}"))
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|x| err(&x))?;
        let steps = 200;
        bar.draw_series((0..steps).map(|s| {
            let at = |s: usize| s as f64 / steps as f64 * top;
            Rectangle::new(
                [(0.0, at(s)), (1.0, at(s + 1))],
                crate::output::maps::false_colour((s as f64 + 0.5) / steps as f64).filled(),
            )
        }))
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
