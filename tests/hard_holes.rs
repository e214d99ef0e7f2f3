//! Hard and huge holes (issue "Scale and hardening"): each ends in bounded time,
//! filled or reported failed, never a hang or a crash, and nothing written intersects.
//!
//! The meshes are generated (tests/common/holes.rs). The hard loops and the huge
//! round holes (a flat one of 5,000 vertices, one of 2,500 on a dense sphere) run the
//! real binary with the default policy; the 10,008-vertex cylinder slot is filled
//! through the library and checked against the cylinder (the geometry oracle). The
//! round 10,000-vertex hole on a dense sphere is timed in `examples/hole_bench.rs`. Wall-time
//! bounds here are generous (debug builds on a loaded CI machine); the speed target
//! lives in `examples/hole_bench.rs`.

#[path = "common/holes.rs"]
mod holes;

use holefill::geometry::bvh::{tri_box, Bvh};
use holefill::io::RawMesh;
use holes::Soup;
use std::process::Command;
use std::time::{Duration, Instant};

/// Wall-time bound of one run in these tests.
const BOUND: Duration = Duration::from_secs(60);

fn raw(s: &Soup) -> RawMesh {
    RawMesh {
        positions: s.v.iter().map(|p| glam::DVec3::from(*p)).collect(),
        faces: s.f.iter().map(|f| f.map(|i| i as u32)).collect(),
        ..Default::default()
    }
}

/// Patch faces (index >= `first`) that intersect another face of `out` (shared
/// vertices by index, under the library's rules).
fn intersecting_patch_faces(out: &RawMesh, first: usize) -> usize {
    let tri = |f: usize| out.faces[f].map(|i| out.positions[i as usize]);
    let keys = |f: usize| out.faces[f].map(|i| i as u64);
    let tree = Bvh::build(out.faces.len(), |f| tri_box(&tri(f)));
    let mut bad = 0;
    for f in first..out.faces.len() {
        let (p, pk) = (tri(f), keys(f));
        let (lo, hi) = tri_box(&p);
        let hit = tree.query(lo, hi, |g| {
            g != f && holefill::geometry::predicates::tri_tri(&p, &pk, &tri(g), &keys(g))
        });
        bad += hit as usize;
    }
    bad
}

/// Runs `holefill fill` on the soup with the default policy and checks the outcome:
/// exit 0 or 2, within [`BOUND`], every hole in the log filled or failed with a
/// reason, input faces kept, no patch face intersecting. Returns the log.
fn run_case(name: &str, s: &Soup) -> serde_json::Value {
    run_case_out(name, s).0
}

/// [`run_case`], returning the log and the output mesh.
fn run_case_out(name: &str, s: &Soup) -> (serde_json::Value, RawMesh) {
    let loops = holes::boundary_loop_sizes(s).expect("fixture has simple boundary loops");
    assert!(!loops.is_empty(), "{name}: fixture has no hole");
    let dir = tempfile::tempdir().expect("tempdir");
    let input = dir.path().join(format!("{name}.obj"));
    let output = dir.path().join(format!("{name}.out.obj"));
    let report = dir.path().join(format!("{name}.json"));
    std::fs::write(&input, s.obj_text()).expect("write fixture");
    let t = Instant::now();
    let res = Command::new(env!("CARGO_BIN_EXE_holefill"))
        .arg("fill")
        .arg(&input)
        .arg(&output)
        .arg("--report")
        .arg(&report)
        .output()
        .expect("run holefill");
    let wall = t.elapsed();
    let code = res.status.code();
    assert!(
        matches!(code, Some(0) | Some(2)),
        "{name}: exit {code:?}\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&res.stdout),
        String::from_utf8_lossy(&res.stderr)
    );
    assert!(wall < BOUND, "{name}: took {wall:?}");
    let log: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).expect("json");
    let hs = log["holes"].as_array().expect("holes");
    assert_eq!(hs.len(), loops.len(), "{name}: one log entry per loop");
    let mut failed = 0;
    for h in hs {
        let status = h["status"].as_str().unwrap_or("");
        assert!(
            ["filled", "stitched", "failed", "skipped"].contains(&status),
            "{name}: status {status}"
        );
        if status != "filled" {
            assert!(
                !h["reason"].as_str().unwrap_or("").is_empty(),
                "{name}: hole without a reason: {h}"
            );
        }
        if status == "failed" {
            failed += 1;
            // every method tried is listed with its outcome and reason
            let tried = h["tried"].as_array().expect("tried");
            assert!(!tried.is_empty(), "{name}: failed without an attempt");
            for a in tried {
                assert!(
                    !a["reason"].as_str().unwrap_or("").is_empty(),
                    "{name}: {a}"
                );
            }
        }
    }
    assert_eq!(
        code == Some(2),
        failed > 0,
        "{name}: exit code and log disagree"
    );
    let out = holefill::read(&output, None).expect("output readable");
    let inp = raw(s);
    assert!(out.faces.len() >= inp.faces.len());
    assert_eq!(
        &out.faces[..inp.faces.len()],
        &inp.faces[..],
        "{name}: input faces changed"
    );
    assert_eq!(
        &out.positions[..inp.positions.len()],
        &inp.positions[..],
        "{name}: input vertices moved"
    );
    assert_eq!(
        intersecting_patch_faces(&out, inp.faces.len()),
        0,
        "{name}: the output intersects itself"
    );
    eprintln!(
        "{name}: loops {loops:?}, {} failed, {:.1} s",
        failed,
        wall.as_secs_f64()
    );
    (log, out)
}

