//! Training side: one optimisation step on a fixed batch lowers imitation + BEV loss, and
//! gradients reach every module; the special functions behind the Beta KL.

mod common;

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Distribution, Tensor};
use common::{model_input, tiny_config};
use ssr_agent::model::hazard::Hazard;
use ssr_agent::model::tcp_head::SPEED_SCALE;
use ssr_agent::model::{SsrModel, float_values};
use ssr_agent::train::gamma::{digamma, ln_gamma, ln_gamma_f64};
use ssr_agent::train::hazard::hazard_loss;
use ssr_agent::train::loss::{AuxiliaryLosses, BetaTargets, ImitationTargets, LossWeights, losses};
use ssr_agent::train::occupancy::{batch_targets, occupancy_loss};
use ssrdrive_proto::dataset::{ActorClass, ActorRecord};

struct MissingGradients<'a> {
    grads: &'a GradientsParams,
    path: Vec<String>,
    checked: usize,
    missing: Vec<String>,
}

impl ModuleVisitor for MissingGradients<'_> {
    fn enter_module(&mut self, name: &str, _container: &str) {
        self.path.push(name.to_string());
    }

    fn exit_module(&mut self, _name: &str, _container: &str) {
        self.path.pop();
    }

    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if !param.val().is_require_grad() {
            return;
        }
        self.checked += 1;
        let reached = self
            .grads
            .get::<D>(param.id)
            .is_some_and(|g| float_values(g).iter().any(|v| *v != 0.0));
        if !reached {
            self.missing.push(self.path.join("."));
        }
    }
}

#[test]
fn one_step_lowers_the_loss_and_reaches_every_module() {
    let device = Device::flex().autodiff();
    // Fixed initial weights. Drawn afresh, tiny's 8-wide can-bus layer was dead for the shared
    // ego motion of this batch (every ReLU negative, so no gradient behind it) in 1 run of 100.
    device.seed(7);
    let config = tiny_config();
    let mut model = config.init(&device);
    let batch = 2;
    let input = model_input(&config, batch, 1, true, &device);
    let future_input = model_input(&config, batch, 1, true, &device);
    // The future frame's BEV, from the same network without gradients (SSR's target).
    let future_bev = model.valid().forward(&future_input.clone()).bev;
    let future_bev = Tensor::from_data(future_bev.into_data(), &device);
    let p = config.head.pred_len;
    let actions: Vec<f32> = (0..batch * (p + 1) * 2)
        .map(|i| ((i % 7) as f32 - 3.0) / 4.0)
        .collect();
    // Speed targets one scale unit (12 m/s) above the untrained predictions. The speed loss is
    // L1: targets the predictions straddled would give gradient signs that cancel over the
    // batch, and the speed bias no gradient, by chance (1 run in 20 with a shared target).
    let untrained_speed = float_values(model.valid().forward(&input.clone()).head.speed);
    let speed_targets: Vec<f32> = untrained_speed
        .iter()
        .map(|s| (s + 1.0) * SPEED_SCALE)
        .collect();
    let targets = ImitationTargets {
        waypoints: Tensor::random([batch, p, 2], Distribution::Normal(0.0, 2.0), &device),
        actions: BetaTargets::new(&actions, batch, p + 1, 10.0, &device),
        speed: Tensor::<1>::from_floats(speed_targets.as_slice(), &device).reshape([batch, 1]),
    };
    // A car 6 m ahead in one frame, nothing recorded in the other: the occupancy head's labels.
    let car = ActorRecord {
        class: ActorClass::Vehicle,
        centre: [6.0, 0.0],
        yaw: 0.0,
        half: [2.4, 1.0],
    };
    let (occupied, recorded) = batch_targets(&[Some(vec![car]), None], &config.bev.grid, &device);
    let weights = LossWeights::default();
    let loss_of = |model: &SsrModel| {
        let output = model.forward(&input);
        let predicted = model.predict_future_bev(&output);
        let head = model.occupancy.as_ref().expect("the presets have the head");
        let occupancy = occupancy_loss(
            head.forward(output.bev.clone()),
            occupied.clone(),
            recorded.clone(),
        );
        let hazards: Vec<Hazard> = (0..batch).map(|i| Hazard::ALL[i % 5]).collect();
        let hazard = model.hazard.as_ref().expect("the presets have the head");
        let hazard = hazard_loss(hazard.forward(output.scene.tokens.clone()), &hazards);
        losses(
            &output.head,
            &targets,
            Some((predicted, future_bev.clone())),
            AuxiliaryLosses {
                hazard: Some(hazard),
                occupancy: Some(occupancy),
                motion: None,
                light: None,
            },
            &weights,
        )
    };

    let before = loss_of(&model);
    let before_total = float_values(before.total.clone())[0];
    let grads = GradientsParams::from_grads(before.total.backward(), &model);
    let mut optimizer = AdamWConfig::new().init();
    model = optimizer.step(1e-3, model, grads);
    let after = loss_of(&model);
    let after_total = float_values(after.total.clone())[0];
    assert!(
        after_total < before_total,
        "loss {before_total} -> {after_total}"
    );

    // MLN starts as the identity (zero gamma/beta weights), so its input layer first receives
    // gradient once those weights moved: check every module on the second step.
    let grads = GradientsParams::from_grads(after.total.backward(), &model);
    let mut visitor = MissingGradients {
        grads: &grads,
        path: Vec::new(),
        checked: 0,
        missing: Vec::new(),
    };
    model.visit(&mut visitor);
    assert!(
        visitor.checked > 100,
        "visited {} parameters",
        visitor.checked
    );
    assert!(
        visitor.missing.is_empty(),
        "no gradient reached: {:?}",
        visitor.missing
    );
}

