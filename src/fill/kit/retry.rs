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
//! this wrapper; the list is fixed, so the output stays deterministic. Once two
//! variants have failed at a triangle on the same loop edge, the rest that only change
//! settings are skipped: the rim forces that failure (on the public photogrammetry
//! vase, all seven wavefront variants failed at one sliver on one loop edge, 1.1 s),
//! and the dispatcher's rim trimming is what mends it. Variants that build the patch
//! differently are still run (on `bunny-res2` the wavefront's residual-closing variant
//! passes where four full fronts meet one mesh face). After a method of the hole's
//! list has stopped that way, the later ones run their first variant only
//! ([`FillContext::rim_bound`]: on that vase hole, `min_area_fair`'s second weight
//! failed too, 80 ms). A patch that is only a surface to pull toward
//! ([`FillContext::guide`]) keeps its first variant as made where that fails the checks.
//! A caller's last step ([`FillContext::finish`]: the dispatcher's blend toward the
//! patch's faired surface, which relaxes and checks it) gets each made patch first;
//! what it returns is the variant's result, and only where it returns nothing is the
//! patch relaxed and checked here.

use super::relax::{relax_checked, RELAX_STEP};
use super::{Cause, FillContext, FillError, VariantFailure, VariantWhy};
use crate::check::{CheckFailure, Checker, PatchChecks};
use crate::fasthash::{HashMap, HashSet};
use crate::patch::Patch;
use crate::policy::Policy;
use crate::report::PatchQuality;

/// How a self-checked method's patch passed the checks (see [`first_passing_at`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Passed {
    /// The quality of the checks it passed.
    pub quality: PatchQuality,
    /// The variant that made it, when that is not the first (the policy as given):
    /// the repair log names it.
    pub variant: Option<&'static str>,
}

