//! Islands inside holes and floating debris.
//!
//! How the words are read:
//! - an island of a hole is the border loop of another connected piece (a loop the
//!   border rule skipped as the outer border of its own piece) all of whose vertices
//!   project onto the hole's best-fit (Newell) plane inside the hole's loop and lie
//!   within half the hole's radius (perimeter / 2π) of that plane; a loop inside
//!   several holes belongs to the one of least area;
//! - an island of fewer than `islands.remove_below_faces` faces is removed (the
//!   whole piece), counted on the hole; a larger one is bridged (`islands.mode =
//!   "bridge"`): two faces join an edge of the hole's loop to an edge of the island's,
//!   chosen shortest first among those whose faces turn the right way in the plane
//!   and whose new edges cross no loop edge there, which makes one loop that the
//!   method chain fills as one patch; when no bridge is valid, or with
//!   `mode = "remove"`, the hole is skipped ("island inside"), never capped;
//! - debris: a connected piece of fewer than `debris.remove_below_faces` faces,
//!   removed before the holes are found (the largest piece is always kept).

use super::clean::components;
use crate::geometry::measure::{newell_normal, point_in_polygon, vector_area};
use crate::geometry::predicates::{orient2, p2, segments_cross, P2};
use crate::mesh::{FaceId, Mesh, VertexId};
use crate::patch::Hole;
use crate::policy::{IslandMode, Policy};
use glam::{DVec2, DVec3};

/// A hole's plane: centroid and a right-handed frame `(u, v, n)`.
struct Frame {
    c: DVec3,
    n: DVec3,
    u: DVec3,
    v: DVec3,
}

impl Frame {
    fn of(pts: &[DVec3]) -> Option<Frame> {
        let n = newell_normal(pts);
        if n == DVec3::ZERO || pts.is_empty() {
            return None;
        }
        let c = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
        let u = n.any_orthonormal_vector();
        Some(Frame {
            c,
            n,
            u,
            v: n.cross(u),
        })
    }
    fn flat(&self, p: DVec3) -> DVec2 {
        let d = p - self.c;
        DVec2::new(d.dot(self.u), d.dot(self.v))
    }
    fn height(&self, p: DVec3) -> f64 {
        (p - self.c).dot(self.n)
    }
}

fn pt(p: DVec2) -> P2 {
    p2(p.x, p.y)
}

/// What was done about the islands of one hole.
#[derive(Clone, Debug, Default)]
pub struct Note {
    /// The hole's loop as it was found (its vertices stay on the loop after bridging).
    pub outer: Vec<VertexId>,
    pub faces_removed: usize,
    pub bridged: usize,
    /// Why the hole is left open (an island neither removed nor bridged).
    pub blocked: Option<String>,
}

/// The piece (connected component) of each loop, through the face at its first vertex.
pub fn loop_pieces(mesh: &Mesh, holes: &[Hole], comp: &[usize]) -> Vec<Option<usize>> {
    holes
        .iter()
        .map(|h| {
            h.vertices
                .first()
                .and_then(|&v| mesh.topo.anchor(v))
                .map(|a| comp[a.face().idx()])
        })
        .collect()
}

/// For each loop, the hole it is an island of (see the module doc): loops `j` with
/// `skip[j]` set, holes `i` without.
pub fn islands_of(
    mesh: &Mesh,
    holes: &[Hole],
    skip: &[Option<String>],
    piece: &[Option<usize>],
) -> Vec<Option<usize>> {
    let mut owner: Vec<Option<(usize, f64)>> = vec![None; holes.len()];
    let candidates: Vec<usize> = (0..holes.len())
        .filter(|&j| skip[j].is_some() && piece[j].is_some() && holes[j].len() >= 3)
        .collect();
    if candidates.is_empty() {
        return vec![None; holes.len()];
    }
    for (i, hole) in holes.iter().enumerate() {
        if skip[i].is_some() || hole.len() < 3 {
            continue;
        }
        let pts: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
        let Some(frame) = Frame::of(&pts) else {
            continue;
        };
        let reach = 0.5 * hole.perimeter / std::f64::consts::TAU;
        let (lo, hi) = pts.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let (lo, hi) = (lo - DVec3::splat(reach), hi + DVec3::splat(reach));
        let poly: Vec<DVec2> = pts.iter().map(|&p| frame.flat(p)).collect();
        let area = vector_area(&pts);
        for &j in &candidates {
            if piece[j] == piece[i] {
                continue;
            }
            let inside = holes[j].vertices.iter().all(|&v| {
                let p = mesh.pos(v);
                p.cmpge(lo).all()
                    && p.cmple(hi).all()
                    && frame.height(p).abs() <= reach
                    && point_in_polygon(&poly, frame.flat(p))
            });
            if inside && owner[j].is_none_or(|(_, a)| area < a) {
                owner[j] = Some((i, area));
            }
        }
    }
    owner.into_iter().map(|o| o.map(|(i, _)| i)).collect()
}

