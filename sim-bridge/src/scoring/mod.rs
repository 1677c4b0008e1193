//! Route scoring the way the CARLA leaderboard 1.0 does it: the seven route criteria of
//! scenario_runner `atomic_criteria.py` (branch `leaderboard-1.0`), the per-route and global
//! statistics of leaderboard `statistics_manager.py`, and its results file.
//!
//! One file per concern: [`completion`] (route completion, RC), [`lanes`] (outside route lanes,
//! the "off-road" row), [`collisions`], [`lights`] (red lights and stop signs), [`progress`]
//! (route deviation, agent blocked, route timeout), [`record`] (route and global records, the
//! results JSON), [`summary`] (a readable table), and Bench2Drive's figures beside the
//! leaderboard's: [`bench2drive`] (success, efficiency) and [`comfort`]. [`RouteScorer`] ties
//! the criteria together for one route; the world calls [`RouteScorer::tick`] once per 20 Hz
//! tick. [`Rules::Lb2`] adds Leaderboard 2.0's minimum-speed penalty and "Perfect" status.
//!
//! Scores: RC is the route-completion percentage, IS the product of the infraction coefficients
//! (pedestrian 0.50, vehicle 0.60, layout 0.65, red light 0.70, stop 0.80) times
//! (1 - off-lane % / 100), and DS = max(RC * IS, 0). Route deviation, agent blocked and route
//! timeout end the route without a penalty.
//!
//! Where we differ from the leaderboard (the simulator has no CARLA server to ask):
//! - Locations are in the OpenDRIVE map frame, messages included (CARLA prints its own
//!   left-handed frame, whose y is the negated OpenDRIVE y).
//! - CARLA's `map.get_waypoint(location, lane_type)` is [`Map::waypoint`]: the nearest lane
//!   centre line of that kind (nearest in 3-D among lanes within 10 m in plan, so bridges
//!   resolve to the right level).
//! - Pass tests (a dot product against a route point's forward vector) and the red-light distance
//!   use the plan (2-D) forward vector; CARLA's forward vector carries the road pitch, which only
//!   matters on steep slopes.
//! - Traffic-light stop lines come from the map (the end of each incoming lane, see
//!   [`crate::map::traffic_control`]) instead of sampling CARLA trigger volumes, and a stop
//!   sign's trigger area is a box we define (see [`lights`]), since our maps have no trigger
//!   volumes.
//! - Collision "type ids" are synthetic (`vehicle`, `walker.pedestrian`, `static.prop`).
//! - The global record averages over the records given and lists only the records that are not
//!   "Completed" as exceptions (see [`global_record`]).

pub mod bench2drive;
pub mod collisions;
pub mod comfort;
pub mod completion;
pub mod lanes;
pub mod lights;
pub mod progress;
pub mod record;
pub mod sightings;
pub mod summary;

use glam::DVec3;
use ssrdrive_proto::camera::Rig;

use crate::map::{LaneKind, Map};
use crate::route::DenseRoute;
use crate::world::state::{CollisionEvent, EgoState, LightState};

pub use progress::route_timeout;
pub use record::{
    Checkpoint, GlobalMeta, GlobalRecord, Infractions, LABELS, Results, ResultsError, RouteEvent,
    RouteMeta, RouteRecord, Scores, global_record,
};
pub use summary::summary_table;

/// Leaderboard 2.0's status of a route completed with no infraction ([`Rules::Lb2`]).
pub const PERFECT_STATUS: &str = "Perfect";
/// Leaderboard 2.0's weight of the minimum-speed penalty: a checkpoint at p % of the traffic's
/// speed multiplies IS by 1 - 0.3 (1 - p / 100) (PENALTY_PERC_DICT's 0.7 at 0 %).
pub const MIN_SPEED_WEIGHT: f64 = 0.3;
/// Leaderboard 2.0's scenario timeout, s (scenario_runner's `_scenario_timeout` of its
/// obstacle scenarios): a scenario the ego has not got past this long after it fired ends.
pub const SCENARIO_TIMEOUT_S: f64 = 240.0;

