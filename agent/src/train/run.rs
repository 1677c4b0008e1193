//! The training loop: batches from the [`BatchLoader`], SSR's forward with a detached history
//! and future BEV, TCP's losses plus the BEV loss, AdamW, validation, checkpoints and resume.
//!
//! # A run's folder
//! ```text
//! <out>/train_config.json          TrainConfig (the run's definition)
//! <out>/control.json               the controller settings its checkpoints carry: the
//!                                  --init checkpoint's, else the defaults
//! <out>/metrics.jsonl              a line per step ("kind": "step") and per validation
//! <out>/checkpoints/step-NNNNNN.safetensors   servable checkpoints (config, rig, notes)
//! <out>/final.safetensors          the last step's weights
//! <out>/resume/                    weights with parameter ids, AdamW state, progress
//!                                  ([`super::resume`])
//! ```
//! Guarantees: resuming a run continues from its last checkpoint with the same batches,
//! augmentation and optimiser state, so its loss curve is the one the uninterrupted run would
//! have drawn; metrics lines past that checkpoint are dropped first, never duplicated. The
//! resume state is written to `resume.partial/` and renamed, so a crash never leaves half.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use burn::module::{Module, ParamId, list_param_ids};
use burn::optim::{
    AdamWConfig, GradientsParams, ModuleOptimizer, OptimizerRecord,
    grad_clipping::GradientClippingConfig,
};
use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};

use super::auxiliary::AuxiliaryOutputs;
use super::config::{Head, TrainConfig};
use super::data::{Batch, SampleDraw, TrainingData};
pub use super::error::TrainError;
use super::light::{light_hits, light_labels};
use super::loader::BatchLoader;
use super::loss::{Losses, losses};
use super::occupancy::confusion;
use super::resume::{Progress, load_model, read_progress, save_weights};
use super::validation::{HeadVerdicts, ValidationMetrics, ValidationSums, spread};
use crate::checkpoint;
use crate::control::ControlConfig;
use crate::device::Backend;
use crate::history::History;
use crate::model::classifier::predicted_classes;
use crate::model::config::SsrConfig;
use crate::model::hazard::Hazard;
use crate::model::light::LightClass;
use crate::model::tcp_head::HeadOutput;
use crate::model::{SsrModel, float_values};

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> TrainError + '_ {
    move |source| TrainError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// How to run: where the data is, where the run goes, and when to stop.
#[derive(Debug, Clone)]
pub struct TrainOptions {
    /// The dataset root (the folder of `manifest.json`).
    pub data: PathBuf,
    /// The run's folder (see the module doc).
    pub out: PathBuf,
    /// Continue the run in `out` from its resume state (its own config is used).
    pub resume: bool,
    /// Stop after this step (with a checkpoint), though the schedule spans all steps: splits a
    /// run over several sittings.
    pub stop_at: Option<u64>,
    /// Where the network trains (resume state is backend-independent).
    pub backend: Backend,
    /// Draw a progress bar on stderr.
    pub progress: bool,
}

/// One line of `metrics.jsonl`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum MetricsLine {
    /// One optimiser step's loss terms (`"kind": "step"`).
    Step(StepMetrics),
    /// One validation pass (`"kind": "validation"`).
    Validation(ValidationMetrics),
}

/// The loss terms of one optimiser step (`step` counts steps done, from 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepMetrics {
    /// Optimiser steps done, this one included.
    pub step: u64,
    /// Learning rate of this step.
    pub lr: f64,
    /// The weighted total loss.
    pub loss: f32,
    /// Waypoint L1, m.
    pub waypoints: f32,
    /// Beta KL of the current action.
    pub action: f32,
    /// Beta KL of the future actions.
    pub future_action: f32,
    /// Speed L1, in units of speed / 12.
    pub speed: f32,
    /// Future-BEV MSE; `None` without the FFP.
    pub bev: Option<f32>,
    /// Hazard cross-entropy; `None` without the hazard head.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hazard: Option<f32>,
    /// Occupancy cross-entropy; `None` without the occupancy head.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub occupancy: Option<f32>,
    /// Motion cross-entropy; `None` without the motion head.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<f32>,
    /// Light cross-entropy; `None` without the light head.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light: Option<f32>,
    /// Training throughput of this sitting so far, samples per second (validation excluded).
    pub samples_per_s: f64,
}

