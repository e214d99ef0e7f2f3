//! Stanford PLY: `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! Vertex `x`/`y`/`z` of any scalar type, optional `red`/`green`/`blue` colours
//! (integer types scaled to `[0, 1]`, floats kept), faces from the `vertex_indices`
//! (or `vertex_index`) list of the `face` element with any integer count and index
//! types. Other properties (scalar or list) and other elements are skipped. Polygons
//! are fanned. The header's counts are checked against the bytes that follow it
//! before anything is allocated.

use super::attrs::{Corners, PlyExtras, PropData, Property, ScalarType, Values};
use super::text::{has_nul, parse_coord, parse_coord_f32, parse_f64, parse_i64, show, tokens};
use super::text::{Lines, Next, MAX_LINE};
use super::{color_byte, unit_color, Caps, MAX_ELEMENTS};
use super::{io_error, malformed, read_error, Encoding, IoError, Precision, RawMesh};
use glam::DVec3;
use std::io::{BufRead, Read, Write};
use std::path::Path;

/// Longest header line accepted.
const MAX_HEADER_LINE: u64 = 64 * 1024;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &[u8]) -> Option<Scalar> {
        Some(match s {
            b"char" | b"int8" => Scalar::I8,
            b"uchar" | b"uint8" => Scalar::U8,
            b"short" | b"int16" => Scalar::I16,
            b"ushort" | b"uint16" => Scalar::U16,
            b"int" | b"int32" => Scalar::I32,
            b"uint" | b"uint32" => Scalar::U32,
            b"float" | b"float32" => Scalar::F32,
            b"double" | b"float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> u64 {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
    fn is_int(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }
    /// The range of an integer type (`None` for floating-point types).
    fn int_range(self) -> Option<(i64, i64)> {
        Some(match self {
            Scalar::I8 => (i8::MIN.into(), i8::MAX.into()),
            Scalar::U8 => (0, u8::MAX.into()),
            Scalar::I16 => (i16::MIN.into(), i16::MAX.into()),
            Scalar::U16 => (0, u16::MAX.into()),
            Scalar::I32 => (i32::MIN.into(), i32::MAX.into()),
            Scalar::U32 => (0, u32::MAX.into()),
            Scalar::F32 | Scalar::F64 => return None,
        })
    }
    /// The type's name in a header.
    fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }
    /// True when every value of the type is exactly an `f32`.
    fn fits_f32(self) -> bool {
        matches!(
            self,
            Scalar::I8 | Scalar::U8 | Scalar::I16 | Scalar::U16 | Scalar::F32
        )
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List(Scalar, Scalar),
}

#[derive(Debug)]
struct Prop {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Prop>,
    line: usize,
}

impl Element {
    /// The fewest bytes one instance can take.
    fn min_size(&self, encoding: Encoding) -> u64 {
        match encoding {
            // A value is at least one character and a separator.
            Encoding::Ascii => 2 * self.props.len() as u64,
            _ => self
                .props
                .iter()
                .map(|p| match p.kind {
                    Kind::Scalar(t) => t.size(),
                    Kind::List(c, _) => c.size(),
                })
                .sum(),
        }
    }
}

/// What a vertex property is used for.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    X,
    Y,
    Z,
    R,
    G,
    B,
    Skip,
}

/// Reads a PLY file of `len` bytes.
pub(crate) fn read<R: BufRead>(
    path: &Path,
    reader: R,
    len: u64,
    caps: &Caps,
) -> Result<RawMesh, IoError> {
    let mut lines = Lines::new(reader);
    let mut header = Vec::new();
    let (encoding, elements) = read_header(path, &mut lines, &mut header)?;
    let remaining = len.saturating_sub(lines.consumed());

    // Roles and sanity of the header before any allocation.
    let mut vertex: Option<usize> = None;
    let mut face: Option<usize> = None;
    let mut need: u128 = 0;
    for (k, el) in elements.iter().enumerate() {
        let bad = |m: String| malformed(path, Some(el.line), m);
        if el.count > 0 && el.props.is_empty() {
            return Err(bad(format!("element '{}' has no properties", el.name)));
        }
        if el.name == "vertex" || el.name == "face" {
            if el.name == "vertex" && el.count > caps.vertices() {
                return Err(bad(caps.vertex_msg(Some(el.count))));
            }
            if el.name == "face" && el.count > caps.faces() {
                return Err(bad(caps.face_msg(Some(el.count))));
            }
            let slot = if el.name == "vertex" {
                &mut vertex
            } else {
                &mut face
            };
            if slot.is_some() {
                return Err(bad(format!("a second '{}' element", el.name)));
            }
            *slot = Some(k);
        }
        need += u128::from(el.count) * u128::from(el.min_size(encoding));
        // The last ASCII value needs no separator.
        let slack = u128::from(encoding == Encoding::Ascii);
        if need.saturating_sub(slack) > u128::from(remaining) {
            return Err(bad(format!(
                "the header claims {} '{}' elements, but only {remaining} bytes follow the header",
                el.count, el.name
            )));
        }
    }
    let vi = vertex.ok_or_else(|| malformed(path, None, "no 'vertex' element"))?;
    let fi = face.ok_or_else(|| malformed(path, None, "no 'face' element"))?;
    let (vel, fel) = match (elements.get(vi), elements.get(fi)) {
        (Some(v), Some(f)) => (v, f),
        _ => return Err(malformed(path, None, "internal: element index")),
    };

    let mut roles = Vec::with_capacity(vel.props.len());
    let mut xyz_types = Vec::new();
    let mut color_types = Vec::new();
    for p in &vel.props {
        let role = match p.name.as_str() {
            "x" => Role::X,
            "y" => Role::Y,
            "z" => Role::Z,
            "red" | "diffuse_red" | "r" => Role::R,
            "green" | "diffuse_green" | "g" => Role::G,
            "blue" | "diffuse_blue" | "b" => Role::B,
            _ => Role::Skip,
        };
        let role = match (role, p.kind) {
            (Role::Skip, _) => Role::Skip,
            (r, Kind::Scalar(t)) => {
                let list = if matches!(r, Role::X | Role::Y | Role::Z) {
                    &mut xyz_types
                } else {
                    &mut color_types
                };
                if roles.contains(&r) {
                    return Err(malformed(
                        path,
                        Some(vel.line),
                        format!("vertex property '{}' appears twice", p.name),
                    ));
                }
                list.push(t);
                r
            }
            (Role::X | Role::Y | Role::Z, Kind::List(..)) => {
                return Err(malformed(
                    path,
                    Some(vel.line),
                    format!("vertex property '{}' is a list, expected a number", p.name),
                ))
            }
            (_, Kind::List(..)) => Role::Skip,
        };
        roles.push(role);
    }
    if xyz_types.len() != 3 {
        return Err(malformed(
            path,
            Some(vel.line),
            "the vertex element needs properties x, y and z",
        ));
    }
    let has_color = color_types.len() == 3;
    let mut notes = Vec::new();
    if !color_types.is_empty() && !has_color {
        notes.push(
            "PLY colour channels kept as properties but not used as vertex colours: not all of red, green, blue present"
                .to_string(),
        );
        for r in roles.iter_mut() {
            if matches!(r, Role::R | Role::G | Role::B) {
                *r = Role::Skip;
            }
        }
    }
    let index_prop = fel
        .props
        .iter()
        .position(|p| p.name == "vertex_indices" || p.name == "vertex_index");
    match index_prop.and_then(|i| fel.props.get(i)).map(|p| p.kind) {
        Some(Kind::List(c, t)) if c.is_int() && t.is_int() => {}
        Some(_) => {
            return Err(malformed(
                path,
                Some(fel.line),
                "face vertex indices must be a list of integers",
            ))
        }
        None if fel.count > 0 => {
            return Err(malformed(
                path,
                Some(fel.line),
                "the face element has no 'vertex_indices' list",
            ))
        }
        None => {}
    }

    let precision = if xyz_types.iter().all(|t| t.fits_f32()) {
        Precision::F32
    } else {
        Precision::F64
    };
    let mut raw = RawMesh {
        precision,
        encoding,
        ..RawMesh::default()
    };
    // Capacity: never more than the bytes left can hold.
    let cap = |el: &Element| -> usize {
        let per = el.min_size(encoding).max(1);
        el.count.min(remaining / per).min(MAX_ELEMENTS) as usize
    };
    raw.positions.reserve(cap(vel));
    if has_color {
        raw.colors = Some(Vec::with_capacity(cap(vel)));
    }
    raw.faces.reserve(cap(fel));
    // every vertex property but x, y, z is kept, with its type
    let mut vkeep = Vec::with_capacity(vel.props.len());
    for p in &vel.props {
        if matches!(p.name.as_str(), "x" | "y" | "z") {
            vkeep.push(None);
        } else {
            vkeep.push(Some(raw.attrs.vertex.len()));
            raw.attrs.vertex.push(new_property(p, cap(vel)));
        }
    }
    // every face property but the indices is kept (per triangle); a float list
    // `texcoord` becomes the corners' texture coordinates
    let mut texcoord = None;
    let mut fkeep = Vec::with_capacity(fel.props.len());
    for (k, p) in fel.props.iter().enumerate() {
        if Some(k) == index_prop {
            fkeep.push(FaceKeep::Indices);
        } else if let (true, Kind::List(c, t)) =
            (p.name == "texcoord" && texcoord.is_none(), p.kind)
        {
            texcoord = Some((attr_type(c), attr_type(t)));
            raw.attrs.uv = Some(Corners::default());
            fkeep.push(FaceKeep::TexCoord);
        } else {
            fkeep.push(FaceKeep::Prop(raw.attrs.face.len()));
            raw.attrs.face.push(new_property(p, cap(fel)));
        }
    }
    let mut extras = PlyExtras {
        header,
        elements: Vec::new(),
        texcoord,
    };

    let mut body = Body {
        path,
        src: match encoding {
            Encoding::Ascii => Src::Ascii {
                lines,
                buf: Vec::with_capacity(256),
                pos: 0,
                line: 0,
            },
            Encoding::BinaryLittleEndian => Src::Binary {
                r: lines.into_inner(),
                be: false,
            },
            Encoding::BinaryBigEndian => Src::Binary {
                r: lines.into_inner(),
                be: true,
            },
        },
        element: String::new(),
        index: 0,
    };
    let mut polygons = 0u64;
    for (k, el) in elements.iter().enumerate() {
        body.element.clear();
        body.element.push_str(&el.name);
        if k == vi {
            read_vertices(&mut body, el, &roles, &vkeep, &mut raw)?;
        } else if k == fi {
            polygons = read_faces(&mut body, el, &fkeep, vel.count, caps, &mut raw, &mut notes)?;
        } else {
            let mut props: Vec<Property> =
                el.props.iter().map(|p| new_property(p, cap(el))).collect();
            let mut scratch = Vec::new();
            for i in 0..el.count {
                body.begin(i, el.count)?;
                for (p, keep) in el.props.iter().zip(props.iter_mut()) {
                    body.keep(p.kind, &mut scratch)?;
                    push_kept(&mut keep.data, &scratch);
                }
                body.end()?;
            }
            extras
                .elements
                .push((el.name.clone(), el.count as usize, props));
        }
    }
    if body.has_trailing_data()? {
        notes.push("ignored data after the last PLY element".into());
    }
    if polygons > 0 {
        notes.push(format!(
            "fanned {polygons} PLY polygons with more than 3 vertices into triangles"
        ));
    }
    if !extras.header.is_empty() || !extras.elements.is_empty() || extras.texcoord.is_some() {
        raw.attrs.ply = Some(extras);
    }
    raw.notes = notes;
    Ok(raw)
}

/// What a face property is read into.
#[derive(Clone, Copy)]
enum FaceKeep {
    Indices,
    TexCoord,
    Prop(usize),
}

fn attr_type(t: Scalar) -> ScalarType {
    match t {
        Scalar::I8 => ScalarType::I8,
        Scalar::U8 => ScalarType::U8,
        Scalar::I16 => ScalarType::I16,
        Scalar::U16 => ScalarType::U16,
        Scalar::I32 => ScalarType::I32,
        Scalar::U32 => ScalarType::U32,
        Scalar::F32 => ScalarType::F32,
        Scalar::F64 => ScalarType::F64,
    }
}

fn type_name(t: ScalarType) -> &'static str {
    match t {
        ScalarType::I8 => "char",
        ScalarType::U8 => "uchar",
        ScalarType::I16 => "short",
        ScalarType::U16 => "ushort",
        ScalarType::I32 => "int",
        ScalarType::U32 => "uint",
        ScalarType::F32 => "float",
        ScalarType::F64 => "double",
    }
}

