//! Control: PID, Beta rules, pure pursuit and speed control, and fusion against hand-computed
//! cases and circle geometry.

use ssr_control::beta::{beta_point, control_from_action, control_from_beta};
use ssr_control::fusion::{Fusion, TurnLead};
use ssr_control::pid::Pid;
use ssr_control::trajectory::TrajectoryFollower;
use ssr_control::unstick::TICKS_PER_SECOND;
use ssr_control::{
    Beliefs, ControlConfig, EpisodeController, FullStop, LightBelief, SafetyStop, Unstick, Vehicle,
};
use ssrdrive_proto::control::Control;

fn near(a: f32, b: f32) -> bool {
    (a - b).abs() < 1e-4
}

/// The hazard head sure a light holds the car, and the light head's `green` and `stop`.
fn light(green: f32, stop: f32) -> Beliefs<'static> {
    Beliefs {
        clear: Some(0.02),
        light_hazard: Some(0.95),
        light: Some(LightBelief { green, stop }),
        ..Beliefs::default()
    }
}

/// Control ticks in `seconds`.
fn ticks(seconds: f32) -> usize {
    (seconds * TICKS_PER_SECOND) as usize
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
fn speed_control_follows_the_first_second_of_the_plan() {
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
    // A plan that stops within its first second brakes, however fast the plan is later.
    let stopping = [[0.1, 0.0], [0.15, 0.0], [5.0, 0.0], [10.0, 0.0]];
    let c = TrajectoryFollower::new(&config).control(&stopping, [20.0, 0.0], 0.0, &config);
    assert_eq!(c.brake, 1.0);
}

/// The simulator's kinematic bicycle (reference point at the box centre, half a wheelbase
/// ahead of the rear axle; steer rate limited to full lock in 0.4 s) driving at constant speed
/// through a 90-degree left turn of `radius` metres whose centre line the plan follows. Returns
/// the largest distance of the box centre from the centre line.
fn turn_error(car: &Vehicle, config: &ControlConfig, radius: f32, speed: f32) -> f32 {
    let centre = [10.0f32, radius]; // straight along +x to x = 10, then the arc, then +y
    let path_at = |s: f32| -> [f32; 2] {
        let arc = radius * std::f32::consts::FRAC_PI_2;
        if s < 10.0 {
            [s, 0.0]
        } else if s < 10.0 + arc {
            let a = (s - 10.0) / radius;
            [10.0 + radius * a.sin(), radius * (1.0 - a.cos())]
        } else {
            [10.0 + radius, radius + s - 10.0 - arc]
        }
    };
    let distance_to_path = |p: [f32; 2]| -> f32 {
        if p[0] <= 10.0 {
            p[1].abs()
        } else if p[1] >= radius {
            (p[0] - 10.0 - radius).abs()
        } else {
            ((p[0] - centre[0]).hypot(p[1] - centre[1]) - radius).abs()
        }
    };
    let (mut x, mut y, mut yaw, mut steer) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
    let mut follower = TrajectoryFollower::new(config);
    let mut worst = 0.0f32;
    let dt = 0.05;
    for _ in 0..((10.0 + 2.0 * radius + 20.0) / speed / dt) as usize {
        // The plan: six points 0.5 s apart from the nearest path point, in the ego frame.
        let s0 = (0..((40.0 + 2.0 * radius) / 0.02) as usize)
            .map(|i| i as f32 * 0.02)
            .min_by(|a, b| {
                let (pa, pb) = (path_at(*a), path_at(*b));
                ((pa[0] - x).hypot(pa[1] - y)).total_cmp(&(pb[0] - x).hypot(pb[1] - y))
            })
            .unwrap();
        let plan: Vec<[f32; 2]> = (1..=6)
            .map(|k| {
                let p = path_at(s0 + speed * 0.5 * k as f32);
                let (dx, dy) = (p[0] - x, p[1] - y);
                [
                    dx * yaw.cos() + dy * yaw.sin(),
                    -dx * yaw.sin() + dy * yaw.cos(),
                ]
            })
            .collect();
        let command = follower.control(&plan, plan[5], speed, config).steer;
        let max_delta = dt / 0.4;
        steer += (command - steer).clamp(-max_delta, max_delta);
        let wheel = -steer * car.max_wheel_angle.to_radians();
        let lr = car.wheelbase / 2.0;
        let beta = (lr / car.wheelbase * wheel.tan()).atan();
        x += speed * (yaw + beta).cos() * dt;
        y += speed * (yaw + beta).sin() * dt;
        yaw += speed / lr * beta.sin() * dt;
        // NaN would drop out of `max` and read as "on the path".
        assert!(
            x.is_finite() && y.is_finite() && steer.is_finite(),
            "{x} {y} {steer}"
        );
        worst = worst.max(distance_to_path([x, y]));
    }
    worst
}

#[test]
fn pure_pursuit_keeps_the_simulated_car_in_its_lane_through_turns() {
    let config = ControlConfig::default();
    let car = config.vehicle.clone();
    for (radius, speed) in [(12.0, 5.0), (8.0, 4.0), (30.0, 8.0), (60.0, 10.0)] {
        let error = turn_error(&car, &config, radius, speed);
        assert!(
            error < 0.55,
            "R {radius} m at {speed} m/s: {error:.2} m off the lane centre"
        );
    }
    // Told its wheels turn twice as far as they do (CARLA's car), it steers half as much and
    // leaves the lane (3.5 m lane, 2.12 m car: 0.7 m of margin).
    let wrong = ControlConfig {
        vehicle: Vehicle {
            max_wheel_angle: 70.0,
            ..Vehicle::default()
        },
        ..ControlConfig::default()
    };
    let error = turn_error(&car, &wrong, 12.0, 5.0);
    assert!(error > 0.7, "half the steer: {error:.2} m");
}

#[test]
fn a_plan_without_direction_steers_to_the_target_point() {
    let config = ControlConfig::default();
    let still = [[0.0, 0.0], [0.01, 0.0], [0.02, 0.0], [0.03, 0.0]];
    let left = TrajectoryFollower::new(&config).control(&still, [10.0, 10.0], 0.0, &config);
    assert!(left.steer < -0.3, "target to the left: {left:?}");
    assert_eq!(left.brake, 1.0, "a still plan holds the car");
    let behind = TrajectoryFollower::new(&config).control(&still, [-10.0, 10.0], 0.0, &config);
    assert_eq!(behind.steer, 0.0, "a target behind gives no direction");
    // A path shorter than the look-ahead is extended along its last segment.
    let short = [[0.5, 0.0], [1.0, 0.5], [1.5, 1.0], [2.0, 1.5]];
    let c = TrajectoryFollower::new(&config).control(&short, [20.0, 0.0], 1.0, &config);
    assert!(
        c.steer < -0.2,
        "the extension keeps the path's left turn: {c:?}"
    );
}

#[test]
fn vehicle_settings_are_range_checked() {
    let bad = |vehicle: Vehicle| ControlConfig {
        vehicle,
        ..ControlConfig::default()
    };
    let error = bad(Vehicle {
        max_wheel_angle: 0.0,
        ..Vehicle::default()
    })
    .validate()
    .unwrap_err();
    assert!(error.contains("max_wheel_angle"), "{error}");
    let error = bad(Vehicle {
        wheelbase: f32::NAN,
        ..Vehicle::default()
    })
    .validate()
    .unwrap_err();
    assert!(error.contains("wheelbase"), "{error}");
    assert!(ControlConfig::default().validate().is_ok());
}

#[test]
fn controller_settings_that_would_panic_or_exhaust_memory_are_refused() {
    let cases = [
        (
            ControlConfig {
                clip_delta: -1.0,
                ..ControlConfig::default()
            },
            "clip_delta",
        ),
        (
            ControlConfig {
                speed_ki: f32::NAN,
                ..ControlConfig::default()
            },
            "speed_ki",
        ),
        (
            ControlConfig {
                pid_window: usize::MAX,
                ..ControlConfig::default()
            },
            "pid_window",
        ),
        (
            ControlConfig {
                turn_window: 1 << 40,
                ..ControlConfig::default()
            },
            "turn_window",
        ),
        (
            ControlConfig {
                turn_count: 21,
                ..ControlConfig::default()
            },
            "turn_count",
        ),
        (
            ControlConfig {
                lookahead_max: f32::INFINITY,
                ..ControlConfig::default()
            },
            "lookahead_max",
        ),
    ];
    for (config, field) in cases {
        let error = config.validate().unwrap_err();
        assert!(error.starts_with(field), "{field}: {error}");
    }
}

#[test]
fn fusion_switches_weights_after_sustained_turning() {
    let config = ControlConfig::default();
    assert_eq!(
        config.turn_lead,
        TurnLead::Branch,
        "TCP's fusion by default"
    );
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
    // While turning: (turn_lead, fused steer, fused throttle).
    for (lead, steer, throttle) in [
        (TurnLead::Branch, 0.48, 0.32),
        (TurnLead::PlanSteer, 0.32, 0.32),
        (TurnLead::Plan, 0.32, 0.48),
    ] {
        let config = ControlConfig {
            turn_lead: lead,
            ..ControlConfig::default()
        };
        let c = fusion.clone().fuse(trajectory, branch, &config);
        assert!(
            near(c.steer, steer) && near(c.throttle, throttle),
            "{lead:?} leads the turn: {c:?}"
        );
    }

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
        Beliefs::default(),
    );
    assert_eq!(d.trajectory.throttle, 0.75);
    assert!(near(d.branch.throttle, 1.0 / 3.0));
    assert!(near(d.control.throttle, 0.3 * (1.0 / 3.0) + 0.7 * 0.75));
    assert!(!d.turning);
    let error = ControlConfig {
        alpha: 1.5,
        ..ControlConfig::default()
    }
    .validate()
    .unwrap_err();
    assert!(error.starts_with("alpha = 1.5"), "{error}");
}

