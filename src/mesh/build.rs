//! Building the half-edge mesh from a triangle soup, resolving what real scans carry:
//! degenerate and duplicate faces, edges with three or more faces, inconsistent
//! orientation and non-manifold vertices. Nothing here panics on bad input; what was
//! resolved is counted in [`BuildReport`].

use super::{group_by_key, HalfedgeId, Mesh, Topology, VertexId};
use crate::io::RawMesh;
use serde::Serialize;

/// What the builder resolved in the input.
#[derive(Clone, Debug, Default, Serialize, PartialEq, Eq)]
pub struct BuildReport {
    /// Faces dropped because a vertex index repeats.
    pub repeated_index_faces: usize,
    /// Faces dropped because their three corners are collinear (exactly zero area).
    pub zero_area_faces: usize,
    /// Faces dropped because the same three vertices already form a face.
    pub duplicate_faces: usize,
    /// Faces dropped because an index is out of range.
    pub out_of_range_faces: usize,
    /// Edges shared by three or more faces; the extra faces were detached there.
    pub non_manifold_edges: usize,
    /// Edges left open because their two faces could not be oriented consistently.
    pub orientation_cuts: usize,
    /// Faces whose orientation was reversed to agree with their component.
    pub flipped_faces: usize,
    /// Vertices whose faces formed several fans; each extra fan got a copy.
    pub non_manifold_vertices: usize,
    /// Vertex copies appended by those splits.
    pub vertices_added_by_split: usize,
    /// Vertices used by no face (kept in the output, untouched).
    pub isolated_vertices: usize,
}

impl BuildReport {
    /// True when the input needed no resolution at all.
    pub fn is_clean(&self) -> bool {
        *self
            == BuildReport {
                isolated_vertices: self.isolated_vertices,
                ..Default::default()
            }
    }
}

impl Mesh {
    /// Builds a mesh from a triangle soup.
    pub fn from_raw(raw: &RawMesh) -> (Mesh, BuildReport) {
        let mut rep = BuildReport::default();
        let nv = raw.positions.len();

        // 1. drop faces that cannot be triangles
        let mut faces: Vec<[u32; 3]> = Vec::with_capacity(raw.faces.len());
        for f in &raw.faces {
            if f.iter().any(|&i| i as usize >= nv) {
                rep.out_of_range_faces += 1;
                continue;
            }
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                rep.repeated_index_faces += 1;
                continue;
            }
            let [a, b, c] = f.map(|i| raw.positions[i as usize]);
            if (b - a).cross(c - a) == glam::DVec3::ZERO {
                rep.zero_area_faces += 1;
                continue;
            }
            faces.push(*f);
        }
        // duplicates (the same three vertices, any order): the first one is kept.
        // Faces grouped by their smallest vertex (a counting sort, no hashing), then
        // each group sorted by its vertex triple and face number.
        let sorted = |f: [u32; 3]| {
            let mut k = f;
            k.sort_unstable();
            k
        };
        let mut dup = vec![false; faces.len()];
        {
            let (off, mut group) = group_by_key(nv, faces.len(), |i| {
                faces[i].iter().copied().min().unwrap_or(0) as usize
            });
            for v in 0..nv {
                let g = &mut group[off[v] as usize..off[v + 1] as usize];
                if g.len() < 2 {
                    continue;
                }
                g.sort_unstable_by_key(|&i| (sorted(faces[i as usize]), i));
                for w in g.windows(2) {
                    if sorted(faces[w[0] as usize]) == sorted(faces[w[1] as usize]) {
                        dup[w[1] as usize] = true;
                    }
                }
            }
        }
        rep.duplicate_faces = dup.iter().filter(|&&d| d).count();
        if rep.duplicate_faces > 0 {
            let mut k = 0;
            faces.retain(|_| {
                k += 1;
                !dup[k - 1]
            });
        }
        drop(dup);
        faces.shrink_to_fit();
        let nf = faces.len();

