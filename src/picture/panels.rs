//! The panels of a picture: the overview (the input surface, then the patches, the
//! outlines and the numbers over it) and each hole's close-up before and after.
//! Each panel is drawn in two steps, the surface first, so that a [`super::Sketch`]
//! can draw the surface while the holes are filled.

use super::font;
use super::holes::{HoleView, Near, Owners, Ring};
use super::palette::{hidden_ink, status_ink, Ink, Material, BAND, BG};
use super::raster::Panel;
use super::view::{corners, draw_face, outline, shade_projected, Camera};
use crate::io::RawMesh;
use glam::DVec3;

/// The overview's input surface: every `stride`-th of the faces before `surface`.
pub(super) fn overview_surface(
    mesh: &RawMesh,
    surface: usize,
    stride: usize,
    cam: &Camera,
    (w, h): (usize, usize),
) -> Panel {
    let (pos, faces) = (
        &mesh.positions,
        &mesh.faces[..surface.min(mesh.faces.len())],
    );
    let mut over = Panel::new(w, h, BG);
    // every vertex projected once when every face is drawn (a face's corners are then
    // three loads); when only every k-th face is, per face, to keep memory bounded
    if stride == 1 {
        let screen: Vec<[f32; 3]> = pos.iter().map(|&p| cam.project(p)).collect();
        for face in faces {
            let (Some(&a), Some(&b), Some(&c)) = (
                screen.get(face[0] as usize),
                screen.get(face[1] as usize),
                screen.get(face[2] as usize),
            ) else {
                continue;
            };
            over.triangle([a, b, c], || shade_projected(cam, [a, b, c], None));
        }
    } else {
        for &face in faces.iter().step_by(stride) {
            if let Some(world) = corners(pos, face) {
                let s = world.map(|p| cam.project(p));
                over.triangle(s, || shade_projected(cam, s, None));
            }
        }
    }
    over
}

/// The rest of the overview on its surface: the faces from `first_patch` (patches in
/// their colour), then every hole outlined in its status colour and numbered.
pub(super) fn overview_finish(
    mut over: Panel,
    cam: &Camera,
    mesh: &RawMesh,
    first_patch: usize,
    holes: &[HoleView],
    owners: &Owners,
) -> Panel {
    let pos = &mesh.positions;
    for (f, &face) in mesh.faces.iter().enumerate().skip(first_patch) {
        if let Some(world) = corners(pos, face) {
            let s = world.map(|p| cam.project(p));
            let status = owners.status(f as u32);
            over.triangle(s, || shade_projected(cam, s, status));
        }
    }
    let bias = (cam.extent * 0.004) as f32;
    for h in holes {
        let (c, faded) = (status_ink(h.status), hidden_ink(h.status, true));
        outline(
            &mut over,
            cam,
            pos,
            &h.ring.boundary,
            c,
            3,
            bias,
            Some(faded),
        );
    }
    if holes.len() <= 60 {
        for h in holes {
            let [x, y, _] = cam.project(h.ring.center);
            label(&mut over, x, y, &format!("#{}", h.id), status_ink(h.status));
        }
    }
    over
}

/// `text` beside a screen point, on a dark backing.
pub(super) fn label(panel: &mut Panel, x: f32, y: f32, text: &str, color: Ink) {
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

/// A close-up's camera: along the loop's normal; for a loop that encloses no area,
/// the mean normal of the surface around it.
pub(super) fn closeup_camera(mesh: &RawMesh, ring: &Ring, surface: &[u32], tile: usize) -> Camera {
    let (pos, faces) = (&mesh.positions, &mesh.faces);
    let mut dir = ring.area.normalize_or_zero();
    if dir == DVec3::ZERO {
        let mut sum = DVec3::ZERO;
        for &f in surface {
            if let Some([a, b, c]) = faces.get(f as usize).and_then(|&f| corners(pos, f)) {
                sum += (b - a).cross(c - a);
            }
        }
        dir = sum.normalize_or(DVec3::Z);
    }
    Camera::new(dir, ring.center, ring.view_radius(), tile, tile)
}

/// A close-up's "before" tile without its outline: the surface around the hole.
pub(super) fn before_tile(mesh: &RawMesh, cam: &Camera, surface: &[u32], tile: usize) -> Panel {
    let mut before = Panel::new(tile, tile, BG);
    for &f in surface {
        if let Some(&face) = mesh.faces.get(f as usize) {
            draw_face(&mut before, cam, &mesh.positions, face, None);
        }
    }
    before
}

/// Both tiles of a close-up from its "before" surface: the "after" tile is that
/// surface with the patches over it (other holes' near it, then the hole's own, with
/// its edges when they are large enough on screen to tell apart), and both get the
/// loop's outline in the hole's status colour.
pub(super) fn finish_tiles(
    mut before: Panel,
    cam: &Camera,
    mesh: &RawMesh,
    owners: &Owners,
    h: &HoleView,
    patches: &[u32],
) -> (Panel, Panel) {
    let (pos, faces) = (&mesh.positions, &mesh.faces);
    let bias = (h.ring.view_radius() * 0.01) as f32;
    let mut after = before.clone();
    for &f in patches {
        if h.patch.contains(&f) {
            continue;
        }
        if let (Some(&face), Some(status)) = (faces.get(f as usize), owners.status(f)) {
            draw_face(&mut after, cam, pos, face, Some(status));
        }
    }
    let patch = h.patch.start as usize..(h.patch.end as usize).min(faces.len());
    for face in &faces[patch.clone()] {
        draw_face(&mut after, cam, pos, *face, Some(h.status));
    }
    let px_area = std::f64::consts::PI * (h.ring.radius * cam.scale).powi(2);
    let edge_px = (2.0 * px_area / patch.len().max(1) as f64).sqrt();
    if !patch.is_empty() && edge_px >= 6.0 {
        let wire = Material::Patch(h.status).wire();
        for face in &faces[patch] {
            for i in 0..3 {
                let (Some(&p), Some(&q)) = (
                    pos.get(face[i] as usize),
                    pos.get(face[(i + 1) % 3] as usize),
                ) else {
                    continue;
                };
                after.line(cam.project(p), cam.project(q), wire, 1, bias * 0.5, None);
            }
        }
    }
    let (color, faded) = (status_ink(h.status), Some(hidden_ink(h.status, false)));
    for tile in [&mut before, &mut after] {
        outline(tile, cam, pos, &h.ring.boundary, color, 2, bias, faded);
    }
    (before, after)
}

/// The before and after tiles of one hole, drawn whole.
pub(super) fn closeup(
    mesh: &RawMesh,
    owners: &Owners,
    h: &HoleView,
    near: &Near,
    tile: usize,
) -> (Panel, Panel) {
    let cam = closeup_camera(mesh, &h.ring, &near.surface, tile);
    let before = before_tile(mesh, &cam, &near.surface, tile);
    finish_tiles(before, &cam, mesh, owners, h, &near.patches)
}
