//! `ssr_agent::train` end to end on a tiny dataset fixture: the loss falls, a resumed run
//! redraws the same loss curve, checkpoints round-trip, and bad datasets or run folders give
//! errors naming the problem.

mod common;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

use burn::tensor::{Device, Tensor};
use common::fixture::{FIXTURE_FRAMES, FIXTURE_ROUTES, write_fixture_dataset};
use common::tiny_config;
use ssr_agent::checkpoint;
use ssr_agent::control::ControlConfig;
use ssr_agent::device::Backend;
use ssr_agent::history::History;
use ssr_agent::model::config::SsrConfig;
use ssr_agent::model::float_values;
use ssr_agent::train::augment::Photometric;
use ssr_agent::train::config::{Head, Schedule, TrainConfig};
use ssr_agent::train::data::{Labels, SampleDraw, TrainingData, action_of};
use ssr_agent::train::run::{MetricsLine, StepMetrics, TrainError, TrainOptions, train};
use ssrdrive_proto::control::Control;

/// Held by every test that seeds the device or draws initial weights. `train` seeds the
/// device's random generator, which is global to the process, and then initialises the model
/// from it; a test running beside it in this binary that draws weights in between would change
/// that model (a resumed run then no longer redraws the same loss curve).
fn device_rng() -> MutexGuard<'static, ()> {
    static DEVICE_RNG: Mutex<()> = Mutex::new(());
    DEVICE_RNG
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// One test's scratch space: a fresh temporary folder, removed when the test ends.
struct Scratch(tempfile::TempDir);

impl Scratch {
    fn new() -> Self {
        Self(tempfile::tempdir().expect("a temporary folder"))
    }

