//! HPDE: hole patching by point prediction with differential evolution (paper 000,
//! "A triangulation-based hole patching method using differential evolution", §4;
//! ALGORITHMS D in docs/references.md).
//!
//! Steps, in the paper's order (§4.1–§4.7), and how this module reads each one:
//!
//! 1. *Smoothing of noisy input* (§4.1) is not done here: it is the pipeline's
//!    optional Taubin pass (`[smooth]`, ALGORITHMS A4).
//! 2. *Base points* (§4.2). The paper resamples the boundary at `n = ⌊BudLen /
//!    (0.8·EdgeLen)⌋` equal arc-length points. To stitch the patch without
//!    T-junctions we use the original boundary vertices as base points; the density
//!    comes from the pipeline's `clean.split_long_edges`. `EdgeLen` is the mean
//!    length of the edges of the ring triangles (every face touching a loop vertex).
//! 3. *Segmentation test* (§4.2, eq. 8). Over every split of the loop into two
//!    consecutive arcs of at least `max(3, n/4)` points (so that each arc has a plane;
//!    the paper allows any `i < j`) we minimise the larger of the two smallest PCA
//!    eigenvalues (prefix sums of the moments make each split O(1)). Each arc's plane
//!    normal is oriented like the mesh's vertex normals on that arc; the dihedral
//!    angle of the two planes is `π − ∠(n₁, n₂)` (π for one flat plane, π/2 for a cube
//!    edge). Below `ac_deg` the hole is handled as two planes. A plane whose middle
//!    eigenvalue is below 4 times its smallest counts as undefined (no segmentation).
//! 4. *Correspondences* (§4.3, eqs. 9–10). A correspondence pairs `BP_a` with
//!    `BP_(s−a) mod n`; the pairs form a chain ordered from one end of the loop to the
//!    other. Unsegmented: `s = 2·sp − 1` (eq. 10's rotation by `sp`), `sp` over every
//!    start, minimising the summed pair distances (first minimum wins). Segmented:
//!    `s = i₀ + j₀` (eq. 9). A pair is skipped (no points are predicted on it; its
//!    base points stay) when its line meets the boundary at either end at an acute
//!    angle below `ic_deg` (Fig. 2: "directly skipping"). The paper's base points lie
//!    inside boundary edges `Q_t Q_(t+1)`; ours are vertices, so the boundary direction
//!    there is the central difference of the two neighbouring base points (a single
//!    edge of a staircase boundary would reject most pairs).
//! 5. *Prediction* (§4.4, eqs. 11–16). Section plane through `P1 P2` with normal
//!    `N = lv × (lv × (mid_(i−1) − mid_(i+1)))`, the mids being the midpoints of the
//!    neighbouring pairs of the chain (one-sided at its ends). `N` is the chain
//!    direction without its component along `lv`, so the plane is transverse to the
//!    chain. Near the chain's ends the mids can move along the surface normal (nested
//!    chords along one boundary arc) and that plane is nearly the tangent plane; so
//!    when `N` makes less than 20° with the mean vertex normal of P1, P2 (projected
//!    off `lv`), or is undefined, we use the normal section instead: the plane through
//!    `lv` and that normal (eq. 11's plane wherever the chain runs along the surface).
//!    `AP` is where the plane crosses the far edge of a ring triangle of the end
//!    point, choosing the crossing most opposite to the chord; `TV1 = P1 − AP1`,
//!    `TV2 = AP2 − P2`; with no crossing, the chord within the vertex's tangent plane.
//!    In plane coordinates (x along `P1→P2`) each end defines one circular arc through
//!    P1 and P2. The paper makes the arc tangent to `TV` at P; but `TV` is a secant
//!    (from `AP`), which over-bends the arc by half the secant's angle (+2 % of the
//!    radius on a unit sphere with edges of 0.15, measured). With `arcs_through_ring`
//!    (default) the arc is the circle through `AP1, P1, P2` (resp. `P1, P2, AP2`), whose
//!    tangent at P1 is `TV1` turned back by the angle `AP1` subtends at P2 (exterior
//!    angle theorem); `false` is the literal reading. Tangent–chord angles are clamped
//!    to ±85° so both arcs are graphs over the chord (the paper: "not suitable for very
//!    high curvature").
//!    `m` from eq. 15 with `EdgeLen` replaced by `spacing · EdgeLen`. `x_i` is the
//!    mean of the x of the `i`-th of `m` equally spaced points (equal arc length) on
//!    the two arcs (eq. 12); `y_i ∈ [lower arc, upper arc]` at `x_i` (eq. 14) is found
//!    by DE/rand/1/bin minimising the largest turning angle of the polyline
//!    `P1, PP_1, …, PP_m, P2`. Population `max(population_factor·m, 4)` (rand/1 needs
//!    four distinct individuals); individual 0 is eq. 16's blend, the others are
//!    uniform within a quarter of the bound width around it (the paper: "randomly
//!    initialized around"); a mutant coordinate outside its bounds is set half-way
//!    between the parent's value and the violated bound; `generations` generations.
//!    Random numbers: one ChaCha8 stream seeded with `policy.seed`, used in chain order.
//! 6. *Topology* (§4.5). Base and predicted points are projected onto the PCA plane of
//!    the loop (unsegmented) or onto the two fitted planes, each rotated about their
//!    line of intersection into one plane (segmented; a predicted point goes to the
//!    plane of its pair's arc, a pair straddling both arcs to the nearer plane). The
//!    projected loop must be a simple polygon. When the paper's plane(s) do not give
//!    one, we try, in order, the Newell (area) plane, the plane normal to the summed
//!    vertex normals and the two unfolded planes of the best split; then, with
//!    `disk_fallback` (the paper's discussion asks for "more intermediate planes"),
//!    the loop is mapped to a circle by arc length and each predicted point to its
//!    fraction along its pair's chord there (chords of the chain do not cross, so the
//!    points keep their order). Without it, [`FillError::Failed`] names every
//!    candidate's problem (the dispatcher falls back). Predicted points outside the
//!    polygon, or closer than `0.4·spacing·EdgeLen` to the polygon or to an earlier
//!    point, are dropped. A 2D constrained Delaunay triangulation (`spade`) with the
//!    loop as constraints; the triangles inside are lifted to the 3D points.
//! 7. *Improvement* (§4.6–§4.7). `num_smooth` Taubin λ/μ iterations of the new
//!    vertices (the paper's step-1 smoother, with `smooth.lambda`/`smooth.mu`; uniform
//!    weights; boundary fixed). Then edges shorter than `collapse_rate · EdgeLen` are
//!    collapsed, shortest first (the paper's "economical" order, done as passes over
//!    the sorted edges): two new vertices meet at the midpoint (Fig. 5); a new vertex
//!    joined to a boundary vertex merges into it (boundary vertices never move). Then
//!    an edge is swapped when that raises the smallest angle of its two triangles
//!    (Fig. 5c–d). Neither operation creates an edge that already exists in the mesh,
//!    flips a triangle, or breaks the link condition. (The collapse rate has no value
//!    in the paper; 0.6 measured best of 0.5–0.8 on the tests' surfaces.)
//!
//! 8. *Self-checked variants* (not in the paper; [`crate::fill::kit::retry`]): when the
//!    patch fails the dispatcher's checks (a CDT triangle jumping across a fold of the
//!    loop, a collapse pulling a vertex over one), a local repair is tried (edge flips,
//!    then minimum-area re-triangulation in 3-D of the region around the failing
//!    triangle), then the variants of [`variants`].
//! 9. *An intermediate surface* (not in the paper, whose discussion asks for "more
//!    intermediate planes" where the hole's surface is far from one plane). When every
//!    plane variant fails, step 6 is done over the loop's minimum-area triangulation
//!    instead: its triangles map affinely onto a circle (the loop by arc length), each
//!    predicted point goes where its closest point on that surface lands, and the CDT
//!    is made there (`topology::over_surface`); a plane sees such a hole folded, the
//!    surface does not. Then the same without collapse and smoothing, and last the
//!    points moved onto the surface (the smoothing alone shapes the patch). On the
//!    bench's seeds 1-5 (nine meshes, 566 holes forced to `hpde`) this closes 14 of
//!    the 18 holes the planes left open (the rest: three CAD holes of `joint`, one
//!    natural hole of the plastic vase); the holes the planes close are unchanged.
//!
//! The noise experiment (§5) uses uniform noise in `[−σ, σ]`; our test uses seeded
//! Gaussian noise (the wording), without the pre-smoothing.