/// What a finished (or stopped) run reports.
#[derive(Debug, Clone)]
pub struct RunSummary {
    /// Optimiser steps the run has done, over every sitting.
    pub steps_done: u64,
    /// Steps run in this sitting and their wall time (the rate excludes validation).
    pub steps_run: u64,
    /// Wall time of this sitting, s (validation and checkpoints included).
    pub wall_seconds: f64,
    /// Training throughput of this sitting, samples per second (validation excluded).
    pub samples_per_s: f64,
    /// The last validation of this sitting, if any.
    pub validation: Option<ValidationMetrics>,
    /// `final.safetensors` when the run is complete, else the checkpoint of the step it
    /// stopped at.
    pub checkpoint: PathBuf,
}

/// The training notes stored in every checkpoint.
#[derive(Debug, Serialize)]
struct TrainingNotes<'a> {
    step: u64,
    config: &'a TrainConfig,
    data: String,
    train_samples: usize,
    train_routes: usize,
    validation_routes: usize,
    validation: Option<&'a ValidationMetrics>,
}

struct Trainer {
    config: TrainConfig,
    data: Arc<TrainingData>,
    options: TrainOptions,
    /// The autodiff device the model trains on, and its inner device for no-grad passes.
    device: Device,
    inner: Device,
    /// Always set between steps (taken for the optimiser's update).
    model: Option<SsrModel>,
    optimizer: ModuleOptimizer,
    step: u64,
    metrics: std::fs::File,
    last_validation: Option<ValidationMetrics>,
    /// The controller settings its checkpoints carry (`control.json`).
    control: ControlConfig,
}

/// Trains (or resumes) a run; `config` is ignored when resuming.
pub fn train(
    config: TrainConfig,
    options: TrainOptions,
    data: Arc<TrainingData>,
) -> Result<RunSummary, TrainError> {
    let mut trainer = Trainer::open(config, options, data)?;
    trainer.run()
}

/// Reads a resumable run's config (to open its dataset with the right model first).
pub fn resumed_config(out: &Path) -> Result<TrainConfig, TrainError> {
    Ok(read_progress(out)?.config)
}

