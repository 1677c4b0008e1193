//! How background vehicles keep clear of the ego ([`EgoPresence`], the ego as they see it).
//!
//! A vehicle near the ego checks the corridor its path sweeps ([`EGO_WATCH`] m ahead) for the
//! ego's box, whatever lane the ego is on, and stops short of it; once the ego has stood
//! [`SQUEEZE_AFTER_S`], a vehicle it holds creeps past with a narrower margin, as drivers do past
//! a car that waits (see [`SQUEEZE_MARGIN`]). Courtesy: while the ego stands waiting to change
//! into a lane (its route changes lanes within [`MERGE_WAIT_AHEAD`] m), vehicles coming up that
//! lane behind it hold back [`COURTESY_GAP`] m short of its rear, within [`COURTESY_RANGE`], so a
//! queue lets it in, as drivers do for a car that signals (without it a lane change planned
//! inside a standing or crawling queue never happens). [`super::traffic`] follows the gaps
//! these give like any other.
//!
//! The squeeze and the courtesy, with two more in [`super::traffic`] (the ego's turn among the
//! vehicles waiting at a junction without lights, and way given to an ego that approaches a
//! junction at speed), read the ego's route or favour it; CARLA's traffic manager does none of
//! them. [`TrafficMode::Carla`] turns all four off and keeps only what the traffic manager does:
//! the ego is a body that vehicles do not drive into (the corridor check, and the ego holding
//! the junction connector it is on).

use glam::DVec2;

use super::state::Obb;
use super::vehicle::Vehicle;
use crate::map::lanes::LanePose;
use crate::map::{LaneIdx, Map};

/// A lane change on the ego's route this close ahead (along the route, m) while the ego stands
/// (slower than [`MERGE_WAIT_SPEED`], m/s) asks traffic on the target lane to let it in.
pub const MERGE_WAIT_AHEAD: f64 = 20.0;
/// Speed under which the ego counts as waiting to merge, m/s.
pub const MERGE_WAIT_SPEED: f64 = 1.0;
/// How far behind a waiting ego's rear the vehicles on the target lane stop, m.
const COURTESY_GAP: f64 = 1.5;
/// Vehicles whose front is farther than this behind that stop point go on as usual, m.
const COURTESY_RANGE: f64 = 30.0;
/// How far ahead of its front a vehicle checks its path for the ego's box, m.
const EGO_WATCH: f64 = 30.0;
/// Spacing of that check, m.
const EGO_WATCH_STEP: f64 = 1.0;
/// Clearance beyond its half width the vehicle keeps from the ego's box, m.
const EGO_WATCH_MARGIN: f64 = 0.4;
/// Seconds the ego must have stood before a held vehicle creeps past it with only
/// [`SQUEEZE_MARGIN`] of clearance. A vehicle that stops for an ego whose corner is near its
/// path while the ego waits for it (its nose near the ego's path) is a deadlock that neither
/// breaks: seen mid-junction on Town02, a crossing car and the ego each waiting for the other.
const SQUEEZE_AFTER_S: f64 = 5.0;
/// Clearance a vehicle's box keeps from a standing ego's box it creeps past, m.
const SQUEEZE_MARGIN: f64 = 0.1;
/// Spacing of the box sweep that checks the room to creep past, m.
const SQUEEZE_STEP: f64 = 0.25;
/// Speed under which a vehicle held by the ego creeps past it with [`SQUEEZE_MARGIN`], m/s:
/// faster, it keeps [`EGO_WATCH_MARGIN`] and brakes, so it passes at about this speed.
const SQUEEZE_SPEED: f64 = 1.0;

/// How background traffic treats the ego (`--traffic`). The default is CARLA's: a score here
/// should mean what it means there, and the courtesies raise it (sim-bridge/README.md, "Traffic").
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum TrafficMode {
    /// Courtesies CARLA's traffic manager does not extend: vehicles let the ego into a lane it
    /// waits to change into, give it its turn at junctions without lights and way when it
    /// approaches a junction at speed, and creep past it once it has stood 5 s.
    Courteous,
    /// As CARLA's traffic manager: the ego is an obstacle vehicles stop for, nothing more.
    #[default]
    Carla,
}

impl TrafficMode {
    /// The mode's name as `--traffic` takes it (clap's, so the two cannot drift apart).
    pub fn name(self) -> String {
        use clap::ValueEnum as _;
        self.to_possible_value()
            .map_or_else(String::new, |v| v.get_name().to_owned())
    }
}

