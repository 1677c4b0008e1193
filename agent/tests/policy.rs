//! The inference API: episode state across steps, batched steps, and input errors that leave
//! every episode as it was.

mod common;

use common::{policy_of, rig, step_input, tiny_config};
use ssr_agent::control::{ControlConfig, ControlDecision, SafetyStop, Unstick};
use ssr_agent::history::History;
use ssr_agent::model::bev::HISTORY_TICKS;
use ssr_agent::model::config::SsrConfig;
use ssr_agent::policy::{InputError, SsrPolicy, StepError, StepInput, StepOutput};
use ssrdrive_proto::camera::Rig;

fn policy() -> SsrPolicy {
    policy_of(tiny_config())
}

#[test]
fn an_episode_keeps_its_bev_and_debug_maps_come_back() {
    let policy = policy();
    let rig = rig(1, 900, 256);
    let mut episode = policy.new_episode();
    assert!(!episode.has_previous_bev());
    let out = policy.step(&mut episode, &step_input(&rig, 0, 1)).unwrap();
    assert_eq!(out.waypoints.len(), policy.config().head.pred_len);
    let c = out.decision.control;
    assert!(
        (-1.0..=1.0).contains(&c.steer)
            && (0.0..=1.0).contains(&c.throttle)
            && (0.0..=1.0).contains(&c.brake)
    );
    let debug = out.debug.unwrap();
    assert_eq!(
        debug.token_attention.len(),
        policy.config().tokens.num_tokens
    );
    assert_eq!(
        debug.token_attention[0].len(),
        debug.bev_rows * debug.bev_cols
    );
    // The occupancy head's vehicle and walker probabilities, even with the safety stop off.
    assert!(!policy.control().safety.enabled);
    assert_eq!(debug.occupancy.len(), 2);
    assert!(debug.occupancy.iter().all(|map| {
        map.len() == debug.bev_rows * debug.bev_cols && map.iter().all(|p| (0.0..=1.0).contains(p))
    }));
    // The history is the BEV of the step HISTORY_TICKS (0.5 s) back, as in training.
    for tick in 1..HISTORY_TICKS as u32 {
        assert!(!episode.has_previous_bev(), "no history yet at tick {tick}");
        policy
            .step(&mut episode, &step_input(&rig, tick, 1))
            .unwrap();
    }
    assert!(episode.has_previous_bev() && episode.ticks() == HISTORY_TICKS as u64);
    policy
        .step(&mut episode, &step_input(&rig, HISTORY_TICKS as u32, 1))
        .unwrap();
    assert!(episode.has_previous_bev() && episode.ticks() == HISTORY_TICKS as u64 + 1);
    assert_eq!(
        policy.episode_state_bytes(),
        2 * HISTORY_TICKS * 8 * 8 * 16 * 4
    );
}

#[test]
fn a_step_sees_the_history_chain_training_gives_it_and_nothing_older() {
    // Training plans from a frame whose history is the frame 0.5 s back, itself with the frame
    // 1 s back as its history. Serving does the same: the plan at tick t depends on the frames
    // of ticks t, t - 10 and t - 20 (and the poses), not on the frame of tick t - 30.
    let policy = policy();
    let rig = rig(1, 900, 256);
    let t = 3 * HISTORY_TICKS as u32;
    let chain = [t - 2 * HISTORY_TICKS as u32, t - HISTORY_TICKS as u32, t];
    let plan_at_t = |history: History, seed_of: &dyn Fn(u32) -> u32| {
        let mut episode = policy.new_episode_with_history(history);
        let mut last = None;
        for tick in 0..=t {
            let input = step_input(&rig, tick, seed_of(tick));
            last = Some(policy.step(&mut episode, &input).unwrap());
        }
        last.unwrap().waypoints
    };
    let outside_differ = |tick| if chain.contains(&tick) { 1 } else { 2 };
    let reference = plan_at_t(History::Chain, &|_| 1);
    let others_differ = plan_at_t(History::Chain, &outside_differ);
    assert_eq!(
        reference, others_differ,
        "frames outside the chain changed the plan"
    );
    let chain_differs = plan_at_t(History::Chain, &|tick| if tick == chain[0] { 2 } else { 1 });
    assert_ne!(
        reference, chain_differs,
        "the frame 1 s back is part of the chain"
    );
    // One link: the frame 0.5 s back, on its own.
    let link = [t - HISTORY_TICKS as u32, t];
    let link_reference = plan_at_t(History::Link, &|_| 1);
    assert_eq!(
        link_reference,
        plan_at_t(History::Link, &|tick| if link.contains(&tick) {
            1
        } else {
            2
        }),
        "frames outside the link changed the plan"
    );
    assert_ne!(
        link_reference,
        plan_at_t(History::Link, &|tick| if tick == link[0] { 2 } else { 1 }),
        "the frame 0.5 s back is the link"
    );
    // The recursion of checkpoints validated before the chain reaches back further.
    assert_ne!(
        plan_at_t(History::Recursive, &|_| 1),
        plan_at_t(History::Recursive, &outside_differ)
    );
}

