//! Post-processing of the closed front: an angle-improving edge-swap pass inside the
//! patch and a simple umbrella relaxation of the new vertices (the local stand-in for
//! the patch fairing of `fill::kit::fair`).

use crate::fasthash::{FxMap, FxSet};
use crate::geometry::measure;
use glam::DVec3;
use std::f64::consts::PI;

fn unit_normal(a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    measure::tri_normal_raw(a, b, c).normalize_or_zero()
}

/// What an edge swap must respect.
pub struct SwapRules<'a> {
    /// Number of loop vertices (patch indices below it are loop vertices).
    pub k: usize,
    /// Loop-vertex pairs `(i, j)`, `i < j`, already joined by a mesh edge outside the
    /// patch: never create them.
    pub forbidden: &'a FxSet<(u32, u32)>,
    /// A swap must not create a triangle with a smaller angle than this (radians).
    pub min_angle: f64,
}

/// Swaps interior patch edges while that raises the smallest angle of the two
/// triangles on the edge (the 3D max-min-angle criterion), never onto an existing
/// edge, never folding the pair. A work queue of edges; the edges around a swapped
/// pair are queued again. At most `max_swaps_per_triangle * triangles` swaps.
/// Returns the number of swaps.
pub fn swap_edges(
    pos: &[DVec3],
    tris: &mut [[u32; 3]],
    rules: &SwapRules,
    max_swaps_per_triangle: usize,
) -> usize {
    let mut owner: FxMap<(u32, u32), usize> = FxMap::default();
    owner.reserve(tris.len() * 3);
    for (ti, t) in tris.iter().enumerate() {
        for c in 0..3 {
            owner.insert((t[c], t[(c + 1) % 3]), ti);
        }
    }
    let mut queue: Vec<(u32, u32)> = Vec::with_capacity(tris.len() * 3);
    for t in tris.iter() {
        for c in 0..3 {
            let (a, b) = (t[c], t[(c + 1) % 3]);
            if a < b && owner.contains_key(&(b, a)) {
                queue.push((a, b));
            }
        }
    }
    let cap = max_swaps_per_triangle.saturating_mul(tris.len());
    let min_sin = rules.min_angle.clamp(0.0, PI / 3.0).sin();
    let mut swaps = 0;
    while let Some((a, b)) = queue.pop() {
        if swaps >= cap {
            break;
        }
        let (Some(&t1), Some(&t2)) = (owner.get(&(a, b)), owner.get(&(b, a))) else {
            continue;
        };
        if t1 == t2 {
            continue;
        }
        let Some(cc) = tris[t1].iter().copied().find(|&x| x != a && x != b) else {
            continue;
        };
        let Some(d) = tris[t2].iter().copied().find(|&x| x != a && x != b) else {
            continue;
        };
        if cc == d || owner.contains_key(&(cc, d)) || owner.contains_key(&(d, cc)) {
            continue;
        }
        let key = (cc.min(d), cc.max(d));
        if (cc as usize) < rules.k && (d as usize) < rules.k && rules.forbidden.contains(&key) {
            continue;
        }
        let (pa, pb, pc, pd) = (
            pos[a as usize],
            pos[b as usize],
            pos[cc as usize],
            pos[d as usize],
        );
        let old =
            measure::smallest_angle_sin(pa, pb, pc).min(measure::smallest_angle_sin(pb, pa, pd));
        // new triangles (d, b, c) and (c, a, d)
        let new =
            measure::smallest_angle_sin(pd, pb, pc).min(measure::smallest_angle_sin(pc, pa, pd));
        let better = new > old + 1e-9;
        if !better || new < min_sin {
            continue;
        }
        let n1 = unit_normal(pa, pb, pc);
        let n2 = unit_normal(pb, pa, pd);
        let m1 = unit_normal(pd, pb, pc);
        let m2 = unit_normal(pc, pa, pd);
        let avg = n1 + n2;
        // no flipped triangle, no sharper crease than before (or than 30 degrees)
        if m1.dot(avg) <= 0.0 || m2.dot(avg) <= 0.0 || m1.dot(m2) < n1.dot(n2).min(0.866) {
            continue;
        }
        tris[t1] = [d, b, cc];
        tris[t2] = [cc, a, d];
        owner.remove(&(a, b));
        owner.remove(&(b, a));
        for t in [t1, t2] {
            let tt = tris[t];
            for e in 0..3 {
                owner.insert((tt[e], tt[(e + 1) % 3]), t);
            }
        }
        for (x, y) in [(a, d), (d, b), (b, cc), (cc, a)] {
            if owner.contains_key(&(y, x)) {
                queue.push((x.min(y), x.max(y)));
            }
        }
        swaps += 1;
    }
    swaps
}

