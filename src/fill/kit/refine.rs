//! Refinement of the initial triangulation to the density of the surrounding mesh:
//! paper 002 §5.2 "patch refinement" (after Liepa 2003), ALGORITHMS B2 step 2.
//!
//! Each loop vertex carries a scale `s(v)`, the mean length of its mesh edges that are
//! not hole-boundary edges (the mean boundary edge length when it has none). A patch
//! triangle `(i, j, m)` with centroid `c` and `s(c) = (s_i + s_j + s_m)/3` is split at
//! `c` into three when for every corner `t`: `ρ·|c - v_t| > s(c)` and
//! `ρ·|c - v_t| > s(v_t)`, with `ρ = refine.density` (paper: sqrt 2). The new vertex
//! gets `s(c)`. After each round of splits every interior patch edge that is not
//! locally Delaunay is swapped (Lawson's flips): the edge `a-b` between triangles
//! `(a, b, c)` and `(b, a, d)` is swapped for `c-d` when the angles at `c` and `d` sum
//! to more than π, the 3D form of "the opposite vertex lies inside the circumcircle".
//! Rounds repeat until no triangle splits.
//!
//! Reading of the vague parts: the paper's "until no new triangles created" is taken
//! literally (rounds repeat), as in Liepa and CGAL. A swap is refused when the new edge
//! already exists (in the patch, or in the mesh between two loop vertices, or as a loop
//! edge), when a new triangle would be degenerate, or when it would fold against the
//! pair it replaces; a flip budget bounds the swapping on non-planar patches, where 3D
//! Delaunay flips need not terminate.
//!
//! Not in the paper: [`Refiner::relax`], a light isotropic remeshing of the new
//! vertices (interior edges longer than 1.6 times the local scale are split at their
//! midpoint, those shorter than `collapse_ratio` times it collapsed when the caller asks,
//! flips bring valences toward 6, and each new vertex moves in its tangent plane toward
//! the mean of the apexes that would make its triangles equilateral). Every
//! operation is refused when it would create an angle below 15 degrees (or below what
//! was there); loop vertices never move.

use super::{Deadline, FillError, TooLarge};
use crate::fasthash::{FxMap, HashSet};
use crate::geometry::measure;
use glam::DVec3;

type EdgeMap = FxMap<(u32, u32), u32>;

/// The patch during refinement.
pub struct Refiner<'a> {
    /// Loop vertices first (k of them), then new vertices.
    pub pos: Vec<DVec3>,
    /// Target edge length per vertex.
    pub scale: Vec<f64>,
    /// Triangles over `pos`.
    pub tris: Vec<[u32; 3]>,
    /// Directed edge -> triangle.
    edges: EdgeMap,
    k: usize,
    forbidden: &'a HashSet<(u32, u32)>,
    /// Relaxation uses valence flips (else Delaunay swaps).
    pub valence: bool,
    /// Relaxation splits interior edges longer than this times the local scale (0: off).
    pub split_ratio: f64,
    /// Relaxation collapses interior edges shorter than this times the local scale
    /// (0: off).
    pub collapse_ratio: f64,
    /// Smallest scale a new vertex gets (0: none): coarsens the refinement of huge
    /// holes (see `limits.max_patch_triangles`).
    pub scale_floor: f64,
    /// Refinement fails past this many triangles.
    pub max_triangles: usize,
}

/// Smallest angle (degrees) that relaxation, valence flips and long-edge splits may
/// create; an operation that would go below it (and below what was there) is refused.
const SLIVER_GUARD: f64 = 15.0;

/// Twice the area of a triangle.
fn tri_area2(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    (b - a).cross(c - a).length()
}

/// A triangle moved from `before` to `after` keeps its orientation and does not
/// flatten (area above 1e-6 of its longest edge squared): the test of a vertex move
/// in the relaxation and of an edge collapse.
fn stays_oriented(before: [DVec3; 3], after: [DVec3; 3]) -> bool {
    let nb = (before[1] - before[0]).cross(before[2] - before[0]);
    let na = (after[1] - after[0]).cross(after[2] - after[0]);
    let l2 = (after[1] - after[0])
        .length_squared()
        .max((after[2] - after[1]).length_squared())
        .max((after[0] - after[2]).length_squared());
    na.dot(nb) > 0.0 && na.length() > 1e-6 * l2
}

/// Hard cap on the refined patch size (a guard against absurd scales).
pub const MAX_TRIANGLES: usize = 4_000_000;

