//! `ssr-agent bench`: forward latency (median of timed runs after warm-up) with the per-stage
//! breakdown of the paper's latency analysis (and the occupancy head, where the network has
//! one), a full policy step from the rig's frames (TCP's one 900x256 camera by default; safety
//! stop on, where it can be), and optionally a training step, plus parameter counts and
//! per-episode state memory.

use std::time::Instant;

use anyhow::Context as _;
use burn::module::Module;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Distribution, Tensor};
use ssr_agent::control::ControlConfig;
use ssr_agent::device::Backend;
use ssr_agent::history::History;
use ssr_agent::model::bev::{GeometryTensors, HISTORY_TICKS, SampleGeometry};
use ssr_agent::model::config::SsrConfig;
use ssr_agent::model::{ModelInput, Navigation, SsrModel, float_tensor};
use ssr_agent::policy::{SsrPolicy, StepInput};
use ssr_agent::pose::{EgoMotion, Pose2};
use ssr_agent::train::loss::{AuxiliaryLosses, BetaTargets, ImitationTargets, LossWeights, losses};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::command::{COMMANDS, RoadOption};
use ssrdrive_proto::image::RgbImage;

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Model config: a preset (cpu-default, paper) or a JSON file. Default: the standard set.
    #[arg(long)]
    config: Option<String>,
    /// Episodes per forward pass (with --config).
    #[arg(long, default_value_t = 1)]
    batch: usize,
    /// Timed runs per measurement (the median is reported).
    #[arg(long, default_value_t = 20)]
    iterations: usize,
    /// Untimed runs first.
    #[arg(long, default_value_t = 3)]
    warmup: usize,
    /// Also time a training step (forward + FFP + losses + backward + AdamW) at --train-batch,
    /// with --rig's cameras.
    #[arg(long)]
    train: bool,
    #[arg(long, default_value_t = 8)]
    train_batch: usize,
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    backend: Backend,
    /// The cameras the network sees: a preset (tcp, tcp-small) or a JSON rig file (a list of
    /// CARLA-style camera descriptions). Every camera's image goes through the backbone, so a
    /// rig of three costs about three backbone passes a step.
    #[arg(long, default_value = "tcp")]
    rig: String,
    /// Print one JSON object per measurement instead of a table.
    #[arg(long)]
    json: bool,
}

fn median(mut samples: Vec<f64>) -> f64 {
    samples.sort_by(f64::total_cmp);
    samples[samples.len() / 2]
}

