//! The buckets: the outcome already stored for a scan, the repaired or failed files
//! and their log stored (the log last), the done notification, the repair log.

use super::WorkerCtx;
use crate::worker::scan::{sha256_hex, DoneMsg, ScanMsg, VERSION};
use anyhow::{anyhow, bail, Context as _, Result};
use async_nats::jetstream;
use serde_json::{json, Value};
use std::path::Path;

/// The outcome already stored for this scan, as its notification.
pub(super) async fn stored_outcome(ctx: &WorkerCtx, scan: &ScanMsg) -> Result<Option<DoneMsg>> {
    let log = scan.object(&scan.log_name());
    for (bucket, status, name) in [
        (&ctx.buckets.results, "repaired", &ctx.names.results),
        (&ctx.buckets.failed, "failed", &ctx.names.failed),
    ] {
        match bucket.store.info(&log).await {
            Ok(i) if !i.deleted => {
                let mut files: Vec<String> = Vec::new();
                let (stage, error) = match status {
                    "repaired" => {
                        files.extend(scan.files.iter().map(|f| f.name.clone()));
                        (None, None)
                    }
                    _ => {
                        // which of the submitted files were kept with the log
                        for f in &scan.files {
                            if bucket
                                .store
                                .info(scan.object(&f.name))
                                .await
                                .is_ok_and(|i| !i.deleted)
                            {
                                files.push(f.name.clone());
                            }
                        }
                        let (stage, error) = read_stage(bucket, &log).await;
                        (stage, error)
                    }
                };
                files.push(scan.log_name());
                return Ok(Some(done_msg(scan, status, name, files, stage, error)));
            }
            Ok(_) => {}
            Err(e) if e.kind() == async_nats::jetstream::object_store::InfoErrorKind::NotFound => {}
            Err(e) => bail!("cannot look for the stored outcome: {e}"),
        }
    }
    Ok(None)
}

async fn read_stage(
    bucket: &crate::worker::queue::Bucket,
    log: &str,
) -> (Option<String>, Option<String>) {
    let Ok(bytes) = bucket.read_bytes(log, 64 << 20).await else {
        return (None, None);
    };
    let v: Value = serde_json::from_slice(&bytes).unwrap_or(Value::Null);
    (
        v["stage"].as_str().map(String::from),
        v["error"].as_str().map(String::from),
    )
}

fn done_msg(
    scan: &ScanMsg,
    status: &str,
    bucket: &str,
    files: Vec<String>,
    stage: Option<String>,
    error: Option<String>,
) -> DoneMsg {
    DoneMsg {
        version: VERSION,
        scan: scan.scan.clone(),
        digest: scan.digest.clone(),
        key: scan.key(),
        status: status.to_string(),
        bucket: bucket.to_string(),
        files,
        stage,
        error,
    }
}

/// Publishes the done notification (id `done:KEY`: once, however often it is sent).
pub(super) async fn notify(ctx: &WorkerCtx, done: &DoneMsg) -> Result<()> {
    let payload = serde_json::to_vec(done)?;
    let publish = jetstream::message::PublishMessage::build()
        .message_id(format!("done:{}", done.key))
        .payload(payload.into());
    ctx.conn
        .js
        .send_publish(ctx.names.done_subject.clone(), publish)
        .await
        .map_err(|e| anyhow!("cannot publish the done notification: {e}"))?
        .await
        .map_err(|e| anyhow!("the done notification was not stored: {e}"))?;
    Ok(())
}

/// Puts bytes or a file as an object.
async fn put_file(bucket: &crate::worker::queue::Bucket, name: &str, path: &Path) -> Result<()> {
    let mut f = tokio::fs::File::open(path)
        .await
        .with_context(|| format!("{}", path.display()))?;
    bucket
        .store
        .put(name, &mut f)
        .await
        .map_err(|e| anyhow!("cannot store {name}: {e}"))?;
    Ok(())
}

async fn put_bytes(bucket: &crate::worker::queue::Bucket, name: &str, bytes: &[u8]) -> Result<()> {
    let mut r = bytes;
    bucket
        .store
        .put(name, &mut r)
        .await
        .map_err(|e| anyhow!("cannot store {name}: {e}"))?;
    Ok(())
}

/// Model, the set's other files, then the log (its presence: complete); notifies.
pub(super) async fn store_repaired(
    ctx: &WorkerCtx,
    scan: &ScanMsg,
    dir: &Path,
    model: &Path,
    log: &Value,
) -> Result<()> {
    let b = &ctx.buckets.results;
    put_file(b, &scan.object(&scan.scan), model).await?;
    for f in &scan.files[1..] {
        put_file(b, &scan.object(&f.name), &dir.join("in").join(&f.name)).await?;
    }
    let text = serde_json::to_vec_pretty(log)?;
    put_bytes(b, &scan.object(&scan.log_name()), &text).await?;
    let mut files: Vec<String> = scan.files.iter().map(|f| f.name.clone()).collect();
    files.push(scan.log_name());
    notify(
        ctx,
        &done_msg(scan, "repaired", &ctx.names.results, files, None, None),
    )
    .await
}

/// The submitted files that were downloaded (from `input`), then the log; notifies.
pub(super) async fn store_failed(
    ctx: &WorkerCtx,
    scan: &ScanMsg,
    input: Option<&Path>,
    log: Value,
    stage: &str,
    error: &str,
) -> Result<()> {
    let b = &ctx.buckets.failed;
    let mut files = Vec::new();
    if let Some(input) = input {
        for f in &scan.files {
            let p = input.join(&f.name);
            // only a complete, verified copy
            let ok = tokio::fs::read(&p)
                .await
                .is_ok_and(|bytes| sha256_hex(&bytes) == f.sha256);
            if ok {
                put_file(b, &scan.object(&f.name), &p).await?;
                files.push(f.name.clone());
            }
        }
    }
    let text = serde_json::to_vec_pretty(&log)?;
    put_bytes(b, &scan.object(&scan.log_name()), &text).await?;
    files.push(scan.log_name());
    let done = done_msg(
        scan,
        "failed",
        &ctx.names.failed,
        files,
        Some(stage.to_string()),
        Some(error.to_string()),
    );
    notify(ctx, &done).await
}

/// The repair log: the child's (or a minimal one) with the outcome and the worker's
/// fields.
pub(super) fn final_log(
    base: Option<Value>,
    status: &str,
    stage: Option<&str>,
    error: Option<&str>,
    worker: Value,
) -> Value {
    let mut base = base
        .filter(Value::is_object)
        .unwrap_or_else(|| json!({ "holefill_version": env!("CARGO_PKG_VERSION") }));
    if let Some(o) = base.as_object_mut() {
        o.insert("status".into(), json!(status));
        o.insert("stage".into(), json!(stage));
        o.insert("error".into(), json!(error));
        o.insert("worker".into(), worker);
    }
    base
}
