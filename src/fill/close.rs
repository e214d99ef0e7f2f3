//! `close`: the last method of every default list. It closes a loop with triangles
//! over the loop's own vertices (no new vertex), so that a hole whose front diverges
//! or gets stuck, or whose smooth patch meets a fold of the surrounding scan, does not
//! end the chain in "failed".
//!
//! Not from a paper. The checks are relaxed only as far as a real scan needs: the
//! smallest-angle rule (`checks.min_angle_deg`) is off, since the loop's own
//! vertices may only allow slivers; zero-area triangles, a patch that is not a disk
//! closing the loop (non-manifold edges), and intersections with the mesh or with
//! itself are still rejected (`checks.self_intersection` as the policy says).
//!
//! Variants, in order; the first whose patch passes is returned:
//! 1. minimum-area triangulation by dynamic programming ([`triangulate`]);
//! 2. the same with Liepa's weight (smallest largest dihedral angle first, including
//!    the faces around the loop): it follows a folded rim instead of cutting across;
//! 3. ear clipping of the loop projected on its best-fit (Newell) plane, the ear with
//!    the largest smallest angle first, when the projection is a simple polygon: a
//!    flat cap with no fold.

use super::kit::triangulate::{self, forbidden_chords, outside_normals, LoopInput};
use super::kit::{FillContext, FillError};
use crate::check::{CheckFailure, Checker};
use crate::fill::kit::retry::Passed;
use crate::geometry::measure;
use crate::patch::Patch;
use crate::policy::{Checks, TriangulationWeight};
use crate::report::PatchQuality;
use glam::{DVec2, DVec3};

/// The checks of this method: the policy's, with the smallest-angle rule off.
pub fn relaxed_checks(policy: &Checks) -> Checks {
    Checks {
        min_angle_deg: 0.0,
        ..policy.clone()
    }
}

/// Closes the hole; the patch is checked (with [`relaxed_checks`]) and returned with
/// its quality.
pub fn fill_checked(ctx: &FillContext) -> Result<(Patch, Option<Passed>), FillError> {
    let k = ctx.hole.len();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "a loop of {k} vertices cannot be closed"
        )));
    }
    let own;
    let checker = match ctx.checker {
        Some(c) => c,
        None => {
            own = Checker::new(ctx.mesh);
            &own
        }
    };
    let checks = relaxed_checks(&ctx.policy.checks);
    let pts = ctx.boundary_positions();
    let forbidden = forbidden_chords(ctx.mesh, &ctx.hole.vertices);
    let normals = outside_normals(ctx.mesh, &ctx.hole.vertices);
    let mut last: Option<CheckFailure> = None;
    let mut try_patch = |tris: Vec<[u32; 3]>| -> Option<(Patch, PatchQuality)> {
        let patch = Patch {
            new_vertices: Vec::new(),
            triangles: tris,
        };
        match checker.check_patch(ctx.mesh, &ctx.hole.vertices, &patch, &checks) {
            Ok(q) => Some((patch, q)),
            Err(e) => {
                last = Some(e);
                None
            }
        }
    };
    for weight in [TriangulationWeight::Area, TriangulationWeight::DihedralArea] {
        ctx.deadline.check()?;
        let inp = LoopInput {
            pts: &pts,
            forbidden: &forbidden,
            outside_normals: &normals,
            weight,
            min_angle: 0.0,
            restricted_above: ctx.policy.refine.restricted_search_above,
            delaunay: ctx.policy.refine.delaunay_first(),
            deadline: ctx.deadline,
        };
        if let Ok(tris) = triangulate::triangulate(&inp) {
            if let Some((p, quality)) = try_patch(tris) {
                let variant =
                    (weight != TriangulationWeight::Area).then_some("dihedral-area weight");
                return Ok((p, Some(Passed { quality, variant })));
            }
        }
    }
    ctx.deadline.check()?;
    if let Some(tris) = ear_clip(&pts) {
        let uses_forbidden = tris.iter().any(|t| {
            (0..3).any(|c| {
                let (a, b) = (t[c], t[(c + 1) % 3]);
                forbidden.contains(&(a.min(b), a.max(b)))
            })
        });
        if !uses_forbidden {
            if let Some((p, quality)) = try_patch(tris) {
                let variant = Some("ear clipping");
                return Ok((p, Some(Passed { quality, variant })));
            }
        }
    }
    Err(match last {
        Some(e) => FillError::stuck(format!("no triangulation of the loop passes: {e}")),
        None => FillError::stuck("no triangulation of the loop found"),
    })
}

/// Ear clipping of the loop projected on its Newell plane: `None` when the projection
/// is not a simple polygon with the loop's orientation (an ear could then cross the
/// loop). Triangles are loop indices, oriented like the hole.
pub fn ear_clip(pts: &[DVec3]) -> Option<Vec<[u32; 3]>> {
    let k = pts.len();
    if k < 3 {
        return None;
    }
    let n = measure::newell_normal(pts).normalize_or_zero();
    if n == DVec3::ZERO {
        return None;
    }
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    let p: Vec<DVec2> = pts.iter().map(|q| DVec2::new(q.dot(u), q.dot(v))).collect();
    let cross = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    // the loop runs counter-clockwise around `n` (the Newell normal follows it)
    if !simple(&p) {
        return None;
    }
    let mut idx: Vec<usize> = (0..k).collect();
    let mut tris = Vec::with_capacity(k - 2);
    // the best ear by smallest angle for loops up to this size, else the first ear
    const BEST_EAR_MAX: usize = 400;
    while idx.len() > 3 {
        let m = idx.len();
        let mut best: Option<(f64, usize)> = None;
        for i in 0..m {
            let (a, b, c) = (idx[(i + m - 1) % m], idx[i], idx[(i + 1) % m]);
            if cross(p[a], p[b], p[c]) <= 0.0 {
                continue; // reflex or flat corner
            }
            let inside = idx.iter().any(|&j| {
                j != a
                    && j != b
                    && j != c
                    && cross(p[a], p[b], p[j]) >= 0.0
                    && cross(p[b], p[c], p[j]) >= 0.0
                    && cross(p[c], p[a], p[j]) >= 0.0
            });
            if inside {
                continue;
            }
            let score = measure::smallest_angle(pts[a], pts[b], pts[c]);
            if best.is_none_or(|(s, _)| score > s) {
                best = Some((score, i));
            }
            if m > BEST_EAR_MAX {
                break;
            }
        }
        let (_, i) = best?;
        let (a, b, c) = (idx[(i + m - 1) % m], idx[i], idx[(i + 1) % m]);
        tris.push([a as u32, b as u32, c as u32]);
        idx.remove(i);
    }
    tris.push([idx[0] as u32, idx[1] as u32, idx[2] as u32]);
    Some(tris)
}

