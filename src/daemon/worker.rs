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

use super::child::{self, ChildEnd};
use super::claim::{self, Job, Layout, Phase};
use super::config::{Collision, OnSuccess, Settings};
use super::fsops::{self, FileId, Stamp};
use super::hooks::Hooks;
use super::sets;
use super::sniff;
use serde_json::{json, Value};
use std::ffi::OsString;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Instant, SystemTime};
use tokio::sync::watch;

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
            return blocking(ctx, move |c| resume_repaired(&c, job, t, None, true)).await
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
    let (end, stderr) = match &ctx.forward {
        // the gateway: repaired by a queue worker, its outcome written as the child's
        Some(f) => {
            let members: Vec<(String, PathBuf)> = job
                .members()
                .iter()
                .enumerate()
                .map(|(i, m)| (m.name.clone(), job.member_path(i)))
                .collect();
            f.repair(
                &job.name.to_string_lossy(),
                &file,
                &members,
                &out,
                &child_log,
                &mut cancel,
            )
            .await
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
            blocking(c2, move |c| commit(&c, job, t, &out, &child_log, code)).await
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

/// Checks the claimed file and opens it (see the module documentation); applies the
/// limits that need no worker. `Err` is the job's end.
#[allow(clippy::result_large_err)]
fn prepare(ctx: &RunCtx, mut job: Job, t: Times) -> Result<(Job, fs::File, Stamp), Box<Done>> {
    let path = job.path();
    let md = match fs::symlink_metadata(&path) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            job.forget();
            return Err(Box::new(Done::Gone {
                job,
                error: "it vanished from the processing folder".into(),
            }));
        }
        Err(e) => {
            return Err(Box::new(Done::Later {
                job,
                error: format!("cannot look at the claimed file: {e}"),
            }))
        }
    };
    if md.is_dir() {
        // swapped in after the inbox was looked at: directories are never taken
        return Err(Box::new(put_back(
            ctx,
            job,
            Some("a directory, not a file: left in the inbox".into()),
            true,
        )));
    }
    if !md.is_file() {
        return Err(Box::new(reject_special(ctx, job, t, &md)));
    }
    let id = FileId::of(&md);
    let judged = job.rec.stamp;
    if judged.is_some_and(|s| s.id != id) {
        return Err(Box::new(put_back(
            ctx,
            job,
            Some("another file took its place between the check and the claim".into()),
            true,
        )));
    }
    let file = match fsops::open_nofollow(&path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::PermissionDenied => {
            let err = format!("cannot read the file: {e}");
            return Err(Box::new(fail(ctx, job, t, "input", err, None, None, true)));
        }
        Err(e) => {
            return Err(Box::new(Done::Later {
                job,
                error: format!("cannot open the claimed file: {e}"),
            }))
        }
    };
    let now = match file.metadata() {
        Ok(m) if m.is_file() && FileId::of(&m) == id => Stamp::of(&m),
        _ => {
            return Err(Box::new(put_back(
                ctx,
                job,
                Some("another file took its place while it was opened".into()),
                true,
            )))
        }
    };
    if job.fresh && judged.is_some_and(|s| (s.size, s.mtime_ns) != (now.size, now.mtime_ns)) {
        return Err(Box::new(put_back(
            ctx,
            job,
            Some("it changed since it was judged complete; it settles again".into()),
            true,
        )));
    }
    if let Some(problem) = fsops::name_problem(&job.name) {
        return Err(Box::new(fail(
            ctx, job, t, "name", problem, None, None, true,
        )));
    }
    if let Some(done) = check_set(ctx, &mut job, t, &file) {
        return Err(Box::new(done));
    }
    let s = &ctx.settings;
    if job.attempt > s.max_attempts {
        let started = job.attempt - 1;
        let err = format!(
            "{started} attempts were started and none finished (the worker or the daemon died each time); max_attempts = {}",
            s.max_attempts
        );
        job.attempt = started;
        return Err(Box::new(fail(ctx, job, t, "worker", err, None, None, true)));
    }
    // the worker writes there (an adopted folder's may be gone with the outbox). The
    // outbox itself is never made here: when it vanished, the daemon's folder check
    // makes it again (and says so); the file waits in the inbox until then.
    if !fs::symlink_metadata(&ctx.layout.outbox).is_ok_and(|m| m.is_dir()) {
        return Err(Box::new(put_back(
            ctx,
            job,
            Some("the outbox is not there (it is made again before the file is taken)".into()),
            false,
        )));
    }
    {
        use std::os::unix::fs::DirBuilderExt;
        let _ = claim::make_private_dir(&ctx.layout.tmp_root, 0o755);
        let _ = fs::DirBuilder::new().mode(0o700).create(&job.home.tmp);
    }
    if job.rec.attempts != job.attempt {
        job.rec.attempts = job.attempt;
        if let Err(e) = job.save() {
            tracing::warn!(file = %job.shown(), "cannot record the attempt count: {e}");
        }
    }
    if s.max_file_bytes > 0 && now.size > s.max_file_bytes {
        let err = format!(
            "file size {} bytes > max_file_bytes = {}",
            now.size, s.max_file_bytes
        );
        return Err(Box::new(fail(ctx, job, t, "limits", err, None, None, true)));
    }
    if now.size == 0 {
        let err = if job.fresh {
            format!(
                "the file is empty, and stayed empty for max_wait_secs = {} s",
                s.max_wait.as_secs()
            )
        } else {
            "the file is empty".to_string()
        };
        return Err(Box::new(fail(ctx, job, t, "input", err, None, None, true)));
    }
    if s.max_faces > 0 {
        let name = job.name.to_string_lossy().into_owned();
        if let Some(n) = sniff::declared_faces(&file, &name).filter(|&n| n > s.max_faces) {
            let err = format!("{n} faces > max_faces = {}", s.max_faces);
            return Err(Box::new(fail(ctx, job, t, "limits", err, None, None, true)));
        }
    }
    Ok((job, file, now))
}

