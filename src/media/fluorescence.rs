//! Fluorescence: a luminophore (dye, phosphor) dissolved in a medium absorbs with its own
//! coefficient μf(λ) and re-emits each absorbed photon with probability q (the quantum yield),
//! isotropically, at a wavelength λ' drawn from its emission spectrum E(λ'), a photon-number
//! distribution. Photon weights carry power, so a re-emitted photon's weight is scaled by the
//! ratio of photon energies hc/λ' ÷ hc/λ = λ/λ' (the Stokes loss stays in the medium as heat).
//! `emission_sampling = "redshift"` draws λ' only from the emission spectrum's part at or above
//! λ (pvtrace's `emit_method = "redshift"`: no anti-Stokes emission).

use glam::Vec3A;

use crate::scene::{Fluorescence, Phase};

/// At a collision in a medium with scattering μs and luminophore absorption μf (the medium's
/// own absorption already decided), whether the luminophore took the photon: probability
/// μf/(μs + μf).
#[inline]
pub fn luminophore_absorbs(mu_s: f64, mu_f: f64, u: f64) -> bool {
    u * (mu_s + mu_f) < mu_f
}

/// A re-emitted photon: its wavelength λ' by inverse CDF of the emission spectrum (with
/// `redshift`, of its part above λ: u mapped into [C(λ), 1), C the emission CDF), its
/// direction uniform on the sphere, and its weight factor λ/λ' (energy per photon).
#[inline]
pub fn reemit(f: &Fluorescence, lambda_nm: f64, u_lambda: f64, u1: f64, u2: f64) -> (f64, Vec3A, f64) {
    let u = if f.redshift {
        let below = f.emission_sampler.cdf_at(lambda_nm);
        below + u_lambda * (1.0 - below)
    } else {
        u_lambda
    };
    let new_lambda = f.emission_sampler.sample(u.min(1.0 - f64::EPSILON / 2.0));
    let dir = super::phase::sample(Phase::Isotropic, Vec3A::Z, u1, u2);
    (new_lambda, dir, lambda_nm / new_lambda)
}
