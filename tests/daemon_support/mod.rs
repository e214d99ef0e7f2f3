//! Helpers of the daemon's integration tests: start the real binary (`holefill watch`)
//! on temporary folders, drop meshes, wait with bounded polling, read the logs. The
//! test declares `mod common;` beside `mod daemon_support;` (the shapes come from there).
#![allow(dead_code)]

use super::common;

use serde_json::Value;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_holefill"))
}

/// The four folders of a test, under one temporary folder.
pub struct Folders {
    pub tmp: tempfile::TempDir,
    pub inbox: PathBuf,
    pub outbox: PathBuf,
    pub failed: PathBuf,
    pub archive: PathBuf,
}

impl Folders {
    pub fn new() -> Folders {
        let tmp = tempfile::tempdir().expect("tempdir");
        let root = tmp.path().to_path_buf();
        let f = Folders {
            inbox: root.join("inbox"),
            outbox: root.join("outbox"),
            failed: root.join("failed"),
            archive: root.join("archive"),
            tmp,
        };
        fs::create_dir_all(&f.inbox).unwrap();
        f
    }
    pub fn root(&self) -> &Path {
        self.tmp.path()
    }
    /// Regular files (not dot-files) directly in `dir`, sorted; the outbox's
    /// `index.html` left out (it lists files, it is not one's output).
    pub fn files(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .map(|rd| {
                rd.flatten()
                    .filter(|e| e.file_type().map(|t| t.is_file()).unwrap_or(false))
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| !n.starts_with('.') && n != "index.html")
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }
    /// The names of the files in any daemon's processing folder (read from their job
    /// records, `ID.json` beside each claimed file `ID`).
    pub fn processing(&self) -> Vec<String> {
        let mut v = Vec::new();
        if let Ok(rd) = fs::read_dir(self.inbox.join(".processing")) {
            for d in rd.flatten() {
                if d.file_name().to_string_lossy().starts_with('.') {
                    continue;
                }
                let Ok(files) = fs::read_dir(d.path()) else {
                    continue;
                };
                for e in files.flatten() {
                    let n = e.file_name().to_string_lossy().into_owned();
                    let Some(id) = n.strip_suffix(".json") else {
                        // a file without a record (an older holefill's layout)
                        let rec = d.path().join(format!("{n}.json"));
                        if !n.starts_with('.')
                            && !n.ends_with(".tmp")
                            && e.file_type().is_ok_and(|t| t.is_file())
                            && !rec.exists()
                        {
                            v.push(n);
                        }
                        continue;
                    };
                    if fs::symlink_metadata(d.path().join(id)).is_err() {
                        continue;
                    }
                    let rec: Value = fs::read(e.path())
                        .ok()
                        .and_then(|b| serde_json::from_slice(&b).ok())
                        .unwrap_or(Value::Null);
                    if let Some(name) = rec["name"].as_str() {
                        v.push(name.to_string());
                    }
                }
            }
        }
        v.sort();
        v
    }
    /// Every entry (any type, dot-files too) directly in `dir`, sorted.
    pub fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .map(|rd| {
                rd.flatten()
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }
    /// Models (not logs, not pictures) in the outbox.
    pub fn models(&self) -> Vec<String> {
        Folders::files(&self.outbox)
            .into_iter()
            .filter(|n| !n.ends_with(".repair.json") && !n.ends_with(".repair.png"))
            .collect()
    }
    pub fn log(dir: &Path, name: &str) -> Value {
        let p = dir.join(format!("{name}.repair.json"));
        let b = fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        serde_json::from_slice(&b).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    }
}

/// A running `holefill watch`, killed when dropped.
pub struct Daemon {
    pub child: Child,
    pub stderr: PathBuf,
}

impl Daemon {
    /// Starts `holefill watch` on the folders with extra flags and environment.
    pub fn start(f: &Folders, extra: &[&str], env: &[(&str, &str)]) -> Daemon {
        Daemon::start_under(f, &[], extra, env)
    }
    /// [`Daemon::start`] through a wrapper command (`setpriv ...`, `unshare ...`).
    pub fn start_under(
        f: &Folders,
        wrapper: &[&str],
        extra: &[&str],
        env: &[(&str, &str)],
    ) -> Daemon {
        static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = N.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        let stderr = f.root().join(format!("daemon-{n}.log"));
        let err = fs::File::create(&stderr).unwrap();
        let mut cmd = match wrapper.split_first() {
            Some((w, rest)) => {
                let mut c = Command::new(w);
                c.args(rest).arg(bin());
                c
            }
            None => Command::new(bin()),
        };
        cmd.arg("watch")
            .arg("--inbox")
            .arg(&f.inbox)
            .arg("--outbox")
            .arg(&f.outbox)
            .arg("--failed")
            .arg(&f.failed)
            .arg("--archive")
            .arg(&f.archive)
            .args(extra)
            .env_remove("NOTIFY_SOCKET")
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(err);
        for (k, v) in [
            ("--settle-ms", "300"),
            ("--rescan-secs", "5"),
            ("--workers", "2"),
        ] {
            if !extra.contains(&k) {
                cmd.args([k, v]);
            }
        }
        for (k, v) in env {
            cmd.env(k, v);
        }
        let child = cmd.spawn().expect("start holefill watch");
        Daemon { child, stderr }
    }
    /// [`Daemon::start`], then waits for its start-up scan to be over.
    pub fn ready(f: &Folders, extra: &[&str], env: &[(&str, &str)]) -> Daemon {
        Daemon::ready_under(f, &[], extra, env)
    }
    /// [`Daemon::start_under`], then waits for its start-up scan to be over.
    pub fn ready_under(
        f: &Folders,
        wrapper: &[&str],
        extra: &[&str],
        env: &[(&str, &str)],
    ) -> Daemon {
        let d = Daemon::start_under(f, wrapper, extra, env);
        assert!(
            wait_until(Duration::from_secs(20), || d
                .log()
                .contains("holefill watch ready")),
            "not ready: {}",
            d.log()
        );
        d
    }
    /// Waits until the journal has `n` lines containing `what`.
    pub fn wait_log(&self, what: &str, n: usize) -> bool {
        wait_until(Duration::from_secs(20), || {
            self.log().matches(what).count() >= n
        })
    }
    pub fn pid(&self) -> u32 {
        self.child.id()
    }
    pub fn log(&self) -> String {
        fs::read_to_string(&self.stderr).unwrap_or_default()
    }
    pub fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
    pub fn signal(&self, sig: &str) {
        let st = Command::new("kill")
            .args(["-s", sig, &self.pid().to_string()])
            .status()
            .unwrap();
        assert!(st.success(), "kill -s {sig}");
    }
    /// Waits for the exit; `None` on timeout.
    pub fn wait_exit(&mut self, timeout: Duration) -> Option<std::process::ExitStatus> {
        let t = Instant::now();
        while t.elapsed() < timeout {
            if let Ok(Some(st)) = self.child.try_wait() {
                return Some(st);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        None
    }
    /// SIGKILL and reap (so that its pid is gone, not a zombie).
    pub fn kill9(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if matches!(self.child.try_wait(), Ok(None)) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// The peak resident memory of a process in KiB (`VmHWM`).
pub fn vmhwm_kib(pid: u32) -> u64 {
    let s = fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    s.lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// The children of a process (for a daemon started through a wrapper).
pub fn children_of(pid: u32) -> Vec<u32> {
    let mut v = Vec::new();
    if let Ok(rd) = fs::read_dir(format!("/proc/{pid}/task")) {
        for t in rd.flatten() {
            if let Ok(c) = fs::read_to_string(t.path().join("children")) {
                v.extend(c.split_whitespace().filter_map(|x| x.parse::<u32>().ok()));
            }
        }
    }
    v
}

/// Sends a signal to a process by pid.
pub fn kill(pid: u32, sig: &str) -> bool {
    Command::new("kill")
        .args(["-s", sig, &pid.to_string()])
        .status()
        .is_ok_and(|s| s.success())
}

/// True when the tests run as root.
pub fn is_root() -> bool {
    rustix::process::geteuid().is_root()
}

/// Exchanges two names atomically (`renameat2(RENAME_EXCHANGE)`).
pub fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use rustix::fs::{renameat_with, RenameFlags, CWD};
    renameat_with(CWD, a, CWD, b, RenameFlags::EXCHANGE).map_err(Into::into)
}

/// A mount made by a test, lazily unmounted when dropped.
pub struct Mount(pub PathBuf);
impl Mount {
    /// `mount ARGS... TARGET`; `None` when it fails.
    pub fn new(args: &[&str], target: &Path) -> Option<Mount> {
        let ok = Command::new("mount")
            .args(args)
            .arg(target)
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        ok.then(|| Mount(target.to_path_buf()))
    }
    /// A read-only bind mount of `dir` on itself.
    pub fn read_only(dir: &Path) -> Option<Mount> {
        let d = dir.to_str()?;
        let m = Mount::new(&["--bind", d], dir)?;
        let ok = Command::new("mount")
            .args(["-o", "remount,ro,bind"])
            .arg(dir)
            .status()
            .is_ok_and(|s| s.success());
        ok.then_some(m)
    }
}
impl Drop for Mount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

/// Polls `cond` every 50 ms until true or `timeout`.
/// Waits until the folder `dir` holds exactly the files `want` (as [`Folders::files`]
/// lists them): a repair's picture follows its log.
pub fn wait_files(dir: &Path, want: &[&str]) -> bool {
    wait_until(Duration::from_secs(30), || Folders::files(dir) == want)
}

/// Whether `dir` comes to hold the model `name` and its log, once, and its picture or
/// not: the picture is drawn by a daemon's child after the model, at the lowest CPU
/// priority, so a daemon killed while publishing may die before it is drawn (its
/// successor publishes it when it is there and never draws it again). Waits up to 30 s.
pub fn published_once(dir: &Path, name: &str) -> bool {
    let picture = format!("{name}.repair.png");
    let want = [name.to_string(), format!("{name}.repair.json")];
    wait_until(Duration::from_secs(30), || {
        let mut files = Folders::files(dir);
        files.retain(|n| *n != picture);
        files == want
    })
}

pub fn wait_until(timeout: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let t = Instant::now();
    loop {
        if cond() {
            return true;
        }
        if t.elapsed() >= timeout {
            return false;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A closed unit sphere (icosahedron subdivided `level` times) with one hole: the faces
/// whose centroid is within `r` of the north pole are removed. OBJ text and the face
/// count.
pub fn holed_sphere_obj(level: usize, r: f64) -> (String, usize) {
    let (holed, _) = common::cut(&common::icosphere(level), [0.0, 0.0, 1.0], r);
    (holed.obj_text(), holed.f.len())
}

/// The small test mesh (level 2: 320 faces, a small hole at the pole).
pub fn mesh() -> (String, usize) {
    holed_sphere_obj(2, 0.3)
}

/// Writes `text` as `dir/name` the recommended way: a dot-file, then rename.
pub fn drop_renamed(dir: &Path, name: &str, text: &str) {
    static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = N.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
    let tmp = dir.join(format!(".drop-{n}.part"));
    fs::write(&tmp, text).unwrap();
    fs::rename(&tmp, dir.join(name)).unwrap();
}

/// Writes `text` in place, in `chunks` pieces over `total` (one open file).
pub fn write_slowly(path: &Path, text: &str, chunks: usize, total: Duration) {
    let mut f = fs::File::create(path).unwrap();
    let bytes = text.as_bytes();
    let step = bytes.len().div_ceil(chunks);
    for (i, c) in bytes.chunks(step).enumerate() {
        f.write_all(c).unwrap();
        f.flush().unwrap();
        if i + 1 < chunks {
            std::thread::sleep(total / chunks as u32);
        }
    }
}
