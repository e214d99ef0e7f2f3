//! Round trips and error cases of the mesh readers and writers (`holefill::io`).

use glam::DVec3;
use holefill::io::{self, Encoding, Format, IoError, Precision, RawMesh};
use proptest::prelude::*;
use std::path::{Path, PathBuf};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn bits(p: &[DVec3]) -> Vec<[u64; 3]> {
    p.iter()
        .map(|v| [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()])
        .collect()
}

fn f32s(p: &[DVec3]) -> Vec<[u32; 3]> {
    p.iter()
        .map(|v| {
            let v = v.as_vec3();
            [v.x.to_bits(), v.y.to_bits(), v.z.to_bits()]
        })
        .collect()
}

/// The three corner positions of every face.
fn corners(m: &RawMesh) -> Vec<[DVec3; 3]> {
    m.faces
        .iter()
        .map(|f| f.map(|i| m.positions[i as usize]))
        .collect()
}

/// Writes `bytes` to `name` in a fresh folder and reads it back.
fn read_bytes(name: &str, bytes: &[u8]) -> (tempfile::TempDir, PathBuf, Result<RawMesh, IoError>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    let r = io::read(&path, None);
    (dir, path, r)
}

/// Asserts that reading `bytes` as `name` fails with a content error naming the file.
#[track_caller]
fn assert_malformed(name: &str, bytes: &[u8]) -> String {
    let (_d, _p, r) = read_bytes(name, bytes);
    let e = match r {
        Ok(m) => panic!("{name}: expected an error, read {} faces", m.faces.len()),
        Err(e) => e,
    };
    let msg = e.to_string();
    assert!(e.is_malformed(), "{name}: {msg}");
    assert!(
        msg.contains(name),
        "{name}: message does not name the file: {msg}"
    );
    msg
}

// ---------------------------------------------------------------------------
// Fixtures

#[test]
fn obj_negative_indices_and_fanning() {
    let m = io::read(&data("negative_indices.obj"), None).unwrap();
    assert_eq!(m.positions.len(), 6);
    assert_eq!(m.positions[4], DVec3::new(2.0, 0.0, 0.0));
    // Quad (1 2 3 4) -> 2 triangles, pentagon (2 6 3 4 5 in 1-based) -> 3 triangles.
    assert_eq!(
        m.faces,
        vec![[0, 1, 2], [0, 2, 3], [1, 5, 2], [1, 2, 3], [1, 3, 4]]
    );
    assert!(
        m.notes.iter().any(|n| n.contains("fanned 2")),
        "{:?}",
        m.notes
    );
    assert_eq!(m.precision, Precision::F64);
    assert_eq!(m.encoding, Encoding::Ascii);
}

#[test]
fn ply_extra_properties_elements_and_colours() {
    let m = io::read(&data("colored_square.ply"), None).unwrap();
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.positions[3], DVec3::new(0.0, 1.0, 0.25));
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]]);
    let c = m.colors.as_ref().unwrap();
    assert_eq!(c[0], [1.0, 0.0, 0.0]);
    assert_eq!(c[3], [51.0 / 255.0, 102.0 / 255.0, 153.0 / 255.0]);
    assert_eq!(m.precision, Precision::F32);
    // other elements are kept, to be written back (issue 18)
    let ply = m.attrs.ply.as_ref().unwrap();
    assert!(
        ply.elements.iter().any(|(name, _, _)| name == "edge"),
        "{:?}",
        ply.elements
    );
}

#[test]
fn stl_ascii_is_welded() {
    let m = io::read(&data("tetra_ascii.stl"), None).unwrap();
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.faces.len(), 4);
    assert!(
        m.notes
            .iter()
            .any(|n| n.contains("12 STL triangle corners into 4")),
        "{:?}",
        m.notes
    );
}

#[test]
fn coff_colours_comments_and_polygons() {
    let m = io::read(&data("square_color.off"), None).unwrap();
    assert_eq!(m.positions.len(), 5);
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]);
    let c = m.colors.unwrap();
    assert_eq!(c[1], [0.0, 1.0, 0.0]);
    assert_eq!(c[4], [0.2, 0.2, 0.2]);
}