#[test]
fn episodes_of_every_history_mode_step_in_one_batch_as_alone() {
    // A batch runs the passes its most demanding episode needs; each episode still plans from
    // its own history.
    let policy = policy();
    let rig = rig(1, 900, 256);
    let modes = [History::Link, History::Chain, History::Recursive];
    let episode = |history| policy.new_episode_with_history(history);
    let mut alone: Vec<_> = modes.iter().map(|&m| episode(m)).collect();
    let mut together: Vec<_> = modes.iter().map(|&m| episode(m)).collect();
    for tick in 0..=2 * HISTORY_TICKS as u32 + 1 {
        let inputs: Vec<_> = (0..modes.len())
            .map(|i| step_input(&rig, tick, tick % 3 + i as u32))
            .collect();
        let expected: Vec<_> = alone
            .iter_mut()
            .zip(&inputs)
            .map(|(e, i)| policy.step(e, i).unwrap())
            .collect();
        let mut refs: Vec<_> = together.iter_mut().collect();
        let got = policy.step_batch(&mut refs, &inputs).unwrap();
        assert_same_outputs(&expected, &got, &format!("tick {tick}, {modes:?}"));
    }
}

/// Batched outputs `got` equal the single steps' `expected`, one for one: as many, each with
/// its full plan, the waypoints and the control to 1e-4.
fn assert_same_outputs(expected: &[StepOutput], got: &[StepOutput], what: &str) {
    assert_eq!(expected.len(), got.len(), "{what}: outputs");
    for (k, (a, b)) in expected.iter().zip(got).enumerate() {
        assert!(!a.waypoints.is_empty(), "{what}: no plan");
        assert_eq!(a.waypoints.len(), b.waypoints.len(), "{what}: plan lengths");
        for (wa, wb) in a.waypoints.iter().zip(&b.waypoints) {
            assert!(
                (wa[0] - wb[0]).abs() < 1e-4 && (wa[1] - wb[1]).abs() < 1e-4,
                "{what}, episode {k}: {wa:?} vs {wb:?}"
            );
        }
        let (ca, cb) = (a.decision.control, b.decision.control);
        let close = [
            (ca.steer, cb.steer),
            (ca.throttle, cb.throttle),
            (ca.brake, cb.brake),
        ]
        .iter()
        .all(|(x, y)| (x - y).abs() < 1e-4);
        assert!(close, "{what}, episode {k}: {ca:?} vs {cb:?}");
    }
}

#[test]
fn a_step_is_the_same_bits_on_any_number_of_threads() {
    // The server runs each model thread's passes on a pool of its own size, so a run must not
    // depend on how many cores it got. The full-size network, so the kernels' parallel paths run.
    let policy = policy_of(SsrConfig::cpu_default());
    let rig = rig(1, 900, 256);
    let drive = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut episode = policy.new_episode();
            (0..3)
                .map(|tick| {
                    let out = policy
                        .step(&mut episode, &step_input(&rig, tick, 5))
                        .unwrap();
                    let control = out.decision.control;
                    let mut bits: Vec<u32> = out
                        .waypoints
                        .iter()
                        .flatten()
                        .map(|v| v.to_bits())
                        .collect();
                    bits.extend([control.steer, control.throttle, control.brake].map(f32::to_bits));
                    bits
                })
                .collect::<Vec<_>>()
        })
    };
    let alone = drive(1);
    assert_eq!(drive(2), alone);
    assert_eq!(drive(3), alone);
}

