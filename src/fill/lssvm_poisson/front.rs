//! Step 1 (paper 003 §3.2): the initial patch by a plain advancing front, with the
//! fallback to the loop's best-fit plane and the guide normals that keep it from
//! turning over.

use super::*;
use crate::geometry::grid::Grid;
use crate::geometry::predicates::{
    orient2, overlap2d_labeled, p2, segments_cross, strictly_inside, P2,
};

/// Guide normal field over the hole: inverse-square-distance mean of the loop's vertex
/// normals. It does not depend on the patch, so it cannot drift with it.
pub(super) struct Guide {
    pub(super) pts: Vec<DVec3>,
    pub(super) normals: Vec<DVec3>,
    pub(super) eps2: f64,
}

impl Guide {
    fn new(mesh: &Mesh, hole: &[VertexId], edge: f64) -> Guide {
        Guide {
            pts: hole.iter().map(|&v| mesh.pos(v)).collect(),
            normals: hole.iter().map(|&v| mesh.vertex_normal(v)).collect(),
            eps2: 1e-3 * edge * edge,
        }
    }

    fn at(&self, x: DVec3) -> DVec3 {
        let mut acc = DVec3::ZERO;
        for (p, n) in self.pts.iter().zip(&self.normals) {
            acc += *n / (x - *p).length_squared().max(self.eps2);
        }
        acc.normalize_or_zero()
    }
}

/// The plain advancing front of paper 003 §3.2 (see the module doc): a patch closing
/// the loop `hole` with new vertices at distance `edge` from the front.
pub fn initial_front(
    mesh: &Mesh,
    hole: &[VertexId],
    edge: f64,
    merge_distance: f64,
    max_area_ratio: f64,
    deadline: &Deadline,
) -> Result<Patch, FillError> {
    initial_front_with(
        mesh,
        hole,
        edge,
        merge_distance,
        max_area_ratio,
        deadline,
        false,
    )
}

/// [`initial_front`]; with `residual`, a stuck 3-D front closes its loop as a residual
/// front ([`crate::fill::kit::residual`]) instead of the planar fallback. A 3-D front
/// whose patch's area passes `max_area_ratio` times the loop's vector area (0: no
/// limit) stops with [`FillError::Runaway`] (then, without `residual`, the planar
/// front is tried).
pub fn initial_front_with(
    mesh: &Mesh,
    hole: &[VertexId],
    edge: f64,
    merge_distance: f64,
    max_area_ratio: f64,
    deadline: &Deadline,
    residual: bool,
) -> Result<Patch, FillError> {
    let k = hole.len();
    if k < 3 {
        return Err(FillError::bad_loop(format!(
            "a loop of {k} vertices cannot be filled"
        )));
    }
    if !(edge.is_finite() && edge > 0.0) {
        return Err(FillError::bad_loop("front edge length is not positive"));
    }
    let front3d = || {
        let mut f = Front::new(mesh, hole, edge, merge_distance, false);
        if let Some(f) = f.as_mut() {
            f.max_area_ratio = max_area_ratio;
            if max_area_ratio > 0.0 {
                f.max_area = max_area_ratio * measure::vector_area(&f.pos[..k]);
            }
        }
        f
    };
    if residual {
        let mut f = front3d();
        if let Some(f) = f.as_mut() {
            f.residual = Some(*deadline);
        }
        return run_front(f, k, deadline);
    }
    match run_front(front3d(), k, deadline) {
        Err(why3d) if why3d != FillError::Timeout => {
            // the same front in the loop's best-fit plane, lifted by a harmonic map
            let flat = run_front(
                Front::new(mesh, hole, edge, merge_distance, true),
                k,
                deadline,
            )
            .map_err(|e| match e {
                FillError::Timeout => e,
                why => FillError::stuck(format!("{why3d}; in the plane: {why}")),
            })?;
            let boundary: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
            let normals: Vec<DVec3> = hole.iter().map(|&v| mesh.vertex_normal(v)).collect();
            let pts = project_loop(&boundary, &normals).ok_or_else(|| why3d.clone())?;
            let pos: Vec<DVec3> = pts
                .into_iter()
                .chain(flat.new_vertices.iter().copied())
                .collect();
            let solver = PoissonSolver::new(&pos, k, &flat.triangles, edge, None)?;
            let zero = vec![DVec3::ZERO; flat.new_vertices.len()];
            let new_vertices = solver.solve(&boundary, &zero)?;
            Ok(Patch {
                new_vertices,
                triangles: flat.triangles,
            })
        }
        other => other,
    }
}