/// Infraction coefficients (LB1.0 `statistics_manager.py` PENALTY_*). TransFuser's Longest6
/// sets `stop` to 1.0 (stop signs ignored); the defaults are the leaderboard's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Penalties {
    /// Collision with a walker: 0.50.
    pub pedestrian: f64,
    /// Collision with a vehicle (cyclists included): 0.60.
    pub vehicle: f64,
    /// Collision with static layout: 0.65.
    pub layout: f64,
    /// Running a red light: 0.70.
    pub red_light: f64,
    /// Running a stop sign: 0.80.
    pub stop: f64,
    /// A scenario timed out (Leaderboard 2.0's SCENARIO_TIMEOUT; [`Rules::Lb2`] only): 0.70.
    pub scenario_timeout: f64,
}

impl Default for Penalties {
    fn default() -> Self {
        Self {
            pedestrian: 0.50,
            vehicle: 0.60,
            layout: 0.65,
            red_light: 0.70,
            stop: 0.80,
            scenario_timeout: 0.70,
        }
    }
}

/// Which leaderboard's rules score a route.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Rules {
    /// Leaderboard 1.0, criterion by criterion (this module's doc).
    #[default]
    Lb1,
    /// Leaderboard 2.0's penalty table where it applies here: LB1.0's criteria and coefficients,
    /// plus the minimum-speed test (4 checkpoints; each value p < 100 % multiplies IS by
    /// 1 - 0.3 (1 - p / 100), "min_speed_infractions"), the scenario timeout (a route-blocking
    /// scenario, Scenario6 here, that the ego has not got past [`SCENARIO_TIMEOUT_S`] after it
    /// fired ends, its barriers and vehicles gone, and multiplies IS by 0.70,
    /// "scenario_timeouts") and the status "Perfect" for a route completed with no infraction.
    /// Not applied: 2.0's progress-based route timeout (our maps carry no speed limits;
    /// LB1.0's timeout stays) and yielding to emergency vehicles (none drive here).
    Lb2,
}

impl Rules {
    /// How long a route-blocking scenario may hold the ego before it ends, under these rules
    /// (`None`: it stands for good, as in leaderboard 1.0).
    pub fn scenario_timeout(self) -> Option<f64> {
        (self == Rules::Lb2).then_some(SCENARIO_TIMEOUT_S)
    }
}

/// Every threshold of the criteria; [`Default`] gives the leaderboard 1.0 values.
#[derive(Debug, Clone, PartialEq)]
pub struct ScoringConfig {
    /// The rules (leaderboard 1.0 unless asked).
    pub rules: Rules,
    /// Infraction coefficients.
    pub penalties: Penalties,
    /// RouteCompletionTest WINDOWS_SIZE: route points tested past the current one (2).
    pub completion_window: usize,
    /// RC (percent) that must be exceeded to complete the route (99).
    pub completion_percentage: f64,
    /// Distance to the last route point under which the route completes (10 m).
    pub completion_distance: f64,
    /// OutsideRouteLanesTest ALLOWED_OUT_DISTANCE beyond half the lane width (1.3 m).
    pub outside_lane_margin: f64,
    /// OutsideRouteLanesTest WINDOWS_SIZE for its own route index (3).
    pub lane_window: usize,
    /// MAX_ALLOWED_VEHICLE_ANGLE, degrees, after leaving a junction (120).
    pub wrong_lane_vehicle_angle: f64,
    /// MAX_ALLOWED_WAYPOINT_ANGLE, degrees, lane-heading jump that toggles wrong lane (150).
    pub wrong_lane_waypoint_angle: f64,
    /// CollisionTest MAX_ID_TIME: seconds the last collided id is remembered (5).
    pub collision_id_seconds: f64,
    /// CollisionTest MIN_AREA_OF_COLLISION: ignore contacts this close to a stored one (3 m).
    pub collision_min_area: f64,
    /// CollisionTest MAX_AREA_OF_COLLISION: forget stored locations beyond this (5 m).
    pub collision_max_area: f64,
    /// RunningRedLightTest DISTANCE_LIGHT: reach of a light's trigger centre (15 m).
    pub light_distance: f64,
    /// RunningStopTest PROXIMITY_THRESHOLD (50 m).
    pub stop_proximity: f64,
    /// RunningStopTest SPEED_THRESHOLD: below it the ego counts as stopped (0.1 m/s).
    pub stop_speed: f64,
    /// Horizon points along the ego's lane in the stop test (20).
    pub stop_horizon_points: usize,
    /// Step between horizon points (RunningStopTest WAYPOINT_STEP, 1 m).
    pub stop_horizon_step: f64,
    /// Length of our stop-sign trigger box before the stop line (6 m; not a CARLA value).
    pub stop_box_length: f64,
    /// InRouteTest offroad_max: deviation distance (30 m).
    pub deviation_max: f64,
    /// InRouteTest offroad_min (offroad_max / 2 = 15 m).
    pub deviation_min: f64,
    /// InRouteTest WINDOWS_SIZE (5).
    pub deviation_window: usize,
    /// InRouteTest MAX_ROUTE_PERCENTAGE as a fraction (0.3).
    pub out_route_fraction: f64,
    /// ActorSpeedAboveThresholdTest speed threshold (0.1 m/s).
    pub blocked_speed: f64,
    /// Seconds below `blocked_speed` that block the agent (180 s in route_scenario).
    pub blocked_seconds: f64,
    /// SECONDS_GIVEN_PER_METERS of the route timeout (0.8).
    pub timeout_per_meter: f64,
    /// INITIAL_SECONDS_DELAY of the route timeout (5 s).
    pub timeout_delay: f64,
    /// Fixed route timeout in seconds; `None` uses the LB1.0 formula (see [`route_timeout`]).
    pub timeout: Option<f64>,
}

