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
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::SystemTime;

mod home;
mod layout;
mod ledger;

pub use home::{clean_staging, clean_tmp, Home};
pub use layout::{make_private_dir, Layout};
pub use ledger::ledger_clean;
use ledger::{ledger_get, ledger_path, ledger_put};

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

/// Writes `bytes` to `path` through `path.tmp` (fsync, rename), readable by the
/// daemon's user only.
fn write_durably(path: &Path, bytes: &[u8]) -> io::Result<()> {
    fsops::write_durably(path, bytes, 0o600).map(drop)
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
    [&b".obj"[..], b".ply", b".stl", b".off", b".glb", b".gltf"]
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
mod tests;
