//! Issue #16's classes of defect, one group of regression tests each: no input panics or runs
//! away (1), nothing non-finite is ever written (2), what can be checked is checked before
//! tracing and a run writes all of its outputs or none (3), messages blame the right thing (4),
//! signals stop a run with its results written and a distinct exit status (5), command-line
//! budgets are obeyed (6), the integrators agree (7), the console reads as a finished tool (8),
//! and the reference document covers every key and flag (9).

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::BASE;

const BIN: &str = env!("CARGO_BIN_EXE_photon");
const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// A fresh folder for one test.
fn dir(name: &str) -> common::TempDir {
    common::temp_dir(&format!("hardening-{name}"))
}

/// Writes `toml` as `scene.toml` in a fresh folder; returns the folder and the scene path.
fn scene_file(name: &str, toml: &str) -> (common::TempDir, PathBuf) {
    let d = dir(name);
    let scene = d.join("scene.toml");
    fs::write(&scene, toml).unwrap();
    (d, scene)
}

fn photon(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// Asserts exit status 2 with every one of `needles` in stderr and no panic.
fn assert_bad(o: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "expected exit 2\n{}", text(o));
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "stderr lacks `{n}`:\n{err}");
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

// ---- 1. Panics, aborts, unbounded allocation ----

#[test]
fn converge_on_a_scene_without_surfaces_is_refused_not_a_panic() {
    // Before: index out of bounds in converge.rs on the bundled luminaire scene.
    let out = dir("converge-luminaire");
    let o = photon(&["converge", &format!("{ROOT}/scenes/luminaire.toml"), "--budget", "1", "--out", s(&out)]);
    assert_bad(&o, &["no surface"]);
}

#[test]
fn converge_on_a_tally_no_photon_reaches_writes_finite_rows() {
    // A collimated lamp shining away from the only surface: its tally stays zero. Before: inf
    // and NaN rows, then an unbounded allocation in the plot.
    let toml = BASE
        .replace("power_w = 10", "power_w = 10\ndistribution = \"collimated\"")
        .replace("[[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]]", "[[0, 1, 0], [0, 1, 1], [1, 1, 1], [1, 1, 0]]");
    let (d, scene) = scene_file("converge-dark", &toml);
    let o = photon(&["converge", s(&scene), "--budget", "1", "--out", s(&d.join("out"))]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("no photon reached"), "{}", text(&o));
    let csv = fs::read_to_string(d.join("out/convergence.csv")).unwrap();
    assert!(csv.lines().count() >= 2, "{csv}");
    for v in csv.lines().skip(1).flat_map(|l| l.split(',')).filter(|v| !v.is_empty()) {
        assert!(v.parse::<f64>().is_ok_and(f64::is_finite), "non-finite `{v}` in\n{csv}");
    }
    assert!(d.join("out/convergence.png").exists());
}

#[test]
fn camera_resolutions_whose_product_overflows_are_refused() {
    // Before: [2^33, 2^31] panicked on the size check; [2^32, 2^32] wrapped to "0×0 pixels".
    for res in ["[8589934592, 2147483648]", "[4294967296, 4294967296]"] {
        let toml = format!(
            "{BASE}\n[camera]\nposition = [0.5, 0.5, 3]\nlook_at = [0.5, 0.5, 0]\nfov_deg = 40\nresolution = {res}\n"
        );
        let (_dir, scene) = scene_file("resolution", &toml);
        assert_bad(&photon(&["info", s(&scene)]), &["`camera.resolution`", "pixels"]);
    }
}

// ---- 2. Non-finite results ----

