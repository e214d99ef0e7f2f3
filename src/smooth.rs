//! Taubin lambda/mu smoothing (ALGORITHMS A4; paper 000 §4 step 1; G. Taubin, "A
//! signal processing approach to fair surface design", SIGGRAPH 1995, §4-§5).
//!
//! Each iteration is Taubin's pair of Laplacian steps: `x += lambda · L(x)` (the
//! Gaussian, shrinking step, `lambda > 0`) then `x += mu · L(x)` (the un-shrinking
//! step, `mu < -lambda`), where `L(x)_i = Σ_j w_ij (x_j - x_i) / Σ_j w_ij` is the
//! normalised umbrella operator. Both steps are simultaneous (every vertex reads
//! the positions from before the step). The policy is expected to have validated
//! `0 < lambda < 1` and `mu < -lambda` (pass band `k_pb = 1/lambda + 1/mu > 0`); this
//! module only refuses non-finite factors (it then does nothing).
//!
//! Readings of what the paper leaves open:
//! - Weights are computed once per iteration from the current positions and used
//!   for both steps, so each iteration is exactly Taubin's `(I + mu K)(I + lambda K)`
//!   with that iteration's `K`. Uniform weights are Taubin's choice; the options are
//!   cotangent weights `(cot α + cot β) / 2`, each edge weight clamped to
//!   `[0, cot 1°]`, falling back to uniform weights for a vertex with a degenerate
//!   incident face or no positive weight; and Fujiwara weights `1 / |x_j - x_i|`
//!   (Taubin §5), falling back to uniform for a vertex with a zero-length edge.
//! - Scope `rings`: a vertex moves when it is at most `rings` edges from a boundary
//!   vertex (ALGORITHMS A4: "N rings around each hole"; the open border of a scan is
//!   a boundary too). Vertices outside the scope are never written.
//! - Boundary vertices either stay (`fixed`) or move by the same two steps using
//!   only their two neighbours along the boundary loop (`boundary_neighbors`), which
//!   smooths the loop as a curve and keeps it from drifting into the hole. On a curve
//!   the cotangent weight is undefined: it uses uniform weights there; Fujiwara uses
//!   inverse lengths.
//! - Isolated vertices (no faces) never move.
//! - A step that would give a vertex a non-finite position leaves that vertex where
//!   it is for that step.

use crate::mesh::{Mesh, VertexId};
use crate::policy::{BoundaryRule, Smooth, SmoothScope, Weights};
use crate::report::SmoothingReport;
use glam::DVec3;
use std::collections::VecDeque;

/// Largest cotangent edge weight (cot 1°).
const COT_MAX: f64 = 57.289_961_630_759_42;

/// How a vertex moves.
#[derive(Clone, Copy, Debug)]
enum Kind {
    /// By its whole one-ring.
    Interior,
    /// By its two neighbours on the boundary loop.
    Boundary(VertexId, VertexId),
}

/// The vertices that move, and how.
fn plan(mesh: &Mesh, opts: &Smooth) -> Vec<(VertexId, Kind)> {
    let topo = &mesh.topo;
    let n = mesh.num_vertices().min(topo.num_vertices());
    let in_scope: Vec<bool> = match opts.scope {
        SmoothScope::Whole => vec![true; n],
        SmoothScope::Rings => {
            let mut depth: Vec<Option<usize>> = vec![None; n];
            let mut queue = VecDeque::new();
            for (i, d) in depth.iter_mut().enumerate() {
                if topo.is_boundary_vertex(VertexId::from_idx(i)) {
                    *d = Some(0);
                    queue.push_back(VertexId::from_idx(i));
                }
            }
            while let Some(v) = queue.pop_front() {
                let dv = depth[v.idx()].unwrap_or(0);
                if dv >= opts.rings {
                    continue;
                }
                for w in topo.neighbors(v) {
                    if w.idx() < n && depth[w.idx()].is_none() {
                        depth[w.idx()] = Some(dv + 1);
                        queue.push_back(w);
                    }
                }
            }
            depth.iter().map(Option::is_some).collect()
        }
    };
    let mut out = Vec::new();
    for (i, &scoped) in in_scope.iter().enumerate() {
        let v = VertexId::from_idx(i);
        let Some(anchor) = topo.anchor(v) else {
            continue; // isolated
        };
        if !scoped {
            continue;
        }
        if topo.twin(anchor).is_none() {
            // boundary vertex: the anchor leaves it along the boundary
            if opts.boundary == BoundaryRule::Fixed {
                continue;
            }
            let next = topo.to(anchor);
            match topo.incoming_boundary(v) {
                Some(h) => out.push((v, Kind::Boundary(topo.from(h), next))),
                None => continue,
            }
        } else {
            out.push((v, Kind::Interior));
        }
    }
    out
}

