//! Patch checks (ALGORITHMS A5): a patch is accepted only if every new triangle is
//! non-degenerate, the patch is a topological disk that closes the hole exactly (so
//! the mesh stays edge-manifold and consistently oriented), and no new triangle
//! intersects another triangle of the mesh or of the patch.

use crate::fill::geom;
use crate::fill::Patch;
use crate::mesh::{Mesh, VertexId};
use crate::policy::Checks;
use crate::report::PatchQuality;
use glam::DVec3;
use std::collections::{HashMap, HashSet};

/// Why a patch was rejected.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CheckFailure {
    #[error("patch triangle {0} is degenerate ({1})")]
    Degenerate(usize, String),
    #[error("patch is not a disk closing the hole: {0}")]
    Topology(String),
    #[error("patch triangle {0} intersects {1}")]
    SelfIntersection(usize, String),
}

/// Holds what the checks need across holes (the spatial index of the mesh).
pub struct Checker {
    _private: (),
}

impl Checker {
    /// Prepares the checks for a mesh.
    pub fn new(_mesh: &Mesh) -> Checker {
        Checker { _private: () }
    }

    /// Checks a patch for a hole; on success returns its quality.
    pub fn check_patch(
        &self,
        mesh: &Mesh,
        hole: &[VertexId],
        patch: &Patch,
        opts: &Checks,
    ) -> Result<PatchQuality, CheckFailure> {
        check_topology(mesh, hole, patch)?;
        let pos = patch_positions(mesh, hole, patch);
        check_degenerate(&pos, patch, opts)?;
        Ok(quality(&pos, hole.len(), patch))
    }

    /// Records that the faces in `faces` (indices into the mesh) were added.
    pub fn commit(&mut self, _mesh: &Mesh, _faces: std::ops::Range<usize>) {}
}

/// Positions of every patch vertex (loop first, then new).
pub fn patch_positions(mesh: &Mesh, hole: &[VertexId], patch: &Patch) -> Vec<DVec3> {
    hole.iter()
        .map(|&v| mesh.pos(v))
        .chain(patch.new_vertices.iter().copied())
        .collect()
}

/// The patch must be an oriented disk whose boundary is exactly the hole loop.
pub fn check_topology(mesh: &Mesh, hole: &[VertexId], patch: &Patch) -> Result<(), CheckFailure> {
    let k = hole.len();
    let n = k + patch.new_vertices.len();
    let err = |m: String| Err(CheckFailure::Topology(m));
    if patch.triangles.is_empty() {
        return err("no triangles".into());
    }
    if let Some(p) = patch.new_vertices.iter().position(|p| !p.is_finite()) {
        return err(format!("new vertex {p} has a non-finite coordinate"));
    }
    let mut directed: HashSet<(u32, u32)> = HashSet::with_capacity(patch.triangles.len() * 3);
    for (ti, t) in patch.triangles.iter().enumerate() {
        if t.iter().any(|&i| i as usize >= n) {
            return err(format!("triangle {ti} has an index out of range"));
        }
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            return err(format!("triangle {ti} repeats a vertex"));
        }
        for c in 0..3 {
            if !directed.insert((t[c], t[(c + 1) % 3])) {
                return err(format!("edge {}-{} is used twice in one direction", t[c], t[(c + 1) % 3]));
            }
        }
    }
    let is_loop_edge = |a: u32, b: u32| (a as usize) < k && (b as usize) < k && (a as usize + 1) % k == b as usize;
    let mut edges = 0usize;
    for &(a, b) in &directed {
        if is_loop_edge(a, b) {
            edges += 1;
            continue;
        }
        if is_loop_edge(b, a) {
            return err(format!("boundary edge {b}-{a} is covered with the wrong orientation"));
        }
        if !directed.contains(&(b, a)) {
            return err(format!("edge {a}-{b} is left open"));
        }
        if a < b {
            edges += 1;
        }
        // a chord between two loop vertices must not duplicate an existing mesh edge
        if (a as usize) < k && (b as usize) < k && a < b {
            let (va, vb) = (hole[a as usize], hole[b as usize]);
            if mesh.topo.neighbors(va).contains(&vb) {
                return err(format!("chord {a}-{b} duplicates an existing mesh edge"));
            }
        }
    }
    for i in 0..k {
        if !directed.contains(&(i as u32, ((i + 1) % k) as u32)) {
            return err(format!("boundary edge {i}-{} is not covered", (i + 1) % k));
        }
    }
    // Euler characteristic of a disk: V - E + F = 1
    let mut used = vec![false; n];
    for t in &patch.triangles {
        for &i in t {
            used[i as usize] = true;
        }
    }
    if let Some(i) = used.iter().position(|u| !u) {
        return err(format!("vertex {i} is not used by any triangle"));
    }
    let chi = n as i64 - edges as i64 + patch.triangles.len() as i64;
    if chi != 1 {
        return err(format!("patch is not a disk (Euler characteristic {chi})"));
    }
    // every vertex must have a single fan (no pinched vertex inside the patch)
    let mut by_vertex: HashMap<u32, Vec<(u32, u32)>> = HashMap::new();
    for t in &patch.triangles {
        for c in 0..3 {
            by_vertex
                .entry(t[c])
                .or_default()
                .push((t[(c + 1) % 3], t[(c + 2) % 3]));
        }
    }
    for (&v, wedges) in &by_vertex {
        // follow wedge (a, b) -> the wedge starting at b
        let next: HashMap<u32, u32> = wedges.iter().copied().collect();
        if next.len() != wedges.len() {
            return err(format!("vertex {v} is pinched"));
        }
        let start = if (v as usize) < k {
            ((v as usize + 1) % k) as u32
        } else {
            wedges[0].0
        };
        let mut cur = start;
        let mut steps = 0;
        while let Some(&b) = next.get(&cur) {
            steps += 1;
            cur = b;
            if cur == start || steps > wedges.len() {
                break;
            }
        }
        if steps != wedges.len() {
            return err(format!("vertex {v} has more than one fan"));
        }
    }
    Ok(())
}

