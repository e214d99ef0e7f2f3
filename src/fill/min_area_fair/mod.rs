//! Middle-sized holes: minimum-area triangulation, refinement, fairing.
//!
//! Paper 002 (Feng et al. 2020), §5.2, Algorithm 2; ALGORITHMS B2. Three stages:
//! 1. [`triangulate`]: the loop is triangulated by dynamic programming, weight Liepa's
//!    max-dihedral-then-area (default, as CGAL) or total area (the paper;
//!    `refine.weight`). Loops over `refine.restricted_search_above` (400) restrict the
//!    search (see that module for how we read CGAL's restriction).
//! 2. [`refine`]: triangles are split at their centroids until they match the density
//!    of the surrounding mesh (`refine.density`, paper: sqrt 2), with Delaunay edge
//!    swaps after each round.
//! 3. [`crate::fill::kit::fair`]: the new vertices solve `Δ^c x = 0` (`fair.continuity`,
//!    `fair.weights`) with the loop and enough outer rings of the mesh fixed.
//!
//! Beyond the paper (for the quality target `Qt > 1.39` on most patch triangles, which
//! Liepa-style refinement alone reaches on about half of them): between stages 2 and 3
//! the refined patch is relaxed ([`refine::Refiner::relax`]: long-edge splits, valence
//! flips, tangential smoothing toward equilateral triangles, never making slivers), and
//! after a first fairing it is relaxed again on the faired surface and faired once more,
//! `fair.passes` times (3); finally a sliver the fairing made is flipped away if it can
//! be. The first fairing's weights come from the flat relaxed patch, which pulls the
//! patch flatter than the surface; each pass takes them from the faired surface.
//! Measured (issue 19, seeds 1-5, nine synthetic meshes, method forced): mean APE 6.70
//! per mille with the area weight, one pass and full search up to 60 loop vertices;
//! 5.77 with Liepa's weight, full search up to 400 and 3 passes (cgal_fair 6.56),
//! at about 2.5 times its fill time. With cotangent
//! weights the tangential layout survives fairing (linear precision), so the relaxed
//! shapes are what the output gets.
//!
//! Huge holes (beyond the paper, whose holes are small): when the patch at the
//! surrounding density would pass `limits.max_patch_triangles`, stages 1 and 2 are
//! replaced by [`graded`], a Delaunay refinement of the loop projected on its best-fit
//! plane whose triangles grow from the loop's spacing inward (about 3 per loop vertex
//! along the loop, the interior sized to keep the patch near half the cap), whose new
//! vertices start on the membrane the loop spans; it is faired, made Delaunay in 3D,
//! faired again with the weights of the faired surface, and slivers are flipped away. A loop whose projection is not a simple polygon keeps stages 1 and
//! 2 with a scale floor ([`coarse_scale`]) instead.
//!
//! Reading of the vague passages: the paper's step 13-15 ("search the two adjacent faces
//! of the boundary, combine them with the refined patch and deform the new patch by
//! Laplace-Beltrami") is read as Liepa's and CGAL's fairing: only the new vertices move,
//! the adjacent faces enter the operator as constraints, because moving input vertices
//! is not allowed here (input vertices are written back bit-exact). The paper's split
//! pass runs once over the initial triangles, but its text says splitting continues
//! "until no new triangles created", which we follow (as Liepa and CGAL do).

pub mod graded;

use super::kit::triangulate::{forbidden_chords, outside_normals};
use super::kit::{fair, refine, retry, triangulate, FillContext, FillError};
use crate::fasthash::HashSet;
use crate::fill::kit::retry::Passed;
use crate::geometry::measure;
use crate::mesh::{Mesh, VertexId};
use crate::patch::Patch;
use crate::policy::{Policy, Search, TriangulationWeight, Weights};
use glam::DVec3;