impl Default for ScoringConfig {
    fn default() -> Self {
        Self {
            rules: Rules::default(),
            penalties: Penalties::default(),
            completion_window: 2,
            completion_percentage: 99.0,
            completion_distance: 10.0,
            outside_lane_margin: 1.3,
            lane_window: 3,
            wrong_lane_vehicle_angle: 120.0,
            wrong_lane_waypoint_angle: 150.0,
            collision_id_seconds: 5.0,
            collision_min_area: 3.0,
            collision_max_area: 5.0,
            light_distance: 15.0,
            stop_proximity: 50.0,
            stop_speed: 0.1,
            stop_horizon_points: 20,
            stop_horizon_step: 1.0,
            stop_box_length: 6.0,
            deviation_max: 30.0,
            deviation_min: 15.0,
            deviation_window: 5,
            out_route_fraction: 0.3,
            blocked_speed: 0.1,
            blocked_seconds: 180.0,
            timeout_per_meter: 0.8,
            timeout_delay: 5.0,
            timeout: None,
        }
    }
}

/// Why a route ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RouteEnd {
    /// RC passed 99 % within 10 m of the last route point (ROUTE_COMPLETED).
    Completed,
    /// InRouteTest failed (ROUTE_DEVIATION).
    Deviated,
    /// ActorSpeedAboveThresholdTest failed (VEHICLE_BLOCKED).
    Blocked,
    /// The route's TimeOut node expired.
    TimedOut,
    /// The agent failed (LB1.0's AgentError: "Agent crashed").
    AgentCrashed,
    /// The user's fixed timeout (`ScoringConfig::timeout`, `eval --timeout`) cut the run: not
    /// the leaderboard's, no timeout infraction (ours).
    Stopped,
}

impl RouteEnd {
    /// The record status the leaderboard writes for it.
    pub fn status(self) -> &'static str {
        match self {
            RouteEnd::Completed => "Completed",
            RouteEnd::Deviated => "Failed - Agent deviated from the route",
            RouteEnd::Blocked => "Failed - Agent got blocked",
            RouteEnd::TimedOut => "Failed - Agent timed out",
            RouteEnd::AgentCrashed => "Failed - Agent crashed",
            RouteEnd::Stopped => "Stopped - --timeout reached",
        }
    }
}

