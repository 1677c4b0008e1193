//! Scenarios while they run: firing each at its trigger, and what a running one does every
//! tick until it ends (Scenario2's leading vehicle leaving, Scenario5's vehicles leaving,
//! Scenario6's oncoming flow, and under Leaderboard 2.0's rules Scenario6 timing out).

use glam::{DVec2, DVec3};

use super::{S2_EGO_NEAR, S2_EGO_STOOD_S, S6_SOURCE_CLEAR, ScenarioAction};
use crate::map::LaneIdx;
use crate::world::vehicle::Script;
use crate::world::{TrafficMode, World};

/// A fired scenario that still has something to do.
#[derive(Debug, Clone)]
pub(in crate::world) enum Running {
    /// Scenario2: the leading vehicle `id` leaves once the ego has stood near it.
    LeaderWaits(u32),
    /// Scenario5 and 6: `vehicles` leave, and a flow stops, once the ego's progress along the
    /// route passes `until` metres; a scenario that blocks the route also ends at its deadline.
    UntilEgoDrove {
        until: f64,
        vehicles: Vec<u32>,
        flow: Option<Flow>,
        blocking: Option<Blocking>,
    },
}

/// A running scenario whose props block the ego's lane (Scenario6's barriers), under a
/// scenario timeout.
#[derive(Debug, Clone)]
pub(in crate::world) struct Blocking {
    name: &'static str,
    /// Sim time at which it ends if the ego has not got past it, s.
    deadline: f64,
    /// Distance along the route beyond which the ego is past it, m.
    past: f64,
    /// Centres of its props.
    props: Vec<DVec2>,
}

/// A scenario that ended on Leaderboard 2.0's scenario timeout.
#[derive(Debug, Clone, PartialEq)]
pub struct TimedOut {
    /// Its leaderboard name, e.g. "Scenario6".
    pub name: &'static str,
    /// Sim time it ended, s.
    pub time: f64,
    /// Where the ego was then.
    pub ego: DVec3,
}

/// Scenario6's source of oncoming vehicles.
#[derive(Debug, Clone, Copy)]
pub(in crate::world) struct Flow {
    lane: LaneIdx,
    s: f64,
    speed: f64,
    left: usize,
}

