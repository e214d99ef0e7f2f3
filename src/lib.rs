//! holefill: repairs scanned triangle meshes by closing every hole with a method
//! chosen by the hole's size under a TOML policy.
//!
//! The public API is three steps: [`read`] a file into a triangle soup, [`repair`] it
//! under a [`Policy`], [`write`] the result. The library knows nothing of folders or
//! daemons.
//!
//! ```no_run
//! use holefill::{policy::Policy, read, repair, write};
//! let raw = read("scan.obj".as_ref(), None).unwrap();
//! let (out, report) = repair(&raw, &Policy::default()).unwrap();
//! write("repaired.obj".as_ref(), &out, None).unwrap();
//! println!("{} filled", report.summary.filled);
//! ```
#![forbid(unsafe_code)]

pub mod bvh;
pub mod check;
pub mod fasthash;
pub mod fill;
pub mod io;
pub mod mesh;
pub mod policy;
pub mod report;
pub mod smooth;
#[cfg(test)]
pub(crate) mod testutil;

use fill::Hole;
use io::{Format, IoError, RawMesh};
use mesh::{FaceId, Mesh, VertexId};
use policy::Policy;
use report::{Counts, HoleReport, HoleStatus, RepairReport};
use std::path::Path;
use std::time::Instant;

/// Why a mesh could not be repaired at all (holes that fail are not errors: they are
/// reported in the log).
#[derive(Debug, thiserror::Error)]
pub enum RepairError {
    /// The input has no triangles.
    #[error("the mesh has no usable triangles")]
    Empty,
    /// The input's topology could not be resolved into a valid mesh.
    #[error("the mesh topology could not be resolved: {0}")]
    Topology(String),
}

/// Reads a mesh file (format from `format`, else from the extension).
pub fn read(path: &Path, format: Option<Format>) -> Result<RawMesh, IoError> {
    io::read(path, format)
}

/// Writes a mesh file atomically (format from `format`, else from the extension).
pub fn write(path: &Path, raw: &RawMesh, format: Option<Format>) -> Result<(), IoError> {
    io::write(path, raw, format)
}

/// Repairs a triangle soup: builds the mesh, cleans the boundary, smooths if the
/// policy says so, and fills every hole. Returns the repaired soup (input vertices
/// first, unmoved unless smoothing is on) and the repair log.
pub fn repair(raw: &RawMesh, policy: &Policy) -> Result<(RawMesh, RepairReport), RepairError> {
    let mut report = RepairReport::new(policy);
    report.resolved.reader = raw.notes.clone();
    let (mut mesh, build) = Mesh::from_raw(raw);
    report.resolved.mesh = build;
    if mesh.num_faces() == 0 {
        return Err(RepairError::Empty);
    }
    mesh.validate().map_err(RepairError::Topology)?;
    report.before = counts(&mesh);

    if policy.clean.remove_teeth {
        let (m, removed) = remove_teeth(mesh);
        mesh = m;
        report.resolved.tooth_faces_removed = removed;
        mesh.validate().map_err(RepairError::Topology)?;
    }
    if policy.clean.split_long_edges > 0.0 {
        report.resolved.long_edges_split =
            split_long_edges(&mut mesh, policy.clean.split_long_edges);
        mesh.validate().map_err(RepairError::Topology)?;
    }

    if policy.smooth.enabled {
        let t = Instant::now();
        report.smoothing = Some(smooth::smooth(&mut mesh, &policy.smooth));
        report.timings.smooth_ms = t.elapsed().as_secs_f64() * 1000.0;
    }

    let t = Instant::now();
    report.holes = fill_all(&mut mesh, policy, &mut report.resolved.degenerate_loops);
    report.timings.fill_ms = t.elapsed().as_secs_f64() * 1000.0;
    report.after = counts(&mesh);
    report.summarise();
    Ok((mesh.to_raw(raw), report))
}

fn counts(mesh: &Mesh) -> Counts {
    Counts {
        vertices: mesh.num_vertices(),
        faces: mesh.num_faces(),
        boundary_loops: mesh.topo.boundary_loops().len(),
    }
}

