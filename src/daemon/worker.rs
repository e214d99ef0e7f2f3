//! One repair: the limits, the `holefill fill` child process under a time and memory
//! limit, and what becomes of the file (outbox, failed folder, back into the inbox).
//!
//! Isolation: each repair is a child process, `holefill fill IN OUT --report LOG`
//! (the daemon's own executable), so that a crash, a runaway allocation or a hang is
//! contained. The memory limit is the child's address-space limit (`RLIMIT_AS`). Setting
//! it in the child takes `pre_exec` or `libc::setrlimit`, both `unsafe`, which the
//! crate forbids; so the child is started through `/bin/sh -c 'ulimit -v KB; exec
//! "$0" "$@"' holefill fill ...`: the shell sets the limit on itself and replaces itself
//! by `holefill` (same pid, the limit inherited). The same script sets a CPU-time limit
//! (`ulimit -t`) as a backstop that also holds for a worker orphaned by a daemon killed
//! with SIGKILL. The wall-clock time limit is the daemon's: past it the child's process
//! group is killed (SIGKILL). Each child gets a process group of its own, so a Ctrl-C
//! on the daemon's terminal does not kill the repairs the daemon lets finish.
//!
//! Exit statuses of `holefill fill`: 0 and 2 (some holes left open) are repairs;
//! 65 (malformed input) and 70 (internal error) are permanent failures; 74 (I/O, such
//! as a full disk) and 78 (invalid policy) are retryable (the file goes back into the
//! inbox and is retried with a back-off); a signal, a timeout or any other status is a
//! crashed attempt, retried up to `max_attempts`, then a failure.
//!
//! Test-only hooks (read from the daemon's environment at start, never set in
//! production): `HOLEFILL_TEST_SLOW=SUBSTR:MS` makes the worker of every file whose
//! name contains SUBSTR sleep MS milliseconds before the repair (an empty SUBSTR
//! matches every file); `HOLEFILL_TEST_CRASH_ON=SUBSTR` makes it kill itself with
//! SIGKILL (as the kernel's OOM killer would).

use super::claim::{self, Layout, Sidecar};
use super::config::{Collision, OnSuccess, Settings};
use super::fsops;
use super::sniff;
use serde_json::{json, Value};
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};
use tokio::io::AsyncReadExt;
use tokio::sync::watch;

/// Test-only hooks (see the module documentation).
#[derive(Clone, Debug, Default)]
pub struct TestHooks {
    pub slow: Option<(String, u64)>,
    pub crash_on: Option<String>,
}

impl TestHooks {
    /// Reads `HOLEFILL_TEST_SLOW` and `HOLEFILL_TEST_CRASH_ON`.
    pub fn from_env() -> TestHooks {
        let slow = std::env::var("HOLEFILL_TEST_SLOW").ok().and_then(|v| {
            let (s, ms) = v.rsplit_once(':')?;
            Some((s.to_string(), ms.parse().ok()?))
        });
        let crash_on = std::env::var("HOLEFILL_TEST_CRASH_ON")
            .ok()
            .filter(|s| !s.is_empty());
        TestHooks { slow, crash_on }
    }
}

/// What every job of one configuration generation shares.
#[derive(Debug)]
pub struct RunCtx {
    pub layout: Layout,
    pub host: String,
    pub pid: u32,
    pub settings: Settings,
    /// The validated policy snapshot passed to the workers (`None`: built-in default).
    pub policy: Option<PathBuf>,
    /// The policy file it was read from.
    pub policy_source: Option<PathBuf>,
    pub exe: PathBuf,
    pub hooks: TestHooks,
    pub cores: usize,
}

/// A claimed file.
#[derive(Clone, Debug)]
pub struct Job {
    /// Its name in the inbox and in our processing folder.
    pub name: String,
    /// This attempt's number (1-based).
    pub attempt: u32,
    /// When it was first seen (RFC 3339).
    pub received: String,
}

