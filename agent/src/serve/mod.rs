//! The gRPC agent server (`ssr-agent serve`): the `ssrdrive.v1.AgentService` over per-episode
//! sessions with dynamic batching, plus what operators expect around it.
//!
//! - [`config`]: every setting, from a TOML file, the environment and the command line.
//! - [`episodes`]: open episodes and their temporal state (leased by one step at a time).
//! - [`decode`]: wire images and numbers to the inference input, checked.
//! - [`batcher`]: the bounded step queue and the model thread that batches it.
//! - [`engine`]: the service logic without gRPC; [`service`]: the tonic layer.
//! - [`metrics`]: Prometheus metrics on their own port.
//!
//! Around the service: `grpc.health.v1.Health` (NOT_SERVING until the model is loaded and
//! warmed up, and again while draining), server reflection (v1 and v1alpha, for grpcurl-style
//! tools), a request timeout (a shorter client deadline wins), message size limits, idle-episode
//! expiry and graceful shutdown (NOT_SERVING, optional grace period, stop accepting, drain
//! in-flight requests within a timeout, exit).

pub mod batcher;
pub mod config;
pub mod decode;
pub mod engine;
pub mod episodes;
pub mod metrics;
pub mod service;

use std::sync::Arc;
use std::time::Duration;

use anyhow::Context as _;
use burn::tensor::Device;
pub use config::{LogFormat, ServeConfig};
pub use engine::{Engine, ModelInfo};
use service::AgentServiceImpl;
use ssrdrive_proto::v1;
use ssrdrive_proto::v1::agent_service_server::AgentServiceServer;
use tokio::net::TcpListener;
use tonic::transport::server::TcpIncoming;
use tonic_health::ServingStatus;

use crate::checkpoint;
use crate::control::ControlConfig;
use crate::history::History;
use crate::model::SsrModel;
use crate::model::config::SsrConfig;
use crate::policy::SsrPolicy;

/// HTTP/2 flow-control window per stream, bytes (a whole 900x256 RGB frame and then some).
pub const STREAM_WINDOW_BYTES: u32 = 4 << 20;

/// How often a drain checks for steps still in flight.
const DRAIN_POLL: Duration = Duration::from_millis(10);
/// How long answers get to go out once no step is in flight, before open streams are cut.
const DRAIN_FLUSH: Duration = Duration::from_millis(200);

/// Loads the network the config names: a checkpoint file, random weights of a config, or
/// (with neither) the checkpoint bundled into the binary.
pub fn load_policy(
    config: &ServeConfig,
    device: &Device,
) -> anyhow::Result<(SsrPolicy, ModelInfo)> {
    let trained = |(model, info): (SsrModel, checkpoint::CheckpointInfo), name: String| {
        let rig = checkpoint::rig(&info).map_err(|e| anyhow::anyhow!("checkpoint {name}: {e}"))?;
        let control = checkpoint::control_config(&info)
            .map_err(|e| anyhow::anyhow!("checkpoint {name}: {e}"))?;
        let history =
            checkpoint::history(&info).map_err(|e| anyhow::anyhow!("checkpoint {name}: {e}"))?;
        anyhow::Ok((model, info.config, name, rig, (control, history)))
    };
    let (model, model_config, checkpoint, rig, (control, history)) =
        match (&config.checkpoint, &config.untrained_config) {
            (Some(path), _) => {
                trained(checkpoint::load(path, device)?, path.display().to_string())?
            }
            (None, Some(spec)) => {
                let model_config = SsrConfig::from_name_or_file(spec)?;
                tracing::warn!(
                    "serving config '{}' with RANDOM weights: a component under test, not a driver",
                    model_config.name
                );
                let model = model_config.init(device);
                (
                    model,
                    model_config,
                    "untrained (random weights)".to_string(),
                    None,
                    (ControlConfig::default(), History::default()),
                )
            }
            (None, None) => trained(
                checkpoint::bundled::load(device)?,
                checkpoint::bundled::NAME.to_string(),
            )?,
        };
    let expected_rig = rig.unwrap_or_else(|| ModelInfo::default_rig(&model_config));
    let info = ModelInfo {
        config: model_config.clone(),
        checkpoint,
        expected_rig,
    };
    let mut control = control;
    control.unstick.enabled = config.unstick.unwrap_or(control.unstick.enabled);
    control.safety.enabled = config.safety_stop.unwrap_or(control.safety.enabled);
    control.safety.motion = config.safety_motion.unwrap_or(control.safety.motion);
    let history = config.history.unwrap_or(history);
    if control.safety.enabled && model.occupancy.is_none() {
        anyhow::bail!(
            "the safety stop reads the network's occupancy head, and {} has none \
             (train with --occupancy-weight above 0, or serve with --safety-stop false)",
            info.checkpoint
        );
    }
    if control.safety.enabled && control.safety.motion && model.motion.is_none() {
        anyhow::bail!(
            "the safety stop's motion rule reads the network's motion head, and {} has none \
             (train with --motion-weight above 0, or serve with --safety-motion false)",
            info.checkpoint
        );
    }
    tracing::info!(
        checkpoint = %info.checkpoint,
        safety_stop = control.safety.enabled,
        safety_motion = control.safety.motion,
        unstick = control.unstick.enabled,
        ?history,
        wheelbase_m = control.vehicle.wheelbase,
        max_wheel_angle_deg = control.vehicle.max_wheel_angle,
        "controller"
    );
    let policy = SsrPolicy::new(model, model_config, control, device.clone()).with_history(history);
    Ok((policy, info))
}

