//! Meshes with one hard or huge hole each, generated analytically (no data files):
//! shared by the integration test `tests/hard_holes.rs` and the bench binary
//! `examples/hole_bench.rs` (included there with `#[path]`).
//!
//! Every generator returns a closed-except-for-the-hole, consistently oriented,
//! edge-manifold soup whose boundary is the loops listed in its doc (checked by
//! [`boundary_loop_sizes`]).
#![allow(dead_code)]

use std::collections::HashMap;
use std::f64::consts::TAU;

#[path = "shapes.rs"]
mod shapes;
pub use shapes::{grid, icosphere, Soup, V3};

/// Adds a small closed sphere (80 faces) beside the mesh, so that the mesh's
/// bounding-box diagonal more than doubles: a hole that spans the whole part (the
/// open end of a tube) is then not taken for the outer border of a scan by the
/// default `[border]` rule (`max_bbox_share = 0.6`), as in a scan with a second part.
pub fn with_companion(mut s: Soup) -> Soup {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in &s.v {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let d = ((hi[0] - lo[0]).powi(2) + (hi[1] - lo[1]).powi(2) + (hi[2] - lo[2]).powi(2)).sqrt();
    let off = 0.75 * d;
    let ball = icosphere(1);
    let base = s.v.len();
    let r = 0.01 * d;
    for p in &ball.v {
        s.v.push([
            hi[0] + off + r * p[0],
            hi[1] + off + r * p[1],
            hi[2] + off + r * p[2],
        ]);
    }
    for f in &ball.f {
        s.f.push(f.map(|i| i + base));
    }
    s
}

/// Sizes of the boundary loops (sorted, largest first); `None` when the boundary is
/// not a set of simple loops (a vertex with more than one outgoing boundary edge).
pub fn boundary_loop_sizes(s: &Soup) -> Option<Vec<usize>> {
    let mut dir: HashMap<(usize, usize), u32> = HashMap::new();
    for f in &s.f {
        for k in 0..3 {
            *dir.entry((f[k], f[(k + 1) % 3])).or_default() += 1;
        }
    }
    if dir.values().any(|&c| c > 1) {
        return None;
    }
    // boundary half-edges run opposite to the face edges with no twin
    let mut next: HashMap<usize, usize> = HashMap::new();
    for &(a, b) in dir.keys() {
        if !dir.contains_key(&(b, a)) && next.insert(b, a).is_some() {
            return None;
        }
    }
    let mut seen: HashMap<usize, bool> = HashMap::new();
    let mut sizes = Vec::new();
    let mut starts: Vec<usize> = next.keys().copied().collect();
    starts.sort_unstable();
    for s0 in starts {
        if seen.contains_key(&s0) {
            continue;
        }
        let mut c = s0;
        let mut n = 0;
        loop {
            seen.insert(c, true);
            n += 1;
            c = *next.get(&c)?;
            if c == s0 {
                break;
            }
            if n > next.len() {
                return None;
            }
        }
        sizes.push(n);
    }
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    Some(sizes)
}

/// Index of the grid quad holding the point `(x, y)` of a [`grid`] at the origin.
fn quad_of(c: V3, h: f64) -> (i64, i64) {
    ((c[0] / h).floor() as i64, (c[1] / h).floor() as i64)
}

/// A closed cylinder of radius `r` around the z axis: `n` vertices per ring, `m`
/// quads along z of height `dz`, both ends closed by a fan to a centre vertex.
/// `open_top`: leave the top end open (a round hole of `n` boundary vertices).
pub fn cylinder(r: f64, n: usize, m: usize, dz: f64, open_top: bool) -> Soup {
    let mut s = Soup::default();
    for j in 0..=m {
        for i in 0..n {
            let t = TAU * i as f64 / n as f64;
            s.v.push([r * t.cos(), r * t.sin(), j as f64 * dz]);
        }
    }
    let id = |i: usize, j: usize| j * n + (i % n);
    for j in 0..m {
        for i in 0..n {
            // outward: (i, j) -> (i+1, j) -> (i+1, j+1)
            s.f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            s.f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let bottom = s.v.len();
    s.v.push([0.0, 0.0, 0.0]);
    for i in 0..n {
        s.f.push([bottom, id(i + 1, 0), id(i, 0)]);
    }
    if !open_top {
        let top = s.v.len();
        s.v.push([0.0, 0.0, m as f64 * dz]);
        for i in 0..n {
            s.f.push([top, id(i, m), id(i + 1, m)]);
        }
    }
    s
}

/// Ring count and angular step of a cylinder with near-equilateral quads.
fn cyl_ring(r: f64, n: usize) -> f64 {
    TAU * r / n as f64
}

/// (a) A long slot cut along a dense closed cylinder of radius 1 with `n` vertices
/// per ring: `w` quads wide, `len` quads long, so the loop has `2 len + 2 w` boundary
/// vertices (len = 5000, w = 4: 10,008). The true surface is the cylinder.
pub fn cylinder_slot(n: usize, w: usize, len: usize) -> Soup {
    let dz = cyl_ring(1.0, n);
    let m = len + 20;
    let c = cylinder(1.0, n, m, dz, false);
    let j0 = 10;
    let z0 = j0 as f64 * dz;
    let z1 = (j0 + len) as f64 * dz;
    let dt = TAU / n as f64;
    c.remove_faces(|p, _| {
        let t = p[1].atan2(p[0]).rem_euclid(TAU);
        let r2 = p[0] * p[0] + p[1] * p[1];
        r2 > 0.25 && t < w as f64 * dt && p[2] > z0 && p[2] < z1
    })
}

/// (b) The open end of a closed-bottom cylinder of radius 1 with `n` vertices per ring
/// (a round hole of `n` boundary vertices), `rings` quads high.
pub fn cylinder_end(n: usize, rings: usize) -> Soup {
    cylinder(1.0, n, rings, cyl_ring(1.0, n), true)
}

/// A unit icosphere with the cap of faces whose centroid lies within angle `cap`
/// (radians) of +z removed: a round hole on a curved surface.
pub fn sphere_cap(level: usize, cap: f64) -> Soup {
    let s = icosphere(level);
    let d = [0.3f64, 0.2, 1.0];
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = d.map(|x| x / l);
    s.remove_faces(|c, _| {
        let lc = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        let cosang = (c[0] * d[0] + c[1] * d[1] + c[2] * d[2]) / lc;
        cosang > cap.cos()
    })
}

/// A unit sphere with a round hole of `k` boundary vertices: the cap of polar angle
/// below `cap` (radians) around +z is missing. The sphere is dense near the hole and
/// coarsens away from it: `fine` rings of `k` vertices (ring spacing about the edge
/// length), then rings whose spacing grows by half each ring (up to 0.2), zipped
/// together, closed by a fan at the south pole. The true surface is the sphere.
pub fn dense_sphere_cap(k: usize, cap: f64, fine: usize) -> Soup {
    let mut s = Soup::default();
    // rings: (polar angle, vertex count, first vertex index)
    let mut rings: Vec<(f64, usize, usize)> = Vec::new();
    let (mut theta, mut n) = (cap, k.max(3));
    let mut edge = TAU * cap.sin() / n as f64;
    let mut j = 0;
    loop {
        let first = s.v.len();
        // alternate rings are rotated by half a step, so the strips zip evenly
        let shift = if j % 2 == 0 { 0.0 } else { 0.5 };
        for i in 0..n {
            let phi = TAU * (i as f64 + shift) / n as f64;
            s.v.push([
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ]);
        }
        rings.push((theta, n, first));
        j += 1;
        if j >= fine {
            edge = (edge * 1.5).min(0.2);
        }
        let next = theta + 0.87 * edge;
        if next > std::f64::consts::PI - 0.6 * edge {
            break;
        }
        theta = next;
        if j >= fine {
            n = ((TAU * theta.sin() / edge).round() as usize).clamp(3, n);
        }
    }
    // zip consecutive rings: advance on the ring whose next vertex comes first; after
    // n_a + n_b triangles the strip has gone once around
    let angle = |r: &(f64, usize, usize), i: usize, j: usize| {
        let shift = if j % 2 == 0 { 0.0 } else { 0.5 };
        TAU * (i as f64 + shift) / r.1 as f64
    };
    let mut tris: Vec<[usize; 3]> = Vec::new();
    for w in 0..rings.len() - 1 {
        let (a, b) = (rings[w], rings[w + 1]);
        let (mut i, mut m) = (0usize, 0usize);
        while i < a.1 || m < b.1 {
            let next_a = angle(&a, i + 1, w);
            let next_b = angle(&b, m + 1, w + 1);
            let va = a.2 + i % a.1;
            let vb = b.2 + m % b.1;
            if m >= b.1 || (i < a.1 && next_a <= next_b) {
                tris.push([va, a.2 + (i + 1) % a.1, vb]);
                i += 1;
            } else {
                tris.push([va, b.2 + (m + 1) % b.1, vb]);
                m += 1;
            }
        }
    }
    let last = rings[rings.len() - 1];
    let pole = s.v.len();
    s.v.push([0.0, 0.0, -1.0]);
    for i in 0..last.1 {
        tris.push([last.2 + i, last.2 + (i + 1) % last.1, pole]);
    }
    // orient every triangle outward (the sphere is star-shaped about the origin)
    for t in tris {
        let [a, b, c] = t.map(|i| s.v[i]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let nrm = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let out = nrm[0] * (a[0] + b[0] + c[0])
            + nrm[1] * (a[1] + b[1] + c[1])
            + nrm[2] * (a[2] + b[2] + c[2]);
        s.f.push(if out >= 0.0 { t } else { [t[0], t[2], t[1]] });
    }
    s
}

/// Distance of a point to the unit sphere.
pub fn sphere_distance(p: V3) -> f64 {
    ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 1.0).abs()
}

/// A rectilinear spiral hole in a gently curved grid (z = 0.05 (x² + y²) on a
/// grid of edge 1/16): arms `width` quads wide, separated by `gap` quads, `turns`
/// quarter-turns. One loop (plus the grid's outer border).
pub fn spiral(width: i64, gap: i64, turns: usize) -> Soup {
    let h = 1.0 / 16.0;
    let pitch = width + gap;
    // the grid is wide enough that its outer border is the longest loop and the
    // spiral spans well under `border.max_bbox_share` of it
    let half = 2 * (turns as i64 / 2 + 2) * pitch + 8;
    let n = (2 * half) as usize;
    let x0 = -(half as f64) * h;
    let g = grid(n, n, h, x0, x0, |x, y| 0.05 * (x * x + y * y));
    // the spiral as a set of quads (i, j) relative to the centre
    let mut cells = std::collections::HashSet::new();
    let (mut x, mut y) = (0i64, 0i64);
    let dirs = [(1i64, 0i64), (0, 1), (-1, 0), (0, -1)];
    for t in 0..turns {
        let (dx, dy) = dirs[t % 4];
        let len = pitch * (t as i64 / 2 + 1);
        for _ in 0..len {
            for a in 0..width {
                for b in 0..width {
                    cells.insert((x + a, y + b));
                }
            }
            x += dx;
            y += dy;
        }
    }
    g.remove_faces(|c, _| {
        let (i, j) = quad_of([c[0] - x0, c[1] - x0, 0.0], h);
        cells.contains(&(i - half, j - half))
    })
}

/// A horseshoe hole whose two arms are separated by one row of quads squeezed to
/// `thin` of the grid edge (the boundary nearly touches itself), on a flat grid.
pub fn near_touch(arm: usize, thin: f64) -> Soup {
    let h = 1.0 / 16.0;
    let n = arm + 12;
    let mut g = grid(n, 16, h, 0.0, 0.0, |_, _| 0.0);
    // hole: rows 5..7 (lower arm) and 8..10 (upper arm), joined at columns 4..6;
    // row 7 (between the arms) is kept for columns >= 6
    let (c0, c1) = (4usize, 4 + arm);
    let removed = |i: usize, j: usize| -> bool {
        (c0..c1).contains(&i) && (5..10).contains(&j) && !(j == 7 && i >= c0 + 2)
    };
    // squeeze the kept row: lines y = 7h and y = 8h move towards 7.5h
    let mid = 7.5 * h;
    for p in g.v.iter_mut() {
        let j = (p[1] / h).round() as i64;
        let i = (p[0] / h).round() as i64;
        if (j == 7 || j == 8) && i >= (c0 + 2) as i64 && i <= c1 as i64 {
            p[1] = mid + (p[1] - mid) * thin;
        }
    }
    // faces are removed by their quad (from the vertex indices: robust to the squeeze)
    let nx = n + 1;
    g.remove_faces(|_, f| {
        let i = f.iter().map(|&v| v % nx).min().unwrap_or(0);
        let j = f.iter().map(|&v| v / nx).min().unwrap_or(0);
        removed(i, j)
    })
}

/// A round hole in a flat grid whose boundary has a sliver: one boundary vertex is
/// pushed almost onto its boundary neighbour (a face of angle below a degree behind
/// the loop) and another almost onto the line through its two boundary neighbours.
pub fn sliver_hole(radius_quads: f64) -> Soup {
    let h = 1.0 / 16.0;
    let n = (2.0 * radius_quads) as usize + 12;
    let c = n as f64 * h / 2.0;
    let g = grid(n, n, h, 0.0, 0.0, |_, _| 0.0);
    let r = radius_quads * h;
    let mut s = g.remove_faces(|p, _| {
        let (i, j) = quad_of(p, h);
        let q = [(i as f64 + 0.5) * h - c, (j as f64 + 0.5) * h - c];
        (q[0] * q[0] + q[1] * q[1]).sqrt() < r
    });
    // the boundary vertices, in loop order
    let lp = boundary_loops(&s)
        .into_iter()
        .min_by_key(|l| l.len())
        .unwrap_or_default();
    if lp.len() > 10 {
        let k = lp.len();
        // (1) vertex 0 almost onto vertex 1
        let (a, b) = (s.v[lp[0]], s.v[lp[1]]);
        s.v[lp[0]] = [
            b[0] + (a[0] - b[0]) * 0.01,
            b[1] + (a[1] - b[1]) * 0.01,
            0.0,
        ];
        // (2) vertex k/2 almost onto the segment of its neighbours
        let (p, q, m) = (s.v[lp[k / 2 - 1]], s.v[lp[k / 2 + 1]], s.v[lp[k / 2]]);
        let mid = [(p[0] + q[0]) / 2.0, (p[1] + q[1]) / 2.0];
        s.v[lp[k / 2]] = [
            mid[0] + (m[0] - mid[0]) * 0.01,
            mid[1] + (m[1] - mid[1]) * 0.01,
            0.0,
        ];
    }
    s
}

/// The boundary loops of a soup, each in boundary order.
pub fn boundary_loops(s: &Soup) -> Vec<Vec<usize>> {
    let mut dir = std::collections::HashSet::new();
    for f in &s.f {
        for k in 0..3 {
            dir.insert((f[k], f[(k + 1) % 3]));
        }
    }
    let mut next: HashMap<usize, usize> = HashMap::new();
    for &(a, b) in &dir {
        if !dir.contains(&(b, a)) {
            next.insert(b, a);
        }
    }
    let mut starts: Vec<usize> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::new();
    for s0 in starts {
        if seen.contains(&s0) {
            continue;
        }
        let mut l = vec![s0];
        seen.insert(s0);
        let mut c = next[&s0];
        while c != s0 && seen.insert(c) {
            l.push(c);
            c = match next.get(&c) {
                Some(&x) => x,
                None => break,
            };
        }
        out.push(l);
    }
    out
}

/// A nearly flat round hole of `n` boundary vertices: a flat annulus (`rings` rings of
/// quads outside the hole) with height noise of `noise` times the edge length.
pub fn flat_annulus(n: usize, rings: usize, noise: f64) -> Soup {
    let r0 = 1.0;
    let h = TAU * r0 / n as f64;
    let mut s = Soup::default();
    // deterministic noise
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut rnd = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    for j in 0..=rings {
        let r = r0 + j as f64 * h;
        for i in 0..n {
            let t = TAU * i as f64 / n as f64;
            s.v.push([r * t.cos(), r * t.sin(), noise * h * rnd()]);
        }
    }
    let id = |i: usize, j: usize| j * n + (i % n);
    for j in 0..rings {
        for i in 0..n {
            s.f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            s.f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    s
}

/// A round hole (radius 0.6) in a saddle z = a (x² - y²) over [-1, 1]²: the loop is
/// strongly non-planar (up and down twice).
pub fn saddle(a: f64, quads: usize) -> Soup {
    let h = 2.0 / quads as f64;
    let g = grid(quads, quads, h, -1.0, -1.0, |x, y| a * (x * x - y * y));
    g.remove_faces(|c, _| {
        let (i, j) = ((c[0] + 1.0) / h, (c[1] + 1.0) / h);
        let q = [(i.floor() + 0.5) * h - 1.0, (j.floor() + 0.5) * h - 1.0];
        (q[0] * q[0] + q[1] * q[1]).sqrt() < 0.6
    })
}

/// Distance of a point to the unit cylinder around the z axis.
pub fn cylinder_distance(p: V3) -> f64 {
    ((p[0] * p[0] + p[1] * p[1]).sqrt() - 1.0).abs()
}