/// The weights of the checkpoint at `path`, which must have been saved from `model`'s config
/// (a fine-tune changes the training, not the network), except that a fine-tune may add the
/// occupancy, hazard, motion or light head to a checkpoint without one: the head starts from random
/// weights; it may deepen the backbone (more blocks per stage, nothing else; the run's
/// model then names itself): the new blocks start as the identity
/// ([`crate::model::backbone::Backbone::deepened`]), so the run starts from the checkpoint's
/// driving; and it may take another camera input size, on which no weight depends.
fn initial_weights(
    path: &Path,
    model: &SsrConfig,
    device: &Device,
) -> Result<(SsrModel, ControlConfig), TrainError> {
    let (mut weights, info) = checkpoint::load(path, device)?;
    let control = checkpoint::control_config(&info)
        .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
    let adds_occupancy = model.occupancy_head && !info.config.occupancy_head;
    let adds_hazard = model.hazard_head && !info.config.hazard_head;
    let adds_motion = model.motion_head && !info.config.motion_head;
    let adds_light = model.light_head && !info.config.light_head;
    let from = info.config.backbone.clone();
    let deepens = model.backbone != from && model.backbone.deepens(&from);
    let resized = (model.image_width, model.image_height)
        != (info.config.image_width, info.config.image_height);
    let name = if deepens || resized {
        model.name.clone()
    } else {
        info.config.name.clone()
    };
    let backbone = if deepens {
        model.backbone.clone()
    } else {
        from.clone()
    };
    let saved = SsrConfig {
        occupancy_head: info.config.occupancy_head || model.occupancy_head,
        hazard_head: info.config.hazard_head || model.hazard_head,
        motion_head: info.config.motion_head || model.motion_head,
        light_head: info.config.light_head || model.light_head,
        name,
        backbone,
        image_width: model.image_width,
        image_height: model.image_height,
        ..info.config
    };
    let differences = saved.differences(model);
    if !differences.is_empty() {
        return Err(TrainError::Config(format!(
            "the initial checkpoint {} was saved from another network than this run's: {}",
            path.display(),
            differences.join("; ")
        )));
    }
    if adds_occupancy {
        weights.occupancy = model.init_occupancy_head(device);
    }
    if adds_hazard {
        weights.hazard = model.init_hazard_head(device);
    }
    if adds_motion {
        weights.motion = model.init_motion_head(device);
    }
    if adds_light {
        weights.light = model.init_light_head(device);
    }
    if deepens {
        weights.backbone = weights
            .backbone
            .deepened(&from, &model.backbone, device)
            .map_err(|e| TrainError::Config(format!("{}: {e}", path.display())))?;
    }
    Ok((weights, control))
}

/// The config fields that shape the perception [`with_perception_of`] copies.
const PERCEPTION_FIELDS: [&str; 5] = ["image_width", "image_height", "backbone", "channels", "bev"];

/// A fresh network for `model` whose backbone, BEV encoder and occupancy head (where both
/// have one) are the checkpoint's at `path`; its tokens, gate, heads and FFP may differ from
/// the checkpoint's, its perception may not.
fn with_perception_of(
    path: &Path,
    model: &SsrConfig,
    device: &Device,
) -> Result<SsrModel, TrainError> {
    let (saved, info) = checkpoint::load(path, device)?;
    let differences: Vec<String> = info
        .config
        .differences(model)
        .into_iter()
        .filter(|d| {
            let field = d.split(['.', ':']).next().unwrap_or_default();
            PERCEPTION_FIELDS.contains(&field)
        })
        .collect();
    if !differences.is_empty() {
        return Err(TrainError::Config(format!(
            "the perception checkpoint {} has another perception than this run's network: {}",
            path.display(),
            differences.join("; ")
        )));
    }
    let fresh = model.init(device);
    let occupancy = match (fresh.occupancy, saved.occupancy) {
        (Some(_), Some(saved)) => Some(saved),
        (fresh, _) => fresh,
    };
    Ok(SsrModel {
        backbone: saved.backbone,
        bev: saved.bev,
        occupancy,
        ..fresh
    })
}

fn optimizer_for(config: &TrainConfig) -> ModuleOptimizer {
    let mut adamw = AdamWConfig::new().with_weight_decay(config.weight_decay);
    if config.clip_norm > 0.0 {
        adamw = adamw.with_grad_clipping(Some(GradientClippingConfig::Norm(config.clip_norm)));
    }
    adamw.init()
}