/// The set of a claimed mesh (see [`super::sets`]): `Some` ends this attempt. A mesh
/// whose references were not read yet and that names other files goes to wait for
/// them ([`Done::Members`]); a set whose members are not all in the processing folder
/// (a crash while they were claimed) puts them back and waits again; a set that timed
/// out fails.
fn check_set(ctx: &RunCtx, job: &mut Job, t: Times, file: &fs::File) -> Option<Done> {
    let name = job.name_str().unwrap_or_default().to_string();
    match &job.rec.set {
        None => match sniff::references(file, &name) {
            Ok(refs) if refs.is_empty() => None,
            Ok(refs) => Some(Done::Members {
                job: job.clone(),
                refs,
            }),
            Err(e) => Some(Done::Later {
                job: job.clone(),
                error: format!("cannot read the files it names: {e}"),
            }),
        },
        Some(set) => {
            let complete = set.members.iter().enumerate().all(|(i, m)| {
                fs::symlink_metadata(job.member_path(i))
                    .is_ok_and(|md| md.is_file() && FileId::of(&md) == m.stamp.id)
            });
            if !complete {
                let stuck = claim::put_back_members(&ctx.layout, job);
                if !stuck.is_empty() {
                    return Some(Done::Later {
                        job: job.clone(),
                        error: format!(
                            "its set is incomplete and cannot be put back: {}",
                            stuck.join("; ")
                        ),
                    });
                }
                return check_set(ctx, job, t, file);
            }
            if !set.missing.is_empty() {
                let err = set.missing_message();
                return Some(fail(ctx, job.clone(), t, "set", err, None, None, true));
            }
            None
        }
    }
}

/// A claimed entry that is not a regular file (symlink, FIFO, socket, device): never
/// opened or followed; removed, with a log in the failed folder saying what it was.
fn reject_special(ctx: &RunCtx, job: Job, t: Times, md: &fs::Metadata) -> Done {
    use std::os::unix::fs::FileTypeExt;
    let ft = md.file_type();
    let what = if ft.is_symlink() {
        let target = fs::read_link(job.path())
            .map(|p| fsops::shown(p.as_os_str()))
            .unwrap_or_else(|_| "?".into());
        format!("a symbolic link (to {target})")
    } else if ft.is_fifo() {
        "a FIFO (named pipe)".to_string()
    } else if ft.is_socket() {
        "a socket".to_string()
    } else if ft.is_block_device() || ft.is_char_device() {
        "a device".to_string()
    } else {
        "not a regular file".to_string()
    };
    let err =
        format!("not a regular file: {what}; it was neither opened nor followed, and is removed");
    fail(ctx, job, t, "input", err, None, None, false)
}

/// The `"daemon"` object of a log.
fn daemon_info(ctx: &RunCtx, job: &Job, t: Times, status: &str, extra: Value) -> Value {
    let mut v = json!({
        "host": ctx.host,
        "pid": ctx.pid,
        "instance": ctx.instance,
        "input": job.shown(),
        "received": job.rec.received,
        "started": fsops::rfc3339(t.started),
        "finished": fsops::rfc3339(SystemTime::now()),
        "seconds": t.t0.elapsed().as_secs_f64(),
        "attempt": job.attempt,
        "max_attempts": ctx.settings.max_attempts,
        "status": status,
        "policy": ctx.policy_source.as_ref().map(|p| p.display().to_string()),
    });
    if job.name.to_str().is_none() {
        v["input_bytes_hex"] = json!(job.rec.raw);
    }
    if let (Some(o), Value::Object(e)) = (v.as_object_mut(), extra) {
        o.extend(e);
    }
    v
}

/// Builds the final log: the worker's repair log (or a minimal one) plus the daemon's
/// fields.
fn final_log(
    mut base: Value,
    status: &str,
    stage: Option<&str>,
    error: Option<&str>,
    daemon: Value,
) -> Value {
    if !base.is_object() {
        base = json!({ "holefill_version": env!("CARGO_PKG_VERSION") });
    }
    if let Some(o) = base.as_object_mut() {
        o.insert("status".into(), json!(status));
        o.insert("stage".into(), json!(stage));
        o.insert("error".into(), json!(error));
        o.insert("daemon".into(), daemon);
    }
    base
}

