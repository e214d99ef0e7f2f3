//! Step 6 of HPDE: projection onto the fitted plane (or the two unfolded planes),
//! constrained Delaunay triangulation with `spade`, lifting (paper 000 §4.5).

use super::predict::{fit_plane, Predicted, Segmentation};
use crate::fasthash::HashMap;
use crate::fill::kit::{Deadline, FillError};
use crate::geometry::bvh::{closest_triangle, tri_box, Bvh};
use crate::geometry::measure::{newell_normal, point_in_polygon};
use crate::geometry::predicates::{self, orient2, p2, P2};
use glam::{DVec2, DVec3};
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

/// Projection of 3D points to the triangulation plane.
#[derive(Clone, Debug)]
pub struct Projection {
    kind: Kind,
    /// The segmentation of a folded projection.
    folded: Option<Segmentation>,
    /// -1 mirrors the second coordinate so that the loop is counter-clockwise.
    mirror: f64,
    /// The projected loop (counter-clockwise, simple).
    pub loop2d: Vec<DVec2>,
}

#[derive(Clone, Debug)]
enum Kind {
    /// Loop on a circle; see [`Plan::Disk`].
    Disk,
    Single {
        origin: DVec3,
        u: DVec3,
        v: DVec3,
    },
    Folded {
        p0: DVec3,
        axis: DVec3,
        w1: DVec3,
        w2: DVec3,
    },
}

/// A candidate projection.
#[derive(Clone, Copy, Debug)]
enum Plan<'a> {
    /// The PCA plane of the loop (the paper's).
    Pca,
    /// The plane normal to the loop's Newell (area) normal.
    Newell,
    /// The plane normal to the sum of the loop's vertex normals.
    Normals,
    /// The two fitted planes of a segmentation, unfolded.
    Folded(&'a Segmentation),
    /// The loop on a circle by arc length, predicted points on their pairs' chords.
    Disk,
}

impl Plan<'_> {
    fn name(&self) -> &'static str {
        match self {
            Plan::Pca => "the fitted (PCA) plane",
            Plan::Newell => "the Newell plane",
            Plan::Normals => "the vertex-normal plane",
            Plan::Folded(_) => "the two unfolded planes",
            Plan::Disk => "the disk",
        }
    }
}

impl Projection {
    /// The first candidate projection on which the loop is a simple polygon: the
    /// paper's choice first (the two unfolded planes when `segmented`, else the PCA
    /// plane), then the Newell plane, the vertex-normal plane and, when the
    /// segmentation test found two planes, their unfolding. Fails, naming every
    /// candidate's problem, when none is simple.
    pub fn choose(
        bp: &[DVec3],
        normals: &[DVec3],
        split: Option<&Segmentation>,
        segmented: bool,
        disk: bool,
    ) -> Result<Projection, FillError> {
        let mut plans = Vec::new();
        if let (Some(s), true) = (split, segmented) {
            plans.push(Plan::Folded(s));
        }
        plans.extend([Plan::Pca, Plan::Newell, Plan::Normals]);
        if let (Some(s), false) = (split, segmented) {
            plans.push(Plan::Folded(s));
        }
        if disk {
            plans.push(Plan::Disk);
        }
        let mut why = Vec::new();
        for plan in plans {
            match Projection::new(bp, normals, plan) {
                Ok(p) => return Ok(p),
                Err(e) => why.push(format!("{}: {e}", plan.name())),
            }
        }
        Err(FillError::bad_loop(format!(
            "hpde: the loop does not project to a simple polygon on any plane ({})",
            why.join("; ")
        )))
    }

    /// 2D position of a predicted point.
    pub fn project_predicted(&self, p: &Predicted) -> DVec2 {
        match (&self.kind, &self.folded) {
            (Kind::Disk, _) => {
                let (a, b) = (self.loop2d[p.pair.0], self.loop2d[p.pair.1]);
                a + (b - a) * p.frac
            }
            (_, Some(s)) => self.project(p.pos, second_plane(s, p)),
            _ => self.project(p.pos, false),
        }
    }

