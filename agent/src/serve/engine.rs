//! The agent service's logic, free of gRPC plumbing: open, step and end episodes; the tonic
//! layer in `service.rs` only converts [`ServeError`]s into status codes and counts requests.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use ssrdrive_proto::camera::{CameraSpec, Rig};
use ssrdrive_proto::command::RoadOption;
use ssrdrive_proto::v1;
use ssrdrive_proto::wire;
use ssrdrive_support::error_text::clipped;
use tokio::sync::oneshot;

use super::batcher::{BatchSettings, BatchedStep, Batcher, StepJob, SubmitError};
use super::config::{DECODED_BYTES_PER_PIXEL, ServeConfig};
use super::decode;
use super::episodes::{Driver, EpisodeError, EpisodeTable};
use super::metrics::{Metrics, StepPhases};
use crate::model::config::SsrConfig;
use crate::model::hazard::Hazard;
use crate::policy::{SsrPolicy, StepOutput};

/// What the server runs, for `GetAgentInfo`.
#[derive(Debug, Clone)]
pub struct ModelInfo {
    /// The network's model config.
    pub config: SsrConfig,
    /// The checkpoint file's path, [`crate::checkpoint::bundled::NAME`], or "untrained (random
    /// weights)".
    pub checkpoint: String,
    /// The rig the network was trained with.
    pub expected_rig: Rig,
}

impl ModelInfo {
    /// TCP's front camera at the network's input size: the rig the bundled data is rendered
    /// with (`tcp-small` for cpu-default, `tcp` for paper).
    pub fn default_rig(config: &SsrConfig) -> Rig {
        Rig {
            cameras: vec![CameraSpec {
                width: config.image_width as u32,
                height: config.image_height as u32,
                ..CameraSpec::tcp_front()
            }],
        }
    }
}

/// Why a request was refused; each maps to one gRPC status code.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// NOT_FOUND, RESOURCE_EXHAUSTED, FAILED_PRECONDITION or ABORTED.
    #[error(transparent)]
    Episode(#[from] EpisodeError),
    /// INVALID_ARGUMENT.
    #[error("{0}")]
    BadRequest(String),
    /// RESOURCE_EXHAUSTED (queue full) or UNAVAILABLE (the model threads have stopped).
    #[error(transparent)]
    Submit(#[from] SubmitError),
    /// RESOURCE_EXHAUSTED: a rig or step over the server's image memory limits.
    #[error("{0}")]
    OverBudget(String),
    /// DEADLINE_EXCEEDED: a Drive step took longer than the request timeout.
    #[error("the step took longer than the server's request timeout of {0:?}")]
    DeadlineExceeded(Duration),
    /// INTERNAL.
    #[error("{0}")]
    Internal(String),
}

impl From<ServeError> for tonic::Status {
    fn from(error: ServeError) -> Self {
        use tonic::Code;
        let code = match &error {
            ServeError::Episode(EpisodeError::NotFound(_)) => Code::NotFound,
            ServeError::Episode(EpisodeError::TooMany { .. }) => Code::ResourceExhausted,
            ServeError::Episode(EpisodeError::OutOfOrder { .. }) => Code::FailedPrecondition,
            ServeError::Episode(EpisodeError::Busy(_)) => Code::Aborted,
            ServeError::Episode(EpisodeError::StreamOwned(_)) => Code::FailedPrecondition,
            ServeError::Episode(EpisodeError::NoRandomness(_)) => Code::Internal,
            ServeError::BadRequest(_) => Code::InvalidArgument,
            ServeError::OverBudget(_) => Code::ResourceExhausted,
            ServeError::Submit(SubmitError::QueueFull(_)) => Code::ResourceExhausted,
            ServeError::Submit(SubmitError::Stopped) => Code::Unavailable,
            ServeError::DeadlineExceeded(_) => Code::DeadlineExceeded,
            ServeError::Internal(_) => Code::Internal,
        };
        tonic::Status::new(code, error.to_string())
    }
}

fn bad(message: impl ToString) -> ServeError {
    ServeError::BadRequest(message.to_string())
}

/// Episodes, the batcher and the model behind them.
pub struct Engine {
    policy: Arc<SsrPolicy>,
    info: ModelInfo,
    episodes: Arc<EpisodeTable>,
    batcher: Batcher,
    metrics: Arc<Metrics>,
    config: ServeConfig,
    /// True until the warm-up is done: its episode and steps stay out of the metrics.
    warming: AtomicBool,
    /// Steps being served now; a drain waits for these, not for idle streams.
    in_flight: AtomicUsize,
    /// Bytes of decoded images the steps in flight hold (`max_decoded_mib` caps it).
    decoded_bytes: AtomicUsize,
}

/// Holds `amount` of a counter for as long as it lives.
struct Held<'a> {
    counter: &'a AtomicUsize,
    amount: usize,
}