/// The ego as other traffic sees it.
#[derive(Debug, Clone, Copy)]
pub struct EgoPresence {
    /// Lane and arc length, when the ego is on a driving lane.
    pub on_lane: Option<(LaneIdx, f64)>,
    /// Ground box.
    pub obb: Obb,
    /// Height of the box's ground, m.
    pub z: f64,
    /// Speed.
    pub speed: f64,
    /// The lane the ego waits to change into and the ego's arc length projected on it, while
    /// it stands before a lane change of its route.
    pub merging_into: Option<(LaneIdx, f64)>,
    /// The junction connector the ego's route enters next and since when the ego has been
    /// within [`super::traffic::REQUEST_DISTANCE`] of it, while it is not yet in the junction.
    pub junction_request: Option<(LaneIdx, f64)>,
    /// Seconds the ego has stood (slower than [`super::traffic::STANDING_SPEED`]) in a row.
    pub standing_for: f64,
    /// Whether traffic extends its courtesies to the ego. With [`TrafficMode::Carla`] the
    /// world leaves `merging_into` and `junction_request` empty.
    pub mode: TrafficMode,
}

impl EgoPresence {
    /// The centre of the ego's box.
    pub(super) fn position(&self) -> DVec2 {
        self.obb.centre
    }
}

/// Where the ego's box intrudes on the corridor a vehicle's path sweeps ahead of it, whatever
/// lane the ego is on (mid-junction, cutting a corner, merging in): the free gap to it and the
/// ego's speed along the path. The traffic's lane occupancy sees the ego only on the lane it is
/// matched to; this is the traffic manager's geometric check that keeps a follower from
/// driving into an ego that turns or stops across its path. A vehicle held by an ego that has
/// stood [`SQUEEZE_AFTER_S`] sweeps its own box instead ([`squeeze_gap`]), in
/// [`TrafficMode::Courteous`] only.
pub(super) fn ego_on_path(map: &Map, v: &Vehicle, ego: &EgoPresence) -> Option<(f64, f64)> {
    let (position, _) = v.pose(map);
    let near = (position.truncate() - ego.position()).length() < EGO_WATCH + 10.0;
    if !near || (position.z - ego.z).abs() > 3.0 {
        return None;
    }
    if ego.mode == TrafficMode::Courteous
        && ego.standing_for > SQUEEZE_AFTER_S
        && v.speed < SQUEEZE_SPEED
    {
        return squeeze_gap(map, v, ego).map(|gap| (gap, 0.0));
    }
    let corridor = v.half.y + EGO_WATCH_MARGIN;
    let ego_velocity = DVec2::from_angle(ego.obb.yaw) * ego.speed;
    path_poses(map, v, v.s + v.half.x, EGO_WATCH_STEP).find_map(|(along, pose)| {
        (ego.obb.distance_to(pose.position.truncate()) < corridor).then(|| {
            let speed = ego_velocity.dot(DVec2::from_angle(pose.yaw)).max(0.0);
            (along, speed)
        })
    })
}

/// How far a vehicle can move along its path before its box, grown by [`SQUEEZE_MARGIN`],
/// touches a standing ego's box (within [`EGO_WATCH`]); `None` when it passes clear.
fn squeeze_gap(map: &Map, v: &Vehicle, ego: &EgoPresence) -> Option<f64> {
    let half = v.half + DVec2::splat(SQUEEZE_MARGIN);
    path_poses(map, v, v.s, SQUEEZE_STEP).find_map(|(along, pose)| {
        let obb = Obb {
            centre: pose.position.truncate(),
            yaw: pose.yaw,
            half,
        };
        obb.overlaps(&ego.obb).then_some(along)
    })
}

/// Poses along a vehicle's path (its lane, then the lanes it will take) from arc length `from`
/// on its lane, every `step` metres for [`EGO_WATCH`] metres, each with the distance from
/// `from`.
fn path_poses<'a>(
    map: &'a Map,
    v: &'a Vehicle,
    from: f64,
    step: f64,
) -> impl Iterator<Item = (f64, LanePose)> + 'a {
    let mut lanes = std::iter::once(v.lane).chain(v.next.iter().copied());
    let mut lane = lanes.next().map(|l| map.lane(l));
    let mut s = from;
    let mut along = 0.0;
    std::iter::from_fn(move || {
        if along > EGO_WATCH {
            return None;
        }
        let mut current = lane?;
        while s > current.length() {
            s -= current.length();
            current = map.lane(lanes.next()?);
            lane = Some(current);
        }
        let item = (along, current.pose_at(s));
        s += step;
        along += step;
        Some(item)
    })
}

/// The free gap to where a vehicle coming up the lane a waiting ego changes into holds back
/// for it (see the module doc), if it is one of those vehicles.
pub(super) fn courtesy_hold(map: &Map, v: &Vehicle, ego: &EgoPresence) -> Option<f64> {
    let (lane, ego_s) = ego.merging_into?;
    let s = if v.lane == lane {
        v.s
    } else if v.next.first() == Some(&lane) {
        v.s - map.lane(v.lane).length()
    } else {
        return None;
    };
    let stop = ego_s - ego.obb.half.x - COURTESY_GAP;
    let gap = stop - (s + v.half.x);
    (gap > -0.5 && gap < COURTESY_RANGE).then_some(gap.max(0.0))
}
