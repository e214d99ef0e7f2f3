//! What a scan carries besides positions: per-vertex, per-face and per-corner
//! properties with their stored types, material libraries, groups and headers.
//!
//! Readers fill [`Attrs`] (on [`RawMesh::attrs`]); the repair's post-pass
//! ([`crate::mesh::attributes::carry`]) writes every input element's values back
//! unchanged and gives new elements interpolated ones; writers store what their
//! format can hold, and [`dropped`] says what it cannot, with the reason.
//!
//! Values keep their stored type ([`Values`]: one typed vector per property), so a
//! binary PLY `uchar`, `ushort`, `float` or `double` is written back with the same
//! bytes. Faces are the reader's triangles: a polygon fanned into triangles gives
//! each of them the polygon's face values.

use super::RawMesh;
use serde::Serialize;

mod check;
mod refs;

pub use check::{check, dropped, Dropped};
pub use refs::{gltf_external, mtl_images, percent_decode, referenced_files, GltfRef};

/// A scalar type as files store it (the PLY types; OBJ and OFF text is `F64`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ScalarType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl ScalarType {
    /// True for the integer types.
    pub fn is_int(self) -> bool {
        !matches!(self, ScalarType::F32 | ScalarType::F64)
    }
    /// Bytes of one value.
    pub fn size(self) -> usize {
        match self {
            ScalarType::I8 | ScalarType::U8 => 1,
            ScalarType::I16 | ScalarType::U16 => 2,
            ScalarType::I32 | ScalarType::U32 | ScalarType::F32 => 4,
            ScalarType::F64 => 8,
        }
    }
}

macro_rules! values {
    ($($var:ident($t:ty)),*) => {
        /// One value per element, in the type the file stored.
        #[derive(Clone, Debug, PartialEq)]
        pub enum Values { $($var(Vec<$t>)),* }

        impl Values {
            /// An empty vector of type `ty`.
            pub fn new(ty: ScalarType, capacity: usize) -> Values {
                match ty { $(ScalarType::$var => Values::$var(Vec::with_capacity(capacity))),* }
            }
            /// The stored type.
            pub fn ty(&self) -> ScalarType {
                match self { $(Values::$var(_) => ScalarType::$var),* }
            }
            /// Number of values.
            pub fn len(&self) -> usize {
                match self { $(Values::$var(v) => v.len()),* }
            }
            /// True when empty.
            pub fn is_empty(&self) -> bool {
                self.len() == 0
            }
            /// Value `i` as an `f64` (exact for every type), `None` out of range.
            pub fn get(&self, i: usize) -> Option<f64> {
                match self { $(Values::$var(v) => v.get(i).map(|&x| x as f64)),* }
            }
            /// Appends `x` converted to the stored type: integers rounded and
            /// clamped to the type's range (NaN as 0), floats rounded to the type.
            pub fn push_f64(&mut self, x: f64) {
                match self { $(Values::$var(v) => v.push(convert::<$t>(x))),* }
            }
            /// Appends value `i` of `other` (same type: bit for bit); false when
            /// `i` is out of range or the types differ.
            pub fn push_from(&mut self, other: &Values, i: usize) -> bool {
                match (self, other) {
                    $((Values::$var(a), Values::$var(b)) => match b.get(i) {
                        Some(&x) => { a.push(x); true }
                        None => false,
                    },)*
                    _ => false,
                }
            }
            /// The little- or big-endian bytes of value `i` appended to `out`.
            pub fn write_bytes(&self, i: usize, be: bool, out: &mut Vec<u8>) {
                match self {
                    $(Values::$var(v) => if let Some(x) = v.get(i) {
                        if be { out.extend_from_slice(&x.to_be_bytes()) }
                        else { out.extend_from_slice(&x.to_le_bytes()) }
                    }),*
                }
            }
        }
    };
}
values!(
    I8(i8),
    U8(u8),
    I16(i16),
    U16(u16),
    I32(i32),
    U32(u32),
    F32(f32),
    F64(f64)
);

/// Conversion of an interpolated `f64` to a stored type.
trait FromF64 {
    fn from_f64(x: f64) -> Self;
}
macro_rules! from_f64_int {
    ($($t:ty),*) => {$(impl FromF64 for $t {
        fn from_f64(x: f64) -> $t {
            // `as` saturates and maps NaN to 0
            x.round() as $t
        }
    })*};
}
from_f64_int!(i8, u8, i16, u16, i32, u32);
impl FromF64 for f32 {
    fn from_f64(x: f64) -> f32 {
        x as f32
    }
}
impl FromF64 for f64 {
    fn from_f64(x: f64) -> f64 {
        x
    }
}
fn convert<T: FromF64>(x: f64) -> T {
    T::from_f64(x)
}

