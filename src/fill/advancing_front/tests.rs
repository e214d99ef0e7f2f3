//! Oracle tests of the advancing front: analytic surfaces (plane, sphere, cylinder)
//! with stated bounds, hard planar loops that must end (filled or a clean error), and
//! random star-shaped loops.

use super::*;
use crate::check::{check_degenerate, check_topology, patch_positions, quality};
use crate::fill::kit::Deadline;
use crate::fill::kit::TooLarge;
use crate::geometry::measure;
use crate::io::RawMesh;
use crate::mesh::Mesh;
use crate::patch::{apply_patch, Hole};
use crate::policy::{Checks, Policy, Settings};
use crate::testutil::{self, cylinder_with_hole, sphere_with_hole};
use glam::{DVec2, DVec3};
use proptest::prelude::*;
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

// ----- mesh builders ----------------------------------------------------------------

/// A planar mesh (z = 0) over `[lo, hi]²` with the simple polygon `poly` (CCW) cut out:
/// a constrained Delaunay triangulation of the polygon's vertices and a jittered
/// grid of spacing `h` outside it. Returns the mesh and the hole loop.
fn planar_with_hole(poly: &[DVec2], h: f64, lo: f64, hi: f64) -> (Mesh, Vec<VertexId>) {
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    let mut handles = Vec::new();
    for p in poly {
        handles.push(cdt.insert(Point2::new(p.x, p.y)).unwrap());
    }
    for i in 0..handles.len() {
        cdt.add_constraint(handles[i], handles[(i + 1) % handles.len()]);
    }
    let n = ((hi - lo) / h).ceil() as i64;
    for j in 0..=n {
        for i in 0..=n {
            // deterministic jitter
            let jx = ((i * 7919 + j * 104729) % 97) as f64 / 97.0 - 0.5;
            let jy = ((i * 3571 + j * 7307) % 89) as f64 / 89.0 - 0.5;
            let edge = i == 0 || j == 0 || i == n || j == n;
            let s = if edge { 0.0 } else { 0.25 * h };
            let q = DVec2::new(lo + i as f64 * h + s * jx, lo + j as f64 * h + s * jy);
            if measure::point_in_polygon(poly, q) || dist_to_poly(poly, q) < 0.6 * h {
                continue;
            }
            let _ = cdt.insert(Point2::new(q.x, q.y));
        }
    }
    let mut raw = RawMesh::default();
    let mut vs: Vec<(usize, DVec3)> = cdt
        .vertices()
        .map(|v| {
            (
                v.fix().index(),
                DVec3::new(v.position().x, v.position().y, 0.0),
            )
        })
        .collect();
    vs.sort_by_key(|x| x.0);
    raw.positions = vs.into_iter().map(|x| x.1).collect();
    for f in cdt.inner_faces() {
        let [a, b, c] = f.vertices();
        let ps = f.positions();
        let cen = DVec2::new(
            (ps[0].x + ps[1].x + ps[2].x) / 3.0,
            (ps[0].y + ps[1].y + ps[2].y) / 3.0,
        );
        if measure::point_in_polygon(poly, cen) {
            continue;
        }
        raw.faces.push([
            a.fix().index() as u32,
            b.fix().index() as u32,
            c.fix().index() as u32,
        ]);
    }
    let first = VertexId(handles[0].index() as u32);
    testutil::mesh_and_loop(&raw, |_, l| l.contains(&first))
}

