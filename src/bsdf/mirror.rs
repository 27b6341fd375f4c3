//! A perfect mirror of reflectance ρ(λ): a delta lobe about the normal.

use glam::Vec3A;

use super::{reflect, Lobe, Sample};
use crate::spectrum::Lanes;

#[derive(Clone, Copy, Debug)]
pub struct Mirror<const N: usize> {
    pub reflectance: Lanes<N>,
}

impl<const N: usize> Mirror<N> {
    /// wi = reflect(−wo), carrying ρ; no random number is drawn.
    #[inline]
    pub fn sample(&self, wo: Vec3A, n: Vec3A) -> Sample<N> {
        Sample {
            wi: reflect(-wo, n),
            lobe: Lobe::SpecularReflection,
            factor: self.reflectance,
            lobe_pdf: 1.0,
            pdf: 0.0,
        }
    }
}
