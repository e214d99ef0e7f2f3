//! Reading a `.gltf` or `.glb`: the triangle primitives of the meshes that share one
//! frame, validated, their vertices welded; external buffers only from safe names.

use crate::io::attrs::{percent_decode, Corners, GltfExtras, GltfPrim};
use crate::io::{malformed, Caps, Encoding, IoError, Precision, RawMesh, Resources};
use base64::Engine as _;
use glam::DVec3;
use serde_json::Value;
use std::collections::HashMap;
use std::path::{Component, Path};

/// Reads a `.gltf` or `.glb` held in `bytes` (`path` names it in errors and locates
/// its external buffers).
pub(crate) fn read(
    path: &Path,
    bytes: &[u8],
    caps: &Caps,
    resources: &Resources,
) -> Result<RawMesh, IoError> {
    let bad = |m: String| malformed(path, None, m);
    let is_glb = bytes.starts_with(b"glTF");
    if is_glb {
        // the crate subtracts the header size from the declared length unchecked
        let declared = bytes
            .get(8..12)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
            .ok_or_else(|| bad("truncated GLB header".into()))?;
        if declared < 12 || declared > bytes.len() {
            return Err(bad(format!(
                "GLB header declares {declared} bytes, the file has {}",
                bytes.len()
            )));
        }
    }
    let parsed = std::panic::catch_unwind(|| ::gltf::Gltf::from_slice(bytes))
        .map_err(|_| bad("the glTF document could not be parsed".into()))?;
    let mut doc = parsed.map_err(|e| bad(format!("not a valid glTF 2.0 document: {e}")))?;
    // the JSON as written, kept for the writer
    let json: Value = if is_glb {
        let glb = ::gltf::binary::Glb::from_slice(bytes).map_err(|e| bad(format!("GLB: {e}")))?;
        serde_json::from_slice(&glb.json).map_err(|e| bad(format!("GLB JSON chunk: {e}")))?
    } else {
        serde_json::from_slice(bytes).map_err(|e| bad(format!("JSON: {e}")))?
    };
    // every buffer's bytes
    let mut buffers: Vec<Vec<u8>> = Vec::new();
    let mut glb_bin: Option<usize> = None;
    let mut blob = doc.blob.take();
    for b in doc.buffers() {
        let data = match b.source() {
            ::gltf::buffer::Source::Bin => {
                // the chunk moved into its buffer (a second buffer naming it: a copy)
                let chunk = match glb_bin.and_then(|k| buffers.get(k)) {
                    Some(first) => Some(first.clone()),
                    None => blob.take(),
                };
                glb_bin = glb_bin.or(Some(b.index()));
                chunk.ok_or_else(|| {
                    bad(format!(
                        "buffer {} names a GLB binary chunk the file does not have",
                        b.index()
                    ))
                })?
            }
            ::gltf::buffer::Source::Uri(uri) => load_uri(path, uri, resources)
                .map_err(|m| bad(format!("buffer {}: {m}", b.index())))?,
        };
        if data.len() < b.length() {
            return Err(bad(format!(
                "buffer {} holds {} bytes, the document says {}",
                b.index(),
                data.len(),
                b.length()
            )));
        }
        buffers.push(data);
    }
    // the meshes with triangles, in one frame
    let meshes: Vec<_> = doc
        .meshes()
        .filter(|m| {
            m.primitives()
                .any(|p| p.mode() == ::gltf::mesh::Mode::Triangles)
        })
        .collect();
    let Some(first_mesh) = meshes.first().map(|m| m.index()) else {
        return Err(bad("the document has no mesh with triangles".into()));
    };
    if meshes.len() > 1 {
        let ids: Vec<usize> = meshes.iter().map(|m| m.index()).collect();
        one_frame(&doc, &ids).map_err(bad)?;
    }
    let several = meshes.len() > 1;
    let mut raw = RawMesh {
        precision: Precision::F32,
        encoding: Encoding::BinaryLittleEndian,
        ..Default::default()
    };
    let mut prims: Vec<GltfPrim> = Vec::new();
    let mut corners: Vec<[u32; 3]> = Vec::new();
    let mut uv_values: Vec<[f64; 2]> = Vec::new();
    let mut uv_index: Vec<Option<[u32; 3]>> = Vec::new();
    let mut n_values: Vec<[f64; 3]> = Vec::new();
    let mut n_index: Vec<Option<[u32; 3]>> = Vec::new();
    let mut colors: Vec<Option<[f32; 3]>> = Vec::new();
    let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
    let (mut any_uv, mut any_normal, mut any_color) = (false, false, false);
    let mut glvert = 0usize; // glTF vertices read so far (uv/normal value index)
    let all = meshes
        .iter()
        .flat_map(|m| m.primitives().map(move |p| (m.index(), p)));
    for (mesh, p) in all {
        let of_mesh = if several {
            format!(" of mesh {mesh}")
        } else {
            String::new()
        };
        if p.mode() != ::gltf::mesh::Mode::Triangles {
            raw.notes.push(format!(
                "glTF primitive {}{of_mesh} ({:?}) kept as it is, not repaired",
                p.index(),
                p.mode()
            ));
            continue;
        }
        for a in p.attributes().map(|(_, a)| a).chain(p.indices()) {
            check_accessor(&a, &buffers)
                .map_err(|m| bad(format!("primitive {}{of_mesh}: {m}", p.index())))?;
        }
        let reader = p.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let pos: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or_else(|| bad(format!("primitive {} has no POSITION", p.index())))?
            .collect();
        let n = pos.len();
        if (glvert + n) as u64 > caps.vertices() {
            return Err(bad(caps.vertex_msg(Some((glvert + n) as u64))));
        }
        let idx: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..n as u32).collect(),
        };
        if idx.len() % 3 != 0 {
            return Err(bad(format!(
                "primitive {}: {} indices, not a multiple of 3",
                p.index(),
                idx.len()
            )));
        }
        if let Some(&i) = idx.iter().find(|&&i| i as usize >= n) {
            return Err(bad(format!(
                "primitive {}: index {i} out of range ({n} vertices)",
                p.index()
            )));
        }
        if (corners.len() + idx.len() / 3) as u64 > caps.faces() {
            return Err(bad(
                caps.face_msg(Some((corners.len() + idx.len() / 3) as u64))
            ));
        }
        let normals: Option<Vec<[f32; 3]>> = reader.read_normals().map(Iterator::collect);
        let uvs: Option<Vec<[f32; 2]>> = reader.read_tex_coords(0).map(|t| t.into_f32().collect());
        let cols: Option<Vec<[f32; 4]>> =
            reader.read_colors(0).map(|c| c.into_rgba_f32().collect());
        for (what, len) in [
            ("NORMAL", normals.as_ref().map(Vec::len)),
            ("TEXCOORD_0", uvs.as_ref().map(Vec::len)),
            ("COLOR_0", cols.as_ref().map(Vec::len)),
        ] {
            if len.is_some_and(|l| l != n) {
                return Err(bad(format!(
                    "primitive {}: {what} has {} values for {n} vertices",
                    p.index(),
                    len.unwrap_or(0)
                )));
            }
        }
        any_uv |= uvs.is_some();
        any_normal |= normals.is_some();
        any_color |= cols.is_some();
        // welded positions, in order of first appearance
        let mut local: Vec<u32> = Vec::with_capacity(n);
        for (k, q) in pos.iter().enumerate() {
            let key = q.map(f32::to_bits);
            let next = raw.positions.len() as u32;
            let v = *weld.entry(key).or_insert(next);
            if v == next {
                raw.positions.push(DVec3::new(
                    f64::from(q[0]),
                    f64::from(q[1]),
                    f64::from(q[2]),
                ));
                colors.push(None);
            }
            if colors[v as usize].is_none() {
                colors[v as usize] = cols
                    .as_ref()
                    .and_then(|c| c.get(k))
                    .map(|c| [c[0], c[1], c[2]]);
            }
            local.push(v);
        }
        let first_face = corners.len();
        for t in idx.chunks_exact(3) {
            let c = [t[0], t[1], t[2]];
            raw.faces.push(c.map(|i| local[i as usize]));
            corners.push(c);
            let g = c.map(|i| (glvert + i as usize) as u32);
            uv_index.push(uvs.as_ref().map(|_| g));
            n_index.push(normals.as_ref().map(|_| g));
        }
        // value tables indexed by glTF vertex (zeros where a primitive has none)
        match &uvs {
            Some(u) => uv_values.extend(u.iter().map(|t| [f64::from(t[0]), f64::from(t[1])])),
            None => uv_values.extend(std::iter::repeat_n([0.0; 2], n)),
        }
        match &normals {
            Some(v) => n_values.extend(v.iter().map(|t| t.map(f64::from))),
            None => n_values.extend(std::iter::repeat_n([0.0; 3], n)),
        }
        prims.push(GltfPrim {
            mesh,
            index: p.index(),
            first_face,
            faces: corners.len() - first_face,
            first_vertex: glvert,
            vertices: n,
            material: p.material().index(),
            has_normal: normals.is_some(),
            has_uv: uvs.is_some(),
            has_color: cols.is_some(),
        });
        glvert += n;
    }
    if any_uv {
        raw.attrs.uv = Some(Corners {
            values: uv_values,
            index: uv_index,
        });
    }
    if any_normal {
        raw.attrs.normals = Some(Corners {
            values: n_values,
            index: n_index,
        });
    }
    if any_color {
        raw.colors = Some(colors.iter().map(|c| c.unwrap_or([1.0; 3])).collect());
    }
    if glvert > raw.positions.len() {
        raw.notes.push(format!(
            "{glvert} glTF vertices welded into {} by position (seams and primitive borders)",
            raw.positions.len()
        ));
    }
    raw.attrs.gltf = Some(GltfExtras {
        json,
        buffers: buffers.into(),
        glb_bin,
        mesh: first_mesh,
        prims,
        corners,
        out_faces: Vec::new(),
        out_prim: Vec::new(),
    });
    Ok(raw)
}