/// How a job ended.
#[derive(Debug)]
pub enum Done {
    /// Model and log in the outbox.
    Repaired {
        name: String,
        output: String,
        filled: u64,
        skipped: u64,
        failed: u64,
        secs: f64,
    },
    /// In the failed folder with its log.
    Failed {
        name: String,
        stage: &'static str,
        error: String,
        secs: f64,
    },
    /// The worker crashed, hung or was killed; attempts are left: the file stays in our
    /// folder and is tried again.
    Again { job: Job, error: String },
    /// Back in the inbox under `inbox_name` (retryable failure, or shutdown).
    PutBack {
        name: String,
        inbox_name: String,
        error: Option<String>,
    },
    /// Could not be moved anywhere; it stays in our processing folder.
    Stranded { name: String, error: String },
}

impl Done {
    /// The file's name.
    pub fn name(&self) -> &str {
        match self {
            Done::Repaired { name, .. }
            | Done::Failed { name, .. }
            | Done::PutBack { name, .. }
            | Done::Stranded { name, .. } => name,
            Done::Again { job, .. } => &job.name,
        }
    }
}

/// How the child ended.
#[derive(Debug)]
enum ChildEnd {
    Exit(i32),
    Signal(i32),
    Timeout(Duration),
    Cancelled,
    SpawnError(io::Error),
}