// ---------------------------------------------------------------------------
// Hand-made binary files

fn cube_triangles() -> Vec<[[f32; 3]; 3]> {
    let p = |i: usize| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32];
    let quads = [
        [0, 2, 3, 1],
        [4, 5, 7, 6],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 4, 6, 2],
        [1, 3, 7, 5],
    ];
    quads
        .iter()
        .flat_map(|q| [[p(q[0]), p(q[1]), p(q[2])], [p(q[0]), p(q[2]), p(q[3])]])
        .collect()
}

fn binary_stl(tris: &[[[f32; 3]; 3]], count: u32) -> Vec<u8> {
    let mut b = vec![b'x'; 80];
    b.extend_from_slice(&count.to_le_bytes());
    for t in tris {
        b.extend_from_slice(&[0u8; 12]);
        for v in t {
            for c in v {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0u8; 2]);
    }
    b
}

#[test]
fn stl_binary_welds_by_exact_position() {
    let tris = cube_triangles();
    let (_d, _p, r) = read_bytes("cube.stl", &binary_stl(&tris, 12));
    let m = r.unwrap();
    assert_eq!(m.positions.len(), 8);
    assert_eq!(m.faces.len(), 12);
    assert_eq!(m.precision, Precision::F32);
    assert_eq!(m.encoding, Encoding::BinaryLittleEndian);
    assert!(
        m.notes
            .iter()
            .any(|n| n.contains("36 STL triangle corners into 8 vertices")),
        "{:?}",
        m.notes
    );
    // Every triangle's corners are where the file put them.
    for (got, want) in corners(&m).iter().zip(&tris) {
        for k in 0..3 {
            assert_eq!(got[k].as_vec3().to_array(), want[k]);
        }
    }
}

#[test]
fn stl_binary_header_starting_with_solid_is_still_binary() {
    let tris = cube_triangles();
    let mut b = binary_stl(&tris, 12);
    b[..5].copy_from_slice(b"solid");
    let (_d, _p, r) = read_bytes("cube.stl", &b);
    assert_eq!(r.unwrap().faces.len(), 12);
}

#[test]
fn stl_negative_zero_welds_with_zero() {
    let mut tris = cube_triangles();
    tris[1][0][0] = -0.0; // was 0.0
    let (_d, _p, r) = read_bytes("cube.stl", &binary_stl(&tris, 12));
    assert_eq!(r.unwrap().positions.len(), 8);
}

/// A big-endian PLY with double coordinates, ushort list counts, uint indices,
/// float colours, extra scalar and list properties and an extra element.
fn binary_ply_be() -> Vec<u8> {
    let mut b = b"ply\nformat binary_big_endian 1.0\n\
        element material 1\nproperty list uchar char name\n\
        element vertex 4\nproperty short id\nproperty double x\nproperty double y\n\
        property double z\nproperty float red\nproperty float green\nproperty float blue\n\
        property list int uchar tags\n\
        element face 2\nproperty list ushort uint vertex_indices\nproperty uchar flag\n\
        end_header\n"
        .to_vec();
    b.extend_from_slice(&[3, b'a', b'b', b'c']);
    let pts = [
        [0.1, 0.2, 0.3],
        [1.0, 1e-300, -0.0],
        [1.5, 2.5, 1e300],
        [-7.25, 3.0, 0.0],
    ];
    for (i, p) in pts.iter().enumerate() {
        b.extend_from_slice(&(i as i16).to_be_bytes());
        for c in p {
            b.extend_from_slice(&f64::to_be_bytes(*c));
        }
        for c in [0.25f32, 0.5, 0.75] {
            b.extend_from_slice(&c.to_be_bytes());
        }
        b.extend_from_slice(&2i32.to_be_bytes());
        b.extend_from_slice(&[9, 9]);
    }
    b.extend_from_slice(&4u16.to_be_bytes());
    for i in [0u32, 1, 2, 3] {
        b.extend_from_slice(&i.to_be_bytes());
    }
    b.push(1);
    b.extend_from_slice(&3u16.to_be_bytes());
    for i in [3u32, 2, 1] {
        b.extend_from_slice(&i.to_be_bytes());
    }
    b.push(0);
    b
}

