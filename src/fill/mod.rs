//! Hole filling: the size-based dispatch of paper 002 (Feng et al. 2020, §3) and
//! the fallback chain.
//!
//! Each method is a module with a `fill(&FillContext) -> Result<Patch, FillError>`.
//! A method only proposes a [`Patch`]; this module checks it ([`crate::check`]),
//! and only an accepted patch is applied to the mesh, so a rejected one needs no undo.
//! Every hole ends filled, skipped (with the rule) or failed (with every attempt and why).

pub mod advancing_front;
pub mod fair;
pub mod fan;
pub mod geom;
pub mod hpde;
pub mod lssvm_poisson;
pub mod min_area_fair;
pub mod relax;
pub mod wavefront;

use crate::check::Checker;
use crate::mesh::{Mesh, VertexId};
use crate::policy::{Method, Policy};
use crate::report::{Attempt, HoleClass, HoleReport, HoleStatus, Outcome, PatchQuality};
use glam::DVec3;
use std::time::{Duration, Instant};

/// A boundary loop to fill.
#[derive(Clone, Debug)]
pub struct Hole {
    /// Index of the hole in the log.
    pub id: usize,
    /// The loop, oriented so that a patch triangle `(v[i], v[i+1], x)` agrees with the
    /// surrounding faces.
    pub vertices: Vec<VertexId>,
    /// Sum of boundary edge lengths.
    pub perimeter: f64,
    /// Mean boundary edge length.
    pub mean_edge_length: f64,
    /// Size class.
    pub class: HoleClass,
}

impl Hole {
    /// Measures a loop.
    pub fn new(id: usize, mesh: &Mesh, vertices: Vec<VertexId>, policy: &Policy) -> Hole {
        let k = vertices.len();
        let perimeter: f64 = (0..k)
            .map(|i| (mesh.pos(vertices[(i + 1) % k]) - mesh.pos(vertices[i])).length())
            .sum();
        let class = if k <= policy.dispatch.small_max {
            HoleClass::Small
        } else if k <= policy.dispatch.middle_max {
            HoleClass::Middle
        } else {
            HoleClass::Large
        };
        Hole {
            id,
            mean_edge_length: if k > 0 { perimeter / k as f64 } else { 0.0 },
            vertices,
            perimeter,
            class,
        }
    }
    /// Boundary vertex count.
    pub fn len(&self) -> usize {
        self.vertices.len()
    }
    /// True for an empty loop.
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }
}

/// A proposed patch. Vertex index `i < k` (k = loop length) is the hole's `i`-th
/// boundary vertex; `i >= k` is `new_vertices[i - k]`. Triangles are oriented like
/// the hole (see [`Hole::vertices`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Patch {
    pub new_vertices: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

/// Why a method produced no patch.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FillError {
    /// The per-hole time limit ran out.
    #[error("time limit reached")]
    Timeout,
    /// The method cannot fill this hole.
    #[error("{0}")]
    Failed(String),
}

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

/// What a method sees: the mesh (read-only), the hole, the policy, the deadline.
pub struct FillContext<'a> {
    pub mesh: &'a Mesh,
    pub hole: &'a Hole,
    pub policy: &'a Policy,
    pub deadline: Deadline,
    /// The dispatcher's checks over `mesh`, for a method that checks its own patch
    /// (`None`: the method builds its own, which costs a tree over the whole mesh).
    pub checker: Option<&'a Checker>,
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
    let est = geom::vector_area(&ctx.boundary_positions()) / (0.75f64.sqrt() / 2.0 * l * l);
    if est > cap as f64 {
        return Err(FillError::Failed(format!(
            "the patch would have about {est:.0} triangles > limits.max_patch_triangles = {cap}"
        )));
    }
    Ok(())
}

/// Runs one method.
pub fn run_method(method: Method, ctx: &FillContext) -> Result<Patch, FillError> {
    run_method_checked(method, ctx).map(|(p, _)| p)
}

/// Runs one method; with the patch, the quality of the checks it already passed
/// inside the method (the self-checked methods `wavefront`, `hpde` and
/// `lssvm_poisson` relax and check their patch with the dispatcher's checker, see
/// [`wavefront::retry`]), or `None` when the dispatcher must relax and check it.
pub fn run_method_checked(
    method: Method,
    ctx: &FillContext,
) -> Result<(Patch, Option<PatchQuality>), FillError> {
    match method {
        Method::Fan => fan::fill(ctx).map(|p| (p, None)),
        Method::MinAreaFair => min_area_fair::fill(ctx).map(|p| (p, None)),
        Method::AdvancingFront => advancing_front::fill(ctx).map(|p| (p, None)),
        Method::LssvmPoisson => lssvm_poisson::fill_checked(ctx),
        Method::Wavefront => wavefront::fill_checked(ctx),
        Method::Hpde => hpde::fill_checked(ctx),
    }
}

