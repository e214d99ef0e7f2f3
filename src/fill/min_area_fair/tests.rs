//! Oracle tests: plane, sphere and cylinder holes, big loops, random polygons.

use super::*;
use crate::check::{check_degenerate, check_topology, patch_positions, quality};
use crate::fill::kit::Deadline;
use crate::io::RawMesh;
use crate::patch::{apply_patch, Hole};
use crate::policy::{Policy, Search, TriangulationWeight, Weights};
use proptest::prelude::*;

use crate::testutil::{cut_faces, cylinder, icosphere, strip, unit_grid};

/// The mesh and the hole whose loop satisfies `pick` (the only such loop).
fn mesh_and_hole(raw: &RawMesh, pick: impl Fn(&Mesh, &[VertexId]) -> bool) -> (Mesh, Hole, Policy) {
    let (mesh, _) = Mesh::from_raw(raw);
    mesh.validate().unwrap();
    let policy = Policy::default();
    let loops: Vec<Vec<VertexId>> = mesh
        .topo
        .boundary_loops()
        .into_iter()
        .filter(|l| pick(&mesh, l))
        .collect();
    assert_eq!(loops.len(), 1, "expected one hole loop");
    let hole = Hole::new(0, &mesh, loops[0].clone(), &policy);
    (mesh, hole, policy)
}

/// Fills, checks topology and degeneracy, applies, validates. Returns the patch.
fn fill_checked(mesh: &mut Mesh, hole: &Hole, policy: &Policy) -> Patch {
    let ctx = FillContext {
        mesh,
        hole,
        policy,
        deadline: Deadline::none(),
        checker: None,
        rim_bound: false,
        guide: false,
        finish: None,
    };
    let patch = fill(&ctx).unwrap();
    check_topology(mesh, &hole.vertices, &patch).unwrap();
    let pos = patch_positions(mesh, &hole.vertices, &patch);
    check_degenerate(&pos, &patch, &policy.checks).unwrap();
    let before: Vec<DVec3> = mesh.positions.clone();
    apply_patch(mesh, hole, &patch).unwrap();
    mesh.validate().unwrap();
    assert!(mesh
        .topo
        .boundary_loops()
        .iter()
        .all(|l| l.len() != hole.len() || l != &hole.vertices));
    // untouched input vertices are bit-exact
    assert_eq!(&mesh.positions[..before.len()], &before[..]);
    patch
}

fn q_share(mesh: &Mesh, hole: &Hole, patch: &Patch) -> f64 {
    let pos = patch_positions(mesh, &hole.vertices, patch);
    quality(&pos, hole.len(), patch).q_good_share
}

/// Grid of (n+1)^2 vertices on z = 0 with the cells within `rad` of the centre removed.
fn planar_grid_hole(n: usize, rad: f64) -> RawMesh {
    let c = DVec3::new(n as f64 / 2.0, n as f64 / 2.0, 0.0);
    cut_faces(unit_grid(n), |p| (p - c).length() < rad)
}

fn interior_loop(n: usize) -> impl Fn(&Mesh, &[VertexId]) -> bool {
    move |m: &Mesh, l: &[VertexId]| {
        l.iter().all(|&v| {
            let p = m.pos(v);
            p.x > 0.0 && p.y > 0.0 && p.x < n as f64 && p.y < n as f64
        })
    }
}

#[test]
fn planar_hole_gives_a_planar_patch() {
    for weights in [Weights::Cotangent, Weights::Uniform, Weights::Fujiwara] {
        for c in 0..=3u8 {
            let raw = planar_grid_hole(24, 7.3);
            let (mut mesh, hole, mut policy) = mesh_and_hole(&raw, interior_loop(24));
            policy = policy.edit(|s| s.fair.weights = weights).unwrap();
            policy = policy.edit(|s| s.fair.continuity = c).unwrap();
            let patch = fill_checked(&mut mesh, &hole, &policy);
            assert!(!patch.new_vertices.is_empty());
            for p in &patch.new_vertices {
                assert!(p.z.abs() < 1e-9, "{weights:?} c={c}: {p}");
            }
            // refined to the surrounding density: edges near 1 (grid spacing)
            // cotangent weights keep the refined layout on a plane (linear precision);
            // the staircase boundary of a grid hole (right angles, 1 and sqrt 2 edges)
            // caps the share of near-equilateral triangles along it
            if weights == Weights::Cotangent {
                let share = q_share(&mesh, &hole, &patch);
                eprintln!("planar c={c}: q share {share:.3}");
                assert!(share > 0.65, "{weights:?} c={c}: q share {share}");
            }
        }
    }
}

