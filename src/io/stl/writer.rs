//! The STL writer.

use crate::io::{Encoding, Precision, RawMesh};
use glam::DVec3;
use std::io::Write;

/// Unit normal of a triangle (zero when degenerate).
fn normal(raw: &RawMesh, f: &[u32; 3]) -> DVec3 {
    let p = |i: u32| {
        raw.positions
            .get(i as usize)
            .copied()
            .unwrap_or(DVec3::ZERO)
    };
    let (a, b, c) = (p(f[0]), p(f[1]), p(f[2]));
    (b - a).cross(c - a).normalize_or_zero()
}

/// Writes binary STL when `raw.encoding` is binary (always little-endian `f32`),
/// else ASCII STL. Normals are computed from the triangles.
pub(crate) fn write<W: Write>(w: &mut W, raw: &RawMesh) -> std::io::Result<()> {
    let pos = |i: u32| {
        raw.positions
            .get(i as usize)
            .copied()
            .unwrap_or(DVec3::ZERO)
    };
    if raw.encoding == Encoding::Ascii {
        let f32 = raw.precision == Precision::F32;
        w.write_all(b"solid holefill\n")?;
        for f in &raw.faces {
            let n = normal(raw, f).as_vec3();
            writeln!(w, "facet normal {} {} {}\n  outer loop", n.x, n.y, n.z)?;
            for &i in f {
                let p = pos(i);
                w.write_all(b"    vertex ")?;
                crate::io::write_real(w, p.x, f32)?;
                w.write_all(b" ")?;
                crate::io::write_real(w, p.y, f32)?;
                w.write_all(b" ")?;
                crate::io::write_real(w, p.z, f32)?;
                w.write_all(b"\n")?;
            }
            w.write_all(b"  endloop\nendfacet\n")?;
        }
        w.write_all(b"endsolid holefill\n")?;
    } else {
        let stl = raw.attrs.stl.as_ref();
        let header = match stl {
            Some(s) => s.header,
            None => {
                let mut header = [b' '; 80];
                let text = b"binary STL written by holefill";
                for (h, t) in header.iter_mut().zip(text) {
                    *h = *t;
                }
                header
            }
        };
        w.write_all(&header)?;
        let n = u32::try_from(raw.faces.len()).unwrap_or(u32::MAX);
        w.write_all(&n.to_le_bytes())?;
        let mut rec = [0u8; 50];
        let attribute = stl.map(|s| s.attribute.as_slice()).unwrap_or_default();
        for (k, f) in raw.faces.iter().enumerate() {
            let a = attribute.get(k).copied().unwrap_or(0).to_le_bytes();
            if let Some(slot) = rec.get_mut(48..50) {
                slot.copy_from_slice(&a);
            }
            let n = normal(raw, f).as_vec3();
            let vals = [
                n,
                pos(f[0]).as_vec3(),
                pos(f[1]).as_vec3(),
                pos(f[2]).as_vec3(),
            ];
            for (chunk, v) in rec
                .chunks_exact_mut(4)
                .zip(vals.iter().flat_map(|v| v.to_array()))
            {
                chunk.copy_from_slice(&v.to_le_bytes());
            }
            w.write_all(&rec)?;
        }
    }
    Ok(())
}