#[test]
fn a_long_stop_ends_in_a_creep_along_the_plan_unless_the_rule_is_off() {
    let config = ControlConfig::default();
    let rule = config.unstick.clone();
    let hold = [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]];
    let left_target = [10.0, 5.0];
    let wait_ticks = ticks(rule.after_s);
    let creep_ticks = ticks(rule.creep_s);

    let mut controller = EpisodeController::new(config.clone());
    let mut decisions = Vec::new();
    for _ in 0..wait_ticks + creep_ticks + 10 {
        decisions.push(controller.act_with_branch(
            &hold,
            left_target,
            0.0,
            None,
            Beliefs::default(),
        ));
    }
    assert!(
        decisions[..wait_ticks - 1]
            .iter()
            .all(|d| !d.unsticking && d.control.brake == 1.0),
        "the controller holds the car until the wait is over"
    );
    let creeping = &decisions[wait_ticks - 1..wait_ticks - 1 + creep_ticks];
    for d in creeping {
        assert!(d.unsticking, "{d:?}");
        assert_eq!(d.control.brake, 0.0);
        assert_eq!(d.control.throttle, rule.creep_throttle);
        assert!(
            d.control.steer < 0.0,
            "towards the target point on the left"
        );
    }
    assert!(
        decisions[wait_ticks - 1 + creep_ticks..]
            .iter()
            .all(|d| !d.unsticking),
        "after the creep the count starts again"
    );

    // Moving resets the count; the creep never exceeds its speed.
    let mut controller = EpisodeController::new(config.clone());
    for tick in 0..wait_ticks / 2 + wait_ticks {
        let speed = if tick == wait_ticks / 2 { 1.0 } else { 0.0 };
        assert!(
            !controller
                .act_with_branch(&hold, left_target, speed, None, Beliefs::default())
                .unsticking
        );
    }
    assert!(
        controller
            .act_with_branch(&hold, left_target, 0.0, None, Beliefs::default())
            .unsticking
    );
    let creep = controller.act_with_branch(
        &hold,
        left_target,
        rule.creep_speed + 0.1,
        None,
        Beliefs::default(),
    );
    assert!(
        creep.unsticking && creep.control.throttle == 0.0,
        "{creep:?}"
    );

    let off = ControlConfig {
        unstick: Unstick {
            enabled: false,
            ..Unstick::default()
        },
        ..config
    };
    let mut controller = EpisodeController::new(off);
    for _ in 0..wait_ticks * 3 {
        let d = controller.act_with_branch(&hold, left_target, 0.0, None, Beliefs::default());
        assert!(!d.unsticking && d.control.brake == 1.0);
    }
}