/// The kinds of traffic event a route record lists, one per LB1.0 infraction key.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum InfractionKind {
    /// `collisions_pedestrian` (COLLISION_PEDESTRIAN).
    CollisionPedestrian,
    /// `collisions_vehicle` (COLLISION_VEHICLE).
    CollisionVehicle,
    /// `collisions_layout` (COLLISION_STATIC).
    CollisionLayout,
    /// `red_light` (TRAFFIC_LIGHT_INFRACTION).
    RedLight,
    /// `stop_infraction` (STOP_INFRACTION).
    StopSign,
    /// `outside_route_lanes` (OUTSIDE_ROUTE_LANES_INFRACTION), emitted once at the end.
    OutsideRouteLanes,
    /// `route_dev` (ROUTE_DEVIATION), ends the route.
    RouteDeviation,
    /// `vehicle_blocked` (VEHICLE_BLOCKED), ends the route.
    VehicleBlocked,
    /// `route_timeout`, ends the route.
    RouteTimeout,
    /// `min_speed_infractions` (Leaderboard 2.0's MIN_SPEED_INFRACTION; [`Rules::Lb2`] only).
    MinSpeed,
    /// `scenario_timeouts` (Leaderboard 2.0's SCENARIO_TIMEOUT; [`Rules::Lb2`] only).
    ScenarioTimeout,
}

impl InfractionKind {
    /// Every kind: the leaderboard 1.0 ones ([`InfractionKind::LB1`]) and 2.0's
    /// ([`InfractionKind::LB2_ONLY`]).
    pub const ALL: [InfractionKind; 11] = {
        let mut all = [InfractionKind::MinSpeed; 11];
        let mut i = 0;
        while i < Self::LB1.len() {
            all[i] = Self::LB1[i];
            i += 1;
        }
        while i < all.len() {
            all[i] = Self::LB2_ONLY[i - Self::LB1.len()];
            i += 1;
        }
        all
    };

    /// The kinds only leaderboard 2.0's rules ([`Rules::Lb2`]) record.
    pub const LB2_ONLY: [InfractionKind; 2] =
        [InfractionKind::MinSpeed, InfractionKind::ScenarioTimeout];

    /// The leaderboard 1.0 kinds, in the order of its `labels`/`values` rows.
    pub const LB1: [InfractionKind; 9] = [
        InfractionKind::CollisionPedestrian,
        InfractionKind::CollisionVehicle,
        InfractionKind::CollisionLayout,
        InfractionKind::RedLight,
        InfractionKind::StopSign,
        InfractionKind::OutsideRouteLanes,
        InfractionKind::RouteDeviation,
        InfractionKind::RouteTimeout,
        InfractionKind::VehicleBlocked,
    ];

    /// The key in a record's `infractions`.
    pub fn key(self) -> &'static str {
        match self {
            InfractionKind::CollisionPedestrian => "collisions_pedestrian",
            InfractionKind::CollisionVehicle => "collisions_vehicle",
            InfractionKind::CollisionLayout => "collisions_layout",
            InfractionKind::RedLight => "red_light",
            InfractionKind::StopSign => "stop_infraction",
            InfractionKind::OutsideRouteLanes => "outside_route_lanes",
            InfractionKind::RouteDeviation => "route_dev",
            InfractionKind::VehicleBlocked => "vehicle_blocked",
            InfractionKind::RouteTimeout => "route_timeout",
            InfractionKind::MinSpeed => "min_speed_infractions",
            InfractionKind::ScenarioTimeout => "scenario_timeouts",
        }
    }

    /// A short column heading for tables.
    pub fn short(self) -> &'static str {
        match self {
            InfractionKind::CollisionPedestrian => "ped",
            InfractionKind::CollisionVehicle => "veh",
            InfractionKind::CollisionLayout => "lay",
            InfractionKind::RedLight => "red",
            InfractionKind::StopSign => "stop",
            InfractionKind::OutsideRouteLanes => "off",
            InfractionKind::RouteDeviation => "dev",
            InfractionKind::VehicleBlocked => "blk",
            InfractionKind::RouteTimeout => "tout",
            InfractionKind::MinSpeed => "slow",
            InfractionKind::ScenarioTimeout => "stmo",
        }
    }
}

