//! `sim-bridge eval`: drive an agent over a route set (a [`Campaign`]: several at once with
//! `--jobs`, resumable with `--resume`), print a summary table, write the leaderboard results
//! JSON and, on request, a top-down picture of each run. `--suite NAME` drives each route file
//! of a named suite ([`sim_bridge::eval::suite`]) into one folder and sums them up.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Args;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use sim_bridge::client::grpc::{GrpcAgent, GrpcOptions};
use sim_bridge::client::local::LocalServer;
use sim_bridge::driver::Agent;
use sim_bridge::eval::campaign::{
    Campaign, CampaignObserver, CampaignReport, RunDone, run_campaign,
};
use sim_bridge::eval::shard::Shard;
use sim_bridge::eval::suite::{Figures, PartSummary, Suite, SuiteSummary, part_town, suite_table};
use sim_bridge::expert::Expert;
use sim_bridge::expert::oracle::{OraclePlan, sim_control_config};
use sim_bridge::map::Map;
use sim_bridge::render::topdown::write_run_png;
use sim_bridge::replay::logging_agent::LoggingAgent;
use sim_bridge::route::xml::RouteSpec;
use sim_bridge::scoring::{ScoringConfig, summary_table};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::dataset::safe_name;

use sim_bridge::client::local::LocalRole;

use super::args::{
    RouteArgs, WorldArgs, parse_count, parse_positive, parse_seconds, server_target,
};

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Who drives: `expert` (the privileged rule-based expert), `oracle-plan` (the agent
    /// server's controller fed the expert's plan and control, fused as served: checks the
    /// controller), `oracle-plan-only` (the same on the plan alone), `grpc://HOST:PORT` (an
    /// agent server, e.g. `ssr-agent serve`), or `local` (starts `ssr-agent serve` on a free
    /// loopback port for the run; SSR_AGENT_* variables configure it).
    #[arg(long, default_value = "expert")]
    agent: String,
    /// Camera rig sent to a gRPC agent: a preset or a JSON file [default: the rig the server
    /// expects].
    #[arg(long)]
    rig: Option<String>,
    /// Deadline of each gRPC call, seconds.
    #[arg(long, default_value = "30", value_parser = parse_seconds)]
    call_timeout: Duration,
    /// How long to wait for a gRPC agent to accept connections and report SERVING, seconds.
    #[arg(long, default_value = "120", value_parser = parse_seconds)]
    ready_timeout: Duration,
    #[command(flatten)]
    route: RouteArgs,
    /// Drive a named suite instead of --routes: `unseen` (the held-out towns: CARLA Town02 and
    /// the radial town, maps from --maps, default ../shared/carla) or `home` (the Town05-style
    /// routes, a regression check); each route file's results go to --out (a folder) and
    /// suite.json sums them up.
    #[arg(long, conflicts_with_all = ["routes", "map", "route_ids", "limit"])]
    suite: Option<String>,
    #[command(flatten)]
    world: WorldArgs,
    /// Runs of each route; repetition r uses seed S + r [default: 1, or the suite's 3].
    #[arg(long, allow_negative_numbers = true, value_parser = parse_count)]
    repetitions: Option<usize>,
    /// Runs at once, each with its own agent, longest routes first; results are the same as
    /// one at a time (a `local` agent steps one run per forward pass; a remote server that
    /// batches the runs' steps rounds differently with the batch, and learned agents may then
    /// diverge)
    #[arg(long, default_value_t = 1, allow_negative_numbers = true, value_parser = parse_count)]
    jobs: usize,
    /// Drive only share K of N of the campaign's runs (K from 0, e.g. `--shard
    /// $JOB_COMPLETION_INDEX/4`): a fixed split, balanced by route length, that N processes
    /// compute alike; `sim-bridge results merge` joins their results files into the one a
    /// single process writes.
    #[arg(long, conflicts_with = "suite")]
    shard: Option<Shard>,
    /// End every route after this many simulated seconds (a timeout without penalty) instead
    /// of the leaderboard's length-based timeout: for quick smoke runs.
    #[arg(long, value_parser = parse_positive)]
    timeout: Option<f64>,
    /// The rules that score the routes: `lb1` (the CARLA leaderboard 1.0) or `lb2` (2.0's
    /// penalty table where it applies here: 1.0's criteria plus its minimum-speed penalty and
    /// "Perfect" status). Bench2Drive's success rate, efficiency and comfort are reported with
    /// either.
    #[arg(long, value_enum, default_value = "lb1")]
    scoring: sim_bridge::scoring::Rules,
    /// Where to write the leaderboard results JSON [default: results.json; with --suite a
    /// folder, suite-NAME].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Keep the runs already in --out (from an interrupted evaluation with the same routes,
    /// repetitions and seed) and drive only the missing ones and those whose agent crashed.
    #[arg(long)]
    resume: bool,
    /// Write a step log of each run into this folder (requests with PNG frames, the agent's
    /// controls and plans, ground truth), for `sim-bridge replay`.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Rig rendered into step logs of an agent without cameras (the expert).
    #[arg(long, default_value = "tcp-small")]
    record_rig: String,
    /// Write a top-down PNG of each run into this folder.
    #[arg(long)]
    pictures: Option<PathBuf>,
    /// No progress bars (CI logs).
    #[arg(long)]
    quiet: bool,
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    if let Some(name) = &args.suite {
        let suite = Suite::find(name).with_context(|| {
            format!("--suite {name}: no such suite (suites: {})", Suite::names())
        })?;
        return run_suite(&args, suite);
    }
    let (target, _local_server) = agent_target(&args)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("results.json"));
    let repetitions = args.repetitions.unwrap_or(1);
    let scope = Scope {
        repetitions,
        first_repetitions: None,
        resume: args.resume,
    };
    let report = drive(
        &args,
        target.as_deref(),
        &args.route,
        scope,
        &out,
        args.pictures.as_deref(),
    )?;
    super::print_stdout(&format!(
        "{}\nresults written to {}",
        summary_table(&report.results),
        out.display()
    ))?;
    check_report(&report, repetitions)
}

