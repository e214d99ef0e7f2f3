//! Taubin lambda/mu smoothing (being written).
use crate::mesh::Mesh;
use crate::policy::Smooth;
use crate::report::SmoothingReport;

/// Smooths the mesh in place.
pub fn smooth(_mesh: &mut Mesh, _opts: &Smooth) -> SmoothingReport {
    SmoothingReport::default()
}
