//! `holefill worker`: takes scans from the work queue, repairs each in the isolated
//! child of the inbox daemon ([`crate::daemon::child`]), stores the outcome, and only
//! then acknowledges.
//!
//! One delivery, in order:
//! 1. the message is read and checked ([`ScanMsg::validate`]); one that is not a job
//!    is terminated (logged, never redelivered);
//! 2. if the results or failed bucket already holds the key's log, the scan is done
//!    (a redelivery after a crash between the upload and the ack): its notification is
//!    published again (de-duplicated by its id) and the job acknowledged, unrepaired;
//! 3. on a delivery past `max_deliver` (every attempt ended with the worker gone:
//!    killed, crashed, lost its connection) the scan fails at once, stage `worker`;
//! 4. its files are downloaded into a private folder and checked against their
//!    SHA-256 and sizes; the mesh is repaired by `holefill fill` under the limits;
//! 5. repaired (exit 0 or 2): the model, the set's other files and the log (last) go
//!    into the results bucket; a permanent failure (exit 65 malformed, 70 internal
//!    error, 78 policy; a file missing or not matching its digest): the submitted files
//!    and the log into the failed bucket; then the done notification is published and
//!    the job acknowledged;
//! 6. a retryable outcome (the child crashed, was killed, hit its time limit, an I/O
//!    error, exit 74; the server unreachable) is negatively acknowledged with a
//!    back-off (`backoff_secs`, doubled per delivery up to `backoff_max_secs`); on the
//!    `max_deliver`-th delivery it fails instead (stage `worker`, or `io`).
//!
//! While a delivery is handled the worker sends an in-progress acknowledgement every
//! third of `ack_wait`, so a long repair is not redelivered; a worker that dies stops
//! sending them and its scan is redelivered once `ack_wait` has passed.

use super::config::{Names, QueueSettings};
use super::queue::{self, Buckets, Conn};
use super::scan::ScanMsg;
use crate::daemon::child;
use crate::daemon::fsops;
use crate::daemon::hooks::Hooks;
use anyhow::{Context as _, Result};
use async_nats::jetstream::{self, AckKind};
use futures_util::StreamExt;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};
use tokio::sync::watch;

mod attempt;
mod store;

use attempt::attempt;
use store::{final_log, notify, store_failed, store_repaired, stored_outcome};

/// What a worker process runs with.
pub struct WorkerCtx {
    pub conn: Conn,
    pub names: Names,
    pub queue: QueueSettings,
    pub buckets: Buckets,
    pub exe: PathBuf,
    /// The validated policy file (`None`: built-in default).
    pub policy: Option<PathBuf>,
    pub limits: Limits,
    pub hooks: Hooks,
    pub cores: usize,
    /// The worker's private folder (removed at exit).
    pub work_dir: PathBuf,
    pub host: String,
    pub pid: u32,
    pub instance: String,
    pub seq: AtomicU64,
}

/// The limits of one repair (the daemon's keys of the same names).
#[derive(Clone, Debug)]
pub struct Limits {
    pub max_file_bytes: u64,
    pub max_faces: u64,
    pub max_vertices: u64,
    pub time_limit: Option<Duration>,
    pub memory_limit_mb: u64,
}

impl WorkerCtx {
    fn spec(&self) -> child::Spec<'_> {
        child::Spec {
            exe: &self.exe,
            policy: self.policy.as_deref(),
            max_file_bytes: self.limits.max_file_bytes,
            max_faces: self.limits.max_faces,
            max_vertices: self.limits.max_vertices,
            time_limit: self.limits.time_limit,
            memory_limit_mb: self.limits.memory_limit_mb,
            cores: self.cores,
            hooks: &self.hooks,
            picture: None,
            resources: &[],
        }
    }
}

