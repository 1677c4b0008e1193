//! `sim-bridge load`: N concurrent episodes at a fixed tick rate against an agent server, with
//! real frames (rendered from a bundled route while the expert drives, or read from a
//! dataset); reports count, RPS, latency percentiles, status codes and the server's memory.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sim_bridge::client::grpc::{GrpcAgent, GrpcOptions};
use sim_bridge::client::load::{LoadConfig, LoadProgress, LoadReport, run_load};
use sim_bridge::driver::{Agent, AgentError, Observation, RouteContext};
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::world::World;
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::Dataset;
use ssrdrive_proto::v1;
use ssrdrive_proto::wire;

use sim_bridge::client::local::LocalRole;

use super::args::{RouteArgs, WorldArgs, parse_positive, parse_seconds, server_target};

#[derive(Debug, Args)]
pub struct LoadArgs {
    /// The server: `grpc://HOST:PORT`, or `local` (starts `ssr-agent serve` for the run;
    /// SSR_AGENT_* variables configure it).
    #[arg(long, default_value = "local")]
    agent: String,
    /// Concurrent episodes, each on its own connection.
    #[arg(long, default_value_t = 8)]
    episodes: usize,
    /// Steps per second of each episode.
    #[arg(long, default_value = "10", value_parser = parse_positive)]
    rate: f64,
    /// Seconds of load.
    #[arg(long, default_value = "60", value_parser = parse_seconds)]
    duration: Duration,
    /// Distinct frames to cycle through.
    #[arg(long, default_value_t = 40)]
    frames: usize,
    /// Send frames of this dataset (its rig) instead of rendering some.
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// Camera rig to render and send: a preset or a JSON file [default: the rig the server
    /// expects].
    #[arg(long, conflicts_with = "dataset")]
    rig: Option<String>,
    /// The server's Prometheus URL (http://HOST:PORT/metrics), to report its memory before and
    /// after; `local` finds its own.
    #[arg(long)]
    metrics: Option<String>,
    /// Deadline of each step, seconds.
    #[arg(long, default_value = "10", value_parser = parse_seconds)]
    call_timeout: Duration,
    /// Also write the report as JSON here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    #[command(flatten)]
    route: RouteArgs,
    #[command(flatten)]
    world: WorldArgs,
}

pub fn run(args: LoadArgs) -> anyhow::Result<()> {
    if args.episodes == 0 || args.frames == 0 {
        bail!("--episodes and --frames must be at least 1");
    }
    let (target, local) = server_target(&args.agent, LocalRole::LoadTest)?;
    let metrics_url = args.metrics.clone().or_else(|| {
        local
            .as_ref()
            .and_then(|l| l.metrics_url().map(str::to_string))
    });

    let dataset = args.dataset.as_deref().map(Dataset::open).transpose()?;
    let rig = match (&dataset, &args.rig) {
        (Some(dataset), _) => Some(dataset.manifest.rig.clone()),
        (None, Some(spec)) => Some(Rig::from_name_or_file(spec)?),
        (None, None) => None,
    };
    let rig = probe_rig(&target, rig)?;

    let templates = match &dataset {
        Some(dataset) => dataset_templates(dataset, args.frames)?,
        None => rendered_templates(&args, &rig)?,
    };
    eprintln!(
        "{} frame(s) of {} camera(s) ready; {} episodes at {} Hz for {:.0} s",
        templates.len(),
        rig.cameras.len(),
        args.episodes,
        args.rate,
        args.duration.as_secs_f64()
    );
    let mut memory = Vec::new();
    if let Some(url) = &metrics_url {
        memory.push((0.0, resident_bytes(url)?));
    }
    let config = LoadConfig {
        target,
        episodes: args.episodes,
        rate_hz: args.rate,
        duration: args.duration,
        call_timeout: args.call_timeout,
        rig: wire::rig_to_proto(&rig),
    };
    let progress = Arc::new(LoadProgress::default());
    let bar = progress_bar(args.quiet, args.duration.as_secs_f64());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    let samples = Arc::new(std::sync::Mutex::new(memory));
    let report = runtime.block_on(async {
        let sampler = metrics_url
            .clone()
            .map(|url| spawn_memory_sampler(url, Arc::clone(&samples)));
        let ticker = spawn_ticker(bar.clone(), Arc::clone(&progress));
        let report = run_load(&config, Arc::new(templates), Arc::clone(&progress)).await;
        ticker.abort();
        if let Some(sampler) = sampler {
            sampler.abort();
        }
        report
    })?;
    bar.finish_and_clear();
    let mut memory = std::mem::take(&mut *samples.lock().expect("not poisoned"));
    if let Some(url) = &metrics_url {
        memory.push((report.duration_s, resident_bytes(url)?));
    }
    print_report(&report, &memory);
    match &args.out {
        Some(path) => write_report(path, &report, &memory),
        None => Ok(()),
    }
}

