//! The folders, the claim, the job records, the put-back ledger, and the adoption of
//! the files of daemons that died.
//!
//! **Folders.** The inbox, outbox, failed and archive folders are resolved (absolute,
//! symlinks resolved) and refused when two are the same or the inbox is inside another
//! or another inside the inbox, compared by path and by device and inode (a symlink or
//! a bind mount to the inbox is the inbox). Each daemon owns `INBOX/.processing/TAG/`
//! (same file system as the inbox) and `OUTBOX/.holefill-tmp/TAG/` (same file system as
//! the outbox), `TAG` = `HOST-PID-RANDOM`, a fresh random instance id at every start.
//! `.processing` and the daemon's folders must belong to the daemon's user and not be
//! writable by others; a folder that is not is never used or taken over.
//!
//! **Liveness** is a lock: the daemon holds `flock(LOCK_EX)` on `TAG/.lock` for its
//! whole life (the folder is created under a temporary name with its lock held, then
//! renamed into place, so a visible folder always has its lock). A daemon that can
//! take another folder's lock knows its owner is gone (dead, whatever PID namespace or
//! container it ran in: the kernel drops the lock with the process) and adopts the
//! folder: it keeps the lock while it finishes the files there, in place, so a second
//! daemon cannot take them too; if it dies in turn, the lock is free again.
//!
//! **Claim.** A file is claimed under a short job id (`INSTANCE-N`): first its record
//! `ID.json` (name, attempts, the identity, size and modification time judged in the
//! inbox), then `renameat2(INBOX/NAME, TAG/ID, RENAME_NOREPLACE)`. The rename is
//! atomic: when two daemons race for a file exactly one wins, the other gets "no such
//! file" and drops its record. Every temporary name derives from the id, never from
//! the file's name, so none exceeds the file system's limit whatever the name.
//!
//! **Records** (`ID.json`) say where a file is in its handling (`claimed`, `repaired`
//! with the output and archive names chosen and the identities of the model and log
//! files, or `failed` with the failed folder's name and the reason), so that a daemon
//! resuming the job after a crash redoes only what is missing and never repairs a
//! published file twice.
//!
//! **Ledger.** A file put back into the inbox (shutdown, retryable failure) leaves
//! `.processing/.attempts/DEV-INO.json` with its failed attempts and first-seen time;
//! the next claim of the same inode (same size and modification time) resumes the
//! count, so a file that kills its worker cannot loop through restarts.

use super::fsops::{self, FileId, Stamp};
use super::sets::{Member, SetRec};
use serde::{Deserialize, Serialize};
use std::ffi::{OsStr, OsString};
use std::fs;
use std::io;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, SystemTime};

/// Who this daemon is: host and pid for people reading folder names and logs, the
/// random instance id for uniqueness.
#[derive(Debug)]
pub struct Identity {
    pub host: String,
    pub pid: u32,
    pub instance: String,
    next: AtomicU64,
}

impl Identity {
    /// This process, with a fresh instance id.
    pub fn current() -> Identity {
        let host = hostname::get()
            .ok()
            .and_then(|h| h.into_string().ok())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "localhost".to_string());
        // a host name never holds '/', but be safe in a path; keep it short
        let host: String = host
            .chars()
            .map(|c| if c == '/' || c.is_control() { '_' } else { c })
            .take(64)
            .collect();
        Identity {
            host,
            pid: std::process::id(),
            instance: format!("{:016x}", rand::random::<u64>()),
            next: AtomicU64::new(1),
        }
    }
    /// `HOST-PID-INSTANCE`, the name of this daemon's folders.
    pub fn tag(&self) -> String {
        format!("{}-{}-{}", self.host, self.pid, self.instance)
    }
    /// A new job id, unique among all daemons' (`INSTANCE-N`).
    pub fn next_id(&self) -> String {
        format!(
            "{}-{}",
            self.instance,
            self.next.fetch_add(1, Ordering::Relaxed)
        )
    }
}

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

