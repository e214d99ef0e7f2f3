//! Initial triangulation of a hole loop: minimum-weight triangulation by dynamic
//! programming (Barequet & Sharir; Liepa 2003), paper 002 §5.2 "initial
//! triangulation", ALGORITHMS B2 step 1.
//!
//! The weight of a triangulation is (in comparison order):
//! 1. the number of "bad" triangles (zero area, or an angle below the policy's
//!    `checks.min_angle_deg`), so a degenerate triangle is used only when no
//!    triangulation avoids it;
//! 2. with `refine.weight = dihedral_area` only: the largest dihedral angle between
//!    adjacent triangles, including the mesh faces outside the loop (Liepa);
//! 3. the total area (the paper's weight).
//!
//! A chord between two loop vertices that already share a mesh edge is never used
//! (the result would have an edge with three faces).
//!
//! Loops up to `refine.restricted_search_above` vertices (and at most
//! [`EXACT_MAX`]) are searched exhaustively, O(k³) time and O(k²) memory. Larger loops
//! restrict the search, as CGAL does with the edges of a 3D Delaunay triangulation of
//! the loop points; we have no 3D Delaunay, so we read it as:
//! * when the loop projected on its Newell (best-fit) plane is a simple polygon, the
//!   candidate edges are those of the 2D constrained Delaunay triangulation (spade) of
//!   the projected loop, inside the polygon, plus for every interior CDT edge the edge
//!   that flipping it would create. The same dynamic programme then runs over the
//!   candidate edges only, O(k) candidates with a few candidate apexes each, so it is
//!   near-linear. The flip edges give the programme room to avoid forbidden chords and
//!   to lower area or dihedral angles where the surface is not flat.
//! * otherwise (the projection self-overlaps, e.g. a loop wrapping around a tube), or
//!   when the restricted search finds nothing, divide and conquer: split the loop along
//!   its best short chord (smallest ratio of chord length to the shorter loop arc,
//!   among chords leaving at least an eighth of the vertices on each side), recursively,
//!   until the pieces are small enough for the exhaustive search.

use super::{Deadline, FillError};
use crate::fasthash::{HashMap, HashSet};
use crate::geometry::{delaunay3, measure};
use crate::mesh::{Mesh, VertexId};
use crate::policy::{Policy, TriangulationWeight};
use glam::DVec3;
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

/// Loop chords `(a, b)`, `a < b`, that are existing mesh edges (loop edges excluded).
pub fn forbidden_chords(mesh: &Mesh, lp: &[VertexId]) -> HashSet<(u32, u32)> {
    let k = lp.len();
    let index: HashMap<VertexId, u32> =
        lp.iter().enumerate().map(|(i, &v)| (v, i as u32)).collect();
    let mut out = HashSet::default();
    for (i, &v) in lp.iter().enumerate() {
        for w in mesh.topo.neighbors(v) {
            if let Some(&j) = index.get(&w) {
                let i = i as u32;
                let adjacent =
                    (i as usize + 1) % k == j as usize || (j as usize + 1) % k == i as usize;
                if !adjacent && i != j {
                    out.insert((i.min(j), i.max(j)));
                }
            }
        }
    }
    out
}

/// Unit normal of the mesh face outside each loop edge `v[i] -> v[i+1]` (the face
/// holding the half-edge `v[i+1] -> v[i]`).
pub fn outside_normals(mesh: &Mesh, lp: &[VertexId]) -> Vec<Option<DVec3>> {
    let k = lp.len();
    (0..k)
        .map(|i| {
            let (a, b) = (lp[i], lp[(i + 1) % k]);
            mesh.topo
                .outgoing(b)
                .find(|&h| mesh.topo.to(h) == a)
                .map(|h| mesh.face_normal_raw(h.face()).normalize_or_zero())
                .filter(|n| *n != DVec3::ZERO)
        })
        .collect()
}

/// Largest polygon the exhaustive search handles (its tables are O(n²)).
pub const EXACT_MAX: usize = 600;

