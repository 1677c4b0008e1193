//! The finished town, as OpenDRIVE sees it: roads with final ids and links,
//! junctions with their connections, signals and controllers. The builder
//! produces it and the writer prints it.

use super::elevation::Cubic;
use super::geometry::Path;
use super::profile::{Profile, Side};

/// Which end of a road.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Contact {
    /// `s = 0`.
    Start,
    /// `s = length`.
    End,
}

impl Contact {
    /// The OpenDRIVE `contactPoint` value.
    pub fn od(self) -> &'static str {
        match self {
            Self::Start => "start",
            Self::End => "end",
        }
    }
}

/// A road's `<predecessor>` or `<successor>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// A junction, by id.
    Junction(u32),
    /// A road, by id, and the end of it that joins.
    Road {
        /// Its id.
        id: u32,
        /// The end that joins.
        contact: Contact,
    },
}

/// What a signal is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalKind {
    /// A traffic light, OpenDRIVE type `1000001`.
    TrafficLight,
    /// A stop sign, type `206`.
    StopSign,
}

/// One `<signal>` on a road, applying to the lanes on `side` from `lanes.0`
/// to `lanes.1`.
#[derive(Debug, Clone, PartialEq)]
pub struct Signal {
    /// Its id.
    pub id: u32,
    /// Where along the road.
    pub s: f64,
    /// Where across it.
    pub t: f64,
    /// The side of the road whose traffic it faces.
    pub side: Side,
    /// The `<validity>` lane range.
    pub lanes: (i32, i32),
    /// What it is.
    pub kind: SignalKind,
}

/// One `<road>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Road {
    /// Its id.
    pub id: u32,
    /// Its name.
    pub name: String,
    /// The junction it belongs to, for a connecting road.
    pub junction: Option<u32>,
    /// Its reference line.
    pub path: Path,
    /// Its lanes.
    pub profile: Profile,
    /// A constant `<laneOffset>`.
    pub lane_offset: f64,
    /// Its `<elevation>` records.
    pub elevation: Vec<Cubic>,
    /// What its start joins.
    pub predecessor: Option<Link>,
    /// What its end joins.
    pub successor: Option<Link>,
    /// For a connecting road, lane `-1`'s predecessor and successor lanes.
    pub lane_link: Option<(i32, i32)>,
    /// Its signals.
    pub signals: Vec<Signal>,
}

/// One `<connection>` with its single `<laneLink>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Connection {
    /// Its id within the junction.
    pub id: u32,
    /// The incoming road.
    pub incoming: u32,
    /// The connecting road, entered at its start.
    pub connecting: u32,
    /// The incoming lane.
    pub from: i32,
    /// The connecting road's lane.
    pub to: i32,
}

/// One `<junction>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Junction {
    /// Its id.
    pub id: u32,
    /// Its name.
    pub name: String,
    /// Its connections.
    pub connections: Vec<Connection>,
    /// The controller of its traffic lights, if it has any.
    pub controller: Option<u32>,
}

/// One `<controller>`: the traffic lights of one junction.
#[derive(Debug, Clone, PartialEq)]
pub struct Controller {
    /// Its id.
    pub id: u32,
    /// Its name.
    pub name: String,
    /// The signals it controls.
    pub signals: Vec<u32>,
}

/// A whole town, ready to write.
#[derive(Debug, Clone, PartialEq)]
pub struct Town {
    /// The header's `name`.
    pub name: String,
    /// Every road, streets first, then connecting roads.
    pub roads: Vec<Road>,
    /// Every junction.
    pub junctions: Vec<Junction>,
    /// Every controller.
    pub controllers: Vec<Controller>,
}
