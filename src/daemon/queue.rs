//! The files waiting in the inbox, and when each is complete enough to take.
//!
//! A file is taken only when nobody holds it open and it has stopped changing:
//! - the inotify events count its opens (`IN_OPEN`) and closes (`IN_CLOSE_WRITE`,
//!   `IN_CLOSE_NOWRITE`); a write (`IN_MODIFY`) by a writer whose open was not seen
//!   counts as an open until its close. While the count is above zero the file waits;
//! - a file renamed into the inbox (`IN_MOVED_TO`) is complete at once; any other
//!   (created or written in place, or found by a scan with no event) once its size and
//!   modification time have not changed, and no event came, for the settle time;
//! - an empty file waits: a producer may create it first and write it later.
//!
//! The wait has a bound, `max_wait`: a file still held open, or still empty, after
//! that long without any change is taken anyway (an empty one then goes to the failed
//! folder as empty). Events lost to a queue overflow, and files already open when the
//! daemon started, cannot be counted: those files are judged by the settle time alone.
//! The daemon compares the file's identity, size and modification time when it claims
//! it and again after the repair, and puts it back to wait if it changed.
//!
//! Memory is bounded: at most `cap` names are remembered (later rescans find the
//! rest), and the order list is compacted when names leave it.

use super::claim::{is_candidate_name, is_watched_name};
use super::fsops::Stamp;
use std::collections::{HashMap, HashSet, VecDeque};
use std::ffi::{OsStr, OsString};
use std::fs;
use std::path::Path;
use std::time::{Duration, Instant, SystemTime};

/// What was learnt about a name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Seen {
    /// Listed by a scan.
    Scan,
    /// Created (or linked) in place.
    Created,
    /// Opened (for reading or writing).
    Opened,
    /// Written.
    Modified,
    /// Closed after writing.
    ClosedWrite,
    /// Closed, not written.
    ClosedRead,
    /// Its attributes changed (chmod, touch).
    Attrib,
    /// Renamed (or put back) into the inbox: complete.
    RenamedIn,
    /// Put back by the daemon because it changed while claimed: judge it afresh.
    Changed,
    /// Gone from the inbox.
    Removed,
}

#[derive(Clone, Debug)]
struct Entry {
    /// A mesh (taken on its own), not a file that may join a set.
    mesh: bool,
    received: SystemTime,
    renamed_in: bool,
    /// Opens seen and not yet closed.
    opens: u32,
    /// The last event that may have changed it (`None`: only seen by scans).
    last_event: Option<Instant>,
    stat: Option<Stamp>,
    stable_since: Instant,
    not_before: Option<Instant>,
}

/// A file ready to be claimed.
#[derive(Clone, Debug)]
pub struct Ready {
    pub name: OsString,
    /// When it was first seen.
    pub received: SystemTime,
    /// Identity, size and modification time as judged now.
    pub stamp: Stamp,
    /// Taken at the `max_wait` bound (still open, or empty), not because complete.
    pub waited_out: bool,
}

/// How a file that may join a set is judged now.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemberState {
    /// Not in the inbox.
    Missing,
    /// There, but not a regular file (a symlink, FIFO, ...): never taken.
    NotRegular,
    /// There, not complete yet (held open, changing, empty).
    NotYet,
    /// Complete, as of this stamp.
    Ready(Stamp),
}

/// What [`judge`] says of an entry.
enum Judged {
    Gone,
    NotYet,
    Ready { stamp: Stamp, waited_out: bool },
}

/// The waiting files, oldest first, at most `cap` of them: the meshes, and the other
/// files that may join a set (judged by the same rules when a set asks for them, never
/// taken on their own).
#[derive(Debug)]
pub struct Pending {
    order: VecDeque<OsString>,
    map: HashMap<OsString, Entry>,
    /// How many entries of `map` are meshes.
    meshes: usize,
    cap: usize,
    /// Names refused because the set was full (a rescan is due once there is room).
    pub overflowed: bool,
}

impl Pending {
    pub fn new(cap: usize) -> Pending {
        Pending {
            order: VecDeque::new(),
            map: HashMap::new(),
            meshes: 0,
            cap,
            overflowed: false,
        }
    }

