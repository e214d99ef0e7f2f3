//! Why a method produced no patch, as data: the dispatch and the self-checked variants
//! act on the kind (a timeout ends the hole's time, a runaway front skips the variants
//! that would run away too), never on the message; the message is the log's reason.

use crate::check::CheckFailure;

/// Why a method produced no patch.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FillError {
    /// The per-hole time limit ran out.
    #[error("time limit reached")]
    Timeout,
    /// A front's patch grew past `max_area_ratio` times the loop's vector area (the
    /// policy key `key`: `wavefront.max_area_ratio`, `lssvm.max_area_ratio`): the front
    /// climbed away from the hole.
    #[error(
        "the front ran away: the patch's area passed {max_area_ratio} times the loop's \
         vector area ({key})"
    )]
    Runaway {
        key: &'static str,
        max_area_ratio: f64,
    },
    /// The patch would pass (or passed) a size limit.
    #[error("{0}")]
    TooLarge(TooLarge),
    /// The method failed, for the cause given.
    #[error("{0}")]
    Failed(Cause),
}

/// Which size limit a patch would pass.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TooLarge {
    /// Estimated from the loop's projected area, before any work.
    #[error(
        "the patch would have about {estimated:.0} triangles > limits.max_patch_triangles = {cap}"
    )]
    Estimated { estimated: f64, cap: usize },
    /// The loop is longer than `wavefront.max_boundary_vertices`.
    #[error("{vertices} boundary vertices > wavefront.max_boundary_vertices = {max}")]
    Loop { vertices: usize, max: usize },
    /// The front made more triangles than `limits.max_patch_triangles` and had not closed.
    #[error(
        "the patch passed limits.max_patch_triangles = {cap} triangles with {front} front \
         vertices left"
    )]
    Front { cap: usize, front: usize },
    /// The refinement would pass its triangle cap.
    #[error("refinement would exceed {0} triangles")]
    Refinement(usize),
    /// The advancing front made more vertices than its cap.
    #[error("advancing front created more than {0} vertices")]
    Vertices(usize),
}

/// What a method could not do. The text says it for the log.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Cause {
    /// The loop is not one the method can fill: too few vertices, no length, a vertex
    /// twice, a non-finite coordinate, no plane it projects onto simply.
    #[error("{0}")]
    Loop(String),
    /// The construction could not go on: a front that is stuck, diverges or overlaps,
    /// no admissible triangulation.
    #[error("{0}")]
    Stuck(String),
    /// A linear solve failed (fairing, LS-SVM, Poisson).
    #[error("{0}")]
    Solver(String),
    /// The method's own bookkeeping broke (a bug): the hole goes to the next method.
    #[error("{0}")]
    Internal(String),
    /// A variant of a self-checked method not run: the policy's own run ran away, and a
    /// variant with the same full front would too.
    #[error("skipped: the front ran away under the policy's settings")]
    SkippedAfterRunaway,
    /// A variant that would repeat the policy's run, whose patch failed the checks.
    #[error("the same front as the policy's, whose patch failed the checks")]
    SameAsPolicy,
    /// A variant of a self-checked method not run: two variants before it made patches
    /// that failed at a triangle on the same loop edge (a sliver or a crossing forced by
    /// the rim there; measured on a folded photogrammetry rim: every variant failed the
    /// same way), which the rim trimming of the dispatcher mends, not other settings.
    #[error("skipped: two variants failed at the same loop edge ({0}, {1})")]
    SameRimFailure(usize, usize),
    /// A variant of a self-checked method not run: an earlier method of the hole's
    /// list stopped its variants at a repeated loop edge ([`Cause::SameRimFailure`]).
    #[error("skipped: an earlier method failed twice at one loop edge")]
    RimBound,
    /// Every variant of a self-checked method failed (see
    /// [`crate::fill::kit::retry`]), each for its reason.
    #[error("{}", variants_text(.0))]
    Variants(Vec<VariantFailure>),
}

/// One variant of a self-checked method and why it gave no patch.
#[derive(Clone, Debug, PartialEq)]
pub struct VariantFailure {
    pub name: &'static str,
    pub why: VariantWhy,
}

/// Why a variant gave no patch.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VariantWhy {
    /// The method failed.
    #[error("{0}")]
    Failed(Box<FillError>),
    /// Its patch failed the checks (and the local repairs).
    #[error("{0}")]
    Rejected(CheckFailure),
}

