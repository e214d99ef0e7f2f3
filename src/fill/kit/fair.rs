//! Fairing of a hole patch: the new vertices are placed so that `Δ^c x = 0`
//! (paper 002, Feng et al. 2020, §5.2 "patch fairing", read with ALGORITHMS B2 step 3).
//!
//! The paper deforms the refined patch "by the Laplace-Beltrami algorithm" after
//! joining it with "the two adjacent faces" of the hole, without saying more. We read
//! it as Liepa's (2003) and CGAL's `fair()`: the unknowns are the new (interior)
//! vertices of the patch, everything else is held fixed, and each unknown satisfies
//! `Δ^c x = 0` with `c` = `policy.fair.continuity` (1 membrane, 2 thin plate,
//! 3 minimum variation; 0 leaves the patch as it is).
//!
//! * The operator is built on the union of the patch and the surrounding mesh: `Δ^c` at
//!   an unknown reaches `c` rings, so the Laplacian must be complete at every vertex
//!   within `c - 1` rings of an unknown. We include every mesh face incident to a mesh
//!   vertex within `c - 2` rings of the hole boundary (ring 0 = the boundary): for
//!   `c = 2` the boundary and its outer 1-ring are the constraints, for `c = 3` two
//!   outer rings.
//! * Weights (`policy.fair.weights`): cotangent `(cot α + cot β)/2` computed on the
//!   patch as it stands before fairing (the refined, flat triangulation; the patch
//!   refinement makes it Delaunay, so the weights are non-negative there). Each
//!   cotangent is clamped (see [`measure::cot_at`]) and a negative edge weight is set to
//!   zero; a vertex with a degenerate incident triangle or no positive weight falls
//!   back to uniform weights. `fujiwara` is the scale-dependent umbrella, weight
//!   `1/|e|`; `uniform` is weight 1.
//! * Normalisation: each Laplacian is divided by the vertex's mixed Voronoi area
//!   (Meyer et al. 2003), i.e. the discrete Laplace-Beltrami operator. CGAL's `fair()`
//!   does the same (`Cotangent_weight_with_voronoi_area_fairing`, weights
//!   `w_i = 1/(2 A_i)`). On sphere and cylinder holes this gives a
//!   smaller error than the unnormalised operator for `c = 2` (see the tests), because
//!   the patch triangles (small, refined) and the ring triangles (input size) differ.
//!   For `uniform`/`fujiwara` weights the operator is normalised by the weight sum
//!   instead (the umbrella operator), as in Taubin's and Kobbelt's work.
//!
//! Each unknown's row is `M·Δ^c` (its own area factor dropped, which leaves the
//! solution unchanged): `L M⁻¹ L …` with the symmetric cotangent matrix `L`, so the
//! system is symmetric, and after negation for odd `c` positive definite; it is
//! factored once by sparse Cholesky (faer) and solved for x, y and z
//! ([`FairSolver`]). When a vertex fell back to uniform weights the matrix is not
//! symmetric and sparse LU is used instead (also when Cholesky fails). A failed
//! factorisation or a non-finite result is `FillError::Failed`.
//!
//! Three fairings ([`FairEnergy`], the candidates of `blend.energy = "validate"`):
//! the `[fair]` keys; the umbrella energy (`c = 2`, each Laplacian over the square of
//! its weight sum: `L S² L`, the least squares of MeshLib's fairing); minimum variation
//! (`c = 3`). [`freed_rings_error`] scores one on a hole: the patch is faired with rings
//! of the known surface around it freed too ([`local_freed`]), and the known vertices
//! move by that mean distance. Measured in docs/measurements.md ("The faired surface's
//! fairing, chosen per large hole"): no one fairing is closest on every mesh; the
//! choice by freed rings is closer than the thin plate alone on the large holes of
//! eight of the bench's nine meshes (not falconstatue).

use super::FillError;
use crate::fasthash::HashMap;
use crate::geometry::measure;
use crate::mesh::{Mesh, VertexId};
use crate::patch::{Hole, Patch};
use crate::policy::{Fair, FairEnergy, Weights};
use faer::linalg::solvers::Solve;
use faer::Mat;
use glam::DVec3;

/// A piece of triangle mesh on which the fairing operator is built.
#[derive(Clone, Debug, Default)]
pub struct LocalMesh {
    /// Vertex positions (the free ones are the starting guess, used for the weights).
    pub positions: Vec<DVec3>,
    /// Triangles over `positions`, consistently oriented.
    pub triangles: Vec<[u32; 3]>,
    /// `free[v]`: the vertex is an unknown; the others are constraints.
    pub free: Vec<bool>,
}

