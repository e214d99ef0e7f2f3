//! One repair, from a triangle soup to a repaired soup and its log: the mesh is
//! built (scan defects resolved and reported), cracks zipped ([`stitch`]), the
//! boundary cleaned and the mesh
//! smoothed when the policy says so, every boundary loop becomes a [`Hole`] (or is
//! skipped by the outer-border rule), and the holes are filled by
//! [`crate::fill::dispatch`] in its two phases.

pub mod clean;
pub mod islands;
pub mod pinch;
pub mod stitch;

use crate::check::Checker;
use crate::fill::dispatch::{self, parallel};
use crate::geometry::measure;
use crate::io::RawMesh;
use crate::mesh::{FaceId, Mesh, VertexId};
use crate::patch::Hole;
use crate::policy::Policy;
use crate::report::{Counts, HoleReport, HoleStatus, HoleTrace, RepairReport};
use crate::smooth;
use clean::{components, remove_teeth, split_long_edges};
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
    Topology(#[from] crate::mesh::TopologyError),
}

/// Repairs a triangle soup: builds the mesh, cleans the boundary, smooths if the
/// policy says so, and fills every hole. Returns the repaired soup (input vertices
/// first, unmoved unless smoothing is on) and the repair log.
pub fn repair(raw: &RawMesh, policy: &Policy) -> Result<(RawMesh, RepairReport), RepairError> {
    let mut report = RepairReport::new(policy);
    let mut stitched_loops: Vec<Vec<VertexId>> = Vec::new();
    report.resolved.reader = raw.notes.clone();
    let (mut mesh, build) = Mesh::from_raw(raw);
    report.resolved.mesh = build;
    if mesh.num_faces() == 0 {
        return Err(RepairError::Empty);
    }
    mesh.validate()?;
    report.before = counts(&mesh);

    // cracks: zipped, their loops logged "stitched" after the holes
    let mut stitched: Vec<HoleReport> = Vec::new();
    let t_stitch = Instant::now();
    if policy.crack.stitch {
        if let Some(s) = stitch::stitch(&mesh, policy.crack.tolerance) {
            report.resolved.stitched_vertices = s.vertices_merged;
            report.resolved.stitched_faces = s.faces_changed;
            for (lp, merged) in s.closed {
                let hole = Hole::new(0, &mesh, lp, policy);
                stitched.push(hole.report(
                    HoleStatus::Stitched,
                    format!(
                        "a crack: {merged} of its {} vertices coincide with boundary vertices \
                         across it (crack.tolerance = {} of the local edge length) and were \
                         identified with them; no faces added",
                        hole.len(),
                        policy.crack.tolerance
                    ),
                ));
                stitched_loops.push(hole.vertices);
            }
            mesh = s.mesh;
            mesh.validate()?;
        }
    }
    if let Some((m, pieces, faces)) =
        islands::remove_debris(&mesh, policy.debris.remove_below_faces)
    {
        mesh = m;
        report.resolved.debris_pieces_removed = pieces;
        report.resolved.debris_faces_removed = faces;
        mesh.validate()?;
    }
    let stitch_ms = t_stitch.elapsed().as_secs_f64() * 1000.0;

    if policy.clean.remove_teeth {
        let (m, removed) = remove_teeth(mesh);
        mesh = m;
        report.resolved.tooth_faces_removed = removed;
        mesh.validate()?;
    }
    if policy.clean.split_long_edges > 0.0 {
        report.resolved.long_edges_split =
            split_long_edges(&mut mesh, policy.clean.split_long_edges);
        mesh.validate()?;
    }

    if policy.smooth.enabled {
        let t = Instant::now();
        report.smoothing = Some(smooth::smooth(&mut mesh, &policy.smooth));
        report.timings.smooth_ms = t.elapsed().as_secs_f64() * 1000.0;
    }

    let t = Instant::now();
    report.holes = fill_all(
        &mut mesh,
        policy,
        &mut report.resolved.degenerate_loops,
        &mut report.traces,
    );
    report.timings.fill_ms = stitch_ms + t.elapsed().as_secs_f64() * 1000.0;
    let end = mesh.num_faces() as u32;
    for (mut h, lp) in stitched.into_iter().zip(stitched_loops) {
        h.id = report.holes.len();
        report.holes.push(h);
        report.traces.push(HoleTrace {
            boundary: lp.iter().map(|v| v.0).collect(),
            patch: end..end,
        });
    }
    report.after = counts(&mesh);
    report.summarise();
    let t = Instant::now();
    let (out, attributes) = crate::mesh::attributes::carry(&mesh, raw);
    report.attributes = attributes;
    report.timings.attributes_ms = t.elapsed().as_secs_f64() * 1000.0;
    Ok((out, report))
}

