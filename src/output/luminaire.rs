//! Luminaire files from a far-field detector: `farfield_<name>.ies` (IES LM-63-2019) and
//! `farfield_<name>.ldt` (EULUMDAT), which lighting programs read as the simulated luminaire.
//!
//! Both sample the detector's bins as a type C table: the intensity of bin (γ band i, C sector
//! j), its flux over its solid angle, at the bin's centre; γ = 0 and γ = 180° carry the mean of
//! the first and last band over all sectors (the poles are single directions), and C runs over
//! the sector centres 0, ΔC, 2ΔC, … (and 360° again in the IES file). A reader interpolating the
//! table bilinearly gets back the bins' means to second order in the bin size: features a few
//! bins wide are smoothed, so choose the detector's resolution for the luminaire. Photometry is
//! absolute (IES lumens per lamp −1; EULUMDAT lamp flux = the luminaire's flux, LORL 100 %).

use std::path::{Path, PathBuf};

use crate::error::Error;
use crate::output::farfield::{file_name, FarFieldEstimate};
use crate::scene::Scene;

/// LM-63-2019 file generation type of a computer simulation.
const FILE_GENERATION_SIMULATION: &str = "1.00010";

/// A type C table sampled from a detector: γ and C angles (degrees) and cd[c][γ].
pub struct SampledTable {
    pub gamma_deg: Vec<f64>,
    pub c_deg: Vec<f64>,
    pub cd: Vec<Vec<f64>>,
}

/// The detector's bins as a table (see the module's comment); C ends before 360°.
pub fn sampled_table(e: &FarFieldEstimate) -> SampledTable {
    let [ng, nc] = e.detector.resolution;
    let cd = |i: usize, j: usize| e.intensity(i, j).1 .0;
    let pole = |i: usize| (0..nc).map(|j| cd(i, j)).sum::<f64>() / nc as f64;
    let mut gamma_deg = vec![0.0];
    gamma_deg.extend((0..ng).map(|i| 180.0 * (i as f64 + 0.5) / ng as f64));
    gamma_deg.push(180.0);
    let c_deg: Vec<f64> = (0..nc).map(|j| 360.0 * j as f64 / nc as f64).collect();
    let table = (0..nc)
        .map(|j| std::iter::once(pole(0)).chain((0..ng).map(|i| cd(i, j))).chain([pole(ng - 1)]).collect())
        .collect();
    SampledTable { gamma_deg, c_deg, cd: table }
}

/// The date written into the files: `SOURCE_DATE_EPOCH` (seconds since 1970, the
/// reproducible-builds convention) when set, else today (UTC), as YYYY-MM-DD.
pub fn issue_date() -> String {
    let seconds =
        std::env::var("SOURCE_DATE_EPOCH").ok().and_then(|s| s.trim().parse::<i64>().ok()).unwrap_or_else(|| {
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs() as i64)
        });
    let (y, m, d) = civil_from_days(seconds.div_euclid(86_400));
    format!("{y:04}-{m:02}-{d:02}")
}

/// Gregorian date of a day count from 1970-01-01 (Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + (m <= 2) as i64, m, d)
}

/// A number with six significant digits in plain decimal notation (no exponent, which not
/// every photometric reader parses), trailing zeros dropped.
pub fn decimal(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return "0".into();
    }
    let digits = (5 - v.abs().log10().floor() as i32).clamp(0, 15) as usize;
    let s = format!("{v:.digits$}");
    let s = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.').to_string() } else { s };
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

/// Text safe in a photometric file's header: printable ASCII (others become '?'), one line.
fn ascii(s: &str, max: usize) -> String {
    s.chars().map(|c| if (' '..='~').contains(&c) { c } else { '?' }).take(max).collect()
}

/// The lights' electrical input power, when every light comes from a photometric file that
/// gives one.
fn input_watts(scene: &Scene) -> Option<f64> {
    let each: Option<Vec<f64>> = scene.lights.iter().map(|l| l.ies.as_ref().and_then(|i| i.profile.input_w)).collect();
    each.filter(|w| !w.is_empty()).map(|w| w.iter().sum())
}

/// Numbers joined by spaces on lines of at most 80 characters, each line ended by CR LF.
fn wrapped(values: impl IntoIterator<Item = String>, out: &mut String) {
    let mut line = String::new();
    for v in values {
        if !line.is_empty() && line.len() + 1 + v.len() > 80 {
            out.push_str(&line);
            out.push_str("\r\n");
            line.clear();
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&v);
    }
    if !line.is_empty() {
        out.push_str(&line);
        out.push_str("\r\n");
    }
}

/// What the run was: for the files' headers.
pub struct RunLabel<'a> {
    pub scene: &'a Scene,
    pub photons: u64,
    pub seed: u64,
}