/// How each Laplacian is scaled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Normalization {
    /// Raw weights: `Σ w_ij (x_j - x_i)`.
    None,
    /// Divided by the weight sum (umbrella form).
    WeightSum,
    /// Divided by the mixed Voronoi area (Laplace-Beltrami).
    VoronoiArea,
    /// Divided by the square of the weight sum: for `c = 2` the system is `L S² L`
    /// (`S = diag(1/W_v)`), the normal equations of the least-squares umbrella energy
    /// `Σ_v |x_v − Σ_u w_vu x_u / W_v|²` ([`FairEnergy::Umbrella`]).
    WeightSumSquared,
}

/// The default normalisation for a weight scheme (see the module docs).
pub fn default_normalization(w: Weights) -> Normalization {
    match w {
        Weights::Cotangent => Normalization::VoronoiArea,
        Weights::Uniform | Weights::Fujiwara => Normalization::WeightSum,
    }
}

/// Per-vertex weighted adjacency, `scale[v] * Σ_u w[v][u] (x_u - x_v)`.
struct Operator {
    nbrs: Vec<Vec<(u32, f64)>>,
    sum: Vec<f64>,
    scale: Vec<f64>,
    /// Every edge has the same weight seen from both ends.
    symmetric: bool,
}

fn build_operator(local: &LocalMesh, weights: Weights, norm: Normalization) -> Operator {
    let n = local.positions.len();
    let p = &local.positions;
    // per undirected edge: sum of cotangents of the opposite angles
    // (collected per triangle corner, then summed per edge in triangle order: a stable
    // sort keeps the order of the additions, so the sums are those of a map filled
    // triangle by triangle, without the hashing, which dominated the fairing's setup)
    let mut cot: Vec<((u32, u32), f64)> = Vec::with_capacity(local.triangles.len() * 3);
    let mut degenerate = vec![false; n];
    let mut area = vec![0.0f64; n];
    for t in &local.triangles {
        let [a, b, c] = t.map(|i| p[i as usize]);
        let l = (b - a).length().max((c - b).length()).max((a - c).length());
        let ar = measure::tri_area(a, b, c);
        if !ar.is_finite() || ar <= 1e-12 * l * l {
            for &i in t {
                degenerate[i as usize] = true;
            }
        }
        // mixed Voronoi area (Meyer et al. 2003)
        // the obtuse corner: its two edges' dot product is negative (no angles)
        let obtuse = [(a, b, c), (b, c, a), (c, a, b)]
            .iter()
            .position(|&(p, q, r)| (q - p).dot(r - p) < 0.0);
        // the cotangent at each corner, once
        let cots = [
            measure::cot_at(a, b, c),
            measure::cot_at(b, c, a),
            measure::cot_at(c, a, b),
        ];
        for corner in 0..3 {
            let i = t[corner] as usize;
            let j = t[(corner + 1) % 3] as usize;
            let k = t[(corner + 2) % 3] as usize;
            let contrib = match obtuse {
                None => {
                    let cj = cots[(corner + 1) % 3];
                    let ck = cots[(corner + 2) % 3];
                    ((p[i] - p[k]).length_squared() * cj + (p[i] - p[j]).length_squared() * ck)
                        / 8.0
                }
                Some(o) if o == corner => ar / 2.0,
                Some(_) => ar / 4.0,
            };
            area[i] += contrib.max(0.0);
        }
        for corner in 0..3 {
            let i = t[corner];
            let j = t[(corner + 1) % 3];
            let key = (i.min(j), i.max(j));
            // the angle opposite edge i-j, at the third corner
            cot.push((key, cots[(corner + 2) % 3]));
        }
    }
    cot.sort_by_key(|e| e.0);
    let mut nbrs: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
    let mut e = 0;
    while e < cot.len() {
        let (i, j) = cot[e].0;
        let mut c = 0.0;
        while e < cot.len() && cot[e].0 == (i, j) {
            c += cot[e].1;
            e += 1;
        }
        nbrs[i as usize].push((j, c));
        nbrs[j as usize].push((i, c));
    }
    let mut sum = vec![0.0; n];
    let mut scale = vec![1.0; n];
    let mut symmetric = true;
    for v in 0..n {
        nbrs[v].sort_unstable_by_key(|e| e.0);
        let pv = p[v];
        let mut uniform = weights == Weights::Uniform || degenerate[v];
        if !uniform {
            for e in nbrs[v].iter_mut() {
                let w = match weights {
                    Weights::Cotangent => (0.5 * e.1).max(0.0),
                    Weights::Fujiwara => {
                        let l = (p[e.0 as usize] - pv).length();
                        if l > 0.0 {
                            1.0 / l
                        } else {
                            f64::NAN
                        }
                    }
                    Weights::Uniform => 1.0,
                };
                e.1 = w;
            }
            let s: f64 = nbrs[v].iter().map(|e| e.1).sum();
            if !s.is_finite() || s <= 0.0 {
                uniform = true;
            }
        }
        if uniform {
            if weights != Weights::Uniform {
                symmetric = false;
            }
            for e in nbrs[v].iter_mut() {
                e.1 = 1.0;
            }
        }
        sum[v] = nbrs[v].iter().map(|e| e.1).sum();
        scale[v] = match norm {
            Normalization::None => 1.0,
            Normalization::WeightSum => {
                if sum[v] > 0.0 {
                    1.0 / sum[v]
                } else {
                    1.0
                }
            }
            Normalization::WeightSumSquared => {
                if sum[v] > 0.0 {
                    1.0 / (sum[v] * sum[v])
                } else {
                    1.0
                }
            }
            Normalization::VoronoiArea => {
                if uniform || area[v].is_nan() || area[v] <= 0.0 {
                    // fall back to the umbrella form, scaled like an area-normalised
                    // operator would be (1 / mean squared edge length)
                    let l2: f64 = nbrs[v]
                        .iter()
                        .map(|e| (p[e.0 as usize] - pv).length_squared())
                        .sum::<f64>()
                        / nbrs[v].len().max(1) as f64;
                    if sum[v] > 0.0 && l2 > 0.0 {
                        1.0 / (sum[v] * l2)
                    } else {
                        1.0
                    }
                } else {
                    1.0 / (2.0 * area[v])
                }
            }
        };
    }
    Operator {
        nbrs,
        sum,
        scale,
        symmetric,
    }
}

