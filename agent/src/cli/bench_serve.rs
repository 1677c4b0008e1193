//! `ssr-agent bench-serve`: what serving costs, measured against a real server on loopback in
//! the same process (random weights; speed does not depend on them).
//!
//! 1. Overhead: one episode stepped in process (`SsrPolicy::step`) and over gRPC (`Step`), with
//!    identical inputs, in alternating blocks so machine noise hits both alike: median and p99
//!    of each and the overhead of the median.
//! 2. Throughput: N episodes, each on its own connection, stepping back to back for a fixed
//!    time, in four server set-ups: one model thread without batching (max batch 1, the
//!    baseline), with dynamic batching, several model threads without batching, and both:
//!    steps per second, the gain over the baseline, median and p99 latency, mean batch size.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use ssr_agent::device::Backend;
use ssr_agent::policy::SsrPolicy;
use ssr_agent::serve::{self, ModelInfo, ServeConfig, decode};
use ssrdrive_proto::command::RoadOption;
use ssrdrive_proto::v1;
use ssrdrive_proto::v1::agent_service_client::AgentServiceClient;
use ssrdrive_proto::wire;
use ssrdrive_support::stats::percentile;
use tonic::transport::Channel;

#[derive(clap::Args, Debug)]
pub struct BenchServeArgs {
    /// Model config: a preset or a JSON file (random weights).
    #[arg(long, default_value = "cpu-default")]
    config: String,
    /// Steps timed on each side of the overhead comparison.
    #[arg(long, default_value_t = 200)]
    steps: usize,
    /// Concurrent episodes of the throughput runs (comma separated).
    #[arg(long, value_delimiter = ',', default_value = "1,4,8,16")]
    episodes: Vec<usize>,
    /// Seconds timed per throughput run (after one second of warm-up).
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Largest batch with batching on.
    #[arg(long, default_value_t = 16)]
    max_batch: usize,
    /// Queue delay with batching on, milliseconds.
    #[arg(long, default_value_t = 2.0)]
    max_queue_delay_ms: f64,
    /// Model threads of the multi-threaded set-ups.
    #[arg(long, default_value_t = 2)]
    model_threads: usize,
    /// Skip the overhead comparison.
    #[arg(long)]
    no_overhead: bool,
}

fn sorted(mut samples: Vec<f64>) -> Vec<f64> {
    samples.sort_by(f64::total_cmp);
    samples
}

/// A step of the expected rig with a fixed noise pattern (the same bytes every run).
fn step_request(episode_id: &str, frame_index: u64, rig: &v1::Rig) -> v1::StepRequest {
    let mut state = 0x2545_f491_u32;
    v1::StepRequest {
        episode_id: episode_id.into(),
        frame_index,
        timestamp_s: frame_index as f64 * 0.05,
        images: wire::rgb_images(rig, |c| {
            (0..c.width * c.height * 3)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 17;
                    state ^= state << 5;
                    (state >> 24) as u8
                })
                .collect()
        }),
        speed_mps: 6.0,
        pose: Some(v1::Pose {
            x: frame_index as f64 * 0.3,
            ..Default::default()
        }),
        command: RoadOption::LaneFollow.value(),
        target_point: Some(v1::EgoPoint { x: 15.0, y: 1.0 }),
        debug: false,
    }
}

/// A server on a free loopback port, running until [`LoopbackServer::stop`].
struct LoopbackServer {
    uri: String,
    stop: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<anyhow::Result<()>>,
}

impl LoopbackServer {
    async fn start(
        config: ServeConfig,
        policy: SsrPolicy,
        info: ModelInfo,
    ) -> anyhow::Result<Self> {
        let listeners = serve::Listeners::bind(&config).await?;
        let uri = format!("http://{}", listeners.grpc.local_addr()?);
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let task = tokio::spawn(serve::run(listeners, config, policy, info, async {
            let _ = stopped.await;
        }));
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            if let Ok(channel) = connect(&uri).await {
                let mut health = tonic_health::pb::health_client::HealthClient::new(channel);
                if let Ok(reply) = health
                    .check(tonic_health::pb::HealthCheckRequest::default())
                    .await
                    && reply.get_ref().status
                        == tonic_health::pb::health_check_response::ServingStatus::Serving as i32
                {
                    break;
                }
            }
            if task.is_finished() {
                return match task.await? {
                    Ok(()) => Err(anyhow::anyhow!("the bench server stopped before serving")),
                    Err(error) => Err(error),
                };
            }
            anyhow::ensure!(Instant::now() < deadline, "the bench server did not start");
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Ok(Self {
            uri,
            stop: Some(stop),
            task,
        })
    }

