//! Feature-based hole filling: LS-SVM regression of the Laplacian + Poisson solve.
//!
//! Paper 003 (Xu, Li, Tan 2013, "Feature Based Hole Filling Algorithm on Triangular
//! Mesh"); ALGORITHMS E (docs/references.md). Four steps; how each reads the paper:
//!
//! 1. **Initial patch** (§3.2): a plain advancing front with the angle rules of paper 002
//!    §5.3 and none of its corrections. At the front vertex with the smallest angle θ
//!    (measured on the hole side about its normal), θ ≤ 75° closes it with one triangle,
//!    θ ≤ 135° adds one vertex on the bisector, larger θ two on the trisectors. New
//!    vertices lie "on the plane determined by e_i and e_{i+1}" (rotation about the
//!    normal of the two front edges; when the edges are nearly collinear, or their plane
//!    nearly contains the vertex normal, about the vertex normal) at the hole's mean
//!    boundary edge length `L`. Step 4 (merging): a new vertex closer than
//!    `merge_distance · L` to a vertex of the same front loop is replaced by it, and the
//!    loop splits in two (a spoke merging into a neighbour of the vertex is dropped).
//!    The paper is silent on overlap; a step is refused when a new edge crosses a front
//!    edge, a new triangle covers a front vertex or overlaps a patch triangle or a mesh
//!    face around the loop (all tested in the tangent plane of the vertex, within `4L`),
//!    a new edge duplicates a patch edge or an existing mesh edge between loop vertices,
//!    a new triangle has an angle below 2° or faces against the vertex normal or the
//!    *guide normal* (inverse-square-distance mean of the loop's vertex normals, which
//!    does not drift with the front), or a new vertex leaves the ball of 1.2 times the
//!    loop's extent. A refused step tries the plain ear, then the next vertex by angle;
//!    when every vertex is refused, the best ear of the loop's best-fit-plane projection
//!    is clipped (when that projection is a simple polygon). Caps: `k² + 100k + 1000`
//!    steps and `k²/4 + 10k` new vertices (k = loop length; the largest disk with the
//!    loop's perimeter needs about `0.18 k²`).
//!    **Fallback** (not in the paper): when that 3-D front fails, the same front runs on
//!    the loop projected to its best-fit (Newell) plane, or else to the plane normal to
//!    its mean vertex normal (whichever gives a simple polygon), where the tests are
//!    exact, and the new vertices are lifted by a harmonic map (the Poisson system below
//!    with a zero target on the planar geometry).
//!    The patch is then relaxed with [`RELAX_ITERATIONS`] umbrella steps (factor
//!    [`RELAX_FACTOR`]) of the new vertices so that its Laplacians are meaningful.
//! 2. **Training set** (§3.3): the rings `SV_1 … SV_K` (`K = rings`) around the loop;
//!    `SV_0`, the loop, is left out (its one-ring is incomplete), and so is any vertex on
//!    a boundary. Each sample is a vertex position and its cotangent Laplacian read as
//!    the mean-curvature normal of eq. 4, `δ_i = 1/(2 A_i) Σ_j (cot α_ij + cot β_ij)
//!    (v_j − v_i)`, with `A_i` the barycentric area (a third of the incident triangle
//!    areas; more robust than the Voronoi area on obtuse triangles). Each weight is
//!    clamped to `[0, 1e3]`; when a vertex's weights sum to nothing, uniform weights
//!    `2 cot 60°` (their value on a regular mesh) stand in. "Lapacian linear approximate
//!    mean curvature in value and principal curvature in direction" is taken literally:
//!    δ is projected onto the vertex normal, which removes the tangential part the
//!    discrete operator picks up on irregular meshes (it carries no shape, and it
//!    drags vertices sideways in step 4). The area-normalised δ (eq. 4) is used rather
//!    than the normalised-weight δ of eq. 1–2 so that it does not depend on the edge
//!    length. At most [`MAX_SAMPLES`] samples: the rings nearest the hole are kept (the
//!    last ring partly, by distance to the loop's centroid).
//! 3. **LS-SVM** (§2.2, eq. 9–15): one regression per axis `d`, output `δ_d`. The paper
//!    feeds one coordinate `V_id` as the input; here the input is the 3-D vertex position
//!    (one coordinate cannot tell points of a surface apart). RBF kernel
//!    `K(x, y) = exp(−|x − y|² / (2σ²))` with `σ = kernel_width · r`, r the loop's radius
//!    `perimeter / 2π` (a width in edge lengths cannot serve both small and large holes:
//!    inside a large hole every sample is many widths away and the regression falls back
//!    to its bias). Eq. 14 is solved through its Schur complement: `H = Ω + I/γ` is
//!    symmetric positive definite, so one dense Cholesky factorisation (faer) solves
//!    `H η = 1` and `H ν_d = y_d`; `b_d = 1ᵀν_d / 1ᵀη`, `a_d = ν_d − b_d η`, and
//!    `f_d(x) = Σ a_i K(x, x_i) + b_d` (eq. 15).
//! 4. **Poisson** (§2.3, §3.4, eq. 16–19), read as ALGORITHMS E5: "`L x = δ'` with the
//!    cotangent L of the patch, boundary and outer ring fixed". Unknowns: the new
//!    vertices. Rows: `x_i − Σ_j w_ij x_j = −(2 A_i / Σ_j ω_ij) δ'_i` (eq. 2 weights
//!    `w = ω / Σω`, cotangent weights and areas of the current geometry) for every new
//!    vertex *and* every loop vertex, whose one-ring spans the patch and the mesh (the
//!    outer ring, fixed). The system is overdetermined; it is solved "in the least
//!    squares sense" (§3.4) through its normal equations, one sparse LU (faer) for the
//!    three axes. The loop rows make the patch meet the surface smoothly. The target
//!    `δ'` is the prediction at each vertex projected onto its normal, its length capped
//!    at the [`CLAMP_QUANTILE`] quantile of the training lengths (a crease's spikes do
//!    not set the cap). Predict-then-solve runs `iterations` times, recomputing weights,
//!    areas and normals. **Safeguard** (not in the paper): a solution in which two
//!    adjacent triangles fold (dihedral angle above 120°) or a triangle gets an angle
//!    below 1° (or below its smallest angle before the solve) is solved again with the
//!    prediction scaled by [`PREDICTION_SCALES`] (the last, 0, is the least-squares
//!    membrane); if every one folds the previous geometry is kept. A non-finite result
//!    fails.
//!
//! Connectivity is the front's throughout; only the positions of new vertices change.
//!
//! **Self-checked variants** (not in the paper; [`crate::fill::kit::retry`]): when the
//! patch fails the dispatcher's checks, a local repair (edge flips, then re-triangulation
//! of the region around the failing triangle) is tried, then the same pipeline with the
//! other initial patches of [`Start`] (the 3-D front closing a stuck loop as a residual
//! front, [`crate::fill::kit::residual`]; the whole loop as one residual front) and a
//! softer regression (`iterations = 1`, `gamma / 4`). Each start's initial patch (or
//! its failure) is made once for all variants. A 3-D front whose patch passes
//! `max_area_ratio` times the loop's vector area has run away (climbed over the hole or
//! folded: on the bench, fronts that pass the checks reach 1.0 to 2.0 times, the others
//! 5.7 to 9.4 or the vertex cap) and stops at once.

