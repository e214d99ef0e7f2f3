use super::*;
use crate::check::{check_degenerate, check_topology, patch_positions};
use crate::fill::kit::Deadline;
use crate::io::RawMesh;
use crate::patch::{apply_patch, Hole};
use crate::policy::{Checks, Policy};
use crate::testutil;
use rand::{Rng, SeedableRng};

/// Builds a mesh from a soup, removing every face that touches a vertex for which
/// `cut` holds; returns the mesh and the hole loop nearest `centre`.
fn cut_mesh(raw: RawMesh, cut: impl Fn(DVec3) -> bool, centre: DVec3) -> (Mesh, Vec<VertexId>) {
    let gone: Vec<bool> = raw.positions.iter().map(|&p| cut(p)).collect();
    let raw = RawMesh {
        faces: raw
            .faces
            .iter()
            .copied()
            .filter(|f| !f.iter().any(|&i| gone[i as usize]))
            .collect(),
        ..raw
    };
    let (mesh, _) = Mesh::from_raw(&raw);
    mesh.validate().unwrap();
    let loops = mesh.topo.boundary_loops();
    let lp = loops
        .into_iter()
        .min_by(|a, b| {
            let ca = measure::centroid(&a.iter().map(|&v| mesh.pos(v)).collect::<Vec<_>>());
            let cb = measure::centroid(&b.iter().map(|&v| mesh.pos(v)).collect::<Vec<_>>());
            (ca - centre).length().total_cmp(&(cb - centre).length())
        })
        .unwrap();
    let mut seen = HashSet::default();
    assert!(
        lp.iter().all(|v| seen.insert(*v)),
        "test hole must be a simple loop"
    );
    (mesh, lp)
}

struct Run {
    patch: Patch,
    front: Patch,
    hole: Hole,
}

/// Fills, and checks that the patch keeps the initial front's triangles, passes the
/// topology and degeneracy checks and applies to a valid mesh.
fn run(mesh: &Mesh, lp: &[VertexId], policy: &Policy) -> Run {
    let (hole, patch) = crate::fill::kit::run_on(mesh, lp.to_vec(), policy, fill);
    let patch = patch.unwrap();
    let front = initial_front(
        mesh,
        lp,
        hole.mean_edge_length,
        policy.lssvm.merge_distance,
        policy.lssvm.max_area_ratio,
        &Deadline::none(),
    )
    .unwrap();
    assert_eq!(front.triangles, patch.triangles);
    check_topology(mesh, lp, &patch).unwrap();
    let pos = patch_positions(mesh, lp, &patch);
    check_degenerate(&pos, &patch, &Checks::default()).unwrap();
    let mut m2 = mesh.clone();
    apply_patch(&mut m2, &hole, &patch).unwrap();
    m2.validate().unwrap();
    Run { patch, front, hole }
}

fn mean_max(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut s, mut m, mut n) = (0.0, 0.0f64, 0usize);
    for x in v {
        s += x;
        m = m.max(x);
        n += 1;
    }
    (s / n.max(1) as f64, m)
}

#[test]
fn planar_hole_gives_planar_patch() {
    let raw = testutil::unit_grid(24);
    let c = DVec3::new(12.3, 11.8, 0.0);
    let (mesh, lp) = cut_mesh(raw, |p| (p - c).length() < 5.0, c);
    let r = run(&mesh, &lp, &Policy::default());
    assert!(!r.patch.new_vertices.is_empty());
    for p in &r.patch.new_vertices {
        assert!(p.z.abs() < 1e-9, "off the plane: {p}");
        assert!((*p - c).length() < 7.0, "outside the hole: {p}");
    }
}

fn sphere_case(subdiv: usize, cap: f64) -> (Mesh, Vec<VertexId>) {
    let raw = testutil::icosphere(subdiv, 1.0);
    let dir = DVec3::new(0.3, 0.2, 1.0).normalize();
    cut_mesh(raw, |p| p.normalize().dot(dir) > cap.cos(), dir)
}

fn sphere_errors(r: &Run) -> ((f64, f64), (f64, f64)) {
    let l = r.hole.mean_edge_length;
    let e = mean_max(
        r.patch
            .new_vertices
            .iter()
            .map(|p| (p.length() - 1.0).abs() / l),
    );
    let e0 = mean_max(
        r.front
            .new_vertices
            .iter()
            .map(|p| (p.length() - 1.0).abs() / l),
    );
    (e, e0)
}