    /// The projection of the loop `bp` by `plan`; `Err` with the reason when the
    /// projected loop is not a simple polygon.
    fn new(bp: &[DVec3], normals: &[DVec3], plan: Plan) -> Result<Projection, String> {
        let single = |n: DVec3| -> Result<Kind, String> {
            let n = n.try_normalize().ok_or("undefined normal")?;
            let origin = bp.iter().copied().sum::<DVec3>() / bp.len().max(1) as f64;
            let u = n.any_orthonormal_vector();
            Ok(Kind::Single {
                origin,
                u,
                v: n.cross(u),
            })
        };
        let seg = match plan {
            Plan::Folded(s) => Some(s),
            _ => None,
        };
        let kind = match plan {
            Plan::Disk => Kind::Disk,
            Plan::Newell => single(newell_normal(bp))?,
            Plan::Normals => single(normals.iter().copied().sum::<DVec3>())?,
            Plan::Pca => {
                let pl = fit_plane(bp, newell_normal(bp));
                let u = pl.normal.any_orthonormal_vector();
                Kind::Single {
                    origin: pl.center,
                    u,
                    v: pl.normal.cross(u),
                }
            }
            Plan::Folded(s) => {
                let (n1, n2) = (s.first.normal, s.second.normal);
                let dir = n1.cross(n2);
                let (d1, d2) = (n1.dot(s.first.center), n2.dot(s.second.center));
                let p0 = (n2.cross(dir) * d1 + dir.cross(n1) * d2) / dir.length_squared();
                let axis = dir.normalize();
                let mut w1 = n1.cross(axis);
                let mut w2 = n2.cross(axis);
                // the first plane's arc on the positive side, the second's on the negative
                let side = |w: DVec3, second: bool| -> f64 {
                    bp.iter()
                        .enumerate()
                        .filter(|(i, _)| s.in_second(*i) == second)
                        .map(|(_, p)| w.dot(*p - p0))
                        .sum()
                };
                if side(w1, false) < 0.0 {
                    w1 = -w1;
                }
                if side(w2, true) > 0.0 {
                    w2 = -w2;
                }
                Kind::Folded { p0, axis, w1, w2 }
            }
        };
        let mut proj = Projection {
            kind,
            folded: seg.cloned(),
            mirror: 1.0,
            loop2d: Vec::new(),
        };
        let mut l: Vec<DVec2> = if let Kind::Disk = proj.kind {
            circle(bp)
        } else {
            bp.iter()
                .enumerate()
                .map(|(i, &p)| proj.project(p, seg.is_some_and(|s| s.in_second(i))))
                .collect()
        };
        if signed_area(&l) < 0.0 {
            proj.mirror = -1.0;
            for p in l.iter_mut() {
                p.y = -p.y;
            }
        }
        if let Some(why) = not_simple(&l) {
            return Err(why);
        }
        proj.loop2d = l;
        Ok(proj)
    }

    /// Projects `p`; `second` selects the second plane of a folded projection.
    pub fn project(&self, p: DVec3, second: bool) -> DVec2 {
        let q = match &self.kind {
            Kind::Disk => DVec2::ZERO,
            Kind::Single { origin, u, v } => DVec2::new(u.dot(p - *origin), v.dot(p - *origin)),
            Kind::Folded { p0, axis, w1, w2 } => {
                let d = p - *p0;
                let w = if second { w2 } else { w1 };
                DVec2::new(axis.dot(d), w.dot(d))
            }
        };
        DVec2::new(q.x, q.y * self.mirror)
    }
}

/// The loop on a circle, counter-clockwise by arc length, radius perimeter / 2π.
fn circle(bp: &[DVec3]) -> Vec<DVec2> {
    let k = bp.len();
    let lens: Vec<f64> = (0..k).map(|i| (bp[(i + 1) % k] - bp[i]).length()).collect();
    let per: f64 = lens.iter().sum();
    let r = per / (2.0 * std::f64::consts::PI);
    let mut acc = 0.0;
    let mut out = Vec::with_capacity(k);
    for len in &lens {
        let a = acc / per * 2.0 * std::f64::consts::PI;
        out.push(DVec2::new(a.cos(), a.sin()) * r);
        acc += len;
    }
    out
}

