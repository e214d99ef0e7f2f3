//! Tests of the exact predicates: hand-made cases (touching, shared corners, coplanar,
//! near-parallel, degenerate) and agreement with an independent separating-axis test.

use super::*;
use proptest::prelude::*;

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

const NONE: [u64; 3] = [10, 11, 12];
const OTHER: [u64; 3] = [20, 21, 22];

fn plain(p: [DVec3; 3], q: [DVec3; 3]) -> bool {
    tri_tri(&p, &NONE, &q, &OTHER)
}

#[test]
fn disjoint_and_crossing() {
    let p = [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)];
    assert!(!plain(p, [v(0., 0., 1.), v(1., 0., 1.), v(0., 1., 1.)]));
    // q's plane cuts p's plane but q's segment there misses p
    assert!(!plain(p, [v(2., 2., -1.), v(3., 2., 1.), v(2., 3., 1.)]));
    // q pierces p
    assert!(plain(
        p,
        [v(0.2, 0.2, -1.), v(0.3, 0.2, 1.), v(0.2, 0.3, 1.)]
    ));
    // q straddles p's edge: a bar through the middle
    assert!(plain(
        p,
        [v(-1., 0.3, -0.5), v(2., 0.3, -0.5), v(0.1, 0.3, 0.5)]
    ));
}

#[test]
fn touching_counts_unless_shared() {
    let p = [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)];
    // q's corner touches the middle of p's edge from above: a real contact
    let q = [v(0.5, 0.0, 0.0), v(0.5, -1.0, 1.0), v(0.6, -1.0, 1.0)];
    assert!(plain(p, q));
    // the same corner coordinates, but a shared vertex, touch only there
    let q = [v(0., 0., 0.), v(-1., -1., 1.), v(-1., 0., 1.)];
    assert!(plain(p, q)); // not shared: touching at a point is an intersection
    assert!(!tri_tri(&p, &[1, 2, 3], &q, &[1, 5, 6]));
    // shared vertex, but q's far edge passes through p
    let q = [v(0., 0., 0.), v(0.3, 0.3, -1.), v(0.3, 0.3, 1.)];
    assert!(tri_tri(&p, &[1, 2, 3], &q, &[1, 5, 6]));
    // shared vertex, coplanar, q inside p's angle
    let q = [v(0., 0., 0.), v(0.2, 0.1, 0.), v(0.1, 0.2, 0.)];
    assert!(tri_tri(&p, &[1, 2, 3], &q, &[1, 5, 6]));
    // shared vertex, coplanar, q outside p's angle
    let q = [v(0., 0., 0.), v(-0.2, -0.1, 0.), v(-0.1, -0.2, 0.)];
    assert!(!tri_tri(&p, &[1, 2, 3], &q, &[1, 5, 6]));
    // shared vertex, coplanar, q's edge runs along p's edge
    let q = [v(0., 0., 0.), v(0.5, 0., 0.), v(0.5, -1., 0.)];
    assert!(tri_tri(&p, &[1, 2, 3], &q, &[1, 5, 6]));
}

#[test]
fn shared_edge_rules() {
    let p = [v(0., 0., 0.), v(1., 0., 0.), v(0.5, 1., 0.)];
    let pk = [1, 2, 3];
    let qk = [2, 1, 9];
    // flat continuation on the other side: no intersection
    assert!(!tri_tri(
        &p,
        &pk,
        &[v(1., 0., 0.), v(0., 0., 0.), v(0.5, -1., 0.)],
        &qk
    ));
    // hinge (not coplanar): only the edge is shared
    assert!(!tri_tri(
        &p,
        &pk,
        &[v(1., 0., 0.), v(0., 0., 0.), v(0.5, 0.5, 1.)],
        &qk
    ));
    // coplanar fold onto p: overlap beyond the edge
    assert!(tri_tri(
        &p,
        &pk,
        &[v(1., 0., 0.), v(0., 0., 0.), v(0.2, 0.3, 0.)],
        &qk
    ));
    // fold by a hair off the plane: exact, so no intersection
    assert!(!tri_tri(
        &p,
        &pk,
        &[v(1., 0., 0.), v(0., 0., 0.), v(0.2, 0.3, 1e-300)],
        &qk
    ));
    // the same triangle twice
    assert!(tri_tri(&p, &pk, &[p[1], p[2], p[0]], &[2, 3, 1]));
}

