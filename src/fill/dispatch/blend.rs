//! The accepted patch blended with a second surface (`[blend]`; not from the four
//! papers, issue 19).
//!
//! With `blend.surface = "faired"` the second surface is the accepted patch itself,
//! faired on its own triangles (`Δ^c x = 0` with the `[fair]` keys, as `min_area_fair`
//! fairs its patch; the loop and the outer rings fixed): each new vertex moves the
//! weight of the way to its faired position, and the moved patch is relaxed
//! tangentially and checked. The wavefront's rows carry the rim's slope on too far
//! where the surface bends; a thin plate over the same rows is the smooth surface the
//! rim implies, and is faired from a patch that already bends as the surface does
//! (the cotangent weights of a flat triangulation pull it flatter). On a flat rim (a
//! machined part) the rows continue the planes and the thin plate bulges between them:
//! `blend.weight_flat` is the weight there. A pull that fails the checks is tried all
//! the way (weight 1): rows folded over each other are untangled by the thin plate on
//! their own triangles. The pull is a self-checked method's last step ([`Finisher`],
//! [`FillContext::finish`]): each patch a variant makes is pulled, relaxed and checked
//! once. With `blend.energy = "validate"` a large hole's faired surface is faired by
//! the one of three fairings that, on the hole's first patch with rings of the known
//! surface around it freed, moves those known vertices least ([`choose_energy`]):
//! which fairing continues a surface best differs by mesh (the thin plate on the bench's
//! armadillo, the umbrella energy on its decimated mesh, minimum variation on its hand),
//! and nothing read off the rim alone told them apart. Where the pull toward the
//! chosen surface fails even all the way, the pull toward the `[fair]` surface is
//! tried (joint seed 2's folded rows: minimum variation leaves them folded, the thin
//! plate untangles them; without this the method's later variants ran unfinished,
//! 0.4 s). Measured in docs/measurements.md.
//!
//! With `blend.surface = "with"`:
//! Where the lost surface bends, the thin plate (`min_area_fair`) tends to flatten it
//! and the wavefront's rows to carry the rim's slope on too far, so their errors are
//! often of opposite sign and their mean is closer than either. The hole is filled
//! again by `blend.with` (its first variant, relaxed where that passes the checks, as
//! made where it fails them: a guide, [`FillContext::guide`]), and
//! each new vertex of the accepted patch moves its class's weight
//! (`blend.weight_middle`, `blend.weight_large`) of the way to the closest point of
//! that patch: the blended surface. With `blend.keep = "with"` the second patch's own
//! triangles are put onto that surface (projected, relaxed and projected again: the
//! wavefront's rows are better shaped than a refined thin plate's triangles); where
//! they fail the checks, or with `keep = "accepted"`, the accepted patch's moved
//! vertices are relaxed tangentially. Either must pass the same checks as any patch,
//! or the accepted one is kept. The second fill has its own `limits.hole_time_ms`, as
//! every attempt has, and is not made where `blend.with` was tried on the hole before
//! the accepted method and failed. The loop and the input are untouched.
//! Measured in docs/measurements.md.

use super::{guarded, run_method_fill, select};
use crate::check::Checker;
use crate::fill::kit::fair;
use crate::fill::kit::{relax, Deadline, FillContext};
use crate::geometry::bvh::{closest_on_triangles, tri_box, Bvh};
use crate::mesh::Mesh;
use crate::patch::{Hole, Patch};
use crate::policy::{BlendEnergy, BlendKeep, BlendSurface, FairEnergy, Method, Policy};
use crate::report::{Attempt, BlendReport, EnergyChoice, HoleClass, PatchQuality};
use glam::DVec3;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, OnceLock, PoisonError};
use std::time::Instant;

/// The blend weight of a hole of `class` (`blend.weight_middle`, `blend.weight_large`;
/// small holes are never blended: 0).
pub fn weight(policy: &Policy, class: HoleClass) -> f64 {
    match class {
        HoleClass::Small => 0.0,
        HoleClass::Middle => policy.blend.weight_middle,
        HoleClass::Large => policy.blend.weight_large,
    }
}

/// The weight for `hole` and the rim's flat share: the class's [`weight`], or
/// `blend.weight_flat` where that is set and the rim reads flat by the `select` rim
/// rule ([`select::rim`]; the share is read only then).
pub fn hole_weight(mesh: &Mesh, hole: &Hole, policy: &Policy) -> (f64, Option<f64>) {
    let w = weight(policy, hole.class);
    let Some(flat) = policy.blend.weight_flat.filter(|_| w > 0.0) else {
        return (w, None);
    };
    let share = select::rim(mesh, hole, &policy.select)
        .rim
        .and_then(|r| r.flat_share);
    match share {
        Some(s) if s >= policy.select.flat_share => (flat, share),
        _ => (w, share),
    }
}

/// Whether `[blend]` applies to a patch of `method` on `hole`: blending is on for the
/// hole's class (middle or large), the patch has new vertices, and (with
/// `surface = "with"`) it is another method's than `blend.with`.
pub fn applies(policy: &Policy, hole: &Hole, method: Method, patch: &Patch) -> bool {
    weight(policy, hole.class) > 0.0
        && (policy.blend.surface == BlendSurface::Faired || method != policy.blend.with)
        && !patch.new_vertices.is_empty()
}

/// Why `blend.with` is not run again on a hole whose earlier attempts are `tried`:
/// it is among them, so it failed there already (made no patch, or one that failed
/// the checks, or ran out of time).
pub fn already_failed(policy: &Policy, tried: &[Attempt]) -> Option<String> {
    if policy.blend.surface != BlendSurface::With {
        return None;
    }
    tried
        .iter()
        .find(|a| a.method == policy.blend.with)
        .map(|a| {
            format!(
                "{} was tried before on this hole and failed ({:?}); not run again",
                a.method.name(),
                a.outcome
            )
        })
}

/// The report of a blend that was not tried, for `reason`.
pub fn not_tried(policy: &Policy, hole: &Hole, reason: String) -> BlendReport {
    BlendReport {
        surface: policy.blend.surface,
        with: (policy.blend.surface == BlendSurface::With).then_some(policy.blend.with),
        weight: weight(policy, hole.class),
        flat_share: None,
        applied: false,
        kept: None,
        reason,
        moved_vertices: 0,
        mean_shift: 0.0,
        energy: None,
        ms: 0.0,
    }
}

