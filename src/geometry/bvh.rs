//! A bounding-volume hierarchy (axis-aligned boxes) over primitives given by their
//! bounding boxes: the broad phase of the self-intersection check (ALGORITHMS A5).
//!
//! Built top-down over the primitives' box centres: each node is split at the middle
//! of the longest axis of its centres' box (the spatial median), falling back to the
//! object median when that leaves one side empty, and to a split by count when all
//! centres coincide. Everything lives in flat arrays (nodes, a permutation of the
//! primitives); node boxes are `f32` rounded outwards, so a node box always contains
//! the exact `f64` boxes below it and queries never miss a primitive. The boxes of the
//! primitives themselves are not stored: they are recomputed from the caller's closure
//! when the tree is built and are the caller's business when it is queried.

use glam::DVec3;

use super::measure::closest_point_on_triangle;

/// Largest number of primitives in a leaf.
const MAX_LEAF: usize = 8;

/// One node: a box and either two children (`count == 0`, children at `first` and
/// `first + 1`) or a leaf of `count` primitives at `perm[first..first + count]`.
#[derive(Clone, Copy, Debug)]
struct Node {
    lo: [f32; 3],
    hi: [f32; 3],
    first: u32,
    count: u32,
}

impl Node {
    const EMPTY: Node = Node {
        lo: [0.0; 3],
        hi: [0.0; 3],
        first: 0,
        count: 0,
    };
}

/// A primitive's box centre and index, during the build.
#[derive(Clone, Copy)]
struct Item {
    c: [f32; 3],
    id: u32,
}

/// A box of centres.
#[derive(Clone, Copy)]
struct CBox {
    lo: [f32; 3],
    hi: [f32; 3],
}

impl CBox {
    const EMPTY: CBox = CBox {
        lo: [f32::INFINITY; 3],
        hi: [f32::NEG_INFINITY; 3],
    };
    #[inline]
    fn add(&mut self, c: [f32; 3]) {
        for (a, &x) in c.iter().enumerate() {
            self.lo[a] = self.lo[a].min(x);
            self.hi[a] = self.hi[a].max(x);
        }
    }
}

/// The tree.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    perm: Vec<u32>,
}

/// Largest `f32` not above `x`. Without a branch on the rounding (it goes either way
/// at random over a mesh's coordinates): the nearest `f32`, moved one step down
/// when it is above `x` (a step down is the next bit pattern up for a negative, down
/// for a positive; `+0.0` is never above `x`, as `x` then rounds to `-0.0`).
#[inline]
pub(crate) fn f32_down(x: f64) -> f32 {
    let y = x as f32;
    let adj = ((y as f64) > x) as u32;
    let b = y.to_bits();
    f32::from_bits(if b >> 31 == 1 {
        b.wrapping_add(adj)
    } else {
        b.wrapping_sub(adj)
    })
}

/// Smallest `f32` not below `x` (as [`f32_down`], the other way).
#[inline]
pub(crate) fn f32_up(x: f64) -> f32 {
    let y = x as f32;
    let adj = ((y as f64) < x) as u32;
    let b = y.to_bits();
    f32::from_bits(if b >> 31 == 1 {
        b.wrapping_sub(adj)
    } else {
        b.wrapping_add(adj)
    })
}

/// The next representable `f32` up or down (NaN as is): what [`f32_down`] and
/// [`f32_up`] do, step by step (their test's reference).
#[cfg(test)]
fn step_f32(y: f32, up: bool) -> f32 {
    if y.is_nan() || (y == f32::INFINITY && up) || (y == f32::NEG_INFINITY && !up) {
        return y;
    }
    if y == f32::INFINITY {
        return f32::MAX;
    }
    if y == f32::NEG_INFINITY {
        return f32::MIN;
    }
    if y == 0.0 {
        let tiny = f32::from_bits(1);
        return if up { tiny } else { -tiny };
    }
    let b = y.to_bits();
    let away = (y > 0.0) == up;
    f32::from_bits(if away { b + 1 } else { b - 1 })
}