fn sphere_case(level: usize, angle_deg: f64) -> (Mesh, Hole, Policy) {
    let r = 10.0;
    let raw = icosphere(level, r);
    let dir = DVec3::new(0.3, 0.5, 0.8).normalize();
    let raw = cut_faces(raw, |p| {
        p.normalize().dot(dir) > angle_deg.to_radians().cos()
    });
    mesh_and_hole(&raw, |_, _| true)
}

/// (mean |r - R| / R, max |r - R| / R) of the new vertices.
fn sphere_error(patch: &Patch, r: f64) -> (f64, f64) {
    let n = patch.new_vertices.len() as f64;
    let errs: Vec<f64> = patch
        .new_vertices
        .iter()
        .map(|p| (p.length() - r).abs() / r)
        .collect();
    (
        errs.iter().sum::<f64>() / n,
        errs.iter().cloned().fold(0.0, f64::max),
    )
}

#[test]
fn sphere_hole_of_about_20_vertices() {
    let (mut mesh, hole, policy) = sphere_case(4, 14.0);
    assert!((15..=30).contains(&hole.len()), "loop of {}", hole.len());
    let patch = fill_checked(&mut mesh, &hole, &policy);
    let (mean, max) = sphere_error(&patch, 10.0);
    let share = q_share(&mesh, &hole, &patch);
    eprintln!(
        "sphere k={} new={} mean={mean:.5} max={max:.5} q={share:.3}",
        hole.len(),
        patch.new_vertices.len()
    );
    assert!(mean < 0.002, "mean radial error {mean}");
    assert!(share > 0.8, "q share {share}");
}

#[test]
fn sphere_hole_of_about_100_vertices() {
    let (mut mesh, hole, policy) = sphere_case(5, 37.0);
    assert!((80..=140).contains(&hole.len()), "loop of {}", hole.len());
    let patch = fill_checked(&mut mesh, &hole, &policy);
    let (mean, max) = sphere_error(&patch, 10.0);
    let share = q_share(&mesh, &hole, &patch);
    eprintln!(
        "sphere k={} new={} mean={mean:.5} max={max:.5} q={share:.3}",
        hole.len(),
        patch.new_vertices.len()
    );
    assert!(mean < 0.01, "mean radial error {mean}");
    assert!(share > 0.8, "q share {share}");
}

fn cylinder_case() -> (Mesh, Hole, Policy, f64) {
    // open cylinder of radius 5 along z, 64 segments, 40 rings of height 0.5
    let (r, seg, rings, dz) = (5.0, 64usize, 40usize, 0.5);
    let raw = cylinder(r, seg, rings + 1, dz, 0.0, false);
    let centre = DVec3::new(r, 0.0, 10.0);
    let raw = cut_faces(raw, |p| (p - centre).length() < 2.6);
    let top = rings as f64 * dz;
    let (m, h, p) = mesh_and_hole(&raw, move |m, l| {
        l.iter().all(|&v| m.pos(v).z > 0.0 && m.pos(v).z < top)
    });
    (m, h, p, r)
}

#[test]
fn cylinder_hole_stays_on_the_cylinder() {
    let (mut mesh, hole, policy, r) = cylinder_case();
    let patch = fill_checked(&mut mesh, &hole, &policy);
    let errs: Vec<f64> = patch
        .new_vertices
        .iter()
        .map(|p| ((p.x * p.x + p.y * p.y).sqrt() - r).abs() / r)
        .collect();
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    let max = errs.iter().cloned().fold(0.0, f64::max);
    let share = q_share(&mesh, &hole, &patch);
    eprintln!(
        "cylinder k={} new={} mean={mean:.5} max={max:.5} q={share:.3}",
        hole.len(),
        patch.new_vertices.len()
    );
    assert!(mean < 0.01, "mean radial error {mean}");
    assert!(max < 0.03, "max radial error {max}");
    assert!(share > 0.8, "q share {share}");
}

