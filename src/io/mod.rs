//! Reading and writing triangle meshes: OBJ, PLY, STL, OFF, glTF 2.0 (`.gltf`, `.glb`).
//!
//! Readers produce a [`RawMesh`] (a triangle soup with what the file said about
//! precision and encoding); writers take one back. The mesh builder
//! ([`crate::mesh::Mesh::from_raw`]) turns the soup into a half-edge mesh.
//!
//! Bit-exactness: coordinates are held as `f64`. A file that stored `f32` (binary
//! STL, PLY `float`, also ASCII PLY `float`, parsed straight to `f32`) reads into
//! `f64` exactly, is marked [`Precision::F32`] and is written back as the same `f32`.
//! Text is written with Rust's shortest representation that round-trips (of the
//! `f64`, or of the `f32` when the precision is `F32`), so every input vertex reads
//! back identical: bit-identical `f64` for `F64` meshes, the identical `f32` for
//! `F32` meshes. Readers never reorder vertices (STL, which has no shared vertices,
//! numbers its welded vertices in order of first appearance).
//!
//! Layout: one module per format (`obj`, `ply`, `stl`, `off`), shared line/token
//! helpers in `text`, atomic output in `atomic`. Every reader streams through a
//! buffered reader, checks header counts against the file size before reserving
//! memory, and never panics on bad input; every error names the file (and the line
//! for text formats where known).

use glam::DVec3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A mesh file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Obj,
    Ply,
    Stl,
    Off,
    /// glTF 2.0 as JSON (`.gltf`, buffers beside it or in `data:` URIs).
    Gltf,
    /// glTF 2.0 binary (`.glb`).
    Glb,
}

impl Format {
    /// The format a path's extension names (any case), if any.
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Format::from_name(&ext)
    }
    /// Parses a format name (`obj`, `ply`, `stl`, `off`, any case).
    pub fn from_name(name: &str) -> Option<Format> {
        match name.to_ascii_lowercase().as_str() {
            "obj" => Some(Format::Obj),
            "ply" => Some(Format::Ply),
            "stl" => Some(Format::Stl),
            "off" => Some(Format::Off),
            "gltf" => Some(Format::Gltf),
            "glb" => Some(Format::Glb),
            _ => None,
        }
    }
    /// The lower-case name of the format.
    pub fn name(self) -> &'static str {
        match self {
            Format::Obj => "obj",
            Format::Ply => "ply",
            Format::Stl => "stl",
            Format::Off => "off",
            Format::Gltf => "gltf",
            Format::Glb => "glb",
        }
    }
}

/// How coordinates were stored in the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// 32-bit floats (binary STL, PLY `float`): written back as `f32`.
    F32,
    /// 64-bit floats or decimal text: written back as `f64` / shortest round-trip text.
    #[default]
    F64,
}

/// Text or binary (with byte order) encoding of the input.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Encoding {
    #[default]
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// A triangle soup as read from a file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RawMesh {
    /// Vertex positions, in file order.
    pub positions: Vec<DVec3>,
    /// Per-vertex colours in `[0, 1]`, when the file has them.
    pub colors: Option<Vec<[f32; 3]>>,
    /// Triangles (polygons are fanned by the reader), indices into `positions`.
    pub faces: Vec<[u32; 3]>,
    /// How the coordinates were stored.
    pub precision: Precision,
    /// Text or binary.
    pub encoding: Encoding,
    /// What the reader resolved on the way (polygons fanned, vertices welded, ...).
    pub notes: Vec<String>,
    /// Everything else the file carried (properties, corner UVs and normals,
    /// materials, groups, headers): see [`attrs`].
    pub attrs: attrs::Attrs,
}

/// An I/O or format error, always naming the file.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file could not be opened, read, written or renamed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file was read but its content is not a valid mesh.
    #[error("{path}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
    Malformed {
        path: PathBuf,
        line: Option<usize>,
        message: String,
    },
    /// The extension (or `--format`) names no supported format.
    #[error("{path}: unsupported format (expected .obj, .ply, .stl, .off, .gltf or .glb)")]
    UnknownFormat { path: PathBuf },
}

impl IoError {
    /// True when the input itself is at fault (unreadable content), false for an
    /// operating-system I/O failure (disk full, permission, ...).
    pub fn is_malformed(&self) -> bool {
        !matches!(self, IoError::Io { .. })
    }
}

mod atomic;
pub mod attrs;
mod gltf;
mod obj;
mod off;
mod ply;
mod stl;
mod text;

pub use atomic::{stage, write_atomic, write_unsynced, Staged};

