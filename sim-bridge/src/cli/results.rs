//! `sim-bridge results`: work on leaderboard results files; `merge` joins the files of one
//! campaign's shares ([`sim_bridge::eval::merge`]).

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use sim_bridge::eval::merge::{Part, merge};
use sim_bridge::scoring::{Results, summary_table};
use ssrdrive_support::files::read_capped_text;

/// The largest results file read (a record is about 1 kB: room for 100,000 runs).
const MAX_RESULTS_BYTES: u64 = 128 << 20;

#[derive(Debug, Subcommand)]
pub enum ResultsCommand {
    /// Join the results files of one campaign's shares (`eval --shard K/N`) into the file one
    /// process would have written: refuses files of other campaigns (routes, settings, seed,
    /// agent, simulator), runs found twice, and missing runs unless --allow-missing.
    Merge(MergeArgs),
}

#[derive(Debug, Args)]
pub struct MergeArgs {
    /// The shares' results files.
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// Where to write the merged results.
    #[arg(long)]
    out: PathBuf,
    /// Write a partial file when runs are missing ("Finished with missing data", each missing
    /// run listed in the global record's meta.exceptions) instead of refusing.
    #[arg(long)]
    allow_missing: bool,
}

pub fn run(command: ResultsCommand) -> anyhow::Result<()> {
    match command {
        ResultsCommand::Merge(args) => run_merge(args),
    }
}

fn run_merge(args: MergeArgs) -> anyhow::Result<()> {
    let parts = args
        .parts
        .iter()
        .map(|path| {
            let text = read_capped_text(path, MAX_RESULTS_BYTES)
                .with_context(|| format!("reading {}", path.display()))?;
            let results =
                Results::from_json(&text).with_context(|| format!("reading {}", path.display()))?;
            Ok(Part {
                path: path.clone(),
                results,
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    if args.parts.iter().any(|p| p == &args.out) {
        bail!(
            "--out {} is one of the parts: write the merged file elsewhere",
            args.out.display()
        );
    }
    let merged = merge(&parts, args.allow_missing)?;
    super::write_output(&args.out, &merged.results.to_json())?;
    println!("{}", summary_table(&merged.results));
    let runs = merged.results.plan.as_ref().map_or(0, |p| p.runs);
    if merged.missing.is_empty() {
        println!(
            "merged {} files, all {runs} runs, into {}",
            parts.len(),
            args.out.display()
        );
    } else {
        println!(
            "merged {} files into {}: {} of {runs} runs missing (listed in its \
             global record's meta.exceptions)",
            parts.len(),
            args.out.display(),
            merged.missing.len()
        );
    }
    Ok(())
}
