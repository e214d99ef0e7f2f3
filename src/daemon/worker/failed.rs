//! The failed folder: the original moved there untouched (or an entry that is not a
//! regular file removed) with its log, each step only if not done yet.

use super::log::{daemon_info, final_log, set_info, write_file};
use super::members::{place_members, Step};
use super::{ensure_place, ext_of, later, place_dir, set_place, tmp_files, Done, RunCtx, Times};
use crate::daemon::claim::{Job, Phase};
use crate::daemon::config::Collision;
use crate::daemon::fsops::{self, FileId};
use serde_json::{json, Value};
use std::fs;
use std::io;
use std::path::Path;
use std::time::SystemTime;

/// Sends the file, untouched, to the failed folder with its log (`kept` false: not a
/// regular file, removed instead): records the decision, then [`finish_failed`].
#[allow(clippy::too_many_arguments)]
pub(super) fn fail(
    ctx: &RunCtx,
    mut job: Job,
    t: Times,
    stage: &str,
    error: String,
    report: Option<Value>,
    exit: Option<i32>,
    kept: bool,
) -> Done {
    for s in tmp_files(&job) {
        if s != ".log.json" {
            let _ = fs::remove_file(job.tmp(&s));
        }
    }
    let name = match job.name_str() {
        Some(n) => n.to_string(),
        None => fsops::safe_name(&job.name),
    };
    let members: Vec<String> = job.members().iter().map(|m| m.name.clone()).collect();
    let dest = set_place(
        &ctx.layout.failed,
        &name,
        &members,
        &[".repair.json"],
        SystemTime::now(),
    );
    job.rec.phase = Phase::Failed {
        dest,
        kept,
        stage: stage.to_string(),
        error,
        exit,
    };
    if let Err(e) = job.save() {
        tracing::warn!(file = %job.shown(), "cannot record the failure: {e}");
    }
    finish_failed(ctx, job, t, report)
}

/// Someone else's file took the failed file's name: records a free name beside it
/// (a time stamp added) as its destination, for the next round.
fn take_free_name(job: &mut Job, failed: &Path, taken: &str) {
    let new = fsops::free_name(
        failed,
        taken,
        &[".repair.json"],
        SystemTime::now(),
        Collision::Timestamp,
        1,
    );
    if let Phase::Failed { dest, .. } = &mut job.rec.phase {
        *dest = new;
    }
    let _ = job.save();
}

/// Moves the original to the failed folder (or removes an entry that is not a regular
/// file) and writes its log there, each step only if not done yet.
pub(super) fn finish_failed(ctx: &RunCtx, mut job: Job, t: Times, report: Option<Value>) -> Done {
    let l = &ctx.layout;
    for _ in 0..64 {
        let Phase::Failed {
            dest,
            kept,
            stage,
            error,
            exit,
        } = job.rec.phase.clone()
        else {
            return later(job, "internal error: not a failed job".into());
        };
        let src = job.path();
        let dst = l.failed.join(&dest);
        if fs::symlink_metadata(&src).is_ok() && !job.members().is_empty() {
            let failed_dir = l.failed.clone();
            let step = place_members(ctx, &mut job, &failed_dir, Some(&dest), &mut |job, new| {
                if let Phase::Failed { dest, .. } = &mut job.rec.phase {
                    *dest = new;
                }
                job.save()
            });
            match step {
                Step::Done => {}
                Step::Again | Step::Rename => continue,
                Step::Later(e) => return later(job, format!("{stage}: {error}; then {e}")),
            }
        }
        if fs::symlink_metadata(&src).is_ok() {
            if kept {
                if fs::symlink_metadata(&dst).is_ok() {
                    if FileId::lstat(&dst) == FileId::lstat(&src) || fsops::same_content(&src, &dst)
                    {
                        let _ = fs::remove_file(&src);
                    } else {
                        take_free_name(&mut job, &l.failed, &dest);
                        continue;
                    }
                } else {
                    ctx.hooks.at("move", &job.name);
                    if let Err(e) = ensure_place(&l.failed, &dest) {
                        return later(job, format!("{stage}: {error}; then making its folder in the failed folder: {e}"));
                    }
                    let copy = format!(".holefill-{}.copy", job.id);
                    match fsops::move_file(&src, &l.failed, dest.as_ref(), &copy, &|| {}) {
                        Ok(()) => {}
                        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
                            take_free_name(&mut job, &l.failed, &dest);
                            continue;
                        }
                        Err(e) => {
                            return later(
                                job,
                                format!(
                                    "{stage}: {error}; then moving it to the failed folder: {e}"
                                ),
                            )
                        }
                    }
                    let _ = fsops::fsync_dir(&place_dir(&l.failed, &dest));
                }
            } else if let Err(e) = fs::remove_file(&src) {
                return later(job, format!("removing it: {e}"));
            }
            let _ = fsops::fsync_dir(&job.home.dir);
            ctx.hooks.at("failed-moved", &job.name);
        }
        let log_path = l.failed.join(format!("{dest}.repair.json"));
        if fs::symlink_metadata(&log_path).is_err() {
            let mut base = report.clone().unwrap_or_else(|| {
                json!({
                    "holefill_version": env!("CARGO_PKG_VERSION"),
                    "input": { "format": ext_of(&job) },
                })
            });
            let input = fsops::shown(l.inbox.join(&job.name).as_os_str());
            match base.pointer_mut("/input") {
                Some(Value::Object(o)) => {
                    o.insert("path".into(), json!(input));
                }
                _ => base["input"] = json!({ "path": input }),
            }
            let original = kept.then(|| dst.display().to_string());
            let set = set_info(&job, None, Some((l.failed.as_path(), dest.as_str())));
            let log = final_log(
                base,
                "failed",
                Some(&stage),
                Some(&error),
                daemon_info(
                    ctx,
                    &job,
                    t,
                    "failed",
                    json!({ "worker_exit": exit, "output": null, "original": original, "set": set }),
                ),
            );
            let text = serde_json::to_string_pretty(&log).unwrap_or_default();
            let tmp = l.failed.join(format!(".holefill-{}.log", job.id));
            let r = write_file(&tmp, text.as_bytes()).and_then(|_| {
                match fsops::rename_noreplace(&tmp, &log_path) {
                    Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(()),
                    r => r,
                }
            });
            let _ = fs::remove_file(&tmp);
            if let Err(e) = r {
                return later(
                    job,
                    format!("writing the failure log {}: {e}", log_path.display()),
                );
            }
            let _ = fsops::fsync_dir(&place_dir(&l.failed, &dest));
        }
        job.forget();
        return Done::Failed {
            job,
            stage,
            error,
            secs: t.t0.elapsed().as_secs_f64(),
        };
    }
    later(
        job,
        "no free name in the failed folder after many tries".into(),
    )
}
