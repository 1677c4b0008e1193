//! The world: ego, background traffic, walkers, cyclists, static obstacles and traffic-light
//! controllers, advanced in 20 Hz lockstep ([`DT`]).
//!
//! One tick, as the leaderboard orders it: the agent sees the state, the scorer evaluates it,
//! then [`World::step`] applies the control, moves everything and reports the contacts the
//! scorer reads on the next tick. Everything random comes from one ChaCha8 stream seeded by
//! [`WorldConfig::seed`], so a (map, route, config) triple always replays identically.

pub mod ego;
pub mod ego_watch;
pub mod idm;
pub mod junctions;
pub mod lights;
pub mod scenarios;
pub mod state;
pub mod traffic;
pub mod vehicle;

use ego::{Ego, EgoParams};
pub use ego_watch::TrafficMode;
use ego_watch::{EgoPresence, MERGE_WAIT_AHEAD, MERGE_WAIT_SPEED};
use glam::{DVec2, DVec3};
use lights::LightController;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use scenarios::{Crosser, IdSource, Scenario, StaticProp};
use ssrdrive_proto::control::Control;
use ssrdrive_proto::frames::{world_to_ego, wrap_angle};
use state::{ActorKind, CollisionEvent, ContactGeometry, EgoState, LightState, Obb};
use traffic::{REQUEST_DISTANCE, Traffic, standing_time};
use vehicle::Script;

use crate::map::{LaneIdx, Map};
use crate::route::DenseRoute;
use crate::route::scenario_file::TownScenarios;

/// Simulation step, seconds: the contract's tick ([`ssrdrive_proto::TICK_S`], 20 Hz).
pub const DT: f64 = ssrdrive_proto::TICK_S;

/// The leaderboard's background-vehicle count for a town (Town05: 120).
pub fn leaderboard_vehicles(map: &Map) -> usize {
    match map.name.to_ascii_lowercase().as_str() {
        "town02" => 100,
        "town04" => 200,
        "town06" => 150,
        "ssr_train_small" => 60,
        _ => 120,
    }
}

/// What to populate the world with.
#[derive(Debug, Clone)]
pub struct WorldConfig {
    /// Background vehicles (the leaderboard uses 120 on Town05).
    pub vehicles: usize,
    /// Background walkers on sidewalks.
    pub walkers: usize,
    /// Route scenarios: from `scenario_file` when given, else S3, S4 and S7-S9 drawn along the
    /// route from the seed.
    pub scenarios: bool,
    /// The town's triggers of a leaderboard scenario file (`--scenarios`), matched to the route
    /// as the leaderboard does ([`crate::route::scenario_file`]).
    pub scenario_file: Option<TownScenarios>,
    /// Parked cars on parking lanes.
    pub parked_cars: bool,
    /// How background traffic treats the ego.
    pub traffic: TrafficMode,
    /// Seed of every random choice.
    pub seed: u64,
    /// Draw camera frames in a look varied from the seed (colours, sun, noise) instead of the
    /// canonical one.
    pub randomise_appearance: bool,
    /// Leaderboard 2.0's scenario timeout, s ([`crate::scoring::Rules::scenario_timeout`]): a
    /// route-blocking scenario (Scenario6's barriers) the ego has not got past this long after
    /// it fired ends, its barriers and vehicles removed, and is reported
    /// ([`World::take_scenario_timeouts`]). `None` (leaderboard 1.0): it stands for good.
    pub scenario_timeout: Option<f64>,
}

impl Default for WorldConfig {
    fn default() -> Self {
        Self {
            vehicles: 120,
            walkers: 0,
            scenarios: true,
            scenario_file: None,
            parked_cars: true,
            traffic: TrafficMode::default(),
            seed: 0,
            randomise_appearance: false,
            scenario_timeout: None,
        }
    }
}

/// Another actor as agents and renderers see it.
#[derive(Debug, Clone, Copy)]
pub struct ActorView {
    /// Actor id (0 for static props).
    pub id: u32,
    /// What it is.
    pub kind: ActorKind,
    /// Ground box.
    pub obb: Obb,
    /// Ground height.
    pub z: f64,
    /// Velocity in plan, m/s.
    pub velocity: DVec2,
}

