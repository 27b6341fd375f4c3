//! `photon converge`: what accuracy costs in time. One run is observed at doubling photon counts
//! (1, 2, 4, … batches: the batches of a shorter run are exactly the first batches of a longer
//! one), and each row gives the tally's estimate, its relative standard error, the error actually
//! observed against a reference (`--reference`, the scene's `[reference]` closed form, or else an
//! independent run with another seed and the same budget), and the figure of merit
//! 1/(rel_error²·seconds), flat when the error falls as N^(−1/2). With a camera, the image's
//! relative RMSE against the independent run's image as well (that noise floor is reached when
//! a row's photons approach the reference's).
//! Seconds are the batches' trace time divided by the threads (batches merged in one round
//! finish at one wall-clock instant, which would blur the first rows).

use std::fmt::Write as _;
use std::sync::atomic::AtomicBool;

use crate::detectors::tally::Tallies;
use crate::error::Error;
use crate::run::{apply_options, simulate_observed, RunOptions, StopReason, BATCH_PHOTONS};
use crate::scene::Scene;

#[derive(Clone, Debug)]
pub struct Row {
    pub photons: u64,
    pub seconds: f64,
    pub estimate_w: f64,
    /// None while no photon has reached the tally (no relative error exists yet).
    pub rel_stderr: Option<f64>,
    /// |estimate − reference| / reference, when there is a reference.
    pub observed_rel_error: Option<f64>,
    pub fom: Option<f64>,
    /// Relative RMSE of the image's Y against the independent reference run's image.
    pub image_rrmse: Option<f64>,
}

pub struct Convergence {
    pub surface: String,
    /// None when a signal stopped the command before any reference was had.
    pub reference_w: Option<f64>,
    pub reference_source: String,
    /// Which integrator made the image, when there is one.
    pub image_integrator: Option<crate::integrators::camera::Integrator>,
    pub rows: Vec<Row>,
    /// How the budget was spent: seconds of the run and of the reference run (0 without one).
    pub budget_s: (f64, f64),
    /// A signal stopped it early: the rows are those done by then.
    pub interrupted: bool,
}

/// Fewest rows that give a slope worth showing.
const MIN_ROWS: usize = 3;

struct Snapshot {
    photons: u64,
    seconds: f64,
    incident: Vec<(f64, f64)>,
    image_y: Option<Vec<f32>>,
    image_y_var: Option<Vec<f32>>,
}

fn snapshot(
    t: &Tallies,
    film: Option<&crate::detectors::film::Film>,
    emitted_w: f64,
    seconds: f64,
    opts: &RunOptions,
) -> Snapshot {
    let model = opts.transport.error_model();
    let image = film.map(|f| f.image(emitted_w));
    Snapshot {
        photons: t.photons,
        seconds,
        incident: (0..t.incident.len()).map(|i| t.incident_estimate(i, emitted_w, model)).collect(),
        image_y: image.as_ref().map(|i| i.xyz.column(1).to_vec()),
        image_y_var: image.map(|i| i.y_var),
    }
}

/// Checks that `scene` has a surface to follow, and `tally` (if given) names one: its index.
pub fn check(scene: &Scene, tally: Option<&str>) -> Result<Option<usize>, Error> {
    if scene.surfaces.is_empty() {
        return Err(Error::Usage(format!(
            "{}: the scene has no surface, and converge follows a surface's incident power",
            scene.path.display()
        )));
    }
    tally
        .map(|name| {
            scene
                .surfaces
                .iter()
                .position(|s| s.name == name)
                .ok_or_else(|| Error::Usage(format!("--tally {name}: no surface of that name")))
        })
        .transpose()
}

