//! Building the half-edge mesh from a triangle soup, resolving what real scans carry:
//! degenerate and duplicate faces (same or opposite orientation), folded quads, edges
//! with three or more faces, inconsistent orientation, non-manifold and pinched
//! vertices. Any soup whose indices are in range gives a valid mesh
//! ([`Mesh::validate`] holds); nothing here panics on bad input, and what was resolved
//! is counted in [`BuildReport`].
//!
//! How each defect is resolved:
//! - a face whose three vertices already form a face (either orientation) is dropped
//!   (both, for a face and its opposite whose edges each have two other faces: a
//!   two-sided fin on a whole surface), unless it is one half of a fanned quad (the reader's `(a, b, c), (a, c, d)`): then
//!   the quad takes its other diagonal when neither new triangle exists (a folded
//!   quad pair of a quad scan stays in the mesh);
//! - an edge with three or more faces keeps the pair of faces that continue each other
//!   best (opposite directions, fewest open edges, most aligned normals); the other
//!   faces are left unpaired there;
//! - orientation is made consistent per component (the majority kept), an edge whose
//!   two faces cannot agree is left open;
//! - a vertex whose faces form several fans gets a copy per extra fan, appended after
//!   the input vertices (input vertices keep their index and position);
//! - a face still sharing a directed edge with another one after that (an unpaired
//!   face in the same fan as the pair it was left out of) is detached: its links to
//!   its neighbours are cut and its corners split again, until nothing is shared.

use super::{group_by_key, HalfedgeId, Mesh, Topology, VertexId};
use crate::io::RawMesh;
use glam::DVec3;
use serde::Serialize;

/// What the builder resolved in the input.
#[derive(Clone, Debug, Default, Serialize, PartialEq, Eq)]
pub struct BuildReport {
    /// Faces dropped because a vertex index repeats.
    pub repeated_index_faces: usize,
    /// Faces dropped because their three corners are collinear (exactly zero area).
    pub zero_area_faces: usize,
    /// Faces dropped because the same three vertices already form a face with the same
    /// orientation.
    pub duplicate_faces: usize,
    /// Faces dropped because the same three vertices already form a face with the
    /// opposite orientation; both faces of such a pair are dropped when each of
    /// their edges has two other faces (a two-sided fin on a whole surface).
    pub opposite_faces: usize,
    /// Fanned quads whose second triangle repeated an existing face, split along their
    /// other diagonal instead.
    pub quads_rediagonalized: usize,
    /// Faces dropped because an index is out of range.
    pub out_of_range_faces: usize,
    /// Edges shared by three or more faces; the extra faces were detached there.
    pub non_manifold_edges: usize,
    /// Edges left open because their two faces could not be oriented consistently.
    pub orientation_cuts: usize,
    /// Faces whose orientation was reversed to agree with their component.
    pub flipped_faces: usize,
    /// Faces cut loose from all their neighbours because they shared a directed edge
    /// with another face that splitting vertices alone did not separate.
    pub detached_faces: usize,
    /// Vertices whose faces formed several fans; each extra fan got a copy.
    pub non_manifold_vertices: usize,
    /// Vertex copies appended by those splits.
    pub vertices_added_by_split: usize,
    /// Vertices used by no face (kept in the output, untouched).
    pub isolated_vertices: usize,
}

impl BuildReport {
    /// True when the input needed no resolution at all.
    pub fn is_clean(&self) -> bool {
        *self
            == BuildReport {
                isolated_vertices: self.isolated_vertices,
                ..Default::default()
            }
    }
}

/// The reader fans a polygon `(a, b, c, d, ...)` into `(a, b, c), (a, c, d), ...`:
/// true when faces `i` and `i + 1` look like two triangles of one fanned polygon.
fn fan_pair(faces: &[[u32; 3]], i: usize) -> bool {
    match (faces.get(i), faces.get(i + 1)) {
        (Some(f), Some(g)) => f[0] == g[0] && f[2] == g[1] && f[1] != g[2],
        _ => false,
    }
}