mod improve;
mod predict;
mod topology;

#[cfg(test)]
mod tests;

use super::kit::{check_patch_size, retry, triangulate, FillContext, FillError};
use crate::fasthash::HashMap;
use crate::mesh::{Mesh, VertexId};
use crate::patch::Patch;
use crate::policy::{Policy, Settings};
use glam::DVec3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeSet;

/// Fills the hole with HPDE (see the module documentation): the policy's settings
/// first; when their patch fails the checks (after a local repair by edge flips), the
/// variants of [`variants`], then those of [`surface_variants`] and
/// [`on_surface_variants`] (step 9; see [`crate::fill::kit::retry`]).
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    fill_checked(ctx).map(|(p, _)| p)
}

/// [`fill`], with the quality of the checks the patch passed (see
/// [`crate::fill::dispatch::run_method_checked`]).
pub fn fill_checked(
    ctx: &FillContext,
) -> Result<(Patch, Option<crate::fill::kit::retry::Passed>), FillError> {
    check_patch_size(ctx)?;
    let mut list = variants(ctx.policy);
    let planes = list.len();
    let over = surface_variants(ctx.policy);
    let surfaces = over.len();
    list.extend(over);
    list.extend(on_surface_variants(ctx.policy));
    // the surface variants change no setting the triangulation reads: made once
    let surface = std::cell::OnceCell::new();
    retry::first_passing_unless(
        ctx,
        &list,
        |at| at < planes,
        |at, c| {
            let Some(i) = at.checked_sub(planes) else {
                return fill_with(c, Topology::Plane);
            };
            let tris = surface
                .get_or_init(|| minimum_area_surface(c, &c.boundary_positions()))
                .as_ref()
                .map_err(Clone::clone)?;
            fill_with(
                c,
                if i < surfaces {
                    Topology::MinimumArea(tris)
                } else {
                    Topology::OnMinimumArea(tris)
                },
            )
        },
    )
}

