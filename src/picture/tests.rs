use super::palette::{FILLED_RGB as FILLED, SKIPPED_RGB as SKIPPED};
use super::*;
use crate::policy::Policy;
use crate::report::RepairReport;
use crate::testutil::sphere_caps_removed;
use glam::DVec3;
use std::path::Path;

/// A sphere of radius 1 (1,280 faces) with a hole of `cap` radians around +z and, when
/// `second` is given, another around +x.
fn holed_sphere(cap: f64, second: Option<f64>) -> RawMesh {
    let caps: Vec<(DVec3, f64)> = [(DVec3::Z, cap)]
        .into_iter()
        .chain(second.map(|c| (DVec3::X, c)))
        .collect();
    sphere_caps_removed(3, 1.0, &caps)
}

fn is(c: [u8; 3], want: [u8; 3]) -> bool {
    c == want
}

/// Pixels of exactly colour `c` in the rectangle.
fn count(p: &Picture, x0: usize, y0: usize, w: usize, h: usize, c: [u8; 3]) -> usize {
    let mut n = 0;
    for y in y0..(y0 + h).min(p.height) {
        for x in x0..(x0 + w).min(p.width) {
            if p.pixel(x, y).is_some_and(|q| is(q, c)) {
                n += 1;
            }
        }
    }
    n
}

/// Where the k-th close-up's tiles are (before, after): top-left corners and size.
fn tiles(p: &Picture, k: usize) -> ((usize, usize), (usize, usize), usize) {
    let tile = p.width / 4;
    let over_h = p.width * 5 / 8;
    let x = (k % 2) * 2 * tile;
    let y = HEADER + over_h + (k / 2) * (TILE_BAND + tile) + TILE_BAND;
    ((x, y), (x + tile, y), tile)
}

#[test]
fn a_filled_hole_is_outlined_green_and_its_patch_shows_only_after() {
    let raw = holed_sphere(0.5, None);
    let (out, report) = crate::pipeline::repair(&raw, &Policy::default_policy()).unwrap();
    assert_eq!(report.summary.filled, 1, "{:?}", report.summary);
    assert_eq!(report.traces.len(), 1);
    let t = &report.traces[0];
    assert!(t.boundary.len() >= 10);
    assert_eq!(
        (t.patch.end - t.patch.start) as usize,
        report.holes[0].added_faces
    );
    assert_eq!(
        t.patch.end as usize,
        out.faces.len(),
        "the patch is appended"
    );

    let pic = render(&out, &report, &Options::default());
    assert_eq!(pic.width, 512);
    let over_h = 512 * 5 / 8;
    let tile = 512 / 4;
    assert_eq!(
        pic.height,
        HEADER + over_h + TILE_BAND + tile,
        "one close-up row"
    );
    assert_eq!(pic.index.len(), pic.width * pic.height);

    // the overview: the outline in the filled colour, the surface lit
    let green = count(&pic, 0, HEADER, pic.width, over_h, FILLED);
    assert!(green > 200, "outline pixels: {green}");
    let lit = pic
        .pixels()
        .filter(|c| c[0] > 120 && c[1] > 120 && c[2] > 110)
        .count();
    assert!(lit > 10_000, "surface pixels: {lit}");

    // the close-up: the middle of the hole shows the inside (bluish back faces) before,
    // the patch (green) after
    let ((bx, by), (ax, ay), s) = tiles(&pic, 0);
    let mid = s / 2;
    let before = pic.pixel(bx + mid, by + mid).unwrap();
    let after = pic.pixel(ax + mid, ay + mid).unwrap();
    assert!(
        before[2] > before[0],
        "inside seen through the hole: {before:?}"
    );
    assert!(
        after[1] > after[0] + 40 && after[1] > after[2] + 20,
        "the patch: {after:?}"
    );
    // the outline in both tiles
    assert!(count(&pic, bx, by, s, s, FILLED) > 50);
    assert!(count(&pic, ax, ay, s, s, FILLED) > 50);

    let png = pic.to_png().unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    assert!(png.len() > 1000 && png.len() < pic.index.len());
    // it decodes to the same colours
    let mut dec = png::Decoder::new(std::io::Cursor::new(&png));
    dec.set_transformations(png::Transformations::EXPAND);
    let mut reader = dec.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(
        (info.width as usize, info.height as usize),
        (pic.width, pic.height)
    );
    assert_eq!(info.color_type, png::ColorType::Rgb);
    assert!(buf[..info.buffer_size()]
        .chunks(3)
        .zip(pic.pixels())
        .all(|(a, b)| a == b));
}

