//! Exact geometric predicates: the one place where the methods and the patch checks
//! decide on which side of a line or plane a point lies, and whether segments and
//! triangles meet. Every answer is the sign of Shewchuk's adaptive exact `orient2d` /
//! `orient3d` (the `robust` crate), so it is exact for the `f64` coordinates given;
//! no test here uses a tolerance, except [`far_apart`], a floating-point filter that
//! only ever answers "apart" when the exact test would.
//!
//! Closed and open readings are both needed and named apart: the checks count touching
//! as meeting ([`tri_tri`], [`tri_tri_plain`], [`seg_tri`], [`segments_meet`]); the
//! fronts ask whether a new triangle overlaps another with positive area
//! ([`overlap2d`]) or crosses it away from shared corners ([`seg_crosses_tri`],
//! [`overlap2d_labeled`]).
//!
//! The triangle-triangle test is the edge form of the classic one: two closed
//! triangles meet iff an edge of one meets the other (their intersection, if not
//! empty, is a convex set whose extreme points lie on the boundary of one of them),
//! which also covers degenerate (collinear) triangles, whose point set is the union of
//! their edges.

use glam::DVec3;
use robust::{Coord, Coord3D};

/// A point of the plane, as `robust` takes it.
pub type P2 = Coord<f64>;

/// `robust::orient2d(a, b, c)`: positive when `a, b, c` turn counter-clockwise, zero
/// when collinear; exact sign.
#[inline]
pub fn orient2(a: P2, b: P2, c: P2) -> f64 {
    robust::orient2d(a, b, c)
}

/// A plane point from its coordinates.
#[inline]
pub fn p2(x: f64, y: f64) -> P2 {
    Coord { x, y }
}

// ---------------------------------------------------------------------------
// In the plane.

/// `c` on the closed segment `ab`, given that the three are collinear.
#[inline]
fn on_segment(a: P2, b: P2, c: P2) -> bool {
    c.x >= a.x.min(b.x) && c.x <= a.x.max(b.x) && c.y >= a.y.min(b.y) && c.y <= a.y.max(b.y)
}

/// Closed segments `pq` and `rs` share a point.
pub fn segments_meet(p: P2, q: P2, r: P2, s: P2) -> bool {
    let d1 = orient2(r, s, p);
    let d2 = orient2(r, s, q);
    let d3 = orient2(p, q, r);
    let d4 = orient2(p, q, s);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(r, s, p))
        || (d2 == 0.0 && on_segment(r, s, q))
        || (d3 == 0.0 && on_segment(p, q, r))
        || (d4 == 0.0 && on_segment(p, q, s))
}

/// Segments `ab` and `cd` cross properly: at one point inside both (touching at an
/// end, or lying along each other, does not count).
pub fn segments_cross(a: P2, b: P2, c: P2, d: P2) -> bool {
    let d1 = orient2(a, b, c);
    let d2 = orient2(a, b, d);
    let d3 = orient2(c, d, a);
    let d4 = orient2(c, d, b);
    ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
}

/// `p` strictly inside the triangle `a, b, c` (either orientation).
pub fn strictly_inside(p: P2, a: P2, b: P2, c: P2) -> bool {
    let s1 = orient2(a, b, p);
    let s2 = orient2(b, c, p);
    let s3 = orient2(c, a, p);
    (s1 > 0.0 && s2 > 0.0 && s3 > 0.0) || (s1 < 0.0 && s2 < 0.0 && s3 < 0.0)
}

/// The triangle counter-clockwise, or `None` when it is degenerate.
pub fn ccw2d(t: [P2; 3]) -> Option<[P2; 3]> {
    let o = orient2(t[0], t[1], t[2]);
    if o > 0.0 {
        Some(t)
    } else if o < 0.0 {
        Some([t[0], t[2], t[1]])
    } else {
        None
    }
}

/// Do two triangles overlap with positive area? A degenerate first triangle counts as
/// overlapping, a degenerate second one as not (separating-axis test over the six
/// edges).
pub fn overlap2d(a: [P2; 3], b: [P2; 3]) -> bool {
    let Some(a) = ccw2d(a) else { return true };
    overlap2d_ccw(a, b)
}

