//! STL meshes, ASCII and binary: the triangles of CAD exports. Written here rather than taken
//! from a crate so that a malformed file is reported with its line (ASCII) or byte offset
//! (binary). Facet normals in the file are ignored: a triangle's side is its winding (counter-
//! clockwise seen from its front, as the format prescribes), like every other mesh's.

use std::path::Path;

use glam::DVec3;

use super::obj::ObjTriangle;
use crate::error::InputError;

/// Bytes of a binary STL's header and of each of its triangles (normal, three corners as f32,
/// a u16 attribute count).
const HEADER_BYTES: usize = 80;
const TRIANGLE_BYTES: usize = 50;

/// Reads the triangles of an STL file, binary or ASCII. A file is binary when its size is
/// exactly 84 + 50·n bytes for the n its header gives (CAD programs often start binary files
/// with "solid" too), ASCII when it starts with "solid" and is not. Zero-area triangles are
/// skipped with one warning.
pub fn read_stl(path: &Path, warnings: &mut Vec<String>) -> Result<Vec<ObjTriangle>, InputError> {
    let bytes = crate::error::read_input(path, "mesh file")?;
    let binary_size = (bytes.len() >= HEADER_BYTES + 4)
        .then(|| u32::from_le_bytes(bytes[HEADER_BYTES..HEADER_BYTES + 4].try_into().expect("4 bytes")) as usize)
        .map(|n| HEADER_BYTES + 4 + TRIANGLE_BYTES * n);
    let (tris, skipped) = if binary_size == Some(bytes.len()) {
        read_binary(path, &bytes)?
    } else if bytes.trim_ascii_start().starts_with(b"solid") && !bytes.contains(&0) {
        // (A NUL is no ASCII STL's: a "solid"-headed binary file of the wrong size is reported
        // as binary below.)
        read_ascii(path, &String::from_utf8_lossy(&bytes))?
    } else {
        let m = match binary_size {
            Some(size) => format!(
                "a binary STL whose header gives {} triangles must be {size} bytes long, but the file has {} \
                 (truncated, or not an STL file)",
                (size - HEADER_BYTES - 4) / TRIANGLE_BYTES,
                bytes.len()
            ),
            None => format!("{} bytes: too short for a binary STL (84 bytes at least), and not ASCII STL", bytes.len()),
        };
        return Err(InputError::new(path, "", None, m));
    };
    if tris.is_empty() {
        return Err(InputError::new(path, "", None, "the mesh has no triangles with non-zero area"));
    }
    if let Some((first, n)) = skipped {
        warnings.push(format!(
            "{}: {n} triangle(s) with zero area (repeated or collinear corners), the first at {first}; skipped",
            path.display()
        ));
    }
    Ok(tris)
}

/// The triangle `t` when it encloses area; its first edge is its tangent (no texture coordinates).
fn triangle(t: [DVec3; 3]) -> Option<ObjTriangle> {
    ((t[1] - t[0]).cross(t[2] - t[0]).length() > 0.0).then(|| ObjTriangle {
        verts: t,
        uv: None,
        tangent: t[1] - t[0],
        normals: None,
    })
}

/// (triangles, (where the first zero-area one is, how many)).
type Read = (Vec<ObjTriangle>, Option<(String, usize)>);

fn read_binary(path: &Path, bytes: &[u8]) -> Result<Read, InputError> {
    let n = (bytes.len() - HEADER_BYTES - 4) / TRIANGLE_BYTES;
    let mut tris = Vec::with_capacity(n);
    let mut skipped: Option<(String, usize)> = None;
    for k in 0..n {
        let at = HEADER_BYTES + 4 + k * TRIANGLE_BYTES;
        let f = |i: usize| {
            let o = at + 12 + 4 * i;
            f32::from_le_bytes(bytes[o..o + 4].try_into().expect("4 bytes")) as f64
        };
        let corner = |c: usize| DVec3::new(f(3 * c), f(3 * c + 1), f(3 * c + 2));
        let t = [corner(0), corner(1), corner(2)];
        if let Some(bad) = t.iter().flat_map(|p| p.to_array()).position(|x| !x.is_finite()) {
            return Err(InputError::new(
                path,
                "",
                None,
                format!("triangle {} (byte {}) has a coordinate that is not a finite number", k + 1, at + 12 + 4 * bad),
            ));
        }
        match triangle(t) {
            Some(t) => tris.push(t),
            None => {
                let s = skipped.get_or_insert_with(|| (format!("triangle {} (byte {at})", k + 1), 0));
                s.1 += 1;
            }
        }
    }
    Ok((tris, skipped))
}

