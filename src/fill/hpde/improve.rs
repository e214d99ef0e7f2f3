//! Step 7 of HPDE: smoothing, short-edge collapse and angle-improving swaps of the
//! patch (paper 000 §4.6–§4.7, Fig. 5). Boundary vertices (index `< k`) never move.

use crate::fill::kit::front::edge_key;
use crate::fill::kit::FillError;
use crate::geometry::measure;
use crate::patch::Patch;
use glam::DVec3;
use std::collections::{BTreeMap, BTreeSet};

/// The patch being improved: vertices `0..k` are the loop, the rest are new.
pub struct Local {
    k: usize,
    pos: Vec<DVec3>,
    alive_v: Vec<bool>,
    tris: Vec<[u32; 3]>,
    alive_t: Vec<bool>,
    /// Loop-index pairs `(i < j)` that are existing mesh edges (not loop edges).
    chords: BTreeSet<(u32, u32)>,
}

impl Local {
    pub fn new(
        k: usize,
        pos: Vec<DVec3>,
        tris: Vec<[u32; 3]>,
        chords: BTreeSet<(u32, u32)>,
    ) -> Local {
        let n = pos.len();
        let nt = tris.len();
        Local {
            k,
            pos,
            alive_v: vec![true; n],
            tris,
            alive_t: vec![true; nt],
            chords,
        }
    }

    fn is_new(&self, v: u32) -> bool {
        v as usize >= self.k
    }

    /// Sorted neighbour lists of every vertex.
    fn neighbours(&self) -> Vec<Vec<u32>> {
        let mut nb: Vec<BTreeSet<u32>> = vec![BTreeSet::new(); self.pos.len()];
        for (t, alive) in self.tris.iter().zip(&self.alive_t) {
            if !alive {
                continue;
            }
            for c in 0..3 {
                nb[t[c] as usize].insert(t[(c + 1) % 3]);
                nb[t[c] as usize].insert(t[(c + 2) % 3]);
            }
        }
        nb.into_iter().map(|s| s.into_iter().collect()).collect()
    }

    /// Triangles around every vertex.
    fn vertex_tris(&self) -> Vec<Vec<u32>> {
        let mut vt: Vec<Vec<u32>> = vec![Vec::new(); self.pos.len()];
        for (ti, t) in self.tris.iter().enumerate() {
            if !self.alive_t[ti] {
                continue;
            }
            for &v in t {
                vt[v as usize].push(ti as u32);
            }
        }
        vt
    }

    /// `iterations` Taubin λ/μ pairs with uniform weights on the new vertices.
    pub fn smooth(&mut self, iterations: usize, lambda: f64, mu: f64) {
        let nb = self.neighbours();
        let mut next = self.pos.clone();
        for _ in 0..iterations {
            for step in [lambda, mu] {
                for v in self.k..self.pos.len() {
                    if !self.alive_v[v] || nb[v].is_empty() {
                        continue;
                    }
                    let avg = nb[v].iter().map(|&w| self.pos[w as usize]).sum::<DVec3>()
                        / nb[v].len() as f64;
                    next[v] = self.pos[v] + (avg - self.pos[v]) * step;
                }
                self.pos[self.k..].copy_from_slice(&next[self.k..]);
            }
        }
    }

    /// Whether an edge `a-b` may be created: not a loop-vertex chord that exists in
    /// the mesh.
    fn edge_allowed(&self, a: u32, b: u32) -> bool {
        if self.is_new(a) || self.is_new(b) {
            return true;
        }
        !self.chords.contains(&edge_key(a, b))
    }

