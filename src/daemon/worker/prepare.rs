//! Checks the claimed entry and opens it once (see the module documentation), with
//! the limits that need no worker, and waits for the members of a set.

use super::failed::fail;
use super::{put_back, Done, RunCtx, Times};
use crate::daemon::claim::{self, Job};
use crate::daemon::fsops::{self, FileId, Stamp};
use crate::daemon::sniff;
use std::fs;
use std::io;

/// Checks the claimed file and opens it (see the module documentation); applies the
/// limits that need no worker. `Err` is the job's end.
#[allow(clippy::result_large_err)]
pub(super) fn prepare(
    ctx: &RunCtx,
    mut job: Job,
    t: Times,
) -> Result<(Job, fs::File, Stamp), Box<Done>> {
    let path = job.path();
    let md = match fs::symlink_metadata(&path) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => {
            job.forget();
            return Err(Box::new(Done::Gone {
                job,
                error: "it vanished from the processing folder".into(),
            }));
        }
        Err(e) => {
            return Err(Box::new(Done::Later {
                job,
                error: format!("cannot look at the claimed file: {e}"),
            }))
        }
    };
    if md.is_dir() {
        // swapped in after the inbox was looked at: directories are never taken
        return Err(Box::new(put_back(
            ctx,
            job,
            Some("a directory, not a file: left in the inbox".into()),
            true,
        )));
    }
    if !md.is_file() {
        return Err(Box::new(reject_special(ctx, job, t, &md)));
    }
    let id = FileId::of(&md);
    let judged = job.rec.stamp;
    if judged.is_some_and(|s| s.id != id) {
        return Err(Box::new(put_back(
            ctx,
            job,
            Some("another file took its place between the check and the claim".into()),
            true,
        )));
    }
    let file = match fsops::open_nofollow(&path) {
        Ok(f) => f,
        Err(e) if e.kind() == io::ErrorKind::PermissionDenied => {
            let err = format!("cannot read the file: {e}");
            return Err(Box::new(fail(ctx, job, t, "input", err, None, None, true)));
        }
        Err(e) => {
            return Err(Box::new(Done::Later {
                job,
                error: format!("cannot open the claimed file: {e}"),
            }))
        }
    };
    let now = match file.metadata() {
        Ok(m) if m.is_file() && FileId::of(&m) == id => Stamp::of(&m),
        _ => {
            return Err(Box::new(put_back(
                ctx,
                job,
                Some("another file took its place while it was opened".into()),
                true,
            )))
        }
    };
    if job.fresh && judged.is_some_and(|s| (s.size, s.mtime_ns) != (now.size, now.mtime_ns)) {
        return Err(Box::new(put_back(
            ctx,
            job,
            Some("it changed since it was judged complete; it settles again".into()),
            true,
        )));
    }
    if let Some(problem) = fsops::name_problem(&job.name) {
        return Err(Box::new(fail(
            ctx, job, t, "name", problem, None, None, true,
        )));
    }
    if let Some(done) = check_set(ctx, &mut job, t, &file) {
        return Err(Box::new(done));
    }
    let s = &ctx.settings;
    if job.attempt > s.max_attempts {
        let started = job.attempt - 1;
        let err = format!(
            "{started} attempts were started and none finished (the worker or the daemon died each time); max_attempts = {}",
            s.max_attempts
        );
        job.attempt = started;
        return Err(Box::new(fail(ctx, job, t, "worker", err, None, None, true)));
    }
    // the worker writes there (an adopted folder's may be gone with the outbox). The
    // outbox itself is never made here: when it vanished, the daemon's folder check
    // makes it again (and says so); the file waits in the inbox until then.
    if !fs::symlink_metadata(&ctx.layout.outbox).is_ok_and(|m| m.is_dir()) {
        return Err(Box::new(put_back(
            ctx,
            job,
            Some("the outbox is not there (it is made again before the file is taken)".into()),
            false,
        )));
    }
    {
        use std::os::unix::fs::DirBuilderExt;
        let _ = claim::make_private_dir(&ctx.layout.tmp_root, 0o755);
        let _ = fs::DirBuilder::new().mode(0o700).create(&job.home.tmp);
    }
    if job.rec.attempts != job.attempt {
        job.rec.attempts = job.attempt;
        if let Err(e) = job.save() {
            tracing::warn!(file = %job.shown(), "cannot record the attempt count: {e}");
        }
    }
    if s.max_file_bytes > 0 && now.size > s.max_file_bytes {
        let err = format!(
            "file size {} bytes > max_file_bytes = {}",
            now.size, s.max_file_bytes
        );
        return Err(Box::new(fail(ctx, job, t, "limits", err, None, None, true)));
    }
    if now.size == 0 {
        let err = if job.fresh {
            format!(
                "the file is empty, and stayed empty for max_wait_secs = {} s",
                s.max_wait.as_secs()
            )
        } else {
            "the file is empty".to_string()
        };
        return Err(Box::new(fail(ctx, job, t, "input", err, None, None, true)));
    }
    if s.max_faces > 0 {
        let name = job.name.to_string_lossy().into_owned();
        if let Some(n) = sniff::declared_faces(&file, &name).filter(|&n| n > s.max_faces) {
            let err = format!("{n} faces > max_faces = {}", s.max_faces);
            return Err(Box::new(fail(ctx, job, t, "limits", err, None, None, true)));
        }
    }
    Ok((job, file, now))
}