/// Where a claimed file is in its handling.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Phase {
    /// Claimed; to be repaired.
    #[default]
    Claimed,
    /// Repaired: the model goes to `OUTBOX/output`, the original to `ARCHIVE/archive`
    /// (`None`: deleted), then the log to `OUTBOX/output.repair.json`.
    Repaired {
        output: String,
        archive: Option<String>,
        /// The worker's model (in the temporary folder, then the outbox).
        model: FileId,
        /// The final log (in the temporary folder, then the outbox).
        log: FileId,
        code: i32,
        filled: u64,
        skipped: u64,
        failed: u64,
    },
    /// Cannot be repaired: the original goes to `FAILED/dest` (or is removed when it is
    /// not a regular file: `kept` false), then the log to `FAILED/dest.repair.json`.
    Failed {
        dest: String,
        kept: bool,
        stage: String,
        error: String,
        exit: Option<i32>,
    },
}

/// What a daemon knows about a claimed file, across crashes (`ID.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// The name, shown (escaped) for people.
    pub name: String,
    /// The name's bytes in hex (what the daemon reads back).
    pub raw: String,
    /// When the file was first seen in the inbox (RFC 3339).
    pub received: String,
    /// Attempts started (including the running one).
    pub attempts: u32,
    /// Identity, size and modification time when judged complete in the inbox.
    pub stamp: Option<Stamp>,
    #[serde(default)]
    pub phase: Phase,
    /// The other files of its set, claimed beside it (`None`: not a set, or its
    /// references not read yet).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub set: Option<SetRec>,
}

impl Record {
    /// Reads a record; `None` when missing or unreadable.
    pub fn read(path: &Path) -> Option<Record> {
        let f = fsops::open_nofollow(path).ok()?;
        serde_json::from_reader(io::BufReader::new(f)).ok()
    }
    /// Writes it durably (temporary file, fsync, rename).
    pub fn write(&self, path: &Path) -> io::Result<()> {
        write_durably(path, &serde_json::to_vec(self).map_err(io::Error::other)?)
    }
}

/// Writes `bytes` to `path` through `path.tmp` (fsync, rename).
fn write_durably(path: &Path, bytes: &[u8]) -> io::Result<()> {
    use std::io::Write;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let _ = fs::remove_file(&tmp);
    let mut f = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&tmp)?;
    f.write_all(bytes)?;
    f.sync_all()?;
    fs::rename(&tmp, path)
}

/// A claimed file.
#[derive(Clone, Debug)]
pub struct Job {
    /// Its id: its name in the processing folder (`ID`, record `ID.json`) and the stem
    /// of its temporary files.
    pub id: String,
    pub home: Arc<Home>,
    /// Its name in the inbox.
    pub name: OsString,
    /// This attempt's number (1-based).
    pub attempt: u32,
    pub rec: Record,
    /// Claimed by this daemon from the inbox just now (not resumed from a record).
    pub fresh: bool,
    /// When the daemon last logged an error about it (rate limit).
    pub warned: Option<std::time::Instant>,
}

impl Job {
    pub fn path(&self) -> PathBuf {
        self.home.dir.join(&self.id)
    }
    pub fn record_path(&self) -> PathBuf {
        self.home.dir.join(format!("{}.json", self.id))
    }
    /// Where member `i` of its set is kept in the processing folder.
    pub fn member_path(&self, i: usize) -> PathBuf {
        self.home.dir.join(format!("{}.m{i}", self.id))
    }
    /// The members of its set (none for a single file).
    pub fn members(&self) -> &[Member] {
        self.rec.set.as_ref().map_or(&[], |s| &s.members)
    }
    /// A temporary file of this job in its temporary output folder.
    pub fn tmp(&self, suffix: &str) -> PathBuf {
        self.home.tmp.join(format!("{}{suffix}", self.id))
    }
    /// The name as it may be logged.
    pub fn shown(&self) -> String {
        fsops::shown(&self.name)
    }
    /// The name as a string, when it is one the daemon can repair under.
    pub fn name_str(&self) -> Option<&str> {
        fsops::name_problem(&self.name)
            .is_none()
            .then(|| self.name.to_str())
            .flatten()
    }
    /// Writes the record.
    pub fn save(&self) -> io::Result<()> {
        self.rec.write(&self.record_path())
    }
    /// Removes the record (the job is over) and makes that durable.
    pub fn forget(&self) {
        let _ = fs::remove_file(self.record_path());
        let _ = fsops::fsync_dir(&self.home.dir);
    }
}

