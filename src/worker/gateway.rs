//! The inbox daemon as a gateway (`holefill watch --forward nats://...`): each file
//! the daemon claims is submitted to the work queue instead of being repaired by a
//! local child, and the result that comes back is handed to the daemon's publishing
//! as the child's output would be: the model into the outbox, the original into the
//! archive, or the file into the failed folder with the worker's log. Everything the
//! daemon promises about its folders (claim, crash-safe publish, put back on stop)
//! holds unchanged; only the repair happens elsewhere.
//!
//! The job's key is the file's name and content ([`super::scan`]), so a gateway that
//! restarts and claims the same file again submits the same job: the queue drops the
//! duplicate (message id), and a result already stored is taken as it is, never
//! repaired again. The gateway waits for the result (woken by the done notifications,
//! polling the buckets every few seconds as a backstop) as long as it takes: the
//! workers enforce the time limits; a daemon stopping puts the file back.

use super::config::{Names, QueueSettings};
use super::queue::{self, Buckets, Conn};
use super::scan::{DoneMsg, ScanMsg};
use crate::daemon::child::ChildEnd;
use anyhow::{anyhow, Result};
use futures_util::StreamExt;
use serde_json::Value;
use std::collections::HashMap;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{watch, Notify};

/// The gateway's connection and the waiters for results.
pub struct Forwarder {
    pub url: String,
    conn: Conn,
    names: Names,
    buckets: Buckets,
    waiters: Arc<Mutex<HashMap<String, Arc<Notify>>>>,
    origin: String,
}

impl std::fmt::Debug for Forwarder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Forwarder({})", self.url)
    }
}

impl Forwarder {
    /// Connects, makes the streams and buckets (retrying while the server is not
    /// there, up to `wait`), and listens to the done notifications.
    pub async fn start(
        url: &str,
        names: Names,
        settings: QueueSettings,
        host: &str,
        wait: Duration,
    ) -> Result<Arc<Forwarder>> {
        let conn = queue::connect(url, "holefill-gateway").await?;
        let buckets = queue::retry("the queue's streams and buckets", wait, || {
            queue::setup(&conn, &names, &settings)
        })
        .await?;
        let f = Arc::new(Forwarder {
            url: url.to_string(),
            conn,
            names,
            buckets,
            waiters: Arc::default(),
            origin: format!("gateway {host}"),
        });
        let sub = f
            .conn
            .client
            .subscribe(f.names.done_subject.clone())
            .await
            .map_err(|e| anyhow!("cannot subscribe to {}: {e}", f.names.done_subject))?;
        let waiters = f.waiters.clone();
        tokio::spawn(async move {
            let mut sub = sub;
            while let Some(m) = sub.next().await {
                if let Ok(d) = serde_json::from_slice::<DoneMsg>(&m.payload) {
                    if let Some(n) = waiters.lock().ok().and_then(|w| w.get(&d.key).cloned()) {
                        n.notify_one();
                    }
                }
            }
        });
        Ok(f)
    }

    /// Submits the file, with the other files of its set (`members`: name and path in
    /// the daemon's processing folder, read without following a link), as one scan and
    /// waits for its outcome, which it writes as the child would: the model into `out`
    /// and the worker's log into `log`. The members come back unchanged from the worker
    /// (the daemon publishes its own copies). Returns how the remote repair ended and a
    /// message for the daemon's log.
    pub async fn repair(
        &self,
        name: &str,
        input: &std::fs::File,
        members: &[(String, std::path::PathBuf)],
        out: &Path,
        log: &Path,
        cancel: &mut watch::Receiver<bool>,
    ) -> (ChildEnd, Vec<u8>) {
        let mut contents = Vec::with_capacity(1 + members.len());
        match read_all(input) {
            Ok(b) => contents.push(b),
            Err(e) => return (ChildEnd::SpawnError(e), Vec::new()),
        }
        for (_, path) in members {
            match crate::daemon::fsops::open_nofollow(path).and_then(|f| read_all(&f)) {
                Ok(b) => contents.push(b),
                Err(e) => return (ChildEnd::SpawnError(e), Vec::new()),
            }
        }
        let names = std::iter::once(name).chain(members.iter().map(|(n, _)| n.as_str()));
        let entries = names
            .zip(&contents)
            .map(|(n, bytes)| super::scan::FileEntry {
                name: n.to_string(),
                size: bytes.len() as u64,
                sha256: super::scan::sha256_hex(bytes),
            })
            .collect();
        let now = crate::daemon::fsops::rfc3339(std::time::SystemTime::now());
        let msg = match ScanMsg::new(entries, now, Some(self.origin.clone())) {
            Ok(m) => m,
            Err(e) => {
                return (
                    ChildEnd::Remote {
                        stage: "name".into(),
                        error: e.to_string(),
                    },
                    Vec::new(),
                )
            }
        };
        let key = msg.key();
        let notify = Arc::new(Notify::new());
        if let Ok(mut w) = self.waiters.lock() {
            w.insert(key.clone(), notify.clone());
        }
        let r = self
            .submit_and_wait(&msg, &contents, &notify, out, log, cancel)
            .await;
        if let Ok(mut w) = self.waiters.lock() {
            w.remove(&key);
        }
        r
    }

