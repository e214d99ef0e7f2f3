//! Degenerate triangles (too little area, an angle below `checks.min_angle_deg`) and
//! the quality of an accepted patch as the log reports it.

use super::{CheckFailure, Degeneracy};
use crate::geometry::measure;
use crate::patch::Patch;
use crate::policy::Checks;
use crate::report::PatchQuality;
use glam::DVec3;

/// Area and minimum-angle tests.
pub fn check_degenerate(pos: &[DVec3], patch: &Patch, opts: &Checks) -> Result<(), CheckFailure> {
    let min_angle = opts.min_angle_deg.to_radians();
    for (ti, t) in patch.triangles.iter().enumerate() {
        let [a, b, c] = t.map(|i| pos[i as usize]);
        if let Some(why) = degenerate_reason(a, b, c, min_angle) {
            return Err(CheckFailure::Degenerate { triangle: ti, why });
        }
    }
    Ok(())
}

/// Why triangle `abc` is degenerate (zero area, or an angle below `min_angle`
/// radians), `None` when it is not.
pub(super) fn degenerate_reason(
    a: DVec3,
    b: DVec3,
    c: DVec3,
    min_angle: f64,
) -> Option<Degeneracy> {
    let l = (b - a).length().max((c - b).length()).max((a - c).length());
    let area = measure::tri_area(a, b, c);
    if area.is_nan() || area <= 1e-12 * l * l {
        return Some(Degeneracy::Area(area));
    }
    let m = measure::smallest_angle(a, b, c);
    if m < min_angle {
        return Some(Degeneracy::SmallAngle(m.to_degrees()));
    }
    None
}

/// Quality of a patch (see [`PatchQuality`]).
pub fn quality(pos: &[DVec3], k: usize, patch: &Patch) -> PatchQuality {
    let mut good = 0usize;
    let mut min_angle = f64::INFINITY;
    for t in &patch.triangles {
        let [a, b, c] = t.map(|i| pos[i as usize]);
        if measure::quality(a, b, c) > 1.39 {
            good += 1;
        }
        min_angle = min_angle.min(measure::smallest_angle(a, b, c));
    }
    let nnew = patch.new_vertices.len();
    let valence6_share = if nnew == 0 {
        None
    } else {
        // distinct neighbours of each new vertex: the two other corners of its
        // triangles, grouped by vertex (a counting sort), each short list sorted
        let new_of = |v: u32| (v as usize).checked_sub(k).filter(|&j| j < nnew);
        let mut start = vec![0usize; nnew + 1];
        for t in &patch.triangles {
            for &v in t {
                if let Some(j) = new_of(v) {
                    start[j + 1] += 2;
                }
            }
        }
        for j in 0..nnew {
            start[j + 1] += start[j];
        }
        let mut fill = start.clone();
        let mut nb = vec![0u32; start[nnew]];
        for t in &patch.triangles {
            for c in 0..3 {
                if let Some(j) = new_of(t[c]) {
                    nb[fill[j]] = t[(c + 1) % 3];
                    nb[fill[j] + 1] = t[(c + 2) % 3];
                    fill[j] += 2;
                }
            }
        }
        let mut six = 0usize;
        for j in 0..nnew {
            let l = &mut nb[start[j]..start[j + 1]];
            l.sort_unstable();
            let distinct = l
                .iter()
                .enumerate()
                .filter(|&(i, &w)| i == 0 || l[i - 1] != w)
                .count();
            six += (distinct == 6) as usize;
        }
        Some(six as f64 / nnew as f64)
    };
    PatchQuality {
        q_good_share: if patch.triangles.is_empty() {
            0.0
        } else {
            good as f64 / patch.triangles.len() as f64
        },
        min_angle_deg: if min_angle.is_finite() {
            min_angle.to_degrees()
        } else {
            0.0
        },
        valence6_share,
    }
}
