//! Helpers of the daemon's integration tests: start the real binary (`holefill watch`)
//! on temporary folders, drop meshes, wait with bounded polling, read the logs.
#![allow(dead_code)]

#[path = "../common/mod.rs"]
mod common;

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
    /// Regular files (not dot-files) directly in `dir`, sorted.
    pub fn files(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .map(|rd| {
                rd.flatten()
                    .filter(|e| e.file_type().map(|t| t.is_file()).unwrap_or(false))
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .filter(|n| !n.starts_with('.'))
                    .collect()
            })
            .unwrap_or_default();
        v.sort();
        v
    }
    /// Files in any daemon's processing folder.
    pub fn processing(&self) -> Vec<String> {
        let mut v = Vec::new();
        if let Ok(rd) = fs::read_dir(self.inbox.join(".processing")) {
            for d in rd.flatten() {
                v.extend(Folders::files(&d.path()));
            }
        }
        v.sort();
        v
    }
    /// Models (not logs) in the outbox.
    pub fn models(&self) -> Vec<String> {
        Folders::files(&self.outbox)
            .into_iter()
            .filter(|n| !n.ends_with(".repair.json"))
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
        static N: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = N.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        let stderr = f.root().join(format!("daemon-{n}.log"));
        let err = fs::File::create(&stderr).unwrap();
        let mut cmd = Command::new(bin());
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
        let d = Daemon::start(f, extra, env);
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

/// Polls `cond` every 50 ms until true or `timeout`.
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
    (common::obj_text(&holed), holed.f.len())
}

/// The small test mesh (level 2: 320 faces, a small hole at the pole).
pub fn mesh() -> (String, usize) {
    holed_sphere_obj(2, 0.3)
}

/// Writes `text` as `dir/name` the recommended way: a dot-file, then rename.
pub fn drop_renamed(dir: &Path, name: &str, text: &str) {
    let tmp = dir.join(format!(".{name}.part"));
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
