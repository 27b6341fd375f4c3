//! Bundled optical constants, compiled into the binary so a scene names them anywhere: the
//! measured n, k of metals (`spectra/metal_*_nk.csv`) and the refractive indices of glasses
//! (`spectra/glass_*_n.csv`, and published dispersion formulas); provenance in
//! `spectra/SOURCES.md`.

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

/// How a bundled glass's index is given.
pub enum GlassData {
    /// A table (wavelength_nm, n), linear between rows.
    Table(&'static str),
    /// Sellmeier terms (Bᵢ, Cᵢ in µm²) and the wavelengths (nm) the formula was fitted over.
    Sellmeier(&'static [(f64, f64)], (f64, f64)),
}

/// The glasses `dielectric`'s `ior` and `outside_ior` know by name.
///
/// The seven Schott tables are pbrt-v4's (from refractiveindex.info, via
/// `shared/data/materials/`). Each table's first row matches Schott's Sellmeier fit (catalog
/// 2017-01-20) to 1e-6 and its last to 2e-5; for "SF5", "SF10" and "SF11" the fits they match
/// are those of the lead-free N-SF5, N-SF10 and N-SF11, whose n_d differ from the lead SF5, SF10,
/// SF11 by at most 3e-5. Between rows (~21 nm apart) the tables depart from the fits by up to
/// 4.3e-4 (N-BK7: 5e-7).
///
/// The other four are published dispersion formulas, n² = 1 + Σ Bᵢλ²/(λ² − Cᵢ), λ in µm:
pub const GLASSES: &[(&str, GlassData)] = &[
    ("BK7", GlassData::Table(include_str!("../../spectra/glass_BK7_n.csv"))),
    ("BAF10", GlassData::Table(include_str!("../../spectra/glass_BAF10_n.csv"))),
    ("FK51A", GlassData::Table(include_str!("../../spectra/glass_FK51A_n.csv"))),
    ("LASF9", GlassData::Table(include_str!("../../spectra/glass_LASF9_n.csv"))),
    ("SF5", GlassData::Table(include_str!("../../spectra/glass_SF5_n.csv"))),
    ("SF10", GlassData::Table(include_str!("../../spectra/glass_SF10_n.csv"))),
    ("SF11", GlassData::Table(include_str!("../../spectra/glass_SF11_n.csv"))),
    // Fused silica at 20 °C: I. H. Malitson, "Interspecimen comparison of the refractive index of
    // fused silica", J. Opt. Soc. Am. 55, 1205–1208 (1965), doi:10.1364/JOSA.55.001205: B =
    // 0.6961663, 0.4079426, 0.8974794; √C = 0.0684043, 0.1162414, 9.896161 µm. Fitted over
    // 0.21–3.71 µm (its measurements 0.2139–3.7067 µm). n_d = 1.45846.
    (
        "fused_silica",
        GlassData::Sellmeier(
            &[(0.6961663, 0.0684043 * 0.0684043), (0.4079426, 0.1162414 * 0.1162414), (0.8974794, 9.896161 * 9.896161)],
            (210.0, 3710.0),
        ),
    ),
    // Poly(methyl methacrylate) at 20 °C: N. Sultanova, S. Kasarova, I. Nikolov, "Dispersion
    // properties of optical polymers", Acta Physica Polonica A 116, 585–587 (2009),
    // doi:10.12693/APhysPolA.116.585; their refractometer measurements at 436.8–1052 nm as fitted
    // by M. Polyanskiy (refractiveindex.info, organic/PMMA/Sultanova): n² − 1 = 1.1819λ²/(λ² −
    // 0.011313). n_d = 1.4906 (the paper measures 1.491).
    ("PMMA", GlassData::Sellmeier(&[(1.1819, 0.011313)], (436.8, 1052.0))),
    // Polycarbonate at 20 °C: the same paper and fit (refractiveindex.info,
    // organic/polycarbonate/Sultanova): n² − 1 = 1.4182λ²/(λ² − 0.021304), 436.8–1052 nm.
    // n_d = 1.5848 (the paper measures 1.585).
    ("polycarbonate", GlassData::Sellmeier(&[(1.4182, 0.021304)], (436.8, 1052.0))),
    // Distilled water at 20.0 °C: M. Daimon and A. Masumura, "Measurement of the refractive index
    // of distilled water from the near-infrared region to the ultraviolet region", Appl. Opt. 46,
    // 3811–3820 (2007), doi:10.1364/AO.46.003811, their four-term Sellmeier fit for 20.0 °C,
    // 182–1129 nm. n_d = 1.3334.
    (
        "water",
        GlassData::Sellmeier(
            &[
                (5.684027565e-1, 5.101829712e-3),
                (1.726177391e-1, 1.821153936e-2),
                (2.086189578e-2, 2.620722293e-2),
                (1.130748688e-1, 1.069792721e1),
            ],
            (182.0, 1129.0),
        ),
    ),
];

/// The named glass's refractive index, and the wavelengths (nm) it covers: a table's span, or the
/// range a formula was fitted over.
pub fn glass(name: &str) -> Option<(Spectrum, (f64, f64))> {
    let (_, data) = GLASSES.iter().find(|(n, _)| *n == name)?;
    Some(match data {
        GlassData::Table(csv) => {
            let rows: Vec<(f64, f64)> = csv
                .lines()
                .skip(1)
                .filter(|l| !l.trim().is_empty())
                .map(|l| {
                    let v: Vec<f64> =
                        l.split(',').map(|x| x.trim().parse().expect("bundled table is numeric")).collect();
                    (v[0], v[1])
                })
                .collect();
            let cover = (rows[0].0, rows[rows.len() - 1].0);
            (Spectrum::Table(Table::new(rows)), cover)
        }
        GlassData::Sellmeier(terms, cover) => (Spectrum::Sellmeier { terms: terms.to_vec() }, *cover),
    })
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

    #[test]
    fn every_bundled_glass_parses_and_covers_the_visible_middle() {
        for (name, _) in GLASSES {
            let (n, cover) = glass(name).unwrap();
            assert!(cover.0 <= 440.0 && cover.1 >= 900.0, "{name} {cover:?}");
            let n = n.eval(550.0);
            assert!((1.3..1.9).contains(&n), "{name}: n(550 nm) = {n}");
        }
        assert!(glass("bk7").is_none(), "names are case-sensitive, as the metals' are");
    }
}
