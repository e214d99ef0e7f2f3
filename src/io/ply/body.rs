//! The PLY body: element values after the header, ASCII or binary, read with error
//! context (element name and index, line); vertices and faces into the `RawMesh`, with
//! a fast path for plain binary vertex and triangle records.

use super::header::{Element, Kind, PlyScalar, Prop, Role};
use super::{push_kept, FaceKeep};
use crate::io::attrs::{PropData, ScalarType};
use crate::io::text::{has_nul, parse_coord, parse_coord_f32, parse_f64, parse_i64, show, tokens};
use crate::io::text::{Lines, Next, MAX_LINE};
use crate::io::{io_error, malformed, read_error, unit_color, Caps, IoError, RawMesh};
use glam::DVec3;
use std::io::{BufRead, Read};
use std::path::Path;

/// Where element values come from.
pub(super) enum Src<R> {
    Ascii {
        lines: Lines<R>,
        /// The current element's line.
        buf: Vec<u8>,
        /// Cursor in `buf`.
        pos: usize,
        line: usize,
    },
    Binary {
        r: R,
        be: bool,
    },
}

/// Reads element values with error context (element name and index, line).
pub(super) struct Body<'p, R> {
    pub(super) path: &'p Path,
    pub(super) src: Src<R>,
    pub(super) element: String,
    pub(super) index: u64,
}

macro_rules! rd {
    ($r:expr, $t:ty, $be:expr) => {{
        let mut b = [0u8; std::mem::size_of::<$t>()];
        $r.read_exact(&mut b)?;
        if $be {
            <$t>::from_be_bytes(b)
        } else {
            <$t>::from_le_bytes(b)
        }
    }};
}

fn read_binary<R: Read>(r: &mut R, t: ScalarType, be: bool) -> std::io::Result<f64> {
    Ok(match t {
        ScalarType::I8 => f64::from(rd!(r, i8, be)),
        ScalarType::U8 => f64::from(rd!(r, u8, be)),
        ScalarType::I16 => f64::from(rd!(r, i16, be)),
        ScalarType::U16 => f64::from(rd!(r, u16, be)),
        ScalarType::I32 => f64::from(rd!(r, i32, be)),
        ScalarType::U32 => f64::from(rd!(r, u32, be)),
        ScalarType::F32 => f64::from(rd!(r, f32, be)),
        ScalarType::F64 => rd!(r, f64, be),
    })
}