/// Flat (neighbour, weight) lists of the planned vertices, normalised to sum 1.
struct Stencils {
    start: Vec<usize>,
    entries: Vec<(VertexId, f64)>,
}

impl Stencils {
    fn compute(mesh: &Mesh, plan: &[(VertexId, Kind)], weights: Weights) -> Stencils {
        let mut start = Vec::with_capacity(plan.len() + 1);
        let mut entries: Vec<(VertexId, f64)> = Vec::with_capacity(plan.len() * 7);
        let mut local: Vec<(VertexId, f64)> = Vec::with_capacity(16);
        for &(v, kind) in plan {
            start.push(entries.len());
            local.clear();
            let p = mesh.pos(v);
            match kind {
                Kind::Boundary(a, b) => {
                    for w in [a, b] {
                        let wt = match weights {
                            Weights::Fujiwara => inverse_length(p, mesh.pos(w)),
                            _ => Some(1.0),
                        };
                        local.push((w, wt.unwrap_or(0.0)));
                    }
                    if local.iter().any(|e| e.1 <= 0.0) {
                        local.iter_mut().for_each(|e| e.1 = 1.0);
                    }
                }
                Kind::Interior => {
                    let ok = match weights {
                        Weights::Uniform => false,
                        Weights::Cotangent => cotangent(mesh, v, &mut local),
                        Weights::Fujiwara => {
                            let mut ok = true;
                            for_each_neighbor(mesh, v, |w| match inverse_length(p, mesh.pos(w)) {
                                Some(x) => local.push((w, x)),
                                None => ok = false,
                            });
                            ok
                        }
                    };
                    if !ok {
                        local.clear();
                        for_each_neighbor(mesh, v, |w| local.push((w, 1.0)));
                    }
                }
            }
            let sum: f64 = local.iter().map(|e| e.1).sum();
            if sum > 0.0 && sum.is_finite() {
                entries.extend(local.iter().map(|&(w, x)| (w, x / sum)));
            }
        }
        start.push(entries.len());
        Stencils { start, entries }
    }

    /// `L(x)` of planned vertex `i`.
    fn laplacian(&self, i: usize, x: &[DVec3], v: VertexId) -> DVec3 {
        let p = x[v.idx()];
        self.entries[self.start[i]..self.start[i + 1]]
            .iter()
            .map(|&(w, wt)| (x[w.idx()] - p) * wt)
            .sum()
    }
}

/// Calls `f` on every neighbour of interior vertex `v` once (no allocation).
fn for_each_neighbor(mesh: &Mesh, v: VertexId, mut f: impl FnMut(VertexId)) {
    for h in mesh.topo.outgoing(v) {
        f(mesh.topo.to(h));
    }
}

/// `1 / |b - a|`, `None` for a zero or non-finite length.
fn inverse_length(a: DVec3, b: DVec3) -> Option<f64> {
    let l = (b - a).length();
    (l > 0.0 && l.is_finite()).then(|| 1.0 / l)
}

