//! One step of the wavefront (paper 004 §2.2, §2.2.1): the rule's variant at a front
//! vertex (one triangle, one or two new points), their placement and curvature
//! restoration, the validity tests of a planned step, and committing it (merging into a
//! front vertex splits the front).

use super::wave::*;
use super::*;

impl Wave {
    /// One step at `node`; false when no variant is valid.
    pub(super) fn process(&mut self, node: u32, alpha: f64, beta: f64) -> bool {
        let nd = self.ring.nodes[node as usize];
        let (pn, nn) = (nd.prev, nd.next);
        let nv = self.expected_normal(node);
        if self.relaxed && self.ring.front_size[nd.front as usize] <= SMALL_FRONT {
            return self.clip_small_front(node);
        }
        if self.ring.front_size[nd.front as usize] == 3 {
            let t = [
                self.ring.nodes[pn as usize].vert,
                nd.vert,
                self.ring.nodes[nn as usize].vert,
            ];
            if !self.valid(nd.vert, &[t], &[], nv, 0.0) {
                return false;
            }
            self.add_triangle(t);
            for x in [pn, node, nn] {
                self.kill(x);
            }
            self.ring.front_size[nd.front as usize] = 0;
            return true;
        }
        let theta = self.angle(node, nv);
        let np = self.expected_normal(pn);
        let nq = self.expected_normal(nn);
        let order: &[usize] = if theta <= alpha {
            &[0, 1]
        } else if theta <= beta {
            &[1, 0, 2]
        } else {
            &[2, 1]
        };
        for &m in order {
            if let Some(plan) = self.plan(node, m, theta, [np, nv, nq]) {
                self.commit(node, plan);
                return true;
            }
        }
        false
    }

    /// Elevation (radians, out of the tangent plane of `nrm`) of the front on one side of
    /// a node, at distance `Avglen`: for the `j`-th front neighbour at distance `s_j` the
    /// chord's elevation `e_j` is about `-κ s_j / 2` on a smooth front, so the estimate is
    /// `Avglen · mean_j(e_j / s_j)` over `FRONT_SPAN` neighbours (fewer on a short front). A
    /// zig-zag of amplitude `a` adds only about `a / s_j²` per neighbour.
    pub(super) fn side_elevation(&self, node: u32, nrm: DVec3, forward: bool) -> f64 {
        let v = self.p(node);
        let other_end = if forward {
            self.ring.nodes[node as usize].prev
        } else {
            self.ring.nodes[node as usize].next
        };
        let mut a = node;
        let (mut sum, mut n) = (0.0, 0usize);
        for _ in 0..FRONT_SPAN {
            let nd = self.ring.nodes[a as usize];
            a = if forward { nd.next } else { nd.prev };
            if a == node || (n > 0 && a == other_end) {
                break;
            }
            let e = self.p(a) - v;
            let s = e.length();
            if s > 0.0 {
                sum += (e.dot(nrm) / s).clamp(-1.0, 1.0).asin() / s;
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            (self.len * sum / n as f64).clamp(-MAX_EL, MAX_EL)
        }
    }

    /// Last resort for a small stuck front: ear clipping without the overlap and angle
    /// tests (best smallest angle first among ears facing the front's mean normal, else
    /// the best ear). The dispatcher's checks judge the result.
    pub(super) fn clip_small_front(&mut self, start: u32) -> bool {
        let f = self.ring.nodes[start as usize].front as usize;
        let mut ring = vec![start];
        let mut a = self.ring.nodes[start as usize].next;
        while a != start && ring.len() <= SMALL_FRONT {
            ring.push(a);
            a = self.ring.nodes[a as usize].next;
        }
        if a != start || ring.len() < 3 {
            return false;
        }
        let vert = |w: &Wave, n: u32| w.ring.nodes[n as usize].vert;
        let pts: Vec<DVec3> = ring.iter().map(|&n| self.p(n)).collect();
        let nrm = unit_or(measure::newell_normal(&pts), self.expected_normal(start));
        while ring.len() > 3 {
            let m = ring.len();
            let mut best: Option<(bool, f64, usize)> = None;
            for i in 0..m {
                let t = [ring[(i + m - 1) % m], ring[i], ring[(i + 1) % m]].map(|n| vert(self, n));
                if self.edge_exists(t[0], t[2]) {
                    continue;
                }
                let p = t.map(|x| self.pos[x as usize]);
                let n = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO);
                let ang = measure::angles(p[0], p[1], p[2]);
                let key = (n.dot(nrm) > FACING_MIN, ang[0].min(ang[1]).min(ang[2]), i);
                if best.is_none_or(|b| (key.0, key.1) > (b.0, b.1)) {
                    best = Some(key);
                }
            }
            let Some((_, _, i)) = best else { return false };
            let t = [ring[(i + m - 1) % m], ring[i], ring[(i + 1) % m]].map(|n| vert(self, n));
            self.add_triangle(t);
            self.kill(ring[i]);
            ring.remove(i);
        }
        let t = [ring[0], ring[1], ring[2]].map(|n| vert(self, n));
        self.add_triangle(t);
        for n in ring {
            self.kill(n);
        }
        self.ring.front_size[f] = 0;
        self.stats.clipped_fronts += 1;
        true
    }

