//! Exact triangle–triangle overlap tests (Shewchuk's predicates from the `robust`
//! crate) and a spatial hash grid of triangles, used to keep the front from creating
//! a triangle that overlaps the patch built so far or the mesh around the hole.
//!
//! Triangles that share a vertex or an edge touch by construction. Rather than
//! special-casing shared corners, both triangles are shrunk towards their centroids
//! by a tiny relative amount ([`SHRINK`]) before the exact closed test: adjacent
//! triangles then no longer touch, while a real overlap (a fold over a neighbour,
//! a crossing) survives the shrink unless it is thinner than `SHRINK` times the
//! triangle size.

use super::improve::FxMap;
use glam::DVec3;
use robust::{orient2d, orient3d, Coord, Coord3D};

/// Relative shrink applied before the exact test.
pub const SHRINK: f64 = 1e-6;

#[inline]
fn c3(p: DVec3) -> Coord3D<f64> {
    Coord3D {
        x: p.x,
        y: p.y,
        z: p.z,
    }
}

#[inline]
fn o3(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> i8 {
    sign(orient3d(c3(a), c3(b), c3(c), c3(d)))
}

#[inline]
fn sign(x: f64) -> i8 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}

/// The triangle shrunk towards its centroid by [`SHRINK`].
pub fn shrink(t: &[DVec3; 3]) -> [DVec3; 3] {
    let c = (t[0] + t[1] + t[2]) / 3.0;
    t.map(|p| c + (p - c) * (1.0 - SHRINK))
}

/// True when the shrunk triangles overlap (see the module doc).
pub fn overlap(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    tri_tri(&shrink(a), &shrink(b))
}

/// Which coordinate to drop when projecting a plane with normal `n` to 2D.
fn drop_axis(n: DVec3) -> Option<usize> {
    let a = n.abs();
    let m = a.max_element();
    if m.is_nan() || m <= 0.0 {
        return None;
    }
    Some(if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    })
}

#[inline]
fn proj(p: DVec3, axis: usize) -> Coord<f64> {
    match axis {
        0 => Coord { x: p.y, y: p.z },
        1 => Coord { x: p.z, y: p.x },
        _ => Coord { x: p.x, y: p.y },
    }
}

#[inline]
fn o2(a: Coord<f64>, b: Coord<f64>, c: Coord<f64>) -> i8 {
    sign(orient2d(a, b, c))
}

/// Closed segments intersect (2D, exact).
fn seg_seg_2d(a: Coord<f64>, b: Coord<f64>, c: Coord<f64>, d: Coord<f64>) -> bool {
    let d1 = o2(a, b, c);
    let d2 = o2(a, b, d);
    let d3 = o2(c, d, a);
    let d4 = o2(c, d, b);
    if d1 * d2 < 0 && d3 * d4 < 0 {
        return true;
    }
    let on = |p: Coord<f64>, q: Coord<f64>, r: Coord<f64>| {
        // r on segment pq, given collinear
        r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    (d1 == 0 && on(a, b, c))
        || (d2 == 0 && on(a, b, d))
        || (d3 == 0 && on(c, d, a))
        || (d4 == 0 && on(c, d, b))
}

/// Point in closed triangle (2D, exact; false for a degenerate triangle).
fn point_in_tri_2d(p: Coord<f64>, t: [Coord<f64>; 3]) -> bool {
    let s = [o2(t[0], t[1], p), o2(t[1], t[2], p), o2(t[2], t[0], p)];
    let area = o2(t[0], t[1], t[2]);
    if area == 0 {
        return false;
    }
    s.iter().all(|&x| x == 0 || x == area)
}

fn tri_tri_2d(p: &[DVec3; 3], q: &[DVec3; 3], axis: usize) -> bool {
    let a = p.map(|x| proj(x, axis));
    let b = q.map(|x| proj(x, axis));
    for i in 0..3 {
        for j in 0..3 {
            if seg_seg_2d(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3]) {
                return true;
            }
        }
    }
    point_in_tri_2d(a[0], b) || point_in_tri_2d(b[0], a)
}

