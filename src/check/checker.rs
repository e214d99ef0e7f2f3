//! The [`Checker`]: the whole-patch check against the mesh (topology, degenerate
//! triangles, intersections with the patch itself and with every mesh face), with the
//! broad phase over the mesh's face boxes: scanned linearly in `f32` blocks, or a tree
//! over them once many checks are expected, plus the faces committed since.

use super::{check_degenerate, check_topology, patch_positions, quality};
use super::{CheckFailure, Meets, TopologyFailure};
use crate::geometry::bvh::{boxes_meet, f32_down, f32_up, tri_box, Bvh};
use crate::geometry::predicates::{tri_axis, tri_tri_axes};
use crate::mesh::{Mesh, VertexId};
use crate::patch::Patch;
use crate::policy::Checks;
use crate::report::PatchQuality;
use glam::DVec3;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

/// Holds what the checks need across holes. For the faces the mesh had at
/// construction: their boxes (`f32`, see [`FaceBox`]), scanned linearly for the faces
/// near a patch, and a bounding-volume hierarchy over them, built when many checks are
/// expected or once the scans have cost about as much as building it
/// ([`SCANS_BEFORE_TREE`]). For the faces committed since: a logarithmic set of smaller
/// trees (Bentley-Saxe: a full tail of `TAIL` faces becomes a tree, and trees of similar
/// size are merged), plus the tail scanned linearly.
///
/// Every check reports the same failure whatever finds the candidates (scan or tree):
/// the smallest failing patch triangle, and for it the smallest other triangle or mesh
/// face it meets. So results never depend on thread timing or on when a tree was built.
pub struct Checker {
    /// Boxes of the faces the mesh had at construction (computed on first use, or
    /// by [`Checker::prepare`] as the first job of the proposal phase, while the
    /// other thread starts on the biggest hole).
    pub(super) boxes: OnceLock<FaceBoxes>,
    /// Number of faces the mesh had at construction.
    pub(super) base_faces: usize,
    /// Checks expected (the tree is built with the boxes when above
    /// [`SCANS_BEFORE_TREE`]).
    pub(super) expected: usize,
    /// Tree over those faces, once built.
    pub(super) base: OnceLock<Bvh>,
    /// Scans of `boxes` so far.
    pub(super) scans: AtomicUsize,
    /// Trees over committed faces, sizes decreasing.
    pub(super) levels: Vec<Level>,
    /// Committed faces not yet in a tree (fewer than `tail_max`).
    pub(super) tail: Vec<u32>,
    /// Size at which the tail becomes a tree ([`TAIL`]; smaller in tests).
    pub(super) tail_max: usize,
    /// First face index not yet in `boxes`, `levels` or `tail`.
    pub(super) next_unseen: usize,
}

/// A face's box in `f32`: the bounds of its corners rounded to the nearest `f32`.
/// Rounding is monotone, so a face whose exact box meets a box `[lo, hi]` meets
/// `[f32_down(lo), f32_up(hi)]` here too ([`FaceBox::meets`]: a superset, tested
/// exactly afterwards); [`FaceBox::as_f64`] widens it by a step to hold the exact box.
#[derive(Clone, Copy, Debug)]
struct FaceBox {
    lo: [f32; 3],
    hi: [f32; 3],
}

impl FaceBox {
    /// Meets the closed box `[ql, qh]` (a query box rounded outwards to `f32`).
    #[inline]
    fn meets(&self, ql: [f32; 3], qh: [f32; 3]) -> bool {
        (self.lo[0] <= qh[0])
            & (ql[0] <= self.hi[0])
            & (self.lo[1] <= qh[1])
            & (ql[1] <= self.hi[1])
            & (self.lo[2] <= qh[2])
            & (ql[2] <= self.hi[2])
    }
    /// The box of everything (for a face with a non-finite corner).
    const EVERYTHING: FaceBox = FaceBox {
        lo: [f32::NEG_INFINITY; 3],
        hi: [f32::INFINITY; 3],
    };
    /// A box holding the face's exact box (one `f32` step out from the rounded one).
    fn as_f64(&self) -> (DVec3, DVec3) {
        let lo = self.lo.map(|x| x.next_down() as f64);
        let hi = self.hi.map(|x| x.next_up() as f64);
        (DVec3::from_array(lo), DVec3::from_array(hi))
    }
}