    /// Direction from the vertex at fraction `f` of θ from the next edge (see module doc).
    pub(super) fn direction(&self, node: u32, nrm: DVec3, theta: f64, f: f64) -> DVec3 {
        let nd = self.ring.nodes[node as usize];
        let v = self.p(node);
        let en = unit_or(self.p(nd.next) - v, DVec3::ZERO);
        let tn = unit_or(en - nrm * en.dot(nrm), nrm.any_orthonormal_vector());
        let bn = nrm.cross(tn);
        let (s, c) = (f * theta).sin_cos();
        let dt = tn * c + bn * s;
        let el_n = self.side_elevation(node, nrm, true);
        let el_p = self.side_elevation(node, nrm, false);
        let interp = (1.0 - f) * el_n + f * el_p;
        let el = match self.placement {
            WavefrontPlacement::Interpolated => interp,
            WavefrontPlacement::EdgePlane if theta < PI => {
                // the plane of the two edges as a height function over the tangent plane:
                // slope g·d with g·t_n = tan el_n and g·t_p = tan el_p
                let (hn, hp) = (
                    el_n.clamp(-MAX_EL, MAX_EL).tan(),
                    el_p.clamp(-MAX_EL, MAX_EL).tan(),
                );
                let st = theta.sin();
                let w = (st / PLANE_WINDOW.sin()).clamp(0.0, 1.0);
                if w > 0.0 {
                    let g2 = (hp - hn * theta.cos()) / st;
                    w * (hn * c + g2 * s).atan() + (1.0 - w) * interp
                } else {
                    interp
                }
            }
            WavefrontPlacement::EdgePlane => interp,
        };
        let (se, ce) = el.sin_cos();
        dt * ce + nrm * se
    }

    /// The nearest live node of `front` within `r` of `x`, other than `skip`.
    pub(super) fn nearest_node(
        &mut self,
        x: DVec3,
        r: f64,
        front: u32,
        skip: [u32; 3],
    ) -> Option<u32> {
        let mut ids = std::mem::take(&mut self.scratch);
        let d = DVec3::splat(r);
        self.node_grid.query_box(x - d, x + d, &mut ids);
        let mut best: Option<(f64, u32)> = None;
        for &id in &ids {
            let nd = self.ring.nodes[id as usize];
            if !nd.alive || nd.front != front || skip.contains(&id) {
                continue;
            }
            let dist = (self.pos[nd.vert as usize] - x).length();
            // ties go to the smallest id (the query's order is arbitrary)
            if dist < r && best.is_none_or(|(b, bid)| dist < b || (dist == b && id < bid)) {
                best = Some((dist, id));
            }
        }
        self.scratch = ids;
        best.map(|b| b.1)
    }

