//! Wavefront OBJ: `v` (with optional `w` or `r g b` vertex colours) and `f` records.
//!
//! A hand parser rather than `tobj`: `tobj` renumbers vertices in order of first use
//! (both with and without `single_index`), splits the file into models at every
//! `o`/`g`/`usemtl`, drops unreferenced vertices, turns a three-index `l` record into
//! a triangle, reports no line numbers, and allocates a `String` per line. The
//! project's rule "never renumber an input vertex" and the error requirements rule
//! it out. This parser reads the same subset (`v`, `f`, relative indices,
//! `v x y z r g b`, `v x y z w`) in the file's vertex order, ignores `vt`, `vn`, `o`,
//! `g`, `s`, `usemtl`, `mtllib`, `l`, `p` and unknown records, and fans polygons.

use super::text::{has_nul, parse_coord, parse_f64, parse_i64, show, strip_comment, tokens};
use super::text::{Lines, Next, MAX_LINE};
use super::{io_error, malformed, unit_color, Caps, IoError, Precision, RawMesh, MAX_ELEMENTS};
use glam::DVec3;
use std::io::{BufRead, Write};
use std::path::Path;

/// Reads an OBJ file.
pub(crate) fn read<R: BufRead>(path: &Path, reader: R, caps: &Caps) -> Result<RawMesh, IoError> {
    let mut lines = Lines::new(reader);
    let mut raw = RawMesh {
        precision: Precision::F64,
        ..RawMesh::default()
    };
    let mut colors: Vec<[f32; 3]> = Vec::new();
    let mut uncolored = 0usize;
    let mut polygons = 0u64;
    let mut w_scaled = 0u64;
    let mut skipped_lp = 0u64;
    // Largest positive index seen that referred past the vertices read so far
    // (forward references are resolved at the end), with its line.
    let mut forward: Option<(u64, usize)> = None;

    loop {
        let (ln, line) = match lines.next_line(MAX_LINE).map_err(|e| io_error(path, e))? {
            Next::Line(ln, l) => (ln, l),
            Next::Eof => break,
            Next::Bad(ln, why) => return Err(malformed(path, Some(ln), why)),
        };
        let bad = |msg: String| malformed(path, Some(ln), msg);
        if has_nul(line) {
            return Err(bad("binary data (NUL byte) in a text OBJ file".into()));
        }
        let mut toks = tokens(strip_comment(line));
        match toks.next() {
            Some(b"v") => {
                if raw.positions.len() as u64 >= caps.vertices() {
                    return Err(bad(caps.vertex_msg(None)));
                }
                let mut vals = [0.0f64; 6];
                let mut n = 0usize;
                for t in toks {
                    let slot = vals.get_mut(n).ok_or_else(|| {
                        bad("too many numbers on a 'v' line (expected 3, 4 or 6)".into())
                    })?;
                    *slot = if n < 3 {
                        parse_coord(t).map_err(&bad)?
                    } else {
                        parse_f64(t)
                            .filter(|v| v.is_finite())
                            .ok_or_else(|| bad(format!("'{}' is not a finite number", show(t))))?
                    };
                    n += 1;
                }
                let [x, y, z, a, b, c] = vals;
                let mut p = DVec3::new(x, y, z);
                match n {
                    3 => uncolored += 1,
                    4 => {
                        // Homogeneous coordinate w.
                        if a == 0.0 {
                            return Err(bad("vertex with w = 0".into()));
                        }
                        if a != 1.0 {
                            p /= a;
                            w_scaled += 1;
                            if !p.is_finite() {
                                return Err(bad("vertex overflows when divided by w".into()));
                            }
                        }
                        uncolored += 1;
                    }
                    6 => {
                        if colors.len() < raw.positions.len() {
                            // Earlier vertices had no colour: colours are dropped below.
                            colors.resize(raw.positions.len(), [0.0; 3]);
                        }
                        colors.push([a as f32, b as f32, c as f32]);
                    }
                    _ => {
                        return Err(bad(format!(
                            "a 'v' line needs 3, 4 or 6 numbers, found {n}"
                        )))
                    }
                }
                raw.positions.push(p);
            }
            Some(b"f") | Some(b"fo") => {
                let nv = raw.positions.len() as i64;
                let mut first = 0u32;
                let mut prev = 0u32;
                let mut count = 0usize;
                for t in toks {
                    let vtok = t.split(|&b| b == b'/').next().unwrap_or(t);
                    let k = parse_i64(vtok)
                        .ok_or_else(|| bad(format!("'{}' is not a vertex index", show(t))))?;
                    let i = match k {
                        0 => return Err(bad("vertex index 0 (OBJ indices start at 1)".into())),
                        k if k > 0 => k - 1,
                        k => {
                            let i = nv + k;
                            if i < 0 {
                                return Err(bad(format!(
                                    "relative vertex index {k} refers before the first vertex ({nv} vertices so far)"
                                )));
                            }
                            i
                        }
                    };
                    if i as u64 >= MAX_ELEMENTS {
                        return Err(bad(format!("vertex index {k} out of range")));
                    }
                    if i >= nv && forward.map_or(true, |(m, _)| (i as u64) > m) {
                        forward = Some((i as u64, ln));
                    }
                    let i = i as u32;
                    count += 1;
                    match count {
                        1 => first = i,
                        2 => prev = i,
                        _ => {
                            if raw.faces.len() as u64 >= caps.faces() {
                                return Err(bad(caps.face_msg(None)));
                            }
                            raw.faces.push([first, prev, i]);
                            prev = i;
                        }
                    }
                }
                if count < 3 {
                    return Err(bad(format!(
                        "a face needs at least 3 vertices, found {count}"
                    )));
                }
                if count > 3 {
                    polygons += 1;
                }
            }
            Some(b"l") | Some(b"p") => skipped_lp += 1,
            // vt, vn, vp, o, g, s, usemtl, mtllib, comments and unknown records.
            _ => {}
        }
    }

    let n = raw.positions.len() as u64;
    if let Some((i, ln)) = forward {
        if i >= n {
            return Err(malformed(
                path,
                Some(ln),
                format!(
                    "vertex index {} out of range (the file has {n} vertices)",
                    i + 1
                ),
            ));
        }
    }
    if !colors.is_empty() {
        if uncolored == 0 && colors.len() == raw.positions.len() {
            if colors.iter().flatten().any(|&c| c > 1.0) {
                for c in colors.iter_mut().flatten() {
                    *c /= 255.0;
                }
                raw.notes
                    .push("OBJ vertex colours above 1 read as 0..255 and divided by 255".into());
            }
            for c in colors.iter_mut().flatten() {
                *c = unit_color(f64::from(*c));
            }
            raw.colors = Some(colors);
        } else {
            raw.notes.push(format!(
                "OBJ vertex colours dropped: {uncolored} of {} vertices have none",
                raw.positions.len()
            ));
        }
    }
    if polygons > 0 {
        raw.notes.push(format!(
            "fanned {polygons} OBJ polygons with more than 3 vertices into triangles"
        ));
    }
    if w_scaled > 0 {
        raw.notes.push(format!(
            "divided {w_scaled} OBJ vertices by their w coordinate"
        ));
    }
    if skipped_lp > 0 {
        raw.notes.push(format!(
            "ignored {skipped_lp} OBJ line/point ('l'/'p') records"
        ));
    }
    Ok(raw)
}

