//! Irradiance maps, as the scene describes them: a surface's grid of texels and where each of
//! its points falls (the tallies per texel are the particle tracer's; the files, `output::maps`).
//!
//! A mapped surface (a quad or a disk) carries an affine frame p = o + u·U + v·V with (u, v) in
//! [0, 1]²: a quad's first corner and its two edges from it, or the square around a disk. Texels
//! are equal rectangles in that plane, so the map reads like a plan view. A texel's area is the
//! part of the surface inside it (its triangles clipped to the texel in (u, v), times |U × V|),
//! so texels that the surface only partly covers, as along a disk's rim or a trapezoid's slanted
//! side, still give true irradiance. Every arrival on the surface lands in one texel (clamped at
//! the edges), so the texels' fluxes add up to the surface's incident tally exactly.

use glam::{DVec2, DVec3, Vec3A};

/// How a surface point gets its (u, v).
#[derive(Clone, Debug)]
pub enum Mapping {
    /// The affine frame of a quad or disk: origin (recentred scene coordinates, m) and the dual
    /// vectors, u = (p − o)·du, v = (p − o)·dv.
    Planar { origin: Vec3A, du: Vec3A, dv: Vec3A },
    /// A mesh's texture coordinates per triangle (in the surface's own triangle order),
    /// interpolated by the hit's barycentrics.
    Uv(Vec<[glam::Vec2; 3]>),
}

#[derive(Clone, Debug)]
pub struct SurfaceMap {
    pub resolution: [usize; 2],
    pub mapping: Mapping,
    /// The map's extent along u and v in metres (planar maps); None for texture coordinates.
    pub size_m: Option<[f64; 2]>,
    /// Area of the surface inside each texel, m², index = j·nu + i (i along u, j along v).
    pub texel_area_m2: Vec<f64>,
    /// First texel of this map in the scene's texel array.
    pub offset: usize,
}

impl SurfaceMap {
    /// The planar map of a surface made of `tris` (m, the same coordinates as `origin`) over the
    /// frame (`origin`, `u_edge`, `v_edge`).
    pub fn planar(
        resolution: [usize; 2],
        origin: DVec3,
        u_edge: DVec3,
        v_edge: DVec3,
        tris: &[[DVec3; 3]],
        offset: usize,
    ) -> Self {
        // Dual basis from the Gram matrix: u = (p − o)·du, v = (p − o)·dv, exact in the plane.
        let (uu, uv, vv) = (u_edge.dot(u_edge), u_edge.dot(v_edge), v_edge.dot(v_edge));
        let det = uu * vv - uv * uv;
        let du = (vv * u_edge - uv * v_edge) / det;
        let dv = (uu * v_edge - uv * u_edge) / det;
        let to_uv = |p: DVec3| DVec2::new((p - origin).dot(du), (p - origin).dot(dv));
        let uvs: Vec<[DVec2; 3]> = tris.iter().map(|t| t.map(to_uv)).collect();
        SurfaceMap {
            resolution,
            mapping: Mapping::Planar { origin: origin.as_vec3a(), du: du.as_vec3a(), dv: dv.as_vec3a() },
            size_m: Some([u_edge.length(), v_edge.length()]),
            texel_area_m2: texel_areas(resolution, tris, &uvs),
            offset,
        }
    }

    /// The map of a mesh over its texture coordinates `uvs` (one triple per triangle of `tris`).
    pub fn textured(resolution: [usize; 2], tris: &[[DVec3; 3]], uvs: &[[DVec2; 3]], offset: usize) -> Self {
        SurfaceMap {
            resolution,
            mapping: Mapping::Uv(uvs.iter().map(|t| t.map(|q| q.as_vec2())).collect()),
            size_m: None,
            texel_area_m2: texel_areas(resolution, tris, uvs),
            offset,
        }
    }

    pub fn texels(&self) -> usize {
        self.resolution[0] * self.resolution[1]
    }

    /// Index (in the scene's texel array) of the texel holding surface point `p`, which lies on
    /// the surface's triangle `local` (its own order) at barycentrics `b`.
    #[inline]
    pub fn texel_of(&self, p: Vec3A, b: [f32; 3], local: u32) -> usize {
        let (u, v) = match &self.mapping {
            Mapping::Planar { origin, du, dv } => ((p - *origin).dot(*du), (p - *origin).dot(*dv)),
            Mapping::Uv(uvs) => {
                let t = uvs[local as usize];
                let q = t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
                (q.x, q.y)
            }
        };
        let [nu, nv] = self.resolution;
        let i = ((u * nu as f32).floor() as isize).clamp(0, nu as isize - 1) as usize;
        let j = ((v * nv as f32).floor() as isize).clamp(0, nv as isize - 1) as usize;
        self.offset + j * nu + i
    }
}

