//! The daemon, `holefill watch`: repairs every mesh dropped into an inbox exactly once,
//! writes the model and its repair log into an outbox, and runs as a systemd service.
//!
//! It knows nothing of geometry: each repair is a `holefill fill` child process
//! ([`worker`]). The pieces:
//! - [`config`]: `config/holefill.toml` and the flags that override it;
//! - [`watch`]: the inbox's inotify events;
//! - [`queue`]: which files wait in the inbox and when each is complete enough to take
//!   (nobody holds it open, it stopped changing);
//! - [`claim`]: the folders and their checks, the atomic claim, the job records, the
//!   lock that tells a live daemon from a dead one, the adoption of dead daemons' files;
//! - [`worker`]: the checks of the claimed file, limits, the child process, and the
//!   crash-safe publish (outbox, archive) or failure;
//! - [`fsops`]: moves that never overwrite (also across file systems), fsync, the
//!   collision rule, names as they may be logged;
//! - [`hooks`]: test-only hooks (cargo feature `test-hooks`).
//!
//! The main loop (one tokio task) takes change events (rescans at start-up, on
//! overflow and on a timer; or polling), keeps the folders there (recreating a folder
//! that vanished, with a rate-limited error while it cannot), claims ready files while
//! fewer than `workers` repairs run, and handles signals: SIGTERM/SIGINT stop claiming
//! and let the running repairs finish within the grace period (then kill them and put
//! their files back), SIGHUP reloads the config and policy. It tells systemd READY=1
//! after the start-up scan, STATUS= with counts, WATCHDOG=1 pings, STOPPING=1.
//!
//! Every file name that reaches the journal goes through [`fsops::shown`]: one line of
//! printable text, whatever bytes the name holds.

mod assembly;
pub mod child;
mod claim;
pub mod config;
mod folders;
pub mod fsops;
pub mod hooks;
pub mod index;
mod jobs;
mod lifecycle;
mod queue;
mod sets;
mod sniff;
mod watch;
mod worker;

use crate::metrics;
use anyhow::{Context, Result};
use claim::{Home, Identity, Job, Layout};
use config::{Collision, LogFormat, OnSuccess, Settings};
use holefill::policy::Policy;
use hooks::Hooks;
use queue::{Pending, Seen};
use sd_notify::NotifyState;
use sets::{Role, SetRec};
use std::collections::{HashMap, VecDeque};
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch as tokio_watch};
use watch::{Ev, Watcher};
use worker::{Done, RunCtx};

