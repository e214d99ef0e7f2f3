//! Fixtures for the integration tests: analytic surfaces with holes cut out (the
//! shapes from `shapes.rs`), written as OBJ files, and helpers to run the real binary.
#![allow(dead_code)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

#[path = "shapes.rs"]
mod shapes;
pub use shapes::*;

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

/// Writes an OBJ file (shortest round-trip decimal coordinates).
pub fn write_obj(path: &Path, s: &Soup) {
    std::fs::write(path, s.obj_text()).expect("write fixture");
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
