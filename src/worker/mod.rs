//! Past one machine: repair workers on a NATS JetStream work queue.
//!
//! - `holefill worker --nats URL`: pulls scans from the work-queue stream and repairs
//!   each in the inbox daemon's isolated child ([`work`]);
//! - `holefill submit --nats URL FILES...`: uploads scans into the scans bucket and
//!   enqueues them; `holefill results --nats URL DIR`: downloads finished ones
//!   ([`client`]);
//! - [`scan`]: the job message, its digest and key, the object names;
//! - [`queue`]: the connection, and the streams, buckets and consumers made on first
//!   use; [`config`]: their names and settings (the `[nats]` section of the config).
//!
//! Deployment, settings and what happens on each failure: docs/worker.md.

pub mod client;
pub mod config;
pub mod gateway;
pub mod queue;
pub mod scan;
pub mod work;

use crate::daemon::config::FileConfig;
use anyhow::{bail, Context as _, Result};
use config::NatsFile;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

/// The connection and names every queue command takes.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct NatsArgs {
    /// The NATS server, e.g. nats://127.0.0.1:4222 [default: config `nats.url`].
    #[arg(long)]
    pub nats: Option<String>,
    /// Config file (TOML; its `[nats]` section and, for the worker, the limits; see
    /// config/holefill.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Work-queue stream [default: HOLEFILL_JOBS].
    #[arg(long)]
    pub stream: Option<String>,
    /// Its subject [default: holefill.jobs].
    #[arg(long)]
    pub subject: Option<String>,
    /// The workers' durable consumer [default: holefill-workers].
    #[arg(long)]
    pub consumer: Option<String>,
    /// Object store of submitted scans [default: holefill-scans].
    #[arg(long)]
    pub scans_bucket: Option<String>,
    /// Object store of repaired scans [default: holefill-results].
    #[arg(long)]
    pub results_bucket: Option<String>,
    /// Object store of failed scans with their logs [default: holefill-failed].
    #[arg(long)]
    pub failed_bucket: Option<String>,
    /// Stream of done notifications [default: HOLEFILL_DONE].
    #[arg(long)]
    pub done_stream: Option<String>,
    /// Its subject [default: holefill.done].
    #[arg(long)]
    pub done_subject: Option<String>,
    /// Repair attempts before a scan fails [default: 5].
    #[arg(long)]
    pub max_deliver: Option<u32>,
    /// A delivery unacknowledged this long is redelivered [default: 60].
    #[arg(long)]
    pub ack_wait_secs: Option<u64>,
    /// First back-off after a retryable failure, doubled per delivery [default: 5].
    #[arg(long)]
    pub backoff_secs: Option<u64>,
}

/// The config file's sections, and the `[nats]` section with the flags applied.
pub struct Loaded {
    pub file: FileConfig,
    pub nats: NatsFile,
    pub url: String,
}

impl NatsArgs {
    /// Reads the config (if any) and applies the flags.
    pub fn load(&self) -> Result<Loaded> {
        let file = match &self.config {
            Some(p) => FileConfig::from_file(p)?,
            None => FileConfig::default(),
        };
        let mut n = file.nats.clone().unwrap_or_default();
        let set = |dst: &mut Option<String>, v: &Option<String>| {
            if v.is_some() {
                *dst = v.clone();
            }
        };
        set(&mut n.stream, &self.stream);
        set(&mut n.subject, &self.subject);
        set(&mut n.consumer, &self.consumer);
        set(&mut n.scans_bucket, &self.scans_bucket);
        set(&mut n.results_bucket, &self.results_bucket);
        set(&mut n.failed_bucket, &self.failed_bucket);
        set(&mut n.done_stream, &self.done_stream);
        set(&mut n.done_subject, &self.done_subject);
        n.max_deliver = self.max_deliver.or(n.max_deliver);
        n.ack_wait_secs = self.ack_wait_secs.or(n.ack_wait_secs);
        n.backoff_secs = self.backoff_secs.or(n.backoff_secs);
        let url = match self.nats.clone().or_else(|| n.url.clone()) {
            Some(u) => u,
            None => bail!("no NATS server: give --nats URL (or nats.url in the config)"),
        };
        Ok(Loaded { file, nats: n, url })
    }
}