/// Options of `holefill watch` (each overrides the config file's key of the same name).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct WatchArgs {
    /// Daemon config file (TOML; see config/holefill.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The folder watched for meshes [default: ./inbox].
    #[arg(long)]
    pub inbox: Option<PathBuf>,
    /// Repaired models and their logs [default: sibling `outbox` of the inbox].
    #[arg(long)]
    pub outbox: Option<PathBuf>,
    /// Files that could not be repaired, with their logs [default: sibling `failed`].
    #[arg(long)]
    pub failed: Option<PathBuf>,
    /// Originals of repaired files [default: sibling `archive`].
    #[arg(long)]
    pub archive: Option<PathBuf>,
    /// The repair policy (TOML) [default: the built-in policy].
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Repairs run at the same time [default: the number of cores].
    #[arg(long)]
    pub workers: Option<usize>,
    /// A file written in place is taken once unchanged this long [default: 2000].
    #[arg(long)]
    pub settle_ms: Option<u64>,
    /// Full rescan of the inbox every this many seconds [default: 60].
    #[arg(long)]
    pub rescan_secs: Option<u64>,
    /// Poll the inbox instead of waiting for change events.
    #[arg(long)]
    pub poll: bool,
    /// Polling interval [default: 1000].
    #[arg(long)]
    pub poll_ms: Option<u64>,
    /// Attempts (crashed, hung or killed workers) before a file goes to failed [default: 3].
    #[arg(long)]
    pub max_attempts: Option<u32>,
    /// Larger files go to failed unread; 0: no limit [default: 2 GiB].
    #[arg(long)]
    pub max_file_bytes: Option<u64>,
    /// Files declaring more faces go to failed; 0: no limit [default: 0].
    #[arg(long)]
    pub max_faces: Option<u64>,
    /// Files with more vertices go to failed (the worker stops reading at the limit);
    /// 0: no limit [default: 0].
    #[arg(long)]
    pub max_vertices: Option<u64>,
    /// Wall-clock limit of one repair; 0: none [default: 600].
    #[arg(long)]
    pub time_limit_secs: Option<u64>,
    /// Address-space limit of one worker in MiB; 0: none [default: 8192].
    #[arg(long)]
    pub memory_limit_mb: Option<u64>,
    /// On SIGTERM, running repairs get this long to finish [default: 30].
    #[arg(long)]
    pub grace_secs: Option<u64>,
    /// Longest back-off before retrying a file after a retryable failure [default: 300].
    #[arg(long)]
    pub retry_max_secs: Option<u64>,
    /// A file still held open by a writer, or still empty, is waited for at most this
    /// long without a change [default: 3600].
    #[arg(long)]
    pub max_wait_secs: Option<u64>,
    /// A set (an OBJ with its material library and images) waits this long for a
    /// missing member, then goes to failed [default: 120].
    #[arg(long)]
    pub set_wait_secs: Option<u64>,
    /// What becomes of a repaired original [default: archive].
    #[arg(long, value_enum)]
    pub on_success: Option<OnSuccess>,
    /// Rule for an output name already taken [default: timestamp].
    #[arg(long, value_enum)]
    pub collision: Option<Collision>,
    /// Journal format on stderr [default: text].
    #[arg(long, value_enum)]
    pub log_format: Option<LogFormat>,
    /// Write a picture of each repair beside its log [default: true].
    #[arg(long, value_name = "BOOL")]
    pub picture: Option<bool>,
    /// Files listed in OUTBOX/index.html; 0: no index [default: 200].
    #[arg(long)]
    pub index_entries: Option<usize>,
    /// Serve Prometheus metrics at http://ADDR/metrics (HOST:PORT, or a port for
    /// 127.0.0.1) [default: off].
    #[arg(long, value_name = "ADDR")]
    pub metrics: Option<String>,
    /// Forward the claimed files to this NATS work queue (nats://HOST:PORT) instead of
    /// repairing them here, and publish the results that come back (docs/worker.md).
    #[arg(long)]
    pub forward: Option<String>,
}

/// Runs the daemon until SIGTERM or SIGINT (then returns `Ok` once every claimed file
/// is repaired, failed or back in the inbox).
pub fn run(args: WatchArgs) -> Result<()> {
    let settings = Settings::load(&args)?;
    init_tracing(settings.log_format);
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    let r = rt.block_on(async move {
        // handlers first: a SIGTERM during the start-up scan is a clean stop too
        let signals = Signals::new()?;
        let d = Daemon::start(args, settings).await?;
        d.run(signals).await
    });
    rt.shutdown_timeout(Duration::from_secs(2));
    if let Err(e) = &r {
        tracing::error!("{e:#}");
    }
    r
}

/// A claimed mesh waiting for the other files of its set (see [`sets`]).
struct Parked {
    job: Job,
    /// Its references as written (`mtllib` arguments, PLY `TextureFile` names, glTF
    /// buffer and image URIs), with what each is to it.
    refs: Vec<(String, Role)>,
    /// Since when no member became complete (the set's timeout counts from here).
    since: Instant,
    /// Members complete at the last look.
    ready: usize,
    /// MTL files read: name -> (stamp, image names).
    libs: HashMap<String, (fsops::Stamp, Vec<String>)>,
    /// What the journal last said about it.
    said: String,
}

/// What a waiting set's files say now.
enum Assembly {
    /// Every member is complete (or not followed).
    Complete(SetRec),
    /// Some member is missing or not complete yet.
    Wait(String),
    /// A member has been missing for `set_wait_secs`: the set fails with what is there.
    TimedOut(SetRec),
}

fn init_tracing(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let b = tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(filter)
        .with_target(false)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()));
    let _ = match format {
        LogFormat::Json => b.json().try_init(),
        LogFormat::Text => b.try_init(),
    };
}

/// Sends states to systemd (a no-op without `NOTIFY_SOCKET`).
fn sd(states: &[NotifyState]) {
    if let Err(e) = sd_notify::notify(false, states) {
        tracing::debug!("sd_notify: {e}");
    }
}