#[test]
fn powers_too_large_for_finite_results_are_refused_naming_the_key() {
    // Before: each exited 0 with `null` in flux.json and inf/NaN in flux.csv.
    let ies = fs::read_to_string(format!("{ROOT}/tests/data/ies/isotropic.ies")).unwrap();
    let cases: [(&str, String, &str); 4] = [
        ("power", BASE.replace("power_w = 10", "power_w = 1e307"), "`lights[0].power_w`"),
        ("radiance", BASE.replace("power_w = 10", "radiance = 1e306"), "`lights[0].radiance`"),
        ("blackbody", BASE.replace("power_w = 10", "power_w = 10\nspectrum = { blackbody_k = 1e300 }"), "blackbody_k"),
        (
            "ies",
            BASE.replace("power_w = 10", "distribution = { ies = \"lamp.ies\" }").replace(
                "{ type = \"quad\", corners = [[0, 1, 0], [1, 1, 0], [1, 1, 1], [0, 1, 1]] }",
                "{ type = \"point\", position = [0.5, 1, 0.5] }\ndirection = [0, -1, 0]",
            ),
            "candela value",
        ),
    ];
    for (name, toml, key) in cases {
        let (d, scene) = scene_file(&format!("huge-{name}"), &toml);
        // A candela table of 1e308 cd: every value of the isotropic test file scaled up.
        let huge = ies.replace("100 100 100", "1e308 1e308 1e308");
        assert_ne!(huge, ies);
        fs::write(d.join("lamp.ies"), huge).unwrap();
        let out = d.join("out");
        let o = photon(&["run", s(&scene), "--photons", "20000", "--out", s(&out), "--quiet"]);
        assert_bad(&o, &[key]);
        assert!(!out.exists(), "{name}: a refused run wrote {}", out.display());
    }
}

#[test]
fn an_image_beyond_f32_is_refused_and_nothing_is_written() {
    // The Sun's power from a 13 cm lamp: Y_var overflowed f32 to inf in image.exr, exit 0.
    let toml = fs::read_to_string(format!("{ROOT}/scenes/cornell_box.toml"))
        .unwrap()
        .replace("../spectra/", &format!("{ROOT}/spectra/"))
        .replace("meshes/", &format!("{ROOT}/scenes/meshes/"))
        .replace("resolution = [512, 512]", "resolution = [32, 32]");
    let toml = regex_replace_power(&toml, "3.828e26");
    let (d, scene) = scene_file("sun", &toml);
    let out = d.join("out");
    let o = photon(&["run", s(&scene), "--photons", "50000", "--out", s(&out), "--quiet"]);
    assert_bad(&o, &["32-bit", "power_w"]);
    assert!(!out.exists());
}

