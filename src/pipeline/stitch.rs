//! Cracks, not holes: boundary vertices that coincide with another
//! boundary vertex (of another loop or of the same loop: a slit) are identified, so
//! that the crack is zipped shut instead of filled. This also closes the loops of zero
//! area the builder leaves where it split a pinched or non-manifold vertex into copies
//! at the same position.
//!
//! How the words are read:
//! - "coincide": the same position, or closer than `crack.tolerance` times the smaller
//!   of the two vertices' local edge lengths (the mean of their two boundary edges);
//!   vertices that share an edge are never identified (the edge would collapse);
//! - "zipped": the later vertex of a pair is identified onto the earlier one (the
//!   smaller index): the faces of the later one take the earlier index; no input
//!   vertex is moved or renumbered, the later vertex stays in the output unreferenced.
//!   No face is added;
//! - an identification is kept only when the result is an oriented manifold with no
//!   face collapsed or turned over: every vertex touched has one fan (each directed
//!   edge once, no face twice); classes that break this are left apart, until what
//!   remains is sound, and the rebuilt mesh must come out of the builder unchanged.
//!
//! A loop all of whose vertices leave the boundary is reported `stitched`; a loop
//! only partly zipped remains a (smaller) hole and is filled.

use crate::io::RawMesh;
use crate::mesh::{FaceId, Mesh, VertexId};

/// What stitching did.
pub struct Stitched {
    /// The mesh with the cracks zipped.
    pub mesh: Mesh,
    /// Vertices identified onto an earlier vertex (now unreferenced).
    pub vertices_merged: usize,
    /// Faces whose corners changed.
    pub faces_changed: usize,
    /// The boundary loops (of the mesh before) that stitching closed completely, with
    /// the number of their vertices identified.
    pub closed: Vec<(Vec<VertexId>, usize)>,
}

/// Union-find over vertex indices; the root of a class is its smallest index.
struct Classes(Vec<u32>);

impl Classes {
    fn find(&mut self, v: u32) -> u32 {
        let mut x = v;
        while self.0[x as usize] != x {
            let p = self.0[x as usize];
            self.0[x as usize] = self.0[p as usize];
            x = p;
        }
        x
    }
    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (lo, hi) = (ra.min(rb), ra.max(rb));
            self.0[hi as usize] = lo;
        }
    }
}

/// True when the faces around `w` (each containing `w`) form one fan: each neighbour
/// follows at most one other, no two faces over the same three vertices, and one walk
/// visits them all.
fn one_fan(w: VertexId, faces: &[[VertexId; 3]]) -> bool {
    let mut link: Vec<(VertexId, VertexId)> = Vec::with_capacity(faces.len());
    for f in faces {
        let Some(c) = f.iter().position(|&x| x == w) else {
            return false;
        };
        let (x, y) = (f[(c + 1) % 3], f[(c + 2) % 3]);
        if x == w || y == w || x == y {
            return false;
        }
        // the same directed edge w->x (or y->w) twice, or the same face reversed
        if link
            .iter()
            .any(|&(a, b)| a == x || b == y || (a == y && b == x))
        {
            return false;
        }
        link.push((x, y));
    }
    if link.is_empty() {
        return true;
    }
    // start at a link vertex nothing leads to (the fan's boundary), else anywhere
    let start = link
        .iter()
        .find(|&&(a, _)| !link.iter().any(|&(_, b)| b == a))
        .map_or(link[0].0, |&(a, _)| a);
    let mut at = start;
    let mut steps = 0;
    while let Some(&(_, b)) = link.iter().find(|&&(a, _)| a == at) {
        steps += 1;
        at = b;
        if at == start || steps > link.len() {
            break;
        }
    }
    steps == link.len()
}

