//! Publishing a repaired job (see the module documentation): the names chosen and
//! recorded, then each step done only if not done yet. The picture follows the log
//! ([`super::LatePicture`]).

use super::failed::fail;
use super::log::write_repaired_log;
use super::members::{archive_members, publish_members, Step};
use super::{
    ensure_place, ext_of, later, member_tmp, place_dir, put_back, read_json, set_place, tmp_files,
    Done, RunCtx, Times, PICTURE,
};
use crate::daemon::claim::{Job, Phase};
use crate::daemon::config::{Collision, OnSuccess};
use crate::daemon::fsops::{self, FileId};
use crate::daemon::sets;
use serde_json::Value;
use std::fs;
use std::io;
use std::path::Path;
use std::time::SystemTime;

/// After a successful worker: chooses the names, writes the final log, records them,
/// then publishes ([`resume_repaired`]).
pub(super) fn commit(
    ctx: &RunCtx,
    mut job: Job,
    t: Times,
    model: &Path,
    child_log: &Path,
    code: i32,
) -> Done {
    let l = &ctx.layout;
    let Some(model_id) = fs::symlink_metadata(model)
        .ok()
        .filter(|m| m.is_file())
        .map(|m| FileId::of(&m))
    else {
        if !job.home.tmp.is_dir() {
            return put_back(
                ctx,
                job,
                Some("the outbox's temporary folder vanished during the repair".into()),
                false,
            );
        }
        let e = format!("the worker exited {code} but wrote no model");
        return fail(ctx, job, t, "output", e, None, Some(code), true);
    };
    let Some(report) = read_json(child_log) else {
        let _ = fs::remove_file(model);
        let e = format!("the worker exited {code} but wrote no readable repair log");
        return fail(ctx, job, t, "output", e, None, Some(code), true);
    };
    let n = |k: &str| {
        report
            .pointer(&format!("/summary/{k}"))
            .and_then(Value::as_u64)
            .unwrap_or(0)
    };
    let name = job.name_str().unwrap_or_default().to_string();
    // a set: copies of its members for the outbox (the originals go to the archive)
    for i in 0..job.members().len() {
        let m = job.members()[i].clone();
        let shown = fsops::shown(m.name.as_ref());
        match sets::copy_member(&job.member_path(i), &job.tmp(&member_tmp(i)), m.stamp) {
            Ok(Some(id)) => {
                if let Some(set) = job.rec.set.as_mut() {
                    set.members[i].copy = Some(id);
                }
            }
            Ok(None) => {
                let e = format!(
                    "{shown} of its set changed while it was repaired; the set settles again"
                );
                return put_back(ctx, job, Some(e), true);
            }
            Err(e) => {
                let e = format!("cannot copy {shown} of its set: {e}");
                return put_back(ctx, job, Some(e), false);
            }
        }
    }
    let members: Vec<String> = job.members().iter().map(|m| m.name.clone()).collect();
    let when = SystemTime::now();
    let output = if !members.is_empty() && ctx.settings.collision == Collision::Timestamp {
        let names: Vec<&str> = members.iter().map(String::as_str).collect();
        if sets::all_free(&l.outbox, &name, &[".repair.json", ".repair.png"], &names) {
            name.clone()
        } else {
            match sets::new_folder(&l.outbox, &name, when) {
                Ok(sub) => format!("{sub}/{name}"),
                Err(e) => {
                    let e = format!("cannot make a folder for its set in the outbox: {e}");
                    return put_back(ctx, job, Some(e), false);
                }
            }
        }
    } else {
        fsops::free_name(
            &l.outbox,
            &name,
            &[".repair.json", ".repair.png"],
            when,
            ctx.settings.collision,
            0,
        )
    };
    let archive = (ctx.settings.on_success == OnSuccess::Archive)
        .then(|| set_place(&l.archive, &name, &members, &[], when));
    job.rec.phase = Phase::Repaired {
        output,
        archive,
        model: model_id,
        log: FileId { dev: 0, ino: 0 },
        code,
        filled: n("filled"),
        skipped: n("skipped"),
        failed: n("failed"),
    };
    if let Err(e) = write_repaired_log(ctx, &mut job, t, Some(&report)).and_then(|()| job.save()) {
        // nothing is published yet: the file goes back, to be tried again
        job.rec.phase = Phase::Claimed;
        return put_back(
            ctx,
            job,
            Some(format!("cannot record the repair: {e}")),
            false,
        );
    }
    ctx.hooks.at("committing", &job.name);
    resume_repaired(ctx, job, t, Some(&report), false)
}