/// True for names the daemon takes: `.obj .ply .stl .off` (any case), not a dot-file,
/// not `*.part`, `*.tmp`, `*~`. Judged on the bytes: a name that is not UTF-8 or too
/// long is taken too (and goes to the failed folder with the reason).
pub fn is_candidate_name(name: &OsStr) -> bool {
    let b = name.as_bytes();
    if b.starts_with(b".") || b.ends_with(b"~") {
        return false;
    }
    let lower = b.to_ascii_lowercase();
    if lower.ends_with(b".part") || lower.ends_with(b".tmp") {
        return false;
    }
    [&b".obj"[..], b".ply", b".stl", b".off"]
        .iter()
        .any(|e| lower.ends_with(e) && lower.len() > e.len())
}

/// True for the names the daemon keeps track of: the meshes it takes and the files
/// that may join a set (any name that is not a dot-file, `*.part`, `*.tmp` or `*~`).
pub fn is_watched_name(name: &OsStr) -> bool {
    let b = name.as_bytes();
    if b.is_empty() || b.starts_with(b".") || b.ends_with(b"~") {
        return false;
    }
    let lower = b.to_ascii_lowercase();
    !(lower.ends_with(b".part") || lower.ends_with(b".tmp"))
}

/// Claims the members of a set beside its claimed mesh: the record lists them first
/// (durably), then each is renamed in with `renameat2(RENAME_NOREPLACE)` and checked
/// to be the regular file judged complete. `Ok(false)`: one vanished or was swapped
/// meanwhile; the members claimed are back in the inbox and the record has no set.
pub fn claim_members(layout: &Layout, job: &mut Job, set: SetRec) -> io::Result<bool> {
    job.rec.set = Some(set);
    job.save()?;
    let n = job.members().len();
    for i in 0..n {
        let m = job.members()[i].clone();
        let dst = job.member_path(i);
        let r = fsops::rename_noreplace(&layout.inbox.join(&m.name), &dst);
        let ok = match r {
            Ok(()) => {
                fs::symlink_metadata(&dst).is_ok_and(|md| md.is_file() && Stamp::of(&md) == m.stamp)
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => false,
            Err(e) => {
                put_back_members(layout, job);
                return Err(e);
            }
        };
        if !ok {
            put_back_members(layout, job);
            return Ok(false);
        }
    }
    Ok(true)
}

/// Moves the members of a job's set that are in its processing folder back into the
/// inbox (each under its name, or the collision rule's next one), and drops the set
/// from its record. Returns the members that could not be moved back (with why).
pub fn put_back_members(layout: &Layout, job: &mut Job) -> Vec<String> {
    let mut stuck = Vec::new();
    let when = SystemTime::now();
    for (i, m) in job.members().iter().enumerate() {
        let src = job.member_path(i);
        if fs::symlink_metadata(&src).is_err() {
            continue;
        }
        let mut why = Some("no free name".to_string());
        for skip in 0..1000 {
            let cand = fsops::free_name(
                &layout.inbox,
                &m.name,
                &[],
                when,
                super::config::Collision::Timestamp,
                skip,
            );
            match fsops::rename_noreplace(&src, &layout.inbox.join(&cand)) {
                Ok(()) => {
                    why = None;
                    break;
                }
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => {
                    why = Some(e.to_string());
                    break;
                }
            }
        }
        if let Some(why) = why {
            stuck.push(format!("{}: {why}", fsops::shown(m.name.as_ref())));
        }
    }
    let _ = fsops::fsync_dir(&layout.inbox);
    if stuck.is_empty() {
        job.rec.set = None;
        if let Err(e) = job.save() {
            tracing::warn!(file = %job.shown(), "cannot record the set's put-back: {e}");
        }
    }
    stuck
}

/// An entry of the put-back ledger.
#[derive(Debug, Serialize, Deserialize)]
struct Ledger {
    attempts: u32,
    received: String,
    size: u64,
    mtime_ns: i128,
}

fn ledger_path(layout: &Layout, id: FileId) -> PathBuf {
    layout.ledger.join(format!("{}-{}.json", id.dev, id.ino))
}

/// The failed attempts and first-seen time of a file put back earlier (same inode,
/// size and modification time).
fn ledger_get(layout: &Layout, s: &Stamp) -> Option<(u32, String)> {
    if check_private(&layout.ledger).is_err() {
        return None;
    }
    let f = fsops::open_nofollow(&ledger_path(layout, s.id)).ok()?;
    let l: Ledger = serde_json::from_reader(io::BufReader::new(f)).ok()?;
    (l.size == s.size && l.mtime_ns == s.mtime_ns).then_some((l.attempts, l.received))
}

fn ledger_put(layout: &Layout, s: &Stamp, attempts: u32, received: &str) -> Result<(), String> {
    make_private_dir(&layout.ledger, 0o700)?;
    let l = Ledger {
        attempts,
        received: received.to_string(),
        size: s.size,
        mtime_ns: s.mtime_ns,
    };
    let bytes = serde_json::to_vec(&l).map_err(|e| e.to_string())?;
    write_durably(&ledger_path(layout, s.id), &bytes).map_err(|e| e.to_string())
}

/// Drops ledger entries of files no longer in the inbox (older than a minute, so that
/// a put-back in progress keeps its entry); removes the ledger folder when empty.
pub fn ledger_clean(layout: &Layout) {
    let Ok(rd) = fs::read_dir(&layout.ledger) else {
        return;
    };
    if check_private(&layout.ledger).is_err() {
        return;
    }
    let mut entries = Vec::new();
    for e in rd.flatten() {
        entries.push(e);
    }
    if entries.is_empty() {
        let _ = fs::remove_dir(&layout.ledger);
        return;
    }
    let inbox: std::collections::HashSet<u64> = fs::read_dir(&layout.inbox)
        .map(|rd| {
            use std::os::unix::fs::DirEntryExt;
            rd.flatten().map(|e| e.ino()).collect()
        })
        .unwrap_or_default();
    for e in entries {
        let n = e.file_name().to_string_lossy().into_owned();
        let ino = n
            .strip_suffix(".json")
            .and_then(|s| s.split_once('-'))
            .and_then(|(_, i)| i.parse::<u64>().ok());
        let old = e
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|a| a > Duration::from_secs(60));
        if old && ino.is_none_or(|i| !inbox.contains(&i)) {
            let _ = fs::remove_file(e.path());
        }
    }
}

