//! Photometric units. Luminous flux Φ_v = K_m ∫ Φ_e(λ) ȳ(λ) dλ with K_m = 683 lm/W, the maximum
//! luminous efficacy of photopic vision (CIE 015:2018 §3; the SI defines the candela by 683 lm/W
//! at 540 THz, λ ≈ 555 nm, where the CIE 1931 ȳ = V(λ) is 1). ȳ is the 1931 2° table in `color`.

use crate::spectrum::color::cmf;
use crate::spectrum::Spectrum;

/// K_m, lm/W.
pub const KM_LM_PER_W: f64 = 683.0;

/// Luminous efficacy K_m ȳ(λ) of monochromatic radiation at `lambda_nm`, lm/W.
#[inline]
pub fn efficacy_at(lambda_nm: f64) -> f64 {
    KM_LM_PER_W * cmf().at(lambda_nm)[1]
}

/// Luminous efficacy of radiation with spectral shape `s` over `range`:
/// K_m ∫ s ȳ dλ / ∫ s dλ, lm/W. Zero when `s` has no power there.
pub fn efficacy_of(s: &Spectrum, range: (f64, f64)) -> f64 {
    let power = s.integral(range);
    if power > 0.0 {
        KM_LM_PER_W * cmf().integrate(s, range)[1] / power
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn efficacy_peaks_at_555_nm_and_flat_white_is_about_a_quarter_of_it() {
        assert!((efficacy_at(555.0) - 683.0).abs() < 0.1);
        // Equal-energy white over 380–780 nm: 683 · ∫ȳ / 400 nm, with ∫ȳ = 106.86 nm (CIE 1931).
        let k = efficacy_of(&Spectrum::Constant(1.0), (380.0, 780.0));
        assert!((k - 683.0 * 106.86 / 400.0).abs() < 0.5, "{k}");
    }
}