    async fn stop(mut self) -> anyhow::Result<()> {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        (&mut self.task).await?
    }
}

async fn connect(uri: &str) -> anyhow::Result<Channel> {
    Ok(Channel::from_shared(uri.to_string())?.connect().await?)
}

async fn start_episode(
    client: &mut AgentServiceClient<Channel>,
    rig: &v1::Rig,
) -> anyhow::Result<String> {
    Ok(client
        .start_episode(v1::StartEpisodeRequest {
            rig: Some(rig.clone()),
            client: "bench-serve".into(),
            ..Default::default()
        })
        .await?
        .into_inner()
        .episode_id)
}

fn server_config(max_batch: usize, max_queue_delay_ms: f64, model_threads: usize) -> ServeConfig {
    ServeConfig {
        listen: "127.0.0.1:0".parse().expect("an address"),
        metrics_listen: None,
        max_batch,
        max_queue_delay_ms,
        model_threads,
        ..ServeConfig::default()
    }
}

pub fn run(args: &BenchServeArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.steps > 0, "--steps must be at least 1");
    anyhow::ensure!(
        args.seconds.is_finite() && args.seconds > 0.0,
        "--seconds must be positive"
    );
    let device = Backend::Cpu.device()?;
    let model_config = ServeConfig {
        untrained_config: Some(args.config.clone()),
        ..ServeConfig::default()
    };
    let (policy, info) = serve::load_policy(&model_config, &device)?;
    let rig = wire::rig_to_proto(&info.expected_rig);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    println!(
        "bench-serve: config {}, rig {}x{} ({} camera), loopback gRPC, {} threads",
        info.config.name,
        rig.cameras[0].width,
        rig.cameras[0].height,
        rig.cameras.len(),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    if !args.no_overhead {
        runtime.block_on(overhead(args, &policy, &info, &rig))?;
    }
    runtime.block_on(throughput(args, &policy, &info, &rig))
}

async fn overhead(
    args: &BenchServeArgs,
    policy: &SsrPolicy,
    info: &ModelInfo,
    rig: &v1::Rig,
) -> anyhow::Result<()> {
    let server =
        LoopbackServer::start(server_config(1, 0.0, 1), policy.clone(), info.clone()).await?;
    let mut client = AgentServiceClient::new(connect(&server.uri).await?);
    let remote_id = start_episode(&mut client, rig).await?;
    let rust_rig = info.expected_rig.clone();
    let mut local = policy.new_episode();
    let (mut in_process, mut over_grpc) = (Vec::new(), Vec::new());
    let rounds = 4;
    let per_round = args.steps.div_ceil(rounds);
    let warmup = 5;
    let mut frame = 0u64;
    for _ in 0..rounds {
        for i in 0..per_round + warmup {
            let request = step_request("", frame, rig);
            let input = decode::step_input(&request, &rust_rig)?;
            let started = Instant::now();
            policy.step(&mut local, &input)?;
            if i >= warmup {
                in_process.push(started.elapsed().as_secs_f64() * 1e3);
            }
            frame += 1;
        }
        for i in 0..per_round + warmup {
            let request = step_request(&remote_id, frame, rig);
            let started = Instant::now();
            client.step(request).await?;
            if i >= warmup {
                over_grpc.push(started.elapsed().as_secs_f64() * 1e3);
            }
            frame += 1;
        }
    }
    server.stop().await?;
    let (a, b) = (sorted(in_process), sorted(over_grpc));
    let (a50, b50) = (percentile(&a, 0.5), percentile(&b, 0.5));
    println!(
        "\nper-step latency, one episode, {} steps each (ms):",
        a.len()
    );
    println!("  {:<12} {:>8} {:>8}", "", "median", "p99");
    println!(
        "  {:<12} {:>8.2} {:>8.2}",
        "in process",
        a50,
        percentile(&a, 0.99)
    );
    println!(
        "  {:<12} {:>8.2} {:>8.2}",
        "gRPC",
        b50,
        percentile(&b, 0.99)
    );
    println!(
        "  overhead: {:+.2} ms per step = {:+.1} % of the in-process median",
        b50 - a50,
        100.0 * (b50 - a50) / a50
    );
    Ok(())
}

