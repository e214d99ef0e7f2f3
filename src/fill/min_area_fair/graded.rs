//! A graded patch for a huge hole: Delaunay refinement of the projected loop.
//!
//! Not in paper 002, whose holes are small: its §5.2 refinement (centroid splits to the
//! density of the surrounding mesh, after Liepa 2003) would put some k²/5 triangles
//! into a round hole of k boundary vertices. Beyond `limits.max_patch_triangles` the
//! patch must be coarser inside than along its loop, and the centroid splits of a
//! minimum-area triangulation cannot make that transition well: a triangulation of a
//! round 10,000-gon is 10,000 slivers, and splitting them to a coarse density leaves
//! long thin triangles along the loop, which the fairing then folds (measured: 1,385
//! triangles under 0.5 degrees on a flat round hole of 10,000 vertices).
//!
//! Here the loop is projected on its best-fit (Newell) plane and, when the projection
//! is a simple polygon, meshed by Delaunay refinement (Ruppert 1995, "A Delaunay
//! refinement algorithm for quality 2-dimensional mesh generation", J. Algorithms 18;
//! Shewchuk 2002, "Delaunay refinement algorithms for triangular mesh generation",
//! via spade's `refine`): circumcentres of triangles with an angle under
//! [`GradedParams::angle_deg`] or an area over [`GradedParams::max_area`] are inserted
//! until none is left. The loop edges are constraints that are never split (the patch
//! must close the hole with exactly its loop vertices). Ruppert's refinement grades by
//! itself: triangles grow from the loop's spacing to the area bound inside, and the
//! size of the graded band is proportional to the loop (about 3 triangles per loop
//! vertex), so the patch stays near its budget whatever the hole.
//!
//! Reading of the vague parts (this is our construction, checked on flat, spherical,
//! cylindrical and saddle-shaped holes, see the tests): the new vertices start on the
//! membrane the loop spans over its plane (the harmonic extension of the loop's
//! heights, with the cotangent weights of the flat, Delaunay layout, where they are
//! non-negative), and the caller fairs them (paper 002 §5.2, step 3) with weights taken
//! on that layout. A flat hole keeps its layout exactly (linear precision); a loop that
//! rises and falls around the hole (a saddle, whose height x² - y² is harmonic) starts
//! on its surface, so that the fairing's weights agree with those of the mesh around
//! it, instead of dragging vertices across the plane into folds.
//! A chord between two loop vertices that is already a mesh edge must not appear in
//! the patch; each such chord left by the refinement is split at its midpoint.

use crate::fasthash::HashSet;
use crate::fill::kit::FillError;
use crate::geometry::measure;
use glam::DVec3;
use spade::handles::{FixedFaceHandle, FixedVertexHandle, InnerTag};
use spade::{
    AngleLimit, ConstrainedDelaunayTriangulation, Point2, RefinementParameters, Triangulation,
};

/// Parameters of the refinement.
#[derive(Clone, Copy, Debug)]
pub struct GradedParams {
    /// Largest triangle area in the plane of the loop.
    pub max_area: f64,
    /// Smallest angle the refinement aims at, degrees (Ruppert: up to about 30).
    pub angle_deg: f64,
    /// Most new vertices the refinement may insert.
    pub max_new_vertices: usize,
}