/// Runs `run` under each policy of `variants` (first = the policy as given) and returns
/// the first patch that passes the checks, else a failure listing why each variant
/// failed.
pub fn first_passing(
    ctx: &FillContext,
    variants: &[(&'static str, Policy)],
    run: impl Fn(&FillContext) -> Result<Patch, FillError>,
) -> Result<Patch, FillError> {
    first_passing_at(ctx, variants, |_, c| run(c)).map(|(p, _)| p)
}

/// [`first_passing`] for variants that are not only policies: `run` also gets the
/// variant's index. Each patch is relaxed tangentially and checked
/// ([`super::relax::relax_checked`], as the dispatcher does: the vertices where
/// the relaxed patch fails are held in place and it is relaxed again), the unrelaxed
/// one kept when only it passes; the quality returned with the
/// patch is that of the checks it passed (`None` when there is a single variant: the
/// patch is returned as made, unchecked), so the dispatcher need not check it again.
pub fn first_passing_at(
    ctx: &FillContext,
    variants: &[(&'static str, Policy)],
    run: impl Fn(usize, &FillContext) -> Result<Patch, FillError>,
) -> Result<(Patch, Option<Passed>), FillError> {
    first_passing_unless(ctx, variants, |_| true, run)
}

/// [`first_passing_at`], where only the variants for which `settings_only` holds
/// (the same construction under other settings) are skipped after two failures at
/// one loop edge; the others (a construction that ends differently, such as the
/// wavefront's residual-closing ones) are still run.
pub fn first_passing_unless(
    ctx: &FillContext,
    variants: &[(&'static str, Policy)],
    settings_only: impl Fn(usize) -> bool,
    run: impl Fn(usize, &FillContext) -> Result<Patch, FillError>,
) -> Result<(Patch, Option<Passed>), FillError> {
    // the dispatcher's checker when there is one; else one built on first use
    let mut own: Option<Checker> = None;
    let mut reasons: Vec<VariantFailure> = Vec::new();
    // the loop edges of the triangles the rejected variants failed at
    let mut failed_at: Vec<(usize, usize)> = Vec::new();
    for (at, (name, pol)) in variants.iter().enumerate() {
        ctx.deadline.check()?;
        let edge = match repeated(&failed_at) {
            Some(e) if settings_only(at) => Some(Cause::SameRimFailure(e.0, e.1)),
            _ if at > 0 && ctx.rim_bound => Some(Cause::RimBound),
            _ => None,
        };
        if let Some(cause) = edge {
            reasons.push(VariantFailure {
                name,
                why: VariantWhy::Failed(Box::new(FillError::Failed(cause))),
            });
            continue;
        }
        let sub = FillContext {
            mesh: ctx.mesh,
            hole: ctx.hole,
            policy: pol,
            deadline: ctx.deadline,
            checker: ctx.checker,
            rim_bound: ctx.rim_bound,
            guide: ctx.guide,
            finish: ctx.finish,
        };
        let t = std::time::Instant::now();
        let made = run(at, &sub);
        tracing::debug!(
            hole = ctx.hole.id,
            variant = *name,
            ok = made.is_ok(),
            ms = t.elapsed().as_secs_f64() * 1000.0,
            error = made.as_ref().err().map(|e| e.to_string()),
            "variant run"
        );
        let passed = |quality| {
            Some(Passed {
                quality,
                variant: (at > 0).then_some(*name),
            })
        };
        match made {
            Ok(p) => {
                if variants.len() == 1 {
                    return Ok((p, None));
                }
                let c: &Checker = match ctx.checker {
                    Some(c) => c,
                    None => own.get_or_insert_with(|| Checker::new(ctx.mesh)),
                };
                let check =
                    |q: &Patch| c.check_patch(ctx.mesh, &ctx.hole.vertices, q, &ctx.policy.checks);
                let relax = |p: &Patch| {
                    relax_checked(
                        ctx.mesh,
                        ctx.hole,
                        p,
                        ctx.policy.fair.tangential_relax,
                        RELAX_STEP,
                        check,
                    )
                };
                // the caller's last step, which relaxes and checks the patch itself
                if let Some((finished, q)) = ctx.finish.and_then(|f| f(&p)) {
                    trace_settled(ctx, name, t, true);
                    return Ok((finished, passed(q)));
                }
                // relaxed if that passes (parts held where it fails), else as it is
                if let Some((relaxed, q)) = relax(&p) {
                    trace_settled(ctx, name, t, true);
                    return Ok((relaxed, passed(q)));
                }
                // as made, with every failure recorded: the repairs below re-test
                // only the triangles they change
                let near = c.faces_near(ctx.mesh, &ctx.hole.vertices, &p);
                let state = PatchChecks::new(
                    ctx.mesh,
                    &ctx.hole.vertices,
                    p.clone(),
                    &ctx.policy.checks,
                    &near,
                );
                let result = match &state {
                    Some(s) => s.result(),
                    None => check(&p),
                };
                #[cfg(debug_assertions)]
                debug_assert_eq!(result, check(&p), "incremental and whole checks disagree");
                trace_settled(ctx, name, t, result.is_ok());
                let e = match result {
                    Ok(q) => return Ok((p, passed(q))),
                    Err(e) => e,
                };
                let repaired = state.and_then(|s| {
                    repair_by_flips(ctx, c, s.clone(), e.clone())
                        .or_else(|| repair_by_retriangulation(ctx, c, &s, e.clone()))
                });
                if let Some((r, known)) = repaired {
                    // the repair passed the checks: relaxed if that passes too
                    if let Some((relaxed, q)) = relax(&r) {
                        return Ok((relaxed, passed(q)));
                    }
                    return Ok((r, passed(known)));
                }
                if ctx.guide {
                    // a surface to pull toward needs no checks (see FillContext::guide)
                    tracing::debug!(hole = ctx.hole.id, variant = *name, failure = %e, "guide kept as made");
                    return Ok((p, None));
                }
                failed_at.extend(loop_edge(&p, &e, ctx.hole.len()));
                reasons.push(VariantFailure {
                    name,
                    why: VariantWhy::Rejected(e),
                });
            }
            Err(FillError::Timeout) => return Err(FillError::Timeout),
            Err(e) => reasons.push(VariantFailure {
                name,
                why: VariantWhy::Failed(Box::new(e)),
            }),
        }
    }
    Err(FillError::Failed(Cause::Variants(reasons)))
}

/// The loop edge `(i, i + 1 mod k)` of the (first) triangle a check failure names,
/// when that triangle has one.
fn loop_edge(patch: &Patch, e: &CheckFailure, k: usize) -> Option<(usize, usize)> {
    let t = patch.triangles.get(*e.triangles().first()?)?;
    (0..3).find_map(|c| {
        let (a, b) = (t[c] as usize, t[(c + 1) % 3] as usize);
        (a < k && b < k && (b == (a + 1) % k || a == (b + 1) % k)).then(|| (a.min(b), a.max(b)))
    })
}

/// The first loop edge named twice.
fn repeated(edges: &[(usize, usize)]) -> Option<(usize, usize)> {
    (1..edges.len())
        .find(|&i| edges[..i].contains(&edges[i]))
        .map(|i| edges[i])
}

/// Logs how long a variant took to be made, relaxed and checked.
fn trace_settled(ctx: &FillContext, name: &str, t: std::time::Instant, passed: bool) {
    tracing::debug!(
        hole = ctx.hole.id,
        variant = name,
        passed,
        ms = t.elapsed().as_secs_f64() * 1000.0,
        "variant relaxed and checked"
    );
}

/// Rounds of [`repair_by_flips`].
const REPAIR_ROUNDS: usize = 24;

/// Local repair of a patch that fails the checks at a few triangles (a triangle
/// spanning a fold of the loop, a sliver): flips an interior edge of a named triangle,
/// keeping a flip when the patch then passes or fails at other triangles, for at most
/// [`REPAIR_ROUNDS`] rounds. Only connectivity changes; no vertex moves. `None` when
/// the patch still fails.
fn repair_by_flips(
    ctx: &FillContext,
    checker: &Checker,
    mut state: PatchChecks,
    mut err: CheckFailure,
) -> Option<(Patch, PatchQuality)> {
    let _ = checker; // the whole check, to compare with in debug builds
    let mut tried: HashSet<(u32, u32)> = HashSet::default();
    // flips move no vertex, and a trial re-tests only its two new triangles
    for _ in 0..REPAIR_ROUNDS {
        if ctx.deadline.check().is_err() {
            return None;
        }
        let bad = err.triangles();
        if bad.is_empty() {
            return None;
        }
        let patch = state.patch();
        let mut owner: HashMap<(u32, u32), usize> = HashMap::default();
        for (t, tri) in patch.triangles.iter().enumerate() {
            for c in 0..3 {
                owner.insert((tri[c], tri[(c + 1) % 3]), t);
            }
        }
        let mut kept = None;
        'search: for &t in &bad {
            let Some(&tri) = patch.triangles.get(t) else {
                continue;
            };
            for c in 0..3 {
                let (a, b, cc) = (tri[c], tri[(c + 1) % 3], tri[(c + 2) % 3]);
                let Some(&u) = owner.get(&(b, a)) else {
                    continue;
                };
                let other = patch.triangles[u];
                let Some(&d) = other.iter().find(|&&x| x != a && x != b) else {
                    continue;
                };
                if cc == d || owner.contains_key(&(cc, d)) || owner.contains_key(&(d, cc)) {
                    continue;
                }
                if !tried.insert((a.min(b), a.max(b))) {
                    continue;
                }
                let (change, q, result) = state.trial(&[t, u], &[[a, d, cc], [b, cc, d]]);
                #[cfg(debug_assertions)]
                debug_assert_eq!(
                    result,
                    checker.check_patch(ctx.mesh, &ctx.hole.vertices, &q, &ctx.policy.checks),
                    "incremental and whole checks disagree on a flip"
                );
                match result {
                    Ok(quality) => return Some((q, quality)),
                    Err(e2) => {
                        let named = e2.triangles();
                        // progress: the flipped pair is no longer what fails
                        if !named.is_empty() && !named.iter().any(|x| *x == t || *x == u) {
                            kept = Some((change, e2));
                            break 'search;
                        }
                    }
                }
            }
        }
        let (change, e2) = kept?;
        if !state.apply(change) {
            return None;
        }
        err = e2;
    }
    None
}

/// Rounds of [`repair_by_retriangulation`] (each one grows the region by a ring).
const RETRIANGULATE_ROUNDS: usize = 6;

/// Local repair of a patch whose failure flips cannot mend (a triangle that jumps
/// across a fold of the loop): the triangles around the named ones (those sharing a
/// vertex with them) are removed, their interior new vertices dropped, and the small
/// loop left is closed by the minimum-area triangulation in 3-D (no projection, so a
/// folded boundary is closed along its fold). The region grows by one ring per round
/// while the patch fails there. `None` when no round passes the checks.
fn repair_by_retriangulation(
    ctx: &FillContext,
    checker: &Checker,
    state: &PatchChecks,
    err: CheckFailure,
) -> Option<(Patch, PatchQuality)> {
    use super::triangulate::{self, forbidden_chords};
    let _ = checker; // the whole check, to compare with in debug builds
    let patch = state.patch();
    let k = ctx.hole.len();
    let seeds = err.triangles();
    if seeds.is_empty() {
        return None;
    }
    let mesh_chords = forbidden_chords(ctx.mesh, &ctx.hole.vertices);
    let boundary = ctx.boundary_positions();
    let pos_of = |p: &Patch, i: u32| {
        let i = i as usize;
        if i < k {
            boundary[i]
        } else {
            p.new_vertices[i - k]
        }
    };
    let mut region: HashSet<usize> = seeds.iter().copied().collect();
    for _ in 0..RETRIANGULATE_ROUNDS {
        if ctx.deadline.check().is_err() {
            return None;
        }
        // grow by the triangles sharing a vertex with the region
        let verts: HashSet<u32> = region
            .iter()
            .filter_map(|&t| patch.triangles.get(t))
            .flat_map(|t| t.iter().copied())
            .collect();
        for (t, tri) in patch.triangles.iter().enumerate() {
            if tri.iter().any(|v| verts.contains(v)) {
                region.insert(t);
            }
        }
        if region.len() == patch.triangles.len() && k > 3 {
            // the whole patch: that is no longer a local repair
            return None;
        }
        // the region's boundary, as directed edges of its triangles
        let inside: HashSet<(u32, u32)> = region
            .iter()
            .flat_map(|&t| {
                let tri = patch.triangles[t];
                (0..3).map(move |c| (tri[c], tri[(c + 1) % 3]))
            })
            .collect();
        let mut next: HashMap<u32, u32> = HashMap::default();
        let mut simple = true;
        for &(a, b) in &inside {
            if !inside.contains(&(b, a)) && next.insert(a, b).is_some() {
                simple = false;
            }
        }
        if !simple || next.len() < 3 {
            continue;
        }
        let start = *next.keys().min()?;
        let mut ring = vec![start];
        let mut v = next[&start];
        while v != start {
            if ring.len() > next.len() {
                break;
            }
            ring.push(v);
            v = *next.get(&v)?;
        }
        if ring.len() != next.len() {
            continue;
        }
        // existing edges outside the region, and mesh chords between loop vertices
        let mut outside_edges: HashSet<(u32, u32)> = HashSet::default();
        for (t, tri) in patch.triangles.iter().enumerate() {
            if !region.contains(&t) {
                for c in 0..3 {
                    let (a, b) = (tri[c], tri[(c + 1) % 3]);
                    outside_edges.insert((a.min(b), a.max(b)));
                }
            }
        }
        let n = ring.len();
        let mut forbidden = HashSet::default();
        for i in 0..n {
            for j in i + 2..n {
                if (i, j) == (0, n - 1) {
                    continue;
                }
                let (a, b) = (ring[i].min(ring[j]), ring[i].max(ring[j]));
                if outside_edges.contains(&(a, b))
                    || ((b as usize) < k && mesh_chords.contains(&(a, b)))
                {
                    forbidden.insert((i as u32, j as u32));
                }
            }
        }
        let pts: Vec<glam::DVec3> = ring.iter().map(|&v| pos_of(patch, v)).collect();
        let outside_normals = vec![None; n];
        let input = triangulate::LoopInput::with_policy(
            &pts,
            &forbidden,
            &outside_normals,
            ctx.policy,
            ctx.deadline,
        );
        let Ok(fill) = triangulate::triangulate(&input) else {
            continue;
        };
        // the new patch: triangles outside the region plus the fill; drop unused vertices
        let mut tris: Vec<[u32; 3]> = patch
            .triangles
            .iter()
            .enumerate()
            .filter(|(t, _)| !region.contains(t))
            .map(|(_, t)| *t)
            .collect();
        tris.extend(fill.iter().map(|t| t.map(|i| ring[i as usize])));
        let mut used = vec![false; patch.new_vertices.len()];
        for t in &tris {
            for &v in t {
                if v as usize >= k {
                    used[v as usize - k] = true;
                }
            }
        }
        let mut remap = vec![u32::MAX; patch.new_vertices.len()];
        let mut new_vertices = Vec::new();
        for (j, &u) in used.iter().enumerate() {
            if u {
                remap[j] = (k + new_vertices.len()) as u32;
                new_vertices.push(patch.new_vertices[j]);
            }
        }
        let triangles = tris
            .iter()
            .map(|t| {
                t.map(|v| {
                    if (v as usize) < k {
                        v
                    } else {
                        remap[v as usize - k]
                    }
                })
            })
            .collect();
        let q = Patch {
            new_vertices,
            triangles,
        };
        // the triangles kept were tested already: only the fill's are tested here
        let mut removed: Vec<usize> = region.iter().copied().collect();
        removed.sort_unstable();
        let added: Vec<[u32; 3]> = fill.iter().map(|t| t.map(|i| ring[i as usize])).collect();
        let result = state.replaced(&removed, &added, &q);
        #[cfg(debug_assertions)]
        debug_assert_eq!(
            result,
            checker.check_patch(ctx.mesh, &ctx.hole.vertices, &q, &ctx.policy.checks),
            "incremental and whole checks disagree on a re-triangulation"
        );
        if let Ok(quality) = result {
            return Some((q, quality));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fill::kit::relax::tangential_relax;
    use crate::mesh::Mesh;
    use crate::patch::Hole;
    use crate::testutil::{cut_faces, grid};

    /// A patch made from the kit as a method makes one: the minimum-area
    /// triangulation of the loop, refined to the loop's mean edge length, faired.
    fn kit_fill(ctx: &FillContext) -> Result<Patch, FillError> {
        use crate::fill::kit::{fair, refine, triangulate};
        let pts = ctx.boundary_positions();
        let k = pts.len();
        let forbidden = triangulate::forbidden_chords(ctx.mesh, &ctx.hole.vertices);
        let outside = triangulate::outside_normals(ctx.mesh, &ctx.hole.vertices);
        let tris = triangulate::triangulate(&triangulate::LoopInput::with_policy(
            &pts,
            &forbidden,
            &outside,
            ctx.policy,
            ctx.deadline,
        ))?;
        let scale = vec![ctx.hole.mean_edge_length; k];
        let mut r = refine::Refiner::new(pts, scale, tris, &forbidden);
        r.refine(ctx.policy.refine.density, &ctx.deadline)?;
        let mut patch = Patch {
            new_vertices: r.pos[k..].to_vec(),
            triangles: r.tris.clone(),
        };
        fair::fair_patch(ctx.mesh, ctx.hole, &mut patch, &ctx.policy.fair)?;
        Ok(patch)
    }

    /// A flat grid with a round hole in the middle, and that hole's loop.
    /// A flat grid with a round hole, and that hole under `policy`.
    fn grid_hole(policy: &Policy) -> (Mesh, Hole) {
        let raw = cut_faces(grid(16, -1.0, 1.0, |_, _| 0.0), |c| c.length() <= 0.55);
        let (mesh, _) = Mesh::from_raw(&raw);
        let lp = mesh
            .topo
            .boundary_loops()
            .into_iter()
            .min_by(|a, b| a.len().cmp(&b.len()))
            .unwrap();
        let hole = Hole::new(0, &mesh, lp, policy);
        (mesh, hole)
    }

    /// A failure at a triangle on a loop edge names that edge (also the closing edge
    /// `(k - 1, 0)`); one at an inner triangle or at none names nothing; the variants
    /// stop at the second failure on one edge.
    #[test]
    fn failures_on_the_same_loop_edge_are_found() {
        use crate::check::{Degeneracy, Meets};
        let patch = Patch {
            new_vertices: vec![glam::DVec3::ZERO; 2],
            triangles: vec![[1, 2, 4], [4, 3, 0], [4, 5, 2], [0, 4, 1]],
        };
        let at = |triangle| CheckFailure::Degenerate {
            triangle,
            why: Degeneracy::SmallAngle(0.1),
        };
        assert_eq!(loop_edge(&patch, &at(0), 4), Some((1, 2)));
        assert_eq!(loop_edge(&patch, &at(1), 4), Some((0, 3)));
        assert_eq!(loop_edge(&patch, &at(2), 4), None);
        assert_eq!(loop_edge(&patch, &at(3), 4), Some((0, 1)));
        assert_eq!(loop_edge(&patch, &at(9), 4), None);
        let crossing = CheckFailure::SelfIntersection {
            triangle: 3,
            meets: Meets::MeshFace(7),
        };
        assert_eq!(loop_edge(&patch, &crossing, 4), Some((0, 1)));
        assert_eq!(repeated(&[(0, 1), (1, 2)]), None);
        assert_eq!(repeated(&[(0, 1), (1, 2), (0, 1)]), Some((0, 1)));
        assert_eq!(repeated(&[]), None);
    }

    /// A hole in a flat grid, filled from the kit ([`kit_fill`]), then one new vertex
    /// is moved outside the hole (onto the mesh, so its triangles overlap mesh faces):
    /// the flips cannot mend that, the re-triangulation of the region around it does,
    /// and the repaired patch passes every check.
    #[test]
    fn a_patch_overlapping_the_mesh_is_repaired_locally() {
        let policy = Policy::default();
        let (mesh, hole) = grid_hole(&policy);
        let ctx = FillContext::new(&mesh, &hole, &policy);
        let mut patch = kit_fill(&ctx).unwrap();
        let checker = Checker::new(&mesh);
        checker
            .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
            .unwrap();
        // the new vertex nearest the boundary, pushed out over the mesh
        let j = (0..patch.new_vertices.len())
            .max_by(|&a, &b| {
                patch.new_vertices[a]
                    .length()
                    .total_cmp(&patch.new_vertices[b].length())
            })
            .unwrap();
        let p = patch.new_vertices[j];
        patch.new_vertices[j] = p.normalize() * 0.75;
        let err = checker
            .check_patch(&mesh, &hole.vertices, &patch, &policy.checks)
            .unwrap_err();
        assert!(!err.triangles().is_empty(), "{err}");
        let near = checker.faces_near(&mesh, &hole.vertices, &patch);
        let state =
            PatchChecks::new(&mesh, &hole.vertices, patch.clone(), &policy.checks, &near).unwrap();
        assert_eq!(state.result(), Err(err.clone()));
        let (fixed, q) = repair_by_flips(&ctx, &checker, state.clone(), err.clone())
            .or_else(|| repair_by_retriangulation(&ctx, &checker, &state, err))
            .expect("repaired");
        assert_eq!(
            q,
            checker
                .check_patch(&mesh, &hole.vertices, &fixed, &policy.checks)
                .unwrap()
        );
        assert!(fixed.new_vertices.len() < patch.new_vertices.len());
        assert!(fixed.new_vertices.iter().all(|p| p.z.abs() < 1e-12));
        // a patch that passes is returned by the wrapper relaxed as the dispatcher
        // would, with the quality of its checks
        let variants = [("policy", policy.clone()), ("again", policy.clone())];
        let mut good = kit_fill(&ctx).unwrap();
        tangential_relax(
            &mesh,
            &hole,
            &mut good,
            policy.fair.tangential_relax,
            RELAX_STEP,
        );
        let (got, q) = first_passing_at(&ctx, &variants, |_, c| kit_fill(c)).unwrap();
        assert_eq!(got, good);
        assert_eq!(
            q,
            Some(Passed {
                quality: checker
                    .check_patch(&mesh, &hole.vertices, &good, &policy.checks)
                    .unwrap(),
                variant: None,
            })
        );
    }

    /// The variant that made a passing patch is named when it is not the first.
    #[test]
    fn a_later_variant_that_passes_is_named() {
        let policy = Policy::default();
        let (mesh, hole) = grid_hole(&policy);
        let ctx = FillContext::new(&mesh, &hole, &policy);
        let variants = [("policy", policy.clone()), ("again", policy.clone())];
        let run = |at: usize, c: &FillContext| {
            if at == 0 {
                Err(FillError::stuck("the first variant fails"))
            } else {
                kit_fill(c)
            }
        };
        let (_, passed) = first_passing_at(&ctx, &variants, run).unwrap();
        assert_eq!(passed.map(|p| p.variant), Some(Some("again")));
        let (_, passed) = first_passing_at(&ctx, &variants, |_, c| kit_fill(c)).unwrap();
        assert_eq!(
            passed.map(|p| p.variant),
            Some(None),
            "the first is not named"
        );
    }

    /// A guide ([`FillContext::guide`]) keeps its first variant as made where that
    /// fails the checks; the later variants are not run. Elsewhere both are run and
    /// both rejected.
    #[test]
    fn a_guide_keeps_its_first_variant_as_made_when_it_fails_the_checks() {
        let loose = Policy::default();
        // no refined patch has every angle at 29.9 degrees or more
        let strict = loose
            .edit(|s| s.checks.min_angle_deg = 29.9)
            .expect("valid");
        let (mesh, hole) = grid_hole(&strict);
        let made = kit_fill(&FillContext::new(&mesh, &hole, &loose)).unwrap();
        let variants = [("policy", strict.clone()), ("again", strict.clone())];
        let calls = std::cell::Cell::new(0);
        let run = |_: usize, _: &FillContext| {
            calls.set(calls.get() + 1);
            kit_fill(&FillContext::new(&mesh, &hole, &loose))
        };
        let ctx = FillContext::new(&mesh, &hole, &strict);
        assert!(
            first_passing_at(&ctx, &variants, run).is_err(),
            "both rejected"
        );
        assert_eq!(calls.get(), 2);
        calls.set(0);
        let guide = FillContext {
            guide: true,
            ..FillContext::new(&mesh, &hole, &strict)
        };
        let (p, q) = first_passing_at(&guide, &variants, run).expect("kept as made");
        assert_eq!(calls.get(), 1, "the second variant is not run");
        assert_eq!(q, None, "unchecked");
        assert_eq!(p, made, "as made, not relaxed");
    }

    /// A caller's finishing step ([`FillContext::finish`]) gets each made patch: what
    /// it returns is the result, unrelaxed by the method; where it returns `None` the
    /// made patch is relaxed and checked as without it.
    #[test]
    fn a_finished_patch_is_the_result_and_is_not_relaxed_again() {
        let policy = Policy::default();
        let (mesh, hole) = grid_hole(&policy);
        let variants = [("policy", policy.clone()), ("again", policy.clone())];
        let plain = FillContext::new(&mesh, &hole, &policy);
        let made = kit_fill(&plain).unwrap();
        let (relaxed, q) = first_passing_at(&plain, &variants, |_, c| kit_fill(c)).unwrap();
        assert_ne!(relaxed, made, "relaxed by the method");
        // the finish lifts every new vertex a little and reports a quality of its own
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let mut lifted = made.clone();
        for p in &mut lifted.new_vertices {
            p.z += 0.01;
        }
        let own = PatchQuality {
            min_angle_deg: 1.0,
            ..q.clone().unwrap().quality
        };
        let finish = |p: &Patch| {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            assert_eq!(*p, made, "the patch as made");
            Some((lifted.clone(), own.clone()))
        };
        let ctx = FillContext {
            finish: Some(&finish),
            ..FillContext::new(&mesh, &hole, &policy)
        };
        let (p, passed) = first_passing_at(&ctx, &variants, |_, c| kit_fill(c)).unwrap();
        assert_eq!(p, lifted, "the finished patch, not relaxed");
        assert_eq!(passed.map(|q| q.quality), Some(own));
        assert_eq!(calls.into_inner(), 1, "the first variant's patch only");
        // a finish that does not apply leaves the method's own relaxation
        let none = |_: &Patch| None;
        let ctx = FillContext {
            finish: Some(&none),
            ..FillContext::new(&mesh, &hole, &policy)
        };
        let (p, passed) = first_passing_at(&ctx, &variants, |_, c| kit_fill(c)).unwrap();
        assert_eq!(p, relaxed);
        assert_eq!(passed, q);
    }
}