/// Writes an OBJ file: `v x y z [r g b]` and `f a b c` (1-based).
pub(crate) fn write<W: Write>(w: &mut W, raw: &RawMesh) -> std::io::Result<()> {
    let f32 = raw.precision == Precision::F32;
    writeln!(
        w,
        "# written by holefill\n# {} vertices, {} triangles",
        raw.positions.len(),
        raw.faces.len()
    )?;
    let colors = raw.colors.as_deref();
    for (i, p) in raw.positions.iter().enumerate() {
        w.write_all(b"v ")?;
        super::write_real(w, p.x, f32)?;
        w.write_all(b" ")?;
        super::write_real(w, p.y, f32)?;
        w.write_all(b" ")?;
        super::write_real(w, p.z, f32)?;
        if let Some(c) = colors.and_then(|c| c.get(i)) {
            write!(w, " {} {} {}", c[0], c[1], c[2])?;
        }
        w.write_all(b"\n")?;
    }
    for f in &raw.faces {
        writeln!(
            w,
            "f {} {} {}",
            u64::from(f[0]) + 1,
            u64::from(f[1]) + 1,
            u64::from(f[2]) + 1
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<RawMesh, IoError> {
        read(Path::new("t.obj"), s.as_bytes(), &Caps::none())
    }

    #[test]
    fn relative_indices_and_fanning() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n").unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(m.notes.iter().any(|n| n.contains("fanned 1")));
    }

    #[test]
    fn slashes_comments_and_ignored_records() {
        let m = parse(
            "# c\nmtllib a.mtl\no x\nv 0 0 0 # inline\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
             usemtl m\ns off\nf 1/1/1 2//1 3/1\nl 1 2 3\n",
        )
        .unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2]]);
        assert!(m.colors.is_none());
    }

    #[test]
    fn vertex_colours_and_order_kept() {
        let m = parse("v 5 0 0 1 0 0\nv 0 0 0 0 1 0\nv 0 1 0 0 0 1\nf 3 1 2\n").unwrap();
        assert_eq!(m.positions[0], DVec3::new(5.0, 0.0, 0.0));
        assert_eq!(m.faces, vec![[2, 0, 1]]);
        assert_eq!(m.colors.unwrap()[1], [0.0, 1.0, 0.0]);
    }

    #[test]
    fn forward_reference_is_allowed_but_range_checked() {
        assert!(parse("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n").is_ok());
        let e = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").unwrap_err();
        assert!(e.to_string().contains("t.obj:4"), "{e}");
    }

    #[test]
    fn errors_name_file_and_line() {
        for (src, line) in [
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", 4),
            ("v 0 0 0\nv 1 0 0\nf 1 2\n", 3),
            ("v 0 0 nan\n", 1),
            ("v 0 inf 0\n", 1),
            ("v 0 0\n", 1),
            ("v 0 0 0\nf -2 -1 1\n", 2),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", 4),
            ("v 0 0 0\x00\n", 1),
        ] {
            let e = parse(src).unwrap_err();
            assert!(e.is_malformed());
            assert!(
                e.to_string().starts_with(&format!("t.obj:{line}:")),
                "{src:?}: {e}"
            );
        }
    }

    #[test]
    fn repeated_index_is_not_an_error() {
        assert!(parse("v 0 0 0\nv 1 0 0\nf 1 2 2\n").is_ok());
    }
}