#[test]
fn sphere_hole_30() {
    let (mesh, lp) = sphere_case(4, 0.3);
    let r = run(&mesh, &lp, &Policy::default());
    let ((mean, max), (mean0, max0)) = sphere_errors(&r);
    eprintln!(
        "sphere k={} new={} err mean {mean:.4} max {max:.4} (front {mean0:.4} {max0:.4}) in edge lengths",
        lp.len(),
        r.patch.new_vertices.len()
    );
    assert!((25..=40).contains(&lp.len()), "{}", lp.len());
    // bound: 2 % (max) and 1 % (mean) of an edge length off the sphere, and at most a
    // tenth of the initial front's mean error
    assert!(max < 0.02 && mean < 0.01, "{mean} {max}");
    assert!(mean < 0.1 * mean0);
}

#[test]
fn sphere_hole_100() {
    let (mesh, lp) = sphere_case(5, 0.52);
    let r = run(&mesh, &lp, &Policy::default());
    let ((mean, max), (mean0, max0)) = sphere_errors(&r);
    eprintln!(
        "sphere k={} new={} err mean {mean:.4} max {max:.4} (front {mean0:.4} {max0:.4}) in edge lengths",
        lp.len(),
        r.patch.new_vertices.len()
    );
    assert!((85..=130).contains(&lp.len()), "{}", lp.len());
    // bound: 5 % (max) and 2 % (mean) of an edge length
    assert!(max < 0.05 && mean < 0.02, "{mean} {max}");
    assert!(mean < 0.1 * mean0);
}

#[test]
fn cylinder_hole() {
    let raw = testutil::unit_cylinder(64, 41);
    let c = DVec3::new(1.0, 0.05, 1.7);
    let (mesh, lp) = cut_mesh(raw, |p| (p - c).length() < 0.45, c);
    let r = run(&mesh, &lp, &Policy::default());
    let l = r.hole.mean_edge_length;
    let rad = |p: &DVec3| ((p.x * p.x + p.y * p.y).sqrt() - 1.0).abs() / l;
    let (mean, max) = mean_max(r.patch.new_vertices.iter().map(rad));
    let (mean0, max0) = mean_max(r.front.new_vertices.iter().map(rad));
    eprintln!(
        "cylinder k={} new={} err mean {mean:.4} max {max:.4} (front {mean0:.4} {max0:.4}) in edge lengths",
        lp.len(),
        r.patch.new_vertices.len()
    );
    // the Laplacian of a cylinder points to the axis, so it turns around the hole;
    // bound: 2 % (max) and 1 % (mean) of an edge length off the cylinder
    assert!(max < 0.02 && mean < 0.01, "{mean} {max}");
    assert!(mean < 0.1 * mean0);
}

#[test]
fn noisy_sphere_still_closes() {
    // seeded Gaussian noise, sigma = 5 % of the mean boundary edge length, on the
    // loop and the three rings around it
    let (mesh, lp) = noisy_sphere(0.05, 7);
    let r = run(&mesh, &lp, &Policy::default());
    let ((mean, max), (mean0, _)) = sphere_errors(&r);
    eprintln!("noisy sphere err mean {mean:.4} max {max:.4} (front {mean0:.4}) in edge lengths");
    assert!(max < 0.15 && mean < 0.05, "{mean} {max}");
}

