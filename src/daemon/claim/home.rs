//! A processing folder and its lock (liveness): created, adopted from a daemon that
//! died, removed when empty; the staging and temporary folders tidied.

use super::layout::{check_private, Layout};
use crate::daemon::fsops::{self, FileId};
use std::fs;
use std::io;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// A processing folder with its lock held: this daemon's, or one adopted from a daemon
/// that died.
#[derive(Debug)]
pub struct Home {
    pub tag: String,
    /// `INBOX/.processing/TAG`
    pub dir: PathBuf,
    /// `OUTBOX/.holefill-tmp/TAG`
    pub tmp: PathBuf,
    lock: fs::File,
}

fn open_lock(path: &Path, create: bool) -> io::Result<fs::File> {
    let mut o = fs::OpenOptions::new();
    o.read(true).custom_flags(libc::O_NOFOLLOW);
    if create {
        o.write(true).create_new(true).mode(0o600);
    }
    o.open(path)
}

fn try_lock(f: &fs::File) -> io::Result<bool> {
    use rustix::fs::{flock, FlockOperation};
    match flock(f, FlockOperation::NonBlockingLockExclusive) {
        Ok(()) => Ok(true),
        Err(rustix::io::Errno::WOULDBLOCK) => Ok(false),
        Err(e) => Err(e.into()),
    }
}

impl Home {
    /// Creates this daemon's folder, its lock held, and its temporary output folder.
    pub fn create(layout: &Layout, tag: &str) -> io::Result<Home> {
        let staging = layout.processing_root.join(format!(".new-{tag}"));
        fs::DirBuilder::new().mode(0o700).create(&staging)?;
        let lock = open_lock(&staging.join(".lock"), true)?;
        if !try_lock(&lock)? {
            return Err(io::Error::other("cannot lock a new folder"));
        }
        let dir = layout.processing_root.join(tag);
        fsops::rename_noreplace(&staging, &dir)?;
        fsops::fsync_dir(&layout.processing_root)?;
        let tmp = layout.tmp_root.join(tag);
        match fs::DirBuilder::new().mode(0o700).create(&tmp) {
            Err(e) if e.kind() != io::ErrorKind::AlreadyExists => return Err(e),
            _ => {}
        }
        Ok(Home {
            tag: tag.to_string(),
            dir,
            tmp,
            lock,
        })
    }

    /// Takes over the folder `tag` when its daemon is gone (its lock is free).
    /// `Ok(None)`: alive (or just taken by another daemon). `Err`: a folder that is not
    /// holefill's (wrong owner or mode), never touched.
    pub fn adopt(layout: &Layout, tag: &str) -> Result<Option<Home>, String> {
        let dir = layout.processing_root.join(tag);
        check_private(&dir)?;
        let lock_path = dir.join(".lock");
        let lock = match open_lock(&lock_path, false) {
            Ok(f) => f,
            // a folder of an older holefill, without a lock file: lock it with one
            Err(e) if e.kind() == io::ErrorKind::NotFound => match open_lock(&lock_path, true) {
                Ok(f) => f,
                Err(_) => return Ok(None),
            },
            Err(e) => return Err(format!("{}: {e}", lock_path.display())),
        };
        match try_lock(&lock) {
            Ok(true) => {}
            Ok(false) => return Ok(None),
            Err(e) => return Err(format!("{}: {e}", lock_path.display())),
        }
        // its previous adopter may have finished and removed it after our open
        let held = lock.metadata().ok().map(|m| FileId::of(&m));
        if held.is_none() || FileId::lstat(&lock_path) != held {
            return Ok(None);
        }
        Ok(Some(Home {
            tag: tag.to_string(),
            tmp: layout.tmp_root.join(tag),
            dir,
            lock,
        }))
    }

    /// True while the folder is there with our lock in it (false once someone removed
    /// the inbox or the folder).
    pub fn intact(&self) -> bool {
        let held = self.lock.metadata().ok().map(|m| FileId::of(&m));
        held.is_some() && FileId::lstat(&self.dir.join(".lock")) == held
    }

    /// Removes the folder (with the lock file) when nothing but records of finished
    /// jobs is left, and the temporary output folder. False when files remain.
    pub fn remove_if_empty(&self) -> bool {
        if let Ok(rd) = fs::read_dir(&self.dir) {
            for e in rd.flatten() {
                let n = e.file_name();
                let n = n.as_bytes();
                if n == b".lock" || n.ends_with(b".json.tmp") {
                    continue;
                }
                return false;
            }
        }
        let _ = fs::remove_dir_all(&self.tmp);
        if let Ok(rd) = fs::read_dir(&self.dir) {
            for e in rd.flatten() {
                let _ = fs::remove_file(e.path());
            }
        }
        fs::remove_dir(&self.dir).is_ok()
    }
}

/// Removes `.processing/.new-TAG` folders left by daemons that died while creating
/// their folder (their lock is free).
pub fn clean_staging(layout: &Layout) {
    let Ok(rd) = fs::read_dir(&layout.processing_root) else {
        return;
    };
    for e in rd.flatten() {
        let n = e.file_name();
        if !n.as_bytes().starts_with(b".new-") || check_private(&e.path()).is_err() {
            continue;
        }
        let Ok(lock) = open_lock(&e.path().join(".lock"), false) else {
            continue;
        };
        if let Ok(true) = try_lock(&lock) {
            let _ = fs::remove_file(e.path().join(".lock"));
            let _ = fs::remove_dir(e.path());
        }
    }
}

/// Removes the temporary output folders whose processing folder is gone (its daemon
/// stopped, or its files were finished by an adopter).
pub fn clean_tmp(layout: &Layout) {
    let Ok(rd) = fs::read_dir(&layout.tmp_root) else {
        return;
    };
    for e in rd.flatten() {
        let tag = e.file_name();
        if !layout.processing_root.join(&tag).exists() && check_private(&e.path()).is_ok() {
            let _ = fs::remove_dir_all(e.path());
        }
    }
}