/// farfield_<name>.ies: IES LM-63-2019, photometric type C, absolute photometry.
pub fn ies_text(e: &FarFieldEstimate, run: &RunLabel) -> String {
    let t = sampled_table(e);
    let d = &e.detector;
    let mut s = String::new();
    let mut line = |l: String| {
        s.push_str(&l);
        s.push_str("\r\n");
    };
    line("IES:LM-63-2019".into());
    line(format!(
        "[TEST] photon far-field detector {}, {} photons, seed {}",
        ascii(&d.name, 100),
        run.photons,
        run.seed
    ));
    line(format!("[TESTLAB] photon {} Monte Carlo light tracer", env!("CARGO_PKG_VERSION")));
    line(format!("[ISSUEDATE] {}", issue_date()));
    line(format!("[MANUFAC] simulated by photon from {}", ascii(&run.scene.stem(), 120)));
    line(format!("[LUMINAIRE] {}", ascii(&run.scene.stem(), 200)));
    line(format!(
        "[FILEGENINFO] {} gamma bands x {} C sectors; bin means at bin centres, poles the mean of the first and last band",
        d.resolution[0], d.resolution[1]
    ));
    line("[_STDERR] standard errors per bin in the detector's CSV file".into());
    line("TILT=NONE".into());
    // One plane for a rotationally symmetric detector; else the full circle, closed at 360°.
    let mut c_deg = t.c_deg.clone();
    let mut cd = t.cd.clone();
    if c_deg.len() > 1 {
        c_deg.push(360.0);
        cd.push(cd[0].clone());
    }
    line(format!("1 -1 1 {} {} 1 2 0 0 0", t.gamma_deg.len(), c_deg.len()));
    line(format!("1 {FILE_GENERATION_SIMULATION} {}", decimal(input_watts(run.scene).unwrap_or(0.0))));
    wrapped(t.gamma_deg.iter().map(|&g| decimal(g)), &mut s);
    wrapped(c_deg.iter().map(|&c| decimal(c)), &mut s);
    for column in &cd {
        wrapped(column.iter().map(|&v| decimal(v)), &mut s);
    }
    s
}

/// farfield_<name>.ldt: EULUMDAT, no symmetry (one plane for a rotationally symmetric detector),
/// intensities in cd per 1000 lm of the luminaire's own flux.
pub fn ldt_text(e: &FarFieldEstimate, run: &RunLabel) -> String {
    let t = sampled_table(e);
    let d = &e.detector;
    let [ng, nc] = d.resolution;
    let total_lm: f64 = e.flux_lm.iter().map(|f| f.0).sum();
    // Share of the flux below the horizontal (γ < 90°), a straddling band split by solid angle.
    let downward: f64 = (0..nc)
        .flat_map(|j| (0..ng).map(move |i| (i, j)))
        .map(|(i, j)| {
            let (g0, g1, _) = d.bin_angles(i, j);
            let below = if g1 <= 90.0 {
                1.0
            } else if g0 >= 90.0 {
                0.0
            } else {
                g0.to_radians().cos() / (g0.to_radians().cos() - g1.to_radians().cos())
            };
            below * e.flux_lm[j * ng + i].0
        })
        .sum();
    let percent = |x: f64| if total_lm > 0.0 { decimal(100.0 * x / total_lm) } else { "0".into() };
    let per_klm = if total_lm > 0.0 { 1000.0 / total_lm } else { 0.0 };
    let symmetric = nc == 1;
    let mut s = String::new();
    let mut line = |l: String| {
        s.push_str(&l);
        s.push_str("\r\n");
    };
    line(format!("photon {} far-field detector {}", env!("CARGO_PKG_VERSION"), ascii(&d.name, 40)));
    line(if symmetric { "1" } else { "3" }.into());
    line(if symmetric { "1" } else { "0" }.into());
    line(nc.to_string());
    line(if symmetric { "0".into() } else { decimal(360.0 / nc as f64) });
    line(t.gamma_deg.len().to_string());
    // γ steps are not equal (half a band at each pole): Dg = 0.
    line("0".into());
    line(format!("{} photons, seed {}", run.photons, run.seed));
    line(ascii(&run.scene.stem(), 78));
    line(ascii(&d.name, 78));
    line(file_name(&d.name, "ldt"));
    line(format!("{} photon", issue_date()));
    for _ in 0..9 {
        line("0".into());
    }
    line(percent(downward));
    line("100".into());
    line("1".into());
    line("0".into());
    // One lamp set: the luminaire itself (absolute photometry).
    line("1".into());
    line("1".into());
    line("simulated light sources".into());
    line(decimal(total_lm));
    line("-".into());
    line("-".into());
    line(decimal(input_watts(run.scene).unwrap_or(0.0)));
    // Direct ratios need a room model (utilisation factors): not computed.
    for _ in 0..10 {
        line("0".into());
    }
    for &c in &t.c_deg {
        line(decimal(c));
    }
    for &g in &t.gamma_deg {
        line(decimal(g));
    }
    for column in &t.cd {
        for &v in column {
            line(decimal(v * per_klm));
        }
    }
    s
}

pub fn write_ies(dir: &Path, e: &FarFieldEstimate, run: &RunLabel) -> Result<PathBuf, Error> {
    crate::output::write_atomic(dir, &file_name(&e.detector.name, "ies"), ies_text(e, run).as_bytes())
}

pub fn write_ldt(dir: &Path, e: &FarFieldEstimate, run: &RunLabel) -> Result<PathBuf, Error> {
    crate::output::write_atomic(dir, &file_name(&e.detector.name, "ldt"), ldt_text(e, run).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn days_become_dates() {
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(20_790), (2026, 12, 3));
        assert_eq!(civil_from_days(11_017), (2000, 3, 1));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
    }

    #[test]
    fn decimals_keep_six_significant_digits_without_exponents() {
        assert_eq!(decimal(755.4), "755.4");
        assert_eq!(decimal(1234567.0), "1234567");
        assert_eq!(decimal(0.000123456789), "0.000123457");
        assert_eq!(decimal(2.5), "2.5");
        assert_eq!(decimal(180.0), "180");
        assert_eq!(decimal(0.0), "0");
    }
}