/// Claims `INBOX/name` (judged complete with `stamp`) into `home` under a new id.
/// `Ok(None)` when the file is gone (another daemon took it).
pub fn claim(
    layout: &Layout,
    home: &Arc<Home>,
    id: String,
    name: &OsStr,
    stamp: Stamp,
    received: SystemTime,
) -> io::Result<Option<Job>> {
    let (attempts, received) =
        ledger_get(layout, &stamp).unwrap_or_else(|| (0, fsops::rfc3339(received)));
    let job = Job {
        id,
        home: home.clone(),
        name: name.to_owned(),
        attempt: attempts + 1,
        rec: Record {
            name: fsops::shown(name),
            raw: fsops::hex(name),
            received,
            // the attempt about to start counts from the claim on (one write less;
            // a daemon that dies before the worker starts has died with this file)
            attempts: attempts + 1,
            stamp: Some(stamp),
            phase: Phase::Claimed,
            set: None,
        },
        fresh: true,
        warned: None,
    };
    job.save()?;
    match fsops::rename_noreplace(&layout.inbox.join(name), &job.path()) {
        Ok(()) => {
            if attempts > 0 {
                let _ = fs::remove_file(ledger_path(layout, stamp.id));
            }
            Ok(Some(job))
        }
        Err(e) => {
            let _ = fs::remove_file(job.record_path());
            if e.kind() == io::ErrorKind::NotFound {
                Ok(None)
            } else {
                Err(e)
            }
        }
    }
}

