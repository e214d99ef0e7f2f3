//! File operations the daemon's guarantees rest on: moves that never replace an
//! existing file, folder fsync, the collision rule, UTC time stamps.
//!
//! Moves without replacing: `renameat2(RENAME_NOREPLACE)` is not reachable without
//! `unsafe` (std does not expose it and the crate forbids unsafe code), so a move into
//! a shared folder is `link(src, dst)` (which fails when `dst` exists) followed by
//! `unlink(src)`. Where `link` is refused (a filesystem without hard links, or
//! `fs.protected_hardlinks` for a file owned by another user) the fallback is a rename
//! after checking that `dst` is free; where the folders are on different filesystems,
//! a copy (fsynced) then the link.

use super::config::Collision;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// fsyncs a folder, so that the renames and links in it are durable.
pub fn fsync_dir(dir: &Path) -> io::Result<()> {
    fs::File::open(dir)?.sync_all()
}

/// True when an error is "the disk (or quota) is full".
pub fn is_disk_full(e: &io::Error) -> bool {
    matches!(e.raw_os_error(), Some(libc::ENOSPC) | Some(libc::EDQUOT))
}

/// Moves `src` to `dst` without replacing an existing `dst`: `Err(AlreadyExists)`
/// when it exists. `Err(NotFound)` when `src` vanished (taken by someone else).
pub fn move_noreplace(src: &Path, dst: &Path) -> io::Result<()> {
    match fs::hard_link(src, dst) {
        Ok(()) => match fs::remove_file(src) {
            Ok(()) => Ok(()),
            Err(e) => {
                // someone else moved `src` away between our link and unlink: the file is
                // theirs; drop our link
                let _ = fs::remove_file(dst);
                Err(e)
            }
        },
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Err(e),
        Err(e) if e.raw_os_error() == Some(libc::EXDEV) => {
            copy_noreplace(src, dst).and_then(|()| fs::remove_file(src))
        }
        Err(e)
            if matches!(
                e.raw_os_error(),
                Some(libc::EPERM) | Some(libc::EOPNOTSUPP) | Some(libc::EMLINK)
            ) =>
        {
            if fs::symlink_metadata(dst).is_ok() {
                return Err(io::Error::new(
                    io::ErrorKind::AlreadyExists,
                    "target exists",
                ));
            }
            fs::rename(src, dst)
        }
        Err(e) => Err(e),
    }
}

/// Copies `src` next to `dst` (fsynced), then links it to `dst` without replacing.
fn copy_noreplace(src: &Path, dst: &Path) -> io::Result<()> {
    let dir = dst.parent().unwrap_or(Path::new("."));
    let name = dst
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{}.{}.copy", name, std::process::id()));
    let r = (|| {
        fs::copy(src, &tmp)?;
        fs::File::open(&tmp)?.sync_all()?;
        match fs::hard_link(&tmp, dst) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Err(e),
            Err(_) => {
                if fs::symlink_metadata(dst).is_ok() {
                    return Err(io::Error::new(
                        io::ErrorKind::AlreadyExists,
                        "target exists",
                    ));
                }
                fs::rename(&tmp, dst)
            }
        }
    })();
    let _ = fs::remove_file(&tmp);
    r
}

/// Links `src` (a temporary file of ours) to `dst`: without replacing under
/// [`Collision::Timestamp`], replacing atomically (rename) under
/// [`Collision::Overwrite`]. `src` stays.
pub fn publish(src: &Path, dst: &Path, rule: Collision) -> io::Result<()> {
    match rule {
        Collision::Timestamp => fs::hard_link(src, dst),
        Collision::Overwrite => {
            let dir = dst.parent().unwrap_or(Path::new("."));
            let name = dst
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let tmp = dir.join(format!(".{}.{}.publish", name, std::process::id()));
            let _ = fs::remove_file(&tmp);
            fs::hard_link(src, &tmp)?;
            fs::rename(&tmp, dst).inspect_err(|_| {
                let _ = fs::remove_file(&tmp);
            })
        }
    }
}

/// Splits `scan01.obj` into `("scan01", ".obj")`.
fn split_ext(name: &str) -> (&str, &str) {
    match name.rfind('.') {
        Some(i) if i > 0 => (&name[..i], &name[i..]),
        _ => (name, ""),
    }
}

/// The collision rule's candidate names for `name` written at `when`: `name` itself,
/// then `stem.STAMP.ext`, `stem.STAMP-2.ext`, ... (STAMP = UTC `YYYYMMDDTHHMMSSZ`).
pub fn candidate_name(name: &str, when: SystemTime, n: usize) -> String {
    if n == 0 {
        return name.to_string();
    }
    let (stem, ext) = split_ext(name);
    let stamp = compact_stamp(when);
    if n == 1 {
        format!("{stem}.{stamp}{ext}")
    } else {
        format!("{stem}.{stamp}-{n}{ext}")
    }
}

/// The first candidate name under which neither `dir/NAME` nor `dir/NAME + suffix` (for
/// each suffix) exists. Under [`Collision::Overwrite`], `name` itself.
pub fn free_name(
    dir: &Path,
    name: &str,
    suffixes: &[&str],
    when: SystemTime,
    rule: Collision,
    skip: usize,
) -> String {
    if rule == Collision::Overwrite {
        return name.to_string();
    }
    let mut n = skip;
    loop {
        let cand = candidate_name(name, when, n);
        let taken = fs::symlink_metadata(dir.join(&cand)).is_ok()
            || suffixes
                .iter()
                .any(|s| fs::symlink_metadata(dir.join(format!("{cand}{s}"))).is_ok());
        if !taken {
            return cand;
        }
        n += 1;
    }
}

