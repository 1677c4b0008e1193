//! `sim-bridge routes`: list and inspect route sets, regenerate the bundled ones.

use std::path::PathBuf;

use anyhow::bail;
use clap::{Args, Subcommand};
use sim_bridge::map::MapOptions;
use sim_bridge::route::DenseRoute;
use sim_bridge::route::plan::global_plan;
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::scenario_file;
use sim_bridge::route::scenario_triggers;
use sim_bridge::route::sets::{self, RandomRoutes, SETS, WalkStyle};
use sim_bridge::route::xml::{RouteSpec, write};
use ssrdrive_proto::command::RoadOption;

#[derive(Debug, Subcommand)]
pub enum RoutesCommand {
    /// List the bundled route sets.
    List,
    /// Show each route of a set (bundled name, or a route XML with --map): length, keypoints,
    /// plan nodes, turns and lane changes, timeout.
    Show {
        /// Bundled set name or route XML file.
        set: String,
        /// Map for a route XML file (.xodr path or bundled town name).
        #[arg(long)]
        map: Option<PathBuf>,
    },
    /// Regenerate the bundled route files (byte-identical to the committed ones).
    Generate {
        /// Folder to write into.
        #[arg(long, default_value = "sim-bridge/routes")]
        out_dir: PathBuf,
    },
    /// Draw random routes on any map and write them as a leaderboard route file, to drive a
    /// town that has no route file (CARLA's Town02, say): random walks over the driving lanes
    /// that prefer turns at junctions and sometimes change lanes, as the bundled sets are made.
    /// The same map, options and seed give the same file.
    Random(RandomArgs),
    /// Place leaderboard scenario triggers on a town that no scenario file covers (the
    /// Town05-style town, a generated town, your own map) and write them as a scenario file for
    /// `eval --scenarios`: one at half the junction approaches (Scenario4, or 7 at a light and 10
    /// without) and one every --spacing metres of road between (Scenario1 or 3), drawn by
    /// --seed. The same map, options and seed give the same file.
    Scenarios(ScenariosArgs),
}

/// `sim-bridge routes scenarios`.
#[derive(Debug, Args)]
pub struct ScenariosArgs {
    /// The map: an .xodr file or a bundled town name.
    #[arg(long)]
    map: PathBuf,
    /// Metres of road between two triggers on one lane (10 or more).
    #[arg(long, default_value_t = scenario_triggers::DEFAULT_SPACING_M)]
    spacing: f64,
    /// Seed of the types drawn.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// The town the file names, as route files name it (default: the map file's name without
    /// .xodr).
    #[arg(long)]
    town: Option<String>,
    /// The scenario file to write.
    #[arg(long)]
    out: PathBuf,
}

/// `sim-bridge routes random`.
#[derive(Debug, Args)]
pub struct RandomArgs {
    /// The map: an .xodr file or a bundled town name.
    #[arg(long)]
    map: PathBuf,
    /// How many routes.
    #[arg(long, default_value_t = 20)]
    count: usize,
    /// Route length range in metres, MIN,MAX (each route drawn uniformly from it).
    #[arg(long, default_value = "500,1500", value_parser = super::args::parse_range)]
    length: [f64; 2],
    /// Seed of the draw.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Chance of turning at a junction that offers a turn (0-1).
    #[arg(long, default_value_t = 0.45)]
    turn_bias: f64,
    /// Chance of a lane change where a lane is long enough (0-1).
    #[arg(long, default_value_t = 0.3)]
    change_rate: f64,
    /// The town named in the file (default: the map file's name without .xodr, so that
    /// `eval --maps DIR` finds the map again).
    #[arg(long)]
    town: Option<String>,
    /// The route file to write.
    #[arg(long)]
    out: PathBuf,
}

pub fn run(cmd: RoutesCommand) -> anyhow::Result<()> {
    match cmd {
        RoutesCommand::List => {
            println!("{:<20} {:<20} {:>6}  description", "set", "town", "routes");
            for set in SETS {
                let n = sim_bridge::route::xml::parse(set.name, set.bundled_xml())?.len();
                println!(
                    "{:<20} {:<20} {:>6}  {}",
                    set.name,
                    set.town.name(),
                    n,
                    set.description
                );
            }
            for file in &sim_bridge::route::sets::CARLA_ROUTE_FILES {
                let n = sim_bridge::route::xml::parse(file.name, file.xml)?.len();
                println!(
                    "{:<20} {:<20} {:>6}  {} (map from --maps)",
                    file.name, file.town, n, file.description
                );
            }
            Ok(())
        }
        RoutesCommand::Show { set, map } => {
            let (map, specs) = super::load_routes(&set, map.as_ref(), None, MapOptions::default())?;
            println!(
                "{:<8} {:>9} {:>9} {:>5} {:>5} {:>5} {:>5} {:>5} {:>9}",
                "route", "kp len m", "dense m", "kps", "plan", "left", "right", "chg", "timeout s"
            );
            let mut total = 0.0;
            for spec in &specs {
                let dense = plan_route(&map, spec)?;
                let (left, right, changes) = manoeuvres(&dense);
                total += dense.length();
                let timeout =
                    sim_bridge::scoring::route_timeout(dense.length(), &Default::default());
                println!(
                    "{:<8} {:>9.1} {:>9.1} {:>5} {:>5} {:>5} {:>5} {:>5} {:>9.0}",
                    spec.id,
                    spec.keypoint_length(),
                    dense.length(),
                    spec.keypoints.len(),
                    global_plan(&dense).len(),
                    left,
                    right,
                    changes,
                    timeout
                );
            }
            println!("{} routes, {:.2} km dense", specs.len(), total / 1000.0);
            Ok(())
        }
        RoutesCommand::Generate { out_dir } => {
            sets::write_bundled(&out_dir)?;
            println!("wrote {} route sets to {}", SETS.len(), out_dir.display());
            Ok(())
        }
        RoutesCommand::Random(args) => random(args),
        RoutesCommand::Scenarios(args) => scenarios(args),
    }
}

