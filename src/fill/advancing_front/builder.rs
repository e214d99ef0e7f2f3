//! The front of the advancing front (paper 002 §5.3): its nodes, the queue of front
//! angles, merging and splitting fronts, the run loop, closing small fronts, and the
//! finished patch. The step rules are in [`super::step`].

use super::*;

/// What an advancing-front node ([`Node`](crate::fill::kit::front::Node): a vertex occurrence on a front; a
/// vertex shared by two fronts after a merge has one node in each) carries besides
/// its place on the ring.
#[derive(Clone, Copy, Debug)]
pub(super) struct NodeData {
    /// Set aside: no valid step at it since it last changed.
    pub(super) blocked: bool,
    /// Unit normal of the triangle behind the front edge `self -> next`.
    pub(super) behind: DVec3,
}

/// The local frame at a front vertex.
#[derive(Clone, Copy, Debug)]
pub(super) struct Eval {
    pub(super) theta: f64,
    pub(super) nc: DVec3,
    pub(super) a_hat: DVec3,
    pub(super) perp: DVec3,
    pub(super) l: f64,
    /// Size carried to new vertices.
    pub(super) s_local: f64,
    pub(super) cos_phi: f64,
}

/// A patch vertex of a planned step: new, or an existing front vertex (merge).
#[derive(Clone, Copy, Debug)]
pub(super) enum Slot {
    New(DVec3),
    Merge(u32),
}

/// A checked step at front node `x`: the front `prev, x, next` becomes
/// `prev, slots..., next`.
#[derive(Clone, Debug)]
pub(super) struct Plan {
    pub(super) x: u32,
    pub(super) slots: Vec<Slot>,
    pub(super) new_pos: Vec<DVec3>,
    /// Size field value of the new vertices.
    pub(super) size: f64,
    pub(super) tris: Vec<[u32; 3]>,
}

pub(super) struct Builder<'a> {
    pub(super) ctx: &'a FillContext<'a>,
    pub(super) p: Params,
    pub(super) k: usize,
    pub(super) pos: Vec<DVec3>,
    pub(super) loop_normal: Vec<DVec3>,
    pub(super) acc: Vec<DVec3>,
    /// Target edge length carried by each vertex (the size field).
    pub(super) size: Vec<f64>,
    pub(super) hole_normal: DVec3,
    pub(super) tris: Vec<[u32; 3]>,
    pub(super) edges: FxSet<(u32, u32)>,
    pub(super) forbidden: FxSet<(u32, u32)>,
    /// The fronts (their nodes and sizes).
    pub(super) ring: Ring<NodeData>,
    pub(super) heap: FrontQueue,
    pub(super) node_grid: Grid,
    pub(super) node_scratch: Vec<u32>,
    pub(super) mesh_tris: Vec<[DVec3; 3]>,
    pub(super) obstacles: Obstacles,
    pub(super) cell: f64,
    /// The grids' origin: the loop's centroid.
    pub(super) origin: DVec3,
    pub(super) steps: usize,
    pub(super) applied: usize,
    pub(super) set_aside: usize,
    /// Fronts closed by [`Builder::close_residual`].
    pub(super) residual_fronts: usize,
}

