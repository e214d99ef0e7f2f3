//! Improved advancing front for large holes.
//!
//! Paper 002 (Feng et al. 2020), §5.3 and Algorithm 3, with the closing rules of
//! ALGORITHMS B3 step 5 (docs/references.md) (the paper is silent on them).
//!
//! The front starts as the hole loop. While a front has more than four vertices, the
//! front vertex with the smallest angle `θ` is processed: `θ <= angle_small` closes it
//! with one triangle `(v_{i-1}, v_i, v_{i+1})`; `θ <= angle_large` adds one new vertex on
//! the bisector (two triangles); otherwise two new vertices on the trisectors (three
//! triangles). A front of three vertices becomes one triangle, a front of four gets the
//! better of its two diagonals (largest smallest `Qt`).
//!
//! How this module reads the paper where it is vague:
//! - **Angle.** `θ_i` is measured on the hole side (the front runs so that the hole is
//!   on its left seen from the surface normal), between the projections of the two
//!   front edges onto the plane normal to the corrected normal `n_c`, in `[0, 2π)`.
//! - **Normals.** `n_i` of an original loop vertex is the mesh's area-weighted vertex
//!   normal (the patch does not change it); of a new vertex, the area-weighted normal
//!   of the patch triangles around it so far.
//! - **Normal correction (eq. 7).** `e_l`, `e_r` sum the vectors from `v_i` to its
//!   `w = round(c/10)` (at least 1) front neighbours on each side, where `c` is the
//!   size of the *current* front (so `w` shrinks as the front closes and never wraps
//!   around it). The paper's normalisation by the summed lengths scales `e_l`, `e_r` by
//!   positive factors and does not change `n_e = e_l × e_r / |e_l × e_r|`, so it is
//!   skipped. `n_e` is oriented to agree with `n_i` ("like the surface"), then
//!   `n_c = normalize(α n_i + (1-α) n_e)`.
//! - **Curvature (eq. 8).** `κ` is the mean of the Taubin estimates `2 n·e/|e|²` at
//!   `v_{i-1}` and `v_{i+1}` along their front edges towards `v_i`, each with its own
//!   (uncorrected) normal. On a sphere of radius `R` with outward normals this is
//!   `-1/R`.
//! - **Placement (eqs. 9–10).** The new edge has length `l` = mean of the two front
//!   edge lengths at `v_i` (averaged with the size field, below) and lies in the plane spanned by `n_c` and the tangent
//!   direction `t` (the bisector or trisector of `θ` in the tangent plane of `n_c`); its
//!   angle `φ` to `n_c` is `cos φ = clamp(ω1 κ l/2 + ω2 s, -1, 1)`, where `s` is the
//!   mean cosine between `n_c` and the two unit front edges (the slope of the front
//!   against `n_c`; the paper's `n_cᵀ e'/|e'|²` term read as a dimensionless cosine). On
//!   a sphere both terms equal `-l/(2R)`, which puts the new vertex on the sphere when
//!   `n_c = n_i`. The new vertex is `v_o = v_i + l (cos φ n_c + sin φ t)` (the paper's
//!   `v_o = e - v_i` is a typo). Because `n_c` leans towards the hole's axis, new
//!   vertices are placed below the tangent continuation of a convex surface: the raw
//!   front flattens large curved holes (measured on a unit sphere: the largest radial
//!   error is 0.66 of the flat cap's sag for a 58-vertex hole, 0.95 for a 204-vertex
//!   one). That is the paper's design (converge fast); the fairing restores shape.
//! - **Priority.** A binary heap keyed by `θ`, with lazy deletion. After a step only
//!   the front vertices whose neighbours or normal changed are re-keyed; the wider
//!   window of `n_e` makes other keys slightly stale, so a popped vertex is
//!   re-evaluated and pushed back if its fresh angle is no longer the smallest.
//!
//! Closing rules (B3 step 5):
//! - **Merging.** A new vertex that lands within `merge_distance · l` of another
//!   vertex of the same front (not `v_{i-1}`, `v_i`, `v_{i+1}`) is replaced by it; the
//!   front then splits in two (the merged vertex appears in both). All fronts share
//!   one heap; a front of two vertices is closed, of three gets its last triangle.
//! - **Validity.** A step is taken only if none of its triangles overlaps the patch
//!   so far or the mesh near the hole (exact tri–tri tests on slightly shrunk
//!   triangles, see the `intersect` submodule), none creates an edge that already exists (in the
//!   patch, or a mesh edge between two loop vertices), none has an angle below
//!   `max(checks.min_angle_deg, 2°)`, none faces away from `n_c`, and none folds
//!   back over the triangle behind the front edge it closes (> 120°). Otherwise the
//!   fallbacks are tried (ear, bisector, bisector merged into the nearest front
//!   vertex); if none is valid the vertex is set aside until its neighbourhood changes.
//!   When every front vertex is set aside, a front of at most 8 vertices is closed
//!   around a new vertex at its centroid (if those triangles pass the same checks);
//!   otherwise it is closed as a residual front (not in the paper, as the wavefront
//!   does: [`crate::fill::kit::residual`], a minimum-weight triangulation of the front
//!   loop in 3-D, refined and faired), and the method fails only when that fails. A
//!   front of four vertices with no valid diagonal tries the same centre vertex.
//! - **Bounded.** At most `max_steps_per_vertex · k` steps (a step is one processed
//!   front vertex, taken or set aside), the deadline is checked every step, and a
//!   front that grows past `4k + 64` vertices is declared divergent (it spreads away
//!   from the hole instead of closing, as on a sphere with more than a hemisphere
//!   missing); a divergent front, and one out of steps, are closed as residual fronts
//!   (measured: forced alone on hole seeds 11 and 12 of the bench's nine meshes, 11
//!   of 18 runs left a hole open, stuck or divergent). Note that the steps a hole needs grow with its area: a round planar
//!   hole needs about `k²/8` steps, so the default 200 steps per vertex limits round
//!   holes to about 1,600 boundary vertices. Before any step, the patch size is
//!   estimated from the loop's projected (vector) area over `0.25 l²` (`l` the loop's
//!   mean incident mesh edge length; measured on slots and caps); past
//!   `limits.max_patch_triangles` the method gives up at once, and it also gives up
//!   as soon as its patch passes that limit (not in the paper; it keeps a round hole of
//!   thousands of vertices from spending its whole time limit before failing over).
//!
//! After closing: an angle-improving edge-swap pass (max-min angle, never onto an
//! existing edge, never folding a pair), then with `front.fair` the new vertices are
//! relaxed (a few umbrella-smoothing iterations, the loop fixed, which evens out the
//! triangles), then faired by `fill::kit::fair::fair_patch` (the `[fair]` policy: the
//! bi-Laplacian by default), which restores the curvature the raw front flattens,
//! and the swap pass runs again.
//! The whole patch is verified against itself and the mesh at the end; a faired
//! patch that fails is replaced by the unfaired one.
//!
//! Size field (a reading): the step length `l` is the mean of the two front edges
//! (the paper) averaged with a size carried by the vertices (loop vertex: mean
//! length of its mesh edges; new vertex: mean of the three front vertices it grew
//! from). With the paper's length alone the front shrinks step after step (a 90°
//! bisector step makes front edges 0.77 `l` long) and a round hole got six times
//! too many vertices.

