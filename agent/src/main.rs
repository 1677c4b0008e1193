//! `ssr-agent`: serve the SSR network over gRPC, train it, benchmark it, show model configs, inspect
//! checkpoints.

mod allocator;
mod bench;
mod bench_serve;
mod serve_args;
mod train_args;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use ssr_agent::checkpoint;
use ssr_agent::model::config::SsrConfig;
use ssr_agent::serve::{self, LogFormat};

#[derive(Parser)]
#[command(
    name = "ssr-agent",
    version,
    about = "SSR end-to-end driving network (Burn): gRPC agent server, benchmarks, configs, checkpoints"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Serve the network over gRPC (ssrdrive.v1.AgentService, see proto/): per-episode
    /// temporal state, dynamic batching, health, reflection, Prometheus metrics. Settings come
    /// from --config FILE, then SSR_AGENT_* variables, then flags. Stops on Ctrl-C or SIGTERM
    /// after draining in-flight requests.
    Serve(Box<serve_args::ServeArgs>),
    /// Train the network on a dataset from `sim-bridge collect`: TCP's imitation losses plus
    /// SSR's future-BEV loss, AdamW with warm-up and decay, validation on held-out routes
    /// (open-loop L2 at 1/2/3 s, control errors), checkpoints, resume (--resume). Ablations:
    /// --no-stl, --no-ffp, --tokens N.
    Train(Box<train_args::TrainArgs>),
    /// Time the network: forward latency with a per-stage breakdown (backbone, BEV encoder,
    /// STL, head), a full policy step from 900x256 camera frames, and optionally a training step.
    /// Without --config it runs the standard set: cpu-default at batch 1 and 8, paper at batch 1.
    Bench(bench::BenchArgs),
    /// Time serving: per-step latency in process vs over gRPC on loopback (the overhead), and
    /// throughput with 1, 4, 8, 16 concurrent episodes with and without dynamic batching.
    BenchServe(bench_serve::BenchServeArgs),
    /// Print a model config preset as JSON (a starting point for your own).
    Config {
        /// Preset name.
        #[arg(value_parser = clap::builder::PossibleValuesParser::new(SsrConfig::PRESETS))]
        preset: String,
    },
    /// Show what a checkpoint holds (config, metadata, size) after checking it is complete.
    Inspect { checkpoint: PathBuf },
}

fn init_logs(format: LogFormat) {
    ssrdrive_proto::logging::init("info", format == LogFormat::Json);
}

fn main() -> ExitCode {
    allocator::keep_freed_memory();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Serve(args) => serve(&args),
        command => {
            init_logs(LogFormat::Human);
            run_tool(command)
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {}", ssrdrive_proto::error_text::error_text(&error));
            ExitCode::FAILURE
        }
    }
}

fn serve(args: &serve_args::ServeArgs) -> anyhow::Result<()> {
    let config = args.resolve()?;
    init_logs(config.log_format);
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
            serve::run(listeners, config, policy, info, shutdown_signal()).await
        })
}

/// Ctrl-C, or SIGTERM on Unix (what container runtimes send).
async fn shutdown_signal() {
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
    }
}

fn run_tool(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Serve(_) => unreachable!("served by main"),
        Command::Bench(args) => bench::run(&args),
        Command::BenchServe(args) => bench_serve::run(&args),
        Command::Train(args) => train_args::run(&args),
        Command::Config { preset } => {
            let config = SsrConfig::preset(&preset).expect("clap checked the name");
            println!(
                "{}",
                serde_json::to_string_pretty(&config).expect("configs serialise")
            );
            Ok(())
        }
        Command::Inspect { checkpoint: path } => {
            checkpoint::inspect(&path).map_err(Into::into).map(|info| {
                println!(
                    "checkpoint: {} ({} bytes, {} tensors)",
                    path.display(),
                    info.bytes,
                    info.tensors
                );
                for (key, value) in &info.metadata {
                    println!("{key}: {value}");
                }
                println!(
                    "config: {}",
                    serde_json::to_string_pretty(&info.config).expect("configs serialise")
                );
            })
        }
    }
}
