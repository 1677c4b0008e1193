//! Traffic control: where a junction approach's traffic light or stop sign
//! stands on its incoming road, and which lanes it governs.

use super::junction::Leg;
use super::model::{Contact, Signal, SignalKind};

/// How far before the junction a signal stands, in metres.
const BEFORE_JUNCTION: f64 = 1.0;

/// The signal of `kind` for the traffic entering a junction along `leg`,
/// whose road is `length` long: just before the junction, on the right
/// edge of the road as that traffic sees it, governing exactly the incoming
/// driving lanes.
pub fn approach_signal(id: u32, kind: SignalKind, leg: &Leg, length: f64) -> Signal {
    let side = leg.in_side();
    let s = match leg.contact {
        Contact::End => length - BEFORE_JUNCTION,
        Contact::Start => BEFORE_JUNCTION,
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