/// Closed segment `ab` meets closed triangle `t` (exact).
fn seg_tri(a: DVec3, b: DVec3, t: &[DVec3; 3]) -> bool {
    let sa = o3(t[0], t[1], t[2], a);
    let sb = o3(t[0], t[1], t[2], b);
    if sa * sb > 0 {
        return false;
    }
    if sa == 0 && sb == 0 {
        let Some(axis) = drop_axis((t[1] - t[0]).cross(t[2] - t[0])) else {
            return false;
        };
        let tt = t.map(|x| proj(x, axis));
        let (pa, pb) = (proj(a, axis), proj(b, axis));
        if point_in_tri_2d(pa, tt) || point_in_tri_2d(pb, tt) {
            return true;
        }
        return (0..3).any(|j| seg_seg_2d(pa, pb, tt[j], tt[(j + 1) % 3]));
    }
    let s1 = o3(a, b, t[0], t[1]);
    let s2 = o3(a, b, t[1], t[2]);
    let s3 = o3(a, b, t[2], t[0]);
    (s1 >= 0 && s2 >= 0 && s3 >= 0) || (s1 <= 0 && s2 <= 0 && s3 <= 0)
}

/// Floating-point separating-axis filter: true only when some axis (the two face
/// normals, the nine edge-edge cross products, the six in-plane edge normals)
/// separates the triangles by far more than the rounding error, so that the exact
/// test is needed only for pairs that (nearly) touch.
fn clearly_separated(p: &[DVec3; 3], q: &[DVec3; 3]) -> bool {
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

/// Closed triangles intersect (exact; a degenerate triangle never intersects).
pub fn tri_tri(p: &[DVec3; 3], q: &[DVec3; 3]) -> bool {
    let np = (p[1] - p[0]).cross(p[2] - p[0]);
    let nq = (q[1] - q[0]).cross(q[2] - q[0]);
    if np == DVec3::ZERO || nq == DVec3::ZERO || !np.is_finite() || !nq.is_finite() {
        return false;
    }
    !clearly_separated(p, q) && tri_tri_exact(p, q, np)
}

/// [`tri_tri`] without the floating-point filter.
fn tri_tri_exact(p: &[DVec3; 3], q: &[DVec3; 3], np: DVec3) -> bool {
    let dq = [
        o3(p[0], p[1], p[2], q[0]),
        o3(p[0], p[1], p[2], q[1]),
        o3(p[0], p[1], p[2], q[2]),
    ];
    if dq.iter().all(|&s| s > 0) || dq.iter().all(|&s| s < 0) {
        return false;
    }
    let dp = [
        o3(q[0], q[1], q[2], p[0]),
        o3(q[0], q[1], q[2], p[1]),
        o3(q[0], q[1], q[2], p[2]),
    ];
    if dp.iter().all(|&s| s > 0) || dp.iter().all(|&s| s < 0) {
        return false;
    }
    if dq.iter().all(|&s| s == 0) {
        // coplanar (p is not degenerate, so its plane is well defined)
        return match drop_axis(np) {
            Some(axis) => tri_tri_2d(p, q, axis),
            None => false,
        };
    }
    for i in 0..3 {
        if seg_tri(p[i], p[(i + 1) % 3], q) || seg_tri(q[i], q[(i + 1) % 3], p) {
            return true;
        }
    }
    false
}

/// A uniform hash grid of axis-aligned boxes (ids), for broad-phase queries.
pub struct Grid {
    inv: f64,
    cells: FxMap<(i64, i64, i64), Vec<u32>>,
    /// Boxes spanning too many cells: tested on every query.
    big: Vec<u32>,
}

/// A box spanning more cells than this goes to the `big` list.
const MAX_CELLS: i64 = 512;

impl Grid {
    /// A grid with cells of edge `cell` (> 0).
    pub fn new(cell: f64) -> Grid {
        Grid {
            inv: 1.0 / cell,
            cells: FxMap::default(),
            big: Vec::new(),
        }
    }

    #[inline]
    fn key(&self, p: DVec3) -> (i64, i64, i64) {
        // `as` saturates, so far-away or huge coordinates stay well defined
        (
            (p.x * self.inv).floor() as i64,
            (p.y * self.inv).floor() as i64,
            (p.z * self.inv).floor() as i64,
        )
    }

    /// Adds box `[lo, hi]` with id `id`.
    pub fn insert(&mut self, id: u32, lo: DVec3, hi: DVec3) {
        let a = self.key(lo);
        let b = self.key(hi);
        let n = (b.0.saturating_sub(a.0).saturating_add(1))
            .saturating_mul(b.1.saturating_sub(a.1).saturating_add(1))
            .saturating_mul(b.2.saturating_sub(a.2).saturating_add(1));
        if !(1..=MAX_CELLS).contains(&n) {
            self.big.push(id);
            return;
        }
        for x in a.0..=b.0 {
            for y in a.1..=b.1 {
                for z in a.2..=b.2 {
                    self.cells.entry((x, y, z)).or_default().push(id);
                }
            }
        }
    }

    /// Appends to `out` the ids of boxes that may meet `[lo, hi]` (with repeats).
    pub fn query(&self, lo: DVec3, hi: DVec3, out: &mut Vec<u32>) {
        out.extend_from_slice(&self.big);
        let a = self.key(lo);
        let b = self.key(hi);
        let n = (b.0.saturating_sub(a.0).saturating_add(1))
            .saturating_mul(b.1.saturating_sub(a.1).saturating_add(1))
            .saturating_mul(b.2.saturating_sub(a.2).saturating_add(1));
        if !(1..=MAX_CELLS * 8).contains(&n) {
            // a huge query box: scan every cell instead
            for v in self.cells.values() {
                out.extend_from_slice(v);
            }
            return;
        }
        for x in a.0..=b.0 {
            for y in a.1..=b.1 {
                for z in a.2..=b.2 {
                    if let Some(v) = self.cells.get(&(x, y, z)) {
                        out.extend_from_slice(v);
                    }
                }
            }
        }
    }
}

/// Triangles that new triangles must not overlap, with a grid over them.
pub struct Obstacles {
    tris: Vec<[DVec3; 3]>,
    grid: Grid,
    scratch: Vec<u32>,
}

/// Bounding box of a triangle.
pub fn tri_box(t: &[DVec3; 3]) -> (DVec3, DVec3) {
    (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]))
}

