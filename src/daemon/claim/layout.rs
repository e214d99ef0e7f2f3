//! The folders: resolved, refused when two are the same or one is inside the inbox
//! (by path and by device and inode), and checked to be private to the daemon.

use crate::daemon::fsops::FileId;
use std::fs;
use std::io;
use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Component, Path, PathBuf};

/// The daemon's folders (absolute, symlinks resolved).
#[derive(Clone, Debug)]
pub struct Layout {
    pub inbox: PathBuf,
    pub outbox: PathBuf,
    pub failed: PathBuf,
    pub archive: PathBuf,
    /// `INBOX/.processing`
    pub processing_root: PathBuf,
    /// `OUTBOX/.holefill-tmp`
    pub tmp_root: PathBuf,
    /// `INBOX/.processing/.attempts`
    pub ledger: PathBuf,
}

/// `p` made absolute with its longest existing ancestor's symlinks resolved (the part
/// that does not exist yet is appended, `..` folded).
pub fn resolve(p: &Path) -> io::Result<PathBuf> {
    let abs = if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir()?.join(p)
    };
    let comps: Vec<Component> = abs.components().collect();
    for k in (1..=comps.len()).rev() {
        let prefix: PathBuf = comps[..k].iter().collect();
        if let Ok(mut c) = fs::canonicalize(&prefix) {
            for comp in &comps[k..] {
                match comp {
                    Component::ParentDir => {
                        c.pop();
                    }
                    Component::Normal(n) => c.push(n),
                    _ => {}
                }
            }
            return Ok(c);
        }
    }
    Err(io::Error::new(
        io::ErrorKind::NotFound,
        format!("{}: cannot be resolved", p.display()),
    ))
}

/// Refuses folders that are the same or nested with the inbox, by resolved path.
fn check_paths(f: &[(&str, &Path)]) -> Result<(), String> {
    for (i, (a, pa)) in f.iter().enumerate() {
        for (b, pb) in f.iter().skip(i + 1) {
            if pa == pb {
                return Err(format!(
                    "the {a} and the {b} are the same folder ({}): give each its own folder, none inside the inbox",
                    pa.display()
                ));
            }
        }
    }
    let inbox = f[0].1;
    for (b, pb) in &f[1..] {
        if pb.starts_with(inbox) {
            return Err(format!(
                "the {b} ({}) is inside the inbox ({}): the daemon would take its own output as input; give each its own folder, none inside the inbox",
                pb.display(),
                inbox.display()
            ));
        }
        if inbox.starts_with(pb) {
            return Err(format!(
                "the inbox ({}) is inside the {b} ({}): give each its own folder, none inside another",
                inbox.display(),
                pb.display()
            ));
        }
    }
    Ok(())
}

/// The same checks by device and inode, once the folders exist: catches bind mounts
/// and anything else the paths do not tell.
fn check_ids(f: &[(&str, &Path)]) -> Result<(), String> {
    let id = |p: &Path| fs::metadata(p).ok().map(|m| FileId::of(&m));
    let ancestors = |p: &Path| -> Vec<FileId> { p.ancestors().skip(1).filter_map(id).collect() };
    let ids: Vec<Option<FileId>> = f.iter().map(|(_, p)| id(p)).collect();
    for (i, (a, pa)) in f.iter().enumerate() {
        for (j, (b, pb)) in f.iter().enumerate().skip(i + 1) {
            if ids[i].is_some() && ids[i] == ids[j] {
                return Err(format!(
                    "the {a} ({}) and the {b} ({}) are the same folder (a bind mount?): give each its own folder, none inside the inbox",
                    pa.display(),
                    pb.display()
                ));
            }
        }
    }
    let (inbox_name, inbox) = f[0];
    let _ = inbox_name;
    let Some(inbox_id) = ids[0] else {
        return Ok(());
    };
    for (j, (b, pb)) in f.iter().enumerate().skip(1) {
        if ancestors(pb).contains(&inbox_id) {
            return Err(format!(
                "the {b} ({}) is inside the inbox ({}): the daemon would take its own output as input",
                pb.display(),
                inbox.display()
            ));
        }
        if let Some(bid) = ids[j] {
            if ancestors(inbox).contains(&bid) {
                return Err(format!(
                    "the inbox ({}) is inside the {b} ({})",
                    inbox.display(),
                    pb.display()
                ));
            }
        }
    }
    Ok(())
}