fn noisy_sphere(sigma_rel: f64, seed: u64) -> (Mesh, Vec<VertexId>) {
    let (mut mesh, lp) = sphere_case(4, 0.3);
    let l0 = Hole::new(0, &mesh, lp.clone(), &Policy::default()).mean_edge_length;
    let sigma = sigma_rel * l0;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut ring: HashSet<VertexId> = lp.iter().copied().collect();
    for _ in 0..3 {
        let cur: Vec<VertexId> = ring.iter().copied().collect();
        for v in cur {
            ring.extend(mesh.topo.neighbors(v));
        }
    }
    let mut ring: Vec<VertexId> = ring.into_iter().collect();
    ring.sort();
    for v in ring {
        let mut g = [0.0; 3];
        for x in &mut g {
            let u1: f64 = rng.random::<f64>().max(1e-300);
            let u2: f64 = rng.random();
            *x = (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos();
        }
        mesh.positions[v.idx()] += DVec3::from_array(g) * sigma;
    }
    (mesh, lp)
}

#[test]
fn same_input_same_bits() {
    let (mesh, lp) = sphere_case(4, 0.3);
    let a = run(&mesh, &lp, &Policy::default()).patch;
    let b = run(&mesh, &lp, &Policy::default()).patch;
    assert_eq!(a.triangles, b.triangles);
    let bits = |p: &Patch| -> Vec<u64> {
        p.new_vertices
            .iter()
            .flat_map(|v| v.to_array().map(f64::to_bits))
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
}

#[test]
fn poisson_has_linear_precision_and_reuses_its_factorisation() {
    // on a plane the cotangent Laplacian of the positions is zero: solving for a zero
    // target on the true geometry must give it back, with and without the ring rows
    let raw = testutil::unit_grid(16);
    let c = DVec3::new(8.2, 7.9, 0.0);
    let (mesh, lp) = cut_mesh(raw, |p| (p - c).length() < 3.5, c);
    let r = run(&mesh, &lp, &Policy::default());
    let k = lp.len();
    let boundary: Vec<DVec3> = lp.iter().map(|&v| mesh.pos(v)).collect();
    let all: Vec<DVec3> = boundary
        .iter()
        .chain(&r.patch.new_vertices)
        .copied()
        .collect();
    let ring = Ring::new(&mesh, &lp);
    let l = r.hole.mean_edge_length;
    for rg in [None, Some(&ring)] {
        let solver = PoissonSolver::new(&all, k, &r.patch.triangles, l, rg).unwrap();
        let zero = vec![DVec3::ZERO; solver.rows()];
        let x = solver.solve(&boundary, &zero).unwrap();
        for (a, b) in x.iter().zip(&r.patch.new_vertices) {
            assert!((*a - *b).length() < 1e-9 * l, "{a} vs {b}");
        }
        let once = solve_poisson(&all, k, &r.patch.triangles, &zero, l, rg).unwrap();
        assert_eq!(once, x);
    }
}

#[test]
fn lssvm_reproduces_a_smooth_field() {
    // samples on a ring; the field is linear: the regression must interpolate it inside
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    let f = |p: DVec3| DVec3::new(0.5 * p.x - p.y, 2.0 + 0.1 * p.y, p.x + p.y);
    for i in 0..60 {
        for r in [3.0, 3.5, 4.0] {
            let a = i as f64 * std::f64::consts::TAU / 60.0;
            let p = DVec3::new(r * a.cos(), r * a.sin(), 0.0);
            xs.push(p);
            ys.push(f(p));
        }
    }
    let m = LssvmModel::fit(&xs, &ys, 1e4, 3.0).unwrap();
    for p in [
        DVec3::new(0.0, 0.0, 0.0),
        DVec3::new(1.0, -1.5, 0.0),
        DVec3::new(3.2, 0.4, 0.0),
    ] {
        let e = (m.predict(p) - f(p)).length();
        assert!(e < 0.05 * f(p).length().max(1.0), "at {p}: {e}");
    }
}

#[test]
fn small_loops_close() {
    // one removed grid cell (4 vertices, no new vertex needed) and a removed vertex star
    let full = testutil::unit_grid(6);
    let raw = testutil::cells_removed(full.clone(), |i, j| (i, j) == (2, 2));
    let (mesh, lp) = testutil::mesh_and_loop(&raw, |_, l| l.len() == 4);
    let r = run(&mesh, &lp, &Policy::default());
    assert_eq!(r.patch.triangles.len(), 2);
    let c = DVec3::new(2.0, 3.0, 0.0);
    let (mesh, lp) = cut_mesh(full, |p| (p - c).length() < 0.5, c);
    assert_eq!(lp.len(), 6);
    let r = run(&mesh, &lp, &Policy::default());
    for p in &r.patch.new_vertices {
        assert!(p.z.abs() < 1e-9);
    }
}

/// LS-SVM options out of range never reach the method: the policy rejects them.
#[test]
fn bad_policy_values_are_rejected_by_the_policy() {
    let mut settings = crate::policy::Settings::default();
    settings.lssvm.gamma = -1.0;
    assert_eq!(Policy::new(settings).unwrap_err().key, "lssvm.gamma");
}

/// Regression (stanford-bunny hole 3, homer hole 3 of the shared bench, where the
/// paper's front made an overlap or got stuck): the minimum-area initial patch and
/// the residual front both close a sphere hole, pass the dispatcher's checks and,
/// after LS-SVM + Poisson, stay within 2 % of an edge length of the sphere (max) and
/// 1 % (mean), as the paper's front does (`sphere_hole_30`).
#[test]
fn other_initial_patches_close_and_stay_on_the_sphere() {
    let (mesh, lp) = sphere_case(4, 0.3);
    let policy = Policy::default();
    let hole = Hole::new(0, &mesh, lp, &policy);
    let ctx = FillContext::new(&mesh, &hole, &policy);
    let l = hole.mean_edge_length;
    for start in [Start::MinArea, Start::ResidualFront] {
        let patch = fill_with(&ctx, start).unwrap();
        crate::check::Checker::new(&mesh)
            .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
            .unwrap();
        let (mean, max) = mean_max(
            patch
                .new_vertices
                .iter()
                .map(|p| (p.length() - 1.0).abs() / l),
        );
        assert!(max < 0.02 && mean < 0.01, "{start:?} {mean} {max}");
    }
}

/// `split_loops` (one pass with a map of first positions) splits like the quadratic
/// search it replaced, which took an eighth of a 200-vertex hole's front: at the first
/// position that repeats, at its next repetition; on seeded random sequences.
#[test]
fn split_loops_splits_at_the_first_repeated_position() {
    fn reference(seq: Vec<u32>) -> Vec<Vec<u32>> {
        let mut out = Vec::new();
        let mut stack = vec![seq];
        while let Some(s) = stack.pop() {
            let mut found = None;
            'outer: for i in 0..s.len() {
                for j in i + 1..s.len() {
                    if s[i] == s[j] {
                        found = Some((i, j));
                        break 'outer;
                    }
                }
            }
            match found {
                Some((i, j)) => {
                    let a = s[i..j].to_vec();
                    let mut b = s[j..].to_vec();
                    b.extend_from_slice(&s[..i]);
                    stack.push(a);
                    stack.push(b);
                }
                None if s.len() >= 3 => out.push(s),
                None => {}
            }
        }
        out
    }
    let mut rng = rand::rngs::StdRng::seed_from_u64(19);
    let mut split = 0;
    for _ in 0..2000 {
        let len = rng.random_range(0..40);
        let range = rng.random_range(1..30);
        let seq: Vec<u32> = (0..len).map(|_| rng.random_range(0..range)).collect();
        let want = reference(seq.clone());
        if want.len() > 1 {
            split += 1;
        }
        assert_eq!(front::split_loops(seq.clone()), want, "{seq:?}");
    }
    assert!(split > 100, "few sequences split: {split}");
}

/// `lssvm.max_area_ratio`: a 3-D front whose patch passes that many times the loop's
/// vector area stops as [`FillError::Runaway`]. The sphere cap of 0.52 rad has 1.07
/// times its rim's vector area: a limit of 1 stops the front, the default (3) lets it
/// close; with the limit of 1 the method still closes the hole (the planar front,
/// then the other starts).
#[test]
fn a_front_past_max_area_ratio_stops_as_a_runaway() {
    let (mesh, lp) = sphere_case(4, 0.52);
    let policy = Policy::default();
    let hole = Hole::new(0, &mesh, lp.clone(), &policy);
    let l = hole.mean_edge_length;
    let front = |ratio: f64| initial_front_with(&mesh, &lp, l, 0.5, ratio, &Deadline::none(), true);
    match front(1.0) {
        Err(FillError::Runaway {
            key: "lssvm.max_area_ratio",
            max_area_ratio,
        }) => assert_eq!(max_area_ratio, 1.0),
        other => panic!("expected a runaway, got {other:?}"),
    }
    let closed = front(policy.lssvm.max_area_ratio).unwrap();
    let pos = patch_positions(&mesh, &lp, &closed);
    let area: f64 = closed
        .triangles
        .iter()
        .map(|t| measure::tri_area(pos[t[0] as usize], pos[t[1] as usize], pos[t[2] as usize]))
        .sum();
    let ratio = area / measure::vector_area(&pos[..lp.len()]);
    assert!((1.0..1.2).contains(&ratio), "{ratio}");
    assert_eq!(front(0.0).unwrap(), closed);
    let tight = policy.edit(|s| s.lssvm.max_area_ratio = 1.0).unwrap();
    let ctx = FillContext::new(&mesh, &hole, &tight);
    let (patch, quality) = fill_checked(&ctx).unwrap();
    assert!(quality.is_some());
    let mut m2 = mesh.clone();
    apply_patch(&mut m2, &hole, &patch).unwrap();
    m2.validate().unwrap();
}
