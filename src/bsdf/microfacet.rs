//! The GGX (Trowbridge–Reitz) microfacet distribution, isotropic or anisotropic, with Smith's
//! height-correlated masking–shadowing (Heitz 2014, "Understanding the Masking-Shadowing
//! Function") and sampling by the distribution of visible normals (Heitz 2018, "Sampling the GGX
//! Distribution of Visible Normals"), in the layout of pbrt-v4's TrowbridgeReitzDistribution.
//! Directions are in the local frame of `Frame`: z along the normal on the side of `wo`, x along
//! the α_x axis.

use glam::Vec3A;
use std::f64::consts::PI;

use crate::scene::Roughness;

/// An orthonormal frame: `t` (the α_x axis), `b`, `n`.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub t: Vec3A,
    pub b: Vec3A,
    pub n: Vec3A,
}

impl Frame {
    /// A frame around unit `n` with its tangent along `tangent` projected off `n` (any
    /// perpendicular direction when `tangent` is parallel to `n` or zero).
    #[inline]
    pub fn new(n: Vec3A, tangent: Vec3A) -> Self {
        let t = tangent - n * n.dot(tangent);
        let t = if t.length_squared() > 1e-12 { t.normalize() } else { crate::geometry::basis(n).0 };
        Frame { t, b: n.cross(t), n }
    }

    #[inline]
    pub fn to_local(&self, w: Vec3A) -> Vec3A {
        Vec3A::new(w.dot(self.t), w.dot(self.b), w.dot(self.n))
    }

    #[inline]
    pub fn to_world(&self, w: Vec3A) -> Vec3A {
        self.t * w.x + self.b * w.y + self.n * w.z
    }

    /// The frame around `n` turned to the side `w` lies on (its z toward `w`): microfacet models
    /// reflect alike from both sides.
    #[inline]
    pub fn facing(n: Vec3A, w: Vec3A) -> Self {
        Frame::facing_along(n, Vec3A::ZERO, w)
    }

    /// The same with its x along `tangent` (an anisotropic lobe's α_x axis; zero for any, as
    /// `facing` takes). Turning to the other side keeps x, so α_x stays along the tangent.
    #[inline]
    pub fn facing_along(n: Vec3A, tangent: Vec3A, w: Vec3A) -> Self {
        let f = Frame::new(n, tangent);
        if w.dot(n) >= 0.0 {
            f
        } else {
            f.flipped()
        }
    }