/// Where step 6 triangulates the loop and the predicted points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Topology<'a> {
    /// The paper's: the fitted plane(s), then the other planes and the disk.
    Plane,
    /// Over the loop's minimum-area triangulation (loop indices, see
    /// [`minimum_area_surface`]) mapped onto a circle (`topology::over_surface`).
    MinimumArea(&'a [[u32; 3]]),
    /// As [`Topology::MinimumArea`], each predicted point moved to its closest point on
    /// that surface (the last resort: the smoothing alone shapes the patch).
    OnMinimumArea(&'a [[u32; 3]]),
}

/// The variants run over the minimum-area surface ([`Topology::MinimumArea`]) when
/// every plane variant failed: the policy, then without the collapse and the smoothing.
pub fn surface_variants(policy: &Policy) -> Vec<(&'static str, Policy)> {
    with_and_without_improvement(
        policy,
        "over the minimum-area surface",
        "over the minimum-area surface, no collapse, no smoothing",
    )
}

/// The last variants, with the points on the minimum-area surface
/// ([`Topology::OnMinimumArea`]): the policy, then without the collapse and the
/// smoothing.
pub fn on_surface_variants(policy: &Policy) -> Vec<(&'static str, Policy)> {
    with_and_without_improvement(
        policy,
        "on the minimum-area surface",
        "on the minimum-area surface, no collapse, no smoothing",
    )
}

fn with_and_without_improvement(
    policy: &Policy,
    with: &'static str,
    without: &'static str,
) -> Vec<(&'static str, Policy)> {
    let mut out = vec![(with, policy.clone())];
    if let Ok(p) = policy.edit(|s| {
        s.hpde.collapse_rate = 0.0;
        s.hpde.num_smooth = 0;
    }) {
        if p != *policy {
            out.push((without, p));
        }
    }
    out
}

/// The policy, then without the short-edge collapse (a collapse can pull a vertex across
/// a fold of the loop), without the smoothing, with neither, then with the next seed.
pub fn variants(policy: &Policy) -> Vec<(&'static str, Policy)> {
    let mut out = vec![("policy", policy.clone())];
    // every change below keeps the policy valid; one that did not would be left out
    let mut push = |name: &'static str, change: &dyn Fn(&mut Settings)| {
        if let Ok(p) = policy.edit(change) {
            if !out.iter().any(|(_, q)| *q == p) {
                out.push((name, p));
            }
        }
    };
    push("no collapse", &|s| s.hpde.collapse_rate = 0.0);
    push("no smoothing", &|s| s.hpde.num_smooth = 0);
    push("no collapse, no smoothing", &|s| {
        s.hpde.collapse_rate = 0.0;
        s.hpde.num_smooth = 0;
    });
    push("next seed", &|s| {
        s.seed = s.seed.wrapping_add(1) & (i64::MAX as u64)
    });
    out
}

/// One HPDE run with the context's policy (the paper's planar topology).
pub fn fill_once(ctx: &FillContext) -> Result<Patch, FillError> {
    fill_with(ctx, Topology::Plane)
}

