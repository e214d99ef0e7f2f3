//! What the picture knows of the holes: each loop's place and size, which patch holds
//! a face, where the overview looks from, which holes get a close-up and the faces
//! around each.

use crate::io::RawMesh;
use crate::report::{HoleStatus, HoleTrace, RepairReport};
use glam::DVec3;

/// A boundary loop and its measures. The loop starts at its smallest vertex number (the
/// orientation kept), so that the same loop found twice, from any start, measures the
/// same to the last bit.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Ring {
    pub boundary: Vec<u32>,
    pub center: DVec3,
    /// Largest distance of a boundary vertex from the center.
    pub radius: f64,
    /// The loop's area vector (patch orientation), not normalised.
    pub area: DVec3,
    pub perimeter: f64,
}

impl Ring {
    /// `None` when no vertex of the loop is a finite point.
    pub fn new(pos: &[DVec3], boundary: &[u32]) -> Option<Ring> {
        let start = (0..boundary.len())
            .min_by_key(|&i| boundary[i])
            .unwrap_or(0);
        let mut boundary = boundary.to_vec();
        boundary.rotate_left(start);
        let pts: Vec<DVec3> = boundary
            .iter()
            .filter_map(|&v| pos.get(v as usize).copied())
            .filter(|p| p.is_finite())
            .collect();
        if pts.is_empty() {
            return None;
        }
        let center = pts.iter().sum::<DVec3>() / pts.len() as f64;
        let radius = pts
            .iter()
            .map(|p| (*p - center).length())
            .fold(0.0, f64::max);
        let k = pts.len();
        let (mut area, mut perimeter) = (DVec3::ZERO, 0.0);
        for i in 0..k {
            let (p, q) = (pts[i] - center, pts[(i + 1) % k] - center);
            area += p.cross(q) * 0.5;
            perimeter += (q - p).length();
        }
        Some(Ring {
            boundary,
            center,
            radius,
            area,
            perimeter,
        })
    }

    /// The view radius of a close-up around the loop.
    pub fn view_radius(&self) -> f64 {
        self.radius * 1.35
    }

    /// Worth a close-up: a loop with some extent.
    pub fn shown(&self) -> bool {
        self.radius > 0.0 && self.radius.is_finite()
    }
}

/// What the picture knows of one hole.
pub(super) struct HoleView {
    pub id: usize,
    pub status: HoleStatus,
    pub ring: Ring,
    pub patch: std::ops::Range<u32>,
}

pub(super) fn hole_views(mesh: &RawMesh, report: &RepairReport) -> Vec<HoleView> {
    let nf = mesh.faces.len() as u32;
    report
        .holes
        .iter()
        .zip(&report.traces)
        .filter_map(|(h, t): (_, &HoleTrace)| {
            let ring = Ring::new(&mesh.positions, &t.boundary)?;
            let start = t.patch.start.min(nf);
            let patch = start..t.patch.end.min(nf).max(start);
            Some(HoleView {
                id: h.id,
                status: h.status,
                ring,
                patch,
            })
        })
        .collect()
}

/// The patches' face ranges, sorted, with their holes' status: which patch holds a
/// face, by binary search.
pub(super) struct Owners(Vec<(u32, u32, HoleStatus)>);

impl Owners {
    pub fn new(holes: &[HoleView]) -> Owners {
        let mut v: Vec<_> = holes
            .iter()
            .filter(|h| !h.patch.is_empty())
            .map(|h| (h.patch.start, h.patch.end, h.status))
            .collect();
        v.sort_by_key(|r| r.0);
        Owners(v)
    }

    /// The status of the hole whose patch holds face `f`.
    pub fn status(&self, f: u32) -> Option<HoleStatus> {
        let i = self.0.partition_point(|r| r.0 <= f);
        let &(start, end, status) = self.0.get(i.checked_sub(1)?)?;
        (start <= f && f < end).then_some(status)
    }
}