impl<R: BufRead> Body<'_, R> {
    fn err(&self, m: impl std::fmt::Display) -> IoError {
        match &self.src {
            Src::Ascii { line, .. } => malformed(self.path, Some(*line), m.to_string()),
            Src::Binary { .. } => malformed(
                self.path,
                None,
                format!("'{}' element {}: {m}", self.element, self.index),
            ),
        }
    }

    fn bin_err(&self, e: std::io::Error) -> IoError {
        read_error(
            self.path,
            e,
            &format!("'{}' element {}", self.element, self.index),
        )
    }

    /// Starts element instance `i` of `count` (ASCII: reads its line).
    pub(super) fn begin(&mut self, i: u64, count: u64) -> Result<(), IoError> {
        self.index = i;
        if let Src::Ascii {
            lines,
            buf,
            pos,
            line,
        } = &mut self.src
        {
            loop {
                match lines
                    .next_line(MAX_LINE)
                    .map_err(|e| io_error(self.path, e))?
                {
                    Next::Line(ln, l) => {
                        if l.trim_ascii().is_empty() {
                            continue;
                        }
                        if has_nul(l) {
                            return Err(malformed(
                                self.path,
                                Some(ln),
                                "binary data (NUL byte) in an ASCII PLY body",
                            ));
                        }
                        buf.clear();
                        buf.extend_from_slice(l);
                        *pos = 0;
                        *line = ln;
                        return Ok(());
                    }
                    Next::Bad(ln, why) => return Err(malformed(self.path, Some(ln), why)),
                    Next::Eof => {
                        return Err(malformed(
                            self.path,
                            None,
                            format!(
                                "truncated file: it ends after {i} of {count} '{}' elements",
                                self.element
                            ),
                        ))
                    }
                }
            }
        }
        Ok(())
    }

    /// Ends an element instance (ASCII: no values may be left on the line).
    pub(super) fn end(&mut self) -> Result<(), IoError> {
        if let Src::Ascii { buf, pos, .. } = &self.src {
            if tokens(buf.get(*pos..).unwrap_or(b"")).next().is_some() {
                return Err(self.err(format!(
                    "more values on the line than the '{}' element declares",
                    self.element
                )));
            }
        }
        Ok(())
    }

    /// The next ASCII token as a byte range of `buf`.
    fn token(&mut self) -> Result<std::ops::Range<usize>, IoError> {
        if let Src::Ascii { buf, pos, .. } = &mut self.src {
            let mut s = *pos;
            while buf.get(s).is_some_and(|b| b.is_ascii_whitespace()) {
                s += 1;
            }
            let mut e = s;
            while buf.get(e).is_some_and(|b| !b.is_ascii_whitespace()) {
                e += 1;
            }
            *pos = e;
            if e > s {
                return Ok(s..e);
            }
        }
        Err(self.err(format!(
            "fewer values on the line than the '{}' element declares",
            self.element
        )))
    }

    fn tok_bytes(&self, r: std::ops::Range<usize>) -> &[u8] {
        match &self.src {
            Src::Ascii { buf, .. } => buf.get(r).unwrap_or(b""),
            Src::Binary { .. } => b"",
        }
    }

    /// A binary value (None for ASCII sources).
    fn bin(&mut self, t: ScalarType) -> Option<std::io::Result<f64>> {
        match &mut self.src {
            Src::Binary { r, be } => {
                let be = *be;
                Some(read_binary(r, t, be))
            }
            Src::Ascii { .. } => None,
        }
    }

    /// A coordinate (finite).
    fn coord(&mut self, t: ScalarType) -> Result<f64, IoError> {
        let v = match self.bin(t) {
            Some(res) => res.map_err(|e| self.bin_err(e))?,
            None => {
                // A value declared `float` is an f32: rounded once from the text.
                if t.is_int() {
                    // The header declares an integer: the text must be one.
                    return self.int(t).map(|v| v as f64);
                }
                let r = self.token()?;
                let tok = self.tok_bytes(r);
                let v = if t == ScalarType::F32 {
                    parse_coord_f32(tok)
                } else {
                    parse_coord(tok)
                };
                return v.map_err(|m| self.err(m));
            }
        };
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err("non-finite coordinate (NaN and infinity are not allowed)"))
        }
    }

    /// An integer (list counts, indices).
    fn int(&mut self, t: ScalarType) -> Result<i64, IoError> {
        match self.bin(t) {
            // Integer types only (checked in the header): exact in f64.
            Some(res) => Ok(res.map_err(|e| self.bin_err(e))? as i64),
            None => {
                let r = self.token()?;
                let tok = self.tok_bytes(r);
                let v = parse_i64(tok).ok_or_else(|| {
                    self.err(format!(
                        "'{}' is not an integer (the header declares {})",
                        show(tok),
                        t.name()
                    ))
                })?;
                match t.int_range() {
                    Some((lo, hi)) if v < lo || v > hi => Err(self.err(format!(
                        "{v} is out of range for the declared type {}",
                        t.name()
                    ))),
                    _ => Ok(v),
                }
            }
        }
    }

    /// A list's length.
    fn count(&mut self, c: ScalarType) -> Result<u64, IoError> {
        let n = self.int(c)?;
        u64::try_from(n).map_err(|_| self.err(format!("negative list length {n}")))
    }

    /// A value of any type kept as it is (NaN and infinities included): exact in
    /// `f64` for every PLY type; ASCII `float` is parsed straight to `f32`.
    fn value(&mut self, t: ScalarType) -> Result<f64, IoError> {
        if let Some(res) = self.bin(t) {
            return res.map_err(|e| self.bin_err(e));
        }
        if t.is_int() {
            return self.int(t).map(|v| v as f64);
        }
        let r = self.token()?;
        let tok = self.tok_bytes(r);
        let v = if t == ScalarType::F32 {
            std::str::from_utf8(tok)
                .ok()
                .and_then(|s| s.parse::<f32>().ok())
                .map(f64::from)
        } else {
            parse_f64(tok)
        };
        v.ok_or_else(|| self.err(format!("'{}' is not a number", show(tok))))
    }

    /// Reads one property into `out` (a scalar: one value; a list: its items).
    pub(super) fn keep(&mut self, kind: Kind, out: &mut Vec<f64>) -> Result<(), IoError> {
        out.clear();
        match kind {
            Kind::Scalar(t) => out.push(self.value(t)?),
            Kind::List(c, t) => {
                let n = self.count(c)?;
                for _ in 0..n {
                    out.push(self.value(t)?);
                }
            }
        }
        Ok(())
    }

    pub(super) fn has_trailing_data(&mut self) -> Result<bool, IoError> {
        match &mut self.src {
            Src::Binary { r, .. } => {
                Ok(!r.fill_buf().map_err(|e| io_error(self.path, e))?.is_empty())
            }
            Src::Ascii { lines, .. } => loop {
                match lines
                    .next_line(MAX_LINE)
                    .map_err(|e| io_error(self.path, e))?
                {
                    Next::Line(_, l) if l.trim_ascii().is_empty() => continue,
                    Next::Eof => return Ok(false),
                    _ => return Ok(true),
                }
            },
        }
    }
}

