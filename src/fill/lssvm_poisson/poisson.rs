//! Step 4 (paper 003 §2.3, §3.4, eq. 16-19): the Poisson system for the patch, solved
//! in the least-squares sense with the loop and its outer ring fixed.

use super::model::cot_laplacian;
use super::*;

/// Labels of mesh vertices outside the patch in a [`Ring`] start here.
pub(super) const EXT: u32 = u32::MAX / 2;

/// The mesh around the loop, for the rows of the loop vertices: for each loop vertex its
/// mesh faces as label pairs (loop vertex `j` is `j`, any other mesh vertex `EXT + e`
/// with position `ext[e]`).
pub struct Ring {
    pub(super) ext: Vec<DVec3>,
    pub(super) fans: Vec<Vec<(u32, u32)>>,
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
    pub(super) lu: faer::sparse::linalg::solvers::Lu<usize, f64>,
    pub(super) n: usize,
    pub(super) k: usize,
    /// Rows: `(scale, unknown entries, fixed entries, own fixed label)`; the equation is
    /// `[x_own] − Σ w_ij x_j = −scale · δ`.
    pub(super) rows: Vec<Row>,
    pub(super) ext: Vec<DVec3>,
}

pub(super) struct Row {
    /// `2 A_i / Σ ω_ij`.
    pub(super) scale: f64,
    pub(super) unknown: Vec<(usize, f64)>,
    pub(super) fixed: Vec<(u32, f64)>,
    /// For a loop-vertex row, the loop vertex itself (fixed); `None` for a new vertex,
    /// whose own coefficient 1 is in `unknown`.
    pub(super) own: Option<u32>,
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
            return Err(FillError::solver(
                "the patch has no new vertex to solve for",
            ));
        }
        if ring.is_some_and(|r| r.fans.len() != k) {
            return Err(FillError::internal("ring does not match the loop"));
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
                return Err(FillError::internal("patch triangle index out of range"));
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
                return Err(FillError::solver(format!(
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
            .map_err(|e| FillError::solver(format!("Poisson matrix: {e:?}")))?;
        let lu = a
            .sp_lu()
            .map_err(|e| FillError::solver(format!("Poisson factorisation: {e:?}")))?;
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
            return Err(FillError::solver(
                "Poisson right-hand side has the wrong length",
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
            return Err(FillError::solver("Poisson solution is not finite"));
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