/// One traffic event of a route.
#[derive(Debug, Clone, PartialEq)]
pub struct Infraction {
    /// What happened.
    pub kind: InfractionKind,
    /// Simulation time since the route started, seconds.
    pub time: f64,
    /// Where (the ego, or the light / stop sign it ran), map frame.
    pub location: DVec3,
    /// The leaderboard's message, e.g. "Agent collided against object with type=vehicle and
    /// id=12 at (x=1.0, y=2.0, z=0.0)".
    pub text: String,
    /// What it multiplies IS by (1.0 for the route-ending events).
    pub factor: f64,
    /// Ours, for failure analysis (the record's `meta.events`): how a vehicle collision
    /// happened ([`collisions::vehicle_contact`]) or which lane and head a red light was run
    /// from; `None` for the other kinds.
    pub detail: Option<String>,
}

/// Scores one route with the LB1.0 criteria. Create it when the route starts, call
/// [`RouteScorer::tick`] every tick, then [`RouteScorer::finish`].
#[derive(Debug)]
pub struct RouteScorer<'a> {
    map: &'a Map,
    route: &'a DenseRoute,
    config: ScoringConfig,
    timeout: f64,
    completion: completion::RouteCompletion,
    lanes: lanes::OutsideRouteLanes,
    collisions: collisions::Collisions,
    red_lights: lights::RedLights,
    stops: lights::StopSigns,
    in_route: progress::InRoute,
    blocked: progress::Blocked,
    efficiency: bench2drive::SpeedRatio,
    min_speed: Option<bench2drive::SpeedRatio>,
    comfort: comfort::ComfortTrace,
    ticks: u64,
    infractions: Vec<Infraction>,
    end: Option<RouteEnd>,
    last_time: f64,
    last_location: DVec3,
}

impl<'a> RouteScorer<'a> {
    /// A scorer for `route` on `map`.
    pub fn new(map: &'a Map, route: &'a DenseRoute, config: ScoringConfig) -> Self {
        let timeout = config
            .timeout
            .unwrap_or_else(|| route_timeout(route.length(), &config));
        let start = route
            .points
            .first()
            .map(|p| p.position)
            .unwrap_or(DVec3::ZERO);
        Self {
            map,
            route,
            timeout,
            completion: completion::RouteCompletion::default(),
            lanes: lanes::OutsideRouteLanes::new(map),
            collisions: collisions::Collisions::default(),
            red_lights: lights::RedLights::default(),
            stops: lights::StopSigns::new(map, &config),
            in_route: progress::InRoute::default(),
            blocked: progress::Blocked::default(),
            efficiency: bench2drive::SpeedRatio::new(
                route.length(),
                bench2drive::EFFICIENCY_CHECKPOINTS,
            ),
            min_speed: (config.rules == Rules::Lb2).then(|| {
                bench2drive::SpeedRatio::new(route.length(), bench2drive::MIN_SPEED_CHECKPOINTS)
            }),
            comfort: comfort::ComfortTrace::default(),
            ticks: 0,
            config,
            infractions: Vec::new(),
            end: None,
            last_time: 0.0,
            last_location: start,
        }
    }

    /// Note which traffic lights' heads the agent's camera `rig` frames from `ego` at sim time
    /// `t` (`lights` indexed like `map.lights`), so that a red light's detail says what the
    /// agent last had in frame of it ([`sightings`]). Call it on the ticks the agent gets
    /// frames, before [`RouteScorer::tick`]; a scorer never told says nothing of sightings.
    pub fn frame_lamps(&mut self, t: f64, ego: &EgoState, lights: &[LightState], rig: &Rig) {
        self.red_lights.frame_lamps(self.map, t, ego, lights, rig);
    }

