//! The message that names a scan on the work queue, and the object names it implies.
//!
//! A scan is a set of files: the mesh (`.obj .ply .stl .off`), first, then any files
//! that travel with it (an OBJ's material library and its images), each by its base
//! name. Its **digest** is the SHA-256 of one line per file, in that order,
//! `NAME\0SIZE\0SHA256-HEX\n`; its **key** is `MESH@DIGEST`. The key names
//! everything on the server:
//!
//! - submitted files: `KEY/NAME` in the scans bucket;
//! - the result: `KEY/MESH` (the repaired model, same name and format), the other
//!   files of the set unchanged as `KEY/NAME`, and `KEY/MESH.repair.json` (put last:
//!   its presence means the result is complete) in the results bucket, or the
//!   submitted files and the log in the failed bucket;
//! - the job message's `Nats-Msg-Id` is the key, so submitting the same scan again
//!   within the duplicate window is one job; the done notification's is `done:KEY`.
//!
//! A worker finding the log of a key already in the results or failed bucket
//! acknowledges the job without repairing it: a redelivery after a crash between the
//! upload and the acknowledgement never makes a second, different result.

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// Version of the message format.
pub const VERSION: u32 = 1;

/// A job on the work queue.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct ScanMsg {
    pub version: u32,
    /// The mesh's name (also the first of `files`).
    pub scan: String,
    /// Hex SHA-256 of the set (see the module documentation).
    pub digest: String,
    pub files: Vec<FileEntry>,
    /// When it was submitted (RFC 3339, UTC).
    pub submitted: String,
    /// Who submitted it (host name, or `gateway HOST`).
    #[serde(default)]
    pub origin: Option<String>,
}

/// One file of a scan.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct FileEntry {
    pub name: String,
    pub size: u64,
    /// Hex SHA-256 of the content.
    pub sha256: String,
}

/// The notification that a scan is done (on the done stream).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct DoneMsg {
    pub version: u32,
    pub scan: String,
    pub digest: String,
    pub key: String,
    /// `"repaired"` or `"failed"`.
    pub status: String,
    /// The bucket that holds its files.
    pub bucket: String,
    /// Names of its objects under `KEY/`, the log last.
    pub files: Vec<String>,
    #[serde(default)]
    pub stage: Option<String>,
    #[serde(default)]
    pub error: Option<String>,
}

/// Why a message or a name is refused.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ScanError {
    #[error("not a job message: {0}")]
    Json(String),
    #[error("message version {0}, this worker reads {VERSION}")]
    Version(u32),
    #[error("file name {0:?}: {1}")]
    Name(String, &'static str),
    #[error("the scan {0:?} is not the first of its files")]
    Order(String),
    #[error("the scan's digest does not match its files")]
    Digest,
    #[error("the scan has no files")]
    Empty,
}

/// Hex of bytes.
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// Hex SHA-256 of bytes.
pub fn sha256_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// The lower-case mesh format of a name (`obj`, `ply`, `stl`, `off`), if it is a mesh.
pub fn mesh_ext(name: &str) -> Option<String> {
    let (_, e) = name.rsplit_once('.')?;
    let e = e.to_ascii_lowercase();
    matches!(e.as_str(), "obj" | "ply" | "stl" | "off").then_some(e)
}

/// Checks that a name is a plain file name a worker may create in its own folder:
/// not empty, no `/`, no control characters, no leading dot, at most 221 bytes (its
/// log adds `.repair.json`, and collision stamps may be added on download).
pub fn check_name(name: &str) -> Result<(), ScanError> {
    let bad = |why| Err(ScanError::Name(name.to_string(), why));
    if name.is_empty() {
        return bad("empty");
    }
    if name.len() > 221 {
        return bad("longer than 221 bytes");
    }
    if name.contains('/') {
        return bad("not a plain file name (contains '/')");
    }
    if name.starts_with('.') {
        return bad("starts with a dot");
    }
    if name.chars().any(|c| c.is_control()) {
        return bad("contains control characters");
    }
    Ok(())
}

/// The digest of a set of files (see the module documentation).
pub fn set_digest(files: &[FileEntry]) -> String {
    let mut h = Sha256::new();
    for f in files {
        h.update(f.name.as_bytes());
        h.update(b"\0");
        h.update(f.size.to_string().as_bytes());
        h.update(b"\0");
        h.update(f.sha256.as_bytes());
        h.update(b"\n");
    }
    hex(&h.finalize())
}

