//! Spectra: constant, tabulated (piecewise linear, zero outside the table), blackbody, and
//! Cauchy and Sellmeier dispersion; and the tabulated CDF used to sample a wavelength by inverse
//! transform.

pub mod color;
pub mod photometry;

use std::path::Path;

use crate::error::InputError;

/// `f` applied to each element of `a`, as a plain loop. `array::map` and `array::from_fn` wrap
/// their closure for a fallible variant, and those wrappers were left out of line in the photon
/// loop: 7 % of a spectral image run went to calls of them (issue #23).
#[inline(always)]
pub fn map_array<T: Copy, U: Copy + Default, const N: usize>(a: [T; N], mut f: impl FnMut(T) -> U) -> [U; N] {
    let mut out = [U::default(); N];
    for k in 0..N {
        out[k] = f(a[k]);
    }
    out
}

/// A value per wavelength lane: one lane for a particle's own wavelength, four for hero
/// wavelengths and camera samples. In grey transport every lane holds the same value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lanes<const N: usize = 4>(pub [f64; N]);

impl<const N: usize> Lanes<N> {
    pub const ZERO: Lanes<N> = Lanes([0.0; N]);
    pub const ONE: Lanes<N> = Lanes([1.0; N]);

    #[inline]
    pub fn splat(v: f64) -> Self {
        Lanes([v; N])
    }

    /// The spectrum at wavelengths `lambda` (once, and repeated, in grey transport).
    #[inline]
    pub fn eval<const SPECTRAL: bool>(spectrum: &Spectrum, lambda: &[f64; N]) -> Self {
        if SPECTRAL {
            // The kind decided once for all lanes: a hit's hero lookups are one table's four.
            match spectrum {
                Spectrum::Constant(c) => Lanes::splat(*c),
                Spectrum::Table(t) => Lanes(t.eval_lanes(lambda)),
                _ => Lanes(map_array(*lambda, |l| spectrum.eval(l))),
            }
        } else {
            Lanes::splat(spectrum.eval(f64::NAN))
        }
    }

    #[inline]
    pub fn mean(&self) -> f64 {
        self.0.iter().sum::<f64>() / N as f64
    }

    #[inline]
    pub fn is_zero(&self) -> bool {
        self.0.iter().all(|&v| v == 0.0)
    }
}

impl<const N: usize> std::ops::Add for Lanes<N> {
    type Output = Lanes<N>;
    #[inline]
    fn add(self, o: Lanes<N>) -> Lanes<N> {
        let mut sum = self.0;
        for (s, x) in sum.iter_mut().zip(o.0) {
            *s += x;
        }
        Lanes(sum)
    }
}

impl<const N: usize> std::ops::Mul for Lanes<N> {
    type Output = Lanes<N>;
    #[inline]
    fn mul(self, o: Lanes<N>) -> Lanes<N> {
        let mut product = self.0;
        for (p, x) in product.iter_mut().zip(o.0) {
            *p *= x;
        }
        Lanes(product)
    }
}

impl<const N: usize> std::ops::Mul<f64> for Lanes<N> {
    type Output = Lanes<N>;
    #[inline]
    fn mul(self, o: f64) -> Lanes<N> {
        Lanes(map_array(self.0, |v| v * o))
    }
}

impl<const N: usize> std::ops::MulAssign for Lanes<N> {
    #[inline]
    fn mul_assign(&mut self, o: Lanes<N>) {
        *self = *self * o;
    }
}

impl<const N: usize> std::ops::MulAssign<f64> for Lanes<N> {
    #[inline]
    fn mul_assign(&mut self, o: f64) {
        *self = *self * o;
    }
}

/// Planck's constant (J s), speed of light (m/s), Boltzmann's constant (J/K); CODATA 2018 exact values.
const PLANCK_H: f64 = 6.626_070_15e-34;
const LIGHT_C: f64 = 299_792_458.0;
const BOLTZMANN_K: f64 = 1.380_649e-23;

