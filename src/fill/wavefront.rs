//! Improved wavefront with curvature restoration.
//!
//! Paper 004: Huang, Li, Ye, "Improved Hole Repairing Method Based on Wavefront Method"
//! (2022, DOI 10.21203/rs.3.rs-1345779/v1); ALGORITHMS.md section C.
//!
//! * §2.2 (improved wavefront): the front starts as the hole loop. `Avglen`, the mean
//!   boundary edge length of the original hole, is measured once. At each step the front
//!   vertex with the smallest angle θ is processed if θ < μ; otherwise a front vertex drawn
//!   at random is processed (§2.2 step 4). With thresholds α < β: θ <= α closes the vertex
//!   with one triangle `(v_{i-1}, v_i, v_{i+1})`; α < θ <= β adds one point on the bisector at
//!   distance `Avglen` (two triangles); θ > β adds two points on the trisectors at distance
//!   `Avglen` (three triangles). A front of three vertices becomes the last triangle.
//! * §2.2.1 (curvature restoration): the expected normal of a front vertex is
//!   `N_v = Σ ω_k N_fk` (Eq. 1) over its faces, `ω_k = λ_k / G_k` (Eq. 2), with the shape
//!   factor `λ = (a+b−c)(a+c−b)(b+c−a)/(abc)` (Eq. 4) and `G_k` the distance from the vertex
//!   to the centroid of face k; the "virtual" triangle `(v_{i−1}, v_i, v_{i+1})` is included.
//!   The expected normal of a new triangle is the mean of the expected normals of its front
//!   vertices (cases (a), (b), (c) of §2.2.1); the triangle is rotated about its centroid
//!   (Rodrigues, Eqs. 5–7) so its normal becomes the expected one.
//!
//! How the vague passages are read:
//! * "Angle formed by the half-edges": θ is measured on the hole side, in the tangent plane
//!   of the vertex's expected normal (so θ is in `[0, 2π)` and reflex vertices are
//!   recognised). The hole lies to the left of each directed front edge seen from the normal.
//! * "On the bisection/trisection direction of θ": the direction's tangent part is at
//!   the fraction 1/2 (or 2/3 and 1/3) of θ from the next edge. Its slope out of the tangent
//!   plane depends on `placement`:
//!   - `edge_plane` (default, the digest's "in the plane of the two front edges"): the slope
//!     of the plane through both edges along that direction. Near a straight angle that
//!     plane tilts without bound (three points of a great circle span a plane through the
//!     sphere's centre), so within 45° of 180° its slope is blended (by `sin θ / sin 45°`)
//!     into the interpolated one below; at a reflex vertex the plane lies on the wrong side
//!     and the interpolated slope is used.
//!   - `interpolated`: the elevation angle interpolated between the two edges' elevations
//!     (the new point continues the chords). Not in the paper.
//!
//!   Either way the slope of a side is measured over five front vertices, scaled to the
//!   distance `Avglen` (see `side_elevation`), not on the one edge: scanned boundaries
//!   zig-zag, and single-edge slopes made fronts climb out of the hole.
//!
//!   Measured (tests below, mean |error| of the new vertices): the edge plane over-curves
//!   (points sink below a sphere) and the restoration rotation lifts them back, so with
//!   `edge_plane` restoration helps (sum over eight curved holes 0.169 against 0.252;
//!   better on seven, 1.5 % worse on one). With `interpolated` the rotation only flattens
//!   (each triangle is turned to the normal of the front edge it grows from, which lags
//!   the surface). `interpolated` without restoration is the closest setting on spheres
//!   and the paraboloid, 6 to 9 times closer (sphere hole of 140: 0.0032 R against
//!   0.020 R), while on the cylinder and the saddle the paper's setting is as good or
//!   better (cylinder 0.0057 against 0.0047, saddle 0.0096 against 0.0062).
//! * Case (a) adds no point, so its rotation would move nothing: skipped. Case (b): each of
//!   the two triangles is rotated; only the new point may move (front vertices stay), so the
//!   new point goes to the mean of its two rotated positions. Case (c): the paper's labels
//!   repeat `V_new2`; we rotate the two outer triangles `(v_{i−1}, v_i, new1)` and
//!   `(new2, v_i, v_{i+1})` (moving new1 and new2 respectively) and leave the middle one, as
//!   the paper says. A rotation with antiparallel normals is undefined and skipped.
//! * Faces of a front vertex: its mesh faces and the patch triangles made so far; the
//!   virtual triangle's normal is flipped, if needed, to agree with the sum of the others (at
//!   a reflex vertex it would otherwise point into the surface).
//! * The random draw uses `ChaCha8` seeded from `policy.seed` mixed with the hole id, so the
//!   same input and policy give the same patch bit for bit.
//! * The paper is silent on robustness (its conclusion admits overlaps). Added here, as the
//!   issue asks:
//!   - a new point within `merge_distance · Avglen` of a non-adjacent vertex of the same
//!     front is merged into it, splitting the front in two (a front of two vertices is two
//!     sides of one edge and is zipped); a new point that close to the processed vertex or
//!     its two neighbours, or within half that distance of a non-adjacent front edge, or
//!     farther from the loop's centroid than twice the loop's radius plus `2 Avglen`, or
//!     projecting (onto the loop's best-fit plane) outside the loop by more than
//!     `Avglen / 2`, makes that variant invalid (the last rule stops fronts that climb out
//!     of the hole; it assumes the hole is not a cap over a protrusion);
//!   - every new triangle must have its smallest angle above `checks.min_angle_deg`, face
//!     the vertex's expected normal, not overlap (in the vertex's tangent plane, exact
//!     `orient2d`) any nearby patch triangle or mesh face around the hole, nor cross a
//!     back-facing one (exact `orient3d` segment tests), and never create an edge that
//!     already exists (patch edges, mesh edges between loop vertices);
//!   - a step may not leave a front angle below 1° at the neighbours, nor a front of three
//!     vertices whose triangle is flipped, or is a sliver with its longest edge on the loop;
//!   - if the rule's variant is invalid, the other variants are tried (fewer or more points);
//!     if none is valid the vertex is put back with a penalty. When every vertex fails, one
//!     step may use thin triangles (angle bound 0), and a front of at most 10 vertices is
//!     closed by ear clipping without the overlap tests; slivers are flipped away at the
//!     end where the patch triangle across their longest edge allows. Failing again, or after
//!     `max_steps_per_vertex · k` steps, every remaining front is closed as a residual loop
//!     ([`residual`]: minimum-area triangulation in 3-D, refined to `Avglen`, thin-plate
//!     faired against the triangles around it; kept unfaired when the faired piece
//!     crosses a triangle around the front and the unfaired one does not, as in a fold of the
//!     bunny scan's hole 2). Closes 1999 of 2000 random star-shaped loops.
//!   - a front whose patch area passes `max_area_ratio` (2.0) times the loop's vector
//!     area (a lower bound on the area of any surface the loop bounds) has run away: it
//!     climbed into a dome over the hole or folded (measured on the bench: full fronts
//!     that pass the checks 1.0 to 2.3, runaway ones 2.5 to 4.7, and all four
//!     full-front variants of such a hole ran away; the one at 2.3 is closer to the
//!     true surface from the residual variant). The run stops at once and the other
//!     full-front variants are skipped, straight to those that close a residual early;
//!   - the whole run is self-checked ([`retry`]): when its patch fails the dispatcher's
//!     checks, a local repair (edge flips, then re-triangulation of the region around the
//!     failing triangle) is tried, then the same method with the settings of [`variants`]
//!     (the robust `interpolated` placement without restoration, the next seed, a short
//!     front whose residual is closed as above, `alpha = 90`). On the shared bench
//!     (35 holes) this closes every hole; before, 3 fronts got stuck or overlapped.
//!
//! Cost: a binary heap of front angles with lazy invalidation (only the vertices a step
//! touches are re-measured) and spatial hashes of the front vertices and the triangles, so
//! one step costs `O(log n)` plus a local neighbourhood.

// `!(x > bound)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::kit::{check_patch_size, residual, retry, FillContext, FillError};
use crate::fasthash::{HashMap, HashSet};
use crate::geometry::measure;
use crate::geometry::predicates::{ccw2d, overlap2d, overlap2d_ccw, p2, seg_crosses_tri, P2};
use crate::patch::Patch;
use crate::policy::{Policy, Wavefront, WavefrontPlacement};
use crate::report::PatchQuality;
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;
use std::f64::consts::{FRAC_PI_4, PI, TAU};

/// A new triangle must face the processed vertex's expected normal at least this much
/// (cosine of the angle between the normals).
const FACING_MIN: f64 = 0.05;
/// Nearby triangles facing the vertex normal more than this are tested in its tangent
/// plane; the others with a 3D crossing test.
const PROJECT_MIN: f64 = 0.2;
/// A cell of the spatial grids is this many `Avglen` wide.
const CELL: f64 = 2.0;
/// With `placement = "edge_plane"`, the plane of the two front edges is used fully when
/// θ is at least this far from 0 and π, and blended into the interpolated elevation
/// (by `sin θ / sin PLANE_WINDOW`) closer to a straight angle, where the plane tilts
/// without bound; reflex vertices use the interpolated elevation.
const PLANE_WINDOW: f64 = FRAC_PI_4;
/// The slope of "a front edge" out of the tangent plane is measured over this many front
/// vertices on that side, not on the one edge (see `side_elevation`): scanned boundaries
/// zig-zag, and single-edge slopes made the front climb out of the hole.
const FRONT_SPAN: usize = 5;
/// Edge elevations are clamped to this (radians) before taking tangents.
const MAX_EL: f64 = 1.4;
/// A step may not leave a front angle below this (radians, 1 degree) at the processed
/// vertex's neighbours: it would only close as a sliver.
const MIN_FRONT_ANGLE: f64 = 1.0 * PI / 180.0;
/// A stuck front of at most this many vertices is closed by ear clipping.
const SMALL_FRONT: usize = 10;
/// Start of the failure message of a front that has run away (see
/// `wavefront.max_area_ratio`); [`fill`] then skips the other full-front variants.
const RUNAWAY: &str = "the front ran away";
/// A triangle spanning more cells than this is kept in a list tested every time.
const MAX_CELLS: i64 = 512;

/// Fills the hole with the improved wavefront (policy section `[wavefront]`): the
/// policy's settings first; when their patch fails the checks, the variants of
/// [`variants`] (see [`retry`]).
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    fill_checked(ctx).map(|(p, _)| p)
}

/// [`fill`], with the quality of the checks the patch passed (see
/// [`crate::fill::dispatch::run_method_checked`]).
pub fn fill_checked(ctx: &FillContext) -> Result<(Patch, Option<PatchQuality>), FillError> {
    // a hole whose patch would pass `limits.max_patch_triangles` is left to the next
    // method at once (the front's cost grows faster than its triangle count: a round
    // hole of 1,000 vertices took 20 s): the loop's projected area over the area of an
    // equilateral triangle at the mean boundary edge length
    let maxk = ctx.policy.wavefront.max_boundary_vertices;
    if maxk > 0 && ctx.hole.len() > maxk {
        return Err(FillError::Failed(format!(
            "{} boundary vertices > wavefront.max_boundary_vertices = {maxk}",
            ctx.hole.len()
        )));
    }
    check_patch_size(ctx)?;
    // a front that ran away under the policy's settings runs away under the other
    // full-front settings too (measured: all four on the bench hole that does), so
    // after one does, only the variants that close a residual early are run
    let ran_away = std::cell::Cell::new(false);
    let full = ctx.policy.wavefront.max_steps_per_vertex;
    let vars = variants(ctx.policy);
    // the variants that are the policy with fewer steps per vertex run the policy's
    // front up to their cap: they resume from a copy of the policy's run taken there
    // (or, when that run ended before their cap, would repeat it)
    let resumable: Vec<Option<usize>> = vars
        .iter()
        .map(|(_, p)| {
            let mut q = p.clone();
            q.wavefront.max_steps_per_vertex = full;
            (q == *ctx.policy && p.wavefront.max_steps_per_vertex < full).then(|| {
                p.wavefront
                    .max_steps_per_vertex
                    .saturating_mul(ctx.hole.len())
            })
        })
        .collect();
    let caps: Vec<usize> = resumable.iter().flatten().copied().collect();
    let first = std::cell::RefCell::new(FirstRun::default());
    retry::first_passing_at(ctx, &vars, |at, c| {
        if ran_away.get() && c.policy.wavefront.max_steps_per_vertex >= full {
            return Err(FillError::Failed(format!(
                "skipped: {RUNAWAY} under the policy's settings"
            )));
        }
        let r = match (at, resumable.get(at).copied().flatten()) {
            (0, _) => {
                let (r, snaps) = run_wave(c, Start::Fresh(&caps));
                let mut f = first.borrow_mut();
                f.snapshots = snaps;
                f.outcome = Some(r.as_ref().map(|_| ()).map_err(Clone::clone));
                r
            }
            (_, Some(cap)) => {
                let (snap, outcome) = {
                    let mut f = first.borrow_mut();
                    let i = f.snapshots.iter().position(|(s, _)| *s == cap);
                    (i.map(|i| f.snapshots.swap_remove(i).1), f.outcome.clone())
                };
                match (snap, outcome) {
                    (Some(w), _) => run_wave(c, Start::Resume(Box::new(w))).0,
                    // the policy's run ended within this cap: the same run again
                    (None, Some(Err(e))) => Err(e),
                    (None, Some(Ok(()))) => Err(FillError::Failed(
                        "the same front as the policy's, whose patch failed the checks".into(),
                    )),
                    (None, None) => run_wave(c, Start::Fresh(&[])).0,
                }
            }
            _ => run_wave(c, Start::Fresh(&[])).0,
        };
        let r = r.map(|(p, _)| p);
        if matches!(&r, Err(FillError::Failed(e)) if e.starts_with(RUNAWAY)) {
            ran_away.set(true);
        }
        r
    })
}

/// What the policy's own run left for the variants that resume it.
#[derive(Default)]
struct FirstRun {
    /// Copies of its wave before step `cap` (for each cap it reached).
    snapshots: Snapshots,
    /// How it ended.
    outcome: Option<Result<(), FillError>>,
}

/// Copies of a wave kept by [`Wave::run`], with the step count before which each was
/// taken.
type Snapshots = Vec<(usize, Wave)>;

/// Where [`run_wave`] starts: a new wave that keeps copies of itself before the given
/// step counts, or a kept copy.
enum Start<'a> {
    Fresh(&'a [usize]),
    Resume(Box<Wave>),
}