/// The accepted `patch` of `method` (quality `q`), after the hole's failed `tried`
/// attempts, as `[blend]` leaves it: pulled when that applies and passes, else as it
/// was; with the blend's report when it applies.
#[allow(clippy::too_many_arguments)]
pub fn blended(
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &Checker,
    method: Method,
    tried: &[Attempt],
    patch: Patch,
    q: PatchQuality,
    guide: Option<Guide>,
) -> (Patch, PatchQuality, Option<BlendReport>) {
    if !applies(policy, hole, method, &patch) {
        return (patch, q, None);
    }
    if let Some(why) = already_failed(policy, tried) {
        return (patch, q, Some(not_tried(policy, hole, why)));
    }
    let (pulled, rep) = match policy.blend.surface {
        BlendSurface::With => pull(mesh, hole, policy, checker, &patch, guide),
        BlendSurface::Faired => pull_faired(mesh, hole, policy, checker, &patch, None),
    };
    match pulled {
        Some((pulled, q)) => (pulled, q, Some(rep)),
        None => (patch, q, Some(rep)),
    }
}

/// `blend.with`'s own patch of a hole (or why it made none), and the milliseconds it
/// took.
pub type Guide = (Result<Patch, String>, f64);

/// Whether [`guide`] is worth making beside `first`, the first method tried on `hole`
/// (both on the two cores): the blend applies to `first`'s patch when it is accepted.
pub fn prefetches(policy: &Policy, hole: &Hole, first: Option<Method>) -> bool {
    policy.blend.surface == BlendSurface::With
        && weight(policy, hole.class) > 0.0
        && first.is_some_and(|m| m != policy.blend.with)
}

/// `blend.with`'s own fill of `hole` as a guide ([`FillContext::guide`]: its first
/// variant, as made where it fails the checks), with its own `limits.hole_time_ms`. A pure function of the mesh, the hole and the policy, so it
/// can be made beside the first method ([`prefetches`]) with the same result.
pub fn guide(mesh: &Mesh, hole: &Hole, policy: &Policy) -> Guide {
    let t0 = Instant::now();
    let with = policy.blend.with;
    let ctx = FillContext {
        deadline: Deadline::after_ms(policy.limits.hole_time_ms),
        guide: true,
        ..FillContext::new(mesh, hole, policy)
    };
    let made = guarded(with, || run_method_fill(with, &ctx))
        .map_err(|why| format!("{} failed: {why}", with.name()));
    (made, t0.elapsed().as_secs_f64() * 1000.0)
}

/// `patch` (accepted, by another method) blended with `blend.with`'s patch of the same
/// hole (`guide`, made here when `None`), with its quality when it passes the checks;
/// and what was done (its time includes the guide's). The blended
/// surface is the accepted patch with its new vertices moved the class's weight of
/// the way to the second patch; with `blend.keep = "with"` the second patch's
/// triangles are put onto it ([`onto_surface`]) and tried first, then (or with
/// `keep = "accepted"` only) the moved accepted patch. Each is relaxed tangentially
/// and checked.
pub fn pull(
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &Checker,
    patch: &Patch,
    guide: Option<Guide>,
) -> (Option<(Patch, PatchQuality)>, BlendReport) {
    let t0 = Instant::now();
    let with = policy.blend.with;
    let (w, flat_share) = hole_weight(mesh, hole, policy);
    let mut rep = BlendReport {
        weight: w,
        flat_share,
        ..not_tried(policy, hole, String::new())
    };
    let (made, guide_ms) = guide.unwrap_or_else(|| self::guide(mesh, hole, policy));
    let elapsed = || guide_ms + t0.elapsed().as_secs_f64() * 1000.0;
    // the blended surface: the accepted patch moved the weight of the way to the
    // guide's (with keep = "with", the guide's vertices are put onto it below)
    let made = made.and_then(|guide| {
        let pulled = moved(mesh, hole, w, patch, &guide)
            .ok_or_else(|| format!("{} made no triangle to pull toward", with.name()))?;
        Ok((guide, pulled))
    });
    let (guide, (pulled, shift)) = match made {
        Ok(m) => m,
        Err(why) => {
            rep.reason = why;
            rep.ms = elapsed();
            return (None, rep);
        }
    };
    let check = |p: &Patch| checker.check_patch(mesh, &hole.vertices, p, &policy.checks);
    // the moves are uneven, so the triangles are evened out again as after any
    // method; the unrelaxed patch is the fallback
    let settled = |p: Patch| {
        relax::settled(
            mesh,
            hole,
            p,
            policy.fair.tangential_relax,
            relax::RELAX_STEP,
            check,
        )
    };
    let t_moved = t0.elapsed();
    let mut order = Vec::new();
    if policy.blend.keep == BlendKeep::With && !guide.new_vertices.is_empty() {
        if let Some(onto) = onto_surface(mesh, hole, &guide, &pulled, policy.fair.tangential_relax)
        {
            order.push((BlendKeep::With, onto));
        }
    }
    order.push((BlendKeep::Accepted, (pulled, shift)));
    let t_onto = t0.elapsed();
    let mut out = None;
    let mut failures = Vec::new();
    for (keep, (p, shift)) in order {
        match settled(p) {
            Ok((p, q)) => {
                rep.applied = true;
                rep.kept = Some(keep);
                rep.moved_vertices = p.new_vertices.len();
                rep.mean_shift = shift / hole.mean_edge_length.max(f64::MIN_POSITIVE);
                out = Some((p, q));
                break;
            }
            Err(why) => failures.push(match keep {
                BlendKeep::With => format!(
                    "the blended surface on {}'s triangles failed the checks: {why}",
                    with.name()
                ),
                BlendKeep::Accepted => {
                    format!(
                        "the accepted patch pulled toward {}'s failed the checks: {why}",
                        with.name()
                    )
                }
            }),
        }
    }
    // not applied: why; applied with the accepted triangles after "with"'s failed: why
    rep.reason = failures.join("; ");
    rep.ms = elapsed();
    tracing::debug!(
        hole = hole.id,
        guide_ms,
        moved_ms = t_moved.as_secs_f64() * 1e3,
        onto_ms = (t_onto - t_moved).as_secs_f64() * 1e3,
        settled_ms = (t0.elapsed() - t_onto).as_secs_f64() * 1e3,
        kept = ?rep.kept,
        "blend done"
    );
    (out, rep)
}

/// The candidates of `blend.energy = "validate"`, in the order a tie goes.
pub const ENERGIES: [FairEnergy; 3] = [
    FairEnergy::Fair,
    FairEnergy::Umbrella,
    FairEnergy::MinimumVariation,
];

/// Whether the faired surface's fairing is chosen for `hole` (`blend.energy =
/// "validate"`, a large hole: measured there, docs/measurements.md).
pub fn validates_energy(policy: &Policy, hole: &Hole) -> bool {
    policy.blend.energy == BlendEnergy::Validate && hole.class == HoleClass::Large
}

