//! Closed-loop evaluation: drive an [`Agent`] over route files on a map, tick by tick in 20 Hz
//! lockstep, score each run with the leaderboard criteria and gather the results.
//!
//! One tick, in the leaderboard's order: read the state, update the route follower and the
//! scenario triggers, render the agent's cameras (if it has any), ask the agent, evaluate the
//! criteria (with the contacts of the previous world step), then step the world.

pub mod campaign;
pub mod compare;
pub mod merge;
pub mod shard;
pub mod suite;

use std::time::Instant;

use glam::DVec3;

use ssrdrive_proto::camera::Rig;

use crate::driver::{Agent, AgentError, CameraFrame, Observation, RouteContext};
use crate::map::Map;
use crate::render::{Appearance, CameraRenderer, SceneState};
use crate::route::DenseRoute;
use crate::route::plan::{RouteFollower, global_plan};
use crate::route::xml::RouteSpec;
use crate::scoring::{Infraction, RouteEnd, RouteRecord, RouteScorer, ScoringConfig};
use crate::world::state::EgoState;
use crate::world::{ActorView, World, WorldConfig};

/// Ticks between two samples of the ego trace kept for pictures.
const TRACE_EVERY: u64 = 5;

/// Everything one route run produced.
#[derive(Debug)]
pub struct RouteRun {
    /// The leaderboard record.
    pub record: RouteRecord,
    /// Every infraction with its place.
    pub infractions: Vec<Infraction>,
    /// Ego positions sampled every [`TRACE_EVERY`] ticks.
    pub trace: Vec<DVec3>,
    /// Other actors at the end of the run.
    pub final_actors: Vec<ActorView>,
    /// Simulated ticks.
    pub ticks: u64,
    /// Wall time, seconds.
    pub wall_seconds: f64,
    /// Why the agent stopped the route, when it crashed.
    pub agent_error: Option<AgentError>,
}

/// An agent's cameras: the rig it asked for and a renderer in the world's look.
struct Cameras {
    rig: Rig,
    renderer: CameraRenderer,
}

impl Cameras {
    /// What the cameras see of `world` on tick `frame`, the ego at `ego`.
    fn render(&mut self, world: &World<'_>, ego: EgoState, frame: u64) -> Vec<CameraFrame> {
        let actors = world.visible_actors();
        let scene = SceneState {
            ego,
            actors: &actors,
            lights: world.light_states(),
        };
        self.renderer.render(&self.rig, &scene, frame)
    }
}

/// Starts `agent` on the route of `context` and sets up the cameras it asks for (none for an
/// agent without sensors); its error when it refuses the route or asks for an unusable rig.
fn start_agent(
    agent: &mut dyn Agent,
    context: &RouteContext<'_>,
    world_config: &WorldConfig,
) -> Result<Option<Cameras>, AgentError> {
    agent.start_route(context)?;
    let Some(rig) = agent.sensors() else {
        return Ok(None);
    };
    rig.validate()
        .map_err(|e| AgentError(format!("its camera rig is unusable: {e}")))?;
    let renderer = CameraRenderer::new(context.map, Appearance::of_world(world_config));
    Ok(Some(Cameras { rig, renderer }))
}

/// One route run: `spec` planned as `dense`, `repetition` and world seed recorded in the
/// record's meta; `on_tick` sees the route completion (percent) every simulated second. The
/// world's scenario timeout follows the scoring rules ([`crate::scoring::Rules::scenario_timeout`]).
#[allow(clippy::too_many_arguments)]
pub fn run_route(
    map: &Map,
    spec: &RouteSpec,
    dense: &DenseRoute,
    agent: &mut dyn Agent,
    world_config: WorldConfig,
    scoring: ScoringConfig,
    index: usize,
    repetition: usize,
    mut on_tick: impl FnMut(f64),
) -> RouteRun {
    let started = Instant::now();
    let plan = global_plan(dense);
    let mut follower = RouteFollower::new(plan.clone());
    let world_config = WorldConfig {
        scenario_timeout: scoring.rules.scenario_timeout(),
        ..world_config
    };
    let mut world = World::new(map, dense, world_config.clone());
    let context = RouteContext {
        map,
        route: dense,
        plan: &plan,
        route_id: &spec.id,
        repetition,
        seed: world_config.seed,
        ego_half_extent: world.ego_state().half_extent,
    };
    let (mut cameras, mut agent_error) = match start_agent(agent, &context, &world_config) {
        Ok(cameras) => (cameras, None),
        Err(error) => (None, Some(error)),
    };
    let mut scorer = RouteScorer::new(map, dense, scoring);
    let mut contacts = Vec::new();
    let mut progress = 0;
    let mut trace = Vec::new();
    let mut frame: u64 = 0;
    let end = loop {
        if agent_error.is_some() {
            break RouteEnd::AgentCrashed;
        }
        let ego = world.ego_state();
        progress = dense.advance_index(progress, ego.position.truncate(), 5);
        world.trigger_scenarios(progress);
        let node = follower.step(ego.position.truncate(), ego.yaw);
        let frames = match &mut cameras {
            Some(cameras) if agent.wants_frames(frame) => {
                scorer.frame_lamps(world.time, &ego, world.light_states(), &cameras.rig);
                cameras.render(&world, ego, frame)
            }
            _ => Vec::new(),
        };
        let obs = Observation::of_ego(world.time, frame, &ego, &node, frames);
        let control = match agent.run_step(&obs, &world) {
            Ok(control) => control,
            Err(error) => {
                agent_error = Some(error);
                continue;
            }
        };
        let traffic_speed = world.background_speed();
        if let Some(end) = scorer.tick(
            world.time,
            &ego,
            &contacts,
            world.light_states(),
            traffic_speed,
        ) {
            break end;
        }
        if frame.is_multiple_of(TRACE_EVERY) {
            trace.push(ego.position);
        }
        if frame.is_multiple_of(20) {
            on_tick(scorer.route_completion());
        }
        contacts = world.step(control);
        for ended in world.take_scenario_timeouts() {
            scorer.scenario_timed_out(ended.time, ended.name, ended.ego);
        }
        frame += 1;
    };
    agent.end_route();
    let wall_seconds = started.elapsed().as_secs_f64();
    let final_actors = world.actors();
    let (mut record, mut infractions) =
        scorer.finish_with_infractions(Some(end), &spec.id, index, world.time, wall_seconds);
    infractions.sort_by(|a, b| a.time.total_cmp(&b.time));
    record.meta.repetition = Some(repetition);
    record.meta.seed = Some(world_config.seed);
    RouteRun {
        record,
        infractions,
        trace,
        final_actors,
        ticks: frame,
        wall_seconds,
        agent_error,
    }
}
