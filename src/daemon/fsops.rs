//! File operations the daemon's guarantees rest on: moves that never replace an
//! existing file (also across file systems), folder fsync, the collision rule, names
//! as they may be logged, UTC time stamps.
//!
//! Moves without replacing are `renameat2(RENAME_NOREPLACE)` (through `rustix`): one
//! atomic step that fails with `EEXIST` when the target exists, whoever owns the file
//! (`link(2)` is refused under `fs.protected_hardlinks` for a file of another user,
//! the normal case of a daemon moving producers' files). A file system without
//! `RENAME_NOREPLACE` (`EINVAL`) gets `link(2)` then `unlink(2)`; where that is
//! refused too the move fails: nothing is ever moved by a check-then-rename. Across
//! file systems a move is a copy under a temporary name in the target folder, fsync
//! of the copy, the no-replace rename to the final name, fsync of the target folder,
//! and only then the removal of the source (and fsync of its folder): a crash at any
//! point leaves the source, or the complete copy, or both (the caller's record of the
//! target name tells a recovering daemon which).

use super::config::Collision;
use rustix::fs::{RenameFlags, CWD};
use rustix::io::Errno;
use serde::{Deserialize, Serialize};
use std::ffi::{OsStr, OsString};
use std::fs;
use std::io;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// The longest file name of Linux file systems, in bytes.
pub const NAME_MAX: usize = 255;
/// The longest inbox name the daemon repairs: its outputs add a time stamp and a
/// counter (`.20261123T120501Z-1000`, 22 bytes) and `.repair.json` (12 bytes) to it.
pub const MAX_NAME: usize = NAME_MAX - 22 - 12;

/// fsyncs a folder, so that the renames and links in it are durable.
pub fn fsync_dir(dir: &Path) -> io::Result<()> {
    fs::File::open(dir)?.sync_all()
}

/// A file's identity: device and inode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct FileId {
    pub dev: u64,
    pub ino: u64,
}

impl FileId {
    pub fn of(m: &fs::Metadata) -> FileId {
        FileId {
            dev: m.dev(),
            ino: m.ino(),
        }
    }
    /// The identity of `path` itself (a symlink is not followed).
    pub fn lstat(path: &Path) -> Option<FileId> {
        fs::symlink_metadata(path).ok().map(|m| FileId::of(&m))
    }
}

/// What the daemon compares to tell that a file did not change: identity, size,
/// modification time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Stamp {
    pub id: FileId,
    pub size: u64,
    pub mtime_ns: i128,
}

impl Stamp {
    pub fn of(m: &fs::Metadata) -> Stamp {
        Stamp {
            id: FileId::of(m),
            size: m.len(),
            mtime_ns: m.mtime() as i128 * 1_000_000_000 + m.mtime_nsec() as i128,
        }
    }
}

/// Opens a file for reading without following a symlink and without blocking (a FIFO
/// or a device opens at once and is then refused by the caller's type check).
pub fn open_nofollow(path: &Path) -> io::Result<fs::File> {
    fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path)
}

/// Renames `src` to `dst` unless `dst` exists (`Err(AlreadyExists)`); `Err(NotFound)`
/// when `src` is gone; `EXDEV` across file systems.
pub fn rename_noreplace(src: &Path, dst: &Path) -> io::Result<()> {
    match rustix::fs::renameat_with(CWD, src, CWD, dst, RenameFlags::NOREPLACE) {
        Ok(()) => Ok(()),
        // the file system does not know the flag: link (fails on an existing target),
        // then unlink
        Err(Errno::INVAL) | Err(Errno::NOSYS) => {
            fs::hard_link(src, dst)?;
            fs::remove_file(src).inspect_err(|_| {
                // someone else moved `src` away between our link and unlink: the file
                // is theirs; drop our link
                let _ = fs::remove_file(dst);
            })
        }
        Err(e) => Err(e.into()),
    }
}

/// Moves the file `src` to `dir/name` without replacing an existing file; across file
/// systems by the fsynced copy described in the module documentation, with `tmp_name`
/// the copy's temporary name in `dir`. `linked` runs once the file is at its target
/// (before the source of a copy is removed).
pub fn move_file(
    src: &Path,
    dir: &Path,
    name: &OsStr,
    tmp_name: &str,
    linked: &dyn Fn(),
) -> io::Result<()> {
    let dst = dir.join(name);
    match rename_noreplace(src, &dst) {
        Ok(()) => {
            linked();
            Ok(())
        }
        Err(e) if e.raw_os_error() == Some(libc::EXDEV) => {
            copy_across(src, dir, &dst, tmp_name)?;
            linked();
            fs::remove_file(src)?;
            if let Some(p) = src.parent() {
                fsync_dir(p)?;
            }
            Ok(())
        }
        Err(e) => Err(e),
    }
}