/// At most this many rings are freed for the choice by the growth with the loop's
/// length (`select.vertices_per_ring`); `select.rings` itself is always honoured.
/// Seeds 1-5: mean APE 5.092 and 4.933 on large holes against 5.117 and 4.955 with
/// up to 8 rings, at 0.85 of the fill time; held-out seeds 6-8: 5.133 / 4.761 against
/// 5.149 / 4.772 (docs/measurements.md).
pub const CHOICE_RINGS_GROWN_MAX: usize = 4;

/// The rings of known surface freed for the choice on a hole of `k` boundary vertices:
/// `select.rings`, or one per `select.vertices_per_ring` boundary vertices up to
/// [`CHOICE_RINGS_GROWN_MAX`] when that is more.
pub fn choice_rings(select: &crate::policy::Select, k: usize) -> usize {
    select
        .rings
        .max(select::rings_for(select, k).min(CHOICE_RINGS_GROWN_MAX))
}

/// The fairing for `hole`'s faired surface, chosen on `patch`: each of [`ENERGIES`]
/// fairs the patch together with rings of the known surface around it
/// ([`fair::freed_rings_error`], [`choice_rings`]), and the one that moves the known
/// vertices least wins. A hole is won or lost on how the surface is continued from its
/// rim inwards; the freed rings ask each energy to continue the surface from further
/// out over ground that is known.
pub fn choose_energy(mesh: &Mesh, hole: &Hole, policy: &Policy, patch: &Patch) -> EnergyChoice {
    let t0 = Instant::now();
    let rings = choice_rings(&policy.select, hole.len());
    let unit = hole.mean_edge_length.max(f64::MIN_POSITIVE);
    let score = |e: FairEnergy| {
        let s = fair::freed_rings_error(mesh, hole, patch, &policy.fair, e, rings)
            .ok()
            .map(|d| d / unit)
            .filter(|d| d.is_finite());
        (e, s)
    };
    // three independent solves, side by side (the large holes are the last to finish)
    let (a, (b, c)) = rayon::join(
        || score(ENERGIES[0]),
        || rayon::join(|| score(ENERGIES[1]), || score(ENERGIES[2])),
    );
    let scores = vec![a, b, c];
    // the lowest score, on a tie the earlier energy, as select's validation picks
    let chosen = select::lowest_score(scores.iter().copied()).unwrap_or(FairEnergy::Fair);
    EnergyChoice {
        chosen,
        used: chosen,
        rings,
        scores,
        ms: t0.elapsed().as_secs_f64() * 1000.0,
    }
}

/// `patch` (accepted) with each new vertex moved the hole's weight ([`hole_weight`])
/// of the way to its position in the same patch faired (`[fair]`, or the fairing
/// `blend.energy = "validate"` chooses: `energy` when the caller chose it already,
/// else chosen here), relaxed tangentially and checked ([`BlendSurface::Faired`]),
/// with its quality when it passes; and what was done.
pub fn pull_faired(
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &Checker,
    patch: &Patch,
    energy: Option<EnergyChoice>,
) -> (Option<(Patch, PatchQuality)>, BlendReport) {
    let t0 = Instant::now();
    let (w, flat_share) = hole_weight(mesh, hole, policy);
    let mut rep = BlendReport {
        weight: w,
        flat_share,
        ..not_tried(policy, hole, String::new())
    };
    if w == 0.0 {
        rep.reason = "the rim reads flat and blend.weight_flat is 0".to_string();
        return (None, rep);
    }
    if policy.fair.continuity == 0 {
        rep.reason = "fair.continuity is 0: the patch has no faired surface".to_string();
        return (None, rep);
    }
    rep.energy = match energy {
        Some(e) => Some(e),
        None if validates_energy(policy, hole) => Some(choose_energy(mesh, hole, policy, patch)),
        None => None,
    };
    let chosen = rep.energy.as_ref().map_or(FairEnergy::Fair, |e| e.chosen);
    let mut t_fair = std::time::Duration::ZERO;
    // the pull toward `energy`'s faired surface: the hole's weight of the way, else
    // all the way; with the weight used and why it is not the hole's
    let pull_toward = |energy: FairEnergy, t_fair: &mut std::time::Duration| {
        let tf = Instant::now();
        let mut faired = patch.clone();
        let made = fair::fair_patch_energy(mesh, hole, &mut faired, &policy.fair, energy);
        *t_fair += tf.elapsed();
        let settle = |weight: f64| {
            let (moved, shift) = toward(patch, &faired, weight);
            relax::settled(
                mesh,
                hole,
                moved,
                policy.fair.tangential_relax,
                relax::RELAX_STEP,
                |p| checker.check_patch(mesh, &hole.vertices, p, &policy.checks),
            )
            .map(|pq| (pq, shift))
        };
        match made {
            Err(e) => Err(format!("the fairing failed: {e}")),
            Ok(()) => match settle(w) {
                Ok(done) => Ok((done, w, String::new())),
                // rows folded over each other (joint seed 2's 202-vertex hole, every
                // wavefront variant) are untangled by the thin plate on their own
                // triangles, not by a share of the way to it
                Err(why) if w < 1.0 => match settle(1.0) {
                    Ok(done) => Ok((
                        done,
                        1.0,
                        format!(
                            "pulled {w} of the way the patch failed the checks ({why}); \
                             pulled all the way onto its faired surface"
                        ),
                    )),
                    Err(again) => Err(format!(
                        "the patch pulled toward its faired surface failed the checks: \
                         {why}; pulled all the way: {again}"
                    )),
                },
                Err(why) => Err(format!(
                    "the patch pulled toward its faired surface failed the checks: {why}"
                )),
            },
        }
    };
    let mut out = pull_toward(chosen, &mut t_fair);
    // a chosen fairing other than the thin plate whose pull fails (joint seed 2's
    // 202-vertex hole: minimum variation leaves the folded rows folded) falls back to
    // the `[fair]` surface, which untangles them
    if chosen != FairEnergy::Fair {
        if let Err(first) = &out {
            let first = format!("toward the {} surface: {first}", chosen.name());
            out = match pull_toward(FairEnergy::Fair, &mut t_fair) {
                Ok((done, w, note)) => {
                    let note = if note.is_empty() {
                        String::new()
                    } else {
                        format!("; {note}")
                    };
                    Ok((
                        done,
                        w,
                        format!("{first}; pulled toward the [fair] surface instead{note}"),
                    ))
                }
                Err(second) => Err(format!("{first}; toward the [fair] surface: {second}")),
            };
            if let (Ok(_), Some(e)) = (&out, rep.energy.as_mut()) {
                e.used = FairEnergy::Fair;
            }
        }
    }
    let out = out.map(|(done, used_w, note)| {
        rep.weight = used_w;
        rep.reason = note;
        done
    });
    let out = match out {
        Ok(((p, q), shift)) => {
            rep.applied = true;
            rep.kept = Some(BlendKeep::Accepted);
            rep.moved_vertices = p.new_vertices.len();
            rep.mean_shift = shift / hole.mean_edge_length.max(f64::MIN_POSITIVE);
            Some((p, q))
        }
        Err(why) => {
            rep.reason = why;
            None
        }
    };
    rep.ms = t0.elapsed().as_secs_f64() * 1000.0;
    tracing::debug!(
        hole = hole.id,
        weight = w,
        fair_ms = t_fair.as_secs_f64() * 1e3,
        settled_ms = (t0.elapsed() - t_fair).as_secs_f64() * 1e3,
        applied = rep.applied,
        "blend toward the faired patch done"
    );
    (out, rep)
}

