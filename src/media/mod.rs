//! What happens between surfaces: Beer–Lambert absorption inside a dielectric with an
//! absorption coefficient α(λ), free flights through a scattering medium (`[media]`) and its
//! phase function (`phase`), re-emission by a luminophore (`fluorescence`), and which medium a path is in after crossing a boundary. Every
//! integrator uses these; a path in a clear medium or outside every dielectric loses nothing.

pub mod fluorescence;
pub mod phase;

use glam::Vec3A;

use crate::scene::Material;
use crate::spectrum::{Lanes, Spectrum};

/// The absorption coefficient (per m) of the medium inside `material`, if it absorbs.
#[inline]
pub fn absorption(material: &Material) -> Option<&Spectrum> {
    match material {
        Material::Dielectric { absorption_per_m: Some(alpha), .. } => Some(alpha),
        _ => None,
    }
}

/// Beer–Lambert transmittance exp(−α(λ)·t) per lane over a segment of length `t` (m).
#[inline]
pub fn transmittance<const SPECTRAL: bool, const N: usize>(alpha: &Spectrum, lambda: &[f64; N], t: f64) -> Lanes<N> {
    let a = Lanes::eval::<SPECTRAL>(alpha, lambda);
    Lanes(crate::spectrum::map_array(a.0, |a| (-a * t).exp()))
}

/// The medium after a path scattered at dielectric `surface` (unit normal `n`) into unit `wi`:
/// the interior behind it (`Scene::surface_inside`: the dielectric itself, or for the face two
/// adjacent dielectrics share the one its normal leaves), or what is in front of it
/// (`Scene::surface_outside`: the dielectric it is nested in or adjacent to, or None for the world).
#[inline]
pub fn after_crossing(surface: u32, n: Vec3A, wi: Vec3A, inside: &[u32], outside: &[Option<u32>]) -> Option<u32> {
    if wi.dot(n) < 0.0 {
        Some(inside[surface as usize])
    } else {
        outside[surface as usize]
    }
}

/// A free-flight distance in a medium of extinction μt (per m): −ln(1 − u)/μt, exponential with
/// mean 1/μt (infinite where μt = 0).
#[inline]
pub fn free_flight(mu_t: f64, u: f64) -> f64 {
    -(1.0 - u).ln() / mu_t
}
