//! Work planes (`[[detectors]] type = "plane"`): virtual parallelograms that photons pass
//! through without being touched, tallying the light that falls on their front face, as a
//! lighting designer's calculation grid over a desk or a floor.
//!
//! A plane p = a + u·U + v·V, (u, v) ∈ [0, 1)², U = b − a, V = d − a, has its front on the side
//! n = (b − a) × (c − a) points to. A straight stretch of a photon's path o + s·ω, s ∈ [0, s_max],
//! crosses it at s = (a − o)·n / (ω·n); it is tallied when ω·n < 0 (arriving at the front face),
//! 0 ≤ s ≤ s_max and (u, v) falls inside. Texels are nu × nv equal parallelograms; after them
//! comes one slot for the plane's whole flux, so E_mean has its own standard error (a photon
//! may cross a plane more than once, and its texels' scores are then correlated).

use glam::DVec3;

#[derive(Clone, Debug)]
pub struct WorkPlane {
    pub name: String,
    /// [nu, nv]: texels along U and along V.
    pub resolution: [usize; 2],
    /// Corner a in the tracer's recentred frame (m), the edges U and V from it, the unit front
    /// normal, and the dual vectors (u = (p − a)·du, v = (p − a)·dv).
    pub origin: DVec3,
    pub u_edge: DVec3,
    pub v_edge: DVec3,
    pub normal: DVec3,
    du: DVec3,
    dv: DVec3,
    /// First slot of this plane in the scene's texel array (after every surface map's).
    pub offset: usize,
}

impl WorkPlane {
    pub fn new(name: String, resolution: [usize; 2], corners: [DVec3; 3], offset: usize) -> Self {
        let [origin, u_end, v_end] = corners;
        let (u_edge, v_edge) = (u_end - origin, v_end - origin);
        let (uu, uv, vv) = (u_edge.dot(u_edge), u_edge.dot(v_edge), v_edge.dot(v_edge));
        let det = uu * vv - uv * uv;
        WorkPlane {
            name,
            resolution,
            origin,
            u_edge,
            v_edge,
            normal: u_edge.cross(v_edge).normalize(),
            du: (vv * u_edge - uv * v_edge) / det,
            dv: (uu * v_edge - uv * u_edge) / det,
            offset,
        }
    }

    /// Slots in the scene's texel array: the texels, then the whole plane.
    pub fn slots(&self) -> usize {
        self.resolution[0] * self.resolution[1] + 1
    }

    /// The slot of the plane's whole flux.
    pub fn total_slot(&self) -> usize {
        self.offset + self.resolution[0] * self.resolution[1]
    }

    pub fn area_m2(&self) -> f64 {
        self.u_edge.cross(self.v_edge).length()
    }

    pub fn size_m(&self) -> [f64; 2] {
        [self.u_edge.length(), self.v_edge.length()]
    }

    /// The texel slot where the stretch o + s·ω, s ∈ [0, s_max] (ω unit, s_max may be infinite)
    /// crosses the plane toward its front face, and s there, if it does.
    #[inline]
    pub fn crossing(&self, o: DVec3, w: DVec3, s_max: f64) -> Option<(usize, f64)> {
        let along = w.dot(self.normal);
        if !(along < 0.0) {
            return None;
        }
        let s = (self.origin - o).dot(self.normal) / along;
        if !(s >= 0.0 && s <= s_max) {
            return None;
        }
        let q = o + s * w - self.origin;
        let (u, v) = (q.dot(self.du), q.dot(self.dv));
        if !((0.0..1.0).contains(&u) && (0.0..1.0).contains(&v)) {
            return None;
        }
        let [nu, nv] = self.resolution;
        let i = ((u * nu as f64) as usize).min(nu - 1);
        let j = ((v * nv as f64) as usize).min(nv - 1);
        Some((self.offset + j * nu + i, s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn desk() -> WorkPlane {
        // 2 m × 1 m at z = 0.75, front up: a, b = a + 2x, d = a + y.
        let a = DVec3::new(0.0, 0.0, 0.75);
        WorkPlane::new("desk".into(), [4, 2], [a, a + DVec3::new(2.0, 0.0, 0.0), a + DVec3::Y], 10)
    }

    #[test]
    fn a_ray_falling_on_the_front_lands_in_its_texel() {
        let p = desk();
        assert!((p.normal - DVec3::Z).length() < 1e-15);
        // Down through (1.3, 0.6): texel i = 2 (u = 0.65), j = 1.
        let slot = p.crossing(DVec3::new(1.3, 0.6, 2.0), DVec3::NEG_Z, f64::INFINITY);
        assert_eq!(slot, Some((10 + 4 + 2, 1.25)));
        assert_eq!(p.total_slot(), 18);
    }

    #[test]
    fn rays_from_behind_short_of_it_or_beside_it_are_not_tallied() {
        let p = desk();
        let from_below = p.crossing(DVec3::new(1.0, 0.5, 0.0), DVec3::Z, f64::INFINITY);
        let stops_short = p.crossing(DVec3::new(1.0, 0.5, 2.0), DVec3::NEG_Z, 1.0);
        let beside = p.crossing(DVec3::new(2.5, 0.5, 2.0), DVec3::NEG_Z, f64::INFINITY);
        let parallel = p.crossing(DVec3::new(1.0, 0.5, 0.75), DVec3::X, f64::INFINITY);
        assert_eq!([from_below, stops_short, beside, parallel], [None; 4]);
        // Ending exactly on the plane still counts (s = s_max).
        assert!(p.crossing(DVec3::new(1.0, 0.5, 1.75), DVec3::NEG_Z, 1.0).is_some());
    }
}
