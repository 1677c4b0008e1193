//! `sim-bridge eval`: drive an agent over a route set, print a summary table, write the
//! leaderboard results JSON (after every route, so an interrupted run keeps what it scored) and,
//! on request, a top-down picture of each run. With `--jobs N`, N routes run at once, each
//! with its own agent (its own connection and episode on a gRPC server, which can batch them).
//! `--resume` keeps the runs an earlier, interrupted evaluation of the same plan wrote to
//! `--out` and drives only the rest (and any run whose agent crashed).

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use clap::Args;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use sim_bridge::agent::Agent;
use sim_bridge::client::grpc::{GrpcAgent, GrpcOptions};
use sim_bridge::client::local::LocalServer;
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::expert::oracle::{OraclePlan, sim_control_config};
use sim_bridge::render::topdown::write_run_png;
use sim_bridge::replay::recorder::LoggingAgent;
use sim_bridge::scoring::{Results, RouteEnd, RouteRecord, ScoringConfig, summary_table};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::files::write_atomic;

use super::args::{RouteArgs, RoutePlan, WorldArgs, parse_positive, parse_seconds, server_target};

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
    #[command(flatten)]
    world: WorldArgs,
    /// Runs of each route; repetition r uses seed S + r.
    #[arg(long, default_value_t = 1)]
    repetitions: usize,
    /// Runs at once, each with its own agent (a gRPC server batches their steps); results
    /// are the same as one at a time.
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// End every route after this many simulated seconds (a timeout without penalty) instead
    /// of the leaderboard's length-based timeout: for quick smoke runs.
    #[arg(long, value_parser = parse_positive)]
    timeout: Option<f64>,
    /// Where to write the leaderboard results JSON.
    #[arg(long, default_value = "results.json")]
    out: PathBuf,
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
    if args.repetitions == 0 || args.jobs == 0 {
        bail!("--repetitions and --jobs must be at least 1");
    }
    let scoring = ScoringConfig {
        timeout: args.timeout,
        ..ScoringConfig::default()
    };
    let (target, _local_server) = agent_target(&args)?;
    let record_rig = match &args.record {
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            Some(Rig::from_name_or_file(&args.record_rig)?)
        }
        None => None,
    };
    let make_agent = || -> anyhow::Result<Box<dyn Agent>> {
        let agent = build_agent(&args, target.as_deref())?;
        Ok(match (&args.record, &record_rig) {
            (Some(dir), Some(rig)) => Box::new(LoggingAgent::new(agent, rig.clone(), dir.clone())),
            _ => agent,
        })
    };
    // Every selected route runs; one that cannot be planned is a failed record, as the
    // leaderboard would count it.
    let (map, planned) = args.route.load_each()?;
    if let Some(dir) = &args.pictures {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    // Runs in leaderboard order: every route of repetition 0, then of repetition 1, ...
    let total = planned.len() * args.repetitions;
    let records = if args.resume {
        earlier_records(&args.out, &planned, total, args.world.seed)?
    } else {
        vec![None; total]
    };
    let kept = records.iter().flatten().count();
    if args.resume {
        eprintln!(
            "resuming: {kept} of {total} runs already scored in {}",
            args.out.display()
        );
    }
    let next_run = AtomicUsize::new(0);
    let finished = Mutex::new(Finished {
        records,
        crashes: 0,
    });
    let bars = MultiProgress::new();
    let jobs = args.jobs.min(total - kept).max(1);
    // Each worker makes its own agent on its own thread (agents need not be Send).
    let worker = |job: usize| -> anyhow::Result<()> {
        let mut agent = make_agent()?;
        if job == 0 {
            bars.suspend(|| eprintln!("agent: {} ({jobs} at once)", agent.name()));
        }
        loop {
            let index = next_run.fetch_add(1, Ordering::Relaxed);
            if index >= total {
                return Ok(());
            }
            if finished
                .lock()
                .expect("no worker panics holding it")
                .records[index]
                .is_some()
            {
                continue;
            }
            let (repetition, (spec, dense)) =
                (index / planned.len(), &planned[index % planned.len()]);
            let seed = args.world.seed.wrapping_add(repetition as u64);
            let dense = match dense {
                Ok(dense) => dense,
                Err(reason) => {
                    let record = RouteRecord::unplannable(
                        index,
                        &spec.id,
                        spec.keypoint_length(),
                        repetition,
                        seed,
                        &reason.to_string(),
                    );
                    bars.suspend(|| {
                        eprintln!("route {:>4} rep {repetition}: {}", spec.id, record.status)
                    });
                    let mut finished = finished.lock().expect("no worker panics holding it");
                    finished.records[index] = Some(record);
                    save(&args.out, &finished.done(), total)?;
                    continue;
                }
            };
            let world = args.world.config(&map, seed);
            let bar = bars.add(progress_bar(
                args.quiet,
                &format!("route {} rep {repetition}", spec.id),
            ));
            let run = run_route(
                &map,
                spec,
                dense,
                agent.as_mut(),
                world,
                scoring.clone(),
                index,
                repetition,
                |rc| bar.set_position(rc.round() as u64),
            );
            bar.finish_and_clear();
            bars.remove(&bar);
            if let Some(dir) = &args.pictures {
                let path = dir.join(format!("route_{}_rep{repetition}.png", spec.id));
                write_run_png(
                    &map,
                    dense,
                    &run.trace,
                    &run.final_actors,
                    &run.infractions,
                    &path,
                )
                .with_context(|| format!("writing {}", path.display()))?;
            }
            let mut finished = finished.lock().expect("no worker panics holding it");
            if let Some(error) = &run.agent_error {
                finished.crashes += 1;
                bars.suspend(|| {
                    eprintln!(
                        "route {} rep {repetition}: the agent crashed: {error}",
                        spec.id
                    )
                });
            }
            let s = run.record.scores;
            bars.suspend(|| {
                eprintln!(
                    "route {:>4} rep {repetition}: DS {:6.2} RC {:6.2} IS {:.3}  {}  ({:.0} s sim in {:.1} s)",
                    spec.id,
                    s.score_composed,
                    s.score_route,
                    s.score_penalty,
                    run.record.status,
                    run.record.meta.duration_game,
                    run.wall_seconds
                )
            });
            finished.records[index] = Some(run.record);
            save(&args.out, &finished.done(), total)?;
        }
    };
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..jobs)
            .map(|job| scope.spawn(move || worker(job)))
            .collect();
        workers
            .into_iter()
            .try_for_each(|w| w.join().expect("eval workers do not panic"))
    })?;
    let finished = finished.into_inner().expect("workers are done");
    let results = Results::new(finished.done(), total, Vec::new());
    println!("{}", summary_table(&results));
    println!("results written to {}", args.out.display());
    if finished.crashes > 0 {
        bail!(
            "the agent crashed on {} of {total} runs (see above)",
            finished.crashes
        );
    }
    let unplannable = planned.iter().filter(|(_, dense)| dense.is_err()).count();
    if unplannable > 0 {
        bail!(
            "{unplannable} of {} routes could not be planned; they count as failed runs with \
             zero scores (see above)",
            planned.len()
        );
    }
    Ok(())
}

