//! The front of the wavefront (paper 004 §2.2): its nodes, the queue of front angles,
//! the grids of nodes and triangles, the run loop, and the closing of residual fronts.
//! The step rules are in [`super::step`].

use super::*;

/// What a wavefront node ([`Node`](crate::fill::kit::front::Node): a vertex occurrence on a front; a vertex
/// can be on two fronts after a split) carries besides its place on the ring.
#[derive(Clone, Copy, Debug)]
pub(super) struct NodeData {
    /// Failed steps at the node since it last changed (its queue penalty).
    pub(super) fails: u32,
}

/// A triangle already in place (patch triangle or mesh face around the hole), with the
/// patch indices of its corners where it has them.
#[derive(Clone, Copy, Debug)]
pub(super) struct Placed {
    pub(super) ids: [Option<u32>; 3],
    pub(super) p: [DVec3; 3],
    pub(super) n: DVec3,
    /// Bounding box (set by [`Wave::place`]).
    pub(super) lo: DVec3,
    pub(super) hi: DVec3,
}

/// A vertex of a step's chain: an existing front node or a new point.
#[derive(Clone, Copy, Debug)]
pub(super) enum Item {
    Node(u32),
    New(DVec3),
}

/// A validated step: the chain `[v_{i-1}, new or merged points..., v_{i+1}]` that replaces
/// the processed vertex (an interior `Item::Node` is the front node merged into).
pub(super) struct Plan {
    pub(super) chain: Vec<Item>,
}

/// The state of the front (cloned to resume a run with a smaller step cap, see
/// [`fill_checked`]).
#[derive(Clone)]
pub(super) struct Wave {
    pub(super) k: usize,
    pub(super) len: f64,
    pub(super) min_angle: f64,
    pub(super) restore: bool,
    pub(super) placement: WavefrontPlacement,
    pub(super) merge_radius: f64,
    /// Positions in patch numbering (loop first, then new points).
    pub(super) pos: Vec<DVec3>,
    /// Σ ω_k N_fk over the faces of each vertex so far (Eq. 1 without the virtual triangle).
    pub(super) acc: Vec<DVec3>,
    pub(super) tris: Vec<[u32; 3]>,
    /// Undirected patch edges.
    pub(super) edges: HashSet<(u32, u32)>,
    /// Undirected mesh edges between two loop vertices.
    pub(super) mesh_edges: HashSet<(u32, u32)>,
    /// The fronts: their nodes, sizes and the alive nodes (picked from at random).
    pub(super) ring: Ring<NodeData>,
    /// Front nodes by θ plus a penalty of 2π per failed attempt (`data`: θ).
    pub(super) heap: FrontQueue<f64>,
    pub(super) placed: Vec<Placed>,
    pub(super) tri_grid: Grid,
    pub(super) big: Vec<u32>,
    pub(super) node_grid: Grid,
    pub(super) rng: ChaCha8Rng,
    pub(super) fallback_normal: DVec3,
    /// New points must lie within `reach` of `centre` (the loop's centroid).
    pub(super) centre: DVec3,
    pub(super) reach: f64,
    /// The loop projected onto its best-fit plane (basis `plane_u`, `plane_w` at
    /// `centre`), and the smallest distance of a projected loop vertex from the centre.
    pub(super) loop2d: Vec<(f64, f64)>,
    pub(super) plane_u: DVec3,
    pub(super) plane_w: DVec3,
    pub(super) inner: f64,
    pub(super) stats: Stats,
    /// Stuck: thin triangles are allowed until the next successful step.
    pub(super) relaxed: bool,
    /// The front lost its shape (a bug, never expected): the run fails cleanly.
    pub(super) corrupt: bool,
    pub(super) scratch: Vec<u32>,
    /// Area of the patch triangles so far, and the runaway bound on it
    /// (`max_area_ratio` times the loop's vector area).
    pub(super) area: f64,
    pub(super) max_area: f64,
    /// Steps taken and failed steps in a row (the state of [`Wave::run`]).
    pub(super) steps: usize,
    pub(super) stalls: usize,
    /// Step counts at which [`Wave::run`] keeps a copy of the wave (before that step),
    /// and the copies kept.
    pub(super) snapshot_at: Vec<usize>,
    pub(super) snapshots: Snapshots,
}