/// The factorisation: Cholesky when the system is symmetric positive definite, else LU.
enum Factor {
    Llt(faer::sparse::linalg::solvers::Llt<usize, f64>),
    Lu(Box<faer::sparse::linalg::solvers::Lu<usize, f64>>),
}

/// Fairing system of one patch, factored once; [`FairSolver::solve`] gives the new
/// positions of the unknowns for x, y and z.
pub struct FairSolver {
    factor: Factor,
    rhs: Mat<f64>,
    /// Local index of each unknown, in column order.
    unknowns: Vec<usize>,
}

impl FairSolver {
    /// Builds and factors `Δ^c x = 0` on `local` (continuity `c` in 1..=3).
    pub fn new(
        local: &LocalMesh,
        continuity: u8,
        weights: Weights,
        norm: Normalization,
    ) -> Result<FairSolver, FillError> {
        if !(1..=3).contains(&continuity) {
            return Err(FillError::solver(format!(
                "fairing continuity {continuity} is not 1, 2 or 3"
            )));
        }
        let n = local.positions.len();
        if local.free.len() != n {
            return Err(FillError::solver(
                "fairing: free flags do not match the vertices",
            ));
        }
        let op = build_operator(local, weights, norm);
        let mut col = vec![usize::MAX; n];
        let mut unknowns = Vec::new();
        for (v, &is_free) in local.free.iter().enumerate() {
            if is_free {
                col[v] = unknowns.len();
                unknowns.push(v);
            }
        }
        let m = unknowns.len();
        // row i of M·Δ^c (the outermost area factor dropped, which does not change
        // the solution): L M⁻¹ L … is symmetric, and negated for odd c it is
        // positive definite on the unknowns
        let rows = power_rows(&op, &unknowns, continuity)?;
        let sign = if continuity % 2 == 1 { -1.0 } else { 1.0 };
        let mut row_ptr: Vec<usize> = Vec::with_capacity(m + 1);
        let mut col_idx: Vec<usize> = Vec::with_capacity(rows.idx.len());
        let mut vals: Vec<f64> = Vec::with_capacity(rows.idx.len());
        let mut rhs = Mat::<f64>::zeros(m, 3);
        row_ptr.push(0);
        for row in 0..m {
            let mut r = [0.0; 3];
            for (u, a) in rows.row(row) {
                let a = sign * a;
                if local.free[u] {
                    // the unknowns are numbered in local order: the columns stay sorted
                    col_idx.push(col[u]);
                    vals.push(a);
                } else {
                    let p = local.positions[u];
                    r[0] -= a * p.x;
                    r[1] -= a * p.y;
                    r[2] -= a * p.z;
                }
            }
            for (c, val) in r.iter().enumerate() {
                rhs[(row, c)] = *val;
            }
            row_ptr.push(col_idx.len());
        }
        let symbolic =
            faer::sparse::SymbolicSparseRowMat::<usize>::new_checked(m, m, row_ptr, None, col_idx);
        let mat = faer::sparse::SparseRowMat::<usize, f64>::new(symbolic, vals)
            .to_col_major()
            .map_err(|e| FillError::solver(format!("fairing matrix: {e:?}")))?;
        let llt = if op.symmetric {
            mat.sp_cholesky(faer::Side::Lower).ok()
        } else {
            None
        };
        let factor = match llt {
            Some(l) => Factor::Llt(l),
            None => {
                // faer's sparse LU panics (instead of returning an error) on an exactly
                // zero pivot of a numerically singular matrix, which degenerate input
                // can produce (found by fuzzing): the panic is caught and the method
                // fails over.
                let lu = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| mat.sp_lu()))
                    .map_err(|_| {
                        FillError::solver(
                            "fairing factorisation failed: singular matrix (zero pivot)",
                        )
                    })?
                    .map_err(|e| {
                        FillError::solver(format!("fairing factorisation failed: {e:?}"))
                    })?;
                Factor::Lu(Box::new(lu))
            }
        };
        Ok(FairSolver {
            factor,
            rhs,
            unknowns,
        })
    }

    /// True when the system was factored by Cholesky (symmetric), false for LU.
    pub fn is_cholesky(&self) -> bool {
        matches!(self.factor, Factor::Llt(_))
    }

    /// Number of unknowns.
    pub fn len(&self) -> usize {
        self.unknowns.len()
    }

    /// True when there is nothing to solve.
    pub fn is_empty(&self) -> bool {
        self.unknowns.is_empty()
    }

    /// Local indices of the unknowns (the order of [`FairSolver::solve`]'s result).
    pub fn unknowns(&self) -> &[usize] {
        &self.unknowns
    }

    /// Solves for x, y, z with the one factorisation.
    pub fn solve(&self) -> Result<Vec<DVec3>, FillError> {
        if self.unknowns.is_empty() {
            return Ok(Vec::new());
        }
        let x = match &self.factor {
            Factor::Llt(f) => f.solve(self.rhs.as_ref()),
            Factor::Lu(f) => f.solve(self.rhs.as_ref()),
        };
        let out: Vec<DVec3> = (0..self.unknowns.len())
            .map(|i| DVec3::new(x[(i, 0)], x[(i, 1)], x[(i, 2)]))
            .collect();
        if out.iter().any(|p| !p.is_finite()) {
            return Err(FillError::solver(
                "fairing gave non-finite positions (singular system)",
            ));
        }
        Ok(out)
    }
}

