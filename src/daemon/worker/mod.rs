//! One job: check the claimed file, run `holefill fill` on it under limits, and dispose
//! of it (outbox and archive, failed folder, back into the inbox, or later).
//!
//! **The file handed over.** The claimed entry is looked at without following it
//! (`lstat`), opened once with `O_NOFOLLOW | O_NONBLOCK` and checked (`fstat`) to be
//! the regular file of the inode, size and modification time judged complete in the
//! inbox; the worker gets that open file as its standard input and reads it as
//! `/proc/self/fd/0` (`--input-format`), so no path is opened twice and nothing a
//! producer swaps in is ever read. A symlink, FIFO, socket or device is never opened
//! for reading or followed: it goes to the failed folder's log as what it is and is
//! removed (a symlink is removed, not its target). A directory is never taken. After
//! the repair the open file is checked again: a file that changed meanwhile (a writer
//! still at work) is put back to settle, its output discarded.
//!
//! **Isolation.** Each repair is a child process under limits ([`super::child`], shared
//! with the queue worker), in a process group of its own.
//!
//! Exit statuses of `holefill fill`: 0 and 2 (some holes left open) are repairs; 65
//! (malformed input) and 70 (internal error) are permanent failures; 74 (I/O, such as
//! a full disk) and 78 (invalid policy) are retryable (back into the inbox, retried
//! with a back-off); a signal, a timeout or any other status is a crashed attempt,
//! retried up to `max_attempts`, then a failure.
//!
//! **Publishing, crash-safe and idempotent.** Once the worker is done, the output and
//! archive names are chosen and the final log is written (in the temporary folder);
//! the job's record takes the names and the identities (device, inode) of the model
//! and the log. Then: the model is renamed into the outbox (no replace), the outbox
//! fsynced; the original moved into the archive (or deleted); the log renamed into the
//! outbox, fsynced; the record removed. Each step first checks whether it is done (the
//! outbox name holds our inode; the original is gone from the processing folder, or
//! the archive holds it: same inode, or the same bytes after a copy across file
//! systems), so a daemon resuming the record after a crash at any point finishes the
//! same publish: one model, one log, one archived original, and never a second
//! repair. A step that cannot be done now (the archive not writable, a folder gone)
//! leaves the job where it is and is retried later; the log, which says the original
//! is archived, is published only once it is.
//!
//! **The picture follows the log.** The child writes the model and the log, says so
//! (`fill --picture-after-log`), and draws the picture at the lowest CPU priority while
//! the job is published and the next repair starts; [`LatePicture`] waits for it
//! (under the same time limit) and puts it beside the log. A picture is best effort:
//! one whose drawing fails, or whose child outlives a daemon that died, is lost with
//! a warning, never the repair.

use super::child::{self, ChildEnd};
use super::claim::{self, Job, Layout, Phase};
use super::config::{Collision, Settings};
use super::fsops::{self, Stamp};
use super::hooks::Hooks;
use super::sets;
use serde_json::Value;
use std::ffi::OsString;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Instant, SystemTime};
use tokio::sync::watch;

mod failed;
mod log;
mod members;
mod prepare;
mod publish;

use failed::{fail, finish_failed};
use prepare::prepare;
use publish::{commit, resume_repaired};

/// What every job of one configuration generation shares.
#[derive(Debug)]
pub struct RunCtx {
    pub layout: Layout,
    pub host: String,
    pub pid: u32,
    pub instance: String,
    pub settings: Settings,
    /// The validated policy snapshot passed to the workers (`None`: built-in default).
    pub policy: Option<PathBuf>,
    /// The policy file it was read from.
    pub policy_source: Option<PathBuf>,
    pub exe: PathBuf,
    pub hooks: Hooks,
    pub cores: usize,
    /// `watch --forward`: repairs go to the work queue instead of a local child.
    pub forward: Option<Arc<crate::worker::gateway::Forwarder>>,
}

