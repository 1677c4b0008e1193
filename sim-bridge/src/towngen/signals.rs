//! Traffic control: where a junction approach's traffic light or stop sign
//! stands, and which lanes it governs.
//!
//! Traffic lights stand where [`LightPlacement`] says. US-style, as in CARLA's
//! Town03-07 and 10 (the default): across the junction, on the far right
//! corner, where a car waiting at the stop line still sees them (a head beside
//! the stop line is out of a forward camera's view there). The signal sits at
//! the end of the connecting road that carries the approach's rightmost lane
//! straight on, governing that road's lane, which the simulator traces back to
//! the approach. An approach with no straight-on connection (a T-junction's
//! stem) and every stop sign stand just before the junction on the right edge
//! of the incoming road; every light of a [`LightPlacement::Kerb`] town just
//! before the junction on the right kerb ([`kerb_light`]), or 2-7 m before it in a
//! [`LightPlacement::KerbSetBack`] town.

use super::junction::Leg;
use super::profile::Side;
use super::town::{Contact, Signal, SignalKind};

/// Where a town's traffic lights stand.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LightPlacement {
    /// Across the junction, on the far right corner (a T-junction's stem keeps its light at
    /// the kerb).
    #[default]
    Across,
    /// At the kerb on the right, just before the stop line, as CARLA's Town01 and Town02 post
    /// theirs: a car at the line has the head beside or above it, out of a forward camera's
    /// view, and keeps the lamp in view only by stopping short of the head.
    Kerb,
    /// At the kerb on the right as [`LightPlacement::Kerb`], but set back 2-7 m before the stop
    /// line (varied by light, [`kerb_set_back`]), as some near-side heads stand (one of CARLA's
    /// Town02 lights, 5 m): a car waiting at the line has the head beside or behind it, in
    /// view of a camera looking right only.
    KerbSetBack,
}

/// How far before the junction a signal stands, in metres.
const BEFORE_JUNCTION: f64 = 1.0;

/// The signal of `kind` for the traffic entering a junction along `leg`,
/// whose road is `length` long: just before the junction, on the right
/// edge of the road as that traffic sees it, governing exactly the incoming
/// driving lanes.
pub fn approach_signal(id: u32, kind: SignalKind, leg: &Leg, length: f64) -> Signal {
    signal_before_junction(id, kind, leg, length, BEFORE_JUNCTION)
}

/// [`approach_signal`] standing `before` m before the junction.
fn signal_before_junction(
    id: u32,
    kind: SignalKind,
    leg: &Leg,
    length: f64,
    before: f64,
) -> Signal {
    let side = leg.in_side();
    let s = match leg.contact {
        Contact::End => length - before,
        Contact::Start => before,
    };
    let n = leg.n_in();
    assert!(n > 0, "a signal on an approach with no lanes in");
    Signal {
        id,
        s,
        t: side.sign() * leg.profile.side_width(side),
        side,
        lanes: (side.od_id(1), side.od_id(n)),
        kind,
    }
}

/// How far onto the sidewalk a kerb-side light's post stands, m.
const POST_FROM_KERB: f64 = 0.5;

/// The [`LightPlacement::Kerb`] light for the traffic entering a junction along `leg`: as
/// [`approach_signal`] places it, but on the kerb (its post half a metre onto the sidewalk),
/// beside the rightmost lane as CARLA's Town01 and Town02 post theirs, not at the sidewalk's
/// back; `set_back` stands it that many metres before the junction instead of
/// [`BEFORE_JUNCTION`] (at most half the road's length, so that a short street keeps it).
pub fn kerb_light(id: u32, leg: &Leg, length: f64, set_back: Option<f64>) -> Signal {
    let side = leg.in_side();
    let before = set_back.map_or(BEFORE_JUNCTION, |b| b.min(length / 2.0));
    Signal {
        t: side.sign() * (leg.profile.kerb_offset(side) + POST_FROM_KERB),
        ..signal_before_junction(id, SignalKind::TrafficLight, leg, length, before)
    }
}

/// How far before its junction a [`LightPlacement::KerbSetBack`] light stands: 2-7 m in steps of
/// half a metre, drawn from the light's id so that neighbouring approaches differ and the
/// same town gives the same bytes.
pub fn kerb_set_back(id: u32) -> f64 {
    2.0 + 0.5 * f64::from(id.wrapping_mul(7) % 11)
}

/// The traffic light, across the junction, for the traffic on the connecting road of length
/// `length` that carries an approach straight on into outgoing lane `to_lane` of leg `to`: at
/// the road's end, on the far road's right edge.
pub fn far_side_light(id: u32, length: f64, to: &Leg, to_lane: usize) -> Signal {
    let side = to.out_side();
    let edge = to.profile.side_width(side) - to.profile.center_offset(side, to_lane);
    Signal {
        id,
        s: length,
        t: Side::Right.sign() * edge,
        side: Side::Right,
        lanes: (Side::Right.od_id(1), Side::Right.od_id(1)),
        kind: SignalKind::TrafficLight,
    }
}