fn counts(mesh: &Mesh) -> Counts {
    Counts {
        vertices: mesh.num_vertices(),
        faces: mesh.num_faces(),
        boundary_loops: mesh.topo.boundary_loops().len(),
    }
}

/// Finds the holes, applies the outer-border rule and fills the rest. (Not inlined:
/// profiles and instruction counts of the filling find it by name.)
#[inline(never)]
fn fill_all(
    mesh: &mut Mesh,
    policy: &Policy,
    degenerate: &mut usize,
    traces: &mut Vec<HoleTrace>,
) -> Vec<HoleReport> {
    let (mut holes, mut skip, mut comp) = find_holes(mesh, policy);
    // loops pinched at a split vertex: each cut into two, the smaller lobe filled
    let mut pinches: Vec<pinch::Pinch> = Vec::new();
    if let Some((m, closed)) = pinch::close_pinches(mesh, &holes, &skip, policy) {
        *mesh = m;
        pinches = closed;
        (holes, skip, comp) = find_holes(mesh, policy);
    }
    let pinch_faces: usize = pinches.iter().map(|p| p.added_faces).sum();
    // islands inside holes: removed or bridged (the mesh changes), or their hole skipped
    let (changed, notes) = islands::resolve(mesh, &holes, &skip, &comp, policy);
    // the border rule's decisions are those made before: a loop the islands did not
    // change keeps its own, a hole joined with its islands is filled (the bridges
    // can make it the longest loop of the joined piece)
    let before: Option<crate::fasthash::HashMap<VertexId, Option<String>>> =
        changed.is_some().then(|| {
            holes
                .iter()
                .zip(&skip)
                .filter_map(|(h, s)| h.vertices.first().map(|&v| (v, s.clone())))
                .collect()
        });
    if let Some(m) = changed {
        *mesh = m;
        (holes, skip, _) = find_holes(mesh, policy);
    }
    let bridged: usize = notes.iter().map(|n| n.bridged).sum();
    // the lobes' faces of the pinches, then the bridges', are the first ones added
    let input_faces = mesh.num_faces() - 2 * bridged - pinch_faces;
    let mut note_of: crate::fasthash::HashMap<VertexId, usize> = Default::default();
    for (n, note) in notes.iter().enumerate() {
        for &v in &note.outer {
            note_of.insert(v, n);
        }
    }
    let hole_note: Vec<Option<&islands::Note>> = holes
        .iter()
        .map(|h| {
            h.vertices
                .iter()
                .find_map(|v| note_of.get(v))
                .map(|&n| &notes[n])
        })
        .collect();
    for ((s, note), hole) in skip.iter_mut().zip(&hole_note).zip(&holes) {
        if let Some(n) = note {
            *s = n.blocked.clone();
        } else if let Some(before) = &before {
            if let Some(old) = hole.vertices.iter().find_map(|v| before.get(v)) {
                s.clone_from(old);
            }
        }
    }
    // about one check per hole to fill (more for holes whose first patch fails)
    let to_fill = skip.iter().filter(|s| s.is_none()).count();
    let mut checker = Checker::for_checks(mesh, to_fill);
    // phase 1, in parallel: every hole's first acceptable patch against the mesh as it
    // is now (read-only); phase 2, serial in hole order: check each against the
    // patches accepted before it and apply it. The output does not depend on threads.
    let proposals = parallel::propose_all(mesh, &holes, &skip, policy, &checker);
    let (nv, nf) = proposals
        .iter()
        .flatten()
        .filter_map(|p| p.accepted.as_ref())
        .fold((0, 0), |(v, f), a| {
            (v + a.patch.new_vertices.len(), f + a.patch.triangles.len())
        });
    mesh.reserve(nv, nf);
    let mut out = Vec::with_capacity(holes.len());
    traces.reserve(holes.len());
    for ((hole, rule), proposal) in holes.iter().zip(skip).zip(proposals) {
        if hole.len() < 3 {
            *degenerate += 1;
        }
        // patches are appended to the faces, one hole after the other
        let first_face = mesh.num_faces() as u32;
        match (rule, proposal) {
            (Some(rule), _) => out.push(hole.report(HoleStatus::Skipped, rule)),
            (None, Some(p)) => out.push(dispatch::finish_hole(mesh, hole, policy, &mut checker, p)),
            (None, None) => out.push(dispatch::fill_hole(mesh, hole, policy, &mut checker)),
        }
        traces.push(HoleTrace {
            boundary: hole.vertices.iter().map(|v| v.0).collect(),
            patch: first_face..(mesh.num_faces() as u32).max(first_face),
        });
    }
    if policy.rim.trim {
        trim_failed(mesh, &holes, &mut out, traces, policy, input_faces);
    }
    pinch_notes(mesh, &holes, &mut out, traces, &pinches, policy);
    for (rep, note) in out.iter_mut().zip(&hole_note) {
        if let Some(n) = note {
            rep.island_faces_removed = n.faces_removed;
            rep.islands_bridged = n.bridged;
            rep.added_faces += 2 * n.bridged;
            if n.bridged > 0 && rep.status == HoleStatus::Filled && rep.reason.is_empty() {
                rep.reason = format!(
                    "filled as one patch with {} island(s) bridged to its loop",
                    n.bridged
                );
            }
        }
    }
    out
}