/// Drive every route file of `suite` into the folder --out, one results JSON each (repetition 0
/// of every file first), then write and print the suite's summary. With --resume each part
/// keeps its finished runs.
fn run_suite(args: &EvalArgs, suite: &Suite) -> anyhow::Result<()> {
    let dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("suite-{}", suite.name)));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let repetitions = args.repetitions.unwrap_or(suite.repetitions);
    if repetitions != suite.repetitions {
        eprintln!(
            "note: {repetitions} repetitions instead of the suite's {}: these figures are not the \
             suite's protocol",
            suite.repetitions
        );
    }
    let maps = args.route.maps.clone().or_else(|| {
        let default = PathBuf::from(DEFAULT_CARLA_MAPS);
        default.is_dir().then_some(default)
    });
    let (target, _local_server) = agent_target(args)?;
    // Repetition 0 of every part, then repetition 1 of every part, ...: a suite cut short is
    // a sample of all its towns, and its --resume goes on where it stopped.
    let mut parts = Vec::new();
    let mut failures = Vec::new();
    for repetition in 0..repetitions {
        let last = repetition + 1 == repetitions;
        for &part in suite.parts {
            let route = RouteArgs {
                routes: part.to_string(),
                map: None,
                maps: maps.clone(),
                route_ids: Vec::new(),
                limit: None,
                no_placed_lights: args.route.no_placed_lights,
            };
            let file = format!("{part}.json");
            let pictures = args.pictures.as_ref().map(|p| p.join(part));
            eprintln!(
                "suite {}: {part}, repetition {} of {repetitions}",
                suite.name,
                repetition + 1
            );
            let scope = Scope {
                repetitions,
                first_repetitions: Some(repetition + 1),
                // Later passes keep what the earlier ones drove.
                resume: args.resume || repetition > 0,
            };
            let report = drive(
                args,
                target.as_deref(),
                &route,
                scope,
                &dir.join(&file),
                pictures.as_deref(),
            )
            .with_context(|| format!("suite {}, part {part}", suite.name))?;
            if last {
                if let Err(e) = check_report(&report, repetitions) {
                    failures.push(format!("{part}: {e:#}"));
                }
                parts.push((part, file, report.results.checkpoint.records));
            }
        }
    }
    let all: Vec<_> = parts
        .iter()
        .flat_map(|(_, _, r)| r.iter().cloned())
        .collect();
    let summary = SuiteSummary {
        suite: suite.name.to_string(),
        repetitions,
        parts: parts
            .into_iter()
            .map(|(part, file, records)| PartSummary {
                name: part.to_string(),
                town: part_town(part).unwrap_or_default().to_string(),
                results: file,
                figures: Figures::of(&records),
            })
            .collect(),
        all: Figures::of(&all),
    };
    let path = dir.join("suite.json");
    let text = serde_json::to_string_pretty(&summary).context("serializing the suite summary")?;
    super::write_output(&path, &text)?;
    super::print_stdout(&format!(
        "{}\nsuite summary written to {}",
        suite_table(&summary),
        path.display()
    ))?;
    if !failures.is_empty() {
        bail!("{}", failures.join("; "));
    }
    Ok(())
}