#[test]
fn a_batch_equals_single_steps_even_with_mixed_rigs() {
    let policy = policy();
    let rigs = [rig(1, 900, 256), rig(3, 400, 300), rig(1, 900, 256)];
    let inputs: Vec<_> = rigs
        .iter()
        .enumerate()
        .map(|(i, r)| step_input(r, 0, i as u32 + 7))
        .collect();
    let mut singles: Vec<_> = (0..3).map(|_| policy.new_episode()).collect();
    let expected: Vec<_> = singles
        .iter_mut()
        .zip(&inputs)
        .map(|(e, i)| policy.step(e, i).unwrap())
        .collect();
    let mut batched: Vec<_> = (0..3).map(|_| policy.new_episode()).collect();
    let mut refs: Vec<_> = batched.iter_mut().collect();
    let got = policy.step_batch(&mut refs, &inputs).unwrap();
    assert_same_outputs(&expected, &got, "mixed rigs");
}

#[test]
fn bad_inputs_are_named_and_change_nothing() {
    let policy = policy();
    let rig = rig(1, 900, 256);
    let mut episode = policy.new_episode();
    policy.step(&mut episode, &step_input(&rig, 0, 1)).unwrap();

    let mut input = step_input(&rig, 1, 1);
    input.speed = f32::NAN;
    assert!(matches!(
        policy.step(&mut episode, &input),
        Err(StepError::Input {
            source: InputError::BadNumber { field: "speed", .. },
            ..
        })
    ));
    // Negative speed is refused here as on the wire: the network only knew forward speeds.
    let mut input = step_input(&rig, 1, 1);
    input.speed = -1.0;
    let error = policy.step(&mut episode, &input).unwrap_err().to_string();
    assert!(
        error.contains("speed = -1 is not a finite number in 0..100"),
        "{error}"
    );
    let mut input = step_input(&rig, 1, 1);
    input.frames.clear();
    assert!(matches!(
        policy.step(&mut episode, &input),
        Err(StepError::Input {
            source: InputError::FrameCount {
                expected: 1,
                got: 0
            },
            ..
        })
    ));
    let mut input = step_input(&rig, 1, 1);
    input.frames[0].rgb.truncate(100);
    let err = policy.step(&mut episode, &input).unwrap_err();
    assert!(
        err.to_string().contains("needs 691200 bytes, got 100"),
        "{err}"
    );
    let mut input = step_input(&rig, 1, 1);
    input.frames[0].width = 800;
    assert!(matches!(
        policy.step(&mut episode, &input),
        Err(StepError::Input {
            source: InputError::FrameSize { .. },
            ..
        })
    ));
    let mut input = step_input(&rig, 1, 1);
    input.rig.cameras[0].fov = -5.0;
    assert!(matches!(
        policy.step(&mut episode, &input),
        Err(StepError::Input {
            source: InputError::Rig(_),
            ..
        })
    ));

    // A bad second episode fails the whole batch before anything runs.
    let mut other = policy.new_episode();
    let mut bad = step_input(&rig, 1, 2);
    bad.target_point = [f32::INFINITY, 0.0];
    let err = policy
        .step_batch(
            &mut [&mut episode, &mut other],
            &[step_input(&rig, 1, 1), bad],
        )
        .unwrap_err();
    assert!(
        matches!(
            err,
            StepError::Input {
                episode: 1,
                source: InputError::BadNumber {
                    field: "target_point.x",
                    ..
                }
            }
        ),
        "{err}"
    );
    assert!(matches!(
        policy.step_batch(&mut [&mut episode], &[]),
        Err(StepError::BatchShape { .. })
    ));
    assert_eq!(
        episode.ticks(),
        1,
        "failed steps leave the episode untouched"
    );
    assert_eq!(other.ticks(), 0);
}