#[test]
fn the_safety_stop_brakes_for_what_lies_on_the_path_within_the_stopping_distance() {
    let rule = SafetyStop {
        enabled: true,
        ..SafetyStop::default()
    };
    let straight = [[2.0, 0.0], [4.0, 0.0], [6.0, 0.0], [8.0, 0.0]];
    // At 4 m/s the check reaches front 2.45 (the sedan's) + margin 1.5 + 2 m of reaction + 1.6 m
    // of braking.
    assert!(near(rule.reach(4.0), 7.55));
    assert!(rule.blocked(&straight, 4.0, &[[6.0, 0.5]]));
    assert!(
        !rule.blocked(&straight, 4.0, &[[9.0, 0.0]]),
        "beyond the reach"
    );
    assert!(
        rule.blocked(&straight, 8.0, &[[9.0, 0.0]]),
        "faster reaches further"
    );
    assert!(
        !rule.blocked(&straight, 4.0, &[[5.0, 2.3]]),
        "beside the corridor"
    );
    assert!(
        !rule.blocked(&straight, 4.0, &[[-3.0, 0.0]]),
        "behind the car"
    );
    assert!(!rule.blocked(&straight, 4.0, &[]));
    // The corridor follows a bend of the plan: a point straight ahead is off it.
    let left = [[2.0, 0.2], [3.5, 1.5], [4.5, 3.0], [5.0, 5.0]];
    assert!(rule.blocked(&left, 4.0, &[[4.2, 2.5]]));
    assert!(!rule.blocked(&left, 4.0, &[[6.0, -1.0]]));
    // The outside of a bend is in the corridor too: this point lies beyond the first
    // segment's end and before the second's start, 0.63 m from the corner between them.
    let bend = [[1.0, 1.0], [2.0, 1.0], [3.0, 1.0]];
    assert!(rule.blocked(&bend, 0.0, &[[0.8, 1.6]]));
    assert!(
        !rule.blocked(&bend, 0.0, &[[0.5, 2.7]]),
        "1.77 m from the corner"
    );
    // A plan to stand still checks straight ahead, as far as the margin at standstill.
    let hold = [[0.0, 0.0]; 4];
    assert!(rule.blocked(&hold, 0.0, &[[3.5, 0.0]]));
    assert!(!rule.blocked(&hold, 0.0, &[[4.5, 0.0]]));
    // Off, it never acts; out of range, it is refused with the field named.
    let off = SafetyStop::default();
    assert!(!off.enabled && !off.blocked(&straight, 4.0, &[[6.0, 0.0]]));
    let bad = SafetyStop {
        threshold: 1.5,
        ..SafetyStop::default()
    };
    assert!(bad.validate().unwrap_err().contains("safety.threshold"));
}

