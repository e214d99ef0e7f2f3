//! Fixtures shared by the unit tests (compiled only for tests).

use crate::io::RawMesh;
use glam::DVec3;
use std::collections::HashMap;

/// Icosphere of radius `r` with `level` subdivisions.
pub fn icosphere(level: usize, r: f64) -> RawMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pos: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
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
        let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
        let mut next = Vec::with_capacity(faces.len() * 4);
        let mut m = |a: u32, b: u32, pos: &mut Vec<DVec3>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                pos.push(((pos[a as usize] + pos[b as usize]) / 2.0).normalize());
                (pos.len() - 1) as u32
            })
        };
        for f in &faces {
            let ab = m(f[0], f[1], &mut pos);
            let bc = m(f[1], f[2], &mut pos);
            let ca = m(f[2], f[0], &mut pos);
            next.push([f[0], ab, ca]);
            next.push([f[1], bc, ab]);
            next.push([f[2], ca, bc]);
            next.push([ab, bc, ca]);
        }
        faces = next;
    }
    RawMesh {
        positions: pos.into_iter().map(|p| p * r).collect(),
        faces,
        ..RawMesh::default()
    }
}

/// An icosphere of radius `r` (`level` subdivisions) without the faces whose centroid
/// direction lies within `cap` radians of `dir`: a sphere with one round hole.
pub fn sphere_cap_removed(level: usize, r: f64, dir: DVec3, cap: f64) -> RawMesh {
    let mut raw = icosphere(level, r);
    let dir = dir.normalize();
    let pos = &raw.positions;
    raw.faces.retain(|f| {
        let c = f
            .iter()
            .map(|&v| pos[v as usize])
            .sum::<DVec3>()
            .normalize();
        c.dot(dir) < cap.cos()
    });
    raw
}

/// A flat `n` x `n` grid of unit squares, two triangles each, facing +z: vertex
/// `(i, j)` is `j * (n + 1) + i`, cell `(i, j)` is faces `2 (j n + i)` and `+ 1`.
pub fn grid(n: usize) -> RawMesh {
    let mut raw = RawMesh::default();
    for j in 0..=n {
        for i in 0..=n {
            raw.positions.push(DVec3::new(i as f64, j as f64, 0.0));
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            raw.faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            raw.faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    raw
}
