//! Prometheus metrics of the server and the HTTP endpoint that serves them (`GET /metrics`, on
//! its own port, OpenMetrics text).
//!
//! - `ssr_requests_total{method, code}`: answered RPCs by gRPC status code name (each Drive
//!   message counts once; calls abandoned by their client are not answered, so not counted).
//! - `ssr_step_seconds{phase}`: step latency split into `queue` (waiting for a batch), `decode`
//!   (images), `model` (the shared forward pass), `control` (PID and fusion) and `total`.
//! - `ssr_batch_size`: episodes per forward pass.
//! - `ssr_active_episodes`, `ssr_episodes_started_total`, `ssr_episodes_expired_total`.
//! - `ssr_process_resident_bytes`: the server's resident memory (Linux), read at scrape time.

use std::sync::Arc;
use std::time::Duration;

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RequestLabels {
    method: &'static str,
    code: &'static str,
}

#[derive(Debug, Clone, Hash, PartialEq, Eq, EncodeLabelSet)]
struct PhaseLabels {
    phase: &'static str,
}

/// The step phases timed separately.
#[derive(Debug, Clone, Copy)]
pub struct StepPhases {
    /// Waiting in the queue for a batch.
    pub queue: Duration,
    /// Decoding the images.
    pub decode: Duration,
    /// The shared forward pass of the step's batch.
    pub model: Duration,
    /// This step's PID and fusion.
    pub control: Duration,
    /// The whole step, from receipt of the request to its answer.
    pub total: Duration,
}

/// Every metric of one server.
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    step_seconds: Family<PhaseLabels, Histogram>,
    batch_size: Histogram,
    active_episodes: Gauge,
    episodes_started: Counter,
    episodes_expired: Counter,
    resident_bytes: Gauge,
}

fn latency_histogram() -> Histogram {
    // 0.1 ms to about 3.3 s.
    Histogram::new(exponential_buckets(1e-4, 2.0, 16))
}

impl Metrics {
    /// A registry with every metric at zero.
    pub fn new() -> Arc<Self> {
        let mut registry = Registry::default();
        let requests = Family::<RequestLabels, Counter>::default();
        registry.register(
            "ssr_requests",
            "RPCs answered, by method and gRPC status code",
            requests.clone(),
        );
        let step_seconds =
            Family::<PhaseLabels, Histogram>::new_with_constructor(latency_histogram as fn() -> _);
        registry.register(
            "ssr_step_seconds",
            "Step latency by phase: queue, decode, model, control, total",
            step_seconds.clone(),
        );
        let batch_size = Histogram::new([1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0]);
        registry.register(
            "ssr_batch_size",
            "Episodes per forward pass",
            batch_size.clone(),
        );
        let active_episodes = Gauge::default();
        registry.register(
            "ssr_active_episodes",
            "Episodes open now",
            active_episodes.clone(),
        );
        let episodes_started = Counter::default();
        registry.register(
            "ssr_episodes_started",
            "Episodes opened",
            episodes_started.clone(),
        );
        let episodes_expired = Counter::default();
        registry.register(
            "ssr_episodes_expired",
            "Episodes closed after being idle",
            episodes_expired.clone(),
        );
        let resident_bytes = Gauge::default();
        registry.register(
            "ssr_process_resident_bytes",
            "Resident memory of the server process (Linux)",
            resident_bytes.clone(),
        );
        Arc::new(Self {
            registry,
            requests,
            step_seconds,
            batch_size,
            active_episodes,
            episodes_started,
            episodes_expired,
            resident_bytes,
        })
    }

    /// Counts one answered RPC of `method` with status `code`.
    pub fn request(&self, method: &'static str, code: tonic::Code) {
        self.requests
            .get_or_create(&RequestLabels {
                method,
                code: code_name(code),
            })
            .inc();
    }

    /// Records the phase times of one step.
    pub fn observe_step(&self, phases: &StepPhases) {
        for (phase, time) in [
            ("queue", phases.queue),
            ("decode", phases.decode),
            ("model", phases.model),
            ("control", phases.control),
            ("total", phases.total),
        ] {
            self.step_seconds
                .get_or_create(&PhaseLabels { phase })
                .observe(time.as_secs_f64());
        }
    }

    /// Records the size of one forward pass, episodes.
    pub fn observe_batch(&self, size: usize) {
        self.batch_size.observe(size as f64);
    }

    /// Counts an opened episode; `open` is the number open now.
    pub fn episode_started(&self, open: usize) {
        self.episodes_started.inc();
        self.active_episodes.set(open as i64);
    }

    /// Records that an episode was ended; `open` is the number open now.
    pub fn episode_ended(&self, open: usize) {
        self.active_episodes.set(open as i64);
    }

    /// Counts `expired` episodes closed for being idle; `open` is the number open now.
    pub fn episodes_expired(&self, expired: usize, open: usize) {
        self.episodes_expired.inc_by(expired as u64);
        self.active_episodes.set(open as i64);
    }

    /// The OpenMetrics text of every metric now.
    pub fn render(&self) -> String {
        if let Some(bytes) = resident_bytes() {
            self.resident_bytes.set(bytes as i64);
        }
        let mut text = String::new();
        prometheus_client::encoding::text::encode(&mut text, &self.registry)
            .expect("writing to a String cannot fail");
        text
    }
}

/// Resident set size from `/proc/self/statm` (pages x 4 KiB), or `None` off Linux.
fn resident_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

/// Serves `GET /metrics` until `shutdown` resolves.
pub async fn serve_metrics(
    listener: tokio::net::TcpListener,
    metrics: Arc<Metrics>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let app = axum::Router::new().route(
        "/metrics",
        axum::routing::get(move || {
            let metrics = Arc::clone(&metrics);
            async move {
                (
                    [(
                        axum::http::header::CONTENT_TYPE,
                        "application/openmetrics-text; version=1.0.0; charset=utf-8",
                    )],
                    metrics.render(),
                )
            }
        }),
    );
    axum::serve(listener, app)
        .with_graceful_shutdown(shutdown)
        .await
}

fn code_name(code: tonic::Code) -> &'static str {
    use tonic::Code::*;
    match code {
        Ok => "OK",
        Cancelled => "CANCELLED",
        Unknown => "UNKNOWN",
        InvalidArgument => "INVALID_ARGUMENT",
        DeadlineExceeded => "DEADLINE_EXCEEDED",
        NotFound => "NOT_FOUND",
        AlreadyExists => "ALREADY_EXISTS",
        PermissionDenied => "PERMISSION_DENIED",
        ResourceExhausted => "RESOURCE_EXHAUSTED",
        FailedPrecondition => "FAILED_PRECONDITION",
        Aborted => "ABORTED",
        OutOfRange => "OUT_OF_RANGE",
        Unimplemented => "UNIMPLEMENTED",
        Internal => "INTERNAL",
        Unavailable => "UNAVAILABLE",
        DataLoss => "DATA_LOSS",
        Unauthenticated => "UNAUTHENTICATED",
    }
}
