//! Shapes → triangles, in the scene file's units (the loader scales them to metres).

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use glam::{DMat3, DVec2, DVec3};

use super::doc::{child_path, Node, Source, R};
use super::obj;
use crate::error::InputError;

/// `transform = { translate, rotate_deg = [x, y, z], scale }`: scale, then rotate about x, y, z
/// (in that order, fixed axes), then translate.
#[derive(Clone, Debug)]
pub struct Transform {
    pub linear: DMat3,
    pub translate: DVec3,
}

impl Default for Transform {
    fn default() -> Self {
        Transform { linear: DMat3::IDENTITY, translate: DVec3::ZERO }
    }
}

impl Transform {
    pub fn apply_point(&self, p: DVec3) -> DVec3 {
        self.linear * p + self.translate
    }

    pub fn apply_dir(&self, d: DVec3) -> DVec3 {
        (self.linear * d).normalize()
    }

    /// A mirroring transform reverses triangle winding; we swap it back so normals keep their side.
    fn flips(&self) -> bool {
        self.linear.determinant() < 0.0
    }
}

#[derive(Clone, Debug)]
pub enum ShapeSpec {
    Quad {
        corners: [[f64; 3]; 4],
        transform: Transform,
    },
    Disk {
        center: [f64; 3],
        normal: [f64; 3],
        radius: f64,
        segments: u32,
        transform: Transform,
    },
    Sphere {
        center: [f64; 3],
        radius: f64,
        subdivisions: u32,
        transform: Transform,
    },
    Box {
        min: [f64; 3],
        max: [f64; 3],
        transform: Transform,
    },
    Mesh {
        file: PathBuf,
        key_line: usize,
        transform: Transform,
    },
    Point {
        position: [f64; 3],
        transform: Transform,
    },
    /// A ray set read from its file (lights only), in the file's coordinates before `transform`.
    Rays {
        set: std::sync::Arc<crate::scene::rays::RaySet>,
        file: PathBuf,
        transform: Transform,
    },
}

impl ShapeSpec {
    /// Triangles the shape will make, where that is known before it is made (a mesh's only once
    /// its file is read).
    pub fn triangle_count(&self) -> Option<u64> {
        match self {
            ShapeSpec::Quad { .. } => Some(2),
            ShapeSpec::Disk { segments, .. } => Some(*segments as u64),
            ShapeSpec::Sphere { subdivisions, .. } => Some(20 << (2 * *subdivisions as u64)),
            ShapeSpec::Box { .. } => Some(12),
            ShapeSpec::Point { .. } | ShapeSpec::Rays { .. } => Some(0),
            ShapeSpec::Mesh { .. } => None,
        }
    }

    /// The shape's `transform` (identity when none was given).
    pub fn transform(&self) -> &Transform {
        match self {
            ShapeSpec::Quad { transform, .. }
            | ShapeSpec::Disk { transform, .. }
            | ShapeSpec::Sphere { transform, .. }
            | ShapeSpec::Box { transform, .. }
            | ShapeSpec::Mesh { transform, .. }
            | ShapeSpec::Point { transform, .. }
            | ShapeSpec::Rays { transform, .. } => transform,
        }
    }
}

