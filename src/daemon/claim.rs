//! Claiming files, the per-daemon processing folder, the attempt counter and the
//! recovery of files a dead daemon left behind.
//!
//! Every daemon owns `INBOX/.processing/HOST-PID/` (same filesystem as the inbox) and
//! `OUTBOX/.holefill-tmp/HOST-PID/` (same filesystem as the outbox). Nobody else creates
//! entries in them, so a claim is one `rename(INBOX/NAME, MINE/NAME)` after checking
//! that `MINE/NAME` is free: the rename is atomic, and when two daemons race for the
//! same file exactly one rename succeeds (the other sees `ENOENT`).
//!
//! Beside each claimed file is `.NAME.holefill.json` (the sidecar): how many attempts
//! were started and when the file was received. A daemon that finds the folder of a
//! dead daemon (same host, its pid gone, a zombie, or reused by another program) moves
//! the files (and sidecars) into its own folder with the same atomic rename, so a
//! file is recovered by exactly one daemon, and the attempt that died counts.

use super::fsops;
use serde::{Deserialize, Serialize};
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// Who this daemon is.
#[derive(Clone, Debug)]
pub struct Identity {
    pub host: String,
    pub pid: u32,
}

impl Identity {
    /// This process.
    pub fn current() -> Identity {
        let host = hostname::get()
            .ok()
            .and_then(|h| h.into_string().ok())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "localhost".to_string());
        // a host name never holds '/', but be safe in a path
        let host = host.replace('/', "_");
        Identity {
            host,
            pid: std::process::id(),
        }
    }
    /// `HOST-PID`, the name of this daemon's folders.
    pub fn tag(&self) -> String {
        format!("{}-{}", self.host, self.pid)
    }
}

/// Parses a folder name `HOST-PID`.
pub fn parse_tag(tag: &str) -> Option<(&str, u32)> {
    let i = tag.rfind('-')?;
    let pid = tag[i + 1..].parse().ok()?;
    Some((&tag[..i], pid))
}

/// The daemon's folders.
#[derive(Clone, Debug)]
pub struct Layout {
    pub inbox: PathBuf,
    pub outbox: PathBuf,
    pub failed: PathBuf,
    pub archive: PathBuf,
    /// `INBOX/.processing`
    pub processing_root: PathBuf,
    /// `INBOX/.processing/HOST-PID`
    pub mine: PathBuf,
    /// `OUTBOX/.holefill-tmp`
    pub tmp_root: PathBuf,
    /// `OUTBOX/.holefill-tmp/HOST-PID`
    pub tmp: PathBuf,
}

impl Layout {
    /// Creates the folders (and parents) if missing and makes the paths absolute.
    pub fn create(
        inbox: &Path,
        outbox: &Path,
        failed: &Path,
        archive: &Path,
        id: &Identity,
    ) -> io::Result<Layout> {
        let abs = |p: &Path| -> io::Result<PathBuf> {
            fs::create_dir_all(p)
                .map_err(|e| io::Error::new(e.kind(), format!("{}: {e}", p.display())))?;
            fs::canonicalize(p)
        };
        let inbox = abs(inbox)?;
        let outbox = abs(outbox)?;
        let failed = abs(failed)?;
        let archive = abs(archive)?;
        let processing_root = inbox.join(".processing");
        let mine = processing_root.join(id.tag());
        let tmp_root = outbox.join(".holefill-tmp");
        let tmp = tmp_root.join(id.tag());
        fs::create_dir_all(&mine)?;
        fs::create_dir_all(&tmp)?;
        Ok(Layout {
            inbox,
            outbox,
            failed,
            archive,
            processing_root,
            mine,
            tmp_root,
            tmp,
        })
    }

    /// The sidecar of a claimed file.
    pub fn sidecar(&self, name: &str) -> PathBuf {
        sidecar_in(&self.mine, name)
    }
}

fn sidecar_in(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!(".{name}.holefill.json"))
}

/// What the daemon remembers about a claimed file across crashes.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Sidecar {
    /// Attempts started (including the one running).
    pub attempts: u32,
    /// When the file was first seen in the inbox (RFC 3339).
    pub received: String,
}

