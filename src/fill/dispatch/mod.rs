//! The size-based dispatch of paper 002 (Feng et al. 2020, §3) and the fallback chain.
//!
//! Each method is a module with a `fill(&FillContext) -> Result<Patch, FillError>`.
//! A method only proposes a [`Patch`]; this module checks it ([`crate::check`]),
//! and only an accepted patch is applied to the mesh, so a rejected one needs no undo.
//! Every hole ends filled, skipped (with the rule) or failed (with every attempt and why).
//! The two phases of a fill, holes in parallel then serially in hole order, are in
//! [`parallel`].

pub mod blend;
pub mod parallel;
pub mod rim;
pub mod select;

use super::kit::retry::Passed;
use super::kit::{relax, Deadline, FillContext, FillError};
use super::{advancing_front, close, fan, hpde, lssvm_poisson, min_area_fair, wavefront};
use crate::check::Checker;
use crate::mesh::Mesh;
use crate::patch::{apply_patch, Hole, Patch};
use crate::policy::{Method, Policy};
use crate::report::{
    Attempt, BlendReport, HoleClass, HoleReport, HoleStatus, Outcome, PatchQuality, Selection,
};
use std::time::Instant;

/// Runs one method.
pub fn run_method(method: Method, ctx: &FillContext) -> Result<Patch, FillError> {
    run_method_checked(method, ctx).map(|(p, _)| p)
}

/// Runs one method; with the patch, the quality of the checks it already passed
/// inside the method (the self-checked methods `min_area_fair`, `advancing_front`,
/// `wavefront`, `hpde` and `lssvm_poisson` relax and check their patch with the
/// dispatcher's checker, or hand it to [`FillContext::finish`], see
/// [`crate::fill::kit::retry`]), or `None` when the dispatcher must relax and check it.
pub fn run_method_checked(
    method: Method,
    ctx: &FillContext,
) -> Result<(Patch, Option<Passed>), FillError> {
    match method {
        Method::Fan => fan::fill(ctx).map(|p| (p, None)),
        Method::MinAreaFair => min_area_fair::fill_checked(ctx),
        Method::AdvancingFront => advancing_front::fill_checked(ctx),
        Method::LssvmPoisson => lssvm_poisson::fill_checked(ctx),
        Method::Wavefront => wavefront::fill_checked(ctx),
        Method::Hpde => hpde::fill_checked(ctx),
        Method::Close => close::fill_checked(ctx),
    }
}

/// Runs one method's `fill`: its patch without the dispatcher's relaxation and final
/// checks (the self-validation's candidates, [`select`], and the blend's guide,
/// [`blend`]). The methods that check their own patches (`wavefront`, `hpde`,
/// `lssvm_poisson`) still run their variants inside it; a guide
/// ([`FillContext::guide`]) keeps its first variant as made.
pub fn run_method_fill(method: Method, ctx: &FillContext) -> Result<Patch, FillError> {
    match method {
        Method::Fan => fan::fill(ctx),
        Method::MinAreaFair => min_area_fair::fill(ctx),
        Method::AdvancingFront => advancing_front::fill(ctx),
        Method::LssvmPoisson => lssvm_poisson::fill(ctx),
        Method::Wavefront => wavefront::fill(ctx),
        Method::Hpde => hpde::fill(ctx),
        Method::Close => close::fill_checked(ctx).map(|(p, _)| p),
    }
}

/// Runs `run` (one method on one hole): a method that panics (a bug, or a solver that
/// panics on singular input) fails over like any other failure, so one bad hole never
/// takes the file down.
pub(crate) fn guarded<T>(
    method: Method,
    run: impl FnOnce() -> Result<T, FillError>,
) -> Result<T, FillError> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(run)).unwrap_or_else(|_| {
        Err(FillError::internal(format!(
            "internal error in {}",
            method.name()
        )))
    })
}

/// The method list of a class.
pub fn methods_for(policy: &Policy, class: HoleClass) -> &[Method] {
    match class {
        HoleClass::Small => &policy.dispatch.small,
        HoleClass::Middle => &policy.dispatch.middle,
        HoleClass::Large => &policy.dispatch.large,
    }
}

/// What the first phase of [`fill_hole`] found for one hole: the order of its methods,
/// every attempt so far and, if one passed the checks against the mesh as it was, that
/// patch.
#[derive(Clone, Debug)]
pub struct Proposal {
    /// The class's methods in the order they are tried: the list's order, or the
    /// self-validation's winner first ([`select`]).
    pub order: Vec<Method>,
    /// The self-validation that chose `order`, when the policy asks for one.
    pub selection: Option<Selection>,
    /// Attempts that failed or were rejected, in order.
    pub tried: Vec<Attempt>,
    /// The accepted attempt.
    pub accepted: Option<Accepted>,
    /// Time spent, in milliseconds.
    pub ms: f64,
}