impl<'a> Held<'a> {
    /// Adds `amount`, unless that takes the counter past `limit`.
    fn take(counter: &'a AtomicUsize, amount: usize, limit: usize) -> Option<Self> {
        let total = counter.fetch_add(amount, Ordering::SeqCst) + amount;
        let held = Self { counter, amount };
        (total <= limit).then_some(held)
    }
}

impl Drop for Held<'_> {
    fn drop(&mut self) {
        self.counter.fetch_sub(self.amount, Ordering::SeqCst);
    }
}

impl Engine {
    /// Starts the model thread.
    pub fn new(policy: SsrPolicy, info: ModelInfo, config: &ServeConfig) -> Arc<Self> {
        let policy = Arc::new(policy);
        let metrics = Metrics::new();
        let episodes = EpisodeTable::new(config.max_episodes, config.idle_timeout());
        let open = Arc::clone(&episodes);
        let batcher = Batcher::start(
            Arc::clone(&policy),
            BatchSettings {
                max_batch: config.max_batch,
                max_queue_delay: config.max_queue_delay(),
                max_queue: config.max_queue,
                model_threads: config.model_threads,
                compute_threads: config.compute_threads,
            },
            Arc::clone(&metrics),
            Arc::new(move || open.len()),
        );
        Arc::new(Self {
            policy,
            info,
            episodes,
            batcher,
            metrics,
            config: config.clone(),
            warming: AtomicBool::new(true),
            in_flight: AtomicUsize::new(0),
            decoded_bytes: AtomicUsize::new(0),
        })
    }

    /// The server's Prometheus metrics.
    pub fn metrics(&self) -> &Arc<Metrics> {
        &self.metrics
    }

    /// Longest a request may take ([`ServeConfig::request_timeout_s`]).
    pub fn request_timeout(&self) -> Duration {
        self.config.request_timeout()
    }

    /// Steps being decoded, queued or run now.
    pub fn steps_in_flight(&self) -> usize {
        self.in_flight.load(Ordering::SeqCst)
    }

    fn counting(&self) -> bool {
        !self.warming.load(Ordering::Relaxed)
    }

    /// The `GetAgentInfo` answer: model, config, expected rig, version and serving limits.
    pub fn agent_info(&self) -> v1::AgentInfo {
        v1::AgentInfo {
            model: "ssr".into(),
            config_name: self.info.config.name.clone(),
            config_json: serde_json::to_string(&self.info.config).expect("configs serialise"),
            expected_rig: Some(wire::rig_to_proto(&self.info.expected_rig)),
            version: env!("CARGO_PKG_VERSION").into(),
            checkpoint: self.info.checkpoint.clone(),
            max_batch: self.config.max_batch as u32,
            max_episodes: self.config.max_episodes as u32,
            idle_timeout_s: self.config.idle_timeout_s,
        }
    }