mod front;
mod model;
mod poisson;

#[cfg(test)]
mod tests;

pub use front::{initial_front, initial_front_with};
pub use model::{kernel_sigma, training_set, LssvmModel};
pub use poisson::{solve_poisson, PoissonSolver, Ring};

use super::kit::front::edge_key;
use super::kit::{
    check_patch_size, residual, retry, triangulate, Deadline, FillContext, FillError, TooLarge,
};
use crate::fasthash::HashSet;
use crate::geometry::measure;
use crate::mesh::{Mesh, VertexId};
use crate::patch::{Hole, Patch};
use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use glam::{DQuat, DVec3};
use std::collections::BTreeMap;

/// `x > 0`, false for NaN.
#[inline]
fn positive(x: f64) -> bool {
    x > 0.0
}

/// Umbrella relaxation steps applied to the initial front before training.
pub const RELAX_ITERATIONS: usize = 5;
/// Factor of each umbrella step.
pub const RELAX_FACTOR: f64 = 0.5;
/// Largest training set (the dense LS-SVM system is `(l+1)²`).
pub const MAX_SAMPLES: usize = 1000;
/// Smallest angle of a front triangle, in degrees.
const FRONT_MIN_ANGLE_DEG: f64 = 2.0;
/// Uniform fallback weight: `cot α + cot β` on a regular triangulation.
const UNIFORM_WEIGHT: f64 = 1.154_700_538_379_251_5;

