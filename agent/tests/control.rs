//! Control: PID, Beta rules, trajectory-to-control and fusion against hand-computed cases.

use ssr_agent::control::beta::{beta_point, control_from_action, control_from_beta};
use ssr_agent::control::fusion::Fusion;
use ssr_agent::control::pid::Pid;
use ssr_agent::control::trajectory::TrajectoryFollower;
use ssr_agent::control::{Control, ControlConfig, EpisodeController};

fn near(a: f32, b: f32) -> bool {
    (a - b).abs() < 1e-4
}

#[test]
fn pid_uses_the_window_mean_and_last_difference() {
    let mut pid = Pid::new(1.0, 0.5, 0.25, 4);
    // window [0, 0, 0, 2]: 2 + 0.5 * 0.5 + 0.25 * 2
    assert!(near(pid.step(2.0), 2.75));
    // window [0, 0, 2, 1]: 1 + 0.5 * 0.75 + 0.25 * (1 - 2)
    assert!(near(pid.step(1.0), 1.125));
}

#[test]
fn beta_mode_and_mean_rules() {
    assert!(
        near(beta_point(3.0, 2.0), 2.0 / 3.0),
        "mode when both exceed 1"
    );
    assert_eq!(beta_point(0.5, 2.0), 0.0);
    assert_eq!(beta_point(2.0, 0.5), 1.0);
    assert!(
        near(beta_point(0.5, 0.5), 0.5),
        "mean when neither exceeds 1"
    );
    assert!(near(beta_point(0.2, 0.6), 0.25));
    let c = control_from_beta([3.0, 2.0], [2.0, 3.0]);
    assert!(near(c.throttle, 1.0 / 3.0) && c.brake == 0.0 && near(c.steer, -1.0 / 3.0));
    assert_eq!(
        control_from_action(-0.03, 0.0),
        Control {
            steer: 0.0,
            throttle: 0.0,
            brake: 0.0
        },
        "small brakes drop"
    );
    assert_eq!(
        control_from_action(-0.6, 2.0),
        Control {
            steer: 1.0,
            throttle: 0.0,
            brake: 0.6
        }
    );
}

#[test]
fn trajectory_control_reproduces_tcp_by_hand() {
    let config = ControlConfig::default();
    let straight = [[2.0, 0.0], [4.0, 0.0], [6.0, 0.0], [8.0, 0.0]]; // 4 m/s
    // Below the desired speed: speed PID on the clipped error 0.25 saturates at 0.75.
    let c = TrajectoryFollower::new(&config).control(&straight, [20.0, 0.0], 3.0, &config);
    assert_eq!(
        c,
        Control {
            steer: 0.0,
            throttle: 0.75,
            brake: 0.0
        }
    );
    // 5 / 4 > 1.1: brake.
    let c = TrajectoryFollower::new(&config).control(&straight, [20.0, 0.0], 5.0, &config);
    assert_eq!(
        c,
        Control {
            steer: 0.0,
            throttle: 0.0,
            brake: 1.0
        }
    );
    // Curving right while the near target is to the left (45 degrees): the target wins,
    // angle -0.5, steer = 0.75 (-0.5) + 0.75 (-0.5 / 40) + 0.3 (-0.5).
    let curve = [[2.0, 0.0], [4.0, -1.0], [6.0, -3.0], [7.0, -5.0]];
    let c = TrajectoryFollower::new(&config).control(&curve, [8.0, 8.0], 4.0, &config);
    assert!(near(c.steer, -0.534375), "{c:?}");
}

#[test]
fn fusion_switches_weights_after_sustained_turning() {
    let config = ControlConfig::default();
    let trajectory = Control {
        steer: 0.2,
        throttle: 0.6,
        brake: 0.0,
    };
    let branch = Control {
        steer: 0.6,
        throttle: 0.2,
        brake: 0.0,
    };
    let mut fusion = Fusion::new(config.turn_window);
    for _ in 0..11 {
        let c = fusion.fuse(trajectory, branch, &config);
        assert!(
            near(c.steer, 0.32) && near(c.throttle, 0.48),
            "trajectory-weighted: {c:?}"
        );
    }
    assert!(fusion.turning(), "11 of 20 steers above 0.1");
    let c = fusion.fuse(trajectory, branch, &config);
    assert!(
        near(c.steer, 0.48) && near(c.throttle, 0.32),
        "branch-weighted: {c:?}"
    );

    let braking = Control {
        steer: 0.0,
        throttle: 0.6,
        brake: 1.0,
    };
    let c = Fusion::new(20).fuse(
        braking,
        Control {
            steer: 0.0,
            throttle: 0.5,
            brake: 0.0,
        },
        &config,
    );
    assert!(
        near(c.brake, 0.7) && c.throttle == 0.0,
        "a fused brake over 0.5 cuts the throttle"
    );
}

#[test]
fn episode_controller_reports_both_sources() {
    let mut controller = EpisodeController::new(ControlConfig::default());
    let d = controller.act(
        &[[2.0, 0.0], [4.0, 0.0], [6.0, 0.0], [8.0, 0.0]],
        [20.0, 0.0],
        3.0,
        [3.0, 2.0],
        [2.0, 2.0],
    );
    assert_eq!(d.trajectory.throttle, 0.75);
    assert!(near(d.branch.throttle, 1.0 / 3.0));
    assert!(near(d.control.throttle, 0.3 * (1.0 / 3.0) + 0.7 * 0.75));
    assert!(!d.turning);
    assert!(
        ControlConfig {
            alpha: 1.5,
            ..ControlConfig::default()
        }
        .validate()
        .is_err()
    );
}