/// Where the CARLA maps are looked for when --maps is not given (a suite with CARLA towns).
const DEFAULT_CARLA_MAPS: &str = "../shared/carla";

/// Which runs of a campaign one [`drive`] covers.
#[derive(Debug, Clone, Copy)]
struct Scope {
    /// The campaign's repetitions (its plan).
    repetitions: usize,
    /// Drive only the first this many now ([`Campaign::first_repetitions`]).
    first_repetitions: Option<usize>,
    /// Keep the runs already in the results file.
    resume: bool,
}

/// One campaign: `route` driven `scope.repetitions` times (those `scope` covers now) by the
/// agent at `target` (or an in-process one), results to `out`, pictures to `pictures`.
fn drive(
    args: &EvalArgs,
    target: Option<&str>,
    route: &RouteArgs,
    scope: Scope,
    out: &Path,
    pictures: Option<&Path>,
) -> anyhow::Result<CampaignReport> {
    let record_rig = match &args.record {
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            Some(Rig::from_name_or_file(&args.record_rig)?)
        }
        None => None,
    };
    let make_agent = || -> Result<Box<dyn Agent>, String> {
        let agent = build_agent(args, target).map_err(|e| format!("{e:#}"))?;
        Ok(match (&args.record, &record_rig) {
            (Some(dir), Some(rig)) => Box::new(LoggingAgent::new(agent, rig.clone(), dir.clone())),
            _ => agent,
        })
    };
    let (map, planned) = route.load_each()?;
    if let Some(dir) = pictures {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let campaign = Campaign {
        map: &map,
        routes: &planned,
        repetitions: scope.repetitions,
        world: args.world.config(&map, args.world.seed)?,
        scoring: ScoringConfig {
            rules: args.scoring,
            timeout: args.timeout,
            ..ScoringConfig::default()
        },
        out: out.to_path_buf(),
        resume: scope.resume,
        jobs: args.jobs,
        shard: args.shard,
        first_repetitions: scope.first_repetitions,
        label: route.routes.clone(),
    };
    let display = EvalDisplay {
        bars: MultiProgress::new(),
        quiet: args.quiet,
        pictures,
        map: &map,
    };
    Ok(run_campaign(&campaign, &make_agent, &display)?)
}

/// An error when some runs' agent crashed or some routes could not be planned.
fn check_report(report: &CampaignReport, repetitions: usize) -> anyhow::Result<()> {
    let total = report
        .results
        .checkpoint
        .progress
        .last()
        .copied()
        .unwrap_or(0);
    if report.crashes > 0 {
        bail!(
            "the agent crashed on {} of {total} runs (see above)",
            report.crashes
        );
    }
    if report.unplannable > 0 {
        let runs = report.results.plan.as_ref().map_or(total, |p| p.runs);
        bail!(
            "{} of {} routes could not be planned; they count as failed runs with zero scores \
             (see above)",
            report.unplannable,
            runs / repetitions.max(1)
        );
    }
    Ok(())
}

/// `eval`'s view of a campaign: a progress bar per run, a line per finished run, pictures.
struct EvalDisplay<'a> {
    bars: MultiProgress,
    quiet: bool,
    pictures: Option<&'a Path>,
    map: &'a Map,
}

