//! Luminaire files: the far-field detector's `farfield_<name>.ies` (LM-63-2019) and `.ldt`
//! (EULUMDAT) read back as sources give the same distribution within noise; the IES file
//! follows LM-63-2019 field by field; EULUMDAT input in every symmetry expands to the full
//! table; malformed EULUMDAT files are refused naming the file and line.

use std::f64::consts::PI;
use std::path::Path;
use std::process::Command;
use std::sync::atomic::AtomicBool;

use photon::output::farfield::FarFieldEstimate;
use photon::output::luminaire::{ies_text, ldt_text, RunLabel};
use photon::run::{apply_options, simulate, RunOptions};
use photon::scene::load_str;

mod common;
use common::{chi_square_bounds, temp_dir};

/// A smooth luminaire with no symmetry in C (cd): I = 500·(1 + ½cos γ + ¼sin²γ·(cos C + sin C)),
/// positive everywhere, so a mirrored, rotated or shifted table would show in every band; it
/// varies slowly against 15° sectors, so re-sampling it at their centres biases little.
fn smooth_cd(gamma_deg: f64, c_deg: f64) -> f64 {
    let (g, c) = (gamma_deg.to_radians(), c_deg.to_radians());
    500.0 * (1.0 + 0.5 * g.cos() + 0.25 * g.sin().powi(2) * (c.cos() + c.sin()))
}

/// The smooth luminaire as an LM-63-2002 file, 5° in γ and 15° in C over the full circle.
fn smooth_ies() -> String {
    let gammas: Vec<f64> = (0..=36).map(|k| 5.0 * k as f64).collect();
    let cs: Vec<f64> = (0..=24).map(|k| 15.0 * k as f64).collect();
    let join = |v: &[f64]| v.iter().map(|x| format!("{x}")).collect::<Vec<_>>().join(" ");
    let mut s = format!(
        "IESNA:LM-63-2002\n[TEST] smooth\nTILT=NONE\n1 -1 1 37 25 1 2 0 0 0\n1 1 30\n{}\n{}\n",
        join(&gammas),
        join(&cs)
    );
    for &c in &cs {
        s.push_str(&join(&gammas.iter().map(|&g| smooth_cd(g, c)).collect::<Vec<_>>()));
        s.push('\n');
    }
    s
}

/// A point light with `distribution` (a TOML inline table) seen by a 36 × 24 far-field detector.
fn goniometer_scene(distribution: &str) -> String {
    format!(
        "[[lights]]\nname = \"lamp\"\nshape = {{ type = \"point\", position = [0, 0, 0] }}\ndirection = [0, 0, -1]\n\
         distribution = {distribution}\n\n[[detectors]]\ntype = \"farfield\"\nname = \"gonio\"\nresolution = [36, 24]\n\
         nadir = [0, 0, -1]\nc0 = [1, 0, 0]\n"
    )
}

/// Runs the scene text (its files resolved in `dir`) and returns the far field with the run's
/// luminaire files as text.
fn measure(dir: &Path, toml: &str, photons: u64, seed: u64) -> (FarFieldEstimate, String, String) {
    let path = dir.join("scene.toml");
    std::fs::write(&path, toml).unwrap();
    let mut s = load_str(&path, toml).unwrap_or_else(|e| panic!("{e}"));
    let opts = RunOptions { photons: Some(photons), seed: Some(seed), threads: Some(2), ..Default::default() };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap();
    let e = photon::output::farfield::estimates(&s, &r).remove(0);
    let label = RunLabel { scene: &s, photons, seed };
    let (ies, ldt) = (ies_text(&e, &label), ldt_text(&e, &label));
    (e, ies, ldt)
}

/// Σ z² over the bins of a measurement `again` of a table written from `original`, with the
/// bin count and the largest |z|. The written table carries the original's noise, which the
/// second run reproduces but for the smoothing of bilinear interpolation: a bin's re-measured
/// mean is 9/16 its own written value plus its neighbours' shares, which leaves 0.227 of the
/// original's variance in the difference (less at the poles). So z = (b − a)/√(σb² + σa²/4).
fn chi2_against_source(original: &FarFieldEstimate, again: &FarFieldEstimate) -> (f64, usize, f64) {
    let [ng, nc] = original.detector.resolution;
    let (mut chi2, mut k, mut worst) = (0.0, 0, 0.0f64);
    for j in 0..nc {
        for i in 0..ng {
            let ((_, (x, sx)), (_, (y, sy))) = (original.intensity(i, j), again.intensity(i, j));
            let z = (y - x) / (sy * sy + sx * sx / 4.0).sqrt();
            chi2 += z * z;
            k += 1;
            worst = worst.max(z.abs());
        }
    }
    (chi2, k, worst)
}

