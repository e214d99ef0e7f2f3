//! Pinched loops: a boundary loop that passes one point twice.
//!
//! Where two wedges of a scan's faces meet only at a vertex (a pinched, non-manifold
//! vertex), the builder splits the vertex into copies at the same place. A loop that
//! runs through two such copies is a figure eight: every disk patch over it has a
//! triangle with both copies as corners, of zero area, so every method fails and the
//! rim trimming removes hundreds of good faces to get rid of the pinch. Instead, the
//! loop is cut at the pinch into its two lobes, before the holes are filled:
//! - the smaller lobe (the loop from one copy to the other, closed over the first) is
//!   filled on its own with the method list of its size class, checked like any
//!   patch (the checker takes the copies for one point);
//! - the two copies are joined into one vertex (the input vertex when one of them is
//!   it; the other stays in the output unreferenced, as in [`super::stitch`]), which
//!   the filled lobe makes manifold; the rebuilt mesh must come out of the builder
//!   with nothing to resolve, or the round is undone;
//! - the larger lobe is an ordinary hole of the fill; a lobe of two vertices needs no
//!   patch (joining the copies closes it).
//!
//! A loop pinched more than once is cut one pinch per round, the smallest lobe
//! first. Loops the border rule skips are left alone. Not from a paper.

use crate::check::Checker;
use crate::fill::dispatch;
use crate::mesh::{Mesh, VertexId};
use crate::patch::{apply_patch, Hole};
use crate::policy::{Method, Policy};

/// Most rounds of cutting (a loop pinched more often keeps its remaining pinches).
const MAX_ROUNDS: usize = 8;

/// One pinch closed: where, and what filled its lobe.
#[derive(Clone, Debug)]
pub struct Pinch {
    /// The joined vertex (on the loop that remains, if any).
    pub vertex: VertexId,
    /// The other vertices of the loop as it was cut, to find its hole afterwards.
    pub rest: Vec<VertexId>,
    /// Boundary vertices of the lobe filled.
    pub lobe: usize,
    /// The method that filled it (`None` for a lobe of two vertices).
    pub method: Option<Method>,
    pub added_vertices: usize,
    pub added_faces: usize,
}

/// The input vertex a mesh vertex stands for, when it sits exactly there (the rule of
/// the checker's shared vertices): copies of one pinched vertex have the same key.
fn key(mesh: &Mesh, v: VertexId) -> u32 {
    match mesh.origin.get(v.idx()).copied().flatten() {
        Some(o)
            if mesh
                .positions
                .get(o.idx())
                .map(|p| p.to_array().map(f64::to_bits))
                == mesh
                    .positions
                    .get(v.idx())
                    .map(|p| p.to_array().map(f64::to_bits)) =>
        {
            o.0
        }
        _ => v.0,
    }
}

/// The pinch of `lp` with the smallest lobe: `(i, j)`, `i < j`, two positions of the
/// loop with the same key, and whether the lobe is `lp[i..j]` (else `lp[j..] + lp[..i]`).
fn smallest_pinch(mesh: &Mesh, lp: &[VertexId]) -> Option<(usize, usize, bool)> {
    let n = lp.len();
    let mut keyed: Vec<(u32, usize)> = lp
        .iter()
        .enumerate()
        .map(|(i, &v)| (key(mesh, v), i))
        .collect();
    keyed.sort_unstable();
    let mut best: Option<(usize, usize, usize, bool)> = None;
    for w in keyed.windows(2) {
        if w[0].0 != w[1].0 {
            continue;
        }
        let (i, j) = (w[0].1, w[1].1);
        let (inner, outer) = (j - i, n - (j - i));
        let (size, first) = if inner <= outer {
            (inner, true)
        } else {
            (outer, false)
        };
        if size >= 2 && best.is_none_or(|b| size < b.0) {
            best = Some((size, i, j, first));
        }
    }
    best.map(|(_, i, j, first)| (i, j, first))
}

/// Cuts the pinched loops of `mesh` among `holes` (those with `skip` unset). Returns
/// the new mesh and what was closed, or `None` when no loop is pinched or no pinch
/// could be closed. Faces added come after the mesh's faces, in order.
pub fn close_pinches(
    mesh: &Mesh,
    holes: &[Hole],
    skip: &[Option<String>],
    policy: &Policy,
) -> Option<(Mesh, Vec<Pinch>)> {
    let mut loops: Vec<Vec<VertexId>> = holes
        .iter()
        .zip(skip)
        .filter(|(_, s)| s.is_none())
        .map(|(h, _)| h.vertices.clone())
        .collect();
    let mut cur: Option<Mesh> = None;
    let mut closed: Vec<Pinch> = Vec::new();
    for _ in 0..MAX_ROUNDS {
        let m = cur.as_ref().unwrap_or(mesh);
        let Some((next, pinches, rest)) = one_round(m, &loops, policy) else {
            break;
        };
        closed.extend(pinches);
        cur = Some(next);
        loops = rest;
        if loops.is_empty() {
            break;
        }
    }
    cur.map(|m| (m, closed))
}

