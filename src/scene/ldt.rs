//! EULUMDAT photometric files (`.ldt`): a luminaire's intensity table I(γ, C) in cd per 1000 lm
//! of its lamps, read into the same `IesProfile` (bilinear between tabulated angles, sampled by
//! its exact sub-cell fluxes) as an IES LM-63 file.
//!
//! The format is one field per line: identification, type indicator Ityp (0–3), symmetry
//! indicator Isym, the number Mc of C planes over 0–360° and their spacing, the number Ng of γ
//! angles and their spacing, five text lines, nine dimensions (mm), the downward flux fraction
//! and light output ratio (%), the conversion factor for the intensities, the measurement tilt,
//! the number n of lamp sets and for each set six lines (lamp count, type, total flux in lm,
//! colour, colour rendering, wattage with ballast), ten direct ratios, the Mc C angles, the Ng γ
//! angles, and the intensities plane by plane. Isym says which planes are stored: 0 all Mc, 1 one
//! (symmetric about the vertical axis), 2 C0–C180 (symmetric about that plane), 3 C90–C270 (about
//! that plane; the convention of the EULUMDAT editors QLumEdit and LDT Editor), 4 C0–C90 (about
//! both). Intensities in cd are the table's values × Φ_lamps/1000 × the conversion factor, with
//! Φ_lamps the first lamp set's flux (further sets are alternatives).

use std::path::Path;

use crate::error::InputError;
use crate::scene::ies::{expand_symmetry, IesProfile, MAX_CANDELA};

/// Most C planes or γ angles accepted (0.036° and 0.018° steps).
const MAX_ANGLES: usize = 10_000;
const MAX_LAMP_SETS: usize = 1000;

struct Lines<'a> {
    path: &'a Path,
    lines: Vec<&'a str>,
    at: usize,
}

impl<'a> Lines<'a> {
    fn err(&self, line: usize, m: String) -> InputError {
        InputError::new(self.path, "", Some(line), m)
    }

    /// The next line (1-based number, text without surrounding blanks).
    fn next(&mut self, what: &str) -> Result<(usize, &'a str), InputError> {
        let Some(l) = self.lines.get(self.at) else {
            return Err(self.err(self.lines.len().max(1), format!("the file ends where {what} should be")));
        };
        self.at += 1;
        Ok((self.at, l.trim()))
    }

    /// A number; a decimal comma is read as a point (files written in German locales). An
    /// empty line reads `empty` when given, and is an error otherwise.
    fn number(&mut self, what: &str, empty: Option<f64>) -> Result<(f64, usize), InputError> {
        let (line, text) = self.next(what)?;
        if text.is_empty() {
            return empty
                .map(|v| (v, line))
                .ok_or_else(|| self.err(line, format!("an empty line where {what} should be")));
        }
        let normal = if text.contains('.') { text.to_string() } else { text.replace(',', ".") };
        let v: f64 = normal.parse().map_err(|_| self.err(line, format!("`{text}` is not a number ({what})")))?;
        if !v.is_finite() {
            return Err(self.err(line, format!("{what} must be finite, found {text}")));
        }
        Ok((v, line))
    }

    /// A whole number from `lo` to `hi`.
    fn count(&mut self, what: &str, lo: usize, hi: usize) -> Result<(usize, usize), InputError> {
        let (v, line) = self.number(what, None)?;
        if !(v.fract() == 0.0 && v >= lo as f64 && v <= hi as f64) {
            return Err(self.err(line, format!("{what} must be a whole number from {lo} to {hi}, found {v}")));
        }
        Ok((v as usize, line))
    }
}

pub fn read(path: &Path) -> Result<IesProfile, InputError> {
    let text = crate::error::read_text_lossy(path, "EULUMDAT file")?;
    parse(path, &text)
}