#[test]
fn a_stop_the_hazard_head_calls_clear_ends_in_an_early_creep() {
    let config = ControlConfig::default();
    let rule = config.unstick.clone();
    let clear_ticks = ticks(rule.clear_after_s);
    assert!(clear_ticks * 5 < ticks(rule.after_s));
    let confident = Some(rule.clear_probability + 0.05);
    let unsure = Some(rule.clear_probability - 0.05);
    // The first tick that creeps, over `ticks` ticks at `speed` with the head's `clear` given
    // by the tick.
    let first_creep = |ticks: usize, speed: f32, clear: &dyn Fn(usize) -> Option<f32>| {
        let mut controller = EpisodeController::new(config.clone());
        (0..ticks).find(|&tick| {
            let beliefs = Beliefs {
                clear: clear(tick),
                ..Beliefs::default()
            };
            let hold = [[0.0, 0.0]; 4];
            let d = controller.act_with_branch(&hold, [10.0, 0.0], speed, None, beliefs);
            d.unsticking && d.control.throttle == rule.creep_throttle && d.control.brake == 0.0
        })
    };
    assert_eq!(
        first_creep(clear_ticks * 3, 0.0, &|_| confident),
        Some(clear_ticks - 1)
    );
    // One unsure tick restarts the count.
    let glitch = clear_ticks / 2;
    let one_unsure = |tick| if tick == glitch { unsure } else { confident };
    assert_eq!(
        first_creep(clear_ticks * 3, 0.0, &one_unsure),
        Some(glitch + clear_ticks)
    );
    // Without the head, or unsure, or rolling, no early creep.
    assert_eq!(first_creep(clear_ticks * 3, 0.0, &|_| None), None);
    assert_eq!(first_creep(clear_ticks * 3, 0.0, &|_| unsure), None);
    assert_eq!(first_creep(clear_ticks * 3, 1.0, &|_| confident), None);
}

