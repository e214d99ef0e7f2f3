//! The inbox's change events, from inotify (the `inotify` crate, the one `notify` is
//! built on: `notify`'s watcher does not subscribe to `IN_CLOSE_NOWRITE`, and the
//! queue counts opens and closes of every kind to know whether a file is still open).
//!
//! A thread reads the events and sends them, for mesh file names only, into a bounded
//! channel; when the channel is full they are dropped and a rescan is asked for (so
//! memory stays bounded), as on the kernel's own queue overflow. The loss of the
//! watched folder itself (removed, moved, unmounted) is reported so that the daemon
//! recreates the inbox and watches it again.

use super::claim::is_watched_name;
use super::queue::Seen;
use inotify::{EventMask, Inotify, WatchMask, Watches};
use std::ffi::OsString;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use tokio::sync::mpsc;

/// One event of the inbox.
#[derive(Debug)]
pub enum Ev {
    /// Something happened to a file of the inbox.
    File(OsString, Seen),
    /// Events were lost (the kernel's queue overflowed).
    Overflow,
    /// The inbox itself was removed, moved or unmounted.
    InboxGone,
    /// Reading events failed for good.
    Error(String),
}

fn mask() -> WatchMask {
    WatchMask::CREATE
        | WatchMask::OPEN
        | WatchMask::MODIFY
        | WatchMask::CLOSE_WRITE
        | WatchMask::CLOSE_NOWRITE
        | WatchMask::ATTRIB
        | WatchMask::MOVED_FROM
        | WatchMask::MOVED_TO
        | WatchMask::DELETE
        | WatchMask::DELETE_SELF
        | WatchMask::MOVE_SELF
        | WatchMask::ONLYDIR
        | WatchMask::EXCL_UNLINK
}

/// The watch on the inbox (to watch it again once it is recreated).
pub struct Watcher {
    watches: Watches,
    inbox: PathBuf,
}

impl Watcher {
    /// Watches `inbox`; events arrive on the receiver (at most `cap` queued; beyond
    /// that `overflow` is set).
    pub fn start(
        inbox: &Path,
        cap: usize,
        overflow: Arc<AtomicBool>,
    ) -> io::Result<(Watcher, mpsc::Receiver<Ev>)> {
        let mut ino = Inotify::init()?;
        let mut watches = ino.watches();
        watches.add(inbox, mask())?;
        let (tx, rx) = mpsc::channel(cap);
        std::thread::Builder::new()
            .name("inbox-events".into())
            .spawn(move || {
                let mut buf = vec![0u8; 64 * 1024];
                loop {
                    let events = match ino.read_events_blocking(&mut buf) {
                        Ok(e) => e,
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                        Err(e) => {
                            let _ = tx.blocking_send(Ev::Error(e.to_string()));
                            return;
                        }
                    };
                    for e in events {
                        let Some(ev) = map(e.mask, e.name) else {
                            continue;
                        };
                        if tx.try_send(ev).is_err() {
                            if tx.is_closed() {
                                return;
                            }
                            overflow.store(true, Ordering::SeqCst);
                        }
                    }
                }
            })?;
        Ok((
            Watcher {
                watches,
                inbox: inbox.to_path_buf(),
            },
            rx,
        ))
    }

    /// Watches the inbox again (after it was recreated).
    pub fn rewatch(&mut self) -> io::Result<()> {
        self.watches.add(&self.inbox, mask()).map(|_| ())
    }
}

fn map(m: EventMask, name: Option<&std::ffi::OsStr>) -> Option<Ev> {
    if m.contains(EventMask::Q_OVERFLOW) {
        return Some(Ev::Overflow);
    }
    if m.intersects(
        EventMask::DELETE_SELF | EventMask::MOVE_SELF | EventMask::IGNORED | EventMask::UNMOUNT,
    ) {
        return Some(Ev::InboxGone);
    }
    let name = name?;
    if m.contains(EventMask::ISDIR) || !is_watched_name(name) {
        return None;
    }
    let seen = if m.contains(EventMask::MOVED_TO) {
        Seen::RenamedIn
    } else if m.intersects(EventMask::MOVED_FROM | EventMask::DELETE) {
        Seen::Removed
    } else if m.contains(EventMask::CREATE) {
        Seen::Created
    } else if m.contains(EventMask::OPEN) {
        Seen::Opened
    } else if m.contains(EventMask::MODIFY) {
        Seen::Modified
    } else if m.contains(EventMask::CLOSE_WRITE) {
        Seen::ClosedWrite
    } else if m.contains(EventMask::CLOSE_NOWRITE) {
        Seen::ClosedRead
    } else if m.contains(EventMask::ATTRIB) {
        Seen::Attrib
    } else {
        return None;
    };
    Some(Ev::File(name.to_owned(), seen))
}