/// The loop projected onto a plane in which it is a simple, counter-clockwise polygon,
/// as points with `z = 0`: its best-fit (Newell) plane, else the plane normal to the
/// mean of its vertex normals (`normals`). `None` when neither works.
pub(super) fn project_loop(pts: &[DVec3], normals: &[DVec3]) -> Option<Vec<DVec3>> {
    let mean = normals.iter().copied().sum::<DVec3>().normalize_or_zero();
    [measure::newell_normal(pts), mean]
        .into_iter()
        .find_map(|n| project_along(pts, n))
}

pub(super) fn project_along(pts: &[DVec3], n: DVec3) -> Option<Vec<DVec3>> {
    if n == DVec3::ZERO {
        return None;
    }
    let t1 = n.any_orthonormal_vector();
    let t2 = n.cross(t1);
    let q: Vec<P2> = pts.iter().map(|p| p2(p.dot(t1), p.dot(t2))).collect();
    let m = q.len();
    let area2: f64 = (0..m)
        .map(|i| {
            let (a, b) = (q[i], q[(i + 1) % m]);
            a.x * b.y - b.x * a.y
        })
        .sum();
    if !positive(area2) {
        return None;
    }
    for a in 0..m {
        for b in a + 2..m {
            if a == 0 && b == m - 1 {
                continue;
            }
            if segments_cross(q[a], q[(a + 1) % m], q[b], q[(b + 1) % m]) {
                return None;
            }
        }
    }
    Some(q.into_iter().map(|c| DVec3::new(c.x, c.y, 0.0)).collect())
}

/// Runs a front until every loop is closed.
pub(super) fn run_front(
    front: Option<Front>,
    k: usize,
    deadline: &Deadline,
) -> Result<Patch, FillError> {
    let mut f = front
        .ok_or_else(|| FillError::bad_loop("the loop's projection is not a simple polygon"))?;
    let cap = k * k + 100 * k + 1000;
    // 1.4 times the vertex count of the largest disk with this perimeter, plus slack
    let vertex_cap = k + k * k / 4 + 10 * k;
    let mut steps = 0usize;
    let mut loops: Vec<Vec<u32>> = vec![(0..k as u32).collect()];
    while let Some(lp) = loops.pop() {
        deadline.check()?;
        steps += 1;
        if steps > cap {
            return Err(FillError::stuck(format!(
                "advancing front did not close in {cap} steps"
            )));
        }
        if lp.len() < 3 {
            continue;
        }
        if lp.len() == 3 {
            f.add_triangles(&[[lp[0], lp[1], lp[2]]]);
            continue;
        }
        if f.pos.len() > vertex_cap {
            return Err(FillError::TooLarge(TooLarge::Vertices(vertex_cap - k)));
        }
        let mut next = f.step(&lp)?;
        loops.append(&mut next);
        if f.area > f.max_area {
            return Err(FillError::Runaway {
                key: "lssvm.max_area_ratio",
                max_area_ratio: f.max_area_ratio,
            });
        }
    }
    let new_vertices = f.pos[k..].to_vec();
    if new_vertices.iter().any(|p| !p.is_finite()) {
        return Err(FillError::stuck("front produced a non-finite vertex"));
    }
    Ok(Patch {
        new_vertices,
        triangles: f.tris,
    })
}

/// A spoke of a front step: a new point, or an existing loop vertex it merged into.
#[derive(Clone, Copy, PartialEq, Debug)]
pub(super) enum Spoke {
    New(DVec3),
    Old(u32),
}

