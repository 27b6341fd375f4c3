//! The irradiance-map detector's own state: the area of its surface inside each texel, from the
//! scene's description of the map (`scene::map`). A texel's area is the part of the surface
//! inside it (each triangle's (u, v) image clipped to the texel, times the triangle's area over
//! its (u, v) area), so texels the surface only partly covers, as along a disk's rim or a
//! trapezoid's slanted side, still give true irradiance.

use glam::DVec2;

use crate::scene::map::{polygon_area, SurfaceMap};

/// Area of the surface inside each texel, m², index = j·nu + i (i along u, j along v). Edge
/// texels reach to ±∞, so a surface sticking out of [0, 1]² (a non-planar quad's far corner,
/// tiled texture coordinates) keeps its area where its arrivals are clamped to.
pub fn texel_areas(map: &SurfaceMap) -> Vec<f64> {
    let [nu, nv] = map.resolution;
    let mut texel_area_m2 = vec![0.0; nu * nv];
    for (q, area) in &map.triangles {
        let uv_area = polygon_area(q);
        if !(uv_area > 0.0) {
            continue;
        }
        let scale = area / uv_area;
        let (lo, hi) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
        let cells = |a: f64, b: f64, n: usize| {
            let first = ((a * n as f64).floor().max(0.0) as usize).min(n - 1);
            let last = ((b * n as f64).floor().max(0.0) as usize).min(n - 1);
            first..=last
        };
        let edge = |k: usize, n: usize, low_side: bool| -> f64 {
            match (k, low_side) {
                (0, true) => f64::NEG_INFINITY,
                (k, false) if k == n - 1 => f64::INFINITY,
                (k, true) => k as f64 / n as f64,
                (k, false) => (k + 1) as f64 / n as f64,
            }
        };
        for j in cells(lo.y, hi.y, nv) {
            for i in cells(lo.x, hi.x, nu) {
                let rect = [edge(i, nu, true), edge(i, nu, false), edge(j, nv, true), edge(j, nv, false)];
                texel_area_m2[j * nu + i] += polygon_area(&clip_to_rect(q, rect)) * scale;
            }
        }
    }
    texel_area_m2
}

/// Sutherland–Hodgman clip of a convex polygon to [u0, u1] × [v0, v1] (bounds may be infinite).
fn clip_to_rect(poly: &[DVec2], [u0, u1, v0, v1]: [f64; 4]) -> Vec<DVec2> {
    let mut out: Vec<DVec2> = poly.to_vec();
    // Each plane: inside when s·(coordinate) ≥ s·bound.
    for (axis, bound, sign) in [(0, u0, 1.0), (0, u1, -1.0), (1, v0, 1.0), (1, v1, -1.0)] {
        if !bound.is_finite() || out.is_empty() {
            continue;
        }
        let inside = |p: DVec2| sign * (p[axis] - bound) >= 0.0;
        let input = std::mem::take(&mut out);
        for k in 0..input.len() {
            let (a, b) = (input[k], input[(k + 1) % input.len()]);
            let (ia, ib) = (inside(a), inside(b));
            if ia {
                out.push(a);
            }
            if ia != ib {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                out.push(a + t * (b - a));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn texel_areas_of_a_trapezoid_add_up_to_its_area_and_full_texels_are_equal() {
        // The Cornell floor (m): a trapezoid whose (u, v) image leaves a sliver of [0, 1]² empty.
        let [a, b, c, d] =
            [[0.5528, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.5592], [0.5496, 0.0, 0.5592]].map(DVec3::from);
        let tris = [[a, b, c], [a, c, d]];
        let area: f64 = tris.iter().map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()).sum();
        let areas = texel_areas(&SurfaceMap::planar([7, 5], a, b - a, d - a, &tris, 0));
        let total: f64 = areas.iter().sum();
        assert!((total - area).abs() < 1e-12 * area, "{total} vs {area}");
        // An interior texel is exactly |U × V| / (7·5).
        let full = (b - a).cross(d - a).length() / 35.0;
        assert!((areas[2 * 7 + 3] - full).abs() < 1e-12 * full);
        // The texel at u = 1, v = 1 (the corner C lies at u < 1): partly covered.
        assert!(areas[4 * 7 + 6] < full);
    }

    #[test]
    fn disk_texels_cover_the_disk_only() {
        let r = 1.0;
        let shape = crate::scene::shapes::ShapeSpec::Disk {
            center: [0.0, 0.0, 0.0],
            normal: [0.0, 0.0, 1.0],
            radius: r,
            segments: 256,
            transform: Default::default(),
        };
        let [o, u, v] = crate::scene::map::frame(&shape).unwrap();
        let ring: Vec<DVec3> = (0..256)
            .map(|i| {
                let (e1, e2) = DVec3::Z.any_orthonormal_pair();
                let phi = 2.0 * std::f64::consts::PI * i as f64 / 256.0;
                r * (phi.cos() * e1 + phi.sin() * e2)
            })
            .collect();
        let tris: Vec<[DVec3; 3]> = (0..256).map(|i| [DVec3::ZERO, ring[i], ring[(i + 1) % 256]]).collect();
        let areas = texel_areas(&SurfaceMap::planar([8, 8], o, u, v, &tris, 0));
        let polygon_area = 0.5 * 256.0 * (2.0 * std::f64::consts::PI / 256.0).sin();
        assert!((areas.iter().sum::<f64>() - polygon_area).abs() < 1e-12);
        // Corner texels lie outside the disk; a centre texel is full (0.25 × 0.25 m).
        assert_eq!(areas[0], 0.0);
        assert!((areas[3 * 8 + 3] - 0.0625).abs() < 1e-12);
    }
}
