//! Geomview OFF (with the `C`, `N` and `ST` prefixes: `COFF`, `NOFF`, `CNOFF`,
//! `STCOFF`, ...). ASCII only.
//!
//! Layout: the keyword line (the counts may follow on it), `nv nf ne`, then one
//! vertex per line `x y z [nx ny nz] [r g b [a]] [s t]`, then one face per line
//! `n i0 .. i(n-1) [colour]`. `#` starts a comment. Colours are integers 0..255
//! (divided by 255) or reals in `[0, 1]` (kept); a line's colour is read as
//! integers when all its components are integers. Polygons are fanned.
//!
//! Face colours (`r g b [a]`, or one integer: a colour map index) become the face
//! properties `red green blue [alpha]` (`uchar` when every face gives integers
//! 0..255, `double` when every face gives reals; a file mixing the two per line is
//! kept as reals 0..1, with a note) or `color_index`, one value per triangle (a
//! fanned polygon's triangles share its colour), written back after the indices.
//! Face colours that cannot all be read the same way (some faces without, 2 or more
//! than 4 values, a value that is not a number) are dropped with a note naming the
//! line. Real colours are written with a decimal point, so that they read back as
//! reals.

use super::text::{has_nul, parse_coord, parse_f64, parse_i64, show, strip_comment, tokens};
use super::text::{Lines, Next, MAX_LINE};
use super::{color_byte, io_error, malformed, unit_color, Caps, IoError, Precision, RawMesh};
use glam::DVec3;
use std::io::{BufRead, Write};
use std::path::Path;

/// The next line that is not blank after removing comments.
fn content_line<'a, R: BufRead>(
    path: &Path,
    lines: &'a mut Lines<R>,
) -> Result<Option<(usize, &'a [u8])>, IoError> {
    loop {
        // Re-borrow per iteration: the returned slice must come from the last call.
        let skip = match lines.next_line(MAX_LINE).map_err(|e| io_error(path, e))? {
            Next::Eof => return Ok(None),
            Next::Bad(ln, why) => return Err(malformed(path, Some(ln), why)),
            Next::Line(ln, l) => {
                if has_nul(l) {
                    return Err(malformed(
                        path,
                        Some(ln),
                        "binary data (NUL byte) in an OFF file (binary OFF is not supported)",
                    ));
                }
                tokens(strip_comment(l)).next().is_none()
            }
        };
        if !skip {
            break;
        }
    }
    // The line just read is in the buffer; hand it out.
    Ok(lines.current().map(|(ln, l)| (ln, strip_comment(l))))
}

/// Parses count tokens (the first two are the vertex and face counts).
fn take_counts<'t>(
    path: &Path,
    toks: impl Iterator<Item = &'t [u8]>,
    ln: usize,
    counts: &mut [u64; 2],
    found: &mut usize,
) -> Result<(), IoError> {
    for t in toks {
        if t.eq_ignore_ascii_case(b"BINARY") {
            return Err(malformed(path, Some(ln), "binary OFF is not supported"));
        }
        if *found < 2 {
            let v = parse_i64(t)
                .and_then(|v| u64::try_from(v).ok())
                .ok_or_else(|| malformed(path, Some(ln), format!("bad OFF count '{}'", show(t))))?;
            if let Some(slot) = counts.get_mut(*found) {
                *slot = v;
            }
            *found += 1;
        }
    }
    Ok(())
}