pub(super) struct Front {
    /// Patch vertex positions: loop first, then new.
    pub(super) pos: Vec<DVec3>,
    /// Accumulated area-weighted normals (mesh faces for loop vertices, plus patch).
    pub(super) nacc: Vec<DVec3>,
    pub(super) tris: Vec<[u32; 3]>,
    /// Undirected edges (min, max) of the patch and mesh edges between loop vertices.
    pub(super) edges: HashSet<(u32, u32)>,
    /// Triangles a new triangle must not overlap: the mesh faces around the loop and
    /// the patch so far (vertex labels: patch indices; other mesh vertices get labels
    /// from `u32::MAX` down, so that they never match).
    pub(super) obstacles: Vec<Obstacle>,
    /// Centroid and largest distance of the loop's vertices from it: new vertices stay
    /// within `1.2` times that ball.
    pub(super) centre: DVec3,
    pub(super) reach: f64,
    pub(super) edge: f64,
    pub(super) merge: f64,
    /// Guide normals (see [`Guide`]): a front that starts to turn over is refused.
    pub(super) guide: Guide,
    /// Front edges and obstacles farther than this from a step's vertex are not tested.
    pub(super) radius: f64,
    /// Close a stuck loop as a residual front (with this deadline) instead of failing.
    pub(super) residual: Option<Deadline>,
    /// Area of the patch so far; the front stops (has run away) once it passes
    /// `max_area` (`max_area_ratio` times the loop's vector area; infinite: no limit).
    area: f64,
    max_area: f64,
    max_area_ratio: f64,
    /// The guide normal at each patch vertex (vertices do not move while the front
    /// runs; the guide sums over the whole loop, so computing it again at every step
    /// made a 200-vertex hole take seconds).
    guide_at: Vec<DVec3>,
    /// The obstacles' centres in cells of `radius` (when that is finite): a step
    /// tests only the obstacles in the cells around its vertex, not the whole patch.
    near_obstacles: Option<Grid>,
}

pub(super) struct Obstacle {
    pub(super) ids: [u32; 3],
    pub(super) pts: [DVec3; 3],
    pub(super) centre: DVec3,
    pub(super) normal: DVec3,
}

impl Obstacle {
    fn new(ids: [u32; 3], pts: [DVec3; 3]) -> Obstacle {
        Obstacle {
            ids,
            pts,
            centre: (pts[0] + pts[1] + pts[2]) / 3.0,
            normal: measure::tri_normal_raw(pts[0], pts[1], pts[2]).normalize_or_zero(),
        }
    }
}

impl Front {
    /// The front of the loop `hole`; with `planar`, of its projection onto its best-fit
    /// plane (`None` when that is not a simple polygon).
    fn new(
        mesh: &Mesh,
        hole: &[VertexId],
        edge: f64,
        merge_distance: f64,
        planar: bool,
    ) -> Option<Front> {
        let k = hole.len();
        let mut pos: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
        let mut nacc: Vec<DVec3> = hole
            .iter()
            .map(|&v| {
                mesh.topo
                    .vertex_faces(v)
                    .map(|f| mesh.face_normal_raw(f))
                    .sum::<DVec3>()
            })
            .collect();
        if planar {
            let normals: Vec<DVec3> = hole.iter().map(|&v| mesh.vertex_normal(v)).collect();
            pos = project_loop(&pos, &normals)?;
            nacc = vec![DVec3::Z; k];
        }
        let mut index = crate::fasthash::HashMap::default();
        for (i, &v) in hole.iter().enumerate() {
            index.insert(v, i as u32);
        }
        let mut edges = HashSet::default();
        for (i, &v) in hole.iter().enumerate() {
            for w in mesh.topo.neighbors(v) {
                if let Some(&j) = index.get(&w) {
                    edges.insert(edge_key(i as u32, j));
                }
            }
            edges.insert(edge_key(i as u32, ((i + 1) % k) as u32));
        }
        let mut obstacles = Vec::new();
        let mut seen = HashSet::default();
        if planar {
            // the loop is the only obstacle; every front edge is checked
            seen.extend((0..mesh.num_faces()).map(crate::mesh::FaceId::from_idx));
        }
        let mut other: crate::fasthash::HashMap<VertexId, u32> =
            crate::fasthash::HashMap::default();
        for &v in hole {
            for f in mesh.topo.vertex_faces(v) {
                if !seen.insert(f) {
                    continue;
                }
                let t = mesh.topo.face(f);
                let ids = t.map(|w| match index.get(&w) {
                    Some(&i) => i,
                    None => {
                        let next = u32::MAX - other.len() as u32;
                        *other.entry(w).or_insert(next)
                    }
                });
                obstacles.push(Obstacle::new(ids, t.map(|w| mesh.pos(w))));
            }
        }
        let centre = measure::centroid(&pos);
        let reach = 1.2
            * pos
                .iter()
                .map(|p| (*p - centre).length())
                .fold(0.0, f64::max)
            + edge;
        let guide = if planar {
            Guide {
                pts: vec![DVec3::ZERO],
                normals: vec![DVec3::Z],
                eps2: 1.0,
            }
        } else {
            Guide::new(mesh, hole, edge)
        };
        let radius = if planar { f64::INFINITY } else { 4.0 * edge };
        let guide_at = pos.iter().map(|&p| guide.at(p)).collect();
        let mut front = Front {
            pos,
            nacc,
            tris: Vec::new(),
            edges,
            obstacles: Vec::new(),
            centre,
            reach,
            guide,
            radius,
            edge,
            merge: merge_distance * edge,
            residual: None,
            area: 0.0,
            max_area: f64::INFINITY,
            max_area_ratio: 0.0,
            guide_at,
            near_obstacles: (radius.is_finite() && radius > 0.0).then(|| Grid::new(radius, centre)),
        };
        for o in obstacles {
            front.push_obstacle(o);
        }
        Some(front)
    }

