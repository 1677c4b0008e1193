//! The privileged rule-based expert: it reads the dense route and the true world state and
//! drives like the CARLA autopilots the research notes describe (TransFuser-2022 / PDM-Lite).
//!
//! - Lateral: pure pursuit on the dense route, look-ahead 4-10 m growing with speed.
//! - Speed targets: [`ROAD_SPEED`] on road, [`JUNCTION_SPEED`] in and just before junctions,
//!   [`WALKER_SPEED`] near walkers and cyclists heading into its path and when nosing into a
//!   slow queue, capped by the curvature ahead.
//! - Longitudinal: IDM towards the nearest obstacle on the path ahead ([`hazards`]): a lead
//!   actor, the stop line of a red or yellow light (yellow only when it can still stop), a
//!   stop sign it has not yet stopped at, where a walker or cyclist will cross.
//! - A short-horizon collision forecast (2 s, 4 s near junctions) of the ego along its route
//!   against every moving actor at constant velocity brakes hard on a predicted overlap.
//! - Each tick it also states its plan ([`plan`]): where these rules take it over the next 3 s.

pub mod hazards;
pub mod oracle;
pub mod plan;

use glam::DVec2;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::{BrakeReason, LightAhead};

use crate::driver::{Agent, AgentError, Observation, RouteContext};
use crate::map::angle_diff;
use crate::route::DenseRoute;
use crate::world::World;
use crate::world::ego::EgoParams;
use crate::world::idm::Idm;
use crate::world::state::LightState;

/// Cruise speed on road, m/s.
pub const ROAD_SPEED: f64 = 8.0;
/// Speed in junctions, m/s.
pub const JUNCTION_SPEED: f64 = 5.0;
/// Speed near walkers and cyclists heading into the path, m/s.
pub const WALKER_SPEED: f64 = 2.0;
/// Heading error to the route (rad) beyond which the expert does not speed up: it is still in
/// a turn its path has already left (pure pursuit lags in the tightest connectors, radius 5-6
/// m on Town03), and accelerating there swings it wide across the next lane. The plan's
/// rollout, which lies on the route's centre line, does not model it.
const ALIGN_ERROR: f64 = 0.35;
/// Speed it may still reach while misaligned, m/s.
const ALIGN_SPEED: f64 = 3.0;
/// How the expert follows: a shorter headway and harder comfortable braking than traffic, a
/// longer standstill gap, and 2 m/s^2 of lateral acceleration in curves.
pub(crate) const IDM: Idm = Idm {
    accel: 2.0,
    decel: 3.5,
    min_gap: 4.0,
    headway: 0.8,
    lateral_accel: 2.0,
};

/// The expert.
#[derive(Debug, Default)]
pub struct Expert {
    route: Option<DenseRoute>,
    /// Index of the ego on the dense route.
    index: usize,
    hazards: hazards::HazardMemory,
    params: EgoParams,
    reason: Option<BrakeReason>,
    /// The last tick's light ahead.
    light_ahead: Option<hazards::NearestLight>,
    /// The last tick's plan, ego frame.
    plan: Vec<DVec2>,
}

impl Expert {
    /// A new expert.
    pub fn new() -> Self {
        Self::default()
    }

    /// Why the last control brakes (or holds the ego still): the hazard that made it, `None`
    /// when it does not brake or brakes only for speed (curves, junctions).
    pub fn brake_reason(&self) -> Option<BrakeReason> {
        self.reason
    }

    /// The last tick's light ahead, as a training label: the nearest light whose stop line ends
    /// a lane of the route within the expert's scan, with the free distance from the ego's
    /// front to that line; [`LightAhead::None`] when there is none.
    pub fn light_ahead(&self) -> LightAhead {
        let Some(light) = self.light_ahead else {
            return LightAhead::None;
        };
        let distance = light.gap;
        match light.state {
            LightState::Green => LightAhead::Green { distance },
            LightState::Yellow => LightAhead::Yellow { distance },
            LightState::Red => LightAhead::Red { distance },
        }
    }

    /// Which light [`Expert::light_ahead`] is (its index in [`crate::map::Map::lights`]).
    pub fn light_ahead_id(&self) -> Option<usize> {
        self.light_ahead.map(|light| light.id)
    }
}

impl Agent for Expert {
    fn name(&self) -> String {
        "expert".into()
    }

    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.route = Some(ctx.route.clone());
        self.index = 0;
        self.hazards = hazards::HazardMemory::default();
        self.params = EgoParams::default();
        self.reason = None;
        self.plan.clear();
        Ok(())
    }

    fn planned_trajectory(&self) -> Vec<DVec2> {
        self.plan.clone()
    }

    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        Ok(self.drive(obs, world))
    }
}