/// Reads an OFF file of `len` bytes.
pub(crate) fn read<R: BufRead>(
    path: &Path,
    reader: R,
    len: u64,
    caps: &Caps,
) -> Result<RawMesh, IoError> {
    let mut lines = Lines::new(reader);
    let Some((ln, first)) = content_line(path, &mut lines)? else {
        return Err(malformed(path, None, "empty OFF file"));
    };
    let mut toks = tokens(first);
    let kw = toks.next().unwrap_or(b"");
    let Some(kind) = kw.strip_suffix(b"OFF") else {
        return Err(malformed(
            path,
            Some(ln),
            format!("not an OFF file: it starts with '{}', not 'OFF'", show(kw)),
        ));
    };
    let mut rest = kind;
    let st = if let Some(r) = rest.strip_prefix(b"ST") {
        rest = r;
        true
    } else {
        false
    };
    let color = if let Some(r) = rest.strip_prefix(b"C") {
        rest = r;
        true
    } else {
        false
    };
    let normals = if let Some(r) = rest.strip_prefix(b"N") {
        rest = r;
        true
    } else {
        false
    };
    if !rest.is_empty() {
        return Err(malformed(
            path,
            Some(ln),
            format!("unsupported OFF variant '{}'", show(kw)),
        ));
    }
    // Counts: on the keyword line or the next content line.
    let mut counts = [0u64; 2];
    let mut found = 0;
    let mut counts_line = ln;
    take_counts(path, toks, ln, &mut counts, &mut found)?;
    if found == 0 {
        let Some((ln2, l)) = content_line(path, &mut lines)? else {
            return Err(malformed(path, None, "truncated file: no OFF counts line"));
        };
        counts_line = ln2;
        take_counts(path, tokens(l), ln2, &mut counts, &mut found)?;
    }
    if found < 2 {
        return Err(malformed(
            path,
            Some(counts_line),
            "the OFF counts line needs the vertex and face counts",
        ));
    }
    let [nv, nf] = counts;
    let remaining = len.saturating_sub(lines.consumed());
    let bad_counts = |m: String| malformed(path, Some(counts_line), m);
    if nv > caps.vertices() {
        return Err(bad_counts(caps.vertex_msg(Some(nv))));
    }
    if nf > caps.faces() {
        return Err(bad_counts(caps.face_msg(Some(nf))));
    }
    // Shortest vertex line "0 0 0\n", shortest face line "3 0 0 0\n" (the last
    // line may lack its newline).
    let need = (u128::from(nv) * 6 + u128::from(nf) * 8).saturating_sub(1);
    if need > u128::from(remaining) {
        return Err(bad_counts(format!(
            "the header claims {nv} vertices and {nf} faces, but only {remaining} bytes follow"
        )));
    }

    let mut raw = RawMesh {
        precision: Precision::F64,
        ..RawMesh::default()
    };
    raw.positions.reserve(nv as usize);
    let mut colors: Vec<[f32; 3]> = Vec::new();
    if color {
        colors.reserve(nv as usize);
    }
    let mut missing_color = 0u64;
    // normals, colours (with their kind: integers or reals, 3 or 4) and texture
    // coordinates kept as vertex properties, values as written
    let mut nrm: [Vec<f64>; 3] = Default::default();
    let mut col: [Vec<f64>; 4] = Default::default();
    let mut col_kind: Option<(bool, usize)> = None;
    let mut col_mixed = false;
    let mut stv: [Vec<f64>; 2] = Default::default();
    for i in 0..nv {
        let Some((ln, l)) = content_line(path, &mut lines)? else {
            return Err(malformed(
                path,
                None,
                format!("truncated file: it ends after {i} of {nv} vertices"),
            ));
        };
        let bad = |m: String| malformed(path, Some(ln), m);
        let mut t = tokens(l);
        let mut p = [0.0f64; 3];
        for c in p.iter_mut() {
            let tok = t
                .next()
                .ok_or_else(|| bad("a vertex needs 3 coordinates".into()))?;
            *c = parse_coord(tok).map_err(&bad)?;
        }
        raw.positions.push(DVec3::from_array(p));
        if normals {
            for n in nrm.iter_mut() {
                let tok = t
                    .next()
                    .ok_or_else(|| bad("missing vertex normal".into()))?;
                n.push(
                    parse_f64(tok)
                        .ok_or_else(|| bad(format!("bad normal value '{}'", show(tok))))?,
                );
            }
        }
        if st && !color {
            // x y z [n] s t
            for v in stv.iter_mut() {
                let tok = t
                    .next()
                    .ok_or_else(|| bad("missing texture coordinate".into()))?;
                v.push(
                    parse_f64(tok)
                        .ok_or_else(|| bad(format!("bad texture coordinate '{}'", show(tok))))?,
                );
            }
        }
        if color {
            // Up to 4 colour components and 2 texture coordinates (no allocation).
            let mut rest: [&[u8]; 6] = [b""; 6];
            let mut k = 0;
            for tok in t {
                if let Some(slot) = rest.get_mut(k) {
                    *slot = tok;
                    k += 1;
                }
            }
            let n = k.saturating_sub(if st { 2 } else { 0 });
            let comps = rest.get(..n.min(4)).unwrap_or(&[]);
            if st {
                for (v, tok) in stv.iter_mut().zip(rest.get(n..k).unwrap_or(&[])) {
                    v.push(
                        parse_f64(tok).ok_or_else(|| {
                            bad(format!("bad texture coordinate '{}'", show(tok)))
                        })?,
                    );
                }
            }
            if comps.len() < 3 {
                missing_color += 1;
                colors.push([1.0; 3]);
                continue;
            }
            let ints = comps.iter().all(|c| parse_i64(c).is_some());
            match col_kind {
                None => col_kind = Some((ints, comps.len())),
                Some(kind) if kind != (ints, comps.len()) => col_mixed = true,
                Some(_) => {}
            }
            for (slot, tok) in col.iter_mut().zip(comps) {
                slot.push(parse_f64(tok).unwrap_or(0.0));
            }
            let mut c = [0.0f32; 3];
            for (slot, tok) in c.iter_mut().zip(comps) {
                let v = parse_f64(tok)
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| bad(format!("bad colour value '{}'", show(tok))))?;
                *slot = unit_color(if ints { v / 255.0 } else { v });
            }
            colors.push(c);
        }
    }
    raw.faces.reserve(nf as usize);
    let mut polygons = 0u64;
    let mut face_colors = FaceColors::default();
    for i in 0..nf {
        let Some((ln, l)) = content_line(path, &mut lines)? else {
            return Err(malformed(
                path,
                None,
                format!("truncated file: it ends after {i} of {nf} faces"),
            ));
        };
        let bad = |m: String| malformed(path, Some(ln), m);
        let mut t = tokens(l);
        let n_tok = t.next().unwrap_or(b"");
        let n = parse_i64(n_tok)
            .ok_or_else(|| bad(format!("'{}' is not a face vertex count", show(n_tok))))?;
        if n < 3 {
            return Err(bad(format!("a face needs at least 3 vertices, found {n}")));
        }
        if n > 3 {
            polygons += 1;
        }
        let (mut first, mut prev) = (0u32, 0u32);
        let tris_before = raw.faces.len();
        for j in 0..n {
            let tok = t
                .next()
                .ok_or_else(|| bad(format!("the face lists fewer than {n} vertices")))?;
            let v = parse_i64(tok)
                .ok_or_else(|| bad(format!("'{}' is not a vertex index", show(tok))))?;
            let v = u32::try_from(v)
                .ok()
                .filter(|&v| u64::from(v) < nv)
                .ok_or_else(|| bad(format!("vertex index {v} out of range ({nv} vertices)")))?;
            match j {
                0 => first = v,
                1 => prev = v,
                _ => {
                    if raw.faces.len() as u64 >= caps.faces() {
                        return Err(bad(caps.face_msg(None)));
                    }
                    raw.faces.push([first, prev, v]);
                    prev = v;
                }
            }
        }
        face_colors.line(ln, t, raw.faces.len() - tris_before);
    }
    face_colors.finish(&mut raw);
    use super::attrs::{PropData, Property, ScalarType, Values};
    let prop = |name: &str, vals: Vec<f64>, ty: ScalarType| {
        let mut v = Values::new(ty, vals.len());
        for x in vals {
            v.push_f64(x);
        }
        Property {
            name: name.into(),
            data: PropData::Scalar(v),
        }
    };
    if normals {
        for (name, v) in ["nx", "ny", "nz"].into_iter().zip(nrm) {
            raw.attrs.vertex.push(prop(name, v, ScalarType::F64));
        }
    }
    if let (Some((ints, n)), false, 0) = (col_kind, col_mixed, missing_color) {
        let ty = if ints {
            ScalarType::U8
        } else {
            ScalarType::F64
        };
        let in_range = !ints || col.iter().flatten().all(|&c| (0.0..=255.0).contains(&c));
        if in_range {
            for (name, v) in ["red", "green", "blue", "alpha"]
                .into_iter()
                .zip(col)
                .take(n)
            {
                raw.attrs.vertex.push(prop(name, v, ty));
            }
        }
    }
    if st && stv[0].len() as u64 == nv && stv[1].len() as u64 == nv {
        for (name, v) in ["s", "t"].into_iter().zip(stv) {
            raw.attrs.vertex.push(prop(name, v, ScalarType::F64));
        }
    }
    if color {
        if missing_color == 0 {
            raw.colors = Some(colors);
        } else {
            raw.notes.push(format!(
                "COFF vertex colours dropped: {missing_color} vertices have none"
            ));
        }
    }
    if polygons > 0 {
        raw.notes.push(format!(
            "fanned {polygons} OFF polygons with more than 3 vertices into triangles"
        ));
    }
    Ok(raw)
}

