//! Feature-based hole filling: LS-SVM regression of the Laplacian + Poisson solve.
//!
//! Paper 003 (Xu, Li, Tan 2013, "Feature Based Hole Filling Algorithm on Triangular
//! Mesh"); ALGORITHMS.md section E. The method runs in four steps.
//!
//! 1. **Initial patch** (§3.2): a plain advancing front. The paper's six steps, with the
//!    angle rules of paper 002 §5.3 without its corrections: at the front vertex with the
//!    smallest angle θ (measured on the hole side about the vertex normal), θ ≤ 75°
//!    closes it with one triangle, θ ≤ 135° adds one vertex on the bisector, larger θ two
//!    vertices on the trisectors. New vertices lie "on the plane determined by e_i and
//!    e_{i+1}" (the rotation axis is the normal of the two front edges; when they are
//!    collinear, the vertex normal), at the hole's mean boundary edge length `L`.
//!    Step 4 (merging) reads: a new vertex closer than `merge_distance · L` to a vertex
//!    of the same front loop is replaced by it, and the loop splits in two. The paper is
//!    silent on overlap; here a step is refused when a new edge crosses a front edge or a
//!    new triangle covers a front vertex (both tested in the tangent plane of the vertex,
//!    within `4L`), when a new edge duplicates a patch edge or an existing mesh edge
//!    between loop vertices, when a new triangle faces away from the vertex normal or has
//!    an angle below 2°. A refused step tries the next vertex by angle, then a plain ear;
//!    after `k² + 100k + 1000` steps (k = loop length; five times the triangle count of
//!    the largest disk with that perimeter) the method fails.
//!    The front is then relaxed with [`RELAX_ITERATIONS`] umbrella steps (factor
//!    [`RELAX_FACTOR`]) of the new vertices, so that its Laplacians are meaningful.
//! 2. **Training set** (§3.3): the vertex rings `SV_1 … SV_K` (`K = rings`) around the
//!    loop (`SV_0`, the loop itself, is left out: its one-ring is incomplete), without
//!    vertices on any boundary. Each sample is the vertex position and its cotangent
//!    Laplacian, read as the mean-curvature normal of eq. 4:
//!    `δ_i = 1/(2 A_i) Σ_j (cot α_ij + cot β_ij)(v_j − v_i)` with `A_i` the barycentric
//!    area (a third of the incident triangle areas; the paper's Voronoi area is less
//!    robust on obtuse triangles). Each weight is clamped to `[0, 1e3]`; when a vertex's
//!    weights sum to nothing, uniform weights `2·cot 60°` (their value on a regular mesh)
//!    stand in. This area-normalised δ is used rather than the normalised-weight δ of
//!    eq. 1–2 so that it does not depend on the patch's edge length. When more than
//!    [`MAX_SAMPLES`] vertices qualify, the rings nearest the hole are kept (the last ring
//!    kept partly, by distance to the loop's centroid).
//! 3. **LS-SVM** (§2.2, eq. 9–15): one regression per axis `d`, output `δ_d`. The paper
//!    feeds one coordinate `V_id` as the input; here the input is the 3-D vertex position
//!    (a single coordinate cannot tell apart points of a surface). RBF kernel
//!    `K(x, y) = exp(−|x − y|² / (2σ²))`, `σ = kernel_width · L`. Eq. 14 is solved through
//!    its Schur complement: `H = Ω + I/γ` is symmetric positive definite, so one dense
//!    Cholesky factorisation (faer) solves `H η = 1` and `H ν_d = y_d`; then
//!    `b_d = 1ᵀν_d / 1ᵀη`, `a_d = ν_d − b_d η`, and `f_d(x) = Σ a_i K(x, x_i) + b_d` (eq. 15).
//! 4. **Poisson** (§2.3, §3.4, eq. 18–19): at every new vertex `i`, with the cotangent
//!    weights `ω_ij` and area `A_i` of the current patch geometry,
//!    `Σ_j ω_ij (x_j − x_i) = 2 A_i f(x_i)`; rows are divided by `Σ_j ω_ij` (eq. 2). The
//!    loop vertices are Dirichlet values; the mesh beyond them (the outer ring) is fixed
//!    and enters through the training set. The system (one per axis, one matrix) is
//!    factored once with faer's sparse LU. Predict-then-solve runs `iterations` times,
//!    recomputing weights and areas on the new geometry. A non-finite result fails.
//!
//! Connectivity is the front's throughout; only positions of new vertices change.