    /// The same frame seen from the other side (z → −z, keeping it right-handed).
    #[inline]
    pub fn flipped(&self) -> Self {
        Frame { t: self.t, b: -self.b, n: -self.n }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ggx {
    pub alpha_x: f64,
    pub alpha_y: f64,
}

impl Ggx {
    pub fn new(alpha_x: f64, alpha_y: f64) -> Self {
        Ggx { alpha_x, alpha_y }
    }

    /// The distribution of a material's `roughness`, α_x along the surface tangent (αu); None
    /// for a smooth surface.
    #[inline]
    pub fn of(roughness: &Roughness) -> Option<Self> {
        roughness.is_rough().then(|| Ggx::new(roughness.u, roughness.v))
    }

    /// D(m) = 1 / (π α_x α_y cos⁴θ_m (1 + tan²θ_m (cos²φ/α_x² + sin²φ/α_y²))²), per unit projected area.
    #[inline]
    pub fn d(&self, m: Vec3A) -> f64 {
        let (x, y, z) = (m.x as f64, m.y as f64, m.z as f64);
        if z <= 0.0 {
            return 0.0;
        }
        // (x²/α_x² + y²/α_y² + z²)² form: the same value without tan θ's division by cos θ.
        let e = (x / self.alpha_x).powi(2) + (y / self.alpha_y).powi(2) + z * z;
        1.0 / (PI * self.alpha_x * self.alpha_y * e * e)
    }

    /// Smith's Λ(w) = (√(1 + α(w)² tan²θ) − 1)/2, α(w)² = cos²φ α_x² + sin²φ α_y².
    #[inline]
    pub fn lambda(&self, w: Vec3A) -> f64 {
        let (x, y, z) = (w.x as f64, w.y as f64, w.z as f64);
        let z2 = z * z;
        if z2 == 0.0 {
            return f64::INFINITY;
        }
        let a2_tan2 = ((x * self.alpha_x).powi(2) + (y * self.alpha_y).powi(2)) / z2;
        ((1.0 + a2_tan2).sqrt() - 1.0) * 0.5
    }

    /// Masking G1(w) = 1/(1 + Λ(w)).
    #[inline]
    pub fn g1(&self, w: Vec3A) -> f64 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Height-correlated masking–shadowing G2(wo, wi) = 1/(1 + Λ(wo) + Λ(wi)) (Heitz 2014). A
    /// build with the `mitsuba-conventions` feature (bench/mitsuba only) takes Mitsuba 3's
    /// separable G1(wo)·G1(wi) instead.
    #[inline]
    pub fn g2(&self, wo: Vec3A, wi: Vec3A) -> f64 {
        if cfg!(feature = "mitsuba-conventions") {
            self.g1(wo) * self.g1(wi)
        } else {
            1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
        }
    }

    /// Density of visible normals seen from `w` (z > 0): D_w(m) = G1(w) max(0, w·m) D(m) / cosθ_w.
    #[inline]
    pub fn visible_pdf(&self, w: Vec3A, m: Vec3A) -> f64 {
        let cos = w.z as f64;
        if cos <= 0.0 {
            return 0.0;
        }
        self.g1(w) * (w.dot(m) as f64).max(0.0) * self.d(m) / cos
    }

    /// Samples a visible normal from `w` (z > 0) by D_w: stretch to the hemisphere configuration,
    /// sample the projected area of the hemisphere seen from there, unstretch (Heitz 2018).
    #[inline]
    pub fn sample_visible(&self, w: Vec3A, u: [f32; 2]) -> Vec3A {
        let (ax, ay) = (self.alpha_x as f32, self.alpha_y as f32);
        let wh = Vec3A::new(ax * w.x, ay * w.y, w.z).normalize();
        let t1 = if wh.z < 0.99999 { Vec3A::Z.cross(wh).normalize() } else { Vec3A::X };
        let t2 = wh.cross(t1);
        // A uniform point on the unit disk (polar), then its y squeezed onto the visible half.
        let r = u[0].sqrt();
        let phi = 2.0 * std::f32::consts::PI * u[1];
        let (px, py) = (r * phi.cos(), r * phi.sin());
        let h = (1.0 - px * px).max(0.0).sqrt();
        let s = 0.5 * (1.0 + wh.z);
        let py = (1.0 - s) * h + s * py;
        let pz = (1.0 - px * px - py * py).max(0.0).sqrt();
        let nh = t1 * px + t2 * py + wh * pz;
        Vec3A::new(ax * nh.x, ay * nh.y, nh.z.max(1e-6)).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ D(m) cosθ_m dω_m = 1 (the projected microfacet area is the macro-surface's), by a
    /// midpoint rule over (cosθ, φ).
    fn projected_area(g: &Ggx) -> f64 {
        let (nt, np) = (4000, 256);
        let mut sum = 0.0;
        for i in 0..nt {
            // cosθ = 1 − s², s uniform, resolves the peak at θ = 0 for small α.
            let s = (i as f64 + 0.5) / nt as f64;
            let c = 1.0 - s * s;
            let dc = 2.0 * s / nt as f64;
            let st = (1.0 - c * c).max(0.0).sqrt();
            for j in 0..np {
                let phi = 2.0 * PI * (j as f64 + 0.5) / np as f64;
                let m = Vec3A::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, c as f32);
                sum += g.d(m) * c * dc * 2.0 * PI / np as f64;
            }
        }
        sum
    }

    #[test]
    fn the_distribution_is_normalised_over_projected_area() {
        for g in [Ggx::new(0.5, 0.5), Ggx::new(0.1, 0.1), Ggx::new(0.2, 0.6)] {
            let a = projected_area(&g);
            assert!((a - 1.0).abs() < 2e-3, "{g:?}: ∫D cos = {a}");
        }
    }

    #[test]
    fn smith_lambda_matches_its_closed_form_and_g1_tends_to_one_at_normal_incidence() {
        let g = Ggx::new(0.3, 0.3);
        // θ = 60°: tanθ = √3, Λ = (√(1 + 0.09·3) − 1)/2.
        let w = Vec3A::new((60f64.to_radians().sin()) as f32, 0.0, (60f64.to_radians().cos()) as f32);
        let expect = ((1.0f64 + 0.09 * 3.0).sqrt() - 1.0) / 2.0;
        assert!((g.lambda(w) - expect).abs() < 1e-6, "{} vs {expect}", g.lambda(w));
        assert!((g.g1(Vec3A::Z) - 1.0).abs() < 1e-12);
    }
}