/// [`overlap2d`] with the first triangle already counter-clockwise.
pub fn overlap2d_ccw(a: [P2; 3], b: [P2; 3]) -> bool {
    let Some(b) = ccw2d(b) else { return false };
    let separates = |s: &[P2; 3], o: &[P2; 3]| {
        (0..3).any(|e| {
            let (p, q) = (s[e], s[(e + 1) % 3]);
            o.iter().all(|&r| orient2(p, q, r) <= 0.0)
        })
    };
    !(separates(&a, &b) || separates(&b, &a))
}

/// Interior overlap of two triangles given with vertex labels (equal labels are the
/// same vertex): sharing an edge, they overlap iff their far corners lie strictly on
/// the same side of it; otherwise iff two edges without a shared end cross properly or
/// a corner not shared lies strictly inside the other triangle.
pub fn overlap2d_labeled(ta: &[u32; 3], pa: &[P2; 3], tb: &[u32; 3], pb: &[P2; 3]) -> bool {
    let mut shared = [(0usize, 0usize); 9];
    let mut count = 0;
    for (i, a) in ta.iter().enumerate() {
        for (j, b) in tb.iter().enumerate() {
            if a == b {
                shared[count] = (i, j);
                count += 1;
            }
        }
    }
    match count {
        0 | 1 => {}
        2 => {
            // same side of the shared edge?
            let (i0, j0) = shared[0];
            let (i1, j1) = shared[1];
            let ia = 3 - i0 - i1;
            let jb = (0..3).find(|&j| j != j0 && j != j1).unwrap_or(0);
            let sa = orient2(pa[i0], pa[i1], pa[ia]);
            let sb = orient2(pa[i0], pa[i1], pb[jb]);
            return (sa > 0.0 && sb > 0.0) || (sa < 0.0 && sb < 0.0);
        }
        _ => return true,
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
    (0..3).any(|i| !tb.contains(&ta[i]) && strictly_inside(pa[i], pb[0], pb[1], pb[2]))
        || (0..3).any(|j| !ta.contains(&tb[j]) && strictly_inside(pb[j], pa[0], pa[1], pa[2]))
}

// ---------------------------------------------------------------------------
// In space.

/// A point of space (the corners of the triangles below).
pub type P3 = DVec3;

/// `robust::orient3d(a, b, c, d)`: positive when `d` lies below the plane of `a, b, c`
/// (counter-clockwise seen from above), zero when the four are coplanar; exact sign.
#[inline]
pub fn o3(a: P3, b: P3, c: P3, d: P3) -> f64 {
    robust::orient3d(c3(a), c3(b), c3(c), c3(d))
}

/// A point as `robust`'s 3-D coordinate.
#[inline]
pub fn c3(p: P3) -> Coord3D<f64> {
    Coord3D {
        x: p.x,
        y: p.y,
        z: p.z,
    }
}

/// A point projected by dropping coordinate `drop`.
#[inline]
pub fn pr(p: P3, drop: usize) -> robust::Coord<f64> {
    match drop {
        0 => robust::Coord { x: p.y, y: p.z },
        1 => robust::Coord { x: p.z, y: p.x },
        _ => robust::Coord { x: p.x, y: p.y },
    }
}

/// [`orient2`] of three points projected by dropping coordinate `drop`.
#[inline]
pub fn o2(a: P3, b: P3, c: P3, drop: usize) -> f64 {
    robust::orient2d(pr(a, drop), pr(b, drop), pr(c, drop))
}

/// A coordinate to drop so that the triangle's projection is not degenerate (the
/// projection is then a bijection of the triangle's plane), `None` for a degenerate
/// (collinear) triangle. The best-conditioned axis is tried first.
pub fn proj_axis(a: P3, b: P3, c: P3) -> Option<usize> {
    let n = (b - a).cross(c - a).abs();
    let first = if n.x >= n.y && n.x >= n.z {
        0
    } else if n.y >= n.z {
        1
    } else {
        2
    };
    [first, (first + 1) % 3, (first + 2) % 3]
        .into_iter()
        .find(|&d| o2(a, b, c, d) != 0.0)
}

/// Closed segments `ab` and `cd` meet; all four points coplanar, projected by `drop`
/// (a bijection of their plane).
fn seg_seg2(a: P3, b: P3, c: P3, d: P3, drop: usize) -> bool {
    segments_meet(pr(a, drop), pr(b, drop), pr(c, drop), pr(d, drop))
}

/// `p` lies in the closed triangle `t` (coplanar, non-degenerate in projection `drop`).
fn in_tri2(p: P3, t: &[P3; 3], drop: usize) -> bool {
    let s = [
        o2(t[0], t[1], p, drop),
        o2(t[1], t[2], p, drop),
        o2(t[2], t[0], p, drop),
    ];
    !(s.iter().any(|&x| x > 0.0) && s.iter().any(|&x| x < 0.0))
}

/// Closed segment `st` meets the closed non-degenerate triangle `t`.
pub fn seg_tri(s: P3, e: P3, t: &[P3; 3]) -> bool {
    seg_tri_sided(s, e, t).unwrap_or(false)
}

/// [`seg_tri`], or `None` when the segment lies strictly on one side of the
/// triangle's plane (so it does not meet it).
fn seg_tri_sided(s: P3, e: P3, t: &[P3; 3]) -> Option<bool> {
    let [a, b, c] = *t;
    let os = o3(a, b, c, s);
    let oe = o3(a, b, c, e);
    if (os > 0.0 && oe > 0.0) || (os < 0.0 && oe < 0.0) {
        return None;
    }
    Some(seg_tri_across(s, e, t, os, oe))
}

/// The rest of [`seg_tri`], with the sides `os`, `oe` of the ends not both strict
/// and equal.
fn seg_tri_across(s: P3, e: P3, t: &[P3; 3], os: f64, oe: f64) -> bool {
    let [a, b, c] = *t;
    if os == 0.0 && oe == 0.0 {
        let Some(drop) = proj_axis(a, b, c) else {
            return false;
        };
        return in_tri2(s, t, drop)
            || in_tri2(e, t, drop)
            || seg_seg2(s, e, a, b, drop)
            || seg_seg2(s, e, b, c, drop)
            || seg_seg2(s, e, c, a, drop);
    }
    // the segment crosses (or touches) the plane at one point: it lies in the
    // triangle iff the line se passes on the same side of all three edges
    let v = [o3(s, e, a, b), o3(s, e, b, c), o3(s, e, c, a)];
    !(v.iter().any(|&x| x > 0.0) && v.iter().any(|&x| x < 0.0))
}

/// Closed segments `ab` and `cd` in space meet.
fn seg_seg3(a: P3, b: P3, c: P3, d: P3) -> bool {
    if o3(a, b, c, d) != 0.0 {
        return false;
    }
    for (x, y, z) in [(a, b, c), (a, b, d), (a, c, d), (b, c, d)] {
        if let Some(drop) = proj_axis(x, y, z) {
            return seg_seg2(a, b, c, d, drop);
        }
    }
    // all four points on one line: compare along the axis where they spread most
    let lo = a.min(b).min(c).min(d);
    let hi = a.max(b).max(c).max(d);
    let ext = hi - lo;
    let i = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    a[i].min(b[i]) <= c[i].max(d[i]) && c[i].min(d[i]) <= a[i].max(b[i])
}

/// Closed triangles `p` and `q` (no shared vertices) meet.
pub fn tri_tri_plain(p: &[P3; 3], q: &[P3; 3]) -> bool {
    tri_tri_plain_axes(p, tri_axis(p), q, tri_axis(q))
}

/// The projection axis of a triangle ([`proj_axis`]), to pass to [`tri_tri_axes`].
pub fn tri_axis(t: &[P3; 3]) -> Option<usize> {
    proj_axis(t[0], t[1], t[2])
}

/// [`tri_tri_plain`] with the triangles' [`tri_axis`] given.
fn tri_tri_plain_axes(p: &[P3; 3], pa: Option<usize>, q: &[P3; 3], qa: Option<usize>) -> bool {
    let edges = |t: &[P3; 3]| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])];
    match (pa, qa) {
        (Some(_), Some(_)) => {
            // early out: all of one triangle strictly on one side of the other's plane
            let side = |t: &[P3; 3], u: &[P3; 3]| {
                let s = u.map(|x| o3(t[0], t[1], t[2], x));
                s.iter().all(|&x| x > 0.0) || s.iter().all(|&x| x < 0.0)
            };
            if side(p, q) || side(q, p) {
                return false;
            }
            edges(p).iter().any(|&(s, e)| seg_tri(s, e, q))
                || edges(q).iter().any(|&(s, e)| seg_tri(s, e, p))
        }
        (Some(_), None) => edges(q).iter().any(|&(s, e)| seg_tri(s, e, p)),
        (None, Some(_)) => edges(p).iter().any(|&(s, e)| seg_tri(s, e, q)),
        (None, None) => edges(p)
            .iter()
            .any(|&(a, b)| edges(q).iter().any(|&(c, d)| seg_seg3(a, b, c, d))),
    }
}

