//! Phase functions of a participating medium: where a photon goes when it scatters in the
//! volume. p(cosθ) per unit solid angle, θ between its direction before and after.
//!   isotropic:          p = 1/(4π)
//!   Henyey–Greenstein:  p = (1 − g²) / (4π (1 + g² − 2g cosθ)^{3/2}),  g = ⟨cosθ⟩
//! (Henyey & Greenstein 1941). Sampled exactly by inverse CDF of cosθ, so a photon's weight
//! does not change when it scatters.

use glam::Vec3A;
use std::f64::consts::PI;

use crate::sampling::local_to_world;
use crate::scene::Phase;

/// Below this |g| the Henyey–Greenstein inverse CDF loses precision (it divides by g) and the
/// lobe differs from isotropic by less than 3|g| anywhere: it is sampled as isotropic.
const NEARLY_ISOTROPIC: f64 = 1e-5;

/// p(cosθ) per steradian.
#[inline]
pub fn pdf(phase: Phase, cos: f64) -> f64 {
    match phase {
        Phase::Isotropic => 1.0 / (4.0 * PI),
        Phase::HenyeyGreenstein { g } => {
            let d = 1.0 + g * g - 2.0 * g * cos;
            (1.0 - g * g) / (4.0 * PI * d * d.sqrt())
        }
    }
}

/// cosθ by inverse CDF: 1 − 2u isotropic; for Henyey–Greenstein
/// cosθ = (1 + g² − ((1 − g²)/(1 − g + 2gu))²)/(2g).
#[inline]
pub fn sample_cos(phase: Phase, u: f64) -> f64 {
    let cos = match phase {
        Phase::HenyeyGreenstein { g } if g.abs() >= NEARLY_ISOTROPIC => {
            let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
            (1.0 + g * g - s * s) / (2.0 * g)
        }
        _ => 1.0 - 2.0 * u,
    };
    cos.clamp(-1.0, 1.0)
}

/// A new unit direction of travel after scattering from `dir` (unit): cosθ from `sample_cos`,
/// the azimuth uniform.
#[inline]
pub fn sample(phase: Phase, dir: Vec3A, u1: f64, u2: f64) -> Vec3A {
    let cos = sample_cos(phase, u1);
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let (sp, cp) = (2.0 * PI * u2).sin_cos();
    local_to_world(dir, (sin * cp) as f32, (sin * sp) as f32, cos as f32).normalize()
}
