//! Route scenarios and other non-traffic actors: walkers and cyclists that cross in front of
//! the ego, red-light runners at signalized junctions, debris, parked cars, and optional
//! background walkers on the sidewalks.
//!
//! A route's scenarios come from one of two placements: [`leaderboard`] gives it those a
//! leaderboard scenario file's triggers give it (`--scenarios`), as the leaderboard 1.0 does;
//! without a file, [`drawn`] draws S3, S4 and S7 along it from the world seed. [`builders`]
//! holds one builder per scenario type, which both use:
//! - S3 DynamicObjectCrossing: a walker waits behind a parked van on the right edge some metres
//!   past the trigger and crosses the whole road when the ego reaches the trigger.
//! - S4 VehicleTurningRoute: after a LEFT or RIGHT turn, a cyclist crosses the exit road a few
//!   metres past the junction.
//! - S7-S9 SignalJunctionCrossingRoute: at a signalized junction the ego crosses, its light is
//!   held green while a vehicle on a conflicting approach runs its red light.
//! - S1 ControlLoss (from a file only): debris on the ego's lane, driven over.
//!
//! Each scenario fires once, when the ego's progress along the route passes its trigger.

mod builders;
mod drawn;
mod leaderboard;
mod live;

pub use drawn::place_route_scenarios;
pub use leaderboard::place_from_file;
pub(super) use live::Running;
pub use live::TimedOut;

use glam::{DVec2, DVec3};
use rand::{Rng, RngExt as _};

use super::state::{ActorKind, Obb};
use crate::map::{LaneIdx, LaneKind, Map};
use crate::route::DenseRoute;
use crate::world::ActorView;

/// Metres of route between S3 walkers, on average.
pub const S3_SPACING: f64 = 250.0;
/// A standing scenario vehicle is in the way of a route that passes within this of its centre
/// (the route runs along its lane), m.
const SAME_LANE_M: f64 = 1.5;
/// A prop is in the way of a route that passes within this of its box (the ego's half width
/// and a margin), m.
const EGO_CLEARANCE_M: f64 = 1.2;
/// Metres past the trigger where the crossing happens.
pub const CROSSING_AHEAD: f64 = 22.0;
/// Walker speed, m/s.
const WALKER_SPEED: f64 = 1.8;
/// Cyclist speed, m/s.
const CYCLIST_SPEED: f64 = 4.0;

/// A walker or cyclist moving in a straight line.
#[derive(Debug, Clone)]
pub struct Crosser {
    /// Actor id.
    pub id: u32,
    /// Walker or cyclist.
    pub kind: ActorKind,
    /// Position (z on the ground).
    pub position: DVec3,
    /// Direction of motion, rad.
    pub yaw: f64,
    /// Speed when moving, m/s.
    pub speed: f64,
    /// Metres left to walk; it stops (and stays) when 0.
    pub remaining: f64,
    /// Whether it has started.
    pub moving: bool,
    /// Half length and half width.
    pub half: DVec2,
    /// Background walkers turn around at the end instead of stopping.
    pub patrol: bool,
    /// Left the scene: crossed the road (scenario crossers leave like CARLA's), or was hit.
    pub gone: bool,
}

impl Crosser {
    /// A scenario crosser waiting `offset` metres outside the road's right edge `edge`, facing
    /// across the `across`-metre carriageway, which it crosses completely once started.
    fn waiting_to_cross(
        id: u32,
        (kind, speed, half): (ActorKind, f64, DVec2),
        edge: DVec3,
        right: DVec2,
        offset: f64,
        across: f64,
    ) -> Self {
        let start = edge.truncate() + right * offset;
        Crosser {
            id,
            kind,
            position: start.extend(edge.z),
            yaw: (-right).y.atan2(-right.x),
            speed,
            remaining: offset + across + offset,
            moving: false,
            half,
            patrol: false,
            gone: false,
        }
    }