use super::{geom, FillContext, FillError, Patch};
use crate::mesh::{Mesh, VertexId};
use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use glam::{DQuat, DVec3};
use std::collections::{BTreeMap, HashSet};

/// Umbrella relaxation steps applied to the initial front before training.
pub const RELAX_ITERATIONS: usize = 5;
/// Factor of each umbrella step.
pub const RELAX_FACTOR: f64 = 0.5;
/// Largest training set (the dense LS-SVM system is `(l+1)²`).
pub const MAX_SAMPLES: usize = 1500;
/// Smallest angle of a front triangle, in degrees.
const FRONT_MIN_ANGLE_DEG: f64 = 2.0;
/// Uniform fallback weight: `cot α + cot β` on a regular triangulation.
const UNIFORM_WEIGHT: f64 = 1.154_700_538_379_251_5;

/// Fills the hole: plain front, LS-SVM prediction of the Laplacian, Poisson solve.
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    let opts = &ctx.policy.lssvm;
    opts.validate()
        .map_err(|(k, m)| FillError::Failed(format!("policy key `{k}`: {m}")))?;
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::Failed(format!("a loop of {k} vertices cannot be filled")));
    }
    let l = ctx.hole.mean_edge_length;
    if !(l.is_finite() && l > 0.0) {
        return Err(FillError::Failed("the loop has no length".into()));
    }
    let mut patch = initial_front(ctx.mesh, &ctx.hole.vertices, l, opts.merge_distance, &ctx.deadline)?;
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
    let model = LssvmModel::fit(&xs, &ys, opts.gamma, opts.kernel_width * l)?;
    ctx.deadline.check()?;
    for _ in 0..opts.iterations {
        let pos: Vec<DVec3> = boundary.iter().chain(patch.new_vertices.iter()).copied().collect();
        let target: Vec<DVec3> = patch.new_vertices.iter().map(|&x| model.predict(x)).collect();
        ctx.deadline.check()?;
        patch.new_vertices = solve_poisson(&pos, k, &patch.triangles, &target, l)?;
        ctx.deadline.check()?;
    }
    Ok(patch)
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
    deadline: &super::Deadline,
) -> Result<Patch, FillError> {
    let k = hole.len();
    if k < 3 {
        return Err(FillError::Failed(format!("a loop of {k} vertices cannot be filled")));
    }
    if !(edge.is_finite() && edge > 0.0) {
        return Err(FillError::Failed("front edge length is not positive".into()));
    }
    let mut f = Front::new(mesh, hole, edge, merge_distance);
    let cap = k * k + 100 * k + 1000;
    let mut steps = 0usize;
    let mut loops: Vec<Vec<u32>> = vec![(0..k as u32).collect()];
    while let Some(lp) = loops.pop() {
        deadline.check()?;
        steps += 1;
        if steps > cap {
            return Err(FillError::Failed(format!("advancing front did not close in {cap} steps")));
        }
        if lp.len() < 3 {
            continue;
        }
        if lp.len() == 3 {
            f.add_triangles(&[[lp[0], lp[1], lp[2]]]);
            continue;
        }
        let mut next = f.step(&lp)?;
        loops.append(&mut next);
    }
    let new_vertices = f.pos[k..].to_vec();
    if new_vertices.iter().any(|p| !p.is_finite()) {
        return Err(FillError::Failed("front produced a non-finite vertex".into()));
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
    edge: f64,
    merge: f64,
}

fn ukey(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

impl Front {
    fn new(mesh: &Mesh, hole: &[VertexId], edge: f64, merge_distance: f64) -> Front {
        let k = hole.len();
        let pos: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
        let nacc = hole
            .iter()
            .map(|&v| mesh.topo.vertex_faces(v).map(|f| mesh.face_normal_raw(f)).sum::<DVec3>())
            .collect();
        let mut index = std::collections::HashMap::new();
        for (i, &v) in hole.iter().enumerate() {
            index.insert(v, i as u32);
        }
        let mut edges = HashSet::new();
        for (i, &v) in hole.iter().enumerate() {
            for w in mesh.topo.neighbors(v) {
                if let Some(&j) = index.get(&w) {
                    edges.insert(ukey(i as u32, j));
                }
            }
            edges.insert(ukey(i as u32, ((i + 1) % k) as u32));
        }
        Front {
            pos,
            nacc,
            tris: Vec::new(),
            edges,
            edge,
            merge: merge_distance * edge,
        }
    }

    fn normal(&self, i: u32) -> DVec3 {
        self.nacc[i as usize].normalize_or_zero()
    }

    fn add_triangles(&mut self, tris: &[[u32; 3]]) {
        for t in tris {
            let n = geom::tri_normal_raw(self.pos[t[0] as usize], self.pos[t[1] as usize], self.pos[t[2] as usize]);
            for c in 0..3 {
                self.nacc[t[c] as usize] += n;
                self.edges.insert(ukey(t[c], t[(c + 1) % 3]));
            }
            self.tris.push(*t);
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
        let cl = c.length();
        let axis = if cl > 1e-6 {
            if c.dot(n) >= 0.0 {
                c / cl
            } else {
                -c / cl
            }
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
        Err(FillError::Failed(format!(
            "advancing front is stuck on a loop of {m} vertices"
        )))
    }

    /// Tries the step at `lp[j]` with spokes at the rotations `rots` of `u` about `axis`
    /// (ordered from the previous vertex's side to the next's).
    fn try_step(&mut self, lp: &[u32], j: usize, axis: DVec3, u: DVec3, rots: &[f64]) -> Option<Vec<Vec<u32>>> {
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
        let is_front_edge = |a: u32, b: u32| -> bool {
            (0..m).any(|t| lp[t] == a && lp[(t + 1) % m] == b)
        };
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
            let nt = geom::tri_normal_raw(x, y, z);
            if !(nt.dot(n) > 0.0) {
                return None;
            }
            let angs = geom::angles(x, y, z);
            if angs.iter().any(|&a| !(a >= FRONT_MIN_ANGLE_DEG.to_radians())) {
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
        let radius = 4.0 * self.edge;
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

fn orient2(a: (f64, f64), b: (f64, f64), c: (f64, f64)) -> f64 {
    (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
}

/// Proper crossing of two segments (touching at an end does not count).
fn segments_cross(a: (f64, f64), b: (f64, f64), c: (f64, f64), d: (f64, f64)) -> bool {
    let d1 = orient2(a, b, c);
    let d2 = orient2(a, b, d);
    let d3 = orient2(c, d, a);
    let d4 = orient2(c, d, b);
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
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
fn cot_laplacian(p: DVec3, fan: &[(DVec3, DVec3, u32, u32)]) -> Option<(DVec3, BTreeMap<u32, f64>, f64)> {
    let mut w: BTreeMap<u32, f64> = BTreeMap::new();
    let mut area = 0.0;
    let mut at: BTreeMap<u32, DVec3> = BTreeMap::new();
    for &(x, y, ix, iy) in fan {
        // cot at x faces edge p-y; cot at y faces edge p-x
        *w.entry(iy).or_insert(0.0) += geom::cot_at(x, y, p);
        *w.entry(ix).or_insert(0.0) += geom::cot_at(y, p, x);
        area += geom::tri_area(p, x, y) / 3.0;
        at.insert(ix, x);
        at.insert(iy, y);
    }
    if !(area > 0.0) || !area.is_finite() {
        return None;
    }
    let mut sum = 0.0;
    for v in w.values_mut() {
        *v = if v.is_finite() { v.clamp(0.0, 1e3) } else { 0.0 };
        sum += *v;
    }
    if !(sum > 1e-12) {
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
    let mut ring_of: std::collections::HashMap<VertexId, usize> = std::collections::HashMap::new();
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
    let centroid = geom::centroid(&hole.iter().map(|&v| mesh.pos(v)).collect::<Vec<_>>());
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
            xs.push(p);
            ys.push(d);
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
    pub fn fit(xs: &[DVec3], ys: &[DVec3], gamma: f64, sigma: f64) -> Result<LssvmModel, FillError> {
        let l = xs.len();
        if l == 0 || ys.len() != l {
            return Err(FillError::Failed("LS-SVM needs matching, non-empty samples".into()));
        }
        if !(gamma > 0.0 && gamma.is_finite() && sigma > 0.0 && sigma.is_finite()) {
            return Err(FillError::Failed("LS-SVM needs positive gamma and kernel width".into()));
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
        let llt = h
            .llt(Side::Lower)
            .map_err(|e| FillError::Failed(format!("LS-SVM kernel matrix is not positive definite: {e:?}")))?;
        let rhs = Mat::<f64>::from_fn(l, 4, |i, c| match c {
            0 => 1.0,
            1 => ys[i].x,
            2 => ys[i].y,
            _ => ys[i].z,
        });
        let sol = llt.solve(&rhs);
        let s_eta: f64 = (0..l).map(|i| sol[(i, 0)]).sum();
        if !(s_eta.abs() > 0.0) || !s_eta.is_finite() {
            return Err(FillError::Failed("LS-SVM system is singular".into()));
        }
        let mut bias = [0.0; 3];
        for (d, b) in bias.iter_mut().enumerate() {
            let s: f64 = (0..l).map(|i| sol[(i, d + 1)]).sum();
            *b = s / s_eta;
        }
        let bias = DVec3::from_array(bias);
        let alpha: Vec<DVec3> = (0..l)
            .map(|i| {
                let eta = sol[(i, 0)];
                DVec3::new(sol[(i, 1)], sol[(i, 2)], sol[(i, 3)]) - bias * eta
            })
            .collect();
        if !bias.is_finite() || alpha.iter().any(|a| !a.is_finite()) {
            return Err(FillError::Failed("LS-SVM solution is not finite".into()));
        }
        Ok(LssvmModel {
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

/// The factored Poisson system of a patch: rows of the new vertices, loop vertices as
/// Dirichlet values. Factor once, solve for any target Laplacian field.
pub struct PoissonSolver {
    lu: faer::sparse::linalg::solvers::Lu<usize, f64>,
    /// Per new vertex: `2 A_i / Σ ω_ij` (scales the target Laplacian).
    scale: Vec<f64>,
    /// Per new vertex: `Σ_{j fixed} w_ij x_j` (the Dirichlet part of the right side).
    fixed: Vec<DVec3>,
}

impl PoissonSolver {
    /// Builds and factors the system on the geometry `pos` (loop first, `k` of them).
    pub fn new(pos: &[DVec3], k: usize, triangles: &[[u32; 3]], edge: f64) -> Result<PoissonSolver, FillError> {
        let n = pos.len().saturating_sub(k);
        if n == 0 {
            return Err(FillError::Failed("the patch has no new vertex to solve for".into()));
        }
        let mut fans: Vec<Vec<(DVec3, DVec3, u32, u32)>> = vec![Vec::new(); n];
        for t in triangles {
            if t.iter().any(|&i| i as usize >= pos.len()) {
                return Err(FillError::Failed("patch triangle index out of range".into()));
            }
            for c in 0..3 {
                let v = t[c] as usize;
                if v >= k {
                    let (a, b) = (t[(c + 1) % 3], t[(c + 2) % 3]);
                    fans[v - k].push((pos[a as usize], pos[b as usize], a, b));
                }
            }
        }
        let mut trip: Vec<Triplet<usize, usize, f64>> = Vec::new();
        let mut scale = Vec::with_capacity(n);
        let mut fixed = Vec::with_capacity(n);
        for (i, fan) in fans.iter().enumerate() {
            let p = pos[k + i];
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
            if !(sum > 0.0) || !s.is_finite() {
                return Err(FillError::Failed(format!("new vertex {i} has no neighbours")));
            }
            trip.push(Triplet::new(i, i, 1.0));
            let mut fx = DVec3::ZERO;
            for (&j, &wj) in &w {
                let wj = wj / sum;
                let j = j as usize;
                if j < k {
                    fx += wj * pos[j];
                } else {
                    trip.push(Triplet::new(i, j - k, -wj));
                }
            }
            scale.push(s);
            fixed.push(fx);
        }
        let a = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &trip)
            .map_err(|e| FillError::Failed(format!("Poisson matrix: {e:?}")))?;
        let lu = a
            .sp_lu()
            .map_err(|e| FillError::Failed(format!("Poisson factorisation: {e:?}")))?;
        Ok(PoissonSolver { lu, scale, fixed })
    }

    /// Positions of the new vertices whose Laplacians are `target` (one per new vertex).
    pub fn solve(&self, target: &[DVec3]) -> Result<Vec<DVec3>, FillError> {
        let n = self.scale.len();
        if target.len() != n {
            return Err(FillError::Failed("target Laplacian has the wrong length".into()));
        }
        // x_i - Σ_unknown w_ij x_j = Σ_fixed w_ij x_j - (2A_i/Σω) δ_i
        let rhs = Mat::<f64>::from_fn(n, 3, |i, d| {
            let v = self.fixed[i] - self.scale[i] * target[i];
            v[d]
        });
        let x = self.lu.solve(&rhs);
        let out: Vec<DVec3> = (0..n).map(|i| DVec3::new(x[(i, 0)], x[(i, 1)], x[(i, 2)])).collect();
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
) -> Result<Vec<DVec3>, FillError> {
    PoissonSolver::new(pos, k, triangles, edge)?.solve(target)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::{check_degenerate, check_topology, patch_positions};
    use crate::fill::{apply_patch, Deadline, Hole};
    use crate::io::RawMesh;
    use crate::policy::{Checks, Policy};
    use rand::{Rng, SeedableRng};
    use std::collections::HashMap;

    /// Builds a mesh from a soup, removing every face that touches a vertex for which
    /// `cut` holds; returns the mesh and the hole loop nearest `centre`.
    fn cut_mesh(pos: &[DVec3], faces: &[[u32; 3]], cut: impl Fn(DVec3) -> bool, centre: DVec3) -> (Mesh, Vec<VertexId>) {
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
                let ca = geom::centroid(&a.iter().map(|&v| mesh.pos(v)).collect::<Vec<_>>());
                let cb = geom::centroid(&b.iter().map(|&v| mesh.pos(v)).collect::<Vec<_>>());
                (ca - centre).length().total_cmp(&(cb - centre).length())
            })
            .unwrap();
        let mut seen = HashSet::new();
        assert!(lp.iter().all(|v| seen.insert(*v)), "test hole must be a simple loop");
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
        let t = (1.0 + 5f64.sqrt()) / 2.0;
        let mut pos: Vec<DVec3> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
        .collect();
        let mut faces: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdiv {
            let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
            let mut nf = Vec::with_capacity(faces.len() * 4);
            for f in &faces {
                let mut m = [0u32; 3];
                for c in 0..3 {
                    let (a, b) = (f[c], f[(c + 1) % 3]);
                    let key = (a.min(b), a.max(b));
                    m[c] = *mid.entry(key).or_insert_with(|| {
                        pos.push(((pos[a as usize] + pos[b as usize]) * 0.5).normalize());
                        (pos.len() - 1) as u32
                    });
                }
                nf.push([f[0], m[0], m[2]]);
                nf.push([f[1], m[1], m[0]]);
                nf.push([f[2], m[2], m[1]]);
                nf.push([m[0], m[1], m[2]]);
            }
            faces = nf;
        }
        (pos.into_iter().map(|p| p * r).collect(), faces)
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
        let hole = Hole::new(0, mesh, lp.to_vec(), policy);
        let ctx = FillContext {
            mesh,
            hole: &hole,
            policy,
            deadline: Deadline::none(),
        };
        let patch = fill(&ctx).unwrap();
        let front = initial_front(mesh, lp, hole.mean_edge_length, policy.lssvm.merge_distance, &Deadline::none()).unwrap();
        assert_eq!(front.triangles, patch.triangles);
        // the patch passes the checks and applies to a valid mesh
        check_topology(mesh, lp, &patch).unwrap();
        let pos = patch_positions(mesh, lp, &patch);
        check_degenerate(&pos, &patch, &Checks::default()).unwrap();
        let mut m2 = mesh.clone();
        apply_patch(&mut m2, &hole, &patch).unwrap();
        m2.validate().unwrap();
        Run { patch, front, hole }
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
        let e = mean_max(r.patch.new_vertices.iter().map(|p| (p.length() - 1.0).abs() / l));
        let e0 = mean_max(r.front.new_vertices.iter().map(|p| (p.length() - 1.0).abs() / l));
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
        assert!(max < 0.1 && mean < 0.05);
        assert!(mean < 0.5 * mean0);
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
        assert!(max < 0.2 && mean < 0.1);
        assert!(mean < 0.5 * mean0);
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
        assert!(max < 0.2 && mean < 0.1);
        assert!(mean < 0.5 * mean0);
    }

    #[test]
    fn noisy_sphere_still_closes() {
        let (mut mesh, lp) = sphere_case(4, 0.3);
        let l0 = Hole::new(0, &mesh, lp.clone(), &Policy::default()).mean_edge_length;
        let sigma = 0.05 * l0;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
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
                // Box-Muller
                let u1: f64 = rng.random::<f64>().max(1e-300);
                let u2: f64 = rng.random();
                *x = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
            }
            mesh.positions[v.idx()] += DVec3::from_array(g) * sigma;
        }
        let r = run(&mesh, &lp, &Policy::default());
        let ((mean, max), (mean0, _)) = sphere_errors(&r);
        eprintln!("noisy sphere err mean {mean:.4} max {max:.4} (front {mean0:.4}) in edge lengths");
        assert!(max < 0.3 && mean < 0.15);
    }

    #[test]
    fn same_input_same_bits() {
        let (mesh, lp) = sphere_case(4, 0.3);
        let a = run(&mesh, &lp, &Policy::default()).patch;
        let b = run(&mesh, &lp, &Policy::default()).patch;
        assert_eq!(a.triangles, b.triangles);
        let bits = |p: &Patch| -> Vec<u64> {
            p.new_vertices.iter().flat_map(|v| v.to_array().map(f64::to_bits)).collect()
        };
        assert_eq!(bits(&a), bits(&b));
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
        for p in [DVec3::new(0.0, 0.0, 0.0), DVec3::new(1.0, -1.5, 0.0), DVec3::new(3.2, 0.4, 0.0)] {
            let e = (m.predict(p) - f(p)).length();
            assert!(e < 0.05 * f(p).length().max(1.0), "at {p}: {e}");
        }
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
        };
        assert!(matches!(fill(&ctx), Err(FillError::Failed(_))));
    }
}
