//! PLY meshes (Turk's polygon file format): ASCII, binary little- and big-endian. Reads the
//! `vertex` element's x, y, z (and u, v or s, t texture coordinates when present) and the
//! `face` element's index lists (fan-triangulated); every other element and property is read
//! past. Vertex normals are read past too, until shading normals exist. Written here so that a
//! malformed file is reported with its line (header, ASCII body) or byte offset (binary body).

use std::path::Path;

use glam::{DVec2, DVec3};

use super::obj::ObjTriangle;
use crate::error::InputError;

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    Little,
    Big,
}

#[derive(Clone, Copy)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn bytes(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

struct Property {
    name: String,
    /// `Some(count type)` for a list property.
    list: Option<Scalar>,
    value: Scalar,
}

struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

/// The body's values, one at a time, with where each came from for messages.
struct Body<'a> {
    format: Format,
    bytes: &'a [u8],
    at: usize,
    /// The body's first byte in the file, so offsets in messages are the file's.
    start: usize,
    /// ASCII: the current line's number in the file, the header's lines before the body's, and
    /// the line's remaining words.
    line: usize,
    line_offset: usize,
    lines: std::iter::Peekable<std::iter::Enumerate<std::str::Lines<'a>>>,
    words: Vec<&'a str>,
}

impl Body<'_> {
    fn next(&mut self, s: Scalar) -> Result<f64, (Option<usize>, String)> {
        if self.format == Format::Ascii {
            while self.words.is_empty() {
                let Some((i, l)) = self.lines.next() else {
                    return Err((Some(self.line), "the file ends before its elements do".into()));
                };
                self.line = self.line_offset + i + 1;
                self.words = l.split_whitespace().rev().collect();
            }
            let w = self.words.pop().expect("not empty");
            return w.parse::<f64>().map_err(|_| (Some(self.line), format!("\"{w}\" is not a number")));
        }
        let n = s.bytes();
        let Some(raw) = self.bytes.get(self.at..self.at + n) else {
            return Err((
                None,
                format!("the file ends at byte {} before its elements do", self.start + self.bytes.len()),
            ));
        };
        let mut b = [0u8; 8];
        b[..n].copy_from_slice(raw);
        if self.format == Format::Big {
            b[..n].reverse();
        }
        self.at += n;
        Ok(match s {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(b),
        })
    }

    /// Where the value just read was: the line, or the byte offset.
    fn place(&self, width: usize) -> String {
        match self.format {
            Format::Ascii => format!("line {}", self.line),
            _ => format!("byte {}", self.start + self.at - width),
        }
    }
}

