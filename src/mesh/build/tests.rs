use super::*;
use glam::DVec3;

fn soup(pos: &[[f64; 3]], faces: &[[u32; 3]]) -> RawMesh {
    RawMesh {
        positions: pos.iter().map(|p| DVec3::from_array(*p)).collect(),
        faces: faces.to_vec(),
        ..Default::default()
    }
}

#[test]
fn resolves_degenerate_duplicate_and_flipped_faces() {
    let raw = soup(
        &[
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 1., 0.],
            [2., 0., 0.],
        ],
        &[
            [0, 1, 2],
            [0, 2, 3],
            [2, 1, 0], // duplicate (other orientation)
            [0, 0, 1], // repeated index
            [0, 1, 4], // collinear
            [1, 3, 2], // wrong orientation? shares 1-2 ... with same direction as face 0? no
            [0, 1, 9], // out of range
        ],
    );
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert_eq!(rep.duplicate_faces, 0);
    assert_eq!(rep.opposite_faces, 1);
    assert_eq!(rep.repeated_index_faces, 1);
    assert_eq!(rep.zero_area_faces, 1);
    assert_eq!(rep.out_of_range_faces, 1);
    assert_eq!(rep.isolated_vertices, 1);
}

#[test]
fn flips_an_inconsistent_face() {
    // faces 0 and 1 share edge 0-2 wound the same way; face 2 agrees with face 0
    let raw = soup(
        &[
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 1., 0.],
            [0.5, -1., 0.],
        ],
        &[[0, 1, 2], [0, 3, 2], [1, 0, 4]],
    );
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert_eq!(rep.flipped_faces, 1);
    assert_eq!(
        m.topo.face(crate::mesh::FaceId(1)),
        [VertexId(0), VertexId(2), VertexId(3)]
    );
    assert_eq!(m.topo.boundary_loops().len(), 1);
}

#[test]
fn splits_bowtie_vertex_and_non_manifold_edge() {
    // two triangles touching at vertex 0 only
    let raw = soup(
        &[
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [-1., 0., 0.],
            [-1., -1., 0.],
        ],
        &[[0, 1, 2], [0, 3, 4]],
    );
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert_eq!(rep.non_manifold_vertices, 1);
    assert_eq!(m.num_vertices(), 6);
    assert_eq!(m.origin[5], Some(VertexId(0)));
    assert_eq!(m.topo.boundary_loops().len(), 2);

    // three triangles on edge 0-1
    let raw = soup(
        &[
            [0., 0., 0.],
            [1., 0., 0.],
            [0.5, 1., 0.],
            [0.5, -1., 0.],
            [0.5, 0., 1.],
        ],
        &[[0, 1, 2], [1, 0, 3], [0, 1, 4]],
    );
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert_eq!(rep.non_manifold_edges, 1);
}

/// The number of boundary loops.
fn boundary_loop_count(m: &Mesh) -> usize {
    m.topo.boundary_loops().len()
}

#[test]
fn duplicate_and_opposite_faces_of_a_closed_sphere_leave_it_closed() {
    let mut raw = crate::testutil::icosphere(2, 1.0);
    let n = raw.faces.len();
    let [a, b, c] = raw.faces[7];
    raw.faces.push([b, c, a]); // the same face, rotated
    let [a, b, c] = raw.faces[30];
    raw.faces.push([a, c, b]); // the opposite face
    raw.faces.push([a, c, b]); // twice
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert_eq!(rep.duplicate_faces, 1);
    assert_eq!(rep.opposite_faces, 2);
    assert_eq!(m.num_faces(), n);
    assert_eq!(boundary_loop_count(&m), 0);
    assert_eq!(m.num_vertices(), raw.positions.len());
}

#[test]
fn a_two_sided_fin_on_a_whole_surface_is_dropped() {
    // triangle a b c split at its centre v, one face outside each edge; the fin is
    // a b c and c b a over the three inner edges
    let raw = soup(
        &[
            [0., 0., 0.],
            [2., 0., 0.],
            [1., 2., 0.],
            [1., 0.7, 0.],
            [1., -1., 0.],
            [2.5, 1.5, 0.],
            [-0.5, 1.5, 0.],
        ],
        &[
            [0, 1, 3],
            [1, 2, 3],
            [2, 0, 3],
            [1, 0, 4],
            [2, 1, 5],
            [0, 2, 6],
            [0, 1, 2],
            [0, 2, 1],
        ],
    );
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert_eq!(rep.opposite_faces, 2);
    assert_eq!(rep.non_manifold_edges, 0);
    assert_eq!(m.num_faces(), 6);
    assert_eq!(m.num_vertices(), 7);
}

#[test]
fn a_folded_quad_takes_its_other_diagonal() {
    // quad 0-1-2-3 and, folded back onto it, quad 0-3-2-4 (three shared vertices,
    // opposite orientation); fanned as the reader does
    let raw = soup(
        &[
            [0., 0., 0.],
            [1., 0., 0.],
            [1., 1., 0.],
            [0., 1., 0.],
            [0.5, 0.5, 0.2],
        ],
        &[[0, 1, 2], [0, 2, 3], [0, 3, 2], [0, 2, 4]],
    );
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert_eq!(rep.quads_rediagonalized, 1);
    assert_eq!(rep.opposite_faces + rep.duplicate_faces, 0);
    assert_eq!(m.num_faces(), 4);
    assert_eq!(rep.detached_faces, 0);
    // the second quad is now 3-2-4, 3-4-0
    let f: Vec<[u32; 3]> = m.topo.faces().iter().map(|f| f.map(|v| v.0)).collect();
    assert!(f.contains(&[3, 2, 4]) && f.contains(&[3, 4, 0]), "{f:?}");
}

