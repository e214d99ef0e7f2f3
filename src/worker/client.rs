//! `holefill submit` (upload a scan's files, then enqueue it) and `holefill results`
//! (download finished scans from the done stream into folders).

use super::config::{Names, QueueSettings};
use super::queue::{self, Buckets, Conn};
use super::scan::{self, DoneMsg, FileEntry, ScanMsg};
use anyhow::{anyhow, bail, Context as _, Result};
use async_nats::jetstream::{self, consumer};
use futures_util::StreamExt;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The outcome of one submission.
#[derive(Debug)]
pub struct Submitted {
    pub key: String,
    /// The work queue already held it (same key within the duplicate window).
    pub duplicate: bool,
}

/// Reads a set of files (the mesh first) into a job.
pub fn read_set(paths: &[PathBuf], origin: Option<String>) -> Result<(ScanMsg, Vec<Vec<u8>>)> {
    let mut entries = Vec::new();
    let mut contents = Vec::new();
    for p in paths {
        let name = p
            .file_name()
            .and_then(|n| n.to_str())
            .ok_or_else(|| anyhow!("{}: not a file name holefill can send (UTF-8)", p.display()))?
            .to_string();
        scan::check_name(&name).map_err(|e| anyhow!("{}: {e}", p.display()))?;
        let bytes = std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?;
        entries.push(FileEntry {
            name,
            size: bytes.len() as u64,
            sha256: scan::sha256_hex(&bytes),
        });
        contents.push(bytes);
    }
    let now = crate::daemon::fsops::rfc3339(std::time::SystemTime::now());
    let msg =
        ScanMsg::new(entries, now, origin).map_err(|e| anyhow!("{}: {e}", paths[0].display()))?;
    Ok((msg, contents))
}

/// Uploads the files (skipping those already stored with the same content), then
/// publishes the job with its key as the message id.
pub async fn submit(
    conn: &Conn,
    names: &Names,
    buckets: &Buckets,
    msg: &ScanMsg,
    contents: &[Vec<u8>],
) -> Result<Submitted> {
    for (f, bytes) in msg.files.iter().zip(contents) {
        let object = msg.object(&f.name);
        let have = match buckets.scans.store.info(&object).await {
            Ok(i) => !i.deleted && i.size as u64 == f.size,
            Err(_) => false,
        };
        if !have {
            let mut r: &[u8] = bytes;
            buckets
                .scans
                .store
                .put(object.as_str(), &mut r)
                .await
                .map_err(|e| anyhow!("cannot upload {object}: {e}"))?;
        }
    }
    let publish = jetstream::message::PublishMessage::build()
        .message_id(msg.key())
        .payload(serde_json::to_vec(msg)?.into());
    let ack = conn
        .js
        .send_publish(names.subject.clone(), publish)
        .await
        .map_err(|e| anyhow!("cannot enqueue {}: {e}", msg.key()))?
        .await
        .map_err(|e| anyhow!("{} was not stored in the queue: {e}", msg.key()))?;
    Ok(Submitted {
        key: msg.key(),
        duplicate: ack.duplicate,
    })
}

/// Where `holefill results` writes.
pub struct ResultDirs {
    pub out: PathBuf,
    pub failed: PathBuf,
}

