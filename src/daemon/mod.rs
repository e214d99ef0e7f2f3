//! The daemon, `holefill watch`: repairs every mesh dropped into an inbox exactly once,
//! writes the model and its repair log into an outbox, and runs as a systemd service.
//!
//! It knows nothing of geometry: each repair is a `holefill fill` child process
//! ([`worker`]). The pieces:
//! - [`config`]: `config/holefill.toml` and the flags that override it;
//! - [`queue`]: which files wait in the inbox and when each is complete enough to take
//!   (renamed in, or written in place and settled);
//! - [`claim`]: the atomic claim into this daemon's processing folder, the attempt
//!   counter, the recovery of dead daemons' files;
//! - [`worker`]: limits, the child process, outbox / failed folder / back into the inbox;
//! - [`fsops`]: moves that never overwrite, folder fsync, the collision rule.
//!
//! The main loop (one tokio task) takes change events (notify; rescans at start-up, on
//! overflow and on a timer; or polling), claims complete files while fewer than
//! `workers` repairs run, and handles signals: SIGTERM/SIGINT stop claiming and let the
//! running repairs finish within the grace period (then kill them and put their files
//! back), SIGHUP reloads the config and policy. It tells systemd READY=1 after the
//! start-up scan, STATUS= with counts, WATCHDOG=1 pings, STOPPING=1.

mod claim;
mod config;
mod fsops;
mod queue;
mod sniff;
mod worker;

