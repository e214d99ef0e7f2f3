//! Atomic file output: a temporary file in the target's folder, written through a
//! buffer, synced, renamed over the target, and the folder synced. On any failure
//! the temporary file is removed, so the target is either the old file or the
//! complete new one, never a partial file.

use super::{io_error, IoError, BUF_CAPACITY};
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Distinguishes temporary files of concurrent writes from one process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes bytes atomically: a temporary file in the same folder, fsync, rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    write_with(path, |w| w.write_all(bytes))
}

/// Runs `body` on a buffered writer to a temporary file next to `path`, then syncs
/// and renames it over `path`. Errors name `path`.
pub(crate) fn write_with<F>(path: &Path, body: F) -> Result<(), IoError>
where
    F: FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
{
    stage_with(path, body, true)?.commit()
}

/// Writes bytes in place by a rename, as [`write_atomic`] does, but syncs nothing: for
/// a file derived from others (a repair's picture), whose loss in a power cut costs
/// only itself, so that writing it never makes other files' syncs wait (on ext4 each
/// sync commits the journal for every file).
pub fn write_unsynced(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    let mut staged = stage_with(path, |w| w.write_all(bytes), false)?;
    std::fs::rename(&staged.tmp, &staged.path).map_err(|e| io_error(path, e))?;
    staged.committed = true;
    Ok(())
}

/// A file written and synced beside its target but not in place yet:
/// [`Staged::commit`] renames it over the target and syncs the folder; dropped
/// uncommitted, it is removed. For a file that must not appear before another one is
/// safely written (a repair's picture after its model) while both are written at once.
#[derive(Debug)]
pub struct Staged {
    tmp: PathBuf,
    path: PathBuf,
    dir: PathBuf,
    committed: bool,
}

/// Writes `bytes` to a temporary file next to `path` and syncs it (see [`Staged`]).
pub fn stage(path: &Path, bytes: &[u8]) -> Result<Staged, IoError> {
    stage_with(path, |w| w.write_all(bytes), true)
}

/// The file written beside `path` by `body`, and synced when `sync`.
fn stage_with<F>(path: &Path, body: F, sync: bool) -> Result<Staged, IoError>
where
    F: FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
{
    let name = path.file_name().ok_or_else(|| {
        io_error(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file name"),
        )
    })?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(
        ".tmp-{}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    let tmp = dir.join(tmp_name);

    let file = OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(|e| io_error(path, e))?;
    // from here on, dropping the staged file removes it
    let staged = Staged {
        tmp,
        path: path.to_path_buf(),
        dir,
        committed: false,
    };
    let mut w = BufWriter::with_capacity(BUF_CAPACITY, file);
    let synced = body(&mut w)
        .and_then(|()| w.into_inner().map_err(|e| e.into_error()))
        .and_then(|file| if sync { file.sync_all() } else { Ok(()) });
    synced.map_err(|e| io_error(path, e))?;
    Ok(staged)
}

impl Staged {
    /// Renames the file over its target and syncs the folder.
    pub fn commit(mut self) -> Result<(), IoError> {
        std::fs::rename(&self.tmp, &self.path).map_err(|e| io_error(&self.path, e))?;
        self.committed = true;
        sync_dir(&self.dir).map_err(|e| io_error(&self.path, e))
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        if !self.committed {
            // best effort: the error that dropped it is what matters
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Makes the rename durable (a no-op where folders cannot be opened as files).
#[cfg(unix)]
fn sync_dir(dir: &Path) -> std::io::Result<()> {
    File::open(dir)?.sync_all()
}

#[cfg(not(unix))]
fn sync_dir(_dir: &Path) -> std::io::Result<()> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp-"))
            .collect()
    }

    #[test]
    fn writes_and_replaces() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("out.json");
        write_atomic(&p, b"first").unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
        assert!(leftovers(d.path()).is_empty());
    }

    #[test]
    fn unsynced_writes_replace_by_a_rename_too() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("pic.png");
        write_unsynced(&p, b"first").unwrap();
        write_unsynced(&p, b"second").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
        assert!(leftovers(d.path()).is_empty());
        let err = write_unsynced(&d.path().join("no/such/folder.png"), b"x").unwrap_err();
        assert!(err.to_string().contains("folder.png"), "{err}");
    }

    #[test]
    fn failing_body_leaves_old_file_and_no_temp() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("out.txt");
        write_atomic(&p, b"old").unwrap();
        let err = write_with(&p, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(matches!(err, IoError::Io { .. }));
        assert!(err.to_string().contains("out.txt"), "{err}");
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert!(leftovers(d.path()).is_empty());
    }

    #[test]
    fn a_staged_file_appears_only_when_committed_and_is_removed_when_dropped() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("pic.png");
        let staged = stage(&p, b"later").unwrap();
        assert!(!p.exists());
        assert_eq!(leftovers(d.path()).len(), 1);
        staged.commit().unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"later");
        assert!(leftovers(d.path()).is_empty());
        drop(stage(&p, b"never").unwrap());
        assert_eq!(std::fs::read(&p).unwrap(), b"later");
        assert!(leftovers(d.path()).is_empty());
    }

    #[test]
    fn missing_folder_is_an_io_error_naming_the_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("no/such/dir/out.obj");
        let err = write_atomic(&p, b"x").unwrap_err();
        assert!(matches!(err, IoError::Io { .. }));
        assert!(err.to_string().contains("out.obj"));
    }

    #[test]
    fn rename_onto_a_directory_fails_cleanly() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("target");
        std::fs::create_dir(&p).unwrap();
        std::fs::write(p.join("keep"), b"k").unwrap();
        assert!(write_atomic(&p, b"x").is_err());
        assert!(leftovers(d.path()).is_empty());
        assert!(p.join("keep").exists());
    }
}