    /// A new empty folder `name` inside.
    fn dir(&self, name: &str) -> PathBuf {
        let dir = self.0.path().join(name);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// A new folder `name` holding the fixture dataset.
    fn fixture(&self, name: &str) -> PathBuf {
        let root = self.dir(name);
        write_fixture_dataset(&root);
        root
    }
}

fn config(steps: u64) -> TrainConfig {
    let mut config = TrainConfig::new(tiny_config(), steps);
    config.batch_size = 4;
    config.lr = 2e-3;
    config.warmup_steps = 2;
    config.validation_fraction = 0.3;
    config.validate_every = 0;
    config.checkpoint_every = 3;
    config
}

fn open(data: &Path, config: &TrainConfig) -> Arc<TrainingData> {
    Arc::new(
        TrainingData::open(
            data,
            &config.model,
            config.labels,
            config.validation_fraction,
            |_, _| {},
        )
        .unwrap(),
    )
}

fn options(data: &Path, out: &Path) -> TrainOptions {
    TrainOptions {
        data: data.to_path_buf(),
        out: out.to_path_buf(),
        resume: false,
        stop_at: None,
        backend: Backend::Cpu,
        progress: false,
    }
}

fn step_lines(out: &Path) -> Vec<StepMetrics> {
    std::fs::read_to_string(out.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .filter_map(|line| match serde_json::from_str(line).unwrap() {
            MetricsLine::Step(step) => Some(step),
            MetricsLine::Validation(_) => None,
        })
        .collect()
}

/// Why a fresh run of `config` on `data` into `out` failed.
/// A run of `config` on `data` into `out`, trained to its end: its last checkpoint.
fn trained(config: &TrainConfig, data: &Path, out: &Path) -> PathBuf {
    train(config.clone(), options(data, out), open(data, config))
        .unwrap()
        .checkpoint
}

fn train_error(config: TrainConfig, data: &Path, out: &Path) -> TrainError {
    let set = open(data, &config);
    train(config, options(data, out), set).expect_err("the run fails")
}

#[test]
fn a_few_steps_lower_the_loss_and_the_checkpoint_round_trips() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("falls");
    let out = tmp.dir("falls-run");
    let config = config(16);
    let started = std::time::Instant::now();
    let summary = train(config.clone(), options(&data, &out), open(&data, &config)).unwrap();
    let wall = started.elapsed().as_secs_f64();
    assert_eq!(summary.steps_done, 16);
    // The throughput counts training only (no validation, no start-up): at least the samples
    // over the whole call's time, and not more than a thousand times that.
    let overall = (16 * config.batch_size) as f64 / wall;
    assert!(
        summary.samples_per_s >= overall && summary.samples_per_s < 1000.0 * overall,
        "{} samples/s reported, {overall:.1} over the whole call",
        summary.samples_per_s
    );
    let losses: Vec<f32> = step_lines(&out).iter().map(|s| s.loss).collect();
    assert_eq!(losses.len(), 16);
    let first: f32 = losses[..4].iter().sum();
    let last: f32 = losses[12..].iter().sum();
    assert!(last < 0.8 * first, "loss did not fall: {losses:?}");
    let validation = summary.validation.expect("validated at the end");
    assert!(validation.all.samples > 0);
    assert_eq!(validation.all.l2_m.len(), 3);
    assert!(
        validation.all.l2_m[1].is_some() && validation.all.l2_m[2].is_none(),
        "tiny plans 2 s"
    );
    // The fixture's frames all follow the lane: one situation, holding every sample.
    let follow = &validation.by_situation["follow"];
    assert_eq!(follow.samples, validation.all.samples);
    assert_eq!(follow.l2_m, validation.all.l2_m);
    // The hazard head (on by default) trains with the network and is validated.
    let hazard: Vec<f32> = step_lines(&out).iter().filter_map(|s| s.hazard).collect();
    assert_eq!(hazard.len(), 16);
    let (first, last): (f32, f32) = (hazard[..4].iter().sum(), hazard[12..].iter().sum());
    assert!(last < first, "the hazard loss did not fall: {hazard:?}");
    // A share of the validation samples: a whole number of them named right.
    let accuracy = validation.all.hazard_accuracy.expect("a hazard head");
    let named = accuracy as f64 * validation.all.samples as f64;
    assert!(
        (0.0..=1.0).contains(&accuracy) && (named - named.round()).abs() < 1e-3,
        "{accuracy} of {} samples",
        validation.all.samples
    );

    // The final checkpoint loads back into the same network, with the rig and notes.
    assert_eq!(summary.checkpoint, out.join("final.safetensors"));
    let (model, info) = checkpoint::load(&summary.checkpoint, &Device::flex()).unwrap();
    assert_eq!(info.config, config.model);
    assert!(info.metadata.contains_key("rig"));
    assert!(info.metadata["training"].contains("\"step\":16"));
    let (again, _) = checkpoint::load(
        &out.join("checkpoints/step-000015.safetensors"),
        &Device::flex(),
    )
    .unwrap();
    let input = common::model_input(&config.model, 2, 1, true, &Device::flex());
    let waypoints = |m: &ssr_agent::model::SsrModel| float_values(m.forward(&input).head.waypoints);
    assert_ne!(
        waypoints(&model),
        waypoints(&again),
        "step 15 and 16 differ"
    );
    let (reloaded, _) = checkpoint::load(&summary.checkpoint, &Device::flex()).unwrap();
    assert_eq!(waypoints(&model), waypoints(&reloaded));
}

#[test]
fn resuming_redraws_the_same_loss_curve() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("resume");
    // History dropout draws per sample too; a resumed run must redraw them.
    let config = TrainConfig {
        history_dropout: 0.5,
        ..config(6)
    };
    let straight = tmp.dir("resume-straight");
    train(
        config.clone(),
        options(&data, &straight),
        open(&data, &config),
    )
    .unwrap();

    let split = tmp.dir("resume-split");
    let first = TrainOptions {
        stop_at: Some(3),
        ..options(&data, &split)
    };
    let stopped = train(config.clone(), first, open(&data, &config)).unwrap();
    assert_eq!((stopped.steps_done, stopped.steps_run), (3, 3));
    let resumed = TrainOptions {
        resume: true,
        ..options(&data, &split)
    };
    let ignored = TrainConfig {
        lr: 1.0,
        ..config.clone()
    };
    let finished = train(ignored, resumed, open(&data, &config)).unwrap();
    assert_eq!((finished.steps_done, finished.steps_run), (6, 3));

    let (a, b) = (step_lines(&straight), step_lines(&split));
    assert_eq!(b.len(), 6, "no step is logged twice");
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.step, y.step);
        assert_eq!(x.lr, y.lr);
        let tolerance = 1e-4 * x.loss.abs().max(1.0);
        assert!(
            (x.loss - y.loss).abs() <= tolerance,
            "step {}: {} vs {}",
            x.step,
            x.loss,
            y.loss
        );
    }
}

