//! The shapes of the integration tests, in one place: a triangle soup and its OBJ
//! text, the icosphere and the grid, and faces cut away. Included by
//! `tests/common/mod.rs` (re-exported there, for the tests and `tests/*_support`) and
//! by `tests/common/holes.rs` (which the bench `examples/hole_bench.rs` includes too),
//! each with `#[path = "shapes.rs"] mod shapes;`.
#![allow(dead_code)]

use std::collections::HashMap;

pub type V3 = [f64; 3];

/// A triangle soup.
#[derive(Clone, Debug, Default)]
pub struct Soup {
    pub v: Vec<V3>,
    pub f: Vec<[usize; 3]>,
}

impl Soup {
    /// OBJ text (shortest round-trip decimal coordinates).
    pub fn obj_text(&self) -> String {
        self.obj_text_with(|_| String::new())
    }

    /// OBJ text whose `v` lines go on with what `more` gives for the vertex (a colour
    /// such as `" 0.1 0.2 0.7"`).
    pub fn obj_text_with(&self, more: impl Fn(V3) -> String) -> String {
        let mut t = String::with_capacity(self.v.len() * 40 + self.f.len() * 24);
        for p in &self.v {
            t.push_str(&format!("v {} {} {}{}\n", p[0], p[1], p[2], more(*p)));
        }
        for f in &self.f {
            t.push_str(&format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1));
        }
        t
    }

    /// Drops faces for which `remove` holds (given the face's centroid and the face),
    /// then the unused vertices.
    pub fn remove_faces(&self, remove: impl Fn(V3, [usize; 3]) -> bool) -> Soup {
        let keep: Vec<[usize; 3]> = self
            .f
            .iter()
            .copied()
            .filter(|f| {
                let c =
                    [0, 1, 2].map(|k| (self.v[f[0]][k] + self.v[f[1]][k] + self.v[f[2]][k]) / 3.0);
                !remove(c, *f)
            })
            .collect();
        let mut map = vec![usize::MAX; self.v.len()];
        let mut out = Soup::default();
        for t in &keep {
            let mut nt = [0; 3];
            for k in 0..3 {
                if map[t[k]] == usize::MAX {
                    map[t[k]] = out.v.len();
                    out.v.push(self.v[t[k]]);
                }
                nt[k] = map[t[k]];
            }
            out.f.push(nt);
        }
        out
    }
}

/// Removes the faces whose centroid lies within `radius` of `center`, then drops
/// unused vertices. Returns the holed soup and the removed faces (ground truth).
pub fn cut(s: &Soup, center: V3, radius: f64) -> (Soup, Soup) {
    let inside = |c: V3| {
        let d =
            ((c[0] - center[0]).powi(2) + (c[1] - center[1]).powi(2) + (c[2] - center[2]).powi(2))
                .sqrt();
        d < radius
    };
    (
        s.remove_faces(|c, _| inside(c)),
        s.remove_faces(|c, _| !inside(c)),
    )
}

/// A unit icosphere subdivided `level` times (level 3: 1280 faces), outward oriented.
pub fn icosphere(level: usize) -> Soup {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let norm = |p: V3| {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        [p[0] / l, p[1] / l, p[2] / l]
    };
    let mut v: Vec<V3> = [
        [-1., t, 0.],
        [1., t, 0.],
        [-1., -t, 0.],
        [1., -t, 0.],
        [0., -1., t],
        [0., 1., t],
        [0., -1., -t],
        [0., 1., -t],
        [t, 0., -1.],
        [t, 0., 1.],
        [-t, 0., -1.],
        [-t, 0., 1.],
    ]
    .iter()
    .map(|p| norm(*p))
    .collect();
    let mut f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: HashMap<(usize, usize), usize> = HashMap::new();
        let mut nf = Vec::with_capacity(f.len() * 4);
        for &[a, b, c] in &f {
            let mut m = |a: usize, b: usize| -> usize {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let p = norm([
                        (v[a][0] + v[b][0]) / 2.0,
                        (v[a][1] + v[b][1]) / 2.0,
                        (v[a][2] + v[b][2]) / 2.0,
                    ]);
                    v.push(p);
                    v.len() - 1
                })
            };
            let ab = m(a, b);
            let bc = m(b, c);
            let ca = m(c, a);
            nf.push([a, ab, ca]);
            nf.push([b, bc, ab]);
            nf.push([c, ca, bc]);
            nf.push([ab, bc, ca]);
        }
        f = nf;
    }
    Soup { v, f }
}

/// A grid of `nx` x `ny` quads of edge `h` (two triangles each, normal +z before the
/// height map), vertex `(i, j)` at `(x0 + i h, y0 + j h, z(x, y))`.
pub fn grid(nx: usize, ny: usize, h: f64, x0: f64, y0: f64, z: impl Fn(f64, f64) -> f64) -> Soup {
    let mut s = Soup::default();
    for j in 0..=ny {
        for i in 0..=nx {
            let (x, y) = (x0 + i as f64 * h, y0 + j as f64 * h);
            s.v.push([x, y, z(x, y)]);
        }
    }
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    for j in 0..ny {
        for i in 0..nx {
            // alternate the diagonal so that no direction is preferred
            if (i + j) % 2 == 0 {
                s.f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                s.f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            } else {
                s.f.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                s.f.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }
    s
}