#[test]
fn ies_and_ldt_written_by_the_far_field_detector_read_back_as_the_same_luminaire() {
    let dir = temp_dir("luminaire-round-trip");
    std::fs::write(dir.join("smooth.ies"), smooth_ies()).unwrap();
    // The original is measured with 1.2·10⁷ photons (~14000 per bin, 0.85 %), the written files
    // with 3·10⁶ (1.7 %). The table re-sampled at bin centres is the bins' mean to second
    // order, Δ²I''/8: for this distribution ≤ 0.2 % per bin, a tenth of a bin's noise, so χ²
    // stays within its 10⁻⁴ bounds; half a sector's shift in C (a 7.5° error) or a mirrored C
    // would move the bins near the horizontal by ~4 % (z ≈ 2 each, χ² in the thousands).
    let photons = 3_000_000;
    let (original, ies, ldt) =
        measure(&dir, &goniometer_scene("{ ies = \"smooth.ies\", c0 = [1, 0, 0] }"), 4 * photons, 1);
    std::fs::write(dir.join("written.ies"), &ies).unwrap();
    std::fs::write(dir.join("written.ldt"), &ldt).unwrap();
    let (lo, hi) = chi_square_bounds(864.0);
    for (file, key) in [("written.ies", "ies"), ("written.ldt", "ldt")] {
        let again =
            measure(&dir, &goniometer_scene(&format!("{{ {key} = \"{file}\", c0 = [1, 0, 0] }}")), photons, 2).0;
        let (chi2, k, worst) = chi2_against_source(&original, &again);
        assert_eq!(k, 864);
        eprintln!("{file}: χ² = {chi2:.1} over {k} bins, worst |z| {worst:.2}");
        assert!(chi2 > lo && chi2 < hi, "{file}: χ² = {chi2:.1} over {k} bins, bounds ({lo:.1}, {hi:.1})");
        assert!(worst < 5.0, "{file}: a bin at |z| = {worst:.2}");
        // The same total flux: the source's power is its table's lumens.
        let total = |e: &FarFieldEstimate| e.flux_lm.iter().map(|f| f.0).sum::<f64>();
        let rel = total(&again) / total(&original) - 1.0;
        assert!(rel.abs() < 3e-3, "{file}: total flux differs by {rel:e}");
    }
}

#[test]
fn the_written_ies_file_follows_lm63_2019_field_by_field() {
    let dir = temp_dir("luminaire-lm63");
    std::fs::write(dir.join("smooth.ies"), smooth_ies()).unwrap();
    let (e, ies, _) = measure(&dir, &goniometer_scene("{ ies = \"smooth.ies\" }"), 200_000, 1);
    // Lines end in CR LF and stay within LM-63-2019's 256 characters.
    assert!(ies.ends_with("\r\n") && !ies.replace("\r\n", "").contains('\n'), "CR LF line ends");
    let lines: Vec<&str> = ies.split("\r\n").filter(|l| !l.is_empty()).collect();
    assert!(lines.iter().all(|l| l.len() <= 256 && l.is_ascii()));
    // §5.1: the first line names the format; §5.2: keywords in brackets until TILT, the four
    // required ones ([TEST], [TESTLAB], [ISSUEDATE], [MANUFAC]) among them.
    assert_eq!(lines[0], "IES:LM-63-2019");
    let tilt = lines.iter().position(|l| l.starts_with("TILT=")).expect("a TILT line");
    assert_eq!(lines[tilt], "TILT=NONE");
    let keywords: Vec<&str> = lines[1..tilt].iter().map(|l| l.split(']').next().unwrap()).collect();
    assert!(lines[1..tilt].iter().all(|l| l.starts_with('[') && l.contains(']')));
    for required in ["[TEST", "[TESTLAB", "[ISSUEDATE", "[MANUFAC"] {
        assert!(keywords.contains(&required), "{required}] missing");
    }
    let date = lines.iter().find_map(|l| l.strip_prefix("[ISSUEDATE] ")).unwrap();
    assert!(date.len() == 10 && date.as_bytes()[4] == b'-' && date.as_bytes()[7] == b'-', "{date}");
    // §5.4–5.7: ten numbers, then three, then the angles and the candela values.
    let numbers: Vec<f64> =
        lines[tilt + 1..].iter().flat_map(|l| l.split_whitespace()).map(|w| w.parse::<f64>().unwrap()).collect();
    let [ng, nc] = e.detector.resolution;
    let (nv, nh) = (ng + 2, nc + 1);
    // Lamps 1, lumens per lamp −1 (absolute photometry), multiplier 1, angle counts,
    // photometric type 1 (C), units 2 (metres), a point luminaire (0 × 0 × 0).
    assert_eq!(numbers[..10], [1.0, -1.0, 1.0, nv as f64, nh as f64, 1.0, 2.0, 0.0, 0.0, 0.0]);
    // Ballast factor 1, file generation type 1.00010 (computer simulation), input watts from
    // the source file (30 W).
    assert_eq!(numbers[10..13], [1.0, 1.0001, 30.0]);
    let gamma = &numbers[13..13 + nv];
    let c = &numbers[13 + nv..13 + nv + nh];
    let cd = &numbers[13 + nv + nh..];
    assert_eq!((gamma[0], gamma[nv - 1], c[0], c[nh - 1]), (0.0, 180.0, 0.0, 360.0));
    assert!(gamma.windows(2).all(|w| w[1] > w[0]) && c.windows(2).all(|w| w[1] > w[0]));
    assert_eq!(cd.len(), nv * nh);
    // Each horizontal angle's values start on a line of their own.
    let table_lines = &lines[tilt + 3..];
    let starts: usize = table_lines.iter().filter(|l| l.split_whitespace().count() > 0).count();
    assert!(starts >= nh + 2);
    // The values are the detector's bins (six significant digits), C0 repeated at 360°.
    for j in 0..nc {
        for i in 0..ng {
            let want = e.intensity(i, j).1 .0;
            let got = cd[j * nv + 1 + i];
            assert!((got - want).abs() <= 1e-5 * want.abs(), "bin ({i}, {j}): {got} vs {want}");
        }
    }
    assert_eq!(cd[..nv], cd[nc * nv..]);
    // And photon reads it back.
    let profile = photon::scene::ies::IesProfile::parse(Path::new("written.ies"), &ies).expect("photon reads it");
    assert!(profile.rated_lm.is_none() && profile.input_w == Some(30.0));
}