        // 2. pair half-edges by undirected edge: half-edges grouped by their smaller
        // vertex (a counting sort), each group sorted by the larger vertex and the
        // half-edge number, so equal edges are adjacent in (edge, half-edge) order
        let from = |faces: &Vec<[u32; 3]>, h: u32| faces[(h / 3) as usize][(h % 3) as usize];
        let to =
            |faces: &Vec<[u32; 3]>, h: u32| faces[(h / 3) as usize][((h % 3 + 1) % 3) as usize];
        let (off, mut halfedges) = group_by_key(nv, nf * 3, |h| {
            from(&faces, h as u32).min(to(&faces, h as u32)) as usize
        });
        // candidate pairs (h1, h2), not yet checked for orientation
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(nf * 3 / 2);
        for v in 0..nv {
            let g = &mut halfedges[off[v] as usize..off[v + 1] as usize];
            g.sort_unstable_by_key(|&h| (from(&faces, h).max(to(&faces, h)), h));
            let far = |h: u32| from(&faces, h).max(to(&faces, h));
            let mut i = 0;
            while i < g.len() {
                let mut j = i + 1;
                while j < g.len() && far(g[j]) == far(g[i]) {
                    j += 1;
                }
                let group = &g[i..j];
                if group.len() == 2 {
                    pairs.push((group[0], group[1]));
                } else if group.len() > 2 {
                    rep.non_manifold_edges += 1;
                    // keep the first pair of opposite direction (else the first two)
                    let h0 = group[0];
                    let opp = group[1..]
                        .iter()
                        .find(|&&g| from(&faces, g) != from(&faces, h0))
                        .copied()
                        .unwrap_or(group[1]);
                    pairs.push((h0, opp));
                }
                i = j;
            }
        }
        drop(halfedges);
        drop(off);

        // 3. orient: breadth-first over the pairs, flipping faces to agree. When every
        // pair already runs in opposite directions (a consistently oriented input, the
        // usual case) the search would flip nothing and cut nothing: skipped.
        let consistent = pairs
            .iter()
            .all(|&(a, b)| from(&faces, a) != from(&faces, b));
        let mut flip: Vec<Option<bool>> = vec![consistent.then_some(false); nf];
        let mut cut = vec![false; pairs.len()];
        if !consistent {
            let mut adj_start = vec![0u32; nf + 1];
            for &(a, b) in &pairs {
                adj_start[(a / 3) as usize + 1] += 1;
                adj_start[(b / 3) as usize + 1] += 1;
            }
            for k in 0..nf {
                adj_start[k + 1] += adj_start[k];
            }
            let mut fill = adj_start.clone();
            let mut adj = vec![0u32; adj_start[nf] as usize]; // pair index
            for (pi, &(a, b)) in pairs.iter().enumerate() {
                for h in [a, b] {
                    let f = (h / 3) as usize;
                    adj[fill[f] as usize] = pi as u32;
                    fill[f] += 1;
                }
            }
            drop(fill);
            let mut queue = std::collections::VecDeque::new();
            let mut component: Vec<usize> = Vec::new();
            for seed in 0..nf {
                if flip[seed].is_some() {
                    continue;
                }
                flip[seed] = Some(false);
                queue.push_back(seed);
                component.clear();
                while let Some(f) = queue.pop_front() {
                    component.push(f);
                    let ff = flip[f].unwrap_or(false);
                    for k in adj_start[f]..adj_start[f + 1] {
                        let pi = adj[k as usize] as usize;
                        if cut[pi] {
                            continue;
                        }
                        let (a, b) = pairs[pi];
                        let (mine, other) = if (a / 3) as usize == f {
                            (a, b)
                        } else {
                            (b, a)
                        };
                        let g = (other / 3) as usize;
                        let same_dir = from(&faces, mine) == from(&faces, other);
                        // after flips the two must run in opposite directions
                        let want = ff ^ same_dir;
                        match flip[g] {
                            None => {
                                flip[g] = Some(want);
                                queue.push_back(g);
                            }
                            Some(x) if x != want => {
                                cut[pi] = true;
                                rep.orientation_cuts += 1;
                            }
                            _ => {}
                        }
                    }
                }
                // keep the orientation most of the component already has
                let flipped = component.iter().filter(|&&f| flip[f] == Some(true)).count();
                if flipped * 2 > component.len() {
                    for &f in &component {
                        flip[f] = flip[f].map(|x| !x);
                    }
                }
            }
        }
        // room for the patches that will close the holes, so that filling appends
        // without moving the arrays (a move copies the whole mesh inside the fill
        // time): a round hole of k edges takes about k^2 / (pi sqrt 3) = 0.18 k^2
        // triangles at its own edge length (the bunny scan's holes 0.09 to 0.25 k^2),
        // so room for b^2 / 4 over the b boundary edges (or 8 b, the most a hole of
        // fewer than 32 edges takes), at most a quarter of the mesh more. Room is
        // address space: the pages of the part never filled are never touched.
        let paired = pairs.iter().enumerate().filter(|&(i, _)| !cut[i]).count();
        let boundary = (nf * 3).saturating_sub(2 * paired);
        let room_faces = boundary
            .saturating_mul(boundary)
            .div_ceil(4)
            .max(boundary.saturating_mul(8))
            .min(nf / 4 + 64);
        let room_vertices = room_faces / 2 + 8;
        let mut out_faces: Vec<[VertexId; 3]> = Vec::with_capacity(nf + room_faces);
        for (fi, f) in faces.iter().enumerate() {
            if flip[fi] == Some(true) {
                rep.flipped_faces += 1;
                out_faces.push([VertexId(f[0]), VertexId(f[2]), VertexId(f[1])]);
            } else {
                out_faces.push(f.map(VertexId));
            }
        }
        drop(faces);
        let find =
            |faces: &Vec<[VertexId; 3]>, f: usize, a: VertexId, b: VertexId| -> Option<u32> {
                (0..3)
                    .find(|&c| faces[f][c] == a && faces[f][(c + 1) % 3] == b)
                    .map(|c| (f * 3 + c) as u32)
            };
        let mut twin: Vec<Option<HalfedgeId>> = Vec::with_capacity((nf + room_faces) * 3);
        twin.resize(nf * 3, None);
        for (pi, &(a, b)) in pairs.iter().enumerate() {
            if cut[pi] {
                continue;
            }
            let fa = (a / 3) as usize;
            let fb = (b / 3) as usize;
            let u = out_faces[fa][(a % 3) as usize];
            let w = out_faces[fa][((a % 3 + 1) % 3) as usize];
            // after flipping, locate the half-edges of the shared edge in each face
            let (ha, hb) = match (find(&out_faces, fa, u, w), find(&out_faces, fb, w, u)) {
                (Some(x), Some(y)) => (x, y),
                _ => match (find(&out_faces, fa, w, u), find(&out_faces, fb, u, w)) {
                    (Some(x), Some(y)) => (x, y),
                    _ => continue,
                },
            };
            twin[ha as usize] = Some(HalfedgeId(ha));
            twin[hb as usize] = Some(HalfedgeId(hb));
            twin[ha as usize] = Some(HalfedgeId(hb));
            twin[hb as usize] = Some(HalfedgeId(ha));
        }
        drop(pairs);