/// Sparse rows over the local vertices, compressed: row `r` is
/// `idx[ptr[r]..ptr[r + 1]]` (sorted, no duplicates) with `val` alongside.
struct Rows {
    ptr: Vec<usize>,
    idx: Vec<u32>,
    val: Vec<f64>,
}

impl Rows {
    fn row(&self, r: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let span = self.ptr[r]..self.ptr[r + 1];
        self.idx[span.clone()]
            .iter()
            .zip(&self.val[span])
            .map(|(&j, &v)| (j as usize, v))
    }
}

/// A dense row being summed: values by local vertex and the vertices touched.
struct Scatter {
    val: Vec<f64>,
    seen: Vec<bool>,
    touched: Vec<u32>,
}

impl Scatter {
    fn new(n: usize) -> Scatter {
        Scatter {
            val: vec![0.0; n],
            seen: vec![false; n],
            touched: Vec::new(),
        }
    }

    fn add(&mut self, j: usize, a: f64) {
        if !self.seen[j] {
            self.seen[j] = true;
            self.touched.push(j as u32);
        }
        self.val[j] += a;
    }

    /// Appends the summed row to `out` (sorted) and clears.
    fn flush(&mut self, out: &mut Rows) {
        self.touched.sort_unstable();
        for &j in &self.touched {
            out.idx.push(j);
            out.val.push(self.val[j as usize]);
            self.val[j as usize] = 0.0;
            self.seen[j as usize] = false;
        }
        self.touched.clear();
        out.ptr.push(out.idx.len());
    }
}

/// `v`'s row of the unscaled Laplacian `L̃` (`w_vu` off the diagonal, `-W_v` on it), or
/// the error when `v` has no neighbours.
fn lap_row(op: &Operator, v: usize) -> Result<impl Iterator<Item = (usize, f64)> + '_, FillError> {
    if op.nbrs[v].is_empty() {
        return Err(FillError::solver(format!(
            "fairing: local vertex {v} has no neighbours"
        )));
    }
    Ok(op.nbrs[v]
        .iter()
        .map(|&(u, w)| (u as usize, w))
        .chain(std::iter::once((v, -op.sum[v]))))
}

