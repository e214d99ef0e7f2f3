//! Self-checked attempts: the in-method fallback shared by `wavefront`, `hpde` and
//! `lssvm_poisson`.
//!
//! The papers' methods are not robust on every scanned hole (paper 004's conclusion
//! admits overlaps; paper 000 projects onto a plane that a folded loop does not project
//! onto simply). Rather than hand such a hole to another method, a method here runs a
//! short list of its own variants (the policy's settings first, then documented
//! alternatives of the same method: another seed, another reading of a vague passage)
//! and returns the first patch that passes the dispatcher's own checks
//! ([`crate::check::Checker::check_patch`]: topology, degenerate triangles,
//! intersections with itself and the mesh). The dispatcher checks the result again.
//! With the policy's settings passing (most holes), the result is the same as without
//! this wrapper; the list is fixed, so the output stays deterministic.

use super::super::{FillContext, FillError, Patch};
use crate::check::Checker;
use crate::policy::Policy;

/// Runs `run` under each policy of `variants` (first = the policy as given) and returns
/// the first patch that passes the checks, else a failure listing why each variant
/// failed.
pub fn first_passing(
    ctx: &FillContext,
    variants: &[(&str, Policy)],
    run: impl Fn(&FillContext) -> Result<Patch, FillError>,
) -> Result<Patch, FillError> {
    first_passing_at(ctx, variants, |_, c| run(c))
}

/// [`first_passing`] for variants that are not only policies: `run` also gets the
/// variant's index.
pub fn first_passing_at(
    ctx: &FillContext,
    variants: &[(&str, Policy)],
    run: impl Fn(usize, &FillContext) -> Result<Patch, FillError>,
) -> Result<Patch, FillError> {
    let mut checker: Option<Checker> = None;
    let mut reasons: Vec<String> = Vec::new();
    for (at, (name, pol)) in variants.iter().enumerate() {
        ctx.deadline.check()?;
        let sub = FillContext {
            mesh: ctx.mesh,
            hole: ctx.hole,
            policy: pol,
            deadline: ctx.deadline,
        };
        match run(at, &sub) {
            Ok(p) => {
                if variants.len() == 1 {
                    return Ok(p);
                }
                let c = checker.get_or_insert_with(|| Checker::new(ctx.mesh));
                match c.check_patch(ctx.mesh, &ctx.hole.vertices, &p, &ctx.policy.checks) {
                    Ok(_) => return Ok(p),
                    Err(e) => reasons.push(format!("{name}: {e}")),
                }
            }
            Err(FillError::Timeout) => return Err(FillError::Timeout),
            Err(FillError::Failed(e)) => reasons.push(format!("{name}: {e}")),
        }
    }
    if reasons.len() == 1 {
        return Err(FillError::Failed(reasons.remove(0)));
    }
    Err(FillError::Failed(format!(
        "every variant failed ({})",
        reasons.join("; ")
    )))
}