/// Removes tooth faces (two edges on the boundary) until none is left, never
/// removing the last faces of a component (ALGORITHMS A2).
fn remove_teeth(mut mesh: Mesh) -> (Mesh, usize) {
    let mut removed = 0;
    for _round in 0..8 {
        let comp = components(&mesh);
        let ncomp = comp.iter().copied().max().map_or(0, |m| m + 1);
        let mut size = vec![0usize; ncomp];
        for &c in &comp {
            size[c] += 1;
        }
        let mut teeth_of = vec![0usize; ncomp];
        let mut teeth: Vec<FaceId> = Vec::new();
        for f in 0..mesh.num_faces() {
            let f = FaceId::from_idx(f);
            let open = (0..3)
                .filter(|&c| mesh.topo.twin(f.halfedge(c)).is_none())
                .count();
            if open == 2 {
                teeth.push(f);
                teeth_of[comp[f.idx()]] += 1;
            }
        }
        // keep components that are all teeth (a strip, a lone pair of triangles)
        teeth.retain(|f| teeth_of[comp[f.idx()]] < size[comp[f.idx()]]);
        if teeth.is_empty() {
            break;
        }
        removed += teeth.len();
        let (m, _) = mesh.without_faces(&teeth);
        mesh = m;
    }
    (mesh, removed)
}

/// Splits boundary edges longer than `factor` times their loop's mean boundary edge
/// length at their midpoint, splitting the one triangle on each (ALGORITHMS A2,
/// paper 003 §3.1), until no edge changes. Returns the number of splits.
fn split_long_edges(mesh: &mut Mesh, factor: f64) -> usize {
    let mut total = 0;
    for _round in 0..16 {
        let mut splits: Vec<(FaceId, usize)> = Vec::new();
        for lp in mesh.topo.boundary_loops() {
            let k = lp.len();
            if k < 3 {
                continue;
            }
            let len = |i: usize| (mesh.pos(lp[(i + 1) % k]) - mesh.pos(lp[i])).length();
            let mean = (0..k).map(len).sum::<f64>() / k as f64;
            for i in 0..k {
                if len(i) > factor * mean {
                    // the face half-edge runs lp[i+1] -> lp[i]
                    if let Some(h) = mesh.topo.incoming_boundary(lp[i]) {
                        if mesh.topo.from(h) == lp[(i + 1) % k] {
                            splits.push((h.face(), h.corner()));
                        }
                    }
                }
            }
        }
        // one split per face per round
        splits.sort_unstable_by_key(|s| s.0);
        splits.dedup_by_key(|s| s.0);
        if splits.is_empty() {
            break;
        }
        total += splits.len();
        let mut faces: Vec<[u32; 3]> = mesh.topo.faces().iter().map(|f| f.map(|v| v.0)).collect();
        let mut positions = mesh.positions.clone();
        let mut colors = mesh.colors.clone();
        let mut origin = mesh.origin.clone();
        for &(f, c) in &splits {
            let t = faces[f.idx()];
            let (a, b, o) = (t[c], t[(c + 1) % 3], t[(c + 2) % 3]);
            let m = positions.len() as u32;
            positions.push((positions[a as usize] + positions[b as usize]) * 0.5);
            if let Some(cs) = colors.as_mut() {
                let (ca, cb) = (cs[a as usize], cs[b as usize]);
                cs.push([0, 1, 2].map(|i| (ca[i] + cb[i]) * 0.5));
            }
            origin.push(None);
            faces[f.idx()] = [a, m, o];
            faces.push([m, b, o]);
        }
        let raw = RawMesh {
            positions,
            colors,
            faces,
            ..Default::default()
        };
        let (mut m, _) = Mesh::from_raw(&raw);
        for (i, o) in origin.into_iter().enumerate().take(m.origin.len()) {
            m.origin[i] = o;
        }
        m.input_vertices = mesh.input_vertices;
        *mesh = m;
    }
    total
}