fn dist_to_poly(poly: &[DVec2], q: DVec2) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            let t = ((q - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
            (a + (b - a) * t - q).length()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Samples a closed polyline so that consecutive points are about `h` apart.
fn resample(corners: &[DVec2], h: f64) -> Vec<DVec2> {
    let mut out = Vec::new();
    for i in 0..corners.len() {
        let (a, b) = (corners[i], corners[(i + 1) % corners.len()]);
        let m = ((b - a).length() / h).round().max(1.0) as usize;
        for j in 0..m {
            out.push(a + (b - a) * (j as f64 / m as f64));
        }
    }
    out
}

/// A grid of `n x n` unit cells (z = 0) with every face whose centroid satisfies
/// `cut` removed.
fn grid_with_hole(n: usize, cut: impl Fn(DVec3) -> bool) -> (Mesh, Vec<VertexId>) {
    let raw = testutil::cut_faces(testutil::unit_grid(n), cut);
    testutil::mesh_and_loop(&raw, |_, l| l.len() != 4 * n)
}

// ----- running and checking ---------------------------------------------------------

fn run(mesh: &Mesh, lp: &[VertexId], policy: &Policy) -> (Hole, Result<Patch, FillError>) {
    crate::fill::kit::run_on(mesh, lp.to_vec(), policy, fill)
}

struct Stats {
    q_good: f64,
    valence6: f64,
    min_angle_deg: f64,
    new_vertices: usize,
    triangles: usize,
}

/// The patch must be a valid disk, non-degenerate, and apply to a valid mesh.
fn validate(mesh: &Mesh, hole: &Hole, patch: &Patch) -> Stats {
    check_topology(mesh, &hole.vertices, patch).unwrap();
    let pos = patch_positions(mesh, &hole.vertices, patch);
    check_degenerate(&pos, patch, &Checks::default()).unwrap();
    let mut m2 = mesh.clone();
    apply_patch(&mut m2, hole, patch).unwrap();
    m2.validate().unwrap();
    // no two patch triangles overlap (shared corners aside)
    let geo: Vec<[DVec3; 3]> = patch
        .triangles
        .iter()
        .map(|t| t.map(|i| pos[i as usize]))
        .collect();
    let mut ob = intersect::Obstacles::new(hole.mean_edge_length * 2.0, measure::centroid(&pos));
    for g in &geo {
        ob.add(*g);
    }
    for (i, g) in geo.iter().enumerate() {
        assert!(
            ob.find_overlap(g, |id| id == i as u32).is_none(),
            "patch triangle {i} overlaps another"
        );
    }
    let q = quality(&pos, hole.len(), patch);
    Stats {
        q_good: q.q_good_share,
        valence6: q.valence6_share.unwrap_or(0.0),
        min_angle_deg: q.min_angle_deg,
        new_vertices: patch.new_vertices.len(),
        triangles: patch.triangles.len(),
    }
}

fn no_fair() -> Policy {
    let mut p = Policy::default();
    p = p.edit(|s| s.front.fair = false).unwrap();
    p
}

fn report(name: &str, k: usize, s: &Stats) {
    eprintln!(
        "{name}: k={k} new={} tris={} q>1.39={:.3} val6={:.3} min_angle={:.2}",
        s.new_vertices, s.triangles, s.q_good, s.valence6, s.min_angle_deg
    );
}

fn circle(n: usize, r: f64, c: DVec2) -> Vec<DVec2> {
    (0..n)
        .map(|i| {
            let a = 2.0 * PI * i as f64 / n as f64;
            c + DVec2::new(a.cos(), a.sin()) * r
        })
        .collect()
}

// ----- planar -----------------------------------------------------------------------

#[test]
fn planar_circular_hole_in_a_grid_stays_planar() {
    let (mesh, lp) = grid_with_hole(30, |c| (c - DVec3::new(15.0, 15.0, 0.0)).length() < 9.0);
    assert!(lp.len() > 50, "loop of {}", lp.len());
    for policy in [no_fair(), Policy::default()] {
        let (hole, r) = run(&mesh, &lp, &policy);
        let patch = r.unwrap();
        let s = validate(&mesh, &hole, &patch);
        report("grid circle", lp.len(), &s);
        for p in &patch.new_vertices {
            assert!(p.z.abs() < 1e-9, "z = {}", p.z);
            assert!((DVec2::new(p.x, p.y) - DVec2::new(15.0, 15.0)).length() < 9.5);
        }
        assert!(s.q_good >= 0.8, "q share {}", s.q_good);
        assert!(s.valence6 >= 0.6, "valence-6 share {}", s.valence6);
    }
}

#[test]
fn tilted_planar_hole_stays_in_its_plane() {
    let poly = circle(72, 6.0, DVec2::ZERO);
    let (mut mesh, lp) = planar_with_hole(&poly, 0.5, -10.0, 10.0);
    // rotate the plane: normal becomes n
    let rot = glam::DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 0.5).normalize(), 0.7);
    for p in mesh.positions.iter_mut() {
        *p = rot * *p + DVec3::new(3.0, -1.0, 2.0);
    }
    let n = rot * DVec3::Z;
    let o = DVec3::new(3.0, -1.0, 2.0);
    for policy in [no_fair(), Policy::default()] {
        let (hole, r) = run(&mesh, &lp, &policy);
        let patch = r.unwrap();
        let s = validate(&mesh, &hole, &patch);
        report("tilted circle", lp.len(), &s);
        for p in &patch.new_vertices {
            assert!((p - o).dot(n).abs() < 1e-9);
        }
        assert!(s.q_good >= 0.8, "q share {}", s.q_good);
    }
}