    fn push_vertex(&mut self, p: DVec3) {
        self.pos.push(p);
        self.nacc.push(DVec3::ZERO);
        self.guide_at.push(self.guide.at(p));
    }

    fn push_obstacle(&mut self, o: Obstacle) {
        if let Some(g) = &mut self.near_obstacles {
            g.insert_point(o.centre, self.obstacles.len() as u32);
        }
        self.obstacles.push(o);
    }

    /// The normal at patch vertex `i`: its own (area-weighted over the mesh and patch
    /// triangles around it) averaged with the guide normal at its position.
    fn normal(&self, i: u32) -> DVec3 {
        let g = self.guide_at[i as usize];
        (self.nacc[i as usize].normalize_or_zero() + g).normalize_or(g)
    }

    fn add_triangles(&mut self, tris: &[[u32; 3]]) {
        for t in tris {
            let n = measure::tri_normal_raw(
                self.pos[t[0] as usize],
                self.pos[t[1] as usize],
                self.pos[t[2] as usize],
            );
            for c in 0..3 {
                self.nacc[t[c] as usize] += n;
                self.edges.insert(edge_key(t[c], t[(c + 1) % 3]));
            }
            self.area += 0.5 * n.length();
            self.tris.push(*t);
            self.push_obstacle(Obstacle::new(*t, t.map(|i| self.pos[i as usize])));
        }
    }

    /// Angle on the hole side at position `j` of loop `lp`, in `[0, 2π)`, and the axis
    /// that turns the direction to the next vertex into the direction to the previous one
    /// by that angle.
    fn angle(&self, lp: &[u32], j: usize) -> (f64, DVec3, DVec3) {
        let m = lp.len();
        let p = self.pos[lp[j] as usize];
        let u = (self.pos[lp[(j + 1) % m] as usize] - p).normalize_or_zero();
        let w = (self.pos[lp[(j + m - 1) % m] as usize] - p).normalize_or_zero();
        let n = self.normal(lp[j]);
        let c = u.cross(w);
        let mut th = c.dot(n).atan2(u.dot(w));
        if th < 0.0 {
            th += std::f64::consts::TAU;
        }
        // the plane of the two front edges, unless they are nearly collinear or their
        // plane nearly contains the normal: then the tangent plane
        let cl = c.length();
        let ch = if c.dot(n) >= 0.0 { c } else { -c };
        let axis = if cl > 0.5 && ch.dot(n) > 0.5 * cl {
            ch / cl
        } else {
            n
        };
        (th, axis, u)
    }

