//! Attributes through the repair: the post-pass that builds the output soup from the
//! repaired mesh and the input's [`Attrs`].
//!
//! Input elements get their input values back, bit for bit: an output vertex stands
//! for the input vertex [`Mesh::origin`] names (itself, or the vertex a non-manifold
//! split copied); an output face whose three vertices stand for input vertices that
//! form an input face is that face (its corners matched by vertex, so a face the
//! builder reoriented keeps each corner's values). Everything else is new: the
//! vertices and faces of the patches (and of boundary cleaning), grouped into
//! *patches* (the connected sets of new faces). Each patch gets its values from its
//! *rim* (the input vertices on it and the input faces across its border):
//!
//! - colours and real scalars: harmonic over the patch from the rim (cotangent
//!   weights, negative ones clamped to zero, so a planar patch reproduces a linear
//!   field; solved by conjugate gradients);
//! - normals: the patch surface's area-weighted vertex normal; corner normals at rim
//!   vertices keep the rim's normal when the rim has one there;
//! - integer properties that are not colours (labels, ids): the rim's most common
//!   value; face properties, OBJ material/group/object/smoothing and STL attribute
//!   bytes: the most common value of the input faces across the patch's border;
//! - texture coordinates: when every rim vertex has one UV on the rim faces (one
//!   chart along the rim), the patch is mapped harmonically into the rim's UV
//!   polygon, and accepted when the polygon is simple and no UV triangle is flipped
//!   or degenerate (cotangent weights, then uniform ones: Tutte's embedding, which is
//!   a bijection for a convex polygon). Otherwise the fallback gives every corner of
//!   the patch one UV, that of a rim corner (the patch samples one texel: flat, never
//!   flipped), and the log counts it per reason ([`UvCounts`]).

use super::{FaceId, HalfedgeId, Mesh, VertexId};
use crate::io::attrs::{
    AttributesReport, Corners, Meaning, ObjExtras, PropData, Property, ScalarType, StlExtras,
    UvCounts,
};
use crate::io::RawMesh;
use glam::{DVec2, DVec3};
use solve::solve;
use uv::{area, simple};

mod solve;
#[cfg(test)]
mod tests;
mod uv;