/// An empty kept property of a header property's types.
fn new_property(p: &Prop, capacity: usize) -> Property {
    let data = match p.kind {
        Kind::Scalar(t) => PropData::Scalar(Values::new(attr_type(t), capacity)),
        Kind::List(c, t) => PropData::List {
            count: attr_type(c),
            starts: vec![0],
            items: Values::new(attr_type(t), capacity),
        },
    };
    Property {
        name: p.name.clone(),
        data,
    }
}

/// Appends the values read by [`Body::keep`] (a scalar: one value; a list: its
/// items).
fn push_kept(data: &mut PropData, vals: &[f64]) {
    match data {
        PropData::Scalar(v) => v.push_f64(vals.first().copied().unwrap_or(0.0)),
        PropData::List { starts, items, .. } => {
            for &x in vals {
                items.push_f64(x);
            }
            starts.push(items.len() as u64);
        }
    }
}

fn read_header<R: BufRead>(
    path: &Path,
    lines: &mut Lines<R>,
    header: &mut Vec<String>,
) -> Result<(Encoding, Vec<Element>), IoError> {
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut first = true;
    loop {
        let (ln, line) = match lines
            .next_line(MAX_HEADER_LINE)
            .map_err(|e| io_error(path, e))?
        {
            Next::Line(ln, l) => (ln, l),
            Next::Eof => return Err(malformed(path, None, "the PLY header has no 'end_header'")),
            Next::Bad(ln, _) if first => {
                return Err(malformed(
                    path,
                    Some(ln),
                    "not a PLY file (the first line is not 'ply')",
                ))
            }
            Next::Bad(ln, why) => {
                return Err(malformed(path, Some(ln), format!("PLY header: {why}")))
            }
        };
        let bad = |m: String| malformed(path, Some(ln), m);
        if first {
            if line.trim_ascii() != b"ply" {
                return Err(bad("not a PLY file (the first line is not 'ply')".into()));
            }
            first = false;
            continue;
        }
        if has_nul(line) {
            return Err(bad("binary data (NUL byte) in the PLY header".into()));
        }
        let mut t = tokens(line);
        let Some(kw) = t.next() else { continue };
        match kw {
            b"format" => {
                encoding = Some(match t.next() {
                    Some(b"ascii") => Encoding::Ascii,
                    Some(b"binary_little_endian") => Encoding::BinaryLittleEndian,
                    Some(b"binary_big_endian") => Encoding::BinaryBigEndian,
                    other => {
                        return Err(bad(format!(
                            "unknown PLY format '{}'",
                            show(other.unwrap_or(b""))
                        )))
                    }
                });
            }
            b"comment" | b"obj_info" => {
                header.push(String::from_utf8_lossy(line.trim_ascii()).into_owned());
            }
            b"element" => {
                let (Some(name), Some(count)) = (t.next(), t.next()) else {
                    return Err(bad("an element line needs a name and a count".into()));
                };
                let count = parse_i64(count)
                    .and_then(|c| u64::try_from(c).ok())
                    .ok_or_else(|| bad(format!("bad element count '{}'", show(count))))?;
                elements.push(Element {
                    name: String::from_utf8_lossy(name).into_owned(),
                    count,
                    props: Vec::new(),
                    line: ln,
                });
            }
            b"property" => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| bad("a property before any element".into()))?;
                let ty = |s: Option<&[u8]>| {
                    let s = s.unwrap_or(b"");
                    Scalar::parse(s)
                        .ok_or_else(|| bad(format!("unknown property type '{}'", show(s))))
                };
                let head = t.next();
                let kind = if head == Some(b"list") {
                    let c = ty(t.next())?;
                    if !c.is_int() {
                        return Err(bad("a list count must have an integer type".into()));
                    }
                    Kind::List(c, ty(t.next())?)
                } else {
                    Kind::Scalar(ty(head)?)
                };
                let name = t
                    .next()
                    .ok_or_else(|| bad("a property needs a name".into()))?;
                el.props.push(Prop {
                    name: String::from_utf8_lossy(name).into_owned(),
                    kind,
                });
            }
            b"end_header" => break,
            other => {
                return Err(bad(format!("unknown PLY header line '{}'", show(other))));
            }
        }
    }
    let encoding =
        encoding.ok_or_else(|| malformed(path, None, "the PLY header has no 'format' line"))?;
    Ok((encoding, elements))
}