    /// One front step on loop `lp`; returns the loops that replace it.
    fn step(&mut self, lp: &[u32]) -> Result<Vec<Vec<u32>>, FillError> {
        let m = lp.len();
        let mut order: Vec<(f64, usize, DVec3, DVec3)> = (0..m)
            .map(|j| {
                let (th, axis, u) = self.angle(lp, j);
                (th, j, axis, u)
            })
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let small = 75f64.to_radians();
        let large = 135f64.to_radians();
        for &(th, j, axis, u) in &order {
            let mut tries: Vec<Vec<f64>> = Vec::new();
            if th <= small {
                tries.push(vec![]);
            } else if th <= large {
                tries.push(vec![th / 2.0]);
                tries.push(vec![]);
            } else {
                tries.push(vec![2.0 * th / 3.0, th / 3.0]);
                if th < std::f64::consts::PI {
                    tries.push(vec![]);
                }
            }
            for rots in tries {
                if let Some(out) = self.try_step(lp, j, axis, u, &rots) {
                    return Ok(out);
                }
            }
        }
        // every rule refused: clip the best ear of the loop's projection
        let pts: Vec<DVec3> = lp.iter().map(|&v| self.pos[v as usize]).collect();
        let mean_guide = pts
            .iter()
            .map(|&p| self.guide.at(p))
            .sum::<DVec3>()
            .normalize_or_zero();
        let newell = measure::newell_normal(&pts);
        if let Some(out) = self
            .clip_ear(lp, newell)
            .or_else(|| self.clip_ear(lp, mean_guide))
        {
            return Ok(out);
        }
        // no ear either: close the loop as a residual front (min-area, refined, faired)
        let Some(deadline) = self.residual else {
            return Err(FillError::stuck(format!(
                "advancing front is stuck on a loop of {m} vertices"
            )));
        };
        self.close_residual(lp, &deadline).map_err(|e| {
            FillError::stuck(format!(
                "advancing front is stuck on a loop of {m} vertices and the residual \
                 closing failed: {e}"
            ))
        })?;
        Ok(Vec::new())
    }

