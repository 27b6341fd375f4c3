//! Mesh formats: an STL file (ASCII, binary, binary whose header starts with "solid") gives the
//! triangles the OBJ of the same mesh gives, so the same flux bit for bit; the scene's `unit`
//! applies to it; malformed files are errors naming the file and the line or byte offset.

use std::path::{Path, PathBuf};

mod common;

/// A closed box with corners at f32-exact coordinates (binary STL stores f32), as triangles
/// wound counterclockwise seen from outside.
fn box_triangles(scale: f64) -> Vec<[[f64; 3]; 3]> {
    let (lo, hi) = ([-0.5, -0.25, 0.125], [0.75, 0.5, 1.0]);
    let p = |x: usize, y: usize, z: usize| {
        [[lo[0], hi[0]][x] * scale, [lo[1], hi[1]][y] * scale, [lo[2], hi[2]][z] * scale]
    };
    let quads = [
        [p(0, 0, 0), p(0, 1, 0), p(1, 1, 0), p(1, 0, 0)], // −z
        [p(0, 0, 1), p(1, 0, 1), p(1, 1, 1), p(0, 1, 1)], // +z
        [p(0, 0, 0), p(1, 0, 0), p(1, 0, 1), p(0, 0, 1)], // −y
        [p(0, 1, 0), p(0, 1, 1), p(1, 1, 1), p(1, 1, 0)], // +y
        [p(0, 0, 0), p(0, 0, 1), p(0, 1, 1), p(0, 1, 0)], // −x
        [p(1, 0, 0), p(1, 1, 0), p(1, 1, 1), p(1, 0, 1)], // +x
    ];
    quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect()
}

fn obj_text(tris: &[[[f64; 3]; 3]]) -> String {
    let mut s = String::new();
    for t in tris {
        for v in t {
            s += &format!("v {} {} {}\n", v[0], v[1], v[2]);
        }
    }
    for k in 0..tris.len() {
        s += &format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3);
    }
    s
}

fn ascii_stl(tris: &[[[f64; 3]; 3]]) -> String {
    let mut s = "solid box\n".to_string();
    for t in tris {
        // A wrong normal: facet normals are ignored, the winding decides.
        s += "  facet normal 0 0 1\n    outer loop\n";
        for v in t {
            s += &format!("      vertex {:e} {:e} {:e}\n", v[0], v[1], v[2]);
        }
        s += "    endloop\n  endfacet\n";
    }
    s + "endsolid box\n"
}

fn binary_stl(tris: &[[[f64; 3]; 3]], header: &[u8]) -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b[..header.len()].copy_from_slice(header);
    b.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        b.extend_from_slice(&[0u8; 12]);
        for v in t {
            for x in v {
                b.extend_from_slice(&(*x as f32).to_le_bytes());
            }
        }
        b.extend_from_slice(&[0u8; 2]);
    }
    b
}