/// The loop on a circle (by arc length) and each predicted point where its closest
/// point on `surface` lands when each triangle of `surface` (loop indices, a
/// triangulation of the loop without interior vertices) is mapped affinely onto the
/// triangle of its corners on the circle. A triangulation of a polygon maps onto one of
/// the convex circle polygon, so the map is one-to-one, and points near each other on
/// the surface stay near each other in the plane, however the loop winds in space.
/// With `on_surface`, each point is lifted to its closest point on the surface instead
/// of its predicted position. The search is points x triangles, so `deadline` is
/// checked as it goes.
pub fn over_surface(
    bp: &[DVec3],
    surface: &[[u32; 3]],
    pts: &[Predicted],
    on_surface: bool,
    deadline: &Deadline,
) -> Result<OverSurface, FillError> {
    let l = circle(bp);
    if let Some(why) = not_simple(&l) {
        return Err(FillError::bad_loop(format!(
            "hpde: the loop does not map to a circle ({why})"
        )));
    }
    let corner = |t: &[u32; 3], c: usize| t[c] as usize;
    if surface
        .iter()
        .any(|t| (0..3).any(|c| corner(t, c) >= bp.len()))
    {
        return Err(FillError::bad_loop(
            "hpde: the loop's triangulation names a vertex outside the loop",
        ));
    }
    // the closest triangle of each point, found in a tree over the triangles (the
    // same one a scan finds: ties to the lowest index), searched first within one
    // mean loop edge
    let tris: Vec<[DVec3; 3]> = surface
        .iter()
        .map(|t| [0, 1, 2].map(|c| bp[corner(t, c)]))
        .collect();
    let tree = Bvh::build(tris.len(), |i| tri_box(&tris[i]));
    let k = bp.len();
    let reach = (0..k).map(|i| bp[i].distance(bp[(i + 1) % k])).sum::<f64>() / k.max(1) as f64;
    let mut out = Vec::with_capacity(pts.len());
    for (i, pr) in pts.iter().enumerate() {
        if i % 256 == 255 {
            deadline.check()?;
        }
        let p = pr.pos;
        let Some((ti, q)) = closest_triangle(&tree, &tris, p, reach) else {
            continue;
        };
        let t = &surface[ti];
        let w = barycentric(q, bp[corner(t, 0)], bp[corner(t, 1)], bp[corner(t, 2)]);
        let at = l[corner(t, 0)] * w.x + l[corner(t, 1)] * w.y + l[corner(t, 2)] * w.z;
        if at.is_finite() {
            out.push((at, if on_surface { q } else { p }));
        }
    }
    Ok(OverSurface {
        loop2d: l,
        points: out,
    })
}

/// The loop and the predicted points mapped over a surface ([`over_surface`]).
#[derive(Clone, Debug)]
pub struct OverSurface {
    /// The loop on the circle.
    pub loop2d: Vec<DVec2>,
    /// Each kept point's plane position and its 3-D position.
    pub points: Vec<(DVec2, DVec3)>,
}

/// Barycentric coordinates of `q` (a point of the triangle's plane) in `abc`; the
/// centroid's for a degenerate triangle.
fn barycentric(q: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (v0, v1, v2) = (b - a, c - a, q - a);
    let (d00, d01, d11) = (v0.dot(v0), v0.dot(v1), v1.dot(v1));
    let (d20, d21) = (v2.dot(v0), v2.dot(v1));
    let den = d00 * d11 - d01 * d01;
    if !den.is_finite() || den <= 1e-12 * d00 * d11 {
        return DVec3::splat(1.0 / 3.0);
    }
    let v = ((d11 * d20 - d01 * d21) / den).clamp(0.0, 1.0);
    let w = ((d00 * d21 - d01 * d20) / den).clamp(0.0, 1.0 - v);
    DVec3::new(1.0 - v - w, v, w)
}