impl World<'_> {
    /// Fire scenarios whose trigger the ego has reached; `progress` is the ego's index on the
    /// dense route.
    pub fn trigger_scenarios(&mut self, progress: usize) {
        self.route_progress = self.route_progress.max(progress);
        for k in 0..self.scenarios.len() {
            if self.scenarios[k].fired || self.scenarios[k].trigger > self.route_progress {
                continue;
            }
            self.scenarios[k].fired = true;
            self.fire(self.scenarios[k].name, self.scenarios[k].action.clone());
        }
    }

    /// The ego's distance along the route, m.
    fn ego_route_distance(&self) -> f64 {
        self.route_distance
            .get(self.route_progress)
            .copied()
            .unwrap_or(0.0)
    }

    fn next_id(&mut self) -> u32 {
        self.ids.0 += 1;
        self.ids.0
    }

    /// Scenarios that ended on their timeout since the last call
    /// ([`crate::world::WorldConfig::scenario_timeout`]), for the scorer.
    pub fn take_scenario_timeouts(&mut self) -> Vec<TimedOut> {
        std::mem::take(&mut self.timed_out)
    }

    fn fire(&mut self, name: &'static str, action: ScenarioAction) {
        match action {
            ScenarioAction::StartCrosser(id) => {
                if let Some(c) = self.crossers.iter_mut().find(|c| c.id == id) {
                    c.moving = true;
                }
            }
            ScenarioAction::RedLightRunner {
                ego_light,
                lane,
                s,
                straight,
            } => {
                self.lights.hold_green(ego_light, self.time + 15.0);
                let id = self.next_id();
                let runner = (Script::RunsReds, 8.0, 9.0);
                // With CARLA-like traffic the runner goes straight on across the ego's way, as
                // scenario_runner's does; courteous traffic keeps the runner that takes any way.
                let straight = straight.filter(|_| self.traffic_mode == TrafficMode::Carla);
                let from = straight.map_or((lane, s), |(lane, s, _)| (lane, s));
                self.traffic
                    .spawn_scenario_vehicle(self.map, id, from, runner, &mut self.rng);
                if let Some((_, _, through)) = straight {
                    self.traffic.set_path(self.map, id, through, &mut self.rng);
                }
            }
            ScenarioAction::LeadingVehicle { lane, s, speed } => {
                let id = self.next_id();
                let leader = (
                    Script::StopsShortOfJunction(super::S2_STOP_SHORT),
                    0.0,
                    speed,
                );
                self.traffic
                    .spawn_scenario_vehicle(self.map, id, (lane, s), leader, &mut self.rng);
                self.running.push(Running::LeaderWaits(id));
            }
            ScenarioAction::Release { vehicles, metres } => {
                for v in &mut self.traffic.vehicles {
                    if let Some((_, speed)) = vehicles.iter().find(|(id, _)| *id == v.id) {
                        v.script = Script::Traffic;
                        v.desired_speed = *speed;
                    }
                }
                self.running.push(Running::UntilEgoDrove {
                    until: self.ego_route_distance() + metres,
                    vehicles: vehicles.iter().map(|(id, _)| *id).collect(),
                    flow: None,
                    blocking: None,
                });
            }
            ScenarioAction::OncomingFlow {
                lane,
                s,
                speed,
                count,
                metres,
                barriers,
                past,
            } => {
                let blocking = self.scenario_timeout.map(|timeout| Blocking {
                    name,
                    deadline: self.time + timeout,
                    past,
                    props: barriers,
                });
                self.running.push(Running::UntilEgoDrove {
                    until: self.ego_route_distance() + metres,
                    vehicles: Vec::new(),
                    flow: Some(Flow {
                        lane,
                        s,
                        speed,
                        left: count,
                    }),
                    blocking,
                });
            }
            ScenarioAction::JunctionCrosser {
                lane,
                ego_to_junction,
            } => {
                const SPEED: f64 = 8.0;
                let ego_time = ego_to_junction / self.ego.speed.max(3.0);
                let length = self.map.lane(lane).length();
                let s = (length - SPEED * ego_time).clamp(0.0, (length - 3.0).max(0.0));
                let id = self.next_id();
                let crosser = (Script::RunsReds, SPEED, SPEED);
                self.traffic.spawn_scenario_vehicle(
                    self.map,
                    id,
                    (lane, s),
                    crosser,
                    &mut self.rng,
                );
            }
        }
    }

    /// One tick of the running scenarios: leaving vehicles leave, flows send the next.
    pub(in crate::world) fn run_scenarios(&mut self) {
        let ego = self.ego.state();
        let progressed = self.ego_route_distance();
        let mut leaving = Vec::new();
        let mut removed_props = Vec::new();
        let mut running = std::mem::take(&mut self.running);
        running.retain_mut(|r| match r {
            Running::LeaderWaits(id) => {
                let near = self
                    .traffic
                    .vehicles
                    .iter()
                    .find(|v| v.id == *id)
                    .is_none_or(|v| {
                        (v.pose(self.map).0 - ego.position).truncate().length() < S2_EGO_NEAR
                    });
                let done = near && self.ego_standing_for >= S2_EGO_STOOD_S;
                if done {
                    leaving.push(*id);
                }
                !done
            }
            Running::UntilEgoDrove {
                until,
                vehicles,
                flow,
                blocking,
            } => {
                if progressed >= *until {
                    leaving.append(vehicles);
                    return false;
                }
                if blocking.as_ref().is_some_and(|b| progressed >= b.past) {
                    *blocking = None;
                }
                if let Some(b) = blocking.as_mut().filter(|b| self.time >= b.deadline) {
                    leaving.append(vehicles);
                    removed_props.append(&mut b.props);
                    self.timed_out.push(TimedOut {
                        name: b.name,
                        time: self.time,
                        ego: ego.position,
                    });
                    return false;
                }
                if let Some(flow) = flow.as_mut().filter(|f| f.left > 0) {
                    let source = self.map.lane(flow.lane).pose_at(flow.s).position;
                    let clear = self.traffic.vehicles.iter().all(|v| {
                        (v.pose(self.map).0 - source).truncate().length() > S6_SOURCE_CLEAR
                    });
                    if clear {
                        self.ids.0 += 1;
                        let id = self.ids.0;
                        let oncoming = (Script::Traffic, flow.speed, flow.speed);
                        self.traffic.spawn_scenario_vehicle(
                            self.map,
                            id,
                            (flow.lane, flow.s),
                            oncoming,
                            &mut self.rng,
                        );
                        vehicles.push(id);
                        flow.left -= 1;
                    }
                }
                true
            }
        });
        self.running = running;
        self.traffic.vehicles.retain(|v| !leaving.contains(&v.id));
        self.statics
            .retain(|p| !removed_props.contains(&p.obb.centre));
    }
}