fn read_ascii(path: &Path, text: &str) -> Result<Read, InputError> {
    let err = |line: usize, m: String| InputError::new(path, "", Some(line), m);
    let mut tris = Vec::new();
    let mut skipped: Option<(String, usize)> = None;
    // Where the reader is: outside a facet, inside one (its line and corners so far), or past
    // its `endloop`.
    let mut facet: Option<(usize, Vec<DVec3>, bool)> = None;
    let mut ended = false;
    let mut last = 0;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        last = line_no;
        let mut words = raw.split_whitespace();
        let Some(word) = words.next() else { continue };
        if ended {
            return Err(err(line_no, format!("\"{}\" after `endsolid`", raw.trim())));
        }
        match (word, &mut facet) {
            ("solid", None) if line_no == first_line(text) => {}
            ("facet", None) => {
                if words.next() != Some("normal") {
                    return Err(err(line_no, "expected `facet normal nx ny nz`".into()));
                }
                facet = Some((line_no, Vec::new(), false));
            }
            ("outer", Some((_, corners, false))) if corners.is_empty() => {
                if words.next() != Some("loop") {
                    return Err(err(line_no, "expected `outer loop`".into()));
                }
            }
            ("vertex", Some((_, corners, false))) => {
                let xyz: Vec<f64> = words.by_ref().take(3).map(|w| w.parse::<f64>().unwrap_or(f64::NAN)).collect();
                if xyz.len() != 3 || xyz.iter().any(|x| !x.is_finite()) || words.next().is_some() {
                    return Err(err(
                        line_no,
                        format!(
                            "malformed vertex: expected `vertex x y z` with finite numbers, found \"{}\"",
                            raw.trim()
                        ),
                    ));
                }
                if corners.len() == 3 {
                    return Err(err(line_no, "a facet has more than 3 vertices: STL facets are triangles".into()));
                }
                corners.push(DVec3::new(xyz[0], xyz[1], xyz[2]));
            }
            ("endloop", Some((start, corners, done))) if !*done => {
                if corners.len() != 3 {
                    return Err(err(
                        line_no,
                        format!("the facet begun at line {start} has {} vertices, not 3", corners.len()),
                    ));
                }
                *done = true;
            }
            ("endfacet", Some((start, corners, true))) => {
                match triangle([corners[0], corners[1], corners[2]]) {
                    Some(t) => tris.push(t),
                    None => {
                        let s = skipped.get_or_insert_with(|| (format!("line {start}"), 0));
                        s.1 += 1;
                    }
                }
                facet = None;
            }
            ("endsolid", None) => ended = true,
            (w, Some((start, _, _))) => {
                return Err(err(line_no, format!("unexpected `{w}` inside the facet begun at line {start}")))
            }
            (w, None) => return Err(err(line_no, format!("unexpected `{w}`: expected `facet normal` or `endsolid`"))),
        }
    }
    if let Some((start, _, _)) = facet {
        return Err(err(last, format!("the file ends inside the facet begun at line {start}")));
    }
    if !ended {
        return Err(err(last, "the file ends without `endsolid` (truncated?)".into()));
    }
    Ok((tris, skipped))
}

/// The number of the first line that holds anything.
fn first_line(text: &str) -> usize {
    text.lines().position(|l| !l.trim().is_empty()).map_or(1, |i| i + 1)
}
