//! Attributes through the repair (issue 18): round trips in every format (every input
//! element's attributes bit-exact), interpolation oracles for the new elements, and
//! the repair log's `attributes` section from the real binary.

mod common;
use common::*;
use holefill::io::attrs::{PropData, Values};
use holefill::io::{self, Format, RawMesh};
use holefill::policy::Policy;
use std::fmt::Write as _;
use std::path::Path;

fn repair(raw: &RawMesh) -> (RawMesh, holefill::report::RepairReport) {
    holefill::repair(raw, &Policy::default()).expect("repair")
}

/// The values of a scalar property as f64 bits.
fn bits(d: &PropData) -> Vec<u64> {
    match d {
        PropData::Scalar(v) => (0..v.len()).map(|i| v.get(i).unwrap().to_bits()).collect(),
        PropData::List { starts, items, .. } => starts
            .iter()
            .copied()
            .chain((0..items.len()).map(|i| items.get(i).unwrap().to_bits()))
            .collect(),
    }
}

fn prop<'a>(raw: &'a RawMesh, name: &str) -> &'a PropData {
    &raw.attrs
        .vertex
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("no vertex property {name}"))
        .data
}

/// The PLY text of a soup with every kind of property: normals, colours, quality,
/// per-vertex UVs, an integer label and a list per vertex; per face an int, a
/// ushort and a texcoord list; a third element; comments.
fn rich_ply(s: &Soup) -> String {
    let mut t = String::new();
    writeln!(
        t,
        "ply\nformat ascii 1.0\ncomment scanner XYZ-3000\nobj_info serial 42\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property uchar red\nproperty uchar green\nproperty uchar blue\n\
         property float quality\nproperty double s\nproperty double t\n\
         property int label\nproperty list uchar short neighbours\n\
         element face {}\nproperty list uchar int vertex_indices\nproperty int texnumber\n\
         property ushort flags\nproperty list uchar float texcoord\n\
         element camera 1\nproperty double focal\nproperty list uchar uint ids\nend_header",
        s.v.len(),
        s.f.len()
    )
    .unwrap();
    for (i, p) in s.v.iter().enumerate() {
        let n = {
            let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt().max(1e-9);
            [p[0] / l, p[1] / l, p[2] / l]
        };
        writeln!(
            t,
            "{} {} {} {} {} {} {} {} {} {} {} {} {} 2 {} -{}",
            p[0] as f32,
            p[1] as f32,
            p[2] as f32,
            n[0] as f32,
            n[1] as f32,
            n[2] as f32,
            (i * 7) % 256,
            (i * 13) % 256,
            (i * 29) % 256,
            (0.1 + i as f32 * 0.37) % 1.0,
            p[0] * 0.5 + 0.5,
            p[1] * 0.5 + 0.5,
            (i % 3) as i32 - 1,
            i % 300,
            i % 7
        )
        .unwrap();
    }
    for (k, f) in s.f.iter().enumerate() {
        let uv = |v: usize| (s.v[v][0] * 0.5 + 0.5, s.v[v][1] * 0.5 + 0.5);
        let (a, b, c) = (uv(f[0]), uv(f[1]), uv(f[2]));
        writeln!(
            t,
            "3 {} {} {} {} {} 6 {} {} {} {} {} {}",
            f[0],
            f[1],
            f[2],
            k % 2,
            (k * 977) % 65536,
            a.0 as f32,
            a.1 as f32,
            b.0 as f32,
            b.1 as f32,
            c.0 as f32,
            c.1 as f32
        )
        .unwrap();
    }
    t.push_str("35.5 3 1 2 3\n");
    t
}

/// Everything but the header line holefill adds compares equal.
fn same_attrs(a: &RawMesh, b: &RawMesh) {
    let mut a = a.attrs.clone();
    let mut b = b.attrs.clone();
    for x in [&mut a, &mut b] {
        if let Some(p) = x.ply.as_mut() {
            p.header.retain(|l| l != "comment written by holefill");
        }
    }
    assert_eq!(a, b);
}

fn write_read(raw: &RawMesh, dir: &Path, name: &str) -> RawMesh {
    let p = dir.join(name);
    io::write(&p, raw, None).expect("write");
    io::read(&p, None).expect("read back")
}