/// Finds the holes, applies the outer-border rule and fills the rest. (Not inlined:
/// profiles and instruction counts of the filling find it by name.)
#[inline(never)]
fn fill_all(mesh: &mut Mesh, policy: &Policy, degenerate: &mut usize) -> Vec<HoleReport> {
    let loops = mesh.topo.boundary_loops();
    let diag = mesh.bbox_diagonal();
    let holes: Vec<Hole> = loops
        .into_iter()
        .enumerate()
        .map(|(i, l)| Hole::new(i, mesh, l, policy))
        .collect();
    // which holes to fill, and which rule skips the others: the rule as it applies to
    // a component's longest loop; with `only_longest`, it then holds only for the
    // longest loop of each component, which needs the components (a walk over every
    // face) only when the rule would skip some loop
    let mut skip: Vec<Option<String>> = holes
        .iter()
        .map(|hole| border_rule(mesh, hole, policy, diag))
        .collect();
    if policy.border.only_longest && skip.iter().any(Option::is_some) {
        let comp = components(mesh);
        let loop_comp: Vec<usize> = holes
            .iter()
            .map(|h| {
                h.vertices
                    .first()
                    .and_then(|&v| mesh.topo.anchor(v))
                    .map(|a| comp[a.face().idx()])
                    .unwrap_or(usize::MAX)
            })
            .collect();
        // longest loop (by perimeter) of each component
        let mut longest: std::collections::HashMap<usize, usize> = std::collections::HashMap::new();
        for (i, h) in holes.iter().enumerate() {
            let e = longest.entry(loop_comp[i]).or_insert(i);
            if h.perimeter > holes[*e].perimeter {
                *e = i;
            }
        }
        for (i, s) in skip.iter_mut().enumerate() {
            if longest.get(&loop_comp[i]) != Some(&i) {
                *s = None;
            }
        }
    }
    // about one check per hole to fill (more for holes whose first patch fails)
    let to_fill = skip.iter().filter(|s| s.is_none()).count();
    let mut checker = check::Checker::for_checks(mesh, to_fill);
    // phase 1, in parallel: every hole's first acceptable patch against the mesh as it
    // is now (read-only); phase 2, serial in hole order: check each against the
    // patches accepted before it and apply it. The output does not depend on threads.
    let proposals = propose_all(mesh, &holes, &skip, policy, &checker);
    let (nv, nf) = proposals
        .iter()
        .flatten()
        .filter_map(|p| p.accepted.as_ref())
        .fold((0, 0), |(v, f), (_, patch, _, _)| {
            (v + patch.new_vertices.len(), f + patch.triangles.len())
        });
    mesh.reserve(nv, nf);
    let mut out = Vec::with_capacity(holes.len());
    for ((hole, rule), proposal) in holes.iter().zip(skip).zip(proposals) {
        if hole.len() < 3 {
            *degenerate += 1;
        }
        match (rule, proposal) {
            (Some(rule), _) => out.push(HoleReport {
                id: hole.id,
                boundary_vertices: hole.len(),
                perimeter: hole.perimeter,
                mean_edge_length: hole.mean_edge_length,
                class: hole.class,
                method: None,
                tried: Vec::new(),
                status: HoleStatus::Skipped,
                reason: rule,
                added_vertices: 0,
                added_faces: 0,
                quality: None,
                ms: 0.0,
            }),
            (None, Some(p)) => out.push(fill::finish_hole(mesh, hole, policy, &mut checker, p)),
            (None, None) => out.push(fill::fill_hole(mesh, hole, policy, &mut checker)),
        }
    }
    out
}

/// Starts the worker threads that [`repair`] fills holes on (`policy.limits.threads`
/// in all, this one included; rayon's global pool), so that a caller can start them
/// before it reads the mesh. Each worker then waits for the fill by spinning, for at
/// most [`WARM_SPIN`]: a worker that sleeps instead (or is started when the fill
/// starts) begins work 2 to 4 ms after the fill starts in about half of the runs on
/// the bench machine (a virtual machine; measured in `holefill fill`, against
/// 0.1 ms when it is awake), a fifth of the whole fill of a 10-hole mesh. The cost is
/// one core busy while the input is read; a spinning worker runs the pool's other jobs
/// (the OBJ reader's) as they come. Optional: without it the pool starts on
/// first use. Does nothing but spin when the pool is already running.
pub fn start_workers(policy: &Policy) {
    let threads = match policy.limits.threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    };
    if threads > 1 {
        let _ = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global();
        for _ in 1..threads {
            rayon::spawn(|| {
                let t = Instant::now();
                let mut spins = 0u32;
                while !FILL_STARTED.load(std::sync::atomic::Ordering::Acquire) {
                    std::hint::spin_loop();
                    spins = spins.wrapping_add(1);
                    // other work for the pool meanwhile (the OBJ reader's pieces) is
                    // done here, so a spinning worker never holds the reader back
                    if spins % 64 == 0 {
                        let _ = rayon::yield_now();
                    }
                    if spins % 1024 == 0 && t.elapsed() > WARM_SPIN {
                        break;
                    }
                }
            });
        }
    }
}

