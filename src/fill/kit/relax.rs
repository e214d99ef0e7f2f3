//! Tangential relaxation of a patch after its method has shaped it.
//!
//! Fairing decides the shape of a patch but stretches its triangles (the refined,
//! near-equilateral triangles of paper 002 §5.2 come out of the bi-Laplacian solve
//! distorted). Each new vertex is moved toward the mean of its neighbours with the
//! component along its normal removed (the tangential smoothing step of isotropic
//! remeshing), so the triangles even out while the faired surface stays where it is.
//! Loop vertices never move. The relaxed patch is kept only if it passes the same
//! checks as the original ([`relax_checked`]): when it fails at a few triangles (a
//! relaxed vertex slid across a fold of the patch), it is relaxed again from the
//! original with the vertices around those triangles held where the method put them,
//! and only when that fails too is the original kept.

use crate::check::CheckFailure;
use crate::mesh::Mesh;
use crate::patch::{Hole, Patch};
use glam::DVec3;

/// The step of each relaxation iteration the dispatcher uses (half way to the
/// tangential mean).
pub const RELAX_STEP: f64 = 0.5;

/// Relaxes the new vertices of `patch` in place (`iterations` Jacobi steps of `step`).
pub fn tangential_relax(mesh: &Mesh, hole: &Hole, patch: &mut Patch, iterations: usize, step: f64) {
    tangential_relax_pinned(mesh, hole, patch, iterations, step, &[]);
}

/// [`tangential_relax`] with some new vertices held in place: `pinned[j]` for new
/// vertex `j` (missing entries are free).
pub fn tangential_relax_pinned(
    mesh: &Mesh,
    hole: &Hole,
    patch: &mut Patch,
    iterations: usize,
    step: f64,
    pinned: &[bool],
) {
    let k = hole.len();
    let n = k + patch.new_vertices.len();
    if patch.new_vertices.is_empty() || iterations == 0 {
        return;
    }
    if patch.triangles.iter().flatten().any(|&i| i as usize >= n) {
        return;
    }
    let mut pos: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
    pos.extend_from_slice(&patch.new_vertices);
    // neighbours of each new vertex (each undirected edge seen twice: dedup), stored
    // one list after the other (`adj[start[j]..start[j + 1]]`), and the triangles
    // with a new corner: the loop runs many times over both. The lists are grouped by
    // a counting sort (no vector per vertex), then each is sorted and deduplicated.
    let m = n - k;
    let mut count = vec![0usize; m + 1];
    for t in &patch.triangles {
        for &v in t {
            if v as usize >= k {
                count[v as usize - k + 1] += 2;
            }
        }
    }
    for j in 0..m {
        count[j + 1] += count[j];
    }
    let mut fill = count.clone();
    let mut raw = vec![0u32; count[m]];
    for t in &patch.triangles {
        for c in 0..3 {
            let v = t[c] as usize;
            if v >= k {
                raw[fill[v - k]] = t[(c + 1) % 3];
                raw[fill[v - k] + 1] = t[(c + 2) % 3];
                fill[v - k] += 2;
            }
        }
    }
    let mut start = Vec::with_capacity(m + 1);
    let mut adj = Vec::with_capacity(raw.len() / 2);
    start.push(0);
    for j in 0..m {
        let l = &mut raw[count[j]..count[j + 1]];
        l.sort_unstable();
        for (i, &w) in l.iter().enumerate() {
            if i == 0 || l[i - 1] != w {
                adj.push(w);
            }
        }
        start.push(adj.len());
    }
    let tris: Vec<[usize; 3]> = patch
        .triangles
        .iter()
        .filter(|t| t.iter().any(|&i| i as usize >= k))
        .map(|t| t.map(|i| i as usize))
        .collect();
    // a pinned vertex (or one without neighbours) has weight 0: it stays
    let inv_deg: Vec<f64> = (0..n - k)
        .map(|j| match start[j + 1] - start[j] {
            _ if pinned.get(j).copied().unwrap_or(false) => 0.0,
            0 => 0.0,
            d => 1.0 / d as f64,
        })
        .collect();
    // two buffers (loop vertices in both), swapped after each Jacobi step
    let mut next = pos.clone();
    // one normal per vertex, loop vertices included (theirs are not used): each
    // triangle adds to its three corners without a test
    let mut normal = vec![DVec3::ZERO; n];
    for _ in 0..iterations {
        normal.fill(DVec3::ZERO);
        for t in &tris {
            let [a, b, c] = t.map(|i| pos[i]);
            let fnrm = (b - a).cross(c - a);
            for &i in t {
                normal[i] += fnrm;
            }
        }
        for (j, (w, out)) in inv_deg.iter().zip(&mut next[k..]).enumerate() {
            let p = pos[k + j];
            if *w == 0.0 {
                *out = p;
                continue;
            }
            let mut c = DVec3::ZERO;
            for &i in &adj[start[j]..start[j + 1]] {
                c += pos[i as usize];
            }
            let nrm = normal[k + j].normalize_or_zero();
            let d = c * *w - p;
            let moved = p + step * (d - nrm * nrm.dot(d));
            *out = if moved.is_finite() { moved } else { p };
        }
        std::mem::swap(&mut pos, &mut next);
    }
    patch.new_vertices.copy_from_slice(&pos[k..]);
}