    /// Does `x` project (onto the loop's best-fit plane) inside the loop or within
    /// `Avglen / 2` of it? (Points nearer the centre than every loop vertex are inside
    /// without a look at the loop.)
    pub(super) fn inside_loop(&self, x: DVec3) -> bool {
        let d = x - self.centre;
        let (px, py) = (d.dot(self.plane_u), d.dot(self.plane_w));
        px * px + py * py < self.inner * self.inner
            || inside_or_near(&self.loop2d, (px, py), 0.5 * self.len)
    }

    /// Is `x` within `clear` of an edge of `front` whose ends are not in `skip`, yet not
    /// near enough to one of its ends to merge? (Edges are found from their ends within
    /// `clear + 1.5 Avglen` of `x`.)
    pub(super) fn near_front_edge(
        &mut self,
        x: DVec3,
        clear: f64,
        front: u32,
        skip: [u32; 3],
    ) -> bool {
        let mut ids = std::mem::take(&mut self.scratch);
        let d = DVec3::splat(clear + 1.5 * self.len);
        self.node_grid.query_box(x - d, x + d, &mut ids);
        let mut hit = false;
        for &id in &ids {
            let nd = self.ring.nodes[id as usize];
            if !nd.alive || nd.front != front {
                continue;
            }
            let b = self.ring.nodes[nd.next as usize].vert;
            if skip.contains(&nd.vert) || skip.contains(&b) {
                continue;
            }
            let (p, q) = (self.pos[nd.vert as usize], self.pos[b as usize]);
            // edges found from their ends in the box (whatever else the grid returns)
            if (p - x).abs().cmpgt(d).any() {
                continue;
            }
            let e = q - p;
            let t = ((x - p).dot(e) / e.length_squared().max(1e-300)).clamp(0.0, 1.0);
            if (p + e * t - x).length() < clear && t > 0.0 && t < 1.0 {
                hit = true;
                break;
            }
        }
        self.scratch = ids;
        hit
    }

    pub(super) fn edge_exists(&self, a: u32, b: u32) -> bool {
        let e = edge_key(a, b);
        self.edges.contains(&e)
            || ((a as usize) < self.k && (b as usize) < self.k && self.mesh_edges.contains(&e))
    }