/// A property's values: one scalar per element, or a list per element.
#[derive(Clone, Debug, PartialEq)]
pub enum PropData {
    Scalar(Values),
    /// Element `i`'s items are `items[starts[i]..starts[i + 1]]`; the count is
    /// stored as `count` in files.
    List {
        count: ScalarType,
        starts: Vec<u64>,
        items: Values,
    },
}

impl PropData {
    /// Number of elements.
    pub fn len(&self) -> usize {
        match self {
            PropData::Scalar(v) => v.len(),
            PropData::List { starts, .. } => starts.len().saturating_sub(1),
        }
    }
    /// True when there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// An empty property of the same types.
    pub fn empty_like(&self, capacity: usize) -> PropData {
        match self {
            PropData::Scalar(v) => PropData::Scalar(Values::new(v.ty(), capacity)),
            PropData::List { count, items, .. } => {
                let mut starts = Vec::with_capacity(capacity + 1);
                starts.push(0);
                PropData::List {
                    count: *count,
                    starts,
                    items: Values::new(items.ty(), capacity),
                }
            }
        }
    }
    /// Appends element `i` of `other` (same types), bit for bit; false when it
    /// cannot.
    pub fn push_from(&mut self, other: &PropData, i: usize) -> bool {
        match (self, other) {
            (PropData::Scalar(a), PropData::Scalar(b)) => a.push_from(b, i),
            (
                PropData::List { starts, items, .. },
                PropData::List {
                    starts: s2,
                    items: i2,
                    ..
                },
            ) => {
                let (Some(&a), Some(&b)) = (s2.get(i), s2.get(i + 1)) else {
                    return false;
                };
                for k in a..b {
                    if !items.push_from(i2, k as usize) {
                        return false;
                    }
                }
                starts.push(items.len() as u64);
                true
            }
            _ => false,
        }
    }
    /// Appends an element with an empty list (lists) or `x` (scalars).
    pub fn push_value(&mut self, x: f64) {
        match self {
            PropData::Scalar(v) => v.push_f64(x),
            PropData::List { starts, items, .. } => starts.push(items.len() as u64),
        }
    }
}

/// A named property (PLY's name; `nx`, `red`, `quality`, ...).
#[derive(Clone, Debug, PartialEq)]
pub struct Property {
    pub name: String,
    pub data: PropData,
}

/// What a vertex property holds, by its name: how new vertices get theirs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Meaning {
    /// A normal component (`nx`, `ny`, `nz`, `normal_x`, ...): from the patch surface.
    Normal(usize),
    /// A colour channel (`red`, `diffuse_green`, `alpha`, ...): harmonic from the rim.
    Color,
    /// A real-valued scalar (`quality`, `confidence`, `s`, `t`, `u`, `v`, ...):
    /// harmonic from the rim.
    Smooth,
    /// An integer that is not a colour (a label, an id, `texnumber`): the rim's
    /// most common value.
    Label,
    /// A list property: new vertices get an empty list.
    List,
}

impl Property {
    /// How new elements get this property's values.
    pub fn meaning(&self) -> Meaning {
        let ty = match &self.data {
            PropData::List { .. } => return Meaning::List,
            PropData::Scalar(v) => v.ty(),
        };
        match self.name.as_str() {
            "nx" | "normal_x" => Meaning::Normal(0),
            "ny" | "normal_y" => Meaning::Normal(1),
            "nz" | "normal_z" => Meaning::Normal(2),
            "red" | "green" | "blue" | "alpha" | "r" | "g" | "b" | "a" | "diffuse_red"
            | "diffuse_green" | "diffuse_blue" | "diffuse_alpha" => Meaning::Color,
            _ if ty.is_int() => Meaning::Label,
            _ => Meaning::Smooth,
        }
    }
}

/// Values indexed per face corner (OBJ `vt`/`vn`, PLY `texcoord` lists): a table
/// of values and, per triangle, the indices of its three corners (`None` for a
/// face that has none).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Corners<T> {
    pub values: Vec<T>,
    pub index: Vec<Option<[u32; 3]>>,
}