/// Scale of each loop vertex: mean length of its mesh edges that are not hole-boundary
/// edges (the loop's mean edge length when it has none).
pub fn loop_scales(mesh: &Mesh, lp: &[VertexId], fallback: f64) -> Vec<f64> {
    let k = lp.len();
    (0..k)
        .map(|i| {
            let v = lp[i];
            let prev = lp[(i + k - 1) % k];
            let next = lp[(i + 1) % k];
            let p = mesh.pos(v);
            let (mut sum, mut n) = (0.0, 0usize);
            for w in mesh.topo.neighbors(v) {
                if w == prev || w == next {
                    continue;
                }
                sum += (mesh.pos(w) - p).length();
                n += 1;
            }
            if n > 0 && sum > 0.0 {
                sum / n as f64
            } else {
                fallback
            }
        })
        .collect()
}

/// Mean area of a refined triangle, in units of the squared scale, at density sqrt 2
/// (measured: 0.67 on a cylinder slot refined to the loop's scale; 0.4 on a round
/// 10,000-vertex hole refined to a floor, where the band along the loop keeps the
/// loop's spacing; the smaller value errs toward coarsening).
const AREA_PER_TRIANGLE: f64 = 0.4;

/// Patches with more triangles than this after refinement get [`RELAX_FLAT_BIG`]
/// relaxation rounds and no second pass: each round costs about as much as the
/// refinement, and the dispatcher's tangential relaxation evens the triangles out too.
const BIG_PATCH: usize = 20_000;
const RELAX_FLAT_BIG: usize = 2;

/// The scale floor that keeps the refined patch of a huge hole under `cap` triangles
/// (`limits.max_patch_triangles`), or `None` when the surrounding density fits.
///
/// The patch's area is that of the initial (minimum-area) triangulation; refined to
/// the density of the surrounding mesh (mean loop scale `s`) it would have about
/// `A / (0.6 s²)` triangles (scaled by `(√2 / density)²`). Beyond the cap, new vertices
/// get at least the scale `s·√(n / n_target)` with `n_target = 0.8 cap` (the band of
/// triangles along the loop, which keeps the loop's spacing, takes the rest). Not in
/// the paper, whose holes are small.
pub fn coarse_scale(
    pts: &[DVec3],
    tris: &[[u32; 3]],
    scale: &[f64],
    density: f64,
    cap: usize,
) -> Option<f64> {
    let area: f64 = tris
        .iter()
        .map(|t| measure::tri_area(pts[t[0] as usize], pts[t[1] as usize], pts[t[2] as usize]))
        .sum();
    coarse_scale_for_area(area, scale, density, cap)
}

/// [`coarse_scale`] for a patch of the given area.
pub fn coarse_scale_for_area(area: f64, scale: &[f64], density: f64, cap: usize) -> Option<f64> {
    if cap == 0 || scale.is_empty() || density.is_nan() || density <= 0.0 {
        return None;
    }
    let s = scale.iter().sum::<f64>() / scale.len() as f64;
    if !(area.is_finite() && s > 0.0 && s.is_finite()) {
        return None;
    }
    let d = density / std::f64::consts::SQRT_2;
    let n = area * d * d / (AREA_PER_TRIANGLE * s * s);
    let target = 0.8 * cap as f64;
    if n <= target {
        return None;
    }
    Some(s * (n / target).sqrt())
}

/// Smallest angle (degrees) the graded refinement of a huge hole aims at: 20 degrees
/// keeps the band along the loop near 3 triangles per loop vertex (measured on a
/// round 10,000-vertex hole: 25 degrees, 4.3 per loop vertex and twice the time).
const GRADED_ANGLE_DEG: f64 = 20.0;

/// Triangles the graded band along a loop takes per loop vertex (measured at
/// [`GRADED_ANGLE_DEG`] on round and slot holes: 2.5 to 3).
const GRADED_BAND_PER_VERTEX: f64 = 3.0;