#[test]
fn a_stopped_car_counts_a_stop_sign_as_served_unless_told_otherwise() {
    // The head is sure something holds the car, and most likely a stop sign.
    let sign = Beliefs {
        clear: Some(0.3),
        stop_sign: Some(0.65),
        ..Beliefs::default()
    };
    let creeps_early = |served_stop_signs: bool| {
        let config = ControlConfig {
            unstick: Unstick {
                served_stop_signs,
                ..Unstick::default()
            },
            ..ControlConfig::default()
        };
        let ticks = ticks(config.unstick.clear_after_s) + 1;
        let mut controller = EpisodeController::new(config);
        let hold = [[0.0, 0.0]; 4];
        (0..ticks).any(|_| {
            controller
                .act_with_branch(&hold, [10.0, 0.0], 0.0, None, sign)
                .unsticking
        })
    };
    assert!(creeps_early(true), "on by default");
    assert!(!creeps_early(false));
    let rule = Unstick::default();
    let clear_only = Beliefs {
        clear: Some(0.3),
        ..Beliefs::default()
    };
    assert_eq!(rule.free_to_go(&clear_only), Some(0.3));
    let sign_only = Beliefs {
        stop_sign: Some(0.65),
        ..Beliefs::default()
    };
    assert_eq!(rule.free_to_go(&sign_only), None, "no head, no early creep");
}

#[test]
fn the_full_stop_turns_a_roll_past_a_stop_sign_into_a_stop() {
    let sign = Beliefs {
        clear: Some(0.1),
        stop_sign: Some(0.8),
        ..Beliefs::default()
    };
    // The plan rolls on at walking pace.
    let roll = [[0.7, 0.0], [1.4, 0.0], [2.1, 0.0], [2.8, 0.0]];
    let tick = |speed: f32, controller: &mut EpisodeController| {
        controller.act_with_branch(&roll, [10.0, 0.0], speed, None, sign)
    };
    let config = |enabled: bool| ControlConfig {
        full_stop: FullStop {
            enabled,
            ..FullStop::default()
        },
        ..ControlConfig::default()
    };
    let mut off = EpisodeController::new(config(false));
    let rolled = tick(1.4, &mut off);
    assert!(!rolled.full_stop && rolled.control.brake < 0.5);

    let mut on = EpisodeController::new(config(true));
    let braked = tick(1.4, &mut on);
    assert!(braked.full_stop && braked.control.brake == 1.0 && braked.control.throttle == 0.0);
    // Once the car stood, the sign is served: the plan drives it on though the head still
    // names the sign.
    tick(0.0, &mut on);
    let on_its_way = tick(1.4, &mut on);
    assert!(!on_its_way.full_stop && on_its_way.control.brake < 0.5);
}

#[test]
fn a_creep_that_started_runs_to_its_end_through_a_light_seen_red() {
    let config = ControlConfig::default();
    let rule = config.unstick.clone();
    let hold = [[0.0, 0.0]; 4];
    let red = light(0.01, 0.98);
    let mut controller = EpisodeController::new(config);
    // The hold lifts after the plain wait of seeing red, then the plain wait runs.
    let plain = ticks(rule.after_s);
    let first = (0..3 * plain)
        .find(|_| {
            controller
                .act_with_branch(&hold, [10.0, 0.0], 0.0, None, red)
                .unsticking
        })
        .expect("a creep starts");
    assert_eq!(first, 2 * plain - 2);
    // The car rolls (below the creep speed) and still sees red: the creep goes on.
    let creep = ticks(rule.creep_s);
    for tick in 1..creep {
        let d = controller.act_with_branch(&hold, [10.0, 0.0], 0.5, None, red);
        assert!(
            d.unsticking && d.control.throttle > 0.0,
            "tick {tick}: {d:?}"
        );
    }
}