impl<'a> Builder<'a> {
    pub(super) fn new(ctx: &'a FillContext<'a>, p: Params) -> Result<Builder<'a>, FillError> {
        let mesh = ctx.mesh;
        let hole = &ctx.hole.vertices;
        let k = hole.len();
        if hole.iter().any(|v| v.idx() >= mesh.num_vertices()) {
            return Err(FillError::bad_loop("hole vertex out of range"));
        }
        let pos: Vec<DVec3> = hole.iter().map(|&v| mesh.pos(v)).collect();
        if pos.iter().any(|q| !q.is_finite()) {
            return Err(FillError::bad_loop(
                "hole has a vertex with a non-finite coordinate",
            ));
        }
        let mut index: HashMap<VertexId, u32> =
            HashMap::with_capacity_and_hasher(k, Default::default());
        for (i, &v) in hole.iter().enumerate() {
            if index.insert(v, i as u32).is_some() {
                return Err(FillError::bad_loop(format!(
                    "the loop visits vertex {v} twice"
                )));
            }
        }
        let perimeter: f64 = (0..k).map(|i| (pos[(i + 1) % k] - pos[i]).length()).sum();
        let lmean = perimeter / k as f64;
        if !(lmean > 0.0 && lmean.is_finite()) {
            return Err(FillError::bad_loop("the loop has zero length"));
        }
        let loop_normal: Vec<DVec3> = hole.iter().map(|&v| mesh.vertex_normal(v)).collect();
        let mut hole_normal = measure::newell_normal(&pos);
        if hole_normal == DVec3::ZERO {
            hole_normal = loop_normal
                .iter()
                .copied()
                .sum::<DVec3>()
                .normalize_or_zero();
        }
        if hole_normal == DVec3::ZERO {
            return Err(FillError::bad_loop(
                "cannot orient the hole (no loop or vertex normal)",
            ));
        }
        // mesh edges between loop vertices that are not loop edges
        let mut forbidden = FxSet::default();
        for (i, &v) in hole.iter().enumerate() {
            for w in mesh.topo.neighbors(v) {
                if let Some(&j) = index.get(&w) {
                    let j = j as usize;
                    if j != (i + 1) % k && i != (j + 1) % k && i != j {
                        forbidden.insert(edge_key(i as u32, j as u32));
                    }
                }
            }
        }
        let mut edges = FxSet::default();
        edges.reserve(k * 8);
        for i in 0..k {
            edges.insert(edge_key(i as u32, ((i + 1) % k) as u32));
        }
        // the mesh face behind each loop edge i -> i+1 holds the half-edge i+1 -> i
        let mut ring = Ring::new(k);
        for i in 0..k {
            let a = hole[(i + 1) % k];
            let b = hole[i];
            let behind = mesh
                .topo
                .outgoing(a)
                .find(|&h| mesh.topo.to(h) == b)
                .map(|h| mesh.face_normal_raw(h.face()).normalize_or_zero())
                .unwrap_or(DVec3::ZERO);
            let data = NodeData {
                blocked: false,
                behind,
            };
            ring.push(
                i as u32,
                ((i + k - 1) % k) as u32,
                ((i + 1) % k) as u32,
                0,
                data,
            );
        }
        let cell = lmean;
        let origin = measure::centroid(&pos);
        let mut node_grid = Grid::new(cell, origin);
        for (i, q) in pos.iter().enumerate() {
            node_grid.insert_point(*q, i as u32);
        }
        // mesh triangles near the hole: its box grown by half its diagonal and a few edges
        let (lo, hi) = pos.iter().fold(
            (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
            |(l, h), q| (l.min(*q), h.max(*q)),
        );
        let margin = 0.5 * (hi - lo).length() + 4.0 * lmean;
        let (lo, hi) = (lo - DVec3::splat(margin), hi + DVec3::splat(margin));
        let mut obstacles = Obstacles::new(2.0 * cell, origin);
        let mut mesh_tris = Vec::new();
        // A triangle's box misses [lo, hi] when on some axis all three corners lie
        // beyond the same side: the per-vertex outcodes (one bit per side and axis)
        // then share a bit. One pass over the vertices and one over the faces'
        // indices, instead of loading every triangle's corners (10M-face scans).
        let outcode: Vec<u8> = mesh
            .positions
            .iter()
            .map(|q| {
                let below = q.cmplt(lo).bitmask() as u8;
                let above = q.cmpgt(hi).bitmask() as u8;
                // a non-finite corner gives a non-finite box: skipped as before
                if q.is_finite() {
                    below | above << 3
                } else {
                    0x40
                }
            })
            .collect();
        for (f, fv) in mesh.topo.faces().iter().enumerate() {
            let codes = fv.map(|v| outcode.get(v.idx()).copied().unwrap_or(0x40));
            if codes[0] & codes[1] & codes[2] != 0 || (codes[0] | codes[1] | codes[2]) & 0x40 != 0 {
                continue;
            }
            let t = mesh.tri(crate::mesh::FaceId::from_idx(f));
            obstacles.add(t);
            mesh_tris.push(t);
        }
        let acc = vec![DVec3::ZERO; k];
        let size: Vec<f64> = (0..k)
            .map(|i| {
                let m = mesh.mean_incident_edge_length(hole[i]);
                if m > 0.0 && m.is_finite() {
                    m
                } else {
                    0.5 * ((pos[(i + 1) % k] - pos[i]).length()
                        + (pos[(i + k - 1) % k] - pos[i]).length())
                }
            })
            .collect();
        Ok(Builder {
            ctx,
            p,
            k,
            pos,
            loop_normal,
            acc,
            size,
            hole_normal,
            tris: Vec::new(),
            edges,
            forbidden,
            ring,
            heap: FrontQueue::new(),
            node_grid,
            node_scratch: Vec::new(),
            mesh_tris,
            obstacles,
            cell,
            origin,
            steps: 0,
            applied: 0,
            set_aside: 0,
            residual_fronts: 0,
        })
    }

