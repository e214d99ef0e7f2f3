//! Steps 3–5 of HPDE: segmentation test, correspondences, section planes, circular
//! arcs and the differential-evolution search (paper 000 §4.2–§4.4, §4.8).

use crate::fill::kit::{Deadline, FillContext, FillError};
use crate::mesh::{Mesh, VertexId};
use glam::{DVec2, DVec3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// The paper's section plane (eq. 11) is used while its normal makes more than 20
/// degrees with the mean vertex normal of the pair; otherwise the plane would nearly
/// be tangent to the surface and the normal section is used.
const NORMAL_SECTION_COS: f64 = 0.9397; // cos 20 degrees

/// Tangent–chord angles are clamped to this, so both arcs are graphs over the chord.
const MAX_ARC_ANGLE: f64 = 85.0 * PI / 180.0;

/// A plane through `center` with unit `normal`.
#[derive(Clone, Copy, Debug)]
pub struct Plane {
    pub center: DVec3,
    pub normal: DVec3,
}

/// The result of a positive segmentation test (eq. 8): `PS2 = [i0, j0)`, `PS1` the
/// rest of the loop.
#[derive(Clone, Debug)]
pub struct Segmentation {
    pub i0: usize,
    pub j0: usize,
    /// Fitted plane of PS1.
    pub first: Plane,
    /// Fitted plane of PS2.
    pub second: Plane,
    /// Dihedral angle of the two planes (radians; π for one flat plane).
    pub dihedral: f64,
}

impl Segmentation {
    /// True when base point `i` belongs to PS2 = `[i0, j0)`.
    pub fn in_second(&self, i: usize) -> bool {
        (self.i0..self.j0).contains(&i)
    }
}

/// A predicted point and the pair of base points whose section plane it lies in.
#[derive(Clone, Copy, Debug)]
pub struct Predicted {
    pub pos: DVec3,
    pub pair: (usize, usize),
    /// Abscissa along the chord, as a fraction of its length.
    pub frac: f64,
}

// ----- PCA ---------------------------------------------------------------------------

/// Moments of a point set: count, sum, and the six sums of products.
#[derive(Clone, Copy, Debug, Default)]
struct Moments {
    n: f64,
    s: DVec3,
    // xx, yy, zz, xy, xz, yz
    q: [f64; 6],
}

impl Moments {
    fn of(p: DVec3) -> Moments {
        Moments {
            n: 1.0,
            s: p,
            q: [
                p.x * p.x,
                p.y * p.y,
                p.z * p.z,
                p.x * p.y,
                p.x * p.z,
                p.y * p.z,
            ],
        }
    }
    fn add(&self, o: &Moments) -> Moments {
        let mut q = self.q;
        for (a, b) in q.iter_mut().zip(o.q.iter()) {
            *a += b;
        }
        Moments {
            n: self.n + o.n,
            s: self.s + o.s,
            q,
        }
    }
    fn sub(&self, o: &Moments) -> Moments {
        let mut q = self.q;
        for (a, b) in q.iter_mut().zip(o.q.iter()) {
            *a -= b;
        }
        Moments {
            n: self.n - o.n,
            s: self.s - o.s,
            q,
        }
    }
    /// Covariance matrix (divided by the count).
    fn covariance(&self) -> [[f64; 3]; 3] {
        let n = self.n.max(1.0);
        let m = self.s / n;
        let xx = self.q[0] / n - m.x * m.x;
        let yy = self.q[1] / n - m.y * m.y;
        let zz = self.q[2] / n - m.z * m.z;
        let xy = self.q[3] / n - m.x * m.y;
        let xz = self.q[4] / n - m.x * m.z;
        let yz = self.q[5] / n - m.y * m.z;
        [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
    }
}

/// Eigenvalues (ascending) of a symmetric 3x3 matrix, closed form.
pub(crate) fn sym3_eigenvalues(a: &[[f64; 3]; 3]) -> [f64; 3] {
    let p1 = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    let p2 = (a[0][0] - q).powi(2) + (a[1][1] - q).powi(2) + (a[2][2] - q).powi(2) + 2.0 * p1;
    if p2 <= 1e-300 {
        return [q, q, q];
    }
    let p = (p2 / 6.0).sqrt();
    let b = |i: usize, j: usize| (a[i][j] - if i == j { q } else { 0.0 }) / p;
    let det = b(0, 0) * (b(1, 1) * b(2, 2) - b(1, 2) * b(2, 1))
        - b(0, 1) * (b(1, 0) * b(2, 2) - b(1, 2) * b(2, 0))
        + b(0, 2) * (b(1, 0) * b(2, 1) - b(1, 1) * b(2, 0));
    let r = (det / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let e1 = q + 2.0 * p * phi.cos();
    let e3 = q + 2.0 * p * (phi + 2.0 * PI / 3.0).cos();
    let e2 = 3.0 * q - e1 - e3;
    [e3, e2, e1]
}

/// Unit eigenvector of the smallest eigenvalue of a symmetric 3x3 matrix (Jacobi).
#[allow(clippy::needless_range_loop)]
pub(crate) fn smallest_eigenvector(a: &[[f64; 3]; 3]) -> DVec3 {
    let mut m = *a;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..64 {
        let off = m[0][1].abs() + m[0][2].abs() + m[1][2].abs();
        let scale = m[0][0].abs() + m[1][1].abs() + m[2][2].abs();
        if off <= 1e-18 * scale.max(1e-300) {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            if m[p][q].abs() <= 1e-300 {
                continue;
            }
            let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // m <- J^T m J
            for row in m.iter_mut() {
                let (mp, mq) = (row[p], row[q]);
                row[p] = c * mp - s * mq;
                row[q] = s * mp + c * mq;
            }
            for j in 0..3 {
                let (mp, mq) = (m[p][j], m[q][j]);
                m[p][j] = c * mp - s * mq;
                m[q][j] = s * mp + c * mq;
            }
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let i = (0..3)
        .min_by(|&x, &y| m[x][x].total_cmp(&m[y][y]))
        .unwrap_or(0);
    DVec3::new(v[0][i], v[1][i], v[2][i]).normalize_or_zero()
}

/// PCA plane of points, normal oriented along `orient` (when not zero).
pub fn fit_plane(pts: &[DVec3], orient: DVec3) -> Plane {
    let mut mo = Moments::default();
    let c = pts.iter().copied().sum::<DVec3>() / pts.len().max(1) as f64;
    for &p in pts {
        mo = mo.add(&Moments::of(p - c));
    }
    let mut n = smallest_eigenvector(&mo.covariance());
    if n == DVec3::ZERO {
        n = DVec3::Z;
    }
    if n.dot(orient) < 0.0 {
        n = -n;
    }
    Plane {
        center: c,
        normal: n,
    }
}

// ----- step 3: segmentation ------------------------------------------------------------

/// The segmentation test (eq. 8): the split of the loop into two consecutive arcs,
/// each of at least `max(3, n/4)` points, minimising the larger of their smallest PCA
/// eigenvalues, with the dihedral angle of the two fitted planes. `None` when a plane
/// is not well defined (middle eigenvalue below 4 times the smallest) or the planes
/// are parallel. The hole is segmented when the dihedral angle is below `Ac`.
pub fn segmentation(bp: &[DVec3], normals: &[DVec3]) -> Option<Segmentation> {
    let n = bp.len();
    let min_len = (n / 4).max(3);
    if n < 2 * min_len {
        return None;
    }
    let c = bp.iter().copied().sum::<DVec3>() / n as f64;
    let mut pre = Vec::with_capacity(2 * n + 1);
    pre.push(Moments::default());
    for t in 0..2 * n {
        let m = pre[t].add(&Moments::of(bp[t % n] - c));
        pre.push(m);
    }
    let arc = |start: usize, len: usize| pre[start + len].sub(&pre[start]);
    let mut best: Option<(f64, usize, usize)> = None;
    for i in 0..n {
        for j in (i + min_len)..n {
            let len2 = j - i;
            let len1 = n - len2;
            if len1 < min_len {
                break;
            }
            let l2 = sym3_eigenvalues(&arc(i, len2).covariance())[0];
            let l1 = sym3_eigenvalues(&arc(j, len1).covariance())[0];
            let v = l1.max(l2);
            if best.is_none_or(|b| v < b.0) {
                best = Some((v, i, j));
            }
        }
    }
    let (_, i0, j0) = best?;
    let ps2: Vec<usize> = (i0..j0).collect();
    let ps1: Vec<usize> = (j0..n).chain(0..i0).collect();
    let plane = |idx: &[usize]| {
        let pts: Vec<DVec3> = idx.iter().map(|&i| bp[i]).collect();
        let orient: DVec3 = idx.iter().map(|&i| normals[i]).sum();
        let pl = fit_plane(&pts, orient);
        let mut mo = Moments::default();
        for p in &pts {
            mo = mo.add(&Moments::of(*p - pl.center));
        }
        let ev = sym3_eigenvalues(&mo.covariance());
        (pl, ev[1] >= 4.0 * ev[0].max(0.0) && ev[1] > 0.0)
    };
    let (first, ok1) = plane(&ps1);
    let (second, ok2) = plane(&ps2);
    if !(ok1 && ok2) {
        return None;
    }
    let dihedral = PI - first.normal.dot(second.normal).clamp(-1.0, 1.0).acos();
    // the two planes must intersect in a usable line
    if first.normal.cross(second.normal).length() > 1e-6 {
        Some(Segmentation {
            i0,
            j0,
            first,
            second,
            dihedral,
        })
    } else {
        None
    }
}

// ----- step 4: correspondences ---------------------------------------------------------

/// The chain of pairs `(a, (s − a) mod n)`, ordered from one end of the loop to the
/// other; a point paired with itself is left out.
pub fn chain(n: usize, s: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    if n < 2 {
        return out;
    }
    let c = s.div_ceil(2) as i64;
    let s = s as i64;
    let n64 = n as i64;
    for i in 0..n64 {
        let diff = 2 * c - s + 2 * i;
        if diff >= n64 {
            break;
        }
        if diff == 0 {
            continue;
        }
        let a = (c + i).rem_euclid(n64) as usize;
        let b = (s - c - i).rem_euclid(n64) as usize;
        out.push((a, b));
    }
    out
}

/// Eq. 10: the rotation `sp` minimising the summed pair distances; returns the pair
/// sum `s = 2·sp − 1 (mod n)` for [`chain`].
pub fn best_pairing(bp: &[DVec3]) -> usize {
    let n = bp.len();
    let mut best: Option<(f64, usize)> = None;
    for sp in 0..n {
        let s = 2 * sp + n - 1;
        let d: f64 = chain(n, s)
            .iter()
            .map(|&(a, b)| (bp[a] - bp[b]).length())
            .sum();
        if best.is_none_or(|b| d < b.0) {
            best = Some((d, s));
        }
    }
    best.map(|b| b.1).unwrap_or(0)
}

/// The Ic rule: the line of the pair must meet the boundary at each end at an acute
/// angle of at least `ic`. The paper's base points lie inside boundary edges; ours are
/// the boundary vertices, so the boundary direction at one is the central difference
/// of its two neighbours.
fn pair_ok(bp: &[DVec3], a: usize, b: usize, ic: f64) -> bool {
    let n = bp.len();
    let Some(dir) = (bp[b] - bp[a]).try_normalize() else {
        return false;
    };
    let cos_max = ic.cos();
    for &e in &[a, b] {
        let Some(t) = (bp[(e + 1) % n] - bp[(e + n - 1) % n]).try_normalize() else {
            return false;
        };
        if dir.dot(t).abs() > cos_max {
            return false;
        }
    }
    true
}

// ----- step 5: prediction ----------------------------------------------------------------

/// Predicts the points of every kept pair of the chain (eqs. 11–16).
pub fn predict(
    ctx: &FillContext,
    bp: &[DVec3],
    normals: &[DVec3],
    chain: &[(usize, usize)],
    edge_len: f64,
    rng: &mut ChaCha8Rng,
) -> Result<Vec<Predicted>, FillError> {
    let opts = &ctx.policy.hpde;
    let ic = opts.ic_deg.to_radians();
    let keep: Vec<bool> = chain.iter().map(|&(a, b)| pair_ok(bp, a, b, ic)).collect();
    let max_len = chain
        .iter()
        .zip(&keep)
        .filter(|(_, &k)| k)
        .map(|(&(a, b), _)| (bp[a] - bp[b]).length())
        .fold(0.0f64, f64::max);
    let mut out = Vec::new();
    if max_len <= 0.0 {
        return Ok(out);
    }
    let h = opts.spacing * edge_len;
    // eq. 15 with EdgeLen -> spacing * EdgeLen
    let big_m = (max_len / h).floor() + 1.0;
    let mid = |t: usize| {
        let (a, b) = chain[t];
        (bp[a] + bp[b]) * 0.5
    };
    for (t, &(a, b)) in chain.iter().enumerate() {
        if !keep[t] {
            continue;
        }
        ctx.deadline.check()?;
        let (p1, p2) = (bp[a], bp[b]);
        let lv = p1 - p2;
        let len = lv.length();
        if len <= 0.0 {
            continue;
        }
        // eq. 11: section plane normal
        let d = if chain.len() < 2 {
            DVec3::ZERO
        } else if t == 0 {
            mid(0) - mid(1)
        } else if t + 1 == chain.len() {
            mid(t - 1) - mid(t)
        } else {
            mid(t - 1) - mid(t + 1)
        };
        // N = lv x (lv x d) = -|lv|^2 d_perp (d_perp: d without its component along lv)
        let e1 = (p2 - p1) / len;
        let nbar = lv.cross(d);
        let paper = lv.cross(nbar).try_normalize();
        // the normal section: the plane through the chord and the mean vertex normal
        let up = normals[a] + normals[b];
        let up_perp = (up - e1 * up.dot(e1)).try_normalize();
        let normal_section = up_perp.and_then(|u| e1.cross(u).try_normalize());
        let nv = match (paper, up_perp) {
            // the paper's plane, unless it nearly contains the chord's tangent plane
            // (chain ends, where the mids move along the surface normal)
            (Some(pn), Some(u)) if pn.dot(u).abs() < NORMAL_SECTION_COS => pn,
            (Some(pn), None) => pn,
            _ => normal_section.unwrap_or_else(|| lv.any_orthonormal_vector()),
        };
        let e2 = nv.cross(e1).normalize();
        // end tangents from the ring triangles
        let ap1 = ring_point(ctx.mesh, ctx.hole.vertices[a], p1, nv, e1);
        let ap2 = ring_point(ctx.mesh, ctx.hole.vertices[b], p2, nv, -e1);
        let tv1 = match ap1 {
            Some(x) => p1 - x,
            None => tangent_fallback(e1, normals[a], nv),
        };
        let tv2 = match ap2 {
            Some(x) => x - p2,
            None => tangent_fallback(e1, normals[b], nv),
        };
        let to2 = |v: DVec3| DVec2::new(v.dot(e1), v.dot(e2));
        let mut ta = to2(tv1).to_angle();
        let mut tb = -to2(tv2).to_angle();
        if opts.arcs_through_ring {
            // the arc through AP1, P1 and P2: its tangent-chord angle at P1 is the
            // secant's minus the angle AP1 subtends at P2 (exterior angle theorem)
            let q2 = DVec2::new(len, 0.0);
            if let Some(x) = ap1 {
                ta -= signed_angle(-q2, to2(x - p1) - q2);
            }
            if let Some(x) = ap2 {
                tb += signed_angle(q2, to2(x - p1));
            }
        }
        let ta = clamp_angle(ta);
        let tb = clamp_angle(tb);
        let m = ((len / max_len * big_m).floor() + 1.0) as usize;
        let (xs, lo, hi) = bounds(ta, tb, len, m);
        let ys = de_search(&xs, &lo, &hi, len, ctx, rng, &ctx.deadline)?;
        for (x, y) in xs.iter().zip(ys.iter()) {
            out.push(Predicted {
                pos: p1 + e1 * *x + e2 * *y,
                pair: (a, b),
                frac: *x / len,
            });
        }
    }
    Ok(out)
}

fn clamp_angle(a: f64) -> f64 {
    if a.is_finite() {
        a.clamp(-MAX_ARC_ANGLE, MAX_ARC_ANGLE)
    } else {
        0.0
    }
}

/// The paper's `AP`: where the section plane (through `p`, normal `n`) crosses the far
/// edge of a ring triangle of boundary vertex `v`, the crossing whose direction from
/// `p` is most opposite to `toward` (the unit chord direction); `None` when the plane
/// misses the ring or every crossing lies towards the hole.
fn ring_point(mesh: &Mesh, v: VertexId, p: DVec3, n: DVec3, toward: DVec3) -> Option<DVec3> {
    let mut best: Option<(f64, DVec3)> = None;
    for f in mesh.topo.vertex_faces(v) {
        let c = mesh.topo.face(f);
        let Some(ci) = c.iter().position(|&x| x == v) else {
            continue;
        };
        let a = mesh.pos(c[(ci + 1) % 3]);
        let b = mesh.pos(c[(ci + 2) % 3]);
        let da = n.dot(a - p);
        let db = n.dot(b - p);
        let mut cands = [None, None];
        if da == 0.0 && db == 0.0 {
            cands = [Some(a), Some(b)];
        } else if (da <= 0.0 && db >= 0.0) || (da >= 0.0 && db <= 0.0) {
            let t = da / (da - db);
            cands[0] = Some(a + (b - a) * t);
        }
        for x in cands.into_iter().flatten() {
            let Some(dir) = (x - p).try_normalize() else {
                continue;
            };
            let score = dir.dot(toward);
            if best.is_none_or(|b| score < b.0) {
                best = Some((score, x));
            }
        }
    }
    match best {
        Some((score, x)) if score < 0.5 => Some(x),
        _ => None,
    }
}

/// Without a ring crossing: the chord direction `e1` within the vertex's tangent
/// plane (normal `vn`) and the section plane (normal `n`).
fn tangent_fallback(e1: DVec3, vn: DVec3, n: DVec3) -> DVec3 {
    let t = e1 - vn * e1.dot(vn);
    let t = t - n * t.dot(n);
    t.try_normalize().unwrap_or(e1)
}

/// Signed angle from `u` to `w` (radians).
fn signed_angle(u: DVec2, w: DVec2) -> f64 {
    u.perp_dot(w).atan2(u.dot(w))
}

/// Point at fraction `f` along the circular arc from (0,0) to (len,0) whose
/// tangent–chord angle is `theta` (signed; 0 is the chord itself).
pub(crate) fn arc_point(theta: f64, len: f64, f: f64) -> DVec2 {
    if theta.abs() < 1e-9 {
        return DVec2::new(f * len, 0.0);
    }
    let th = theta.abs();
    let r = len / (2.0 * th.sin());
    let c = DVec2::new(len / 2.0, -(len / 2.0) / th.tan());
    let a = PI / 2.0 + th - 2.0 * th * f;
    let p = c + DVec2::new(a.cos(), a.sin()) * r;
    DVec2::new(p.x, p.y * theta.signum())
}

/// Height of that arc above abscissa `x` in `[0, len]`.
pub(crate) fn arc_y(theta: f64, len: f64, x: f64) -> f64 {
    if theta.abs() < 1e-9 {
        return 0.0;
    }
    let th = theta.abs();
    let r = len / (2.0 * th.sin());
    let yc = -(len / 2.0) / th.tan();
    let dx = x - len / 2.0;
    (yc + (r * r - dx * dx).max(0.0).sqrt()) * theta.signum()
}

/// Abscissae (eq. 12) and the bounds `[L_i, U_i]` (eq. 14) of `m` points.
fn bounds(ta: f64, tb: f64, len: f64, m: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut xs = Vec::with_capacity(m);
    let mut lo = Vec::with_capacity(m);
    let mut hi = Vec::with_capacity(m);
    for i in 1..=m {
        let f = i as f64 / (m + 1) as f64;
        let x = 0.5 * (arc_point(ta, len, f).x + arc_point(tb, len, f).x);
        let x = x.clamp(0.0, len);
        let (ya, yb) = (arc_y(ta, len, x), arc_y(tb, len, x));
        xs.push(x);
        lo.push(ya.min(yb));
        hi.push(ya.max(yb));
    }
    (xs, lo, hi)
}

/// Eq. 14's objective: the largest turning angle of the polyline
/// `(0,0), (x_i, y_i)…, (len, 0)`, as minus the smallest cosine (monotone in it).
fn objective(xs: &[f64], ys: &[f64], len: f64) -> f64 {
    let m = xs.len();
    let pt = |i: usize| -> DVec2 {
        if i == 0 {
            DVec2::ZERO
        } else if i == m + 1 {
            DVec2::new(len, 0.0)
        } else {
            DVec2::new(xs[i - 1], ys[i - 1])
        }
    };
    let mut min_cos = 1.0f64;
    for i in 1..=m {
        let u = pt(i) - pt(i - 1);
        let v = pt(i + 1) - pt(i);
        let d = u.length() * v.length();
        let c = if d > 0.0 { u.dot(v) / d } else { -1.0 };
        min_cos = min_cos.min(c);
    }
    -min_cos
}

/// DE/rand/1/bin over `y ∈ [lo, hi]` (Algorithm 1, eqs. 14 and 16).
fn de_search(
    xs: &[f64],
    lo: &[f64],
    hi: &[f64],
    len: f64,
    ctx: &FillContext,
    rng: &mut ChaCha8Rng,
    deadline: &Deadline,
) -> Result<Vec<f64>, FillError> {
    let opts = &ctx.policy.hpde;
    let m = xs.len();
    if m == 0 {
        return Ok(Vec::new());
    }
    // eq. 16
    let y0: Vec<f64> = (0..m)
        .map(|i| lo[i] + (hi[i] - lo[i]) * (i + 1) as f64 / (m + 1) as f64)
        .collect();
    let width: Vec<f64> = (0..m).map(|i| hi[i] - lo[i]).collect();
    if width.iter().all(|&w| w <= 1e-12 * len) {
        return Ok(y0);
    }
    let np = (opts.population_factor * m).max(4);
    let mut pop: Vec<Vec<f64>> = Vec::with_capacity(np);
    pop.push(y0.clone());
    for _ in 1..np {
        let ind: Vec<f64> = (0..m)
            .map(|i| {
                let r: f64 = rng.random::<f64>() - 0.5;
                (y0[i] + width[i] * 0.5 * r).clamp(lo[i], hi[i])
            })
            .collect();
        pop.push(ind);
    }
    let mut fit: Vec<f64> = pop.iter().map(|y| objective(xs, y, len)).collect();
    let mut trial = vec![0.0; m];
    for _ in 0..opts.generations {
        deadline.check()?;
        for i in 0..np {
            let r1 = pick(rng, np, &[i]);
            let r2 = pick(rng, np, &[i, r1]);
            let r3 = pick(rng, np, &[i, r1, r2]);
            let jr = rng.random_range(0..m);
            for j in 0..m {
                let x = pop[i][j];
                trial[j] = if j == jr || rng.random::<f64>() < opts.cr {
                    let v = pop[r1][j] + opts.f * (pop[r2][j] - pop[r3][j]);
                    if v < lo[j] {
                        0.5 * (lo[j] + x)
                    } else if v > hi[j] {
                        0.5 * (hi[j] + x)
                    } else {
                        v
                    }
                } else {
                    x
                };
            }
            let ft = objective(xs, &trial, len);
            if ft <= fit[i] {
                fit[i] = ft;
                pop[i].copy_from_slice(&trial);
            }
        }
    }
    let best = (0..np)
        .min_by(|&a, &b| fit[a].total_cmp(&fit[b]))
        .unwrap_or(0);
    Ok(pop.swap_remove(best))
}

/// A uniformly random index in `0..n` not in `not` (`n > not.len()`).
fn pick(rng: &mut ChaCha8Rng, n: usize, not: &[usize]) -> usize {
    loop {
        let r = rng.random_range(0..n);
        if !not.contains(&r) {
            return r;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arcs_pass_through_their_ends_with_the_given_tangent() {
        for &th in &[0.3, -0.7, 1.2, 1e-12] {
            let len = 2.5;
            assert!(arc_point(th, len, 0.0).length() < 1e-12);
            assert!((arc_point(th, len, 1.0) - DVec2::new(len, 0.0)).length() < 1e-12);
            let p = arc_point(th, len, 1e-6);
            let ang = p.y.atan2(p.x);
            assert!((ang - th).abs() < 1e-5 || th.abs() < 1e-9, "{ang} vs {th}");
            for f in [0.1, 0.37, 0.8] {
                let q = arc_point(th, len, f);
                assert!((arc_y(th, len, q.x) - q.y).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn chain_pairs_every_point_once() {
        for n in 3..12 {
            for s in 0..2 * n {
                let c = chain(n, s);
                let mut seen = vec![0; n];
                for &(a, b) in &c {
                    assert_ne!(a, b);
                    assert_eq!((a + b) % n, s % n);
                    seen[a] += 1;
                    seen[b] += 1;
                }
                // every point at most once, at most 2 unpaired
                assert!(seen.iter().all(|&x| x <= 1));
                assert!(seen.iter().filter(|&&x| x == 0).count() <= 2);
                // consecutive pairs are neighbours
                for w in c.windows(2) {
                    assert_eq!((w[0].0 + 1) % n, w[1].0);
                    assert_eq!((w[1].1 + 1) % n, w[0].1);
                }
            }
        }
    }

    #[test]
    fn eigen_of_a_diagonal_and_a_rotated_matrix() {
        let a = [[3.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 2.0]];
        let e = sym3_eigenvalues(&a);
        assert!((e[0] - 1.0).abs() < 1e-12 && (e[1] - 2.0).abs() < 1e-12);
        assert!((smallest_eigenvector(&a).abs() - DVec3::Y).length() < 1e-12);
        // points on a tilted plane
        let n = DVec3::new(1.0, 2.0, 2.0).normalize();
        let u = n.any_orthonormal_vector();
        let v = n.cross(u);
        let pts: Vec<DVec3> = (0..40)
            .map(|i| {
                let t = i as f64 * 0.7;
                u * t.cos() * 3.0 + v * (1.3 * t).sin() + n * 1e-3 * (i % 3) as f64
            })
            .collect();
        let pl = fit_plane(&pts, n);
        assert!(pl.normal.dot(n) > 0.9999, "{}", pl.normal);
    }

    #[test]
    fn de_straightens_a_free_polyline() {
        // bounds wide enough for the straight line: the optimum is y = 0
        let xs: Vec<f64> = (1..=5).map(|i| i as f64).collect();
        let lo = vec![-1.0; 5];
        let hi = vec![1.0; 5];
        let y0: Vec<f64> = (0..5).map(|i| -1.0 + 2.0 * (i + 1) as f64 / 6.0).collect();
        let policy = crate::policy::Policy::default();
        let (mesh, _) = crate::mesh::Mesh::from_raw(&crate::io::RawMesh::default());
        let hole = crate::patch::Hole {
            id: 0,
            vertices: vec![],
            perimeter: 0.0,
            mean_edge_length: 0.0,
            class: crate::report::HoleClass::Small,
        };
        let ctx = FillContext::new(&mesh, &hole, &policy);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        use rand::SeedableRng;
        let y = de_search(&xs, &lo, &hi, 6.0, &ctx, &mut rng, &Deadline::none()).unwrap();
        let f0 = objective(&xs, &y0, 6.0);
        let f1 = objective(&xs, &y, 6.0);
        assert!(f1 < f0, "{f1} !< {f0}");
        for (i, yi) in y.iter().enumerate() {
            assert!((lo[i]..=hi[i]).contains(yi));
        }
    }
}