/// Writes `bytes` as `path` (temporary name, fsync, rename) and returns its identity.
fn write_file(path: &Path, bytes: &[u8]) -> io::Result<FileId> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let _ = fs::remove_file(&tmp);
    let mut f = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o644)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&tmp)?;
    let r = f
        .write_all(bytes)
        .and_then(|()| f.sync_all())
        .and_then(|()| fs::rename(&tmp, path));
    if r.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    r?;
    Ok(FileId::of(&f.metadata()?))
}

/// After a successful worker: chooses the names, writes the final log, records them,
/// then publishes ([`resume_repaired`]).
fn commit(ctx: &RunCtx, mut job: Job, t: Times, model: &Path, child_log: &Path, code: i32) -> Done {
    let l = &ctx.layout;
    let Some(model_id) = fs::symlink_metadata(model)
        .ok()
        .filter(|m| m.is_file())
        .map(|m| FileId::of(&m))
    else {
        if !job.home.tmp.is_dir() {
            return put_back(
                ctx,
                job,
                Some("the outbox's temporary folder vanished during the repair".into()),
                false,
            );
        }
        let e = format!("the worker exited {code} but wrote no model");
        return fail(ctx, job, t, "output", e, None, Some(code), true);
    };
    let Some(report) = read_json(child_log) else {
        let _ = fs::remove_file(model);
        let e = format!("the worker exited {code} but wrote no readable repair log");
        return fail(ctx, job, t, "output", e, None, Some(code), true);
    };
    let n = |k: &str| {
        report
            .pointer(&format!("/summary/{k}"))
            .and_then(Value::as_u64)
            .unwrap_or(0)
    };
    let name = job.name_str().unwrap_or_default().to_string();
    // a set: copies of its members for the outbox (the originals go to the archive)
    for i in 0..job.members().len() {
        let m = job.members()[i].clone();
        let shown = fsops::shown(m.name.as_ref());
        match sets::copy_member(&job.member_path(i), &job.tmp(&member_tmp(i)), m.stamp) {
            Ok(Some(id)) => {
                if let Some(set) = job.rec.set.as_mut() {
                    set.members[i].copy = Some(id);
                }
            }
            Ok(None) => {
                let e = format!(
                    "{shown} of its set changed while it was repaired; the set settles again"
                );
                return put_back(ctx, job, Some(e), true);
            }
            Err(e) => {
                let e = format!("cannot copy {shown} of its set: {e}");
                return put_back(ctx, job, Some(e), false);
            }
        }
    }
    let members: Vec<String> = job.members().iter().map(|m| m.name.clone()).collect();
    let when = SystemTime::now();
    let output = if !members.is_empty() && ctx.settings.collision == Collision::Timestamp {
        let names: Vec<&str> = members.iter().map(String::as_str).collect();
        if sets::all_free(&l.outbox, &name, &[".repair.json", ".repair.png"], &names) {
            name.clone()
        } else {
            match sets::new_folder(&l.outbox, &name, when) {
                Ok(sub) => format!("{sub}/{name}"),
                Err(e) => {
                    let e = format!("cannot make a folder for its set in the outbox: {e}");
                    return put_back(ctx, job, Some(e), false);
                }
            }
        }
    } else {
        fsops::free_name(
            &l.outbox,
            &name,
            &[".repair.json", ".repair.png"],
            when,
            ctx.settings.collision,
            0,
        )
    };
    let archive = (ctx.settings.on_success == OnSuccess::Archive)
        .then(|| set_place(&l.archive, &name, &members, &[], when));
    job.rec.phase = Phase::Repaired {
        output,
        archive,
        model: model_id,
        log: FileId { dev: 0, ino: 0 },
        code,
        filled: n("filled"),
        skipped: n("skipped"),
        failed: n("failed"),
    };
    if let Err(e) = write_repaired_log(ctx, &mut job, t, Some(&report)).and_then(|()| job.save()) {
        // nothing is published yet: the file goes back, to be tried again
        job.rec.phase = Phase::Claimed;
        return put_back(
            ctx,
            job,
            Some(format!("cannot record the repair: {e}")),
            false,
        );
    }
    ctx.hooks.at("committing", &job.name);
    resume_repaired(ctx, job, t, Some(&report), false)
}