mod builder;
mod improve;
mod intersect;
mod step;
#[cfg(test)]
mod tests;

use super::kit::front::{edge_key, Entry, FrontQueue, Ring};
use super::kit::{fair, residual, retry, FillContext, FillError, TooLarge};
use crate::fasthash::FxSet;
use crate::fasthash::HashMap;
use crate::fill::kit::retry::Passed;
use crate::geometry::grid::Grid;
use crate::geometry::measure;
use crate::mesh::VertexId;
use crate::patch::Patch;
use crate::policy::Policy;
use builder::Builder;
use glam::DVec3;
use intersect::Obstacles;
use std::f64::consts::PI;

/// Smallest angle (degrees) a step may create (at least the checks' minimum).
const STEP_MIN_ANGLE_DEG: f64 = 2.0;
/// A step must not fold over the triangle behind a front edge by more than this
/// (cosine of the angle between their normals).
const FOLD_COS: f64 = -0.5;
/// Key offset of a vertex set aside (larger than any angle).
const BLOCKED: f64 = 10.0;
/// The front has diverged when it holds more than this many times the loop's
/// vertices (plus 64): it is spreading away instead of closing.
const DIVERGE_FACTOR: usize = 4;
/// A front of at most this many vertices on which every step failed is closed
/// around a centre vertex when that is valid.
const FAN_MAX: usize = 8;
/// Umbrella relaxation: iterations and step.
const RELAX_ITERATIONS: usize = 8;
const RELAX_LAMBDA: f64 = 0.5;
/// Relaxation never creates an angle below this (degrees) unless it was smaller already.
const RELAX_MIN_ANGLE_DEG: f64 = 0.5;
/// Edge swaps: at most this many per patch triangle.
const SWAPS_PER_TRIANGLE: usize = 10;

/// Fills the hole as [`fill`] does, self-checked ([`retry`], as the other methods): a
/// patch that fails the dispatcher's checks is repaired locally, then made again by
/// the variants of [`variants`].
pub fn fill_checked(ctx: &FillContext) -> Result<(Patch, Option<Passed>), FillError> {
    retry::first_passing_at(ctx, &variants(ctx.policy), |_, c| fill(c))
}

