//! Far-field intensity detector: photons leaving the scene, binned by direction. Far from the
//! scene every escaping photon's direction is where its power goes, so a bin's flux over its solid
//! angle is the scene's intensity there: I = Φ_bin/ΔΩ (W/sr, and cd from the lumen tally).
//!
//! Bins are in the photometric (γ, C) angles of a frame (nadir, C = 0 direction; see
//! `ies::Frame`): n_γ equal bands of γ from 0 to 180°, and n_C equal sectors of C centred on
//! C = 0, ΔC, 2ΔC, …, so that the C0, C90, C180 and C270 planes each have a sector of their own
//! when n_C is a multiple of 4.

use std::f64::consts::PI;

use glam::Vec3A;

use crate::scene::ies::Frame;

#[derive(Clone, Debug)]
pub struct FarField {
    pub name: String,
    /// [n_γ, n_C].
    pub resolution: [usize; 2],
    pub frame: Frame,
    /// First bin of this detector in the scene's far-field bin array.
    pub offset: usize,
}

impl FarField {
    pub fn bins(&self) -> usize {
        self.resolution[0] * self.resolution[1]
    }

    /// Bin (in the scene's array) of unit direction `w`.
    #[inline]
    pub fn bin_of(&self, w: Vec3A) -> usize {
        let [ng, nc] = self.resolution;
        let (gamma, c) = self.frame.angles(w);
        let i = ((gamma / PI * ng as f64) as usize).min(ng - 1);
        let j = ((c / (2.0 * PI) * nc as f64 + 0.5) as usize) % nc;
        self.offset + j * ng + i
    }

    /// γ band edges and C sector centre of bin (i, j), degrees.
    pub fn bin_angles(&self, i: usize, j: usize) -> (f64, f64, f64) {
        let [ng, nc] = self.resolution;
        (180.0 * i as f64 / ng as f64, 180.0 * (i + 1) as f64 / ng as f64, 360.0 * j as f64 / nc as f64)
    }

    /// Solid angle of a bin in band i: (cos γ₀ − cos γ₁)·ΔC.
    pub fn solid_angle_sr(&self, i: usize) -> f64 {
        let (g0, g1, _) = self.bin_angles(i, 0);
        (g0.to_radians().cos() - g1.to_radians().cos()) * 2.0 * PI / self.resolution[1] as f64
    }
}
