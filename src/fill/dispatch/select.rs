//! Per-hole choice of method (not from the four papers; issue 19): by self-validation
//! (`select.mode = "validate"`) or by a rule from the rim (`"rim"`, [`rim`]).
//!
//! No method is best on every hole, and the true surface of a hole is unknown; the
//! surface around it is known. So the hole is grown by some rings of input faces (the
//! faces with a corner on the current loop, ring by ring: `select.rings`, or one per
//! `select.vertices_per_ring` boundary vertices when that is more, since a large hole
//! is lost or won in its middle, which a thin band along its rim does not test), each
//! candidate fills the grown hole on a copy of the surrounding surface
//! (`CONTEXT_RINGS` more rings, so that a method sees the rim it would see on the real
//! hole), and its patch is scored by the mean distance from the known points it
//! replaced (the removed faces' vertices inside the grown hole, the original loop
//! among them, and the removed faces' centroids) to the patch. A candidate runs its
//! own fill only, without the dispatcher's relaxation and checks or its variants: the
//! score is of its surface, and the real hole gets the full treatment. The
//! best-scoring candidate goes first on the real hole; the others keep the list's
//! order, so the fallback chain is as before. Surface the grown region encloses joins
//! it; a region that is still not a disk (its rim pinched, another hole or the border
//! reached) is grown by one ring fewer at a time, down to one, and otherwise the list's
//! order is kept, with the reason in the log. Measurements: docs/measurements.md.
//!
//! The rim rule reads no candidate's patch: where most edges around the loop are flat
//! (a machined, piecewise-planar surface) `select.flat_method` goes first, elsewhere
//! the list's order; it costs a walk over a few rings.

use super::{guarded, run_method_fill};
use crate::fill::kit::{Deadline, FillContext};
use crate::geometry::bvh::{closest_on_triangles, tri_box, Bvh};
use crate::io::RawMesh;
use crate::mesh::{FaceId, Mesh, VertexId};
use crate::patch::{Hole, Patch};
use crate::policy::{Method, Policy, Select, SelectMode};
use crate::report::{Candidate, RimReading, Selection};
use glam::DVec3;
use std::collections::HashMap;
use std::time::Instant;

/// Rings of surface kept around the grown hole for the candidates to read (rim
/// normals, the fairing's outer ring, the LS-SVM's fitting rings).
const CONTEXT_RINGS: usize = 4;

/// The order in which the methods of `methods` (the hole's class list) are tried on
/// `hole`, and the selection that made it (`None` when the policy compares nothing
/// for this hole: mode `first`, or fewer than two candidates in the list).
pub fn order(
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    methods: &[Method],
) -> (Vec<Method>, Option<Selection>) {
    let sel = match policy.select.mode {
        SelectMode::First => None,
        _ if hole.len() < 3 => None,
        SelectMode::Rim => {
            if methods.contains(&policy.select.flat_method) {
                Some(rim(mesh, hole, &policy.select))
            } else {
                None
            }
        }
        SelectMode::Validate => {
            let candidates: Vec<Method> = methods
                .iter()
                .copied()
                .filter(|m| policy.select.methods.contains(m))
                .collect();
            if candidates.len() < 2 {
                None
            } else {
                Some(validate(mesh, hole, policy, &candidates))
            }
        }
    };
    let mut order = methods.to_vec();
    if let Some(w) = sel.as_ref().and_then(|s| s.winner) {
        order.retain(|&m| m != w);
        order.insert(0, w);
    }
    (order, sel)
}