use anyhow::{Context, Result};
use claim::{Identity, Layout};
use config::{Collision, LogFormat, OnSuccess, Settings};
use holefill::policy::Policy;
use queue::{Pending, Seen};
use sd_notify::NotifyState;
use std::collections::{HashMap, HashSet, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{mpsc, watch};
use worker::{Done, Job, RunCtx, TestHooks};

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
    /// What becomes of a repaired original [default: archive].
    #[arg(long, value_enum)]
    pub on_success: Option<OnSuccess>,
    /// Rule for an output name already taken [default: timestamp].
    #[arg(long, value_enum)]
    pub collision: Option<Collision>,
    /// Journal format on stderr [default: text].
    #[arg(long, value_enum)]
    pub log_format: Option<LogFormat>,
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
fn snapshot_policy(settings: &Settings, dir: &Path, generation: u32) -> Result<Option<PathBuf>> {
    let Some(src) = &settings.policy else {
        return Ok(None);
    };
    let text = std::fs::read_to_string(src)
        .with_context(|| format!("{}: cannot read the policy", src.display()))?;
    Policy::from_toml_str(&text, src).map_err(|e| anyhow::anyhow!("invalid policy: {e}"))?;
    let snap = dir.join(format!("policy-{generation}.toml"));
    holefill::io::write_atomic(&snap, text.as_bytes())
        .map_err(|e| anyhow::anyhow!("cannot store the policy snapshot: {e}"))?;
    Ok(Some(snap))
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

struct Daemon {
    args: WatchArgs,
    settings: Settings,
    id: Identity,
    layout: Layout,
    ctx: Arc<RunCtx>,
    generation: u32,
    pending: Pending,
    /// Crashed attempts waiting to run again (files in our folder), with their time.
    again: VecDeque<(Job, Instant)>,
    working: HashSet<String>,
    /// Retryable failures per inbox name (for the back-off).
    retries: HashMap<String, u32>,
    /// Names we put back with link(2): their create event is ours, not a writer's.
    expect_create: HashSet<String>,
    repaired: u64,
    failed: u64,
    cancel: watch::Sender<bool>,
    done_tx: mpsc::UnboundedSender<Done>,
    done_rx: mpsc::UnboundedReceiver<Done>,
    events: Option<mpsc::Receiver<notify::Result<notify::Event>>>,
    events_on: bool,
    _watcher: Option<notify::RecommendedWatcher>,
    rescan_flag: Arc<AtomicBool>,
    last_scan: Instant,
    last_status: String,
    watchdog: Option<Duration>,
    last_ping: Instant,
    stopping: Option<Instant>,
    cancelled: bool,
}

impl Daemon {
    async fn start(args: WatchArgs, settings: Settings) -> Result<Daemon> {
        let id = Identity::current();
        let layout = Layout::create(
            &settings.inbox,
            &settings.outbox,
            &settings.failed,
            &settings.archive,
            &id,
        )
        .context("cannot create the folders")?;
        worker::probe_limits(settings.memory_limit_mb)?;
        let policy = snapshot_policy(&settings, &layout.tmp, 0)?;
        let exe = std::env::current_exe().context("cannot find the holefill executable")?;
        let cores = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1);
        let hooks = TestHooks::from_env();
        if hooks.slow.is_some() || hooks.crash_on.is_some() {
            tracing::warn!("test hooks active (HOLEFILL_TEST_*): {hooks:?}");
        }
        let ctx = Arc::new(RunCtx {
            layout: layout.clone(),
            host: id.host.clone(),
            pid: id.pid,
            settings: settings.clone(),
            policy,
            policy_source: settings.policy.clone(),
            exe,
            hooks,
            cores,
        });
        let (cancel, _) = watch::channel(false);
        let (done_tx, done_rx) = mpsc::unbounded_channel();
        let rescan_flag = Arc::new(AtomicBool::new(false));

        // the watcher first, then the scan: a file arriving in between is seen by one
        let (events, watcher) = if settings.poll {
            (None, None)
        } else {
            let (tx, rx) = mpsc::channel(4096);
            let flag = rescan_flag.clone();
            let mut w = notify::recommended_watcher(move |res: notify::Result<notify::Event>| {
                // a full queue loses events: rescan instead (memory stays bounded)
                if tx.try_send(res).is_err() {
                    flag.store(true, Ordering::SeqCst);
                }
            })
            .context("cannot start the inbox watcher (try poll = true)")?;
            use notify::Watcher;
            w.watch(&layout.inbox, notify::RecursiveMode::NonRecursive)
                .with_context(|| {
                    format!("cannot watch {} (try poll = true)", layout.inbox.display())
                })?;
            (Some(rx), Some(w))
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
            ctx,
            generation: 0,
            again: VecDeque::new(),
            working: HashSet::new(),
            retries: HashMap::new(),
            expect_create: HashSet::new(),
            repaired: 0,
            failed: 0,
            cancel,
            done_tx,
            done_rx,
            events_on: events.is_some(),
            events,
            _watcher: watcher,
            rescan_flag,
            last_scan: Instant::now(),
            last_status: String::new(),
            watchdog,
            last_ping: Instant::now(),
            stopping: None,
            cancelled: false,
        };
        d.rescan(true);
        tracing::info!(
            inbox = %d.layout.inbox.display(),
            outbox = %d.layout.outbox.display(),
            failed = %d.layout.failed.display(),
            archive = %d.layout.archive.display(),
            workers = d.settings.workers,
            mode = if d.settings.poll { "poll" } else { "events" },
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
            self.pending.len() + self.again.len(),
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
                    self.rescan(false);
                }
                self.dispatch();
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

    /// Lists the inbox and takes over dead daemons' files.
    fn rescan(&mut self, startup: bool) {
        self.last_scan = Instant::now();
        for r in claim::recover(&self.layout, &self.id, startup) {
            if self.working.contains(&r.name) || self.again.iter().any(|(j, _)| j.name == r.name) {
                continue;
            }
            if let Some(output) = &r.published {
                self.finish_published(&r.name, output);
                continue;
            }
            tracing::warn!(file = %r.name, attempts = r.sidecar.attempts, "recovered from a daemon that died while repairing it");
            self.again.push_back((
                Job {
                    name: r.name,
                    attempt: r.sidecar.attempts + 1,
                    received: r.sidecar.received,
                },
                Instant::now(),
            ));
        }
        claim::clean_tmp(&self.layout, &self.id);
        self.pending.overflowed = false;
        self.expect_create.clear();
        let now = Instant::now();
        match std::fs::read_dir(&self.layout.inbox) {
            Ok(rd) => {
                for e in rd.flatten() {
                    let Ok(name) = e.file_name().into_string() else {
                        continue; // not UTF-8: cannot be named in a JSON log
                    };
                    if claim::is_candidate_name(&name)
                        && e.file_type().map(|t| t.is_file()).unwrap_or(false)
                    {
                        self.pending.note(&name, Seen::Scan, now);
                    }
                }
            }
            Err(e) => tracing::error!("cannot list the inbox {}: {e}", self.layout.inbox.display()),
        }
    }

    /// A recovered file whose model and log a dead daemon had already published: only
    /// the original's archiving (or deletion) was left to do.
    fn finish_published(&mut self, name: &str, output: &str) {
        let src = self.layout.mine.join(name);
        let r = match self.settings.on_success {
            OnSuccess::Archive => {
                fsops::move_into(&src, &self.layout.archive, name, &[]).map(|_| ())
            }
            OnSuccess::Delete => std::fs::remove_file(&src),
        };
        match r {
            Ok(()) => {
                let _ = std::fs::remove_file(self.layout.sidecar(name));
                let _ = fsops::fsync_dir(&self.layout.mine);
                self.repaired += 1;
                tracing::info!(
                    file = %name,
                    status = "repaired",
                    output = %output,
                    "{name} repaired -> {output} (by a daemon that died before archiving the original; not repaired again)"
                );
            }
            Err(e) => {
                tracing::error!(file = %name, "{name}: already repaired as {output}, but the original could not be archived: {e}")
            }
        }
    }

    fn on_event(&mut self, ev: notify::Result<notify::Event>) {
        use notify::event::{AccessKind, AccessMode, EventKind, ModifyKind, RenameMode};
        let ev = match ev {
            Ok(ev) => ev,
            Err(e) => {
                tracing::warn!("watcher error (rescanning): {e}");
                self.rescan_flag.store(true, Ordering::SeqCst);
                self.pending.forget_events();
                return;
            }
        };
        if ev.need_rescan() {
            self.rescan_flag.store(true, Ordering::SeqCst);
            self.pending.forget_events();
        }
        let now = Instant::now();
        let inbox = &self.layout.inbox;
        let name_of = |p: &PathBuf| -> Option<String> {
            (p.parent() == Some(inbox.as_path()))
                .then(|| p.file_name()?.to_str().map(str::to_string))
                .flatten()
        };
        let names: Vec<Option<String>> = ev.paths.iter().map(name_of).collect();
        let mut note = |i: usize, seen: Seen| {
            if let Some(Some(n)) = names.get(i) {
                self.pending.note(n, seen, now);
            }
        };
        match ev.kind {
            EventKind::Create(_) => {
                if let Some(Some(n)) = names.first() {
                    if self.expect_create.remove(n) {
                        return;
                    }
                }
                note(0, Seen::Created)
            }
            EventKind::Modify(ModifyKind::Name(RenameMode::To)) => note(0, Seen::RenamedIn),
            EventKind::Modify(ModifyKind::Name(RenameMode::From)) => note(0, Seen::Removed),
            EventKind::Modify(ModifyKind::Name(RenameMode::Both)) => {
                note(0, Seen::Removed);
                note(1, Seen::RenamedIn);
            }
            EventKind::Modify(ModifyKind::Name(_)) => {
                self.rescan_flag.store(true, Ordering::SeqCst)
            }
            EventKind::Modify(ModifyKind::Metadata(_)) => note(0, Seen::Created),
            EventKind::Modify(_) => note(0, Seen::Written),
            EventKind::Access(AccessKind::Close(AccessMode::Write)) => note(0, Seen::Closed),
            EventKind::Remove(_) => note(0, Seen::Removed),
            _ => {}
        }
    }

    /// Claims complete files while fewer than `workers` repairs run.
    fn dispatch(&mut self) {
        while self.working.len() < self.settings.workers {
            let now = Instant::now();
            if let Some(pos) = self.again.iter().position(|(_, t)| *t <= now) {
                if let Some((job, _)) = self.again.remove(pos) {
                    self.spawn(job);
                }
                continue;
            }
            let Some((name, received)) =
                self.pending
                    .take_ready(&self.layout.inbox, self.settings.settle, now)
            else {
                break;
            };
            match claim::claim(&self.layout, &name) {
                Ok(Some(_)) => {
                    tracing::debug!(file = %name, "claimed");
                    self.spawn(Job {
                        name,
                        attempt: 1,
                        received: fsops::rfc3339(received),
                    });
                }
                Ok(None) => {}
                Err(e) if fsops::is_disk_full(&e) => {
                    tracing::warn!(file = %name, "cannot claim (disk full), later: {e}");
                    self.pending.note(&name, Seen::RenamedIn, now);
                    self.pending.defer(&name, now + Duration::from_secs(5));
                    break;
                }
                Err(e) => tracing::warn!(file = %name, "cannot claim: {e}"),
            }
        }
    }

    fn spawn(&mut self, job: Job) {
        self.working.insert(job.name.clone());
        let ctx = self.ctx.clone();
        let cancel = self.cancel.subscribe();
        let tx = self.done_tx.clone();
        let name = job.name.clone();
        tokio::spawn(async move {
            let h = tokio::spawn(worker::process(ctx, job, cancel));
            let done = match h.await {
                Ok(Done::Stranded { name: n, error }) if n.is_empty() => {
                    Done::Stranded { name, error }
                }
                Ok(d) => d,
                Err(e) => Done::Stranded {
                    name,
                    error: format!("internal error: {e}"),
                },
            };
            let _ = tx.send(done);
        });
    }

    fn on_done(&mut self, done: Done) {
        self.working.remove(done.name());
        match done {
            Done::Repaired {
                name,
                output,
                filled,
                skipped,
                failed,
                secs,
            } => {
                self.repaired += 1;
                self.retries.remove(&name);
                tracing::info!(
                    file = %name,
                    status = "repaired",
                    output = %output,
                    filled,
                    skipped,
                    holes_failed = failed,
                    secs,
                    "{name} repaired -> {output}: holes {filled} filled, {skipped} skipped, {failed} failed; {secs:.2} s"
                );
            }
            Done::Failed {
                name,
                stage,
                error,
                secs,
            } => {
                self.failed += 1;
                self.retries.remove(&name);
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
                tracing::warn!(file = %job.name, attempt = job.attempt, "{}: attempt {} of {} failed: {error}", job.name, job.attempt, self.settings.max_attempts);
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
            Done::PutBack {
                name,
                inbox_name,
                error,
            } => {
                if self.events_on {
                    self.expect_create.insert(inbox_name.clone());
                }
                if self.stopping.is_some() {
                    tracing::info!(file = %name, "put back into the inbox as {inbox_name}");
                    return;
                }
                let n = self.retries.entry(inbox_name.clone()).or_insert(0);
                *n += 1;
                let delay =
                    Duration::from_secs(1u64 << (*n - 1).min(20)).min(self.settings.retry_max);
                tracing::warn!(
                    file = %name,
                    "{name}: {}; back in the inbox as {inbox_name}, retry in {} s",
                    error.as_deref().unwrap_or("put back"),
                    delay.as_secs()
                );
                let now = Instant::now();
                self.pending.note(&inbox_name, Seen::RenamedIn, now);
                self.pending.defer(&inbox_name, now + delay);
            }
            Done::Stranded { name, error } => {
                tracing::error!(file = %name, "{name}: {error}; it stays in {}", self.layout.mine.display());
            }
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

    /// Puts the files waiting for another attempt back into the inbox (at shutdown).
    fn put_back_waiting(&mut self) {
        while let Some((job, _)) = self.again.pop_front() {
            match claim::put_back(&self.layout, &job.name) {
                Ok(n) => tracing::info!(file = %job.name, "put back into the inbox as {n}"),
                Err(e) => {
                    tracing::error!(file = %job.name, "cannot put back into the inbox: {e}; it stays in {}", self.layout.mine.display())
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
        if let Err(e) = worker::probe_limits(new.memory_limit_mb) {
            tracing::error!("SIGHUP: the config is refused, the old one kept: {e:#}");
            return;
        }
        let policy = match snapshot_policy(&new, &self.layout.tmp, self.generation + 1) {
            Ok(p) => p,
            Err(e) => {
                tracing::error!("SIGHUP: the policy is refused, the old one kept: {e:#}");
                return;
            }
        };
        self.generation += 1;
        self.ctx = Arc::new(RunCtx {
            settings: new.clone(),
            policy,
            policy_source: new.policy.clone(),
            layout: self.ctx.layout.clone(),
            host: self.ctx.host.clone(),
            pid: self.ctx.pid,
            exe: self.ctx.exe.clone(),
            hooks: self.ctx.hooks.clone(),
            cores: self.ctx.cores,
        });
        self.settings = new;
        tracing::info!(policy = ?self.settings.policy, "SIGHUP: config and policy reloaded");
    }

    fn shutdown(&mut self) {
        self.put_back_waiting();
        let _ = std::fs::remove_dir_all(&self.layout.tmp);
        // our folder: stranded files stay (a later daemon recovers them)
        if let Ok(rd) = std::fs::read_dir(&self.layout.mine) {
            for e in rd.flatten() {
                let n = e.file_name().to_string_lossy().into_owned();
                let file = n
                    .strip_prefix('.')
                    .and_then(|s| s.strip_suffix(".holefill.json"));
                if let Some(f) = file {
                    if !self.layout.mine.join(f).exists() {
                        let _ = std::fs::remove_file(e.path());
                    }
                }
            }
        }
        if std::fs::remove_dir(&self.layout.mine).is_err() {
            tracing::warn!("files remain in {}", self.layout.mine.display());
        }
        let _ = fsops::fsync_dir(&self.layout.inbox);
        tracing::info!(
            repaired = self.repaired,
            failed = self.failed,
            "stopped: {}",
            self.status()
        );
    }
}