#[test]
fn special_functions_match_known_values() {
    let device = Device::flex();
    let x = Tensor::<1>::from_floats([0.5, 1.0, 2.0, 10.0, 0.05], &device);
    let expected = [0.572_364_9, 0.0, 0.0, 12.801_827, 2.968_88];
    for (got, want) in float_values(ln_gamma(x)).iter().zip(expected) {
        assert!((got - want).abs() < 1e-4, "ln_gamma: {got} vs {want}");
    }
    assert!((ln_gamma_f64(0.5) - 0.572_364_942_924_700_1).abs() < 1e-7);
    assert!((digamma(1.0) + 0.577_215_664_901_532_9).abs() < 1e-8);
    assert!((digamma(0.5) + 1.963_510_026_021_423_5).abs() < 1e-8);
}

#[test]
fn validation_situations_follow_the_command_start_ups_and_brake_causes() {
    use ssr_agent::train::validation::situations;
    let one_hot = |i: usize| {
        let mut v = [0.0f32; 6];
        v[i] = 1.0;
        v
    };
    assert_eq!(situations(&one_hot(0), 5.0, 0.5, None), ["left"]);
    assert_eq!(situations(&one_hot(1), 5.0, 0.0, None), ["right"]);
    assert_eq!(situations(&one_hot(3), 0.2, 0.6, None), ["follow", "start"]);
    assert_eq!(
        situations(&one_hot(3), 0.2, 0.0, None),
        ["follow"],
        "standing, not starting"
    );
    assert_eq!(situations(&one_hot(5), 8.0, 0.3, None), ["change-lane"]);
    // What the expert brakes for.
    use ssrdrive_proto::dataset::BrakeReason;
    let light = Some(BrakeReason::TrafficLight);
    assert_eq!(
        situations(&one_hot(2), 0.0, 0.0, light),
        ["straight", "brake:light"]
    );
    let walker = Some(BrakeReason::Walker);
    assert_eq!(
        situations(&one_hot(3), 4.0, 0.0, walker),
        ["follow", "brake:road-user"]
    );
    let sign = Some(BrakeReason::StopSign);
    assert_eq!(
        situations(&one_hot(3), 4.0, 0.0, sign),
        ["follow", "brake:sign"]
    );
}

