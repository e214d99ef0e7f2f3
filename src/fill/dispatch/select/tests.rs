use super::*;
use crate::check::Checker;
use crate::fill::dispatch::{fill_hole, methods_for};
use crate::policy::Settings;
use crate::report::HoleStatus;
use crate::testutil::{cells_removed, mesh_and_loop, sphere_with_hole, unit_grid};

fn validating() -> Policy {
    let mut s = Settings::default();
    s.select.mode = SelectMode::Validate;
    Policy::new(s).unwrap()
}

#[test]
fn a_hole_on_a_sphere_is_grown_each_candidate_scored_and_the_best_goes_first() {
    let policy = validating();
    let (mut mesh, lp) = sphere_with_hole(4, 0.45);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let methods = methods_for(&policy, hole.class).to_vec();
    let (order, sel) = order(&mesh, &hole, &policy, &methods);
    let sel = sel.expect("two candidates in the list");
    assert!(sel.reason.is_empty(), "{}", sel.reason);
    assert!(sel.grown_boundary_vertices > hole.len());
    assert!(sel.known_points > 2 * hole.len(), "{}", sel.known_points);
    let names: Vec<Method> = sel.candidates.iter().map(|c| c.method).collect();
    assert_eq!(names, vec![Method::Wavefront, Method::MinAreaFair]);
    // the true surface is the unit sphere: every candidate passes near it (per mille
    // of the diagonal, 2 * sqrt(3); an edge is about 22 of it)
    let scores: Vec<f64> = sel.candidates.iter().map(|c| c.score.unwrap()).collect();
    for s in &scores {
        assert!(*s > 0.0 && *s < 8.0, "{scores:?}");
    }
    let best = if scores[1] < scores[0] {
        Method::MinAreaFair
    } else {
        Method::Wavefront
    };
    assert_eq!(sel.winner, Some(best));
    assert_eq!(order[0], best);
    let mut rest = methods.clone();
    rest.retain(|&m| m != best);
    assert_eq!(&order[1..], &rest[..], "the others keep the list's order");
    // and the fill uses that order and logs the selection
    let mut checker = Checker::new(&mesh);
    let rep = fill_hole(&mut mesh, &hole, &policy, &mut checker);
    mesh.validate().unwrap();
    assert_eq!(rep.status, HoleStatus::Filled, "{}", rep.reason);
    assert_eq!(rep.method, Some(best));
    assert_eq!(rep.selection.as_ref().and_then(|s| s.winner), Some(best));
    assert!(mesh.topo.boundary_loops().is_empty());
}

/// A 20 x 20 flat grid with a 2 x 2 hole in the middle, and the hole's loop.
fn flat_hole() -> (Mesh, Vec<VertexId>) {
    let raw = cells_removed(unit_grid(20), |i, j| {
        (9..11).contains(&i) && (9..11).contains(&j)
    });
    mesh_and_loop(&raw, |_, l| l.len() == 8)
}

#[test]
fn the_score_is_the_distance_from_the_removed_surface() {
    let policy = validating();
    let (mesh, lp) = flat_hole();
    let hole = Hole::new(0, &mesh, lp, &policy);
    let g = Grown::new(&mesh, &hole, &policy, 2).unwrap();
    assert_eq!(
        g.mesh.topo.boundary_loops().len(),
        2,
        "the grown hole and the piece's border"
    );
    g.mesh.validate().unwrap();
    // two rings around the 2 x 2 hole (from x, y = 9 to 11): the grown loop lies
    // between one and two cells out, every known point inside it, on the plane
    assert!(g.hole.len() > 8);
    for &v in &g.hole.vertices {
        let p = g.mesh.pos(v);
        let out = (p.x - 10.0).abs().max((p.y - 10.0).abs());
        assert!((2.0..=3.0).contains(&out), "{p}");
    }
    assert!(g.known.len() > 8 + 16, "{}", g.known.len());
    for p in &g.known {
        assert!(
            p.z == 0.0 && (p.x - 10.0).abs() < 3.0 && (p.y - 10.0).abs() < 3.0,
            "{p}"
        );
    }
    let k = g.hole.len();
    let fan = |z: f64| Patch {
        new_vertices: vec![DVec3::new(10.0, 10.0, z)],
        triangles: (0..k)
            .map(|i| [i as u32, ((i + 1) % k) as u32, k as u32])
            .collect(),
    };
    // a flat fan lies on the removed surface
    assert!(g.mean_distance(&fan(0.0)) < 1e-12);
    // a raised one does not: the centre point alone is 3 above it
    let raised = g.mean_distance(&fan(3.0));
    assert!(raised > 0.3 && raised < 3.0, "{raised}");
}