impl Sidecar {
    /// Reads a sidecar; `None` when missing or unreadable.
    pub fn read(path: &Path) -> Option<Sidecar> {
        fs::read(path)
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
    }
    /// Writes it durably (temporary file, fsync, rename).
    pub fn write(&self, path: &Path) -> io::Result<()> {
        let bytes = serde_json::to_vec(self).map_err(io::Error::other)?;
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".tmp");
        let tmp = PathBuf::from(tmp);
        {
            use std::io::Write;
            let mut f = fs::File::create(&tmp)?;
            f.write_all(&bytes)?;
            f.sync_all()?;
        }
        fs::rename(&tmp, path)
    }
}

/// True for names the daemon takes: `.obj .ply .stl .off` (any case), not a dot-file,
/// not `*.part`, `*.tmp`, `*~`.
pub fn is_candidate_name(name: &str) -> bool {
    if name.starts_with('.') || name.ends_with('~') {
        return false;
    }
    let lower = name.to_ascii_lowercase();
    if lower.ends_with(".part") || lower.ends_with(".tmp") {
        return false;
    }
    [".obj", ".ply", ".stl", ".off"]
        .iter()
        .any(|e| lower.ends_with(e) && lower.len() > e.len())
}

/// Claims `INBOX/name` into this daemon's folder. `Ok(None)` when the file is gone
/// (another daemon took it) or a file of that name is already ours.
pub fn claim(layout: &Layout, name: &str) -> io::Result<Option<PathBuf>> {
    let dst = layout.mine.join(name);
    if fs::symlink_metadata(&dst).is_ok() {
        return Ok(None);
    }
    match fs::rename(layout.inbox.join(name), &dst) {
        Ok(()) => Ok(Some(dst)),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e),
    }
}

/// Puts a claimed file back into the inbox (never over a file of the same name: then
/// under the collision rule's next name), drops its sidecar. Returns the name it got.
pub fn put_back(layout: &Layout, name: &str) -> io::Result<String> {
    let src = layout.mine.join(name);
    let dst = fsops::move_into(&src, &layout.inbox, name, &[])?;
    let _ = fs::remove_file(layout.sidecar(name));
    let _ = fsops::fsync_dir(&layout.inbox);
    let _ = fsops::fsync_dir(&layout.mine);
    Ok(dst
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| name.to_string()))
}

/// Liveness of a daemon of this host: its pid exists, is not a zombie, and runs the
/// same program as we do (`/proc/PID/comm`), so that a reused pid counts as dead.
/// Without `/proc` every daemon counts as alive (nothing is taken).
pub fn is_alive(pid: u32) -> bool {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return true;
    }
    let dir = proc.join(pid.to_string());
    let Ok(stat) = fs::read_to_string(dir.join("stat")) else {
        return false;
    };
    // "pid (comm) S ..." : the state follows the last ')'
    if let Some(i) = stat.rfind(')') {
        let state = stat[i + 1..].trim_start().chars().next();
        if matches!(state, Some('Z') | Some('X')) {
            return false;
        }
    }
    match (
        fs::read_to_string(dir.join("comm")),
        fs::read_to_string(proc.join("self/comm")),
    ) {
        (Ok(theirs), Ok(ours)) => theirs.trim() == ours.trim(),
        _ => true,
    }
}

/// A file recovered from a dead daemon's folder, now in ours.
#[derive(Clone, Debug)]
pub struct Recovered {
    pub name: String,
    pub sidecar: Sidecar,
    /// The dead daemon had already published its model and log under this outbox name
    /// (it died before archiving the original): nothing to repair again.
    pub published: Option<String>,
}

/// What a dead daemon had published of `name`. Its worker's model stays linked in the
/// daemon's temporary folder until the original is archived, so an outbox file with the
/// same inode is its output: complete when its log is there too (`Some(name)`), else a
/// partial publish, which is withdrawn (`None`: repair again).
fn published(layout: &Layout, tmp_dir: &Path, name: &str) -> Option<String> {
    use std::os::unix::fs::MetadataExt;
    let m = fs::metadata(tmp_dir.join(name)).ok()?;
    if m.nlink() < 2 {
        return None;
    }
    for e in fs::read_dir(&layout.outbox).ok()?.flatten() {
        let n = e.file_name().to_string_lossy().into_owned();
        if n.ends_with(".repair.json") {
            continue;
        }
        let Ok(om) = e.metadata() else { continue };
        if om.dev() == m.dev() && om.ino() == m.ino() {
            if n.starts_with('.') {
                let _ = fs::remove_file(e.path()); // an overwrite's temporary link
                continue;
            }
            if layout.outbox.join(format!("{n}.repair.json")).exists() {
                return Some(n);
            }
            let _ = fs::remove_file(e.path());
            let _ = fsops::fsync_dir(&layout.outbox);
            return None;
        }
    }
    None
}