    /// Evaluate every criterion on the state at sim time `t` (seconds since the route started).
    /// Called once per 20 Hz tick, after the agent acted and before the world integrates;
    /// `collisions` are the contacts the world detected since the last call, `lights` the light
    /// states indexed like `map.lights`, `traffic_speed` the mean speed of the background
    /// vehicles (m/s; `None` when there are none), for efficiency and minimum speed. Returns
    /// why the route ended, if it did (then and on every later call, which evaluates nothing
    /// more).
    ///
    /// Criteria run in the order LB1.0 builds them: collision, in-route, completion, outside
    /// route lanes, red light, stop sign, blocked; then the route timeout. If several end the
    /// route on one tick, completion wins, then blocked, deviation and timeout (the order in
    /// which the leaderboard overwrites the failure message).
    pub fn tick(
        &mut self,
        t: f64,
        ego: &EgoState,
        collisions: &[CollisionEvent],
        lights: &[LightState],
        traffic_speed: Option<f64>,
    ) -> Option<RouteEnd> {
        if self.end.is_some() {
            return self.end;
        }
        if self.ticks.is_multiple_of(comfort::TICKS_PER_SAMPLE) {
            self.comfort.push(comfort::MotionSample {
                velocity: ego.forward() * ego.speed,
                yaw: ego.yaw,
            });
        }
        self.ticks += 1;
        self.last_time = t;
        self.last_location = ego.position;
        let cfg = &self.config;
        let driving = self
            .map
            .waypoint(ego.position, |l| l.kind == LaneKind::Driving);

        let in_junction = driving
            .as_ref()
            .is_some_and(|w| self.map.lane(w.lane).in_junction());
        self.collisions
            .register(t, collisions, in_junction, cfg, &mut self.infractions);
        self.collisions.update(t, ego.position, cfg);

        let deviated = self.in_route.update(self.route, ego.position, cfg);
        if deviated {
            self.infractions.push(Infraction {
                kind: InfractionKind::RouteDeviation,
                time: t,
                location: ego.position,
                text: format!(
                    "Agent deviated from the route at {}",
                    fmt_location(ego.position)
                ),
                factor: 1.0,
                detail: None,
            });
        }

        let completed = self.completion.update(self.route, ego.position, cfg);
        let progress_m = self.progress_m();
        self.efficiency.update(progress_m, ego.speed, traffic_speed);
        if let Some(value) = self
            .min_speed
            .as_mut()
            .and_then(|test| test.update(progress_m, ego.speed, traffic_speed))
        {
            Self::push_min_speed(&mut self.infractions, value, t, ego.position);
        }

        self.lanes
            .update(self.map, self.route, ego, driving.as_ref(), cfg);

        self.red_lights
            .update(self.map, t, ego, lights, cfg, &mut self.infractions);
        self.stops.update(
            self.map,
            t,
            ego,
            driving.as_ref(),
            cfg,
            &mut self.infractions,
        );

        let blocked = self.blocked.update(t, ego.speed, cfg);
        if blocked {
            self.infractions.push(Infraction {
                kind: InfractionKind::VehicleBlocked,
                time: t,
                location: ego.position,
                text: format!("Agent got blocked at {}", fmt_location(ego.position)),
                factor: 1.0,
                detail: None,
            });
        }

        let timed_out = t >= self.timeout;
        let cut = timed_out && self.config.timeout.is_some();
        if timed_out && !completed && !cut {
            self.push_timeout(t, ego.position);
        }

        self.end = if completed {
            Some(RouteEnd::Completed)
        } else if blocked {
            Some(RouteEnd::Blocked)
        } else if deviated {
            Some(RouteEnd::Deviated)
        } else if cut {
            Some(RouteEnd::Stopped)
        } else if timed_out {
            Some(RouteEnd::TimedOut)
        } else {
            None
        };
        self.end
    }

    /// Leaderboard 2.0's minimum-speed event for a checkpoint value (percent) under 100.
    fn push_min_speed(infractions: &mut Vec<Infraction>, value: f64, t: f64, location: DVec3) {
        if value >= 100.0 {
            return;
        }
        infractions.push(Infraction {
            kind: InfractionKind::MinSpeed,
            time: t,
            location,
            text: format!(
                "Average speed is {}% of the surrounding traffic's one",
                py_round(value, 2)
            ),
            factor: 1.0 - MIN_SPEED_WEIGHT * (1.0 - value / 100.0),
            detail: None,
        });
    }