#[test]
fn coplanar_cases() {
    let p = [v(0., 0., 0.), v(2., 0., 0.), v(0., 2., 0.)];
    assert!(plain(p, [v(0.5, 0.5, 0.), v(3., 0.5, 0.), v(0.5, 3., 0.)]));
    // q inside p
    assert!(plain(
        p,
        [v(0.2, 0.2, 0.), v(0.5, 0.2, 0.), v(0.2, 0.5, 0.)]
    ));
    // p inside q
    assert!(plain(p, [v(-1., -1., 0.), v(9., -1., 0.), v(-1., 9., 0.)]));
    // beside each other, touching along part of an edge
    assert!(plain(p, [v(1., 1., 0.), v(3., 1., 0.), v(1., 3., 0.)]));
    // beside each other, apart
    assert!(!plain(p, [v(1.1, 1.1, 0.), v(3., 1.1, 0.), v(1.1, 3., 0.)]));
    // in a tilted plane, where no coordinate plane is the triangle's
    let m = |x: DVec3| v(x.x + 0.3 * x.y, x.y, 0.7 * x.x - 0.2 * x.y);
    let p2 = p.map(m);
    assert!(plain(
        p2,
        [v(0.2, 0.2, 0.), v(0.5, 0.2, 0.), v(0.2, 0.5, 0.)].map(m)
    ));
    assert!(!plain(
        p2,
        [v(1.1, 1.1, 0.), v(3., 1.1, 0.), v(1.1, 3., 0.)].map(m)
    ));
}

#[test]
fn near_parallel_is_exact() {
    let p = [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)];
    // almost parallel, one corner a hair below the plane over p: crosses p
    let q = [v(0.1, 0.1, -1e-30), v(5., 0.2, 1e-20), v(0.2, 5., 1e-20)];
    assert!(plain(p, q));
    // the same but the corner a hair above: all of q above p's plane
    let q = [v(0.1, 0.1, 1e-30), v(5., 0.2, 1e-20), v(0.2, 5., 1e-20)];
    assert!(!plain(p, q));
    // crossing p's plane only outside p
    let q = [v(1.0, 1.0, -1e-30), v(5., 0.2, 1e-20), v(0.2, 5., 1e-20)];
    assert!(!plain(p, q));
}

