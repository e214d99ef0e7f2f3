//! glTF 2.0: `.gltf` (JSON with its buffers) and `.glb` (binary), parsed and validated
//! by the `gltf` crate.
//!
//! Reading takes the triangle primitives of every mesh with triangles as one mesh
//! (points, lines, strips and fans are kept as they are, not repaired). Several such
//! meshes are read only when they share one frame: every node that places one of them
//! has the same world transform (equal matrices), so that their vertices are in the same
//! coordinates; otherwise the document is refused with that reason (moving input
//! vertices into a common frame would change them). glTF vertices belong to one primitive and
//! are split at UV and normal seams, so the reader welds the vertices whose positions
//! are bit-identical into one mesh vertex (in order of first appearance): seams and
//! primitive borders are not holes. Each glTF vertex's normal and texture coordinate
//! become corner values; its colour the vertex colour (the first glTF vertex of a
//! welded vertex gives it).
//!
//! Writing a mesh read from glTF keeps the document: buffers, images, materials,
//! nodes, extensions and primitives are written back byte for byte. The patches become
//! one new primitive per primitive whose faces surround them (same material), with
//! their own accessors in a new stretch of buffer; rim vertices are repeated there
//! with their input values (glTF primitives share no vertices). A primitive that lost
//! input faces (rim trimming, debris) gets a new index accessor. Attributes the new
//! primitive cannot be given (tangents, a second UV set, skinning) are left out of it.
//! Other inputs are written as a new document: one mesh with one primitive, `f32`
//! positions, and normals, texture coordinates and colours when the mesh has them.
//!
//! External buffers of a `.gltf` are read from names relative to the file, never from
//! an absolute path, a `..` component or a URL; `data:` URIs are decoded. A `.gltf`
//! written keeps the external names it read (those files travel beside it) and holds
//! the new stretch as a `data:` URI; a `.glb` holds it in its binary chunk.

use super::attrs::{percent_decode, Corners, GltfExtras, GltfPrim};
use super::{malformed, Caps, Encoding, IoError, Precision, RawMesh, Resources};
use base64::Engine as _;
use glam::DVec3;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::io::{self, Write};
use std::path::{Component, Path};

const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const TRIANGLES: u32 = 4;

/// Reads a `.gltf` or `.glb` held in `bytes` (`path` names it in errors and locates
/// its external buffers).
pub(super) fn read(
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

/// The new stretch of buffer being written: views and accessors appended to `doc`.
struct Stretch {
    blob: Vec<u8>,
    /// Per new view: (index in `bufferViews`, offset in `blob`).
    views: Vec<(usize, usize)>,
}

impl Stretch {
    /// Appends the bytes as a new buffer view and an accessor over it; the accessor's
    /// index.
    fn accessor(
        &mut self,
        doc: &mut Value,
        bytes: &[u8],
        count: usize,
        component: u32,
        ty: &str,
        target: u32,
        minmax: Option<([f32; 3], [f32; 3])>,
    ) -> usize {
        while self.blob.len() % 4 != 0 {
            self.blob.push(0);
        }
        let off = self.blob.len();
        self.blob.extend_from_slice(bytes);
        let views = array(doc, "bufferViews");
        let vi = views.len();
        views.push(
            json!({"buffer": 0, "byteOffset": 0, "byteLength": bytes.len(), "target": target}),
        );
        self.views.push((vi, off));
        let accs = array(doc, "accessors");
        let ai = accs.len();
        let mut a =
            json!({"bufferView": vi, "componentType": component, "count": count, "type": ty});
        if let Some((lo, hi)) = minmax {
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        accs.push(a);
        ai
    }
}

/// `doc[key]` as an array (made when absent).
fn array<'a>(doc: &'a mut Value, key: &str) -> &'a mut Vec<Value> {
    if !doc.get(key).is_some_and(Value::is_array) {
        doc[key] = json!([]);
    }
    match doc.get_mut(key) {
        Some(Value::Array(a)) => a,
        _ => unreachable!("made an array above"),
    }
}