/// Publishes a repaired job from its record, each step only if not done yet (see the
/// module documentation). `resumed`: finishing the record of a daemon that died.
pub(super) fn resume_repaired(
    ctx: &RunCtx,
    mut job: Job,
    t: Times,
    report: Option<&Value>,
    resumed: bool,
) -> Done {
    let l = &ctx.layout;
    let rule = ctx.settings.collision;
    let name = job.name_str().unwrap_or_default().to_string();
    let tmp_model = job.tmp(&format!(".{}", ext_of(&job)));
    let tmp_log = job.tmp(".log.json");
    for _ in 0..64 {
        let Phase::Repaired {
            output,
            archive,
            model,
            log,
            filled,
            skipped,
            failed,
            ..
        } = job.rec.phase.clone()
        else {
            return later(job, "internal error: not a repaired job".into());
        };
        let renamed = |job: &mut Job, skip_from: &str| -> io::Result<()> {
            // `output` (or its log) is someone else's: take the next free name
            let new = if job.members().is_empty() {
                let mut skip = 1;
                loop {
                    let cand = fsops::free_name(
                        &l.outbox,
                        &name,
                        &[".repair.json", ".repair.png"],
                        SystemTime::now(),
                        Collision::Timestamp,
                        skip,
                    );
                    if cand != skip_from {
                        break cand;
                    }
                    skip += 1;
                }
            } else {
                // a set moves whole into a new folder: no name changes, so the model's
                // and the MTL's references still find their files
                let sub = sets::new_folder(&l.outbox, &name, SystemTime::now())?;
                format!("{sub}/{name}")
            };
            let old_path = l.outbox.join(skip_from);
            if FileId::lstat(&old_path) == Some(model) {
                fsops::rename_noreplace(&old_path, &l.outbox.join(&new))?;
            }
            for m in job.members() {
                let old = l.outbox.join(sets::beside(skip_from, &m.name));
                if m.copy.is_some() && FileId::lstat(&old) == m.copy {
                    fsops::rename_noreplace(&old, &l.outbox.join(sets::beside(&new, &m.name)))?;
                }
            }
            if let Phase::Repaired { output, .. } = &mut job.rec.phase {
                *output = new;
            }
            write_repaired_log(ctx, job, t, report)?;
            job.save()
        };

        // 1. the model
        let out_path = l.outbox.join(&output);
        let there = FileId::lstat(&out_path);
        if there != Some(model) {
            if FileId::lstat(&tmp_model) == Some(model) {
                if there.is_some() && rule == Collision::Timestamp {
                    if let Err(e) = renamed(&mut job, &output) {
                        return later(job, format!("choosing another output name: {e}"));
                    }
                    continue;
                }
                if let Err(e) = ensure_place(&l.outbox, &output) {
                    return later(job, format!("making the set's folder in the outbox: {e}"));
                }
                match fsops::publish(&tmp_model, &out_path, rule) {
                    Ok(()) => {}
                    Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                    Err(e) => return later(job, format!("publishing the model: {e}")),
                }
                if let Err(e) = fsops::fsync_dir(&place_dir(&l.outbox, &output)) {
                    return later(job, format!("syncing the outbox: {e}"));
                }
                ctx.hooks.at("model-published", &job.name);
            } else if fs::symlink_metadata(job.path()).is_ok() {
                // the worker's model is lost (its folder removed): repair again
                job.rec.phase = Phase::Claimed;
                let _ = job.save();
                return later(
                    job,
                    "its repaired model was lost before it was published; it is repaired again"
                        .into(),
                );
            } else {
                tracing::error!(file = %job.shown(), "the repaired model {} is gone from the outbox (taken before its log was written?)", out_path.display());
            }
        }

        // 1b. the other files of its set, copies of the originals, byte for byte
        match publish_members(ctx, &mut job, &output, rule) {
            Step::Done => {}
            Step::Again => continue,
            Step::Rename => {
                if let Err(e) = renamed(&mut job, &output) {
                    return later(job, format!("choosing another folder for the set: {e}"));
                }
                continue;
            }
            Step::Later(e) => return later(job, e),
        }

        // 2a. the originals of the other files of its set, before the mesh's (whose
        // absence from the processing folder says the step is over)
        if fs::symlink_metadata(job.path()).is_ok() {
            match archive_members(ctx, &mut job, t, report, archive.as_deref()) {
                Step::Done => {}
                Step::Again | Step::Rename => continue,
                Step::Later(e) => return later(job, e),
            }
        }

        // 2. the original
        let src = job.path();
        if fs::symlink_metadata(&src).is_ok() {
            match &archive {
                Some(a) => {
                    let dst = l.archive.join(a);
                    if fs::symlink_metadata(&dst).is_ok() {
                        // ours, from before a crash (same inode, or a complete copy), or
                        // someone else's file under that name
                        if FileId::lstat(&dst) == FileId::lstat(&src)
                            || fsops::same_content(&src, &dst)
                        {
                            if let Err(e) = fs::remove_file(&src) {
                                return later(job, format!("removing the archived original from the processing folder: {e}"));
                            }
                        } else {
                            let new = if job.members().is_empty() {
                                fsops::free_name(
                                    &l.archive,
                                    &name,
                                    &[],
                                    SystemTime::now(),
                                    Collision::Timestamp,
                                    1,
                                )
                            } else {
                                let sub =
                                    sets::free_folder(&l.archive, &name, SystemTime::now(), 1);
                                format!("{sub}/{name}")
                            };
                            if let Phase::Repaired { archive, .. } = &mut job.rec.phase {
                                *archive = Some(new);
                            }
                            if let Err(e) = write_repaired_log(ctx, &mut job, t, report)
                                .and_then(|()| job.save())
                            {
                                return later(job, format!("recording another archive name: {e}"));
                            }
                            continue;
                        }
                    } else {
                        ctx.hooks.at("move", &job.name);
                        if let Err(e) = ensure_place(&l.archive, a) {
                            return later(
                                job,
                                format!("making the set's folder in the archive: {e}"),
                            );
                        }
                        let copy = format!(".holefill-{}.copy", job.id);
                        let linked = || ctx.hooks.at("archive-linked", &job.name);
                        match fsops::move_file(&src, &l.archive, a.as_ref(), &copy, &linked) {
                            Ok(()) => {}
                            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                            Err(e) => {
                                return later(
                                    job,
                                    format!(
                                        "archiving the original in {}: {e} (the model is in the outbox; its log follows once the original is archived)",
                                        l.archive.display()
                                    ),
                                )
                            }
                        }
                        if let Err(e) = fsops::fsync_dir(&place_dir(&l.archive, a)) {
                            return later(job, format!("syncing the archive: {e}"));
                        }
                    }
                }
                None => {
                    if let Err(e) = fs::remove_file(&src) {
                        return later(job, format!("deleting the original: {e}"));
                    }
                    if let Err(e) = fsops::fsync_dir(&job.home.dir) {
                        return later(job, format!("syncing the processing folder: {e}"));
                    }
                }
            }
            ctx.hooks.at("archived", &job.name);
        }

        // 3. the log
        let log_path = l.outbox.join(format!("{output}.repair.json"));
        let there = FileId::lstat(&log_path);
        if there != Some(log) {
            if FileId::lstat(&tmp_log) != Some(log) {
                // lost with the temporary folder: write it again
                if let Err(e) =
                    write_repaired_log(ctx, &mut job, t, report).and_then(|()| job.save())
                {
                    return later(job, format!("writing the log: {e}"));
                }
                continue;
            }
            if there.is_some() && rule == Collision::Timestamp {
                if let Err(e) = renamed(&mut job, &output) {
                    return later(job, format!("choosing another output name: {e}"));
                }
                continue;
            }
            match fsops::publish(&tmp_log, &log_path, rule) {
                Ok(()) => {}
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
                Err(e) => return later(job, format!("publishing the log: {e}")),
            }
            if let Err(e) = fsops::fsync_dir(&l.outbox) {
                return later(job, format!("syncing the outbox: {e}"));
            }
            ctx.hooks.at("log-published", &job.name);
        }
        job.forget();
        // the picture, which the child may still be drawing, is its waiter's
        for s in tmp_files(&job).iter().filter(|s| *s != PICTURE) {
            let _ = fs::remove_file(job.tmp(s));
        }
        return Done::Repaired {
            job,
            output,
            filled,
            skipped,
            failed,
            secs: t.t0.elapsed().as_secs_f64(),
            resumed,
            picture: None,
        };
    }
    later(
        job,
        "no free output or archive name after many tries".into(),
    )
}