impl Bvh {
    /// Builds the tree over `n` primitives; `bounds(i)` gives the box (min, max) of
    /// primitive `i`. Primitives with a non-finite box are still stored (their box is
    /// widened to everything), so nothing is lost. Large trees are built on up to
    /// `available_parallelism` threads (one subtree each below the top splits).
    pub fn build(n: usize, bounds: impl Fn(usize) -> (DVec3, DVec3) + Sync) -> Bvh {
        if n == 0 {
            return Bvh::default();
        }
        // the mesh's u32 half-edge ids keep n below 2^31, so u32 indices suffice.
        // Items (centre, id) are partitioned in place, so every pass is sequential.
        let mut items: Vec<Item> = Vec::with_capacity(n);
        let mut root = CBox::EMPTY;
        for i in 0..n {
            let (lo, hi) = bounds(i);
            let c = (lo + hi) * 0.5;
            let c = [c.x as f32, c.y as f32, c.z as f32];
            root.add(c);
            items.push(Item { c, id: i as u32 });
        }
        let threads = std::thread::available_parallelism().map_or(1, |t| t.get());
        let par = usize::BITS - (threads.max(1) - 1).leading_zeros(); // ceil(log2)
        let nodes = build_sub(&mut items, 0, root, par, &bounds);
        let perm = items.iter().map(|it| it.id).collect();
        Bvh { nodes, perm }
    }

    /// Number of primitives.
    pub fn len(&self) -> usize {
        self.perm.len()
    }

    /// True when the tree holds nothing.
    pub fn is_empty(&self) -> bool {
        self.perm.is_empty()
    }

    /// Calls `visit(i)` for every primitive whose node box meets the closed box
    /// `[lo, hi]` (a superset of the primitives whose own box meets it). Stops early,
    /// returning `true`, when `visit` returns `true`.
    pub fn query(&self, lo: DVec3, hi: DVec3, mut visit: impl FnMut(usize) -> bool) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let meets =
            |n: &Node| (0..3).all(|a| (n.lo[a] as f64) <= hi[a] && lo[a] <= (n.hi[a] as f64));
        // a stack on the stack while the tree is shallow enough (always, but for
        // degenerate inputs: then on the heap), in the same order either way
        let mut fixed = [0u32; 64];
        let mut top = 1usize;
        let mut spill: Vec<u32> = Vec::new();
        loop {
            let ni = if let Some(x) = spill.pop() {
                x
            } else if top > 0 {
                top -= 1;
                fixed[top]
            } else {
                break;
            };
            let n = &self.nodes[ni as usize];
            if !meets(n) {
                continue;
            }
            if n.count > 0 {
                for &p in &self.perm[n.first as usize..(n.first + n.count) as usize] {
                    if visit(p as usize) {
                        return true;
                    }
                }
            } else {
                for c in [n.first, n.first + 1] {
                    if spill.is_empty() && top < fixed.len() {
                        fixed[top] = c;
                        top += 1;
                    } else {
                        spill.push(c);
                    }
                }
            }
        }
        false
    }

    /// Calls `visit(i, j)` once for every unordered pair of distinct primitives whose
    /// leaf boxes meet (a superset of the pairs whose own boxes meet), by one walk of
    /// the tree against itself.
    pub fn self_pairs(&self, mut visit: impl FnMut(usize, usize)) {
        if self.nodes.is_empty() {
            return;
        }
        let meet = |a: &Node, b: &Node| (0..3).all(|x| a.lo[x] <= b.hi[x] && b.lo[x] <= a.hi[x]);
        let leaf = |n: &Node| &self.perm[n.first as usize..(n.first + n.count) as usize];
        let mut stack: Vec<(u32, u32)> = vec![(0, 0)];
        while let Some((a, b)) = stack.pop() {
            let (na, nb) = (&self.nodes[a as usize], &self.nodes[b as usize]);
            if a == b {
                if na.count > 0 {
                    let l = leaf(na);
                    for (x, &p) in l.iter().enumerate() {
                        for &q in &l[x + 1..] {
                            visit(p as usize, q as usize);
                        }
                    }
                } else {
                    let (l, r) = (na.first, na.first + 1);
                    stack.push((l, l));
                    stack.push((r, r));
                    stack.push((l, r));
                }
                continue;
            }
            if !meet(na, nb) {
                continue;
            }
            match (na.count > 0, nb.count > 0) {
                (true, true) => {
                    for &p in leaf(na) {
                        for &q in leaf(nb) {
                            visit(p as usize, q as usize);
                        }
                    }
                }
                (false, true) => {
                    stack.push((na.first, b));
                    stack.push((na.first + 1, b));
                }
                _ => {
                    stack.push((a, nb.first));
                    stack.push((a, nb.first + 1));
                }
            }
        }
    }
}