    /// Opens an episode for the request's rig (checked against the pixel and decoded-image
    /// budgets), with its fusion-alpha override if any, driven by `driver`.
    pub fn start_episode(
        &self,
        request: &v1::StartEpisodeRequest,
        driver: Driver,
    ) -> Result<v1::StartEpisodeResponse, ServeError> {
        let rig = request.rig.as_ref().ok_or_else(|| bad("rig is missing"))?;
        let rig = wire::rig_from_proto(rig).map_err(|e| bad(format!("rig: {e}")))?;
        let pixels = rig_pixels(&rig);
        if pixels > self.config.max_pixels_per_step {
            return Err(ServeError::OverBudget(format!(
                "the rig's cameras hold {pixels} pixels per step, over this server's \
                 max_pixels_per_step of {}",
                self.config.max_pixels_per_step
            )));
        }
        // One step of this rig would be over the image budget even alone: every step would
        // be refused, so the episode is refused now.
        let decoded = pixels as usize * DECODED_BYTES_PER_PIXEL;
        if decoded > self.config.max_decoded_bytes() {
            return Err(ServeError::OverBudget(format!(
                "the rig's images take {} MiB decoded per step, over this server's \
                 max_decoded_mib of {} MiB",
                decoded.div_ceil(1 << 20),
                self.config.max_decoded_mib
            )));
        }
        let mut control = self.policy.control().clone();
        if let Some(alpha) = request.overrides.as_ref().and_then(|o| o.fusion_alpha) {
            if !(0.0..=1.0).contains(&alpha) {
                return Err(bad(format!(
                    "overrides.fusion_alpha = {alpha} is not in [0, 1]"
                )));
            }
            control.alpha = alpha as f32;
        }
        let id = self
            .episodes
            .open(rig, self.policy.new_episode_with(control), driver)?;
        tracing::info!(
            episode = %id,
            client = %clipped(&request.client),
            seed = ?request.seed,
            "episode started"
        );
        if self.counting() {
            self.metrics.episode_started(self.episodes.len());
        }
        Ok(v1::StartEpisodeResponse {
            episode_id: id,
            idle_timeout_s: self.config.idle_timeout_s,
        })
    }

    /// Closes an episode `driver` drives; the answer gives the steps it ran.
    pub fn end_episode(
        &self,
        episode_id: &str,
        driver: Driver,
    ) -> Result<v1::EndEpisodeResponse, ServeError> {
        let steps = self.episodes.close(episode_id, driver)?;
        tracing::info!(episode = %episode_id, steps, "episode ended");
        if self.counting() {
            self.metrics.episode_ended(self.episodes.len());
        }
        Ok(v1::EndEpisodeResponse { steps })
    }

    /// Closes idle episodes; returns how many.
    pub fn expire_idle(&self) -> usize {
        let expired = self.episodes.expire_idle(Instant::now());
        for id in &expired {
            tracing::info!(episode = %id, "episode expired after being idle");
        }
        if !expired.is_empty() {
            self.metrics
                .episodes_expired(expired.len(), self.episodes.len());
        }
        expired.len()
    }

    /// Runs two steps of a throwaway episode with grey frames of the expected rig through the
    /// whole path (decode, queue, network, control), so no client pays for first-use setup.
    pub async fn warm_up(&self) -> Result<Duration, ServeError> {
        let started = Instant::now();
        let rig = wire::rig_to_proto(&self.info.expected_rig);
        let episode = self.start_episode(
            &v1::StartEpisodeRequest {
                rig: Some(rig.clone()),
                client: "warm-up".into(),
                ..Default::default()
            },
            Driver::Unary,
        )?;
        for frame_index in 0..2 {
            let images = wire::rgb_images(&rig, |c| {
                vec![128; c.width as usize * c.height as usize * 3]
            });
            let step = v1::StepRequest {
                episode_id: episode.episode_id.clone(),
                frame_index,
                images,
                pose: Some(v1::Pose::default()),
                command: RoadOption::LaneFollow.value(),
                target_point: Some(v1::EgoPoint { x: 10.0, y: 0.0 }),
                ..Default::default()
            };
            self.step(step, Driver::Unary).await?;
        }
        self.end_episode(&episode.episode_id, Driver::Unary)?;
        self.warming.store(false, Ordering::Relaxed);
        Ok(started.elapsed())
    }

