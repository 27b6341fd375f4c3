//! Bad input is rejected properly: every malformed scene, mesh, spectrum file or command line
//! makes `photon` exit with status 2, with a message of the form `FILE:LINE: `KEY`: message`
//! naming the file, the key path and the line, and without creating the output folder.
//!
//! Each case starts from one small valid scene and changes one thing in it, so that every
//! failure has exactly one cause.

use std::fs;
use std::path::Path;
use std::process::{Command, Output};

mod common;
use common::BASE;

/// A second surface, appended to `BASE` where a case needs one.
const SECOND_SURFACE: &str = r#"
[[surfaces]]
name = "wall"
material = "white"
shape = { type = "quad", corners = [[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]] }
"#;

const RUN: &[&str] = &["run", "{scene}", "--out", "{out}", "--photons", "1000", "--quiet"];
const INFO: &[&str] = &["info", "{scene}"];

/// `text` with `from` (which must occur exactly once) replaced by `to`.
fn edit(text: &str, from: &str, to: &str) -> String {
    assert_eq!(text.matches(from).count(), 1, "`{from}` must occur exactly once in the scene being edited");
    text.replacen(from, to, 1)
}

/// 1-based number of the `n`th (1-based) line of `text` that contains `needle`.
fn line_of_nth(text: &str, needle: &str, n: usize) -> usize {
    text.lines()
        .enumerate()
        .filter(|(_, l)| l.contains(needle))
        .nth(n - 1)
        .map(|(i, _)| i + 1)
        .unwrap_or_else(|| panic!("no line number {n} containing `{needle}`"))
}

/// 1-based number of the only line of `text` that contains `needle`.
fn line_of(text: &str, needle: &str) -> usize {
    assert_eq!(text.lines().filter(|l| l.contains(needle)).count(), 1, "`{needle}` must be on exactly one line");
    line_of_nth(text, needle, 1)
}

/// The start of the message for a problem at `line` of the scene file, under key path `key`.
fn at(line: usize, key: &str) -> String {
    format!("error: {{scene}}:{line}: `{key}`: ")
}

/// A fresh, empty folder for one case (removed when the test passes).
fn case_dir(name: &str) -> common::TempDir {
    common::temp_dir(&format!("bad-input-{name}"))
}

/// Writes `scene.toml` (unless `toml` is None) and `extra_files` into a fresh folder and runs
/// `photon` with `args`, where `{scene}`, `{out}` and `{dir}` stand for the scene file, the output
/// folder and the case's folder.
fn photon(name: &str, toml: Option<&str>, extra_files: &[(&str, &str)], args: &[&str]) -> (common::TempDir, Output) {
    let dir = case_dir(name);
    let scene = dir.join("scene.toml");
    if let Some(text) = toml {
        fs::write(&scene, text).unwrap();
    }
    for (rel, text) in extra_files {
        let path = dir.join(rel);
        fs::create_dir_all(path.parent().unwrap()).unwrap();
        fs::write(path, text).unwrap();
    }
    let args: Vec<String> = args.iter().map(|a| expand(a, &dir)).collect();
    let output =
        Command::new(env!("CARGO_BIN_EXE_photon")).args(&args).current_dir(&dir).output().expect("cannot start photon");
    (dir, output)
}

fn expand(s: &str, dir: &Path) -> String {
    s.replace("{scene}", &dir.join("scene.toml").display().to_string())
        .replace("{out}", &dir.join("out").display().to_string())
        .replace("{dir}", &dir.display().to_string())
}

/// Runs `photon ARGS` on the scene and checks that it is rejected as bad input: exit status 2,
/// every string of `must_contain` (placeholders expanded) in stderr, no panic, nothing on
/// stdout and no output folder.
fn expect_exit2(name: &str, toml: Option<&str>, extra_files: &[(&str, &str)], args: &[&str], must_contain: &[&str]) {
    let (dir, out) = photon(name, toml, extra_files, args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let context = format!("case `{name}`\n--- stderr ---\n{stderr}--- stdout ---\n{stdout}");
    assert_eq!(out.status.code(), Some(2), "wrong exit status; {context}");
    assert!(!stderr.contains("panicked"), "photon panicked; {context}");
    assert!(stdout.is_empty(), "nothing belongs on stdout; {context}");
    for s in must_contain {
        let s = expand(s, &dir);
        assert!(stderr.contains(&s), "stderr lacks `{s}`; {context}");
    }
    assert!(!dir.join("out").exists(), "the output folder was created for bad input; {context}");
    fs::remove_dir_all(&dir).unwrap();
}

/// `photon run` on a bad scene (or with bad files beside it).
fn expect_bad(name: &str, toml: &str, extra_files: &[(&str, &str)], must_contain: &[&str]) {
    expect_exit2(name, Some(toml), extra_files, RUN, must_contain);
}

/// `photon info` on a bad scene.
fn expect_bad_info(name: &str, toml: &str, extra_files: &[(&str, &str)], must_contain: &[&str]) {
    expect_exit2(name, Some(toml), extra_files, INFO, must_contain);
}

/// `photon run SCENE --out OUT` on the valid base scene with the arguments `extra_args`.
fn expect_bad_args(name: &str, extra_args: &[&str], must_contain: &[&str]) {
    let args: Vec<&str> = ["run", "{scene}", "--out", "{out}", "--quiet"].iter().chain(extra_args).copied().collect();
    expect_exit2(name, Some(BASE), &[], &args, must_contain);
}

// ---------------------------------------------------------------- the base scenes are valid

#[test]
fn base_scene_is_valid() {
    for (name, toml) in [("base-valid", BASE.to_string()), ("base2-valid", format!("{BASE}{SECOND_SURFACE}"))] {
        let (dir, out) = photon(name, Some(&toml), &[], RUN);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{name}: {stderr}");
        assert!(dir.join("out").join("flux.json").exists(), "{name}");
        let (dir2, out) = photon(&format!("{name}-info"), Some(&toml), &[], INFO);
        assert_eq!(out.status.code(), Some(0), "{name}: info");
        fs::remove_dir_all(dir).unwrap();
        fs::remove_dir_all(dir2).unwrap();
    }
}

// ---------------------------------------------------------------- the file as a whole

#[test]
fn empty_file() {
    expect_bad("empty", "", &[], &["error: {scene}: the scene file is empty"]);
}

#[test]
fn blank_file() {
    expect_bad("blank", "\n   \n\n", &[], &["error: {scene}: the scene file is empty"]);
}

#[test]
fn missing_scene_file() {
    expect_exit2("missing-scene", None, &[], RUN, &["error: {scene}: cannot read the scene file"]);
}

#[test]
fn toml_syntax_error() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = = 0.5");
    let line = line_of(&toml, "reflectance");
    expect_bad("syntax", &toml, &[], &[&format!("error: {{scene}}:{line}: TOML syntax error")]);
}

#[test]
fn no_light() {
    let toml = BASE.split("[[lights]]").next().unwrap();
    expect_bad("no-light", toml, &[], &["error: {scene}: `lights`: the scene has no light"]);
}

// ---------------------------------------------------------------- keys and types

#[test]
fn unknown_top_level_key() {
    let toml = format!("colour = \"red\"\n{BASE}");
    expect_bad(
        "unknown-root-key",
        &toml,
        &[],
        &[
            &at(1, "colour"),
            "unknown key `colour`; allowed keys here: simulation, camera, scene, materials, media, surfaces, lights",
        ],
    );
}

#[test]
fn unknown_material_key() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectivity = 0.5");
    let line = line_of(&toml, "reflectivity");
    expect_bad(
        "unknown-material-key",
        &toml,
        &[],
        &[
            &at(line, "materials.white.reflectivity"),
            "unknown key `reflectivity`; allowed keys here: type, reflectance, transmittance",
        ],
    );
}

#[test]
fn missing_surface_shape() {
    let shape_line = BASE.lines().find(|l| l.starts_with("shape") && l.contains("[0, 0, 0]")).unwrap();
    let toml = edit(BASE, &format!("{shape_line}\n"), "");
    // A missing key is reported at its table: here the `[[surfaces]]` header.
    let line = line_of(&toml, "[[surfaces]]");
    expect_bad("missing-shape", &toml, &[], &[&at(line, "surfaces[0].shape"), "missing required key `shape`"]);
}