/// The server's bound ports (bind first to learn the real port when asking for port 0).
pub struct Listeners {
    /// The gRPC port, at `listen`.
    pub grpc: TcpListener,
    /// The metrics port, at `metrics_listen`; `None` when metrics are off.
    pub metrics: Option<TcpListener>,
}

impl Listeners {
    /// Binds the gRPC port and, if configured, the metrics port.
    pub async fn bind(config: &ServeConfig) -> anyhow::Result<Self> {
        let grpc = TcpListener::bind(config.listen)
            .await
            .with_context(|| format!("binding the gRPC port {}", config.listen))?;
        let metrics = match config.metrics_listen {
            Some(address) => Some(
                TcpListener::bind(address)
                    .await
                    .with_context(|| format!("binding the metrics port {address}"))?,
            ),
            None => None,
        };
        Ok(Self { grpc, metrics })
    }
}

/// A spawned task that is aborted when this handle is dropped (every exit path of [`run`]).
struct AbortOnDrop<T>(tokio::task::JoinHandle<T>);

impl<T> Drop for AbortOnDrop<T> {
    fn drop(&mut self) {
        self.0.abort();
    }
}

/// The gRPC server task's end as this function's result.
fn server_ended(
    ended: Result<Result<(), tonic::transport::Error>, tokio::task::JoinError>,
) -> anyhow::Result<()> {
    ended
        .context("the gRPC server task failed")?
        .context("the gRPC server failed")
}

/// Reports `status` for the whole server ("") and for the agent service.
async fn set_health(reporter: &tonic_health::server::HealthReporter, status: ServingStatus) {
    reporter.set_service_status("", status).await;
    reporter
        .set_service_status(
            <AgentServiceServer<AgentServiceImpl> as tonic::server::NamedService>::NAME,
            status,
        )
        .await;
}

/// This machine's name (`HOSTNAME`, else the kernel's), for the default replica id; printable
/// ASCII only.
fn host_name() -> String {
    let name = std::env::var("HOSTNAME")
        .ok()
        .or_else(|| std::fs::read_to_string("/proc/sys/kernel/hostname").ok())
        .unwrap_or_default();
    let name: String = name
        .trim()
        .chars()
        .filter(|c| c.is_ascii_graphic())
        .take(100)
        .collect();
    if name.is_empty() {
        "localhost".into()
    } else {
        name
    }
}