#[test]
fn ply_binary_big_endian_with_extras() {
    let (_d, _p, r) = read_bytes("be.ply", &binary_ply_be());
    let m = r.unwrap();
    assert_eq!(m.encoding, Encoding::BinaryBigEndian);
    assert_eq!(m.precision, Precision::F64);
    assert_eq!(m.positions[0], DVec3::new(0.1, 0.2, 0.3));
    assert_eq!(m.positions[1].y, 1e-300);
    assert!(m.positions[1].z.is_sign_negative());
    assert_eq!(m.positions[2].z, 1e300);
    assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3], [3, 2, 1]]);
    assert_eq!(m.colors.as_ref().unwrap()[2], [0.25, 0.5, 0.75]);
    // Round trip through every format keeps the doubles bit-exact.
    let d = tempfile::tempdir().unwrap();
    for name in ["a.ply", "a.obj", "a.off"] {
        let p = d.path().join(name);
        io::write(&p, &m, None).unwrap();
        let back = io::read(&p, None).unwrap();
        assert_eq!(bits(&back.positions), bits(&m.positions), "{name}");
        assert_eq!(back.faces, m.faces, "{name}");
    }
}

#[test]
fn ply_truncated_and_lying_headers() {
    let good = binary_ply_be();
    // Truncated inside the faces.
    let msg = assert_malformed("t.ply", &good[..good.len() - 5]);
    assert!(msg.contains("truncated"), "{msg}");
    // Truncated in the middle of the header.
    assert_malformed("t.ply", &good[..40]);
    // Header claims 2^31 vertices: refused before allocating.
    let s = String::from_utf8_lossy(&good).replace("element vertex 4", "element vertex 2147483648");
    let msg = assert_malformed("huge.ply", s.as_bytes());
    assert!(msg.contains("2147483648"), "{msg}");
    // More than u32::MAX vertices.
    let s = String::from_utf8_lossy(&good).replace("element vertex 4", "element vertex 4294967296");
    assert_malformed("huge.ply", s.as_bytes());
    // Header says double but the data is float-sized: runs out of bytes.
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\n\
        property double y\nproperty double z\nelement face 1\n\
        property list uchar int vertex_indices\nend_header\n"
        .to_vec();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.push(3);
    for i in [0i32, 1, 2] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    assert_malformed("lie.ply", &b);
}

fn ascii_ply(body: &str, header_extra: &str) -> Vec<u8> {
    format!(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\n{header_extra}element face 1\nproperty list uchar int vertex_indices\n\
         end_header\n{body}"
    )
    .into_bytes()
}

