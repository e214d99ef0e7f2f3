//! Stanford PLY: `ascii`, `binary_little_endian` and `binary_big_endian`.
//!
//! Vertex `x`/`y`/`z` of any scalar type, optional `red`/`green`/`blue` colours
//! (integer types scaled to `[0, 1]`, floats kept), faces from the `vertex_indices`
//! (or `vertex_index`) list of the `face` element with any integer count and index
//! types. Other properties (scalar or list) and other elements are skipped. Polygons
//! are fanned. The header's counts are checked against the bytes that follow it
//! before anything is allocated.

mod body;
mod header;
mod writer;

pub(crate) use writer::write;

use super::attrs::{Corners, PlyExtras, PropData, Property};
use super::text::Lines;
use super::{malformed, Caps, Encoding, IoError, Precision, RawMesh, MAX_ELEMENTS};
use body::{read_faces, read_vertices, Body, Src};
use header::{new_property, read_header, Element, Kind, PlyScalar, Role};
use std::io::BufRead;
use std::path::Path;

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
            texcoord = Some((c, t));
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
pub(super) enum FaceKeep {
    Indices,
    TexCoord,
    Prop(usize),
}

/// Appends the values read by [`Body::keep`] (a scalar: one value; a list: its
/// items).
pub(super) fn push_kept(data: &mut PropData, vals: &[f64]) {
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
