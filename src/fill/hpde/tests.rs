//! Oracle tests of HPDE: analytic surfaces (plane, sphere, cylinder, saddle) with
//! stated bounds, the paper's noise experiment, determinism, and the patch checks.

use super::*;
use crate::check::{check_degenerate, check_topology, patch_positions, quality};
use crate::io::RawMesh;
use crate::mesh::Mesh;
use crate::patch::{apply_patch, Hole};
use crate::policy::{Checks, Policy};
use crate::testutil::{self, cylinder_with_hole, sphere_with_hole};
use glam::DVec3;
use rand::{Rng, SeedableRng};
use std::f64::consts::PI;

// ----- mesh builders ----------------------------------------------------------------

/// Builds a mesh from raw data and returns it with the loop that is not the outer
/// border (the loop for which `pick` is true).
fn build(raw: &RawMesh, pick: impl Fn(&[VertexId]) -> bool) -> (Mesh, Vec<VertexId>) {
    testutil::mesh_and_loop(raw, |_, l| pick(l))
}

/// A grid of `n x n` cells of size `h` centred on the origin, heights `z(x, y)`, with
/// every face whose centroid satisfies `cut` removed.
fn height_grid(
    n: usize,
    h: f64,
    z: impl Fn(f64, f64) -> f64,
    cut: impl Fn(DVec3) -> bool,
) -> (Mesh, Vec<VertexId>) {
    // the diagonals alternate so the grid has no preferred direction
    let half = n as f64 * h / 2.0;
    let raw = testutil::cut_faces(testutil::grid_alternating(n, -half, half, z), cut);
    build(&raw, |l| l.len() != 4 * n)
}

// ----- running and checking ---------------------------------------------------------

/// The largest `|r - 1|` of the patch's new vertices, `r` their distance from the z
/// axis (the unit cylinder's oracle).
fn max_radial_error(patch: &Patch) -> f64 {
    patch
        .new_vertices
        .iter()
        .map(|p| (p.truncate().length() - 1.0).abs())
        .fold(0.0, f64::max)
}

fn run(mesh: &Mesh, lp: &[VertexId], policy: &Policy) -> (Hole, Result<Patch, FillError>) {
    crate::fill::kit::run_on(mesh, lp.to_vec(), policy, fill)
}

/// The patch passes the dispatcher's topology and degeneracy checks and applies to a
/// valid mesh; returns (share of q > 1.39, smallest angle in degrees).
fn validate(mesh: &Mesh, hole: &Hole, patch: &Patch) -> (f64, f64) {
    check_topology(mesh, &hole.vertices, patch).unwrap();
    let pos = patch_positions(mesh, &hole.vertices, patch);
    check_degenerate(&pos, patch, &Checks::default()).unwrap();
    let mut m2 = mesh.clone();
    let faces = apply_patch(&mut m2, hole, patch).unwrap();
    assert_eq!(faces.len(), patch.triangles.len());
    m2.validate().unwrap();
    // the input vertices are untouched
    for v in 0..mesh.num_vertices() {
        let v = VertexId::from_idx(v);
        assert_eq!(mesh.pos(v).to_array(), m2.pos(v).to_array());
    }
    let q = quality(&pos, hole.len(), patch);
    (q.q_good_share, q.min_angle_deg)
}

fn report(name: &str, k: usize, patch: &Patch, q: (f64, f64), err: f64) {
    eprintln!(
        "hpde {name}: k={k} new={} tris={} q>1.39={:.3} min_angle={:.2} max_err={:.2e}",
        patch.new_vertices.len(),
        patch.triangles.len(),
        q.0,
        q.1,
        err
    );
}

// ----- tests --------------------------------------------------------------------------