/// A huge hole whose projection on its best-fit plane is a simple polygon: the
/// graded patch of [`graded`], faired, slivers the fairing made flipped away.
/// `Ok(None)` when the hole is not huge (its patch at the surrounding density fits
/// under `limits.max_patch_triangles`) or the graded mesh does not apply.
fn fill_graded(
    ctx: &FillContext,
    pts: &[DVec3],
    scale: &[f64],
    forbidden: &HashSet<(u32, u32)>,
) -> Result<Option<Patch>, FillError> {
    let k = pts.len();
    let cap = ctx.policy.limits.max_patch_triangles;
    let area = measure::vector_area(pts);
    if coarse_scale_for_area(area, scale, ctx.policy.refine.density, cap).is_none() {
        return Ok(None);
    }
    // the interior gets what the band leaves of half the cap (at least a twentieth of
    // it); the refinement's triangles average about 0.75 of its area bound
    let interior = (0.5 * cap as f64 - GRADED_BAND_PER_VERTEX * k as f64).max(0.05 * cap as f64);
    let params = graded::GradedParams {
        max_area: area / (0.75 * interior),
        angle_deg: GRADED_ANGLE_DEG,
        max_new_vertices: cap.saturating_mul(2).max(4 * k),
    };
    let t0 = std::time::Instant::now();
    let Some(g) = graded::graded(pts, forbidden, params)? else {
        tracing::debug!(hole = ctx.hole.id, k, "min_area_fair: no graded mesh");
        return Ok(None);
    };
    let t_mesh = t0.elapsed();
    ctx.deadline.check()?;
    let mut patch = Patch {
        new_vertices: g.new_vertices,
        triangles: g.triangles,
    };
    // the first fairing takes its cotangent weights on the starting layout (the flat
    // Delaunay mesh lifted onto the membrane of the loop); the faired surface is then
    // made Delaunay again in 3D (Lawson flips) and faired once more with its own
    // weights, which follows a curved hole more closely (measured on a 46-degree
    // spherical cap of 10,000 boundary vertices: the largest sag below the sphere
    // drops from 4.6 % to 3.1 % of its radius; on caps beyond a hemisphere and on a
    // steep saddle the flips raise the share of well-shaped triangles from 6-43 % to
    // 22-57 %)
    fair::fair_patch(ctx.mesh, ctx.hole, &mut patch, &ctx.policy.fair)?;
    ctx.deadline.check()?;
    let mut r = refine::Refiner::new(pts.to_vec(), vec![0.0; k], patch.triangles, forbidden);
    r.pos.extend_from_slice(&patch.new_vertices);
    r.scale.resize(r.pos.len(), 0.0);
    let swaps = if ctx.policy.fair.continuity > 0 {
        r.delaunay_swaps(&ctx.deadline)?
    } else {
        0
    };
    patch.triangles = r.tris.clone();
    if swaps > 0 {
        fair::fair_patch(ctx.mesh, ctx.hole, &mut patch, &ctx.policy.fair)?;
    }
    let t_fair = t0.elapsed();
    let mut flips = 0;
    if ctx.policy.fair.continuity > 0 && !patch.new_vertices.is_empty() {
        // fairing moves vertices: mend any sliver it made with a flip
        let limit = (2.0 * ctx.policy.checks.min_angle_deg)
            .max(2.0)
            .to_radians();
        r.pos.truncate(k);
        r.pos.extend_from_slice(&patch.new_vertices);
        let worst = r
            .tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| r.pos[i as usize]);
                measure::smallest_angle_by_cosines(a, b, c)
            })
            .fold(f64::INFINITY, f64::min);
        if worst < limit {
            flips = r.fix_slivers(limit, &ctx.deadline)?;
            patch.triangles = r.tris;
        }
    }
    tracing::debug!(
        hole = ctx.hole.id,
        k,
        triangles = patch.triangles.len(),
        new_vertices = patch.new_vertices.len(),
        mesh_ms = t_mesh.as_secs_f64() * 1e3,
        fair_ms = (t_fair - t_mesh).as_secs_f64() * 1e3,
        swaps,
        flips,
        "min_area_fair: graded patch"
    );
    Ok(Some(patch))
}

/// Relaxation rounds on the refined (flat) patch before fairing.
const RELAX_FLAT: usize = 8;
/// Relaxation rounds on the faired patch before each further fairing.
const RELAX_FAIRED: usize = 3;