fn sorted3(f: [u32; 3]) -> [u32; 3] {
    let mut k = f;
    k.sort_unstable();
    k
}

/// True when `f` and `g` (the same three vertices) have the same cyclic order.
fn same_orientation(f: [u32; 3], g: [u32; 3]) -> bool {
    (0..3).any(|r| f == [g[r], g[(r + 1) % 3], g[(r + 2) % 3]])
}

fn zero_area(p: &[DVec3], f: [u32; 3]) -> bool {
    let [a, b, c] = f.map(|i| p[i as usize]);
    (b - a).cross(c - a) == DVec3::ZERO
}

/// Drops faces that repeat the vertex set of an earlier face, or re-splits the quad
/// they belong to along its other diagonal. Returns the faces kept.
fn resolve_duplicates(
    mut faces: Vec<[u32; 3]>,
    positions: &[DVec3],
    rep: &mut BuildReport,
) -> Vec<[u32; 3]> {
    let nv = positions.len();
    // duplicates (the same three vertices, any order): the first one is kept. Faces
    // grouped by their smallest vertex (a counting sort, no hashing), then each group
    // sorted by its vertex triple and face number.
    // for a repeated face: whether it has the orientation of the face it repeats
    let mut dup: Vec<Option<bool>> = vec![None; faces.len()];
    // (kept face, its repeat)
    let mut repeats: Vec<(u32, u32)> = Vec::new();
    {
        let (off, mut group) = group_by_key(nv, faces.len(), |i| {
            faces[i].iter().copied().min().unwrap_or(0) as usize
        });
        for v in 0..nv {
            let g = &mut group[off[v] as usize..off[v + 1] as usize];
            if g.len() < 2 {
                continue;
            }
            g.sort_unstable_by_key(|&i| (sorted3(faces[i as usize]), i));
            let mut first = g[0];
            for w in g.windows(2) {
                if sorted3(faces[w[0] as usize]) == sorted3(faces[w[1] as usize]) {
                    dup[w[1] as usize] = Some(same_orientation(
                        faces[w[1] as usize],
                        faces[first as usize],
                    ));
                    repeats.push((first, w[1]));
                } else {
                    first = w[1];
                }
            }
        }
    }
    if repeats.is_empty() {
        return faces;
    }
    // a face and its opposite alone (a two-sided fin of a decimated scan) whose
    // three edges each have two more faces: the surface is whole without them, so
    // the kept face goes too (else it would make three edges non-manifold)
    let mut fins = vec![false; faces.len()];
    {
        let mut on_edge: crate::fasthash::HashMap<(u32, u32), u32> = Default::default();
        for f in &faces {
            for c in 0..3 {
                let (a, b) = (f[c], f[(c + 1) % 3]);
                *on_edge.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let mut times: crate::fasthash::HashMap<u32, u32> = Default::default();
        for &(first, _) in &repeats {
            *times.entry(first).or_default() += 1;
        }
        for &(first, i) in &repeats {
            let f = faces[first as usize];
            let fin = times.get(&first) == Some(&1)
                && dup[i as usize] == Some(false)
                && (0..3).all(|c| {
                    let (a, b) = (f[c], f[(c + 1) % 3]);
                    on_edge.get(&(a.min(b), a.max(b))).copied().unwrap_or(0) >= 4
                });
            if fin {
                dup[first as usize] = Some(false);
                fins[first as usize] = true;
                fins[i as usize] = true;
            }
        }
    }
    // a repeated face that is half of a fanned quad: the quad (a, b, c, d) from
    // (a, b, c), (a, c, d) becomes (b, c, d), (b, d, a) when neither exists
    let mut existing: crate::fasthash::HashSet<[u32; 3]> = faces
        .iter()
        .zip(&dup)
        .filter(|(_, d)| d.is_none())
        .map(|(f, _)| sorted3(*f))
        .collect();
    for i in 0..faces.len() {
        if dup[i].is_none() || fins[i] {
            continue;
        }
        let sibling = if i > 0 && fan_pair(&faces, i - 1) && dup[i - 1].is_none() {
            Some(i - 1)
        } else if fan_pair(&faces, i) && dup.get(i + 1).is_some_and(Option::is_none) {
            Some(i + 1)
        } else {
            None
        };
        let Some(j) = sibling else { continue };
        let (t1, t2) = (faces[i.min(j)], faces[i.max(j)]);
        let [a, b, c] = t1;
        let d = t2[2];
        let n1 = [b, c, d];
        let n2 = [b, d, a];
        if existing.contains(&sorted3(n1))
            || existing.contains(&sorted3(n2))
            || zero_area(positions, n1)
            || zero_area(positions, n2)
        {
            continue;
        }
        existing.remove(&sorted3(faces[j]));
        existing.insert(sorted3(n1));
        existing.insert(sorted3(n2));
        faces[i.min(j)] = n1;
        faces[i.max(j)] = n2;
        dup[i] = None;
        rep.quads_rediagonalized += 1;
    }
    for d in &dup {
        match d {
            Some(true) => rep.duplicate_faces += 1,
            Some(false) => rep.opposite_faces += 1,
            None => {}
        }
    }
    let mut k = 0;
    faces.retain(|_| {
        k += 1;
        dup[k - 1].is_none()
    });
    faces
}

impl Mesh {
    /// Builds a mesh from a triangle soup. The result always passes
    /// [`Mesh::validate`]; every resolution is counted in the report.
    pub fn from_raw(raw: &RawMesh) -> (Mesh, BuildReport) {
        let mut rep = BuildReport::default();
        let nv = raw.positions.len();

        // 1. drop faces that cannot be triangles
        let mut faces: Vec<[u32; 3]> = Vec::with_capacity(raw.faces.len());
        for f in &raw.faces {
            if f.iter().any(|&i| i as usize >= nv) {
                rep.out_of_range_faces += 1;
                continue;
            }
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                rep.repeated_index_faces += 1;
                continue;
            }
            if zero_area(&raw.positions, *f) {
                rep.zero_area_faces += 1;
                continue;
            }
            faces.push(*f);
        }
        faces = resolve_duplicates(faces, &raw.positions, &mut rep);
        faces.shrink_to_fit();
        let nf = faces.len();
        // 2. pair half-edges by undirected edge: half-edges grouped by their smaller
        // vertex (a counting sort), each group sorted by the larger vertex and the
        // half-edge number, so equal edges are adjacent in (edge, half-edge) order
        let from = |faces: &Vec<[u32; 3]>, h: u32| faces[(h / 3) as usize][(h % 3) as usize];
        let to =
            |faces: &Vec<[u32; 3]>, h: u32| faces[(h / 3) as usize][((h % 3 + 1) % 3) as usize];
        let (off, mut halfedges) = group_by_key(nv, nf * 3, |h| {
            from(&faces, h as u32).min(to(&faces, h as u32)) as usize
        });
        // candidate pairs (h1, h2), not yet checked for orientation; the edges with
        // three or more half-edges (ranges of `halfedges`) resolved after every group
        // is sorted, since that looks up the other edges of their faces
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(nf * 3 / 2);
        let mut crowded: Vec<(usize, usize)> = Vec::new();
        for v in 0..nv {
            let (lo, hi) = (off[v] as usize, off[v + 1] as usize);
            let g = &mut halfedges[lo..hi];
            g.sort_unstable_by_key(|&h| (from(&faces, h).max(to(&faces, h)), h));
            let far = |h: u32| from(&faces, h).max(to(&faces, h));
            let mut i = 0;
            while i < g.len() {
                let mut j = i + 1;
                while j < g.len() && far(g[j]) == far(g[i]) {
                    j += 1;
                }
                if j - i == 2 {
                    pairs.push((g[i], g[i + 1]));
                } else if j - i > 2 {
                    crowded.push((lo + i, lo + j));
                }
                i = j;
            }
        }
        if !crowded.is_empty() {
            rep.non_manifold_edges = crowded.len();
            // the number of half-edges on the undirected edge a-b
            let on_edge = |a: u32, b: u32| -> usize {
                let (m, x) = (a.min(b) as usize, a.max(b));
                let g = &halfedges[off[m] as usize..off[m + 1] as usize];
                let key = |h: &u32| from(&faces, *h).max(to(&faces, *h));
                g.partition_point(|h| key(h) <= x) - g.partition_point(|h| key(h) < x)
            };
            let open_edges = |f: usize| -> f64 {
                (0..3)
                    .filter(|&c| on_edge(faces[f][c], faces[f][(c + 1) % 3]) == 1)
                    .count() as f64
            };
            let normal = |f: usize| -> DVec3 {
                let [a, b, c] = faces[f].map(|i| raw.positions[i as usize]);
                (b - a).cross(c - a).normalize_or_zero()
            };
            for &(lo, hi) in &crowded {
                // keep the pair that continues the surface best: opposite directions
                // (no flip needed), no open edges on either face (a flap or a tooth
                // is the one left out), then the most aligned normals; at most 64
                // half-edges are weighed (a pathological fan takes the first pair)
                let group = &halfedges[lo..hi.min(lo + 64)];
                let mut best: Option<(f64, u32, u32)> = None;
                for (x, &ha) in group.iter().enumerate() {
                    for &hb in &group[x + 1..] {
                        let (fa, fb) = ((ha / 3) as usize, (hb / 3) as usize);
                        let opposite = from(&faces, ha) != from(&faces, hb);
                        let dot = normal(fa).dot(normal(fb));
                        let score = if opposite { 4.0 + dot } else { -dot }
                            - 2.0 * (open_edges(fa) + open_edges(fb));
                        if best.is_none_or(|(s, _, _)| score > s) {
                            best = Some((score, ha, hb));
                        }
                    }
                }
                if let Some((_, ha, hb)) = best {
                    pairs.push((ha, hb));
                }
            }
        }
        drop(halfedges);
        drop(off);

        // 3. orient: breadth-first over the pairs, flipping faces to agree. When every
        // pair already runs in opposite directions (a consistently oriented input, the
        // usual case) the search would flip nothing and cut nothing: skipped.
        let consistent = pairs
            .iter()
            .all(|&(a, b)| from(&faces, a) != from(&faces, b));
        let mut flip: Vec<Option<bool>> = vec![consistent.then_some(false); nf];
        let mut cut = vec![false; pairs.len()];
        if !consistent {
            let mut adj_start = vec![0u32; nf + 1];
            for &(a, b) in &pairs {
                adj_start[(a / 3) as usize + 1] += 1;
                adj_start[(b / 3) as usize + 1] += 1;
            }
            for k in 0..nf {
                adj_start[k + 1] += adj_start[k];
            }
            let mut fill = adj_start.clone();
            let mut adj = vec![0u32; adj_start[nf] as usize]; // pair index
            for (pi, &(a, b)) in pairs.iter().enumerate() {
                for h in [a, b] {
                    let f = (h / 3) as usize;
                    adj[fill[f] as usize] = pi as u32;
                    fill[f] += 1;
                }
            }
            drop(fill);
            let mut queue = std::collections::VecDeque::new();
            let mut component: Vec<usize> = Vec::new();
            for seed in 0..nf {
                if flip[seed].is_some() {
                    continue;
                }
                flip[seed] = Some(false);
                queue.push_back(seed);
                component.clear();
                while let Some(f) = queue.pop_front() {
                    component.push(f);
                    let ff = flip[f].unwrap_or(false);
                    for k in adj_start[f]..adj_start[f + 1] {
                        let pi = adj[k as usize] as usize;
                        if cut[pi] {
                            continue;
                        }
                        let (a, b) = pairs[pi];
                        let (mine, other) = if (a / 3) as usize == f {
                            (a, b)
                        } else {
                            (b, a)
                        };
                        let g = (other / 3) as usize;
                        let same_dir = from(&faces, mine) == from(&faces, other);
                        // after flips the two must run in opposite directions
                        let want = ff ^ same_dir;
                        match flip[g] {
                            None => {
                                flip[g] = Some(want);
                                queue.push_back(g);
                            }
                            Some(x) if x != want => {
                                cut[pi] = true;
                                rep.orientation_cuts += 1;
                            }
                            _ => {}
                        }
                    }
                }
                // keep the orientation most of the component already has
                let flipped = component.iter().filter(|&&f| flip[f] == Some(true)).count();
                if flipped * 2 > component.len() {
                    for &f in &component {
                        flip[f] = flip[f].map(|x| !x);
                    }
                }
            }
        }
        // room for the patches that will close the holes, so that filling appends
        // without moving the arrays (a move copies the whole mesh inside the fill
        // time): a round hole of k edges takes about k^2 / (pi sqrt 3) = 0.18 k^2
        // triangles at its own edge length (the bunny scan's holes 0.09 to 0.25 k^2),
        // so room for b^2 / 4 over the b boundary edges (or 8 b, the most a hole of
        // fewer than 32 edges takes), at most a quarter of the mesh more. Room is
        // address space: the pages of the part never filled are never touched.
        let paired = pairs.iter().enumerate().filter(|&(i, _)| !cut[i]).count();
        let boundary = (nf * 3).saturating_sub(2 * paired);
        let room_faces = boundary
            .saturating_mul(boundary)
            .div_ceil(4)
            .max(boundary.saturating_mul(8))
            .min(nf / 4 + 64);
        let room_vertices = room_faces / 2 + 8;
        let mut out_faces: Vec<[VertexId; 3]> = Vec::with_capacity(nf + room_faces);
        for (fi, f) in faces.iter().enumerate() {
            if flip[fi] == Some(true) {
                rep.flipped_faces += 1;
                out_faces.push([VertexId(f[0]), VertexId(f[2]), VertexId(f[1])]);
            } else {
                out_faces.push(f.map(VertexId));
            }
        }
        let find =
            |faces: &Vec<[VertexId; 3]>, f: usize, a: VertexId, b: VertexId| -> Option<u32> {
                (0..3)
                    .find(|&c| faces[f][c] == a && faces[f][(c + 1) % 3] == b)
                    .map(|c| (f * 3 + c) as u32)
            };
        // the twin links, as half-edge pairs of the oriented faces
        let mut links: Vec<(u32, u32)> = Vec::with_capacity(paired);
        let mut unlinked = 0usize;
        for (pi, &(a, b)) in pairs.iter().enumerate() {
            if cut[pi] {
                continue;
            }
            let fa = (a / 3) as usize;
            let fb = (b / 3) as usize;
            // the shared edge's ends, from the faces as read (a flip reorders corners)
            let u = VertexId(from(&faces, a));
            let w = VertexId(to(&faces, a));
            // after flipping, locate the half-edges of the shared edge in each face
            match (find(&out_faces, fa, u, w), find(&out_faces, fb, w, u)) {
                (Some(x), Some(y)) => links.push((x, y)),
                _ => match (find(&out_faces, fa, w, u), find(&out_faces, fb, u, w)) {
                    (Some(x), Some(y)) => links.push((x, y)),
                    _ => unlinked += 1,
                },
            }
        }
        drop(pairs);
        drop(faces);

        // 4. split vertices with several fans. When some edge had more than two faces
        // or was left open by orientation, a face left out of a pair can still share
        // a directed edge with the pair (it lies in the same fan at both ends): such
        // faces are detached and the split redone, until nothing is shared. Each
        // round detaches at least one face (see `shared_edge_faces`), so it ends.
        let room = Room {
            faces: room_faces,
            vertices: room_vertices,
        };
        let suspect = rep.non_manifold_edges > 0 || rep.orientation_cuts > 0 || unlinked > 0;
        let mut detached: Vec<bool> = Vec::new();
        loop {
            let (mesh, split) = assemble(raw, out_faces.clone(), &links, &detached, room);
            let bad = if suspect {
                shared_edge_faces(&mesh.topo)
            } else {
                Vec::new()
            };
            let fresh: Vec<usize> = bad
                .into_iter()
                .filter(|&f| !detached.get(f).copied().unwrap_or(false))
                .collect();
            if fresh.is_empty() {
                rep.non_manifold_vertices = split.non_manifold_vertices;
                rep.vertices_added_by_split = split.vertices_added;
                rep.isolated_vertices = split.isolated;
                return (mesh, rep);
            }
            if detached.is_empty() {
                detached = vec![false; nf];
            }
            rep.detached_faces += fresh.len();
            for f in fresh {
                detached[f] = true;
            }
        }
    }
}

/// Room reserved in the mesh's arrays for the patches.
#[derive(Clone, Copy)]
struct Room {
    faces: usize,
    vertices: usize,
}

/// What splitting the fans did.
struct Split {
    non_manifold_vertices: usize,
    vertices_added: usize,
    isolated: usize,
}

/// Links the twins (those of detached faces left out) and gives every fan of a vertex
/// after its first its own copy of the vertex. Fans of detached faces come after all
/// others, so a vertex keeps its id in the surface and the detached face takes copies.
fn assemble(
    raw: &RawMesh,
    faces: Vec<[VertexId; 3]>,
    links: &[(u32, u32)],
    detached: &[bool],
    room: Room,
) -> (Mesh, Split) {
    let nv = raw.positions.len();
    let nf = faces.len();
    let is_detached = |h: u32| detached.get((h / 3) as usize).copied().unwrap_or(false);
    let mut twin: Vec<Option<HalfedgeId>> = Vec::with_capacity((nf + room.faces) * 3);
    twin.resize(nf * 3, None);
    for &(a, b) in links {
        if is_detached(a) || is_detached(b) {
            continue;
        }
        twin[a as usize] = Some(HalfedgeId(b));
        twin[b as usize] = Some(HalfedgeId(a));
    }
    let mut positions = Vec::with_capacity(nv + room.vertices);
    positions.extend_from_slice(&raw.positions);
    let mut colors = raw.colors.as_ref().map(|c| {
        let mut v = Vec::with_capacity(nv + room.vertices);
        v.extend_from_slice(c);
        v.resize(nv, [0.5, 0.5, 0.5]);
        v
    });
    let mut origin: Vec<Option<VertexId>> = Vec::with_capacity(nv + room.vertices);
    origin.extend((0..nv).map(|i| Some(VertexId::from_idx(i))));
    let mut anchor: Vec<Option<HalfedgeId>> = Vec::with_capacity(nv + room.vertices);
    anchor.resize(nv, None);
    let mut visited = vec![false; nf * 3];
    let mut topo = Topology {
        faces,
        twin,
        anchor: Vec::new(),
    };
    let mut fan: Vec<HalfedgeId> = Vec::new();
    let mut split_vertices = vec![false; nv];
    let mut split = Split {
        non_manifold_vertices: 0,
        vertices_added: 0,
        isolated: 0,
    };
    let order = (0..nf * 3)
        .filter(|&h| !is_detached(h as u32))
        .chain((0..nf * 3).filter(|&h| is_detached(h as u32)));
    for hi in order {
        if visited[hi] {
            continue;
        }
        let h0 = HalfedgeId::from_idx(hi);
        let v = topo.from(h0);
        // walk back to the fan's boundary start (or all the way round)
        let mut start = h0;
        let mut guard = 0;
        while let Some(p) = topo.prev_outgoing(start) {
            if p == h0 || guard > nf * 3 {
                break;
            }
            start = p;
            guard += 1;
        }
        fan.clear();
        let mut h = start;
        loop {
            fan.push(h);
            match topo.next_outgoing(h) {
                Some(n) if n != start && fan.len() <= nf * 3 => h = n,
                _ => break,
            }
        }
        for &g in &fan {
            visited[g.0 as usize] = true;
        }
        let target = if anchor[v.idx()].is_none() {
            anchor[v.idx()] = Some(start);
            v
        } else {
            // a further fan: give it its own copy of the vertex
            if !split_vertices[v.idx()] {
                split_vertices[v.idx()] = true;
                split.non_manifold_vertices += 1;
            }
            split.vertices_added += 1;
            let nvid = VertexId::from_idx(positions.len());
            positions.push(positions[v.idx()]);
            if let Some(c) = colors.as_mut() {
                let col = c[v.idx()];
                c.push(col);
            }
            origin.push(Some(v));
            anchor.push(Some(start));
            nvid
        };
        if target != v {
            for &g in &fan {
                let f = g.face().idx();
                topo.faces[f][g.corner()] = target;
            }
        }
    }
    split.isolated = anchor[..nv].iter().filter(|a| a.is_none()).count();
    topo.anchor = anchor;
    (
        Mesh {
            topo,
            positions,
            colors,
            origin,
            input_vertices: nv,
        },
        split,
    )
}

/// The faces with an unlinked half-edge that shares its directed edge with another
/// half-edge, or whose opposite exists without being its twin (after the fans are
/// split). Every such clash has an unlinked half-edge (a linked pair is the only pair
/// of its edge), so detaching these faces makes progress. Linear: half-edges grouped
/// by start vertex with a counting sort, each vertex's short list sorted.
fn shared_edge_faces(topo: &Topology) -> Vec<usize> {
    let nv = topo.anchor.len();
    let nh = topo.twin.len();
    let (off, mut hs) = group_by_key(nv, nh, |h| topo.from(HalfedgeId::from_idx(h)).idx());
    for v in 0..nv {
        let g = &mut hs[off[v] as usize..off[v + 1] as usize];
        g.sort_unstable_by_key(|&h| (topo.to(HalfedgeId(h)), h));
    }
    let out_of = |v: VertexId, w: VertexId| -> &[u32] {
        let g = &hs[off[v.idx()] as usize..off[v.idx() + 1] as usize];
        let lo = g.partition_point(|&h| topo.to(HalfedgeId(h)) < w);
        let hi = g.partition_point(|&h| topo.to(HalfedgeId(h)) <= w);
        &g[lo..hi]
    };
    let mut bad = Vec::new();
    for h in 0..nh {
        let he = HalfedgeId::from_idx(h);
        if topo.twin(he).is_some() {
            continue;
        }
        let (u, w) = (topo.from(he), topo.to(he));
        if out_of(u, w).len() > 1 || !out_of(w, u).is_empty() {
            bad.push(h / 3);
        }
    }
    bad.sort_unstable();
    bad.dedup();
    bad
}

impl Mesh {
    /// The mesh as a triangle soup: input vertices first in their order, then the
    /// vertices added by splitting and filling; faces in mesh order.
    pub fn to_raw(&self, template: &RawMesh) -> RawMesh {
        RawMesh {
            positions: self.positions.clone(),
            colors: self.colors.clone(),
            faces: self.topo.faces().iter().map(|f| f.map(|v| v.0)).collect(),
            precision: template.precision,
            encoding: template.encoding,
            notes: Vec::new(),
            attrs: Default::default(),
        }
    }

    /// Rebuilds the mesh without the given faces (boundary cleaning). Vertex ids are
    /// kept; faces are renumbered.
    pub fn without_faces(&self, remove: &[super::FaceId]) -> (Mesh, BuildReport) {
        let mut drop_f = vec![false; self.num_faces()];
        for f in remove {
            drop_f[f.idx()] = true;
        }
        let raw = RawMesh {
            positions: self.positions.clone(),
            colors: self.colors.clone(),
            faces: self
                .topo
                .faces()
                .iter()
                .enumerate()
                .filter(|(i, _)| !drop_f[*i])
                .map(|(_, f)| f.map(|v| v.0))
                .collect(),
            ..Default::default()
        };
        let (mut m, rep) = Mesh::from_raw(&raw);
        // keep provenance of earlier splits
        for (i, o) in m.origin.iter_mut().enumerate() {
            if i < self.origin.len() {
                *o = self.origin[i];
            } else if let Some(src) = o {
                *o = self.origin.get(src.idx()).copied().flatten();
            }
        }
        m.input_vertices = self.input_vertices;
        (m, rep)
    }
}

#[cfg(test)]
mod tests;