/// The simulated world of one route run.
pub struct World<'m> {
    /// The map.
    pub map: &'m Map,
    /// Seconds since the start.
    pub time: f64,
    /// The ego vehicle.
    pub ego: Ego,
    /// Background and scenario vehicles.
    pub traffic: Traffic,
    /// Walkers and cyclists.
    pub crossers: Vec<Crosser>,
    /// Static obstacles.
    pub statics: Vec<StaticProp>,
    /// Debris on the road (Scenario1): seen, never touched.
    pub debris: Vec<StaticProp>,
    /// Traffic lights.
    pub lights: LightController,
    /// Route scenarios.
    pub scenarios: Vec<Scenario>,
    /// Fired scenarios still running.
    running: Vec<scenarios::Running>,
    /// [`WorldConfig::scenario_timeout`].
    scenario_timeout: Option<f64>,
    /// Scenarios that timed out since [`World::take_scenario_timeouts`] was last called.
    timed_out: Vec<scenarios::TimedOut>,
    route_progress: usize,
    /// Distance along the route of each route point, m.
    route_distance: Vec<f64>,
    /// The route's lane changes: where each starts (distance along the route, m) and the lane
    /// it changes into.
    lane_changes: Vec<(f64, LaneIdx)>,
    /// Where the route enters each junction from an approach without a light (distance along
    /// the route, m) and the connector.
    junction_entries: Vec<(f64, LaneIdx)>,
    /// The connector the ego is about to enter and since when it has been waiting its turn.
    junction_request: Option<(LaneIdx, f64)>,
    /// Seconds the ego has stood still in a row.
    ego_standing_for: f64,
    traffic_mode: TrafficMode,
    rng: ChaCha8Rng,
    ids: IdSource,
}

impl<'m> World<'m> {
    /// A world with the ego at rest at the start of `route`.
    pub fn new(map: &'m Map, route: &DenseRoute, config: WorldConfig) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let start = route.points[0];
        let ego = Ego::new(EgoParams::default(), start.position, start.yaw);
        let lights = LightController::new(map, &mut rng);
        let mut traffic = Traffic::new(
            map,
            config.vehicles,
            start.position.truncate(),
            1000,
            &mut rng,
        );
        let mut ids = IdSource(100_000);
        let mut statics = if config.parked_cars {
            scenarios::parked_cars(map, &mut rng)
        } else {
            Vec::new()
        };
        let mut crossers = scenarios::background_walkers(map, config.walkers, &mut ids, &mut rng);
        let placed = match (&config.scenario_file, config.scenarios) {
            (_, false) => scenarios::Placement::default(),
            (Some(file), true) => {
                scenarios::place_from_file(map, route, &file.triggers, config.seed, &mut ids)
            }
            (None, true) => scenarios::place_route_scenarios(map, route, &mut ids, &mut rng),
        };
        statics.extend(placed.statics);
        crossers.extend(placed.crossers);
        for v in &placed.vehicles {
            let waits = (Script::Waits, 0.0, 1.0);
            traffic.spawn_scenario_vehicle(map, v.id, (v.lane, v.s), waits, &mut rng);
        }
        // Nothing may start on top of the ego.
        let ego_box = ego.state().obb();
        statics.retain(|s| !s.obb.overlaps(&ego_box));
        let mut world = World {
            map,
            time: 0.0,
            ego,
            traffic,
            crossers,
            statics,
            debris: placed.debris,
            lights,
            scenarios: placed.scenarios,
            running: Vec::new(),
            scenario_timeout: config.scenario_timeout,
            timed_out: Vec::new(),
            route_progress: 0,
            route_distance: route.cum.clone(),
            lane_changes: lane_changes(map, route),
            junction_entries: junction_entries(map, route),
            junction_request: None,
            ego_standing_for: 0.0,
            traffic_mode: config.traffic,
            rng,
            ids,
        };
        world.settle_ego_height();
        world
    }

    /// The ego's published state.
    pub fn ego_state(&self) -> EgoState {
        self.ego.state()
    }

    /// Light states, indexed like `Map::lights`.
    pub fn light_states(&self) -> &[LightState] {
        self.lights.states()
    }

