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

pub mod child;
mod claim;
pub mod config;
pub mod fsops;
pub mod hooks;
pub mod index;
mod queue;
mod sets;
mod sniff;
mod watch;
mod worker;

use crate::metrics;
use anyhow::{Context, Result};
use claim::{Home, Identity, Job, Layout, Phase};
use config::{Collision, LogFormat, OnSuccess, Settings};
use fsops::shown;
use holefill::policy::Policy;
use hooks::Hooks;
use queue::{MemberState, Pending, Seen};
use sd_notify::NotifyState;
use sets::{Member, Missing, Refused, Role, SetRec};
use std::collections::{HashMap, VecDeque};
use std::ffi::{OsStr, OsString};
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
            "waiting {}, working {}, repaired {}, failed {}",
            self.pending.len() + self.again.len() + self.sets.len(),
            self.working.len(),
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
                Some(ev) = async { match events.as_mut() { Some(rx) => rx.recv().await, None => std::future::pending().await } } => self.on_event(ev),
                _ = ticker.tick() => {}
            }
            let now = Instant::now();
            if let Some(deadline) = self.stopping {
                if self.working.is_empty() {
                    break;
                }
                if now >= deadline && !self.cancelled {
                    tracing::warn!("grace period over: killing {} running repairs; their files go back into the inbox", self.working.len());
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

    /// Checks that the folders are there (recreating the ones that vanished) and are
    /// still what they were (not the inbox). At most every second unless `force`.
    /// False while one cannot be had: then no file is claimed.
    fn check_folders(&mut self, force: bool) -> bool {
        let now = Instant::now();
        if !force
            && self
                .folders_checked
                .is_some_and(|t| now.duration_since(t) < FOLDER_CHECK)
        {
            return self.folders_ok;
        }
        self.folders_checked = Some(now);
        let mut ok = true;
        let layout = self.layout.clone();
        for (what, p) in layout.named() {
            let key = format!("folder:{what}");
            match std::fs::symlink_metadata(p) {
                Ok(m) if m.is_dir() => {
                    self.error_over(&key, &format!("the {what} {} is back", p.display()))
                }
                Ok(_) => {
                    ok = false;
                    self.error_limited(&key, &format!("the {what} {} is not a folder any more (a file or a link in its place); no file is taken until it is one again", p.display()));
                }
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    match std::fs::create_dir_all(p) {
                        Ok(()) => {
                            tracing::warn!(
                                "the {what} {} had vanished: created again",
                                p.display()
                            );
                            if what == "inbox" {
                                if let Some(w) = self.watcher.as_mut() {
                                    if let Err(e) = w.rewatch() {
                                        tracing::error!(
                                            "cannot watch the inbox again: {e}; polling it"
                                        );
                                    }
                                }
                                self.rescan_flag.store(true, Ordering::SeqCst);
                            }
                        }
                        Err(e) => {
                            ok = false;
                            self.error_limited(&key, &format!("the {what} {} vanished and cannot be created again: {e}; no file is taken until it can", p.display()));
                        }
                    }
                }
                Err(e) => {
                    ok = false;
                    self.error_limited(&key, &format!("the {what} {}: {e}", p.display()));
                }
            }
        }
        if ok {
            if let Err(e) = self.layout.check_aliases() {
                ok = false;
                self.error_limited(
                    "aliases",
                    &format!("{e}; no file is taken until that changes"),
                );
            }
        }
        if ok {
            for p in [
                self.layout.processing_root.clone(),
                self.layout.tmp_root.clone(),
            ] {
                if let Err(e) = claim::make_private_dir(&p, 0o755) {
                    ok = false;
                    self.error_limited(
                        "private",
                        &format!("{e}; no file is taken until that changes"),
                    );
                }
            }
        }
        if ok && !self.home.intact() {
            // our folder went (with the inbox): a new one; files in the old one, if any,
            // are gone with it
            match Home::create(&self.layout, &self.id.tag()) {
                Ok(h) => {
                    tracing::warn!(
                        "this daemon's folder {} had vanished: created again",
                        h.dir.display()
                    );
                    self.home = Arc::new(h);
                }
                Err(e) => {
                    ok = false;
                    self.error_limited(
                        "home",
                        &format!("cannot create this daemon's folder again: {e}"),
                    );
                }
            }
        }
        if ok && !self.home.tmp.is_dir() {
            use std::os::unix::fs::DirBuilderExt;
            match std::fs::DirBuilder::new()
                .mode(0o700)
                .create(&self.home.tmp)
            {
                Ok(()) => {
                    tracing::warn!(
                        "the temporary folder {} had vanished: created again",
                        self.home.tmp.display()
                    );
                    if let Err(e) = self.write_policy_snapshot() {
                        ok = false;
                        self.error_limited(
                            "policy",
                            &format!("cannot store the policy snapshot again: {e}"),
                        );
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => {
                    ok = false;
                    self.error_limited(
                        "tmp",
                        &format!(
                            "cannot create the temporary folder {}: {e}",
                            self.home.tmp.display()
                        ),
                    );
                }
            }
        }
        self.folders_ok = ok;
        ok
    }

    /// Writes the current policy snapshot again (its folder was recreated).
    fn write_policy_snapshot(&mut self) -> Result<()> {
        if let (Some(text), Some(path)) = (&self.policy_text, &self.ctx.policy) {
            holefill::io::write_atomic(path, text.as_bytes())
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        Ok(())
    }

    /// Lists the inbox, adopts the folders of dead daemons, tidies up.
    fn rescan(&mut self) {
        self.last_scan = Instant::now();
        self.adopt_dead();
        claim::clean_staging(&self.layout);
        claim::clean_tmp(&self.layout);
        claim::ledger_clean(&self.layout);
        self.pending.overflowed = false;
        self.expect.clear();
        let now = Instant::now();
        match std::fs::read_dir(&self.layout.inbox) {
            Ok(rd) => {
                let mut listed = std::collections::HashSet::new();
                for e in rd.flatten() {
                    let name = e.file_name();
                    if claim::is_watched_name(&name) && !e.file_type().is_ok_and(|t| t.is_dir()) {
                        self.pending.note(&name, Seen::Scan, now);
                        if !claim::is_candidate_name(&name) {
                            listed.insert(name);
                        }
                    }
                }
                self.pending.retain_members(&listed);
            }
            Err(e) => {
                let msg = format!("cannot list the inbox {}: {e}", self.layout.inbox.display());
                self.error_limited("list", &msg);
            }
        }
    }

    /// Takes over the folders of daemons that died (their lock is free).
    fn adopt_dead(&mut self) {
        let Ok(rd) = std::fs::read_dir(&self.layout.processing_root) else {
            return;
        };
        let tags: Vec<String> = rd
            .flatten()
            .filter_map(|e| e.file_name().into_string().ok())
            .filter(|t| !t.starts_with('.'))
            .filter(|t| *t != self.home.tag && !self.adopted.iter().any(|h| h.tag == *t))
            .collect();
        for tag in tags {
            match Home::adopt(&self.layout, &tag) {
                Ok(Some(h)) => {
                    let h = Arc::new(h);
                    let jobs = claim::jobs_of(&h, &self.id);
                    if jobs.is_empty() {
                        if !h.remove_if_empty() {
                            tracing::warn!("{}: a dead daemon's folder with files that are not jobs; left alone", h.dir.display());
                        }
                        continue;
                    }
                    tracing::warn!(
                        "taking over {} files of a daemon that died ({})",
                        jobs.len(),
                        h.dir.display()
                    );
                    for job in jobs {
                        match &job.rec.phase {
                            Phase::Claimed => {
                                tracing::warn!(file = %job.shown(), attempts = job.rec.attempts, "{}: recovered from a daemon that died while repairing it", job.shown())
                            }
                            _ => {
                                tracing::warn!(file = %job.shown(), "{}: recovered from a daemon that died while publishing it; finishing that (not repaired again)", job.shown())
                            }
                        }
                        self.again.push_back((job, Instant::now()));
                    }
                    self.adopted.push(h);
                }
                Ok(None) => {}
                Err(msg) => {
                    self.error_limited(
                        &format!("foreign:{tag}"),
                        &format!("{msg}; its files are left alone"),
                    );
                }
            }
        }
    }

    /// Releases the adopted folders whose jobs are all done.
    fn release_adopted(&mut self) {
        let busy = |tag: &str, d: &Daemon| {
            d.working.values().any(|(t, _)| t == tag)
                || d.again.iter().any(|(j, _)| j.home.tag == tag)
                || d.sets.iter().any(|p| p.job.home.tag == tag)
        };
        let mut keep = Vec::new();
        for h in std::mem::take(&mut self.adopted) {
            if busy(&h.tag, self) || !h.remove_if_empty() {
                keep.push(h);
            }
        }
        self.adopted = keep;
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

    /// Looks at the waiting sets: claims the members of each complete set (or of one
    /// that timed out) beside its mesh and starts it, while fewer than `workers`
    /// repairs run.
    fn advance_sets(&mut self) {
        let now = Instant::now();
        let mut keep = Vec::new();
        for mut p in std::mem::take(&mut self.sets) {
            if self.working.len() >= self.settings.workers {
                keep.push(p);
                continue;
            }
            let set = match self.assemble(&mut p, now) {
                Assembly::Wait(what) => {
                    if what != p.said {
                        tracing::info!(file = %p.job.shown(), "{}: its set waits for {what}", p.job.shown());
                        p.said = what;
                    }
                    keep.push(p);
                    continue;
                }
                Assembly::TimedOut(set) => {
                    tracing::warn!(file = %p.job.shown(), "{}: {} after set_wait_secs = {} s; the set goes to failed", p.job.shown(), set.missing_message(), self.settings.set_wait.as_secs());
                    set
                }
                Assembly::Complete(set) => set,
            };
            let names: Vec<String> = set
                .members
                .iter()
                .map(|m| shown(OsStr::new(&m.name)))
                .collect();
            match claim::claim_members(&self.layout, &mut p.job, set) {
                Ok(true) => {
                    tracing::info!(file = %p.job.shown(), "{}: its set is complete: {}", p.job.shown(), if names.is_empty() { "no other file".to_string() } else { names.join(", ") });
                    self.spawn(p.job);
                }
                Ok(false) => {
                    tracing::info!(file = %p.job.shown(), "{}: a file of its set changed or went while it was taken; it waits again", p.job.shown());
                    keep.push(p);
                }
                Err(e) => {
                    tracing::warn!(file = %p.job.shown(), "{}: cannot take the files of its set: {e}; later", p.job.shown());
                    keep.push(p);
                }
            }
        }
        keep.append(&mut self.sets);
        self.sets = keep;
    }

    /// Judges the files of a waiting set (see [`sets`]): references followed or not,
    /// each member missing, not complete, or complete (an MTL read once complete, its
    /// images added).
    fn assemble(&mut self, p: &mut Parked, now: Instant) -> Assembly {
        let inbox = self.layout.inbox.clone();
        let (settle, max_wait) = (self.settings.settle, self.settings.max_wait);
        let mesh = p.job.name_str().unwrap_or_default().to_string();
        let mut set = SetRec::default();
        let mut not_yet: Vec<String> = Vec::new();
        let mut wanted: Vec<(String, Role, String)> = Vec::new();
        for (r, role) in &p.refs {
            if *role == Role::MaterialLibrary {
                // a whole name with spaces is looked for only when it is one to follow
                let exists = |w: &str| {
                    sets::member_name(w, &mesh).is_ok()
                        && std::fs::symlink_metadata(inbox.join(w)).is_ok()
                };
                for n in sets::split_libs(r, exists) {
                    wanted.push((n, Role::MaterialLibrary, mesh.clone()));
                }
            } else {
                wanted.push((r.clone(), *role, mesh.clone()));
            }
        }
        let mut k = 0;
        while k < wanted.len() {
            let (reference, role, by) = wanted[k].clone();
            k += 1;
            let name = match sets::member_name(&reference, &mesh) {
                Ok(n) => n,
                Err(why) => {
                    set.refused.push(Refused { reference, by, why });
                    continue;
                }
            };
            if set.members.iter().any(|m| m.name == name)
                || set.missing.iter().any(|m| m.name == name)
                || not_yet.contains(&name)
            {
                continue;
            }
            let state = self
                .pending
                .member_state(&inbox, OsStr::new(&name), settle, max_wait, now);
            match state {
                MemberState::Missing => set.missing.push(Missing { name, role, by }),
                MemberState::NotRegular => set.refused.push(Refused {
                    reference,
                    by,
                    why: "not a regular file (a symbolic link, FIFO, ...): never followed".into(),
                }),
                MemberState::NotYet => not_yet.push(name),
                MemberState::Ready(stamp) => {
                    if role == Role::MaterialLibrary {
                        let images = match p.libs.get(&name) {
                            Some((st, imgs)) if *st == stamp => imgs.clone(),
                            _ => match sets::read_mtl(&inbox.join(&name)) {
                                Ok((imgs, st)) if st == stamp => {
                                    p.libs.insert(name.clone(), (st, imgs.clone()));
                                    imgs
                                }
                                // changed since it was judged: judged again
                                Ok(_) => {
                                    not_yet.push(name);
                                    continue;
                                }
                                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                                    set.missing.push(Missing { name, role, by });
                                    continue;
                                }
                                Err(e) => {
                                    set.refused.push(Refused {
                                        reference,
                                        by,
                                        why: format!("cannot be read: {e}"),
                                    });
                                    continue;
                                }
                            },
                        };
                        for img in images {
                            wanted.push((img, Role::Texture, name.clone()));
                        }
                    }
                    set.members.push(Member {
                        name,
                        role,
                        by,
                        stamp,
                        copy: None,
                        placed: None,
                    });
                }
            }
        }
        if set.members.len() > p.ready {
            p.ready = set.members.len();
            p.since = now;
        }
        if !set.missing.is_empty() && now.duration_since(p.since) >= self.settings.set_wait {
            return Assembly::TimedOut(set);
        }
        if !set.missing.is_empty() || !not_yet.is_empty() {
            let mut what: Vec<String> = set
                .missing
                .iter()
                .map(|m| format!("{} {} (missing)", m.role.what(), shown(OsStr::new(&m.name))))
                .collect();
            what.extend(
                not_yet
                    .iter()
                    .map(|n| format!("{} (not complete yet)", shown(OsStr::new(n)))),
            );
            return Assembly::Wait(what.join(", "));
        }
        Assembly::Complete(set)
    }

    /// Claims ready files while fewer than `workers` repairs run.
    fn dispatch(&mut self) {
        if self.working.len() >= self.settings.workers {
            return;
        }
        if !self.check_folders(false) {
            return;
        }
        self.advance_sets();
        while self.working.len() < self.settings.workers {
            let now = Instant::now();
            if let Some(pos) = self.again.iter().position(|(_, t)| *t <= now) {
                if let Some((job, _)) = self.again.remove(pos) {
                    self.spawn(job);
                }
                continue;
            }
            let Some(r) = self.pending.take_ready(
                &self.layout.inbox,
                self.settings.settle,
                self.settings.max_wait,
                now,
            ) else {
                break;
            };
            if r.waited_out {
                tracing::warn!(file = %shown(&r.name), "{}: taken after max_wait_secs = {} s without a change, though {}", shown(&r.name), self.settings.max_wait.as_secs(), if r.stamp.size == 0 { "empty" } else { "still held open" });
            }
            match claim::claim(
                &self.layout,
                &self.home,
                self.id.next_id(),
                &r.name,
                r.stamp,
                r.received,
            ) {
                Ok(Some(job)) => {
                    tracing::debug!(file = %job.shown(), id = %job.id, "claimed");
                    self.ctx.hooks.at("claimed", &job.name);
                    self.spawn(job);
                }
                Ok(None) => {}
                Err(e) => {
                    tracing::warn!(file = %shown(&r.name), "cannot claim {}: {e}; later", shown(&r.name));
                    self.pending.note(&r.name, Seen::RenamedIn, now);
                    self.pending.defer(&r.name, now + Duration::from_secs(5));
                    self.folders_checked = None;
                    break;
                }
            }
        }
    }

    fn spawn(&mut self, job: Job) {
        self.working
            .insert(job.id.clone(), (job.home.tag.clone(), job.shown()));
        let ctx = self.ctx.clone();
        let cancel = self.cancel.subscribe();
        let tx = self.done_tx.clone();
        tokio::spawn(async move {
            let kept = job.clone();
            let done = match tokio::spawn(worker::process(ctx, job, cancel)).await {
                Ok(d) => d,
                // a bug, not the file's fault: it stays where it is and is tried again
                Err(e) => Done::Later {
                    job: kept,
                    error: format!("internal error: {e}"),
                },
            };
            let _ = tx.send(done);
        });
    }

    fn on_done(&mut self, done: Done) {
        self.working.remove(&done.job().id);
        match done {
            Done::Repaired {
                job,
                output,
                filled,
                skipped,
                failed,
                secs,
                resumed,
            } => {
                self.repaired += 1;
                self.retries.remove(&job.name);
                self.file_done(
                    &self.layout.outbox.join(format!("{output}.repair.json")),
                    None,
                    secs,
                    job.rec.stamp.map(|s| s.size),
                );
                let name = job.shown();
                let output = shown(OsStr::new(&output));
                let how = if resumed {
                    " (published for a daemon that died after repairing it; not repaired again)"
                } else {
                    ""
                };
                tracing::info!(
                    file = %name,
                    status = "repaired",
                    output = %output,
                    filled,
                    skipped,
                    holes_failed = failed,
                    secs,
                    "{name} repaired -> {output}: holes {filled} filled, {skipped} skipped, {failed} failed; {secs:.2} s{how}"
                );
            }
            Done::Failed {
                job,
                stage,
                error,
                secs,
            } => {
                self.failed += 1;
                self.retries.remove(&job.name);
                if let Phase::Failed { dest, .. } = &job.rec.phase {
                    self.file_done(
                        &self.layout.failed.join(format!("{dest}.repair.json")),
                        Some(stage.as_str()),
                        secs,
                        job.rec.stamp.map(|s| s.size),
                    );
                }
                let name = job.shown();
                tracing::warn!(
                    file = %name,
                    status = "failed",
                    stage,
                    error = %error,
                    secs,
                    "{name} failed at {stage}: {error}; holes - filled, - skipped, - failed; {secs:.2} s"
                );
            }
            Done::Again { job, error } => {
                if let Some(m) = metrics::global() {
                    m.retry("crashed");
                }
                tracing::warn!(file = %job.shown(), attempt = job.attempt, "{}: attempt {} of {} failed: {error}", job.shown(), job.attempt, self.settings.max_attempts);
                let next = Job {
                    attempt: job.attempt + 1,
                    ..job
                };
                let delay =
                    Duration::from_millis(500 * next.attempt as u64).min(self.settings.retry_max);
                self.again.push_back((next, Instant::now() + delay));
                if self.stopping.is_some() {
                    self.put_back_waiting();
                }
            }
            Done::Later { mut job, error } => {
                let now = Instant::now();
                let name = job.shown();
                if job
                    .warned
                    .is_none_or(|t| now.duration_since(t) >= ERROR_EVERY)
                {
                    tracing::error!(file = %name, "{name}: {error}; it waits in {} and is tried again", job.home.dir.display());
                    job.warned = Some(now);
                } else {
                    tracing::debug!(file = %name, "{name}: {error}");
                }
                self.folders_checked = None;
                let delay = if self.stopping.is_some() {
                    Duration::ZERO
                } else {
                    Duration::from_secs(5)
                };
                self.again.push_back((job, now + delay));
                if self.stopping.is_some() {
                    self.put_back_waiting();
                }
            }
            Done::PutBack {
                job,
                inbox_name,
                error,
                changed,
            } => {
                let name = job.shown();
                let back = shown(&inbox_name);
                let now = Instant::now();
                if let (Some(m), None) = (metrics::global(), self.stopping) {
                    m.retry(if changed { "changed" } else { "retryable" });
                }
                // a folder may have gone (the outbox): checked again before the next claim
                self.folders_checked = None;
                if self.watcher.is_some() && changed {
                    self.expect.insert(inbox_name.clone(), Seen::Changed);
                }
                if self.stopping.is_some() {
                    tracing::info!(file = %name, "{name}: put back into the inbox as {back}");
                    return;
                }
                if changed {
                    tracing::warn!(file = %name, "{name}: {}; back in the inbox as {back}", error.as_deref().unwrap_or("changed"));
                    self.pending.note(&inbox_name, Seen::Changed, now);
                    return;
                }
                let n = self.retries.entry(inbox_name.clone()).or_insert(0);
                *n += 1;
                let delay =
                    Duration::from_secs(1u64 << (*n - 1).min(20)).min(self.settings.retry_max);
                tracing::warn!(
                    file = %name,
                    "{name}: {}; back in the inbox as {back}, retry in {} s",
                    error.as_deref().unwrap_or("put back"),
                    delay.as_secs()
                );
                self.pending.note(&inbox_name, Seen::RenamedIn, now);
                self.pending.defer(&inbox_name, now + delay);
                self.folders_checked = None;
            }
            Done::Gone { job, error } => {
                tracing::error!(file = %job.shown(), "{}: {error}; nothing left to do for it", job.shown());
            }
            Done::Members { job, refs } => {
                let name = job.shown();
                let named: Vec<String> = refs.iter().map(|(r, _)| shown(OsStr::new(r))).collect();
                tracing::info!(file = %name, "{name}: a set (it names {}): waiting for its files", named.join(", "));
                self.sets.push(Parked {
                    job,
                    refs,
                    since: Instant::now(),
                    ready: 0,
                    libs: HashMap::new(),
                    said: String::new(),
                });
                if self.stopping.is_some() {
                    self.put_back_waiting();
                }
            }
        }
        self.release_adopted();
    }

    /// A file's end (repaired, or failed at `stage`), its log published at `log`: into
    /// the index and the metrics.
    fn file_done(&mut self, log: &Path, stage: Option<&str>, secs: f64, bytes: Option<u64>) {
        let m = metrics::global();
        if self.index.is_none() && m.is_none() {
            return;
        }
        let read = index::read_log(log);
        if let Some(ix) = self.index.as_mut() {
            ix.add(log, read.as_ref());
        }
        match (m, stage) {
            (Some(m), Some(stage)) => m.failed(stage, secs, bytes),
            (Some(m), None) => m.repaired(read.as_ref().map(|(v, _)| v), secs, bytes),
            (None, _) => {}
        }
    }

    fn begin_stop(&mut self, why: &str) {
        if self.stopping.is_some() {
            if !self.cancelled {
                tracing::warn!("{why} again: killing the running repairs now");
                self.cancelled = true;
                let _ = self.cancel.send(true);
            }
            return;
        }
        let grace = self.settings.grace;
        self.stopping = Some(Instant::now() + grace);
        tracing::info!(
            "{why}: stopping; {} repairs running, up to {} s to finish",
            self.working.len(),
            grace.as_secs()
        );
        let usec = (grace + Duration::from_secs(10))
            .as_micros()
            .min(u32::MAX as u128) as u32;
        sd(&[
            NotifyState::Stopping,
            NotifyState::ExtendTimeoutUsec(usec),
            NotifyState::Status("stopping"),
        ]);
        self.put_back_waiting();
    }

    /// At shutdown: puts the waiting jobs that are only claimed back into the inbox
    /// (their failed attempts recorded); jobs further on stay for the next daemon.
    fn put_back_waiting(&mut self) {
        while let Some((job, _)) = self.again.pop_front() {
            let name = job.shown();
            match worker::put_back_waiting(&self.ctx, &job) {
                Some(Ok(n)) => {
                    tracing::info!(file = %name, "{name}: put back into the inbox as {}", shown(&n))
                }
                Some(Err(e)) => {
                    tracing::error!(file = %name, "{name}: cannot put back into the inbox: {e}; it stays in {}", job.home.dir.display())
                }
                None => {
                    tracing::warn!(file = %name, "{name}: left in {} for the next daemon to finish", job.home.dir.display())
                }
            }
        }
        for p in std::mem::take(&mut self.sets) {
            let name = p.job.shown();
            match worker::put_back_waiting(&self.ctx, &p.job) {
                Some(Ok(n)) => {
                    tracing::info!(file = %name, "{name}: put back into the inbox as {} (its set was not complete)", shown(&n))
                }
                Some(Err(e)) => {
                    tracing::error!(file = %name, "{name}: cannot put back into the inbox: {e}; it stays in {}", p.job.home.dir.display())
                }
                None => {
                    tracing::warn!(file = %name, "{name}: left in {} for the next daemon", p.job.home.dir.display())
                }
            }
        }
    }

    fn reload(&mut self) {
        if self.stopping.is_some() {
            return;
        }
        let mono = NotifyState::monotonic_usec_now().ok();
        let mut st = vec![NotifyState::Reloading];
        st.extend(mono);
        sd(&st);
        self.try_reload();
        sd(&[NotifyState::Ready]);
    }

    fn try_reload(&mut self) {
        let new = match Settings::load(&self.args) {
            Ok(s) => s,
            Err(e) => {
                tracing::error!("SIGHUP: the config is refused, the old one kept: {e:#}");
                return;
            }
        };
        let fixed = self.settings.restart_only_changes(&new);
        if !fixed.is_empty() {
            tracing::warn!(
                "SIGHUP: {} cannot change without a restart; kept",
                fixed.join(", ")
            );
        }
        let new = self.settings.reloaded(&new);
        if let Err(e) = child::probe_limits(new.memory_limit_mb) {
            tracing::error!("SIGHUP: the config is refused, the old one kept: {e:#}");
            return;
        }
        let (policy, text) = match snapshot_policy(&new, &self.home.tmp, self.generation + 1) {
            Ok(p) => p,
            Err(e) => {
                tracing::error!("SIGHUP: the policy is refused, the old one kept: {e:#}");
                return;
            }
        };
        self.generation += 1;
        self.policy_text = text;
        self.ctx = Arc::new(RunCtx {
            settings: new.clone(),
            policy,
            policy_source: new.policy.clone(),
            layout: self.ctx.layout.clone(),
            host: self.ctx.host.clone(),
            pid: self.ctx.pid,
            instance: self.ctx.instance.clone(),
            exe: self.ctx.exe.clone(),
            hooks: self.ctx.hooks.clone(),
            cores: self.ctx.cores,
            forward: self.ctx.forward.clone(),
        });
        self.settings = new;
        tracing::info!(policy = ?self.settings.policy, "SIGHUP: config and policy reloaded");
    }

    fn shutdown(&mut self) {
        self.put_back_waiting();
        for h in std::iter::once(self.home.clone()).chain(self.adopted.drain(..)) {
            if !h.remove_if_empty() {
                tracing::warn!(
                    "files remain in {}: the next daemon finishes them",
                    h.dir.display()
                );
            }
        }
        claim::ledger_clean(&self.layout);
        let _ = fsops::fsync_dir(&self.layout.inbox);
        if let Some(ix) = self.index.as_mut() {
            ix.flush(true);
        }
        tracing::info!(
            repaired = self.repaired,
            failed = self.failed,
            "stopped: {}",
            self.status()
        );
    }
}