    /// Ground box.
    pub fn obb(&self) -> Obb {
        Obb {
            centre: self.position.truncate(),
            yaw: self.yaw,
            half: self.half,
        }
    }

    /// Current velocity in plan.
    pub fn velocity(&self) -> DVec2 {
        if self.moving && self.remaining > 0.0 {
            DVec2::from_angle(self.yaw) * self.speed
        } else {
            DVec2::ZERO
        }
    }

    /// Move for `dt`.
    pub fn step(&mut self, dt: f64) {
        if !self.moving {
            return;
        }
        if self.remaining <= 0.0 {
            if self.patrol {
                self.yaw += std::f64::consts::PI;
                self.remaining = 40.0;
            } else {
                self.gone = true;
            }
            return;
        }
        let d = (self.speed * dt).min(self.remaining);
        self.position += (DVec2::from_angle(self.yaw) * d).extend(0.0);
        self.remaining -= d;
    }
}

/// A static obstacle (parked car, scenario van): collisions with it are layout collisions. Also
/// the shape of Scenario1's debris, which nothing collides with.
#[derive(Debug, Clone, Copy)]
pub struct StaticProp {
    /// Ground box.
    pub obb: Obb,
    /// Ground height.
    pub z: f64,
}

impl StaticProp {
    /// As agents and renderers see it, as a `kind`.
    pub fn view(&self, kind: ActorKind) -> ActorView {
        ActorView {
            id: 0,
            kind,
            obb: self.obb,
            z: self.z,
            velocity: DVec2::ZERO,
        }
    }
}

/// What a scenario does when triggered.
#[derive(Debug, Clone)]
pub enum ScenarioAction {
    /// Start the crosser with this id.
    StartCrosser(u32),
    /// Hold `ego_light` green and launch a red-light runner from `lane` at `s`.
    RedLightRunner {
        /// Id of the traffic light that controls the ego's approach to the junction.
        ego_light: usize,
        /// Lane the runner starts on, taking any way across the ego's.
        lane: LaneIdx,
        /// Distance along that lane where the runner starts, m.
        s: f64,
        /// With CARLA-like traffic, where the runner starts instead and the connector it takes:
        /// an approach whose straight-on way crosses the ego's (the way scenario_runner's
        /// runner drives), if the junction has one.
        straight: Option<(LaneIdx, f64, LaneIdx)>,
    },
    /// Scenario2: a leading vehicle appears on `lane` at `s` and drives at `speed` until
    /// [`S2_STOP_SHORT`] m short of the next junction, where it stops; it leaves once the ego
    /// has stood [`S2_EGO_STOOD_S`] within [`S2_EGO_NEAR`] m of it.
    LeadingVehicle {
        /// Lane it appears on.
        lane: LaneIdx,
        /// Where along it, m.
        s: f64,
        /// Cruise speed, m/s.
        speed: f64,
    },
    /// Scenario5: the placed vehicles (ids, each with its cruise speed) that wait for the
    /// trigger drive off; they leave once the ego has driven `metres` past the trigger.
    Release {
        /// Vehicle ids and cruise speeds, m/s.
        vehicles: Vec<(u32, f64)>,
        /// How far past the trigger the ego drives before they leave, m.
        metres: f64,
    },
    /// Scenario6: vehicles come along the oncoming lane `lane` from `s` at `speed`, one
    /// whenever none is within [`S6_SOURCE_CLEAR`] m of the source, at most `count`, until the
    /// ego has driven `metres` past the trigger, when they leave. The static props centred at
    /// `barriers` block the ego's lane until it is `past` m along the route: under a scenario
    /// timeout ([`crate::world::WorldConfig::scenario_timeout`]) they go with the flow's
    /// vehicles if it is not past them by then.
    OncomingFlow {
        /// The oncoming lane.
        lane: LaneIdx,
        /// Where along it they appear, m.
        s: f64,
        /// Their speed, m/s.
        speed: f64,
        /// How many at most.
        count: usize,
        /// How far past the trigger the ego drives before they leave, m.
        metres: f64,
        /// Centres of the barriers across the ego's lane.
        barriers: Vec<DVec2>,
        /// Distance along the route beyond which the ego is past them, m.
        past: f64,
    },
    /// Scenario10: a vehicle on the approach `lane` of a junction without lights crosses it
    /// without giving way, placed so that at its speed it reaches the junction about when the
    /// ego, `ego_to_junction` m from its entry at the trigger, does at its speed then.
    JunctionCrosser {
        /// The approach lane it drives in on.
        lane: LaneIdx,
        /// The ego's distance to the junction at the trigger, along the route, m.
        ego_to_junction: f64,
    },
}