/// A few Gauss–Seidel iterations of umbrella (uniform Laplacian) smoothing of the
/// new vertices (index `>= k`), the loop vertices fixed. A move is taken only when
/// no incident triangle flips or gets an angle below `floor` (or below its own
/// smallest angle, when that already is smaller).
pub fn relax(
    pos: &mut [DVec3],
    k: usize,
    tris: &[[u32; 3]],
    iterations: usize,
    lambda: f64,
    floor: f64,
) {
    let n = pos.len();
    if n <= k {
        return;
    }
    let floor_sin = floor.clamp(0.0, PI / 3.0).sin();
    let mut nbrs: Vec<Vec<u32>> = vec![Vec::new(); n - k];
    let mut inc: Vec<Vec<usize>> = vec![Vec::new(); n - k];
    for (ti, t) in tris.iter().enumerate() {
        for c in 0..3 {
            let v = t[c] as usize;
            if v >= k {
                inc[v - k].push(ti);
                for w in [t[(c + 1) % 3], t[(c + 2) % 3]] {
                    if !nbrs[v - k].contains(&w) {
                        nbrs[v - k].push(w);
                    }
                }
            }
        }
    }
    for _ in 0..iterations {
        for v in k..n {
            let nb = &nbrs[v - k];
            if nb.is_empty() {
                continue;
            }
            let target = nb.iter().map(|&w| pos[w as usize]).sum::<DVec3>() / nb.len() as f64;
            let old = pos[v];
            let cand = old + (target - old) * lambda;
            let ok = inc[v - k].iter().all(|&ti| {
                let t = tris[ti];
                let before = t.map(|i| pos[i as usize]);
                let after = t.map(|i| {
                    if i as usize == v {
                        cand
                    } else {
                        pos[i as usize]
                    }
                });
                let nb0 = measure::tri_normal_raw(before[0], before[1], before[2]);
                let nb1 = measure::tri_normal_raw(after[0], after[1], after[2]);
                if nb0.dot(nb1) <= 0.5 * nb0.length() * nb1.length() {
                    return false;
                }
                let s1 = measure::smallest_angle_sin(after[0], after[1], after[2]);
                s1 >= floor_sin
                    || s1 >= measure::smallest_angle_sin(before[0], before[1], before[2])
            });
            if ok {
                pos[v] = cand;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_angle_and_its_sine_agree() {
        let a = DVec3::new(0.0, 0.0, 0.0);
        let b = DVec3::new(3.0, 0.2, 0.1);
        let c = DVec3::new(0.4, 1.0, -0.3);
        let g = measure::angles(a, b, c);
        let m = g[0].min(g[1]).min(g[2]);
        assert!((measure::smallest_angle(a, b, c) - m).abs() < 1e-12);
        assert!((measure::smallest_angle_sin(a, b, c) - m.sin()).abs() < 1e-12);
        assert_eq!(measure::smallest_angle_sin(a, a, c), 0.0);
    }

    #[test]
    fn swap_fixes_a_bad_diagonal() {
        // a flat rhombus split along its long diagonal
        let pos = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.0, 0.4, 0.0),
            DVec3::new(1.0, -0.4, 0.0),
        ];
        let mut tris = vec![[0, 1, 2], [1, 0, 3]];
        let forbidden = FxSet::default();
        let rules = SwapRules {
            k: 0,
            forbidden: &forbidden,
            min_angle: 0.0,
        };
        assert_eq!(swap_edges(&pos, &mut tris, &rules, 5), 1);
        let mut e: Vec<(u32, u32)> = Vec::new();
        for t in &tris {
            for c in 0..3 {
                e.push((t[c].min(t[(c + 1) % 3]), t[c].max(t[(c + 1) % 3])));
            }
        }
        assert!(e.contains(&(2, 3)) && !e.contains(&(0, 1)));
        // forbidding the new diagonal prevents the swap
        let mut tris = vec![[0, 1, 2], [1, 0, 3]];
        let forbidden: FxSet<(u32, u32)> = [(2, 3)].into_iter().collect();
        let rules = SwapRules {
            k: 4,
            forbidden: &forbidden,
            min_angle: 0.0,
        };
        assert_eq!(swap_edges(&pos, &mut tris, &rules, 5), 0);
    }

    #[test]
    fn relax_moves_towards_the_centroid_of_neighbours() {
        // a square with a centre vertex pushed off-centre, in the plane z = 0
        let mut pos = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
            DVec3::new(0.7, 0.6, 0.0),
        ];
        let tris = vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        relax(&mut pos, 4, &tris, 30, 0.5, 0.0);
        assert!((pos[4] - DVec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
        assert_eq!(pos[4].z, 0.0);
    }
}