/// The `rim` rule: reads the interior edges with both ends within `select.rings`
/// rings of the loop (vertex rings: the loop, its neighbours, theirs), and puts
/// `select.flat_method` first when at least `select.flat_share` of them are flat.
///
/// Why flatness: on the bench's CAD parts (fandisk, joint) the rows of the wavefront
/// continue the planes and the thin-plate surface of `min_area_fair` bulges between
/// them (seeds 1-5: 6.25 against 7.38 per mille on fandisk, 9.87 against 10.77 on
/// joint), while on the scans the thin plate is closer. A machined surface is flat
/// almost everywhere with creases between the flats, so most of its edges have a
/// dihedral angle of nearly 0; a scanned one almost never does (noise). Measured per
/// hole on the bench's outputs: shares from 0.4 to 0.6 split the meshes alike.
pub fn rim(mesh: &Mesh, hole: &Hole, select: &Select) -> Selection {
    let t0 = Instant::now();
    let topo = &mesh.topo;
    let n = mesh.num_vertices();
    let mut inside = vec![false; n];
    let mut frontier: Vec<VertexId> = Vec::new();
    for &v in &hole.vertices {
        if v.idx() < n && !inside[v.idx()] {
            inside[v.idx()] = true;
            frontier.push(v);
        }
    }
    let mut region = frontier.clone();
    for _ in 0..select.rings {
        let mut next = Vec::new();
        for &v in &frontier {
            for w in topo.neighbors(v) {
                if w.idx() < n && !inside[w.idx()] {
                    inside[w.idx()] = true;
                    next.push(w);
                }
            }
        }
        region.extend_from_slice(&next);
        frontier = next;
    }
    let cos_flat = select.flat_angle_deg.to_radians().cos();
    let (mut edges, mut flat) = (0usize, 0usize);
    for &v in &region {
        for h in topo.outgoing(v) {
            let w = topo.to(h);
            // each interior edge once, from its smaller end
            let Some(t) = topo.twin(h) else { continue };
            if w.idx() >= n || !inside[w.idx()] || w.idx() < v.idx() {
                continue;
            }
            let a = mesh.face_normal_raw(h.face());
            let b = mesh.face_normal_raw(t.face());
            let (la, lb) = (a.length(), b.length());
            edges += 1;
            if la > 0.0 && lb > 0.0 && a.dot(b) >= cos_flat * la * lb {
                flat += 1;
            }
        }
    }
    let share = (edges > 0).then(|| flat as f64 / edges as f64);
    let (winner, reason) = match share {
        Some(s) if s >= select.flat_share => (Some(select.flat_method), String::new()),
        Some(s) => (
            None,
            format!(
                "{:.0} % of the rim's edges are flat, under select.flat_share",
                100.0 * s
            ),
        ),
        None => (None, "no interior edge within the rings".to_string()),
    };
    Selection {
        mode: SelectMode::Rim,
        rings: select.rings,
        grown_boundary_vertices: 0,
        known_points: 0,
        candidates: Vec::new(),
        winner,
        reason,
        rim: Some(RimReading {
            edges,
            flat_share: share,
        }),
        ms: ms_since(t0),
    }
}

/// The rings a hole of `k` boundary vertices is grown by: `select.rings`, or one per
/// `select.vertices_per_ring` boundary vertices when that is more.
pub fn rings_for(select: &Select, k: usize) -> usize {
    match select.vertices_per_ring {
        0 => select.rings,
        n => select.rings.max(k / n),
    }
}

/// Grows `hole`, fills the grown hole with each candidate and scores it.
pub fn validate(mesh: &Mesh, hole: &Hole, policy: &Policy, candidates: &[Method]) -> Selection {
    let t0 = Instant::now();
    let rings = rings_for(&policy.select, hole.len());
    let mut sel = Selection {
        mode: SelectMode::Validate,
        rings,
        grown_boundary_vertices: 0,
        known_points: 0,
        candidates: Vec::new(),
        winner: None,
        reason: String::new(),
        rim: None,
        ms: 0.0,
    };
    // the policy's rings, or one fewer at a time (down to 1) while the region they give
    // is not a disk (its rim pinched where two growing fronts met, another hole reached)
    let mut r = rings;
    let grown = loop {
        let g = Grown::new(mesh, hole, policy, r);
        if g.is_ok() || r <= 1 {
            sel.rings = r;
            break g;
        }
        r -= 1;
    };
    let grown = match grown {
        Ok(g) => g,
        Err(why) => {
            sel.reason = why;
            sel.ms = ms_since(t0);
            return sel;
        }
    };
    sel.grown_boundary_vertices = grown.hole.len();
    sel.known_points = grown.known.len();
    let diag = mesh.bbox_diagonal().max(f64::MIN_POSITIVE);
    // the candidates together get one hole's time limit
    let deadline = Deadline::after_ms(policy.limits.hole_time_ms);
    for &method in candidates {
        let tc = Instant::now();
        let ctx = FillContext {
            mesh: &grown.mesh,
            hole: &grown.hole,
            policy,
            deadline,
            checker: None,
            rim_bound: false,
            guide: false,
            finish: None,
        };
        let run = guarded(method, || run_method_fill(method, &ctx));
        let c = match run {
            Ok(patch) => Candidate {
                method,
                score: Some(1000.0 * grown.mean_distance(&patch) / diag),
                reason: String::new(),
                ms: ms_since(tc),
            },
            Err(why) => Candidate {
                method,
                score: None,
                reason: why.to_string(),
                ms: ms_since(tc),
            },
        };
        sel.candidates.push(c);
    }
    match lowest_score(sel.candidates.iter().map(|c| (c.method, c.score))) {
        Some(m) => sel.winner = Some(m),
        None => sel.reason = "no candidate filled the grown hole".into(),
    }
    sel.ms = ms_since(t0);
    sel
}

