//! Argument parsing and the subcommands, each a thin layer over the library.

mod args;
mod bench;
mod collect;
mod eval;
mod load;
mod render;
mod replay;
mod results;
mod routes;
mod towns;

use std::path::PathBuf;

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::route::sets::{CARLA_ROUTE_FILES, CarlaRouteFile, RouteSet};
use sim_bridge::route::xml::{self, RouteSpec};
use sim_bridge::towngen::TownStyle;

/// A kinematic driving simulator on OpenDRIVE maps that scores agents on routes exactly like the
/// CARLA leaderboard 1.0 (route completion RC, infraction score IS, driving score DS).
///
/// Frames: OpenDRIVE map frame (x east, y north, z up, metres); route files use CARLA's frame
/// (y flipped). The simulator ticks at 20 Hz in lockstep with the agent.
#[derive(Debug, Parser)]
#[command(name = "sim-bridge", version, propagate_version = true)]
pub struct Cli {
    /// More log output (-v info, -vv debug).
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Drive an agent over a route set and score it like the leaderboard.
    Eval(eval::EvalArgs),
    /// Drive routes (the expert, or a served agent with --agent) and write what the cameras
    /// saw: PNG frames and an animation of each run with the camera view beside a top-down
    /// view, and a served agent's scene-token attention and occupancy maps.
    Render(render::RenderArgs),
    /// Record the expert driving route sets (with noise injection) into a training dataset;
    /// resumable.
    Collect(collect::CollectArgs),
    /// List, show or regenerate route sets.
    #[command(subcommand)]
    Routes(routes::RoutesCommand),
    /// List or regenerate the bundled towns.
    #[command(subcommand)]
    Towns(towns::TownsCommand),
    /// Load-test an agent server: N episodes ticking at a fixed rate with real frames; prints
    /// RPS, latency percentiles (from intended send times), status codes and server memory.
    Load(load::LoadArgs),
    /// Re-feed step logs (from `eval --record`) to an agent server: latency, drift from the
    /// recorded answers, open-loop L2 and collision rate at 1, 2, 3 s.
    Replay(replay::ReplayArgs),
    /// Work on leaderboard results files: merge the shares of a campaign.
    #[command(subcommand)]
    Results(results::ResultsCommand),
    /// Benchmarks that print figures.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
}

/// Logging to stderr at warn, info (`-v`) or debug (`-vv`); `RUST_LOG` overrides the level.
pub fn init_logging(verbose: u8) {
    let level = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    ssrdrive_support::logging::init(level, false);
}

/// Run a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Eval(args) => eval::run(args),
        Command::Load(args) => load::run(args),
        Command::Replay(args) => replay::run(args),
        Command::Results(command) => results::run(command),
        Command::Render(args) => render::run(args),
        Command::Collect(args) => collect::run(args),
        Command::Routes(cmd) => routes::run(cmd),
        Command::Towns(cmd) => towns::run(cmd),
        Command::Bench(cmd) => bench::run(cmd),
    }
}

/// Routes and their map from `--routes` (a bundled set name or a route XML file) and `--map`
/// (an .xodr file or a bundled town name; for a bundled set it defaults to the set's town).
pub fn load_routes(
    routes: &str,
    map: Option<&PathBuf>,
    maps: Option<&PathBuf>,
    options: MapOptions,
) -> anyhow::Result<(Map, Vec<RouteSpec>)> {
    let map_arg = map.map(|m| m.to_string_lossy().into_owned());
    if let Some(set) = RouteSet::find(routes) {
        let specs = xml::parse(set.name, set.bundled_xml())?;
        let map = match map_arg {
            Some(m) => load_map(&m, options)?,
            None => load_map(set.town.name(), options)?,
        };
        return Ok((map, specs));
    }
    let (specs, what) = if let Some(file) = CarlaRouteFile::find(routes) {
        (
            xml::parse(file.name, file.xml)?,
            format!("{routes} (routes on {})", file.town),
        )
    } else {
        let path = PathBuf::from(routes);
        if !path.exists() {
            let names: Vec<&str> = sim_bridge::route::sets::SETS
                .iter()
                .map(|s| s.name)
                .chain(CARLA_ROUTE_FILES.iter().map(|f| f.name))
                .collect();
            bail!(
                "--routes {routes}: no such file and no bundled set of that name (bundled: {})",
                names.join(", ")
            );
        }
        (xml::read_file(&path)?, format!("{routes} (a route file)"))
    };
    let map_arg = match (map_arg, maps) {
        (Some(map), _) => map,
        (None, Some(dir)) => town_map(&specs, dir, routes)?,
        (None, None) => bail!(
            "--routes {what}: give its map with --map <file.xodr | bundled town>, or a folder \
             of maps named after the towns with --maps DIR (CARLA's: ../shared/carla)"
        ),
    };
    Ok((load_map(&map_arg, options)?, specs))
}

/// DIR/<town>.xodr for a route file whose routes all name one town (CARLA's `town="Town05"`).
fn town_map(specs: &[RouteSpec], dir: &std::path::Path, routes: &str) -> anyhow::Result<String> {
    let mut towns: Vec<&str> = specs.iter().map(|s| s.town.as_str()).collect();
    towns.sort_unstable();
    towns.dedup();
    let town = match towns.as_slice() {
        [town] if !town.is_empty() => *town,
        [] | [_] => bail!("--routes {routes}: its routes name no town; give the map with --map"),
        many => bail!(
            "--routes {routes} names {} towns ({}); evaluate one town per run with --map",
            many.len(),
            many.join(", ")
        ),
    };
    let path = dir.join(format!("{town}.xodr"));
    if !path.is_file() {
        bail!(
            "--maps {}: no {town}.xodr there for the town --routes {routes} names",
            dir.display()
        );
    }
    Ok(path.to_string_lossy().into_owned())
}

/// Prints a command's report on standard output. A reader that closed the pipe early
/// (`sim-bridge results compare A B | head -3`) ends the printing quietly, not the command with a
/// panic: what the command wrote to files stays written.
pub fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match writeln!(out, "{text}").and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(e).context("writing to standard output")
        }
        _ => Ok(()),
    }
}

/// Writes a command's output file whole (atomically: a reader never sees half of it), the
/// error naming the file.
pub fn write_output(path: &std::path::Path, text: &str) -> anyhow::Result<()> {
    ssrdrive_support::files::write_atomic(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}

/// A map from an .xodr path or a bundled town name.
pub fn load_map(arg: &str, options: MapOptions) -> anyhow::Result<Map> {
    if let Some(style) = TownStyle::from_name(arg) {
        return Map::from_str(style.name(), sim_bridge::towngen::bundled(style), options)
            .with_context(|| format!("bundled town {arg}"));
    }
    let path = PathBuf::from(arg);
    if !path.exists() {
        let towns: Vec<&str> = TownStyle::ALL.iter().map(|s| s.name()).collect();
        bail!(
            "map {arg}: no such .xodr file and no bundled town of that name (bundled towns: {})",
            towns.join(", ")
        );
    }
    Ok(Map::load_file(&path, options)?)
}
