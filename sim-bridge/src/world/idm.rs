//! The car-following law every simulated driver uses, the privileged expert and the background
//! traffic alike: the Intelligent Driver Model (Treiber et al., 2000) and the curve-speed cap
//! that keeps lateral acceleration under a limit. Each driver keeps its own [`Idm`] parameters
//! (the expert follows closer and brakes harder than traffic); the law lives here once.

/// IDM parameters and the lateral-acceleration limit in curves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Idm {
    /// Comfortable acceleration, m/s^2.
    pub accel: f64,
    /// Comfortable deceleration, m/s^2.
    pub decel: f64,
    /// Standstill gap to the leader, m.
    pub min_gap: f64,
    /// Time headway, s.
    pub headway: f64,
    /// Lateral acceleration allowed in curves, m/s^2.
    pub lateral_accel: f64,
}

impl Idm {
    /// Acceleration at `speed` towards `desired` speed, behind a leader (free gap in metres,
    /// its speed along the path) if there is one. Unbounded below: a leader inside the standstill
    /// gap asks for hard braking, and the caller caps it at what its vehicle can do.
    pub fn acceleration(&self, speed: f64, desired: f64, leader: Option<(f64, f64)>) -> f64 {
        let free = 1.0 - (speed / desired.max(0.1)).powi(4);
        let interaction = leader.map_or(0.0, |(gap, lead_speed)| {
            let dv = speed - lead_speed;
            let braking = speed * dv / (2.0 * (self.accel * self.decel).sqrt());
            let wanted_gap = self.min_gap + (speed * self.headway + braking).max(0.0);
            (wanted_gap / gap.max(0.05)).powi(2)
        });
        self.accel * (free - interaction)
    }

    /// Highest speed on a curve of `radius` metres.
    pub fn curve_speed(&self, radius: f64) -> f64 {
        (self.lateral_accel * radius).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const IDM: Idm = Idm {
        accel: 2.0,
        decel: 3.0,
        min_gap: 2.5,
        headway: 1.2,
        lateral_accel: 2.5,
    };

    #[test]
    fn free_road_accelerates_to_the_desired_speed_and_a_close_leader_brakes() {
        assert_eq!(IDM.acceleration(0.0, 10.0, None), IDM.accel);
        assert!(IDM.acceleration(10.0, 10.0, None).abs() < 1e-12);
        assert!(IDM.acceleration(12.0, 10.0, None) < 0.0);
        let far = IDM.acceleration(8.0, 10.0, Some((200.0, 8.0)));
        let near = IDM.acceleration(8.0, 10.0, Some((5.0, 0.0)));
        assert!(far > 0.0 && near < -IDM.decel, "{far} {near}");
        assert!(IDM.acceleration(0.0, 10.0, Some((0.0, 0.0))).is_finite());
    }

    #[test]
    fn curve_speed_keeps_lateral_acceleration_at_the_limit() {
        let v = IDM.curve_speed(10.0);
        assert!((v * v / 10.0 - IDM.lateral_accel).abs() < 1e-12);
    }
}
