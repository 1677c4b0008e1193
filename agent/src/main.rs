//! `ssr-agent`: benchmark the SSR network, show model configs, inspect checkpoints.

mod bench;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use ssr_agent::checkpoint;
use ssr_agent::model::config::SsrConfig;

#[derive(Parser)]
#[command(
    name = "ssr-agent",
    version,
    about = "SSR end-to-end driving network (Burn): benchmarks, configs, checkpoints"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Time the network: forward latency with a per-stage breakdown (backbone, BEV encoder,
    /// STL, head), a full policy step from 900x256 camera frames, and optionally a training step.
    /// Without --config it runs the standard set: cpu-default at batch 1 and 8, paper at batch 1.
    Bench(bench::BenchArgs),
    /// Print a model config preset as JSON (a starting point for your own).
    Config {
        /// Preset name.
        #[arg(value_parser = clap::builder::PossibleValuesParser::new(SsrConfig::PRESETS))]
        preset: String,
    },
    /// Show what a checkpoint holds (config, metadata, size) after checking it is complete.
    Inspect { checkpoint: PathBuf },
}

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bench(args) => bench::run(&args),
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
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