pub fn parse_shape(n: Node, base_dir: &Path, is_light: bool) -> R<ShapeSpec> {
    let t = n.table()?;
    let kind = t.req_str("type")?;
    let transform = t.with("transform", parse_transform)?.unwrap_or_default();
    let positive = |key: &str| -> R<f64> {
        t.require(key, |n| {
            let v = n.f64()?;
            if v <= 0.0 {
                return Err(n.err(format!("{key} must be positive, found {v}")));
            }
            Ok(v)
        })
    };
    let count = |key: &str, default: u64, lo: u64, hi: u64| -> R<u64> {
        Ok(t.with(key, |n| {
            let v = n.u64()?;
            if v < lo || v > hi {
                return Err(n.err(format!("{key} must be between {lo} and {hi}, found {v}")));
            }
            Ok(v)
        })?
        .unwrap_or(default))
    };
    match kind.as_str() {
        "quad" => {
            t.allow(&["type", "corners", "transform"])?;
            let corners = t.require("corners", |n| {
                let c = n.each(|p| p.vec3())?;
                <[[f64; 3]; 4]>::try_from(c).map_err(|c| n.err(format!("a quad needs 4 corners, found {}", c.len())))
            })?;
            Ok(ShapeSpec::Quad { corners, transform })
        }
        "disk" => {
            t.allow(&["type", "center", "normal", "radius", "segments", "transform"])?;
            let center = t.req_vec3("center")?;
            let normal = t.require("normal", |n| {
                let v = n.vec3()?;
                if DVec3::from(v).length() == 0.0 {
                    return Err(n.err("normal must not be the zero vector"));
                }
                Ok(v)
            })?;
            let radius = positive("radius")?;
            let segments = count("segments", 256, 3, 1 << 16)? as u32;
            Ok(ShapeSpec::Disk { center, normal, radius, segments, transform })
        }
        "sphere" => {
            t.allow(&["type", "center", "radius", "subdivisions", "transform"])?;
            let center = t.req_vec3("center")?;
            let radius = positive("radius")?;
            let subdivisions = count("subdivisions", 5, 0, 9)? as u32;
            Ok(ShapeSpec::Sphere { center, radius, subdivisions, transform })
        }
        "box" => {
            t.allow(&["type", "min", "max", "transform"])?;
            let min = t.req_vec3("min")?;
            let max = t.req_vec3("max")?;
            if (0..3).any(|i| max[i] <= min[i]) {
                return Err(t.err_at("max", "every coordinate of max must exceed min's"));
            }
            Ok(ShapeSpec::Box { min, max, transform })
        }
        "mesh" => {
            t.allow(&["type", "file", "transform"])?;
            let file = t.req_str("file")?;
            Ok(ShapeSpec::Mesh { file: base_dir.join(file), key_line: t.line_of_key("file"), transform })
        }
        "point" => {
            if !is_light {
                return Err(t.err_at("type", "a point has no area: `point` is for lights only"));
            }
            t.allow(&["type", "position", "transform"])?;
            Ok(ShapeSpec::Point { position: t.req_vec3("position")?, transform })
        }
        "rays" => {
            if !is_light {
                return Err(t.err_at("type", "a ray set has no area: `rays` is for lights only"));
            }
            t.allow(&["type", "file", "transform"])?;
            let rel = t.req_str("file")?;
            let file = base_dir.join(rel);
            let line = t.line_of_key("file");
            let set = crate::scene::rays::read(&file).map_err(|mut e| {
                e.message = format!("{} (ray set named by `{}` at line {line})", e.message, child_path(t.path, "file"));
                e
            })?;
            Ok(ShapeSpec::Rays { set: std::sync::Arc::new(set), file, transform })
        }
        other => Err(t.err_at(
            "type",
            format!(
                "unknown shape type \"{other}\"; known types: quad, disk, sphere, box, mesh{}",
                if is_light { ", point, rays" } else { "" }
            ),
        )),
    }
}

fn parse_transform(n: Node) -> R<Transform> {
    let t = n.table()?;
    t.allow(&["translate", "rotate_deg", "scale"])?;
    let translate = DVec3::from(t.vec3("translate")?.unwrap_or([0.0; 3]));
    let rot = DVec3::from(t.vec3("rotate_deg")?.unwrap_or([0.0; 3])) * (PI / 180.0);
    let scale = t
        .with("scale", |n| {
            let s = if n.is_number() { DVec3::splat(n.f64()?) } else { DVec3::from(n.vec3()?) };
            if s.x == 0.0 || s.y == 0.0 || s.z == 0.0 {
                return Err(n.err("scale must not be zero along any axis"));
            }
            Ok(s)
        })?
        .unwrap_or(DVec3::ONE);
    let linear = DMat3::from_rotation_z(rot.z)
        * DMat3::from_rotation_y(rot.y)
        * DMat3::from_rotation_x(rot.x)
        * DMat3::from_diagonal(scale);
    Ok(Transform { linear, translate })
}