/// What the triangulation needs to know about the loop.
pub struct LoopInput<'a> {
    /// Loop positions, in hole order.
    pub pts: &'a [DVec3],
    /// Chords `(a, b)`, `a < b`, that are existing mesh edges.
    pub forbidden: &'a HashSet<(u32, u32)>,
    /// Unit normal of the mesh face outside loop edge `i -> i + 1`, when known.
    pub outside_normals: &'a [Option<DVec3>],
    pub weight: TriangulationWeight,
    /// Smallest acceptable angle, radians.
    pub min_angle: f64,
    /// Loops above this size use the restricted search.
    pub restricted_above: usize,
    /// Loops up to `restricted_above` are searched among the edges of their 3D
    /// Delaunay triangulation first (`refine.search = "delaunay"`).
    pub delaunay: bool,
    pub deadline: Deadline,
}

impl<'a> LoopInput<'a> {
    /// The input as the policy asks for it: its triangulation weight, the checks'
    /// smallest angle, its search settings and the hole's deadline.
    pub fn with_policy(
        pts: &'a [DVec3],
        forbidden: &'a HashSet<(u32, u32)>,
        outside_normals: &'a [Option<DVec3>],
        policy: &Policy,
        deadline: Deadline,
    ) -> LoopInput<'a> {
        LoopInput {
            pts,
            forbidden,
            outside_normals,
            weight: policy.refine.weight,
            min_angle: policy.checks.min_angle_deg.max(0.0).to_radians(),
            restricted_above: policy.refine.restricted_search_above,
            delaunay: policy.refine.delaunay_first(),
            deadline,
        }
    }

    fn k(&self) -> usize {
        self.pts.len()
    }
    /// May `a`-`b` (loop indices) be an interior edge?
    fn chord_ok(&self, a: u32, b: u32) -> bool {
        let k = self.k() as u32;
        if a == b || (a + 1) % k == b || (b + 1) % k == a {
            return false;
        }
        !self.forbidden.contains(&(a.min(b), a.max(b)))
    }
    /// Outside normal of the directed loop edge `a -> b`, if it is a loop edge.
    fn outside(&self, a: u32, b: u32) -> Option<DVec3> {
        let k = self.k() as u32;
        if (a + 1) % k == b {
            self.outside_normals[a as usize]
        } else {
            None
        }
    }
    fn dihedral(&self) -> bool {
        self.weight == TriangulationWeight::DihedralArea
    }
}

/// Weight of a (partial) triangulation.
#[derive(Clone, Copy, Debug, PartialEq)]
struct W {
    bad: u32,
    dih: f64,
    area: f64,
}

impl W {
    const ZERO: W = W {
        bad: 0,
        dih: 0.0,
        area: 0.0,
    };
    fn plus(self, o: W) -> W {
        W {
            bad: self.bad + o.bad,
            dih: self.dih.max(o.dih),
            area: self.area + o.area,
        }
    }
    fn better_than(&self, o: &W) -> bool {
        if self.bad != o.bad {
            return self.bad < o.bad;
        }
        if (self.dih - o.dih).abs() > 1e-12 {
            return self.dih < o.dih;
        }
        self.area < o.area
    }
}

fn unit_normal(a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    (b - a).cross(c - a).normalize_or_zero()
}

/// Dihedral measure between two unit normals: `1 - cos(angle)`, monotone in the
/// angle (0 coplanar, 2 folded back), cheaper than the angle itself.
fn dihedral(n1: DVec3, n2: DVec3) -> f64 {
    if n1 == DVec3::ZERO || n2 == DVec3::ZERO {
        return 2.0;
    }
    1.0 - n1.dot(n2).clamp(-1.0, 1.0)
}

/// Weight of triangle (a, m, b) alone (loop indices), without dihedral terms;
/// `cos_lim` is the cosine of `inp.min_angle` (computed once by the caller).
fn tri_weight(inp: &LoopInput, cos_lim: f64, a: u32, m: u32, b: u32) -> W {
    let [pa, pm, pb] = [a, m, b].map(|i| inp.pts[i as usize]);
    let area = measure::tri_area(pa, pm, pb);
    // the smallest angle is opposite the shortest edge; compare cosines (the squared
    // lengths in order by a three-element sorting network)
    let (mut s, mut m2, mut g) = (
        (pm - pb).length_squared(),
        (pb - pa).length_squared(),
        (pa - pm).length_squared(),
    );
    if s.total_cmp(&m2).is_gt() {
        std::mem::swap(&mut s, &mut m2);
    }
    if m2.total_cmp(&g).is_gt() {
        std::mem::swap(&mut m2, &mut g);
    }
    if s.total_cmp(&m2).is_gt() {
        std::mem::swap(&mut s, &mut m2);
    }
    let cos_min = if m2 > 0.0 && g > 0.0 {
        (m2 + g - s) / (2.0 * (m2 * g).sqrt())
    } else {
        1.0
    };
    let bad = area.is_nan() || area <= 1e-12 * g || cos_min > cos_lim;
    W {
        bad: bad as u32,
        dih: 0.0,
        area,
    }
}

