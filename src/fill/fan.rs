//! Centroid fan for small holes.
//!
//! Paper 002 (Feng et al. 2020), §5.1: the centroid `c` of the boundary loop is
//! connected to every boundary edge, giving triangles `(v_i, v_{i+1}, c)` oriented like
//! the neighbouring faces (the loop's orientation, see [`crate::patch::Hole`]). A loop of three
//! vertices gets one triangle and no new vertex.
//!
//! Reading: the paper places `c` at the plain mean of the loop vertices. On a curved
//! surface that sinks the apex below the surface for larger loops; it is what the
//! paper says and the policy uses `fan` only for loops of at most `small_max` vertices.

use super::kit::{FillContext, FillError};
use crate::geometry::measure;
use crate::patch::Patch;

/// Fills the hole with a centroid fan.
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "a loop of {k} vertices has no fan"
        )));
    }
    if k == 3 {
        return Ok(Patch {
            new_vertices: Vec::new(),
            triangles: vec![[0, 1, 2]],
        });
    }
    let pts = ctx.boundary_positions();
    let c = measure::centroid(&pts);
    let ci = k as u32;
    let triangles = (0..k)
        .map(|i| [i as u32, ((i + 1) % k) as u32, ci])
        .collect();
    Ok(Patch {
        new_vertices: vec![c],
        triangles,
    })
}
