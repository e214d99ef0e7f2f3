//! The edges of the 3D Delaunay triangulation of a small point set: the search space
//! CGAL's `triangulate_hole` restricts its minimum-weight triangulation (Liepa 2003,
//! "Filling holes in meshes") to by default (`use_delaunay_triangulation`), not from
//! the four papers; measured in docs/measurements.md.
//!
//! Bowyer–Watson insertion into a bounding tetrahedron, deciding by Shewchuk's exact
//! `orient3d` and `insphere` (`robust`). A hole's loop is often degenerate for a 3D
//! Delaunay triangulation (coplanar, cocircular on a machined part), which CGAL meets
//! with symbolic perturbation; here the points are moved by a seeded random amount of
//! 1e-9 of the set's diameter for the predicates only (the Delaunay triangulation of
//! the moved points is one of the original's where that is not unique), and a
//! degenerate tetrahedron that still arises gives `None`. Near the convex hull the
//! bounding vertices can take the place of a hull facet whose sphere is huge (a flat
//! set): there the edges are those of the planar Delaunay triangulation, which is what
//! a flat loop wants. Quadratic time: for loops up to a few hundred points.

use crate::fasthash::HashMap;
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robust::Coord3D;

fn c3(p: DVec3) -> Coord3D<f64> {
    Coord3D {
        x: p.x,
        y: p.y,
        z: p.z,
    }
}

fn orient(p: &[DVec3], t: [u32; 4]) -> f64 {
    let [a, b, c, d] = t.map(|i| c3(p[i as usize]));
    robust::orient3d(a, b, c, d)
}