/// Triangle `p` (keys `pk`) and triangle `q` (keys `qk`) intersect, under CGAL's
/// convention for triangles sharing vertices (equal keys = the same vertex):
/// - no shared vertex: the closed triangles meet;
/// - one shared vertex `w`: they meet somewhere other than `w` (iff the edge of one
///   opposite `w` meets the other triangle);
/// - two shared vertices (a shared edge): they overlap beyond the edge, which for
///   non-degenerate triangles means coplanar with both far vertices strictly on the
///   same side of the edge (a fold);
/// - three: the same triangle, always an intersection.
///
/// `p` must be non-degenerate (patch triangles are checked for that first); a
/// degenerate `p` is reported as intersecting whenever it shares a vertex.
/// `q` may be degenerate (a zero-area face of the input).
pub fn tri_tri(p: &[P3; 3], pk: &[u64; 3], q: &[P3; 3], qk: &[u64; 3]) -> bool {
    tri_tri_axes(p, pk, tri_axis(p), q, qk, tri_axis(q))
}

/// [`tri_tri`] with the triangles' [`tri_axis`] given (computed once per triangle by a
/// caller that tests it against many).
pub fn tri_tri_axes(
    p: &[P3; 3],
    pk: &[u64; 3],
    pa: Option<usize>,
    q: &[P3; 3],
    qk: &[u64; 3],
    qa: Option<usize>,
) -> bool {
    // the shared corners, without allocating (called for every candidate pair)
    let mut shared = [(0usize, 0usize); 9];
    let mut count = 0;
    for (i, a) in pk.iter().enumerate() {
        for (j, b) in qk.iter().enumerate() {
            if a == b {
                shared[count] = (i, j);
                count += 1;
            }
        }
    }
    match count {
        0 => tri_tri_plain_axes(p, pa, q, qa),
        1 => {
            let (i, j) = shared[0];
            let w = p[i];
            let (p1, p2) = (p[(i + 1) % 3], p[(i + 2) % 3]);
            let (q1, q2) = (q[(j + 1) % 3], q[(j + 2) % 3]);
            if pa.is_none() {
                return true;
            }
            if qa.is_some() {
                // p1 and p2 strictly on one side of q's plane (w is on it): p meets
                // that plane, so q, at w only
                return match seg_tri_sided(p1, p2, q) {
                    None => false,
                    Some(hit) => hit || seg_tri(q1, q2, p),
                };
            }
            // q is a segment through w: it meets p beyond w iff one of its two
            // pieces from w runs into p
            [q1, q2]
                .into_iter()
                .any(|x| x != w && ray_enters(w, x, p1, p2))
        }
        2 => {
            let (i0, j0) = shared[0];
            let (i1, j1) = shared[1];
            let (u, v) = (p[i0], p[i1]);
            let pf = p[3 - i0 - i1];
            let qf = q[3 - j0 - j1];
            let Some(drop) = pa else {
                return true;
            };
            if o3(u, v, pf, qf) != 0.0 {
                return false;
            }
            let a = o2(u, v, pf, drop);
            let b = o2(u, v, qf, drop);
            (a > 0.0 && b > 0.0) || (a < 0.0 && b < 0.0)
        }
        _ => true,
    }
}

