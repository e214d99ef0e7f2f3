//! Rim trimming, the last step of the fallback chain (not from a paper).
//!
//! On real scans a hole is often bordered by faces no patch can meet cleanly: folded
//! or stretched faces at a range scan's depth jump, slivers of photogrammetry, a
//! pinch where the loop passes a vertex twice (split by the builder into copies at
//! the same place, so any patch there has a zero-area triangle). When every method
//! of the hole's list failed, the input faces around the loop are removed, one ring
//! at a time (the faces with a corner on the current loop), the mesh rebuilt, and
//! the larger loop that the removed faces leave is filled with the class's list.
//! At most `rim.max_rings` rings and `rim.max_faces` input faces per hole; faces of
//! patches already applied are never removed. Every removed input face is counted
//! in the hole's log entry (`rim_faces_removed`).

use super::fill_hole;
use crate::check::Checker;
use crate::mesh::{FaceId, Mesh, VertexId};
use crate::patch::Hole;
use crate::policy::Policy;
use crate::report::{HoleReport, HoleStatus};

/// A hole closed after trimming its rim: the new mesh, the log entry and the number
/// of input faces removed.
pub struct Trimmed {
    pub mesh: Mesh,
    pub report: HoleReport,
    pub removed: usize,
}

/// Trims the rim of `hole` (every method failed on it) and fills the larger hole.
/// Faces with index below `input_faces` are input faces (patches come after them, and
/// rebuilding keeps face order). A trim that reaches a vertex marked in `avoid` (the
/// loops skipped as outer borders) is not made: the border is never filled this way.
/// `None` when no trim within the policy's limits gave a fillable hole; the mesh is
/// then unchanged.
pub fn trim_and_fill(
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    input_faces: usize,
    avoid: &[bool],
) -> Option<Trimmed> {
    let rim = &policy.rim;
    let mut remove: Vec<bool> = vec![false; mesh.num_faces()];
    let mut removed = 0usize;
    let mut ring: Vec<VertexId> = hole.vertices.clone();
    for _ in 0..rim.max_rings {
        // the next ring: input faces with a corner on the current loop
        let mut added = 0usize;
        for &v in &ring {
            if v.idx() >= mesh.num_vertices() {
                continue;
            }
            for f in mesh.topo.vertex_faces(v) {
                if f.idx() < input_faces && !remove[f.idx()] {
                    remove[f.idx()] = true;
                    added += 1;
                }
            }
        }
        if added == 0 {
            return None;
        }
        removed += added;
        if rim.max_faces > 0 && removed > rim.max_faces {
            return None;
        }
        let gone: Vec<FaceId> = remove
            .iter()
            .enumerate()
            .filter(|(_, &r)| r)
            .map(|(i, _)| FaceId::from_idx(i))
            .collect();
        let corners: Vec<VertexId> = gone.iter().flat_map(|&f| mesh.topo.face(f)).collect();
        let (trimmed, _) = mesh.without_faces(&gone);
        // the loop the removed faces leave: the one through most of their corners
        let mut on_corner = vec![false; trimmed.num_vertices()];
        for v in &corners {
            if let Some(x) = on_corner.get_mut(v.idx()) {
                *x = true;
            }
        }
        let on = |l: &Vec<VertexId>| l.iter().filter(|v| on_corner[v.idx()]).count();
        let lp = trimmed
            .topo
            .boundary_loops()
            .into_iter()
            .filter(|l| on(l) > 0)
            .max_by_key(on)?;
        if lp
            .iter()
            .any(|v| avoid.get(v.idx()).copied().unwrap_or(false))
        {
            return None;
        }
        let bigger = Hole::new(hole.id, &trimmed, lp, policy);
        let mut filled = trimmed.clone();
        let mut checker = Checker::new(&filled);
        let mut rep = fill_hole(&mut filled, &bigger, policy, &mut checker);
        if rep.status == HoleStatus::Filled {
            rep.rim_faces_removed = removed;
            return Some(Trimmed {
                mesh: filled,
                report: rep,
                removed,
            });
        }
        ring = bigger.vertices;
        // the ring's faces in the trimmed mesh are the same input faces: the next
        // round removes from the original mesh, by vertex, so map nothing
        ring.retain(|v| v.idx() < mesh.num_vertices());
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::RawMesh;
    use glam::DVec3;

    /// A flat grid with a square hole whose rim has a folded sliver: a vertex of the
    /// rim is pulled across the hole, so the faces around it fold over the hole (the
    /// methods may or may not close it as it is; trimmed, it is a plain hole).
    fn folded_rim() -> RawMesh {
        use crate::testutil::{cells_removed, unit_grid};
        let mut raw = cells_removed(unit_grid(8), |i, j| {
            (3..5).contains(&i) && (3..5).contains(&j)
        });
        // vertex (3, 4) of the loop pulled across the hole to (4.6, 4, 0.02)
        raw.positions[4 * 9 + 3] = DVec3::new(4.6, 4.0, 0.02);
        raw
    }

    #[test]
    fn a_hole_with_a_folded_rim_is_closed_after_trimming() {
        let raw = folded_rim();
        let (mesh, _) = Mesh::from_raw(&raw);
        mesh.validate().unwrap();
        let policy = Policy::default();
        let lp = mesh
            .topo
            .boundary_loops()
            .into_iter()
            .min_by_key(|l| l.len())
            .unwrap();
        let hole = Hole::new(0, &mesh, lp, &policy);
        let t = trim_and_fill(&mesh, &hole, &policy, mesh.num_faces(), &[]).expect("trimmed");
        t.mesh.validate().unwrap();
        assert!(t.removed > 0 && t.removed <= policy.rim.max_faces);
        assert_eq!(t.report.rim_faces_removed, t.removed);
        assert_eq!(t.report.status, HoleStatus::Filled);
        // only the outer border is left, input vertices unmoved
        assert_eq!(t.mesh.topo.boundary_loops().len(), 1);
        for i in 0..raw.positions.len() {
            assert_eq!(t.mesh.positions[i], raw.positions[i]);
        }
        // no trimming when the policy caps it below one ring
        let tight = policy.edit(|s| s.rim.max_faces = 1).unwrap();
        assert!(trim_and_fill(&mesh, &hole, &tight, mesh.num_faces(), &[]).is_none());
        // nor when it would reach the outer border
        let avoid = vec![true; mesh.num_vertices()];
        assert!(trim_and_fill(&mesh, &hole, &policy, mesh.num_faces(), &avoid).is_none());
    }
}