/// The method list of a class.
pub fn methods_for(policy: &Policy, class: HoleClass) -> &[Method] {
    match class {
        HoleClass::Small => &policy.dispatch.small,
        HoleClass::Middle => &policy.dispatch.middle,
        HoleClass::Large => &policy.dispatch.large,
    }
}

/// What the first phase of [`fill_hole`] found for one hole: every attempt so far and,
/// if one passed the checks against the mesh as it was, that patch.
#[derive(Clone, Debug)]
pub struct Proposal {
    /// Attempts that failed or were rejected, in order.
    pub tried: Vec<Attempt>,
    /// The accepted attempt: index in the class's method list, patch, quality, ms.
    pub accepted: Option<(usize, Patch, PatchQuality, f64)>,
    /// Time spent, in milliseconds.
    pub ms: f64,
}

/// One method on one hole: run it, relax the patch tangentially, check it. `Ok` holds
/// the checked patch and its quality; `Err` the attempt that failed.
fn attempt(
    method: Method,
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &Checker,
) -> Result<(Patch, PatchQuality, f64), Attempt> {
    let ta = Instant::now();
    let ctx = FillContext {
        mesh,
        hole,
        policy,
        deadline: Deadline::after_ms(policy.limits.hole_time_ms),
        checker: Some(checker),
    };
    let failed = |outcome, reason: String| Attempt {
        method,
        outcome,
        reason,
        ms: ms_since(ta),
    };
    // a method that panics (a bug, or a solver that panics on singular input)
    // fails over like any other failure: one bad hole never takes the file down
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        run_method_checked(method, &ctx)
    }))
    .unwrap_or_else(|_| {
        Err(FillError::Failed(format!(
            "internal error in {}",
            method.name()
        )))
    })
    .and_then(|p| {
        ctx.deadline.check()?;
        Ok(p)
    });
    let patch = match result {
        // relaxed and checked by the method itself, with this checker
        Ok((p, Some(q))) => return Ok((p, q, ms_since(ta))),
        Ok((p, None)) => p,
        Err(FillError::Timeout) => {
            return Err(failed(
                Outcome::Timeout,
                format!("time limit of {} ms reached", policy.limits.hole_time_ms),
            ))
        }
        Err(FillError::Failed(why)) => return Err(failed(Outcome::Error, why)),
    };
    // even out the triangles tangentially; keep that only if it passes the checks
    if let Some((relaxed, q)) = relax::relax_checked(
        mesh,
        hole,
        &patch,
        policy.fair.tangential_relax,
        relax::RELAX_STEP,
        |p| checker.check_patch(mesh, &hole.vertices, p, &policy.checks),
    ) {
        return Ok((relaxed, q, ms_since(ta)));
    }
    match checker.check_patch(mesh, &hole.vertices, &patch, &policy.checks) {
        Ok(q) => Ok((patch, q, ms_since(ta))),
        Err(why) => Err(failed(Outcome::Rejected, why.to_string())),
    }
}