/// Runs one attempt on a claimed file and disposes of it.
pub async fn process(ctx: Arc<RunCtx>, job: Job, mut cancel: watch::Receiver<bool>) -> Done {
    let started = SystemTime::now();
    let t0 = Instant::now();
    let input = ctx.layout.mine.join(&job.name);
    // recovered from daemons that died while repairing it, max_attempts times
    if job.attempt > ctx.settings.max_attempts {
        let started_attempts = job.attempt - 1;
        let err = format!(
            "{started_attempts} attempts were started and none finished (the worker or the daemon died each time); max_attempts = {}",
            ctx.settings.max_attempts
        );
        let job = Job {
            attempt: started_attempts,
            ..job
        };
        return blocking(ctx.clone(), move |c| {
            fail(&c, &job, started, t0, "worker", err, None, None)
        })
        .await;
    }
    let sidecar = Sidecar {
        attempts: job.attempt,
        received: job.received.clone(),
    };
    if let Err(e) = sidecar.write(&ctx.layout.sidecar(&job.name)) {
        tracing::warn!(file = %job.name, "cannot record the attempt count: {e}");
    }

    // limits checked before any worker runs
    let s = &ctx.settings;
    match fs::metadata(&input) {
        Ok(m) if s.max_file_bytes > 0 && m.len() > s.max_file_bytes => {
            let err = format!(
                "file size {} bytes > max_file_bytes = {}",
                m.len(),
                s.max_file_bytes
            );
            return blocking(ctx.clone(), move |c| {
                fail(&c, &job, started, t0, "limits", err, None, None)
            })
            .await;
        }
        Ok(_) => {}
        Err(e) => {
            return Done::Stranded {
                name: job.name,
                error: format!("claimed file unreadable: {e}"),
            }
        }
    }
    // unreadable (permissions): permanent, and the worker would report it as a
    // retryable I/O error
    if let Err(e) = fs::File::open(&input) {
        if e.kind() == io::ErrorKind::PermissionDenied {
            let err = format!("cannot read the file: {e}");
            return blocking(ctx.clone(), move |c| {
                fail(&c, &job, started, t0, "input", err, None, None)
            })
            .await;
        }
    }
    if s.max_faces > 0 {
        let p = input.clone();
        let faces = tokio::task::spawn_blocking(move || sniff::declared_faces(&p))
            .await
            .ok()
            .flatten();
        if let Some(n) = faces.filter(|&n| n > s.max_faces) {
            let err = format!("{n} faces > max_faces = {}", s.max_faces);
            return blocking(ctx.clone(), move |c| {
                fail(&c, &job, started, t0, "limits", err, None, None)
            })
            .await;
        }
    }

    let out = ctx.layout.tmp.join(&job.name);
    let log = ctx.layout.tmp.join(format!("{}.child.json", job.name));
    let _ = fs::remove_file(&out);
    let _ = fs::remove_file(&log);
    let (end, stderr) = run_child(&ctx, &job.name, &input, &out, &log, &mut cancel).await;
    let msg = stderr_message(&stderr).replace(
        &input.display().to_string(),
        &ctx.layout.inbox.join(&job.name).display().to_string(),
    );
    let ctx2 = ctx.clone();
    match end {
        ChildEnd::Exit(code @ (0 | 2)) => {
            blocking(ctx2, move |c| {
                finish_repaired(&c, &job, started, t0, &out, &log, code).unwrap_or_else(
                    |(stage, e, retry)| {
                        let _ = fs::remove_file(&out);
                        if retry {
                            put_back(&c, &job.name, Some(format!("{stage}: {e}")))
                        } else {
                            fail(&c, &job, started, t0, stage, e, None, Some(code))
                        }
                    },
                )
            })
            .await
        }
        ChildEnd::Exit(65) => {
            blocking(ctx2, move |c| {
                fail(
                    &c,
                    &job,
                    started,
                    t0,
                    "input",
                    or(msg, "unreadable or malformed input (exit 65)"),
                    None,
                    Some(65),
                )
            })
            .await
        }
        ChildEnd::Exit(70) => {
            blocking(ctx2, move |c| {
                fail(
                    &c,
                    &job,
                    started,
                    t0,
                    "repair",
                    or(msg, "internal error (exit 70)"),
                    None,
                    Some(70),
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
            blocking(ctx2, move |c| put_back(&c, &job.name, Some(e))).await
        }
        ChildEnd::Cancelled => {
            blocking(ctx2, move |c| {
                put_back(&c, &job.name, Some("daemon stopping".into()))
            })
            .await
        }
        ChildEnd::SpawnError(e) => {
            let e = format!("cannot start the worker: {e}");
            blocking(ctx2, move |c| put_back(&c, &job.name, Some(e))).await
        }
        end => {
            let why = match end {
                ChildEnd::Timeout(d) => {
                    format!("time limit of {} s exceeded: worker killed", d.as_secs())
                }
                ChildEnd::Signal(sig) if msg.contains("memory allocation") => format!(
                    "memory limit of {} MiB exceeded: worker died (signal {sig}): {msg}",
                    ctx.settings.memory_limit_mb
                ),
                ChildEnd::Signal(sig) if ctx.settings.memory_limit_mb > 0 && matches!(sig, 6 | 11) => format!(
                    "worker killed by signal {sig} (an allocation past memory_limit_mb = {} MiB?){}",
                    ctx.settings.memory_limit_mb,
                    if msg.is_empty() {
                        String::new()
                    } else {
                        format!(": {msg}")
                    }
                ),
                ChildEnd::Signal(sig) => format!(
                    "worker killed by signal {sig}{}",
                    if msg.is_empty() {
                        String::new()
                    } else {
                        format!(": {msg}")
                    }
                ),
                ChildEnd::Exit(125) => {
                    "the worker's limits could not be applied (ulimit)".to_string()
                }
                ChildEnd::Exit(code) => format!(
                    "worker crashed (exit {code}){}",
                    if msg.is_empty() {
                        String::new()
                    } else {
                        format!(": {msg}")
                    }
                ),
                _ => "worker ended".to_string(),
            };
            let _ = fs::remove_file(&out);
            let _ = fs::remove_file(&log);
            if job.attempt >= ctx.settings.max_attempts {
                let e = format!(
                    "{why} (attempt {} of {}; giving up)",
                    job.attempt, ctx.settings.max_attempts
                );
                blocking(ctx2, move |c| {
                    fail(&c, &job, started, t0, "worker", e, None, None)
                })
                .await
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

/// Runs a blocking disposition off the async runtime.
async fn blocking<F>(ctx: Arc<RunCtx>, f: F) -> Done
where
    F: FnOnce(Arc<RunCtx>) -> Done + Send + 'static,
{
    tokio::task::spawn_blocking(move || f(ctx))
        .await
        .unwrap_or_else(|e| Done::Stranded {
            name: String::new(),
            error: format!("internal error in the disposition: {e}"),
        })
}

/// The last meaningful line(s) of the child's stderr.
fn stderr_message(tail: &[u8]) -> String {
    let s = String::from_utf8_lossy(tail);
    let lines: Vec<&str> = s
        .lines()
        .map(|l| l.trim().trim_start_matches("error: "))
        .filter(|l| !l.is_empty())
        .collect();
    let n = lines.len();
    lines[n.saturating_sub(3)..].join(" | ")
}

/// The shell script that applies the limits (and test hooks) and execs the worker.
fn wrapper_script(ctx: &RunCtx, name: &str) -> String {
    let mut script = String::new();
    if ctx.settings.memory_limit_mb > 0 {
        script.push_str(&format!(
            "ulimit -v {} || exit 125; ",
            ctx.settings.memory_limit_mb.saturating_mul(1024)
        ));
    }
    if let Some(t) = ctx.settings.time_limit {
        // CPU seconds: every core busy for the whole wall-clock limit, plus a margin
        let cpu = t
            .as_secs()
            .saturating_mul(ctx.cores.max(1) as u64)
            .saturating_add(60);
        script.push_str(&format!("ulimit -t {cpu} 2>/dev/null; "));
    }
    if let Some((sub, ms)) = &ctx.hooks.slow {
        if name.contains(sub.as_str()) {
            script.push_str(&format!("sleep {}.{:03}; ", ms / 1000, ms % 1000));
        }
    }
    if let Some(sub) = &ctx.hooks.crash_on {
        if name.contains(sub.as_str()) {
            script.push_str("kill -KILL $$; ");
        }
    }
    script.push_str("exec \"$0\" \"$@\"");
    script
}

/// Checks that the shell can apply the configured limits.
pub fn probe_limits(memory_limit_mb: u64) -> anyhow::Result<()> {
    if memory_limit_mb == 0 {
        return Ok(());
    }
    let st = std::process::Command::new("/bin/sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v {}",
            memory_limit_mb.saturating_mul(1024)
        ))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .map_err(|e| anyhow::anyhow!("/bin/sh is needed to start workers under limits: {e}"))?;
    if !st.success() {
        anyhow::bail!("memory_limit_mb = {memory_limit_mb} cannot be applied (ulimit -v refused; above the hard limit?)");
    }
    Ok(())
}

async fn run_child(
    ctx: &RunCtx,
    name: &str,
    input: &Path,
    out: &Path,
    log: &Path,
    cancel: &mut watch::Receiver<bool>,
) -> (ChildEnd, Vec<u8>) {
    let mut cmd = tokio::process::Command::new("/bin/sh");
    cmd.arg("-c").arg(wrapper_script(ctx, name)).arg(&ctx.exe);
    cmd.arg("fill")
        .arg(input)
        .arg(out)
        .arg("--report")
        .arg(log)
        .arg("--quiet");
    if let Some(p) = &ctx.policy {
        cmd.arg("--policy").arg(p);
    }
    // the read limits, enforced by the reader too: the header sniff above cannot
    // count vertices, nor triangles of fanned polygons
    let s = &ctx.settings;
    for (flag, value) in [
        ("--max-file-bytes", s.max_file_bytes),
        ("--max-faces", s.max_faces),
        ("--max-vertices", s.max_vertices),
    ] {
        if value > 0 {
            cmd.arg(flag).arg(value.to_string());
        }
    }
    cmd.stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("WATCHDOG_PID")
        .env_remove("HOLEFILL_TEST_SLOW")
        .env_remove("HOLEFILL_TEST_CRASH_ON")
        .process_group(0)
        .kill_on_drop(true);
    let mut child = match cmd.spawn() {
        Ok(c) => c,
        Err(e) => return (ChildEnd::SpawnError(e), Vec::new()),
    };
    let pid = child.id();
    // keep only the tail of stderr, however much the worker writes
    let reader = child.stderr.take().map(|mut err| {
        tokio::spawn(async move {
            let mut tail: Vec<u8> = Vec::new();
            let mut buf = [0u8; 4096];
            loop {
                match err.read(&mut buf).await {
                    Ok(0) | Err(_) => break,
                    Ok(n) => {
                        tail.extend_from_slice(&buf[..n]);
                        if tail.len() > 8192 {
                            tail.drain(..tail.len() - 4096);
                        }
                    }
                }
            }
            tail
        })
    });
    let limit = ctx.settings.time_limit;
    let sleep = async {
        match limit {
            Some(d) => tokio::time::sleep(d).await,
            None => std::future::pending().await,
        }
    };
    let cancelled = async {
        loop {
            if *cancel.borrow_and_update() {
                return;
            }
            if cancel.changed().await.is_err() {
                std::future::pending::<()>().await;
            }
        }
    };
    let end = tokio::select! {
        st = child.wait() => match st {
            Ok(st) => {
                use std::os::unix::process::ExitStatusExt;
                match (st.code(), st.signal()) {
                    (Some(c), _) => ChildEnd::Exit(c),
                    (None, Some(s)) => ChildEnd::Signal(s),
                    _ => ChildEnd::Exit(-1),
                }
            }
            Err(e) => ChildEnd::SpawnError(e),
        },
        _ = sleep => ChildEnd::Timeout(limit.unwrap_or_default()),
        _ = cancelled => ChildEnd::Cancelled,
    };
    if matches!(end, ChildEnd::Timeout(_) | ChildEnd::Cancelled) {
        kill_group(pid).await;
        let _ = child.kill().await;
    }
    let tail = match reader {
        Some(h) => match tokio::time::timeout(Duration::from_secs(2), h).await {
            Ok(Ok(t)) => t,
            _ => Vec::new(),
        },
        None => Vec::new(),
    };
    (end, tail)
}

/// SIGKILL to the worker's whole process group (the worker and anything it started).
async fn kill_group(pid: Option<u32>) {
    let Some(pid) = pid else { return };
    let _ = tokio::process::Command::new("/bin/sh")
        .arg("-c")
        .arg("kill -s KILL -- \"-$1\" 2>/dev/null")
        .arg("sh")
        .arg(pid.to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .await;
}

/// The `"daemon"` object of a log.
#[allow(clippy::too_many_arguments)]
fn daemon_info(
    ctx: &RunCtx,
    job: &Job,
    started: SystemTime,
    t0: Instant,
    status: &str,
    output: Option<&Path>,
    original: Option<String>,
    exit: Option<i32>,
) -> Value {
    json!({
        "host": ctx.host,
        "pid": ctx.pid,
        "input": job.name,
        "received": job.received,
        "started": fsops::rfc3339(started),
        "finished": fsops::rfc3339(SystemTime::now()),
        "seconds": t0.elapsed().as_secs_f64(),
        "attempt": job.attempt,
        "max_attempts": ctx.settings.max_attempts,
        "status": status,
        "worker_exit": exit,
        "output": output.map(|p| p.display().to_string()),
        "original": original,
        "policy": ctx.policy_source.as_ref().map(|p| p.display().to_string()),
    })
}

/// The format name of a file name's extension.
fn format_of(name: &str) -> Option<String> {
    let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
    Some(ext)
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

type FinishErr = (&'static str, String, bool);

/// Publishes the worker's model and the log (model first, log last), then archives or
/// deletes the original. `Err((stage, error, retryable))`.
fn finish_repaired(
    ctx: &RunCtx,
    job: &Job,
    started: SystemTime,
    t0: Instant,
    tmp_model: &Path,
    child_log: &Path,
    code: i32,
) -> Result<Done, FinishErr> {
    let l = &ctx.layout;
    let io_err = |what: &str, e: io::Error| -> FinishErr {
        let retry = fsops::is_disk_full(&e) || e.kind() != io::ErrorKind::InvalidData;
        ("output", format!("{what}: {e}"), retry)
    };
    if !tmp_model.is_file() {
        return Err((
            "output",
            format!("the worker exited {code} but wrote no model"),
            false,
        ));
    }
    let report: Value = fs::read(child_log)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .ok_or_else(|| {
            (
                "output",
                format!("the worker exited {code} but wrote no readable repair log"),
                false,
            )
        })?;
    let summary = |k: &str| {
        report
            .pointer(&format!("/summary/{k}"))
            .and_then(Value::as_u64)
            .unwrap_or(0)
    };
    let (filled, skipped, failed) = (summary("filled"), summary("skipped"), summary("failed"));

    let when = SystemTime::now();
    let rule = ctx.settings.collision;
    let mut skip = 0;
    let (final_name, log_path) = loop {
        if skip > 1000 {
            return Err(("output", "no free output name".into(), false));
        }
        let name = fsops::free_name(&l.outbox, &job.name, &[".repair.json"], when, rule, skip);
        let model_path = l.outbox.join(&name);
        let log_path = l.outbox.join(format!("{name}.repair.json"));
        let original = match ctx.settings.on_success {
            OnSuccess::Archive => Some("archive".to_string()),
            OnSuccess::Delete => Some("deleted".to_string()),
        };
        let mut log = final_log(
            report.clone(),
            "repaired",
            None,
            None,
            daemon_info(
                ctx,
                job,
                started,
                t0,
                "repaired",
                Some(&model_path),
                original,
                Some(code),
            ),
        );
        if let Some(o) = log.pointer_mut("/input/path") {
            *o = json!(l.inbox.join(&job.name).display().to_string());
        }
        if let Some(o) = log.pointer_mut("/output/path") {
            *o = json!(model_path.display().to_string());
        }
        let text =
            serde_json::to_string_pretty(&log).map_err(|e| ("output", e.to_string(), false))?;
        let tmp_log = l.tmp.join(format!("{name}.repair.json"));
        holefill::io::write_atomic(&tmp_log, text.as_bytes()).map_err(|e| match e {
            holefill::io::IoError::Io { source, .. } => io_err("writing the log", source),
            other => ("output", other.to_string(), true),
        })?;
        match fsops::publish(tmp_model, &model_path, rule) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
                let _ = fs::remove_file(&tmp_log);
                skip += 1;
                continue;
            }
            Err(e) => {
                let _ = fs::remove_file(&tmp_log);
                return Err(io_err("publishing the model", e));
            }
        }
        match fsops::publish(&tmp_log, &log_path, rule) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
                let _ = fs::remove_file(&model_path);
                let _ = fs::remove_file(&tmp_log);
                skip += 1;
                continue;
            }
            Err(e) => {
                if rule == Collision::Timestamp {
                    let _ = fs::remove_file(&model_path);
                }
                let _ = fs::remove_file(&tmp_log);
                return Err(io_err("publishing the log", e));
            }
        }
        let _ = fs::remove_file(&tmp_log);
        break (name, log_path);
    };
    if let Err(e) = fsops::fsync_dir(&l.outbox) {
        tracing::warn!(file = %job.name, "fsync of the outbox failed: {e}");
    }
    let _ = fs::remove_file(child_log);

    // only now the original (the worker's model stays linked in our temporary folder
    // until the original is gone: a daemon recovering our files after a crash here
    // recognises the published output by its inode)
    let src = l.mine.join(&job.name);
    let moved = match ctx.settings.on_success {
        OnSuccess::Archive => fsops::move_into(&src, &l.archive, &job.name, &[]).map(|p| {
            let _ = fsops::fsync_dir(&l.archive);
            p.display().to_string()
        }),
        OnSuccess::Delete => fs::remove_file(&src).map(|()| "deleted".to_string()),
    };
    let _ = fs::remove_file(l.sidecar(&job.name));
    let _ = fsops::fsync_dir(&l.mine);
    let _ = fs::remove_file(tmp_model);
    match moved {
        Ok(_) => Ok(Done::Repaired {
            name: job.name.clone(),
            output: final_name,
            filled,
            skipped,
            failed,
            secs: t0.elapsed().as_secs_f64(),
        }),
        Err(e) => {
            tracing::error!(file = %job.name, log = %log_path.display(), "repaired, but the original could not be archived: {e}");
            Ok(Done::Stranded {
                name: job.name.clone(),
                error: format!(
                    "repaired as {final_name}, but the original could not be archived: {e}"
                ),
            })
        }
    }
}

/// Moves the original, untouched, to the failed folder and writes its log there.
#[allow(clippy::too_many_arguments)]
fn fail(
    ctx: &RunCtx,
    job: &Job,
    started: SystemTime,
    t0: Instant,
    stage: &'static str,
    error: String,
    report: Option<Value>,
    exit: Option<i32>,
) -> Done {
    let l = &ctx.layout;
    let src = l.mine.join(&job.name);
    let dst = match fsops::move_into(&src, &l.failed, &job.name, &[".repair.json"]) {
        Ok(p) => p,
        Err(e) => {
            tracing::error!(file = %job.name, "cannot move to the failed folder: {e}");
            return put_back(
                ctx,
                &job.name,
                Some(format!(
                    "{stage}: {error}; then moving it to the failed folder: {e}"
                )),
            );
        }
    };
    let _ = fs::remove_file(l.sidecar(&job.name));
    let _ = fsops::fsync_dir(&l.mine);
    let mut base = report.unwrap_or_else(|| {
        json!({
            "holefill_version": env!("CARGO_PKG_VERSION"),
            "input": { "path": l.inbox.join(&job.name).display().to_string(), "format": format_of(&job.name) },
        })
    });
    if let Some(o) = base.pointer_mut("/input/path") {
        *o = json!(l.inbox.join(&job.name).display().to_string());
    }
    let log = final_log(
        base,
        "failed",
        Some(stage),
        Some(&error),
        daemon_info(
            ctx,
            job,
            started,
            t0,
            "failed",
            None,
            Some(dst.display().to_string()),
            exit,
        ),
    );
    let log_path = {
        let mut p = dst.as_os_str().to_owned();
        p.push(".repair.json");
        PathBuf::from(p)
    };
    let text = serde_json::to_string_pretty(&log).unwrap_or_default();
    if let Err(e) = holefill::io::write_atomic(&log_path, text.as_bytes()) {
        tracing::error!(file = %job.name, "cannot write the failure log {}: {e}", log_path.display());
    }
    let _ = fsops::fsync_dir(&l.failed);
    Done::Failed {
        name: job.name.clone(),
        stage,
        error,
        secs: t0.elapsed().as_secs_f64(),
    }
}

/// Puts the file back into the inbox (retry later).
pub fn put_back(ctx: &RunCtx, name: &str, error: Option<String>) -> Done {
    let _ = fs::remove_file(ctx.layout.tmp.join(name));
    let _ = fs::remove_file(ctx.layout.tmp.join(format!("{name}.child.json")));
    match claim::put_back(&ctx.layout, name) {
        Ok(inbox_name) => Done::PutBack {
            name: name.to_string(),
            inbox_name,
            error,
        },
        Err(e) => Done::Stranded {
            name: name.to_string(),
            error: format!(
                "{}; and it could not be put back into the inbox: {e}",
                error.unwrap_or_default()
            ),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stderr_tail_keeps_the_last_lines() {
        assert_eq!(stderr_message(b"a\n\nb\nc\nerror: d\n"), "b | c | d");
        assert_eq!(stderr_message(b""), "");
    }

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