/// Connects once to `target`, which waits until it is SERVING, and returns the rig it expects
/// (`rig`, when given, is checked against it).
fn probe_rig(target: &str, rig: Option<Rig>) -> anyhow::Result<Rig> {
    let probe = GrpcAgent::connect(
        target,
        GrpcOptions {
            rig,
            ..GrpcOptions::default()
        },
    )?;
    eprintln!("server: {}", probe.name());
    Ok(probe.sensors().expect("a gRPC agent has a rig"))
}

/// Reads the server's resident memory every [`MEMORY_SAMPLE_PERIOD`] into `samples` (seconds
/// since the start, bytes) until aborted.
fn spawn_memory_sampler(
    url: String,
    samples: Arc<std::sync::Mutex<Vec<(f64, u64)>>>,
) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let started = tokio::time::Instant::now();
        loop {
            tokio::time::sleep(MEMORY_SAMPLE_PERIOD).await;
            let url = url.clone();
            if let Ok(Ok(bytes)) = tokio::task::spawn_blocking(move || resident_bytes(&url)).await {
                let at = started.elapsed().as_secs_f64();
                samples.lock().expect("not poisoned").push((at, bytes));
            }
        }
    })
}

/// Moves the progress bar twice a second with the steps and errors so far, until aborted.
fn spawn_ticker(bar: ProgressBar, progress: Arc<LoadProgress>) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        loop {
            tokio::time::sleep(Duration::from_millis(500)).await;
            bar.set_position(bar.elapsed().as_secs());
            bar.set_message(format!(
                "{} steps, {} errors",
                progress.steps.load(Ordering::Relaxed),
                progress.errors.load(Ordering::Relaxed)
            ));
        }
    })
}

/// The report and the server's memory samples as JSON at `path` (`--out`).
fn write_report(path: &Path, report: &LoadReport, memory: &[(f64, u64)]) -> anyhow::Result<()> {
    let json = serde_json::json!({
        "report": report,
        "server_rss_bytes": memory
            .iter()
            .map(|(at, bytes)| serde_json::json!({"at_s": at, "bytes": bytes}))
            .collect::<Vec<_>>(),
    });
    super::write_output(path, &serde_json::to_string_pretty(&json)?)
}

/// How often the server's memory is read during a run.
const MEMORY_SAMPLE_PERIOD: Duration = Duration::from_secs(10);

/// `memory`: (seconds into the run, resident bytes) of the server, before, during and after.
fn print_report(report: &LoadReport, memory: &[(f64, u64)]) {
    println!(
        "load: {} episodes at {} Hz for {:.1} s: {} steps, {:.1} steps/s",
        report.episodes, report.rate_hz, report.duration_s, report.count, report.rps
    );
    println!("latency from intended send (ms): {}", report.latency_ms);
    let codes: Vec<String> = report
        .codes
        .iter()
        .map(|(code, n)| format!("{code} {n}"))
        .collect();
    println!("status codes: {}", codes.join(", "));
    if report.behind_schedule > 0 {
        println!(
            "behind schedule: {} steps were due before the end but never sent (the server \
             answered slower than the episodes tick)",
            report.behind_schedule
        );
    }
    let mib = |bytes: u64| bytes as f64 / (1 << 20) as f64;
    if let (Some(&(_, start)), Some(&(_, end))) = (memory.first(), memory.last()) {
        // After a tenth of the run every batch size has been seen: growth from there on is
        // what a leak would show.
        let warm = memory
            .iter()
            .find(|(at, _)| *at >= report.duration_s / 10.0)
            .map_or(end, |&(_, bytes)| bytes);
        let peak = memory.iter().map(|&(_, bytes)| bytes).max().unwrap_or(end);
        println!(
            "server resident memory (MiB): {:.1} before, {:.1} after a tenth of the run, \
             {:.1} peak, {:.1} at the end ({} samples)",
            mib(start),
            mib(warm),
            mib(peak),
            mib(end),
            memory.len()
        );
    }
}