/// One round: the smallest-lobe pinch of each loop closed, one rebuild. Returns the
/// mesh, the pinches closed and the loops that remain pinched candidates (the rest of
/// each loop cut).
fn one_round(
    mesh: &Mesh,
    loops: &[Vec<VertexId>],
    policy: &Policy,
) -> Option<(Mesh, Vec<Pinch>, Vec<Vec<VertexId>>)> {
    let mut work = mesh.clone();
    let mut checker = Checker::new(mesh);
    let mut join: Vec<(VertexId, VertexId)> = Vec::new();
    let mut pinches = Vec::new();
    let mut rest_loops = Vec::new();
    for lp in loops {
        let Some((i, j, first)) = smallest_pinch(mesh, lp) else {
            continue;
        };
        // the lobe from one copy up to (not including) the other, and the rest
        let (lobe, rest): (Vec<VertexId>, Vec<VertexId>) = if first {
            (
                lp[i..j].to_vec(),
                lp[j..].iter().chain(&lp[..i]).copied().collect(),
            )
        } else {
            (
                lp[j..].iter().chain(&lp[..i]).copied().collect(),
                lp[i..j].to_vec(),
            )
        };
        let (a, b) = (lp[i], lp[j]);
        // keep the input vertex (the smaller id: copies are appended)
        let (keep, gone) = if a.0 <= b.0 { (a, b) } else { (b, a) };
        let mut pinch = Pinch {
            vertex: keep,
            rest: rest.iter().copied().filter(|&v| v != a && v != b).collect(),
            lobe: lobe.len(),
            method: None,
            added_vertices: 0,
            added_faces: 0,
        };
        if lobe.len() >= 3 {
            let hole = Hole::new(0, mesh, lobe, policy);
            let proposal = dispatch::propose(mesh, &hole, policy, &checker);
            let methods = proposal.order;
            let Some(dispatch::Accepted { at: m, patch, .. }) = proposal.accepted else {
                continue;
            };
            if checker
                .check_against_added(&work, &hole.vertices, &patch, &policy.checks)
                .is_err()
            {
                continue;
            }
            let Ok(faces) = apply_patch(&mut work, &hole, &patch) else {
                continue;
            };
            checker.commit(&work, faces);
            pinch.method = methods.get(m).copied();
            pinch.added_vertices = patch.new_vertices.len();
            pinch.added_faces = patch.triangles.len();
        }
        join.push((gone, keep));
        pinches.push(pinch);
        if rest.len() > 3 {
            rest_loops.push(rest);
        }
    }
    if join.is_empty() {
        return None;
    }
    join.sort_unstable();
    let map = |v: VertexId| match join.binary_search_by_key(&v, |j| j.0) {
        Ok(i) => join[i].1,
        Err(_) => v,
    };
    // the builder must find nothing to resolve but the copies joined away
    let faces = work
        .topo
        .faces()
        .iter()
        .map(|f| f.map(|v| map(v).0))
        .collect();
    let m = super::stitch::rebuild_clean(&work, faces)?;
    // the loops still open after the round (the rest of each, renamed)
    let rest_loops = rest_loops
        .into_iter()
        .map(|l| l.into_iter().map(map).collect::<Vec<_>>())
        .filter(|l| l.iter().all(|&v| m.topo.is_boundary_vertex(v)))
        .filter_map(|l| {
            m.topo
                .boundary_loops()
                .into_iter()
                .find(|b| b.contains(&l[0]))
        })
        .collect();
    Some((m, pinches, rest_loops))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::RawMesh;
    use crate::testutil::{cells_removed, unit_grid};

    /// A flat grid with two square holes that touch at one corner: the builder splits
    /// the shared corner, and the two holes are one loop pinched there.
    fn touching_holes() -> RawMesh {
        cells_removed(unit_grid(8), |i, j| (i, j) == (3, 3) || (i, j) == (4, 4))
    }

    #[test]
    fn a_loop_pinched_at_a_split_vertex_is_cut_into_two_holes() {
        let raw = touching_holes();
        let (mesh, rep) = Mesh::from_raw(&raw);
        mesh.validate().unwrap();
        assert!(rep.vertices_added_by_split >= 1, "{rep:?}");
        let policy = Policy::default();
        let loops = mesh.topo.boundary_loops();
        let holes: Vec<Hole> = loops
            .into_iter()
            .enumerate()
            .map(|(i, l)| Hole::new(i, &mesh, l, &policy))
            .collect();
        let pinched: Vec<&Hole> = holes.iter().filter(|h| h.len() == 8).collect();
        assert_eq!(pinched.len(), 1, "one loop of 8 through the split corner");
        let skip: Vec<Option<String>> = holes
            .iter()
            .map(|h| (h.len() > 8).then(|| "border".to_string()))
            .collect();
        let (out, closed) = close_pinches(&mesh, &holes, &skip, &policy).expect("closed");
        out.validate().unwrap();
        assert_eq!(closed.len(), 1);
        let p = &closed[0];
        assert_eq!(p.lobe, 4);
        assert!(p.added_faces >= 2);
        // the corner is one vertex again, on the one square hole left
        let left: Vec<Vec<VertexId>> = out
            .topo
            .boundary_loops()
            .into_iter()
            .filter(|l| l.len() < 32)
            .collect();
        assert_eq!(left.len(), 1);
        assert_eq!(left[0].len(), 4);
        assert!(left[0].contains(&p.vertex));
        // input vertices unmoved, the faces of the input kept in order
        for i in 0..raw.positions.len() {
            assert_eq!(out.positions[i], raw.positions[i]);
        }
        assert_eq!(out.num_faces(), mesh.num_faces() + p.added_faces);
    }

    #[test]
    fn no_pinch_no_change() {
        let raw = cells_removed(unit_grid(6), |i, j| (i, j) == (2, 2));
        let (mesh, _) = Mesh::from_raw(&raw);
        let policy = Policy::default();
        let holes: Vec<Hole> = mesh
            .topo
            .boundary_loops()
            .into_iter()
            .enumerate()
            .map(|(i, l)| Hole::new(i, &mesh, l, &policy))
            .collect();
        let skip = vec![None; holes.len()];
        assert!(close_pinches(&mesh, &holes, &skip, &policy).is_none());
    }
}
