//! The dispatcher end to end on small meshes: methods forced by the policy, patches
//! checked against the mesh and against the patches accepted before them, rejected
//! patches falling through to the next method.

use super::*;
use crate::policy::Checks;
use crate::policy::SelectMode;
use crate::testutil::{
    cells_removed, cut_faces, cylinder_with_hole, fan, grid, joined, mesh_and_loop, sheet,
    sheet_hole_at, sphere_cap_removed, sphere_with_hole, unit_grid, SHEET_HOLE,
};
use glam::DVec3;

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

fn checks() -> Checks {
    Checks {
        self_intersection: true,
        min_angle_deg: 0.5,
    }
}

/// Every class sent to `method` alone.
fn only(method: Method) -> Policy {
    Policy::default()
        .edit(|s| {
            s.dispatch.small = vec![method];
            s.dispatch.middle = vec![method];
            s.dispatch.large = vec![method];
        })
        .unwrap()
}

#[test]
fn a_proposal_that_meets_an_earlier_patch_fails_over_to_the_next_method() {
    // the parallel phase checked the tall fan on the lower hole against the mesh
    // as read (clean); the upper hole's lid was accepted first, and the fan pokes
    // through it: the serial phase must reject it and try the next method
    let raw = joined(sheet(6, 0.0, &SHEET_HOLE), &sheet(6, 0.3, &SHEET_HOLE));
    let (mut m, _) = Mesh::from_raw(&raw);
    let lower = sheet_hole_at(&m, 0.0);
    let upper = sheet_hole_at(&m, 0.3);
    let policy = Policy::default();
    let mut chk = Checker::new(&m);
    let tall = fan(lower.len(), v(3., 3., 1.0));
    let q = chk.check_patch(&m, &lower, &tall, &checks()).unwrap();
    // nothing added yet: nothing to meet
    chk.check_against_added(&m, &lower, &tall, &checks())
        .unwrap();
    let up = Hole::new(1, &m, upper, &policy);
    let lid = fill_hole(&mut m, &up, &policy, &mut chk);
    assert_eq!(lid.status, HoleStatus::Filled);
    m.validate().unwrap();
    let e = chk
        .check_against_added(&m, &lower, &tall, &checks())
        .unwrap_err();
    assert!(
        matches!(e, crate::check::CheckFailure::SelfIntersection { .. }),
        "{e}"
    );
    let low = Hole::new(0, &m, lower, &policy);
    let methods = methods_for(&policy, low.class).to_vec();
    assert!(methods.len() >= 2);
    let proposal = Proposal {
        order: methods.clone(),
        selection: None,
        tried: Vec::new(),
        accepted: Some(Accepted {
            at: 0,
            patch: tall,
            quality: q,
            variant: None,
            ms: 0.0,
            blend: None,
        }),
        ms: 0.0,
    };
    let rep = finish_hole(&mut m, &low, &policy, &mut chk, proposal);
    m.validate().unwrap();
    assert_eq!(rep.status, HoleStatus::Filled, "{}", rep.reason);
    assert_eq!(rep.tried[0].method, methods[0]);
    assert_eq!(rep.tried[0].outcome, Outcome::Rejected);
    assert!(
        rep.tried[0].reason.contains("intersects mesh face"),
        "{}",
        rep.tried[0].reason
    );
    assert_eq!(rep.method, Some(methods[1]));
    assert_eq!(
        m.topo.boundary_loops().len(),
        2,
        "only the sheets' outer borders"
    );
}

#[test]
fn dispatcher_rejects_a_fan_through_an_obstacle_and_fills_without_it() {
    let policy = Policy::default()
        .edit(|s| s.dispatch.small = vec![Method::Fan])
        .unwrap();
    for obstacle in [true, false] {
        // a grid missing cell (2, 2), and a small upright triangle through the
        // cell's centre (its own component)
        let mut raw = sheet(5, 0.0, &[(2, 2)]);
        if obstacle {
            let b = raw.positions.len() as u32;
            raw.positions
                .extend([v(2.5, 2.4, -0.5), v(2.6, 2.6, 0.5), v(2.4, 2.6, 0.5)]);
            raw.faces.push([b, b + 1, b + 2]);
        }
        let (mut m, l) = mesh_and_loop(&raw, |_, l| l.len() == 4);
        let hole = Hole::new(0, &m, l, &policy);
        let mut chk = Checker::new(&m);
        let nf = m.num_faces();
        let rep = fill_hole(&mut m, &hole, &policy, &mut chk);
        if obstacle {
            assert_eq!(rep.status, HoleStatus::Failed);
            assert_eq!(rep.tried[0].outcome, Outcome::Rejected);
            assert!(
                rep.tried[0].reason.contains("intersects mesh face"),
                "{}",
                rep.tried[0].reason
            );
            assert_eq!(m.num_faces(), nf);
        } else {
            assert_eq!(rep.status, HoleStatus::Filled, "{}", rep.reason);
            assert_eq!(m.num_faces(), nf + 4);
            m.validate().unwrap();
            // the patch's faces were committed to the checker
            assert_eq!(chk.committed_faces(), 4);
        }
    }
}