fn signed_area(l: &[DVec2]) -> f64 {
    let n = l.len();
    (0..n)
        .map(|i| {
            let (a, b) = (l[i], l[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        * 0.5
}

/// A plane point as the exact predicates take it.
fn pt(a: DVec2) -> P2 {
    p2(a.x, a.y)
}

fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    orient2(pt(a), pt(b), pt(c))
}

/// Closed segments `pq` and `rs` share a point.
fn segments_meet(p: DVec2, q: DVec2, r: DVec2, s: DVec2) -> bool {
    predicates::segments_meet(pt(p), pt(q), pt(r), pt(s))
}

/// Why a closed polyline is not a simple polygon, or `None`.
fn not_simple(l: &[DVec2]) -> Option<String> {
    let n = l.len();
    if n < 3 {
        return Some("fewer than 3 points".into());
    }
    if l.iter().any(|p| !p.is_finite()) {
        return Some("non-finite coordinate".into());
    }
    if signed_area(l) <= 0.0 {
        return Some("zero area".into());
    }
    for i in 0..n {
        let (a, b, c) = (l[i], l[(i + 1) % n], l[(i + 2) % n]);
        if a == b {
            return Some(format!("vertices {i} and {} coincide", (i + 1) % n));
        }
        // adjacent edges folding back onto each other
        if n > 3 && orient(a, b, c) == 0.0 && (a - b).dot(c - b) > 0.0 {
            return Some(format!("edges at vertex {} overlap", (i + 1) % n));
        }
    }
    // a bounding-box sweep over x keeps this near-linear for typical loops
    let mut order: Vec<usize> = (0..n).collect();
    let lo = |i: usize| l[i].x.min(l[(i + 1) % n].x);
    let hi = |i: usize| l[i].x.max(l[(i + 1) % n].x);
    order.sort_by(|&a, &b| lo(a).total_cmp(&lo(b)).then(a.cmp(&b)));
    let mut active: Vec<usize> = Vec::new();
    for &e in &order {
        let x = lo(e);
        active.retain(|&f| hi(f) >= x);
        for &f in &active {
            let adjacent = (e + 1) % n == f || (f + 1) % n == e;
            if adjacent {
                continue;
            }
            if segments_meet(l[e], l[(e + 1) % n], l[f], l[(f + 1) % n]) {
                return Some(format!(
                    "edges {e}-{} and {f}-{} cross",
                    (e + 1) % n,
                    (f + 1) % n
                ));
            }
        }
        active.push(e);
    }
    None
}

/// The plane of a predicted point in a folded projection: that of its pair's arc, or,
/// for a pair straddling both arcs, the nearer fitted plane.
fn second_plane(s: &Segmentation, p: &Predicted) -> bool {
    match (s.in_second(p.pair.0), s.in_second(p.pair.1)) {
        (true, true) => true,
        (false, false) => false,
        _ => {
            let d1 = s.first.normal.dot(p.pos - s.first.center).abs();
            let d2 = s.second.normal.dot(p.pos - s.second.center).abs();
            d2 < d1
        }
    }
}

fn dist_to_segment(a: DVec2, b: DVec2, q: DVec2) -> f64 {
    let ab = b - a;
    let l2 = ab.length_squared();
    let t = if l2 > 0.0 {
        ((q - a).dot(ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (a + ab * t - q).length()
}

/// The lifted triangulation: loop vertices first, then the kept predicted points.
#[derive(Clone, Debug)]
pub struct Triangulated {
    pub positions: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

/// The predicted points on a projection: each one's plane position beside its 3-D one.
pub fn project_all(proj: &Projection, pts: &[Predicted]) -> Vec<(DVec2, DVec3)> {
    pts.iter()
        .map(|p| (proj.project_predicted(p), p.pos))
        .collect()
}

/// Constrained Delaunay triangulation of the plane loop `poly` (the image of `bp`,
/// counter-clockwise and simple) and the predicted points (plane and 3-D positions),
/// lifted to 3D.
pub fn triangulate(
    poly: &[DVec2],
    bp: &[DVec3],
    pts: &[(DVec2, DVec3)],
    drop_dist: f64,
) -> Result<Triangulated, FillError> {
    let k = bp.len();
    if poly.len() != k {
        return Err(FillError::bad_loop(format!(
            "hpde: the plane loop has {} vertices, the loop {k}",
            poly.len()
        )));
    }
    let fail = |m: &str| FillError::stuck(format!("hpde: {m}"));
    // keep predicted points inside, away from the loop and from each other
    let cell = drop_dist.max(1e-300);
    let key = |q: DVec2| ((q.x / cell).floor() as i64, (q.y / cell).floor() as i64);
    let mut grid: HashMap<(i64, i64), Vec<DVec2>> = HashMap::default();
    let mut kept: Vec<(DVec2, DVec3)> = Vec::new();
    for &(q, p) in pts {
        if !q.is_finite() || !point_in_polygon(poly, q) {
            continue;
        }
        let near_loop = (0..k).any(|i| dist_to_segment(poly[i], poly[(i + 1) % k], q) < drop_dist);
        if near_loop {
            continue;
        }
        let (cx, cy) = key(q);
        let mut close = false;
        'outer: for dx in -1..=1 {
            for dy in -1..=1 {
                if let Some(list) = grid.get(&(cx + dx, cy + dy)) {
                    if list.iter().any(|o| (*o - q).length() < drop_dist) {
                        close = true;
                        break 'outer;
                    }
                }
            }
        }
        if close {
            continue;
        }
        grid.entry((cx, cy)).or_default().push(q);
        kept.push((q, p));
    }
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    // spade vertex index -> our index
    let mut ours: Vec<Option<u32>> = Vec::new();
    let mut handles = Vec::with_capacity(k);
    for (i, q) in poly.iter().enumerate() {
        let before = cdt.num_vertices();
        let h = cdt
            .insert(Point2::new(q.x, q.y))
            .map_err(|e| fail(&format!("cannot triangulate the projected loop: {e:?}")))?;
        if cdt.num_vertices() == before {
            return Err(fail("two loop vertices project to the same point"));
        }
        if ours.len() <= h.index() {
            ours.resize(h.index() + 1, None);
        }
        ours[h.index()] = Some(i as u32);
        handles.push(h);
    }
    let mut positions: Vec<DVec3> = bp.to_vec();
    for (q, p) in &kept {
        let before = cdt.num_vertices();
        let Ok(h) = cdt.insert(Point2::new(q.x, q.y)) else {
            continue;
        };
        if cdt.num_vertices() == before {
            continue;
        }
        if ours.len() <= h.index() {
            ours.resize(h.index() + 1, None);
        }
        ours[h.index()] = Some(positions.len() as u32);
        positions.push(*p);
    }
    for i in 0..k {
        let (a, b) = (handles[i], handles[(i + 1) % k]);
        if !cdt.exists_constraint(a, b) {
            let _ = cdt.try_add_constraint(a, b);
        }
        if !cdt.exists_constraint(a, b) {
            return Err(fail(&format!(
                "boundary edge {i}-{} could not be kept in the triangulation",
                (i + 1) % k
            )));
        }
    }
    let mut triangles = Vec::new();
    for f in cdt.inner_faces() {
        let ps = f.positions();
        let cen = DVec2::new(
            (ps[0].x + ps[1].x + ps[2].x) / 3.0,
            (ps[0].y + ps[1].y + ps[2].y) / 3.0,
        );
        if !point_in_polygon(poly, cen) {
            continue;
        }
        let vs = f.vertices();
        let mut t = [0u32; 3];
        for (c, v) in vs.iter().enumerate() {
            t[c] = ours
                .get(v.fix().index())
                .copied()
                .flatten()
                .ok_or_else(|| fail("triangulation produced an unknown vertex"))?;
        }
        triangles.push(t);
    }
    if triangles.is_empty() {
        return Err(fail("the triangulation of the loop is empty"));
    }
    // drop predicted points no triangle uses (cannot happen for interior points, but
    // keep the output a clean disk)
    let mut used = vec![false; positions.len()];
    for t in &triangles {
        for &i in t {
            used[i as usize] = true;
        }
    }
    if used[..k].iter().any(|u| !u) {
        return Err(fail("a loop vertex is not used by the triangulation"));
    }
    let mut remap = vec![u32::MAX; positions.len()];
    let mut out_pos = Vec::with_capacity(positions.len());
    for (i, p) in positions.iter().enumerate() {
        if used[i] {
            remap[i] = out_pos.len() as u32;
            out_pos.push(*p);
        }
    }
    for t in triangles.iter_mut() {
        for i in t.iter_mut() {
            *i = remap[*i as usize];
        }
    }
    Ok(Triangulated {
        positions: out_pos,
        triangles,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A loop wound three quarters around a cylinder (no plane sees it as a simple
    /// polygon) and a fan triangulation of it: each point above a surface triangle's
    /// centroid maps to the centroid of that triangle's image on the circle, inside
    /// the circle polygon; `on_surface` lifts it to the centroid itself.
    #[test]
    fn points_over_a_wound_surface_map_into_their_triangles_image() {
        let k = 24;
        let bp: Vec<DVec3> = (0..k)
            .map(|i| {
                let a = 1.5 * std::f64::consts::PI * i as f64 / (k - 1) as f64;
                let z = if i % 2 == 0 { 0.0 } else { 0.3 };
                DVec3::new(a.cos(), a.sin(), z)
            })
            .collect();
        let surface: Vec<[u32; 3]> = (1..k as u32 - 1).map(|i| [0, i, i + 1]).collect();
        let pts: Vec<Predicted> = surface
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| bp[i as usize]);
                let n = (b - a).cross(c - a).normalize();
                Predicted {
                    pos: (a + b + c) / 3.0 + n * 1e-3,
                    pair: (0, 1),
                    frac: 0.5,
                }
            })
            .collect();
        let o = over_surface(&bp, &surface, &pts, false, &Deadline::none()).unwrap();
        let (l, over) = (o.loop2d, o.points);
        assert!(not_simple(&l).is_none());
        assert_eq!(over.len(), pts.len());
        for ((q, p), (t, pr)) in over.iter().zip(surface.iter().zip(&pts)) {
            let image = (l[t[0] as usize] + l[t[1] as usize] + l[t[2] as usize]) / 3.0;
            assert!((*q - image).length() < 1e-9, "{q} against {image}");
            assert!(point_in_polygon(&l, *q));
            assert_eq!(*p, pr.pos);
        }
        let on = over_surface(&bp, &surface, &pts, true, &Deadline::none())
            .unwrap()
            .points;
        for ((_, p), t) in on.iter().zip(&surface) {
            let c = t.map(|i| bp[i as usize]);
            assert!((*p - (c[0] + c[1] + c[2]) / 3.0).length() < 1e-9);
        }
        // a triangle naming a vertex outside the loop is an error, not a panic
        assert!(over_surface(&bp, &[[0, 1, k as u32]], &pts, false, &Deadline::none()).is_err());
        // a spent deadline stops the search (checked every 256 points)
        let many: Vec<Predicted> = pts.iter().cycle().take(300).copied().collect();
        let spent = Deadline(Some(std::time::Instant::now()));
        assert!(matches!(
            over_surface(&bp, &surface, &many, false, &spent),
            Err(FillError::Timeout)
        ));
        assert!(over_surface(&bp, &surface, &many, false, &Deadline::none()).is_ok());
    }

    #[test]
    fn simple_and_self_crossing_polygons() {
        let sq = vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        assert!(not_simple(&sq).is_none());
        let bow = vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.0, 1.0),
        ];
        assert!(not_simple(&bow).is_some());
        // a vertex touching a non-adjacent edge
        let touch = vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(2.0, 0.0),
            DVec2::new(2.0, 2.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.0, 2.0),
        ];
        assert!(not_simple(&touch).is_some());
    }
}