/// `holefill worker`.
#[derive(clap::Args, Debug)]
pub struct WorkerArgs {
    #[command(flatten)]
    pub nats: NatsArgs,
    /// Scans repaired at the same time [default: config `workers`, else the cores].
    #[arg(long)]
    pub workers: Option<usize>,
    /// The repair policy (TOML) [default: config `policy`, else built in].
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Wall-clock limit of one repair; 0: none [default: 600].
    #[arg(long)]
    pub time_limit_secs: Option<u64>,
    /// Address-space limit of one repair in MiB; 0: none [default: 8192].
    #[arg(long)]
    pub memory_limit_mb: Option<u64>,
    /// Larger files fail unread; 0: no limit [default: 2 GiB].
    #[arg(long)]
    pub max_file_bytes: Option<u64>,
    /// On SIGTERM, running repairs get this long to finish [default: 30].
    #[arg(long)]
    pub grace_secs: Option<u64>,
    /// The worker's private folder for downloads and outputs [default: a new folder
    /// in $TMPDIR, removed at exit].
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Serve Prometheus metrics at http://ADDR/metrics (e.g. 127.0.0.1:9465, or a
    /// port on loopback) [default: config `nats.worker_metrics`, else off].
    #[arg(long, value_name = "ADDR")]
    pub metrics: Option<String>,
}

/// `holefill submit`.
#[derive(clap::Args, Debug)]
pub struct SubmitArgs {
    #[command(flatten)]
    pub nats: NatsArgs,
    /// Meshes to repair, each a scan; with --set, one scan: the mesh first, then the
    /// files that travel with it (material library, images).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// The files are one set (the first the mesh).
    #[arg(long)]
    pub set: bool,
}

/// `holefill results`.
#[derive(clap::Args, Debug)]
pub struct ResultsArgs {
    #[command(flatten)]
    pub nats: NatsArgs,
    /// Repaired models and their logs go here.
    pub dir: PathBuf,
    /// Failed scans (the submitted files, when stored, and the log) [default: DIR/failed].
    #[arg(long)]
    pub failed: Option<PathBuf>,
    /// Keep waiting for more results until SIGTERM or Ctrl-C.
    #[arg(long)]
    pub watch: bool,
    /// The durable consumer that remembers what was downloaded [default: holefill-results].
    #[arg(long)]
    pub results_consumer: Option<String>,
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,async_nats=warn"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .try_init();
}