/// True when no two non-adjacent edges of the closed polygon meet (O(k²)).
fn simple(p: &[DVec2]) -> bool {
    let k = p.len();
    let orient = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
    let meet = |a: DVec2, b: DVec2, c: DVec2, d: DVec2| {
        let (o1, o2) = (orient(a, b, c), orient(a, b, d));
        let (o3, o4) = (orient(c, d, a), orient(c, d, b));
        if o1 == 0.0 && o2 == 0.0 {
            // collinear: they meet only if their extents overlap
            return a.min(b).cmple(c.max(d)).all() && c.min(d).cmple(a.max(b)).all();
        }
        (o1 * o2 <= 0.0) && (o3 * o4 <= 0.0)
    };
    if k > 3000 {
        return false;
    }
    for i in 0..k {
        for j in i + 2..k {
            if i == 0 && j == k - 1 {
                continue;
            }
            if meet(p[i], p[(i + 1) % k], p[j], p[(j + 1) % k]) {
                return false;
            }
        }
    }
    true
}

/// Quality of a patch over the loop alone (for tests).
#[cfg(test)]
fn patch_quality(pts: &[DVec3], patch: &Patch) -> PatchQuality {
    crate::check::quality(pts, pts.len(), patch)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fill::kit::Deadline;
    use crate::mesh::Mesh;
    use crate::patch::Hole;
    use crate::policy::Policy;

    /// A flat grid with a hole whose rim has a folded sliver: the hole's loop is an
    /// L-shaped notch, and one rim vertex is lifted so that the loop is far from flat.
    #[test]
    fn closes_a_notched_loop_that_others_find_hard() {
        use crate::testutil::{cells_removed, unit_grid};
        // remove cells (1..5, 1..3) and (1..3, 3..5): an L-shaped hole
        let mut raw = cells_removed(unit_grid(6), |i, j| {
            (1..5).contains(&i) && (1..5).contains(&j) && (j < 3 || i < 3)
        });
        raw.positions[4 * 7 + 4].z = 0.6; // the reflex corner of the L, lifted
        let (mesh, _) = Mesh::from_raw(&raw);
        mesh.validate().unwrap();
        let policy = Policy::default();
        let lp = mesh
            .topo
            .boundary_loops()
            .into_iter()
            .min_by_key(|l| l.len())
            .unwrap();
        let hole = Hole::new(0, &mesh, lp, &policy);
        let checker = Checker::new(&mesh);
        let ctx = FillContext {
            mesh: &mesh,
            hole: &hole,
            policy: &policy,
            deadline: Deadline::none(),
            checker: Some(&checker),
            rim_bound: false,
            guide: false,
            finish: None,
        };
        let (patch, q) = fill_checked(&ctx).unwrap();
        assert!(patch.new_vertices.is_empty());
        assert_eq!(patch.triangles.len(), hole.len() - 2);
        assert!(q.is_some());
        let mut m = mesh.clone();
        crate::patch::apply_patch(&mut m, &hole, &patch).unwrap();
        m.validate().unwrap();
        assert_eq!(m.topo.boundary_loops().len(), 1);
        let pts: Vec<DVec3> = hole.vertices.iter().map(|&v| mesh.pos(v)).collect();
        assert!(patch_quality(&pts, &patch).min_angle_deg > 0.0);
    }

    #[test]
    fn ear_clipping_triangulates_a_simple_polygon_and_refuses_a_crossing_one() {
        // a comb: counter-clockwise, with two notches
        let pts: Vec<DVec3> = [
            (0., 0.),
            (6., 0.),
            (6., 3.),
            (5., 3.),
            (5., 1.),
            (4., 1.),
            (4., 3.),
            (2., 3.),
            (2., 1.),
            (1., 1.),
            (1., 3.),
            (0., 3.),
        ]
        .iter()
        .map(|&(x, y)| DVec3::new(x, y, 0.0))
        .collect();
        let t = ear_clip(&pts).unwrap();
        assert_eq!(t.len(), pts.len() - 2);
        let area: f64 = t
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| pts[i as usize]);
                (b - a).cross(c - a).z / 2.0
            })
            .sum();
        // every triangle counter-clockwise, total = polygon area (18 - two 1 x 2 notches)
        assert!((area - 14.0).abs() < 1e-9, "{area}");
        let bowtie: Vec<DVec3> = [(0., 0.), (1., 1.), (1., 0.), (0., 1.)]
            .iter()
            .map(|&(x, y)| DVec3::new(x, y, 0.0))
            .collect();
        assert!(ear_clip(&bowtie).is_none());
    }
}