    /// Collapses edges shorter than `min_len`, shortest first: two new vertices meet
    /// at the midpoint; a new vertex joined to a loop vertex merges into it.
    pub fn collapse(&mut self, min_len: f64) {
        if min_len <= 0.0 {
            return;
        }
        for _pass in 0..64 {
            let nb = self.neighbours();
            let vt = self.vertex_tris();
            let mut edges: Vec<(f64, u32, u32)> = Vec::new();
            for (a, list) in nb.iter().enumerate() {
                let a = a as u32;
                for &b in list {
                    if a < b && (self.is_new(a) || self.is_new(b)) {
                        let l = (self.pos[a as usize] - self.pos[b as usize]).length();
                        if l < min_len {
                            edges.push((l, a, b));
                        }
                    }
                }
            }
            if edges.is_empty() {
                return;
            }
            edges.sort_by(|x, y| x.0.total_cmp(&y.0).then((x.1, x.2).cmp(&(y.1, y.2))));
            let mut touched = vec![false; self.pos.len()];
            let mut changed = false;
            for &(_, a, b) in &edges {
                if touched[a as usize] || touched[b as usize] {
                    continue;
                }
                // keep = the vertex that stays, gone = the one removed
                let (keep, gone, target) = if !self.is_new(a) {
                    (a, b, self.pos[a as usize])
                } else if !self.is_new(b) {
                    (b, a, self.pos[b as usize])
                } else {
                    (a, b, (self.pos[a as usize] + self.pos[b as usize]) * 0.5)
                };
                if self.try_collapse(keep, gone, target, &nb, &vt) {
                    touched[a as usize] = true;
                    touched[b as usize] = true;
                    for &w in nb[a as usize].iter().chain(nb[b as usize].iter()) {
                        touched[w as usize] = true;
                    }
                    changed = true;
                }
            }
            if !changed {
                return;
            }
        }
    }

    fn try_collapse(
        &mut self,
        keep: u32,
        gone: u32,
        target: DVec3,
        nb: &[Vec<u32>],
        vt: &[Vec<u32>],
    ) -> bool {
        // link condition: the common neighbours are exactly the two opposite corners
        let na = &nb[keep as usize];
        let ng = &nb[gone as usize];
        let common: Vec<u32> = na.iter().filter(|x| ng.contains(x)).copied().collect();
        let shared: Vec<u32> = vt[gone as usize]
            .iter()
            .filter(|t| self.tris[**t as usize].contains(&keep))
            .copied()
            .collect();
        if shared.len() != 2 || common.len() != 2 {
            return false;
        }
        // a loop vertex whose edge to a new vertex is interior must keep a loop edge pair:
        // refuse if both are loop vertices (never happens: one is new)
        if !self.is_new(keep) && !self.is_new(gone) {
            return false;
        }
        // new edges keep-w for every neighbour w of gone
        for &w in ng {
            if w != keep && !common.contains(&w) && !self.edge_allowed(keep, w) {
                return false;
            }
        }
        // geometry: no triangle around keep or gone may flip or degenerate
        let moved = |v: u32| -> DVec3 {
            if v == keep || v == gone {
                target
            } else {
                self.pos[v as usize]
            }
        };
        let mut around: Vec<u32> = vt[keep as usize].clone();
        around.extend(vt[gone as usize].iter().copied());
        around.sort_unstable();
        around.dedup();
        for &t in &around {
            if shared.contains(&t) {
                continue;
            }
            let c = self.tris[t as usize];
            let [p, q, r] = c.map(|v| self.pos[v as usize]);
            let [p2, q2, r2] = c.map(moved);
            let n0 = measure::tri_normal_raw(p, q, r);
            let n1 = measure::tri_normal_raw(p2, q2, r2);
            if n1.dot(n0) <= 0.25 * n0.length() * n1.length() || n1.length() <= 0.0 {
                return false;
            }
            let ang = measure::angles(p2, q2, r2);
            if ang.iter().copied().fold(f64::INFINITY, f64::min) < 2f64.to_radians() {
                return false;
            }
        }
        // apply
        for &t in &shared {
            self.alive_t[t as usize] = false;
        }
        for &t in &vt[gone as usize] {
            if shared.contains(&t) {
                continue;
            }
            for v in self.tris[t as usize].iter_mut() {
                if *v == gone {
                    *v = keep;
                }
            }
        }
        self.pos[keep as usize] = target;
        self.alive_v[gone as usize] = false;
        true
    }

