//! Bundled optical constants, compiled into the binary so a scene names them anywhere: the
//! measured n, k of metals (`spectra/metal_*_nk.csv`, provenance in `spectra/SOURCES.md`).

use crate::spectrum::{Spectrum, Table};

/// The metals `conductor` knows by name, with their tables (wavelength_nm, n, k).
pub const METALS: &[(&str, &str)] = &[
    ("Ag", include_str!("../../spectra/metal_Ag_nk.csv")),
    ("Al", include_str!("../../spectra/metal_Al_nk.csv")),
    ("Au", include_str!("../../spectra/metal_Au_nk.csv")),
    ("Cu", include_str!("../../spectra/metal_Cu_nk.csv")),
    ("CuZn", include_str!("../../spectra/metal_CuZn_nk.csv")),
];

/// The named metal's (n, k) as piecewise-linear spectra, and the wavelengths they cover (nm).
pub fn metal(name: &str) -> Option<(Spectrum, Spectrum, (f64, f64))> {
    let (_, csv) = METALS.iter().find(|(n, _)| *n == name)?;
    let rows: Vec<[f64; 3]> = csv
        .lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().expect("bundled table is numeric")).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    let n = Table::new(rows.iter().map(|r| (r[0], r[1])).collect());
    let k = Table::new(rows.iter().map(|r| (r[0], r[2])).collect());
    let cover = (rows[0][0], rows[rows.len() - 1][0]);
    Some((Spectrum::Table(n), Spectrum::Table(k), cover))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bundled_metal_parses_and_reflects_like_a_metal_at_normal_incidence() {
        // R(0) = ((n − 1)² + k²)/((n + 1)² + k²) at 550 nm; shared/data/materials/SOURCES.md
        // quotes Al ≈ 0.91, Ag ≈ 0.96–0.98, Au ≈ 0.7–0.8.
        let r0 = |name: &str| {
            let (n, k, _) = metal(name).unwrap();
            let (n, k) = (n.eval(550.0), k.eval(550.0));
            ((n - 1.0f64).powi(2) + k * k) / ((n + 1.0f64).powi(2) + k * k)
        };
        assert!((r0("Al") - 0.915).abs() < 0.01, "Al {}", r0("Al"));
        assert!((0.95..0.99).contains(&r0("Ag")), "Ag {}", r0("Ag"));
        assert!((0.65..0.85).contains(&r0("Au")), "Au {}", r0("Au"));
        for (name, _) in METALS {
            let (_, _, cover) = metal(name).unwrap();
            assert!(cover.0 <= 300.0 && cover.1 >= 885.0, "{name} {cover:?}");
        }
    }
}