/// A colour value of type `t` as a component in `[0, 1]`.
fn color_value(v: f64, t: ScalarType) -> f32 {
    let c = match t {
        ScalarType::U16 => v / 65535.0,
        ScalarType::F32 | ScalarType::F64 => v,
        _ => v / 255.0,
    };
    unit_color(c)
}

pub(super) fn read_vertices<R: BufRead>(
    body: &mut Body<'_, R>,
    el: &Element,
    roles: &[Role],
    keep: &[Option<usize>],
    raw: &mut RawMesh,
) -> Result<(), IoError> {
    let layout = binary_vertex_layout(body, el, roles, keep);
    let mut scratch = Vec::new();
    let mut fast_scratch = Vec::new();
    for i in 0..el.count {
        if let Some((layout, size)) = &layout {
            if fast_vertex(body, layout, *size, raw, &mut fast_scratch) {
                continue;
            }
        }
        body.begin(i, el.count)?;
        let mut p = DVec3::ZERO;
        let mut c = [0.0f32; 3];
        for ((prop, &role), &k) in el.props.iter().zip(roles).zip(keep) {
            match (role, prop.kind) {
                (Role::X, Kind::Scalar(t)) => p.x = body.coord(t)?,
                (Role::Y, Kind::Scalar(t)) => p.y = body.coord(t)?,
                (Role::Z, Kind::Scalar(t)) => p.z = body.coord(t)?,
                (_, kind) => {
                    body.keep(kind, &mut scratch)?;
                    if let (Kind::Scalar(t), Some(&v)) = (kind, scratch.first()) {
                        // a colour must be a number (other properties keep any value)
                        if matches!(role, Role::R | Role::G | Role::B) && !v.is_finite() {
                            return Err(body.err("non-finite value"));
                        }
                        match role {
                            Role::R => c[0] = color_value(v, t),
                            Role::G => c[1] = color_value(v, t),
                            Role::B => c[2] = color_value(v, t),
                            _ => {}
                        }
                    }
                    if let Some(prop) = k.and_then(|k| raw.attrs.vertex.get_mut(k)) {
                        push_kept(&mut prop.data, &scratch);
                    }
                }
            }
        }
        body.end()?;
        raw.positions.push(p);
        if let Some(cs) = raw.colors.as_mut() {
            cs.push(c);
        }
    }
    Ok(())
}

/// Decodes a binary scalar from the start of `b` (None when `b` is too short).
fn decode(b: &[u8], t: ScalarType, be: bool) -> Option<f64> {
    macro_rules! d {
        ($t:ty) => {{
            let a: [u8; std::mem::size_of::<$t>()] =
                b.get(..std::mem::size_of::<$t>())?.try_into().ok()?;
            if be {
                <$t>::from_be_bytes(a)
            } else {
                <$t>::from_le_bytes(a)
            }
        }};
    }
    Some(match t {
        ScalarType::I8 => f64::from(d!(i8)),
        ScalarType::U8 => f64::from(d!(u8)),
        ScalarType::I16 => f64::from(d!(i16)),
        ScalarType::U16 => f64::from(d!(u16)),
        ScalarType::I32 => f64::from(d!(i32)),
        ScalarType::U32 => f64::from(d!(u32)),
        ScalarType::F32 => f64::from(d!(f32)),
        ScalarType::F64 => d!(f64),
    })
}

