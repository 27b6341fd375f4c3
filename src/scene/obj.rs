//! A small Wavefront OBJ reader: `v`, `vt`, `vn` and `f` statements (polygons fan-triangulated,
//! `v/vt/vn`, `v//vn` and negative indices accepted); everything else is ignored. Written here rather than taken
//! from tobj so that every malformed statement is reported with its line number.

use std::path::Path;

use glam::{DVec2, DVec3};

use crate::error::InputError;

/// One triangle of a mesh: its corners, their texture coordinates when the face gives them
/// (`v/vt`), and its surface tangent (`tangent`).
pub struct ObjTriangle {
    pub verts: [DVec3; 3],
    pub uv: Option<[DVec2; 3]>,
    pub tangent: DVec3,
    /// Unit vertex normals for smooth shading, when the face gives them (`v/vt/vn`, `v//vn`).
    pub normals: Option<[DVec3; 3]>,
}

/// A triangle's surface tangent, the u axis of an anisotropic material: ∂P/∂u of the map from
/// its texture coordinates to its corners when it has them and they enclose area, else its
/// face's first edge (first vertex to second as listed, shared by all of a polygon's triangles,
/// or the triangle's own where those two coincide).
/// With P = P₀ + (u − u₀)∂P/∂u + (v − v₀)∂P/∂v on the triangle, the edges e₁ = P₁ − P₀,
/// e₂ = P₂ − P₀ and their (Δu, Δv) give ∂P/∂u = (Δv₂ e₁ − Δv₁ e₂)/(Δu₁Δv₂ − Δu₂Δv₁).
pub(super) fn tangent(t: &[DVec3; 3], uv: Option<[DVec2; 3]>, first_edge: DVec3) -> DVec3 {
    if let Some(q) = uv {
        let (d1, d2) = (q[1] - q[0], q[2] - q[0]);
        let det = d1.x * d2.y - d2.x * d1.y;
        // Relative to the UV edges' size: rounding noise is not an area.
        if det.abs() > 1e-9 * d1.length_squared().max(d2.length_squared()) {
            let dpdu = ((t[1] - t[0]) * d2.y - (t[2] - t[0]) * d1.y) / det;
            if dpdu.length_squared() > 0.0 && dpdu.is_finite() {
                return dpdu;
            }
        }
    }
    // A polygon starting with a repeated vertex: the triangle's own first edge.
    if first_edge.length_squared() > 0.0 {
        first_edge
    } else {
        t[1] - t[0]
    }
}