#[test]
fn the_auxiliary_outputs_resume_with_the_run_and_can_be_left_out() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("probe");
    let config = config(4);
    let stop_at = |out: &Path| TrainOptions {
        stop_at: Some(3),
        ..options(&data, out)
    };
    let resume = |out: &Path| TrainOptions {
        resume: true,
        ..options(&data, out)
    };

    // The hazard and occupancy heads train by default: their losses are logged, validation
    // reports them, and the heads are in the checkpoints.
    let out = tmp.dir("probe-on");
    let done = train(config.clone(), options(&data, &out), open(&data, &config)).unwrap();
    assert!(
        step_lines(&out).iter().all(|s| {
            s.hazard.is_some_and(f32::is_finite) && s.occupancy.is_some_and(|v| v > 0.0)
        })
    );
    let validation = done.validation.unwrap();
    assert!(validation.all.hazard_accuracy.is_some());
    assert!(
        validation.occupancy_accuracy.contains_key("vehicle"),
        "{validation:?}"
    );
    let (model, _) = checkpoint::load(&done.checkpoint, &Device::flex()).unwrap();
    assert!(model.occupancy.is_some() && model.hazard.is_some());

    // Without its saved weights the run cannot go on as it was: the error names the file.
    let lost = tmp.dir("weights-lost");
    train(config.clone(), stop_at(&lost), open(&data, &config)).unwrap();
    std::fs::remove_file(lost.join("resume/model.bpk")).unwrap();
    let error = train(config.clone(), resume(&lost), open(&data, &config))
        .err()
        .unwrap();
    assert!(
        matches!(error, TrainError::Resume { .. }) && error.to_string().contains("model.bpk"),
        "{error}"
    );

    // A metrics history that cannot be read stops the resume and is left as it was.
    let unreadable = tmp.dir("metrics-unreadable");
    train(config.clone(), stop_at(&unreadable), open(&data, &config)).unwrap();
    let metrics = unreadable.join("metrics.jsonl");
    let mut history = std::fs::read(&metrics).unwrap();
    history.extend_from_slice(b"\xff\n");
    std::fs::write(&metrics, &history).unwrap();
    let error = train(config.clone(), resume(&unreadable), open(&data, &config))
        .err()
        .unwrap();
    assert!(error.to_string().contains("metrics.jsonl"), "{error}");
    assert_eq!(std::fs::read(&metrics).unwrap(), history);

    // Each head trains exactly when its loss has a weight.
    let mut untrained = config.clone();
    untrained.loss.occupancy = 0.0;
    let error = train_error(untrained, &data, &tmp.dir("head-untrained"));
    assert!(error.to_string().contains("occupancy_head"), "{error}");
    let mut untrained = config.clone();
    untrained.loss.hazard = 0.0;
    let error = train_error(untrained, &data, &tmp.dir("hazard-untrained"));
    assert!(error.to_string().contains("hazard_head"), "{error}");

    // Weight 0 and no head: no loss, nothing saved for them; the run still resumes.
    let mut plain = config.clone();
    plain.loss.hazard = 0.0;
    plain.loss.occupancy = 0.0;
    plain.model.occupancy_head = false;
    plain.model.hazard_head = false;
    let out = tmp.dir("probe-off");
    train(plain.clone(), stop_at(&out), open(&data, &plain)).unwrap();
    let done = train(plain.clone(), resume(&out), open(&data, &plain)).unwrap();
    assert_eq!(done.steps_done, 4);
    assert!(
        step_lines(&out)
            .iter()
            .all(|s| s.hazard.is_none() && s.occupancy.is_none())
    );
    let validation = done.validation.unwrap();
    assert_eq!(validation.all.hazard_accuracy, None);
    assert!(validation.occupancy_accuracy.is_empty());
    let (model, _) = checkpoint::load(&done.checkpoint, &Device::flex()).unwrap();
    assert!(model.occupancy.is_none() && model.hazard.is_none());

    // A fine-tune adds the heads to a checkpoint without them, the motion head (off by
    // default) when its loss has a weight: its loss is logged and validation reports it.
    assert!(model.motion.is_none() && step_lines(&out).iter().all(|s| s.motion.is_none()));
    let mut added = TrainConfig {
        init: Some(done.checkpoint),
        ..config.clone()
    };
    added.loss.motion = 1.0;
    added.model.motion_head = true;
    added.loss.light = 1.0;
    added.model.light_head = true;
    let out = tmp.dir("head-added");
    let tuned = train(added.clone(), options(&data, &out), open(&data, &added)).unwrap();
    let (model, _) = checkpoint::load(&tuned.checkpoint, &Device::flex()).unwrap();
    assert!(model.occupancy.is_some() && model.hazard.is_some() && model.motion.is_some());
    assert!(
        step_lines(&out)
            .iter()
            .all(|s| s.motion.is_some_and(|v| v > 0.0))
    );
    let validation = tuned.validation.unwrap();
    assert!(
        validation.motion_accuracy.contains_key("vehicle"),
        "{validation:?}"
    );
    // The light head too: the fixture's even routes record a red light ahead, the odd ones no
    // label; a loss on every step, and validation says how many red lights it calls red.
    assert!(model.light.is_some());
    assert!(
        step_lines(&out)
            .iter()
            .all(|s| s.light.is_some_and(f32::is_finite))
    );
    let recall = validation
        .light_red_recall
        .expect("red lights in validation");
    assert!((0.0..=1.0).contains(&recall), "{recall}");
    assert!(validation.light_accuracy.is_some());
}