/// `name: why` for one variant; `every variant failed (a: ..; b: ..)` for more.
fn variants_text(v: &[VariantFailure]) -> String {
    let each: Vec<String> = v.iter().map(|f| format!("{}: {}", f.name, f.why)).collect();
    match each.as_slice() {
        [one] => one.clone(),
        _ => format!("every variant failed ({})", each.join("; ")),
    }
}

impl FillError {
    /// Whether a self-checked method stopped its variants at a repeated loop edge
    /// ([`Cause::SameRimFailure`] among its variants' failures).
    pub fn stopped_at_rim(&self) -> bool {
        matches!(self, FillError::Failed(Cause::Variants(v)) if v.iter().any(|f| matches!(
            &f.why,
            VariantWhy::Failed(e) if matches!(**e, FillError::Failed(Cause::SameRimFailure(..)))
        )))
    }
    /// [`Cause::Loop`].
    pub fn bad_loop(why: impl Into<String>) -> FillError {
        FillError::Failed(Cause::Loop(why.into()))
    }
    /// [`Cause::Stuck`].
    pub fn stuck(why: impl Into<String>) -> FillError {
        FillError::Failed(Cause::Stuck(why.into()))
    }
    /// [`Cause::Solver`].
    pub fn solver(why: impl Into<String>) -> FillError {
        FillError::Failed(Cause::Solver(why.into()))
    }
    /// [`Cause::Internal`].
    pub fn internal(why: impl Into<String>) -> FillError {
        FillError::Failed(Cause::Internal(why.into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::check::{CheckFailure, Meets};

    /// Only a variant stopped at a repeated loop edge marks the hole's rim as the cause
    /// (the dispatcher's `rim_bound`), not another failure, nor a skip for that reason.
    #[test]
    fn a_stop_at_a_repeated_loop_edge_is_found_among_the_variants() {
        let failed = |c: Cause| VariantFailure {
            name: "v",
            why: VariantWhy::Failed(Box::new(FillError::Failed(c))),
        };
        let rejected = VariantFailure {
            name: "policy",
            why: VariantWhy::Rejected(CheckFailure::SelfIntersection {
                triangle: 0,
                meets: Meets::MeshFace(1),
            }),
        };
        let stopped = FillError::Failed(Cause::Variants(vec![
            rejected.clone(),
            failed(Cause::SameRimFailure(3, 4)),
        ]));
        assert!(stopped.stopped_at_rim());
        let other = FillError::Failed(Cause::Variants(vec![
            rejected,
            failed(Cause::RimBound),
            failed(Cause::SkippedAfterRunaway),
        ]));
        assert!(!other.stopped_at_rim());
        assert!(!FillError::Failed(Cause::SameRimFailure(3, 4)).stopped_at_rim());
        assert!(!FillError::Timeout.stopped_at_rim());
    }

    #[test]
    fn messages_are_the_logs_wording() {
        assert_eq!(
            FillError::Runaway {
                key: "wavefront.max_area_ratio",
                max_area_ratio: 2.0
            }
            .to_string(),
            "the front ran away: the patch's area passed 2 times the loop's vector area \
             (wavefront.max_area_ratio)"
        );
        assert_eq!(
            FillError::TooLarge(TooLarge::Estimated {
                estimated: 1234.4,
                cap: 1000
            })
            .to_string(),
            "the patch would have about 1234 triangles > limits.max_patch_triangles = 1000"
        );
        let one = vec![VariantFailure {
            name: "policy",
            why: VariantWhy::Failed(Box::new(FillError::bad_loop("no length"))),
        }];
        assert_eq!(
            FillError::Failed(Cause::Variants(one.clone())).to_string(),
            "policy: no length"
        );
        let mut two = one;
        two.push(VariantFailure {
            name: "next seed",
            why: VariantWhy::Rejected(CheckFailure::SelfIntersection {
                triangle: 1,
                meets: Meets::MeshFace(2),
            }),
        });
        assert_eq!(
            FillError::Failed(Cause::Variants(two)).to_string(),
            "every variant failed (policy: no length; next seed: patch triangle 1 intersects \
             mesh face 2)"
        );
    }
}