#[test]
fn a_light_seen_red_holds_the_car_and_one_seen_green_is_nothing_to_wait_for() {
    let config = ControlConfig::default();
    let rule = config.unstick.clone();
    let hold = [[0.0, 0.0]; 4];
    // The first tick that creeps within `ticks`, with the beliefs given by the tick.
    let first_creep = |ticks: usize, beliefs: &dyn Fn(usize) -> Beliefs<'static>| {
        let mut controller = EpisodeController::new(config.clone());
        (0..ticks).find(|&tick| {
            controller
                .act_with_branch(&hold, [10.0, 0.0], 0.0, None, beliefs(tick))
                .unsticking
        })
    };
    let plain = ticks(rule.after_s);
    let early = ticks(rule.clear_after_s);
    // Seen red: no creep while a light can stay red; seen red for longer than the plain wait
    // in one standstill, flickering or not, the hold lifts and the plain wait runs from there.
    assert_eq!(first_creep(plain, &|_| light(0.01, 0.98)), None);
    assert_eq!(
        first_creep(plain * 3, &|_| light(0.01, 0.98)),
        Some(2 * plain - 2)
    );
    let flicker = |tick: usize| {
        if tick.is_multiple_of(10) {
            light(0.4, 0.4)
        } else {
            light(0.01, 0.98)
        }
    };
    let lifted = first_creep(plain * 4, &flicker).expect("the hold lifts");
    assert!(lifted < 3 * plain, "{lifted}");
    // Seen green: the light counts as served and the early creep comes.
    assert_eq!(first_creep(plain, &|_| light(0.98, 0.01)), Some(early - 1));
    // Red until a tick, then unsure of the colour: the plain wait counts from that tick.
    let seen_until = plain / 2;
    let red_then_unsure = |tick| {
        if tick < seen_until {
            light(0.01, 0.98)
        } else {
            light(0.4, 0.4)
        }
    };
    assert_eq!(
        first_creep(plain * 2, &red_then_unsure),
        Some(seen_until + plain - 1)
    );
    // Without the light head, the hazard head's "light" never counts as served.
    let no_light_head = Beliefs {
        light: None,
        ..light(0.98, 0.01)
    };
    assert_eq!(
        first_creep(plain, &|_| no_light_head),
        Some(plain - 1),
        "only the plain wait"
    );
    let bad = Unstick {
        light_hold_probability: 1.5,
        ..Unstick::default()
    };
    assert!(
        bad.validate()
            .unwrap_err()
            .contains("unstick.light_hold_probability")
    );
}

/// The default settings with the safety stop on.
fn safety_on() -> ControlConfig {
    ControlConfig {
        safety: SafetyStop {
            enabled: true,
            ..SafetyStop::default()
        },
        ..ControlConfig::default()
    }
}

#[test]
fn the_safety_stop_overrides_the_fused_control_and_the_creep() {
    let config = safety_on();
    let ahead = [[2.0, 0.0], [4.0, 0.0], [6.0, 0.0], [8.0, 0.0]];
    let mut controller = EpisodeController::new(config.clone());
    let free = controller.act(
        &ahead,
        [20.0, 0.0],
        3.0,
        [3.0, 2.0],
        [2.0, 2.0],
        Beliefs::default(),
    );
    assert!(!free.safety_stop && free.control.throttle > 0.5);
    let stop = controller.act(
        &ahead,
        [20.0, 0.0],
        3.0,
        [3.0, 2.0],
        [2.0, 2.0],
        Beliefs {
            occupied: &[[5.0, 0.0]],
            ..Beliefs::default()
        },
    );
    assert!(stop.safety_stop, "{stop:?}");
    assert_eq!((stop.control.throttle, stop.control.brake), (0.0, 1.0));
    assert!(stop.trajectory.throttle > 0.5, "the sources still say go");

    // After the long wait the unstick rule would creep; not into an occupied cell.
    let hold = [[0.0, 0.0]; 4];
    let wait_ticks = ticks(config.unstick.after_s);
    let mut controller = EpisodeController::new(config);
    let decisions: Vec<_> = (0..wait_ticks + 5)
        .map(|_| {
            let beliefs = Beliefs {
                occupied: &[[3.0, 0.0]],
                ..Beliefs::default()
            };
            controller.act_with_branch(&hold, [10.0, 0.0], 0.0, None, beliefs)
        })
        .collect();
    let last = decisions.last().unwrap();
    assert!(last.unsticking && last.safety_stop && last.control.throttle == 0.0);
}