/// How far short of the next junction Scenario2's leading vehicle stops, m.
pub const S2_STOP_SHORT: f64 = 20.0;
/// Scenario2's leading vehicle leaves once the ego has stood this long ...
pub const S2_EGO_STOOD_S: f64 = 1.0;
/// ... within this distance of it, m.
pub const S2_EGO_NEAR: f64 = 20.0;
/// Scenario6's source sends the next vehicle once none is this close to it, m.
pub const S6_SOURCE_CLEAR: f64 = 40.0;

/// A scenario vehicle placed with the world that waits for its trigger (Scenario5).
#[derive(Debug, Clone, Copy)]
pub struct WaitingVehicle {
    /// Its id, which the scenario's action names.
    pub id: u32,
    /// Lane.
    pub lane: LaneIdx,
    /// Where along it, m.
    pub s: f64,
}

/// One scenario instance on the route.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Leaderboard name, e.g. "Scenario3".
    pub name: &'static str,
    /// Route index at which it fires.
    pub trigger: usize,
    /// What happens.
    pub action: ScenarioAction,
    /// Whether it has fired.
    pub fired: bool,
}

/// Actors and scenarios placed for one route.
#[derive(Debug, Default)]
pub struct Placement {
    /// Walkers and cyclists (scenario ones start still).
    pub crossers: Vec<Crosser>,
    /// Static props.
    pub statics: Vec<StaticProp>,
    /// Debris on the road (Scenario1).
    pub debris: Vec<StaticProp>,
    /// Scenario vehicles standing from the start (Scenario5).
    pub vehicles: Vec<WaitingVehicle>,
    /// Scenarios in trigger order.
    pub scenarios: Vec<Scenario>,
}

impl Placement {
    /// A scenario that fires at route index `trigger`.
    fn add(&mut self, name: &'static str, trigger: usize, action: ScenarioAction) {
        self.scenarios.push(Scenario {
            name,
            trigger,
            action,
            fired: false,
        });
    }

    /// Adds `one` scenario's actors and scenarios, unless a prop or standing vehicle of it
    /// stands on the part of `route` the ego drives before `trigger`: a route that comes back
    /// past a later scenario's place would meet them first and stand behind them for good
    /// (scenario_runner spawns them at the route's start too, but its occluders stand off the
    /// road). Returns whether it was added.
    fn add_unless_in_the_way(
        &mut self,
        map: &Map,
        route: &DenseRoute,
        trigger: usize,
        one: Placement,
    ) -> bool {
        let before = |z: f64, near: &dyn Fn(DVec2) -> bool| {
            route.points[..trigger]
                .iter()
                .any(|q| (q.position.z - z).abs() < 3.0 && near(q.position.truncate()))
        };
        let in_the_way = one.vehicles.iter().any(|v| {
            let at = map.lane(v.lane).pose_at(v.s).position;
            before(at.z, &|q| (q - at.truncate()).length() < SAME_LANE_M)
        }) || one
            .statics
            .iter()
            .any(|p| before(p.z, &|q| p.obb.distance_to(q) < EGO_CLEARANCE_M));
        if in_the_way {
            return false;
        }
        self.crossers.extend(one.crossers);
        self.statics.extend(one.statics);
        self.debris.extend(one.debris);
        self.vehicles.extend(one.vehicles);
        self.scenarios.extend(one.scenarios);
        true
    }