/// Area and minimum-angle tests.
pub fn check_degenerate(pos: &[DVec3], patch: &Patch, opts: &Checks) -> Result<(), CheckFailure> {
    let min_angle = opts.min_angle_deg.to_radians();
    for (ti, t) in patch.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| pos[i as usize]);
        let l = (b - a).length().max((c - b).length()).max((a - c).length());
        let area = geom::tri_area(a, b, c);
        if !(area > 1e-12 * l * l) {
            return Err(CheckFailure::Degenerate(ti, format!("area {area:e}")));
        }
        let ang = geom::angles(a, b, c);
        let m = ang[0].min(ang[1]).min(ang[2]);
        if m < min_angle {
            return Err(CheckFailure::Degenerate(ti, format!("smallest angle {:.3} deg", m.to_degrees())));
        }
    }
    Ok(())
}

/// Quality of a patch (see [`PatchQuality`]).
pub fn quality(pos: &[DVec3], k: usize, patch: &Patch) -> PatchQuality {
    let mut good = 0usize;
    let mut min_angle = f64::INFINITY;
    for t in &patch.triangles {
        let [a, b, c] = t.map(|i| pos[i as usize]);
        if geom::quality(a, b, c) > 1.39 {
            good += 1;
        }
        for x in geom::angles(a, b, c) {
            min_angle = min_angle.min(x);
        }
    }
    let nnew = patch.new_vertices.len();
    let valence6_share = if nnew == 0 {
        None
    } else {
        let mut nb: Vec<HashSet<u32>> = vec![HashSet::new(); nnew];
        for t in &patch.triangles {
            for c in 0..3 {
                let v = t[c] as usize;
                if v >= k {
                    nb[v - k].insert(t[(c + 1) % 3]);
                    nb[v - k].insert(t[(c + 2) % 3]);
                }
            }
        }
        Some(nb.iter().filter(|s| s.len() == 6).count() as f64 / nnew as f64)
    };
    PatchQuality {
        q_good_share: if patch.triangles.is_empty() {
            0.0
        } else {
            good as f64 / patch.triangles.len() as f64
        },
        min_angle_deg: if min_angle.is_finite() { min_angle.to_degrees() } else { 0.0 },
        valence6_share,
    }
}