impl Trainer {
    fn open(
        config: TrainConfig,
        options: TrainOptions,
        data: Arc<TrainingData>,
    ) -> Result<Self, TrainError> {
        let inner = options.backend.device()?;
        let device = inner.clone().autodiff();
        let out = options.out.clone();
        std::fs::create_dir_all(&out).map_err(io_error(&out))?;
        let metrics_path = out.join("metrics.jsonl");
        let control_path = out.join("control.json");
        let (config, model, optimizer, step, control) = if options.resume {
            let resume_dir = out.join("resume");
            let progress = read_progress(&out)?;
            let fail = |problem: String| TrainError::Resume {
                path: resume_dir.clone(),
                problem,
            };
            let config = progress.config;
            config
                .validate()
                .map_err(|e| fail(format!("train_config: {e}")))?;
            let model = load_model(&resume_dir, &config.model, &device).map_err(fail)?;
            let record = OptimizerRecord::load(resume_dir.join("optimizer.bpk"))
                .map_err(|e| fail(format!("optimizer.bpk: {e}")))?;
            let optimizer = optimizer_for(&config).load_record(record);
            keep_metrics_until(&metrics_path, progress.step)?;
            // Runs from before the file carried the defaults.
            let control = match std::fs::read_to_string(&control_path) {
                Ok(json) => serde_json::from_str::<ControlConfig>(&json)
                    .map_err(|e| e.to_string())
                    .and_then(|c| c.validate().map(|()| c))
                    .map_err(|e| fail(format!("{}: {e}", control_path.display())))?,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => ControlConfig::default(),
                Err(e) => return Err(io_error(&control_path)(e)),
            };
            (config, model, optimizer, progress.step, control)
        } else {
            config.validate().map_err(TrainError::Config)?;
            device.seed(config.seed);
            // Fine-tuning keeps the driving's controller settings; a fresh head gets the defaults.
            let (model, control) = match (&config.init, &config.init_perception) {
                (Some(path), _) => initial_weights(path, &config.model, &device)?,
                (None, Some(path)) => (
                    with_perception_of(path, &config.model, &device)?,
                    ControlConfig::default(),
                ),
                (None, None) => (config.model.init(&device), ControlConfig::default()),
            };
            std::fs::write(
                out.join("train_config.json"),
                serde_json::to_string_pretty(&config).expect("configs serialise"),
            )
            .map_err(io_error(&out))?;
            std::fs::write(
                &control_path,
                serde_json::to_string_pretty(&control).expect("configs serialise"),
            )
            .map_err(io_error(&control_path))?;
            std::fs::write(&metrics_path, b"").map_err(io_error(&metrics_path))?;
            let optimizer = optimizer_for(&config);
            (config, model, optimizer, 0, control)
        };
        let metrics = std::fs::OpenOptions::new()
            .append(true)
            .open(&metrics_path)
            .map_err(io_error(&metrics_path))?;
        Ok(Self {
            config,
            data,
            options,
            device,
            inner,
            model: Some(model),
            optimizer,
            step,
            metrics,
            last_validation: None,
            control,
        })
    }

    fn model(&self) -> &SsrModel {
        self.model
            .as_ref()
            .expect("the model is back after every step")
    }

    fn log(&mut self, line: &MetricsLine) -> Result<(), TrainError> {
        let path = self.options.out.join("metrics.jsonl");
        let mut text = serde_json::to_string(line).expect("metrics serialise");
        text.push('\n');
        self.metrics
            .write_all(text.as_bytes())
            .map_err(io_error(&path))
    }

