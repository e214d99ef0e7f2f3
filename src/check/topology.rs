//! The topology check: a patch must be an oriented disk whose boundary is exactly the
//! hole's loop (so the mesh stays edge-manifold and consistently oriented), and a chord
//! between two loop vertices must not be an edge of the mesh already.

use super::{CheckFailure, TopologyFailure};
use crate::mesh::{Mesh, VertexId};
use crate::patch::Patch;

/// The patch must be an oriented disk whose boundary is exactly the hole loop.
pub fn check_topology(mesh: &Mesh, hole: &[VertexId], patch: &Patch) -> Result<(), CheckFailure> {
    let k = hole.len();
    let n = k + patch.new_vertices.len();
    let err = |m: TopologyFailure| Err(CheckFailure::Topology(m));
    if patch.triangles.is_empty() {
        return err(TopologyFailure::NoTriangles);
    }
    if let Some(p) = patch.new_vertices.iter().position(|p| !p.is_finite()) {
        return err(TopologyFailure::NonFinite(p));
    }
    for (ti, t) in patch.triangles.iter().enumerate() {
        if t.iter().any(|&i| i as usize >= n) {
            return err(TopologyFailure::IndexOutOfRange(ti));
        }
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            return err(TopologyFailure::RepeatedVertex(ti));
        }
    }
    // the corners of each vertex, as wedges (next, previous) in its triangles, one
    // list after the other sorted by `next`: the directed edges v -> next, and the
    // fan around v
    let mut start = vec![0usize; n + 1];
    for t in &patch.triangles {
        for &v in t {
            start[v as usize + 1] += 1;
        }
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut wedge = vec![(0u32, 0u32); start[n]];
    for t in &patch.triangles {
        for c in 0..3 {
            let v = t[c] as usize;
            wedge[fill[v]] = (t[(c + 1) % 3], t[(c + 2) % 3]);
            fill[v] += 1;
        }
    }
    for v in 0..n {
        wedge[start[v]..start[v + 1]].sort_unstable();
    }
    let out = |v: u32| &wedge[start[v as usize]..start[v as usize + 1]];
    let has_edge = |a: u32, b: u32| out(a).binary_search_by_key(&b, |w| w.0).is_ok();
    for v in 0..n as u32 {
        if let Some(w) = out(v).windows(2).find(|w| w[0].0 == w[1].0) {
            return err(TopologyFailure::EdgeUsedTwice(v, w[0].0));
        }
    }
    let is_loop_edge =
        |a: u32, b: u32| (a as usize) < k && (b as usize) < k && (a as usize + 1) % k == b as usize;
    let mut edges = 0usize;
    for a in 0..n as u32 {
        for &(b, _) in out(a) {
            if is_loop_edge(a, b) {
                edges += 1;
                continue;
            }
            if is_loop_edge(b, a) {
                return err(TopologyFailure::BoundaryReversed(b, a));
            }
            if !has_edge(b, a) {
                return err(TopologyFailure::OpenEdge(a, b));
            }
            if a < b {
                edges += 1;
            }
            // a chord between two loop vertices must not duplicate an existing mesh edge
            if (a as usize) < k && (b as usize) < k && a < b {
                let (va, vb) = (hole[a as usize], hole[b as usize]);
                if mesh.topo.neighbors(va).contains(&vb) {
                    return err(TopologyFailure::ChordIsMeshEdge(a, b));
                }
            }
        }
    }
    for i in 0..k {
        if !has_edge(i as u32, ((i + 1) % k) as u32) {
            return err(TopologyFailure::BoundaryUncovered(i, (i + 1) % k));
        }
    }
    // Euler characteristic of a disk: V - E + F = 1
    if let Some(i) = (0..n).find(|&i| start[i] == start[i + 1]) {
        return err(TopologyFailure::UnusedVertex(i));
    }
    let chi = n as i64 - edges as i64 + patch.triangles.len() as i64;
    if chi != 1 {
        return err(TopologyFailure::NotADisk(chi));
    }
    // connected: otherwise a disk plus a closed torus of new vertices has chi = 1 too
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for t in &patch.triangles {
        for c in 1..3 {
            let (a, b) = (
                root(&mut parent, t[0] as usize),
                root(&mut parent, t[c] as usize),
            );
            parent[a] = b;
        }
    }
    let r0 = root(&mut parent, 0);
    if let Some(i) = (1..n).find(|&i| root(&mut parent, i) != r0) {
        return err(TopologyFailure::Disconnected(i));
    }
    // every vertex must have a single fan (no pinched vertex inside the patch): follow
    // wedge (a, b) to the wedge starting at b (its `next` is unique, checked above)
    for v in 0..n {
        let wedges = &wedge[start[v]..start[v + 1]];
        let next = |a: u32| {
            wedges
                .binary_search_by_key(&a, |w| w.0)
                .ok()
                .map(|i| wedges[i].1)
        };
        let begin = if v < k {
            ((v + 1) % k) as u32
        } else {
            wedges[0].0
        };
        let mut cur = begin;
        let mut steps = 0;
        while let Some(b) = next(cur) {
            steps += 1;
            cur = b;
            if cur == begin || steps > wedges.len() {
                break;
            }
        }
        if steps != wedges.len() {
            return err(TopologyFailure::Pinched(v));
        }
    }
    Ok(())
}