impl CampaignObserver for EvalDisplay<'_> {
    type Run = ProgressBar;

    fn resuming(&self, kept: usize, total: usize, out: &Path) {
        eprintln!(
            "resuming: {kept} of {total} runs already scored in {}",
            out.display()
        );
    }

    fn agent_ready(&self, name: &str, jobs: usize) {
        self.bars
            .suspend(|| eprintln!("agent: {name} ({jobs} at once)"));
    }

    fn run_started(&self, spec: &RouteSpec, repetition: usize) -> ProgressBar {
        self.bars.add(progress_bar(
            self.quiet,
            &format!("route {} rep {repetition}", spec.id),
        ))
    }

    fn progress(&self, bar: &ProgressBar, route_completion: f64) {
        bar.set_position(route_completion.round() as u64);
    }

    fn run_finished(&self, bar: ProgressBar, done: &RunDone) -> Result<(), String> {
        bar.finish_and_clear();
        self.bars.remove(&bar);
        let (id, repetition) = (&done.spec.id, done.repetition);
        let Some((dense, run)) = done.driven else {
            self.bars
                .suspend(|| eprintln!("route {id:>4} rep {repetition}: {}", done.record.status));
            return Ok(());
        };
        if let Some(dir) = self.pictures {
            let path = dir.join(safe_name(&format!("route_{id}_rep{repetition}")) + ".png");
            let s = done.record.scores;
            let title = format!(
                "{} route {id} rep {repetition}: {}  DS {:.1} RC {:.1} IS {:.2}",
                self.map.name, done.record.status, s.score_composed, s.score_route, s.score_penalty
            );
            write_run_png(
                self.map,
                dense,
                &run.trace,
                &run.final_actors,
                &run.infractions,
                &title,
                &path,
            )
            .map_err(|e| format!("writing {}: {e}", path.display()))?;
        }
        if let Some(error) = &run.agent_error {
            self.bars
                .suspend(|| eprintln!("route {id} rep {repetition}: the agent crashed: {error}"));
        }
        let s = done.record.scores;
        self.bars.suspend(|| {
            eprintln!(
                "route {id:>4} rep {repetition}: DS {:6.2} RC {:6.2} IS {:.3}  {}  ({:.0} s sim in {:.1} s)",
                s.score_composed,
                s.score_route,
                s.score_penalty,
                done.record.status,
                done.record.meta.duration_game,
                run.wall_seconds
            )
        });
        Ok(())
    }
}

/// The server `--agent` names (started here for `local`), or `None` for the expert.
fn agent_target(args: &EvalArgs) -> anyhow::Result<(Option<String>, Option<LocalServer>)> {
    if matches!(
        args.agent.as_str(),
        "expert" | "oracle-plan" | "oracle-plan-only"
    ) {
        return Ok((None, None));
    }
    let (target, server) = server_target(&args.agent, LocalRole::Driving { runs: args.jobs })?;
    Ok((Some(target), server))
}

/// One agent: the expert or the oracle-plan agent in process, or a connection to the server
/// at `target`.
fn build_agent(args: &EvalArgs, target: Option<&str>) -> anyhow::Result<Box<dyn Agent>> {
    let Some(target) = target else {
        return Ok(match args.agent.as_str() {
            "oracle-plan" => Box::new(OraclePlan::new(sim_control_config())),
            "oracle-plan-only" => Box::new(OraclePlan::plan_only(sim_control_config())),
            _ => Box::new(Expert::new()),
        });
    };
    let options = GrpcOptions {
        rig: args
            .rig
            .as_deref()
            .map(Rig::from_name_or_file)
            .transpose()?,
        call_timeout: args.call_timeout,
        ready_timeout: args.ready_timeout,
        client: "sim-bridge eval".into(),
        ..GrpcOptions::default()
    };
    Ok(Box::new(GrpcAgent::connect(target, options)?))
}

fn progress_bar(quiet: bool, label: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(100);
    let style = ProgressStyle::with_template("{msg:>18} [{bar:40}] RC {pos:>3}% {elapsed}")
        .unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style.progress_chars("=> "));
    bar.set_message(label.to_string());
    bar
}