/// Validates the policy file of `settings` and writes the exact text validated into
/// `dir` for the workers (so that an edit of the file takes effect only on SIGHUP).
/// Returns the snapshot's path and the text.
fn snapshot_policy(
    settings: &Settings,
    dir: &Path,
    generation: u32,
) -> Result<(Option<PathBuf>, Option<String>)> {
    let Some(src) = &settings.policy else {
        return Ok((None, None));
    };
    let text = std::fs::read_to_string(src)
        .with_context(|| format!("{}: cannot read the policy", src.display()))?;
    Policy::from_toml_str(&text, src).map_err(|e| anyhow::anyhow!("invalid policy: {e}"))?;
    let snap = dir.join(format!("policy-{generation}.toml"));
    holefill::io::write_atomic(&snap, text.as_bytes())
        .map_err(|e| anyhow::anyhow!("cannot store the policy snapshot: {e}"))?;
    Ok((Some(snap), Some(text)))
}

/// The signals the daemon handles.
struct Signals {
    sigterm: tokio::signal::unix::Signal,
    sigint: tokio::signal::unix::Signal,
    sighup: tokio::signal::unix::Signal,
}

impl Signals {
    fn new() -> Result<Signals> {
        use tokio::signal::unix::{signal, SignalKind};
        Ok(Signals {
            sigterm: signal(SignalKind::terminate())?,
            sigint: signal(SignalKind::interrupt())?,
            sighup: signal(SignalKind::hangup())?,
        })
    }
}

/// Rate limit of repeated errors (a folder that cannot be created, a foreign folder).
const ERROR_EVERY: Duration = Duration::from_secs(60);
/// How often the folders are checked while all is well.
const FOLDER_CHECK: Duration = Duration::from_secs(1);

struct Daemon {
    args: WatchArgs,
    settings: Settings,
    id: Arc<Identity>,
    layout: Layout,
    /// Our processing folder.
    home: Arc<Home>,
    /// Folders of dead daemons whose files we finish.
    adopted: Vec<Arc<Home>>,
    ctx: Arc<RunCtx>,
    generation: u32,
    /// The validated policy text of this generation (rewritten if its folder vanished).
    policy_text: Option<String>,
    pending: Pending,
    /// Jobs waiting to run (again), with their time.
    again: VecDeque<(Job, Instant)>,
    /// Claimed meshes waiting for the other files of their sets.
    sets: Vec<Parked>,
    /// Running jobs: id -> (home tag, shown name).
    working: HashMap<String, (String, String)>,
    /// Retryable failures per inbox name (for the back-off).
    retries: HashMap<OsString, u32>,
    /// Names we put back: their rename event is ours, not a producer's.
    expect: HashMap<OsString, Seen>,
    repaired: u64,
    failed: u64,
    cancel: tokio_watch::Sender<bool>,
    done_tx: mpsc::UnboundedSender<Done>,
    done_rx: mpsc::UnboundedReceiver<Done>,
    /// Repairs whose pictures are still being drawn: id -> home tag.
    drawing: HashMap<String, String>,
    drawn_tx: mpsc::UnboundedSender<Drawn>,
    drawn_rx: mpsc::UnboundedReceiver<Drawn>,
    events: Option<mpsc::Receiver<Ev>>,
    watcher: Option<Watcher>,
    rescan_flag: Arc<AtomicBool>,
    last_scan: Instant,
    last_status: String,
    watchdog: Option<Duration>,
    last_ping: Instant,
    stopping: Option<Instant>,
    cancelled: bool,
    /// Last time each repeated error was logged.
    errors: HashMap<String, Instant>,
    folders_checked: Option<Instant>,
    folders_ok: bool,
    /// `OUTBOX/index.html` (`None`: index_entries = 0).
    index: Option<index::Index>,
}

/// A repair's picture, drawn after its log was published: `picture` is where it was
/// published (`None`: lost).
#[derive(Debug)]
struct Drawn {
    /// The job's id.
    id: String,
    log: PathBuf,
    picture: Option<PathBuf>,
}

