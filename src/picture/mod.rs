//! A picture of a repair: the model with every hole outlined and coloured by its
//! status (filled green, skipped amber, failed red) and numbered as in the log, then a
//! close-up of each hole before and after (the patch's triangles drawn over the
//! surrounding surface, shaded). `holefill fill --picture FILE` and the daemon write
//! it as PNG beside the repair log.
//!
//! How: a small software rasteriser ([`raster`]): orthographic views, one flat-shaded
//! colour per triangle (a head light; back faces, seen through holes, bluish), a
//! depth buffer, outlines drawn over the surface and faded where it hides them; 256
//! colours ([`palette`]), a byte a pixel, an indexed PNG. The overview looks at the
//! input's boundary loops (along the mean of their normals, else at the largest),
//! each close-up along its hole's normal (the loop's area vector, else the mean
//! normal around it).
//!
//! Two steps, so that a picture costs the repair little: a [`Sketch`] draws what the
//! input decides (the overview's surface, the close-ups' surfaces of the largest
//! boundary loops) while the holes are filled, and [`Sketch::finish`] the rest (the
//! patches, outlines and numbers, the close-ups of other holes) once they are. It
//! keeps what the sketch drew where the repaired model's first faces have the input's
//! corner points, bit for bit (the repair may renumber a vertex it does not move);
//! where it also kept the input's vertex numbers, the picture is the one [`render`],
//! which draws everything after the repair, draws, bit for bit (a test holds them
//! equal).
//!
//! Bounded time and memory for huge meshes: memory is the image and its depth buffers
//! (about 2 MB at the default width) plus the face numbers of the close-ups'
//! neighbourhoods; the overview draws at most [`Options::max_overview_faces`] of the
//! surface's faces (every k-th one: far more than its pixels) and the patches, and the
//! close-ups' neighbourhoods are found in one pass over the faces that looks up one
//! grid cell per face (a bit mask of the close-ups near it) and measures only the
//! faces near a hole.

mod font;
mod holes;
mod palette;
mod panels;
mod raster;
mod sketch;
mod view;

pub use sketch::Sketch;

use crate::io::RawMesh;
use crate::report::{HoleStatus, RepairReport};
use holes::{
    bounds, choose_closeups, hole_views, loop_rings, neighbourhoods, overview_direction, HoleView,
    Owners, Ring,
};
use palette::{status_ink, Ink, BAND, BG, TEXT};
use raster::Panel;
use rayon::prelude::*;
use view::Camera;

/// Size and limits of a picture.
#[derive(Clone, Debug)]
pub struct Options {
    /// Width of the image in pixels (at least 320); the height follows from the
    /// number of close-ups.
    pub width: usize,
    /// At most this many holes get a close-up (failed holes first, then the largest
    /// filled ones, then skipped ones); every hole is outlined in the overview.
    pub max_closeups: usize,
    /// The overview draws every k-th face of the input's surface so that at most this
    /// many are drawn (and every patch face).
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

/// An image of 256 colours: a palette index per pixel, rows top first.
#[derive(Clone, Debug)]
pub struct Picture {
    pub width: usize,
    pub height: usize,
    /// `width * height` palette indices.
    pub index: Vec<u8>,
}

/// The picture could not be encoded.
#[derive(Debug, thiserror::Error)]
#[error("cannot encode the picture as PNG: {0}")]
pub struct PictureError(String);

impl Picture {
    /// The colour of a pixel (`None` outside the image).
    pub fn pixel(&self, x: usize, y: usize) -> Option<[u8; 3]> {
        (x < self.width && y < self.height)
            .then(|| palette::palette()[self.index[y * self.width + x] as usize])
    }

    /// The colours of the pixels, rows top first.
    pub fn pixels(&self) -> impl Iterator<Item = [u8; 3]> + '_ {
        let p = palette::palette();
        self.index.iter().map(|&i| p[i as usize])
    }