use std::fs::File;
use std::io::{BufReader, Write};

/// Capacity of the buffered readers and writers (large: meshes of 10M faces).
const BUF_CAPACITY: usize = 1 << 20;

/// Reads a mesh file (format from `format`, else from the extension).
///
/// Every error names the file (and the line, for text formats, when known). The
/// returned soup keeps the file's vertex order; polygons are fanned into triangles
/// and what the reader resolved on the way is listed in [`RawMesh::notes`].
pub fn read(path: &Path, format: Option<Format>) -> Result<RawMesh, IoError> {
    read_with_limits(path, format, &ReadLimits::default())
}

/// Size limits for reading untrusted files; `0` means no limit (the format limit
/// of `u32` indices still applies).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReadLimits {
    /// Largest accepted file, in bytes (checked from the file's metadata before
    /// anything is read).
    pub max_file_bytes: u64,
    /// Largest accepted number of vertices (header counts are checked before any
    /// allocation; streamed vertices as they are read).
    pub max_vertices: u64,
    /// Largest accepted number of faces, counted as triangles after fanning
    /// (header counts of polygons are checked before any allocation).
    pub max_faces: u64,
}

/// The element caps a reader enforces: the configured limits, or the `u32` format
/// limit when none is set.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Caps {
    limits: ReadLimits,
}

impl Caps {
    pub(crate) fn new(limits: &ReadLimits) -> Caps {
        Caps { limits: *limits }
    }
    /// Caps with no configured limit (only the format limit).
    #[cfg(test)]
    pub(crate) fn none() -> Caps {
        Caps::new(&ReadLimits::default())
    }
    /// The most vertices accepted.
    pub(crate) fn vertices(&self) -> u64 {
        cap(self.limits.max_vertices)
    }
    /// The most triangles accepted.
    pub(crate) fn faces(&self) -> u64 {
        cap(self.limits.max_faces)
    }
    /// The error message for `n` vertices (or "more than the cap" when `n` is None).
    pub(crate) fn vertex_msg(&self, n: Option<u64>) -> String {
        limit_msg(n, "vertices", self.limits.max_vertices, "max_vertices")
    }
    /// The error message for `n` faces (or "more than the cap" when `n` is None).
    pub(crate) fn face_msg(&self, n: Option<u64>) -> String {
        limit_msg(n, "triangles", self.limits.max_faces, "max_faces")
    }
}

fn cap(limit: u64) -> u64 {
    if limit == 0 {
        MAX_ELEMENTS
    } else {
        limit.min(MAX_ELEMENTS)
    }
}

fn limit_msg(n: Option<u64>, what: &str, limit: u64, key: &str) -> String {
    let cap = cap(limit);
    let head = match n {
        Some(n) => format!("{n} {what} exceed"),
        None => format!("more than {cap} {what}:"),
    };
    if limit == 0 || limit > MAX_ELEMENTS {
        format!("{head} the format limit of {MAX_ELEMENTS}")
    } else {
        format!("{head} the configured limit {key} = {limit}")
    }
}

/// Reads a mesh file under [`ReadLimits`]: a file over `max_file_bytes` is refused
/// before it is read, and vertex/face counts over their limits stop the reader
/// (header counts before any allocation). Errors are [`IoError::Malformed`] naming
/// the file and the limit.
pub fn read_with_limits(
    path: &Path,
    format: Option<Format>,
    limits: &ReadLimits,
) -> Result<RawMesh, IoError> {
    read_with_resources(path, format, limits, &Resources::default())
}

/// Where the reader finds the other files a mesh needs (a glTF document's external
/// buffers): by default beside the mesh, under the name it gives them.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Resources {
    /// Files given by the caller: the name a mesh gives (its relative `uri`, `%XX`
    /// decoded, `./` removed) and the file to read for it.
    pub files: Vec<(String, PathBuf)>,
    /// Only `files` are read, never a file beside the mesh (the daemon reads a mesh
    /// through `/proc/self/fd/0`, beside which nothing may be opened).
    pub only: bool,
}

impl Resources {
    /// The file to read for the relative name `rel` of a mesh at `path`, or why none is.
    pub(crate) fn locate(&self, path: &Path, rel: &Path) -> Result<PathBuf, String> {
        let key: Vec<&str> = rel
            .components()
            .filter_map(|c| match c {
                std::path::Component::Normal(n) => n.to_str(),
                _ => None,
            })
            .collect();
        let key = key.join("/");
        if let Some((_, p)) = self.files.iter().find(|(n, _)| *n == key) {
            return Ok(p.clone());
        }
        if self.only {
            return Err(format!(
                "{key:?} is not among the files given with the mesh"
            ));
        }
        Ok(path.parent().unwrap_or(Path::new(".")).join(rel))
    }
}