/// Joins the island loop `island` to the hole loop `outer` with two faces (see the
/// module doc). True when the faces were added.
fn bridge(mesh: &mut Mesh, outer: &[VertexId], island: &[VertexId]) -> bool {
    let (m, k) = (outer.len(), island.len());
    if m < 3 || k < 3 {
        return false;
    }
    let pts: Vec<DVec3> = outer.iter().map(|&v| mesh.pos(v)).collect();
    let Some(frame) = Frame::of(&pts) else {
        return false;
    };
    let o: Vec<DVec2> = pts.iter().map(|&p| frame.flat(p)).collect();
    let i: Vec<DVec2> = island.iter().map(|&v| frame.flat(mesh.pos(v))).collect();
    let d = |a: VertexId, b: VertexId| (mesh.pos(a) - mesh.pos(b)).length();
    // faces (o_s, o_s+1, i_u) and (i_u, i_u+1, o_s): new edges o_s+1 - i_u,
    // i_u+1 - o_s and the diagonal o_s - i_u
    // the candidates: the best pair for each edge of either loop (m + k of them, not
    // m k: a big hole around a big island stays small in memory), shortest first
    let cost =
        |s: usize, u: usize| d(outer[(s + 1) % m], island[u]) + d(outer[s], island[(u + 1) % k]);
    let mut best_s: Vec<Option<(f64, usize, usize)>> = vec![None; m];
    let mut best_u: Vec<Option<(f64, usize, usize)>> = vec![None; k];
    #[allow(clippy::needless_range_loop)] // s and u index both tables and the cost
    for s in 0..m {
        for u in 0..k {
            let c = cost(s, u);
            if best_s[s].is_none_or(|b| c < b.0) {
                best_s[s] = Some((c, s, u));
            }
            if best_u[u].is_none_or(|b| c < b.0) {
                best_u[u] = Some((c, s, u));
            }
        }
    }
    let mut cands: Vec<(f64, usize, usize)> = best_s.into_iter().chain(best_u).flatten().collect();
    cands.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then((a.1, a.2).cmp(&(b.1, b.2))));
    cands.dedup_by_key(|c| (c.1, c.2));
    let crosses = |a: DVec2, b: DVec2| {
        let edges = (0..m)
            .map(|x| (o[x], o[(x + 1) % m]))
            .chain((0..k).map(|x| (i[x], i[(x + 1) % k])));
        let mut e = edges;
        e.any(|(c, q)| segments_cross(pt(a), pt(b), pt(c), pt(q)))
    };
    for &(_, s, u) in cands.iter().take(32) {
        let (s1, u1) = ((s + 1) % m, (u + 1) % k);
        if orient2(pt(o[s]), pt(o[s1]), pt(i[u])) <= 0.0
            || orient2(pt(i[u]), pt(i[u1]), pt(o[s])) <= 0.0
            || crosses(o[s1], i[u])
            || crosses(i[u1], o[s])
            || crosses(o[s], i[u])
        {
            continue;
        }
        let faces = [
            [outer[s], outer[s1], island[u]],
            [island[u], island[u1], outer[s]],
        ];
        let flat = faces.iter().any(|f| {
            let [a, b, c] = f.map(|v| mesh.pos(v));
            (b - a).cross(c - a).length_squared() == 0.0
        });
        if !flat && mesh.add_faces(&faces).is_ok() {
            return true;
        }
    }
    false
}