    /// The image as an indexed PNG file's bytes (the fastest compression, rows
    /// filtered by `Up`, which makes the panels' flat and repeated rows runs of zeros:
    /// a quarter of the bytes and half the time of no filter; the picture must cost
    /// little next to the repair).
    pub fn to_png(&self) -> Result<Vec<u8>, PictureError> {
        let mut out = Vec::with_capacity(self.index.len() / 4);
        {
            let w = u32::try_from(self.width).map_err(|e| PictureError(e.to_string()))?;
            let h = u32::try_from(self.height).map_err(|e| PictureError(e.to_string()))?;
            let mut enc = png::Encoder::new(&mut out, w, h);
            enc.set_color(png::ColorType::Indexed);
            enc.set_depth(png::BitDepth::Eight);
            enc.set_palette(palette::palette().as_flattened());
            enc.set_compression(png::Compression::Fastest);
            enc.set_filter(png::Filter::Up);
            let mut wr = enc
                .write_header()
                .map_err(|e| PictureError(e.to_string()))?;
            wr.write_image_data(&self.index)
                .map_err(|e| PictureError(e.to_string()))?;
            wr.finish().map_err(|e| PictureError(e.to_string()))?;
        }
        Ok(out)
    }
}

/// The colour of a hole's outline and label.
pub fn status_color(s: HoleStatus) -> [u8; 3] {
    match s {
        HoleStatus::Filled | HoleStatus::Stitched => palette::FILLED_RGB,
        HoleStatus::Skipped => palette::SKIPPED_RGB,
        HoleStatus::Failed => palette::FAILED_RGB,
    }
}

const HEADER: usize = 20;
const TILE_BAND: usize = 14;

/// Renders the picture of a repair: `mesh` is the repaired soup that
/// [`crate::repair`] returned with `report` (whose `traces` locate the holes).
pub fn render(mesh: &RawMesh, report: &RepairReport, opts: &Options) -> Picture {
    draw(mesh, report, opts, None)
}

/// What a [`Sketch`] drew that the picture keeps: the overview's surface when it was
/// drawn with the same camera, and the close-ups' "before" surfaces of the same loops.
struct Kept {
    /// The number of faces the sketch's surface had.
    surface: usize,
    /// The surface's bounds and the overview's direction, as [`draw`] finds them.
    view: View,
    overview: Option<(Camera, Panel)>,
    tiles: Vec<sketch::Tile>,
}

/// The picture, with what a sketch drew of it kept (`kept`: the input's surface is
/// the repaired model's up to its first patch, bit for bit).
fn draw(mesh: &RawMesh, report: &RepairReport, opts: &Options, kept: Option<Kept>) -> Picture {
    let width = opts.width.max(320);
    let (pos, faces) = (&mesh.positions, &mesh.faces);
    let holes = hole_views(mesh, report);
    // faces from here on are patches (they are appended, one hole after another)
    let first_patch = first_patch(&holes, faces.len());
    let owners = Owners::new(&holes);
    let stride = overview_stride(first_patch, opts);
    let over_h = width * 5 / 8;
    let chosen = choose_closeups(&holes, opts.max_closeups);
    let tile = width / 4;
    let kept = kept.filter(|k| k.surface == first_patch);
    let View { lo, hi, dir } = match &kept {
        Some(k) => k.view,
        None => {
            let surface = &faces[..first_patch];
            View::of(pos, surface, stride, &loop_rings(pos, surface))
        }
    };
    let cam = lo
        .cmple(hi)
        .all()
        .then(|| Camera::fit(dir, lo, hi, width, over_h, 0.92));
    let (mut kept_over, mut kept_tiles) = match kept {
        Some(k) => (k.overview, k.tiles),
        None => (None, Vec::new()),
    };

    // the overview and the close-ups are drawn side by side (rayon::join)
    let (over, tiles) = rayon::join(
        || {
            let Some(cam) = &cam else {
                return Panel::new(width, over_h, BG);
            };
            let surface = match kept_over.take() {
                Some((c, panel)) if c == *cam => panel,
                _ => panels::overview_surface(mesh, first_patch, stride, cam, (width, over_h)),
            };
            panels::overview_finish(surface, cam, mesh, first_patch, &holes, &owners)
        },
        || {
            // the sketch's tiles of these loops, else none
            let mut from_sketch: Vec<Option<sketch::Tile>> = chosen
                .iter()
                .map(|&i| {
                    let k = kept_tiles.iter().position(|t| t.ring == holes[i].ring)?;
                    Some(kept_tiles.swap_remove(k))
                })
                .collect();
            let rings = |kept: bool| -> Vec<&Ring> {
                chosen
                    .iter()
                    .zip(&from_sketch)
                    .filter(|(_, t)| t.is_some() == kept)
                    .map(|(&i, _)| &holes[i].ring)
                    .collect()
            };
            // the kept ones need the patches around them, the others everything
            let kept_near = neighbourhoods(
                pos,
                (&faces[first_patch..], first_patch),
                &rings(true),
                opts.max_closeup_faces,
                (lo, hi),
                first_patch,
            );
            let new_near = neighbourhoods(
                pos,
                (faces, 0),
                &rings(false),
                opts.max_closeup_faces,
                (lo, hi),
                first_patch,
            );
            let (mut kept_near, mut new_near) = (kept_near.into_iter(), new_near.into_iter());
            let work: Vec<_> = chosen
                .iter()
                .zip(from_sketch.iter_mut())
                .map(|(&i, t)| match t.take() {
                    Some(t) => (i, Some(t), kept_near.next().unwrap_or_default()),
                    None => (i, None, new_near.next().unwrap_or_default()),
                })
                .collect();
            work.into_par_iter()
                .map(|(i, t, near)| match t {
                    Some(t) => panels::finish_tiles(
                        t.before,
                        &t.cam,
                        mesh,
                        &owners,
                        &holes[i],
                        &near.patches,
                    ),
                    None => panels::closeup(mesh, &owners, &holes[i], &near, tile),
                })
                .collect::<Vec<_>>()
        },
    );
    compose(report, &holes, &chosen, over, tiles, width)
}