#[test]
fn dihedral_weight_also_fills_the_sphere() {
    let (mut mesh, hole, mut policy) = sphere_case(4, 14.0);
    policy = policy
        .edit(|s| s.refine.weight = TriangulationWeight::DihedralArea)
        .unwrap();
    let patch = fill_checked(&mut mesh, &hole, &policy);
    let (mean, _) = sphere_error(&patch, 10.0);
    assert!(mean < 0.002, "mean radial error {mean}");
}

#[test]
fn higher_continuity_fits_the_sphere_better_than_membrane() {
    let mut errs = Vec::new();
    for c in 1..=3u8 {
        let (mut mesh, hole, mut policy) = sphere_case(5, 30.0);
        policy = policy.edit(|s| s.fair.continuity = c).unwrap();
        let patch = fill_checked(&mut mesh, &hole, &policy);
        errs.push(sphere_error(&patch, 10.0).0);
    }
    eprintln!("sphere errors by continuity {errs:?}");
    // a membrane is flat-ish: it sags well inside the sphere
    assert!(errs[1] < errs[0] / 3.0, "{errs:?}");
    assert!(errs[2] < errs[0] / 3.0, "{errs:?}");
}

#[test]
fn refairing_on_the_faired_surface_keeps_the_patch_on_the_sphere() {
    // the first fairing runs on the flat first guess; later passes (`fair.passes`)
    // take the layout and the weights from the faired surface
    let mut errs = Vec::new();
    for passes in [0usize, 1, 3] {
        let (mut mesh, hole, mut policy) = sphere_case(5, 37.0);
        policy = policy.edit(|s| s.fair.passes = passes).unwrap();
        let patch = fill_checked(&mut mesh, &hole, &policy);
        errs.push(sphere_error(&patch, 10.0).0);
    }
    eprintln!("sphere errors by passes 0, 1, 3: {errs:?}");
    assert!(errs.iter().all(|&e| e < 0.01), "{errs:?}");
    // measured: 0.0063, 0.0041, 0.0039
    assert!(errs[1] < errs[0] * 0.8, "{errs:?}");
    assert!(errs[2] <= errs[1] * 1.05, "{errs:?}");
}

/// A loop with no surrounding mesh but its own ring: an annulus of one strip, faces up.
fn annulus(k: usize, wave: f64) -> (Mesh, Hole, Policy) {
    let r = k as f64 / std::f64::consts::TAU;
    let circle = |radius: f64| -> Vec<DVec3> {
        (0..k)
            .map(|i| {
                let t = i as f64 / k as f64 * std::f64::consts::TAU;
                let z = wave * r * (2.0 * t).cos() * 0.3;
                DVec3::new(radius * t.cos(), radius * t.sin(), z)
            })
            .collect()
    };
    let raw = strip(&circle(r), &circle(r + 1.0));
    mesh_and_hole(&raw, |m, l| {
        l.iter().all(|&v| v.idx() < k && m.pos(v).is_finite())
    })
}

#[test]
fn long_loops_are_filled() {
    // a full fill of a 300-vertex loop, flat and saddle-like (a 1,000-vertex one takes
    // seconds in the test profile; its triangulation is tested below)
    for wave in [0.0, 1.0] {
        let (mut mesh, hole, policy) = annulus(300, wave);
        let patch = fill_checked(&mut mesh, &hole, &policy);
        if wave == 0.0 {
            assert!(patch.new_vertices.iter().all(|p| p.z.abs() < 1e-9));
        }
        assert!(patch.new_vertices.len() > 1000);
    }
}