impl ScanMsg {
    /// A job for files already read: the mesh first, then the rest of its set.
    pub fn new(
        files: Vec<FileEntry>,
        submitted: String,
        origin: Option<String>,
    ) -> Result<ScanMsg, ScanError> {
        let first = files.first().ok_or(ScanError::Empty)?;
        let m = ScanMsg {
            version: VERSION,
            scan: first.name.clone(),
            digest: set_digest(&files),
            files,
            submitted,
            origin,
        };
        m.validate()?;
        Ok(m)
    }

    /// Reads and checks a message.
    pub fn parse(payload: &[u8]) -> Result<ScanMsg, ScanError> {
        let m: ScanMsg =
            serde_json::from_slice(payload).map_err(|e| ScanError::Json(e.to_string()))?;
        m.validate()?;
        Ok(m)
    }

    /// Names plain, the mesh first and a mesh, no name twice, the digest right.
    pub fn validate(&self) -> Result<(), ScanError> {
        if self.version != VERSION {
            return Err(ScanError::Version(self.version));
        }
        let first = self.files.first().ok_or(ScanError::Empty)?;
        if first.name != self.scan {
            return Err(ScanError::Order(self.scan.clone()));
        }
        if mesh_ext(&self.scan).is_none() {
            return Err(ScanError::Name(
                self.scan.clone(),
                "not a mesh (.obj .ply .stl .off)",
            ));
        }
        for (i, f) in self.files.iter().enumerate() {
            check_name(&f.name)?;
            if f.name.ends_with(".repair.json") {
                return Err(ScanError::Name(f.name.clone(), "a repair log's name"));
            }
            if self.files[..i].iter().any(|g| g.name == f.name) {
                return Err(ScanError::Name(f.name.clone(), "given twice"));
            }
            if f.sha256.len() != 64 || !f.sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
                return Err(ScanError::Name(f.name.clone(), "no SHA-256"));
            }
        }
        if set_digest(&self.files) != self.digest {
            return Err(ScanError::Digest);
        }
        Ok(())
    }

    /// `MESH@DIGEST`.
    pub fn key(&self) -> String {
        format!("{}@{}", self.scan, self.digest)
    }

    /// The object name of a file of this scan: `KEY/NAME`.
    pub fn object(&self, name: &str) -> String {
        format!("{}/{}", self.key(), name)
    }

    /// The repair log's name.
    pub fn log_name(&self) -> String {
        format!("{}.repair.json", self.scan)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(name: &str, data: &[u8]) -> FileEntry {
        FileEntry {
            name: name.into(),
            size: data.len() as u64,
            sha256: sha256_hex(data),
        }
    }

    #[test]
    fn a_message_round_trips_and_its_key_follows_the_content() {
        let a = ScanMsg::new(vec![entry("s.obj", b"v 0 0 0\n")], "t".into(), None).unwrap();
        let back = ScanMsg::parse(&serde_json::to_vec(&a).unwrap()).unwrap();
        assert_eq!(a, back);
        let b = ScanMsg::new(vec![entry("s.obj", b"v 0 0 1\n")], "t".into(), None).unwrap();
        assert_ne!(a.key(), b.key());
        assert!(a.key().starts_with("s.obj@"));
        assert_eq!(a.object("s.obj"), format!("{}/s.obj", a.key()));
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn hostile_messages_are_refused() {
        let mut m = ScanMsg::new(
            vec![entry("s.obj", b"x"), entry("s.mtl", b"y")],
            "t".into(),
            None,
        )
        .unwrap();
        m.files[1].name = "../etc/passwd".into();
        assert!(matches!(m.validate(), Err(ScanError::Name(..))));
        let mut m2 = ScanMsg::new(vec![entry("s.obj", b"x")], "t".into(), None).unwrap();
        m2.files[0].size = 7;
        assert_eq!(m2.validate(), Err(ScanError::Digest));
        assert!(ScanMsg::new(vec![entry("s.mtl", b"x")], "t".into(), None).is_err());
        assert!(ScanMsg::new(vec![entry(".s.obj", b"x")], "t".into(), None).is_err());
        assert!(ScanMsg::new(
            vec![entry("s.obj", b"x"), entry("s.obj", b"x")],
            "t".into(),
            None
        )
        .is_err());
        assert!(ScanMsg::parse(b"{}").is_err());
    }
}