/// Cotangent weights of interior vertex `v` into `out`; `false` when a face is
/// degenerate or no weight is positive (the caller falls back to uniform).
fn cotangent(mesh: &Mesh, v: VertexId, out: &mut Vec<(VertexId, f64)>) -> bool {
    let p = mesh.pos(v);
    for f in mesh.topo.vertex_faces(v) {
        let vs = mesh.topo.face(f);
        let Some(c) = vs.iter().position(|&u| u == v) else {
            return false;
        };
        let (j, k) = (vs[(c + 1) % 3], vs[(c + 2) % 3]);
        let (pj, pk) = (mesh.pos(j), mesh.pos(k));
        let l2 = (pj - p)
            .length_squared()
            .max((pk - p).length_squared())
            .max((pk - pj).length_squared());
        let area2 = (pj - p).cross(pk - p).length();
        if area2.is_nan() || area2 <= 1e-12 * l2 {
            return false;
        }
        // edge (v, j) is opposite the corner at k, edge (v, k) the corner at j
        for (w, corner, a, b) in [(j, pk, p, pj), (k, pj, p, pk)] {
            let u = a - corner;
            let t = b - corner;
            let cot = u.dot(t) / u.cross(t).length();
            let half = 0.5 * cot;
            match out.iter_mut().find(|e| e.0 == w) {
                Some(e) => e.1 += half,
                None => out.push((w, half)),
            }
        }
    }
    for e in out.iter_mut() {
        e.1 = e.1.clamp(0.0, COT_MAX);
    }
    out.iter().any(|e| e.1 > 0.0)
}

