//! The half-edge triangle mesh.
//!
//! Topology ([`Topology`]) is kept apart from geometry (positions, colours). The
//! half-edges of a face are implicit: half-edge `3f + i` runs from corner `i` to
//! corner `i + 1` of face `f`, so `next`/`prev` are arithmetic and only the twin
//! (`Option`: `None` on a boundary) is stored. Every vertex has at most one fan of
//! faces (non-manifold vertices are split by the builder), so each boundary vertex
//! lies on exactly one boundary loop, once.
//!
//! Vertices are never renumbered: the vertices of the input keep their index, and
//! vertices added by the builder (copies of split non-manifold vertices) or by hole
//! filling are appended.

pub mod attributes;
mod build;
mod error;
mod ids;

pub use build::BuildReport;
pub use error::TopologyError;
pub use ids::{FaceId, HalfedgeId, VertexId};

use glam::DVec3;

/// Connectivity only: faces, twins and one outgoing half-edge per vertex.
#[derive(Clone, Debug, Default)]
pub struct Topology {
    faces: Vec<[VertexId; 3]>,
    twin: Vec<Option<HalfedgeId>>,
    /// For a boundary vertex: the outgoing half-edge whose twin is `None`, so that
    /// walking [`Topology::next_outgoing`] from it visits the whole fan. `None` for an
    /// isolated vertex.
    anchor: Vec<Option<HalfedgeId>>,
}