#[test]
fn missing_material_type() {
    let toml = edit(BASE, "type = \"lambertian\"\n", "");
    expect_bad(
        "missing-type",
        &toml,
        &[],
        &[&at(line_of(&toml, "[materials.white]"), "materials.white.type"), "missing required key `type`"],
    );
}

#[test]
fn string_where_a_number_is_expected() {
    let toml = edit(BASE, "power_w = 10", "power_w = \"ten\"");
    expect_bad(
        "wrong-type",
        &toml,
        &[],
        &[&at(line_of(&toml, "power_w"), "lights[0].power_w"), "expected a number, found a string"],
    );
}

#[test]
fn number_where_a_point_is_expected() {
    let toml = edit(BASE, "[1, 0, 1], [1, 0, 0]", "[1, 0, 1], 5");
    expect_bad(
        "wrong-type-point",
        &toml,
        &[],
        &[&at(line_of(&toml, "[1, 0, 1], 5"), "surfaces[0].shape.corners[3]"), "expected an array, found an integer"],
    );
}

#[test]
fn unknown_material_type() {
    let toml = edit(BASE, "\"lambertian\"", "\"lambertain\"");
    expect_bad(
        "unknown-material-type",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "lambertain"), "materials.white.type"),
            "unknown material type \"lambertain\"; known types: absorber, lambertian, mirror, conductor, plastic, dielectric",
        ],
    );
}

#[test]
fn unknown_shape_type() {
    let toml = edit(BASE, "{ type = \"quad\", corners = [[0, 0, 0]", "{ type = \"triangle\", corners = [[0, 0, 0]");
    expect_bad(
        "unknown-shape-type",
        &toml,
        &[],
        &[&at(line_of(&toml, "triangle"), "surfaces[0].shape.type"), "unknown shape type \"triangle\""],
    );
}

#[test]
fn point_shape_on_a_surface() {
    let shape_line = BASE.lines().find(|l| l.starts_with("shape") && l.contains("[0, 0, 0]")).unwrap();
    let toml = edit(BASE, shape_line, "shape = { type = \"point\", position = [0, 0, 0] }");
    expect_bad(
        "point-surface",
        &toml,
        &[],
        &[&at(line_of(&toml, "\"point\""), "surfaces[0].shape.type"), "`point` is for lights only"],
    );
}

#[test]
fn unknown_distribution() {
    let toml = edit(BASE, "power_w = 10", "power_w = 10\ndistribution = \"spot\"");
    expect_bad(
        "unknown-distribution",
        &toml,
        &[],
        &[&at(line_of(&toml, "distribution"), "lights[0].distribution"), "unknown distribution \"spot\""],
    );
}

#[test]
fn surface_names_a_missing_material() {
    let toml = edit(BASE, "material = \"white\"", "material = \"whte\"");
    expect_bad(
        "missing-material",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "whte"), "surfaces[0].material"),
            "no material named \"whte\"; defined materials: absorber, white",
        ],
    );
}

#[test]
fn duplicate_surface_names() {
    let toml = format!("{BASE}{}", edit(SECOND_SURFACE, "name = \"wall\"", "name = \"floor\""));
    expect_bad(
        "duplicate-surface",
        &toml,
        &[],
        &[
            &at(line_of_nth(&toml, "name = \"floor\"", 2), "surfaces[1]"),
            "duplicate name \"floor\": `surfaces[0]` already uses it",
        ],
    );
}

#[test]
fn light_shares_a_surface_name() {
    let toml = edit(BASE, "name = \"lamp\"", "name = \"floor\"");
    expect_bad(
        "duplicate-light",
        &toml,
        &[],
        &[
            &at(line_of_nth(&toml, "name = \"floor\"", 2), "lights[0]"),
            "duplicate name \"floor\": `surfaces[0]` already uses it",
        ],
    );
}

// ---------------------------------------------------------------- values that cannot be physical

#[test]
fn reflectance_below_zero() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = -0.1");
    expect_bad(
        "reflectance-negative",
        &toml,
        &[],
        &[&at(line_of(&toml, "reflectance"), "materials.white.reflectance"), "must not be negative, found -0.1"],
    );
}

#[test]
fn reflectance_above_one() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = 1.2");
    expect_bad(
        "reflectance-above-one",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "reflectance"), "materials.white.reflectance"),
            "reflectance must lie in [0, 1] at every wavelength",
        ],
    );
}

#[test]
fn reflectance_table_above_one() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = { table = [[400, 0.5], [700, 1.5]] }");
    expect_bad(
        "reflectance-table-above-one",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "reflectance"), "materials.white.reflectance"),
            "reflectance must lie in [0, 1] at every wavelength",
        ],
    );
}

#[test]
fn mirror_reflectance_above_one() {
    let toml = edit(BASE, "type = \"lambertian\"\nreflectance = 0.5", "type = \"mirror\"\nreflectance = 1.01");
    expect_bad(
        "mirror-above-one",
        &toml,
        &[],
        &[&at(line_of(&toml, "reflectance"), "materials.white.reflectance"), "reflectance must lie in [0, 1]"],
    );
}

#[test]
fn reflectance_plus_transmittance_above_one() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = 0.5\ntransmittance = 0.6");
    // The sum belongs to no one key: it is reported at the material's table.
    expect_bad(
        "reflectance-plus-transmittance",
        &toml,
        &[],
        &[&at(line_of(&toml, "[materials.white]"), "materials.white"), "reflectance + transmittance must not exceed 1"],
    );
}

#[test]
fn ior_zero() {
    let toml = edit(BASE, "type = \"lambertian\"\nreflectance = 0.5", "type = \"dielectric\"\nior = 0");
    expect_bad(
        "ior-zero",
        &toml,
        &[],
        &[&at(line_of(&toml, "ior"), "materials.white.ior"), "ior must be positive at every wavelength"],
    );
}

#[test]
fn ior_negative() {
    let toml = edit(BASE, "type = \"lambertian\"\nreflectance = 0.5", "type = \"dielectric\"\nior = -1.5");
    expect_bad(
        "ior-negative",
        &toml,
        &[],
        &[&at(line_of(&toml, "ior"), "materials.white.ior"), "must not be negative, found -1.5"],
    );
}

#[test]
fn cauchy_ior_not_positive() {
    let toml =
        edit(BASE, "type = \"lambertian\"\nreflectance = 0.5", "type = \"dielectric\"\nior = { cauchy = [-1.0, 0.0] }");
    expect_bad(
        "ior-cauchy",
        &toml,
        &[],
        &[&at(line_of(&toml, "ior"), "materials.white.ior"), "ior must be positive at every wavelength"],
    );
}

/// `BASE` with its material a dielectric whose index is `ior` (`ior = ...` or `outside_ior = ...`).
fn dielectric_base(ior: &str) -> String {
    edit(BASE, "type = \"lambertian\"\nreflectance = 0.5", &format!("type = \"dielectric\"\n{ior}"))
}

#[test]
fn unknown_glass_lists_the_bundled_ones() {
    let toml = dielectric_base("ior = \"N-BK7\"");
    expect_bad(
        "glass-unknown",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "ior"), "materials.white.ior"),
            "unknown glass \"N-BK7\"; bundled glasses: \"BK7\", \"BAF10\", \"FK51A\", \"LASF9\", \"SF5\", \"SF10\", \
             \"SF11\", \"fused_silica\", \"PMMA\", \"polycarbonate\", \"water\"",
        ],
    );
}