/// Writes the final log of a repaired job into its temporary folder (with the output
/// and archive names of its record) and puts its identity into the record (not saved).
fn write_repaired_log(
    ctx: &RunCtx,
    job: &mut Job,
    t: Times,
    report: Option<&Value>,
) -> io::Result<()> {
    let l = &ctx.layout;
    let Phase::Repaired {
        output,
        archive,
        code,
        ..
    } = &job.rec.phase
    else {
        return Err(io::Error::other("not a repaired job"));
    };
    let model_path = l.outbox.join(output);
    let archived = archive
        .as_ref()
        .map(|a| l.archive.join(a).display().to_string());
    let set = set_info(
        job,
        Some(&place_dir(&l.outbox, output)),
        archive.as_deref().map(|a| (l.archive.as_path(), a)),
    );
    let base = report
        .cloned()
        .or_else(|| read_json(&job.tmp(".child.json")))
        .unwrap_or(Value::Null);
    let mut log = final_log(
        base,
        "repaired",
        None,
        None,
        daemon_info(
            ctx,
            job,
            t,
            "repaired",
            json!({
                "worker_exit": code,
                "output": model_path.display().to_string(),
                "original": if archive.is_some() { "archive" } else { "deleted" },
                "archived_as": archived,
                "set": set,
            }),
        ),
    );
    if let Some(o) = log.pointer_mut("/input/path") {
        *o = json!(fsops::shown(l.inbox.join(&job.name).as_os_str()));
    }
    if let Some(o) = log.pointer_mut("/output/path") {
        *o = json!(model_path.display().to_string());
    }
    let text = serde_json::to_string_pretty(&log).map_err(io::Error::other)?;
    let id = write_file(&job.tmp(".log.json"), text.as_bytes())?;
    if let Phase::Repaired { log, .. } = &mut job.rec.phase {
        *log = id;
    }
    Ok(())
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

/// The log's `daemon.set` object: the members, where each went, and the references
/// not followed. `None` for a single file.
fn set_info(job: &Job, out_dir: Option<&Path>, placed_in: Option<(&Path, &str)>) -> Option<Value> {
    let set = job.rec.set.as_ref()?;
    let members: Vec<Value> = set
        .members
        .iter()
        .map(|m| {
            let output = out_dir.map(|d| d.join(&m.name).display().to_string());
            let placed = placed_in.map(|(dir, rel)| {
                dir.join(
                    m.placed
                        .clone()
                        .unwrap_or_else(|| sets::beside(rel, &m.name)),
                )
                .display()
                .to_string()
            });
            json!({
                "name": fsops::shown(m.name.as_ref()),
                "role": m.role.what(),
                "named_by": fsops::shown(m.by.as_ref()),
                "bytes": m.stamp.size,
                "output": output,
                "original": placed,
            })
        })
        .collect();
    let refused: Vec<Value> = set
        .refused
        .iter()
        .map(|r| json!({ "reference": fsops::shown(r.reference.as_ref()), "named_by": fsops::shown(r.by.as_ref()), "why": r.why }))
        .collect();
    let missing: Vec<Value> = set
        .missing
        .iter()
        .map(|m| json!({ "name": fsops::shown(m.name.as_ref()), "role": m.role.what(), "named_by": fsops::shown(m.by.as_ref()) }))
        .collect();
    Some(json!({ "members": members, "not_followed": refused, "missing": missing }))
}

/// A step of the publish that cannot be done now.
fn later(job: Job, error: String) -> Done {
    Done::Later { job, error }
}

/// Publishes a repaired job from its record, each step only if not done yet (see the
/// module documentation). `resumed`: finishing the record of a daemon that died.
fn resume_repaired(
    ctx: &RunCtx,
    mut job: Job,
    t: Times,
    report: Option<&Value>,
    resumed: bool,
) -> Done {
    let l = &ctx.layout;
    let rule = ctx.settings.collision;
    let name = job.name_str().unwrap_or_default().to_string();
    let tmp_model = job.tmp(&format!(".{}", ext_of(&job)));
    let tmp_log = job.tmp(".log.json");
    for _ in 0..64 {
        let Phase::Repaired {
            output,
            archive,
            model,
            log,
            filled,
            skipped,
            failed,
            ..
        } = job.rec.phase.clone()
        else {
            return later(job, "internal error: not a repaired job".into());
        };
        let renamed = |job: &mut Job, skip_from: &str| -> io::Result<()> {
            // `output` (or its log) is someone else's: take the next free name
            let new = if job.members().is_empty() {
                let mut skip = 1;
                loop {
                    let cand = fsops::free_name(
                        &l.outbox,
                        &name,
                        &[".repair.json", ".repair.png"],
                        SystemTime::now(),
                        Collision::Timestamp,
                        skip,
                    );
                    if cand != skip_from {
                        break cand;
                    }
                    skip += 1;
                }
            } else {
                // a set moves whole into a new folder: no name changes, so the model's
                // and the MTL's references still find their files
                let sub = sets::new_folder(&l.outbox, &name, SystemTime::now())?;
                format!("{sub}/{name}")
            };
            let old_path = l.outbox.join(skip_from);
            if FileId::lstat(&old_path) == Some(model) {
                fsops::rename_noreplace(&old_path, &l.outbox.join(&new))?;
            }
            for m in job.members() {
                let old = l.outbox.join(sets::beside(skip_from, &m.name));
                if m.copy.is_some() && FileId::lstat(&old) == m.copy {
                    fsops::rename_noreplace(&old, &l.outbox.join(sets::beside(&new, &m.name)))?;
                }
            }
            if let Phase::Repaired { output, .. } = &mut job.rec.phase {
                *output = new;
            }
            write_repaired_log(ctx, job, t, report)?;
            job.save()
        };

        // 1. the model
        let out_path = l.outbox.join(&output);
        let there = FileId::lstat(&out_path);
        if there != Some(model) {
            if FileId::lstat(&tmp_model) == Some(model) {
                if there.is_some() && rule == Collision::Timestamp {
                    if let Err(e) = renamed(&mut job, &output) {
                        return later(job, format!("choosing another output name: {e}"));
                    }
                    continue;
                }
                if let Err(e) = ensure_place(&l.outbox, &output) {
                    return later(job, format!("making the set's folder in the outbox: {e}"));
                }
                match fsops::publish(&tmp_model, &out_path, rule) {
                    Ok(()) => {}
                    Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                    Err(e) => return later(job, format!("publishing the model: {e}")),
                }
                if let Err(e) = fsops::fsync_dir(&place_dir(&l.outbox, &output)) {
                    return later(job, format!("syncing the outbox: {e}"));
                }
                ctx.hooks.at("model-published", &job.name);
            } else if fs::symlink_metadata(job.path()).is_ok() {
                // the worker's model is lost (its folder removed): repair again
                job.rec.phase = Phase::Claimed;
                let _ = job.save();
                return later(
                    job,
                    "its repaired model was lost before it was published; it is repaired again"
                        .into(),
                );
            } else {
                tracing::error!(file = %job.shown(), "the repaired model {} is gone from the outbox (taken before its log was written?)", out_path.display());
            }
        }

        // 1b. the other files of its set, copies of the originals, byte for byte
        match publish_members(ctx, &mut job, &output, rule) {
            Step::Done => {}
            Step::Again => continue,
            Step::Rename => {
                if let Err(e) = renamed(&mut job, &output) {
                    return later(job, format!("choosing another folder for the set: {e}"));
                }
                continue;
            }
            Step::Later(e) => return later(job, e),
        }

        // 2a. the originals of the other files of its set, before the mesh's (whose
        // absence from the processing folder says the step is over)
        if fs::symlink_metadata(job.path()).is_ok() {
            match archive_members(ctx, &mut job, t, report, archive.as_deref()) {
                Step::Done => {}
                Step::Again | Step::Rename => continue,
                Step::Later(e) => return later(job, e),
            }
        }

        // 2. the original
        let src = job.path();
        if fs::symlink_metadata(&src).is_ok() {
            match &archive {
                Some(a) => {
                    let dst = l.archive.join(a);
                    if fs::symlink_metadata(&dst).is_ok() {
                        // ours, from before a crash (same inode, or a complete copy), or
                        // someone else's file under that name
                        if FileId::lstat(&dst) == FileId::lstat(&src)
                            || fsops::same_content(&src, &dst)
                        {
                            if let Err(e) = fs::remove_file(&src) {
                                return later(job, format!("removing the archived original from the processing folder: {e}"));
                            }
                        } else {
                            let new = if job.members().is_empty() {
                                fsops::free_name(
                                    &l.archive,
                                    &name,
                                    &[],
                                    SystemTime::now(),
                                    Collision::Timestamp,
                                    1,
                                )
                            } else {
                                let sub =
                                    sets::free_folder(&l.archive, &name, SystemTime::now(), 1);
                                format!("{sub}/{name}")
                            };
                            if let Phase::Repaired { archive, .. } = &mut job.rec.phase {
                                *archive = Some(new);
                            }
                            if let Err(e) = write_repaired_log(ctx, &mut job, t, report)
                                .and_then(|()| job.save())
                            {
                                return later(job, format!("recording another archive name: {e}"));
                            }
                            continue;
                        }
                    } else {
                        ctx.hooks.at("move", &job.name);
                        if let Err(e) = ensure_place(&l.archive, a) {
                            return later(
                                job,
                                format!("making the set's folder in the archive: {e}"),
                            );
                        }
                        let copy = format!(".holefill-{}.copy", job.id);
                        let linked = || ctx.hooks.at("archive-linked", &job.name);
                        match fsops::move_file(&src, &l.archive, a.as_ref(), &copy, &linked) {
                            Ok(()) => {}
                            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                            Err(e) => {
                                return later(
                                    job,
                                    format!(
                                        "archiving the original in {}: {e} (the model is in the outbox; its log follows once the original is archived)",
                                        l.archive.display()
                                    ),
                                )
                            }
                        }
                        if let Err(e) = fsops::fsync_dir(&place_dir(&l.archive, a)) {
                            return later(job, format!("syncing the archive: {e}"));
                        }
                    }
                }
                None => {
                    if let Err(e) = fs::remove_file(&src) {
                        return later(job, format!("deleting the original: {e}"));
                    }
                    if let Err(e) = fsops::fsync_dir(&job.home.dir) {
                        return later(job, format!("syncing the processing folder: {e}"));
                    }
                }
            }
            ctx.hooks.at("archived", &job.name);
        }

        // 3. the log
        let log_path = l.outbox.join(format!("{output}.repair.json"));
        let there = FileId::lstat(&log_path);
        if there != Some(log) {
            if FileId::lstat(&tmp_log) != Some(log) {
                // lost with the temporary folder: write it again
                if let Err(e) =
                    write_repaired_log(ctx, &mut job, t, report).and_then(|()| job.save())
                {
                    return later(job, format!("writing the log: {e}"));
                }
                continue;
            }
            if there.is_some() && rule == Collision::Timestamp {
                if let Err(e) = renamed(&mut job, &output) {
                    return later(job, format!("choosing another output name: {e}"));
                }
                continue;
            }
            publish_picture(&job, &l.outbox.join(format!("{output}.repair.png")), rule);
            match fsops::publish(&tmp_log, &log_path, rule) {
                Ok(()) => {}
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => return later(job, format!("publishing the log: {e}")),
            }
            if let Err(e) = fsops::fsync_dir(&l.outbox) {
                return later(job, format!("syncing the outbox: {e}"));
            }
            ctx.hooks.at("log-published", &job.name);
        }
        job.forget();
        for s in tmp_files(&job) {
            let _ = fs::remove_file(job.tmp(&s));
        }
        return Done::Repaired {
            job,
            output,
            filled,
            skipped,
            failed,
            secs: t.t0.elapsed().as_secs_f64(),
            resumed,
        };
    }
    later(
        job,
        "no free output or archive name after many tries".into(),
    )
}

/// How a step of a set's publish went.
enum Step {
    /// Done (or nothing to do).
    Done,
    /// Something changed (a record updated, a name taken meanwhile): the publish
    /// starts over from its record.
    Again,
    /// A name in the outbox is someone else's: the set moves to a new folder.
    Rename,
    /// Cannot be done now.
    Later(String),
}

/// Publishes the outbox copies of a set's members beside the model (`output`), each
/// only if not there yet (the outbox name holds the copy's inode). A copy lost with
/// the temporary folder is made again from the claimed member.
fn publish_members(ctx: &RunCtx, job: &mut Job, output: &str, rule: Collision) -> Step {
    let l = &ctx.layout;
    let mut published = false;
    for i in 0..job.members().len() {
        let m = job.members()[i].clone();
        let shown = fsops::shown(m.name.as_ref());
        let dst = l.outbox.join(sets::beside(output, &m.name));
        let there = FileId::lstat(&dst);
        if m.copy.is_some() && there == m.copy {
            continue;
        }
        let tmp = job.tmp(&member_tmp(i));
        if m.copy.is_none() || FileId::lstat(&tmp) != m.copy {
            let src = job.member_path(i);
            if fs::symlink_metadata(&src).is_err() {
                tracing::error!(file = %job.shown(), "{shown} of its set is neither in the outbox nor in the processing folder (removed by hand?)");
                continue;
            }
            {
                use std::os::unix::fs::DirBuilderExt;
                let _ = fs::DirBuilder::new().mode(0o700).create(&job.home.tmp);
            }
            match sets::copy_member(&src, &tmp, m.stamp) {
                Ok(Some(id)) => {
                    if let Some(set) = job.rec.set.as_mut() {
                        set.members[i].copy = Some(id);
                    }
                    if let Err(e) = job.save() {
                        return Step::Later(format!("recording the copy of {shown}: {e}"));
                    }
                    return Step::Again;
                }
                Ok(None) => {
                    return Step::Later(format!(
                        "{shown} of its set is not the file claimed any more"
                    ))
                }
                Err(e) => return Step::Later(format!("copying {shown} of its set: {e}")),
            }
        }
        if there.is_some() && rule == Collision::Timestamp {
            return Step::Rename;
        }
        match fsops::publish(&tmp, &dst, rule) {
            Ok(()) => published = true,
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => return Step::Again,
            Err(e) => return Step::Later(format!("publishing {shown} of its set: {e}")),
        }
    }
    if published {
        if let Err(e) = fsops::fsync_dir(&place_dir(&l.outbox, output)) {
            return Step::Later(format!("syncing the outbox: {e}"));
        }
        ctx.hooks.at("members-published", &job.name);
    }
    Step::Done
}

/// Moves the originals of a set's members beside the mesh's place `dest` in `dir`
/// (the archive or the failed folder; `None`: deleted), each only if still in the
/// processing folder. A name taken there by another file sends the set to a new
/// folder (`Again`, after `moved_on` recorded it).
fn place_members(
    ctx: &RunCtx,
    job: &mut Job,
    dir: &Path,
    dest: Option<&str>,
    moved_on: &mut dyn FnMut(&mut Job, String) -> io::Result<()>,
) -> Step {
    let mut moved = false;
    let name = job.name_str().unwrap_or_default().to_string();
    for i in 0..job.members().len() {
        let m = job.members()[i].clone();
        let shown = fsops::shown(m.name.as_ref());
        let src = job.member_path(i);
        if fs::symlink_metadata(&src).is_err() {
            continue;
        }
        let Some(dest) = dest else {
            if let Err(e) = fs::remove_file(&src) {
                return Step::Later(format!("deleting {shown} of its set: {e}"));
            }
            moved = true;
            continue;
        };
        let rel = sets::beside(dest, &m.name);
        let dst = dir.join(&rel);
        if fs::symlink_metadata(&dst).is_ok() {
            if FileId::lstat(&dst) == FileId::lstat(&src) || fsops::same_content(&src, &dst) {
                if let Err(e) = fs::remove_file(&src) {
                    return Step::Later(format!(
                        "removing {shown} from the processing folder: {e}"
                    ));
                }
                moved = true;
                continue;
            }
            let sub = sets::free_folder(dir, &name, SystemTime::now(), 1);
            if let Err(e) = moved_on(job, format!("{sub}/{name}")) {
                return Step::Later(format!("recording another folder for the set: {e}"));
            }
            return Step::Again;
        }
        if let Err(e) = ensure_place(dir, dest) {
            return Step::Later(format!("making the set's folder in {}: {e}", dir.display()));
        }
        ctx.hooks.at("move", &job.name);
        let copy = format!(".holefill-{}.m{i}.copy", job.id);
        match fsops::move_file(&src, &place_dir(dir, dest), m.name.as_ref(), &copy, &|| {}) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => return Step::Again,
            Err(e) => {
                return Step::Later(format!(
                    "moving {shown} of its set into {}: {e}",
                    dir.display()
                ))
            }
        }
        moved = true;
        if let Some(set) = job.rec.set.as_mut() {
            set.members[i].placed = Some(rel);
        }
        if let Err(e) = job.save() {
            tracing::warn!(file = %job.shown(), "cannot record where {shown} went: {e}");
        }
    }
    if moved {
        if let Some(d) = dest {
            if let Err(e) = fsops::fsync_dir(&place_dir(dir, d)) {
                return Step::Later(format!("syncing {}: {e}", dir.display()));
            }
        }
        let _ = fsops::fsync_dir(&job.home.dir);
    }
    Step::Done
}