/// Zips the cracks of `mesh` (see the module doc); `None` when nothing coincides or
/// no identification is sound.
pub fn stitch(mesh: &Mesh, tolerance: f64) -> Option<Stitched> {
    let loops = mesh.topo.boundary_loops();
    // boundary vertices with their reach (tolerance times the local edge length)
    let mut bv: Vec<(VertexId, f64)> = Vec::new();
    for lp in &loops {
        let k = lp.len();
        for i in 0..k {
            let p = mesh.pos(lp[i]);
            let a = (mesh.pos(lp[(i + k - 1) % k]) - p).length();
            let b = (mesh.pos(lp[(i + 1) % k]) - p).length();
            bv.push((lp[i], tolerance * 0.5 * (a + b)));
        }
    }
    if bv.len() < 2 {
        return None;
    }
    bv.sort_unstable_by(|a, b| mesh.pos(a.0).x.total_cmp(&mesh.pos(b.0).x));
    let reach = bv.iter().map(|b| b.1).fold(0.0f64, f64::max);
    let mut classes = Classes((0..mesh.num_vertices() as u32).collect());
    let mut any = false;
    for i in 0..bv.len() {
        let (u, ru) = bv[i];
        let pu = mesh.pos(u);
        for &(v, rv) in &bv[i + 1..] {
            let pv = mesh.pos(v);
            if pv.x - pu.x > reach {
                break;
            }
            if u == v || (pv - pu).length() > ru.min(rv) {
                continue;
            }
            if mesh.topo.neighbors(u).contains(&v) {
                continue;
            }
            classes.union(u.0, v.0);
            any = true;
        }
    }
    if !any {
        return None;
    }
    // the members of classes of two or more (every member is a boundary vertex), and
    // the root of each; `active`: the classes still identified
    let mut root: Vec<(VertexId, u32)> = bv.iter().map(|b| (b.0, classes.find(b.0 .0))).collect();
    root.sort_unstable_by_key(|r| (r.1, r.0));
    let size = |r: u32, root: &[(VertexId, u32)]| {
        root.partition_point(|x| x.1 <= r) - root.partition_point(|x| x.1 < r)
    };
    let keep: Vec<bool> = root.iter().map(|r| size(r.1, &root) > 1).collect();
    let mut k = 0;
    root.retain(|_| {
        k += 1;
        keep[k - 1]
    });
    let members: Vec<VertexId> = root.iter().map(|r| r.0).collect();
    root.sort_unstable();
    let root_of = |v: VertexId| -> Option<u32> {
        root.binary_search_by_key(&v, |r| r.0)
            .ok()
            .map(|i| root[i].1)
    };
    let mut active: Vec<u32> = root.iter().map(|r| r.1).collect();
    active.sort_unstable();
    active.dedup();
    loop {
        let is_active = |r: u32| active.binary_search(&r).is_ok();
        let map = |v: VertexId| match root_of(v) {
            Some(r) if is_active(r) => VertexId(r),
            _ => v,
        };
        let mut affected: Vec<FaceId> = members
            .iter()
            .filter(|&&v| root_of(v).is_some_and(is_active))
            .flat_map(|&v| mesh.topo.vertex_faces(v).collect::<Vec<_>>())
            .collect();
        affected.sort_unstable();
        affected.dedup();
        let mut bad: Vec<u32> = Vec::new();
        let roots_in = |f: &[VertexId; 3]| -> Vec<u32> {
            f.iter()
                .filter_map(|&v| root_of(v).filter(|&r| is_active(r)))
                .collect()
        };
        // each vertex of a changed face, with its faces as they would be
        let mut around: Vec<(VertexId, [VertexId; 3], FaceId)> = Vec::new();
        for &f in &affected {
            let orig = mesh.topo.face(f);
            let m = orig.map(map);
            let [a, b, c] = m.map(|v| mesh.pos(v));
            let n = (b - a).cross(c - a);
            if m[0] == m[1] || m[1] == m[2] || m[0] == m[2] || n.dot(mesh.face_normal_raw(f)) <= 0.0
            {
                bad.extend(roots_in(&orig));
                continue;
            }
            for &w in &m {
                around.push((w, m, f));
            }
        }
        around.sort_unstable_by_key(|a| (a.0, a.2));
        let mut i = 0;
        while i < around.len() {
            let w = around[i].0;
            let mut j = i;
            while j < around.len() && around[j].0 == w {
                j += 1;
            }
            let mut faces: Vec<[VertexId; 3]> = around[i..j].iter().map(|a| a.1).collect();
            // the faces of `w` that do not change (none when `w` is a merged class)
            for g in mesh.topo.vertex_faces(w) {
                if affected.binary_search(&g).is_err() {
                    faces.push(mesh.topo.face(g));
                }
            }
            if !one_fan(w, &faces) {
                match root_of(w).filter(|&r| is_active(r) && r == w.0) {
                    Some(r) => bad.push(r),
                    None => {
                        for a in &around[i..j] {
                            bad.extend(roots_in(&mesh.topo.face(a.2)));
                        }
                    }
                }
            }
            i = j;
        }
        if bad.is_empty() {
            break;
        }
        bad.sort_unstable();
        bad.dedup();
        active.retain(|r| bad.binary_search(r).is_err());
        if active.is_empty() {
            return None;
        }
    }
    let is_active = |r: u32| active.binary_search(&r).is_ok();
    let map = |v: VertexId| match root_of(v) {
        Some(r) if is_active(r) => VertexId(r),
        _ => v,
    };
    let mut faces_changed = 0;
    let faces: Vec<[u32; 3]> = mesh
        .topo
        .faces()
        .iter()
        .map(|f| {
            let m = f.map(map);
            if m != *f {
                faces_changed += 1;
            }
            m.map(|v| v.0)
        })
        .collect();
    let vertices_merged = root
        .iter()
        .filter(|&&(v, r)| is_active(r) && v.0 != r)
        .count();
    let m = rebuild_clean(mesh, faces)?;
    let closed = loops
        .into_iter()
        .filter_map(|lp| {
            let merged = lp
                .iter()
                .filter(|&&v| root_of(v).is_some_and(is_active))
                .count();
            let shut = merged > 0 && lp.iter().all(|&v| !m.topo.is_boundary_vertex(map(v)));
            shut.then_some((lp, merged))
        })
        .collect();
    Some(Stitched {
        mesh: m,
        vertices_merged,
        faces_changed,
        closed,
    })
}