/// The edges `(a, b)`, `a < b`, of a Delaunay triangulation of `pts` (indices into
/// `pts`), sorted; `None` for fewer than 4 points, a non-finite coordinate, or a
/// degenerate configuration the perturbation did not resolve.
pub fn delaunay_edges(pts: &[DVec3]) -> Option<Vec<(u32, u32)>> {
    let n = pts.len();
    if n < 4 || pts.iter().any(|p| !p.is_finite()) {
        return None;
    }
    let (lo, hi) = pts.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let diam = (hi - lo).length();
    if diam <= 0.0 || !diam.is_finite() {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
    let jitter = 1e-9 * diam;
    let mut p: Vec<DVec3> = pts
        .iter()
        .map(|&q| {
            q + jitter
                * DVec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
        })
        .collect();
    // a tetrahedron whose inscribed sphere (radius R / sqrt 3) holds the set
    let c = 0.5 * (lo + hi);
    let r = 1e3 * diam;
    p.extend(
        [
            DVec3::new(1.0, 1.0, 1.0),
            DVec3::new(1.0, -1.0, -1.0),
            DVec3::new(-1.0, 1.0, -1.0),
            DVec3::new(-1.0, -1.0, 1.0),
        ]
        .map(|d| c + r * d),
    );
    let s = n as u32;
    let mut first = [s, s + 1, s + 2, s + 3];
    if orient(&p, first) < 0.0 {
        first.swap(0, 1);
    }
    // tetrahedra, positively oriented (robust's convention), with a liveness flag
    let mut tets: Vec<[u32; 4]> = vec![first];
    let mut alive: Vec<bool> = vec![true];
    let mut bad: Vec<usize> = Vec::new();
    let mut faces: HashMap<[u32; 3], Option<[u32; 3]>> = HashMap::default();
    for v in 0..s {
        let q = c3(p[v as usize]);
        bad.clear();
        for (i, t) in tets.iter().enumerate() {
            if !alive[i] {
                continue;
            }
            let [a, b, cc, d] = t.map(|j| c3(p[j as usize]));
            if robust::insphere(a, b, cc, d, q) > 0.0 {
                bad.push(i);
            }
        }
        if bad.is_empty() {
            // a repeated point: on every sphere through its twin
            continue;
        }
        // the cavity's boundary: faces of exactly one bad tetrahedron, each kept with
        // the orientation that sees the tetrahedron on its positive side
        faces.clear();
        for &i in &bad {
            alive[i] = false;
            let [a, b, cc, d] = tets[i];
            for f in [[b, cc, d], [a, d, cc], [a, b, d], [a, cc, b]] {
                let mut key = f;
                key.sort_unstable();
                faces
                    .entry(key)
                    .and_modify(|e| *e = None)
                    .or_insert(Some(f));
            }
        }
        for f in faces.values().flatten() {
            // [b, c, d] of a positive [a, b, c, d] has a on its positive side: the new
            // tetrahedron puts v where a was
            let t = [v, f[0], f[1], f[2]];
            let o = orient(&p, t);
            if o <= 0.0 {
                return None;
            }
            tets.push(t);
            alive.push(true);
        }
    }
    let mut edges: Vec<(u32, u32)> = Vec::with_capacity(7 * n);
    for (t, _) in tets.iter().zip(&alive).filter(|(_, &a)| a) {
        for (i, j) in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
            let (a, b) = (t[i], t[j]);
            if a < s && b < s {
                edges.push((a.min(b), a.max(b)));
            }
        }
    }
    edges.sort_unstable();
    edges.dedup();
    Some(edges)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `(a, b)` is a Delaunay edge of `pts` by brute force: some sphere through
    /// both holds no other point. For points in general position that is: some
    /// Delaunay tetrahedron, i.e. some empty sphere through a, b and two more points.
    fn brute_force_edges(pts: &[DVec3]) -> Vec<(u32, u32)> {
        let n = pts.len();
        let mut out = Vec::new();
        let p = |i: usize| c3(pts[i]);
        for a in 0..n {
            for b in a + 1..n {
                let mut found = false;
                'search: for c in 0..n {
                    for d in c + 1..n {
                        if [a, b].contains(&c) || [a, b].contains(&d) {
                            continue;
                        }
                        let mut t = [a, b, c, d];
                        let o = robust::orient3d(p(t[0]), p(t[1]), p(t[2]), p(t[3]));
                        if o == 0.0 {
                            continue;
                        }
                        if o < 0.0 {
                            t.swap(0, 1);
                        }
                        let empty = (0..n).filter(|e| !t.contains(e)).all(|e| {
                            robust::insphere(p(t[0]), p(t[1]), p(t[2]), p(t[3]), p(e)) < 0.0
                        });
                        if empty {
                            found = true;
                            break 'search;
                        }
                    }
                }
                if found {
                    out.push((a as u32, b as u32));
                }
            }
        }
        out
    }

    #[test]
    fn random_points_give_the_brute_force_delaunay_edges() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for n in [4usize, 5, 9, 17, 30] {
            let pts: Vec<DVec3> = (0..n)
                .map(|_| {
                    DVec3::new(
                        rng.random_range(0.0..1.0),
                        rng.random_range(0.0..1.0),
                        rng.random_range(0.0..1.0),
                    )
                })
                .collect();
            let got = delaunay_edges(&pts).expect("general position");
            assert_eq!(got, brute_force_edges(&pts), "{n} points");
        }
    }

    #[test]
    fn a_tetrahedron_has_its_six_edges() {
        let pts = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        let e = delaunay_edges(&pts).expect("edges");
        assert_eq!(e, vec![(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]);
    }

    #[test]
    fn a_flat_circle_gives_a_planar_triangulation() {
        // 12 cocircular points in a plane: every triangulation of the polygon is
        // Delaunay; the perturbed one must be a triangulation (the 12 sides and 9
        // non-crossing diagonals), each side among the edges
        let n = 12u32;
        let pts: Vec<DVec3> = (0..n)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / n as f64;
                DVec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let e = delaunay_edges(&pts).expect("edges");
        for i in 0..n {
            let j = (i + 1) % n;
            assert!(e.contains(&(i.min(j), i.max(j))), "side {i}-{j}: {e:?}");
        }
        assert!(e.len() >= (2 * n - 3) as usize, "{}", e.len());
    }

    #[test]
    fn too_few_or_bad_points_give_none() {
        assert!(delaunay_edges(&[DVec3::ZERO, DVec3::X, DVec3::Y]).is_none());
        let nan = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::splat(f64::NAN)];
        assert!(delaunay_edges(&nan).is_none());
        assert!(delaunay_edges(&[DVec3::ONE; 5]).is_none());
    }
}
