//! Waypoints to control. Lateral: pure pursuit on the planned path, re-derived for the vehicle
//! that drives (its [`Vehicle`] geometry), not TCP's PID. Longitudinal: TCP's speed PID on the
//! speed the first waypoints imply, with TCP's boolean brake.
//!
//! # Why pure pursuit
//! TCP's turn PID (0.75 / 0.75 / 0.3 on a normalised angle to an aim point ~4 m ahead) was tuned
//! for CARLA's Lincoln MKZ, whose wheels turn 70 degrees at full steer. A car whose wheels turn
//! 35 degrees needs twice the steer for the same curvature, so the same gains under-steer by half:
//! fed the expert's own future path, TCP's PID left a 90-degree, 12 m-radius turn at 5 m/s by
//! 4.7 m. Pure pursuit computes the wheel angle that puts the rear axle on a circle through a
//! point one look-ahead distance along the path, `delta = atan(2 L sin(a) / l_d)`, and divides by
//! the vehicle's lock: the geometry is the vehicle's, so it stays right on any car. The
//! look-ahead grows with speed (3 m + 0.3 s x speed beyond the box centre, at most 10 m), which
//! damps the loop at speed; pure pursuit cuts corners by about its look-ahead squared over the
//! radius, so it is kept short. On the simulator's car following a 12 m-radius turn at 5 m/s it
//! stays within 0.36 m of the lane centre (4 m + 0.6 s, the expert's own look-ahead: 0.68 m;
//! the lane leaves 0.7 m), 0.17 m on a 30 m bend at 8 m/s (`tests/control.rs`).
//!
//! The path runs from the ego (the origin) through the waypoints; a look-ahead beyond the last
//! waypoint extends the last segment. A plan shorter than [`MIN_PATH`] (a stopped or stopping
//! car) says nothing about direction, so the target point is followed instead.

use ssrdrive_proto::control::Control;

use super::pid::Pid;
use super::{ControlConfig, Vehicle};

/// Waypoints (0.5 s apart) that set the desired speed: the first second of the plan.
const SPEED_WAYPOINTS: usize = 2;
/// Seconds between waypoints.
const WAYPOINT_DT: f32 = 0.5;
/// A plan whose path is shorter than this (m) does not give a direction.
pub const MIN_PATH: f32 = 1.0;

fn norm(v: [f32; 2]) -> f32 {
    v[0].hypot(v[1])
}

/// The point at distance `reach` from `from` on the path (ego frame), searching segments in
/// order; past the end, the last segment is extended. `None` when the path is degenerate.
fn point_at_reach(path: &[[f32; 2]], from: [f32; 2], reach: f32) -> Option<[f32; 2]> {
    let dist = |p: [f32; 2]| norm([p[0] - from[0], p[1] - from[1]]);
    for pair in path.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if dist(b) < reach {
            continue;
        }
        // Solve |a + t (b - a) - from| = reach for the largest t in [0, 1].
        let d = [b[0] - a[0], b[1] - a[1]];
        let f = [a[0] - from[0], a[1] - from[1]];
        let qa = d[0] * d[0] + d[1] * d[1];
        if qa < 1e-9 {
            continue;
        }
        let qb = 2.0 * (f[0] * d[0] + f[1] * d[1]);
        let qc = f[0] * f[0] + f[1] * f[1] - reach * reach;
        let t = ((-qb + (qb * qb - 4.0 * qa * qc).max(0.0).sqrt()) / (2.0 * qa)).clamp(0.0, 1.0);
        return Some([a[0] + t * d[0], a[1] + t * d[1]]);
    }
    // The whole path lies inside the circle: extend its last non-degenerate segment.
    let (a, b) = path
        .windows(2)
        .rev()
        .map(|p| (p[0], p[1]))
        .find(|(a, b)| norm([b[0] - a[0], b[1] - a[1]]) > 1e-3)?;
    let len = norm([b[0] - a[0], b[1] - a[1]]);
    let u = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
    // Walk from b along u until the distance from `from` reaches `reach`.
    let f = [b[0] - from[0], b[1] - from[1]];
    let proj = f[0] * u[0] + f[1] * u[1];
    let t = -proj
        + (proj * proj - (f[0] * f[0] + f[1] * f[1]) + reach * reach)
            .max(0.0)
            .sqrt();
    Some([b[0] + t * u[0], b[1] + t * u[1]])
}