#[test]
fn fine_tuning_starts_from_a_checkpoint_of_the_same_network() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("init");
    let config = config(8);
    let first = tmp.dir("init-first");
    let trained = trained(&config, &data, &first);

    // Step 1's loss is measured before the update: from the trained weights it is lower than
    // from fresh ones on the same batch.
    let first_loss = |init: Option<PathBuf>, name: &str| {
        let run = TrainConfig {
            init,
            ..config.clone()
        };
        let out = tmp.dir(name);
        let stop = TrainOptions {
            stop_at: Some(1),
            ..options(&data, &out)
        };
        train(run, stop, open(&data, &config)).unwrap();
        step_lines(&out)[0].loss
    };
    let fresh = first_loss(None, "init-fresh");
    let tuned = first_loss(Some(trained.clone()), "init-tuned");
    assert!(tuned < 0.8 * fresh, "fine-tune {tuned} vs fresh {fresh}");

    let mut other = config.clone();
    other.model.tokens.num_tokens += 1;
    other.init = Some(trained);
    let error = train_error(other, &data, &tmp.dir("init-other"));
    assert!(
        matches!(error, TrainError::Config(_)) && error.to_string().contains("tokens.num_tokens"),
        "{error}"
    );
    let missing = TrainConfig {
        init: Some(first.join("no-such.safetensors")),
        ..config.clone()
    };
    let error = train_error(missing, &data, &tmp.dir("init-missing"));
    assert!(error.to_string().contains("no-such.safetensors"), "{error}");
}

#[test]
fn a_fine_tuned_run_keeps_its_initial_checkpoints_controller_settings() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("control");
    let base = config(2);
    let fresh = trained(&base, &data, &tmp.dir("control-fresh"));
    let control_of =
        |path: &Path| checkpoint::control_config(&checkpoint::inspect(path).unwrap()).unwrap();
    assert_eq!(
        control_of(&fresh),
        ControlConfig::default(),
        "fresh weights"
    );
    let mut served = ControlConfig::default();
    served.safety.enabled = true;
    let init = tmp.dir("control-init").join("init.safetensors");
    checkpoint::with_control(&fresh, &init, &served, &Device::flex()).unwrap();

    // Stopped after a step and resumed: both halves write the initial checkpoint's settings.
    let run = TrainConfig {
        init: Some(init),
        ..base.clone()
    };
    let out = tmp.dir("control-run");
    let resumed = |stop_at: Option<u64>, resume: bool| {
        let options = TrainOptions {
            stop_at,
            resume,
            ..options(&data, &out)
        };
        train(run.clone(), options, open(&data, &run))
    };
    let first = resumed(Some(1), false).unwrap().checkpoint;
    assert_eq!(control_of(&first), served);
    assert_eq!(control_of(&resumed(None, true).unwrap().checkpoint), served);

    std::fs::write(out.join("control.json"), "{ not json").unwrap();
    let error = resumed(None, true).unwrap_err();
    assert!(error.to_string().contains("control.json"), "{error}");
}