/// The rows of `L̃ (S L̃)^(c-1)` (`S` the scaling) at the `unknowns`, over all local
/// vertices: the matrix `D = S L̃` is raised to the power `c - 1` row by row on the
/// vertices within `c - 1` rings of an unknown, and each unknown's row of `L̃` combines
/// those rows. The same sum as expanding `Δ^c` recursively, in `O(deg^2)` per row
/// instead of `O(deg^c)`.
fn power_rows(op: &Operator, unknowns: &[usize], continuity: u8) -> Result<Rows, FillError> {
    let n = op.nbrs.len();
    let mut scatter = Scatter::new(n);
    // the vertices within c - 1 rings of an unknown, ordered by ring (breadth
    // first), so that each power is needed on a prefix of `need`; ends[r]: the
    // count within r rings
    let depth = continuity.saturating_sub(1) as usize;
    let mut slot = vec![usize::MAX; n];
    let mut need: Vec<usize> = Vec::new();
    let mut ends = Vec::with_capacity(depth + 1);
    for &v in unknowns {
        if slot[v] == usize::MAX {
            slot[v] = need.len();
            need.push(v);
        }
    }
    ends.push(need.len());
    let mut from = 0;
    for _ in 0..depth {
        let to = need.len();
        for i in from..to {
            let v = need[i];
            for (u, _) in lap_row(op, v)? {
                if slot[u] == usize::MAX {
                    slot[u] = need.len();
                    need.push(u);
                }
            }
        }
        from = to;
        ends.push(need.len());
    }
    // power k (0 = the identity) at the first ends[depth + 1 - k] vertices of
    // `need`: within c - k rings of an unknown
    let mut power: Option<Rows> = None;
    for k in 1..=depth {
        let count = ends[depth + 1 - k];
        let mut next = Rows {
            ptr: Vec::with_capacity(count + 1),
            idx: Vec::new(),
            val: Vec::new(),
        };
        next.ptr.push(0);
        for &v in &need[..count] {
            let s = op.scale[v];
            for (u, w) in lap_row(op, v)? {
                match &power {
                    None => scatter.add(u, s * w),
                    Some(p) => {
                        for (t, b) in p.row(slot[u]) {
                            scatter.add(t, s * w * b);
                        }
                    }
                }
            }
            scatter.flush(&mut next);
        }
        power = Some(next);
    }
    let mut out = Rows {
        ptr: Vec::with_capacity(unknowns.len() + 1),
        idx: Vec::new(),
        val: Vec::new(),
    };
    out.ptr.push(0);
    for &v in unknowns {
        for (u, w) in lap_row(op, v)? {
            match &power {
                None => scatter.add(u, w),
                Some(p) => {
                    for (t, b) in p.row(slot[u]) {
                        scatter.add(t, w * b);
                    }
                }
            }
        }
        scatter.flush(&mut out);
    }
    Ok(out)
}

/// One-off: fairs `local` in place (moves only the free vertices).
pub fn fair_local(
    local: &mut LocalMesh,
    continuity: u8,
    weights: Weights,
) -> Result<(), FillError> {
    fair_local_with(local, continuity, weights, default_normalization(weights))
}

/// [`fair_local`] with the Laplacians scaled by `norm`.
pub fn fair_local_with(
    local: &mut LocalMesh,
    continuity: u8,
    weights: Weights,
    norm: Normalization,
) -> Result<(), FillError> {
    if continuity == 0 || !local.free.iter().any(|&f| f) {
        return Ok(());
    }
    let solver = FairSolver::new(local, continuity, weights, norm)?;
    let x = solver.solve()?;
    for (i, &v) in solver.unknowns().iter().enumerate() {
        local.positions[v] = x[i];
    }
    Ok(())
}

/// The patch joined with the mesh faces the operator needs (see the module docs).
/// Local vertex `i < k` is loop vertex `i`, `k + j` is new vertex `j`, then mesh
/// vertices. Only the new vertices are free.
pub fn local_from_patch(mesh: &Mesh, hole: &Hole, patch: &Patch, continuity: u8) -> LocalMesh {
    local_freed(mesh, hole, patch, 0, continuity).0
}

/// Fairs a patch: moves only `patch.new_vertices` (see the module docs).
pub fn fair_patch(
    mesh: &Mesh,
    hole: &Hole,
    patch: &mut Patch,
    opts: &Fair,
) -> Result<(), FillError> {
    fair_patch_energy(mesh, hole, patch, opts, FairEnergy::Fair)
}

