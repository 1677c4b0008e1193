//! Cross-sections: which lanes a road has on each side of its reference
//! line, how wide they are, the marks between them, and its speed limit.

/// Width of a driving lane, in metres.
pub const LANE_WIDTH: f64 = 3.5;
/// Width of a sidewalk.
pub const SIDEWALK_WIDTH: f64 = 3.0;
/// Width of a parking lane.
pub const PARKING_WIDTH: f64 = 2.5;
/// Width of a highway shoulder.
pub const SHOULDER_WIDTH: f64 = 2.0;

/// What a lane is for, as its OpenDRIVE `type`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaneKind {
    /// `driving`.
    Driving,
    /// `parking`.
    Parking,
    /// `shoulder`.
    Shoulder,
    /// `sidewalk`.
    Sidewalk,
}

impl LaneKind {
    /// The OpenDRIVE `type` attribute.
    pub fn od_type(self) -> &'static str {
        match self {
            Self::Driving => "driving",
            Self::Parking => "parking",
            Self::Shoulder => "shoulder",
            Self::Sidewalk => "sidewalk",
        }
    }
}

/// One side of the reference line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Positive lane ids, `+t`; traffic runs against `s`.
    Left,
    /// Negative lane ids, `-t`; traffic runs along `s`.
    Right,
}

impl Side {
    /// The OpenDRIVE id of lane `j` counted from the centre, 1-based.
    pub fn od_id(self, j: usize) -> i32 {
        let j = i32::try_from(j).expect("few lanes");
        match self {
            Self::Left => j,
            Self::Right => -j,
        }
    }

    /// `+1` on the left, `-1` on the right: the sign of `t`.
    pub fn sign(self) -> f64 {
        match self {
            Self::Left => 1.0,
            Self::Right => -1.0,
        }
    }
}

/// How a road's marks are painted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marking {
    /// A two-way street: double yellow centre line, broken white between
    /// lanes, solid white at the outer driving edge.
    TwoWay,
    /// A one-way road: solid yellow at its left edge, else as a street.
    OneWay,
    /// A junction's connecting road: no paint.
    Junction,
}

/// A lane: its kind and width.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LaneSpec {
    /// What it is for.
    pub kind: LaneKind,
    /// Its constant width, in metres.
    pub width: f64,
}

/// A road's cross-section and speed limit.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// Lanes left of the reference line, centre outwards.
    pub left: Vec<LaneSpec>,
    /// Lanes right of the reference line, centre outwards.
    pub right: Vec<LaneSpec>,
    /// How the marks are painted.
    pub marking: Marking,
    /// The OpenDRIVE road `<type>`, such as `town`.
    pub road_type: &'static str,
    /// The speed limit in km/h.
    pub speed_kmh: u32,
}

fn lane(kind: LaneKind, width: f64) -> LaneSpec {
    LaneSpec { kind, width }
}

/// One side of a street: `driving` lanes, maybe a parking lane, a sidewalk.
fn street_side(driving: usize, parking: bool) -> Vec<LaneSpec> {
    let mut side = vec![lane(LaneKind::Driving, LANE_WIDTH); driving];
    if parking {
        side.push(lane(LaneKind::Parking, PARKING_WIDTH));
    }
    side.push(lane(LaneKind::Sidewalk, SIDEWALK_WIDTH));
    side
}

impl Profile {
    /// A two-way town street with `lanes` driving lanes each way, an
    /// optional parking lane each side, and sidewalks.
    pub fn street(lanes: usize, parking: bool, speed_kmh: u32) -> Self {
        Self {
            left: street_side(lanes, parking),
            right: street_side(lanes, parking),
            marking: Marking::TwoWay,
            road_type: "town",
            speed_kmh,
        }
    }

    /// The same cross-section with every driving lane `width` metres wide.
    pub fn with_lane_width(mut self, width: f64) -> Self {
        for spec in self.left.iter_mut().chain(self.right.iter_mut()) {
            if spec.kind == LaneKind::Driving {
                spec.width = width;
            }
        }
        self
    }

    /// A two-way highway: `lanes` each way, a shoulder, a sidewalk.
    pub fn highway(lanes: usize, speed_kmh: u32) -> Self {
        let mut side = vec![lane(LaneKind::Driving, LANE_WIDTH); lanes];
        side.push(lane(LaneKind::Shoulder, SHOULDER_WIDTH));
        side.push(lane(LaneKind::Sidewalk, SIDEWALK_WIDTH));
        Self {
            left: side.clone(),
            right: side,
            marking: Marking::TwoWay,
            road_type: "motorway",
            speed_kmh,
        }
    }