/// `mesh` with its faces replaced by `faces` (vertices identified: some renamed to
/// others at the same place), the origins and input count carried over. `None` unless
/// the builder finds nothing to resolve but the vertices identified away (isolated)
/// and keeps every face.
pub(super) fn rebuild_clean(mesh: &Mesh, faces: Vec<[u32; 3]>) -> Option<Mesh> {
    let n = faces.len();
    let raw = RawMesh {
        positions: mesh.positions.clone(),
        colors: mesh.colors.clone(),
        faces,
        ..Default::default()
    };
    let (mut m, rep) = Mesh::from_raw(&raw);
    let clean = crate::mesh::BuildReport {
        isolated_vertices: rep.isolated_vertices,
        ..Default::default()
    };
    if rep != clean || m.num_faces() != n {
        return None;
    }
    m.origin.clone_from(&mesh.origin);
    m.input_vertices = mesh.input_vertices;
    Some(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{split_along, unit_grid};
    use glam::DVec3;

    /// A 6x6 grid cut along x = 3 into two halves with their own vertices on the cut
    /// (a crack): the right half's copies of the cut vertices are appended, shifted by
    /// `gap` in x.
    fn cracked(gap: f64) -> RawMesh {
        split_along(
            unit_grid(6),
            |p| p.x == 3.0,
            DVec3::new(gap, 0.0, 0.0),
            |c| c.x > 3.0,
        )
    }

    #[test]
    fn a_crack_of_coincident_vertices_is_zipped() {
        let raw = cracked(0.0);
        let (m, _) = Mesh::from_raw(&raw);
        assert_eq!(m.topo.boundary_loops().len(), 2);
        let s = stitch(&m, 0.0).expect("stitched");
        s.mesh.validate().unwrap();
        assert_eq!(s.vertices_merged, 7);
        assert_eq!(
            s.mesh.topo.boundary_loops().len(),
            1,
            "one outer border left"
        );
        // the two halves' loops each had crack vertices, and neither is closed (both
        // borders go on around the grid as one loop)
        assert!(s.closed.is_empty());
        for (i, p) in raw.positions.iter().enumerate() {
            assert_eq!(s.mesh.pos(VertexId::from_idx(i)), *p);
        }
        assert_eq!(s.mesh.num_faces(), m.num_faces());
    }

    #[test]
    fn the_tolerance_is_relative_to_the_edge_length() {
        let raw = cracked(0.05);
        let (m, _) = Mesh::from_raw(&raw);
        assert!(stitch(&m, 0.0).is_none(), "not coincident");
        assert!(stitch(&m, 0.01).is_none(), "0.05 > 0.01 of an edge of 1");
        let s = stitch(&m, 0.1).expect("within 0.1 of the edge length");
        s.mesh.validate().unwrap();
        assert_eq!(s.mesh.topo.boundary_loops().len(), 1);
    }

    #[test]
    fn a_slit_closes_completely_and_is_reported() {
        // a slit inside a grid: the faces on the two sides of the segment x = 3,
        // 1 <= y <= 4 use copies of its inner vertices on the right: one loop of zero
        // area
        let raw = split_along(
            unit_grid(6),
            |p| p.x == 3.0 && p.y > 1.0 && p.y < 4.0,
            DVec3::ZERO,
            |c| c.x > 3.0 && c.y > 1.0 && c.y < 4.0,
        );
        let (m, _) = Mesh::from_raw(&raw);
        m.validate().unwrap();
        assert_eq!(m.topo.boundary_loops().len(), 2, "border and slit");
        let s = stitch(&m, 0.1).expect("stitched");
        s.mesh.validate().unwrap();
        assert_eq!(s.mesh.topo.boundary_loops().len(), 1);
        assert_eq!(s.closed.len(), 1);
        // the two inner vertices of the slit and their copies
        assert_eq!(s.closed[0].1, 4);
    }

    #[test]
    fn a_pinch_that_cannot_be_zipped_is_left() {
        // two squares touching at one corner only (a pinched vertex split by the
        // builder): identifying the copy would make the vertex non-manifold again
        let raw = RawMesh {
            positions: vec![
                DVec3::new(0., 0., 0.),
                DVec3::new(1., 0., 0.),
                DVec3::new(1., 1., 0.),
                DVec3::new(0., 1., 0.),
                DVec3::new(2., 1., 0.),
                DVec3::new(2., 2., 0.),
                DVec3::new(1., 2., 0.),
            ],
            faces: vec![[0, 1, 2], [0, 2, 3], [2, 4, 5], [2, 5, 6]],
            ..Default::default()
        };
        let (m, rep) = Mesh::from_raw(&raw);
        assert_eq!(rep.vertices_added_by_split, 1);
        assert!(stitch(&m, 0.1).is_none());
    }
}