/// `[lo, hi]` rounded outwards to `f32`, for [`FaceBox::meets`].
fn query_f32(lo: DVec3, hi: DVec3) -> ([f32; 3], [f32; 3]) {
    (lo.to_array().map(f32_down), hi.to_array().map(f32_up))
}

/// The boxes of many faces, one array per bound (`lo.x, lo.y, lo.z, hi.x, hi.y,
/// hi.z`), so that a scan compares whole blocks of faces at once.
#[derive(Default)]
pub(super) struct FaceBoxes {
    b: [Vec<f32>; 6],
}

/// Faces compared at once by [`FaceBoxes::scan`] (a bit mask per block).
const SCAN_BLOCK: usize = 16;

impl FaceBoxes {
    fn len(&self) -> usize {
        self.b[0].len()
    }
    fn get(&self, f: usize) -> FaceBox {
        FaceBox {
            lo: [self.b[0][f], self.b[1][f], self.b[2][f]],
            hi: [self.b[3][f], self.b[4][f], self.b[5][f]],
        }
    }
    /// Appends to `out` the faces whose box meets the closed box `[ql, qh]`,
    /// ascending. Compared in `f32` in blocks of [`SCAN_BLOCK`] faces, without a
    /// branch per face (the compiler makes vector compares of it).
    fn scan(&self, ql: [f32; 3], qh: [f32; 3], out: &mut Vec<u32>) {
        let n = self.len();
        let [lx, ly, lz, hx, hy, hz] = &self.b;
        let meets = |f: usize| {
            (lx[f] <= qh[0])
                & (ql[0] <= hx[f])
                & (ly[f] <= qh[1])
                & (ql[1] <= hy[f])
                & (lz[f] <= qh[2])
                & (ql[2] <= hz[f])
        };
        let full = n - n % SCAN_BLOCK;
        let mut base = 0;
        while base < full {
            let (lx, ly, lz) = (
                &lx[base..base + SCAN_BLOCK],
                &ly[base..base + SCAN_BLOCK],
                &lz[base..base + SCAN_BLOCK],
            );
            let (hx, hy, hz) = (
                &hx[base..base + SCAN_BLOCK],
                &hy[base..base + SCAN_BLOCK],
                &hz[base..base + SCAN_BLOCK],
            );
            let mut mask = 0u32;
            for i in 0..SCAN_BLOCK {
                let m = (lx[i] <= qh[0])
                    & (ql[0] <= hx[i])
                    & (ly[i] <= qh[1])
                    & (ql[1] <= hy[i])
                    & (lz[i] <= qh[2])
                    & (ql[2] <= hz[i]);
                mask |= (m as u32) << i;
            }
            while mask != 0 {
                let i = mask.trailing_zeros() as usize;
                out.push((base + i) as u32);
                mask &= mask - 1;
            }
            base += SCAN_BLOCK;
        }
        out.extend((full..n).filter(|&f| meets(f)).map(|f| f as u32));
    }
}

/// A tree over some committed faces.
pub(super) struct Level {
    pub(super) faces: Vec<u32>,
    tree: Bvh,
}

impl Level {
    fn new(mesh: &Mesh, faces: Vec<u32>) -> Level {
        let tree = Bvh::build(faces.len(), |i| face_box(mesh, faces[i] as usize));
        Level { faces, tree }
    }
}

/// Committed faces scanned linearly before they are put in a tree. A scan of the tail
/// costs a few instructions per face, a tree over it about a hundred per face, and
/// most meshes get fewer new faces than this in all (the bench's ten holes add 1,900
/// to 2,500): their patches are checked against the faces added before them without
/// a tree (commits on the bench: 3.2M -> 0.1M instructions per mesh).
const TAIL: usize = 4096;

/// Scans of the face boxes after which the tree over them is built (a scan costs about
/// a hundredth of the build, so this keeps the total within twice the better choice).
pub const SCANS_BEFORE_TREE: usize = 64;

