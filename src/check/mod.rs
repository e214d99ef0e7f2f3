//! Patch checks (ALGORITHMS A5): a patch is accepted only if every new triangle is
//! non-degenerate, the patch is a topological disk that closes the hole exactly (so
//! the mesh stays edge-manifold and consistently oriented), and no new triangle
//! intersects another triangle of the mesh or of the patch.
//!
//! Self-intersection: the broad phase is a scan of the mesh's face boxes (`f32`,
//! compared in blocks) or, after many checks, a bounding-volume hierarchy
//! ([`crate::geometry::bvh`]) over them, plus a logarithmic set of small trees over the faces
//! committed since and a linear scan of a short tail of them (see [`Checker`]); the
//! narrow phase is an exact triangle-triangle test on `robust::orient3d`/`orient2d`
//! signs ([`crate::geometry::predicates::tri_tri`]). Repairs that change a few
//! triangles of a patch at a time (edge flips, re-triangulating a region) use
//! [`PatchChecks`], which records every failure once and re-tests only what a change
//! touches, with the same result.
//!
//! Readings where A5 is vague:
//! - Triangles that share vertices follow CGAL's convention (as in
//!   `Polygon_mesh_processing::self_intersections`): sharing one vertex they
//!   intersect only if they meet somewhere else; sharing an edge only if they
//!   overlap beyond it (a coplanar fold). Nothing else is excluded: a mesh face that
//!   merely touches a patch triangle at a point that is not a shared vertex counts.
//! - "Shared" is by identity, never by coordinates: a patch's loop vertex `i` is mesh
//!   vertex `hole[i]`, new vertices are new. Copies of one input vertex made by the
//!   mesh builder when it split a non-manifold vertex count as the same vertex while
//!   they still sit at the same coordinates (else a hole at a pinch point could never
//!   be filled: the other fan touches it there).
//! - Patch triangles are tested against each other by the same rules.
//! - The patch's own triangles are checked for degeneracy first, so the narrow phase
//!   may assume them non-degenerate; a zero-area face of the mesh is handled exactly
//!   (as the union of its edges).

mod checker;
mod failure;
mod incremental;
mod quality;
mod topology;

pub use checker::{Checker, SCANS_BEFORE_TREE};
pub use failure::{CheckFailure, Degeneracy, Meets, TopologyFailure};
pub use incremental::{Change, PatchChecks};
pub use quality::{check_degenerate, quality};
pub use topology::check_topology;

use crate::mesh::{Mesh, VertexId};
use crate::patch::Patch;
use glam::DVec3;

/// Positions of every patch vertex (loop first, then new).
pub fn patch_positions(mesh: &Mesh, hole: &[VertexId], patch: &Patch) -> Vec<DVec3> {
    hole.iter()
        .map(|&v| mesh.pos(v))
        .chain(patch.new_vertices.iter().copied())
        .collect()
}

#[cfg(test)]
mod tests;