/// Downloads done scans: each notification's files into the outbox (repaired) or the
/// failed folder, the log last, then acknowledges it. With `watch`, runs until
/// SIGTERM/SIGINT; without, returns once nothing is pending. Returns the count.
pub async fn results(
    conn: &Conn,
    names: &Names,
    settings: &QueueSettings,
    dirs: &ResultDirs,
    watch: bool,
) -> Result<u64> {
    queue::setup(conn, names, settings).await?;
    let stream = queue::done_stream(conn, names, settings).await?;
    let consumer: consumer::PullConsumer = stream
        .get_or_create_consumer(
            &names.results_consumer,
            consumer::pull::Config {
                durable_name: Some(names.results_consumer.clone()),
                description: Some("holefill results".into()),
                ack_policy: consumer::AckPolicy::Explicit,
                ack_wait: Duration::from_secs(120),
                filter_subject: names.done_subject.clone(),
                num_replicas: settings.replicas,
                ..Default::default()
            },
        )
        .await
        .map_err(|e| anyhow!("consumer {}: {e}", names.results_consumer))?;
    std::fs::create_dir_all(&dirs.out).with_context(|| format!("{}", dirs.out.display()))?;
    std::fs::create_dir_all(&dirs.failed).with_context(|| format!("{}", dirs.failed.display()))?;
    let mut count = 0u64;
    let mut stop = Box::pin(async {
        let mut term =
            tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()).ok();
        tokio::select! {
            _ = async { match term.as_mut() { Some(t) => { t.recv().await; } None => std::future::pending::<()>().await } } => {}
            _ = tokio::signal::ctrl_c() => {}
        }
    });
    loop {
        let batch = consumer
            .batch()
            .max_messages(32)
            .expires(Duration::from_secs(if watch { 5 } else { 1 }))
            .messages()
            .await;
        let mut batch = match batch {
            Ok(b) => b,
            Err(e) => {
                if !watch {
                    bail!("cannot pull done notifications: {e}");
                }
                tracing::warn!("cannot pull done notifications: {e} (retrying)");
                tokio::time::sleep(Duration::from_secs(1)).await;
                continue;
            }
        };
        let mut got = 0;
        loop {
            let m = tokio::select! {
                m = batch.next() => m,
                _ = &mut stop => return Ok(count),
            };
            let Some(m) = m else { break };
            let msg = match m {
                Ok(m) => m,
                Err(e) => {
                    tracing::debug!("pull: {e}");
                    break;
                }
            };
            got += 1;
            let done: DoneMsg = match serde_json::from_slice(&msg.payload) {
                Ok(d) => d,
                Err(e) => {
                    tracing::error!("dropping a notification that is not one: {e}");
                    let _ = msg.ack_with(jetstream::AckKind::Term).await;
                    continue;
                }
            };
            let dir = if done.status == "repaired" {
                &dirs.out
            } else {
                &dirs.failed
            };
            // only our two buckets, whatever the notification names
            let bucket_name = if done.status == "repaired" {
                &names.results
            } else {
                &names.failed
            };
            let bucket = match queue::existing_bucket(conn, bucket_name).await {
                Ok(b) => b,
                Err(e) => {
                    tracing::error!("object store {bucket_name}: {e}");
                    let _ = msg
                        .ack_with(jetstream::AckKind::Nak(Some(Duration::from_secs(5))))
                        .await;
                    continue;
                }
            };
            match fetch_result(&bucket, &done, dir).await {
                Ok(written) => {
                    count += 1;
                    println!("{} {}", done.status, written.display());
                    let _ = msg.double_ack().await;
                }
                Err(e) => {
                    tracing::error!("{}: {e:#}", done.key);
                    let _ = msg
                        .ack_with(jetstream::AckKind::Nak(Some(Duration::from_secs(5))))
                        .await;
                }
            }
        }
        if got == 0 && !watch {
            return Ok(count);
        }
    }
}

