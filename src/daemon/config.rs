//! The daemon's configuration: `config/holefill.toml` (every key documented there),
//! overridden by command-line flags, resolved into [`Settings`].

use super::WatchArgs;
use anyhow::{bail, Context, Result};
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// What to do with an original once its repaired model and log are in the outbox.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum OnSuccess {
    /// Move it into the archive folder.
    Archive,
    /// Delete it.
    Delete,
}

/// What to do when the output name is already taken in the outbox (or the failed or
/// archive folder).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Collision {
    /// `scan01.obj` taken: write `scan01.20261123T120501Z.obj` (UTC time of writing),
    /// then `scan01.20261123T120501Z-2.obj`, ... ; the log follows the model's name.
    Timestamp,
    /// Replace the earlier model and log (each replaced atomically). Opt-in only.
    Overwrite,
}

/// Journal format.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// Human-readable lines.
    Text,
    /// One JSON object per line.
    Json,
}

/// The config file as written (every key optional).
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct FileConfig {
    pub inbox: Option<PathBuf>,
    pub outbox: Option<PathBuf>,
    pub failed: Option<PathBuf>,
    pub archive: Option<PathBuf>,
    pub policy: Option<PathBuf>,
    pub workers: Option<usize>,
    pub max_pending: Option<usize>,
    pub settle_ms: Option<u64>,
    pub rescan_secs: Option<u64>,
    pub poll: Option<bool>,
    pub poll_ms: Option<u64>,
    pub max_attempts: Option<u32>,
    pub max_file_bytes: Option<u64>,
    pub max_faces: Option<u64>,
    pub max_vertices: Option<u64>,
    pub time_limit_secs: Option<u64>,
    pub memory_limit_mb: Option<u64>,
    pub grace_secs: Option<u64>,
    pub retry_max_secs: Option<u64>,
    pub max_wait_secs: Option<u64>,
    pub set_wait_secs: Option<u64>,
    pub on_success: Option<OnSuccess>,
    pub collision: Option<Collision>,
    pub log_format: Option<LogFormat>,
    pub picture: Option<bool>,
    pub index_entries: Option<usize>,
    pub metrics: Option<String>,
    /// Forward claimed files to this NATS server's work queue (`watch --forward`).
    pub forward: Option<String>,
    /// The queue (`holefill worker`, `submit`, `results`): see crate::worker::config.
    pub nats: Option<crate::worker::config::NatsFile>,
}

impl FileConfig {
    /// Reads a config file.
    pub fn from_file(path: &Path) -> Result<FileConfig> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the config file", path.display()))?;
        toml::from_str(&text).map_err(|e| {
            let line = e
                .span()
                .map(|s| text[..s.start.min(text.len())].lines().count().max(1));
            anyhow::anyhow!(
                "{}{}: {}",
                path.display(),
                line.map(|l| format!(":{l}")).unwrap_or_default(),
                e.message().trim()
            )
        })
    }
}

/// The resolved settings the daemon runs with.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub inbox: PathBuf,
    pub outbox: PathBuf,
    pub failed: PathBuf,
    pub archive: PathBuf,
    /// `None`: the built-in default policy.
    pub policy: Option<PathBuf>,
    pub workers: usize,
    /// Most files remembered as waiting in the inbox; more are found by later rescans.
    pub max_pending: usize,
    pub settle: Duration,
    pub rescan: Duration,
    pub poll: bool,
    pub poll_interval: Duration,
    pub max_attempts: u32,
    /// 0: no limit.
    pub max_file_bytes: u64,
    /// 0: no limit.
    pub max_faces: u64,
    /// 0: no limit.
    pub max_vertices: u64,
    /// `None`: no limit.
    pub time_limit: Option<Duration>,
    /// 0: no limit.
    pub memory_limit_mb: u64,
    pub grace: Duration,
    pub retry_max: Duration,
    /// A file held open by a writer, or empty, waits at most this long unchanged.
    pub max_wait: Duration,
    /// A set (an OBJ with its MTL and images) whose member is still missing this long
    /// after the mesh was taken or the last member came goes to failed.
    pub set_wait: Duration,
    pub on_success: OnSuccess,
    pub collision: Collision,
    pub log_format: LogFormat,
    /// Write `NAME.repair.png` beside each repaired file's log.
    pub picture: bool,
    /// Files listed in `OUTBOX/index.html`; 0: no index.
    pub index_entries: usize,
    /// Serve Prometheus metrics at `http://ADDR/metrics`.
    pub metrics: Option<std::net::SocketAddr>,
    /// `Some(url)`: the gateway (repairs on the work queue at `url`).
    pub forward: Option<String>,
    /// The queue's names and settings (the config's `[nats]` section).
    pub nats: crate::worker::config::NatsFile,
}