/// A patch over the loop: new vertices (patch index `k + i`) and triangles oriented
/// like the hole.
#[derive(Clone, Debug, Default)]
pub struct GradedPatch {
    pub new_vertices: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

type Cdt = ConstrainedDelaunayTriangulation<Point2<f64>>;

/// The projection of the loop on its Newell plane: origin, axes, 2D points, and
/// whether the loop runs counter-clockwise there (`None`: no plane).
fn project(pts: &[DVec3]) -> Option<(DVec3, DVec3, DVec3, Vec<Point2<f64>>)> {
    let n = measure::newell_normal(pts);
    if n == DVec3::ZERO {
        return None;
    }
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    let c = measure::centroid(pts);
    let p2: Vec<Point2<f64>> = pts
        .iter()
        .map(|&p| Point2::new((p - c).dot(u), (p - c).dot(v)))
        .collect();
    if p2.iter().any(|p| !p.x.is_finite() || !p.y.is_finite()) {
        return None;
    }
    Some((c, u, v, p2))
}

/// The faces inside the loop (flood fill from the inner side of every loop edge,
/// stopped by the constraint edges); `None` when the fill reaches the outside (the
/// projected loop is not simple) or a loop edge is missing.
fn inner_faces(cdt: &Cdt, k: usize, ccw: bool) -> Option<Vec<FixedFaceHandle<InnerTag>>> {
    let vh = FixedVertexHandle::from_index;
    let mut inside = vec![false; cdt.num_all_faces()];
    let mut out = Vec::new();
    for i in 0..k {
        let e = cdt.get_edge_from_neighbors(vh(i), vh((i + 1) % k))?;
        if !e.is_constraint_edge() {
            return None;
        }
        let e = if ccw { e } else { e.rev() };
        let f = e.face().as_inner()?.fix();
        if !inside[f.index()] {
            inside[f.index()] = true;
            out.push(f);
        }
    }
    let mut next = 0;
    while next < out.len() {
        let f = out[next];
        next += 1;
        for e in cdt.face(f).adjacent_edges() {
            if e.is_constraint_edge() {
                continue;
            }
            let g = e.rev().face().as_inner()?.fix();
            if !inside[g.index()] {
                inside[g.index()] = true;
                out.push(g);
            }
        }
    }
    out.sort_unstable_by_key(|f| f.index());
    Some(out)
}

/// Meshes the loop `pts` (hole order) by constrained Delaunay refinement of its
/// projection. `forbidden` holds the loop chords `(a, b)`, `a < b`, that are mesh
/// edges. `Ok(None)` when the method does not apply (no plane, the projected loop is
/// not simple, two loop vertices project to one point, or the refinement fails);
/// the caller then uses the minimum-area triangulation and its refinement.
pub fn graded(
    pts: &[DVec3],
    forbidden: &HashSet<(u32, u32)>,
    params: GradedParams,
) -> Result<Option<GradedPatch>, FillError> {
    let k = pts.len();
    if k < 3 || params.max_area.is_nan() || params.max_area <= 0.0 || !params.max_area.is_finite() {
        return Ok(None);
    }
    let Some((c, u, v, p2)) = project(pts) else {
        return Ok(None);
    };
    let mut signed = 0.0;
    for i in 0..k {
        let (a, b) = (p2[i], p2[(i + 1) % k]);
        signed += a.x * b.y - b.x * a.y;
    }
    if signed.is_nan() || signed == 0.0 {
        return Ok(None);
    }
    let ccw = signed > 0.0;
    let edges: Vec<[usize; 2]> = (0..k).map(|i| [i, (i + 1) % k]).collect();
    let mut conflict = false;
    let Ok(mut cdt) = Cdt::try_bulk_load_cdt(p2.clone(), edges, |_| conflict = true) else {
        return Ok(None);
    };
    if conflict || cdt.num_vertices() != k || cdt.num_constraints() != k {
        return Ok(None);
    }
    // bulk loading keeps the vertex order: vertex i is loop vertex i
    if (0..k).any(|i| cdt.vertex(FixedVertexHandle::from_index(i)).position() != p2[i]) {
        return Ok(None);
    }
    // the shortest loop edge bounds the smallest triangle worth refining: a skinny
    // triangle smaller than a fifth of an equilateral one on it is left as it is
    // (it sits in a sharp corner of the loop, which no refinement can widen)
    let shortest = (0..k)
        .map(|i| {
            let (a, b) = (p2[i], p2[(i + 1) % k]);
            ((a.x - b.x).powi(2) + (a.y - b.y).powi(2)).sqrt()
        })
        .fold(f64::INFINITY, f64::min);
    let min_area = 0.2 * 0.75f64.sqrt() / 2.0 * shortest * shortest;
    let refine = RefinementParameters::<f64>::new()
        .exclude_outer_faces(true)
        .keep_constraint_edges()
        .with_angle_limit(AngleLimit::from_deg(params.angle_deg))
        .with_max_allowed_area(params.max_area)
        .with_min_required_area(min_area.min(params.max_area / 4.0))
        .with_max_additional_vertices(params.max_new_vertices);
    // spade panics when a circumcentre cannot be inserted (loss of precision)
    let refined = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let r = cdt.refine(refine);
        (cdt, r.refinement_complete)
    }));
    let Ok((mut cdt, complete)) = refined else {
        return Ok(None);
    };
    if !complete {
        return Ok(None);
    }
    // split the forbidden chords the refinement left (a few rounds: a split can leave
    // another forbidden chord only through a new vertex, which is not a loop vertex)
    let mut faces = None;
    for _ in 0..8 {
        let Some(fs) = inner_faces(&cdt, k, ccw) else {
            return Ok(None);
        };
        let mut split = Vec::new();
        for &f in &fs {
            for e in cdt.face(f).adjacent_edges() {
                let (a, b) = (e.from().fix().index(), e.to().fix().index());
                if a < k && b < k && a < b && forbidden.contains(&(a as u32, b as u32)) {
                    let [pa, pb] = [e.from().position(), e.to().position()];
                    split.push(Point2::new((pa.x + pb.x) / 2.0, (pa.y + pb.y) / 2.0));
                }
            }
        }
        if split.is_empty() {
            faces = Some(fs);
            break;
        }
        for p in split {
            if cdt.insert(p).is_err() {
                return Ok(None);
            }
        }
    }
    let Some(faces) = faces else {
        return Ok(None);
    };
    // patch index of each triangulation vertex (loop vertex i is i; new vertices are
    // numbered in the order the faces meet them)
    let mut index = vec![u32::MAX; cdt.num_vertices()];
    let mut flat = p2;
    let mut out = GradedPatch::default();
    for f in faces {
        let vs = cdt.face(f).vertices();
        let mut t = [0u32; 3];
        for (corner, vh) in vs.iter().enumerate() {
            let i = vh.fix().index();
            t[corner] = if i < k {
                i as u32
            } else {
                if index[i] == u32::MAX {
                    flat.push(vh.position());
                    index[i] = (flat.len() - 1) as u32;
                }
                index[i]
            };
        }
        if !ccw {
            t.swap(1, 2);
        }
        out.triangles.push(t);
    }
    // the new vertices start on the membrane the loop spans over its plane
    let n = u.cross(v);
    let heights: Vec<f64> = pts.iter().map(|&p| (p - c).dot(n)).collect();
    let lift =
        harmonic(&flat, &out.triangles, &heights).unwrap_or_else(|| vec![0.0; flat.len() - k]);
    out.new_vertices = flat[k..]
        .iter()
        .zip(&lift)
        .map(|(p, &h)| c + u * p.x + v * p.y + n * h)
        .collect();
    Ok(Some(out))
}