#[test]
fn thousand_vertex_loops_triangulate() {
    for wave in [0.0, 1.0] {
        let (mesh, hole, policy) = annulus(1000, wave);
        let pts: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
        let forbidden = forbidden_chords(&mesh, &hole.vertices);
        let outside = outside_normals(&mesh, &hole.vertices);
        for weight in [TriangulationWeight::Area, TriangulationWeight::DihedralArea] {
            let input = triangulate::LoopInput {
                pts: &pts,
                forbidden: &forbidden,
                outside_normals: &outside,
                weight,
                min_angle: policy.checks.min_angle_deg.to_radians(),
                restricted_above: policy.refine.restricted_search_above,
                delaunay: false,
                deadline: Deadline::none(),
            };
            let tris = triangulate::triangulate(&input).unwrap();
            let patch = Patch {
                new_vertices: Vec::new(),
                triangles: tris,
            };
            check_topology(&mesh, &hole.vertices, &patch).unwrap();
        }
    }
}

#[test]
fn ten_thousand_vertex_loop_triangulates() {
    let k = 10_000;
    let pts: Vec<DVec3> = (0..k)
        .map(|i| {
            let t = -(i as f64) / k as f64 * std::f64::consts::TAU;
            DVec3::new(t.cos(), t.sin(), 0.2 * (5.0 * t).sin())
        })
        .collect();
    let forbidden = HashSet::default();
    let outside = vec![None; k];
    let input = triangulate::LoopInput {
        pts: &pts,
        forbidden: &forbidden,
        outside_normals: &outside,
        weight: TriangulationWeight::DihedralArea,
        min_angle: 0.0,
        restricted_above: 60,
        delaunay: false,
        deadline: Deadline::none(),
    };
    let tris = triangulate::triangulate(&input).unwrap();
    assert_eq!(tris.len(), k - 2);
}

/// A mesh whose hole is a star-shaped polygon: the polygon plus a one-strip collar.
fn star_hole(radii: &[f64], lift: f64) -> (Mesh, Hole, Policy) {
    let k = radii.len();
    let mut raw = RawMesh::default();
    for (i, &r) in radii.iter().enumerate() {
        let t = i as f64 / k as f64 * std::f64::consts::TAU;
        let z = lift * (3.0 * t).sin();
        raw.positions.push(DVec3::new(r * t.cos(), r * t.sin(), z));
        raw.positions
            .push(DVec3::new((r + 0.5) * t.cos(), (r + 0.5) * t.sin(), z));
    }
    for i in 0..k {
        let j = (i + 1) % k;
        let (a, b, c, d) = (
            2 * i as u32,
            2 * j as u32,
            2 * j as u32 + 1,
            2 * i as u32 + 1,
        );
        raw.faces.push([a, b, c]);
        raw.faces.push([a, c, d]);
    }
    mesh_and_hole(&raw, |_, l| l.iter().all(|&v| v.idx() % 2 == 0))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    #[test]
    fn random_star_polygons_give_disk_patches(
        radii in proptest::collection::vec(0.5f64..2.0, 5..90),
        lift in 0.0f64..0.5,
        restricted in 3usize..80,
    ) {
        let (mut mesh, hole, mut policy) = star_hole(&radii, lift);
        policy = policy.edit(|s| s.refine.restricted_search_above = restricted).unwrap();
        let ctx = FillContext { mesh: &mesh, hole: &hole, policy: &policy, deadline: Deadline::none(), checker: None, rim_bound: false, guide: false, finish: None };
        let patch = fill(&ctx).unwrap();
        check_topology(&mesh, &hole.vertices, &patch).unwrap();
        apply_patch(&mut mesh, &hole, &patch).unwrap();
        mesh.validate().unwrap();
    }
}
#[test]
fn voronoi_normalisation_beats_the_raw_cotangent_operator_on_the_sphere() {
    // the reason fair.rs normalises by the mixed Voronoi area: the refined patch has
    // smaller triangles than the ring around it
    for (level, angle) in [(4usize, 14.0f64), (5, 30.0)] {
        let (mesh, hole, policy) = sphere_case(level, angle);
        let ctx = FillContext::new(&mesh, &hole, &policy);
        let patch = fill(&ctx).unwrap();
        let err = |norm| {
            let local = fair::local_from_patch(&mesh, &hole, &patch, 2);
            let s = fair::FairSolver::new(&local, 2, Weights::Cotangent, norm).unwrap();
            let p = Patch {
                new_vertices: s.solve().unwrap(),
                triangles: patch.triangles.clone(),
            };
            sphere_error(&p, 10.0).0
        };
        let (raw, vor) = (
            err(fair::Normalization::None),
            err(fair::Normalization::VoronoiArea),
        );
        assert!(vor < raw / 2.0, "voronoi {vor} raw {raw}");
    }
}