impl Expert {
    /// This tick's control (the expert never fails).
    fn drive(&mut self, obs: &Observation, world: &World<'_>) -> Control {
        let Some(route) = self.route.as_ref() else {
            return Control {
                steer: 0.0,
                throttle: 0.0,
                brake: 1.0,
            };
        };
        let map = world.map;
        let ego = world.ego_state();
        self.index = route.advance_index(self.index, ego.position.truncate(), 20);
        let steer = pure_pursuit(route, self.index, &ego, &self.params);

        let view = hazards::scan(world, route, self.index, &mut self.hazards);
        self.light_ahead = view.light_ahead;
        let mut target = target_speed(map, route, self.index, &view);
        if angle_diff(ego.yaw, route.points[self.index].yaw).abs() > ALIGN_ERROR {
            target = target.min(obs.speed.max(ALIGN_SPEED));
        }
        self.plan = plan::plan(&plan::PlanStart {
            map,
            route,
            index: self.index,
            ego: &ego,
            view: &view,
            max_brake: self.params.max_brake,
        });
        let free = IDM.acceleration(obs.speed, target, None);
        let mut accel = IDM.acceleration(obs.speed, target, view.obstacle);
        let mut cause = view.cause.filter(|_| accel < free - 0.1);
        if view.collision_predicted {
            accel = -self.params.max_brake;
            cause = Some(BrakeReason::PredictedCollision);
        }
        let control = to_pedals(accel, obs.speed, &self.params);
        let holding = obs.speed < 0.1 && control.throttle == 0.0;
        let reason = cause.filter(|_| control.brake > 0.0 || holding);
        if reason != self.reason {
            tracing::debug!(
                time = world.time,
                position = ?ego.position.truncate(),
                "expert brake reason: {reason:?}"
            );
        }
        self.reason = reason;
        let steer = if control.brake > 0.5 {
            steer * 0.5
        } else {
            steer
        };
        Control {
            steer: steer as f32,
            ..control
        }
    }
}

/// The speed the expert aims for at route point `index`: cruise, capped by the curvature ahead,
/// in and just before junctions, and near walkers.
fn target_speed(
    map: &crate::map::Map,
    route: &DenseRoute,
    index: usize,
    view: &hazards::HazardView,
) -> f64 {
    let mut target = ROAD_SPEED.min(curve_speed(route, index));
    if near_junction(map, route, index) {
        target = target.min(JUNCTION_SPEED);
    }
    if view.walker_near || view.nosing_in {
        target = target.min(WALKER_SPEED);
    }
    target
}

/// Throttle and brake that produce acceleration `accel` at `speed`.
fn to_pedals(accel: f64, speed: f64, p: &EgoParams) -> Control {
    let resist = if speed > 0.0 {
        p.rolling + p.drag * speed * speed
    } else {
        0.0
    };
    if accel >= -resist {
        let drive = p.max_accel * (1.0 - speed / p.top_speed).max(0.05);
        Control {
            steer: 0.0,
            throttle: ((accel + resist) / drive).clamp(0.0, 0.75) as f32,
            brake: 0.0,
        }
    } else if accel > -resist - 0.3 {
        Control::default()
    } else {
        Control {
            steer: 0.0,
            throttle: 0.0,
            brake: ((-accel - resist) / p.max_brake).clamp(0.0, 1.0) as f32,
        }
    }
}

/// Pure pursuit towards the route point one look-ahead distance past the ego.
///
/// The law is the agent's ([`ssr_control::trajectory::pursuit_steer`]: the wheel angle
/// `atan(2 L sin(alpha) / d)` from the rear axle, over the lock), kept here in `f64` on the world
/// frame: the expert aims at its dense route, not at an ego-frame plan, and moving it onto the
/// agent's `f32` function would shift every expert label of the recorded datasets by rounding.
fn pure_pursuit(
    route: &DenseRoute,
    index: usize,
    ego: &crate::world::state::EgoState,
    p: &EgoParams,
) -> f64 {
    let lookahead = (4.0 + 0.6 * ego.speed).clamp(4.0, 10.0);
    let rear = ego.position.truncate() - ego.forward() * (p.wheelbase / 2.0);
    let mut j = index;
    while j + 1 < route.points.len()
        && (route.points[j].position.truncate() - rear).length() < lookahead + p.wheelbase / 2.0
    {
        j += 1;
    }
    let d = route.points[j].position.truncate() - rear;
    let alpha = angle_diff(d.y.atan2(d.x), ego.yaw);
    let wheel = (2.0 * p.wheelbase * alpha.sin() / d.length().max(1.0)).atan();
    (-wheel / p.max_wheel_angle).clamp(-1.0, 1.0)
}

/// Speed that keeps lateral acceleration under the limit over the next 25 m.
fn curve_speed(route: &DenseRoute, index: usize) -> f64 {
    let mut limit = f64::INFINITY;
    let end = (index + 25).min(route.points.len().saturating_sub(4));
    for i in index..end {
        let turn = angle_diff(route.points[i + 3].yaw, route.points[i].yaw).abs();
        let len = route.cum[i + 3] - route.cum[i];
        if turn > 1e-3 && len > 0.5 {
            limit = limit.min(IDM.curve_speed(len / turn));
        }
    }
    limit
}

/// Whether a junction connector starts within 12 m ahead or the ego is in one.
fn near_junction(map: &crate::map::Map, route: &DenseRoute, index: usize) -> bool {
    let start = route.cum[index];
    route.points[index..]
        .iter()
        .zip(&route.cum[index..])
        .take_while(|(_, c)| **c - start < 12.0)
        .any(|(p, _)| map.lane(p.lane).in_junction())
}

/// Distance along the route from index `a` to index `b`.
pub(crate) fn along(route: &DenseRoute, a: usize, b: usize) -> f64 {
    route.cum[b] - route.cum[a]
}

/// Unit vector of the route at index `i`.
pub(crate) fn route_dir(route: &DenseRoute, i: usize) -> DVec2 {
    route.points[i].forward()
}
