//! Fixtures shared by the unit tests (compiled only for tests): the meshes (grid,
//! icosphere, cylinder) and their holes (faces cut away, cracks and slits, the loop
//! picked), and a fan patch.

use crate::io::RawMesh;
use crate::mesh::{Mesh, VertexId};
use crate::patch::Patch;
use glam::DVec3;
use std::collections::HashMap;

mod icosahedron;

/// A grid of `n x n` square cells over `[lo, hi]²` with heights `z(x, y)`, faces up:
/// vertex `(i, j)` is `j * (n + 1) + i`, each cell cut by its diagonal from `(i, j)` to
/// `(i + 1, j + 1)` into two faces, cells in row order.
pub fn grid(n: usize, lo: f64, hi: f64, z: impl FnMut(f64, f64) -> f64) -> RawMesh {
    grid_cut(n, lo, hi, z, false)
}

/// A flat [`grid`] of `n x n` unit cells: over `[0, n]²`, in z = 0.
pub fn unit_grid(n: usize) -> RawMesh {
    grid(n, 0.0, n as f64, |_, _| 0.0)
}

/// The [`grid`] with the diagonals alternating, so that no direction is preferred: a
/// cell `(i, j)` with `i + j` odd is cut from `(i + 1, j)` to `(i, j + 1)` instead.
pub fn grid_alternating(n: usize, lo: f64, hi: f64, z: impl FnMut(f64, f64) -> f64) -> RawMesh {
    grid_cut(n, lo, hi, z, true)
}