/// Status of the hole with `k` boundary vertices.
fn status_of(log: &serde_json::Value, k: usize) -> String {
    log["holes"]
        .as_array()
        .and_then(|hs| hs.iter().find(|h| h["boundary_vertices"] == k))
        .map(|h| h["status"].as_str().unwrap_or("").to_string())
        .unwrap_or_default()
}

#[test]
fn spiral_hole() {
    let s = holes::spiral(2, 2, 16);
    let log = run_case("spiral", &s);
    assert_eq!(status_of(&log, 582), "filled");
}

#[test]
fn hole_whose_boundary_nearly_touches_itself() {
    // the arms of a horseshoe are 0.05 edge lengths apart
    run_case("near_touch", &holes::near_touch(60, 0.05));
}

#[test]
fn hole_next_to_slivers() {
    let s = holes::sliver_hole(10.0);
    run_case("sliver", &s);
}

/// New vertices of the output (those after the input's).
fn new_vertices(s: &Soup, out: &RawMesh) -> Vec<[f64; 3]> {
    out.positions[s.v.len()..]
        .iter()
        .map(|p| p.to_array())
        .collect()
}

/// A nearly flat round hole of 5,000 boundary vertices (heights within 0.0005 edge
/// lengths of the plane): filled (a graded patch: its triangles grow from the loop's
/// spacing inward), and every new vertex within 0.01 edge lengths of the plane and
/// inside the loop.
#[test]
fn nearly_flat_hole_of_5000_vertices() {
    let s = holes::flat_annulus(5000, 3, 1e-3);
    let (log, out) = run_case_out("flat5k", &s);
    assert_eq!(status_of(&log, 5000), "filled");
    let h = std::f64::consts::TAU / 5000.0;
    let new = new_vertices(&s, &out);
    assert!(!new.is_empty());
    for p in &new {
        assert!(p[2].abs() < 0.01 * h, "{p:?} is off the plane");
        assert!(p[0].hypot(p[1]) < 1.0, "{p:?} is outside the loop");
    }
    // graded, not at the loop's density (which would take some 6.5 million triangles)
    let faces = out.faces.len() - s.f.len();
    assert!(faces < 50_000, "{faces} patch triangles");
}

/// A round hole of 2,500 boundary vertices cut from a dense unit sphere (a cap of
/// polar angle 0.8, 46 degrees): too big for the front methods' patch budget, filled
/// by min_area_fair's graded patch. The oracle is the sphere: a thin plate sags below
/// a cap this wide (the continuous clamped plate would bulge 7 % above it), measured
/// 3.1 % of the radius at the centre and 0.9 % on average; bounds 4 % and 1.5 %.
#[test]
fn round_hole_on_a_dense_sphere_follows_the_sphere() {
    let s = holes::with_companion(holes::dense_sphere_cap(2500, 0.8, 3));
    assert_eq!(holes::boundary_loop_sizes(&s), Some(vec![2500]));
    let (log, out) = run_case_out("sphere2500", &s);
    assert_eq!(status_of(&log, 2500), "filled");
    let d: Vec<f64> = new_vertices(&s, &out)
        .into_iter()
        .map(holes::sphere_distance)
        .collect();
    assert!(!d.is_empty());
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let worst = d.iter().copied().fold(0.0f64, f64::max);
    eprintln!("sphere2500: mean distance {mean:.2e}, largest {worst:.2e}");
    assert!(worst < 0.04, "a new vertex is {worst} from the sphere");
    assert!(mean < 0.015, "mean distance {mean}");
}

#[test]
fn saddle_hole() {
    let s = holes::saddle(0.8, 80);
    let log = run_case("saddle", &s);
    assert_eq!(status_of(&log, 192), "filled");
}

/// The 10,008-vertex slot along a cylinder of radius 1 (48 vertices per ring, slot
/// 4 quads = 30 degrees wide): filled, and every new vertex within 0.1 edge lengths
/// (0.013) of the cylinder. The flat chord across the slot sags 0.034 below it,
/// so the bound needs the fairing to have restored the curvature.
#[test]
fn slot_of_10000_vertices_follows_the_cylinder() {
    let s = holes::with_companion(holes::cylinder_slot(48, 4, 5000));
    assert_eq!(holes::boundary_loop_sizes(&s), Some(vec![10_008]));
    let input = raw(&s);
    let t = Instant::now();
    let (out, rep) =
        holefill::repair(&input, &holefill::policy::Policy::default()).expect("repair");
    assert!(t.elapsed() < BOUND, "took {:?}", t.elapsed());
    assert_eq!(rep.holes.len(), 1);
    let h = &rep.holes[0];
    assert_eq!(
        h.status,
        holefill::report::HoleStatus::Filled,
        "{}",
        h.reason
    );
    let edge = std::f64::consts::TAU / 48.0;
    let n0 = input.positions.len();
    assert!(out.positions.len() > n0);
    let worst = out.positions[n0..]
        .iter()
        .map(|p| holes::cylinder_distance(p.to_array()))
        .fold(0.0f64, f64::max);
    assert!(
        worst < 0.1 * edge,
        "a new vertex is {worst} from the cylinder (bound {})",
        0.1 * edge
    );
    assert_eq!(intersecting_patch_faces(&out, input.faces.len()), 0);
}

#[test]
fn fixtures_have_the_loops_they_claim() {
    assert_eq!(
        holes::boundary_loop_sizes(&holes::cylinder_end(1000, 4)),
        Some(vec![1000])
    );
    assert_eq!(
        holes::boundary_loop_sizes(&holes::flat_annulus(5000, 3, 1e-3)),
        Some(vec![5000, 5000])
    );
    let sp = holes::boundary_loop_sizes(&holes::spiral(2, 2, 16)).expect("simple");
    assert_eq!(sp.len(), 2);
}
