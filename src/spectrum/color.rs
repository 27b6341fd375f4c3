//! Colour: the CIE 1931 2° colour-matching functions (1 nm table from `spectra/`, embedded at
//! build time) and the XYZ → linear sRGB (D65) matrix.

use std::sync::OnceLock;

use glam::Vec3;

use crate::spectrum::Spectrum;

const CIE_CSV: &str = include_str!("../../spectra/cie1931_2deg_xyz.csv");

/// x̄, ȳ, z̄ at 1 nm from `CIE_FIRST_NM` to 830 nm.
pub struct Cmf {
    first_nm: f64,
    rows: Vec<[f64; 3]>,
    /// The last row's index as u32: `at` then converts no index from usize.
    last: u32,
}

pub fn cmf() -> &'static Cmf {
    static TABLE: OnceLock<Cmf> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut rows = Vec::new();
        let mut first_nm = f64::NAN;
        for line in CIE_CSV.lines().skip(1).filter(|l| !l.trim().is_empty()) {
            let v: Vec<f64> = line.split(',').map(|s| s.trim().parse().expect("CIE table is numeric")).collect();
            if rows.is_empty() {
                first_nm = v[0];
            }
            assert_eq!(v[0], first_nm + rows.len() as f64, "CIE table must be on a 1 nm grid");
            rows.push([v[1], v[2], v[3]]);
        }
        assert!(rows.len() >= 2, "CIE table has rows");
        let last = rows.len() - 1;
        Cmf { first_nm, rows, last: last as u32 }
    })
}

impl Cmf {
    /// (x̄, ȳ, z̄)(λ), linear between the 1 nm rows, zero outside the table.
    #[inline]
    pub fn at(&self, lambda_nm: f64) -> [f64; 3] {
        let x = lambda_nm - self.first_nm;
        if !(x >= 0.0) || x > self.last as f64 {
            return [0.0; 3];
        }
        // SAFETY: 0 ≤ x ≤ last < 2^32.
        let i = unsafe { x.to_int_unchecked::<u32>() }.min(self.last - 1);
        let f = x - i as f64;
        // SAFETY: i + 1 ≤ last < rows.len().
        let (a, b) = unsafe { (*self.rows.get_unchecked(i as usize), *self.rows.get_unchecked(i as usize + 1)) };
        [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])]
    }

    /// ∫ s(λ)·(x̄, ȳ, z̄)(λ) dλ over `range`, trapezoid on the 1 nm grid merged with s's breakpoints.
    pub fn integrate(&self, s: &Spectrum, range: (f64, f64)) -> [f64; 3] {
        // Integrate over the spectrum's support only (see `Spectrum::breakpoints`).
        let mut xs = s.breakpoints(range);
        let (lo, hi) = (xs[0], xs[xs.len() - 1]);
        let mut x = lo.floor() + 1.0;
        while x < hi {
            xs.push(x);
            x += 1.0;
        }
        xs.sort_by(f64::total_cmp);
        xs.dedup();
        let mut acc = [0.0; 3];
        for w in xs.windows(2) {
            let (fa, fb) = (self.at(w[0]), self.at(w[1]));
            let (sa, sb) = (s.eval(w[0]), s.eval(w[1]));
            for c in 0..3 {
                acc[c] += 0.5 * (sa * fa[c] + sb * fb[c]) * (w[1] - w[0]);
            }
        }
        acc
    }

    /// ∫ȳ dλ over `range`: the normalisation that makes a flat spectral radiance c read as Y = c.
    pub fn y_integral(&self, range: (f64, f64)) -> f64 {
        self.integrate(&Spectrum::Constant(1.0), range)[1]
    }
}

/// XYZ → linear sRGB (IEC 61966-2-1, D65 white).
pub fn xyz_to_linear_srgb(xyz: Vec3) -> Vec3 {
    Vec3::new(
        3.240_454_2 * xyz.x - 1.537_138_5 * xyz.y - 0.498_531_4 * xyz.z,
        -0.969_266 * xyz.x + 1.876_010_8 * xyz.y + 0.041_556_0 * xyz.z,
        0.055_643_4 * xyz.x - 0.204_025_9 * xyz.y + 1.057_225_2 * xyz.z,
    )
}

/// Brings a linear sRGB colour with a negative component back into the gamut by mixing it with
/// the grey of the same luminance Y, just enough: c' = Y + t(c − Y), t = min over negative
/// components of Y/(Y − cᵢ). Y is kept exactly (sRGB's luminance row is CIE Y for D65 white), only
/// the chromaticity of out-of-gamut or noise-dominated pixels moves toward white.
pub fn desaturate_into_gamut(c: Vec3, y: f32) -> Vec3 {
    if c.min_element() >= 0.0 {
        return c;
    }
    if !(y > 0.0) {
        return Vec3::ZERO;
    }
    let grey = Vec3::splat(y);
    let t = [c.x, c.y, c.z].iter().filter(|&&ci| ci < 0.0).map(|&ci| y / (y - ci)).fold(1.0f32, f32::min);
    (grey + t * (c - grey)).max(Vec3::ZERO)
}

/// The sRGB transfer curve (linear → encoded), for the PNG preview.
pub fn srgb_encode(v: f32) -> f32 {
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cie_y_sums_and_peak_match_the_reference() {
        // shared/data/SOURCES.md: Σȳ over the 1 nm grid 360–830 = 106.856917; ȳ(555) = 1.
        let c = cmf();
        let sum: f64 = (360..=830).map(|l| c.at(l as f64)[1]).sum();
        assert!((sum - 106.856917).abs() < 1e-5, "{sum}");
        assert_eq!(c.at(555.0)[1], 1.0);
    }

    #[test]
    fn desaturation_keeps_luminance_and_clears_negatives() {
        // A saturated spectral blue-green, outside sRGB.
        let xyz = Vec3::new(0.05, 0.3, 0.4);
        let c = xyz_to_linear_srgb(xyz);
        assert!(c.min_element() < 0.0);
        let d = desaturate_into_gamut(c, xyz.y);
        assert!(d.min_element() >= 0.0 && d.min_element() < 1e-6);
        let lum = 0.2126 * d.x + 0.7152 * d.y + 0.0722 * d.z;
        assert!((lum - xyz.y).abs() < 1e-4, "{lum} vs {}", xyz.y);
        let inside = Vec3::new(0.2, 0.3, 0.1);
        assert_eq!(desaturate_into_gamut(inside, 0.25), inside);
    }

    #[test]
    fn d65_white_maps_to_equal_rgb() {
        // D65's chromaticity is sRGB's white point, so its linear RGB components are equal.
        let d65 = crate::spectrum::read_csv(std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/spectra/cie_d65.csv"
        )))
        .unwrap();
        let xyz = cmf().integrate(&d65, (360.0, 830.0));
        let rgb = xyz_to_linear_srgb(Vec3::new(xyz[0] as f32, xyz[1] as f32, xyz[2] as f32));
        assert!((rgb.x / rgb.y - 1.0).abs() < 2e-3 && (rgb.z / rgb.y - 1.0).abs() < 2e-3, "{rgb}");
    }
}
