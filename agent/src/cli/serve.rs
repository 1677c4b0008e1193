//! `ssr-agent serve`: its command-line and environment settings, layered over the config file
//! (defaults < `--config` file < environment (`SSR_AGENT_*`) < flags), and the run itself.

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::Args;
use ssr_agent::device::Backend;
use ssr_agent::history::History;
use ssr_agent::serve::{self, LogFormat, ServeConfig};

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// A TOML file with any of the settings below (snake_case keys, e.g. `max_batch = 8`).
    #[arg(long, env = "SSR_AGENT_CONFIG")]
    config: Option<PathBuf>,
    /// gRPC address [default: 127.0.0.1:50051]; port 0 picks a free one (printed on stdout).
    #[arg(long, env = "SSR_AGENT_LISTEN", value_parser = serve::config::parse_listen)]
    listen: Option<SocketAddr>,
    /// Prometheus /metrics address [default: 127.0.0.1:9090], or `off`.
    #[arg(long, env = "SSR_AGENT_METRICS_LISTEN", value_parser = parse_metrics_listen)]
    metrics_listen: Option<MetricsListen>,
    /// Checkpoint written by `ssr-agent train`.
    #[arg(long, env = "SSR_AGENT_CHECKPOINT")]
    checkpoint: Option<PathBuf>,
    /// Serve RANDOM weights of this config preset or file instead of a checkpoint (tests and
    /// benchmarks: such a network does not drive).
    #[arg(
        long,
        env = "SSR_AGENT_UNTRAINED_CONFIG",
        conflicts_with = "checkpoint"
    )]
    untrained_config: Option<String>,
    /// Most episodes open at once [default: 64].
    #[arg(long, env = "SSR_AGENT_MAX_EPISODES")]
    max_episodes: Option<usize>,
    /// Seconds without a request before an episode is closed [default: 60].
    #[arg(long, env = "SSR_AGENT_IDLE_TIMEOUT_S")]
    idle_timeout_s: Option<f64>,
    /// Largest batch of concurrent steps in one forward pass; 1 turns batching off [default: 8].
    #[arg(long, env = "SSR_AGENT_MAX_BATCH")]
    max_batch: Option<usize>,
    /// Milliseconds the first step of a batch waits for others [default: 2].
    #[arg(long, env = "SSR_AGENT_MAX_QUEUE_DELAY_MS")]
    max_queue_delay_ms: Option<f64>,
    /// Steps waiting for the network at most; more are refused [default: 256].
    #[arg(long, env = "SSR_AGENT_MAX_QUEUE")]
    max_queue: Option<usize>,
    /// Model threads, each forming and running its own batches [default: 2].
    #[arg(long, env = "SSR_AGENT_MODEL_THREADS")]
    model_threads: Option<usize>,
    /// Size of the rayon pool each model thread gets to itself; 0: all model threads share
    /// rayon's global pool [default: 0].
    #[arg(long, env = "SSR_AGENT_COMPUTE_THREADS")]
    compute_threads: Option<usize>,
    /// Longest a request may take, seconds; a shorter client deadline wins [default: 30].
    #[arg(long, env = "SSR_AGENT_REQUEST_TIMEOUT_S")]
    request_timeout_s: Option<f64>,
    /// Largest request, MiB [default: 64; six 1600x900 RGB frames are 25 MiB].
    #[arg(long, env = "SSR_AGENT_MAX_MESSAGE_MIB")]
    max_message_mib: Option<usize>,
    /// Most pixels a step may carry over all its cameras; a bigger rig is refused
    /// [default: 8640000, six 1600x900 cameras].
    #[arg(long, env = "SSR_AGENT_MAX_PIXELS_PER_STEP")]
    max_pixels_per_step: Option<u64>,
    /// Memory for decoded images of all steps in flight, MiB; a step past it is refused
    /// (RESOURCE_EXHAUSTED, retry) [default: 1024].
    #[arg(long, env = "SSR_AGENT_MAX_DECODED_MIB")]
    max_decoded_mib: Option<usize>,
    /// On shutdown, seconds to report NOT_SERVING before refusing connections [default: 0].
    #[arg(long, env = "SSR_AGENT_DRAIN_GRACE_S")]
    drain_grace_s: Option<f64>,
    /// On shutdown, longest wait for in-flight requests, seconds [default: 30].
    #[arg(long, env = "SSR_AGENT_DRAIN_TIMEOUT_S")]
    drain_timeout_s: Option<f64>,
    /// Log format [default: human].
    #[arg(long, env = "SSR_AGENT_LOG_FORMAT")]
    log_format: Option<LogFormat>,
    /// Where the network runs [default: cpu]; `wgpu` needs a build with `--features wgpu`
    /// and a Vulkan, Metal or DX12 adapter.
    #[arg(long, env = "SSR_AGENT_BACKEND")]
    backend: Option<Backend>,
    /// The unstick rule: after a long stop, creep along the plan (how long: the checkpoint's
    /// `unstick` settings) [default: the checkpoint's setting (`ssr-agent control`); on in
    /// every shipped one].
    #[arg(long, env = "SSR_AGENT_UNSTICK")]
    unstick: Option<bool>,
    /// The safety stop: brake when the network's occupancy head believes the path just ahead
    /// occupied (needs a checkpoint with the head) [default: the checkpoint's setting
    /// (`ssr-agent control`)].
    #[arg(long, env = "SSR_AGENT_SAFETY_STOP")]
    safety_stop: Option<bool>,
    /// The safety stop also brakes for the cells where the network's motion head believes a
    /// road user will be 1.5 s later (needs a checkpoint with the head) [default: the
    /// checkpoint's setting].
    #[arg(long, env = "SSR_AGENT_SAFETY_MOTION")]
    safety_motion: Option<bool>,
    /// How the network gets its history: `chain` (the frame 0.5 s back with the frame 1 s back
    /// as its history; three BEV passes a step), `link` (the frame 0.5 s back on its own; two
    /// passes) or `recursive` (each step's BEV is the history of the step 0.5 s later; one
    /// pass). Serve a checkpoint with the history it was trained with (`ssr-agent train
    /// --history`) [default: the checkpoint's own (its `history` metadata, which `ssr-agent
    /// control` prints); `recursive` for checkpoints from before the chain].
    #[arg(long, env = "SSR_AGENT_HISTORY")]
    history: Option<History>,
    /// This server's name among replicas behind a load balancer, sent with every answer as
    /// `x-ssrdrive-replica` metadata [default: HOSTNAME:PORT].
    #[arg(long, env = "SSR_AGENT_REPLICA_ID")]
    replica_id: Option<String>,
    /// Also shut down (draining as on SIGTERM) when standard input reaches its end: a parent
    /// that keeps a pipe to it open (sim-bridge's local server does) takes the server with it
    /// when it ends, even when it is killed.
    #[arg(long, env = "SSR_AGENT_EXIT_WITH_STDIN")]
    exit_with_stdin: bool,
}