#[test]
fn tiny_loops_three_and_four() {
    let (mesh, lp) = planar_with_hole(
        &[
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.3, 0.9),
        ],
        0.5,
        -3.0,
        3.0,
    );
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    assert_eq!(patch.triangles.len(), 1);
    validate(&mesh, &hole, &patch);
    let quad = [
        DVec2::new(0.0, 0.0),
        DVec2::new(1.0, 0.0),
        DVec2::new(1.3, 0.4),
        DVec2::new(0.0, 1.0),
    ];
    let (mesh, lp) = planar_with_hole(&quad, 0.5, -3.0, 3.0);
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    assert_eq!(patch.triangles.len(), 2);
    assert!(patch.new_vertices.is_empty());
    validate(&mesh, &hole, &patch);
    // the better diagonal: 1-3 gives the larger smallest quality here
    let has = |a: u32, b: u32| {
        patch
            .triangles
            .iter()
            .any(|t| t.contains(&a) && t.contains(&b))
    };
    let pos: Vec<DVec3> = lp.iter().map(|&v| mesh.pos(v)).collect();
    let q = |a: usize, b: usize, c: usize| measure::quality(pos[a], pos[b], pos[c]);
    let q02 = q(0, 1, 2).min(q(2, 3, 0));
    let q13 = q(1, 2, 3).min(q(3, 0, 1));
    if q02 > q13 {
        assert!(has(0, 2));
    } else {
        assert!(has(1, 3));
    }
}

/// A quad hole whose one diagonal is already a mesh edge (on a triangular
/// bipyramid with two faces around a polar edge removed): the other one is used.
#[test]
fn never_duplicates_a_mesh_edge_between_loop_vertices() {
    let h = 3f64.sqrt() / 2.0;
    let raw = RawMesh {
        positions: vec![
            DVec3::new(1.0, 0.0, 0.0),  // a
            DVec3::new(-0.5, h, 0.0),   // b
            DVec3::new(-0.5, -h, 0.0),  // c
            DVec3::new(0.0, 0.0, 1.0),  // t
            DVec3::new(0.0, 0.0, -1.0), // u
        ],
        // (a,b,t) and (b,c,t) removed
        faces: vec![[2, 0, 3], [1, 0, 4], [2, 1, 4], [0, 2, 4]],
        ..Default::default()
    };
    let (mesh, _) = Mesh::from_raw(&raw);
    mesh.validate().unwrap();
    let lp = mesh.topo.boundary_loops().pop().unwrap();
    assert_eq!(lp.len(), 4);
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    validate(&mesh, &hole, &patch);
    let ids: Vec<u32> = patch
        .triangles
        .iter()
        .flatten()
        .map(|&i| lp[i as usize].0)
        .collect();
    // the diagonal b-t (1-3) is used, a-c (0-2) is not
    let has = |x: u32, y: u32| {
        patch.triangles.iter().any(|t| {
            let v: Vec<u32> = t.iter().map(|&i| lp[i as usize].0).collect();
            v.contains(&x) && v.contains(&y)
        })
    };
    assert!(has(1, 3) && !has(0, 2), "{ids:?}");
}