#[derive(Clone, Debug, PartialEq)]
pub enum Spectrum {
    Constant(f64),
    /// (wavelength_nm, value), wavelengths strictly increasing; linear between points, zero outside.
    Table(Table),
    /// Planck spectral radiance at temperature `kelvin`, in W m^-2 sr^-1 nm^-1.
    Blackbody {
        kelvin: f64,
    },
    /// Cauchy's equation n(λ) = A + B/λ², with λ in micrometres (B in µm²).
    Cauchy {
        a: f64,
        b_um2: f64,
    },
    /// Sellmeier's equation n² = 1 + Σ Bᵢλ²/(λ² − Cᵢ), λ in micrometres: the terms (Bᵢ, Cᵢ),
    /// Cᵢ in µm². The loader checks that n² is positive and finite over the simulated range.
    Sellmeier {
        terms: Vec<(f64, f64)>,
    },
}

/// A tabulated spectrum. Tables on a uniform grid (most measured data) are looked up in O(1);
/// others by binary search.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// Private: `eval` relies on `uniform` describing exactly these points.
    points: Vec<(f64, f64)>,
    /// The grid, when the wavelengths are equally spaced.
    uniform: Option<Grid>,
}

/// A uniform table's first wavelength (so a lookup reads no point to find it), 1/step, and its
/// last point's index as u32: converting a usize index to and from f64 and two bounds checks
/// were half of a lookup's instructions.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Grid {
    x0: f64,
    inv_step: f64,
    last: u32,
}

impl Table {
    pub fn new(points: Vec<(f64, f64)>) -> Self {
        // At most 2^31 points, so that an index fits the signed conversion of `eval_pair`.
        let uniform = points.len() >= 2 && points.len() <= i32::MAX as usize && {
            let step = points[1].0 - points[0].0;
            points.windows(2).all(|w| ((w[1].0 - w[0].0) - step).abs() <= 1e-9 * step)
        };
        let uniform = uniform.then(|| {
            let last = points.len() - 1;
            Grid { x0: points[0].0, inv_step: last as f64 / (points[last].0 - points[0].0), last: last as u32 }
        });
        Table { points, uniform }
    }

    #[inline(always)]
    fn eval(&self, x: f64) -> f64 {
        let p = &self.points;
        let Some(g) = self.uniform else { return table_eval(p, x) };
        let f = (x - g.x0) * g.inv_step;
        if !(f >= 0.0 && f <= g.last as f64) {
            return 0.0;
        }
        // SAFETY: 0 ≤ f ≤ last < 2^32, so the truncation is in range.
        let i = unsafe { f.to_int_unchecked::<u32>() }.min(g.last - 1);
        let t = f - i as f64;
        // SAFETY: i + 1 ≤ last = points.len() − 1 (a uniform table has at least two points).
        let (lo, hi) = unsafe { (p.get_unchecked(i as usize).1, p.get_unchecked(i as usize + 1).1) };
        lo + (hi - lo) * t
    }

    /// `eval` at each of `x`, two lanes at a time in SSE2 (every x86-64 CPU has it): the
    /// same operations in the same order, so the same bits, in about half the instructions.
    #[inline(always)]
    fn eval_lanes<const N: usize>(&self, x: &[f64; N]) -> [f64; N] {
        #[cfg(target_arch = "x86_64")]
        if let Some(g) = &self.uniform {
            let mut out = [0.0; N];
            for k in (0..N - N % 2).step_by(2) {
                [out[k], out[k + 1]] = self.eval_pair(g, [x[k], x[k + 1]]);
            }
            if N % 2 == 1 {
                out[N - 1] = self.eval(x[N - 1]);
            }
            return out;
        }
        map_array(*x, |l| self.eval(l))
    }