/// Writes `[ST][C][N]OFF`: vertex normals when the mesh has `nx ny nz`, colours
/// from the colour properties as they were read (integers or reals, with alpha when
/// read with it) or else 0..255 with alpha 255, texture coordinates when it has
/// `s t`.
pub(crate) fn write<W: Write>(w: &mut W, raw: &RawMesh) -> std::io::Result<()> {
    use super::attrs::{PropData, Property, Values};
    let f32 = raw.precision == Precision::F32;
    fn property<'a>(raw: &'a RawMesh, name: &str) -> Option<&'a Values> {
        raw.attrs
            .vertex
            .iter()
            .find_map(|p: &Property| match &p.data {
                PropData::Scalar(v) if p.name == name => Some(v),
                _ => None,
            })
    }
    let find = |name: &str| property(raw, name);
    let normals = match (find("nx"), find("ny"), find("nz")) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    let color_props: Vec<&Values> = match (find("red"), find("green"), find("blue")) {
        (Some(r), Some(g), Some(b)) => [Some(r), Some(g), Some(b), find("alpha")]
            .into_iter()
            .flatten()
            .collect(),
        _ => Vec::new(),
    };
    let colors = raw.colors.as_deref().filter(|_| color_props.is_empty());
    let st = match (find("s"), find("t")) {
        (Some(a), Some(b)) => Some([a, b]),
        _ => None,
    };
    let has_color = colors.is_some() || !color_props.is_empty();
    writeln!(
        w,
        "{}{}{}OFF\n{} {} 0",
        if st.is_some() { "ST" } else { "" },
        if has_color { "C" } else { "" },
        if normals.is_some() { "N" } else { "" },
        raw.positions.len(),
        raw.faces.len()
    )?;
    let ffind = |name: &str| {
        raw.attrs
            .face
            .iter()
            .find_map(|p: &Property| match &p.data {
                PropData::Scalar(v) if p.name == name && v.len() == raw.faces.len() => Some(v),
                _ => None,
            })
    };
    let face_colors: Vec<&Values> = match (ffind("red"), ffind("green"), ffind("blue")) {
        (Some(r), Some(g), Some(b)) => [Some(r), Some(g), Some(b), ffind("alpha")]
            .into_iter()
            .flatten()
            .collect(),
        _ => ffind("color_index").into_iter().collect(),
    };
    let val = |w: &mut W, v: &Values, i: usize| -> std::io::Result<()> {
        let x = v.get(i).unwrap_or(0.0);
        w.write_all(b" ")?;
        if v.ty().is_int() {
            write!(w, "{}", x as i64)
        } else {
            super::write_real(w, x, v.ty() == super::attrs::ScalarType::F32)
        }
    };
    for (i, p) in raw.positions.iter().enumerate() {
        super::write_real(w, p.x, f32)?;
        w.write_all(b" ")?;
        super::write_real(w, p.y, f32)?;
        w.write_all(b" ")?;
        super::write_real(w, p.z, f32)?;
        for v in normals.iter().flatten() {
            val(w, v, i)?;
        }
        for v in &color_props {
            colour_val(w, v, i)?;
        }
        if let Some(c) = colors.and_then(|c| c.get(i)) {
            write!(
                w,
                " {} {} {} 255",
                color_byte(c[0]),
                color_byte(c[1]),
                color_byte(c[2])
            )?;
        }
        for v in st.iter().flatten() {
            val(w, v, i)?;
        }
        w.write_all(b"\n")?;
    }
    for (j, f) in raw.faces.iter().enumerate() {
        write!(w, "3 {} {} {}", f[0], f[1], f[2])?;
        for v in &face_colors {
            colour_val(w, v, j)?;
        }
        w.write_all(b"\n")?;
    }
    Ok(())
}

