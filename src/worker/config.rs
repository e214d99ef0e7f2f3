//! The queue's names and settings: the `[nats]` section of `config/holefill.toml`
//! (every key documented there), overridden by flags, resolved into [`Names`] and
//! [`QueueSettings`].

use anyhow::{bail, Result};
use serde::Deserialize;
use std::time::Duration;

/// The `[nats]` section as written (every key optional).
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct NatsFile {
    pub url: Option<String>,
    pub stream: Option<String>,
    pub subject: Option<String>,
    pub consumer: Option<String>,
    pub scans_bucket: Option<String>,
    pub results_bucket: Option<String>,
    pub failed_bucket: Option<String>,
    pub done_stream: Option<String>,
    pub done_subject: Option<String>,
    pub results_consumer: Option<String>,
    pub replicas: Option<usize>,
    pub max_deliver: Option<u32>,
    pub ack_wait_secs: Option<u64>,
    pub backoff_secs: Option<u64>,
    pub backoff_max_secs: Option<u64>,
    pub duplicate_window_secs: Option<u64>,
    pub max_age_days: Option<u64>,
    /// `holefill worker` serves Prometheus metrics here (`HOST:PORT` or a port on
    /// loopback); off when absent. (The daemon's own key is the top-level `metrics`.)
    pub worker_metrics: Option<String>,
}

/// Every name on the server, each configurable.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Names {
    /// The work-queue stream and its subject.
    pub stream: String,
    pub subject: String,
    /// The workers' shared durable pull consumer.
    pub consumer: String,
    /// Object stores: submitted files, repaired results, failed scans with logs.
    pub scans: String,
    pub results: String,
    pub failed: String,
    /// The stream of notifications "this scan is done" and its subject.
    pub done_stream: String,
    pub done_subject: String,
    /// The durable consumer of `holefill results` on the done stream.
    pub results_consumer: String,
}

/// How the streams, buckets and consumer are created, and the retry rule.
#[derive(Clone, Debug, PartialEq)]
pub struct QueueSettings {
    pub replicas: usize,
    /// Repair attempts of one scan (deliveries ending in a crash, a kill, a time-out or
    /// an I/O error) before it fails. The consumer delivers once more than this, so
    /// that a scan whose worker was killed on every attempt is failed, not stranded.
    pub max_deliver: u32,
    /// A delivery with no acknowledgement (nor progress) for this long is redelivered.
    pub ack_wait: Duration,
    /// First back-off after a retryable failure; doubled each delivery, up to the max.
    pub backoff: Duration,
    pub backoff_max: Duration,
    /// Submissions of one scan (same name, same content) within this window are one.
    pub duplicate_window: Duration,
    /// Objects and notifications older than this are removed; `None`: kept.
    pub max_age: Option<Duration>,
}

impl NatsFile {
    /// The names, with the defaults.
    pub fn names(&self) -> Result<Names> {
        let pick = |v: &Option<String>, d: &str| v.clone().unwrap_or_else(|| d.to_string());
        let n = Names {
            stream: pick(&self.stream, "HOLEFILL_JOBS"),
            subject: pick(&self.subject, "holefill.jobs"),
            consumer: pick(&self.consumer, "holefill-workers"),
            scans: pick(&self.scans_bucket, "holefill-scans"),
            results: pick(&self.results_bucket, "holefill-results"),
            failed: pick(&self.failed_bucket, "holefill-failed"),
            done_stream: pick(&self.done_stream, "HOLEFILL_DONE"),
            done_subject: pick(&self.done_subject, "holefill.done"),
            results_consumer: pick(&self.results_consumer, "holefill-results"),
        };
        for (key, v) in [
            ("stream", &n.stream),
            ("consumer", &n.consumer),
            ("scans_bucket", &n.scans),
            ("results_bucket", &n.results),
            ("failed_bucket", &n.failed),
            ("done_stream", &n.done_stream),
            ("results_consumer", &n.results_consumer),
        ] {
            if v.is_empty()
                || !v
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
            {
                bail!("nats.{key} = {v:?}: only letters, digits, '-' and '_'");
            }
        }
        for (key, v) in [("subject", &n.subject), ("done_subject", &n.done_subject)] {
            if v.is_empty()
                || v.split('.').any(|t| t.is_empty())
                || v.bytes()
                    .any(|b| b.is_ascii_whitespace() || b == b'*' || b == b'>')
            {
                bail!("nats.{key} = {v:?}: a subject of dot-separated tokens, no wildcards");
            }
        }
        if n.subject == n.done_subject {
            bail!("nats.subject and nats.done_subject must differ");
        }
        if n.stream == n.done_stream {
            bail!("nats.stream and nats.done_stream must differ");
        }
        Ok(n)
    }