/// Runs `scene` within `budget_s` seconds in all and tabulates the convergence of surface
/// `tally` (default: the scene's reference surface, else the surface receiving the most power).
/// When an independent reference run is needed (no closed form, or an image to compare), the
/// run and the reference run get half the budget each. `interrupt` stops it early with the
/// rows done so far.
pub fn converge(
    scene: &mut Scene,
    opts: &RunOptions,
    tally: Option<&str>,
    reference: Option<f64>,
    budget_s: f64,
    interrupt: &AtomicBool,
) -> Result<Convergence, Error> {
    let chosen_surface = match check(scene, tally)? {
        Some(s) => Some(s),
        None => scene.reference.as_ref().map(|r| r.surface),
    };
    let scene_reference =
        scene.reference.as_ref().filter(|r| chosen_surface == Some(r.surface)).map(|r| (r.incident_w, r.note.clone()));
    let closed_form = reference.or(scene_reference.as_ref().map(|r| r.0));
    let has_image = scene.camera.is_some() && !opts.no_image;
    // Without a closed form, the reference is an independent run (another seed, same budget):
    // the doubling rows share their batches, so none of them can serve as an unbiased reference.
    let needs_independent = closed_form.is_none() || has_image;
    let run_budget = if needs_independent { budget_s / 2.0 } else { budget_s };

    let mut run_opts = opts.clone();
    run_opts.time_s = Some(run_budget);
    run_opts.photons = None;
    run_opts.progress = true;
    let chosen = apply_options(scene, &run_opts)?;
    let mut snaps: Vec<Snapshot> = Vec::new();
    let mut next = BATCH_PHOTONS;
    let result = simulate_observed(scene, &run_opts, &chosen, interrupt, &mut |p| {
        if p.tallies.photons >= next {
            let seconds = p.seconds();
            snaps.push(snapshot(p.tallies, p.film.map(|f| f.flushed()), p.emitted_w, seconds, &run_opts));
            next *= 2;
        }
    })?;
    // The run's final state is the longest run: add it if the doubling sequence missed it.
    if snaps.last().map(|s| s.photons) != Some(result.tallies.photons) {
        let seconds = result.tallies.counters.trace_seconds / result.threads as f64;
        snaps.push(snapshot(&result.tallies, result.film.as_ref(), result.emitted_w, seconds, &run_opts));
    }
    let mut interrupted = result.stop_reason == StopReason::Interrupted;
    let surface = chosen_surface.unwrap_or_else(|| {
        let final_incident = &snaps[snaps.len() - 1].incident;
        (0..final_incident.len()).max_by(|&a, &b| final_incident[a].0.total_cmp(&final_incident[b].0)).unwrap_or(0)
    });
    let independent = if needs_independent && !interrupted {
        eprintln!("reference run (seed + 1) for {run_budget:.3} s");
        let seed = scene.simulation.seed;
        scene.simulation.seed = seed.wrapping_add(1);
        let r = simulate_observed(scene, &run_opts, &chosen, interrupt, &mut |_| {});
        scene.simulation.seed = seed;
        let r = r?;
        interrupted |= r.stop_reason == StopReason::Interrupted;
        Some(snapshot(&r.tallies, r.film.as_ref(), r.emitted_w, r.wall_seconds, &run_opts))
    } else {
        None
    };
    let (reference_w, reference_source) = match (reference, &scene_reference, &independent) {
        (Some(v), _, _) => (Some(v), "--reference".to_string()),
        (None, Some((w, note)), _) => (Some(*w), format!("closed form from the scene: {note}")),
        (None, None, Some(ind)) => (
            Some(ind.incident[surface].0).filter(|&w| w > 0.0),
            format!("an independent run, seed + 1, {} photons", ind.photons),
        ),
        (None, None, None) => (None, "none: stopped before the reference run".to_string()),
    };
    let ref_image = independent.as_ref().and_then(|s| s.image_y.clone().zip(s.image_y_var.clone()));
    let rows: Vec<Row> = snaps
        .iter()
        .map(|s| {
            let (est, se) = s.incident[surface];
            let rel = (est > 0.0).then(|| se / est);
            let image_rrmse = match (&s.image_y, &ref_image) {
                (Some(y), Some((r, r_var))) => rrmse(y, r, r_var),
                _ => None,
            };
            Row {
                photons: s.photons,
                seconds: s.seconds,
                estimate_w: est,
                rel_stderr: rel,
                observed_rel_error: reference_w.map(|r| ((est - r) / r).abs()),
                fom: rel.filter(|&r| r > 0.0 && s.seconds > 0.0).map(|r| 1.0 / (r * r * s.seconds)),
                image_rrmse,
            }
        })
        .collect();
    if rows.len() < MIN_ROWS && !interrupted {
        eprintln!(
            "warning: the budget allowed only {} photon count(s); slopes need at least {MIN_ROWS}: give a longer --budget",
            rows.len()
        );
    }
    if rows.iter().all(|r| r.rel_stderr.is_none()) {
        eprintln!(
            "warning: no photon reached \"{}\" in {} photons",
            scene.surfaces[surface].name, result.tallies.photons
        );
    }
    Ok(Convergence {
        surface: scene.surfaces[surface].name.clone(),
        reference_w,
        reference_source,
        image_integrator: result.film.is_some().then_some(result.integrator),
        rows,
        budget_s: (run_budget, if needs_independent { run_budget } else { 0.0 }),
        interrupted,
    })
}