    /// `eval` at two wavelengths of the uniform table on grid `g`: f = (x − x₀)/step, zero
    /// unless 0 ≤ f ≤ last; else i = ⌊min(f, last − 1)⌋ (as ⌊f⌋ capped at last − 1) and
    /// y_i + (y_{i+1} − y_i)(f − i).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn eval_pair(&self, g: &Grid, x: [f64; 2]) -> [f64; 2] {
        use std::arch::x86_64::*;
        let p = &self.points;
        // SAFETY: SSE2 is part of x86-64. A lane outside the table is masked to f = 0, so each
        // lane's i ≤ last − 1 < 2^31 (`new`), and i + 1 ≤ last = points.len() − 1.
        unsafe {
            let f = _mm_mul_pd(_mm_sub_pd(_mm_loadu_pd(x.as_ptr()), _mm_set1_pd(g.x0)), _mm_set1_pd(g.inv_step));
            let inside = _mm_and_pd(_mm_cmpge_pd(f, _mm_setzero_pd()), _mm_cmple_pd(f, _mm_set1_pd(g.last as f64)));
            let f = _mm_and_pd(f, inside);
            let i = _mm_cvttpd_epi32(_mm_min_pd(f, _mm_set1_pd((g.last - 1) as f64)));
            let t = _mm_sub_pd(f, _mm_cvtepi32_pd(i));
            let i0 = _mm_cvtsi128_si32(i) as u32 as usize;
            let i1 = _mm_cvtsi128_si32(_mm_shuffle_epi32::<0b01>(i)) as u32 as usize;
            let lo = _mm_loadh_pd(_mm_load_sd(&p.get_unchecked(i0).1), &p.get_unchecked(i1).1);
            let hi = _mm_loadh_pd(_mm_load_sd(&p.get_unchecked(i0 + 1).1), &p.get_unchecked(i1 + 1).1);
            let v = _mm_and_pd(_mm_add_pd(lo, _mm_mul_pd(_mm_sub_pd(hi, lo), t)), inside);
            let mut out = [0.0; 2];
            _mm_storeu_pd(out.as_mut_ptr(), v);
            out
        }
    }
}

/// Planck's law: B(λ, T) = 2hc²/λ⁵ / (exp(hc/(λkT)) − 1), per metre of wavelength; returned per nm.
pub fn planck_w_m2_sr_nm(lambda_nm: f64, kelvin: f64) -> f64 {
    let lambda_m = lambda_nm * 1e-9;
    let x = PLANCK_H * LIGHT_C / (lambda_m * BOLTZMANN_K * kelvin);
    2.0 * PLANCK_H * LIGHT_C * LIGHT_C / lambda_m.powi(5) / x.exp_m1() * 1e-9
}

impl Spectrum {
    #[inline]
    pub fn eval(&self, lambda_nm: f64) -> f64 {
        // A constant (every grey material) by one compare: the kind's jump table cost ~11
        // instructions an evaluation, two a hit in grey transport.
        if let Spectrum::Constant(c) = self {
            return *c;
        }
        self.eval_varying(lambda_nm)
    }

    #[inline]
    fn eval_varying(&self, lambda_nm: f64) -> f64 {
        match self {
            Spectrum::Constant(c) => *c,
            Spectrum::Table(t) => t.eval(lambda_nm),
            Spectrum::Blackbody { kelvin } => planck_w_m2_sr_nm(lambda_nm, *kelvin),
            Spectrum::Cauchy { a, b_um2 } => {
                let um = lambda_nm * 1e-3;
                a + b_um2 / (um * um)
            }
            Spectrum::Sellmeier { terms } => sellmeier_n2(terms, lambda_nm).sqrt(),
        }
    }

    /// Some(c) when the spectrum takes the single value c everywhere in `range`.
    pub fn constant_over(&self, range: (f64, f64)) -> Option<f64> {
        match self {
            Spectrum::Constant(c) => Some(*c),
            Spectrum::Table(Table { points, .. }) => {
                let first = points.first()?;
                let last = points.last()?;
                let covers = first.0 <= range.0 && last.0 >= range.1;
                let all_equal = points.iter().all(|p| p.1 == first.1);
                (covers && all_equal).then_some(first.1)
            }
            Spectrum::Cauchy { a, b_um2 } => (*b_um2 == 0.0).then_some(*a),
            // Bᵢλ²/(λ² − Cᵢ) is the constant Bᵢ when Cᵢ = 0, and nothing when Bᵢ = 0.
            Spectrum::Sellmeier { terms } => terms
                .iter()
                .all(|&(b, c)| b == 0.0 || c == 0.0)
                .then(|| (1.0 + terms.iter().map(|t| t.0).sum::<f64>()).sqrt()),
            Spectrum::Blackbody { .. } => None,
        }
    }