#[test]
fn a_safety_stop_with_hold_s_brakes_on_that_long_after_the_path_last_looked_blocked() {
    let ahead = [[2.0, 0.0], [4.0, 0.0], [6.0, 0.0], [8.0, 0.0]];
    // Blocked on the first tick only, then clear: how many ticks after it still brake.
    let braked_after = |hold_s: f32| {
        let mut config = safety_on();
        config.safety.hold_s = hold_s;
        let mut controller = EpisodeController::new(config);
        (0..ticks(3.0))
            .map(|tick| {
                let occupied: &[[f32; 2]] = if tick == 0 { &[[5.0, 0.0]] } else { &[] };
                let beliefs = Beliefs {
                    occupied,
                    ..Beliefs::default()
                };
                controller.act_with_branch(&ahead, [20.0, 0.0], 3.0, None, beliefs)
            })
            .skip(1)
            .take_while(|d| d.safety_stop && d.control.brake == 1.0)
            .count()
    };
    assert_eq!(braked_after(0.0), 0, "released on the first clear tick");
    assert_eq!(braked_after(1.0), ticks(1.0));
    assert_eq!(braked_after(0.5), ticks(0.5));

    let mut config = safety_on();
    config.safety.hold_s = -1.0;
    assert!(config.validate().unwrap_err().contains("safety.hold_s"));
}

#[test]
fn the_safety_stop_lets_a_creep_through_once_it_held_the_car_too_long() {
    let config = safety_on();
    let hold = [[0.0, 0.0]; 4];
    let beliefs = Beliefs {
        occupied: &[[3.0, 0.0]],
        ..Beliefs::default()
    };
    let mut controller = EpisodeController::new(config.clone());
    // Stopped and held: the creeps before `yield_after_s` are braked, the first one after it
    // goes through, all of it, while the car gathers speed.
    let yield_ticks = ticks(config.safety.yield_after_s);
    let mut speed = 0.0;
    let mut through = Vec::new();
    for tick in 0..yield_ticks + 3 * ticks(config.unstick.after_s) {
        let d = controller.act_with_branch(&hold, [10.0, 0.0], speed, None, beliefs);
        if d.unsticking && !d.safety_stop {
            assert!(d.control.throttle > 0.0 && d.control.brake == 0.0, "{d:?}");
            through.push(tick);
            speed = 1.0;
        } else {
            assert!(d.control.brake == 1.0, "tick {tick}: {d:?}");
            speed = 0.0;
        }
    }
    let creep_ticks = ticks(config.unstick.creep_s);
    assert!(through[0] >= yield_ticks, "yielded at tick {}", through[0]);
    assert_eq!(
        through[..creep_ticks],
        (through[0]..through[0] + creep_ticks).collect::<Vec<_>>()[..],
        "the whole creep goes through"
    );
    assert!(
        through
            .iter()
            .all(|&t| t < through[0] + creep_ticks || t >= through[0] + yield_ticks),
        "then the stop holds again until it has held too long again"
    );
}

#[test]
fn a_belief_that_flickers_does_not_restart_the_safety_stops_count() {
    let config = safety_on();
    let hold = [[0.0, 0.0]; 4];
    let mut controller = EpisodeController::new(config.clone());
    // The cell ahead drops out for one tick every 10 s; the creeps on the ticks it is there
    // are braked until the stop has held the car `yield_after_s`, then let through.
    let yield_ticks = ticks(config.safety.yield_after_s);
    let through = (0..yield_ticks + 2 * ticks(config.unstick.after_s)).find(|&tick| {
        let occupied: &[[f32; 2]] = if tick % ticks(10.0) == ticks(5.0) {
            &[]
        } else {
            &[[3.0, 0.0]]
        };
        let beliefs = Beliefs {
            occupied,
            ..Beliefs::default()
        };
        let d = controller.act_with_branch(&hold, [10.0, 0.0], 0.0, None, beliefs);
        !occupied.is_empty() && d.unsticking && !d.safety_stop
    });
    let through = through.expect("a creep gets through");
    assert!(through >= yield_ticks, "yielded at tick {through}");
}