/// A large hole goes to the advancing front, whose patch passes the checks and is
/// applied.
#[test]
fn dispatcher_fills_a_large_hole_with_the_front() {
    let c = DVec3::new(15.0, 15.0, 0.0);
    let raw = cut_faces(unit_grid(30), |p| (p - c).length() < 9.0);
    let (mut mesh, lp) = mesh_and_loop(&raw, |_, l| l.len() != 4 * 30);
    // paper 002's list for large holes (the default puts wavefront first)
    let policy = Policy::default()
        .edit(|s| s.dispatch.large = vec![Method::AdvancingFront, Method::MinAreaFair])
        .unwrap();
    let hole = Hole::new(0, &mesh, lp, &policy);
    let mut checker = Checker::new(&mesh);
    let rep = fill_hole(&mut mesh, &hole, &policy, &mut checker);
    assert_eq!(rep.status, HoleStatus::Filled, "{}", rep.reason);
    assert_eq!(rep.method, Some(Method::AdvancingFront));
    mesh.validate().unwrap();
    assert_eq!(mesh.topo.boundary_loops().len(), 1);
}

/// Forced by the policy for every class, HPDE's patches pass the dispatcher's full
/// checks (including self-intersection against the mesh) and are applied as HPDE's.
#[test]
fn dispatcher_accepts_hpde_patches() {
    let policy = only(Method::Hpde);
    let sphere =
        |level, cap| mesh_and_loop(&sphere_cap_removed(level, 1.0, DVec3::Z, cap), |_, _| true);
    for (mut mesh, lp) in [
        sphere(3, 0.75),
        sphere(4, 1.1),
        cylinder_with_hole(48, 30, 0.7, 1.2),
    ] {
        let loops = mesh.topo.boundary_loops().len();
        let hole = Hole::new(0, &mesh, lp, &policy);
        let mut chk = Checker::new(&mesh);
        let rep = fill_hole(&mut mesh, &hole, &policy, &mut chk);
        assert_eq!(rep.status, HoleStatus::Filled, "{:?}", rep.tried);
        assert_eq!(rep.method, Some(Method::Hpde));
        // the paper's own settings closed these: no variant named
        assert_eq!(rep.tried.last().map(|a| a.variant.clone()), Some(None));
        mesh.validate().unwrap();
        assert_eq!(mesh.topo.boundary_loops().len(), loops - 1);
    }
}

/// A hole that a later variant of a self-checked method closes is logged with that
/// variant's name: HPDE on a hole wound round a cylinder, which no plane shows as a
/// simple polygon (the disk fallback off), is closed over the minimum-area surface.
#[test]
fn the_log_names_the_variant_that_made_the_patch() {
    let policy = only(Method::Hpde)
        .edit(|s| s.hpde.disk_fallback = false)
        .unwrap();
    let (mut mesh, lp) = cylinder_with_hole(32, 24, 2.9, 1.5);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let mut chk = Checker::new(&mesh);
    let rep = fill_hole(&mut mesh, &hole, &policy, &mut chk);
    mesh.validate().unwrap();
    assert_eq!(rep.status, HoleStatus::Filled, "{:?}", rep.tried);
    let last = rep.tried.last().expect("an attempt");
    assert_eq!(last.outcome, Outcome::Accepted);
    let variant = last.variant.as_deref().expect("a variant named");
    assert!(variant.contains("minimum-area surface"), "{variant}");
    let json = serde_json::to_value(&rep).unwrap();
    assert_eq!(json["tried"][rep.tried.len() - 1]["variant"], variant);
    // and a logged attempt without one has no such key
    let rejected = Attempt {
        method: Method::Hpde,
        outcome: Outcome::Rejected,
        reason: "a self-intersection".into(),
        variant: None,
        ms: 1.0,
    };
    assert!(serde_json::to_value(&rejected)
        .unwrap()
        .get("variant")
        .is_none());
}