// ----- curved -----------------------------------------------------------------------

/// The raw front follows the paper's placement: new vertices near the plane of the
/// two front edges, bent by the Taubin term, with the normal tilted towards the hole
/// axis. That flattens large holes; restoring the sphere is the fairing's job (the
/// umbrella stand-in does not). The oracle is that the patch lies between the sphere
/// and the flat cap over the loop: `max |r - 1| <= max_share * sag`,
/// `mean |r - 1| <= mean_share * sag` (a flat disk has mean about `sag / 2`), with
/// `sag = 1 - cos(cap)`, and no new vertex outside the sphere by more than
/// `0.1 * sag`.
fn sphere_case(
    level: usize,
    cap: f64,
    k_min: usize,
    k_max: usize,
    max_share: f64,
    mean_share: f64,
) {
    let (mesh, lp) = sphere_with_hole(level, cap);
    assert!(
        lp.len() >= k_min && lp.len() <= k_max,
        "loop of {}",
        lp.len()
    );
    let sag = 1.0 - cap.cos();
    for policy in [no_fair(), Policy::default()] {
        let (hole, r) = run(&mesh, &lp, &policy);
        let patch = r.unwrap();
        let s = validate(&mesh, &hole, &patch);
        let dev = patch
            .new_vertices
            .iter()
            .map(|p| (p.length() - 1.0).abs())
            .fold(0.0, f64::max);
        let out = patch
            .new_vertices
            .iter()
            .map(|p| p.length() - 1.0)
            .fold(f64::MIN, f64::max);
        let mean = patch
            .new_vertices
            .iter()
            .map(|p| (p.length() - 1.0).abs())
            .sum::<f64>()
            / patch.new_vertices.len() as f64;
        report(
            &format!("sphere L{level} fair={} max|r-1|={dev:.4} mean={mean:.4} out={out:.4} sag={sag:.4}", policy.front.fair),
            lp.len(),
            &s,
        );
        assert!(
            dev <= max_share * sag,
            "max radial deviation {dev} > {max_share} * {sag}"
        );
        assert!(
            mean <= mean_share * sag,
            "mean radial deviation {mean} > {mean_share} * {sag}"
        );
        assert!(
            out <= 0.1 * sag,
            "a new vertex lies {out} outside the sphere"
        );
        assert!(s.q_good >= 0.8, "q share {}", s.q_good);
        assert!(s.valence6 >= 0.6, "valence-6 share {}", s.valence6);
    }
}

#[test]
fn sphere_hole_about_60() {
    sphere_case(4, 0.5, 50, 80, 0.75, 0.45);
}

#[test]
fn sphere_hole_about_200() {
    sphere_case(6, 0.45, 170, 260, 1.0, 0.6);
}

/// Same oracle as the sphere: between the cylinder and the flat chord.
#[test]
fn cylinder_hole() {
    let half_angle: f64 = 0.9;
    let (mesh, lp) = cylinder_with_hole(48, 24, half_angle, 0.9);
    assert!(lp.len() > 40, "loop of {}", lp.len());
    let sag = 1.0 - half_angle.cos();
    for policy in [no_fair(), Policy::default()] {
        let (hole, r) = run(&mesh, &lp, &policy);
        let patch = r.unwrap();
        let s = validate(&mesh, &hole, &patch);
        let rad = |p: &DVec3| DVec2::new(p.x, p.y).length() - 1.0;
        let dev = patch
            .new_vertices
            .iter()
            .map(|p| rad(p).abs())
            .fold(0.0, f64::max);
        let out = patch.new_vertices.iter().map(rad).fold(f64::MIN, f64::max);
        report(
            &format!(
                "cylinder fair={} max|r-1|={dev:.4} out={out:.4} sag={sag:.4}",
                policy.front.fair
            ),
            lp.len(),
            &s,
        );
        assert!(dev <= 0.7 * sag, "radial deviation {dev}");
        assert!(
            out <= 0.1 * sag,
            "a new vertex lies {out} outside the cylinder"
        );
        assert!(s.q_good >= 0.8, "q share {}", s.q_good);
    }
}

