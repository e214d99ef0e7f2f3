//! Helpers of the queue worker's integration tests: a real `nats-server` with
//! JetStream on a free loopback port and a temporary store, stopped (and its store
//! removed) when dropped; the real binary as workers, submitter and results taker. The
//! test declares `mod common;` and `mod metrics_support;` beside `mod worker_support;`.
#![allow(dead_code)]

use super::common::{icosphere, Soup};
use serde_json::Value;
use std::collections::HashMap;
use std::fs;
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

pub fn bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_holefill"))
}

/// The `nats-server` binary (`HOLEFILL_NATS_SERVER`, else on PATH or in /usr/sbin).
pub fn nats_server_bin() -> PathBuf {
    if let Some(p) = std::env::var_os("HOLEFILL_NATS_SERVER") {
        return PathBuf::from(p);
    }
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/usr/local/sbin")])
        .map(|d| d.join("nats-server"))
        .find(|p| p.is_file())
        .expect("nats-server is not installed (apt-get install nats-server)")
}

/// A nats-server on 127.0.0.1 with JetStream, its store in a temporary folder.
pub struct Nats {
    pub port: u16,
    pub store: tempfile::TempDir,
    child: Option<Child>,
    log: PathBuf,
}

impl Nats {
    pub fn start() -> Nats {
        let port = free_port();
        let store = tempfile::tempdir().expect("tempdir");
        let log = store.path().join("server.log");
        let mut n = Nats {
            port,
            store,
            child: None,
            log,
        };
        n.spawn();
        n
    }