    /// Leaderboard 2.0's scenario timeout: the world ended scenario `name` at sim time `t`, the
    /// ego at `location`, because the ego had not got past it in time
    /// ([`Rules::scenario_timeout`]). Ignored once the route has ended.
    pub fn scenario_timed_out(&mut self, t: f64, name: &str, location: DVec3) {
        if self.end.is_some() {
            return;
        }
        self.infractions.push(Infraction {
            kind: InfractionKind::ScenarioTimeout,
            time: t,
            location,
            text: format!("Agent timed out a scenario ({name})"),
            factor: self.config.penalties.scenario_timeout,
            detail: None,
        });
    }

    fn push_timeout(&mut self, t: f64, location: DVec3) {
        self.infractions.push(Infraction {
            kind: InfractionKind::RouteTimeout,
            time: t,
            location,
            text: "Route timeout.".to_string(),
            factor: 1.0,
            detail: None,
        });
    }

    /// Metres of the route behind the ego (RC of the dense route's length).
    fn progress_m(&self) -> f64 {
        self.completion.percentage / 100.0 * self.route.length()
    }

    /// Route completion in percent (RC), live; 100 once the route is completed.
    pub fn route_completion(&self) -> f64 {
        self.completion.percentage
    }

    /// Whether the route was completed (ROUTE_COMPLETED fired).
    pub fn completed(&self) -> bool {
        self.completion.completed
    }

    /// The infraction score so far: the product of the events' coefficients. The off-lane factor
    /// joins only at [`RouteScorer::finish`], as in LB1.0.
    pub fn infraction_score(&self) -> f64 {
        self.infractions.iter().map(|i| i.factor).product()
    }

    /// Every event so far, in the order they happened.
    pub fn infractions(&self) -> &[Infraction] {
        &self.infractions
    }

    /// Why the route ended, once it has.
    pub fn end(&self) -> Option<RouteEnd> {
        self.end
    }

    /// The route's timeout in seconds of simulation time.
    pub fn timeout_seconds(&self) -> f64 {
        self.timeout
    }

    /// The configuration in use.
    pub fn config(&self) -> &ScoringConfig {
        &self.config
    }

    /// Close the route and build its record, as LB1.0 `compute_route_statistics` does: the
    /// outside-route-lanes criterion emits its single event (IS *= 1 - percentage / 100),
    /// `route_timeout` gets "Route timeout." when the route timed out (`end` may report a
    /// timeout the caller enforced itself), RC is 100 when completed, else the last RC; DS =
    /// max(RC * IS, 0). The status is "Completed" when the target was reached, else "Failed"
    /// plus the reason. `meta.route_length` is the route file's keypoint length, as in LB1.0;
    /// `repetition` and `seed` are left for the caller to fill.
    pub fn finish(
        self,
        end: Option<RouteEnd>,
        route_id: &str,
        index: usize,
        duration_game: f64,
        duration_system: f64,
    ) -> RouteRecord {
        self.finish_with_infractions(end, route_id, index, duration_game, duration_system)
            .0
    }