impl Checker {
    /// Prepares the checks for a mesh (the face boxes; the tree when needed).
    pub fn new(mesh: &Mesh) -> Checker {
        Checker::for_checks(mesh, 0)
    }

    /// [`Checker::new`] for about `expected` patch checks: with more than
    /// [`SCANS_BEFORE_TREE`] the tree is built with the boxes. Nothing is computed
    /// here: the face boxes on first use or by [`Checker::prepare`].
    pub fn for_checks(mesh: &Mesh, expected: usize) -> Checker {
        let nf = mesh.num_faces();
        Checker {
            boxes: OnceLock::new(),
            base_faces: nf,
            expected,
            base: OnceLock::new(),
            scans: AtomicUsize::new(0),
            levels: Vec::new(),
            tail: Vec::new(),
            tail_max: TAIL,
            next_unseen: nf,
        }
    }

    /// Computes what the checks need of the mesh (`mesh` as given at construction,
    /// or with faces added since): the face boxes, and the tree when many checks are
    /// expected. Called by one thread while the others start on the holes; a check
    /// that comes first computes them itself (or waits for this to finish).
    pub fn prepare(&self, mesh: &Mesh) {
        self.boxes(mesh);
        if self.expected > SCANS_BEFORE_TREE {
            self.tree(mesh);
        }
    }

    /// The boxes of the construction-time faces (computed on first call; see
    /// [`FaceBox`]). A face with a non-finite corner (or out of range) gets the box
    /// of everything, as in the tree: always a candidate.
    fn boxes(&self, mesh: &Mesh) -> &FaceBoxes {
        self.boxes.get_or_init(|| {
            let faces = mesh.topo.faces();
            let faces = &faces[..self.base_faces.min(faces.len())];
            let pos = &mesh.positions;
            let n = faces.len();
            let mut b: [Vec<f32>; 6] = std::array::from_fn(|_| vec![0.0; n]);
            let [lx, ly, lz, hx, hy, hz] = &mut b;
            let slots = lx
                .iter_mut()
                .zip(ly.iter_mut())
                .zip(lz.iter_mut())
                .zip(hx.iter_mut().zip(hy.iter_mut()).zip(hz.iter_mut()));
            let np = pos.len();
            for (f, (((lx, ly), lz), ((hx, hy), hz))) in faces.iter().zip(slots) {
                let (i, j, k) = (f[0].idx(), f[1].idx(), f[2].idx());
                let fb = if i.max(j).max(k) < np {
                    let (a, b, c) = (pos[i], pos[j], pos[k]);
                    // plain comparisons (f64::min also handles NaN); a NaN, an
                    // infinity or a coordinate beyond the f32 range gives a
                    // non-finite bound (or a sum of bounds past the f32 range, when
                    // the box of everything is only a wider box than needed), and
                    // the box of everything
                    let lo = |x: f64, y: f64| if y < x { y } else { x };
                    let hi = |x: f64, y: f64| if y > x { y } else { x };
                    let l = [
                        lo(lo(a.x, b.x), c.x) as f32,
                        lo(lo(a.y, b.y), c.y) as f32,
                        lo(lo(a.z, b.z), c.z) as f32,
                    ];
                    let h = [
                        hi(hi(a.x, b.x), c.x) as f32,
                        hi(hi(a.y, b.y), c.y) as f32,
                        hi(hi(a.z, b.z), c.z) as f32,
                    ];
                    if (l[0] - h[0] + l[1] - h[1] + l[2] - h[2]).is_finite() {
                        FaceBox { lo: l, hi: h }
                    } else {
                        FaceBox::EVERYTHING
                    }
                } else {
                    FaceBox::EVERYTHING
                };
                (*lx, *ly, *lz) = (fb.lo[0], fb.lo[1], fb.lo[2]);
                (*hx, *hy, *hz) = (fb.hi[0], fb.hi[1], fb.hi[2]);
            }
            FaceBoxes { b }
        })
    }

    /// The tree over the construction-time faces (built on first call).
    fn tree(&self, mesh: &Mesh) -> &Bvh {
        self.base.get_or_init(|| {
            let boxes = self.boxes(mesh);
            Bvh::build(boxes.len(), |f| boxes.get(f).as_f64())
        })
    }