#[test]
fn glass_whose_table_or_formula_misses_part_of_the_range() {
    // SF10's table starts at 380 nm, the default range at 360 nm; on the outside as well.
    let toml = dielectric_base("outside_ior = \"SF10\"");
    expect_bad(
        "glass-range-table",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "outside_ior"), "materials.white.outside_ior"),
            "the table of SF10 covers 380 to 910 nm, but the simulation's wavelength_range_nm is [360, 830]",
        ],
    );
    // BK7's table ends at 916 nm.
    let toml = format!("[simulation]\nwavelength_range_nm = [400, 1000]\n{}", dielectric_base("ior = \"BK7\""));
    expect_bad(
        "glass-range-table-long",
        &toml,
        &[],
        &[&at(line_of(&toml, "ior"), "materials.white.ior"), "the table of BK7 covers 300 to 916 nm"],
    );
    // Sultanova et al. measured PMMA from 436.8 nm.
    let toml = dielectric_base("ior = \"PMMA\"");
    expect_bad(
        "glass-range-formula",
        &toml,
        &[],
        &[&at(line_of(&toml, "ior"), "materials.white.ior"), "the dispersion formula of PMMA covers 436.8 to 1052 nm"],
    );
}

#[test]
fn sellmeier_pole_inside_the_range() {
    // C = 0.36 µm²: a pole at 600 nm.
    let toml = dielectric_base("ior = { sellmeier = { B = [1.0, 0.2], C = [0.01, 0.36] } }");
    expect_bad(
        "sellmeier-pole",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "ior"), "materials.white.ior.sellmeier.C[1]"),
            "C = 0.36 µm² puts a pole of n² (λ² = C, at 600.0 nm) inside the simulated wavelength_range_nm [360, 830]",
        ],
    );
}

#[test]
fn sellmeier_b_and_c_of_unequal_length() {
    let toml = dielectric_base("ior = { sellmeier = { B = [1.0, 0.2], C = [0.01] } }");
    expect_bad(
        "sellmeier-lengths",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "ior"), "materials.white.ior.sellmeier"),
            "B and C must have one entry per Sellmeier term, the same number each; found 2 B and 1 C",
        ],
    );
}

#[test]
fn sellmeier_negative_c() {
    let toml = dielectric_base("ior = { sellmeier = { B = [1.0], C = [-0.01] } }");
    expect_bad(
        "sellmeier-negative-c",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "ior"), "materials.white.ior.sellmeier.C[0]"),
            "C (a resonance wavelength squared, in µm²) must not be negative, found -0.01",
        ],
    );
}

#[test]
fn sellmeier_malformed_terms() {
    // No terms, too many terms, a non-finite one, a missing array, a stray key.
    let seven = "[1, 1, 1, 1, 1, 1, 1]";
    let seven = format!("{{ B = {seven}, C = {seven} }}");
    let cases: &[(&str, &str, &str, &str)] = &[
        ("sellmeier-empty", "{ B = [], C = [] }", "sellmeier.B", "expected 1 to 6 Sellmeier terms, found 0"),
        ("sellmeier-seven", &seven, "sellmeier.B", "expected 1 to 6 Sellmeier terms, found 7"),
        ("sellmeier-inf", "{ B = [inf], C = [0.01] }", "sellmeier.B[0]", "inf is not a finite number"),
        ("sellmeier-no-c", "{ B = [1.0] }", "sellmeier.C", "missing required key `C`"),
        (
            "sellmeier-stray",
            "{ B = [1.0], C = [0.01], D = [1] }",
            "sellmeier.D",
            "unknown key `D`; allowed keys here: B, C",
        ),
    ];
    for &(name, terms, key, message) in cases {
        let toml = dielectric_base(&format!("ior = {{ sellmeier = {terms} }}"));
        expect_bad(name, &toml, &[], &[&at(line_of(&toml, "ior"), &format!("materials.white.ior.{key}")), message]);
    }
}

#[test]
fn sellmeier_index_squared_not_positive() {
    // B = −3 with a far-UV resonance: n² ≈ 1 − 3 < 0 across the range.
    let toml = dielectric_base("ior = { sellmeier = { B = [-3.0], C = [0.01] } }");
    expect_bad(
        "sellmeier-negative-n2",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "ior"), "materials.white.ior.sellmeier"),
            "n² = 1 + Σ Bλ²/(λ² − C) must be positive and finite over the simulated wavelength_range_nm [360, 830]; at \
             360 nm it is",
        ],
    );
}

#[test]
fn anisotropic_roughness_is_two_numbers_each_in_range() {
    // `roughness = [αu, αv]` on each model that takes it; a bad element is named by its index.
    let two = "anisotropic roughness is [αu, αv], two numbers (along and across the surface tangent)";
    let cases: [(&str, &str, &str, &str, String); 7] = [
        ("one", "conductor\"\neta = 1\nk = 5", "[0.1]", "roughness", format!("{two}; found 1")),
        ("three", "conductor\"\neta = 1\nk = 5", "[0.1, 0.2, 0.3]", "roughness", format!("{two}; found 3")),
        (
            "negative",
            "conductor\"\neta = 1\nk = 5",
            "[-0.1, 0.2]",
            "roughness[0]",
            "roughness (GGX α) must lie in [0, 1], found -0.1".into(),
        ),
        (
            "string",
            "conductor\"\neta = 1\nk = 5",
            "[\"x\", 0.1]",
            "roughness[0]",
            "expected a number, found a string".into(),
        ),
        (
            "table",
            "plastic\"",
            "{ u = 0.1 }",
            "roughness",
            "expected a number (the GGX α) or [αu, αv] (along and across the surface tangent)".into(),
        ),
        (
            "plastic",
            "plastic\"",
            "[0.2, 1.5]",
            "roughness[1]",
            "roughness (GGX α) must lie in [0, 1], found 1.5".into(),
        ),
        ("dielectric", "dielectric\"", "[0.2]", "roughness", format!("{two}; found 1")),
    ];
    for (name, kind, value, key, message) in cases {
        let toml = edit(BASE, "lambertian\"\nreflectance = 0.5", &format!("{kind}\nroughness = {value}"));
        expect_bad(
            &format!("roughness-{name}"),
            &toml,
            &[],
            &[&at(line_of(&toml, "roughness"), &format!("materials.white.{key}")), &message],
        );
    }
}

#[test]
fn glass_names_and_sellmeier_belong_to_dielectrics_only() {
    // A conductor's `eta` is not a glass.
    let toml = edit(
        BASE,
        "type = \"lambertian\"\nreflectance = 0.5",
        "type = \"conductor\"\neta = { sellmeier = { B = [1.0], C = [0.01] } }\nk = 1",
    );
    expect_bad(
        "sellmeier-conductor",
        &toml,
        &[],
        &[&at(line_of(&toml, "eta"), "materials.white.eta.sellmeier"), "unknown key `sellmeier`"],
    );
}

#[test]
fn negative_power() {
    let toml = edit(BASE, "power_w = 10", "power_w = -10");
    expect_bad(
        "power-negative",
        &toml,
        &[],
        &[&at(line_of(&toml, "power_w"), "lights[0].power_w"), "power must be positive, found -10"],
    );
}

#[test]
fn zero_power() {
    let toml = edit(BASE, "power_w = 10", "power_w = 0");
    expect_bad(
        "power-zero",
        &toml,
        &[],
        &[&at(line_of(&toml, "power_w"), "lights[0].power_w"), "power must be positive, found 0"],
    );
}

#[test]
fn nan_reflectance() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = nan");
    expect_bad(
        "nan",
        &toml,
        &[],
        &[&at(line_of(&toml, "reflectance"), "materials.white.reflectance"), "NaN is not a finite number"],
    );
}

#[test]
fn inf_power() {
    let toml = edit(BASE, "power_w = 10", "power_w = inf");
    expect_bad("inf", &toml, &[], &[&at(line_of(&toml, "power_w"), "lights[0].power_w"), "inf is not a finite number"]);
}

#[test]
fn nan_in_a_corner() {
    let toml = edit(BASE, "[0, 0, 1], [1, 0, 1]", "[0, nan, 1], [1, 0, 1]");
    expect_bad(
        "nan-corner",
        &toml,
        &[],
        &[&at(line_of(&toml, "nan"), "surfaces[0].shape.corners[1][1]"), "NaN is not a finite number"],
    );
}

#[test]
fn minus_inf_in_a_spectrum_table() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = { table = [[400, 0.5], [-inf, 0.5]] }");
    expect_bad(
        "minus-inf-table",
        &toml,
        &[],
        &[&at(line_of(&toml, "reflectance"), "materials.white.reflectance.table[1][0]"), "-inf is not a finite number"],
    );
}