/// Runs [`slot`] number `n` again whenever it panics (a library's unwrap on a server
/// error, say): the message it held is not acknowledged, so the server hands it out
/// again after the ack wait, and the worker keeps its slots.
async fn supervised_slot(
    n: usize,
    ctx: Arc<WorkerCtx>,
    consumer: jetstream::consumer::PullConsumer,
    stop: watch::Receiver<bool>,
    cancel: watch::Receiver<bool>,
) {
    loop {
        let run = tokio::spawn(slot(
            ctx.clone(),
            consumer.clone(),
            stop.clone(),
            cancel.clone(),
        ));
        match run.await {
            Ok(()) => return,
            Err(e) if e.is_panic() && !*stop.borrow() => {
                tracing::error!("slot {n} panicked; it starts again ({e})");
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
            Err(_) => return,
        }
    }
}

/// One slot: pulls one message at a time and handles it, until `stop` turns true.
pub async fn slot(
    ctx: Arc<WorkerCtx>,
    consumer: jetstream::consumer::PullConsumer,
    mut stop: watch::Receiver<bool>,
    cancel: watch::Receiver<bool>,
) {
    let mut logged: Option<Instant> = None;
    while !*stop.borrow() {
        let batch = consumer
            .batch()
            .max_messages(1)
            .expires(Duration::from_secs(2))
            .messages()
            .await;
        let mut batch = match batch {
            Ok(b) => b,
            Err(e) => {
                if logged.is_none_or(|l| l.elapsed() >= Duration::from_secs(10)) {
                    tracing::warn!("cannot pull from the queue: {e} (retrying)");
                    logged = Some(Instant::now());
                }
                let _ = tokio::time::timeout(Duration::from_millis(500), stop.changed()).await;
                continue;
            }
        };
        while let Some(m) = batch.next().await {
            match m {
                Ok(msg) => handle(&ctx, Arc::new(msg), cancel.clone()).await,
                Err(e) => {
                    tracing::debug!("pull: {e}");
                    tokio::time::sleep(Duration::from_millis(200)).await;
                    break;
                }
            }
        }
    }
}

/// How an attempt ended.
enum Outcome {
    /// Repaired: the model and its child log in `dir`.
    Repaired {
        exit: i32,
        model: PathBuf,
        log: Value,
    },
    /// A permanent failure.
    Failed {
        stage: &'static str,
        error: String,
        exit: Option<i32>,
        log: Option<Value>,
    },
    /// Retryable (a crash, a kill, a time-out, an I/O error).
    Retry { stage: &'static str, error: String },
}

impl Outcome {
    /// The metrics' retry reason of a retryable outcome.
    fn retry_reason(stage: &str) -> &'static str {
        if stage == "worker" {
            "crashed"
        } else {
            "retryable"
        }
    }
}

/// Handles one delivery (see the module documentation).
async fn handle(ctx: &Arc<WorkerCtx>, msg: Arc<jetstream::Message>, cancel: watch::Receiver<bool>) {
    let delivered = msg
        .info()
        .map(|i| u32::try_from(i.delivered).unwrap_or(u32::MAX))
        .unwrap_or(1);
    let scan = match ScanMsg::parse(&msg.payload) {
        Ok(s) => s,
        Err(e) => {
            tracing::error!("dropping a message of {}: {e}", msg.subject);
            let _ = msg.ack_with(AckKind::Term).await;
            return;
        }
    };
    let key = scan.key();
    let t0 = Instant::now();
    let started = SystemTime::now();
    // in-progress acknowledgements for as long as this delivery is handled
    let ticker = {
        let m = msg.clone();
        let every = (ctx.queue.ack_wait / 3).max(Duration::from_millis(500));
        tokio::spawn(async move {
            loop {
                tokio::time::sleep(every).await;
                let _ = m.ack_with(AckKind::Progress).await;
            }
        })
    };
    let m = crate::metrics::global();
    if let Some(m) = m {
        m.in_flight.inc();
    }
    let r = handle_scan(ctx, &scan, delivered, started, t0, cancel).await;
    ticker.abort();
    if let Some(m) = m {
        m.in_flight.dec();
    }
    match r {
        Ok(Settled::Done(status)) => match msg.double_ack().await {
            Ok(()) => tracing::info!(
                "done: {status} {key} (delivery {delivered}, {:.2} s)",
                t0.elapsed().as_secs_f64()
            ),
            // the next delivery finds the outcome stored and only acknowledges
            Err(e) => tracing::warn!("{key}: {status}, but the ack failed: {e}"),
        },
        Ok(Settled::Again(why, delay)) => {
            if let Some(m) = m {
                m.retry(why.reason);
            }
            let why = why.error;
            tracing::warn!(
                "{key}: {why}; delivery {delivered} of {}, retried in {} s",
                ctx.queue.max_deliver,
                delay.as_secs()
            );
            let _ = msg.ack_with(AckKind::Nak(Some(delay))).await;
        }
        Err(e) => {
            // the server unreachable, or an upload failed: the outcome is not stored
            if let Some(m) = m {
                m.retry("retryable");
            }
            let delay = ctx.queue.backoff_after(delivered);
            tracing::warn!("{key}: {e:#}; retried in {} s", delay.as_secs());
            let _ = msg.ack_with(AckKind::Nak(Some(delay))).await;
        }
    }
}

enum Settled {
    /// Stored (and notified): acknowledge. "repaired", "failed", "already done".
    Done(&'static str),
    /// Negatively acknowledge with this delay.
    Again(Retry, Duration),
}

/// Why a delivery is tried again: the error, and the metrics' reason (`crashed`: the
/// repair process crashed, was killed or timed out; `retryable`: anything else).
struct Retry {
    error: String,
    reason: &'static str,
}

async fn handle_scan(
    ctx: &Arc<WorkerCtx>,
    scan: &ScanMsg,
    delivered: u32,
    started: SystemTime,
    t0: Instant,
    cancel: watch::Receiver<bool>,
) -> Result<Settled> {
    if let Some(done) = stored_outcome(ctx, scan).await? {
        notify(ctx, &done).await?;
        return Ok(Settled::Done("already done"));
    }
    let info = |status: &str, exit: Option<i32>| {
        json!({
            "host": ctx.host,
            "pid": ctx.pid,
            "instance": ctx.instance,
            "scan": scan.scan,
            "key": scan.key(),
            "digest": scan.digest,
            "files": scan.files.iter().map(|f| &f.name).collect::<Vec<_>>(),
            "submitted": scan.submitted,
            "origin": scan.origin,
            "started": fsops::rfc3339(started),
            "finished": fsops::rfc3339(SystemTime::now()),
            "seconds": t0.elapsed().as_secs_f64(),
            "delivery": delivered,
            "max_deliver": ctx.queue.max_deliver,
            "status": status,
            "worker_exit": exit,
        })
    };
    if delivered > ctx.queue.max_deliver {
        let error = format!(
            "no outcome after {} deliveries: the worker died (killed, crashed or cut off) on each",
            ctx.queue.max_deliver
        );
        let log = final_log(
            None,
            "failed",
            Some("worker"),
            Some(&error),
            info("failed", None),
        );
        store_failed(ctx, scan, None, log, "worker", &error).await?;
        if let Some(m) = crate::metrics::global() {
            m.failed("worker", t0.elapsed().as_secs_f64(), None);
        }
        return Ok(Settled::Done("failed"));
    }
    tracing::info!("taken {} (delivery {delivered})", scan.key());
    let dir = ctx
        .work_dir
        .join(ctx.seq.fetch_add(1, Ordering::Relaxed).to_string());
    let r = attempt(ctx, scan, &dir, cancel).await;
    let m = crate::metrics::global();
    let bytes = scan
        .files
        .iter()
        .find(|f| f.name == scan.scan)
        .map(|f| f.size);
    let failed = |stage: &str| {
        if let Some(m) = m {
            m.failed(stage, t0.elapsed().as_secs_f64(), bytes);
        }
    };
    let settled = match r {
        Outcome::Repaired { exit, model, log } => {
            let log = final_log(
                Some(log),
                "repaired",
                None,
                None,
                info("repaired", Some(exit)),
            );
            store_repaired(ctx, scan, &dir, &model, &log).await?;
            if let Some(m) = m {
                m.repaired(Some(&log), t0.elapsed().as_secs_f64(), bytes);
            }
            Settled::Done("repaired")
        }
        Outcome::Failed {
            stage,
            error,
            exit,
            log,
        } => {
            let log = final_log(
                log,
                "failed",
                Some(stage),
                Some(&error),
                info("failed", exit),
            );
            store_failed(ctx, scan, Some(&dir.join("in")), log, stage, &error).await?;
            failed(stage);
            Settled::Done("failed")
        }
        Outcome::Retry { stage, error } => {
            if delivered >= ctx.queue.max_deliver {
                let error = format!(
                    "{error} (delivery {delivered} of {}; giving up)",
                    ctx.queue.max_deliver
                );
                let log = final_log(
                    None,
                    "failed",
                    Some(stage),
                    Some(&error),
                    info("failed", None),
                );
                store_failed(ctx, scan, Some(&dir.join("in")), log, stage, &error).await?;
                failed(stage);
                Settled::Done("failed")
            } else {
                let reason = Outcome::retry_reason(stage);
                Settled::Again(Retry { error, reason }, ctx.queue.backoff_after(delivered))
            }
        }
    };
    let _ = tokio::fs::remove_dir_all(&dir).await;
    Ok(settled)
}

/// Runs the worker until SIGTERM or SIGINT: `workers` slots pull and repair; on a
/// signal they stop pulling, running repairs get `grace` to finish, then their
/// children are killed and their scans negatively acknowledged (redelivered at once).
pub async fn run(ctx: Arc<WorkerCtx>, slots: usize, grace: Duration) -> Result<()> {
    let consumer = queue::retry("the workers' consumer", Duration::from_secs(3600), || {
        queue::workers_consumer(&ctx.conn, &ctx.names, &ctx.queue)
    })
    .await?;
    let (stop_tx, stop_rx) = watch::channel(false);
    let (cancel_tx, cancel_rx) = watch::channel(false);
    // the metrics' waiting files: the scans of the queue not yet handed to a worker
    let poll = crate::metrics::global().map(|m| {
        let c = consumer.clone();
        tokio::spawn(async move {
            loop {
                if let Ok(i) = c.get_info().await {
                    m.waiting
                        .set(i64::try_from(i.num_pending).unwrap_or(i64::MAX));
                }
                tokio::time::sleep(Duration::from_secs(2)).await;
            }
        })
    });
    let mut tasks = Vec::new();
    for n in 0..slots {
        tasks.push(tokio::spawn(supervised_slot(
            n,
            ctx.clone(),
            consumer.clone(),
            stop_rx.clone(),
            cancel_rx.clone(),
        )));
    }
    tracing::info!(
        "worker ready: {slots} slot(s) on {} / {} (consumer {}), results in {}, failed in {}",
        ctx.names.stream,
        ctx.names.subject,
        ctx.names.consumer,
        ctx.names.results,
        ctx.names.failed
    );
    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .context("SIGTERM handler")?;
    tokio::select! {
        _ = term.recv() => {}
        _ = tokio::signal::ctrl_c() => {}
    }
    tracing::info!(
        "stopping: no new scans; running repairs get {} s",
        grace.as_secs()
    );
    let _ = stop_tx.send(true);
    let all = futures_util::future::join_all(tasks);
    tokio::pin!(all);
    if tokio::time::timeout(grace, &mut all).await.is_err() {
        let _ = cancel_tx.send(true);
        let _ = all.await;
    }
    if let Some(p) = poll {
        p.abort();
    }
    Ok(())
}