/// Fills the hole: plain front, LS-SVM prediction of the Laplacian, Poisson solve.
/// Self-checked variants (see [`crate::fill::kit::retry`]): first the front as the
/// module doc says (3-D, else planar); when its patch fails the checks, the 3-D front
/// that closes a stuck loop as a residual front; then both with `iterations = 1` and
/// the prediction halved (`gamma` / 4, a smoother regression).
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    fill_checked(ctx).map(|(p, _)| p)
}

/// [`fill`], with the quality of the checks the patch passed (see
/// [`crate::fill::dispatch::run_method_checked`]).
pub fn fill_checked(
    ctx: &FillContext,
) -> Result<(Patch, Option<crate::fill::kit::retry::Passed>), FillError> {
    check_patch_size(ctx)?;
    let p = ctx.policy.clone();
    // a valid policy stays valid (gamma / 4 stays positive)
    let soft = p
        .edit(|s| {
            s.lssvm.iterations = 1;
            s.lssvm.gamma = (s.lssvm.gamma / 4.0).max(1e-6);
        })
        .unwrap_or_else(|_| p.clone());
    let variants = [
        ("policy", p.clone()),
        ("residual front", p),
        ("one iteration, gamma / 4", soft.clone()),
        ("residual front, one iteration, gamma / 4", soft),
        ("minimum-area initial patch", ctx.policy.clone()),
    ];
    // the initial patch depends on the start only (not on gamma or iterations): each
    // is made once, its failure too (a front that ran away 5 s into a 220-vertex
    // hole, run twice, left no time for the minimum-area start)
    let made: std::cell::RefCell<Vec<(Start, Result<Patch, FillError>)>> = Default::default();
    // only the softer regressions (2, 3) are the same construction under other
    // settings; the other starts are still run after two failures at one loop edge
    retry::first_passing_unless(
        ctx,
        &variants,
        |at| (2..=3).contains(&at),
        |at, c| {
            let start = match at {
                4 => Start::MinArea,
                1 | 3 => Start::ResidualFront,
                _ => Start::Front,
            };
            let known = made
                .borrow()
                .iter()
                .find(|(s, _)| *s == start)
                .map(|(_, r)| r.clone());
            let initial = match known {
                Some(r) => r,
                None => {
                    let r = initial_patch(c, start);
                    if !matches!(r, Err(FillError::Timeout)) {
                        made.borrow_mut().push((start, r.clone()));
                    }
                    r
                }
            };
            fill_from(c, initial?)
        },
    )
}

/// The initial patch of [`fill_with`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Start {
    /// The plain front of paper 003 §3.2 (3-D, else in the loop's plane).
    Front,
    /// The 3-D front; a stuck loop is closed as a residual front.
    ResidualFront,
    /// Not the paper's: the whole loop closed as one residual front (minimum-area
    /// triangulation, refined, faired), for loops where the front makes an overlap.
    MinArea,
}

/// The initial patch closing the whole loop as a residual front.
fn min_area_start(ctx: &FillContext) -> Result<Patch, FillError> {
    let pts = ctx.boundary_positions();
    let forbidden = triangulate::forbidden_chords(ctx.mesh, &ctx.hole.vertices);
    let outside = triangulate::outside_normals(ctx.mesh, &ctx.hole.vertices);
    let mut faces = HashSet::default();
    for &v in &ctx.hole.vertices {
        faces.extend(ctx.mesh.topo.vertex_faces(v));
    }
    let mut faces: Vec<_> = faces.into_iter().collect();
    faces.sort_unstable();
    let context: Vec<[DVec3; 3]> = faces.into_iter().map(|f| ctx.mesh.tri(f)).collect();
    let input = residual::Residual {
        ring: &pts,
        forbidden: &forbidden,
        outside_normals: &outside,
        context: &context,
        edge_length: ctx.hole.mean_edge_length,
    };
    let (new_vertices, triangles) = residual::close(&input, ctx.policy, &ctx.deadline)?;
    Ok(Patch {
        new_vertices,
        triangles,
    })
}

