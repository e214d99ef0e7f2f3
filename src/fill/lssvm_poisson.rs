//! Feature-based hole filling: LS-SVM regression of the Laplacian + Poisson solve.
//!
//! Paper 003 (Xu, Li, Tan 2013, "Feature Based Hole Filling Algorithm on Triangular
//! Mesh"); ALGORITHMS.md section E. Four steps; how each reads the paper:
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
//! **Self-checked variants** (not in the paper; [`super::wavefront::retry`]): when the
//! patch fails the dispatcher's checks, a local repair (edge flips, then re-triangulation
//! of the region around the failing triangle) is tried, then the same pipeline with the
//! other initial patches of [`Start`] (the 3-D front closing a stuck loop as a residual
//! front, [`super::wavefront::residual`]; the whole loop as one residual front) and a
//! softer regression (`iterations = 1`, `gamma / 4`). On the shared bench (35 holes)
//! this closes every hole; before, homer's folded hole 3 and a bunny hole failed.

use super::kit::{
    check_patch_size, residual, retry, triangulate, Deadline, FillContext, FillError,
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
/// Self-checked variants (see [`super::wavefront::retry`]): first the front as the
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
) -> Result<(Patch, Option<crate::report::PatchQuality>), FillError> {
    check_patch_size(ctx)?;
    let p = ctx.policy.clone();
    let mut soft = p.clone();
    soft.lssvm.iterations = 1;
    soft.lssvm.gamma = (soft.lssvm.gamma / 4.0).max(1e-6);
    let variants = [
        ("policy", p.clone()),
        ("residual front", p),
        ("one iteration, gamma / 4", soft.clone()),
        ("residual front, one iteration, gamma / 4", soft),
        ("minimum-area initial patch", ctx.policy.clone()),
    ];
    retry::first_passing_at(ctx, &variants, |at, c| {
        let start = match at {
            4 => Start::MinArea,
            1 | 3 => Start::ResidualFront,
            _ => Start::Front,
        };
        fill_with(c, start)
    })
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
    let opts = &ctx.policy.lssvm;
    opts.validate()
        .map_err(|e| FillError::Failed(format!("policy {e}")))?;
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::Failed(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    let l = ctx.hole.mean_edge_length;
    if !(l.is_finite() && l > 0.0) {
        return Err(FillError::Failed("the loop has no length".into()));
    }
    let mut patch = match start {
        Start::MinArea => min_area_start(ctx)?,
        _ => initial_front_with(
            ctx.mesh,
            &ctx.hole.vertices,
            l,
            opts.merge_distance,
            &ctx.deadline,
            start == Start::ResidualFront,
        )?,
    };
    if patch.new_vertices.is_empty() {
        return Ok(patch);
    }
    let boundary = ctx.boundary_positions();
    relax(&boundary, &mut patch, RELAX_ITERATIONS, RELAX_FACTOR);
    ctx.deadline.check()?;
    let (xs, ys) = training_set(ctx.mesh, &ctx.hole.vertices, opts.rings);
    if xs.len() < 4 {
        return Err(FillError::Failed(format!(
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
            let key = ukey(t[c], t[(c + 1) % 3]);
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

/// Guide normal field over the hole: inverse-square-distance mean of the loop's vertex
/// normals. It does not depend on the patch, so it cannot drift with it.
struct Guide {
    pts: Vec<DVec3>,
    normals: Vec<DVec3>,
    eps2: f64,
}

impl Guide {
    fn new(mesh: &Mesh, hole: &[VertexId], edge: f64) -> Guide {
        Guide {
            pts: hole.iter().map(|&v| mesh.pos(v)).collect(),
            normals: hole.iter().map(|&v| mesh.vertex_normal(v)).collect(),
            eps2: 1e-3 * edge * edge,
        }
    }

    fn at(&self, x: DVec3) -> DVec3 {
        let mut acc = DVec3::ZERO;
        for (p, n) in self.pts.iter().zip(&self.normals) {
            acc += *n / (x - *p).length_squared().max(self.eps2);
        }
        acc.normalize_or_zero()
    }
}

/// The RBF width: `kernel_width` times the loop's radius `perimeter / 2π`.
pub fn kernel_sigma(opts: &crate::policy::Lssvm, hole: &Hole) -> f64 {
    opts.kernel_width * hole.perimeter / std::f64::consts::TAU
}

// ---------------------------------------------------------------------------
// 1. plain advancing front

/// The plain advancing front of paper 003 §3.2 (see the module doc): a patch closing
/// the loop `hole` with new vertices at distance `edge` from the front.
pub fn initial_front(
    mesh: &Mesh,
    hole: &[VertexId],
    edge: f64,
    merge_distance: f64,
    deadline: &Deadline,
) -> Result<Patch, FillError> {
    initial_front_with(mesh, hole, edge, merge_distance, deadline, false)
}

/// [`initial_front`]; with `residual`, a stuck 3-D front closes its loop as a residual
/// front ([`super::wavefront::residual`]) instead of the planar fallback.
pub fn initial_front_with(
    mesh: &Mesh,
    hole: &[VertexId],
    edge: f64,
    merge_distance: f64,
    deadline: &Deadline,
    residual: bool,
) -> Result<Patch, FillError> {
    let k = hole.len();
    if k < 3 {
        return Err(FillError::Failed(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    if !(edge.is_finite() && edge > 0.0) {
        return Err(FillError::Failed(
            "front edge length is not positive".into(),
        ));
    }
    if residual {
        let mut f = Front::new(mesh, hole, edge, merge_distance, false);
        if let Some(f) = f.as_mut() {
            f.residual = Some(*deadline);
        }
        return run_front(f, k, deadline);
    }
    match run_front(
        Front::new(mesh, hole, edge, merge_distance, false),
        k,
        deadline,
    ) {
        Err(FillError::Failed(why3d)) => {
            // the same front in the loop's best-fit plane, lifted by a harmonic map
            let flat = run_front(
                Front::new(mesh, hole, edge, merge_distance, true),
                k,
                deadline,
            )
            .map_err(|e| match e {
                FillError::Failed(why) => {
                    FillError::Failed(format!("{why3d}; in the plane: {why}"))
                }
                t => t,
            })?;
            let boundary: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
            let normals: Vec<DVec3> = hole.iter().map(|&v| mesh.vertex_normal(v)).collect();
            let pts = project_loop(&boundary, &normals)
                .ok_or_else(|| FillError::Failed(why3d.clone()))?;
            let pos: Vec<DVec3> = pts
                .into_iter()
                .chain(flat.new_vertices.iter().copied())
                .collect();
            let solver = PoissonSolver::new(&pos, k, &flat.triangles, edge, None)?;
            let zero = vec![DVec3::ZERO; flat.new_vertices.len()];
            let new_vertices = solver.solve(&boundary, &zero)?;
            Ok(Patch {
                new_vertices,
                triangles: flat.triangles,
            })
        }
        other => other,
    }
}

/// The loop projected onto a plane in which it is a simple, counter-clockwise polygon,
/// as points with `z = 0`: its best-fit (Newell) plane, else the plane normal to the
/// mean of its vertex normals (`normals`). `None` when neither works.
fn project_loop(pts: &[DVec3], normals: &[DVec3]) -> Option<Vec<DVec3>> {
    let mean = normals.iter().copied().sum::<DVec3>().normalize_or_zero();
    [measure::newell_normal(pts), mean]
        .into_iter()
        .find_map(|n| project_along(pts, n))
}

fn project_along(pts: &[DVec3], n: DVec3) -> Option<Vec<DVec3>> {
    if n == DVec3::ZERO {
        return None;
    }
    let t1 = n.any_orthonormal_vector();
    let t2 = n.cross(t1);
    let q: Vec<(f64, f64)> = pts.iter().map(|p| (p.dot(t1), p.dot(t2))).collect();
    let m = q.len();
    let area2: f64 = (0..m)
        .map(|i| {
            let (a, b) = (q[i], q[(i + 1) % m]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum();
    if !positive(area2) {
        return None;
    }
    for a in 0..m {
        for b in a + 2..m {
            if a == 0 && b == m - 1 {
                continue;
            }
            if segments_cross(q[a], q[(a + 1) % m], q[b], q[(b + 1) % m]) {
                return None;
            }
        }
    }
    Some(q.into_iter().map(|(x, y)| DVec3::new(x, y, 0.0)).collect())
}

/// Runs a front until every loop is closed.
fn run_front(front: Option<Front>, k: usize, deadline: &Deadline) -> Result<Patch, FillError> {
    let mut f = front
        .ok_or_else(|| FillError::Failed("the loop's projection is not a simple polygon".into()))?;
    let cap = k * k + 100 * k + 1000;
    // 1.4 times the vertex count of the largest disk with this perimeter, plus slack
    let vertex_cap = k + k * k / 4 + 10 * k;
    let mut steps = 0usize;
    let mut loops: Vec<Vec<u32>> = vec![(0..k as u32).collect()];
    while let Some(lp) = loops.pop() {
        deadline.check()?;
        steps += 1;
        if steps > cap {
            return Err(FillError::Failed(format!(
                "advancing front did not close in {cap} steps"
            )));
        }
        if lp.len() < 3 {
            continue;
        }
        if lp.len() == 3 {
            f.add_triangles(&[[lp[0], lp[1], lp[2]]]);
            continue;
        }
        if f.pos.len() > vertex_cap {
            return Err(FillError::Failed(format!(
                "advancing front created more than {} vertices",
                vertex_cap - k
            )));
        }
        let mut next = f.step(&lp)?;
        loops.append(&mut next);
    }
    let new_vertices = f.pos[k..].to_vec();
    if new_vertices.iter().any(|p| !p.is_finite()) {
        return Err(FillError::Failed(
            "front produced a non-finite vertex".into(),
        ));
    }
    Ok(Patch {
        new_vertices,
        triangles: f.tris,
    })
}

/// A spoke of a front step: a new point, or an existing loop vertex it merged into.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Spoke {
    New(DVec3),
    Old(u32),
}

struct Front {
    /// Patch vertex positions: loop first, then new.
    pos: Vec<DVec3>,
    /// Accumulated area-weighted normals (mesh faces for loop vertices, plus patch).
    nacc: Vec<DVec3>,
    tris: Vec<[u32; 3]>,
    /// Undirected edges (min, max) of the patch and mesh edges between loop vertices.
    edges: HashSet<(u32, u32)>,
    /// Triangles a new triangle must not overlap: the mesh faces around the loop and
    /// the patch so far (vertex labels: patch indices; other mesh vertices get labels
    /// from `u32::MAX` down, so that they never match).
    obstacles: Vec<Obstacle>,
    /// Centroid and largest distance of the loop's vertices from it: new vertices stay
    /// within `1.2` times that ball.
    centre: DVec3,
    reach: f64,
    edge: f64,
    merge: f64,
    /// Guide normals (see [`Guide`]): a front that starts to turn over is refused.
    guide: Guide,
    /// Front edges and obstacles farther than this from a step's vertex are not tested.
    radius: f64,
    /// Close a stuck loop as a residual front (with this deadline) instead of failing.
    residual: Option<Deadline>,
}

struct Obstacle {
    ids: [u32; 3],
    pts: [DVec3; 3],
    centre: DVec3,
    normal: DVec3,
}

impl Obstacle {
    fn new(ids: [u32; 3], pts: [DVec3; 3]) -> Obstacle {
        Obstacle {
            ids,
            pts,
            centre: (pts[0] + pts[1] + pts[2]) / 3.0,
            normal: measure::tri_normal_raw(pts[0], pts[1], pts[2]).normalize_or_zero(),
        }
    }
}

fn ukey(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

impl Front {
    /// The front of the loop `hole`; with `planar`, of its projection onto its best-fit
    /// plane (`None` when that is not a simple polygon).
    fn new(
        mesh: &Mesh,
        hole: &[VertexId],
        edge: f64,
        merge_distance: f64,
        planar: bool,
    ) -> Option<Front> {
        let k = hole.len();
        let mut pos: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
        let mut nacc: Vec<DVec3> = hole
            .iter()
            .map(|&v| {
                mesh.topo
                    .vertex_faces(v)
                    .map(|f| mesh.face_normal_raw(f))
                    .sum::<DVec3>()
            })
            .collect();
        if planar {
            let normals: Vec<DVec3> = hole.iter().map(|&v| mesh.vertex_normal(v)).collect();
            pos = project_loop(&pos, &normals)?;
            nacc = vec![DVec3::Z; k];
        }
        let mut index = crate::fasthash::HashMap::default();
        for (i, &v) in hole.iter().enumerate() {
            index.insert(v, i as u32);
        }
        let mut edges = HashSet::default();
        for (i, &v) in hole.iter().enumerate() {
            for w in mesh.topo.neighbors(v) {
                if let Some(&j) = index.get(&w) {
                    edges.insert(ukey(i as u32, j));
                }
            }
            edges.insert(ukey(i as u32, ((i + 1) % k) as u32));
        }
        let mut obstacles = Vec::new();
        let mut seen = HashSet::default();
        if planar {
            // the loop is the only obstacle; every front edge is checked
            seen.extend((0..mesh.num_faces()).map(crate::mesh::FaceId::from_idx));
        }
        let mut other: crate::fasthash::HashMap<VertexId, u32> =
            crate::fasthash::HashMap::default();
        for &v in hole {
            for f in mesh.topo.vertex_faces(v) {
                if !seen.insert(f) {
                    continue;
                }
                let t = mesh.topo.face(f);
                let ids = t.map(|w| match index.get(&w) {
                    Some(&i) => i,
                    None => {
                        let next = u32::MAX - other.len() as u32;
                        *other.entry(w).or_insert(next)
                    }
                });
                obstacles.push(Obstacle::new(ids, t.map(|w| mesh.pos(w))));
            }
        }
        let centre = measure::centroid(&pos);
        let reach = 1.2
            * pos
                .iter()
                .map(|p| (*p - centre).length())
                .fold(0.0, f64::max)
            + edge;
        let guide = if planar {
            Guide {
                pts: vec![DVec3::ZERO],
                normals: vec![DVec3::Z],
                eps2: 1.0,
            }
        } else {
            Guide::new(mesh, hole, edge)
        };
        Some(Front {
            pos,
            nacc,
            tris: Vec::new(),
            edges,
            obstacles,
            centre,
            reach,
            guide,
            radius: if planar { f64::INFINITY } else { 4.0 * edge },
            edge,
            merge: merge_distance * edge,
            residual: None,
        })
    }

    /// The normal at patch vertex `i`: its own (area-weighted over the mesh and patch
    /// triangles around it) averaged with the guide normal at its position.
    fn normal(&self, i: u32) -> DVec3 {
        let g = self.guide.at(self.pos[i as usize]);
        (self.nacc[i as usize].normalize_or_zero() + g).normalize_or(g)
    }

    fn add_triangles(&mut self, tris: &[[u32; 3]]) {
        for t in tris {
            let n = measure::tri_normal_raw(
                self.pos[t[0] as usize],
                self.pos[t[1] as usize],
                self.pos[t[2] as usize],
            );
            for c in 0..3 {
                self.nacc[t[c] as usize] += n;
                self.edges.insert(ukey(t[c], t[(c + 1) % 3]));
            }
            self.tris.push(*t);
            self.obstacles
                .push(Obstacle::new(*t, t.map(|i| self.pos[i as usize])));
        }
    }

    /// Angle on the hole side at position `j` of loop `lp`, in `[0, 2π)`, and the axis
    /// that turns the direction to the next vertex into the direction to the previous one
    /// by that angle.
    fn angle(&self, lp: &[u32], j: usize) -> (f64, DVec3, DVec3) {
        let m = lp.len();
        let p = self.pos[lp[j] as usize];
        let u = (self.pos[lp[(j + 1) % m] as usize] - p).normalize_or_zero();
        let w = (self.pos[lp[(j + m - 1) % m] as usize] - p).normalize_or_zero();
        let n = self.normal(lp[j]);
        let c = u.cross(w);
        let mut th = c.dot(n).atan2(u.dot(w));
        if th < 0.0 {
            th += std::f64::consts::TAU;
        }
        // the plane of the two front edges, unless they are nearly collinear or their
        // plane nearly contains the normal: then the tangent plane
        let cl = c.length();
        let ch = if c.dot(n) >= 0.0 { c } else { -c };
        let axis = if cl > 0.5 && ch.dot(n) > 0.5 * cl {
            ch / cl
        } else {
            n
        };
        (th, axis, u)
    }

    /// One front step on loop `lp`; returns the loops that replace it.
    fn step(&mut self, lp: &[u32]) -> Result<Vec<Vec<u32>>, FillError> {
        let m = lp.len();
        let mut order: Vec<(f64, usize, DVec3, DVec3)> = (0..m)
            .map(|j| {
                let (th, axis, u) = self.angle(lp, j);
                (th, j, axis, u)
            })
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let small = 75f64.to_radians();
        let large = 135f64.to_radians();
        for &(th, j, axis, u) in &order {
            let mut tries: Vec<Vec<f64>> = Vec::new();
            if th <= small {
                tries.push(vec![]);
            } else if th <= large {
                tries.push(vec![th / 2.0]);
                tries.push(vec![]);
            } else {
                tries.push(vec![2.0 * th / 3.0, th / 3.0]);
                if th < std::f64::consts::PI {
                    tries.push(vec![]);
                }
            }
            for rots in tries {
                if let Some(out) = self.try_step(lp, j, axis, u, &rots) {
                    return Ok(out);
                }
            }
        }
        // every rule refused: clip the best ear of the loop's projection
        let pts: Vec<DVec3> = lp.iter().map(|&v| self.pos[v as usize]).collect();
        let mean_guide = pts
            .iter()
            .map(|&p| self.guide.at(p))
            .sum::<DVec3>()
            .normalize_or_zero();
        let newell = measure::newell_normal(&pts);
        if let Some(out) = self
            .clip_ear(lp, newell)
            .or_else(|| self.clip_ear(lp, mean_guide))
        {
            return Ok(out);
        }
        // no ear either: close the loop as a residual front (min-area, refined, faired)
        let Some(deadline) = self.residual else {
            return Err(FillError::Failed(format!(
                "advancing front is stuck on a loop of {m} vertices"
            )));
        };
        self.close_residual(lp, &deadline).map_err(|e| {
            FillError::Failed(format!(
                "advancing front is stuck on a loop of {m} vertices and the residual \
                 closing failed: {e}"
            ))
        })?;
        Ok(Vec::new())
    }

    /// Closes loop `lp` with [`residual::close`].
    fn close_residual(&mut self, lp: &[u32], deadline: &Deadline) -> Result<(), FillError> {
        let m = lp.len();
        if lp.iter().collect::<HashSet<_>>().len() != m {
            return Err(FillError::Failed("the loop passes a vertex twice".into()));
        }
        let pts: Vec<DVec3> = lp.iter().map(|&v| self.pos[v as usize]).collect();
        let mut forbidden = HashSet::default();
        for i in 0..m {
            for j in i + 2..m {
                if (i, j) != (0, m - 1) && self.edges.contains(&ukey(lp[i], lp[j])) {
                    forbidden.insert((i as u32, j as u32));
                }
            }
        }
        let on: HashSet<u32> = lp.iter().copied().collect();
        let context: Vec<[DVec3; 3]> = self
            .obstacles
            .iter()
            .filter(|o| o.ids.iter().any(|i| on.contains(i)))
            .map(|o| o.pts)
            .collect();
        let outside = vec![None; m];
        let policy = crate::policy::Policy::default();
        let input = residual::Residual {
            ring: &pts,
            forbidden: &forbidden,
            outside_normals: &outside,
            context: &context,
            edge_length: self.edge,
        };
        let (new_pts, tris) = residual::close(&input, &policy, deadline)?;
        let base = self.pos.len() as u32;
        for p in new_pts {
            self.pos.push(p);
            self.nacc.push(DVec3::ZERO);
        }
        let mapped: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| {
                t.map(|i| {
                    if (i as usize) < m {
                        lp[i as usize]
                    } else {
                        base + i - m as u32
                    }
                })
            })
            .collect();
        self.add_triangles(&mapped);
        Ok(())
    }

    /// Fallback when no front rule applies: project the loop onto the plane normal to
    /// `n` (its best-fit plane, then the mean guide normal) and, when the projection is a
    /// simple polygon, cut off the ear with the largest smallest angle whose new edge is
    /// not an existing edge.
    fn clip_ear(&mut self, lp: &[u32], n: DVec3) -> Option<Vec<Vec<u32>>> {
        let m = lp.len();
        let pts: Vec<DVec3> = lp.iter().map(|&v| self.pos[v as usize]).collect();
        if n == DVec3::ZERO {
            return None;
        }
        let t1 = n.any_orthonormal_vector();
        let t2 = n.cross(t1);
        let q: Vec<(f64, f64)> = pts.iter().map(|p| (p.dot(t1), p.dot(t2))).collect();
        // simple polygon?
        for a in 0..m {
            for b in a + 2..m {
                if a == 0 && b == m - 1 {
                    continue;
                }
                if segments_cross(q[a], q[(a + 1) % m], q[b], q[(b + 1) % m]) {
                    return None;
                }
            }
        }
        let mut best: Option<(f64, usize)> = None;
        for j in 0..m {
            let (i0, i2) = ((j + m - 1) % m, (j + 1) % m);
            // convex corner: the loop runs counter-clockwise about n
            if orient2(q[i0], q[j], q[i2]) <= 0.0 {
                continue;
            }
            if self.edges.contains(&ukey(lp[i0], lp[i2])) {
                continue;
            }
            if (0..m).any(|t| {
                t != i0 && t != j && t != i2 && point_in_triangle(q[t], q[i0], q[j], q[i2])
            }) {
                continue;
            }
            let a = measure::angles(pts[i0], pts[j], pts[i2]);
            let score = a[0].min(a[1]).min(a[2]);
            if best.is_none_or(|(bs, _)| score > bs) {
                best = Some((score, j));
            }
        }
        let (_, j) = best?;
        let (prev, next) = (lp[(j + m - 1) % m], lp[(j + 1) % m]);
        self.add_triangles(&[[prev, lp[j], next]]);
        let mut rest = lp.to_vec();
        rest.remove(j);
        Some(split_loops(rest))
    }

    /// Tries the step at `lp[j]` with spokes at the rotations `rots` of `u` about `axis`
    /// (ordered from the previous vertex's side to the next's).
    fn try_step(
        &mut self,
        lp: &[u32],
        j: usize,
        axis: DVec3,
        u: DVec3,
        rots: &[f64],
    ) -> Option<Vec<Vec<u32>>> {
        let m = lp.len();
        let pi = lp[j];
        let prev = lp[(j + m - 1) % m];
        let next = lp[(j + 1) % m];
        let p = self.pos[pi as usize];
        // tangent direction of u in the rotation plane
        let ut = (u - axis * u.dot(axis)).normalize_or_zero();
        if ut == DVec3::ZERO {
            return None;
        }
        let mut spokes: Vec<Spoke> = Vec::new();
        for &r in rots {
            let d = DQuat::from_axis_angle(axis, r) * ut;
            let q = p + d * self.edge;
            if (q - self.centre).length() > self.reach {
                return None;
            }
            let mut best: Option<(f64, u32)> = None;
            for &v in lp {
                if v == pi {
                    continue;
                }
                let dist = (self.pos[v as usize] - q).length();
                if dist < self.merge && best.is_none_or(|(bd, _)| dist < bd) {
                    best = Some((dist, v));
                }
            }
            let s = match best {
                Some((_, v)) if v == prev || v == next => continue,
                Some((_, v)) => Spoke::Old(v),
                None => Spoke::New(q),
            };
            if spokes.last() != Some(&s) {
                spokes.push(s);
            }
        }
        // provisional indices of new points
        let base = self.pos.len() as u32;
        let mut new_pts: Vec<DVec3> = Vec::new();
        let mut chain: Vec<u32> = vec![prev];
        for s in &spokes {
            match *s {
                Spoke::Old(v) => chain.push(v),
                Spoke::New(q) => {
                    chain.push(base + new_pts.len() as u32);
                    new_pts.push(q);
                }
            }
        }
        chain.push(next);
        let at = |i: u32| -> DVec3 {
            if i >= base {
                new_pts[(i - base) as usize]
            } else {
                self.pos[i as usize]
            }
        };
        let tris: Vec<[u32; 3]> = chain.windows(2).map(|w| [w[0], pi, w[1]]).collect();
        let n = self.normal(pi);
        let is_front_edge =
            |a: u32, b: u32| -> bool { (0..m).any(|t| lp[t] == a && lp[(t + 1) % m] == b) };
        // combinatorial checks
        let mut new_edges: Vec<(u32, u32)> = Vec::new();
        for t in &tris {
            for c in 0..3 {
                let (a, b) = (t[c], t[(c + 1) % 3]);
                if a == b {
                    return None;
                }
                if is_front_edge(a, b) {
                    continue;
                }
                if a < base && b < base && self.edges.contains(&ukey(a, b)) {
                    return None;
                }
                new_edges.push((a, b));
            }
            let [x, y, z] = t.map(at);
            let nt = measure::tri_normal_raw(x, y, z);
            if !positive(nt.dot(n)) || !positive(nt.dot(self.guide.at((x + y + z) / 3.0))) {
                return None;
            }
            let angs = measure::angles(x, y, z);
            if angs
                .iter()
                .any(|&a| a.is_nan() || a < FRONT_MIN_ANGLE_DEG.to_radians())
            {
                return None;
            }
        }
        // geometric checks in the tangent plane at p
        let t1 = n.any_orthonormal_vector();
        let t2 = n.cross(t1);
        let proj = |x: DVec3| -> (f64, f64) {
            let d = x - p;
            (d.dot(t1), d.dot(t2))
        };
        let radius = self.radius;
        let near = |x: DVec3| (x - p).length() <= radius;
        for &(a, b) in &new_edges {
            let (pa, pb) = (at(a), at(b));
            for t in 0..m {
                let (c, d) = (lp[t], lp[(t + 1) % m]);
                if c == a || c == b || d == a || d == b {
                    continue;
                }
                let (pc, pd) = (self.pos[c as usize], self.pos[d as usize]);
                if !near(pc) && !near(pd) {
                    continue;
                }
                if segments_cross(proj(pa), proj(pb), proj(pc), proj(pd)) {
                    return None;
                }
            }
        }
        for t in &tris {
            let [x, y, z] = t.map(at);
            let (px, py, pz) = (proj(x), proj(y), proj(z));
            for &v in lp {
                if t.contains(&v) {
                    continue;
                }
                let pv = self.pos[v as usize];
                if !near(pv) {
                    continue;
                }
                if point_in_triangle(proj(pv), px, py, pz) {
                    return None;
                }
            }
            // a new point must not sit on the far side of the front
            for &q in &new_pts {
                let pq = proj(q);
                for s in 0..m {
                    let (c, d) = (lp[s], lp[(s + 1) % m]);
                    if c == pi || d == pi {
                        continue;
                    }
                    let (pc, pd) = (self.pos[c as usize], self.pos[d as usize]);
                    if !near(pc) && !near(pd) {
                        continue;
                    }
                    if segments_cross((0.0, 0.0), pq, proj(pc), proj(pd)) {
                        return None;
                    }
                }
            }
        }
        // no overlap with the patch so far or the mesh around the loop
        for t in &tris {
            let pts = t.map(at);
            let pq = pts.map(proj);
            for o in &self.obstacles {
                if (o.centre - p).length() > radius || o.normal.dot(n) < 0.2 {
                    continue;
                }
                if overlap2d(t, &pq, &o.ids, &o.pts.map(proj)) {
                    return None;
                }
            }
        }
        // commit
        for q in new_pts {
            self.pos.push(q);
            self.nacc.push(DVec3::ZERO);
        }
        self.add_triangles(&tris);
        let mut seq: Vec<u32> = Vec::with_capacity(m + 2);
        for (t, &v) in lp.iter().enumerate() {
            if t == j {
                seq.extend_from_slice(&chain[1..chain.len() - 1]);
            } else {
                seq.push(v);
            }
        }
        Some(split_loops(seq))
    }
}

/// Splits a cyclic vertex sequence at repeated vertices into simple loops; loops of
/// fewer than three vertices are closed already and dropped.
fn split_loops(seq: Vec<u32>) -> Vec<Vec<u32>> {
    let mut out = Vec::new();
    let mut stack = vec![seq];
    while let Some(s) = stack.pop() {
        let mut found = None;
        'outer: for i in 0..s.len() {
            for j in i + 1..s.len() {
                if s[i] == s[j] {
                    found = Some((i, j));
                    break 'outer;
                }
            }
        }
        match found {
            Some((i, j)) => {
                let a: Vec<u32> = s[i..j].to_vec();
                let mut b: Vec<u32> = s[j..].to_vec();
                b.extend_from_slice(&s[..i]);
                stack.push(a);
                stack.push(b);
            }
            None => {
                if s.len() >= 3 {
                    out.push(s);
                }
            }
        }
    }
    out
}

/// Interior overlap of two projected triangles given with their vertex labels (shared
/// labels are the same vertex).
fn overlap2d(ta: &[u32; 3], pa: &[(f64, f64); 3], tb: &[u32; 3], pb: &[(f64, f64); 3]) -> bool {
    let shared: Vec<(usize, usize)> = (0..3)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .filter(|&(i, j)| ta[i] == tb[j])
        .collect();
    match shared.len() {
        3 => return true,
        2 => {
            // same side of the shared edge?
            let (i0, j0) = shared[0];
            let (i1, _) = shared[1];
            let ia = 3 - i0 - i1;
            let jb = (0..3).find(|&j| j != j0 && j != shared[1].1).unwrap_or(0);
            let e0 = pa[i0];
            let e1 = pa[i1];
            let sa = orient2(e0, e1, pa[ia]);
            let sb = orient2(e0, e1, pb[jb]);
            return sa * sb > 0.0;
        }
        _ => {}
    }
    for i in 0..3 {
        for j in 0..3 {
            let (a0, a1) = (ta[i], ta[(i + 1) % 3]);
            let (b0, b1) = (tb[j], tb[(j + 1) % 3]);
            if a0 == b0 || a0 == b1 || a1 == b0 || a1 == b1 {
                continue;
            }
            if segments_cross(pa[i], pa[(i + 1) % 3], pb[j], pb[(j + 1) % 3]) {
                return true;
            }
        }
    }
    for i in 0..3 {
        if !tb.contains(&ta[i]) && point_in_triangle(pa[i], pb[0], pb[1], pb[2]) {
            return true;
        }
    }
    for j in 0..3 {
        if !ta.contains(&tb[j]) && point_in_triangle(pb[j], pa[0], pa[1], pa[2]) {
            return true;
        }
    }
    false
}

fn orient2(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> f64 {
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// Proper crossing of two segments (touching at an end does not count).
fn segments_cross(a: (f64, f64), b: (f64, f64), c: (f64, f64), d: (f64, f64)) -> bool {
    let d1 = orient2(a, b, c);
    let d2 = orient2(a, b, d);
    let d3 = orient2(c, d, a);
    let d4 = orient2(c, d, b);
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

/// Strictly inside a triangle (either orientation).
fn point_in_triangle(p: (f64, f64), a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> bool {
    let s1 = orient2(a, b, p);
    let s2 = orient2(b, c, p);
    let s3 = orient2(c, a, p);
    (s1 > 0.0 && s2 > 0.0 && s3 > 0.0) || (s1 < 0.0 && s2 < 0.0 && s3 < 0.0)
}

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

/// Cotangent weights `ω_ij` and barycentric area of vertex `i` from its triangles
/// (each as `(i, x, y)` positions), clamped as in the module doc. Returns the
/// mean-curvature normal `δ_i`, `Σ ω_ij` and `A_i`, or `None` for a degenerate star.
fn cot_laplacian(
    p: DVec3,
    fan: &[(DVec3, DVec3, u32, u32)],
) -> Option<(DVec3, BTreeMap<u32, f64>, f64)> {
    let mut w: BTreeMap<u32, f64> = BTreeMap::new();
    let mut area = 0.0;
    let mut at: BTreeMap<u32, DVec3> = BTreeMap::new();
    for &(x, y, ix, iy) in fan {
        // cot at x faces edge p-y; cot at y faces edge p-x
        *w.entry(iy).or_insert(0.0) += measure::cot_at(x, y, p);
        *w.entry(ix).or_insert(0.0) += measure::cot_at(y, p, x);
        area += measure::tri_area(p, x, y) / 3.0;
        at.insert(ix, x);
        at.insert(iy, y);
    }
    if !positive(area) || !area.is_finite() {
        return None;
    }
    let mut sum = 0.0;
    for v in w.values_mut() {
        *v = if v.is_finite() {
            v.clamp(0.0, 1e3)
        } else {
            0.0
        };
        sum += *v;
    }
    if !positive(sum - 1e-12) {
        for v in w.values_mut() {
            *v = UNIFORM_WEIGHT;
        }
    }
    let mut d = DVec3::ZERO;
    for (j, &wj) in &w {
        d += wj * (at[j] - p);
    }
    let delta = d / (2.0 * area);
    delta.is_finite().then_some((delta, w, area))
}

/// The training samples: positions and Laplacians of rings `1..=rings` around `hole`.
pub fn training_set(mesh: &Mesh, hole: &[VertexId], rings: usize) -> (Vec<DVec3>, Vec<DVec3>) {
    let mut ring_of: crate::fasthash::HashMap<VertexId, usize> =
        crate::fasthash::HashMap::default();
    for &v in hole {
        ring_of.insert(v, 0);
    }
    let mut layers: Vec<Vec<VertexId>> = vec![hole.to_vec()];
    for r in 1..=rings {
        let mut layer = Vec::new();
        for &v in &layers[r - 1] {
            for w in mesh.topo.neighbors(v) {
                if let std::collections::hash_map::Entry::Vacant(e) = ring_of.entry(w) {
                    e.insert(r);
                    layer.push(w);
                }
            }
        }
        if layer.is_empty() {
            break;
        }
        layers.push(layer);
    }
    let centroid = measure::centroid(&hole.iter().map(|&v| mesh.pos(v)).collect::<Vec<_>>());
    let mut chosen: Vec<VertexId> = Vec::new();
    for layer in layers.iter().skip(1) {
        let mut cand: Vec<VertexId> = layer
            .iter()
            .copied()
            .filter(|&v| !mesh.topo.is_boundary_vertex(v))
            .collect();
        if chosen.len() + cand.len() > MAX_SAMPLES {
            cand.sort_by(|&a, &b| {
                let da = (mesh.pos(a) - centroid).length_squared();
                let db = (mesh.pos(b) - centroid).length_squared();
                da.total_cmp(&db).then(a.cmp(&b))
            });
            cand.truncate(MAX_SAMPLES - chosen.len());
        }
        chosen.extend(cand);
        if chosen.len() >= MAX_SAMPLES {
            break;
        }
    }
    let mut xs = Vec::with_capacity(chosen.len());
    let mut ys = Vec::with_capacity(chosen.len());
    for v in chosen {
        let p = mesh.pos(v);
        let fan: Vec<(DVec3, DVec3, u32, u32)> = mesh
            .topo
            .vertex_faces(v)
            .map(|f| {
                let t = mesh.topo.face(f);
                let c = t.iter().position(|&x| x == v).unwrap_or(0);
                let (a, b) = (t[(c + 1) % 3], t[(c + 2) % 3]);
                (mesh.pos(a), mesh.pos(b), a.0, b.0)
            })
            .collect();
        if let Some((d, _, _)) = cot_laplacian(p, &fan) {
            let n = mesh.vertex_normal(v);
            xs.push(p);
            ys.push(n * d.dot(n));
        }
    }
    (xs, ys)
}

// ---------------------------------------------------------------------------
// 3. LS-SVM

/// A trained LS-SVM regression `R³ → R³` (one function per output axis, one kernel).
pub struct LssvmModel {
    xs: Vec<DVec3>,
    alpha: Vec<DVec3>,
    bias: DVec3,
    inv2s2: f64,
}

impl LssvmModel {
    /// Solves eq. 14 for samples `xs → ys` with regularisation `gamma` and RBF width `sigma`.
    pub fn fit(
        xs: &[DVec3],
        ys: &[DVec3],
        gamma: f64,
        sigma: f64,
    ) -> Result<LssvmModel, FillError> {
        let l = xs.len();
        if l == 0 || ys.len() != l {
            return Err(FillError::Failed(
                "LS-SVM needs matching, non-empty samples".into(),
            ));
        }
        if !(gamma > 0.0 && gamma.is_finite() && sigma > 0.0 && sigma.is_finite()) {
            return Err(FillError::Failed(
                "LS-SVM needs positive gamma and kernel width".into(),
            ));
        }
        let inv2s2 = 1.0 / (2.0 * sigma * sigma);
        let h = Mat::<f64>::from_fn(l, l, |i, j| {
            let k = (-(xs[i] - xs[j]).length_squared() * inv2s2).exp();
            if i == j {
                k + 1.0 / gamma
            } else {
                k
            }
        });
        let llt = h.llt(Side::Lower).map_err(|e| {
            FillError::Failed(format!(
                "LS-SVM kernel matrix is not positive definite: {e:?}"
            ))
        })?;
        let rhs = Mat::<f64>::from_fn(l, 4, |i, c| match c {
            0 => 1.0,
            1 => ys[i].x,
            2 => ys[i].y,
            _ => ys[i].z,
        });
        let x = llt.solve(&rhs);
        let sol: Vec<[f64; 4]> = (0..l)
            .map(|i| [x[(i, 0)], x[(i, 1)], x[(i, 2)], x[(i, 3)]])
            .collect();
        Self::from_solution(xs, &sol, inv2s2)
            .ok_or_else(|| FillError::Failed("LS-SVM system is singular".into()))
    }

    /// The model from the solutions `[η, ν_x, ν_y, ν_z]` of `H X = [1, y]`.
    fn from_solution(xs: &[DVec3], sol: &[[f64; 4]], inv2s2: f64) -> Option<LssvmModel> {
        let s_eta: f64 = sol.iter().map(|r| r[0]).sum();
        if !positive(s_eta.abs()) || !s_eta.is_finite() {
            return None;
        }
        let bias = DVec3::new(
            sol.iter().map(|r| r[1]).sum::<f64>() / s_eta,
            sol.iter().map(|r| r[2]).sum::<f64>() / s_eta,
            sol.iter().map(|r| r[3]).sum::<f64>() / s_eta,
        );
        let alpha: Vec<DVec3> = sol
            .iter()
            .map(|r| DVec3::new(r[1], r[2], r[3]) - bias * r[0])
            .collect();
        if !bias.is_finite() || alpha.iter().any(|a| !a.is_finite()) {
            return None;
        }
        Some(LssvmModel {
            xs: xs.to_vec(),
            alpha,
            bias,
            inv2s2,
        })
    }

    /// Eq. 15 for the three axes.
    pub fn predict(&self, x: DVec3) -> DVec3 {
        let mut s = self.bias;
        for (xi, a) in self.xs.iter().zip(&self.alpha) {
            s += *a * (-(x - *xi).length_squared() * self.inv2s2).exp();
        }
        s
    }
}

// ---------------------------------------------------------------------------
// 4. Poisson

/// Labels of mesh vertices outside the patch in a [`Ring`] start here.
const EXT: u32 = u32::MAX / 2;

/// The mesh around the loop, for the rows of the loop vertices: for each loop vertex its
/// mesh faces as label pairs (loop vertex `j` is `j`, any other mesh vertex `EXT + e`
/// with position `ext[e]`).
pub struct Ring {
    ext: Vec<DVec3>,
    fans: Vec<Vec<(u32, u32)>>,
}

impl Ring {
    /// Collects the mesh faces around the loop `hole`.
    pub fn new(mesh: &Mesh, hole: &[VertexId]) -> Ring {
        let mut label: crate::fasthash::HashMap<VertexId, u32> =
            crate::fasthash::HashMap::default();
        for (i, &v) in hole.iter().enumerate() {
            label.insert(v, i as u32);
        }
        let mut ext = Vec::new();
        let mut fans = Vec::with_capacity(hole.len());
        for &v in hole {
            let mut fan = Vec::new();
            for f in mesh.topo.vertex_faces(v) {
                let t = mesh.topo.face(f);
                let c = t.iter().position(|&x| x == v).unwrap_or(0);
                let mut pair = [0u32; 2];
                for (slot, w) in pair.iter_mut().zip([t[(c + 1) % 3], t[(c + 2) % 3]]) {
                    *slot = *label.entry(w).or_insert_with(|| {
                        ext.push(mesh.pos(w));
                        EXT + (ext.len() - 1) as u32
                    });
                }
                fan.push((pair[0], pair[1]));
            }
            fans.push(fan);
        }
        Ring { ext, fans }
    }
}

/// The factored Poisson system of a patch. Unknowns are the new vertices; the loop
/// vertices are Dirichlet values. Rows: one per new vertex, and with a [`Ring`] one per
/// loop vertex as well (its one-ring spans the mesh, whose vertices are fixed, and the
/// patch); the overdetermined system is solved in the least-squares sense through its
/// normal equations. Factor once, solve for any target Laplacian field.
pub struct PoissonSolver {
    lu: faer::sparse::linalg::solvers::Lu<usize, f64>,
    n: usize,
    k: usize,
    /// Rows: `(scale, unknown entries, fixed entries, own fixed label)`; the equation is
    /// `[x_own] − Σ w_ij x_j = −scale · δ`.
    rows: Vec<Row>,
    ext: Vec<DVec3>,
}

struct Row {
    /// `2 A_i / Σ ω_ij`.
    scale: f64,
    unknown: Vec<(usize, f64)>,
    fixed: Vec<(u32, f64)>,
    /// For a loop-vertex row, the loop vertex itself (fixed); `None` for a new vertex,
    /// whose own coefficient 1 is in `unknown`.
    own: Option<u32>,
}

impl PoissonSolver {
    /// Builds and factors the system on the geometry `pos` (loop first, `k` of them).
    pub fn new(
        pos: &[DVec3],
        k: usize,
        triangles: &[[u32; 3]],
        edge: f64,
        ring: Option<&Ring>,
    ) -> Result<PoissonSolver, FillError> {
        let n = pos.len().saturating_sub(k);
        if n == 0 {
            return Err(FillError::Failed(
                "the patch has no new vertex to solve for".into(),
            ));
        }
        if ring.is_some_and(|r| r.fans.len() != k) {
            return Err(FillError::Failed("ring does not match the loop".into()));
        }
        let ext: &[DVec3] = ring.map(|r| r.ext.as_slice()).unwrap_or(&[]);
        let at = |l: u32| -> DVec3 {
            if l >= EXT {
                ext[(l - EXT) as usize]
            } else {
                pos[l as usize]
            }
        };
        let nrows = if ring.is_some() { n + k } else { n };
        // fans: rows 0..n new vertices, n..n+k loop vertices
        let mut fans: Vec<Vec<(DVec3, DVec3, u32, u32)>> = vec![Vec::new(); nrows];
        for t in triangles {
            if t.iter().any(|&i| i as usize >= pos.len()) {
                return Err(FillError::Failed(
                    "patch triangle index out of range".into(),
                ));
            }
            for c in 0..3 {
                let v = t[c] as usize;
                let row = if v >= k {
                    Some(v - k)
                } else if ring.is_some() {
                    Some(n + v)
                } else {
                    None
                };
                if let Some(r) = row {
                    let (a, b) = (t[(c + 1) % 3], t[(c + 2) % 3]);
                    fans[r].push((pos[a as usize], pos[b as usize], a, b));
                }
            }
        }
        if let Some(r) = ring {
            for (i, fan) in r.fans.iter().enumerate() {
                for &(a, b) in fan {
                    fans[n + i].push((at(a), at(b), a, b));
                }
            }
        }
        let mut rows = Vec::with_capacity(nrows);
        for (r, fan) in fans.iter().enumerate() {
            let me = if r < n { k + r } else { r - n };
            let p = pos[me];
            let (w, s) = match cot_laplacian(p, fan) {
                Some((_, w, area)) => {
                    let sum: f64 = w.values().sum();
                    (w, 2.0 * area / sum)
                }
                None => {
                    // degenerate star: uniform weights, the regular-mesh scale L²/4
                    let mut w = BTreeMap::new();
                    for &(_, _, a, b) in fan {
                        w.insert(a, UNIFORM_WEIGHT);
                        w.insert(b, UNIFORM_WEIGHT);
                    }
                    (w, edge * edge / 4.0)
                }
            };
            let sum: f64 = w.values().sum();
            if !positive(sum) || !s.is_finite() {
                return Err(FillError::Failed(format!(
                    "patch vertex {me} has no neighbours"
                )));
            }
            let mut unknown = Vec::new();
            let mut fixed = Vec::new();
            if r < n {
                unknown.push((r, 1.0));
            }
            for (&j, &wj) in &w {
                let wj = wj / sum;
                if j < EXT && j as usize >= k {
                    unknown.push((j as usize - k, -wj));
                } else {
                    fixed.push((j, wj));
                }
            }
            rows.push(Row {
                scale: s,
                unknown,
                fixed,
                own: (r >= n).then_some(me as u32),
            });
        }
        // normal equations AᵀA (for the square system A itself)
        let mut acc: BTreeMap<(usize, usize), f64> = BTreeMap::new();
        if ring.is_some() {
            for row in &rows {
                for &(c1, v1) in &row.unknown {
                    for &(c2, v2) in &row.unknown {
                        *acc.entry((c1, c2)).or_insert(0.0) += v1 * v2;
                    }
                }
            }
        } else {
            for (r, row) in rows.iter().enumerate() {
                for &(c, v) in &row.unknown {
                    *acc.entry((r, c)).or_insert(0.0) += v;
                }
            }
        }
        let trip: Vec<Triplet<usize, usize, f64>> = acc
            .into_iter()
            .map(|((i, j), v)| Triplet::new(i, j, v))
            .collect();
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &trip)
            .map_err(|e| FillError::Failed(format!("Poisson matrix: {e:?}")))?;
        let lu = a
            .sp_lu()
            .map_err(|e| FillError::Failed(format!("Poisson factorisation: {e:?}")))?;
        Ok(PoissonSolver {
            lu,
            n,
            k,
            rows,
            ext: ext.to_vec(),
        })
    }

    /// Number of rows: new vertices first, then (with a ring) the loop vertices.
    pub fn rows(&self) -> usize {
        self.rows.len()
    }

    /// Positions of the new vertices whose Laplacians best match `target` (one per row:
    /// new vertices, then loop vertices when built with a ring), with the loop vertices
    /// at `boundary`.
    pub fn solve(&self, boundary: &[DVec3], target: &[DVec3]) -> Result<Vec<DVec3>, FillError> {
        let n = self.n;
        if target.len() != self.rows.len() || boundary.len() != self.k {
            return Err(FillError::Failed(
                "Poisson right-hand side has the wrong length".into(),
            ));
        }
        let at = |l: u32| -> DVec3 {
            if l >= EXT {
                self.ext[(l - EXT) as usize]
            } else {
                boundary[l as usize]
            }
        };
        // b_r = Σ_fixed w x_fixed − x_own − scale·δ
        let b: Vec<DVec3> = self
            .rows
            .iter()
            .zip(target)
            .map(|(row, &d)| {
                let fx: DVec3 = row.fixed.iter().map(|&(j, w)| w * at(j)).sum();
                let own = row.own.map(at).unwrap_or(DVec3::ZERO);
                fx - own - row.scale * d
            })
            .collect();
        let mut rhs = Mat::<f64>::zeros(n, 3);
        if self.rows.len() > n {
            for (row, bv) in self.rows.iter().zip(&b) {
                for &(c, v) in &row.unknown {
                    for d in 0..3 {
                        rhs[(c, d)] += v * bv[d];
                    }
                }
            }
        } else {
            for (i, bv) in b.iter().enumerate() {
                for d in 0..3 {
                    rhs[(i, d)] = bv[d];
                }
            }
        }
        let x = self.lu.solve(&rhs);
        let out: Vec<DVec3> = (0..n)
            .map(|i| DVec3::new(x[(i, 0)], x[(i, 1)], x[(i, 2)]))
            .collect();
        if out.iter().any(|p| !p.is_finite()) {
            return Err(FillError::Failed("Poisson solution is not finite".into()));
        }
        Ok(out)
    }
}

/// One-off Poisson solve: factors the system on `pos` and solves for `target`.
pub fn solve_poisson(
    pos: &[DVec3],
    k: usize,
    triangles: &[[u32; 3]],
    target: &[DVec3],
    edge: f64,
    ring: Option<&Ring>,
) -> Result<Vec<DVec3>, FillError> {
    PoissonSolver::new(pos, k, triangles, edge, ring)?.solve(&pos[..k.min(pos.len())], target)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::{check_degenerate, check_topology, patch_positions};
    use crate::fill::kit::Deadline;
    use crate::io::RawMesh;
    use crate::patch::{apply_patch, Hole};
    use crate::policy::{Checks, Policy};
    use rand::{Rng, SeedableRng};

    /// Builds a mesh from a soup, removing every face that touches a vertex for which
    /// `cut` holds; returns the mesh and the hole loop nearest `centre`.
    fn cut_mesh(
        pos: &[DVec3],
        faces: &[[u32; 3]],
        cut: impl Fn(DVec3) -> bool,
        centre: DVec3,
    ) -> (Mesh, Vec<VertexId>) {
        let gone: Vec<bool> = pos.iter().map(|&p| cut(p)).collect();
        let raw = RawMesh {
            positions: pos.to_vec(),
            faces: faces
                .iter()
                .copied()
                .filter(|f| !f.iter().any(|&i| gone[i as usize]))
                .collect(),
            ..Default::default()
        };
        let (mesh, _) = Mesh::from_raw(&raw);
        mesh.validate().unwrap();
        let loops = mesh.topo.boundary_loops();
        let lp = loops
            .into_iter()
            .min_by(|a, b| {
                let ca = measure::centroid(&a.iter().map(|&v| mesh.pos(v)).collect::<Vec<_>>());
                let cb = measure::centroid(&b.iter().map(|&v| mesh.pos(v)).collect::<Vec<_>>());
                (ca - centre).length().total_cmp(&(cb - centre).length())
            })
            .unwrap();
        let mut seen = HashSet::default();
        assert!(
            lp.iter().all(|v| seen.insert(*v)),
            "test hole must be a simple loop"
        );
        (mesh, lp)
    }

    fn grid(n: usize) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                pos.push(DVec3::new(i as f64, j as f64, 0.0));
            }
        }
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        let mut faces = Vec::new();
        for j in 0..n {
            for i in 0..n {
                faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        (pos, faces)
    }

    /// Icosphere of radius `r`, `subdiv` midpoint subdivisions.
    fn icosphere(subdiv: usize, r: f64) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let m = crate::testutil::icosphere(subdiv, r);
        (m.positions, m.faces)
    }

    /// Open cylinder of radius `r` about the z axis.
    fn cylinder(r: f64, around: usize, rows: usize) -> (Vec<DVec3>, Vec<[u32; 3]>) {
        let dz = std::f64::consts::TAU * r / around as f64;
        let mut pos = Vec::new();
        for j in 0..=rows {
            for i in 0..around {
                // rows are staggered by half a step for near-equilateral triangles
                let a = (i as f64 + 0.5 * (j % 2) as f64) * std::f64::consts::TAU / around as f64;
                pos.push(DVec3::new(r * a.cos(), r * a.sin(), j as f64 * dz * 0.866));
            }
        }
        let id = |i: usize, j: usize| (j * around + i % around) as u32;
        let mut faces = Vec::new();
        for j in 0..rows {
            for i in 0..around {
                if j % 2 == 0 {
                    faces.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                    faces.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
                } else {
                    faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                    faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
                }
            }
        }
        (pos, faces)
    }

    struct Run {
        patch: Patch,
        front: Patch,
        hole: Hole,
    }

    fn run(mesh: &Mesh, lp: &[VertexId], policy: &Policy) -> Run {
        try_run(mesh, lp, policy).unwrap()
    }

    fn try_run(mesh: &Mesh, lp: &[VertexId], policy: &Policy) -> Result<Run, String> {
        let hole = Hole::new(0, mesh, lp.to_vec(), policy);
        let ctx = FillContext {
            mesh,
            hole: &hole,
            policy,
            deadline: Deadline::none(),
            checker: None,
        };
        let patch = fill(&ctx).map_err(|e| e.to_string())?;
        let front = initial_front(
            mesh,
            lp,
            hole.mean_edge_length,
            policy.lssvm.merge_distance,
            &Deadline::none(),
        )
        .map_err(|e| e.to_string())?;
        assert_eq!(front.triangles, patch.triangles);
        // the patch passes the checks and applies to a valid mesh
        check_topology(mesh, lp, &patch).map_err(|e| e.to_string())?;
        let pos = patch_positions(mesh, lp, &patch);
        check_degenerate(&pos, &patch, &Checks::default()).map_err(|e| e.to_string())?;
        let mut m2 = mesh.clone();
        apply_patch(&mut m2, &hole, &patch)?;
        m2.validate()?;
        Ok(Run { patch, front, hole })
    }

    fn mean_max(v: impl Iterator<Item = f64>) -> (f64, f64) {
        let (mut s, mut m, mut n) = (0.0, 0.0f64, 0usize);
        for x in v {
            s += x;
            m = m.max(x);
            n += 1;
        }
        (s / n.max(1) as f64, m)
    }

    #[test]
    fn planar_hole_gives_planar_patch() {
        let (pos, faces) = grid(24);
        let c = DVec3::new(12.3, 11.8, 0.0);
        let (mesh, lp) = cut_mesh(&pos, &faces, |p| (p - c).length() < 5.0, c);
        let r = run(&mesh, &lp, &Policy::default());
        assert!(!r.patch.new_vertices.is_empty());
        for p in &r.patch.new_vertices {
            assert!(p.z.abs() < 1e-9, "off the plane: {p}");
            assert!((*p - c).length() < 7.0, "outside the hole: {p}");
        }
    }

    fn sphere_case(subdiv: usize, cap: f64) -> (Mesh, Vec<VertexId>) {
        let (pos, faces) = icosphere(subdiv, 1.0);
        let dir = DVec3::new(0.3, 0.2, 1.0).normalize();
        cut_mesh(&pos, &faces, |p| p.normalize().dot(dir) > cap.cos(), dir)
    }

    fn sphere_errors(r: &Run) -> ((f64, f64), (f64, f64)) {
        let l = r.hole.mean_edge_length;
        let e = mean_max(
            r.patch
                .new_vertices
                .iter()
                .map(|p| (p.length() - 1.0).abs() / l),
        );
        let e0 = mean_max(
            r.front
                .new_vertices
                .iter()
                .map(|p| (p.length() - 1.0).abs() / l),
        );
        (e, e0)
    }

    #[test]
    fn sphere_hole_30() {
        let (mesh, lp) = sphere_case(4, 0.3);
        let r = run(&mesh, &lp, &Policy::default());
        let ((mean, max), (mean0, max0)) = sphere_errors(&r);
        eprintln!(
            "sphere k={} new={} err mean {mean:.4} max {max:.4} (front {mean0:.4} {max0:.4}) in edge lengths",
            lp.len(),
            r.patch.new_vertices.len()
        );
        assert!((25..=40).contains(&lp.len()), "{}", lp.len());
        // bound: 2 % (max) and 1 % (mean) of an edge length off the sphere, and at most a
        // tenth of the initial front's mean error
        assert!(max < 0.02 && mean < 0.01, "{mean} {max}");
        assert!(mean < 0.1 * mean0);
    }

    #[test]
    fn sphere_hole_100() {
        let (mesh, lp) = sphere_case(5, 0.52);
        let r = run(&mesh, &lp, &Policy::default());
        let ((mean, max), (mean0, max0)) = sphere_errors(&r);
        eprintln!(
            "sphere k={} new={} err mean {mean:.4} max {max:.4} (front {mean0:.4} {max0:.4}) in edge lengths",
            lp.len(),
            r.patch.new_vertices.len()
        );
        assert!((85..=130).contains(&lp.len()), "{}", lp.len());
        // bound: 5 % (max) and 2 % (mean) of an edge length
        assert!(max < 0.05 && mean < 0.02, "{mean} {max}");
        assert!(mean < 0.1 * mean0);
    }

    #[test]
    fn cylinder_hole() {
        let (pos, faces) = cylinder(1.0, 64, 40);
        let c = DVec3::new(1.0, 0.05, 1.7);
        let (mesh, lp) = cut_mesh(&pos, &faces, |p| (p - c).length() < 0.45, c);
        let r = run(&mesh, &lp, &Policy::default());
        let l = r.hole.mean_edge_length;
        let rad = |p: &DVec3| ((p.x * p.x + p.y * p.y).sqrt() - 1.0).abs() / l;
        let (mean, max) = mean_max(r.patch.new_vertices.iter().map(rad));
        let (mean0, max0) = mean_max(r.front.new_vertices.iter().map(rad));
        eprintln!(
            "cylinder k={} new={} err mean {mean:.4} max {max:.4} (front {mean0:.4} {max0:.4}) in edge lengths",
            lp.len(),
            r.patch.new_vertices.len()
        );
        // the Laplacian of a cylinder points to the axis, so it turns around the hole;
        // bound: 2 % (max) and 1 % (mean) of an edge length off the cylinder
        assert!(max < 0.02 && mean < 0.01, "{mean} {max}");
        assert!(mean < 0.1 * mean0);
    }

    #[test]
    fn noisy_sphere_still_closes() {
        // seeded Gaussian noise, sigma = 5 % of the mean boundary edge length, on the
        // loop and the three rings around it
        let (mesh, lp) = noisy_sphere(0.05, 7);
        let r = run(&mesh, &lp, &Policy::default());
        let ((mean, max), (mean0, _)) = sphere_errors(&r);
        eprintln!(
            "noisy sphere err mean {mean:.4} max {max:.4} (front {mean0:.4}) in edge lengths"
        );
        assert!(max < 0.15 && mean < 0.05, "{mean} {max}");
    }

    fn noisy_sphere(sigma_rel: f64, seed: u64) -> (Mesh, Vec<VertexId>) {
        let (mut mesh, lp) = sphere_case(4, 0.3);
        let l0 = Hole::new(0, &mesh, lp.clone(), &Policy::default()).mean_edge_length;
        let sigma = sigma_rel * l0;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let mut ring: HashSet<VertexId> = lp.iter().copied().collect();
        for _ in 0..3 {
            let cur: Vec<VertexId> = ring.iter().copied().collect();
            for v in cur {
                ring.extend(mesh.topo.neighbors(v));
            }
        }
        let mut ring: Vec<VertexId> = ring.into_iter().collect();
        ring.sort();
        for v in ring {
            let mut g = [0.0; 3];
            for x in &mut g {
                let u1: f64 = rng.random::<f64>().max(1e-300);
                let u2: f64 = rng.random();
                *x = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            }
            mesh.positions[v.idx()] += DVec3::from_array(g) * sigma;
        }
        (mesh, lp)
    }

    #[test]
    fn same_input_same_bits() {
        let (mesh, lp) = sphere_case(4, 0.3);
        let a = run(&mesh, &lp, &Policy::default()).patch;
        let b = run(&mesh, &lp, &Policy::default()).patch;
        assert_eq!(a.triangles, b.triangles);
        let bits = |p: &Patch| -> Vec<u64> {
            p.new_vertices
                .iter()
                .flat_map(|v| v.to_array().map(f64::to_bits))
                .collect()
        };
        assert_eq!(bits(&a), bits(&b));
    }

    #[test]
    fn poisson_has_linear_precision_and_reuses_its_factorisation() {
        // on a plane the cotangent Laplacian of the positions is zero: solving for a zero
        // target on the true geometry must give it back, with and without the ring rows
        let (pos, faces) = grid(16);
        let c = DVec3::new(8.2, 7.9, 0.0);
        let (mesh, lp) = cut_mesh(&pos, &faces, |p| (p - c).length() < 3.5, c);
        let r = run(&mesh, &lp, &Policy::default());
        let k = lp.len();
        let boundary: Vec<DVec3> = lp.iter().map(|&v| mesh.pos(v)).collect();
        let all: Vec<DVec3> = boundary
            .iter()
            .chain(&r.patch.new_vertices)
            .copied()
            .collect();
        let ring = Ring::new(&mesh, &lp);
        let l = r.hole.mean_edge_length;
        for rg in [None, Some(&ring)] {
            let solver = PoissonSolver::new(&all, k, &r.patch.triangles, l, rg).unwrap();
            let zero = vec![DVec3::ZERO; solver.rows()];
            let x = solver.solve(&boundary, &zero).unwrap();
            for (a, b) in x.iter().zip(&r.patch.new_vertices) {
                assert!((*a - *b).length() < 1e-9 * l, "{a} vs {b}");
            }
            let once = solve_poisson(&all, k, &r.patch.triangles, &zero, l, rg).unwrap();
            assert_eq!(once, x);
        }
    }

    #[test]
    fn lssvm_reproduces_a_smooth_field() {
        // samples on a ring; the field is linear: the regression must interpolate it inside
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        let f = |p: DVec3| DVec3::new(0.5 * p.x - p.y, 2.0 + 0.1 * p.y, p.x + p.y);
        for i in 0..60 {
            for r in [3.0, 3.5, 4.0] {
                let a = i as f64 * std::f64::consts::TAU / 60.0;
                let p = DVec3::new(r * a.cos(), r * a.sin(), 0.0);
                xs.push(p);
                ys.push(f(p));
            }
        }
        let m = LssvmModel::fit(&xs, &ys, 1e4, 3.0).unwrap();
        for p in [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, -1.5, 0.0),
            DVec3::new(3.2, 0.4, 0.0),
        ] {
            let e = (m.predict(p) - f(p)).length();
            assert!(e < 0.05 * f(p).length().max(1.0), "at {p}: {e}");
        }
    }

    #[test]
    fn small_loops_close() {
        // one removed grid cell (4 vertices, no new vertex needed) and a removed vertex star
        let (pos, faces) = grid(6);
        let cell = 2 * (2 * 6 + 2);
        let mut f1 = faces.clone();
        f1.drain(cell..cell + 2);
        let raw = RawMesh {
            positions: pos.clone(),
            faces: f1,
            ..Default::default()
        };
        let (mesh, _) = Mesh::from_raw(&raw);
        let lp = mesh
            .topo
            .boundary_loops()
            .into_iter()
            .find(|l| l.len() == 4)
            .unwrap();
        let r = run(&mesh, &lp, &Policy::default());
        assert_eq!(r.patch.triangles.len(), 2);
        let c = DVec3::new(2.0, 3.0, 0.0);
        let (mesh, lp) = cut_mesh(&pos, &faces, |p| (p - c).length() < 0.5, c);
        assert_eq!(lp.len(), 6);
        let r = run(&mesh, &lp, &Policy::default());
        for p in &r.patch.new_vertices {
            assert!(p.z.abs() < 1e-9);
        }
    }

    #[test]
    fn a_passed_deadline_is_a_timeout() {
        let (mesh, lp) = sphere_case(4, 0.3);
        let policy = Policy::default();
        let hole = Hole::new(0, &mesh, lp, &policy);
        let ctx = FillContext {
            mesh: &mesh,
            hole: &hole,
            policy: &policy,
            deadline: Deadline(Some(std::time::Instant::now())),
            checker: None,
        };
        assert_eq!(fill(&ctx), Err(FillError::Timeout));
    }

    #[test]
    fn bad_policy_values_fail_cleanly() {
        let (pos, faces) = grid(10);
        let c = DVec3::new(5.2, 4.9, 0.0);
        let (mesh, lp) = cut_mesh(&pos, &faces, |p| (p - c).length() < 2.5, c);
        let mut policy = Policy::default();
        policy.lssvm.gamma = -1.0;
        let hole = Hole::new(0, &mesh, lp, &policy);
        let ctx = FillContext {
            mesh: &mesh,
            hole: &hole,
            policy: &policy,
            deadline: Deadline::none(),
            checker: None,
        };
        assert!(matches!(fill(&ctx), Err(FillError::Failed(_))));
    }

    /// Regression (stanford-bunny hole 3, homer hole 3 of the shared bench, where the
    /// paper's front made an overlap or got stuck): the minimum-area initial patch and
    /// the residual front both close a sphere hole, pass the dispatcher's checks and,
    /// after LS-SVM + Poisson, stay within 2 % of an edge length of the sphere (max) and
    /// 1 % (mean), as the paper's front does (`sphere_hole_30`).
    #[test]
    fn other_initial_patches_close_and_stay_on_the_sphere() {
        let (mesh, lp) = sphere_case(4, 0.3);
        let policy = Policy::default();
        let hole = Hole::new(0, &mesh, lp, &policy);
        let ctx = FillContext {
            mesh: &mesh,
            hole: &hole,
            policy: &policy,
            deadline: Deadline::none(),
            checker: None,
        };
        let l = hole.mean_edge_length;
        for start in [Start::MinArea, Start::ResidualFront] {
            let patch = fill_with(&ctx, start).unwrap();
            crate::check::Checker::new(&mesh)
                .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
                .unwrap();
            let (mean, max) = mean_max(
                patch
                    .new_vertices
                    .iter()
                    .map(|p| (p.length() - 1.0).abs() / l),
            );
            assert!(max < 0.02 && mean < 0.01, "{start:?} {mean} {max}");
        }
    }
}