/// A patch that passed every check against the mesh it was made on.
#[derive(Clone, Debug)]
pub struct Accepted {
    /// Index of its method in the proposal's `order`.
    pub at: usize,
    pub patch: Patch,
    pub quality: PatchQuality,
    /// The variant of a self-checked method that made it, when not the method's first
    /// ([`crate::fill::kit::retry::Passed`]).
    pub variant: Option<&'static str>,
    /// Time spent on it, in milliseconds.
    pub ms: f64,
    /// What `[blend]` did to it (`None` when the blend does not apply).
    pub blend: Option<BlendReport>,
}

/// One method on one hole: run it, relax the patch tangentially, check it. `Ok` holds
/// the checked patch (its `at` is 0: the caller sets it); `Err` the attempt that
/// failed, and whether the method stopped its variants at a repeated loop edge (see
/// [`FillContext::rim_bound`], which `rim_bound` sets for this method).
fn attempt(
    method: Method,
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &Checker,
    rim_bound: bool,
) -> Result<Accepted, (Attempt, bool)> {
    let ta = Instant::now();
    // `[blend]` toward the patch's faired surface as the self-checked method's last
    // step (it relaxes and checks the patch itself)
    let finisher = blend::Finisher::new(mesh, hole, policy, checker, method);
    let finish = |p: &Patch| finisher.finish(p);
    let ctx = FillContext {
        mesh,
        hole,
        policy,
        deadline: Deadline::after_ms(policy.limits.hole_time_ms),
        checker: Some(checker),
        rim_bound,
        guide: false,
        finish: Some(&finish),
    };
    let failed = |outcome, reason: String| Attempt {
        method,
        outcome,
        reason,
        variant: None,
        ms: ms_since(ta),
    };
    let accepted = |patch, quality, variant| Accepted {
        at: 0,
        patch,
        quality,
        variant,
        ms: ms_since(ta),
        blend: None,
    };
    let result = guarded(method, || run_method_checked(method, &ctx)).and_then(|p| {
        ctx.deadline.check()?;
        Ok(p)
    });
    let patch = match result {
        // relaxed and checked by the method itself, with this checker
        Ok((p, Some(q))) => {
            let blend = finisher.report(&p);
            return Ok(Accepted {
                blend,
                ..accepted(p, q.quality, q.variant)
            });
        }
        Ok((p, None)) => p,
        Err(FillError::Timeout) => {
            return Err((
                failed(
                    Outcome::Timeout,
                    format!("time limit of {} ms reached", policy.limits.hole_time_ms),
                ),
                false,
            ))
        }
        Err(why) => {
            return Err((
                failed(Outcome::Error, why.to_string()),
                why.stopped_at_rim(),
            ))
        }
    };
    // even out the triangles tangentially; keep that only if it passes the checks
    match relax::settled(
        mesh,
        hole,
        patch,
        policy.fair.tangential_relax,
        relax::RELAX_STEP,
        |p| checker.check_patch(mesh, &hole.vertices, p, &policy.checks),
    ) {
        Ok((p, q)) => Ok(accepted(p, q, None)),
        Err(why) => Err((failed(Outcome::Rejected, why.to_string()), false)),
    }
}

/// First phase of filling a hole, read-only so that holes can run in parallel: orders
/// the class's methods ([`select::order`]), tries them in that order and stops at the
/// first patch that passes every check against `mesh`, which [`blend`] may pull toward
/// a second surface.
pub fn propose(mesh: &Mesh, hole: &Hole, policy: &Policy, checker: &Checker) -> Proposal {
    let t0 = Instant::now();
    let (order, selection) = select::order(mesh, hole, policy, methods_for(policy, hole.class));
    // the blend's second fill beside the first method, when the blend would use it
    let (mut p, guide) = if blend::prefetches(policy, hole, order.first().copied()) {
        let (p, g) = rayon::join(
            || propose_from(mesh, hole, policy, checker, order, 0),
            || blend::guide(mesh, hole, policy),
        );
        (p, Some(g))
    } else {
        (propose_from(mesh, hole, policy, checker, order, 0), None)
    };
    p.selection = selection;
    // a patch the method finished with the blend is as the blend left it
    if let Some(a) = p.accepted.take_if(|a| a.blend.is_none()) {
        let (patch, quality, rep) = blend::blended(
            mesh,
            hole,
            policy,
            checker,
            p.order[a.at],
            &p.tried,
            a.patch,
            a.quality,
            guide,
        );
        let ms = a.ms + rep.as_ref().map_or(0.0, |r| r.ms);
        p.accepted = Some(Accepted {
            patch,
            quality,
            ms,
            blend: rep,
            ..a
        });
    }
    p.ms = ms_since(t0);
    p
}