/// Takes over the files of dead daemons of this host (and of an earlier daemon with
/// our own pid, which cannot be alive since we are). Removes their temporary output
/// folders. Returns the files now in our folder, with their sidecars. With `startup`,
/// the files already in our own folder (left by an earlier daemon with our pid) are
/// listed too.
pub fn recover(layout: &Layout, id: &Identity, startup: bool) -> Vec<Recovered> {
    let mut out = Vec::new();
    let Ok(rd) = fs::read_dir(&layout.processing_root) else {
        return out;
    };
    // our own folder first, before the files of dead daemons are moved into it
    let mut tags: Vec<String> = rd
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    tags.sort_by_key(|t| *t != id.tag());
    for tag in tags {
        let Some((host, pid)) = parse_tag(&tag) else {
            continue;
        };
        if host != id.host {
            continue; // another machine: its liveness cannot be checked from here
        }
        let dir = layout.processing_root.join(&tag);
        let ours = pid == id.pid;
        if (ours && !startup) || (!ours && is_alive(pid)) {
            continue;
        }
        let Ok(files) = fs::read_dir(&dir) else {
            continue;
        };
        for f in files.flatten() {
            let name = f.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') || !f.file_type().map(|t| t.is_file()).unwrap_or(false) {
                continue;
            }
            let src = f.path();
            let old_sidecar = sidecar_in(&dir, &name);
            // died between link and unlink of a put-back: the inbox already has it
            if let (Ok(a), Ok(b)) = (fs::metadata(&src), fs::metadata(layout.inbox.join(&name))) {
                use std::os::unix::fs::MetadataExt;
                if a.dev() == b.dev() && a.ino() == b.ino() {
                    let _ = fs::remove_file(&src);
                    let _ = fs::remove_file(&old_sidecar);
                    continue;
                }
            }
            let sidecar = Sidecar::read(&old_sidecar).unwrap_or_else(|| Sidecar {
                attempts: 1,
                received: fsops::rfc3339(
                    f.metadata()
                        .and_then(|m| m.modified())
                        .unwrap_or_else(|_| SystemTime::now()),
                ),
            });
            if !ours {
                let dst = layout.mine.join(&name);
                if fs::symlink_metadata(&dst).is_ok() {
                    continue; // a file of that name is ours already: take it on a later pass
                }
                if fs::rename(&src, &dst).is_err() {
                    continue; // another daemon recovered it first
                }
            }
            let _ = sidecar.write(&layout.sidecar(&name));
            if !ours {
                let _ = fs::remove_file(&old_sidecar);
            }
            let tmp_dir = layout.tmp_root.join(&tag);
            let published = published(layout, &tmp_dir, &name);
            out.push(Recovered {
                name,
                sidecar,
                published,
            });
        }
        if !ours {
            // leftover sidecars (their files were put back or finished), then the folder
            if let Ok(rest) = fs::read_dir(&dir) {
                for f in rest.flatten() {
                    let n = f.file_name().to_string_lossy().into_owned();
                    if n.starts_with('.') && (n.ends_with(".holefill.json") || n.ends_with(".tmp"))
                    {
                        let _ = fs::remove_file(f.path());
                    }
                }
            }
            let _ = fs::remove_dir(&dir);
            let _ = fs::remove_dir_all(layout.tmp_root.join(&tag));
        }
    }
    let _ = fsops::fsync_dir(&layout.mine);
    out
}