/// Writes a done scan's files into `dir` (each atomically, the log last) and returns
/// the log's path. The same content is not written twice. When a name is already
/// taken by other content ([`result_names`]): a single file and its log get
/// `.DIGEST12` before the extension; a set (an OBJ with its MTL and images) goes whole
/// into the folder `dir/STEM.DIGEST12/` under its own names, so the OBJ's `mtllib` and
/// the MTL's image names still find their files.
pub async fn fetch_result(bucket: &queue::Bucket, done: &DoneMsg, dir: &Path) -> Result<PathBuf> {
    for f in &done.files {
        scan::check_name(f)?;
    }
    let mut contents = Vec::new();
    for f in &done.files {
        let object = format!("{}/{}", done.key, f);
        contents.push(bucket.read_bytes(&object, 16 << 30).await?);
    }
    let taken_by_other =
        done.files
            .iter()
            .zip(&contents)
            .any(|(f, bytes)| match std::fs::read(dir.join(f)) {
                Ok(have) => &have != bytes,
                Err(_) => false,
            });
    let (dir, names) = result_names(dir, &done.scan, &done.digest, &done.files, taken_by_other);
    std::fs::create_dir_all(&dir).with_context(|| format!("{}", dir.display()))?;
    let mut log_path = PathBuf::new();
    for (name, bytes) in names.iter().zip(&contents) {
        let path = dir.join(name);
        holefill::io::write_atomic(&path, bytes).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        log_path = path;
    }
    Ok(log_path)
}

/// Where a done scan's `files` go in `dir` (the folder and each file's name there, in
/// the order of `files`): their own names unless `taken_by_other`; then a set (more
/// than the mesh and its log) keeps its names in `dir/STEM.DIGEST12/`, and a single
/// file gets `.DIGEST12` before its extension (its log too).
pub fn result_names(
    dir: &Path,
    scan: &str,
    digest: &str,
    files: &[String],
    taken_by_other: bool,
) -> (PathBuf, Vec<String>) {
    let short = &digest[..digest.len().min(12)];
    if !taken_by_other {
        return (dir.to_path_buf(), files.to_vec());
    }
    if files.len() > 2 {
        let stem = match scan.rsplit_once('.') {
            Some((s, _)) if !s.is_empty() => s,
            _ => scan,
        };
        return (dir.join(format!("{stem}.{short}")), files.to_vec());
    }
    (
        dir.to_path_buf(),
        files.iter().map(|f| stamped(f, short)).collect(),
    )
}

/// `scan01.obj` -> `scan01.TAG.obj`; `scan01.obj.repair.json` -> `scan01.TAG.obj.repair.json`.
fn stamped(name: &str, tag: &str) -> String {
    let (base, log) = match name.strip_suffix(".repair.json") {
        Some(b) => (b, ".repair.json"),
        None => (name, ""),
    };
    match base.rsplit_once('.') {
        Some((stem, ext)) if !stem.is_empty() => format!("{stem}.{tag}.{ext}{log}"),
        _ => format!("{base}.{tag}{log}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stamps_go_before_the_extension() {
        assert_eq!(stamped("a.obj", "abc"), "a.abc.obj");
        assert_eq!(stamped("a.obj.repair.json", "abc"), "a.abc.obj.repair.json");
        assert_eq!(stamped("tex.png", "abc"), "tex.abc.png");
        assert_eq!(stamped("noext", "abc"), "noext.abc");
    }

    #[test]
    fn a_taken_set_keeps_its_names_in_a_folder_of_its_own() {
        let d = Path::new("/out");
        let set: Vec<String> = ["s.obj", "s.mtl", "t.jpg", "s.obj.repair.json"]
            .map(String::from)
            .to_vec();
        assert_eq!(
            result_names(d, "s.obj", "0123456789abcdef", &set, false),
            (d.to_path_buf(), set.clone())
        );
        let (dir, names) = result_names(d, "s.obj", "0123456789abcdef", &set, true);
        assert_eq!(dir, d.join("s.0123456789ab"));
        assert_eq!(
            names, set,
            "names unchanged: the OBJ's mtllib still finds s.mtl"
        );
        let single: Vec<String> = ["s.obj", "s.obj.repair.json"].map(String::from).to_vec();
        assert_eq!(
            result_names(d, "s.obj", "0123456789abcdef", &single, true),
            (
                d.to_path_buf(),
                vec![
                    "s.0123456789ab.obj".to_string(),
                    "s.0123456789ab.obj.repair.json".into()
                ]
            )
        );
    }
}
