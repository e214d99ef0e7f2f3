//! The front's overlap test (the exact triangle-triangle test of
//! [`crate::geometry::predicates`] on shrunk triangles) and a set of triangles with a
//! [`Grid`] over them, used to keep the front from creating a triangle that overlaps the patch
//! built so far or the mesh around the hole.
//!
//! Triangles that share a vertex or an edge touch by construction. Rather than
//! special-casing shared corners, both triangles are shrunk towards their centroids
//! by a tiny relative amount ([`SHRINK`]) before the exact closed test: adjacent
//! triangles then no longer touch, while a real overlap (a fold over a neighbour,
//! a crossing) survives the shrink unless it is thinner than `SHRINK` times the
//! triangle size.

use crate::geometry::bvh::tri_box;
use crate::geometry::grid::Grid;
use crate::geometry::predicates::tri_tri_nondegenerate;
use glam::DVec3;

/// Relative shrink applied before the exact test.
pub const SHRINK: f64 = 1e-6;

/// The triangle shrunk towards its centroid by [`SHRINK`].
pub fn shrink(t: &[DVec3; 3]) -> [DVec3; 3] {
    let c = (t[0] + t[1] + t[2]) / 3.0;
    t.map(|p| c + (p - c) * (1.0 - SHRINK))
}

/// True when the shrunk triangles overlap (see the module doc; a triangle degenerate
/// in floating point overlaps nothing).
pub fn overlap(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    tri_tri_nondegenerate(&shrink(a), &shrink(b))
}

/// Triangles that new triangles must not overlap, with a grid over them.
pub struct Obstacles {
    tris: Vec<[DVec3; 3]>,
    grid: Grid,
    /// Triangles whose box spans too many cells: tested on every query.
    big: Vec<u32>,
    scratch: Vec<u32>,
}

impl Obstacles {
    /// An empty set with grid cells of edge `cell` around `origin`.
    pub fn new(cell: f64, origin: DVec3) -> Obstacles {
        Obstacles {
            tris: Vec::new(),
            grid: Grid::new(cell, origin),
            big: Vec::new(),
            scratch: Vec::new(),
        }
    }

    /// Adds a triangle; returns its id.
    pub fn add(&mut self, t: [DVec3; 3]) -> u32 {
        let id = self.tris.len() as u32;
        let (lo, hi) = tri_box(&t);
        if !self.grid.insert_box(lo, hi, id) {
            self.big.push(id);
        }
        self.tris.push(t);
        id
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// The id of a triangle overlapping `t` (see [`overlap`]; the first one found),
    /// skipping ids for which `skip` is true.
    pub fn find_overlap(&mut self, t: &[DVec3; 3], skip: impl Fn(u32) -> bool) -> Option<u32> {
        let (lo, hi) = tri_box(t);
        let pad = (hi - lo).max_element() * 1e-9;
        let mut ids = std::mem::take(&mut self.scratch);
        self.grid
            .query_box(lo - DVec3::splat(pad), hi + DVec3::splat(pad), &mut ids);
        ids.extend_from_slice(&self.big);
        let st = shrink(t);
        let mut found = None;
        for &id in &ids {
            if skip(id) {
                continue;
            }
            let o = &self.tris[id as usize];
            let (olo, ohi) = tri_box(o);
            if olo.cmpgt(hi).any() || ohi.cmplt(lo).any() {
                continue;
            }
            if tri_tri_nondegenerate(&st, &shrink(o)) {
                found = Some(id);
                break;
            }
        }
        self.scratch = ids;
        found
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> [DVec3; 3] {
        [DVec3::from(a), DVec3::from(b), DVec3::from(c)]
    }

    #[test]
    fn neighbours_do_not_overlap_but_folds_do() {
        let a = t([0., 0., 0.], [1., 0., 0.], [0., 1., 0.]);
        // shares edge (1,0)-(0,1), other side
        let b = t([1., 0., 0.], [1., 1., 0.], [0., 1., 0.]);
        assert!(!overlap(&a, &b));
        // shares the edge but folds over a
        let c = t([1., 0., 0.], [0.2, 0.2, 0.], [0., 1., 0.]);
        assert!(overlap(&a, &c));
        // shares only a vertex, bent out of plane
        let d = t([0., 0., 0.], [-1., 0., 0.5], [0., -1., 0.5]);
        assert!(!overlap(&a, &d));
        // shares a vertex and pierces a
        let e = t([0., 0., 0.], [0.5, 0.2, -1.], [0.2, 0.5, 1.]);
        assert!(overlap(&a, &e));
        // nearly flat neighbour on the other side of a shared edge
        let f = t([1., 0., 0.], [1., 1., 1e-9], [0., 1., 0.]);
        assert!(!overlap(&a, &f));
    }

    #[test]
    fn grid_finds_overlaps() {
        let mut o = Obstacles::new(0.5, DVec3::ZERO);
        o.add(t([0., 0., 0.], [1., 0., 0.], [0., 1., 0.]));
        o.add(t([5., 5., 0.], [6., 5., 0.], [5., 6., 0.]));
        let q = t([0.2, 0.2, -1.], [0.2, 0.2, 1.], [0.9, 0.9, 0.]);
        assert_eq!(o.find_overlap(&q, |_| false), Some(0));
        assert_eq!(o.find_overlap(&q, |id| id == 0), None);
        let far = t([9., 9., 0.], [10., 9., 0.], [9., 10., 0.]);
        assert_eq!(o.find_overlap(&far, |_| false), None);
        // a huge triangle goes to the big list and is still found
        o.add(t(
            [-1000., -1000., 3.],
            [1000., -1000., 3.],
            [0., 1000., 3.],
        ));
        let r = t([0.2, 0.2, 2.], [0.2, 0.2, 4.], [0.9, 0.9, 3.]);
        assert_eq!(o.find_overlap(&r, |_| false), Some(2));
    }
}