/// Rounds of re-relaxing with more vertices held (see [`relax_checked`]).
const PIN_ROUNDS: usize = 2;

/// `patch` relaxed ([`relax_checked`]) where that passes `check`, else as it is where
/// that passes, with what `check` made of it; else the failure of `patch` as it is.
/// What the dispatcher does to every patch a method returns unchecked, and the blend to
/// a moved patch.
pub fn settled<Q>(
    mesh: &Mesh,
    hole: &Hole,
    patch: Patch,
    iterations: usize,
    step: f64,
    mut check: impl FnMut(&Patch) -> Result<Q, CheckFailure>,
) -> Result<(Patch, Q), CheckFailure> {
    match relax_checked(mesh, hole, &patch, iterations, step, &mut check) {
        Some(relaxed) => Ok(relaxed),
        None => check(&patch).map(|q| (patch, q)),
    }
}

/// Relaxes `patch` ([`tangential_relax`]) and returns the relaxed patch with what
/// `check` made of it, if it passes. A relaxed patch that fails at some triangles is
/// relaxed again from `patch` with the new corners of those triangles and their new
/// neighbours held where they are (for at most [`PIN_ROUNDS`] rounds, the held set
/// growing by each round's failure), so that the rest of the patch is still evened
/// out. `None` when relaxing moves nothing or no relaxed patch passes: the caller
/// keeps `patch` as it is.
pub fn relax_checked<Q>(
    mesh: &Mesh,
    hole: &Hole,
    patch: &Patch,
    iterations: usize,
    step: f64,
    mut check: impl FnMut(&Patch) -> Result<Q, CheckFailure>,
) -> Option<(Patch, Q)> {
    let mut relaxed = patch.clone();
    tangential_relax(mesh, hole, &mut relaxed, iterations, step);
    if relaxed == *patch {
        return None;
    }
    let mut err = match check(&relaxed) {
        Ok(q) => return Some((relaxed, q)),
        Err(e) => e,
    };
    let k = hole.len();
    let m = patch.new_vertices.len();
    let mut pinned = vec![false; m];
    for round in 0..PIN_ROUNDS {
        tracing::debug!(hole = hole.id, round, failure = %err, "relaxed patch rejected");
        let bad = err.triangles();
        let mut held: Vec<usize> = bad
            .iter()
            .filter_map(|&t| patch.triangles.get(t))
            .flatten()
            .filter_map(|&v| (v as usize).checked_sub(k))
            .filter(|&j| j < m)
            .collect();
        if held.is_empty() {
            return None;
        }
        // and their new neighbours
        let corners = held.clone();
        for t in &patch.triangles {
            if t.iter()
                .any(|&v| (v as usize) >= k && corners.contains(&(v as usize - k)))
            {
                held.extend(t.iter().filter_map(|&v| (v as usize).checked_sub(k)));
            }
        }
        let before = pinned.iter().filter(|&&b| b).count();
        for j in held {
            if j < m {
                pinned[j] = true;
            }
        }
        if pinned.iter().filter(|&&b| b).count() == before {
            return None;
        }
        let mut again = patch.clone();
        tangential_relax_pinned(mesh, hole, &mut again, iterations, step, &pinned);
        if again == *patch {
            return None;
        }
        match check(&again) {
            Ok(q) => return Some((again, q)),
            Err(e) => err = e,
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::{check_topology, patch_positions, quality, Meets, TopologyFailure};
    use crate::io::RawMesh;
    use crate::patch::{apply_patch, Hole};
    use crate::policy::Policy;

    /// A planar grid with its middle 2x2 cells removed, and a patch over that hole
    /// whose one new vertex sits far off-centre (skewed triangles).
    fn skewed() -> (Mesh, Hole, Patch) {
        let mut raw = RawMesh::default();
        for j in 0..5 {
            for i in 0..5 {
                raw.positions.push(DVec3::new(i as f64, j as f64, 0.0));
            }
        }
        let id = |i: u32, j: u32| j * 5 + i;
        for j in 0..4 {
            for i in 0..4 {
                if (1..3).contains(&i) && (1..3).contains(&j) {
                    continue;
                }
                raw.faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                raw.faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let (mesh, _) = Mesh::from_raw(&raw);
        let loops = mesh.topo.boundary_loops();
        let lp = loops
            .into_iter()
            .find(|l| l.len() == 8)
            .expect("inner hole");
        let hole = Hole::new(0, &mesh, lp, &Policy::default());
        let k = hole.len() as u32;
        let patch = Patch {
            new_vertices: vec![DVec3::new(1.3, 1.4, 0.0)],
            triangles: (0..k).map(|i| [i, (i + 1) % k, k]).collect(),
        };
        (mesh, hole, patch)
    }

    #[test]
    fn relaxation_centres_the_vertex_and_stays_on_the_plane() {
        let (mesh, hole, mut patch) = skewed();
        let before = quality(
            &patch_positions(&mesh, &hole.vertices, &patch),
            hole.len(),
            &patch,
        );
        tangential_relax(&mesh, &hole, &mut patch, 100, 0.5);
        let p = patch.new_vertices[0];
        assert!((p - DVec3::new(2.0, 2.0, 0.0)).length() < 1e-6, "{p}");
        assert_eq!(p.z, 0.0);
        let after = quality(
            &patch_positions(&mesh, &hole.vertices, &patch),
            hole.len(),
            &patch,
        );
        assert!(after.min_angle_deg > before.min_angle_deg);
        check_topology(&mesh, &hole.vertices, &patch).unwrap();
        let mut m = mesh.clone();
        apply_patch(&mut m, &hole, &patch).unwrap();
        m.validate().unwrap();
    }

    /// A planar 8x8 grid with its middle 4x4 cells removed, and the patch of those
    /// cells (9 new vertices), each new vertex pushed off its grid point in the plane.
    fn grid_hole() -> (Mesh, Hole, Patch, Vec<DVec3>) {
        let n = 9u32;
        let raw = crate::testutil::cells_removed(crate::testutil::unit_grid(8), |i, j| {
            (2..6).contains(&i) && (2..6).contains(&j)
        });
        let id = |i: u32, j: u32| j * n + i;
        let (mesh, lp) = crate::testutil::mesh_and_loop(&raw, |_, l| l.len() == 16);
        let hole = Hole::new(0, &mesh, lp, &Policy::default());
        let k = hole.len() as u32;
        // patch index of grid vertex (i, j): its place in the loop, else a new vertex
        let mut new_vertices = Vec::new();
        let mut index = std::collections::HashMap::new();
        for j in 2..7 {
            for i in 2..7 {
                let v = id(i, j);
                let at = match hole.vertices.iter().position(|x| x.0 == v) {
                    Some(p) => p as u32,
                    None => {
                        let wobble = DVec3::new(0.3 * ((i + j) % 2) as f64, -0.25, 0.0);
                        new_vertices.push(DVec3::new(i as f64, j as f64, 0.0) + wobble);
                        k + new_vertices.len() as u32 - 1
                    }
                };
                index.insert((i, j), at);
            }
        }
        let at = |i: u32, j: u32| index[&(i, j)];
        let mut triangles = Vec::new();
        for j in 2..6 {
            for i in 2..6 {
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        let start = new_vertices.clone();
        let patch = Patch {
            new_vertices,
            triangles,
        };
        (mesh, hole, patch, start)
    }

    #[test]
    fn a_relaxation_that_fails_at_one_vertex_holds_it_and_relaxes_the_rest() {
        let (mesh, hole, patch, start) = grid_hole();
        let k = hole.len() as u32;
        check_topology(&mesh, &hole.vertices, &patch).unwrap();
        // a check that refuses any triangle around new vertex 4 when it has moved
        // (as a real check refuses a vertex slid across a fold)
        let mut calls = 0;
        let check = |p: &Patch| {
            calls += 1;
            if p.new_vertices[4] != start[4] {
                let t = p
                    .triangles
                    .iter()
                    .position(|t| t.contains(&(k + 4)))
                    .unwrap();
                return Err(CheckFailure::SelfIntersection {
                    triangle: t,
                    meets: Meets::MeshFace(0),
                });
            }
            Ok(())
        };
        let (relaxed, ()) =
            relax_checked(&mesh, &hole, &patch, 30, RELAX_STEP, check).expect("pinned pass");
        assert_eq!(calls, 2, "one failing relaxation, one that passes");
        assert_eq!(relaxed.new_vertices[4], start[4]);
        // the vertices away from the held ones were still relaxed toward the grid
        let moved = (0..start.len())
            .filter(|&j| relaxed.new_vertices[j] != start[j])
            .count();
        assert!(moved > 0, "nothing relaxed");
        let err = |p: &[DVec3]| -> f64 {
            let mut e = 0.0;
            for (j, q) in p.iter().enumerate() {
                let g = DVec3::new((2 + j % 3 + 1) as f64, (2 + j / 3 + 1) as f64, 0.0);
                e += (*q - g).length();
            }
            e
        };
        assert!(err(&relaxed.new_vertices) < err(&start));
        assert!(relaxed.new_vertices.iter().all(|p| p.z == 0.0));
        let mut m = mesh.clone();
        apply_patch(&mut m, &hole, &relaxed).unwrap();
        m.validate().unwrap();
    }

    #[test]
    fn a_relaxation_that_always_fails_or_fails_its_topology_keeps_the_patch() {
        let (mesh, hole, patch, _) = grid_hole();
        let always = |_: &Patch| -> Result<(), CheckFailure> {
            Err(CheckFailure::SelfIntersection {
                triangle: 0,
                meets: Meets::PatchTriangle(17),
            })
        };
        assert!(relax_checked(&mesh, &hole, &patch, 30, RELAX_STEP, always).is_none());
        let topo = |_: &Patch| -> Result<(), CheckFailure> {
            Err(CheckFailure::Topology(TopologyFailure::NoTriangles))
        };
        assert!(relax_checked(&mesh, &hole, &patch, 30, RELAX_STEP, topo).is_none());
        let fine = |_: &Patch| -> Result<(), CheckFailure> { Ok(()) };
        assert!(relax_checked(&mesh, &hole, &patch, 0, RELAX_STEP, fine).is_none());
    }

    #[test]
    fn zero_iterations_change_nothing() {
        let (mesh, hole, mut patch) = skewed();
        let orig = patch.clone();
        tangential_relax(&mesh, &hole, &mut patch, 0, 0.5);
        assert_eq!(patch, orig);
    }
}
