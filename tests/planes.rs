//! Work planes (`[[detectors]] type = "plane"`): an isotropic point source over a plane gives
//! each texel the flux I·Ω_texel (the texel average of I·cos³θ/h²), the plane does not block,
//! light crossing it from behind is not counted, and the uniformity figures follow.

use std::f64::consts::PI;
use std::path::Path;
use std::sync::atomic::AtomicBool;

use photon::output::maps::{MapEstimate, MapKind};
use photon::output::Flux;
use photon::run::{apply_options, simulate, RunOptions};

mod common;
use common::{assert_z, chi_square_bounds, scene};

const POWER_W: f64 = 4.0 * PI; // I = 1 W/sr
const H: f64 = 1.0;

/// A 1 W/sr point source at height H over a 2H × 2H work plane, and, optionally, a grey
/// Lambertian floor H/2 below the plane (whose light crosses the plane from behind).
fn toml(with_plane: bool, with_floor: bool) -> String {
    let mut t = format!(
        "[simulation]\nseed = 3\n\n[[lights]]\nname = \"bulb\"\nshape = {{ type = \"point\", position = [0, 0, {H}] }}\n\
         power_w = {POWER_W}\n"
    );
    if with_floor {
        t.push_str(
            "\n[materials.grey]\ntype = \"lambertian\"\nreflectance = 0.5\n\n[[surfaces]]\nname = \"floor\"\n\
             material = \"grey\"\nshape = { type = \"quad\", corners = [[-2, -2, -0.5], [2, -2, -0.5], [2, 2, -0.5], [-2, 2, -0.5]] }\n",
        );
    }
    if with_plane {
        t.push_str(
            "\n[[detectors]]\ntype = \"plane\"\nname = \"grid\"\ncorners = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]\n\
             resolution = [8, 8]\n",
        );
    }
    t
}

fn run(toml: &str, photons: u64) -> (Flux, Vec<MapEstimate>) {
    let mut s = scene(toml);
    let opts = RunOptions { photons: Some(photons), threads: Some(2), ..Default::default() };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &AtomicBool::new(false)).unwrap();
    (photon::output::flux(&s, &r), photon::output::maps::estimates(&s, &r))
}

/// Solid angle of the rectangle [x0, x1] × [y0, y1] in the plane z = 0 seen from (0, 0, H):
/// inclusion–exclusion over F(x, y) = atan(x·y / (H·√(H² + x² + y²))), the solid angle of the
/// rectangle from the foot of the perpendicular to (x, y).
fn solid_angle(x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
    let f = |x: f64, y: f64| (x * y / (H * (H * H + x * x + y * y).sqrt())).atan();
    f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)
}

#[test]
fn point_source_over_a_work_plane_gives_i_cos3_over_h2_per_texel() {
    // 2·10⁶ photons: a sixth cross the plane, ~5000 per texel, so each texel's relative error is
    // ~1.4 % and a 5 % deviation in one texel would stand at z ≈ 3.5 (and in the χ² far more).
    let (flux, maps) = run(&toml(true, true), 2_000_000);
    let grid = &maps[0];
    assert_eq!((grid.kind, grid.surface.as_str()), (MapKind::Plane, "grid"));
    let [nu, nv] = grid.resolution;
    let side = 2.0 * H / nu as f64;
    let texel_area = side * side;
    let (mut chi2, mut worst, mut e_min) = (0.0, 0.0f64, f64::INFINITY);
    for j in 0..nv {
        for i in 0..nu {
            let (x0, y0) = (-H + i as f64 * side, -H + j as f64 * side);
            // I = 1 W/sr: the texel's flux is its solid angle; per area the mean of cos³θ/h².
            let expected_w = solid_angle(x0, x0 + side, y0, y0 + side);
            e_min = e_min.min(expected_w / texel_area);
            let (w, se) = grid.flux_w[j * nu + i];
            let z = (w - expected_w) / se;
            chi2 += z * z;
            worst = worst.max(z.abs());
        }
    }
    // With 64 texels the 10⁻⁴ tails of χ²(64) are the bounds. The floor's reflected light
    // crosses the plane upward, from behind, and must not count: the floor reflects ~1.4 W, and
    // about a third of it (the view factor to the plane 0.5 m above) would add ~0.5 W to the
    // direct 2.09 W, hundreds of standard errors.
    let (lo, hi) = chi_square_bounds((nu * nv) as f64);
    assert!(chi2 > lo && chi2 < hi, "χ² = {chi2:.1} over {} texels, bounds ({lo:.1}, {hi:.1})", nu * nv);
    assert!(worst < 4.5, "a texel at |z| = {worst:.2}");

    // The whole plane's flux and the summary: E_mean is exact in closed form; E_min is the corner
    // texels' mean, biased low by the minimum over four noisy corners (about one standard
    // error), hence the bound of 4 on it and on U₀.
    let row = &flux.planes[0];
    let whole = solid_angle(-H, H, -H, H);
    assert!((whole - 2.0 * PI / 3.0).abs() < 1e-12, "a square of side 2h seen from h spans 2π/3 sr");
    assert_z("plane flux", row.incident_w, whole, row.incident_w_stderr, 4.0);
    let e = &row.irradiance_w_m2;
    let e_mean = whole / (4.0 * H * H);
    assert_z("E_mean", e.mean, e_mean, e.mean_stderr, 4.0);
    assert_z("E_min", e.min, e_min, e.min_stderr, 4.0);
    assert_z("U0", e.u0, e_min / e_mean, e.u0_stderr, 4.0);
    assert!(e.max > e.mean && e.mean > e.min && e.min > 0.0);
    assert_eq!(row.texels_counted, nu * nv);
    // The illuminance figures are the same in lux: one light, one efficacy.
    let k = row.incident_lm / row.incident_w;
    assert!((row.illuminance_lx.min / e.min - k).abs() < 1e-9 * k);
    assert!((row.illuminance_lx.u0 - e.u0).abs() < 1e-9);
}

#[test]
fn a_work_plane_blocks_nothing() {
    // Photons pass through a plane untouched, and testing them against it draws no random
    // number: the floor behind it reads the same bits with and without it.
    let (with, _) = run(&toml(true, true), 200_000);
    let (without, maps) = run(&toml(false, true), 200_000);
    assert!(maps.is_empty());
    let floor = |f: &Flux| {
        let s = &f.surfaces[0];
        (s.incident_w, s.incident_w_stderr, s.absorbed_w, f.ledger.escaped_w)
    };
    assert_eq!(floor(&with), floor(&without));
    assert!(with.surfaces[0].incident_w > 0.0 && with.planes[0].incident_w > 0.0);
}

#[test]
fn a_work_plane_writes_its_map_files() {
    let dir = common::temp_dir("plane-files");
    let path = dir.join("scene.toml");
    std::fs::write(&path, toml(true, false)).unwrap();
    let out = dir.join("out");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_photon"))
        .args(["run", path.to_str().unwrap(), "--photons", "20000", "--quiet", "--out", out.to_str().unwrap()])
        .status()
        .unwrap();
    assert!(status.success());
    for f in ["maps/grid.exr", "maps/grid.png", "flux.json"] {
        assert!(Path::new(&out).join(f).is_file(), "{f} missing");
    }
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("flux.json")).unwrap()).unwrap();
    let plane = &json["planes"][0];
    assert_eq!(plane["name"], "grid");
    for key in ["min", "min_stderr", "mean", "mean_stderr", "max", "max_stderr", "u0", "u0_stderr"] {
        assert!(plane["illuminance_lx"][key].as_f64().is_some_and(f64::is_finite), "illuminance_lx.{key}");
    }
}
