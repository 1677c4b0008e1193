//! `sim-bridge results`: work on leaderboard results files; `merge` joins the files of one
//! campaign's shares ([`sim_bridge::eval::merge`]), `compare` pairs two agents' runs
//! ([`sim_bridge::eval::compare`]), `summary` tabulates files side by side
//! ([`sim_bridge::eval::suite::figures_table`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, Subcommand};
use sim_bridge::eval::compare::{Runs, compare, runs_of};
use sim_bridge::eval::merge::{Part, merge};
use sim_bridge::eval::suite::{Figures, figures_table};
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
    /// Pair two agents' runs (same part, route and repetition) and show each side's mean DS, RC
    /// and IS, the paired difference (second minus first) and its 95 % confidence interval: an
    /// interval that holds 0 means these runs cannot tell the two apart (closed loop, one run's
    /// DS swings by tens of points from the smallest change).
    Compare(CompareArgs),
    /// One line per results file (a suite's output folder counts as its parts' files): runs,
    /// completed, km driven, mean DS, RC and IS, success rate and infractions per km driven;
    /// then a line for all of them together and their failure classes. For tables of
    /// campaigns run apart (towns, traffic modes, checkpoints).
    Summary(SummaryArgs),
}

#[derive(Debug, Args)]
pub struct SummaryArgs {
    /// Results files, or suites' output folders.
    #[arg(required = true)]
    paths: Vec<PathBuf>,
}

#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The first agent's results: a results file, or a suite's output folder (`eval --suite
    /// NAME --out DIR`: one file per part).
    first: PathBuf,
    /// The second agent's, the same way.
    second: PathBuf,
    /// Also write the comparison as JSON here.
    #[arg(long)]
    out: Option<PathBuf>,
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
        ResultsCommand::Compare(args) => run_compare(args),
        ResultsCommand::Summary(args) => run_summary(args),
    }
}

fn read_results(path: &Path) -> anyhow::Result<Results> {
    let text = read_capped_text(path, MAX_RESULTS_BYTES)
        .with_context(|| format!("reading {}", path.display()))?;
    Results::from_json(&text).with_context(|| format!("reading {}", path.display()))
}

/// The results files at `path`: the file itself, or every part's file in a suite's folder
/// (`suite.json`, the suite's summary, left out), by name.
fn results_files(path: &Path) -> anyhow::Result<Vec<PathBuf>> {
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut files = Vec::new();
    let entries = std::fs::read_dir(path).with_context(|| format!("reading {}", path.display()))?;
    for entry in entries {
        let file = entry
            .with_context(|| format!("reading {}", path.display()))?
            .path();
        if file.extension().is_some_and(|e| e == "json") && part_of(&file) != "suite" {
            files.push(file);
        }
    }
    if files.is_empty() {
        bail!("{} holds no results files", path.display());
    }
    files.sort();
    Ok(files)
}

/// A suite part's name: its results file's stem.
fn part_of(file: &Path) -> &str {
    file.file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or_default()
}

/// The runs of a results file, or of every part's file in a suite's folder (named by part).
fn read_runs(path: &Path) -> anyhow::Result<Runs> {
    let mut runs = Runs::new();
    for file in results_files(path)? {
        let part = if path.is_dir() { part_of(&file) } else { "" };
        runs.extend(runs_of(part, &read_results(&file)?.checkpoint.records));
    }
    Ok(runs)
}

fn run_summary(args: SummaryArgs) -> anyhow::Result<()> {
    let mut files = Vec::new();
    for path in &args.paths {
        for file in results_files(path)? {
            let records = read_results(&file)?.checkpoint.records;
            files.push((file.display().to_string(), records));
        }
    }
    let all: Vec<_> = files.iter().flat_map(|(_, r)| r.iter().cloned()).collect();
    let all = Figures::of(&all);
    let figures: Vec<(String, Figures)> = files
        .iter()
        .map(|(name, records)| (name.clone(), Figures::of(records)))
        .collect();
    let total = format!("all ({} files)", figures.len());
    let mut lines: Vec<(&str, &Figures)> = figures.iter().map(|(n, f)| (n.as_str(), f)).collect();
    if figures.len() > 1 {
        lines.push((&total, &all));
    }
    super::print_stdout(&figures_table(&lines, &all))
}

fn run_compare(args: CompareArgs) -> anyhow::Result<()> {
    let (first, second) = (read_runs(&args.first)?, read_runs(&args.second)?);
    let Some(c) = compare(&first, &second) else {
        bail!(
            "{} and {} share no run (same part, route id and repetition)",
            args.first.display(),
            args.second.display()
        );
    };
    let mut report = format!(
        "{} runs paired ({} only in the first, {} only in the second)\n",
        c.pairs, c.only_first, c.only_second
    );
    report.push_str("      first   second   second - first (95 % interval)\n");
    for (name, p, digits) in [("DS", &c.ds, 2), ("RC", &c.rc, 2), ("IS", &c.is, 3)] {
        let interval = p.half_width.map_or("-".to_string(), |h| {
            format!(
                "+/- {h:.digits$}{}",
                if p.tells_apart() { "" } else { ", holds 0" }
            )
        });
        report.push_str(&format!(
            "{name}  {:>7.digits$}  {:>7.digits$}   {:+.digits$} ({interval})\n",
            p.first, p.second, p.difference
        ));
    }
    report.push_str(&format!(
        "DS per run: second higher {}, lower {}, equal {}",
        c.second_better, c.second_worse, c.same
    ));
    if let Some(out) = &args.out {
        super::write_output(out, &serde_json::to_string_pretty(&c)?)?;
    }
    super::print_stdout(&report)
}

fn run_merge(args: MergeArgs) -> anyhow::Result<()> {
    let parts = args
        .parts
        .iter()
        .map(|path| {
            Ok(Part {
                path: path.clone(),
                results: read_results(path)?,
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
    let runs = merged.results.plan.as_ref().map_or(0, |p| p.runs);
    let outcome = if merged.missing.is_empty() {
        format!(
            "merged {} files, all {runs} runs, into {}",
            parts.len(),
            args.out.display()
        )
    } else {
        format!(
            "merged {} files into {}: {} of {runs} runs missing (listed in its \
             global record's meta.exceptions)",
            parts.len(),
            args.out.display(),
            merged.missing.len()
        )
    };
    super::print_stdout(&format!("{}\n{outcome}", summary_table(&merged.results)))
}