/// Where the overview looks from: the bounds of the input's surface (every
/// `stride`-th face) and the direction towards its boundary loops (the holes as the
/// input has them, which a sketch knows before the repair ends: so that the overview
/// a sketch draws is the one kept).
#[derive(Clone, Copy, Debug)]
struct View {
    lo: glam::DVec3,
    hi: glam::DVec3,
    dir: glam::DVec3,
}

impl View {
    /// The view of the surface `surface` whose boundary loops are `rings`.
    fn of(pos: &[glam::DVec3], surface: &[[u32; 3]], stride: usize, rings: &[Ring]) -> View {
        let (lo, hi) = bounds(pos, surface, stride);
        let dir = overview_direction(rings.iter());
        View { lo, hi, dir }
    }
}

/// The first face of a patch (the faces before it are the input's surface).
fn first_patch(holes: &[HoleView], faces: usize) -> usize {
    holes
        .iter()
        .filter(|h| !h.patch.is_empty())
        .map(|h| h.patch.start as usize)
        .min()
        .unwrap_or(faces)
        .min(faces)
}

/// The overview draws every k-th surface face (and every patch face).
fn overview_stride(surface: usize, opts: &Options) -> usize {
    surface.div_ceil(opts.max_overview_faces.max(1)).max(1)
}

/// The picture from its panels: the header, the overview, then the close-ups two
/// holes to a row, each with its band (number, status).
fn compose(
    report: &RepairReport,
    holes: &[HoleView],
    chosen: &[usize],
    over: Panel,
    tiles: Vec<(Panel, Panel)>,
    width: usize,
) -> Picture {
    let (over_h, tile) = (over.h, width / 4);
    let rows = chosen.len().div_ceil(2);
    let height = HEADER + over_h + rows * (TILE_BAND + tile);
    let mut pic = Panel::flat(width, height, BAND);
    header(&mut pic, report, holes.len());
    pic.blit(&over, 0, HEADER);
    for (k, (&i, (before, after))) in chosen.iter().zip(&tiles).enumerate() {
        let h = &holes[i];
        let x = (k % 2) * 2 * tile;
        let y = HEADER + over_h + (k / 2) * (TILE_BAND + tile);
        let c = status_ink(h.status);
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
        index: pic.px,
    }
}

/// The top band: hole counts in their colours.
fn header(pic: &mut Panel, report: &RepairReport, shown: usize) {
    let s = &report.summary;
    let mut x = 6;
    let mut put = |pic: &mut Panel, t: &str, c: Ink| {
        pic.text(x, 6, t, c, 1);
        x += t.chars().count() * font::ADVANCE;
    };
    put(pic, &format!("{} holes: ", s.holes.max(shown)), TEXT);
    let filled = status_ink(HoleStatus::Filled);
    put(pic, &format!("{} filled", s.filled), filled);
    put(pic, ", ", TEXT);
    if s.stitched > 0 {
        put(pic, &format!("{} stitched", s.stitched), filled);
        put(pic, ", ", TEXT);
    }
    put(
        pic,
        &format!("{} skipped", s.skipped),
        status_ink(HoleStatus::Skipped),
    );
    put(pic, ", ", TEXT);
    put(
        pic,
        &format!("{} failed", s.failed),
        status_ink(HoleStatus::Failed),
    );
    put(
        pic,
        &format!("   faces {} -> {}", report.before.faces, report.after.faces),
        TEXT,
    );
}

#[cfg(test)]
mod tests;