/// Pure-pursuit steer (CARLA convention, +1 full right) towards `aim`, a point in the ego frame.
pub fn pursuit_steer(aim: [f32; 2], vehicle: &Vehicle) -> f32 {
    let rel = [aim[0] + vehicle.rear_axle, aim[1]];
    let distance = norm(rel).max(1.0);
    let alpha = rel[1].atan2(rel[0]);
    let wheel = (2.0 * vehicle.wheelbase * alpha.sin() / distance).atan();
    (-wheel / vehicle.max_wheel_angle.to_radians()).clamp(-1.0, 1.0)
}

/// The look-ahead distance beyond the box centre at `speed`, m.
pub fn lookahead(speed: f32, config: &ControlConfig) -> f32 {
    (config.lookahead_base + config.lookahead_gain * speed)
        .clamp(config.lookahead_base, config.lookahead_max)
}

/// Length of the path from the ego through the waypoints, m.
fn path_length(waypoints: &[[f32; 2]]) -> f32 {
    std::iter::once([0.0, 0.0])
        .chain(waypoints.iter().copied())
        .collect::<Vec<_>>()
        .windows(2)
        .map(|p| norm([p[1][0] - p[0][0], p[1][1] - p[0][1]]))
        .sum()
}

/// The speed PID of one episode (the lateral law keeps no state).
#[derive(Debug, Clone)]
pub struct TrajectoryFollower {
    speed: Pid,
}

impl TrajectoryFollower {
    /// A fresh speed PID with the gains and window of `config`.
    pub fn new(config: &ControlConfig) -> Self {
        Self {
            speed: Pid::new(
                config.speed_kp,
                config.speed_ki,
                config.speed_kd,
                config.pid_window,
            ),
        }
    }

    /// The speed the plan asks for: the mean speed over its first second, m/s.
    pub fn desired_speed(waypoints: &[[f32; 2]]) -> f32 {
        let n = waypoints.len().min(SPEED_WAYPOINTS);
        path_length(&waypoints[..n]) / (n as f32 * WAYPOINT_DT)
    }

    /// Control from the waypoints (ego frame, 0.5 s apart, at least one), the target point
    /// (ego frame) and the speed (m/s).
    pub fn control(
        &mut self,
        waypoints: &[[f32; 2]],
        target: [f32; 2],
        speed: f32,
        config: &ControlConfig,
    ) -> Control {
        let vehicle = &config.vehicle;
        let reach = lookahead(speed, config);
        let from = [-vehicle.rear_axle, 0.0];
        let path: Vec<[f32; 2]> = std::iter::once([0.0, 0.0])
            .chain(waypoints.iter().copied())
            .collect();
        let aim = if path_length(waypoints) >= MIN_PATH {
            point_at_reach(&path, from, reach + vehicle.rear_axle)
        } else {
            None
        };
        let steer = match aim {
            Some(aim) => pursuit_steer(aim, vehicle),
            None if target[0] > 0.0 => pursuit_steer(target, vehicle),
            None => 0.0,
        };

        let desired_speed = Self::desired_speed(waypoints);
        let brake =
            desired_speed < config.brake_speed || speed / desired_speed > config.brake_ratio;
        let delta = (desired_speed - speed).clamp(0.0, config.clip_delta);
        let throttle = self.speed.step(delta).clamp(0.0, config.max_throttle);
        // The trajectory brake is boolean (full brake, no throttle).
        if brake {
            Control {
                steer,
                throttle: 0.0,
                brake: 1.0,
            }
        } else {
            Control {
                steer,
                throttle,
                brake: 0.0,
            }
        }
    }
}
