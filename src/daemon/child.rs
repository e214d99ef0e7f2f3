//! The isolated repair child, shared by the inbox daemon and the queue worker
//! (`holefill worker`): one `holefill fill` process per repair, under limits.
//!
//! Each repair is a child process (the running executable), so a crash, a runaway
//! allocation or a hang is contained. The memory limit is the child's address space
//! (`RLIMIT_AS`); setting it takes `pre_exec` or `setrlimit`, both `unsafe`, which the
//! crate forbids, so the child is started through `/bin/sh -c 'ulimit -v KB; ulimit -t
//! CPU; exec "$0" "$@"' holefill fill ...` (the shell sets the limits on itself and
//! replaces itself by `holefill`). The wall-clock limit is the caller's: past it the
//! child's process group is killed. Each child has a process group of its own, so a
//! Ctrl-C on the terminal does not kill the repairs its parent lets finish, and raises
//! its own `oom_score_adj` to 1000, so that under memory pressure the kernel kills a
//! child (a failed attempt) rather than its parent.

use super::hooks::Hooks;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;
use tokio::io::{AsyncBufReadExt, AsyncReadExt, BufReader};
use tokio::sync::{oneshot, watch};

/// How children are started: the executable, the policy and the limits.
#[derive(Clone, Copy, Debug)]
pub struct Spec<'a> {
    /// The `holefill` executable (the running one).
    pub exe: &'a Path,
    /// `None`: the built-in default policy.
    pub policy: Option<&'a Path>,
    /// 0: no limit.
    pub max_file_bytes: u64,
    /// 0: no limit.
    pub max_faces: u64,
    /// 0: no limit.
    pub max_vertices: u64,
    /// Wall clock; `None`: no limit.
    pub time_limit: Option<Duration>,
    /// Address space; 0: no limit.
    pub memory_limit_mb: u64,
    /// Cores of the machine (the CPU-time backstop is the wall-clock limit on all).
    pub cores: usize,
    /// Test-only hooks (slow or crashing children).
    pub hooks: &'a Hooks,
    /// Where the child draws its picture of the repair (`fill --picture`); `None`: none.
    pub picture: Option<&'a Path>,
    /// The files of the mesh's set that its reader needs (glTF buffers), by the name
    /// the mesh gives them (`fill --resource NAME PATH`).
    pub resources: &'a [(String, PathBuf)],
}