#[test]
fn degenerate_other_triangle() {
    let p = [v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.)];
    // a needle (collinear) through p
    let q = [v(0.2, 0.2, -1.), v(0.2, 0.2, 0.5), v(0.2, 0.2, 1.)];
    assert!(plain(p, q));
    let q = [v(2., 2., -1.), v(2., 2., 0.5), v(2., 2., 1.)];
    assert!(!plain(p, q));
    // a needle sharing p's corner, lying along p's edge: overlap beyond the corner
    let q = [v(0., 0., 0.), v(0.5, 0., 0.), v(0.25, 0., 0.)];
    assert!(tri_tri(&p, &[1, 2, 3], &q, &[1, 5, 6]));
    // a needle through the shared corner, pointing away on both sides in the plane
    let q = [v(0., 0., 0.), v(-0.5, 0.1, 0.), v(0.5, -0.1, 0.)];
    assert!(!tri_tri(&p, &[1, 2, 3], &q, &[1, 5, 6]));
    // ... and one that points into p on one side
    let q = [v(0., 0., 0.), v(-0.5, -0.5, 0.), v(0.5, 0.5, 0.)];
    assert!(tri_tri(&p, &[1, 2, 3], &q, &[1, 5, 6]));
    // two needles
    assert!(tri_tri_plain(
        &[v(0., 0., 0.), v(1., 1., 1.), v(2., 2., 2.)],
        &[v(0., 2., 0.), v(2., 0., 2.), v(1., 1., 1.)]
    ));
    assert!(!tri_tri_plain(
        &[v(0., 0., 0.), v(1., 1., 1.), v(2., 2., 2.)],
        &[v(3., 3., 3.), v(4., 4., 4.), v(5., 5., 5.)]
    ));
    assert!(tri_tri_plain(
        &[v(0., 0., 0.), v(1., 1., 1.), v(2., 2., 2.)],
        &[v(2., 2., 2.), v(4., 4., 4.), v(5., 5., 5.)]
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    /// The answer does not depend on the order of the triangles or their corners;
    /// and on small integer grids (many touching and coplanar cases) it agrees
    /// with a dense sampling reference when the reference finds a common point.
    #[test]
    fn symmetric_and_order_free(c in prop::array::uniform18(-3i32..4)) {
        let t = |o: usize| [0, 1, 2].map(|i| v(c[o + 3 * i] as f64, c[o + 3 * i + 1] as f64, c[o + 3 * i + 2] as f64));
        let (p, q) = (t(0), t(9));
        let r = tri_tri_plain(&p, &q);
        prop_assert_eq!(r, tri_tri_plain(&q, &p));
        prop_assert_eq!(r, tri_tri_plain(&[p[1], p[2], p[0]], &[q[2], q[1], q[0]]));
        // sampled points of p (barycentric grid) that lie exactly in q imply r
        let n = 8;
        for i in 0..=n {
            for j in 0..=(n - i) {
                let x = p[0] + (p[1] - p[0]) * (i as f64 / n as f64) + (p[2] - p[0]) * (j as f64 / n as f64);
                if proj_axis(q[0], q[1], q[2]).is_some() && x.is_finite() {
                    let d = o3(q[0], q[1], q[2], x);
                    let inside = d == 0.0 && seg_tri(x, x, &q);
                    if inside {
                        prop_assert!(r);
                    }
                }
            }
        }
    }
}

/// Separating-axis verdict in floating point: `Some(true/false)` when every
/// candidate axis is decisive by a margin, `None` when the case is too close
/// to call (or an axis is near zero).
fn sat(p: &[DVec3; 3], q: &[DVec3; 3]) -> Option<bool> {
    let ep = [p[1] - p[0], p[2] - p[1], p[0] - p[2]];
    let eq = [q[1] - q[0], q[2] - q[1], q[0] - q[2]];
    let (np, nq) = (ep[0].cross(ep[1]), eq[0].cross(eq[1]));
    let mut axes = vec![np, nq];
    for a in ep {
        axes.push(np.cross(a));
        for b in eq {
            axes.push(a.cross(b));
        }
    }
    for b in eq {
        axes.push(nq.cross(b));
    }
    let mut separated = false;
    for ax in axes {
        let len = ax.length();
        if len < 1e-6 {
            return None;
        }
        let proj = |t: &[DVec3; 3]| {
            let d = t.map(|x| x.dot(ax) / len);
            (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]))
        };
        let ((a0, a1), (b0, b1)) = (proj(p), proj(q));
        if a0 == a1 && b0 == b1 && a0 == b0 {
            continue; // both flat on this axis, at the same place: no information
        }
        let gap = (b0 - a1).max(a0 - b1);
        if gap.abs() < 1e-9 {
            return None;
        }
        separated |= gap > 0.0;
    }
    Some(!separated)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]
    /// Agrees with an independent separating-axis test wherever that one is
    /// decisive; and is unchanged by exact transformations (a power-of-two
    /// scale, swapping the triangles).
    #[test]
    fn agrees_with_separating_axes(c in prop::array::uniform18(-1.0f64..1.0), k in -40i32..40) {
        let t = |o: usize| [0, 1, 2].map(|i| v(c[o + 3 * i], c[o + 3 * i + 1], c[o + 3 * i + 2]));
        let (p, q) = (t(0), t(9));
        let r = tri_tri_plain(&p, &q);
        if let Some(expect) = sat(&p, &q) {
            prop_assert_eq!(r, expect);
        }
        let s = 2f64.powi(k);
        prop_assert_eq!(r, tri_tri_plain(&q.map(|x| x * s), &p.map(|x| x * s)));
    }

    /// Coplanar pairs (both in z = 0) against the same oracle.
    #[test]
    fn coplanar_agrees_with_separating_axes(c in prop::array::uniform12(-1.0f64..1.0)) {
        let t = |o: usize| [0, 1, 2].map(|i| v(c[o + 2 * i], c[o + 2 * i + 1], 0.0));
        let (p, q) = (t(0), t(6));
        if let Some(expect) = sat(&p, &q) {
            prop_assert_eq!(tri_tri_plain(&p, &q), expect);
        }
    }
}

fn t(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [DVec3; 3] {
    [DVec3::from(a), DVec3::from(b), DVec3::from(c)]
}

#[test]
fn nondegenerate_test_crossing_and_coplanar() {
    let a = t([0., 0., 0.], [2., 0., 0.], [0., 2., 0.]);
    let b = t([0.5, 0.5, -1.], [0.5, 0.5, 1.], [3., 3., 0.]);
    assert!(tri_tri_nondegenerate(&a, &b));
    let c = t([0.5, 0.5, 0.1], [0.6, 0.5, 1.], [3., 3., 0.1]);
    assert!(!tri_tri_nondegenerate(&a, &c));
    // coplanar: overlapping, contained, disjoint
    let b = t([0.5, 0.5, 0.], [3., 0.5, 0.], [0.5, 3., 0.]);
    assert!(tri_tri_nondegenerate(&a, &b));
    let c = t([0.1, 0.1, 0.], [0.3, 0.1, 0.], [0.1, 0.3, 0.]);
    assert!(tri_tri_nondegenerate(&a, &c) && tri_tri_nondegenerate(&c, &a));
    let d = t([3., 3., 0.], [4., 3., 0.], [3., 4., 0.]);
    assert!(!tri_tri_nondegenerate(&a, &d));
    // a degenerate triangle never meets anything here
    let e = t([0.2, 0.2, -1.], [0.2, 0.2, 0.], [0.2, 0.2, 1.]);
    assert!(tri_tri_plain(&a, &e) && !tri_tri_nondegenerate(&a, &e));
}

/// The floating-point filter never changes the exact answer.
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
        if tri_axis(&p).is_none() || tri_axis(&q).is_none() {
            continue;
        }
        let exact = tri_tri_plain(&p, &q);
        assert_eq!(tri_tri_nondegenerate(&p, &q), exact, "pair {i}");
        if far_apart(&p, &q) {
            assert!(!exact, "pair {i}");
        }
        hits += exact as usize;
    }
    assert!(hits > 1000);
}

