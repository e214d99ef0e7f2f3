use super::wave::inside_or_near;
use super::*;
use crate::check::{check_degenerate, check_topology, patch_positions};
use crate::fill::kit::Deadline;
use crate::io::RawMesh;
use crate::mesh::{Mesh, VertexId};
use crate::patch::{apply_patch, Hole};
use crate::policy::{Policy, Settings};
use crate::testutil::{self, loop_near};
use proptest::prelude::*;

/// A regular grid `n x n` over `[-1, 1]^2` with heights `z(x, y)`, faces up, and the
/// faces whose centroid lies within `r` of the origin removed.
fn grid_hole(n: usize, r: f64, z: impl Fn(f64, f64) -> f64) -> RawMesh {
    testutil::cut_faces(testutil::grid(n, -1.0, 1.0, z), |c| {
        c.x * c.x + c.y * c.y <= r * r
    })
}

/// An open cylinder of radius `rad` around z, `nt` columns, `nz` rows of height
/// `h`, faces outward, with the faces whose centroid is within `r` of `(rad, 0, 0)`
/// removed.
fn cylinder_hole(rad: f64, nt: usize, nz: usize, h: f64, r: f64) -> RawMesh {
    let raw = testutil::cylinder(rad, nt, nz + 1, h, -(nz as f64) * h / 2.0, false);
    let hc = DVec3::new(rad, 0.0, 0.0);
    testutil::cut_faces(raw, |c| (c - hc).length() <= r)
}

fn run(mesh: &Mesh, l: Vec<VertexId>, policy: &Policy) -> (Hole, Result<Patch, FillError>) {
    crate::fill::kit::run_on(mesh, l, policy, fill)
}

/// The patch passes the dispatcher's checks and applies to a valid, hole-free mesh.
fn accept(mesh: &Mesh, hole: &Hole, patch: &Patch, policy: &Policy) {
    check_topology(mesh, &hole.vertices, patch).unwrap();
    let pos = patch_positions(mesh, &hole.vertices, patch);
    check_degenerate(&pos, patch, &policy.checks).unwrap();
    let mut m = mesh.clone();
    let loops = m.topo.boundary_loops().len();
    apply_patch(&mut m, hole, patch).unwrap();
    m.validate().unwrap();
    assert_eq!(m.topo.boundary_loops().len(), loops - 1);
}

/// Mean and max of `err` over the new vertices.
fn stats_of(patch: &Patch, err: impl Fn(DVec3) -> f64) -> (f64, f64) {
    let e: Vec<f64> = patch.new_vertices.iter().map(|&p| err(p)).collect();
    let mean = e.iter().sum::<f64>() / e.len().max(1) as f64;
    (mean, e.iter().cloned().fold(0.0, f64::max))
}

#[test]
fn planar_hole_gives_a_planar_patch() {
    let (mesh, _) = Mesh::from_raw(&grid_hole(20, 0.45, |_, _| 0.0));
    let policy = Policy::default();
    let l = loop_near(&mesh, DVec3::ZERO);
    assert!(l.len() > 20, "{}", l.len());
    let (hole, r) = run(&mesh, l, &policy);
    let patch = r.unwrap();
    assert!(!patch.new_vertices.is_empty());
    accept(&mesh, &hole, &patch, &policy);
    for p in &patch.new_vertices {
        assert!(p.z.abs() < 1e-9, "{p}");
        assert!(p.x * p.x + p.y * p.y < 0.6 * 0.6, "{p} outside the hole");
    }
}

/// A filled hole measured against its surface.
#[derive(Debug)]
struct Measure {
    k: usize,
    mean: f64,
    max: f64,
    stats: Stats,
    patch: Patch,
}

/// Fills the loop nearest `centre` under a policy changed by `tweak`, checks the patch
/// like the dispatcher does and measures `|err|` over the new vertices.
fn measure(
    raw: &RawMesh,
    centre: DVec3,
    tweak: impl Fn(&mut Settings),
    err: impl Fn(DVec3) -> f64,
) -> Measure {
    let (mesh, _) = Mesh::from_raw(raw);
    mesh.validate().unwrap();
    let mut settings = Settings::default();
    tweak(&mut settings);
    let policy = Policy::new(settings).unwrap();
    let l = loop_near(&mesh, centre);
    let k = l.len();
    let hole = Hole::new(0, &mesh, l, &policy);
    let ctx = FillContext::new(&mesh, &hole, &policy);
    let (patch, stats) = fill_with_stats(&ctx).unwrap();
    accept(&mesh, &hole, &patch, &policy);
    let (mean, max) = stats_of(&patch, |p| err(p).abs());
    Measure {
        k,
        mean,
        max,
        stats,
        patch,
    }
}