    /// Smallest and largest value over `range` (exact for tables; sampled at 1 nm otherwise).
    pub fn min_max_over(&self, range: (f64, f64)) -> (f64, f64) {
        let (mut lo, mut hi) = if self.has_gaps(range) { (0.0, 0.0) } else { (f64::INFINITY, f64::NEG_INFINITY) };
        for x in self.breakpoints(range) {
            let v = self.eval(x);
            lo = lo.min(v);
            hi = hi.max(v);
        }
        (lo, hi)
    }

    /// Wavelengths at which the spectrum is exactly linear in between, spanning its support within
    /// `range`: a table is zero outside its own points, so its span is clipped to them (a trapezoid
    /// across the jump at a table's end would invent power that is not there). Analytic spectra
    /// get a 1 nm grid.
    pub fn breakpoints(&self, range: (f64, f64)) -> Vec<f64> {
        let (mut a, mut b) = range;
        if let Spectrum::Table(Table { points, .. }) = self {
            a = a.max(points[0].0);
            b = b.min(points[points.len() - 1].0);
            if a >= b {
                return vec![range.0, range.1];
            }
        }
        let mut xs = vec![a];
        match self {
            Spectrum::Constant(_) => {}
            Spectrum::Table(Table { points, .. }) => xs.extend(points.iter().map(|p| p.0).filter(|&x| x > a && x < b)),
            Spectrum::Blackbody { .. } | Spectrum::Cauchy { .. } | Spectrum::Sellmeier { .. } => {
                let mut x = a.floor() + 1.0;
                while x < b {
                    xs.push(x);
                    x += 1.0;
                }
            }
        }
        xs.push(b);
        xs
    }

    /// True when a table leaves part of `range` uncovered, where it is zero.
    pub fn has_gaps(&self, range: (f64, f64)) -> bool {
        match self {
            Spectrum::Table(Table { points, .. }) => points[0].0 > range.0 || points[points.len() - 1].0 < range.1,
            _ => false,
        }
    }

    /// ∫ over `range` of the spectrum, in value·nm (trapezoid between breakpoints: exact for tables).
    pub fn integral(&self, range: (f64, f64)) -> f64 {
        let xs = self.breakpoints(range);
        xs.windows(2).map(|w| 0.5 * (self.eval(w[0]) + self.eval(w[1])) * (w[1] - w[0])).sum()
    }
}

/// n² = 1 + Σ Bᵢλ²/(λ² − Cᵢ) at `lambda_nm` (λ in µm inside the sum; Cᵢ in µm²).
#[inline]
pub fn sellmeier_n2(terms: &[(f64, f64)], lambda_nm: f64) -> f64 {
    let l2 = (lambda_nm * 1e-3) * (lambda_nm * 1e-3);
    1.0 + terms.iter().map(|&(b, c)| b * l2 / (l2 - c)).sum::<f64>()
}

/// The wavelength (nm) of the pole λ² = C of a Sellmeier term, if it lies inside `range` (nm).
pub fn sellmeier_pole_in(c_um2: f64, range: (f64, f64)) -> Option<f64> {
    let pole_nm = c_um2.sqrt() * 1e3;
    (c_um2 > 0.0 && pole_nm >= range.0 && pole_nm <= range.1).then_some(pole_nm)
}

/// Err(why) when Sellmeier terms cannot describe an index over `range` (nm): a pole λ² = Cᵢ
/// inside it, or n² not positive and finite somewhere in it, checked at the range's ends and at
/// every whole nanometre between (the wavelengths `breakpoints` gives an analytic spectrum).
pub fn check_sellmeier(terms: &[(f64, f64)], range: (f64, f64)) -> Result<(), String> {
    if let Some((i, pole)) = terms.iter().enumerate().find_map(|(i, t)| Some((i, sellmeier_pole_in(t.1, range)?))) {
        return Err(format!(
            "term {i} has a pole of n² (λ² = C, λ = {pole:.1} nm) inside the simulated wavelength_range_nm [{}, {}]",
            range.0, range.1
        ));
    }
    let s = Spectrum::Sellmeier { terms: terms.to_vec() };
    match s.breakpoints(range).into_iter().find(|&x| {
        let n2 = sellmeier_n2(terms, x);
        !(n2 > 0.0 && n2.is_finite())
    }) {
        Some(x) => Err(format!(
            "n² = 1 + Σ Bλ²/(λ² − C) must be positive and finite over the simulated wavelength_range_nm [{}, {}]; \
             at {x} nm it is {}",
            range.0,
            range.1,
            sellmeier_n2(terms, x)
        )),
        None => Ok(()),
    }
}