pub fn parse(path: &Path, text: &str) -> Result<IesProfile, InputError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut f = Lines { path, lines: text.lines().collect(), at: 0 };
    f.next("the identification line")?;
    f.count("the type indicator Ityp", 0, 3)?;
    let (isym, isym_line) = f.count("the symmetry indicator Isym", 0, 4)?;
    let (mc, mc_line) = f.count("the number of C planes Mc", 1, MAX_ANGLES)?;
    f.number("the distance between C planes Dc", Some(0.0))?;
    let (ng, ng_line) = f.count("the number of intensities per C plane Ng", 2, MAX_ANGLES)?;
    f.number("the distance between intensities Dg", Some(0.0))?;
    for what in [
        "the measurement report number",
        "the luminaire name",
        "the luminaire number",
        "the file name",
        "the date and user",
    ] {
        f.next(what)?;
    }
    for what in [
        "the luminaire's length or diameter (mm)",
        "the luminaire's width (mm)",
        "the luminaire's height (mm)",
        "the luminous area's length or diameter (mm)",
        "the luminous area's width (mm)",
        "the luminous area's height at C0 (mm)",
        "the luminous area's height at C90 (mm)",
        "the luminous area's height at C180 (mm)",
        "the luminous area's height at C270 (mm)",
        "the downward flux fraction (%)",
        "the light output ratio (%)",
    ] {
        f.number(what, Some(0.0))?;
    }
    let (conversion, cl) = f.number("the conversion factor for the intensities", Some(1.0))?;
    if !(conversion > 0.0) {
        return Err(
            f.err(cl, format!("the conversion factor for the intensities must be positive, found {conversion}"))
        );
    }
    f.number("the tilt during measurement", Some(0.0))?;
    let (sets, _) = f.count("the number of lamp sets", 1, MAX_LAMP_SETS)?;
    let mut lamps_lm = None;
    let mut watts = None;
    for set in 0..sets {
        f.number("the number of lamps", Some(1.0))?;
        f.next("the type of lamps")?;
        let (flux, fl) = f.number("the lamps' total luminous flux (lm)", None)?;
        if set == 0 && !(flux > 0.0) {
            return Err(f.err(fl, format!("the lamps' total luminous flux must be positive, found {flux} lm")));
        }
        f.next("the lamps' colour appearance")?;
        f.next("the lamps' colour rendering")?;
        let (w, _) = f.number("the wattage including ballast (W)", Some(0.0))?;
        if set == 0 {
            lamps_lm = Some(flux);
            watts = (w > 0.0).then_some(w);
        }
    }
    let lamps_lm = lamps_lm.expect("at least one lamp set");
    for k in 0..10 {
        f.number(&format!("direct ratio {} of 10", k + 1), Some(0.0))?;
    }
    let mut angles = |n: usize, what: &str, hi: f64| -> Result<(Vec<f64>, usize), InputError> {
        let mut v: Vec<f64> = Vec::with_capacity(n);
        let mut first_line = 0;
        for k in 0..n {
            let (a, line) = f.number(what, None)?;
            if k == 0 {
                first_line = line;
            }
            if !(0.0..=hi).contains(&a) {
                return Err(f.err(line, format!("{what} must lie within 0 to {hi} degrees, found {a}")));
            }
            if let Some(&prev) = v.last() {
                if !(a > prev) {
                    return Err(f.err(line, format!("{what} must increase, found {a} after {prev}")));
                }
            }
            v.push(a);
        }
        Ok((v, first_line))
    };
    let (c_all, cl) = angles(mc, "C angles", 360.0)?;
    let (gamma_deg, _) = angles(ng, "γ angles", 180.0)?;
    if c_all[0] != 0.0 {
        return Err(f.err(cl, format!("the C angles must begin at 0, found {}", c_all[0])));
    }
    // The stored planes and their angles, as an LM-63 table's horizontal angles.
    let plane_range = |from: f64, to: f64, divisor: usize| -> Result<Vec<f64>, InputError> {
        if !mc.is_multiple_of(divisor) {
            return Err(f.err(
                mc_line,
                format!("Isym {isym} stores the C{from}–C{to} planes of Mc = {mc}: Mc must be a multiple of {divisor}"),
            ));
        }
        let start = c_all.iter().position(|&c| (c - from).abs() < 1e-9);
        let count = mc / divisor + 1;
        match start.map(|s| (s, c_all.get(s..s + count))) {
            Some((_, Some(stored))) if (stored[count - 1] - to).abs() < 1e-9 => Ok(stored.to_vec()),
            _ => Err(f.err(
                cl,
                format!(
                    "Isym {isym} stores {count} planes from C{from} to C{to}: the C angles must hold them in a row, \
                     C{from} first and C{to} last"
                ),
            )),
        }
    };
    let (h_deg, planes) = match isym {
        0 => {
            let mut h = c_all.clone();
            h.push(360.0);
            (h, mc)
        }
        1 => (vec![0.0], 1),
        2 => (plane_range(0.0, 180.0, 2)?, mc / 2 + 1),
        3 => (plane_range(90.0, 270.0, 2)?, mc / 2 + 1),
        _ => (plane_range(0.0, 90.0, 4)?, mc / 4 + 1),
    };
    let scale = lamps_lm / 1000.0 * conversion;
    let mut table: Vec<Vec<f64>> = Vec::with_capacity(planes + 1);
    for _ in 0..planes {
        let mut column = Vec::with_capacity(ng);
        for _ in 0..ng {
            let (v, line) = f.number("an intensity (cd/klm)", None)?;
            if v < 0.0 {
                return Err(f.err(line, format!("intensities must be >= 0, found {v}")));
            }
            if !(v * scale <= MAX_CANDELA) {
                return Err(f.err(
                    line,
                    format!("an intensity of {:e} cd (after the lamps' flux and the conversion factor) is beyond the {MAX_CANDELA:e} cd photon accepts", v * scale),
                ));
            }
            column.push(v * scale);
        }
        table.push(column);
    }
    if isym == 0 {
        // The full circle closes on C0 again at 360°.
        table.push(table[0].clone());
    }
    if let Some(k) = (f.at..f.lines.len()).find(|&k| !f.lines[k].trim().is_empty()) {
        return Err(f.err(k + 1, format!("unexpected `{}` after the intensity table", f.lines[k].trim())));
    }
    let (c_deg, cd) = expand_symmetry(&h_deg, table).map_err(|m| f.err(isym_line, m))?;
    IesProfile::from_table(gamma_deg, c_deg, cd, Some(lamps_lm), watts).map_err(|m| f.err(ng_line, m))
}