// ----- hard loops: filled or a clean error, in bounded steps -----------------------

fn filled_or_clean_error(name: &str, mesh: &Mesh, lp: &[VertexId]) -> bool {
    let (hole, r) = run(mesh, lp, &Policy::default());
    match r {
        Ok(patch) => {
            let s = validate(mesh, &hole, &patch);
            report(name, lp.len(), &s);
            true
        }
        Err(FillError::Failed(why)) => {
            eprintln!("{name}: k={} error: {why}", lp.len());
            false
        }
        Err(e) => panic!("unexpected {e:?}"),
    }
}

fn star(n: usize, r1: f64, r2: f64, h: f64) -> Vec<DVec2> {
    let corners: Vec<DVec2> = (0..2 * n)
        .map(|i| {
            let a = PI * i as f64 / n as f64;
            let r = if i % 2 == 0 { r2 } else { r1 };
            DVec2::new(a.cos(), a.sin()) * r
        })
        .collect();
    resample(&corners, h)
}

#[test]
fn concave_star_loop() {
    let poly = star(7, 2.0, 6.0, 0.5);
    let (mesh, lp) = planar_with_hole(&poly, 0.5, -8.0, 8.0);
    assert!(
        filled_or_clean_error("star", &mesh, &lp),
        "the star should fill"
    );
}

#[test]
fn spiral_loop() {
    // a corridor wound around itself
    let (b, w, turns) = (0.9 / (2.0 * PI), 0.45, 2.5);
    let mut outer = Vec::new();
    let mut inner = Vec::new();
    let steps = 200;
    for i in 0..=steps {
        let t = 2.0 * PI * turns * i as f64 / steps as f64;
        let r = 1.0 + b * t;
        inner.push(DVec2::new(t.cos(), t.sin()) * r);
        outer.push(DVec2::new(t.cos(), t.sin()) * (r + w));
    }
    let mut corners = inner.clone();
    corners.extend(outer.into_iter().rev());
    // make it counter-clockwise
    let area: f64 = (0..corners.len())
        .map(|i| corners[i].perp_dot(corners[(i + 1) % corners.len()]))
        .sum();
    if area < 0.0 {
        corners.reverse();
    }
    let poly = resample(&corners, 0.15);
    let (mesh, lp) = planar_with_hole(&poly, 0.2, -5.0, 5.0);
    assert!(lp.len() > 50);
    filled_or_clean_error("spiral", &mesh, &lp);
}

#[test]
fn long_thin_loop() {
    let corners = [
        DVec2::new(0.0, 0.0),
        DVec2::new(20.0, 0.0),
        DVec2::new(20.0, 1.5),
        DVec2::new(0.0, 1.5),
    ];
    let poly = resample(&corners, 0.5);
    let (mesh, lp) = planar_with_hole(&poly, 0.5, -3.0, 23.0);
    assert!(
        filled_or_clean_error("thin", &mesh, &lp),
        "the thin loop should fill"
    );
}

#[test]
fn nearly_self_touching_c_loop() {
    let (r1, r2) = (2.0, 3.0);
    let a0 = 0.06;
    let mut corners = Vec::new();
    let n = 40;
    for i in 0..=n {
        let a = a0 + (2.0 * PI - 2.0 * a0) * i as f64 / n as f64;
        corners.push(DVec2::new(a.cos(), a.sin()) * r2);
    }
    for i in (0..=n).rev() {
        let a = a0 + (2.0 * PI - 2.0 * a0) * i as f64 / n as f64;
        corners.push(DVec2::new(a.cos(), a.sin()) * r1);
    }
    let poly = resample(&corners, 0.3);
    let (mesh, lp) = planar_with_hole(&poly, 0.3, -5.0, 5.0);
    assert!(filled_or_clean_error("C", &mesh, &lp), "the C should fill");
}

