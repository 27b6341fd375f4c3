//! The light-traced film: normalisation against closed forms, colour, determinism, EXR layout.
//! Statistical bounds: 4 standard errors for a whole-image mean (false-failure chance 6e-5);
//! 6 for each of hundreds of pixels, whose Y_var comes from ~1000 film batches of 1024 photons,
//! so P(|z| > 6) ≈ 2e-9 per pixel keeps the whole image's false-failure chance below 1e-5.

mod common;
use common::{cornell_toml, temp_dir, TempDir};

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

struct Exr {
    width: usize,
    height: usize,
    channels: HashMap<String, Vec<f32>>,
}

fn read_exr(path: &Path) -> Exr {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .unwrap();
    let size = image.layer_data.size;
    let channels = image
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect::<Vec<f32>>()))
        .collect();
    Exr { width: size.0, height: size.1, channels }
}

/// Writes `toml` to a scene file, runs it, and returns the image and output folder.
fn render(name: &str, toml: &str, args: &[&str]) -> (Exr, TempDir) {
    let dir = temp_dir(name);
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, toml).unwrap();
    let out = dir.join("out");
    let o = Command::new(env!("CARGO_BIN_EXE_photon"))
        .arg("run")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .arg("--quiet")
        .args(args)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (read_exr(&out.join("image.exr")), dir)
}

/// Whole-image mean of Y and its standard error sqrt(ΣY_var)/n. Pixels are independent here
/// because in these scenes each photon splats at most once (emission, or one diffuse hit).
fn image_mean(img: &Exr) -> (f64, f64) {
    let y = &img.channels["Y"];
    let var = &img.channels["Y_var"];
    let n = y.len() as f64;
    let mean = y.iter().map(|&v| v as f64).sum::<f64>() / n;
    let se = var.iter().map(|&v| v as f64).sum::<f64>().sqrt() / n;
    (mean, se)
}

/// A Lambertian emitter of spectral radiance `c`, 40 m × 40 m, 10 m in front of the camera, so
/// it fills every field of view tested. `spectral` adds an unseen surface whose reflectance
/// varies with wavelength, forcing spectral transport, to test both colour paths.
fn emitter_scene(c: f64, fov: f64, res: [u32; 2], spectral: bool) -> String {
    let extra = if spectral {
        r#"
        [materials.tinted]
        type = "lambertian"
        reflectance = { table = [[360, 0.2], [830, 0.8]] }
        [[surfaces]]
        name = "behind"
        material = "tinted"
        shape = { type = "quad", corners = [[0, 0, -50], [1, 0, -50], [1, 1, -50], [0, 1, -50]] }
        "#
    } else {
        ""
    };
    format!(
        r#"
        [camera]
        position = [0, 0, 0]
        look_at = [0, 0, 1]
        up = [0, 1, 0]
        fov_deg = {fov}
        resolution = [{}, {}]
        [[lights]]
        name = "wall"
        # Corners ordered so the front normal points −z, toward the camera.
        shape = {{ type = "quad", corners = [[-20, -20, 10], [-20, 20, 10], [20, 20, 10], [20, -20, 10]] }}
        radiance = {c}
        {extra}
        "#,
        res[0], res[1]
    )
}