/// Serves on `listeners` until `shutdown` resolves, then drains and returns.
pub async fn run(
    listeners: Listeners,
    config: ServeConfig,
    policy: SsrPolicy,
    info: ModelInfo,
    shutdown: impl Future<Output = ()>,
) -> anyhow::Result<()> {
    config.validate()?;
    let Listeners {
        grpc: listener,
        metrics: metrics_listener,
    } = listeners;
    let address = listener.local_addr()?;

    let engine = Engine::new(policy, info, &config);
    let (reporter, health) = tonic_health::server::health_reporter();
    set_health(&reporter, ServingStatus::NotServing).await;
    let reflection = || {
        tonic_reflection::server::Builder::configure()
            .register_encoded_file_descriptor_set(v1::FILE_DESCRIPTOR_SET)
            .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
    };
    let reflection_v1 = reflection().build_v1()?;
    let reflection_v1alpha = reflection().build_v1alpha()?;
    // Drive streams end (UNAVAILABLE) when this flips, so a drain does not wait on them.
    let (draining, drain_signal) = tokio::sync::watch::channel(false);
    let replica = config
        .replica_id
        .clone()
        .unwrap_or_else(|| format!("{}:{}", host_name(), address.port()));
    let agent = AgentServiceServer::new(AgentServiceImpl::new(
        Arc::clone(&engine),
        drain_signal,
        &replica,
    ))
    .max_decoding_message_size(config.max_message_bytes());

    // Small answers must not wait for Nagle's algorithm.
    let incoming = TcpIncoming::from(listener).with_nodelay(Some(true));
    let (stop_server, server_stopped) = tokio::sync::oneshot::channel::<()>();
    let mut server = AbortOnDrop(tokio::spawn(
        tonic::transport::Server::builder()
            .timeout(config.request_timeout())
            // Frames are 0.1-5 MB: HTTP/2's default 64 KiB windows would stall every request
            // on flow-control round trips.
            .initial_stream_window_size(STREAM_WINDOW_BYTES)
            .initial_connection_window_size(4 * STREAM_WINDOW_BYTES)
            .add_service(health)
            .add_service(reflection_v1)
            .add_service(reflection_v1alpha)
            .add_service(agent)
            .serve_with_incoming_shutdown(incoming, async {
                let _ = server_stopped.await;
            }),
    ));
    let (_metrics_task, stop_metrics) = spawn_metrics(metrics_listener, &engine);
    let _sweeper = spawn_sweeper(&engine, config.idle_timeout());

    // Warm up, then serve until the shutdown signal, unless the server fails first.
    let warm_up = tokio::select! {
        warm_up = engine.warm_up() => warm_up.context("warm-up step failed")?,
        ended = &mut server.0 => return server_ended(ended),
    };
    set_health(&reporter, ServingStatus::Serving).await;
    tracing::info!(
        %address,
        warm_up_ms = warm_up.as_secs_f64() * 1000.0,
        "serving"
    );
    tokio::select! {
        () = shutdown => {}
        ended = &mut server.0 => return server_ended(ended),
    }

    tracing::info!("shutting down: reporting NOT_SERVING");
    set_health(&reporter, ServingStatus::NotServing).await;
    tokio::time::sleep(Duration::from_secs_f64(config.drain_grace_s)).await;
    tracing::info!("refusing new connections; draining in-flight steps");
    let _ = draining.send(true);
    let _ = stop_server.send(());
    let drained = drain(&engine, &mut server, config.drain_timeout_s).await;
    let _ = stop_metrics.send(());
    drained?;
    tracing::info!("stopped");
    Ok(())
}

/// The metrics endpoint on its own task, where metrics are on; the sender stops it.
fn spawn_metrics(
    listener: Option<TcpListener>,
    engine: &Arc<Engine>,
) -> (Option<AbortOnDrop<()>>, tokio::sync::oneshot::Sender<()>) {
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let task = listener.map(|listener| {
        let metrics = Arc::clone(engine.metrics());
        AbortOnDrop(tokio::spawn(async move {
            let stopped = async {
                let _ = stopped.await;
            };
            if let Err(error) = metrics::serve_metrics(listener, metrics, stopped).await {
                tracing::error!("metrics endpoint failed: {error}");
            }
        }))
    });
    (task, stop)
}

/// Ends idle episodes every quarter of the idle timeout (0.1 to 5 s).
fn spawn_sweeper(engine: &Arc<Engine>, idle_timeout: Duration) -> AbortOnDrop<()> {
    let engine = Arc::clone(engine);
    let period = idle_timeout
        .div_f64(4.0)
        .clamp(Duration::from_millis(100), Duration::from_secs(5));
    AbortOnDrop(tokio::spawn(async move {
        let mut ticker = tokio::time::interval(period);
        loop {
            ticker.tick().await;
            engine.expire_idle();
        }
    }))
}

/// After the server stopped taking connections: waits for the steps being served, not for
/// streams that carry none (a health watch, a reflection session, a Drive stream between
/// steps): once no step is in flight and the answers had a moment to go out, whatever is still
/// open is cut; at most `timeout_s`.
async fn drain(
    engine: &Engine,
    server: &mut AbortOnDrop<Result<(), tonic::transport::Error>>,
    timeout_s: f64,
) -> anyhow::Result<()> {
    let steps_done = async {
        while engine.steps_in_flight() > 0 {
            tokio::time::sleep(DRAIN_POLL).await;
        }
        tokio::time::sleep(DRAIN_FLUSH).await;
    };
    let drained = tokio::time::timeout(Duration::from_secs_f64(timeout_s), async {
        tokio::select! {
            ended = &mut server.0 => Some(ended),
            () = steps_done => None,
        }
    })
    .await;
    match drained {
        Ok(Some(ended)) => server_ended(ended)?,
        Ok(None) => tracing::info!("no step in flight; closing the streams still open"),
        Err(_) => tracing::warn!("steps still in flight after {timeout_s} s; exiting anyway"),
    }
    Ok(())
}