#[test]
fn a_run_that_trains_only_a_head_keeps_the_rest_of_its_checkpoint() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("head-only");
    let base = config(3);
    let init = trained(&base, &data, &tmp.dir("head-only-init"));
    let mut only = TrainConfig {
        init: Some(init.clone()),
        train_only: vec![Head::Light],
        ..base.clone()
    };
    only.loss.light = 1.0;
    only.model.light_head = true;
    let out = tmp.dir("head-only-run");
    let done = train(only.clone(), options(&data, &out), open(&data, &only)).unwrap();
    assert!(
        step_lines(&out)
            .iter()
            .all(|s| s.light.is_some_and(f32::is_finite))
    );

    // The network drives as the checkpoint did (batch-norm statistics included), and has the
    // light head it did not.
    let device = Device::flex();
    let (before, _) = checkpoint::load(&init, &device).unwrap();
    let (after, _) = checkpoint::load(&done.checkpoint, &device).unwrap();
    let input = common::model_input(&only.model, 2, 1, true, &device);
    let plan =
        |model: &ssr_agent::model::SsrModel| float_values(model.forward(&input).head.waypoints);
    assert_eq!(common::max_abs_diff(plan(&before), plan(&after)), 0.0);
    assert!(before.light.is_none() && after.light.is_some());

    // It needs a checkpoint to keep, and heads the network has.
    let error = train_error(
        TrainConfig {
            init: None,
            ..only.clone()
        },
        &data,
        &tmp.dir("head-only-fresh"),
    );
    assert!(
        error.to_string().contains("train_only needs init"),
        "{error}"
    );
    let mut missing = only.clone();
    missing.model.light_head = false;
    missing.loss.light = 0.0;
    let error = train_error(missing, &data, &tmp.dir("head-only-missing"));
    assert!(error.to_string().contains("Light head"), "{error}");
}

#[test]
fn an_ablation_starts_from_a_checkpoints_perception() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("perception");
    let config = config(8);
    let trained = trained(&config, &data, &tmp.dir("perception-first"));

    // Another token count, no FFP, a learning rate too small to move a weight: the checkpoint
    // of its first step holds the start, whose BEV encoder is the trained network's (the
    // backbone's batch statistics move in a step, so the encoders get the same features).
    let mut variant = config.clone();
    variant.model.tokens.num_tokens += 1;
    variant.future_bev = false;
    variant.lr = 1e-20;
    let device = Device::flex();
    let start_of = |init_perception: Option<PathBuf>, name: &str| {
        let run = TrainConfig {
            init_perception,
            ..variant.clone()
        };
        let stop = TrainOptions {
            stop_at: Some(1),
            ..options(&data, &tmp.dir(name))
        };
        let summary = train(run, stop, open(&data, &variant)).unwrap();
        checkpoint::load(&summary.checkpoint, &device).unwrap().0
    };
    let (reference, _) = checkpoint::load(&trained, &device).unwrap();
    let input = common::model_input(&variant.model, 2, 1, true, &device);
    let features = reference.image_features(input.images.clone());
    let bev = |model: &ssr_agent::model::SsrModel| {
        float_values(model.encode_bev(features.clone(), &input))
    };
    let shared = start_of(Some(trained.clone()), "perception-shared");
    let fresh = start_of(None, "perception-fresh");
    assert_eq!(common::max_abs_diff(bev(&shared), bev(&reference)), 0.0);
    assert!(common::max_abs_diff(bev(&fresh), bev(&reference)) > 1e-3);
    let tokens = shared.forward(&input).scene.tokens.dims()[1];
    assert_eq!(tokens, variant.model.tokens.num_tokens);

    // The perception itself must match; a run starts from one checkpoint.
    let mut other = variant.clone();
    other.model.channels += 8;
    other.init_perception = Some(trained.clone());
    let error = train_error(other, &data, &tmp.dir("perception-other"));
    assert!(
        matches!(error, TrainError::Config(_)) && error.to_string().contains("channels"),
        "{error}"
    );
    let both = TrainConfig {
        init: Some(trained.clone()),
        init_perception: Some(trained),
        ..config.clone()
    };
    let error = train_error(both, &data, &tmp.dir("perception-both"));
    assert!(error.to_string().contains("exclusive"), "{error}");
}

