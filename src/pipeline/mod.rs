//! One repair, from a triangle soup to a repaired soup and its log: the mesh is
//! built (scan defects resolved and reported), the boundary cleaned and the mesh
//! smoothed when the policy says so, every boundary loop becomes a [`Hole`] (or is
//! skipped by the outer-border rule), and the holes are filled by
//! [`crate::fill::dispatch`] in its two phases.

pub mod clean;

use crate::check::Checker;
use crate::fill::dispatch::{self, parallel};
use crate::io::RawMesh;
use crate::mesh::{Mesh, VertexId};
use crate::patch::Hole;
use crate::policy::Policy;
use crate::report::{Counts, HoleReport, HoleStatus, RepairReport};
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
    report.resolved.reader = raw.notes.clone();
    let (mut mesh, build) = Mesh::from_raw(raw);
    report.resolved.mesh = build;
    if mesh.num_faces() == 0 {
        return Err(RepairError::Empty);
    }
    mesh.validate()?;
    report.before = counts(&mesh);

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
    report.holes = fill_all(&mut mesh, policy, &mut report.resolved.degenerate_loops);
    report.timings.fill_ms = t.elapsed().as_secs_f64() * 1000.0;
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
    let mut checker = Checker::for_checks(mesh, to_fill);
    // phase 1, in parallel: every hole's first acceptable patch against the mesh as it
    // is now (read-only); phase 2, serial in hole order: check each against the
    // patches accepted before it and apply it. The output does not depend on threads.
    let proposals = parallel::propose_all(mesh, &holes, &skip, policy, &checker);
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
            (None, Some(p)) => out.push(dispatch::finish_hole(mesh, hole, policy, &mut checker, p)),
            (None, None) => out.push(dispatch::fill_hole(mesh, hole, policy, &mut checker)),
        }
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