#[test]
fn ply_malformed_cases() {
    let ok = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    let (_d, _p, r) = read_bytes("ok.ply", &ascii_ply(ok, ""));
    assert_eq!(r.unwrap().faces, vec![[0, 1, 2]]);
    let cases = [
        ("0.000000 0.000000 0.000000\n1 0 0\n", "ends after 2 of 3"),
        ("0 0 0\n1 0 0\n", "claims 3 'vertex' elements"),
        ("0 0 0\n1 0 0\n0 1 0          \n", "ends after 0 of 1"),
        ("0 0 nan\n1 0 0\n0 1 0\n3 0 1 2\n", "non-finite"),
        ("0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n", "non-finite"),
        ("0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "out of range"),
        ("0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n", "out of range"),
        ("0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "at least 3"),
        ("0 0 0\n1 0 0\n0 1 0\n3 0 1\n", "fewer values"),
        ("0 0 0 5\n1 0 0\n0 1 0\n3 0 1 2\n", "more values"),
        ("0 0 x\n1 0 0\n0 1 0\n3 0 1 2\n", "not a number"),
    ];
    for (body, want) in cases {
        let msg = assert_malformed("bad.ply", &ascii_ply(body, ""));
        assert!(msg.contains(want), "{body:?}: {msg}");
    }
    // Line numbers are reported for ASCII bodies (the header is 9 lines).
    let msg = assert_malformed("bad.ply", &ascii_ply("0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", ""));
    assert!(msg.contains("bad.ply:13:"), "{msg}");
    // Header errors.
    for (extra, want) in [
        ("property list uchar int x2\n", ""),
        ("property quad w\n", "unknown property type"),
        ("element extra 5\n", "no properties"),
        ("bogus line\n", "unknown PLY header line"),
    ] {
        let msg = assert_malformed("hdr.ply", &ascii_ply(ok, extra));
        assert!(msg.contains(want), "{extra:?}: {msg}");
    }
    assert_malformed("nohdr.ply", b"ply\nformat ascii 1.0\nelement vertex 0\n");
    assert_malformed("nomagic.ply", b"plx\nformat ascii 1.0\nend_header\n");
}

#[test]
fn stl_malformed_cases() {
    let tris = cube_triangles();
    // Count disagrees with size.
    let mut b = binary_stl(&tris, 12);
    b.truncate(b.len() - 10);
    let msg = assert_malformed("short.stl", &b);
    assert!(msg.contains("needs"), "{msg}");
    let msg = assert_malformed("lie.stl", &binary_stl(&tris, 2_000_000_000));
    assert!(msg.contains("2000000000"), "{msg}");
    // NaN in binary.
    let mut t = tris.clone();
    t[3][1][2] = f32::NAN;
    let msg = assert_malformed("nan.stl", &binary_stl(&t, 12));
    assert!(msg.contains("non-finite"), "{msg}");
    // Zero triangles.
    assert_malformed("none.stl", &binary_stl(&[], 0));
    // ASCII errors carry lines.
    let text = std::fs::read_to_string(data("tetra_ascii.stl")).unwrap();
    let msg = assert_malformed(
        "a.stl",
        text.replace("vertex 0 1 0", "vertex 0 nan 0").as_bytes(),
    );
    assert!(msg.contains("a.stl:5:"), "{msg}");
    let cut: String = text.lines().take(12).collect::<Vec<_>>().join("\n");
    let msg = assert_malformed("cut.stl", cut.as_bytes());
    assert!(msg.contains("truncated"), "{msg}");
    let two = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid\n";
    let msg = assert_malformed("two.stl", two.as_bytes());
    assert!(msg.contains("at least 3"), "{msg}");
    assert_malformed("tiny.stl", b"abc");
}

#[test]
fn off_malformed_cases() {
    for (src, want) in [
        (
            "OFF\n3 1 0\n0.000000 0.000000 0\n1 0 0\n",
            "ends after 2 of 3",
        ),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n", "claims 3 vertices"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "out of range"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2  0  1\n", "at least 3"),
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 NaN\n3 0 1 2\n", "non-finite"),
        ("OFF\n2147483648 1 0\n0 0 0\n", "claims"),
        ("OFF\n3\n", "counts"),
        ("OFF BINARY\n3 1 0\n", "binary"),
        ("PLY\n", "not an OFF"),
    ] {
        let msg = assert_malformed("m.off", src.as_bytes());
        assert!(msg.contains(want), "{src:?}: {msg}");
    }
}

#[test]
fn obj_malformed_cases() {
    for (src, want) in [
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
            "m.obj:4: vertex index 0",
        ),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
            "m.obj:4: vertex index 9 out of range",
        ),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", "m.obj:4:"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "at least 3"),
        ("v 0 0 1e999\n", "non-finite"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
        ("# nothing\n", "no vertices"),
    ] {
        let msg = assert_malformed("m.obj", src.as_bytes());
        assert!(msg.contains(want), "{src:?}: {msg}");
    }
}

#[test]
fn empty_files_and_junk_are_errors_for_every_format() {
    // Deterministic junk (xorshift), with NUL bytes and no structure.
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let junk: Vec<u8> = (0..5000)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 24) as u8
        })
        .collect();
    for ext in ["obj", "ply", "stl", "off"] {
        let name = format!("e.{ext}");
        let msg = assert_malformed(&name, b"");
        assert!(msg.contains("empty"), "{msg}");
        assert_malformed(&format!("j.{ext}"), &junk);
        // Junk behind a plausible magic.
        let mut j = match ext {
            "ply" => b"ply\nformat binary_little_endian 1.0\n".to_vec(),
            "off" => b"OFF\n".to_vec(),
            "stl" => b"solid junk\n".to_vec(),
            _ => b"v 0 0 0\n".to_vec(),
        };
        j.extend_from_slice(&junk);
        assert_malformed(&format!("jm.{ext}"), &j);
    }
}