    /// Builds and validates the variant with `m` new points (0, 1 or 2).
    pub(super) fn plan(
        &mut self,
        node: u32,
        m: usize,
        theta: f64,
        [np, nv, nq]: [DVec3; 3],
    ) -> Option<Plan> {
        let nd = self.ring.nodes[node as usize];
        let (pn, nn) = (nd.prev, nd.next);
        let (p, v, q) = (self.p(pn), self.p(node), self.p(nn));
        let mut pts: Vec<DVec3> = (1..=m)
            .map(|j| {
                v + self.direction(node, nv, theta, 1.0 - j as f64 / (m + 1) as f64) * self.len
            })
            .collect();
        if self.restore && m > 0 {
            let rot = |x: DVec3, a: DVec3, b: DVec3, c: DVec3, want: DVec3| {
                let n = unit_or((b - a).cross(c - a), DVec3::ZERO);
                let want = unit_or(want, DVec3::ZERO);
                if n == DVec3::ZERO || want == DVec3::ZERO {
                    x
                } else {
                    rotate_to(x, (a + b + c) / 3.0, n, want)
                }
            };
            // case (b): triangles (p, v, x) and (x, v, q); case (c): the two outer ones
            let first = rot(pts[0], p, v, pts[0], np + nv);
            let last = rot(pts[m - 1], pts[m - 1], v, q, nv + nq);
            if m == 1 {
                pts[0] = (first + last) * 0.5;
            } else {
                pts[0] = first;
                pts[m - 1] = last;
            }
        }
        // merging and the too-close test
        let r = self.merge_radius;
        let mut chain = vec![Item::Node(pn)];
        let mut merged: Option<u32> = None;
        for &x in &pts {
            if !x.is_finite() || (x - self.centre).length() > self.reach || !self.inside_loop(x) {
                return None;
            }
            if r > 0.0 {
                if (x - p).length() < r || (x - q).length() < r || (x - v).length() < r {
                    return None;
                }
                let (pv, vv, qv) = (
                    self.ring.nodes[pn as usize].vert,
                    nd.vert,
                    self.ring.nodes[nn as usize].vert,
                );
                if self.near_front_edge(x, 0.5 * r, nd.front, [pv, vv, qv]) {
                    return None;
                }
                if let Some(a) = self.nearest_node(x, r, nd.front, [pn, node, nn]) {
                    match merged {
                        None => {
                            merged = Some(a);
                            chain.push(Item::Node(a));
                        }
                        Some(b) if b == a => {}
                        Some(_) => return None,
                    }
                    continue;
                }
            }
            chain.push(Item::New(x));
        }
        chain.push(Item::Node(nn));
        // ids, positions and new edges
        let base = self.pos.len() as u32;
        let mut newpos = Vec::new();
        let ids: Vec<u32> = chain
            .iter()
            .map(|it| match *it {
                Item::Node(a) => self.ring.nodes[a as usize].vert,
                Item::New(x) => {
                    newpos.push(x);
                    base + newpos.len() as u32 - 1
                }
            })
            .collect();
        let old = |i: usize| match chain[i] {
            Item::Node(a) => Some(a),
            Item::New(_) => None,
        };
        for j in 0..chain.len() - 1 {
            if let (Some(a), Some(b)) = (old(j), old(j + 1)) {
                if self.edge_exists(ids[j], ids[j + 1]) {
                    // a merge into the second neighbour closes the edge between them (zip)
                    let zip = (a == pn && b == self.ring.nodes[pn as usize].prev)
                        || (b == nn && a == self.ring.nodes[nn as usize].next);
                    if !zip {
                        return None;
                    }
                }
            }
            if j > 0 && old(j).is_some() && self.edge_exists(nd.vert, ids[j]) {
                return None;
            }
        }
        // the front angles left at v_{i-1} and v_{i+1} must not be slivers in the making
        let pos_of = |j: usize| -> DVec3 {
            match chain[j] {
                Item::Node(a) => self.p(a),
                Item::New(x) => x,
            }
        };
        let last = chain.len() - 1;
        let pp = self.p(self.ring.nodes[pn as usize].prev);
        let qq = self.p(self.ring.nodes[nn as usize].next);
        let front_angle = |at: DVec3, a: DVec3, b: DVec3| measure::angle_at(at, a, b);
        if self.ring.front_size[nd.front as usize] > 3
            && !self.relaxed
            && (front_angle(p, pp, pos_of(1)) < MIN_FRONT_ANGLE
                || front_angle(q, pos_of(last - 1), qq) < MIN_FRONT_ANGLE)
        {
            return None;
        }
        let tris: Vec<[u32; 3]> = (0..chain.len() - 1)
            .map(|j| [ids[j], nd.vert, ids[j + 1]])
            .collect();
        let min_angle = if self.relaxed { 0.0 } else { self.min_angle };
        if !self.valid(nd.vert, &tris, &newpos, nv, min_angle)
            || !self.small_fronts_ok(node, &chain, &ids, &newpos, merged, nv)
        {
            return None;
        }
        Some(Plan { chain })
    }