/// Where one vertex property sits in a binary record: offset, type, role, and the
/// kept property it goes to.
type Field = (usize, ScalarType, Role, Option<usize>);

/// For a binary vertex element of scalars only: each property's field and the
/// record size (the fast path of [`read_vertices`]).
fn binary_vertex_layout<R>(
    body: &Body<'_, R>,
    el: &Element,
    roles: &[Role],
    keep: &[Option<usize>],
) -> Option<(Vec<Field>, usize)> {
    if !matches!(body.src, Src::Binary { .. }) {
        return None;
    }
    let mut layout = Vec::with_capacity(el.props.len());
    let mut off = 0usize;
    for ((p, &role), &k) in el.props.iter().zip(roles).zip(keep) {
        let Kind::Scalar(t) = p.kind else {
            return None;
        };
        layout.push((off, t, role, k));
        off += t.size();
    }
    Some((layout, off))
}

/// Binary fast path: decodes one vertex straight from the reader's buffer when the
/// buffer holds the whole record and every coordinate is valid; false (nothing
/// consumed) otherwise, and the generic path reads it (and reports any error).
fn fast_vertex<R: BufRead>(
    body: &mut Body<'_, R>,
    layout: &[Field],
    size: usize,
    raw: &mut RawMesh,
    kept: &mut Vec<(usize, f64)>,
) -> bool {
    let Src::Binary { r, be } = &mut body.src else {
        return false;
    };
    let be = *be;
    let Ok(buf) = r.fill_buf() else {
        return false;
    };
    let Some(rec) = buf.get(..size) else {
        return false;
    };
    let mut p = DVec3::ZERO;
    let mut c = [0.0f32; 3];
    kept.clear();
    for &(off, t, role, k) in layout {
        if role == Role::Skip && k.is_none() {
            continue;
        }
        let Some(v) = rec.get(off..).and_then(|b| decode(b, t, be)) else {
            return false;
        };
        if let Some(k) = k {
            kept.push((k, v));
        }
        match role {
            Role::X | Role::Y | Role::Z | Role::R | Role::G | Role::B if !v.is_finite() => {
                return false
            }
            Role::X => p.x = v,
            Role::Y => p.y = v,
            Role::Z => p.z = v,
            Role::R => c[0] = color_value(v, t),
            Role::G => c[1] = color_value(v, t),
            Role::B => c[2] = color_value(v, t),
            Role::Skip => {}
        }
    }
    r.consume(size);
    raw.positions.push(p);
    if let Some(cs) = raw.colors.as_mut() {
        cs.push(c);
    }
    for &(k, v) in kept.iter() {
        if let Some(PropData::Scalar(vals)) = raw.attrs.vertex.get_mut(k).map(|p| &mut p.data) {
            vals.push_f64(v);
        }
    }
    true
}

/// Binary fast path for a face element of one `list uchar int|uint`: a triangle with
/// indices in range, whole in the reader's buffer, is decoded in place; false
/// (nothing consumed) for anything else, which the generic path reads.
fn fast_triangle<R: BufRead>(
    body: &mut Body<'_, R>,
    num_vertices: u64,
    caps: &Caps,
    raw: &mut RawMesh,
) -> bool {
    let Src::Binary { r, be } = &mut body.src else {
        return false;
    };
    let be = *be;
    if raw.faces.len() as u64 >= caps.faces() {
        return false;
    }
    let Ok(buf) = r.fill_buf() else {
        return false;
    };
    let Some(rec) = buf.get(..13) else {
        return false;
    };
    if rec.first() != Some(&3) {
        return false;
    }
    let mut f = [0u32; 3];
    for (k, slot) in f.iter_mut().enumerate() {
        let Some(&[a, b, c, d]) = rec.get(1 + 4 * k..5 + 4 * k) else {
            return false;
        };
        let w = [a, b, c, d];
        // Signed or unsigned: a negative i32 is a huge u32, out of range either way.
        let v = if be {
            u32::from_be_bytes(w)
        } else {
            u32::from_le_bytes(w)
        };
        if u64::from(v) >= num_vertices {
            return false;
        }
        *slot = v;
    }
    r.consume(13);
    raw.faces.push(f);
    true
}