/// Runs `holefill worker` until SIGTERM or SIGINT.
pub fn run_worker(args: WorkerArgs) -> Result<()> {
    init_tracing();
    let loaded = args.nats.load()?;
    let names = loaded.nats.names()?;
    let queue_settings = loaded.nats.settings()?;
    let f = &loaded.file;
    let policy = args.policy.clone().or_else(|| f.policy.clone());
    if let Some(p) = &policy {
        holefill::policy::Policy::from_file(p)
            .map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
    }
    let limits = work::Limits {
        max_file_bytes: args.max_file_bytes.or(f.max_file_bytes).unwrap_or(2 << 30),
        max_faces: f.max_faces.unwrap_or(0),
        max_vertices: f.max_vertices.unwrap_or(0),
        time_limit: match args.time_limit_secs.or(f.time_limit_secs).unwrap_or(600) {
            0 => None,
            n => Some(Duration::from_secs(n)),
        },
        memory_limit_mb: args.memory_limit_mb.or(f.memory_limit_mb).unwrap_or(8192),
    };
    crate::daemon::child::probe_limits(limits.memory_limit_mb)?;
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let slots = match args.workers.or(f.workers).unwrap_or(0) {
        0 => cores,
        n => n,
    };
    let grace = Duration::from_secs(args.grace_secs.or(f.grace_secs).unwrap_or(30));
    let metrics_addr = match args
        .metrics
        .as_deref()
        .or(loaded.nats.worker_metrics.as_deref())
    {
        Some(a) => Some(crate::daemon::config::metrics_addr(a)?),
        None => None,
    };
    let pid = std::process::id();
    let instance = format!("{:016x}", rand::random::<u64>());
    let (work_dir, remove_dir) = match &args.work_dir {
        Some(d) => (
            d.join(format!("holefill-worker-{pid}-{}", &instance[..8])),
            true,
        ),
        None => (
            std::env::temp_dir().join(format!("holefill-worker-{pid}-{}", &instance[..8])),
            true,
        ),
    };
    {
        use std::os::unix::fs::DirBuilderExt;
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(&work_dir)
            .with_context(|| format!("{}: cannot make the work folder", work_dir.display()))?;
    }
    let exe = std::env::current_exe().context("cannot find the holefill executable")?;
    let hooks = crate::daemon::hooks::Hooks::from_env();
    if let Some(w) = hooks.warning() {
        tracing::warn!("{w}");
    }
    let host = hostname::get()
        .map(|h| h.to_string_lossy().into_owned())
        .unwrap_or_else(|_| "unknown".into());
    let rt = runtime()?;
    let r = rt.block_on(async {
        if let Some(addr) = metrics_addr {
            let m = crate::metrics::init("worker");
            let bound = crate::metrics::serve(addr, m)
                .await
                .with_context(|| format!("cannot serve the metrics on {addr}"))?;
            tracing::info!("metrics at http://{bound}/metrics");
        }
        let conn = queue::connect(&loaded.url, "holefill-worker").await?;
        let mut buckets = queue::retry(
            "the queue's streams and buckets",
            Duration::from_secs(3600),
            || queue::setup(&conn, &names, &queue_settings),
        )
        .await?;
        buckets.scans.hooks = hooks.clone();
        let ctx = Arc::new(work::WorkerCtx {
            conn,
            names: names.clone(),
            queue: queue_settings.clone(),
            buckets,
            exe,
            policy,
            limits,
            hooks,
            cores,
            work_dir: work_dir.clone(),
            host,
            pid,
            instance,
            seq: Default::default(),
        });
        work::run(ctx, slots, grace).await
    });
    rt.shutdown_timeout(Duration::from_secs(2));
    if remove_dir {
        let _ = std::fs::remove_dir_all(&work_dir);
    }
    r
}

/// Runs `holefill submit`: prints one line per scan, `queued KEY` or `duplicate KEY`.
pub fn run_submit(args: SubmitArgs) -> Result<()> {
    init_tracing();
    let loaded = args.nats.load()?;
    let names = loaded.nats.names()?;
    let settings = loaded.nats.settings()?;
    let origin = hostname::get()
        .ok()
        .map(|h| h.to_string_lossy().into_owned());
    // every file read and checked before anything is sent
    let sets: Vec<Vec<PathBuf>> = if args.set {
        vec![args.files.clone()]
    } else {
        args.files.iter().map(|f| vec![f.clone()]).collect()
    };
    let jobs = sets
        .iter()
        .map(|s| client::read_set(s, origin.clone()))
        .collect::<Result<Vec<_>>>()?;
    let rt = runtime()?;
    rt.block_on(async {
        let conn = queue::connect(&loaded.url, "holefill-submit").await?;
        let buckets = tokio::time::timeout(
            Duration::from_secs(30),
            queue::setup(&conn, &names, &settings),
        )
        .await
        .context("the NATS server did not answer within 30 s")??;
        for (msg, contents) in &jobs {
            let s = client::submit(&conn, &names, &buckets, msg, contents).await?;
            println!(
                "{} {}",
                if s.duplicate { "duplicate" } else { "queued" },
                s.key
            );
        }
        Ok(())
    })
}

/// Runs `holefill results`.
pub fn run_results(args: ResultsArgs) -> Result<()> {
    init_tracing();
    let mut loaded = args.nats.load()?;
    if args.results_consumer.is_some() {
        loaded.nats.results_consumer = args.results_consumer.clone();
    }
    let names = loaded.nats.names()?;
    let settings = loaded.nats.settings()?;
    let dirs = client::ResultDirs {
        out: args.dir.clone(),
        failed: args
            .failed
            .clone()
            .unwrap_or_else(|| args.dir.join("failed")),
    };
    let rt = runtime()?;
    rt.block_on(async {
        let conn = queue::connect(&loaded.url, "holefill-results").await?;
        let n = client::results(&conn, &names, &settings, &dirs, args.watch).await?;
        eprintln!("{n} result(s) downloaded");
        Ok(())
    })
}