impl<'a> Refiner<'a> {
    /// A refiner over loop positions `pos` (k = pos.len()), their scales and an initial
    /// triangulation; `forbidden` holds the loop chords that are existing mesh edges.
    pub fn new(
        pos: Vec<DVec3>,
        scale: Vec<f64>,
        tris: Vec<[u32; 3]>,
        forbidden: &'a HashSet<(u32, u32)>,
    ) -> Refiner<'a> {
        let k = pos.len();
        let mut edges = EdgeMap::with_capacity_and_hasher(tris.len() * 3, Default::default());
        for (t, tri) in tris.iter().enumerate() {
            for c in 0..3 {
                edges.insert((tri[c], tri[(c + 1) % 3]), t as u32);
            }
        }
        Refiner {
            pos,
            scale,
            tris,
            edges,
            k,
            forbidden,
            valence: true,
            split_ratio: 1.6,
            collapse_ratio: 0.0,
            scale_floor: 0.0,
            max_triangles: MAX_TRIANGLES,
        }
    }

    /// Runs split rounds and swaps until no triangle splits.
    pub fn refine(&mut self, density: f64, deadline: &Deadline) -> Result<(), FillError> {
        if !density.is_finite() || density <= 0.0 {
            return Ok(());
        }
        let mut rounds = 0usize;
        loop {
            deadline.check()?;
            let split = self.split_round(density, deadline)?;
            if split == 0 {
                break;
            }
            let flips = self.delaunay_swaps(deadline)?;
            tracing::trace!(
                round = rounds,
                split,
                flips,
                triangles = self.tris.len(),
                "refine round"
            );
            rounds += 1;
            if rounds > 200 {
                break;
            }
        }
        Ok(())
    }

    fn split_round(&mut self, density: f64, deadline: &Deadline) -> Result<usize, FillError> {
        let n = self.tris.len();
        let mut count = 0;
        for t in 0..n {
            if t % 4096 == 0 {
                deadline.check()?;
            }
            let [a, b, c] = self.tris[t];
            let [pa, pb, pc] = [a, b, c].map(|i| self.pos[i as usize]);
            let cen = (pa + pb + pc) / 3.0;
            let sc = ((self.scale[a as usize] + self.scale[b as usize] + self.scale[c as usize])
                / 3.0)
                .max(self.scale_floor);
            let ok = [a, b, c].iter().all(|&v| {
                let d = density * (cen - self.pos[v as usize]).length();
                d > sc && d > self.scale[v as usize]
            });
            if !ok {
                continue;
            }
            // with a coarser density, a triangle on a loop edge is split only when its
            // height over that edge exceeds the scale: its centroid would otherwise
            // start a row of vertices at the loop's spacing, and the split cascade
            // would refine the whole band along the loop to the density the floor is
            // there to avoid. Its apex angle stays near loop spacing / scale. Other
            // thin triangles are not split either.
            if self.scale_floor > 0.0 {
                let k = self.k as u32;
                let on_loop =
                    |x: u32, y: u32| x < k && y < k && ((x + 1) % k == y || (y + 1) % k == x);
                let base = [(pa, pb, a, b), (pb, pc, b, c), (pc, pa, c, a)]
                    .into_iter()
                    .filter(|e| on_loop(e.2, e.3))
                    .map(|e| (e.1 - e.0).length())
                    .fold(0.0f64, f64::max);
                let a2 = tri_area2(pa, pb, pc);
                let thin = if base > 0.0 {
                    a2 / base < sc
                } else {
                    // elsewhere a thin triangle would start the same cascade (an
                    // equilateral one that passes the test above has area >= 0.65 sc²)
                    a2 < 2.0 * 0.3 * sc * sc
                };
                if thin {
                    continue;
                }
            }
            if self.tris.len() + 2 > self.max_triangles {
                return Err(FillError::TooLarge(TooLarge::Refinement(
                    self.max_triangles,
                )));
            }
            let nv = self.pos.len() as u32;
            self.pos.push(cen);
            self.scale.push(sc);
            let t1 = self.tris.len() as u32;
            let t2 = t1 + 1;
            self.tris[t] = [a, b, nv];
            self.tris.push([b, c, nv]);
            self.tris.push([c, a, nv]);
            let t = t as u32;
            self.edges.insert((b, nv), t);
            self.edges.insert((nv, a), t);
            self.edges.insert((b, c), t1);
            self.edges.insert((c, nv), t1);
            self.edges.insert((nv, b), t1);
            self.edges.insert((c, a), t2);
            self.edges.insert((a, nv), t2);
            self.edges.insert((nv, c), t2);
            count += 1;
        }
        Ok(count)
    }

    fn third(tri: [u32; 3], a: u32, b: u32) -> u32 {
        tri.into_iter().find(|&v| v != a && v != b).unwrap_or(a)
    }

    /// May `c`-`d` become an edge?
    fn edge_allowed(&self, c: u32, d: u32) -> bool {
        if c == d || self.edges.contains_key(&(c, d)) || self.edges.contains_key(&(d, c)) {
            return false;
        }
        let k = self.k as u32;
        if c < k && d < k {
            if (c + 1) % k == d || (d + 1) % k == c {
                return false;
            }
            if self.forbidden.contains(&(c.min(d), c.max(d))) {
                return false;
            }
        }
        true
    }

    /// The flip of edge a-b (triangles `(a, b, c)`, `(b, a, d)`) to c-d, when it is
    /// admissible: the new edge is allowed, neither new triangle is degenerate or
    /// folds against the pair it replaces. Returns `(t1, t2, c, d)`.
    fn flip_candidate(&self, a: u32, b: u32) -> Option<(u32, u32, u32, u32)> {
        let (Some(&t1), Some(&t2)) = (self.edges.get(&(a, b)), self.edges.get(&(b, a))) else {
            return None;
        };
        let c = Self::third(self.tris[t1 as usize], a, b);
        let d = Self::third(self.tris[t2 as usize], a, b);
        if !self.edge_allowed(c, d) {
            return None;
        }
        let [pa, pb, pc, pd] = [a, b, c, d].map(|i| self.pos[i as usize]);
        let n_old = (pb - pa).cross(pc - pa) + (pa - pb).cross(pd - pb);
        let n1 = (pa - pc).cross(pd - pc);
        let n2 = (pb - pd).cross(pc - pd);
        let l2 = (pc - pd).length_squared().max((pa - pb).length_squared());
        if !(n1.dot(n_old) > 0.0 && n2.dot(n_old) > 0.0)
            || n1.length() <= 1e-12 * l2
            || n2.length() <= 1e-12 * l2
        {
            return None;
        }
        Some((t1, t2, c, d))
    }

    /// The smallest angle after flipping a-b to c-d is at least the smaller of the
    /// smallest angle before and 15 degrees (a valence flip must not make slivers).
    fn flip_keeps_angles(&self, a: u32, b: u32, c: u32, d: u32) -> bool {
        let [pa, pb, pc, pd] = [a, b, c, d].map(|i| self.pos[i as usize]);
        let min3 = measure::smallest_angle_by_cosines;
        let before = min3(pa, pb, pc).min(min3(pb, pa, pd));
        let after = min3(pc, pa, pd).min(min3(pd, pb, pc));
        after >= before.min(SLIVER_GUARD.to_radians())
    }

    fn do_flip(&mut self, a: u32, b: u32, (t1, t2, c, d): (u32, u32, u32, u32)) {
        self.tris[t1 as usize] = [c, a, d];
        self.tris[t2 as usize] = [d, b, c];
        self.edges.remove(&(a, b));
        self.edges.remove(&(b, a));
        self.edges.insert((c, a), t1);
        self.edges.insert((a, d), t1);
        self.edges.insert((d, c), t1);
        self.edges.insert((d, b), t2);
        self.edges.insert((b, c), t2);
        self.edges.insert((c, d), t2);
    }

    /// Swaps the edge a-b when it is not locally Delaunay and the swap is admissible.
    /// Returns the new edge `(c, d)`.
    fn try_swap(&mut self, a: u32, b: u32) -> Option<(u32, u32)> {
        let (Some(&t1), Some(&t2)) = (self.edges.get(&(a, b)), self.edges.get(&(b, a))) else {
            return None;
        };
        let c = Self::third(self.tris[t1 as usize], a, b);
        let d = Self::third(self.tris[t2 as usize], a, b);
        let [pa, pb, pc, pd] = [a, b, c, d].map(|i| self.pos[i as usize]);
        let alpha = measure::angle_at(pc, pa, pb);
        let beta = measure::angle_at(pd, pa, pb);
        if alpha + beta <= std::f64::consts::PI + 1e-10 {
            return None;
        }
        let f = self.flip_candidate(a, b)?;
        self.do_flip(a, b, f);
        Some((c, d))
    }

    /// Flips that bring vertex valences toward their ideal: 6 for a new vertex, and for
    /// a loop vertex one more than its patch angle in multiples of 60 degrees (the
    /// number of near-equilateral triangles that fit). Returns the number of flips.
    pub fn valence_flips(&mut self, deadline: &Deadline) -> Result<usize, FillError> {
        let n = self.pos.len();
        let k = self.k;
        let mut angle = vec![0.0f64; k];
        for t in &self.tris {
            for c in 0..3 {
                let v = t[c] as usize;
                if v < k {
                    let [p, q, r] =
                        [t[c], t[(c + 1) % 3], t[(c + 2) % 3]].map(|i| self.pos[i as usize]);
                    angle[v] += measure::angle_at(p, q, r);
                }
            }
        }
        let target: Vec<i64> = (0..n)
            .map(|v| {
                if v < k {
                    ((angle[v] / (std::f64::consts::PI / 3.0)).round() as i64 + 1).max(2)
                } else {
                    6
                }
            })
            .collect();
        let mut val = vec![0i64; n];
        for &(a, b) in self.edges.keys() {
            if a < b || !self.edges.contains_key(&(b, a)) {
                val[a as usize] += 1;
                val[b as usize] += 1;
            }
        }
        let mut flips = 0;
        for _pass in 0..4 {
            deadline.check()?;
            let mut keys: Vec<(u32, u32)> =
                self.edges.keys().copied().filter(|&(a, b)| a < b).collect();
            keys.sort_unstable();
            let mut changed = 0;
            for (a, b) in keys {
                // the valence test first (integers), the geometry only for a flip
                // that would help
                let (Some(&t1), Some(&t2)) = (self.edges.get(&(a, b)), self.edges.get(&(b, a)))
                else {
                    continue;
                };
                let c = Self::third(self.tris[t1 as usize], a, b);
                let d = Self::third(self.tris[t2 as usize], a, b);
                let dev = |v: u32, dv: i64| {
                    let x = val[v as usize] + dv - target[v as usize];
                    x * x
                };
                let before = dev(a, 0) + dev(b, 0) + dev(c, 0) + dev(d, 0);
                let after = dev(a, -1) + dev(b, -1) + dev(c, 1) + dev(d, 1);
                if after >= before {
                    continue;
                }
                let Some(f) = self.flip_candidate(a, b) else {
                    continue;
                };
                if self.flip_keeps_angles(a, b, c, d) {
                    self.do_flip(a, b, f);
                    val[a as usize] -= 1;
                    val[b as usize] -= 1;
                    val[c as usize] += 1;
                    val[d as usize] += 1;
                    changed += 1;
                }
            }
            flips += changed;
            if changed == 0 {
                break;
            }
        }
        Ok(flips)
    }

    /// Lawson flips until every interior edge is locally Delaunay (or the budget runs out).
    pub fn delaunay_swaps(&mut self, deadline: &Deadline) -> Result<usize, FillError> {
        let mut stack: Vec<(u32, u32)> =
            self.edges.keys().copied().filter(|&(a, b)| a < b).collect();
        stack.sort_unstable();
        let budget = 20 * self.tris.len() + 1000;
        let mut flips = 0usize;
        let mut steps = 0usize;
        while let Some((a, b)) = stack.pop() {
            steps += 1;
            if steps % 8192 == 0 {
                deadline.check()?;
            }
            if let Some((c, d)) = self.try_swap(a, b) {
                flips += 1;
                if flips > budget {
                    break;
                }
                // the four outer edges of the new pair
                for (x, y) in [(c, a), (a, d), (d, b), (b, c)] {
                    stack.push((x.min(y), x.max(y)));
                }
            }
        }
        Ok(flips)
    }

    /// Splits every interior edge longer than `ratio` times the mean scale of its ends
    /// at its midpoint (the isotropic-remeshing split; the paper's centroid splits
    /// leave long chords across narrow holes, whose slivers no flip can mend).
    /// Returns the number of splits.
    pub fn split_long_edges(
        &mut self,
        ratio: f64,
        deadline: &Deadline,
    ) -> Result<usize, FillError> {
        let mut keys: Vec<(u32, u32)> = self
            .edges
            .keys()
            .copied()
            .filter(|&(a, b)| a < b && self.edges.contains_key(&(b, a)))
            .collect();
        keys.sort_unstable();
        let mut count = 0;
        for (i, (a, b)) in keys.into_iter().enumerate() {
            if i % 4096 == 0 {
                deadline.check()?;
            }
            let (Some(&t1), Some(&t2)) = (self.edges.get(&(a, b)), self.edges.get(&(b, a))) else {
                continue;
            };
            let (pa, pb) = (self.pos[a as usize], self.pos[b as usize]);
            let target = 0.5 * (self.scale[a as usize] + self.scale[b as usize]);
            if (pb - pa).length() <= ratio * target {
                continue;
            }
            if self.tris.len() + 2 > self.max_triangles {
                return Err(FillError::TooLarge(TooLarge::Refinement(
                    self.max_triangles,
                )));
            }
            let c = Self::third(self.tris[t1 as usize], a, b);
            let d = Self::third(self.tris[t2 as usize], a, b);
            let (pc, pd, pm) = (self.pos[c as usize], self.pos[d as usize], (pa + pb) / 2.0);
            // the split halves the angles at c and d: refuse when that makes slivers
            let before = measure::smallest_angle_by_cosines(pa, pb, pc)
                .min(measure::smallest_angle_by_cosines(pb, pa, pd));
            let after = measure::smallest_angle_by_cosines(pa, pm, pc)
                .min(measure::smallest_angle_by_cosines(pm, pb, pc))
                .min(measure::smallest_angle_by_cosines(pb, pm, pd))
                .min(measure::smallest_angle_by_cosines(pm, pa, pd));
            if after < before.min(SLIVER_GUARD.to_radians()) {
                continue;
            }
            let m = self.pos.len() as u32;
            self.pos.push(pm);
            self.scale.push(target);
            let t3 = self.tris.len() as u32;
            let t4 = t3 + 1;
            // (a, b, c) -> (a, m, c) + (m, b, c); (b, a, d) -> (b, m, d) + (m, a, d)
            self.tris[t1 as usize] = [a, m, c];
            self.tris.push([m, b, c]);
            self.tris[t2 as usize] = [b, m, d];
            self.tris.push([m, a, d]);
            self.edges.remove(&(a, b));
            self.edges.remove(&(b, a));
            self.edges.insert((a, m), t1);
            self.edges.insert((m, c), t1);
            self.edges.insert((c, a), t1);
            self.edges.insert((m, b), t3);
            self.edges.insert((b, c), t3);
            self.edges.insert((c, m), t3);
            self.edges.insert((b, m), t2);
            self.edges.insert((m, d), t2);
            self.edges.insert((d, b), t2);
            self.edges.insert((m, a), t4);
            self.edges.insert((a, d), t4);
            self.edges.insert((d, m), t4);
            count += 1;
        }
        Ok(count)
    }

    /// Collapses every interior edge shorter than `ratio` times the mean scale of its
    /// ends, shortest first (the isotropic-remeshing collapse: centroid splits leave
    /// clusters of vertices that no flip or smoothing can even out). A new vertex goes
    /// into a loop neighbour, which stays where it is; two new vertices meet at their
    /// midpoint. Refused unless the ends share exactly the two opposite vertices (the
    /// link condition), no new edge joins two loop vertices that must not be joined,
    /// no edge of the merged vertex grows past the split length, and no triangle
    /// around it flips or gets an angle below the smaller of 15 degrees and what was
    /// there. Returns the number of collapses.
    pub fn collapse_short_edges(
        &mut self,
        ratio: f64,
        deadline: &Deadline,
    ) -> Result<usize, FillError> {
        let k = self.k;
        let n = self.pos.len();
        if n == k {
            return Ok(0);
        }
        let mut cands: Vec<(f64, u32, u32)> = self
            .edges
            .keys()
            .filter(|&&(a, b)| {
                a < b && (b as usize >= k || a as usize >= k) && self.edges.contains_key(&(b, a))
            })
            .filter_map(|&(a, b)| {
                let l = (self.pos[b as usize] - self.pos[a as usize]).length();
                let target = 0.5 * (self.scale[a as usize] + self.scale[b as usize]);
                (l < ratio * target).then_some((l / target, a, b))
            })
            .collect();
        if cands.is_empty() {
            return Ok(0);
        }
        cands.sort_by(|x, y| x.0.total_cmp(&y.0).then((x.1, x.2).cmp(&(y.1, y.2))));
        let mut fan: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (t, tri) in self.tris.iter().enumerate() {
            for &v in tri {
                fan[v as usize].push(t as u32);
            }
        }
        let mut dead_tri = vec![false; self.tris.len()];
        let mut dead_vert = vec![false; n];
        let max_len = if self.split_ratio > 0.0 {
            0.8 * self.split_ratio
        } else {
            1.3
        };
        let min3 = measure::smallest_angle_by_cosines;
        let guard = SLIVER_GUARD.to_radians();
        let mut count = 0;
        for (i, &(_, a, b)) in cands.iter().enumerate() {
            if i % 1024 == 0 {
                deadline.check()?;
            }
            if dead_vert[a as usize] || dead_vert[b as usize] {
                continue;
            }
            let (Some(&t1), Some(&t2)) = (self.edges.get(&(a, b)), self.edges.get(&(b, a))) else {
                continue;
            };
            let (pa, pb) = (self.pos[a as usize], self.pos[b as usize]);
            let (u, w, p) = match (a as usize >= k, b as usize >= k) {
                (false, true) => (a, b, pa),
                (true, false) => (b, a, pb),
                (true, true) => (a, b, (pa + pb) / 2.0),
                (false, false) => continue,
            };
            let target = 0.5 * (self.scale[a as usize] + self.scale[b as usize]);
            if (pb - pa).length() >= ratio * target {
                continue;
            }
            let c = Self::third(self.tris[t1 as usize], a, b);
            let d = Self::third(self.tris[t2 as usize], a, b);
            // link condition: the common neighbours of u and w are c and d only
            let nbrs = |v: u32, fan: &Vec<Vec<u32>>| -> Vec<u32> {
                let mut out: Vec<u32> = fan[v as usize]
                    .iter()
                    .filter(|&&t| !dead_tri[t as usize])
                    .flat_map(|&t| self.tris[t as usize])
                    .filter(|&x| x != v)
                    .collect();
                out.sort_unstable();
                out.dedup();
                out
            };
            let nu = nbrs(u, &fan);
            let nw = nbrs(w, &fan);
            let common = nu.iter().filter(|x| nw.binary_search(x).is_ok()).count();
            if common != 2 || c == d {
                continue;
            }
            // new edges u-x for the neighbours x of w
            let ku = (u as usize) < k;
            let bad_edge = nw.iter().any(|&x| {
                if x == u || x == c || x == d {
                    return false;
                }
                if ku && (x as usize) < k {
                    let kk = k as u32;
                    if (u + 1) % kk == x || (x + 1) % kk == u {
                        return true;
                    }
                    if self.forbidden.contains(&(u.min(x), u.max(x))) {
                        return true;
                    }
                }
                let lim = max_len * 0.5 * (self.scale[u as usize] + self.scale[x as usize]);
                (self.pos[x as usize] - p).length() > lim
            });
            if bad_edge {
                continue;
            }
            // the triangles that stay and change: those of w and (when u moves) of u
            let mut moved: Vec<u32> = fan[w as usize]
                .iter()
                .chain(fan[u as usize].iter())
                .copied()
                .filter(|&t| !dead_tri[t as usize] && t != t1 && t != t2)
                .collect();
            moved.sort_unstable();
            moved.dedup();
            let mut before_min = f64::INFINITY;
            for t in [t1, t2] {
                let q = self.tris[t as usize].map(|i| self.pos[i as usize]);
                before_min = before_min.min(min3(q[0], q[1], q[2]));
            }
            let mut ok = true;
            let mut after_min = f64::INFINITY;
            for &t in &moved {
                let tri = self.tris[t as usize];
                let before = tri.map(|i| self.pos[i as usize]);
                let after = tri.map(|i| {
                    if i == u || i == w {
                        p
                    } else {
                        self.pos[i as usize]
                    }
                });
                before_min = before_min.min(min3(before[0], before[1], before[2]));
                after_min = after_min.min(min3(after[0], after[1], after[2]));
                if !stays_oriented(before, after) {
                    ok = false;
                    break;
                }
            }
            // false also when an angle is NaN
            let angles_ok = after_min >= before_min.min(guard);
            if !ok || !angles_ok || !p.is_finite() {
                continue;
            }
            // apply
            for t in [t1, t2] {
                let tri = self.tris[t as usize];
                for c in 0..3 {
                    self.edges.remove(&(tri[c], tri[(c + 1) % 3]));
                }
                dead_tri[t as usize] = true;
            }
            let w_tris: Vec<u32> = fan[w as usize]
                .iter()
                .copied()
                .filter(|&t| !dead_tri[t as usize])
                .collect();
            for &t in &w_tris {
                let tri = self.tris[t as usize];
                for c in 0..3 {
                    self.edges.remove(&(tri[c], tri[(c + 1) % 3]));
                }
                let tri = tri.map(|i| if i == w { u } else { i });
                self.tris[t as usize] = tri;
                for c in 0..3 {
                    self.edges.insert((tri[c], tri[(c + 1) % 3]), t);
                }
            }
            fan[u as usize].extend_from_slice(&w_tris);
            fan[w as usize].clear();
            self.pos[u as usize] = p;
            if (u as usize) >= k {
                self.scale[u as usize] = target;
            }
            dead_vert[w as usize] = true;
            count += 1;
        }
        if count > 0 {
            self.compact(&dead_tri, &dead_vert);
        }
        Ok(count)
    }

    /// Drops dead triangles and vertices (new ones only), renumbering the rest.
    fn compact(&mut self, dead_tri: &[bool], dead_vert: &[bool]) {
        let mut map: Vec<u32> = Vec::with_capacity(self.pos.len());
        let (mut pos, mut scale) = (Vec::new(), Vec::new());
        for (v, &dead) in dead_vert.iter().enumerate() {
            map.push(pos.len() as u32);
            if !dead {
                pos.push(self.pos[v]);
                scale.push(self.scale[v]);
            }
        }
        self.pos = pos;
        self.scale = scale;
        let tris: Vec<[u32; 3]> = self
            .tris
            .iter()
            .zip(dead_tri)
            .filter(|(_, &dead)| !dead)
            .map(|(tri, _)| tri.map(|i| map[i as usize]))
            .collect();
        self.tris = tris;
        self.edges.clear();
        for (t, tri) in self.tris.iter().enumerate() {
            for c in 0..3 {
                self.edges.insert((tri[c], tri[(c + 1) % 3]), t as u32);
            }
        }
    }

    /// Flips the longest edge of every triangle whose smallest angle is below
    /// `limit` (radians) when that raises the smallest angle of the pair; a few
    /// passes. Used after fairing, which can move vertices into slivers.
    pub fn fix_slivers(&mut self, limit: f64, deadline: &Deadline) -> Result<usize, FillError> {
        let min3 = measure::smallest_angle_by_cosines;
        let mut flips = 0;
        for _ in 0..4 {
            deadline.check()?;
            let mut changed = 0;
            for t in 0..self.tris.len() {
                let tri = self.tris[t];
                let p = tri.map(|i| self.pos[i as usize]);
                let before_t = min3(p[0], p[1], p[2]);
                if before_t >= limit {
                    continue;
                }
                // longest edge
                let mut e = 0;
                let mut best = -1.0;
                for c in 0..3 {
                    let l = (p[(c + 1) % 3] - p[c]).length_squared();
                    if l > best {
                        best = l;
                        e = c;
                    }
                }
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                let Some(f) = self.flip_candidate(a, b) else {
                    continue;
                };
                let (c, d) = (f.2, f.3);
                let [pa, pb, pc, pd] = [a, b, c, d].map(|i| self.pos[i as usize]);
                let before = min3(pa, pb, pc).min(min3(pb, pa, pd));
                let after = min3(pc, pa, pd).min(min3(pd, pb, pc));
                if after > before {
                    self.do_flip(a, b, f);
                    changed += 1;
                }
            }
            flips += changed;
            if changed == 0 {
                break;
            }
        }
        Ok(flips)
    }

    /// Tangential relaxation of the new vertices, each moved toward the mean of its
    /// neighbours within its tangent plane (uniform Laplacian with the normal part
    /// removed), followed by Delaunay swaps; `iterations` rounds. A move that would
    /// flip or flatten an incident triangle is not made. The loop vertices stay fixed.
    pub fn relax(&mut self, iterations: usize, deadline: &Deadline) -> Result<(), FillError> {
        let k = self.k;
        for _ in 0..iterations {
            deadline.check()?;
            if self.split_ratio > 0.0 {
                self.split_long_edges(self.split_ratio, deadline)?;
            }
            if self.collapse_ratio > 0.0 {
                self.collapse_short_edges(self.collapse_ratio, deadline)?;
            }
            let n = self.pos.len();
            if n == k {
                return Ok(());
            }
            if self.valence {
                self.valence_flips(deadline)?;
            }
            // the triangles of each new vertex, one list after the other
            // (`fan[start[v - k]..start[v - k + 1]]`)
            let mut start = vec![0usize; n - k + 1];
            for tri in &self.tris {
                for &v in tri {
                    if v as usize >= k {
                        start[v as usize - k + 1] += 1;
                    }
                }
            }
            for i in 0..n - k {
                start[i + 1] += start[i];
            }
            let mut fill = start.clone();
            let mut fan = vec![0u32; start[n - k]];
            for (t, tri) in self.tris.iter().enumerate() {
                for &v in tri {
                    if v as usize >= k {
                        fan[fill[v as usize - k]] = t as u32;
                        fill[v as usize - k] += 1;
                    }
                }
            }
            // smallest angle of each triangle at the current positions, once known
            let mut tri_min: Vec<f64> = vec![f64::NAN; self.tris.len()];
            let mut after_of: Vec<f64> = Vec::new();
            for v in k..n {
                let ts = &fan[start[v - k]..start[v - k + 1]];
                if ts.is_empty() {
                    continue;
                }
                let p = self.pos[v];
                let mut normal = DVec3::ZERO;
                for &t in ts {
                    let [a, b, c] = self.tris[t as usize].map(|i| self.pos[i as usize]);
                    normal += (b - a).cross(c - a);
                }
                let normal = normal.normalize_or_zero();
                // mean of the apexes that would make each incident triangle equilateral
                let (mut target, mut wsum) = (DVec3::ZERO, 0.0);
                for &t in ts {
                    let tri = self.tris[t as usize];
                    let Some(c) = tri.iter().position(|&i| i as usize == v) else {
                        continue;
                    };
                    let a = self.pos[tri[(c + 1) % 3] as usize];
                    let b = self.pos[tri[(c + 2) % 3] as usize];
                    let e = b - a;
                    let len = e.length();
                    let left = normal.cross(e).normalize_or_zero();
                    target += ((a + b) / 2.0 + left * (0.75f64.sqrt() * len)) * len;
                    wsum += len;
                }
                let mean = if wsum > 0.0 {
                    target / wsum
                } else {
                    // the neighbours (each corner after v in its triangles), as the
                    // uniform Laplacian
                    let nb: Vec<u32> = ts
                        .iter()
                        .filter_map(|&t| {
                            let tri = self.tris[t as usize];
                            let c = tri.iter().position(|&i| i as usize == v)?;
                            Some(tri[(c + 1) % 3])
                        })
                        .collect();
                    nb.iter().map(|&w| self.pos[w as usize]).sum::<DVec3>() / nb.len() as f64
                };
                let d = mean - p;
                let d = d - normal * normal.dot(d);
                let q = p + d;
                // keep every incident triangle oriented, and its smallest angle above
                // the smaller of the current one and 15 degrees
                let mut before_min = f64::INFINITY;
                let mut after_min = f64::INFINITY;
                after_of.clear();
                for &t in ts {
                    let tri = self.tris[t as usize];
                    let before = match tri_min[t as usize] {
                        m if m.is_nan() => {
                            let b = tri.map(|i| self.pos[i as usize]);
                            measure::smallest_angle_by_cosines(b[0], b[1], b[2])
                        }
                        m => m,
                    };
                    let a = tri.map(|i| {
                        if i as usize == v {
                            q
                        } else {
                            self.pos[i as usize]
                        }
                    });
                    let after = measure::smallest_angle_by_cosines(a[0], a[1], a[2]);
                    tri_min[t as usize] = before;
                    after_of.push(after);
                    before_min = before_min.min(before);
                    after_min = after_min.min(after);
                }
                let ok = after_min >= before_min.min(SLIVER_GUARD.to_radians())
                    && ts.iter().all(|&t| {
                        let tri = self.tris[t as usize];
                        let before = tri.map(|i| self.pos[i as usize]);
                        let after = tri.map(|i| {
                            if i as usize == v {
                                q
                            } else {
                                self.pos[i as usize]
                            }
                        });
                        stays_oriented(before, after)
                    });
                if ok && q.is_finite() {
                    self.pos[v] = q;
                    for (&t, &m) in ts.iter().zip(&after_of) {
                        tri_min[t as usize] = m;
                    }
                }
            }
            if !self.valence {
                self.delaunay_swaps(deadline)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fill::kit::Deadline;

    /// A flat round loop of `k` vertices (radius 1, z = 0), fanned from vertex 0 and
    /// refined to a scale of `scale`.
    fn refined_disk<'a>(k: usize, scale: f64, forbidden: &'a HashSet<(u32, u32)>) -> Refiner<'a> {
        let pos: Vec<DVec3> = (0..k)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / k as f64;
                DVec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let tris: Vec<[u32; 3]> = (1..k as u32 - 1).map(|i| [0, i, i + 1]).collect();
        let mut r = Refiner::new(pos, vec![scale; k], tris, forbidden);
        r.refine(std::f64::consts::SQRT_2, &Deadline::none())
            .unwrap();
        r
    }

    /// The triangles form an oriented disk over the vertices: every vertex used, every
    /// directed edge once, the loop edges the only unpaired ones, V - E + F = 1, all
    /// faces up.
    fn assert_disk(r: &Refiner, k: usize) {
        let mut used = vec![false; r.pos.len()];
        let mut directed = HashSet::default();
        for tri in &r.tris {
            for c in 0..3 {
                used[tri[c] as usize] = true;
                assert!(
                    directed.insert((tri[c], tri[(c + 1) % 3])),
                    "edge twice: {tri:?}"
                );
            }
            let p = tri.map(|i| r.pos[i as usize]);
            assert!((p[1] - p[0]).cross(p[2] - p[0]).z > 0.0, "flipped {tri:?}");
        }
        assert!(used.iter().all(|&u| u), "an unused vertex");
        let unpaired: Vec<_> = directed
            .iter()
            .filter(|&&(a, b)| !directed.contains(&(b, a)))
            .collect();
        assert_eq!(unpaired.len(), k);
        for &&(a, b) in &unpaired {
            assert!(
                (a as usize) < k && (b as usize) == (a as usize + 1) % k,
                "{a}-{b}"
            );
        }
        let edges = (directed.len() + k) / 2;
        assert_eq!(r.pos.len() as i64 - edges as i64 + r.tris.len() as i64, 1);
        assert_eq!(r.pos.len(), r.scale.len());
    }

    #[test]
    fn collapsing_short_edges_keeps_an_oriented_disk_and_the_loop() {
        let forbidden = HashSet::default();
        let k = 40;
        let mut r = refined_disk(k, 0.12, &forbidden);
        assert_disk(&r, k);
        let loop_before: Vec<DVec3> = r.pos[..k].to_vec();
        let short = |r: &Refiner| {
            let mut n = 0;
            for tri in &r.tris {
                for c in 0..3 {
                    let (a, b) = (tri[c] as usize, tri[(c + 1) % 3] as usize);
                    if a < b && (a >= k || b >= k) {
                        let l = (r.pos[a] - r.pos[b]).length();
                        if l < 0.75 * 0.5 * (r.scale[a] + r.scale[b]) {
                            n += 1;
                        }
                    }
                }
            }
            n
        };
        let (n_before, short_before) = (r.pos.len(), short(&r));
        assert!(short_before > 0, "the centroid splits leave short edges");
        let collapsed = r.collapse_short_edges(0.75, &Deadline::none()).unwrap();
        assert!(collapsed > 0);
        assert_eq!(r.pos.len(), n_before - collapsed);
        assert_disk(&r, k);
        assert_eq!(&r.pos[..k], &loop_before[..], "loop vertices moved");
        assert!(
            short(&r) < short_before,
            "{} -> {}",
            short_before,
            short(&r)
        );
        // and again through the relaxation, which interleaves it with the rest
        r.collapse_ratio = 0.75;
        r.relax(5, &Deadline::none()).unwrap();
        assert_disk(&r, k);
        assert_eq!(&r.pos[..k], &loop_before[..]);
    }
}