    /// Checks a patch for a hole; on success returns its quality.
    ///
    /// Order: topology (an oriented disk closing the loop exactly), degenerate
    /// triangles, then, with `opts.self_intersection`, intersections of every patch
    /// triangle with the other patch triangles and with every face of the mesh.
    pub fn check_patch(
        &self,
        mesh: &Mesh,
        hole: &[VertexId],
        patch: &Patch,
        opts: &Checks,
    ) -> Result<PatchQuality, CheckFailure> {
        self.check_patch_near(mesh, hole, patch, opts, None)
    }

    /// The mesh faces whose boxes meet the box of the patch's triangles (what
    /// [`Checker::check_patch`] tests the patch against; compared in `f32`, so a
    /// few more, which meet no triangle of the patch), ascending. For checking many
    /// patches over the same vertices at the same places (edge flips of one patch) with
    /// [`Checker::check_patch_near`], without finding them again each time.
    pub fn faces_near(&self, mesh: &Mesh, hole: &[VertexId], patch: &Patch) -> Vec<u32> {
        let pos = patch_positions(mesh, hole, patch);
        let (lo, hi) = patch_box(&pos, patch);
        self.candidates(mesh, lo, hi, true)
    }

    /// [`Checker::check_patch`] with the candidate mesh faces given (`near`, from
    /// [`Checker::faces_near`] for a patch whose triangles have the same box; `None`:
    /// found here). Same result.
    pub fn check_patch_near(
        &self,
        mesh: &Mesh,
        hole: &[VertexId],
        patch: &Patch,
        opts: &Checks,
        near: Option<&[u32]>,
    ) -> Result<PatchQuality, CheckFailure> {
        if let Some(v) = hole.iter().find(|v| v.idx() >= mesh.num_vertices()) {
            return Err(CheckFailure::Topology(TopologyFailure::HoleVertexMissing(
                *v,
            )));
        }
        check_topology(mesh, hole, patch)?;
        let pos = patch_positions(mesh, hole, patch);
        check_degenerate(&pos, patch, opts)?;
        if opts.self_intersection {
            self.check_intersections(mesh, hole, patch, &pos, true, near)?;
        }
        Ok(quality(&pos, hole.len(), patch))
    }

    /// For a patch that passed [`Checker::check_patch`] against the mesh this checker
    /// was built on: checks it against the faces added since (the patches of other
    /// holes). The topology and degeneracy checks do not depend on them (loops are
    /// vertex-disjoint), so only intersections are tested.
    pub fn check_against_added(
        &self,
        mesh: &Mesh,
        hole: &[VertexId],
        patch: &Patch,
        opts: &Checks,
    ) -> Result<(), CheckFailure> {
        if !opts.self_intersection
            || self.levels.is_empty()
                && self.tail.is_empty()
                && self.next_unseen >= mesh.num_faces()
        {
            return Ok(());
        }
        let pos = patch_positions(mesh, hole, patch);
        self.check_intersections(mesh, hole, patch, &pos, false, None)
    }

    /// Faces committed since construction (in the trees or the tail).
    #[cfg(test)]
    pub(crate) fn committed_faces(&self) -> usize {
        self.levels.iter().map(|l| l.faces.len()).sum::<usize>() + self.tail.len()
    }

    /// Records that the faces in `faces` (indices into the mesh) were added. Faces
    /// appended to the mesh earlier without a commit are indexed too, so every face
    /// of the mesh is always checked against.
    pub fn commit(&mut self, mesh: &Mesh, faces: std::ops::Range<usize>) {
        let end = faces.end.max(self.next_unseen).min(mesh.num_faces());
        for f in self.next_unseen..end {
            self.tail.push(f as u32);
        }
        self.next_unseen = self.next_unseen.max(end);
        if self.tail.len() < self.tail_max {
            return;
        }
        let mut faces = std::mem::take(&mut self.tail);
        // merge with every smaller-or-equal level at the end (a binary counter)
        while let Some(last) = self.levels.last() {
            if last.faces.len() > faces.len() {
                break;
            }
            if let Some(l) = self.levels.pop() {
                faces.extend_from_slice(&l.faces);
            }
        }
        self.levels.push(Level::new(mesh, faces));
    }