#[test]
fn unknown_format_and_missing_file() {
    let e = io::read(Path::new("/nonexistent/x.xyz"), None).unwrap_err();
    assert!(matches!(e, IoError::UnknownFormat { .. }));
    let e = io::read(Path::new("/nonexistent/x.obj"), None).unwrap_err();
    assert!(matches!(e, IoError::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/x.obj"));
    // An explicit format overrides the extension.
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("mesh.txt");
    std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    assert_eq!(io::read(&p, Some(Format::Obj)).unwrap().faces.len(), 1);
}

// ---------------------------------------------------------------------------
// Writing

fn triangle_mesh() -> RawMesh {
    RawMesh {
        positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y],
        faces: vec![[0, 1, 2]],
        ..RawMesh::default()
    }
}

#[test]
fn write_refuses_unwritable_meshes_without_leaving_files() {
    let d = tempfile::tempdir().unwrap();
    let mut nan = triangle_mesh();
    nan.positions[1].y = f64::NAN;
    let mut range = triangle_mesh();
    range.faces[0][2] = 3;
    let mut colors = triangle_mesh();
    colors.colors = Some(vec![[0.0; 3]; 2]);
    let mut big = triangle_mesh();
    big.precision = Precision::F32;
    big.positions[0].x = 1e300;
    for (m, name) in [
        (nan, "nan"),
        (range, "range"),
        (colors, "colors"),
        (big, "big"),
    ] {
        for ext in ["obj", "ply", "stl", "off"] {
            let p = d.path().join(format!("{name}.{ext}"));
            let e = io::write(&p, &m, None).unwrap_err();
            assert!(e.to_string().contains(&format!("{name}.{ext}")), "{e}");
        }
    }
    assert_eq!(std::fs::read_dir(d.path()).unwrap().count(), 0);
    let e = io::write(&d.path().join("x.abc"), &triangle_mesh(), None).unwrap_err();
    assert!(matches!(e, IoError::UnknownFormat { .. }));
}

#[test]
fn write_replaces_existing_file() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("out.obj");
    std::fs::write(&p, "old content").unwrap();
    io::write(&p, &triangle_mesh(), None).unwrap();
    assert_eq!(io::read(&p, None).unwrap(), {
        let mut m = triangle_mesh();
        m.notes.clear();
        m
    });
    let names: Vec<_> = std::fs::read_dir(d.path()).unwrap().collect();
    assert_eq!(names.len(), 1);
}

#[test]
fn extreme_values_round_trip_in_text() {
    let mut m = triangle_mesh();
    m.positions = vec![
        DVec3::new(1e300, -1e-300, 5e-324),
        DVec3::new(f64::MAX, f64::MIN_POSITIVE, -0.0),
        DVec3::new(0.1 + 0.2, 1.0 / 3.0, 123456789.12345679),
    ];
    let d = tempfile::tempdir().unwrap();
    for name in ["a.obj", "a.off", "a.ply", "a.stl"] {
        let p = d.path().join(name);
        io::write(&p, &m, None).unwrap();
        let back = io::read(&p, None).unwrap();
        assert_eq!(bits(&back.positions), bits(&m.positions), "{name}");
    }
}

#[test]
fn obj_keeps_vertex_order_and_unused_vertices() {
    let m = RawMesh {
        positions: vec![DVec3::new(9.0, 9.0, 9.0), DVec3::ZERO, DVec3::X, DVec3::Y],
        faces: vec![[3, 2, 1]],
        ..RawMesh::default()
    };
    let d = tempfile::tempdir().unwrap();
    for name in ["a.obj", "a.off", "a.ply"] {
        let p = d.path().join(name);
        io::write(&p, &m, None).unwrap();
        let back = io::read(&p, None).unwrap();
        assert_eq!(back.positions, m.positions, "{name}");
        assert_eq!(back.faces, m.faces, "{name}");
    }
}