/// Bounds of the vertices of every `stride`-th face (unreferenced and non-finite
/// vertices left out).
pub(super) fn bounds(pos: &[DVec3], faces: &[[u32; 3]], stride: usize) -> (DVec3, DVec3) {
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for f in faces.iter().step_by(stride) {
        for &v in f {
            if let Some(p) = pos.get(v as usize).filter(|p| p.is_finite()) {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
    }
    (lo, hi)
}

/// The overview looks at the holes: along the perimeter-weighted mean of their unit
/// normals when they agree enough, else at the largest, in the order of their first
/// vertex (so that the same loops give the same view whatever order they come in); a
/// slight tilt shows the relief. Without holes: an oblique view.
pub(super) fn overview_direction<'a>(rings: impl Iterator<Item = &'a Ring>) -> DVec3 {
    let oblique = DVec3::new(0.45, 0.35, 0.82).normalize();
    let mut rings: Vec<&Ring> = rings.collect();
    rings.sort_by_key(|r| (r.boundary.first().copied(), r.boundary.len()));
    let mut sum = DVec3::ZERO;
    let mut total = 0.0;
    let mut largest: Option<&Ring> = None;
    for h in rings {
        let n = h.area.normalize_or_zero();
        if n == DVec3::ZERO {
            continue;
        }
        sum += n * h.perimeter;
        total += h.perimeter;
        if largest.is_none_or(|l| h.perimeter > l.perimeter) {
            largest = Some(h);
        }
    }
    let n = if total > 0.0 && sum.length() > 0.35 * total {
        sum.normalize()
    } else if let Some(l) = largest {
        l.area.normalize()
    } else {
        return oblique;
    };
    (n * 0.85 + oblique * 0.15).normalize_or(n)
}

/// Which holes get a close-up: failed ones, then filled ones, then skipped ones, the
/// larger first within each; shown in the log's order.
pub(super) fn choose_closeups(holes: &[HoleView], max: usize) -> Vec<usize> {
    let rank = |s: HoleStatus| match s {
        HoleStatus::Failed => 0,
        HoleStatus::Filled | HoleStatus::Stitched => 1,
        HoleStatus::Skipped => 2,
    };
    let mut order: Vec<usize> = (0..holes.len())
        .filter(|&i| holes[i].ring.shown())
        .collect();
    order.sort_by(|&a, &b| {
        rank(holes[a].status)
            .cmp(&rank(holes[b].status))
            .then(holes[b].ring.perimeter.total_cmp(&holes[a].ring.perimeter))
    });
    order.truncate(max.min(u64::BITS as usize));
    order.sort_unstable();
    order
}

/// The faces around one close-up's hole.
#[derive(Default)]
pub(super) struct Near {
    /// Faces of the repaired model's input surface.
    pub surface: Vec<u32>,
    /// Faces of patches (of any hole).
    pub patches: Vec<u32>,
}

/// The faces near each ring among `faces` (numbered from `offset`): their centroid
/// within the close-up's radius, surface faces before `first_patch`, patches from it,
/// at most `cap` of each. One pass over the faces: a grid over the bounds holds, per
/// cell, a bit mask of the close-ups whose sphere reaches it; a face is measured only
/// where its first vertex's cell has a bit set.
pub(super) fn neighbourhoods(
    pos: &[DVec3],
    (faces, offset): (&[[u32; 3]], usize),
    rings: &[&Ring],
    cap: usize,
    (lo, hi): (DVec3, DVec3),
    first_patch: usize,
) -> Vec<Near> {
    let mut out: Vec<Near> = (0..rings.len()).map(|_| Near::default()).collect();
    if rings.is_empty() || rings.len() > 64 || !lo.cmple(hi).all() {
        return out;
    }
    const G: usize = 32;
    let size = (hi - lo).max(DVec3::splat(1e-300));
    let cell_of = |p: DVec3| -> Option<usize> {
        let t = (p - lo) / size * G as f64;
        if !t.is_finite() {
            return None;
        }
        let c = t
            .as_ivec3()
            .clamp(glam::IVec3::ZERO, glam::IVec3::splat(G as i32 - 1));
        Some((c.x as usize * G + c.y as usize) * G + c.z as usize)
    };
    let mut mask = vec![0u64; G * G * G];
    for (k, h) in rings.iter().enumerate() {
        // a face's first vertex is within about one edge of its centroid
        let margin = 2.0 * h.perimeter / h.boundary.len().max(1) as f64;
        let (c, r) = (h.center, h.view_radius() + margin);
        let a = ((c - r - lo) / size * G as f64).floor().as_ivec3();
        let b = ((c + r - lo) / size * G as f64).floor().as_ivec3();
        let a = a.clamp(glam::IVec3::ZERO, glam::IVec3::splat(G as i32 - 1));
        let b = b.clamp(glam::IVec3::ZERO, glam::IVec3::splat(G as i32 - 1));
        let zs = a.z as usize..(b.z + 1).max(a.z) as usize;
        for x in a.x..=b.x {
            for y in a.y..=b.y {
                let row = (x as usize * G + y as usize) * G;
                for m in &mut mask[row + zs.start..row + zs.end] {
                    *m |= 1 << k;
                }
            }
        }
    }
    let radii: Vec<f64> = rings.iter().map(|h| h.view_radius()).collect();
    for (i, face) in faces.iter().enumerate() {
        let f = offset + i;
        let Some(&a) = pos.get(face[0] as usize) else {
            continue;
        };
        let Some(cell) = cell_of(a) else { continue };
        let mut m = mask[cell];
        if m == 0 {
            continue;
        }
        let (Some(&b), Some(&c)) = (pos.get(face[1] as usize), pos.get(face[2] as usize)) else {
            continue;
        };
        let centroid = (a + b + c) / 3.0;
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            if (centroid - rings[k].center).length_squared() <= radii[k] * radii[k] {
                let list = if f >= first_patch {
                    &mut out[k].patches
                } else {
                    &mut out[k].surface
                };
                if list.len() < cap {
                    list.push(f as u32);
                }
            }
        }
    }
    out
}