/// Steps per second, sorted latencies (ms) and mean batch size of one throughput run.
struct RunResult {
    steps_per_second: f64,
    latencies: Vec<f64>,
    mean_batch: f64,
}

async fn throughput(
    args: &BenchServeArgs,
    policy: &SsrPolicy,
    info: &ModelInfo,
    rig: &v1::Rig,
) -> anyhow::Result<()> {
    let threads = args.model_threads;
    let setups = [
        ("1 thread, no batching", server_config(1, 0.0, 1)),
        (
            "1 thread, batching",
            server_config(args.max_batch, args.max_queue_delay_ms, 1),
        ),
        ("N threads, no batching", server_config(1, 0.0, threads)),
        (
            "N threads, batching",
            server_config(args.max_batch, args.max_queue_delay_ms, threads),
        ),
    ];
    println!(
        "\nthroughput, episodes stepping back to back for {:.0} s each (batching: max batch {}, \
         queue delay {} ms; N = {threads} model threads):",
        args.seconds, args.max_batch, args.max_queue_delay_ms
    );
    println!(
        "  {:>8}  {:<24} {:>9} {:>7} {:>16} {:>10}",
        "episodes", "server", "steps/s", "gain", "p50/p99 ms", "mean batch"
    );
    for &episodes in &args.episodes {
        anyhow::ensure!(episodes > 0, "--episodes values must be at least 1");
        let mut baseline = None;
        for (name, config) in &setups {
            let run = throughput_run(args, policy, info, rig, episodes, config.clone()).await?;
            let base = *baseline.get_or_insert(run.steps_per_second);
            println!(
                "  {:>8}  {:<24} {:>9.1} {:>6.2}x {:>16} {:>10.2}",
                episodes,
                name,
                run.steps_per_second,
                run.steps_per_second / base,
                format!(
                    "{:.1}/{:.1}",
                    percentile(&run.latencies, 0.5),
                    percentile(&run.latencies, 0.99)
                ),
                run.mean_batch
            );
        }
    }
    Ok(())
}

async fn throughput_run(
    args: &BenchServeArgs,
    policy: &SsrPolicy,
    info: &ModelInfo,
    rig: &v1::Rig,
    episodes: usize,
    config: ServeConfig,
) -> anyhow::Result<RunResult> {
    let server = LoopbackServer::start(config, policy.clone(), info.clone()).await?;
    let measuring = Arc::new(AtomicBool::new(false));
    let done = Arc::new(AtomicBool::new(false));
    let mut tasks = Vec::new();
    for _ in 0..episodes {
        let mut client = AgentServiceClient::new(connect(&server.uri).await?);
        let id = start_episode(&mut client, rig).await?;
        let request = step_request(&id, 0, rig);
        let (measuring, done) = (Arc::clone(&measuring), Arc::clone(&done));
        tasks.push(tokio::spawn(async move {
            let mut samples = Vec::new();
            let mut batch_sum = 0u64;
            let mut frame = 0;
            while !done.load(Ordering::Relaxed) {
                let mut request = request.clone();
                request.frame_index = frame;
                frame += 1;
                let started = Instant::now();
                let answer = client.step(request).await?.into_inner();
                if measuring.load(Ordering::Relaxed) && !done.load(Ordering::Relaxed) {
                    samples.push(started.elapsed().as_secs_f64() * 1e3);
                    batch_sum += u64::from(answer.timings.map_or(1, |t| t.batch_size));
                }
            }
            anyhow::Ok((samples, batch_sum))
        }));
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    measuring.store(true, Ordering::Relaxed);
    let started = Instant::now();
    tokio::time::sleep(Duration::from_secs_f64(args.seconds)).await;
    done.store(true, Ordering::Relaxed);
    let elapsed = started.elapsed().as_secs_f64();
    let (mut latencies, mut batch_sum) = (Vec::new(), 0);
    for task in tasks {
        let (samples, batches) = task.await.context("a bench client failed")??;
        latencies.extend(samples);
        batch_sum += batches;
    }
    server.stop().await?;
    Ok(RunResult {
        steps_per_second: latencies.len() as f64 / elapsed,
        mean_batch: batch_sum as f64 / latencies.len().max(1) as f64,
        latencies: sorted(latencies),
    })
}