// ---------------------------------------------------------------------------
// Property tests: read -> write -> read is bit-exact for every format/encoding.

#[derive(Clone, Copy, Debug)]
struct Target {
    format: Format,
    encoding: Encoding,
    precision: Precision,
}

fn targets() -> Vec<Target> {
    let mut t = Vec::new();
    for precision in [Precision::F32, Precision::F64] {
        for (format, encoding) in [
            (Format::Obj, Encoding::Ascii),
            (Format::Off, Encoding::Ascii),
            (Format::Ply, Encoding::Ascii),
            (Format::Ply, Encoding::BinaryLittleEndian),
            (Format::Ply, Encoding::BinaryBigEndian),
            (Format::Stl, Encoding::Ascii),
            (Format::Stl, Encoding::BinaryLittleEndian),
        ] {
            t.push(Target {
                format,
                encoding,
                precision,
            });
        }
    }
    t
}

fn finite_f32() -> impl Strategy<Value = f64> {
    any::<f32>()
        .prop_filter("finite", |v| v.is_finite())
        .prop_map(f64::from)
}

fn finite_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        any::<f64>().prop_filter("finite", |v| v.is_finite()),
        (-1000.0f64..1000.0),
        finite_f32(),
    ]
}

/// A random soup: `f32`-exact coordinates when `f32` is set.
fn soup(f32: bool) -> impl Strategy<Value = RawMesh> {
    let coord = if f32 {
        finite_f32().boxed()
    } else {
        finite_f64().boxed()
    };
    (3usize..24, any::<bool>()).prop_flat_map(move |(n, with_colors)| {
        (
            prop::collection::vec((coord.clone(), coord.clone(), coord.clone()), n),
            prop::collection::vec([0..n as u32, 0..n as u32, 0..n as u32], 1..30),
            prop::collection::vec([any::<u8>(), any::<u8>(), any::<u8>()], n),
        )
            .prop_map(move |(p, faces, c)| RawMesh {
                positions: p.into_iter().map(|(x, y, z)| DVec3::new(x, y, z)).collect(),
                faces,
                colors: with_colors
                    .then(|| c.iter().map(|c| c.map(|b| f32::from(b) / 255.0)).collect()),
                ..RawMesh::default()
            })
    })
}

fn ext(f: Format) -> &'static str {
    f.name()
}

/// Writes `m` as `t` and reads it back.
fn through(dir: &Path, m: &RawMesh, t: Target, tag: &str) -> RawMesh {
    let mut m = m.clone();
    m.encoding = t.encoding;
    m.precision = t.precision;
    let p = dir.join(format!("{tag}.{}", ext(t.format)));
    io::write(&p, &m, None).unwrap_or_else(|e| panic!("write {t:?}: {e}"));
    io::read(&p, None).unwrap_or_else(|e| panic!("read {t:?}: {e}"))
}

fn check_round_trip(m: &RawMesh, f32_input: bool) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    for t in targets() {
        // F32 output needs f32-representable input; binary STL is always f32.
        let stores_f32 = t.precision == Precision::F32
            || (t.format == Format::Stl && t.encoding != Encoding::Ascii);
        if stores_f32 && !f32_input {
            continue;
        }
        let first = through(dir.path(), m, t, "first");
        let binary = t.encoding != Encoding::Ascii;
        if t.format == Format::Stl {
            // Welded, renumbered by first use: compare triangle corners by value
            // (the weld merges -0.0 with +0.0, keeping the first one seen).
            let got: Vec<_> = corners(&first).into_iter().flatten().collect();
            let want: Vec<_> = corners(m).into_iter().flatten().collect();
            if stores_f32 {
                let f = |p: &[DVec3]| p.iter().map(|v| v.as_vec3()).collect::<Vec<_>>();
                prop_assert_eq!(f(&got), f(&want), "{:?}", t);
            } else {
                prop_assert_eq!(got, want, "{:?}", t);
            }
        } else {
            prop_assert_eq!(&first.faces, &m.faces, "{:?}", t);
            if stores_f32 && !binary && t.format != Format::Ply {
                // Shortest f32 text parsed as f64: the same f32. (ASCII PLY declares
                // `float`, so its values are read as f32 and come back bit-exact.)
                prop_assert_eq!(f32s(&first.positions), f32s(&m.positions), "{:?}", t);
            } else {
                prop_assert_eq!(bits(&first.positions), bits(&m.positions), "{:?}", t);
            }
            prop_assert_eq!(&first.colors, &m.colors, "{:?}", t);
        }
        if binary && t.format == Format::Ply {
            prop_assert_eq!(first.precision, t.precision);
        }
        // Second trip: with the precision and encoding the reader reported.
        let second = through(
            dir.path(),
            &first,
            Target {
                format: t.format,
                encoding: first.encoding,
                precision: first.precision,
            },
            "second",
        );
        prop_assert_eq!(bits(&second.positions), bits(&first.positions), "{:?}", t);
        prop_assert_eq!(&second.faces, &first.faces, "{:?}", t);
        prop_assert_eq!(&second.colors, &first.colors, "{:?}", t);
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn round_trip_f32_exact(m in soup(true)) {
        check_round_trip(&m, true)?;
    }

    #[test]
    fn round_trip_f64(m in soup(false)) {
        check_round_trip(&m, false)?;
    }
}

