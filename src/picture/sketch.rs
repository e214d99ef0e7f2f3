//! The part of a picture that the input decides, drawn while it is repaired (the
//! holes as the input's boundary loops): the overview's surface and the "before"
//! surfaces of the largest loops' close-ups. [`Sketch::finish`] draws the rest once
//! the repair is known and keeps of the sketch what it would have drawn the same:
//! where the repair kept the input's faces and vertex numbers, the picture is the one
//! [`super::render`] draws, to the bit.

#[cfg(test)]
use super::holes::rings;
use super::holes::{loop_rings, neighbourhoods, Ring};
use super::panels::{before_tile, closeup_camera, overview_surface};
use super::raster::Panel;
use super::view::Camera;
use super::{draw, overview_stride, Kept, Options, Picture, View};
use crate::io::RawMesh;
use crate::report::RepairReport;
use glam::DVec3;

/// What is drawn of a repair's picture before the repair ends; see the module doc.
///
/// ```no_run
/// # let (raw, policy) = (holefill::io::RawMesh::default(), holefill::policy::Policy::default_policy());
/// use holefill::picture::{Options, Sketch};
/// let opts = Options::default();
/// // the sketch beside the repair (here on a thread of its own)
/// let (sketch, repaired) = std::thread::scope(|s| {
///     let sketch = s.spawn(|| Sketch::new(&raw, &opts));
///     let repaired = holefill::repair(&raw, &policy);
///     (sketch.join().ok(), repaired)
/// });
/// let (out, report) = repaired.unwrap();
/// let picture = match sketch {
///     Some(s) => s.finish(&raw, &out, &report, &opts),
///     None => holefill::picture::render(&out, &report, &opts),
/// };
/// ```
pub struct Sketch {
    /// The options it was drawn with.
    width: usize,
    max_overview_faces: usize,
    max_closeup_faces: usize,
    /// The surface's bounds and the overview's direction.
    view: View,
    pub(super) overview: Option<(Camera, Panel)>,
    pub(super) tiles: Vec<Tile>,
}

/// A close-up's surface before the repair.
pub(super) struct Tile {
    pub ring: Ring,
    pub cam: Camera,
    pub before: Panel,
}

impl Sketch {
    /// Draws the surface of `input` for the overview, looking at its boundary loops
    /// (the holes the repair will find in a clean mesh), and the surfaces around the
    /// largest loops for their close-ups (the repair decides which holes get one: the
    /// failed ones first; the largest are those in the common case).
    pub fn new(input: &RawMesh, opts: &Options) -> Sketch {
        Sketch::with(input, &loop_rings(&input.positions, &input.faces), opts)
    }

    /// [`Sketch::new`] taking `loops` for the input's boundary loops (the overview
    /// looks at them, the close-ups are theirs).
    #[cfg(test)]
    pub(super) fn from_loops(input: &RawMesh, loops: &[Vec<u32>], opts: &Options) -> Sketch {
        Sketch::with(input, &rings(&input.positions, loops), opts)
    }

    /// The sketch of `input` whose boundary loops are `rings`.
    fn with(input: &RawMesh, rings: &[Ring], opts: &Options) -> Sketch {
        let width = opts.width.max(320);
        let (over_h, tile) = (width * 5 / 8, width / 4);
        let (pos, faces) = (&input.positions, &input.faces);
        let stride = overview_stride(faces.len(), opts);
        let view = View::of(pos, faces, stride, rings);
        let View { lo, hi, dir } = view;
        let mut sketch = Sketch {
            width,
            max_overview_faces: opts.max_overview_faces,
            max_closeup_faces: opts.max_closeup_faces,
            view,
            overview: None,
            tiles: Vec::new(),
        };
        if !lo.cmple(hi).all() {
            return sketch;
        }
        let cam = Camera::fit(dir, lo, hi, width, over_h, 0.92);
        let surface = overview_surface(input, faces.len(), stride, &cam, (width, over_h));
        sketch.overview = Some((cam, surface));

        let mut order: Vec<&Ring> = rings.iter().filter(|r| r.shown()).collect();
        order.sort_by(|a, b| b.perimeter.total_cmp(&a.perimeter));
        order.truncate(opts.max_closeups.min(u64::BITS as usize));
        let near = neighbourhoods(
            pos,
            (faces, 0),
            &order,
            opts.max_closeup_faces,
            (lo, hi),
            faces.len(),
        );
        sketch.tiles = order
            .into_iter()
            .zip(near)
            .map(|(ring, near)| {
                let cam = closeup_camera(input, ring, &near.surface, tile);
                let before = before_tile(input, &cam, &near.surface, tile);
                Tile {
                    ring: ring.clone(),
                    cam,
                    before,
                }
            })
            .collect();
        sketch
    }

    /// The picture of the repair of `input` (the input this sketch drew) into `mesh`
    /// with `report`: what the sketch drew is kept where the repaired model's surface
    /// is the input's, bit for bit (faces up to the first patch with the input's
    /// corner points) and drawn the same way (same options, camera and loop); the rest
    /// is drawn now.
    pub fn finish(
        self,
        input: &RawMesh,
        mesh: &RawMesh,
        report: &RepairReport,
        opts: &Options,
    ) -> Picture {
        let same_options = self.width == opts.width.max(320)
            && self.max_overview_faces == opts.max_overview_faces
            && self.max_closeup_faces == opts.max_closeup_faces;
        let kept = (same_options && same_surface(input, mesh)).then_some(Kept {
            surface: input.faces.len(),
            view: self.view,
            overview: self.overview,
            tiles: self.tiles,
        });
        draw(mesh, report, opts, kept)
    }
}

/// The repaired model's first faces are the input's faces where it matters to a
/// picture: the same corner points, bit for bit, in the same order (the repair may
/// have renumbered a vertex, splitting a non-manifold one, without moving it); that
/// the faces after them are patches, [`draw`] checks.
fn same_surface(input: &RawMesh, mesh: &RawMesh) -> bool {
    let Some(out) = mesh.faces.get(..input.faces.len()) else {
        return false;
    };
    let bits = |p: &DVec3| p.to_array().map(f64::to_bits);
    let n = input.positions.len();
    let kept_points = mesh.positions.get(..n).is_some_and(|p| {
        p.iter()
            .zip(&input.positions)
            .all(|(a, b)| bits(a) == bits(b))
    });
    if kept_points && out == input.faces.as_slice() {
        // the same faces on the same points, but for a vertex past the input's
        let (n, m) = (n as u64, mesh.positions.len() as u64);
        return out
            .iter()
            .flatten()
            .all(|&v| u64::from(v) < n || u64::from(v) >= m);
    }
    let corner = |pos: &[DVec3], v: u32| pos.get(v as usize).map(bits);
    out.iter().zip(&input.faces).all(|(a, b)| {
        (0..3).all(|k| corner(&mesh.positions, a[k]) == corner(&input.positions, b[k]))
    })
}
