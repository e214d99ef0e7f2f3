//! The files waiting in the inbox, and when each is complete enough to take.
//!
//! A file renamed in (an `IN_MOVED_TO` event) is complete at once. A file written in
//! place is taken only when its writer has closed it (close-write event, where the
//! platform reports one) and its size and modification time have not changed for the
//! settle time. A file found by a scan (start-up, timer, overflow, polling) with no
//! event is judged by size and modification time alone: taken once its modification
//! time is older than the settle time and its size stays put. A create or write event
//! not followed by close-write (a writer that holds the file open) blocks it, for at
//! most ten settle times of silence (a `link(2)` into the inbox gives a create event and
//! no close).

use super::claim::is_candidate_name;
use std::collections::{HashMap, VecDeque};
use std::fs;
use std::path::Path;
use std::time::{Duration, Instant, SystemTime};

/// What was learnt about a name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Seen {
    /// Listed by a scan.
    Scan,
    /// Created (or linked) in place: complete once quiet for the settle time.
    Created,
    /// Written in place (open for writing until closed).
    Written,
    /// Closed after writing.
    Closed,
    /// Renamed (or put back) into the inbox: complete.
    RenamedIn,
    /// Gone from the inbox.
    Removed,
}

#[derive(Clone, Debug)]
struct Entry {
    received: SystemTime,
    renamed_in: bool,
    open_write: bool,
    /// The last create/write/close/rename event (`None`: only seen by scans).
    last_event: Option<Instant>,
    stat: Option<(u64, SystemTime)>,
    stable_since: Instant,
    not_before: Option<Instant>,
}

/// The waiting files, oldest first, at most `cap` of them.
#[derive(Debug)]
pub struct Pending {
    order: VecDeque<String>,
    map: HashMap<String, Entry>,
    cap: usize,
    /// Names refused because the set was full (a rescan is due once there is room).
    pub overflowed: bool,
}

impl Pending {
    pub fn new(cap: usize) -> Pending {
        Pending {
            order: VecDeque::new(),
            map: HashMap::new(),
            cap,
            overflowed: false,
        }
    }

    pub fn len(&self) -> usize {
        self.map.len()
    }