/// Fills the hole as [`fill`] does, self-checked ([`retry`]): when the patch fails the
/// dispatcher's checks (a fold of the minimum-area triangulation that fairing turns
/// into a self-intersection: measured on large falconstatue holes, where forced alone
/// it left 2 of 11 holes open), it is repaired locally, then made again from the
/// other triangulation weight, without collapses and with uniform fairing weights
/// ([`variants`]).
///
/// With `refine.search = "both"`, the patch is made twice, from the triangulation
/// found among every triangulation of the loop and from the one found among the edges
/// of its 3D Delaunay triangulation (CGAL's), and the passing patch of larger area is
/// kept: a triangulation that cuts across the lost surface (a chord over a bulge,
/// which refinement and fairing keep) makes a smaller patch than one that follows it.
/// Read off CGAL's two searches on the bench (seeds 1-5, nine meshes, 284 middle and
/// large holes): they differ by up to 2x per hole, either way, and the larger patch is
/// the closer one on 77 % of the large holes where they differ. Ours differ less (the
/// relaxation and refairing re-mesh the patch) and the larger is the closer on 23 of
/// 36: no gain measured (docs/measurements.md), so it is an option, off by default.
pub fn fill_checked(ctx: &FillContext) -> Result<(Patch, Option<Passed>), FillError> {
    if ctx.policy.refine.search != Search::Both {
        return retry::first_passing_at(ctx, &variants(ctx.policy), |_, c| fill(c));
    }
    let made = |search: Search| -> Result<(Patch, Option<Passed>), FillError> {
        let Ok(policy) = ctx.policy.edit(|s| s.refine.search = search) else {
            return Err(FillError::stuck("the policy does not take the search"));
        };
        let sub = FillContext {
            policy: &policy,
            ..*ctx
        };
        retry::first_passing_at(&sub, &variants(&policy), |_, c| fill(c))
    };
    let full = made(Search::Full);
    if full
        .as_ref()
        .is_err_and(|e| matches!(e, FillError::Timeout))
    {
        return full;
    }
    let delaunay = made(Search::Delaunay);
    match (full, delaunay) {
        (Ok(f), Ok(d)) => {
            let (af, ad) = (f.0.area(ctx.mesh, ctx.hole), d.0.area(ctx.mesh, ctx.hole));
            tracing::debug!(
                hole = ctx.hole.id,
                full = af,
                delaunay = ad,
                "min_area_fair: patch areas of the two searches"
            );
            Ok(if ad > af { d } else { f })
        }
        (Ok(f), Err(_)) => Ok(f),
        (Err(_), Ok(d)) => Ok(d),
        (Err(e), Err(_)) => Err(e),
    }
}

/// The policy, then the other triangulation weight (`refine.weight`: total area or
/// Liepa's dihedral-then-area), which folds other loops, then (unless the policy has
/// them) no collapses (`refine.collapse = 0`: on boot, `min_area_fair` forced, one
/// hole's collapsed patch failed the checks in every other variant and the rim was
/// trimmed, 202 input faces; seed-mean APE 2.826 against `cgal_fair`'s 2.789, 2.716
/// with this variant), then uniform fairing weights (on falconstatue seed 2's
/// 140-vertex hole, the cotangent weights of both triangulations fair a triangle flat,
/// 0.002 degrees, that uniform weights do not).
pub fn variants(policy: &Policy) -> Vec<(&'static str, Policy)> {
    let mut out = vec![("policy", policy.clone())];
    let other = match policy.refine.weight {
        TriangulationWeight::Area => TriangulationWeight::DihedralArea,
        TriangulationWeight::DihedralArea => TriangulationWeight::Area,
    };
    if let Ok(p) = policy.edit(|s| s.refine.weight = other) {
        out.push(("the other triangulation weight", p));
    }
    if policy.refine.collapse > 0.0 {
        if let Ok(p) = policy.edit(|s| s.refine.collapse = 0.0) {
            out.push(("no collapses", p));
        }
    }
    if policy.fair.weights != Weights::Uniform {
        if let Ok(p) = policy.edit(|s| s.fair.weights = Weights::Uniform) {
            out.push(("uniform fairing weights", p));
        }
    }
    out
}