/// Median milliseconds of `f` after `warmup` untimed runs; `f` must finish its device work.
fn time_ms(warmup: usize, iterations: usize, mut f: impl FnMut()) -> f64 {
    for _ in 0..warmup {
        f();
    }
    median(
        (0..iterations.max(1))
            .map(|_| {
                let start = Instant::now();
                f();
                start.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

/// A batch seen by `rig`'s cameras, with a previous BEV and a small ego motion, random images.
fn model_input(config: &SsrConfig, batch: usize, rig: &Rig, device: &Device) -> ModelInput {
    let grid = config.bev.grid;
    let motion = EgoMotion {
        dx: 0.4,
        dy: 0.0,
        dyaw: 0.01,
    };
    let geometry: Vec<SampleGeometry> = (0..batch)
        .map(|_| {
            SampleGeometry::new(
                &grid,
                &config.bev.pillar_heights,
                rig,
                Some(motion),
                Some(6.0),
            )
        })
        .collect();
    let command: Vec<f32> = (0..batch)
        .flat_map(|_| RoadOption::LaneFollow.one_hot())
        .collect();
    ModelInput {
        images: Tensor::random(
            [
                batch * rig.cameras.len(),
                3,
                config.image_height,
                config.image_width,
            ],
            Distribution::Normal(0.0, 1.0),
            device,
        ),
        cameras: rig.cameras.len(),
        geometry: GeometryTensors::batch(&geometry, &grid, config.bev.pillar_heights.len(), device),
        previous_bev: Tensor::random(
            [batch, grid.cells(), config.channels],
            Distribution::Normal(0.0, 1.0),
            device,
        ),
        navigation: Navigation {
            speed: Tensor::full([batch, 1], 6.0, device),
            target_point: float_tensor([12.0, 1.0].repeat(batch), [batch, 2], device),
            command: float_tensor(command, [batch, COMMANDS], device),
        },
    }
}

struct Report {
    config: String,
    batch: usize,
    rows: Vec<(&'static str, f64)>,
}

impl Report {
    fn print(&self, json: bool) {
        if json {
            let fields: serde_json::Map<String, serde_json::Value> = self
                .rows
                .iter()
                .map(|(k, v)| (k.to_string(), serde_json::json!(v)))
                .collect();
            println!(
                "{}",
                serde_json::json!({"framework": "burn", "config": self.config, "batch": self.batch, "results": fields})
            );
        } else {
            println!("{} batch {}", self.config, self.batch);
            for (name, value) in &self.rows {
                println!("  {name:<28} {value:>10.2}");
            }
        }
    }
}

fn sync(device: &Device) {
    device.sync().expect("device work completes");
}

fn bench_forward(
    config: &SsrConfig,
    batch: usize,
    rig: &Rig,
    args: &BenchArgs,
    device: &Device,
) -> Report {
    let model = config.init(device).valid();
    let input = model_input(config, batch, rig, device);
    let (w, i) = (args.warmup, args.iterations);
    let features = model.image_features(input.images.clone());
    let bev = model.encode_bev(features.clone(), &input);
    let scene = model.stl.forward(
        bev.clone(),
        model.bev.positions(),
        input.navigation.command.clone(),
        input.navigation.target_point.clone(),
    );
    let mut rows = vec![
        ("params", model.num_params() as f64),
        (
            "forward_ms",
            time_ms(w, i, || {
                let out = model.forward(&input);
                let _ = out.head.alpha.into_data();
            }),
        ),
        (
            "backbone_ms",
            time_ms(w, i, || {
                model.image_features(input.images.clone());
                sync(device);
            }),
        ),
        (
            "bev_encoder_ms",
            time_ms(w, i, || {
                model.encode_bev(features.clone(), &input);
                sync(device);
            }),
        ),
        (
            "stl_ms",
            time_ms(w, i, || {
                model.stl.forward(
                    bev.clone(),
                    model.bev.positions(),
                    input.navigation.command.clone(),
                    input.navigation.target_point.clone(),
                );
                sync(device);
            }),
        ),
        (
            "head_ms",
            time_ms(w, i, || {
                model.head.forward(
                    scene.tokens.clone(),
                    input.navigation.speed.clone(),
                    input.navigation.target_point.clone(),
                    input.navigation.command.clone(),
                );
                sync(device);
            }),
        ),
    ];
    if let Some(occupancy) = &model.occupancy {
        rows.push((
            "occupancy_head_ms",
            time_ms(w, i, || {
                occupancy.forward(bev.clone());
                sync(device);
            }),
        ));
    }
    if batch == 1 {
        rows.extend(policy_step_rows(model, config, rig, (w, i), device));
    }
    Report {
        config: config.name.clone(),
        batch,
        rows,
    }
}

/// A whole policy step (decode, encoders, heads, controller) as served, from one frame per
/// camera of `rig`, in the steady state of each history, and the memory an episode holds. Its
/// rows are named after TCP's 900x256 camera for that rig, `policy_step_rig_*` for another.
fn policy_step_rows(
    model: SsrModel,
    config: &SsrConfig,
    rig: &Rig,
    (w, i): (usize, usize),
    device: &Device,
) -> Vec<(&'static str, f64)> {
    let mut rows = Vec::new();
    // As served: a network with the occupancy head runs it every step for the safety stop.
    let mut control = ControlConfig::default();
    control.safety.enabled = model.occupancy.is_some();
    let policy = SsrPolicy::new(model, config.clone(), control, device.clone());
    let frames: Vec<RgbImage> = rig
        .cameras
        .iter()
        .map(|camera| RgbImage {
            width: camera.width,
            height: camera.height,
            rgb: (0..camera.width * camera.height * 3)
                .map(|k| ((k * 2654435761) >> 24) as u8)
                .collect(),
        })
        .collect();
    let names = if *rig == Rig::tcp() {
        [
            "policy_step_900x256_ms",
            "policy_step_900x256_link_ms",
            "policy_step_900x256_recursive_ms",
        ]
    } else {
        [
            "policy_step_rig_ms",
            "policy_step_rig_link_ms",
            "policy_step_rig_recursive_ms",
        ]
    };
    // Timed in the steady state, where the episode has its history (the first steps of an
    // episode encode one BEV; later ones three on the chain, two on the link, one on the
    // recursion).
    for (history, row) in [History::Chain, History::Link, History::Recursive]
        .into_iter()
        .zip(names)
    {
        let mut episode = policy.new_episode_with_history(history);
        let mut tick = 0;
        let mut step_once = || {
            tick += 1;
            let input = StepInput {
                frames: frames.clone(),
                rig: rig.clone(),
                pose: Pose2::new(0.3 * tick as f32, 0.0, 0.0),
                speed: 6.0,
                command: RoadOption::LaneFollow,
                target_point: [12.0, 1.0],
                debug: false,
            };
            policy.step(&mut episode, &input).expect("valid input");
        };
        (0..HISTORY_TICKS).for_each(|_| step_once());
        rows.push((row, time_ms(w, i, step_once)));
    }
    rows.push(("episode_state_bytes", policy.episode_state_bytes() as f64));
    rows
}

fn bench_train(
    config: &SsrConfig,
    batch: usize,
    rig: &Rig,
    args: &BenchArgs,
    device: &Device,
) -> Report {
    let device = device.clone().autodiff();
    let mut model = config.init(&device);
    let mut optimizer = AdamWConfig::new().with_weight_decay(0.01).init();
    let input = model_input(config, batch, rig, &device);
    let p = config.head.pred_len;
    let targets = ImitationTargets {
        waypoints: Tensor::random([batch, p, 2], Distribution::Normal(0.0, 3.0), &device),
        actions: BetaTargets::new(&vec![0.2; batch * (p + 1) * 2], batch, p + 1, 10.0, &device),
        speed: Tensor::full([batch, 1], 5.0, &device),
    };
    let grid = config.bev.grid;
    let future = Tensor::random(
        [batch, grid.cells(), config.channels],
        Distribution::Normal(0.0, 1.0),
        &device,
    );
    let weights = LossWeights::default();
    // Each phase ends with its device work done, so the phases add up to the step.
    let mut phases: [Vec<f64>; 3] = Default::default();
    let warmup = args.warmup.min(2);
    for run in 0..warmup + args.iterations.clamp(1, 5) {
        let mut lap = Instant::now();
        let mut record = |phase: usize| {
            sync(&device);
            if run >= warmup {
                phases[phase].push(lap.elapsed().as_secs_f64() * 1e3);
            }
            lap = Instant::now();
        };
        let output = model.forward(&input);
        let predicted = model.predict_future_bev(&output);
        let loss = losses(
            &output.head,
            &targets,
            Some((predicted, future.clone())),
            AuxiliaryLosses::default(),
            &weights,
        );
        record(0);
        let grads = GradientsParams::from_grads(loss.total.backward(), &model);
        record(1);
        model = optimizer.step(1e-4, model.clone(), grads);
        record(2);
    }
    let steps: Vec<f64> = (0..phases[0].len())
        .map(|k| phases[0][k] + phases[1][k] + phases[2][k])
        .collect();
    let [forward, backward, optimizer] = phases.map(median);
    Report {
        config: config.name.clone(),
        batch,
        rows: vec![
            ("train_step_ms", median(steps)),
            ("train_forward_loss_ms", forward),
            ("train_backward_ms", backward),
            ("train_optimizer_ms", optimizer),
        ],
    }
}

pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    let device = args.backend.device()?;
    let rig = Rig::from_name_or_file(&args.rig).context("--rig")?;
    rig.validate()
        .map_err(|e| anyhow::anyhow!("--rig {}: {e}", args.rig))?;
    let runs: Vec<(SsrConfig, usize)> = match &args.config {
        Some(spec) => vec![(
            SsrConfig::from_name_or_file(spec).context("--config")?,
            args.batch,
        )],
        None => vec![
            (SsrConfig::cpu_default(), 1),
            (SsrConfig::cpu_default(), 8),
            (SsrConfig::paper(), 1),
        ],
    };
    if !args.json {
        println!(
            "ssr-agent bench: backend {:?}, rig {} ({} cameras), {} threads, median of {} runs after {} warm-up (ms)",
            args.backend,
            args.rig,
            rig.cameras.len(),
            std::thread::available_parallelism()
                .map(|n| n.get())
                .unwrap_or(1),
            args.iterations,
            args.warmup
        );
    }
    for (config, batch) in &runs {
        bench_forward(config, *batch, &rig, args, &device).print(args.json);
    }
    if args.train {
        let config = &runs[0].0;
        bench_train(config, args.train_batch, &rig, args, &device).print(args.json);
    }
    Ok(())
}