/// Where element values come from.
enum Src<R> {
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
struct Body<'p, R> {
    path: &'p Path,
    src: Src<R>,
    element: String,
    index: u64,
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

fn read_binary<R: Read>(r: &mut R, t: Scalar, be: bool) -> std::io::Result<f64> {
    Ok(match t {
        Scalar::I8 => f64::from(rd!(r, i8, be)),
        Scalar::U8 => f64::from(rd!(r, u8, be)),
        Scalar::I16 => f64::from(rd!(r, i16, be)),
        Scalar::U16 => f64::from(rd!(r, u16, be)),
        Scalar::I32 => f64::from(rd!(r, i32, be)),
        Scalar::U32 => f64::from(rd!(r, u32, be)),
        Scalar::F32 => f64::from(rd!(r, f32, be)),
        Scalar::F64 => rd!(r, f64, be),
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
    fn begin(&mut self, i: u64, count: u64) -> Result<(), IoError> {
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
    fn end(&mut self) -> Result<(), IoError> {
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
    fn bin(&mut self, t: Scalar) -> Option<std::io::Result<f64>> {
        match &mut self.src {
            Src::Binary { r, be } => {
                let be = *be;
                Some(read_binary(r, t, be))
            }
            Src::Ascii { .. } => None,
        }
    }

    /// A coordinate (finite).
    fn coord(&mut self, t: Scalar) -> Result<f64, IoError> {
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
                let v = if t == Scalar::F32 {
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
    fn int(&mut self, t: Scalar) -> Result<i64, IoError> {
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
    fn count(&mut self, c: Scalar) -> Result<u64, IoError> {
        let n = self.int(c)?;
        u64::try_from(n).map_err(|_| self.err(format!("negative list length {n}")))
    }

    /// A value of any type kept as it is (NaN and infinities included): exact in
    /// `f64` for every PLY type; ASCII `float` is parsed straight to `f32`.
    fn value(&mut self, t: Scalar) -> Result<f64, IoError> {
        if let Some(res) = self.bin(t) {
            return res.map_err(|e| self.bin_err(e));
        }
        if t.is_int() {
            return self.int(t).map(|v| v as f64);
        }
        let r = self.token()?;
        let tok = self.tok_bytes(r);
        let v = if t == Scalar::F32 {
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
    fn keep(&mut self, kind: Kind, out: &mut Vec<f64>) -> Result<(), IoError> {
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

    fn has_trailing_data(&mut self) -> Result<bool, IoError> {
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
fn color_value(v: f64, t: Scalar) -> f32 {
    let c = match t {
        Scalar::U16 => v / 65535.0,
        Scalar::F32 | Scalar::F64 => v,
        _ => v / 255.0,
    };
    unit_color(c)
}

fn read_vertices<R: BufRead>(
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
fn decode(b: &[u8], t: Scalar, be: bool) -> Option<f64> {
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
        Scalar::I8 => f64::from(d!(i8)),
        Scalar::U8 => f64::from(d!(u8)),
        Scalar::I16 => f64::from(d!(i16)),
        Scalar::U16 => f64::from(d!(u16)),
        Scalar::I32 => f64::from(d!(i32)),
        Scalar::U32 => f64::from(d!(u32)),
        Scalar::F32 => f64::from(d!(f32)),
        Scalar::F64 => d!(f64),
    })
}

/// Where one vertex property sits in a binary record: offset, type, role, and the
/// kept property it goes to.
type Field = (usize, Scalar, Role, Option<usize>);

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
        off += t.size() as usize;
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
fn read_faces<R: BufRead>(
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
                kind: Kind::List(Scalar::U8, Scalar::I32 | Scalar::U32),
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

/// Writes a PLY file in `raw.encoding`: `float` coordinates when the precision is
/// `F32`, else `double`; every kept vertex and face property with its type (input
/// values bit for bit); `uchar` colours when the colours are not among them;
/// `uchar`/`int` index lists; the corners' texture coordinates as a face
/// `texcoord` list; the input's comment/obj_info lines and other elements.
pub(crate) fn write<W: Write>(w: &mut W, raw: &RawMesh) -> std::io::Result<()> {
    let f32 = raw.precision == Precision::F32;
    let a = &raw.attrs;
    let has_color_props = a
        .vertex
        .iter()
        .any(|p| matches!(p.name.as_str(), "red" | "diffuse_red" | "r"));
    let colors = raw.colors.as_deref().filter(|_| !has_color_props);
    let index_type = if raw.positions.len() > i32::MAX as usize {
        "uint"
    } else {
        "int"
    };
    let format = match raw.encoding {
        Encoding::Ascii => "ascii",
        Encoding::BinaryLittleEndian => "binary_little_endian",
        Encoding::BinaryBigEndian => "binary_big_endian",
    };
    let real = if f32 { "float" } else { "double" };
    let ply = a.ply.as_ref();
    write!(w, "ply\nformat {format} 1.0\n")?;
    for line in ply.map(|p| p.header.as_slice()).unwrap_or_default() {
        // one line each: a line break inside would start a header line of its own
        writeln!(w, "{}", line.replace(['\n', '\r'], " "))?;
    }
    write!(
        w,
        "comment written by holefill\nelement vertex {}\n\
         property {real} x\nproperty {real} y\nproperty {real} z\n",
        raw.positions.len()
    )?;
    let declare = |w: &mut W, p: &Property| -> std::io::Result<()> {
        match &p.data {
            PropData::Scalar(v) => writeln!(w, "property {} {}", type_name(v.ty()), p.name),
            PropData::List { count, items, .. } => writeln!(
                w,
                "property list {} {} {}",
                type_name(*count),
                type_name(items.ty()),
                p.name
            ),
        }
    };
    for p in &a.vertex {
        declare(w, p)?;
    }
    if colors.is_some() {
        w.write_all(b"property uchar red\nproperty uchar green\nproperty uchar blue\n")?;
    }
    write!(
        w,
        "element face {}\nproperty list uchar {index_type} vertex_indices\n",
        raw.faces.len()
    )?;
    for p in &a.face {
        declare(w, p)?;
    }
    let texcoord = a.uv.as_ref().map(|_| {
        ply.and_then(|p| p.texcoord)
            .unwrap_or((ScalarType::U8, ScalarType::F32))
    });
    if let Some((c, t)) = texcoord {
        writeln!(
            w,
            "property list {} {} texcoord",
            type_name(c),
            type_name(t)
        )?;
    }
    for (name, n, props) in ply.map(|p| p.elements.as_slice()).unwrap_or_default() {
        writeln!(w, "element {name} {n}")?;
        for p in props {
            declare(w, p)?;
        }
    }
    w.write_all(b"end_header\n")?;

    let be = match raw.encoding {
        Encoding::Ascii => None,
        Encoding::BinaryLittleEndian => Some(false),
        Encoding::BinaryBigEndian => Some(true),
    };
    let mut rec: Vec<u8> = Vec::with_capacity(64);
    let mut out = Out { be, rec: &mut rec };
    for (i, p) in raw.positions.iter().enumerate() {
        out.rec.clear();
        for v in [p.x, p.y, p.z] {
            if f32 {
                out.real(v, ScalarType::F32);
            } else {
                out.real(v, ScalarType::F64);
            }
        }
        for p in &a.vertex {
            out.prop(&p.data, i);
        }
        if let Some(c) = colors.and_then(|c| c.get(i)) {
            for &c in c {
                out.int(i64::from(color_byte(c)), ScalarType::U8);
            }
        }
        out.finish(w)?;
    }
    let uv = a.uv.as_ref();
    for (k, f) in raw.faces.iter().enumerate() {
        out.rec.clear();
        out.int(3, ScalarType::U8);
        let it = if index_type == "uint" {
            ScalarType::U32
        } else {
            ScalarType::I32
        };
        for &i in f {
            out.int(i64::from(i), it);
        }
        for p in &a.face {
            out.prop(&p.data, k);
        }
        if let (Some(uv), Some((c, t))) = (uv, texcoord) {
            match uv.index.get(k).copied().flatten() {
                Some(idx) => {
                    out.int(6, c);
                    for i in idx {
                        let v = uv.values.get(i as usize).copied().unwrap_or([0.0; 2]);
                        out.real(v[0], t);
                        out.real(v[1], t);
                    }
                }
                None => out.int(0, c),
            }
        }
        out.finish(w)?;
    }
    for (_, n, props) in ply.map(|p| p.elements.as_slice()).unwrap_or_default() {
        for i in 0..*n {
            out.rec.clear();
            for p in props {
                out.prop(&p.data, i);
            }
            out.finish(w)?;
        }
    }
    Ok(())
}

/// One element's record being written: binary bytes (`be`: byte order) or ASCII
/// text, values separated by spaces.
struct Out<'a> {
    be: Option<bool>,
    rec: &'a mut Vec<u8>,
}

impl Out<'_> {
    fn sep(&mut self) {
        if self.be.is_none() && !self.rec.is_empty() {
            self.rec.push(b' ');
        }
    }
    /// An integer of type `t` (binary: its bytes).
    fn int(&mut self, v: i64, t: ScalarType) {
        self.sep();
        match self.be {
            None => {
                use std::io::Write as _;
                let _ = write!(self.rec, "{v}");
            }
            Some(be) => {
                let mut one = Values::new(t, 1);
                one.push_f64(v as f64);
                one.write_bytes(0, be, self.rec);
            }
        }
    }
    /// A real of type `t` (ASCII: shortest round-trip text of that type).
    fn real(&mut self, v: f64, t: ScalarType) {
        if t.is_int() {
            return self.int(v.round() as i64, t);
        }
        self.sep();
        match self.be {
            None => {
                let _ = super::write_real(self.rec, v, t == ScalarType::F32);
            }
            Some(be) => {
                if t == ScalarType::F32 {
                    let x = v as f32;
                    self.rec
                        .extend_from_slice(&if be { x.to_be_bytes() } else { x.to_le_bytes() });
                } else {
                    self.rec
                        .extend_from_slice(&if be { v.to_be_bytes() } else { v.to_le_bytes() });
                }
            }
        }
    }
    /// Value `k` of `vals`, in its type.
    fn scalar(&mut self, vals: &Values, k: usize) {
        match self.be {
            Some(be) => vals.write_bytes(k, be, self.rec),
            None => {
                let v = vals.get(k).unwrap_or(0.0);
                if vals.ty().is_int() {
                    self.int(v as i64, vals.ty())
                } else {
                    self.real(v, vals.ty())
                }
            }
        }
    }
    /// Value `i` of a kept property, in its type.
    fn prop(&mut self, d: &PropData, i: usize) {
        match d {
            PropData::Scalar(v) => self.scalar(v, i),
            PropData::List {
                count,
                starts,
                items,
            } => {
                let (a, b) = match (starts.get(i), starts.get(i + 1)) {
                    (Some(&a), Some(&b)) => (a as usize, b as usize),
                    _ => (0, 0),
                };
                self.int((b - a) as i64, *count);
                for k in a..b {
                    self.scalar(items, k);
                }
            }
        }
    }
    fn finish<W: Write>(&mut self, w: &mut W) -> std::io::Result<()> {
        if self.be.is_none() {
            self.rec.push(b'\n');
        }
        w.write_all(self.rec)
    }
}
