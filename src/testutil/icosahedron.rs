//! The icosphere's construction in plain arrays, shared by the unit tests' fixtures
//! (`crate::testutil`) and the integration tests' (`tests/common/shapes.rs`, which
//! includes this file by `#[path]`); each wraps it in its own mesh type.

/// The vertices and faces (outward) of an icosphere: the icosahedron, then `level`
/// times every face split in four at its edges' midpoints. `unit` puts a point on the
/// unit sphere (each side keeps its own rounding of it).
pub fn icosphere(
    level: usize,
    unit: impl Fn([f64; 3]) -> [f64; 3],
) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v: Vec<[f64; 3]> = [
        [-1., t, 0.],
        [1., t, 0.],
        [-1., -t, 0.],
        [1., -t, 0.],
        [0., -1., t],
        [0., 1., t],
        [0., -1., -t],
        [0., 1., -t],
        [t, 0., -1.],
        [t, 0., 1.],
        [-t, 0., -1.],
        [-t, 0., 1.],
    ]
    .into_iter()
    .map(&unit)
    .collect();
    let mut f: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid: std::collections::HashMap<(usize, usize), usize> = Default::default();
        let mut nf = Vec::with_capacity(f.len() * 4);
        for &[a, b, c] in &f {
            let mut m = |a: usize, b: usize| -> usize {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    v.push(unit([0, 1, 2].map(|k| (v[a][k] + v[b][k]) / 2.0)));
                    v.len() - 1
                })
            };
            let ab = m(a, b);
            let bc = m(b, c);
            let ca = m(c, a);
            nf.push([a, ab, ca]);
            nf.push([b, bc, ab]);
            nf.push([c, ca, bc]);
            nf.push([ab, bc, ca]);
        }
        f = nf;
    }
    (v, f)
}
