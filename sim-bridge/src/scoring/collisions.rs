//! Collisions, LB1.0 `CollisionTest`.
//!
//! Each contact the world reports is classified by the other actor: walker 0.50, vehicle
//! (cyclists included) 0.60, static layout 0.65. De-duplication, as in LB1.0:
//! - a contact with the last collided actor id is ignored; that id is forgotten 5 s after the
//!   collision, and static layout (id 0) never becomes the last id;
//! - a contact while the ego is within 3 m (plan) of a stored collision location is ignored;
//!   every counted collision stores the ego location, and a stored location is forgotten once
//!   the ego is more than 5 m from it.
//!
//! Timing: CARLA reports contacts through a sensor callback during the world tick, between two
//! criteria updates, and the update then prunes the memory. The scorer does the same per call:
//! first the contacts detected since the last call (stamped with the current time), then the
//! pruning at the current ego location. A collision never ends the route.

use glam::DVec3;

use crate::world::state::{CollisionClass, CollisionEvent};

use super::{Infraction, InfractionKind, ScoringConfig, fmt_location};

/// State of the collision criterion.
#[derive(Debug, Clone, Default)]
pub(crate) struct Collisions {
    last_id: Option<u32>,
    collision_time: f64,
    registered: Vec<DVec3>,
}

/// Plan distance.
fn plan_distance(a: DVec3, b: DVec3) -> f64 {
    (a - b).truncate().length()
}

impl Collisions {
    /// Count the contacts reported since the last call.
    pub fn register(
        &mut self,
        t: f64,
        events: &[CollisionEvent],
        cfg: &ScoringConfig,
        out: &mut Vec<Infraction>,
    ) {
        for event in events {
            if self.last_id == Some(event.other_id) {
                continue;
            }
            let location = event.location;
            if self
                .registered
                .iter()
                .any(|r| plan_distance(location, *r) <= cfg.collision_min_area)
            {
                continue;
            }
            let (kind, factor, type_id) = match event.class {
                CollisionClass::Pedestrian => (
                    InfractionKind::CollisionPedestrian,
                    cfg.penalties.pedestrian,
                    "walker.pedestrian",
                ),
                CollisionClass::Vehicle => (
                    InfractionKind::CollisionVehicle,
                    cfg.penalties.vehicle,
                    "vehicle",
                ),
                CollisionClass::Layout => (
                    InfractionKind::CollisionLayout,
                    cfg.penalties.layout,
                    "static.prop",
                ),
            };
            out.push(Infraction {
                kind,
                time: t,
                location,
                text: format!(
                    "Agent collided against object with type={type_id} and id={} at {}",
                    event.other_id,
                    fmt_location(location)
                ),
                factor,
            });
            self.collision_time = t;
            self.registered.push(location);
            if event.other_id != 0 {
                self.last_id = Some(event.other_id);
            }
        }
    }

    /// The per-tick update: forget far locations and an expired last id.
    pub fn update(&mut self, t: f64, ego: DVec3, cfg: &ScoringConfig) {
        self.registered
            .retain(|r| plan_distance(ego, *r) <= cfg.collision_max_area);
        if self.last_id.is_some() && t - self.collision_time > cfg.collision_id_seconds {
            self.last_id = None;
        }
    }
}