/// Adds the pinches closed before the fill to the log entries of their holes (the
/// hole whose loop runs through the joined vertex), and an entry of their own for
/// the loops that joining closed completely.
fn pinch_notes(
    mesh: &Mesh,
    holes: &[Hole],
    out: &mut Vec<HoleReport>,
    traces: &mut Vec<HoleTrace>,
    pinches: &[pinch::Pinch],
    policy: &Policy,
) {
    let mut own: Vec<(usize, Vec<VertexId>)> = Vec::new();
    for p in pinches {
        let what = match p.method {
            Some(m) => format!(
                "pinched at one point: a lobe of {} boundary vertices filled first ({}, {} faces) \
                 and the two copies of the point joined",
                p.lobe,
                m.name(),
                p.added_faces
            ),
            None => format!(
                "pinched at one point: a lobe of {} boundary vertices closed by joining the two \
                 copies of the point",
                p.lobe
            ),
        };
        // the hole through the joined point, or through what was left of the loop
        // (a pinch nested in another's rest); else a loop closed by pinches alone
        let on = |vs: &[VertexId]| vs.contains(&p.vertex) || p.rest.iter().any(|v| vs.contains(v));
        let at = holes
            .iter()
            .position(|h| on(&h.vertices))
            .or_else(|| own.iter().find(|(_, vs)| on(vs)).map(|(i, _)| *i));
        let rep = match at {
            Some(i) => &mut out[i],
            None => {
                let mut lp = vec![p.vertex];
                lp.extend(p.rest.iter().copied());
                own.push((out.len(), lp.clone()));
                let hole = Hole::new(out.len(), mesh, lp, policy);
                let mut rep = hole.report(HoleStatus::Filled, String::new());
                rep.method = p.method;
                let end = mesh.num_faces() as u32;
                traces.push(HoleTrace {
                    boundary: hole.vertices.iter().map(|v| v.0).collect(),
                    patch: end..end,
                });
                out.push(rep);
                out.last_mut().expect("pushed")
            }
        };
        rep.added_vertices += p.added_vertices;
        rep.added_faces += p.added_faces;
        if rep.method.is_none() && rep.status == HoleStatus::Filled {
            rep.method = p.method;
        }
        rep.reason = if rep.reason.is_empty() {
            what
        } else {
            format!("{}; {what}", rep.reason)
        };
    }
}