#[test]
fn a_hole_whose_grown_region_reaches_another_is_grown_less() {
    let policy = validating();
    // two 2 x 2 holes two cells apart: two rings reach from one to the other, one
    // does not
    let raw = cells_removed(unit_grid(20), |i, j| {
        (5..7).contains(&j) && ((5..7).contains(&i) || (9..11).contains(&i))
    });
    let (mesh, lp) = mesh_and_loop(&raw, |m, l| l.len() == 8 && m.pos(l[0]).x < 8.0);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let methods = vec![Method::Wavefront, Method::MinAreaFair, Method::Close];
    let (_, sel) = order(&mesh, &hole, &policy, &methods);
    let sel = sel.unwrap();
    assert_eq!(sel.rings, 1, "{sel:?}");
    assert!(sel.winner.is_some(), "{sel:?}");
}

#[test]
fn a_hole_whose_grown_region_reaches_another_keeps_the_list_order() {
    let policy = validating();
    // two 2 x 2 holes one cell apart: one ring reaches from one to the other
    let raw = cells_removed(unit_grid(20), |i, j| {
        (5..7).contains(&j) && ((5..7).contains(&i) || (8..10).contains(&i))
    });
    let (mesh, lp) = mesh_and_loop(&raw, |m, l| l.len() == 8 && m.pos(l[0]).x < 8.0);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let methods = vec![Method::Wavefront, Method::MinAreaFair, Method::Close];
    let (order, sel) = order(&mesh, &hole, &policy, &methods);
    let sel = sel.unwrap();
    assert_eq!(order, methods);
    assert_eq!(sel.winner, None);
    assert!(sel.candidates.is_empty());
    assert!(sel.reason.contains("another hole"), "{}", sel.reason);
}

#[test]
fn the_first_mode_or_a_single_candidate_compares_nothing() {
    let (mesh, lp) = flat_hole();
    let first = Policy::default();
    let hole = Hole::new(0, &mesh, lp, &first);
    let methods = vec![Method::Wavefront, Method::MinAreaFair];
    assert_eq!(
        order(&mesh, &hole, &first, &methods),
        (methods.clone(), None)
    );
    let one = vec![Method::Fan, Method::MinAreaFair, Method::Close];
    assert_eq!(
        order(&mesh, &hole, &validating(), &one),
        (one.clone(), None)
    );
}

#[test]
fn surface_the_grown_region_encloses_joins_it() {
    let policy = validating();
    // a C-shaped hole, two cells wide, around a 3 x 3 block of kept cells joined to the
    // rest by a neck one cell wide: one ring removes the block's outer cells and the
    // neck, and leaves its centre cell enclosed by the grown region; the centre joins
    // the grown region, whose rim is then one loop
    let raw = cells_removed(unit_grid(20), |i, j| {
        let ring = (7..14).contains(&i) && (7..14).contains(&j);
        let block = (9..12).contains(&i) && (9..12).contains(&j);
        let neck = i == 10 && j >= 12;
        ring && !block && !neck
    });
    let (mesh, lp) = mesh_and_loop(&raw, |_, l| l.len() != 80);
    assert_eq!(mesh.topo.boundary_loops().len(), 2);
    let hole = Hole::new(0, &mesh, lp, &policy);
    let g = Grown::new(&mesh, &hole, &policy, 1).unwrap();
    g.mesh.validate().unwrap();
    // the centre cell's two faces are known points, not in the copy
    let centre = |p: &DVec3| (p.x - 10.5).abs() < 0.5 && (p.y - 10.5).abs() < 0.5;
    assert_eq!(g.known.iter().filter(|p| centre(p)).count(), 2);
    assert_eq!(
        g.mesh.topo.boundary_loops().len(),
        2,
        "the grown hole and the border"
    );
}

#[test]
fn a_large_hole_is_grown_deeper() {
    let mut s = Settings::default().select;
    assert_eq!(rings_for(&s, 10), 2);
    assert_eq!(rings_for(&s, 74), 2);
    assert_eq!(rings_for(&s, 75), 3);
    assert_eq!(rings_for(&s, 220), 8);
    s.vertices_per_ring = 0;
    assert_eq!(rings_for(&s, 220), 2);
}