/// Is `p` inside the closed polygon `poly` (non-zero winding number, counted by the
/// signed crossings of the ray from `p` towards +x, so no angles are summed) or within
/// `near` of one of its edges?
pub(super) fn inside_or_near(poly: &[(f64, f64)], p: (f64, f64), near: f64) -> bool {
    let Some(&last) = poly.last() else {
        return false;
    };
    let (px, py) = p;
    let mut wind = 0i64;
    let mut prev = last;
    for &cur in poly {
        let (ax, ay) = (prev.0 - px, prev.1 - py);
        let (bx, by) = (cur.0 - px, cur.1 - py);
        let cross = ax * by - ay * bx;
        if ay <= 0.0 {
            if by > 0.0 && cross > 0.0 {
                wind += 1;
            }
        } else if by <= 0.0 && cross < 0.0 {
            wind -= 1;
        }
        prev = cur;
    }
    if wind != 0 {
        return true;
    }
    let r2 = near * near;
    let mut prev = last;
    for &cur in poly {
        let (ax, ay) = (prev.0 - px, prev.1 - py);
        let (ex, ey) = (cur.0 - prev.0, cur.1 - prev.1);
        let t = (-(ax * ex + ay * ey) / (ex * ex + ey * ey).max(1e-300)).clamp(0.0, 1.0);
        if (ax + t * ex).powi(2) + (ay + t * ey).powi(2) < r2 {
            return true;
        }
        prev = cur;
    }
    false
}

