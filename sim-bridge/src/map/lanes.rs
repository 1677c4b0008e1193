//! The lane graph the simulator drives on: every baked OpenDRIVE lane in travel order, with its
//! successors, its left and right same-direction neighbours and the junction it belongs to.
//!
//! Guarantees: centre lines run in the direction of travel (a `Backward` lane of the file is
//! reversed here), have at least two points, carry a cumulative arc length, and have no sideways
//! step (one in the file is ramped at 0.1 m a metre, so the heading of [`Lane::pose_at`] turns
//! only where the road bends); every index in a lane's links is a valid [`LaneIdx`] of the same
//! map.

use glam::{DVec2, DVec3};
use xodr::LaneType;

/// Dense index of a lane in [`super::Map::lanes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LaneIdx(pub u32);

impl LaneIdx {
    /// Position in the map's lane list.
    pub fn get(self) -> usize {
        self.0 as usize
    }
}

/// Dense index of a junction in [`super::Map::junctions`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct JunctionIdx(pub u32);

/// What a lane is for, as far as driving and scoring care.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum LaneKind {
    /// An ordinary traffic lane (OpenDRIVE `driving`): routes run here.
    Driving,
    /// A parking lane: not routed on, but not "outside the lanes" for scoring.
    Parking,
    /// A footway.
    Sidewalk,
    /// Hard shoulder, border, curb, median, restricted and the like.
    Shoulder,
    /// Anything else (biking, rail, unknown types).
    Other,
}

impl LaneKind {
    /// Collapse the OpenDRIVE lane type.
    pub fn from_xodr(kind: LaneType) -> Self {
        match kind {
            LaneType::Driving
            | LaneType::Entry
            | LaneType::Exit
            | LaneType::OnRamp
            | LaneType::OffRamp
            | LaneType::ConnectingRamp
            | LaneType::SlipLane
            | LaneType::Bidirectional => LaneKind::Driving,
            LaneType::Parking => LaneKind::Parking,
            LaneType::Sidewalk => LaneKind::Sidewalk,
            LaneType::Shoulder
            | LaneType::Border
            | LaneType::Curb
            | LaneType::Median
            | LaneType::Restricted
            | LaneType::Stop
            | LaneType::None => LaneKind::Shoulder,
            _ => LaneKind::Other,
        }
    }
}

/// One lane in travel order.
#[derive(Debug, Clone)]
pub struct Lane {
    /// This lane's index.
    pub idx: LaneIdx,
    /// What the lane is for.
    pub kind: LaneKind,
    /// The OpenDRIVE `<road id>`.
    pub road_id: String,
    /// The zero-based lane section within the road.
    pub section: usize,
    /// The OpenDRIVE `<lane id>` (negative right of the reference line).
    pub lane_id: i32,
    /// The junction the lane's road belongs to, if any.
    pub junction: Option<JunctionIdx>,
    /// Nominal width in metres.
    pub width: f64,
    /// Centre line in travel order (world frame, metres).
    pub points: Vec<DVec3>,
    /// Cumulative 3-D arc length at each point; `cum[0] == 0`.
    pub cum: Vec<f64>,
    /// Lanes entered from this lane's end.
    pub successors: Vec<LaneIdx>,
    /// Lanes that lead into this lane's start.
    pub predecessors: Vec<LaneIdx>,
    /// The same-direction neighbour to the left (lane change left), if any.
    pub left: Option<LaneIdx>,
    /// The same-direction neighbour to the right, if any.
    pub right: Option<LaneIdx>,
}

/// A place on a lane centre line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LanePose {
    /// Position on the centre line.
    pub position: DVec3,
    /// Heading of travel, radians, counter-clockwise from +x.
    pub yaw: f64,
}

impl Lane {
    /// Length of the centre line in metres.
    pub fn length(&self) -> f64 {
        *self.cum.last().unwrap_or(&0.0)
    }

    /// Whether it is a junction connector.
    pub fn in_junction(&self) -> bool {
        self.junction.is_some()
    }

    /// The segment containing arc length `s` (clamped) and the fraction along it.
    fn locate(&self, s: f64) -> (usize, f64) {
        let s = s.clamp(0.0, self.length());
        let i = match self.cum.binary_search_by(|c| c.total_cmp(&s)) {
            Ok(i) => i.min(self.points.len() - 2),
            Err(i) => i.saturating_sub(1).min(self.points.len() - 2),
        };
        let seg = self.cum[i + 1] - self.cum[i];
        let t = if seg > 0.0 {
            (s - self.cum[i]) / seg
        } else {
            0.0
        };
        (i, t)
    }

    /// Pose at arc length `s` along the centre line (clamped to the lane).
    pub fn pose_at(&self, s: f64) -> LanePose {
        let (i, t) = self.locate(s);
        let (a, b) = (self.points[i], self.points[i + 1]);
        let d = b - a;
        LanePose {
            position: a + d * t,
            yaw: d.y.atan2(d.x),
        }
    }

    /// Project a plan point onto the centre line: (arc length, signed lateral offset with
    /// positive to the left of travel, plan distance).
    pub fn project(&self, p: DVec2) -> Projection {
        let mut best = Projection {
            s: 0.0,
            offset: f64::INFINITY,
            distance: f64::INFINITY,
        };
        for i in 0..self.points.len() - 1 {
            best = best.min(self.project_segment(i, p));
        }
        best
    }

    /// Projection onto segment `i` only.
    pub(crate) fn project_segment(&self, i: usize, p: DVec2) -> Projection {
        let a = self.points[i].truncate();
        let b = self.points[i + 1].truncate();
        let d = b - a;
        let len2 = d.length_squared();
        let t = if len2 > 0.0 {
            ((p - a).dot(d) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let foot = a + d * t;
        let distance = (p - foot).length();
        let side = if len2 > 0.0 {
            d.perp_dot(p - a).signum()
        } else {
            1.0
        };
        let seg = self.cum[i + 1] - self.cum[i];
        Projection {
            s: self.cum[i] + seg * t,
            offset: side * distance,
            distance,
        }
    }
}

/// The result of projecting a point onto a lane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Arc length along the lane.
    pub s: f64,
    /// Signed lateral offset, positive left of travel.
    pub offset: f64,
    /// Plan distance from the centre line.
    pub distance: f64,
}

impl Projection {
    fn min(self, other: Projection) -> Projection {
        if other.distance < self.distance {
            other
        } else {
            self
        }
    }
}

/// Cumulative 3-D arc length of a polyline.
pub fn cumulative_length(points: &[DVec3]) -> Vec<f64> {
    let mut cum = Vec::with_capacity(points.len());
    let mut total = 0.0;
    cum.push(0.0);
    for w in points.windows(2) {
        total += (w[1] - w[0]).length();
        cum.push(total);
    }
    cum
}
