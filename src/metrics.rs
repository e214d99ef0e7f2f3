//! Prometheus metrics of the service (`holefill watch --metrics ADDR`, and any other
//! long-running command that calls [`init`] and [`serve`]): what happened to the
//! files and their holes, how long repairs take, what waits and what runs.
//!
//! The metrics live in one process-wide [`Metrics`] ([`global`]; `None` until
//! [`init`], so a service without `--metrics` records nothing). [`serve`] answers
//! `GET /metrics` with the OpenMetrics text format (which Prometheus reads) on a plain
//! HTTP/1.1 listener of a few lines: one request per connection, a bounded request
//! head, a time-out, a cap on open connections. The names follow the Prometheus
//! conventions (`_total` counters, `_seconds`, `_bytes`); README.md ("Metrics") lists
//! them with their meaning.

use prometheus_client::encoding::text::encode;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{exponential_buckets, Histogram};
use prometheus_client::metrics::info::Info;
use prometheus_client::registry::{Registry, Unit};
use serde_json::Value;
use std::net::SocketAddr;
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, SystemTime};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Label sets (a list of name and value pairs).
type Labels = Vec<(&'static str, String)>;

/// Every metric of the service.
pub struct Metrics {
    registry: Registry,
    /// Files done, by `outcome`: `repaired` (model and log in the outbox, also when
    /// some hole failed) or `failed` (in the failed folder).
    pub files: Family<Labels, Counter>,
    /// Failed files by `stage` (`limits`, `input`, `name`, `repair`, `worker`, `output`).
    pub failures: Family<Labels, Counter>,
    /// Holes of repaired files by `status`, `class` and `method` (`none` when no
    /// method's patch was accepted).
    pub holes: Family<Labels, Counter>,
    /// Seconds from the start of a file's last attempt to its end (repaired or failed).
    pub duration: Histogram,
    /// Size of each input file done.
    pub size: Histogram,
    /// Faces (triangles) of each repaired input.
    pub faces: Histogram,
    /// Files waiting in the inbox (or waiting for another attempt).
    pub waiting: Gauge,
    /// Files being repaired or published.
    pub in_flight: Gauge,
    /// Repair processes started.
    pub attempts: Counter,
    /// Files tried again, by `reason`: `crashed` (the worker crashed, was killed or
    /// timed out; counts towards max_attempts), `retryable` (a retryable failure such
    /// as a full disk: back into the inbox with a back-off), `changed` (it changed
    /// while claimed or repaired: back to settle).
    pub retries: Family<Labels, Counter>,
    /// Workers that crashed or were killed (signal, non-repair exit status).
    pub crashes: Counter,
    /// Workers killed at the time limit.
    pub timeouts: Counter,
    /// Unix time of the last repaired file.
    pub last_success: Gauge<f64, AtomicU64>,
}

static GLOBAL: OnceLock<Metrics> = OnceLock::new();

/// The process's metrics, once [`init`] ran.
pub fn global() -> Option<&'static Metrics> {
    GLOBAL.get()
}

/// Creates the process's metrics (idempotent). `service` names the command
/// (`watch`, `worker`) in the build info.
pub fn init(service: &str) -> &'static Metrics {
    GLOBAL.get_or_init(|| Metrics::new(service))
}