fn restore(on: bool) -> impl Fn(&mut Settings) {
    move |p: &mut Settings| p.wavefront.curvature_restoration = on
}

fn sphere_err(p: DVec3) -> f64 {
    p.length() - 1.0
}

fn sphere(level: usize, cap: f64) -> RawMesh {
    testutil::sphere_cap_removed(level, 1.0, SPHERE_DIR, cap)
}

const SPHERE_DIR: DVec3 = DVec3::new(0.3, 0.2, 1.0);

/// Unit sphere, hole of ~30 boundary vertices (icosphere level 3, 25): mean |r - 1| of
/// the new vertices below 0.05, max below 0.15 (measured 0.033 / 0.090 with
/// restoration, 0.033 / 0.067 without; edge length 0.148). Hole of ~150 (level 5, 140):
/// below 0.03 with restoration, 0.05 without (measured 0.020 and 0.032; edge length
/// 0.037), and restoration is better there.
#[test]
fn sphere_holes_stay_near_the_sphere() {
    let small_on = measure(&sphere(3, 0.55), SPHERE_DIR, restore(true), sphere_err);
    let small_off = measure(&sphere(3, 0.55), SPHERE_DIR, restore(false), sphere_err);
    assert!((20..=40).contains(&small_on.k), "{}", small_on.k);
    assert!(small_on.mean < 0.05 && small_off.mean < 0.05);
    assert!(small_on.max < 0.15 && small_off.max < 0.15);
    let large_on = measure(&sphere(5, 0.7), SPHERE_DIR, restore(true), sphere_err);
    let large_off = measure(&sphere(5, 0.7), SPHERE_DIR, restore(false), sphere_err);
    assert!((120..=180).contains(&large_on.k), "{}", large_on.k);
    assert!(large_on.mean < 0.03, "{}", large_on.mean);
    assert!(large_off.mean < 0.05, "{}", large_off.mean);
    assert!(large_on.mean <= large_off.mean);
}

/// A hole deeper than a hemisphere (cap of 109 degrees: its surface has 2.95 times
/// the loop's vector area): the front passes `max_area_ratio` (2.0) and stops with
/// the runaway failure at once, the other full-front variants are skipped, and a
/// residual-closing variant closes the hole with a patch that passes the checks
/// (with the front allowed to close the whole hole, `max_steps_per_vertex = 200`;
/// the default of 4 closes the residual first, checked at the end). Without the
/// bound the policy's front is not stopped that way.
#[test]
fn a_front_over_a_deep_hole_stops_as_runaway_and_a_residual_variant_closes_it() {
    let (mesh, _) = Mesh::from_raw(&sphere(3, 1.9));
    let loops = mesh.topo.boundary_loops();
    assert_eq!(loops.len(), 1);
    let mut policy = Policy::default();
    assert_eq!(policy.wavefront.max_area_ratio, 2.0);
    policy = policy
        .edit(|s| s.wavefront.max_steps_per_vertex = 200)
        .unwrap();
    let hole = Hole::new(0, &mesh, loops[0].clone(), &policy);
    let ctx = FillContext::new(&mesh, &hole, &policy);
    match fill_with_stats(&ctx) {
        Err(FillError::Runaway { .. }) => {}
        other => panic!("expected the runaway failure, got {:?}", other.map(|p| p.1)),
    }
    let patch = fill(&ctx).unwrap();
    accept(&mesh, &hole, &patch, &policy);
    let free = policy.edit(|s| s.wavefront.max_area_ratio = 0.0).unwrap();
    let ctx = FillContext {
        policy: &free,
        ..ctx
    };
    let r = fill_with_stats(&ctx);
    assert!(
        !matches!(r, Err(FillError::Runaway { .. })),
        "{:?}",
        r.map(|p| p.1)
    );
    // the default: a few rings of front, then the residual, within the bound
    let default = Policy::default();
    let ctx = FillContext {
        policy: &default,
        ..ctx
    };
    let (patch, stats) = fill_with_stats(&ctx).unwrap();
    assert!(stats.residual_fronts >= 1, "{stats:?}");
    accept(&mesh, &hole, &patch, &default);
}