    /// One tick of one episode, batched with whatever else is in flight.
    pub async fn step(
        &self,
        request: v1::StepRequest,
        driver: Driver,
    ) -> Result<v1::StepResponse, ServeError> {
        let received = Instant::now();
        let _in_flight = Held::take(&self.in_flight, 1, usize::MAX);
        let (episode_id, frame_index) = (request.episode_id.clone(), request.frame_index);
        let lease = self
            .episodes
            .lease(&request.episode_id, request.frame_index, driver)?;
        let rig = lease.rig().clone();
        let decoded = rig_pixels(&rig) as usize * DECODED_BYTES_PER_PIXEL;
        let limit = self.config.max_decoded_bytes();
        let _decoded = Held::take(&self.decoded_bytes, decoded, limit).ok_or_else(|| {
            ServeError::OverBudget(format!(
                "the steps in flight hold the server's max_decoded_mib of {} MiB of images; \
                 retry",
                self.config.max_decoded_mib
            ))
        })?;
        let (input, decode_time) = tokio::task::spawn_blocking(move || {
            let started = Instant::now();
            (decode::step_input(&request, &rig), started.elapsed())
        })
        .await
        .map_err(|e| ServeError::Internal(format!("image decoding failed: {e}")))?;
        let input = input.map_err(bad)?;
        self.policy.check(&input).map_err(bad)?;

        let (reply, answer) = oneshot::channel();
        self.batcher.submit(StepJob {
            lease,
            input,
            enqueued: Instant::now(),
            reply,
        })?;
        let BatchedStep {
            output,
            queue,
            model,
            batch_size,
        } = answer
            .await
            .map_err(|_| ServeError::Internal("the model thread dropped the step".into()))?
            .map_err(ServeError::Internal)?;
        let phases = StepPhases {
            queue,
            decode: decode_time,
            model,
            control: output.control_time,
            total: received.elapsed(),
        };
        if self.counting() {
            self.metrics.observe_step(&phases);
        }
        Ok(v1::StepResponse {
            episode_id,
            frame_index,
            control: Some(wire::control_to_proto(output.decision.control)),
            trajectory: output
                .waypoints
                .iter()
                .map(|&[x, y]| v1::EgoPoint {
                    x: x.into(),
                    y: y.into(),
                })
                .collect(),
            debug: debug_to_proto(&output),
            timings: Some(v1::Timings {
                queue_ms: millis(phases.queue),
                decode_ms: millis(phases.decode),
                model_ms: millis(phases.model),
                control_ms: millis(phases.control),
                total_ms: millis(phases.total),
                batch_size: batch_size as u32,
            }),
        })
    }
}

/// Pixels of one step of `rig`, all cameras together.
fn rig_pixels(rig: &Rig) -> u64 {
    rig.cameras
        .iter()
        .map(|c| c.width as u64 * c.height as u64)
        .sum()
}

fn millis(time: Duration) -> f64 {
    time.as_secs_f64() * 1000.0
}

fn debug_to_proto(output: &StepOutput) -> Option<v1::Debug> {
    let debug = output.debug.as_ref()?;
    let maps = |maps: &[Vec<f32>]| {
        maps.iter()
            .map(|weights| v1::TokenMap {
                rows: debug.bev_rows as u32,
                cols: debug.bev_cols as u32,
                weights: weights.clone(),
            })
            .collect()
    };
    Some(v1::Debug {
        token_attention: maps(&debug.token_attention),
        occupancy: maps(&debug.occupancy),
        trajectory_control: Some(wire::control_to_proto(output.decision.trajectory)),
        branch_control: Some(wire::control_to_proto(output.decision.branch)),
        beta_params: vec![debug.alpha[0], debug.beta[0], debug.alpha[1], debug.beta[1]],
        predicted_speed_mps: debug.predicted_speed.into(),
        hazard: debug.hazard.map(|p| v1::HazardBelief {
            clear: p[Hazard::Clear.index()],
            light: p[Hazard::Light.index()],
            stop_sign: p[Hazard::Sign.index()],
            road_user: p[Hazard::RoadUser.index()],
            lane_change: p[Hazard::LaneChange.index()],
        }),
        light: debug.light.map(|light| v1::LightBelief {
            green: light.green,
            stop: light.stop,
        }),
        controller: Some(v1::ControllerState {
            turning: output.decision.turning,
            unsticking: output.decision.unsticking,
            committed: output.decision.committed,
            full_stop: output.decision.full_stop,
            safety_stop: output.decision.safety_stop,
        }),
    })
}