/// Weight ω = λ / G (Eqs. 2, 4) and unit normal of triangle (a, b, c) seen from corner `q`.
pub(super) fn face_weight(q: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<(f64, DVec3)> {
    let n = (b - a).cross(c - a);
    let nl = n.length();
    if !(nl > 0.0 && nl.is_finite()) {
        return None;
    }
    let la = (b - c).length();
    let lb = (a - c).length();
    let lc = (a - b).length();
    let lambda = ((la + lb - lc) * (la + lc - lb) * (lb + lc - la) / (la * lb * lc)).max(0.0);
    let g = (q - (a + b + c) / 3.0).length();
    if !(g > 0.0 && lambda.is_finite()) {
        return None;
    }
    Some((lambda / g, n / nl))
}

/// Rotates `x` about `g` by the rotation taking unit `from` to unit `to` (Rodrigues).
pub(super) fn rotate_to(x: DVec3, g: DVec3, from: DVec3, to: DVec3) -> DVec3 {
    let axis = from.cross(to);
    let s = axis.length();
    let c = from.dot(to);
    if !(s > 1e-12) {
        return x;
    }
    let k = axis / s;
    let ang = s.atan2(c);
    let (sn, cs) = ang.sin_cos();
    let r = x - g;
    g + r * cs + k.cross(r) * sn + k * k.dot(r) * (1.0 - cs)
}

pub(super) fn unit_or(v: DVec3, fallback: DVec3) -> DVec3 {
    let l = v.length();
    if l > 1e-300 && l.is_finite() {
        v / l
    } else {
        fallback
    }
}

/// Do two triangles cross in 3D away from their shared corners? Edges touching a shared
/// corner are not tested (they meet the other triangle there by construction).
pub(super) fn cross3d(
    ai: [Option<u32>; 3],
    a: &[DVec3; 3],
    bi: [Option<u32>; 3],
    b: &[DVec3; 3],
) -> bool {
    let shared = |id: Option<u32>, other: &[Option<u32>; 3]| id.is_some() && other.contains(&id);
    for (xi, x, yi, y) in [(ai, a, bi, b), (bi, b, ai, a)] {
        for e in 0..3 {
            let f = (e + 1) % 3;
            if shared(xi[e], &yi) || shared(xi[f], &yi) {
                continue;
            }
            if seg_crosses_tri(x[e], x[f], y) {
                return true;
            }
        }
    }
    false
}

/// A new triangle of a step, prepared for the tests against the nearby triangles.
pub(super) struct Candidate {
    pub(super) ids: [Option<u32>; 3],
    /// Projected into the tangent plane, counter-clockwise; `None` when degenerate.
    pub(super) ccw: Option<[P2; 3]>,
    pub(super) box2: Box2,
    pub(super) box3: Box3,
}

/// A closed 2-D bounding box.
pub(super) struct Box2 {
    pub(super) lo: [f64; 2],
    pub(super) hi: [f64; 2],
}

impl Box2 {
    pub(super) fn of(t: &[P2; 3]) -> Box2 {
        Box2 {
            lo: [
                t[0].x.min(t[1].x).min(t[2].x),
                t[0].y.min(t[1].y).min(t[2].y),
            ],
            hi: [
                t[0].x.max(t[1].x).max(t[2].x),
                t[0].y.max(t[1].y).max(t[2].y),
            ],
        }
    }
    /// False only when the boxes are apart (then no two triangles in them overlap).
    pub(super) fn meets(&self, o: &Box2) -> bool {
        !(self.hi[0] < o.lo[0]
            || o.hi[0] < self.lo[0]
            || self.hi[1] < o.lo[1]
            || o.hi[1] < self.lo[1])
    }
}

/// A closed 3-D bounding box.
pub(super) struct Box3 {
    pub(super) lo: DVec3,
    pub(super) hi: DVec3,
}

impl Box3 {
    pub(super) fn of(t: &[DVec3; 3]) -> Box3 {
        Box3 {
            lo: t[0].min(t[1]).min(t[2]),
            hi: t[0].max(t[1]).max(t[2]),
        }
    }
    /// False only when the boxes are apart (then no segment of one crosses the other).
    pub(super) fn meets(&self, o: &Box3) -> bool {
        !(self.hi.cmplt(o.lo).any() || o.hi.cmplt(self.lo).any())
    }
}

impl Wave {
    pub(super) fn new(ctx: &FillContext, opts: &Wavefront, len: f64) -> Result<Wave, FillError> {
        let mesh = ctx.mesh;
        let hole = &ctx.hole.vertices;
        let k = hole.len();
        let mut index: HashMap<u32, u32> = HashMap::with_capacity_and_hasher(k, Default::default());
        for (i, v) in hole.iter().enumerate() {
            if v.idx() >= mesh.num_vertices() {
                return Err(FillError::bad_loop(format!(
                    "loop vertex {} is not in the mesh",
                    v.idx()
                )));
            }
            if index.insert(v.idx() as u32, i as u32).is_some() {
                return Err(FillError::bad_loop(format!(
                    "the loop passes vertex {} twice",
                    v.idx()
                )));
            }
        }
        let pos: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
        let fallback_normal = unit_or(measure::newell_normal(&pos), DVec3::Z);
        let centre = measure::centroid(&pos);
        let pu = fallback_normal.any_orthonormal_vector();
        let pw = fallback_normal.cross(pu);
        let loop2d: Vec<(f64, f64)> = pos
            .iter()
            .map(|&p| ((p - centre).dot(pu), (p - centre).dot(pw)))
            .collect();
        let inner = loop2d
            .iter()
            .map(|&(x, y)| (x * x + y * y).sqrt())
            .fold(f64::INFINITY, f64::min);
        let reach = 2.0
            * pos
                .iter()
                .map(|&p| (p - centre).length())
                .fold(0.0, f64::max)
            + 2.0 * len;
        let max_area = if opts.max_area_ratio > 0.0 {
            opts.max_area_ratio * measure::vector_area(&pos)
        } else {
            f64::INFINITY
        };
        let mut w = Wave {
            k,
            len,
            min_angle: ctx.policy.checks.min_angle_deg.max(0.0).to_radians() + 1e-9,
            restore: opts.curvature_restoration,
            placement: opts.placement,
            merge_radius: opts.merge_distance * len,
            acc: vec![DVec3::ZERO; k],
            pos,
            tris: Vec::new(),
            edges: HashSet::default(),
            mesh_edges: HashSet::default(),
            ring: Ring::new(k),
            heap: FrontQueue::new(),
            placed: Vec::new(),
            tri_grid: Grid::new(CELL * len, centre),
            big: Vec::new(),
            node_grid: Grid::new(CELL * len, centre),
            rng: ChaCha8Rng::seed_from_u64(
                ctx.policy.seed ^ (ctx.hole.id as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            ),
            fallback_normal,
            centre,
            reach,
            loop2d,
            plane_u: pu,
            plane_w: pw,
            inner,
            stats: Stats::default(),
            relaxed: false,
            corrupt: false,
            scratch: Vec::new(),
            area: 0.0,
            max_area,
            steps: 0,
            stalls: 0,
            snapshot_at: Vec::new(),
            snapshots: Vec::new(),
        };
        // mesh faces around the hole: expected normals (Eq. 1) and obstacles
        let mut seen = HashSet::default();
        for (i, &v) in hole.iter().enumerate() {
            for nb in mesh.topo.neighbors(v) {
                if let Some(&j) = index.get(&(nb.idx() as u32)) {
                    w.mesh_edges.insert(edge_key(i as u32, j));
                }
            }
            for f in mesh.topo.vertex_faces(v) {
                let p = mesh.tri(f);
                if let Some((wt, n)) = face_weight(mesh.pos(v), p[0], p[1], p[2]) {
                    w.acc[i] += wt * n;
                }
                if seen.insert(f) {
                    let ids = mesh
                        .topo
                        .face(f)
                        .map(|c| index.get(&(c.idx() as u32)).copied());
                    let n = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO);
                    w.place(Placed {
                        ids,
                        p,
                        n,
                        lo: DVec3::ZERO,
                        hi: DVec3::ZERO,
                    });
                }
            }
        }
        for i in 0..k {
            w.new_node(i as u32, ((i + k - 1) % k) as u32, ((i + 1) % k) as u32, 0);
        }
        for i in 0..k {
            w.refresh(i as u32);
        }
        Ok(w)
    }

    pub(super) fn place(&mut self, mut t: Placed) {
        let id = self.placed.len() as u32;
        let lo = t.p[0].min(t.p[1]).min(t.p[2]);
        let hi = t.p[0].max(t.p[1]).max(t.p[2]);
        (t.lo, t.hi) = (lo, hi);
        self.placed.push(t);
        if !self.tri_grid.insert_box(lo, hi, id) {
            self.big.push(id);
        }
    }

    pub(super) fn new_node(&mut self, vert: u32, prev: u32, next: u32, front: u32) -> u32 {
        let id = self
            .ring
            .push(vert, prev, next, front, NodeData { fails: 0 });
        let p = self.pos[vert as usize];
        self.node_grid.insert_point(p, id);
        id
    }

    pub(super) fn kill(&mut self, n: u32) {
        self.ring.kill(n);
    }

    pub(super) fn p(&self, n: u32) -> DVec3 {
        self.pos[self.ring.nodes[n as usize].vert as usize]
    }

    /// Expected normal of a front node (Eq. 1 with the virtual triangle).
    pub(super) fn expected_normal(&self, n: u32) -> DVec3 {
        let nd = self.ring.nodes[n as usize];
        let base = self.acc[nd.vert as usize];
        let (p, v, q) = (self.p(nd.prev), self.p(n), self.p(nd.next));
        let mut s = base;
        if let Some((wt, nv)) = face_weight(v, p, v, q) {
            s += if base.dot(nv) < 0.0 {
                -wt * nv
            } else {
                wt * nv
            };
        }
        unit_or(s, self.fallback_normal)
    }

    /// The front angle at a node, on the hole side, in the tangent plane of `nrm`.
    pub(super) fn angle(&self, n: u32, nrm: DVec3) -> f64 {
        let nd = self.ring.nodes[n as usize];
        let v = self.p(n);
        let en = self.p(nd.next) - v;
        let ep = self.p(nd.prev) - v;
        let tn = unit_or(en - nrm * en.dot(nrm), unit_or(en, DVec3::ZERO));
        let tp = unit_or(ep - nrm * ep.dot(nrm), unit_or(ep, DVec3::ZERO));
        let t = nrm.dot(tn.cross(tp)).atan2(tn.dot(tp));
        if t < 0.0 {
            t + TAU
        } else {
            t
        }
    }

    pub(super) fn push(&mut self, n: u32) {
        let nrm = self.expected_normal(n);
        let theta = self.angle(n, nrm);
        let nd = &mut self.ring.nodes[n as usize];
        nd.version = nd.version.wrapping_add(1);
        self.heap.push(Entry {
            key: theta + TAU * nd.data.fails as f64,
            node: n,
            version: nd.version,
            data: theta,
        });
    }

    /// Re-measures a node whose neighbourhood changed.
    pub(super) fn refresh(&mut self, n: u32) {
        if self.ring.nodes[n as usize].alive {
            self.ring.nodes[n as usize].data.fails = 0;
            self.push(n);
        }
    }

    pub(super) fn penalize(&mut self, n: u32) {
        if self.ring.nodes[n as usize].alive {
            self.ring.nodes[n as usize].data.fails += 1;
            self.push(n);
        }
    }

    /// The current smallest entry (stale entries are dropped).
    pub(super) fn peek(&mut self) -> Option<Entry<f64>> {
        while let Some(e) = self.heap.peek() {
            let nd = self.ring.nodes[e.node as usize];
            if nd.alive && nd.version == e.version {
                return Some(e);
            }
            self.heap.pop();
        }
        None
    }

    /// `Err` when the front has run away (see `wavefront.max_area_ratio`). Checked while
    /// the front advances only: the residual closing of a front stopped early may
    /// rightly make a deep patch.
    pub(super) fn check_area(&self, opts: &Wavefront) -> Result<(), FillError> {
        if self.area > self.max_area {
            return Err(FillError::Runaway {
                key: "wavefront.max_area_ratio",
                max_area_ratio: opts.max_area_ratio,
            });
        }
        Ok(())
    }

    /// Runs the front until it closes, from where it stands (a fresh wave, or a copy
    /// kept by an earlier run: the loop's state is in the wave).
    pub(super) fn run(&mut self, ctx: &FillContext, opts: &Wavefront) -> Result<(), FillError> {
        let cap = opts.max_steps_per_vertex.saturating_mul(self.k);
        let mu = opts.mu.to_radians();
        let (alpha, beta) = (opts.alpha.to_radians(), opts.beta.to_radians());
        while !self.ring.alive().is_empty() {
            ctx.deadline.check()?;
            if self.snapshot_at.contains(&self.steps) {
                let mut copy = self.clone();
                copy.snapshot_at.clear();
                copy.snapshots.clear();
                self.snapshots.push((self.steps, copy));
            }
            self.steps += 1;
            let steps = self.steps;
            self.stats.steps = steps;
            if steps > cap {
                // out of steps: close what is left as residual fronts
                return self.close_residual_fronts(ctx).map_err(|e| {
                    FillError::stuck(format!(
                        "the front did not close within {cap} steps (max_steps_per_vertex = {}) \
                         and its residual could not be closed: {e}",
                        opts.max_steps_per_vertex
                    ))
                });
            }
            let node = match self.peek() {
                Some(e) if e.data < mu && self.ring.nodes[e.node as usize].data.fails == 0 => {
                    e.node
                }
                _ => {
                    self.stats.random_picks += 1;
                    let i = self.rng.random_range(0..self.ring.alive().len());
                    self.ring.alive()[i]
                }
            };
            let advanced = self.process(node, alpha, beta);
            if self.corrupt {
                return Err(FillError::internal(
                    "internal error: the front lost its shape",
                ));
            }
            self.check_area(opts)?;
            if advanced {
                self.stalls = 0;
                self.relaxed = false;
            } else {
                self.stalls += 1;
                self.stats.failed_steps += 1;
                self.penalize(node);
                if self.stalls > 2 * self.ring.alive().len() + 16 && !self.relaxed {
                    // stuck: accept thin triangles until the next step succeeds; the
                    // sliver flips repair them or the checks reject the patch
                    self.relaxed = true;
                    self.stats.relaxed_steps += 1;
                    self.stalls = 0;
                } else if self.stalls > 2 * self.ring.alive().len() + 16 {
                    // stuck: close every remaining front as a residual loop
                    let left = self.ring.alive().len();
                    return self.close_residual_fronts(ctx).map_err(|e| {
                        FillError::stuck(format!(
                            "the front is stuck (none of its {left} vertices can advance without \
                             an overlap, a duplicate edge or a degenerate triangle) and its \
                             residual could not be closed: {e}"
                        ))
                    });
                }
            }
        }
        Ok(())
    }

    /// Closes every remaining front with [`residual::close`] (see that module).
    pub(super) fn close_residual_fronts(&mut self, ctx: &FillContext) -> Result<(), FillError> {
        while let Some(&start) = self.ring.alive().first() {
            ctx.deadline.check()?;
            let f = self.ring.nodes[start as usize].front as usize;
            let mut ring = vec![start];
            let mut a = self.ring.nodes[start as usize].next;
            while a != start {
                if ring.len() > self.ring.nodes.len() {
                    return Err(FillError::internal("internal error: open front"));
                }
                ring.push(a);
                a = self.ring.nodes[a as usize].next;
            }
            let verts: Vec<u32> = ring
                .iter()
                .map(|&n| self.ring.nodes[n as usize].vert)
                .collect();
            if verts.iter().collect::<HashSet<_>>().len() != verts.len() {
                return Err(FillError::bad_loop(
                    "the residual front passes a vertex twice",
                ));
            }
            let n = verts.len();
            if n < 3 {
                return Err(FillError::bad_loop(format!(
                    "a residual front of {n} vertices"
                )));
            }
            let pts: Vec<DVec3> = verts.iter().map(|&v| self.pos[v as usize]).collect();
            let mut forbidden = HashSet::default();
            for i in 0..n {
                for j in i + 2..n {
                    if (i, j) != (0, n - 1) && self.edge_exists(verts[i], verts[j]) {
                        forbidden.insert((i as u32, j as u32));
                    }
                }
            }
            let on_ring: HashSet<u32> = verts.iter().copied().collect();
            let mut outside = vec![None; n];
            let mut context = Vec::new();
            let mut around: Vec<u32> = Vec::new();
            for (id, t) in self.placed.iter().enumerate() {
                if !t
                    .ids
                    .iter()
                    .any(|c| c.is_some_and(|c| on_ring.contains(&c)))
                {
                    continue;
                }
                context.push(t.p);
                around.push(id as u32);
                for c in 0..3 {
                    if let (Some(a), Some(b)) = (t.ids[c], t.ids[(c + 1) % 3]) {
                        // the triangle outside ring edge i -> i+1 holds the half-edge i+1 -> i
                        if let Some(i) = verts.iter().position(|&x| x == b) {
                            if verts[(i + 1) % n] == a && t.n != DVec3::ZERO {
                                outside[i] = Some(t.n);
                            }
                        }
                    }
                }
            }
            let input = residual::Residual {
                ring: &pts,
                forbidden: &forbidden,
                outside_normals: &outside,
                context: &context,
                edge_length: self.len,
            };
            let closed = residual::close_keeping_unfaired(&input, ctx.policy, &ctx.deadline)?;
            let base = self.pos.len() as u32;
            let map = |i: u32| {
                if (i as usize) < n {
                    verts[i as usize]
                } else {
                    base + i - n as u32
                }
            };
            let tris = closed.triangles;
            let mut new_pts = closed.new_vertices;
            // the fairing can push the piece through the front's own triangles (a
            // residual inside a fold of the front): then the unfaired piece (on its
            // minimum-area triangulation), when that one crosses none of those around
            // the ring
            if let Some(flat) = closed.unfaired {
                if self.crosses_around(&around, &tris, map, &new_pts, base)
                    && !self.crosses_around(&around, &tris, map, &flat, base)
                {
                    new_pts = flat;
                    self.stats.unfaired_residuals += 1;
                }
            }
            for p in new_pts {
                self.pos.push(p);
                self.acc.push(DVec3::ZERO);
            }
            for t in tris {
                self.add_triangle(t.map(map));
            }
            for node in ring {
                self.kill(node);
            }
            self.ring.front_size[f] = 0;
            self.stats.residual_fronts += 1;
        }
        Ok(())
    }

    /// Does a triangle of a residual piece (`tris` in ring numbering, mapped to patch
    /// numbering by `map`; new vertex `base + i` at `new_pts[i]`) cross one of the
    /// triangles in place `around` it (those with a corner on its ring: the front's and
    /// the mesh faces there, which a bulging piece meets first), away from their shared
    /// corners? The test of [`Wave::valid`]'s non-projected case. A choice between two
    /// pieces only: the patch checks test the patch against everything.
    pub(super) fn crosses_around(
        &self,
        around: &[u32],
        tris: &[[u32; 3]],
        map: impl Fn(u32) -> u32,
        new_pts: &[DVec3],
        base: u32,
    ) -> bool {
        let at = |v: u32| {
            if v < base {
                self.pos[v as usize]
            } else {
                new_pts[(v - base) as usize]
            }
        };
        let pieces: Vec<([u32; 3], [DVec3; 3], Box3)> = tris
            .iter()
            .map(|t| {
                let ids = t.map(&map);
                let p = ids.map(at);
                (ids, p, Box3::of(&p))
            })
            .collect();
        around.iter().any(|&id| {
            let pl = &self.placed[id as usize];
            let pb = Box3 {
                lo: pl.lo,
                hi: pl.hi,
            };
            pieces
                .iter()
                .any(|(ids, p, b)| b.meets(&pb) && cross3d(ids.map(Some), p, pl.ids, &pl.p))
        })
    }
}