#[test]
fn balanced_sampling_favours_starts_slowing_light_waits_stop_signs_walkers_turns_recoveries_and_the_learners_states()
 {
    use ssr_agent::train::data::sampling_weight;
    use ssrdrive_proto::dataset::{BrakeReason, FrameRecord};
    let record = |speed: f64, throttle: f32, brake: f32, command: i32, noise: bool| {
        let mut f: FrameRecord = serde_json::from_str(
            r#"{"index":0,"tick":0,"time":0,"speed":0,"position":[0,0,0],"yaw":0,"command":4,
            "target_point":[10,0],"control":{"steer":0,"throttle":0,"brake":0},
            "executed":{"steer":0,"throttle":0,"brake":0},"noise":false,"brake_reason":null,
            "waypoints":[],"future_controls":[],"future_complete":true,"images":[]}"#,
        )
        .unwrap();
        f.speed = speed;
        f.control.throttle = throttle;
        f.control.brake = brake;
        f.command = command;
        f.noise = noise;
        f
    };
    let frame = |speed, throttle, brake, command, noise| {
        sampling_weight(&record(speed, throttle, brake, command, noise), false)
    };
    let cruising = frame(8.0, 0.5, 0.0, 4, false);
    let standing = frame(0.0, 0.0, 1.0, 4, false);
    let mut at_red = record(0.0, 0.0, 1.0, 4, false);
    at_red.brake_reason = Some(BrakeReason::TrafficLight);
    assert!(
        sampling_weight(&at_red, false) > standing,
        "waiting at a red light"
    );
    let slowing = frame(6.0, 0.0, 0.5, 4, false);
    let starting = frame(0.5, 0.6, 0.0, 4, false);
    assert!(standing < cruising, "{standing} vs {cruising}");
    assert!(cruising < slowing && slowing < starting);
    let mut for_sign = record(6.0, 0.0, 0.5, 4, false);
    for_sign.brake_reason = Some(BrakeReason::StopSign);
    assert!(
        sampling_weight(&for_sign, false) > starting,
        "slowing for a stop sign"
    );
    let mut for_walker = record(2.0, 0.0, 1.0, 4, false);
    for_walker.brake_reason = Some(BrakeReason::Walker);
    assert!(
        sampling_weight(&for_walker, false) > starting,
        "braking for a walker"
    );
    assert!(frame(8.0, 0.5, 0.0, 1, false) > cruising, "a turn");
    assert!(
        frame(8.0, 0.5, 0.0, 6, false) > frame(8.0, 0.5, 0.0, 1, false),
        "a lane change"
    );
    assert!(
        frame(8.0, 0.5, 0.0, 4, true) > cruising,
        "a perturbed frame"
    );
    assert!(
        sampling_weight(&record(8.0, 0.5, 0.0, 4, false), true) > cruising,
        "a state the learner reached (DAgger)"
    );
}

#[test]
fn frames_whose_label_follows_a_lamp_out_of_view_are_left_out() {
    use ssr_agent::train::data::blind_to_its_light;
    use ssrdrive_proto::dataset::{BrakeReason, FrameRecord};
    let mut frame: FrameRecord = serde_json::from_str(
        r#"{"index":0,"tick":0,"time":0,"speed":0,"position":[0,0,0],"yaw":0,"command":4,
        "target_point":[10,0],"control":{"steer":0,"throttle":0,"brake":1},
        "executed":{"steer":0,"throttle":0,"brake":1},"noise":false,"brake_reason":"traffic_light",
        "waypoints":[],"future_controls":[],"future_complete":true,"images":[],
        "light":{"state":"red","distance":1.0},"light_in_view":false}"#,
    )
    .unwrap();
    assert!(blind_to_its_light(&frame), "holding for a lamp out of view");
    frame.brake_reason = Some(BrakeReason::Vehicle);
    assert!(
        !blind_to_its_light(&frame),
        "holding for a car, which the camera shows"
    );
    frame.brake_reason = None;
    frame.light = serde_json::from_str(r#"{"state":"green","distance":1.0}"#).unwrap();
    assert!(
        !blind_to_its_light(&frame),
        "going on past a head out of view"
    );
    frame.brake_reason = Some(BrakeReason::TrafficLight);
    frame.light_in_view = Some(true);
    assert!(!blind_to_its_light(&frame), "the lamp in view");
    frame.light_in_view = None;
    assert!(
        !blind_to_its_light(&frame),
        "recorded before the field (or no light ahead)"
    );
}