/// [`propose`] with a given order, from its `from`-th method.
fn propose_from(
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &Checker,
    order: Vec<Method>,
    from: usize,
) -> Proposal {
    let t0 = Instant::now();
    let mut tried = Vec::new();
    let mut rim_bound = false;
    if hole.len() >= 3 {
        for (i, &method) in order.iter().enumerate().skip(from) {
            match attempt(method, mesh, hole, policy, checker, rim_bound) {
                Ok(a) => {
                    return Proposal {
                        order,
                        selection: None,
                        tried,
                        accepted: Some(Accepted { at: i, ..a }),
                        ms: ms_since(t0),
                    }
                }
                Err((a, at_rim)) => {
                    rim_bound |= at_rim;
                    tried.push(a);
                }
            }
        }
    }
    Proposal {
        order,
        selection: None,
        tried,
        accepted: None,
        ms: ms_since(t0),
    }
}

/// Second phase, serial in hole order: checks the proposed patch against the patches
/// of the holes filled before it and applies it; if it meets one, goes on down the
/// method list with full checks. Returns the hole's log entry. The result depends only
/// on the mesh the proposals were made on and on the hole order, never on threads.
pub fn finish_hole(
    mesh: &mut Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &mut Checker,
    proposal: Proposal,
) -> HoleReport {
    let t0 = Instant::now();
    let mut rep = HoleReport {
        tried: proposal.tried,
        selection: proposal.selection,
        ..hole.report(HoleStatus::Failed, String::new())
    };
    let done = |rep: &mut HoleReport| rep.ms = proposal.ms + ms_since(t0);
    if hole.len() < 3 {
        rep.reason = format!(
            "a loop of {} boundary vertices cannot be filled",
            hole.len()
        );
        done(&mut rep);
        return rep;
    }
    let methods = proposal.order;
    let mut next = Some(proposal.accepted);
    let mut from = methods.len();
    // the proposal first, then each later method with full checks
    loop {
        let candidate = match next.take() {
            Some(Some(a)) => {
                from = a.at + 1;
                match checker.check_against_added(mesh, &hole.vertices, &a.patch, &policy.checks) {
                    Ok(()) => Some(a),
                    Err(why) => {
                        rep.tried.push(Attempt {
                            method: methods[a.at],
                            outcome: Outcome::Rejected,
                            reason: why.to_string(),
                            variant: a.variant.map(str::to_string),
                            ms: a.ms,
                        });
                        None
                    }
                }
            }
            Some(None) => break,
            None => {
                if from >= methods.len() {
                    break;
                }
                let p = propose_from(mesh, hole, policy, checker, methods.clone(), from);
                rep.tried.extend(p.tried);
                from = methods.len();
                p.accepted
            }
        };
        let Some(Accepted {
            at,
            patch,
            quality,
            variant,
            ms,
            blend,
        }) = candidate
        else {
            continue;
        };
        let method = methods[at];
        let variant = variant.map(str::to_string);
        match apply_patch(mesh, hole, &patch) {
            Ok(faces) => {
                checker.commit(mesh, faces);
                rep.tried.push(Attempt {
                    method,
                    outcome: Outcome::Accepted,
                    reason: String::new(),
                    variant,
                    ms,
                });
                rep.method = Some(method);
                rep.status = HoleStatus::Filled;
                rep.added_vertices = patch.new_vertices.len();
                rep.added_faces = patch.triangles.len();
                rep.quality = Some(quality);
                rep.blend = blend;
                done(&mut rep);
                return rep;
            }
            Err(why) => rep.tried.push(Attempt {
                method,
                outcome: Outcome::Rejected,
                reason: why.to_string(),
                variant,
                ms,
            }),
        }
    }
    rep.reason = if rep.tried.is_empty() {
        "no method configured".into()
    } else {
        let list: Vec<String> = rep
            .tried
            .iter()
            .map(|a| format!("{}: {}", a.method.name(), a.reason))
            .collect();
        format!("every method failed ({})", list.join("; "))
    };
    done(&mut rep);
    rep
}

/// Fills one hole with the class's method list, checking every patch and applying
/// the first accepted one. Returns the hole's log entry.
pub fn fill_hole(
    mesh: &mut Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &mut Checker,
) -> HoleReport {
    let proposal = propose(mesh, hole, policy, checker);
    finish_hole(mesh, hole, policy, checker, proposal)
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1000.0
}

#[cfg(test)]
mod tests;
