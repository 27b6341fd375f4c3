//! The variance-reduction options change noise, never the answer: each estimator and emission
//! scheme must agree with the others on every tally within 4 combined standard errors (fixed
//! seeds, independent runs: a false failure has probability ~6e-5 per comparison), and each must
//! balance the ledger exactly.

mod common;
use common::{assert_z, cornell_toml, run_with, surface};

use photon::integrators::particle::{Estimator, TransportOptions};
use photon::output::Flux;

fn compare(a: &Flux, b: &Flux, label: &str) {
    assert!(a.ledger.relative_residual() < 1e-9 && b.ledger.relative_residual() < 1e-9, "{label}: ledger");
    for (x, y) in a.surfaces.iter().zip(&b.surfaces) {
        for (what, mx, sx, my, sy) in [
            ("incident", x.incident_w, x.incident_w_stderr, y.incident_w, y.incident_w_stderr),
            ("absorbed", x.absorbed_w, x.absorbed_w_stderr, y.absorbed_w, y.absorbed_w_stderr),
        ] {
            if mx == 0.0 && my == 0.0 {
                continue;
            }
            assert_z(&format!("{label}: {} {what}", x.name), mx, my, (sx * sx + sy * sy).sqrt(), 4.0);
        }
    }
}

#[test]
fn expected_value_and_analog_absorption_agree_on_the_cornell_box() {
    let toml = cornell_toml();
    let plain = |estimator| TransportOptions { estimator, stratified: false, hero: true };
    let analog = run_with(&toml, 300_000, 1, plain(Estimator::Analog));
    let expected = run_with(&toml, 150_000, 2, plain(Estimator::Expected));
    compare(&analog, &expected, "analog vs expected");
}

#[test]
fn stratified_and_plain_emission_agree_on_the_cornell_box_and_plates() {
    let toml = cornell_toml();
    for estimator in [Estimator::Analog, Estimator::Expected] {
        let opts = |stratified| TransportOptions { estimator, stratified, hero: true };
        // 20 batches: the stratified run's errors come from the spread between its batches.
        let plain = run_with(&toml, 327_680, 3, opts(false));
        let stratified = run_with(&toml, 327_680, 4, opts(true));
        compare(&plain, &stratified, &format!("{estimator:?}: plain vs stratified"));
    }
    // Direct transfer between parallel squares (F = 0.19982 for a = c = 1): stratification must
    // still hit the closed form, and with less noise than plain sampling.
    let plates = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/parallel_plates.toml")).unwrap();
    let opts = |stratified| TransportOptions { estimator: Estimator::Analog, stratified, hero: true };
    let plain = run_with(&plates, 327_680, 5, opts(false));
    let stratified = run_with(&plates, 327_680, 6, opts(true));
    let (p, s) = (surface(&plain, "receiver"), surface(&stratified, "receiver"));
    assert_z("stratified plates", s.incident_w, 10.0 * 0.199825, s.incident_w_stderr, 4.0);
    assert!(
        s.incident_w_stderr < p.incident_w_stderr,
        "stratified {} vs plain {}",
        s.incident_w_stderr,
        p.incident_w_stderr
    );
}

/// Runs `toml` with `--estimator auto`; returns the estimator the pilot chose and its figures.
fn auto_choice(toml: &str, seed: u64, threads: usize) -> photon::run::EstimatorPilot {
    use photon::run::{apply_options, simulate, RunOptions};
    let mut s = common::scene(toml);
    let opts = RunOptions { photons: Some(16_384), seed: Some(seed), threads: Some(threads), ..Default::default() };
    assert_eq!(opts.transport.estimator, Estimator::Auto, "auto is the default");
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &std::sync::atomic::AtomicBool::new(false)).unwrap();
    let pilot = r.pilot.expect("auto runs a pilot");
    assert_eq!(r.transport.estimator, pilot.chosen);
    pilot
}

/// Worst relative variance per photon × rays per photon of a full run with `estimator`: the
/// pilot's cost, measured independently of it.
fn full_run_cost(toml: &str, photons: u64, seed: u64, estimator: Estimator) -> f64 {
    use photon::run::{apply_options, simulate, RunOptions};
    let mut s = common::scene(toml);
    let transport = TransportOptions { estimator, stratified: false, hero: true };
    let opts =
        RunOptions { photons: Some(photons), seed: Some(seed), threads: Some(2), transport, ..Default::default() };
    let chosen = apply_options(&mut s, &opts).unwrap();
    let r = simulate(&s, &opts, &chosen, &std::sync::atomic::AtomicBool::new(false)).unwrap();
    let f = photon::output::flux(&s, &r);
    let worst = f
        .surfaces
        .iter()
        .flat_map(|r| [(r.incident_w, r.incident_w_stderr), (r.absorbed_w, r.absorbed_w_stderr)])
        .filter(|(m, _)| *m > 0.0)
        .map(|(m, s)| (s / m).powi(2) * photons as f64)
        .fold(0.0, f64::max);
    let c = r.tallies.counters;
    worst * (c.rays + c.shadow_rays) as f64 / photons as f64
}

#[test]
fn auto_picks_expected_value_absorption_in_the_furnace_and_analog_in_the_open_cornell_box() {
    // The furnace (closed sphere, ρ = 0.9): expected-value absorption costs ~3× the rays but cuts
    // the worst tally's variance ~100×; the pilot must see it, at any seed or thread count.
    let furnace = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/furnace.toml")).unwrap();
    // The pilot's figures, not only its verdict, are the same for any thread count.
    assert_eq!(auto_choice(&furnace, 3, 1), auto_choice(&furnace, 3, 2));
    assert_eq!(auto_choice(&cornell_toml(), 3, 1), auto_choice(&cornell_toml(), 3, 2));
    for (seed, threads) in [(1, 2), (2, 1)] {
        let p = auto_choice(&furnace, seed, threads);
        assert_eq!(p.chosen, Estimator::Expected, "furnace, seed {seed}: {p:?}");
        let (a, e) = (p.analog.unwrap(), p.expected.unwrap());
        // Here neither pilot reaches the ray cap: both trace the full pilot.
        assert_eq!((a.photons, e.photons), (photon::run::PILOT_PHOTONS, photon::run::PILOT_PHOTONS));
        assert!(a.cost > 10.0 * e.cost, "{p:?}");
    }
    // Independent full runs confirm the verdict by a wide margin (the pilots saw ~30×).
    let (analog, expected) = (
        full_run_cost(&furnace, 100_000, 7, Estimator::Analog),
        full_run_cost(&furnace, 100_000, 8, Estimator::Expected),
    );
    assert!(analog > 10.0 * expected, "full runs: analog {analog} vs expected {expected}");
    // The Cornell box, open and darker, where analog photons' short paths win (README table:
    // analog's worst-tally FOM 1.1–1.35× and image FOM 1.6–1.9× expected's).
    for seed in [1, 2, 3] {
        let p = auto_choice(&cornell_toml(), seed, 2);
        assert_eq!(p.chosen, Estimator::Analog, "Cornell box, seed {seed}: {p:?}");
    }
}
