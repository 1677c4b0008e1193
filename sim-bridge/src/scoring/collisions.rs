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
//!
//! Ours: each counted vehicle collision says how the two met ([`vehicle_contact`]), for the
//! record's `meta.events`.

use glam::DVec3;

use crate::world::state::{CollisionClass, CollisionEvent, ContactGeometry};

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
        in_junction: bool,
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
                detail: event
                    .contact
                    .filter(|_| event.class == CollisionClass::Vehicle)
                    .map(|c| vehicle_contact(&c, in_junction)),
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

/// How a vehicle collision happened, e.g. "crossing, in a junction, other 6.2 m/s, ego 4.0
/// m/s": `crossing` (the other's heading 45-135 degrees off the ego's and it moving),
/// `standing across` (the same, it standing), `ego rear-ends` (headings within 45 degrees, the
/// other ahead), `hit from behind` (the other behind), `head-on` (more than 135 degrees); where
/// the ego stood (in a junction or on a road); both speeds.
pub fn vehicle_contact(c: &ContactGeometry, in_junction: bool) -> String {
    let off = c.relative_yaw.abs().to_degrees();
    let moving = c.other_speed > 0.5;
    let how = if off > 135.0 {
        "head-on"
    } else if off >= 45.0 {
        if moving {
            "crossing"
        } else {
            "standing across"
        }
    } else if c.other_offset.x > 0.0 {
        "ego rear-ends"
    } else {
        "hit from behind"
    };
    let place = if in_junction {
        "in a junction"
    } else {
        "on a road"
    };
    format!(
        "{how}, {place}, other {:.1} m/s, ego {:.1} m/s",
        c.other_speed, c.ego_speed
    )
}

#[cfg(test)]
mod tests {
    use glam::DVec2;

    use super::*;

    fn contact(relative_deg: f64, ahead: f64, other_speed: f64) -> ContactGeometry {
        ContactGeometry {
            relative_yaw: relative_deg.to_radians(),
            other_offset: DVec2::new(ahead, 0.5),
            other_speed,
            ego_speed: 4.0,
        }
    }

    #[test]
    fn vehicle_contacts_are_named_by_how_the_cars_met() {
        let named = |c: ContactGeometry, junction: bool| vehicle_contact(&c, junction);
        assert_eq!(
            named(contact(90.0, 3.0, 6.0), true),
            "crossing, in a junction, other 6.0 m/s, ego 4.0 m/s"
        );
        assert!(named(contact(-80.0, 3.0, 0.0), false).starts_with("standing across, on a road"));
        assert!(named(contact(10.0, 4.0, 0.0), false).starts_with("ego rear-ends"));
        assert!(named(contact(-5.0, -4.0, 8.0), false).starts_with("hit from behind"));
        assert!(named(contact(170.0, 3.0, 8.0), false).starts_with("head-on"));
    }
}