/// The item with the lowest finite score; on a tie the earlier one (the list's order).
/// `None` when nothing has a finite score.
pub fn lowest_score<T: Copy>(scored: impl IntoIterator<Item = (T, Option<f64>)>) -> Option<T> {
    let mut best: Option<(T, f64)> = None;
    for (item, score) in scored {
        if let Some(s) = score.filter(|s| s.is_finite()) {
            if best.is_none_or(|(_, b)| s < b) {
                best = Some((item, s));
            }
        }
    }
    best.map(|(item, _)| item)
}

/// A hole grown by some rings, on a copy of the surface around it.
struct Grown {
    /// The surrounding surface without the grown region (local vertex numbers).
    mesh: Mesh,
    /// The grown hole in `mesh`.
    hole: Hole,
    /// The known points the grown region held: vertices inside it and face centroids.
    known: Vec<DVec3>,
}

impl Grown {
    fn new(mesh: &Mesh, hole: &Hole, policy: &Policy, rings: usize) -> Result<Grown, String> {
        let topo = &mesh.topo;
        let mut on_hole = HashMap::with_capacity(hole.len());
        for (i, &v) in hole.vertices.iter().enumerate() {
            on_hole.insert(v, i);
        }
        // ring by ring: faces with a corner on the current frontier; `depth` of a
        // vertex: the ring whose faces first reached it (0: the hole's loop)
        let mut depth: HashMap<VertexId, usize> = hole.vertices.iter().map(|&v| (v, 0)).collect();
        let mut face_ring: HashMap<FaceId, usize> = HashMap::new();
        let mut frontier: Vec<VertexId> = hole.vertices.clone();
        for r in 0..rings + CONTEXT_RINGS {
            let mut next = Vec::new();
            for &v in &frontier {
                for f in topo.vertex_faces(v) {
                    if face_ring.contains_key(&f) {
                        continue;
                    }
                    face_ring.insert(f, r);
                    for c in topo.face(f) {
                        if let std::collections::hash_map::Entry::Vacant(e) = depth.entry(c) {
                            e.insert(r + 1);
                            next.push(c);
                        }
                    }
                }
            }
            frontier = next;
        }
        // pieces of surface the grown region encloses (where fronts met around them)
        // join it: the kept faces are those connected to the outermost ring
        let outer = rings + CONTEXT_RINGS - 1;
        let kept_faces: Vec<FaceId> = face_ring
            .iter()
            .filter(|&(_, &r)| r >= rings)
            .map(|(&f, _)| f)
            .collect();
        let mut uf = UnionFind::default();
        for &f in &kept_faces {
            let [a, b, c] = topo.face(f);
            uf.union(a, b);
            uf.union(a, c);
        }
        let outer_roots: std::collections::HashSet<VertexId> = kept_faces
            .iter()
            .filter(|f| face_ring.get(f) == Some(&outer))
            .map(|&f| uf.find(topo.face(f)[0]))
            .collect();
        for &f in &kept_faces {
            if !outer_roots.contains(&uf.find(topo.face(f)[0])) {
                face_ring.insert(f, 0);
                for c in topo.face(f) {
                    depth.insert(c, 0);
                }
            }
        }
        // the grown region must not reach another boundary (hole or border): its
        // faces' corners are all interior vertices or on this hole's loop
        for (&f, &r) in &face_ring {
            if r >= rings {
                continue;
            }
            for c in topo.face(f) {
                if !on_hole.contains_key(&c) && topo.is_boundary_vertex(c) {
                    return Err(format!(
                        "another hole or the border is within {} of this one",
                        rings_text(rings)
                    ));
                }
            }
        }
        // the local copy: context faces only, vertices renumbered in first-use order
        let mut local_of: HashMap<VertexId, u32> = HashMap::new();
        let mut positions = Vec::new();
        let mut colors = mesh.colors.as_ref().map(|_| Vec::new());
        let mut faces = Vec::new();
        let mut kept: Vec<(FaceId, usize)> = face_ring.iter().map(|(&f, &r)| (f, r)).collect();
        kept.sort_unstable_by_key(|&(f, _)| f.idx());
        let mut known = Vec::new();
        let mut local = |v: VertexId, positions: &mut Vec<DVec3>| -> u32 {
            *local_of.entry(v).or_insert_with(|| {
                positions.push(mesh.pos(v));
                if let (Some(out), Some(src)) = (colors.as_mut(), mesh.colors.as_ref()) {
                    out.push(src[v.idx()]);
                }
                (positions.len() - 1) as u32
            })
        };
        for &(f, r) in &kept {
            let [a, b, c] = topo.face(f);
            if r < rings {
                known.push((mesh.pos(a) + mesh.pos(b) + mesh.pos(c)) / 3.0);
            } else {
                faces.push([
                    local(a, &mut positions),
                    local(b, &mut positions),
                    local(c, &mut positions),
                ]);
            }
        }
        // vertices inside the grown region: reached by its rings and on no kept face
        // (in vertex order, so that the score does not depend on hashing)
        let mut inside: Vec<VertexId> = depth
            .iter()
            .filter(|&(v, &d)| d <= rings && !local_of.contains_key(v))
            .map(|(&v, _)| v)
            .collect();
        inside.sort_unstable_by_key(|v| v.idx());
        known.extend(inside.into_iter().map(|v| mesh.pos(v)));
        let raw = RawMesh {
            positions,
            colors: colors.filter(|c| !c.is_empty()),
            faces,
            ..Default::default()
        };
        let (sub, _) = Mesh::from_raw(&raw);
        // the grown loop: through the corners of the removed faces that are kept
        let mut is_rim = vec![false; sub.num_vertices()];
        for (&f, &r) in &face_ring {
            if r < rings {
                for c in topo.face(f) {
                    if let Some(&l) = local_of.get(&c) {
                        if let Some(x) = is_rim.get_mut(l as usize) {
                            *x = true;
                        }
                    }
                }
            }
        }
        let rims = is_rim.iter().filter(|&&x| x).count();
        let loops: Vec<Vec<VertexId>> = sub
            .topo
            .boundary_loops()
            .into_iter()
            .filter(|l| {
                l.iter()
                    .any(|v| is_rim.get(v.idx()).copied().unwrap_or(false))
            })
            .collect();
        let [lp] = loops.as_slice() else {
            return Err(format!(
                "the region grown by {} is not a disk ({} boundary loops)",
                rings_text(rings),
                loops.len()
            ));
        };
        let on_loop = lp
            .iter()
            .filter(|v| is_rim.get(v.idx()).copied().unwrap_or(false))
            .count();
        if on_loop != rims || lp.len() < 3 {
            return Err(format!(
                "the region grown by {} is not a disk (its rim is not one simple loop)",
                rings_text(rings)
            ));
        }
        if known.is_empty() {
            return Err("the grown region holds no known point".into());
        }
        let grown = Hole::new(hole.id, &sub, lp.clone(), policy);
        Ok(Grown {
            mesh: sub,
            hole: grown,
            known,
        })
    }