/// The segment from `w` (a corner of the non-degenerate triangle `w p1 p2`) to `x`
/// meets the triangle at a point other than `w`.
fn ray_enters(w: P3, x: P3, p1: P3, p2: P3) -> bool {
    if o3(w, p1, p2, x) != 0.0 {
        return false; // crosses the plane at w only
    }
    let Some(drop) = proj_axis(w, p1, p2) else {
        return true;
    };
    // direction x - w inside the closed angle p1 w p2
    let turn = o2(w, p1, p2, drop).signum();
    let a = o2(w, p1, x, drop) * turn;
    let b = o2(w, x, p2, drop) * turn;
    a >= 0.0 && b >= 0.0
}

/// Does segment `ab` cross triangle `t` (touching counts; a segment in the triangle's
/// plane does not)?
pub fn seg_crosses_tri(a: P3, b: P3, t: &[P3; 3]) -> bool {
    let da = o3(t[0], t[1], t[2], a);
    let db = o3(t[0], t[1], t[2], b);
    if (da > 0.0 && db > 0.0) || (da < 0.0 && db < 0.0) || (da == 0.0 && db == 0.0) {
        return false;
    }
    let s0 = o3(a, b, t[0], t[1]);
    let s1 = o3(a, b, t[1], t[2]);
    let s2 = o3(a, b, t[2], t[0]);
    (s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0) || (s0 <= 0.0 && s1 <= 0.0 && s2 <= 0.0)
}

