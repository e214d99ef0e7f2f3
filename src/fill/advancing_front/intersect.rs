//! The front's overlap test (the exact triangle-triangle test of
//! [`crate::geometry::predicates`] on shrunk triangles) and a spatial hash grid of
//! triangles, used to keep the front from creating a triangle that overlaps the patch
//! built so far or the mesh around the hole.
//!
//! Triangles that share a vertex or an edge touch by construction. Rather than
//! special-casing shared corners, both triangles are shrunk towards their centroids
//! by a tiny relative amount ([`SHRINK`]) before the exact closed test: adjacent
//! triangles then no longer touch, while a real overlap (a fold over a neighbour,
//! a crossing) survives the shrink unless it is thinner than `SHRINK` times the
//! triangle size.

use crate::fasthash::FxMap;
use crate::geometry::bvh::tri_box;
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

/// A uniform hash grid of axis-aligned boxes (ids), for broad-phase queries.
pub struct Grid {
    inv: f64,
    cells: FxMap<(i64, i64, i64), Vec<u32>>,
    /// Boxes spanning too many cells: tested on every query.
    big: Vec<u32>,
}

/// A box spanning more cells than this goes to the `big` list.
const MAX_CELLS: i64 = 512;

impl Grid {
    /// A grid with cells of edge `cell` (> 0).
    pub fn new(cell: f64) -> Grid {
        Grid {
            inv: 1.0 / cell,
            cells: FxMap::default(),
            big: Vec::new(),
        }
    }

    #[inline]
    fn key(&self, p: DVec3) -> (i64, i64, i64) {
        // `as` saturates, so far-away or huge coordinates stay well defined
        (
            (p.x * self.inv).floor() as i64,
            (p.y * self.inv).floor() as i64,
            (p.z * self.inv).floor() as i64,
        )
    }

    /// Adds box `[lo, hi]` with id `id`.
    pub fn insert(&mut self, id: u32, lo: DVec3, hi: DVec3) {
        let a = self.key(lo);
        let b = self.key(hi);
        let n = (b.0.saturating_sub(a.0).saturating_add(1))
            .saturating_mul(b.1.saturating_sub(a.1).saturating_add(1))
            .saturating_mul(b.2.saturating_sub(a.2).saturating_add(1));
        if !(1..=MAX_CELLS).contains(&n) {
            self.big.push(id);
            return;
        }
        for x in a.0..=b.0 {
            for y in a.1..=b.1 {
                for z in a.2..=b.2 {
                    self.cells.entry((x, y, z)).or_default().push(id);
                }
            }
        }
    }

    /// Appends to `out` the ids of boxes that may meet `[lo, hi]` (with repeats).
    pub fn query(&self, lo: DVec3, hi: DVec3, out: &mut Vec<u32>) {
        out.extend_from_slice(&self.big);
        let a = self.key(lo);
        let b = self.key(hi);
        let n = (b.0.saturating_sub(a.0).saturating_add(1))
            .saturating_mul(b.1.saturating_sub(a.1).saturating_add(1))
            .saturating_mul(b.2.saturating_sub(a.2).saturating_add(1));
        if !(1..=MAX_CELLS * 8).contains(&n) {
            // a huge query box: scan every cell instead
            for v in self.cells.values() {
                out.extend_from_slice(v);
            }
            return;
        }
        for x in a.0..=b.0 {
            for y in a.1..=b.1 {
                for z in a.2..=b.2 {
                    if let Some(v) = self.cells.get(&(x, y, z)) {
                        out.extend_from_slice(v);
                    }
                }
            }
        }
    }
}

/// Triangles that new triangles must not overlap, with a grid over them.
pub struct Obstacles {
    tris: Vec<[DVec3; 3]>,
    grid: Grid,
    scratch: Vec<u32>,
}

impl Obstacles {
    /// An empty set with grid cells of edge `cell`.
    pub fn new(cell: f64) -> Obstacles {
        Obstacles {
            tris: Vec::new(),
            grid: Grid::new(cell),
            scratch: Vec::new(),
        }
    }

    /// Adds a triangle; returns its id.
    pub fn add(&mut self, t: [DVec3; 3]) -> u32 {
        let id = self.tris.len() as u32;
        let (lo, hi) = tri_box(&t);
        self.grid.insert(id, lo, hi);
        self.tris.push(t);
        id
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// The id of a triangle overlapping `t` (see [`overlap`]), skipping ids for
    /// which `skip` is true.
    pub fn find_overlap(&mut self, t: &[DVec3; 3], skip: impl Fn(u32) -> bool) -> Option<u32> {
        let (lo, hi) = tri_box(t);
        let pad = (hi - lo).max_element() * 1e-9;
        let mut ids = std::mem::take(&mut self.scratch);
        ids.clear();
        self.grid
            .query(lo - DVec3::splat(pad), hi + DVec3::splat(pad), &mut ids);
        ids.sort_unstable();
        ids.dedup();
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
        let mut o = Obstacles::new(0.5);
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