/// Reads the triangles of a PLY file. Zero-area triangles are skipped with one warning.
pub fn read_ply(path: &Path, warnings: &mut Vec<String>) -> Result<Vec<ObjTriangle>, InputError> {
    let bytes = crate::error::read_input(path, "mesh file")?;
    let at_line = |line: usize, m: String| InputError::new(path, "", Some(line), m);
    let at_byte = |m: String| InputError::new(path, "", None, m);
    // The header: ASCII lines up to `end_header`.
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n" || w == b"end_header\r")
        .ok_or_else(|| at_byte("no `end_header` line: not a PLY file, or its header is cut short".into()))?;
    let header_text = String::from_utf8_lossy(&bytes[..end]);
    // The body starts after `end_header` and its line end (LF or CRLF).
    let mut body_start = end + "end_header".len();
    if bytes.get(body_start) == Some(&b'\r') {
        body_start += 1;
    }
    if bytes.get(body_start) == Some(&b'\n') {
        body_start += 1;
    }
    let header_lines = header_text.lines().count() + 1;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for (i, line) in header_text.lines().enumerate() {
        let n = i + 1;
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["ply"] if n == 1 => {}
            _ if n == 1 => return Err(at_line(1, "the first line must be `ply`".into())),
            ["format", f, _] => {
                format = Some(match *f {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::Little,
                    "binary_big_endian" => Format::Big,
                    other => return Err(at_line(n, format!("unknown format \"{other}\""))),
                })
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["element", name, count] => {
                let count = count.parse().map_err(|_| at_line(n, format!("\"{count}\" is not an element count")))?;
                elements.push(Element { name: name.to_string(), count, properties: Vec::new() });
            }
            ["property", "list", c, v, name] => {
                let (Some(c), Some(v)) = (Scalar::parse(c), Scalar::parse(v)) else {
                    return Err(at_line(n, format!("unknown type in \"{line}\"")));
                };
                let e = elements.last_mut().ok_or_else(|| at_line(n, "a property before any element".into()))?;
                e.properties.push(Property { name: name.to_string(), list: Some(c), value: v });
            }
            ["property", t, name] => {
                let v = Scalar::parse(t).ok_or_else(|| at_line(n, format!("unknown type \"{t}\"")))?;
                let e = elements.last_mut().ok_or_else(|| at_line(n, "a property before any element".into()))?;
                e.properties.push(Property { name: name.to_string(), list: None, value: v });
            }
            _ => return Err(at_line(n, format!("unexpected header line \"{line}\""))),
        }
    }
    let format = format.ok_or_else(|| at_line(header_lines, "the header gives no `format`".into()))?;
    let vertex = elements.iter().position(|e| e.name == "vertex");
    let slot = |names: &[&str]| {
        vertex.and_then(|v| {
            elements[v].properties.iter().position(|p| p.list.is_none() && names.contains(&p.name.as_str()))
        })
    };
    let (Some(x), Some(y), Some(z)) = (slot(&["x"]), slot(&["y"]), slot(&["z"])) else {
        return Err(at_line(header_lines, "the header's `vertex` element lacks x, y or z".into()));
    };
    let uv = slot(&["u", "s", "texture_u"]).zip(slot(&["v", "t", "texture_v"]));
    let normal_slots = match (slot(&["nx"]), slot(&["ny"]), slot(&["nz"])) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    // A corrupt count must not allocate more than the file could hold (a byte a value at least).
    let left = bytes.len() - body_start;
    if elements.iter().any(|e| e.count > left) {
        return Err(at_line(header_lines, format!("an element count exceeds the file's {left} body bytes")));
    }
    // Items without properties take no bytes: their count would bound nothing.
    if let Some(e) = elements.iter().find(|e| e.count > 0 && e.properties.is_empty()) {
        return Err(at_line(header_lines, format!("the element `{}` has items but no properties", e.name)));
    }
    let body_text = if format == Format::Ascii {
        String::from_utf8_lossy(&bytes[body_start..]).into_owned()
    } else {
        String::new()
    };
    if vertex.is_some_and(|v| elements.iter().position(|e| e.name == "face").is_some_and(|f| f < v)) {
        return Err(at_line(
            header_lines,
            "the `face` element comes before `vertex`: faces index vertices read earlier".into(),
        ));
    }
    let mut body = Body {
        format,
        bytes: &bytes[body_start..],
        at: 0,
        start: body_start,
        line: header_lines,
        line_offset: header_lines,
        lines: body_text.lines().enumerate().peekable(),
        words: Vec::new(),
    };
    let fail = |_: &Body, e: (Option<usize>, String)| match e.0 {
        Some(line) => at_line(line, e.1),
        None => at_byte(e.1),
    };
    let mut verts: Vec<DVec3> = Vec::new();
    let mut texcoords: Vec<DVec2> = Vec::new();
    let mut normals: Vec<DVec3> = Vec::new();
    let mut tris = Vec::new();
    let mut skipped: Option<(String, usize)> = None;
    for (k, e) in elements.iter().enumerate() {
        let is_vertex = Some(k) == vertex;
        let is_face = e.name == "face";
        let mut values = vec![0.0f64; e.properties.len()];
        let mut corners: Vec<usize> = Vec::new();
        for item in 0..e.count {
            corners.clear();
            for (j, p) in e.properties.iter().enumerate() {
                match p.list {
                    None => {
                        values[j] = body.next(p.value).map_err(|m| fail(&body, m))?;
                    }
                    Some(count_type) => {
                        let n = body.next(count_type).map_err(|m| fail(&body, m))?;
                        if !(n >= 0.0 && n.fract() == 0.0 && n as usize <= left) {
                            return Err(fail(
                                &body,
                                (None, format!("a list length {n} at {}", body.place(count_type.bytes()))),
                            ));
                        }
                        let wanted = is_face && (p.name == "vertex_indices" || p.name == "vertex_index");
                        for _ in 0..n as usize {
                            let v = body.next(p.value).map_err(|m| fail(&body, m))?;
                            if wanted {
                                if !(v >= 0.0 && v.fract() == 0.0 && (v as usize) < verts.len()) {
                                    let m = format!(
                                        "face {} refers to vertex {v}, at {}, of {} defined",
                                        item + 1,
                                        body.place(p.value.bytes()),
                                        verts.len()
                                    );
                                    return Err(at_byte(m));
                                }
                                corners.push(v as usize);
                            }
                        }
                    }
                }
            }
            if is_vertex {
                let p = DVec3::new(values[x], values[y], values[z]);
                if !p.is_finite() {
                    return Err(at_byte(format!("vertex {} (at {}) is not finite", item + 1, body.place(0))));
                }
                verts.push(p);
                if let Some((u, v)) = uv {
                    let t = DVec2::new(values[u], values[v]);
                    if !t.is_finite() {
                        return Err(at_byte(format!(
                            "vertex {} (at {}) has texture coordinates that are not finite",
                            item + 1,
                            body.place(0)
                        )));
                    }
                    texcoords.push(t);
                }
                if let Some([a, b, c]) = normal_slots {
                    let n = DVec3::new(values[a], values[b], values[c]);
                    if !(n.is_finite() && n.length() > 0.0) {
                        return Err(at_byte(format!(
                            "vertex {} (at {}) has a normal (nx, ny, nz) that is zero or not finite",
                            item + 1,
                            body.place(0)
                        )));
                    }
                    normals.push(n.normalize());
                }
            } else if is_face {
                if corners.len() < 3 {
                    return Err(at_byte(format!(
                        "face {} has {} vertices: at least 3 are needed",
                        item + 1,
                        corners.len()
                    )));
                }
                let first_edge = verts[corners[1]] - verts[corners[0]];
                for j in 1..corners.len() - 1 {
                    let c = [corners[0], corners[j], corners[j + 1]];
                    let t = c.map(|i| verts[i]);
                    let tex = (!texcoords.is_empty()).then(|| c.map(|i| texcoords[i]));
                    let normal = (!normals.is_empty()).then(|| c.map(|i| normals[i]));
                    if (t[1] - t[0]).cross(t[2] - t[0]).length() > 0.0 {
                        let tangent = super::obj::tangent(&t, tex, first_edge);
                        tris.push(ObjTriangle { verts: t, uv: tex, tangent, normals: normal });
                    } else {
                        skipped.get_or_insert_with(|| (format!("face {}", item + 1), 0)).1 += 1;
                    }
                }
            }
        }
    }
    if tris.is_empty() {
        return Err(at_byte("the mesh has no faces with non-zero area".into()));
    }
    if let Some((first, n)) = skipped {
        warnings.push(format!(
            "{}: {n} triangle(s) with zero area (repeated or collinear corners), the first in {first}; skipped",
            path.display()
        ));
    }
    Ok(tris)
}