/// An EULUMDAT file of `smooth`-like data with symmetry `isym`, 24 C planes of 15° and 19 γ
/// angles of 5° (0–90°), lamps of 2000 lm and a conversion factor of 1.5.
fn ldt_file(isym: usize, intensity: impl Fn(f64, f64) -> f64) -> String {
    let (mc, ng) = (24usize, 19usize);
    let cs: Vec<f64> = (0..mc).map(|k| 15.0 * k as f64).collect();
    let gs: Vec<f64> = (0..ng).map(|k| 5.0 * k as f64).collect();
    let stored: Vec<f64> = match isym {
        0 => cs.clone(),
        1 => vec![0.0],
        2 => cs[..=12].to_vec(),
        3 => cs[6..=18].to_vec(),
        _ => cs[..=6].to_vec(),
    };
    let mut l: Vec<String> = vec!["test".into(), "3".into(), isym.to_string(), mc.to_string(), "15".into()];
    l.extend([ng.to_string(), "5".into(), "r".into(), "n".into(), "1".into(), "f.ldt".into(), "d".into()]);
    l.extend(["600", "150", "80", "580", "140", "0", "0", "0", "0", "100", "85", "1,5", "0"].map(String::from));
    l.extend(["1", "2", "T5", "2000", "840", "1B", "30"].map(String::from));
    l.extend((0..10).map(|_| "0.5".to_string()));
    l.extend(cs.iter().map(|c| c.to_string()));
    l.extend(gs.iter().map(|g| g.to_string()));
    for &c in &stored {
        l.extend(gs.iter().map(|&g| format!("{}", intensity(g, c))));
    }
    l.join("\r\n") + "\r\n"
}

#[test]
fn eulumdat_symmetries_expand_to_the_full_table() {
    // Each symmetry's distribution, written once in reduced form and once in full (Isym 0):
    // both read to the same intensities everywhere (cd/klm × 2000 lm/1000 × 1.5).
    let fold = |c: f64, isym: usize| -> f64 {
        let c = c.rem_euclid(360.0);
        match isym {
            1 => 0.0,
            2 => c.min(360.0 - c),
            // Mirror about the C90–C270 plane: C ↦ 180 − C.
            3 => (180.0 - c).rem_euclid(360.0).min(c),
            4 => {
                let h = c.min(360.0 - c);
                h.min(180.0 - h)
            }
            _ => c,
        }
    };
    for isym in 1..=4 {
        let f = move |g: f64, c: f64| {
            let c = fold(c, isym);
            // Any function of the folded angle has the symmetry; cos of it keeps it smooth.
            100.0 + 50.0 * (g.to_radians()).cos() + 20.0 * (c.to_radians() * 1.3).cos() + g * c / 2000.0
        };
        let reduced = photon::scene::ldt::parse(Path::new("r.ldt"), &ldt_file(isym, f)).unwrap();
        let full = photon::scene::ldt::parse(Path::new("f.ldt"), &ldt_file(0, f)).unwrap();
        for g in (0..=18).map(|k| 5.0 * k as f64) {
            for c in (0..24).map(|k| 15.0 * k as f64) {
                let (a, b) = (reduced.intensity_cd(g, c), full.intensity_cd(g, c));
                assert!((a - b).abs() < 1e-9 * b, "Isym {isym}: γ {g}, C {c}: {a} vs {b}");
                assert!((b - f(g, c) * 3.0).abs() < 1e-9 * b, "Isym {isym}: γ {g}, C {c}: {b} cd");
            }
        }
        assert!((reduced.total_lm - full.total_lm).abs() < 1e-9 * full.total_lm);
        assert_eq!((reduced.rated_lm, reduced.input_w), (Some(2000.0), Some(30.0)));
    }
    // A rotationally symmetric table's flux in closed form: I = 300 + 150 cos γ over 0–90°
    // (linear in cos between 5° steps is not exact, so 0.1 %): Φ = 2π(300 + 75) = 750π lm.
    let p = photon::scene::ldt::parse(Path::new("s.ldt"), &ldt_file(1, |g, _| 100.0 + 50.0 * g.to_radians().cos()))
        .unwrap();
    assert!((p.total_lm / (750.0 * PI) - 1.0).abs() < 1e-3, "{}", p.total_lm);
}