/// Curvature restoration against none, over every curved oracle here: five sphere
/// holes (25 to 140 boundary vertices), a cylinder, a saddle, a paraboloid. Per hole it
/// is not always better (on one of the five sphere holes it is 1.5 % worse); on the sum
/// of mean errors it is better (measured 0.169 against 0.252).
#[test]
fn curvature_restoration_is_not_worse_overall() {
    type Case = (RawMesh, DVec3, fn(DVec3) -> f64);
    let mut cases: Vec<Case> = Vec::new();
    for (level, cap) in [(3, 0.55), (3, 0.8), (4, 0.5), (4, 0.9), (5, 0.7)] {
        cases.push((sphere(level, cap), SPHERE_DIR, sphere_err));
    }
    cases.push((cylinder_hole(1.0, 60, 40, 0.1, 0.5), DVec3::X, cylinder_err));
    cases.push((
        grid_hole(40, 0.45, |x, y| x * x - y * y),
        DVec3::ZERO,
        saddle_err,
    ));
    cases.push((
        grid_hole(40, 0.45, |x, y| 0.5 * (x * x + y * y)),
        DVec3::ZERO,
        bowl_err,
    ));
    let (mut on, mut off) = (0.0, 0.0);
    for (raw, c, err) in &cases {
        let a = measure(raw, *c, restore(true), err);
        let b = measure(raw, *c, restore(false), err);
        eprintln!(
            "k {:3}: restoration {:.5}, without {:.5}",
            a.k, a.mean, b.mean
        );
        on += a.mean;
        off += b.mean;
    }
    eprintln!("sum: restoration {on:.4}, without {off:.4}");
    assert!(on <= off, "{on} > {off}");
}

fn cylinder_err(p: DVec3) -> f64 {
    (p.x * p.x + p.y * p.y).sqrt() - 1.0
}
fn saddle_err(p: DVec3) -> f64 {
    p.z - (p.x * p.x - p.y * p.y)
}
fn bowl_err(p: DVec3) -> f64 {
    p.z - 0.5 * (p.x * p.x + p.y * p.y)
}

/// Cylinder of radius 1, hole of radius 0.5 (36 boundary vertices, edge length 0.1):
/// mean |rho - 1| below 0.008 with restoration, 0.025 without (measured 0.0047 and
/// 0.018), max below 0.05.
#[test]
fn cylinder_hole_stays_near_the_cylinder() {
    let raw = cylinder_hole(1.0, 60, 40, 0.1, 0.5);
    let on = measure(&raw, DVec3::X, restore(true), cylinder_err);
    let off = measure(&raw, DVec3::X, restore(false), cylinder_err);
    assert!(
        on.mean < 0.008 && off.mean < 0.025,
        "{} {}",
        on.mean,
        off.mean
    );
    assert!(on.max < 0.05 && off.max < 0.05);
    assert!(on.mean <= off.mean);
}

/// Saddle z = x^2 - y^2 over [-1, 1]^2, hole of radius 0.45 (70 boundary vertices,
/// edge length 0.05): mean |z - (x^2 - y^2)| below 0.01 with restoration, 0.02
/// without (measured 0.0062 and 0.0139), max below 0.08 (measured 0.038, 0.068).
#[test]
fn saddle_hole_stays_near_the_saddle() {
    let raw = grid_hole(40, 0.45, |x, y| x * x - y * y);
    let on = measure(&raw, DVec3::ZERO, restore(true), saddle_err);
    let off = measure(&raw, DVec3::ZERO, restore(false), saddle_err);
    assert!(
        on.mean < 0.01 && off.mean < 0.02,
        "{} {}",
        on.mean,
        off.mean
    );
    assert!(on.max < 0.08 && off.max < 0.08);
}

