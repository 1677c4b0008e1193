//! `sim-bridge eval`: drive an agent over a route set, print a summary table, write the
//! leaderboard results JSON (after every route, so an interrupted run keeps what it scored) and,
//! on request, a top-down picture of each run.

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sim_bridge::agent::Agent;
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::render::topdown::write_run_png;
use sim_bridge::route::planner::plan_route;
use sim_bridge::scoring::{Results, ScoringConfig, summary_table};
use sim_bridge::world::WorldConfig;

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Who drives: `expert` (the privileged rule-based expert).
    #[arg(long, default_value = "expert")]
    agent: String,
    /// A bundled route set (see `sim-bridge routes list`) or a CARLA route XML file.
    #[arg(long, default_value = "town05-long-style")]
    routes: String,
    /// The map: an .xodr file or a bundled town name (defaults to a bundled set's own town).
    #[arg(long)]
    map: Option<PathBuf>,
    /// Only these route ids (comma separated).
    #[arg(long, value_delimiter = ',')]
    route_ids: Vec<String>,
    /// At most this many routes (after --route-ids).
    #[arg(long)]
    limit: Option<usize>,
    /// Runs of each route; repetition r uses seed S + r.
    #[arg(long, default_value_t = 1)]
    repetitions: usize,
    /// Base seed of traffic, scenarios and lights.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Background vehicles (default: the leaderboard's number for the town, 120 for Town05).
    #[arg(long)]
    vehicles: Option<usize>,
    /// Background walkers on sidewalks.
    #[arg(long, default_value_t = 0)]
    walkers: usize,
    /// No route scenarios (walkers crossing, cyclists, red-light runners).
    #[arg(long)]
    no_scenarios: bool,
    /// No parked cars.
    #[arg(long)]
    no_parked_cars: bool,
    /// Do not place lights at multi-lane four-way junctions that the map leaves without.
    #[arg(long)]
    no_placed_lights: bool,
    /// Where to write the leaderboard results JSON.
    #[arg(long, default_value = "results.json")]
    out: PathBuf,
    /// Write a top-down PNG of each run into this folder.
    #[arg(long)]
    pictures: Option<PathBuf>,
    /// No progress bars (CI logs).
    #[arg(long)]
    quiet: bool,
}

/// The leaderboard's background-vehicle count for a town (Town05: 120).
pub fn default_vehicles(map: &Map) -> usize {
    match map.name.to_ascii_lowercase().as_str() {
        "town02" => 100,
        "town04" => 200,
        "town06" => 150,
        "ssr_train_small" => 60,
        _ => 120,
    }
}

pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    let options = MapOptions {
        place_missing_lights: !args.no_placed_lights,
    };
    let (map, mut specs) = super::load_routes(&args.routes, args.map.as_ref(), options)?;
    if !args.route_ids.is_empty() {
        specs.retain(|s| args.route_ids.contains(&s.id));
        if specs.is_empty() {
            bail!(
                "none of --route-ids {:?} is in {}",
                args.route_ids,
                args.routes
            );
        }
    }
    if let Some(limit) = args.limit {
        specs.truncate(limit);
    }
    if args.repetitions == 0 {
        bail!("--repetitions must be at least 1");
    }
    let mut agent: Box<dyn Agent> = match args.agent.as_str() {
        "expert" => Box::new(Expert::new()),
        other => bail!("--agent {other}: unknown agent (available: expert)"),
    };
    if let Some(dir) = &args.pictures {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    // Plan every route first: one that cannot be planned on this map is reported and left out,
    // and the rest still run.
    let mut planned = Vec::with_capacity(specs.len());
    for spec in &specs {
        match plan_route(&map, spec) {
            Ok(dense) => planned.push((spec, dense)),
            Err(e) => eprintln!("warning: skipping route {}: {e}", spec.id),
        }
    }
    if planned.is_empty() {
        bail!(
            "no route of {} could be planned on map {}",
            args.routes,
            map.name
        );
    }
    let vehicles = args.vehicles.unwrap_or_else(|| default_vehicles(&map));
    let total = planned.len() * args.repetitions;
    let mut records = Vec::with_capacity(total);
    for repetition in 0..args.repetitions {
        for (spec, dense) in &planned {
            let world = WorldConfig {
                vehicles,
                walkers: args.walkers,
                scenarios: !args.no_scenarios,
                parked_cars: !args.no_parked_cars,
                seed: args.seed + repetition as u64,
            };
            let bar = progress_bar(args.quiet, &format!("route {} rep {repetition}", spec.id));
            let index = records.len();
            let run = run_route(
                &map,
                spec,
                dense,
                agent.as_mut(),
                world,
                ScoringConfig::default(),
                index,
                repetition,
                |rc| bar.set_position(rc.round() as u64),
            );
            bar.finish_and_clear();
            let s = run.record.scores;
            eprintln!(
                "route {:>4} rep {repetition}: DS {:6.2} RC {:6.2} IS {:.3}  {}  ({:.0} s sim in {:.1} s)",
                spec.id,
                s.score_composed,
                s.score_route,
                s.score_penalty,
                run.record.status,
                run.record.meta.duration_game,
                run.wall_seconds
            );
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
            records.push(run.record);
            let results = Results::new(records.clone(), total, Vec::new());
            std::fs::write(&args.out, results.to_json())
                .with_context(|| format!("writing {}", args.out.display()))?;
        }
    }
    let results = Results::new(records, total, Vec::new());
    println!("{}", summary_table(&results));
    println!("results written to {}", args.out.display());
    Ok(())
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