fn twice_area(t: &[DVec3; 3]) -> f64 {
    (t[1] - t[0]).cross(t[2] - t[0]).length()
}

/// A shape's triangles in scene units, after its transform.
pub struct Triangles {
    pub tris: Vec<[DVec3; 3]>,
    /// A mesh's unit vertex normals per triangle, for smooth shading (None for a triangle
    /// without them; None for a shape without any).
    pub normals: Option<Vec<Option<[DVec3; 3]>>>,
    /// Each triangle's surface tangent, the u axis of an anisotropic material (`[αu, αv]`), not
    /// normalised and not yet projected into the triangle's plane (`Geometry` does both):
    /// * quad: its first edge, corners[1] − corners[0], on both halves;
    /// * disk: the first axis e₁ of its in-plane frame, the one its map's u and its first rim
    ///   vertex lie along (`DVec3::any_orthonormal_pair` of the unit normal (x, y, z), with
    ///   σ = sign z: e₁ = (1 − x²/(1 + |z|), −xy/(1 + |z|), −σx), so +x for every normal
    ///   perpendicular to x);
    /// * sphere: ∂P/∂φ at each triangle's centroid, φ the longitude about the sphere's own z
    ///   axis (along the parallels, eastward), so a brushed sphere is brushed around z;
    /// * box: the first of its own axes x, y, z lying in the face: y on the ±x faces, x on the
    ///   ±y and ±z faces;
    /// * mesh: ∂P/∂u from the texture coordinates, else the face's first edge (`obj::read_obj`).
    ///
    /// All before the transform, then turned and stretched by its linear part as the surface is.
    pub tangents: Vec<DVec3>,
    /// Texture coordinates, when the shape is a mesh whose every face has them.
    pub uvs: Option<Vec<[DVec2; 3]>>,
}