#[test]
fn coarse_scale_keeps_huge_patches_under_the_cap() {
    // a planar unit square fanned from one corner, scale 0.01: about 25,000 triangles
    // at density sqrt 2 (area 1 / (0.4 * 0.01²))
    let pts = vec![DVec3::ZERO, DVec3::X, DVec3::new(1.0, 1.0, 0.0), DVec3::Y];
    let tris = vec![[0, 1, 2], [0, 2, 3]];
    let scale = vec![0.01; 4];
    let d = std::f64::consts::SQRT_2;
    assert_eq!(super::coarse_scale(&pts, &tris, &scale, d, 0), None);
    assert_eq!(super::coarse_scale(&pts, &tris, &scale, d, 100_000), None);
    let f = super::coarse_scale(&pts, &tris, &scale, d, 10_000).expect("coarser");
    // n / (0.8 cap) = 25,000 / 8,000: the scale grows by its square root
    assert!(
        (f - 0.01 * (25_000.0f64 / 8_000.0).sqrt()).abs() < 1e-9,
        "{f}"
    );
}

#[test]
fn huge_planar_hole_gets_a_graded_planar_patch() {
    // a round hole of radius 25 in a unit grid: refined to the grid's density its
    // patch would have some 3,800 triangles; under a cap of 1,000 it is graded
    let raw = planar_grid_hole(60, 25.0);
    let (mut mesh, hole, mut policy) = mesh_and_hole(&raw, interior_loop(60));
    policy = policy
        .edit(|s| s.limits.max_patch_triangles = 1000)
        .unwrap();
    let k = hole.len();
    let patch = fill_checked(&mut mesh, &hole, &policy);
    assert!(
        patch.triangles.len() < 1000,
        "{} triangles",
        patch.triangles.len()
    );
    assert!(
        patch.triangles.len() > k,
        "{} triangles",
        patch.triangles.len()
    );
    // every fixed vertex has z = 0: so has every new one, exactly
    assert!(patch.new_vertices.iter().all(|p| p.z == 0.0));
    let c = DVec3::new(30.0, 30.0, 0.0);
    assert!(patch.new_vertices.iter().all(|p| (*p - c).length() < 25.5));
    // Delaunay refinement at 20 degrees; the cotangent fairing keeps a flat layout
    let pos = patch_positions(&mesh, &hole.vertices, &patch);
    let q = quality(&pos, k, &patch);
    assert!(q.min_angle_deg > 15.0, "smallest angle {}", q.min_angle_deg);
    // triangles grow away from the loop: the largest is far bigger than the grid's
    let largest = patch
        .triangles
        .iter()
        .map(|t| {
            crate::geometry::measure::tri_area(
                pos[t[0] as usize],
                pos[t[1] as usize],
                pos[t[2] as usize],
            )
        })
        .fold(0.0f64, f64::max);
    assert!(largest > 4.0, "largest triangle {largest}");
}

#[test]
fn huge_sphere_hole_gets_a_graded_patch_near_the_sphere() {
    // a hole of about 100 vertices on a sphere of radius 10 (37-degree cap), under a
    // cap that makes it huge: graded, faired twice; measured 0.4 % of the radius on
    // average and 1.2 % at most (the bounds of the full-density patch above: 1 %)
    let (mut mesh, hole, mut policy) = sphere_case(5, 37.0);
    policy = policy
        .edit(|s| s.limits.max_patch_triangles = 1000)
        .unwrap();
    let patch = fill_checked(&mut mesh, &hole, &policy);
    assert!(
        patch.triangles.len() < 1000,
        "{} triangles",
        patch.triangles.len()
    );
    let (mean, max) = sphere_error(&patch, 10.0);
    eprintln!(
        "graded sphere k={} new={} mean={mean:.5} max={max:.5}",
        hole.len(),
        patch.new_vertices.len()
    );
    assert!(mean < 0.008, "mean radial error {mean}");
    assert!(max < 0.025, "max radial error {max}");
}

