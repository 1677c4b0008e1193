//! `sim-bridge replay`: re-feed step logs (from `eval --record`) to an agent server and report
//! latency, drift from the recorded answers and open-loop metrics.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Args;
use sim_bridge::replay::{ReplayReport, Spread, log::read_log, replay};

use sim_bridge::client::local::LocalRole;

use super::args::{parse_seconds, server_target};

#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// Step log files (`*.ssrlog`), or folders of them.
    #[arg(required = true)]
    logs: Vec<PathBuf>,
    /// The server: `grpc://HOST:PORT`, or `local` (starts `ssr-agent serve` for the run).
    #[arg(long, default_value = "local")]
    agent: String,
    /// Deadline of each step, seconds.
    #[arg(long, default_value = "30", value_parser = parse_seconds)]
    call_timeout: Duration,
    /// Also write the reports as a JSON list here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Ask the server for its debug outputs and write one JSON line per replayed tick here: the
    /// log, frame, time, speed, replayed and recorded control, the hazard and light heads'
    /// probabilities, which controller rule acted (turning, unsticking, safety_stop) and the
    /// log's lights within 60 m in the ego's frame (state, ahead, left, faces_ego).
    #[arg(long, value_name = "FILE.jsonl")]
    ticks: Option<PathBuf>,
}

/// The log files named, folders expanded (sorted).
fn log_files(paths: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for path in paths {
        if path.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(path)
                .with_context(|| format!("reading {}", path.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "ssrlog"))
                .collect();
            found.sort();
            files.extend(found);
        } else {
            files.push(path.clone());
        }
    }
    if files.is_empty() {
        bail!("no .ssrlog files in {paths:?}");
    }
    Ok(files)
}

fn spread(s: Option<Spread>) -> String {
    s.map_or("-".into(), |s| format!("{:.3}/{:.3}", s.mean, s.max))
}

fn print(report: &ReplayReport, path: &std::path::Path) {
    println!(
        "{}: route {} ({} ticks{}, recorded with {})",
        path.display(),
        report.route_id,
        report.ticks,
        if report.truncated { ", cut short" } else { "" },
        report.recorded_agent
    );
    println!(
        "  latency (ms): {}; codes {:?}",
        report.latency_ms, report.codes
    );
    println!(
        "  |replayed - recorded| mean/max: steer {} throttle {} brake {} trajectory {} m",
        spread(report.steer_diff),
        spread(report.throttle_diff),
        spread(report.brake_diff),
        spread(report.trajectory_drift_m)
    );
    for h in &report.open_loop {
        let value =
            |v: Option<f64>, scale: f64| v.map_or("-".into(), |v| format!("{:.3}", v * scale));
        println!(
            "  open loop at {:.0} s: L2 {} m, collisions {} % ({} samples)",
            h.horizon_s,
            value(h.l2_m, 1.0),
            value(h.collision_rate, 100.0),
            h.samples
        );
    }
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let files = log_files(&args.logs)?;
    let (target, _local) = server_target(&args.agent, LocalRole::Driving { runs: 1 })?;
    let mut reports = Vec::new();
    let mut tick_lines = String::new();
    for path in &files {
        let log = read_log(path)?;
        if log.truncated {
            eprintln!(
                "warning: {} was cut short; replaying its {} whole ticks",
                path.display(),
                log.ticks.len()
            );
        }
        let (report, traces) = replay(&log, &target, args.call_timeout, args.ticks.is_some())?;
        for trace in traces {
            let mut line = serde_json::to_value(trace)?;
            line["log"] = serde_json::json!(path);
            tick_lines.push_str(&line.to_string());
            tick_lines.push('\n');
        }
        print(&report, path);
        reports.push(report);
    }
    if let Some(out) = &args.out {
        super::write_output(out, &serde_json::to_string_pretty(&reports)?)?;
    }
    if let Some(ticks) = &args.ticks {
        super::write_output(ticks, &tick_lines)?;
    }
    Ok(())
}