fn grid_cut(
    n: usize,
    lo: f64,
    hi: f64,
    mut z: impl FnMut(f64, f64) -> f64,
    alternate: bool,
) -> RawMesh {
    let mut raw = RawMesh::default();
    for j in 0..=n {
        for i in 0..=n {
            let x = lo + (hi - lo) * i as f64 / n as f64;
            let y = lo + (hi - lo) * j as f64 / n as f64;
            raw.positions.push(DVec3::new(x, y, z(x, y)));
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            if alternate && (i + j) % 2 == 1 {
                raw.faces.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                raw.faces
                    .push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            } else {
                raw.faces.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                raw.faces.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }
    raw
}

/// `raw` without the faces whose centroid satisfies `cut` (the vertices stay).
pub fn cut_faces(mut raw: RawMesh, cut: impl Fn(DVec3) -> bool) -> RawMesh {
    let pos = &raw.positions;
    raw.faces.retain(|f| {
        let c = f.iter().map(|&v| pos[v as usize]).sum::<DVec3>() / 3.0;
        !cut(c)
    });
    raw
}

/// A grid of unit cells (a [`grid`] over `[0, n]²`) without the cells `(i, j)` for
/// which `cut` holds.
pub fn cells_removed(raw: RawMesh, cut: impl Fn(usize, usize) -> bool) -> RawMesh {
    cut_faces(raw, |c| cut(c.x.floor() as usize, c.y.floor() as usize))
}

/// An `n x n` sheet of unit cells at height `z` (a [`grid`] over `[0, n]²`) without
/// the cells `removed` (i, j).
pub fn sheet(n: usize, z: f64, removed: &[(usize, usize)]) -> RawMesh {
    cells_removed(grid(n, 0.0, n as f64, |_, _| z), |i, j| {
        removed.contains(&(i, j))
    })
}

/// The 2 x 2 cells of a [`sheet`]'s hole (a loop of 8).
pub const SHEET_HOLE: [(usize, usize); 4] = [(2, 2), (3, 2), (2, 3), (3, 3)];

/// The loop of 8 vertices around the [`SHEET_HOLE`] of the sheet at height `z`.
pub fn sheet_hole_at(m: &Mesh, z: f64) -> Vec<VertexId> {
    m.topo
        .boundary_loops()
        .into_iter()
        .find(|l| l.len() == 8 && l.iter().all(|&u| m.pos(u).z == z))
        .expect("hole loop")
}

/// A strip of one ring of quads between the closed loops `inner` and `outer` (as many
/// points each, `outer[i]` across from `inner[i]`): the inner loop's vertices first,
/// then the outer's; quad `i` cut from `inner[i]` to `outer[i + 1]`, faces up for an
/// inner loop counter-clockwise inside the outer one.
pub fn strip(inner: &[DVec3], outer: &[DVec3]) -> RawMesh {
    assert_eq!(inner.len(), outer.len());
    let k = inner.len();
    let mut raw = RawMesh::default();
    raw.positions.extend_from_slice(inner);
    raw.positions.extend_from_slice(outer);
    for i in 0..k {
        let j = (i + 1) % k;
        let (vi, vj, ui, uj) = (i as u32, j as u32, (k + i) as u32, (k + j) as u32);
        raw.faces.push([vi, ui, uj]);
        raw.faces.push([vi, uj, vj]);
    }
    raw
}

/// `raw` split along a cut: each vertex for which `on_cut` holds gets a copy, moved by
/// `offset` and appended (in vertex order), and the faces whose centroid satisfies
/// `side` use the copies instead: a crack (or, with `offset` zero, a slit) between the
/// two sides.
pub fn split_along(
    mut raw: RawMesh,
    on_cut: impl Fn(DVec3) -> bool,
    offset: DVec3,
    side: impl Fn(DVec3) -> bool,
) -> RawMesh {
    let mut copy = HashMap::new();
    for i in 0..raw.positions.len() {
        let p = raw.positions[i];
        if on_cut(p) {
            copy.insert(i as u32, raw.positions.len() as u32);
            raw.positions.push(p + offset);
        }
    }
    let pos = &raw.positions;
    for f in &mut raw.faces {
        let c = f.iter().map(|&v| pos[v as usize]).sum::<DVec3>() / 3.0;
        if side(c) {
            for v in f.iter_mut() {
                if let Some(&k) = copy.get(v) {
                    *v = k;
                }
            }
        }
    }
    raw
}

/// `a` and `b` as one soup, `b`'s vertices numbered after `a`'s.
pub fn joined(mut a: RawMesh, b: &RawMesh) -> RawMesh {
    let base = a.positions.len() as u32;
    a.positions.extend_from_slice(&b.positions);
    a.faces.extend(b.faces.iter().map(|f| f.map(|v| v + base)));
    a
}

/// An open cylinder of radius `radius` around the z axis: `rings` rings of `seg`
/// vertices, ring `r` at height `z0 + r * dz`, faces outward. `staggered`: odd rings
/// turned by half a step, the triangles of a cell alternating with the ring (near
/// equilateral triangles for `dz = 2π/seg · 0.866`); else every quad cut by the same
/// diagonal, as [`grid`] does.
pub fn cylinder(
    radius: f64,
    seg: usize,
    rings: usize,
    dz: f64,
    z0: f64,
    staggered: bool,
) -> RawMesh {
    use std::f64::consts::TAU;
    let mut raw = RawMesh::default();
    for r in 0..rings {
        for s in 0..seg {
            let shift = if staggered { 0.5 * (r % 2) as f64 } else { 0.0 };
            let a = (s as f64 + shift) * TAU / seg as f64;
            raw.positions.push(DVec3::new(
                radius * a.cos(),
                radius * a.sin(),
                z0 + r as f64 * dz,
            ));
        }
    }
    let id = |r: usize, s: usize| (r * seg + s % seg) as u32;
    for r in 0..rings - 1 {
        for s in 0..seg {
            let fs = if !staggered {
                [
                    [id(r, s), id(r, s + 1), id(r + 1, s + 1)],
                    [id(r, s), id(r + 1, s + 1), id(r + 1, s)],
                ]
            } else if r % 2 == 0 {
                [
                    [id(r, s), id(r, s + 1), id(r + 1, s)],
                    [id(r, s + 1), id(r + 1, s + 1), id(r + 1, s)],
                ]
            } else {
                [
                    [id(r, s), id(r + 1, s + 1), id(r + 1, s)],
                    [id(r, s), id(r, s + 1), id(r + 1, s + 1)],
                ]
            };
            raw.faces.extend(fs);
        }
    }
    raw
}

/// The staggered [`cylinder`] of radius 1 from z = 0 up: `seg` vertices a ring, `rings`
/// rings, near-equilateral triangles.
pub fn unit_cylinder(seg: usize, rings: usize) -> RawMesh {
    cylinder(1.0, seg, rings, unit_cylinder_dz(seg), 0.0, true)
}

/// The ring spacing of a [`unit_cylinder`].
fn unit_cylinder_dz(seg: usize) -> f64 {
    2.0 * std::f64::consts::PI / seg as f64 * 0.866
}

/// The [`unit_cylinder`] with a hole on its side: the faces whose centroid has
/// `|angle| < half_angle` and `|z - zc| < half_height` (`zc` the middle height)
/// removed. Returns the mesh and the hole's loop.
pub fn cylinder_with_hole(
    seg: usize,
    rings: usize,
    half_angle: f64,
    half_height: f64,
) -> (Mesh, Vec<VertexId>) {
    let zc = (rings - 1) as f64 * unit_cylinder_dz(seg) * 0.5;
    let raw = cut_faces(unit_cylinder(seg, rings), |c| {
        c.y.atan2(c.x).abs() < half_angle && (c.z - zc).abs() < half_height
    });
    mesh_and_loop(&raw, |_, l| l.len() != seg)
}

/// The mesh of `raw` (validated) and the first of its boundary loops for which `pick`
/// holds.
pub fn mesh_and_loop(
    raw: &RawMesh,
    pick: impl Fn(&Mesh, &[VertexId]) -> bool,
) -> (Mesh, Vec<VertexId>) {
    let (mesh, _) = Mesh::from_raw(raw);
    mesh.validate().unwrap();
    let lp = mesh
        .topo
        .boundary_loops()
        .into_iter()
        .find(|l| pick(&mesh, l))
        .expect("a boundary loop that fits");
    (mesh, lp)
}

/// The boundary loop of `mesh` whose farthest vertex from `p` is nearest.
pub fn loop_near(mesh: &Mesh, p: DVec3) -> Vec<VertexId> {
    let mut loops = mesh.topo.boundary_loops();
    loops.sort_by(|a, b| {
        let c = |l: &Vec<VertexId>| {
            l.iter()
                .map(|&v| (mesh.pos(v) - p).length())
                .fold(0.0, f64::max)
        };
        c(a).total_cmp(&c(b))
    });
    loops.swap_remove(0)
}

/// A fan over a loop of `k` vertices: one new vertex, `apex`, joined to every edge.
pub fn fan(k: usize, apex: DVec3) -> Patch {
    Patch {
        new_vertices: vec![apex],
        triangles: (0..k)
            .map(|i| [i as u32, ((i + 1) % k) as u32, k as u32])
            .collect(),
    }
}

/// Icosphere of radius `r` with `level` subdivisions.
pub fn icosphere(level: usize, r: f64) -> RawMesh {
    let (v, f) = icosahedron::icosphere(level, |p| DVec3::from_array(p).normalize().to_array());
    RawMesh {
        positions: v.into_iter().map(|p| DVec3::from_array(p) * r).collect(),
        faces: f.into_iter().map(|t| t.map(|i| i as u32)).collect(),
        ..RawMesh::default()
    }
}

/// An icosphere of radius `r` (`level` subdivisions) without the faces whose centroid
/// direction lies within `cap` radians of `dir`: a sphere with one round hole.
pub fn sphere_cap_removed(level: usize, r: f64, dir: DVec3, cap: f64) -> RawMesh {
    sphere_caps_removed(level, r, &[(dir, cap)])
}

/// A unit icosphere (`level` subdivisions) without the faces whose centroid direction
/// lies within `cap` radians of +z, as a mesh, and the hole's loop (its only one).
pub fn sphere_with_hole(level: usize, cap: f64) -> (Mesh, Vec<VertexId>) {
    let raw = sphere_cap_removed(level, 1.0, DVec3::Z, cap);
    let (mesh, lp) = mesh_and_loop(&raw, |_, _| true);
    assert_eq!(mesh.topo.boundary_loops().len(), 1);
    (mesh, lp)
}

/// An icosphere of radius `r` without the faces whose centroid direction lies within
/// `cap` radians of one of the directions `dir`: a sphere with round holes.
pub fn sphere_caps_removed(level: usize, r: f64, caps: &[(DVec3, f64)]) -> RawMesh {
    let mut raw = icosphere(level, r);
    let pos = &raw.positions;
    raw.faces.retain(|f| {
        let c = f
            .iter()
            .map(|&v| pos[v as usize])
            .sum::<DVec3>()
            .normalize();
        caps.iter().all(|(d, cap)| c.dot(d.normalize()) < cap.cos())
    });
    raw
}