/// The decision of a new episode's first step under `control`.
fn first_decision(policy: &SsrPolicy, rig: &Rig, control: ControlConfig) -> ControlDecision {
    let mut episode = policy.new_episode_with(control);
    policy
        .step(&mut episode, &step_input(rig, 0, 1))
        .unwrap()
        .decision
}

#[test]
fn the_safety_stop_reads_the_occupancy_head_at_its_threshold() {
    let policy = policy();
    let rig = rig(1, 900, 256);
    // The tiny grid's cells are 6 m wide: the nearest centres ahead are 3 m to either side.
    let safety = |threshold: f32| ControlConfig {
        safety: SafetyStop {
            enabled: true,
            threshold,
            half_width: 3.5,
            ..SafetyStop::default()
        },
        ..ControlConfig::default()
    };
    let decide = |policy: &SsrPolicy, control: ControlConfig| first_decision(policy, &rig, control);
    // Every cell counts at threshold 0, none at 1 (the random head is far from certain).
    let stop = decide(&policy, safety(0.0));
    assert!(stop.safety_stop && stop.control.brake == 1.0 && stop.control.throttle == 0.0);
    assert!(!decide(&policy, safety(1.0)).safety_stop);
    assert!(
        !decide(&policy, ControlConfig::default()).safety_stop,
        "off by default"
    );
    // A network without the head gives the rule nothing to see.
    let headless = policy_of(SsrConfig {
        occupancy_head: false,
        ..tiny_config()
    });
    assert!(!decide(&headless, safety(0.0)).safety_stop);
}

#[test]
fn the_safety_stops_motion_rule_reads_the_motion_head_at_its_threshold() {
    let rig = rig(1, 900, 256);
    let with_motion = policy_of(SsrConfig {
        motion_head: true,
        ..tiny_config()
    });
    // The occupancy cells never count (threshold above any probability); the motion head's do
    // where its threshold lets them.
    let safety = |motion: bool, motion_threshold: f32| ControlConfig {
        safety: SafetyStop {
            enabled: true,
            threshold: 1.0,
            half_width: 3.5,
            motion,
            motion_threshold,
            ..SafetyStop::default()
        },
        ..ControlConfig::default()
    };
    let decide = |policy: &SsrPolicy, control: ControlConfig| first_decision(policy, &rig, control);
    assert!(decide(&with_motion, safety(true, 0.0)).safety_stop);
    assert!(!decide(&with_motion, safety(true, 1.0)).safety_stop);
    assert!(
        !decide(&with_motion, safety(false, 0.0)).safety_stop,
        "the motion rule is off unless asked for"
    );
    // A network without the head gives the rule nothing to see.
    assert!(!decide(&policy(), safety(true, 0.0)).safety_stop);
}

#[test]
fn the_early_creep_reads_the_hazard_head_at_its_threshold() {
    let policy = policy();
    let rig = rig(1, 900, 256);
    // Creep after one standing tick whose "clear" reaches `probability`.
    let early = |probability: f32| ControlConfig {
        unstick: Unstick {
            clear_after_s: 0.05,
            clear_probability: probability,
            ..Unstick::default()
        },
        ..ControlConfig::default()
    };
    let decide = |policy: &SsrPolicy, control: ControlConfig| {
        let mut episode = policy.new_episode_with(control);
        let standing = StepInput {
            speed: 0.0,
            ..step_input(&rig, 0, 1)
        };
        policy.step(&mut episode, &standing).unwrap().decision
    };
    // Any probability reaches 0, none of the random head's reaches 1.
    assert!(decide(&policy, early(0.0)).unsticking);
    assert!(!decide(&policy, early(1.0)).unsticking);
    // A network without the head gives the rule nothing to read.
    let headless = policy_of(SsrConfig {
        hazard_head: false,
        ..tiny_config()
    });
    assert!(!decide(&headless, early(0.0)).unsticking);
}