/// `placement = "interpolated"` without restoration follows spheres more closely than
/// the paper's reading (sphere hole of 140: mean |r - 1| below 0.006, measured 0.0032
/// against 0.020); on the cylinder it stays below 0.008 (measured 0.0057).
#[test]
fn interpolated_placement_is_closer_on_curved_holes() {
    let interp = |p: &mut Settings| {
        p.wavefront.placement = WavefrontPlacement::Interpolated;
        p.wavefront.curvature_restoration = false;
    };
    let s = measure(&sphere(5, 0.7), SPHERE_DIR, interp, sphere_err);
    let paper = measure(&sphere(5, 0.7), SPHERE_DIR, restore(true), sphere_err);
    assert!(
        s.mean < 0.006 && s.mean < paper.mean,
        "{} {}",
        s.mean,
        paper.mean
    );
    let c = measure(
        &cylinder_hole(1.0, 60, 40, 0.1, 0.5),
        DVec3::X,
        interp,
        cylinder_err,
    );
    assert!(c.mean < 0.008, "{}", c.mean);
}

/// A flat annulus: the loop `loop_pts` (counter-clockwise, star-shaped around the
/// origin) inside a ring of faces out to radius `outer`; the loop is the hole.
fn ring_mesh(loop_pts: &[DVec3], outer: f64) -> Option<RawMesh> {
    let ring: Vec<DVec3> = loop_pts
        .iter()
        .map(|p| {
            let d = DVec3::new(p.x, p.y, 0.0).normalize();
            DVec3::new(d.x * outer, d.y * outer, p.z)
        })
        .collect();
    let raw = testutil::strip(loop_pts, &ring);
    let up = |f: &[u32; 3]| {
        let [a, b, c] = f.map(|x| raw.positions[x as usize]);
        (b - a).cross(c - a).z > 1e-9
    };
    raw.faces.iter().all(up).then_some(raw)
}

fn circle(k: usize, r: f64) -> Vec<DVec3> {
    (0..k)
        .map(|i| {
            let a = TAU * i as f64 / k as f64;
            DVec3::new(r * a.cos(), r * a.sin(), 0.0)
        })
        .collect()
}

/// A round hole of 60 vertices has every angle at 174 degrees > mu: the paper's random
/// draw starts it; it closes flat. With mu small every step is a draw and it still
/// closes.
#[test]
fn round_hole_uses_the_random_draw() {
    let raw = ring_mesh(&circle(60, 1.0), 2.0).unwrap();
    let m = measure(&raw, DVec3::ZERO, |_| {}, |p| p.z);
    assert!(m.stats.random_picks > 0);
    assert!(m.max < 1e-9);
    assert!(m.patch.new_vertices.iter().all(|p| p.length() < 1.0));
    let m = measure(&raw, DVec3::ZERO, |p| p.wavefront.mu = 1.0, |p| p.z);
    assert!(m.stats.random_picks >= m.stats.steps / 2, "{:?}", m.stats);
    assert!(m.max < 1e-9);
}

/// Long slots (1.4 long, 0.12 to 0.4 wide, on a 60 x 60 grid of [-1, 1]^2): the fronts
/// from both long sides meet; some new points merge into front vertices across the
/// slot and split the front. Every slot closes flat.
#[test]
fn slot_holes_merge_and_split_the_front() {
    let mut merges = 0;
    for h in [0.06, 0.08, 0.1, 0.15, 0.2] {
        let mut raw = grid_hole(60, 0.0, |_, _| 0.0);
        raw.faces.retain(|f| {
            let c = f.iter().map(|&v| raw.positions[v as usize]).sum::<DVec3>() / 3.0;
            !(c.x.abs() < 0.7 && c.y.abs() < h)
        });
        let m = measure(&raw, DVec3::ZERO, |_| {}, |p| p.z);
        assert!(m.k > 80, "{}", m.k);
        assert!(m.max < 1e-9);
        merges += m.stats.merges;
    }
    assert!(merges > 0);
}