#[test]
fn emitter_of_radiance_c_reads_y_equals_c() {
    let c = 0.37;
    for integrator in ["light", "path", "bdpt"] {
        for (fov, res, spectral) in [(40.0, [32, 24], false), (70.0, [16, 16], false), (55.0, [24, 32], true)] {
            let what = format!("{integrator}, fov {fov} res {res:?} spectral {spectral}");
            let toml = emitter_scene(c, fov, res, spectral);
            let args = ["--photons", "1000000", "--integrator", integrator];
            let (img, dir) = render(&format!("norm{fov}{integrator}"), &toml, &args);
            assert_eq!((img.width, img.height), (res[0] as usize, res[1] as usize));
            let (mean, se) = image_mean(&img);
            // A grey path tracer sees the emitter directly and exactly: no variance at all; so
            // does the light tracer, which images a lamp in view from the camera with the
            // lamp's exact colour (`EmitterView`), grey or spectral.
            let exact = (integrator == "path" && !spectral) || integrator == "light";
            if se == 0.0 {
                assert!(exact, "{what}: zero standard error");
                assert!((mean - c).abs() <= 1e-6 * c, "{what}: mean Y {mean}, expected {c} exactly");
            } else {
                let z = (mean - c) / se;
                assert!(z.abs() < 4.0, "{what}: mean Y {mean}, expected {c}, stderr {se}, z {z:.2}");
            }
            for (i, (&y, &v)) in img.channels["Y"].iter().zip(&img.channels["Y_var"]).enumerate() {
                if v == 0.0 && exact {
                    assert!((y as f64 - c).abs() <= 1e-6 * c, "{what}: pixel {i} Y = {y}");
                    continue;
                }
                assert!(v > 0.0, "{what}: pixel {i} has no variance estimate");
                let z = (y as f64 - c) / (v as f64).sqrt();
                assert!(z.abs() < 6.0, "{what}: pixel {i} Y = {y}, z = {z:.2}");
            }
            std::fs::remove_dir_all(dir).unwrap();
        }
    }
}

#[test]
fn white_plate_under_collimated_light_reads_rho_e_over_pi() {
    // A collimated beam of power P through area A gives irradiance E = P/A on the plate below.
    // A Lambertian plate of reflectance ρ then has radiance L = ρE/π, spread over the flat
    // spectrum's Δλ = 830 − 360 nm: L_λ = ρE/(πΔλ), and Y = ∫ȳL_λ/∫ȳ = ρE/(πΔλ).
    let (rho, power, area, dl) = (0.6, 50.0, 4.0, 470.0);
    let toml = format!(
        r#"
        [camera]
        position = [0, 1, -3]
        look_at = [0, 0, 0]
        up = [0, 1, 0]
        fov_deg = 8
        resolution = [16, 16]
        [materials.white]
        type = "lambertian"
        reflectance = {rho}
        [[surfaces]]
        name = "plate"
        material = "white"
        shape = {{ type = "quad", corners = [[-3, 0, -3], [-3, 0, 3], [3, 0, 3], [3, 0, -3]] }}
        [[lights]]
        name = "beam"
        # 2 m × 2 m at y = 2, front normal −y: straight down onto the plate.
        shape = {{ type = "quad", corners = [[-1, 2, -1], [1, 2, -1], [1, 2, 1], [-1, 2, 1]] }}
        power_w = {power}
        distribution = "collimated"
        "#
    );
    // Light tracing and BDPT (whose light subpaths reach the plate). A path tracer cannot see a
    // collimated light at all: no light sample can be connected along a delta direction.
    for integrator in ["light", "bdpt"] {
        let (img, dir) =
            render(&format!("plate{integrator}"), &toml, &["--photons", "2000000", "--integrator", integrator]);
        let expected = rho * (power / area) / (std::f64::consts::PI * dl);
        let (mean, se) = image_mean(&img);
        let z = (mean - expected) / se;
        assert!(z.abs() < 4.0, "{integrator}: plate Y {mean}, expected {expected}, stderr {se}, z {z:.2}");
        std::fs::remove_dir_all(dir).unwrap();
    }
}

fn cornell(args: &[&str], name: &str) -> (Exr, TempDir) {
    let toml = cornell_toml().replace("resolution = [512, 512]", "resolution = [64, 64]");
    render(name, &toml, args)
}