    fn run(&mut self) -> Result<RunSummary, TrainError> {
        let last = self
            .options
            .stop_at
            .map_or(self.config.steps, |s| s.min(self.config.steps));
        let first = self.step;
        let bar = progress_bar(self.options.progress, first, self.config.steps);
        let mut loader = BatchLoader::start(self.data.clone(), &self.config, first..last);
        let started = Instant::now();
        let mut training_time = 0.0;
        while self.step < last {
            let Some((step, batch)) = loader.next_batch() else {
                break;
            };
            debug_assert_eq!(step, self.step);
            let batch = batch?;
            let step_started = Instant::now();
            let metrics = self.optimise(&batch)?;
            training_time += step_started.elapsed().as_secs_f64();
            let done_here = self.step - first;
            let rate = (done_here as usize * self.config.batch_size) as f64 / training_time;
            self.log(&MetricsLine::Step(StepMetrics {
                samples_per_s: rate,
                ..metrics.clone()
            }))?;
            bar.set_position(self.step);
            bar.set_message(format!(
                "loss {:.3} (wp {:.3}, bev {}) {:.1} samples/s",
                metrics.loss,
                metrics.waypoints,
                metrics.bev.map_or("-".into(), |b| format!("{b:.3}")),
                rate
            ));
            let at_end = self.step == last;
            let every = self.config.validate_every;
            if at_end || (every > 0 && self.step.is_multiple_of(every)) {
                let validation = self.validate()?;
                bar.println(format!(
                    "step {}: validation {}",
                    self.step,
                    validation.summary()
                ));
                self.log(&MetricsLine::Validation(validation.clone()))?;
                self.last_validation = Some(validation);
            }
            if at_end || self.step.is_multiple_of(self.config.checkpoint_every) {
                self.save_checkpoint()?;
            }
        }
        bar.finish();
        let checkpoint = if self.step == self.config.steps {
            let path = self.options.out.join("final.safetensors");
            self.export(&path)?;
            path
        } else {
            self.checkpoint_path()
        };
        let steps_run = self.step - first;
        Ok(RunSummary {
            steps_done: self.step,
            steps_run,
            wall_seconds: started.elapsed().as_secs_f64(),
            samples_per_s: (steps_run as usize * self.config.batch_size) as f64
                / training_time.max(1e-9),
            validation: self.last_validation.clone(),
            checkpoint,
        })
    }

    /// One optimiser step on a batch.
    fn optimise(&mut self, batch: &Batch) -> Result<StepMetrics, TrainError> {
        let config = &self.config;
        let frozen = self.model().valid();
        let (terms, _, _) = batch_losses(
            self.model(),
            &frozen,
            batch,
            config,
            &self.inner,
            &self.device,
        );
        let metrics = step_metrics(&terms, self.step + 1, config.lr_at(self.step));
        if !metrics.loss.is_finite() {
            return Err(TrainError::Diverged {
                step: self.step + 1,
                value: metrics.loss,
            });
        }
        let mut grads = terms.total.backward();
        let model_grads = match self.config.train_only.as_slice() {
            [] => GradientsParams::from_module(&mut grads, self.model()),
            heads => {
                let trained = trained_params(self.model(), heads);
                GradientsParams::from_params(&mut grads, self.model(), &trained)
            }
        };
        let model = self
            .model
            .take()
            .expect("the model is back after every step");
        self.model = Some(self.optimizer.step(metrics.lr, model, model_grads));
        self.step += 1;
        Ok(metrics)
    }

    /// Open-loop metrics over (a spread subset of) the validation samples.
    fn validate(&self) -> Result<ValidationMetrics, TrainError> {
        let config = &self.config;
        let samples = spread(&self.data.validation, config.validation_samples);
        let model = self.model().valid();
        let device = &self.inner;
        let p = config.model.head.pred_len;
        let mut sums = ValidationSums::default();
        for chunk in samples.chunks(config.batch_size) {
            let batch = self.data.batch(chunk, &config.model, config.history, |_| {
                SampleDraw::default()
            })?;
            let (terms, head, outputs) =
                batch_losses(&model, &model, &batch, config, device, device);
            let hazards = outputs.hazard.map(|logits| {
                predicted_classes(&float_values(logits), Hazard::ALL.len())
                    .into_iter()
                    .map(|i| Hazard::ALL[i])
                    .collect::<Vec<_>>()
            });
            let cells = |(logits, targets, recorded): (Tensor<3>, Tensor<3>, Tensor<1>)| {
                confusion(
                    &float_values(logits),
                    &float_values(targets),
                    &float_values(recorded),
                )
            };
            let lights = outputs.light.map(|logits| {
                let predicted = predicted_classes(&float_values(logits), LightClass::ALL.len());
                light_hits(&predicted, &light_labels(batch.lights()))
            });
            let verdicts = HeadVerdicts {
                hazards,
                cells: [outputs.occupancy.map(cells), outputs.motion.map(cells)],
                light: lights,
            };
            sums.add(&batch, &head, verdicts, p, float_values(terms.total)[0]);
        }
        Ok(sums.finish(self.step, p))
    }

