//! The camera integrators' side of participating media: free flights along a subpath's segments,
//! the event at a collision (scattering by the phase function or, with a luminophore,
//! re-emission: its adjoint on the camera side), and transmittance for connections. The physics
//! is `media`'s; this is how a subpath with four wavelength lanes samples it.
//!
//! Lanes. A free flight is drawn with lane 0's extinction μt₀, so each lane's throughput takes
//! its own value over that density, Tₖ·μsₖ/(μt₀T₀) at a collision and Tₖ/T₀ at the next surface.
//! Where the lanes are kept to the end (no dispersion, no fluorescence), a sample is one sample
//! of the one-sample MIS over which lane drives the flights (the lanes are rotations of λ₀, so
//! any of them is lane 0 with equal probability; pbrt-v4's hero wavelength sampling): `lane_pdf`
//! keeps each lane's path density over lane 0's, and a contribution is divided by its mean
//! (the balance heuristic). Without that division a lane with lower μt than lane 0 would carry
//! exp((μt₀ − μtₖ)t), unbounded. Where lanes are dropped (a dispersive boundary, fluorescence),
//! `lane_pdf` stays one and the ratios are plain importance weights, unbiased for lane 0.
//! Distance densities stay out of BDPT's MIS (as in pbrt-v3): its weights still sum to one.

use glam::Vec3A;

use super::{ImageKernel, Lanes, Wavelengths};
use crate::bsdf::Mode;
use crate::detectors::tally::Counters;
use crate::media;
use crate::media::fluorescence;
use crate::sampling::Sampler;
use crate::scene::{Medium, Phase};
use crate::spectrum::Spectrum;

/// The `[media]` medium inside a dielectric, at the subpath's current wavelengths (per metre).
#[derive(Clone, Copy)]
pub(super) struct Coefficients<'m> {
    pub medium: &'m Medium,
    pub mu_s: Lanes,
    /// The luminophore's μf (zero without one, or outside fluorescent transport).
    pub mu_f: Lanes,
    pub mu_t: Lanes,
}

impl Coefficients<'_> {
    /// Whether free flights are drawn in it: it scatters or holds a luminophore somewhere in the
    /// range (a property of the medium, not of the sample's wavelengths).
    fn scatters(&self, fluorescent: bool) -> bool {
        self.medium.scattering_per_m != Spectrum::Constant(0.0) || (fluorescent && self.medium.fluorescence.is_some())
    }
}

/// What a collision in a medium did: scattered by the medium's phase function, or was
/// re-emitted (isotropically) at a new wavelength, which lane 0 now carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Event {
    Scattered(Phase),
    Reemitted,
}

impl Event {
    /// The direction density of the event, which is also its angular factor: p(cosθ) between
    /// the propagation directions, for `wo` and `wi` both pointing away from the vertex.
    #[inline]
    pub fn phase_pdf(self, wo: Vec3A, wi: Vec3A) -> f64 {
        match self {
            Event::Scattered(phase) => media::phase::pdf(phase, -(wo.dot(wi)) as f64),
            Event::Reemitted => media::phase::pdf(Phase::Isotropic, 0.0),
        }
    }

    pub fn phase(self) -> Phase {
        match self {
            Event::Scattered(phase) => phase,
            Event::Reemitted => Phase::Isotropic,
        }
    }
}