/// [`fill`] with the given initial patch.
pub fn fill_with(ctx: &FillContext, start: Start) -> Result<Patch, FillError> {
    fill_from(ctx, initial_patch(ctx, start)?)
}

/// The initial patch of step 1 made from `start`.
fn initial_patch(ctx: &FillContext, start: Start) -> Result<Patch, FillError> {
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    let l = ctx.hole.mean_edge_length;
    if !(l.is_finite() && l > 0.0) {
        return Err(FillError::bad_loop("the loop has no length"));
    }
    match start {
        Start::MinArea => min_area_start(ctx),
        _ => initial_front_with(
            ctx.mesh,
            &ctx.hole.vertices,
            l,
            ctx.policy.lssvm.merge_distance,
            ctx.policy.lssvm.max_area_ratio,
            &ctx.deadline,
            start == Start::ResidualFront,
        ),
    }
}

/// Steps 2-4 on the initial patch `patch` (from [`initial_patch`]).
fn fill_from(ctx: &FillContext, mut patch: Patch) -> Result<Patch, FillError> {
    let opts = &ctx.policy.lssvm;
    let k = ctx.hole.len();
    let l = ctx.hole.mean_edge_length;
    if patch.new_vertices.is_empty() {
        return Ok(patch);
    }
    let boundary = ctx.boundary_positions();
    relax(&boundary, &mut patch, RELAX_ITERATIONS, RELAX_FACTOR);
    ctx.deadline.check()?;
    let (xs, ys) = training_set(ctx.mesh, &ctx.hole.vertices, opts.rings);
    if xs.len() < 4 {
        return Err(FillError::bad_loop(format!(
            "only {} training vertices around the hole",
            xs.len()
        )));
    }
    let sigma = kernel_sigma(opts, ctx.hole);
    let model = LssvmModel::fit(&xs, &ys, opts.gamma, sigma)?;
    let dmax = clamp_length(&ys);
    let ring = Ring::new(ctx.mesh, &ctx.hole.vertices);
    let boundary_normals: Vec<DVec3> = ctx
        .hole
        .vertices
        .iter()
        .map(|&v| ctx.mesh.vertex_normal(v))
        .collect();
    ctx.deadline.check()?;
    for _ in 0..opts.iterations {
        let pos: Vec<DVec3> = boundary
            .iter()
            .chain(patch.new_vertices.iter())
            .copied()
            .collect();
        let normals = vertex_normals(&pos, k, &patch.triangles);
        let target: Vec<DVec3> = patch
            .new_vertices
            .iter()
            .zip(&normals)
            .chain(boundary.iter().zip(&boundary_normals))
            .map(|(&x, &n)| (n * model.predict(x).dot(n)).clamp_length_max(dmax))
            .collect();
        ctx.deadline.check()?;
        let solver = PoissonSolver::new(&pos, k, &patch.triangles, l, Some(&ring))?;
        let mut accepted = None;
        for scale in PREDICTION_SCALES {
            let t: Vec<DVec3> = target.iter().map(|d| *d * scale).collect();
            let x = solver.solve(&boundary, &t)?;
            if is_sound(&boundary, &patch.new_vertices, &x, &patch.triangles) {
                accepted = Some(x);
                break;
            }
            tracing::debug!(
                hole = ctx.hole.id,
                scale,
                "lssvm_poisson: solution folds, damping the prediction"
            );
        }
        match accepted {
            Some(x) => patch.new_vertices = x,
            None => break,
        }
        ctx.deadline.check()?;
    }
    Ok(patch)
}

/// Area-weighted normals of the new vertices of a patch (`pos`: loop first, `k` of them).
fn vertex_normals(pos: &[DVec3], k: usize, triangles: &[[u32; 3]]) -> Vec<DVec3> {
    let mut acc = vec![DVec3::ZERO; pos.len().saturating_sub(k)];
    for t in triangles {
        let [a, b, c] = t.map(|i| pos[i as usize]);
        let n = measure::tri_normal_raw(a, b, c);
        for &i in t {
            if i as usize >= k {
                acc[i as usize - k] += n;
            }
        }
    }
    acc.into_iter().map(|n| n.normalize_or_zero()).collect()
}

