//! Improved advancing front for large holes.
//!
//! Paper 002 (Feng et al. 2020), §5.3 and Algorithm 3, with the closing rules of
//! ALGORITHMS.md B3 step 5 (the paper is silent on them).
//!
//! The front starts as the hole loop. While a front has more than four vertices, the
//! front vertex with the smallest angle `θ` is processed: `θ <= angle_small` closes it
//! with one triangle `(v_{i-1}, v_i, v_{i+1})`; `θ <= angle_large` adds one new vertex on
//! the bisector (two triangles); otherwise two new vertices on the trisectors (three
//! triangles). A front of three vertices becomes one triangle, a front of four gets the
//! better of its two diagonals (largest smallest `Qt`).
//!
//! How this module reads the paper where it is vague:
//! - **Angle.** `θ_i` is measured on the hole side (the front runs so that the hole is
//!   on its left seen from the surface normal), between the projections of the two
//!   front edges onto the plane normal to the corrected normal `n_c`, in `[0, 2π)`.
//! - **Normals.** `n_i` of an original loop vertex is the mesh's area-weighted vertex
//!   normal (the patch does not change it); of a new vertex, the area-weighted normal
//!   of the patch triangles around it so far.
//! - **Normal correction (eq. 7).** `e_l`, `e_r` sum the vectors from `v_i` to its
//!   `w = round(c/10)` (at least 1) front neighbours on each side, where `c` is the
//!   size of the *current* front (so `w` shrinks as the front closes and never wraps
//!   around it). The paper's normalisation by the summed lengths scales `e_l`, `e_r` by
//!   positive factors and does not change `n_e = e_l × e_r / |e_l × e_r|`, so it is
//!   skipped. `n_e` is oriented to agree with `n_i` ("like the surface"), then
//!   `n_c = normalize(α n_i + (1-α) n_e)`.
//! - **Curvature (eq. 8).** `κ` is the mean of the Taubin estimates `2 n·e/|e|²` at
//!   `v_{i-1}` and `v_{i+1}` along their front edges towards `v_i`, each with its own
//!   (uncorrected) normal. On a sphere of radius `R` with outward normals this is
//!   `-1/R`.
//! - **Placement (eqs. 9–10).** The new edge has length `l` = mean of the two front
//!   edge lengths at `v_i` (averaged with the size field, below) and lies in the plane spanned by `n_c` and the tangent
//!   direction `t` (the bisector or trisector of `θ` in the tangent plane of `n_c`); its
//!   angle `φ` to `n_c` is `cos φ = clamp(ω1 κ l/2 + ω2 s, -1, 1)`, where `s` is the
//!   mean cosine between `n_c` and the two unit front edges (the slope of the front
//!   against `n_c`; the paper's `n_cᵀ e'/|e'|²` term read as a dimensionless cosine). On
//!   a sphere both terms equal `-l/(2R)`, which puts the new vertex on the sphere when
//!   `n_c = n_i`. The new vertex is `v_o = v_i + l (cos φ n_c + sin φ t)` (the paper's
//!   `v_o = e - v_i` is a typo). Because `n_c` leans towards the hole's axis, new
//!   vertices are placed below the tangent continuation of a convex surface: the raw
//!   front flattens large curved holes (measured on a unit sphere: the largest radial
//!   error is 0.66 of the flat cap's sag for a 58-vertex hole, 0.95 for a 204-vertex
//!   one). That is the paper's design (converge fast); the fairing restores shape.
//! - **Priority.** A binary heap keyed by `θ`, with lazy deletion. After a step only
//!   the front vertices whose neighbours or normal changed are re-keyed; the wider
//!   window of `n_e` makes other keys slightly stale, so a popped vertex is
//!   re-evaluated and pushed back if its fresh angle is no longer the smallest.
//!
//! Closing rules (B3 step 5):
//! - **Merging.** A new vertex that lands within `merge_distance · l` of another
//!   vertex of the same front (not `v_{i-1}`, `v_i`, `v_{i+1}`) is replaced by it; the
//!   front then splits in two (the merged vertex appears in both). All fronts share
//!   one heap; a front of two vertices is closed, of three gets its last triangle.
//! - **Validity.** A step is taken only if none of its triangles overlaps the patch
//!   so far or the mesh near the hole (exact tri–tri tests on slightly shrunk
//!   triangles, see the `intersect` submodule), none creates an edge that already exists (in the
//!   patch, or a mesh edge between two loop vertices), none has an angle below
//!   `max(checks.min_angle_deg, 2°)`, none faces away from `n_c`, and none folds
//!   back over the triangle behind the front edge it closes (> 120°). Otherwise the
//!   fallbacks are tried (ear, bisector, bisector merged into the nearest front
//!   vertex); if none is valid the vertex is set aside until its neighbourhood changes.
//!   When every front vertex is set aside, a front of at most 8 vertices is closed
//!   around a new vertex at its centroid (if those triangles pass the same checks);
//!   otherwise the method fails. A front of four vertices with no valid diagonal
//!   tries the same centre vertex.
//! - **Bounded.** At most `max_steps_per_vertex · k` steps (a step is one processed
//!   front vertex, taken or set aside), the deadline is checked every step, and a
//!   front that grows past `4k + 64` vertices is declared divergent (it spreads away
//!   from the hole instead of closing, as on a sphere with more than a hemisphere
//!   missing). Note that the steps a hole needs grow with its area: a round planar
//!   hole needs about `k²/8` steps, so the default 200 steps per vertex limits round
//!   holes to about 1,600 boundary vertices. Before any step, the patch size is
//!   estimated from the loop's projected (vector) area over `0.25 l²` (`l` the loop's
//!   mean incident mesh edge length; measured on slots and caps); past
//!   `limits.max_patch_triangles` the method gives up at once, and it also gives up
//!   as soon as its patch passes that limit (not in the paper; it keeps a round hole of
//!   thousands of vertices from spending its whole time limit before failing over).
//!
//! After closing: an angle-improving edge-swap pass (max-min angle, never onto an
//! existing edge, never folding a pair), then with `front.fair` the new vertices are
//! relaxed (a few umbrella-smoothing iterations, the loop fixed, which evens out the
//! triangles), then faired by `fill::fair::fair_patch` (the `[fair]` policy: the
//! bi-Laplacian by default), which restores the curvature the raw front flattens,
//! and the swap pass runs again.
//! The whole patch is verified against itself and the mesh at the end; a faired
//! patch that fails is replaced by the unfaired one.
//!
//! Size field (a reading): the step length `l` is the mean of the two front edges
//! (the paper) averaged with a size carried by the vertices (loop vertex: mean
//! length of its mesh edges; new vertex: mean of the three front vertices it grew
//! from). With the paper's length alone the front shrinks step after step (a 90°
//! bisector step makes front edges 0.77 `l` long) and a round hole got six times
//! too many vertices.

