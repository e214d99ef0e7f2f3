//! One step of the advancing front (paper 002 §5.3): the local frame at a front vertex
//! (angle, corrected normal, curvature), the placement of new vertices, the checks of a
//! planned step, and applying it (a merge splits the front).

use super::builder::*;
use super::*;

impl Builder<'_> {
    /// The angle and local frame at a front node.
    pub(super) fn eval(&self, x: u32) -> Eval {
        let nd = &self.ring.nodes[x as usize];
        let (p, n) = (nd.prev, nd.next);
        let pi = self.npos(x);
        let pp = self.npos(p);
        let pn = self.npos(n);
        let mut ni = self.vnormal(nd.vert);
        let size = self.ring.front_size[nd.front as usize];
        let w = ((size as f64 / 10.0).round() as usize)
            .min(size.saturating_sub(1) / 2)
            .max(1);
        let (mut sl, mut sr) = (DVec3::ZERO, DVec3::ZERO);
        let (mut cl, mut cr) = (x, x);
        for _ in 0..w {
            cl = self.ring.nodes[cl as usize].prev;
            cr = self.ring.nodes[cr as usize].next;
            sl += self.npos(cl) - pi;
            sr += self.npos(cr) - pi;
        }
        let mut ne = sr.cross(sl).normalize_or_zero();
        if ne.dot(ni) < 0.0 {
            ne = -ne;
        }
        if ni == DVec3::ZERO {
            ni = self.hole_normal;
        }
        if ne == DVec3::ZERO || !ne.is_finite() {
            ne = ni;
        }
        let mut nc = (self.p.alpha * ni + (1.0 - self.p.alpha) * ne).normalize_or_zero();
        if nc == DVec3::ZERO || !nc.is_finite() {
            nc = ni;
        }
        let a = pn - pi;
        let b = pp - pi;
        let (la, lb) = (a.length(), b.length());
        let ap = a - nc * a.dot(nc);
        let bp = b - nc * b.dot(nc);
        let s_local = (self.size[nd.vert as usize]
            + self.size[self.ring.nodes[p as usize].vert as usize]
            + self.size[self.ring.nodes[n as usize].vert as usize])
            / 3.0;
        let l = 0.5 * (0.5 * (la + lb)) + 0.5 * s_local;
        let (theta, a_hat) = if ap.length() > 1e-9 * la && bp.length() > 1e-9 * lb {
            let a_hat = ap.normalize();
            let perp = nc.cross(a_hat);
            let mut t = bp.dot(perp).atan2(bp.dot(a_hat));
            if t < 0.0 {
                t += 2.0 * PI;
            }
            (t, a_hat)
        } else {
            (PI, nc.any_orthonormal_vector())
        };
        let perp = nc.cross(a_hat);
        // Taubin curvature at the two neighbours along their edges to v_i
        let taubin = |q: DVec3, nq: DVec3| {
            let e = pi - q;
            let d = e.length_squared();
            if d > 0.0 {
                2.0 * nq.dot(e) / d
            } else {
                0.0
            }
        };
        let kappa = 0.5
            * (taubin(pp, self.vnormal(self.ring.nodes[p as usize].vert))
                + taubin(pn, self.vnormal(self.ring.nodes[n as usize].vert)));
        let slope = if la > 0.0 && lb > 0.0 {
            0.5 * (nc.dot(a) / la + nc.dot(b) / lb)
        } else {
            0.0
        };
        let c = self.p.omega1 * kappa * l * 0.5 + (1.0 - self.p.omega1) * slope;
        let cos_phi = if c.is_finite() {
            c.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        Eval {
            theta,
            nc,
            a_hat,
            perp,
            l,
            s_local,
            cos_phi,
        }
    }

    /// New vertex at rotation `psi` from the direction to `next`.
    pub(super) fn place(&self, x: u32, ev: &Eval, psi: f64) -> DVec3 {
        let t = ev.a_hat * psi.cos() + ev.perp * psi.sin();
        let sin_phi = (1.0 - ev.cos_phi * ev.cos_phi).max(0.0).sqrt();
        self.npos(x) + ev.l * (ev.cos_phi * ev.nc + sin_phi * t)
    }

    /// The nearest node of `x`'s front within `r` of `q`, other than `x` and its
    /// two neighbours.
    pub(super) fn nearest_front_node(&mut self, x: u32, q: DVec3, r: f64) -> Option<u32> {
        let nd = &self.ring.nodes[x as usize];
        let (f, p, n) = (nd.front, nd.prev, nd.next);
        let mut ids = std::mem::take(&mut self.node_scratch);
        self.node_grid
            .query_box(q - DVec3::splat(r), q + DVec3::splat(r), &mut ids);
        let mut best: Option<(f64, u32)> = None;
        for &c in &ids {
            let cn = &self.ring.nodes[c as usize];
            if !cn.alive || cn.front != f || c == x || c == p || c == n {
                continue;
            }
            let d = (self.pos[cn.vert as usize] - q).length();
            if d <= r && best.is_none_or(|(bd, bc)| d < bd || (d == bd && c < bc)) {
                best = Some((d, c));
            }
        }
        self.node_scratch = ids;
        best.map(|(_, c)| c)
    }

    // ----- planning ---------------------------------------------------------------

    /// Checks the step that replaces `x` by `slots` on its front.
    pub(super) fn check(&mut self, x: u32, ev: &Eval, slots: Vec<Slot>) -> Option<Plan> {
        let nd = self.ring.nodes[x as usize];
        let (p, n) = (nd.prev, nd.next);
        let (vi, vp, vn) = (
            nd.vert,
            self.ring.nodes[p as usize].vert,
            self.ring.nodes[n as usize].vert,
        );
        let base = self.pos.len() as u32;
        let mut new_pos = Vec::new();
        let mut s = Vec::with_capacity(slots.len());
        let mut merged: Option<u32> = None;
        for sl in &slots {
            match *sl {
                Slot::New(q) => {
                    if !q.is_finite() {
                        return None;
                    }
                    s.push(base + new_pos.len() as u32);
                    new_pos.push(q);
                }
                Slot::Merge(w) => {
                    let wn = &self.ring.nodes[w as usize];
                    if merged.is_some()
                        || !wn.alive
                        || wn.front != nd.front
                        || w == x
                        || w == p
                        || w == n
                    {
                        return None;
                    }
                    merged = Some(w);
                    s.push(wn.vert);
                }
            }
        }
        let m = s.len();
        let mut tris = Vec::with_capacity(m + 1);
        if m == 0 {
            tris.push([vp, vi, vn]);
        } else {
            tris.push([vp, vi, s[0]]);
            for j in 0..m - 1 {
                tris.push([vi, s[j + 1], s[j]]);
            }
            tris.push([vi, vn, s[m - 1]]);
        }
        let at = |i: u32| -> DVec3 {
            if i < base {
                self.pos[i as usize]
            } else {
                new_pos[(i - base) as usize]
            }
        };
        // geometry of each triangle
        let mut normals = Vec::with_capacity(tris.len());
        for t in &tris {
            let [a, b, c] = t.map(at);
            if measure::smallest_angle_sin(a, b, c) < self.p.min_angle.sin() {
                return None;
            }
            let nr = measure::tri_normal_raw(a, b, c).normalize_or_zero();
            let facing = nr.dot(ev.nc) > 0.0;
            if !facing {
                return None;
            }
            normals.push(nr);
        }
        // no fold over the triangles behind the front edges it closes
        if normals[0].dot(self.ring.nodes[p as usize].data.behind) < FOLD_COS
            || normals[m].dot(nd.data.behind) < FOLD_COS
        {
            return None;
        }
        // edges: consumed front edges, new interior edges, new front edges
        let mut consumed: Vec<(u32, u32)> = vec![(vp, vi), (vi, vn)];
        if let Some(w) = merged {
            let wv = self.ring.nodes[w as usize].vert;
            if self.ring.nodes[n as usize].next == w {
                consumed.push((vn, wv));
                if normals[m].dot(self.ring.nodes[n as usize].data.behind) < FOLD_COS {
                    return None;
                }
            }
            if self.ring.nodes[p as usize].prev == w {
                consumed.push((wv, vp));
                if normals[0].dot(self.ring.nodes[w as usize].data.behind) < FOLD_COS {
                    return None;
                }
            }
        }
        let mut directed: Vec<(u32, u32)> = Vec::with_capacity(tris.len() * 3);
        for t in &tris {
            for c in 0..3 {
                let e = (t[c], t[(c + 1) % 3]);
                if directed.contains(&e) {
                    return None;
                }
                directed.push(e);
            }
        }
        for &(a, b) in &directed {
            if consumed.contains(&(a, b)) {
                continue;
            }
            if self.edges.contains(&edge_key(a, b)) {
                return None;
            }
            if (a as usize) < self.k
                && (b as usize) < self.k
                && self.forbidden.contains(&edge_key(a, b))
            {
                return None;
            }
        }
        // no overlap with the patch, the mesh, or each other
        let geo: Vec<[DVec3; 3]> = tris.iter().map(|t| t.map(at)).collect();
        for (i, g) in geo.iter().enumerate() {
            if self.obstacles.find_overlap(g, |_| false).is_some() {
                return None;
            }
            for h in &geo[i + 1..] {
                if intersect::overlap(g, h) {
                    return None;
                }
            }
        }
        Some(Plan {
            x,
            slots,
            new_pos,
            size: ev.s_local,
            tris,
        })
    }

    /// The step for `n_new` new vertices at `x` (0: ear), merging a new vertex into a
    /// nearby front vertex when `merge` is set.
    pub(super) fn step_slots(
        &mut self,
        x: u32,
        ev: &Eval,
        n_new: usize,
        merge: bool,
    ) -> Option<Vec<Slot>> {
        let r = self.p.merge * ev.l;
        let mut slots = Vec::with_capacity(n_new);
        // front order: prev, s_1 (largest rotation) ... s_m (smallest), next
        for j in (1..=n_new).rev() {
            let psi = ev.theta * j as f64 / (n_new + 1) as f64;
            let q = self.place(x, ev, psi);
            let slot = if merge && r > 0.0 {
                match self.nearest_front_node(x, q, r) {
                    Some(w) => Slot::Merge(w),
                    None => Slot::New(q),
                }
            } else {
                Slot::New(q)
            };
            slots.push(slot);
        }
        if slots.iter().filter(|s| matches!(s, Slot::Merge(_))).count() > 1 {
            return None;
        }
        Some(slots)
    }

    /// Tries the rule's step at `x`, then the fallbacks.
    pub(super) fn try_steps(&mut self, x: u32, ev: &Eval) -> Option<Plan> {
        let th = ev.theta;
        let rule = if th <= self.p.angle_small {
            0
        } else if th <= self.p.angle_large {
            1
        } else {
            2
        };
        let mut order: Vec<(usize, bool)> = vec![(rule, true)];
        match rule {
            0 => order.push((1, true)),
            1 => {
                order.push((1, false));
                if th < PI {
                    order.push((0, true));
                }
            }
            _ => {
                order.push((2, false));
                order.push((1, true));
            }
        }
        for (n_new, merge) in order {
            if let Some(slots) = self.step_slots(x, ev, n_new, merge) {
                if let Some(plan) = self.check(x, ev, slots) {
                    return Some(plan);
                }
            }
        }
        // last resort: join x to the nearest vertex of its front near the bisector
        let q = self.place(x, ev, 0.5 * th);
        if let Some(w) = self.nearest_front_node(x, q, 1.5 * ev.l) {
            if let Some(plan) = self.check(x, ev, vec![Slot::Merge(w)]) {
                return Some(plan);
            }
        }
        None
    }

    // ----- applying -------------------------------------------------------------

    pub(super) fn apply(&mut self, plan: Plan) -> Result<(), FillError> {
        let x = plan.x;
        let nd = self.ring.nodes[x as usize];
        let (p, n, f) = (nd.prev, nd.next, nd.front);
        for q in &plan.new_pos {
            self.pos.push(*q);
            self.acc.push(DVec3::ZERO);
            self.size.push(plan.size);
        }
        let tn: Vec<DVec3> = plan.tris.iter().map(|&t| self.emit(t)).collect();
        let base = (self.pos.len() - plan.new_pos.len()) as u32;
        let m = plan.slots.len();
        // chain nodes in front order
        let mut chain = Vec::with_capacity(m);
        let mut merged_at = None;
        let mut next_new = base;
        for (j, sl) in plan.slots.iter().enumerate() {
            match *sl {
                Slot::New(_) => {
                    let id = self.new_node(next_new, f, tn[j + 1]);
                    next_new += 1;
                    chain.push(id);
                }
                Slot::Merge(w) => {
                    merged_at = Some(j);
                    chain.push(w);
                }
            }
        }
        self.ring.kill(x);
        self.ring.nodes[p as usize].data.behind = tn[0];
        let mut touched = vec![p, n];
        touched.extend_from_slice(&chain);
        let mut fronts = vec![f];
        match merged_at {
            None => {
                let mut prev = p;
                for &c in &chain {
                    self.ring.link(prev, c);
                    prev = c;
                }
                self.ring.link(prev, n);
                self.ring.front_size[f as usize] = self.ring.front_size[f as usize] + m - 1;
            }
            Some(jm) => {
                let w = chain[jm];
                let old_next = self.ring.nodes[w as usize].next;
                let old_behind = self.ring.nodes[w as usize].data.behind;
                let wv = self.ring.nodes[w as usize].vert;
                let w2 = self.new_node(wv, f, old_behind);
                touched.push(w2);
                // loop 2: p, chain[..jm], w2, old_next ...
                let mut prev = p;
                for &c in &chain[..jm] {
                    self.ring.link(prev, c);
                    prev = c;
                }
                self.ring.link(prev, w2);
                self.ring.link(w2, old_next);
                // loop 1: w, chain[jm+1..], n ...
                self.ring.nodes[w as usize].data.behind = tn[jm + 1];
                let mut prev = w;
                for &c in &chain[jm + 1..] {
                    self.ring.link(prev, c);
                    prev = c;
                }
                self.ring.link(prev, n);
                let total = self.ring.front_size[f as usize] + m - 1; // -1 (x) + (m-1) new + 1 (w2)
                let (small, size) = self.smaller_loop(w, w2)?;
                self.ring.front_size[f as usize] = total;
                let f2 = self
                    .ring
                    .split_off(small, size, 0)
                    .ok_or_else(|| FillError::internal("internal: front sizes out of step"))?;
                fronts.push(f2);
            }
        }
        for &fr in &fronts {
            let start = touched.iter().copied().find(|&t| {
                let tn = &self.ring.nodes[t as usize];
                tn.alive && tn.front == fr
            });
            if let Some(s) = start {
                self.close_small(fr, s)?;
            }
        }
        for t in touched {
            self.rekey(t);
        }
        Ok(())
    }
}