/// [`tri_tri_plain`] for triangles whose floating-point normals are not zero (`false`
/// otherwise), behind the [`far_apart`] filter.
pub fn tri_tri_nondegenerate(p: &[P3; 3], q: &[P3; 3]) -> bool {
    let np = (p[1] - p[0]).cross(p[2] - p[0]);
    let nq = (q[1] - q[0]).cross(q[2] - q[0]);
    if np == DVec3::ZERO || nq == DVec3::ZERO || !np.is_finite() || !nq.is_finite() {
        return false;
    }
    !far_apart(p, q) && tri_tri_plain(p, q)
}

/// Floating-point separating-axis filter: true only when some axis (the two face
/// normals, the nine edge-edge cross products, the six in-plane edge normals)
/// separates the triangles by far more than the rounding error, so that the exact
/// test is needed only for pairs that (nearly) touch.
pub fn far_apart(p: &[P3; 3], q: &[P3; 3]) -> bool {
    // work relative to one corner to keep the rounding error relative to the size
    let o = p[0];
    let a = p.map(|x| x - o);
    let b = q.map(|x| x - o);
    let ea = [a[1] - a[0], a[2] - a[1], a[0] - a[2]];
    let eb = [b[1] - b[0], b[2] - b[1], b[0] - b[2]];
    let na = ea[0].cross(ea[1]);
    let nb = eb[0].cross(eb[1]);
    let scale = a
        .iter()
        .chain(b.iter())
        .fold(0.0f64, |m, x| m.max(x.abs().max_element()));
    let sep = |axis: DVec3| -> bool {
        let len = axis.length();
        if !len.is_finite() || len <= 0.0 {
            return false;
        }
        let tol = 1e-9 * scale * len;
        let (mut amin, mut amax) = (f64::INFINITY, f64::NEG_INFINITY);
        for x in &a {
            let d = x.dot(axis);
            amin = amin.min(d);
            amax = amax.max(d);
        }
        let (mut bmin, mut bmax) = (f64::INFINITY, f64::NEG_INFINITY);
        for x in &b {
            let d = x.dot(axis);
            bmin = bmin.min(d);
            bmax = bmax.max(d);
        }
        bmin > amax + tol || amin > bmax + tol
    };
    if sep(na) || sep(nb) {
        return true;
    }
    for u in &ea {
        if sep(na.cross(*u)) {
            return true;
        }
        for v in &eb {
            if sep(u.cross(*v)) {
                return true;
            }
        }
    }
    eb.iter().any(|v| sep(nb.cross(*v)))
}

#[cfg(test)]
mod tests;
