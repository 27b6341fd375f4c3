//! Closed-form checks of the transport: each compares a tally with an exact value using a
//! z-score bound of 4 at a fixed seed. Under a correct simulator |z| > 4 has probability 6e-5,
//! so a failure means a bias, not bad luck; the photon counts make a 1–2 % bias fail.

mod common;
use common::{assert_z, run, run_with, surface, ANALOG};

#[test]
fn closed_absorbing_box_absorbs_exactly_the_emitted_power() {
    let f = run(
        r#"
        [[surfaces]]
        name = "box"
        material = "absorber"
        shape = { type = "box", min = [-1, -2, -3], max = [1, 2, 3] }
        [[lights]]
        name = "bulb"
        shape = { type = "point", position = [0.3, 0.2, -0.1] }
        power_w = 7
        distribution = "isotropic"
        "#,
        100_000,
        1,
    );
    // Every photon must end in the box: nothing escapes through edges or vertices.
    assert_eq!(f.ledger.escaped_w, 0.0);
    assert_eq!(f.ledger.truncated_w, 0.0);
    let b = surface(&f, "box");
    assert!((b.absorbed_w - 7.0).abs() <= 1e-12 * 7.0, "absorbed {}", b.absorbed_w);
    assert!((b.incident_w - 7.0).abs() <= 1e-12 * 7.0, "incident {}", b.incident_w);
}

fn furnace(rho: f64) -> String {
    format!(
        r#"
        [materials.wall]
        type = "lambertian"
        reflectance = {rho}
        [[surfaces]]
        name = "sphere"
        material = "wall"
        shape = {{ type = "sphere", center = [0, 0, 0], radius = 2, subdivisions = 4 }}
        [[lights]]
        name = "bulb"
        shape = {{ type = "point", position = [0.5, -0.3, 0.2] }}
        power_w = 3
        distribution = "isotropic"
        "#
    )
}

#[test]
fn furnace_incident_is_power_over_one_minus_albedo() {
    // In a closed enclosure each photon arrives K times, K geometric with mean 1/(1−ρ), whatever
    // the shape: incident = P/(1−ρ). Every photon ends absorbed by the sphere: absorbed = P.
    for (rho, photons) in [(0.5, 100_000), (0.9, 60_000)] {
        // Both estimators, then the analog one's error against its own closed form.
        let expected_value = run(&furnace(rho), photons / 4, 4);
        let s = surface(&expected_value, "sphere");
        assert_z(
            &format!("furnace rho={rho} incident (expected)"),
            s.incident_w,
            3.0 / (1.0 - rho),
            s.incident_w_stderr,
            4.0,
        );
        assert!((s.absorbed_w - 3.0).abs() <= 1e-12 * 3.0, "absorbed {}", s.absorbed_w);
        let f = run_with(&furnace(rho), photons, 3, ANALOG);
        let s = surface(&f, "sphere");
        assert_z(&format!("furnace rho={rho} incident"), s.incident_w, 3.0 / (1.0 - rho), s.incident_w_stderr, 4.0);
        assert!((s.absorbed_w - 3.0).abs() <= 1e-12 * 3.0, "absorbed {}", s.absorbed_w);
        assert_eq!(f.ledger.escaped_w, 0.0);
        // Independent check of the standard error: Var K = ρ/(1−ρ)², so stderr = P√ρ/(1−ρ)/√N.
        // K's excess kurtosis is about 6, so the estimated stderr itself scatters by about
        // √(8/N)/2 < 1 % here: a 5 % tolerance is over 5 of its standard deviations.
        let predicted = 3.0 * rho.sqrt() / (1.0 - rho) / (photons as f64).sqrt();
        assert!((s.incident_w_stderr / predicted - 1.0).abs() < 0.05, "stderr {} vs {predicted}", s.incident_w_stderr);
    }
}

#[test]
fn parallel_squares_receive_power_times_view_factor() {
    for (a, c) in [(1.0, 1.0), (2.0, 0.5), (0.3, 1.2)] {
        let toml = format!(
            r#"
            [[surfaces]]
            name = "receiver"
            material = "absorber"
            shape = {{ type = "quad", corners = [[0, 0, {c}], [{a}, 0, {c}], [{a}, {a}, {c}], [0, {a}, {c}]] }}
            [[lights]]
            name = "emitter"
            shape = {{ type = "quad", corners = [[0, 0, 0], [{a}, 0, 0], [{a}, {a}, 0], [0, {a}, 0]] }}
            power_w = 5
            "#
        );
        let f = run(&toml, 200_000, 11);
        let r = surface(&f, "receiver");
        let expected = 5.0 * photon::validate::vf_parallel_rectangles(a, a, c);
        assert_z(&format!("view factor a={a} c={c}"), r.incident_w, expected, r.incident_w_stderr, 4.0);
    }
}

#[test]
fn dielectric_slab_transmits_two_n_over_n_squared_plus_one() {
    // A non-absorbing slab at normal incidence, with all inter-reflections summed incoherently:
    // T = (1−R)/(1+R) with R = ((n−1)/(n+1))², which simplifies to 2n/(n²+1).
    for n in [1.5, 2.4] {
        let toml = format!(
            r#"
            [materials.glass]
            type = "dielectric"
            ior = {n}
            [[surfaces]]
            name = "slab"
            material = "glass"
            shape = {{ type = "box", min = [-1, -1, 0.2], max = [1, 1, 0.5] }}
            [[surfaces]]
            name = "detector"
            material = "absorber"
            shape = {{ type = "quad", corners = [[-3, -3, 1], [3, -3, 1], [3, 3, 1], [-3, 3, 1]] }}
            [[lights]]
            name = "beam"
            shape = {{ type = "quad", corners = [[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]] }}
            power_w = 1
            distribution = "collimated"
            "#
        );
        let f = run(&toml, 200_000, 5);
        let d = surface(&f, "detector");
        assert_z(&format!("slab n={n}"), d.incident_w, 2.0 * n / (n * n + 1.0), d.incident_w_stderr, 4.0);
        // What is not transmitted is reflected back to the beam's own (absorbing) face.
        let back = surface(&f, "beam").absorbed_w;
        assert!((back + d.incident_w - 1.0).abs() < 1e-12, "reflected {back} + transmitted {}", d.incident_w);
    }
}