impl Obstacles {
    /// An empty set with grid cells of edge `cell`.
    pub fn new(cell: f64) -> Obstacles {
        Obstacles {
            tris: Vec::new(),
            grid: Grid::new(cell),
            scratch: Vec::new(),
        }
    }

    /// Adds a triangle; returns its id.
    pub fn add(&mut self, t: [DVec3; 3]) -> u32 {
        let id = self.tris.len() as u32;
        let (lo, hi) = tri_box(&t);
        self.grid.insert(id, lo, hi);
        self.tris.push(t);
        id
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// The id of a triangle overlapping `t` (see [`overlap`]), skipping ids for
    /// which `skip` is true.
    pub fn find_overlap(&mut self, t: &[DVec3; 3], skip: impl Fn(u32) -> bool) -> Option<u32> {
        let (lo, hi) = tri_box(t);
        let pad = (hi - lo).max_element() * 1e-9;
        let mut ids = std::mem::take(&mut self.scratch);
        ids.clear();
        self.grid
            .query(lo - DVec3::splat(pad), hi + DVec3::splat(pad), &mut ids);
        ids.sort_unstable();
        ids.dedup();
        let st = shrink(t);
        let mut found = None;
        for &id in &ids {
            if skip(id) {
                continue;
            }
            let o = &self.tris[id as usize];
            let (olo, ohi) = tri_box(o);
            if olo.cmpgt(hi).any() || ohi.cmplt(lo).any() {
                continue;
            }
            if tri_tri(&st, &shrink(o)) {
                found = Some(id);
                break;
            }
        }
        self.scratch = ids;
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [DVec3; 3] {
        [DVec3::from(a), DVec3::from(b), DVec3::from(c)]
    }

    #[test]
    fn crossing_triangles_intersect() {
        let a = t([0., 0., 0.], [2., 0., 0.], [0., 2., 0.]);
        let b = t([0.5, 0.5, -1.], [0.5, 0.5, 1.], [3., 3., 0.]);
        assert!(tri_tri(&a, &b));
        let c = t([0.5, 0.5, 0.1], [0.6, 0.5, 1.], [3., 3., 0.1]);
        assert!(!tri_tri(&a, &c));
    }

    #[test]
    fn coplanar_cases() {
        let a = t([0., 0., 0.], [2., 0., 0.], [0., 2., 0.]);
        // overlapping
        let b = t([0.5, 0.5, 0.], [3., 0.5, 0.], [0.5, 3., 0.]);
        assert!(tri_tri(&a, &b));
        // contained
        let c = t([0.1, 0.1, 0.], [0.3, 0.1, 0.], [0.1, 0.3, 0.]);
        assert!(tri_tri(&a, &c) && tri_tri(&c, &a));
        // disjoint
        let d = t([3., 3., 0.], [4., 3., 0.], [3., 4., 0.]);
        assert!(!tri_tri(&a, &d));
    }

    #[test]
    fn neighbours_do_not_overlap_but_folds_do() {
        let a = t([0., 0., 0.], [1., 0., 0.], [0., 1., 0.]);
        // shares edge (1,0)-(0,1), other side
        let b = t([1., 0., 0.], [1., 1., 0.], [0., 1., 0.]);
        assert!(!overlap(&a, &b));
        // shares the edge but folds over a
        let c = t([1., 0., 0.], [0.2, 0.2, 0.], [0., 1., 0.]);
        assert!(overlap(&a, &c));
        // shares only a vertex, bent out of plane
        let d = t([0., 0., 0.], [-1., 0., 0.5], [0., -1., 0.5]);
        assert!(!overlap(&a, &d));
        // shares a vertex and pierces a
        let e = t([0., 0., 0.], [0.5, 0.2, -1.], [0.2, 0.5, 1.]);
        assert!(overlap(&a, &e));
        // nearly flat neighbour on the other side of a shared edge
        let f = t([1., 0., 0.], [1., 1., 1e-9], [0., 1., 0.]);
        assert!(!overlap(&a, &f));
    }

    #[test]
    fn filter_agrees_with_the_exact_test() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut hits = 0;
        for i in 0..20000 {
            let mut pt = |flat: bool| {
                let z = if flat {
                    0.0
                } else {
                    rng.random_range(-1.0..1.0)
                };
                DVec3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), z)
            };
            let flat = i % 2 == 0;
            let p = [pt(flat), pt(flat), pt(flat)];
            let mut q = [pt(flat), pt(flat), pt(flat)];
            if i % 3 == 0 {
                q[0] = p[1]; // share a corner
            }
            for t in [(p, q), (shrink(&p), shrink(&q))] {
                let np = (t.0[1] - t.0[0]).cross(t.0[2] - t.0[0]);
                let nq = (t.1[1] - t.1[0]).cross(t.1[2] - t.1[0]);
                if np == DVec3::ZERO || nq == DVec3::ZERO {
                    continue;
                }
                let exact = tri_tri_exact(&t.0, &t.1, np);
                assert_eq!(tri_tri(&t.0, &t.1), exact, "pair {i}");
                hits += exact as usize;
            }
        }
        assert!(hits > 1000);
    }

    #[test]
    fn grid_finds_overlaps() {
        let mut o = Obstacles::new(0.5);
        o.add(t([0., 0., 0.], [1., 0., 0.], [0., 1., 0.]));
        o.add(t([5., 5., 0.], [6., 5., 0.], [5., 6., 0.]));
        let q = t([0.2, 0.2, -1.], [0.2, 0.2, 1.], [0.9, 0.9, 0.]);
        assert_eq!(o.find_overlap(&q, |_| false), Some(0));
        assert_eq!(o.find_overlap(&q, |id| id == 0), None);
        let far = t([9., 9., 0.], [10., 9., 0.], [9., 10., 0.]);
        assert_eq!(o.find_overlap(&far, |_| false), None);
        // a huge triangle goes to the big list and is still found
        o.add(t(
            [-1000., -1000., 3.],
            [1000., -1000., 3.],
            [0., 1000., 3.],
        ));
        let r = t([0.2, 0.2, 2.], [0.2, 0.2, 4.], [0.9, 0.9, 3.]);
        assert_eq!(o.find_overlap(&r, |_| false), Some(2));
    }
}