fn table_eval(points: &[(f64, f64)], x: f64) -> f64 {
    let i = points.partition_point(|p| p.0 < x);
    if i == 0 {
        return if points.first().is_some_and(|p| p.0 == x) { points[0].1 } else { 0.0 };
    }
    if i == points.len() {
        return 0.0;
    }
    let (x0, y0) = points[i - 1];
    let (x1, y1) = points[i];
    y0 + (y1 - y0) * (x - x0) / (x1 - x0)
}

/// Inverse-CDF sampler of a wavelength from a non-negative spectrum that is piecewise linear
/// between breakpoints: pick the segment by its integral, then invert the segment's quadratic
/// CDF exactly. No rejection loop.
#[derive(Clone, Debug)]
pub struct SpectralSampler {
    xs: Vec<f64>,
    ys: Vec<f64>,
    /// cdf[i] = ∫ from xs[0] to xs[i], unnormalised; cdf.last() is the total.
    cdf: Vec<f64>,
    /// guide[j]: the last segment whose cdf starts at or below j/G of the total, where the search
    /// for a u in [j/G, (j+1)/G) begins (a guide table: O(1) expected instead of a binary search).
    guide: Vec<u32>,
    /// 2(f1 − f0)/w per segment: the quadratic's coefficient, kept so a sample divides once.
    twice_slope: Vec<f64>,
}

impl SpectralSampler {
    /// None when the spectrum integrates to zero over the range.
    pub fn new(spectrum: &Spectrum, range: (f64, f64)) -> Option<Self> {
        let xs = spectrum.breakpoints(range);
        let ys: Vec<f64> = xs.iter().map(|&x| spectrum.eval(x).max(0.0)).collect();
        let mut cdf = Vec::with_capacity(xs.len());
        cdf.push(0.0);
        for i in 1..xs.len() {
            cdf.push(cdf[i - 1] + 0.5 * (ys[i - 1] + ys[i]) * (xs[i] - xs[i - 1]));
        }
        let total = *cdf.last().unwrap();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let cells = xs.len().max(64);
        let guide = (0..cells)
            .map(|j| {
                let start = j as f64 / cells as f64 * total;
                (cdf.partition_point(|&c| c <= start).max(1) - 1).min(xs.len() - 2) as u32
            })
            .collect();
        let twice_slope = xs.windows(2).zip(ys.windows(2)).map(|(x, y)| 2.0 * (y[1] - y[0]) / (x[1] - x[0])).collect();
        Some(SpectralSampler { xs, ys, cdf, guide, twice_slope })
    }

    pub fn total(&self) -> f64 {
        *self.cdf.last().unwrap()
    }

    /// Segment i (spanning xs[i]..xs[i+1]) holding `target` = u·total: the last with
    /// cdf[i] ≤ target, and i ≤ len − 2. The guide's start is at or just below it; the backward
    /// step only guards against rounding in u·cells.
    #[inline]
    fn segment(&self, u: f64, target: f64) -> usize {
        let cells = self.guide.len();
        let mut i = self.guide[((u * cells as f64) as usize).min(cells - 1)] as usize;
        while i > 0 && self.cdf[i] > target {
            i -= 1;
        }
        while i + 2 < self.xs.len() && self.cdf[i + 1] <= target {
            i += 1;
        }
        i
    }

    /// The share of ∫f below `x`: the u that `sample` maps to x.
    pub fn cdf_at(&self, x: f64) -> f64 {
        let n = self.xs.len();
        if !(x > self.xs[0]) {
            return 0.0;
        }
        if x >= self.xs[n - 1] {
            return 1.0;
        }
        let i = (self.xs.partition_point(|&v| v <= x) - 1).min(n - 2);
        let (x0, x1) = (self.xs[i], self.xs[i + 1]);
        let (f0, f1) = (self.ys[i], self.ys[i + 1]);
        let dx = x - x0;
        let f = f0 + (f1 - f0) * dx / (x1 - x0);
        ((self.cdf[i] + 0.5 * (f0 + f) * dx) / self.total()).min(1.0)
    }

