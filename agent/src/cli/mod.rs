//! The `ssr-agent` command line: one module per subcommand ([`serve`], [`train`], [`bench`],
//! [`bench_serve`], [`control`], [`blend`]), the small ones (`config`, `inspect`) here.

pub mod bench;
pub mod bench_serve;
pub mod blend;
pub mod control;
pub mod serve;
pub mod train;

use std::path::PathBuf;

use clap::{Parser, Subcommand};
use ssr_agent::checkpoint;
use ssr_agent::model::config::SsrConfig;
use ssr_agent::serve::LogFormat;

#[derive(Parser)]
#[command(
    name = "ssr-agent",
    version,
    about = "SSR end-to-end driving network (Burn): gRPC agent server, benchmarks, configs, checkpoints"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Serve the network over gRPC (ssrdrive.v1.AgentService, see proto/): per-episode
    /// temporal state, dynamic batching, health, reflection, Prometheus metrics. Settings come
    /// from --config FILE, then SSR_AGENT_* variables, then flags. Stops on Ctrl-C or SIGTERM
    /// after draining in-flight requests.
    Serve(Box<serve::ServeArgs>),
    /// Train the network on a dataset from `sim-bridge collect`: TCP's imitation losses plus
    /// SSR's future-BEV loss, AdamW with warm-up and decay, validation on held-out routes
    /// (open-loop L2 at 1/2/3 s, control errors), checkpoints, resume (--resume). Ablations:
    /// --no-stl, --no-ffp, --tokens N.
    Train(Box<train::TrainArgs>),
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
    /// Print a checkpoint's controller settings (vehicle geometry, look-ahead, PID gains,
    /// fusion, unstick rule, safety stop) as JSON, or write a copy with some changed (--set
    /// JSON --out PATH). `serve` drives with them unless its flags override the unstick rule
    /// or the safety stop.
    Control(control::ControlArgs),
    /// Write a checkpoint whose weights are (1 - WEIGHT) x FROM + WEIGHT x TO, tensor by tensor
    /// (WiSE-FT: a fine-tuned network blended with the one it started from can keep what each
    /// does well away from the fine-tuning data). Both must share their model config, history
    /// mode and rig; the blend carries TO's controller settings.
    Blend(blend::BlendArgs),
}

/// Logging for one run: `format` at info level unless `RUST_LOG` says otherwise.
pub fn init_logs(format: LogFormat) {
    ssrdrive_support::logging::init("info", format == LogFormat::Json);
}

/// Run a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Serve(args) => serve::run(&args),
        command => {
            init_logs(LogFormat::Human);
            run_tool(command)
        }
    }
}

fn run_tool(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Serve(_) => unreachable!("served by run"),
        Command::Bench(args) => bench::run(&args),
        Command::BenchServe(args) => bench_serve::run(&args),
        Command::Train(args) => train::run(&args),
        Command::Control(args) => control::run(&args),
        Command::Blend(args) => blend::run(&args),
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