/// `toml` with its `power_w = …` line set to `value`.
fn regex_replace_power(toml: &str, value: &str) -> String {
    toml.lines()
        .map(|l| if l.trim_start().starts_with("power_w") { format!("power_w = {value}") } else { l.to_string() })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn non_positive_or_non_finite_references_are_bad_input() {
    let plates = format!("{ROOT}/scenes/parallel_plates.toml");
    for r in ["nan", "inf", "0", "-5"] {
        let reference = format!("--reference={r}");
        let o = photon(&["converge", &plates, "--budget", "1", &reference, "--out", "/tmp/never"]);
        assert_bad(&o, &["--reference"]);
    }
    let toml = format!("{BASE}\n[reference]\nsurface = \"floor\"\nincident_w = 0\n");
    let (_dir, scene) = scene_file("reference-zero", &toml);
    assert_bad(&photon(&["info", s(&scene)]), &["`reference.incident_w`"]);
}

// ---- 3. Checked before tracing; all outputs or none ----

/// Runs `args` and asserts it is refused within `limit`: the checks come before the photons.
fn assert_refused_quickly(args: &[&str], limit: Duration, needles: &[&str]) {
    let start = Instant::now();
    let o = photon(args);
    assert_bad(&o, needles);
    assert!(start.elapsed() < limit, "refused only after {:?}: the run traced first", start.elapsed());
}

#[test]
fn output_problems_are_found_before_any_photon_is_traced() {
    // Before: each failed with exit 1 after the whole run, leaving flux.json beside no map.
    // 10^9 photons take minutes: a refusal within seconds was decided before tracing.
    let many = "1000000000";
    let long = "a".repeat(300);
    let toml = BASE.replace("name = \"floor\"", &format!("name = \"{long}\"\nmap = {{ resolution = [4, 4] }}"));
    let (d, scene) = scene_file("long-name", &toml);
    let out = d.join("out");
    assert_refused_quickly(
        &["run", s(&scene), "--photons", many, "--out", s(&out)],
        Duration::from_secs(20),
        &["too long"],
    );
    assert!(!out.exists());

    let (d, scene) = scene_file("out-is-file", BASE);
    let file = d.join("file");
    fs::write(&file, "x").unwrap();
    let args = ["run", s(&scene), "--photons", many, "--out", s(&file)];
    assert_refused_quickly(&args, Duration::from_secs(20), &["is a file"]);
    let beneath = file.join("sub");
    let args = ["run", s(&scene), "--photons", many, "--out", s(&beneath)];
    assert_refused_quickly(&args, Duration::from_secs(20), &["--out"]);
    assert_eq!(fs::read_to_string(&file).unwrap(), "x");
    // A scene refused after its output folder was prepared leaves no folder behind, not even the
    // parents made for it (converge checks the scene's surfaces before anything is created).
    let deep = d.join("a/b/c");
    let luminaire = format!("{ROOT}/scenes/luminaire.toml");
    assert_bad(&photon(&["converge", &luminaire, "--budget", "1", "--out", s(&deep)]), &["no surface"]);
    assert!(!d.join("a").exists(), "converge left {} behind", d.join("a").display());
}

#[test]
fn a_rerun_removes_the_outputs_it_did_not_write_and_keeps_other_files() {
    let toml = format!(
        "{}\n[camera]\nposition = [0.5, 0.5, 3]\nlook_at = [0.5, 0.5, 0]\nfov_deg = 40\nresolution = [16, 16]\n",
        BASE.replace("name = \"floor\"", "name = \"floor\"\nmap = { resolution = [4, 4] }")
    );
    let (d, scene) = scene_file("rerun", &toml);
    let out = d.join("out");
    // The user's own files, named as photon's outputs could be: no run listed them, so they stay.
    fs::create_dir_all(out.join("maps")).unwrap();
    fs::write(out.join("spectrum_mine.csv"), "mine").unwrap();
    fs::write(out.join("maps/mine.png"), "mine").unwrap();
    let o = photon(&["run", s(&scene), "--photons", "20000", "--out", s(&out), "--quiet"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    for f in ["flux.json", "image.exr", "image.png", "maps/floor.exr", "maps/floor.png"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    fs::write(out.join("notes.txt"), "mine").unwrap();
    // Without the map and the image: the old ones must go, the user's file must stay.
    let toml2 = toml.replace("map = { resolution = [4, 4] }", "");
    fs::write(&scene, toml2).unwrap();
    let o = photon(&["run", s(&scene), "--photons", "20000", "--out", s(&out), "--quiet", "--no-image"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    for f in ["image.exr", "image.png", "maps/floor.exr", "maps/floor.png"] {
        assert!(!out.join(f).exists(), "stale {f} left from the earlier run");
    }
    for f in ["notes.txt", "spectrum_mine.csv", "maps/mine.png"] {
        assert_eq!(fs::read_to_string(out.join(f)).unwrap(), "mine", "{f}");
    }
    let leftovers: Vec<_> = fs::read_dir(&d).unwrap().chain(fs::read_dir(&out).unwrap()).flatten().collect();
    assert!(
        leftovers.iter().all(|e| !e.file_name().to_string_lossy().contains("staging")),
        "a staging folder was left behind"
    );
}

// ---- 4. Messages that blame the right thing ----

#[test]
fn a_far_point_light_is_blamed_not_the_surface_it_unbalances() {
    // Before: "`surfaces[0].shape`: ... too thin for its size".
    let toml = format!(
        "{BASE}\n[[lights]]\nname = \"far\"\nshape = {{ type = \"point\", position = [1e20, 1, 0.5] }}\npower_w = 1\n"
    );
    let (_dir, scene) = scene_file("far-point", &toml);
    assert_bad(&photon(&["info", s(&scene)]), &["`lights[1].shape`"]);
    // Within range but far enough to leave the floor unresolvable in f32: the scene's extent is named.
    let toml = toml.replace("1e20", "1e13");
    let (_dir, scene) = scene_file("far-point-2", &toml);
    assert_bad(&photon(&["info", s(&scene)]), &["from the centre of the scene"]);
}

#[test]
fn a_camera_far_out_is_blamed_for_its_position() {
    // Before: blamed `camera.up`.
    let toml =
        format!("{BASE}\n[camera]\nposition = [-1e300, -1e300, -1e300]\nlook_at = [0.5, 0.5, 0]\nfov_deg = 40\n");
    let (_dir, scene) = scene_file("far-camera", &toml);
    assert_bad(&photon(&["info", s(&scene)]), &["`camera.position`"]);
}

#[test]
fn a_spectrum_file_without_a_header_keeps_its_first_row() {
    // Before: the first row was taken for a header and lost (the floor absorbed 1.89 W, not 0.97).
    let with_header = "wavelength_nm,value\n360,0.2\n830,0.2\n";
    let without = "360,0.2\n830,0.2\n";
    let mut absorbed = Vec::new();
    for (name, csv) in [("header", with_header), ("no-header", without)] {
        let toml = BASE.replace("reflectance = 0.5", "reflectance = { file = \"r.csv\" }");
        let (d, scene) = scene_file(&format!("csv-{name}"), &toml);
        fs::write(d.join("r.csv"), csv).unwrap();
        let out = d.join("out");
        let o = photon(&["run", s(&scene), "--photons", "20000", "--out", s(&out), "--quiet"]);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        absorbed.push(fs::read_to_string(out.join("flux.json")).unwrap());
    }
    assert_eq!(absorbed[0], absorbed[1], "the same table with and without a header gave different results");
}

#[test]
fn non_utf8_bytes_in_mesh_comments_are_harmless_and_elsewhere_named_by_line() {
    let toml = BASE.replace(
        "shape = { type = \"quad\", corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]] }",
        "shape = { type = \"mesh\", file = \"m.obj\" }",
    );
    let (d, scene) = scene_file("latin1", &toml);
    // "# 20 °C" in Latin-1: 0xB0 is not UTF-8. Before: refused without a line number.
    let mut obj = b"# measured at 20 \xb0C\nv 0 0 0\nv 0 0 1\nv 1 0 1\nf 1 2 3\n".to_vec();
    fs::write(d.join("m.obj"), &obj).unwrap();
    let o = photon(&["info", s(&scene)]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    obj.extend_from_slice(b"v 1 0 \xb0\n");
    fs::write(d.join("m.obj"), &obj).unwrap();
    assert_bad(&photon(&["info", s(&scene)]), &["m.obj:6"]);
}

#[test]
fn thousands_of_degenerate_faces_give_one_warning() {
    let mut obj = String::from("v 0 0 0\nv 0 0 1\nv 1 0 1\nv 2 0 2\nf 1 2 3\n");
    for _ in 0..5000 {
        obj.push_str("f 1 1 2\n");
    }
    let toml = BASE.replace(
        "shape = { type = \"quad\", corners = [[0, 0, 0], [0, 0, 1], [1, 0, 1], [1, 0, 0]] }",
        "shape = { type = \"mesh\", file = \"m.obj\" }",
    );
    let (d, scene) = scene_file("degenerate", &toml);
    fs::write(d.join("m.obj"), obj).unwrap();
    let o = photon(&["info", s(&scene)]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().filter(|l| l.contains("zero area")).count(), 1, "{err}");
    assert!(err.contains("and 4999 more"), "{err}");
}

#[test]
fn unsupported_dielectric_geometry_is_refused() {
    // Each ran silently before although the README says it is not supported (or, nested, is
    // declared inconsistently).
    let glass = "[materials.glass]\ntype = \"dielectric\"\nior = 1.5\n";
    let lamp = "[[lights]]\nname = \"lamp\"\nshape = { type = \"point\", position = [0, 3, 0] }\npower_w = 1\n";
    let surface =
        |name: &str, shape: &str| format!("[[surfaces]]\nname = \"{name}\"\nmaterial = \"glass\"\nshape = {shape}\n");
    let cases = [
        ("open", surface("pane", "{ type = \"quad\", corners = [[0,0,0],[0,0,1],[1,0,1],[1,0,0]] }"), "not closed"),
        (
            // Nested, but the inner glass says its outside is air (outside_ior 1).
            "nested",
            surface("outer", "{ type = \"sphere\", center = [0,0,0], radius = 1 }")
                + &surface("inner", "{ type = \"sphere\", center = [0,0,0], radius = 0.5 }"),
            "needs outside_ior equal to the ior of material \"glass\"",
        ),
        (
            "touching",
            // Touching over part of a face: the triangles there do not match (adjacent
            // dielectrics with matching faces are joined instead).
            surface("left", "{ type = \"box\", min = [0,0,0], max = [1,1,1] }")
                + &surface("right", "{ type = \"box\", min = [1,-1,0], max = [2,1,1] }"),
            "do not match vertex for vertex",
        ),
        (
            // Adjacent (matching faces) but one rough: the joined interface would need both.
            "adjacent-rough",
            surface("left", "{ type = \"box\", min = [0,0,0], max = [1,1,1] }")
                + "[[surfaces]]\nname = \"right\"\nmaterial = \"frosted\"\nshape = { type = \"box\", min = [1,0,0], max = [2,1,1] }\n"
                + "[materials.frosted]\ntype = \"dielectric\"\nior = 1.5\nroughness = 0.2\n",
            "must both be smooth",
        ),
        (
            "camera-inside",
            surface("ball", "{ type = \"sphere\", center = [0,0,0], radius = 1 }")
                + "[camera]\nposition = [0, 0, 0.2]\nlook_at = [0, 0, -1]\nfov_deg = 40\nresolution = [8, 8]\n",
            "`camera.position`",
        ),
    ];
    for (name, body, needle) in cases {
        let (_dir, scene) = scene_file(&format!("glass-{name}"), &format!("{glass}{lamp}{body}"));
        assert_bad(&photon(&["info", s(&scene)]), &[needle]);
    }
    // A closed mesh with one face listed twice (three triangles on an edge): not a manifold.
    let (d, scene) = scene_file(
        "glass-non-manifold",
        &format!("{glass}{lamp}{}", surface("m", "{ type = \"mesh\", file = \"t.obj\" }")),
    );
    let tetra = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\nf 1 4 3\n";
    fs::write(d.join("t.obj"), tetra).unwrap();
    assert_bad(&photon(&["info", s(&scene)]), &["manifold"]);
    // A mesh wound inward: its inside would be the world outside it.
    let (d, scene) =
        scene_file("glass-inward", &format!("{glass}{lamp}{}", surface("m", "{ type = \"mesh\", file = \"t.obj\" }")));
    let inward = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 4 2\nf 2 4 3\nf 1 3 4\n";
    fs::write(d.join("t.obj"), inward).unwrap();
    assert_bad(&photon(&["info", s(&scene)]), &["point inward"]);
    // A mirroring (negative) scale keeps the normals outward (the winding is swapped back), so
    // a mirrored glass box is accepted.
    let mirrored =
        surface("box", "{ type = \"box\", min = [0,0,0], max = [1,1,1], transform = { scale = [-1, 1, 1] } }");
    let (_dir, scene) = scene_file("glass-mirrored", &format!("{glass}{lamp}{mirrored}"));
    let o = photon(&["info", s(&scene)]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    // The bundled glass scene passes every check.
    let o = photon(&["info", &format!("{ROOT}/scenes/glass.toml")]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
}

// ---- 5. Signals and exit status ----

/// Starts `args`, sends `signal` after `after`, and returns its output.
fn signalled(args: &[&str], signal: &str, after: Duration) -> Output {
    let child = Command::new(BIN).args(args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    std::thread::sleep(after);
    let sent = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
    assert!(sent.success());
    child.wait_with_output().unwrap()
}

#[test]
fn sigterm_and_sigint_stop_a_run_with_its_results_written_and_exit_3() {
    // Before: SIGTERM killed the run with nothing written; Ctrl-C exited 0.
    for signal in ["TERM", "INT"] {
        let out = dir(&format!("signal-{signal}"));
        let furnace = format!("{ROOT}/scenes/furnace.toml");
        let args = ["run", &furnace, "--photons", "10000000000", "--out", s(&out), "--quiet"];
        let o = signalled(&args, signal, Duration::from_millis(2500));
        assert_eq!(o.status.code(), Some(3), "SIG{signal}\n{}", text(&o));
        let run = fs::read_to_string(out.join("run.json")).unwrap();
        assert!(run.contains("\"stop_reason\": \"interrupted\""), "{run}");
        assert!(out.join("flux.json").exists());
    }
}

#[test]
fn a_second_signal_stops_at_once_and_leaves_no_staging_folder() {
    // Two Ctrl-Cs back to back: the first asks the run to stop and write, the second (arriving
    // while it writes the 512² image) ends the process at once with status 130. Either way the
    // outputs are whole or absent, and no hidden staging folder is left behind.
    let d = dir("second-signal");
    let out = d.join("out");
    let cornell = format!("{ROOT}/scenes/cornell_box.toml");
    let child = Command::new(BIN)
        .args(["run", &cornell, "--photons", "10000000000", "--quiet", "--out", s(&out)])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(2500));
    for _ in 0..2 {
        assert!(Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap().success());
    }
    let o = child.wait_with_output().unwrap();
    match o.status.code() {
        Some(130) => assert!(!out.exists(), "a half-moved output folder after status 130"),
        Some(3) => assert!(out.join("run.json").exists() && out.join("image.exr").exists()),
        other => panic!("exit {other:?}\n{}", text(&o)),
    }
    let left: Vec<_> = fs::read_dir(&d).unwrap().flatten().map(|e| e.file_name()).collect();
    assert!(left.iter().all(|n| !n.to_string_lossy().contains("staging")), "left behind: {left:?}");
}

#[test]
fn converge_and_validate_keep_what_they_have_on_a_signal() {
    let out = dir("signal-converge");
    let cornell = format!("{ROOT}/scenes/cornell_box.toml");
    let args = ["converge", &cornell, "--budget", "60", "--out", s(&out), "--no-image"];
    let o = signalled(&args, "INT", Duration::from_secs(4));
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(text(&o).contains("interrupted"), "{}", text(&o));
    let csv = fs::read_to_string(out.join("convergence.csv")).unwrap();
    assert!(csv.lines().count() >= 3, "{csv}");

    // validate: signalled once its first case is printed (cases stream out as they finish), so
    // the test does not depend on how fast the machine is.
    use std::io::BufRead as _;
    let mut child = Command::new(BIN).args(["validate"]).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let mut seen = Vec::new();
    for line in lines.by_ref() {
        let line = line.unwrap();
        let done = line.contains("PASS") || line.contains("FAIL");
        seen.push(line);
        if done {
            break;
        }
    }
    assert!(seen.iter().any(|l| l.contains("PASS")), "no case was reported as it finished:\n{}", seen.join("\n"));
    let sent = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(sent.success());
    seen.extend(lines.map(|l| l.unwrap()));
    let status = child.wait().unwrap();
    let stdout = seen.join("\n");
    assert_eq!(status.code(), Some(3), "{stdout}");
    assert!(stdout.contains("interrupted") && stdout.contains("passed"), "{stdout}");
}

// ---- 6. Budgets ----

fn run_json(out: &Path) -> serde_json::Value {
    serde_json::from_str(&fs::read_to_string(out.join("run.json")).unwrap()).unwrap()
}

#[test]
fn command_line_budgets_are_not_capped_by_the_scenes_photon_count() {
    // Before: `--time 3` stopped after the scene's photons, at 1 s; `--rel-error` likewise.
    let toml = format!("[simulation]\nphotons = 16384\n{BASE}");
    let (d, scene) = scene_file("budget", &toml);
    let out = d.join("time");
    let o = photon(&["run", s(&scene), "--time", "1.5", "--out", s(&out), "--quiet"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let r = run_json(&out);
    assert_eq!(r["stop_reason"], "time", "{r}");
    assert!(r["photons"].as_u64().unwrap() > 16384, "{r}");

    let out = d.join("rel");
    let o = photon(&["run", s(&scene), "--rel-error", "0.002", "--out", s(&out), "--quiet"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let r = run_json(&out);
    assert_eq!(r["stop_reason"], "rel_error", "{r}");
    assert!(r["photons"].as_u64().unwrap() > 16384, "{r}");
    // A command-line photon count still caps.
    let out = d.join("capped");
    let o = photon(&["run", s(&scene), "--rel-error", "1e-6", "--photons", "40000", "--out", s(&out), "--quiet"]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert_eq!(run_json(&out)["photons"].as_u64(), Some(40000));
}

#[test]
fn converge_fits_its_reference_run_into_the_budget() {
    // Before: `converge --budget 8` took 16 s (the reference run had a budget of its own).
    let out = dir("converge-budget");
    let start = Instant::now();
    let o = photon(&[
        "converge",
        &format!("{ROOT}/scenes/cornell_box.toml"),
        "--budget",
        "4",
        "--no-image",
        "--out",
        s(&out),
    ]);
    let took = start.elapsed().as_secs_f64();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    // Half each: the run and the reference run's own time budgets, as printed.
    assert!(text(&o).contains("budget: 2.000 s for the run + 2.000 s for the reference run"), "{}", text(&o));
    // Each run stops within a few hundredths of its budget (the time-budget test in
    // tests/scenes.rs); loading, pilots and writing add well under 2 s, while the old code took
    // two full budgets (8 s) plus the same.
    assert!(took < 7.5, "converge --budget 4 took {took:.1} s");
}

// ---- 7. Integrators agree ----

#[test]
fn flux_json_does_not_depend_on_the_integrator_or_the_image() {
    // Before: --integrator path|bdpt flipped the estimator pilot from analog to expected.
    let cornell = format!("{ROOT}/scenes/cornell_box.toml");
    let base = dir("integrator-flux");
    let mut fluxes = Vec::new();
    for (name, extra) in [
        ("light", vec![]),
        ("path", vec!["--integrator", "path"]),
        ("bdpt", vec!["--integrator", "bdpt"]),
        ("none", vec!["--no-image"]),
    ] {
        let out = base.join(name);
        let mut args = vec!["run", &cornell, "--photons", "32768", "--out", s(&out), "--quiet"];
        args.extend(extra);
        let o = photon(&args);
        assert_eq!(o.status.code(), Some(0), "{}", text(&o));
        fluxes.push((name, fs::read(out.join("flux.json")).unwrap()));
    }
    for (name, f) in &fluxes[1..] {
        assert!(f == &fluxes[0].1, "flux.json with {name} differs from the light tracer's");
    }
}

// ---- 8. Console and help ----

#[test]
fn the_console_speaks_words_not_internals() {
    // The floor absorbs all, so nothing reaches the surface above the lamp (which emits down).
    let toml = BASE.replace(
        "name = \"floor\"\nmaterial = \"white\"",
        "name = \"floor\"\nmaterial = \"absorber\"\nmap = { resolution = [4, 4] }",
    );
    let (d, scene) = scene_file("console", &toml);
    let extra = "[[surfaces]]\nname = \"hidden\"\nmaterial = \"white\"\nshape = { type = \"quad\", corners = [[5,5,5],[5,5,6],[6,5,6],[6,5,5]] }\n";
    fs::write(&scene, format!("{}{extra}", fs::read_to_string(&scene).unwrap())).unwrap();
    let o = photon(&["run", s(&scene), "--photons", "20000", "--out", s(&d.join("out"))]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(stdout.contains("stopped by the photon count"), "{stdout}");
    assert!(!stdout.contains("Photons") && !stdout.contains("RelError"), "{stdout}");
    assert!(stdout.contains("maps/floor.exr"), "written maps are not named:\n{stdout}");
    // A surface nothing reached has no relative error: "-", not 0 (which reads as converged).
    let hidden = stdout.lines().find(|l| l.starts_with("hidden")).unwrap();
    assert!(hidden.split_whitespace().any(|w| w == "-") && !hidden.contains("0.00e0"), "{hidden}");

    let help = String::from_utf8_lossy(&photon(&["run", "--help"]).stdout).into_owned();
    for needle in ["scene file", "default: the scene's", "Exit status", "3 stopped early"] {
        assert!(help.contains(needle), "`run --help` lacks `{needle}`:\n{help}");
    }
    assert!(!help.contains("::"), "`run --help` names internal items:\n{help}");

    // info shows a point light where the scene file put it (the office's downlights).
    let info = String::from_utf8_lossy(&photon(&["info", &format!("{ROOT}/scenes/office.toml")]).stdout).into_owned();
    let office = fs::read_to_string(format!("{ROOT}/scenes/office.toml")).unwrap();
    let first = office.lines().find(|l| l.contains("type = \"point\"")).unwrap();
    let position = first.split("position = [").nth(1).unwrap().split(']').next().unwrap();
    let coords: Vec<f64> = position.split(',').map(|v| v.trim().parse().unwrap()).collect();
    let shown = format!("point at [{}, {}, {}]", coords[0], coords[1], coords[2]);
    assert!(info.contains(&shown), "info lacks `{shown}`:\n{info}");
}

#[test]
fn a_scene_of_point_lights_and_detectors_prints_no_empty_table() {
    let out = dir("luminaire-table");
    let o = photon(&["run", &format!("{ROOT}/scenes/luminaire.toml"), "--photons", "20000", "--out", s(&out)]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(!stdout.contains("incident W"), "an empty table header:\n{stdout}");
    assert!(stdout.contains("farfield_"), "the far-field files are not named:\n{stdout}");
}

// ---- 9. The reference document ----

#[test]
fn the_reference_names_every_flag_and_every_scene_key() {
    let reference = fs::read_to_string(format!("{ROOT}/docs/reference.md")).unwrap();
    for command in ["run", "info", "validate", "converge", "merge"] {
        let help = String::from_utf8_lossy(&photon(&[command, "--help"]).stdout).into_owned();
        for flag in help.split_whitespace().filter(|w| w.starts_with("--") && w.len() > 2) {
            let flag = flag.trim_end_matches(|c: char| !c.is_ascii_alphanumeric() && c != '-');
            if flag != "--help" && flag != "--version" {
                assert!(reference.contains(flag), "docs/reference.md lacks `{command} {flag}`");
            }
        }
    }
    // Every key the loader accepts: the string lists of its `allow(&[...])` calls.
    let loader = fs::read_to_string(format!("{ROOT}/src/scene/load.rs")).unwrap()
        + &fs::read_to_string(format!("{ROOT}/src/scene/shapes.rs")).unwrap();
    let mut keys = 0;
    let mut missing = Vec::new();
    for list in loader.split("allow(&[").skip(1) {
        let list = list.split("])").next().unwrap();
        for key in list.split(',').map(|k| k.trim().trim_matches('"')).filter(|k| !k.is_empty()) {
            keys += 1;
            if !reference.contains(&format!("`{key}`")) {
                missing.push(key);
            }
        }
    }
    assert!(keys > 40, "found only {keys} keys: the loader's key lists were not read");
    assert!(missing.is_empty(), "docs/reference.md lacks the keys {missing:?}");
}

#[test]
fn a_mapped_surface_named_beyond_latin1_writes_its_maps() {
    // EXR header text holds Latin-1 only: the layer takes the name's file stem instead of
    // panicking (found by tests/fuzz.rs with a CJK name on the office floor).
    let toml = common::BASE
        .replace("name = \"floor\"", "name = \"床面漢字\"")
        .replace("material = \"white\"\n", "material = \"white\"\nmap = { resolution = [2, 2] }\n");
    let (d, scene) = scene_file("cjk-map", &(toml + "\n[simulation]\nphotons = 2000\n"));
    let out = d.join("out");
    let o = photon(&["run", s(&scene), "--out", s(&out), "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        out.join("maps").join("____.exr").is_file(),
        "{:?}",
        std::fs::read_dir(out.join("maps")).map(|d| d.count())
    );
}