    /// The settings, with the defaults.
    pub fn settings(&self) -> Result<QueueSettings> {
        let s = QueueSettings {
            replicas: self.replicas.unwrap_or(1),
            max_deliver: self.max_deliver.unwrap_or(5),
            ack_wait: Duration::from_secs(self.ack_wait_secs.unwrap_or(60)),
            backoff: Duration::from_secs(self.backoff_secs.unwrap_or(5)),
            backoff_max: Duration::from_secs(self.backoff_max_secs.unwrap_or(300)),
            duplicate_window: Duration::from_secs(self.duplicate_window_secs.unwrap_or(3600)),
            max_age: match self.max_age_days.unwrap_or(7) {
                0 => None,
                d => Some(Duration::from_secs(d.saturating_mul(86_400))),
            },
        };
        if !(1..=5).contains(&s.replicas) {
            bail!("nats.replicas must be 1 to 5");
        }
        if s.max_deliver == 0 {
            bail!("nats.max_deliver must be at least 1");
        }
        if s.ack_wait < Duration::from_secs(1) {
            bail!("nats.ack_wait_secs must be at least 1");
        }
        if s.duplicate_window.is_zero() {
            bail!("nats.duplicate_window_secs must be at least 1");
        }
        if s.max_age.is_some_and(|a| a < s.duplicate_window) {
            bail!("nats.max_age_days must cover nats.duplicate_window_secs");
        }
        Ok(s)
    }
}

impl QueueSettings {
    /// The back-off before the next delivery after `delivered` deliveries.
    pub fn backoff_after(&self, delivered: u32) -> Duration {
        let shift = delivered.saturating_sub(1).min(20);
        self.backoff
            .saturating_mul(1u32 << shift)
            .min(self.backoff_max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_validation() {
        let f = NatsFile::default();
        let n = f.names().unwrap();
        assert_eq!(n.stream, "HOLEFILL_JOBS");
        assert_eq!(n.results, "holefill-results");
        let s = f.settings().unwrap();
        assert_eq!(s.max_deliver, 5);
        assert!(NatsFile {
            stream: Some("a.b".into()),
            ..Default::default()
        }
        .names()
        .is_err());
        assert!(NatsFile {
            subject: Some("jobs.>".into()),
            ..Default::default()
        }
        .names()
        .is_err());
        assert!(NatsFile {
            max_deliver: Some(0),
            ..Default::default()
        }
        .settings()
        .is_err());
    }

    #[test]
    fn backoff_doubles_up_to_the_max() {
        let s = NatsFile {
            backoff_secs: Some(2),
            backoff_max_secs: Some(10),
            ..Default::default()
        }
        .settings()
        .unwrap();
        assert_eq!(s.backoff_after(1), Duration::from_secs(2));
        assert_eq!(s.backoff_after(2), Duration::from_secs(4));
        assert_eq!(s.backoff_after(3), Duration::from_secs(8));
        assert_eq!(s.backoff_after(4), Duration::from_secs(10));
        assert_eq!(s.backoff_after(400), Duration::from_secs(10));
    }
}
