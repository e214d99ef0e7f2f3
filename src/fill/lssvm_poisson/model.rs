//! Steps 2 and 3 (paper 003 §3.3, §2.2 eq. 9-15): the training set of cotangent
//! Laplacians around the hole and the LS-SVM regression of the Laplacian.

use super::*;

/// The RBF width: `kernel_width` times the loop's radius `perimeter / 2π`.
pub fn kernel_sigma(opts: &crate::policy::Lssvm, hole: &Hole) -> f64 {
    opts.kernel_width * hole.perimeter / std::f64::consts::TAU
}

// ---------------------------------------------------------------------------
// 1. plain advancing front

/// Cotangent weights `ω_ij` and barycentric area of vertex `i` from its triangles
/// (each as `(i, x, y)` positions), clamped as in the module doc. Returns the
/// mean-curvature normal `δ_i`, `Σ ω_ij` and `A_i`, or `None` for a degenerate star.
pub(super) fn cot_laplacian(
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
    pub(super) xs: Vec<DVec3>,
    pub(super) alpha: Vec<DVec3>,
    pub(super) bias: DVec3,
    pub(super) inv2s2: f64,
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
            return Err(FillError::solver(
                "LS-SVM needs matching, non-empty samples",
            ));
        }
        if !(gamma > 0.0 && gamma.is_finite() && sigma > 0.0 && sigma.is_finite()) {
            return Err(FillError::solver(
                "LS-SVM needs positive gamma and kernel width",
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
            FillError::solver(format!(
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
            .ok_or_else(|| FillError::solver("LS-SVM system is singular"))
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
