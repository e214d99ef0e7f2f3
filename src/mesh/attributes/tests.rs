use super::*;
use crate::io::attrs::Values;

/// A planar grid (n x n quads) with the faces of one inner square removed.
fn holed_grid(n: usize) -> RawMesh {
    let inner = n / 2 - 1..=n / 2;
    crate::testutil::cells_removed(crate::testutil::unit_grid(n), |i, j| {
        inner.contains(&i) && inner.contains(&j)
    })
}

#[test]
fn harmonic_solve_reproduces_a_linear_field_on_a_plane() {
    let raw = holed_grid(6);
    let (mut mesh, _) = Mesh::from_raw(&raw);
    // fill the hole with a centre vertex
    let loops = mesh.topo.boundary_loops();
    let inner = loops
        .iter()
        .find(|l| l.len() == 8)
        .cloned()
        .unwrap_or_default();
    let c = mesh.add_vertex(DVec3::new(3.0, 3.0, 0.0), None);
    let k = inner.len();
    let tris: Vec<[VertexId; 3]> = (0..k).map(|i| [inner[i], inner[(i + 1) % k], c]).collect();
    mesh.add_faces(&tris).unwrap();
    mesh.validate().unwrap();
    let field = |p: DVec3| [2.0 * p.x - 0.5 * p.y + 1.0];
    let vals = solve(&mesh, &[c], Weights::Cotan, &|v: VertexId| {
        (v != c).then(|| field(mesh.pos(v)))
    });
    assert!(
        (vals[0][0] - field(DVec3::new(3.0, 3.0, 0.0))[0]).abs() < 1e-9,
        "{vals:?}"
    );
}

#[test]
fn input_elements_keep_their_values_through_a_rebuild() {
    let mut raw = holed_grid(4);
    let nv = raw.positions.len();
    let nf = raw.faces.len();
    raw.attrs.vertex.push(Property {
        name: "quality".into(),
        data: PropData::Scalar(Values::F32((0..nv).map(|i| i as f32 * 0.1).collect())),
    });
    raw.attrs.face.push(Property {
        name: "label".into(),
        data: PropData::Scalar(Values::U8((0..nf).map(|i| (i % 7) as u8).collect())),
    });
    // reverse one face's orientation: the builder flips it back
    raw.faces[3].swap(0, 1);
    let (mesh, _) = Mesh::from_raw(&raw);
    mesh.validate().unwrap();
    let (out, rep) = carry(&mesh, &raw);
    assert!(rep.read.iter().any(|r| r.contains("quality")));
    crate::io::attrs::check(&out).unwrap();
    assert_eq!(out.attrs.vertex[0].data, raw.attrs.vertex[0].data);
    assert_eq!(out.attrs.face[0].data, raw.attrs.face[0].data);
    let ty = match &out.attrs.face[0].data {
        PropData::Scalar(v) => v.ty(),
        _ => ScalarType::F64,
    };
    assert_eq!(ty, ScalarType::U8);
}
