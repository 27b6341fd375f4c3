//! Volume detectors (`[[detectors]] type = "volume"`): the track-length fluence rate and the
//! absorbed power density per voxel against closed forms, and the two estimators against each
//! other (absorbed = μa·φ in a scattering medium).

mod common;
use common::assert_z;

use photon::run::{apply_options, simulate, RunOptions, RunResult};
use photon::scene::Scene;

fn run(toml: &str, photons: u64, seed: u64) -> (Scene, RunResult) {
    let mut s = common::scene(toml);
    let opts = RunOptions {
        photons: Some(photons),
        seed: Some(seed),
        threads: Some(2),
        transport: common::EXPECTED,
        ..Default::default()
    };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &std::sync::atomic::AtomicBool::new(false)).unwrap();
    (s, r)
}

#[test]
fn a_beam_through_an_absorbing_slab_gives_beer_lambert_per_voxel_exactly() {
    // 1 W down the axis of a 1 cm slab with μa = 1 cm⁻¹, voxels 1 × 1 × 0.25 cm around it. The
    // weight decays as e^{−s/cm}, so layer [a, b] (depth, cm) holds
    //   fluence rate = ∫ₐᵇ e^{−s} ds / V,  absorbed density = (e^{−a} − e^{−b}) / V,
    // with V = 0.25 cm³. Expected-value transport makes every history the same: exact (to the
    // f32 tracer's path lengths).
    let toml = r#"[scene]
unit = "cm"
[media.ink]
absorption_per_m = 100
[materials.slab]
type = "dielectric"
ior = 1.0
medium = "ink"
[[surfaces]]
name = "slab"
material = "slab"
shape = { type = "box", min = [-2, -2, -1], max = [2, 2, 0] }
[[lights]]
name = "beam"
shape = { type = "quad", corners = [[-0.001, -0.001, 0.1], [-0.001, 0.001, 0.1], [0.001, 0.001, 0.1], [0.001, -0.001, 0.1]] }
distribution = "collimated"
power_w = 1
[[detectors]]
type = "volume"
name = "column"
min = [-0.5, -0.5, -1]
max = [0.5, 0.5, 0]
resolution = [1, 1, 4]
"#;
    let (s, r) = run(toml, 4000, 1);
    let v = &photon::output::volume::estimates(&s, &r)[0];
    let volume = 0.25e-6;
    for k in 0..4 {
        // Voxel k spans z from −1 + k/4 to −1 + (k + 1)/4 cm: depths a = 0.75 − k/4, b = a + 0.25.
        let a = 0.75 - 0.25 * k as f64;
        let b = a + 0.25;
        // Per metre: s in m, μ = 100 /m; ∫ e^{−100 s} ds = (e^{−100a'} − e^{−100b'})/100.
        let lost = (-a).exp() - (-b).exp();
        let (fluence, absorbed) = (lost / 100.0 / volume, lost / volume);
        let (f, fa) = (v.fluence_w_m2[k].0, v.absorbed_w_m3[k].0);
        assert!((f / fluence - 1.0).abs() < 1e-5, "layer {k}: fluence {f} against {fluence}");
        assert!((fa / absorbed - 1.0).abs() < 1e-5, "layer {k}: absorbed {fa} against {absorbed}");
    }
}

#[test]
fn a_point_source_in_vacuum_gives_the_inverse_square_fluence_rate() {
    // 1 W isotropic at the origin, nothing else: φ(r) = P/(4πr²). Each voxel's estimate is the
    // voxel's mean of it, integrated here by the midpoint rule on 40³ points (error < 10⁻⁴,
    // far below the Monte Carlo error). |z| < 4 per voxel.
    let toml = r#"[[lights]]
name = "p"
shape = { type = "point", position = [0, 0, 0] }
power_w = 1
[[detectors]]
type = "volume"
name = "box"
min = [0.5, -0.5, -0.5]
max = [1.5, 0.5, 0.5]
resolution = [2, 2, 2]
"#;
    let (s, r) = run(toml, 400_000, 2);
    let v = &photon::output::volume::estimates(&s, &r)[0];
    let m = 40;
    for k in 0..2 {
        for j in 0..2 {
            for i in 0..2 {
                let lo = [0.5 + 0.5 * i as f64, -0.5 + 0.5 * j as f64, -0.5 + 0.5 * k as f64];
                let mut sum = 0.0;
                for a in 0..m {
                    for b in 0..m {
                        for c in 0..m {
                            let p = [a, b, c].map(|x| (x as f64 + 0.5) / m as f64 * 0.5);
                            let (x, y, z) = (lo[0] + p[0], lo[1] + p[1], lo[2] + p[2]);
                            sum += 1.0 / (4.0 * std::f64::consts::PI * (x * x + y * y + z * z));
                        }
                    }
                }
                let want = sum / (m * m * m) as f64;
                let (got, se) = v.fluence_w_m2[(k * 2 + j) * 2 + i];
                println!("voxel ({i}, {j}, {k}): {got:.5} ± {se:.5} W/m² against {want:.5}");
                assert_z(&format!("voxel ({i}, {j}, {k})"), got, want, se, 4.0);
                assert_eq!(v.absorbed_w_m3[(k * 2 + j) * 2 + i].0, 0.0, "nothing absorbs in vacuum");
            }
        }
    }
}

