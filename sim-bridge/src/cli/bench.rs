//! `sim-bridge bench`: benchmarks that print figures.

use std::time::Instant;

use clap::Subcommand;
use sim_bridge::driver::{Agent, AgentError, Observation, RouteContext};
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::map::MapOptions;
use sim_bridge::render::{Appearance, CameraRenderer, SceneState};
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::sets::RouteSet;
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::world::ActorView;
use sim_bridge::world::state::{EgoState, LightState};
use sim_bridge::world::{DT, World, WorldConfig};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::control::Control;

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
    /// Camera render time per frame on one core: the expert drives the first Town05-style
    /// long route with full traffic, its world is captured every few ticks, and each capture
    /// is rendered through the rig. Prints the median and p90 per frame (all cameras).
    Render {
        /// A rig preset (`tcp`: 900x256; `tcp-small`: 320x96, the cpu-default model's input) or
        /// a JSON rig file.
        #[arg(long, default_value = "tcp")]
        rig: String,
        /// Frames to render.
        #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
        frames: u64,
        /// Ticks between captures (20 Hz ticks).
        #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..))]
        every: u64,
        /// Background vehicles.
        #[arg(long, default_value_t = 120)]
        vehicles: usize,
    },
}

pub fn run(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Render {
            rig,
            frames,
            every,
            vehicles,
        } => bench_render(&rig, frames, every, vehicles),
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

/// Captures world states while the expert drives, then times rendering each through the rig.
fn bench_render(rig: &str, frames: u64, every: u64, vehicles: usize) -> anyhow::Result<()> {
    let rig = Rig::from_name_or_file(rig)?;
    let set = RouteSet::find("town05-long-style").expect("bundled set");
    let map = super::load_map(set.town.name(), MapOptions::default())?;
    let spec = &sim_bridge::route::xml::parse(set.name, set.bundled_xml())?[0];
    let dense = plan_route(&map, spec)?;
    let config = WorldConfig {
        vehicles,
        ..WorldConfig::default()
    };
    let mut capture = Capture {
        expert: Expert::new(),
        every,
        wanted: frames as usize,
        states: Vec::new(),
    };
    run_route(
        &map,
        spec,
        &dense,
        &mut capture,
        config.clone(),
        ScoringConfig::default(),
        0,
        0,
        |_| {},
    );
    let baked = Instant::now();
    let mut renderer = CameraRenderer::new(&map, Appearance::of_world(&config));
    let bake_ms = baked.elapsed().as_secs_f64() * 1e3;
    let mut times = Vec::with_capacity(capture.states.len());
    for (k, (ego, actors, lights)) in capture.states.iter().enumerate() {
        let state = SceneState {
            ego: *ego,
            actors,
            lights,
        };
        let start = Instant::now();
        let out = renderer.render(&rig, &state, k as u64);
        times.push(start.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(out);
    }
    times.sort_by(f64::total_cmp);
    let pick = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
    let sizes: Vec<String> = rig
        .cameras
        .iter()
        .map(|c| format!("{}x{}", c.width, c.height))
        .collect();
    println!(
        "bench render: {} frames of {} camera(s) [{}] on {} ({} static triangles, baked in {bake_ms:.0} ms), 1 thread",
        times.len(),
        rig.cameras.len(),
        sizes.join(", "),
        map.name,
        renderer.static_triangles()
    );
    println!(
        "  per frame: median {:.2} ms, p90 {:.2} ms, max {:.2} ms",
        pick(0.5),
        pick(0.9),
        pick(1.0)
    );
    Ok(())
}

/// The expert, capturing the world every `every` ticks until it has `wanted` states.
struct Capture {
    expert: Expert,
    every: u64,
    wanted: usize,
    states: Vec<(EgoState, Vec<ActorView>, Vec<LightState>)>,
}

impl Agent for Capture {
    fn name(&self) -> String {
        "expert (capturing)".into()
    }

    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.expert.start_route(ctx)
    }

    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        if obs.frame.is_multiple_of(self.every) && self.states.len() < self.wanted {
            self.states.push((
                world.ego_state(),
                world.actors(),
                world.light_states().to_vec(),
            ));
        }
        self.expert.run_step(obs, world)
    }
}