/// The archive step of a set's members (see [`place_members`]).
fn archive_members(
    ctx: &RunCtx,
    job: &mut Job,
    t: Times,
    report: Option<&Value>,
    archive: Option<&str>,
) -> Step {
    let dir = ctx.layout.archive.clone();
    place_members(ctx, job, &dir, archive, &mut |job, new| {
        if let Phase::Repaired { archive, .. } = &mut job.rec.phase {
            *archive = Some(new);
        }
        write_repaired_log(ctx, job, t, report)?;
        job.save()
    })
}

/// The worker's picture of the repair, in the job's temporary folder.
const PICTURE: &str = ".png";

/// Moves the worker's picture (if it drew one) to `dst`, beside where the log goes
/// next. Best effort: a repair is complete without its picture, so a name taken by
/// someone else or an error loses only the picture (with a warning). After a crash the
/// picture is already there, or still in the temporary folder, or lost with that
/// folder.
fn publish_picture(job: &Job, dst: &Path, rule: Collision) {
    let tmp = job.tmp(PICTURE);
    if !fs::symlink_metadata(&tmp).is_ok_and(|m| m.is_file()) {
        return;
    }
    if let Err(e) = fsops::publish(&tmp, dst, rule) {
        tracing::warn!(file = %job.shown(), "{}: the picture is not published as {}: {e}", job.shown(), dst.display());
        let _ = fs::remove_file(&tmp);
    }
}