    /// Closes loop `lp` with [`residual::close`].
    fn close_residual(&mut self, lp: &[u32], deadline: &Deadline) -> Result<(), FillError> {
        let m = lp.len();
        if lp.iter().collect::<HashSet<_>>().len() != m {
            return Err(FillError::bad_loop("the loop passes a vertex twice"));
        }
        let pts: Vec<DVec3> = lp.iter().map(|&v| self.pos[v as usize]).collect();
        let mut forbidden = HashSet::default();
        for i in 0..m {
            for j in i + 2..m {
                if (i, j) != (0, m - 1) && self.edges.contains(&edge_key(lp[i], lp[j])) {
                    forbidden.insert((i as u32, j as u32));
                }
            }
        }
        let on: HashSet<u32> = lp.iter().copied().collect();
        let context: Vec<[DVec3; 3]> = self
            .obstacles
            .iter()
            .filter(|o| o.ids.iter().any(|i| on.contains(i)))
            .map(|o| o.pts)
            .collect();
        let outside = vec![None; m];
        let policy = crate::policy::Policy::default();
        let input = residual::Residual {
            ring: &pts,
            forbidden: &forbidden,
            outside_normals: &outside,
            context: &context,
            edge_length: self.edge,
        };
        let (new_pts, tris) = residual::close(&input, &policy, deadline)?;
        let base = self.pos.len() as u32;
        for p in new_pts {
            self.push_vertex(p);
        }
        let mapped: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| {
                t.map(|i| {
                    if (i as usize) < m {
                        lp[i as usize]
                    } else {
                        base + i - m as u32
                    }
                })
            })
            .collect();
        self.add_triangles(&mapped);
        Ok(())
    }

    /// Fallback when no front rule applies: project the loop onto the plane normal to
    /// `n` (its best-fit plane, then the mean guide normal) and, when the projection is a
    /// simple polygon, cut off the ear with the largest smallest angle whose new edge is
    /// not an existing edge.
    fn clip_ear(&mut self, lp: &[u32], n: DVec3) -> Option<Vec<Vec<u32>>> {
        let m = lp.len();
        let pts: Vec<DVec3> = lp.iter().map(|&v| self.pos[v as usize]).collect();
        if n == DVec3::ZERO {
            return None;
        }
        let t1 = n.any_orthonormal_vector();
        let t2 = n.cross(t1);
        let q: Vec<P2> = pts.iter().map(|p| p2(p.dot(t1), p.dot(t2))).collect();
        // simple polygon?
        for a in 0..m {
            for b in a + 2..m {
                if a == 0 && b == m - 1 {
                    continue;
                }
                if segments_cross(q[a], q[(a + 1) % m], q[b], q[(b + 1) % m]) {
                    return None;
                }
            }
        }
        let mut best: Option<(f64, usize)> = None;
        for j in 0..m {
            let (i0, i2) = ((j + m - 1) % m, (j + 1) % m);
            // convex corner: the loop runs counter-clockwise about n
            if orient2(q[i0], q[j], q[i2]) <= 0.0 {
                continue;
            }
            if self.edges.contains(&edge_key(lp[i0], lp[i2])) {
                continue;
            }
            if (0..m)
                .any(|t| t != i0 && t != j && t != i2 && strictly_inside(q[t], q[i0], q[j], q[i2]))
            {
                continue;
            }
            let a = measure::angles(pts[i0], pts[j], pts[i2]);
            let score = a[0].min(a[1]).min(a[2]);
            if best.is_none_or(|(bs, _)| score > bs) {
                best = Some((score, j));
            }
        }
        let (_, j) = best?;
        let (prev, next) = (lp[(j + m - 1) % m], lp[(j + 1) % m]);
        self.add_triangles(&[[prev, lp[j], next]]);
        let mut rest = lp.to_vec();
        rest.remove(j);
        Some(split_loops(rest))
    }

    /// Tries the step at `lp[j]` with spokes at the rotations `rots` of `u` about `axis`
    /// (ordered from the previous vertex's side to the next's).
    fn try_step(
        &mut self,
        lp: &[u32],
        j: usize,
        axis: DVec3,
        u: DVec3,
        rots: &[f64],
    ) -> Option<Vec<Vec<u32>>> {
        let m = lp.len();
        let pi = lp[j];
        let prev = lp[(j + m - 1) % m];
        let next = lp[(j + 1) % m];
        let p = self.pos[pi as usize];
        // tangent direction of u in the rotation plane
        let ut = (u - axis * u.dot(axis)).normalize_or_zero();
        if ut == DVec3::ZERO {
            return None;
        }
        let mut spokes: Vec<Spoke> = Vec::new();
        for &r in rots {
            let d = DQuat::from_axis_angle(axis, r) * ut;
            let q = p + d * self.edge;
            if (q - self.centre).length() > self.reach {
                return None;
            }
            let mut best: Option<(f64, u32)> = None;
            for &v in lp {
                if v == pi {
                    continue;
                }
                let dist = (self.pos[v as usize] - q).length();
                if dist < self.merge && best.is_none_or(|(bd, _)| dist < bd) {
                    best = Some((dist, v));
                }
            }
            let s = match best {
                Some((_, v)) if v == prev || v == next => continue,
                Some((_, v)) => Spoke::Old(v),
                None => Spoke::New(q),
            };
            if spokes.last() != Some(&s) {
                spokes.push(s);
            }
        }
        // provisional indices of new points
        let base = self.pos.len() as u32;
        let mut new_pts: Vec<DVec3> = Vec::new();
        let mut chain: Vec<u32> = vec![prev];
        for s in &spokes {
            match *s {
                Spoke::Old(v) => chain.push(v),
                Spoke::New(q) => {
                    chain.push(base + new_pts.len() as u32);
                    new_pts.push(q);
                }
            }
        }
        chain.push(next);
        let at = |i: u32| -> DVec3 {
            if i >= base {
                new_pts[(i - base) as usize]
            } else {
                self.pos[i as usize]
            }
        };
        let tris: Vec<[u32; 3]> = chain.windows(2).map(|w| [w[0], pi, w[1]]).collect();
        let n = self.normal(pi);
        let is_front_edge =
            |a: u32, b: u32| -> bool { (0..m).any(|t| lp[t] == a && lp[(t + 1) % m] == b) };
        // combinatorial checks
        let mut new_edges: Vec<(u32, u32)> = Vec::new();
        for t in &tris {
            for c in 0..3 {
                let (a, b) = (t[c], t[(c + 1) % 3]);
                if a == b {
                    return None;
                }
                if is_front_edge(a, b) {
                    continue;
                }
                if a < base && b < base && self.edges.contains(&edge_key(a, b)) {
                    return None;
                }
                new_edges.push((a, b));
            }
            let [x, y, z] = t.map(at);
            let nt = measure::tri_normal_raw(x, y, z);
            if !positive(nt.dot(n)) || !positive(nt.dot(self.guide.at((x + y + z) / 3.0))) {
                return None;
            }
            let angs = measure::angles(x, y, z);
            if angs
                .iter()
                .any(|&a| a.is_nan() || a < FRONT_MIN_ANGLE_DEG.to_radians())
            {
                return None;
            }
        }
        // geometric checks in the tangent plane at p
        let t1 = n.any_orthonormal_vector();
        let t2 = n.cross(t1);
        let proj = |x: DVec3| -> P2 {
            let d = x - p;
            p2(d.dot(t1), d.dot(t2))
        };
        let radius = self.radius;
        let near = |x: DVec3| (x - p).length() <= radius;
        for &(a, b) in &new_edges {
            let (pa, pb) = (at(a), at(b));
            for t in 0..m {
                let (c, d) = (lp[t], lp[(t + 1) % m]);
                if c == a || c == b || d == a || d == b {
                    continue;
                }
                let (pc, pd) = (self.pos[c as usize], self.pos[d as usize]);
                if !near(pc) && !near(pd) {
                    continue;
                }
                if segments_cross(proj(pa), proj(pb), proj(pc), proj(pd)) {
                    return None;
                }
            }
        }
        for t in &tris {
            let [x, y, z] = t.map(at);
            let (px, py, pz) = (proj(x), proj(y), proj(z));
            for &v in lp {
                if t.contains(&v) {
                    continue;
                }
                let pv = self.pos[v as usize];
                if !near(pv) {
                    continue;
                }
                if strictly_inside(proj(pv), px, py, pz) {
                    return None;
                }
            }
            // a new point must not sit on the far side of the front
            for &q in &new_pts {
                let pq = proj(q);
                for s in 0..m {
                    let (c, d) = (lp[s], lp[(s + 1) % m]);
                    if c == pi || d == pi {
                        continue;
                    }
                    let (pc, pd) = (self.pos[c as usize], self.pos[d as usize]);
                    if !near(pc) && !near(pd) {
                        continue;
                    }
                    if segments_cross(p2(0.0, 0.0), pq, proj(pc), proj(pd)) {
                        return None;
                    }
                }
            }
        }
        // no overlap with the patch so far or the mesh around the loop (the obstacles
        // whose centre is within `radius` of p: from the grid's cells around p when
        // there is one, each tested alike)
        let mut ids: Vec<u32> = Vec::new();
        match &self.near_obstacles {
            Some(g) => g.query_box(p - DVec3::splat(radius), p + DVec3::splat(radius), &mut ids),
            None => ids.extend(0..self.obstacles.len() as u32),
        }
        for t in &tris {
            let pts = t.map(at);
            let pq = pts.map(proj);
            for &id in &ids {
                let o = &self.obstacles[id as usize];
                if (o.centre - p).length() > radius || o.normal.dot(n) < 0.2 {
                    continue;
                }
                if overlap2d_labeled(t, &pq, &o.ids, &o.pts.map(proj)) {
                    return None;
                }
            }
        }
        // commit
        for q in new_pts {
            self.push_vertex(q);
        }
        self.add_triangles(&tris);
        let mut seq: Vec<u32> = Vec::with_capacity(m + 2);
        for (t, &v) in lp.iter().enumerate() {
            if t == j {
                seq.extend_from_slice(&chain[1..chain.len() - 1]);
            } else {
                seq.push(v);
            }
        }
        Some(split_loops(seq))
    }
}