/// Triangulates the whole loop. Triangles are loop indices, oriented like the hole.
pub fn triangulate(inp: &LoopInput) -> Result<Vec<[u32; 3]>, FillError> {
    let k = inp.k();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "a loop of {k} vertices cannot be triangulated"
        )));
    }
    if k == 3 {
        return Ok(vec![[0, 1, 2]]);
    }
    let all: Vec<u32> = (0..k as u32).collect();
    if k <= inp.restricted_above.max(3) && k <= EXACT_MAX {
        if inp.delaunay {
            if let Some(t) = delaunay_search(inp)? {
                return Ok(t);
            }
        }
        return exact(inp, &all);
    }
    match restricted(inp)? {
        Some(t) => Ok(t),
        None => divide(inp, all),
    }
}

/// Exhaustive O(n³) search over the polygon `idx` (loop indices in loop order; the
/// closing edge runs `idx[n-1] -> idx[0]`).
pub fn exact(inp: &LoopInput, idx: &[u32]) -> Result<Vec<[u32; 3]>, FillError> {
    let n = idx.len();
    if n < 3 {
        return Err(FillError::bad_loop("polygon with fewer than 3 vertices"));
    }
    let at = |i: usize, j: usize| i * n + j;
    let mut best: Vec<Option<W>> = vec![None; n * n];
    let mut arg: Vec<u32> = vec![u32::MAX; n * n];
    for i in 0..n - 1 {
        best[at(i, i + 1)] = Some(W::ZERO);
    }
    let dih = inp.dihedral();
    // normal of the triangle on the inner side of each polygon edge or chord i-j
    let mut side: Vec<Option<DVec3>> = vec![None; if dih { n * n } else { 0 }];
    if dih {
        for i in 0..n - 1 {
            side[at(i, i + 1)] = inp.outside(idx[i], idx[i + 1]);
        }
    }
    let p = |i: usize| inp.pts[idx[i] as usize];
    let cos_lim = inp.min_angle.cos();
    for d in 2..n {
        inp.deadline.check()?;
        for i in 0..n - d {
            let j = i + d;
            let closing = d == n - 1;
            if !closing && !inp.chord_ok(idx[i], idx[j]) {
                continue;
            }
            let mut cur: Option<(W, u32, DVec3)> = None;
            for m in i + 1..j {
                let (Some(wl), Some(wr)) = (best[at(i, m)], best[at(m, j)]) else {
                    continue;
                };
                let partial = wl.plus(wr);
                // weights only grow: a partial sum that is not better cannot win
                if let Some(c) = &cur {
                    if !partial.better_than(&c.0) {
                        continue;
                    }
                }
                let mut w = partial.plus(tri_weight(inp, cos_lim, idx[i], idx[m], idx[j]));
                let nt = if dih {
                    unit_normal(p(i), p(m), p(j))
                } else {
                    DVec3::ZERO
                };
                if dih {
                    let mut worst = 0.0f64;
                    for nn in [side[at(i, m)], side[at(m, j)]].into_iter().flatten() {
                        worst = worst.max(dihedral(nt, nn));
                    }
                    if closing {
                        if let Some(no) = inp.outside(idx[j], idx[i]) {
                            worst = worst.max(dihedral(nt, no));
                        }
                    }
                    w.dih = w.dih.max(worst);
                }
                if cur.as_ref().is_none_or(|c| w.better_than(&c.0)) {
                    cur = Some((w, m as u32, nt));
                }
            }
            if let Some((w, m, nt)) = cur {
                best[at(i, j)] = Some(w);
                arg[at(i, j)] = m;
                if dih {
                    side[at(i, j)] = Some(nt);
                }
            }
        }
    }
    if best[at(0, n - 1)].is_none() {
        return Err(FillError::stuck(
            "no triangulation of the loop avoids the existing mesh edges",
        ));
    }
    let mut tris = Vec::with_capacity(n - 2);
    let mut stack = vec![(0usize, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j <= i + 1 {
            continue;
        }
        let m = arg[at(i, j)] as usize;
        tris.push([idx[i], idx[m], idx[j]]);
        stack.push((i, m));
        stack.push((m, j));
    }
    Ok(tris)
}

/// The candidate edges of the restricted search, from the constrained Delaunay
/// triangulation of the projected loop. `None` when the projection is not simple.
fn cdt_candidates(inp: &LoopInput) -> Option<Vec<(u32, u32)>> {
    let k = inp.k();
    let n = measure::newell_normal(inp.pts);
    if n == DVec3::ZERO {
        return None;
    }
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    let c = measure::centroid(inp.pts);
    let p2: Vec<Point2<f64>> = inp
        .pts
        .iter()
        .map(|&p| Point2::new((p - c).dot(u), (p - c).dot(v)))
        .collect();
    if p2.iter().any(|p| !p.x.is_finite() || !p.y.is_finite()) {
        return None;
    }
    let edges: Vec<[usize; 2]> = (0..k).map(|i| [i, (i + 1) % k]).collect();
    let mut conflict = false;
    let cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::try_bulk_load_cdt(
        p2.clone(),
        edges,
        |_| {
            conflict = true;
        },
    )
    .ok()?;
    if conflict || cdt.num_vertices() != k {
        return None;
    }
    let mut signed = 0.0;
    for i in 0..k {
        let (a, b) = (p2[i], p2[(i + 1) % k]);
        signed += a.x * b.y - b.x * a.y;
    }
    let ccw = signed > 0.0;
    let vh = |i: usize| spade::handles::FixedVertexHandle::from_index(i);
    // seed faces: the inner side of every loop edge
    let mut inside: HashSet<spade::handles::FixedFaceHandle<spade::handles::InnerTag>> =
        HashSet::default();
    let mut stack = Vec::new();
    for i in 0..k {
        let e = cdt.get_edge_from_neighbors(vh(i), vh((i + 1) % k))?;
        if !e.is_constraint_edge() {
            return None;
        }
        let e = if ccw { e } else { e.rev() };
        let f = e.face().as_inner()?;
        if inside.insert(f.fix()) {
            stack.push(f.fix());
        }
    }
    while let Some(f) = stack.pop() {
        let face = cdt.face(f);
        for e in face.adjacent_edges() {
            if e.is_constraint_edge() {
                continue;
            }
            let g = e.rev().face().as_inner()?; // reaching the outer face: not simple
            if inside.insert(g.fix()) {
                stack.push(g.fix());
            }
        }
    }
    let mut cand: HashSet<(u32, u32)> = HashSet::default();
    let key = |a: usize, b: usize| (a.min(b) as u32, a.max(b) as u32);
    for &f in &inside {
        let face = cdt.face(f);
        for e in face.adjacent_edges() {
            let a = e.from().fix().index();
            let b = e.to().fix().index();
            cand.insert(key(a, b));
            if e.is_constraint_edge() {
                continue;
            }
            // the flip edge of an interior edge
            let r = e.rev();
            if let (Some(_), Some(_)) = (e.face().as_inner(), r.face().as_inner()) {
                let c = e.next().to().fix().index();
                let d = r.next().to().fix().index();
                if c != d {
                    cand.insert(key(c, d));
                }
            }
        }
    }
    let mut out: Vec<(u32, u32)> = cand.into_iter().collect();
    out.sort_unstable();
    Some(out)
}

/// The dynamic programme over the CDT candidate edges. `Ok(None)`: not applicable or
/// nothing found (the caller falls back to divide and conquer).
fn restricted(inp: &LoopInput) -> Result<Option<Vec<[u32; 3]>>, FillError> {
    let Some(cand) = cdt_candidates(inp) else {
        return Ok(None);
    };
    restricted_over(inp, &cand)
}

/// The dynamic programme over the edges of the loop's 3D Delaunay triangulation
/// ([`crate::geometry::delaunay3`]) and the loop's own edges, CGAL's default search
/// space. `Ok(None)`: no Delaunay triangulation, or no triangulation of the loop among
/// its edges (the caller searches every one).
fn delaunay_search(inp: &LoopInput) -> Result<Option<Vec<[u32; 3]>>, FillError> {
    let k = inp.k() as u32;
    let Some(mut cand) = delaunay3::delaunay_edges(inp.pts) else {
        return Ok(None);
    };
    cand.extend((0..k - 1).map(|a| (a, a + 1)));
    cand.push((0, k - 1));
    cand.sort_unstable();
    cand.dedup();
    restricted_over(inp, &cand)
}

/// The dynamic programme over candidate edges `(a, b)`, `a < b` (loop edges that are
/// missing cannot be used).
fn restricted_over(
    inp: &LoopInput,
    cand: &[(u32, u32)],
) -> Result<Option<Vec<[u32; 3]>>, FillError> {
    let k = inp.k() as u32;
    inp.deadline.check()?;
    // chords (i < j), sorted by span; loop edges are the base cases
    let mut adj: Vec<Vec<u32>> = vec![Vec::new(); k as usize];
    let mut chords: Vec<(u32, u32)> = Vec::new();
    for &(a, b) in cand {
        let loop_edge = b == a + 1;
        let closing = a == 0 && b == k - 1;
        if !(loop_edge || closing || inp.chord_ok(a, b)) {
            continue;
        }
        adj[a as usize].push(b);
        adj[b as usize].push(a);
        if !loop_edge {
            chords.push((a, b));
        }
    }
    for l in adj.iter_mut() {
        l.sort_unstable();
    }
    chords.sort_by_key(|&(a, b)| (b - a, a));
    let mut best: HashMap<(u32, u32), (W, u32)> =
        HashMap::with_capacity_and_hasher(chords.len() * 2 + k as usize, Default::default());
    for a in 0..k - 1 {
        best.insert((a, a + 1), (W::ZERO, u32::MAX));
    }
    let dih = inp.dihedral();
    let cos_lim = inp.min_angle.cos();
    let side_normal = |best: &HashMap<(u32, u32), (W, u32)>, i: u32, j: u32| -> Option<DVec3> {
        if j == i + 1 {
            inp.outside(i, j)
        } else {
            let &(_, m) = best.get(&(i, j))?;
            Some(unit_normal(
                inp.pts[i as usize],
                inp.pts[m as usize],
                inp.pts[j as usize],
            ))
        }
    };
    for (ci, &(i, j)) in chords.iter().enumerate() {
        if ci % 1024 == 0 {
            inp.deadline.check()?;
        }
        let closing = i == 0 && j == k - 1;
        let mut cur: Option<(W, u32)> = None;
        for &m in &adj[i as usize] {
            if m <= i || m >= j {
                continue;
            }
            let (Some(&(wl, _)), Some(&(wr, _))) = (best.get(&(i, m)), best.get(&(m, j))) else {
                continue;
            };
            let mut w = wl.plus(wr).plus(tri_weight(inp, cos_lim, i, m, j));
            if dih {
                let nt = unit_normal(
                    inp.pts[i as usize],
                    inp.pts[m as usize],
                    inp.pts[j as usize],
                );
                let mut worst = 0.0f64;
                for nn in [side_normal(&best, i, m), side_normal(&best, m, j)]
                    .into_iter()
                    .flatten()
                {
                    worst = worst.max(dihedral(nt, nn));
                }
                if closing {
                    if let Some(no) = inp.outside(j, i) {
                        worst = worst.max(dihedral(nt, no));
                    }
                }
                w.dih = w.dih.max(worst);
            }
            if cur.as_ref().is_none_or(|c| w.better_than(&c.0)) {
                cur = Some((w, m));
            }
        }
        if let Some(c) = cur {
            best.insert((i, j), c);
        }
    }
    if !best.contains_key(&(0, k - 1)) {
        return Ok(None);
    }
    let mut tris = Vec::with_capacity(k as usize - 2);
    let mut stack = vec![(0u32, k - 1)];
    while let Some((i, j)) = stack.pop() {
        if j <= i + 1 {
            continue;
        }
        let Some(&(_, m)) = best.get(&(i, j)) else {
            return Ok(None);
        };
        tris.push([i, m, j]);
        stack.push((i, m));
        stack.push((m, j));
    }
    Ok(Some(tris))
}

/// Divide and conquer along short chords (see the module docs).
fn divide(inp: &LoopInput, all: Vec<u32>) -> Result<Vec<[u32; 3]>, FillError> {
    let leaf = inp.restricted_above.clamp(12, 60);
    let mut out = Vec::with_capacity(inp.k());
    let mut work = vec![all];
    while let Some(idx) = work.pop() {
        inp.deadline.check()?;
        let n = idx.len();
        if n <= leaf {
            out.extend(exact(inp, &idx)?);
            continue;
        }
        // arc length from idx[0] to each position
        let mut arc = vec![0.0f64; n + 1];
        for t in 0..n {
            let a = inp.pts[idx[t] as usize];
            let b = inp.pts[idx[(t + 1) % n] as usize];
            arc[t + 1] = arc[t] + (b - a).length();
        }
        let total = arc[n];
        let min_side = (n / 8).max(3);
        let stride = (n / 64).max(1);
        let mut best: Option<(f64, usize, usize)> = None;
        for a in (0..n).step_by(stride) {
            for b in a + min_side..n {
                if n - (b - a) < min_side {
                    break;
                }
                if !inp.chord_ok(idx[a], idx[b]) {
                    continue;
                }
                let along = arc[b] - arc[a];
                let shorter = along.min(total - along);
                if shorter.is_nan() || shorter <= 0.0 {
                    continue;
                }
                let d = (inp.pts[idx[a] as usize] - inp.pts[idx[b] as usize]).length() / shorter;
                if best.is_none_or(|c| d < c.0) {
                    best = Some((d, a, b));
                }
            }
        }
        let Some((_, a, b)) = best else {
            // no admissible chord: try the exhaustive search if it is small enough
            if n <= EXACT_MAX {
                out.extend(exact(inp, &idx)?);
                continue;
            }
            return Err(FillError::stuck("no admissible chord to split the loop"));
        };
        let first: Vec<u32> = idx[a..=b].to_vec();
        let mut second: Vec<u32> = idx[b..].to_vec();
        second.extend_from_slice(&idx[..=a]);
        work.push(first);
        work.push(second);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input<'a>(
        pts: &'a [DVec3],
        forb: &'a HashSet<(u32, u32)>,
        out: &'a [Option<DVec3>],
        above: usize,
    ) -> LoopInput<'a> {
        LoopInput {
            pts,
            forbidden: forb,
            outside_normals: out,
            weight: TriangulationWeight::Area,
            min_angle: 0.0,
            restricted_above: above,
            delaunay: false,
            deadline: Deadline::none(),
        }
    }

    fn circle(k: usize, wobble: f64) -> Vec<DVec3> {
        (0..k)
            .map(|i| {
                let t = -(i as f64) / k as f64 * std::f64::consts::TAU;
                DVec3::new(t.cos(), t.sin(), wobble * (3.0 * t).sin())
            })
            .collect()
    }

    /// Every loop edge once in loop direction, every other edge once each way.
    fn assert_disk(k: usize, tris: &[[u32; 3]]) {
        assert_eq!(tris.len(), k - 2);
        let mut dir = HashSet::default();
        for t in tris {
            for c in 0..3 {
                assert!(dir.insert((t[c], t[(c + 1) % 3])), "edge used twice");
            }
        }
        for &(a, b) in &dir {
            if (a as usize + 1) % k == b as usize {
                continue;
            }
            assert!(dir.contains(&(b, a)), "open edge {a}-{b}");
        }
        for i in 0..k {
            assert!(dir.contains(&(i as u32, ((i + 1) % k) as u32)));
        }
    }

    #[test]
    fn square_takes_the_smaller_diagonal_pair() {
        // a non-planar quad: the area-minimal split is along the fold
        let pts = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.0, 1.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(1.0, 1.0, 0.0),
        ];
        let f = HashSet::default();
        let o = vec![None; 4];
        let t = triangulate(&input(&pts, &f, &o, 60)).unwrap();
        assert_disk(4, &t);
        let area: f64 = t
            .iter()
            .map(|t| {
                crate::geometry::measure::tri_area(
                    pts[t[0] as usize],
                    pts[t[1] as usize],
                    pts[t[2] as usize],
                )
            })
            .sum();
        let a1 = crate::geometry::measure::tri_area(pts[0], pts[1], pts[2])
            + crate::geometry::measure::tri_area(pts[0], pts[2], pts[3]);
        let a2 = crate::geometry::measure::tri_area(pts[0], pts[1], pts[3])
            + crate::geometry::measure::tri_area(pts[1], pts[2], pts[3]);
        assert!((area - a1.min(a2)).abs() < 1e-12);
    }

    #[test]
    fn forbidden_chord_is_avoided() {
        let pts = circle(6, 0.0);
        let mut f = HashSet::default();
        f.insert((0, 3));
        f.insert((1, 4));
        let o = vec![None; 6];
        let t = triangulate(&input(&pts, &f, &o, 60)).unwrap();
        assert_disk(6, &t);
        for t in &t {
            for c in 0..3 {
                let (a, b) = (t[c].min(t[(c + 1) % 3]), t[c].max(t[(c + 1) % 3]));
                assert!(!f.contains(&(a, b)));
            }
        }
        // all three long diagonals forbidden and the fans too: still possible?
        let mut f = HashSet::default();
        for (a, b) in [
            (0, 2),
            (0, 3),
            (0, 4),
            (1, 3),
            (1, 4),
            (1, 5),
            (2, 4),
            (2, 5),
            (3, 5),
        ] {
            f.insert((a, b));
        }
        assert!(triangulate(&input(&pts, &f, &o, 60)).is_err());
    }

    #[test]
    fn restricted_and_divided_searches_give_disks() {
        let f = HashSet::default();
        for (k, wob) in [(100, 0.0), (250, 0.2), (1000, 0.0), (1000, 0.3)] {
            let pts = circle(k, wob);
            let o = vec![None; k];
            let inp = input(&pts, &f, &o, 60);
            let t = triangulate(&inp).unwrap();
            assert_disk(k, &t);
            let t = divide(&inp, (0..k as u32).collect()).unwrap();
            assert_disk(k, &t);
        }
    }

    #[test]
    fn the_delaunay_search_uses_delaunay_edges_only() {
        let f = HashSet::default();
        for (k, wob) in [(12, 0.0), (40, 0.3), (150, 0.2)] {
            let pts = circle(k, wob);
            let o = vec![None; k];
            let mut inp = input(&pts, &f, &o, 400);
            inp.weight = TriangulationWeight::DihedralArea;
            inp.delaunay = true;
            let t = delaunay_search(&inp).unwrap().expect("a triangulation");
            assert_disk(k, &t);
            let edges = delaunay3::delaunay_edges(&pts).unwrap();
            for t in &t {
                for c in 0..3 {
                    let (a, b) = (t[c].min(t[(c + 1) % 3]), t[c].max(t[(c + 1) % 3]));
                    let side = b == a + 1 || (a == 0 && b as usize == k - 1);
                    assert!(side || edges.binary_search(&(a, b)).is_ok(), "{a}-{b}");
                }
            }
            // and the whole triangulation takes it
            assert_eq!(triangulate(&inp).unwrap(), t);
        }
    }

    #[test]
    fn restricted_matches_exact_area_on_a_planar_convex_loop() {
        // on a planar convex loop every triangulation has the same area
        let pts = circle(80, 0.0);
        let f = HashSet::default();
        let o = vec![None; 80];
        let t = triangulate(&input(&pts, &f, &o, 60)).unwrap();
        let area: f64 = t
            .iter()
            .map(|t| {
                crate::geometry::measure::tri_area(
                    pts[t[0] as usize],
                    pts[t[1] as usize],
                    pts[t[2] as usize],
                )
            })
            .sum();
        let exact_area = 0.5 * 80.0 * (std::f64::consts::TAU / 80.0).sin();
        assert!((area - exact_area).abs() < 1e-9);
    }
}