    /// Would the step leave a front of three vertices whose last triangle is flipped, or
    /// a sliver that cannot be flipped away later (its longest edge on the hole loop)? Walks the fronts after the step
    /// without changing them, at most three nodes from each changed place.
    pub(super) fn small_fronts_ok(
        &self,
        node: u32,
        chain: &[Item],
        ids: &[u32],
        newpos: &[DVec3],
        merged: Option<u32>,
        nrm: DVec3,
    ) -> bool {
        let nd = self.ring.nodes[node as usize];
        let last = chain.len() - 1;
        let base = self.ring.nodes.len() as u32;
        // node ids after the step: chain interior items get fresh ids base + j - 1
        let cnode = |j: usize| -> u32 {
            match chain[j] {
                Item::Node(a) if j == 0 || j == last => a,
                _ => base + j as u32 - 1,
            }
        };
        let mut over: Vec<(u32, u32)> = (0..last).map(|j| (cnode(j), cnode(j + 1))).collect();
        let vert_of = |x: u32| -> u32 {
            if x >= base {
                ids[(x - base) as usize + 1]
            } else {
                self.ring.nodes[x as usize].vert
            }
        };
        if let Some(a) = merged {
            if let Some(jm) = (1..last).find(|&j| matches!(chain[j], Item::Node(x) if x == a)) {
                let b = cnode(jm);
                let an = self.ring.nodes[a as usize].next;
                let bn = cnode(jm + 1);
                over.retain(|&(x, _)| x != b);
                over.push((a, bn));
                over.push((b, an));
            }
        }
        let next = |x: u32| -> u32 {
            over.iter()
                .find(|&&(y, _)| y == x)
                .map(|&(_, z)| z)
                .unwrap_or_else(|| self.ring.nodes[x as usize].next)
        };
        let np = self.pos.len();
        let at = |i: u32| -> DVec3 {
            let i = i as usize;
            if i < np {
                self.pos[i]
            } else {
                newpos[i - np]
            }
        };
        for s in [nd.prev, nd.next] {
            let x1 = next(s);
            let x2 = next(x1);
            if next(x2) != s || x1 == s || x2 == s {
                continue;
            }
            let p = [vert_of(s), vert_of(x1), vert_of(x2)].map(at);
            let n = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO);
            if !(n.dot(nrm) > FACING_MIN) {
                return false;
            }
            // a sliver whose longest edge has a mesh face across cannot be flipped away
            let ang = measure::angles(p[0], p[1], p[2]);
            let c = (0..3).fold(0, |m, c| if ang[c] > ang[m] { c } else { m });
            let v = [vert_of(s), vert_of(x1), vert_of(x2)];
            let (a, b) = (v[(c + 1) % 3], v[(c + 2) % 3]);
            let across_mesh = (a as usize) < self.k
                && (b as usize) < self.k
                && self.mesh_edges.contains(&edge_key(a, b));
            if across_mesh && !self.relaxed && ang.iter().any(|&x| !(x >= self.min_angle)) {
                return false;
            }
        }
        true
    }

    /// Are the step's triangles acceptable (angles, facing, no overlap, no crossing)?
    pub(super) fn valid(
        &mut self,
        v: u32,
        tris: &[[u32; 3]],
        newpos: &[DVec3],
        nrm: DVec3,
        min_angle: f64,
    ) -> bool {
        let np = self.pos.len();
        let at = |i: u32| -> DVec3 {
            let i = i as usize;
            if i < np {
                self.pos[i]
            } else {
                newpos[i - np]
            }
        };
        let mut corners = Vec::with_capacity(tris.len());
        let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
        for t in tris {
            let p = t.map(at);
            if !(measure::smallest_angle(p[0], p[1], p[2]) >= min_angle) {
                return false;
            }
            let n = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO);
            if !(n.dot(nrm) > FACING_MIN) {
                return false;
            }
            for x in p {
                lo = lo.min(x);
                hi = hi.max(x);
            }
            corners.push(p);
        }
        // tangent plane of the vertex
        let o = self.pos[v as usize];
        let u = nrm.any_orthonormal_vector();
        let w = nrm.cross(u);
        let proj = |x: DVec3| p2((x - o).dot(u), (x - o).dot(w));
        let pr = |t: &[DVec3; 3]| [proj(t[0]), proj(t[1]), proj(t[2])];
        for i in 0..corners.len() {
            for j in 0..i {
                if overlap2d(pr(&corners[i]), pr(&corners[j])) {
                    return false;
                }
            }
        }
        // each new triangle once: projected (counter-clockwise, `None` when degenerate,
        // which overlaps everything) and its boxes, which skip the exact tests of the
        // nearby triangles they cannot meet (same answers, fewer predicates)
        let cand: Vec<Candidate> = tris
            .iter()
            .zip(&corners)
            .map(|(t, c)| {
                let p2 = pr(c);
                Candidate {
                    ids: t.map(Some),
                    ccw: ccw2d(p2),
                    box2: Box2::of(&p2),
                    box3: Box3::of(c),
                }
            })
            .collect();
        // the triangles within `Avglen` of the step's box (farther ones cannot meet it)
        let d = DVec3::splat(self.len);
        let (qlo, qhi) = (lo - d, hi + d);
        let mut near = std::mem::take(&mut self.scratch);
        self.tri_grid.query_box(qlo, qhi, &mut near);
        near.extend_from_slice(&self.big);
        let mut ok = true;
        'outer: for &id in &near {
            let pl = &self.placed[id as usize];
            if pl.hi.cmplt(qlo).any() || qhi.cmplt(pl.lo).any() {
                continue;
            }
            if pl.n.dot(nrm) > PROJECT_MIN {
                let q = pr(&pl.p);
                let qb = Box2::of(&q);
                for c in &cand {
                    let hit = match c.ccw {
                        None => true,
                        Some(a) => c.box2.meets(&qb) && overlap2d_ccw(a, q),
                    };
                    if hit {
                        ok = false;
                        break 'outer;
                    }
                }
            } else {
                let pb = Box3::of(&pl.p);
                for (c, corner) in cand.iter().zip(&corners) {
                    if c.box3.meets(&pb) && cross3d(c.ids, corner, pl.ids, &pl.p) {
                        ok = false;
                        break 'outer;
                    }
                }
            }
        }
        self.scratch = near;
        ok
    }

    /// Flips the longest edge of each sliver (smallest angle below twice the checks'
    /// bound, at least 1 degree) with the patch triangle across it when that raises the
    /// smallest angle of the pair, keeps both facing the same way and makes no duplicate
    /// edge. Closing a thin front of three vertices can leave such slivers.
    pub(super) fn flip_slivers(&mut self) {
        let tau = (2.0 * self.min_angle).max(1f64.to_radians());
        let min_of = |p: [DVec3; 3]| {
            let a = measure::angles(p[0], p[1], p[2]);
            a[0].min(a[1]).min(a[2])
        };
        let mut owner: HashMap<(u32, u32), usize> =
            HashMap::with_capacity_and_hasher(self.tris.len() * 3, Default::default());
        for (i, t) in self.tris.iter().enumerate() {
            for c in 0..3 {
                owner.insert((t[c], t[(c + 1) % 3]), i);
            }
        }
        for _round in 0..4 {
            let mut changed = false;
            for i in 0..self.tris.len() {
                let t = self.tris[i];
                let p = t.map(|v| self.pos[v as usize]);
                let ang = measure::angles(p[0], p[1], p[2]);
                if !(ang[0].min(ang[1]).min(ang[2]) < tau) {
                    continue;
                }
                let c = (0..3).fold(0, |m, c| if ang[c] > ang[m] { c } else { m });
                let (x, a, b) = (t[c], t[(c + 1) % 3], t[(c + 2) % 3]);
                let Some(&j) = owner.get(&(b, a)) else {
                    continue;
                };
                let u = self.tris[j];
                let Some(&y) = u.iter().find(|&&q| q != a && q != b) else {
                    continue;
                };
                if y == x || self.edge_exists(x, y) {
                    continue;
                }
                let q = u.map(|v| self.pos[v as usize]);
                let nref = unit_or((p[1] - p[0]).cross(p[2] - p[0]), DVec3::ZERO)
                    + unit_or((q[1] - q[0]).cross(q[2] - q[0]), DVec3::ZERO);
                let t1 = [x, a, y];
                let t2 = [x, y, b];
                let p1 = t1.map(|v| self.pos[v as usize]);
                let p2 = t2.map(|v| self.pos[v as usize]);
                let faces = |r: [DVec3; 3]| {
                    unit_or((r[1] - r[0]).cross(r[2] - r[0]), DVec3::ZERO).dot(nref) > FACING_MIN
                };
                let before = min_of(p).min(min_of(q));
                let after = min_of(p1).min(min_of(p2));
                if !(faces(p1) && faces(p2) && after > before) {
                    continue;
                }
                self.tris[i] = t1;
                self.tris[j] = t2;
                owner.remove(&(a, b));
                owner.remove(&(b, a));
                for (k, tt) in [(i, t1), (j, t2)] {
                    for c in 0..3 {
                        owner.insert((tt[c], tt[(c + 1) % 3]), k);
                    }
                }
                self.edges.remove(&edge_key(a, b));
                self.edges.insert(edge_key(x, y));
                changed = true;
            }
            if !changed {
                break;
            }
        }
    }

    pub(super) fn add_triangle(&mut self, t: [u32; 3]) {
        let p = t.map(|i| self.pos[i as usize]);
        for c in 0..3 {
            self.edges.insert(edge_key(t[c], t[(c + 1) % 3]));
            if let Some((wt, n)) = face_weight(p[c], p[0], p[1], p[2]) {
                self.acc[t[c] as usize] += wt * n;
            }
        }
        self.tris.push(t);
        let cr = (p[1] - p[0]).cross(p[2] - p[0]);
        self.area += 0.5 * cr.length();
        let n = unit_or(cr, DVec3::ZERO);
        self.place(Placed {
            ids: t.map(Some),
            p,
            n,
            lo: DVec3::ZERO,
            hi: DVec3::ZERO,
        });
    }

    pub(super) fn commit(&mut self, node: u32, plan: Plan) {
        let nd = self.ring.nodes[node as usize];
        let front = nd.front;
        let mut chain_nodes: Vec<u32> = Vec::with_capacity(plan.chain.len());
        let mut verts: Vec<u32> = Vec::with_capacity(plan.chain.len());
        let last = plan.chain.len() - 1;
        let mut split: Option<(u32, u32)> = None;
        for (j, it) in plan.chain.iter().enumerate() {
            match *it {
                Item::Node(a) if j == 0 || j == last => {
                    chain_nodes.push(a);
                    verts.push(self.ring.nodes[a as usize].vert);
                }
                Item::Node(a) => {
                    let vert = self.ring.nodes[a as usize].vert;
                    let b = self.new_node(vert, 0, 0, front);
                    split = Some((a, b));
                    self.stats.merges += 1;
                    chain_nodes.push(b);
                    verts.push(vert);
                }
                Item::New(x) => {
                    let vert = self.pos.len() as u32;
                    self.pos.push(x);
                    self.acc.push(DVec3::ZERO);
                    chain_nodes.push(self.new_node(vert, 0, 0, front));
                    verts.push(vert);
                }
            }
        }
        for j in 0..last {
            self.add_triangle([verts[j], nd.vert, verts[j + 1]]);
        }
        for j in 0..last {
            self.ring.nodes[chain_nodes[j] as usize].next = chain_nodes[j + 1];
            self.ring.nodes[chain_nodes[j + 1] as usize].prev = chain_nodes[j];
        }
        self.kill(node);
        let f = front as usize;
        self.ring.front_size[f] = self.ring.front_size[f] + last - 1 - 1;
        let mut touched = chain_nodes.clone();
        if let Some((a, b)) = split {
            self.split(a, b);
            touched.push(a);
        }
        for t in touched {
            self.refresh(t);
        }
    }

    /// Splits a front at two nodes of the same vertex into two fronts; a front of two
    /// nodes left over is one edge seen from both sides and is zipped.
    pub(super) fn split(&mut self, a: u32, b: u32) {
        let an = self.ring.nodes[a as usize].next;
        let bn = self.ring.nodes[b as usize].next;
        self.ring.link(a, bn);
        self.ring.link(b, an);
        // the shorter of the two rings becomes a new front
        let Some((small, count)) = self.ring.shorter_cycle(a, b) else {
            self.corrupt = true;
            return;
        };
        if self.ring.split_off(small, count, 2).is_none() {
            self.corrupt = true;
            return;
        }
        for (start, f) in [
            (a, self.ring.nodes[a as usize].front),
            (b, self.ring.nodes[b as usize].front),
        ] {
            if self.ring.front_size[f as usize] == 2 {
                let other = self.ring.nodes[start as usize].next;
                self.stats.zips += 1;
                self.kill(start);
                self.kill(other);
                self.ring.front_size[f as usize] = 0;
            }
        }
    }
}