#[test]
fn planar_hole_gives_a_planar_patch() {
    let (mesh, lp) = height_grid(
        30,
        1.0,
        |_, _| 0.0,
        |c| (c - DVec3::new(0.3, -0.2, 0.0)).length() < 9.0,
    );
    assert!(lp.len() > 40, "loop of {}", lp.len());
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    let q = validate(&mesh, &hole, &patch);
    let err = patch
        .new_vertices
        .iter()
        .map(|p| p.z.abs())
        .fold(0.0, f64::max);
    report("plane", lp.len(), &patch, q, err);
    assert!(patch.new_vertices.len() > 100);
    assert!(err < 1e-9, "z = {err}");
    for p in &patch.new_vertices {
        assert!((p.truncate() - glam::DVec2::new(0.3, -0.2)).length() < 9.5);
    }
}

fn sphere_case(level: usize, cap: f64, k_range: std::ops::Range<usize>, bound: f64) {
    let (mesh, lp) = sphere_with_hole(level, cap);
    assert!(k_range.contains(&lp.len()), "loop of {}", lp.len());
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    let q = validate(&mesh, &hole, &patch);
    let err = patch
        .new_vertices
        .iter()
        .map(|p| (p.length() - 1.0).abs())
        .fold(0.0, f64::max);
    report(&format!("sphere L{level}"), lp.len(), &patch, q, err);
    let signed: f64 = patch
        .new_vertices
        .iter()
        .map(|p| p.length() - 1.0)
        .sum::<f64>()
        / patch.new_vertices.len().max(1) as f64;
    eprintln!(
        "  mean signed r-1 = {signed:.2e}, edge {:.3}",
        hole.mean_edge_length
    );
    assert!(!patch.new_vertices.is_empty());
    assert!(err < bound, "max |r - 1| = {err} (bound {bound})");
}

#[test]
fn sphere_hole_about_30() {
    sphere_case(3, 0.75, 20..45, 0.02);
}

#[test]
fn sphere_hole_about_100() {
    sphere_case(4, 1.1, 70..140, 0.02);
}

#[test]
fn cylinder_hole() {
    let (mesh, lp) = cylinder_with_hole(48, 30, 0.7, 1.2);
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    let q = validate(&mesh, &hole, &patch);
    let err = max_radial_error(&patch);
    report("cylinder", lp.len(), &patch, q, err);
    assert!(!patch.new_vertices.is_empty());
    assert!(err < 0.02, "max |r - 1| = {err}");
}

#[test]
fn saddle_hole() {
    let c = 0.03;
    let z = move |x: f64, y: f64| c * (x * x - y * y);
    let (mesh, lp) = height_grid(30, 1.0, z, |p| p.truncate().length() < 7.0);
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    let q = validate(&mesh, &hole, &patch);
    let err = patch
        .new_vertices
        .iter()
        .map(|p| (p.z - z(p.x, p.y)).abs())
        .fold(0.0, f64::max);
    report("saddle", lp.len(), &patch, q, err);
    assert!(!patch.new_vertices.is_empty());
    // the surface spans z in [-1.47, 1.47] around the hole (radius 7)
    assert!(err < 0.1, "max |z - c(x^2 - y^2)| = {err}");
}