    // ----- geometry -------------------------------------------------------------

    pub(super) fn vnormal(&self, v: u32) -> DVec3 {
        let v = v as usize;
        if v < self.k && self.loop_normal[v] != DVec3::ZERO {
            return self.loop_normal[v];
        }
        let n = self.acc[v].normalize_or_zero();
        if n == DVec3::ZERO {
            self.hole_normal
        } else {
            n
        }
    }

    pub(super) fn npos(&self, node: u32) -> DVec3 {
        self.pos[self.ring.nodes[node as usize].vert as usize]
    }

    pub(super) fn emit(&mut self, t: [u32; 3]) -> DVec3 {
        let [a, b, c] = t.map(|i| self.pos[i as usize]);
        let nr = measure::tri_normal_raw(a, b, c);
        for &v in &t {
            self.acc[v as usize] += nr;
        }
        for c in 0..3 {
            self.edges.insert(edge_key(t[c], t[(c + 1) % 3]));
        }
        self.obstacles.add([a, b, c]);
        self.tris.push(t);
        nr.normalize_or_zero()
    }

    pub(super) fn new_node(&mut self, v: u32, front: u32, behind: DVec3) -> u32 {
        let id = self.ring.nodes.len() as u32;
        let blocked = false;
        self.ring
            .push(v, id, id, front, NodeData { blocked, behind });
        let q = self.pos[v as usize];
        self.node_grid.insert_point(q, id);
        id
    }

    /// Walks the loops through `a` and `b` in turn; returns the start and size of the
    /// one that closes first (cost: twice the smaller size).
    pub(super) fn smaller_loop(&self, a: u32, b: u32) -> Result<(u32, usize), FillError> {
        self.ring
            .shorter_cycle(a, b)
            .ok_or_else(|| FillError::internal("internal: a front is not a closed loop"))
    }