    /// The mean speed of the background vehicles (scenario vehicles, which stand or run red
    /// lights on purpose, left out), m/s; `None` when there are none.
    pub fn background_speed(&self) -> Option<f64> {
        let (sum, count) = self
            .traffic
            .vehicles
            .iter()
            .filter(|v| v.is_background())
            .fold((0.0, 0usize), |(sum, count), v| (sum + v.speed, count + 1));
        (count > 0).then(|| sum / count as f64)
    }

    /// Every other actor.
    pub fn actors(&self) -> Vec<ActorView> {
        let mut out = Vec::with_capacity(
            self.traffic.vehicles.len() + self.crossers.len() + self.statics.len(),
        );
        for v in &self.traffic.vehicles {
            let (p, yaw) = v.pose(self.map);
            let obb = Obb {
                centre: p.truncate(),
                yaw,
                half: v.half,
            };
            out.push(ActorView {
                id: v.id,
                kind: ActorKind::Vehicle,
                obb,
                z: p.z,
                velocity: DVec2::from_angle(yaw) * v.speed,
            });
        }
        for c in self.crossers.iter().filter(|c| !c.gone) {
            out.push(ActorView {
                id: c.id,
                kind: c.kind,
                obb: c.obb(),
                z: c.position.z,
                velocity: c.velocity(),
            });
        }
        out.extend(self.statics.iter().map(|s| s.view(ActorKind::Static)));
        out
    }

    /// [`Self::actors`] and the debris on the road, which nothing touches: what cameras see.
    pub fn visible_actors(&self) -> Vec<ActorView> {
        let mut out = self.actors();
        out.extend(self.debris.iter().map(|s| s.view(ActorKind::Debris)));
        out
    }

    /// The lane the route changes into next, when that change starts within
    /// [`MERGE_WAIT_AHEAD`] of the ego's progress.
    fn lane_change_ahead(&self) -> Option<LaneIdx> {
        let here = self.route_distance.get(self.route_progress)?;
        self.lane_changes
            .iter()
            .find(|(at, _)| *at > *here)
            .filter(|(at, _)| at - here <= MERGE_WAIT_AHEAD)
            .map(|&(_, lane)| lane)
    }

    /// The junction connector the ego's route enters next from an approach without a light and
    /// since when (sim time) the ego has been within [`REQUEST_DISTANCE`] of it, while the ego
    /// is not in a junction: its turn at the junction, which traffic respects and the expert
    /// takes ([`Traffic::ego_may_enter`]).
    pub fn ego_junction_request(&self) -> Option<(LaneIdx, f64)> {
        self.junction_request
    }

    /// Updates [`Self::ego_junction_request`] for the ego's progress; `in_junction` says
    /// whether the ego is on a junction lane.
    fn update_junction_request(&mut self, in_junction: bool) {
        let next = self
            .route_distance
            .get(self.route_progress)
            .and_then(|here| {
                self.junction_entries
                    .iter()
                    .find(|(at, _)| *at > *here)
                    .filter(|(at, _)| at - here <= REQUEST_DISTANCE)
            })
            .map(|&(_, connector)| connector)
            .filter(|_| !in_junction);
        self.junction_request = match (next, self.junction_request) {
            (Some(connector), Some((waiting, since))) if connector == waiting => {
                Some((connector, since))
            }
            (Some(connector), _) => Some((connector, self.time)),
            (None, _) => None,
        };
    }

    /// Apply `control` to the ego and advance everything by [`DT`]; returns the ego's contacts.
    pub fn step(&mut self, control: Control) -> Vec<CollisionEvent> {
        let before = self.ego.position;
        self.ego.step(control, DT);
        self.settle_ego_height();
        let ego = self.ego.state();
        let on_lane = self
            .map
            .lane_for_pose(ego.position, ego.yaw)
            .filter(|(_, p)| p.distance < 2.0)
            .map(|(l, p)| (l, p.s));
        let courteous = self.traffic_mode == TrafficMode::Courteous;
        let merging_into = (courteous && ego.speed < MERGE_WAIT_SPEED)
            .then(|| self.lane_change_ahead())
            .flatten()
            .map(|lane| (lane, self.map.lane(lane).project(ego.position.truncate()).s));
        self.update_junction_request(on_lane.is_some_and(|(l, _)| self.map.lane(l).in_junction()));
        self.ego_standing_for = standing_time(self.ego_standing_for, ego.speed, DT);
        let presence = EgoPresence {
            on_lane,
            obb: ego.obb(),
            z: ego.position.z,
            speed: ego.speed,
            merging_into,
            junction_request: self.junction_request.filter(|_| courteous),
            standing_for: self.ego_standing_for,
            mode: self.traffic_mode,
        };
        self.time += DT;
        self.lights.update(self.time);
        self.traffic.step(
            self.map,
            self.lights.states(),
            &presence,
            self.time,
            DT,
            &mut self.rng,
        );
        for c in &mut self.crossers {
            c.step(DT);
        }
        self.run_scenarios();
        self.collisions(before)
    }