/// [`read_with_limits`], the files the mesh names looked for as `resources` says.
pub fn read_with_resources(
    path: &Path,
    format: Option<Format>,
    limits: &ReadLimits,
    resources: &Resources,
) -> Result<RawMesh, IoError> {
    let format = resolve_format(path, format)?;
    let file = File::open(path).map_err(|e| io_error(path, e))?;
    let len = file.metadata().map_err(|e| io_error(path, e))?.len();
    if limits.max_file_bytes > 0 && len > limits.max_file_bytes {
        return Err(malformed(
            path,
            None,
            format!(
                "the file has {len} bytes, over the configured limit max_file_bytes = {}",
                limits.max_file_bytes
            ),
        ));
    }
    let reader = BufReader::with_capacity(BUF_CAPACITY, file);
    read_source(path, reader, len, format, limits, resources)
}

/// Reads a mesh from bytes in memory (`path` only names the source in errors).
/// The same readers and checks as [`read_with_limits`], without the file system:
/// for fuzzing and for callers that already hold the file.
pub fn read_bytes(
    path: &Path,
    bytes: &[u8],
    format: Format,
    limits: &ReadLimits,
) -> Result<RawMesh, IoError> {
    let len = bytes.len() as u64;
    if limits.max_file_bytes > 0 && len > limits.max_file_bytes {
        return Err(malformed(
            path,
            None,
            format!(
                "the input has {len} bytes, over the configured limit max_file_bytes = {}",
                limits.max_file_bytes
            ),
        ));
    }
    read_source(path, bytes, len, format, limits, &Resources::default())
}

fn read_source<R: std::io::BufRead>(
    path: &Path,
    reader: R,
    len: u64,
    format: Format,
    limits: &ReadLimits,
    resources: &Resources,
) -> Result<RawMesh, IoError> {
    if len == 0 {
        return Err(malformed(path, None, "empty file"));
    }
    let caps = Caps::new(limits);
    let raw = match format {
        Format::Obj => obj::read(path, reader, &caps)?,
        Format::Ply => ply::read(path, reader, len, &caps)?,
        Format::Stl => stl::read(path, reader, len, &caps)?,
        Format::Off => off::read(path, reader, len, &caps)?,
        Format::Gltf | Format::Glb => {
            let mut reader = reader;
            let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0).min(1 << 30));
            std::io::Read::read_to_end(&mut reader, &mut bytes)
                .map_err(|e| read_error(path, e, "the glTF file"))?;
            gltf::read(path, &bytes, &caps, resources)?
        }
    };
    check_read(path, &raw)?;
    attrs::check(&raw).map_err(|m| malformed(path, None, m))?;
    Ok(raw)
}

/// Writes a mesh file atomically (format from `format`, else from the extension).
///
/// The mesh is checked first (indices in range, finite coordinates, colours for every
/// vertex); the file is then written to a temporary file in the same folder, synced
/// and renamed over `path`, so `path` never holds a partial file.
///
/// Coordinates: binary formats store `f32` when `raw.precision` is
/// [`Precision::F32`] (and binary STL always does), else `f64`; text formats write
/// Rust's shortest round-trip representation of the `f64` (or of the `f32` when the
/// precision is `F32`), so every value reads back identical.
pub fn write(path: &Path, raw: &RawMesh, format: Option<Format>) -> Result<(), IoError> {
    let format = resolve_format(path, format)?;
    let binary_stl = format == Format::Stl && raw.encoding != Encoding::Ascii;
    check_writable(path, raw, raw.precision == Precision::F32 || binary_stl)?;
    atomic::write_with(path, |w| match format {
        Format::Obj => obj::write(w, raw),
        Format::Ply => ply::write(w, raw),
        Format::Stl => stl::write(w, raw),
        Format::Off => off::write(w, raw),
        Format::Gltf => gltf::write(w, raw, false),
        Format::Glb => gltf::write(w, raw, true),
    })
}

fn resolve_format(path: &Path, format: Option<Format>) -> Result<Format, IoError> {
    format
        .or_else(|| Format::from_path(path))
        .ok_or_else(|| IoError::UnknownFormat {
            path: path.to_path_buf(),
        })
}