/// `--metrics-listen`: an address, or none (`off`).
#[derive(Debug, Clone, Copy)]
struct MetricsListen(Option<SocketAddr>);

fn parse_metrics_listen(value: &str) -> Result<MetricsListen, String> {
    serve::config::parse_metrics_listen(value).map(MetricsListen)
}

impl ServeArgs {
    /// The effective settings, validated.
    pub fn resolve(&self) -> anyhow::Result<ServeConfig> {
        let mut config = match &self.config {
            Some(path) => ServeConfig::from_file(path)?,
            None => ServeConfig::default(),
        };
        fn set<T: Clone>(target: &mut T, value: &Option<T>) {
            if let Some(value) = value {
                *target = value.clone();
            }
        }
        set(&mut config.listen, &self.listen);
        if let Some(MetricsListen(address)) = self.metrics_listen {
            config.metrics_listen = address;
        }
        if self.checkpoint.is_some() {
            config.checkpoint = self.checkpoint.clone();
            config.untrained_config = None;
        }
        if self.untrained_config.is_some() {
            config.untrained_config = self.untrained_config.clone();
            config.checkpoint = None;
        }
        set(&mut config.max_episodes, &self.max_episodes);
        set(&mut config.idle_timeout_s, &self.idle_timeout_s);
        set(&mut config.max_batch, &self.max_batch);
        set(&mut config.max_queue_delay_ms, &self.max_queue_delay_ms);
        set(&mut config.max_queue, &self.max_queue);
        set(&mut config.model_threads, &self.model_threads);
        set(&mut config.compute_threads, &self.compute_threads);
        set(&mut config.request_timeout_s, &self.request_timeout_s);
        set(&mut config.max_message_mib, &self.max_message_mib);
        set(&mut config.max_pixels_per_step, &self.max_pixels_per_step);
        set(&mut config.max_decoded_mib, &self.max_decoded_mib);
        set(&mut config.drain_grace_s, &self.drain_grace_s);
        set(&mut config.drain_timeout_s, &self.drain_timeout_s);
        set(&mut config.log_format, &self.log_format);
        set(&mut config.backend, &self.backend);
        config.unstick = self.unstick.or(config.unstick);
        config.safety_stop = self.safety_stop.or(config.safety_stop);
        config.safety_motion = self.safety_motion.or(config.safety_motion);
        config.history = self.history.or(config.history);
        if self.replica_id.is_some() {
            config.replica_id = self.replica_id.clone();
        }
        config.validate()?;
        Ok(config)
    }
}

/// Serve until Ctrl-C or SIGTERM (or the end of standard input with `--exit-with-stdin`),
/// then drain.
pub fn run(args: &ServeArgs) -> anyhow::Result<()> {
    let config = args.resolve()?;
    super::init_logs(config.log_format);
    let device = config.backend.device()?;
    let (policy, info) = serve::load_policy(&config, &device)?;
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?
        .block_on(async {
            let listeners = serve::Listeners::bind(&config).await?;
            // Parents that asked for port 0 read the real ports from these lines.
            println!("listening on {}", listeners.grpc.local_addr()?);
            if let Some(metrics) = &listeners.metrics {
                println!("metrics on http://{}/metrics", metrics.local_addr()?);
            }
            let shutdown = shutdown_signal(args.exit_with_stdin.then(stdin_closed));
            serve::run(listeners, config, policy, info, shutdown).await
        })
}

/// Resolves when standard input reaches its end (or fails), read on a thread of its own.
fn stdin_closed() -> tokio::sync::oneshot::Receiver<()> {
    let (closed, receiver) = tokio::sync::oneshot::channel();
    std::thread::spawn(move || {
        let _ = std::io::copy(&mut std::io::stdin().lock(), &mut std::io::sink());
        let _ = closed.send(());
    });
    receiver
}

/// Ctrl-C, SIGTERM on Unix (what container runtimes send), or `stdin` closing when given.
async fn shutdown_signal(stdin: Option<tokio::sync::oneshot::Receiver<()>>) {
    let stdin_closed = async {
        match stdin {
            Some(closed) => {
                let _ = closed.await;
                tracing::info!("standard input closed: shutting down");
            }
            None => std::future::pending().await,
        }
    };
    let interrupt = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut signal) => {
                signal.recv().await;
            }
            Err(_) => std::future::pending().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        () = interrupt => {}
        () = terminate => {}
        () = stdin_closed => {}
    }
}