    fn checkpoint_path(&self) -> PathBuf {
        self.options
            .out
            .join("checkpoints")
            .join(format!("step-{:06}.safetensors", self.step))
    }

    /// A servable checkpoint at `path` with the config, rig and training notes.
    fn export(&self, path: &Path) -> Result<(), TrainError> {
        let notes = TrainingNotes {
            step: self.step,
            config: &self.config,
            data: self.options.data.display().to_string(),
            train_samples: self.data.train.len(),
            train_routes: self.data.train_routes,
            validation_routes: self.data.validation_routes,
            validation: self.last_validation.as_ref(),
        };
        let rig = serde_json::to_string(self.data.rig()).expect("rigs serialise");
        checkpoint::save(
            &self.exported_model()?,
            &self.config.model,
            &[
                (checkpoint::RIG_KEY, rig),
                (
                    checkpoint::CONTROL_KEY,
                    serde_json::to_string(&self.control).expect("configs serialise"),
                ),
                (
                    checkpoint::HISTORY_KEY,
                    serde_json::to_string(&self.config.history).expect("modes serialise"),
                ),
                (
                    checkpoint::TRAINING_KEY,
                    serde_json::to_string(&notes).expect("notes serialise"),
                ),
            ],
            path,
        )?;
        Ok(())
    }

    /// The network a checkpoint holds: the trained one, or, where only some heads train, the
    /// `init` checkpoint's with those heads, so that its trunk is exactly that checkpoint's
    /// (training-mode passes move the batch-norm statistics even where no weight trains).
    fn exported_model(&self) -> Result<SsrModel, TrainError> {
        let trained = self.model().valid();
        let (false, Some(init)) = (self.config.train_only.is_empty(), &self.config.init) else {
            return Ok(trained);
        };
        let (mut model, _) = checkpoint::load(init, &self.inner)?;
        for head in &self.config.train_only {
            match head {
                Head::Hazard => model.hazard = trained.hazard.clone(),
                Head::Occupancy => model.occupancy = trained.occupancy.clone(),
                Head::Motion => model.motion = trained.motion.clone(),
                Head::Light => model.light = trained.light.clone(),
            }
        }
        Ok(model)
    }

    /// A checkpoint plus the resume state (weights with ids, optimiser, progress).
    fn save_checkpoint(&self) -> Result<(), TrainError> {
        self.export(&self.checkpoint_path())?;
        let out = &self.options.out;
        let partial = out.join("resume.partial");
        let _ = std::fs::remove_dir_all(&partial);
        std::fs::create_dir_all(&partial).map_err(io_error(&partial))?;
        let fail = |problem: String| TrainError::Io {
            path: partial.clone(),
            source: std::io::Error::other(problem),
        };
        save_weights(self.model(), &partial, "model.bpk").map_err(fail)?;
        self.optimizer
            .to_record()
            .save(partial.join("optimizer.bpk"))
            .map_err(|e| fail(e.to_string()))?;
        let progress = Progress {
            step: self.step,
            config: self.config.clone(),
        };
        std::fs::write(
            partial.join("progress.json"),
            serde_json::to_string_pretty(&progress).expect("progress serialises"),
        )
        .map_err(io_error(&partial))?;
        let resume = out.join("resume");
        let _ = std::fs::remove_dir_all(&resume);
        std::fs::rename(&partial, &resume).map_err(io_error(&resume))
    }
}

