//! The put-back ledger: the failed attempts and first-seen time of a file put back
//! into the inbox, by device and inode, resumed by its next claim.

use super::layout::{check_private, make_private_dir, Layout};
use super::write_durably;
use crate::daemon::fsops::{self, FileId, Stamp};
use serde::{Deserialize, Serialize};
use std::fs;
use std::io;
use std::path::PathBuf;
use std::time::Duration;

/// An entry of the put-back ledger.
#[derive(Debug, Serialize, Deserialize)]
struct Ledger {
    attempts: u32,
    received: String,
    size: u64,
    mtime_ns: i128,
}

pub(super) fn ledger_path(layout: &Layout, id: FileId) -> PathBuf {
    layout.ledger.join(format!("{}-{}.json", id.dev, id.ino))
}

/// The failed attempts and first-seen time of a file put back earlier (same inode,
/// size and modification time).
pub(super) fn ledger_get(layout: &Layout, s: &Stamp) -> Option<(u32, String)> {
    if check_private(&layout.ledger).is_err() {
        return None;
    }
    let f = fsops::open_nofollow(&ledger_path(layout, s.id)).ok()?;
    let l: Ledger = serde_json::from_reader(io::BufReader::new(f)).ok()?;
    (l.size == s.size && l.mtime_ns == s.mtime_ns).then_some((l.attempts, l.received))
}

pub(super) fn ledger_put(
    layout: &Layout,
    s: &Stamp,
    attempts: u32,
    received: &str,
) -> Result<(), String> {
    make_private_dir(&layout.ledger, 0o700)?;
    let l = Ledger {
        attempts,
        received: received.to_string(),
        size: s.size,
        mtime_ns: s.mtime_ns,
    };
    let bytes = serde_json::to_vec(&l).map_err(|e| e.to_string())?;
    write_durably(&ledger_path(layout, s.id), &bytes).map_err(|e| e.to_string())
}

/// Drops ledger entries of files no longer in the inbox (older than a minute, so that
/// a put-back in progress keeps its entry); removes the ledger folder when empty.
pub fn ledger_clean(layout: &Layout) {
    let Ok(rd) = fs::read_dir(&layout.ledger) else {
        return;
    };
    if check_private(&layout.ledger).is_err() {
        return;
    }
    let mut entries = Vec::new();
    for e in rd.flatten() {
        entries.push(e);
    }
    if entries.is_empty() {
        let _ = fs::remove_dir(&layout.ledger);
        return;
    }
    let inbox: std::collections::HashSet<u64> = fs::read_dir(&layout.inbox)
        .map(|rd| {
            use std::os::unix::fs::DirEntryExt;
            rd.flatten().map(|e| e.ino()).collect()
        })
        .unwrap_or_default();
    for e in entries {
        let n = e.file_name().to_string_lossy().into_owned();
        let ino = n
            .strip_suffix(".json")
            .and_then(|s| s.split_once('-'))
            .and_then(|(_, i)| i.parse::<u64>().ok());
        let old = e
            .metadata()
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .is_some_and(|a| a > Duration::from_secs(60));
        if old && ino.is_none_or(|i| !inbox.contains(&i)) {
            let _ = fs::remove_file(e.path());
        }
    }
}