fn progress_bar(quiet: bool, seconds: f64) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(seconds.ceil() as u64);
    let style = ProgressStyle::with_template("load [{bar:40}] {pos}/{len} s  {msg}")
        .unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style.progress_chars("=> "));
    bar
}

/// `ssr_process_resident_bytes` from a Prometheus endpoint (plain HTTP/1.1 GET).
fn resident_bytes(url: &str) -> anyhow::Result<u64> {
    let rest = url
        .strip_prefix("http://")
        .with_context(|| format!("--metrics {url}: expected http://HOST:PORT/metrics"))?;
    let (host, path) = rest.split_once('/').unwrap_or((rest, "metrics"));
    let mut stream = TcpStream::connect(host).with_context(|| format!("connecting to {url}"))?;
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    write!(
        stream,
        "GET /{path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )?;
    let mut text = String::new();
    stream.read_to_string(&mut text)?;
    text.lines()
        .find_map(|line| {
            line.strip_prefix("ssr_process_resident_bytes ")?
                .trim()
                .parse()
                .ok()
        })
        .with_context(|| format!("{url} has no ssr_process_resident_bytes"))
}

/// Step templates from the first frames of a dataset, in episode order.
fn dataset_templates(dataset: &Dataset, wanted: usize) -> anyhow::Result<Vec<v1::StepRequest>> {
    let mut templates = Vec::new();
    for entry in &dataset.manifest.episode_list {
        for record in dataset.frames(&entry.name)? {
            let images = dataset.images(&entry.name, &record)?;
            if images.len() != dataset.manifest.rig.cameras.len() {
                bail!(
                    "episode {} frame {}: {} image(s) for a {}-camera rig",
                    entry.name,
                    record.index,
                    images.len(),
                    dataset.manifest.rig.cameras.len()
                );
            }
            let frames = images
                .into_iter()
                .zip(&dataset.manifest.rig.cameras)
                .map(|(image, camera)| sim_bridge::driver::CameraFrame {
                    camera: camera.id.clone(),
                    width: image.width,
                    height: image.height,
                    rgb: image.rgb,
                })
                .collect();
            let observation = Observation {
                time: record.time,
                frame: record.tick,
                speed: record.speed,
                position: record.position.into(),
                yaw: record.yaw,
                compass: Observation::compass_of(record.yaw),
                command: ssrdrive_proto::command::RoadOption::from_value(record.command)
                    .unwrap_or(ssrdrive_proto::command::RoadOption::LaneFollow),
                target_point: record.target_point.into(),
                frames,
            };
            templates.push(observation.step_request(""));
            if templates.len() == wanted {
                return Ok(templates);
            }
        }
    }
    if templates.is_empty() {
        bail!("the dataset holds no frames");
    }
    Ok(templates)
}

/// Step templates rendered while the expert drives the first selected route.
fn rendered_templates(args: &LoadArgs, rig: &Rig) -> anyhow::Result<Vec<v1::StepRequest>> {
    let (map, planned) = args.route.load()?;
    let first = &planned[0];
    let every = 5;
    let mut capture = Capture {
        expert: Expert::new(),
        rig: rig.clone(),
        every,
        wanted: args.frames,
        templates: Vec::new(),
    };
    let scoring = ScoringConfig {
        timeout: Some((args.frames as u64 * every) as f64 * sim_bridge::world::DT + 1.0),
        ..ScoringConfig::default()
    };
    let world = args.world.config(&map, args.world.seed)?;
    run_route(
        &map,
        &first.spec,
        &first.dense,
        &mut capture,
        world,
        scoring,
        0,
        0,
        |_| {},
    );
    if capture.templates.is_empty() {
        bail!("no frames were rendered from route {}", first.spec.id);
    }
    Ok(capture.templates)
}

/// The expert driving with the load rig, keeping a step template every `every` ticks.
struct Capture {
    expert: Expert,
    rig: Rig,
    every: u64,
    wanted: usize,
    templates: Vec<v1::StepRequest>,
}

impl Agent for Capture {
    fn name(&self) -> String {
        "expert (capturing frames)".into()
    }

    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.expert.start_route(ctx)
    }

    fn sensors(&self) -> Option<Rig> {
        Some(self.rig.clone())
    }

    fn wants_frames(&self, frame: u64) -> bool {
        frame.is_multiple_of(self.every) && self.templates.len() < self.wanted
    }

    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        if !obs.frames.is_empty() {
            self.templates.push(obs.step_request(""));
        }
        self.expert.run_step(obs, world)
    }
}