/// Copies `src` (a regular file, not followed) to `dst` in `dir` through `dir/tmp_name`:
/// copy, fsync, no-replace rename, fsync of `dir`. Keeps the permission bits and the
/// modification time.
fn copy_across(src: &Path, dir: &Path, dst: &Path, tmp_name: &str) -> io::Result<()> {
    let tmp = dir.join(tmp_name);
    let _ = fs::remove_file(&tmp);
    let r = (|| {
        let mut from = open_nofollow(src)?;
        let m = from.metadata()?;
        if !m.is_file() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "not a regular file",
            ));
        }
        let mut to = fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&tmp)?;
        io::copy(&mut from, &mut to)?;
        to.set_permissions(fs::Permissions::from_mode(m.mode() & 0o777))?;
        if let Ok(t) = m.modified() {
            let _ = to.set_modified(t);
        }
        to.sync_all()?;
        rename_noreplace(&tmp, dst)?;
        fsync_dir(dir)
    })();
    if r.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    r
}

/// True when two regular files have the same bytes (read without following links).
pub fn same_content(a: &Path, b: &Path) -> bool {
    use std::io::Read;
    let (Ok(fa), Ok(fb)) = (open_nofollow(a), open_nofollow(b)) else {
        return false;
    };
    match (fa.metadata(), fb.metadata()) {
        (Ok(ma), Ok(mb)) if ma.is_file() && mb.is_file() && ma.len() == mb.len() => {}
        _ => return false,
    }
    let (mut ra, mut rb) = (io::BufReader::new(fa), io::BufReader::new(fb));
    let (mut ba, mut bb) = (vec![0u8; 1 << 16], vec![0u8; 1 << 16]);
    loop {
        let n = match ra.read(&mut ba) {
            Ok(n) => n,
            Err(_) => return false,
        };
        if n == 0 {
            return rb.read(&mut bb[..1]).map(|m| m == 0).unwrap_or(false);
        }
        if rb.read_exact(&mut bb[..n]).is_err() || ba[..n] != bb[..n] {
            return false;
        }
    }
}

/// Puts `src` (a temporary file of ours) at `dst`: without replacing under
/// [`Collision::Timestamp`] (`Err(AlreadyExists)`), replacing atomically under
/// [`Collision::Overwrite`].
pub fn publish(src: &Path, dst: &Path, rule: Collision) -> io::Result<()> {
    match rule {
        Collision::Timestamp => rename_noreplace(src, dst),
        Collision::Overwrite => fs::rename(src, dst),
    }
}

/// Writes `bytes` as `path` durably: through `path.tmp` (a stale one removed first,
/// created anew with `mode`, never through a symlink), fsync, rename. On an error the
/// temporary file is removed. Returns the file, as written.
pub fn write_durably(path: &Path, bytes: &[u8], mode: u32) -> io::Result<fs::File> {
    use std::io::Write;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let _ = fs::remove_file(&tmp);
    let mut f = fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&tmp)?;
    let r = f
        .write_all(bytes)
        .and_then(|()| f.sync_all())
        .and_then(|()| fs::rename(&tmp, path));
    if r.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    r.map(|()| f)
}

/// A file name as it may be written into a journal line or a log: control and other
/// invisible characters (line breaks, bidirectional overrides, ...) and backslashes
/// escaped Rust-style (`\n`, `\u{202e}`, `\\`), bytes that are not UTF-8 as `\xNN`.
/// The result is one line of printable text, and two different names never show alike
/// (the escapes are the only backslashes).
pub fn shown(name: &OsStr) -> String {
    let mut out = String::with_capacity(name.len());
    for chunk in name.as_bytes().utf8_chunks() {
        for c in chunk.valid().chars() {
            match c {
                '"' | '\'' => out.push(c),
                c if c.is_control()
                    || matches!(c, '\u{2028}' | '\u{2029}' | '\u{200e}' | '\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}') =>
                {
                    out.extend(c.escape_unicode())
                }
                c => out.extend(c.escape_debug()),
            }
        }
        for b in chunk.invalid() {
            out.push_str(&format!("\\x{b:02x}"));
        }
    }
    out
}

/// Why the daemon cannot repair a file under this name, if it cannot: not UTF-8 (a
/// JSON log could not name it), or too long for its outputs' names.
pub fn name_problem(name: &OsStr) -> Option<String> {
    if name.to_str().is_none() {
        return Some("the file name is not valid UTF-8".to_string());
    }
    if name.len() > MAX_NAME {
        return Some(format!(
            "the file name has {} bytes; the daemon repairs names of at most {MAX_NAME} bytes (its outputs add a time stamp and `.repair.json`, and a file name holds at most {NAME_MAX} bytes)",
            name.len()
        ));
    }
    None
}

/// A name the daemon can use for a file it cannot repair under its own name: the
/// [`shown`] form, shortened to at most [`MAX_NAME`] bytes with its extension kept.
pub fn safe_name(name: &OsStr) -> String {
    let s = shown(name);
    if s.len() <= MAX_NAME && name_problem(OsStr::new(&s)).is_none() && !s.starts_with('.') {
        return s;
    }
    let s = s.trim_start_matches('.');
    let (stem, ext) = split_ext(s);
    let ext = if ext.len() <= 8 { ext } else { "" };
    if stem.len() + ext.len() <= MAX_NAME && !stem.is_empty() {
        return format!("{stem}{ext}");
    }
    let mut keep = (MAX_NAME - ext.len() - 3).min(stem.len()); // "..." marks the cut
    while !stem.is_char_boundary(keep) {
        keep -= 1;
    }
    format!("{}...{ext}", &stem[..keep])
}