/// The largest length allowed for a predicted Laplacian: the [`CLAMP_QUANTILE`] quantile
/// of the training Laplacians' lengths (spikes on creases do not set the bound).
fn clamp_length(ys: &[DVec3]) -> f64 {
    let mut len: Vec<f64> = ys.iter().map(|d| d.length()).collect();
    len.sort_by(f64::total_cmp);
    if len.is_empty() {
        return 0.0;
    }
    let i = ((len.len() - 1) as f64 * CLAMP_QUANTILE).round() as usize;
    len[i.min(len.len() - 1)]
}

/// See [`clamp_length`].
pub const CLAMP_QUANTILE: f64 = 0.9;

/// Factors applied to the predicted Laplacian when a Poisson solution folds (the last,
/// 0, is the membrane); when every one folds the previous geometry is kept.
pub const PREDICTION_SCALES: [f64; 4] = [1.0, 0.5, 0.25, 0.0];
/// Smallest angle of a solved patch triangle, in degrees.
const SOUND_MIN_ANGLE_DEG: f64 = 1.0;

/// A solved patch is sound when no two adjacent triangles fold onto each other (unit
/// normals with a dot product below [`FOLD_DOT`]) and no triangle has an angle below
/// [`SOUND_MIN_ANGLE_DEG`] (or below its smallest angle in `old`, the geometry it was
/// solved on, when that was smaller already).
fn is_sound(boundary: &[DVec3], old: &[DVec3], new: &[DVec3], triangles: &[[u32; 3]]) -> bool {
    let k = boundary.len();
    let at = |v: &[DVec3], i: u32| {
        let i = i as usize;
        if i < k {
            boundary[i]
        } else {
            v[i - k]
        }
    };
    let min = SOUND_MIN_ANGLE_DEG.to_radians();
    let mut normals = Vec::with_capacity(triangles.len());
    for t in triangles {
        let [a, b, c] = t.map(|i| at(new, i));
        let [a0, b0, c0] = t.map(|i| at(old, i));
        let min0 = measure::angles(a0, b0, c0)
            .into_iter()
            .fold(f64::INFINITY, f64::min);
        let floor = min.min(min0);
        if !measure::angles(a, b, c).iter().all(|&x| x >= floor) {
            return false;
        }
        normals.push(measure::tri_normal_raw(a, b, c).normalize_or_zero());
    }
    let mut by_edge: crate::fasthash::HashMap<(u32, u32), usize> =
        crate::fasthash::HashMap::default();
    for (ti, t) in triangles.iter().enumerate() {
        for c in 0..3 {
            let key = edge_key(t[c], t[(c + 1) % 3]);
            if let Some(&other) = by_edge.get(&key) {
                if normals[ti].dot(normals[other]) < FOLD_DOT {
                    return false;
                }
            } else {
                by_edge.insert(key, ti);
            }
        }
    }
    true
}

/// Adjacent patch triangles whose unit normals have a smaller dot product (a dihedral
/// angle above 120°) count as a fold.
const FOLD_DOT: f64 = -0.5;

/// Umbrella relaxation of the new vertices (loop vertices fixed).
fn relax(boundary: &[DVec3], patch: &mut Patch, iterations: usize, factor: f64) {
    let k = boundary.len();
    let n = patch.new_vertices.len();
    let mut nb: Vec<Vec<u32>> = vec![Vec::new(); n];
    for t in &patch.triangles {
        for c in 0..3 {
            let v = t[c] as usize;
            if v >= k {
                for d in [t[(c + 1) % 3], t[(c + 2) % 3]] {
                    if !nb[v - k].contains(&d) {
                        nb[v - k].push(d);
                    }
                }
            }
        }
    }
    for _ in 0..iterations {
        let cur = patch.new_vertices.clone();
        let at = |i: u32| -> DVec3 {
            let i = i as usize;
            if i < k {
                boundary[i]
            } else {
                cur[i - k]
            }
        };
        for (i, list) in nb.iter().enumerate() {
            if list.is_empty() {
                continue;
            }
            let mean = list.iter().map(|&j| at(j)).sum::<DVec3>() / list.len() as f64;
            patch.new_vertices[i] = cur[i] + factor * (mean - cur[i]);
        }
    }
}

// ---------------------------------------------------------------------------
// 2. training set