impl RunCtx {
    /// How this generation's children are started.
    pub fn child_spec(&self) -> child::Spec<'_> {
        child::Spec {
            exe: &self.exe,
            policy: self.policy.as_deref(),
            max_file_bytes: self.settings.max_file_bytes,
            max_faces: self.settings.max_faces,
            max_vertices: self.settings.max_vertices,
            time_limit: self.settings.time_limit,
            memory_limit_mb: self.settings.memory_limit_mb,
            cores: self.cores,
            hooks: &self.hooks,
            picture: None,
            resources: &[],
        }
    }
}

/// How a job ended.
#[derive(Debug)]
pub enum Done {
    /// Model and log in the outbox, the original archived or deleted.
    Repaired {
        job: Job,
        output: String,
        filled: u64,
        skipped: u64,
        failed: u64,
        secs: f64,
        /// Finished from a record (a daemon died after the repair): not repaired again.
        resumed: bool,
        /// The picture, still being drawn: published beside the log once it is.
        picture: Option<Box<LatePicture>>,
    },
    /// In the failed folder with its log.
    Failed {
        job: Job,
        stage: String,
        error: String,
        secs: f64,
    },
    /// The worker crashed, hung or was killed; attempts are left: the file stays in
    /// the processing folder and is tried again.
    Again { job: Job, error: String },
    /// Could not be finished now (a folder missing or not writable): stays in the
    /// processing folder as it is, tried again later; no attempt counted.
    Later { job: Job, error: String },
    /// Back in the inbox under `inbox_name` (retryable failure, shutdown, or a change).
    PutBack {
        job: Job,
        inbox_name: OsString,
        error: Option<String>,
        /// It changed while claimed: it settles again before it is taken.
        changed: bool,
    },
    /// Vanished from the processing folder (removed by someone with the daemon's
    /// rights, or with the whole inbox).
    Gone { job: Job, error: String },
    /// The mesh names other files (`mtllib`, `TextureFile`, glTF `uri`s): it waits,
    /// claimed, for the members of its set (`refs`: the references as written, with
    /// what each is).
    Members {
        job: Job,
        refs: Vec<(String, super::sets::Role)>,
    },
}

impl Done {
    /// The job.
    pub fn job(&self) -> &Job {
        match self {
            Done::Repaired { job, .. }
            | Done::Failed { job, .. }
            | Done::Again { job, .. }
            | Done::Later { job, .. }
            | Done::PutBack { job, .. }
            | Done::Gone { job, .. }
            | Done::Members { job, .. } => job,
        }
    }
}

/// When this attempt started.
#[derive(Clone, Copy, Debug)]
struct Times {
    started: SystemTime,
    t0: Instant,
}