/// [`pull_faired`] as a self-checked method's last step ([`FillContext::finish`]) on
/// each patch one method makes for a hole, where the blend applies with
/// `surface = "faired"`. Where it fails (the pulled patch fails the checks), the method
/// relaxes and checks the patch as made, and the dispatcher blends what it accepts as
/// before ([`blended`]); after one failure the later variants are not finished either
/// (a pull that fails even all the way fails on the other variants' rows too: joint
/// seed 2 before the full pull, six variants, 30 ms each).
pub struct Finisher<'a> {
    mesh: &'a Mesh,
    hole: &'a Hole,
    policy: &'a Policy,
    checker: &'a Checker,
    method: Method,
    /// The pulled patches, with their reports.
    done: Mutex<Vec<(Patch, BlendReport)>>,
    failed: AtomicBool,
    /// The fairing chosen on the first patch (`blend.energy = "validate"`), kept for
    /// the later variants' patches: one choice per hole.
    energy: OnceLock<EnergyChoice>,
}

impl<'a> Finisher<'a> {
    /// The finishing step of `method`'s patches of `hole`.
    pub fn new(
        mesh: &'a Mesh,
        hole: &'a Hole,
        policy: &'a Policy,
        checker: &'a Checker,
        method: Method,
    ) -> Finisher<'a> {
        Finisher {
            mesh,
            hole,
            policy,
            checker,
            method,
            done: Mutex::new(Vec::new()),
            failed: AtomicBool::new(false),
            energy: OnceLock::new(),
        }
    }

    /// `patch` pulled toward its faired surface, relaxed, with the quality of the
    /// checks it passed; `None` where the blend does not apply, the pull fails, or an
    /// earlier one failed.
    pub fn finish(&self, patch: &Patch) -> Option<(Patch, PatchQuality)> {
        if self.policy.blend.surface != BlendSurface::Faired
            || !applies(self.policy, self.hole, self.method, patch)
            || self.failed.load(Ordering::Relaxed)
        {
            return None;
        }
        let energy = validates_energy(self.policy, self.hole).then(|| {
            self.energy
                .get_or_init(|| choose_energy(self.mesh, self.hole, self.policy, patch))
                .clone()
        });
        let (out, rep) = pull_faired(
            self.mesh,
            self.hole,
            self.policy,
            self.checker,
            patch,
            energy,
        );
        let Some((pulled, q)) = out else {
            self.failed.store(true, Ordering::Relaxed);
            return None;
        };
        self.done
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push((pulled.clone(), rep));
        Some((pulled, q))
    }

    /// The report of `accepted` when it is a patch [`Finisher::finish`] made (`None`:
    /// the method relaxed and checked it itself).
    pub fn report(self, accepted: &Patch) -> Option<BlendReport> {
        self.done
            .into_inner()
            .unwrap_or_else(PoisonError::into_inner)
            .into_iter()
            .find(|(p, _)| p == accepted)
            .map(|(_, rep)| rep)
    }
}

/// `patch` with each new vertex moved `weight` of the way to the same vertex of
/// `target` (the same patch, moved), and the mean distance moved.
fn toward(patch: &Patch, target: &Patch, weight: f64) -> (Patch, f64) {
    let mut out = patch.clone();
    let mut total = 0.0;
    for (p, q) in out.new_vertices.iter_mut().zip(&target.new_vertices) {
        let d = weight * (*q - *p);
        total += d.length();
        *p += d;
    }
    let n = out.new_vertices.len().max(1) as f64;
    (out, total / n)
}

/// Rounds of [`onto_surface`]: relax, put back onto the surface.
const ONTO_ROUNDS: usize = 3;

/// `guide`'s triangles on `surface`: its new vertices put onto the closest points of
/// `surface`, then, [`ONTO_ROUNDS`] times, relaxed tangentially (a share of
/// `iterations`) and put back (the first closest points bunch where the two surfaces
/// part; the relaxation spreads them and the last projection leaves them on the
/// surface). With the mean distance the vertices moved from the guide.
fn onto_surface(
    mesh: &Mesh,
    hole: &Hole,
    guide: &Patch,
    surface: &Patch,
    iterations: usize,
) -> Option<(Patch, f64)> {
    let onto = Surface::of(mesh, hole, surface)?;
    let (mut p, _) = onto.pull(hole, 1.0, guide);
    for _ in 0..ONTO_ROUNDS {
        relax::tangential_relax(
            mesh,
            hole,
            &mut p,
            iterations.div_ceil(ONTO_ROUNDS),
            relax::RELAX_STEP,
        );
        p = onto.pull(hole, 1.0, &p).0;
    }
    let n = p.new_vertices.len().max(1) as f64;
    let shift = p
        .new_vertices
        .iter()
        .zip(&guide.new_vertices)
        .map(|(a, b)| (*a - *b).length())
        .sum::<f64>()
        / n;
    Some((p, shift))
}

/// `patch` with each new vertex moved `weight` of the way to the closest point of
/// `guide`'s triangles, and the mean distance moved; `None` when `guide` has none.
pub fn moved(
    mesh: &Mesh,
    hole: &Hole,
    weight: f64,
    patch: &Patch,
    guide: &Patch,
) -> Option<(Patch, f64)> {
    Some(Surface::of(mesh, hole, guide)?.pull(hole, weight, patch))
}

/// A patch's triangles, indexed for closest points.
struct Surface {
    tris: Vec<[DVec3; 3]>,
    bvh: Bvh,
}

impl Surface {
    /// `None` when the patch has no triangle (or none whose corners it has).
    fn of(mesh: &Mesh, hole: &Hole, patch: &Patch) -> Option<Surface> {
        let tris = patch.triangle_positions(mesh, hole);
        if tris.is_empty() {
            return None;
        }
        let bvh = Bvh::build(tris.len(), |i| tri_box(&tris[i]));
        Some(Surface { tris, bvh })
    }

