//! A uniform grid of boxes in space, hashed by cell: the broad phase with which the
//! fronts (the advancing front and the wavefront) find the front nodes and the
//! triangles near a step.

use crate::fasthash::FxMap;
use glam::DVec3;

/// An id whose box spans more cells than this is not stored (the caller keeps such
/// ids apart and tests them every time).
pub const MAX_CELLS: i64 = 512;

/// A uniform grid of ids in space: an id is stored in every cell its box touches, in
/// per-cell linked lists over one array (no allocation per cell; a copy is two array
/// copies and one table copy, which the wavefront's snapshots need). Cells are hashed,
/// so the grid holds only the cells in use; it spans [`REACH`] cells each way from its
/// origin, and positions beyond fall in its border cells. A query reports each id
/// whose cells meet the query's cells exactly once (in the first cell of the overlap).
/// It is a broad phase only: callers test the ids' own boxes, so what they find does
/// not depend on the grid.
#[derive(Clone)]
pub struct Grid {
    origin: DVec3,
    inv: f64,
    /// First entry of each cell's list.
    head: FxMap<Cell, u32>,
    /// Entries: id and next entry of the same cell.
    entries: Vec<(u32, Option<u32>)>,
    /// Cell range `[lo, hi]` of each stored id (indexed by id; `None`: not stored).
    ranges: Vec<Option<[[i32; 3]; 2]>>,
}

/// Cells per side each way from a grid's origin (the cell coordinates fit 21 bits).
pub const REACH: i32 = 1 << 20;

/// A cell's key: its three coordinates (offset by [`REACH`], 21 bits each) in one
/// word, hashed as one.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
struct Cell(u64);

impl Cell {
    #[inline]
    fn of([x, y, z]: [i32; 3]) -> Cell {
        let c = |v: i32| (v + REACH) as u64;
        Cell(c(x) | c(y) << 21 | c(z) << 42)
    }
}

impl Grid {
    /// A grid with cubic cells of edge `cell` around `origin` (a non-finite or
    /// non-positive `cell` gives one cell per unit).
    pub fn new(cell: f64, origin: DVec3) -> Grid {
        let cell = if cell.is_finite() && cell > 0.0 {
            cell
        } else {
            1.0
        };
        Grid {
            origin: if origin.is_finite() {
                origin
            } else {
                DVec3::ZERO
            },
            inv: 1.0 / cell,
            head: FxMap::default(),
            entries: Vec::new(),
            ranges: Vec::new(),
        }
    }

    /// The cell of `p`, clamped to the grid's reach (NaN: the origin's).
    #[inline]
    fn cell(&self, p: DVec3) -> [i32; 3] {
        let q = (p - self.origin) * self.inv;
        // floor without a call to libm's floor: `as` truncates (and saturates)
        let floor = |v: f64| {
            let t = v as i32;
            t.saturating_sub(i32::from((t as f64) > v))
                .clamp(-REACH, REACH - 1)
        };
        [floor(q.x), floor(q.y), floor(q.z)]
    }

    /// Cell range of the box `[lo, hi]` and its number of cells.
    #[inline]
    fn range(&self, lo: DVec3, hi: DVec3) -> ([[i32; 3]; 2], i64) {
        let (a, b) = (self.cell(lo), self.cell(hi));
        let side = |k: usize| (b[k] as i64 - a[k] as i64 + 1).max(0);
        // up to 2^21 cells a side: the product of three can pass i64
        (
            [a, b],
            side(0).saturating_mul(side(1)).saturating_mul(side(2)),
        )
    }

    /// Inserts `id` into every cell the box `[lo, hi]` touches; false (not stored)
    /// when it spans more than [`MAX_CELLS`] cells or none. Each id is inserted once
    /// (a query finds an id by the one cell range it keeps).
    pub fn insert_box(&mut self, lo: DVec3, hi: DVec3, id: u32) -> bool {
        let (r, cells) = self.range(lo, hi);
        if !(1..=MAX_CELLS).contains(&cells) {
            return false;
        }
        let i = id as usize;
        if self.ranges.len() <= i {
            self.ranges.resize(i + 1, None);
        }
        self.ranges[i] = Some(r);
        let [a, b] = r;
        for x in a[0]..=b[0] {
            for y in a[1]..=b[1] {
                for z in a[2]..=b[2] {
                    let e = self.entries.len() as u32;
                    let next = self.head.insert(Cell::of([x, y, z]), e);
                    self.entries.push((id, next));
                }
            }
        }
        true
    }