mod improve;
mod intersect;
#[cfg(test)]
mod tests;

use super::kit::{fair, FillContext, FillError};
use crate::fasthash::FxSet;
use crate::fasthash::HashMap;
use crate::geometry::measure;
use crate::mesh::VertexId;
use crate::patch::Patch;
use glam::DVec3;
use intersect::{Grid, Obstacles};
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::f64::consts::PI;

/// Smallest angle (degrees) a step may create (at least the checks' minimum).
const STEP_MIN_ANGLE_DEG: f64 = 2.0;
/// A step must not fold over the triangle behind a front edge by more than this
/// (cosine of the angle between their normals).
const FOLD_COS: f64 = -0.5;
/// Key offset of a vertex set aside (larger than any angle).
const BLOCKED: f64 = 10.0;
/// The front has diverged when it holds more than this many times the loop's
/// vertices (plus 64): it is spreading away instead of closing.
const DIVERGE_FACTOR: usize = 4;
/// A front of at most this many vertices on which every step failed is closed
/// around a centre vertex when that is valid.
const FAN_MAX: usize = 8;
/// Umbrella relaxation: iterations and step.
const RELAX_ITERATIONS: usize = 8;
const RELAX_LAMBDA: f64 = 0.5;
/// Relaxation never creates an angle below this (degrees) unless it was smaller already.
const RELAX_MIN_ANGLE_DEG: f64 = 0.5;
/// Edge swaps: at most this many per patch triangle.
const SWAPS_PER_TRIANGLE: usize = 10;

/// Fills the hole with the improved advancing front.
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::Failed(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    let params = Params::from_policy(ctx)?;
    let t0 = std::time::Instant::now();
    let cap = ctx.policy.limits.max_patch_triangles;
    if cap > 0 {
        // give up at once on a hole whose patch would pass the cap (a round hole of
        // thousands of vertices): the front would take minutes and fail anyway
        let est = estimated_triangles(ctx);
        if est > cap as f64 {
            return failed(format!(
                "the patch would have about {est:.0} triangles > limits.max_patch_triangles = {cap}"
            ));
        }
    }
    let mut b = Builder::new(ctx, params)?;
    let t1 = std::time::Instant::now();
    b.run()?;
    let t2 = std::time::Instant::now();
    let steps = b.steps;
    let patch = b.finish()?;
    tracing::debug!(
        hole = ctx.hole.id,
        k,
        steps,
        new_vertices = patch.new_vertices.len(),
        triangles = patch.triangles.len(),
        setup_ms = (t1 - t0).as_secs_f64() * 1e3,
        front_ms = (t2 - t1).as_secs_f64() * 1e3,
        finish_ms = t2.elapsed().as_secs_f64() * 1e3,
        "advancing front closed"
    );
    Ok(patch)
}

/// Mean area of a front triangle in units of the squared mean incident edge length of
/// the loop (measured on a 10,008-vertex cylinder slot: 0.26, on a 217-vertex sphere
/// cap: 0.25; the front's steps are shorter than the size field).
const AREA_PER_TRIANGLE: f64 = 0.25;

/// The number of triangles the front would make: the loop's projected area
/// ([`measure::vector_area`], a lower bound of the patch's area) over the area of a
/// front triangle at the loop's mean incident edge length.
fn estimated_triangles(ctx: &FillContext) -> f64 {
    let pts = ctx.boundary_positions();
    let area = measure::vector_area(&pts);
    let (mut sum, mut n) = (0.0, 0usize);
    for &v in &ctx.hole.vertices {
        let m = ctx.mesh.mean_incident_edge_length(v);
        if m > 0.0 && m.is_finite() {
            sum += m;
            n += 1;
        }
    }
    let s = if n > 0 {
        sum / n as f64
    } else {
        ctx.hole.mean_edge_length
    };
    if !(s > 0.0 && area.is_finite()) {
        return 0.0;
    }
    area / (AREA_PER_TRIANGLE * s * s)
}

/// Validated parameters (angles in radians).
#[derive(Clone, Copy, Debug)]
struct Params {
    angle_small: f64,
    angle_large: f64,
    alpha: f64,
    omega1: f64,
    merge: f64,
    min_angle: f64,
    max_steps: usize,
    fair: bool,
}

impl Params {
    fn from_policy(ctx: &FillContext) -> Result<Params, FillError> {
        let f = &ctx.policy.front;
        let bad = |m: &str| Err(FillError::Failed(format!("policy front.{m}")));
        if !(f.angle_small > 0.0 && f.angle_small <= f.angle_large && f.angle_large < 360.0) {
            return bad(
                "angle_small/angle_large must satisfy 0 < angle_small <= angle_large < 360",
            );
        }
        if !(0.0..=1.0).contains(&f.alpha) {
            return bad("alpha must lie in [0, 1]");
        }
        if !(0.0..=1.0).contains(&f.omega1) {
            return bad("omega1 must lie in [0, 1]");
        }
        if !(f.merge_distance >= 0.0 && f.merge_distance.is_finite()) {
            return bad("merge_distance must be a finite number >= 0");
        }
        // no triangle has a smallest angle above 60 degrees
        let min_deg = ctx
            .policy
            .checks
            .min_angle_deg
            .clamp(STEP_MIN_ANGLE_DEG, 60.0);
        Ok(Params {
            angle_small: f.angle_small.to_radians(),
            angle_large: f.angle_large.to_radians(),
            alpha: f.alpha,
            omega1: f.omega1,
            merge: f.merge_distance,
            min_angle: if min_deg.is_finite() {
                min_deg.to_radians()
            } else {
                STEP_MIN_ANGLE_DEG.to_radians()
            },
            max_steps: f.max_steps_per_vertex.max(1).saturating_mul(ctx.hole.len()),
            fair: f.fair,
        })
    }
}