/// A colour component: an integer as an integer, a real always with a decimal
/// point or an exponent (a real written `1` would read back as the integer 1 of
/// 0..255).
fn colour_val<W: Write>(w: &mut W, v: &super::attrs::Values, i: usize) -> std::io::Result<()> {
    let x = v.get(i).unwrap_or(0.0);
    w.write_all(b" ")?;
    if v.ty().is_int() {
        return write!(w, "{}", x as i64);
    }
    let mut text = Vec::with_capacity(24);
    super::write_real(&mut text, x, v.ty() == super::attrs::ScalarType::F32)?;
    if !text
        .iter()
        .any(|b| matches!(b, b'.' | b'e' | b'E' | b'N' | b'i'))
    {
        text.extend_from_slice(b".0");
    }
    w.write_all(&text)
}

/// Face colours as read, per triangle, and whether they can be kept.
#[derive(Default)]
struct FaceColors {
    /// Per triangle of a face with a colour, its values as written.
    vals: [Vec<f64>; 4],
    /// Per triangle, whether its line gave integers.
    ints: Vec<bool>,
    /// (integers, number of values) of the first face with a colour.
    kind: Option<(bool, usize)>,
    /// Some lines integers, others reals (same number of values).
    mixed: bool,
    /// The first line whose colour cannot be kept with the others, and why.
    bad: Option<(usize, String)>,
    /// Face lines with and without a colour.
    with: u64,
    without: u64,
}