#[test]
fn cornell_box_walls_have_their_colours_and_no_pixel_is_nan_or_negative() {
    let (img, dir) = cornell(&["--photons", "1000000"], "cornell");
    let (r, g, y) = (&img.channels["R"], &img.channels["G"], &img.channels["Y"]);
    for (name, ch) in &img.channels {
        assert!(ch.iter().all(|v| v.is_finite()), "channel {name} has a NaN or infinite pixel");
    }
    // Y is a luminance estimate built from non-negative splats: it can never be negative; R, G, B
    // are brought into the sRGB gamut at constant Y, so no channel may be negative either.
    assert!(y.iter().all(|&v| v >= 0.0), "negative Y");
    for c in ["R", "G", "B"] {
        assert!(img.channels[c].iter().all(|&v| v >= 0.0), "negative {c}");
    }
    assert!(img.channels["Y_var"].iter().all(|&v| v >= 0.0), "negative Y_var");
    // The red wall fills the image's left edge band at mid height, the green one the right.
    let band = |x0: usize, x1: usize| {
        let (mut sr, mut sg) = (0.0f64, 0.0f64);
        for row in 24..40 {
            for col in x0..x1 {
                sr += r[row * 64 + col] as f64;
                sg += g[row * 64 + col] as f64;
            }
        }
        (sr, sg)
    };
    let (lr, lg) = band(3, 10);
    let (rr, rg) = band(54, 61);
    assert!(lr > 0.0 && lg > 0.0 && rr > 0.0 && rg > 0.0, "{lr} {lg} {rr} {rg}");
    assert!(lr / lg > 2.0 * (rr / rg), "left wall R/G {} vs right wall {}", lr / lg, rr / rg);
    assert!(rg / rr > 2.0 * (lg / lr), "right wall G/R {} vs left wall {}", rg / rr, lg / lr);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn image_is_identical_for_one_and_two_threads_and_has_five_channels() {
    let (a, da) = cornell(&["--photons", "100000", "--threads", "1"], "t1");
    let (b, db) = cornell(&["--photons", "100000", "--threads", "2"], "t2");
    let mut names: Vec<&String> = a.channels.keys().collect();
    names.sort();
    assert_eq!(names, ["B", "G", "R", "Y", "Y_var"]);
    assert_eq!((a.width, a.height), (64, 64));
    for n in names {
        assert_eq!(a.channels[n].len(), 64 * 64);
        assert_eq!(a.channels[n], b.channels[n], "channel {n} differs between 1 and 2 threads");
    }
    assert_eq!(std::fs::read(da.join("out/image.exr")).unwrap(), std::fs::read(db.join("out/image.exr")).unwrap());
    assert!(da.join("out/image.png").is_file());
    std::fs::remove_dir_all(da).unwrap();
    std::fs::remove_dir_all(db).unwrap();
}

#[test]
fn no_image_flag_writes_no_image_and_records_no_camera_effect() {
    let (_, dir) = cornell(&["--photons", "20000"], "with");
    let scene = dir.join("scene.toml");
    let out = dir.join("noimg");
    let o = Command::new(env!("CARGO_BIN_EXE_photon"))
        .arg("run")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .args(["--photons", "20000", "--no-image", "--quiet"])
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(!out.join("image.exr").exists() && !out.join("image.png").exists());
    let run = std::fs::read_to_string(out.join("run.json")).unwrap();
    assert!(!run.contains("\"camera\""), "{run}");
    // The flux tallies do not depend on whether the film was on.
    assert_eq!(std::fs::read(out.join("flux.json")).unwrap(), std::fs::read(dir.join("out/flux.json")).unwrap());
    std::fs::remove_dir_all(dir).unwrap();
}

/// A run frees the digest lists it kept for reuse when it ends: held, they stayed allocated
/// between the runs of a process that runs many scenes (the Python module). In process, unlike
/// this file's other tests, so that it sees the run's own spare lists: the pool is global, so
/// another in-process run in this file would make the last assertion racy.
#[test]
fn a_run_releases_its_spare_pixel_lists_when_it_ends() {
    use photon::detectors::film::spare_pixel_list_bytes;
    use photon::run::{apply_options, simulate_observed, RunOptions};
    let toml = cornell_toml().replace("resolution = [512, 512]", "resolution = [64, 64]");
    let mut scene = common::scene(&toml);
    let opts = RunOptions { photons: Some(4 * 16_384), seed: Some(3), threads: Some(2), ..Default::default() };
    let chosen = apply_options(&mut scene, &opts).unwrap();
    let mut held_during = 0;
    let r = simulate_observed(&scene, &opts, &chosen, &std::sync::atomic::AtomicBool::new(false), &mut |p| {
        // Adding the held batches hands their lists to the spares.
        if let Some(film) = p.film {
            film.flush();
        }
        held_during = held_during.max(spare_pixel_list_bytes());
    })
    .unwrap();
    assert!(r.film.is_some());
    assert!(held_during > 0, "the run kept no list for reuse: the test would not see a release");
    assert_eq!(spare_pixel_list_bytes(), 0, "lists still held after the run");
}