#[test]
fn a_skipped_hole_is_amber_and_every_hole_is_outlined() {
    // the big hole is the longest loop and exceeds border.max_vertices: skipped
    let raw = holed_sphere(0.9, Some(0.35));
    let policy =
        Policy::from_toml_str("[border]\nmax_vertices = 20\n", Path::new("test.toml")).unwrap();
    let (out, report) = crate::pipeline::repair(&raw, &policy).unwrap();
    assert_eq!(
        (report.summary.filled, report.summary.skipped),
        (1, 1),
        "{:?}",
        report.holes
    );
    let pic = render(&out, &report, &Options::default());
    let over_h = pic.width * 5 / 8;
    assert!(count(&pic, 0, HEADER, pic.width, over_h, SKIPPED) > 100);
    assert!(count(&pic, 0, HEADER, pic.width, over_h, FILLED) > 30);
    // two close-ups on one row: the filled hole's patch, the skipped hole open
    assert_eq!(pic.height, HEADER + over_h + TILE_BAND + pic.width / 4);
    let skipped = report
        .holes
        .iter()
        .position(|h| h.status == HoleStatus::Skipped)
        .unwrap();
    let ((_, _), (ax, ay), s) = tiles(&pic, skipped);
    let mid = pic.pixel(ax + s / 2, ay + s / 2).unwrap();
    assert!(mid[2] >= mid[1], "a skipped hole stays open after: {mid:?}");
    assert!(count(&pic, ax, ay, s, s, SKIPPED) > 50);
}

#[test]
fn without_holes_only_the_overview_is_drawn() {
    let raw = crate::testutil::icosphere(2, 1.0);
    let (out, report) = crate::pipeline::repair(&raw, &Policy::default_policy()).unwrap();
    assert_eq!(report.summary.holes, 0);
    let pic = render(&out, &report, &Options::default());
    assert_eq!(pic.height, HEADER + pic.width * 5 / 8);
    // the header says "0 filled" in green; the model has no outline
    assert_eq!(count(&pic, 0, HEADER, pic.width, pic.height, FILLED), 0);
}

#[test]
fn the_overview_of_a_huge_mesh_draws_a_bounded_share_of_its_faces() {
    // max_overview_faces far below the face count: every k-th face is drawn, and the
    // surface still covers the sphere's disc (faces are smaller than pixels there)
    let raw = holed_sphere(0.5, None);
    let (out, report) = crate::pipeline::repair(&raw, &Policy::default_policy()).unwrap();
    let full = render(&out, &report, &Options::default());
    let opts = Options {
        max_overview_faces: out.faces.len() / 3,
        width: 320,
        ..Options::default()
    };
    let few = render(&out, &report, &opts);
    assert_eq!(few.width, 320);
    let lit = |p: &Picture| p.pixels().filter(|c| c[0] > 120 && c[1] > 120).count();
    assert!(lit(&few) > 0 && lit(&few) < lit(&full));
}

#[test]
fn bad_indices_and_non_finite_points_do_not_panic() {
    let raw = holed_sphere(0.5, None);
    let (mut out, mut report) = crate::pipeline::repair(&raw, &Policy::default_policy()).unwrap();
    out.faces.push([0, 1, u32::MAX]);
    out.positions[0] = DVec3::splat(f64::NAN);
    report.traces[0].boundary.push(u32::MAX);
    report.traces[0].patch.end += 1000;
    let pic = render(&out, &report, &Options::default());
    assert!(pic.width > 0 && pic.height > 0);
    // a report without traces (the hole is then not drawn)
    report.traces.clear();
    let pic = render(&out, &report, &Options::default());
    assert_eq!(pic.height, HEADER + pic.width * 5 / 8);
}

/// The repair of `raw` and the boundary loops of `raw` that the sketch looks at.
fn repair_seen(raw: &RawMesh, policy: &Policy) -> (RawMesh, RepairReport, Vec<Vec<u32>>) {
    let (out, report) = crate::pipeline::repair(raw, policy).unwrap();
    (
        out,
        report,
        holes::soup_loops(&raw.faces, raw.positions.len()),
    )
}

#[test]
fn the_soups_loops_are_the_holes_the_repair_finds() {
    let raw = holed_sphere(0.5, Some(0.35));
    let (_, report, loops) = repair_seen(&raw, &Policy::default_policy());
    // the same loops, oriented the same way (a turn of the start aside)
    let ring = |l: &[u32]| Ring::new(&raw.positions, l).unwrap();
    let mut got: Vec<Ring> = loops.iter().map(|l| ring(l)).collect();
    let mut want: Vec<Ring> = report.traces.iter().map(|t| ring(&t.boundary)).collect();
    got.sort_by_key(|r| r.boundary[0]);
    want.sort_by_key(|r| r.boundary[0]);
    assert_eq!(got.len(), 2);
    assert_eq!(got, want);

    // loops touching at a vertex (which way they pair is the repair's choice), a face
    // with a vertex missing and a degenerate face: left out, no panic
    let faces = vec![[0, 1, 2], [0, 3, 4], [0, 1, 99], [2, 2, 3]];
    assert!(holes::soup_loops(&faces, 5).is_empty());
    // one triangle: its loop runs against it
    assert_eq!(holes::soup_loops(&[[0, 1, 2]], 3), vec![vec![0, 2, 1]]);
}