/// More than a hemisphere missing: the loop is smaller than the hole behind it (the
/// paper's divergent case).
#[test]
fn divergent_sphere_hole() {
    let (mesh, lp) = sphere_with_hole(4, 2.0);
    filled_or_clean_error("divergent sphere", &mesh, &lp);
}

/// Unit cube `[0, 1]³` with `n x n` cells per face, with the faces whose centroid is
/// within `r` of the corner (1, 1, 1) removed.
fn cube_with_corner_hole(n: usize, r: f64) -> (Mesh, Vec<VertexId>) {
    let mut raw = RawMesh::default();
    let mut index: std::collections::HashMap<(i64, i64, i64), u32> = Default::default();
    let mut vid = |p: DVec3, raw: &mut RawMesh| -> u32 {
        let key = (
            (p.x * 1e6).round() as i64,
            (p.y * 1e6).round() as i64,
            (p.z * 1e6).round() as i64,
        );
        *index.entry(key).or_insert_with(|| {
            raw.positions.push(p);
            (raw.positions.len() - 1) as u32
        })
    };
    // each face: origin, two axes (u x v points outwards)
    let faces = [
        (DVec3::new(1.0, 0.0, 0.0), DVec3::Y, DVec3::Z),
        (DVec3::new(0.0, 0.0, 0.0), DVec3::Z, DVec3::Y),
        (DVec3::new(0.0, 1.0, 0.0), DVec3::Z, DVec3::X),
        (DVec3::new(0.0, 0.0, 0.0), DVec3::X, DVec3::Z),
        (DVec3::new(0.0, 0.0, 1.0), DVec3::X, DVec3::Y),
        (DVec3::new(0.0, 0.0, 0.0), DVec3::Y, DVec3::X),
    ];
    let corner = DVec3::ONE;
    for (o, u, v) in faces {
        for j in 0..n {
            for i in 0..n {
                let p =
                    |a: usize, b: usize| o + u * (a as f64 / n as f64) + v * (b as f64 / n as f64);
                let q = [p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1)];
                for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                    let c = (t[0] + t[1] + t[2]) / 3.0;
                    if (c - corner).length() < r {
                        continue;
                    }
                    let f = [
                        vid(t[0], &mut raw),
                        vid(t[1], &mut raw),
                        vid(t[2], &mut raw),
                    ];
                    raw.faces.push(f);
                }
            }
        }
    }
    let (mesh, rep) = Mesh::from_raw(&raw);
    assert_eq!(rep.flipped_faces, 0);
    mesh.validate().unwrap();
    let loops = mesh.topo.boundary_loops();
    assert_eq!(loops.len(), 1);
    (mesh, loops.into_iter().next().unwrap())
}

/// A hole over a cube corner: three faces meeting at right angles.
#[test]
fn cube_corner_hole() {
    let (mesh, lp) = cube_with_corner_hole(24, 0.6);
    assert!(lp.len() > 50, "loop of {}", lp.len());
    assert!(
        filled_or_clean_error("cube corner", &mesh, &lp),
        "the corner should fill"
    );
}

/// A hole in a height field `z = f(x, y)`; the patch stays within the range of the
/// surface heights around the loop, widened by the amplitude.
#[test]
fn saddle_hole() {
    let poly = circle(64, 4.0, DVec2::ZERO);
    let (mut mesh, lp) = planar_with_hole(&poly, 0.4, -7.0, 7.0);
    let f = |x: f64, y: f64| 0.05 * (x * x - y * y);
    for p in mesh.positions.iter_mut() {
        p.z = f(p.x, p.y);
    }
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    let s = validate(&mesh, &hole, &patch);
    report("saddle", lp.len(), &s);
    for p in &patch.new_vertices {
        // the saddle spans [-0.8, 0.8] over the disk
        assert!(p.z.abs() <= 0.85, "z = {}", p.z);
        assert!(DVec2::new(p.x, p.y).length() < 4.2);
    }
    assert!(s.q_good >= 0.8, "q share {}", s.q_good);
}