impl Metrics {
    fn new(service: &str) -> Metrics {
        let mut r = Registry::default();
        let files = Family::<Labels, Counter>::default();
        r.register(
            "holefill_files",
            "Files done, by outcome (repaired: in the outbox; failed: in the failed folder)",
            files.clone(),
        );
        let failures = Family::<Labels, Counter>::default();
        r.register(
            "holefill_file_failures",
            "Failed files by the stage that failed (limits, input, name, repair, worker, output)",
            failures.clone(),
        );
        let holes = Family::<Labels, Counter>::default();
        r.register(
            "holefill_holes",
            "Holes of repaired files by status (filled, skipped, failed), size class and method",
            holes.clone(),
        );
        let duration = Histogram::new([
            0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0, 60.0, 120.0, 300.0, 600.0,
        ]);
        r.register_with_unit(
            "holefill_repair_duration",
            "Time of a file's last attempt, from its start to the file's end in the outbox or failed folder",
            Unit::Seconds,
            duration.clone(),
        );
        // 1 KiB .. 16 GiB
        let size = Histogram::new(exponential_buckets(1024.0, 4.0, 13));
        r.register_with_unit(
            "holefill_file_size",
            "Size of each input file done",
            Unit::Bytes,
            size.clone(),
        );
        // 100 .. 100 M
        let faces = Histogram::new(exponential_buckets(100.0, 10.0, 7));
        r.register(
            "holefill_file_faces",
            "Faces (triangles) of each repaired input",
            faces.clone(),
        );
        let waiting = Gauge::default();
        r.register(
            "holefill_files_waiting",
            "Files waiting in the inbox or for another attempt",
            waiting.clone(),
        );
        let in_flight = Gauge::default();
        r.register(
            "holefill_files_in_flight",
            "Files being repaired or published",
            in_flight.clone(),
        );
        let attempts = Counter::default();
        r.register(
            "holefill_attempts",
            "Repair processes started",
            attempts.clone(),
        );
        let retries = Family::<Labels, Counter>::default();
        r.register(
            "holefill_retries",
            "Files tried again, by reason (crashed: the worker crashed or timed out; retryable: a retryable failure such as a full disk; changed: the file changed while claimed)",
            retries.clone(),
        );
        let crashes = Counter::default();
        r.register(
            "holefill_worker_crashes",
            "Workers that crashed or were killed (signal, unexpected exit status)",
            crashes.clone(),
        );
        let timeouts = Counter::default();
        r.register(
            "holefill_worker_timeouts",
            "Workers killed at the time limit",
            timeouts.clone(),
        );
        let last_success = Gauge::<f64, AtomicU64>::default();
        r.register_with_unit(
            "holefill_last_success_timestamp",
            "Unix time of the last repaired file",
            Unit::Seconds,
            last_success.clone(),
        );
        r.register(
            "holefill_build",
            "The running build",
            Info::new(vec![
                ("version", env!("CARGO_PKG_VERSION").to_string()),
                ("service", service.to_string()),
            ]),
        );
        Metrics {
            registry: r,
            files,
            failures,
            holes,
            duration,
            size,
            faces,
            waiting,
            in_flight,
            attempts,
            retries,
            crashes,
            timeouts,
            last_success,
        }
    }

    /// A repaired file: its final repair log, the seconds of its last attempt, its
    /// input's size when known.
    pub fn repaired(&self, log: Option<&Value>, seconds: f64, bytes: Option<u64>) {
        self.files
            .get_or_create(&vec![("outcome", "repaired".into())])
            .inc();
        self.duration.observe(seconds);
        if let Some(b) = bytes {
            self.size.observe(b as f64);
        }
        if let Some(log) = log {
            if let Some(f) = log.pointer("/before/faces").and_then(Value::as_u64) {
                self.faces.observe(f as f64);
            }
            for h in log
                .get("holes")
                .and_then(Value::as_array)
                .map(Vec::as_slice)
                .unwrap_or_default()
            {
                let s = |k: &str| h.get(k).and_then(Value::as_str).unwrap_or("none");
                self.holes
                    .get_or_create(&vec![
                        ("status", s("status").into()),
                        ("class", s("class").into()),
                        ("method", s("method").into()),
                    ])
                    .inc();
            }
        }
        let now = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map(|d| d.as_secs_f64())
            .unwrap_or(0.0);
        self.last_success.set(now);
    }

    /// A failed file.
    pub fn failed(&self, stage: &str, seconds: f64, bytes: Option<u64>) {
        self.files
            .get_or_create(&vec![("outcome", "failed".into())])
            .inc();
        self.failures
            .get_or_create(&vec![("stage", stage.to_string())])
            .inc();
        self.duration.observe(seconds);
        if let Some(b) = bytes {
            self.size.observe(b as f64);
        }
    }

    /// A file tried again (`crashed`, `retryable`, `changed`).
    pub fn retry(&self, reason: &'static str) {
        self.retries
            .get_or_create(&vec![("reason", reason.to_string())])
            .inc();
    }

    /// The metrics in the OpenMetrics text format.
    pub fn render(&self) -> String {
        let mut s = String::with_capacity(8192);
        if let Err(e) = encode(&mut s, &self.registry) {
            tracing::error!("cannot encode the metrics: {e}");
        }
        s
    }
}

/// Most connections served at once; more wait for the listener.
const MAX_CONNECTIONS: usize = 16;
/// A request head longer than this is refused.
const MAX_HEAD: usize = 8192;
/// A client has this long to send its request and read the answer.
const CLIENT_TIME: Duration = Duration::from_secs(10);

