//! The folders kept there: checked and recreated (with rate-limited errors), the
//! policy snapshot rewritten, the inbox rescanned, dead daemons' folders adopted.

use super::claim::{self, Home, Phase};
use super::queue::Seen;
use super::{Daemon, FOLDER_CHECK};
use anyhow::Result;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Instant;

impl Daemon {
    /// Checks that the folders are there (recreating the ones that vanished) and are
    /// still what they were (not the inbox). At most every second unless `force`.
    /// False while one cannot be had: then no file is claimed.
    pub(super) fn check_folders(&mut self, force: bool) -> bool {
        let now = Instant::now();
        if !force
            && self
                .folders_checked
                .is_some_and(|t| now.duration_since(t) < FOLDER_CHECK)
        {
            return self.folders_ok;
        }
        self.folders_checked = Some(now);
        let mut ok = true;
        let layout = self.layout.clone();
        for (what, p) in layout.named() {
            let key = format!("folder:{what}");
            match std::fs::symlink_metadata(p) {
                Ok(m) if m.is_dir() => {
                    self.error_over(&key, &format!("the {what} {} is back", p.display()))
                }
                Ok(_) => {
                    ok = false;
                    self.error_limited(&key, &format!("the {what} {} is not a folder any more (a file or a link in its place); no file is taken until it is one again", p.display()));
                }
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    match std::fs::create_dir_all(p) {
                        Ok(()) => {
                            tracing::warn!(
                                "the {what} {} had vanished: created again",
                                p.display()
                            );
                            if what == "inbox" {
                                if let Some(w) = self.watcher.as_mut() {
                                    if let Err(e) = w.rewatch() {
                                        tracing::error!(
                                            "cannot watch the inbox again: {e}; polling it"
                                        );
                                    }
                                }
                                self.rescan_flag.store(true, Ordering::SeqCst);
                            }
                        }
                        Err(e) => {
                            ok = false;
                            self.error_limited(&key, &format!("the {what} {} vanished and cannot be created again: {e}; no file is taken until it can", p.display()));
                        }
                    }
                }
                Err(e) => {
                    ok = false;
                    self.error_limited(&key, &format!("the {what} {}: {e}", p.display()));
                }
            }
        }
        if ok {
            if let Err(e) = self.layout.check_aliases() {
                ok = false;
                self.error_limited(
                    "aliases",
                    &format!("{e}; no file is taken until that changes"),
                );
            }
        }
        if ok {
            for p in [
                self.layout.processing_root.clone(),
                self.layout.tmp_root.clone(),
            ] {
                if let Err(e) = claim::make_private_dir(&p, 0o755) {
                    ok = false;
                    self.error_limited(
                        "private",
                        &format!("{e}; no file is taken until that changes"),
                    );
                }
            }
        }
        if ok && !self.home.intact() {
            // our folder went (with the inbox): a new one; files in the old one, if any,
            // are gone with it
            match Home::create(&self.layout, &self.id.tag()) {
                Ok(h) => {
                    tracing::warn!(
                        "this daemon's folder {} had vanished: created again",
                        h.dir.display()
                    );
                    self.home = Arc::new(h);
                }
                Err(e) => {
                    ok = false;
                    self.error_limited(
                        "home",
                        &format!("cannot create this daemon's folder again: {e}"),
                    );
                }
            }
        }
        if ok && !self.home.tmp.is_dir() {
            use std::os::unix::fs::DirBuilderExt;
            match std::fs::DirBuilder::new()
                .mode(0o700)
                .create(&self.home.tmp)
            {
                Ok(()) => {
                    tracing::warn!(
                        "the temporary folder {} had vanished: created again",
                        self.home.tmp.display()
                    );
                    if let Err(e) = self.write_policy_snapshot() {
                        ok = false;
                        self.error_limited(
                            "policy",
                            &format!("cannot store the policy snapshot again: {e}"),
                        );
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => {
                    ok = false;
                    self.error_limited(
                        "tmp",
                        &format!(
                            "cannot create the temporary folder {}: {e}",
                            self.home.tmp.display()
                        ),
                    );
                }
            }
        }
        self.folders_ok = ok;
        ok
    }

    /// Writes the current policy snapshot again (its folder was recreated).
    fn write_policy_snapshot(&mut self) -> Result<()> {
        if let (Some(text), Some(path)) = (&self.policy_text, &self.ctx.policy) {
            holefill::io::write_atomic(path, text.as_bytes())
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
        Ok(())
    }

    /// Lists the inbox, adopts the folders of dead daemons, tidies up.
    pub(super) fn rescan(&mut self) {
        self.last_scan = Instant::now();
        self.adopt_dead();
        claim::clean_staging(&self.layout);
        claim::clean_tmp(&self.layout);
        claim::ledger_clean(&self.layout);
        self.pending.overflowed = false;
        self.expect.clear();
        let now = Instant::now();
        match std::fs::read_dir(&self.layout.inbox) {
            Ok(rd) => {
                let mut listed = std::collections::HashSet::new();
                for e in rd.flatten() {
                    let name = e.file_name();
                    if claim::is_watched_name(&name) && !e.file_type().is_ok_and(|t| t.is_dir()) {
                        self.pending.note(&name, Seen::Scan, now);
                        if !claim::is_candidate_name(&name) {
                            listed.insert(name);
                        }
                    }
                }
                self.pending.retain_members(&listed);
            }
            Err(e) => {
                let msg = format!("cannot list the inbox {}: {e}", self.layout.inbox.display());
                self.error_limited("list", &msg);
            }
        }
    }

    /// Takes over the folders of daemons that died (their lock is free).
    fn adopt_dead(&mut self) {
        let Ok(rd) = std::fs::read_dir(&self.layout.processing_root) else {
            return;
        };
        let tags: Vec<String> = rd
            .flatten()
            .filter_map(|e| e.file_name().into_string().ok())
            .filter(|t| !t.starts_with('.'))
            .filter(|t| *t != self.home.tag && !self.adopted.iter().any(|h| h.tag == *t))
            .collect();
        for tag in tags {
            match Home::adopt(&self.layout, &tag) {
                Ok(Some(h)) => {
                    let h = Arc::new(h);
                    let jobs = claim::jobs_of(&h, &self.id);
                    if jobs.is_empty() {
                        if !h.remove_if_empty() {
                            tracing::warn!("{}: a dead daemon's folder with files that are not jobs; left alone", h.dir.display());
                        }
                        continue;
                    }
                    tracing::warn!(
                        "taking over {} files of a daemon that died ({})",
                        jobs.len(),
                        h.dir.display()
                    );
                    for job in jobs {
                        match &job.rec.phase {
                            Phase::Claimed => {
                                tracing::warn!(file = %job.shown(), attempts = job.rec.attempts, "{}: recovered from a daemon that died while repairing it", job.shown())
                            }
                            _ => {
                                tracing::warn!(file = %job.shown(), "{}: recovered from a daemon that died while publishing it; finishing that (not repaired again)", job.shown())
                            }
                        }
                        self.again.push_back((job, Instant::now()));
                    }
                    self.adopted.push(h);
                }
                Ok(None) => {}
                Err(msg) => {
                    self.error_limited(
                        &format!("foreign:{tag}"),
                        &format!("{msg}; its files are left alone"),
                    );
                }
            }
        }
    }

    /// Releases the adopted folders whose jobs are all done.
    pub(super) fn release_adopted(&mut self) {
        let busy = |tag: &str, d: &Daemon| {
            d.working.values().any(|(t, _)| t == tag)
                || d.drawing.values().any(|t| t == tag)
                || d.again.iter().any(|(j, _)| j.home.tag == tag)
                || d.sets.iter().any(|p| p.job.home.tag == tag)
        };
        let mut keep = Vec::new();
        for h in std::mem::take(&mut self.adopted) {
            if busy(&h.tag, self) || !h.remove_if_empty() {
                keep.push(h);
            }
        }
        self.adopted = keep;
    }
}
