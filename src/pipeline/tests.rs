//! The whole repair on dirty inputs: generated defects of real scans, each repaired
//! with a valid manifold output, and a property test that injects random defects into
//! a closed mesh with holes.

use super::repair;
use crate::geometry::predicates::tri_tri;
use crate::io::RawMesh;
use crate::mesh::Mesh;
use crate::policy::{IslandMode, Policy};
use crate::report::{HoleStatus, RepairReport};
use glam::DVec3;
use proptest::prelude::*;
use std::collections::HashMap;

/// A unit icosphere (1,280 faces) with round holes around the given directions.
fn holed_sphere(dirs: &[(DVec3, f64)]) -> RawMesh {
    crate::testutil::sphere_caps_removed(3, 1.0, dirs)
}

/// Checks what every repair must give: an oriented manifold output (each edge at most
/// two faces, each directed edge once), the input's vertices first and bit-exact, no
/// patch face meeting another face (vertices compared by position, as the bench
/// does), and every boundary loop left accounted for by a hole skipped or failed in
/// the log.
fn assert_sound(raw: &RawMesh, out: &RawMesh, rep: &RepairReport) {
    for (i, p) in raw.positions.iter().enumerate() {
        assert_eq!(out.positions[i], *p, "input vertex {i} moved");
    }
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    let mut undirected: HashMap<(u32, u32), usize> = HashMap::new();
    for f in &out.faces {
        for c in 0..3 {
            let (a, b) = (f[c], f[(c + 1) % 3]);
            *directed.entry((a, b)).or_default() += 1;
            *undirected.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    assert!(
        directed.values().all(|&n| n == 1),
        "a directed edge used twice"
    );
    assert!(
        undirected.values().all(|&n| n <= 2),
        "an edge with three faces"
    );
    let (m, build) = Mesh::from_raw(out);
    m.validate().unwrap();
    assert_eq!(build.non_manifold_edges, 0);
    assert_eq!(build.flipped_faces, 0);
    assert_eq!(build.detached_faces, 0);
    // patch faces are the last ones (input faces keep their order before them)
    let added: usize = rep.holes.iter().map(|h| h.added_faces).sum();
    let first_patch = out.faces.len() - added;
    let mut key_of: HashMap<[u64; 3], u64> = HashMap::new();
    let key: Vec<u64> = out
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            *key_of
                .entry([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
                .or_insert(i as u64)
        })
        .collect();
    let tri = |f: [u32; 3]| f.map(|v| out.positions[v as usize]);
    let keys = |f: [u32; 3]| f.map(|v| key[v as usize]);
    for (pi, &p) in out.faces.iter().enumerate().skip(first_patch) {
        for (qi, &q) in out.faces.iter().enumerate() {
            if qi == pi {
                continue;
            }
            assert!(
                !tri_tri(&tri(p), &keys(p), &tri(q), &keys(q)),
                "patch face {pi} {p:?} meets face {qi} {q:?}"
            );
        }
    }
    let open = m.topo.boundary_loops().len();
    let logged = rep
        .holes
        .iter()
        .filter(|h| h.status != HoleStatus::Filled)
        .count();
    assert!(
        open <= logged,
        "{open} loops open, {logged} logged: {rep:#?}"
    );
    for h in &rep.holes {
        if h.status != HoleStatus::Filled {
            assert!(!h.reason.is_empty());
        }
    }
}

fn three_holes() -> RawMesh {
    holed_sphere(&[
        (DVec3::Z, 0.25),
        (DVec3::X, 0.4),
        (DVec3::new(0.0, -0.6, -0.8), 0.5),
    ])
}

#[test]
fn a_clean_holed_sphere_is_closed() {
    let raw = three_holes();
    let (out, rep) = repair(&raw, &Policy::default()).unwrap();
    assert_eq!(rep.summary.filled, 3, "{:#?}", rep.holes);
    assert_sound(&raw, &out, &rep);
}

/// One of the defects a scan carries, injected into a soup.
#[derive(Clone, Debug)]
enum Defect {
    /// Face `i` repeated, rotated (same orientation) or reversed.
    Duplicate(usize, bool),
    /// Face `i` reversed.
    Flip(usize),
    /// A flap on an edge of face `i`: a new vertex lifted off the surface, one face
    /// (a third face on an interior edge).
    Flap(usize, usize),
    /// A small triangle touching vertex `corner` of face `i` only (a pinched vertex).
    Pinch(usize),
    /// An unreferenced vertex.
    Unreferenced,
    /// Face `i` cut loose: its three corners replaced by copies at the same positions
    /// (a crack of coincident vertices all round it).
    Crack(usize),
    /// The first corner of face `i` replaced by a copy at the same position: a loop of
    /// zero area (two slits) around it.
    Slit(usize),
    /// A flat fan of `k` faces (a piece of its own) inside the hole at the north pole:
    /// an island.
    Island(u32),
}

fn inject(raw: &mut RawMesh, d: &Defect) {
    let n = raw.faces.len();
    match *d {
        Defect::Duplicate(i, same) => {
            let [a, b, c] = raw.faces[i % n];
            raw.faces.push(if same { [b, c, a] } else { [a, c, b] });
        }
        Defect::Flip(i) => raw.faces[i % n].swap(1, 2),
        Defect::Flap(i, e) => {
            let f = raw.faces[i % n];
            let (a, b) = (f[e % 3], f[(e + 1) % 3]);
            let (pa, pb) = (raw.positions[a as usize], raw.positions[b as usize]);
            let mid = (pa + pb) * 0.5;
            raw.positions.push(mid * 1.15);
            let x = raw.positions.len() as u32 - 1;
            raw.faces.push([a, b, x]);
        }
        Defect::Pinch(i) => {
            let v = raw.faces[i % n][0];
            let p = raw.positions[v as usize];
            let t = p.any_orthonormal_vector() * 0.05;
            raw.positions.push(p * 1.1 + t);
            raw.positions.push(p * 1.1 - t);
            let k = raw.positions.len() as u32;
            raw.faces.push([v, k - 2, k - 1]);
        }
        Defect::Unreferenced => raw.positions.push(DVec3::new(3.0, 3.0, 3.0)),
        Defect::Island(k) => {
            let c = DVec3::new(0.0, 0.0, 0.995);
            let b = raw.positions.len() as u32;
            raw.positions.push(c);
            for j in 0..k {
                let a = std::f64::consts::TAU * f64::from(j) / f64::from(k);
                raw.positions
                    .push(c + DVec3::new(0.08 * a.cos(), 0.08 * a.sin(), 0.0));
            }
            for j in 0..k {
                raw.faces.push([b, b + 1 + j, b + 1 + (j + 1) % k]);
            }
        }
        Defect::Crack(i) | Defect::Slit(i) => {
            let corners = if matches!(d, Defect::Crack(_)) { 3 } else { 1 };
            for c in 0..corners {
                let v = raw.faces[i % n][c];
                raw.positions.push(raw.positions[v as usize]);
                raw.faces[i % n][c] = raw.positions.len() as u32 - 1;
            }
        }
    }
}

fn defect() -> impl Strategy<Value = Defect> {
    prop_oneof![
        (0usize..2000, any::<bool>()).prop_map(|(i, s)| Defect::Duplicate(i, s)),
        (0usize..2000).prop_map(Defect::Flip),
        (0usize..2000, 0usize..3).prop_map(|(i, e)| Defect::Flap(i, e)),
        (0usize..2000).prop_map(Defect::Pinch),
        Just(Defect::Unreferenced),
        (0usize..2000).prop_map(Defect::Crack),
        (0usize..2000).prop_map(Defect::Slit),
    ]
}

#[test]
fn each_defect_alone_is_repaired() {
    for d in [
        Defect::Duplicate(100, true),
        Defect::Duplicate(200, false),
        Defect::Flip(300),
        Defect::Flap(400, 1),
        Defect::Pinch(500),
        Defect::Unreferenced,
        // removed (4 faces < islands.remove_below_faces), bridged (12 faces)
        Defect::Island(4),
        Defect::Island(12),
    ] {
        let mut raw = three_holes();
        inject(&mut raw, &d);
        let (out, rep) = repair(&raw, &Policy::default()).unwrap_or_else(|e| panic!("{d:?}: {e}"));
        assert_sound(&raw, &out, &rep);
        assert_eq!(rep.summary.failed, 0, "{d:?}: {:#?}", rep.holes);
        if let Defect::Island(k) = d {
            let removed: usize = rep.holes.iter().map(|h| h.island_faces_removed).sum();
            let bridged: usize = rep.holes.iter().map(|h| h.islands_bridged).sum();
            assert_eq!((removed, bridged), if k < 10 { (4, 0) } else { (0, 1) });
            assert_eq!(rep.summary.filled, 3, "{:#?}", rep.holes);
        }
    }
}

/// The face of `raw` whose centroid is nearest the direction `dir`.
fn face_toward(raw: &RawMesh, dir: DVec3) -> usize {
    let c = |f: &[u32; 3]| f.iter().map(|&v| raw.positions[v as usize]).sum::<DVec3>();
    (0..raw.faces.len())
        .max_by(|&a, &b| {
            let (x, y) = (c(&raw.faces[a]).normalize(), c(&raw.faces[b]).normalize());
            x.dot(dir).total_cmp(&y.dot(dir))
        })
        .unwrap()
}

#[test]
fn cracks_and_zero_area_loops_are_stitched_not_filled() {
    let clean = repair(&three_holes(), &Policy::default()).unwrap().0;
    let far = face_toward(&three_holes(), DVec3::new(-1.0, 0.3, 0.2).normalize());
    // a face cut loose: the triangle hole and the loose face's border; a slit corner:
    // one loop of zero area
    for (d, stitched) in [(Defect::Crack(far), 2), (Defect::Slit(far), 1)] {
        let mut raw = three_holes();
        inject(&mut raw, &d);
        let (m, _) = Mesh::from_raw(&raw);
        assert_eq!(m.topo.boundary_loops().len(), 3 + stitched, "{d:?}");
        let (out, rep) = repair(&raw, &Policy::default()).unwrap();
        assert_sound(&raw, &out, &rep);
        assert_eq!(rep.summary.stitched, stitched, "{d:?}: {:#?}", rep.holes);
        assert_eq!(rep.summary.filled, 3, "{d:?}");
        assert_eq!(rep.summary.failed + rep.summary.skipped, 0, "{d:?}");
        for h in rep
            .holes
            .iter()
            .filter(|h| h.status == HoleStatus::Stitched)
        {
            assert_eq!(h.added_faces, 0);
            assert!(h.reason.contains("crack"), "{}", h.reason);
        }
        // no patch over the crack: the same faces as the repair without it, the cut
        // face back on the input's vertices
        assert_eq!(out.faces.len(), clean.faces.len(), "{d:?}");
        assert_eq!(out.faces[far], three_holes().faces[far]);
        assert_eq!(rep.resolved.stitched_faces, 1, "{d:?}");
        // stitching off: the loops are holes (a patch each, or a skipped piece)
        let off = Policy::default().edit(|s| s.crack.stitch = false).unwrap();
        let (_, rep) = repair(&raw, &off).unwrap();
        assert_eq!(rep.summary.stitched, 0);
        assert_eq!(rep.summary.holes, 3 + stitched);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]
    /// Random defects in a closed mesh with holes: never refused, the output an
    /// oriented manifold with no self-intersecting patch, every hole closed or logged.
    #[test]
    fn random_defects_are_never_refused(defects in proptest::collection::vec(defect(), 1..8)) {
        let mut raw = three_holes();
        for d in &defects {
            inject(&mut raw, d);
        }
        let r = repair(&raw, &Policy::default());
        prop_assert!(r.is_ok(), "{:?}", r.err());
        let (out, rep) = r.unwrap();
        assert_sound(&raw, &out, &rep);
    }
}

/// A flat grid over `[0, n]²` with the cells whose centre lies within `hole` of
/// `(c, c)` removed, except those within `r` of one of the `islands` centres (pieces
/// of their own, with no vertex shared with the rest).
fn holed_grid(n: usize, hole: f64, islands: &[([f64; 2], f64)]) -> RawMesh {
    let c = n as f64 / 2.0;
    crate::testutil::cells_removed(crate::testutil::unit_grid(n), |i, j| {
        let (x, y) = (i as f64 + 0.5, j as f64 + 0.5);
        let in_hole = (x - c).hypot(y - c) < hole;
        let on_island = islands.iter().any(|(p, r)| (x - p[0]).hypot(y - p[1]) < *r);
        in_hole && !on_island
    })
}

fn island_policy(mode: IslandMode, below: usize) -> Policy {
    Policy::default()
        .edit(|s| {
            s.islands.mode = mode;
            s.islands.remove_below_faces = below;
        })
        .unwrap()
}

#[test]
fn an_island_is_bridged_and_filled_with_its_hole_never_capped() {
    // an annulus (a 20x20 grid with a hole of radius 4.5) around a disk of 12 cells
    let raw = holed_grid(20, 4.5, &[([10.0, 10.0], 1.6)]);
    let (m, _) = Mesh::from_raw(&raw);
    assert_eq!(m.topo.boundary_loops().len(), 3, "border, hole, island");
    let (out, rep) = repair(&raw, &island_policy(IslandMode::Bridge, 0)).unwrap();
    assert_sound(&raw, &out, &rep);
    let filled: Vec<_> = rep
        .holes
        .iter()
        .filter(|h| h.status == HoleStatus::Filled)
        .collect();
    assert_eq!(filled.len(), 1, "{:#?}", rep.holes);
    assert_eq!(filled[0].islands_bridged, 1);
    assert_eq!(filled[0].island_faces_removed, 0);
    // the island's faces are all in the output (none removed) and only the outer
    // border is open
    assert_eq!(out.faces.len(), raw.faces.len() + filled[0].added_faces);
    let (o, _) = Mesh::from_raw(&out);
    o.validate().unwrap();
    assert_eq!(o.topo.boundary_loops().len(), 1);
    assert_eq!(rep.summary.failed, 0);
}

#[test]
fn two_islands_are_bridged_into_one_loop() {
    let raw = holed_grid(24, 6.0, &[([9.5, 12.0], 1.3), ([14.5, 12.0], 1.3)]);
    let (m, _) = Mesh::from_raw(&raw);
    assert_eq!(m.topo.boundary_loops().len(), 4);
    let (out, rep) = repair(&raw, &island_policy(IslandMode::Bridge, 0)).unwrap();
    assert_sound(&raw, &out, &rep);
    let bridged: usize = rep.holes.iter().map(|h| h.islands_bridged).sum();
    assert_eq!(bridged, 2, "{:#?}", rep.holes);
    assert_eq!(rep.summary.filled, 1);
    assert_eq!(rep.summary.failed, 0);
    let (o, _) = Mesh::from_raw(&out);
    assert_eq!(o.topo.boundary_loops().len(), 1);
}

#[test]
fn small_islands_are_removed_and_large_ones_block_their_hole_in_remove_mode() {
    let raw = holed_grid(24, 6.0, &[([9.5, 12.0], 1.3), ([14.5, 12.0], 1.3)]);
    // both islands below the count: removed, the hole filled as a disk
    let (out, rep) = repair(&raw, &island_policy(IslandMode::Remove, 1000)).unwrap();
    assert_sound(&raw, &out, &rep);
    let (m, _) = Mesh::from_raw(&raw);
    let island_faces = m.num_faces() - {
        let (big, _) = Mesh::from_raw(&holed_grid(24, 6.0, &[]));
        big.num_faces()
    };
    let h: Vec<_> = rep
        .holes
        .iter()
        .filter(|h| h.status == HoleStatus::Filled)
        .collect();
    assert_eq!(h.len(), 1, "{:#?}", rep.holes);
    assert_eq!(h[0].island_faces_removed, island_faces);
    assert_eq!(rep.summary.holes, 2, "the border and the hole");
    // above the count in remove mode: the hole is skipped by the island rule
    let (out, rep) = repair(&raw, &island_policy(IslandMode::Remove, 0)).unwrap();
    assert_sound(&raw, &out, &rep);
    assert_eq!(rep.summary.filled, 0, "{:#?}", rep.holes);
    assert!(rep
        .holes
        .iter()
        .any(|h| h.status == HoleStatus::Skipped && h.reason.starts_with("island inside")));
    assert_eq!(out.faces.len(), raw.faces.len(), "no cap");
}

#[test]
fn floating_debris_is_removed_by_policy_only() {
    // a holed sphere with two loose triangles and a loose pair of triangles
    let mut raw = three_holes();
    for (k, z) in [(0u32, 3.0), (1, 4.0)] {
        let b = raw.positions.len() as u32;
        raw.positions.extend([
            DVec3::new(0.0, 0.0, z),
            DVec3::new(0.1, 0.0, z),
            DVec3::new(0.0, 0.1, z),
            DVec3::new(0.1, 0.1, z),
        ]);
        raw.faces.push([b, b + 1, b + 2]);
        if k == 1 {
            raw.faces.push([b + 1, b + 3, b + 2]);
        }
    }
    let (out, rep) = repair(&raw, &Policy::default()).unwrap();
    assert_sound(&raw, &out, &rep);
    assert_eq!(rep.resolved.debris_faces_removed, 0, "kept by default");
    assert_eq!(rep.summary.skipped, 2, "their borders");
    let p = Policy::default()
        .edit(|s| s.debris.remove_below_faces = 3)
        .unwrap();
    let (out, rep) = repair(&raw, &p).unwrap();
    assert_sound(&raw, &out, &rep);
    assert_eq!(rep.resolved.debris_pieces_removed, 2);
    assert_eq!(rep.resolved.debris_faces_removed, 3);
    assert_eq!(rep.summary.filled, 3);
    assert_eq!(rep.summary.skipped, 0);
}

/// Three square holes of a grid in a diagonal chain, touching at two corners: one loop
/// of 12 pinched at two vertices (each split by the builder). The lobes are filled
/// first and the copies joined, so the chain closes as holes of its own, with no
/// failure, one log entry naming the pinches, and a sound output whose only open
/// loop is the grid's border.
#[test]
fn a_loop_pinched_at_two_vertices_is_closed() {
    let raw = crate::testutil::cells_removed(crate::testutil::unit_grid(8), |i, j| {
        i == j && (2..=4).contains(&i)
    });
    let (out, rep) = repair(&raw, &Policy::default()).unwrap();
    assert_eq!(rep.summary.failed, 0, "{:#?}", rep.holes);
    assert_eq!(rep.summary.skipped, 1, "the border: {:#?}", rep.holes);
    let pinched: Vec<_> = rep
        .holes
        .iter()
        .filter(|h| h.reason.contains("pinched at one point"))
        .collect();
    assert_eq!(pinched.len(), 1, "{:#?}", rep.holes);
    assert_eq!(pinched[0].status, HoleStatus::Filled);
    assert_eq!(pinched[0].reason.matches("pinched").count(), 2);
    assert_sound(&raw, &out, &rep);
    let (m, _) = Mesh::from_raw(&out);
    assert_eq!(
        m.topo.boundary_loops().len(),
        1,
        "only the border left open"
    );
    // every cell of the three holes is covered: the patch areas add up
    let area = |f: &[u32; 3]| {
        let p = f.map(|v| out.positions[v as usize]);
        (p[1] - p[0]).cross(p[2] - p[0]).length() / 2.0
    };
    let total: f64 = out.faces.iter().map(area).sum();
    assert!((total - 64.0).abs() < 1e-9, "area {total}");
}
