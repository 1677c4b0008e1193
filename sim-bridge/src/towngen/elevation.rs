//! Elevation profiles: the `<elevation>` cubic records of a road, flat or a
//! smooth hill (up, level, down).

/// One `<elevation>` record: `z = a + b ds + c ds² + d ds³`, `ds = s - s0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cubic {
    /// Where it starts along the road.
    pub s: f64,
    /// Coefficients.
    pub a: f64,
    /// Linear.
    pub b: f64,
    /// Quadratic.
    pub c: f64,
    /// Cubic.
    pub d: f64,
}

impl Cubic {
    const fn constant(s: f64, a: f64) -> Self {
        Self {
            s,
            a,
            b: 0.0,
            c: 0.0,
            d: 0.0,
        }
    }

    /// A smooth step from `from` to `to` over `length` metres starting at
    /// `s`, level at both ends.
    fn step(s: f64, length: f64, from: f64, to: f64) -> Self {
        let h = to - from;
        Self {
            s,
            a: from,
            b: 0.0,
            c: 3.0 * h / (length * length),
            d: -2.0 * h / (length * length * length),
        }
    }

    /// The height `s` metres along the road, if this record covers it.
    pub fn eval(&self, s: f64) -> f64 {
        let ds = s - self.s;
        ((self.d * ds + self.c) * ds + self.b) * ds + self.a
    }
}

/// A level road at height 0.
pub fn flat() -> Vec<Cubic> {
    vec![Cubic::constant(0.0, 0.0)]
}

/// A road that is level at 0 until `start`, climbs smoothly to `height`
/// over `ramp` metres, stays there, and comes back down over `ramp` metres
/// to end level at 0 `start` metres before its `length`.
pub fn hill(length: f64, start: f64, ramp: f64, height: f64) -> Vec<Cubic> {
    let down = length - start - ramp;
    assert!(
        down >= start + ramp,
        "a hill of {ramp} m ramps doesn't fit in {length} m"
    );
    vec![
        Cubic::constant(0.0, 0.0),
        Cubic::step(start, ramp, 0.0, height),
        Cubic::constant(start + ramp, height),
        Cubic::step(down, ramp, height, 0.0),
        Cubic::constant(down + ramp, 0.0),
    ]
}

/// A smooth climb from `from` to `to` over a whole road `length` long.
pub fn ramp(length: f64, from: f64, to: f64) -> Vec<Cubic> {
    vec![Cubic::step(0.0, length, from, to)]
}

/// The height at `s` on a profile.
pub fn height_at(profile: &[Cubic], s: f64) -> f64 {
    profile
        .iter()
        .rev()
        .find(|c| c.s <= s)
        .unwrap_or(&profile[0])
        .eval(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hill_is_continuous() {
        let p = hill(400.0, 50.0, 100.0, 8.0);
        for c in &p[1..] {
            let before = height_at(&p, c.s - 1e-9);
            assert!((before - c.a).abs() < 1e-6, "step at {}", c.s);
        }
        assert!((height_at(&p, 200.0) - 8.0).abs() < 1e-12);
        assert!(height_at(&p, 399.0).abs() < 1e-12);
    }
}