/// Valid files of every format and encoding, as bytes (written once).
fn sample_files() -> &'static [(String, Vec<u8>)] {
    static FILES: std::sync::OnceLock<Vec<(String, Vec<u8>)>> = std::sync::OnceLock::new();
    FILES.get_or_init(make_sample_files)
}

fn make_sample_files() -> Vec<(String, Vec<u8>)> {
    let m = RawMesh {
        positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.5)],
        faces: vec![[0, 1, 2], [1, 3, 2]],
        colors: Some(vec![
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0; 3],
        ]),
        ..RawMesh::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let mut out = Vec::new();
    for t in targets() {
        let mut m = m.clone();
        m.encoding = t.encoding;
        m.precision = t.precision;
        let name = format!("s.{}", ext(t.format));
        let p = dir.path().join(&name);
        io::write(&p, &m, None).unwrap();
        out.push((name, std::fs::read(&p).unwrap()));
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Corrupted files (bytes overwritten, then truncated) give Ok or a content
    /// error naming the file, never a panic.
    #[test]
    fn corrupted_files_never_panic(
        which in 0usize..14,
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in any::<prop::sample::Index>(),
        do_cut in any::<bool>(),
    ) {
        let files = sample_files();
        let (name, mut bytes) = files[which % files.len()].clone();
        for (i, b) in edits {
            let k = i.index(bytes.len());
            bytes[k] = b;
        }
        if do_cut {
            let k = cut.index(bytes.len());
            bytes.truncate(k);
        }
        let (_d, _p, r) = read_bytes(&name, &bytes);
        if let Err(e) = r {
            prop_assert!(e.is_malformed(), "{}", e);
            prop_assert!(e.to_string().contains(&name), "{}", e);
        }
    }
}

#[test]
fn ply_integer_coordinates_and_count_types() {
    let src = "ply\nformat ascii 1.0\nelement vertex 3\nproperty short x\nproperty int16 y\n\
               property uint8 z\nelement face 1\nproperty list char uint vertex_indices\n\
               end_header\n-3 0 0\n1 -2 0\n0 1 255\n3 2 1 0\n";
    let (_d, _p, r) = read_bytes("i.ply", src.as_bytes());
    let m = r.unwrap();
    assert_eq!(m.precision, Precision::F32);
    assert_eq!(m.positions[2], DVec3::new(0.0, 1.0, 255.0));
    assert_eq!(m.faces, vec![[2, 1, 0]]);
    let wide = src.replace("property short x", "property int x");
    let (_d, _p, r) = read_bytes("i.ply", wide.as_bytes());
    assert_eq!(r.unwrap().precision, Precision::F64);
    // Float indices are a header lie about types.
    let bad = src.replace("char uint vertex_indices", "char float vertex_indices");
    let msg = assert_malformed("f.ply", bad.as_bytes());
    assert!(msg.contains("list of integers"), "{msg}");
}
