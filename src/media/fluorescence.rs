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

/// e(λ'|λ): the density per nm of re-emission at λ' for a photon absorbed at λ, as `reemit`
/// draws it: the emission pdf, or with `redshift` its part at or above λ renormalised. Zero
/// where `reemit` puts its point mass (λ beyond the emission spectrum under `redshift`), which
/// no density describes.
#[inline]
pub fn emission_pdf(f: &Fluorescence, lambda_in: f64, lambda_out: f64) -> f64 {
    let e = f.emission_sampler.pdf(lambda_out);
    if !f.redshift {
        return e;
    }
    let below = f.emission_sampler.cdf_at(lambda_in);
    if lambda_out >= lambda_in && below < 1.0 {
        e / (1.0 - below)
    } else {
        0.0
    }
}

/// The adjoint of re-emission, for paths traced from the camera: light leaving at λ' came from
/// light absorbed at some λ. Draws λ by inverse CDF of μf (density μf(λ)/F, F = ∫μf) and returns
/// it with the kernel over that density, μf(λ)·q·e(λ'|λ)·(λ/λ') / (μf(λ)/F) = q·e(λ'|λ)·(λ/λ')·F:
/// the spectral radiance re-emitted at λ' per unit fluence at λ, as the integrand of
/// L_e(λ') = ∫ μf(λ) q e(λ'|λ) (λ/λ') φ(λ)/(4π) dλ (the 1/(4π) cancels against the isotropic
/// direction's density). None where the luminophore absorbs nothing in the range.
#[inline]
pub fn absorbed_for(f: &Fluorescence, lambda_out: f64, u: f64) -> Option<(f64, f64)> {
    let absorption = f.absorption_sampler.as_ref()?;
    let lambda_in = absorption.sample(u);
    let weight =
        f.quantum_yield * emission_pdf(f, lambda_in, lambda_out) * (lambda_in / lambda_out) * absorption.total();
    Some((lambda_in, weight))
}

/// The adjoint kernel's strength at λ' (per metre) as if re-emission drew from the whole
/// emission spectrum, q·e(λ')·F: the odds the camera integrators give a collision's
/// re-emission branch against scattering (μs). Any positive value where the kernel is positive
/// keeps them unbiased; under `redshift` it is only an approximation of the true strength.
#[inline]
pub fn adjoint_strength(f: &Fluorescence, lambda_out: f64) -> f64 {
    f.absorption_sampler.as_ref().map_or(0.0, |a| f.quantum_yield * f.emission_sampler.pdf(lambda_out) * a.total())
}

/// Whether `reemit` puts a photon absorbed at λ on its point mass: under `redshift`, λ beyond
/// the emission spectrum re-emits at its longest wavelength, which no density describes.
#[inline]
pub fn reemits_at_point_mass(f: &Fluorescence, lambda_in: f64) -> bool {
    f.redshift && f.emission_sampler.cdf_at(lambda_in) >= 1.0
}
