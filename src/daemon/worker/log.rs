//! The job's log: the daemon's fields added to the worker's repair log, the set's
//! members, and the final log of a repaired job written into its temporary folder.

use super::{place_dir, read_json, RunCtx, Times};
use crate::daemon::claim::{Job, Phase};
use crate::daemon::fsops::{self, FileId};
use crate::daemon::sets;
use serde_json::{json, Value};
use std::io;
use std::path::Path;
use std::time::SystemTime;

/// The `"daemon"` object of a log.
pub(super) fn daemon_info(ctx: &RunCtx, job: &Job, t: Times, status: &str, extra: Value) -> Value {
    let mut v = json!({
        "host": ctx.host,
        "pid": ctx.pid,
        "instance": ctx.instance,
        "input": job.shown(),
        "received": job.rec.received,
        "started": fsops::rfc3339(t.started),
        "finished": fsops::rfc3339(SystemTime::now()),
        "seconds": t.t0.elapsed().as_secs_f64(),
        "attempt": job.attempt,
        "max_attempts": ctx.settings.max_attempts,
        "status": status,
        "policy": ctx.policy_source.as_ref().map(|p| p.display().to_string()),
    });
    if job.name.to_str().is_none() {
        v["input_bytes_hex"] = json!(job.rec.raw);
    }
    if let (Some(o), Value::Object(e)) = (v.as_object_mut(), extra) {
        o.extend(e);
    }
    v
}

/// Builds the final log: the worker's repair log (or a minimal one) plus the daemon's
/// fields.
pub(super) fn final_log(
    mut base: Value,
    status: &str,
    stage: Option<&str>,
    error: Option<&str>,
    daemon: Value,
) -> Value {
    if !base.is_object() {
        base = json!({ "holefill_version": env!("CARGO_PKG_VERSION") });
    }
    if let Some(o) = base.as_object_mut() {
        o.insert("status".into(), json!(status));
        o.insert("stage".into(), json!(stage));
        o.insert("error".into(), json!(error));
        o.insert("daemon".into(), daemon);
    }
    base
}

/// Writes `bytes` as `path` (temporary name, fsync, rename) and returns its identity.
pub(super) fn write_file(path: &Path, bytes: &[u8]) -> io::Result<FileId> {
    let f = fsops::write_durably(path, bytes, 0o644)?;
    Ok(FileId::of(&f.metadata()?))
}

/// The log's `daemon.set` object: the members, where each went, and the references
/// not followed. `None` for a single file.
pub(super) fn set_info(
    job: &Job,
    out_dir: Option<&Path>,
    placed_in: Option<(&Path, &str)>,
) -> Option<Value> {
    let set = job.rec.set.as_ref()?;
    let members: Vec<Value> = set
        .members
        .iter()
        .map(|m| {
            let output = out_dir.map(|d| d.join(&m.name).display().to_string());
            let placed = placed_in.map(|(dir, rel)| {
                dir.join(
                    m.placed
                        .clone()
                        .unwrap_or_else(|| sets::beside(rel, &m.name)),
                )
                .display()
                .to_string()
            });
            json!({
                "name": fsops::shown(m.name.as_ref()),
                "role": m.role.what(),
                "named_by": fsops::shown(m.by.as_ref()),
                "bytes": m.stamp.size,
                "output": output,
                "original": placed,
            })
        })
        .collect();
    let refused: Vec<Value> = set
        .refused
        .iter()
        .map(|r| json!({ "reference": fsops::shown(r.reference.as_ref()), "named_by": fsops::shown(r.by.as_ref()), "why": r.why }))
        .collect();
    let missing: Vec<Value> = set
        .missing
        .iter()
        .map(|m| json!({ "name": fsops::shown(m.name.as_ref()), "role": m.role.what(), "named_by": fsops::shown(m.by.as_ref()) }))
        .collect();
    Some(json!({ "members": members, "not_followed": refused, "missing": missing }))
}

/// Writes the final log of a repaired job into its temporary folder (with the output
/// and archive names of its record) and puts its identity into the record (not saved).
pub(super) fn write_repaired_log(
    ctx: &RunCtx,
    job: &mut Job,
    t: Times,
    report: Option<&Value>,
) -> io::Result<()> {
    let l = &ctx.layout;
    let Phase::Repaired {
        output,
        archive,
        code,
        ..
    } = &job.rec.phase
    else {
        return Err(io::Error::other("not a repaired job"));
    };
    let model_path = l.outbox.join(output);
    let archived = archive
        .as_ref()
        .map(|a| l.archive.join(a).display().to_string());
    let set = set_info(
        job,
        Some(&place_dir(&l.outbox, output)),
        archive.as_deref().map(|a| (l.archive.as_path(), a)),
    );
    let base = report
        .cloned()
        .or_else(|| read_json(&job.tmp(".child.json")))
        .unwrap_or(Value::Null);
    let mut log = final_log(
        base,
        "repaired",
        None,
        None,
        daemon_info(
            ctx,
            job,
            t,
            "repaired",
            json!({
                "worker_exit": code,
                "output": model_path.display().to_string(),
                "original": if archive.is_some() { "archive" } else { "deleted" },
                "archived_as": archived,
                "set": set,
            }),
        ),
    );
    if let Some(o) = log.pointer_mut("/input/path") {
        *o = json!(fsops::shown(l.inbox.join(&job.name).as_os_str()));
    }
    if let Some(o) = log.pointer_mut("/output/path") {
        *o = json!(model_path.display().to_string());
    }
    let text = serde_json::to_string_pretty(&log).map_err(io::Error::other)?;
    let id = write_file(&job.tmp(".log.json"), text.as_bytes())?;
    if let Phase::Repaired { log, .. } = &mut job.rec.phase {
        *log = id;
    }
    Ok(())
}