    fn spawn(&mut self) {
        let js = self.store.path().join("js");
        let log = fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.log)
            .unwrap();
        let child = Command::new(nats_server_bin())
            .args([
                "-js",
                "-a",
                "127.0.0.1",
                "-p",
                &self.port.to_string(),
                "-sd",
            ])
            .arg(&js)
            .stdout(Stdio::from(log.try_clone().unwrap()))
            .stderr(Stdio::from(log))
            .spawn()
            .expect("start nats-server");
        self.child = Some(child);
        let t = Instant::now();
        while TcpStream::connect(("127.0.0.1", self.port)).is_err() {
            assert!(
                t.elapsed() < Duration::from_secs(20),
                "nats-server did not start:\n{}",
                self.server_log()
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    pub fn url(&self) -> String {
        format!("nats://127.0.0.1:{}", self.port)
    }

    /// SIGKILL, then a new server on the same port and store.
    pub fn restart(&mut self, down: Duration) {
        self.kill();
        std::thread::sleep(down);
        self.spawn();
    }

    /// The server stops answering for `d` (SIGSTOP, then SIGCONT): the connections
    /// stay open and the requests sent meanwhile time out.
    pub fn freeze(&self, d: Duration) {
        let pid = self
            .child
            .as_ref()
            .expect("a running server")
            .id()
            .to_string();
        let signal = |s: &str| {
            let ok = Command::new("kill")
                .args([s, &pid])
                .status()
                .is_ok_and(|st| st.success());
            assert!(ok, "kill {s} {pid}");
        };
        signal("-STOP");
        std::thread::sleep(d);
        signal("-CONT");
    }

    pub fn kill(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    pub fn server_log(&self) -> String {
        fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Nats {
    fn drop(&mut self) {
        self.kill();
    }
}

// every test crate that includes this module includes metrics_support too
use super::metrics_support::free_port;

/// A `holefill worker` process; killed when dropped. Its stderr goes to a file.
pub struct Worker {
    pub child: Child,
    pub log: PathBuf,
    _dir: tempfile::TempDir,
}

impl Worker {
    pub fn start(nats: &Nats, args: &[&str], env: &[(&str, &str)]) -> Worker {
        let dir = tempfile::tempdir().expect("tempdir");
        let log = dir.path().join("worker.log");
        let f = fs::File::create(&log).unwrap();
        let mut cmd = Command::new(bin());
        cmd.args([
            "worker",
            "--nats",
            &nats.url(),
            "--workers",
            "1",
            "--work-dir",
        ])
        .arg(dir.path())
        .args(args)
        .env("RUST_LOG", "info,async_nats=warn")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::from(f));
        for (k, v) in env {
            cmd.env(k, v);
        }
        let child = cmd.spawn().expect("start holefill worker");
        Worker {
            child,
            log,
            _dir: dir,
        }
    }

    pub fn log(&self) -> String {
        fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// The keys this worker reported repaired (`repaired KEY` lines).
    pub fn repaired(&self) -> Vec<String> {
        lines_after(&self.log(), " done: repaired ")
    }

    pub fn failed(&self) -> Vec<String> {
        lines_after(&self.log(), " done: failed ")
    }

    pub fn kill9(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    pub fn is_ready(&self) -> bool {
        self.log().contains("worker ready")
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn lines_after(log: &str, marker: &str) -> Vec<String> {
    log.lines()
        .filter_map(|l| {
            let i = l.find(marker)?;
            l[i + marker.len()..]
                .split_whitespace()
                .next()
                .map(String::from)
        })
        .collect()
}

/// Runs `holefill ARGS`; panics with its output when it fails.
pub fn holefill(args: &[&str]) -> Output {
    let out = Command::new(bin())
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run holefill");
    assert!(
        out.status.success(),
        "holefill {args:?}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Submits files (paths) and returns the keys, in order.
pub fn submit(nats: &Nats, files: &[PathBuf]) -> Vec<String> {
    let mut args: Vec<String> = vec!["submit".into(), "--nats".into(), nats.url()];
    args.extend(files.iter().map(|p| p.display().to_string()));
    let a: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
    let out = holefill(&a);
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.strip_prefix("queued ").or(l.strip_prefix("duplicate ")))
        .map(String::from)
        .collect()
}

/// Downloads what is done into `dir` (`holefill results`, not watching).
pub fn results(nats: &Nats, dir: &Path) {
    holefill(&["results", "--nats", &nats.url(), &dir.display().to_string()]);
}

/// Runs `holefill results` into `dir` (failures ignored: the server may be away) until
/// `n` repair logs are there or `timeout` passes; whether they are.
pub fn results_until(nats: &Nats, dir: &Path, n: usize, timeout: Duration) -> bool {
    wait_until(timeout, || {
        let _ = Command::new(bin())
            .args(["results", "--nats", &nats.url()])
            .arg(dir)
            .output();
        logs(dir).len() >= n
    })
}

/// Repair logs (`*.repair.json`) directly in `dir`, by name.
pub fn logs(dir: &Path) -> HashMap<String, Value> {
    let mut m = HashMap::new();
    for e in fs::read_dir(dir).into_iter().flatten().flatten() {
        let n = e.file_name().to_string_lossy().into_owned();
        if n.ends_with(".repair.json") {
            let v: Value = serde_json::from_slice(&fs::read(e.path()).unwrap())
                .unwrap_or_else(|err| panic!("{n}: {err}"));
            m.insert(n, v);
        }
    }
    m
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
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A small closed sphere with a hole at the pole, made distinct by `i` (a translation),
/// as OBJ text (level 1: 80 faces before the cut; every vertex kept).
pub fn holed_obj(i: usize) -> String {
    let s = icosphere(1);
    // the hole: faces whose centroid is near the north pole (+y)
    let f =
        s.f.iter()
            .copied()
            .filter(|f| f.iter().map(|&k| s.v[k][1]).sum::<f64>() / 3.0 <= 0.8)
            .collect();
    let v = s.v.iter().map(|p| [p[0] + i as f64, p[1], p[2]]).collect();
    Soup { v, f }.obj_text()
}

/// Writes `n` distinct holed meshes `sNNN.obj` into `dir`; their paths.
pub fn write_meshes(dir: &Path, prefix: &str, n: usize) -> Vec<PathBuf> {
    (0..n)
        .map(|i| {
            let p = dir.join(format!("{prefix}{i:03}.obj"));
            fs::write(&p, holed_obj(i)).unwrap();
            p
        })
        .collect()
}