    /// Records what was seen of `name` (ignored unless it is a mesh file name).
    pub fn note(&mut self, name: &str, seen: Seen, now: Instant) {
        if !is_candidate_name(name) {
            return;
        }
        if seen == Seen::Removed {
            self.map.remove(name);
            return;
        }
        if !self.map.contains_key(name) {
            if self.map.len() >= self.cap {
                self.overflowed = true;
                return;
            }
            self.order.push_back(name.to_string());
            self.map.insert(
                name.to_string(),
                Entry {
                    received: SystemTime::now(),
                    renamed_in: false,
                    open_write: false,
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
            Seen::Written => {
                e.open_write = true;
                e.renamed_in = false;
                e.last_event = Some(now);
            }
            Seen::Closed => {
                e.open_write = false;
                e.last_event = Some(now);
            }
            Seen::RenamedIn => {
                e.open_write = false;
                e.renamed_in = true;
                e.last_event = Some(now);
            }
        }
    }

    /// Do not take `name` before `at` (back-off after a retryable failure).
    pub fn defer(&mut self, name: &str, at: Instant) {
        if let Some(e) = self.map.get_mut(name) {
            e.not_before = Some(at);
        }
    }

    /// Events may have been lost: forget what they said (judge by stat alone).
    pub fn forget_events(&mut self) {
        for e in self.map.values_mut() {
            e.open_write = false;
        }
    }

    /// The oldest waiting file that is complete, removed from the set; names that are no
    /// longer in the inbox are dropped on the way. `received` is when it was first seen.
    pub fn take_ready(
        &mut self,
        inbox: &Path,
        settle: Duration,
        now: Instant,
    ) -> Option<(String, SystemTime)> {
        let mut i = 0;
        while i < self.order.len() {
            let name = self.order[i].clone();
            let Some(e) = self.map.get_mut(&name) else {
                self.order.remove(i);
                continue;
            };
            if e.not_before.is_some_and(|t| t > now) {
                i += 1;
                continue;
            }
            // cannot be ready yet whatever its stat says: spare the system call (a
            // change is caught by the stat at the moment it could be taken)
            let quiet = e
                .last_event
                .map_or(Duration::MAX, |t| now.saturating_duration_since(t));
            let complete = e.renamed_in && !e.open_write;
            let too_soon = e.stat.is_some()
                && !complete
                && ((e.open_write && quiet < settle * 10)
                    || now.saturating_duration_since(e.stable_since) < settle
                    || quiet < settle);
            if too_soon {
                i += 1;
                continue;
            }
            let md = match fs::symlink_metadata(inbox.join(&name)) {
                Ok(m) if m.is_file() => m,
                _ => {
                    // gone (taken by another daemon, removed) or not a regular file
                    self.map.remove(&name);
                    self.order.remove(i);
                    continue;
                }
            };
            let mtime = md.modified().unwrap_or(SystemTime::UNIX_EPOCH);
            let st = (md.len(), mtime);
            if e.stat != Some(st) {
                let first = e.stat.is_none();
                e.stat = Some(st);
                e.stable_since = if first {
                    // already unchanged for as long as its modification time says
                    let age = SystemTime::now().duration_since(mtime).unwrap_or_default();
                    now.checked_sub(age.min(settle)).unwrap_or(now)
                } else {
                    now
                };
            }
            let quiet = e
                .last_event
                .map_or(Duration::MAX, |t| now.saturating_duration_since(t));
            let stable = now.saturating_duration_since(e.stable_since);
            let ready = if e.renamed_in && !e.open_write {
                true
            } else if e.open_write && quiet < settle * 10 {
                false
            } else {
                stable >= settle && quiet >= settle.min(stable)
            };
            if ready {
                let received = e.received;
                self.map.remove(&name);
                self.order.remove(i);
                return Some((name, received));
            }
            i += 1;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renamed_in_is_ready_at_once_written_in_place_after_settle_and_close() {
        let d = tempfile::tempdir().unwrap();
        let settle = Duration::from_millis(200);
        let mut p = Pending::new(10);
        let t = Instant::now();
        fs::write(d.path().join("a.obj"), "x").unwrap();
        fs::write(d.path().join("b.obj"), "x").unwrap();
        p.note("a.obj", Seen::RenamedIn, t);
        p.note("b.obj", Seen::Written, t);
        p.note("c.part", Seen::Written, t);
        assert_eq!(p.len(), 2);
        assert_eq!(
            p.take_ready(d.path(), settle, t).map(|x| x.0),
            Some("a.obj".into())
        );
        // b: open for writing
        assert!(p.take_ready(d.path(), settle, t + settle * 2).is_none());
        p.note("b.obj", Seen::Closed, t + settle * 2);
        assert!(
            p.take_ready(d.path(), settle, t + settle * 2).is_none(),
            "closed, but not quiet for the settle time"
        );
        assert_eq!(
            p.take_ready(d.path(), settle, t + settle * 4).map(|x| x.0),
            Some("b.obj".into())
        );
    }

    #[test]
    fn scanned_files_are_judged_by_stat() {
        let d = tempfile::tempdir().unwrap();
        let settle = Duration::from_millis(300);
        let mut p = Pending::new(10);
        let t = Instant::now();
        fs::write(d.path().join("a.obj"), "x").unwrap();
        p.note("a.obj", Seen::Scan, t);
        // just written: its modification time is recent
        assert!(p.take_ready(d.path(), settle, t).is_none());
        // it grows
        fs::write(d.path().join("a.obj"), "xy").unwrap();
        let t2 = t + settle;
        assert!(p.take_ready(d.path(), settle, t2).is_none());
        assert!(p.take_ready(d.path(), settle, t2 + settle / 2).is_none());
        assert_eq!(
            p.take_ready(d.path(), settle, t2 + settle * 2).map(|x| x.0),
            Some("a.obj".into())
        );
    }

    #[test]
    fn gone_files_are_dropped_and_the_cap_holds() {
        let d = tempfile::tempdir().unwrap();
        let mut p = Pending::new(2);
        let t = Instant::now();
        for n in ["a.obj", "b.obj", "c.obj"] {
            p.note(n, Seen::RenamedIn, t);
        }
        assert_eq!(p.len(), 2);
        assert!(p.overflowed);
        assert!(p.take_ready(d.path(), Duration::ZERO, t).is_none());
        assert_eq!(p.len(), 0);
    }

    #[test]
    fn deferred_files_wait() {
        let d = tempfile::tempdir().unwrap();
        fs::write(d.path().join("a.obj"), "x").unwrap();
        let mut p = Pending::new(2);
        let t = Instant::now();
        p.note("a.obj", Seen::RenamedIn, t);
        p.defer("a.obj", t + Duration::from_secs(5));
        assert!(p.take_ready(d.path(), Duration::ZERO, t).is_none());
        assert!(p
            .take_ready(d.path(), Duration::ZERO, t + Duration::from_secs(6))
            .is_some());
    }
}