/// An operating-system error on `path`.
pub(crate) fn io_error(path: &Path, source: std::io::Error) -> IoError {
    IoError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A content error in `path` (at `line` when known).
pub(crate) fn malformed(path: &Path, line: Option<usize>, message: impl Into<String>) -> IoError {
    IoError::Malformed {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// A read error: an unexpected end of file is a truncated (malformed) file, anything
/// else an operating-system failure.
pub(crate) fn read_error(path: &Path, e: std::io::Error, what: &str) -> IoError {
    if e.kind() == std::io::ErrorKind::UnexpectedEof {
        malformed(path, None, format!("truncated file: it ends inside {what}"))
    } else {
        io_error(path, e)
    }
}

/// The largest number of vertices or faces a mesh may have (indices are `u32`).
pub(crate) const MAX_ELEMENTS: u64 = u32::MAX as u64;

/// Checks what every reader must deliver: at least one face, a colour per vertex
/// when there are colours, indices in range.
fn check_read(path: &Path, raw: &RawMesh) -> Result<(), IoError> {
    if raw.positions.is_empty() {
        return Err(malformed(path, None, "the file has no vertices"));
    }
    if raw.faces.is_empty() {
        return Err(malformed(path, None, "the file has no faces"));
    }
    if let Some(c) = &raw.colors {
        if c.len() != raw.positions.len() {
            return Err(malformed(
                path,
                None,
                format!("{} colours for {} vertices", c.len(), raw.positions.len()),
            ));
        }
    }
    let n = raw.positions.len();
    if let Some(f) = raw
        .faces
        .iter()
        .find(|f| f.iter().any(|&i| i as usize >= n))
    {
        return Err(malformed(
            path,
            None,
            format!("face {f:?} has a vertex index out of range ({n} vertices)"),
        ));
    }
    Ok(())
}

/// Checks a mesh before writing it, so that no half-written file is ever produced
/// for a mesh that cannot be stored.
fn check_writable(path: &Path, raw: &RawMesh, as_f32: bool) -> Result<(), IoError> {
    let n = raw.positions.len();
    let bad = |message: String| malformed(path, None, format!("cannot write mesh: {message}"));
    if n as u64 > MAX_ELEMENTS || raw.faces.len() as u64 > MAX_ELEMENTS {
        return Err(bad(format!(
            "{n} vertices / {} faces exceed the limit of {MAX_ELEMENTS}",
            raw.faces.len()
        )));
    }
    if let Some(c) = &raw.colors {
        if c.len() != n {
            return Err(bad(format!("{} colours for {n} vertices", c.len())));
        }
        if let Some((i, _)) = c
            .iter()
            .enumerate()
            .find(|(_, c)| c.iter().any(|v| !v.is_finite()))
        {
            return Err(bad(format!("vertex {i} has a non-finite colour")));
        }
    }
    for (i, p) in raw.positions.iter().enumerate() {
        if !p.is_finite() {
            return Err(bad(format!("vertex {i} has a non-finite coordinate {p}")));
        }
        if as_f32 && !p.as_vec3().is_finite() {
            return Err(bad(format!(
                "vertex {i} coordinate {p} does not fit in a 32-bit float"
            )));
        }
    }
    if let Some((k, f)) = raw
        .faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&i| i as usize >= n))
    {
        return Err(bad(format!(
            "face {k} {f:?} has a vertex index out of range ({n} vertices)"
        )));
    }
    attrs::check(raw).map_err(bad)
}

/// Writes a coordinate as text: Rust's shortest representation that parses back to
/// the same value (of the `f32` when `f32` is set). Plain decimal notation for
/// ordinary magnitudes, exponent notation for very large or small ones (both are
/// shortest round-trip forms; plain notation of `1e300` would be 301 digits).
pub(crate) fn write_real<W: Write>(w: &mut W, v: f64, f32: bool) -> std::io::Result<()> {
    if f32 {
        let v = v as f32;
        let a = v.abs();
        if a == 0.0 || (1e-5..1e16).contains(&a) {
            write!(w, "{v}")
        } else {
            write!(w, "{v:e}")
        }
    } else {
        let a = v.abs();
        if a == 0.0 || (1e-5..1e16).contains(&a) {
            write!(w, "{v}")
        } else {
            write!(w, "{v:e}")
        }
    }
}

/// A colour component read from a file, as the `[0, 1]` value [`RawMesh::colors`]
/// holds: clamped (NaN reads as 0), so that a finite `f64` too large for an `f32`
/// or a value out of range never becomes a non-finite or out-of-range colour.
pub(crate) fn unit_color(v: f64) -> f32 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(0.0, 1.0) as f32
    }
}

/// A colour component in `[0, 1]` as a byte.
pub(crate) fn color_byte(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0).round() as u8
}