/// `routes random`: check the options, draw, write, and say what was drawn.
fn random(args: RandomArgs) -> anyhow::Result<()> {
    let RandomArgs {
        map: map_arg,
        count,
        length,
        seed,
        turn_bias,
        change_rate,
        town,
        out,
    } = args;
    let style = WalkStyle {
        turn_bias,
        change_rate,
    };
    if !(1..=10_000).contains(&count) {
        bail!("--count {count}: give 1 to 10000 routes");
    }
    if !(length[0] >= 20.0 && length[1] <= 50_000.0) {
        bail!(
            "--length {},{}: routes of 20 m to 50 km",
            length[0],
            length[1]
        );
    }
    for (flag, p) in [
        ("--turn-bias", style.turn_bias),
        ("--change-rate", style.change_rate),
    ] {
        if !(0.0..=1.0).contains(&p) {
            bail!("{flag} {p}: a chance between 0 and 1");
        }
    }
    let map = super::load_map(&map_arg.to_string_lossy(), MapOptions::default())?;
    let town = town.unwrap_or_else(|| map.name.clone());
    let options = RandomRoutes {
        count,
        length,
        seed,
        style,
    };
    let specs = sets::random_routes(&map, &town, &options);
    if specs.is_empty() {
        bail!(
            "{}: no route of {}-{} m could be drawn ({} walks each); try shorter routes",
            map_arg.display(),
            length[0],
            length[1],
            sets::ATTEMPTS
        );
    }
    super::write_output(&out, &write(&specs))?;
    let km: f64 = specs.iter().map(RouteSpec::keypoint_length).sum::<f64>() / 1000.0;
    println!(
        "wrote {} routes ({km:.2} km) on {town} to {}{}",
        specs.len(),
        out.display(),
        if specs.len() < count {
            format!(
                "; {} lengths could not be drawn on this map",
                count - specs.len()
            )
        } else {
            String::new()
        }
    );
    Ok(())
}

/// `routes scenarios`: check the options, place, write, and count what was placed.
fn scenarios(args: ScenariosArgs) -> anyhow::Result<()> {
    let ScenariosArgs {
        map: map_arg,
        spacing,
        seed,
        town,
        out,
    } = args;
    if !(scenario_triggers::MIN_SPACING_M..=10_000.0).contains(&spacing) {
        bail!(
            "--spacing {spacing}: give {} to 10000 m (closer triggers would share a position)",
            scenario_triggers::MIN_SPACING_M
        );
    }
    let map = super::load_map(&map_arg.to_string_lossy(), MapOptions::default())?;
    let town = town.unwrap_or_else(|| map.name.clone());
    let triggers = scenario_triggers::place(&map, spacing, seed);
    if triggers.is_empty() {
        bail!(
            "{}: no lane outside junctions is {} m long, so no trigger fits",
            map_arg.display(),
            2.0 * scenario_triggers::EDGE_M
        );
    }
    super::write_output(&out, &scenario_file::write(&town, &triggers))?;
    let mut counts = std::collections::BTreeMap::new();
    for t in &triggers {
        *counts.entry(t.scenario).or_insert(0) += 1;
    }
    let counts: Vec<String> = counts
        .iter()
        .map(|(n, c)| format!("Scenario{n} {c}"))
        .collect();
    println!(
        "wrote {} triggers on {town} to {} ({})",
        triggers.len(),
        out.display(),
        counts.join(", ")
    );
    Ok(())
}

/// Left turns, right turns and lane changes along a dense route.
fn manoeuvres(route: &DenseRoute) -> (usize, usize, usize) {
    let mut counts = (0, 0, 0);
    let mut prev = RoadOption::LaneFollow;
    for p in &route.points {
        if p.option != prev {
            match p.option {
                RoadOption::Left => counts.0 += 1,
                RoadOption::Right => counts.1 += 1,
                RoadOption::ChangeLaneLeft | RoadOption::ChangeLaneRight => counts.2 += 1,
                _ => {}
            }
        }
        prev = p.option;
    }
    // Each lane change is marked twice (its start and a point a few metres in).
    (counts.0, counts.1, counts.2 / 2)
}