impl Daemon {
    async fn start(args: WatchArgs, settings: Settings) -> Result<Daemon> {
        let id = Arc::new(Identity::current());
        let layout = Layout::create(
            &settings.inbox,
            &settings.outbox,
            &settings.failed,
            &settings.archive,
        )
        .map_err(|e| anyhow::anyhow!("{e}"))
        .context("refused folders")?;
        let home = Arc::new(Home::create(&layout, &id.tag()).with_context(|| {
            format!(
                "cannot create this daemon's folder in {}",
                layout.processing_root.display()
            )
        })?);
        child::probe_limits(settings.memory_limit_mb)?;
        let (policy, policy_text) = snapshot_policy(&settings, &home.tmp, 0)?;
        if let Some(addr) = settings.metrics {
            let m = metrics::init("watch");
            let bound = metrics::serve(addr, m)
                .await
                .with_context(|| format!("cannot serve the metrics on {addr}"))?;
            tracing::info!("metrics at http://{bound}/metrics");
        }
        let exe = std::env::current_exe().context("cannot find the holefill executable")?;
        let cores = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1);
        let hooks = Hooks::from_env();
        if let Some(w) = hooks.warning() {
            tracing::warn!("{w}");
        }
        let forward = match &settings.forward {
            Some(url) => Some(
                crate::worker::gateway::Forwarder::start(
                    url,
                    settings.nats.names()?,
                    settings.nats.settings()?,
                    &id.host,
                    Duration::from_secs(30),
                )
                .await
                .with_context(|| format!("--forward {url}"))?,
            ),
            None => None,
        };
        let ctx = Arc::new(RunCtx {
            forward,
            layout: layout.clone(),
            host: id.host.clone(),
            pid: id.pid,
            instance: id.instance.clone(),
            settings: settings.clone(),
            policy,
            policy_source: settings.policy.clone(),
            exe,
            hooks,
            cores,
        });
        let (cancel, _) = tokio_watch::channel(false);
        let (done_tx, done_rx) = mpsc::unbounded_channel();
        let (drawn_tx, drawn_rx) = mpsc::unbounded_channel();
        let rescan_flag = Arc::new(AtomicBool::new(false));

