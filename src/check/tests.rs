use super::checker::{face_tri, vertex_key, NEW_KEY};
use super::*;
use crate::geometry::predicates::tri_tri;
use crate::io::RawMesh;
use crate::policy::Checks;
use crate::testutil::{self, sheet_hole_at, SHEET_HOLE};

fn v(x: f64, y: f64, z: f64) -> DVec3 {
    DVec3::new(x, y, z)
}

// ---- whole-patch checks -------------------------------------------------

/// A torus of 3 x 3 new vertices: closed, every vertex a single fan, chi = 0.
fn torus(base: u32) -> Vec<[u32; 3]> {
    let id = |i: u32, j: u32| base + (j % 3) * 3 + (i % 3);
    let mut t = Vec::new();
    for j in 0..3 {
        for i in 0..3 {
            t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    t
}

#[test]
fn topology_rejects_extra_closed_components() {
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    let (m, _) = Mesh::from_raw(&raw);
    let hole = sheet_hole_at(&m, 0.0);
    let mut p = fan(&hole, v(3., 3., 0.));
    check_topology(&m, &hole, &p).unwrap();
    let base = (hole.len() + 1) as u32;
    p.triangles.extend(torus(base));
    for i in 0..9 {
        p.new_vertices.push(v(10. + i as f64, 0., 0.));
    }
    let e = check_topology(&m, &hole, &p).unwrap_err();
    assert!(
        matches!(e, CheckFailure::Topology(TopologyFailure::Disconnected(_))),
        "{e}"
    );
}

#[test]
fn topology_rejects_open_and_misoriented_patches() {
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    let (m, _) = Mesh::from_raw(&raw);
    let hole = sheet_hole_at(&m, 0.0);
    let good = fan(&hole, v(3., 3., 0.));
    let mut open = good.clone();
    open.triangles.pop();
    assert!(check_topology(&m, &hole, &open).is_err());
    let mut flipped = good.clone();
    for t in &mut flipped.triangles {
        t.swap(0, 1);
    }
    assert!(check_topology(&m, &hole, &flipped).is_err());
    let mut oob = good.clone();
    oob.triangles[0][2] = 99;
    assert!(check_topology(&m, &hole, &oob).is_err());
    let mut nan = good;
    nan.new_vertices[0].x = f64::NAN;
    assert!(check_topology(&m, &hole, &nan).is_err());
    // an L-shaped hole whose reflex corner (3,3) sits between two loop vertices
    // joined by a mesh edge (the diagonal of the remaining cell (2,3)): cutting
    // the ear at (3,3) would add that edge a second time
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &[(2, 2), (3, 2), (3, 3)], &mut raw);
    let (m, l) = testutil::mesh_and_loop(&raw, |_, l| l.len() == 8);
    let k = l.len();
    let i = l.iter().position(|&u| m.pos(u) == v(3., 3., 0.)).unwrap();
    let at = |d: usize| ((i + d) % k) as u32;
    let ear = || {
        let mut t = vec![[at(k - 1), at(0), at(1)]];
        for j in 2..k - 1 {
            t.push([at(1), at(j), at(j + 1)]);
        }
        Patch {
            new_vertices: vec![],
            triangles: t,
        }
    };
    let e = check_topology(&m, &l, &ear()).unwrap_err();
    assert!(
        matches!(
            e,
            CheckFailure::Topology(TopologyFailure::ChordIsMeshEdge(..))
        ),
        "{e}"
    );
    // the ear at the convex corner (2,2) is fine
    let j = l.iter().position(|&u| m.pos(u) == v(2., 2., 0.)).unwrap();
    let at = |d: usize| ((j + d) % k) as u32;
    let mut t = vec![[at(k - 1), at(0), at(1)]];
    for d in 2..k - 1 {
        t.push([at(1), at(d), at(d + 1)]);
    }
    check_topology(
        &m,
        &l,
        &Patch {
            new_vertices: vec![],
            triangles: t,
        },
    )
    .unwrap();
}

/// Appends to `raw` an n x n grid of unit cells at height z (its vertex ids start at
/// `base`, the vertices `raw` has), minus the cells in `removed` (i, j).
fn grid(n: usize, z: f64, base: u32, removed: &[(usize, usize)], raw: &mut RawMesh) {
    assert_eq!(raw.positions.len(), base as usize);
    *raw = testutil::joined(std::mem::take(raw), &testutil::sheet(n, z, removed));
}

fn fan(hole: &[VertexId], apex: DVec3) -> Patch {
    testutil::fan(hole.len(), apex)
}

fn checks() -> Checks {
    Checks {
        self_intersection: true,
        min_angle_deg: 0.5,
    }
}

#[test]
fn flat_fan_on_a_grid_hole_is_accepted() {
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    let (m, _) = Mesh::from_raw(&raw);
    let hole = sheet_hole_at(&m, 0.0);
    let chk = Checker::new(&m);
    let q = chk
        .check_patch(&m, &hole, &fan(&hole, v(3., 3., 0.)), &checks())
        .unwrap();
    assert!(q.min_angle_deg > 40.0);
    // a raised apex is fine too, as long as nothing is in the way
    chk.check_patch(&m, &hole, &fan(&hole, v(3., 3., 2.)), &checks())
        .unwrap();
    // an apex pushed sideways in the plane folds the fan over itself and the mesh
    let e = chk
        .check_patch(&m, &hole, &fan(&hole, v(4.5, 3., 0.)), &checks())
        .unwrap_err();
    assert!(matches!(e, CheckFailure::SelfIntersection { .. }), "{e}");
}

#[test]
fn patch_poking_through_the_far_side_is_rejected() {
    // a thin shell: the holed sheet at z = 0 and a full sheet 0.3 above it
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    grid(6, 0.3, 49, &[], &mut raw);
    let (m, _) = Mesh::from_raw(&raw);
    let hole = sheet_hole_at(&m, 0.0);
    let chk = Checker::new(&m);
    chk.check_patch(&m, &hole, &fan(&hole, v(3., 3., 0.1)), &checks())
        .unwrap();
    let e = chk
        .check_patch(&m, &hole, &fan(&hole, v(3., 3., 1.0)), &checks())
        .unwrap_err();
    let CheckFailure::SelfIntersection {
        meets: Meets::MeshFace(f),
        ..
    } = e
    else {
        panic!("{e}")
    };
    assert!(m
        .tri(crate::mesh::FaceId::from_idx(f))
        .iter()
        .all(|p| p.z == 0.3));
    // with the check off the same patch passes
    let off = Checks {
        self_intersection: false,
        ..checks()
    };
    chk.check_patch(&m, &hole, &fan(&hole, v(3., 3., 1.0)), &off)
        .unwrap();
}

#[test]
fn patch_folding_onto_itself_is_rejected() {
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    let (m, _) = Mesh::from_raw(&raw);
    let hole = sheet_hole_at(&m, 0.0);
    let k = hole.len() as u32;
    let chk = Checker::new(&m);
    // two apexes; triangles 0..k/2 go to the first, the rest to the second
    let tri = |a: DVec3, b: DVec3| {
        let mut t: Vec<[u32; 3]> = Vec::new();
        for i in 0..k {
            let apex = if i < k / 2 { k } else { k + 1 };
            t.push([i, (i + 1) % k, apex]);
        }
        t.push([k / 2, k + 1, k]);
        t.push([0, k, k + 1]);
        Patch {
            new_vertices: vec![a, b],
            triangles: t,
        }
    };
    // the loop runs clockwise seen from +z: find which half each apex belongs to
    let mid0 = (m.pos(hole[0]) + m.pos(hole[(k / 2) as usize])) * 0.5;
    let half = |i: usize| m.pos(hole[i]) - mid0;
    let side = (half(1) + half(2) + half(3)).normalize() * 0.5;
    let good = tri(mid0 + side, mid0 - side);
    chk.check_patch(&m, &hole, &good, &checks()).unwrap();
    let bad = tri(mid0 - side, mid0 + side);
    let e = chk.check_patch(&m, &hole, &bad, &checks()).unwrap_err();
    assert!(
        matches!(
            e,
            CheckFailure::SelfIntersection {
                meets: Meets::PatchTriangle(_),
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn committed_faces_are_checked() {
    // two holed sheets, the second 0.3 above; fill the upper hole, then a tall
    // fan on the lower hole hits the new faces (before, it passed through)
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    grid(6, 0.3, 49, &SHEET_HOLE, &mut raw);
    let (mut m, _) = Mesh::from_raw(&raw);
    let lower = sheet_hole_at(&m, 0.0);
    let upper = sheet_hole_at(&m, 0.3);
    let mut chk = Checker::new(&m);
    let tall = fan(&lower, v(3., 3., 1.0));
    chk.check_patch(&m, &lower, &tall, &checks()).unwrap();
    let lid = fan(&upper, v(3., 3., 0.3));
    chk.check_patch(&m, &upper, &lid, &checks()).unwrap();
    let hole = crate::patch::Hole::new(0, &m, upper.clone(), &crate::policy::Policy::default());
    let faces = crate::patch::apply_patch(&mut m, &hole, &lid).unwrap();
    // before the commit the faces are scanned as unseen, after it they are indexed
    let e1 = chk.check_patch(&m, &lower, &tall, &checks()).unwrap_err();
    chk.commit(&m, faces);
    let e2 = chk.check_patch(&m, &lower, &tall, &checks()).unwrap_err();
    assert_eq!(e1, e2);
    let CheckFailure::SelfIntersection {
        meets: Meets::MeshFace(f),
        ..
    } = e2
    else {
        panic!()
    };
    assert!(f >= m.num_faces() - 8);
}

#[test]
fn incremental_index_matches_a_fresh_one() {
    // the checker of the lower sheet alone, then the upper sheet's faces
    // committed in small batches (through the tail and several rebuilds)
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    let nb = raw.faces.len();
    grid(12, 0.3, 49, &[], &mut raw);
    let (m, _) = Mesh::from_raw(&raw);
    let lower_raw = RawMesh {
        positions: raw.positions.clone(),
        faces: raw.faces[..nb].to_vec(),
        ..Default::default()
    };
    let (m0, _) = Mesh::from_raw(&lower_raw);
    assert_eq!(m0.topo.faces(), &m.topo.faces()[..nb]);
    let hole = sheet_hole_at(&m, 0.0);
    let fresh = Checker::new(&m);
    let mut inc = Checker::new(&m0);
    inc.tail_max = 64;
    let mut f = nb;
    while f < m.num_faces() {
        let e = (f + 7).min(m.num_faces());
        inc.commit(&m, f..e);
        f = e;
    }
    // 288 faces in batches of 7: trees of 70 merged into 140, then 280, tail 8
    assert!(!inc.levels.is_empty() && !inc.tail.is_empty() && inc.tail.len() < inc.tail_max);
    let sizes: Vec<usize> = inc.levels.iter().map(|l| l.faces.len()).collect();
    assert!(sizes.windows(2).all(|w| w[0] > w[1]), "{sizes:?}");
    let total: usize = sizes.iter().sum::<usize>() + inc.tail.len();
    assert_eq!(total, m.num_faces() - nb);
    let mut all: Vec<u32> = inc.levels.iter().flat_map(|l| l.faces.clone()).collect();
    all.extend_from_slice(&inc.tail);
    all.sort_unstable();
    assert_eq!(all, (nb as u32..m.num_faces() as u32).collect::<Vec<_>>());
    for (apex, ok) in [
        (v(3., 3., 0.1), true),
        (v(3., 3., 1.), false),
        (v(2.5, 3.5, 0.5), false),
    ] {
        let p = fan(&hole, apex);
        let a = fresh.check_patch(&m, &hole, &p, &checks());
        let b = inc.check_patch(&m, &hole, &p, &checks());
        assert_eq!(a.is_ok(), ok);
        assert_eq!(a.is_ok(), b.is_ok());
    }
}

/// The checker finds the same failure whether it scans the face boxes or walks its
/// tree, and that failure is the canonical one (smallest failing patch triangle,
/// then the smallest patch triangle or mesh face it meets), as a brute force over
/// every pair finds it. After `SCANS_BEFORE_TREE` scans the tree is built.
#[test]
fn scan_and_tree_report_the_canonical_failure() {
    use rand::{Rng, SeedableRng};
    // a grid with a 2x2 hole, an upper sheet and a small tilted sheet crossing the
    // space above the hole
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    grid(6, 0.7, 49, &[], &mut raw);
    let b = raw.positions.len() as u32;
    raw.positions
        .extend([v(2.2, 2.2, 0.2), v(2.8, 2.2, 0.2), v(2.5, 2.8, 0.5)]);
    raw.faces.push([b, b + 1, b + 2]);
    let (m, _) = Mesh::from_raw(&raw);
    let hole = sheet_hole_at(&m, 0.0);
    let k = hole.len();
    let brute = |p: &Patch| -> Result<(), CheckFailure> {
        let pos = patch_positions(&m, &hole, p);
        let key = |i: u32| {
            if (i as usize) < k {
                vertex_key(&m, hole[i as usize])
            } else {
                NEW_KEY + (i as usize - k) as u64
            }
        };
        let tri = |t: &[u32; 3]| (t.map(|i| pos[i as usize]), t.map(key));
        for (i, t) in p.triangles.iter().enumerate() {
            let (a, ak) = tri(t);
            for (j, u) in p.triangles.iter().enumerate().skip(i + 1) {
                let (b, bk) = tri(u);
                if tri_tri(&a, &ak, &b, &bk) {
                    return Err(CheckFailure::SelfIntersection {
                        triangle: i,
                        meets: Meets::PatchTriangle(j),
                    });
                }
            }
        }
        for (i, t) in p.triangles.iter().enumerate() {
            let (a, ak) = tri(t);
            for f in 0..m.num_faces() {
                let (q, qk) = face_tri(&m, f).unwrap();
                if tri_tri(&a, &ak, &q, &qk) {
                    return Err(CheckFailure::SelfIntersection {
                        triangle: i,
                        meets: Meets::MeshFace(f),
                    });
                }
            }
        }
        Ok(())
    };
    let scan = Checker::new(&m);
    let tree = Checker::for_checks(&m, SCANS_BEFORE_TREE + 1);
    assert!(tree.base.get().is_none() && tree.boxes.get().is_none());
    tree.prepare(&m);
    assert!(tree.base.get().is_some());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut outcomes = [0usize; 3];
    for round in 0..SCANS_BEFORE_TREE + 20 {
        // two apexes: the fan splits the hole in two, so patch triangles can meet
        let centre = |r: std::ops::RangeInclusive<usize>| {
            let n = r.clone().count() as f64;
            r.map(|i| m.pos(hole[i % k])).sum::<DVec3>() / n
        };
        let mut jitter = |c: DVec3, s: f64| {
            c + v(
                rng.random_range(-s..s),
                rng.random_range(-s..s),
                rng.random_range(-0.4..0.9),
            )
        };
        let (mut a1, mut a2) = (
            jitter(centre(0..=k / 2), 0.6),
            jitter(centre(k / 2..=k), 0.6),
        );
        if round % 4 == 0 {
            // each fan over the other half: the patch folds over itself
            std::mem::swap(&mut a1, &mut a2);
            a2.z = a1.z + 0.3;
        }
        let mut p = Patch {
            new_vertices: vec![a1, a2],
            triangles: Vec::new(),
        };
        let (x, y) = (k as u32, k as u32 + 1);
        for i in 0..k as u32 {
            let j = (i + 1) % k as u32;
            p.triangles
                .push([i, j, if i < k as u32 / 2 { x } else { y }]);
        }
        let h = k as u32 / 2;
        p.triangles.push([x, h, y]);
        p.triangles.push([x, y, 0]);
        if check_topology(&m, &hole, &p).is_err() {
            continue;
        }
        let pos = patch_positions(&m, &hole, &p);
        let want = brute(&p);
        let got_scan = scan.check_intersections(&m, &hole, &p, &pos, true, None);
        let got_tree = tree.check_intersections(&m, &hole, &p, &pos, true, None);
        // with the nearby faces found once and given (as the flip repair does)
        let near = tree.faces_near(&m, &hole, &p);
        let got_near = tree.check_intersections(&m, &hole, &p, &pos, true, Some(&near));
        assert_eq!(got_scan, want, "round {round}");
        assert_eq!(got_tree, want, "round {round}");
        assert_eq!(got_near, want, "round {round}");
        outcomes[match &want {
            Ok(()) => 0,
            Err(CheckFailure::SelfIntersection {
                meets: Meets::PatchTriangle(_),
                ..
            }) => 1,
            Err(_) => 2,
        }] += 1;
    }
    assert!(outcomes.iter().all(|&n| n > 0), "{outcomes:?}");
    // the scanning checker built its tree once it had scanned enough
    assert!(scan.base.get().is_some());
}

/// [`PatchChecks`] (every failure recorded, changes re-tested incrementally)
/// reports what the whole check reports, on random two-apex fans over a hole
/// under obstacles: as made, after random edge flips (some kept), and with one
/// apex's triangles replaced by a fan over their ring (a vertex dropped, the
/// triangles renumbered).
#[test]
fn incremental_checks_report_what_the_whole_check_reports() {
    use rand::{Rng, SeedableRng};
    let mut raw = RawMesh::default();
    grid(6, 0.0, 0, &SHEET_HOLE, &mut raw);
    grid(6, 0.7, 49, &[], &mut raw);
    let b = raw.positions.len() as u32;
    raw.positions
        .extend([v(2.2, 2.2, 0.2), v(2.8, 2.2, 0.2), v(2.5, 2.8, 0.5)]);
    raw.faces.push([b, b + 1, b + 2]);
    let (m, _) = Mesh::from_raw(&raw);
    let hole = sheet_hole_at(&m, 0.0);
    let k = hole.len();
    let opts = checks();
    let checker = Checker::new(&m);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let (mut trials, mut kept, mut passed, mut failed) = (0usize, 0usize, 0usize, 0usize);
    for _ in 0..60 {
        let mut jitter = |s: f64| {
            v(
                2.5 + rng.random_range(-s..s),
                2.5 + rng.random_range(-s..s),
                rng.random_range(-0.4..0.9),
            )
        };
        let (a1, a2) = (jitter(0.9), jitter(0.9));
        let (x, y) = (k as u32, k as u32 + 1);
        let mut p = Patch {
            new_vertices: vec![a1, a2],
            triangles: Vec::new(),
        };
        for i in 0..k as u32 {
            let j = (i + 1) % k as u32;
            p.triangles
                .push([i, j, if i < k as u32 / 2 { x } else { y }]);
        }
        let h = k as u32 / 2;
        p.triangles.push([x, h, y]);
        p.triangles.push([x, y, 0]);
        let near = checker.faces_near(&m, &hole, &p);
        let mut st = PatchChecks::new(&m, &hole, p.clone(), &opts, &near).unwrap();
        assert_eq!(st.result(), checker.check_patch(&m, &hole, &p, &opts));
        // the ring of apex y's triangles, closed by a fan from its first vertex
        {
            let mut removed = Vec::new();
            let mut next = std::collections::HashMap::new();
            for (t, tri) in p.triangles.iter().enumerate() {
                if let Some(c) = tri.iter().position(|&w| w == y) {
                    removed.push(t);
                    next.insert(tri[(c + 1) % 3], tri[(c + 2) % 3]);
                }
            }
            let start = tri_start(&p, y);
            let mut ring = vec![start];
            while let Some(&n) = next.get(ring.last().unwrap()) {
                if n == start || ring.len() > next.len() {
                    break;
                }
                ring.push(n);
            }
            // from apex x (on the ring): the loop's vertices along a side of
            // the hole are collinear, a fan from one of them degenerate
            if let Some(at) = ring.iter().position(|&w| w == x) {
                ring.rotate_left(at);
            }
            let added: Vec<[u32; 3]> = (1..ring.len() - 1)
                .map(|i| [ring[0], ring[i], ring[i + 1]])
                .collect();
            let mut q = Patch {
                new_vertices: vec![a1],
                triangles: p
                    .triangles
                    .iter()
                    .enumerate()
                    .filter(|(t, _)| !removed.contains(t))
                    .map(|(_, t)| *t)
                    .collect(),
            };
            q.triangles.extend(&added);
            let got = st.replaced(&removed, &added, &q);
            assert_eq!(got, checker.check_patch(&m, &hole, &q, &opts));
            if got.is_ok() {
                passed += 1;
            } else {
                failed += 1;
            }
        }
        // random flips of interior edges
        for _ in 0..25 {
            let cur = st.patch().clone();
            let t = rng.random_range(0..cur.triangles.len());
            let c = rng.random_range(0..3);
            let tri = cur.triangles[t];
            let (a, b, cc) = (tri[c], tri[(c + 1) % 3], tri[(c + 2) % 3]);
            let Some(u) = cur
                .triangles
                .iter()
                .position(|o| (0..3).any(|e| o[e] == b && o[(e + 1) % 3] == a))
            else {
                continue;
            };
            let Some(&d) = cur.triangles[u].iter().find(|&&w| w != a && w != b) else {
                continue;
            };
            let (change, q, got) = st.trial(&[t, u], &[[a, d, cc], [b, cc, d]]);
            assert_eq!(got, checker.check_patch(&m, &hole, &q, &opts));
            trials += 1;
            if rng.random_bool(0.5) && st.apply(change) {
                kept += 1;
                assert_eq!(st.patch(), &q);
                assert_eq!(st.result(), checker.check_patch(&m, &hole, &q, &opts));
            }
        }
    }
    assert!(trials > 500 && kept > 100, "{trials} trials, {kept} kept");
    assert!(passed > 0 && failed > 0, "{passed} passed, {failed} failed");
}

/// A vertex of the triangle opposite `apex` in the first triangle using it.
fn tri_start(p: &Patch, apex: u32) -> u32 {
    p.triangles
        .iter()
        .find_map(|t| t.iter().position(|&w| w == apex).map(|c| t[(c + 1) % 3]))
        .unwrap()
}