/// Relative RMSE of `y` against an independent reference `r`: sqrt(mean((y − r)²) − mean(Var r))
/// / mean(r). E[(y − r)²] = Var y + Var r + bias², so subtracting the reference's own variance
/// (its Y_var) leaves the error of `y` alone, free of the reference's noise floor.
/// None when the reference image is black (no relative error exists).
fn rrmse(y: &[f32], r: &[f32], r_var: &[f32]) -> Option<f64> {
    let n = r.len() as f64;
    let mean = r.iter().map(|&v| v as f64).sum::<f64>() / n;
    let mse = y.iter().zip(r).map(|(&a, &b)| (a as f64 - b as f64).powi(2)).sum::<f64>() / n;
    let ref_var = r_var.iter().map(|&v| v as f64).sum::<f64>() / n;
    (mean > 0.0).then(|| (mse - ref_var).max(0.0).sqrt() / mean)
}

/// Least-squares slope of log(y) against log(x) over points with positive values.
pub fn log_log_slope(points: &[(f64, f64)]) -> Option<f64> {
    let pts: Vec<(f64, f64)> = points.iter().filter(|p| p.0 > 0.0 && p.1 > 0.0).map(|p| (p.0.ln(), p.1.ln())).collect();
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

impl Convergence {
    pub fn table(&self) -> String {
        let image = match self.image_integrator {
            Some(i) => format!("; image rRMSE: the {} image against the independent run's", i.name()),
            None => String::new(),
        };
        let reference = self.reference_w.map_or("-".into(), |w| format!("{w:.6e} W"));
        let budget = match self.budget_s {
            (run, 0.0) => format!("budget: {run:.3} s of tracing"),
            (run, reference) => format!("budget: {run:.3} s for the run + {reference:.3} s for the reference run"),
        };
        let mut s = format!(
            "surface {}: incident power; reference {reference} ({}){image}\n{budget}\n{:>11}  {:>9}  {:>14}  {:>10}  {:>12}  {:>10}  {:>12}\n",
            self.surface,
            self.reference_source,
            "photons",
            "seconds",
            "estimate W",
            "rel.stderr",
            "observed err",
            "FOM",
            "image rRMSE"
        );
        let show = |v: Option<f64>| v.map_or("-".into(), |e| format!("{e:.3e}"));
        for r in &self.rows {
            let _ = writeln!(
                s,
                "{:>11}  {:>9.3}  {:>14.6e}  {:>10}  {:>12}  {:>10}  {:>12}",
                r.photons,
                r.seconds,
                r.estimate_w,
                show(r.rel_stderr),
                show(r.observed_rel_error),
                show(r.fom),
                show(r.image_rrmse)
            );
        }
        if self.interrupted {
            s.push_str("interrupted: these are the rows done by then\n");
        }
        let slope = |f: &dyn Fn(&Row) -> Option<f64>| {
            log_log_slope(&self.rows.iter().filter_map(|r| f(r).map(|e| (r.seconds, e))).collect::<Vec<_>>())
        };
        let show = |v: Option<f64>| v.map_or("n/a".into(), |v| format!("{v:.3}"));
        let _ = writeln!(
            s,
            "log-log slopes against seconds (N^-1/2 gives -0.5): rel.stderr {}, observed error {}, image rRMSE {}",
            show(slope(&|r| r.rel_stderr)),
            show(slope(&|r| r.observed_rel_error)),
            show(slope(&|r| r.image_rrmse))
        );
        s
    }

    pub fn csv(&self) -> String {
        let mut s = String::from("photons,seconds,estimate_w,rel_stderr,observed_rel_error,fom,image_rrmse\n");
        for r in &self.rows {
            let opt = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{}",
                r.photons,
                r.seconds,
                r.estimate_w,
                opt(r.rel_stderr),
                opt(r.observed_rel_error),
                opt(r.fom),
                opt(r.image_rrmse)
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slope_of_a_power_law_is_its_exponent() {
        let pts: Vec<(f64, f64)> = (1..8).map(|k| (k as f64, 3.0 * (k as f64).powf(-0.5))).collect();
        assert!((log_log_slope(&pts).unwrap() + 0.5).abs() < 1e-12);
    }
}
