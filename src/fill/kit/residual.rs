//! Closing a residual front: the in-method fallback of the front-based methods
//! (`wavefront`, and the initial front of `lssvm_poisson`).
//!
//! None of the papers says what to do when a front cannot advance (paper 004's conclusion
//! admits overlaps on complex holes). Scanned holes that fold back on themselves (a loop
//! that runs into a thin flap and out again) leave fronts where every vertex's step
//! overlaps something. Such a residual front is closed the way paper 002 §5.2 closes a
//! middle hole: a minimum-weight triangulation of the front loop in 3D (no projection,
//! so folded loops are fine), refined to the front's edge length and relaxed
//! ([`super::triangulate`] and [`super::refine`], as `min_area_fair` uses them), then the new interior
//! vertices are faired (thin plate, with the patch and mesh triangles around the front
//! fixed as constraints) so the residual piece continues the surface instead of spanning
//! it flat. The caller's patch checks judge the result; [`close_keeping_unfaired`] also
//! returns the piece before the fairing, which the wavefront keeps when the faired one
//! crosses the triangles around the front (the fairing bulges a residual that sits in a fold).

// `!(x > bound)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::refine::Refiner;
use super::{fair, triangulate, Deadline, FillError};
use crate::fasthash::{HashMap, HashSet};
use crate::policy::Policy;
use glam::DVec3;

/// Relaxation rounds of the refined residual (as `min_area_fair` does before fairing).
const RELAX_ROUNDS: usize = 2;

/// A front loop to close.
pub struct Residual<'a> {
    /// Front positions, oriented like the hole (a triangle `(r[i], r[i+1], x)` agrees
    /// with the triangles outside the front).
    pub ring: &'a [DVec3],
    /// Ring index pairs `(a, b)`, `a < b`, that already are edges (patch or mesh).
    pub forbidden: &'a HashSet<(u32, u32)>,
    /// Unit normal of the triangle outside ring edge `i -> i + 1`, when known.
    pub outside_normals: &'a [Option<DVec3>],
    /// Triangles around the front (patch triangles and mesh faces), as positions; their
    /// vertices are fixed constraints of the fairing. Vertices are matched to the ring by
    /// exact position.
    pub context: &'a [[DVec3; 3]],
    /// Target edge length of the new triangles.
    pub edge_length: f64,
}

/// A closed ring: the new interior vertices and the triangles, in ring numbering
/// (index `i < ring.len()` is ring vertex `i`, then the new vertices).
pub struct Closed {
    /// The new vertices, faired.
    pub new_vertices: Vec<DVec3>,
    /// The same vertices before the fairing (refined and relaxed on the minimum-area
    /// triangulation), when the fairing moved them: the fallback of a caller whose
    /// faired piece crosses what is around it.
    pub unfaired: Option<Vec<DVec3>>,
    pub triangles: Vec<[u32; 3]>,
}

/// Closes the ring: returns the new interior vertices and the triangles, in ring
/// numbering (index `i < ring.len()` is ring vertex `i`, then the new vertices).
pub fn close(
    r: &Residual,
    policy: &Policy,
    deadline: &Deadline,
) -> Result<(Vec<DVec3>, Vec<[u32; 3]>), FillError> {
    close_keeping_unfaired(r, policy, deadline).map(|c| (c.new_vertices, c.triangles))
}

/// [`close`], also returning the new vertices as they were before the fairing.
pub fn close_keeping_unfaired(
    r: &Residual,
    policy: &Policy,
    deadline: &Deadline,
) -> Result<Closed, FillError> {
    let n = r.ring.len();
    if n < 3 {
        return Err(FillError::bad_loop(format!(
            "a residual front of {n} vertices cannot be closed"
        )));
    }
    if r.ring.iter().any(|p| !p.is_finite()) || !(r.edge_length > 0.0) {
        return Err(FillError::bad_loop(
            "the residual front has a non-finite coordinate",
        ));
    }
    let input = triangulate::LoopInput::with_policy(
        r.ring,
        r.forbidden,
        r.outside_normals,
        policy,
        *deadline,
    );
    let tris = triangulate::triangulate(&input)?;
    let scale = vec![r.edge_length; n];
    let mut rf = Refiner::new(r.ring.to_vec(), scale, tris, r.forbidden);
    let density = if policy.refine.density > 0.0 {
        policy.refine.density
    } else {
        std::f64::consts::SQRT_2
    };
    rf.refine(density, deadline)?;
    rf.relax(RELAX_ROUNDS, deadline)?;
    let mut pos = rf.pos.clone();
    let tris = rf.tris.clone();
    if pos.len() > n {
        fair_interior(&mut pos, n, &tris, r.context)?;
    }
    let unfaired = (pos[n..] != rf.pos[n..]).then(|| rf.pos[n..].to_vec());
    Ok(Closed {
        new_vertices: pos[n..].to_vec(),
        unfaired,
        triangles: tris,
    })
}

/// Thin-plate fairing of `pos[n..]` over `tris` plus the context triangles (fixed).
fn fair_interior(
    pos: &mut [DVec3],
    n: usize,
    tris: &[[u32; 3]],
    context: &[[DVec3; 3]],
) -> Result<(), FillError> {
    let key = |p: DVec3| (p.x.to_bits(), p.y.to_bits(), p.z.to_bits());
    let mut positions: Vec<DVec3> = pos.to_vec();
    let mut free = vec![false; n];
    free.resize(pos.len(), true);
    let mut index: HashMap<(u64, u64, u64), u32> = HashMap::default();
    for (i, &p) in pos[..n].iter().enumerate() {
        index.entry(key(p)).or_insert(i as u32);
    }
    let mut triangles: Vec<[u32; 3]> = tris.to_vec();
    let mut seen: HashSet<[u32; 3]> = HashSet::default();
    for t in context {
        let ids = t.map(|p| {
            *index.entry(key(p)).or_insert_with(|| {
                positions.push(p);
                free.push(false);
                (positions.len() - 1) as u32
            })
        });
        if ids[0] == ids[1] || ids[1] == ids[2] || ids[0] == ids[2] {
            continue;
        }
        let mut s = ids;
        s.sort_unstable();
        if seen.insert(s) {
            triangles.push(ids);
        }
    }
    let mut local = fair::LocalMesh {
        positions,
        triangles,
        free,
    };
    fair::fair_local(&mut local, 2, crate::policy::Weights::Cotangent)?;
    let m = pos.len();
    if local.positions[n..m].iter().any(|p| !p.is_finite()) {
        return Ok(());
    }
    pos[n..].copy_from_slice(&local.positions[n..m]);
    Ok(())
}