    /// The meshes waiting.
    pub fn len(&self) -> usize {
        self.meshes
    }

    fn remove(&mut self, name: &OsStr) -> Option<Entry> {
        let e = self.map.remove(name);
        if e.as_ref().is_some_and(|e| e.mesh) {
            self.meshes -= 1;
        }
        e
    }

    /// Forgets the files that may join a set and are not in `listed` (the inbox as
    /// just listed): a member that left without an event.
    pub fn retain_members(&mut self, listed: &HashSet<OsString>) {
        self.map.retain(|n, e| e.mesh || listed.contains(n));
        self.compact();
    }

    /// Length of the order list (for tests of its bound).
    #[cfg(test)]
    fn order_len(&self) -> usize {
        self.order.len()
    }

    /// Keeps the order list within twice the set (plus a little): names that left the
    /// set, and repeats, are dropped.
    fn compact(&mut self) {
        if self.order.len() <= 2 * self.map.len() + 64 {
            return;
        }
        let mut seen = HashSet::with_capacity(self.map.len());
        let map = &self.map;
        self.order
            .retain(|n| map.contains_key(n) && seen.insert(n.clone()));
        self.order.shrink_to(2 * self.map.len() + 64);
    }

    /// Records what was seen of `name` (ignored unless it is a mesh file name).
    pub fn note(&mut self, name: &OsStr, seen: Seen, now: Instant) {
        if !is_watched_name(name) {
            return;
        }
        if seen == Seen::Removed {
            self.remove(name);
            self.compact();
            return;
        }
        if !self.map.contains_key(name) {
            if self.map.len() >= self.cap {
                self.overflowed = true;
                return;
            }
            self.order.push_back(name.to_owned());
            self.compact();
            let mesh = is_candidate_name(name);
            if mesh {
                self.meshes += 1;
            }
            self.map.insert(
                name.to_owned(),
                Entry {
                    mesh,
                    received: SystemTime::now(),
                    renamed_in: false,
                    opens: 0,
                    last_event: None,
                    stat: None,
                    stable_since: now,
                    not_before: None,
                },
            );
        }
        let Some(e) = self.map.get_mut(name) else {
            return;
        };
        match seen {
            Seen::Scan | Seen::Removed => {}
            Seen::Created => {
                e.renamed_in = false;
                e.last_event = Some(now);
            }
            Seen::Opened => e.opens = e.opens.saturating_add(1),
            Seen::Modified => {
                // a writer we did not see open (before the daemon started, or lost
                // events) holds it open until its close
                e.opens = e.opens.max(1);
                e.renamed_in = false;
                e.last_event = Some(now);
            }
            Seen::ClosedWrite => {
                e.opens = e.opens.saturating_sub(1);
                e.last_event = Some(now);
            }
            Seen::ClosedRead => e.opens = e.opens.saturating_sub(1),
            Seen::Attrib => e.last_event = Some(now),
            Seen::RenamedIn => {
                e.opens = 0;
                e.renamed_in = true;
                e.last_event = Some(now);
            }
            Seen::Changed => {
                e.opens = 0;
                e.renamed_in = false;
                e.stat = None;
                e.stable_since = now;
                e.last_event = Some(now);
            }
        }
    }

    /// Do not take `name` before `at` (back-off after a retryable failure).
    pub fn defer(&mut self, name: &OsStr, at: Instant) {
        if let Some(e) = self.map.get_mut(name) {
            e.not_before = Some(at);
        }
    }

    /// Events may have been lost: forget the open counts (judge by stat alone).
    pub fn forget_events(&mut self) {
        for e in self.map.values_mut() {
            e.opens = 0;
        }
    }

    /// The oldest waiting mesh that is ready, removed from the set; names that are no
    /// longer in the inbox are dropped on the way.
    pub fn take_ready(
        &mut self,
        inbox: &Path,
        settle: Duration,
        max_wait: Duration,
        now: Instant,
    ) -> Option<Ready> {
        let mut i = 0;
        while i < self.order.len() {
            let name = self.order[i].clone();
            let Some(e) = self.map.get_mut(&name) else {
                self.order.remove(i);
                continue;
            };
            if !e.mesh {
                i += 1;
                continue;
            }
            match judge(e, &inbox.join(&name), settle, max_wait, now) {
                Judged::Gone => {
                    self.remove(&name);
                    self.order.remove(i);
                }
                Judged::NotYet => i += 1,
                Judged::Ready { stamp, waited_out } => {
                    let received = e.received;
                    self.remove(&name);
                    self.order.remove(i);
                    return Some(Ready {
                        name,
                        received,
                        stamp,
                        waited_out,
                    });
                }
            }
        }
        None
    }