/// Longest time a worker started by [`start_workers`] spins waiting for the fill.
pub const WARM_SPIN: std::time::Duration = std::time::Duration::from_millis(200);

/// Longest time the filling thread spins for the other workers' last holes before
/// it sleeps until they finish (see [`propose_all`]).
const JOIN_SPIN: std::time::Duration = std::time::Duration::from_millis(50);

/// Set when a fill starts: the workers of [`start_workers`] stop spinning.
static FILL_STARTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Phase 1 of [`fill_all`]: the proposals of the holes not skipped (`None` for those),
/// computed on `policy.limits.threads` threads (this one and the others started
/// here). Each thread takes the biggest hole not yet taken (a shared counter over the
/// holes sorted by size, largest first), so a thread that finishes early never waits
/// while another works through a list of big holes (a fixed split put two big holes
/// on one thread).
fn propose_all(
    mesh: &Mesh,
    holes: &[Hole],
    skip: &[Option<String>],
    policy: &Policy,
    checker: &check::Checker,
) -> Vec<Option<fill::Proposal>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let mut order: Vec<usize> = (0..holes.len()).filter(|&i| skip[i].is_none()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(holes[i].len()));
    let run = |i: usize| fill::propose(mesh, &holes[i], policy, checker, 0);
    let threads = match policy.limits.threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
    .min(order.len() + 1);
    let next = AtomicUsize::new(0);
    let slots: Vec<Mutex<Option<fill::Proposal>>> =
        order.iter().map(|_| Mutex::new(None)).collect();
    // job 0 computes the checker's face boxes, so that they are ready (or being
    // made) when the first patch is checked; the others are the holes
    let work = || loop {
        let j = next.fetch_add(1, Ordering::Relaxed);
        if j == 0 {
            if !order.is_empty() {
                checker.prepare(mesh);
            }
            continue;
        }
        let Some(&i) = order.get(j - 1) else { break };
        let j = j - 1;
        let p = run(i);
        if let Ok(mut slot) = slots[j].lock() {
            *slot = Some(p);
        }
    };
    // this thread works too, so the biggest hole starts at once; the others are jobs
    // on rayon's pool (started early by [`start_workers`], or here on first use); a
    // job that starts late finds the holes taken and leaves at once
    // the workers of `start_workers` stop spinning and take these jobs
    FILL_STARTED.store(true, Ordering::Release);
    // jobs that have returned from `work`: this thread waits for them by spinning
    // before it leaves the scope, whose own wait sleeps on a condition variable
    // when a job is still running (waking from it took 0.5 ms on the bench machine,
    // a twentieth of a bunny scan's fill). A job still running after JOIN_SPIN is
    // waited for by the scope.
    let done = AtomicUsize::new(0);
    rayon::in_place_scope(|s| {
        for _ in 1..threads {
            s.spawn(|_| {
                work();
                done.fetch_add(1, Ordering::Release);
            });
        }
        work();
        let t = std::time::Instant::now();
        let mut spins = 0u32;
        while done.load(Ordering::Acquire) < threads - 1 {
            std::hint::spin_loop();
            spins = spins.wrapping_add(1);
            if spins % 1024 == 0 && t.elapsed() > JOIN_SPIN {
                break;
            }
        }
        // the pool marks a job finished just after it returns: a few more
        // microseconds, so that the scope finds it finished and does not sleep
        let t = std::time::Instant::now();
        while t.elapsed() < std::time::Duration::from_micros(20) {
            std::hint::spin_loop();
        }
    });
    let computed = slots.into_iter().map(|m| m.into_inner().ok().flatten());
    let mut out: Vec<Option<fill::Proposal>> = vec![None; holes.len()];
    for (&i, c) in order.iter().zip(computed) {
        out[i] = Some(c.unwrap_or_else(|| run(i)));
    }
    out
}