    /// `patch` with each new vertex moved `weight` of the way to its closest point
    /// here, and the mean distance moved.
    fn pull(&self, hole: &Hole, weight: f64, patch: &Patch) -> (Patch, f64) {
        let r = hole.mean_edge_length;
        let mut out = patch.clone();
        let mut total = 0.0;
        for p in &mut out.new_vertices {
            if let Some(q) = closest_on_triangles(&self.bvh, &self.tris, *p, r) {
                let d = weight * (q - *p);
                total += d.length();
                *p += d;
            }
        }
        let n = out.new_vertices.len().max(1) as f64;
        (out, total / n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{fan, sheet, sheet_hole_at, SHEET_HOLE};
    use glam::DVec3;

    /// The 8-vertex hole of a flat sheet, as a hole of `class`.
    fn sheet_hole(class: HoleClass) -> (Mesh, Hole) {
        let (mesh, _) = Mesh::from_raw(&sheet(6, 0.0, &SHEET_HOLE));
        let lp = sheet_hole_at(&mesh, 0.0);
        let mut hole = Hole::new(0, &mesh, lp, &Policy::default());
        hole.class = class;
        (mesh, hole)
    }

    /// A fan over the hole, apex at height `h` above its middle.
    fn tent(h: f64) -> Patch {
        fan(8, DVec3::new(3.0, 3.0, h))
    }

    #[test]
    fn the_apex_moves_the_weighted_way_to_the_other_surface() {
        let (mesh, hole) = sheet_hole(HoleClass::Middle);
        for (w, want) in [(0.0, 0.4), (0.5, 0.25), (1.0, 0.1)] {
            let (p, shift) = moved(&mesh, &hole, w, &tent(0.4), &tent(0.1)).expect("guide");
            let z = p.new_vertices[0].z;
            assert!((z - want).abs() < 1e-12, "weight {w}: apex at {z}");
            assert!((shift - w * 0.3).abs() < 1e-12, "weight {w}: shift {shift}");
            assert_eq!(p.triangles, tent(0.4).triangles, "connectivity kept");
        }
    }

    #[test]
    fn a_guide_without_triangles_moves_nothing() {
        let (mesh, hole) = sheet_hole(HoleClass::Middle);
        assert!(moved(&mesh, &hole, 0.5, &tent(0.4), &Patch::default()).is_none());
        // triangles naming vertices the guide does not have are left out
        let broken = Patch {
            new_vertices: Vec::new(),
            triangles: vec![[0, 1, 9]],
        };
        assert!(moved(&mesh, &hole, 0.5, &tent(0.4), &broken).is_none());
    }

    #[test]
    fn the_pulled_patch_is_checked_and_reported() {
        let (mut mesh, hole) = sheet_hole(HoleClass::Middle);
        let policy = Policy::default()
            .edit(|s| {
                s.blend.weight_middle = 0.5;
                s.blend.weight_large = 0.5;
                s.blend.keep = BlendKeep::Accepted;
            })
            .expect("valid");
        let checker = Checker::new(&mesh);
        // the wavefront fills a flat hole flat: the tent comes down halfway
        let (out, rep) = pull(&mesh, &hole, &policy, &checker, &tent(0.4), None);
        let (p, _) = out.expect("applied");
        assert!(rep.applied, "{rep:?}");
        assert_eq!(rep.kept, Some(BlendKeep::Accepted));
        assert_eq!(rep.with, Some(Method::Wavefront));
        assert_eq!(rep.surface, BlendSurface::With);
        assert_eq!(rep.moved_vertices, 1);
        assert!(
            (p.new_vertices[0].z - 0.2).abs() < 1e-9,
            "{:?}",
            p.new_vertices
        );
        crate::patch::apply_patch(&mut mesh, &hole, &p).expect("applies");
        mesh.validate().expect("valid mesh");
    }

    /// `Policy::default()` blending toward the faired patch with `weight_middle`, and
    /// `weight_flat` where the rim reads flat.
    fn faired_policy(weight_middle: f64, weight_flat: Option<f64>) -> Policy {
        Policy::default()
            .edit(|s| {
                s.blend.surface = BlendSurface::Faired;
                s.blend.weight_middle = weight_middle;
                s.blend.weight_flat = weight_flat;
            })
            .expect("valid")
    }

    #[test]
    fn the_faired_surface_pulls_the_tent_the_weighted_way_down() {
        // a thin plate over a flat rim is the plane: the apex's faired height is 0
        let (mut mesh, hole) = sheet_hole(HoleClass::Middle);
        let checker = Checker::new(&mesh);
        for (w, want) in [(0.5, 0.2), (0.9, 0.04)] {
            let policy = faired_policy(w, None);
            assert!(applies(&policy, &hole, Method::Wavefront, &tent(0.4)));
            assert!(!prefetches(&policy, &hole, Some(Method::MinAreaFair)));
            let (out, rep) = pull_faired(&mesh, &hole, &policy, &checker, &tent(0.4), None);
            let (p, _) = out.expect("applied");
            assert!(rep.applied, "{rep:?}");
            assert_eq!(rep.surface, BlendSurface::Faired);
            assert_eq!((rep.with, rep.weight, rep.flat_share), (None, w, None));
            assert_eq!(rep.kept, Some(BlendKeep::Accepted));
            assert_eq!(p.triangles, tent(0.4).triangles, "its own triangles");
            let z = p.new_vertices[0].z;
            assert!((z - want).abs() < 1e-9, "weight {w}: apex at {z}");
            let shift = (0.4 - want) / hole.mean_edge_length;
            assert!((rep.mean_shift - shift).abs() < 1e-9, "{rep:?}");
            let json = serde_json::to_value(&rep).expect("json");
            assert!(json.get("with").is_none() && json.get("flat_share").is_none());
            assert_eq!(json["surface"], "faired");
        }
        // through the dispatcher's entry: the same patch
        let policy = faired_policy(0.5, None);
        let q = checker
            .check_patch(&mesh, &hole.vertices, &tent(0.4), &policy.checks)
            .expect("the tent passes");
        let (p, _, rep) = blended(
            &mesh,
            &hole,
            &policy,
            &checker,
            Method::Wavefront,
            &[],
            tent(0.4),
            q,
            None,
        );
        assert!(rep.is_some_and(|r| r.applied));
        assert!((p.new_vertices[0].z - 0.2).abs() < 1e-9);
        crate::patch::apply_patch(&mut mesh, &hole, &p).expect("applies");
        mesh.validate().expect("valid mesh");
    }

    /// As a method's last step: the pulled patch and its report, found again by the
    /// patch; nothing where the blend pulls toward another method's patch; and after
    /// one failed pull, no more pulls for that method on the hole.
    #[test]
    fn the_finisher_pulls_each_made_patch_until_one_fails() {
        let (mesh, hole) = sheet_hole(HoleClass::Middle);
        let checker = Checker::new(&mesh);
        let policy = faired_policy(0.5, None);
        let fin = Finisher::new(&mesh, &hole, &policy, &checker, Method::Wavefront);
        let (p, _) = fin.finish(&tent(0.4)).expect("pulled");
        assert!((p.new_vertices[0].z - 0.2).abs() < 1e-9);
        let (q, _) = fin.finish(&tent(0.2)).expect("pulled");
        assert!((q.new_vertices[0].z - 0.1).abs() < 1e-9);
        let rep = fin.report(&p).expect("a patch it made");
        assert!(rep.applied && rep.weight == 0.5, "{rep:?}");
        let fin = Finisher::new(&mesh, &hole, &policy, &checker, Method::Wavefront);
        assert!(fin.finish(&tent(0.4)).is_some());
        assert_eq!(fin.report(&tent(0.4)), None, "the method's own patch");
        // toward another method's patch: the dispatcher blends afterwards
        let with = Policy::default()
            .edit(|s| s.blend.weight_middle = 0.5)
            .expect("valid");
        let fin = Finisher::new(&mesh, &hole, &with, &checker, Method::Wavefront);
        assert_eq!(fin.finish(&tent(0.4)), None);
        // a new vertex on no triangle cannot be faired: that pull fails, and the
        // method's later patches are not pulled
        let mut stray = tent(0.4);
        stray.new_vertices.push(DVec3::new(3.0, 3.0, 1.0));
        let fin = Finisher::new(&mesh, &hole, &policy, &checker, Method::Wavefront);
        assert!(pull_faired(&mesh, &hole, &policy, &checker, &stray, None)
            .0
            .is_none());
        assert_eq!(fin.finish(&stray), None);
        assert_eq!(fin.finish(&tent(0.4)), None, "not after a failure");
    }

    /// Where the patch pulled the weighted way still fails the checks (here an apex
    /// beyond the loop, whose triangles fold over the sheet), it is pulled all the way
    /// onto its faired surface, and the log says so; where that fails too, the
    /// accepted patch is kept with both reasons.
    #[test]
    fn a_pull_that_fails_the_checks_is_made_all_the_way() {
        let (mesh, hole) = sheet_hole(HoleClass::Middle);
        let checker = Checker::new(&mesh);
        // uniform weights: the faired apex is the middle whatever the folded fan's
        // angles (cotangents of a folded fan are not those of the surface)
        let policy = faired_policy(0.5, None)
            .edit(|s| {
                s.fair.tangential_relax = 0;
                s.fair.weights = crate::policy::Weights::Uniform;
            })
            .expect("valid");
        let check = |p: &Patch| checker.check_patch(&mesh, &hole.vertices, p, &policy.checks);
        let folded = fan(8, DVec3::new(6.0, 3.0, 0.0));
        // halfway to the faired apex (the middle of the flat hole) it still folds
        assert!(check(&folded).is_err());
        assert!(check(&fan(8, DVec3::new(4.5, 3.0, 0.0))).is_err());
        let (out, rep) = pull_faired(&mesh, &hole, &policy, &checker, &folded, None);
        let Some((p, _)) = out else {
            panic!("not applied: {rep:?}");
        };
        assert!(rep.applied, "{rep:?}");
        assert_eq!(rep.weight, 1.0);
        assert!(rep.reason.contains("all the way"), "{}", rep.reason);
        let apex = p.new_vertices[0];
        assert!(apex.distance(DVec3::new(3.0, 3.0, 0.0)) < 1e-9, "{apex}");
        assert!(check(&p).is_ok());
        // a patch that fails however far it is pulled: a triangle twice over
        let mut twice = tent(0.4);
        twice.triangles.push(twice.triangles[0]);
        let (out, rep) = pull_faired(&mesh, &hole, &policy, &checker, &twice, None);
        assert!(out.is_none() && !rep.applied);
        assert!(
            rep.reason.contains("pulled all the way: "),
            "{}",
            rep.reason
        );
        // a chosen fairing other than the thin plate whose pull fails falls back to the
        // [fair] surface; where that fails too, both reasons are kept
        let choice = |chosen| EnergyChoice {
            chosen,
            used: chosen,
            rings: 1,
            scores: Vec::new(),
            ms: 0.0,
        };
        let (out, rep) = pull_faired(
            &mesh,
            &hole,
            &policy,
            &checker,
            &twice,
            Some(choice(FairEnergy::MinimumVariation)),
        );
        assert!(out.is_none() && !rep.applied);
        assert!(
            rep.reason
                .starts_with("toward the minimum_variation surface: ")
                && rep.reason.contains("; toward the [fair] surface: "),
            "{}",
            rep.reason
        );
        assert_eq!(
            rep.energy.map(|e| e.used),
            Some(FairEnergy::MinimumVariation),
            "nothing was used"
        );
    }

    #[test]
    fn a_flat_rim_takes_the_flat_weight() {
        // the sheet is flat everywhere: share 1, over select.flat_share (0.5)
        let (mesh, hole) = sheet_hole(HoleClass::Middle);
        let checker = Checker::new(&mesh);
        let policy = faired_policy(0.9, Some(0.25));
        assert_eq!(hole_weight(&mesh, &hole, &policy), (0.25, Some(1.0)));
        let (out, rep) = pull_faired(&mesh, &hole, &policy, &checker, &tent(0.4), None);
        let (p, _) = out.expect("applied");
        assert_eq!((rep.weight, rep.flat_share), (0.25, Some(1.0)));
        assert!(
            (p.new_vertices[0].z - 0.3).abs() < 1e-9,
            "{:?}",
            p.new_vertices
        );
        // a sphere's rim is nowhere flat: the class's weight
        let (sphere, lp) = crate::testutil::sphere_with_hole(3, 0.4);
        let mut round = Hole::new(0, &sphere, lp, &policy);
        round.class = HoleClass::Middle;
        assert_eq!(hole_weight(&sphere, &round, &policy), (0.9, Some(0.0)));
        // a flat weight of 0 leaves the patch as it was, and says why
        let policy = faired_policy(0.9, Some(0.0));
        let (out, rep) = pull_faired(&mesh, &hole, &policy, &checker, &tent(0.4), None);
        assert!(out.is_none() && !rep.applied, "{rep:?}");
        assert!(rep.reason.contains("weight_flat is 0"), "{rep:?}");
        // without fairing there is no second surface: not applied, and why
        let unfaired = faired_policy(0.9, None)
            .edit(|s| s.fair.continuity = 0)
            .expect("valid");
        let (out, rep) = pull_faired(&mesh, &hole, &unfaired, &checker, &tent(0.4), None);
        assert!(out.is_none() && !rep.applied, "{rep:?}");
        assert!(rep.reason.contains("fair.continuity is 0"), "{rep:?}");
        // small holes are never blended, whatever the flat weight
        let (_, small) = sheet_hole(HoleClass::Small);
        assert_eq!(hole_weight(&mesh, &small, &policy), (0.0, None));
    }

    #[test]
    fn keeping_the_second_methods_triangles_lifts_them_halfway_to_the_accepted_surface() {
        let (mut mesh, hole) = sheet_hole(HoleClass::Middle);
        let policy = Policy::default()
            .edit(|s| {
                s.blend.weight_middle = 0.5;
                s.blend.keep = BlendKeep::With;
            })
            .expect("valid");
        let checker = Checker::new(&mesh);
        let ctx = FillContext::new(&mesh, &hole, &policy);
        let own = run_method_fill(Method::Wavefront, &ctx).expect("the wavefront fills");
        assert!(!own.new_vertices.is_empty(), "the wavefront adds vertices");
        let (out, rep) = pull(&mesh, &hole, &policy, &checker, &tent(0.4), None);
        let (p, _) = out.expect("applied");
        assert!(rep.applied, "{rep:?}");
        assert_eq!(rep.kept, Some(BlendKeep::With));
        assert_eq!(rep.moved_vertices, own.new_vertices.len());
        assert_eq!(p.triangles, own.triangles, "the wavefront's triangles");
        // the blended surface is the tent with its apex halfway down: each vertex at
        // half the tent's height where it stands (the last tangential relaxation
        // slides it a little over the creases of that surface)
        let height = |v: DVec3| 0.4 * (1.0 - (v.x - 3.0).abs().max((v.y - 3.0).abs()));
        for v in &p.new_vertices {
            let h = height(*v);
            assert!((v.z - 0.5 * h).abs() < 0.05 * h, "{v}: tent at {h}");
        }
        crate::patch::apply_patch(&mut mesh, &hole, &p).expect("applies");
        mesh.validate().expect("valid mesh");
    }

    #[test]
    fn a_guide_made_beforehand_gives_the_same_patch_and_counts_in_the_time() {
        let (mut mesh, hole) = sheet_hole(HoleClass::Middle);
        let policy = Policy::default()
            .edit(|s| s.blend.weight_middle = 0.5)
            .expect("valid");
        let checker = Checker::new(&mesh);
        let made = guide(&mesh, &hole, &policy);
        let own = made.0.clone().expect("the wavefront fills");
        assert!(!own.new_vertices.is_empty());
        let (here, _) = pull(&mesh, &hole, &policy, &checker, &tent(0.4), None);
        let (before, rep) = pull(&mesh, &hole, &policy, &checker, &tent(0.4), Some(made));
        let (here, before) = (here.expect("applied").0, before.expect("applied").0);
        assert_eq!(here.triangles, before.triangles);
        assert_eq!(here.new_vertices, before.new_vertices, "bit for bit");
        // a guide that took long is in the blend's time
        let slow = (Ok(own), 1.0e6);
        let (_, rep_slow) = pull(&mesh, &hole, &policy, &checker, &tent(0.4), Some(slow));
        assert!(
            rep_slow.ms >= 1.0e6 && rep.ms < 1.0e6,
            "{} {}",
            rep_slow.ms,
            rep.ms
        );
        // a guide that failed: not applied, its reason reported
        let failed = (Err("wavefront failed: no".to_string()), 0.0);
        let (none, rep) = pull(&mesh, &hole, &policy, &checker, &tent(0.4), Some(failed));
        assert!(
            none.is_none() && !rep.applied && rep.reason.contains("no"),
            "{rep:?}"
        );
        crate::patch::apply_patch(&mut mesh, &hole, &here).expect("applies");
        mesh.validate().expect("valid mesh");
    }

    #[test]
    fn the_guide_is_made_beforehand_only_where_the_first_method_would_be_blended() {
        let on = Policy::default()
            .edit(|s| s.blend.weight_large = 0.5)
            .expect("valid");
        let (_, large) = sheet_hole(HoleClass::Large);
        let (_, middle) = sheet_hole(HoleClass::Middle);
        assert!(prefetches(&on, &large, Some(Method::MinAreaFair)));
        assert!(
            !prefetches(&on, &large, Some(Method::Wavefront)),
            "the guide itself"
        );
        assert!(!prefetches(&on, &large, None));
        assert!(
            !prefetches(&on, &middle, Some(Method::MinAreaFair)),
            "weight 0"
        );
        assert!(!prefetches(
            &Policy::default(),
            &large,
            Some(Method::MinAreaFair)
        ));
    }

    #[test]
    fn a_guide_that_failed_on_the_hole_is_not_run_again() {
        use crate::report::Outcome;
        let policy = Policy::default()
            .edit(|s| s.blend.weight_large = 0.5)
            .expect("valid");
        let failed = |method| Attempt {
            method,
            outcome: Outcome::Rejected,
            reason: "a self-intersection".into(),
            variant: None,
            ms: 1.0,
        };
        assert_eq!(already_failed(&policy, &[]), None);
        assert_eq!(
            already_failed(&policy, &[failed(Method::AdvancingFront)]),
            None
        );
        let why = already_failed(&policy, &[failed(Method::Wavefront)]).expect("skipped");
        assert!(
            why.contains("wavefront") && why.contains("Rejected"),
            "{why}"
        );
        let (_, large) = sheet_hole(HoleClass::Large);
        let rep = not_tried(&policy, &large, why);
        assert!(!rep.applied && rep.weight == 0.5 && rep.moved_vertices == 0);
    }

    #[test]
    fn blending_applies_only_to_another_methods_patch_of_a_larger_hole() {
        let on = Policy::default()
            .edit(|s| {
                s.blend.weight_middle = 0.5;
                s.blend.weight_large = 0.5;
            })
            .expect("valid");
        let (_, small) = sheet_hole(HoleClass::Small);
        let (_, large) = sheet_hole(HoleClass::Large);
        let patch = tent(0.3);
        assert!(!applies(&on, &small, Method::MinAreaFair, &patch));
        assert!(applies(&on, &large, Method::MinAreaFair, &patch));
        assert!(
            !applies(&on, &large, Method::Wavefront, &patch),
            "the guide's own patch"
        );
        assert!(!applies(
            &on,
            &large,
            Method::MinAreaFair,
            &Patch::default()
        ));
        assert!(
            !applies(&Policy::default(), &large, Method::MinAreaFair, &patch),
            "off"
        );
        // each class by its own weight
        let large_only = Policy::default()
            .edit(|s| s.blend.weight_large = 0.4)
            .expect("valid");
        let (_, middle) = sheet_hole(HoleClass::Middle);
        assert!(!applies(&large_only, &middle, Method::MinAreaFair, &patch));
        assert!(applies(&large_only, &large, Method::MinAreaFair, &patch));
        assert_eq!(weight(&large_only, HoleClass::Large), 0.4);
        assert_eq!(weight(&large_only, HoleClass::Small), 0.0);
    }

    /// A 16 x 16 grid of unit cells with heights `z`, the 4 x 4 cells from (6, 6)
    /// removed: the mesh, that 16-vertex hole as a large one, and the removed cells as
    /// its patch (the 9 inner vertices new, `lift` above the surface: the start, from
    /// which the cotangent weights are read), with the true positions of the new
    /// vertices.
    fn grid_hole(z: impl Fn(f64, f64) -> f64, lift: f64) -> (Mesh, Hole, Patch, Vec<DVec3>) {
        let full = crate::testutil::grid(16, 0.0, 16.0, &z);
        let inside = |c: DVec3| (6.0..10.0).contains(&c.x) && (6.0..10.0).contains(&c.y);
        let raw = crate::testutil::cut_faces(full.clone(), inside);
        let (mesh, lp) = crate::testutil::mesh_and_loop(&raw, |_, l| l.len() == 16);
        let mut hole = Hole::new(0, &mesh, lp, &Policy::default());
        hole.class = HoleClass::Large;
        let loop_pos: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
        let mut patch = Patch::default();
        let mut truth = Vec::new();
        let mut new_of: std::collections::HashMap<u32, u32> = Default::default();
        for f in &full.faces {
            let c = f.iter().map(|&v| full.positions[v as usize]).sum::<DVec3>() / 3.0;
            if !inside(c) {
                continue;
            }
            let t = f.map(|v| {
                let p = full.positions[v as usize];
                if let Some(i) = loop_pos.iter().position(|&q| q == p) {
                    return i as u32;
                }
                *new_of.entry(v).or_insert_with(|| {
                    patch.new_vertices.push(p + DVec3::new(0.0, 0.0, lift));
                    truth.push(p);
                    (loop_pos.len() + patch.new_vertices.len() - 1) as u32
                })
            });
            patch.triangles.push(t);
        }
        (mesh, hole, patch, truth)
    }

    /// The choice's rings grow with the loop's length up to four; `select.rings` is kept.
    #[test]
    fn the_choice_frees_rings_grown_with_the_loop_up_to_four() {
        let select = Policy::default().select.clone();
        assert_eq!((select.rings, select.vertices_per_ring), (2, 25));
        assert_eq!(
            [10, 60, 75, 100, 140, 220].map(|k| choice_rings(&select, k)),
            [2, 2, 3, 4, 4, 4]
        );
        let mut six = select.clone();
        six.rings = 6;
        assert_eq!(choice_rings(&six, 220), 6);
        let mut none = select;
        none.vertices_per_ring = 0;
        assert_eq!(choice_rings(&none, 220), 2);
    }

    /// The names the repair log's reasons give the fairings are its serialised ones.
    #[test]
    fn the_fairings_are_named_as_the_log_names_them() {
        for e in ENERGIES {
            assert_eq!(serde_json::to_value(e).expect("serialises"), e.name());
        }
    }

    #[test]
    fn validation_chooses_minimum_variation_on_a_quartic_and_the_patch_lands_closer() {
        // Δ³ of a quartic is 0 and its Δ² is not: of the three fairings, only minimum
        // variation continues the known surface, and the freed rings show it
        let z = |x: f64, _: f64| 0.02 * (x - 8.0).powi(4) / 16.0;
        let (mesh, hole, patch, _) = grid_hole(z, 0.2);
        assert_eq!(patch.new_vertices.len(), 9);
        let checker = Checker::new(&mesh);
        let choice = |energy: BlendEnergy| {
            Policy::default()
                .edit(|s| {
                    s.blend.surface = BlendSurface::Faired;
                    s.blend.weight_large = 1.0;
                    s.blend.energy = energy;
                    s.fair.tangential_relax = 0;
                })
                .expect("valid")
        };
        let validate = choice(BlendEnergy::Validate);
        let e = choose_energy(&mesh, &hole, &validate, &patch);
        assert_eq!(e.chosen, FairEnergy::MinimumVariation, "{e:?}");
        assert_eq!(e.rings, 2);
        assert_eq!(e.scores.len(), 3);
        let score = |w: FairEnergy| e.scores.iter().find(|s| s.0 == w).and_then(|s| s.1);
        let (fair_s, min_var) = (
            score(FairEnergy::Fair).expect("scored"),
            score(FairEnergy::MinimumVariation).expect("scored"),
        );
        let umbrella = score(FairEnergy::Umbrella).expect("scored");
        assert!(min_var < 0.5 * fair_s.min(umbrella), "{e:?}");
        // the pull uses the chosen fairing and reports the choice; its new vertices are
        // closer to the surface (heights above their own x, y)
        let error = |p: &Patch| {
            p.new_vertices
                .iter()
                .map(|a| (a.z - z(a.x, a.y)).abs())
                .fold(0.0, f64::max)
        };
        let (out, rep) = pull_faired(&mesh, &hole, &validate, &checker, &patch, None);
        let (chosen, _) = out.expect("passes");
        assert_eq!(
            rep.energy.as_ref().map(|e| (e.chosen, e.used)),
            Some((FairEnergy::MinimumVariation, FairEnergy::MinimumVariation))
        );
        assert!(rep.reason.is_empty(), "{}", rep.reason);
        let (plain, rep_plain) = pull_faired(
            &mesh,
            &hole,
            &choice(BlendEnergy::Fair),
            &checker,
            &patch,
            None,
        );
        let (plain, _) = plain.expect("passes");
        assert!(rep_plain.energy.is_none(), "{rep_plain:?}");
        assert!(
            error(&chosen) < 0.5 * error(&plain),
            "chosen {} against the thin plate's {}",
            error(&chosen),
            error(&plain)
        );
        // a middle hole keeps the [fair] keys' fairing
        let mut middle = hole.clone();
        middle.class = HoleClass::Middle;
        assert!(!validates_energy(&validate, &middle));
    }

    #[test]
    fn on_a_plane_every_fairing_puts_the_freed_rings_back() {
        // a plane is harmonic: every candidate reproduces it, known rings and patch
        // (the start on the plane: cotangent weights read off a bent start reproduce
        // it only nearly)
        let (mesh, hole, patch, _) = grid_hole(|x, y| 0.3 * x - 0.1 * y + 1.0, 0.0);
        let policy = Policy::default()
            .edit(|s| {
                s.blend.surface = BlendSurface::Faired;
                s.blend.energy = BlendEnergy::Validate;
            })
            .expect("valid");
        let e = choose_energy(&mesh, &hole, &policy, &patch);
        assert_eq!(e.scores.len(), 3);
        for (w, s) in &e.scores {
            assert!(s.expect("scored") < 1e-9, "{w:?}: {e:?}");
        }
    }
}
