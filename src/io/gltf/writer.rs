//! Writing glTF: a document read from glTF written back with its patches as new
//! primitives in a new stretch of buffer, or a new one-primitive document.

use super::{ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER, FLOAT, TRIANGLES, UNSIGNED_INT};
use crate::io::attrs::{GltfExtras, GltfPrim};
use crate::io::RawMesh;
use base64::Engine as _;
use glam::DVec3;
use serde_json::{json, Value};
use std::collections::HashMap;
use std::io::{self, Write};

/// The new stretch of buffer being written: views and accessors appended to `doc`.
struct Stretch {
    blob: Vec<u8>,
    /// Per new view: (index in `bufferViews`, offset in `blob`).
    views: Vec<(usize, usize)>,
}

impl Stretch {
    /// Appends the bytes as a new buffer view and an accessor over it; the accessor's
    /// index.
    #[allow(clippy::too_many_arguments)]
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
pub(crate) fn write<W: Write>(w: &mut W, raw: &RawMesh, glb: bool) -> io::Result<()> {
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