/// A vertex occurrence on a front (a vertex shared by two fronts after a merge has
/// one node in each).
#[derive(Clone, Debug)]
struct Node {
    /// Patch vertex index.
    v: u32,
    prev: u32,
    next: u32,
    front: u32,
    alive: bool,
    version: u32,
    blocked: bool,
    /// Unit normal of the triangle behind the front edge `self -> next`.
    behind: DVec3,
}

/// A heap entry (min-heap on `key`).
#[derive(Clone, Copy, Debug)]
struct Entry {
    key: f64,
    node: u32,
    version: u32,
}

impl PartialEq for Entry {
    fn eq(&self, o: &Self) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Entry {
    fn cmp(&self, o: &Self) -> Ordering {
        o.key.total_cmp(&self.key).then(o.node.cmp(&self.node))
    }
}

/// The local frame at a front vertex.
#[derive(Clone, Copy, Debug)]
struct Eval {
    theta: f64,
    nc: DVec3,
    a_hat: DVec3,
    perp: DVec3,
    l: f64,
    /// Size carried to new vertices.
    s_local: f64,
    cos_phi: f64,
}

/// A patch vertex of a planned step: new, or an existing front vertex (merge).
#[derive(Clone, Copy, Debug)]
enum Slot {
    New(DVec3),
    Merge(u32),
}

/// A checked step at front node `x`: the front `prev, x, next` becomes
/// `prev, slots..., next`.
#[derive(Clone, Debug)]
struct Plan {
    x: u32,
    slots: Vec<Slot>,
    new_pos: Vec<DVec3>,
    /// Size field value of the new vertices.
    size: f64,
    tris: Vec<[u32; 3]>,
}

struct Builder<'a> {
    ctx: &'a FillContext<'a>,
    p: Params,
    k: usize,
    pos: Vec<DVec3>,
    loop_normal: Vec<DVec3>,
    acc: Vec<DVec3>,
    /// Target edge length carried by each vertex (the size field).
    size: Vec<f64>,
    hole_normal: DVec3,
    tris: Vec<[u32; 3]>,
    edges: FxSet<(u32, u32)>,
    forbidden: FxSet<(u32, u32)>,
    nodes: Vec<Node>,
    front_size: Vec<usize>,
    alive: usize,
    heap: BinaryHeap<Entry>,
    node_grid: Grid,
    node_scratch: Vec<u32>,
    mesh_tris: Vec<[DVec3; 3]>,
    obstacles: Obstacles,
    cell: f64,
    steps: usize,
    applied: usize,
    set_aside: usize,
}

