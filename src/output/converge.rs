//! convergence.png of `photon converge`: log-log error against seconds.

use std::path::Path;

use plotters::prelude::*;

use crate::error::Error;
use crate::run::converge::{log_log_slope, Convergence, Row};

/// convergence.png: log-log error against seconds, with the N^(−1/2) line and fitted slopes.
pub fn plot(report: &Convergence, path: &Path, title: &str) -> Result<(), Error> {
    let err = |e: &dyn std::fmt::Display| Error::Other(format!("cannot draw {}: {e}", path.display()));
    super::register_plot_font();
    let root = BitMapBackend::new(path, (900, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    type Series = (String, Vec<(f64, f64)>, RGBColor);
    let mut series: Vec<Series> = Vec::new();
    let pick = |f: &dyn Fn(&Row) -> Option<f64>| -> Vec<(f64, f64)> {
        report.rows.iter().filter_map(|r| f(r).filter(|v| *v > 0.0 && v.is_finite()).map(|v| (r.seconds, v))).collect()
    };
    let slope_label = |name: &str, pts: &[(f64, f64)]| match log_log_slope(pts) {
        Some(s) => format!("{name} (slope {s:.2})"),
        None => name.to_string(),
    };
    let stderr = pick(&|r| r.rel_stderr);
    series.push((slope_label(&format!("{}: relative standard error", report.surface), &stderr), stderr.clone(), BLUE));
    let observed = pick(&|r| r.observed_rel_error);
    series.push((slope_label(&format!("{}: observed error vs reference", report.surface), &observed), observed, RED));
    let image = pick(&|r| r.image_rrmse);
    if !image.is_empty() {
        series.push((slope_label("image: relative RMSE vs reference run", &image), image, RGBColor(0, 140, 0)));
    }
    let all: Vec<(f64, f64)> = series.iter().flat_map(|s| s.1.iter().copied()).collect();
    if all.is_empty() {
        // Nothing to plot (no photon reached the tally): say so rather than draw empty axes.
        root.titled(title, ("sans-serif", 22))
            .map_err(|e| err(&e))?
            .draw_text(
                &format!("no data: no photon reached \"{}\"", report.surface),
                &("sans-serif", 20).into_text_style(&root),
                (40, 80),
            )
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
        return Ok(());
    }
    let (x0, x1) = all.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (y0, y1) = all.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d((x0 / 1.5..x1 * 1.5).log_scale(), (y0 / 3.0..y1 * 3.0).log_scale())
        .map_err(|e| err(&e))?;
    chart.configure_mesh().x_desc("wall-clock seconds").y_desc("relative error").draw().map_err(|e| err(&e))?;
    // N^(−1/2) ∝ t^(−1/2) through the first standard-error point.
    if let Some(&(t0, e0)) = stderr.first() {
        let line = [(x0 / 1.5, e0 * (t0 / (x0 / 1.5)).sqrt()), (x1 * 1.5, e0 * (t0 / (x1 * 1.5)).sqrt())];
        chart
            .draw_series(LineSeries::new(line, BLACK.mix(0.5)))
            .map_err(|e| err(&e))?
            .label("N^-1/2 (slope -0.5)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.5)));
    }
    for (label, pts, colour) in series {
        chart.draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2))).map_err(|e| err(&e))?;
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, colour.filled())))
            .map_err(|e| err(&e))?
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
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