    /// The density `sample` draws from, f(x)/∫f (piecewise linear between breakpoints; zero
    /// outside them).
    pub fn pdf(&self, x: f64) -> f64 {
        let n = self.xs.len();
        if !(x >= self.xs[0] && x <= self.xs[n - 1]) {
            return 0.0;
        }
        let i = (self.xs.partition_point(|&v| v <= x).max(1) - 1).min(n - 2);
        let (x0, x1) = (self.xs[i], self.xs[i + 1]);
        let (f0, f1) = (self.ys[i], self.ys[i + 1]);
        (f0 + (f1 - f0) * (x - x0) / (x1 - x0)) / self.total()
    }

    /// λ with density f(λ)/∫f, from one uniform u in [0, 1).
    pub fn sample(&self, u: f64) -> f64 {
        let target = u * self.total();
        let i = self.segment(u, target);
        let (x0, x1) = (self.xs[i], self.xs[i + 1]);
        let f0 = self.ys[i];
        let w = x1 - x0;
        let r = (target - self.cdf[i]).max(0.0);
        // Solve f0·x + (f1−f0)·x²/(2w) = r for x in [0, w], in the cancellation-free form
        // x = 2r / (f0 + sqrt(f0² + 2(f1−f0)r/w)).
        let disc = (f0 * f0 + self.twice_slope[i] * r).max(0.0);
        let denom = f0 + disc.sqrt();
        let x = if denom > 0.0 { 2.0 * r / denom } else { 0.0 };
        (x0 + x.clamp(0.0, w)).min(x1)
    }
}

/// Wavelengths strictly increasing and positive; values non-negative. Err((row, message)).
pub fn check_table(points: &[(f64, f64)]) -> Result<(), (usize, String)> {
    if points.is_empty() {
        return Err((0, "a spectrum table needs at least one [wavelength_nm, value] row".into()));
    }
    for (i, p) in points.iter().enumerate() {
        if p.0 <= 0.0 {
            return Err((i, format!("wavelength must be positive, found {}", p.0)));
        }
        if p.1 < 0.0 {
            return Err((i, format!("spectrum values must not be negative, found {} at {} nm", p.1, p.0)));
        }
        if i > 0 && p.0 <= points[i - 1].0 {
            return Err((
                i,
                format!(
                    "wavelengths must be sorted and strictly increasing: {} nm follows {} nm",
                    p.0,
                    points[i - 1].0
                ),
            ));
        }
    }
    Ok(())
}

