//! The connection and the server-side objects: the work-queue stream and its consumer,
//! the three object stores, the done stream. Each is created on first use with the
//! settings documented in `config/holefill.toml` (an existing one is used as it is).

use super::config::{Names, QueueSettings};
use anyhow::{anyhow, Context as _, Result};
use async_nats::jetstream::{self, consumer, object_store, stream};
use std::time::Duration;

/// A connected client and its JetStream context.
#[derive(Clone)]
pub struct Conn {
    pub client: async_nats::Client,
    pub js: jetstream::Context,
}

/// Connects (retrying until the server answers, reconnecting for ever afterwards).
pub async fn connect(url: &str, name: &str) -> Result<Conn> {
    let client = async_nats::ConnectOptions::new()
        .name(name)
        .retry_on_initial_connect()
        .connection_timeout(Duration::from_secs(5))
        .reconnect_delay_callback(|n| Duration::from_millis((100 * n as u64).min(2000)))
        .event_callback(|ev| async move {
            match ev {
                async_nats::Event::Disconnected => {
                    tracing::warn!("disconnected from the NATS server")
                }
                async_nats::Event::Connected => tracing::info!("connected to the NATS server"),
                other => tracing::debug!("nats: {other}"),
            }
        })
        .connect(url)
        .await
        .with_context(|| format!("{url}: cannot connect to the NATS server"))?;
    let js = jetstream::new(client.clone());
    Ok(Conn { client, js })
}

/// Repeats a server call until it succeeds (the server may be starting or
/// restarting), logging the error at most every 10 s; gives up after `limit`.
pub async fn retry<T, F, Fut>(what: &str, limit: Duration, mut f: F) -> Result<T>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T>>,
{
    let t0 = tokio::time::Instant::now();
    let mut logged: Option<tokio::time::Instant> = None;
    let mut delay = Duration::from_millis(100);
    loop {
        match f().await {
            Ok(v) => return Ok(v),
            Err(e) => {
                if t0.elapsed() >= limit {
                    return Err(e.context(format!("{what}: gave up after {} s", limit.as_secs())));
                }
                if logged.is_none_or(|l| l.elapsed() >= Duration::from_secs(10)) {
                    tracing::warn!("{what}: {e:#} (retrying)");
                    logged = Some(tokio::time::Instant::now());
                }
                tokio::time::sleep(delay).await;
                delay = (delay * 2).min(Duration::from_secs(2));
            }
        }
    }
}

/// The work-queue stream: subject `names.subject`, work-queue retention (a message
/// is removed when acknowledged), file storage, `replicas`, duplicate window; no age
/// or size limit (a job is never dropped).
pub async fn jobs_stream(c: &Conn, n: &Names, s: &QueueSettings) -> Result<stream::Stream> {
    let cfg = stream::Config {
        name: n.stream.clone(),
        subjects: vec![n.subject.clone()],
        retention: stream::RetentionPolicy::WorkQueue,
        storage: stream::StorageType::File,
        num_replicas: s.replicas,
        duplicate_window: s.duplicate_window,
        description: Some("holefill: scans waiting for a worker".into()),
        ..Default::default()
    };
    c.js.get_or_create_stream(cfg)
        .await
        .map_err(|e| anyhow!("stream {}: {e}", n.stream))
}

/// The done stream: one notification per finished scan; limits retention with the
/// objects' `max_age`, the same duplicate window.
pub async fn done_stream(c: &Conn, n: &Names, s: &QueueSettings) -> Result<stream::Stream> {
    let cfg = stream::Config {
        name: n.done_stream.clone(),
        subjects: vec![n.done_subject.clone()],
        retention: stream::RetentionPolicy::Limits,
        storage: stream::StorageType::File,
        num_replicas: s.replicas,
        duplicate_window: s.duplicate_window,
        max_age: s.max_age.unwrap_or_default(),
        description: Some("holefill: finished scans (repaired or failed)".into()),
        ..Default::default()
    };
    c.js.get_or_create_stream(cfg)
        .await
        .map_err(|e| anyhow!("stream {}: {e}", n.done_stream))
}

/// The workers' durable pull consumer: explicit acks, `ack_wait`, at most
/// `max_deliver + 1` deliveries (the last only records the failure of a scan whose
/// worker died on every attempt), one message per pull.
pub async fn workers_consumer(
    c: &Conn,
    n: &Names,
    s: &QueueSettings,
) -> Result<consumer::PullConsumer> {
    let stream = jobs_stream(c, n, s).await?;
    let cfg = consumer::pull::Config {
        durable_name: Some(n.consumer.clone()),
        description: Some("holefill workers".into()),
        ack_policy: consumer::AckPolicy::Explicit,
        ack_wait: s.ack_wait,
        max_deliver: i64::from(s.max_deliver) + 1,
        filter_subject: n.subject.clone(),
        max_ack_pending: 10_000,
        num_replicas: s.replicas,
        ..Default::default()
    };
    stream
        .get_or_create_consumer(&n.consumer, cfg)
        .await
        .map_err(|e| anyhow!("consumer {}: {e}", n.consumer))
}

/// An object store: file storage, `replicas`, `max_age`.
pub async fn bucket(c: &Conn, name: &str, s: &QueueSettings) -> Result<object_store::ObjectStore> {
    match c.js.get_object_store(name).await {
        Ok(b) => Ok(b),
        Err(e) if e.kind() == jetstream::context::ObjectStoreErrorKind::GetStore => {
            let cfg = object_store::Config {
                bucket: name.to_string(),
                description: Some("holefill".into()),
                max_age: s.max_age.unwrap_or_default(),
                storage: stream::StorageType::File,
                num_replicas: s.replicas,
                ..Default::default()
            };
            match c.js.create_object_store(cfg).await {
                Ok(b) => Ok(b),
                // made meanwhile by another worker
                Err(e) => {
                    c.js.get_object_store(name)
                        .await
                        .map_err(|_| anyhow!("object store {name}: {e}"))
                }
            }
        }
        Err(e) => Err(anyhow!("object store {name}: {e}")),
    }
}

/// Everything a worker, a submitter or a gateway uses.
#[derive(Clone)]
pub struct Buckets {
    pub scans: object_store::ObjectStore,
    pub results: object_store::ObjectStore,
    pub failed: object_store::ObjectStore,
}

/// Gets or makes the three buckets and both streams.
pub async fn setup(c: &Conn, n: &Names, s: &QueueSettings) -> Result<Buckets> {
    jobs_stream(c, n, s).await?;
    done_stream(c, n, s).await?;
    Ok(Buckets {
        scans: bucket(c, &n.scans, s).await?,
        results: bucket(c, &n.results, s).await?,
        failed: bucket(c, &n.failed, s).await?,
    })
}