// ---------------------------------------------------------------- spectra

#[test]
fn spectrum_table_not_sorted() {
    // One row per line, so the line number tells which row is meant.
    let toml =
        edit(BASE, "reflectance = 0.5", "reflectance = { table = [\n  [400, 0.2],\n  [700, 0.3],\n  [600, 0.4],\n] }");
    expect_bad(
        "table-unsorted",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "[600, 0.4]"), "materials.white.reflectance.table[2]"),
            "wavelengths must be sorted and strictly increasing: 600 nm follows 700 nm",
        ],
    );
}

#[test]
fn spectrum_table_negative_value() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = { table = [\n  [400, 0.2],\n  [700, -0.1],\n] }");
    expect_bad(
        "table-negative",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "[700, -0.1]"), "materials.white.reflectance.table[1]"),
            "spectrum values must not be negative, found -0.1 at 700 nm",
        ],
    );
}

#[test]
fn spectrum_table_empty() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = { table = [] }");
    expect_bad(
        "table-empty",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "reflectance"), "materials.white.reflectance.table"),
            "a spectrum table needs at least one [wavelength_nm, value] row",
        ],
    );
}

#[test]
fn spectrum_table_row_not_a_pair() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = { table = [[400, 0.5], [700]] }");
    expect_bad(
        "table-row",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "reflectance"), "materials.white.reflectance.table[1]"),
            "expected a [wavelength_nm, value] pair",
        ],
    );
}

#[test]
fn missing_spectrum_file() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = { file = \"spectra/nope.csv\" }");
    let line = line_of(&toml, "nope.csv");
    expect_bad(
        "spectrum-missing",
        &toml,
        &[],
        &[
            "error: {dir}/spectra/nope.csv: cannot read spectrum file",
            &format!("(spectrum file named by `materials.white.reflectance.file` at {{scene}}:{line})"),
        ],
    );
}

#[test]
fn malformed_spectrum_csv() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = { file = \"spectra/white.csv\" }");
    let csv = "wavelength_nm,value\n400,0.5\n\n500,abc\n600,0.4\n";
    let line = line_of(&toml, "white.csv");
    expect_bad(
        "spectrum-malformed",
        &toml,
        &[("spectra/white.csv", csv)],
        &[
            &format!("error: {{dir}}/spectra/white.csv:{}: ", line_of(csv, "abc")),
            "expected `wavelength_nm,value` (two finite numbers), found \"500,abc\"",
            &format!("(spectrum file named by `materials.white.reflectance.file` at {{scene}}:{line})"),
        ],
    );
}

#[test]
fn spectrum_csv_not_sorted() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = { file = \"spectra/white.csv\" }");
    let csv = "wavelength_nm,value\n400,0.5\n# a comment\n700,0.5\n600,0.5\n";
    expect_bad(
        "spectrum-csv-unsorted",
        &toml,
        &[("spectra/white.csv", csv)],
        &[
            &format!("error: {{dir}}/spectra/white.csv:{}: ", line_of(csv, "600")),
            "wavelengths must be sorted and strictly increasing: 600 nm follows 700 nm",
        ],
    );
}

// ---------------------------------------------------------------- meshes and shapes

/// `BASE` with the floor made of the mesh `file`.
fn mesh_scene(file: &str) -> String {
    let shape_line = BASE.lines().find(|l| l.starts_with("shape") && l.contains("[0, 0, 0]")).unwrap();
    edit(BASE, shape_line, &format!("shape = {{ type = \"mesh\", file = \"{file}\" }}"))
}

#[test]
fn missing_mesh_file() {
    let toml = mesh_scene("meshes/nope.obj");
    let line = line_of(&toml, "nope.obj");
    expect_bad(
        "mesh-missing",
        &toml,
        &[],
        &[
            "error: {dir}/meshes/nope.obj: cannot read mesh file",
            &format!("(mesh named by `surfaces[0].shape` at {{scene}}:{line})"),
        ],
    );
}

#[test]
fn obj_bad_vertex() {
    let toml = mesh_scene("meshes/floor.obj");
    let obj = "# floor\nv 0 0 0\nv 0 0 1\nv 1 0 x\nv 1 0 0\nf 1 2 3 4\n";
    let line = line_of(&toml, "floor.obj");
    expect_bad(
        "obj-vertex",
        &toml,
        &[("meshes/floor.obj", obj)],
        &[
            &format!("error: {{dir}}/meshes/floor.obj:{}: malformed vertex", line_of(obj, "1 0 x")),
            &format!("(mesh named by `surfaces[0].shape` at {{scene}}:{line})"),
        ],
    );
}

/// A mesh that repeats one face (in any corner order) more than 32 times is refused before the
/// tree is built: copies share one box, and a few hundred made a tree too deep to trace after a
/// build whose time grew as their number squared. 32 copies still run.
#[test]
fn obj_face_repeated_too_often() {
    let toml = mesh_scene("meshes/floor.obj");
    let line = line_of(&toml, "floor.obj");
    let faces = |n: usize| (0..n).map(|k| ["f 1 2 3\n", "f 3 1 2\n", "f 2 1 3\n"][k % 3]).collect::<String>();
    let obj = |n: usize| format!("v 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 0 0\nf 1 3 4\n{}", faces(n));
    expect_bad(
        "obj-repeated-face",
        &toml,
        &[("meshes/floor.obj", &obj(33))],
        &[&format!("error: {{scene}}:{line}: `surfaces[0].shape`: 33 triangles of surface \"floor\" lie exactly on one another")],
    );
    let (dir, out) = photon("obj-repeated-32", Some(&toml), &[("meshes/floor.obj", &obj(32))], RUN);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn obj_face_index_out_of_range() {
    let toml = mesh_scene("meshes/floor.obj");
    let obj = "v 0 0 0\nv 0 0 1\nv 1 0 1\n\nf 1 2 3\nf 1 3 4\n";
    expect_bad(
        "obj-face",
        &toml,
        &[("meshes/floor.obj", obj)],
        &[&format!(
            "error: {{dir}}/meshes/floor.obj:{}: face index 4 refers to no vertex (3 defined so far)",
            line_of(obj, "f 1 3 4")
        )],
    );
}

#[test]
fn obj_without_faces() {
    let toml = mesh_scene("meshes/floor.obj");
    let obj = "v 0 0 0\nv 0 0 1\nv 1 0 1\n";
    expect_bad(
        "obj-no-faces",
        &toml,
        &[("meshes/floor.obj", obj)],
        &["error: {dir}/meshes/floor.obj: the mesh has no faces with non-zero area"],
    );
}

#[test]
fn degenerate_quad() {
    // All four corners on one line: zero area.
    let toml =
        edit(BASE, "[[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]]", "[[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]");
    expect_bad(
        "degenerate-quad",
        &toml,
        &[],
        &[&at(line_of(&toml, "[3, 0, 0]"), "surfaces[0].shape"), "degenerate quad: its corners enclose zero area"],
    );
}

#[test]
fn coordinates_too_far_out() {
    // Far beyond any real scene; the single-precision BVH used to panic on such geometry.
    let toml = edit(
        BASE,
        "[[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]]",
        "[[0, 0, 0], [0, 0, 1e20], [1e20, 0, 1e20], [1e20, 0, 0]]",
    );
    expect_bad(
        "far-quad",
        &toml,
        &[],
        &[
            &at(line_of(&toml, "1e20"), "surfaces[0].shape"),
            "a coordinate reaches 1e20 m; every point must lie within 1e15 m of the origin",
        ],
    );
}

#[test]
fn light_scaled_too_far_out() {
    let toml = edit(BASE, "[0, 1, 1]] }", "[0, 1, 1]], transform = { scale = 1e30 } }");
    expect_bad(
        "far-light",
        &toml,
        &[],
        &[&at(line_of(&toml, "scale"), "lights[0].shape"), "every point must lie within 1e15 m of the origin"],
    );
}

#[test]
fn camera_look_at_equals_position() {
    let toml = format!("[camera]\nposition = [0.5, 0.5, -2]\nlook_at = [0.5, 0.5, -2]\nfov_deg = 40\n\n{BASE}");
    expect_bad(
        "camera-look-at",
        &toml,
        &[],
        &[&at(line_of(&toml, "look_at"), "camera.look_at"), "look_at equals position"],
    );
}

// ---------------------------------------------------------------- `photon info`

#[test]
fn info_empty_file() {
    expect_bad_info("info-empty", "", &[], &["error: {scene}: the scene file is empty"]);
}

#[test]
fn info_unknown_material_key() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = 0.5\ncolor = 1");
    expect_bad_info(
        "info-unknown-key",
        &toml,
        &[],
        &[&at(line_of(&toml, "color"), "materials.white.color"), "unknown key `color`"],
    );
}

