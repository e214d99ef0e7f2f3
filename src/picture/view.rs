//! Cameras and shading: orthographic views, one flat-shaded colour per triangle (a
//! head light; back faces, seen through holes, bluish), loops drawn as outlines.

use super::palette::{Ink, Material};
use super::raster::Panel;
use crate::report::HoleStatus;
use glam::DVec3;

/// An orthographic camera: looks along `-dir` (from outside, where `dir` points).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Camera {
    center: DVec3,
    right: DVec3,
    up: DVec3,
    pub fwd: DVec3,
    pub scale: f64,
    cx: f64,
    cy: f64,
    /// The radius of the scene it frames (world units).
    pub extent: f64,
    /// The light's direction (towards the light): from the viewer, a little from the
    /// upper left.
    light: DVec3,
    /// The same in the camera's (right, up, forward) coordinates.
    light_cam: glam::Vec3,
}

impl Camera {
    /// Frames the sphere of radius `radius` around `center` in a `w` x `h` panel.
    pub fn new(dir: DVec3, center: DVec3, radius: f64, w: usize, h: usize) -> Camera {
        let fwd = -dir.normalize_or(DVec3::Z);
        let hint = if fwd.y.abs() < 0.9 {
            DVec3::Y
        } else {
            DVec3::Z
        };
        let right = fwd.cross(hint).normalize();
        let up = right.cross(fwd);
        let radius = if radius > 0.0 && radius.is_finite() {
            radius
        } else {
            1.0
        };
        Camera {
            center,
            right,
            up,
            fwd,
            scale: 0.5 * w.min(h) as f64 / radius,
            cx: w as f64 / 2.0,
            cy: h as f64 / 2.0,
            extent: radius,
            light: (-fwd + up * 0.45 - right * 0.3).normalize(),
            light_cam: glam::Vec3::new(-0.3, 0.45, -1.0).normalize(),
        }
    }

    /// Frames the box `lo..hi` (its projected corners) at `fill` of the panel.
    pub fn fit(dir: DVec3, lo: DVec3, hi: DVec3, w: usize, h: usize, fill: f64) -> Camera {
        let mut cam = Camera::new(dir, (lo + hi) / 2.0, (hi - lo).length() / 2.0, w, h);
        let (mut sx, mut sy) = (0.0f64, 0.0f64);
        for i in 0..8 {
            let p = DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            ) - cam.center;
            sx = sx.max(p.dot(cam.right).abs());
            sy = sy.max(p.dot(cam.up).abs());
        }
        if sx > 0.0 || sy > 0.0 {
            let s = (w as f64 / 2.0 / sx.max(1e-300)).min(h as f64 / 2.0 / sy.max(1e-300));
            if s.is_finite() && s > 0.0 {
                cam.scale = s * fill;
            }
        }
        cam
    }

    #[inline]
    pub fn project(&self, p: DVec3) -> [f32; 3] {
        let q = p - self.center;
        [
            (self.cx + q.dot(self.right) * self.scale) as f32,
            (self.cy - q.dot(self.up) * self.scale) as f32,
            q.dot(self.fwd) as f32,
        ]
    }
}

/// The corners of a face (`None` when an index is out of range).
#[inline]
pub(super) fn corners(pos: &[DVec3], f: [u32; 3]) -> Option<[DVec3; 3]> {
    Some([
        *pos.get(f[0] as usize)?,
        *pos.get(f[1] as usize)?,
        *pos.get(f[2] as usize)?,
    ])
}

/// The flat shade of a face: `patch` is its hole's status when it belongs to a patch.
#[inline]
fn shade(cam: &Camera, [a, b, c]: [DVec3; 3], patch: Option<HoleStatus>) -> Ink {
    let n = (b - a).cross(c - a).normalize_or_zero();
    Material::of(patch, n.dot(cam.fwd) <= 0.0).shade(n.dot(cam.light).abs() as f32)
}

/// [`shade`] from a face's projected corners: the camera frame's coordinates are
/// `((x - cx) / scale, (cy - y) / scale, depth)`, and as (right, up, forward) is a
/// left-handed frame, the world normal is minus the cross product of those
/// coordinates' edges. In f32: for the overview's faces, at most a few pixels wide.
#[inline]
pub(super) fn shade_projected(
    cam: &Camera,
    [a, b, c]: [[f32; 3]; 3],
    patch: Option<HoleStatus>,
) -> Ink {
    let inv = (1.0 / cam.scale) as f32;
    let e1 = glam::Vec3::new((b[0] - a[0]) * inv, (a[1] - b[1]) * inv, b[2] - a[2]);
    let e2 = glam::Vec3::new((c[0] - a[0]) * inv, (a[1] - c[1]) * inv, c[2] - a[2]);
    // the world normal in camera coordinates
    let n = -e1.cross(e2).normalize_or_zero();
    Material::of(patch, n.z <= 0.0).shade(n.dot(cam.light_cam).abs())
}

/// Draws one face, flat-shaded: `patch` is its hole's status when it belongs to a
/// patch.
#[inline]
pub(super) fn draw_face(
    panel: &mut Panel,
    cam: &Camera,
    pos: &[DVec3],
    f: [u32; 3],
    patch: Option<HoleStatus>,
) {
    let Some(world) = corners(pos, f) else {
        return;
    };
    panel.triangle(world.map(|p| cam.project(p)), || shade(cam, world, patch));
}

/// Draws a boundary loop; where the surface hides it, in `hidden`.
#[allow(clippy::too_many_arguments)]
pub(super) fn outline(
    panel: &mut Panel,
    cam: &Camera,
    pos: &[DVec3],
    boundary: &[u32],
    color: Ink,
    width: usize,
    bias: f32,
    hidden: Option<Ink>,
) {
    let k = boundary.len();
    for i in 0..k {
        let (Some(&p), Some(&q)) = (
            pos.get(boundary[i] as usize),
            pos.get(boundary[(i + 1) % k] as usize),
        ) else {
            continue;
        };
        panel.line(cam.project(p), cam.project(q), color, width, bias, hidden);
    }
}
