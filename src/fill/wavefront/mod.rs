//! Improved wavefront with curvature restoration.
//!
//! Paper 004: Huang, Li, Ye, "Improved Hole Repairing Method Based on Wavefront Method"
//! (2022, DOI 10.21203/rs.3.rs-1345779/v1); ALGORITHMS C (docs/references.md).
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
//!   With `edge_plane` the points over-curve (sink below a sphere) and the restoration
//!   rotation lifts them back; with `interpolated` the rotation only flattens (each
//!   triangle is turned to the normal of the front edge it grows from, which lags the
//!   surface), so `interpolated` goes without restoration (the tests measure both).
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
//! * The paper is silent on robustness (its conclusion admits overlaps). Added here:
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
//!     crosses a triangle around the front and the unfaired one does not).
//!   - a front whose patch area passes `max_area_ratio` (2.0) times the loop's vector
//!     area (a lower bound on the area of any surface the loop bounds) has run away: it
//!     climbed into a dome over the hole or folded. The run stops at once and the other
//!     full-front variants are skipped, straight to those that close a residual early;
//!   - the whole run is self-checked ([`retry`]): when its patch fails the dispatcher's
//!     checks, a local repair (edge flips, then re-triangulation of the region around the
//!     failing triangle) is tried, then the same method with the settings of [`variants`]
//!     (the robust `interpolated` placement without restoration, the next seed, a short
//!     front whose residual is closed as above, `alpha = 90`).
//!
//! Cost: a binary heap of front angles with lazy invalidation (only the vertices a step
//! touches are re-measured) and grids of the front vertices and the triangles, so
//! one step costs `O(log n)` plus a local neighbourhood.

// `!(x > bound)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod step;
mod wave;

#[cfg(test)]
mod tests;

use super::kit::front::{edge_key, Entry, FrontQueue, Ring};
use super::kit::{check_patch_size, residual, retry, Cause, FillContext, FillError, TooLarge};
use crate::fasthash::{HashMap, HashSet};
use crate::fill::kit::retry::Passed;
use crate::geometry::grid::Grid;
use crate::geometry::measure;
use crate::geometry::predicates::{ccw2d, overlap2d, overlap2d_ccw, p2, seg_crosses_tri, P2};
use crate::patch::Patch;
use crate::policy::{Policy, Settings, Wavefront, WavefrontPlacement};
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::{FRAC_PI_4, PI, TAU};
use wave::Wave;

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

/// Fills the hole with the improved wavefront (policy section `[wavefront]`): the
/// policy's settings first; when their patch fails the checks, the variants of
/// [`variants`] (see [`retry`]).
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    fill_checked(ctx).map(|(p, _)| p)
}

/// [`fill`], with the quality of the checks the patch passed (see
/// [`crate::fill::dispatch::run_method_checked`]).
pub fn fill_checked(ctx: &FillContext) -> Result<(Patch, Option<Passed>), FillError> {
    // a hole whose patch would pass `limits.max_patch_triangles` is left to the next
    // method at once (the front's cost grows faster than its triangle count: a round
    // hole of 1,000 vertices took 20 s): the loop's projected area over the area of an
    // equilateral triangle at the mean boundary edge length
    let maxk = ctx.policy.wavefront.max_boundary_vertices;
    if maxk > 0 && ctx.hole.len() > maxk {
        return Err(FillError::TooLarge(TooLarge::Loop {
            vertices: ctx.hole.len(),
            max: maxk,
        }));
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
            let mut q: Settings = (**p).clone();
            q.wavefront.max_steps_per_vertex = full;
            (q == **ctx.policy && p.wavefront.max_steps_per_vertex < full).then(|| {
                p.wavefront
                    .max_steps_per_vertex
                    .saturating_mul(ctx.hole.len())
            })
        })
        .collect();
    let caps: Vec<usize> = resumable.iter().flatten().copied().collect();
    let first = std::cell::RefCell::new(FirstRun::default());
    // after two failures at one loop edge, the full-front variants are skipped, not
    // those that close a residual early (see [`retry`])
    let full_front = |at: usize| {
        vars.get(at)
            .is_some_and(|(_, p)| p.wavefront.max_steps_per_vertex >= full)
    };
    retry::first_passing_unless(ctx, &vars, full_front, |at, c| {
        if ran_away.get() && c.policy.wavefront.max_steps_per_vertex >= full {
            return Err(FillError::Failed(Cause::SkippedAfterRunaway));
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
                    (None, Some(Ok(()))) => Err(FillError::Failed(Cause::SameAsPolicy)),
                    (None, None) => run_wave(c, Start::Fresh(&[])).0,
                }
            }
            _ => run_wave(c, Start::Fresh(&[])).0,
        };
        let r = r.map(|(p, _)| p);
        if matches!(r, Err(FillError::Runaway { .. })) {
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
    // every change below keeps the policy valid; one that did not would be left out
    let mut push = |name: &'static str, change: &dyn Fn(&mut Settings)| {
        if let Ok(p) = policy.edit(change) {
            if !out.iter().any(|(_, q)| *q == p) {
                out.push((name, p));
            }
        }
    };
    let plain = |s: &mut Settings| {
        s.wavefront.placement = WavefrontPlacement::Interpolated;
        s.wavefront.curvature_restoration = false;
    };
    let next_seed = |s: &mut Settings| s.seed = s.seed.wrapping_add(1) & (i64::MAX as u64);
    push("interpolated, no restoration", &plain);
    push("next seed", &next_seed);
    push("interpolated, no restoration, next seed", &|s| {
        plain(s);
        next_seed(s);
    });
    // a few rings of wavefront, the rest closed as a residual front (min-area,
    // refined, faired against the rings): for large holes whose fronts climb or fold
    for steps in [4, 2] {
        if policy.wavefront.max_steps_per_vertex > steps {
            push(
                if steps == 4 {
                    "4 steps per vertex, residual closed"
                } else {
                    "2 steps per vertex, residual closed"
                },
                &|s| s.wavefront.max_steps_per_vertex = steps,
            );
        }
    }
    if policy.wavefront.alpha < 90.0 && policy.wavefront.beta > 90.0 {
        push("alpha 90", &|s| s.wavefront.alpha = 90.0);
        push("interpolated, no restoration, alpha 90", &|s| {
            plain(s);
            s.wavefront.alpha = 90.0;
        });
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
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    let len = ctx.hole.mean_edge_length;
    if !(len.is_finite() && len > 0.0) {
        return Err(FillError::bad_loop(format!(
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