/// Puts a claimed file back into the inbox under its name or, when taken, the collision
/// rule's next name (never over a file), with its failed attempts in the ledger.
/// Returns the name it got. `before_move` runs before each move (a test hook).
pub fn put_back(layout: &Layout, job: &Job, before_move: &dyn Fn()) -> io::Result<OsString> {
    let name = job.name_str().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            "a name the daemon cannot handle is never put back",
        )
    })?;
    let src = job.path();
    let stamp = Stamp::of(&fs::symlink_metadata(&src)?);
    if job.rec.set.is_some() {
        let mut j = job.clone();
        let stuck = put_back_members(layout, &mut j);
        if !stuck.is_empty() {
            return Err(io::Error::other(format!(
                "members of its set could not be put back: {}",
                stuck.join("; ")
            )));
        }
    }
    let ledger = ledger_put(
        layout,
        &stamp,
        job.attempt.saturating_sub(1),
        &job.rec.received,
    );
    if let Err(e) = &ledger {
        tracing::warn!(file = %job.shown(), "cannot record the attempt count: {e}");
    }
    let when = SystemTime::now();
    let mut moved = None;
    for skip in 0..1000 {
        let cand = fsops::free_name(
            &layout.inbox,
            name,
            &[],
            when,
            super::config::Collision::Timestamp,
            skip,
        );
        before_move();
        match fsops::rename_noreplace(&src, &layout.inbox.join(&cand)) {
            Ok(()) => {
                moved = Some(cand);
                break;
            }
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => {
                if ledger.is_ok() {
                    let _ = fs::remove_file(ledger_path(layout, stamp.id));
                }
                return Err(e);
            }
        }
    }
    let Some(cand) = moved else {
        return Err(io::Error::other("no free name in the inbox"));
    };
    let _ = fsops::fsync_dir(&layout.inbox);
    job.forget();
    Ok(OsString::from(cand))
}