/// The triangles of a shape (not a point), transformed, in scene units.
pub fn triangulate(
    shape: &ShapeSpec,
    src: &Source,
    key: &str,
    line: usize,
    warnings: &mut Vec<String>,
) -> Result<Triangles, InputError> {
    let mut uvs: Option<Vec<[DVec2; 3]>> = None;
    let mut normals: Option<Vec<Option<[DVec3; 3]>>> = None;
    let (raw, tangents, transform): (Vec<[DVec3; 3]>, Vec<DVec3>, &Transform) = match shape {
        ShapeSpec::Quad { corners, transform } => {
            let [a, b, c, d] = corners.map(DVec3::from);
            let tris = vec![[a, b, c], [a, c, d]];
            let (n0, n1) = ((b - a).cross(c - a), (c - a).cross(d - a));
            if n0.dot(n1) < 0.0 {
                return Err(InputError::new(
                    src.file,
                    key,
                    Some(line),
                    "the quad's corners do not go around it in order: its two halves face opposite ways",
                ));
            }
            let total = twice_area(&tris[0]) + twice_area(&tris[1]);
            let scale = [a, b, c, d].iter().map(|p| p.abs().max_element()).fold(0.0, f64::max).max(1e-300);
            if total <= 1e-12 * scale * scale {
                return Err(InputError::new(
                    src.file,
                    key,
                    Some(line),
                    "degenerate quad: its corners enclose zero area",
                ));
            }
            let tris: Vec<_> = tris.into_iter().filter(|t| twice_area(t) > 0.0).collect();
            let tangents = vec![b - a; tris.len()];
            (tris, tangents, transform)
        }
        ShapeSpec::Disk { center, normal, radius, segments, transform } => {
            let c = DVec3::from(*center);
            let n = DVec3::from(*normal).normalize();
            let (u, v) = n.any_orthonormal_pair();
            let ring: Vec<DVec3> = (0..*segments)
                .map(|i| {
                    let phi = 2.0 * PI * i as f64 / *segments as f64;
                    c + *radius * (phi.cos() * u + phi.sin() * v)
                })
                .collect();
            // (u, v, n) is right-handed, so (c, ring[i], ring[i+1]) has normal +n.
            let tris: Vec<_> = (0..ring.len()).map(|i| [c, ring[i], ring[(i + 1) % ring.len()]]).collect();
            let tangents = vec![u; tris.len()];
            (tris, tangents, transform)
        }
        ShapeSpec::Sphere { center, radius, subdivisions, transform } => {
            let c = DVec3::from(*center);
            let unit = icosphere(*subdivisions);
            // ∂P/∂φ ∝ ẑ × p at the centroid p.
            let tangents = unit.iter().map(|t| DVec3::Z.cross(t[0] + t[1] + t[2])).collect();
            let tris = unit.into_iter().map(|t| t.map(|p| c + *radius * p)).collect();
            (tris, tangents, transform)
        }
        ShapeSpec::Box { min, max, transform } => {
            // Two triangles per face, faces in the order −x, +x, −y, +y, −z, +z.
            let tangents =
                [DVec3::Y, DVec3::Y, DVec3::X, DVec3::X, DVec3::X, DVec3::X].iter().flat_map(|&t| [t, t]).collect();
            (box_triangles(DVec3::from(*min), DVec3::from(*max)), tangents, transform)
        }
        ShapeSpec::Mesh { file, key_line, transform } => {
            let faces = read_mesh(file, warnings).map_err(|mut e| {
                e.message = format!("{} (mesh named by `{key}` at {}:{key_line})", e.message, src.file.display());
                e
            })?;
            uvs = faces.iter().map(|f| f.uv).collect();
            if faces.iter().any(|f| f.normals.is_some()) {
                normals = Some(faces.iter().map(|f| f.normals).collect());
            }
            let tangents = faces.iter().map(|f| f.tangent).collect();
            (faces.into_iter().map(|f| f.verts).collect(), tangents, transform)
        }
        ShapeSpec::Point { .. } | ShapeSpec::Rays { .. } => unreachable!("points and ray sets are not triangulated"),
    };
    let flip = transform.flips();
    let tris = raw
        .into_iter()
        .map(|t| {
            let p = t.map(|v| transform.apply_point(v));
            if flip {
                [p[0], p[2], p[1]]
            } else {
                p
            }
        })
        .collect();
    // A tangent is a direction in the surface: the linear part maps it into the moved surface
    // (normals need the inverse transpose; tangents do not).
    let tangents = tangents.into_iter().map(|t| transform.linear * t).collect();
    let uvs = uvs.map(|u| u.into_iter().map(|t| if flip { [t[0], t[2], t[1]] } else { t }).collect());
    // Normals map by the inverse transpose of the linear part (they stay perpendicular to the
    // moved surface), then unit again.
    let normal_map = transform.linear.inverse().transpose();
    let normals = normals.map(|all| {
        all.into_iter()
            .map(|n| {
                n.map(|t| {
                    let m = t.map(|v| (normal_map * v).normalize_or_zero());
                    if flip {
                        [m[0], m[2], m[1]]
                    } else {
                        m
                    }
                })
            })
            .collect()
    });
    Ok(Triangles { tris, tangents, uvs, normals })
}

/// Axis-aligned box, 12 triangles, normals outward.
fn box_triangles(lo: DVec3, hi: DVec3) -> Vec<[DVec3; 3]> {
    let p = |x: bool, y: bool, z: bool| {
        DVec3::new(if x { hi.x } else { lo.x }, if y { hi.y } else { lo.y }, if z { hi.z } else { lo.z })
    };
    // Each face as a counter-clockwise quad seen from outside.
    let faces = [
        [p(false, false, false), p(false, false, true), p(false, true, true), p(false, true, false)], // -x
        [p(true, false, false), p(true, true, false), p(true, true, true), p(true, false, true)],     // +x
        [p(false, false, false), p(true, false, false), p(true, false, true), p(false, false, true)], // -y
        [p(false, true, false), p(false, true, true), p(true, true, true), p(true, true, false)],     // +y
        [p(false, false, false), p(false, true, false), p(true, true, false), p(true, false, false)], // -z
        [p(false, false, true), p(true, false, true), p(true, true, true), p(false, true, true)],     // +z
    ];
    faces.iter().flat_map(|[a, b, c, d]| [[*a, *b, *c], [*a, *c, *d]]).collect()
}