/// One HPDE run with the context's policy and step 6 done by `topology`.
pub fn fill_with(ctx: &FillContext, topology: Topology<'_>) -> Result<Patch, FillError> {
    let opts = &ctx.policy.hpde;
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "hpde needs a loop of at least 3 vertices (got {k})"
        )));
    }
    let bp = ctx.boundary_positions();
    if bp.iter().any(|p| !p.is_finite()) {
        return Err(FillError::bad_loop(
            "hpde: a boundary vertex has a non-finite coordinate",
        ));
    }
    let edge_len = ring_edge_length(ctx.mesh, &ctx.hole.vertices);
    if !(edge_len.is_finite() && edge_len > 0.0) {
        return Err(FillError::bad_loop(
            "hpde: the triangles around the hole have no usable edge length",
        ));
    }
    let normals: Vec<DVec3> = ctx
        .hole
        .vertices
        .iter()
        .map(|&v| ctx.mesh.vertex_normal(v))
        .collect();

    // step 3: segmentation test
    let split = predict::segmentation(&bp, &normals);
    let segmented = split
        .as_ref()
        .is_some_and(|s| s.dihedral < opts.ac_deg.to_radians());
    ctx.deadline.check()?;
    // step 4: correspondences
    let sum = match (&split, segmented) {
        (Some(s), true) => s.i0 + s.j0,
        _ => predict::best_pairing(&bp),
    };
    let chain = predict::chain(k, sum);
    // step 5: prediction
    let mut rng = ChaCha8Rng::seed_from_u64(ctx.policy.seed);
    let predicted = predict::predict(ctx, &bp, &normals, &chain, edge_len, &mut rng)?;
    // step 6: topology
    let (loop2d, points) = match topology {
        Topology::Plane => {
            let proj = topology::Projection::choose(
                &bp,
                &normals,
                split.as_ref(),
                segmented,
                opts.disk_fallback,
            )?;
            let points = topology::project_all(&proj, &predicted);
            (proj.loop2d, points)
        }
        Topology::MinimumArea(surface) | Topology::OnMinimumArea(surface) => {
            let on = matches!(topology, Topology::OnMinimumArea(_));
            let o = topology::over_surface(&bp, surface, &predicted, on, &ctx.deadline)?;
            (o.loop2d, o.points)
        }
    };
    let drop_dist = 0.4 * opts.spacing * edge_len;
    let tri = topology::triangulate(&loop2d, &bp, &points, drop_dist)?;
    ctx.deadline.check()?;
    // step 7: improvement
    let chords = mesh_chords(ctx.mesh, &ctx.hole.vertices);
    let mut local = improve::Local::new(k, tri.positions, tri.triangles, chords);
    local.smooth(
        opts.num_smooth,
        ctx.policy.smooth.lambda,
        ctx.policy.smooth.mu,
    );
    ctx.deadline.check()?;
    local.collapse(opts.collapse_rate * edge_len);
    ctx.deadline.check()?;
    local.swap();
    local.ensure_no_mesh_chords()?;
    Ok(local.into_patch())
}

/// The loop's minimum-area triangulation (the kit's, with the policy's weight and
/// search; no existing mesh edge as a chord).
pub fn minimum_area_surface(ctx: &FillContext, bp: &[DVec3]) -> Result<Vec<[u32; 3]>, FillError> {
    let forbidden = triangulate::forbidden_chords(ctx.mesh, &ctx.hole.vertices);
    let outside = triangulate::outside_normals(ctx.mesh, &ctx.hole.vertices);
    triangulate::triangulate(&triangulate::LoopInput::with_policy(
        bp,
        &forbidden,
        &outside,
        ctx.policy,
        ctx.deadline,
    ))
}

/// Mean length of the edges of the faces touching the loop (the paper's `EdgeLen`).
fn ring_edge_length(mesh: &Mesh, lp: &[VertexId]) -> f64 {
    let mut faces = BTreeSet::new();
    for &v in lp {
        for f in mesh.topo.vertex_faces(v) {
            faces.insert(f);
        }
    }
    let mut edges = BTreeSet::new();
    for &f in &faces {
        let c = mesh.topo.face(f);
        for i in 0..3 {
            let (a, b) = (c[i], c[(i + 1) % 3]);
            edges.insert((a.min(b), a.max(b)));
        }
    }
    if edges.is_empty() {
        // no ring faces: fall back to the loop itself
        let k = lp.len();
        return (0..k)
            .map(|i| (mesh.pos(lp[(i + 1) % k]) - mesh.pos(lp[i])).length())
            .sum::<f64>()
            / k.max(1) as f64;
    }
    edges
        .iter()
        .map(|&(a, b)| (mesh.pos(a) - mesh.pos(b)).length())
        .sum::<f64>()
        / edges.len() as f64
}

/// Pairs of loop indices `(i, j)`, `i < j`, joined by an existing mesh edge that is
/// not a loop edge: a patch must not add them again.
fn mesh_chords(mesh: &Mesh, lp: &[VertexId]) -> BTreeSet<(u32, u32)> {
    let k = lp.len();
    let index: HashMap<VertexId, u32> =
        lp.iter().enumerate().map(|(i, &v)| (v, i as u32)).collect();
    let mut out = BTreeSet::new();
    for (i, &v) in lp.iter().enumerate() {
        for w in mesh.topo.neighbors(v) {
            if let Some(&j) = index.get(&w) {
                let (a, b) = ((i as u32).min(j), (i as u32).max(j));
                let adjacent =
                    (a as usize + 1) % k == b as usize || (b as usize + 1) % k == a as usize;
                if a != b && !adjacent {
                    out.insert((a, b));
                }
            }
        }
    }
    out
}