/// Two columns `wavelength_nm,value`, after an optional header line (one whose first column is not a number).
pub fn read_csv(path: &Path) -> Result<Spectrum, InputError> {
    let text = crate::error::read_text_lossy(path, "spectrum file")?;
    let mut points = Vec::new();
    let mut lines_of_rows = Vec::new();
    let parse = |s: &str| s.trim().parse::<f64>().ok().filter(|v| v.is_finite());
    let mut header_seen = false;
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let cols: Vec<&str> = line.split(',').map(str::trim).collect();
        // The header line is optional: a first line of two numbers is the first row, not lost.
        if !header_seen && points.is_empty() {
            header_seen = true;
            if cols.first().and_then(|s| parse(s)).is_none() {
                continue;
            }
        }
        match (cols.len(), cols.first().and_then(|s| parse(s)), cols.get(1).and_then(|s| parse(s))) {
            (2, Some(w), Some(v)) => {
                points.push((w, v));
                lines_of_rows.push(i + 1);
            }
            _ => {
                return Err(InputError::new(
                    path,
                    "",
                    Some(i + 1),
                    format!("expected `wavelength_nm,value` (two finite numbers), found \"{line}\""),
                ))
            }
        }
    }
    if text.lines().next().is_none() {
        return Err(InputError::new(path, "", None, "the spectrum file is empty"));
    }
    check_table(&points)
        .map_err(|(row, m)| InputError::new(path, "", lines_of_rows.get(row).copied().or(Some(1)), m))?;
    Ok(Spectrum::Table(Table::new(points)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_interpolates_and_is_zero_outside() {
        let s = Spectrum::Table(Table::new(vec![(400.0, 1.0), (500.0, 3.0)]));
        assert_eq!(s.eval(450.0), 2.0);
        assert_eq!(s.eval(400.0), 1.0);
        assert_eq!(s.eval(500.0), 3.0);
        assert_eq!(s.eval(399.0), 0.0);
        assert_eq!(s.eval(501.0), 0.0);
        assert_eq!(s.integral((400.0, 500.0)), 200.0);
        // A table narrower than the range is zero outside its points: no ramp up to them.
        assert_eq!(s.integral((360.0, 830.0)), 200.0);
        assert_eq!(s.min_max_over((360.0, 830.0)), (0.0, 3.0));
        let sampler = SpectralSampler::new(&s, (360.0, 830.0)).unwrap();
        assert!((0..100).all(|k| (400.0..=500.0).contains(&sampler.sample(k as f64 / 100.0))));
    }

    #[test]
    fn uniform_and_irregular_tables_interpolate_alike() {
        let pts = vec![(400.0, 0.2), (404.0, 0.5), (408.0, 0.1), (412.0, 0.9)];
        let uniform = Table::new(pts.clone());
        assert!(uniform.uniform.is_some());
        // Past both ends too, where both are zero.
        for k in 0..=160 {
            let x = 398.0 + 0.1 * k as f64;
            assert!((uniform.eval(x) - table_eval(&pts, x)).abs() < 1e-12, "at {x}");
        }
        // The end points exactly (the last one is the top of the last segment), and no number.
        assert_eq!((uniform.eval(400.0), uniform.eval(412.0), uniform.eval(f64::NAN)), (0.2, 0.9, 0.0));
        let two = Table::new(vec![(400.0, 1.0), (500.0, 3.0)]);
        assert!(two.uniform.is_some());
        assert_eq!((two.eval(400.0), two.eval(450.0), two.eval(500.0), two.eval(500.1)), (1.0, 2.0, 3.0, 0.0));
    }

    /// The two-lane lookup is the scalar one's arithmetic: the same bits at every wavelength,
    /// inside, at the grid points and ends, just outside, and at no number or an infinity.
    #[test]
    fn lane_lookups_give_the_scalar_bits() {
        let mut s = crate::sampling::Sampler::for_batch(5, 0);
        let values: Vec<(f64, f64)> = (0..81).map(|k| (380.0 + 5.0 * k as f64, s.uniform() * 2.0 - 0.5)).collect();
        for points in [values, vec![(400.0, 1.0), (500.0, 3.0)]] {
            let table = Table::new(points.clone());
            assert!(table.uniform.is_some());
            let (first, last) = (points[0].0, points[points.len() - 1].0);
            let mut xs: Vec<f64> = points.iter().map(|p| p.0).collect();
            xs.extend([first.next_down(), last.next_up(), last.next_down(), f64::NAN, f64::INFINITY, -f64::INFINITY]);
            xs.extend([-0.0, 0.0, 1e300, -1e300, f64::MIN_POSITIVE]);
            xs.extend((0..4000).map(|_| first - 20.0 + (last - first + 40.0) * s.uniform()));
            for x in xs.chunks_exact(4) {
                let lanes = table.eval_lanes(&[x[0], x[1], x[2], x[3]]);
                let odd = table.eval_lanes(&[x[0], x[1], x[2]]);
                for k in 0..4 {
                    assert_eq!(lanes[k].to_bits(), table.eval(x[k]).to_bits(), "at {}", x[k]);
                }
                for k in 0..3 {
                    assert_eq!(odd[k].to_bits(), table.eval(x[k]).to_bits(), "at {}", x[k]);
                }
            }
        }
    }

    #[test]
    fn sampler_matches_linear_pdf_cdf() {
        // f(λ) = λ − 400 on [400, 500]: CDF(λ) = ((λ−400)/100)², so λ(u) = 400 + 100·√u exactly.
        let s = Spectrum::Table(Table::new(vec![(400.0, 0.0), (500.0, 100.0)]));
        let sampler = SpectralSampler::new(&s, (400.0, 500.0)).unwrap();
        for k in 0..100 {
            let u = k as f64 / 100.0;
            assert!((sampler.sample(u) - (400.0 + 100.0 * u.sqrt())).abs() < 1e-9);
            // cdf_at inverts sample: CDF(λ) = ((λ−400)/100)².
            let l = 400.0 + 100.0 * u.sqrt();
            assert!((sampler.cdf_at(l) - u).abs() < 1e-12, "cdf_at({l})");
        }
        assert_eq!((sampler.cdf_at(350.0), sampler.cdf_at(400.0), sampler.cdf_at(500.0)), (0.0, 0.0, 1.0));
    }

    #[test]
    fn guided_search_finds_the_binary_search_segment() {
        // Zero stretches make flat runs in the cdf, where "the last segment with cdf ≤ target"
        // and a search that starts in the wrong place would disagree.
        let pts =
            vec![(400.0, 0.0), (410.0, 0.0), (420.0, 2.0), (430.0, 0.0), (440.0, 0.0), (450.0, 5.0), (700.0, 1.0)];
        let sampler = SpectralSampler::new(&Spectrum::Table(Table::new(pts)), (400.0, 700.0)).unwrap();
        let mut s = crate::sampling::Sampler::for_batch(5, 0);
        let edges = (0..=64).map(|j| j as f64 / 64.0);
        for u in edges.chain((0..100_000).map(|_| s.uniform())).filter(|&u| u < 1.0) {
            let target = u * sampler.total();
            let binary = (sampler.cdf.partition_point(|&c| c <= target).max(1) - 1).min(sampler.xs.len() - 2);
            assert_eq!(sampler.segment(u, target), binary, "u = {u}");
        }
    }

    #[test]
    fn sellmeier_evaluates_schotts_n_bk7_and_is_checked_over_a_range() {
        // Schott N-BK7: n_d = 1.5168 at 587.56 nm.
        let terms = vec![(1.03961212, 0.00600069867), (0.231792344, 0.0200179144), (1.01046945, 103.560653)];
        let s = Spectrum::Sellmeier { terms: terms.clone() };
        assert!((s.eval(587.56) - 1.5168).abs() < 1e-5, "{}", s.eval(587.56));
        assert_eq!(s.constant_over((360.0, 830.0)), None);
        assert_eq!(s.breakpoints((400.0, 402.5)), vec![400.0, 401.0, 402.0, 402.5]);
        let (lo, hi) = s.min_max_over((400.0, 700.0));
        assert_eq!((lo, hi), (s.eval(700.0), s.eval(400.0)), "normal dispersion: n falls with λ");
        assert!(check_sellmeier(&terms, (360.0, 830.0)).is_ok());
        // The pole at √103.56 µm ≈ 10.18 µm, inside a (hypothetical) infrared range.
        assert!(check_sellmeier(&terms, (9000.0, 11000.0)).unwrap_err().contains("pole"));
        assert_eq!(sellmeier_pole_in(0.36, (360.0, 830.0)), Some(600.0));
        assert_eq!(sellmeier_pole_in(0.36, (610.0, 830.0)), None);
        assert_eq!(sellmeier_pole_in(0.0, (0.0, 830.0)), None, "C = 0 is a constant term, not a pole");
        assert!(check_sellmeier(&[(-3.0, 0.01)], (360.0, 830.0)).unwrap_err().contains("at 360 nm"));
        // Terms without dispersion (C = 0, or B = 0) are a constant index.
        let flat = Spectrum::Sellmeier { terms: vec![(1.25, 0.0), (0.0, 0.3)] };
        assert_eq!(flat.constant_over((360.0, 830.0)), Some(1.5));
        assert_eq!(flat.eval(500.0), 1.5);
    }

    #[test]
    fn planck_peak_follows_wien() {
        // Wien's displacement law: λ_max = b/T with b = 2.897771955e-3 m·K.
        let t = 5000.0;
        let peak = (300..1000)
            .map(|l| l as f64)
            .max_by(|a, b| planck_w_m2_sr_nm(*a, t).total_cmp(&planck_w_m2_sr_nm(*b, t)))
            .unwrap();
        assert!((peak - 2.897771955e6 / t).abs() <= 1.0);
    }
}