        // 4. split vertices with several fans
        let mut positions = Vec::with_capacity(nv + room_vertices);
        positions.extend_from_slice(&raw.positions);
        let mut colors = raw.colors.as_ref().map(|c| {
            let mut v = Vec::with_capacity(nv + room_vertices);
            v.extend_from_slice(c);
            v.resize(nv, [0.5, 0.5, 0.5]);
            v
        });
        let mut origin: Vec<Option<VertexId>> = Vec::with_capacity(nv + room_vertices);
        origin.extend((0..nv).map(|i| Some(VertexId::from_idx(i))));
        let mut anchor: Vec<Option<HalfedgeId>> = Vec::with_capacity(nv + room_vertices);
        anchor.resize(nv, None);
        let mut visited = vec![false; nf * 3];
        let mut topo = Topology {
            faces: out_faces,
            twin,
            anchor: Vec::new(),
        };
        let mut fan: Vec<HalfedgeId> = Vec::new();
        let mut split_vertices = vec![false; nv];
        for hi in 0..nf * 3 {
            if visited[hi] {
                continue;
            }
            let h0 = HalfedgeId::from_idx(hi);
            let v = topo.from(h0);
            // walk back to the fan's boundary start (or all the way round)
            let mut start = h0;
            let mut guard = 0;
            while let Some(p) = topo.prev_outgoing(start) {
                if p == h0 || guard > nf * 3 {
                    break;
                }
                start = p;
                guard += 1;
            }
            fan.clear();
            let mut h = start;
            loop {
                fan.push(h);
                match topo.next_outgoing(h) {
                    Some(n) if n != start && fan.len() <= nf * 3 => h = n,
                    _ => break,
                }
            }
            for &g in &fan {
                visited[g.0 as usize] = true;
            }
            let target = if anchor[v.idx()].is_none() {
                anchor[v.idx()] = Some(start);
                v
            } else {
                // a further fan: give it its own copy of the vertex
                if !split_vertices[v.idx()] {
                    split_vertices[v.idx()] = true;
                    rep.non_manifold_vertices += 1;
                }
                rep.vertices_added_by_split += 1;
                let nvid = VertexId::from_idx(positions.len());
                positions.push(positions[v.idx()]);
                if let Some(c) = colors.as_mut() {
                    let col = c[v.idx()];
                    c.push(col);
                }
                origin.push(Some(v));
                anchor.push(Some(start));
                nvid
            };
            if target != v {
                for &g in &fan {
                    let f = g.face().idx();
                    topo.faces[f][g.corner()] = target;
                }
            }
        }
        rep.isolated_vertices = anchor[..nv].iter().filter(|a| a.is_none()).count();
        topo.anchor = anchor;
        (
            Mesh {
                topo,
                positions,
                colors,
                origin,
                input_vertices: nv,
            },
            rep,
        )
    }

    /// The mesh as a triangle soup: input vertices first in their order, then the
    /// vertices added by splitting and filling; faces in mesh order.
    pub fn to_raw(&self, template: &RawMesh) -> RawMesh {
        RawMesh {
            positions: self.positions.clone(),
            colors: self.colors.clone(),
            faces: self.topo.faces().iter().map(|f| f.map(|v| v.0)).collect(),
            precision: template.precision,
            encoding: template.encoding,
            notes: Vec::new(),
            attrs: Default::default(),
        }
    }

    /// Rebuilds the mesh without the given faces (boundary cleaning). Vertex ids are
    /// kept; faces are renumbered.
    pub fn without_faces(&self, remove: &[super::FaceId]) -> (Mesh, BuildReport) {
        let mut drop_f = vec![false; self.num_faces()];
        for f in remove {
            drop_f[f.idx()] = true;
        }
        let raw = RawMesh {
            positions: self.positions.clone(),
            colors: self.colors.clone(),
            faces: self
                .topo
                .faces()
                .iter()
                .enumerate()
                .filter(|(i, _)| !drop_f[*i])
                .map(|(_, f)| f.map(|v| v.0))
                .collect(),
            ..Default::default()
        };
        let (mut m, rep) = Mesh::from_raw(&raw);
        // keep provenance of earlier splits
        for (i, o) in m.origin.iter_mut().enumerate() {
            if i < self.origin.len() {
                *o = self.origin[i];
            } else if let Some(src) = o {
                *o = self.origin.get(src.idx()).copied().flatten();
            }
        }
        m.input_vertices = self.input_vertices;
        (m, rep)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn soup(pos: &[[f64; 3]], faces: &[[u32; 3]]) -> RawMesh {
        RawMesh {
            positions: pos.iter().map(|p| DVec3::from_array(*p)).collect(),
            faces: faces.to_vec(),
            ..Default::default()
        }
    }

    #[test]
    fn resolves_degenerate_duplicate_and_flipped_faces() {
        let raw = soup(
            &[
                [0., 0., 0.],
                [1., 0., 0.],
                [1., 1., 0.],
                [0., 1., 0.],
                [2., 0., 0.],
            ],
            &[
                [0, 1, 2],
                [0, 2, 3],
                [2, 1, 0], // duplicate (other orientation)
                [0, 0, 1], // repeated index
                [0, 1, 4], // collinear
                [1, 3, 2], // wrong orientation? shares 1-2 ... with same direction as face 0? no
                [0, 1, 9], // out of range
            ],
        );
        let (m, rep) = Mesh::from_raw(&raw);
        m.validate().unwrap();
        assert_eq!(rep.duplicate_faces, 1);
        assert_eq!(rep.repeated_index_faces, 1);
        assert_eq!(rep.zero_area_faces, 1);
        assert_eq!(rep.out_of_range_faces, 1);
        assert_eq!(rep.isolated_vertices, 1);
    }

    #[test]
    fn flips_an_inconsistent_face() {
        // faces 0 and 1 share edge 0-2 wound the same way; face 2 agrees with face 0
        let raw = soup(
            &[
                [0., 0., 0.],
                [1., 0., 0.],
                [1., 1., 0.],
                [0., 1., 0.],
                [0.5, -1., 0.],
            ],
            &[[0, 1, 2], [0, 3, 2], [1, 0, 4]],
        );
        let (m, rep) = Mesh::from_raw(&raw);
        m.validate().unwrap();
        assert_eq!(rep.flipped_faces, 1);
        assert_eq!(
            m.topo.face(crate::mesh::FaceId(1)),
            [VertexId(0), VertexId(2), VertexId(3)]
        );
        assert_eq!(m.topo.boundary_loops().len(), 1);
    }

    #[test]
    fn splits_bowtie_vertex_and_non_manifold_edge() {
        // two triangles touching at vertex 0 only
        let raw = soup(
            &[
                [0., 0., 0.],
                [1., 0., 0.],
                [1., 1., 0.],
                [-1., 0., 0.],
                [-1., -1., 0.],
            ],
            &[[0, 1, 2], [0, 3, 4]],
        );
        let (m, rep) = Mesh::from_raw(&raw);
        m.validate().unwrap();
        assert_eq!(rep.non_manifold_vertices, 1);
        assert_eq!(m.num_vertices(), 6);
        assert_eq!(m.origin[5], Some(VertexId(0)));
        assert_eq!(m.topo.boundary_loops().len(), 2);

        // three triangles on edge 0-1
        let raw = soup(
            &[
                [0., 0., 0.],
                [1., 0., 0.],
                [0.5, 1., 0.],
                [0.5, -1., 0.],
                [0.5, 0., 1.],
            ],
            &[[0, 1, 2], [1, 0, 3], [0, 1, 4]],
        );
        let (m, rep) = Mesh::from_raw(&raw);
        m.validate().unwrap();
        assert_eq!(rep.non_manifold_edges, 1);
    }
}