#[inline]
fn ekey(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

fn failed<T>(m: impl Into<String>) -> Result<T, FillError> {
    Err(FillError::Failed(m.into()))
}

impl<'a> Builder<'a> {
    fn new(ctx: &'a FillContext<'a>, p: Params) -> Result<Builder<'a>, FillError> {
        let mesh = ctx.mesh;
        let hole = &ctx.hole.vertices;
        let k = hole.len();
        if hole.iter().any(|v| v.idx() >= mesh.num_vertices()) {
            return failed("hole vertex out of range");
        }
        let pos: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
        if pos.iter().any(|q| !q.is_finite()) {
            return failed("hole has a vertex with a non-finite coordinate");
        }
        let mut index: HashMap<VertexId, u32> =
            HashMap::with_capacity_and_hasher(k, Default::default());
        for (i, &v) in hole.iter().enumerate() {
            if index.insert(v, i as u32).is_some() {
                return failed(format!("the loop visits vertex {v} twice"));
            }
        }
        let perimeter: f64 = (0..k).map(|i| (pos[(i + 1) % k] - pos[i]).length()).sum();
        let lmean = perimeter / k as f64;
        if !(lmean > 0.0 && lmean.is_finite()) {
            return failed("the loop has zero length");
        }
        let loop_normal: Vec<DVec3> = hole.iter().map(|&v| mesh.vertex_normal(v)).collect();
        let mut hole_normal = measure::newell_normal(&pos);
        if hole_normal == DVec3::ZERO {
            hole_normal = loop_normal
                .iter()
                .copied()
                .sum::<DVec3>()
                .normalize_or_zero();
        }
        if hole_normal == DVec3::ZERO {
            return failed("cannot orient the hole (no loop or vertex normal)");
        }
        // mesh edges between loop vertices that are not loop edges
        let mut forbidden = FxSet::default();
        for (i, &v) in hole.iter().enumerate() {
            for w in mesh.topo.neighbors(v) {
                if let Some(&j) = index.get(&w) {
                    let j = j as usize;
                    if j != (i + 1) % k && i != (j + 1) % k && i != j {
                        forbidden.insert(ekey(i as u32, j as u32));
                    }
                }
            }
        }
        let mut edges = FxSet::default();
        edges.reserve(k * 8);
        for i in 0..k {
            edges.insert(ekey(i as u32, ((i + 1) % k) as u32));
        }
        // the mesh face behind each loop edge i -> i+1 holds the half-edge i+1 -> i
        let mut nodes = Vec::with_capacity(k * 4);
        for i in 0..k {
            let a = hole[(i + 1) % k];
            let b = hole[i];
            let behind = mesh
                .topo
                .outgoing(a)
                .find(|&h| mesh.topo.to(h) == b)
                .map(|h| mesh.face_normal_raw(h.face()).normalize_or_zero())
                .unwrap_or(DVec3::ZERO);
            nodes.push(Node {
                v: i as u32,
                prev: ((i + k - 1) % k) as u32,
                next: ((i + 1) % k) as u32,
                front: 0,
                alive: true,
                version: 0,
                blocked: false,
                behind,
            });
        }
        let cell = lmean;
        let mut node_grid = Grid::new(cell);
        for (i, q) in pos.iter().enumerate() {
            node_grid.insert(i as u32, *q, *q);
        }
        // mesh triangles near the hole: its box grown by half its diagonal and a few edges
        let (lo, hi) = pos.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(l, h), q| (l.min(*q), h.max(*q)),
        );
        let margin = 0.5 * (hi - lo).length() + 4.0 * lmean;
        let (lo, hi) = (lo - DVec3::splat(margin), hi + DVec3::splat(margin));
        let mut obstacles = Obstacles::new(2.0 * cell);
        let mut mesh_tris = Vec::new();
        // A triangle's box misses [lo, hi] when on some axis all three corners lie
        // beyond the same side: the per-vertex outcodes (one bit per side and axis)
        // then share a bit. One pass over the vertices and one over the faces'
        // indices, instead of loading every triangle's corners (10M-face scans).
        let outcode: Vec<u8> = mesh
            .positions
            .iter()
            .map(|q| {
                let below = q.cmplt(lo).bitmask() as u8;
                let above = q.cmpgt(hi).bitmask() as u8;
                // a non-finite corner gives a non-finite box: skipped as before
                if q.is_finite() {
                    below | above << 3
                } else {
                    0x40
                }
            })
            .collect();
        for (f, fv) in mesh.topo.faces().iter().enumerate() {
            let codes = fv.map(|v| outcode.get(v.idx()).copied().unwrap_or(0x40));
            if codes[0] & codes[1] & codes[2] != 0 || (codes[0] | codes[1] | codes[2]) & 0x40 != 0 {
                continue;
            }
            let t = mesh.tri(crate::mesh::FaceId::from_idx(f));
            obstacles.add(t);
            mesh_tris.push(t);
        }
        let acc = vec![DVec3::ZERO; k];
        let size: Vec<f64> = (0..k)
            .map(|i| {
                let m = mesh.mean_incident_edge_length(hole[i]);
                if m > 0.0 && m.is_finite() {
                    m
                } else {
                    0.5 * ((pos[(i + 1) % k] - pos[i]).length()
                        + (pos[(i + k - 1) % k] - pos[i]).length())
                }
            })
            .collect();
        Ok(Builder {
            ctx,
            p,
            k,
            pos,
            loop_normal,
            acc,
            size,
            hole_normal,
            tris: Vec::new(),
            edges,
            forbidden,
            nodes,
            front_size: vec![k],
            alive: k,
            heap: BinaryHeap::new(),
            node_grid,
            node_scratch: Vec::new(),
            mesh_tris,
            obstacles,
            cell,
            steps: 0,
            applied: 0,
            set_aside: 0,
        })
    }

    // ----- geometry -------------------------------------------------------------

    fn vnormal(&self, v: u32) -> DVec3 {
        let v = v as usize;
        if v < self.k && self.loop_normal[v] != DVec3::ZERO {
            return self.loop_normal[v];
        }
        let n = self.acc[v].normalize_or_zero();
        if n == DVec3::ZERO {
            self.hole_normal
        } else {
            n
        }
    }

    fn npos(&self, node: u32) -> DVec3 {
        self.pos[self.nodes[node as usize].v as usize]
    }

    /// The angle and local frame at a front node.
    fn eval(&self, x: u32) -> Eval {
        let nd = &self.nodes[x as usize];
        let (p, n) = (nd.prev, nd.next);
        let pi = self.npos(x);
        let pp = self.npos(p);
        let pn = self.npos(n);
        let mut ni = self.vnormal(nd.v);
        let size = self.front_size[nd.front as usize];
        let w = ((size as f64 / 10.0).round() as usize)
            .min(size.saturating_sub(1) / 2)
            .max(1);
        let (mut sl, mut sr) = (DVec3::ZERO, DVec3::ZERO);
        let (mut cl, mut cr) = (x, x);
        for _ in 0..w {
            cl = self.nodes[cl as usize].prev;
            cr = self.nodes[cr as usize].next;
            sl += self.npos(cl) - pi;
            sr += self.npos(cr) - pi;
        }
        let mut ne = sr.cross(sl).normalize_or_zero();
        if ne.dot(ni) < 0.0 {
            ne = -ne;
        }
        if ni == DVec3::ZERO {
            ni = self.hole_normal;
        }
        if ne == DVec3::ZERO || !ne.is_finite() {
            ne = ni;
        }
        let mut nc = (self.p.alpha * ni + (1.0 - self.p.alpha) * ne).normalize_or_zero();
        if nc == DVec3::ZERO || !nc.is_finite() {
            nc = ni;
        }
        let a = pn - pi;
        let b = pp - pi;
        let (la, lb) = (a.length(), b.length());
        let ap = a - nc * a.dot(nc);
        let bp = b - nc * b.dot(nc);
        let s_local = (self.size[nd.v as usize]
            + self.size[self.nodes[p as usize].v as usize]
            + self.size[self.nodes[n as usize].v as usize])
            / 3.0;
        let l = 0.5 * (0.5 * (la + lb)) + 0.5 * s_local;
        let (theta, a_hat) = if ap.length() > 1e-9 * la && bp.length() > 1e-9 * lb {
            let a_hat = ap.normalize();
            let perp = nc.cross(a_hat);
            let mut t = bp.dot(perp).atan2(bp.dot(a_hat));
            if t < 0.0 {
                t += 2.0 * PI;
            }
            (t, a_hat)
        } else {
            (PI, nc.any_orthonormal_vector())
        };
        let perp = nc.cross(a_hat);
        // Taubin curvature at the two neighbours along their edges to v_i
        let taubin = |q: DVec3, nq: DVec3| {
            let e = pi - q;
            let d = e.length_squared();
            if d > 0.0 {
                2.0 * nq.dot(e) / d
            } else {
                0.0
            }
        };
        let kappa = 0.5
            * (taubin(pp, self.vnormal(self.nodes[p as usize].v))
                + taubin(pn, self.vnormal(self.nodes[n as usize].v)));
        let slope = if la > 0.0 && lb > 0.0 {
            0.5 * (nc.dot(a) / la + nc.dot(b) / lb)
        } else {
            0.0
        };
        let c = self.p.omega1 * kappa * l * 0.5 + (1.0 - self.p.omega1) * slope;
        let cos_phi = if c.is_finite() {
            c.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        Eval {
            theta,
            nc,
            a_hat,
            perp,
            l,
            s_local,
            cos_phi,
        }
    }

    /// New vertex at rotation `psi` from the direction to `next`.
    fn place(&self, x: u32, ev: &Eval, psi: f64) -> DVec3 {
        let t = ev.a_hat * psi.cos() + ev.perp * psi.sin();
        let sin_phi = (1.0 - ev.cos_phi * ev.cos_phi).max(0.0).sqrt();
        self.npos(x) + ev.l * (ev.cos_phi * ev.nc + sin_phi * t)
    }

    /// The nearest node of `x`'s front within `r` of `q`, other than `x` and its
    /// two neighbours.
    fn nearest_front_node(&mut self, x: u32, q: DVec3, r: f64) -> Option<u32> {
        let nd = &self.nodes[x as usize];
        let (f, p, n) = (nd.front, nd.prev, nd.next);
        let mut ids = std::mem::take(&mut self.node_scratch);
        ids.clear();
        self.node_grid
            .query(q - DVec3::splat(r), q + DVec3::splat(r), &mut ids);
        let mut best: Option<(f64, u32)> = None;
        for &c in &ids {
            let cn = &self.nodes[c as usize];
            if !cn.alive || cn.front != f || c == x || c == p || c == n {
                continue;
            }
            let d = (self.pos[cn.v as usize] - q).length();
            if d <= r && best.is_none_or(|(bd, bc)| d < bd || (d == bd && c < bc)) {
                best = Some((d, c));
            }
        }
        self.node_scratch = ids;
        best.map(|(_, c)| c)
    }

    // ----- planning ---------------------------------------------------------------

    /// Checks the step that replaces `x` by `slots` on its front.
    fn check(&mut self, x: u32, ev: &Eval, slots: Vec<Slot>) -> Option<Plan> {
        let nd = self.nodes[x as usize].clone();
        let (p, n) = (nd.prev, nd.next);
        let (vi, vp, vn) = (nd.v, self.nodes[p as usize].v, self.nodes[n as usize].v);
        let base = self.pos.len() as u32;
        let mut new_pos = Vec::new();
        let mut s = Vec::with_capacity(slots.len());
        let mut merged: Option<u32> = None;
        for sl in &slots {
            match *sl {
                Slot::New(q) => {
                    if !q.is_finite() {
                        return None;
                    }
                    s.push(base + new_pos.len() as u32);
                    new_pos.push(q);
                }
                Slot::Merge(w) => {
                    let wn = &self.nodes[w as usize];
                    if merged.is_some()
                        || !wn.alive
                        || wn.front != nd.front
                        || w == x
                        || w == p
                        || w == n
                    {
                        return None;
                    }
                    merged = Some(w);
                    s.push(wn.v);
                }
            }
        }
        let m = s.len();
        let mut tris = Vec::with_capacity(m + 1);
        if m == 0 {
            tris.push([vp, vi, vn]);
        } else {
            tris.push([vp, vi, s[0]]);
            for j in 0..m - 1 {
                tris.push([vi, s[j + 1], s[j]]);
            }
            tris.push([vi, vn, s[m - 1]]);
        }
        let at = |i: u32| -> DVec3 {
            if i < base {
                self.pos[i as usize]
            } else {
                new_pos[(i - base) as usize]
            }
        };
        // geometry of each triangle
        let mut normals = Vec::with_capacity(tris.len());
        for t in &tris {
            let [a, b, c] = t.map(at);
            if measure::smallest_angle_sin(a, b, c) < self.p.min_angle.sin() {
                return None;
            }
            let nr = measure::tri_normal_raw(a, b, c).normalize_or_zero();
            let facing = nr.dot(ev.nc) > 0.0;
            if !facing {
                return None;
            }
            normals.push(nr);
        }
        // no fold over the triangles behind the front edges it closes
        if normals[0].dot(self.nodes[p as usize].behind) < FOLD_COS
            || normals[m].dot(nd.behind) < FOLD_COS
        {
            return None;
        }
        // edges: consumed front edges, new interior edges, new front edges
        let mut consumed: Vec<(u32, u32)> = vec![(vp, vi), (vi, vn)];
        if let Some(w) = merged {
            let wv = self.nodes[w as usize].v;
            if self.nodes[n as usize].next == w {
                consumed.push((vn, wv));
                if normals[m].dot(self.nodes[n as usize].behind) < FOLD_COS {
                    return None;
                }
            }
            if self.nodes[p as usize].prev == w {
                consumed.push((wv, vp));
                if normals[0].dot(self.nodes[w as usize].behind) < FOLD_COS {
                    return None;
                }
            }
        }
        let mut directed: Vec<(u32, u32)> = Vec::with_capacity(tris.len() * 3);
        for t in &tris {
            for c in 0..3 {
                let e = (t[c], t[(c + 1) % 3]);
                if directed.contains(&e) {
                    return None;
                }
                directed.push(e);
            }
        }
        for &(a, b) in &directed {
            if consumed.contains(&(a, b)) {
                continue;
            }
            if self.edges.contains(&ekey(a, b)) {
                return None;
            }
            if (a as usize) < self.k
                && (b as usize) < self.k
                && self.forbidden.contains(&ekey(a, b))
            {
                return None;
            }
        }
        // no overlap with the patch, the mesh, or each other
        let geo: Vec<[DVec3; 3]> = tris.iter().map(|t| t.map(at)).collect();
        for (i, g) in geo.iter().enumerate() {
            if self.obstacles.find_overlap(g, |_| false).is_some() {
                return None;
            }
            for h in &geo[i + 1..] {
                if intersect::overlap(g, h) {
                    return None;
                }
            }
        }
        Some(Plan {
            x,
            slots,
            new_pos,
            size: ev.s_local,
            tris,
        })
    }

    /// The step for `n_new` new vertices at `x` (0: ear), merging a new vertex into a
    /// nearby front vertex when `merge` is set.
    fn step_slots(&mut self, x: u32, ev: &Eval, n_new: usize, merge: bool) -> Option<Vec<Slot>> {
        let r = self.p.merge * ev.l;
        let mut slots = Vec::with_capacity(n_new);
        // front order: prev, s_1 (largest rotation) ... s_m (smallest), next
        for j in (1..=n_new).rev() {
            let psi = ev.theta * j as f64 / (n_new + 1) as f64;
            let q = self.place(x, ev, psi);
            let slot = if merge && r > 0.0 {
                match self.nearest_front_node(x, q, r) {
                    Some(w) => Slot::Merge(w),
                    None => Slot::New(q),
                }
            } else {
                Slot::New(q)
            };
            slots.push(slot);
        }
        if slots.iter().filter(|s| matches!(s, Slot::Merge(_))).count() > 1 {
            return None;
        }
        Some(slots)
    }

    /// Tries the rule's step at `x`, then the fallbacks.
    fn try_steps(&mut self, x: u32, ev: &Eval) -> Option<Plan> {
        let th = ev.theta;
        let rule = if th <= self.p.angle_small {
            0
        } else if th <= self.p.angle_large {
            1
        } else {
            2
        };
        let mut order: Vec<(usize, bool)> = vec![(rule, true)];
        match rule {
            0 => order.push((1, true)),
            1 => {
                order.push((1, false));
                if th < PI {
                    order.push((0, true));
                }
            }
            _ => {
                order.push((2, false));
                order.push((1, true));
            }
        }
        for (n_new, merge) in order {
            if let Some(slots) = self.step_slots(x, ev, n_new, merge) {
                if let Some(plan) = self.check(x, ev, slots) {
                    return Some(plan);
                }
            }
        }
        // last resort: join x to the nearest vertex of its front near the bisector
        let q = self.place(x, ev, 0.5 * th);
        if let Some(w) = self.nearest_front_node(x, q, 1.5 * ev.l) {
            if let Some(plan) = self.check(x, ev, vec![Slot::Merge(w)]) {
                return Some(plan);
            }
        }
        None
    }

    // ----- applying -------------------------------------------------------------

    fn emit(&mut self, t: [u32; 3]) -> DVec3 {
        let [a, b, c] = t.map(|i| self.pos[i as usize]);
        let nr = measure::tri_normal_raw(a, b, c);
        for &v in &t {
            self.acc[v as usize] += nr;
        }
        for c in 0..3 {
            self.edges.insert(ekey(t[c], t[(c + 1) % 3]));
        }
        self.obstacles.add([a, b, c]);
        self.tris.push(t);
        nr.normalize_or_zero()
    }

    fn new_node(&mut self, v: u32, front: u32, behind: DVec3) -> u32 {
        let id = self.nodes.len() as u32;
        self.nodes.push(Node {
            v,
            prev: id,
            next: id,
            front,
            alive: true,
            version: 0,
            blocked: false,
            behind,
        });
        let q = self.pos[v as usize];
        self.node_grid.insert(id, q, q);
        self.alive += 1;
        id
    }

    fn link(&mut self, a: u32, b: u32) {
        self.nodes[a as usize].next = b;
        self.nodes[b as usize].prev = a;
    }

    fn kill(&mut self, x: u32) {
        let nd = &mut self.nodes[x as usize];
        if nd.alive {
            nd.alive = false;
            nd.version = nd.version.wrapping_add(1);
            self.alive -= 1;
        }
    }

    fn apply(&mut self, plan: Plan) -> Result<(), FillError> {
        let x = plan.x;
        let nd = self.nodes[x as usize].clone();
        let (p, n, f) = (nd.prev, nd.next, nd.front);
        for q in &plan.new_pos {
            self.pos.push(*q);
            self.acc.push(DVec3::ZERO);
            self.size.push(plan.size);
        }
        let tn: Vec<DVec3> = plan.tris.iter().map(|&t| self.emit(t)).collect();
        let base = (self.pos.len() - plan.new_pos.len()) as u32;
        let m = plan.slots.len();
        // chain nodes in front order
        let mut chain = Vec::with_capacity(m);
        let mut merged_at = None;
        let mut next_new = base;
        for (j, sl) in plan.slots.iter().enumerate() {
            match *sl {
                Slot::New(_) => {
                    let id = self.new_node(next_new, f, tn[j + 1]);
                    next_new += 1;
                    chain.push(id);
                }
                Slot::Merge(w) => {
                    merged_at = Some(j);
                    chain.push(w);
                }
            }
        }
        self.kill(x);
        self.nodes[p as usize].behind = tn[0];
        let mut touched = vec![p, n];
        touched.extend_from_slice(&chain);
        let mut fronts = vec![f];
        match merged_at {
            None => {
                let mut prev = p;
                for &c in &chain {
                    self.link(prev, c);
                    prev = c;
                }
                self.link(prev, n);
                self.front_size[f as usize] = self.front_size[f as usize] + m - 1;
            }
            Some(jm) => {
                let w = chain[jm];
                let old_next = self.nodes[w as usize].next;
                let old_behind = self.nodes[w as usize].behind;
                let wv = self.nodes[w as usize].v;
                let w2 = self.new_node(wv, f, old_behind);
                touched.push(w2);
                // loop 2: p, chain[..jm], w2, old_next ...
                let mut prev = p;
                for &c in &chain[..jm] {
                    self.link(prev, c);
                    prev = c;
                }
                self.link(prev, w2);
                self.link(w2, old_next);
                // loop 1: w, chain[jm+1..], n ...
                self.nodes[w as usize].behind = tn[jm + 1];
                let mut prev = w;
                for &c in &chain[jm + 1..] {
                    self.link(prev, c);
                    prev = c;
                }
                self.link(prev, n);
                let total = self.front_size[f as usize] + m - 1; // -1 (x) + (m-1) new + 1 (w2)
                let f2 = self.front_size.len() as u32;
                let (small, size) = self.smaller_loop(w, w2)?;
                let mut c = small;
                loop {
                    self.nodes[c as usize].front = f2;
                    c = self.nodes[c as usize].next;
                    if c == small {
                        break;
                    }
                }
                self.front_size.push(size);
                self.front_size[f as usize] = match total.checked_sub(size) {
                    Some(x) => x,
                    None => return failed("internal: front sizes out of step"),
                };
                fronts.push(f2);
            }
        }
        for &fr in &fronts {
            let start = touched.iter().copied().find(|&t| {
                let tn = &self.nodes[t as usize];
                tn.alive && tn.front == fr
            });
            if let Some(s) = start {
                self.close_small(fr, s)?;
            }
        }
        for t in touched {
            self.rekey(t);
        }
        Ok(())
    }

    /// Walks the loops through `a` and `b` in turn; returns the start and size of the
    /// one that closes first (cost: twice the smaller size).
    fn smaller_loop(&self, a: u32, b: u32) -> Result<(u32, usize), FillError> {
        let (mut ca, mut cb) = (a, b);
        for n in 1..=self.nodes.len() {
            ca = self.nodes[ca as usize].next;
            if ca == a {
                return Ok((a, n));
            }
            cb = self.nodes[cb as usize].next;
            if cb == b {
                return Ok((b, n));
            }
        }
        failed("internal: a front is not a closed loop")
    }

    fn front_nodes(&self, start: u32) -> Vec<u32> {
        let mut out = vec![start];
        let mut c = self.nodes[start as usize].next;
        while c != start && out.len() <= self.nodes.len() {
            out.push(c);
            c = self.nodes[c as usize].next;
        }
        out
    }

    /// Closes a front of at most four vertices when it can.
    fn close_small(&mut self, f: u32, start: u32) -> Result<(), FillError> {
        let size = self.front_size[f as usize];
        if size > 4 {
            return Ok(());
        }
        let ns = self.front_nodes(start);
        if ns.len() != size {
            return failed(format!(
                "internal: front of {} nodes recorded as {size}",
                ns.len()
            ));
        }
        let vs: Vec<u32> = ns.iter().map(|&c| self.nodes[c as usize].v).collect();
        match size {
            0..=2 => {}
            3 => {
                let t = [vs[0], vs[1], vs[2]];
                let g = t.map(|i| self.pos[i as usize]);
                if measure::tri_normal_raw(g[0], g[1], g[2]) == DVec3::ZERO {
                    return failed("the last triangle of a front is degenerate");
                }
                if self.obstacles.find_overlap(&g, |_| false).is_some() {
                    return failed("the last triangle of a front overlaps the patch or the mesh");
                }
                self.emit(t);
            }
            _ => {
                let mut best: Option<(f64, [[u32; 3]; 2])> = None;
                for d in 0..2 {
                    let (a, b, c, e) = (vs[d], vs[d + 1], vs[(d + 2) % 4], vs[(d + 3) % 4]);
                    let pair = [[a, b, c], [c, e, a]];
                    if self.edges.contains(&ekey(a, c))
                        || ((a as usize) < self.k
                            && (c as usize) < self.k
                            && self.forbidden.contains(&ekey(a, c)))
                    {
                        continue;
                    }
                    let g = pair.map(|t| t.map(|i| self.pos[i as usize]));
                    let n0 = measure::tri_normal_raw(g[0][0], g[0][1], g[0][2]);
                    let n1 = measure::tri_normal_raw(g[1][0], g[1][1], g[1][2]);
                    let unfolded = n0.dot(n1) > FOLD_COS * n0.length() * n1.length();
                    if !unfolded {
                        continue;
                    }
                    if g.iter().any(|t| {
                        measure::smallest_angle(t[0], t[1], t[2])
                            < self.p.min_angle.min(0.5f64.to_radians())
                    }) {
                        continue;
                    }
                    if g.iter()
                        .any(|t| self.obstacles.find_overlap(t, |_| false).is_some())
                        || intersect::overlap(&g[0], &g[1])
                    {
                        continue;
                    }
                    let q = measure::quality(g[0][0], g[0][1], g[0][2])
                        .min(measure::quality(g[1][0], g[1][1], g[1][2]));
                    if best.is_none_or(|(bq, _)| q > bq) {
                        best = Some((q, pair));
                    }
                }
                let Some((_, pair)) = best else {
                    // no diagonal: a centre vertex, else left to the main loop
                    self.close_fan(start);
                    return Ok(());
                };
                for t in pair {
                    self.emit(t);
                }
            }
        }
        for c in ns {
            self.kill(c);
        }
        Ok(())
    }

    /// Closes the front through `start` with a new vertex at its centroid joined to
    /// every front edge, if all those triangles pass the step checks. Returns whether
    /// it did.
    fn close_fan(&mut self, start: u32) -> bool {
        let ns = self.front_nodes(start);
        let m = ns.len();
        if m < 3 || m != self.front_size[self.nodes[start as usize].front as usize] {
            return false;
        }
        let vs: Vec<u32> = ns.iter().map(|&c| self.nodes[c as usize].v).collect();
        let pts: Vec<DVec3> = vs.iter().map(|&v| self.pos[v as usize]).collect();
        let c = measure::centroid(&pts);
        let mut up = vs.iter().map(|&v| self.vnormal(v)).sum::<DVec3>();
        if up == DVec3::ZERO {
            up = measure::newell_normal(&pts);
        }
        let min_sin = self.p.min_angle.sin();
        let mut geo = Vec::with_capacity(m);
        for j in 0..m {
            let t = [pts[j], pts[(j + 1) % m], c];
            let nr = measure::tri_normal_raw(t[0], t[1], t[2]).normalize_or_zero();
            let behind = self.nodes[ns[j] as usize].behind;
            if measure::smallest_angle_sin(t[0], t[1], t[2]) < min_sin
                || nr.dot(up) <= 0.0
                || nr.dot(behind) < FOLD_COS
            {
                return false;
            }
            geo.push(t);
        }
        for (i, g) in geo.iter().enumerate() {
            if self.obstacles.find_overlap(g, |_| false).is_some()
                || geo[i + 1..].iter().any(|h| intersect::overlap(g, h))
            {
                return false;
            }
        }
        let id = self.pos.len() as u32;
        let size = vs.iter().map(|&v| self.size[v as usize]).sum::<f64>() / m as f64;
        self.pos.push(c);
        self.acc.push(DVec3::ZERO);
        self.size.push(size);
        for j in 0..m {
            self.emit([vs[j], vs[(j + 1) % m], id]);
        }
        for n in ns {
            self.kill(n);
        }
        true
    }

    fn rekey(&mut self, x: u32) {
        if !self.nodes[x as usize].alive {
            return;
        }
        let ev = self.eval(x);
        let nd = &mut self.nodes[x as usize];
        nd.version = nd.version.wrapping_add(1);
        nd.blocked = false;
        self.heap.push(Entry {
            key: ev.theta,
            node: x,
            version: nd.version,
        });
    }

    // ----- main loop ------------------------------------------------------------

    fn run(&mut self) -> Result<(), FillError> {
        self.close_small(0, 0)?;
        for x in 0..self.k as u32 {
            self.rekey(x);
        }
        while self.alive > 0 {
            self.ctx.deadline.check()?;
            let Some(e) = self.heap.pop() else {
                return failed("internal: front vertices left without a queue entry");
            };
            let nd = &self.nodes[e.node as usize];
            if !nd.alive || nd.version != e.version {
                continue;
            }
            if nd.blocked {
                // every vertex is set aside: close a small front around a centre vertex
                let f = nd.front as usize;
                if self.front_size[f] <= FAN_MAX && self.close_fan(e.node) {
                    continue;
                }
                return failed(format!(
                    "the front is stuck: no valid step at any of its {} vertices",
                    self.alive
                ));
            }
            self.steps += 1;
            let cap = self.ctx.policy.limits.max_patch_triangles;
            if cap > 0 && self.tris.len() > cap {
                return failed(format!(
                    "the patch passed limits.max_patch_triangles = {cap} triangles with {} front vertices left",
                    self.alive
                ));
            }
            if self.steps > self.p.max_steps {
                return failed(format!(
                    "front did not close after {} steps ({} taken, {} set aside; {} triangles, {} front vertices left)",
                    self.p.max_steps,
                    self.applied,
                    self.set_aside,
                    self.tris.len(),
                    self.alive
                ));
            }
            let ev = self.eval(e.node);
            if ev.theta > e.key + 1e-12 {
                if let Some(top) = self.heap.peek() {
                    if top.key < ev.theta {
                        let nd = &mut self.nodes[e.node as usize];
                        nd.version = nd.version.wrapping_add(1);
                        self.heap.push(Entry {
                            key: ev.theta,
                            node: e.node,
                            version: nd.version,
                        });
                        continue;
                    }
                }
            }
            match self.try_steps(e.node, &ev) {
                Some(plan) => {
                    self.applied += 1;
                    self.apply(plan)?;
                    if self.alive > DIVERGE_FACTOR * self.k + 64 {
                        return failed(format!(
                            "the front diverges: {} front vertices from a loop of {} after {} steps",
                            self.alive, self.k, self.steps
                        ));
                    }
                }
                None => {
                    let nd = &mut self.nodes[e.node as usize];
                    nd.version = nd.version.wrapping_add(1);
                    nd.blocked = true;
                    self.set_aside += 1;
                    self.heap.push(Entry {
                        key: ev.theta + BLOCKED,
                        node: e.node,
                        version: nd.version,
                    });
                }
            }
        }
        Ok(())
    }

    // ----- finishing ------------------------------------------------------------

    /// True when no two patch triangles overlap and none overlaps the mesh.
    fn patch_is_clean(&self, pos: &[DVec3], tris: &[[u32; 3]]) -> bool {
        // the dispatcher's degenerate-triangle rule first (fairing can make slivers)
        let patch = Patch {
            new_vertices: Vec::new(),
            triangles: tris.to_vec(),
        };
        if crate::check::check_degenerate(pos, &patch, &self.ctx.policy.checks).is_err() {
            return false;
        }
        let mut ob = Obstacles::new(2.0 * self.cell);
        for t in &self.mesh_tris {
            ob.add(*t);
        }
        let first = ob.len() as u32;
        let geo: Vec<[DVec3; 3]> = tris.iter().map(|t| t.map(|i| pos[i as usize])).collect();
        for g in &geo {
            ob.add(*g);
        }
        geo.iter()
            .enumerate()
            .all(|(i, g)| ob.find_overlap(g, |id| id == first + i as u32).is_none())
    }

    fn finish(self) -> Result<Patch, FillError> {
        let k = self.k;
        let rules = improve::SwapRules {
            k,
            forbidden: &self.forbidden,
            min_angle: self.p.min_angle.min(0.5f64.to_radians()),
        };
        let raw_tris = self.tris.clone();
        let mut tris = self.tris.clone();
        let t = std::time::Instant::now();
        let n_swaps = improve::swap_edges(&self.pos, &mut tris, &rules, SWAPS_PER_TRIANGLE);
        tracing::debug!(
            ms = t.elapsed().as_secs_f64() * 1e3,
            n_swaps,
            "advancing front: swaps"
        );
        self.ctx.deadline.check()?;
        let mut candidates: Vec<(Vec<DVec3>, Vec<[u32; 3]>)> = Vec::new();
        if self.p.fair {
            // umbrella relaxation evens out the triangles, then the fairing solve
            // (`fill::fair`, the `[fair]` policy) gives the patch its shape
            let mut patch = Patch {
                new_vertices: self.pos[k..].to_vec(),
                triangles: tris.clone(),
            };
            let t = std::time::Instant::now();
            let faired = relax(
                self.ctx.mesh,
                self.ctx.hole,
                &mut patch,
                &self.ctx.policy.fair,
            )
            .and_then(|()| {
                // the first solve's cotangent weights come from the flat front; a
                // second solve on the curved result gets them right
                let (mesh, hole, fair) = (self.ctx.mesh, self.ctx.hole, &self.ctx.policy.fair);
                fair::fair_patch(mesh, hole, &mut patch, fair)?;
                fair::fair_patch(mesh, hole, &mut patch, fair)
            });
            match faired {
                Ok(()) if patch.new_vertices.len() == self.pos.len() - k => {
                    let mut pos = self.pos.clone();
                    pos[k..].copy_from_slice(&patch.new_vertices);
                    let mut t2 = patch.triangles;
                    improve::swap_edges(&pos, &mut t2, &rules, SWAPS_PER_TRIANGLE);
                    candidates.push((pos, t2));
                }
                Ok(()) => {
                    tracing::debug!("advancing front: fairing changed the vertex count; not used")
                }
                Err(FillError::Timeout) => return Err(FillError::Timeout),
                Err(FillError::Failed(why)) => {
                    tracing::debug!(%why, "advancing front: fairing failed; not used")
                }
            }
            tracing::debug!(
                ms = t.elapsed().as_secs_f64() * 1e3,
                "advancing front: fairing"
            );
        }
        candidates.push((self.pos.clone(), tris));
        candidates.push((self.pos.clone(), raw_tris));
        for (pos, tris) in candidates {
            self.ctx.deadline.check()?;
            let t = std::time::Instant::now();
            let clean = self.patch_is_clean(&pos, &tris);
            tracing::debug!(
                ms = t.elapsed().as_secs_f64() * 1e3,
                clean,
                "advancing front: patch verified"
            );
            if clean {
                return Ok(Patch {
                    new_vertices: pos[k..].to_vec(),
                    triangles: tris,
                });
            }
        }
        failed("the closed front overlaps itself or the mesh")
    }
}

/// A few iterations of umbrella smoothing of the new vertices, the loop fixed (see
/// [`improve::relax`]), before the fairing solve.
fn relax(
    mesh: &crate::mesh::Mesh,
    hole: &crate::patch::Hole,
    patch: &mut Patch,
    _opts: &crate::policy::Fair,
) -> Result<(), FillError> {
    let k = hole.len();
    let mut pos: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
    pos.extend_from_slice(&patch.new_vertices);
    if patch
        .triangles
        .iter()
        .flatten()
        .any(|&i| i as usize >= pos.len())
    {
        return failed("patch index out of range");
    }
    improve::relax(
        &mut pos,
        k,
        &patch.triangles,
        RELAX_ITERATIONS,
        RELAX_LAMBDA,
        RELAX_MIN_ANGLE_DEG.to_radians(),
    );
    patch.new_vertices.copy_from_slice(&pos[k..]);
    Ok(())
}