    /// Closes a front of at most four vertices when it can.
    pub(super) fn close_small(&mut self, f: u32, start: u32) -> Result<(), FillError> {
        let size = self.ring.front_size[f as usize];
        if size > 4 {
            return Ok(());
        }
        let ns = self.ring.cycle(start);
        if ns.len() != size {
            return Err(FillError::internal(format!(
                "internal: front of {} nodes recorded as {size}",
                ns.len()
            )));
        }
        let vs: Vec<u32> = ns
            .iter()
            .map(|&c| self.ring.nodes[c as usize].vert)
            .collect();
        match size {
            0..=2 => {}
            3 => {
                let t = [vs[0], vs[1], vs[2]];
                let g = t.map(|i| self.pos[i as usize]);
                if measure::tri_normal_raw(g[0], g[1], g[2]) == DVec3::ZERO {
                    return Err(FillError::stuck(
                        "the last triangle of a front is degenerate",
                    ));
                }
                if self.obstacles.find_overlap(&g, |_| false).is_some() {
                    return Err(FillError::stuck(
                        "the last triangle of a front overlaps the patch or the mesh",
                    ));
                }
                self.emit(t);
            }
            _ => {
                let mut best: Option<(f64, [[u32; 3]; 2])> = None;
                for d in 0..2 {
                    let (a, b, c, e) = (vs[d], vs[d + 1], vs[(d + 2) % 4], vs[(d + 3) % 4]);
                    let pair = [[a, b, c], [c, e, a]];
                    if self.edges.contains(&edge_key(a, c))
                        || ((a as usize) < self.k
                            && (c as usize) < self.k
                            && self.forbidden.contains(&edge_key(a, c)))
                    {
                        continue;
                    }
                    let g = pair.map(|t| t.map(|i| self.pos[i as usize]));
                    let n0 = measure::tri_normal_raw(g[0][0], g[0][1], g[0][2]);
                    let n1 = measure::tri_normal_raw(g[1][0], g[1][1], g[1][2]);
                    let unfolded = n0.dot(n1) > FOLD_COS * n0.length() * n1.length();
                    if !unfolded {
                        continue;
                    }
                    if g.iter().any(|t| {
                        measure::smallest_angle(t[0], t[1], t[2])
                            < self.p.min_angle.min(0.5f64.to_radians())
                    }) {
                        continue;
                    }
                    if g.iter()
                        .any(|t| self.obstacles.find_overlap(t, |_| false).is_some())
                        || intersect::overlap(&g[0], &g[1])
                    {
                        continue;
                    }
                    let q = measure::quality(g[0][0], g[0][1], g[0][2])
                        .min(measure::quality(g[1][0], g[1][1], g[1][2]));
                    if best.is_none_or(|(bq, _)| q > bq) {
                        best = Some((q, pair));
                    }
                }
                let Some((_, pair)) = best else {
                    // no diagonal: a centre vertex, else left to the main loop
                    self.close_fan(start);
                    return Ok(());
                };
                for t in pair {
                    self.emit(t);
                }
            }
        }
        for c in ns {
            self.ring.kill(c);
        }
        Ok(())
    }

    /// Closes the front through `start` with a new vertex at its centroid joined to
    /// every front edge, if all those triangles pass the step checks. Returns whether
    /// it did.
    pub(super) fn close_fan(&mut self, start: u32) -> bool {
        let ns = self.ring.cycle(start);
        let m = ns.len();
        if m < 3 || m != self.ring.front_size[self.ring.nodes[start as usize].front as usize] {
            return false;
        }
        let vs: Vec<u32> = ns
            .iter()
            .map(|&c| self.ring.nodes[c as usize].vert)
            .collect();
        let pts: Vec<DVec3> = vs.iter().map(|&v| self.pos[v as usize]).collect();
        let c = measure::centroid(&pts);
        let mut up = vs.iter().map(|&v| self.vnormal(v)).sum::<DVec3>();
        if up == DVec3::ZERO {
            up = measure::newell_normal(&pts);
        }
        let min_sin = self.p.min_angle.sin();
        let mut geo = Vec::with_capacity(m);
        for j in 0..m {
            let t = [pts[j], pts[(j + 1) % m], c];
            let nr = measure::tri_normal_raw(t[0], t[1], t[2]).normalize_or_zero();
            let behind = self.ring.nodes[ns[j] as usize].data.behind;
            if measure::smallest_angle_sin(t[0], t[1], t[2]) < min_sin
                || nr.dot(up) <= 0.0
                || nr.dot(behind) < FOLD_COS
            {
                return false;
            }
            geo.push(t);
        }
        for (i, g) in geo.iter().enumerate() {
            if self.obstacles.find_overlap(g, |_| false).is_some()
                || geo[i + 1..].iter().any(|h| intersect::overlap(g, h))
            {
                return false;
            }
        }
        let id = self.pos.len() as u32;
        let size = vs.iter().map(|&v| self.size[v as usize]).sum::<f64>() / m as f64;
        self.pos.push(c);
        self.acc.push(DVec3::ZERO);
        self.size.push(size);
        for j in 0..m {
            self.emit([vs[j], vs[(j + 1) % m], id]);
        }
        for n in ns {
            self.ring.kill(n);
        }
        true
    }

