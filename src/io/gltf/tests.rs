use super::*;
use crate::io::attrs::{percent_decode, GltfExtras};
use crate::io::{read_bytes, Format, ReadLimits};
use crate::io::{IoError, Precision, RawMesh, Resources};
use base64::Engine as _;
use serde_json::{json, Value};
use std::path::Path;

/// A unit square of two triangles in one primitive, with normals, UVs and colours,
/// as a GLB (or its JSON with a data URI).
fn square(glb: bool) -> Vec<u8> {
    let pos: [[f32; 3]; 4] = [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
    let mut bin: Vec<u8> = Vec::new();
    for p in pos {
        for x in p {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    for _ in 0..4 {
        for x in [0f32, 0., 1.] {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    for p in pos {
        for x in [p[0], p[1]] {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let mut doc = json!({
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "materials": [{"name": "skin"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": 0}]}],
        "accessors": [
            {"bufferView": 0, "componentType": FLOAT, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]},
            {"bufferView": 1, "componentType": FLOAT, "count": 4, "type": "VEC3"},
            {"bufferView": 2, "componentType": FLOAT, "count": 4, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 48},
            {"buffer": 0, "byteOffset": 96, "byteLength": 32},
            {"buffer": 0, "byteOffset": 128, "byteLength": 12}
        ],
        "buffers": [{"byteLength": bin.len()}]
    });
    if !glb {
        doc["buffers"][0]["uri"] = json!(format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&bin)
        ));
        return serde_json::to_vec(&doc).unwrap();
    }
    let mut raw = RawMesh::default();
    raw.attrs.gltf = Some(GltfExtras {
        json: doc,
        buffers: vec![bin].into(),
        glb_bin: Some(0),
        mesh: 0,
        prims: Vec::new(),
        corners: Vec::new(),
        out_faces: Vec::new(),
        out_prim: Vec::new(),
    });
    // every face kept: writes the document back as it is
    let mut out = Vec::new();
    write(&mut out, &raw, true).unwrap();
    out
}

fn read_mem(bytes: &[u8], format: Format) -> Result<RawMesh, IoError> {
    read_bytes(Path::new("mem.glb"), bytes, format, &ReadLimits::default())
}

#[test]
fn a_glb_square_reads_with_its_corner_values() {
    let raw = read_mem(&square(true), Format::Glb).unwrap();
    assert_eq!(raw.positions.len(), 4);
    assert_eq!(raw.faces, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(raw.precision, Precision::F32);
    let uv = raw.attrs.uv.as_ref().unwrap();
    assert_eq!(uv.at(1, 2), Some(&[0.0, 1.0]));
    let n = raw.attrs.normals.as_ref().unwrap();
    assert_eq!(n.at(0, 0), Some(&[0.0, 0.0, 1.0]));
    let g = raw.attrs.gltf.as_ref().unwrap();
    assert_eq!(g.prims.len(), 1);
    assert_eq!(g.prims[0].material, Some(0));
    // the JSON form with a data URI reads the same
    let j = read_mem(&square(false), Format::Gltf).unwrap();
    assert_eq!(j.positions, raw.positions);
    assert_eq!(j.faces, raw.faces);
}

#[test]
fn hostile_documents_are_errors_not_panics() {
    let good = square(true);
    // declared length past the end, below the header, truncated chunks
    for cut in [0usize, 5, 11, 12, 19, 20, 40, good.len() - 1] {
        let _ = read_mem(&good[..cut], Format::Glb);
    }
    let mut long = good.clone();
    long[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(read_mem(&long, Format::Glb).is_err());
    let mut short = good.clone();
    short[8..12].copy_from_slice(&3u32.to_le_bytes());
    assert!(read_mem(&short, Format::Glb).is_err());
    // an accessor past its view, a view past its buffer
    let mut doc: Value = serde_json::from_slice(&square(false)).unwrap();
    doc["accessors"][0]["count"] = json!(1000);
    let e = read_mem(&serde_json::to_vec(&doc).unwrap(), Format::Gltf).unwrap_err();
    assert!(e.to_string().contains("mem.glb"), "{e}");
    let mut doc: Value = serde_json::from_slice(&square(false)).unwrap();
    doc["bufferViews"][3]["byteLength"] = json!(100000);
    assert!(read_mem(&serde_json::to_vec(&doc).unwrap(), Format::Gltf).is_err());
    // external buffers outside the folder are never read
    for uri in ["/etc/passwd", "../secret.bin", "http://example.com/a.bin"] {
        let mut doc: Value = serde_json::from_slice(&square(false)).unwrap();
        doc["buffers"][0]["uri"] = json!(uri);
        let e = read_mem(&serde_json::to_vec(&doc).unwrap(), Format::Gltf).unwrap_err();
        assert!(e.to_string().contains("relative"), "{uri}: {e}");
    }
    // two meshes with triangles in different frames; a node its own ancestor
    let mut doc: Value = serde_json::from_slice(&square(false)).unwrap();
    let m = doc["meshes"][0].clone();
    doc["meshes"] = json!([m.clone(), m]);
    doc["nodes"] = json!([{"mesh": 0}, {"mesh": 1, "translation": [1, 0, 0]}]);
    let e = read_mem(&serde_json::to_vec(&doc).unwrap(), Format::Gltf).unwrap_err();
    assert!(e.to_string().contains("different frames"), "{e}");
    doc["nodes"] = json!([{"mesh": 0, "children": [1]}, {"mesh": 1, "children": [0]}]);
    assert!(read_mem(&serde_json::to_vec(&doc).unwrap(), Format::Gltf).is_err());
}

#[test]
fn external_buffers_are_read_from_the_files_given_or_beside() {
    let d = tempfile::tempdir().unwrap();
    let mut doc: Value = serde_json::from_slice(&square(false)).unwrap();
    let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_string();
    let bin = base64::engine::general_purpose::STANDARD
        .decode(uri.split_once(";base64,").unwrap().1)
        .unwrap();
    doc["buffers"][0]["uri"] = json!("./sq%20a.bin");
    let gltf = d.path().join("sq.gltf");
    std::fs::write(&gltf, serde_json::to_vec(&doc).unwrap()).unwrap();
    let read =
        |res: &Resources| crate::io::read_with_resources(&gltf, None, &ReadLimits::default(), res);
    // beside the file, by the decoded name
    std::fs::write(d.path().join("sq a.bin"), &bin).unwrap();
    let beside = read(&Resources::default()).unwrap();
    assert_eq!(beside.faces.len(), 2);
    // only the files given: the one beside is not read
    let e = read(&Resources {
        files: Vec::new(),
        only: true,
    })
    .unwrap_err();
    assert!(e.to_string().contains("not among the files given"), "{e}");
    std::fs::rename(d.path().join("sq a.bin"), d.path().join("claimed.m0")).unwrap();
    let given = read(&Resources {
        files: vec![("sq a.bin".into(), d.path().join("claimed.m0"))],
        only: true,
    })
    .unwrap();
    assert_eq!(given.positions, beside.positions);
    // `..` and absolute names are refused before any lookup
    let mut doc2 = doc.clone();
    doc2["buffers"][0]["uri"] = json!("../claimed.m0");
    std::fs::write(&gltf, serde_json::to_vec(&doc2).unwrap()).unwrap();
    let e = read(&Resources {
        files: vec![("claimed.m0".into(), d.path().join("claimed.m0"))],
        only: false,
    })
    .unwrap_err();
    assert!(e.to_string().contains("relative"), "{e}");
}

#[test]
fn meshes_sharing_one_frame_read_as_one_and_write_back_unchanged() {
    let mut doc: Value = serde_json::from_slice(&square(false)).unwrap();
    let m = doc["meshes"][0].clone();
    doc["meshes"] = json!([m.clone(), m]);
    // the same frame: one node with no transform, one with an identity matrix
    doc["nodes"] =
        json!([{"mesh": 0}, {"mesh": 1, "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]}]);
    doc["scenes"] = json!([{"nodes": [0, 1]}]);
    let bytes = serde_json::to_vec(&doc).unwrap();
    let raw = read_mem(&bytes, Format::Gltf).unwrap();
    assert_eq!(raw.positions.len(), 4, "welded across the meshes");
    assert_eq!(raw.faces.len(), 4);
    let g = raw.attrs.gltf.as_ref().unwrap();
    assert_eq!(g.prims.iter().map(|p| p.mesh).collect::<Vec<_>>(), [0, 1]);
    assert!(raw
        .attrs
        .names(&raw)
        .iter()
        .any(|n| n.contains("mesh 0, 1,")));
    // written as read: the document unchanged
    let mut out = Vec::new();
    write(&mut out, &raw, false).unwrap();
    let back: Value = serde_json::from_slice(&out).unwrap();
    assert_eq!(back, doc);
    // a mesh whose every face went (debris) goes, and so does its node's reference
    let mut cut = raw.clone();
    cut.faces.truncate(2);
    let g = cut.attrs.gltf.as_mut().unwrap();
    g.out_faces = vec![Some(0), Some(1)];
    g.out_prim = vec![0, 0];
    let mut out = Vec::new();
    write(&mut out, &cut, false).unwrap();
    let back: Value = serde_json::from_slice(&out).unwrap();
    assert_eq!(back["meshes"].as_array().unwrap().len(), 1, "{back}");
    assert_eq!(
        back["nodes"],
        json!([{"mesh": 0}, {"matrix": doc["nodes"][1]["matrix"]}])
    );
    assert_eq!(read_mem(&out, Format::Gltf).unwrap().faces.len(), 2);
    // world transforms: a parent's translation counts; equal products are one frame
    doc["nodes"] = json!([
        {"translation": [1, 0, 0], "children": [1]},
        {"mesh": 0},
        {"mesh": 1, "translation": [1, 0, 0]}
    ]);
    doc["scenes"] = json!([{"nodes": [0, 2]}]);
    assert!(read_mem(&serde_json::to_vec(&doc).unwrap(), Format::Gltf).is_ok());
    doc["nodes"][0]["translation"] = json!([2, 0, 0]);
    let e = read_mem(&serde_json::to_vec(&doc).unwrap(), Format::Gltf).unwrap_err();
    assert!(e.to_string().contains("node 1 and node 2"), "{e}");
}

#[test]
fn percent_escapes_in_names_are_decoded() {
    assert_eq!(percent_decode("my%20scan.bin"), "my scan.bin");
    assert_eq!(percent_decode("100%"), "100%");
    assert_eq!(percent_decode("a%2"), "a%2");
}