#[test]
fn info_reflectance_above_one() {
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = 2");
    expect_bad_info(
        "info-reflectance",
        &toml,
        &[],
        &[&at(line_of(&toml, "reflectance"), "materials.white.reflectance"), "must lie in [0, 1]"],
    );
}

#[test]
fn info_malformed_obj() {
    let toml = mesh_scene("meshes/floor.obj");
    let obj = "v 0 0 0\nv 0 0 1\nv 1 0 1\nf 1 2 0\n";
    expect_bad_info(
        "info-obj",
        &toml,
        &[("meshes/floor.obj", obj)],
        &["error: {dir}/meshes/floor.obj:4: face index 0 refers to no vertex"],
    );
}

#[test]
fn info_missing_scene_file() {
    expect_exit2("info-missing", None, &[], INFO, &["error: {scene}: cannot read the scene file"]);
}

// ---------------------------------------------------------------- command-line arguments

#[test]
fn zero_photons() {
    expect_bad_args("photons-0", &["--photons", "0"], &["--photons must be at least 1"]);
}

#[test]
fn zero_threads() {
    expect_bad_args("threads-0", &["--threads", "0"], &["--threads must be between 1 and 1024"]);
}

#[test]
fn absurd_thread_count() {
    expect_bad_args("threads-5000", &["--threads", "5000"], &["--threads must be between 1 and 1024"]);
}

#[test]
fn unknown_flag() {
    expect_bad_args("unknown-flag", &["--photons", "1000", "--bogus"], &["unexpected argument '--bogus'"]);
}

#[test]
fn photons_not_a_number() {
    expect_bad_args("photons-nan", &["--photons", "many"], &["--photons"]);
}

#[test]
fn negative_rel_error() {
    expect_bad_args(
        "rel-error",
        &["--photons", "1000", "--rel-error=-0.1"],
        &["--rel-error must be a positive number"],
    );
}

#[test]
fn tally_of_an_unknown_surface() {
    expect_bad_args(
        "tally",
        &["--photons", "1000", "--rel-error", "0.1", "--tally", "ceiling"],
        &["--tally ceiling: no surface or medium of that name; surfaces: floor, lamp"],
    );
}

#[test]
fn unknown_integrator_in_scene() {
    let toml = format!("[simulation]\nintegrator = \"photon_mapping\"\n\n{BASE}");
    expect_bad(
        "integrator-key",
        &toml,
        &[],
        &[&at(2, "simulation.integrator"), "unknown integrator \"photon_mapping\"", "\"bdpt\""],
    );
}

#[test]
fn unknown_integrator_flag() {
    expect_bad_args("integrator-flag", &["--integrator", "mlt"], &["invalid value 'mlt'", "--integrator"]);
}

#[test]
fn watts_and_lumens_together() {
    let toml = edit(BASE, "power_w = 10", "power_w = 10\npower_lm = 800");
    expect_bad(
        "power-w-and-lm",
        &toml,
        &[],
        &[&at(line_of(&toml, "power_lm"), "lights[0].power_lm"), "give only one of power_w, power_lm"],
    );
}

#[test]
fn negative_lumens() {
    let toml = edit(BASE, "power_w = 10", "power_lm = -800");
    expect_bad(
        "power-lm-negative",
        &toml,
        &[],
        &[&at(line_of(&toml, "power_lm"), "lights[0].power_lm"), "power must be positive, found -800"],
    );
}

#[test]
fn lumens_from_an_invisible_spectrum() {
    // All its power below 360 nm, where the CIE table has ȳ = 0: lumens cannot set its power.
    let toml = edit(BASE, "power_w = 10", "power_lm = 800\nspectrum = { file = \"uv.csv\" }");
    expect_bad(
        "power-lm-invisible",
        &format!("[simulation]\nwavelength_range_nm = [300, 800]\n{toml}"),
        &[("uv.csv", "wavelength_nm,value\n300,1\n350,1\n360,0\n800,0\n")],
        &["lights[0].power_lm", "no visible power"],
    );
}

#[test]
fn map_on_a_sphere() {
    let toml = format!(
        "{BASE}\n[[surfaces]]\nname = \"ball\"\nmaterial = \"white\"\nshape = {{ type = \"sphere\", center = [0.5, 0.5, 0.5], radius = 0.1 }}\nmap = {{ resolution = [8, 8] }}\n"
    );
    expect_bad(
        "map-sphere",
        &toml,
        &[],
        &[&at(line_of(&toml, "map ="), "surfaces[1].map"), "needs a surface of type \"quad\" or \"disk\""],
    );
}

/// One mesh file used by many surfaces: each use is counted as it is read, so the scene is
/// refused once their sum passes the cap, not after all are made (one file is bounded by its
/// size; its uses were not). The cap is lowered to 1000 through `PHOTON_MAX_SCENE_TRIANGLES`.
#[test]
fn a_mesh_used_by_many_surfaces_counts_toward_the_triangle_limit() {
    // A closed cube of 12 triangles, used by 100 surfaces: 4 (the floor and the lamp, counted
    // ahead) + 12·k passes 1000 at the 84th use, surfaces[84], with 1012.
    let cube = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
                f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 4 8 7\nf 4 7 3\n\
                f 1 5 8\nf 1 8 4\nf 2 3 7\nf 2 7 6\n";
    let mut toml = BASE.to_string();
    for k in 0..100 {
        toml += &format!(
            "\n[[surfaces]]\nname = \"cube{k}\"\nmaterial = \"white\"\nshape = {{ type = \"mesh\", file = \"cube.obj\", transform = {{ translate = [{}, 5, 0] }} }}\n",
            2 * k
        );
    }
    // `photon run` on `scene` beside cube.obj, with the limit lowered to `limit`.
    let run = |name: &str, scene: &str, limit: &str| {
        let dir = case_dir(name);
        fs::write(dir.join("scene.toml"), scene).unwrap();
        fs::write(dir.join("cube.obj"), cube).unwrap();
        let args: Vec<String> = RUN.iter().map(|a| expand(a, &dir)).collect();
        let out = Command::new(env!("CARGO_BIN_EXE_photon"))
            .args(&args)
            .current_dir(&dir)
            .env("PHOTON_MAX_SCENE_TRIANGLES", limit)
            .output()
            .unwrap();
        (dir, out)
    };
    let (dir, out) = run("mesh-uses-over-limit", &toml, "1000");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    let line = line_of(&toml, "name = \"cube83\"") + 2;
    for part in [
        format!("scene.toml:{line}: `surfaces[84].shape`"),
        "the scene's generated shapes and the meshes read so far make 1012 triangles, more than 1000".to_string(),
        "PHOTON_MAX_SCENE_TRIANGLES".to_string(),
    ] {
        assert!(err.contains(&part), "missing {part:?} in: {err}");
    }
    assert!(!dir.join("out").exists(), "a refused scene left an output folder");
    // Under a cap its 1204 triangles fit, the same scene runs.
    let (_dir, out) = run("mesh-uses-under-limit", &toml, "1204");
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    // A light's mesh counts too: the base scene's lamp made of the cube, under a limit of 13
    // (the floor's 2 and the lamp's 12 make 14).
    let lamp = BASE.lines().find(|l| l.starts_with("shape") && l.contains("[0, 1, 0]")).unwrap();
    let lamp_toml = BASE.replace(lamp, "shape = { type = \"mesh\", file = \"cube.obj\" }");
    let (_dir, out) = run("mesh-light-over-limit", &lamp_toml, "13");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    let line = line_of(&lamp_toml, "cube.obj");
    assert!(err.contains(&format!("scene.toml:{line}: `lights[0].shape`")), "{err}");
    assert!(err.contains("make 14 triangles, more than 13"), "{err}");
}