/// The set of a claimed mesh (see [`crate::daemon::sets`]): `Some` ends this attempt. A mesh
/// whose references were not read yet and that names other files goes to wait for
/// them ([`Done::Members`]); a set whose members are not all in the processing folder
/// (a crash while they were claimed) puts them back and waits again; a set that timed
/// out fails.
fn check_set(ctx: &RunCtx, job: &mut Job, t: Times, file: &fs::File) -> Option<Done> {
    let name = job.name_str().unwrap_or_default().to_string();
    match &job.rec.set {
        None => match sniff::references(file, &name) {
            Ok(refs) if refs.is_empty() => None,
            Ok(refs) => Some(Done::Members {
                job: job.clone(),
                refs,
            }),
            Err(e) => Some(Done::Later {
                job: job.clone(),
                error: format!("cannot read the files it names: {e}"),
            }),
        },
        Some(set) => {
            let complete = set.members.iter().enumerate().all(|(i, m)| {
                fs::symlink_metadata(job.member_path(i))
                    .is_ok_and(|md| md.is_file() && FileId::of(&md) == m.stamp.id)
            });
            if !complete {
                let stuck = claim::put_back_members(&ctx.layout, job);
                if !stuck.is_empty() {
                    return Some(Done::Later {
                        job: job.clone(),
                        error: format!(
                            "its set is incomplete and cannot be put back: {}",
                            stuck.join("; ")
                        ),
                    });
                }
                return check_set(ctx, job, t, file);
            }
            if !set.missing.is_empty() {
                let err = set.missing_message();
                return Some(fail(ctx, job.clone(), t, "set", err, None, None, true));
            }
            None
        }
    }
}

/// A claimed entry that is not a regular file (symlink, FIFO, socket, device): never
/// opened or followed; removed, with a log in the failed folder saying what it was.
fn reject_special(ctx: &RunCtx, job: Job, t: Times, md: &fs::Metadata) -> Done {
    use std::os::unix::fs::FileTypeExt;
    let ft = md.file_type();
    let what = if ft.is_symlink() {
        let target = fs::read_link(job.path())
            .map(|p| fsops::shown(p.as_os_str()))
            .unwrap_or_else(|_| "?".into());
        format!("a symbolic link (to {target})")
    } else if ft.is_fifo() {
        "a FIFO (named pipe)".to_string()
    } else if ft.is_socket() {
        "a socket".to_string()
    } else if ft.is_block_device() || ft.is_char_device() {
        "a device".to_string()
    } else {
        "not a regular file".to_string()
    };
    let err =
        format!("not a regular file: {what}; it was neither opened nor followed, and is removed");
    fail(ctx, job, t, "input", err, None, None, false)
}