/// Fills the hole: triangulate, refine, relax, fair.
pub fn fill(ctx: &FillContext) -> Result<Patch, FillError> {
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    let pts = ctx.boundary_positions();
    if pts.iter().any(|p| !p.is_finite()) {
        return Err(FillError::bad_loop("the loop has a non-finite coordinate"));
    }
    let forbidden = forbidden_chords(ctx.mesh, &ctx.hole.vertices);
    let outside = outside_normals(ctx.mesh, &ctx.hole.vertices);
    let scale = loop_scales(ctx.mesh, &ctx.hole.vertices, ctx.hole.mean_edge_length);
    if let Some(p) = fill_graded(ctx, &pts, &scale, &forbidden)? {
        return Ok(p);
    }
    let input =
        triangulate::LoopInput::with_policy(&pts, &forbidden, &outside, ctx.policy, ctx.deadline);
    let t0 = std::time::Instant::now();
    let tris = triangulate::triangulate(&input)?;
    let t_tri = t0.elapsed();
    let cap = ctx.policy.limits.max_patch_triangles;
    let floor = coarse_scale(&pts, &tris, &scale, ctx.policy.refine.density, cap);
    let mut r = refine::Refiner::new(pts, scale, tris, &forbidden);
    r.collapse_ratio = ctx.policy.refine.collapse;
    if let Some(f) = floor {
        r.scale_floor = f;
        tracing::debug!(
            hole = ctx.hole.id,
            k,
            floor = f,
            "min_area_fair: coarser density"
        );
    }
    if cap > 0 {
        r.max_triangles = r.max_triangles.min(cap.saturating_mul(2).max(k * 4));
    }
    r.refine(ctx.policy.refine.density, &ctx.deadline)?;
    let t_refine = t0.elapsed();
    let refined = ctx.policy.refine.density > 0.0;
    let big = r.tris.len() > BIG_PATCH;
    let relax_faired = if big { 0 } else { RELAX_FAIRED };
    if refined {
        let extra = if ctx.policy.fair.continuity == 0 {
            relax_faired
        } else {
            0
        };
        let flat = if big { RELAX_FLAT_BIG } else { RELAX_FLAT };
        r.relax(flat + extra, &ctx.deadline)?;
    }
    let t_relax = t0.elapsed();
    let mut patch = Patch {
        new_vertices: r.pos[k..].to_vec(),
        triangles: r.tris.clone(),
    };
    ctx.deadline.check()?;
    fair::fair_patch(ctx.mesh, ctx.hole, &mut patch, &ctx.policy.fair)?;
    let t_fair = t0.elapsed();
    if refined && ctx.policy.fair.continuity > 0 && relax_faired > 0 {
        // more passes on the faired surface: even out, swap, fair again
        for _ in 0..ctx.policy.fair.passes {
            r.pos.truncate(k);
            r.pos.extend_from_slice(&patch.new_vertices);
            r.relax(relax_faired, &ctx.deadline)?;
            patch.new_vertices = r.pos[k..].to_vec();
            patch.triangles = r.tris.clone();
            fair::fair_patch(ctx.mesh, ctx.hole, &mut patch, &ctx.policy.fair)?;
        }
    }
    if ctx.policy.fair.continuity > 0 && !patch.new_vertices.is_empty() {
        // fairing moves vertices: mend any sliver it made with a flip
        r.pos.truncate(k);
        r.pos.extend_from_slice(&patch.new_vertices);
        let limit = (2.0 * ctx.policy.checks.min_angle_deg)
            .max(2.0)
            .to_radians();
        if r.fix_slivers(limit, &ctx.deadline)? > 0 {
            patch.triangles = r.tris.clone();
        }
    }
    tracing::debug!(
        hole = ctx.hole.id,
        k,
        triangles = patch.triangles.len(),
        triangulate_ms = t_tri.as_secs_f64() * 1e3,
        refine_ms = (t_refine - t_tri).as_secs_f64() * 1e3,
        relax_ms = (t_relax - t_refine).as_secs_f64() * 1e3,
        fair_ms = (t_fair - t_relax).as_secs_f64() * 1e3,
        second_pass_ms = (t0.elapsed() - t_fair).as_secs_f64() * 1e3,
        "min_area_fair done"
    );
    Ok(patch)
}

#[cfg(test)]
mod tests;