/// The holes of the mesh as it is, the border rule's reason for each loop it skips,
/// and the connected piece of every face.
fn find_holes(mesh: &Mesh, policy: &Policy) -> (Vec<Hole>, Vec<Option<String>>, Vec<usize>) {
    let loops = mesh.topo.boundary_loops();
    let diag = mesh.bbox_diagonal();
    let holes: Vec<Hole> = loops
        .into_iter()
        .enumerate()
        .map(|(i, l)| Hole::new(i, mesh, l, policy))
        .collect();
    // which holes to fill, and which rule skips the others (the outer border of an
    // open piece); with `only_longest` the rules hold only for the longest loop of
    // each connected component (also the islands' pieces).
    let b = &policy.border;
    let mut skip: Vec<Option<String>> = holes
        .iter()
        .map(|hole| border_rule(mesh, hole, policy, diag))
        .collect();
    let comp = components(mesh);
    {
        let ncomp = comp.iter().copied().max().map_or(0, |m| m + 1);
        let mut area = vec![0.0f64; ncomp];
        let mut count = vec![0usize; ncomp];
        for (f, &c) in comp.iter().enumerate() {
            area[c] += mesh.face_normal_raw(FaceId::from_idx(f)).length() * 0.5;
            count[c] += 1;
        }
        let loop_comp: Vec<Option<usize>> = holes
            .iter()
            .map(|h| {
                h.vertices
                    .first()
                    .and_then(|&v| mesh.topo.anchor(v))
                    .map(|a| comp[a.face().idx()])
            })
            .collect();
        // longest loop (by perimeter) of each component
        let mut longest: Vec<Option<usize>> = vec![None; ncomp];
        for (i, h) in holes.iter().enumerate() {
            if let Some(c) = loop_comp[i] {
                if longest[c].is_none_or(|j| h.perimeter > holes[j].perimeter) {
                    longest[c] = Some(i);
                }
            }
        }
        for (i, s) in skip.iter_mut().enumerate() {
            let Some(c) = loop_comp[i] else { continue };
            if b.only_longest && longest[c] != Some(i) {
                *s = None;
                continue;
            }
            if s.is_none() && b.min_area_share > 0.0 && area[c] > 0.0 {
                let pts: Vec<_> = holes[i].vertices.iter().map(|&v| mesh.pos(v)).collect();
                let share = measure::vector_area(&pts) / area[c];
                if share >= b.min_area_share {
                    *s = Some(format!(
                        "outer border: the loop spans {share:.2} of the area of its piece \
                         ({} faces) >= border.min_area_share = {} (an open surface, not a \
                         hole in a closed one)",
                        count[c], b.min_area_share
                    ));
                }
            }
        }
    }
    (holes, skip, comp)
}

/// The last step of the chain: every hole that failed, in hole order, gets its rim
/// trimmed and the larger hole filled ([`dispatch::rim`]). A hole whose loop is no
/// longer a boundary loop of the mesh (an earlier trim reached it) is left as it is
/// reported.
fn trim_failed(
    mesh: &mut Mesh,
    holes: &[Hole],
    out: &mut [HoleReport],
    traces: &mut [HoleTrace],
    policy: &Policy,
    input_faces: usize,
) {
    let mut input_faces = input_faces;
    let mut avoid = vec![false; mesh.num_vertices()];
    for (hole, rep) in holes.iter().zip(out.iter()) {
        if rep.status == HoleStatus::Skipped {
            for v in &hole.vertices {
                avoid[v.idx()] = true;
            }
        }
    }
    for (i, (hole, rep)) in holes.iter().zip(out.iter_mut()).enumerate() {
        if rep.status != HoleStatus::Failed || hole.len() < 3 {
            continue;
        }
        // still a boundary loop of the mesh as it is now?
        let open = hole
            .vertices
            .iter()
            .all(|&v| mesh.topo.is_boundary_vertex(v));
        if !open {
            continue;
        }
        let t0 = Instant::now();
        if let Some(t) = dispatch::rim::trim_and_fill(mesh, hole, policy, input_faces, &avoid) {
            let mut tried = std::mem::take(&mut rep.tried);
            tried.extend(t.report.tried.iter().cloned());
            let ms = rep.ms;
            *rep = t.report;
            rep.tried = tried;
            rep.reason = format!(
                "filled after rim trimming: {} input faces removed, loop of {} boundary vertices",
                t.removed, rep.boundary_vertices
            );
            rep.ms = ms + t0.elapsed().as_secs_f64() * 1000.0;
            input_faces -= t.removed;
            // rebuilding keeps face order: the patches (after the input faces) move
            // down by the faces removed, and this hole's patch is the new tail
            let before = (mesh.num_faces() - t.removed) as u32;
            let shift = t.removed as u32;
            for tr in traces.iter_mut() {
                tr.patch = tr.patch.start.saturating_sub(shift)..tr.patch.end.saturating_sub(shift);
            }
            if let Some(tr) = traces.get_mut(i) {
                tr.patch = before..(t.mesh.num_faces() as u32).max(before);
            }
            *mesh = t.mesh;
        }
    }
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

#[cfg(test)]
mod tests;