/// Same input and policy: the same patch, bit for bit; another seed also closes.
#[test]
fn same_seed_same_patch_bits() {
    let raw = ring_mesh(&circle(48, 1.0), 2.0).unwrap();
    let bits = |seed: u64| {
        let m = measure(&raw, DVec3::ZERO, move |p| p.seed = seed, |p| p.z);
        let v: Vec<[u64; 3]> = m
            .patch
            .new_vertices
            .iter()
            .map(|p| p.to_array().map(f64::to_bits))
            .collect();
        (v, m.patch.triangles, m.stats)
    };
    let a = bits(7);
    assert!(a.2.random_picks > 0);
    assert_eq!(a, bits(7));
    // another seed also closes the hole (measure accepts its patch), picking at random
    let b = bits(8);
    assert!(b.2.random_picks > 0 && !b.1.is_empty());
    let raw = sphere(4, 0.9);
    let run = || measure(&raw, SPHERE_DIR, |_| {}, sphere_err).patch;
    let (p, q) = (run(), run());
    assert_eq!(p.triangles, q.triangles);
    assert!(p
        .new_vertices
        .iter()
        .zip(&q.new_vertices)
        .all(|(a, b)| a.to_array().map(f64::to_bits) == b.to_array().map(f64::to_bits)));
}

/// Gaussian noise (sigma = 1 % of the radius, about 0.13 edge lengths; seeded) on
/// every vertex within 0.3 rad of a large hole of a unit sphere (82 boundary
/// vertices, the hole spans 1.8 rad of arc): the hole still closes for three noise
/// seeds. The paper's reading stays within mean |r - 1| < 0.08 and max < 0.3
/// (measured 0.033 to 0.048, max 0.12 to 0.18: the noisy normals tilt the rotated
/// triangles); `placement = "interpolated"` without restoration within mean < 0.025,
/// max < 0.08 (measured 0.008 to 0.015, max 0.03 to 0.043).
#[test]
fn noisy_sphere_still_closes() {
    for seed in [1u64, 2, 3] {
        let mut raw = sphere(4, 0.9);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let dir = SPHERE_DIR.normalize();
        let mut gauss = move || {
            let u1: f64 = rand::Rng::random_range(&mut rng, 1e-12..1.0);
            let u2: f64 = rand::Rng::random_range(&mut rng, 0.0..1.0);
            (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
        };
        for p in raw.positions.iter_mut() {
            if p.normalize().dot(dir) > (0.9f64 + 0.3).cos() {
                *p += DVec3::new(gauss(), gauss(), gauss()) * 0.01;
            }
        }
        let m = measure(&raw, SPHERE_DIR, |_| {}, sphere_err);
        assert!(
            m.mean < 0.08 && m.max < 0.3,
            "seed {seed}: {} {}",
            m.mean,
            m.max
        );
        let interp = |p: &mut Settings| {
            p.wavefront.placement = WavefrontPlacement::Interpolated;
            p.wavefront.curvature_restoration = false;
        };
        let m = measure(&raw, SPHERE_DIR, interp, sphere_err);
        assert!(
            m.mean < 0.025 && m.max < 0.08,
            "seed {seed}: {} {}",
            m.mean,
            m.max
        );
    }
}

/// The bunny scan's hole 2 (42 boundary vertices, in a fold of the ear's base):
/// the thin-plate fairing of its residual front bulged the residual through the
/// front's own triangles, so its patch passed the checks only after a
/// re-triangulation repair. Now the residual is kept unfaired and the patch as made
/// passes the whole check (intersections with itself and the mesh included), and
/// its tangential relaxation, which crosses two patch triangles when done over the
/// whole patch, passes with the vertices at the crossing held in place. The
/// bunny is bench data that must not be copied into the repository
/// (`../shared/bench-data/README.md`): the test reads it from there, so it runs only
/// where that is beside the checkout (`.ci/run` runs it there).
#[test]
#[ignore = "needs ../shared"]
fn bunny_hole_2_residual_is_kept_unfaired_and_relaxed_around_its_fold() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/bench-data/meshes/stanford-bunny.obj");
    let raw = crate::io::read(&path, None)
        .unwrap_or_else(|e| panic!("this test needs {}: {e}", path.display()));
    let (mesh, _) = Mesh::from_raw(&raw);
    mesh.validate().unwrap();
    let loops = mesh.topo.boundary_loops();
    assert_eq!(loops.len(), 5);
    // the residual's triangulation as it was when the fold was found (total area, the
    // restricted search from 60): Liepa's weight, the default since, makes a residual
    // whose faired patch does not cross, and the safeguards are not called on
    let policy = Policy::default()
        .edit(|s| {
            s.refine.weight = crate::policy::TriangulationWeight::Area;
            s.refine.restricted_search_above = 60;
        })
        .unwrap();
    let hole = Hole::new(2, &mesh, loops[2].clone(), &policy);
    assert_eq!(hole.len(), 42);
    let ctx = FillContext::new(&mesh, &hole, &policy);
    let (patch, stats) = fill_with_stats(&ctx).unwrap();
    assert_eq!(stats.residual_fronts, 1, "{stats:?}");
    assert_eq!(stats.unfaired_residuals, 1, "{stats:?}");
    let checker = crate::check::Checker::new(&mesh);
    let made = checker
        .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
        .unwrap();
    accept(&mesh, &hole, &patch, &policy);
    use crate::fill::kit::relax::RELAX_STEP;
    // relaxed as a whole, a vertex slides across a fold of the patch (two patch
    // triangles cross); relaxed with the vertices there held, it passes, with
    // better triangles than as made
    let check = |p: &Patch| checker.check_patch(&mesh, &hole.vertices, p, &policy.checks);
    let mut whole = patch.clone();
    let iterations = policy.fair.tangential_relax;
    crate::fill::kit::relax::tangential_relax(&mesh, &hole, &mut whole, iterations, RELAX_STEP);
    assert!(
        matches!(
            check(&whole),
            Err(crate::check::CheckFailure::SelfIntersection { .. })
        ),
        "{:?}",
        check(&whole)
    );
    let (relaxed, q) =
        crate::fill::kit::relax::relax_checked(&mesh, &hole, &patch, iterations, RELAX_STEP, check)
            .expect("the relaxation with held vertices passes");
    assert!(q.q_good_share > made.q_good_share, "{q:?} vs {made:?}");
    assert!(q.min_angle_deg > made.min_angle_deg, "{q:?} vs {made:?}");
    accept(&mesh, &hole, &relaxed, &policy);
}

