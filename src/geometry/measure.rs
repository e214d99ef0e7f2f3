//! Small geometric helpers shared by the methods and the checks.

use glam::{DVec2, DVec3};

/// Twice the area vector of a triangle.
#[inline]
pub fn tri_normal_raw(a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    (b - a).cross(c - a)
}

/// Area of a triangle.
#[inline]
pub fn tri_area(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    0.5 * tri_normal_raw(a, b, c).length()
}

/// Circumradius of a triangle (infinite for a degenerate one).
pub fn circumradius(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let la = (b - c).length();
    let lb = (a - c).length();
    let lc = (a - b).length();
    let area2 = tri_normal_raw(a, b, c).length(); // 2 * area
    if area2 <= 0.0 {
        return f64::INFINITY;
    }
    la * lb * lc / (2.0 * area2)
}

/// Paper 002's quality `Qt = shortest edge / circumradius` (sqrt 3 for equilateral).
pub fn quality(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let r = circumradius(a, b, c);
    if !r.is_finite() || r <= 0.0 {
        return 0.0;
    }
    let s = (b - c).length().min((a - c).length()).min((a - b).length());
    s / r
}

/// The three interior angles (radians) at a, b, c.
pub fn angles(a: DVec3, b: DVec3, c: DVec3) -> [f64; 3] {
    [angle_at(a, b, c), angle_at(b, c, a), angle_at(c, a, b)]
}

/// The smallest interior angle (radians): the one opposite the shortest edge (one
/// `atan2` instead of three).
pub fn smallest_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (la, lb, lc) = (
        (c - b).length_squared(),
        (a - c).length_squared(),
        (b - a).length_squared(),
    );
    if la <= lb && la <= lc {
        angle_at(a, b, c)
    } else if lb <= lc {
        angle_at(b, c, a)
    } else {
        angle_at(c, a, b)
    }
}

/// Sine of the smallest interior angle (which is at most 60 degrees, so the sine is
/// monotonic in it): cheaper than [`smallest_angle`] for comparisons.
pub fn smallest_angle_sin(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (la, lb, lc) = (
        (b - c).length_squared(),
        (c - a).length_squared(),
        (a - b).length_squared(),
    );
    let (p, q, r, l1, l2) = if la <= lb && la <= lc {
        (a, b, c, lc, lb)
    } else if lb <= lc {
        (b, c, a, la, lc)
    } else {
        (c, a, b, lb, la)
    };
    let d = (l1 * l2).sqrt();
    if d > 0.0 {
        (q - p).cross(r - p).length() / d
    } else {
        0.0
    }
}

/// The smallest interior angle (radians) by the law of cosines at the corner opposite
/// the shortest edge (0 for a degenerate triangle); the refinement's reading, which
/// differs from [`smallest_angle`] in the last bits.
pub fn smallest_angle_by_cosines(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let mut l = [
        (b - c).length_squared(),
        (c - a).length_squared(),
        (a - b).length_squared(),
    ];
    l.sort_unstable_by(|x, y| x.total_cmp(y));
    let [s, m, g] = l;
    if m.is_nan() || g.is_nan() || m <= 0.0 || g <= 0.0 {
        return 0.0;
    }
    ((m + g - s) / (2.0 * (m * g).sqrt()))
        .clamp(-1.0, 1.0)
        .acos()
}

/// The angle at `p` between the directions to `q` and `r` (radians, 0 when undefined).
pub fn angle_at(p: DVec3, q: DVec3, r: DVec3) -> f64 {
    let u = q - p;
    let v = r - p;
    let cr = u.cross(v).length();
    let dt = u.dot(v);
    if cr == 0.0 && dt == 0.0 {
        0.0
    } else {
        cr.atan2(dt)
    }
}

/// Cotangent of the angle at `p` in triangle (p, q, r), clamped to a safe range.
pub fn cot_at(p: DVec3, q: DVec3, r: DVec3) -> f64 {
    let u = q - p;
    let v = r - p;
    let cr = u.cross(v).length();
    if cr <= 1e-300 {
        return 0.0;
    }
    (u.dot(v) / cr).clamp(-1e3, 1e3)
}

/// Best-fit plane normal of a closed polygon (Newell's method), unit or zero.
pub fn newell_normal(pts: &[DVec3]) -> DVec3 {
    let mut n = DVec3::ZERO;
    let k = pts.len();
    for i in 0..k {
        let a = pts[i];
        let b = pts[(i + 1) % k];
        n.x += (a.y - b.y) * (a.z + b.z);
        n.y += (a.z - b.z) * (a.x + b.x);
        n.z += (a.x - b.x) * (a.y + b.y);
    }
    n.normalize_or_zero()
}