#[test]
fn too_many_triangles_are_refused_before_they_are_made() {
    // 103 spheres of 20·4⁹ = 5 242 880 triangles: 540 M, past the 2²⁸ the tree can index on any
    // machine (and past the memory on most, which the refusal may name instead). Refused before
    // any is made, so the case takes no time and no memory.
    let mut toml = BASE.to_string();
    for k in 0..103 {
        toml += &format!(
            "\n[[surfaces]]\nname = \"ball{k}\"\nmaterial = \"white\"\nshape = {{ type = \"sphere\", center = [0.5, 0.5, 0.5], radius = 0.1, subdivisions = 9 }}\n"
        );
    }
    expect_bad(
        "too-many-triangles",
        &toml,
        &[],
        &["shape`: the scene's shapes make", "triangles up to this one, more than"],
    );
    // The total named is the declared counts' sum where it crossed the limit: the floor's 2 and
    // k whole spheres (k ≤ 103), counted ahead (made first, 5·10⁸ triangles would take minutes
    // and tens of GB before any message).
    let (_dir, out) = photon("too-many-triangles-total", Some(&toml), &[], RUN);
    let err = String::from_utf8_lossy(&out.stderr);
    let total: u64 = err.split("make ").nth(1).and_then(|r| r.split(' ').next()).and_then(|n| n.parse().ok()).unwrap();
    let spheres = (total - 2) / 5_242_880;
    assert!((total - 2).is_multiple_of(5_242_880) && (1..=103).contains(&spheres), "{err}");
}

