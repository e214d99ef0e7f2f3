//! A uniform grid over a plane: the broad phase with which the wavefront finds the
//! front nodes and the triangles near a step.

use glam::DVec3;

/// An id whose box spans more cells than this is not stored (the caller keeps such
/// ids apart and tests them every time).
pub const MAX_CELLS: i64 = 512;

/// A uniform grid of ids over a plane (a loop's best-fit plane): an id is stored in every cell
/// that the projection of its box touches (positions beyond the grid fall in its border
/// cells), in per-cell linked lists over one array (no allocation per cell; a copy is
/// two array copies). A query reports each id whose cells meet the query's cells
/// exactly once (in the first cell of the overlap). It is a broad phase only: callers
/// test the ids' own boxes, so what they find does not depend on the grid.
#[derive(Clone)]
pub struct PlaneGrid {
    centre: DVec3,
    u: DVec3,
    w: DVec3,
    /// Plane coordinate of the grid's corner, inverse cell size, cells per side.
    origin: f64,
    inv: f64,
    n: usize,
    /// First entry of each cell's list (`NONE`: empty).
    head: Vec<u32>,
    /// Entries: id and next entry of the same cell.
    entries: Vec<(u32, u32)>,
    /// Cell range `[i0, j0, i1, j1]` of each id (indexed by id).
    ranges: Vec<[u32; 4]>,
}

/// End of a cell's list.
const NONE: u32 = u32::MAX;
/// Largest number of cells per side of a [`PlaneGrid`] (the cells grow past it).
const MAX_SIDE: usize = 256;

impl PlaneGrid {
    /// A grid with cells of about `cell` over the square of half-width `extent` around
    /// `centre` in the plane spanned by `u` and `w` (unit, orthogonal).
    pub fn new(cell: f64, centre: DVec3, u: DVec3, w: DVec3, extent: f64) -> PlaneGrid {
        let extent = if extent.is_finite() && extent > 0.0 {
            extent
        } else {
            1.0
        };
        let cell = if cell.is_finite() && cell > 0.0 {
            cell
        } else {
            extent
        };
        let n = ((2.0 * extent / cell).ceil() as usize).clamp(1, MAX_SIDE);
        PlaneGrid {
            centre,
            u,
            w,
            origin: -extent,
            inv: n as f64 / (2.0 * extent),
            n,
            head: vec![NONE; n * n],
            entries: Vec::new(),
            ranges: Vec::new(),
        }
    }
    /// Cell range of the projection of the box `[lo, hi]`.
    pub fn range(&self, lo: DVec3, hi: DVec3) -> [u32; 4] {
        let c = (lo + hi) * 0.5 - self.centre;
        let h = (hi - lo) * 0.5;
        let span = |a: DVec3| h.x * a.x.abs() + h.y * a.y.abs() + h.z * a.z.abs();
        let (cu, ru) = (c.dot(self.u), span(self.u));
        let (cw, rw) = (c.dot(self.w), span(self.w));
        let max = (self.n - 1) as f64;
        let cell = |x: f64| ((x - self.origin) * self.inv).floor().clamp(0.0, max) as u32;
        [cell(cu - ru), cell(cw - rw), cell(cu + ru), cell(cw + rw)]
    }
    /// Inserts `id` into every cell the box touches; false when it spans more than
    /// `MAX_CELLS` (the caller keeps such ids apart).
    pub fn insert_box(&mut self, lo: DVec3, hi: DVec3, id: u32) -> bool {
        let r = self.range(lo, hi);
        let cells = (r[2] - r[0] + 1) as i64 * (r[3] - r[1] + 1) as i64;
        if cells > MAX_CELLS {
            return false;
        }
        let i = id as usize;
        if self.ranges.len() <= i {
            self.ranges.resize(i + 1, [1, 1, 0, 0]);
        }
        self.ranges[i] = r;
        for y in r[1]..=r[3] {
            for x in r[0]..=r[2] {
                let c = y as usize * self.n + x as usize;
                self.entries.push((id, self.head[c]));
                self.head[c] = (self.entries.len() - 1) as u32;
            }
        }
        true
    }
    /// Every id in a cell the box touches, each once (in no particular order).
    pub fn query_box(&self, lo: DVec3, hi: DVec3, out: &mut Vec<u32>) {
        out.clear();
        let q = self.range(lo, hi);
        for y in q[1]..=q[3] {
            for x in q[0]..=q[2] {
                let mut e = self.head[y as usize * self.n + x as usize];
                while e != NONE {
                    let (id, next) = self.entries[e as usize];
                    let r = self.ranges[id as usize];
                    // this is the first cell of the id's overlap with the query
                    if x == r[0].max(q[0]) && y == r[1].max(q[1]) {
                        out.push(id);
                    }
                    e = next;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A grid query reports each id at most once, every id whose box meets the query
    /// box among them (also boxes beyond the grid's extent, in its border cells), and
    /// exactly the ids whose cell ranges meet the query's.
    #[test]
    fn grid_query_reports_every_overlap_once() {
        use rand::Rng;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = DVec3::new(0.3, -0.2, 1.0).normalize();
        let u = n.any_orthonormal_vector();
        let w = n.cross(u);
        let mut g = PlaneGrid::new(0.1, DVec3::new(0.1, 0.2, 0.3), u, w, 3.0);
        let mut boxes = Vec::new();
        let rand_box = |rng: &mut ChaCha8Rng, size: f64| {
            let c = DVec3::new(
                rng.random_range(-4.0..4.0),
                rng.random_range(-4.0..4.0),
                rng.random_range(-4.0..4.0),
            );
            let h = DVec3::new(
                rng.random_range(0.0..size),
                rng.random_range(0.0..size),
                rng.random_range(0.0..size),
            );
            (c - h, c + h)
        };
        for id in 0..400u32 {
            let (lo, hi) = rand_box(&mut rng, if id % 50 == 0 { 6.0 } else { 0.6 });
            if g.insert_box(lo, hi, id) {
                boxes.push((id, lo, hi, g.range(lo, hi)));
            }
        }
        assert!(boxes.len() < 400, "some boxes span too many cells");
        let mut out = Vec::new();
        let mut found = 0;
        for q in 0..300 {
            let (lo, hi) = rand_box(&mut rng, if q % 20 == 0 { 8.0 } else { 1.0 });
            g.query_box(lo, hi, &mut out);
            let r = g.range(lo, hi);
            let mut want: Vec<u32> = boxes
                .iter()
                .filter(|(_, _, _, c)| c[0] <= r[2] && r[0] <= c[2] && c[1] <= r[3] && r[1] <= c[3])
                .map(|b| b.0)
                .collect();
            let mut got = out.clone();
            got.sort_unstable();
            assert!(got.windows(2).all(|w| w[0] != w[1]), "an id twice");
            want.sort_unstable();
            assert_eq!(got, want);
            for (id, blo, bhi, _) in &boxes {
                if !(bhi.cmplt(lo).any() || hi.cmplt(*blo).any()) {
                    assert!(got.binary_search(id).is_ok(), "box {id} meets the query");
                    found += 1;
                }
            }
        }
        assert!(found > 100, "{found}");
    }
}