    /// Mesh faces whose box meets `[lo, hi]`, ascending (construction-time faces with
    /// `with_base`, always the faces added since).
    fn candidates(&self, mesh: &Mesh, lo: DVec3, hi: DVec3, with_base: bool) -> Vec<u32> {
        let mut out: Vec<u32> = Vec::new();
        if with_base {
            let n = self.scans.fetch_add(1, Ordering::Relaxed);
            let boxes = self.boxes(mesh);
            // compared in f32, against the query box rounded outwards: a superset of
            // the faces whose box meets it (the few more ones are tested exactly
            // like the others, and meet no triangle)
            let (ql, qh) = query_f32(lo, hi);
            match self.base.get() {
                Some(t) => t.query(lo, hi, |f| {
                    if boxes.get(f).meets(ql, qh) {
                        out.push(f as u32);
                    }
                    false
                }),
                None if n >= SCANS_BEFORE_TREE => self.tree(mesh).query(lo, hi, |f| {
                    if boxes.get(f).meets(ql, qh) {
                        out.push(f as u32);
                    }
                    false
                }),
                None => {
                    boxes.scan(ql, qh, &mut out);
                    false
                }
            };
        }
        let meets = |f: usize| {
            let (a, b) = face_box(mesh, f);
            boxes_meet(lo, hi, a, b) || !(a.is_finite() && b.is_finite())
        };
        for l in &self.levels {
            l.tree.query(lo, hi, |j| {
                let f = l.faces[j] as usize;
                if meets(f) {
                    out.push(f as u32);
                }
                false
            });
        }
        out.extend(self.tail.iter().copied().filter(|&f| meets(f as usize)));
        out.extend(
            (self.next_unseen..mesh.num_faces())
                .filter(|&f| meets(f))
                .map(|f| f as u32),
        );
        out.sort_unstable();
        out
    }

    /// The self-intersection check (see [`crate::geometry::predicates::tri_tri`] for the rules on shared vertices).
    /// The failure reported is the smallest failing patch triangle `i`: first against
    /// the other patch triangles (with `against_base`; the smallest other one it meets),
    /// then against the mesh faces (the smallest face it meets).
    pub(super) fn check_intersections(
        &self,
        mesh: &Mesh,
        hole: &[VertexId],
        patch: &Patch,
        pos: &[DVec3],
        against_base: bool,
        given: Option<&[u32]>,
    ) -> Result<(), CheckFailure> {
        if patch.triangles.is_empty() {
            return Ok(());
        }
        // the faces near the patch's box first: against the faces added since the
        // proposal there are usually none, and nothing else is needed
        let near = match given {
            Some(n) => n.to_vec(),
            None => {
                let (plo, phi) = patch_box(pos, patch);
                self.candidates(mesh, plo, phi, against_base)
            }
        };
        if !against_base && near.is_empty() {
            return Ok(());
        }
        let keys = patch_keys(mesh, hole, pos.len());
        let tris: Vec<([DVec3; 3], [u64; 3])> = patch
            .triangles
            .iter()
            .map(|t| (t.map(|i| pos[i as usize]), t.map(|i| keys[i as usize])))
            .collect();
        let boxes: Vec<(DVec3, DVec3)> = tris.iter().map(|(p, _)| tri_box(p)).collect();
        let axes: Vec<Option<usize>> = tris.iter().map(|(p, _)| tri_axis(p)).collect();
        let ptree = Bvh::build(tris.len(), |i| boxes[i]);
        // patch against patch: every pair whose boxes meet, the smallest failing one
        // kept (the walk's order is not that of the pairs)
        if against_base {
            let mut hit: Option<(usize, usize)> = None;
            ptree.self_pairs(|a, b| {
                let (i, j) = (a.min(b), a.max(b));
                if hit.is_none_or(|h| (i, j) < h)
                    && boxes_meet(boxes[i].0, boxes[i].1, boxes[j].0, boxes[j].1)
                {
                    let ((p, pk), (q, qk)) = (&tris[i], &tris[j]);
                    if tri_tri_axes(p, pk, axes[i], q, qk, axes[j]) {
                        hit = Some((i, j));
                    }
                }
            });
            if let Some((i, j)) = hit {
                return Err(CheckFailure::SelfIntersection {
                    triangle: i,
                    meets: Meets::PatchTriangle(j),
                });
            }
        }
        // patch against mesh: each nearby face against the patch triangles near it;
        // faces ascending, so for the smallest failing triangle the first face found
        // is the smallest
        let mut hit: Option<(usize, u32)> = None;
        for &f in &near {
            let Some((q, qk)) = face_tri(mesh, f as usize) else {
                continue;
            };
            let qa = tri_axis(&q);
            let (qlo, qhi) = tri_box(&q);
            let (qlo, qhi) = if qlo.is_finite() && qhi.is_finite() {
                (qlo, qhi)
            } else {
                (DVec3::splat(f64::NEG_INFINITY), DVec3::splat(f64::INFINITY))
            };
            ptree.query(qlo, qhi, |i| {
                if hit.is_none_or(|(h, _)| i < h) && boxes_meet(boxes[i].0, boxes[i].1, qlo, qhi) {
                    let (p, pk) = &tris[i];
                    if tri_tri_axes(p, pk, axes[i], &q, &qk, qa) {
                        hit = Some((i, f));
                    }
                }
                false
            });
        }
        match hit {
            Some((i, f)) => Err(CheckFailure::SelfIntersection {
                triangle: i,
                meets: Meets::MeshFace(f as usize),
            }),
            None => Ok(()),
        }
    }
}