/// Weight added to every edge of [`harmonic`]'s Laplacian, relative to a cotangent
/// weight of order 1: keeps the system positive definite when an edge's cotangents
/// sum to a negative value (set to zero) without changing the result measurably.
const HARMONIC_EPS: f64 = 1e-9;

/// The harmonic extension of `values` (one per loop vertex, the first `values.len()`
/// vertices of `flat`) to the other vertices of the planar triangulation `tris` over
/// `flat`: cotangent weights of the flat layout (negative edge sums set to zero),
/// Dirichlet values at the loop, sparse Cholesky. `None` when the solve fails.
fn harmonic(flat: &[Point2<f64>], tris: &[[u32; 3]], values: &[f64]) -> Option<Vec<f64>> {
    use faer::sparse::{SparseColMat, Triplet};
    let k = values.len();
    let m = flat.len().checked_sub(k)?;
    if m == 0 {
        return Some(Vec::new());
    }
    // cotangent of the angle at each corner, on the edge across it
    let mut edges: Vec<((u32, u32), f64)> = Vec::with_capacity(3 * tris.len());
    for t in tris {
        for corner in 0..3 {
            let (o, a, b) = (t[corner], t[(corner + 1) % 3], t[(corner + 2) % 3]);
            let [po, pa, pb] = [o, a, b].map(|i| flat[i as usize]);
            let (ux, uy, vx, vy) = (pa.x - po.x, pa.y - po.y, pb.x - po.x, pb.y - po.y);
            let cross = (ux * vy - uy * vx).abs();
            let cot = if cross > 0.0 {
                (ux * vx + uy * vy) / cross
            } else {
                0.0
            };
            edges.push(((a.min(b), a.max(b)), 0.5 * cot.clamp(-1e3, 1e3)));
        }
    }
    edges.sort_by_key(|e| e.0);
    let mut entries: Vec<Triplet<usize, usize, f64>> = Vec::with_capacity(4 * edges.len() / 2);
    let mut rhs = faer::Mat::<f64>::zeros(m, 1);
    let mut e = 0;
    while e < edges.len() {
        let key = edges[e].0;
        let mut w = 0.0;
        while e < edges.len() && edges[e].0 == key {
            w += edges[e].1;
            e += 1;
        }
        let w = w.max(0.0) + HARMONIC_EPS;
        let (a, b) = (key.0 as usize, key.1 as usize);
        for (i, j) in [(a, b), (b, a)] {
            if i < k {
                continue;
            }
            entries.push(Triplet::new(i - k, i - k, w));
            if j < k {
                rhs[(i - k, 0)] += w * values[j];
            } else {
                entries.push(Triplet::new(i - k, j - k, -w));
            }
        }
    }
    let mat = SparseColMat::<usize, f64>::try_new_from_triplets(m, m, &entries).ok()?;
    let llt = mat.sp_cholesky(faer::Side::Lower).ok()?;
    use faer::linalg::solvers::Solve;
    let x = llt.solve(rhs.as_ref());
    let out: Vec<f64> = (0..m).map(|i| x[(i, 0)]).collect();
    out.iter().all(|h| h.is_finite()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn circle(k: usize, r: f64) -> Vec<DVec3> {
        (0..k)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / k as f64;
                DVec3::new(r * t.cos(), r * t.sin(), 0.0)
            })
            .collect()
    }

    fn params(max_area: f64) -> GradedParams {
        GradedParams {
            max_area,
            angle_deg: 20.0,
            max_new_vertices: 100_000,
        }
    }

    fn pos(pts: &[DVec3], g: &GradedPatch, i: u32) -> DVec3 {
        let i = i as usize;
        if i < pts.len() {
            pts[i]
        } else {
            g.new_vertices[i - pts.len()]
        }
    }

    /// Every loop edge is used once, in the loop's direction; every other edge twice,
    /// once each way (an oriented disk).
    fn assert_oriented_disk(k: usize, g: &GradedPatch) {
        let mut dir: HashMap<(u32, u32), usize> = HashMap::new();
        for t in &g.triangles {
            assert!(t[0] != t[1] && t[1] != t[2] && t[0] != t[2], "{t:?}");
            for c in 0..3 {
                *dir.entry((t[c], t[(c + 1) % 3])).or_default() += 1;
            }
        }
        assert!(
            dir.values().all(|&n| n == 1),
            "an edge is used twice the same way"
        );
        for i in 0..k as u32 {
            let j = (i + 1) % k as u32;
            assert!(dir.contains_key(&(i, j)), "loop edge {i}-{j} missing");
            assert!(!dir.contains_key(&(j, i)), "loop edge {i}-{j} reversed");
        }
        for &(a, b) in dir.keys() {
            let on_loop = (a as usize) < k
                && (b as usize) < k
                && ((a + 1) % k as u32 == b || (b + 1) % k as u32 == a);
            if !on_loop {
                assert!(dir.contains_key(&(b, a)), "inner edge {a}-{b} has one side");
            }
        }
        // Euler characteristic of a disk
        let v = k + g.new_vertices.len();
        let e = dir.len() - (dir.len() - k) / 2;
        assert_eq!(v as i64 - e as i64 + g.triangles.len() as i64, 1);
    }

    #[test]
    fn round_loop_gets_a_graded_mesh_of_good_angles() {
        let k = 2000;
        let pts = circle(k, 1.0);
        let area = std::f64::consts::PI;
        let g = graded(&pts, &HashSet::default(), params(area / 200.0))
            .unwrap()
            .expect("a circle projects to a simple polygon");
        assert_oriented_disk(k, &g);
        let mut total = 0.0;
        let mut worst = f64::INFINITY;
        for t in &g.triangles {
            let [a, b, c] = t.map(|i| pos(&pts, &g, i));
            let n = (b - a).cross(c - a);
            // the loop runs counter-clockwise about +z: so do the triangles
            assert!(n.z > 0.0, "{t:?} is flipped");
            total += 0.5 * n.length();
            worst = worst.min(
                measure::angles(a, b, c)
                    .into_iter()
                    .fold(f64::INFINITY, f64::min),
            );
        }
        let polygon = measure::vector_area(&pts);
        assert!(
            (total - polygon).abs() < 1e-9 * polygon,
            "{total} vs {polygon}"
        );
        assert!(
            worst.to_degrees() > 15.0,
            "smallest angle {}",
            worst.to_degrees()
        );
        assert!(g
            .new_vertices
            .iter()
            .all(|p| p.z == 0.0 && p.length() < 1.0));
        // graded: a uniform mesh at the loop's spacing would have about
        // area / (0.43 h²) = 1.2 million triangles; this one has about 3 per loop
        // vertex plus the interior's area bound
        assert!(
            g.triangles.len() < 3 * k + 2 * 200,
            "{} triangles",
            g.triangles.len()
        );
        assert!(g.triangles.len() > k);
    }

    #[test]
    fn new_vertices_start_on_the_membrane_of_the_loop() {
        // a loop on the saddle z = (x² - y²) / 2: its height is harmonic, so the
        // membrane over the unit disk is the saddle itself (up to the discretisation)
        let k = 400;
        let f = |x: f64, y: f64| 0.5 * (x * x - y * y);
        let pts: Vec<DVec3> = circle(k, 1.0)
            .into_iter()
            .map(|p| DVec3::new(p.x, p.y, f(p.x, p.y)))
            .collect();
        let g = graded(&pts, &HashSet::default(), params(0.002))
            .unwrap()
            .expect("simple");
        assert_oriented_disk(k, &g);
        assert!(g.new_vertices.len() > 100);
        let worst = g
            .new_vertices
            .iter()
            .map(|p| (p.z - f(p.x, p.y)).abs())
            .fold(0.0f64, f64::max);
        assert!(worst < 0.005, "{worst} off the saddle (heights up to 0.5)");
        // a loop on a tilted plane: the membrane is the plane, exactly up to rounding
        let tilt: Vec<DVec3> = circle(k, 1.0)
            .into_iter()
            .map(|p| DVec3::new(p.x, p.y, 0.3 * p.x - 0.2 * p.y))
            .collect();
        let g = graded(&tilt, &HashSet::default(), params(0.01))
            .unwrap()
            .expect("simple");
        for p in &g.new_vertices {
            assert!((p.z - (0.3 * p.x - 0.2 * p.y)).abs() < 1e-9, "{p}");
        }
    }

    #[test]
    fn clockwise_loop_keeps_its_orientation() {
        let k = 300;
        let mut pts = circle(k, 1.0);
        pts.reverse();
        let g = graded(&pts, &HashSet::default(), params(0.05))
            .unwrap()
            .expect("simple");
        assert_oriented_disk(k, &g);
        for t in &g.triangles {
            let [a, b, c] = t.map(|i| pos(&pts, &g, i));
            assert!((b - a).cross(c - a).z < 0.0);
        }
    }

    #[test]
    fn forbidden_chords_are_split() {
        // a square: any triangulation without new vertices uses one diagonal
        let pts = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
            DVec3::new(0.0, 1.0, 0.0),
        ];
        let forbidden: HashSet<(u32, u32)> = [(0, 2), (1, 3)].into_iter().collect();
        let g = graded(&pts, &forbidden, params(10.0))
            .unwrap()
            .expect("simple");
        assert_oriented_disk(4, &g);
        assert!(!g.new_vertices.is_empty());
        for t in &g.triangles {
            for c in 0..3 {
                let (a, b) = (t[c].min(t[(c + 1) % 3]), t[c].max(t[(c + 1) % 3]));
                assert!(!forbidden.contains(&(a, b)), "chord {a}-{b} used");
            }
        }
        // without the rule a diagonal is used
        let g = graded(&pts, &HashSet::default(), params(10.0))
            .unwrap()
            .expect("simple");
        assert_eq!(g.triangles.len(), 2);
        assert!(g.new_vertices.is_empty());
    }

    #[test]
    fn loops_without_a_simple_projection_are_declined() {
        // a figure eight in the plane with lobes of unequal size (so its best-fit
        // plane is the plane): its projection crosses itself
        let k = 200;
        let eight: Vec<DVec3> = (0..k)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / k as f64;
                let s = if t < std::f64::consts::PI { 1.0 } else { 0.5 };
                DVec3::new(s * t.sin(), s * (2.0 * t).sin() / 2.0, 0.0)
            })
            .collect();
        assert!(measure::newell_normal(&eight).z.abs() > 0.99);
        assert!(graded(&eight, &HashSet::default(), params(0.01))
            .unwrap()
            .is_none());
        // collinear points have no plane
        let line: Vec<DVec3> = (0..10).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect();
        assert!(graded(&line, &HashSet::default(), params(0.01))
            .unwrap()
            .is_none());
        // a helix of two turns projects onto itself twice
        let helix: Vec<DVec3> = (0..k)
            .map(|i| {
                let t = 2.0 * std::f64::consts::TAU * i as f64 / k as f64;
                DVec3::new(
                    t.cos(),
                    t.sin(),
                    0.3 * (t - 2.0 * std::f64::consts::PI).abs(),
                )
            })
            .collect();
        assert!(graded(&helix, &HashSet::default(), params(0.01))
            .unwrap()
            .is_none());
        // no area bound
        assert!(graded(&circle(20, 1.0), &HashSet::default(), params(0.0))
            .unwrap()
            .is_none());
        assert!(
            graded(&circle(20, 1.0), &HashSet::default(), params(f64::NAN))
                .unwrap()
                .is_none()
        );
    }
}