/// The continuity and the scaling of `energy` under the `[fair]` keys `opts`.
pub fn energy_setup(energy: FairEnergy, opts: &Fair) -> (u8, Normalization) {
    match energy {
        FairEnergy::Fair => (opts.continuity, default_normalization(opts.weights)),
        FairEnergy::Umbrella => (2, Normalization::WeightSumSquared),
        FairEnergy::MinimumVariation => (3, default_normalization(opts.weights)),
    }
}

/// [`fair_patch`] with `energy`'s continuity and scaling (the `[fair]` weights).
pub fn fair_patch_energy(
    mesh: &Mesh,
    hole: &Hole,
    patch: &mut Patch,
    opts: &Fair,
    energy: FairEnergy,
) -> Result<(), FillError> {
    let (c, norm) = energy_setup(energy, opts);
    if c == 0 || patch.new_vertices.is_empty() {
        return Ok(());
    }
    let mut local = local_from_patch(mesh, hole, patch, c);
    fair_local_with(&mut local, c, opts.weights, norm)?;
    let k = hole.len();
    for (j, p) in patch.new_vertices.iter_mut().enumerate() {
        *p = local.positions[k + j];
    }
    Ok(())
}

/// The patch joined with the mesh around it, where the mesh vertices within `rings - 1`
/// rings of the loop (the loop is ring 0) are unknowns too (`rings = 0`: only the new
/// vertices, [`local_from_patch`]), with the faces the operator needs: those of the
/// mesh vertices within `rings + continuity - 2` rings (none when that is negative).
/// With the local index and the position of each freed mesh vertex. Local vertex
/// `i < k` is loop vertex `i`, `k + j` new vertex `j`, then mesh vertices.
pub fn local_freed(
    mesh: &Mesh,
    hole: &Hole,
    patch: &Patch,
    rings: usize,
    continuity: u8,
) -> (LocalMesh, Vec<(usize, DVec3)>) {
    let k = hole.len();
    let mut positions: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
    positions.extend_from_slice(&patch.new_vertices);
    let mut free = vec![rings > 0; k];
    free.resize(positions.len(), true);
    let mut freed: Vec<(usize, DVec3)> = if rings > 0 {
        (0..k).map(|i| (i, positions[i])).collect()
    } else {
        Vec::new()
    };
    let mut triangles = patch.triangles.clone();
    if rings + continuity as usize >= 2 {
        let mut map: HashMap<VertexId, u32> = HashMap::default();
        let mut depth: HashMap<VertexId, usize> = HashMap::default();
        for (i, &v) in hole.vertices.iter().enumerate() {
            map.insert(v, i as u32);
            depth.insert(v, 0);
        }
        let reach = rings + continuity as usize - 2;
        let mut ring: Vec<VertexId> = hole.vertices.clone();
        let mut centres = ring.clone();
        for d in 1..=reach {
            let mut next = Vec::new();
            for &v in &ring {
                for w in mesh.topo.neighbors(v) {
                    if let std::collections::hash_map::Entry::Vacant(e) = depth.entry(w) {
                        e.insert(d);
                        next.push(w);
                    }
                }
            }
            centres.extend_from_slice(&next);
            ring = next;
        }
        let mut faces = crate::fasthash::HashSet::default();
        for &v in &centres {
            faces.extend(mesh.topo.vertex_faces(v));
        }
        let mut faces: Vec<_> = faces.into_iter().collect();
        faces.sort_unstable();
        for f in faces {
            let t = mesh.topo.face(f).map(|v| {
                *map.entry(v).or_insert_with(|| {
                    let p = mesh.pos(v);
                    let unknown = depth.get(&v).is_some_and(|&d| d < rings);
                    positions.push(p);
                    free.push(unknown);
                    if unknown {
                        freed.push((positions.len() - 1, p));
                    }
                    (positions.len() - 1) as u32
                })
            });
            triangles.push(t);
        }
    }
    (
        LocalMesh {
            positions,
            triangles,
            free,
        },
        freed,
    )
}