        // the watcher first, then the scan: a file arriving in between is seen by one
        let (watcher, events) = if settings.poll {
            (None, None)
        } else {
            let (w, rx) =
                Watcher::start(&layout.inbox, 16_384, rescan_flag.clone()).with_context(|| {
                    format!("cannot watch {} (try poll = true)", layout.inbox.display())
                })?;
            (Some(w), Some(rx))
        };
        let mut usec = 0;
        let watchdog = sd_notify::watchdog_enabled(false, &mut usec)
            .then(|| Duration::from_micros(usec / 2).max(Duration::from_millis(100)));
        let mut d = Daemon {
            pending: Pending::new(settings.max_pending),
            args,
            settings,
            id,
            layout,
            home,
            adopted: Vec::new(),
            ctx,
            generation: 0,
            policy_text,
            again: VecDeque::new(),
            sets: Vec::new(),
            working: HashMap::new(),
            retries: HashMap::new(),
            expect: HashMap::new(),
            repaired: 0,
            failed: 0,
            cancel,
            done_tx,
            done_rx,
            drawing: HashMap::new(),
            drawn_tx,
            drawn_rx,
            events,
            watcher,
            rescan_flag,
            last_scan: Instant::now(),
            last_status: String::new(),
            watchdog,
            last_ping: Instant::now(),
            stopping: None,
            cancelled: false,
            errors: HashMap::new(),
            folders_checked: None,
            folders_ok: true,
            index: None,
        };
        if d.settings.index_entries > 0 {
            d.index = Some(index::Index::load(
                &d.layout.outbox,
                &d.layout.failed,
                d.settings.index_entries,
            ));
        }
        d.rescan();
        tracing::info!(
            inbox = %d.layout.inbox.display(),
            outbox = %d.layout.outbox.display(),
            failed = %d.layout.failed.display(),
            archive = %d.layout.archive.display(),
            workers = d.settings.workers,
            mode = if d.settings.poll { "poll" } else { "events" },
            instance = %d.home.tag,
            "holefill watch ready: {} files waiting",
            d.pending.len() + d.again.len()
        );
        let status = d.status();
        sd(&[NotifyState::Ready, NotifyState::Status(&status)]);
        d.last_status = status;
        Ok(d)
    }

    fn status(&self) -> String {
        format!(
            "waiting {}, working {}, drawing {}, repaired {}, failed {}",
            self.pending.len() + self.again.len() + self.sets.len(),
            self.working.len(),
            self.drawing.len(),
            self.repaired,
            self.failed
        )
    }

    async fn run(mut self, signals: Signals) -> Result<()> {
        let Signals {
            mut sigterm,
            mut sigint,
            mut sighup,
        } = signals;
        let tick =
            (self.settings.settle / 4).clamp(Duration::from_millis(20), Duration::from_millis(250));
        let tick = if self.settings.poll {
            tick.min(self.settings.poll_interval)
        } else {
            tick
        };
        let mut ticker = tokio::time::interval(tick);
        ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut events = self.events.take();
        loop {
            tokio::select! {
                _ = sigterm.recv() => self.begin_stop("SIGTERM"),
                _ = sigint.recv() => self.begin_stop("SIGINT"),
                _ = sighup.recv() => self.reload(),
                Some(done) = self.done_rx.recv() => self.on_done(done),
                Some(drawn) = self.drawn_rx.recv() => self.on_drawn(drawn),
                Some(ev) = async { match events.as_mut() { Some(rx) => rx.recv().await, None => std::future::pending().await } } => self.on_event(ev),
                _ = ticker.tick() => {}
            }
            let now = Instant::now();
            if let Some(deadline) = self.stopping {
                if self.working.is_empty() && self.drawing.is_empty() {
                    break;
                }
                if now >= deadline && !self.cancelled {
                    tracing::warn!("grace period over: killing {} running repairs (their files go back into the inbox) and {} pictures being drawn", self.working.len(), self.drawing.len());
                    self.cancelled = true;
                    let _ = self.cancel.send(true);
                }
            } else {
                let every = if self.settings.poll {
                    self.settings.poll_interval
                } else {
                    self.settings.rescan
                };
                let room =
                    self.pending.overflowed && self.pending.len() < self.settings.max_pending / 2;
                if self.rescan_flag.swap(false, Ordering::SeqCst)
                    || room
                    || now.duration_since(self.last_scan) >= every
                {
                    self.rescan();
                }
                self.dispatch();
            }
            if let Some(ix) = self.index.as_mut() {
                ix.flush(false);
            }
            if let Some(m) = metrics::global() {
                m.waiting
                    .set((self.pending.len() + self.again.len() + self.sets.len()) as i64);
                m.in_flight.set(self.working.len() as i64);
            }
            let status = self.status();
            if status != self.last_status {
                sd(&[NotifyState::Status(&status)]);
                self.last_status = status;
            }
            if let Some(iv) = self.watchdog {
                if now.duration_since(self.last_ping) >= iv {
                    sd(&[NotifyState::Watchdog]);
                    self.last_ping = now;
                }
            }
        }
        self.shutdown();
        Ok(())
    }

    /// Logs `msg` as an error, at most once per [`ERROR_EVERY`] for `key`.
    fn error_limited(&mut self, key: &str, msg: &str) {
        let now = Instant::now();
        match self.errors.get(key) {
            Some(t) if now.duration_since(*t) < ERROR_EVERY => {
                tracing::debug!("{msg}");
            }
            _ => {
                tracing::error!("{msg} (repeated at most once a minute)");
                self.errors.insert(key.to_string(), now);
            }
        }
    }

    /// The error of `key` is over.
    fn error_over(&mut self, key: &str, msg: &str) {
        if self.errors.remove(key).is_some() {
            tracing::info!("{msg}");
        }
    }

    fn on_event(&mut self, ev: Ev) {
        let now = Instant::now();
        match ev {
            Ev::File(name, seen) => {
                if seen == Seen::RenamedIn {
                    if let Some(ours) = self.expect.remove(&name) {
                        // our own put-back: its state was noted when it was put back
                        if ours == Seen::Changed {
                            return;
                        }
                    }
                }
                self.pending.note(&name, seen, now);
            }
            Ev::Overflow => {
                tracing::warn!("the inbox's change events overflowed: rescanning");
                self.rescan_flag.store(true, Ordering::SeqCst);
                self.pending.forget_events();
            }
            Ev::InboxGone => {
                self.check_folders(true);
            }
            Ev::Error(e) => {
                tracing::error!(
                    "the inbox's change events failed ({e}); rescanning every {} s",
                    self.settings.rescan.as_secs()
                );
                self.pending.forget_events();
            }
        }
    }
}