/// A flat grid with `extra` flaps hinged on one interior edge (4 to 6 faces on it).
fn grid_with_fan(extra: usize, connected: bool) -> RawMesh {
    let mut raw = crate::testutil::unit_grid(4);
    // the interior edge 6-12 of the 5x5 vertex grid (the diagonal of cell (1,1))
    let (u, w) = (6u32, 12u32);
    for k in 0..extra {
        let t = k as f64 + 1.0;
        let p = DVec3::new(1.5 + 0.1 * t, 1.5 - 0.1 * t, 0.3 * t);
        raw.positions.push(p);
        let x = raw.positions.len() as u32 - 1;
        raw.faces
            .push(if k % 2 == 0 { [u, w, x] } else { [w, u, x] });
        if connected && k > 0 {
            // the flaps also share an edge with each other through the tip
            raw.faces.push([x - 1, x, w]);
        }
    }
    raw
}

#[test]
fn fans_of_four_to_six_faces_on_one_edge_are_resolved() {
    for extra in 2..=4 {
        for connected in [false, true] {
            let raw = grid_with_fan(extra, connected);
            let (m, rep) = Mesh::from_raw(&raw);
            m.validate()
                .unwrap_or_else(|e| panic!("{extra} flaps, {connected}: {e}"));
            assert!(rep.non_manifold_edges >= 1, "{rep:?}");
            // the grid keeps its input vertex ids and positions
            for i in 0..raw.positions.len() {
                assert_eq!(m.positions[i], raw.positions[i]);
            }
            // the grid's own two faces on the edge stay paired
            assert_eq!(m.num_faces(), raw.faces.len());
        }
    }
}

#[test]
fn a_pinched_boundary_vertex_is_split() {
    // a grid with two holes touching at vertex 12 (cells (1,1) and (2,2))
    let raw = crate::testutil::cells_removed(crate::testutil::unit_grid(4), |i, j| {
        [(1, 1), (2, 2)].contains(&(i, j))
    });
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert_eq!(rep.non_manifold_vertices, 1);
    assert_eq!(rep.vertices_added_by_split, 1);
    assert_eq!(m.origin[25], Some(VertexId(12)));
    assert_eq!(m.positions[25], m.positions[12]);
    // the outer border, and the two holes as one loop through the vertex and its
    // copy (the walk passes from one hole to the other at the pinch)
    assert_eq!(boundary_loop_count(&m), 2);
}

#[test]
fn inconsistent_orientation_and_unreferenced_vertices() {
    let mut raw = crate::testutil::icosphere(2, 1.0);
    for (i, f) in raw.faces.iter_mut().enumerate() {
        if i % 7 == 3 {
            f.swap(1, 2);
        }
    }
    raw.positions.push(DVec3::new(5.0, 5.0, 5.0));
    let (m, rep) = Mesh::from_raw(&raw);
    m.validate().unwrap();
    assert!(rep.flipped_faces > 0);
    assert_eq!(rep.isolated_vertices, 1);
    assert_eq!(boundary_loop_count(&m), 0);
    // every face now points outwards, as most of them did
    for f in 0..m.num_faces() {
        let fid = crate::mesh::FaceId::from_idx(f);
        let [a, b, c] = m.tri(fid);
        assert!(m.face_normal_raw(fid).dot(a + b + c) > 0.0);
    }
}

proptest::proptest! {
    /// Any soup of in-range faces gives a valid mesh whose first vertices are
    /// the input's, unmoved.
    #[test]
    fn any_soup_gives_a_valid_mesh(
        pts in proptest::collection::vec((0u8..4, 0u8..4, 0u8..3), 4..14),
        faces in proptest::collection::vec((0usize..14, 0usize..14, 0usize..14), 1..40),
    ) {
        let positions: Vec<DVec3> = pts
            .iter()
            .map(|&(x, y, z)| DVec3::new(x as f64, y as f64, z as f64 * 0.5))
            .collect();
        let n = positions.len();
        let faces: Vec<[u32; 3]> = faces
            .iter()
            .map(|&(a, b, c)| [(a % n) as u32, (b % n) as u32, (c % n) as u32])
            .collect();
        let raw = RawMesh { positions, faces, ..Default::default() };
        let (m, _) = Mesh::from_raw(&raw);
        proptest::prop_assert!(m.validate().is_ok(), "{:?}", m.validate());
        for i in 0..n {
            proptest::prop_assert_eq!(m.positions[i], raw.positions[i]);
        }
        for (i, o) in m.origin.iter().enumerate() {
            let src = o.map(|v| v.idx());
            proptest::prop_assert!(src.is_some_and(|s| s < n && m.positions[s] == m.positions[i]));
        }
    }
}
