//! The shapes of the integration tests, in one place: a triangle soup and its OBJ
//! text, the icosphere (built by the unit tests' `src/testutil/icosahedron.rs`) and the
//! grid, and faces cut away. Included by
//! `tests/common/mod.rs` (re-exported there, for the tests and `tests/*_support`) and
//! by `tests/common/holes.rs` (which the bench `examples/hole_bench.rs` includes too),
//! each with `#[path = "shapes.rs"] mod shapes;`.
#![allow(dead_code)]

#[path = "../../src/testutil/icosahedron.rs"]
mod icosahedron;

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
    let (v, f) = icosahedron::icosphere(level, |p| {
        let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        [p[0] / l, p[1] / l, p[2] / l]
    });
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