/// A zero-area slit (a cut along a grid line): no valid patch exists, so a clean
/// error.
#[test]
fn slit_gives_a_clean_error() {
    let n = 8;
    // copies of (2..=6, 4) for the faces above the cut
    let raw = testutil::split_along(
        testutil::unit_grid(n),
        |p| p.y == 4.0 && (2.0..=6.0).contains(&p.x),
        DVec3::ZERO,
        |c| c.y > 4.0,
    );
    let (mesh, lp) = testutil::mesh_and_loop(&raw, |_, l| l.len() != 4 * n);
    assert_eq!(lp.len(), 12);
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    match r {
        Err(FillError::Failed(why)) => eprintln!("slit: {why}"),
        Ok(patch) => {
            // only acceptable if it passes every check
            validate(&mesh, &hole, &patch);
        }
        Err(e) => panic!("unexpected {e:?}"),
    }
}

/// Out of steps (one per loop vertex), the front closes what is left as a residual
/// front: a valid patch, still in the plane of the grid.
#[test]
fn step_cap_closes_the_rest_as_a_residual_front() {
    let (mesh, lp) = grid_with_hole(30, |c| (c - DVec3::new(15.0, 15.0, 0.0)).length() < 9.0);
    let policy = Policy::default()
        .edit(|s| s.front.max_steps_per_vertex = 1)
        .unwrap();
    let (hole, r) = run(&mesh, &lp, &policy);
    let patch = r.expect("closed as a residual front");
    validate(&mesh, &hole, &patch);
    assert!(
        patch.new_vertices.len() > lp.len(),
        "the residual is refined"
    );
    for p in &patch.new_vertices {
        assert!(p.z.abs() < 1e-9, "off the plane: {p}");
    }
}