/// Hex of a name's bytes (how a record keeps a name that may not be UTF-8).
pub fn hex(name: &OsStr) -> String {
    name.as_bytes().iter().map(|b| format!("{b:02x}")).collect()
}

/// The name back from [`hex`]; `None` when malformed or not a plain file name.
pub fn unhex(s: &str) -> Option<OsString> {
    if s.len() % 2 != 0 || s.is_empty() {
        return None;
    }
    let bytes: Option<Vec<u8>> = (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect();
    let bytes = bytes?;
    if bytes.contains(&b'/') || bytes.contains(&0) || bytes == b"." || bytes == b".." {
        return None;
    }
    use std::os::unix::ffi::OsStringExt;
    Some(OsString::from_vec(bytes))
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

/// The first candidate name, from the `skip`-th on, under which neither `dir/NAME` nor
/// `dir/NAME + suffix` (for each suffix) exists. Under [`Collision::Overwrite`], `name`
/// itself.
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
    fn rename_noreplace_never_overwrites() {
        let d = tempfile::tempdir().unwrap();
        let a = d.path().join("a");
        let b = d.path().join("b");
        fs::write(&a, "A").unwrap();
        fs::write(&b, "B").unwrap();
        let e = rename_noreplace(&a, &b).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::AlreadyExists);
        assert_eq!(fs::read_to_string(&b).unwrap(), "B");
        assert_eq!(fs::read_to_string(&a).unwrap(), "A");
        let c = d.path().join("c");
        rename_noreplace(&a, &c).unwrap();
        assert!(!a.exists());
        assert_eq!(fs::read_to_string(&c).unwrap(), "A");
        assert_eq!(
            rename_noreplace(&a, &d.path().join("e"))
                .unwrap_err()
                .kind(),
            io::ErrorKind::NotFound
        );
    }

    #[test]
    fn move_file_keeps_an_existing_target() {
        let d = tempfile::tempdir().unwrap();
        let dst = d.path().join("dst");
        fs::create_dir(&dst).unwrap();
        fs::write(dst.join("s.obj"), "old").unwrap();
        let src = d.path().join("s.obj");
        fs::write(&src, "new").unwrap();
        let hit = std::cell::Cell::new(false);
        let e = move_file(&src, &dst, OsStr::new("s.obj"), ".t", &|| hit.set(true));
        assert_eq!(e.unwrap_err().kind(), io::ErrorKind::AlreadyExists);
        assert!(!hit.get());
        move_file(&src, &dst, OsStr::new("s2.obj"), ".t", &|| hit.set(true)).unwrap();
        assert!(hit.get());
        assert_eq!(fs::read_to_string(dst.join("s2.obj")).unwrap(), "new");
        assert_eq!(fs::read_to_string(dst.join("s.obj")).unwrap(), "old");
        assert!(!src.exists());
    }

    #[test]
    fn copies_compare_by_content() {
        let d = tempfile::tempdir().unwrap();
        let (a, b, c) = (d.path().join("a"), d.path().join("b"), d.path().join("c"));
        fs::write(&a, "same").unwrap();
        fs::write(&b, "same").unwrap();
        fs::write(&c, "diff").unwrap();
        assert!(same_content(&a, &b));
        assert!(!same_content(&a, &c));
        assert!(!same_content(&a, &d.path().join("none")));
    }

    #[test]
    fn names_are_shown_on_one_line_and_kept_losslessly() {
        use std::os::unix::ffi::OsStrExt;
        assert_eq!(shown(OsStr::new("scan 01.obj")), "scan 01.obj");
        assert_eq!(shown(OsStr::new("a\nWARN b.obj")), "a\\u{a}WARN b.obj");
        assert_eq!(shown(OsStr::new("a\\b\u{202e}.obj")), "a\\\\b\\u{202e}.obj");
        assert_eq!(shown(OsStr::new("é\"'.obj")), "é\"'.obj");
        let bad = OsStr::from_bytes(b"bad\xff.obj");
        assert_eq!(shown(bad), "bad\\xff.obj");
        assert_eq!(unhex(&hex(bad)).as_deref(), Some(bad));
        assert_eq!(unhex("2f"), None, "a slash is never a name");
        assert_eq!(unhex("2e2e"), None);
        assert!(name_problem(bad).is_some());
        assert!(name_problem(OsStr::new("ok.obj")).is_none());
        let long = format!("{}.obj", "a".repeat(246));
        assert!(name_problem(OsStr::new(&long)).is_some());
        let safe = safe_name(OsStr::new(&long));
        assert!(
            safe.len() <= MAX_NAME && safe.ends_with("....obj"),
            "{safe}"
        );
        assert_eq!(safe_name(bad), "bad\\xff.obj");
        assert_eq!(safe_name(OsStr::new("x.obj")), "x.obj");
        let dotted = safe_name(OsStr::from_bytes(b".\xff.obj"));
        assert!(!dotted.starts_with('.'), "{dotted}");
    }
}