#[test]
fn a_dropped_history_trains_the_first_frame_path() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("dropout");
    let config = config(1);
    let set = open(&data, &config);
    let with_history: Vec<_> = set
        .train
        .iter()
        .filter(|s| s.frame >= 1)
        .take(2)
        .copied()
        .collect();
    let device = Device::flex();
    let model = config.model.init(&device);
    let waypoints = |drop_history: bool, history_value: f32| {
        let batch = set
            .batch(&with_history, &config.model, History::Chain, |_| {
                SampleDraw {
                    drop_history,
                    ..SampleDraw::default()
                }
            })
            .unwrap();
        let shape = [2, config.model.bev.grid.cells(), config.model.channels];
        let history = Tensor::full(shape, history_value, &device);
        float_values(
            model
                .forward(&batch.current_input(&config.model, history, &device))
                .head
                .waypoints,
        )
    };
    assert_ne!(
        waypoints(false, 0.0),
        waypoints(false, 1.0),
        "the history is read"
    );
    assert_eq!(
        waypoints(true, 0.0),
        waypoints(true, 1.0),
        "dropped, it is not"
    );

    let error = TrainConfig {
        history_dropout: 1.5,
        ..config.clone()
    }
    .validate()
    .unwrap_err();
    assert!(
        error.contains("history_dropout must be in [0, 1]"),
        "{error}"
    );
}

#[test]
fn a_later_target_is_the_followers_target_of_a_later_frame_in_the_samples_own_frame() {
    let tmp = Scratch::new();
    let data = tmp.fixture("later");
    let config = config(2);
    let set = open(&data, &config);
    // The fixture drives straight along x at 2 + route m/s, 2 frames a second, its target point
    // always 30 m ahead: a later frame's target lies 30 m + the distance driven meanwhile ahead.
    let last_frames = (FIXTURE_FRAMES - 6) as u32;
    let early = *set.train.iter().find(|s| s.frame == 0).unwrap();
    let late = *set.train.iter().find(|s| s.frame >= last_frames).unwrap();
    let target = |sample, later_target| {
        let batch = set
            .batch(&[sample], &config.model, History::Chain, |_| SampleDraw {
                later_target,
                ..SampleDraw::default()
            })
            .unwrap();
        let device = Device::flex();
        let shape = [1, config.model.bev.grid.cells(), config.model.channels];
        let input = batch.current_input(&config.model, Tensor::zeros(shape, &device), &device);
        float_values(input.navigation.target_point)
    };
    assert_eq!(target(early, None), vec![30.0, 0.0]);
    // The whole window, 3 s later, at one of the fixture's speeds; half of it, 1.5 s.
    let whole = target(early, Some(1.0));
    let speed = (whole[0] - 30.0) / 3.0;
    assert!(
        (0..FIXTURE_ROUTES).any(|route| speed == 2.0 + route as f32),
        "{whole:?}"
    );
    assert_eq!(whole[1], 0.0);
    assert_eq!(target(early, Some(0.5)), vec![30.0 + 1.5 * speed, 0.0]);
    // Too near the episode's end for a frame 3 s later: its own target.
    assert_eq!(target(late, Some(1.0)), vec![30.0, 0.0]);

    let error = TrainConfig {
        later_target: -0.1,
        ..config.clone()
    }
    .validate()
    .unwrap_err();
    assert!(error.contains("later_target must be in [0, 1]"), "{error}");
}

#[test]
fn a_link_trains_without_the_frame_1_s_back_and_its_checkpoints_are_served_so() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let data = tmp.fixture("link");
    let mut config = config(2);
    config.history = History::Link;
    let set = open(&data, &config);
    let deep: Vec<_> = set
        .train
        .iter()
        .filter(|s| s.frame >= 2)
        .take(2)
        .copied()
        .collect();
    let deep_frames = |history| {
        let batch = set
            .batch(&deep, &config.model, history, |_| SampleDraw::default())
            .unwrap();
        let images = batch.deep_input(&config.model, &Device::flex()).images;
        float_values(images.abs().sum())[0]
    };
    assert!(deep_frames(History::Chain) > 0.0, "the chain reads it");
    assert_eq!(deep_frames(History::Link), 0.0, "the link does not");

    let out = tmp.dir("link-run");
    let summary = train(config.clone(), options(&data, &out), set).unwrap();
    let info = checkpoint::inspect(&summary.checkpoint).unwrap();
    assert_eq!(checkpoint::history(&info), Ok(History::Link));

    config.history = History::Recursive;
    let error = config.validate().unwrap_err();
    assert!(error.contains("history must be chain or link"), "{error}");
}