/// The self-checked fill returns a patch that passes the dispatcher's checks, with the
/// quality of those checks (so the dispatcher need not check it again), and its
/// variants are the policy and the other triangulation weight.
#[test]
fn the_self_checked_fill_returns_a_checked_patch() {
    let (mesh, hole, policy) = sphere_case(4, 20.0);
    let ctx = FillContext::new(&mesh, &hole, &policy);
    let (patch, q) = super::fill_checked(&ctx).unwrap();
    let checker = crate::check::Checker::new(&mesh);
    let want = checker
        .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
        .unwrap();
    assert_eq!(q.map(|q| q.quality), Some(want));
    let (mean, _) = sphere_error(&patch, 10.0);
    assert!(mean < 0.002, "mean radial error {mean}");
    let v = variants(&policy);
    assert_eq!(v.len(), 4);
    assert_eq!(v[0].1.refine.weight, TriangulationWeight::DihedralArea);
    assert_eq!(v[1].1.refine.weight, TriangulationWeight::Area);
    assert_eq!(v[2].1.refine.collapse, 0.0);
    assert_eq!(v[2].1.refine.weight, TriangulationWeight::DihedralArea);
    assert_eq!(v[3].1.fair.weights, crate::policy::Weights::Uniform);
    assert_eq!(v[3].1.refine.collapse, policy.refine.collapse);
    // a policy without collapses, or with uniform weights, has no such variant
    let none = policy.edit(|s| s.refine.collapse = 0.0).unwrap();
    assert_eq!(variants(&none).len(), 3);
    let uniform = policy
        .edit(|s| s.fair.weights = crate::policy::Weights::Uniform)
        .unwrap();
    assert_eq!(variants(&uniform).len(), 3);
}

/// `refine.search = "both"` keeps whichever of the two searches' checked patches has
/// the larger area; the Delaunay search's patch is a valid patch on the sphere too.
#[test]
fn both_searches_keep_the_larger_patch() {
    let (mesh, hole, policy) = sphere_case(5, 37.0);
    let made = |search: Search| {
        let p = policy.edit(|s| s.refine.search = search).unwrap();
        let ctx = FillContext::new(&mesh, &hole, &p);
        super::fill_checked(&ctx).unwrap()
    };
    let area = |p: &Patch| p.area(&mesh, &hole);
    let (full, delaunay, both) = (
        made(Search::Full),
        made(Search::Delaunay),
        made(Search::Both),
    );
    let larger = if area(&delaunay.0) > area(&full.0) {
        &delaunay
    } else {
        &full
    };
    assert_eq!(&both, larger);
    assert!(both.1.is_some(), "checked");
    let (mean, _) = sphere_error(&delaunay.0, 10.0);
    assert!(mean < 0.01, "mean radial error {mean}");
    let mut m = mesh.clone();
    apply_patch(&mut m, &hole, &delaunay.0).unwrap();
    m.validate().unwrap();
}

#[test]
fn refine_collapse_zero_keeps_the_short_edges_of_the_splits() {
    // the sphere hole of about 100 vertices: collapsing (the default 0.75) leaves fewer
    // new vertices and a larger share of well-shaped triangles than none, both on the
    // sphere
    let (mesh, hole, policy) = sphere_case(5, 37.0);
    let none = policy.edit(|s| s.refine.collapse = 0.0).unwrap();
    let (mut m1, mut m2) = (mesh.clone(), mesh);
    let with = fill_checked(&mut m1, &hole, &policy);
    let without = fill_checked(&mut m2, &hole, &none);
    assert!(
        with.new_vertices.len() < without.new_vertices.len(),
        "{} collapsed against {} not",
        with.new_vertices.len(),
        without.new_vertices.len()
    );
    assert!(q_share(&m1, &hole, &with) > q_share(&m2, &hole, &without));
    for p in [&with, &without] {
        let (mean, _) = sphere_error(p, 10.0);
        assert!(mean < 0.01, "mean radial error {mean}");
    }
}