/// What the child reads.
#[derive(Clone, Copy, Debug)]
pub enum Input<'a> {
    /// An open, checked file handed over as standard input and read as
    /// `/proc/self/fd/0` (the daemon: no path is opened twice).
    Stdin(&'a fs::File),
    /// A path in a folder only the caller writes (the queue worker's private copy,
    /// beside the other files of its set).
    Path(&'a Path),
}

/// How the child ended.
#[derive(Debug)]
pub enum ChildEnd {
    Exit(i32),
    Signal(i32),
    Timeout(Duration),
    Cancelled,
    SpawnError(io::Error),
    /// Repaired elsewhere and failed there (the gateway: a queue worker's outcome),
    /// with the stage and error of the worker's log.
    Remote {
        stage: String,
        error: String,
    },
}

/// Runs `holefill fill INPUT OUT --input-format EXT --report LOG` under the limits of
/// `spec`; `name` (the file's name) selects the test hooks. Ends early, killing the
/// child's process group, on the time limit or when `cancel` turns true. Returns how
/// it ended and the tail of its standard error; with a picture to draw, as soon as the
/// child says its model and log are written: then its exit status is the one it
/// announced, and the [`Drawing`] is the child drawing the picture.
pub async fn run(
    spec: &Spec<'_>,
    name: &str,
    input: Input<'_>,
    ext: &str,
    out: &Path,
    log: &Path,
    cancel: &mut watch::Receiver<bool>,
) -> (ChildEnd, Vec<u8>, Option<Drawing>) {
    let (stdin, input_path): (Stdio, &Path) = match input {
        Input::Stdin(f) => match f.try_clone() {
            Ok(f) => (Stdio::from(f), Path::new("/proc/self/fd/0")),
            Err(e) => return (ChildEnd::SpawnError(e), Vec::new(), None),
        },
        Input::Path(p) => (Stdio::null(), p),
    };
    let mut cmd = tokio::process::Command::new("/bin/sh");
    cmd.arg("-c").arg(wrapper_script(spec, name)).arg(spec.exe);
    cmd.arg("fill")
        .arg(input_path)
        .arg(out)
        .arg("--input-format")
        .arg(ext)
        .arg("--report")
        .arg(log)
        .arg("--quiet");
    if let Some(p) = spec.policy {
        cmd.arg("--policy").arg(p);
    }
    // the picture is drawn after the child announces its model and log written
    let deferred = spec.picture.is_some();
    if let Some(p) = spec.picture {
        cmd.arg("--picture").arg(p).arg("--picture-after-log");
    }
    // the files a mesh names are read from its set's members only (never beside
    // /proc/self/fd/0)
    if matches!(input, Input::Stdin(_)) {
        cmd.arg("--only-resources");
    }
    for (name, path) in spec.resources {
        cmd.arg("--resource").arg(name).arg(path);
    }
    // the read limits, enforced by the reader too: the header sniff cannot count
    // vertices, nor triangles of fanned polygons
    for (flag, value) in [
        ("--max-file-bytes", spec.max_file_bytes),
        ("--max-faces", spec.max_faces),
        ("--max-vertices", spec.max_vertices),
    ] {
        if value > 0 {
            cmd.arg(flag).arg(value.to_string());
        }
    }
    cmd.stdin(stdin)
        .stdout(if deferred {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stderr(Stdio::piped())
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env_remove("WATCHDOG_PID")
        .env_remove("HOLEFILL_TEST_SLOW")
        .env_remove("HOLEFILL_TEST_SLOW_PICTURE")
        .env_remove(super::hooks::PICTURE_SLEEP_MS)
        .env_remove("HOLEFILL_TEST_CRASH_ON")
        .env_remove("HOLEFILL_TEST_DIE_AT")
        .env_remove("HOLEFILL_TEST_PAUSE_AT")
        .process_group(0)
        .kill_on_drop(true);
    let mut child = match cmd.spawn() {
        Ok(c) => c,
        Err(e) => return (ChildEnd::SpawnError(e), Vec::new(), None),
    };
    if let Some(m) = crate::metrics::global() {
        m.attempts.inc();
    }
    let pid = child.id();
    // keep only the tail of stderr, however much the child writes
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
    // `written CODE` on stdout: the model and the log are written, the picture follows
    let announced = child.stdout.take().map(|out| {
        let (tx, rx) = oneshot::channel();
        tokio::spawn(async move {
            let mut lines = BufReader::new(out).lines();
            let mut tx = Some(tx);
            while let Ok(Some(line)) = lines.next_line().await {
                let code = line.strip_prefix("written ").and_then(|c| c.parse().ok());
                if let Some(code) = code {
                    if let Some(tx) = tx.take() {
                        let _ = tx.send(code);
                    }
                }
            }
        });
        rx
    });
    let limit = spec.time_limit;
    let deadline = limit.map(|d| tokio::time::Instant::now() + d);
    let written = async {
        match announced {
            Some(rx) => match rx.await {
                Ok(code) => code,
                // no announcement: the exit decides
                Err(_) => std::future::pending().await,
            },
            None => std::future::pending().await,
        }
    };
    let end = tokio::select! {
        end = wait_until(&mut child, pid, deadline, limit, cancel) => end,
        code = written => {
            let drawing = Drawing { child, pid, reader, deadline, limit, code };
            return (ChildEnd::Exit(code), Vec::new(), Some(drawing));
        }
    };
    (end, tail_of(reader).await, None)
}

/// Waits for the child's exit until `deadline` or until `cancel` turns true (then
/// `Timeout` or `Cancelled`, the child's process group killed).
async fn wait_until(
    child: &mut tokio::process::Child,
    pid: Option<u32>,
    deadline: Option<tokio::time::Instant>,
    limit: Option<Duration>,
    cancel: &mut watch::Receiver<bool>,
) -> ChildEnd {
    let sleep = async {
        match deadline {
            Some(t) => tokio::time::sleep_until(t).await,
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
        kill(child, pid).await;
    }
    end
}

/// SIGKILL to the child's process group, then the child reaped.
async fn kill(child: &mut tokio::process::Child, pid: Option<u32>) {
    kill_group(pid);
    let _ = child.kill().await;
}

/// The tail of the child's stderr once it is closed (at most 2 s after the exit).
async fn tail_of(reader: Option<tokio::task::JoinHandle<Vec<u8>>>) -> Vec<u8> {
    match reader {
        Some(h) => match tokio::time::timeout(Duration::from_secs(2), h).await {
            Ok(Ok(t)) => t,
            _ => Vec::new(),
        },
        None => Vec::new(),
    }
}

/// A child that wrote its model and log and now draws its picture, at the lowest CPU
/// priority, under what is left of its time limit. Dropped, it is killed.
#[derive(Debug)]
pub struct Drawing {
    child: tokio::process::Child,
    pid: Option<u32>,
    reader: Option<tokio::task::JoinHandle<Vec<u8>>>,
    deadline: Option<tokio::time::Instant>,
    limit: Option<Duration>,
    /// The exit status it announced.
    code: i32,
}

impl Drawing {
    /// Waits for the picture: `Ok` when the child exits with the status it announced,
    /// else why not (killed at the time limit or when `cancel` turns true).
    pub async fn finish(mut self, cancel: &mut watch::Receiver<bool>) -> Result<(), String> {
        let end = wait_until(&mut self.child, self.pid, self.deadline, self.limit, cancel).await;
        let msg = stderr_message(&tail_of(self.reader.take()).await).replace("warning: ", "");
        match end {
            ChildEnd::Exit(c) if c == self.code && msg.is_empty() => Ok(()),
            ChildEnd::Exit(c) if c == self.code => Err(msg),
            ChildEnd::Cancelled => Err("the daemon is stopping".into()),
            end => Err(crash_reason(0, end, &msg)),
        }
    }

    /// Kills the child and waits for it to end (its picture is not wanted).
    pub async fn abandon(mut self) {
        kill(&mut self.child, self.pid).await;
    }
}

/// The shell script that applies the limits (and test hooks) and execs the child.
fn wrapper_script(spec: &Spec<'_>, name: &str) -> String {
    // the child, not its parent, is the kernel's OOM killer's first choice
    let mut script = String::from("{ echo 1000 > /proc/self/oom_score_adj; } 2>/dev/null; ");
    if spec.memory_limit_mb > 0 {
        script.push_str(&format!(
            "ulimit -v {} || exit 125; ",
            spec.memory_limit_mb.saturating_mul(1024)
        ));
    }
    if let Some(t) = spec.time_limit {
        // CPU seconds: every core busy for the whole wall-clock limit, plus a margin
        let cpu = t
            .as_secs()
            .saturating_mul(spec.cores.max(1) as u64)
            .saturating_add(60);
        script.push_str(&format!("ulimit -t {cpu} 2>/dev/null; "));
    }
    script.push_str(&spec.hooks.worker_prefix(name));
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

/// Why a child that neither repaired nor failed cleanly ended (a crashed attempt).
pub fn crash_reason(memory_limit_mb: u64, end: ChildEnd, msg: &str) -> String {
    let tail = if msg.is_empty() {
        String::new()
    } else {
        format!(": {msg}")
    };
    match end {
        ChildEnd::Timeout(d) => format!("time limit of {} s exceeded: worker killed", d.as_secs()),
        ChildEnd::Signal(sig) if msg.contains("memory allocation") => format!(
            "memory limit of {memory_limit_mb} MiB exceeded: worker died (signal {sig}){tail}"
        ),
        ChildEnd::Signal(sig) if memory_limit_mb > 0 && matches!(sig, 6 | 11) => {
            format!(
                "worker killed by signal {sig} (an allocation past memory_limit_mb = {memory_limit_mb} MiB?){tail}"
            )
        }
        ChildEnd::Signal(sig) => format!("worker killed by signal {sig}{tail}"),
        ChildEnd::Exit(125) => "the worker's limits could not be applied (ulimit)".to_string(),
        ChildEnd::Exit(code) => format!("worker crashed (exit {code}){tail}"),
        ChildEnd::Cancelled => "worker stopped".to_string(),
        ChildEnd::SpawnError(e) => format!("cannot start the worker: {e}"),
        ChildEnd::Remote { error, .. } => error,
    }
}

/// SIGKILL to the child's whole process group (the child and anything it started).
pub fn kill_group(pid: Option<u32>) {
    let Some(pid) = pid.and_then(|p| rustix::process::Pid::from_raw(p as i32)) else {
        return;
    };
    let _ = rustix::process::kill_process_group(pid, rustix::process::Signal::KILL);
}

/// The last meaningful line(s) of the child's stderr.
pub fn stderr_message(tail: &[u8]) -> String {
    let s = String::from_utf8_lossy(tail);
    let lines: Vec<&str> = s
        .lines()
        .map(|l| l.trim().trim_start_matches("error: "))
        .filter(|l| !l.is_empty())
        .collect();
    let n = lines.len();
    lines[n.saturating_sub(3)..].join(" | ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stderr_message_keeps_the_last_lines() {
        assert_eq!(stderr_message(b"a\n\nb\nc\nerror: d\n"), "b | c | d");
        assert_eq!(stderr_message(b""), "");
    }

    #[test]
    fn the_wrapper_applies_the_limits_before_the_exec() {
        let hooks = Hooks::default();
        let spec = Spec {
            exe: Path::new("/x/holefill"),
            policy: None,
            max_file_bytes: 0,
            max_faces: 0,
            max_vertices: 0,
            time_limit: Some(Duration::from_secs(10)),
            memory_limit_mb: 100,
            cores: 2,
            hooks: &hooks,
            picture: None,
            resources: &[],
        };
        let s = wrapper_script(&spec, "a.obj");
        let v = s.find("ulimit -v 102400").expect("memory limit");
        let t = s.find("ulimit -t 80").expect("cpu limit");
        let e = s.find("exec \"$0\" \"$@\"").expect("exec");
        assert!(v < e && t < e, "{s}");
    }
}