#[test]
fn segments_in_the_plane() {
    let (a, b) = (p2(0., 0.), p2(2., 0.));
    // crossing
    assert!(segments_meet(a, b, p2(1., -1.), p2(1., 1.)));
    assert!(segments_cross(a, b, p2(1., -1.), p2(1., 1.)));
    // touching at an end: meets, does not cross
    assert!(segments_meet(a, b, p2(1., 0.), p2(1., 1.)));
    assert!(!segments_cross(a, b, p2(1., 0.), p2(1., 1.)));
    // collinear, overlapping and apart
    assert!(segments_meet(a, b, p2(1., 0.), p2(3., 0.)));
    assert!(!segments_meet(a, b, p2(2.5, 0.), p2(3., 0.)));
    assert!(!segments_cross(a, b, p2(1., 0.), p2(3., 0.)));
    // apart
    assert!(!segments_meet(a, b, p2(0., 1.), p2(2., 1.)));
}

#[test]
fn triangles_in_the_plane() {
    let a = [p2(0., 0.), p2(2., 0.), p2(0., 2.)];
    let cw = [a[0], a[2], a[1]];
    assert_eq!(ccw2d(cw), Some([a[0], a[1], a[2]]));
    assert_eq!(ccw2d([a[0], a[1], p2(4., 0.)]), None);
    // positive-area overlap, in either orientation
    let b = [p2(0.5, 0.5), p2(3., 0.5), p2(0.5, 3.)];
    assert!(overlap2d(a, b) && overlap2d(cw, b) && overlap2d(b, a));
    // sharing an edge from the other side: no positive-area overlap
    let c = [p2(2., 0.), p2(2., 2.), p2(0., 2.)];
    assert!(!overlap2d(a, c));
    // a degenerate first triangle counts as overlapping, a degenerate second not
    let d = [p2(0., 0.), p2(1., 0.), p2(2., 0.)];
    assert!(overlap2d(d, a) && !overlap2d(a, d));
    assert!(strictly_inside(p2(0.5, 0.5), a[0], a[1], a[2]));
    assert!(strictly_inside(p2(0.5, 0.5), a[0], a[2], a[1]));
    assert!(!strictly_inside(p2(1., 0.), a[0], a[1], a[2]));
}

#[test]
fn labeled_overlap_ignores_shared_corners() {
    let pa = [p2(0., 0.), p2(2., 0.), p2(0., 2.)];
    // shared edge 1-2, far corners on opposite sides: no overlap; same side: overlap
    let pb = [p2(2., 0.), p2(2., 2.), p2(0., 2.)];
    assert!(!overlap2d_labeled(&[0, 1, 2], &pa, &[1, 3, 2], &pb));
    let pf = [p2(2., 0.), p2(0.5, 0.5), p2(0., 2.)];
    assert!(overlap2d_labeled(&[0, 1, 2], &pa, &[1, 3, 2], &pf));
    // a shared corner only: touching there is no overlap, a crossing edge is
    let pc = [p2(0., 0.), p2(-1., 0.), p2(0., -1.)];
    assert!(!overlap2d_labeled(&[0, 1, 2], &pa, &[0, 4, 5], &pc));
    let pd = [p2(0., 0.), p2(1.5, 1.5), p2(-1., 1.)];
    assert!(overlap2d_labeled(&[0, 1, 2], &pa, &[0, 4, 5], &pd));
    // the same triangle
    assert!(overlap2d_labeled(
        &[0, 1, 2],
        &pa,
        &[2, 0, 1],
        &[pa[2], pa[0], pa[1]]
    ));
}

#[test]
fn segment_crossing_a_triangle() {
    let tri = t([0., 0., 0.], [2., 0., 0.], [0., 2., 0.]);
    let v = DVec3::new;
    assert!(seg_crosses_tri(v(0.5, 0.5, -1.), v(0.5, 0.5, 1.), &tri));
    // touching the triangle from one side counts
    assert!(seg_crosses_tri(v(0.5, 0.5, 0.), v(0.5, 0.5, 1.), &tri));
    // beside it, and in its plane: no
    assert!(!seg_crosses_tri(v(3., 3., -1.), v(3., 3., 1.), &tri));
    assert!(!seg_crosses_tri(v(-1., 0.5, 0.), v(3., 0.5, 0.), &tri));
    // the closed test counts the segment in the plane
    assert!(seg_tri(v(-1., 0.5, 0.), v(3., 0.5, 0.), &tri));
}