/// Writes `raw` as glTF (`glb`: binary) to `w`.
pub(super) fn write<W: Write>(w: &mut W, raw: &RawMesh, glb: bool) -> io::Result<()> {
    // a mesh written as it was read (no repair in between) keeps every triangle
    let read = raw.attrs.gltf.as_ref();
    let identity: Option<(Vec<Option<u32>>, Vec<u32>)> = read.and_then(|g| {
        (g.out_faces.is_empty() && g.corners.len() == raw.faces.len()).then(|| {
            (
                (0..raw.faces.len() as u32).map(Some).collect(),
                (0..raw.faces.len())
                    .map(|j| g.prim_of(j).unwrap_or(0))
                    .collect(),
            )
        })
    });
    let (out_faces, out_prim): (&[Option<u32>], &[u32]) = match (&identity, read) {
        (Some((f, p)), _) => (f, p),
        (None, Some(g)) => (&g.out_faces, &g.out_prim),
        (None, None) => (&[], &[]),
    };
    // the buffers as read are borrowed, never copied
    type Read<'a> = (
        Value,
        &'a [Vec<u8>],
        Option<usize>,
        usize,
        &'a [GltfPrim],
        Option<(&'a GltfExtras, Vec<bool>)>,
    );
    let (mut doc, read_buffers, glb_bin, mesh_index, prims, kept_faces): Read<'_> = match read {
        Some(g) if out_faces.len() == raw.faces.len() => {
            let mut kept = vec![false; g.corners.len()];
            for &j in out_faces.iter().flatten() {
                if let Some(k) = kept.get_mut(j as usize) {
                    *k = true;
                }
            }
            (
                g.json.clone(),
                &g.buffers,
                g.glb_bin,
                g.mesh,
                &g.prims,
                Some((g, kept)),
            )
        }
        _ => (
            json!({
                "asset": {"version": "2.0", "generator": concat!("holefill ", env!("CARGO_PKG_VERSION"))},
                "scene": 0,
                "scenes": [{"nodes": [0]}],
                "nodes": [{"mesh": 0}],
                "meshes": [{"primitives": []}],
            }),
            &[],
            None,
            0,
            &[],
            None,
        ),
    };
    let mut st = Stretch {
        blob: Vec::new(),
        views: Vec::new(),
    };
    let mut new_prims: Vec<(usize, Value)> = Vec::new();
    let mut emptied: Vec<(usize, usize)> = Vec::new();
    // primitives that lost input faces: a new index accessor
    if let Some((g, kept)) = &kept_faces {
        for p in prims {
            let range = p.first_face..p.first_face + p.faces;
            if range.clone().all(|j| kept[j]) {
                continue;
            }
            let idx: Vec<u32> = range
                .filter(|&j| kept[j])
                .flat_map(|j| g.corners[j])
                .collect();
            if idx.is_empty() {
                emptied.push((p.mesh, p.index));
                continue;
            }
            let bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
            let a = st.accessor(
                &mut doc,
                &bytes,
                idx.len(),
                UNSIGNED_INT,
                "SCALAR",
                ELEMENT_ARRAY_BUFFER,
                None,
            );
            doc["meshes"][p.mesh]["primitives"][p.index]["indices"] = json!(a);
        }
    }
    // the new faces (every face of a mesh not read from glTF), by target primitive
    let mut groups: Vec<(Option<usize>, Vec<usize>)> = Vec::new();
    for f in 0..raw.faces.len() {
        let target = match &kept_faces {
            Some(_) => {
                if out_faces.get(f).copied().flatten().is_some() {
                    continue;
                }
                out_prim
                    .get(f)
                    .map(|&s| s as usize)
                    .filter(|&s| s < prims.len())
            }
            None => None,
        };
        match groups.iter_mut().find(|(t, _)| *t == target) {
            Some((_, fs)) => fs.push(f),
            None => groups.push((target, vec![f])),
        }
    }
    for (target, faces) in &groups {
        let tp = target.and_then(|s| prims.get(s));
        let want_normal = raw.attrs.normals.is_some() && tp.is_none_or(|p| p.has_normal);
        let want_uv = raw.attrs.uv.is_some() && tp.is_none_or(|p| p.has_uv);
        let want_color = raw.colors.is_some() && tp.is_none_or(|p| p.has_color);
        let mut map: HashMap<(u32, Option<u32>, Option<u32>), u32> = HashMap::new();
        let (mut pos, mut nor, mut uv, mut col) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut idx: Vec<u32> = Vec::with_capacity(faces.len() * 3);
        for &f in faces {
            let fv = raw.faces[f];
            let fnormal = {
                let p = fv.map(|i| raw.positions[i as usize]);
                (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero()
            };
            for k in 0..3 {
                let v = fv[k];
                let ui = want_uv
                    .then(|| {
                        raw.attrs
                            .uv
                            .as_ref()?
                            .index
                            .get(f)
                            .copied()
                            .flatten()
                            .map(|c| c[k])
                    })
                    .flatten();
                let ni = want_normal
                    .then(|| {
                        raw.attrs
                            .normals
                            .as_ref()?
                            .index
                            .get(f)
                            .copied()
                            .flatten()
                            .map(|c| c[k])
                    })
                    .flatten();
                let next = pos.len() as u32;
                let i = *map.entry((v, ui, ni)).or_insert(next);
                if i == next {
                    let p = raw.positions[v as usize];
                    pos.push([p.x as f32, p.y as f32, p.z as f32]);
                    if want_normal {
                        let n = ni
                            .and_then(|i| {
                                raw.attrs.normals.as_ref()?.values.get(i as usize).copied()
                            })
                            .map(|n| DVec3::from(n).normalize_or_zero())
                            .filter(|n| *n != DVec3::ZERO)
                            .unwrap_or(fnormal);
                        nor.push([n.x as f32, n.y as f32, n.z as f32]);
                    }
                    if want_uv {
                        let t = ui
                            .and_then(|i| raw.attrs.uv.as_ref()?.values.get(i as usize).copied())
                            .unwrap_or([0.0; 2]);
                        uv.push([t[0] as f32, t[1] as f32]);
                    }
                    if want_color {
                        let c = raw
                            .colors
                            .as_ref()
                            .and_then(|c| c.get(v as usize).copied())
                            .unwrap_or([1.0; 3]);
                        col.push([c[0], c[1], c[2], 1.0]);
                    }
                }
                idx.push(i);
            }
        }
        let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &pos {
            for d in 0..3 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let mut attributes = serde_json::Map::new();
        let a = st.accessor(
            &mut doc,
            &f32s(&flat(&pos)),
            pos.len(),
            FLOAT,
            "VEC3",
            ARRAY_BUFFER,
            Some((lo, hi)),
        );
        attributes.insert("POSITION".into(), json!(a));
        if want_normal {
            let a = st.accessor(
                &mut doc,
                &f32s(&flat(&nor)),
                nor.len(),
                FLOAT,
                "VEC3",
                ARRAY_BUFFER,
                None,
            );
            attributes.insert("NORMAL".into(), json!(a));
        }
        if want_uv {
            let v: Vec<f32> = uv.iter().flatten().copied().collect();
            let a = st.accessor(
                &mut doc,
                &f32s(&v),
                uv.len(),
                FLOAT,
                "VEC2",
                ARRAY_BUFFER,
                None,
            );
            attributes.insert("TEXCOORD_0".into(), json!(a));
        }
        if want_color {
            let v: Vec<f32> = col.iter().flatten().copied().collect();
            let a = st.accessor(
                &mut doc,
                &f32s(&v),
                col.len(),
                FLOAT,
                "VEC4",
                ARRAY_BUFFER,
                None,
            );
            attributes.insert("COLOR_0".into(), json!(a));
        }
        let bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
        let ia = st.accessor(
            &mut doc,
            &bytes,
            idx.len(),
            UNSIGNED_INT,
            "SCALAR",
            ELEMENT_ARRAY_BUFFER,
            None,
        );
        let mut prim = json!({"attributes": attributes, "indices": ia, "mode": TRIANGLES});
        if let Some(m) = tp.and_then(|p| p.material) {
            prim["material"] = json!(m);
        }
        new_prims.push((tp.map_or(mesh_index, |p| p.mesh), prim));
    }
    // each mesh that lost a primitive or gains one
    let mut touched: Vec<usize> = vec![mesh_index];
    for m in emptied
        .iter()
        .map(|e| e.0)
        .chain(new_prims.iter().map(|p| p.0))
    {
        if !touched.contains(&m) {
            touched.push(m);
        }
    }
    let mut gone: Vec<usize> = Vec::new();
    for m in touched {
        let mine: Vec<Value> = new_prims
            .iter()
            .filter(|p| p.0 == m)
            .map(|p| p.1.clone())
            .collect();
        let list = &mut doc["meshes"][m]["primitives"];
        if let Value::Array(ps) = list {
            // primitives left with no face go (their accessors stay, unused)
            let mut i = 0;
            ps.retain(|_| {
                let keep = !emptied.contains(&(m, i));
                i += 1;
                keep
            });
            ps.extend(mine);
            if ps.is_empty() {
                gone.push(m);
            }
        } else {
            *list = Value::Array(mine);
        }
    }
    drop_meshes(&mut doc, gone);
    // where the new stretch lives; each buffer's bytes: as read (borrowed), zero
    // padding, and the new stretch (appended to a GLB's binary chunk)
    let blob = std::mem::take(&mut st.blob);
    let mut parts: Vec<Part<'_>> = read_buffers
        .iter()
        .map(|b| Part {
            read: b,
            pad: 0,
            new: &[],
        })
        .collect();
    let new_buffer: Option<usize> = if blob.is_empty() {
        None
    } else if glb {
        match glb_bin {
            Some(b) => {
                let part = parts
                    .get_mut(b)
                    .ok_or_else(|| io::Error::other("the GLB binary chunk names no buffer"))?;
                let base = part.read.len().next_multiple_of(4);
                part.pad = base - part.read.len();
                part.new = &blob;
                for (_, off) in st.views.iter_mut() {
                    *off += base;
                }
                Some(b)
            }
            None => {
                // a new first buffer (only the first may be the binary chunk)
                for v in array(&mut doc, "bufferViews").iter_mut() {
                    if let Some(b) = v.get("buffer").and_then(Value::as_u64) {
                        v["buffer"] = json!(b + 1);
                    }
                }
                array(&mut doc, "buffers").insert(0, json!({"byteLength": 0}));
                parts.insert(
                    0,
                    Part {
                        read: &blob,
                        pad: 0,
                        new: &[],
                    },
                );
                Some(0)
            }
        }
    } else {
        array(&mut doc, "buffers").push(json!({"byteLength": 0}));
        parts.push(Part {
            read: &blob,
            pad: 0,
            new: &[],
        });
        Some(parts.len() - 1)
    };
    if let Some(nb) = new_buffer {
        let views = array(&mut doc, "bufferViews");
        for &(vi, off) in &st.views {
            views[vi]["buffer"] = json!(nb);
            views[vi]["byteOffset"] = json!(off);
        }
    }
    // buffer lengths and where each is stored
    let glb_buffer = if glb {
        new_buffer.filter(|_| glb_bin.is_none()).or(glb_bin)
    } else {
        None
    };
    let mut bin: Option<Part<'_>> = None;
    let bufs = array(&mut doc, "buffers");
    for (i, b) in bufs.iter_mut().enumerate() {
        let Some(&data) = parts.get(i) else { continue };
        let from_file = b
            .get("uri")
            .and_then(Value::as_str)
            .is_some_and(|u| !u.starts_with("data:"));
        // a buffer that grew (or is new) says so; the others keep their length
        if Some(i) == new_buffer {
            b["byteLength"] = json!(data.len());
        }
        if Some(i) == glb_buffer {
            if let Some(o) = b.as_object_mut() {
                o.remove("uri");
            }
            bin = Some(data);
        } else if !from_file {
            // the binary chunk of a .glb written as .gltf, and every new stretch
            let engine = &base64::engine::general_purpose::STANDARD;
            let text = if data.pad == 0 && data.new.is_empty() {
                engine.encode(data.read)
            } else {
                engine.encode(data.to_vec())
            };
            b["uri"] = json!(format!("data:application/octet-stream;base64,{text}"));
        }
    }
    let text = serde_json::to_vec(&doc).map_err(io::Error::other)?;
    if !glb {
        return w.write_all(&text);
    }
    let mut jchunk = text;
    while jchunk.len() % 4 != 0 {
        jchunk.push(b' ');
    }
    let bin = bin.unwrap_or(Part {
        read: &[],
        pad: 0,
        new: &[],
    });
    let blen = bin.len().next_multiple_of(4);
    let total = 12 + 8 + jchunk.len() + if blen == 0 { 0 } else { 8 + blen };
    let total =
        u32::try_from(total).map_err(|_| io::Error::other("a GLB file holds at most 4 GiB"))?;
    w.write_all(b"glTF")?;
    w.write_all(&2u32.to_le_bytes())?;
    w.write_all(&total.to_le_bytes())?;
    w.write_all(&(jchunk.len() as u32).to_le_bytes())?;
    w.write_all(b"JSON")?;
    w.write_all(&jchunk)?;
    if blen != 0 {
        w.write_all(&(blen as u32).to_le_bytes())?;
        w.write_all(b"BIN\0")?;
        bin.write(w)?;
        w.write_all(&[0u8; 3][..blen - bin.len()])?;
    }
    Ok(())
}

/// Removes the meshes `gone` (left with no primitive: glTF requires one) from the
/// document: the nodes that placed them lose their `mesh`, later meshes' indices move
/// down.
fn drop_meshes(doc: &mut Value, mut gone: Vec<usize>) {
    if gone.is_empty() {
        return;
    }
    gone.sort_unstable();
    gone.dedup();
    let meshes = array(doc, "meshes");
    for &m in gone.iter().rev() {
        if m < meshes.len() {
            meshes.remove(m);
        }
    }
    for node in array(doc, "nodes").iter_mut() {
        let Some(k) = node.get("mesh").and_then(Value::as_u64) else {
            continue;
        };
        let k = k as usize;
        if gone.contains(&k) {
            if let Some(o) = node.as_object_mut() {
                o.remove("mesh");
            }
        } else {
            node["mesh"] = json!(k - gone.iter().filter(|&&g| g < k).count());
        }
    }
}

/// A buffer's bytes as written: the bytes read (borrowed), zero padding, the new
/// stretch.
#[derive(Clone, Copy)]
struct Part<'a> {
    read: &'a [u8],
    pad: usize,
    new: &'a [u8],
}

impl Part<'_> {
    fn len(&self) -> usize {
        self.read.len() + self.pad + self.new.len()
    }
    fn write<W: Write>(&self, w: &mut W) -> io::Result<()> {
        w.write_all(self.read)?;
        w.write_all(&vec![0u8; self.pad])?;
        w.write_all(self.new)
    }
    fn to_vec(self) -> Vec<u8> {
        let mut v = Vec::with_capacity(self.len());
        v.extend_from_slice(self.read);
        v.resize(self.read.len() + self.pad, 0);
        v.extend_from_slice(self.new);
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{read_bytes, Format, ReadLimits};

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
        let read = |res: &Resources| {
            crate::io::read_with_resources(&gltf, None, &ReadLimits::default(), res)
        };
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
}