/// The output soup of a repaired mesh with every attribute of `input` carried
/// (input elements unchanged, new ones interpolated), and the log's `attributes`
/// section (`dropped` is left to the writer's caller, who knows the format).
pub fn carry(mesh: &Mesh, input: &RawMesh) -> (RawMesh, AttributesReport) {
    let mut out = mesh.to_raw(input);
    let a = &input.attrs;
    let mut rep = AttributesReport {
        read: a.names(input),
        ..Default::default()
    };
    let per_element = !a.vertex.is_empty()
        || !a.face.is_empty()
        || a.uv.is_some()
        || a.normals.is_some()
        || a.obj.is_some()
        || a.gltf.is_some()
        || input.colors.is_some()
        || a.stl.as_ref().is_some_and(|s| !s.attribute.is_empty());
    if !per_element {
        // nothing per element: headers are carried as they are
        out.attrs.stl = a.stl.clone();
        out.attrs.ply = a.ply.clone();
        rep.carried = rep.read.clone();
        return (out, rep);
    }
    rep.carried = rep.read.clone();
    let ctx = Context::new(mesh, input);
    let new_vertices = ctx.src.iter().any(Option::is_none);
    let new_faces = ctx.face_src.iter().any(Option::is_none);

    // vertex values
    if let Some(colors) = &input.colors {
        let fixed = |i: usize| colors.get(i).map(|c| c.map(f64::from));
        let solved = ctx.harmonic::<3>(&fixed, Weights::Cotan);
        out.colors = Some(
            (0..mesh.num_vertices())
                .map(|v| match ctx.src[v] {
                    Some(i) => colors.get(i).copied().unwrap_or([0.0; 3]),
                    None => solved[v].map(|c| c.clamp(0.0, 1.0) as f32),
                })
                .collect(),
        );
        if new_vertices {
            rep.interpolated
                .push("vertex colours: harmonic over the patch from the rim".into());
        }
    }
    // the surface normals, only where something takes them
    let wants_normals = a.normals.is_some()
        || a.vertex
            .iter()
            .any(|p| matches!(p.meaning(), Meaning::Normal(_)));
    let normals = if new_vertices && wants_normals {
        ctx.vertex_normals()
    } else {
        Vec::new()
    };
    for p in &a.vertex {
        let (data, how) = ctx.vertex_property(p, &normals);
        if new_vertices {
            rep.interpolated.push(format!("vertex {}: {how}", p.name));
        }
        out.attrs.vertex.push(Property {
            name: p.name.clone(),
            data,
        });
    }
    // OBJ colours kept as written: a new vertex's 0..1 colour is that of its values
    // (0..255 ones rounded), as reading the written file gives
    let kept = a.obj.as_ref().filter(|o| o.byte_colors || o.exact_colors);
    if let Some(scale) = kept
        .filter(|_| new_vertices)
        .map(|o| if o.byte_colors { 255.0 } else { 1.0 })
    {
        let RawMesh { attrs, colors, .. } = &mut out;
        let find = |name: &str| {
            attrs.vertex.iter().find_map(|p| match &p.data {
                PropData::Scalar(v) if p.name == name => Some(v),
                _ => None,
            })
        };
        if let (Some(r), Some(g), Some(b), Some(cs)) =
            (find("red"), find("green"), find("blue"), colors.as_mut())
        {
            for (v, c) in cs.iter_mut().enumerate() {
                if ctx.src.get(v).copied().flatten().is_none() {
                    *c = [r, g, b].map(|ch| {
                        crate::io::unit_color(f64::from(ch.get(v).unwrap_or(0.0) as f32 / scale))
                    });
                }
            }
        }
    }

    // face values; the colour channels chosen together (one face's whole colour)
    let colour: Vec<&PropData> = a
        .face
        .iter()
        .filter(|p| p.meaning() == Meaning::Color)
        .map(|p| &p.data)
        .collect();
    let colour_key = |j: usize| {
        colour
            .iter()
            .try_fold(0u64, |h, d| Some(h.rotate_left(17) ^ key_of(d, j)?))
    };
    for p in &a.face {
        let is_colour = p.meaning() == Meaning::Color;
        let data = if is_colour {
            ctx.face_column(&p.data, colour_key)
        } else {
            ctx.face_column(&p.data, |j| key_of(&p.data, j))
        };
        out.attrs.face.push(Property {
            name: p.name.clone(),
            data,
        });
        if new_faces {
            rep.interpolated.push(format!(
                "face {}: the most common {} of the faces around the hole",
                p.name,
                if is_colour { "colour" } else { "value" }
            ));
        }
    }
    if let Some(o) = &a.obj {
        let face_state = if o.face_state.is_empty() {
            Vec::new()
        } else {
            let pick = ctx.patch_pick(|j| o.face_state.get(j).map(|&s| u64::from(s)));
            (0..ctx.face_src.len())
                .map(|f| {
                    let j = ctx.face_src[f].map(|(j, _)| j).or(pick(f));
                    j.and_then(|j| o.face_state.get(j).copied()).unwrap_or(0)
                })
                .collect()
        };
        if new_faces && !face_state.is_empty() {
            rep.interpolated.push(
                "face usemtl/g/o/s: the most common state of the faces around the hole".into(),
            );
        }
        out.attrs.obj = Some(ObjExtras {
            mtllibs: o.mtllibs.clone(),
            states: o.states.clone(),
            face_state,
            byte_colors: o.byte_colors,
            exact_colors: o.exact_colors,
        });
    }
    if let Some(s) = a.stl.as_ref().filter(|s| s.attribute.is_empty()) {
        out.attrs.stl = Some(s.clone());
    } else if let Some(s) = &a.stl {
        let pick = ctx.patch_pick(|j| s.attribute.get(j).map(|&x| u64::from(x)));
        let attribute = (0..ctx.face_src.len())
            .map(|f| {
                let j = ctx.face_src[f].map(|(j, _)| j).or(pick(f));
                j.and_then(|j| s.attribute.get(j).copied()).unwrap_or(0)
            })
            .collect();
        if new_faces {
            rep.interpolated.push(
                "STL facet attribute bytes: the most common value of the facets around the hole"
                    .into(),
            );
        }
        out.attrs.stl = Some(StlExtras {
            header: s.header,
            attribute,
        });
    }
    out.attrs.ply = a.ply.clone();
    if let Some(g) = &a.gltf {
        // which triangle read each output face is; the primitive a new face joins
        let pick = ctx.patch_pick(|j| g.prim_of(j).map(u64::from));
        let out_faces: Vec<Option<u32>> = ctx
            .face_src
            .iter()
            .map(|s| s.map(|(j, _)| j as u32))
            .collect();
        let out_prim = (0..ctx.face_src.len())
            .map(|f| {
                let j = ctx.face_src[f].map(|(j, _)| j).or(pick(f));
                j.and_then(|j| g.prim_of(j)).unwrap_or(0)
            })
            .collect();
        if new_faces && g.prims.len() > 1 {
            rep.interpolated.push(
                "glTF primitive (material) of new faces: the most common of the faces around the hole"
                    .into(),
            );
        }
        out.attrs.gltf = Some(crate::io::attrs::GltfExtras {
            out_faces,
            out_prim,
            ..g.clone()
        });
    }

    // corner values
    if let Some(uv) = &a.uv {
        let (mut c, counts) = ctx.corner_uvs(uv);
        // new values in the precision the file stores them in (PLY `float` lists)
        if a.ply
            .as_ref()
            .and_then(|p| p.texcoord)
            .is_some_and(|(_, t)| t == ScalarType::F32)
        {
            for v in c.values.iter_mut().skip(uv.values.len()) {
                *v = v.map(|x| f64::from(x as f32));
            }
        }
        out.attrs.uv = Some(c);
        if new_faces {
            rep.interpolated.push(
                "texture coordinates: mapped into the rim's UV polygon, else one rim UV per patch (counted in uv_patches)"
                    .into(),
            );
        }
        rep.uv_patches = counts;
    }
    if let Some(n) = &a.normals {
        out.attrs.normals = Some(ctx.corner_normals(n, &normals));
        if new_faces {
            rep.interpolated
                .push("corner normals: the patch surface's, the rim's own at rim vertices".into());
        }
    }
    (out, rep)
}

