//! glTF 2.0 meshes (`.gltf` with external or embedded buffers, `.glb`): every triangle primitive
//! of every mesh its scene's nodes place, each moved by its node's world transform, with vertex
//! normals (smooth shading) and TEXCOORD_0 when present. The `gltf` crate parses and validates
//! the JSON and reads accessors; the buffers (a GLB's BIN chunk, base64 data URIs, files beside
//! the .gltf) are resolved here.
//!
//! Coordinates are taken in the scene's unit like every mesh's (glTF's own are metres, +y up:
//! give `[scene] unit = "m"`, or a `transform`). Triangle strips and fans are split into
//! triangles; points and lines have no area and are skipped with a warning.

use std::path::Path;

use glam::{DMat3, DMat4, DVec2, DVec3};

use super::obj::ObjTriangle;
use crate::error::InputError;

pub fn read_gltf(path: &Path, warnings: &mut Vec<String>) -> Result<Vec<ObjTriangle>, InputError> {
    let bytes = crate::error::read_input(path, "glTF file")?;
    // The crate validates indices and ranges, but its validation itself indexes past the end of
    // some malformed documents: such a panic is an error about the file, not a crash, and its
    // message is not printed (the hook is swapped while the file is read, on the loading thread
    // before any worker starts).
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let read = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parse(path, &bytes, warnings)));
    std::panic::set_hook(hook);
    match read {
        Ok(r) => r,
        Err(_) => Err(InputError::new(
            path,
            "",
            None,
            "malformed glTF: a reference to an accessor, buffer view or buffer points at nothing \
             (the glTF reader failed on it)",
        )),
    }
}

fn parse(path: &Path, bytes: &[u8], warnings: &mut Vec<String>) -> Result<Vec<ObjTriangle>, InputError> {
    let err = |m: String| InputError::new(path, "", None, m);
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| err(format!("malformed glTF: {}", describe(&e))))?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut buffers: Vec<Vec<u8>> = Vec::new();
    for b in gltf.buffers() {
        let data = match b.source() {
            gltf::buffer::Source::Bin => gltf
                .blob
                .clone()
                .ok_or_else(|| err(format!("buffer {} refers to a GLB binary chunk the file lacks", b.index())))?,
            gltf::buffer::Source::Uri(uri) => match uri.strip_prefix("data:") {
                Some(rest) => {
                    let (_, payload) = rest
                        .split_once(";base64,")
                        .ok_or_else(|| err(format!("buffer {}: a data URI must be base64 (`;base64,`)", b.index())))?;
                    base64(payload).map_err(|at| err(format!("buffer {}: bad base64 at character {at}", b.index())))?
                }
                None => {
                    let file = base.join(percent_decoded(uri));
                    std::fs::read(&file)
                        .map_err(|e| err(format!("buffer {}: cannot read {}: {e}", b.index(), file.display())))?
                }
            },
        };
        if data.len() < b.length() {
            return Err(err(format!(
                "buffer {} holds {} bytes but declares byteLength {}",
                b.index(),
                data.len(),
                b.length()
            )));
        }
        buffers.push(data);
    }
    let scenes: Vec<gltf::Scene> = match gltf.default_scene() {
        Some(s) => vec![s],
        None => gltf.scenes().collect(),
    };
    let mut tris = Vec::new();
    let mut skipped_modes = 0usize;
    let mut stack: Vec<(gltf::Node, DMat4)> = Vec::new();
    for scene in scenes {
        stack.extend(scene.nodes().map(|n| (n, DMat4::IDENTITY)));
    }
    // glTF node graphs are trees (the crate's validation refuses cycles); the depth bound keeps a
    // malformed file from looping regardless.
    let mut visited = 0usize;
    while let Some((node, parent)) = stack.pop() {
        visited += 1;
        if visited > 10_000_000 {
            return Err(err("the node hierarchy is too large (a cycle?)".into()));
        }
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        if let Some(mesh) = node.mesh() {
            for (k, primitive) in mesh.primitives().enumerate() {
                let what = format!("mesh {} primitive {k}", mesh.index());
                let added = primitive_triangles(&primitive, &buffers, world, &what).map_err(err)?;
                match added {
                    Some(t) => tris.extend(t),
                    None => skipped_modes += 1,
                }
            }
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    if skipped_modes > 0 {
        warnings.push(format!("{}: {skipped_modes} point or line primitive(s) have no area; skipped", path.display()));
    }
    if tris.is_empty() {
        return Err(err("the glTF scene places no triangle of non-zero area".into()));
    }
    Ok(tris)
}

/// A primitive's triangles in world coordinates; None for points and lines.
fn primitive_triangles(
    primitive: &gltf::Primitive,
    buffers: &[Vec<u8>],
    world: DMat4,
    what: &str,
) -> Result<Option<Vec<ObjTriangle>>, String> {
    use gltf::mesh::Mode;
    let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| d.as_slice()));
    let positions: Vec<DVec3> = reader
        .read_positions()
        .ok_or_else(|| format!("{what} has no POSITION attribute"))?
        .map(|p| world.transform_point3(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)))
        .collect();
    if let Some(k) = positions.iter().position(|p| !p.is_finite()) {
        return Err(format!("{what}: vertex {k} is not finite"));
    }
    let normal_map = DMat3::from_mat4(world).inverse().transpose();
    let normals: Option<Vec<DVec3>> = reader.read_normals().map(|it| {
        it.map(|n| (normal_map * DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64)).normalize_or_zero()).collect()
    });
    let uvs: Option<Vec<DVec2>> =
        reader.read_tex_coords(0).map(|t| t.into_f32().map(|q| DVec2::new(q[0] as f64, q[1] as f64)).collect());
    let count = positions.len();
    for (name, len) in [("NORMAL", normals.as_ref().map(Vec::len)), ("TEXCOORD_0", uvs.as_ref().map(Vec::len))] {
        if len.is_some_and(|l| l != count) {
            return Err(format!("{what}: {name} has {} items for {count} positions", len.unwrap_or(0)));
        }
    }
    let indices: Vec<usize> = match reader.read_indices() {
        Some(i) => i.into_u32().map(|v| v as usize).collect(),
        None => (0..count).collect(),
    };
    if let Some(&bad) = indices.iter().find(|&&i| i >= count) {
        return Err(format!("{what}: index {bad} refers to no vertex ({count} defined)"));
    }
    let corners: Vec<[usize; 3]> = match primitive.mode() {
        Mode::Triangles => indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        // Every second strip triangle is wound the other way round.
        Mode::TriangleStrip => (2..indices.len())
            .map(|k| {
                if k % 2 == 0 {
                    [indices[k - 2], indices[k - 1], indices[k]]
                } else {
                    [indices[k - 1], indices[k - 2], indices[k]]
                }
            })
            .collect(),
        Mode::TriangleFan => (2..indices.len()).map(|k| [indices[0], indices[k - 1], indices[k]]).collect(),
        _ => return Ok(None),
    };
    // A mirroring transform turns counterclockwise (glTF's front) into clockwise.
    let flip = DMat3::from_mat4(world).determinant() < 0.0;
    let mut out = Vec::with_capacity(corners.len());
    for c in corners {
        let c = if flip { [c[0], c[2], c[1]] } else { c };
        let t = c.map(|i| positions[i]);
        if !((t[1] - t[0]).cross(t[2] - t[0]).length() > 0.0) {
            continue;
        }
        let uv = uvs.as_ref().map(|u| c.map(|i| u[i]));
        let vn = normals.as_ref().map(|n| c.map(|i| n[i])).filter(|n| n.iter().all(|v| v.length_squared() > 0.0));
        out.push(ObjTriangle { verts: t, uv, tangent: super::obj::tangent(&t, uv, t[1] - t[0]), normals: vn });
    }
    Ok(Some(out))
}