/// The address of `--metrics` / `metrics = ...`: `HOST:PORT`, `[V6]:PORT`, or a port
/// alone (on 127.0.0.1).
pub fn metrics_addr(text: &str) -> Result<std::net::SocketAddr> {
    let t = text.trim();
    if let Ok(port) = t.parse::<u16>() {
        return Ok(std::net::SocketAddr::from(([127, 0, 0, 1], port)));
    }
    t.parse().map_err(|_| {
        anyhow::anyhow!("metrics = {t:?}: expected an address such as 127.0.0.1:9464 (or a port)")
    })
}

impl Settings {
    /// Reads the config file named by `--config` (if any) and applies the flags.
    pub fn load(args: &WatchArgs) -> Result<Settings> {
        let file = match &args.config {
            Some(p) => FileConfig::from_file(p)?,
            None => FileConfig::default(),
        };
        Settings::resolve(args, &file)
    }

    /// Flags over the file over the defaults.
    pub fn resolve(args: &WatchArgs, file: &FileConfig) -> Result<Settings> {
        let inbox = args.inbox.clone().or_else(|| file.inbox.clone());
        let sibling = |name: &str| -> PathBuf {
            match &inbox {
                Some(i) => match i.parent() {
                    Some(p) if !p.as_os_str().is_empty() => p.join(name),
                    _ => PathBuf::from(".").join(name),
                },
                None => PathBuf::from(".").join(name),
            }
        };
        let outbox = args
            .outbox
            .clone()
            .or_else(|| file.outbox.clone())
            .unwrap_or_else(|| sibling("outbox"));
        let failed = args
            .failed
            .clone()
            .or_else(|| file.failed.clone())
            .unwrap_or_else(|| sibling("failed"));
        let archive = args
            .archive
            .clone()
            .or_else(|| file.archive.clone())
            .unwrap_or_else(|| sibling("archive"));
        let inbox = inbox.unwrap_or_else(|| PathBuf::from("./inbox"));
        let forward = args.forward.clone().or_else(|| file.forward.clone());
        // a gateway's workers are files in flight on the queue, not local children
        let default_workers = if forward.is_some() { 64 } else { 0 };
        let workers = match args.workers.or(file.workers).unwrap_or(default_workers) {
            0 => std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            n => n,
        };
        let s = Settings {
            inbox,
            outbox,
            failed,
            archive,
            policy: args.policy.clone().or_else(|| file.policy.clone()),
            workers,
            max_pending: file.max_pending.unwrap_or(100_000),
            settle: Duration::from_millis(args.settle_ms.or(file.settle_ms).unwrap_or(2000)),
            rescan: Duration::from_secs(args.rescan_secs.or(file.rescan_secs).unwrap_or(60)),
            poll: args.poll || file.poll.unwrap_or(false),
            poll_interval: Duration::from_millis(args.poll_ms.or(file.poll_ms).unwrap_or(1000)),
            max_attempts: args.max_attempts.or(file.max_attempts).unwrap_or(3),
            max_file_bytes: args
                .max_file_bytes
                .or(file.max_file_bytes)
                .unwrap_or(2 << 30),
            max_faces: args.max_faces.or(file.max_faces).unwrap_or(0),
            max_vertices: args.max_vertices.or(file.max_vertices).unwrap_or(0),
            time_limit: match args.time_limit_secs.or(file.time_limit_secs).unwrap_or(600) {
                0 => None,
                n => Some(Duration::from_secs(n)),
            },
            memory_limit_mb: args
                .memory_limit_mb
                .or(file.memory_limit_mb)
                .unwrap_or(8192),
            grace: Duration::from_secs(args.grace_secs.or(file.grace_secs).unwrap_or(30)),
            retry_max: Duration::from_secs(
                args.retry_max_secs
                    .or(file.retry_max_secs)
                    .unwrap_or(300)
                    .max(1),
            ),
            max_wait: Duration::from_secs(
                args.max_wait_secs
                    .or(file.max_wait_secs)
                    .unwrap_or(3600)
                    .max(1),
            ),
            set_wait: Duration::from_secs(args.set_wait_secs.or(file.set_wait_secs).unwrap_or(120)),
            on_success: args
                .on_success
                .or(file.on_success)
                .unwrap_or(OnSuccess::Archive),
            collision: args
                .collision
                .or(file.collision)
                .unwrap_or(Collision::Timestamp),
            log_format: args
                .log_format
                .or(file.log_format)
                .unwrap_or(LogFormat::Text),
            picture: args.picture.or(file.picture).unwrap_or(true),
            index_entries: args.index_entries.or(file.index_entries).unwrap_or(200),
            metrics: match args.metrics.as_deref().or(file.metrics.as_deref()) {
                Some(a) => Some(metrics_addr(a)?),
                None => None,
            },
            forward,
            nats: file.nats.clone().unwrap_or_default(),
        };
        s.validate()?;
        Ok(s)
    }

