//! The checks of [`Checker::check_patch_near`] for a sequence of patches over the same
//! vertices that differ by a few triangles at a time (the edge flips of
//! `fill::kit::retry`): every failing pair is recorded once, and a change
//! re-tests only its new triangles, so a flip trial costs a few thousand
//! instructions instead of a whole check.
//!
//! The failure reported is the one [`Checker::check_patch_near`] reports for the same
//! patch (tests compare the two on every trial): topology first (checked whole, it is
//! cheap), then the smallest degenerate triangle, then the smallest failing pair of
//! patch triangles, then the smallest patch triangle meeting a mesh face, with the
//! smallest such face.

use super::checker::{face_tri, patch_keys};
use super::quality::degenerate_reason;
use super::{
    check_topology, patch_positions, quality, CheckFailure, Degeneracy, Meets, TopologyFailure,
};
use crate::geometry::bvh::{boxes_meet, tri_box, Bvh};
use crate::geometry::predicates::{tri_axis, tri_tri_axes};
use crate::mesh::{Mesh, VertexId};
use crate::patch::Patch;
use crate::policy::Checks;
use crate::report::PatchQuality;
use glam::DVec3;

/// What the intersection tests need of a triangle.
#[derive(Clone, Debug)]
struct Tri {
    p: [DVec3; 3],
    k: [u64; 3],
    axis: Option<usize>,
    lo: DVec3,
    hi: DVec3,
}

impl Tri {
    fn new(p: [DVec3; 3], k: [u64; 3]) -> Tri {
        let (lo, hi) = tri_box(&p);
        Tri {
            p,
            k,
            axis: tri_axis(&p),
            lo,
            hi,
        }
    }
    fn meets(&self, o: &Tri) -> bool {
        boxes_meet(self.lo, self.hi, o.lo, o.hi)
            && tri_tri_axes(&self.p, &self.k, self.axis, &o.p, &o.k, o.axis)
    }
}

/// A patch with every failure of the checks recorded (see the module doc).
#[derive(Clone)]
pub struct PatchChecks<'a> {
    mesh: &'a Mesh,
    hole: &'a [VertexId],
    opts: &'a Checks,
    pos: Vec<DVec3>,
    keys: Vec<u64>,
    /// The mesh faces near the patch (index, triangle).
    near: Vec<(u32, Tri)>,
    patch: Patch,
    tris: Vec<Tri>,
    /// Why each patch triangle is degenerate (`None`: it is not).
    degenerate: Vec<Option<Degeneracy>>,
    /// Failing pairs of patch triangles `(i, j)`, `i < j`, ascending (pairs with a
    /// degenerate triangle are not tested: while it is there, it is what fails).
    pp: Vec<(usize, usize)>,
    /// Failing (patch triangle, mesh face) pairs, ascending.
    pm: Vec<(usize, u32)>,
    /// The topology check of the patch as it is now.
    topology: Result<(), CheckFailure>,
}

/// A change to a [`PatchChecks`]: triangles replaced, with what they fail.
pub struct Change {
    at: Vec<usize>,
    new: Vec<[u32; 3]>,
    tris: Vec<Tri>,
    degenerate: Vec<Option<Degeneracy>>,
    pp: Vec<(usize, usize)>,
    pm: Vec<(usize, u32)>,
}