    /// Swaps an interior edge when that raises the smallest angle of its two
    /// triangles; never onto an existing edge, never flipping a triangle.
    pub fn swap(&mut self) {
        let max_passes = 100;
        for _ in 0..max_passes {
            let mut changed = false;
            // directed edge -> triangle
            let mut de: BTreeMap<(u32, u32), u32> = BTreeMap::new();
            for (ti, t) in self.tris.iter().enumerate() {
                if self.alive_t[ti] {
                    for c in 0..3 {
                        de.insert((t[c], t[(c + 1) % 3]), ti as u32);
                    }
                }
            }
            let mut touched = vec![false; self.tris.len()];
            let keys: Vec<(u32, u32)> = de.keys().copied().collect();
            // undirected edges, kept current as swaps happen
            let mut edges: BTreeSet<(u32, u32)> =
                keys.iter().map(|&(a, b)| edge_key(a, b)).collect();
            for (a, b) in keys {
                if a > b {
                    continue;
                }
                let (Some(&t1), Some(&t2)) = (de.get(&(a, b)), de.get(&(b, a))) else {
                    continue;
                };
                if touched[t1 as usize] || touched[t2 as usize] {
                    continue;
                }
                let c = third(self.tris[t1 as usize], a, b);
                let d = third(self.tris[t2 as usize], b, a);
                let (Some(c), Some(d)) = (c, d) else {
                    continue;
                };
                if c == d || edges.contains(&edge_key(c, d)) {
                    continue;
                }
                if !self.edge_allowed(c, d) {
                    continue;
                }
                let p = |v: u32| self.pos[v as usize];
                let old_min = min_angle(p(a), p(b), p(c)).min(min_angle(p(b), p(a), p(d)));
                // (a,b,c) + (b,a,d) -> (a,d,c) + (d,b,c)
                let new_min = min_angle(p(a), p(d), p(c)).min(min_angle(p(d), p(b), p(c)));
                if new_min <= old_min + 1e-9 {
                    continue;
                }
                let n_old = measure::tri_normal_raw(p(a), p(b), p(c))
                    + measure::tri_normal_raw(p(b), p(a), p(d));
                let n1 = measure::tri_normal_raw(p(a), p(d), p(c));
                let n2 = measure::tri_normal_raw(p(d), p(b), p(c));
                if n1.dot(n_old) <= 0.0 || n2.dot(n_old) <= 0.0 || n1.dot(n2) <= 0.0 {
                    continue;
                }
                self.tris[t1 as usize] = [a, d, c];
                self.tris[t2 as usize] = [d, b, c];
                edges.remove(&edge_key(a, b));
                edges.insert(edge_key(c, d));
                touched[t1 as usize] = true;
                touched[t2 as usize] = true;
                changed = true;
            }
            if !changed {
                return;
            }
        }
    }

    /// Fails when the patch still holds an edge between two loop vertices that the
    /// mesh already has (the triangulation can produce one; the swaps try to remove it).
    pub fn ensure_no_mesh_chords(&self) -> Result<(), FillError> {
        for (ti, t) in self.tris.iter().enumerate() {
            if !self.alive_t[ti] {
                continue;
            }
            for c in 0..3 {
                let (a, b) = (t[c], t[(c + 1) % 3]);
                if !self.edge_allowed(a, b) {
                    return Err(FillError::stuck(format!(
                        "hpde: the triangulation joins loop vertices {a} and {b}, \
                         already joined by a mesh edge"
                    )));
                }
            }
        }
        Ok(())
    }

    /// The patch: loop indices kept, new vertices renumbered densely.
    pub fn into_patch(self) -> Patch {
        let mut remap = vec![u32::MAX; self.pos.len()];
        let mut new_vertices = Vec::new();
        for (v, r) in remap.iter_mut().enumerate() {
            if v < self.k {
                *r = v as u32;
            } else if self.alive_v[v] {
                *r = (self.k + new_vertices.len()) as u32;
                new_vertices.push(self.pos[v]);
            }
        }
        let triangles = self
            .tris
            .iter()
            .zip(&self.alive_t)
            .filter(|(_, &a)| a)
            .map(|(t, _)| t.map(|v| remap[v as usize]))
            .collect();
        Patch {
            new_vertices,
            triangles,
        }
    }
}

fn third(t: [u32; 3], a: u32, b: u32) -> Option<u32> {
    for c in 0..3 {
        if t[c] == a && t[(c + 1) % 3] == b {
            return Some(t[(c + 2) % 3]);
        }
    }
    None
}

fn min_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let ang = measure::angles(a, b, c);
    ang[0].min(ang[1]).min(ang[2])
}
