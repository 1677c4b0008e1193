//! `ssr-agent train`: flags to a [`TrainConfig`], the dataset index, the run and its summary.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Context as _;
use clap::{Args, ValueEnum};
use ssr_agent::checkpoint;
use ssr_agent::device::Backend;
use ssr_agent::history::History;
use ssr_agent::model::config::{BackboneConfig, SsrConfig};
use ssr_agent::train::config::{Head, Schedule, TrainConfig};
use ssr_agent::train::data::{Labels, TrainingData};
use ssr_agent::train::run::{self, TrainOptions};
use ssr_agent::train::validation::format_l2;

#[derive(Debug, Clone, Copy, ValueEnum)]
enum ScheduleKind {
    Cosine,
    Step,
}

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Dataset folder written by `sim-bridge collect` (holds manifest.json).
    #[arg(long)]
    data: PathBuf,
    /// Run folder: config, metrics.jsonl, checkpoints/, final.safetensors, resume/.
    #[arg(long, default_value = "runs/train")]
    out: PathBuf,
    /// Continue the run in --out from its last checkpoint (with its own settings; only
    /// --stop-at, --backend and --quiet apply).
    #[arg(long)]
    resume: bool,
    /// Where the network trains: the CPU (all cores), or a GPU through wgpu (a build with
    /// `--features wgpu`). A run may resume on the other.
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    backend: Backend,
    /// Stop after this step with a checkpoint, keeping the schedule of --steps (split a run
    /// over several sittings, then --resume).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    stop_at: Option<u64>,
    /// Model preset (cpu-default, paper) or a JSON config file.
    #[arg(long, default_value = "cpu-default")]
    model: String,
    /// Start from this checkpoint's weights and network (fine-tuning) instead of fresh
    /// weights; for example agent/models/ssr-cpu-default.safetensors, the bundled one.
    #[arg(long, conflicts_with_all = ["model", "no_stl", "tokens"])]
    init: Option<PathBuf>,
    /// With --init: grow the checkpoint's image backbone to these blocks per stage
    /// (comma-separated, one per stage, none fewer than the checkpoint's; e.g. 2,3,4,3 for the
    /// cpu-default's 1,1,2,1). The new blocks start as the identity, so the run starts from the
    /// checkpoint's driving with a deeper trunk: a capacity experiment without training from
    /// scratch. The run's model is named after the growth (cpu-default-blocks-2-3-4-3).
    #[arg(long, requires = "init", value_delimiter = ',')]
    deepen_backbone: Option<Vec<usize>>,
    /// With --init: train the checkpoint's network at this camera input size, WIDTHxHEIGHT
    /// (e.g. 416x128 for the cpu-default's 320x96). No weight depends on the size (the trunk is
    /// convolutional and the BEV encoder samples its features at projected points), so the run
    /// starts from the checkpoint's weights and sees finer frames: the input-size capacity
    /// experiment. Record the data at that size (`sim-bridge collect --rig`); the run's model is
    /// named after it (cpu-default-input-416x128).
    #[arg(long, requires = "init", value_parser = parse_input_size)]
    input_size: Option<(usize, usize)>,
    /// Start a fresh network of --model and the ablation flags from this checkpoint's
    /// perception (backbone, BEV encoder, occupancy head), drawing the scene tokens, heads and
    /// FFP from --seed: the ablations' shared start (agent/ablation/ablate.py).
    #[arg(long, conflicts_with = "init")]
    init_perception: Option<PathBuf>,
    /// Optimiser steps of the whole run.
    #[arg(long, default_value_t = 4000)]
    steps: u64,
    #[arg(long, default_value_t = 8)]
    batch_size: usize,
    /// Peak learning rate (AdamW).
    #[arg(long, default_value_t = 3e-4)]
    lr: f64,
    #[arg(long, default_value_t = 1e-2)]
    weight_decay: f32,
    /// Steps of linear warm-up.
    #[arg(long, default_value_t = 300)]
    warmup_steps: u64,
    /// Decay after the warm-up: cosine to 5 % of --lr, or step (x --step-gamma every
    /// --step-every steps).
    #[arg(long, value_enum, default_value = "cosine")]
    schedule: ScheduleKind,
    #[arg(long, default_value_t = 1000)]
    step_every: u64,
    #[arg(long, default_value_t = 0.5)]
    step_gamma: f64,
    /// Per-parameter gradient norm clip (0 = none).
    #[arg(long, default_value_t = 1.0)]
    clip_norm: f32,
    /// Photometric jitter strength (0 = none).
    #[arg(long, default_value_t = 1.0)]
    augment: f32,
    /// Share of samples (0 to 1) trained without history BEV and ego motion, as on an
    /// episode's first tick, so the network cannot just repeat what the expert was doing.
    #[arg(long, default_value_t = 0.0)]
    history_dropout: f64,
    /// Share of samples (0 to 1) shown the target point the route follower gave up to 3 s
    /// later (the next plan node, past one), their labels unchanged: against driving the
    /// straight line to the target across a bend or a loop.
    #[arg(long, default_value_t = 0.0)]
    later_target: f64,
    /// The history the network trains with, written into its checkpoints as their serving
    /// setting: `chain` (the frame 0.5 s back attending to the frame 1 s back; served with
    /// three BEV passes a step) or `link` (the frame 0.5 s back on its own; two passes, about
    /// a third less time a step, and a training step without the frame 1 s back).
    #[arg(long, default_value = "chain")]
    history: History,
    /// Waypoint labels: the expert's plan from each frame's state, or the positions it went on
    /// to drive (perturbations included).
    #[arg(long, value_enum, default_value = "plan")]
    labels: Labels,
    /// Draw samples uniformly instead of by weight (standstills down; starts, turns, lane
    /// changes and perturbed frames up).
    #[arg(long)]
    uniform_sampling: bool,
    /// Show the network the ego's speed and motion (the copycat shortcut; off by default: the
    /// speed is then only an auxiliary prediction).
    #[arg(long, conflicts_with = "init")]
    ego_status: bool,
    /// Weight of the future-BEV loss (SSR: 1).
    #[arg(long, default_value_t = 1.0)]
    bev_weight: f32,
    /// Weight of the hazard head's loss: a classifier of what the expert brakes for (a light, a
    /// sign, a road user, a lane change, or nothing) from the scene tokens, part of the network
    /// and its checkpoints (the unstick rule creeps early while it says "clear"). Fine-tuning a
    /// checkpoint without the head adds one; 0 = no head.
    #[arg(long, default_value_t = 0.5)]
    hazard_weight: f32,
    /// Weight of the occupancy head's loss: a per-cell classifier of where the road users are,
    /// from the BEV, part of the network and its checkpoints (labels: the actors each frame
    /// records; frames of datasets from before that are left out of it). Fine-tuning a
    /// checkpoint without the head adds one; 0 = no head.
    #[arg(long, default_value_t = 1.0)]
    occupancy_weight: f32,
    /// Weight of the motion head's loss: the occupancy head's twin for where the road users
    /// will be 1.5 s later (labels: the future frame's actors, in this frame's ego frame), part
    /// of the network and its checkpoints; the safety stop can read it (`safety.motion`).
    /// Fine-tuning a checkpoint without the head adds one; 0 = no head.
    #[arg(long, default_value_t = 0.0)]
    motion_weight: f32,
    /// Weight of the light head's loss: a classifier of the state of the light ahead (none
    /// within 40 m, green, yellow, red) from the scene tokens (labels: the light each frame
    /// records; frames of datasets from before that are left out of it), part of the network
    /// and its checkpoints. Fine-tuning a checkpoint without the head adds one; 0 = no head.
    #[arg(long, default_value_t = 0.0)]
    light_weight: f32,
    /// Train only these heads (comma-separated: hazard, occupancy, motion, light); the rest of
    /// the network keeps the weights of --init, so it drives as that checkpoint did while the
    /// new heads feed the controller (a light head for the unstick rule's light hold, say).
    #[arg(long, value_enum, value_delimiter = ',', requires = "init")]
    train_only: Vec<Head>,
    /// Ablation: no Scenes TokenLearner; the head attends over every BEV cell.
    #[arg(long)]
    no_stl: bool,
    /// Ablation: no Future Feature Predictor and no BEV loss.
    #[arg(long)]
    no_ffp: bool,
    /// Number of scene tokens (SSR: 16).
    #[arg(long)]
    tokens: Option<usize>,
    /// Ablation: the navigation gate reads the command only, not the target point.
    #[arg(long, conflicts_with = "init")]
    gate_command_only: bool,
    /// Share of routes held out for validation.
    #[arg(long, default_value_t = 0.05)]
    validation_fraction: f64,
    /// Validate every N steps (and at the end); 0 = only at the end.
    #[arg(long, default_value_t = 1000)]
    validate_every: u64,
    /// Validation samples, spread over the held-out routes (0 = all).
    #[arg(long, default_value_t = 1024)]
    validation_samples: usize,
    /// Checkpoint (and resume state) every N steps, and at the end.
    #[arg(long, default_value_t = 500)]
    checkpoint_every: u64,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