#[test]
fn in_a_scattering_slab_the_absorbed_density_is_mu_a_times_the_fluence_rate() {
    // The MCML tissue slab (μa 10 cm⁻¹) filling the grid: the collisions' deposits sum to the
    // medium's own absorbed power (the same scores), and μa·Σφ·V (track length) estimates the
    // same power independently: within 4 of the two standard errors added (a conservative bound
    // whatever their correlation).
    let toml = r#"[scene]
unit = "cm"
[media.tissue]
absorption_per_m = 1000
scattering_per_m = 9000
phase = { henyey_greenstein = 0.75 }
[materials.slab]
type = "dielectric"
ior = 1.0
medium = "tissue"
[[surfaces]]
name = "slab"
material = "slab"
shape = { type = "box", min = [-2, -2, -0.02], max = [2, 2, 0] }
[[lights]]
name = "beam"
shape = { type = "quad", corners = [[-0.001, -0.001, 0.1], [-0.001, 0.001, 0.1], [0.001, 0.001, 0.1], [0.001, -0.001, 0.1]] }
distribution = "collimated"
power_w = 1
[[detectors]]
type = "volume"
name = "slab"
min = [-2, -2, -0.02]
max = [2, 2, 0]
resolution = [4, 4, 2]
"#;
    let (s, r) = run(toml, 200_000, 3);
    let f = photon::output::flux(&s, &r);
    let v = &photon::output::volume::estimates(&s, &r)[0];
    let volume = s.volumes[0].voxel_volume_m3();
    let deposits: f64 = v.absorbed_w_m3.iter().map(|x| x.0 * volume).sum();
    let medium = &f.media[0];
    assert!((deposits - medium.absorbed_w).abs() < 1e-9, "deposits {deposits} against {medium:?}");
    let track: f64 = v.fluence_w_m2.iter().map(|x| x.0 * volume * 1000.0).sum();
    // The voxels' errors add in quadrature for the sum (an approximation: histories cross voxels).
    let track_se: f64 = v.fluence_w_m2.iter().map(|x| (x.1 * volume * 1000.0).powi(2)).sum::<f64>().sqrt();
    println!("absorbed {:.5} ± {:.5}; μa·Σφ·V {track:.5} ± {track_se:.5}", medium.absorbed_w, medium.absorbed_w_stderr);
    assert!(
        (track - medium.absorbed_w).abs() < 4.0 * (track_se + medium.absorbed_w_stderr),
        "track-length {track} against collision {}",
        medium.absorbed_w
    );
}

#[test]
fn the_npy_file_has_numpys_header_and_shape() {
    let bytes = photon::output::volume::npy(&[4, 3, 2, 1], (0..24).map(|x| x as f64));
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    assert_eq!((10 + len) % 64, 0, "the data starts on a 64-byte boundary");
    let header = std::str::from_utf8(&bytes[10..10 + len]).unwrap();
    assert!(header.starts_with("{'descr': '<f8', 'fortran_order': False, 'shape': (4, 3, 2, 1), }"), "{header}");
    assert!(header.ends_with('\n'));
    assert_eq!(bytes.len(), 10 + len + 24 * 8);
    assert_eq!(f64::from_le_bytes(bytes[10 + len + 8..10 + len + 16].try_into().unwrap()), 1.0);
}
