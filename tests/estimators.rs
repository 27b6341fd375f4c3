//! The variance-reduction options change noise, never the answer: each estimator and emission
//! scheme must agree with the others on every tally within 4 combined standard errors (fixed
//! seeds, independent runs: a false failure has probability ~6e-5 per comparison), and each must
//! balance the ledger exactly.

mod common;
use common::{assert_z, cornell_toml, run_with, surface};

use photon::output::Flux;
use photon::transport::{Estimator, TransportOptions};

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