/// Options the front cannot run with never reach it (the policy rejects them when it
/// is validated); a loop too short to fill is a clean error.
#[test]
fn bad_options_are_rejected_and_bad_loops_are_errors() {
    let raw = ring_mesh(&circle(12, 1.0), 2.0).unwrap();
    let (mesh, _) = Mesh::from_raw(&raw);
    let l = loop_near(&mesh, DVec3::ZERO);
    for tweak in [
        (|p: &mut Settings| p.wavefront.alpha = 140.0) as fn(&mut Settings),
        |p| p.wavefront.beta = 190.0,
        |p| p.wavefront.mu = f64::NAN,
        |p| p.wavefront.merge_distance = -1.0,
        |p| p.wavefront.max_steps_per_vertex = 0,
    ] {
        let mut settings = Settings::default();
        tweak(&mut settings);
        let key = Policy::new(settings).unwrap_err().key;
        assert!(key.starts_with("wavefront."), "{key}");
    }
    let policy = Policy::default();
    let (_, r) = run(&mesh, l[..2].to_vec(), &policy);
    assert!(matches!(r, Err(FillError::Failed(_))));
    // a step cap too small to close leaves a residual front, which is closed
    let mut policy = Policy::default();
    policy = policy
        .edit(|s| s.wavefront.max_steps_per_vertex = 1)
        .unwrap();
    let (hole, r) = run(&mesh, l, &policy);
    accept(&mesh, &hole, &r.unwrap(), &policy);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Random star-shaped planar loops: a valid flat disk or a clean error, never a
    /// panic or a hang.
    #[test]
    fn star_shaped_loops_close_or_fail_cleanly(
        radii in proptest::collection::vec(0.4f64..1.6, 4..60),
        jitter in proptest::collection::vec(-0.4f64..0.4, 60),
        seed in 0u64..1000,
    ) {
        let k = radii.len();
        let pts: Vec<DVec3> = (0..k)
            .map(|i| {
                let a = TAU * (i as f64 + jitter[i]) / k as f64;
                DVec3::new(radii[i] * a.cos(), radii[i] * a.sin(), 0.0)
            })
            .collect();
        let Some(raw) = ring_mesh(&pts, 3.0) else { return Ok(()) };
        let (mesh, _) = Mesh::from_raw(&raw);
        prop_assume!(mesh.validate().is_ok());
        let policy = Policy::default().edit(|s| s.seed = seed).unwrap();
        let l = loop_near(&mesh, DVec3::ZERO);
        prop_assume!(l.len() == k);
        let (hole, r) = run(&mesh, l, &policy);
        if let Ok(patch) = r {
            accept(&mesh, &hole, &patch, &policy);
            prop_assert!(patch.new_vertices.iter().all(|p| p.z == 0.0));
        }
    }
}