/// Below this many primitives a subtree is built on the calling thread.
const PAR_MIN: usize = 1 << 16;

/// Splits `items` (centres in the box `cb`) in two at the middle of the longest
/// axis of `cb`, or by count when that leaves a side empty. Returns the split index
/// and the centre boxes of both sides.
fn split(items: &mut [Item], cb: CBox) -> (usize, CBox, CBox) {
    let count = items.len();
    let ext = [
        cb.hi[0] - cb.lo[0],
        cb.hi[1] - cb.lo[1],
        cb.hi[2] - cb.lo[2],
    ];
    let axis = if ext[0] >= ext[1] && ext[0] >= ext[2] {
        0
    } else if ext[1] >= ext[2] {
        1
    } else {
        2
    };
    let (mut lb, mut rb) = (CBox::EMPTY, CBox::EMPTY);
    let mut mid = 0;
    if ext[axis] > 0.0 && ext[axis].is_finite() {
        let cut = cb.lo[axis] + 0.5 * ext[axis];
        let (mut i, mut j) = (0, count);
        while i < j {
            let c = items[i].c;
            if c[axis] < cut {
                lb.add(c);
                i += 1;
            } else {
                rb.add(c);
                j -= 1;
                items.swap(i, j);
            }
        }
        mid = i;
    }
    if mid == 0 || mid == count {
        // all centres on one side (or all equal): split by count
        mid = count / 2;
        items.select_nth_unstable_by(mid, |x, y| x.c[axis].total_cmp(&y.c[axis]));
        lb = CBox::EMPTY;
        rb = CBox::EMPTY;
        for it in &items[..mid] {
            lb.add(it.c);
        }
        for it in &items[mid..] {
            rb.add(it.c);
        }
    }
    (mid, lb, rb)
}