#[test]
fn ply_every_property_round_trips_bit_exact_in_every_encoding() {
    let dir = tempdir();
    let s = icosphere(1);
    let src = dir.path().join("rich.ply");
    std::fs::write(&src, rich_ply(&s)).unwrap();
    let raw = io::read(&src, None).unwrap();
    assert_eq!(
        raw.attrs.vertex.len(),
        11,
        "{:?}",
        raw.attrs.vertex.iter().map(|p| &p.name).collect::<Vec<_>>()
    );
    assert_eq!(raw.attrs.face.len(), 2);
    assert!(raw.attrs.uv.is_some());
    let ply = raw.attrs.ply.as_ref().unwrap();
    assert_eq!(
        ply.header,
        ["comment scanner XYZ-3000", "obj_info serial 42"]
    );
    assert_eq!(ply.elements.len(), 1);
    // a closed mesh: the repair changes nothing, and every value comes back
    let (out, report) = repair(&raw);
    assert_eq!(report.summary.holes, 0);
    assert!(
        report
            .attributes
            .read
            .iter()
            .any(|r| r == "vertex quality (f32)"),
        "{:?}",
        report.attributes.read
    );
    same_attrs(&raw, &out);
    for enc in [
        io::Encoding::Ascii,
        io::Encoding::BinaryLittleEndian,
        io::Encoding::BinaryBigEndian,
    ] {
        let mut o = out.clone();
        o.encoding = enc;
        let back = write_read(&o, dir.path(), "out.ply");
        same_attrs(&raw, &back);
        assert_eq!(back.colors, raw.colors);
        let pb = |m: &RawMesh| {
            m.positions
                .iter()
                .map(|p| p.to_array().map(f64::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(pb(&back), pb(&raw));
    }
}

#[test]
fn ply_holed_input_elements_unchanged_and_new_ones_filled() {
    let dir = tempdir();
    let (s, _) = cut(&icosphere(3), [0.0, 0.0, 1.0], 0.3);
    let src = dir.path().join("holed.ply");
    std::fs::write(&src, rich_ply(&s)).unwrap();
    let raw = io::read(&src, None).unwrap();
    let (out, report) = repair(&raw);
    assert_eq!(report.summary.filled, 1);
    let nv = raw.positions.len();
    assert!(out.positions.len() > nv);
    for p in &raw.attrs.vertex {
        let o = prop(&out, &p.name);
        assert_eq!(o.len(), out.positions.len());
        match (&p.data, o) {
            (PropData::Scalar(a), PropData::Scalar(b)) => {
                assert_eq!(a.ty(), b.ty());
                for i in 0..nv {
                    assert_eq!(
                        a.get(i).unwrap().to_bits(),
                        b.get(i).unwrap().to_bits(),
                        "{} {i}",
                        p.name
                    );
                }
            }
            (a, b) => assert_eq!(bits(a)[..nv], bits(b)[..nv]),
        }
    }
    // new vertices: normals from the surface (unit, outward on the sphere), quality
    // within the rim's range, labels from the rim
    let PropData::Scalar(Values::F32(nz)) = prop(&out, "nz") else {
        panic!()
    };
    let PropData::Scalar(Values::F32(q)) = prop(&out, "quality") else {
        panic!()
    };
    let PropData::Scalar(Values::F32(q0)) = prop(&raw, "quality") else {
        panic!()
    };
    let (lo, hi) = q0
        .iter()
        .fold((f32::MAX, f32::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    for v in nv..out.positions.len() {
        assert!(nz[v] > 0.8, "normal of new vertex {v}: {}", nz[v]);
        assert!(q[v] >= lo && q[v] <= hi);
    }
    // every output face that is an input face keeps its values; new faces take the
    // neighbours' texnumber
    let key = |f: [u32; 3]| {
        let mut k = f;
        k.sort_unstable();
        k
    };
    let input: std::collections::HashMap<[u32; 3], usize> = raw
        .faces
        .iter()
        .enumerate()
        .map(|(i, f)| (key(*f), i))
        .collect();
    let fb = |m: &RawMesh, k: usize| bits(&m.attrs.face[1].data)[k];
    let mut new_faces = 0;
    for (k, f) in out.faces.iter().enumerate() {
        match input.get(&key(*f)) {
            Some(&j) => assert_eq!(fb(&out, k), fb(&raw, j)),
            None => new_faces += 1,
        }
    }
    assert!(new_faces > 0);
    let uv = out.attrs.uv.as_ref().unwrap();
    assert_eq!(
        report.attributes.uv_patches.mapped, 1,
        "{:?}",
        report.attributes
    );
    assert!(uv.index.iter().all(Option::is_some));
    // written and read back: the same
    let back = write_read(&out, dir.path(), "out.ply");
    for (a, b) in out.attrs.vertex.iter().zip(&back.attrs.vertex) {
        assert_eq!(a, b, "{}", a.name);
    }
    assert_eq!(out.attrs.face, back.attrs.face);
    // per corner (the file stores texcoord per face, so its table is per corner)
    let (u0, u1) = (
        out.attrs.uv.as_ref().unwrap(),
        back.attrs.uv.as_ref().unwrap(),
    );
    for k in 0..out.faces.len() {
        for c in 0..3 {
            let (a, b) = (u0.at(k, c).unwrap(), u1.at(k, c).unwrap());
            assert_eq!(
                a.map(f64::to_bits),
                b.map(f64::to_bits),
                "face {k} corner {c}"
            );
        }
    }
    assert_eq!(
        out.attrs.ply,
        back.attrs.ply.map(|mut p| {
            p.header.retain(|l| l != "comment written by holefill");
            p
        })
    );
}

/// A textured OBJ: the upper part of a sphere, UV = (x, y) / 2 + 1/2 (one chart),
/// normals per corner, two materials, groups, smoothing.
fn textured_obj(s: &Soup) -> String {
    let mut t = String::from("# scan\nmtllib scan.mtl\n");
    for p in &s.v {
        writeln!(t, "v {} {} {}", p[0], p[1], p[2]).unwrap();
    }
    for p in &s.v {
        writeln!(t, "vt {} {}", p[0] * 0.5 + 0.5, p[1] * 0.5 + 0.5).unwrap();
    }
    for p in &s.v {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        writeln!(t, "vn {} {} {}", p[0] / l, p[1] / l, p[2] / l).unwrap();
    }
    t.push_str("o scan\ng front\nusemtl skin\ns 1\n");
    for (k, f) in s.f.iter().enumerate() {
        if k == s.f.len() / 2 {
            t.push_str("g back\nusemtl cloth\n");
        }
        let c = |i: usize| format!("{0}/{0}/{0}", i + 1);
        writeln!(t, "f {} {} {}", c(f[0]), c(f[1]), c(f[2])).unwrap();
    }
    t
}

/// Faces whose centroid is above `z`.
fn upper(s: &Soup, z: f64) -> Soup {
    s.remove_faces(|c, _| c[2] <= z)
}

#[test]
fn obj_textured_round_trip_is_exact() {
    let dir = tempdir();
    let s = icosphere(2);
    let src = dir.path().join("scan.obj");
    std::fs::write(&src, textured_obj(&s)).unwrap();
    let raw = io::read(&src, None).unwrap();
    let obj = raw.attrs.obj.as_ref().unwrap();
    assert_eq!(obj.mtllibs, ["scan.mtl"]);
    assert_eq!(obj.states.len(), 3); // default, front/skin, back/cloth
    let (out, report) = repair(&raw);
    assert_eq!(report.summary.holes, 0);
    same_attrs(&raw, &out);
    let back = write_read(&out, dir.path(), "out.obj");
    assert_eq!(back.attrs, raw.attrs);
    let text = std::fs::read_to_string(dir.path().join("out.obj")).unwrap();
    for line in [
        "mtllib scan.mtl",
        "usemtl skin",
        "usemtl cloth",
        "g back",
        "s 1",
        "o scan",
    ] {
        assert!(text.lines().any(|l| l == line), "{line} missing");
    }
}

/// Twice the signed UV area of every face that has texture coordinates.
fn uv_areas(m: &RawMesh) -> Vec<(usize, f64)> {
    let uv = m.attrs.uv.as_ref().unwrap();
    m.faces
        .iter()
        .enumerate()
        .filter_map(|(k, _)| {
            let i = uv.index[k]?;
            let [a, b, c] = i.map(|i| uv.values[i as usize]);
            Some((
                k,
                (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]),
            ))
        })
        .collect()
}

#[test]
fn sphere_cap_hole_gets_unflipped_uvs_and_the_neighbours_material() {
    let dir = tempdir();
    // the upper part of a sphere (UV = projection on the xy plane: one chart,
    // every input UV triangle counter-clockwise), with a hole off the pole
    let s = upper(&icosphere(4), 0.2);
    let (s, _) = cut(&s, [0.35, 0.2, 0.915], 0.25);
    let src = dir.path().join("cap.obj");
    std::fs::write(&src, textured_obj(&s)).unwrap();
    let raw = io::read(&src, None).unwrap();
    assert!(uv_areas(&raw).iter().all(|&(_, a)| a > 0.0));
    let (out, report) = repair(&raw);
    // the rim of the cap is the outer border (skipped); the hole is filled
    assert_eq!(report.summary.filled, 1, "{:?}", report.summary);
    assert_eq!(
        report.attributes.uv_patches.mapped, 1,
        "{:?}",
        report.attributes
    );
    let areas = uv_areas(&out);
    assert_eq!(areas.len(), out.faces.len());
    let flipped: Vec<_> = areas.iter().filter(|&&(_, a)| a <= 0.0).collect();
    assert!(flipped.is_empty(), "flipped UV triangles: {flipped:?}");
    // new faces take the state of the faces around the hole; every input face keeps
    // its own
    let o = out.attrs.obj.as_ref().unwrap();
    assert_eq!(o.face_state.len(), out.faces.len());
    let input_states = &raw.attrs.obj.as_ref().unwrap().face_state;
    assert_eq!(&o.face_state[..raw.faces.len()], &input_states[..]);
    // normals: every new face has them, unit
    let n = out.attrs.normals.as_ref().unwrap();
    for k in raw.faces.len()..out.faces.len() {
        for i in n.index[k].unwrap() {
            let v = n.values[i as usize];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            assert!((l - 1.0).abs() < 1e-9 && v[2] > 0.5, "{v:?}");
        }
    }
}

#[test]
fn planar_grid_hole_uvs_and_colours_are_linear_within_bound() {
    // a 20 x 20 grid of unit quads; UV = (x, y) / 20; colour = (x / 20, y / 20, 0.25 +
    // (x + y) / 80), all linear; a round hole of radius 4 in the middle
    let g = grid_soup(20);
    let (s, _) = cut(&g, [10.0, 10.0, 0.0], 4.0);
    let t = linear_grid_obj(&s);
    let dir = tempdir();
    let src = dir.path().join("grid.obj");
    std::fs::write(&src, t).unwrap();
    let raw = io::read(&src, None).unwrap();
    let (out, report) = repair(&raw);
    assert_eq!(report.summary.filled, 1, "{:?}", report.summary);
    assert_eq!(
        report.attributes.uv_patches.mapped, 1,
        "{:?}",
        report.attributes
    );
    let nv = raw.positions.len();
    assert!(out.positions.len() > nv + 10);
    // the bound: 1e-6 of the UV range (cotangent weights reproduce a linear field
    // on a planar patch; the patch is planar to within the fill's tolerance)
    let bound = 1e-6;
    let colors = out.colors.as_ref().unwrap();
    let uv = out.attrs.uv.as_ref().unwrap();
    let mut worst: f64 = 0.0;
    assert_eq!(colors.len(), out.positions.len(), "a colour per vertex");
    for (p, color) in out.positions.iter().zip(colors).skip(nv) {
        assert!(p.z.abs() < 1e-9, "patch not planar: {p}");
        let want = [p.x / 20.0, p.y / 20.0, 0.25 + (p.x + p.y) / 80.0];
        for k in 0..3 {
            worst = worst.max((f64::from(color[k]) - want[k]).abs() - 1e-7);
        }
    }
    for (k, f) in out.faces.iter().enumerate().skip(raw.faces.len()) {
        let idx = uv.index[k].expect("new face without UVs");
        for c in 0..3 {
            let p = out.positions[f[c] as usize];
            let t = uv.values[idx[c] as usize];
            worst = worst
                .max((t[0] - p.x / 20.0).abs())
                .max((t[1] - p.y / 20.0).abs());
        }
    }
    assert!(
        worst < bound,
        "worst deviation from the linear field: {worst}"
    );
}

/// A planar grid of `n` x `n` unit quads in z = 0.
fn grid_soup(n: usize) -> Soup {
    grid(n, n, 1.0, 0.0, 0.0, |_, _| 0.0)
}

#[test]
fn stl_header_and_attribute_bytes_are_carried() {
    let dir = tempdir();
    let (s, _) = cut(&icosphere(3), [0.0, 0.0, 1.0], 0.3);
    let mut b = Vec::new();
    let mut header = [0u8; 80];
    let text = b"COLOR=\x10\x20\x30\xffMATERIAL=";
    header[..text.len()].copy_from_slice(text);
    b.extend_from_slice(&header);
    b.extend_from_slice(&(s.f.len() as u32).to_le_bytes());
    for (k, f) in s.f.iter().enumerate() {
        b.extend_from_slice(&[0u8; 12]);
        for &v in f {
            for c in s.v[v] {
                b.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
        let attr: u16 = if k % 5 == 0 {
            0x8000 | k as u16
        } else {
            0x7c1f
        };
        b.extend_from_slice(&attr.to_le_bytes());
    }
    let src = dir.path().join("c.stl");
    std::fs::write(&src, &b).unwrap();
    let raw = io::read(&src, None).unwrap();
    let (out, report) = repair(&raw);
    assert_eq!(report.summary.filled, 1);
    let back = write_read(&out, dir.path(), "out.stl");
    let st = back.attrs.stl.as_ref().unwrap();
    assert_eq!(st.header, header);
    let a0 = &raw.attrs.stl.as_ref().unwrap().attribute;
    assert_eq!(&st.attribute[..a0.len()], &a0[..]);
    // new facets: the most common attribute around the hole
    assert!(st.attribute[a0.len()..].iter().all(|&a| a == 0x7c1f));
}

#[test]
fn off_normals_colours_and_texture_coordinates_round_trip() {
    let dir = tempdir();
    let s = icosphere(1);
    let mut t = format!("STCNOFF\n{} {} 0\n", s.v.len(), s.f.len());
    for (i, p) in s.v.iter().enumerate() {
        writeln!(
            t,
            "{} {} {} {} {} {} {} {} {} {} 0.{} 0.{}",
            p[0],
            p[1],
            p[2],
            p[0],
            p[1],
            p[2],
            i * 9 % 256,
            17,
            200,
            255,
            i,
            i + 1
        )
        .unwrap();
    }
    for f in &s.f {
        writeln!(t, "3 {} {} {}", f[0], f[1], f[2]).unwrap();
    }
    let src = dir.path().join("n.off");
    std::fs::write(&src, t).unwrap();
    let raw = io::read(&src, None).unwrap();
    assert_eq!(raw.attrs.vertex.len(), 9);
    let (out, _) = repair(&raw);
    let back = write_read(&out, dir.path(), "out.off");
    assert_eq!(back.attrs, raw.attrs);
    assert_eq!(back.colors, raw.colors);
}

#[test]
fn dropped_attributes_are_named_with_the_reason() {
    let s = icosphere(1);
    let dir = tempdir();
    let src = dir.path().join("scan.obj");
    std::fs::write(&src, textured_obj(&s)).unwrap();
    let raw = io::read(&src, None).unwrap();
    let d = io::attrs::dropped(&raw, Format::Stl);
    assert!(
        d.iter()
            .any(|d| d.what == "texture coordinates" && d.reason.starts_with("STL")),
        "{d:?}"
    );
    assert!(d.iter().any(|d| d.what == "material library scan.mtl"));
    assert!(io::attrs::dropped(&raw, Format::Obj).is_empty());
}

#[test]
fn cli_log_has_the_attributes_section() {
    let dir = tempdir();
    let (s, _) = cut(&upper(&icosphere(3), 0.2), [0.35, 0.2, 0.915], 0.3);
    let src = dir.path().join("scan.obj");
    std::fs::write(&src, textured_obj(&s)).unwrap();
    for (out, dropped) in [("out.obj", false), ("out.stl", true)] {
        let o = dir.path().join(out);
        let log = dir.path().join("log.json");
        let r = run(&[
            "fill",
            src.to_str().unwrap(),
            o.to_str().unwrap(),
            "--report",
            log.to_str().unwrap(),
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&log).unwrap()).unwrap();
        let a = &j["attributes"];
        assert!(
            a["read"]
                .as_array()
                .unwrap()
                .iter()
                .any(|x| x == "corner texture coordinates"),
            "{a}"
        );
        assert!(a["interpolated"].as_array().unwrap().len() >= 2, "{a}");
        let d = a["dropped"].as_array().unwrap();
        assert_eq!(!d.is_empty(), dropped, "{a}");
    }
}

/// The holed 20 x 20 grid with UV = (x, y) / 20 and a linear colour, as OBJ text.
fn linear_grid_obj(s: &Soup) -> String {
    let mut t = String::new();
    for p in &s.v {
        writeln!(
            t,
            "v {} {} {} {} {} {}",
            p[0],
            p[1],
            p[2],
            p[0] / 20.0,
            p[1] / 20.0,
            0.25 + (p[0] + p[1]) / 80.0
        )
        .unwrap();
    }
    for p in &s.v {
        writeln!(t, "vt {} {}", p[0] / 20.0, p[1] / 20.0).unwrap();
    }
    for f in &s.f {
        writeln!(t, "f {0}/{0} {1}/{1} {2}/{2}", f[0] + 1, f[1] + 1, f[2] + 1).unwrap();
    }
    t
}

#[test]
fn gltf_keeps_its_document_and_the_patch_gets_linear_uvs_and_colours() {
    let dir = tempdir();
    let (s, _) = cut(&grid_soup(20), [10.0, 10.0, 0.0], 4.0);
    let obj = dir.path().join("grid.obj");
    std::fs::write(&obj, linear_grid_obj(&s)).unwrap();
    // a .gltf made by the writer, then given a material with extras, as a scanner's
    let made = dir.path().join("made.gltf");
    io::write(&made, &io::read(&obj, None).unwrap(), None).unwrap();
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&made).unwrap()).unwrap();
    doc["materials"] = serde_json::json!([{"name": "skin", "extras": {"scanner": "XYZ-3000"}}]);
    doc["meshes"][0]["primitives"][0]["material"] = serde_json::json!(0);
    let src = dir.path().join("scan.gltf");
    std::fs::write(&src, serde_json::to_vec(&doc).unwrap()).unwrap();

    for out_name in ["out.gltf", "out.glb"] {
        let out = dir.path().join(out_name);
        let log = dir.path().join("log.json");
        let r = run(&[
            "fill",
            src.to_str().unwrap(),
            out.to_str().unwrap(),
            "--report",
            log.to_str().unwrap(),
        ]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&log).unwrap()).unwrap();
        assert_eq!(j["summary"]["filled"], 1, "{j}");
        assert!(
            j["attributes"]["dropped"].as_array().unwrap().is_empty(),
            "{j}"
        );

        // the document: everything read is there unchanged, the patch a new primitive
        let back = io::read(&out, None).expect("the output reads as glTF");
        let g = back.attrs.gltf.as_ref().unwrap();
        let o = &g.json;
        assert_eq!(o["materials"], doc["materials"]);
        let prims = o["meshes"][0]["primitives"].as_array().unwrap();
        assert_eq!(prims.len(), 2, "{o}");
        assert_eq!(prims[0], doc["meshes"][0]["primitives"][0]);
        assert_eq!(prims[1]["material"], 0);
        let n_acc = doc["accessors"].as_array().unwrap().len();
        assert_eq!(
            o["accessors"].as_array().unwrap()[..n_acc],
            doc["accessors"].as_array().unwrap()[..]
        );
        // the input's buffer is there byte for byte: first in a .gltf (the patch data
        // is a new buffer after it), second in a .glb (the binary chunk, which holds the
        // patch data, must be the first buffer)
        let input = io::read(&src, None).unwrap();
        let ib = &input.attrs.gltf.as_ref().unwrap().buffers[0];
        let k = usize::from(out_name.ends_with(".glb"));
        assert_eq!(g.buffers.len(), 2);
        assert_eq!(&g.buffers[k], ib);
        // every input vertex and triangle is there, bit for bit
        assert_eq!(back.positions[..input.positions.len()], input.positions[..]);
        assert_eq!(back.faces[..input.faces.len()], input.faces[..]);
        assert!(back.faces.len() > input.faces.len());

        // the patch's UVs and colours: the linear field within f32 rounding
        let uv = back.attrs.uv.as_ref().unwrap();
        let colors = back.colors.as_ref().unwrap();
        let mut worst: f64 = 0.0;
        for (k, f) in back.faces.iter().enumerate().skip(input.faces.len()) {
            let idx = uv.index[k].expect("a patch face without UVs");
            for c in 0..3 {
                let p = back.positions[f[c] as usize];
                let t = uv.values[idx[c] as usize];
                worst = worst
                    .max((t[0] - p.x / 20.0).abs())
                    .max((t[1] - p.y / 20.0).abs());
                let want = [p.x / 20.0, p.y / 20.0, 0.25 + (p.x + p.y) / 80.0];
                for d in 0..3 {
                    worst = worst.max((f64::from(colors[f[c] as usize][d]) - want[d]).abs());
                }
            }
        }
        assert!(worst < 1e-6, "{out_name}: worst deviation {worst}");
    }

    // as OBJ, its UVs are kept
    let as_obj = dir.path().join("as.obj");
    let r = run(&["fill", src.to_str().unwrap(), as_obj.to_str().unwrap()]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let o = io::read(&as_obj, None).unwrap();
    assert!(o.attrs.uv.is_some());
}

#[test]
fn a_gltf_without_holes_is_written_back_byte_for_byte() {
    let dir = tempdir();
    let s = icosphere(2);
    let obj = dir.path().join("ball.obj");
    write_obj(&obj, &s);
    for name in ["ball.glb", "ball.gltf"] {
        let src = dir.path().join(name);
        io::write(&src, &io::read(&obj, None).unwrap(), None).unwrap();
        let out = dir.path().join(format!("out-{name}"));
        let r = run(&["fill", src.to_str().unwrap(), out.to_str().unwrap()]);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        assert_eq!(
            std::fs::read(&src).unwrap(),
            std::fs::read(&out).unwrap(),
            "{name}"
        );
    }
}

/// The holed 20 x 20 grid as OBJ with colours written 0..255: red and green linear in
/// x and y (integers at the grid's vertices), blue constant.
fn byte_colour_grid_obj(s: &Soup) -> String {
    s.obj_text_with(|p| {
        let (r, g) = (40.0 + 8.0 * p[0], 30.0 + 9.0 * p[1]);
        format!(" {r} {g} 200")
    })
}

#[test]
fn obj_byte_colours_come_back_as_written_and_new_vertices_in_the_same_scale() {
    let dir = tempdir();
    let vlines = |t: &str| -> Vec<String> {
        t.lines()
            .filter(|l| l.starts_with("v "))
            .map(str::to_string)
            .collect()
    };
    // no hole: every vertex line comes back as written
    let whole = byte_colour_grid_obj(&grid_soup(6));
    std::fs::write(dir.path().join("whole.obj"), &whole).unwrap();
    let raw = io::read(&dir.path().join("whole.obj"), None).unwrap();
    let (out, report) = repair(&raw);
    assert_eq!(report.summary.filled, 0, "{:?}", report.summary); // the border is no hole
    assert_eq!(out.positions.len(), raw.positions.len());
    same_attrs(&raw, &out);
    io::write(&dir.path().join("whole.out.obj"), &out, None).unwrap();
    let text = std::fs::read_to_string(dir.path().join("whole.out.obj")).unwrap();
    assert_eq!(vlines(&text), vlines(&whole));

    // a hole: input vertices' lines unchanged, new vertices' colours 0..255, linear
    let (s, _) = cut(&grid_soup(20), [10.0, 10.0, 0.0], 4.0);
    let holed = byte_colour_grid_obj(&s);
    let src = dir.path().join("holed.obj");
    std::fs::write(&src, &holed).unwrap();
    let raw = io::read(&src, None).unwrap();
    let (out, report) = repair(&raw);
    assert!(report.summary.filled >= 1);
    let nv = raw.positions.len();
    assert!(out.positions.len() > nv);
    let dst = dir.path().join("out.obj");
    io::write(&dst, &out, None).unwrap();
    let text = std::fs::read_to_string(&dst).unwrap();
    let (a, b) = (vlines(&holed), vlines(&text));
    assert_eq!(b.len(), out.positions.len());
    assert_eq!(a[..], b[..nv]);
    for (v, line) in b.iter().enumerate().skip(nv) {
        let t: Vec<f64> = line
            .split_whitespace()
            .skip(1)
            .map(|x| x.parse().unwrap())
            .collect();
        assert_eq!(t.len(), 6, "{line}");
        let p = out.positions[v];
        assert!((t[3] - (40.0 + 8.0 * p.x)).abs() <= 0.5 + 1e-6, "{line}");
        assert!((t[4] - (30.0 + 9.0 * p.y)).abs() <= 0.5 + 1e-6, "{line}");
        assert_eq!(t[5], 200.0, "{line}");
    }
    // read back: the same values, the same 0..1 colours (new vertices' those of the
    // bytes written)
    let back = io::read(&dst, None).unwrap();
    assert_eq!(back.attrs, out.attrs);
    assert_eq!(back.colors, out.colors);
    assert!(report
        .attributes
        .interpolated
        .iter()
        .any(|s| s.starts_with("vertex red")));
}

#[test]
fn obj_unit_colours_with_more_digits_than_f32_come_back_as_written() {
    // red and green linear in x and y with every digit of an f64, blue constant
    let obj = |s: &Soup| {
        s.obj_text_with(|p| {
            let (r, g) = (0.1 + 0.031 * p[0], 0.2 + 0.029 * p[1]);
            format!(" {r} {g} 0.7")
        })
    };
    let vlines = |t: &str| -> Vec<String> {
        t.lines()
            .filter(|l| l.starts_with("v "))
            .map(str::to_string)
            .collect()
    };
    let dir = tempdir();
    let (s, _) = cut(&grid_soup(20), [10.0, 10.0, 0.0], 4.0);
    let holed = obj(&s);
    let src = dir.path().join("holed.obj");
    std::fs::write(&src, &holed).unwrap();
    let raw = io::read(&src, None).unwrap();
    let (out, report) = repair(&raw);
    assert!(report.summary.filled >= 1);
    let nv = raw.positions.len();
    let dst = dir.path().join("out.obj");
    io::write(&dst, &out, None).unwrap();
    let text = std::fs::read_to_string(&dst).unwrap();
    let (a, b) = (vlines(&holed), vlines(&text));
    assert_eq!(b.len(), out.positions.len());
    assert!(b.len() > nv);
    assert_eq!(a[..], b[..nv], "input vertices' lines as written");
    for (v, line) in b.iter().enumerate().skip(nv) {
        let t: Vec<f64> = line
            .split_whitespace()
            .skip(1)
            .map(|x| x.parse().unwrap())
            .collect();
        let p = out.positions[v];
        assert!((t[3] - (0.1 + 0.031 * p.x)).abs() <= 1e-3, "{line}");
        assert!((t[4] - (0.2 + 0.029 * p.y)).abs() <= 1e-3, "{line}");
        assert!((t[5] - 0.7).abs() <= 1e-9, "{line}");
    }
    let back = io::read(&dst, None).unwrap();
    assert_eq!(back.attrs, out.attrs);
    assert_eq!(back.colors, out.colors);
}

/// OFF text of a soup with a colour `r g b a` on every face (the writer's layout).
fn face_coloured_off(s: &Soup, colour: impl Fn(usize, &[usize; 3]) -> [u8; 4]) -> String {
    let mut t = format!("OFF\n{} {} 0\n", s.v.len(), s.f.len());
    for p in &s.v {
        writeln!(t, "{} {} {}", p[0], p[1], p[2]).unwrap();
    }
    for (k, f) in s.f.iter().enumerate() {
        let c = colour(k, f);
        writeln!(
            t,
            "3 {} {} {} {} {} {} {}",
            f[0], f[1], f[2], c[0], c[1], c[2], c[3]
        )
        .unwrap();
    }
    t
}

/// Each face's `red green blue alpha` values.
fn face_colours(raw: &RawMesh) -> Vec<[f64; 4]> {
    let col = |name: &str| match raw.attrs.face.iter().find(|p| p.name == name) {
        Some(p) => match &p.data {
            PropData::Scalar(v) => v.clone(),
            _ => panic!("{name} is a list"),
        },
        None => panic!("no face property {name}"),
    };
    let c = ["red", "green", "blue", "alpha"].map(col);
    (0..raw.faces.len())
        .map(|j| [0, 1, 2, 3].map(|k| c[k].get(j).unwrap()))
        .collect()
}

#[test]
fn off_face_colours_are_kept_and_new_faces_take_the_colour_around_the_hole() {
    let dir = tempdir();
    // no hole: the file comes back identical
    let g = grid_soup(4);
    let whole = face_coloured_off(&g, |k, _| [(k * 37 % 256) as u8, 200, (k * 3) as u8, 255]);
    std::fs::write(dir.path().join("whole.off"), &whole).unwrap();
    let raw = io::read(&dir.path().join("whole.off"), None).unwrap();
    assert_eq!(raw.attrs.face.len(), 4);
    let (out, report) = repair(&raw);
    assert_eq!(report.summary.filled, 0, "{:?}", report.summary);
    io::write(&dir.path().join("whole.out.off"), &out, None).unwrap();
    let text = std::fs::read_to_string(dir.path().join("whole.out.off")).unwrap();
    assert_eq!(text, whole);

    // a hole: input faces keep theirs; the faces around the hole are one colour,
    // which every new face takes (all four channels from one face)
    let s0 = icosphere(3);
    let centre = [0.0, 0.0, 1.0];
    let (s, _) = cut(&s0, centre, 0.3);
    let near = |f: &[usize; 3]| {
        let c = [0, 1, 2].map(|k| f.iter().map(|&i| s.v[i][k]).sum::<f64>() / 3.0);
        (0..3)
            .map(|k| (c[k] - centre[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            < 0.6
    };
    let text = face_coloured_off(&s, |k, f| {
        if near(f) {
            [10, 20, 30, 255]
        } else {
            [
                (k % 256) as u8,
                (k * 7 % 256) as u8,
                255 - (k % 256) as u8,
                128,
            ]
        }
    });
    let src = dir.path().join("holed.off");
    std::fs::write(&src, text).unwrap();
    let raw = io::read(&src, None).unwrap();
    let (out, report) = repair(&raw);
    assert_eq!(report.summary.filled, 1);
    let key = |f: [u32; 3]| {
        let mut k = f;
        k.sort_unstable();
        k
    };
    let input: std::collections::HashMap<[u32; 3], usize> = raw
        .faces
        .iter()
        .enumerate()
        .map(|(j, &f)| (key(f), j))
        .collect();
    let (a, b) = (face_colours(&raw), face_colours(&out));
    let mut new = 0;
    for (f, c) in out.faces.iter().zip(&b) {
        let in_face = (f.iter().all(|&v| (v as usize) < raw.positions.len()))
            .then(|| input.get(&key(*f)))
            .flatten();
        match in_face {
            Some(&j) => assert_eq!(c.map(f64::to_bits), a[j].map(f64::to_bits)),
            None => {
                new += 1;
                assert_eq!(*c, [10.0, 20.0, 30.0, 255.0]);
            }
        }
    }
    assert!(new > 0);
    assert!(
        report
            .attributes
            .interpolated
            .iter()
            .any(|s| s == "face red: the most common colour of the faces around the hole"),
        "{:?}",
        report.attributes
    );
    assert!(report.attributes.read.iter().any(|s| s == "face red (u8)"));
    // written and read back: the same values
    let back = write_read(&out, dir.path(), "out.off");
    assert_eq!(back.attrs, out.attrs);
}

/// The holed 20 x 20 grid as a `.gltf` of two meshes (the faces left and right of
/// x = 10, each with its own material and index accessor, one POSITION accessor shared),
/// each placed by a node of its own (the second with `translation`).
fn two_mesh_grid_gltf(s: &Soup, translation: [f64; 3]) -> Vec<u8> {
    use base64::Engine as _;
    use serde_json::json;
    let mut bin: Vec<u8> = Vec::new();
    for p in &s.v {
        for x in p {
            bin.extend_from_slice(&(*x as f32).to_le_bytes());
        }
    }
    let mut views = vec![json!({"buffer": 0, "byteOffset": 0, "byteLength": bin.len()})];
    let mut accessors = vec![json!({"bufferView": 0, "componentType": 5126,
        "count": s.v.len(), "type": "VEC3", "min": [0, 0, 0], "max": [20, 20, 0]})];
    let centre_x = |f: &[usize; 3]| f.iter().map(|&i| s.v[i][0]).sum::<f64>() / 3.0;
    for left in [true, false] {
        let off = bin.len();
        let mut n = 0;
        for f in s.f.iter().filter(|f| (centre_x(f) < 10.0) == left) {
            for &i in f {
                bin.extend_from_slice(&(i as u32).to_le_bytes());
                n += 1;
            }
        }
        views.push(json!({"buffer": 0, "byteOffset": off, "byteLength": bin.len() - off}));
        accessors.push(json!({"bufferView": views.len() - 1, "componentType": 5125,
            "count": n, "type": "SCALAR"}));
    }
    let doc = json!({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"mesh": 0}, {"mesh": 1, "translation": translation}],
        "materials": [{"name": "left"}, {"name": "right"}],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]},
            {"primitives": [{"attributes": {"POSITION": 0}, "indices": 2, "material": 1}]}
        ],
        "accessors": accessors, "bufferViews": views,
        "buffers": [{"byteLength": bin.len(), "uri": format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&bin))}]
    });
    serde_json::to_vec(&doc).unwrap()
}

