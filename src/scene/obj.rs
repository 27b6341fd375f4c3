//! A small Wavefront OBJ reader: `v` and `f` statements (polygons fan-triangulated, `v/vt/vn`
//! and negative indices accepted); everything else is ignored. Written here rather than taken
//! from tobj so that every malformed statement is reported with its line number.

use std::path::Path;

use glam::DVec3;

use crate::error::InputError;

/// Reads the triangles of an OBJ file. Zero-area triangles (repeated or collinear vertices) can
/// never be hit: each is skipped with a warning naming the file, the line and the face.
pub fn read_obj(path: &Path, warnings: &mut Vec<String>) -> Result<Vec<[DVec3; 3]>, InputError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| InputError::new(path, "", None, format!("cannot read mesh file: {e}")))?;
    let err = |line: usize, m: String| InputError::new(path, "", Some(line), m);
    let mut verts: Vec<DVec3> = Vec::new();
    let mut tris: Vec<[DVec3; 3]> = Vec::new();
    let mut face = 0usize;
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
            Some("f") => {
                let mut idx = Vec::new();
                for w in words {
                    let first = w.split('/').next().unwrap_or("");
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
                for j in 1..idx.len() - 1 {
                    let t = [verts[idx[0]], verts[idx[j]], verts[idx[j + 1]]];
                    if (t[1] - t[0]).cross(t[2] - t[0]).length() > 0.0 {
                        tris.push(t);
                    } else {
                        warnings.push(format!(
                            "{}:{line_no}: face {face} has zero area (repeated or collinear vertices); skipped",
                            path.display()
                        ));
                    }
                }
            }
            _ => {}
        }
    }
    if tris.is_empty() {
        return Err(InputError::new(path, "", None, "the mesh has no faces with non-zero area"));
    }
    Ok(tris)
}
