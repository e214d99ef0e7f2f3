//! The members of a set (an OBJ's materials and textures, a glTF's buffers and
//! images): their outbox copies published beside the model, their originals moved.

use super::log::write_repaired_log;
use super::{ensure_place, member_tmp, place_dir, RunCtx, Times};
use crate::daemon::claim::{Job, Phase};
use crate::daemon::config::Collision;
use crate::daemon::fsops::{self, FileId};
use crate::daemon::sets;
use serde_json::Value;
use std::fs;
use std::io;
use std::path::Path;
use std::time::SystemTime;

/// How a step of a set's publish went.
pub(super) enum Step {
    /// Done (or nothing to do).
    Done,
    /// Something changed (a record updated, a name taken meanwhile): the publish
    /// starts over from its record.
    Again,
    /// A name in the outbox is someone else's: the set moves to a new folder.
    Rename,
    /// Cannot be done now.
    Later(String),
}

/// Publishes the outbox copies of a set's members beside the model (`output`), each
/// only if not there yet (the outbox name holds the copy's inode). A copy lost with
/// the temporary folder is made again from the claimed member.
pub(super) fn publish_members(ctx: &RunCtx, job: &mut Job, output: &str, rule: Collision) -> Step {
    let l = &ctx.layout;
    let mut published = false;
    for i in 0..job.members().len() {
        let m = job.members()[i].clone();
        let shown = fsops::shown(m.name.as_ref());
        let dst = l.outbox.join(sets::beside(output, &m.name));
        let there = FileId::lstat(&dst);
        if m.copy.is_some() && there == m.copy {
            continue;
        }
        let tmp = job.tmp(&member_tmp(i));
        if m.copy.is_none() || FileId::lstat(&tmp) != m.copy {
            let src = job.member_path(i);
            if fs::symlink_metadata(&src).is_err() {
                tracing::error!(file = %job.shown(), "{shown} of its set is neither in the outbox nor in the processing folder (removed by hand?)");
                continue;
            }
            {
                use std::os::unix::fs::DirBuilderExt;
                let _ = fs::DirBuilder::new().mode(0o700).create(&job.home.tmp);
            }
            match sets::copy_member(&src, &tmp, m.stamp) {
                Ok(Some(id)) => {
                    if let Some(set) = job.rec.set.as_mut() {
                        set.members[i].copy = Some(id);
                    }
                    if let Err(e) = job.save() {
                        return Step::Later(format!("recording the copy of {shown}: {e}"));
                    }
                    return Step::Again;
                }
                Ok(None) => {
                    return Step::Later(format!(
                        "{shown} of its set is not the file claimed any more"
                    ))
                }
                Err(e) => return Step::Later(format!("copying {shown} of its set: {e}")),
            }
        }
        if there.is_some() && rule == Collision::Timestamp {
            return Step::Rename;
        }
        match fsops::publish(&tmp, &dst, rule) {
            Ok(()) => published = true,
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => return Step::Again,
            Err(e) => return Step::Later(format!("publishing {shown} of its set: {e}")),
        }
    }
    if published {
        if let Err(e) = fsops::fsync_dir(&place_dir(&l.outbox, output)) {
            return Step::Later(format!("syncing the outbox: {e}"));
        }
        ctx.hooks.at("members-published", &job.name);
    }
    Step::Done
}

/// Moves the originals of a set's members beside the mesh's place `dest` in `dir`
/// (the archive or the failed folder; `None`: deleted), each only if still in the
/// processing folder. A name taken there by another file sends the set to a new
/// folder (`Again`, after `moved_on` recorded it).
pub(super) fn place_members(
    ctx: &RunCtx,
    job: &mut Job,
    dir: &Path,
    dest: Option<&str>,
    moved_on: &mut dyn FnMut(&mut Job, String) -> io::Result<()>,
) -> Step {
    let mut moved = false;
    let name = job.name_str().unwrap_or_default().to_string();
    for i in 0..job.members().len() {
        let m = job.members()[i].clone();
        let shown = fsops::shown(m.name.as_ref());
        let src = job.member_path(i);
        if fs::symlink_metadata(&src).is_err() {
            continue;
        }
        let Some(dest) = dest else {
            if let Err(e) = fs::remove_file(&src) {
                return Step::Later(format!("deleting {shown} of its set: {e}"));
            }
            moved = true;
            continue;
        };
        let rel = sets::beside(dest, &m.name);
        let dst = dir.join(&rel);
        if fs::symlink_metadata(&dst).is_ok() {
            if FileId::lstat(&dst) == FileId::lstat(&src) || fsops::same_content(&src, &dst) {
                if let Err(e) = fs::remove_file(&src) {
                    return Step::Later(format!(
                        "removing {shown} from the processing folder: {e}"
                    ));
                }
                moved = true;
                continue;
            }
            let sub = sets::free_folder(dir, &name, SystemTime::now(), 1);
            if let Err(e) = moved_on(job, format!("{sub}/{name}")) {
                return Step::Later(format!("recording another folder for the set: {e}"));
            }
            return Step::Again;
        }
        if let Err(e) = ensure_place(dir, dest) {
            return Step::Later(format!("making the set's folder in {}: {e}", dir.display()));
        }
        ctx.hooks.at("move", &job.name);
        let copy = format!(".holefill-{}.m{i}.copy", job.id);
        match fsops::move_file(&src, &place_dir(dir, dest), m.name.as_ref(), &copy, &|| {}) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => return Step::Again,
            Err(e) => {
                return Step::Later(format!(
                    "moving {shown} of its set into {}: {e}",
                    dir.display()
                ))
            }
        }
        moved = true;
        if let Some(set) = job.rec.set.as_mut() {
            set.members[i].placed = Some(rel);
        }
        if let Err(e) = job.save() {
            tracing::warn!(file = %job.shown(), "cannot record where {shown} went: {e}");
        }
    }
    if moved {
        if let Some(d) = dest {
            if let Err(e) = fsops::fsync_dir(&place_dir(dir, d)) {
                return Step::Later(format!("syncing {}: {e}", dir.display()));
            }
        }
        let _ = fsops::fsync_dir(&job.home.dir);
    }
    Step::Done
}

/// The archive step of a set's members (see [`place_members`]).
pub(super) fn archive_members(
    ctx: &RunCtx,
    job: &mut Job,
    t: Times,
    report: Option<&Value>,
    archive: Option<&str>,
) -> Step {
    let dir = ctx.layout.archive.clone();
    place_members(ctx, job, &dir, archive, &mut |job, new| {
        if let Phase::Repaired { archive, .. } = &mut job.rec.phase {
            *archive = Some(new);
        }
        write_repaired_log(ctx, job, t, report)?;
        job.save()
    })
}