/// The policy, then the same method with the settings measured most robust on folded
/// scanned holes (`placement = "interpolated"` without the restoration rotation, which
/// can turn a triangle into its neighbour on a tight fold), then both with the next seed
/// (other random draws), then `alpha = 90` (the paper's setting for some models).
pub fn variants(policy: &Policy) -> Vec<(&'static str, Policy)> {
    let mut out: Vec<(&'static str, Policy)> = vec![("policy", policy.clone())];
    let mut plain = policy.clone();
    plain.wavefront.placement = WavefrontPlacement::Interpolated;
    plain.wavefront.curvature_restoration = false;
    let mut push = |name: &'static str, p: Policy| {
        if !out.iter().any(|(_, q)| *q == p) {
            out.push((name, p));
        }
    };
    push("interpolated, no restoration", plain.clone());
    let mut s1 = policy.clone();
    s1.seed = s1.seed.wrapping_add(1) & (i64::MAX as u64);
    push("next seed", s1);
    let mut s2 = plain.clone();
    s2.seed = s2.seed.wrapping_add(1) & (i64::MAX as u64);
    push("interpolated, no restoration, next seed", s2);
    // a few rings of wavefront, the rest closed as a residual front (min-area,
    // refined, faired against the rings): for large holes whose fronts climb or fold
    for steps in [4, 2] {
        if policy.wavefront.max_steps_per_vertex > steps {
            let mut r = policy.clone();
            r.wavefront.max_steps_per_vertex = steps;
            push(
                if steps == 4 {
                    "4 steps per vertex, residual closed"
                } else {
                    "2 steps per vertex, residual closed"
                },
                r,
            );
        }
    }
    if policy.wavefront.alpha < 90.0 && policy.wavefront.beta > 90.0 {
        let mut a = policy.clone();
        a.wavefront.alpha = 90.0;
        push("alpha 90", a);
        let mut b = plain;
        b.wavefront.alpha = 90.0;
        push("interpolated, no restoration, alpha 90", b);
    }
    out
}

/// What a run did (for tests and diagnostics).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// Steps taken (successful or not).
    pub steps: usize,
    /// Steps at a vertex drawn at random (smallest angle at least μ).
    pub random_picks: usize,
    /// New points merged into a front vertex (each splits a front).
    pub merges: usize,
    /// Fronts of two vertices zipped after a split.
    pub zips: usize,
    /// Steps where no variant was valid.
    pub failed_steps: usize,
    /// Times the front got stuck and thin triangles were allowed for one step.
    pub relaxed_steps: usize,
    /// Small stuck fronts closed by unchecked ear clipping.
    pub clipped_fronts: usize,
    /// Stuck fronts closed by [`residual::close`].
    pub residual_fronts: usize,
    /// Residual fronts whose faired piece crossed a triangle around the front, kept unfaired.
    pub unfaired_residuals: usize,
}

/// [`fill`], also returning what the run did.
pub fn fill_with_stats(ctx: &FillContext) -> Result<(Patch, Stats), FillError> {
    run_wave(ctx, Start::Fresh(&[])).0
}

/// The checks before a run; `Some` patch when the loop is a triangle.
fn precheck(ctx: &FillContext) -> Result<Option<Patch>, FillError> {
    let opts = &ctx.policy.wavefront;
    check_options(opts)?;
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::Failed(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    let len = ctx.hole.mean_edge_length;
    if !(len.is_finite() && len > 0.0) {
        return Err(FillError::Failed(format!(
            "mean boundary edge length {len} is not positive"
        )));
    }
    if k == 3 {
        return Ok(Some(Patch {
            new_vertices: Vec::new(),
            triangles: vec![[0, 1, 2]],
        }));
    }
    Ok(None)
}

/// [`fill_with_stats`] from `start`; also returns the copies of the wave kept on the
/// way.
fn run_wave(ctx: &FillContext, start: Start) -> (Result<(Patch, Stats), FillError>, Snapshots) {
    let opts = &ctx.policy.wavefront;
    let k = ctx.hole.len();
    let mut w = match start {
        Start::Fresh(at) => {
            match precheck(ctx) {
                Err(e) => return (Err(e), Vec::new()),
                Ok(Some(tri)) => return (Ok((tri, Stats::default())), Vec::new()),
                Ok(None) => {}
            }
            match Wave::new(ctx, opts, ctx.hole.mean_edge_length) {
                Ok(mut w) => {
                    w.snapshot_at = at.to_vec();
                    w
                }
                Err(e) => return (Err(e), Vec::new()),
            }
        }
        Start::Resume(w) => *w,
    };
    let r = w.run(ctx, opts);
    let snapshots = std::mem::take(&mut w.snapshots);
    if let Err(e) = r {
        return (Err(e), snapshots);
    }
    w.flip_slivers();
    let patch = Patch {
        new_vertices: w.pos[k..].to_vec(),
        triangles: w.tris,
    };
    (Ok((patch, w.stats)), snapshots)
}

fn check_options(o: &Wavefront) -> Result<(), FillError> {
    let bad = |m: String| Err(FillError::Failed(format!("wavefront options: {m}")));
    if !(o.alpha.is_finite() && o.beta.is_finite() && o.mu.is_finite()) {
        return bad("alpha, beta and mu must be finite".into());
    }
    if !(0.0 < o.alpha && o.alpha < o.beta && o.beta < 180.0) {
        return bad(format!(
            "need 0 < alpha ({}) < beta ({}) < 180",
            o.alpha, o.beta
        ));
    }
    if !(0.0 < o.mu && o.mu <= 180.0) {
        return bad(format!("need 0 < mu ({}) <= 180", o.mu));
    }
    if !(0.0..=1.0).contains(&o.merge_distance) {
        return bad(format!(
            "merge_distance ({}) must be in [0, 1]",
            o.merge_distance
        ));
    }
    if o.max_steps_per_vertex == 0 {
        return bad("max_steps_per_vertex must be at least 1".into());
    }
    Ok(())
}

/// A front vertex occurrence. A vertex can be on two fronts after a split, so nodes and
/// vertices are apart.
#[derive(Clone, Copy, Debug)]
struct Node {
    vert: u32,
    prev: u32,
    next: u32,
    front: u32,
    version: u32,
    fails: u32,
    alive: bool,
}

/// A heap entry: `key` is θ plus a penalty of 2π per failed attempt.
#[derive(Clone, Copy, Debug)]
struct Entry {
    key: f64,
    theta: f64,
    node: u32,
    version: u32,
}

impl PartialEq for Entry {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        self.key
            .total_cmp(&o.key)
            .then(self.node.cmp(&o.node))
            .then(self.version.cmp(&o.version))
    }
}

/// A triangle already in place (patch triangle or mesh face around the hole), with the
/// patch indices of its corners where it has them.
#[derive(Clone, Copy, Debug)]
struct Placed {
    ids: [Option<u32>; 3],
    p: [DVec3; 3],
    n: DVec3,
    /// Bounding box (set by [`Wave::place`]).
    lo: DVec3,
    hi: DVec3,
}

/// A uniform grid of ids over the loop's best-fit plane: an id is stored in every cell
/// that the projection of its box touches (positions beyond the grid fall in its border
/// cells), in per-cell linked lists over one array (no allocation per cell; a copy is
/// two array copies). A query reports each id whose cells meet the query's cells
/// exactly once (in the first cell of the overlap). It is a broad phase only: callers
/// test the ids' own boxes, so what they find does not depend on the grid.
#[derive(Clone)]
struct Grid {
    centre: DVec3,
    u: DVec3,
    w: DVec3,
    /// Plane coordinate of the grid's corner, inverse cell size, cells per side.
    origin: f64,
    inv: f64,
    n: usize,
    /// First entry of each cell's list (`NONE`: empty).
    head: Vec<u32>,
    /// Entries: id and next entry of the same cell.
    entries: Vec<(u32, u32)>,
    /// Cell range `[i0, j0, i1, j1]` of each id (indexed by id).
    ranges: Vec<[u32; 4]>,
}

/// End of a cell's list.
const NONE: u32 = u32::MAX;
/// Largest number of cells per side of a [`Grid`] (the cells grow past it).
const MAX_SIDE: usize = 256;

impl Grid {
    /// A grid with cells of about `cell` over the square of half-width `extent` around
    /// `centre` in the plane spanned by `u` and `w` (unit, orthogonal).
    fn new(cell: f64, centre: DVec3, u: DVec3, w: DVec3, extent: f64) -> Grid {
        let extent = if extent.is_finite() && extent > 0.0 {
            extent
        } else {
            1.0
        };
        let cell = if cell.is_finite() && cell > 0.0 {
            cell
        } else {
            extent
        };
        let n = ((2.0 * extent / cell).ceil() as usize).clamp(1, MAX_SIDE);
        Grid {
            centre,
            u,
            w,
            origin: -extent,
            inv: n as f64 / (2.0 * extent),
            n,
            head: vec![NONE; n * n],
            entries: Vec::new(),
            ranges: Vec::new(),
        }
    }
    /// Cell range of the projection of the box `[lo, hi]`.
    fn range(&self, lo: DVec3, hi: DVec3) -> [u32; 4] {
        let c = (lo + hi) * 0.5 - self.centre;
        let h = (hi - lo) * 0.5;
        let span = |a: DVec3| h.x * a.x.abs() + h.y * a.y.abs() + h.z * a.z.abs();
        let (cu, ru) = (c.dot(self.u), span(self.u));
        let (cw, rw) = (c.dot(self.w), span(self.w));
        let max = (self.n - 1) as f64;
        let cell = |x: f64| ((x - self.origin) * self.inv).floor().clamp(0.0, max) as u32;
        [cell(cu - ru), cell(cw - rw), cell(cu + ru), cell(cw + rw)]
    }
    /// Inserts `id` into every cell the box touches; false when it spans more than
    /// `MAX_CELLS` (the caller keeps such ids apart).
    fn insert_box(&mut self, lo: DVec3, hi: DVec3, id: u32) -> bool {
        let r = self.range(lo, hi);
        let cells = (r[2] - r[0] + 1) as i64 * (r[3] - r[1] + 1) as i64;
        if cells > MAX_CELLS {
            return false;
        }
        let i = id as usize;
        if self.ranges.len() <= i {
            self.ranges.resize(i + 1, [1, 1, 0, 0]);
        }
        self.ranges[i] = r;
        for y in r[1]..=r[3] {
            for x in r[0]..=r[2] {
                let c = y as usize * self.n + x as usize;
                self.entries.push((id, self.head[c]));
                self.head[c] = (self.entries.len() - 1) as u32;
            }
        }
        true
    }
    /// Every id in a cell the box touches, each once (in no particular order).
    fn query_box(&self, lo: DVec3, hi: DVec3, out: &mut Vec<u32>) {
        out.clear();
        let q = self.range(lo, hi);
        for y in q[1]..=q[3] {
            for x in q[0]..=q[2] {
                let mut e = self.head[y as usize * self.n + x as usize];
                while e != NONE {
                    let (id, next) = self.entries[e as usize];
                    let r = self.ranges[id as usize];
                    // this is the first cell of the id's overlap with the query
                    if x == r[0].max(q[0]) && y == r[1].max(q[1]) {
                        out.push(id);
                    }
                    e = next;
                }
            }
        }
    }
}

/// A vertex of a step's chain: an existing front node or a new point.
#[derive(Clone, Copy, Debug)]
enum Item {
    Node(u32),
    New(DVec3),
}

/// A validated step: the chain `[v_{i-1}, new or merged points..., v_{i+1}]` that replaces
/// the processed vertex (an interior `Item::Node` is the front node merged into).
struct Plan {
    chain: Vec<Item>,
}

/// The state of the front (cloned to resume a run with a smaller step cap, see
/// [`fill_checked`]).
#[derive(Clone)]
struct Wave {
    k: usize,
    len: f64,
    min_angle: f64,
    restore: bool,
    placement: WavefrontPlacement,
    merge_radius: f64,
    /// Positions in patch numbering (loop first, then new points).
    pos: Vec<DVec3>,
    /// Σ ω_k N_fk over the faces of each vertex so far (Eq. 1 without the virtual triangle).
    acc: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
    /// Undirected patch edges.
    edges: HashSet<(u32, u32)>,
    /// Undirected mesh edges between two loop vertices.
    mesh_edges: HashSet<(u32, u32)>,
    nodes: Vec<Node>,
    front_size: Vec<usize>,
    heap: BinaryHeap<Reverse<Entry>>,
    alive: Vec<u32>,
    alive_pos: Vec<usize>,
    placed: Vec<Placed>,
    tri_grid: Grid,
    big: Vec<u32>,
    node_grid: Grid,
    rng: ChaCha8Rng,
    fallback_normal: DVec3,
    /// New points must lie within `reach` of `centre` (the loop's centroid).
    centre: DVec3,
    reach: f64,
    /// The loop projected onto its best-fit plane (basis `plane_u`, `plane_w` at
    /// `centre`), and the smallest distance of a projected loop vertex from the centre.
    loop2d: Vec<(f64, f64)>,
    plane_u: DVec3,
    plane_w: DVec3,
    inner: f64,
    stats: Stats,
    /// Stuck: thin triangles are allowed until the next successful step.
    relaxed: bool,
    /// The front lost its shape (a bug, never expected): the run fails cleanly.
    corrupt: bool,
    scratch: Vec<u32>,
    /// Area of the patch triangles so far, and the runaway bound on it
    /// (`max_area_ratio` times the loop's vector area).
    area: f64,
    max_area: f64,
    /// Steps taken and failed steps in a row (the state of [`Wave::run`]).
    steps: usize,
    stalls: usize,
    /// Step counts at which [`Wave::run`] keeps a copy of the wave (before that step),
    /// and the copies kept.
    snapshot_at: Vec<usize>,
    snapshots: Snapshots,
}

