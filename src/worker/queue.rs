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
    stream_made_or_found(c, cfg).await
}

/// The stream of `cfg`, made when missing. Two clients starting together (two workers,
/// or a worker and `submit`) both find it missing and both make it; the server refuses
/// the second ("subjects overlap with an existing stream"), and then it is there: it
/// is looked up once more, as [`bucket`] does for an object store.
async fn stream_made_or_found(c: &Conn, cfg: stream::Config) -> Result<stream::Stream> {
    let name = cfg.name.clone();
    match c.js.get_or_create_stream(cfg).await {
        Ok(s) => Ok(s),
        Err(e) => {
            c.js.get_stream(&name)
                .await
                .map_err(|_| anyhow!("stream {name}: {e}"))
        }
    }
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
    stream_made_or_found(c, cfg).await
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

/// An object store and its name. Objects are read here ([`Bucket::read`]) and not
/// through `async_nats`' `Object` reader, which unwraps the result of making its
/// consumer and so panics when the server is away at that moment (async-nats 0.46,
/// `object_store/mod.rs`: a worker slot died that way in a server restart).
#[derive(Clone)]
pub struct Bucket {
    pub name: String,
    pub store: object_store::ObjectStore,
    js: jetstream::Context,
    /// The worker's test hooks (a pause at `chunks`).
    pub hooks: crate::daemon::hooks::Hooks,
}

/// Why an object could not be read.
#[derive(Debug)]
pub enum ReadError {
    /// Not in the bucket (never stored, deleted or expired).
    Missing,
    /// Its stored size, larger than the caller's limit.
    TooLarge(u64),
    /// The server or the object's chunks (retrying may help).
    Other(anyhow::Error),
}

/// How long one chunk of an object may take to arrive.
const CHUNK_WAIT: Duration = Duration::from_secs(30);

impl Bucket {
    /// Writes the object `name` into `out` (at most `max` bytes) and returns its size
    /// and SHA-256 (hex). The chunks are read in order through an ordered consumer on
    /// the bucket's stream (`OBJ_<bucket>`, subject `$O.<bucket>.C.<nuid>`, as ADR-20
    /// lays out an object store); their count, total size and digest are checked
    /// against the object's info.
    pub async fn read<W>(
        &self,
        name: &str,
        max: u64,
        out: &mut W,
    ) -> Result<(u64, String), ReadError>
    where
        W: tokio::io::AsyncWrite + Unpin,
    {
        use base64::Engine as _;
        use futures_util::StreamExt as _;
        use object_store::InfoErrorKind;
        use sha2::Digest as _;
        use tokio::io::AsyncWriteExt as _;
        let other = |what: &str, e: &dyn std::fmt::Display| {
            ReadError::Other(anyhow!("{}/{name}: {what}: {e}", self.name))
        };
        let info = match self.store.info(name).await {
            Ok(i) if !i.deleted => i,
            Ok(_) => return Err(ReadError::Missing),
            Err(e) if e.kind() == InfoErrorKind::NotFound => return Err(ReadError::Missing),
            Err(e) => return Err(other("info", &e)),
        };
        if info.options.as_ref().is_some_and(|o| o.link.is_some()) {
            return Err(other("a link", &"holefill stores no links"));
        }
        let size = info.size as u64;
        if size > max {
            return Err(ReadError::TooLarge(size));
        }
        let mut h = sha2::Sha256::new();
        let mut total = 0u64;
        if info.chunks > 0 {
            let stream = self
                .js
                .get_stream(format!("OBJ_{}", self.name))
                .await
                .map_err(|e| other("its stream", &e))?;
            if let Some(d) = self.hooks.pause("chunks", name.as_ref()) {
                tokio::time::sleep(d).await;
            }
            let consumer = stream
                .create_consumer(consumer::push::OrderedConfig {
                    deliver_subject: self.js.client().new_inbox(),
                    filter_subject: format!("$O.{}.C.{}", self.name, info.nuid),
                    ..Default::default()
                })
                .await
                .map_err(|e| other("cannot read its chunks", &e))?;
            let mut chunks = consumer
                .messages()
                .await
                .map_err(|e| other("cannot read its chunks", &e))?;
            for i in 0..info.chunks {
                let which = format!("chunk {} of {}", i + 1, info.chunks);
                let m = match tokio::time::timeout(CHUNK_WAIT, chunks.next()).await {
                    Err(_) => {
                        let waited = format!("none within {} s", CHUNK_WAIT.as_secs());
                        return Err(other(&which, &waited));
                    }
                    Ok(None) => return Err(other(&which, &"the subscription ended")),
                    Ok(Some(Err(e))) => return Err(other(&which, &e)),
                    Ok(Some(Ok(m))) => m,
                };
                total += m.payload.len() as u64;
                if total > size {
                    return Err(other("chunks", &format!("more than its {size} bytes")));
                }
                h.update(&m.payload);
                out.write_all(&m.payload)
                    .await
                    .map_err(|e| other("write", &e))?;
            }
        }
        if total != size {
            return Err(other(
                "chunks",
                &format!("{total} bytes, its info says {size}"),
            ));
        }
        let digest = h.finalize();
        if let Some(want) = info
            .digest
            .as_deref()
            .and_then(|d| d.strip_prefix("SHA-256="))
        {
            let want = base64::engine::general_purpose::URL_SAFE_NO_PAD
                .decode(want.trim_end_matches('='))
                .map_err(|e| other("its digest", &e))?;
            if want.as_slice() != digest.as_slice() {
                return Err(other("chunks", &"their SHA-256 is not the object's digest"));
            }
        }
        out.flush().await.map_err(|e| other("write", &e))?;
        Ok((total, crate::worker::scan::hex(&digest)))
    }

    /// The object's bytes, at most `max` of them.
    pub async fn read_bytes(&self, name: &str, max: u64) -> Result<Vec<u8>> {
        let mut v = Vec::new();
        match self.read(name, max, &mut v).await {
            Ok(_) => Ok(v),
            Err(ReadError::Missing) => Err(anyhow!("{}/{name}: not in the bucket", self.name)),
            Err(ReadError::TooLarge(n)) => Err(anyhow!(
                "{}/{name}: {n} bytes, larger than {max}",
                self.name
            )),
            Err(ReadError::Other(e)) => Err(e),
        }
    }
}

/// Gets an existing object store as a [`Bucket`].
pub async fn existing_bucket(c: &Conn, name: &str) -> Result<Bucket> {
    let store =
        c.js.get_object_store(name)
            .await
            .map_err(|e| anyhow!("object store {name}: {e}"))?;
    Ok(Bucket {
        name: name.to_string(),
        store,
        js: c.js.clone(),
        hooks: Default::default(),
    })
}

/// An object store: file storage, `replicas`, `max_age`.
pub async fn bucket(c: &Conn, name: &str, s: &QueueSettings) -> Result<Bucket> {
    let store = match c.js.get_object_store(name).await {
        Ok(b) => b,
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
                Ok(b) => b,
                // made meanwhile by another worker
                Err(e) => {
                    c.js.get_object_store(name)
                        .await
                        .map_err(|_| anyhow!("object store {name}: {e}"))?
                }
            }
        }
        Err(e) => return Err(anyhow!("object store {name}: {e}")),
    };
    Ok(Bucket {
        name: name.to_string(),
        store,
        js: c.js.clone(),
        hooks: Default::default(),
    })
}

/// Everything a worker, a submitter or a gateway uses.
#[derive(Clone)]
pub struct Buckets {
    pub scans: Bucket,
    pub results: Bucket,
    pub failed: Bucket,
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