/// Ok when `path` is a real folder (not a symlink) of the daemon's user that nobody
/// else may write into; else why not.
pub fn check_private(path: &Path) -> Result<(), String> {
    let m = fs::symlink_metadata(path).map_err(|e| format!("{}: {e}", path.display()))?;
    if !m.file_type().is_dir() {
        return Err(format!(
            "{} is not a folder (a symbolic link or a file?)",
            path.display()
        ));
    }
    let me = rustix::process::geteuid().as_raw();
    if m.uid() != me {
        return Err(format!(
            "{} belongs to uid {}, not to the daemon's user (uid {me}): it was not made by holefill",
            path.display(),
            m.uid()
        ));
    }
    if m.mode() & 0o022 != 0 {
        return Err(format!(
            "{} may be written by others (mode {:o}): it was not made by holefill",
            path.display(),
            m.mode() & 0o7777
        ));
    }
    Ok(())
}

impl Layout {
    /// Resolves the folders, refuses aliases (see the module documentation), creates
    /// the missing ones and the shared private folders, and checks those.
    pub fn create(
        inbox: &Path,
        outbox: &Path,
        failed: &Path,
        archive: &Path,
    ) -> Result<Layout, String> {
        let r = |what: &str, p: &Path| resolve(p).map_err(|e| format!("the {what}: {e}"));
        let l = Layout::with(
            r("inbox", inbox)?,
            r("outbox", outbox)?,
            r("failed folder", failed)?,
            r("archive", archive)?,
        );
        check_paths(&l.named())?;
        for (what, p) in l.named() {
            fs::create_dir_all(p)
                .map_err(|e| format!("cannot create the {what} {}: {e}", p.display()))?;
        }
        // created through symlinks that appeared meanwhile? compare again
        let again = Layout::with(
            r("inbox", &l.inbox)?,
            r("outbox", &l.outbox)?,
            r("failed folder", &l.failed)?,
            r("archive", &l.archive)?,
        );
        check_paths(&again.named())?;
        check_ids(&again.named())?;
        for p in [&again.processing_root, &again.tmp_root] {
            make_private_dir(p, 0o755)?;
        }
        Ok(again)
    }

    fn with(inbox: PathBuf, outbox: PathBuf, failed: PathBuf, archive: PathBuf) -> Layout {
        Layout {
            processing_root: inbox.join(".processing"),
            tmp_root: outbox.join(".holefill-tmp"),
            ledger: inbox.join(".processing").join(".attempts"),
            inbox,
            outbox,
            failed,
            archive,
        }
    }

    /// The four folders with what they are called in messages.
    pub fn named(&self) -> [(&'static str, &Path); 4] {
        [
            ("inbox", &self.inbox),
            ("outbox", &self.outbox),
            ("failed folder", &self.failed),
            ("archive", &self.archive),
        ]
    }

    /// The device-and-inode check of [`Layout::create`], for the running daemon (a
    /// folder replaced by a link to the inbox).
    pub fn check_aliases(&self) -> Result<(), String> {
        check_ids(&self.named())
    }
}

/// Creates `p` (one level) with `mode` if missing, then checks it is private.
pub fn make_private_dir(p: &Path, mode: u32) -> Result<(), String> {
    match fs::DirBuilder::new().mode(mode).create(p) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(format!("cannot create {}: {e}", p.display())),
    }
    check_private(p)
}