/// The jobs of a processing folder (an adopted one, or ours after the inbox came
/// back), read from their records. Records whose claim never happened are dropped;
/// files of an older holefill (no record) get one.
pub fn jobs_of(home: &Arc<Home>, id: &Identity) -> Vec<Job> {
    let mut out = Vec::new();
    let Ok(rd) = fs::read_dir(&home.dir) else {
        return out;
    };
    let entries: Vec<OsString> = rd.flatten().map(|e| e.file_name()).collect();
    let mut ids = std::collections::HashSet::new();
    for n in &entries {
        let Some(jid) = n.to_str().and_then(|s| s.strip_suffix(".json")) else {
            continue;
        };
        if jid.starts_with('.') {
            continue;
        }
        ids.insert(jid.to_string());
        let rec_path = home.dir.join(n);
        let Some(rec) = Record::read(&rec_path) else {
            tracing::warn!("{}: unreadable job record, left alone", rec_path.display());
            continue;
        };
        let Some(name) = fsops::unhex(&rec.raw) else {
            tracing::warn!(
                "{}: a job record with no valid name, left alone",
                rec_path.display()
            );
            continue;
        };
        let present = fs::symlink_metadata(home.dir.join(jid)).is_ok();
        if rec.phase == Phase::Claimed && !present {
            let _ = fs::remove_file(&rec_path); // died between record and claim
            continue;
        }
        let attempt = match rec.phase {
            Phase::Claimed => rec.attempts + 1, // the attempt that died counts
            _ => rec.attempts.max(1),
        };
        out.push(Job {
            id: jid.to_string(),
            home: home.clone(),
            name,
            attempt,
            rec,
            fresh: false,
            warned: None,
        });
    }
    // files of an older holefill: NAME with `.NAME.holefill.json`
    for n in &entries {
        let b = n.as_bytes();
        if b.starts_with(b".") || b.ends_with(b".json") || b.ends_with(b".tmp") {
            continue;
        }
        // a job's file, or a member of a job's set (`ID.mN`)
        let of_a_job = n.to_str().is_some_and(|s| {
            ids.contains(s)
                || s.rsplit_once(".m").is_some_and(|(id, k)| {
                    ids.contains(id) && !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit())
                })
        });
        if of_a_job {
            continue;
        }
        let path = home.dir.join(n);
        if !fs::symlink_metadata(&path).is_ok_and(|m| m.is_file()) {
            continue;
        }
        #[derive(Deserialize)]
        struct Old {
            attempts: u32,
            received: String,
        }
        let mut old_side = OsString::from(".");
        old_side.push(n);
        old_side.push(".holefill.json");
        let old: Option<Old> = fs::read(home.dir.join(&old_side))
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok());
        let (attempts, received) = match old {
            Some(o) => (o.attempts, o.received),
            None => (1, fsops::rfc3339(SystemTime::now())),
        };
        let job = Job {
            id: id.next_id(),
            home: home.clone(),
            name: n.clone(),
            attempt: attempts + 1,
            rec: Record {
                name: fsops::shown(n),
                raw: fsops::hex(n),
                received,
                attempts,
                stamp: None,
                phase: Phase::Claimed,
                set: None,
            },
            fresh: false,
            warned: None,
        };
        if job.save().is_err() || fsops::rename_noreplace(&path, &job.path()).is_err() {
            let _ = fs::remove_file(job.record_path());
            continue;
        }
        let _ = fs::remove_file(home.dir.join(&old_side));
        out.push(job);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        for n in ["a.obj", "B.PLY", "x.y.Stl", "scan 01.off"] {
            assert!(is_candidate_name(OsStr::new(n)), "{n}");
        }
        assert!(is_candidate_name(OsStr::from_bytes(b"\xff.obj")));
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
            assert!(!is_candidate_name(OsStr::new(n)), "{n}");
        }
    }

    #[test]
    fn resolve_folds_what_does_not_exist_yet() {
        let d = tempfile::tempdir().unwrap();
        let root = fs::canonicalize(d.path()).unwrap();
        std::os::unix::fs::symlink(&root, root.join("link")).unwrap();
        assert_eq!(
            resolve(&root.join("link/a/../b/./c")).unwrap(),
            root.join("b/c")
        );
    }

    fn layout(d: &Path) -> Layout {
        Layout::create(
            &d.join("in"),
            &d.join("out"),
            &d.join("failed"),
            &d.join("archive"),
        )
        .unwrap()
    }

    #[test]
    fn aliased_folders_are_refused() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path();
        fs::create_dir(p.join("in")).unwrap();
        std::os::unix::fs::symlink(p.join("in"), p.join("alias")).unwrap();
        for (out, why) in [
            (p.join("in"), "same"),
            (p.join("in/../in/"), "same"),
            (p.join("alias"), "same"),
            (p.join("in/out"), "inside the inbox"),
            (p.join("alias/x/y"), "inside the inbox"),
            (p.to_path_buf(), "inbox"),
        ] {
            let e = Layout::create(&p.join("in"), &out, &p.join("f"), &p.join("a")).unwrap_err();
            assert!(e.contains(why), "{}: {e}", out.display());
        }
        assert!(
            !p.join("in/out").exists(),
            "nothing created for a refused layout"
        );
        layout(p);
    }

    #[test]
    fn a_home_is_alive_while_its_lock_is_held() {
        let d = tempfile::tempdir().unwrap();
        let l = layout(d.path());
        let a = Home::create(&l, "h-1-a").unwrap();
        assert!(a.intact());
        assert!(matches!(Home::adopt(&l, "h-1-a"), Ok(None)), "alive");
        drop(a);
        let b = Home::adopt(&l, "h-1-a").unwrap().expect("dead: adopted");
        assert!(matches!(Home::adopt(&l, "h-1-a"), Ok(None)), "adopted once");
        assert!(b.remove_if_empty());
        assert!(!l.processing_root.join("h-1-a").exists());
    }

    #[test]
    fn folders_of_others_are_refused() {
        use std::os::unix::fs::PermissionsExt;
        let d = tempfile::tempdir().unwrap();
        let l = layout(d.path());
        let fake = l.processing_root.join("h-2-b");
        fs::create_dir(&fake).unwrap();
        fs::set_permissions(&fake, fs::Permissions::from_mode(0o777)).unwrap();
        let e = Home::adopt(&l, "h-2-b").unwrap_err();
        assert!(e.contains("written by others"), "{e}");
    }

    #[test]
    fn claim_is_exclusive_put_back_never_overwrites_and_keeps_the_count() {
        let d = tempfile::tempdir().unwrap();
        let l = layout(d.path());
        let id = Identity::current();
        let a = Arc::new(Home::create(&l, "h-3-a").unwrap());
        let b = Arc::new(Home::create(&l, "h-4-b").unwrap());
        let p = l.inbox.join("s.obj");
        fs::write(&p, "1").unwrap();
        let st = Stamp::of(&fs::metadata(&p).unwrap());
        let now = SystemTime::now();
        let mut job = claim(&l, &a, id.next_id(), OsStr::new("s.obj"), st, now)
            .unwrap()
            .unwrap();
        assert!(claim(&l, &b, id.next_id(), OsStr::new("s.obj"), st, now)
            .unwrap()
            .is_none());
        assert_eq!(fs::read_dir(&b.dir).unwrap().count(), 1, "only b's lock");
        // a new file of the same name arrives while ours is claimed
        fs::write(&p, "2").unwrap();
        job.attempt = 3; // two attempts failed
        let back = put_back(&l, &job, &|| {}).unwrap();
        assert_ne!(back, "s.obj");
        assert_eq!(fs::read_to_string(&p).unwrap(), "2");
        let q = l.inbox.join(&back);
        assert_eq!(fs::read_to_string(&q).unwrap(), "1");
        let st = Stamp::of(&fs::metadata(&q).unwrap());
        let again = claim(&l, &a, id.next_id(), &back, st, now)
            .unwrap()
            .unwrap();
        assert_eq!(again.attempt, 3, "the count survives the put-back");
        assert_eq!(again.rec.received, job.rec.received);
    }

    #[test]
    fn adopted_jobs_resume_and_count_the_attempt_that_died() {
        let d = tempfile::tempdir().unwrap();
        let l = layout(d.path());
        let id = Identity::current();
        let dead = Arc::new(Home::create(&l, "h-5-d").unwrap());
        let p = l.inbox.join("a.obj");
        fs::write(&p, "a").unwrap();
        let st = Stamp::of(&fs::metadata(&p).unwrap());
        let mut job = claim(
            &l,
            &dead,
            id.next_id(),
            OsStr::new("a.obj"),
            st,
            SystemTime::now(),
        )
        .unwrap()
        .unwrap();
        job.rec.attempts = 2;
        job.save().unwrap();
        // a record whose claim never happened, and a file of an older holefill
        fs::write(
            dead.dir.join("x-9.json"),
            serde_json::to_vec(&job.rec).unwrap(),
        )
        .unwrap();
        fs::write(dead.dir.join("old.obj"), "o").unwrap();
        drop(job);
        let dead = Arc::try_unwrap(dead).unwrap();
        drop(dead);
        let h = Arc::new(Home::adopt(&l, "h-5-d").unwrap().unwrap());
        let mut jobs = jobs_of(&h, &id);
        jobs.sort_by(|a, b| a.name.cmp(&b.name));
        assert_eq!(jobs.len(), 2, "{jobs:?}");
        assert_eq!((jobs[0].name.to_str(), jobs[0].attempt), (Some("a.obj"), 3));
        assert_eq!(
            (jobs[1].name.to_str(), jobs[1].attempt),
            (Some("old.obj"), 2)
        );
        assert!(!h.dir.join("x-9.json").exists());
        assert!(jobs[1].path().is_file() && jobs[1].record_path().is_file());
    }
}