/// Is `p` inside the closed polygon `poly` (non-zero winding number, counted by the
/// signed crossings of the ray from `p` towards +x, so no angles are summed) or within
/// `near` of one of its edges?
fn inside_or_near(poly: &[(f64, f64)], p: (f64, f64), near: f64) -> bool {
    let Some(&last) = poly.last() else {
        return false;
    };
    let (px, py) = p;
    let mut wind = 0i64;
    let mut prev = last;
    for &cur in poly {
        let (ax, ay) = (prev.0 - px, prev.1 - py);
        let (bx, by) = (cur.0 - px, cur.1 - py);
        let cross = ax * by - ay * bx;
        if ay <= 0.0 {
            if by > 0.0 && cross > 0.0 {
                wind += 1;
            }
        } else if by <= 0.0 && cross < 0.0 {
            wind -= 1;
        }
        prev = cur;
    }
    if wind != 0 {
        return true;
    }
    let r2 = near * near;
    let mut prev = last;
    for &cur in poly {
        let (ax, ay) = (prev.0 - px, prev.1 - py);
        let (ex, ey) = (cur.0 - prev.0, cur.1 - prev.1);
        let t = (-(ax * ex + ay * ey) / (ex * ex + ey * ey).max(1e-300)).clamp(0.0, 1.0);
        if (ax + t * ex).powi(2) + (ay + t * ey).powi(2) < r2 {
            return true;
        }
        prev = cur;
    }
    false
}

fn ekey(a: u32, b: u32) -> (u32, u32) {
    if a < b {
        (a, b)
    } else {
        (b, a)
    }
}