/// 600 random star-shaped loops (4 to 80 vertices, radii 0.4 to 1.6, angular
/// jitter), flat and with the loop vertices jittered in z by up to 0.02 (a fifth of a
/// typical edge): at least 99 % close (measured 1999 and 1996 of 2000), and every
/// patch passes the dispatcher's topology and degeneracy checks.
#[test]
fn random_star_loops_mostly_close() {
    let policy = Policy::default();
    for zamp in [0.0, 0.02] {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let (mut ok, mut tried) = (0, 0);
        for _ in 0..600 {
            let k = rand::Rng::random_range(&mut rng, 4..80usize);
            let pts: Vec<DVec3> = (0..k)
                .map(|i| {
                    let r: f64 = rand::Rng::random_range(&mut rng, 0.4..1.6);
                    let j: f64 = rand::Rng::random_range(&mut rng, -0.4..0.4);
                    let z: f64 = rand::Rng::random_range(&mut rng, -1.0..1.0) * zamp;
                    let a = TAU * (i as f64 + j) / k as f64;
                    DVec3::new(r * a.cos(), r * a.sin(), z)
                })
                .collect();
            let Some(raw) = ring_mesh(&pts, 3.0) else {
                continue;
            };
            let (mesh, _) = Mesh::from_raw(&raw);
            let l = loop_near(&mesh, DVec3::ZERO);
            if mesh.validate().is_err() || l.len() != k {
                continue;
            }
            tried += 1;
            let (hole, r) = run(&mesh, l, &policy);
            if let Ok(patch) = r {
                check_topology(&mesh, &hole.vertices, &patch).unwrap();
                let pos = patch_positions(&mesh, &hole.vertices, &patch);
                check_degenerate(&pos, &patch, &policy.checks).unwrap();
                ok += 1;
            }
        }
        assert!(
            tried > 500 && ok * 100 >= tried * 99,
            "zamp {zamp}: {ok} of {tried}"
        );
    }
}

/// Regression (homer hole 3, cheburashka hole 1 of the shared bench: fronts stuck on
/// a folded loop or out of steps used to fail the method): a front stopped after one
/// step per boundary vertex is closed as a residual front, and the patch passes every
/// check of the dispatcher, stays within 0.05 of the unit sphere on average (0.12 at
/// most) and is the same bit for bit on a second run.
#[test]
fn a_stopped_front_is_closed_as_a_residual() {
    let (mesh, _) = Mesh::from_raw(&sphere(4, 0.6));
    let mut policy = Policy::default();
    policy = policy
        .edit(|s| s.wavefront.max_steps_per_vertex = 1)
        .unwrap();
    let l = loop_near(&mesh, SPHERE_DIR.normalize());
    let hole = Hole::new(0, &mesh, l, &policy);
    let ctx = FillContext::new(&mesh, &hole, &policy);
    let (patch, stats) = fill_with_stats(&ctx).unwrap();
    assert!(stats.residual_fronts >= 1, "{stats:?}");
    accept(&mesh, &hole, &patch, &policy);
    crate::check::Checker::new(&mesh)
        .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
        .unwrap();
    let (mean, max) = stats_of(&patch, |p| sphere_err(p).abs());
    assert!(mean < 0.05 && max < 0.12, "{mean} {max}");
    let (again, _) = fill_with_stats(&ctx).unwrap();
    assert_eq!(again, patch);
}

/// The variants start with the policy itself and never repeat one.
#[test]
fn variants_start_with_the_policy() {
    let p = Policy::default();
    let v = variants(&p);
    assert_eq!(v[0].1, p);
    for i in 0..v.len() {
        for j in i + 1..v.len() {
            assert_ne!(v[i].1, v[j].1, "{} {}", v[i].0, v[j].0);
        }
    }
}

