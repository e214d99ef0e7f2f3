//! The PLY header: scalar types, elements and their properties, read and checked
//! line by line (`format`, `element`, `property`, `comment`/`obj_info`).

use crate::io::attrs::{PropData, Property, ScalarType, Values};
use crate::io::text::{has_nul, parse_i64, show, tokens, Lines, Next};
use crate::io::{io_error, malformed, Encoding, IoError};
use std::io::BufRead;
use std::path::Path;

/// Longest header line accepted.
const MAX_HEADER_LINE: u64 = 64 * 1024;

/// The PLY side of a stored scalar type: its names in a header, the range of an
/// integer type, whether every value is exactly an `f32`.
pub(super) trait PlyScalar: Sized {
    /// The type a header names (`uchar`, `uint8`, ...).
    fn parse(s: &[u8]) -> Option<Self>;
    /// The range of an integer type (`None` for floating-point types).
    fn int_range(self) -> Option<(i64, i64)>;
    /// The type's name in a header.
    fn name(self) -> &'static str;
    /// True when every value of the type is exactly an `f32`.
    fn fits_f32(self) -> bool;
}

impl PlyScalar for ScalarType {
    fn parse(s: &[u8]) -> Option<ScalarType> {
        Some(match s {
            b"char" | b"int8" => ScalarType::I8,
            b"uchar" | b"uint8" => ScalarType::U8,
            b"short" | b"int16" => ScalarType::I16,
            b"ushort" | b"uint16" => ScalarType::U16,
            b"int" | b"int32" => ScalarType::I32,
            b"uint" | b"uint32" => ScalarType::U32,
            b"float" | b"float32" => ScalarType::F32,
            b"double" | b"float64" => ScalarType::F64,
            _ => return None,
        })
    }
    fn int_range(self) -> Option<(i64, i64)> {
        Some(match self {
            ScalarType::I8 => (i8::MIN.into(), i8::MAX.into()),
            ScalarType::U8 => (0, u8::MAX.into()),
            ScalarType::I16 => (i16::MIN.into(), i16::MAX.into()),
            ScalarType::U16 => (0, u16::MAX.into()),
            ScalarType::I32 => (i32::MIN.into(), i32::MAX.into()),
            ScalarType::U32 => (0, u32::MAX.into()),
            ScalarType::F32 | ScalarType::F64 => return None,
        })
    }
    fn name(self) -> &'static str {
        match self {
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
    fn fits_f32(self) -> bool {
        matches!(
            self,
            ScalarType::I8 | ScalarType::U8 | ScalarType::I16 | ScalarType::U16 | ScalarType::F32
        )
    }
}

#[derive(Clone, Copy, Debug)]
pub(super) enum Kind {
    Scalar(ScalarType),
    List(ScalarType, ScalarType),
}

#[derive(Debug)]
pub(super) struct Prop {
    pub(super) name: String,
    pub(super) kind: Kind,
}

#[derive(Debug)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: u64,
    pub(super) props: Vec<Prop>,
    pub(super) line: usize,
}

impl Element {
    /// The fewest bytes one instance can take.
    pub(super) fn min_size(&self, encoding: Encoding) -> u64 {
        match encoding {
            // A value is at least one character and a separator.
            Encoding::Ascii => 2 * self.props.len() as u64,
            _ => self
                .props
                .iter()
                .map(|p| match p.kind {
                    Kind::Scalar(t) => t.size() as u64,
                    Kind::List(c, _) => c.size() as u64,
                })
                .sum(),
        }
    }
}

/// What a vertex property is used for.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Role {
    X,
    Y,
    Z,
    R,
    G,
    B,
    Skip,
}

/// An empty kept property of a header property's types.
pub(super) fn new_property(p: &Prop, capacity: usize) -> Property {
    let data = match p.kind {
        Kind::Scalar(t) => PropData::Scalar(Values::new(t, capacity)),
        Kind::List(c, t) => PropData::List {
            count: c,
            starts: vec![0],
            items: Values::new(t, capacity),
        },
    };
    Property {
        name: p.name.clone(),
        data,
    }
}

pub(super) fn read_header<R: BufRead>(
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
                    ScalarType::parse(s)
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
