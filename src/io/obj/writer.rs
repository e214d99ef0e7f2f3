//! The OBJ writer.

use crate::io::attrs::{ObjState, PropData, Values};
use crate::io::{Precision, RawMesh};
use std::io::Write;

/// Writes an OBJ file: `mtllib`, `v x y z [r g b]` (colours read as 0..255, or 0..1
/// with more digits than an f32 keeps, as they were written), `vt`, `vn`, the face states
/// (`o`, `g`, `usemtl`, `s` where they change) and `f a[/t][/n] ...` (1-based).
pub(crate) fn write<W: Write>(w: &mut W, raw: &RawMesh) -> std::io::Result<()> {
    let f32 = raw.precision == Precision::F32;
    writeln!(
        w,
        "# written by holefill\n# {} vertices, {} triangles",
        raw.positions.len(),
        raw.faces.len()
    )?;
    let a = &raw.attrs;
    if let Some(o) = &a.obj {
        for m in &o.mtllibs {
            writeln!(w, "mtllib {}", one_line(m))?;
        }
    }
    // colours read as 0..255, or 0..1 with more digits than f32 keeps, go back as
    // written (new vertices: interpolated in that scale)
    let bytes: Option<[&Values; 3]> = a
        .obj
        .as_ref()
        .filter(|o| o.byte_colors || o.exact_colors)
        .and_then(|_| Some([prop(raw, "red")?, prop(raw, "green")?, prop(raw, "blue")?]))
        .filter(|c| c.iter().all(|v| v.len() == raw.positions.len()));
    let colors = raw.colors.as_deref().filter(|_| bytes.is_none());
    for (i, p) in raw.positions.iter().enumerate() {
        w.write_all(b"v ")?;
        crate::io::write_real(w, p.x, f32)?;
        w.write_all(b" ")?;
        crate::io::write_real(w, p.y, f32)?;
        w.write_all(b" ")?;
        crate::io::write_real(w, p.z, f32)?;
        if let Some(c) = colors.and_then(|c| c.get(i)) {
            write!(w, " {} {} {}", c[0], c[1], c[2])?;
        }
        for v in bytes.iter().flatten() {
            let x = v.get(i).unwrap_or(0.0);
            w.write_all(b" ")?;
            if v.ty().is_int() {
                write!(w, "{}", x as i64)?;
            } else {
                crate::io::write_real(w, x, false)?;
            }
        }
        w.write_all(b"\n")?;
    }
    if let Some(uv) = &a.uv {
        for t in &uv.values {
            w.write_all(b"vt ")?;
            crate::io::write_real(w, t[0], false)?;
            w.write_all(b" ")?;
            crate::io::write_real(w, t[1], false)?;
            w.write_all(b"\n")?;
        }
    }
    if let Some(n) = &a.normals {
        for t in &n.values {
            w.write_all(b"vn ")?;
            crate::io::write_real(w, t[0], false)?;
            w.write_all(b" ")?;
            crate::io::write_real(w, t[1], false)?;
            w.write_all(b" ")?;
            crate::io::write_real(w, t[2], false)?;
            w.write_all(b"\n")?;
        }
    }
    let states = a.obj.as_ref().filter(|o| !o.face_state.is_empty());
    let default = ObjState::default();
    let mut last = &default;
    let uv = a.uv.as_ref();
    let nrm = a.normals.as_ref();
    for (k, f) in raw.faces.iter().enumerate() {
        if let Some(o) = states {
            let s = o
                .face_state
                .get(k)
                .and_then(|&s| o.states.get(s as usize))
                .unwrap_or(&default);
            if s.object != last.object {
                writeln!(w, "o {}", one_line(s.object.as_deref().unwrap_or("")))?;
            }
            if s.group != last.group {
                writeln!(w, "g {}", one_line(s.group.as_deref().unwrap_or("")))?;
            }
            if s.material != last.material {
                if let Some(m) = &s.material {
                    writeln!(w, "usemtl {}", one_line(m))?;
                }
            }
            if s.smoothing != last.smoothing {
                writeln!(w, "s {}", one_line(s.smoothing.as_deref().unwrap_or("off")))?;
            }
            last = s;
        }
        let t = uv.and_then(|c| c.index.get(k).copied().flatten());
        let n = nrm.and_then(|c| c.index.get(k).copied().flatten());
        w.write_all(b"f")?;
        for c in 0..3 {
            write!(w, " {}", u64::from(f[c]) + 1)?;
            match (t, n) {
                (Some(t), Some(n)) => {
                    write!(w, "/{}/{}", u64::from(t[c]) + 1, u64::from(n[c]) + 1)?
                }
                (Some(t), None) => write!(w, "/{}", u64::from(t[c]) + 1)?,
                (None, Some(n)) => write!(w, "//{}", u64::from(n[c]) + 1)?,
                (None, None) => {}
            }
        }
        w.write_all(b"\n")?;
    }
    Ok(())
}

/// The scalar vertex property `name`.
fn prop<'a>(raw: &'a RawMesh, name: &str) -> Option<&'a Values> {
    raw.attrs.vertex.iter().find_map(|p| match &p.data {
        PropData::Scalar(v) if p.name == name => Some(v),
        _ => None,
    })
}

/// A name on one line (a line break inside would start a record of its own).
fn one_line(s: &str) -> String {
    s.replace(['\n', '\r'], " ")
}