/// Builds the subtree over `items` (which start at `base` in the final order) and
/// fits its boxes; node 0 of the result is its root. With `par > 0` the two halves
/// of the top split are built on two threads.
fn build_sub<F>(items: &mut [Item], base: usize, cb: CBox, par: u32, bounds: &F) -> Vec<Node>
where
    F: Fn(usize) -> (DVec3, DVec3) + Sync,
{
    let n = items.len();
    if par > 0 && n >= PAR_MIN {
        let (mid, lb, rb) = split(items, cb);
        let (li, ri) = items.split_at_mut(mid);
        let (left, right) = std::thread::scope(|sc| {
            let spawned = std::thread::Builder::new()
                .spawn_scoped(sc, move || build_sub(li, base, lb, par - 1, bounds));
            match spawned {
                Ok(h) => {
                    let right = build_sub(ri, base + mid, rb, par - 1, bounds);
                    let left = h.join().unwrap_or_else(|e| std::panic::resume_unwind(e));
                    (left, right)
                }
                // no thread to be had: build both here (li was moved into the
                // closure that failed to start, so split again from the slices)
                Err(_) => (Vec::new(), Vec::new()),
            }
        });
        if left.is_empty() || right.is_empty() {
            return build_sub(items, base, cb, 0, bounds);
        }
        // layout: root, left root, right root, rest of left, rest of right
        let nl = left.len();
        let map_l = |i: u32| if i == 0 { 1 } else { i + 2 };
        let map_r = |i: u32| if i == 0 { 2 } else { i + 2 + nl as u32 - 1 };
        let mut nodes = Vec::with_capacity(nl + right.len() + 1);
        let (l0, r0) = (left[0], right[0]);
        let mut root = Node::EMPTY;
        for a in 0..3 {
            root.lo[a] = l0.lo[a].min(r0.lo[a]);
            root.hi[a] = l0.hi[a].max(r0.hi[a]);
        }
        root.first = 1;
        nodes.push(root);
        let fix = |mut nd: Node, map: &dyn Fn(u32) -> u32| {
            if nd.count == 0 {
                nd.first = map(nd.first);
            }
            nd
        };
        nodes.push(fix(l0, &map_l));
        nodes.push(fix(r0, &map_r));
        nodes.extend(left[1..].iter().map(|&nd| fix(nd, &map_l)));
        nodes.extend(right[1..].iter().map(|&nd| fix(nd, &map_r)));
        return nodes;
    }
    let mut nodes: Vec<Node> = Vec::with_capacity(n / 2 + 1);
    nodes.push(Node::EMPTY);
    // (node, start, end, box of the centres), positions local to `items`
    let mut stack: Vec<(usize, usize, usize, CBox)> = vec![(0, 0, n, cb)];
    while let Some((ni, s, e, cb)) = stack.pop() {
        if e - s <= MAX_LEAF {
            nodes[ni].first = (base + s) as u32;
            nodes[ni].count = (e - s) as u32;
            continue;
        }
        let (mid, lb, rb) = split(&mut items[s..e], cb);
        let left = nodes.len();
        nodes.push(Node::EMPTY);
        nodes.push(Node::EMPTY);
        nodes[ni].first = left as u32;
        nodes[ni].count = 0;
        stack.push((left, s, s + mid, lb));
        stack.push((left + 1, s + mid, e, rb));
    }
    // fit the boxes: children always come after their parent
    for ni in (0..nodes.len()).rev() {
        let nd = nodes[ni];
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        if nd.count > 0 {
            let s = nd.first as usize - base;
            for it in &items[s..s + nd.count as usize] {
                let (l, h) = bounds(it.id as usize);
                let (l, h) = if l.is_finite() && h.is_finite() {
                    (l, h)
                } else {
                    (DVec3::splat(f64::NEG_INFINITY), DVec3::splat(f64::INFINITY))
                };
                for a in 0..3 {
                    lo[a] = lo[a].min(f32_down(l[a]));
                    hi[a] = hi[a].max(f32_up(h[a]));
                }
            }
        } else {
            for c in [nodes[nd.first as usize], nodes[nd.first as usize + 1]] {
                for a in 0..3 {
                    lo[a] = lo[a].min(c.lo[a]);
                    hi[a] = hi[a].max(c.hi[a]);
                }
            }
        }
        nodes[ni].lo = lo;
        nodes[ni].hi = hi;
    }
    nodes
}

/// Closed boxes `[alo, ahi]` and `[blo, bhi]` meet.
pub fn boxes_meet(alo: DVec3, ahi: DVec3, blo: DVec3, bhi: DVec3) -> bool {
    alo.x <= bhi.x
        && blo.x <= ahi.x
        && alo.y <= bhi.y
        && blo.y <= ahi.y
        && alo.z <= bhi.z
        && blo.z <= ahi.z
}

/// The closest point to `p` on the triangles `tris` (indexed by `bvh`, built over
/// their boxes): boxes of half-width `r` around `p`, doubled until the closest point
/// found lies within the box. `None` when there is no triangle. Among equally near
/// triangles the first visited wins, so on a shared edge the point may differ in the
/// last bit from [`closest_triangle`]'s (the blend's outputs depend on it).
pub fn closest_on_triangles(bvh: &Bvh, tris: &[[DVec3; 3]], p: DVec3, r: f64) -> Option<DVec3> {
    let mut r = r.max(f64::MIN_POSITIVE);
    for _ in 0..64 {
        let mut best: Option<(f64, DVec3)> = None;
        bvh.query(p - DVec3::splat(r), p + DVec3::splat(r), |i| {
            let [a, b, c] = tris[i];
            let q = closest_point_on_triangle(p, a, b, c);
            let d = (q - p).length();
            if best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, q));
            }
            false
        });
        if let Some((_, q)) = best.filter(|&(d, _)| d <= r) {
            return Some(q);
        }
        r *= 2.0;
    }
    // reached only for non-finite input or distances beyond 2^64 r: every triangle
    tris.iter()
        .map(|&[a, b, c]| closest_point_on_triangle(p, a, b, c))
        .min_by(|x, y| (*x - p).length().total_cmp(&(*y - p).length()))
}