/// A sortable key of value `j` of a property (its bits; a list's first item).
fn key_of(d: &PropData, j: usize) -> Option<u64> {
    match d {
        PropData::Scalar(v) => v.get(j).map(f64::to_bits),
        PropData::List { starts, items, .. } => {
            let s = *starts.get(j)? as usize;
            let e = *starts.get(j + 1)? as usize;
            let mut h: u64 = (e - s) as u64;
            for k in s..e {
                h = h.rotate_left(7) ^ items.get(k).map_or(0, f64::to_bits);
            }
            Some(h)
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Weights {
    Cotan,
    Uniform,
}

/// The correspondence of output and input elements, and the patches.
struct Context<'m> {
    mesh: &'m Mesh,
    /// Per output vertex, the input vertex it stands for.
    src: Vec<Option<usize>>,
    /// Per output face, the input face it is and, per output corner, the input
    /// corner.
    face_src: Vec<Option<(usize, [usize; 3])>>,
    /// Per output face, its patch (new faces only).
    patch_of: Vec<Option<u32>>,
    /// Per patch, its faces.
    patches: Vec<Vec<FaceId>>,
    /// Per patch, its border half-edges (in a patch face, twin in an input face).
    borders: Vec<Vec<HalfedgeId>>,
}

impl<'m> Context<'m> {
    fn new(mesh: &'m Mesh, input: &RawMesh) -> Context<'m> {
        let nin = input.positions.len();
        let src: Vec<Option<usize>> = (0..mesh.num_vertices())
            .map(|v| {
                mesh.origin
                    .get(v)
                    .copied()
                    .flatten()
                    .map(|o| o.idx())
                    .filter(|&i| i < nin)
            })
            .collect();
        // input faces by their smallest vertex
        let (off, faces_of) = super::group_by_key(nin, input.faces.len(), |j| {
            input.faces[j].iter().copied().min().unwrap_or(0) as usize % nin.max(1)
        });
        let face_src: Vec<Option<(usize, [usize; 3])>> = mesh
            .topo
            .faces()
            .iter()
            .map(|f| {
                let s = [src[f[0].idx()]?, src[f[1].idx()]?, src[f[2].idx()]?];
                let lo = *s.iter().min()?;
                let (a, b) = (*off.get(lo)? as usize, *off.get(lo + 1)? as usize);
                faces_of.get(a..b)?.iter().find_map(|&j| {
                    let t = input.faces.get(j as usize)?.map(|i| i as usize);
                    let corner = |v: usize| t.iter().position(|&w| w == v);
                    Some((j as usize, [corner(s[0])?, corner(s[1])?, corner(s[2])?]))
                        .filter(|(_, c)| c[0] != c[1] && c[1] != c[2] && c[0] != c[2])
                })
            })
            .collect();
        // patches: connected sets of new faces
        let nf = mesh.num_faces();
        let mut patch_of: Vec<Option<u32>> = vec![None; nf];
        let mut patches: Vec<Vec<FaceId>> = Vec::new();
        let mut borders: Vec<Vec<HalfedgeId>> = Vec::new();
        for f0 in 0..nf {
            if face_src[f0].is_some() || patch_of[f0].is_some() {
                continue;
            }
            let id = patches.len() as u32;
            let mut faces = vec![FaceId::from_idx(f0)];
            let mut border = Vec::new();
            patch_of[f0] = Some(id);
            let mut k = 0;
            while let Some(&f) = faces.get(k) {
                k += 1;
                for c in 0..3 {
                    let h = f.halfedge(c);
                    let Some(t) = mesh.topo.twin(h) else { continue };
                    let g = t.face().idx();
                    if face_src[g].is_some() {
                        border.push(h);
                    } else if patch_of[g].is_none() {
                        patch_of[g] = Some(id);
                        faces.push(t.face());
                    }
                }
            }
            patches.push(faces);
            borders.push(border);
        }
        Context {
            mesh,
            src,
            face_src,
            patch_of,
            patches,
            borders,
        }
    }

    /// The new vertices of each patch (a new vertex's faces are all new, so it
    /// belongs to one patch; one with no face is left out).
    fn patch_vertices(&self) -> Vec<Vec<VertexId>> {
        let mut seen = vec![false; self.mesh.num_vertices()];
        self.patches
            .iter()
            .map(|faces| {
                let mut vs = Vec::new();
                for &f in faces {
                    for v in self.mesh.topo.face(f) {
                        if self.src[v.idx()].is_none() && !seen[v.idx()] {
                            seen[v.idx()] = true;
                            vs.push(v);
                        }
                    }
                }
                vs
            })
            .collect()
    }

    /// Harmonic values of dimension `D` for every new vertex (input vertices: their
    /// own, from `fixed`), per patch; zeros for a vertex nothing fixes.
    fn harmonic<const D: usize>(
        &self,
        fixed: &dyn Fn(usize) -> Option<[f64; D]>,
        w: Weights,
    ) -> Vec<[f64; D]> {
        let n = self.mesh.num_vertices();
        let mut out = vec![[0.0; D]; n];
        for (v, s) in self.src.iter().enumerate() {
            if let Some(x) = s.and_then(fixed) {
                out[v] = x;
            }
        }
        for free in self.patch_vertices() {
            let vals = solve(self.mesh, &free, w, &|v: VertexId| {
                self.src[v.idx()].and_then(fixed)
            });
            for (v, x) in free.iter().zip(vals) {
                out[v.idx()] = x;
            }
        }
        out
    }

    /// Unit area-weighted vertex normals of the output mesh at the vertices of the
    /// patches (zero elsewhere: nothing there takes them).
    fn vertex_normals(&self) -> Vec<DVec3> {
        let mut out = vec![DVec3::ZERO; self.mesh.num_vertices()];
        let mut done = vec![false; self.mesh.num_vertices()];
        for &f in self.patches.iter().flatten() {
            for v in self.mesh.topo.face(f) {
                if !done[v.idx()] {
                    done[v.idx()] = true;
                    out[v.idx()] = self.mesh.vertex_normal(v);
                }
            }
        }
        out
    }

    /// A vertex property for every output vertex, and how new vertices got it.
    fn vertex_property(&self, p: &Property, normals: &[DVec3]) -> (PropData, &'static str) {
        let n = self.mesh.num_vertices();
        let mut data = p.data.empty_like(n);
        let meaning = p.meaning();
        let (solved, how): (Vec<f64>, &str) = match meaning {
            Meaning::Color | Meaning::Smooth => {
                let fixed = |i: usize| match &p.data {
                    PropData::Scalar(v) => v.get(i).filter(|x| x.is_finite()).map(|x| [x]),
                    PropData::List { .. } => None,
                };
                let s = self.harmonic::<1>(&fixed, Weights::Cotan);
                (
                    s.into_iter().map(|[x]| x).collect(),
                    "harmonic over the patch from the rim",
                )
            }
            Meaning::Normal(k) => (
                normals.iter().map(|n| n[k]).collect(),
                "the patch surface's normal",
            ),
            Meaning::Label => (Vec::new(), "the rim's most common value"),
            Meaning::List => (Vec::new(), "an empty list"),
        };
        // labels: per patch, the most common value of its rim vertices
        let mut label_src: Vec<Option<usize>> = Vec::new();
        if meaning == Meaning::Label {
            label_src = vec![None; n];
            for (free, faces) in self.patch_vertices().iter().zip(&self.patches) {
                let mut rim: Vec<usize> = faces
                    .iter()
                    .flat_map(|&f| self.mesh.topo.face(f))
                    .filter_map(|v| self.src[v.idx()])
                    .collect();
                rim.sort_unstable();
                rim.dedup();
                let pick = most_common(rim.iter().copied(), |i| key_of(&p.data, i));
                for v in free {
                    label_src[v.idx()] = pick;
                }
            }
        }
        for v in 0..n {
            let copied = match self.src[v] {
                Some(i) => data.push_from(&p.data, i),
                None => match label_src.get(v).copied().flatten() {
                    Some(i) => data.push_from(&p.data, i),
                    None => false,
                },
            };
            if !copied {
                data.push_value(solved.get(v).copied().unwrap_or(0.0));
            }
        }
        (data, how)
    }

    /// For a new face `f`, a function choosing the input face whose value it takes:
    /// the most common `key` among the input faces across its patch's border.
    fn patch_pick(&self, key: impl Fn(usize) -> Option<u64>) -> impl Fn(usize) -> Option<usize> {
        let picks: Vec<Option<usize>> = self
            .borders
            .iter()
            .map(|b| {
                let faces = b.iter().filter_map(|&h| {
                    let t = self.mesh.topo.twin(h)?;
                    self.face_src[t.face().idx()].map(|(j, _)| j)
                });
                most_common(faces, &key)
            })
            .collect();
        let patch_of = self.patch_of.clone();
        move |f| {
            picks
                .get(patch_of.get(f).copied().flatten()? as usize)
                .copied()
                .flatten()
        }
    }

    /// A face property for every output face.
    fn face_column(&self, d: &PropData, key: impl Fn(usize) -> Option<u64>) -> PropData {
        let nf = self.face_src.len();
        let pick = self.patch_pick(key);
        let mut data = d.empty_like(nf);
        for f in 0..nf {
            let j = self.face_src[f].map(|(j, _)| j).or_else(|| pick(f));
            if !j.is_some_and(|j| data.push_from(d, j)) {
                data.push_value(0.0);
            }
        }
        data
    }

    /// The corner indices of input-derived faces (corners matched), `None` for new
    /// faces.
    fn input_corners<T>(&self, c: &Corners<T>) -> Vec<Option<[u32; 3]>> {
        self.face_src
            .iter()
            .map(|s| {
                let (j, m) = (*s)?;
                let idx = (*c.index.get(j)?)?;
                Some([idx[m[0]], idx[m[1]], idx[m[2]]])
            })
            .collect()
    }

    /// Per patch, per rim vertex, the corner value indices the input faces across
    /// the border give it (from both ends of each border edge).
    fn rim_corners(
        &self,
        index: &[Option<[u32; 3]>],
        patch: usize,
    ) -> Vec<(VertexId, Option<u32>)> {
        let mut out = Vec::new();
        for &h in &self.borders[patch] {
            let Some(t) = self.mesh.topo.twin(h) else {
                continue;
            };
            let g = t.face().idx();
            let (a, b) = (t.corner(), (t.corner() + 1) % 3);
            let vs = self.mesh.topo.face(t.face());
            let idx = index.get(g).copied().flatten();
            out.push((vs[a], idx.map(|i| i[a])));
            out.push((vs[b], idx.map(|i| i[b])));
        }
        out
    }

    /// Texture coordinates of every output face's corners.
    fn corner_uvs(&self, uv: &Corners<[f64; 2]>) -> (Corners<[f64; 2]>, UvCounts) {
        let mut counts = UvCounts::default();
        let mut index = self.input_corners(uv);
        let mut values = uv.values.clone();
        let patch_vertices = self.patch_vertices();
        for (p, faces) in self.patches.iter().enumerate() {
            let rim = self.rim_corners(&index, p);
            // one UV per rim vertex?
            let mut at: Vec<(VertexId, u32)> = Vec::new();
            let mut missing = rim.is_empty();
            let mut seam = false;
            for &(v, i) in &rim {
                let Some(i) = i else {
                    missing = true;
                    continue;
                };
                match at.iter().find(|(w, _)| *w == v) {
                    Some(&(_, j)) => {
                        if uv.values.get(j as usize) != uv.values.get(i as usize) {
                            seam = true;
                        }
                    }
                    None => at.push((v, i)),
                }
            }
            // rim vertices of the patch that no border edge reaches (a patch
            // touching the rim at a vertex only) also need a UV
            for &f in faces {
                for v in self.mesh.topo.face(f) {
                    if self.src[v.idx()].is_some() && !at.iter().any(|(w, _)| *w == v) {
                        missing = true;
                    }
                }
            }
            let uv_of =
                |i: u32| DVec2::from_array(uv.values.get(i as usize).copied().unwrap_or([0.0; 2]));
            if missing {
                counts.missing += 1;
                continue; // the patch's faces keep no texture coordinates
            }
            let mapped = if seam {
                counts.seam += 1;
                None
            } else {
                self.map_patch(p, &patch_vertices[p], &at, &uv_of, &rim, &index)
            };
            if !seam && mapped.is_none() {
                counts.not_simple += 1;
            }
            match mapped {
                Some(new_uv) => {
                    counts.mapped += 1;
                    let base = values.len() as u32;
                    let mut slot: crate::fasthash::HashMap<VertexId, u32> =
                        at.iter().copied().collect();
                    for (k, (v, x)) in patch_vertices[p].iter().zip(&new_uv).enumerate() {
                        values.push(x.to_array());
                        slot.insert(*v, base + k as u32);
                    }
                    for &f in faces {
                        let vs = self.mesh.topo.face(f);
                        let corner = |v: VertexId| slot.get(&v).copied();
                        index[f.idx()] = match (corner(vs[0]), corner(vs[1]), corner(vs[2])) {
                            (Some(a), Some(b), Some(c)) => Some([a, b, c]),
                            _ => None,
                        };
                    }
                }
                None => {
                    // fallback: one rim UV for the whole patch
                    let one = at.first().map(|x| x.1);
                    for &f in faces {
                        index[f.idx()] = one.map(|i| [i; 3]);
                    }
                }
            }
        }
        (Corners { values, index }, counts)
    }

    /// The harmonic map of a patch into the UV polygon of its rim: the new
    /// vertices' UVs, or `None` when the polygon is not simple or a UV triangle
    /// flips with both weightings.
    fn map_patch(
        &self,
        patch: usize,
        free: &[VertexId],
        at: &[(VertexId, u32)],
        uv_of: &dyn Fn(u32) -> DVec2,
        rim: &[(VertexId, Option<u32>)],
        index: &[Option<[u32; 3]>],
    ) -> Option<Vec<DVec2>> {
        let faces = &self.patches[patch];
        let at: crate::fasthash::HashMap<VertexId, u32> = at.iter().copied().collect();
        let rim_uv = |v: VertexId| at.get(&v).map(|&i| uv_of(i));
        // the border in UV: simple?
        let segs: Vec<(DVec2, DVec2)> = rim
            .chunks_exact(2)
            .filter_map(|c| Some((rim_uv(c[0].0)?, rim_uv(c[1].0)?)))
            .collect();
        if !simple(&segs) {
            return None;
        }
        // the orientation of the rim faces in UV
        let mut sign = 0.0;
        for &h in &self.borders[patch] {
            if let Some(t) = self.mesh.topo.twin(h) {
                if let Some(i) = index.get(t.face().idx()).copied().flatten() {
                    sign += area(uv_of(i[0]), uv_of(i[1]), uv_of(i[2]));
                }
            }
        }
        if sign == 0.0 {
            return None;
        }
        for w in [Weights::Cotan, Weights::Uniform] {
            let vals = solve(self.mesh, free, w, &|v: VertexId| {
                rim_uv(v).map(|p| p.to_array())
            });
            let pos: crate::fasthash::HashMap<VertexId, usize> =
                free.iter().enumerate().map(|(k, &v)| (v, k)).collect();
            let uv_at = |v: VertexId| {
                pos.get(&v)
                    .and_then(|&k| vals.get(k))
                    .map(|x| DVec2::from_array(*x))
                    .or_else(|| rim_uv(v))
            };
            let ok = faces.iter().all(|&f| {
                let [a, b, c] = self.mesh.topo.face(f);
                match (uv_at(a), uv_at(b), uv_at(c)) {
                    (Some(a), Some(b), Some(c)) => area(a, b, c) * sign.signum() > 0.0,
                    _ => false,
                }
            });
            if ok {
                return Some(vals.into_iter().map(DVec2::from_array).collect());
            }
        }
        None
    }

    /// Corner normals of every output face: input faces' own; new faces: the
    /// rim's normal at a rim vertex where the rim has exactly one, else the patch
    /// surface's normal.
    fn corner_normals(&self, n: &Corners<[f64; 3]>, normals: &[DVec3]) -> Corners<[f64; 3]> {
        let mut index = self.input_corners(n);
        let mut values = n.values.clone();
        let mut slot: Vec<Option<u32>> = vec![None; self.mesh.num_vertices()];
        for (p, faces) in self.patches.iter().enumerate() {
            let rim = self.rim_corners(&index, p);
            let mut own: Vec<(VertexId, Option<u32>)> = Vec::new();
            for (v, i) in rim {
                match own.iter_mut().find(|(w, _)| *w == v) {
                    Some(e) => {
                        if e.1.is_some()
                            && n.values.get(i.unwrap_or(u32::MAX) as usize)
                                != e.1.and_then(|j| n.values.get(j as usize))
                        {
                            e.1 = None;
                        }
                    }
                    None => own.push((v, i)),
                }
            }
            for &f in faces {
                let vs = self.mesh.topo.face(f);
                let mut c = [0u32; 3];
                for (k, v) in vs.into_iter().enumerate() {
                    let rimmed = if self.src[v.idx()].is_some() {
                        own.iter().find(|(w, _)| *w == v).and_then(|x| x.1)
                    } else {
                        None
                    };
                    c[k] = match rimmed.or(slot[v.idx()]) {
                        Some(i) => i,
                        None => {
                            let i = values.len() as u32;
                            let nn = normals.get(v.idx()).copied().unwrap_or(DVec3::Z);
                            values.push(nn.to_array());
                            if self.src[v.idx()].is_none() {
                                slot[v.idx()] = Some(i);
                            }
                            i
                        }
                    };
                }
                index[f.idx()] = Some(c);
            }
        }
        Corners { values, index }
    }
}

/// The item whose key is most common (ties: the first seen).
fn most_common(
    items: impl Iterator<Item = usize>,
    key: impl Fn(usize) -> Option<u64>,
) -> Option<usize> {
    let mut seen: Vec<(u64, usize, usize)> = Vec::new();
    for i in items {
        let Some(k) = key(i) else { continue };
        match seen.iter_mut().find(|e| e.0 == k) {
            Some(e) => e.2 += 1,
            None => seen.push((k, i, 1)),
        }
    }
    let best = seen.iter().map(|e| e.2).max()?;
    seen.into_iter().find(|e| e.2 == best).map(|e| e.1)
}
