//! The PLY writer.

use super::header::PlyScalar;
use crate::io::attrs::{PropData, Property, ScalarType, Values};
use crate::io::{color_byte, Encoding, Precision, RawMesh};
use std::io::Write;

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
            PropData::Scalar(v) => writeln!(w, "property {} {}", v.ty().name(), p.name),
            PropData::List { count, items, .. } => writeln!(
                w,
                "property list {} {} {}",
                count.name(),
                items.ty().name(),
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
        writeln!(w, "property list {} {} texcoord", c.name(), t.name())?;
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
                let _ = crate::io::write_real(self.rec, v, t == ScalarType::F32);
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