/// The triangle of `tris` (indexed by `bvh`, built over their boxes) closest to `p`,
/// with the closest point on it: the smallest squared distance, ties to the lowest
/// index, which is what a scan in index order finds ([`closest_by_scan`]). Boxes of
/// half-width `r` around `p`, doubled until the point found lies within the box (every
/// triangle at most that far was then visited). `None` when there is no triangle.
pub fn closest_triangle(
    bvh: &Bvh,
    tris: &[[DVec3; 3]],
    p: DVec3,
    r: f64,
) -> Option<(usize, DVec3)> {
    let mut r = r.max(f64::MIN_POSITIVE);
    for _ in 0..64 {
        let mut best: Option<(f64, usize, DVec3)> = None;
        bvh.query(p - DVec3::splat(r), p + DVec3::splat(r), |i| {
            let [a, b, c] = tris[i];
            let q = closest_point_on_triangle(p, a, b, c);
            let d = (q - p).length_squared();
            if best.is_none_or(|(bd, bi, _)| d < bd || (d == bd && i < bi)) {
                best = Some((d, i, q));
            }
            false
        });
        if let Some((_, i, q)) = best.filter(|&(d, _, _)| d <= r * r) {
            return Some((i, q));
        }
        r *= 2.0;
    }
    // reached only for non-finite input or distances beyond 2^64 r
    closest_by_scan(tris, p)
}

/// [`closest_triangle`] by a scan of every triangle in index order (the first of the
/// nearest).
fn closest_by_scan(tris: &[[DVec3; 3]], p: DVec3) -> Option<(usize, DVec3)> {
    let mut best: Option<(f64, usize, DVec3)> = None;
    for (i, &[a, b, c]) in tris.iter().enumerate() {
        let q = closest_point_on_triangle(p, a, b, c);
        let d = (q - p).length_squared();
        if best.is_none_or(|(bd, _, _)| d < bd) {
            best = Some((d, i, q));
        }
    }
    best.map(|(_, i, q)| (i, q))
}

