//! The jobs: ready files claimed and started while fewer than `workers` repairs run,
//! and each attempt's end handled (journal, retries, back-off, index, metrics).

use super::claim::{self, Job, Phase};
use super::fsops::shown;
use super::index;
use super::queue::Seen;
use super::worker::{self, Done};
use super::{Daemon, Drawn, Parked, ERROR_EVERY};
use crate::metrics;
use std::collections::HashMap;
use std::ffi::OsStr;
use std::path::Path;
use std::time::{Duration, Instant};

impl Daemon {
    /// Claims ready files while fewer than `workers` repairs run (and fewer than twice
    /// as many pictures are being drawn: each holds its child's memory).
    pub(super) fn dispatch(&mut self) {
        if !self.room() {
            return;
        }
        if !self.check_folders(false) {
            return;
        }
        self.advance_sets();
        while self.room() {
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

    /// Room for another repair: fewer than `workers` running and fewer than twice as
    /// many pictures being drawn.
    fn room(&self) -> bool {
        self.working.len() < self.settings.workers && self.drawing.len() < 2 * self.settings.workers
    }

    pub(super) fn spawn(&mut self, job: Job) {
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

    pub(super) fn on_done(&mut self, done: Done) {
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
                picture,
            } => {
                self.repaired += 1;
                self.retries.remove(&job.name);
                let log = self.layout.outbox.join(format!("{output}.repair.json"));
                self.file_done(&log, None, secs, job.rec.stamp.map(|s| s.size));
                if let Some(p) = picture {
                    // its temporary folder stays until it is published
                    let id = job.id.clone();
                    self.drawing.insert(id.clone(), job.home.tag.clone());
                    let (cancel, tx) = (self.cancel.subscribe(), self.drawn_tx.clone());
                    tokio::spawn(async move {
                        let picture = p.publish(cancel).await;
                        let _ = tx.send(Drawn { id, log, picture });
                    });
                }
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

    /// A repair's picture published (or lost): the index shows it.
    pub(super) fn on_drawn(&mut self, d: Drawn) {
        self.drawing.remove(&d.id);
        if let (Some(ix), Some(p)) = (self.index.as_mut(), d.picture) {
            ix.picture(&d.log, p);
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
}