/// The box (white Lambertian) lit by a quad light above it, the mesh from `file`.
fn scene_with(file: &Path, unit: &str) -> String {
    let s = if unit == "mm" { 1000.0 } else { 1.0 };
    format!(
        r#"[scene]
unit = "{unit}"

[materials.white]
type = "lambertian"
reflectance = 0.6

[[surfaces]]
name = "part"
material = "white"
shape = {{ type = "mesh", file = "{}" }}

[[surfaces]]
name = "floor"
material = "white"
shape = {{ type = "quad", corners = [[-{f}, -{f}, 0], [{f}, -{f}, 0], [{f}, {f}, 0], [-{f}, {f}, 0]] }}

[[lights]]
name = "lamp"
power_w = 10
shape = {{ type = "quad", corners = [[-{l}, -{l}, {h}], [-{l}, {l}, {h}], [{l}, {l}, {h}], [{l}, -{l}, {h}]] }}
"#,
        file.display(),
        f = 3.0 * s,
        l = 0.5 * s,
        h = 2.0 * s,
    )
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn flux_bits(f: &photon::output::Flux) -> Vec<(String, u64, u64, u64)> {
    f.surfaces
        .iter()
        .map(|r| (r.name.clone(), r.area_m2.to_bits(), r.incident_w.to_bits(), r.absorbed_w.to_bits()))
        .collect()
}

#[test]
fn stl_files_give_the_triangles_of_the_same_obj() {
    let dir = common::temp_dir("meshes-stl");
    let tris = box_triangles(1.0);
    let obj = write(&dir, "box.obj", obj_text(&tris).as_bytes());
    let reference = flux_bits(&common::run(&scene_with(&obj, "m"), 40_000, 3));
    let variants = [
        ("ascii.stl", ascii_stl(&tris).into_bytes()),
        ("binary.stl", binary_stl(&tris, b"exported by some CAD")),
        // Binary files that start with "solid", as many CAD exporters write them.
        ("solid-binary.STL", binary_stl(&tris, b"solid box, but binary")),
        // CRLF line ends and blank lines.
        ("crlf.stl", ascii_stl(&tris).replace('\n', "\r\n\r\n").into_bytes()),
    ];
    for (name, bytes) in variants {
        let file = write(&dir, name, &bytes);
        assert_eq!(flux_bits(&common::run(&scene_with(&file, "m"), 40_000, 3)), reference, "{name}");
    }
    // A part drawn in millimetres, in a scene in millimetres: the same box in metres.
    let mm = write(&dir, "mm.stl", &binary_stl(&box_triangles(1000.0), b"mm"));
    let s = common::scene(&scene_with(&mm, "mm"));
    let m = common::scene(&scene_with(&obj, "m"));
    assert!((s.surfaces[0].area_m2 - m.surfaces[0].area_m2).abs() <= 1e-12 * m.surfaces[0].area_m2);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_zero_area_stl_triangle_is_skipped_with_a_warning() {
    let dir = common::temp_dir("meshes-flat");
    let mut tris = box_triangles(1.0);
    tris.push([[0.0, 0.0, 0.5], [0.0, 0.0, 0.5], [0.25, 0.0, 0.5]]);
    let file = write(&dir, "flat.stl", &binary_stl(&tris, b""));
    let s = common::scene(&scene_with(&file, "m"));
    assert_eq!(s.surfaces[0].triangles, 12);
    assert!(
        s.warnings.iter().any(|w| w.contains("flat.stl") && w.contains("triangle 13 (byte 684)")),
        "{:?}",
        s.warnings
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_stl_files_name_the_file_and_the_line_or_byte() {
    let dir = common::temp_dir("meshes-bad");
    let good = ascii_stl(&box_triangles(1.0));
    let binary = binary_stl(&box_triangles(1.0), b"");
    let mut nan = binary.clone();
    // Triangle 2's first corner's y: byte 84 + 50 + 12 + 4.
    nan[84 + 50 + 16..84 + 50 + 20].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut count_too_large = binary.clone();
    count_too_large[80..84].copy_from_slice(&13u32.to_le_bytes());
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("number.stl", good.replacen("vertex -5e-1", "vertex -5e-1x", 1).into_bytes(), ":4: malformed vertex"),
        (
            "two-coords.stl",
            good.replacen("vertex -5e-1 -2.5e-1 1.25e-1", "vertex 1 2", 1).into_bytes(),
            ":4: malformed vertex",
        ),
        ("inf.stl", good.replacen("vertex -5e-1", "vertex inf", 1).into_bytes(), ":4: malformed vertex"),
        (
            "four.stl",
            good.replacen("    endloop", "      vertex 0 0 0\n    endloop", 1).into_bytes(),
            ":7: a facet has more than 3 vertices",
        ),
        (
            "two.stl",
            good.replacen("      vertex 7.5e-1 -2.5e-1 1.25e-1\n", "", 1).into_bytes(),
            "has 2 vertices, not 3",
        ),
        ("keyword.stl", good.replacen("outer loop", "outer lop", 1).into_bytes(), ":3: expected `outer loop`"),
        (
            "stray.stl",
            good.replacen("  endfacet", "  vertex 1 1 1\n  endfacet", 1).into_bytes(),
            "unexpected `vertex` inside the facet begun at line 2",
        ),
        ("unclosed.stl", good.replace("endsolid box\n", "").into_bytes(), "ends without `endsolid`"),
        (
            "cut.stl",
            good.lines().take(5).collect::<Vec<_>>().join("\n").into_bytes(),
            ":5: the file ends inside the facet begun at line 2",
        ),
        ("after.stl", (good.clone() + "facet normal 0 0 1\n").into_bytes(), "after `endsolid`"),
        ("nan.stl", nan, "triangle 2 (byte 150) has a coordinate that is not a finite number"),
        ("truncated.stl", binary[..binary.len() - 7].to_vec(), "must be 684 bytes long, but the file has 677"),
        ("count.stl", count_too_large, "header gives 13 triangles must be 734 bytes long"),
        ("tiny.stl", b"\x00\x01".to_vec(), "too short for a binary STL"),
        // A CAD binary file whose header starts with "solid", cut short: still reported as binary.
        (
            "solid-cut.stl",
            binary_stl(&box_triangles(1.0), b"solid part")[..677].to_vec(),
            "must be 684 bytes long, but the file has 677",
        ),
        ("empty-ascii.stl", b"solid nothing\nendsolid nothing\n".to_vec(), "no triangles with non-zero area"),
        ("empty-binary.stl", binary_stl(&[], b""), "no triangles with non-zero area"),
    ];
    assert!(cases.len() >= 10);
    for (name, bytes, expected) in cases {
        let file = write(&dir, name, &bytes);
        let toml = scene_with(&file, "m");
        let e = match photon::scene::load_str(Path::new("tests/inline.toml"), &toml) {
            Ok(_) => panic!("{name}: loaded"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(name), "{name}: the message should name the file: {e}");
        assert!(e.contains(expected), "{name}: the message should say \"{expected}\": {e}");
        assert!(e.contains("shape") || e.contains("surfaces"), "{name}: the message should name the scene key: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The box as a PLY of 6 quads (24 vertices, each with a normal and a colour byte to read past),
/// and an `edge` element after the faces: `format` is "ascii", "binary_little_endian" or
/// "binary_big_endian"; `double` stores x, y, z as float64.
fn ply(format: &str, double: bool) -> Vec<u8> {
    let tris = box_triangles(1.0);
    let quads: Vec<[[f64; 3]; 4]> = tris.chunks(2).map(|t| [t[0][0], t[0][1], t[0][2], t[1][2]]).collect();
    let coord = if double { "double" } else { "float" };
    let mut b = format!(
        "ply\nformat {format} 1.0\ncomment made by a test\nelement vertex 24\nproperty {coord} x\n\
         property {coord} y\nproperty {coord} z\nproperty float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nelement face 6\nproperty list uchar int vertex_indices\nelement edge 1\n\
         property int vertex1\nproperty int vertex2\nend_header\n"
    )
    .into_bytes();
    let big = format == "binary_big_endian";
    let f32b = |x: f64| if big { (x as f32).to_be_bytes().to_vec() } else { (x as f32).to_le_bytes().to_vec() };
    let f64b = |x: f64| if big { x.to_be_bytes().to_vec() } else { x.to_le_bytes().to_vec() };
    let i32b = |x: i32| if big { x.to_be_bytes().to_vec() } else { x.to_le_bytes().to_vec() };
    for q in &quads {
        for v in q {
            if format == "ascii" {
                b.extend(format!("{} {} {} 0 0 1 255\n", v[0], v[1], v[2]).bytes());
            } else {
                for x in v {
                    b.extend(if double { f64b(*x) } else { f32b(*x) });
                }
                for x in [0.0, 0.0, 1.0] {
                    b.extend(f32b(x));
                }
                b.push(255);
            }
        }
    }
    for k in 0..6i32 {
        if format == "ascii" {
            b.extend(format!("4 {} {} {} {}\n", 4 * k, 4 * k + 1, 4 * k + 2, 4 * k + 3).bytes());
        } else {
            b.push(4);
            for i in 0..4 {
                b.extend(i32b(4 * k + i));
            }
        }
    }
    if format == "ascii" {
        b.extend(b"0 1\n");
    } else {
        b.extend(i32b(0));
        b.extend(i32b(1));
    }
    b
}

#[test]
fn ply_files_give_the_triangles_of_the_same_obj() {
    let dir = common::temp_dir("meshes-ply");
    let obj = write(&dir, "box.obj", obj_text(&box_triangles(1.0)).as_bytes());
    let reference = flux_bits(&common::run(&scene_with(&obj, "m"), 40_000, 3));
    for (name, format, double) in [
        ("ascii.ply", "ascii", false),
        ("little.ply", "binary_little_endian", false),
        ("big.ply", "binary_big_endian", false),
        ("double.ply", "binary_little_endian", true),
    ] {
        let file = write(&dir, name, &ply(format, double));
        assert_eq!(flux_bits(&common::run(&scene_with(&file, "m"), 40_000, 3)), reference, "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_ply_files_name_the_file_and_the_line_or_byte() {
    let dir = common::temp_dir("meshes-ply-bad");
    let ascii = String::from_utf8(ply("ascii", false)).unwrap();
    let little = ply("binary_little_endian", false);
    // The header has 17 lines; the ASCII body's first vertex is line 18.
    let header_end = little.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let mut bad_index = little.clone();
    // Face 1's first index: after 24 vertices of 7 values (6 floats + 1 byte) and the count byte.
    let at = header_end + 24 * 25 + 1;
    bad_index[at..at + 4].copy_from_slice(&99i32.to_le_bytes());
    let mut nan = little.clone();
    nan[header_end + 4..header_end + 8].copy_from_slice(&f32::NAN.to_le_bytes());
    // Offsets are the file's: the cut file ends at its own length.
    let cut_message = format!("the file ends at byte {} before its elements do", little.len() - 3);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("first.ply", ascii.replacen("ply", "plx", 1).into_bytes(), ":1: the first line must be `ply`"),
        ("format.ply", ascii.replacen("format ascii", "format text", 1).into_bytes(), ":2: unknown format \"text\""),
        (
            "type.ply",
            ascii.replacen("property float nx", "property quad nx", 1).into_bytes(),
            ":8: unknown type \"quad\"",
        ),
        (
            "orphan.ply",
            ascii.replacen("comment made by a test", "property float w", 1).into_bytes(),
            ":3: a property before any element",
        ),
        ("header.ply", ascii.replacen("end_header", "end_headr", 1).into_bytes(), "no `end_header` line"),
        ("noz.ply", ascii.replacen("property float z", "property float w", 1).into_bytes(), "lacks x, y or z"),
        (
            "count.ply",
            ascii.replacen("element vertex 24", "element vertex 99999999", 1).into_bytes(),
            "exceeds the file's",
        ),
        ("word.ply", ascii.replacen("0 0 1 255", "0 0 one 255", 1).into_bytes(), ":18: \"one\" is not a number"),
        ("short.ply", ascii.replacen("0 1\n", "", 1).into_bytes(), "the file ends before its elements do"),
        ("cut.ply", little[..little.len() - 3].to_vec(), &cut_message),
        (
            "hollow.ply",
            ascii.replacen("property int vertex1\nproperty int vertex2\n", "", 1).into_bytes(),
            "the element `edge` has items but no properties",
        ),
        ("index.ply", bad_index, "face 1 refers to vertex 99"),
        ("two.ply", ascii.replacen("4 0 1 2 3", "2 0 1", 1).into_bytes(), "face 1 has 2 vertices"),
        ("nan.ply", nan, "vertex 1"),
        (
            "order.ply",
            ascii.replacen("element vertex 24", "element face 0\nelement vertex 24", 1).into_bytes(),
            "comes before `vertex`",
        ),
    ];
    for (name, bytes, expected) in cases {
        let file = write(&dir, name, &bytes);
        let toml = scene_with(&file, "m");
        let e = match photon::scene::load_str(Path::new("tests/inline.toml"), &toml) {
            Ok(_) => panic!("{name}: loaded"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(name), "{name}: the message should name the file: {e}");
        assert!(e.contains(expected), "{name}: the message should say \"{expected}\": {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_obj_normals_name_the_file_and_the_line() {
    let dir = common::temp_dir("obj-normals");
    std::fs::create_dir_all(&dir).unwrap();
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let cases = [
        ("short.obj", format!("{tri}vn 0 0\nf 1//1 2//1 3//1\n"), ":4: malformed normal"),
        ("zero.obj", format!("{tri}vn 0 0 0\nf 1//1 2//1 3//1\n"), ":4: malformed normal"),
        ("nan.obj", format!("{tri}vn 0 nan 1\nf 1//1 2//1 3//1\n"), ":4: malformed normal"),
        (
            "index.obj",
            format!("{tri}vn 0 0 1\nf 1//1 2//7 3//1\n"),
            ":5: normal index 7 refers to no `vn` (1 defined so far)",
        ),
        ("word.obj", format!("{tri}vn 0 0 1\nf 1//1 2//x 3//1\n"), ":5: malformed normal index"),
    ];
    for (name, text, expected) in cases {
        let file = write(&dir, name, text.as_bytes());
        let e = match photon::scene::load_str(Path::new("tests/inline.toml"), &scene_with(&file, "m")) {
            Ok(_) => panic!("{name}: loaded"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(name) && e.contains(expected), "{name}: expected \"{expected}\": {e}");
    }
    // Well-formed: `v//vn` and `v/vt/vn` both load.
    for (name, text) in [
        ("ok1.obj", format!("{tri}vn 0 0 1\nf 1//1 2//1 3//1\n")),
        ("ok2.obj", format!("{tri}vt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1\n")),
    ] {
        let file = write(&dir, name, text.as_bytes());
        photon::scene::load_str(Path::new("tests/inline.toml"), &scene_with(&file, "m"))
            .unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The box's 36 corners as f32 and 36 u16 indices: the binary data of a glTF buffer (positions
/// at 0, indices after them), with its byte lengths.
fn gltf_buffer(tris: &[[[f64; 3]; 3]], offset: [f64; 3], scale: f64) -> (Vec<u8>, usize, usize) {
    let mut data = Vec::new();
    for v in tris.iter().flatten() {
        for i in 0..3 {
            data.extend_from_slice(&(((v[i] - offset[i]) / scale) as f32).to_le_bytes());
        }
    }
    let positions = data.len();
    for k in 0..tris.len() * 3 {
        data.extend_from_slice(&(k as u16).to_le_bytes());
    }
    (data.clone(), positions, data.len() - positions)
}

/// A glTF document over one buffer `uri` (None: a GLB's BIN chunk) holding `gltf_buffer`'s data,
/// one node with `node` (extra JSON members: a transform) placing the mesh.
fn gltf_json(uri: Option<&str>, len: usize, positions: usize, indices: usize, node: &str) -> String {
    let uri = uri.map(|u| format!("\"uri\": \"{u}\", ")).unwrap_or_default();
    let n = positions / 12;
    format!(
        r#"{{
  "asset": {{ "version": "2.0" }},
  "scene": 0,
  "scenes": [ {{ "nodes": [0] }} ],
  "nodes": [ {{ "mesh": 0{node} }} ],
  "meshes": [ {{ "primitives": [ {{ "attributes": {{ "POSITION": 0 }}, "indices": 1 }} ] }} ],
  "buffers": [ {{ {uri}"byteLength": {len} }} ],
  "bufferViews": [
    {{ "buffer": 0, "byteOffset": 0, "byteLength": {positions} }},
    {{ "buffer": 0, "byteOffset": {positions}, "byteLength": {indices} }}
  ],
  "accessors": [
    {{ "bufferView": 0, "componentType": 5126, "count": {n}, "type": "VEC3", "min": [-10, -10, -10], "max": [10, 10, 10] }},
    {{ "bufferView": 1, "componentType": 5123, "count": {n}, "type": "SCALAR" }}
  ]
}}"#
    )
}

fn base64(data: &[u8]) -> String {
    const ABC: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let v = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            s.push(if k <= c.len() { ABC[(v >> (18 - 6 * k) & 63) as usize] as char } else { '=' });
        }
    }
    s
}

/// A GLB container: header, JSON chunk (space-padded), BIN chunk (zero-padded).
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut j = json.as_bytes().to_vec();
    j.resize(j.len().div_ceil(4) * 4, b' ');
    let mut b = bin.to_vec();
    b.resize(b.len().div_ceil(4) * 4, 0);
    let total = 12 + 8 + j.len() + 8 + b.len();
    let mut out = b"glTF".to_vec();
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}

#[test]
fn gltf_files_give_the_triangles_of_the_same_obj() {
    let dir = common::temp_dir("meshes-gltf");
    let tris = box_triangles(1.0);
    let obj = write(&dir, "box.obj", obj_text(&tris).as_bytes());
    let reference = flux_bits(&common::run(&scene_with(&obj, "m"), 40_000, 3));
    let (data, p, i) = gltf_buffer(&tris, [0.0; 3], 1.0);
    write(&dir, "box data.bin", &data);
    let uri = format!("data:application/octet-stream;base64,{}", base64(&data));
    let variants: Vec<(&str, Vec<u8>)> = vec![
        ("embedded.gltf", gltf_json(Some(&uri), data.len(), p, i, "").into_bytes()),
        ("external.gltf", gltf_json(Some("box%20data.bin"), data.len(), p, i, "").into_bytes()),
        ("binary.glb", glb(&gltf_json(None, data.len(), p, i, ""), &data)),
        // The mesh drawn half size about (0.25, 0, 0.5), put back by its node's transform.
        ("node.gltf", {
            let (d, p, i) = gltf_buffer(&tris, [0.25, 0.0, 0.5], 2.0);
            let uri = format!("data:application/octet-stream;base64,{}", base64(&d));
            gltf_json(Some(&uri), d.len(), p, i, r#", "translation": [0.25, 0, 0.5], "scale": [2, 2, 2]"#).into_bytes()
        }),
    ];
    for (name, bytes) in variants {
        let file = write(&dir, name, &bytes);
        assert_eq!(flux_bits(&common::run(&scene_with(&file, "m"), 40_000, 3)), reference, "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn malformed_gltf_files_name_the_file_and_the_line_or_the_part() {
    let dir = common::temp_dir("meshes-gltf-bad");
    let tris = box_triangles(1.0);
    let (data, p, i) = gltf_buffer(&tris, [0.0; 3], 1.0);
    let uri = format!("data:application/octet-stream;base64,{}", base64(&data));
    let good = gltf_json(Some(&uri), data.len(), p, i, "");
    let mut nan = data.clone();
    nan[4..8].copy_from_slice(&f32::NAN.to_le_bytes());
    let nan_uri = format!("data:application/octet-stream;base64,{}", base64(&nan));
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("syntax.gltf", good.replacen("\"scenes\"", "scenes", 1).into_bytes(), "malformed glTF: line 4, column"),
        (
            "noasset.gltf",
            good.replacen("\"asset\": { \"version\": \"2.0\" },", "", 1).into_bytes(),
            "malformed glTF: line",
        ),
        (
            "short.gltf",
            good.replacen(
                &format!("\"byteLength\": {} }}", data.len()),
                &format!("\"byteLength\": {} }}", data.len() + 8),
                1,
            )
            .into_bytes(),
            "holds 504 bytes but declares byteLength 512",
        ),
        (
            "plain-uri.gltf",
            good.replacen("application/octet-stream;base64,", "text/plain,", 1).into_bytes(),
            "a data URI must be base64",
        ),
        ("bad64.gltf", good.replacen("base64,", "base64,*", 1).into_bytes(), "bad base64 at character 0"),
        ("nofile.gltf", good.replacen(&uri, "missing.bin", 1).into_bytes(), "cannot read"),
        ("accessor.gltf", good.replacen("\"POSITION\": 0", "\"POSITION\": 7", 1).into_bytes(), "malformed glTF"),
        ("view.gltf", good.replacen("\"bufferView\": 1,", "\"bufferView\": 5,", 1).into_bytes(), "malformed glTF"),
        (
            "noposition.gltf",
            good.replacen("\"POSITION\": 0", "\"TEXCOORD_1\": 0", 1).into_bytes(),
            "attributes[\"POSITION\"]: Missing data",
        ),
        ("nan.gltf", good.replacen(&uri, &nan_uri, 1).into_bytes(), "vertex 0 is not finite"),
        (
            "points.gltf",
            good.replacen("\"indices\": 1", "\"indices\": 1, \"mode\": 0", 1).into_bytes(),
            "places no triangle",
        ),
        ("magic.glb", b"glTX\x02\0\0\0\x14\0\0\0\0\0\0\0JSON".to_vec(), "malformed glTF"),
        ("cut.glb", glb(&good, &[])[..30].to_vec(), "malformed glTF"),
    ];
    assert!(cases.len() >= 10);
    for (name, bytes, expected) in cases {
        let file = write(&dir, name, &bytes);
        let e = match photon::scene::load_str(Path::new("tests/inline.toml"), &scene_with(&file, "m")) {
            Ok(_) => panic!("{name}: loaded"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(name), "{name}: the message should name the file: {e}");
        assert!(e.contains(expected), "{name}: the message should say \"{expected}\": {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