/// A policy that names only `wavefront` fills the sphere hole with it.
#[test]
fn dispatcher_fills_with_wavefront() {
    let policy = only(Method::Wavefront);
    let raw = sphere_cap_removed(4, 1.0, DVec3::new(0.3, 0.2, 1.0), 0.5);
    let (mut mesh, lp) = mesh_and_loop(&raw, |_, _| true);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let mut chk = Checker::new(&mesh);
    let rep = fill_hole(&mut mesh, &hole, &policy, &mut chk);
    assert_eq!(rep.method, Some(Method::Wavefront), "{rep:?}");
    assert!(mesh.num_vertices() > raw.positions.len());
    mesh.validate().unwrap();
    assert!(mesh.topo.boundary_loops().is_empty());
}

/// A passed deadline ends every method of the table with a timeout, on a hole each
/// would otherwise fill (the fan, which makes its few triangles at once, aside).
#[test]
fn every_method_times_out_on_a_passed_deadline() {
    let (mesh, lp) = sphere_with_hole(3, 0.75);
    let policy = Policy::default();
    let hole = Hole::new(0, &mesh, lp, &policy);
    let mut timed = 0;
    for &method in Method::ALL {
        let live = FillContext::new(&mesh, &hole, &policy);
        assert!(
            run_method(method, &live).is_ok(),
            "{} fills it",
            method.name()
        );
        if method == Method::Fan {
            continue;
        }
        let ctx = FillContext {
            deadline: Deadline(Some(std::time::Instant::now())),
            ..FillContext::new(&mesh, &hole, &policy)
        };
        assert_eq!(
            run_method(method, &ctx),
            Err(FillError::Timeout),
            "{}",
            method.name()
        );
        timed += 1;
    }
    assert_eq!(timed, Method::ALL.len() - 1);
}

/// The `rim` rule reads the flatness of the rim: on a flat sheet every rim edge is
/// flat and `select.flat_method` goes first; on a sphere (dihedral angles of some
/// degrees between its faces) none is and the list's order stays, with the reason;
/// on a sheet folded along a crease through the hole the crease's edges are not flat
/// under `select.flat_angle_deg` and are over a wider angle; a list without the flat
/// method is not read at all.
#[test]
fn rim_rule_puts_the_flat_method_first_only_on_a_flat_rim() {
    let rule = |edit: &dyn Fn(&mut crate::policy::Settings)| {
        Policy::default()
            .edit(|s| {
                s.select.mode = SelectMode::Rim;
                edit(s);
            })
            .unwrap()
    };
    let policy = rule(&|_| {});
    let list = [Method::MinAreaFair, Method::Wavefront, Method::Close];
    let in_middle = |i: usize, j: usize| (3..5).contains(&i) && (3..5).contains(&j);

    let sheet = cells_removed(unit_grid(8), in_middle);
    let (mesh, lp) = mesh_and_loop(&sheet, |_, l| l.len() == 8);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let (order, sel) = select::order(&mesh, &hole, &policy, &list);
    let sel = sel.expect("a reading");
    assert_eq!(
        order,
        [Method::Wavefront, Method::MinAreaFair, Method::Close]
    );
    assert_eq!(sel.mode, SelectMode::Rim);
    assert_eq!(sel.winner, Some(Method::Wavefront));
    assert_eq!(sel.reason, "");
    let rim = sel.rim.expect("rim reading");
    assert_eq!(rim.flat_share, Some(1.0));
    // the vertices within 2 rings of the loop: x and y in 1..=7 around the empty middle
    assert!(rim.edges > 60, "{rim:?}");
    // a list without the flat method: nothing to choose
    let (order, sel) = select::order(&mesh, &hole, &policy, &[Method::MinAreaFair]);
    assert_eq!(order, [Method::MinAreaFair]);
    assert!(sel.is_none());

    let (mesh, lp) = sphere_with_hole(3, 0.5);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let (order, sel) = select::order(&mesh, &hole, &policy, &list);
    let sel = sel.expect("a reading");
    assert_eq!(order, list);
    assert_eq!(sel.winner, None);
    assert_eq!(sel.rim.as_ref().and_then(|r| r.flat_share), Some(0.0));
    assert!(sel.reason.contains("flat"), "{}", sel.reason);

    // folded along x = 4 by 2 atan(0.5) = 53 degrees: only the crease's edges bend
    let folded = cells_removed(grid(8, 0.0, 8.0, |x, _| 0.5 * (x - 4.0).abs()), in_middle);
    let (mesh, lp) = mesh_and_loop(&folded, |_, l| l.len() == 8);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let (_, sel) = select::order(&mesh, &hole, &policy, &list);
    let share = sel.and_then(|s| s.rim).and_then(|r| r.flat_share).unwrap();
    assert!(share > 0.9 && share < 1.0, "flat share {share}");
    let strict = rule(&|s| s.select.flat_share = 0.99);
    let (order, sel) = select::order(&mesh, &hole, &strict, &list);
    assert_eq!(order, list);
    assert_eq!(sel.map(|s| s.winner), Some(None));
    let wide = rule(&|s| {
        s.select.flat_share = 0.99;
        s.select.flat_angle_deg = 60.0;
    });
    let (order, sel) = select::order(&mesh, &hole, &wide, &list);
    assert_eq!(order[0], Method::Wavefront);
    assert_eq!(
        sel.and_then(|s| s.rim).and_then(|r| r.flat_share),
        Some(1.0)
    );
}