impl Topology {
    /// Number of vertices (including isolated ones).
    pub fn num_vertices(&self) -> usize {
        self.anchor.len()
    }
    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.faces.len()
    }
    /// The three corners of a face, counter-clockwise seen from outside.
    #[inline]
    pub fn face(&self, f: FaceId) -> [VertexId; 3] {
        self.faces[f.idx()]
    }
    /// All faces.
    pub fn faces(&self) -> &[[VertexId; 3]] {
        &self.faces
    }
    /// The vertex a half-edge starts at.
    #[inline]
    pub fn from(&self, h: HalfedgeId) -> VertexId {
        self.faces[h.face().idx()][h.corner()]
    }
    /// The vertex a half-edge ends at.
    #[inline]
    pub fn to(&self, h: HalfedgeId) -> VertexId {
        self.faces[h.face().idx()][(h.corner() + 1) % 3]
    }
    /// The opposite half-edge, `None` on a boundary.
    #[inline]
    pub fn twin(&self, h: HalfedgeId) -> Option<HalfedgeId> {
        self.twin[h.0 as usize]
    }
    /// An outgoing half-edge of `v` (for a boundary vertex the one with no twin).
    #[inline]
    pub fn anchor(&self, v: VertexId) -> Option<HalfedgeId> {
        self.anchor[v.idx()]
    }
    /// The next outgoing half-edge around `from(h)`, `None` at the boundary.
    #[inline]
    pub fn next_outgoing(&self, h: HalfedgeId) -> Option<HalfedgeId> {
        self.twin(h.prev())
    }
    /// The previous outgoing half-edge around `from(h)`, `None` at the boundary.
    #[inline]
    pub fn prev_outgoing(&self, h: HalfedgeId) -> Option<HalfedgeId> {
        self.twin(h).map(|t| t.next())
    }
    /// True when `v` has faces and lies on a boundary.
    pub fn is_boundary_vertex(&self, v: VertexId) -> bool {
        match self.anchor(v) {
            Some(h) => self.twin(h).is_none(),
            None => false,
        }
    }
    /// The outgoing half-edges of `v`, in fan order (from the boundary, if any).
    pub fn outgoing(&self, v: VertexId) -> Outgoing<'_> {
        let start = self.anchor(v);
        Outgoing {
            topo: self,
            start,
            cur: start,
            steps: 0,
        }
    }
    /// The neighbours of `v`. For a boundary vertex the last fan face's far vertex
    /// is included, so the list holds every adjacent vertex once.
    pub fn neighbors(&self, v: VertexId) -> Vec<VertexId> {
        let mut out = Vec::new();
        let mut last = None;
        for h in self.outgoing(v) {
            out.push(self.to(h));
            last = Some(h);
        }
        if let Some(h) = last {
            if self.next_outgoing(h).is_none() {
                out.push(self.from(h.prev()));
            }
        }
        out
    }
    /// The faces around `v`, in fan order.
    pub fn vertex_faces(&self, v: VertexId) -> impl Iterator<Item = FaceId> + '_ {
        self.outgoing(v).map(|h| h.face())
    }
    /// The boundary half-edge (twin `None`) incoming to boundary vertex `v`.
    pub fn incoming_boundary(&self, v: VertexId) -> Option<HalfedgeId> {
        let mut last = None;
        for h in self.outgoing(v) {
            last = Some(h);
        }
        let h = last?;
        let p = h.prev();
        if self.twin(p).is_none() {
            Some(p)
        } else {
            None
        }
    }
    /// Every boundary loop, as the vertex sequence of the hole: consecutive vertices
    /// `l[i] -> l[i+1]` run opposite to the existing face's half-edge, so a patch
    /// triangle `(l[i], l[i+1], x)` is oriented like the surrounding surface.
    pub fn boundary_loops(&self) -> Vec<Vec<VertexId>> {
        // the boundary half-edges already walked (a few among many: a set, not a
        // flag per half-edge, which would be most of this walk's cost)
        let mut seen: crate::fasthash::HashSet<u32> = Default::default();
        let mut loops = Vec::new();
        // blocks of half-edges all with a twin (nearly all of a mesh) skipped at once
        let open: Vec<usize> = self
            .twin
            .chunks(16)
            .enumerate()
            .filter(|(_, c)| !c.iter().fold(true, |all, t| all & t.is_some()))
            .flat_map(|(b, c)| {
                c.iter()
                    .enumerate()
                    .filter(|(_, t)| t.is_none())
                    .map(move |(i, _)| b * 16 + i)
            })
            .collect();
        for i in open {
            if seen.contains(&(i as u32)) {
                continue;
            }
            // face half-edge a -> b; the hole runs b -> a -> ...
            let start = HalfedgeId::from_idx(i);
            let mut lp = vec![self.to(start)];
            let mut h = start;
            let mut guard = 0usize;
            loop {
                seen.insert(h.0);
                let a = self.from(h);
                lp.push(a);
                match self.incoming_boundary(a) {
                    Some(g) if g != start => h = g,
                    _ => break,
                }
                guard += 1;
                if guard > self.twin.len() {
                    break;
                }
            }
            // the loop closes on its first vertex: drop the repeat
            if lp.len() > 1 && lp.first() == lp.last() {
                lp.pop();
            }
            loops.push(lp);
        }
        loops
    }

    /// Appends faces and links their twins with each other and with the boundary.
    ///
    /// Fails, changing nothing, when a new directed edge already exists (the result
    /// would not be an oriented manifold).
    ///
    /// No hashing: the directed edges that matter (the new ones, and the existing ones
    /// leaving or entering a vertex of the new faces) are grouped by their start
    /// vertex with a counting sort over the new faces' vertices (sorted, found by
    /// binary search), and each vertex's short list is searched for an end vertex
    /// (a patch of 1,800 faces: 0.5 ms with two hash maps, serial in the fill).
    pub fn add_faces(
        &mut self,
        new: &[[VertexId; 3]],
        num_vertices: usize,
    ) -> Result<(), TopologyError> {
        if self.anchor.len() < num_vertices {
            self.anchor.resize(num_vertices, None);
        }
        let mut touched: Vec<VertexId> = Vec::with_capacity(new.len() * 3);
        for f in new {
            touched.extend_from_slice(f);
        }
        touched.sort_unstable();
        touched.dedup();
        if let Some(&v) = touched.last() {
            if v.idx() >= self.anchor.len() {
                return Err(TopologyError::VertexOutOfRange(v));
            }
        }
        // the new vertices of a patch are one run of ids at the end of `touched`: an
        // offset there, a binary search among the others (the loop's)
        let t = touched.len();
        let mut run = t.saturating_sub(1);
        while run > 0 && touched[run - 1].0 + 1 == touched[run].0 {
            run -= 1;
        }
        let run_first = touched.get(run).map_or(u32::MAX, |v| v.0);
        let local = |v: VertexId| -> Option<usize> {
            if v.0 >= run_first {
                let i = run + (v.0 - run_first) as usize;
                (i < t).then_some(i)
            } else {
                touched[..run].binary_search(&v).ok()
            }
        };
        // every vertex of a new face is touched
        let corners: Vec<[usize; 3]> = new
            .iter()
            .map(|f| f.map(|v| local(v).unwrap_or(0)))
            .collect();
        let base = self.faces.len() as u32;
        let new_half = |fi: usize, c: usize| HalfedgeId((base + fi as u32) * 3 + c as u32);
        // the directed edges by start vertex: (end, half-edge); new half-edges are
        // those from `base * 3` on
        let mut edges: Vec<(usize, VertexId, HalfedgeId)> = Vec::with_capacity(new.len() * 6);
        for (fi, f) in new.iter().enumerate() {
            for c in 0..3 {
                edges.push((corners[fi][c], f[(c + 1) % 3], new_half(fi, c)));
            }
        }
        for (a, &v) in touched.iter().enumerate() {
            for h in self.outgoing(v) {
                edges.push((a, self.to(h), h));
                // the one entering `v`, kept under its start when that is touched
                // (a complete fan lists it there too; the copy is harmless)
                let p = h.prev();
                if let Some(u) = local(self.from(p)) {
                    edges.push((u, v, p));
                }
            }
        }
        let mut start = vec![0usize; t + 1];
        for e in &edges {
            start[e.0 + 1] += 1;
        }
        for i in 0..t {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut by_start: Vec<(VertexId, HalfedgeId)> =
            vec![(VertexId(0), HalfedgeId(0)); edges.len()];
        for &(a, b, h) in &edges {
            by_start[fill[a]] = (b, h);
            fill[a] += 1;
        }
        let first_new = base * 3;
        let out_of = |a: usize| &by_start[start[a]..start[a + 1]];
        // in face order, as the first failure is reported: a repeated vertex, or a
        // directed edge that exists already or comes in an earlier new face
        for (fi, f) in new.iter().enumerate() {
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                return Err(TopologyError::NewFaceRepeatsVertex(fi));
            }
            for c in 0..3 {
                let (a, b) = (f[c], f[(c + 1) % 3]);
                let h = new_half(fi, c);
                if out_of(corners[fi][c])
                    .iter()
                    .any(|&(e, g)| e == b && (g.0 < first_new || g.0 < h.0))
                {
                    return Err(TopologyError::DirectedEdgeTaken(a, b));
                }
            }
        }
        let mut links: Vec<(HalfedgeId, HalfedgeId)> = Vec::with_capacity(new.len() * 2);
        for (fi, f) in new.iter().enumerate() {
            for c in 0..3 {
                let (a, b) = (f[c], f[(c + 1) % 3]);
                let h = new_half(fi, c);
                let Some(&(_, t)) = out_of(corners[fi][(c + 1) % 3])
                    .iter()
                    .find(|&&(e, _)| e == a)
                else {
                    continue;
                };
                if t.0 >= first_new {
                    if h.0 < t.0 {
                        links.push((h, t));
                    }
                } else {
                    if self.twin(t).is_some() {
                        return Err(TopologyError::ThirdFace(a, b));
                    }
                    links.push((h, t));
                }
            }
        }
        self.faces.extend_from_slice(new);
        self.twin.resize(self.faces.len() * 3, None);
        for (h, t) in links {
            self.twin[h.0 as usize] = Some(t);
            self.twin[t.0 as usize] = Some(h);
        }
        for (fi, f) in new.iter().enumerate() {
            for (c, &v) in f.iter().enumerate() {
                if self.anchor[v.idx()].is_none() {
                    self.anchor[v.idx()] = Some(new_half(fi, c));
                }
            }
        }
        for v in touched {
            self.reanchor(v);
        }
        Ok(())
    }

    /// Moves the anchor of `v` to the start of its fan (the boundary half-edge).
    fn reanchor(&mut self, v: VertexId) {
        let Some(start) = self.anchor[v.idx()] else {
            return;
        };
        let mut h = start;
        let mut guard = 0usize;
        while let Some(p) = self.prev_outgoing(h) {
            if p == start {
                return; // interior vertex: any half-edge will do
            }
            h = p;
            guard += 1;
            if guard > self.twin.len() {
                return;
            }
        }
        self.anchor[v.idx()] = Some(h);
    }

    /// Checks every invariant; returns the first violation found.
    ///
    /// Linear time and memory (no hashing): the half-edges are grouped by their start
    /// vertex with a counting sort, and each vertex's (short) list of end vertices is
    /// sorted to find a repeated directed edge and to look up opposites.
    pub fn validate(&self) -> Result<(), TopologyError> {
        let nv = self.anchor.len();
        if self.twin.len() != self.faces.len() * 3 {
            return Err(TopologyError::TwinArraySize);
        }
        if self.twin.len() > u32::MAX as usize {
            return Err(TopologyError::TooManyHalfEdges);
        }
        for (fi, f) in self.faces.iter().enumerate() {
            for c in 0..3 {
                if f[c].idx() >= nv {
                    return Err(TopologyError::FaceVertexOutOfRange {
                        face: fi,
                        vertex: f[c],
                    });
                }
                if f[c] == f[(c + 1) % 3] {
                    return Err(TopologyError::FaceRepeatsVertex {
                        face: fi,
                        vertex: f[c],
                    });
                }
            }
        }
        // the end vertices of the half-edges leaving each vertex, sorted
        let (off, mut ends) = group_by_key(nv, self.twin.len(), |h| {
            self.from(HalfedgeId::from_idx(h)).idx()
        });
        for e in ends.iter_mut() {
            *e = self.to(HalfedgeId(*e)).0;
        }
        for v in 0..nv {
            let (a, b) = (off[v] as usize, off[v + 1] as usize);
            let list = &mut ends[a..b];
            list.sort_unstable();
            if let Some(w) = list.windows(2).find(|w| w[0] == w[1]) {
                return Err(TopologyError::DirectedEdgeTwice { from: v, to: w[0] });
            }
        }
        let ends_of = |v: usize| -> &[u32] {
            ends.get(off[v] as usize..off[v + 1] as usize)
                .unwrap_or(&[])
        };
        for (i, t) in self.twin.iter().enumerate() {
            let h = HalfedgeId::from_idx(i);
            if let Some(t) = *t {
                if self.twin(t) != Some(h) {
                    return Err(TopologyError::TwinNotSymmetric(i));
                }
                if self.from(t) != self.to(h) || self.to(t) != self.from(h) {
                    return Err(TopologyError::TwinEndpoints(i));
                }
            } else if ends_of(self.to(h).idx())
                .binary_search(&self.from(h).0)
                .is_ok()
            {
                return Err(TopologyError::UnlinkedOpposite {
                    half_edge: i,
                    from: self.from(h),
                    to: self.to(h),
                });
            }
        }
        let corners = |v: usize| off[v + 1] - off[v];
        for vi in 0..nv {
            let count = corners(vi);
            let v = VertexId::from_idx(vi);
            match self.anchor[vi] {
                None if count > 0 => return Err(TopologyError::NoAnchor(vi)),
                None => {}
                Some(h) => {
                    if self.from(h) != v {
                        return Err(TopologyError::AnchorElsewhere(vi));
                    }
                    let n = self.outgoing(v).count() as u32;
                    if n != count {
                        return Err(TopologyError::NonManifoldVertex {
                            vertex: vi,
                            fan: n,
                            faces: count,
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

/// A counting sort: the items `0..m` grouped by `key(item)` (each `< n`), each group
/// in item order. Returns the group offsets (`n + 1` of them: group `k` is
/// `items[off[k]..off[k + 1]]`) and the items. Linear time, no hashing; `m` must fit
/// in `u32`.
pub(crate) fn group_by_key(
    n: usize,
    m: usize,
    key: impl Fn(usize) -> usize,
) -> (Vec<u32>, Vec<u32>) {
    let mut off = vec![0u32; n + 1];
    for i in 0..m {
        off[key(i) + 1] += 1;
    }
    for k in 0..n {
        off[k + 1] += off[k];
    }
    let mut cursor: Vec<u32> = off[..n].to_vec();
    let mut items = vec![0u32; m];
    for i in 0..m {
        let c = &mut cursor[key(i)];
        items[*c as usize] = i as u32;
        *c += 1;
    }
    (off, items)
}

/// Iterator over the outgoing half-edges of a vertex.
pub struct Outgoing<'a> {
    topo: &'a Topology,
    start: Option<HalfedgeId>,
    cur: Option<HalfedgeId>,
    steps: usize,
}

impl Iterator for Outgoing<'_> {
    type Item = HalfedgeId;
    fn next(&mut self) -> Option<HalfedgeId> {
        let h = self.cur?;
        self.steps += 1;
        let n = self.topo.next_outgoing(h);
        self.cur = if n == self.start || self.steps > self.topo.twin.len() {
            None
        } else {
            n
        };
        Some(h)
    }
}

/// A triangle mesh: topology plus geometry.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Connectivity.
    pub topo: Topology,
    /// Vertex positions.
    pub positions: Vec<DVec3>,
    /// Per-vertex colours in `[0, 1]`, when the input had them.
    pub colors: Option<Vec<[f32; 3]>>,
    /// For each vertex the input vertex it stands for (itself, or the vertex a
    /// non-manifold split copied), `None` for vertices added by filling.
    pub origin: Vec<Option<VertexId>>,
    /// Number of vertices in the input file.
    pub input_vertices: usize,
}

impl Mesh {
    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }
    /// Number of faces.
    pub fn num_faces(&self) -> usize {
        self.topo.num_faces()
    }
    /// Position of a vertex.
    #[inline]
    pub fn pos(&self, v: VertexId) -> DVec3 {
        self.positions[v.idx()]
    }
    /// The corner positions of a face.
    #[inline]
    pub fn tri(&self, f: FaceId) -> [DVec3; 3] {
        let [a, b, c] = self.topo.face(f);
        [self.pos(a), self.pos(b), self.pos(c)]
    }
    /// Unnormalised face normal (twice the area vector).
    pub fn face_normal_raw(&self, f: FaceId) -> DVec3 {
        let [a, b, c] = self.tri(f);
        (b - a).cross(c - a)
    }
    /// Area-weighted vertex normal (unit, or zero when undefined).
    pub fn vertex_normal(&self, v: VertexId) -> DVec3 {
        let mut n = DVec3::ZERO;
        for f in self.topo.vertex_faces(v) {
            n += self.face_normal_raw(f);
        }
        n.normalize_or_zero()
    }
    /// Axis-aligned bounding box (min, max) of all vertices.
    pub fn bbox(&self) -> (DVec3, DVec3) {
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for p in &self.positions {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        if self.positions.is_empty() {
            (DVec3::ZERO, DVec3::ZERO)
        } else {
            (lo, hi)
        }
    }
    /// Length of the bounding-box diagonal.
    pub fn bbox_diagonal(&self) -> f64 {
        let (lo, hi) = self.bbox();
        (hi - lo).length()
    }
    /// Mean length of the edges incident to `v`.
    pub fn mean_incident_edge_length(&self, v: VertexId) -> f64 {
        let nb = self.topo.neighbors(v);
        if nb.is_empty() {
            return 0.0;
        }
        let p = self.pos(v);
        nb.iter().map(|&w| (self.pos(w) - p).length()).sum::<f64>() / nb.len() as f64
    }
    /// Appends a vertex (added by filling) and returns its id.
    pub fn add_vertex(&mut self, p: DVec3, color: Option<[f32; 3]>) -> VertexId {
        let id = VertexId::from_idx(self.positions.len());
        self.positions.push(p);
        if let Some(c) = self.colors.as_mut() {
            c.push(color.unwrap_or([0.5, 0.5, 0.5]));
        }
        self.origin.push(None);
        id
    }
    /// Appends faces over existing vertices (see [`Topology::add_faces`]).
    pub fn add_faces(&mut self, faces: &[[VertexId; 3]]) -> Result<(), TopologyError> {
        let n = self.positions.len();
        self.topo.add_faces(faces, n)
    }
    /// Makes room for `vertices` more vertices and `faces` more faces, so that
    /// adding the patches of a file's holes moves the arrays once, not once per
    /// doubling (an append to a 70,000-face mesh copies it: 1 ms on the bench).
    pub fn reserve(&mut self, vertices: usize, faces: usize) {
        self.positions.reserve(vertices);
        self.origin.reserve(vertices);
        if let Some(c) = self.colors.as_mut() {
            c.reserve(vertices);
        }
        self.topo.anchor.reserve(vertices);
        self.topo.faces.reserve(faces);
        self.topo.twin.reserve(faces * 3);
    }
    /// Removes the last `n` vertices (used to undo a rejected patch's vertices,
    /// which no face references).
    pub fn truncate_vertices(&mut self, n: usize) {
        self.positions.truncate(n);
        self.origin.truncate(n);
        if let Some(c) = self.colors.as_mut() {
            c.truncate(n);
        }
        self.topo.anchor.truncate(n);
    }
    /// Checks topology invariants and that geometry arrays match it.
    pub fn validate(&self) -> Result<(), TopologyError> {
        if self.positions.len() != self.topo.num_vertices() {
            return Err(TopologyError::PositionCount {
                positions: self.positions.len(),
                vertices: self.topo.num_vertices(),
            });
        }
        if self.origin.len() != self.positions.len() {
            return Err(TopologyError::OriginArraySize);
        }
        if let Some(c) = &self.colors {
            if c.len() != self.positions.len() {
                return Err(TopologyError::ColourArraySize);
            }
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(TopologyError::NonFinite(i));
        }
        self.topo.validate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{cells_removed, mesh_and_loop, unit_grid};

    #[test]
    fn grid_has_one_boundary_loop() {
        let (m, rep) = Mesh::from_raw(&unit_grid(4));
        m.validate().unwrap();
        assert_eq!(rep.flipped_faces, 0);
        let loops = m.topo.boundary_loops();
        assert_eq!(loops.len(), 1);
        assert_eq!(loops[0].len(), 16);
        // the hole runs opposite to the faces: for an upward grid it is clockwise
        let l = &loops[0];
        let mut area = 0.0;
        for i in 0..l.len() {
            let a = m.pos(l[i]);
            let b = m.pos(l[(i + 1) % l.len()]);
            area += a.x * b.y - b.x * a.y;
        }
        assert!(area < 0.0);
    }

    #[test]
    fn fill_a_hole_by_adding_faces() {
        // remove the two faces of the cell (1,1)
        let raw = cells_removed(unit_grid(4), |i, j| (i, j) == (1, 1));
        let (mut m, _) = Mesh::from_raw(&raw);
        m.validate().unwrap();
        let loops = m.topo.boundary_loops();
        assert_eq!(loops.len(), 2);
        let hole = loops.iter().find(|l| l.len() == 4).unwrap().clone();
        m.add_faces(&[[hole[0], hole[1], hole[2]], [hole[0], hole[2], hole[3]]])
            .unwrap();
        m.validate().unwrap();
        assert_eq!(m.topo.boundary_loops().len(), 1);
        // adding the same faces again must fail and change nothing
        let before = m.num_faces();
        assert!(m.add_faces(&[[hole[0], hole[1], hole[2]]]).is_err());
        assert_eq!(m.num_faces(), before);
        m.validate().unwrap();
    }

    /// The grid of [`grid`]`(4)` with the cells (1,1) and (2,1) removed: a hole of 6.
    fn grid_with_hole() -> (Mesh, Vec<VertexId>) {
        let raw = cells_removed(unit_grid(4), |i, j| j == 1 && (1..=2).contains(&i));
        mesh_and_loop(&raw, |_, l| l.len() == 6)
    }

    /// A fan around a new centre vertex closes the hole; every twin is linked (the
    /// new spokes with each other, the rim with the mesh) and the ids of the input are
    /// untouched.
    #[test]
    fn a_fan_over_new_vertex_links_every_twin() {
        let (mut m, hole) = grid_with_hole();
        let nv = m.num_vertices();
        let c = m.add_vertex(DVec3::new(2.0, 1.5, 0.0), None);
        let k = hole.len();
        let fan: Vec<[VertexId; 3]> = (0..k).map(|i| [hole[i], hole[(i + 1) % k], c]).collect();
        let before: Vec<[VertexId; 3]> = m.topo.faces().to_vec();
        m.add_faces(&fan).unwrap();
        m.validate().unwrap();
        assert_eq!(m.num_vertices(), nv + 1);
        assert_eq!(&m.topo.faces()[..before.len()], &before[..]);
        assert_eq!(m.topo.boundary_loops().len(), 1);
        // every half-edge of the fan has a twin
        let base = before.len();
        for f in base..m.num_faces() {
            for corner in 0..3 {
                let h = HalfedgeId((f * 3 + corner) as u32);
                assert!(m.topo.twin(h).is_some(), "face {f} corner {corner}");
            }
        }
    }

    /// Each way a batch can break the mesh is an error that changes nothing: a vertex
    /// repeated in a face, a directed edge the mesh has, one used twice in the batch,
    /// an edge that would get a third face, a vertex out of range.
    #[test]
    fn bad_batches_are_errors_and_change_nothing() {
        let (mut m, hole) = grid_with_hole();
        let k = hole.len();
        let c = m.add_vertex(DVec3::new(2.0, 1.5, 0.0), None);
        let rim = |i: usize| [hole[i], hole[(i + 1) % k], c];
        // the reverse of a rim edge: a directed edge the mesh already has
        let reversed = [hole[1], hole[0], c];
        let cases: Vec<(Vec<[VertexId; 3]>, TopologyError)> = vec![
            (
                vec![rim(0), [hole[1], hole[1], c]],
                TopologyError::NewFaceRepeatsVertex(1),
            ),
            (
                vec![rim(0), reversed],
                TopologyError::DirectedEdgeTaken(hole[1], hole[0]),
            ),
            (
                vec![rim(0), rim(1), rim(0)],
                TopologyError::DirectedEdgeTaken(hole[0], hole[1]),
            ),
            (
                vec![[hole[0], hole[1], VertexId(9999)]],
                TopologyError::VertexOutOfRange(VertexId(9999)),
            ),
        ];
        for (batch, want) in cases {
            let mut t = m.clone();
            let e = t.add_faces(&batch).unwrap_err();
            assert_eq!(e, want);
            assert_eq!(t.topo.faces(), m.topo.faces());
            assert_eq!(t.topo.boundary_loops(), m.topo.boundary_loops());
            t.validate().unwrap();
        }
        // a face on an interior edge (a face on each side already), either way round
        let mut inner = None;
        'find: for f in m.topo.faces() {
            for c2 in 0..3 {
                let (u, v) = (f[c2], f[(c2 + 1) % 3]);
                let both = m
                    .topo
                    .outgoing(u)
                    .any(|h| m.topo.to(h) == v && m.topo.twin(h).is_some());
                if both {
                    inner = Some((u, v));
                    break 'find;
                }
            }
        }
        let (u, v) = inner.unwrap();
        let mut t = m.clone();
        let w = t.add_vertex(DVec3::new(9.0, 9.0, 1.0), None);
        for face in [[v, u, w], [u, v, w]] {
            let e = t.add_faces(&[face]).unwrap_err();
            assert_eq!(e, TopologyError::DirectedEdgeTaken(face[0], face[1]));
            assert_eq!(t.topo.faces(), m.topo.faces());
        }
        t.validate().unwrap();
    }
}