/// The outer-border rule for a loop that is the longest of its component (with
/// `border.only_longest`, the caller clears it for the others): `Some(reason)` when
/// the loop is skipped.
fn border_rule(mesh: &Mesh, hole: &Hole, policy: &Policy, diag: f64) -> Option<String> {
    let b = &policy.border;
    if b.max_vertices > 0 && hole.len() > b.max_vertices {
        return Some(format!(
            "outer border: {} boundary vertices > border.max_vertices = {}",
            hole.len(),
            b.max_vertices
        ));
    }
    if b.max_bbox_share > 0.0 && diag > 0.0 {
        let pts: Vec<_> = hole
            .vertices
            .iter()
            .map(|&v: &VertexId| mesh.pos(v))
            .collect();
        let lo = pts
            .iter()
            .fold(glam::DVec3::splat(f64::INFINITY), |a, p| a.min(*p));
        let hi = pts
            .iter()
            .fold(glam::DVec3::splat(f64::NEG_INFINITY), |a, p| a.max(*p));
        let share = (hi - lo).length() / diag;
        if share > b.max_bbox_share {
            return Some(format!(
                "outer border: loop spans {:.2} of the mesh's bounding-box diagonal > border.max_bbox_share = {}",
                share, b.max_bbox_share
            ));
        }
    }
    None
}

/// Connected component of every face (through twins).
fn components(mesh: &Mesh) -> Vec<usize> {
    let nf = mesh.num_faces();
    let mut comp = vec![usize::MAX; nf];
    let mut stack = Vec::new();
    let mut next = 0;
    for s in 0..nf {
        if comp[s] != usize::MAX {
            continue;
        }
        comp[s] = next;
        stack.push(s);
        while let Some(f) = stack.pop() {
            for c in 0..3 {
                if let Some(t) = mesh.topo.twin(FaceId::from_idx(f).halfedge(c)) {
                    let g = t.face().idx();
                    if comp[g] == usize::MAX {
                        comp[g] = next;
                        stack.push(g);
                    }
                }
            }
        }
        next += 1;
    }
    comp
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn soup(pos: &[[f64; 2]], faces: &[[u32; 3]]) -> RawMesh {
        RawMesh {
            positions: pos.iter().map(|p| DVec3::new(p[0], p[1], 0.0)).collect(),
            faces: faces.to_vec(),
            ..Default::default()
        }
    }

    #[test]
    fn long_boundary_edges_are_split_until_none_is_long() {
        // A(0,0) B(4,0) C(4,1) D(0,1) E(1,1) F(2,1) G(3,1): edge A-B is long
        let raw = soup(
            &[
                [0., 0.],
                [4., 0.],
                [4., 1.],
                [0., 1.],
                [1., 1.],
                [2., 1.],
                [3., 1.],
            ],
            &[[0, 1, 6], [0, 6, 5], [0, 5, 4], [0, 4, 3], [1, 2, 6]],
        );
        let (mut m, _) = Mesh::from_raw(&raw);
        let n = split_long_edges(&mut m, 2.0);
        m.validate().unwrap();
        assert_eq!(n, 1);
        assert_eq!(m.num_faces(), 6);
        assert_eq!(m.pos(VertexId(7)), DVec3::new(2.0, 0.0, 0.0));
        assert_eq!(m.origin[7], None);
        // input vertices untouched
        for i in 0..7 {
            assert_eq!(m.pos(VertexId(i)), raw.positions[i as usize]);
        }
    }

    #[test]
    fn teeth_are_removed_but_never_a_whole_component() {
        // a 2x1 grid of quads with a tooth on its top edge, plus a lone pair of triangles
        let raw = soup(
            &[
                [0., 0.],
                [1., 0.],
                [2., 0.],
                [0., 1.],
                [1., 1.],
                [2., 1.],
                [1.5, 2.],
                [5., 5.],
                [6., 5.],
                [6., 6.],
                [5., 6.],
            ],
            &[
                [0, 1, 4],
                [0, 4, 3],
                [1, 2, 5],
                [1, 5, 4],
                [4, 5, 6], // tooth
                [7, 8, 9],
                [7, 9, 10],
            ],
        );
        let (m, _) = Mesh::from_raw(&raw);
        let (m, removed) = remove_teeth(m);
        m.validate().unwrap();
        // the tooth goes; then corner triangles of the grid become teeth too and go,
        // but each component keeps faces
        assert!(removed >= 1);
        assert!(m.num_faces() >= 3, "{} faces left", m.num_faces());
        let comp = components(&m);
        assert_eq!(
            comp.iter().max().copied(),
            Some(1),
            "both components survive"
        );
    }
}