/// Weight ω = λ / G (Eqs. 2, 4) and unit normal of triangle (a, b, c) seen from corner `q`.
fn face_weight(q: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<(f64, DVec3)> {
    let n = (b - a).cross(c - a);
    let nl = n.length();
    if !(nl > 0.0 && nl.is_finite()) {
        return None;
    }
    let la = (b - c).length();
    let lb = (a - c).length();
    let lc = (a - b).length();
    let lambda = ((la + lb - lc) * (la + lc - lb) * (lb + lc - la) / (la * lb * lc)).max(0.0);
    let g = (q - (a + b + c) / 3.0).length();
    if !(g > 0.0 && lambda.is_finite()) {
        return None;
    }
    Some((lambda / g, n / nl))
}

/// Rotates `x` about `g` by the rotation taking unit `from` to unit `to` (Rodrigues).
fn rotate_to(x: DVec3, g: DVec3, from: DVec3, to: DVec3) -> DVec3 {
    let axis = from.cross(to);
    let s = axis.length();
    let c = from.dot(to);
    if !(s > 1e-12) {
        return x;
    }
    let k = axis / s;
    let ang = s.atan2(c);
    let (sn, cs) = ang.sin_cos();
    let r = x - g;
    g + r * cs + k.cross(r) * sn + k * k.dot(r) * (1.0 - cs)
}

fn unit_or(v: DVec3, fallback: DVec3) -> DVec3 {
    let l = v.length();
    if l > 1e-300 && l.is_finite() {
        v / l
    } else {
        fallback
    }
}

/// Do two triangles cross in 3D away from their shared corners? Edges touching a shared
/// corner are not tested (they meet the other triangle there by construction).
fn cross3d(ai: [Option<u32>; 3], a: &[DVec3; 3], bi: [Option<u32>; 3], b: &[DVec3; 3]) -> bool {
    let shared = |id: Option<u32>, other: &[Option<u32>; 3]| id.is_some() && other.contains(&id);
    for (xi, x, yi, y) in [(ai, a, bi, b), (bi, b, ai, a)] {
        for e in 0..3 {
            let f = (e + 1) % 3;
            if shared(xi[e], &yi) || shared(xi[f], &yi) {
                continue;
            }
            if seg_crosses_tri(x[e], x[f], y) {
                return true;
            }
        }
    }
    false
}

/// A new triangle of a step, prepared for the tests against the nearby triangles.
struct Candidate {
    ids: [Option<u32>; 3],
    /// Projected into the tangent plane, counter-clockwise; `None` when degenerate.
    ccw: Option<[P2; 3]>,
    box2: Box2,
    box3: Box3,
}

/// A closed 2-D bounding box.
struct Box2 {
    lo: [f64; 2],
    hi: [f64; 2],
}

impl Box2 {
    fn of(t: &[P2; 3]) -> Box2 {
        Box2 {
            lo: [
                t[0].x.min(t[1].x).min(t[2].x),
                t[0].y.min(t[1].y).min(t[2].y),
            ],
            hi: [
                t[0].x.max(t[1].x).max(t[2].x),
                t[0].y.max(t[1].y).max(t[2].y),
            ],
        }
    }
    /// False only when the boxes are apart (then no two triangles in them overlap).
    fn meets(&self, o: &Box2) -> bool {
        !(self.hi[0] < o.lo[0]
            || o.hi[0] < self.lo[0]
            || self.hi[1] < o.lo[1]
            || o.hi[1] < self.lo[1])
    }
}

/// A closed 3-D bounding box.
struct Box3 {
    lo: DVec3,
    hi: DVec3,
}

impl Box3 {
    fn of(t: &[DVec3; 3]) -> Box3 {
        Box3 {
            lo: t[0].min(t[1]).min(t[2]),
            hi: t[0].max(t[1]).max(t[2]),
        }
    }
    /// False only when the boxes are apart (then no segment of one crosses the other).
    fn meets(&self, o: &Box3) -> bool {
        !(self.hi.cmplt(o.lo).any() || o.hi.cmplt(self.lo).any())
    }
}

impl Wave {
    fn new(ctx: &FillContext, opts: &Wavefront, len: f64) -> Result<Wave, FillError> {
        let mesh = ctx.mesh;
        let hole = &ctx.hole.vertices;
        let k = hole.len();
        let mut index: HashMap<u32, u32> = HashMap::with_capacity_and_hasher(k, Default::default());
        for (i, v) in hole.iter().enumerate() {
            if v.idx() >= mesh.num_vertices() {
                return Err(FillError::Failed(format!(
                    "loop vertex {} is not in the mesh",
                    v.idx()
                )));
            }
            if index.insert(v.idx() as u32, i as u32).is_some() {
                return Err(FillError::Failed(format!(
                    "the loop passes vertex {} twice",
                    v.idx()
                )));
            }
        }
        let pos: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
        let fallback_normal = unit_or(measure::newell_normal(&pos), DVec3::Z);
        let centre = measure::centroid(&pos);
        let pu = fallback_normal.any_orthonormal_vector();
        let pw = fallback_normal.cross(pu);
        let loop2d: Vec<(f64, f64)> = pos
            .iter()
            .map(|&p| ((p - centre).dot(pu), (p - centre).dot(pw)))
            .collect();
        let inner = loop2d
            .iter()
            .map(|&(x, y)| (x * x + y * y).sqrt())
            .fold(f64::INFINITY, f64::min);
        let reach = 2.0
            * pos
                .iter()
                .map(|&p| (p - centre).length())
                .fold(0.0, f64::max)
            + 2.0 * len;
        let max_area = if opts.max_area_ratio > 0.0 {
            opts.max_area_ratio * measure::vector_area(&pos)
        } else {
            f64::INFINITY
        };
        let mut w = Wave {
            k,
            len,
            min_angle: ctx.policy.checks.min_angle_deg.max(0.0).to_radians() + 1e-9,
            restore: opts.curvature_restoration,
            placement: opts.placement,
            merge_radius: opts.merge_distance * len,
            acc: vec![DVec3::ZERO; k],
            pos,
            tris: Vec::new(),
            edges: HashSet::default(),
            mesh_edges: HashSet::default(),
            nodes: Vec::with_capacity(2 * k),
            front_size: vec![k],
            heap: BinaryHeap::new(),
            alive: Vec::with_capacity(2 * k),
            alive_pos: Vec::with_capacity(2 * k),
            placed: Vec::new(),
            tri_grid: Grid::new(CELL * len, centre, pu, pw, reach + 2.0 * len),
            big: Vec::new(),
            node_grid: Grid::new(CELL * len, centre, pu, pw, reach + 2.0 * len),
            rng: ChaCha8Rng::seed_from_u64(
                ctx.policy.seed ^ (ctx.hole.id as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            ),
            fallback_normal,
            centre,
            reach,
            loop2d,
            plane_u: pu,
            plane_w: pw,
            inner,
            stats: Stats::default(),
            relaxed: false,
            corrupt: false,
            scratch: Vec::new(),
            area: 0.0,
            max_area,
            steps: 0,
            stalls: 0,
            snapshot_at: Vec::new(),
            snapshots: Vec::new(),
        };
        // mesh faces around the hole: expected normals (Eq. 1) and obstacles
        let mut seen = HashSet::default();
        for (i, &v) in hole.iter().enumerate() {
            for nb in mesh.topo.neighbors(v) {
                if let Some(&j) = index.get(&(nb.idx() as u32)) {
                    w.mesh_edges.insert(ekey(i as u32, j));
                }
            }
            for f in mesh.topo.vertex_faces(v) {
                let p = mesh.tri(f);
                if let Some((wt, n)) = face_weight(mesh.pos(v), p[0], p[1], p[2]) {
                    w.acc[i] += wt * n;
                }
                if seen.insert(f) {
                    let ids = mesh
                        .topo
                        .face(f)
                        .map(|c| index.get(&(c.idx() as u32)).copied());
                    let n = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO);
                    w.place(Placed {
                        ids,
                        p,
                        n,
                        lo: DVec3::ZERO,
                        hi: DVec3::ZERO,
                    });
                }
            }
        }
        for i in 0..k {
            w.new_node(i as u32, ((i + k - 1) % k) as u32, ((i + 1) % k) as u32, 0);
        }
        for i in 0..k {
            w.refresh(i as u32);
        }
        Ok(w)
    }

    fn place(&mut self, mut t: Placed) {
        let id = self.placed.len() as u32;
        let lo = t.p[0].min(t.p[1]).min(t.p[2]);
        let hi = t.p[0].max(t.p[1]).max(t.p[2]);
        (t.lo, t.hi) = (lo, hi);
        self.placed.push(t);
        if !self.tri_grid.insert_box(lo, hi, id) {
            self.big.push(id);
        }
    }

    fn new_node(&mut self, vert: u32, prev: u32, next: u32, front: u32) -> u32 {
        let id = self.nodes.len() as u32;
        self.nodes.push(Node {
            vert,
            prev,
            next,
            front,
            version: 0,
            fails: 0,
            alive: true,
        });
        self.alive_pos.push(self.alive.len());
        self.alive.push(id);
        let p = self.pos[vert as usize];
        self.node_grid.insert_box(p, p, id);
        id
    }

    fn kill(&mut self, n: u32) {
        let node = &mut self.nodes[n as usize];
        if !node.alive {
            return;
        }
        node.alive = false;
        node.version = node.version.wrapping_add(1);
        let i = self.alive_pos[n as usize];
        self.alive.swap_remove(i);
        if let Some(&moved) = self.alive.get(i) {
            self.alive_pos[moved as usize] = i;
        }
    }

    fn p(&self, n: u32) -> DVec3 {
        self.pos[self.nodes[n as usize].vert as usize]
    }

    /// Expected normal of a front node (Eq. 1 with the virtual triangle).
    fn expected_normal(&self, n: u32) -> DVec3 {
        let nd = self.nodes[n as usize];
        let base = self.acc[nd.vert as usize];
        let (p, v, q) = (self.p(nd.prev), self.p(n), self.p(nd.next));
        let mut s = base;
        if let Some((wt, nv)) = face_weight(v, p, v, q) {
            s += if base.dot(nv) < 0.0 {
                -wt * nv
            } else {
                wt * nv
            };
        }
        unit_or(s, self.fallback_normal)
    }

    /// The front angle at a node, on the hole side, in the tangent plane of `nrm`.
    fn angle(&self, n: u32, nrm: DVec3) -> f64 {
        let nd = self.nodes[n as usize];
        let v = self.p(n);
        let en = self.p(nd.next) - v;
        let ep = self.p(nd.prev) - v;
        let tn = unit_or(en - nrm * en.dot(nrm), unit_or(en, DVec3::ZERO));
        let tp = unit_or(ep - nrm * ep.dot(nrm), unit_or(ep, DVec3::ZERO));
        let t = nrm.dot(tn.cross(tp)).atan2(tn.dot(tp));
        if t < 0.0 {
            t + TAU
        } else {
            t
        }
    }

    fn push(&mut self, n: u32) {
        let nrm = self.expected_normal(n);
        let theta = self.angle(n, nrm);
        let nd = &mut self.nodes[n as usize];
        nd.version = nd.version.wrapping_add(1);
        self.heap.push(Reverse(Entry {
            key: theta + TAU * nd.fails as f64,
            theta,
            node: n,
            version: nd.version,
        }));
    }

    /// Re-measures a node whose neighbourhood changed.
    fn refresh(&mut self, n: u32) {
        if self.nodes[n as usize].alive {
            self.nodes[n as usize].fails = 0;
            self.push(n);
        }
    }

    fn penalize(&mut self, n: u32) {
        if self.nodes[n as usize].alive {
            self.nodes[n as usize].fails += 1;
            self.push(n);
        }
    }

    /// The current smallest entry (stale entries are dropped).
    fn peek(&mut self) -> Option<Entry> {
        while let Some(Reverse(e)) = self.heap.peek().copied() {
            let nd = self.nodes[e.node as usize];
            if nd.alive && nd.version == e.version {
                return Some(e);
            }
            self.heap.pop();
        }
        None
    }

    /// `Err` when the front has run away (see `wavefront.max_area_ratio`). Checked while
    /// the front advances only: the residual closing of a front stopped early may
    /// rightly make a deep patch.
    fn check_area(&self, opts: &Wavefront) -> Result<(), FillError> {
        if self.area > self.max_area {
            return Err(FillError::Failed(format!(
                "{RUNAWAY}: the patch's area passed {} times the loop's vector area \
                 (wavefront.max_area_ratio)",
                opts.max_area_ratio
            )));
        }
        Ok(())
    }

    /// Runs the front until it closes, from where it stands (a fresh wave, or a copy
    /// kept by an earlier run: the loop's state is in the wave).
    fn run(&mut self, ctx: &FillContext, opts: &Wavefront) -> Result<(), FillError> {
        let cap = opts.max_steps_per_vertex.saturating_mul(self.k);
        let mu = opts.mu.to_radians();
        let (alpha, beta) = (opts.alpha.to_radians(), opts.beta.to_radians());
        while !self.alive.is_empty() {
            ctx.deadline.check()?;
            if self.snapshot_at.contains(&self.steps) {
                let mut copy = self.clone();
                copy.snapshot_at.clear();
                copy.snapshots.clear();
                self.snapshots.push((self.steps, copy));
            }
            self.steps += 1;
            let steps = self.steps;
            self.stats.steps = steps;
            if steps > cap {
                // out of steps: close what is left as residual fronts
                return self.close_residual_fronts(ctx).map_err(|e| {
                    FillError::Failed(format!(
                        "the front did not close within {cap} steps (max_steps_per_vertex = {}) \
                         and its residual could not be closed: {e}",
                        opts.max_steps_per_vertex
                    ))
                });
            }
            let node = match self.peek() {
                Some(e) if e.theta < mu && self.nodes[e.node as usize].fails == 0 => e.node,
                _ => {
                    self.stats.random_picks += 1;
                    let i = self.rng.random_range(0..self.alive.len());
                    self.alive[i]
                }
            };
            let advanced = self.process(node, alpha, beta);
            if self.corrupt {
                return Err(FillError::Failed(
                    "internal error: the front lost its shape".into(),
                ));
            }
            self.check_area(opts)?;
            if advanced {
                self.stalls = 0;
                self.relaxed = false;
            } else {
                self.stalls += 1;
                self.stats.failed_steps += 1;
                self.penalize(node);
                if self.stalls > 2 * self.alive.len() + 16 && !self.relaxed {
                    // stuck: accept thin triangles until the next step succeeds; the
                    // sliver flips repair them or the checks reject the patch
                    self.relaxed = true;
                    self.stats.relaxed_steps += 1;
                    self.stalls = 0;
                } else if self.stalls > 2 * self.alive.len() + 16 {
                    // stuck: close every remaining front as a residual loop
                    let left = self.alive.len();
                    return self.close_residual_fronts(ctx).map_err(|e| {
                        FillError::Failed(format!(
                            "the front is stuck (none of its {left} vertices can advance without \
                             an overlap, a duplicate edge or a degenerate triangle) and its \
                             residual could not be closed: {e}"
                        ))
                    });
                }
            }
        }
        Ok(())
    }

    /// Closes every remaining front with [`residual::close`] (see that module).
    fn close_residual_fronts(&mut self, ctx: &FillContext) -> Result<(), FillError> {
        while let Some(&start) = self.alive.first() {
            ctx.deadline.check()?;
            let f = self.nodes[start as usize].front as usize;
            let mut ring = vec![start];
            let mut a = self.nodes[start as usize].next;
            while a != start {
                if ring.len() > self.nodes.len() {
                    return Err(FillError::Failed("internal error: open front".into()));
                }
                ring.push(a);
                a = self.nodes[a as usize].next;
            }
            let verts: Vec<u32> = ring.iter().map(|&n| self.nodes[n as usize].vert).collect();
            if verts.iter().collect::<HashSet<_>>().len() != verts.len() {
                return Err(FillError::Failed(
                    "the residual front passes a vertex twice".into(),
                ));
            }
            let n = verts.len();
            if n < 3 {
                return Err(FillError::Failed(format!(
                    "a residual front of {n} vertices"
                )));
            }
            let pts: Vec<DVec3> = verts.iter().map(|&v| self.pos[v as usize]).collect();
            let mut forbidden = HashSet::default();
            for i in 0..n {
                for j in i + 2..n {
                    if (i, j) != (0, n - 1) && self.edge_exists(verts[i], verts[j]) {
                        forbidden.insert((i as u32, j as u32));
                    }
                }
            }
            let on_ring: HashSet<u32> = verts.iter().copied().collect();
            let mut outside = vec![None; n];
            let mut context = Vec::new();
            let mut around: Vec<u32> = Vec::new();
            for (id, t) in self.placed.iter().enumerate() {
                if !t
                    .ids
                    .iter()
                    .any(|c| c.is_some_and(|c| on_ring.contains(&c)))
                {
                    continue;
                }
                context.push(t.p);
                around.push(id as u32);
                for c in 0..3 {
                    if let (Some(a), Some(b)) = (t.ids[c], t.ids[(c + 1) % 3]) {
                        // the triangle outside ring edge i -> i+1 holds the half-edge i+1 -> i
                        if let Some(i) = verts.iter().position(|&x| x == b) {
                            if verts[(i + 1) % n] == a && t.n != DVec3::ZERO {
                                outside[i] = Some(t.n);
                            }
                        }
                    }
                }
            }
            let input = residual::Residual {
                ring: &pts,
                forbidden: &forbidden,
                outside_normals: &outside,
                context: &context,
                edge_length: self.len,
            };
            let closed = residual::close_keeping_unfaired(&input, ctx.policy, &ctx.deadline)?;
            let base = self.pos.len() as u32;
            let map = |i: u32| {
                if (i as usize) < n {
                    verts[i as usize]
                } else {
                    base + i - n as u32
                }
            };
            let tris = closed.triangles;
            let mut new_pts = closed.new_vertices;
            // the fairing can push the piece through the front's own triangles (a
            // residual inside a fold of the front): then the unfaired piece (on its
            // minimum-area triangulation), when that one crosses none of those around
            // the ring
            if let Some(flat) = closed.unfaired {
                if self.crosses_around(&around, &tris, map, &new_pts, base)
                    && !self.crosses_around(&around, &tris, map, &flat, base)
                {
                    new_pts = flat;
                    self.stats.unfaired_residuals += 1;
                }
            }
            for p in new_pts {
                self.pos.push(p);
                self.acc.push(DVec3::ZERO);
            }
            for t in tris {
                self.add_triangle(t.map(map));
            }
            for node in ring {
                self.kill(node);
            }
            self.front_size[f] = 0;
            self.stats.residual_fronts += 1;
        }
        Ok(())
    }

    /// Does a triangle of a residual piece (`tris` in ring numbering, mapped to patch
    /// numbering by `map`; new vertex `base + i` at `new_pts[i]`) cross one of the
    /// triangles in place `around` it (those with a corner on its ring: the front's and
    /// the mesh faces there, which a bulging piece meets first), away from their shared
    /// corners? The test of [`Wave::valid`]'s non-projected case. A choice between two
    /// pieces only: the patch checks test the patch against everything.
    fn crosses_around(
        &self,
        around: &[u32],
        tris: &[[u32; 3]],
        map: impl Fn(u32) -> u32,
        new_pts: &[DVec3],
        base: u32,
    ) -> bool {
        let at = |v: u32| {
            if v < base {
                self.pos[v as usize]
            } else {
                new_pts[(v - base) as usize]
            }
        };
        let pieces: Vec<([u32; 3], [DVec3; 3], Box3)> = tris
            .iter()
            .map(|t| {
                let ids = t.map(&map);
                let p = ids.map(at);
                (ids, p, Box3::of(&p))
            })
            .collect();
        around.iter().any(|&id| {
            let pl = &self.placed[id as usize];
            let pb = Box3 {
                lo: pl.lo,
                hi: pl.hi,
            };
            pieces
                .iter()
                .any(|(ids, p, b)| b.meets(&pb) && cross3d(ids.map(Some), p, pl.ids, &pl.p))
        })
    }

    /// One step at `node`; false when no variant is valid.
    fn process(&mut self, node: u32, alpha: f64, beta: f64) -> bool {
        let nd = self.nodes[node as usize];
        let (pn, nn) = (nd.prev, nd.next);
        let nv = self.expected_normal(node);
        if self.relaxed && self.front_size[nd.front as usize] <= SMALL_FRONT {
            return self.clip_small_front(node);
        }
        if self.front_size[nd.front as usize] == 3 {
            let t = [
                self.nodes[pn as usize].vert,
                nd.vert,
                self.nodes[nn as usize].vert,
            ];
            if !self.valid(nd.vert, &[t], &[], nv, 0.0) {
                return false;
            }
            self.add_triangle(t);
            for x in [pn, node, nn] {
                self.kill(x);
            }
            self.front_size[nd.front as usize] = 0;
            return true;
        }
        let theta = self.angle(node, nv);
        let np = self.expected_normal(pn);
        let nq = self.expected_normal(nn);
        let order: &[usize] = if theta <= alpha {
            &[0, 1]
        } else if theta <= beta {
            &[1, 0, 2]
        } else {
            &[2, 1]
        };
        for &m in order {
            if let Some(plan) = self.plan(node, m, theta, [np, nv, nq]) {
                self.commit(node, plan);
                return true;
            }
        }
        false
    }

    /// Elevation (radians, out of the tangent plane of `nrm`) of the front on one side of
    /// a node, at distance `Avglen`: for the `j`-th front neighbour at distance `s_j` the
    /// chord's elevation `e_j` is about `-κ s_j / 2` on a smooth front, so the estimate is
    /// `Avglen · mean_j(e_j / s_j)` over `FRONT_SPAN` neighbours (fewer on a short front). A
    /// zig-zag of amplitude `a` adds only about `a / s_j²` per neighbour.
    fn side_elevation(&self, node: u32, nrm: DVec3, forward: bool) -> f64 {
        let v = self.p(node);
        let other_end = if forward {
            self.nodes[node as usize].prev
        } else {
            self.nodes[node as usize].next
        };
        let mut a = node;
        let (mut sum, mut n) = (0.0, 0usize);
        for _ in 0..FRONT_SPAN {
            let nd = self.nodes[a as usize];
            a = if forward { nd.next } else { nd.prev };
            if a == node || (n > 0 && a == other_end) {
                break;
            }
            let e = self.p(a) - v;
            let s = e.length();
            if s > 0.0 {
                sum += (e.dot(nrm) / s).clamp(-1.0, 1.0).asin() / s;
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            (self.len * sum / n as f64).clamp(-MAX_EL, MAX_EL)
        }
    }

    /// Last resort for a small stuck front: ear clipping without the overlap and angle
    /// tests (best smallest angle first among ears facing the front's mean normal, else
    /// the best ear). The dispatcher's checks judge the result.
    fn clip_small_front(&mut self, start: u32) -> bool {
        let f = self.nodes[start as usize].front as usize;
        let mut ring = vec![start];
        let mut a = self.nodes[start as usize].next;
        while a != start && ring.len() <= SMALL_FRONT {
            ring.push(a);
            a = self.nodes[a as usize].next;
        }
        if a != start || ring.len() < 3 {
            return false;
        }
        let vert = |w: &Wave, n: u32| w.nodes[n as usize].vert;
        let pts: Vec<DVec3> = ring.iter().map(|&n| self.p(n)).collect();
        let nrm = unit_or(measure::newell_normal(&pts), self.expected_normal(start));
        while ring.len() > 3 {
            let m = ring.len();
            let mut best: Option<(bool, f64, usize)> = None;
            for i in 0..m {
                let t = [ring[(i + m - 1) % m], ring[i], ring[(i + 1) % m]].map(|n| vert(self, n));
                if self.edge_exists(t[0], t[2]) {
                    continue;
                }
                let p = t.map(|x| self.pos[x as usize]);
                let n = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO);
                let ang = measure::angles(p[0], p[1], p[2]);
                let key = (n.dot(nrm) > FACING_MIN, ang[0].min(ang[1]).min(ang[2]), i);
                if best.is_none_or(|b| (key.0, key.1) > (b.0, b.1)) {
                    best = Some(key);
                }
            }
            let Some((_, _, i)) = best else { return false };
            let t = [ring[(i + m - 1) % m], ring[i], ring[(i + 1) % m]].map(|n| vert(self, n));
            self.add_triangle(t);
            self.kill(ring[i]);
            ring.remove(i);
        }
        let t = [ring[0], ring[1], ring[2]].map(|n| vert(self, n));
        self.add_triangle(t);
        for n in ring {
            self.kill(n);
        }
        self.front_size[f] = 0;
        self.stats.clipped_fronts += 1;
        true
    }

    /// Direction from the vertex at fraction `f` of θ from the next edge (see module doc).
    fn direction(&self, node: u32, nrm: DVec3, theta: f64, f: f64) -> DVec3 {
        let nd = self.nodes[node as usize];
        let v = self.p(node);
        let en = unit_or(self.p(nd.next) - v, DVec3::ZERO);
        let tn = unit_or(en - nrm * en.dot(nrm), nrm.any_orthonormal_vector());
        let bn = nrm.cross(tn);
        let (s, c) = (f * theta).sin_cos();
        let dt = tn * c + bn * s;
        let el_n = self.side_elevation(node, nrm, true);
        let el_p = self.side_elevation(node, nrm, false);
        let interp = (1.0 - f) * el_n + f * el_p;
        let el = match self.placement {
            WavefrontPlacement::Interpolated => interp,
            WavefrontPlacement::EdgePlane if theta < PI => {
                // the plane of the two edges as a height function over the tangent plane:
                // slope g·d with g·t_n = tan el_n and g·t_p = tan el_p
                let (hn, hp) = (
                    el_n.clamp(-MAX_EL, MAX_EL).tan(),
                    el_p.clamp(-MAX_EL, MAX_EL).tan(),
                );
                let st = theta.sin();
                let w = (st / PLANE_WINDOW.sin()).clamp(0.0, 1.0);
                if w > 0.0 {
                    let g2 = (hp - hn * theta.cos()) / st;
                    w * (hn * c + g2 * s).atan() + (1.0 - w) * interp
                } else {
                    interp
                }
            }
            WavefrontPlacement::EdgePlane => interp,
        };
        let (se, ce) = el.sin_cos();
        dt * ce + nrm * se
    }

    /// The nearest live node of `front` within `r` of `x`, other than `skip`.
    fn nearest_node(&mut self, x: DVec3, r: f64, front: u32, skip: [u32; 3]) -> Option<u32> {
        let mut ids = std::mem::take(&mut self.scratch);
        let d = DVec3::splat(r);
        self.node_grid.query_box(x - d, x + d, &mut ids);
        let mut best: Option<(f64, u32)> = None;
        for &id in &ids {
            let nd = self.nodes[id as usize];
            if !nd.alive || nd.front != front || skip.contains(&id) {
                continue;
            }
            let dist = (self.pos[nd.vert as usize] - x).length();
            // ties go to the smallest id (the query's order is arbitrary)
            if dist < r && best.is_none_or(|(b, bid)| dist < b || (dist == b && id < bid)) {
                best = Some((dist, id));
            }
        }
        self.scratch = ids;
        best.map(|b| b.1)
    }

    /// Does `x` project (onto the loop's best-fit plane) inside the loop or within
    /// `Avglen / 2` of it? (Points nearer the centre than every loop vertex are inside
    /// without a look at the loop.)
    fn inside_loop(&self, x: DVec3) -> bool {
        let d = x - self.centre;
        let (px, py) = (d.dot(self.plane_u), d.dot(self.plane_w));
        px * px + py * py < self.inner * self.inner
            || inside_or_near(&self.loop2d, (px, py), 0.5 * self.len)
    }

    /// Is `x` within `clear` of an edge of `front` whose ends are not in `skip`, yet not
    /// near enough to one of its ends to merge? (Edges are found from their ends within
    /// `clear + 1.5 Avglen` of `x`.)
    fn near_front_edge(&mut self, x: DVec3, clear: f64, front: u32, skip: [u32; 3]) -> bool {
        let mut ids = std::mem::take(&mut self.scratch);
        let d = DVec3::splat(clear + 1.5 * self.len);
        self.node_grid.query_box(x - d, x + d, &mut ids);
        let mut hit = false;
        for &id in &ids {
            let nd = self.nodes[id as usize];
            if !nd.alive || nd.front != front {
                continue;
            }
            let b = self.nodes[nd.next as usize].vert;
            if skip.contains(&nd.vert) || skip.contains(&b) {
                continue;
            }
            let (p, q) = (self.pos[nd.vert as usize], self.pos[b as usize]);
            // edges found from their ends in the box (whatever else the grid returns)
            if (p - x).abs().cmpgt(d).any() {
                continue;
            }
            let e = q - p;
            let t = ((x - p).dot(e) / e.length_squared().max(1e-300)).clamp(0.0, 1.0);
            if (p + e * t - x).length() < clear && t > 0.0 && t < 1.0 {
                hit = true;
                break;
            }
        }
        self.scratch = ids;
        hit
    }

    fn edge_exists(&self, a: u32, b: u32) -> bool {
        let e = ekey(a, b);
        self.edges.contains(&e)
            || ((a as usize) < self.k && (b as usize) < self.k && self.mesh_edges.contains(&e))
    }

    /// Builds and validates the variant with `m` new points (0, 1 or 2).
    fn plan(&mut self, node: u32, m: usize, theta: f64, [np, nv, nq]: [DVec3; 3]) -> Option<Plan> {
        let nd = self.nodes[node as usize];
        let (pn, nn) = (nd.prev, nd.next);
        let (p, v, q) = (self.p(pn), self.p(node), self.p(nn));
        let mut pts: Vec<DVec3> = (1..=m)
            .map(|j| {
                v + self.direction(node, nv, theta, 1.0 - j as f64 / (m + 1) as f64) * self.len
            })
            .collect();
        if self.restore && m > 0 {
            let rot = |x: DVec3, a: DVec3, b: DVec3, c: DVec3, want: DVec3| {
                let n = unit_or((b - a).cross(c - a), DVec3::ZERO);
                let want = unit_or(want, DVec3::ZERO);
                if n == DVec3::ZERO || want == DVec3::ZERO {
                    x
                } else {
                    rotate_to(x, (a + b + c) / 3.0, n, want)
                }
            };
            // case (b): triangles (p, v, x) and (x, v, q); case (c): the two outer ones
            let first = rot(pts[0], p, v, pts[0], np + nv);
            let last = rot(pts[m - 1], pts[m - 1], v, q, nv + nq);
            if m == 1 {
                pts[0] = (first + last) * 0.5;
            } else {
                pts[0] = first;
                pts[m - 1] = last;
            }
        }
        // merging and the too-close test
        let r = self.merge_radius;
        let mut chain = vec![Item::Node(pn)];
        let mut merged: Option<u32> = None;
        for &x in &pts {
            if !x.is_finite() || (x - self.centre).length() > self.reach || !self.inside_loop(x) {
                return None;
            }
            if r > 0.0 {
                if (x - p).length() < r || (x - q).length() < r || (x - v).length() < r {
                    return None;
                }
                let (pv, vv, qv) = (
                    self.nodes[pn as usize].vert,
                    nd.vert,
                    self.nodes[nn as usize].vert,
                );
                if self.near_front_edge(x, 0.5 * r, nd.front, [pv, vv, qv]) {
                    return None;
                }
                if let Some(a) = self.nearest_node(x, r, nd.front, [pn, node, nn]) {
                    match merged {
                        None => {
                            merged = Some(a);
                            chain.push(Item::Node(a));
                        }
                        Some(b) if b == a => {}
                        Some(_) => return None,
                    }
                    continue;
                }
            }
            chain.push(Item::New(x));
        }
        chain.push(Item::Node(nn));
        // ids, positions and new edges
        let base = self.pos.len() as u32;
        let mut newpos = Vec::new();
        let ids: Vec<u32> = chain
            .iter()
            .map(|it| match *it {
                Item::Node(a) => self.nodes[a as usize].vert,
                Item::New(x) => {
                    newpos.push(x);
                    base + newpos.len() as u32 - 1
                }
            })
            .collect();
        let old = |i: usize| match chain[i] {
            Item::Node(a) => Some(a),
            Item::New(_) => None,
        };
        for j in 0..chain.len() - 1 {
            if let (Some(a), Some(b)) = (old(j), old(j + 1)) {
                if self.edge_exists(ids[j], ids[j + 1]) {
                    // a merge into the second neighbour closes the edge between them (zip)
                    let zip = (a == pn && b == self.nodes[pn as usize].prev)
                        || (b == nn && a == self.nodes[nn as usize].next);
                    if !zip {
                        return None;
                    }
                }
            }
            if j > 0 && old(j).is_some() && self.edge_exists(nd.vert, ids[j]) {
                return None;
            }
        }
        // the front angles left at v_{i-1} and v_{i+1} must not be slivers in the making
        let pos_of = |j: usize| -> DVec3 {
            match chain[j] {
                Item::Node(a) => self.p(a),
                Item::New(x) => x,
            }
        };
        let last = chain.len() - 1;
        let pp = self.p(self.nodes[pn as usize].prev);
        let qq = self.p(self.nodes[nn as usize].next);
        let front_angle = |at: DVec3, a: DVec3, b: DVec3| measure::angle_at(at, a, b);
        if self.front_size[nd.front as usize] > 3
            && !self.relaxed
            && (front_angle(p, pp, pos_of(1)) < MIN_FRONT_ANGLE
                || front_angle(q, pos_of(last - 1), qq) < MIN_FRONT_ANGLE)
        {
            return None;
        }
        let tris: Vec<[u32; 3]> = (0..chain.len() - 1)
            .map(|j| [ids[j], nd.vert, ids[j + 1]])
            .collect();
        let min_angle = if self.relaxed { 0.0 } else { self.min_angle };
        if !self.valid(nd.vert, &tris, &newpos, nv, min_angle)
            || !self.small_fronts_ok(node, &chain, &ids, &newpos, merged, nv)
        {
            return None;
        }
        Some(Plan { chain })
    }

    /// Would the step leave a front of three vertices whose last triangle is flipped, or
    /// a sliver that cannot be flipped away later (its longest edge on the hole loop)? Walks the fronts after the step
    /// without changing them, at most three nodes from each changed place.
    fn small_fronts_ok(
        &self,
        node: u32,
        chain: &[Item],
        ids: &[u32],
        newpos: &[DVec3],
        merged: Option<u32>,
        nrm: DVec3,
    ) -> bool {
        let nd = self.nodes[node as usize];
        let last = chain.len() - 1;
        let base = self.nodes.len() as u32;
        // node ids after the step: chain interior items get fresh ids base + j - 1
        let cnode = |j: usize| -> u32 {
            match chain[j] {
                Item::Node(a) if j == 0 || j == last => a,
                _ => base + j as u32 - 1,
            }
        };
        let mut over: Vec<(u32, u32)> = (0..last).map(|j| (cnode(j), cnode(j + 1))).collect();
        let vert_of = |x: u32| -> u32 {
            if x >= base {
                ids[(x - base) as usize + 1]
            } else {
                self.nodes[x as usize].vert
            }
        };
        if let Some(a) = merged {
            if let Some(jm) = (1..last).find(|&j| matches!(chain[j], Item::Node(x) if x == a)) {
                let b = cnode(jm);
                let an = self.nodes[a as usize].next;
                let bn = cnode(jm + 1);
                over.retain(|&(x, _)| x != b);
                over.push((a, bn));
                over.push((b, an));
            }
        }
        let next = |x: u32| -> u32 {
            over.iter()
                .find(|&&(y, _)| y == x)
                .map(|&(_, z)| z)
                .unwrap_or_else(|| self.nodes[x as usize].next)
        };
        let np = self.pos.len();
        let at = |i: u32| -> DVec3 {
            let i = i as usize;
            if i < np {
                self.pos[i]
            } else {
                newpos[i - np]
            }
        };
        for s in [nd.prev, nd.next] {
            let x1 = next(s);
            let x2 = next(x1);
            if next(x2) != s || x1 == s || x2 == s {
                continue;
            }
            let p = [vert_of(s), vert_of(x1), vert_of(x2)].map(at);
            let n = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO);
            if !(n.dot(nrm) > FACING_MIN) {
                return false;
            }
            // a sliver whose longest edge has a mesh face across cannot be flipped away
            let ang = measure::angles(p[0], p[1], p[2]);
            let c = (0..3).fold(0, |m, c| if ang[c] > ang[m] { c } else { m });
            let v = [vert_of(s), vert_of(x1), vert_of(x2)];
            let (a, b) = (v[(c + 1) % 3], v[(c + 2) % 3]);
            let across_mesh = (a as usize) < self.k
                && (b as usize) < self.k
                && self.mesh_edges.contains(&ekey(a, b));
            if across_mesh && !self.relaxed && ang.iter().any(|&x| !(x >= self.min_angle)) {
                return false;
            }
        }
        true
    }

    /// Are the step's triangles acceptable (angles, facing, no overlap, no crossing)?
    fn valid(
        &mut self,
        v: u32,
        tris: &[[u32; 3]],
        newpos: &[DVec3],
        nrm: DVec3,
        min_angle: f64,
    ) -> bool {
        let np = self.pos.len();
        let at = |i: u32| -> DVec3 {
            let i = i as usize;
            if i < np {
                self.pos[i]
            } else {
                newpos[i - np]
            }
        };
        let mut corners = Vec::with_capacity(tris.len());
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for t in tris {
            let p = t.map(at);
            if !(measure::smallest_angle(p[0], p[1], p[2]) >= min_angle) {
                return false;
            }
            let n = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO);
            if !(n.dot(nrm) > FACING_MIN) {
                return false;
            }
            for x in p {
                lo = lo.min(x);
                hi = hi.max(x);
            }
            corners.push(p);
        }
        // tangent plane of the vertex
        let o = self.pos[v as usize];
        let u = nrm.any_orthonormal_vector();
        let w = nrm.cross(u);
        let proj = |x: DVec3| p2((x - o).dot(u), (x - o).dot(w));
        let pr = |t: &[DVec3; 3]| [proj(t[0]), proj(t[1]), proj(t[2])];
        for i in 0..corners.len() {
            for j in 0..i {
                if overlap2d(pr(&corners[i]), pr(&corners[j])) {
                    return false;
                }
            }
        }
        // each new triangle once: projected (counter-clockwise, `None` when degenerate,
        // which overlaps everything) and its boxes, which skip the exact tests of the
        // nearby triangles they cannot meet (same answers, fewer predicates)
        let cand: Vec<Candidate> = tris
            .iter()
            .zip(&corners)
            .map(|(t, c)| {
                let p2 = pr(c);
                Candidate {
                    ids: t.map(Some),
                    ccw: ccw2d(p2),
                    box2: Box2::of(&p2),
                    box3: Box3::of(c),
                }
            })
            .collect();
        // the triangles within `Avglen` of the step's box (farther ones cannot meet it)
        let d = DVec3::splat(self.len);
        let (qlo, qhi) = (lo - d, hi + d);
        let mut near = std::mem::take(&mut self.scratch);
        self.tri_grid.query_box(qlo, qhi, &mut near);
        near.extend_from_slice(&self.big);
        let mut ok = true;
        'outer: for &id in &near {
            let pl = &self.placed[id as usize];
            if pl.hi.cmplt(qlo).any() || qhi.cmplt(pl.lo).any() {
                continue;
            }
            if pl.n.dot(nrm) > PROJECT_MIN {
                let q = pr(&pl.p);
                let qb = Box2::of(&q);
                for c in &cand {
                    let hit = match c.ccw {
                        None => true,
                        Some(a) => c.box2.meets(&qb) && overlap2d_ccw(a, q),
                    };
                    if hit {
                        ok = false;
                        break 'outer;
                    }
                }
            } else {
                let pb = Box3::of(&pl.p);
                for (c, corner) in cand.iter().zip(&corners) {
                    if c.box3.meets(&pb) && cross3d(c.ids, corner, pl.ids, &pl.p) {
                        ok = false;
                        break 'outer;
                    }
                }
            }
        }
        self.scratch = near;
        ok
    }

    /// Flips the longest edge of each sliver (smallest angle below twice the checks'
    /// bound, at least 1 degree) with the patch triangle across it when that raises the
    /// smallest angle of the pair, keeps both facing the same way and makes no duplicate
    /// edge. Closing a thin front of three vertices can leave such slivers.
    fn flip_slivers(&mut self) {
        let tau = (2.0 * self.min_angle).max(1f64.to_radians());
        let min_of = |p: [DVec3; 3]| {
            let a = measure::angles(p[0], p[1], p[2]);
            a[0].min(a[1]).min(a[2])
        };
        let mut owner: HashMap<(u32, u32), usize> =
            HashMap::with_capacity_and_hasher(self.tris.len() * 3, Default::default());
        for (i, t) in self.tris.iter().enumerate() {
            for c in 0..3 {
                owner.insert((t[c], t[(c + 1) % 3]), i);
            }
        }
        for _round in 0..4 {
            let mut changed = false;
            for i in 0..self.tris.len() {
                let t = self.tris[i];
                let p = t.map(|v| self.pos[v as usize]);
                let ang = measure::angles(p[0], p[1], p[2]);
                if !(ang[0].min(ang[1]).min(ang[2]) < tau) {
                    continue;
                }
                let c = (0..3).fold(0, |m, c| if ang[c] > ang[m] { c } else { m });
                let (x, a, b) = (t[c], t[(c + 1) % 3], t[(c + 2) % 3]);
                let Some(&j) = owner.get(&(b, a)) else {
                    continue;
                };
                let u = self.tris[j];
                let Some(&y) = u.iter().find(|&&q| q != a && q != b) else {
                    continue;
                };
                if y == x || self.edge_exists(x, y) {
                    continue;
                }
                let q = u.map(|v| self.pos[v as usize]);
                let nref = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO)
                    + unit_or((q[1] - q[0]).cross(q[2] - q[0]), DVec3::ZERO);
                let t1 = [x, a, y];
                let t2 = [x, y, b];
                let p1 = t1.map(|v| self.pos[v as usize]);
                let p2 = t2.map(|v| self.pos[v as usize]);
                let faces = |r: [DVec3; 3]| {
                    unit_or((r[1] - r[0]).cross(r[2] - r[0]), DVec3::ZERO).dot(nref) > FACING_MIN
                };
                let before = min_of(p).min(min_of(q));
                let after = min_of(p1).min(min_of(p2));
                if !(faces(p1) && faces(p2) && after > before) {
                    continue;
                }
                self.tris[i] = t1;
                self.tris[j] = t2;
                owner.remove(&(a, b));
                owner.remove(&(b, a));
                for (k, tt) in [(i, t1), (j, t2)] {
                    for c in 0..3 {
                        owner.insert((tt[c], tt[(c + 1) % 3]), k);
                    }
                }
                self.edges.remove(&ekey(a, b));
                self.edges.insert(ekey(x, y));
                changed = true;
            }
            if !changed {
                break;
            }
        }
    }

    fn add_triangle(&mut self, t: [u32; 3]) {
        let p = t.map(|i| self.pos[i as usize]);
        for c in 0..3 {
            self.edges.insert(ekey(t[c], t[(c + 1) % 3]));
            if let Some((wt, n)) = face_weight(p[c], p[0], p[1], p[2]) {
                self.acc[t[c] as usize] += wt * n;
            }
        }
        self.tris.push(t);
        let cr = (p[1] - p[0]).cross(p[2] - p[0]);
        self.area += 0.5 * cr.length();
        let n = unit_or(cr, DVec3::ZERO);
        self.place(Placed {
            ids: t.map(Some),
            p,
            n,
            lo: DVec3::ZERO,
            hi: DVec3::ZERO,
        });
    }

    fn commit(&mut self, node: u32, plan: Plan) {
        let nd = self.nodes[node as usize];
        let front = nd.front;
        let mut chain_nodes: Vec<u32> = Vec::with_capacity(plan.chain.len());
        let mut verts: Vec<u32> = Vec::with_capacity(plan.chain.len());
        let last = plan.chain.len() - 1;
        let mut split: Option<(u32, u32)> = None;
        for (j, it) in plan.chain.iter().enumerate() {
            match *it {
                Item::Node(a) if j == 0 || j == last => {
                    chain_nodes.push(a);
                    verts.push(self.nodes[a as usize].vert);
                }
                Item::Node(a) => {
                    let vert = self.nodes[a as usize].vert;
                    let b = self.new_node(vert, 0, 0, front);
                    split = Some((a, b));
                    self.stats.merges += 1;
                    chain_nodes.push(b);
                    verts.push(vert);
                }
                Item::New(x) => {
                    let vert = self.pos.len() as u32;
                    self.pos.push(x);
                    self.acc.push(DVec3::ZERO);
                    chain_nodes.push(self.new_node(vert, 0, 0, front));
                    verts.push(vert);
                }
            }
        }
        for j in 0..last {
            self.add_triangle([verts[j], nd.vert, verts[j + 1]]);
        }
        for j in 0..last {
            self.nodes[chain_nodes[j] as usize].next = chain_nodes[j + 1];
            self.nodes[chain_nodes[j + 1] as usize].prev = chain_nodes[j];
        }
        self.kill(node);
        let f = front as usize;
        self.front_size[f] = self.front_size[f] + last - 1 - 1;
        let mut touched = chain_nodes.clone();
        if let Some((a, b)) = split {
            self.split(a, b);
            touched.push(a);
        }
        for t in touched {
            self.refresh(t);
        }
    }

    /// Splits a front at two nodes of the same vertex into two fronts; a front of two
    /// nodes left over is one edge seen from both sides and is zipped.
    fn split(&mut self, a: u32, b: u32) {
        let an = self.nodes[a as usize].next;
        let bn = self.nodes[b as usize].next;
        self.nodes[a as usize].next = bn;
        self.nodes[bn as usize].prev = a;
        self.nodes[b as usize].next = an;
        self.nodes[an as usize].prev = b;
        // walk both cycles together; the shorter one becomes a new front
        let (mut x, mut y) = (a, b);
        let mut count = 0usize;
        let bound = self.nodes.len();
        let small = loop {
            count += 1;
            x = self.nodes[x as usize].next;
            y = self.nodes[y as usize].next;
            if x == a {
                break a;
            }
            if y == b {
                break b;
            }
            if count > bound {
                self.corrupt = true;
                return;
            }
        };
        let old = self.nodes[a as usize].front as usize;
        let new = self.front_size.len() as u32;
        self.front_size.push(count);
        if self.front_size[old] < count + 2 {
            self.corrupt = true;
            return;
        }
        self.front_size[old] -= count;
        let mut z = small;
        for _ in 0..count {
            self.nodes[z as usize].front = new;
            z = self.nodes[z as usize].next;
        }
        for (start, f) in [
            (a, self.nodes[a as usize].front),
            (b, self.nodes[b as usize].front),
        ] {
            if self.front_size[f as usize] == 2 {
                let other = self.nodes[start as usize].next;
                self.stats.zips += 1;
                self.kill(start);
                self.kill(other);
                self.front_size[f as usize] = 0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::{check_degenerate, check_topology, patch_positions};
    use crate::fill::kit::Deadline;
    use crate::io::RawMesh;
    use crate::mesh::{Mesh, VertexId};
    use crate::patch::{apply_patch, Hole};
    use crate::policy::{Method, Policy};
    use proptest::prelude::*;

    /// A regular grid `n x n` over `[-1, 1]^2` with heights `z(x, y)`, faces up, and the
    /// faces whose centroid lies within `r` of the origin removed.
    fn grid_hole(n: usize, r: f64, z: impl Fn(f64, f64) -> f64) -> RawMesh {
        let mut raw = RawMesh::default();
        for j in 0..=n {
            for i in 0..=n {
                let x = -1.0 + 2.0 * i as f64 / n as f64;
                let y = -1.0 + 2.0 * j as f64 / n as f64;
                raw.positions.push(DVec3::new(x, y, z(x, y)));
            }
        }
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        for j in 0..n {
            for i in 0..n {
                for f in [
                    [id(i, j), id(i + 1, j), id(i + 1, j + 1)],
                    [id(i, j), id(i + 1, j + 1), id(i, j + 1)],
                ] {
                    let c = f.iter().map(|&v| raw.positions[v as usize]).sum::<DVec3>() / 3.0;
                    if c.x * c.x + c.y * c.y > r * r {
                        raw.faces.push(f);
                    }
                }
            }
        }
        raw
    }

    /// An icosphere of radius `rad` subdivided `level` times, faces outward, with the
    /// faces whose centroid direction is within `cap` radians of `dir` removed.
    fn sphere_hole(level: usize, rad: f64, dir: DVec3, cap: f64) -> RawMesh {
        crate::testutil::sphere_cap_removed(level, rad, dir, cap)
    }

    /// An open cylinder of radius `rad` around z, `nt` columns, `nz` rows of height
    /// `h`, faces outward, with the faces whose centroid is within `r` of `(rad, 0, 0)`
    /// removed.
    fn cylinder_hole(rad: f64, nt: usize, nz: usize, h: f64, r: f64) -> RawMesh {
        let mut raw = RawMesh::default();
        let z0 = -(nz as f64) * h / 2.0;
        for j in 0..=nz {
            for i in 0..nt {
                let a = TAU * i as f64 / nt as f64;
                raw.positions
                    .push(DVec3::new(rad * a.cos(), rad * a.sin(), z0 + j as f64 * h));
            }
        }
        let id = |i: usize, j: usize| (j * nt + i % nt) as u32;
        let hc = DVec3::new(rad, 0.0, 0.0);
        for j in 0..nz {
            for i in 0..nt {
                for f in [
                    [id(i, j), id(i + 1, j), id(i + 1, j + 1)],
                    [id(i, j), id(i + 1, j + 1), id(i, j + 1)],
                ] {
                    let c = f.iter().map(|&v| raw.positions[v as usize]).sum::<DVec3>() / 3.0;
                    if (c - hc).length() > r {
                        raw.faces.push(f);
                    }
                }
            }
        }
        raw
    }

    /// The loop of `mesh` whose centroid is nearest `p`.
    fn loop_near(mesh: &Mesh, p: DVec3) -> Vec<VertexId> {
        let mut loops = mesh.topo.boundary_loops();
        loops.sort_by(|a, b| {
            let c = |l: &Vec<VertexId>| {
                l.iter()
                    .map(|&v| (mesh.pos(v) - p).length())
                    .fold(0.0, f64::max)
            };
            c(a).total_cmp(&c(b))
        });
        loops.swap_remove(0)
    }

    fn run(mesh: &Mesh, l: Vec<VertexId>, policy: &Policy) -> (Hole, Result<Patch, FillError>) {
        let hole = Hole::new(0, mesh, l, policy);
        let ctx = FillContext {
            mesh,
            hole: &hole,
            policy,
            deadline: Deadline::none(),
            checker: None,
        };
        let r = fill(&ctx);
        (hole, r)
    }

    /// The patch passes the dispatcher's checks and applies to a valid, hole-free mesh.
    fn accept(mesh: &Mesh, hole: &Hole, patch: &Patch, policy: &Policy) {
        check_topology(mesh, &hole.vertices, patch).unwrap();
        let pos = patch_positions(mesh, &hole.vertices, patch);
        check_degenerate(&pos, patch, &policy.checks).unwrap();
        let mut m = mesh.clone();
        let loops = m.topo.boundary_loops().len();
        apply_patch(&mut m, hole, patch).unwrap();
        m.validate().unwrap();
        assert_eq!(m.topo.boundary_loops().len(), loops - 1);
    }

    /// Mean and max of `err` over the new vertices.
    fn stats_of(patch: &Patch, err: impl Fn(DVec3) -> f64) -> (f64, f64) {
        let e: Vec<f64> = patch.new_vertices.iter().map(|&p| err(p)).collect();
        let mean = e.iter().sum::<f64>() / e.len().max(1) as f64;
        (mean, e.iter().cloned().fold(0.0, f64::max))
    }

    #[test]
    fn planar_hole_gives_a_planar_patch() {
        let (mesh, _) = Mesh::from_raw(&grid_hole(20, 0.45, |_, _| 0.0));
        let policy = Policy::default();
        let l = loop_near(&mesh, DVec3::ZERO);
        assert!(l.len() > 20, "{}", l.len());
        let (hole, r) = run(&mesh, l, &policy);
        let patch = r.unwrap();
        assert!(!patch.new_vertices.is_empty());
        accept(&mesh, &hole, &patch, &policy);
        for p in &patch.new_vertices {
            assert!(p.z.abs() < 1e-9, "{p}");
            assert!(p.x * p.x + p.y * p.y < 0.6 * 0.6, "{p} outside the hole");
        }
    }

    /// A filled hole measured against its surface.
    #[derive(Debug)]
    struct Measure {
        k: usize,
        mean: f64,
        max: f64,
        stats: Stats,
        patch: Patch,
    }

    /// Fills the loop nearest `centre` under a policy changed by `tweak`, checks the patch
    /// like the dispatcher does and measures `|err|` over the new vertices.
    fn measure(
        raw: &RawMesh,
        centre: DVec3,
        tweak: impl Fn(&mut Policy),
        err: impl Fn(DVec3) -> f64,
    ) -> Measure {
        let (mesh, _) = Mesh::from_raw(raw);
        mesh.validate().unwrap();
        let mut policy = Policy::default();
        tweak(&mut policy);
        let l = loop_near(&mesh, centre);
        let k = l.len();
        let hole = Hole::new(0, &mesh, l, &policy);
        let ctx = FillContext {
            mesh: &mesh,
            hole: &hole,
            policy: &policy,
            deadline: Deadline::none(),
            checker: None,
        };
        let (patch, stats) = fill_with_stats(&ctx).unwrap();
        accept(&mesh, &hole, &patch, &policy);
        let (mean, max) = stats_of(&patch, |p| err(p).abs());
        Measure {
            k,
            mean,
            max,
            stats,
            patch,
        }
    }

    fn restore(on: bool) -> impl Fn(&mut Policy) {
        move |p: &mut Policy| p.wavefront.curvature_restoration = on
    }

    fn sphere_err(p: DVec3) -> f64 {
        p.length() - 1.0
    }

    fn sphere(level: usize, cap: f64) -> RawMesh {
        sphere_hole(level, 1.0, DVec3::new(0.3, 0.2, 1.0), cap)
    }

    const SPHERE_DIR: DVec3 = DVec3::new(0.3, 0.2, 1.0);

    /// Unit sphere, hole of ~30 boundary vertices (icosphere level 3, 25): mean |r - 1| of
    /// the new vertices below 0.05, max below 0.15 (measured 0.033 / 0.090 with
    /// restoration, 0.033 / 0.067 without; edge length 0.148). Hole of ~150 (level 5, 140):
    /// below 0.03 with restoration, 0.05 without (measured 0.020 and 0.032; edge length
    /// 0.037), and restoration is better there.
    #[test]
    fn sphere_holes_stay_near_the_sphere() {
        let small_on = measure(&sphere(3, 0.55), SPHERE_DIR, restore(true), sphere_err);
        let small_off = measure(&sphere(3, 0.55), SPHERE_DIR, restore(false), sphere_err);
        assert!((20..=40).contains(&small_on.k), "{}", small_on.k);
        assert!(small_on.mean < 0.05 && small_off.mean < 0.05);
        assert!(small_on.max < 0.15 && small_off.max < 0.15);
        let large_on = measure(&sphere(5, 0.7), SPHERE_DIR, restore(true), sphere_err);
        let large_off = measure(&sphere(5, 0.7), SPHERE_DIR, restore(false), sphere_err);
        assert!((120..=180).contains(&large_on.k), "{}", large_on.k);
        assert!(large_on.mean < 0.03, "{}", large_on.mean);
        assert!(large_off.mean < 0.05, "{}", large_off.mean);
        assert!(large_on.mean <= large_off.mean);
    }

    /// A hole deeper than a hemisphere (cap of 109 degrees: its surface has 2.95 times
    /// the loop's vector area): the front passes `max_area_ratio` (2.0) and stops with
    /// the runaway failure at once, the other full-front variants are skipped, and a
    /// residual-closing variant closes the hole with a patch that passes the checks
    /// (with the front allowed to close the whole hole, `max_steps_per_vertex = 200`;
    /// the default of 4 closes the residual first, checked at the end). Without the
    /// bound the policy's front is not stopped that way.
    #[test]
    fn a_front_over_a_deep_hole_stops_as_runaway_and_a_residual_variant_closes_it() {
        let (mesh, _) = Mesh::from_raw(&sphere(3, 1.9));
        let loops = mesh.topo.boundary_loops();
        assert_eq!(loops.len(), 1);
        let mut policy = Policy::default();
        assert_eq!(policy.wavefront.max_area_ratio, 2.0);
        policy.wavefront.max_steps_per_vertex = 200;
        let hole = Hole::new(0, &mesh, loops[0].clone(), &policy);
        let ctx = FillContext {
            mesh: &mesh,
            hole: &hole,
            policy: &policy,
            deadline: Deadline::none(),
            checker: None,
        };
        match fill_with_stats(&ctx) {
            Err(FillError::Failed(e)) => assert!(e.starts_with(RUNAWAY), "{e}"),
            other => panic!("expected the runaway failure, got {:?}", other.map(|p| p.1)),
        }
        let patch = fill(&ctx).unwrap();
        accept(&mesh, &hole, &patch, &policy);
        let mut free = policy.clone();
        free.wavefront.max_area_ratio = 0.0;
        let ctx = FillContext {
            policy: &free,
            ..ctx
        };
        if let Err(FillError::Failed(e)) = fill_with_stats(&ctx) {
            assert!(!e.starts_with(RUNAWAY), "{e}");
        }
        // the default: a few rings of front, then the residual, within the bound
        let default = Policy::default();
        let ctx = FillContext {
            policy: &default,
            ..ctx
        };
        let (patch, stats) = fill_with_stats(&ctx).unwrap();
        assert!(stats.residual_fronts >= 1, "{stats:?}");
        accept(&mesh, &hole, &patch, &default);
    }

    /// Curvature restoration against none, over every curved oracle here: five sphere
    /// holes (25 to 140 boundary vertices), a cylinder, a saddle, a paraboloid. Per hole it
    /// is not always better (on one of the five sphere holes it is 1.5 % worse); on the sum
    /// of mean errors it is better (measured 0.169 against 0.252).
    #[test]
    fn curvature_restoration_is_not_worse_overall() {
        type Case = (RawMesh, DVec3, fn(DVec3) -> f64);
        let mut cases: Vec<Case> = Vec::new();
        for (level, cap) in [(3, 0.55), (3, 0.8), (4, 0.5), (4, 0.9), (5, 0.7)] {
            cases.push((sphere(level, cap), SPHERE_DIR, sphere_err));
        }
        cases.push((cylinder_hole(1.0, 60, 40, 0.1, 0.5), DVec3::X, cylinder_err));
        cases.push((
            grid_hole(40, 0.45, |x, y| x * x - y * y),
            DVec3::ZERO,
            saddle_err,
        ));
        cases.push((
            grid_hole(40, 0.45, |x, y| 0.5 * (x * x + y * y)),
            DVec3::ZERO,
            bowl_err,
        ));
        let (mut on, mut off) = (0.0, 0.0);
        for (raw, c, err) in &cases {
            let a = measure(raw, *c, restore(true), err);
            let b = measure(raw, *c, restore(false), err);
            eprintln!(
                "k {:3}: restoration {:.5}, without {:.5}",
                a.k, a.mean, b.mean
            );
            on += a.mean;
            off += b.mean;
        }
        eprintln!("sum: restoration {on:.4}, without {off:.4}");
        assert!(on <= off, "{on} > {off}");
    }

    fn cylinder_err(p: DVec3) -> f64 {
        (p.x * p.x + p.y * p.y).sqrt() - 1.0
    }
    fn saddle_err(p: DVec3) -> f64 {
        p.z - (p.x * p.x - p.y * p.y)
    }
    fn bowl_err(p: DVec3) -> f64 {
        p.z - 0.5 * (p.x * p.x + p.y * p.y)
    }

    /// Cylinder of radius 1, hole of radius 0.5 (36 boundary vertices, edge length 0.1):
    /// mean |rho - 1| below 0.008 with restoration, 0.025 without (measured 0.0047 and
    /// 0.018), max below 0.05.
    #[test]
    fn cylinder_hole_stays_near_the_cylinder() {
        let raw = cylinder_hole(1.0, 60, 40, 0.1, 0.5);
        let on = measure(&raw, DVec3::X, restore(true), cylinder_err);
        let off = measure(&raw, DVec3::X, restore(false), cylinder_err);
        assert!(
            on.mean < 0.008 && off.mean < 0.025,
            "{} {}",
            on.mean,
            off.mean
        );
        assert!(on.max < 0.05 && off.max < 0.05);
        assert!(on.mean <= off.mean);
    }

    /// Saddle z = x^2 - y^2 over [-1, 1]^2, hole of radius 0.45 (70 boundary vertices,
    /// edge length 0.05): mean |z - (x^2 - y^2)| below 0.01 with restoration, 0.02
    /// without (measured 0.0062 and 0.0139), max below 0.08 (measured 0.038, 0.068).
    #[test]
    fn saddle_hole_stays_near_the_saddle() {
        let raw = grid_hole(40, 0.45, |x, y| x * x - y * y);
        let on = measure(&raw, DVec3::ZERO, restore(true), saddle_err);
        let off = measure(&raw, DVec3::ZERO, restore(false), saddle_err);
        assert!(
            on.mean < 0.01 && off.mean < 0.02,
            "{} {}",
            on.mean,
            off.mean
        );
        assert!(on.max < 0.08 && off.max < 0.08);
    }

    /// `placement = "interpolated"` without restoration follows spheres more closely than
    /// the paper's reading (sphere hole of 140: mean |r - 1| below 0.006, measured 0.0032
    /// against 0.020); on the cylinder it stays below 0.008 (measured 0.0057).
    #[test]
    fn interpolated_placement_is_closer_on_curved_holes() {
        let interp = |p: &mut Policy| {
            p.wavefront.placement = WavefrontPlacement::Interpolated;
            p.wavefront.curvature_restoration = false;
        };
        let s = measure(&sphere(5, 0.7), SPHERE_DIR, interp, sphere_err);
        let paper = measure(&sphere(5, 0.7), SPHERE_DIR, restore(true), sphere_err);
        assert!(
            s.mean < 0.006 && s.mean < paper.mean,
            "{} {}",
            s.mean,
            paper.mean
        );
        let c = measure(
            &cylinder_hole(1.0, 60, 40, 0.1, 0.5),
            DVec3::X,
            interp,
            cylinder_err,
        );
        assert!(c.mean < 0.008, "{}", c.mean);
    }

    /// A flat annulus: the loop `loop_pts` (counter-clockwise, star-shaped around the
    /// origin) inside a ring of faces out to radius `outer`; the loop is the hole.
    fn ring_mesh(loop_pts: &[DVec3], outer: f64) -> Option<RawMesh> {
        let k = loop_pts.len();
        let mut raw = RawMesh::default();
        raw.positions.extend_from_slice(loop_pts);
        for p in loop_pts {
            let d = DVec3::new(p.x, p.y, 0.0).normalize();
            raw.positions
                .push(DVec3::new(d.x * outer, d.y * outer, p.z));
        }
        for i in 0..k {
            let j = (i + 1) % k;
            let (vi, vj, ui, uj) = (i as u32, j as u32, (k + i) as u32, (k + j) as u32);
            for f in [[vi, ui, uj], [vi, uj, vj]] {
                let [a, b, c] = f.map(|x| raw.positions[x as usize]);
                if (b - a).cross(c - a).z <= 1e-9 {
                    return None;
                }
                raw.faces.push(f);
            }
        }
        Some(raw)
    }

    fn circle(k: usize, r: f64) -> Vec<DVec3> {
        (0..k)
            .map(|i| {
                let a = TAU * i as f64 / k as f64;
                DVec3::new(r * a.cos(), r * a.sin(), 0.0)
            })
            .collect()
    }

    /// A round hole of 60 vertices has every angle at 174 degrees > mu: the paper's random
    /// draw starts it; it closes flat. With mu small every step is a draw and it still
    /// closes.
    #[test]
    fn round_hole_uses_the_random_draw() {
        let raw = ring_mesh(&circle(60, 1.0), 2.0).unwrap();
        let m = measure(&raw, DVec3::ZERO, |_| {}, |p| p.z);
        assert!(m.stats.random_picks > 0);
        assert!(m.max < 1e-9);
        assert!(m.patch.new_vertices.iter().all(|p| p.length() < 1.0));
        let m = measure(&raw, DVec3::ZERO, |p| p.wavefront.mu = 1.0, |p| p.z);
        assert!(m.stats.random_picks >= m.stats.steps / 2, "{:?}", m.stats);
        assert!(m.max < 1e-9);
    }

    /// Long slots (1.4 long, 0.12 to 0.4 wide, on a 60 x 60 grid of [-1, 1]^2): the fronts
    /// from both long sides meet; some new points merge into front vertices across the
    /// slot and split the front. Every slot closes flat.
    #[test]
    fn slot_holes_merge_and_split_the_front() {
        let mut merges = 0;
        for h in [0.06, 0.08, 0.1, 0.15, 0.2] {
            let mut raw = grid_hole(60, 0.0, |_, _| 0.0);
            raw.faces.retain(|f| {
                let c = f.iter().map(|&v| raw.positions[v as usize]).sum::<DVec3>() / 3.0;
                !(c.x.abs() < 0.7 && c.y.abs() < h)
            });
            let m = measure(&raw, DVec3::ZERO, |_| {}, |p| p.z);
            assert!(m.k > 80, "{}", m.k);
            assert!(m.max < 1e-9);
            merges += m.stats.merges;
        }
        assert!(merges > 0);
    }

    /// Same input and policy: the same patch, bit for bit; another seed also closes.
    #[test]
    fn same_seed_same_patch_bits() {
        let raw = ring_mesh(&circle(48, 1.0), 2.0).unwrap();
        let bits = |seed: u64| {
            let m = measure(&raw, DVec3::ZERO, move |p| p.seed = seed, |p| p.z);
            let v: Vec<[u64; 3]> = m
                .patch
                .new_vertices
                .iter()
                .map(|p| p.to_array().map(f64::to_bits))
                .collect();
            (v, m.patch.triangles, m.stats)
        };
        let a = bits(7);
        assert!(a.2.random_picks > 0);
        assert_eq!(a, bits(7));
        let _ = bits(8);
        let raw = sphere(4, 0.9);
        let run = || measure(&raw, SPHERE_DIR, |_| {}, sphere_err).patch;
        let (p, q) = (run(), run());
        assert_eq!(p.triangles, q.triangles);
        assert!(p
            .new_vertices
            .iter()
            .zip(&q.new_vertices)
            .all(|(a, b)| a.to_array().map(f64::to_bits) == b.to_array().map(f64::to_bits)));
    }

    /// Gaussian noise (sigma = 1 % of the radius, about 0.13 edge lengths; seeded) on
    /// every vertex within 0.3 rad of a large hole of a unit sphere (82 boundary
    /// vertices, the hole spans 1.8 rad of arc): the hole still closes for three noise
    /// seeds. The paper's reading stays within mean |r - 1| < 0.08 and max < 0.3
    /// (measured 0.033 to 0.048, max 0.12 to 0.18: the noisy normals tilt the rotated
    /// triangles); `placement = "interpolated"` without restoration within mean < 0.025,
    /// max < 0.08 (measured 0.008 to 0.015, max 0.03 to 0.043).
    #[test]
    fn noisy_sphere_still_closes() {
        for seed in [1u64, 2, 3] {
            let mut raw = sphere(4, 0.9);
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let dir = SPHERE_DIR.normalize();
            let mut gauss = move || {
                let u1: f64 = rand::Rng::random_range(&mut rng, 1e-12..1.0);
                let u2: f64 = rand::Rng::random_range(&mut rng, 0.0..1.0);
                (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
            };
            for p in raw.positions.iter_mut() {
                if p.normalize().dot(dir) > (0.9f64 + 0.3).cos() {
                    *p += DVec3::new(gauss(), gauss(), gauss()) * 0.01;
                }
            }
            let m = measure(&raw, SPHERE_DIR, |_| {}, sphere_err);
            assert!(
                m.mean < 0.08 && m.max < 0.3,
                "seed {seed}: {} {}",
                m.mean,
                m.max
            );
            let interp = |p: &mut Policy| {
                p.wavefront.placement = WavefrontPlacement::Interpolated;
                p.wavefront.curvature_restoration = false;
            };
            let m = measure(&raw, SPHERE_DIR, interp, sphere_err);
            assert!(
                m.mean < 0.025 && m.max < 0.08,
                "seed {seed}: {} {}",
                m.mean,
                m.max
            );
        }
    }

    /// The bunny scan's hole 2 (42 boundary vertices, in a fold of the ear's base):
    /// the thin-plate fairing of its residual front bulged the residual through the
    /// front's own triangles, so its patch passed the checks only after a
    /// re-triangulation repair. Now the residual is kept unfaired and the patch as made
    /// passes the whole check (intersections with itself and the mesh included), and
    /// its tangential relaxation, which crosses two patch triangles when done over the
    /// whole patch, passes with the vertices at the crossing held in place. The
    /// bunny is bench data that must not be copied into the repository
    /// (`../shared/bench-data/README.md`): the test reads it from there and says so and
    /// passes when it is absent.
    #[test]
    fn bunny_hole_2_residual_is_kept_unfaired_and_relaxed_around_its_fold() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/bench-data/meshes/stanford-bunny.obj");
        if !path.exists() {
            eprintln!("skipped: {} is absent", path.display());
            return;
        }
        let raw = crate::read(&path, None).unwrap();
        let (mesh, _) = Mesh::from_raw(&raw);
        mesh.validate().unwrap();
        let loops = mesh.topo.boundary_loops();
        assert_eq!(loops.len(), 5);
        let policy = Policy::default();
        let hole = Hole::new(2, &mesh, loops[2].clone(), &policy);
        assert_eq!(hole.len(), 42);
        let ctx = FillContext {
            mesh: &mesh,
            hole: &hole,
            policy: &policy,
            deadline: Deadline::none(),
            checker: None,
        };
        let (patch, stats) = fill_with_stats(&ctx).unwrap();
        assert_eq!(stats.residual_fronts, 1, "{stats:?}");
        assert_eq!(stats.unfaired_residuals, 1, "{stats:?}");
        let checker = crate::check::Checker::new(&mesh);
        let made = checker
            .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
            .unwrap();
        accept(&mesh, &hole, &patch, &policy);
        use crate::fill::kit::relax::RELAX_STEP;
        // relaxed as a whole, a vertex slides across a fold of the patch (two patch
        // triangles cross); relaxed with the vertices there held, it passes, with
        // better triangles than as made
        let check = |p: &Patch| checker.check_patch(&mesh, &hole.vertices, p, &policy.checks);
        let mut whole = patch.clone();
        let iterations = policy.fair.tangential_relax;
        crate::fill::kit::relax::tangential_relax(&mesh, &hole, &mut whole, iterations, RELAX_STEP);
        assert!(
            matches!(
                check(&whole),
                Err(crate::check::CheckFailure::SelfIntersection { .. })
            ),
            "{:?}",
            check(&whole)
        );
        let (relaxed, q) = crate::fill::kit::relax::relax_checked(
            &mesh, &hole, &patch, iterations, RELAX_STEP, check,
        )
        .expect("the relaxation with held vertices passes");
        assert!(q.q_good_share > made.q_good_share, "{q:?} vs {made:?}");
        assert!(q.min_angle_deg > made.min_angle_deg, "{q:?} vs {made:?}");
        accept(&mesh, &hole, &relaxed, &policy);
    }

    /// Bad options and loops give a clean error.
    #[test]
    fn bad_options_are_errors() {
        let raw = ring_mesh(&circle(12, 1.0), 2.0).unwrap();
        let (mesh, _) = Mesh::from_raw(&raw);
        let l = loop_near(&mesh, DVec3::ZERO);
        for tweak in [
            (|p: &mut Policy| p.wavefront.alpha = 140.0) as fn(&mut Policy),
            |p| p.wavefront.beta = 190.0,
            |p| p.wavefront.mu = f64::NAN,
            |p| p.wavefront.merge_distance = -1.0,
            |p| p.wavefront.max_steps_per_vertex = 0,
        ] {
            let mut policy = Policy::default();
            tweak(&mut policy);
            let (_, r) = run(&mesh, l.clone(), &policy);
            assert!(matches!(r, Err(FillError::Failed(_))), "{r:?}");
        }
        let policy = Policy::default();
        let (_, r) = run(&mesh, l[..2].to_vec(), &policy);
        assert!(matches!(r, Err(FillError::Failed(_))));
        // a step cap too small to close leaves a residual front, which is closed
        let mut policy = Policy::default();
        policy.wavefront.max_steps_per_vertex = 1;
        let (hole, r) = run(&mesh, l, &policy);
        accept(&mesh, &hole, &r.unwrap(), &policy);
    }

    /// Through the dispatcher: a policy that names only `wavefront` fills the sphere
    /// hole with it.
    #[test]
    fn dispatcher_fills_with_wavefront() {
        let raw = sphere(4, 0.5);
        let mut policy = Policy::default();
        policy.dispatch.small = vec![Method::Wavefront];
        policy.dispatch.middle = vec![Method::Wavefront];
        policy.dispatch.large = vec![Method::Wavefront];
        let (out, report) = crate::repair(&raw, &policy).unwrap();
        assert_eq!(report.holes.len(), 1);
        let h = &report.holes[0];
        assert_eq!(h.method, Some(Method::Wavefront), "{h:?}");
        assert!(out.positions.len() > raw.positions.len());
        let (m, _) = Mesh::from_raw(&out);
        m.validate().unwrap();
        assert!(m.topo.boundary_loops().is_empty());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Random star-shaped planar loops: a valid flat disk or a clean error, never a
        /// panic or a hang.
        #[test]
        fn star_shaped_loops_close_or_fail_cleanly(
            radii in proptest::collection::vec(0.4f64..1.6, 4..60),
            jitter in proptest::collection::vec(-0.4f64..0.4, 60),
            seed in 0u64..1000,
        ) {
            let k = radii.len();
            let pts: Vec<DVec3> = (0..k)
                .map(|i| {
                    let a = TAU * (i as f64 + jitter[i]) / k as f64;
                    DVec3::new(radii[i] * a.cos(), radii[i] * a.sin(), 0.0)
                })
                .collect();
            let Some(raw) = ring_mesh(&pts, 3.0) else { return Ok(()) };
            let (mesh, _) = Mesh::from_raw(&raw);
            prop_assume!(mesh.validate().is_ok());
            let policy = Policy {
                seed,
                ..Policy::default()
            };
            let l = loop_near(&mesh, DVec3::ZERO);
            prop_assume!(l.len() == k);
            let (hole, r) = run(&mesh, l, &policy);
            if let Ok(patch) = r {
                accept(&mesh, &hole, &patch, &policy);
                prop_assert!(patch.new_vertices.iter().all(|p| p.z == 0.0));
            }
        }
    }

    /// 600 random star-shaped loops (4 to 80 vertices, radii 0.4 to 1.6, angular
    /// jitter), flat and with the loop vertices jittered in z by up to 0.02 (a fifth of a
    /// typical edge): at least 99 % close (measured 1999 and 1996 of 2000), and every
    /// patch passes the dispatcher's topology and degeneracy checks.
    #[test]
    fn random_star_loops_mostly_close() {
        let policy = Policy::default();
        for zamp in [0.0, 0.02] {
            let mut rng = ChaCha8Rng::seed_from_u64(42);
            let (mut ok, mut tried) = (0, 0);
            for _ in 0..600 {
                let k = rand::Rng::random_range(&mut rng, 4..80usize);
                let pts: Vec<DVec3> = (0..k)
                    .map(|i| {
                        let r: f64 = rand::Rng::random_range(&mut rng, 0.4..1.6);
                        let j: f64 = rand::Rng::random_range(&mut rng, -0.4..0.4);
                        let z: f64 = rand::Rng::random_range(&mut rng, -1.0..1.0) * zamp;
                        let a = TAU * (i as f64 + j) / k as f64;
                        DVec3::new(r * a.cos(), r * a.sin(), z)
                    })
                    .collect();
                let Some(raw) = ring_mesh(&pts, 3.0) else {
                    continue;
                };
                let (mesh, _) = Mesh::from_raw(&raw);
                let l = loop_near(&mesh, DVec3::ZERO);
                if mesh.validate().is_err() || l.len() != k {
                    continue;
                }
                tried += 1;
                let (hole, r) = run(&mesh, l, &policy);
                if let Ok(patch) = r {
                    check_topology(&mesh, &hole.vertices, &patch).unwrap();
                    let pos = patch_positions(&mesh, &hole.vertices, &patch);
                    check_degenerate(&pos, &patch, &policy.checks).unwrap();
                    ok += 1;
                }
            }
            assert!(
                tried > 500 && ok * 100 >= tried * 99,
                "zamp {zamp}: {ok} of {tried}"
            );
        }
    }

    /// Regression (homer hole 3, cheburashka hole 1 of the shared bench: fronts stuck on
    /// a folded loop or out of steps used to fail the method): a front stopped after one
    /// step per boundary vertex is closed as a residual front, and the patch passes every
    /// check of the dispatcher, stays within 0.05 of the unit sphere on average (0.12 at
    /// most) and is the same bit for bit on a second run.
    #[test]
    fn a_stopped_front_is_closed_as_a_residual() {
        let (mesh, _) = Mesh::from_raw(&sphere(4, 0.6));
        let mut policy = Policy::default();
        policy.wavefront.max_steps_per_vertex = 1;
        let l = loop_near(&mesh, SPHERE_DIR.normalize());
        let hole = Hole::new(0, &mesh, l, &policy);
        let ctx = FillContext {
            mesh: &mesh,
            hole: &hole,
            policy: &policy,
            deadline: Deadline::none(),
            checker: None,
        };
        let (patch, stats) = fill_with_stats(&ctx).unwrap();
        assert!(stats.residual_fronts >= 1, "{stats:?}");
        accept(&mesh, &hole, &patch, &policy);
        crate::check::Checker::new(&mesh)
            .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
            .unwrap();
        let (mean, max) = stats_of(&patch, |p| sphere_err(p).abs());
        assert!(mean < 0.05 && max < 0.12, "{mean} {max}");
        let (again, _) = fill_with_stats(&ctx).unwrap();
        assert_eq!(again, patch);
    }

    /// The variants start with the policy itself and never repeat one.
    #[test]
    fn variants_start_with_the_policy() {
        let p = Policy::default();
        let v = variants(&p);
        assert_eq!(v[0].1, p);
        for i in 0..v.len() {
            for j in i + 1..v.len() {
                assert_ne!(v[i].1, v[j].1, "{} {}", v[i].0, v[j].0);
            }
        }
    }

    /// The winding count by ray crossings gives what the summed angles gave (non-zero
    /// winding, or within `near` of an edge) on random simple and self-crossing loops.
    #[test]
    fn crossing_count_agrees_with_summed_angles() {
        use rand::Rng;
        let reference = |poly: &[(f64, f64)], (px, py): (f64, f64), near: f64| {
            let k = poly.len();
            let (mut wind, mut dist) = (0.0f64, f64::INFINITY);
            for i in 0..k {
                let (ax, ay) = (poly[i].0 - px, poly[i].1 - py);
                let (bx, by) = (poly[(i + 1) % k].0 - px, poly[(i + 1) % k].1 - py);
                wind += (ax * by - ay * bx).atan2(ax * bx + ay * by);
                let (ex, ey) = (bx - ax, by - ay);
                let t = (-(ax * ex + ay * ey) / (ex * ex + ey * ey).max(1e-300)).clamp(0.0, 1.0);
                dist = dist.min(((ax + t * ex).powi(2) + (ay + t * ey).powi(2)).sqrt());
            }
            wind.abs() > PI || dist < near
        };
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut inside, mut total) = (0, 0);
        for round in 0..300 {
            let k = rng.random_range(3..40);
            let poly: Vec<(f64, f64)> = (0..k)
                .map(|i| {
                    if round % 3 == 0 {
                        // anywhere: self-crossing loops, winding numbers above one
                        (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                    } else {
                        let a = TAU * (i as f64 + rng.random_range(0.0..0.9)) / k as f64;
                        let r = rng.random_range(0.2..1.0);
                        (r * a.cos(), r * a.sin())
                    }
                })
                .collect();
            for _ in 0..50 {
                let p = (rng.random_range(-1.2..1.2), rng.random_range(-1.2..1.2));
                let want = reference(&poly, p, 0.05);
                assert_eq!(inside_or_near(&poly, p, 0.05), want, "{poly:?} {p:?}");
                inside += want as usize;
                total += 1;
            }
        }
        assert!(
            inside > total / 5 && inside < total * 4 / 5,
            "{inside} of {total}"
        );
    }

    /// A grid query reports each id at most once, every id whose box meets the query
    /// box among them (also boxes beyond the grid's extent, in its border cells), and
    /// exactly the ids whose cell ranges meet the query's.
    #[test]
    fn grid_query_reports_every_overlap_once() {
        use rand::Rng;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = DVec3::new(0.3, -0.2, 1.0).normalize();
        let u = n.any_orthonormal_vector();
        let w = n.cross(u);
        let mut g = Grid::new(0.1, DVec3::new(0.1, 0.2, 0.3), u, w, 3.0);
        let mut boxes = Vec::new();
        let rand_box = |rng: &mut ChaCha8Rng, size: f64| {
            let c = DVec3::new(
                rng.random_range(-4.0..4.0),
                rng.random_range(-4.0..4.0),
                rng.random_range(-4.0..4.0),
            );
            let h = DVec3::new(
                rng.random_range(0.0..size),
                rng.random_range(0.0..size),
                rng.random_range(0.0..size),
            );
            (c - h, c + h)
        };
        for id in 0..400u32 {
            let (lo, hi) = rand_box(&mut rng, if id % 50 == 0 { 6.0 } else { 0.6 });
            if g.insert_box(lo, hi, id) {
                boxes.push((id, lo, hi, g.range(lo, hi)));
            }
        }
        assert!(boxes.len() < 400, "some boxes span too many cells");
        let mut out = Vec::new();
        let mut found = 0;
        for q in 0..300 {
            let (lo, hi) = rand_box(&mut rng, if q % 20 == 0 { 8.0 } else { 1.0 });
            g.query_box(lo, hi, &mut out);
            let r = g.range(lo, hi);
            let mut want: Vec<u32> = boxes
                .iter()
                .filter(|(_, _, _, c)| c[0] <= r[2] && r[0] <= c[2] && c[1] <= r[3] && r[1] <= c[3])
                .map(|b| b.0)
                .collect();
            let mut got = out.clone();
            got.sort_unstable();
            assert!(got.windows(2).all(|w| w[0] != w[1]), "an id twice");
            want.sort_unstable();
            assert_eq!(got, want);
            for (id, blo, bhi, _) in &boxes {
                if !(bhi.cmplt(lo).any() || hi.cmplt(*blo).any()) {
                    assert!(got.binary_search(id).is_ok(), "box {id} meets the query");
                    found += 1;
                }
            }
        }
        assert!(found > 100, "{found}");
    }

    /// A variant with fewer steps per vertex resumed from the copy the policy's run kept
    /// at its cap gives the same patch, bit for bit, as that variant run afresh.
    #[test]
    fn a_resumed_run_equals_a_fresh_one() {
        let (mesh, _) = Mesh::from_raw(&sphere(4, 0.6));
        let policy = Policy::default();
        let hole = Hole::new(0, &mesh, loop_near(&mesh, SPHERE_DIR.normalize()), &policy);
        let k = hole.len();
        assert!(k >= 20, "{k}");
        let ctx = |policy| FillContext {
            mesh: &mesh,
            hole: &hole,
            policy,
            deadline: Deadline::none(),
            checker: None,
        };
        let mut short = policy.clone();
        short.wavefront.max_steps_per_vertex = 1;
        let (full, mut snaps) = run_wave(&ctx(&policy), Start::Fresh(&[k]));
        let full = full.unwrap();
        assert!(
            full.1.steps > k,
            "the policy's run passed the cap: {:?}",
            full.1
        );
        assert_eq!(snaps.len(), 1);
        let (at, w) = snaps.remove(0);
        assert_eq!(at, k);
        let resumed = run_wave(&ctx(&short), Start::Resume(Box::new(w)))
            .0
            .unwrap();
        let fresh = run_wave(&ctx(&short), Start::Fresh(&[])).0.unwrap();
        assert_eq!(resumed.1.residual_fronts, 1);
        assert_eq!(resumed, fresh);
        let bits = |p: &Patch| -> Vec<u64> {
            p.new_vertices
                .iter()
                .flat_map(|v| v.to_array().map(f64::to_bits))
                .collect()
        };
        assert_eq!(bits(&resumed.0), bits(&fresh.0));
        // the same through the method: the policy's run is the full one
        assert_eq!(fill_with_stats(&ctx(&policy)).unwrap(), full);
    }
}