    /// A crosser that starts when the ego reaches route index `trigger`, unless the place it
    /// waits at reaches into a driving lane: where roads bend or meet, a spot beside one road
    /// can lie on another (the route's own, before the trigger: the ego would wait for it, and
    /// it for the ego, for good).
    fn add_crossing(&mut self, map: &Map, name: &'static str, trigger: usize, crosser: Crosser) {
        if reaches_driving_lane(map, &crosser.obb()) {
            return;
        }
        self.add(name, trigger, ScenarioAction::StartCrosser(crosser.id));
        self.crossers.push(crosser);
    }
}

/// Ids handed to actors, above the traffic's.
pub struct IdSource(pub u32);

impl IdSource {
    fn next(&mut self) -> u32 {
        self.0 += 1;
        self.0
    }
}

/// Whether a box on the ground reaches into a driving lane (a corner or the centre lies within
/// half a lane width of a driving lane's centre line).
fn reaches_driving_lane(map: &Map, obb: &Obb) -> bool {
    let forward = DVec2::from_angle(obb.yaw);
    let left = forward.perp();
    let corners = [
        (1.0, 1.0),
        (1.0, -1.0),
        (-1.0, 1.0),
        (-1.0, -1.0),
        (0.0, 0.0),
    ];
    corners.iter().any(|(a, b)| {
        let p = obb.centre + forward * (a * obb.half.x) + left * (b * obb.half.y);
        map.lanes_near(p, 4.0, |l| l.kind == LaneKind::Driving)
            .iter()
            .any(|(lane, proj)| proj.distance < map.lane(*lane).width / 2.0)
    })
}

/// Parked cars on parking lanes, about one per 12 m with gaps, from the seed; none where the
/// car would reach into a driving lane (CARLA's Town03 has parking lanes that run beside a
/// junction's connectors).
pub fn parked_cars(map: &Map, rng: &mut impl Rng) -> Vec<StaticProp> {
    let mut out = Vec::new();
    for lane in map
        .lanes
        .iter()
        .filter(|l| l.kind == LaneKind::Parking && l.length() > 8.0)
    {
        let mut s = rng.random_range(2.0..8.0);
        while s + 3.0 < lane.length() {
            if rng.random_range(0.0..1.0) < 0.45 {
                let pose = lane.pose_at(s);
                let obb = Obb {
                    centre: pose.position.truncate(),
                    yaw: pose.yaw,
                    half: DVec2::new(2.2, 0.95),
                };
                if !reaches_driving_lane(map, &obb) {
                    out.push(StaticProp {
                        obb,
                        z: pose.position.z,
                    });
                }
            }
            s += rng.random_range(6.0..9.0);
        }
    }
    out
}

/// Background walkers pacing along sidewalks.
pub fn background_walkers(
    map: &Map,
    count: usize,
    ids: &mut IdSource,
    rng: &mut impl Rng,
) -> Vec<Crosser> {
    let sidewalks: Vec<&crate::map::Lane> = map
        .lanes
        .iter()
        .filter(|l| l.kind == LaneKind::Sidewalk && l.length() > 20.0)
        .collect();
    if sidewalks.is_empty() {
        return Vec::new();
    }
    (0..count)
        .map(|_| {
            let lane = sidewalks[rng.random_range(0..sidewalks.len())];
            let pose = lane.pose_at(rng.random_range(0.0..lane.length()));
            Crosser {
                id: ids.next(),
                kind: ActorKind::Walker,
                position: pose.position,
                yaw: pose.yaw,
                speed: rng.random_range(1.0..1.6),
                remaining: rng.random_range(10.0..40.0),
                moving: true,
                half: DVec2::splat(0.3),
                patrol: true,
                gone: false,
            }
        })
        .collect()
}
