//! Tangential relaxation of a patch after its method has shaped it.
//!
//! Fairing decides the shape of a patch but stretches its triangles (the refined,
//! near-equilateral triangles of paper 002 §5.2 come out of the bi-Laplacian solve
//! distorted). Each new vertex is moved toward the mean of its neighbours with the
//! component along its normal removed (the tangential smoothing step of isotropic
//! remeshing), so the triangles even out while the faired surface stays where it is.
//! Loop vertices never move. The dispatcher keeps the relaxed patch only if it passes
//! the same checks as the original, and falls back to the original otherwise.

use super::{Hole, Patch};
use crate::mesh::Mesh;
use glam::DVec3;

/// The step of each relaxation iteration the dispatcher uses (half way to the
/// tangential mean).
pub const RELAX_STEP: f64 = 0.5;

/// Relaxes the new vertices of `patch` in place (`iterations` Jacobi steps of `step`).
pub fn tangential_relax(mesh: &Mesh, hole: &Hole, patch: &mut Patch, iterations: usize, step: f64) {
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
    let inv_deg: Vec<f64> = (0..n - k)
        .map(|j| match start[j + 1] - start[j] {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::{check_topology, patch_positions, quality};
    use crate::fill::{apply_patch, Hole};
    use crate::io::RawMesh;
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

    #[test]
    fn zero_iterations_change_nothing() {
        let (mesh, hole, mut patch) = skewed();
        let orig = patch.clone();
        tangential_relax(&mesh, &hole, &mut patch, 0, 0.5);
        assert_eq!(patch, orig);
    }
}