impl FaceColors {
    /// The tokens after a face's indices on line `ln`, for its `tris` triangles.
    fn line<'t>(&mut self, ln: usize, toks: impl Iterator<Item = &'t [u8]>, tris: usize) {
        let mut rest: [&[u8]; 5] = [b""; 5];
        let mut k = 0usize;
        for tok in toks {
            if let Some(slot) = rest.get_mut(k) {
                *slot = tok;
            }
            k += 1;
        }
        if k == 0 {
            self.without += 1;
            return;
        }
        self.with += 1;
        if self.bad.is_some() {
            return;
        }
        match self.take(rest.get(..k).unwrap_or(&[]), k, tris) {
            Ok(()) => {}
            Err(why) => self.bad = Some((ln, why)),
        }
    }

    /// One face's `k` colour values `comps`, for its `tris` triangles.
    fn take(&mut self, comps: &[&[u8]], k: usize, tris: usize) -> Result<(), String> {
        if k == 2 || k > 4 {
            return Err(format!(
                "{k} values after the indices (a colour is 1, 3 or 4)"
            ));
        }
        let ints = comps
            .iter()
            .all(|c| parse_i64(c).is_some_and(|v| i32::try_from(v).is_ok()));
        let mut v = [0.0f64; 4];
        for (slot, tok) in v.iter_mut().zip(comps) {
            *slot = parse_f64(tok)
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("'{}' is not a colour value", show(tok)))?;
        }
        if k == 1 && !ints {
            return Err("a single value after the indices that is not a colour map index".into());
        }
        match self.kind {
            None => self.kind = Some((ints, k)),
            Some((_, n)) if n != k => {
                return Err(format!("{k} colour values, earlier faces have {n}"))
            }
            Some((i, _)) if i != ints => self.mixed = true,
            Some(_) => {}
        }
        for _ in 0..tris {
            for (col, x) in self.vals.iter_mut().zip(v).take(k) {
                col.push(x);
            }
            self.ints.push(ints);
        }
        Ok(())
    }

    /// The face properties (or a note saying why there are none).
    fn finish(self, raw: &mut RawMesh) {
        use super::attrs::{PropData, Property, ScalarType, Values};
        if self.with == 0 {
            return;
        }
        if let Some((ln, why)) = self.bad {
            raw.notes
                .push(format!("OFF face colours dropped: line {ln}: {why}"));
            return;
        }
        if self.without > 0 {
            raw.notes.push(format!(
                "OFF face colours dropped: {} of {} faces have none",
                self.without,
                self.with + self.without
            ));
            return;
        }
        let Some((ints, n)) = self.kind else {
            return;
        };
        let ty = if n == 1 {
            ScalarType::I32
        } else if self.mixed || !ints {
            ScalarType::F64
        } else if self.vals[..n]
            .iter()
            .flatten()
            .all(|x| (0.0..=255.0).contains(x))
        {
            ScalarType::U8
        } else {
            ScalarType::I32
        };
        if self.mixed {
            raw.notes.push(
                "OFF face colours given as integers on some faces and reals on others: kept as reals 0..1".into(),
            );
        }
        let names: &[&str] = if n == 1 {
            &["color_index"]
        } else {
            &["red", "green", "blue", "alpha"]
        };
        for (name, col) in names.iter().zip(self.vals).take(n) {
            let mut v = Values::new(ty, col.len());
            for (x, &int) in col.into_iter().zip(&self.ints) {
                v.push_f64(if self.mixed && int { x / 255.0 } else { x });
            }
            raw.attrs.face.push(Property {
                name: (*name).into(),
                data: PropData::Scalar(v),
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::attrs::{PropData, Values};

    fn parse(s: &str) -> RawMesh {
        read(
            Path::new("t.off"),
            s.as_bytes(),
            s.len() as u64,
            &Caps::none(),
        )
        .unwrap()
    }

    fn written(raw: &RawMesh) -> String {
        let mut out = Vec::new();
        write(&mut out, raw).unwrap();
        String::from_utf8(out).unwrap()
    }

    fn face<'a>(raw: &'a RawMesh, name: &str) -> &'a Values {
        match raw
            .attrs
            .face
            .iter()
            .find(|p| p.name == name)
            .map(|p| &p.data)
        {
            Some(PropData::Scalar(v)) => v,
            _ => panic!("no face property {name}: {:?}", raw.attrs.face),
        }
    }

    const SQUARE: &str = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n";

    #[test]
    fn face_colours_are_read_per_triangle_and_written_back() {
        // integers with alpha; the quad's two triangles share its colour
        let m = parse(&format!(
            "OFF\n4 2 0\n{SQUARE}3 0 1 2 255 0 0 128\n4 0 1 2 3 1 2 3 4\n"
        ));
        assert_eq!(m.faces.len(), 3);
        assert_eq!(face(&m, "red"), &Values::U8(vec![255, 1, 1]));
        assert_eq!(face(&m, "alpha"), &Values::U8(vec![128, 4, 4]));
        let text = written(&m);
        assert!(text.contains("3 0 1 2 255 0 0 128\n"), "{text}");
        assert!(text.contains("3 0 2 3 1 2 3 4\n"), "{text}");
        let back = parse(&text);
        assert_eq!(back.attrs, m.attrs);
        // reals keep a decimal point (else they would read back as 0..255)
        let m = parse(&format!(
            "OFF\n4 2 0\n{SQUARE}3 0 1 2 1.0 0.5 0\n3 0 2 3 0.25 1 1\n"
        ));
        assert!(matches!(face(&m, "green"), Values::F64(_)));
        let text = written(&m);
        assert!(text.contains("3 0 1 2 1.0 0.5 0.0\n"), "{text}");
        assert!(text.contains("3 0 2 3 0.25 1.0 1.0\n"), "{text}");
        assert_eq!(parse(&text).attrs, m.attrs);
        // a colour map index
        let m = parse(&format!("OFF\n4 2 0\n{SQUARE}3 0 1 2 7\n3 0 2 3 9\n"));
        assert_eq!(face(&m, "color_index"), &Values::I32(vec![7, 9]));
        assert!(written(&m).contains("3 0 2 3 9\n"));
        // no face colours: none written
        let m = parse(&format!("OFF\n4 2 0\n{SQUARE}3 0 1 2\n3 0 2 3\n"));
        assert!(m.attrs.face.is_empty() && m.notes.is_empty());
        assert!(written(&m).ends_with("3 0 2 3\n"));
    }

    #[test]
    fn face_colours_that_cannot_be_kept_alike_are_dropped_with_a_note() {
        let cases = [
            ("3 0 1 2 255 0 0\n3 0 2 3\n", "1 of 2 faces have none"),
            ("3 0 1 2 255 0\n3 0 2 3 1 2\n", "line 7: 2 values"),
            (
                "3 0 1 2 255 0 0\n3 0 2 3 1 2 3 4\n",
                "line 8: 4 colour values, earlier faces have 3",
            ),
            (
                "3 0 1 2 1 x 0\n3 0 2 3 1 2 3\n",
                "line 7: 'x' is not a colour value",
            ),
        ];
        for (faces, why) in cases {
            let m = parse(&format!("OFF\n4 2 0\n{SQUARE}{faces}"));
            assert!(m.attrs.face.is_empty(), "{faces}");
            assert!(
                m.notes
                    .iter()
                    .any(|n| n.starts_with("OFF face colours dropped") && n.contains(why)),
                "{faces}: {:?}",
                m.notes
            );
            assert!(written(&m).ends_with("3 0 2 3\n"));
        }
        // integers on one face, reals on another: reals 0..1, said so
        let m = parse(&format!(
            "OFF\n4 2 0\n{SQUARE}3 0 1 2 255 0 51\n3 0 2 3 0.5 1 0\n"
        ));
        assert_eq!(face(&m, "blue"), &Values::F64(vec![0.2, 0.0]));
        assert_eq!(face(&m, "red"), &Values::F64(vec![1.0, 0.5]));
        assert!(m.notes.iter().any(|n| n.contains("kept as reals 0..1")));
    }

    #[test]
    fn real_vertex_colours_read_back_as_reals() {
        let m =
            parse("COFF\n3 1 0\n0 0 0 1.0 0.0 0.0\n1 0 0 0 1.0 0\n0 1 0 0.5 0.5 0.5\n3 0 1 2\n");
        let text = written(&m);
        assert!(text.contains("0 0 0 1.0 0.0 0.0\n"), "{text}");
        let back = parse(&text);
        assert_eq!(back.attrs, m.attrs);
        assert_eq!(back.colors, m.colors);
    }
}