impl<'a> PatchChecks<'a> {
    /// Records every failure of `patch` against the mesh faces `near` (from
    /// [`super::Checker::faces_near`] for a patch with the same box). `None` when a
    /// hole vertex or a patch index is out of range (the whole check reports that).
    pub fn new(
        mesh: &'a Mesh,
        hole: &'a [VertexId],
        patch: Patch,
        opts: &'a Checks,
        near: &[u32],
    ) -> Option<PatchChecks<'a>> {
        if hole.iter().any(|v| v.idx() >= mesh.num_vertices()) {
            return None;
        }
        let pos = patch_positions(mesh, hole, &patch);
        if patch
            .triangles
            .iter()
            .any(|t| t.iter().any(|&i| i as usize >= pos.len()))
        {
            return None;
        }
        let keys = patch_keys(mesh, hole, pos.len());
        let mut s = PatchChecks {
            mesh,
            hole,
            opts,
            pos,
            keys,
            near: Vec::new(),
            patch,
            tris: Vec::new(),
            degenerate: Vec::new(),
            pp: Vec::new(),
            pm: Vec::new(),
            topology: Ok(()),
        };
        s.topology = check_topology(mesh, hole, &s.patch);
        let min_angle = opts.min_angle_deg.to_radians();
        s.tris = s.patch.triangles.iter().map(|t| s.tri(t)).collect();
        s.degenerate = s
            .patch
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| s.pos[i as usize]);
                degenerate_reason(a, b, c, min_angle)
            })
            .collect();
        if opts.self_intersection {
            s.near = near
                .iter()
                .filter_map(|&f| {
                    let (p, k) = face_tri(mesh, f as usize)?;
                    let mut t = Tri::new(p, k);
                    if !(t.lo.is_finite() && t.hi.is_finite()) {
                        t.lo = DVec3::splat(f64::NEG_INFINITY);
                        t.hi = DVec3::splat(f64::INFINITY);
                    }
                    Some((f, t))
                })
                .collect();
            let ok = |i: usize| s.degenerate[i].is_none();
            let boxes: Vec<(DVec3, DVec3)> = s.tris.iter().map(|t| (t.lo, t.hi)).collect();
            let tree = Bvh::build(boxes.len(), |i| boxes[i]);
            let mut pp = Vec::new();
            tree.self_pairs(|a, b| {
                let (i, j) = (a.min(b), a.max(b));
                if i != j && ok(i) && ok(j) && s.tris[i].meets(&s.tris[j]) {
                    pp.push((i, j));
                }
            });
            pp.sort_unstable();
            pp.dedup();
            let mut pm = Vec::new();
            for (f, q) in &s.near {
                tree.query(q.lo, q.hi, |i| {
                    if ok(i) && s.tris[i].meets(q) {
                        pm.push((i, *f));
                    }
                    false
                });
            }
            pm.sort_unstable();
            pm.dedup();
            s.pp = pp;
            s.pm = pm;
        }
        Some(s)
    }

    fn tri(&self, t: &[u32; 3]) -> Tri {
        Tri::new(
            t.map(|i| self.pos[i as usize]),
            t.map(|i| self.keys[i as usize]),
        )
    }

    /// The patch as it is now.
    pub fn patch(&self) -> &Patch {
        &self.patch
    }

    /// What [`super::Checker::check_patch_near`] says of the patch as it is now.
    pub fn result(&self) -> Result<PatchQuality, CheckFailure> {
        self.topology.clone()?;
        if let Some((i, r)) = self
            .degenerate
            .iter()
            .enumerate()
            .find_map(|(i, d)| d.as_ref().map(|r| (i, r)))
        {
            return Err(CheckFailure::Degenerate {
                triangle: i,
                why: *r,
            });
        }
        if self.opts.self_intersection {
            if let Some(&(i, j)) = self.pp.first() {
                return Err(CheckFailure::SelfIntersection {
                    triangle: i,
                    meets: Meets::PatchTriangle(j),
                });
            }
            if let Some(&(i, f)) = self.pm.first() {
                return Err(CheckFailure::SelfIntersection {
                    triangle: i,
                    meets: Meets::MeshFace(f as usize),
                });
            }
        }
        Ok(quality(&self.pos, self.hole.len(), &self.patch))
    }

    /// What [`super::Checker::check_patch_near`] says of `q`: this patch with the
    /// triangles `removed` (ascending) taken out and `added` (in this patch's
    /// numbering) put after the others, renumbered (vertices no triangle uses
    /// dropped, the others in order). Only the added triangles are tested; `q`
    /// itself is used for the topology and the quality. Changes nothing.
    pub fn replaced(
        &self,
        removed: &[usize],
        added: &[[u32; 3]],
        q: &Patch,
    ) -> Result<PatchQuality, CheckFailure> {
        check_topology(self.mesh, self.hole, q)?;
        let gone = |i: usize| removed.binary_search(&i).is_ok();
        // index in `q` of each kept triangle
        let mut at = vec![usize::MAX; self.tris.len()];
        let mut kept = 0usize;
        for (i, a) in at.iter_mut().enumerate() {
            if !gone(i) {
                *a = kept;
                kept += 1;
            }
        }
        if let Some((i, r)) = (0..self.tris.len())
            .filter(|&i| !gone(i))
            .find_map(|i| self.degenerate[i].as_ref().map(|r| (at[i], r)))
        {
            return Err(CheckFailure::Degenerate {
                triangle: i,
                why: *r,
            });
        }
        let min_angle = self.opts.min_angle_deg.to_radians();
        for (a, t) in added.iter().enumerate() {
            if t.iter().any(|&i| i as usize >= self.pos.len()) {
                return Err(CheckFailure::Topology(TopologyFailure::IndexOutOfRange(
                    kept + a,
                )));
            }
            let [x, y, z] = t.map(|i| self.pos[i as usize]);
            if let Some(r) = degenerate_reason(x, y, z, min_angle) {
                return Err(CheckFailure::Degenerate {
                    triangle: kept + a,
                    why: r,
                });
            }
        }
        if self.opts.self_intersection {
            let new: Vec<Tri> = added.iter().map(|t| self.tri(t)).collect();
            let mut pp: Vec<(usize, usize)> = self
                .pp
                .iter()
                .filter(|(i, j)| !gone(*i) && !gone(*j))
                .map(|&(i, j)| (at[i], at[j]))
                .collect();
            for (a, t) in new.iter().enumerate() {
                for (j, o) in self.tris.iter().enumerate() {
                    // the kept triangle comes first in `q`
                    if !gone(j) && o.meets(t) {
                        pp.push((at[j], kept + a));
                    }
                }
                for (b, o) in new.iter().enumerate().skip(a + 1) {
                    if t.meets(o) {
                        pp.push((kept + a, kept + b));
                    }
                }
            }
            if let Some(&(i, j)) = pp.iter().min() {
                return Err(CheckFailure::SelfIntersection {
                    triangle: i,
                    meets: Meets::PatchTriangle(j),
                });
            }
            let mut pm: Vec<(usize, u32)> = self
                .pm
                .iter()
                .filter(|(i, _)| !gone(*i))
                .map(|&(i, f)| (at[i], f))
                .collect();
            for (a, t) in new.iter().enumerate() {
                for (f, o) in &self.near {
                    if t.meets(o) {
                        pm.push((kept + a, *f));
                    }
                }
            }
            if let Some(&(i, f)) = pm.iter().min() {
                return Err(CheckFailure::SelfIntersection {
                    triangle: i,
                    meets: Meets::MeshFace(f as usize),
                });
            }
        }
        let pos = patch_positions(self.mesh, self.hole, q);
        Ok(quality(&pos, self.hole.len(), q))
    }

    /// The patch with triangles `at[i]` replaced by `new[i]` (distinct indices, in
    /// range), and what the checks say of it: the result of
    /// [`super::Checker::check_patch_near`] on it. Changes nothing; [`Self::apply`]
    /// keeps the change.
    pub fn trial(
        &self,
        at: &[usize],
        new: &[[u32; 3]],
    ) -> (Change, Patch, Result<PatchQuality, CheckFailure>) {
        let mut q = self.patch.clone();
        for (&i, t) in at.iter().zip(new) {
            q.triangles[i] = *t;
        }
        let mut change = Change {
            at: at.to_vec(),
            new: new.to_vec(),
            tris: Vec::new(),
            degenerate: Vec::new(),
            pp: Vec::new(),
            pm: Vec::new(),
        };
        let topology = match self.flipped_edge(at, new) {
            Some((c, d)) => self.flip_topology(c, d),
            None => check_topology(self.mesh, self.hole, &q),
        };
        #[cfg(debug_assertions)]
        debug_assert_eq!(topology, check_topology(self.mesh, self.hole, &q));
        if let Err(e) = topology {
            return (change, q, Err(e));
        }
        let min_angle = self.opts.min_angle_deg.to_radians();
        change.tris = new.iter().map(|t| self.tri(t)).collect();
        change.degenerate = new
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.pos[i as usize]);
                degenerate_reason(a, b, c, min_angle)
            })
            .collect();
        let changed = |i: usize| at.contains(&i);
        let degenerate_now =
            (0..self.degenerate.len()).find_map(|i| match at.iter().position(|&x| x == i) {
                Some(c) => change.degenerate[c].as_ref().map(|r| (i, r)),
                None => self.degenerate[i].as_ref().map(|r| (i, r)),
            });
        if let Some((i, r)) = degenerate_now {
            let e = CheckFailure::Degenerate {
                triangle: i,
                why: *r,
            };
            return (change, q, Err(e));
        }
        if self.opts.self_intersection {
            // every triangle is non-degenerate now: test the new ones against the rest
            let mut pp: Vec<(usize, usize)> = Vec::new();
            let mut pm: Vec<(usize, u32)> = Vec::new();
            for (c, &i) in at.iter().enumerate() {
                let t = &change.tris[c];
                for (j, o) in self.tris.iter().enumerate() {
                    if changed(j) {
                        continue;
                    }
                    let (a, b) = (i.min(j), i.max(j));
                    let hit = if a == i { t.meets(o) } else { o.meets(t) };
                    if hit {
                        pp.push((a, b));
                    }
                }
                for (d, &j) in at.iter().enumerate().skip(c + 1) {
                    let o = &change.tris[d];
                    let hit = if i < j { t.meets(o) } else { o.meets(t) };
                    if hit {
                        pp.push((i.min(j), i.max(j)));
                    }
                }
                for (f, o) in &self.near {
                    if t.meets(o) {
                        pm.push((i, *f));
                    }
                }
            }
            pp.extend(self.pp.iter().filter(|(i, j)| !changed(*i) && !changed(*j)));
            pm.extend(self.pm.iter().filter(|(i, _)| !changed(*i)));
            pp.sort_unstable();
            pp.dedup();
            pm.sort_unstable();
            pm.dedup();
            let first_pp = pp.first().copied();
            let first_pm = pm.first().copied();
            change.pp = pp;
            change.pm = pm;
            if let Some((i, j)) = first_pp {
                let e = CheckFailure::SelfIntersection {
                    triangle: i,
                    meets: Meets::PatchTriangle(j),
                };
                return (change, q, Err(e));
            }
            if let Some((i, f)) = first_pm {
                let e = CheckFailure::SelfIntersection {
                    triangle: i,
                    meets: Meets::MeshFace(f as usize),
                };
                return (change, q, Err(e));
            }
        }
        let quality = quality(&self.pos, self.hole.len(), &q);
        (change, q, Ok(quality))
    }

    /// `Some((c, d))` when replacing triangles `at` by `new` flips an interior edge
    /// of a patch that passes the topology check (`[a, b, c]` and `[b, a, d]` become
    /// `[a, d, c]` and `[b, c, d]`, with no edge `c-d` yet): the patch then stays a
    /// disk closing the loop (the same vertices, edges and faces but for `a-b`
    /// replaced by `c-d`), and only the new edge can fail the check.
    fn flipped_edge(&self, at: &[usize], new: &[[u32; 3]]) -> Option<(u32, u32)> {
        if self.topology.is_err() || at.len() != 2 || new.len() != 2 || at[0] == at[1] {
            return None;
        }
        let (t, u) = (
            *self.patch.triangles.get(at[0])?,
            *self.patch.triangles.get(at[1])?,
        );
        for r in 0..3 {
            let (a, b, c) = (t[r], t[(r + 1) % 3], t[(r + 2) % 3]);
            let Some(e) = (0..3).find(|&e| u[e] == b && u[(e + 1) % 3] == a) else {
                continue;
            };
            let d = u[(e + 2) % 3];
            if c == d || new[0] != [a, d, c] || new[1] != [b, c, d] {
                return None;
            }
            let has_cd = self.patch.triangles.iter().any(|x| {
                (0..3).any(|i| {
                    let (p, q) = (x[i], x[(i + 1) % 3]);
                    (p == c && q == d) || (p == d && q == c)
                })
            });
            return (!has_cd).then_some((c, d));
        }
        None
    }

    /// The topology check of a patch made by [`Self::flipped_edge`]'s flip: the new
    /// edge `c-d`, a chord when both are loop vertices, must not be an edge of the
    /// mesh already.
    fn flip_topology(&self, c: u32, d: u32) -> Result<(), CheckFailure> {
        let (a, b) = (c.min(d), c.max(d));
        let k = self.hole.len();
        if (b as usize) < k {
            let (va, vb) = (self.hole[a as usize], self.hole[b as usize]);
            if self.mesh.topo.neighbors(va).contains(&vb) {
                return Err(CheckFailure::Topology(TopologyFailure::ChordIsMeshEdge(
                    a, b,
                )));
            }
        }
        Ok(())
    }

    /// Keeps a change made by [`Self::trial`] on this state. A change whose topology
    /// failed (its triangles were not tested) is refused: `false`, nothing changed.
    pub fn apply(&mut self, change: Change) -> bool {
        if change.tris.len() != change.at.len() {
            return false;
        }
        // the trial tested the triangles only when the topology passed
        self.topology = Ok(());
        let at = change.at.clone();
        for (c, &i) in at.iter().enumerate() {
            self.patch.triangles[i] = change.new[c];
            self.tris[i] = change.tris[c].clone();
            self.degenerate[i] = change.degenerate[c];
        }
        if self.opts.self_intersection {
            if change.degenerate.iter().all(Option::is_none)
                && self.degenerate.iter().all(Option::is_none)
            {
                // the trial tested every pair with a new triangle
                self.pp = change.pp;
                self.pm = change.pm;
            } else {
                // it stopped at a degenerate triangle: test the new ones here
                self.retest(&at);
            }
        }
        true
    }

    /// Re-tests the pairs of the triangles `at` (after they changed).
    fn retest(&mut self, at: &[usize]) {
        let changed = |i: usize| at.contains(&i);
        self.pp.retain(|(i, j)| !changed(*i) && !changed(*j));
        self.pm.retain(|(i, _)| !changed(*i));
        for &i in at {
            if self.degenerate[i].is_some() {
                continue;
            }
            for j in 0..self.tris.len() {
                if j == i || self.degenerate[j].is_some() || (changed(j) && j < i) {
                    continue;
                }
                let (a, b) = (i.min(j), i.max(j));
                if self.tris[a].meets(&self.tris[b]) {
                    self.pp.push((a, b));
                }
            }
            for (f, o) in &self.near {
                if self.tris[i].meets(o) {
                    self.pm.push((i, *f));
                }
            }
        }
        self.pp.sort_unstable();
        self.pp.dedup();
        self.pm.sort_unstable();
        self.pm.dedup();
    }
}