    /// [`RouteScorer::finish`], also handing back every event of the route, the end-of-route
    /// ones (outside route lanes, a caller-reported timeout) included.
    pub fn finish_with_infractions(
        mut self,
        end: Option<RouteEnd>,
        route_id: &str,
        index: usize,
        duration_game: f64,
        duration_system: f64,
    ) -> (RouteRecord, Vec<Infraction>) {
        let end = self.end.or(end);
        let has = |s: &Self, k: InfractionKind| s.infractions.iter().any(|i| i.kind == k);
        if end == Some(RouteEnd::TimedOut)
            && !self.completion.completed
            && !has(&self, InfractionKind::RouteTimeout)
        {
            self.push_timeout(self.last_time, self.last_location);
        }
        let progress_m = self.progress_m();
        if let Some(value) = self
            .min_speed
            .as_mut()
            .and_then(|test| test.finish(progress_m))
        {
            Self::push_min_speed(
                &mut self.infractions,
                value,
                self.last_time,
                self.last_location,
            );
        }
        if let Some(off) = self.lanes.finish(self.last_time, self.last_location) {
            self.infractions.push(off);
        }

        let completed = self.completion.completed;
        let score_route = if completed {
            100.0
        } else {
            self.completion.percentage
        };
        let score_penalty = self.infraction_score();
        let status = if completed && self.config.rules == Rules::Lb2 && self.infractions.is_empty()
        {
            PERFECT_STATUS.to_string()
        } else if completed {
            RouteEnd::Completed.status().to_string()
        } else if has(&self, InfractionKind::VehicleBlocked) {
            RouteEnd::Blocked.status().to_string()
        } else if has(&self, InfractionKind::RouteDeviation) {
            RouteEnd::Deviated.status().to_string()
        } else if has(&self, InfractionKind::RouteTimeout) {
            RouteEnd::TimedOut.status().to_string()
        } else {
            match end {
                Some(e) if e != RouteEnd::Completed => e.status().to_string(),
                _ => "Failed".to_string(),
            }
        };

        let mut infractions = Infractions::<Vec<String>>::default();
        for i in &self.infractions {
            infractions.get_mut(i.kind).push(i.text.clone());
        }
        self.efficiency.finish(progress_m);
        let efficiency = bench2drive::efficiency(self.efficiency.values());
        let comfort = self
            .comfort
            .comfort(&comfort::ComfortBounds::default())
            .map(|share| 100.0 * share);
        let mut record = RouteRecord {
            index,
            infractions,
            meta: RouteMeta {
                duration_game,
                duration_system,
                route_length: self.route.keypoint_length,
                repetition: None,
                seed: None,
                stopped_at_s: (end == Some(RouteEnd::Stopped)).then_some(self.timeout),
                events: self
                    .infractions
                    .iter()
                    .filter_map(|i| {
                        Some(RouteEvent {
                            kind: i.kind.key().to_string(),
                            time: i.time,
                            location: [i.location.x, i.location.y],
                            detail: i.detail.clone()?,
                        })
                    })
                    .collect(),
                bench2drive: None,
            },
            route_id: route_id.to_string(),
            scores: Scores {
                score_composed: (score_route * score_penalty).max(0.0),
                score_penalty,
                score_route,
            },
            status,
        };
        record.meta.bench2drive = Some(bench2drive::RouteFigures {
            success: bench2drive::success(&record),
            efficiency,
            comfort,
        });
        (record, self.infractions)
    }
}

/// Python's `str(round(x, digits))` for the magnitudes the messages print.
pub(crate) fn py_round(x: f64, digits: i32) -> String {
    let scale = 10f64.powi(digits);
    let r = (x * scale).round() / scale;
    format!("{r:?}")
}

/// The leaderboard's "(x=.., y=.., z=..)" with coordinates rounded to 3 decimals.
pub(crate) fn fmt_location(p: DVec3) -> String {
    format!(
        "(x={}, y={}, z={})",
        py_round(p.x, 3),
        py_round(p.y, 3),
        py_round(p.z, 3)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn python_style_rounding() {
        assert_eq!(py_round(12.0, 3), "12.0");
        assert_eq!(py_round(20.034_56, 3), "20.035");
        assert_eq!(py_round(-0.0001, 3), "-0.0");
        assert_eq!(py_round(19.999_6, 2), "20.0");
        assert_eq!(
            fmt_location(DVec3::new(1.0, -2.5, 0.25)),
            "(x=1.0, y=-2.5, z=0.25)"
        );
    }

    #[test]
    fn route_end_statuses_match_the_leaderboard() {
        assert_eq!(RouteEnd::Completed.status(), "Completed");
        assert_eq!(
            RouteEnd::Deviated.status(),
            "Failed - Agent deviated from the route"
        );
        assert_eq!(RouteEnd::Blocked.status(), "Failed - Agent got blocked");
        assert_eq!(RouteEnd::TimedOut.status(), "Failed - Agent timed out");
    }
}