/// Sends the file, untouched, to the failed folder with its log (`kept` false: not a
/// regular file, removed instead): records the decision, then [`finish_failed`].
#[allow(clippy::too_many_arguments)]
fn fail(
    ctx: &RunCtx,
    mut job: Job,
    t: Times,
    stage: &str,
    error: String,
    report: Option<Value>,
    exit: Option<i32>,
    kept: bool,
) -> Done {
    for s in tmp_files(&job) {
        if s != ".log.json" {
            let _ = fs::remove_file(job.tmp(&s));
        }
    }
    let name = match job.name_str() {
        Some(n) => n.to_string(),
        None => fsops::safe_name(&job.name),
    };
    let members: Vec<String> = job.members().iter().map(|m| m.name.clone()).collect();
    let dest = set_place(
        &ctx.layout.failed,
        &name,
        &members,
        &[".repair.json"],
        SystemTime::now(),
    );
    job.rec.phase = Phase::Failed {
        dest,
        kept,
        stage: stage.to_string(),
        error,
        exit,
    };
    if let Err(e) = job.save() {
        tracing::warn!(file = %job.shown(), "cannot record the failure: {e}");
    }
    finish_failed(ctx, job, t, report)
}

/// Moves the original to the failed folder (or removes an entry that is not a regular
/// file) and writes its log there, each step only if not done yet.
fn finish_failed(ctx: &RunCtx, mut job: Job, t: Times, report: Option<Value>) -> Done {
    let l = &ctx.layout;
    for _ in 0..64 {
        let Phase::Failed {
            dest,
            kept,
            stage,
            error,
            exit,
        } = job.rec.phase.clone()
        else {
            return later(job, "internal error: not a failed job".into());
        };
        let src = job.path();
        let dst = l.failed.join(&dest);
        if fs::symlink_metadata(&src).is_ok() && !job.members().is_empty() {
            let failed_dir = l.failed.clone();
            let step = place_members(ctx, &mut job, &failed_dir, Some(&dest), &mut |job, new| {
                if let Phase::Failed { dest, .. } = &mut job.rec.phase {
                    *dest = new;
                }
                job.save()
            });
            match step {
                Step::Done => {}
                Step::Again | Step::Rename => continue,
                Step::Later(e) => return later(job, format!("{stage}: {error}; then {e}")),
            }
        }
        if fs::symlink_metadata(&src).is_ok() {
            if kept {
                if fs::symlink_metadata(&dst).is_ok() {
                    if FileId::lstat(&dst) == FileId::lstat(&src) || fsops::same_content(&src, &dst)
                    {
                        let _ = fs::remove_file(&src);
                    } else {
                        let base = dest.clone();
                        let new = fsops::free_name(
                            &l.failed,
                            &base,
                            &[".repair.json"],
                            SystemTime::now(),
                            Collision::Timestamp,
                            1,
                        );
                        if let Phase::Failed { dest, .. } = &mut job.rec.phase {
                            *dest = new;
                        }
                        let _ = job.save();
                        continue;
                    }
                } else {
                    ctx.hooks.at("move", &job.name);
                    if let Err(e) = ensure_place(&l.failed, &dest) {
                        return later(job, format!("{stage}: {error}; then making its folder in the failed folder: {e}"));
                    }
                    let copy = format!(".holefill-{}.copy", job.id);
                    match fsops::move_file(&src, &l.failed, dest.as_ref(), &copy, &|| {}) {
                        Ok(()) => {}
                        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
                            let new = fsops::free_name(
                                &l.failed,
                                &dest,
                                &[".repair.json"],
                                SystemTime::now(),
                                Collision::Timestamp,
                                1,
                            );
                            if let Phase::Failed { dest, .. } = &mut job.rec.phase {
                                *dest = new;
                            }
                            let _ = job.save();
                            continue;
                        }
                        Err(e) => {
                            return later(
                                job,
                                format!(
                                    "{stage}: {error}; then moving it to the failed folder: {e}"
                                ),
                            )
                        }
                    }
                    let _ = fsops::fsync_dir(&place_dir(&l.failed, &dest));
                }
            } else if let Err(e) = fs::remove_file(&src) {
                return later(job, format!("removing it: {e}"));
            }
            let _ = fsops::fsync_dir(&job.home.dir);
            ctx.hooks.at("failed-moved", &job.name);
        }
        let log_path = l.failed.join(format!("{dest}.repair.json"));
        if fs::symlink_metadata(&log_path).is_err() {
            let mut base = report.clone().unwrap_or_else(|| {
                json!({
                    "holefill_version": env!("CARGO_PKG_VERSION"),
                    "input": { "format": ext_of(&job) },
                })
            });
            let input = fsops::shown(l.inbox.join(&job.name).as_os_str());
            match base.pointer_mut("/input") {
                Some(Value::Object(o)) => {
                    o.insert("path".into(), json!(input));
                }
                _ => base["input"] = json!({ "path": input }),
            }
            let original = kept.then(|| dst.display().to_string());
            let set = set_info(&job, None, Some((l.failed.as_path(), dest.as_str())));
            let log = final_log(
                base,
                "failed",
                Some(&stage),
                Some(&error),
                daemon_info(
                    ctx,
                    &job,
                    t,
                    "failed",
                    json!({ "worker_exit": exit, "output": null, "original": original, "set": set }),
                ),
            );
            let text = serde_json::to_string_pretty(&log).unwrap_or_default();
            let tmp = l.failed.join(format!(".holefill-{}.log", job.id));
            let r = write_file(&tmp, text.as_bytes()).and_then(|_| {
                match fsops::rename_noreplace(&tmp, &log_path) {
                    Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(()),
                    r => r,
                }
            });
            let _ = fs::remove_file(&tmp);
            if let Err(e) = r {
                return later(
                    job,
                    format!("writing the failure log {}: {e}", log_path.display()),
                );
            }
            let _ = fsops::fsync_dir(&place_dir(&l.failed, &dest));
        }
        job.forget();
        return Done::Failed {
            job,
            stage,
            error,
            secs: t.t0.elapsed().as_secs_f64(),
        };
    }
    later(
        job,
        "no free name in the failed folder after many tries".into(),
    )
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
mod tests {
    use super::*;

    #[test]
    fn final_log_adds_the_daemon_fields() {
        let v = final_log(
            json!({"summary": {"filled": 1}}),
            "failed",
            Some("input"),
            Some("bad"),
            json!({"pid": 1}),
        );
        assert_eq!(v["status"], "failed");
        assert_eq!(v["stage"], "input");
        assert_eq!(v["error"], "bad");
        assert_eq!(v["daemon"]["pid"], 1);
        assert_eq!(v["summary"]["filled"], 1);
        let v = final_log(Value::Null, "repaired", None, None, json!({}));
        assert_eq!(v["status"], "repaired");
        assert!(v["error"].is_null());
    }
}