/// Reads the faces (and their kept properties, per triangle); returns the number
/// of polygons fanned.
pub(super) fn read_faces<R: BufRead>(
    body: &mut Body<'_, R>,
    el: &Element,
    keep: &[FaceKeep],
    num_vertices: u64,
    caps: &Caps,
    raw: &mut RawMesh,
    notes: &mut Vec<String>,
) -> Result<u64, IoError> {
    let mut polygons = 0;
    let mut bad_texcoord = 0u64;
    // Binary fast path: a face element holding only a `list uchar int|uint` of indices.
    let fast = matches!(body.src, Src::Binary { .. })
        && matches!(keep, [FaceKeep::Indices])
        && matches!(
            el.props.as_slice(),
            [Prop {
                kind: Kind::List(ScalarType::U8, ScalarType::I32 | ScalarType::U32),
                ..
            }]
        );
    let mut corners: Vec<u32> = Vec::new();
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); el.props.len()];
    for i in 0..el.count {
        if fast && fast_triangle(body, num_vertices, caps, raw) {
            continue;
        }
        body.begin(i, el.count)?;
        corners.clear();
        for (k, (prop, &what)) in el.props.iter().zip(keep).enumerate() {
            match (what, prop.kind) {
                (FaceKeep::Indices, Kind::List(c, t)) => {
                    let n = body.count(c)?;
                    if n < 3 {
                        return Err(
                            body.err(format!("a face needs at least 3 vertices, found {n}"))
                        );
                    }
                    for _ in 0..n {
                        let v = body.int(t)?;
                        let v = u32::try_from(v)
                            .ok()
                            .filter(|&v| u64::from(v) < num_vertices)
                            .ok_or_else(|| {
                                body.err(format!(
                                    "vertex index {v} out of range ({num_vertices} vertices)"
                                ))
                            })?;
                        corners.push(v);
                    }
                }
                (_, kind) => {
                    let slot = values
                        .get_mut(k)
                        .ok_or_else(|| body.err("internal: property"))?;
                    body.keep(kind, slot)?;
                }
            }
        }
        body.end()?;
        let n = corners.len();
        if n > 3 {
            polygons += 1;
        }
        let tris = n.saturating_sub(2);
        if raw.faces.len() as u64 + tris as u64 > caps.faces() {
            return Err(body.err(caps.face_msg(None)));
        }
        for j in 2..n {
            if let (Some(&a), Some(&b), Some(&c)) =
                (corners.first(), corners.get(j - 1), corners.get(j))
            {
                raw.faces.push([a, b, c]);
            }
        }
        for (&what, vals) in keep.iter().zip(&values) {
            match what {
                FaceKeep::Indices => {}
                FaceKeep::Prop(p) => {
                    if let Some(prop) = raw.attrs.face.get_mut(p) {
                        for _ in 0..tris {
                            push_kept(&mut prop.data, vals);
                        }
                    }
                }
                FaceKeep::TexCoord => {
                    if let Some(uv) = raw.attrs.uv.as_mut() {
                        if vals.len() == 2 * n {
                            let base = uv.values.len() as u32;
                            for c in vals.chunks_exact(2) {
                                uv.values.push([c[0], c[1]]);
                            }
                            for j in 2..n as u32 {
                                uv.index.push(Some([base, base + j - 1, base + j]));
                            }
                        } else {
                            bad_texcoord += 1;
                            uv.index.extend(std::iter::repeat_n(None, tris));
                        }
                    }
                }
            }
        }
    }
    // faces read by the fast path carry nothing else
    if let Some(uv) = raw.attrs.uv.as_mut() {
        uv.index.resize(raw.faces.len(), None);
    }
    if bad_texcoord > 0 {
        notes.push(format!(
            "{bad_texcoord} PLY faces have a texcoord list that is not two values per corner: they have no texture coordinates"
        ));
    }
    Ok(polygons)
}