/// A front option out of range never reaches the front: the policy rejects it.
#[test]
fn bad_front_options_are_rejected_by_the_policy() {
    let mut settings = Settings::default();
    settings.front.alpha = 2.0;
    assert_eq!(Policy::new(settings).unwrap_err().key, "front.alpha");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]
    #[test]
    fn random_star_shaped_loops(radii in proptest::collection::vec(0.4f64..1.0, 5..14), rot in 0.0f64..std::f64::consts::TAU) {
        let n = radii.len();
        let corners: Vec<DVec2> = radii
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let a = rot + 2.0 * PI * i as f64 / n as f64;
                DVec2::new(a.cos(), a.sin()) * (r * 6.0)
            })
            .collect();
        let poly = resample(&corners, 0.45);
        let (mesh, lp) = planar_with_hole(&poly, 0.45, -8.0, 8.0);
        let (hole, r) = run(&mesh, &lp, &Policy::default());
        match r {
            Ok(patch) => {
                validate(&mesh, &hole, &patch);
                for p in &patch.new_vertices {
                    prop_assert!(p.z.abs() < 1e-9);
                }
            }
            Err(FillError::Failed(_)) => {}
            Err(e) => prop_assert!(false, "unexpected {:?}", e),
        }
    }

    /// Any policy in range: a valid disk or a clean error, on a curved loop.
    #[test]
    fn random_policies(alpha in 0.0f64..=1.0, omega1 in 0.0f64..=1.0, merge in 0.0f64..1.0,
                       small in 30.0f64..100.0, extra in 0.0f64..80.0, fair in proptest::bool::ANY) {
        let (mesh, lp) = sphere_with_hole(4, 0.5);
        let mut policy = Policy::default();
        policy = policy.edit(|s| s.front.alpha = alpha).unwrap();
        policy = policy.edit(|s| s.front.omega1 = omega1).unwrap();
        policy = policy.edit(|s| s.front.merge_distance = merge).unwrap();
        policy = policy.edit(|s| s.front.angle_small = small).unwrap();
        policy = policy.edit(|s| s.front.angle_large = small + extra).unwrap();
        policy = policy.edit(|s| s.front.fair = fair).unwrap();
        let (hole, r) = run(&mesh, &lp, &policy);
        match r {
            Ok(patch) => {
                validate(&mesh, &hole, &patch);
            }
            Err(FillError::Failed(_)) => {}
            Err(e) => prop_assert!(false, "unexpected {:?}", e),
        }
    }

    /// A hole in a noisy sphere (radial noise up to `noise`): a valid disk or a
    /// clean error.
    #[test]
    fn noisy_sphere_hole(seed in 0u64..1000, noise in 0.0f64..0.02) {
        use rand::{Rng, SeedableRng};
        let (mut mesh, lp) = sphere_with_hole(4, 0.55);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        for p in mesh.positions.iter_mut() {
            *p *= 1.0 + rng.random_range(-noise..=noise);
        }
        let (hole, r) = run(&mesh, &lp, &Policy::default());
        match r {
            Ok(patch) => {
                let s = validate(&mesh, &hole, &patch);
                prop_assert!(s.q_good > 0.5);
            }
            Err(FillError::Failed(_)) => {}
            Err(e) => prop_assert!(false, "unexpected {:?}", e),
        }
    }

    /// Star-shaped loops on a wavy height field: a valid disk or a clean error.
    #[test]
    fn random_loops_on_a_wavy_surface(radii in proptest::collection::vec(0.4f64..1.0, 5..12), amp in 0.0f64..1.5, freq in 0.2f64..0.8) {
        let n = radii.len();
        let corners: Vec<DVec2> = radii
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let a = 2.0 * PI * i as f64 / n as f64;
                DVec2::new(a.cos(), a.sin()) * (r * 6.0)
            })
            .collect();
        let poly = resample(&corners, 0.45);
        let (mut mesh, lp) = planar_with_hole(&poly, 0.45, -8.0, 8.0);
        for p in mesh.positions.iter_mut() {
            p.z = amp * (freq * p.x).sin() * (freq * p.y).cos();
        }
        let (hole, r) = run(&mesh, &lp, &Policy::default());
        match r {
            Ok(patch) => {
                validate(&mesh, &hole, &patch);
            }
            Err(FillError::Failed(_)) => {}
            Err(e) => prop_assert!(false, "unexpected {:?}", e),
        }
    }
}

#[test]
fn gives_up_at_once_past_the_patch_size_limit() {
    // a cap of 1 radian cut from a level-4 sphere: filled under the default limit
    let (mesh, lp) = sphere_with_hole(4, 1.0);
    let mut policy = Policy::default();
    let (_, r) = run(&mesh, &lp, &policy);
    assert!(r.is_ok(), "{r:?}");
    // with a limit of 100 triangles the estimate alone refuses it
    policy = policy.edit(|s| s.limits.max_patch_triangles = 100).unwrap();
    let t = std::time::Instant::now();
    let (_, r) = run(&mesh, &lp, &policy);
    match r {
        Err(FillError::TooLarge(TooLarge::Estimated { cap: 100, .. })) => {}
        other => panic!("expected a failure, got {other:?}"),
    }
    assert!(t.elapsed().as_secs_f64() < 1.0);
    // just above the estimate the front starts, then stops at the limit
    let est = super::estimated_triangles(&FillContext {
        mesh: &mesh,
        hole: &Hole::new(0, &mesh, lp.clone(), &policy),
        policy: &policy,
        deadline: Deadline::none(),
        checker: None,
        rim_bound: false,
        guide: false,
        finish: None,
    });
    policy = policy
        .edit(|s| s.limits.max_patch_triangles = (est as usize + 1).max(100))
        .unwrap();
    let (_, r) = run(&mesh, &lp, &policy);
    if let Ok(p) = &r {
        assert!(p.triangles.len() <= policy.limits.max_patch_triangles + 8);
    }
}