    /// Closes every front as a residual front ([`Self::close_residual`]); false when
    /// one cannot be (the fronts closed so far stay closed, and the method fails).
    pub(super) fn close_all_residual(&mut self) -> Result<bool, FillError> {
        while let Some(&n) = self.ring.alive().first() {
            if !self.close_residual(n)? {
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// Closes the front through node `start` as a residual front
    /// ([`residual::close`]: the minimum-weight triangulation of its loop in 3-D,
    /// refined to the size field and faired with the triangles around it fixed), the
    /// last resort of a front that is stuck, divergent or out of steps. The whole patch
    /// is verified when it is finished. False when the loop passes a vertex twice or
    /// the closing fails (a timeout is passed on).
    pub(super) fn close_residual(&mut self, start: u32) -> Result<bool, FillError> {
        let ns = self.ring.cycle(start);
        let m = ns.len();
        let f = self.ring.nodes[start as usize].front as usize;
        if m < 3 || m != self.ring.front_size[f] {
            return Ok(false);
        }
        let vs: Vec<u32> = ns
            .iter()
            .map(|&c| self.ring.nodes[c as usize].vert)
            .collect();
        if vs.iter().collect::<FxSet<_>>().len() != m {
            return Ok(false);
        }
        let pts: Vec<DVec3> = vs.iter().map(|&v| self.pos[v as usize]).collect();
        let mut forbidden = crate::fasthash::HashSet::default();
        for i in 0..m {
            for j in i + 2..m {
                let e = edge_key(vs[i], vs[j]);
                if (i, j) != (0, m - 1) && (self.edges.contains(&e) || self.forbidden.contains(&e))
                {
                    forbidden.insert((i as u32, j as u32));
                }
            }
        }
        let outside: Vec<Option<DVec3>> = ns
            .iter()
            .map(|&c| {
                let b = self.ring.nodes[c as usize].data.behind;
                (b != DVec3::ZERO).then_some(b)
            })
            .collect();
        // the patch triangles and mesh faces with a corner on the front: the fairing's
        // fixed ring (matched by position)
        let on: FxSet<u32> = vs.iter().copied().collect();
        let key = |p: DVec3| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
        let at: FxSet<[u64; 3]> = pts.iter().map(|&p| key(p)).collect();
        let mut context: Vec<[DVec3; 3]> = self
            .tris
            .iter()
            .filter(|t| t.iter().any(|v| on.contains(v)))
            .map(|t| t.map(|v| self.pos[v as usize]))
            .collect();
        context.extend(
            self.mesh_tris
                .iter()
                .filter(|t| t.iter().any(|&p| at.contains(&key(p))))
                .copied(),
        );
        let edge_length = vs.iter().map(|&v| self.size[v as usize]).sum::<f64>() / m as f64;
        let input = residual::Residual {
            ring: &pts,
            forbidden: &forbidden,
            outside_normals: &outside,
            context: &context,
            edge_length,
        };
        let (new_pts, tris) = match residual::close(&input, self.ctx.policy, &self.ctx.deadline) {
            Ok(c) => c,
            Err(FillError::Timeout) => return Err(FillError::Timeout),
            Err(why) => {
                tracing::debug!(%why, m, "advancing front: residual closing failed");
                return Ok(false);
            }
        };
        let base = self.pos.len() as u32;
        for p in new_pts {
            self.pos.push(p);
            self.acc.push(DVec3::ZERO);
            self.size.push(edge_length);
        }
        for t in tris {
            self.emit(t.map(|i| {
                if (i as usize) < m {
                    vs[i as usize]
                } else {
                    base + i - m as u32
                }
            }));
        }
        for n in ns {
            self.ring.kill(n);
        }
        self.residual_fronts += 1;
        tracing::debug!(m, "advancing front: front closed as a residual");
        Ok(true)
    }

    pub(super) fn rekey(&mut self, x: u32) {
        if !self.ring.nodes[x as usize].alive {
            return;
        }
        let ev = self.eval(x);
        let nd = &mut self.ring.nodes[x as usize];
        nd.version = nd.version.wrapping_add(1);
        nd.data.blocked = false;
        self.heap.push(Entry {
            key: ev.theta,
            node: x,
            version: nd.version,
            data: (),
        });
    }

    // ----- main loop ------------------------------------------------------------

    pub(super) fn run(&mut self) -> Result<(), FillError> {
        self.close_small(0, 0)?;
        for x in 0..self.k as u32 {
            self.rekey(x);
        }
        while !self.ring.alive().is_empty() {
            self.ctx.deadline.check()?;
            let Some(e) = self.heap.pop() else {
                return Err(FillError::internal(
                    "internal: front vertices left without a queue entry",
                ));
            };
            let nd = &self.ring.nodes[e.node as usize];
            if !nd.alive || nd.version != e.version {
                continue;
            }
            if nd.data.blocked {
                // every vertex is set aside: close a small front around a centre vertex
                let f = nd.front as usize;
                if self.ring.front_size[f] <= FAN_MAX && self.close_fan(e.node) {
                    continue;
                }
                if self.close_residual(e.node)? {
                    continue;
                }
                return Err(FillError::stuck(format!(
                    "the front is stuck: no valid step at any of its {} vertices",
                    self.ring.alive().len()
                )));
            }
            self.steps += 1;
            let cap = self.ctx.policy.limits.max_patch_triangles;
            if cap > 0 && self.tris.len() > cap {
                return Err(FillError::TooLarge(TooLarge::Front {
                    cap,
                    front: self.ring.alive().len(),
                }));
            }
            if self.steps > self.p.max_steps {
                if self.close_all_residual()? {
                    break;
                }
                return Err(FillError::stuck(format!(
                    "front did not close after {} steps ({} taken, {} set aside; {} triangles, {} front vertices left)",
                    self.p.max_steps,
                    self.applied,
                    self.set_aside,
                    self.tris.len(),
                    self.ring.alive().len()
                )));
            }
            let ev = self.eval(e.node);
            if ev.theta > e.key + 1e-12 {
                if let Some(top) = self.heap.peek() {
                    if top.key < ev.theta {
                        let nd = &mut self.ring.nodes[e.node as usize];
                        nd.version = nd.version.wrapping_add(1);
                        self.heap.push(Entry {
                            key: ev.theta,
                            node: e.node,
                            version: nd.version,
                            data: (),
                        });
                        continue;
                    }
                }
            }
            match self.try_steps(e.node, &ev) {
                Some(plan) => {
                    self.applied += 1;
                    self.apply(plan)?;
                    if self.ring.alive().len() > DIVERGE_FACTOR * self.k + 64 {
                        if self.close_all_residual()? {
                            break;
                        }
                        return Err(FillError::stuck(format!(
                            "the front diverges: {} front vertices from a loop of {} after {} steps",
                            self.ring.alive().len(), self.k, self.steps
                        )));
                    }
                }
                None => {
                    let nd = &mut self.ring.nodes[e.node as usize];
                    nd.version = nd.version.wrapping_add(1);
                    nd.data.blocked = true;
                    self.set_aside += 1;
                    self.heap.push(Entry {
                        key: ev.theta + BLOCKED,
                        node: e.node,
                        version: nd.version,
                        data: (),
                    });
                }
            }
        }
        Ok(())
    }

    // ----- finishing ------------------------------------------------------------

    /// True when no two patch triangles overlap and none overlaps the mesh.
    pub(super) fn patch_is_clean(&self, pos: &[DVec3], tris: &[[u32; 3]]) -> bool {
        // the dispatcher's degenerate-triangle rule first (fairing can make slivers)
        let patch = Patch {
            new_vertices: Vec::new(),
            triangles: tris.to_vec(),
        };
        if crate::check::check_degenerate(pos, &patch, &self.ctx.policy.checks).is_err() {
            return false;
        }
        let mut ob = Obstacles::new(2.0 * self.cell, self.origin);
        for t in &self.mesh_tris {
            ob.add(*t);
        }
        let first = ob.len() as u32;
        let geo: Vec<[DVec3; 3]> = tris.iter().map(|t| t.map(|i| pos[i as usize])).collect();
        for g in &geo {
            ob.add(*g);
        }
        geo.iter()
            .enumerate()
            .all(|(i, g)| ob.find_overlap(g, |id| id == first + i as u32).is_none())
    }

    pub(super) fn finish(self) -> Result<Patch, FillError> {
        let k = self.k;
        let rules = improve::SwapRules {
            k,
            forbidden: &self.forbidden,
            min_angle: self.p.min_angle.min(0.5f64.to_radians()),
        };
        let raw_tris = self.tris.clone();
        let mut tris = self.tris.clone();
        let t = std::time::Instant::now();
        let n_swaps = improve::swap_edges(&self.pos, &mut tris, &rules, SWAPS_PER_TRIANGLE);
        tracing::debug!(
            ms = t.elapsed().as_secs_f64() * 1e3,
            n_swaps,
            "advancing front: swaps"
        );
        self.ctx.deadline.check()?;
        let mut candidates: Vec<(Vec<DVec3>, Vec<[u32; 3]>)> = Vec::new();
        if self.p.fair {
            // umbrella relaxation evens out the triangles, then the fairing solve
            // (`fill::kit::fair`, the `[fair]` policy) gives the patch its shape
            let mut patch = Patch {
                new_vertices: self.pos[k..].to_vec(),
                triangles: tris.clone(),
            };
            let t = std::time::Instant::now();
            let faired = relax(
                self.ctx.mesh,
                self.ctx.hole,
                &mut patch,
                &self.ctx.policy.fair,
            )
            .and_then(|()| {
                // the first solve's cotangent weights come from the flat front; a
                // second solve on the curved result gets them right
                let (mesh, hole, fair) = (self.ctx.mesh, self.ctx.hole, &self.ctx.policy.fair);
                fair::fair_patch(mesh, hole, &mut patch, fair)?;
                fair::fair_patch(mesh, hole, &mut patch, fair)
            });
            match faired {
                Ok(()) if patch.new_vertices.len() == self.pos.len() - k => {
                    let mut pos = self.pos.clone();
                    pos[k..].copy_from_slice(&patch.new_vertices);
                    let mut t2 = patch.triangles;
                    improve::swap_edges(&pos, &mut t2, &rules, SWAPS_PER_TRIANGLE);
                    candidates.push((pos, t2));
                }
                Ok(()) => {
                    tracing::debug!("advancing front: fairing changed the vertex count; not used")
                }
                Err(FillError::Timeout) => return Err(FillError::Timeout),
                Err(why) => {
                    tracing::debug!(%why, "advancing front: fairing failed; not used")
                }
            }
            tracing::debug!(
                ms = t.elapsed().as_secs_f64() * 1e3,
                "advancing front: fairing"
            );
        }
        candidates.push((self.pos.clone(), tris));
        candidates.push((self.pos.clone(), raw_tris));
        for (pos, tris) in candidates {
            self.ctx.deadline.check()?;
            let t = std::time::Instant::now();
            let clean = self.patch_is_clean(&pos, &tris);
            tracing::debug!(
                ms = t.elapsed().as_secs_f64() * 1e3,
                clean,
                "advancing front: patch verified"
            );
            if clean {
                return Ok(Patch {
                    new_vertices: pos[k..].to_vec(),
                    triangles: tris,
                });
            }
        }
        Err(FillError::stuck(
            "the closed front overlaps itself or the mesh",
        ))
    }
}