/// `advancing_front` forced alone on more than a hemisphere missing (the paper's
/// divergent case): the front that spreads is closed as a residual front, or made again
/// with one step per loop vertex, and the hole is closed by the method itself with a
/// patch that passes the dispatcher's checks. Before, it failed ("the front diverges").
#[test]
fn advancing_front_closes_a_divergent_front_itself() {
    let policy = only(Method::AdvancingFront)
        .edit(|s| s.rim.trim = false)
        .unwrap();
    let (mut mesh, lp) = sphere_with_hole(4, 2.0);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let mut chk = Checker::new(&mesh);
    let rep = fill_hole(&mut mesh, &hole, &policy, &mut chk);
    assert_eq!(rep.method, Some(Method::AdvancingFront), "{rep:?}");
    assert_eq!(rep.status, HoleStatus::Filled, "{rep:?}");
    mesh.validate().unwrap();
    assert!(mesh.topo.boundary_loops().is_empty());
}

/// On a sphere hole the wavefront's rows carry the rim's slope on; pulled toward their
/// own thin plate (`blend.surface = "faired"`) the new vertices come closer to the
/// sphere (oracle: radius 1), and the log says so.
#[test]
fn the_faired_blend_brings_a_sphere_patch_closer_to_the_sphere() {
    let radial = |blend: bool| {
        let policy = only(Method::Wavefront)
            .edit(|s| {
                if blend {
                    s.blend.surface = crate::policy::BlendSurface::Faired;
                    s.blend.weight_middle = 0.9;
                    s.blend.weight_large = 0.9;
                }
            })
            .unwrap();
        let raw = sphere_cap_removed(4, 1.0, DVec3::new(0.3, 0.2, 1.0), 0.7);
        let (mut mesh, lp) = mesh_and_loop(&raw, |_, _| true);
        let n = mesh.num_vertices();
        let hole = Hole::new(0, &mesh, lp, &policy);
        let mut chk = Checker::new(&mesh);
        let rep = fill_hole(&mut mesh, &hole, &policy, &mut chk);
        mesh.validate().unwrap();
        assert_eq!(rep.status, HoleStatus::Filled, "{:?}", rep.tried);
        assert_eq!(
            rep.blend.as_ref().is_some_and(|b| b.applied),
            blend,
            "{rep:?}"
        );
        let new: Vec<f64> = (n..mesh.num_vertices())
            .map(|v| (mesh.pos(crate::mesh::VertexId::from_idx(v)).length() - 1.0).abs())
            .collect();
        assert!(!new.is_empty());
        new.iter().sum::<f64>() / new.len() as f64
    };
    let (rows, blended) = (radial(false), radial(true));
    eprintln!("mean |r - 1|: wavefront {rows:.5}, blended {blended:.5}");
    assert!(blended < 0.25 * rows, "wavefront {rows}, blended {blended}");
}