/// Smooths the mesh in place (see the module comment) and reports what moved.
pub fn smooth(mesh: &mut Mesh, opts: &Smooth) -> SmoothingReport {
    let mut rep = SmoothingReport::default();
    if !opts.lambda.is_finite()
        || !opts.mu.is_finite()
        || mesh.positions.len() != mesh.topo.num_vertices()
    {
        return rep;
    }
    let plan = plan(mesh, opts);
    if plan.is_empty() {
        rep.iterations = opts.iterations;
        return rep;
    }
    let original: Vec<DVec3> = plan.iter().map(|&(v, _)| mesh.pos(v)).collect();
    let mut delta = vec![DVec3::ZERO; plan.len()];
    // uniform weights do not depend on the positions: one stencil for all iterations
    let mut st = Stencils::compute(mesh, &plan, opts.weights);
    for it in 0..opts.iterations {
        if it > 0 && opts.weights != Weights::Uniform {
            st = Stencils::compute(mesh, &plan, opts.weights);
        }
        for factor in [opts.lambda, opts.mu] {
            for (i, &(v, _)) in plan.iter().enumerate() {
                delta[i] = st.laplacian(i, &mesh.positions, v) * factor;
            }
            for (i, &(v, _)) in plan.iter().enumerate() {
                let q = mesh.positions[v.idx()] + delta[i];
                if q.is_finite() {
                    mesh.positions[v.idx()] = q;
                }
            }
        }
    }
    rep.iterations = opts.iterations;
    for (i, &(v, _)) in plan.iter().enumerate() {
        let q = mesh.pos(v);
        if q != original[i] {
            rep.vertices_moved += 1;
            rep.max_displacement = rep.max_displacement.max((q - original[i]).length());
        }
    }
    rep
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{cells_removed, grid, unit_grid};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn volume(m: &Mesh) -> f64 {
        m.topo
            .faces()
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| m.pos(v));
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Mean distance to the unit sphere (the oracle).
    fn sphere_error(m: &Mesh) -> f64 {
        m.positions
            .iter()
            .map(|p| (p.length() - 1.0).abs())
            .sum::<f64>()
            / m.positions.len() as f64
    }

    /// A unit icosphere (level 3, 642 vertices) with radial noise of up to ±3 %.
    fn noisy_sphere() -> Mesh {
        let mut raw = crate::testutil::icosphere(3, 1.0);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for p in &mut raw.positions {
            *p *= 1.0 + rng.random_range(-0.03..0.03);
        }
        Mesh::from_raw(&raw).0
    }

    fn opts(weights: Weights, mu: f64) -> Smooth {
        Smooth {
            enabled: true,
            iterations: 10,
            lambda: 0.33,
            mu,
            weights,
            scope: SmoothScope::Whole,
            rings: 3,
            boundary: BoundaryRule::Fixed,
        }
    }

    #[test]
    fn taubin_keeps_volume_and_removes_noise() {
        let exact = 4.0 / 3.0 * std::f64::consts::PI;
        for w in [Weights::Uniform, Weights::Cotangent, Weights::Fujiwara] {
            let mut m = noisy_sphere();
            let v0 = volume(&m);
            let e0 = sphere_error(&m);
            let rep = smooth(&mut m, &opts(w, -0.34));
            let v1 = volume(&m);
            let e1 = sphere_error(&m);
            assert_eq!(rep.iterations, 10);
            assert_eq!(rep.vertices_moved, m.num_vertices());
            assert!(rep.max_displacement > 0.0 && rep.max_displacement < 0.1);
            // bound: the volume changes by less than 1 % (measured: +0.26 to +0.29 %) ...
            assert!(((v1 - v0) / v0).abs() < 0.01, "{w:?}: volume {v0} -> {v1}");
            // ... and the noise (mean distance to the true sphere) at least halves
            assert!(e1 < 0.5 * e0, "{w:?}: error {e0} -> {e1}");
            // the polyhedron's volume stays near the sphere's (inscribed: slightly less)
            assert!((v1 - exact).abs() / exact < 0.03, "{w:?}: {v1} vs {exact}");
        }
    }

    #[test]
    fn plain_laplacian_shrinks() {
        let mut m = noisy_sphere();
        let v0 = volume(&m);
        smooth(&mut m, &opts(Weights::Uniform, 0.0));
        let v1 = volume(&m);
        // measured: -10.7 %
        assert!(v1 < 0.95 * v0, "plain Laplacian: volume {v0} -> {v1}");
    }

    /// A flat n x n grid (z = 0) with z noise on every vertex, and the cell (c, c)
    /// removed to make a hole.
    fn noisy_grid(n: usize, hole: Option<usize>) -> Mesh {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let raw = grid(n, 0.0, n as f64, |_, _| rng.random_range(-0.1..0.1));
        let mut raw = cells_removed(raw, |i, j| hole.is_some_and(|c| (i, j) == (c, c)));
        // an isolated vertex
        raw.positions.push(DVec3::new(100.0, 100.0, 100.0));
        Mesh::from_raw(&raw).0
    }

    #[test]
    fn fixed_boundary_and_isolated_vertices_stay() {
        let mut m = noisy_grid(12, Some(6));
        let before = m.positions.clone();
        let rep = smooth(&mut m, &opts(Weights::Cotangent, -0.34));
        let mut interior = 0;
        for (i, (p, q)) in before.iter().zip(&m.positions).enumerate() {
            let v = VertexId::from_idx(i);
            if m.topo.anchor(v).is_none() || m.topo.is_boundary_vertex(v) {
                assert_eq!(
                    p.to_array().map(f64::to_bits),
                    q.to_array().map(f64::to_bits)
                );
            } else {
                interior += 1;
            }
        }
        assert_eq!(rep.vertices_moved, interior);
        // oracle: the plane z = 0; the interior noise drops
        let rms = |ps: &[DVec3]| {
            let zs: Vec<f64> = (0..ps.len())
                .filter(|&i| {
                    let v = VertexId::from_idx(i);
                    m.topo.anchor(v).is_some() && !m.topo.is_boundary_vertex(v)
                })
                .map(|i| ps[i].z)
                .collect();
            (zs.iter().map(|z| z * z).sum::<f64>() / zs.len() as f64).sqrt()
        };
        // white noise has much energy at middle frequencies, which Taubin's filter
        // passes slowly ((1 - 0.33 k)(1 + 0.34 k) = 0.9 at k = 1): bound 0.6
        assert!(rms(&m.positions) < 0.6 * rms(&before));
    }

    /// A flat 16 x 16 grid with the 8 x 2 cells (4..12, 7..9) removed.
    fn slot_grid() -> Mesh {
        let raw = cells_removed(unit_grid(16), |i, j| {
            (4..12).contains(&i) && (7..9).contains(&j)
        });
        Mesh::from_raw(&raw).0
    }

    #[test]
    fn boundary_vertices_follow_only_their_loop() {
        let mut o = opts(Weights::Uniform, -0.34);
        o.boundary = BoundaryRule::BoundaryNeighbors;
        o.iterations = 1;
        // a spike on the slot's lower side, pushed into the hole in-plane
        let spike = 7 * 17 + 8;
        let mut m = slot_grid();
        assert!(m.topo.is_boundary_vertex(VertexId::from_idx(spike)));
        m.positions[spike].y += 0.3;
        // the same mesh with its interior vertices moved about
        let mut m2 = m.clone();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for (i, p) in m2.positions.iter_mut().enumerate() {
            if !m.topo.is_boundary_vertex(VertexId::from_idx(i)) {
                *p += DVec3::new(
                    rng.random_range(-0.2..0.2),
                    rng.random_range(-0.2..0.2),
                    rng.random_range(-0.2..0.2),
                );
            }
        }
        smooth(&mut m, &o);
        smooth(&mut m2, &o);
        // boundary vertices read only boundary vertices: the same result, bit for bit
        for i in 0..m.num_vertices() {
            if m.topo.is_boundary_vertex(VertexId::from_idx(i)) {
                assert_eq!(m.positions[i], m2.positions[i]);
            }
        }
        // the spike shrinks as the two steps predict on a straight loop stretch:
        // lambda step: spike s1 = h (1 - lambda), its neighbours n1 = h lambda / 2;
        // mu step: s2 = s1 + mu (n1 - s1)
        let h = 0.3;
        let s1 = h * (1.0 - o.lambda);
        let n1 = h * o.lambda / 2.0;
        let s2 = s1 + o.mu * (n1 - s1);
        let dev = m.positions[spike].y - 7.0;
        assert!((dev - s2).abs() < 1e-12 && dev < h, "{dev} vs {s2}");
        // and the plane is kept exactly (every vertex and neighbour has z = 0)
        assert!(m.positions.iter().all(|p| p.z == 0.0));
        // a straight stretch of the loop two vertices or more from the spike and the
        // corners (one iteration reaches two vertices along the loop) stays put
        assert_eq!(m.positions[9 * 17 + 8], DVec3::new(8.0, 9.0, 0.0));
        assert_ne!(m.positions[7 * 17 + 5], DVec3::new(5.0, 7.0, 0.0));
    }

    #[test]
    fn rings_scope_leaves_far_vertices_bit_identical() {
        let n = 20;
        let mut m = noisy_grid(n, Some(10));
        let before = m.positions.clone();
        let mut o = opts(Weights::Fujiwara, -0.34);
        o.scope = SmoothScope::Rings;
        o.rings = 2;
        let rep = smooth(&mut m, &o);
        assert!(rep.vertices_moved > 0);
        // grid distance (in rings) of a grid vertex from the boundary: the outer
        // border and the loop of cell (10, 10); the grid's diagonals make rings
        // Chebyshev-like along one diagonal only, so use a safe margin of 3
        let mut moved_near = 0;
        for j in 0..=n {
            for i in 0..=n {
                let k = j * (n + 1) + i;
                let border = i.min(j).min(n - i).min(n - j);
                let di = (i as i64 - 10).abs().min((i as i64 - 11).abs());
                let dj = (j as i64 - 10).abs().min((j as i64 - 11).abs());
                let hole = di.max(dj) as usize;
                if border.min(hole) > 4 {
                    assert_eq!(
                        before[k].to_array().map(f64::to_bits),
                        m.positions[k].to_array().map(f64::to_bits),
                        "vertex ({i}, {j}) moved"
                    );
                } else if before[k] != m.positions[k] {
                    moved_near += 1;
                }
            }
        }
        assert_eq!(moved_near, rep.vertices_moved);
        // the isolated vertex stays too
        let last = m.num_vertices() - 1;
        assert_eq!(m.positions[last], before[last]);
    }

    #[test]
    fn non_finite_factors_do_nothing() {
        let mut m = noisy_sphere();
        let before = m.positions.clone();
        let rep = smooth(&mut m, &opts(Weights::Uniform, f64::NAN));
        assert_eq!(rep, SmoothingReport::default());
        assert_eq!(m.positions, before);
    }
}