    /// How the file `name`, asked for by a set, is judged now (by the rules of a
    /// mesh). A file not noted yet (its events lost, or older than the daemon) is
    /// noted now and judged by its stat.
    pub fn member_state(
        &mut self,
        inbox: &Path,
        name: &OsStr,
        settle: Duration,
        max_wait: Duration,
        now: Instant,
    ) -> MemberState {
        let path = inbox.join(name);
        match fs::symlink_metadata(&path) {
            Ok(m) if m.is_file() => {}
            Ok(_) => return MemberState::NotRegular,
            Err(_) => {
                self.remove(name);
                return MemberState::Missing;
            }
        }
        if !self.map.contains_key(name) {
            self.note(name, Seen::Scan, now);
        }
        let Some(e) = self.map.get_mut(name) else {
            // the set of names is full: judged on its own
            return MemberState::NotYet;
        };
        match judge(e, &path, settle, max_wait, now) {
            Judged::Gone => {
                self.remove(name);
                MemberState::Missing
            }
            Judged::NotYet => MemberState::NotYet,
            Judged::Ready { stamp, .. } => MemberState::Ready(stamp),
        }
    }
}

/// Judges one entry (see the module documentation): gone, not yet, or ready.
fn judge(e: &mut Entry, path: &Path, settle: Duration, max_wait: Duration, now: Instant) -> Judged {
    let quiet = e
        .last_event
        .map_or(Duration::MAX, |t| now.saturating_duration_since(t));
    // cannot be ready yet whatever its stat says: spare the system call (a change is
    // caught by the stat at the moment it could be taken)
    if e.not_before.is_some_and(|t| t > now) {
        return Judged::NotYet;
    }
    if e.stat.is_some() {
        let stable = now.saturating_duration_since(e.stable_since);
        let too_soon = if e.opens > 0 {
            quiet.min(stable) < max_wait
        } else {
            !e.renamed_in && (stable < settle || quiet < settle)
        };
        if too_soon {
            return Judged::NotYet;
        }
    }
    let md = match fs::symlink_metadata(path) {
        Ok(m) if !m.is_dir() => m,
        // gone (taken by another daemon, removed), or a directory (never taken)
        _ => return Judged::Gone,
    };
    let st = Stamp::of(&md);
    if e.stat != Some(st) {
        let first = e.stat.is_none();
        e.stat = Some(st);
        e.stable_since = if first {
            // already unchanged for as long as its modification time says
            let mtime = md.modified().unwrap_or(SystemTime::UNIX_EPOCH);
            let age = SystemTime::now().duration_since(mtime).unwrap_or_default();
            now.checked_sub(age.min(max_wait.max(settle)))
                .unwrap_or(now)
        } else {
            now
        };
    }
    let stable = now.saturating_duration_since(e.stable_since);
    let empty = md.is_file() && md.len() == 0;
    let (ready, waited_out) = if e.opens > 0 || empty {
        let r = quiet.min(stable) >= max_wait;
        (r, r)
    } else if e.renamed_in {
        (true, false)
    } else {
        (stable >= settle && quiet >= settle, false)
    };
    if ready {
        Judged::Ready {
            stamp: st,
            waited_out,
        }
    } else {
        Judged::NotYet
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn os(s: &str) -> &OsStr {
        OsStr::new(s)
    }
    const LONG: Duration = Duration::from_secs(3600);

    fn take(p: &mut Pending, d: &Path, settle: Duration, t: Instant) -> Option<String> {
        p.take_ready(d, settle, LONG, t)
            .map(|r| r.name.to_string_lossy().into_owned())
    }

    #[test]
    fn renamed_in_is_ready_at_once_written_in_place_after_settle_and_close() {
        let d = tempfile::tempdir().unwrap();
        let settle = Duration::from_millis(200);
        let mut p = Pending::new(10);
        let t = Instant::now();
        fs::write(d.path().join("a.obj"), "x").unwrap();
        fs::write(d.path().join("b.obj"), "x").unwrap();
        p.note(os("a.obj"), Seen::RenamedIn, t);
        p.note(os("b.obj"), Seen::Created, t);
        p.note(os("b.obj"), Seen::Opened, t);
        p.note(os("b.obj"), Seen::Modified, t);
        p.note(os("c.part"), Seen::Modified, t);
        assert_eq!(p.len(), 2);
        assert_eq!(take(&mut p, d.path(), settle, t).as_deref(), Some("a.obj"));
        // b: open for writing, however long
        assert!(take(&mut p, d.path(), settle, t + settle * 100).is_none());
        p.note(os("b.obj"), Seen::ClosedWrite, t + settle * 100);
        assert!(
            take(&mut p, d.path(), settle, t + settle * 100).is_none(),
            "closed, but not quiet for the settle time"
        );
        assert_eq!(
            take(&mut p, d.path(), settle, t + settle * 102).as_deref(),
            Some("b.obj")
        );
    }

    #[test]
    fn a_reader_holds_it_too_and_an_empty_file_waits() {
        let d = tempfile::tempdir().unwrap();
        let settle = Duration::from_millis(100);
        let mut p = Pending::new(10);
        let t = Instant::now();
        fs::write(d.path().join("e.obj"), "").unwrap();
        p.note(os("e.obj"), Seen::RenamedIn, t);
        assert!(
            take(&mut p, d.path(), settle, t + settle * 50).is_none(),
            "empty"
        );
        fs::write(d.path().join("e.obj"), "v 0 0 0").unwrap();
        p.note(os("e.obj"), Seen::Opened, t + settle * 51);
        p.note(os("e.obj"), Seen::Modified, t + settle * 51);
        assert!(
            take(&mut p, d.path(), settle, t + settle * 60).is_none(),
            "open"
        );
        p.note(os("e.obj"), Seen::ClosedWrite, t + settle * 60);
        p.note(os("e.obj"), Seen::Opened, t + settle * 60); // a reader
        assert!(take(&mut p, d.path(), settle, t + settle * 70).is_none());
        p.note(os("e.obj"), Seen::ClosedRead, t + settle * 70);
        // its new size is seen now: unchanged from here for the settle time
        assert!(take(&mut p, d.path(), settle, t + settle * 72).is_none());
        assert_eq!(
            take(&mut p, d.path(), settle, t + settle * 74).as_deref(),
            Some("e.obj")
        );
    }

    #[test]
    fn members_are_judged_when_asked_never_taken_alone() {
        let d = tempfile::tempdir().unwrap();
        let settle = Duration::from_millis(100);
        let mut p = Pending::new(10);
        let t = Instant::now();
        fs::write(d.path().join("s.mtl"), "newmtl a").unwrap();
        fs::write(d.path().join("t.jpg"), "jpg").unwrap();
        p.note(os("s.mtl"), Seen::RenamedIn, t);
        p.note(os("t.jpg"), Seen::Created, t);
        p.note(os("t.jpg"), Seen::Opened, t);
        p.note(os(".x.jpg"), Seen::RenamedIn, t);
        assert_eq!(p.len(), 0, "members are not meshes waiting");
        assert!(take(&mut p, d.path(), settle, t + settle * 10).is_none());
        let st = |p: &mut Pending, n: &str, at| p.member_state(d.path(), os(n), settle, LONG, at);
        assert!(matches!(st(&mut p, "s.mtl", t), MemberState::Ready(_)));
        assert_eq!(
            st(&mut p, "t.jpg", t + settle * 10),
            MemberState::NotYet,
            "held open"
        );
        p.note(os("t.jpg"), Seen::ClosedWrite, t + settle * 10);
        assert_eq!(
            st(&mut p, "t.jpg", t + settle * 10 + settle / 2),
            MemberState::NotYet,
            "settling"
        );
        assert!(matches!(
            st(&mut p, "t.jpg", t + settle * 13),
            MemberState::Ready(_)
        ));
        assert_eq!(st(&mut p, "none.jpg", t), MemberState::Missing);
        std::os::unix::fs::symlink("/etc/passwd", d.path().join("l.jpg")).unwrap();
        assert_eq!(st(&mut p, "l.jpg", t), MemberState::NotRegular);
        // a file never noted (its events lost) is judged by its stat
        fs::write(d.path().join("u.png"), "png").unwrap();
        let later = Instant::now() + settle * 50;
        assert_eq!(
            st(&mut p, "u.png", later),
            MemberState::NotYet,
            "just written"
        );
        assert!(matches!(
            st(&mut p, "u.png", later + settle * 2),
            MemberState::Ready(_)
        ));
        p.retain_members(&HashSet::new());
        assert_eq!(p.map.len(), 0, "members not listed are forgotten");
    }

    #[test]
    fn the_wait_is_bounded() {
        let d = tempfile::tempdir().unwrap();
        let settle = Duration::from_millis(100);
        let max_wait = Duration::from_secs(2);
        let mut p = Pending::new(10);
        let t = Instant::now();
        fs::write(d.path().join("e.obj"), "").unwrap();
        p.note(os("e.obj"), Seen::Created, t);
        assert!(p.take_ready(d.path(), settle, max_wait, t).is_none());
        let r = p
            .take_ready(d.path(), settle, max_wait, t + max_wait * 2)
            .unwrap();
        assert!(r.waited_out);
        assert_eq!(r.stamp.size, 0);
    }

    #[test]
    fn scanned_files_are_judged_by_stat() {
        let d = tempfile::tempdir().unwrap();
        let settle = Duration::from_millis(300);
        let mut p = Pending::new(10);
        let t = Instant::now();
        fs::write(d.path().join("a.obj"), "x").unwrap();
        p.note(os("a.obj"), Seen::Scan, t);
        // just written: its modification time is recent
        assert!(take(&mut p, d.path(), settle, t).is_none());
        // it grows
        fs::write(d.path().join("a.obj"), "xy").unwrap();
        let t2 = t + settle;
        assert!(take(&mut p, d.path(), settle, t2).is_none());
        assert!(take(&mut p, d.path(), settle, t2 + settle / 2).is_none());
        assert_eq!(
            take(&mut p, d.path(), settle, t2 + settle * 2).as_deref(),
            Some("a.obj")
        );
    }

    #[test]
    fn gone_files_are_dropped_and_the_bounds_hold() {
        let d = tempfile::tempdir().unwrap();
        let mut p = Pending::new(2);
        let t = Instant::now();
        for n in ["a.obj", "b.obj", "c.obj"] {
            p.note(os(n), Seen::RenamedIn, t);
        }
        assert_eq!(p.len(), 2);
        assert!(p.overflowed);
        assert!(take(&mut p, d.path(), Duration::ZERO, t).is_none());
        assert_eq!(p.len(), 0);
        // names that come and go never pile up in the order list
        let mut p = Pending::new(100);
        for i in 0..100_000 {
            let n = format!("f{i}.obj");
            p.note(os(&n), Seen::Created, t);
            p.note(os(&n), Seen::Removed, t);
        }
        assert_eq!(p.len(), 0);
        assert!(p.order_len() <= 64, "{}", p.order_len());
    }

    #[test]
    fn directories_are_never_taken() {
        let d = tempfile::tempdir().unwrap();
        fs::create_dir(d.path().join("dir.obj")).unwrap();
        let mut p = Pending::new(10);
        let t = Instant::now();
        p.note(os("dir.obj"), Seen::Changed, t);
        assert!(take(&mut p, d.path(), Duration::ZERO, t + LONG).is_none());
        assert_eq!(p.len(), 0);
    }

    #[test]
    fn deferred_files_wait() {
        let d = tempfile::tempdir().unwrap();
        fs::write(d.path().join("a.obj"), "x").unwrap();
        let mut p = Pending::new(2);
        let t = Instant::now();
        p.note(os("a.obj"), Seen::RenamedIn, t);
        p.defer(os("a.obj"), t + Duration::from_secs(5));
        assert!(take(&mut p, d.path(), Duration::ZERO, t).is_none());
        assert!(take(&mut p, d.path(), Duration::ZERO, t + Duration::from_secs(6)).is_some());
    }
}