    /// Contacts of the ego box with every other actor, and what they do to the ego's move this
    /// tick (from `before`). The ego cannot drive into what it touches, but it slides along it:
    /// the part of its move into the face it touches (the face of the other box it overlaps
    /// least) is taken away, and its speed shrinks with its move. Head-on, that stops it; a
    /// scrape along a side goes on; a corner caught on a car at an angle slides past, as
    /// CARLA's physics would let it, where stopping it would pin the ego for as long as the
    /// boxes touch (the kinematic model has no physics to push them apart). A hit walker or
    /// cyclist leaves the scene.
    fn collisions(&mut self, before: DVec3) -> Vec<CollisionEvent> {
        let ego = self.ego.state();
        let ego_box = ego.obb();
        let moved = (ego.position - before).truncate();
        let mut kept = moved;
        let mut events = Vec::new();
        for a in self.actors() {
            let offset = a.obb.centre - ego_box.centre;
            if (a.z - ego.position.z).abs() > 3.0 || offset.length() > 8.0 {
                continue;
            }
            if let Some(face) = ego_box.contact_face_of(&a.obb) {
                kept -= kept.dot(face).min(0.0) * face;
                events.push(CollisionEvent {
                    other_id: a.id,
                    class: a.kind.collision_class(),
                    location: ego.position,
                    contact: Some(ContactGeometry {
                        relative_yaw: wrap_angle(a.obb.yaw - ego.yaw),
                        other_offset: DVec2::from(world_to_ego([offset.x, offset.y], ego.yaw)),
                        other_speed: a.velocity.length(),
                        ego_speed: ego.speed,
                    }),
                });
            }
        }
        if kept != moved {
            self.ego.position = before + kept.extend(0.0);
            self.ego.position.z = ego.position.z;
            self.ego.speed *= kept.length() / moved.length();
        }
        let hit: Vec<u32> = events.iter().map(|e| e.other_id).collect();
        for c in self.crossers.iter_mut().filter(|c| hit.contains(&c.id)) {
            c.gone = true;
        }
        events
    }

    /// Put the ego on the road surface under it.
    fn settle_ego_height(&mut self) {
        let p = self.ego.position;
        if let Some((lane, proj)) = self.map.lane_for_pose(p, self.ego.yaw) {
            self.ego.position.z = self.map.lane(lane).pose_at(proj.s).position.z;
        }
    }
}

/// Where the route changes lanes: the distance along it at which each change starts (its first
/// point commanded to change lanes) and the lane it changes into.
/// Where `route` enters each junction from an approach without a light (distance along it, m)
/// and the connector it enters: where a light controls the approach, the light gives the turn.
fn junction_entries(map: &Map, route: &DenseRoute) -> Vec<(f64, LaneIdx)> {
    let points = &route.points;
    (1..points.len())
        .filter(|&j| {
            let approach = points[j - 1].lane;
            map.lane(points[j].lane).in_junction()
                && !map.lane(approach).in_junction()
                && map.light_ending(approach).is_none()
        })
        .map(|j| (route.cum[j], points[j].lane))
        .collect()
}

fn lane_changes(map: &Map, route: &DenseRoute) -> Vec<(f64, LaneIdx)> {
    let points = &route.points;
    (1..points.len())
        .filter_map(|j| {
            let (from, to) = (map.lane(points[j - 1].lane), points[j].lane);
            if from.left != Some(to) && from.right != Some(to) {
                return None;
            }
            let start = (0..j)
                .rev()
                .take_while(|&k| points[k].option.is_lane_change())
                .last()
                .unwrap_or(j);
            Some((route.cum[start], to))
        })
        .collect()
}
