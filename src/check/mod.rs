//! Patch checks (ALGORITHMS A5): a patch is accepted only if every new triangle is
//! non-degenerate, the patch is a topological disk that closes the hole exactly (so
//! the mesh stays edge-manifold and consistently oriented), and no new triangle
//! intersects another triangle of the mesh or of the patch.
//!
//! Self-intersection: the broad phase is a scan of the mesh's face boxes (`f32`,
//! compared in blocks) or, after many checks, a bounding-volume hierarchy
//! ([`crate::bvh`]) over them, plus a logarithmic set of small trees over the faces
//! committed since and a linear scan of a short tail of them (see [`Checker`]); the
//! narrow phase is an exact triangle-triangle test on `robust::orient3d`/`orient2d`
//! signs ([`crate::geometry::predicates::tri_tri`]). Repairs that change a few triangles of a patch at a time
//! (edge flips, re-triangulating a region) use [`PatchChecks`], which records every
//! failure once and re-tests only what a change touches, with the same result.
//!
//! Readings where A5 is vague:
//! - Triangles that share vertices follow CGAL's convention (as in
//!   `Polygon_mesh_processing::self_intersections`): sharing one vertex they
//!   intersect only if they meet somewhere else; sharing an edge only if they
//!   overlap beyond it (a coplanar fold). Nothing else is excluded: a mesh face that
//!   merely touches a patch triangle at a point that is not a shared vertex counts.
//! - "Shared" is by identity, never by coordinates: a patch's loop vertex `i` is mesh
//!   vertex `hole[i]`, new vertices are new. Copies of one input vertex made by the
//!   mesh builder when it split a non-manifold vertex count as the same vertex while
//!   they still sit at the same coordinates (else a hole at a pinch point could never
//!   be filled: the other fan touches it there).
//! - Patch triangles are tested against each other by the same rules.
//! - The patch's own triangles are checked for degeneracy first, so the narrow phase
//!   may assume them non-degenerate; a zero-area face of the mesh is handled exactly
//!   (as the union of its edges).

use crate::geometry::bvh::{boxes_meet, f32_down, f32_up, tri_box, Bvh};
use crate::geometry::measure;
use crate::geometry::predicates::{tri_axis, tri_tri_axes};
use crate::mesh::{Mesh, VertexId};
use crate::patch::Patch;
use crate::policy::Checks;
use crate::report::PatchQuality;
use glam::DVec3;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

