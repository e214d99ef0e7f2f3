//! A picture of a repair: the model with every hole outlined and coloured by its
//! status (filled green, skipped amber, failed red) and numbered as in the log, then a
//! close-up of each hole before and after (the patch's triangles drawn over the
//! surrounding surface, shaded). `holefill fill --picture FILE` and the daemon write
//! it as PNG beside the repair log.
//!
//! How: a small software rasteriser ([`raster`]): orthographic views, one flat-shaded
//! colour per triangle (a head light; back faces, seen through holes, bluish), a
//! depth buffer, outlines drawn over the surface and faded where it hides them. The
//! overview looks at the holes (along the mean of their normals, else at the
//! largest), each close-up along its hole's normal (the loop's area vector, else the
//! mean normal around it).
//!
//! Bounded time and memory for huge meshes: memory is the image and its depth buffers
//! (about 4 MB at the default width) plus the face numbers of the close-ups'
//! neighbourhoods; the overview draws at most [`Options::max_overview_faces`] faces
//! (every k-th one: far more than its pixels), and the close-ups' neighbourhoods are
//! found in one pass over the faces that looks up one grid cell per face (a bit mask
//! of the close-ups near it) and measures only the faces near a hole.

mod font;
mod raster;

use crate::io::RawMesh;
use crate::report::{HoleStatus, HoleTrace, RepairReport};
use glam::DVec3;
use raster::{Panel, Rgb};
use rayon::prelude::*;

/// Size and limits of a picture.
#[derive(Clone, Debug)]
pub struct Options {
    /// Width of the image in pixels (at least 320); the height follows from the
    /// number of close-ups.
    pub width: usize,
    /// At most this many holes get a close-up (failed holes first, then the largest
    /// filled ones, then skipped ones); every hole is outlined in the overview.
    pub max_closeups: usize,
    /// The overview draws every k-th face so that at most this many are drawn.
    pub max_overview_faces: usize,
    /// A close-up draws at most this many faces around its hole (besides the patch).
    pub max_closeup_faces: usize,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            width: 512,
            max_closeups: 8,
            max_overview_faces: 1_000_000,
            max_closeup_faces: 400_000,
        }
    }
}

/// An RGB image, 8 bits per channel, rows top first.
#[derive(Clone, Debug)]
pub struct Picture {
    pub width: usize,
    pub height: usize,
    /// `width * height * 3` bytes.
    pub rgb: Vec<u8>,
}

/// The picture could not be encoded.
#[derive(Debug, thiserror::Error)]
#[error("cannot encode the picture as PNG: {0}")]
pub struct PictureError(String);