/// The losses of a batch, the head's output and the auxiliary heads' outputs. `context_model` (without
/// gradients, on `inner`) gives the history BEVs (each from its own history frame, as serving
/// does) and the FFP's targets; `model` (on `device`) runs the current frames.
fn batch_losses(
    model: &SsrModel,
    context_model: &SsrModel,
    batch: &Batch,
    config: &TrainConfig,
    inner: &Device,
    device: &Device,
) -> (Losses, HeadOutput, AuxiliaryOutputs) {
    let b = batch.size;
    let deep_bev = match config.history {
        History::Link => Tensor::zeros(
            [b, config.model.bev.grid.cells(), config.model.channels],
            inner,
        ),
        _ => {
            let deep = batch.deep_input(&config.model, inner);
            context_model.encode_bev(context_model.image_features(deep.images.clone()), &deep)
        }
    };
    let context = batch.context_input(&config.model, deep_bev, config.future_bev, inner);
    let context_bev = context_model.encode_bev(
        context_model.image_features(context.images.clone()),
        &context,
    );
    let detached = |bev: Tensor<3>| Tensor::from_data(bev.into_data(), device);
    let history = detached(context_bev.clone().narrow(0, 0, b));
    let output = model.forward(&batch.current_input(&config.model, history, device));
    let bev = config.future_bev.then(|| {
        let future = detached(context_bev.narrow(0, b, b));
        (model.predict_future_bev(&output), future)
    });
    let targets = batch.targets(
        config.model.head.pred_len,
        config.loss.target_concentration,
        device,
    );
    let outputs = AuxiliaryOutputs::of(model, &output, batch, config, device);
    (
        losses(
            &output.head,
            &targets,
            bev,
            outputs.losses(batch),
            &config.loss,
        ),
        output.head,
        outputs,
    )
}

fn step_metrics(terms: &Losses, step: u64, lr: f64) -> StepMetrics {
    let value = |t: &Tensor<1>| float_values(t.clone())[0];
    StepMetrics {
        step,
        lr,
        loss: value(&terms.total),
        waypoints: value(&terms.waypoints),
        action: value(&terms.action),
        future_action: value(&terms.future_action),
        speed: value(&terms.speed),
        bev: terms.bev.as_ref().map(value),
        hazard: terms.hazard.as_ref().map(value),
        occupancy: terms.occupancy.as_ref().map(value),
        motion: terms.motion.as_ref().map(value),
        light: terms.light.as_ref().map(value),
        samples_per_s: 0.0,
    }
}

/// Keeps the metrics lines of steps up to `step` (a resumed run redraws the rest).
fn keep_metrics_until(path: &Path, step: u64) -> Result<(), TrainError> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        // Unreadable history is an error, never a reason to overwrite it with nothing.
        Err(e) => return Err(io_error(path)(e)),
    };
    let kept: String = text
        .lines()
        .filter(|line| match serde_json::from_str::<MetricsLine>(line) {
            Ok(MetricsLine::Step(m)) => m.step <= step,
            Ok(MetricsLine::Validation(m)) => m.step <= step,
            Err(_) => false,
        })
        .flat_map(|line| [line, "\n"])
        .collect();
    std::fs::write(path, kept).map_err(io_error(path))
}

fn progress_bar(visible: bool, position: u64, steps: u64) -> indicatif::ProgressBar {
    if !visible {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(steps).with_position(position);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] step {pos}/{len} (eta {eta}) {msg}",
        )
        .expect("a valid template")
        .progress_chars("=> "),
    );
    bar
}

/// The parameters of `heads` in `model`: all a run with [`TrainConfig::train_only`] updates.
fn trained_params(model: &SsrModel, heads: &[Head]) -> Vec<ParamId> {
    let mut ids = Vec::new();
    for head in heads {
        ids.extend(
            match head {
                Head::Hazard => model.hazard.as_ref().map(list_param_ids),
                Head::Occupancy => model.occupancy.as_ref().map(list_param_ids),
                Head::Motion => model.motion.as_ref().map(list_param_ids),
                Head::Light => model.light.as_ref().map(list_param_ids),
            }
            .unwrap_or_default(),
        );
    }
    ids
}