/// The parser's error, with the JSON's line and column where it has them.
fn describe(e: &gltf::Error) -> String {
    match e {
        gltf::Error::Deserialize(j) => format!("line {}, column {}: {j}", j.line(), j.column()),
        gltf::Error::Validation(list) => {
            let first: Vec<String> = list.iter().take(3).map(|(path, why)| format!("{path}: {why}")).collect();
            format!("invalid: {}{}", first.join("; "), if list.len() > 3 { "; ..." } else { "" })
        }
        other => other.to_string(),
    }
}

/// A URI's %XX escapes decoded (file names with spaces are written `%20`).
fn percent_decoded(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut k = 0;
    while k < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[k] == b'%' && k + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[k + 1]), hex(b[k + 2])) {
                out.push((h * 16 + l) as u8);
                k += 3;
                continue;
            }
        }
        out.push(b[k]);
        k += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Standard base64 (RFC 4648, padding optional); Err(position) of the first bad character.
fn base64(s: &str) -> Result<Vec<u8>, usize> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0u32);
    for (k, c) in s.bytes().enumerate() {
        if c == b'=' {
            break;
        }
        let v = value(c).ok_or(k)?;
        acc = (acc << 6) | v as u32;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #[test]
    fn base64_decodes_rfc4648_examples() {
        assert_eq!(super::base64("Zm9vYmFy").unwrap(), b"foobar");
        assert_eq!(super::base64("Zm9vYg==").unwrap(), b"foob");
        assert_eq!(super::base64("Zm9vYg").unwrap(), b"foob");
        assert_eq!(super::base64("Zm9v!mFy"), Err(4));
    }

    #[test]
    fn percent_escapes_decode() {
        assert_eq!(super::percent_decoded("my%20mesh.bin"), "my mesh.bin");
        assert_eq!(super::percent_decoded("100%"), "100%");
    }
}
