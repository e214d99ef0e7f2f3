//! Stopping (SIGTERM/SIGINT: the grace period, the waiting jobs put back, the last
//! status) and reloading (SIGHUP: the config and the policy).

use super::child;
use super::claim;
use super::config::Settings;
use super::fsops::{self, shown};
use super::worker::{self, RunCtx};
use super::{sd, snapshot_policy, Daemon};
use sd_notify::NotifyState;
use std::sync::Arc;
use std::time::{Duration, Instant};

impl Daemon {
    pub(super) fn begin_stop(&mut self, why: &str) {
        if self.stopping.is_some() {
            if !self.cancelled {
                tracing::warn!("{why} again: killing the running repairs now");
                self.cancelled = true;
                let _ = self.cancel.send(true);
            }
            return;
        }
        let grace = self.settings.grace;
        self.stopping = Some(Instant::now() + grace);
        tracing::info!(
            "{why}: stopping; {} repairs running, up to {} s to finish",
            self.working.len(),
            grace.as_secs()
        );
        let usec = (grace + Duration::from_secs(10))
            .as_micros()
            .min(u32::MAX as u128) as u32;
        sd(&[
            NotifyState::Stopping,
            NotifyState::ExtendTimeoutUsec(usec),
            NotifyState::Status("stopping"),
        ]);
        self.put_back_waiting();
    }

    /// At shutdown: puts the waiting jobs that are only claimed back into the inbox
    /// (their failed attempts recorded); jobs further on stay for the next daemon.
    pub(super) fn put_back_waiting(&mut self) {
        while let Some((job, _)) = self.again.pop_front() {
            let name = job.shown();
            match worker::put_back_waiting(&self.ctx, &job) {
                Some(Ok(n)) => {
                    tracing::info!(file = %name, "{name}: put back into the inbox as {}", shown(&n))
                }
                Some(Err(e)) => {
                    tracing::error!(file = %name, "{name}: cannot put back into the inbox: {e}; it stays in {}", job.home.dir.display())
                }
                None => {
                    tracing::warn!(file = %name, "{name}: left in {} for the next daemon to finish", job.home.dir.display())
                }
            }
        }
        for p in std::mem::take(&mut self.sets) {
            let name = p.job.shown();
            match worker::put_back_waiting(&self.ctx, &p.job) {
                Some(Ok(n)) => {
                    tracing::info!(file = %name, "{name}: put back into the inbox as {} (its set was not complete)", shown(&n))
                }
                Some(Err(e)) => {
                    tracing::error!(file = %name, "{name}: cannot put back into the inbox: {e}; it stays in {}", p.job.home.dir.display())
                }
                None => {
                    tracing::warn!(file = %name, "{name}: left in {} for the next daemon", p.job.home.dir.display())
                }
            }
        }
    }

    pub(super) fn reload(&mut self) {
        if self.stopping.is_some() {
            return;
        }
        let mono = NotifyState::monotonic_usec_now().ok();
        let mut st = vec![NotifyState::Reloading];
        st.extend(mono);
        sd(&st);
        self.try_reload();
        sd(&[NotifyState::Ready]);
    }

    fn try_reload(&mut self) {
        let new = match Settings::load(&self.args) {
            Ok(s) => s,
            Err(e) => {
                tracing::error!("SIGHUP: the config is refused, the old one kept: {e:#}");
                return;
            }
        };
        let fixed = self.settings.restart_only_changes(&new);
        if !fixed.is_empty() {
            tracing::warn!(
                "SIGHUP: {} cannot change without a restart; kept",
                fixed.join(", ")
            );
        }
        let new = self.settings.reloaded(&new);
        if let Err(e) = child::probe_limits(new.memory_limit_mb) {
            tracing::error!("SIGHUP: the config is refused, the old one kept: {e:#}");
            return;
        }
        let (policy, text) = match snapshot_policy(&new, &self.home.tmp, self.generation + 1) {
            Ok(p) => p,
            Err(e) => {
                tracing::error!("SIGHUP: the policy is refused, the old one kept: {e:#}");
                return;
            }
        };
        self.generation += 1;
        self.policy_text = text;
        self.ctx = Arc::new(RunCtx {
            settings: new.clone(),
            policy,
            policy_source: new.policy.clone(),
            layout: self.ctx.layout.clone(),
            host: self.ctx.host.clone(),
            pid: self.ctx.pid,
            instance: self.ctx.instance.clone(),
            exe: self.ctx.exe.clone(),
            hooks: self.ctx.hooks.clone(),
            cores: self.ctx.cores,
            forward: self.ctx.forward.clone(),
        });
        self.settings = new;
        tracing::info!(policy = ?self.settings.policy, "SIGHUP: config and policy reloaded");
    }

    pub(super) fn shutdown(&mut self) {
        self.put_back_waiting();
        for h in std::iter::once(self.home.clone()).chain(self.adopted.drain(..)) {
            if !h.remove_if_empty() {
                tracing::warn!(
                    "files remain in {}: the next daemon finishes them",
                    h.dir.display()
                );
            }
        }
        claim::ledger_clean(&self.layout);
        let _ = fsops::fsync_dir(&self.layout.inbox);
        if let Some(ix) = self.index.as_mut() {
            ix.flush(true);
        }
        tracing::info!(
            repaired = self.repaired,
            failed = self.failed,
            "stopped: {}",
            self.status()
        );
    }
}
