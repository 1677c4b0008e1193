//! Junction topology: the legs of a junction (the road ends that meet in
//! it), where each leg's lanes enter and leave, and the default rule for
//! which incoming lane connects to which outgoing lane.

use std::f64::consts::PI;

use super::geometry::Pose;
use super::profile::{Profile, Side};
use super::town::Contact;
use ssrdrive_proto::frames::wrap_angle;

/// One road end in a junction.
#[derive(Debug, Clone, Copy)]
pub struct Leg<'a> {
    /// The road's index among the town's streets.
    pub road: usize,
    /// Which end of the road is in the junction.
    pub contact: Contact,
    /// The road's reference-line pose at that end, heading along `s`.
    pub end: Pose,
    /// The road's cross-section.
    pub profile: &'a Profile,
}

/// A lane-to-lane connection through a junction: incoming lane `from_lane`
/// of leg `from` to outgoing lane `to_lane` of leg `to`. Lanes count from
/// the centre line, 1-based, in the traffic's own terms.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LaneLink {
    /// The incoming leg's index.
    pub from: usize,
    /// Its lane.
    pub from_lane: usize,
    /// The outgoing leg's index.
    pub to: usize,
    /// Its lane.
    pub to_lane: usize,
}

impl Leg<'_> {
    /// The side whose traffic drives into the junction.
    pub fn in_side(&self) -> Side {
        match self.contact {
            Contact::End => Side::Right,
            Contact::Start => Side::Left,
        }
    }

    /// The side whose traffic drives out of the junction.
    pub fn out_side(&self) -> Side {
        match self.contact {
            Contact::End => Side::Left,
            Contact::Start => Side::Right,
        }
    }

    /// How many driving lanes come in.
    pub fn n_in(&self) -> usize {
        self.profile.driving(self.in_side())
    }

    /// How many driving lanes go out.
    pub fn n_out(&self) -> usize {
        self.profile.driving(self.out_side())
    }

    /// The heading of traffic coming in.
    pub fn in_heading(&self) -> f64 {
        match self.contact {
            Contact::End => self.end.hdg,
            Contact::Start => self.end.hdg + PI,
        }
    }

    fn lane_pose(&self, side: Side, j: usize, hdg: f64) -> Pose {
        let t = side.sign() * self.profile.center_offset(side, j);
        Pose {
            pos: self.end.at(0.0, t),
            hdg,
        }
    }

    /// Where incoming lane `j` ends, heading into the junction.
    pub fn in_lane(&self, j: usize) -> Pose {
        self.lane_pose(self.in_side(), j, self.in_heading())
    }

    /// Where outgoing lane `j` starts, heading out of the junction.
    pub fn out_lane(&self, j: usize) -> Pose {
        self.lane_pose(self.out_side(), j, self.in_heading() + PI)
    }
}

/// How traffic turns from one leg into another.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Turn {
    Straight,
    Left,
    Right,
    /// A U-turn.
    Back,
}

fn turn(from: &Leg, to: &Leg) -> Turn {
    let angle = wrap_angle(to.in_heading() + PI - from.in_heading());
    let quarter = PI / 4.0;
    if angle.abs() < quarter {
        Turn::Straight
    } else if angle.abs() > 3.0 * quarter {
        Turn::Back
    } else if angle > 0.0 {
        Turn::Left
    } else {
        Turn::Right
    }
}

/// The link that carries leg `a`'s rightmost incoming lane straight on, with its index in
/// `links` (none where the leg only turns, as a T-junction's stem does).
pub fn straight_on_from_rightmost(
    links: &[LaneLink],
    legs: &[Leg],
    a: usize,
) -> Option<(usize, LaneLink)> {
    let n_in = legs[a].n_in();
    links.iter().copied().enumerate().find(|(_, l)| {
        l.from == a && l.from_lane == n_in && turn(&legs[a], &legs[l.to]) == Turn::Straight
    })
}

/// The default connections of a junction of `legs`:
///
/// - straight on, lane `j` to lane `j`; where the outgoing road has fewer
///   lanes the outer ones merge into its outermost, and where it has more
///   its outer ones are fed from the incoming outermost;
/// - right turns from the rightmost lane into the rightmost lane;
/// - left turns from the leftmost lane into the leftmost lane;
/// - no U-turns.
///
/// An incoming lane left without a connection (a middle lane where the road
/// only turns) follows its neighbour's turn into the nearest lane, so no
/// lane dead-ends; an outgoing lane left without one (a middle lane of a
/// road that is only turned into) is fed like its nearest neighbour, so
/// every lane is entered.
pub fn default_links(legs: &[Leg]) -> Vec<LaneLink> {
    let mut links = Vec::new();
    for (a, from) in legs.iter().enumerate() {
        let n_in = from.n_in();
        if n_in == 0 {
            continue;
        }
        let first = links.len();
        for (b, to) in legs.iter().enumerate() {
            let n_out = to.n_out();
            if a == b || n_out == 0 {
                continue;
            }
            let mut link = |from_lane, to_lane| {
                links.push(LaneLink {
                    from: a,
                    from_lane,
                    to: b,
                    to_lane,
                })
            };
            match turn(from, to) {
                Turn::Straight => {
                    for j in 1..=n_in {
                        link(j, j.min(n_out));
                    }
                    for j in n_in + 1..=n_out {
                        link(n_in, j);
                    }
                }
                Turn::Right => link(n_in, n_out),
                Turn::Left => link(1, 1),
                Turn::Back => {}
            }
        }
        cover_missing(&mut links, first, a, n_in, legs);
    }
    feed_missing(&mut links, legs);
    links
}

/// Give each outgoing lane without a link one, copying the link of the
/// nearest lane of the same road that has one.
fn feed_missing(links: &mut Vec<LaneLink>, legs: &[Leg]) {
    for (b, leg) in legs.iter().enumerate() {
        for k in 1..=leg.n_out() {
            let into = |l: &&LaneLink| l.to == b;
            if links.iter().filter(into).any(|l| l.to_lane == k) {
                continue;
            }
            let nearest = links
                .iter()
                .filter(into)
                .min_by_key(|l| (l.to_lane.abs_diff(k), l.to_lane))
                .copied();
            if let Some(near) = nearest {
                links.push(LaneLink { to_lane: k, ..near });
            }
        }
    }
}

/// Give each incoming lane of leg `a` without a link one, copying the turn
/// of the nearest linked lane into that road's nearest lane.
fn cover_missing(links: &mut Vec<LaneLink>, first: usize, a: usize, n_in: usize, legs: &[Leg]) {
    for j in 1..=n_in {
        if links[first..].iter().any(|l| l.from_lane == j) {
            continue;
        }
        let nearest = links[first..]
            .iter()
            .min_by_key(|l| l.from_lane.abs_diff(j))
            .copied();
        if let Some(near) = nearest {
            links.push(LaneLink {
                from: a,
                from_lane: j,
                to: near.to,
                to_lane: j.min(legs[near.to].n_out()),
            });
        }
    }
}