/// The rings of the boundary loops of the faces `faces` ([`soup_loops`]).
pub(super) fn loop_rings(pos: &[DVec3], faces: &[[u32; 3]]) -> Vec<Ring> {
    rings(pos, &soup_loops(faces, pos.len()))
}

/// The rings of the loops `loops` (a loop without a finite point left out).
pub(super) fn rings(pos: &[DVec3], loops: &[Vec<u32>]) -> Vec<Ring> {
    loops.iter().filter_map(|l| Ring::new(pos, l)).collect()
}

/// The boundary loops of a triangle soup as the repair finds its holes, before it
/// does (oriented against the faces, as [`HoleTrace::boundary`]): an edge `a -> b` of
/// a face is on the boundary when no other face has it, either way round. Faces with
/// a repeated or missing vertex are left out, and so are loops through a vertex where
/// two boundary edges start (touching loops: which way they pair is the repair's
/// choice). For a clean mesh these are the repair's holes; where they are not, the
/// picture draws again what depends on them.
pub(super) fn soup_loops(faces: &[[u32; 3]], vertices: usize) -> Vec<Vec<u32>> {
    const NONE: u32 = u32::MAX;
    let ok = |f: &[u32; 3]| {
        f.iter().all(|&v| (v as usize) < vertices) && f[0] != f[1] && f[1] != f[2] && f[0] != f[2]
    };
    // each vertex's corners, in one array (offsets per vertex): the corner's next
    // and previous vertex, its face's edges out of and into the vertex
    let mut start = vec![0u32; vertices + 1];
    for f in faces.iter().filter(|f| ok(f)) {
        for &v in f {
            start[v as usize + 1] += 1;
        }
    }
    for i in 0..vertices {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut corners = vec![[0u32; 2]; start[vertices] as usize];
    for f in faces.iter().filter(|f| ok(f)) {
        for i in 0..3 {
            let a = f[i] as usize;
            corners[fill[a] as usize] = [f[(i + 1) % 3], f[(i + 2) % 3]];
            fill[a] += 1;
        }
    }
    // the loop goes against the faces: a boundary edge a -> b makes a follow b; an
    // edge b -> a comes into a
    let mut next = vec![NONE; vertices];
    let mut forked = vec![false; vertices];
    for a in 0..vertices {
        let at = &corners[start[a] as usize..start[a + 1] as usize];
        for &[b, _] in at {
            if !at.iter().any(|&[_, p]| p == b) && at.iter().filter(|&&[c, _]| c == b).count() == 1
            {
                let n = &mut next[b as usize];
                if *n == NONE {
                    *n = a as u32;
                } else {
                    forked[b as usize] = true;
                }
            }
        }
    }
    let mut seen = vec![false; vertices];
    let mut loops = Vec::new();
    for s in 0..vertices {
        if next[s] == NONE || seen[s] {
            continue;
        }
        let mut lp = Vec::new();
        let mut v = s;
        let closed = loop {
            seen[v] = true;
            lp.push(v as u32);
            if forked[v] {
                break false;
            }
            let n = next[v];
            if n == NONE {
                break false;
            }
            if n as usize == s {
                break true;
            }
            if seen[n as usize] {
                break false;
            }
            v = n as usize;
        };
        if closed && lp.len() >= 3 {
            loops.push(lp);
        }
    }
    loops
}
