//! (being written)
use super::{FillContext, FillError, Patch};

/// Fills the hole.
pub fn fill(_ctx: &FillContext) -> Result<Patch, FillError> {
    Err(FillError::Failed("wavefront is not available yet".into()))
}