#[test]
fn malformed_eulumdat_files_exit_2_naming_the_file_and_line() {
    let good = ldt_file(2, |g, _| 100.0 + g);
    let lines: Vec<&str> = good.split("\r\n").collect();
    // Line numbers are 1-based (the layout of `ldt_file`: lamp set on 27–32, direct ratios on
    // 33–42, C angles on 43–66, γ angles on 67–85, intensities from 86); each case changes
    // lines or cuts the file.
    let set_all = |changes: &[(usize, &str)]| -> String {
        let mut l: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
        for &(n, to) in changes {
            l[n - 1] = to.into();
        }
        l.join("\r\n")
    };
    let set = |n: usize, to: &str| set_all(&[(n, to)]);
    let cases: Vec<(String, String)> = vec![
        (set(2, "7"), "2: the type indicator Ityp must be a whole number from 0 to 3".into()),
        (set(3, "5"), "3: the symmetry indicator Isym must be a whole number from 0 to 4".into()),
        (set(4, "0"), "4: the number of C planes Mc must be a whole number".into()),
        (set(6, "x"), "6: `x` is not a number (the number of intensities per C plane Ng)".into()),
        (set(24, "-2"), "24: the conversion factor for the intensities must be positive".into()),
        (set(26, "0"), "26: the number of lamp sets must be a whole number from 1".into()),
        (set(29, "0"), "29: the lamps' total luminous flux must be positive".into()),
        (set(29, "abc"), "29: `abc` is not a number (the lamps' total luminous flux (lm))".into()),
        (set(44, "0"), "44: C angles must increase, found 0 after 0".into()),
        (set(43, "5"), "43: the C angles must begin at 0".into()),
        (set(66, "361"), "66: C angles must lie within 0 to 360 degrees, found 361".into()),
        (set(85, "181"), "85: γ angles must lie within 0 to 180 degrees, found 181".into()),
        (set(86, "-1"), "86: intensities must be >= 0".into()),
        (set(86, "inf"), "86: an intensity (cd/klm) must be finite".into()),
        (set_all(&[(3, "3"), (49, "91")]), "43: Isym 3 stores 13 planes from C90 to C270".into()),
        // Isym 4 stores 7 planes: the 13 of the C0–C180 half leave values over.
        (set(3, "4"), "219: unexpected `100` after the intensity table".into()),
        (lines[..100].join("\r\n"), "the file ends where an intensity (cd/klm) should be".into()),
        (format!("{good}12\r\n"), "unexpected `12` after the intensity table".into()),
        (lines[..20].join("\r\n"), "the file ends where the luminous area's height at C270 (mm) should be".into()),
    ];
    assert!(cases.len() >= 10);
    let bin = env!("CARGO_BIN_EXE_photon");
    for (k, (text, message)) in cases.iter().enumerate() {
        let dir = temp_dir(&format!("ldt-bad-{k}"));
        std::fs::write(dir.join("lamp.ldt"), text).unwrap();
        std::fs::write(dir.join("scene.toml"), goniometer_scene("{ ldt = \"lamp.ldt\" }")).unwrap();
        let out = Command::new(bin)
            .args(["run", "scene.toml", "--photons", "1000", "--quiet", "--out", "out"])
            .current_dir(&dir)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "case {k}: {stderr}");
        assert!(stderr.contains("lamp.ldt:"), "case {k} names no file: {stderr}");
        assert!(stderr.contains(message.as_str()), "case {k}: expected `{message}` in {stderr}");
        assert!(stderr.contains("lights[0].distribution.ldt"), "case {k} names no key: {stderr}");
        assert!(!dir.join("out").exists(), "case {k} left output");
    }
}