#[test]
fn lambertian_transmitter_splits_reflectance_and_transmittance() {
    // A collimated beam onto a diffuser (ρ = 0.3, τ = 0.5) between two large absorbing plates
    // that catch everything except what escapes sideways. Arrivals at the diffuser are exactly
    // the emitted power (first hit), and the diffuser absorbs 1 − ρ − τ of it.
    let f = run(
        r#"
        [materials.diffuser]
        type = "lambertian"
        reflectance = 0.3
        transmittance = 0.5
        [[surfaces]]
        name = "diffuser"
        material = "diffuser"
        shape = { type = "quad", corners = [[-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]] }
        [[lights]]
        name = "beam"
        shape = { type = "quad", corners = [[-0.1, -0.1, 0], [0.1, -0.1, 0], [0.1, 0.1, 0], [-0.1, 0.1, 0]] }
        power_w = 2
        distribution = "collimated"
        "#,
        100_000,
        9,
    );
    let d = surface(&f, "diffuser");
    assert!((d.incident_w - 2.0).abs() < 1e-12);
    assert_z("diffuser absorbed", d.absorbed_w, 2.0 * 0.2, d.absorbed_w_stderr, 4.0);
}

#[test]
fn a_lamp_inside_an_absorbing_medium_emits_into_it() {
    // An isotropic 1 W point lamp at the centre of a tank of index-matched "water" (n = 1, so no
    // surface reflects or bends; α = 1/m), an absorbing plate 0.5 m below it. The plate receives
    // only direct light: ∫ I e^{−α r} cosθ/r² dA with I = 1/(4π) W/sr. The lamp's first segment
    // ends on the plate, not on the tank, so only knowing the lamp is inside the water (found by
    // ray parity when the scene is set up) attenuates it.
    let f = run(
        r#"
        [materials.water]
        type = "dielectric"
        ior = 1.0
        absorption_per_m = 1.0
        [[surfaces]]
        name = "tank"
        material = "water"
        shape = { type = "box", min = [-1, -1, -1], max = [1, 1, 1] }
        [[surfaces]]
        name = "plate"
        material = "absorber"
        shape = { type = "quad", corners = [[-0.4, -0.5, -0.4], [0.4, -0.5, -0.4], [0.4, -0.5, 0.4], [-0.4, -0.5, 0.4]] }
        [[lights]]
        name = "lamp"
        shape = { type = "point", position = [0, 0, 0] }
        power_w = 1
        "#,
        200_000,
        9,
    );
    // Midpoint rule on a 400 × 400 grid: the integrand is smooth, the error far below 1e-5.
    let (h, a, n) = (0.5f64, 0.4f64, 400);
    let cell = 2.0 * a / n as f64;
    let mut expected = 0.0;
    for i in 0..n {
        for j in 0..n {
            let (x, z) = (-a + (i as f64 + 0.5) * cell, -a + (j as f64 + 0.5) * cell);
            let r = (x * x + z * z + h * h).sqrt();
            expected += (-r).exp() * (h / r) / (r * r) * cell * cell / (4.0 * std::f64::consts::PI);
        }
    }
    let p = surface(&f, "plate");
    assert_z("plate under a lamp in water", p.incident_w, expected, p.incident_w_stderr, 4.0);
}

#[test]
fn absorbing_medium_attenuates_the_path_to_an_immersed_object() {
    // A beam enters a water tank (n = 1.33, α = 1/m) at normal incidence through its top face and
    // crosses 1 m of water to an absorbing plate lying inside on the bottom: it arrives with
    // P·(1 − R)·e^{−α·1 m}, R = ((n − 1)/(n + 1))². The path ends on the plate, not on the tank's
    // own face, so this needs the photon to know which medium it is in.
    let f = run(
        r#"
        [materials.water]
        type = "dielectric"
        ior = 1.33
        absorption_per_m = 1.0
        [[surfaces]]
        name = "tank"
        material = "water"
        shape = { type = "box", min = [-1, -1.5, -1], max = [1, 0, 1] }
        [[surfaces]]
        name = "plate"
        material = "absorber"
        shape = { type = "quad", corners = [[-0.5, -1, -0.5], [0.5, -1, -0.5], [0.5, -1, 0.5], [-0.5, -1, 0.5]] }
        [[lights]]
        name = "beam"
        shape = { type = "quad", corners = [[-0.1, 1, -0.1], [0.1, 1, -0.1], [0.1, 1, 0.1], [-0.1, 1, 0.1]] }
        power_w = 1
        distribution = "collimated"
        "#,
        100_000,
        4,
    );
    let r: f64 = ((1.33f64 - 1.0) / (1.33 + 1.0)).powi(2);
    let p = surface(&f, "plate");
    assert_z("immersed plate", p.incident_w, (1.0 - r) * (-1.0f64).exp(), p.incident_w_stderr, 4.0);
}