    async fn submit_and_wait(
        &self,
        msg: &ScanMsg,
        contents: &[Vec<u8>],
        notify: &Notify,
        out: &Path,
        log: &Path,
        cancel: &mut watch::Receiver<bool>,
    ) -> (ChildEnd, Vec<u8>) {
        let mut submitted = false;
        let mut delay = Duration::from_millis(200);
        loop {
            if *cancel.borrow() {
                return (ChildEnd::Cancelled, Vec::new());
            }
            match self.outcome(msg, out, log).await {
                Ok(Some(end)) => return end,
                Ok(None) if !submitted => {
                    match super::client::submit(
                        &self.conn,
                        &self.names,
                        &self.buckets,
                        msg,
                        contents,
                    )
                    .await
                    {
                        Ok(s) => {
                            submitted = true;
                            tracing::info!(
                                "forwarded {}{}",
                                s.key,
                                if s.duplicate { " (already queued)" } else { "" }
                            );
                        }
                        Err(e) => tracing::warn!("{}: {e:#} (retrying)", msg.key()),
                    }
                }
                Ok(None) => {}
                Err(e) => tracing::warn!("{}: {e:#} (retrying)", msg.key()),
            }
            tokio::select! {
                _ = notify.notified() => { delay = Duration::from_millis(200); }
                _ = tokio::time::sleep(delay) => { delay = (delay * 2).min(Duration::from_secs(5)); }
                r = cancel.changed() => {
                    if r.is_err() {
                        // no one can cancel any more: wait as the timer says
                        tokio::time::sleep(delay).await;
                    }
                }
            }
        }
    }

    /// The stored outcome of `msg`, written into `out` and `log`, if there is one.
    async fn outcome(
        &self,
        msg: &ScanMsg,
        out: &Path,
        log: &Path,
    ) -> Result<Option<(ChildEnd, Vec<u8>)>> {
        use async_nats::jetstream::object_store::InfoErrorKind;
        let log_object = msg.object(&msg.log_name());
        for (bucket, repaired) in [(&self.buckets.results, true), (&self.buckets.failed, false)] {
            match bucket.store.info(&log_object).await {
                Ok(i) if !i.deleted => {
                    let text = bucket.read_bytes(&log_object, 256 << 20).await?;
                    let v: Value = serde_json::from_slice(&text)
                        .map_err(|e| anyhow!("{log_object}: not a repair log: {e}"))?;
                    let error = v["error"].as_str().unwrap_or("").to_string();
                    let end = if repaired {
                        let model = bucket
                            .read_bytes(&msg.object(&msg.scan), u64::MAX >> 1)
                            .await?;
                        write(out, &model)?;
                        let code = v["worker"]["worker_exit"].as_i64().unwrap_or(0) as i32;
                        ChildEnd::Exit(code)
                    } else {
                        let stage = v["stage"].as_str().unwrap_or("worker").to_string();
                        ChildEnd::Remote {
                            stage,
                            error: error.clone(),
                        }
                    };
                    write(log, &text)?;
                    return Ok(Some((end, error.into_bytes())));
                }
                Ok(_) => {}
                Err(e) if e.kind() == InfoErrorKind::NotFound => {}
                Err(e) => return Err(anyhow!("cannot look for the result: {e}")),
            }
        }
        Ok(None)
    }
}

fn read_all(f: &std::fs::File) -> std::io::Result<Vec<u8>> {
    use std::io::{Read, Seek};
    let mut f = f.try_clone()?;
    f.seek(std::io::SeekFrom::Start(0))?;
    let mut v = Vec::new();
    f.read_to_end(&mut v)?;
    Ok(v)
}

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| anyhow!("{}: {e}", path.display()))
}