    fn validate(&self) -> Result<()> {
        if self.max_attempts == 0 {
            bail!("max_attempts must be at least 1");
        }
        if self.max_pending == 0 {
            bail!("max_pending must be at least 1");
        }
        if self.poll && self.poll_interval.is_zero() {
            bail!("poll_ms must be at least 1");
        }
        if self.rescan.is_zero() {
            bail!("rescan_secs must be at least 1");
        }
        // the folders: compared once resolved, by the daemon's start (claim::Layout)
        Ok(())
    }

    /// The keys a SIGHUP cannot change (folders, workers, watch mode, journal format):
    /// their names when `new` differs from `self` there.
    pub fn restart_only_changes(&self, new: &Settings) -> Vec<&'static str> {
        let mut v = Vec::new();
        if self.inbox != new.inbox {
            v.push("inbox");
        }
        if self.outbox != new.outbox {
            v.push("outbox");
        }
        if self.failed != new.failed {
            v.push("failed");
        }
        if self.archive != new.archive {
            v.push("archive");
        }
        if self.workers != new.workers {
            v.push("workers");
        }
        if self.poll != new.poll {
            v.push("poll");
        }
        if self.log_format != new.log_format {
            v.push("log_format");
        }
        if self.metrics != new.metrics {
            v.push("metrics");
        }
        if self.forward != new.forward {
            v.push("forward");
        }
        if self.nats != new.nats {
            v.push("nats");
        }
        v
    }

    /// `new` with the keys that need a restart taken from `self`.
    pub fn reloaded(&self, new: &Settings) -> Settings {
        Settings {
            inbox: self.inbox.clone(),
            outbox: self.outbox.clone(),
            failed: self.failed.clone(),
            archive: self.archive.clone(),
            workers: self.workers,
            poll: self.poll,
            log_format: self.log_format,
            metrics: self.metrics,
            forward: self.forward.clone(),
            nats: self.nats.clone(),
            ..new.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct T {
        #[command(flatten)]
        w: WatchArgs,
    }

    fn args(a: &[&str]) -> WatchArgs {
        let mut v = vec!["t"];
        v.extend_from_slice(a);
        T::parse_from(v).w
    }

    #[test]
    fn defaults_are_dot_folders() {
        let s = Settings::resolve(&args(&[]), &FileConfig::default()).unwrap();
        assert_eq!(s.inbox, PathBuf::from("./inbox"));
        assert_eq!(s.outbox, PathBuf::from("./outbox"));
        assert_eq!(s.failed, PathBuf::from("./failed"));
        assert_eq!(s.archive, PathBuf::from("./archive"));
        assert_eq!(s.on_success, OnSuccess::Archive);
        assert_eq!(s.collision, Collision::Timestamp);
        assert!(s.workers >= 1);
    }

    #[test]
    fn folders_default_to_siblings_of_the_inbox_and_flags_win() {
        let file = FileConfig {
            inbox: Some("/scans/in".into()),
            failed: Some("/elsewhere/bad".into()),
            workers: Some(5),
            settle_ms: Some(10),
            ..Default::default()
        };
        let s = Settings::resolve(&args(&["--workers", "2"]), &file).unwrap();
        assert_eq!(s.inbox, PathBuf::from("/scans/in"));
        assert_eq!(s.outbox, PathBuf::from("/scans/outbox"));
        assert_eq!(s.failed, PathBuf::from("/elsewhere/bad"));
        assert_eq!(s.archive, PathBuf::from("/scans/archive"));
        assert_eq!(s.workers, 2);
        assert_eq!(s.settle, Duration::from_millis(10));
        let s = Settings::resolve(&args(&["--inbox", "/x/y", "--outbox", "/o"]), &file).unwrap();
        assert_eq!(s.inbox, PathBuf::from("/x/y"));
        assert_eq!(s.outbox, PathBuf::from("/o"));
        assert_eq!(s.archive, PathBuf::from("/x/archive"));
    }

    #[test]
    fn shipped_config_parses_and_every_key_is_documented() {
        let text = include_str!("../../config/holefill.toml");
        let f: FileConfig = toml::from_str(text).unwrap();
        assert_eq!(
            f,
            FileConfig::default(),
            "the shipped config sets nothing: every key is a comment"
        );
        // every key of FileConfig appears (commented) in the file
        for key in [
            "inbox",
            "outbox",
            "failed",
            "archive",
            "policy",
            "workers",
            "max_pending",
            "settle_ms",
            "rescan_secs",
            "poll",
            "poll_ms",
            "max_attempts",
            "max_file_bytes",
            "max_faces",
            "max_vertices",
            "time_limit_secs",
            "memory_limit_mb",
            "grace_secs",
            "retry_max_secs",
            "max_wait_secs",
            "set_wait_secs",
            "on_success",
            "collision",
            "log_format",
            "picture",
            "index_entries",
            "metrics",
            "forward",
        ] {
            // `## ` lines are prose, `# key = value` lines are the documented keys
            let uncommented: String = text
                .lines()
                .filter(|l| !l.starts_with("##"))
                .map(|l| l.strip_prefix("# ").unwrap_or(l))
                .collect::<Vec<_>>()
                .join("\n");
            let parsed: toml::Table =
                toml::from_str(&uncommented).unwrap_or_else(|e| panic!("uncommented config: {e}"));
            assert!(
                parsed.contains_key(key),
                "config/holefill.toml does not document `{key}`"
            );
        }
    }

    #[test]
    fn picture_index_and_metrics_keys() {
        let s = Settings::resolve(&args(&[]), &FileConfig::default()).unwrap();
        assert!(s.picture, "pictures are on by default");
        assert_eq!(s.index_entries, 200);
        assert_eq!(s.metrics, None, "metrics are off by default");
        let file = FileConfig {
            picture: Some(false),
            metrics: Some("9464".into()),
            ..Default::default()
        };
        let s = Settings::resolve(&args(&[]), &file).unwrap();
        assert!(!s.picture);
        assert_eq!(
            s.metrics,
            Some("127.0.0.1:9464".parse().unwrap()),
            "a port alone: loopback"
        );
        let s = Settings::resolve(
            &args(&[
                "--picture",
                "true",
                "--metrics",
                "[::1]:9000",
                "--index-entries",
                "0",
            ]),
            &file,
        )
        .unwrap();
        assert!(s.picture);
        assert_eq!(s.index_entries, 0);
        assert_eq!(s.metrics, Some("[::1]:9000".parse().unwrap()));
        assert!(Settings::resolve(&args(&["--metrics", "localhost"]), &file).is_err());
    }

    #[test]
    fn unknown_keys_are_errors() {
        assert!(toml::from_str::<FileConfig>("inbx = \"/a\"").is_err());
    }
}