impl TrainArgs {
    fn config(&self) -> anyhow::Result<TrainConfig> {
        let mut model = match &self.init {
            Some(path) => checkpoint::inspect(path)?.config,
            None => SsrConfig::from_name_or_file(&self.model)?,
        };
        if let Some(blocks) = &self.deepen_backbone {
            // clap's `requires` lets a present --model stand in for the missing --init.
            anyhow::ensure!(
                self.init.is_some(),
                "--deepen-backbone grows the backbone of the --init checkpoint: give one"
            );
            let deeper = BackboneConfig {
                blocks: blocks.clone(),
                ..model.backbone.clone()
            };
            anyhow::ensure!(
                deeper.deepens(&model.backbone),
                "--deepen-backbone {blocks:?}: the checkpoint's backbone has {:?} blocks per \
                 stage; give one number per stage, none smaller",
                model.backbone.blocks
            );
            let tag: Vec<String> = blocks.iter().map(usize::to_string).collect();
            model.name = format!("{}-blocks-{}", model.name, tag.join("-"));
            model.backbone = deeper;
        }
        if let Some((width, height)) = self.input_size {
            // As for --deepen-backbone, a present --model can stand in for --init under clap.
            anyhow::ensure!(
                self.init.is_some(),
                "--input-size changes the input of the --init checkpoint: give one"
            );
            model.name = format!("{}-input-{width}x{height}", model.name);
            model.image_width = width;
            model.image_height = height;
        }
        model.tokens.dense_bev |= self.no_stl;
        model.tokens.gate_target_point &= !self.gate_command_only;
        model.ego_status |= self.ego_status;
        model.occupancy_head = self.occupancy_weight > 0.0;
        model.hazard_head = self.hazard_weight > 0.0;
        model.motion_head = self.motion_weight > 0.0;
        model.light_head = self.light_weight > 0.0;
        if let Some(tokens) = self.tokens {
            model.tokens.num_tokens = tokens;
        }
        if self.no_stl || self.no_ffp || self.gate_command_only || self.tokens.is_some() {
            let mut name = model.name.clone();
            for (on, tag) in [
                (self.no_stl, "-no-stl"),
                (self.no_ffp, "-no-ffp"),
                (self.gate_command_only, "-gate-command"),
            ] {
                if on {
                    name.push_str(tag);
                }
            }
            if let Some(tokens) = self.tokens {
                name.push_str(&format!("-{tokens}tok"));
            }
            model.name = name;
        }
        let mut config = TrainConfig::new(model, self.steps);
        config.batch_size = self.batch_size;
        config.lr = self.lr;
        config.weight_decay = self.weight_decay;
        config.warmup_steps = self.warmup_steps;
        config.schedule = match self.schedule {
            ScheduleKind::Cosine => Schedule::Cosine { final_ratio: 0.05 },
            ScheduleKind::Step => Schedule::Step {
                every: self.step_every,
                gamma: self.step_gamma,
            },
        };
        config.clip_norm = self.clip_norm;
        config.augment = self.augment;
        config.history_dropout = self.history_dropout;
        config.later_target = self.later_target;
        config.history = self.history;
        config.labels = self.labels;
        config.balanced = !self.uniform_sampling;
        config.init = self.init.clone();
        config.init_perception = self.init_perception.clone();
        config.train_only = self.train_only.clone();
        config.loss.bev = self.bev_weight;
        config.loss.hazard = self.hazard_weight;
        config.loss.occupancy = self.occupancy_weight;
        config.loss.motion = self.motion_weight;
        config.loss.light = self.light_weight;
        config.future_bev = !self.no_ffp;
        config.validation_fraction = self.validation_fraction;
        config.validate_every = self.validate_every;
        config.validation_samples = self.validation_samples;
        config.checkpoint_every = self.checkpoint_every;
        config.seed = self.seed;
        config.validate().map_err(anyhow::Error::msg)?;
        Ok(config)
    }
}