/// Unit icosphere: the icosahedron with each triangle split in four `level` times, vertices
/// pushed onto the sphere. Midpoints are computed symmetrically ((a+b)/2 is commutative), so
/// neighbouring triangles share bit-identical vertices and the mesh is closed.
pub fn icosphere(level: u32) -> Vec<[DVec3; 3]> {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let v: Vec<DVec3> = [
        [-1.0, phi, 0.0],
        [1.0, phi, 0.0],
        [-1.0, -phi, 0.0],
        [1.0, -phi, 0.0],
        [0.0, -1.0, phi],
        [0.0, 1.0, phi],
        [0.0, -1.0, -phi],
        [0.0, 1.0, -phi],
        [phi, 0.0, -1.0],
        [phi, 0.0, 1.0],
        [-phi, 0.0, -1.0],
        [-phi, 0.0, 1.0],
    ]
    .iter()
    .map(|p| DVec3::from(*p).normalize())
    .collect();
    let faces = [
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let mut tris: Vec<[DVec3; 3]> = faces.iter().map(|f| [v[f[0]], v[f[1]], v[f[2]]]).collect();
    for _ in 0..level {
        let mid = |a: DVec3, b: DVec3| ((a + b) * 0.5).normalize();
        tris = tris
            .iter()
            .flat_map(|&[a, b, c]| {
                let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    tris
}

/// A mesh file's triangles, its format chosen by extension: `.stl` (ASCII or binary STL), else
/// `.ply`, else Wavefront OBJ. glTF is not read yet, and is refused rather than misread as OBJ.
fn read_mesh(file: &Path, warnings: &mut Vec<String>) -> Result<Vec<obj::ObjTriangle>, InputError> {
    let ext = file.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("stl") => super::stl::read_stl(file, warnings),
        Some("ply") => super::ply::read_ply(file, warnings),
        Some("gltf" | "glb") => super::gltf::read_gltf(file, warnings),
        _ => obj::read_obj(file, warnings),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangle_counts_are_known_ahead() {
        let t = Transform::default();
        for (shape, n) in [
            (ShapeSpec::Sphere { center: [0.0; 3], radius: 1.0, subdivisions: 3, transform: t.clone() }, 1280),
            (
                ShapeSpec::Disk {
                    center: [0.0; 3],
                    normal: [0.0, 0.0, 1.0],
                    radius: 1.0,
                    segments: 17,
                    transform: t.clone(),
                },
                17,
            ),
            (ShapeSpec::Box { min: [0.0; 3], max: [1.0; 3], transform: t.clone() }, 12),
            (
                ShapeSpec::Quad {
                    corners: [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
                    transform: t,
                },
                2,
            ),
        ] {
            let src = Source::new(Path::new("t.toml"), "");
            let made = triangulate(&shape, &src, "shape", 1, &mut Vec::new()).unwrap().tris.len() as u64;
            assert_eq!((shape.triangle_count(), made), (Some(n), n));
        }
    }

    #[test]
    fn icosphere_normals_point_outward() {
        for t in icosphere(2) {
            let n = (t[1] - t[0]).cross(t[2] - t[0]);
            assert!(n.dot(t[0] + t[1] + t[2]) > 0.0);
        }
    }

    #[test]
    fn box_normals_point_outward() {
        let lo = DVec3::new(-1.0, -2.0, -3.0);
        let hi = DVec3::new(1.0, 2.0, 3.0);
        for t in box_triangles(lo, hi) {
            let n = (t[1] - t[0]).cross(t[2] - t[0]);
            assert!(n.dot((t[0] + t[1] + t[2]) / 3.0) > 0.0);
        }
    }
}
