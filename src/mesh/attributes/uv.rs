//! The UV polygon of a patch's rim: signed areas and the simplicity test that decide
//! whether a harmonic map into it is accepted.

use glam::DVec2;

/// Twice the signed area of a UV triangle.
pub(super) fn area(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

/// True when no two segments that share no end point cross or touch.
pub(super) fn simple(segs: &[(DVec2, DVec2)]) -> bool {
    let orient = |a: DVec2, b: DVec2, c: DVec2| robust_sign(area(a, b, c));
    for (i, &(a, b)) in segs.iter().enumerate() {
        if a == b {
            return false;
        }
        for &(c, d) in segs.iter().skip(i + 1) {
            if a == c || a == d || b == c || b == d {
                continue;
            }
            let (o1, o2) = (orient(a, b, c), orient(a, b, d));
            let (o3, o4) = (orient(c, d, a), orient(c, d, b));
            if o1 == 0 && o2 == 0 && o3 == 0 && o4 == 0 {
                // collinear: they meet only when their extents overlap
                let overlap =
                    |p: f64, q: f64, r: f64, s: f64| p.max(q) >= r.min(s) && r.max(s) >= p.min(q);
                if overlap(a.x, b.x, c.x, d.x) && overlap(a.y, b.y, c.y, d.y) {
                    return false;
                }
            } else if o1 * o2 <= 0 && o3 * o4 <= 0 {
                return false;
            }
        }
    }
    true
}

fn robust_sign(x: f64) -> i32 {
    if x > 0.0 {
        1
    } else if x < 0.0 {
        -1
    } else {
        0
    }
}
