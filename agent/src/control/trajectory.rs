//! Waypoints to control, TCP's `control_pid`: a speed PID tracks the speed implied by the
//! waypoint spacing (0.5 s apart) and a turn PID steers towards an aim point about 4 m ahead,
//! or towards the target point when that agrees better with the route.
//!
//! Angles are TCP's: `degrees(pi/2 - atan2(forward, right)) / 90`, so 1 means 90 degrees to the
//! right and positive steers right.

use super::pid::Pid;
use super::{Control, ControlConfig};

/// Waypoints (0.5 s apart) the trajectory controller reads: TCP's 2 s horizon.
pub const CONTROL_WAYPOINTS: usize = 4;

/// Normalised angle of an ego-frame vector (x forward, y left), TCP's formula.
fn tcp_angle(point: [f32; 2]) -> f32 {
    let (forward, right) = (point[0], -point[1]);
    (std::f32::consts::FRAC_PI_2 - forward.atan2(right)).to_degrees() / 90.0
}

fn norm(v: [f32; 2]) -> f32 {
    v[0].hypot(v[1])
}

/// The turn and speed PIDs of one episode.
#[derive(Debug, Clone)]
pub struct TrajectoryFollower {
    turn: Pid,
    speed: Pid,
}

impl TrajectoryFollower {
    /// Fresh PIDs with the gains and window of `config`.
    pub fn new(config: &ControlConfig) -> Self {
        Self {
            turn: Pid::new(
                config.turn_kp,
                config.turn_ki,
                config.turn_kd,
                config.pid_window,
            ),
            speed: Pid::new(
                config.speed_kp,
                config.speed_ki,
                config.speed_kd,
                config.pid_window,
            ),
        }
    }

    /// Control from at least two waypoints (ego frame), the target point and the speed (m/s).
    pub fn control(
        &mut self,
        waypoints: &[[f32; 2]],
        target: [f32; 2],
        speed: f32,
        config: &ControlConfig,
    ) -> Control {
        assert!(
            waypoints.len() >= 2,
            "trajectory control needs two waypoints"
        );
        // TCP's controller reads a 2 s horizon; longer plans (for 3 s open-loop metrics) are cut.
        let waypoints = &waypoints[..waypoints.len().min(CONTROL_WAYPOINTS)];
        let pairs = waypoints.len() - 1;
        let mut desired_speed = 0.0;
        let mut aim = waypoints[0];
        let mut best = 1e5_f32;
        for i in 0..pairs {
            let (a, b) = (waypoints[i], waypoints[i + 1]);
            desired_speed += norm([b[0] - a[0], b[1] - a[1]]) * 2.0 / pairs as f32;
            let middle = norm([(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]);
            if (config.aim_dist - best).abs() > (config.aim_dist - middle).abs() {
                aim = a;
                best = middle;
            }
        }
        let (last, before) = (waypoints[pairs], waypoints[pairs - 1]);
        let angle = tcp_angle(aim);
        let angle_last = tcp_angle([last[0] - before[0], last[1] - before[1]]);
        let angle_target = tcp_angle(target);
        let use_target = angle_target.abs() < angle.abs()
            || ((angle_target - angle_last).abs() > config.angle_thresh
                && target[0] < config.dist_thresh);
        let steer = self
            .turn
            .step(if use_target { angle_target } else { angle })
            .clamp(-1.0, 1.0);

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