/// Moves `src` into folder `dir` under `name` or, when taken, the collision rule's next
/// name; writes nothing over an existing file (even under `Overwrite`: the failed and
/// archive folders keep every original). Returns the final path.
pub fn move_into(src: &Path, dir: &Path, name: &str, suffixes: &[&str]) -> io::Result<PathBuf> {
    let when = SystemTime::now();
    let mut skip = 0;
    for _ in 0..1000 {
        let cand = free_name(dir, name, suffixes, when, Collision::Timestamp, skip);
        let dst = dir.join(&cand);
        match move_noreplace(src, &dst) {
            Ok(()) => return Ok(dst),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
                skip += 1;
                continue;
            }
            Err(e) => return Err(e),
        }
    }
    Err(io::Error::other(format!(
        "no free name for {name} in {}",
        dir.display()
    )))
}

/// Days since 1970-01-01 to (year, month, day) (proleptic Gregorian).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (if m <= 2 { y + 1 } else { y }, m, d)
}

fn parts(t: SystemTime) -> (i64, u32, u32, u32, u32, u32, u32) {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs() as i64;
    let (y, mo, da) = civil_from_days(secs.div_euclid(86_400));
    let s = secs.rem_euclid(86_400);
    (
        y,
        mo,
        da,
        (s / 3600) as u32,
        ((s / 60) % 60) as u32,
        (s % 60) as u32,
        d.subsec_millis(),
    )
}

/// `2026-11-23T12:05:01.123Z`.
pub fn rfc3339(t: SystemTime) -> String {
    let (y, mo, d, h, mi, s, ms) = parts(t);
    format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}.{ms:03}Z")
}

/// `20261123T120501Z`.
pub fn compact_stamp(t: SystemTime) -> String {
    let (y, mo, d, h, mi, s, _) = parts(t);
    format!("{y:04}{mo:02}{d:02}T{h:02}{mi:02}{s:02}Z")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn time_stamps_match_known_dates() {
        assert_eq!(rfc3339(UNIX_EPOCH), "1970-01-01T00:00:00.000Z");
        // 2026-11-23 12:05:01 UTC = 1795435501
        let t = UNIX_EPOCH + Duration::from_millis(1_795_435_501_250);
        assert_eq!(rfc3339(t), "2026-11-23T12:05:01.250Z");
        assert_eq!(compact_stamp(t), "20261123T120501Z");
        // leap day
        let t = UNIX_EPOCH + Duration::from_secs(951_782_400); // 2000-02-29
        assert_eq!(rfc3339(t), "2000-02-29T00:00:00.000Z");
    }

    #[test]
    fn collision_names() {
        let t = UNIX_EPOCH + Duration::from_secs(1_795_435_501);
        assert_eq!(candidate_name("scan01.obj", t, 0), "scan01.obj");
        assert_eq!(
            candidate_name("scan01.obj", t, 1),
            "scan01.20261123T120501Z.obj"
        );
        assert_eq!(
            candidate_name("scan01.obj", t, 2),
            "scan01.20261123T120501Z-2.obj"
        );
        assert_eq!(candidate_name("a.b.PLY", t, 1), "a.b.20261123T120501Z.PLY");
    }

    #[test]
    fn free_name_skips_a_taken_model_or_log() {
        let d = tempfile::tempdir().unwrap();
        let t = UNIX_EPOCH + Duration::from_secs(1_795_435_501);
        let sfx = [".repair.json"];
        assert_eq!(
            free_name(d.path(), "s.obj", &sfx, t, Collision::Timestamp, 0),
            "s.obj"
        );
        fs::write(d.path().join("s.obj.repair.json"), "{}").unwrap();
        assert_eq!(
            free_name(d.path(), "s.obj", &sfx, t, Collision::Timestamp, 0),
            "s.20261123T120501Z.obj"
        );
        fs::write(d.path().join("s.20261123T120501Z.obj"), "x").unwrap();
        assert_eq!(
            free_name(d.path(), "s.obj", &sfx, t, Collision::Timestamp, 0),
            "s.20261123T120501Z-2.obj"
        );
        assert_eq!(
            free_name(d.path(), "s.obj", &sfx, t, Collision::Overwrite, 0),
            "s.obj"
        );
    }

    #[test]
    fn move_noreplace_never_overwrites() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("a");
        let b = d.path().join("b");
        fs::write(&a, "A").unwrap();
        fs::write(&b, "B").unwrap();
        let e = move_noreplace(&a, &b).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::AlreadyExists);
        assert_eq!(fs::read_to_string(&b).unwrap(), "B");
        assert_eq!(fs::read_to_string(&a).unwrap(), "A");
        let c = d.path().join("c");
        move_noreplace(&a, &c).unwrap();
        assert!(!a.exists());
        assert_eq!(fs::read_to_string(&c).unwrap(), "A");
        assert_eq!(
            move_noreplace(&a, &d.path().join("e")).unwrap_err().kind(),
            io::ErrorKind::NotFound
        );
    }

    #[test]
    fn move_into_uses_the_collision_rule() {
        let d = tempfile::tempdir().unwrap();
        let dst = d.path().join("dst");
        fs::create_dir(&dst).unwrap();
        fs::write(dst.join("s.obj"), "old").unwrap();
        let src = d.path().join("s.obj");
        fs::write(&src, "new").unwrap();
        let p = move_into(&src, &dst, "s.obj", &[]).unwrap();
        assert_ne!(p, dst.join("s.obj"));
        assert_eq!(fs::read_to_string(&p).unwrap(), "new");
        assert_eq!(fs::read_to_string(dst.join("s.obj")).unwrap(), "old");
    }
}