#[test]
fn labels_come_from_the_plan_or_the_driven_path_and_datasets_without_plans_are_refused() {
    let tmp = Scratch::new();
    let data = tmp.fixture("labels");
    let mut config = config(1);
    let lateral = |config: &TrainConfig| {
        let set = open(&data, config);
        let batch = set
            .batch(&set.train[..1], &config.model, History::Chain, |_| {
                SampleDraw::default()
            })
            .unwrap();
        batch.waypoints[1]
    };
    assert_eq!(config.labels, Labels::Plan, "the plan by default");
    // A run's config written before plans were labels names none: its labels were driven.
    let mut before = serde_json::to_value(&config).unwrap();
    before.as_object_mut().unwrap().remove("labels");
    let before: TrainConfig = serde_json::from_value(before).unwrap();
    assert_eq!(before.labels, Labels::Driven);
    assert_eq!(lateral(&config), 0.25, "the fixture's plan");
    config.labels = Labels::Driven;
    assert_eq!(lateral(&config), 0.0, "where the fixture's car went");

    // A dataset recorded before plans were stored: the plan is refused with the way out.
    let episode = std::fs::read_dir(data.join("episodes"))
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let lines = episode.join("measurements.jsonl");
    let text = std::fs::read_to_string(&lines).unwrap();
    let old: String = text
        .lines()
        .map(|line| {
            let mut record: serde_json::Value = serde_json::from_str(line).unwrap();
            record.as_object_mut().unwrap().remove("plan");
            format!("{record}\n")
        })
        .collect();
    std::fs::write(&lines, old).unwrap();
    let error = open_error(&data, &config.model);
    assert!(
        error.contains("plan") && error.contains("--labels driven"),
        "{error}"
    );
    assert!(TrainingData::open(&data, &config.model, Labels::Driven, 0.1, |_, _| {}).is_ok());
}

#[test]
fn routes_split_whole_and_samples_need_a_future() {
    let tmp = Scratch::new();
    let data = tmp.fixture("split");
    let config = config(1);
    let set = TrainingData::open(&data, &config.model, config.labels, 0.5, |_, _| {}).unwrap();
    assert_eq!(set.train_routes + set.validation_routes, FIXTURE_ROUTES);
    assert!(set.train_routes > 0 && set.validation_routes > 0);
    let episodes = |samples: &[ssr_agent::train::data::SampleRef]| {
        samples
            .iter()
            .map(|s| s.episode)
            .collect::<std::collections::BTreeSet<_>>()
    };
    assert!(episodes(&set.train).is_disjoint(&episodes(&set.validation)));
    // 10 frames at 2 Hz: the last 3 have no frame 1.5 s ahead.
    assert_eq!(set.train.len() + set.validation.len(), FIXTURE_ROUTES * 7);
    let none = TrainingData::open(&data, &config.model, config.labels, 0.0, |_, _| {}).unwrap();
    assert_eq!(none.validation.len(), 0);
}

/// Why `TrainingData::open` refused `data`.
fn open_error(data: &Path, model: &SsrConfig) -> String {
    TrainingData::open(data, model, Labels::Plan, 0.1, |_, _| {})
        .err()
        .expect("the dataset is refused")
        .to_string()
}

/// Replaces the first `from` in the file at `path` by `to`.
fn edit(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(from), "{} has no {from}", path.display());
    std::fs::write(path, text.replacen(from, to, 1)).unwrap();
}

/// Without the `wgpu` feature a GPU run is refused before anything is written, naming the
/// feature that gives one.
#[cfg(not(feature = "wgpu"))]
#[test]
fn a_gpu_run_on_a_build_without_wgpu_says_how_to_get_one() {
    let tmp = Scratch::new();
    let config = config(2);
    let data = tmp.fixture("data");
    let out = tmp.0.path().join("gpu-run");
    let gpu = TrainOptions {
        backend: Backend::Wgpu,
        ..options(&data, &out)
    };
    let error = train(config.clone(), gpu, open(&data, &config)).expect_err("refused");
    assert!(
        matches!(error, TrainError::Backend(_)) && error.to_string().contains("--features wgpu"),
        "{error}"
    );
    assert!(!out.exists(), "nothing is written for a refused run");
}