impl<T> Corners<T> {
    /// The value at corner `k` of face `f`.
    pub fn at(&self, f: usize, k: usize) -> Option<&T> {
        let i = (*self.index.get(f)?.as_ref()?.get(k)?) as usize;
        self.values.get(i)
    }
}

/// The OBJ state a face was written under: `usemtl`, `g`, `o`, `s` (the text after
/// the keyword, as in the file).
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct ObjState {
    pub material: Option<String>,
    pub group: Option<String>,
    pub object: Option<String>,
    pub smoothing: Option<String>,
}

/// OBJ extras: material libraries and each face's state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjExtras {
    /// `mtllib` arguments, in file order.
    pub mtllibs: Vec<String>,
    /// Distinct states; `face_state[f]` indexes it.
    pub states: Vec<ObjState>,
    /// Per triangle, its state (empty when the file has no `usemtl`/`g`/`o`/`s`).
    pub face_state: Vec<u32>,
    /// The vertex colours were written 0..255 (`v x y z 255 128 0`): the vertex
    /// properties `red green blue` hold them as written and the writer writes those.
    pub byte_colors: bool,
    /// The vertex colours were written 0..1 with more digits than an f32 keeps
    /// (`v x y z 0.123456789 ...`): the vertex properties `red green blue` (double)
    /// hold them as written and the writer writes those.
    pub exact_colors: bool,
}

/// PLY extras: header lines and the elements other than vertex and face.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlyExtras {
    /// `comment ...` and `obj_info ...` lines (without the newline), in order.
    pub header: Vec<String>,
    /// Other elements, with all their properties, written back after the faces.
    pub elements: Vec<(String, usize, Vec<Property>)>,
    /// The types of the face `texcoord` list read into [`Attrs::uv`].
    pub texcoord: Option<(ScalarType, ScalarType)>,
}

/// STL extras: the binary header and each facet's attribute bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct StlExtras {
    pub header: [u8; 80],
    /// Per triangle, the facet's 2 attribute bytes (a `u16`, little-endian);
    /// empty when they are all zero.
    pub attribute: Vec<u16>,
}

/// A triangle primitive of the glTF mesh that was read.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfPrim {
    /// The mesh it belongs to (its index in the document's `meshes`).
    pub mesh: usize,
    /// Its index in the mesh's `primitives`.
    pub index: usize,
    /// Its triangles in [`RawMesh::faces`]: `first_face..first_face + faces`.
    pub first_face: usize,
    pub faces: usize,
    /// Its glTF vertices in the corner value tables: `first_vertex..+vertices`.
    pub first_vertex: usize,
    pub vertices: usize,
    pub material: Option<usize>,
    pub has_normal: bool,
    pub has_uv: bool,
    pub has_color: bool,
}

/// glTF extras: the document and its buffers as read, and where each triangle came
/// from (see `io::gltf`).
#[derive(Clone, Debug, PartialEq)]
pub struct GltfExtras {
    /// The JSON document as read.
    pub json: serde_json::Value,
    /// Every buffer's bytes, by buffer index (shared: the repaired mesh's extras and
    /// the input's hold one copy).
    pub buffers: std::sync::Arc<[Vec<u8>]>,
    /// The buffer that is the GLB binary chunk, when read from a `.glb`.
    pub glb_bin: Option<usize>,
    /// The first mesh whose triangles were read (each primitive names its own).
    pub mesh: usize,
    pub prims: Vec<GltfPrim>,
    /// Per triangle read, its corners' glTF vertices (local to its primitive).
    pub corners: Vec<[u32; 3]>,
    /// Set by the repair for the output: per output face, the triangle read that it
    /// is (`None`: a new face)...
    pub out_faces: Vec<Option<u32>>,
    /// ... and the primitive (index into `prims`) a new face joins.
    pub out_prim: Vec<u32>,
}

impl GltfExtras {
    /// The primitive (index into `prims`) of triangle `j` as read.
    pub fn prim_of(&self, j: usize) -> Option<u32> {
        let k = self.prims.partition_point(|p| p.first_face <= j);
        let p = self.prims.get(k.checked_sub(1)?)?;
        (j < p.first_face + p.faces).then_some((k - 1) as u32)
    }
}