mod failure;
mod incremental;
pub use failure::{CheckFailure, Degeneracy, Meets, TopologyFailure};
pub use incremental::{Change, PatchChecks};

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
    boxes: OnceLock<FaceBoxes>,
    /// Number of faces the mesh had at construction.
    base_faces: usize,
    /// Checks expected (the tree is built with the boxes when above
    /// [`SCANS_BEFORE_TREE`]).
    expected: usize,
    /// Tree over those faces, once built.
    base: OnceLock<Bvh>,
    /// Scans of `boxes` so far.
    scans: AtomicUsize,
    /// Trees over committed faces, sizes decreasing.
    levels: Vec<Level>,
    /// Committed faces not yet in a tree (fewer than `tail_max`).
    tail: Vec<u32>,
    /// Size at which the tail becomes a tree ([`TAIL`]; smaller in tests).
    tail_max: usize,
    /// First face index not yet in `boxes`, `levels` or `tail`.
    next_unseen: usize,
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
struct FaceBoxes {
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
struct Level {
    faces: Vec<u32>,
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
    fn check_intersections(
        &self,
        mesh: &Mesh,
        hole: &[VertexId],
        patch: &Patch,
        pos: &[DVec3],
        against_base: bool,
        given: Option<&[u32]>,
    ) -> Result<(), CheckFailure> {
        let k = hole.len();
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
        let keys: Vec<u64> = (0..pos.len())
            .map(|i| {
                if i < k {
                    vertex_key(mesh, hole[i])
                } else {
                    NEW_KEY + (i - k) as u64
                }
            })
            .collect();
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
const NEW_KEY: u64 = 1 << 32;

/// The identity of a mesh vertex for the shared-vertex rules: the input vertex it
/// stands for (copies made by the builder when it split a non-manifold vertex are
/// the same point), as long as it still sits exactly where that vertex sits.
fn vertex_key(mesh: &Mesh, v: VertexId) -> u64 {
    if let Some(Some(o)) = mesh.origin.get(v.idx()) {
        if let (Some(a), Some(b)) = (mesh.positions.get(o.idx()), mesh.positions.get(v.idx())) {
            if a.to_array().map(f64::to_bits) == b.to_array().map(f64::to_bits) {
                return o.idx() as u64;
            }
        }
    }
    v.idx() as u64
}

/// Corners and vertex keys of mesh face `f` (`None` when out of range).
fn face_tri(mesh: &Mesh, f: usize) -> Option<([DVec3; 3], [u64; 3])> {
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

/// Area and minimum-angle tests.
pub fn check_degenerate(pos: &[DVec3], patch: &Patch, opts: &Checks) -> Result<(), CheckFailure> {
    let min_angle = opts.min_angle_deg.to_radians();
    for (ti, t) in patch.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| pos[i as usize]);
        if let Some(why) = degenerate_reason(a, b, c, min_angle) {
            return Err(CheckFailure::Degenerate { triangle: ti, why });
        }
    }
    Ok(())
}

/// Why triangle `abc` is degenerate (zero area, or an angle below `min_angle`
/// radians), `None` when it is not.
fn degenerate_reason(a: DVec3, b: DVec3, c: DVec3, min_angle: f64) -> Option<Degeneracy> {
    let l = (b - a).length().max((c - b).length()).max((a - c).length());
    let area = measure::tri_area(a, b, c);
    if area.is_nan() || area <= 1e-12 * l * l {
        return Some(Degeneracy::Area(area));
    }
    let m = measure::smallest_angle(a, b, c);
    if m < min_angle {
        return Some(Degeneracy::SmallAngle(m.to_degrees()));
    }
    None
}

/// Quality of a patch (see [`PatchQuality`]).
pub fn quality(pos: &[DVec3], k: usize, patch: &Patch) -> PatchQuality {
    let mut good = 0usize;
    let mut min_angle = f64::INFINITY;
    for t in &patch.triangles {
        let [a, b, c] = t.map(|i| pos[i as usize]);
        if measure::quality(a, b, c) > 1.39 {
            good += 1;
        }
        min_angle = min_angle.min(measure::smallest_angle(a, b, c));
    }
    let nnew = patch.new_vertices.len();
    let valence6_share = if nnew == 0 {
        None
    } else {
        // distinct neighbours of each new vertex: the two other corners of its
        // triangles, grouped by vertex (a counting sort), each short list sorted
        let new_of = |v: u32| (v as usize).checked_sub(k).filter(|&j| j < nnew);
        let mut start = vec![0usize; nnew + 1];
        for t in &patch.triangles {
            for &v in t {
                if let Some(j) = new_of(v) {
                    start[j + 1] += 2;
                }
            }
        }
        for j in 0..nnew {
            start[j + 1] += start[j];
        }
        let mut fill = start.clone();
        let mut nb = vec![0u32; start[nnew]];
        for t in &patch.triangles {
            for c in 0..3 {
                if let Some(j) = new_of(t[c]) {
                    nb[fill[j]] = t[(c + 1) % 3];
                    nb[fill[j] + 1] = t[(c + 2) % 3];
                    fill[j] += 2;
                }
            }
        }
        let mut six = 0usize;
        for j in 0..nnew {
            let l = &mut nb[start[j]..start[j + 1]];
            l.sort_unstable();
            let distinct = l
                .iter()
                .enumerate()
                .filter(|&(i, &w)| i == 0 || l[i - 1] != w)
                .count();
            six += (distinct == 6) as usize;
        }
        Some(six as f64 / nnew as f64)
    };
    PatchQuality {
        q_good_share: if patch.triangles.is_empty() {
            0.0
        } else {
            good as f64 / patch.triangles.len() as f64
        },
        min_angle_deg: if min_angle.is_finite() {
            min_angle.to_degrees()
        } else {
            0.0
        },
        valence6_share,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::predicates::tri_tri;
    use crate::io::RawMesh;

    fn v(x: f64, y: f64, z: f64) -> DVec3 {
        DVec3::new(x, y, z)
    }

    // ---- whole-patch checks -------------------------------------------------

    /// A torus of 3 x 3 new vertices: closed, every vertex a single fan, chi = 0.
    fn torus(base: u32) -> Vec<[u32; 3]> {
        let id = |i: u32, j: u32| base + (j % 3) * 3 + (i % 3);
        let mut t = Vec::new();
        for j in 0..3 {
            for i in 0..3 {
                t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        t
    }

    #[test]
    fn topology_rejects_extra_closed_components() {
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        let (m, _) = Mesh::from_raw(&raw);
        let hole = hole_at(&m, 0.0);
        let mut p = fan(&hole, v(3., 3., 0.));
        check_topology(&m, &hole, &p).unwrap();
        let base = (hole.len() + 1) as u32;
        p.triangles.extend(torus(base));
        for i in 0..9 {
            p.new_vertices.push(v(10. + i as f64, 0., 0.));
        }
        let e = check_topology(&m, &hole, &p).unwrap_err();
        assert!(e.to_string().contains("not connected"), "{e}");
    }

    #[test]
    fn topology_rejects_open_and_misoriented_patches() {
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        let (m, _) = Mesh::from_raw(&raw);
        let hole = hole_at(&m, 0.0);
        let good = fan(&hole, v(3., 3., 0.));
        let mut open = good.clone();
        open.triangles.pop();
        assert!(check_topology(&m, &hole, &open).is_err());
        let mut flipped = good.clone();
        for t in &mut flipped.triangles {
            t.swap(0, 1);
        }
        assert!(check_topology(&m, &hole, &flipped).is_err());
        let mut oob = good.clone();
        oob.triangles[0][2] = 99;
        assert!(check_topology(&m, &hole, &oob).is_err());
        let mut nan = good;
        nan.new_vertices[0].x = f64::NAN;
        assert!(check_topology(&m, &hole, &nan).is_err());
        // an L-shaped hole whose reflex corner (3,3) sits between two loop vertices
        // joined by a mesh edge (the diagonal of the remaining cell (2,3)): cutting
        // the ear at (3,3) would add that edge a second time
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &[(2, 2), (3, 2), (3, 3)], &mut raw);
        let (m, _) = Mesh::from_raw(&raw);
        let l = m
            .topo
            .boundary_loops()
            .into_iter()
            .find(|l| l.len() == 8)
            .unwrap();
        let k = l.len();
        let i = l.iter().position(|&u| m.pos(u) == v(3., 3., 0.)).unwrap();
        let at = |d: usize| ((i + d) % k) as u32;
        let ear = || {
            let mut t = vec![[at(k - 1), at(0), at(1)]];
            for j in 2..k - 1 {
                t.push([at(1), at(j), at(j + 1)]);
            }
            Patch {
                new_vertices: vec![],
                triangles: t,
            }
        };
        let e = check_topology(&m, &l, &ear()).unwrap_err();
        assert!(
            e.to_string().contains("duplicates an existing mesh edge"),
            "{e}"
        );
        // the ear at the convex corner (2,2) is fine
        let j = l.iter().position(|&u| m.pos(u) == v(2., 2., 0.)).unwrap();
        let at = |d: usize| ((j + d) % k) as u32;
        let mut t = vec![[at(k - 1), at(0), at(1)]];
        for d in 2..k - 1 {
            t.push([at(1), at(d), at(d + 1)]);
        }
        check_topology(
            &m,
            &l,
            &Patch {
                new_vertices: vec![],
                triangles: t,
            },
        )
        .unwrap();
    }

    /// An n x n grid of unit cells at height z, vertex ids offset by `base`, minus
    /// the cells in `removed` (i, j).
    fn grid(n: usize, z: f64, base: u32, removed: &[(usize, usize)], raw: &mut RawMesh) {
        for j in 0..=n {
            for i in 0..=n {
                raw.positions.push(v(i as f64, j as f64, z));
            }
        }
        let id = |i: usize, j: usize| base + (j * (n + 1) + i) as u32;
        for j in 0..n {
            for i in 0..n {
                if removed.contains(&(i, j)) {
                    continue;
                }
                raw.faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                raw.faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }

    const HOLE: [(usize, usize); 4] = [(2, 2), (3, 2), (2, 3), (3, 3)];

    /// The loop of 8 vertices around the 2x2 hole whose centre is (cx, cy, z).
    fn hole_at(m: &Mesh, z: f64) -> Vec<VertexId> {
        m.topo
            .boundary_loops()
            .into_iter()
            .find(|l| l.len() == 8 && l.iter().all(|&u| m.pos(u).z == z))
            .expect("hole loop")
    }

    fn fan(hole: &[VertexId], apex: DVec3) -> Patch {
        let k = hole.len();
        Patch {
            new_vertices: vec![apex],
            triangles: (0..k)
                .map(|i| [i as u32, ((i + 1) % k) as u32, k as u32])
                .collect(),
        }
    }

    fn checks() -> Checks {
        Checks {
            self_intersection: true,
            min_angle_deg: 0.5,
        }
    }

    #[test]
    fn flat_fan_on_a_grid_hole_is_accepted() {
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        let (m, _) = Mesh::from_raw(&raw);
        let hole = hole_at(&m, 0.0);
        let chk = Checker::new(&m);
        let q = chk
            .check_patch(&m, &hole, &fan(&hole, v(3., 3., 0.)), &checks())
            .unwrap();
        assert!(q.min_angle_deg > 40.0);
        // a raised apex is fine too, as long as nothing is in the way
        chk.check_patch(&m, &hole, &fan(&hole, v(3., 3., 2.)), &checks())
            .unwrap();
        // an apex pushed sideways in the plane folds the fan over itself and the mesh
        let e = chk
            .check_patch(&m, &hole, &fan(&hole, v(4.5, 3., 0.)), &checks())
            .unwrap_err();
        assert!(matches!(e, CheckFailure::SelfIntersection { .. }), "{e}");
    }

    #[test]
    fn patch_poking_through_the_far_side_is_rejected() {
        // a thin shell: the holed sheet at z = 0 and a full sheet 0.3 above it
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        grid(6, 0.3, 49, &[], &mut raw);
        let (m, _) = Mesh::from_raw(&raw);
        let hole = hole_at(&m, 0.0);
        let chk = Checker::new(&m);
        chk.check_patch(&m, &hole, &fan(&hole, v(3., 3., 0.1)), &checks())
            .unwrap();
        let e = chk
            .check_patch(&m, &hole, &fan(&hole, v(3., 3., 1.0)), &checks())
            .unwrap_err();
        let CheckFailure::SelfIntersection {
            meets: Meets::MeshFace(f),
            ..
        } = e
        else {
            panic!("{e}")
        };
        assert!(m
            .tri(crate::mesh::FaceId::from_idx(f))
            .iter()
            .all(|p| p.z == 0.3));
        // with the check off the same patch passes
        let off = Checks {
            self_intersection: false,
            ..checks()
        };
        chk.check_patch(&m, &hole, &fan(&hole, v(3., 3., 1.0)), &off)
            .unwrap();
    }

    #[test]
    fn patch_folding_onto_itself_is_rejected() {
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        let (m, _) = Mesh::from_raw(&raw);
        let hole = hole_at(&m, 0.0);
        let k = hole.len() as u32;
        let chk = Checker::new(&m);
        // two apexes; triangles 0..k/2 go to the first, the rest to the second
        let tri = |a: DVec3, b: DVec3| {
            let mut t: Vec<[u32; 3]> = Vec::new();
            for i in 0..k {
                let apex = if i < k / 2 { k } else { k + 1 };
                t.push([i, (i + 1) % k, apex]);
            }
            t.push([k / 2, k + 1, k]);
            t.push([0, k, k + 1]);
            Patch {
                new_vertices: vec![a, b],
                triangles: t,
            }
        };
        // the loop runs clockwise seen from +z: find which half each apex belongs to
        let mid0 = (m.pos(hole[0]) + m.pos(hole[(k / 2) as usize])) * 0.5;
        let half = |i: usize| m.pos(hole[i]) - mid0;
        let side = (half(1) + half(2) + half(3)).normalize() * 0.5;
        let good = tri(mid0 + side, mid0 - side);
        chk.check_patch(&m, &hole, &good, &checks()).unwrap();
        let bad = tri(mid0 - side, mid0 + side);
        let e = chk.check_patch(&m, &hole, &bad, &checks()).unwrap_err();
        assert!(
            matches!(
                e,
                CheckFailure::SelfIntersection {
                    meets: Meets::PatchTriangle(_),
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn committed_faces_are_checked() {
        // two holed sheets, the second 0.3 above; fill the upper hole, then a tall
        // fan on the lower hole hits the new faces (before, it passed through)
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        grid(6, 0.3, 49, &HOLE, &mut raw);
        let (mut m, _) = Mesh::from_raw(&raw);
        let lower = hole_at(&m, 0.0);
        let upper = hole_at(&m, 0.3);
        let mut chk = Checker::new(&m);
        let tall = fan(&lower, v(3., 3., 1.0));
        chk.check_patch(&m, &lower, &tall, &checks()).unwrap();
        let lid = fan(&upper, v(3., 3., 0.3));
        chk.check_patch(&m, &upper, &lid, &checks()).unwrap();
        let hole = crate::patch::Hole::new(0, &m, upper.clone(), &crate::policy::Policy::default());
        let faces = crate::patch::apply_patch(&mut m, &hole, &lid).unwrap();
        // before the commit the faces are scanned as unseen, after it they are indexed
        let e1 = chk.check_patch(&m, &lower, &tall, &checks()).unwrap_err();
        chk.commit(&m, faces);
        let e2 = chk.check_patch(&m, &lower, &tall, &checks()).unwrap_err();
        assert_eq!(e1, e2);
        let CheckFailure::SelfIntersection {
            meets: Meets::MeshFace(f),
            ..
        } = e2
        else {
            panic!()
        };
        assert!(f >= m.num_faces() - 8);
    }

    #[test]
    fn a_proposal_that_meets_an_earlier_patch_fails_over_to_the_next_method() {
        // the parallel phase checked the tall fan on the lower hole against the mesh
        // as read (clean); the upper hole's lid was accepted first, and the fan pokes
        // through it: the serial phase must reject it and try the next method
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        grid(6, 0.3, 49, &HOLE, &mut raw);
        let (mut m, _) = Mesh::from_raw(&raw);
        let lower = hole_at(&m, 0.0);
        let upper = hole_at(&m, 0.3);
        let policy = crate::policy::Policy::default();
        let mut chk = Checker::new(&m);
        let tall = fan(&lower, v(3., 3., 1.0));
        let q = chk.check_patch(&m, &lower, &tall, &checks()).unwrap();
        // nothing added yet: nothing to meet
        chk.check_against_added(&m, &lower, &tall, &checks())
            .unwrap();
        let up = crate::patch::Hole::new(1, &m, upper, &policy);
        let lid = crate::fill::dispatch::fill_hole(&mut m, &up, &policy, &mut chk);
        assert_eq!(lid.status, crate::report::HoleStatus::Filled);
        m.validate().unwrap();
        let e = chk
            .check_against_added(&m, &lower, &tall, &checks())
            .unwrap_err();
        assert!(matches!(e, CheckFailure::SelfIntersection { .. }), "{e}");
        let low = crate::patch::Hole::new(0, &m, lower, &policy);
        let methods = crate::fill::dispatch::methods_for(&policy, low.class).to_vec();
        assert!(methods.len() >= 2);
        let proposal = crate::fill::dispatch::Proposal {
            tried: Vec::new(),
            accepted: Some((0, tall, q, 0.0)),
            ms: 0.0,
        };
        let rep = crate::fill::dispatch::finish_hole(&mut m, &low, &policy, &mut chk, proposal);
        m.validate().unwrap();
        assert_eq!(
            rep.status,
            crate::report::HoleStatus::Filled,
            "{}",
            rep.reason
        );
        assert_eq!(rep.tried[0].method, methods[0]);
        assert_eq!(rep.tried[0].outcome, crate::report::Outcome::Rejected);
        assert!(
            rep.tried[0].reason.contains("intersects mesh face"),
            "{}",
            rep.tried[0].reason
        );
        assert_eq!(rep.method, Some(methods[1]));
        assert_eq!(
            m.topo.boundary_loops().len(),
            2,
            "only the sheets' outer borders"
        );
    }

    #[test]
    fn incremental_index_matches_a_fresh_one() {
        // the checker of the lower sheet alone, then the upper sheet's faces
        // committed in small batches (through the tail and several rebuilds)
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        let nb = raw.faces.len();
        grid(12, 0.3, 49, &[], &mut raw);
        let (m, _) = Mesh::from_raw(&raw);
        let lower_raw = RawMesh {
            positions: raw.positions.clone(),
            faces: raw.faces[..nb].to_vec(),
            ..Default::default()
        };
        let (m0, _) = Mesh::from_raw(&lower_raw);
        assert_eq!(m0.topo.faces(), &m.topo.faces()[..nb]);
        let hole = hole_at(&m, 0.0);
        let fresh = Checker::new(&m);
        let mut inc = Checker::new(&m0);
        inc.tail_max = 64;
        let mut f = nb;
        while f < m.num_faces() {
            let e = (f + 7).min(m.num_faces());
            inc.commit(&m, f..e);
            f = e;
        }
        // 288 faces in batches of 7: trees of 70 merged into 140, then 280, tail 8
        assert!(!inc.levels.is_empty() && !inc.tail.is_empty() && inc.tail.len() < inc.tail_max);
        let sizes: Vec<usize> = inc.levels.iter().map(|l| l.faces.len()).collect();
        assert!(sizes.windows(2).all(|w| w[0] > w[1]), "{sizes:?}");
        let total: usize = sizes.iter().sum::<usize>() + inc.tail.len();
        assert_eq!(total, m.num_faces() - nb);
        let mut all: Vec<u32> = inc.levels.iter().flat_map(|l| l.faces.clone()).collect();
        all.extend_from_slice(&inc.tail);
        all.sort_unstable();
        assert_eq!(all, (nb as u32..m.num_faces() as u32).collect::<Vec<_>>());
        for (apex, ok) in [
            (v(3., 3., 0.1), true),
            (v(3., 3., 1.), false),
            (v(2.5, 3.5, 0.5), false),
        ] {
            let p = fan(&hole, apex);
            let a = fresh.check_patch(&m, &hole, &p, &checks());
            let b = inc.check_patch(&m, &hole, &p, &checks());
            assert_eq!(a.is_ok(), ok);
            assert_eq!(a.is_ok(), b.is_ok());
        }
    }

    #[test]
    fn dispatcher_rejects_a_fan_through_an_obstacle_and_fills_without_it() {
        use crate::fill::dispatch::fill_hole;
        use crate::patch::Hole;
        use crate::policy::{Method, Policy};
        use crate::report::{HoleStatus, Outcome};
        let mut policy = Policy::default();
        policy.dispatch.small = vec![Method::Fan];
        for obstacle in [true, false] {
            // a grid missing cell (2, 2), and a small upright triangle through the
            // cell's centre (its own component)
            let mut raw = RawMesh::default();
            grid(5, 0.0, 0, &[(2, 2)], &mut raw);
            if obstacle {
                let b = raw.positions.len() as u32;
                raw.positions
                    .extend([v(2.5, 2.4, -0.5), v(2.6, 2.6, 0.5), v(2.4, 2.6, 0.5)]);
                raw.faces.push([b, b + 1, b + 2]);
            }
            let (mut m, _) = Mesh::from_raw(&raw);
            let l = m
                .topo
                .boundary_loops()
                .into_iter()
                .find(|l| l.len() == 4)
                .unwrap();
            let hole = Hole::new(0, &m, l, &policy);
            let mut chk = Checker::new(&m);
            let nf = m.num_faces();
            let rep = fill_hole(&mut m, &hole, &policy, &mut chk);
            if obstacle {
                assert_eq!(rep.status, HoleStatus::Failed);
                assert_eq!(rep.tried[0].outcome, Outcome::Rejected);
                assert!(
                    rep.tried[0].reason.contains("intersects mesh face"),
                    "{}",
                    rep.tried[0].reason
                );
                assert_eq!(m.num_faces(), nf);
            } else {
                assert_eq!(rep.status, HoleStatus::Filled, "{}", rep.reason);
                assert_eq!(m.num_faces(), nf + 4);
                m.validate().unwrap();
                // the patch's faces were committed to the checker
                assert_eq!(chk.tail.len(), 4);
            }
        }
    }

    /// The checker finds the same failure whether it scans the face boxes or walks its
    /// tree, and that failure is the canonical one (smallest failing patch triangle,
    /// then the smallest patch triangle or mesh face it meets), as a brute force over
    /// every pair finds it. After `SCANS_BEFORE_TREE` scans the tree is built.
    #[test]
    fn scan_and_tree_report_the_canonical_failure() {
        use rand::{Rng, SeedableRng};
        // a grid with a 2x2 hole, an upper sheet and a small tilted sheet crossing the
        // space above the hole
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        grid(6, 0.7, 49, &[], &mut raw);
        let b = raw.positions.len() as u32;
        raw.positions
            .extend([v(2.2, 2.2, 0.2), v(2.8, 2.2, 0.2), v(2.5, 2.8, 0.5)]);
        raw.faces.push([b, b + 1, b + 2]);
        let (m, _) = Mesh::from_raw(&raw);
        let hole = hole_at(&m, 0.0);
        let k = hole.len();
        let brute = |p: &Patch| -> Result<(), CheckFailure> {
            let pos = patch_positions(&m, &hole, p);
            let key = |i: u32| {
                if (i as usize) < k {
                    vertex_key(&m, hole[i as usize])
                } else {
                    NEW_KEY + (i as usize - k) as u64
                }
            };
            let tri = |t: &[u32; 3]| (t.map(|i| pos[i as usize]), t.map(key));
            for (i, t) in p.triangles.iter().enumerate() {
                let (a, ak) = tri(t);
                for (j, u) in p.triangles.iter().enumerate().skip(i + 1) {
                    let (b, bk) = tri(u);
                    if tri_tri(&a, &ak, &b, &bk) {
                        return Err(CheckFailure::SelfIntersection {
                            triangle: i,
                            meets: Meets::PatchTriangle(j),
                        });
                    }
                }
            }
            for (i, t) in p.triangles.iter().enumerate() {
                let (a, ak) = tri(t);
                for f in 0..m.num_faces() {
                    let (q, qk) = face_tri(&m, f).unwrap();
                    if tri_tri(&a, &ak, &q, &qk) {
                        return Err(CheckFailure::SelfIntersection {
                            triangle: i,
                            meets: Meets::MeshFace(f),
                        });
                    }
                }
            }
            Ok(())
        };
        let scan = Checker::new(&m);
        let tree = Checker::for_checks(&m, SCANS_BEFORE_TREE + 1);
        assert!(tree.base.get().is_none() && tree.boxes.get().is_none());
        tree.prepare(&m);
        assert!(tree.base.get().is_some());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut outcomes = [0usize; 3];
        for round in 0..SCANS_BEFORE_TREE + 20 {
            // two apexes: the fan splits the hole in two, so patch triangles can meet
            let centre = |r: std::ops::RangeInclusive<usize>| {
                let n = r.clone().count() as f64;
                r.map(|i| m.pos(hole[i % k])).sum::<DVec3>() / n
            };
            let mut jitter = |c: DVec3, s: f64| {
                c + v(
                    rng.random_range(-s..s),
                    rng.random_range(-s..s),
                    rng.random_range(-0.4..0.9),
                )
            };
            let (mut a1, mut a2) = (
                jitter(centre(0..=k / 2), 0.6),
                jitter(centre(k / 2..=k), 0.6),
            );
            if round % 4 == 0 {
                // each fan over the other half: the patch folds over itself
                std::mem::swap(&mut a1, &mut a2);
                a2.z = a1.z + 0.3;
            }
            let mut p = Patch {
                new_vertices: vec![a1, a2],
                triangles: Vec::new(),
            };
            let (x, y) = (k as u32, k as u32 + 1);
            for i in 0..k as u32 {
                let j = (i + 1) % k as u32;
                p.triangles
                    .push([i, j, if i < k as u32 / 2 { x } else { y }]);
            }
            let h = k as u32 / 2;
            p.triangles.push([x, h, y]);
            p.triangles.push([x, y, 0]);
            if check_topology(&m, &hole, &p).is_err() {
                continue;
            }
            let pos = patch_positions(&m, &hole, &p);
            let want = brute(&p);
            let got_scan = scan.check_intersections(&m, &hole, &p, &pos, true, None);
            let got_tree = tree.check_intersections(&m, &hole, &p, &pos, true, None);
            // with the nearby faces found once and given (as the flip repair does)
            let near = tree.faces_near(&m, &hole, &p);
            let got_near = tree.check_intersections(&m, &hole, &p, &pos, true, Some(&near));
            assert_eq!(got_scan, want, "round {round}");
            assert_eq!(got_tree, want, "round {round}");
            assert_eq!(got_near, want, "round {round}");
            outcomes[match &want {
                Ok(()) => 0,
                Err(CheckFailure::SelfIntersection {
                    meets: Meets::PatchTriangle(_),
                    ..
                }) => 1,
                Err(_) => 2,
            }] += 1;
        }
        assert!(outcomes.iter().all(|&n| n > 0), "{outcomes:?}");
        // the scanning checker built its tree once it had scanned enough
        assert!(scan.base.get().is_some());
    }

    /// [`PatchChecks`] (every failure recorded, changes re-tested incrementally)
    /// reports what the whole check reports, on random two-apex fans over a hole
    /// under obstacles: as made, after random edge flips (some kept), and with one
    /// apex's triangles replaced by a fan over their ring (a vertex dropped, the
    /// triangles renumbered).
    #[test]
    fn incremental_checks_report_what_the_whole_check_reports() {
        use rand::{Rng, SeedableRng};
        let mut raw = RawMesh::default();
        grid(6, 0.0, 0, &HOLE, &mut raw);
        grid(6, 0.7, 49, &[], &mut raw);
        let b = raw.positions.len() as u32;
        raw.positions
            .extend([v(2.2, 2.2, 0.2), v(2.8, 2.2, 0.2), v(2.5, 2.8, 0.5)]);
        raw.faces.push([b, b + 1, b + 2]);
        let (m, _) = Mesh::from_raw(&raw);
        let hole = hole_at(&m, 0.0);
        let k = hole.len();
        let opts = checks();
        let checker = Checker::new(&m);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (mut trials, mut kept, mut passed, mut failed) = (0usize, 0usize, 0usize, 0usize);
        for _ in 0..60 {
            let mut jitter = |s: f64| {
                v(
                    2.5 + rng.random_range(-s..s),
                    2.5 + rng.random_range(-s..s),
                    rng.random_range(-0.4..0.9),
                )
            };
            let (a1, a2) = (jitter(0.9), jitter(0.9));
            let (x, y) = (k as u32, k as u32 + 1);
            let mut p = Patch {
                new_vertices: vec![a1, a2],
                triangles: Vec::new(),
            };
            for i in 0..k as u32 {
                let j = (i + 1) % k as u32;
                p.triangles
                    .push([i, j, if i < k as u32 / 2 { x } else { y }]);
            }
            let h = k as u32 / 2;
            p.triangles.push([x, h, y]);
            p.triangles.push([x, y, 0]);
            let near = checker.faces_near(&m, &hole, &p);
            let mut st = PatchChecks::new(&m, &hole, p.clone(), &opts, &near).unwrap();
            assert_eq!(st.result(), checker.check_patch(&m, &hole, &p, &opts));
            // the ring of apex y's triangles, closed by a fan from its first vertex
            {
                let mut removed = Vec::new();
                let mut next = std::collections::HashMap::new();
                for (t, tri) in p.triangles.iter().enumerate() {
                    if let Some(c) = tri.iter().position(|&w| w == y) {
                        removed.push(t);
                        next.insert(tri[(c + 1) % 3], tri[(c + 2) % 3]);
                    }
                }
                let start = tri_start(&p, y);
                let mut ring = vec![start];
                while let Some(&n) = next.get(ring.last().unwrap()) {
                    if n == start || ring.len() > next.len() {
                        break;
                    }
                    ring.push(n);
                }
                // from apex x (on the ring): the loop's vertices along a side of
                // the hole are collinear, a fan from one of them degenerate
                if let Some(at) = ring.iter().position(|&w| w == x) {
                    ring.rotate_left(at);
                }
                let added: Vec<[u32; 3]> = (1..ring.len() - 1)
                    .map(|i| [ring[0], ring[i], ring[i + 1]])
                    .collect();
                let mut q = Patch {
                    new_vertices: vec![a1],
                    triangles: p
                        .triangles
                        .iter()
                        .enumerate()
                        .filter(|(t, _)| !removed.contains(t))
                        .map(|(_, t)| *t)
                        .collect(),
                };
                q.triangles.extend(&added);
                let got = st.replaced(&removed, &added, &q);
                assert_eq!(got, checker.check_patch(&m, &hole, &q, &opts));
                if got.is_ok() {
                    passed += 1;
                } else {
                    failed += 1;
                }
            }
            // random flips of interior edges
            for _ in 0..25 {
                let cur = st.patch().clone();
                let t = rng.random_range(0..cur.triangles.len());
                let c = rng.random_range(0..3);
                let tri = cur.triangles[t];
                let (a, b, cc) = (tri[c], tri[(c + 1) % 3], tri[(c + 2) % 3]);
                let Some(u) = cur
                    .triangles
                    .iter()
                    .position(|o| (0..3).any(|e| o[e] == b && o[(e + 1) % 3] == a))
                else {
                    continue;
                };
                let Some(&d) = cur.triangles[u].iter().find(|&&w| w != a && w != b) else {
                    continue;
                };
                let (change, q, got) = st.trial(&[t, u], &[[a, d, cc], [b, cc, d]]);
                assert_eq!(got, checker.check_patch(&m, &hole, &q, &opts));
                trials += 1;
                if rng.random_bool(0.5) && st.apply(change) {
                    kept += 1;
                    assert_eq!(st.patch(), &q);
                    assert_eq!(st.result(), checker.check_patch(&m, &hole, &q, &opts));
                }
            }
        }
        assert!(trials > 500 && kept > 100, "{trials} trials, {kept} kept");
        assert!(passed > 0 && failed > 0, "{passed} passed, {failed} failed");
    }

    /// A vertex of the triangle opposite `apex` in the first triangle using it.
    fn tri_start(p: &Patch, apex: u32) -> u32 {
        p.triangles
            .iter()
            .find_map(|t| t.iter().position(|&w| w == apex).map(|c| t[(c + 1) % 3]))
            .unwrap()
    }
}