/// Runs one attempt on a job and disposes of its file.
pub async fn process(ctx: Arc<RunCtx>, job: Job, mut cancel: watch::Receiver<bool>) -> Done {
    let t = Times {
        started: SystemTime::now(),
        t0: Instant::now(),
    };
    match &job.rec.phase {
        Phase::Claimed => {}
        Phase::Repaired { .. } => {
            let c = ctx.clone();
            let done = blocking(ctx, move |c| resume_repaired(&c, job, t, None, true)).await;
            // the picture, if the dead daemon's child drew it
            return with_picture(&c, done, None);
        }
        Phase::Failed { .. } => {
            return blocking(ctx, move |c| finish_failed(&c, job, t, None)).await
        }
    }
    let prepared = {
        let c = ctx.clone();
        tokio::task::spawn_blocking(move || prepare(&c, job, t)).await
    };
    let (job, file, stamp) = match prepared {
        Ok(Ok(p)) => p,
        Ok(Err(done)) => return *done,
        Err(e) => panic!("the preparation of a job panicked: {e}"),
    };
    let ext = ext_of(&job);
    let out = job.tmp(&format!(".{ext}"));
    let child_log = job.tmp(".child.json");
    let _ = fs::remove_file(&out);
    let _ = fs::remove_file(&child_log);
    let picture = job.tmp(PICTURE);
    let _ = fs::remove_file(&picture);
    let (end, stderr, drawing) = match &ctx.forward {
        // the gateway: repaired by a queue worker, its outcome written as the child's
        Some(f) => {
            let members: Vec<(String, PathBuf)> = job
                .members()
                .iter()
                .enumerate()
                .map(|(i, m)| (m.name.clone(), job.member_path(i)))
                .collect();
            let (end, stderr) = f
                .repair(
                    &job.name.to_string_lossy(),
                    &file,
                    &members,
                    &out,
                    &child_log,
                    &mut cancel,
                )
                .await;
            (end, stderr, None)
        }
        None => {
            // glTF buffers of the set: read by the child from their claimed copies
            let resources: Vec<(String, PathBuf)> = job
                .members()
                .iter()
                .enumerate()
                .filter(|(_, m)| m.role == super::sets::Role::Buffer)
                .map(|(i, m)| (m.name.clone(), job.member_path(i)))
                .collect();
            let spec = child::Spec {
                picture: ctx.settings.picture.then_some(picture.as_path()),
                resources: &resources,
                ..ctx.child_spec()
            };
            child::run(
                &spec,
                &job.name.to_string_lossy(),
                child::Input::Stdin(&file),
                &ext,
                &out,
                &child_log,
                &mut cancel,
            )
            .await
        }
    };
    let shown_input = fsops::shown(ctx.layout.inbox.join(&job.name).as_os_str());
    let msg = child::stderr_message(&stderr).replace("/proc/self/fd/0", &shown_input);
    // a writer still at work through an open descriptor: its output is of a partial file
    let changed = file.metadata().map(|m| Stamp::of(&m)).ok() != Some(stamp);
    drop(file);
    if changed && !matches!(end, ChildEnd::Cancelled) {
        if let Some(d) = drawing {
            d.abandon().await;
        }
        let _ = fs::remove_file(&out);
        let _ = fs::remove_file(&child_log);
        return blocking(ctx, move |c| {
            put_back(
                &c,
                job,
                Some("it changed while it was being repaired; its output is discarded and it settles again".into()),
                true,
            )
        })
        .await;
    }
    let c2 = ctx.clone();
    match end {
        ChildEnd::Exit(code @ (0 | 2)) => {
            let done = blocking(c2, move |c| commit(&c, job, t, &out, &child_log, code)).await;
            match (&done, drawing) {
                (Done::Repaired { .. }, d) | (_, d @ None) => with_picture(&ctx, done, d),
                // published later: the picture waits with the model and the log
                (Done::Later { .. }, Some(d)) => {
                    let _ = d.finish(&mut cancel).await;
                    done
                }
                // not published: the picture is not wanted
                (_, Some(d)) => {
                    d.abandon().await;
                    let _ = fs::remove_file(&picture);
                    done
                }
            }
        }
        ChildEnd::Exit(65) => {
            let e = or(msg, "unreadable or malformed input (exit 65)");
            blocking(c2, move |c| {
                fail(
                    &c,
                    job,
                    t,
                    "input",
                    e,
                    read_json(&child_log),
                    Some(65),
                    true,
                )
            })
            .await
        }
        ChildEnd::Exit(70) => {
            let e = or(msg, "internal error (exit 70)");
            blocking(c2, move |c| {
                fail(
                    &c,
                    job,
                    t,
                    "repair",
                    e,
                    read_json(&child_log),
                    Some(70),
                    true,
                )
            })
            .await
        }
        ChildEnd::Exit(code @ (74 | 78)) => {
            let what = if code == 74 {
                "I/O error (retryable)"
            } else {
                "invalid policy"
            };
            let e = format!("worker exit {code} ({what}): {}", or(msg, "-"));
            blocking(c2, move |c| put_back(&c, job, Some(e), false)).await
        }
        ChildEnd::Cancelled => {
            blocking(c2, move |c| {
                put_back(&c, job, Some("daemon stopping".into()), false)
            })
            .await
        }
        ChildEnd::Remote { stage, error } => {
            blocking(c2, move |c| {
                fail(&c, job, t, &stage, error, read_json(&child_log), None, true)
            })
            .await
        }
        ChildEnd::SpawnError(e) => {
            let e = format!("cannot start the worker: {e}");
            blocking(c2, move |c| put_back(&c, job, Some(e), false)).await
        }
        end => {
            if let Some(m) = crate::metrics::global() {
                match end {
                    ChildEnd::Timeout(_) => m.timeouts.inc(),
                    _ => m.crashes.inc(),
                };
            }
            let why = child::crash_reason(ctx.settings.memory_limit_mb, end, &msg);
            let _ = fs::remove_file(&out);
            let _ = fs::remove_file(&child_log);
            if job.attempt >= ctx.settings.max_attempts {
                let e = format!(
                    "{why} (attempt {} of {}; giving up)",
                    job.attempt, ctx.settings.max_attempts
                );
                blocking(c2, move |c| fail(&c, job, t, "worker", e, None, None, true)).await
            } else {
                Done::Again { job, error: why }
            }
        }
    }
}