    /// Mean distance from the known points to `patch` (a patch of the grown hole).
    fn mean_distance(&self, patch: &Patch) -> f64 {
        let tris = patch.triangle_positions(&self.mesh, &self.hole);
        if tris.is_empty() {
            return f64::INFINITY;
        }
        let bvh = Bvh::build(tris.len(), |i| tri_box(&tris[i]));
        let start = self.hole.mean_edge_length.max(f64::MIN_POSITIVE);
        let total: f64 = self
            .known
            .iter()
            .map(|&p| {
                closest_on_triangles(&bvh, &tris, p, start)
                    .map_or(f64::INFINITY, |q| (q - p).length())
            })
            .sum();
        total / self.known.len() as f64
    }
}

/// "1 ring", "2 rings".
fn rings_text(n: usize) -> String {
    if n == 1 {
        "1 ring".into()
    } else {
        format!("{n} rings")
    }
}

/// Union-find over vertices (path halving), for the pieces of the kept surface.
#[derive(Default)]
struct UnionFind {
    parent: HashMap<VertexId, VertexId>,
}

impl UnionFind {
    fn find(&mut self, v: VertexId) -> VertexId {
        let mut x = v;
        loop {
            let p = *self.parent.entry(x).or_insert(x);
            if p == x {
                return x;
            }
            let gp = *self.parent.entry(p).or_insert(p);
            self.parent.insert(x, gp);
            x = gp;
        }
    }
    fn union(&mut self, a: VertexId, b: VertexId) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent.insert(ra, rb);
        }
    }
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1000.0
}

#[cfg(test)]
mod tests;
