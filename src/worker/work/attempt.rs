//! One attempt: the set downloaded into a private folder and checked against its
//! digests and sizes, the child run under the limits, its outputs read.

use super::{Outcome, WorkerCtx};
use crate::daemon::child::{self, ChildEnd, Input};
use crate::worker::scan::ScanMsg;
use anyhow::{anyhow, Result};
use serde_json::Value;
use std::path::Path;
use std::sync::Arc;
use tokio::sync::watch;

/// Downloads the set, runs the child, reads its outputs.
pub(super) async fn attempt(
    ctx: &Arc<WorkerCtx>,
    scan: &ScanMsg,
    dir: &Path,
    mut cancel: watch::Receiver<bool>,
) -> Outcome {
    let input = dir.join("in");
    let out_dir = dir.join("out");
    if let Err(e) = make_dirs(&[&input, &out_dir]).await {
        return Outcome::Retry {
            stage: "io",
            error: format!("cannot make the work folder {}: {e}", dir.display()),
        };
    }
    // the size limit before anything is downloaded
    let max = ctx.limits.max_file_bytes;
    if let Some(f) = scan.files.iter().find(|f| max > 0 && f.size > max) {
        return Outcome::Failed {
            stage: "limits",
            error: format!("{}: {} bytes > max_file_bytes = {max}", f.name, f.size),
            exit: None,
            log: None,
        };
    }
    for f in &scan.files {
        let object = scan.object(&f.name);
        match download(&ctx.buckets.scans, &object, &input.join(&f.name), f.size).await {
            Ok(sha) if sha == f.sha256 => {}
            Ok(_) => {
                return Outcome::Failed {
                    stage: "input",
                    error: format!(
                        "{}: the object {object} does not match the SHA-256 the job names",
                        f.name
                    ),
                    exit: None,
                    log: None,
                }
            }
            Err(Download::Missing) => {
                return Outcome::Failed {
                    stage: "input",
                    error: format!(
                        "{}: the object {object} is not in the bucket {} (removed or expired)",
                        f.name, ctx.names.scans
                    ),
                    exit: None,
                    log: None,
                }
            }
            Err(Download::Size(got)) => {
                return Outcome::Failed {
                    stage: "input",
                    error: format!(
                        "{}: the object {object} holds {got} bytes, the job names {}",
                        f.name, f.size
                    ),
                    exit: None,
                    log: None,
                }
            }
            Err(Download::Other(e)) => {
                return Outcome::Retry {
                    stage: "io",
                    error: format!("cannot download {object}: {e:#}"),
                }
            }
        }
    }
    let ext = crate::worker::scan::mesh_ext(&scan.scan).unwrap_or_else(|| "obj".into());
    let mesh = input.join(&scan.scan);
    let model = out_dir.join(&scan.scan);
    let child_log = dir.join("child.json");
    // no picture here (the spec has none): the child ends before `run` returns
    let (end, stderr, _) = child::run(
        &ctx.spec(),
        &scan.scan,
        Input::Path(&mesh),
        &ext,
        &model,
        &child_log,
        &mut cancel,
    )
    .await;
    // the error names the file, not the worker's private folder
    let msg = child::stderr_message(&stderr).replace(&format!("{}/", input.display()), "");
    let read_log = || {
        std::fs::read(&child_log)
            .ok()
            .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
    };
    let or = |s: &str, d: &str| {
        if s.is_empty() {
            d.to_string()
        } else {
            s.to_string()
        }
    };
    match end {
        ChildEnd::Exit(code @ (0 | 2)) => match (model.is_file(), read_log()) {
            (true, Some(log)) => Outcome::Repaired {
                exit: code,
                model,
                log,
            },
            _ => Outcome::Failed {
                stage: "output",
                error: format!("the worker exited {code} but left no model or log"),
                exit: Some(code),
                log: None,
            },
        },
        ChildEnd::Exit(65) => Outcome::Failed {
            stage: "input",
            error: or(&msg, "unreadable or malformed input (exit 65)"),
            exit: Some(65),
            log: read_log(),
        },
        ChildEnd::Exit(70) => Outcome::Failed {
            stage: "repair",
            error: or(&msg, "internal error (exit 70)"),
            exit: Some(70),
            log: read_log(),
        },
        ChildEnd::Exit(78) => Outcome::Failed {
            stage: "policy",
            error: format!("invalid policy (exit 78): {}", or(&msg, "-")),
            exit: Some(78),
            log: None,
        },
        ChildEnd::Exit(74) => Outcome::Retry {
            stage: "io",
            error: format!("worker exit 74 (I/O error): {}", or(&msg, "-")),
        },
        ChildEnd::Cancelled => Outcome::Retry {
            stage: "worker",
            error: "the worker is stopping".into(),
        },
        end => {
            if let Some(m) = crate::metrics::global() {
                match end {
                    ChildEnd::Timeout(_) => m.timeouts.inc(),
                    _ => m.crashes.inc(),
                };
            }
            Outcome::Retry {
                stage: "worker",
                error: child::crash_reason(ctx.limits.memory_limit_mb, end, &msg),
            }
        }
    }
}

async fn make_dirs(dirs: &[&Path]) -> std::io::Result<()> {
    for d in dirs {
        tokio::fs::create_dir_all(d).await?;
    }
    Ok(())
}

enum Download {
    Missing,
    Size(u64),
    Other(anyhow::Error),
}

/// Downloads an object into `path` (created new), at most `size` bytes; its SHA-256.
async fn download(
    bucket: &crate::worker::queue::Bucket,
    object: &str,
    path: &Path,
    size: u64,
) -> Result<String, Download> {
    use crate::worker::queue::ReadError;
    let mut f = tokio::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
        .await
        .map_err(|e| Download::Other(anyhow!("{}: {e}", path.display())))?;
    match bucket.read(object, size, &mut f).await {
        Ok((n, _)) if n != size => Err(Download::Size(n)),
        Ok((_, sha)) => Ok(sha),
        Err(ReadError::Missing) => Err(Download::Missing),
        Err(ReadError::TooLarge(n)) => Err(Download::Size(n)),
        Err(ReadError::Other(e)) => Err(Download::Other(e)),
    }
}