impl Picture {
    /// The colour of a pixel (`None` outside the image).
    pub fn pixel(&self, x: usize, y: usize) -> Option<[u8; 3]> {
        (x < self.width && y < self.height).then(|| {
            let i = 3 * (y * self.width + x);
            [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
        })
    }

    /// The image as a PNG file's bytes (the fastest compression, rows filtered by
    /// `Up`: the picture must cost little next to the repair).
    pub fn to_png(&self) -> Result<Vec<u8>, PictureError> {
        let mut out = Vec::with_capacity(self.rgb.len() / 4);
        {
            let w = u32::try_from(self.width).map_err(|e| PictureError(e.to_string()))?;
            let h = u32::try_from(self.height).map_err(|e| PictureError(e.to_string()))?;
            let mut enc = png::Encoder::new(&mut out, w, h);
            enc.set_color(png::ColorType::Rgb);
            enc.set_depth(png::BitDepth::Eight);
            enc.set_compression(png::Compression::Fastest);
            let mut wr = enc
                .write_header()
                .map_err(|e| PictureError(e.to_string()))?;
            wr.write_image_data(&self.rgb)
                .map_err(|e| PictureError(e.to_string()))?;
            wr.finish().map_err(|e| PictureError(e.to_string()))?;
        }
        Ok(out)
    }
}

/// The colour of a hole's outline and label.
pub fn status_color(s: HoleStatus) -> [u8; 3] {
    match s {
        HoleStatus::Filled | HoleStatus::Stitched => FILLED,
        HoleStatus::Skipped => SKIPPED,
        HoleStatus::Failed => FAILED,
    }
}

const FILLED: Rgb = [46, 204, 113];
const SKIPPED: Rgb = [243, 176, 26];
const FAILED: Rgb = [235, 64, 52];
const BG: Rgb = [30, 34, 40];
const BAND: Rgb = [18, 20, 24];
const TEXT: Rgb = [230, 230, 230];
const FRONT: [f32; 3] = [210.0, 208.0, 200.0];
const BACK: [f32; 3] = [95.0, 110.0, 150.0];
const PATCH: [f32; 3] = [70.0, 200.0, 120.0];
const HEADER: usize = 20;
const TILE_BAND: usize = 14;

/// Renders the picture of a repair: `mesh` is the repaired soup that
/// [`crate::repair`] returned with `report` (whose `traces` locate the holes).
pub fn render(mesh: &RawMesh, report: &RepairReport, opts: &Options) -> Picture {
    let width = opts.width.max(320);
    let pos = &mesh.positions;
    let faces = &mesh.faces;
    let holes = hole_views(mesh, report);
    // faces from here on are patches (they are appended, one hole after another)
    let first_patch = holes
        .iter()
        .filter(|h| !h.patch.is_empty())
        .map(|h| h.patch.start as usize)
        .min()
        .unwrap_or(faces.len());

    let owners = Owners::new(&holes);

    // the overview and the close-ups are drawn side by side (rayon::join)
    let stride = faces.len().div_ceil(opts.max_overview_faces.max(1)).max(1);
    let (lo, hi) = bounds(pos, faces, stride);
    let over_h = width * 5 / 8;
    let chosen = choose_closeups(&holes, opts.max_closeups);
    let tile = width / 4;
    let (over, tiles) = rayon::join(
        || {
            overview(
                mesh,
                &holes,
                &owners,
                first_patch,
                stride,
                (lo, hi),
                width,
                over_h,
            )
        },
        || {
            let hood = neighbourhoods(
                mesh,
                &holes,
                &chosen,
                opts.max_closeup_faces,
                (lo, hi),
                first_patch,
            );
            chosen
                .par_iter()
                .zip(hood.par_iter())
                .map(|(&i, near)| closeup(mesh, &owners, &holes[i], near, tile))
                .collect::<Vec<_>>()
        },
    );

    let rows = chosen.len().div_ceil(2);
    let height = HEADER + over_h + rows * (TILE_BAND + tile);
    let mut pic = Panel::flat(width, height, BAND);
    header(&mut pic, report, holes.len());
    pic.blit(&over, 0, HEADER);
    for (k, (&i, (before, after))) in chosen.iter().zip(&tiles).enumerate() {
        let h = &holes[i];
        let x = (k % 2) * 2 * tile;
        let y = HEADER + over_h + (k / 2) * (TILE_BAND + tile);
        let c = status_color(h.status);
        pic.rect(x, y, 2 * tile, TILE_BAND, BAND);
        pic.rect(x, y + TILE_BAND - 2, 2 * tile, 2, c);
        pic.text(x + 4, y + 3, &format!("#{} before", h.id), TEXT, 1);
        let status = match h.status {
            HoleStatus::Filled => "filled",
            HoleStatus::Stitched => "stitched",
            HoleStatus::Skipped => "skipped",
            HoleStatus::Failed => "failed",
        };
        pic.text(
            x + tile + 4,
            y + 3,
            &format!("#{} after: {status}", h.id),
            c,
            1,
        );
        pic.blit(before, x, y + TILE_BAND);
        pic.blit(after, x + tile, y + TILE_BAND);
        // a thin separator between the pair's tiles
        pic.rect(x + tile, y + TILE_BAND, 1, tile, BAND);
    }
    Picture {
        width,
        height,
        rgb: pic.rgb,
    }
}

/// The overview panel: the model (every `stride`-th face) looking at the holes, each
/// hole outlined in its status colour and numbered.
#[allow(clippy::too_many_arguments)]
fn overview(
    mesh: &RawMesh,
    holes: &[HoleView],
    owners: &Owners,
    first_patch: usize,
    stride: usize,
    (lo, hi): (DVec3, DVec3),
    width: usize,
    over_h: usize,
) -> Panel {
    let (pos, faces) = (&mesh.positions, &mesh.faces);
    let mut over = Panel::new(width, over_h, BG);
    if !lo.cmple(hi).all() {
        return over;
    }
    let dir = overview_direction(holes);
    let cam = Camera::fit(dir, lo, hi, width, over_h, 0.92);
    // every vertex projected once when every face is drawn (a face's corners are then
    // three loads); when only every k-th face is, per face, to keep memory bounded
    let screen: Vec<[f32; 3]> = if stride == 1 {
        pos.iter().map(|&p| cam.project(p)).collect()
    } else {
        Vec::new()
    };
    for (f, &face) in faces.iter().enumerate().step_by(stride) {
        let color = if f >= first_patch {
            owners.status(f as u32).map(patch_color)
        } else {
            None
        };
        if stride == 1 {
            let (Some(&a), Some(&b), Some(&c)) = (
                screen.get(face[0] as usize),
                screen.get(face[1] as usize),
                screen.get(face[2] as usize),
            ) else {
                continue;
            };
            over.triangle([a, b, c], shade_projected(&cam, [a, b, c], color));
        } else if let Some(world) = corners(pos, face) {
            over.triangle(world.map(|p| cam.project(p)), shade(&cam, world, color));
        }
    }
    let bias = (cam.extent * 0.004) as f32;
    for h in holes {
        outline(
            &mut over,
            &cam,
            pos,
            &h.boundary,
            status_color(h.status),
            3,
            bias,
            0.45,
        );
    }
    if holes.len() <= 60 {
        for h in holes {
            let [x, y, _] = cam.project(h.center);
            label(
                &mut over,
                x,
                y,
                &format!("#{}", h.id),
                status_color(h.status),
            );
        }
    }
    over
}

/// What the picture knows of one hole.
struct HoleView {
    id: usize,
    status: HoleStatus,
    boundary: Vec<u32>,
    patch: std::ops::Range<u32>,
    center: DVec3,
    /// Largest distance of a boundary vertex from the center.
    radius: f64,
    /// The loop's area vector (patch orientation), not normalised.
    area: DVec3,
    perimeter: f64,
}

fn hole_views(mesh: &RawMesh, report: &RepairReport) -> Vec<HoleView> {
    let pos = &mesh.positions;
    let nf = mesh.faces.len() as u32;
    report
        .holes
        .iter()
        .zip(&report.traces)
        .filter_map(|(h, t): (_, &HoleTrace)| {
            let pts: Vec<DVec3> = t
                .boundary
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
            let start = t.patch.start.min(nf);
            let patch = start..t.patch.end.min(nf).max(start);
            Some(HoleView {
                id: h.id,
                status: h.status,
                boundary: t.boundary.clone(),
                patch,
                center,
                radius,
                area,
                perimeter,
            })
        })
        .collect()
}

/// The patches' face ranges, sorted, with their holes' status: which patch holds a
/// face, by binary search.
struct Owners(Vec<(u32, u32, HoleStatus)>);

impl Owners {
    fn new(holes: &[HoleView]) -> Owners {
        let mut v: Vec<_> = holes
            .iter()
            .filter(|h| !h.patch.is_empty())
            .map(|h| (h.patch.start, h.patch.end, h.status))
            .collect();
        v.sort_by_key(|r| r.0);
        Owners(v)
    }

