//! Fixtures for the integration tests: analytic surfaces with holes cut out, written
//! as OBJ files, and helpers to run the real binary.
#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub type V3 = [f64; 3];

/// A triangle soup.
#[derive(Clone, Debug, Default)]
pub struct Soup {
    pub v: Vec<V3>,
    pub f: Vec<[usize; 3]>,
}

fn norm(p: V3) -> V3 {
    let l = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    [p[0] / l, p[1] / l, p[2] / l]
}

/// Unit icosphere subdivided `level` times (level 3: 1280 faces), outward oriented.
pub fn icosphere(level: usize) -> Soup {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
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
        let mut m = |a: usize, b: usize, v: &mut Vec<V3>| -> usize {
            let key = (a.min(b), a.max(b));
            *mid.entry(key).or_insert_with(|| {
                let p = norm([
                    (v[a][0] + v[b][0]) / 2.0,
                    (v[a][1] + v[b][1]) / 2.0,
                    (v[a][2] + v[b][2]) / 2.0,
                ]);
                v.push(p);
                v.len() - 1
            })
        };
        for &[a, b, c] in &f {
            let ab = m(a, b, &mut v);
            let bc = m(b, c, &mut v);
            let ca = m(c, a, &mut v);
            nf.push([a, ab, ca]);
            nf.push([b, bc, ab]);
            nf.push([c, ca, bc]);
            nf.push([ab, bc, ca]);
        }
        f = nf;
    }
    Soup { v, f }
}

/// Torus with major radius `r1`, minor `r2`, `n` x `m` quads split in two.
pub fn torus(r1: f64, r2: f64, n: usize, m: usize) -> Soup {
    let mut s = Soup::default();
    for i in 0..n {
        let u = i as f64 / n as f64 * std::f64::consts::TAU;
        for j in 0..m {
            let w = j as f64 / m as f64 * std::f64::consts::TAU;
            s.v.push([
                (r1 + r2 * w.cos()) * u.cos(),
                (r1 + r2 * w.cos()) * u.sin(),
                r2 * w.sin(),
            ]);
        }
    }
    let id = |i: usize, j: usize| (i % n) * m + (j % m);
    for i in 0..n {
        for j in 0..m {
            s.f.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            s.f.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    s
}

/// Distance of a point to the torus surface.
pub fn torus_distance(p: V3, r1: f64, r2: f64) -> f64 {
    let q = ((p[0] * p[0] + p[1] * p[1]).sqrt() - r1, p[2]);
    ((q.0 * q.0 + q.1 * q.1).sqrt() - r2).abs()
}

/// Removes the faces whose centroid lies within `radius` of `center`, then drops
/// unused vertices. Returns the holed soup and the removed faces (ground truth).
pub fn cut(s: &Soup, center: V3, radius: f64) -> (Soup, Soup) {
    let mut keep = Vec::new();
    let mut gone = Vec::new();
    for f in &s.f {
        let c = [0, 1, 2].map(|k| (s.v[f[0]][k] + s.v[f[1]][k] + s.v[f[2]][k]) / 3.0);
        let d =
            ((c[0] - center[0]).powi(2) + (c[1] - center[1]).powi(2) + (c[2] - center[2]).powi(2))
                .sqrt();
        if d < radius {
            gone.push(*f);
        } else {
            keep.push(*f);
        }
    }
    (compact(&s.v, &keep), compact(&s.v, &gone))
}

fn compact(v: &[V3], f: &[[usize; 3]]) -> Soup {
    let mut map = vec![usize::MAX; v.len()];
    let mut out = Soup::default();
    for t in f {
        let mut nt = [0; 3];
        for k in 0..3 {
            if map[t[k]] == usize::MAX {
                map[t[k]] = out.v.len();
                out.v.push(v[t[k]]);
            }
            nt[k] = map[t[k]];
        }
        out.f.push(nt);
    }
    out
}

/// OBJ text of a soup (shortest round-trip decimal coordinates).
pub fn obj_text(s: &Soup) -> String {
    let mut t = String::new();
    for p in &s.v {
        t.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for f in &s.f {
        t.push_str(&format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1));
    }
    t
}

/// Writes an OBJ file (shortest round-trip decimal coordinates).
pub fn write_obj(path: &Path, s: &Soup) {
    std::fs::write(path, obj_text(s)).expect("write fixture");
}

/// Reads back an OBJ written by holefill (v and f lines only).
pub fn read_obj(path: &Path) -> Soup {
    let text = std::fs::read_to_string(path).expect("read output");
    let mut s = Soup::default();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|x| x.parse().expect("coordinate")).collect();
                s.v.push([c[0], c[1], c[2]]);
            }
            Some("f") => {
                let c: Vec<usize> = it
                    .map(|x| {
                        x.split('/')
                            .next()
                            .unwrap_or("")
                            .parse::<usize>()
                            .expect("index")
                            - 1
                    })
                    .collect();
                for k in 1..c.len() - 1 {
                    s.f.push([c[0], c[k], c[k + 1]]);
                }
            }
            _ => {}
        }
    }
    s
}

/// Number of boundary edges (edges with one face).
pub fn boundary_edges(s: &Soup) -> usize {
    let mut count: HashMap<(usize, usize), i32> = HashMap::new();
    for f in &s.f {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    count.values().filter(|&&c| c == 1).count()
}

/// The holefill binary.
pub fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_holefill"))
}

/// Runs holefill with arguments.
pub fn run(args: &[&str]) -> Output {
    Command::new(bin())
        .args(args)
        .output()
        .expect("run holefill")
}

/// A fresh temporary folder.
pub fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("tempdir")
}