#[test]
fn more_camera_samples_a_pixel_than_the_film_counts_are_refused() {
    // A 1×1 image from the path tracer: one camera sample a photon, all in the one pixel, whose
    // count is a u32 (film and state files). 2³² photons would wrap it.
    let toml = format!(
        "[camera]\nposition = [0.5, 0.5, -2]\nlook_at = [0.5, 0.5, 0]\nfov_deg = 40\nresolution = [1, 1]\n\n{BASE}"
    );
    let run = |extra: &[&str]| -> Vec<String> {
        ["run", "{scene}", "--out", "{out}", "--quiet", "--integrator", "path"]
            .iter()
            .chain(extra)
            .map(|s| s.to_string())
            .collect()
    };
    for (name, extra) in [
        ("camera-samples-photons", &["--photons", "4294967296"][..]),
        ("camera-samples-batches", &["--batches", "262143..262144"][..]),
    ] {
        let args = run(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        expect_exit2(name, Some(&toml), &[], &args, &["more than 2^32 − 1 samples each", "at most 4294967295 photons"]);
    }
}

#[test]
fn map_of_zero_texels() {
    let toml = edit(BASE, "[1, 0, 0]] }\n", "[1, 0, 0]] }\nmap = { resolution = [0, 8] }\n");
    expect_bad(
        "map-zero",
        &toml,
        &[],
        &[&at(line_of(&toml, "map ="), "surfaces[0].map.resolution"), "each between 1 and 1024 texels"],
    );
}

#[test]
fn map_with_an_unknown_key() {
    let toml = edit(BASE, "[1, 0, 0]] }\n", "[1, 0, 0]] }\nmap = { resolution = [8, 8], colour = \"jet\" }\n");
    expect_bad("map-key", &toml, &[], &[&at(line_of(&toml, "map ="), "surfaces[0].map.colour")]);
}

const GOOD_IES: &str = "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 3 1 1 2 0 0 0\n1 1 0\n0 45 90\n0\n100 80 0\n";

/// BASE's quad light turned into an IES one.
fn ies_scene() -> String {
    edit(BASE, "power_w = 10", "distribution = { ies = \"lamp.ies\" }")
}

#[test]
fn ies_with_a_word_among_the_candela_values() {
    let ies = GOOD_IES.replace("100 80 0", "100 eighty 0");
    expect_bad(
        "ies-word",
        &ies_scene(),
        &[("lamp.ies", &ies)],
        &["{dir}/lamp.ies:7: `eighty` is not a number (a candela value)", "lights[0].distribution.ies"],
    );
}

#[test]
fn ies_cut_short() {
    let ies = GOOD_IES.replace("100 80 0\n", "100 80\n");
    expect_bad(
        "ies-short",
        &ies_scene(),
        &[("lamp.ies", &ies)],
        &["{dir}/lamp.ies:7: the file ends where a candela value should be"],
    );
}

#[test]
fn ies_with_a_tilt_table() {
    let ies = GOOD_IES.replace("TILT=NONE", "TILT=INCLUDE");
    expect_bad("ies-tilt", &ies_scene(), &[("lamp.ies", &ies)], &["{dir}/lamp.ies:2: TILT=INCLUDE is not supported"]);
}

#[test]
fn ies_with_falling_angles() {
    let ies = GOOD_IES.replace("0 45 90\n", "0 90 45\n");
    expect_bad("ies-angles", &ies_scene(), &[("lamp.ies", &ies)], &["{dir}/lamp.ies:5: vertical angles must increase"]);
}

#[test]
fn ies_file_missing() {
    expect_bad("ies-missing", &ies_scene(), &[], &["{dir}/lamp.ies: cannot read IES file"]);
}

#[test]
fn ies_with_upward_light_on_an_area_light() {
    let ies = GOOD_IES.replace("0 45 90\n", "0 90 180\n");
    let toml = ies_scene();
    expect_bad(
        "ies-upward",
        &toml,
        &[("lamp.ies", &ies)],
        &[&at(line_of(&toml, "distribution"), "lights[0].distribution"), "use a point light"],
    );
}

#[test]
fn map_on_a_mesh_without_texture_coordinates() {
    let toml = format!(
        "{BASE}\n[[surfaces]]\nname = \"tri\"\nmaterial = \"white\"\nshape = {{ type = \"mesh\", file = \"tri.obj\" }}\nmap = {{ resolution = [8, 8] }}\n"
    );
    expect_bad(
        "map-mesh-no-uv",
        &toml,
        &[("tri.obj", "v 0 0.5 0\nv 1 0.5 0\nv 0 0.5 1\nf 1 2 3\n")],
        &[&at(line_of(&toml, "map ="), "surfaces[1].map"), "needs texture coordinates"],
    );
}

#[test]
fn map_on_a_mesh_with_texture_coordinates_of_no_area() {
    let toml = format!(
        "{BASE}\n[[surfaces]]\nname = \"tri\"\nmaterial = \"white\"\nshape = {{ type = \"mesh\", file = \"tri.obj\" }}\nmap = {{ resolution = [8, 8] }}\n"
    );
    let obj = "v 0 0.5 0\nv 1 0.5 0\nv 0 0.5 1\nvt 0 0\nvt 0.5 0.5\nvt 1 1\nf 1/1 2/2 3/3\n";
    expect_bad(
        "map-mesh-flat-uv",
        &toml,
        &[("tri.obj", obj)],
        &[&at(line_of(&toml, "map ="), "surfaces[1].map"), "triangle 0", "enclose no area"],
    );
}

#[test]
fn map_on_a_quad_whose_first_edges_are_parallel() {
    // Corners listed so that the edges from the first corner to the second and the fourth lie
    // along one line: the quad is a proper surface but gives the map no second axis.
    let toml = edit(
        BASE,
        "corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]] }\n",
        "corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [0, 0, 0.5]] }\nmap = { resolution = [8, 8] }\n",
    );
    expect_bad("map-parallel-edges", &toml, &[], &[&at(line_of(&toml, "map ="), "surfaces[0].map"), "parallel"]);
}

#[test]
fn names_that_make_the_same_file_name() {
    let toml = format!(
        "{BASE}{}{}",
        SECOND_SURFACE.replace("\"wall\"", "\"wall 1\""),
        SECOND_SURFACE.replace("\"wall\"", "\"wall_1\"")
    );
    expect_bad(
        "name-stems",
        &toml,
        &[],
        &[&at(line_of(&toml, "\"wall_1\""), "surfaces[2]"), "same output file name \"wall_1\""],
    );
}

#[test]
fn ies_c0_along_the_area_lights_normal() {
    // The base lamp faces −y; c0 along y has no part across the axis to name C = 0 by.
    let toml = edit(BASE, "power_w = 10", "distribution = { ies = \"lamp.ies\", c0 = [0, 1, 0] }");
    expect_bad(
        "ies-c0-parallel",
        &toml,
        &[("lamp.ies", GOOD_IES)],
        &[&at(line_of(&toml, "distribution"), "lights[0].distribution.c0"), "parallel to the light's normal"],
    );
}

#[test]
fn ies_c0_along_a_point_lights_direction() {
    let toml = edit(
        BASE,
        "shape = { type = \"quad\", corners = [[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]] }\npower_w = 10",
        "shape = { type = \"point\", position = [0.5, 1, 0.5] }\ndirection = [0, -1, 0]\ndistribution = { ies = \"lamp.ies\", c0 = [0, 2, 0] }",
    );
    expect_bad(
        "ies-c0-point",
        &toml,
        &[("lamp.ies", GOOD_IES)],
        &[&at(line_of(&toml, "distribution"), "lights[0].distribution.c0"), "parallel to the light's direction"],
    );
}

#[test]
fn bad_abg_scatter() {
    // Each: the material's lines in place of the Lambertian's, the key path, the message.
    let cases: [(&str, &str, &str, &str); 8] = [
        (
            "abg-two",
            "type = \"mirror\"\nscatter = { abg = [0.1, 0.01] }",
            "scatter.abg",
            "expected [A, B, g], three numbers; found 2 values",
        ),
        ("abg-text", "type = \"mirror\"\nscatter = { abg = [0.1, \"x\", 2] }", "scatter.abg[1]", ""),
        (
            "abg-zero-b",
            "type = \"mirror\"\nscatter = { abg = [0.1, 0, 2] }",
            "scatter.abg",
            "B must be positive (0 allowed only with g = 0)",
        ),
        (
            "abg-negative-a",
            "type = \"mirror\"\nscatter = { abg = [-0.1, 0.01, 2] }",
            "scatter.abg",
            "A must be positive and finite",
        ),
        (
            "abg-g",
            "type = \"mirror\"\nscatter = { abg = [0.1, 0.01, 9] }",
            "scatter.abg",
            "g must lie in [0, 8], found 9",
        ),
        // πA ln(1 + 1/B) = 14.499 for A = 1, B = 0.01, g = 2.
        ("abg-tis", "type = \"mirror\"\nscatter = { abg = [1, 0.01, 2] }", "scatter.abg", "these A, B, g scatter 14.4"),
        (
            "abg-key",
            "type = \"mirror\"\nscatter = { abc = [0.1, 0.01, 2] }",
            "scatter.abc",
            "unknown key `abc`; allowed keys here: abg",
        ),
        (
            "abg-rough",
            "type = \"conductor\"\nmetal = \"Al\"\nroughness = 0.2\nscatter = { abg = [0.1, 0.01, 2] }",
            "scatter",
            "give either `roughness` or `scatter`",
        ),
    ];
    for (name, material, key, message) in cases {
        let toml = edit(BASE, "type = \"lambertian\"\nreflectance = 0.5", material);
        let line = line_of(&toml, "scatter");
        expect_bad(name, &toml, &[], &[&at(line, &format!("materials.white.{key}")), message]);
    }
    // Not on a Lambertian surface.
    let toml = edit(BASE, "reflectance = 0.5", "reflectance = 0.5\nscatter = { abg = [0.1, 0.01, 2] }");
    expect_bad(
        "abg-lambertian",
        &toml,
        &[],
        &[&at(line_of(&toml, "scatter"), "materials.white.scatter"), "unknown key `scatter`"],
    );
}

#[test]
fn bad_media() {
    // Each: the material's lines in place of the Lambertian's, the [media] entry, the line's
    // text, the key path, the message.
    let fog = "[media.fog]\nabsorption_per_m = 1\nscattering_per_m = 10\n";
    let glass = "type = \"dielectric\"\nmedium = \"fog\"";
    let cases: [(&str, &str, &str, &str, &str, &str); 14] = [
        (
            "medium-unknown",
            "type = \"dielectric\"\nmedium = \"smoke\"",
            fog,
            "medium =",
            "materials.white.medium",
            "unknown medium \"smoke\"; the [media] entries are: fog",
        ),
        (
            "medium-none",
            glass,
            "",
            "medium =",
            "materials.white.medium",
            "unknown medium \"fog\": the file has no [media] entries",
        ),
        (
            "medium-and-absorption",
            "type = \"dielectric\"\nmedium = \"fog\"\nabsorption_per_m = 3",
            fog,
            "medium =",
            "materials.white.medium",
            "give either medium or absorption_per_m, not both",
        ),
        (
            "medium-outside-unknown",
            "type = \"dielectric\"\nmedium = \"fog\"\noutside_medium = \"smog\"",
            fog,
            "outside_medium",
            "materials.white.outside_medium",
            "unknown medium \"smog\"; the [media] entries are: fog",
        ),
        (
            "medium-g",
            glass,
            "[media.fog]\nscattering_per_m = 10\nphase = { henyey_greenstein = 1 }\n",
            "henyey_greenstein",
            "media.fog.phase.henyey_greenstein",
            "must lie strictly between −1 and 1, found 1",
        ),
        (
            "medium-phase",
            glass,
            "[media.fog]\nscattering_per_m = 10\nphase = \"rayleigh\"\n",
            "phase",
            "media.fog.phase",
            "unknown phase function \"rayleigh\"",
        ),
        (
            "medium-negative",
            glass,
            "[media.fog]\nscattering_per_m = -10\n",
            "scattering_per_m",
            "media.fog.scattering_per_m",
            "must not be negative, found -10",
        ),
        (
            "fluorescence-missing",
            glass,
            "[media.fog]\nscattering_per_m = 10\nfluorescence = { quantum_yield = 0.9 }\n",
            "fluorescence",
            "media.fog.fluorescence.absorption_per_m",
            "missing required key `absorption_per_m`",
        ),
        (
            "fluorescence-yield",
            glass,
            "[media.fog]\nfluorescence = { absorption_per_m = 5, emission = 1, quantum_yield = 1.5 }\n",
            "fluorescence",
            "media.fog.fluorescence.quantum_yield",
            "must lie in [0, 1], found 1.5",
        ),
        (
            "fluorescence-dark",
            glass,
            "[media.fog]\nfluorescence = { absorption_per_m = 5, emission = { table = [[900, 1], [950, 1]] }, quantum_yield = 1 }\n",
            "fluorescence",
            "media.fog.fluorescence.emission",
            "no power inside the simulated wavelengths 360–830 nm",
        ),
        (
            "fluorescence-sampling",
            glass,
            "[media.fog]\nfluorescence = { absorption_per_m = 5, emission = 1, quantum_yield = 1, emission_sampling = \"kT\" }\n",
            "fluorescence",
            "media.fog.fluorescence.emission_sampling",
            "unknown emission_sampling \"kT\"",
        ),
        (
            "fluorescence-key",
            glass,
            "[media.fog]\nfluorescence = { absorption_per_m = 5, emission = 1, yield = 1 }\n",
            "fluorescence",
            "media.fog.fluorescence.yield",
            "unknown key `yield`",
        ),
        (
            "medium-key",
            glass,
            "[media.fog]\nscatering_per_m = 10\n",
            "scatering",
            "media.fog.scatering_per_m",
            "unknown key `scatering_per_m`",
        ),
        (
            "medium-lambertian",
            "type = \"lambertian\"\nreflectance = 0.5\nmedium = \"fog\"",
            fog,
            "medium =",
            "materials.white.medium",
            "unknown key `medium`",
        ),
    ];
    for (name, material, media, needle, key, message) in cases {
        let toml = format!("{media}\n{}", edit(BASE, "type = \"lambertian\"\nreflectance = 0.5", material));
        let line = line_of(&toml, needle);
        expect_bad(name, &toml, &[], &[&at(line, key), message]);
    }
}

#[test]
fn a_point_light_has_no_spectrum_to_tally() {
    let toml = format!(
        "{BASE}\n[[lights]]\nname = \"p\"\nshape = {{ type = \"point\", position = [0.5, 0.5, 0.5] }}\nspectrum_bins = 4\n"
    );
    let line = line_of(&toml, "spectrum_bins");
    expect_bad(
        "point-light-spectrum-bins",
        &toml,
        &[],
        &[&at(line, "lights[1].spectrum_bins"), "a point light is not a surface"],
    );
}

#[test]
fn bad_volume_detectors() {
    // Each: the detector's body, the line's text, the key path, the message.
    let cases = [
        ("min = [0, 0, 0]\nmax = [1, 0, 1]\nresolution = [2, 2, 2]", "max =", "detectors[0].max", "must exceed min's"),
        (
            "min = [0, 0, 0]\nmax = [1, 1, 1]\nresolution = [2, 2]",
            "resolution",
            "detectors[0].resolution",
            "expected [nx, ny, nz]",
        ),
        (
            "min = [0, 0, 0]\nmax = [1, 1, 1]\nresolution = [1024, 1024, 8]",
            "resolution",
            "detectors[0].resolution",
            "too many",
        ),
        ("min = [0, 0, 0]\nresolution = [2, 2, 2]", "[[detectors]]", "detectors[0].max", "missing required key `max`"),
        (
            "min = [0, 0, 0]\nmax = [1, 1, 1]\nresolution = [2, 2, 2]\nnadir = [0, 0, 1]",
            "nadir",
            "detectors[0].nadir",
            "unknown key `nadir`",
        ),
    ];
    for (k, (body, needle, key, message)) in cases.into_iter().enumerate() {
        let toml = format!("{BASE}\n[[detectors]]\ntype = \"volume\"\n{body}\n");
        let line = line_of(&toml, needle);
        expect_bad(&format!("volume-{k}"), &toml, &[], &[&at(line, key), message]);
    }
    let two = format!(
        "{BASE}\n[[detectors]]\ntype = \"volume\"\nname = \"a b\"\nmin = [0, 0, 0]\nmax = [1, 1, 1]\nresolution = [1, 1, 1]\n\
         \n[[detectors]]\ntype = \"volume\"\nname = \"a_b\"\nmin = [0, 0, 0]\nmax = [1, 1, 1]\nresolution = [1, 1, 1]\n"
    );
    expect_bad("volume-names", &two, &[], &["would both write volume_a_b.npy"]);
}

#[test]
fn bad_work_planes() {
    const SQUARE: &str = "corners = [[0, 0.5, 0], [1, 0.5, 0], [1, 0.5, 1], [0, 0.5, 1]]";
    // Each: the plane's body, the line's text, the key path, the message.
    let cases = [
        (
            "corners = [[0, 0.5, 0], [1, 0.5, 0], [1, 0.5, 1]]\nresolution = [2, 2]",
            "[[0, 0.5, 0]",
            "detectors[0].corners",
            "expected four corners",
        ),
        (
            "corners = [[0, 0.5, 0], [1, 0.5, 0], [1.5, 0.5, 1], [0, 0.5, 1]]\nresolution = [2, 2]",
            "[[0, 0.5, 0]",
            "detectors[0].corners",
            "must form a parallelogram",
        ),
        (
            "corners = [[0, 0.5, 0], [1, 0.5, 0], [2, 0.5, 0], [1, 0.5, 0]]\nresolution = [2, 2]",
            "[[0, 0.5, 0]",
            "detectors[0].corners",
            "span no area",
        ),
        (
            "corners = [[0, 0.5, 0], [1, 0.5, 0], [1, 0.5, 1], [0, 0.5, 2e16]]\nresolution = [2, 2]",
            "[[0, 0.5, 0]",
            "detectors[0].corners",
            "must lie within",
        ),
        (
            "corners = [[0, 0.5, 0], [1, 0.5, 0], [1, 0.5, 1], [0, 0.5, \"x\"]]\nresolution = [2, 2]",
            "[[0, 0.5, 0]",
            "detectors[0].corners[3][2]",
            "",
        ),
        (&format!("{SQUARE}\nresolution = [0, 4]"), "resolution", "detectors[0].resolution", "expected [nu, nv]"),
        (&format!("{SQUARE}\nresolution = [2, 2, 2]"), "resolution", "detectors[0].resolution", "expected [nu, nv]"),
        ("resolution = [2, 2]", "[[detectors]]", "detectors[0].corners", "missing required key `corners`"),
        (
            &format!("{SQUARE}\nresolution = [2, 2]\nnadir = [0, 0, 1]"),
            "nadir",
            "detectors[0].nadir",
            "unknown key `nadir`",
        ),
    ];
    for (k, (body, needle, key, message)) in cases.into_iter().enumerate() {
        let toml = format!("{BASE}\n[[detectors]]\ntype = \"plane\"\n{body}\n");
        let line = line_of(&toml, needle);
        expect_bad(&format!("plane-{k}"), &toml, &[], &[&at(line, key), message]);
    }
    let plane =
        |name: &str| format!("\n[[detectors]]\ntype = \"plane\"\nname = \"{name}\"\n{SQUARE}\nresolution = [2, 2]\n");
    let two = format!("{BASE}{}{}", plane("a b"), plane("a_b"));
    expect_bad("plane-names", &two, &[], &["work plane \"a b\" and work plane \"a_b\" would both write maps/a_b.exr"]);
    let mapped = edit(
        BASE,
        "shape = { type = \"quad\", corners = [[0, 0, 0]",
        "map = { resolution = [2, 2] }\nshape = { type = \"quad\", corners = [[0, 0, 0]",
    );
    let clash = format!("{mapped}{}", plane("floor"));
    expect_bad(
        "plane-surface-name",
        &clash,
        &[],
        &["surface \"floor\" and work plane \"floor\" would both write maps/floor.exr"],
    );
}

#[test]
fn bad_ray_set_detectors_and_lights() {
    let body = |b: &str| format!("{BASE}\n[[detectors]]\ntype = \"rays\"\n{b}\n");
    let cases = [
        (
            "surface = \"ceiling\"",
            "surface =",
            "detectors[0].surface",
            "no surface is named \"ceiling\"; surfaces: floor",
        ),
        ("name = \"r\"", "[[detectors]]", "detectors[0].surface", "missing required key `surface`"),
        ("surface = \"floor\"\nmax_rays = 0", "max_rays", "detectors[0].max_rays", "max_rays must be between 1 and"),
        (
            "surface = \"floor\"\nresolution = [2, 2]",
            "resolution",
            "detectors[0].resolution",
            "unknown key `resolution`",
        ),
    ];
    for (k, (b, needle, key, message)) in cases.into_iter().enumerate() {
        let toml = body(b);
        expect_bad(&format!("rays-{k}"), &toml, &[], &[&at(line_of(&toml, needle), key), message]);
    }
    let two = format!(
        "{}\n[[detectors]]\ntype = \"rays\"\nname = \"b\"\nsurface = \"floor\"\n",
        body("name = \"a\"\nsurface = \"floor\"")
    );
    expect_bad("rays-twice", &two, &[], &["ray-set detector \"a\" already records \"floor\""]);
    let surface = edit(
        BASE,
        "shape = { type = \"quad\", corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]] }",
        "shape = { type = \"rays\", file = \"x.npy\" }",
    );
    expect_bad("rays-surface", &surface, &[], &["`rays` is for lights only"]);
}

#[test]
fn a_ray_set_past_max_rays_stops_the_run_with_no_output() {
    let toml = format!("{BASE}\n[[detectors]]\ntype = \"rays\"\nsurface = \"floor\"\nmax_rays = 10\n");
    let (dir, out) = photon("rays-cap", Some(&toml), &[], RUN);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("recorded more than its max_rays = 10 arrivals"), "{stderr}");
    assert!(!dir.join("out").exists());
    let partial: Vec<&str> = ["run", "{scene}", "--out", "{out}", "--batches", "0..1", "--quiet"].to_vec();
    let (_, out) = photon("rays-partial", Some(&toml), &[], &partial);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("records its rays in one whole run"));
}