fn or(s: String, d: &str) -> String {
    if s.is_empty() {
        d.to_string()
    } else {
        s
    }
}

fn read_json(p: &Path) -> Option<Value> {
    fs::read(p)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
}

/// The lower-case extension of the job's name (`obj`), for the worker's formats.
fn ext_of(job: &Job) -> String {
    let n = job.name.to_string_lossy();
    n.rsplit_once('.')
        .map(|(_, e)| e.to_ascii_lowercase())
        .filter(|e| matches!(e.as_str(), "obj" | "ply" | "stl" | "off" | "glb" | "gltf"))
        .unwrap_or_else(|| "obj".to_string())
}

/// Runs a blocking disposition off the async runtime.
async fn blocking<F>(ctx: Arc<RunCtx>, f: F) -> Done
where
    F: FnOnce(Arc<RunCtx>) -> Done + Send + 'static,
{
    match tokio::task::spawn_blocking(move || f(ctx)).await {
        Ok(d) => d,
        Err(e) => panic!("a job's disposition panicked: {e}"),
    }
}

/// The temporary name (in the job's temporary folder) of member `i`'s outbox copy.
fn member_tmp(i: usize) -> String {
    format!(".m{i}")
}

/// The job's temporary files (removed when it ends or goes back).
fn tmp_files(job: &Job) -> Vec<String> {
    let mut v = vec![
        ".child.json".to_string(),
        ".log.json".into(),
        PICTURE.into(),
        format!(".{}", ext_of(job)),
    ];
    v.extend((0..job.members().len()).map(member_tmp));
    v
}

/// Where a set goes in the archive or failed folder `dir` (relative): the mesh's own
/// name when neither it (with `suffixes`) nor a member's name is taken, else the mesh's
/// name in a new subfolder (made when the first file moves there). A single file: the
/// collision rule's name.
fn set_place(
    dir: &Path,
    name: &str,
    members: &[String],
    suffixes: &[&str],
    when: SystemTime,
) -> String {
    let names: Vec<&str> = members.iter().map(String::as_str).collect();
    if members.is_empty() {
        fsops::free_name(dir, name, suffixes, when, Collision::Timestamp, 0)
    } else if sets::all_free(dir, name, suffixes, &names) {
        name.to_string()
    } else {
        format!("{}/{name}", sets::free_folder(dir, name, when, 1))
    }
}

/// Makes the subfolder of a relative place (`sub/name`) in `dir`, if it has one.
fn ensure_place(dir: &Path, rel: &str) -> io::Result<()> {
    match rel.rsplit_once('/') {
        Some((sub, _)) => sets::ensure_folder(dir, sub),
        None => Ok(()),
    }
}

/// The folder a relative place's file is in (for its fsync).
fn place_dir(dir: &Path, rel: &str) -> PathBuf {
    match rel.rsplit_once('/') {
        Some((sub, _)) => dir.join(sub),
        None => dir.to_path_buf(),
    }
}

/// A step of the publish that cannot be done now.
fn later(job: Job, error: String) -> Done {
    Done::Later { job, error }
}