/// Area of a closed polygon projected on its best-fit plane: half the length of its
/// vector area `Σ (p_i - c) × (p_{i+1} - c)`. A lower bound of the area of any
/// surface the polygon bounds (equal for a planar polygon).
pub fn vector_area(pts: &[DVec3]) -> f64 {
    let c = centroid(pts);
    let k = pts.len();
    let mut n = DVec3::ZERO;
    for i in 0..k {
        n += (pts[i] - c).cross(pts[(i + 1) % k] - c);
    }
    0.5 * n.length()
}

/// Centroid of points.
pub fn centroid(pts: &[DVec3]) -> DVec3 {
    if pts.is_empty() {
        return DVec3::ZERO;
    }
    pts.iter().copied().sum::<DVec3>() / pts.len() as f64
}

/// `q` strictly inside the polygon `poly` (crossing number; floating point, not exact).
pub fn point_in_polygon(poly: &[DVec2], q: DVec2) -> bool {
    let mut c = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a.y > q.y) != (b.y > q.y) && q.x < a.x + (q.y - a.y) / (b.y - a.y) * (b.x - a.x) {
            c = !c;
        }
    }
    c
}

/// The point of triangle `abc` closest to `p` (Ericson, Real-Time Collision
/// Detection, §5.1.5: the Voronoi region of a corner, an edge or the face). A
/// degenerate triangle gives a point of one of its edges.
pub fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() < f64::MIN_POSITIVE {
        // degenerate: the nearest of the three edges
        let on = |s: DVec3, e: DVec3| {
            let d = e - s;
            let t = if d.length_squared() > 0.0 {
                ((p - s).dot(d) / d.length_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            s + d * t
        };
        return [on(a, b), on(b, c), on(c, a)]
            .into_iter()
            .min_by(|x, y| {
                (*x - p)
                    .length_squared()
                    .total_cmp(&(*y - p).length_squared())
            })
            .unwrap_or(a);
    }
    let v = vb / denom;
    let w = vc / denom;
    a + ab * v + ac * w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_quality_is_sqrt3() {
        let a = DVec3::new(0.0, 0.0, 0.0);
        let b = DVec3::new(1.0, 0.0, 0.0);
        let c = DVec3::new(0.5, 3f64.sqrt() / 2.0, 0.0);
        assert!((quality(a, b, c) - 3f64.sqrt()).abs() < 1e-12);
        let s: f64 = angles(a, b, c).iter().sum();
        assert!((s - std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn vector_area_of_a_square_and_a_bent_loop() {
        let sq = [DVec3::ZERO, DVec3::X, DVec3::X + DVec3::Y, DVec3::Y];
        assert!((vector_area(&sq) - 1.0).abs() < 1e-12);
        // a loop folded at a right angle: the projection is smaller than the surface
        let bent = [
            DVec3::ZERO,
            DVec3::X,
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(0.0, 1.0, 1.0),
            DVec3::Y,
        ];
        let a = vector_area(&bent);
        assert!(a > 1.0 && a < 2.0, "{a}");
    }

    #[test]
    fn degenerate_quality_is_zero() {
        let a = DVec3::ZERO;
        assert_eq!(quality(a, DVec3::X, DVec3::X * 2.0), 0.0);
    }

    #[test]
    fn closest_points_on_a_triangle_against_a_dense_sampling() {
        let (a, b, c) = (
            DVec3::ZERO,
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(0.5, 1.5, 0.3),
        );
        let mut rng_state = 7u64;
        let mut r = || {
            rng_state = rng_state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((rng_state >> 11) as f64 / (1u64 << 53) as f64) * 6.0 - 3.0
        };
        for _ in 0..200 {
            let p = DVec3::new(r(), r(), r());
            let q = closest_point_on_triangle(p, a, b, c);
            // the oracle: the nearest of a fine barycentric grid
            let n = 200;
            let mut best = f64::INFINITY;
            for i in 0..=n {
                for j in 0..=(n - i) {
                    let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                    let s = a + (b - a) * u + (c - a) * v;
                    best = best.min((s - p).length());
                }
            }
            let d = (q - p).length();
            assert!(d <= best + 1e-12 && d > best - 0.02, "{p}: {d} vs {best}");
        }
        // a degenerate triangle: the nearest point of its segment
        let q = closest_point_on_triangle(DVec3::new(1.0, 1.0, 0.0), a, b, b * 0.5);
        assert!((q - DVec3::new(1.0, 0.0, 0.0)).length() < 1e-12, "{q}");
    }
}