#[test]
fn a_gltf_of_two_meshes_in_one_frame_is_repaired_as_one_and_each_keeps_its_primitives() {
    let dir = tempdir();
    let (s, _) = cut(&grid_soup(20), [10.0, 10.0, 0.0], 4.0);
    let src = dir.path().join("two.gltf");
    std::fs::write(&src, two_mesh_grid_gltf(&s, [0.0, 0.0, 0.0])).unwrap();
    let input = io::read(&src, None).unwrap();
    let g = input.attrs.gltf.as_ref().unwrap();
    assert_eq!(g.prims.iter().map(|p| p.mesh).collect::<Vec<_>>(), [0, 1]);
    assert_eq!(
        input.positions.len(),
        s.v.len(),
        "the meshes share their vertices"
    );
    let out = dir.path().join("out.gltf");
    let log = dir.path().join("out.json");
    let r = run(&[
        "fill",
        src.to_str().unwrap(),
        out.to_str().unwrap(),
        "--report",
        log.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&log).unwrap()).unwrap();
    assert_eq!(j["summary"]["filled"], 1, "{j}");
    // both meshes keep their primitive; the patch is one new primitive in the mesh
    // (and with the material) of the faces around the hole
    let back = io::read(&out, None).unwrap();
    let o = &back.attrs.gltf.as_ref().unwrap().json;
    let doc: serde_json::Value = serde_json::from_slice(&std::fs::read(&src).unwrap()).unwrap();
    let mut added = Vec::new();
    for m in 0..2 {
        let ps = o["meshes"][m]["primitives"].as_array().unwrap();
        assert_eq!(ps[0], doc["meshes"][m]["primitives"][0]);
        for p in &ps[1..] {
            assert_eq!(p["material"], m, "{p}");
            added.push(m);
        }
    }
    assert_eq!(added.len(), 1, "{o}");
    // every input vertex and triangle is there, bit for bit (read back, the patch's
    // triangles follow those of its mesh's first primitive)
    assert_eq!(back.positions[..input.positions.len()], input.positions[..]);
    let bg = back.attrs.gltf.as_ref().unwrap();
    let kept: Vec<[u32; 3]> = bg
        .prims
        .iter()
        .filter(|p| p.index == 0)
        .flat_map(|p| back.faces[p.first_face..p.first_face + p.faces].to_vec())
        .collect();
    assert_eq!(kept, input.faces);
    assert!(back.faces.len() > input.faces.len());

    // meshes placed in different frames: refused, with the reason
    std::fs::write(&src, two_mesh_grid_gltf(&s, [5.0, 0.0, 0.0])).unwrap();
    let e = io::read(&src, None).unwrap_err();
    assert!(e.to_string().contains("different frames"), "{e}");
    let r = run(&["fill", src.to_str().unwrap(), out.to_str().unwrap()]);
    assert_eq!(r.status.code(), Some(65));
}