    /// A one-lane, one-way ramp along `+s`, with a sidewalk each side.
    pub fn ramp(speed_kmh: u32) -> Self {
        Self {
            left: vec![lane(LaneKind::Sidewalk, SIDEWALK_WIDTH)],
            right: street_side(1, false),
            marking: Marking::OneWay,
            road_type: "town",
            speed_kmh,
        }
    }

    /// A junction's connecting road: one driving lane, `-1`.
    pub fn connector(speed_kmh: u32) -> Self {
        Self {
            left: Vec::new(),
            right: vec![lane(LaneKind::Driving, LANE_WIDTH)],
            marking: Marking::Junction,
            road_type: "town",
            speed_kmh,
        }
    }

    /// The lanes on `side`, centre outwards.
    pub fn lanes(&self, side: Side) -> &[LaneSpec] {
        match side {
            Side::Left => &self.left,
            Side::Right => &self.right,
        }
    }

    /// How many driving lanes `side` has. They are the innermost ones.
    pub fn driving(&self, side: Side) -> usize {
        let lanes = self.lanes(side);
        let n = lanes
            .iter()
            .take_while(|l| l.kind == LaneKind::Driving)
            .count();
        debug_assert!(
            lanes[n..].iter().all(|l| l.kind != LaneKind::Driving),
            "driving lanes must be innermost"
        );
        n
    }

    /// `|t|` of the centre of lane `j` (1-based) on `side`.
    pub fn center_offset(&self, side: Side, j: usize) -> f64 {
        let lanes = self.lanes(side);
        let inner: f64 = lanes[..j - 1].iter().map(|l| l.width).sum();
        inner + lanes[j - 1].width / 2.0
    }

    /// `|t|` of `side`'s kerb: the outer edge of its lanes short of the sidewalk.
    pub fn kerb_offset(&self, side: Side) -> f64 {
        self.lanes(side)
            .iter()
            .take_while(|l| l.kind != LaneKind::Sidewalk)
            .map(|l| l.width)
            .sum()
    }

    /// The total width of `side`.
    pub fn side_width(&self, side: Side) -> f64 {
        self.lanes(side).iter().map(|l| l.width).sum()
    }

    /// The wider side's width: how far the road reaches from its line.
    pub fn half_width(&self) -> f64 {
        self.side_width(Side::Left)
            .max(self.side_width(Side::Right))
    }
}

/// One `<roadMark>`: its `type`, `color`, `width` and `laneChange`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mark {
    /// `type`, such as `broken`.
    pub kind: &'static str,
    /// `color`.
    pub color: &'static str,
    /// `laneChange`.
    pub lane_change: &'static str,
}

impl Mark {
    const NONE: Mark = Mark {
        kind: "none",
        color: "standard",
        lane_change: "none",
    };
    const LANE_DIVIDER: Mark = Mark {
        kind: "broken",
        color: "white",
        lane_change: "both",
    };
    const EDGE: Mark = Mark {
        kind: "solid",
        color: "white",
        lane_change: "none",
    };
}

impl Profile {
    /// The mark on the centre line.
    pub fn center_mark(&self) -> Mark {
        match self.marking {
            Marking::TwoWay => Mark {
                kind: "solid solid",
                color: "yellow",
                lane_change: "none",
            },
            Marking::OneWay => Mark {
                kind: "solid",
                color: "yellow",
                lane_change: "none",
            },
            Marking::Junction => Mark::NONE,
        }
    }

    /// The mark on the outer edge of lane `j` (1-based) on `side`.
    pub fn outer_mark(&self, side: Side, j: usize) -> Mark {
        let lanes = self.lanes(side);
        if self.marking == Marking::Junction || lanes[j - 1].kind != LaneKind::Driving {
            return Mark::NONE;
        }
        match lanes.get(j) {
            Some(next) if next.kind == LaneKind::Driving => Mark::LANE_DIVIDER,
            _ => Mark::EDGE,
        }
    }
}

/// How far a junction's roads stop short of its centre so that the widest
/// of `profiles` fits across it, with a margin for the turns.
pub fn setback(profiles: &[&Profile]) -> f64 {
    const MARGIN: f64 = 2.0;
    profiles.iter().map(|p| p.half_width()).fold(0.0, f64::max) + MARGIN
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn street_offsets_and_marks() {
        let p = Profile::street(2, true, 40);
        assert_eq!(p.driving(Side::Right), 2);
        assert_eq!(p.center_offset(Side::Right, 2), 5.25);
        assert_eq!(p.half_width(), 12.5);
        assert_eq!(p.outer_mark(Side::Left, 1).kind, "broken");
        assert_eq!(p.outer_mark(Side::Left, 2).kind, "solid");
        assert_eq!(p.outer_mark(Side::Left, 3).kind, "none");
        assert_eq!(Side::Left.od_id(2), 2);
        assert_eq!(Side::Right.od_id(2), -2);
    }
}