/// The winding count by ray crossings gives what the summed angles gave (non-zero
/// winding, or within `near` of an edge) on random simple and self-crossing loops.
#[test]
fn crossing_count_agrees_with_summed_angles() {
    use rand::Rng;
    let reference = |poly: &[(f64, f64)], (px, py): (f64, f64), near: f64| {
        let k = poly.len();
        let (mut wind, mut dist) = (0.0f64, f64::INFINITY);
        for i in 0..k {
            let (ax, ay) = (poly[i].0 - px, poly[i].1 - py);
            let (bx, by) = (poly[(i + 1) % k].0 - px, poly[(i + 1) % k].1 - py);
            wind += (ax * by - ay * bx).atan2(ax * bx + ay * by);
            let (ex, ey) = (bx - ax, by - ay);
            let t = (-(ax * ex + ay * ey) / (ex * ex + ey * ey).max(1e-300)).clamp(0.0, 1.0);
            dist = dist.min(((ax + t * ex).powi(2) + (ay + t * ey).powi(2)).sqrt());
        }
        wind.abs() > PI || dist < near
    };
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (mut inside, mut total) = (0, 0);
    for round in 0..300 {
        let k = rng.random_range(3..40);
        let poly: Vec<(f64, f64)> = (0..k)
            .map(|i| {
                if round % 3 == 0 {
                    // anywhere: self-crossing loops, winding numbers above one
                    (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                } else {
                    let a = TAU * (i as f64 + rng.random_range(0.0..0.9)) / k as f64;
                    let r = rng.random_range(0.2..1.0);
                    (r * a.cos(), r * a.sin())
                }
            })
            .collect();
        for _ in 0..50 {
            let p = (rng.random_range(-1.2..1.2), rng.random_range(-1.2..1.2));
            let want = reference(&poly, p, 0.05);
            assert_eq!(inside_or_near(&poly, p, 0.05), want, "{poly:?} {p:?}");
            inside += want as usize;
            total += 1;
        }
    }
    assert!(
        inside > total / 5 && inside < total * 4 / 5,
        "{inside} of {total}"
    );
}

/// A variant with fewer steps per vertex resumed from the copy the policy's run kept
/// at its cap gives the same patch, bit for bit, as that variant run afresh.
#[test]
fn a_resumed_run_equals_a_fresh_one() {
    let (mesh, _) = Mesh::from_raw(&sphere(4, 0.6));
    let policy = Policy::default();
    let hole = Hole::new(0, &mesh, loop_near(&mesh, SPHERE_DIR.normalize()), &policy);
    let k = hole.len();
    assert!(k >= 20, "{k}");
    let ctx = |policy| FillContext {
        mesh: &mesh,
        hole: &hole,
        policy,
        deadline: Deadline::none(),
        checker: None,
        rim_bound: false,
        guide: false,
        finish: None,
    };
    let mut short = policy.clone();
    short = short
        .edit(|s| s.wavefront.max_steps_per_vertex = 1)
        .unwrap();
    let (full, mut snaps) = run_wave(&ctx(&policy), Start::Fresh(&[k]));
    let full = full.unwrap();
    assert!(
        full.1.steps > k,
        "the policy's run passed the cap: {:?}",
        full.1
    );
    assert_eq!(snaps.len(), 1);
    let (at, w) = snaps.remove(0);
    assert_eq!(at, k);
    let resumed = run_wave(&ctx(&short), Start::Resume(Box::new(w)))
        .0
        .unwrap();
    let fresh = run_wave(&ctx(&short), Start::Fresh(&[])).0.unwrap();
    assert_eq!(resumed.1.residual_fronts, 1);
    assert_eq!(resumed, fresh);
    let bits = |p: &Patch| -> Vec<u64> {
        p.new_vertices
            .iter()
            .flat_map(|v| v.to_array().map(f64::to_bits))
            .collect()
    };
    assert_eq!(bits(&resumed.0), bits(&fresh.0));
    // the same through the method: the policy's run is the full one
    assert_eq!(fill_with_stats(&ctx(&policy)).unwrap(), full);
}
