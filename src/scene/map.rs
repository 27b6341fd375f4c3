//! Irradiance maps, as the scene describes them: a surface's grid of texels, where each of its
//! points falls, and each triangle's (u, v) image. The texels' areas are the detector's to work
//! out (`detectors::maps`), the tallies per texel the particle tracer's, the files `output::maps`.
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
    /// Each of the surface's triangles: its (u, v) image and its area (m², from the f64 vertices).
    pub triangles: Vec<([DVec2; 3], f64)>,
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
            triangles: with_areas(tris, &uvs),
            offset,
        }
    }

    /// The map of a mesh over its texture coordinates `uvs` (one triple per triangle of `tris`).
    pub fn textured(resolution: [usize; 2], tris: &[[DVec3; 3]], uvs: &[[DVec2; 3]], offset: usize) -> Self {
        SurfaceMap {
            resolution,
            mapping: Mapping::Uv(uvs.iter().map(|t| t.map(|q| q.as_vec2())).collect()),
            size_m: None,
            triangles: with_areas(tris, uvs),
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

/// Each triangle's (u, v) image with its area.
fn with_areas(tris: &[[DVec3; 3]], uvs: &[[DVec2; 3]]) -> Vec<([DVec2; 3], f64)> {
    tris.iter().zip(uvs).map(|(t, q)| (*q, 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length())).collect()
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

/// A file name for a surface's map: its name with anything but letters, digits, '-' and '_'
/// replaced by '_'.
pub fn file_stem(surface: &str) -> String {
    surface.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' }).collect()
}

/// The map file of a surface inside `maps/`: `<stem>.<ext>`.
pub fn file_name(surface: &str, ext: &str) -> String {
    format!("{}.{ext}", file_stem(surface))
}
