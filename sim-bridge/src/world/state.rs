//! Plain state records the world publishes each tick and the scorer, the expert and the
//! renderer read: the ego, other actors, collisions and light states.

use glam::{DVec2, DVec3};
use serde::{Deserialize, Serialize};

/// An oriented box on the ground plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obb {
    /// Centre.
    pub centre: DVec2,
    /// Heading of the box's x axis, radians.
    pub yaw: f64,
    /// Half length (x) and half width (y), metres.
    pub half: DVec2,
}

impl Obb {
    /// Unit axes (forward, left).
    pub fn axes(&self) -> (DVec2, DVec2) {
        let f = DVec2::from_angle(self.yaw);
        (f, f.perp())
    }

    /// Whether two boxes overlap (separating-axis test).
    pub fn overlaps(&self, other: &Obb) -> bool {
        let d = other.centre - self.centre;
        let (a0, a1) = self.axes();
        let (b0, b1) = other.axes();
        for axis in [a0, a1, b0, b1] {
            let ra = self.half.x * a0.dot(axis).abs() + self.half.y * a1.dot(axis).abs();
            let rb = other.half.x * b0.dot(axis).abs() + other.half.y * b1.dot(axis).abs();
            if d.dot(axis).abs() > ra + rb {
                return false;
            }
        }
        true
    }

    /// Where `other` overlaps this box, the normal of the face of `other` it overlaps least:
    /// the unit axis of `other` pointing out of it towards this box's side, the face this box
    /// can slide along. `None` when the boxes do not overlap.
    pub fn contact_face_of(&self, other: &Obb) -> Option<DVec2> {
        if !self.overlaps(other) {
            return None;
        }
        let d = self.centre - other.centre;
        let (a0, a1) = self.axes();
        let (b0, b1) = other.axes();
        let depth = |axis: DVec2| {
            let ra = self.half.x * a0.dot(axis).abs() + self.half.y * a1.dot(axis).abs();
            let rb = other.half.x * b0.dot(axis).abs() + other.half.y * b1.dot(axis).abs();
            ra + rb - d.dot(axis).abs()
        };
        let axis = if depth(b0) <= depth(b1) { b0 } else { b1 };
        Some(if d.dot(axis) >= 0.0 { axis } else { -axis })
    }

    /// Plan distance from a point to the box (0 inside).
    pub fn distance_to(&self, p: DVec2) -> f64 {
        let (f, l) = self.axes();
        let d = p - self.centre;
        let local = DVec2::new(d.dot(f).abs() - self.half.x, d.dot(l).abs() - self.half.y);
        local.max(DVec2::ZERO).length()
    }

    /// Whether a point is inside.
    pub fn contains(&self, p: DVec2) -> bool {
        let (f, l) = self.axes();
        let d = p - self.centre;
        d.dot(f).abs() <= self.half.x && d.dot(l).abs() <= self.half.y
    }
}

/// The ego vehicle's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgoState {
    /// Centre of the vehicle box on the ground (world frame, metres).
    pub position: DVec3,
    /// Heading, radians counter-clockwise from +x (OpenDRIVE frame).
    pub yaw: f64,
    /// Forward speed, m/s (never negative).
    pub speed: f64,
    /// Half length and half width of the box, metres.
    pub half_extent: DVec2,
}

impl EgoState {
    /// The ego's ground box.
    pub fn obb(&self) -> Obb {
        Obb {
            centre: self.position.truncate(),
            yaw: self.yaw,
            half: self.half_extent,
        }
    }

    /// Unit forward vector in plan.
    pub fn forward(&self) -> DVec2 {
        DVec2::from_angle(self.yaw)
    }
}

/// What another actor is; decides the collision class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ActorKind {
    /// A car (background traffic or scenario vehicle).
    Vehicle,
    /// A cyclist: a vehicle for collision scoring, as bicycles are in CARLA.
    Cyclist,
    /// A pedestrian.
    Walker,
    /// A static prop or obstacle: a layout collision.
    Static,
    /// Flat debris on the road (Scenario1), drawn but driven over: never a contact, and not
    /// among [`crate::world::World::actors`].
    Debris,
}

/// Collision class and its infraction coefficient (leaderboard 1.0).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum CollisionClass {
    /// `collisions_pedestrian`, 0.50.
    Pedestrian,
    /// `collisions_vehicle`, 0.60.
    Vehicle,
    /// `collisions_layout`, 0.65.
    Layout,
}

impl ActorKind {
    /// The collision class a contact with this actor scores as.
    pub fn collision_class(self) -> CollisionClass {
        match self {
            ActorKind::Vehicle | ActorKind::Cyclist => CollisionClass::Vehicle,
            ActorKind::Walker => CollisionClass::Pedestrian,
            ActorKind::Static | ActorKind::Debris => CollisionClass::Layout,
        }
    }
}

/// A contact between the ego and another actor, reported on the tick it is detected.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CollisionEvent {
    /// The other actor's id; 0 for static layout (which never sets the "last id" rule).
    pub other_id: u32,
    /// Its class.
    pub class: CollisionClass,
    /// Where the ego was, world frame.
    pub location: DVec3,
    /// How the two boxes met (ours, for failure analysis); `None` where not known.
    pub contact: Option<ContactGeometry>,
}

/// How the ego and the actor it touched stood and moved at the contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactGeometry {
    /// The other actor's heading minus the ego's, radians in (-pi, pi].
    pub relative_yaw: f64,
    /// The other actor's centre in the ego frame (x forward, y left), m.
    pub other_offset: DVec2,
    /// The other actor's speed, m/s.
    pub other_speed: f64,
    /// The ego's speed, m/s.
    pub ego_speed: f64,
}

/// A traffic light's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum LightState {
    /// Go.
    Green,
    /// Stop if you can (the leaderboard does not penalise it).
    Yellow,
    /// Stop.
    Red,
}

impl LightState {
    /// "green", "yellow" or "red".
    pub fn name(self) -> &'static str {
        match self {
            LightState::Green => "green",
            LightState::Yellow => "yellow",
            LightState::Red => "red",
        }
    }
}
