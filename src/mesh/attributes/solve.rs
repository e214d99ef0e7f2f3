//! The harmonic solve that interpolates colours, scalars and texture coordinates
//! over a patch from its rim: a Dirichlet problem for the Laplace equation with
//! cotangent (negative ones clamped) or uniform weights, by Jacobi-preconditioned
//! conjugate gradients.

use super::Weights;
use crate::mesh::{Mesh, VertexId};

/// Solves the Laplace equation for `free` vertices with the values `fixed` gives
/// their other neighbours (Dirichlet), by Jacobi-preconditioned conjugate
/// gradients, `D` channels at once. A vertex no fixed value reaches gets zeros.
pub(super) fn solve<const D: usize>(
    mesh: &Mesh,
    free: &[VertexId],
    w: Weights,
    fixed: &dyn Fn(VertexId) -> Option<[f64; D]>,
) -> Vec<[f64; D]> {
    let n = free.len();
    if n == 0 {
        return Vec::new();
    }
    let mut local = crate::fasthash::HashMap::default();
    for (k, v) in free.iter().enumerate() {
        local.insert(*v, k);
    }
    // rows: off-diagonal (column, weight) among free vertices, diagonal, right side
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    let mut diag = vec![0.0; n];
    let mut rhs = vec![[0.0; D]; n];
    let mut reached = vec![false; n];
    for (k, &v) in free.iter().enumerate() {
        for f in mesh.topo.vertex_faces(v) {
            let vs = mesh.topo.face(f);
            let Some(c) = vs.iter().position(|&x| x == v) else {
                continue;
            };
            // the two edges of f at v: to the next and the previous corner, each
            // weighted by the cotangent of the angle opposite it in f (half)
            for (other, opp) in [
                (vs[(c + 1) % 3], vs[(c + 2) % 3]),
                (vs[(c + 2) % 3], vs[(c + 1) % 3]),
            ] {
                let wt = match w {
                    Weights::Uniform => 0.5,
                    Weights::Cotan => {
                        let (p, q, o) = (mesh.pos(v), mesh.pos(other), mesh.pos(opp));
                        let (a, b) = (p - o, q - o);
                        let s = a.cross(b).length();
                        if s > 0.0 {
                            (0.5 * a.dot(b) / s).max(0.0)
                        } else {
                            0.0
                        }
                    }
                } + 1e-9;
                diag[k] += wt;
                match local.get(&other) {
                    Some(&j) => rows[k].push((j, wt)),
                    None => {
                        if let Some(x) = fixed(other) {
                            reached[k] = true;
                            for d in 0..D {
                                rhs[k][d] += wt * x[d];
                            }
                        } else {
                            // a neighbour with no value: treat it as absent
                            diag[k] -= wt;
                        }
                    }
                }
            }
        }
    }
    // vertices no fixed value reaches (through free vertices) get zeros
    let mut stack: Vec<usize> = (0..n).filter(|&k| reached[k]).collect();
    while let Some(k) = stack.pop() {
        for &(j, _) in &rows[k] {
            if !reached[j] {
                reached[j] = true;
                stack.push(j);
            }
        }
    }
    let mut x = vec![[0.0; D]; n];
    for d in 0..D {
        let active = |k: usize| reached[k] && diag[k] > 0.0;
        let mul = |v: &[f64], out: &mut [f64]| {
            for k in 0..n {
                if !active(k) {
                    out[k] = 0.0;
                    continue;
                }
                let mut s = diag[k] * v[k];
                for &(j, wt) in &rows[k] {
                    if active(j) {
                        s -= wt * v[j];
                    }
                }
                out[k] = s;
            }
        };
        let b: Vec<f64> = (0..n)
            .map(|k| if active(k) { rhs[k][d] } else { 0.0 })
            .collect();
        // initial guess: the mean of the fixed values reached
        let mut xs = vec![0.0; n];
        let mut r = b.clone();
        let mut ax = vec![0.0; n];
        mul(&xs, &mut ax);
        for k in 0..n {
            r[k] -= ax[k];
        }
        let pre = |k: usize| if active(k) { 1.0 / diag[k] } else { 0.0 };
        let mut z: Vec<f64> = (0..n).map(|k| r[k] * pre(k)).collect();
        let mut p = z.clone();
        let mut rz: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
        let bnorm = b.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-300);
        let mut ap = vec![0.0; n];
        for _ in 0..(4 * n + 100) {
            let rn = r.iter().map(|v| v * v).sum::<f64>().sqrt();
            if rn <= 1e-13 * bnorm {
                break;
            }
            mul(&p, &mut ap);
            let pap: f64 = p.iter().zip(&ap).map(|(a, b)| a * b).sum();
            if pap <= 0.0 || !pap.is_finite() {
                break;
            }
            let alpha = rz / pap;
            for k in 0..n {
                xs[k] += alpha * p[k];
                r[k] -= alpha * ap[k];
            }
            for k in 0..n {
                z[k] = r[k] * pre(k);
            }
            let rz2: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
            let beta = rz2 / rz;
            rz = rz2;
            for k in 0..n {
                p[k] = z[k] + beta * p[k];
            }
        }
        for k in 0..n {
            x[k][d] = if xs[k].is_finite() { xs[k] } else { 0.0 };
        }
    }
    x
}