/// Runs scored so far, by index.
struct Finished {
    records: Vec<Option<RouteRecord>>,
    crashes: usize,
}

impl Finished {
    /// The finished runs in leaderboard order.
    fn done(&self) -> Vec<RouteRecord> {
        self.records.iter().flatten().cloned().collect()
    }
}

/// Writes the results so far to `path` whole or not at all: after a failed write (a full
/// disk), the file still holds the previous results, which `--resume` reads.
fn save(path: &Path, records: &[RouteRecord], total: usize) -> anyhow::Result<()> {
    let results = Results::new(records.to_vec(), total, Vec::new());
    write_atomic(path, results.to_json().as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// The records an earlier evaluation of the same plan wrote to `path`, by run index (none if
/// there is no file yet). Runs whose agent crashed are dropped so they run again. A record of
/// another route, repetition or seed at its index means another plan: an error, as the file
/// would otherwise mix two evaluations.
fn earlier_records(
    path: &Path,
    planned: &[RoutePlan],
    total: usize,
    seed: u64,
) -> anyhow::Result<Vec<Option<RouteRecord>>> {
    let mut records = vec![None; total];
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(records),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let results =
        Results::from_json(&text).with_context(|| format!("resuming from {}", path.display()))?;
    for record in results.checkpoint.records {
        let index = record.index;
        let spec = &planned[index % planned.len()].0;
        let repetition = index / planned.len();
        let expected_seed = seed.wrapping_add(repetition as u64);
        if index >= total
            || record.route_id != spec.id
            || record.meta.repetition != Some(repetition)
            || record.meta.seed != Some(expected_seed)
        {
            bail!(
                "cannot resume from {}: its run {index} is route {} repetition {:?} seed {:?}, \
                 but this evaluation plans {} there; resume with the same --routes, \
                 --route-ids, --limit, --repetitions and --seed, or write to another --out",
                path.display(),
                record.route_id,
                record.meta.repetition,
                record.meta.seed,
                if index < total {
                    format!(
                        "route {} repetition {repetition} seed {expected_seed}",
                        spec.id
                    )
                } else {
                    format!("only {total} runs")
                },
            );
        }
        if record.status != RouteEnd::AgentCrashed.status() {
            records[index] = Some(record);
        }
    }
    Ok(records)
}

/// The server `--agent` names (started here for `local`), or `None` for the expert.
fn agent_target(args: &EvalArgs) -> anyhow::Result<(Option<String>, Option<LocalServer>)> {
    if matches!(
        args.agent.as_str(),
        "expert" | "oracle-plan" | "oracle-plan-only"
    ) {
        return Ok((None, None));
    }
    let (target, server) = server_target(&args.agent, false)?;
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