pub fn run(args: &TrainArgs) -> anyhow::Result<()> {
    let config = if args.resume {
        run::resumed_config(&args.out)?
    } else {
        args.config()?
    };
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(0).with_message("reading measurements")
    };
    let data = TrainingData::open(
        &args.data,
        &config.model,
        config.labels,
        config.validation_fraction,
        |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    )
    .with_context(|| format!("opening the dataset {}", args.data.display()))?;
    bar.finish_and_clear();
    eprintln!(
        "{}: {} training samples on {} routes, {} validation samples on {} routes; model {}, {} steps of {}",
        args.data.display(),
        data.train.len(),
        data.train_routes,
        data.validation.len(),
        data.validation_routes,
        config.model.name,
        config.steps,
        config.batch_size,
    );
    let options = TrainOptions {
        data: args.data.clone(),
        out: args.out.clone(),
        resume: args.resume,
        stop_at: args.stop_at,
        backend: args.backend,
        progress: !args.quiet,
    };
    let summary = run::train(config, options, Arc::new(data))?;
    println!(
        "{} steps done ({} in this run, {:.0} s, {:.1} samples/s)",
        summary.steps_done, summary.steps_run, summary.wall_seconds, summary.samples_per_s
    );
    if let Some(v) = &summary.validation {
        println!(
            "validation at step {} ({} samples): L2 at 1/2/3 s {} m, steer/throttle/brake MAE {:.3}/{:.3}/{:.3}",
            v.step,
            v.all.samples,
            format_l2(&v.all.l2_m),
            v.all.steer_mae,
            v.all.throttle_mae,
            v.all.brake_mae
        );
        for (situation, g) in &v.by_situation {
            println!(
                "  {situation:>11} ({:>5} samples): L2 {} m, steer/throttle/brake MAE {:.3}/{:.3}/{:.3}",
                g.samples,
                format_l2(&g.l2_m),
                g.steer_mae,
                g.throttle_mae,
                g.brake_mae
            );
        }
    }
    println!("checkpoint: {}", summary.checkpoint.display());
    Ok(())
}

/// `WIDTHxHEIGHT`, both positive pixel counts.
fn parse_input_size(text: &str) -> Result<(usize, usize), String> {
    let size = text.split_once(['x', 'X']).and_then(|(w, h)| {
        let (w, h) = (
            w.trim().parse::<usize>().ok()?,
            h.trim().parse::<usize>().ok()?,
        );
        (w > 0 && h > 0).then_some((w, h))
    });
    size.ok_or_else(|| format!("'{text}' is not WIDTHxHEIGHT in pixels, e.g. 416x128"))
}
