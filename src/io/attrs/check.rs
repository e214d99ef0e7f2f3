//! What a writer may rely on: the check that every attribute has one value per element
//! and corner indices in range; and what a target format cannot hold, with the reason.

use super::{Corners, Meaning, Property};
use crate::io::{Format, RawMesh};
use serde::Serialize;

/// Checks that every attribute has one value per element it belongs to and that
/// every corner index is in range (what readers deliver and writers rely on).
pub fn check(raw: &RawMesh) -> Result<(), String> {
    let a = &raw.attrs;
    let (nv, nf) = (raw.positions.len(), raw.faces.len());
    for p in &a.vertex {
        if p.data.len() != nv {
            return Err(format!(
                "vertex property {}: {} values for {nv} vertices",
                p.name,
                p.data.len()
            ));
        }
    }
    for p in &a.face {
        if p.data.len() != nf {
            return Err(format!(
                "face property {}: {} values for {nf} faces",
                p.name,
                p.data.len()
            ));
        }
    }
    fn corners<T>(c: &Option<Corners<T>>, nf: usize, what: &str) -> Result<(), String> {
        if let Some(c) = c {
            if c.index.len() != nf {
                return Err(format!("{what}: {} faces indexed of {nf}", c.index.len()));
            }
            let n = c.values.len();
            if let Some(f) = c
                .index
                .iter()
                .flatten()
                .find(|f| f.iter().any(|&i| i as usize >= n))
            {
                return Err(format!(
                    "{what}: corner index {f:?} out of range ({n} values)"
                ));
            }
        }
        Ok(())
    }
    corners(&a.uv, nf, "texture coordinates")?;
    corners(&a.normals, nf, "normals")?;
    if let Some(o) = &a.obj {
        if !o.face_state.is_empty() && o.face_state.len() != nf {
            return Err(format!(
                "OBJ face states: {} for {nf} faces",
                o.face_state.len()
            ));
        }
        if o.face_state.iter().any(|&s| s as usize >= o.states.len()) {
            return Err("OBJ face state out of range".into());
        }
    }
    if let Some(s) = &a.stl {
        if !s.attribute.is_empty() && s.attribute.len() != nf {
            return Err(format!(
                "STL attributes: {} for {nf} faces",
                s.attribute.len()
            ));
        }
    }
    Ok(())
}

/// Something a target format cannot hold, and why.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Dropped {
    pub what: String,
    pub reason: String,
}

/// What writing `raw` as `format` leaves out (empty when the format holds it all).
pub fn dropped(raw: &RawMesh, format: Format) -> Vec<Dropped> {
    let a = &raw.attrs;
    let mut out = Vec::new();
    let mut drop = |what: String, reason: &str| {
        out.push(Dropped {
            what,
            reason: format!("{} {reason}", format.name().to_uppercase()),
        })
    };
    let vertex_ok = |p: &Property| match format {
        Format::Ply => true,
        // OBJ: colours (v x y z r g b)
        Format::Obj => p.meaning() == Meaning::Color && p.name != "alpha" && p.name != "a",
        // OFF: colours and normals (CNOFF)
        Format::Off => {
            matches!(p.meaning(), Meaning::Color | Meaning::Normal(_))
                || matches!(p.name.as_str(), "s" | "t")
        }
        Format::Stl => false,
        // glTF: COLOR_0 (written from the vertex colours, without alpha)
        Format::Gltf | Format::Glb => {
            p.meaning() == Meaning::Color && !matches!(p.name.as_str(), "alpha" | "a")
        }
    };
    for p in a.vertex.iter().filter(|p| !vertex_ok(p)) {
        drop(
            format!("vertex property {}", p.name),
            "has no place for this vertex property",
        );
    }
    if raw.colors.is_some() && format == Format::Stl {
        drop("vertex colours".into(), "has no vertex colours");
    }
    // OFF: face colours (`r g b [a]` or a colour map index after the indices)
    let face_ok = |p: &Property| match format {
        Format::Ply => true,
        Format::Off => p.meaning() == Meaning::Color || p.name == "color_index",
        _ => false,
    };
    for p in a.face.iter().filter(|p| !face_ok(p)) {
        drop(
            format!("face property {}", p.name),
            if format == Format::Off {
                "has no per-face properties other than a colour"
            } else {
                "has no per-face properties"
            },
        );
    }
    if a.uv.is_some() && matches!(format, Format::Stl | Format::Off) {
        drop(
            "texture coordinates".into(),
            "has no per-corner texture coordinates",
        );
    }
    if a.normals.is_some() && !matches!(format, Format::Obj | Format::Gltf | Format::Glb) {
        drop("corner normals".into(), "has no per-corner normals");
    }
    if let Some(o) = &a.obj {
        if format != Format::Obj {
            for m in &o.mtllibs {
                drop(
                    format!("material library {m}"),
                    "cannot name an OBJ material library",
                );
            }
            if !o.face_state.is_empty() {
                drop(
                    "face materials, groups, objects and smoothing groups".into(),
                    "has no usemtl/g/o/s records",
                );
            }
        }
    }
    if let Some(p) = &a.ply {
        if format != Format::Ply {
            if !p.header.is_empty() {
                drop(
                    "PLY comment/obj_info lines".into(),
                    "has no such header lines",
                );
            }
            for (name, _, _) in &p.elements {
                drop(format!("PLY element {name}"), "has no other elements");
            }
        }
    }
    if a.gltf.is_some() && !matches!(format, Format::Gltf | Format::Glb) {
        drop(
            "glTF materials, textures, nodes and the rest of the document".into(),
            "has no place for them",
        );
    }
    if a.stl.is_some() && format != Format::Stl {
        drop(
            "STL header and facet attribute bytes".into(),
            "has no STL header or facet attributes",
        );
    }
    if a.stl.is_some() && format == Format::Stl && raw.encoding == crate::io::Encoding::Ascii {
        drop(
            "STL header and facet attribute bytes".into(),
            "in ASCII has no header bytes or facet attributes",
        );
    }
    out
}