/// Checks that every node placing one of `meshes` has the same world transform (the
/// product of its ancestors' and its own matrices); a mesh no node places is taken in
/// its own coordinates.
fn one_frame(doc: &::gltf::Document, meshes: &[usize]) -> Result<(), String> {
    type M4 = [[f32; 4]; 4];
    let n = doc.nodes().count();
    let mut parent: Vec<Option<usize>> = vec![None; n];
    for node in doc.nodes() {
        for c in node.children() {
            if let Some(p) = parent.get_mut(c.index()) {
                *p = Some(node.index());
            }
        }
    }
    let local: Vec<M4> = doc.nodes().map(|n| n.transform().matrix()).collect();
    // column-major: m[column][row]
    let mul = |a: &M4, b: &M4| -> M4 {
        let mut out = [[0.0f32; 4]; 4];
        for (c, col) in out.iter_mut().enumerate() {
            for (r, x) in col.iter_mut().enumerate() {
                *x = (0..4).map(|k| a[k][r] * b[c][k]).sum();
            }
        }
        out
    };
    let world = |i: usize| -> Option<M4> {
        let mut m = *local.get(i)?;
        let mut at = i;
        // a parent chain longer than the nodes is a cycle: no frame
        for _ in 0..=n {
            match parent.get(at).copied().flatten() {
                None => return Some(m),
                Some(p) => {
                    m = mul(local.get(p)?, &m);
                    at = p;
                }
            }
        }
        None
    };
    let mut frame: Option<(usize, M4)> = None;
    for node in doc.nodes() {
        let Some(m) = node.mesh().filter(|m| meshes.contains(&m.index())) else {
            continue;
        };
        let w = world(node.index())
            .ok_or_else(|| format!("node {} is its own ancestor", node.index()))?;
        match frame {
            None => frame = Some((node.index(), w)),
            Some((first, f)) if f != w => {
                return Err(format!(
                    "the document has triangles in {} meshes placed in different frames \
                     (node {first} and node {}, mesh {}, have different transforms); \
                     holefill repairs several meshes only when they share one frame",
                    meshes.len(),
                    node.index(),
                    m.index()
                ))
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// Checks that an accessor's bytes lie inside its buffer view and the view inside its
/// buffer (the crate's reader indexes them unchecked).
fn check_accessor(a: &::gltf::Accessor, buffers: &[Vec<u8>]) -> Result<(), String> {
    if a.sparse().is_some() {
        return Err(format!(
            "accessor {}: sparse accessors are not read",
            a.index()
        ));
    }
    let Some(view) = a.view() else {
        return Err(format!("accessor {} has no buffer view", a.index()));
    };
    let blen = buffers.get(view.buffer().index()).map_or(0, Vec::len);
    let vend = view.offset().checked_add(view.length());
    if vend.is_none_or(|e| e > blen) {
        return Err(format!(
            "buffer view {} ({} + {} bytes) outside its buffer of {blen} bytes",
            view.index(),
            view.offset(),
            view.length()
        ));
    }
    let size = a.size();
    let stride = view.stride().unwrap_or(size);
    if a.count() == 0 {
        return Ok(());
    }
    let need = (a.count() - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(size))
        .and_then(|x| x.checked_add(a.offset()));
    if need.is_none_or(|n| n > view.length()) || stride < size {
        return Err(format!(
            "accessor {} ({} values) outside its buffer view of {} bytes",
            a.index(),
            a.count(),
            view.length()
        ));
    }
    Ok(())
}

/// The bytes a buffer URI names: a `data:` URI, or a file beside `path`.
fn load_uri(path: &Path, uri: &str, resources: &Resources) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let (_, payload) = rest
            .split_once(";base64,")
            .ok_or_else(|| "a data URI that is not base64".to_string())?;
        return base64::engine::general_purpose::STANDARD
            .decode(payload)
            .map_err(|e| format!("data URI: {e}"));
    }
    let name = percent_decode(uri);
    let rel = Path::new(&name);
    if uri.contains("://")
        || rel
            .components()
            .any(|c| !matches!(c, Component::Normal(_) | Component::CurDir))
    {
        return Err(format!(
            "{uri:?}: only a name relative to the file (no absolute path, `..` or URL) is read"
        ));
    }
    let full = resources.locate(path, rel)?;
    std::fs::read(&full).map_err(|e| format!("cannot read {}: {e}", full.display()))
}