/// The policy, then one step per loop vertex (`front.max_steps_per_vertex = 1`): a
/// row of the front along the rim, the rest closed as one residual front. A front
/// that diverges leaves a patch spread around the hole, which its residual closing
/// then crosses (measured on hole seeds 11 and 12 of the bench: 7 holes of 6 meshes);
/// the short front stops before it spreads.
pub fn variants(policy: &Policy) -> Vec<(&'static str, Policy)> {
    let mut out = vec![("policy", policy.clone())];
    if policy.front.max_steps_per_vertex > 1 {
        if let Ok(p) = policy.edit(|s| s.front.max_steps_per_vertex = 1) {
            out.push(("one step per loop vertex, then the residual", p));
        }
    }
    out
}

/// Fills the hole with the improved advancing front.
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    let params = Params::from_policy(ctx);
    let t0 = std::time::Instant::now();
    let cap = ctx.policy.limits.max_patch_triangles;
    if cap > 0 {
        // give up at once on a hole whose patch would pass the cap (a round hole of
        // thousands of vertices): the front would take minutes and fail anyway
        let est = estimated_triangles(ctx);
        if est > cap as f64 {
            return Err(FillError::TooLarge(TooLarge::Estimated {
                estimated: est,
                cap,
            }));
        }
    }
    let mut b = Builder::new(ctx, params)?;
    let t1 = std::time::Instant::now();
    b.run()?;
    let t2 = std::time::Instant::now();
    let steps = b.steps;
    let residual_fronts = b.residual_fronts;
    let patch = b.finish()?;
    tracing::debug!(
        hole = ctx.hole.id,
        k,
        steps,
        residual_fronts,
        new_vertices = patch.new_vertices.len(),
        triangles = patch.triangles.len(),
        setup_ms = (t1 - t0).as_secs_f64() * 1e3,
        front_ms = (t2 - t1).as_secs_f64() * 1e3,
        finish_ms = t2.elapsed().as_secs_f64() * 1e3,
        "advancing front closed"
    );
    Ok(patch)
}

/// Mean area of a front triangle in units of the squared mean incident edge length of
/// the loop (measured on a 10,008-vertex cylinder slot: 0.26, on a 217-vertex sphere
/// cap: 0.25; the front's steps are shorter than the size field).
const AREA_PER_TRIANGLE: f64 = 0.25;

/// The number of triangles the front would make: the loop's projected area
/// ([`measure::vector_area`], a lower bound of the patch's area) over the area of a
/// front triangle at the loop's mean incident edge length.
fn estimated_triangles(ctx: &FillContext) -> f64 {
    let pts = ctx.boundary_positions();
    let area = measure::vector_area(&pts);
    let (mut sum, mut n) = (0.0, 0usize);
    for &v in &ctx.hole.vertices {
        let m = ctx.mesh.mean_incident_edge_length(v);
        if m > 0.0 && m.is_finite() {
            sum += m;
            n += 1;
        }
    }
    let s = if n > 0 {
        sum / n as f64
    } else {
        ctx.hole.mean_edge_length
    };
    if !(s > 0.0 && area.is_finite()) {
        return 0.0;
    }
    area / (AREA_PER_TRIANGLE * s * s)
}

/// Validated parameters (angles in radians).
#[derive(Clone, Copy, Debug)]
struct Params {
    angle_small: f64,
    angle_large: f64,
    alpha: f64,
    omega1: f64,
    merge: f64,
    min_angle: f64,
    max_steps: usize,
    fair: bool,
}

impl Params {
    fn from_policy(ctx: &FillContext) -> Params {
        let f = &ctx.policy.front;
        // no triangle has a smallest angle above 60 degrees
        let min_deg = ctx
            .policy
            .checks
            .min_angle_deg
            .clamp(STEP_MIN_ANGLE_DEG, 60.0);
        Params {
            angle_small: f.angle_small.to_radians(),
            angle_large: f.angle_large.to_radians(),
            alpha: f.alpha,
            omega1: f.omega1,
            merge: f.merge_distance,
            min_angle: if min_deg.is_finite() {
                min_deg.to_radians()
            } else {
                STEP_MIN_ANGLE_DEG.to_radians()
            },
            max_steps: f.max_steps_per_vertex.max(1).saturating_mul(ctx.hole.len()),
            fair: f.fair,
        }
    }
}

/// A few iterations of umbrella smoothing of the new vertices, the loop fixed (see
/// [`improve::relax`]), before the fairing solve.
fn relax(
    mesh: &crate::mesh::Mesh,
    hole: &crate::patch::Hole,
    patch: &mut Patch,
    _opts: &crate::policy::Fair,
) -> Result<(), FillError> {
    let k = hole.len();
    let mut pos: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
    pos.extend_from_slice(&patch.new_vertices);
    if patch
        .triangles
        .iter()
        .flatten()
        .any(|&i| i as usize >= pos.len())
    {
        return Err(FillError::internal("patch index out of range"));
    }
    improve::relax(
        &mut pos,
        k,
        &patch.triangles,
        RELAX_ITERATIONS,
        RELAX_LAMBDA,
        RELAX_MIN_ANGLE_DEG.to_radians(),
    );
    patch.new_vertices.copy_from_slice(&pos[k..]);
    Ok(())
}