    /// Inserts `id` at the point `p` (one cell: always stored).
    pub fn insert_point(&mut self, p: DVec3, id: u32) {
        let stored = self.insert_box(p, p, id);
        debug_assert!(stored, "a point spans one cell");
    }

    /// Every stored id in a cell the box `[lo, hi]` touches, each once (in no
    /// particular order), into `out` (cleared first).
    pub fn query_box(&self, lo: DVec3, hi: DVec3, out: &mut Vec<u32>) {
        out.clear();
        let ([qa, qb], cells) = self.range(lo, hi);
        if cells == 0 {
            return; // an empty box (a corner past the other, or NaN)
        }
        let meets = |[a, b]: [[i32; 3]; 2]| (0..3).all(|k| a[k] <= qb[k] && qa[k] <= b[k]);
        if cells > MAX_CELLS * 8 {
            // a huge query box: every stored id's own range instead
            for (id, r) in self.ranges.iter().enumerate() {
                if r.is_some_and(meets) {
                    out.push(id as u32);
                }
            }
            return;
        }
        for x in qa[0]..=qb[0] {
            for y in qa[1]..=qb[1] {
                for z in qa[2]..=qb[2] {
                    let mut e = self.head.get(&Cell::of([x, y, z])).copied();
                    while let Some(i) = e {
                        let (id, next) = self.entries[i as usize];
                        // reported in the first cell of the id's overlap with the query
                        if let Some([a, _]) = self.ranges[id as usize] {
                            if x == a[0].max(qa[0]) && y == a[1].max(qa[1]) && z == a[2].max(qa[2])
                            {
                                out.push(id);
                            }
                        }
                        e = next;
                    }
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
    /// box among them, and exactly the ids whose cell ranges meet the query's (through
    /// the cells, and through the ranges for a huge query).
    /// Boxes out to the grid's reach and past it (and a NaN corner) are kept apart or
    /// land in the border cells: no overflow, and a query there finds them.
    #[test]
    fn far_and_huge_boxes_are_well_defined() {
        let mut g = Grid::new(1e-3, DVec3::ZERO);
        let huge = DVec3::splat(1e300);
        assert!(
            !g.insert_box(-huge, huge, 0),
            "spans every cell: kept apart"
        );
        assert!(g.insert_box(huge, huge, 1));
        assert!(g.insert_box(DVec3::splat(f64::NAN), DVec3::splat(f64::NAN), 2));
        let mut out = Vec::new();
        g.query_box(huge * 0.5, huge, &mut out);
        assert_eq!(out, vec![1]);
        g.query_box(-huge, huge, &mut out);
        out.sort_unstable();
        assert_eq!(out, vec![1, 2]);
    }

    #[test]
    fn grid_query_reports_every_overlap_once() {
        use rand::Rng;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut g = Grid::new(0.25, DVec3::new(0.1, 0.2, 0.3));
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
                boxes.push((id, lo, hi, g.range(lo, hi).0));
            }
        }
        assert!(boxes.len() < 400, "some boxes span too many cells");
        let mut out = Vec::new();
        let mut found = 0;
        let mut huge = 0;
        for q in 0..300 {
            let (lo, hi) = rand_box(&mut rng, if q % 20 == 0 { 8.0 } else { 1.0 });
            g.query_box(lo, hi, &mut out);
            let ([qa, qb], cells) = g.range(lo, hi);
            huge += usize::from(cells > MAX_CELLS * 8);
            let mut want: Vec<u32> = boxes
                .iter()
                .filter(|(_, _, _, [a, b])| (0..3).all(|k| a[k] <= qb[k] && qa[k] <= b[k]))
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
        assert!(huge > 5 && huge < 300, "{huge} huge queries");
    }
}