/// How far fairing with `energy` moves the known surface around a hole: the patch and
/// the mesh within `rings - 1` rings of the loop are faired together ([`local_freed`]),
/// and the known vertices among them move from where they are by this mean distance.
/// An energy that puts the known surface back where it is continues it across the
/// hole best (`blend.energy = "validate"`).
pub fn freed_rings_error(
    mesh: &Mesh,
    hole: &Hole,
    patch: &Patch,
    opts: &Fair,
    energy: FairEnergy,
    rings: usize,
) -> Result<f64, FillError> {
    let (c, norm) = energy_setup(energy, opts);
    let (mut local, freed) = local_freed(mesh, hole, patch, rings.max(1), c.max(1));
    fair_local_with(&mut local, c, opts.weights, norm)?;
    let n = freed.len().max(1) as f64;
    Ok(freed
        .iter()
        .map(|&(i, p)| (local.positions[i] - p).length())
        .sum::<f64>()
        / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A regular grid over [0,n]^2 with heights from `f`, interior vertices free.
    fn grid(n: usize, f: impl Fn(f64, f64) -> f64) -> LocalMesh {
        let raw = crate::testutil::grid(n, 0.0, n as f64, f);
        let free = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| i > 1 && j > 1 && i + 2 <= n && j + 2 <= n))
            .collect();
        LocalMesh {
            positions: raw.positions,
            triangles: raw.faces,
            free,
        }
    }

    #[test]
    fn linear_function_is_reproduced_by_every_scheme() {
        // z = 0.3x - 0.2y + 1 is harmonic and biharmonic: every operator keeps it
        let f = |x: f64, y: f64| 0.3 * x - 0.2 * y + 1.0;
        for c in 1..=3u8 {
            for w in [Weights::Cotangent, Weights::Uniform, Weights::Fujiwara] {
                let mut m = grid(10, f);
                // start the unknowns away from the answer
                for (p, &fr) in m.positions.iter_mut().zip(&m.free) {
                    if fr {
                        p.z = 0.0;
                    }
                }
                fair_local(&mut m, c, w).unwrap();
                for p in &m.positions {
                    assert!((p.z - f(p.x, p.y)).abs() < 1e-9, "c={c} w={w:?} {p}");
                }
            }
        }
    }

    #[test]
    fn the_umbrella_scaling_reproduces_a_linear_function() {
        let f = |x: f64, y: f64| -0.4 * x + 0.25 * y + 2.0;
        for w in [Weights::Cotangent, Weights::Uniform, Weights::Fujiwara] {
            let mut m = grid(10, f);
            for (p, &fr) in m.positions.iter_mut().zip(&m.free) {
                if fr {
                    p.z = 5.0;
                }
            }
            fair_local_with(&mut m, 2, w, Normalization::WeightSumSquared).unwrap();
            for p in &m.positions {
                assert!((p.z - f(p.x, p.y)).abs() < 1e-9, "w={w:?} {p}");
            }
        }
    }

    #[test]
    fn freeing_rings_frees_the_loop_and_the_rings_inside_the_reach() {
        use crate::testutil::{fan, sheet, sheet_hole_at};
        // a 2 x 2 hole in the middle of a 10 x 10 sheet: the operator's rings stay off
        // the sheet's border (a border vertex's Laplacian is not complete)
        let (mesh, _) = Mesh::from_raw(&sheet(10, 0.0, &[(4, 4), (5, 4), (4, 5), (5, 5)]));
        let hole = Hole::new(
            0,
            &mesh,
            sheet_hole_at(&mesh, 0.0),
            &crate::policy::Policy::default(),
        );
        let patch = fan(8, DVec3::new(5.0, 5.0, 0.0));
        let (local, freed) = local_freed(&mesh, &hole, &patch, 2, 2);
        assert_eq!(local.free.len(), local.positions.len());
        // freed: the loop and its neighbours (ring 1), nothing else of the mesh
        let on_loop: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
        let mut ring1: Vec<VertexId> = Vec::new();
        for &v in &hole.vertices {
            for w in mesh.topo.neighbors(v) {
                if !hole.vertices.contains(&w) && !ring1.contains(&w) {
                    ring1.push(w);
                }
            }
        }
        assert_eq!(freed.len(), 8 + ring1.len());
        for &(i, p) in &freed {
            assert!(local.free[i] && local.positions[i] == p);
            assert!(
                on_loop.contains(&p) || ring1.iter().any(|&w| mesh.pos(w) == p),
                "{p}"
            );
        }
        assert!(local.free[8], "the new vertex");
        // every freed vertex's neighbours are there (its Laplacian is complete), and
        // the vertices beyond ring 1 are fixed
        for &w in &ring1 {
            for u in mesh.topo.neighbors(w) {
                let i = local.positions.iter().position(|&p| p == mesh.pos(u));
                let i = i.expect("neighbour of ring 1 in the local mesh");
                let near = hole.vertices.contains(&u) || ring1.contains(&u);
                assert_eq!(local.free[i], near, "{}", mesh.pos(u));
            }
        }
        // minimum variation reaches one ring further
        let (local3, freed3) = local_freed(&mesh, &hole, &patch, 2, 3);
        assert_eq!(freed3.len(), freed.len());
        assert!(local3.positions.len() > local.positions.len());
        // the sheet and the fan are flat: every fairing puts every freed vertex back
        for e in [
            FairEnergy::Fair,
            FairEnergy::Umbrella,
            FairEnergy::MinimumVariation,
        ] {
            let err = freed_rings_error(&mesh, &hole, &patch, &Fair::default(), e, 2).unwrap();
            assert!(err < 1e-9, "{e:?}: {err}");
        }
    }

    /// The rows by powers are those of the matrix product `L̃ (S L̃)^(c-1)`, computed
    /// densely here, on a grid moved off its regular shape (unequal weights and areas).
    #[test]
    fn power_rows_are_the_rows_of_the_matrix_product() {
        let mut local = grid(7, |x, y| 0.1 * (x * y).sin());
        for (i, p) in local.positions.iter_mut().enumerate() {
            p.x += 0.2 * ((i * 37 % 11) as f64 / 11.0 - 0.5);
            p.y += 0.2 * ((i * 53 % 13) as f64 / 13.0 - 0.5);
        }
        let n = local.positions.len();
        let unknowns: Vec<usize> = (0..n).filter(|&v| local.free[v]).collect();
        for norm in [Normalization::VoronoiArea, Normalization::WeightSumSquared] {
            let op = build_operator(&local, Weights::Cotangent, norm);
            let mut lap = vec![vec![0.0; n]; n];
            for (v, row) in lap.iter_mut().enumerate() {
                for &(u, w) in &op.nbrs[v] {
                    row[u as usize] += w;
                }
                row[v] -= op.sum[v];
            }
            let mul = |a: &Vec<Vec<f64>>, b: &Vec<Vec<f64>>| {
                let mut out = vec![vec![0.0; n]; n];
                for i in 0..n {
                    for k in 0..n {
                        if a[i][k] != 0.0 {
                            for j in 0..n {
                                out[i][j] += a[i][k] * b[k][j];
                            }
                        }
                    }
                }
                out
            };
            // D = S L̃, and the product L̃ D^(c-1)
            let d: Vec<Vec<f64>> = (0..n)
                .map(|i| lap[i].iter().map(|x| op.scale[i] * x).collect())
                .collect();
            for c in 1..=3u8 {
                let mut product = lap.clone();
                for _ in 1..c {
                    product = mul(&product, &d);
                }
                let rows = power_rows(&op, &unknowns, c).expect("rows");
                for (r, &v) in unknowns.iter().enumerate() {
                    let mut dense = vec![0.0; n];
                    for (u, a) in rows.row(r) {
                        dense[u] = a;
                    }
                    for u in 0..n {
                        let want = product[v][u];
                        assert!(
                            (dense[u] - want).abs() <= 1e-9 * (1.0 + want.abs()),
                            "c {c} {norm:?} row {v} col {u}: {} against {want}",
                            dense[u]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn quadratic_is_reproduced_by_the_bilaplacian() {
        // z = x^2 + y^2 has constant Laplacian, so Δ²z = 0 on a regular grid
        let f = |x: f64, y: f64| 0.01 * (x * x + y * y);
        let mut m = grid(12, f);
        for (p, &fr) in m.positions.iter_mut().zip(&m.free) {
            if fr {
                p.z = 0.0;
            }
        }
        fair_local(&mut m, 2, Weights::Uniform).unwrap();
        for p in &m.positions {
            assert!((p.z - f(p.x, p.y)).abs() < 1e-9, "{p}");
        }
    }

    #[test]
    fn degenerate_start_takes_the_lu_path_and_stays_exact() {
        // a free vertex starting on top of its neighbour makes its triangles degenerate:
        // it falls back to uniform weights, the system is no longer symmetric and is
        // solved by LU; the solution still satisfies z = f(x, y) exactly, because the
        // operator's rows sum to zero whatever the weights
        let f = |x: f64, y: f64| 0.3 * x - 0.2 * y + 1.0;
        for c in 1..=3u8 {
            let mut m = grid(10, f);
            let n = 10;
            let v = 5 * (n + 1) + 5;
            m.positions[v] = m.positions[v + 1];
            let s = FairSolver::new(&m, c, Weights::Cotangent, Normalization::VoronoiArea).unwrap();
            assert!(!s.is_cholesky());
            let x = s.solve().unwrap();
            for p in &x {
                assert!((p.z - f(p.x, p.y)).abs() < 1e-9, "c={c} {p}");
            }
            let m2 = grid(10, f);
            let s2 =
                FairSolver::new(&m2, c, Weights::Cotangent, Normalization::VoronoiArea).unwrap();
            assert!(s2.is_cholesky());
        }
    }

    #[test]
    fn bad_continuity_is_an_error() {
        let m = grid(6, |_, _| 0.0);
        assert!(FairSolver::new(&m, 4, Weights::Uniform, Normalization::None).is_err());
    }
}