/// Bounding box of a triangle.
pub fn tri_box(t: &[DVec3; 3]) -> (DVec3, DVec3) {
    (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn down_ref(x: f64) -> f32 {
        let y = x as f32;
        if (y as f64) > x {
            step_f32(y, false)
        } else {
            y
        }
    }

    fn up_ref(x: f64) -> f32 {
        let y = x as f32;
        if (y as f64) < x {
            step_f32(y, true)
        } else {
            y
        }
    }

    #[test]
    fn f32_rounding_edge_cases() {
        let tiny = f64::from(f32::from_bits(1));
        for x in [
            0.0,
            -0.0,
            1e-50,
            -1e-50,
            tiny,
            -tiny,
            tiny / 3.0,
            -tiny / 3.0,
            f64::from(f32::MAX),
            f64::from(f32::MAX) * 1.5,
            -f64::from(f32::MAX) * 1.5,
            f64::INFINITY,
            f64::NEG_INFINITY,
            0.1,
            -0.1,
            1.0,
            -1.0,
            1.0 + 1e-12,
            -1.0 - 1e-12,
        ] {
            assert_eq!(f32_down(x).to_bits(), down_ref(x).to_bits(), "down {x:e}");
            assert_eq!(f32_up(x).to_bits(), up_ref(x).to_bits(), "up {x:e}");
            assert!(
                f64::from(f32_down(x)) <= x && x <= f64::from(f32_up(x)),
                "{x:e}"
            );
        }
        assert!(f32_down(f64::NAN).is_nan() && f32_up(f64::NAN).is_nan());
    }

    proptest! {
        #[test]
        fn f32_rounding_matches_the_stepwise_one(bits in any::<u64>()) {
            let x = f64::from_bits(bits);
            prop_assume!(!x.is_nan());
            prop_assert_eq!(f32_down(x).to_bits(), down_ref(x).to_bits());
            prop_assert_eq!(f32_up(x).to_bits(), up_ref(x).to_bits());
        }
    }

    fn brute(boxes: &[(DVec3, DVec3)], lo: DVec3, hi: DVec3) -> Vec<usize> {
        (0..boxes.len())
            .filter(|&i| boxes_meet(boxes[i].0, boxes[i].1, lo, hi))
            .collect()
    }

    #[test]
    fn rounding_is_outward() {
        for x in [
            0.1f64, -0.1, 1e-30, -1e-30, 0.0, 3.0, 1e300, -1e300, 16777217.0,
        ] {
            assert!((f32_down(x) as f64) <= x, "{x}");
            assert!((f32_up(x) as f64) >= x, "{x}");
        }
    }

    #[test]
    fn empty_and_single() {
        let b = Bvh::build(0, |_| (DVec3::ZERO, DVec3::ONE));
        assert!(b.is_empty());
        assert!(!b.query(DVec3::ZERO, DVec3::ONE, |_| true));
        let b = Bvh::build(1, |_| (DVec3::ZERO, DVec3::ONE));
        let mut hits = Vec::new();
        b.query(DVec3::splat(0.5), DVec3::splat(2.0), |i| {
            hits.push(i);
            false
        });
        assert_eq!(hits, vec![0]);
        hits.clear();
        b.query(DVec3::splat(1.5), DVec3::splat(2.0), |i| {
            hits.push(i);
            false
        });
        assert!(hits.is_empty());
    }

    #[test]
    fn identical_boxes_split_by_count() {
        let n = 1000;
        let b = Bvh::build(n, |_| (DVec3::ZERO, DVec3::ONE));
        let mut hits = Vec::new();
        b.query(DVec3::ONE, DVec3::splat(3.0), |i| {
            hits.push(i);
            false
        });
        hits.sort_unstable();
        assert_eq!(hits, (0..n).collect::<Vec<_>>());
    }

    #[test]
    fn large_tree_built_in_parallel_matches_brute_force() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let n = 3 * PAR_MIN + 17;
        let boxes: Vec<(DVec3, DVec3)> = (0..n)
            .map(|_| {
                let a = DVec3::new(rng.random(), rng.random(), rng.random()) * 100.0;
                let d = DVec3::new(rng.random(), rng.random(), rng.random());
                (a, a + d)
            })
            .collect();
        let bvh = Bvh::build(n, |i| boxes[i]);
        assert_eq!(bvh.len(), n);
        let mut seen = vec![false; n];
        for &p in &bvh.perm {
            assert!(!std::mem::replace(&mut seen[p as usize], true));
        }
        for q in 0..20 {
            let lo = DVec3::new(rng.random(), rng.random(), rng.random()) * 100.0;
            let hi = lo + DVec3::splat(q as f64 * 0.5);
            let mut got = Vec::new();
            bvh.query(lo, hi, |i| {
                if boxes_meet(boxes[i].0, boxes[i].1, lo, hi) {
                    got.push(i);
                }
                false
            });
            got.sort_unstable();
            assert_eq!(got, brute(&boxes, lo, hi));
        }
        // every node box contains its children's
        for nd in &bvh.nodes {
            if nd.count == 0 {
                for c in [
                    bvh.nodes[nd.first as usize],
                    bvh.nodes[nd.first as usize + 1],
                ] {
                    assert!((0..3).all(|a| nd.lo[a] <= c.lo[a] && c.hi[a] <= nd.hi[a]));
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The walk of a tree against itself visits each unordered pair once, and
        /// every pair of meeting boxes among them.
        #[test]
        fn self_pairs_match_brute_force(
            tris in prop::collection::vec(prop::array::uniform9(-10.0f64..10.0), 1..300),
            scale in 0.01f64..5.0,
        ) {
            let boxes: Vec<(DVec3, DVec3)> = tris
                .iter()
                .map(|t| {
                    let a = DVec3::new(t[0], t[1], t[2]);
                    let b = a + DVec3::new(t[3], t[4], t[5]) * (scale / 10.0);
                    let c = a + DVec3::new(t[6], t[7], t[8]) * (scale / 10.0);
                    tri_box(&[a, b, c])
                })
                .collect();
            let bvh = Bvh::build(boxes.len(), |i| boxes[i]);
            let mut got = Vec::new();
            bvh.self_pairs(|i, j| {
                assert_ne!(i, j);
                got.push((i.min(j), i.max(j)));
            });
            got.sort_unstable();
            prop_assert!(got.windows(2).all(|w| w[0] != w[1]), "a pair twice");
            for i in 0..boxes.len() {
                for j in i + 1..boxes.len() {
                    if boxes_meet(boxes[i].0, boxes[i].1, boxes[j].0, boxes[j].1) {
                        prop_assert!(got.binary_search(&(i, j)).is_ok(), "pair {} {} missed", i, j);
                    }
                }
            }
        }

        /// The tree's closest triangle is the scan's (smallest squared distance, the
        /// lowest index among equals, here made by repeating triangles), from any
        /// starting radius and for points far outside.
        #[test]
        fn closest_triangle_matches_the_scan(
            tris in prop::collection::vec(prop::array::uniform9(-10.0f64..10.0), 1..120),
            pts in prop::collection::vec(prop::array::uniform3(-40.0f64..40.0), 1..20),
            r in 0.001f64..5.0,
            twice in 0usize..120,
        ) {
            let mut tris: Vec<[DVec3; 3]> = tris
                .iter()
                .map(|t| {
                    let a = DVec3::new(t[0], t[1], t[2]);
                    [a, a + DVec3::new(t[3], t[4], t[5]) * 0.2, a + DVec3::new(t[6], t[7], t[8]) * 0.2]
                })
                .collect();
            let again = tris[twice % tris.len()];
            tris.push(again);
            let bvh = Bvh::build(tris.len(), |i| tri_box(&tris[i]));
            for p in &pts {
                let p = DVec3::from_array(*p);
                let want = closest_by_scan(&tris, p);
                prop_assert_eq!(closest_triangle(&bvh, &tris, p, r), want);
            }
            prop_assert_eq!(closest_triangle(&Bvh::build(0, |_| tri_box(&tris[0])), &[], DVec3::ZERO, r), None);
        }

        #[test]
        fn query_matches_brute_force(
            tris in prop::collection::vec(prop::array::uniform9(-100.0f64..100.0), 1..400),
            q in prop::array::uniform6(-120.0f64..120.0),
            scale in 0.001f64..50.0,
        ) {
            // small triangles spread over the cube
            let boxes: Vec<(DVec3, DVec3)> = tris
                .iter()
                .map(|t| {
                    let a = DVec3::new(t[0], t[1], t[2]);
                    let b = a + DVec3::new(t[3], t[4], t[5]) * (scale / 100.0);
                    let c = a + DVec3::new(t[6], t[7], t[8]) * (scale / 100.0);
                    tri_box(&[a, b, c])
                })
                .collect();
            let bvh = Bvh::build(boxes.len(), |i| boxes[i]);
            prop_assert_eq!(bvh.len(), boxes.len());
            let lo = DVec3::new(q[0].min(q[3]), q[1].min(q[4]), q[2].min(q[5]));
            let hi = DVec3::new(q[0].max(q[3]), q[1].max(q[4]), q[2].max(q[5]));
            let mut got = Vec::new();
            bvh.query(lo, hi, |i| {
                if boxes_meet(boxes[i].0, boxes[i].1, lo, hi) {
                    got.push(i);
                }
                false
            });
            got.sort_unstable();
            prop_assert_eq!(got, brute(&boxes, lo, hi));
            // every primitive is found by its own box (touching counts)
            for (i, &(l, h)) in boxes.iter().enumerate() {
                let mut found = false;
                bvh.query(l, h, |j| {
                    found |= j == i;
                    found
                });
                prop_assert!(found);
            }
        }
    }
}