#[test]
fn bad_datasets_and_run_folders_are_named() {
    let _rng = device_rng();
    let tmp = Scratch::new();
    let config = config(2);
    let error = open_error(&tmp.dir("missing"), &config.model);
    assert!(error.contains("manifest.json"), "{error}");

    let broken = tmp.fixture("broken-line");
    edit(
        &broken.join("episodes/fixture__fixture__2__r0/measurements.jsonl"),
        "{\"index\":3",
        "{\"index\":oops",
    );
    let error = open_error(&broken, &config.model);
    assert!(
        error.contains("measurements.jsonl") && error.contains("line 4"),
        "{error}"
    );

    let mut finer = config.model.clone();
    finer.image_width *= 2;
    let error = open_error(&tmp.fixture("coarse"), &finer);
    assert!(
        error.contains("64x32 frames, smaller than the network's 128x32 input"),
        "{error}"
    );

    let mut far = config.clone();
    far.model.head.pred_len = 8;
    let error = open_error(&tmp.fixture("far"), &far.model);
    assert!(error.contains("plans 8"), "{error}");

    // At 0.5 Hz there is no frame 0.5 s back to be the history.
    let slow = tmp.fixture("slow");
    edit(
        &slow.join("manifest.json"),
        "\"rate_hz\": 2.0",
        "\"rate_hz\": 0.5",
    );
    let error = open_error(&slow, &config.model);
    assert!(
        error.contains("rate_hz = 0.5 gives no frame 0.5 s back"),
        "{error}"
    );

    // A missing image stops training with its path; what was written so far stays.
    let holes = tmp.fixture("holes");
    for route in 0..FIXTURE_ROUTES {
        let _ = std::fs::remove_file(holes.join(format!(
            "episodes/fixture__fixture__{route}__r0/cam0/000004.png"
        )));
    }
    let out = tmp.dir("holes-run");
    let mut long = config.clone();
    long.steps = 40;
    let error = train_error(long, &holes, &out);
    assert!(
        matches!(error, TrainError::Dataset(_)) && error.to_string().contains("000004.png"),
        "{error}"
    );
    assert!(out.join("train_config.json").exists());

    let empty = tmp.dir("no-resume");
    let resume = TrainOptions {
        resume: true,
        ..options(&holes, &empty)
    };
    let error = train(config.clone(), resume, open(&holes, &config))
        .err()
        .unwrap();
    assert!(
        matches!(error, TrainError::Resume { .. }) && error.to_string().contains("progress.json"),
        "{error}"
    );

    let mut bad = config.clone();
    bad.batch_size = 0;
    let error = train_error(bad, &holes, &tmp.dir("bad-config"));
    assert!(error.to_string().contains("batch_size"), "{error}");
}

#[test]
fn schedule_actions_and_augmentation() {
    let mut config = TrainConfig::new(tiny_config(), 100);
    config.warmup_steps = 10;
    config.lr = 1e-3;
    assert!((config.lr_at(0) - 1e-4).abs() < 1e-12);
    assert!((config.lr_at(9) - 1e-3).abs() < 1e-12);
    assert!(
        (config.lr_at(99) - 1e-3 * 0.05).abs() < 1e-6,
        "{}",
        config.lr_at(99)
    );
    config.schedule = Schedule::Step {
        every: 30,
        gamma: 0.5,
    };
    assert!((config.lr_at(45) - 5e-4).abs() < 1e-12);

    let brake = Control {
        steer: 0.3,
        throttle: 0.0,
        brake: 0.7,
    };
    assert_eq!(action_of(&brake), [-0.7, 0.3]);
    let drive = Control {
        steer: -0.1,
        throttle: 0.6,
        brake: 0.0,
    };
    assert_eq!(action_of(&drive), [0.6, -0.1]);

    let mut rgb: Vec<u8> = (0..300).map(|i| (i % 256) as u8).collect();
    let original = rgb.clone();
    Photometric::draw(7, 0.0).apply(&mut rgb);
    assert_eq!(rgb, original, "strength 0 is the identity");
    let jitter = Photometric::draw(7, 1.0);
    assert_eq!(jitter, Photometric::draw(7, 1.0), "seeded");
    jitter.apply(&mut rgb);
    assert_ne!(rgb, original);
}