/// Reads the triangles of an OBJ file. Zero-area triangles (repeated or collinear vertices) can
/// never be hit: each is skipped with a warning naming the file, the line and the face.
pub fn read_obj(path: &Path, warnings: &mut Vec<String>) -> Result<Vec<ObjTriangle>, InputError> {
    let text = crate::error::read_text_lossy(path, "mesh file")?;
    let err = |line: usize, m: String| InputError::new(path, "", Some(line), m);
    let mut verts: Vec<DVec3> = Vec::new();
    let mut texcoords: Vec<DVec2> = Vec::new();
    let mut normals: Vec<DVec3> = Vec::new();
    let mut tris: Vec<ObjTriangle> = Vec::new();
    let mut face = 0usize;
    // (line, face) of each zero-area triangle, skipped.
    let mut flat: Vec<(usize, usize)> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let xyz: Vec<f64> = words.take(3).map(|w| w.parse::<f64>().unwrap_or(f64::NAN)).collect();
                if xyz.len() != 3 || xyz.iter().any(|x| !x.is_finite()) {
                    return Err(err(
                        line_no,
                        format!("malformed vertex: expected `v x y z` with finite numbers, found \"{line}\""),
                    ));
                }
                verts.push(DVec3::new(xyz[0], xyz[1], xyz[2]));
            }
            Some("vt") => {
                let uv: Vec<f64> = words.take(2).map(|w| w.parse::<f64>().unwrap_or(f64::NAN)).collect();
                if uv.is_empty() || uv.iter().any(|x| !x.is_finite()) {
                    return Err(err(
                        line_no,
                        format!(
                            "malformed texture coordinate: expected `vt u [v]` with finite numbers, found \"{line}\""
                        ),
                    ));
                }
                texcoords.push(DVec2::new(uv[0], uv.get(1).copied().unwrap_or(0.0)));
            }
            Some("vn") => {
                let xyz: Vec<f64> = words.take(3).map(|w| w.parse::<f64>().unwrap_or(f64::NAN)).collect();
                let n = (xyz.len() == 3).then(|| DVec3::new(xyz[0], xyz[1], xyz[2]));
                match n {
                    Some(n) if n.is_finite() && n.length() > 0.0 => normals.push(n.normalize()),
                    _ => {
                        return Err(err(
                            line_no,
                            format!("malformed normal: expected `vn x y z`, finite and not all zero, found \"{line}\""),
                        ))
                    }
                }
            }
            Some("f") => {
                let mut idx = Vec::new();
                let mut tex: Vec<Option<usize>> = Vec::new();
                let mut nor: Vec<Option<usize>> = Vec::new();
                for w in words {
                    let mut parts = w.split('/');
                    let first = parts.next().unwrap_or("");
                    let t = match parts.next().filter(|t| !t.is_empty()) {
                        None => None,
                        Some(t) => {
                            let k: i64 =
                                t.parse().map_err(|_| err(line_no, format!("malformed texture index in \"{w}\"")))?;
                            let resolved = if k > 0 { k - 1 } else { texcoords.len() as i64 + k };
                            if k == 0 || resolved < 0 || resolved >= texcoords.len() as i64 {
                                return Err(err(
                                    line_no,
                                    format!("texture index {k} refers to no `vt` ({} defined so far)", texcoords.len()),
                                ));
                            }
                            Some(resolved as usize)
                        }
                    };
                    tex.push(t);
                    let normal = match parts.next().filter(|t| !t.is_empty()) {
                        None => None,
                        Some(t) => {
                            let k: i64 =
                                t.parse().map_err(|_| err(line_no, format!("malformed normal index in \"{w}\"")))?;
                            let resolved = if k > 0 { k - 1 } else { normals.len() as i64 + k };
                            if k == 0 || resolved < 0 || resolved >= normals.len() as i64 {
                                return Err(err(
                                    line_no,
                                    format!("normal index {k} refers to no `vn` ({} defined so far)", normals.len()),
                                ));
                            }
                            Some(resolved as usize)
                        }
                    };
                    nor.push(normal);
                    let k: i64 = first.parse().map_err(|_| err(line_no, format!("malformed face index \"{w}\"")))?;
                    // OBJ indices are 1-based; negative ones count back from the last vertex.
                    let resolved = if k > 0 { k - 1 } else { verts.len() as i64 + k };
                    if k == 0 || resolved < 0 || resolved >= verts.len() as i64 {
                        return Err(err(
                            line_no,
                            format!("face index {k} refers to no vertex ({} defined so far)", verts.len()),
                        ));
                    }
                    idx.push(resolved as usize);
                }
                if idx.len() < 3 {
                    return Err(err(line_no, format!("a face needs at least 3 vertices, found {}", idx.len())));
                }
                face += 1;
                let first_edge = verts[idx[1]] - verts[idx[0]];
                for j in 1..idx.len() - 1 {
                    let t = [verts[idx[0]], verts[idx[j]], verts[idx[j + 1]]];
                    let uv = match (tex[0], tex[j], tex[j + 1]) {
                        (Some(a), Some(b), Some(c)) => Some([texcoords[a], texcoords[b], texcoords[c]]),
                        _ => None,
                    };
                    let vn = match (nor[0], nor[j], nor[j + 1]) {
                        (Some(a), Some(b), Some(c)) => Some([normals[a], normals[b], normals[c]]),
                        _ => None,
                    };
                    if (t[1] - t[0]).cross(t[2] - t[0]).length() > 0.0 {
                        tris.push(ObjTriangle { verts: t, uv, tangent: tangent(&t, uv, first_edge), normals: vn });
                    } else {
                        flat.push((line_no, face));
                    }
                }
            }
            _ => {}
        }
    }
    if tris.is_empty() {
        return Err(InputError::new(path, "", None, "the mesh has no faces with non-zero area"));
    }
    // One warning for all of them: a mesh may have thousands.
    if let Some(&(line, face)) = flat.first() {
        let more = match flat.len() {
            1 => String::new(),
            n => format!(", and {} more ({})", n - 1, summarise_faces(&flat[1..])),
        };
        warnings.push(format!(
            "{}:{line}: face {face} has zero area (repeated or collinear vertices){more}; skipped",
            path.display()
        ));
    }
    Ok(tris)
}

/// The first few (line, face) pairs of `items` as "face F at line L", then an ellipsis.
fn summarise_faces(items: &[(usize, usize)]) -> String {
    const SHOWN: usize = 5;
    let mut s: Vec<String> = items.iter().take(SHOWN).map(|(l, f)| format!("face {f} at line {l}")).collect();
    if items.len() > SHOWN {
        s.push("...".into());
    }
    s.join(", ")
}