impl ImageKernel<'_> {
    /// The scattering or absorbing `[media]` medium inside dielectric `surface`, if it has one.
    #[inline]
    pub(super) fn coefficients<const SPECTRAL: bool>(
        &self,
        surface: u32,
        wl: &Wavelengths,
    ) -> Option<Coefficients<'_>> {
        let v = self.scene.surface_medium[surface as usize]?;
        let medium = &self.scene.media[v as usize];
        let mu_s = Lanes::eval::<SPECTRAL>(&medium.scattering_per_m, &wl.lambda);
        let mu_a = Lanes::eval::<SPECTRAL>(&medium.absorption_per_m, &wl.lambda);
        let mu_f = match &medium.fluorescence {
            Some(f) if SPECTRAL && self.fluorescent => Lanes::eval::<true>(&f.absorption_per_m, &wl.lambda),
            _ => Lanes::ZERO,
        };
        Some(Coefficients { medium, mu_s, mu_f, mu_t: mu_s + mu_a + mu_f })
    }

    /// Transmittance exp(−μt(λ)t) per lane over a segment of length `t` inside dielectric
    /// `medium`: its `[media]` extinction, or its own absorption_per_m; None if it is clear.
    #[inline]
    pub(super) fn medium_transmittance<const SPECTRAL: bool>(
        &self,
        medium: u32,
        t: f64,
        wl: &Wavelengths,
    ) -> Option<Lanes> {
        match self.coefficients::<SPECTRAL>(medium, wl) {
            Some(c) => Some(Lanes(c.mu_t.0.map(|mu| (-mu * t).exp()))),
            None => media::absorption(self.materials[medium as usize])
                .map(|alpha| media::transmittance::<SPECTRAL, { super::LANES }>(alpha, &wl.lambda, t)),
        }
    }

    /// The segment from a subpath's last vertex toward its next surface, `t_hit` away (infinite
    /// if none), inside `medium`. Through a scattering medium a free flight t ~ μt₀e^{−μt₀t} is
    /// drawn: a collision before the surface returns its distance and the medium, `beta` taking
    /// Tₖ/(μt₀T₀) (the event adds μs or the re-emission kernel); reaching the surface, `beta`
    /// takes Tₖ/T₀. Through an absorbing medium `beta` takes its transmittance. None: the
    /// subpath goes on to the surface.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(super) fn fly<const SPECTRAL: bool>(
        &self,
        medium: Option<u32>,
        t_hit: f64,
        wl: &mut Wavelengths,
        beta: &mut Lanes,
        lane_pdf: &mut Lanes,
        s: &mut Sampler,
        counters: &mut Counters,
    ) -> Option<(f64, Coefficients<'_>)> {
        let m = medium?;
        let Some(c) = self.coefficients::<SPECTRAL>(m, wl).filter(|c| c.scatters(SPECTRAL && self.fluorescent)) else {
            if let Some(t) = self.medium_transmittance::<SPECTRAL>(m, t_hit, wl) {
                *beta *= t;
            }
            return None;
        };
        counters.free_flights += 1;
        let lane_mis = SPECTRAL && self.lane_mis;
        if SPECTRAL && !lane_mis {
            // Without the MIS over lanes, lane 0's flights would miss collisions where only another
            // lane's μt is positive: from the first flight on, lane 0 alone is kept. (The test is on
            // the medium, not the lanes, so the decision does not depend on λ₁..λ₃.)
            wl.terminate_secondary();
        }
        let mu0 = c.mu_t.0[0];
        let t = media::free_flight(mu0, s.uniform());
        if t < t_hit {
            for k in 0..super::LANES {
                // Tₖ/T₀ as one exponential, which neither overflows nor underflows early.
                let ratio = (-(c.mu_t.0[k] - mu0) * t).exp();
                beta.0[k] *= ratio / mu0;
                if lane_mis {
                    lane_pdf.0[k] *= c.mu_t.0[k] / mu0 * ratio;
                }
            }
            return Some((t, c));
        }
        if !t_hit.is_finite() {
            // Leaving a closed medium without a boundary cannot happen; end the subpath.
            *beta = Lanes::ZERO;
            return None;
        }
        for k in 0..super::LANES {
            let ratio = (-(c.mu_t.0[k] - mu0) * t_hit).exp();
            beta.0[k] *= ratio;
            if lane_mis {
                lane_pdf.0[k] *= ratio;
            }
        }
        None
    }

    /// The event at a collision in `c`, for a subpath of `mode` at wavelengths `wl`, then
    /// Russian roulette: `beta` takes the event's weight over its probability. A luminophore
    /// competes with scattering: on the light side (importance) with odds μs : μf as the light
    /// tracer's photons; on the camera side with odds μs : q·e(λ')·F (the adjoint's strength),
    /// drawing the absorbed λ from μf. Re-emission changes lane 0's wavelength (its colour stays
    /// the sensor's). None ends the subpath.
    pub(super) fn collide<const SPECTRAL: bool>(
        &self,
        c: &Coefficients,
        mode: Mode,
        wl: &mut Wavelengths,
        beta: &mut Lanes,
        s: &mut Sampler,
    ) -> Option<Event> {
        let scattered = Event::Scattered(c.medium.phase);
        let luminophore = c.medium.fluorescence.as_ref().filter(|_| SPECTRAL && self.fluorescent);
        let Some(f) = luminophore else {
            *beta *= c.mu_s;
            // A survival probability symmetric in the lanes (the mean albedo), so that lane 0
            // driving the flights stays one MIS sample of the four.
            let albedo = Lanes::<{ super::LANES }>(std::array::from_fn(|k| {
                let mu_t = c.mu_t.0[k];
                if mu_t > 0.0 {
                    c.mu_s.0[k] / mu_t
                } else {
                    0.0
                }
            }))
            .mean()
            .min(1.0);
            return roulette(albedo, beta, s).then_some(scattered);
        };
        // Fluorescent transport keeps lane 0 alone.
        let (lambda, mu_s, mu_t) = (wl.lambda[0], c.mu_s.0[0], c.mu_t.0[0]);
        let (event, factor) = match mode {
            Mode::Importance => {
                let mu_f = c.mu_f.0[0];
                let odds = mu_s + mu_f;
                if !(odds > 0.0) {
                    return None;
                }
                if s.uniform() * odds < mu_s {
                    (scattered, odds)
                } else {
                    let (new_lambda, _, energy) =
                        fluorescence::reemit(f, lambda, s.uniform(), s.uniform(), s.uniform());
                    wl.lambda[0] = new_lambda;
                    (Event::Reemitted, odds * f.quantum_yield * energy)
                }
            }
            Mode::Radiance => {
                let strength = fluorescence::adjoint_strength(f, lambda);
                let odds = mu_s + strength;
                if !(odds > 0.0) {
                    return None;
                }
                if s.uniform() * odds < mu_s {
                    (scattered, odds)
                } else {
                    let (lambda_in, kernel) = fluorescence::absorbed_for(f, lambda, s.uniform())?;
                    wl.lambda[0] = lambda_in;
                    (Event::Reemitted, odds * kernel / strength)
                }
            }
        };
        *beta *= factor;
        roulette((factor / mu_t).min(1.0), beta, s).then_some(event)
    }
}

/// Survives with probability `p`, `beta` taking 1/p.
#[inline]
fn roulette(p: f64, beta: &mut Lanes, s: &mut Sampler) -> bool {
    if !(p > 0.0) || !(s.uniform() < p) {
        return false;
    }
    *beta *= 1.0 / p;
    true
}