/// First phase of filling a hole, read-only so that holes can run in parallel: tries
/// the class's methods in order from `from` and stops at the first patch that passes
/// every check against `mesh`.
pub fn propose(
    mesh: &Mesh,
    hole: &Hole,
    policy: &Policy,
    checker: &Checker,
    from: usize,
) -> Proposal {
    let t0 = Instant::now();
    let mut tried = Vec::new();
    if hole.len() >= 3 {
        for (i, &method) in methods_for(policy, hole.class)
            .iter()
            .enumerate()
            .skip(from)
        {
            match attempt(method, mesh, hole, policy, checker) {
                Ok((patch, q, ms)) => {
                    return Proposal {
                        tried,
                        accepted: Some((i, patch, q, ms)),
                        ms: ms_since(t0),
                    }
                }
                Err(a) => tried.push(a),
            }
        }
    }
    Proposal {
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
        id: hole.id,
        boundary_vertices: hole.len(),
        perimeter: hole.perimeter,
        mean_edge_length: hole.mean_edge_length,
        class: hole.class,
        method: None,
        tried: proposal.tried,
        status: HoleStatus::Failed,
        reason: String::new(),
        added_vertices: 0,
        added_faces: 0,
        quality: None,
        ms: 0.0,
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
    let methods = methods_for(policy, hole.class);
    let mut next = Some(proposal.accepted);
    let mut from = methods.len();
    // the proposal first, then each later method with full checks
    loop {
        let candidate = match next.take() {
            Some(Some((i, patch, q, ms))) => {
                from = i + 1;
                match checker.check_against_added(mesh, &hole.vertices, &patch, &policy.checks) {
                    Ok(()) => Some((i, patch, q, ms)),
                    Err(why) => {
                        rep.tried.push(Attempt {
                            method: methods[i],
                            outcome: Outcome::Rejected,
                            reason: why.to_string(),
                            ms,
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
                let p = propose(mesh, hole, policy, checker, from);
                rep.tried.extend(p.tried);
                from = methods.len();
                p.accepted
            }
        };
        let Some((i, patch, quality, ms)) = candidate else {
            continue;
        };
        let method = methods[i];
        match apply_patch(mesh, hole, &patch) {
            Ok(faces) => {
                checker.commit(mesh, faces);
                rep.tried.push(Attempt {
                    method,
                    outcome: Outcome::Accepted,
                    reason: String::new(),
                    ms,
                });
                rep.method = Some(method);
                rep.status = HoleStatus::Filled;
                rep.added_vertices = patch.new_vertices.len();
                rep.added_faces = patch.triangles.len();
                rep.quality = Some(quality);
                done(&mut rep);
                return rep;
            }
            Err(why) => rep.tried.push(Attempt {
                method,
                outcome: Outcome::Rejected,
                reason: why,
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
    let proposal = propose(mesh, hole, policy, checker, 0);
    finish_hole(mesh, hole, policy, checker, proposal)
}

/// Adds a checked patch to the mesh. Returns the range of new face indices.
/// On failure the mesh is left as it was.
pub fn apply_patch(
    mesh: &mut Mesh,
    hole: &Hole,
    patch: &Patch,
) -> Result<std::ops::Range<usize>, String> {
    let k = hole.len();
    let nv0 = mesh.num_vertices();
    let nf0 = mesh.num_faces();
    let colors = mesh.colors.as_ref().map(|c| {
        let bc: Vec<[f32; 3]> = hole.vertices.iter().map(|v| c[v.idx()]).collect();
        bc
    });
    for &p in &patch.new_vertices {
        let col = colors
            .as_ref()
            .map(|bc| interpolate_color(mesh, hole, bc, p));
        mesh.add_vertex(p, col);
    }
    let map = |i: u32| -> Result<VertexId, String> {
        let i = i as usize;
        if i < k {
            Ok(hole.vertices[i])
        } else if i - k < patch.new_vertices.len() {
            Ok(VertexId::from_idx(nv0 + i - k))
        } else {
            Err(format!("patch index {i} out of range"))
        }
    };
    let mut faces = Vec::with_capacity(patch.triangles.len());
    for t in &patch.triangles {
        match (map(t[0]), map(t[1]), map(t[2])) {
            (Ok(a), Ok(b), Ok(c)) => faces.push([a, b, c]),
            _ => {
                mesh.truncate_vertices(nv0);
                return Err("patch references a vertex that does not exist".into());
            }
        }
    }
    if let Err(e) = mesh.add_faces(&faces) {
        mesh.truncate_vertices(nv0);
        return Err(format!("patch would break the mesh: {e}"));
    }
    Ok(nf0..mesh.num_faces())
}

/// Colour of a new vertex: inverse-distance weighting of the loop's colours.
fn interpolate_color(mesh: &Mesh, hole: &Hole, bc: &[[f32; 3]], p: DVec3) -> [f32; 3] {
    let mut acc = [0.0f64; 3];
    let mut wsum = 0.0;
    for (i, &v) in hole.vertices.iter().enumerate() {
        let d = (mesh.pos(v) - p).length_squared().max(1e-300);
        let w = 1.0 / d;
        for c in 0..3 {
            acc[c] += w * bc[i][c] as f64;
        }
        wsum += w;
    }
    if wsum > 0.0 {
        [
            (acc[0] / wsum) as f32,
            (acc[1] / wsum) as f32,
            (acc[2] / wsum) as f32,
        ]
    } else {
        [0.5, 0.5, 0.5]
    }
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1000.0
}