/// Resolves the islands of the holes to fill (`skip[i]` unset): removes the small
/// ones and bridges the others (or blocks their hole). Returns the changed mesh, if
/// anything changed, and a note per hole with islands.
pub fn resolve(
    mesh: &Mesh,
    holes: &[Hole],
    skip: &[Option<String>],
    comp: &[usize],
    policy: &Policy,
) -> (Option<Mesh>, Vec<Note>) {
    let piece = loop_pieces(mesh, holes, comp);
    let owner = islands_of(mesh, holes, skip, &piece);
    if owner.iter().all(Option::is_none) {
        return (None, Vec::new());
    }
    let ncomp = comp.iter().copied().max().map_or(0, |m| m + 1);
    let mut size = vec![0usize; ncomp];
    for &c in comp {
        size[c] += 1;
    }
    let mut remove_piece = vec![false; ncomp];
    let mut notes: Vec<Note> = Vec::new();
    let mut bridges: Vec<(usize, Vec<usize>)> = Vec::new();
    for (i, hole) in holes.iter().enumerate() {
        let islands: Vec<usize> = (0..holes.len()).filter(|&j| owner[j] == Some(i)).collect();
        if islands.is_empty() {
            continue;
        }
        let mut note = Note {
            outer: hole.vertices.clone(),
            ..Default::default()
        };
        let mut to_bridge = Vec::new();
        for j in islands {
            let Some(p) = piece[j] else { continue };
            if size[p] < policy.islands.remove_below_faces {
                if !remove_piece[p] {
                    remove_piece[p] = true;
                    note.faces_removed += size[p];
                }
            } else if policy.islands.mode == IslandMode::Remove {
                note.blocked = Some(format!(
                    "island inside: a piece of {} faces lies inside the hole (>= \
                     islands.remove_below_faces = {}, islands.mode = \"remove\"); not capped",
                    size[p], policy.islands.remove_below_faces
                ));
            } else {
                to_bridge.push(j);
            }
        }
        if note.blocked.is_none() && !to_bridge.is_empty() {
            bridges.push((notes.len(), to_bridge));
        }
        notes.push(note);
    }
    let removed: Vec<FaceId> = (0..mesh.num_faces())
        .filter(|&f| remove_piece[comp[f]])
        .map(FaceId::from_idx)
        .collect();
    if removed.is_empty() && bridges.is_empty() {
        return (None, notes);
    }
    let mut out = if removed.is_empty() {
        mesh.clone()
    } else {
        mesh.without_faces(&removed).0
    };
    for (n, islands) in bridges {
        let mut cur = notes[n].outer.clone();
        for j in islands {
            if !bridge(&mut out, &cur, &holes[j].vertices) {
                notes[n].blocked = Some(format!(
                    "island inside: the border of a piece of {} faces lies inside the hole \
                     and no bridge to it is valid; not capped",
                    piece[j].map_or(0, |p| size[p])
                ));
                break;
            }
            notes[n].bridged += 1;
            // the hole's loop now runs round the island too
            if let Some(l) = out
                .topo
                .boundary_loops()
                .into_iter()
                .find(|l| l.contains(&cur[0]))
            {
                cur = l;
            }
        }
    }
    (Some(out), notes)
}

/// Removes the connected pieces of fewer than `below` faces (never the largest).
/// Returns the mesh, pieces and faces removed, or `None` when none is that small.
pub fn remove_debris(mesh: &Mesh, below: usize) -> Option<(Mesh, usize, usize)> {
    if below == 0 {
        return None;
    }
    let comp = components(mesh);
    let ncomp = comp.iter().copied().max().map_or(0, |m| m + 1);
    let mut size = vec![0usize; ncomp];
    for &c in &comp {
        size[c] += 1;
    }
    let largest = (0..ncomp).max_by_key(|&c| size[c])?;
    let small = |c: usize| c != largest && size[c] < below;
    let removed: Vec<FaceId> = (0..mesh.num_faces())
        .filter(|&f| small(comp[f]))
        .map(FaceId::from_idx)
        .collect();
    if removed.is_empty() {
        return None;
    }
    let pieces = (0..ncomp).filter(|&c| small(c)).count();
    Some((mesh.without_faces(&removed).0, pieces, removed.len()))
}