#[test]
fn a_sketch_finishes_into_the_picture_render_draws() {
    let raw = holed_sphere(0.5, Some(0.35));
    let policy = Policy::default_policy();
    let (out, report, loops) = repair_seen(&raw, &policy);
    assert_eq!(loops.len(), 2);
    assert_eq!(report.summary.filled, 2);
    let opts = Options::default();
    let want = render(&out, &report, &opts);
    let sketch = Sketch::new(&raw, &opts);
    assert!(sketch.overview.is_some());
    assert_eq!(sketch.tiles.len(), 2);
    let got = sketch.finish(&raw, &out, &report, &opts);
    assert_eq!((got.width, got.height), (want.width, want.height));
    assert!(
        got.index == want.index,
        "the finished sketch differs from render"
    );

    // the loops from any start and in any order: the same
    let mut turned: Vec<Vec<u32>> = loops.iter().rev().cloned().collect();
    turned[0].rotate_left(3);
    let got = Sketch::from_loops(&raw, &turned, &opts).finish(&raw, &out, &report, &opts);
    assert!(got.index == want.index);
    // other options than the sketch's: drawn again, the same as render
    let small = Options {
        width: 320,
        ..Options::default()
    };
    let got = Sketch::from_loops(&raw, &loops, &opts).finish(&raw, &out, &report, &small);
    assert!(got.index == render(&out, &report, &small).index);
}

#[test]
fn what_the_sketch_drew_is_kept_only_where_the_surface_is_the_inputs() {
    // a mark in the text's ink, which the overview and the tiles never draw: the
    // marks are the text's pixels beyond render's
    const MARK: Ink = TEXT;
    let raw = holed_sphere(0.5, Some(0.35));
    let marked = |loops: &[Vec<u32>]| {
        let mut s = Sketch::from_loops(&raw, loops, &Options::default());
        let (_, over) = s.overview.as_mut().unwrap();
        over.rect(1, 1, 3, 3, MARK);
        for t in &mut s.tiles {
            t.before.rect(1, 1, 3, 3, MARK);
        }
        s
    };
    let opts = Options::default();
    let text = |p: &Picture| p.index.iter().filter(|&&c| c == MARK).count();
    let marks = |p: &Picture, out: &RawMesh, report: &RepairReport| {
        text(p) - text(&render(out, report, &opts))
    };

    // kept: the overview's and both close-ups' marks (before and after tiles)
    let (out, report, loops) = repair_seen(&raw, &Policy::default_policy());
    let pic = marked(&loops).finish(&raw, &out, &report, &opts);
    assert_eq!(marks(&pic, &out, &report), 9 * (1 + 2 * 2));

    // a loop the repair did not report: its close-up is drawn again; the other
    // close-up and the overview (which looks at the input's loops) are kept
    let mut other = loops.clone();
    other[0].pop();
    let pic = marked(&other).finish(&raw, &out, &report, &opts);
    assert_eq!(marks(&pic, &out, &report), 9 * (1 + 2));

    // the repair gave a vertex of the input's surface a new number without moving it
    // (as splitting a non-manifold vertex does): what the sketch drew is kept
    let mut renumbered = out.clone();
    let v = renumbered.faces[0][0];
    renumbered.positions.push(renumbered.positions[v as usize]);
    renumbered.faces[0][0] = (renumbered.positions.len() - 1) as u32;
    let pic = marked(&loops).finish(&raw, &renumbered, &report, &opts);
    assert_eq!(marks(&pic, &renumbered, &report), 9 * (1 + 2 * 2));
    // moved, even by a bit: nothing is kept
    let mut moved = out.clone();
    moved.positions[v as usize].x = f64::from_bits(moved.positions[v as usize].x.to_bits() ^ 1);
    let pic = marked(&loops).finish(&raw, &moved, &report, &opts);
    assert_eq!(marks(&pic, &moved, &report), 0);

    // smoothing moves the input's vertices: nothing kept, the picture is render's
    let policy = Policy::from_toml_str(
        "[smooth]\nenabled = true\niterations = 2\n",
        Path::new("test.toml"),
    )
    .unwrap();
    let (out, report, loops) = repair_seen(&raw, &policy);
    let pic = marked(&loops).finish(&raw, &out, &report, &opts);
    assert_eq!(marks(&pic, &out, &report), 0);
    assert!(pic.index == render(&out, &report, &opts).index);
}
