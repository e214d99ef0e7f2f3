//! What the methods are built from: the context a method sees ([`FillContext`]), its
//! error ([`FillError`]) and deadline, and the shared building blocks: minimum-area
//! triangulation ([`triangulate`]), refinement ([`refine`]), the fairing solver
//! ([`fair`]), tangential relaxation ([`relax`]), the closing of a residual front
//! ([`residual`]), the self-checked variants with their local repairs ([`retry`]), and
//! the queue and edge keys of the front engines ([`front`]).

mod error;
pub mod fair;
pub mod front;
pub mod refine;
pub mod relax;
pub mod residual;
pub mod retry;
pub mod triangulate;

pub use error::{Cause, FillError, TooLarge, VariantFailure, VariantWhy};

use crate::check::Checker;
use crate::geometry::measure;
use crate::mesh::Mesh;
use crate::patch::{Hole, Patch};
use crate::policy::Policy;
use crate::report::PatchQuality;
use glam::DVec3;
use std::time::{Duration, Instant};

/// A point in time past which a method gives up with [`FillError::Timeout`].
#[derive(Clone, Copy, Debug)]
pub struct Deadline(pub Option<Instant>);

impl Deadline {
    /// A deadline `ms` from now (0: none).
    pub fn after_ms(ms: u64) -> Deadline {
        if ms == 0 {
            Deadline(None)
        } else {
            Deadline(Some(Instant::now() + Duration::from_millis(ms)))
        }
    }
    /// No deadline.
    pub fn none() -> Deadline {
        Deadline(None)
    }
    /// `Err(Timeout)` once the deadline has passed.
    pub fn check(&self) -> Result<(), FillError> {
        match self.0 {
            Some(t) if Instant::now() >= t => Err(FillError::Timeout),
            _ => Ok(()),
        }
    }
}

/// A caller's last step for each patch a self-checked method makes ([`retry`]): the
/// patch finished (moved, relaxed and checked by the caller) with the quality of the
/// checks it passed, or `None` when it does not apply or fails, and the method then
/// relaxes and checks the patch as made itself.
pub type Finish<'a> = dyn Fn(&Patch) -> Option<(Patch, PatchQuality)> + Sync + 'a;

/// What a method sees: the mesh (read-only), the hole, the policy, the deadline.
pub struct FillContext<'a> {
    pub mesh: &'a Mesh,
    pub hole: &'a Hole,
    pub policy: &'a Policy,
    pub deadline: Deadline,
    /// The dispatcher's checks over `mesh`, for a method that checks its own patch
    /// (`None`: the method builds its own, which costs a tree over the whole mesh).
    pub checker: Option<&'a Checker>,
    /// An earlier method of the hole's list stopped its variants at a loop edge where
    /// two of them had failed (the rim forces that failure, see [`retry`]): a
    /// self-checked method then runs its first variant only, with its local repairs,
    /// and leaves the rest to the rim trimming.
    pub rim_bound: bool,
    /// The patch is only a surface to pull toward (`[blend]`'s second fill): a
    /// self-checked method whose first variant is made but fails the checks returns it
    /// as made rather than running the others (joint seed 2: six wavefront variants,
    /// 450 ms, for a guide).
    pub guide: bool,
    /// The dispatcher's `[blend]` toward the patch's own faired surface, applied by a
    /// self-checked method to each patch it makes before its own relaxation: the
    /// blend relaxes and checks the patch anyway, so relaxing it first was done twice
    /// (`None`: the patch is relaxed and checked as made).
    pub finish: Option<&'a Finish<'a>>,
}

impl FillContext<'_> {
    /// Position of patch vertex `i` (boundary vertices only: `i < k`).
    pub fn boundary_pos(&self, i: usize) -> DVec3 {
        self.mesh.pos(self.hole.vertices[i])
    }
    /// Positions of the loop.
    pub fn boundary_positions(&self) -> Vec<DVec3> {
        self.hole
            .vertices
            .iter()
            .map(|&v| self.mesh.pos(v))
            .collect()
    }
}

impl<'a> FillContext<'a> {
    /// The context of `hole` without deadline or checker.
    pub fn new(mesh: &'a Mesh, hole: &'a Hole, policy: &'a Policy) -> FillContext<'a> {
        FillContext {
            mesh,
            hole,
            policy,
            deadline: Deadline::none(),
            checker: None,
            rim_bound: false,
            guide: false,
            finish: None,
        }
    }
}

/// Runs `method` on the loop `lp` of `mesh` as hole 0, without deadline or checker
/// (the methods' unit tests).
#[cfg(test)]
pub(crate) fn run_on(
    mesh: &Mesh,
    lp: Vec<crate::mesh::VertexId>,
    policy: &Policy,
    method: impl Fn(&FillContext) -> Result<crate::patch::Patch, FillError>,
) -> (Hole, Result<crate::patch::Patch, FillError>) {
    let hole = Hole::new(0, mesh, lp, policy);
    let r = method(&FillContext::new(mesh, &hole, policy));
    (hole, r)
}

/// For methods without a coarsening of their own (`wavefront`, `hpde`,
/// `lssvm_poisson`): `Err` at once when a patch at the loop's mean edge length would
/// pass `limits.max_patch_triangles` (the loop's projected area over the area of an
/// equilateral triangle; a lower bound), so that a hole they cannot finish in time goes
/// to the next method without spending the time limit.
pub fn check_patch_size(ctx: &FillContext) -> Result<(), FillError> {
    let cap = ctx.policy.limits.max_patch_triangles;
    let l = ctx.hole.mean_edge_length;
    if cap == 0 || l.is_nan() || l <= 0.0 {
        return Ok(());
    }
    let est = measure::vector_area(&ctx.boundary_positions()) / (0.75f64.sqrt() / 2.0 * l * l);
    if est > cap as f64 {
        return Err(FillError::TooLarge(TooLarge::Estimated {
            estimated: est,
            cap,
        }));
    }
    Ok(())
}
