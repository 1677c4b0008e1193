//! `sim-bridge bench`: benchmarks that print figures.

use std::time::Instant;

use clap::Subcommand;
use sim_bridge::map::MapOptions;
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::sets::RouteSet;
use sim_bridge::world::ego::Control;
use sim_bridge::world::{DT, World, WorldConfig};

#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Simulation speed without cameras: the Town05-style town with full traffic (120
    /// vehicles), the ego idling at the start of a long route, on one core. Prints simulated
    /// seconds per wall second (median of the repeats).
    Sim {
        /// Simulated seconds per repeat.
        #[arg(long, default_value_t = 120.0)]
        seconds: f64,
        /// Repeats (the median is reported).
        #[arg(long, default_value_t = 5)]
        repeats: usize,
        /// Background vehicles.
        #[arg(long, default_value_t = 120)]
        vehicles: usize,
    },
}

pub fn run(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Sim {
            seconds,
            repeats,
            vehicles,
        } => {
            let set = RouteSet::find("town05-long-style").expect("bundled set");
            let map = super::load_map(set.town.name(), MapOptions::default())?;
            let spec = &sim_bridge::route::xml::parse(set.name, set.bundled_xml())?[0];
            let dense = plan_route(&map, spec)?;
            let ticks = (seconds / DT).round() as usize;
            let mut rates = Vec::new();
            for r in 0..repeats.max(1) {
                let config = WorldConfig {
                    vehicles,
                    seed: r as u64,
                    ..WorldConfig::default()
                };
                let mut world = World::new(&map, &dense, config);
                let start = Instant::now();
                for _ in 0..ticks {
                    world.step(Control {
                        steer: 0.0,
                        throttle: 0.0,
                        brake: 1.0,
                    });
                }
                let rate = seconds / start.elapsed().as_secs_f64();
                println!(
                    "repeat {r}: {rate:.0}x real time ({} vehicles, {seconds:.0} s simulated)",
                    world.traffic.vehicles.len()
                );
                rates.push(rate);
            }
            rates.sort_by(f64::total_cmp);
            println!(
                "bench sim: median {:.0} simulated s per wall s on {} ({vehicles} vehicles, 1 thread)",
                rates[rates.len() / 2],
                map.name
            );
            Ok(())
        }
    }
}