/// Box of the patch's triangles (`pos`: loop vertices, then new ones).
fn patch_box(pos: &[DVec3], patch: &Patch) -> (DVec3, DVec3) {
    patch.triangles.iter().flatten().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &i| {
            let p = pos.get(i as usize).copied().unwrap_or(DVec3::NAN);
            (lo.min(p), hi.max(p))
        },
    )
}

/// Keys of new patch vertices start here (mesh vertex keys are below 2^32).
pub(super) const NEW_KEY: u64 = 1 << 32;

/// The identity of a mesh vertex for the shared-vertex rules: the input vertex it
/// stands for (copies made by the builder when it split a non-manifold vertex are
/// the same point), as long as it still sits exactly where that vertex sits.
pub(super) fn vertex_key(mesh: &Mesh, v: VertexId) -> u64 {
    if let Some(Some(o)) = mesh.origin.get(v.idx()) {
        if let (Some(a), Some(b)) = (mesh.positions.get(o.idx()), mesh.positions.get(v.idx())) {
            if a.to_array().map(f64::to_bits) == b.to_array().map(f64::to_bits) {
                return o.idx() as u64;
            }
        }
    }
    v.idx() as u64
}

/// The keys of the `n` patch vertices over the loop `hole`: [`vertex_key`] for the
/// loop's, [`NEW_KEY`] on for the new ones.
pub(super) fn patch_keys(mesh: &Mesh, hole: &[VertexId], n: usize) -> Vec<u64> {
    let k = hole.len();
    (0..n)
        .map(|i| {
            if i < k {
                vertex_key(mesh, hole[i])
            } else {
                NEW_KEY + (i - k) as u64
            }
        })
        .collect()
}

/// Corners and vertex keys of mesh face `f` (`None` when out of range).
pub(super) fn face_tri(mesh: &Mesh, f: usize) -> Option<([DVec3; 3], [u64; 3])> {
    let vs = mesh.topo.faces().get(f)?;
    let mut p = [DVec3::ZERO; 3];
    for c in 0..3 {
        p[c] = *mesh.positions.get(vs[c].idx())?;
    }
    Some((p, vs.map(|v| vertex_key(mesh, v))))
}

/// Bounding box of mesh face `f` (an empty box when out of range).
fn face_box(mesh: &Mesh, f: usize) -> (DVec3, DVec3) {
    let pos = &mesh.positions;
    match mesh.topo.faces().get(f) {
        Some(&[a, b, c]) => match (pos.get(a.idx()), pos.get(b.idx()), pos.get(c.idx())) {
            (Some(&a), Some(&b), Some(&c)) => (a.min(b).min(c), a.max(b).max(c)),
            _ => (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        },
        None => (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
    }
}