/// Binds `addr` and serves `GET /metrics` on the current tokio runtime until it ends.
/// Returns the bound address (port 0 picks a free one).
pub async fn serve(addr: SocketAddr, metrics: &'static Metrics) -> std::io::Result<SocketAddr> {
    let listener = tokio::net::TcpListener::bind(addr).await?;
    let local = listener.local_addr()?;
    if !local.ip().is_loopback() {
        tracing::warn!("metrics are served on {local}, beyond this machine (no authentication)");
    }
    let slots = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    tokio::spawn(async move {
        loop {
            let Ok(permit) = slots.clone().acquire_owned().await else {
                return;
            };
            match listener.accept().await {
                Ok((stream, _)) => {
                    tokio::spawn(async move {
                        let _ = tokio::time::timeout(CLIENT_TIME, answer(stream, metrics)).await;
                        drop(permit);
                    });
                }
                Err(e) => {
                    tracing::warn!("metrics listener: {e}");
                    drop(permit);
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            }
        }
    });
    Ok(local)
}

/// Reads one request head and answers it.
async fn answer(mut stream: tokio::net::TcpStream, metrics: &Metrics) -> std::io::Result<()> {
    let mut head = Vec::with_capacity(1024);
    let mut buf = [0u8; 1024];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        if head.len() > MAX_HEAD {
            return respond(
                &mut stream,
                "431 Request Header Fields Too Large",
                "text/plain",
                "",
            )
            .await;
        }
        let n = stream.read(&mut buf).await?;
        if n == 0 {
            return Ok(());
        }
        head.extend_from_slice(&buf[..n]);
    }
    let line = head.split(|&b| b == b'\r').next().unwrap_or_default();
    let mut parts = line.split(|&b| b == b' ');
    let (method, target) = (
        parts.next().unwrap_or_default(),
        parts.next().unwrap_or_default(),
    );
    let path = target.split(|&b| b == b'?').next().unwrap_or_default();
    match (method, path) {
        (b"GET", b"/metrics") => {
            let body = metrics.render();
            respond(
                &mut stream,
                "200 OK",
                "application/openmetrics-text; version=1.0.0; charset=utf-8",
                &body,
            )
            .await
        }
        (b"GET", b"/") => {
            respond(
                &mut stream,
                "200 OK",
                "text/html; charset=utf-8",
                "<a href=\"/metrics\">/metrics</a>\n",
            )
            .await
        }
        (b"GET", _) => respond(&mut stream, "404 Not Found", "text/plain", "not found\n").await,
        _ => {
            respond(
                &mut stream,
                "405 Method Not Allowed",
                "text/plain",
                "GET only\n",
            )
            .await
        }
    }
}

async fn respond(
    stream: &mut tokio::net::TcpStream,
    status: &str,
    content_type: &str,
    body: &str,
) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes()).await?;
    stream.write_all(body.as_bytes()).await?;
    stream.shutdown().await
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn names_units_and_counts() {
        let m = Metrics::new("test");
        let log = json!({
            "before": {"faces": 1200},
            "holes": [
                {"status": "filled", "class": "small", "method": "fan"},
                {"status": "filled", "class": "small", "method": "fan"},
                {"status": "failed", "class": "large", "method": null},
            ]
        });
        m.repaired(Some(&log), 0.3, Some(5000));
        m.failed("input", 0.1, Some(10));
        m.retry("crashed");
        m.attempts.inc();
        let t = m.render();
        for line in [
            "holefill_files_total{outcome=\"repaired\"} 1",
            "holefill_files_total{outcome=\"failed\"} 1",
            "holefill_file_failures_total{stage=\"input\"} 1",
            "holefill_holes_total{status=\"filled\",class=\"small\",method=\"fan\"} 2",
            "holefill_holes_total{status=\"failed\",class=\"large\",method=\"none\"} 1",
            "holefill_repair_duration_seconds_count 2",
            "holefill_file_size_bytes_sum 5010.0",
            "holefill_file_faces_count 1",
            "holefill_retries_total{reason=\"crashed\"} 1",
            "holefill_attempts_total 1",
            "holefill_worker_crashes_total 0",
            "holefill_files_in_flight 0",
            "# TYPE holefill_last_success_timestamp_seconds gauge",
            "# EOF",
        ] {
            assert!(t.lines().any(|l| l == line), "no line {line:?} in\n{t}");
        }
        assert!(t.contains("holefill_build_info{version=\""), "{t}");
    }
}
