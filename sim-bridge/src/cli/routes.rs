//! `sim-bridge routes`: list and inspect route sets, regenerate the bundled ones.

use std::path::PathBuf;

use clap::Subcommand;
use sim_bridge::map::MapOptions;
use sim_bridge::route::DenseRoute;
use sim_bridge::route::plan::global_plan;
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::sets::{self, SETS};
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
    }
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