/// The affine frame (origin, U, V) of a shape that can carry a map, in its own units after its
/// transform: a quad's first corner with the edges to its second and fourth corners; the square
/// circumscribing a disk, along the same in-plane axes its triangles are built on.
pub fn frame(shape: &crate::scene::shapes::ShapeSpec) -> Option<[DVec3; 3]> {
    use crate::scene::shapes::ShapeSpec;
    let (o, u, v, t) = match shape {
        ShapeSpec::Quad { corners, transform } => {
            let [a, b, _, d] = corners.map(DVec3::from);
            (a, b - a, d - a, transform)
        }
        ShapeSpec::Disk { center, normal, radius, transform, .. } => {
            let (e1, e2) = DVec3::from(*normal).normalize().any_orthonormal_pair();
            let c = DVec3::from(*center);
            (c - *radius * (e1 + e2), 2.0 * *radius * e1, 2.0 * *radius * e2, transform)
        }
        _ => return None,
    };
    let o_t = t.apply_point(o);
    Some([o_t, t.apply_point(o + u) - o_t, t.apply_point(o + v) - o_t])
}

/// Area of the surface inside each texel: every triangle's area split over the texels by its
/// (u, v) image, clipped to each texel (the area scale of an affine map is the triangle's area
/// over its (u, v) area). Edge texels reach to ±∞, so a surface sticking out of [0, 1]² (a
/// non-planar quad's far corner, tiled texture coordinates) keeps its area where its arrivals are
/// clamped to.
fn texel_areas(resolution: [usize; 2], tris: &[[DVec3; 3]], uvs: &[[DVec2; 3]]) -> Vec<f64> {
    let [nu, nv] = resolution;
    let mut texel_area_m2 = vec![0.0; nu * nv];
    for (t, q) in tris.iter().zip(uvs) {
        let uv_area = polygon_area(q);
        let area = 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length();
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

/// Area of a simple polygon (shoelace), ≥ 0.
pub fn polygon_area(p: &[DVec2]) -> f64 {
    let n = p.len();
    if n < 3 {
        return 0.0;
    }
    let twice: f64 = (0..n).map(|k| p[k].perp_dot(p[(k + 1) % n])).sum();
    0.5 * twice.abs()
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

/// A file name for a surface's map: its name with anything but letters, digits, '-' and '_'
/// replaced by '_'.
pub fn file_stem(surface: &str) -> String {
    surface.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}

/// The map file of a surface inside `maps/`: `<stem>.<ext>`.
pub fn file_name(surface: &str, ext: &str) -> String {
    format!("{}.{ext}", file_stem(surface))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_areas_of_a_trapezoid_add_up_to_its_area_and_full_texels_are_equal() {
        // The Cornell floor (m): a trapezoid whose (u, v) image leaves a sliver of [0, 1]² empty.
        let [a, b, c, d] =
            [[0.5528, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.5592], [0.5496, 0.0, 0.5592]].map(DVec3::from);
        let tris = [[a, b, c], [a, c, d]];
        let area: f64 = tris.iter().map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length()).sum();
        let map = SurfaceMap::planar([7, 5], a, b - a, d - a, &tris, 0);
        let total: f64 = map.texel_area_m2.iter().sum();
        assert!((total - area).abs() < 1e-12 * area, "{total} vs {area}");
        // An interior texel is exactly |U × V| / (7·5).
        let full = (b - a).cross(d - a).length() / 35.0;
        assert!((map.texel_area_m2[2 * 7 + 3] - full).abs() < 1e-12 * full);
        // The texel at u = 1, v = 1 (the corner C lies at u < 1): partly covered.
        assert!(map.texel_area_m2[4 * 7 + 6] < full);
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
        let [o, u, v] = frame(&shape).unwrap();
        let ring: Vec<DVec3> = (0..256)
            .map(|i| {
                let (e1, e2) = DVec3::Z.any_orthonormal_pair();
                let phi = 2.0 * std::f64::consts::PI * i as f64 / 256.0;
                r * (phi.cos() * e1 + phi.sin() * e2)
            })
            .collect();
        let tris: Vec<[DVec3; 3]> = (0..256).map(|i| [DVec3::ZERO, ring[i], ring[(i + 1) % 256]]).collect();
        let map = SurfaceMap::planar([8, 8], o, u, v, &tris, 0);
        let polygon_area = 0.5 * 256.0 * (2.0 * std::f64::consts::PI / 256.0).sin();
        assert!((map.texel_area_m2.iter().sum::<f64>() - polygon_area).abs() < 1e-12);
        // Corner texels lie outside the disk; a centre texel is full (0.25 × 0.25 m).
        assert_eq!(map.texel_area_m2[0], 0.0);
        assert!((map.texel_area_m2[3 * 8 + 3] - 0.0625).abs() < 1e-12);
    }
}