/// Everything a file carried besides positions, faces and [`RawMesh::colors`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Attrs {
    /// Per-vertex properties (PLY: every one but `x y z`; OFF: `nx ny nz`), one
    /// value per vertex of [`RawMesh::positions`].
    pub vertex: Vec<Property>,
    /// Per-face properties, one value per triangle of [`RawMesh::faces`].
    pub face: Vec<Property>,
    /// Per-corner texture coordinates.
    pub uv: Option<Corners<[f64; 2]>>,
    /// Per-corner normals.
    pub normals: Option<Corners<[f64; 3]>>,
    pub obj: Option<ObjExtras>,
    pub ply: Option<PlyExtras>,
    pub stl: Option<StlExtras>,
    pub gltf: Option<GltfExtras>,
}

impl Attrs {
    /// True when the file carried nothing besides positions, faces and colours.
    pub fn is_empty(&self) -> bool {
        self.vertex.is_empty()
            && self.face.is_empty()
            && self.uv.is_none()
            && self.normals.is_none()
            && self.obj.is_none()
            && self.ply.is_none()
            && self.stl.is_none()
            && self.gltf.is_none()
    }

    /// Names of what is carried, for the repair log (`vertex red (uchar)`,
    /// `corner uv`, `obj mtllib scan.mtl`, ...).
    pub fn names(&self, raw: &RawMesh) -> Vec<String> {
        let mut out = Vec::new();
        if raw.colors.is_some() && !self.vertex.iter().any(|p| p.meaning() == Meaning::Color) {
            out.push("vertex colour".to_string());
        }
        let ty = |d: &PropData| match d {
            PropData::Scalar(v) => format!("{:?}", v.ty()).to_lowercase(),
            PropData::List { count, items, .. } => format!(
                "list {} {}",
                format!("{count:?}").to_lowercase(),
                format!("{:?}", items.ty()).to_lowercase()
            ),
        };
        for p in &self.vertex {
            out.push(format!("vertex {} ({})", p.name, ty(&p.data)));
        }
        for p in &self.face {
            out.push(format!("face {} ({})", p.name, ty(&p.data)));
        }
        if self.uv.is_some() {
            out.push("corner texture coordinates".into());
        }
        if self.normals.is_some() {
            out.push("corner normals".into());
        }
        if let Some(o) = &self.obj {
            for m in &o.mtllibs {
                out.push(format!("mtllib {m}"));
            }
            if !o.face_state.is_empty() {
                out.push("face material/group/object/smoothing (usemtl, g, o, s)".into());
            }
        }
        if let Some(p) = &self.ply {
            if !p.header.is_empty() {
                out.push(format!("{} header comment/obj_info lines", p.header.len()));
            }
            for (name, n, _) in &p.elements {
                out.push(format!("element {name} ({n})"));
            }
        }
        if self.stl.is_some() {
            out.push("STL header and facet attribute bytes".into());
        }
        if let Some(g) = &self.gltf {
            let mut meshes: Vec<usize> = g.prims.iter().map(|p| p.mesh).collect();
            meshes.dedup();
            let meshes = meshes
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ");
            out.push(format!(
                "glTF document (mesh {meshes}, {} triangle primitive(s), materials, textures, nodes, {} buffer(s))",
                g.prims.len(),
                g.buffers.len()
            ));
        }
        out
    }
}

/// The repair log's `attributes` section.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct AttributesReport {
    /// What the input carried (besides positions and faces).
    pub read: Vec<String>,
    /// Carried unchanged on every input element.
    pub carried: Vec<String>,
    /// How new elements got their values (`vertex quality: harmonic from the rim`).
    pub interpolated: Vec<String>,
    /// Per filled patch, how its texture coordinates were made: `mapped` into the
    /// rim's UV chart, or a stated fallback.
    pub uv_patches: UvCounts,
    /// What the output format cannot hold.
    pub dropped: Vec<Dropped>,
}

/// Patches by how their texture coordinates were made.
#[derive(Clone, Debug, Default, Serialize, PartialEq, Eq)]
pub struct UvCounts {
    /// Mapped into the UV polygon of the rim (one chart, simple polygon, no flipped
    /// UV triangle).
    pub mapped: usize,
    /// Fallback: the rim crosses a UV seam (its corners lie in more than one chart).
    pub seam: usize,
    /// Fallback: the rim's UV polygon is not simple, or the mapping flipped a
    /// triangle with both weightings tried.
    pub not_simple: usize,
    /// Fallback: the rim has corners without texture coordinates.
    pub missing: usize,
}

#[cfg(test)]
mod tests;