    /// The status of the hole whose patch holds face `f`.
    fn status(&self, f: u32) -> Option<HoleStatus> {
        let i = self.0.partition_point(|r| r.0 <= f);
        let &(start, end, status) = self.0.get(i.checked_sub(1)?)?;
        (start <= f && f < end).then_some(status)
    }
}

fn patch_color(s: HoleStatus) -> [f32; 3] {
    match s {
        HoleStatus::Filled => PATCH,
        // a patch of a hole not filled cannot be; shown in the status colour anyway
        other => status_color(other).map(f32::from),
    }
}

/// Bounds of the vertices of every `stride`-th face (unreferenced and non-finite
/// vertices left out).
fn bounds(pos: &[DVec3], faces: &[[u32; 3]], stride: usize) -> (DVec3, DVec3) {
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
/// normals when they agree enough, else at the largest hole; a slight tilt shows the
/// relief. Without holes: an oblique view.
fn overview_direction(holes: &[HoleView]) -> DVec3 {
    let oblique = DVec3::new(0.45, 0.35, 0.82).normalize();
    let mut sum = DVec3::ZERO;
    let mut total = 0.0;
    let mut largest: Option<&HoleView> = None;
    for h in holes {
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

/// An orthographic camera: looks along `-dir` (from outside, where `dir` points).
struct Camera {
    center: DVec3,
    right: DVec3,
    up: DVec3,
    fwd: DVec3,
    scale: f64,
    cx: f64,
    cy: f64,
    /// The radius of the scene it frames (world units).
    extent: f64,
    /// The light's direction (towards the light): from the viewer, a little from the
    /// upper left.
    light: DVec3,
    /// The same in the camera's (right, up, forward) coordinates.
    light_cam: glam::Vec3,
}

impl Camera {
    /// Frames the sphere of radius `radius` around `center` in a `w` x `h` panel.
    fn new(dir: DVec3, center: DVec3, radius: f64, w: usize, h: usize) -> Camera {
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
    fn fit(dir: DVec3, lo: DVec3, hi: DVec3, w: usize, h: usize, fill: f64) -> Camera {
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
    fn project(&self, p: DVec3) -> [f32; 3] {
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
fn corners(pos: &[DVec3], f: [u32; 3]) -> Option<[DVec3; 3]> {
    Some([
        *pos.get(f[0] as usize)?,
        *pos.get(f[1] as usize)?,
        *pos.get(f[2] as usize)?,
    ])
}

/// The flat-shaded colour of a face: `patch` is its colour when it belongs to a patch.
#[inline]
fn shade(cam: &Camera, [a, b, c]: [DVec3; 3], patch: Option<[f32; 3]>) -> Rgb {
    let n = (b - a).cross(c - a).normalize_or_zero();
    let facing = -n.dot(cam.fwd);
    let base = match patch {
        Some(p) => p,
        None if facing >= 0.0 => FRONT,
        None => BACK,
    };
    let lit = n.dot(cam.light).abs() as f32;
    let k = 0.28 + 0.72 * lit;
    base.map(|x| (x * k).min(255.0) as u8)
}

/// [`shade`] from a face's projected corners: the camera frame's coordinates are
/// `((x - cx) / scale, (cy - y) / scale, depth)`, and as (right, up, forward) is a
/// left-handed frame, the world normal is minus the cross product of those
/// coordinates' edges. In f32: for the overview's faces, at most a few pixels wide.
#[inline]
fn shade_projected(cam: &Camera, [a, b, c]: [[f32; 3]; 3], patch: Option<[f32; 3]>) -> Rgb {
    let inv = (1.0 / cam.scale) as f32;
    let e1 = glam::Vec3::new((b[0] - a[0]) * inv, (a[1] - b[1]) * inv, b[2] - a[2]);
    let e2 = glam::Vec3::new((c[0] - a[0]) * inv, (a[1] - c[1]) * inv, c[2] - a[2]);
    // the world normal in camera coordinates
    let n = -e1.cross(e2).normalize_or_zero();
    let facing = -n.z;
    let base = match patch {
        Some(p) => p,
        None if facing >= 0.0 => FRONT,
        None => BACK,
    };
    let lit = n.dot(cam.light_cam).abs();
    let k = 0.28 + 0.72 * lit;
    base.map(|x| (x * k).min(255.0) as u8)
}

/// Draws one face, flat-shaded: `patch` is its colour when it belongs to a patch.
#[inline]
fn draw_face(panel: &mut Panel, cam: &Camera, pos: &[DVec3], f: [u32; 3], patch: Option<[f32; 3]>) {
    let Some(world) = corners(pos, f) else {
        return;
    };
    panel.triangle(world.map(|p| cam.project(p)), shade(cam, world, patch));
}

/// Draws a boundary loop.
#[allow(clippy::too_many_arguments)]
fn outline(
    panel: &mut Panel,
    cam: &Camera,
    pos: &[DVec3],
    boundary: &[u32],
    color: Rgb,
    width: usize,
    bias: f32,
    hidden: f32,
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

/// `text` beside a screen point, on a dark backing.
fn label(panel: &mut Panel, x: f32, y: f32, text: &str, color: Rgb) {
    if !(x.is_finite() && y.is_finite()) {
        return;
    }
    let w = text.chars().count() * font::ADVANCE + 3;
    let h = font::HEIGHT + 4;
    let x = (x + 6.0).clamp(0.0, panel.w.saturating_sub(w) as f32) as usize;
    let y = (y - h as f32 / 2.0).clamp(0.0, panel.h.saturating_sub(h) as f32) as usize;
    panel.rect(x, y, w, h, BAND);
    panel.text(x + 2, y + 2, text, color, 1);
}

/// The top band: hole counts in their colours.
fn header(pic: &mut Panel, report: &RepairReport, shown: usize) {
    let s = &report.summary;
    let mut x = 6;
    let mut put = |pic: &mut Panel, t: &str, c: Rgb| {
        pic.text(x, 6, t, c, 1);
        x += t.chars().count() * font::ADVANCE;
    };
    put(pic, &format!("{} holes: ", s.holes.max(shown)), TEXT);
    put(pic, &format!("{} filled", s.filled), FILLED);
    put(pic, ", ", TEXT);
    if s.stitched > 0 {
        put(pic, &format!("{} stitched", s.stitched), FILLED);
        put(pic, ", ", TEXT);
    }
    put(pic, &format!("{} skipped", s.skipped), SKIPPED);
    put(pic, ", ", TEXT);
    put(pic, &format!("{} failed", s.failed), FAILED);
    put(
        pic,
        &format!("   faces {} -> {}", report.before.faces, report.after.faces),
        TEXT,
    );
}

/// Which holes get a close-up: failed ones, then filled ones, then skipped ones, the
/// larger first within each; shown in the log's order.
fn choose_closeups(holes: &[HoleView], max: usize) -> Vec<usize> {
    let rank = |s: HoleStatus| match s {
        HoleStatus::Failed => 0,
        HoleStatus::Filled | HoleStatus::Stitched => 1,
        HoleStatus::Skipped => 2,
    };
    let mut order: Vec<usize> = (0..holes.len())
        .filter(|&i| holes[i].radius > 0.0 && holes[i].radius.is_finite())
        .collect();
    order.sort_by(|&a, &b| {
        rank(holes[a].status)
            .cmp(&rank(holes[b].status))
            .then(holes[b].perimeter.total_cmp(&holes[a].perimeter))
    });
    order.truncate(max.min(u64::BITS as usize));
    order.sort_unstable();
    order
}

/// The view radius of a close-up around its hole.
fn closeup_radius(h: &HoleView) -> f64 {
    h.radius * 1.35
}

/// The faces near each chosen hole (their centroid within the close-up's radius), in
/// one pass over the faces: a grid over the bounds holds, per cell, a bit mask of the
/// close-ups whose sphere reaches it; a face is measured only where its first vertex's
/// cell has a bit set.
fn neighbourhoods(
    mesh: &RawMesh,
    holes: &[HoleView],
    chosen: &[usize],
    cap: usize,
    (lo, hi): (DVec3, DVec3),
    first_patch: usize,
) -> Vec<Near> {
    let mut out: Vec<Near> = (0..chosen.len()).map(|_| Near::default()).collect();
    if chosen.is_empty() || !lo.cmple(hi).all() {
        return out;
    }
    let pos = &mesh.positions;
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
    let spheres: Vec<(DVec3, f64)> = chosen
        .iter()
        .map(|&i| {
            let h = &holes[i];
            // a face's first vertex is within about one edge of its centroid
            let margin = 2.0 * h.perimeter / h.boundary.len().max(1) as f64;
            (h.center, closeup_radius(h) + margin)
        })
        .collect();
    for (k, &(c, r)) in spheres.iter().enumerate() {
        let a = ((c - r - lo) / size * G as f64).floor().as_ivec3();
        let b = ((c + r - lo) / size * G as f64).floor().as_ivec3();
        let a = a.clamp(glam::IVec3::ZERO, glam::IVec3::splat(G as i32 - 1));
        let b = b.clamp(glam::IVec3::ZERO, glam::IVec3::splat(G as i32 - 1));
        for x in a.x..=b.x {
            for y in a.y..=b.y {
                for z in a.z..=b.z {
                    mask[(x as usize * G + y as usize) * G + z as usize] |= 1 << k;
                }
            }
        }
    }
    let radii: Vec<f64> = chosen.iter().map(|&i| closeup_radius(&holes[i])).collect();
    for (f, face) in mesh.faces.iter().enumerate() {
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
            let (center, _) = spheres[k];
            if (centroid - center).length_squared() <= radii[k] * radii[k] {
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

/// The faces around one close-up's hole.
#[derive(Default)]
struct Near {
    /// Faces of the repaired model's input surface.
    surface: Vec<u32>,
    /// Faces of patches (of any hole).
    patches: Vec<u32>,
}

/// The before and after tiles of one hole.
fn closeup(
    mesh: &RawMesh,
    owners: &Owners,
    h: &HoleView,
    near: &Near,
    tile: usize,
) -> (Panel, Panel) {
    let pos = &mesh.positions;
    let faces = &mesh.faces;
    // the loop's normal; for a loop that encloses no area, the mean normal around it
    let mut dir = h.area.normalize_or_zero();
    if dir == DVec3::ZERO {
        let mut sum = DVec3::ZERO;
        for &f in &near.surface {
            if let Some([a, b, c]) = faces.get(f as usize).and_then(|&f| corners(pos, f)) {
                sum += (b - a).cross(c - a);
            }
        }
        dir = sum.normalize_or(DVec3::Z);
    }
    let r = closeup_radius(h);
    let cam = Camera::new(dir, h.center, r, tile, tile);
    let bias = (r * 0.01) as f32;
    let color = status_color(h.status);
    let mut before = Panel::new(tile, tile, BG);
    for &f in &near.surface {
        if let Some(&face) = faces.get(f as usize) {
            draw_face(&mut before, &cam, pos, face, None);
        }
    }
    // the after tile: the same surface with the patches over it
    let mut after = before.clone();
    for &f in &near.patches {
        if h.patch.contains(&f) {
            continue;
        }
        if let (Some(&face), Some(status)) = (faces.get(f as usize), owners.status(f)) {
            draw_face(&mut after, &cam, pos, face, Some(patch_color(status)));
        }
    }
    let patch = h.patch.start as usize..(h.patch.end as usize).min(faces.len());
    let tint = patch_color(h.status);
    for face in &faces[patch.clone()] {
        draw_face(&mut after, &cam, pos, *face, Some(tint));
    }
    // the patch's edges, when its triangles are large enough on screen to tell apart
    let px_area = std::f64::consts::PI * (h.radius * cam.scale).powi(2);
    let edge_px = (2.0 * px_area / patch.len().max(1) as f64).sqrt();
    if !patch.is_empty() && edge_px >= 6.0 {
        let wire = tint.map(|x| (x * 0.45) as u8);
        for face in &faces[patch] {
            for i in 0..3 {
                let (Some(&p), Some(&q)) = (
                    pos.get(face[i] as usize),
                    pos.get(face[(i + 1) % 3] as usize),
                ) else {
                    continue;
                };
                after.line(cam.project(p), cam.project(q), wire, 1, bias * 0.5, 0.0);
            }
        }
    }
    outline(&mut before, &cam, pos, &h.boundary, color, 2, bias, 0.35);
    outline(&mut after, &cam, pos, &h.boundary, color, 2, bias, 0.35);
    (before, after)
}

#[cfg(test)]
mod tests;