/// Removes the temporary output folders of dead daemons of this host whose processing
/// folder is gone.
pub fn clean_tmp(layout: &Layout, id: &Identity) {
    let Ok(rd) = fs::read_dir(&layout.tmp_root) else {
        return;
    };
    for entry in rd.flatten() {
        let tag = entry.file_name().to_string_lossy().into_owned();
        let Some((host, pid)) = parse_tag(&tag) else {
            continue;
        };
        if host == id.host
            && pid != id.pid
            && !is_alive(pid)
            && !layout.processing_root.join(&tag).exists()
        {
            let _ = fs::remove_dir_all(entry.path());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        for n in ["a.obj", "B.PLY", "x.y.Stl", "scan 01.off"] {
            assert!(is_candidate_name(n), "{n}");
        }
        for n in [
            ".a.obj",
            "a.obj.part",
            "a.obj.tmp",
            "a.obj~",
            "a.txt",
            ".obj",
            "a.objx",
            "a.TMP",
        ] {
            assert!(!is_candidate_name(n), "{n}");
        }
    }

    #[test]
    fn tags() {
        assert_eq!(parse_tag("my-host-123"), Some(("my-host", 123)));
        assert_eq!(parse_tag("host"), None);
        assert_eq!(parse_tag("host-x"), None);
    }

    #[test]
    fn liveness() {
        assert!(is_alive(std::process::id()));
        // pid 1 runs another program than this test binary
        assert!(
            !is_alive(1)
                || fs::read_to_string("/proc/1/comm")
                    .map(|c| c.contains("holefill"))
                    .unwrap_or(true)
        );
        assert!(!is_alive(u32::MAX - 1));
    }

    fn layout(d: &Path, id: &Identity) -> Layout {
        Layout::create(
            &d.join("in"),
            &d.join("out"),
            &d.join("failed"),
            &d.join("archive"),
            id,
        )
        .unwrap()
    }

    #[test]
    fn claim_is_exclusive_and_put_back_never_overwrites() {
        let d = tempfile::tempdir().unwrap();
        let a = Identity {
            host: "h".into(),
            pid: 10,
        };
        let b = Identity {
            host: "h".into(),
            pid: 11,
        };
        let la = layout(d.path(), &a);
        let lb = layout(d.path(), &b);
        fs::write(la.inbox.join("s.obj"), "1").unwrap();
        assert!(claim(&la, "s.obj").unwrap().is_some());
        assert!(claim(&lb, "s.obj").unwrap().is_none());
        // a new file of the same name arrives while ours is claimed
        fs::write(la.inbox.join("s.obj"), "2").unwrap();
        assert!(
            claim(&la, "s.obj").unwrap().is_none(),
            "never over our own claimed file"
        );
        let back = put_back(&la, "s.obj").unwrap();
        assert_ne!(back, "s.obj");
        assert_eq!(fs::read_to_string(la.inbox.join("s.obj")).unwrap(), "2");
        assert_eq!(fs::read_to_string(la.inbox.join(&back)).unwrap(), "1");
    }

    #[test]
    fn recovery_takes_dead_folders_once_and_counts_attempts() {
        let d = tempfile::tempdir().unwrap();
        let me = Identity {
            host: "h".into(),
            pid: std::process::id(),
        };
        // a dead daemon of this host (pid that does not exist), one of another host
        let dead = Identity {
            host: "h".into(),
            pid: u32::MAX - 1,
        };
        let other_host = Identity {
            host: "elsewhere".into(),
            pid: 1,
        };
        let ld = layout(d.path(), &dead);
        let lo = layout(d.path(), &other_host);
        fs::write(ld.mine.join("a.obj"), "a").unwrap();
        Sidecar {
            attempts: 2,
            received: "2026-01-01T00:00:00.000Z".into(),
        }
        .write(&ld.sidecar("a.obj"))
        .unwrap();
        fs::write(ld.mine.join("b.obj"), "b").unwrap(); // no sidecar: one attempt
        fs::write(lo.mine.join("c.obj"), "c").unwrap();
        let lm = layout(d.path(), &me);
        let mut r = recover(&lm, &me, true);
        r.sort_by(|x, y| x.name.cmp(&y.name));
        assert_eq!(r.len(), 2);
        assert_eq!((r[0].name.as_str(), r[0].sidecar.attempts), ("a.obj", 2));
        assert_eq!((r[1].name.as_str(), r[1].sidecar.attempts), ("b.obj", 1));
        assert!(lm.mine.join("a.obj").exists() && lm.mine.join("b.obj").exists());
        assert!(!ld.mine.exists(), "the dead folder is removed");
        assert!(!ld.tmp.exists(), "the dead tmp folder is removed");
        assert!(
            lo.mine.join("c.obj").exists(),
            "another host's folder is left alone"
        );
        assert_eq!(Sidecar::read(&lm.sidecar("a.obj")).unwrap().attempts, 2);
        // nothing more the second time
        assert_eq!(
            recover(&lm, &me, false).len(),
            0,
            "a running daemon never re-takes its own files"
        );
    }
}