/// The worker's picture of the repair, in the job's temporary folder.
const PICTURE: &str = ".png";

/// A repaired job with its picture to publish when the daemon draws pictures (the
/// child's, still being drawn, when `drawing` is given).
fn with_picture(ctx: &RunCtx, mut done: Done, drawing: Option<child::Drawing>) -> Done {
    if let Done::Repaired {
        job,
        output,
        picture,
        ..
    } = &mut done
    {
        if ctx.settings.picture && ctx.forward.is_none() {
            *picture = Some(Box::new(LatePicture {
                drawing,
                tmp: job.tmp(PICTURE),
                dst: ctx.layout.outbox.join(format!("{output}.repair.png")),
                rule: ctx.settings.collision,
                shown: job.shown(),
            }));
        }
    }
    done
}

/// A repaired job's picture, drawn by its child after the model and the log were
/// published (at the lowest CPU priority, so that it never delays a repair).
#[derive(Debug)]
pub struct LatePicture {
    /// The child drawing it; `None`: it ended (the picture is there, or not at all).
    drawing: Option<child::Drawing>,
    /// Where the child writes it (the job's temporary folder).
    tmp: PathBuf,
    /// `OUTBOX/OUTPUT.repair.png`, beside the log.
    dst: PathBuf,
    rule: Collision,
    shown: String,
}

impl LatePicture {
    /// Waits for the picture and publishes it; its path, or `None` when it is lost
    /// (the drawing failed or was killed, or the name is taken: said in a warning).
    /// Its temporary file is removed in any case.
    pub async fn publish(self: Box<Self>, mut cancel: watch::Receiver<bool>) -> Option<PathBuf> {
        let LatePicture {
            drawing,
            tmp,
            dst,
            rule,
            shown,
        } = *self;
        let waited = drawing.is_some();
        let drawn = match drawing {
            Some(d) => d.finish(&mut cancel).await,
            None => Ok(()),
        };
        let published = tokio::task::spawn_blocking(move || {
            let there = fs::symlink_metadata(&tmp).is_ok_and(|m| m.is_file());
            let published = match (drawn, there) {
                // not synced, as the child wrote it (`io::write_unsynced`)
                (Ok(()), true) => fsops::publish(&tmp, &dst, rule)
                    .map_err(|e| format!("not published as {}: {e}", dst.display()))
                    .map(|()| Some(dst)),
                // a child that ended before it was waited for said why on its stderr
                (Ok(()), false) if !waited => Ok(None),
                (Ok(()), false) => Err("none drawn".to_string()),
                (Err(e), _) => Err(e),
            };
            let _ = fs::remove_file(&tmp);
            published.unwrap_or_else(|e| {
                tracing::warn!(file = %shown, "{shown}: the picture of its repair is lost: {e}");
                None
            })
        })
        .await;
        published.ok().flatten()
    }
}

/// Puts the file back into the inbox (retry later, or settle again when `changed`).
fn put_back(ctx: &RunCtx, job: Job, error: Option<String>, changed: bool) -> Done {
    for s in tmp_files(&job) {
        let _ = fs::remove_file(job.tmp(&s));
    }
    match claim::put_back(&ctx.layout, &job, &|| ctx.hooks.at("move", &job.name)) {
        Ok(inbox_name) => Done::PutBack {
            job,
            inbox_name,
            error,
            changed,
        },
        Err(e) => later(
            job,
            format!(
                "{}; and it could not be put back into the inbox: {e}",
                error.unwrap_or_default()
            ),
        ),
    }
}

/// Puts a job that waits (crashed attempt, or a step to retry) back into the inbox at
/// shutdown, when it is still only claimed (nothing published). `None`: it stays in
/// its processing folder for the next daemon.
pub fn put_back_waiting(ctx: &RunCtx, job: &Job) -> Option<io::Result<OsString>> {
    (job.rec.phase == Phase::Claimed && job.name_str().is_some())
        .then(|| claim::put_back(&ctx.layout, job, &|| ctx.hooks.at("move", &job.name)))
}

#[cfg(test)]
mod tests;