/// Splits a cyclic vertex sequence at repeated vertices into simple loops; loops of
/// fewer than three vertices are closed already and dropped.
pub(super) fn split_loops(seq: Vec<u32>) -> Vec<Vec<u32>> {
    let mut out = Vec::new();
    let mut stack = vec![seq];
    let mut first: crate::fasthash::HashMap<u32, usize> = crate::fasthash::HashMap::default();
    while let Some(s) = stack.pop() {
        // the first position that repeats and its next repetition (one pass: the
        // smallest first index wins; for it, the earliest repetition comes first)
        first.clear();
        let mut found: Option<(usize, usize)> = None;
        for (j, &v) in s.iter().enumerate() {
            match first.get(&v) {
                Some(&i) => {
                    if found.is_none_or(|(fi, _)| i < fi) {
                        found = Some((i, j));
                    }
                }
                None => {
                    first.insert(v, j);
                }
            }
        }
        match found {
            Some((i, j)) => {
                let a: Vec<u32> = s[i..j].to_vec();
                let mut b: Vec<u32> = s[j..].to_vec();
                b.extend_from_slice(&s[..i]);
                stack.push(a);
                stack.push(b);
            }
            None => {
                if s.len() >= 3 {
                    out.push(s);
                }
            }
        }
    }
    out
}
