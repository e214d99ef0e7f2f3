//! Boundary cleaning before filling, when the policy asks for it (section `[clean]`):
//! tooth faces removed, long boundary edges split (ALGORITHMS A2, paper 003 §3.1).
//! Both change input faces; both keep every input vertex where it is.

use crate::io::RawMesh;
use crate::mesh::{FaceId, Mesh};

/// Removes tooth faces (two edges on the boundary) until none is left, never
/// removing the last faces of a component (ALGORITHMS A2).
pub fn remove_teeth(mut mesh: Mesh) -> (Mesh, usize) {
    let mut removed = 0;
    for _round in 0..8 {
        let comp = components(&mesh);
        let ncomp = comp.iter().copied().max().map_or(0, |m| m + 1);
        let mut size = vec![0usize; ncomp];
        for &c in &comp {
            size[c] += 1;
        }
        let mut teeth_of = vec![0usize; ncomp];
        let mut teeth: Vec<FaceId> = Vec::new();
        for f in 0..mesh.num_faces() {
            let f = FaceId::from_idx(f);
            let open = (0..3)
                .filter(|&c| mesh.topo.twin(f.halfedge(c)).is_none())
                .count();
            if open == 2 {
                teeth.push(f);
                teeth_of[comp[f.idx()]] += 1;
            }
        }
        // keep components that are all teeth (a strip, a lone pair of triangles)
        teeth.retain(|f| teeth_of[comp[f.idx()]] < size[comp[f.idx()]]);
        if teeth.is_empty() {
            break;
        }
        removed += teeth.len();
        let (m, _) = mesh.without_faces(&teeth);
        mesh = m;
    }
    (mesh, removed)
}

/// Splits boundary edges longer than `factor` times their loop's mean boundary edge
/// length at their midpoint, splitting the one triangle on each (ALGORITHMS A2,
/// paper 003 §3.1), until no edge changes. Returns the number of splits.
pub fn split_long_edges(mesh: &mut Mesh, factor: f64) -> usize {
    let mut total = 0;
    for _round in 0..16 {
        let mut splits: Vec<(FaceId, usize)> = Vec::new();
        for lp in mesh.topo.boundary_loops() {
            let k = lp.len();
            if k < 3 {
                continue;
            }
            let len = |i: usize| (mesh.pos(lp[(i + 1) % k]) - mesh.pos(lp[i])).length();
            let mean = (0..k).map(len).sum::<f64>() / k as f64;
            for i in 0..k {
                if len(i) > factor * mean {
                    // the face half-edge runs lp[i+1] -> lp[i]
                    if let Some(h) = mesh.topo.incoming_boundary(lp[i]) {
                        if mesh.topo.from(h) == lp[(i + 1) % k] {
                            splits.push((h.face(), h.corner()));
                        }
                    }
                }
            }
        }
        // one split per face per round
        splits.sort_unstable_by_key(|s| s.0);
        splits.dedup_by_key(|s| s.0);
        if splits.is_empty() {
            break;
        }
        total += splits.len();
        let mut faces: Vec<[u32; 3]> = mesh.topo.faces().iter().map(|f| f.map(|v| v.0)).collect();
        let mut positions = mesh.positions.clone();
        let mut colors = mesh.colors.clone();
        let mut origin = mesh.origin.clone();
        for &(f, c) in &splits {
            let t = faces[f.idx()];
            let (a, b, o) = (t[c], t[(c + 1) % 3], t[(c + 2) % 3]);
            let m = positions.len() as u32;
            positions.push((positions[a as usize] + positions[b as usize]) * 0.5);
            if let Some(cs) = colors.as_mut() {
                let (ca, cb) = (cs[a as usize], cs[b as usize]);
                cs.push([0, 1, 2].map(|i| (ca[i] + cb[i]) * 0.5));
            }
            origin.push(None);
            faces[f.idx()] = [a, m, o];
            faces.push([m, b, o]);
        }
        let raw = RawMesh {
            positions,
            colors,
            faces,
            ..Default::default()
        };
        let (mut m, _) = Mesh::from_raw(&raw);
        for (i, o) in origin.into_iter().enumerate().take(m.origin.len()) {
            m.origin[i] = o;
        }
        m.input_vertices = mesh.input_vertices;
        *mesh = m;
    }
    total
}

/// Connected component of every face (through twins).
pub fn components(mesh: &Mesh) -> Vec<usize> {
    let nf = mesh.num_faces();
    let mut comp = vec![usize::MAX; nf];
    let mut stack = Vec::new();
    let mut next = 0;
    for s in 0..nf {
        if comp[s] != usize::MAX {
            continue;
        }
        comp[s] = next;
        stack.push(s);
        while let Some(f) = stack.pop() {
            for c in 0..3 {
                if let Some(t) = mesh.topo.twin(FaceId::from_idx(f).halfedge(c)) {
                    let g = t.face().idx();
                    if comp[g] == usize::MAX {
                        comp[g] = next;
                        stack.push(g);
                    }
                }
            }
        }
        next += 1;
    }
    comp
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::VertexId;
    use glam::DVec3;

    fn soup(pos: &[[f64; 2]], faces: &[[u32; 3]]) -> RawMesh {
        RawMesh {
            positions: pos.iter().map(|p| DVec3::new(p[0], p[1], 0.0)).collect(),
            faces: faces.to_vec(),
            ..Default::default()
        }
    }

    #[test]
    fn long_boundary_edges_are_split_until_none_is_long() {
        // A(0,0) B(4,0) C(4,1) D(0,1) E(1,1) F(2,1) G(3,1): edge A-B is long
        let raw = soup(
            &[
                [0., 0.],
                [4., 0.],
                [4., 1.],
                [0., 1.],
                [1., 1.],
                [2., 1.],
                [3., 1.],
            ],
            &[[0, 1, 6], [0, 6, 5], [0, 5, 4], [0, 4, 3], [1, 2, 6]],
        );
        let (mut m, _) = Mesh::from_raw(&raw);
        let n = split_long_edges(&mut m, 2.0);
        m.validate().unwrap();
        assert_eq!(n, 1);
        assert_eq!(m.num_faces(), 6);
        assert_eq!(m.pos(VertexId(7)), DVec3::new(2.0, 0.0, 0.0));
        assert_eq!(m.origin[7], None);
        // input vertices untouched
        for i in 0..7 {
            assert_eq!(m.pos(VertexId(i)), raw.positions[i as usize]);
        }
    }

    #[test]
    fn teeth_are_removed_but_never_a_whole_component() {
        // a 2x1 grid of quads with a tooth on its top edge, plus a lone pair of triangles
        let raw = soup(
            &[
                [0., 0.],
                [1., 0.],
                [2., 0.],
                [0., 1.],
                [1., 1.],
                [2., 1.],
                [1.5, 2.],
                [5., 5.],
                [6., 5.],
                [6., 6.],
                [5., 6.],
            ],
            &[
                [0, 1, 4],
                [0, 4, 3],
                [1, 2, 5],
                [1, 5, 4],
                [4, 5, 6], // tooth
                [7, 8, 9],
                [7, 9, 10],
            ],
        );
        let (m, _) = Mesh::from_raw(&raw);
        let (m, removed) = remove_teeth(m);
        m.validate().unwrap();
        // the tooth goes; then corner triangles of the grid become teeth too and go,
        // but each component keeps faces
        assert!(removed >= 1);
        assert!(m.num_faces() >= 3, "{} faces left", m.num_faces());
        let comp = components(&m);
        assert_eq!(
            comp.iter().max().copied(),
            Some(1),
            "both components survive"
        );
    }
}