/// The paper's noise experiment (§5): noise on the vertices around the hole; the
/// hole still closes and the patch stays near the true sphere.
#[test]
fn noisy_sphere_hole_still_closes() {
    let (mut mesh, lp) = sphere_with_hole(4, 0.8);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let sigma = 0.005;
    // vertices within 3 rings of the loop
    let mut ring: BTreeSet<VertexId> = lp.iter().copied().collect();
    for _ in 0..3 {
        let cur: Vec<VertexId> = ring.iter().copied().collect();
        for v in cur {
            for w in mesh.topo.neighbors(v) {
                ring.insert(w);
            }
        }
    }
    for &v in &ring {
        // Box-Muller: Gaussian noise along each axis
        let mut g = || {
            let u1: f64 = rng.random::<f64>().max(1e-300);
            let u2: f64 = rng.random();
            (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
        };
        let d = DVec3::new(g(), g(), g()) * sigma;
        mesh.positions[v.idx()] += d;
    }
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    let q = validate(&mesh, &hole, &patch);
    let err = patch
        .new_vertices
        .iter()
        .map(|p| (p.length() - 1.0).abs())
        .fold(0.0, f64::max);
    report("noisy sphere", lp.len(), &patch, q, err);
    // sigma = 0.005: the bound is 10 sigma
    assert!(err < 0.05, "max |r - 1| = {err}");
}

/// Without smoothing or collapse, the raw triangulation plus swaps is still a valid
/// disk (the improvement steps keep the topology whatever the geometry).
#[test]
fn every_improvement_step_keeps_a_valid_disk() {
    for (mesh, lp) in [
        sphere_with_hole(3, 0.75),
        sphere_with_hole(4, 1.1),
        cylinder_with_hole(48, 30, 0.7, 1.2),
    ] {
        for (ns, cr) in [(0, 0.0), (0, 0.6), (60, 0.0), (5, 0.9)] {
            let mut policy = Policy::default();
            policy = policy.edit(|s| s.hpde.num_smooth = ns).unwrap();
            policy = policy.edit(|s| s.hpde.collapse_rate = cr).unwrap();
            let (hole, r) = run(&mesh, &lp, &policy);
            validate(&mesh, &hole, &r.unwrap());
        }
    }
}

#[test]
fn same_seed_same_patch_bits() {
    let (mesh, lp) = sphere_with_hole(3, 0.75);
    let policy = Policy::default();
    let (_, a) = run(&mesh, &lp, &policy);
    let (_, b) = run(&mesh, &lp, &policy);
    let (a, b) = (a.unwrap(), b.unwrap());
    let bits = |p: &Patch| -> Vec<u64> {
        p.new_vertices
            .iter()
            .flat_map(|v| v.to_array().map(f64::to_bits))
            .collect()
    };
    assert_eq!(a.triangles, b.triangles);
    assert_eq!(bits(&a), bits(&b));
}

/// A hole across the ridge of a roof whose faces meet at 60 degrees: the segmentation
/// test splits it in two planes and the patch follows both faces.
#[test]
fn sharp_ridge_is_segmented_into_two_planes() {
    // faces z = -|x| tan(60 deg): dihedral angle at the ridge 60 degrees
    let s = 60f64.to_radians().tan();
    let roof = move |x: f64, _y: f64| -x.abs() * s;
    let (mesh, lp) = height_grid(48, 0.25, roof, |c| {
        // cut a disk measured along the surface (unfolded x)
        let u = c.x.abs() / (60f64.to_radians().cos());
        (u * u + c.y * c.y).sqrt() < 2.6
    });
    let bp: Vec<DVec3> = lp.iter().map(|&v| mesh.pos(v)).collect();
    let normals: Vec<DVec3> = lp.iter().map(|&v| mesh.vertex_normal(v)).collect();
    let seg = predict::segmentation(&bp, &normals).unwrap();
    assert!(
        (seg.dihedral - 60f64.to_radians()).abs() < 0.05,
        "a 60 degree ridge must be segmented (dihedral {} deg)",
        seg.dihedral.to_degrees()
    );
    let (hole, r) = run(&mesh, &lp, &Policy::default());
    let patch = r.unwrap();
    let q = validate(&mesh, &hole, &patch);
    // distance to the nearer face plane
    let dist = |p: DVec3| {
        let d = |sg: f64| (p.z + s * sg * p.x).abs() / (1.0 + s * s).sqrt();
        d(1.0).min(d(-1.0))
    };
    let near: Vec<f64> = patch
        .new_vertices
        .iter()
        .filter(|p| p.x.abs() < 0.4)
        .map(|p| dist(*p))
        .collect();
    let far: Vec<f64> = patch
        .new_vertices
        .iter()
        .filter(|p| p.x.abs() >= 0.4)
        .map(|p| dist(*p))
        .collect();
    let err = far.iter().copied().fold(0.0, f64::max);
    let err_near = near.iter().copied().fold(0.0, f64::max);
    report("ridge", lp.len(), &patch, q, err);
    eprintln!(
        "  near the ridge {err_near:.3e} ({} points), away {err:.3e} ({} points)",
        near.len(),
        far.len()
    );
    assert!(far.len() > 50 && near.len() > 10);
    // the smoothing rounds the ridge (the paper's Fig. 15b): within 0.4 of it (about
    // one edge) the bound is 0.2, elsewhere 0.08 (edges are about 0.35 long)
    assert!(err_near < 0.2, "near the ridge: {err_near}");
    assert!(err < 0.08, "away from the ridge: {err}");
    // a flat disk is not segmented
    let (flat, lp) = height_grid(24, 0.5, |_, _| 0.0, |c| c.truncate().length() < 2.6);
    let bp: Vec<DVec3> = lp.iter().map(|&v| flat.pos(v)).collect();
    let normals: Vec<DVec3> = lp.iter().map(|&v| flat.vertex_normal(v)).collect();
    if let Some(s) = predict::segmentation(&bp, &normals) {
        assert!(
            s.dihedral > 170f64.to_radians(),
            "{}",
            s.dihedral.to_degrees()
        );
    }
}

/// A hole wrapping most of the way around a cylinder does not project to a simple
/// polygon on one plane: the paper's topology says so (and the variants over the
/// minimum-area surface are tried next).
#[test]
fn non_injective_projection_is_a_clean_error() {
    // +-166 degrees around the axis: even the two unfolded planes fold over
    let (mesh, lp) = cylinder_with_hole(32, 24, 2.9, 1.5);
    let mut policy = Policy::default();
    policy = policy.edit(|s| s.hpde.disk_fallback = false).unwrap();
    let hole = Hole::new(0, &mesh, lp, &policy);
    let ctx = FillContext::new(&mesh, &hole, &policy);
    match fill_with(&ctx, Topology::Plane) {
        Err(e @ FillError::Failed(_)) => {
            assert!(e.to_string().contains("simple polygon on any plane"), "{e}")
        }
        other => panic!(
            "expected a projection failure, got {:?}",
            other.map(|p| p.triangles.len())
        ),
    }
}

/// The same hole: where no plane variant closes it, the variants over the loop's
/// minimum-area surface do, with a valid patch near the cylinder.
#[test]
fn a_hole_no_plane_sees_closes_over_its_minimum_area_surface() {
    let (mesh, lp) = cylinder_with_hole(32, 24, 2.9, 1.5);
    let policy = Policy::default()
        .edit(|s| s.hpde.disk_fallback = false)
        .unwrap();
    let (hole, r) = run(&mesh, &lp, &policy);
    let patch = r.unwrap();
    let q = validate(&mesh, &hole, &patch);
    crate::check::Checker::new(&mesh)
        .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
        .unwrap();
    let err = max_radial_error(&patch);
    report("cylinder, wound", lp.len(), &patch, q, err);
    assert!(!patch.new_vertices.is_empty());
    assert!(err < 0.05, "max |r - 1| = {err}");
}

/// The self-checked wrapper returns the policy's own patch when it passes the checks
/// (so the variants change nothing on holes HPDE closes as the paper says), relaxed
/// tangentially as the dispatcher would.
#[test]
fn the_wrapper_keeps_a_passing_patch() {
    let raw = crate::testutil::sphere_cap_removed(3, 1.0, DVec3::new(0.3, 0.2, 1.0), 0.6);
    let (mesh, lp) = build(&raw, |_| true);
    let policy = Policy::default();
    let hole = Hole::new(0, &mesh, lp, &policy);
    let ctx = FillContext::new(&mesh, &hole, &policy);
    let once = fill_once(&ctx).unwrap();
    crate::check::Checker::new(&mesh)
        .check_patch(&mesh, &hole.vertices, &once, &policy.checks)
        .unwrap();
    let mut relaxed = once.clone();
    crate::fill::kit::relax::tangential_relax(
        &mesh,
        &hole,
        &mut relaxed,
        policy.fair.tangential_relax,
        crate::fill::kit::relax::RELAX_STEP,
    );
    assert_ne!(relaxed, once);
    assert_eq!(fill(&ctx).unwrap(), relaxed);
    assert_eq!(variants(&policy)[0].1, policy);
}
