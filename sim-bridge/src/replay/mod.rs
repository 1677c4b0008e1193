//! Recording and replaying agent steps.
//!
//! - [`log`]: the step log file format (`proto/ssrdrive/v1/log.proto`), writer and reader.
//! - [`logging_agent`]: [`logging_agent::LoggingAgent`], which logs any agent's route runs.
//! - [`metrics`]: open-loop L2 and collision rate at 1, 2 and 3 s.
//!
//! [`replay`] re-feeds a log's requests, in order, as one episode to an agent server and
//! reports the latency of each step, how far the answers drift from the recorded controls and
//! trajectories (zero drift from a log of the same server and checkpoint means the server is
//! deterministic; from a log of the expert it is the control error against the expert), and
//! the open-loop metrics of the server's trajectories against what the recorded ego did.
//! Asked to trace, it also asks the server for its debug outputs and keeps, per tick, what the
//! network believed and which of the controller's rules acted, beside the log's ground truth of
//! the lights around ([`TickTrace`]): the way to read why a recorded car stood where it stood.

pub mod log;
pub mod logging_agent;
pub mod metrics;

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use glam::DVec2;
use ssrdrive_proto::frames::{world_to_ego, wrap_angle};
use ssrdrive_proto::v1;
use ssrdrive_proto::v1::agent_service_client::AgentServiceClient;

use crate::client::grpc::{connect_when_serving, status_error};
use crate::client::load::Percentiles;
use crate::driver::AgentError;
use log::StepLog;
use metrics::{HorizonMetrics, open_loop};

/// Mean and max of absolute differences.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct Spread {
    /// Mean of the absolute differences.
    pub mean: f64,
    /// Largest absolute difference.
    pub max: f64,
}

impl Spread {
    fn of(values: &[f64]) -> Option<Self> {
        (!values.is_empty()).then(|| Self {
            mean: values.iter().sum::<f64>() / values.len() as f64,
            max: values.iter().copied().fold(0.0, f64::max),
        })
    }
}

/// What a replay measured.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ReplayReport {
    /// Who drove when the log was recorded.
    pub recorded_agent: String,
    /// The route's id in its set.
    pub route_id: String,
    /// Ticks in the log (those without a recorded request are not sent).
    pub ticks: usize,
    /// The log was cut short (its whole ticks were replayed).
    pub truncated: bool,
    /// Round-trip latency per step, milliseconds.
    pub latency_ms: Percentiles,
    /// Answers by gRPC status code name.
    pub codes: BTreeMap<String, usize>,
    /// |replayed - recorded| of steer, over answered ticks (`None` without any).
    pub steer_diff: Option<Spread>,
    /// |replayed - recorded| of throttle, over answered ticks (`None` without any).
    pub throttle_diff: Option<Spread>,
    /// |replayed - recorded| of brake, over answered ticks (`None` without any).
    pub brake_diff: Option<Spread>,
    /// Per tick, the mean distance between replayed and recorded waypoints (metres): mean and
    /// max over ticks (logs of agents that planned).
    pub trajectory_drift_m: Option<Spread>,
    /// Open-loop L2 and collision rate of the replayed trajectories, one entry per horizon.
    pub open_loop: Vec<HorizonMetrics>,
}

/// One replayed tick, as the server answered it with its debug outputs.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TickTrace {
    /// The request's frame index.
    pub frame: u64,
    /// Simulation time, seconds.
    pub t: f64,
    /// The ego's speed the request gave, m/s.
    pub speed: f64,
    /// The replayed answer's control: steer, throttle, brake.
    pub control: [f64; 3],
    /// The recorded answer's control, where the log has one.
    pub recorded: Option<[f64; 3]>,
    /// The trajectory's control before the fusion (pure pursuit and the speed PID on the plan).
    pub trajectory_control: Option<[f64; 3]>,
    /// The control branch's control before the fusion.
    pub branch_control: Option<[f64; 3]>,
    /// The speed head's prediction, m/s.
    pub predicted_speed: f64,
    /// The hazard head's probabilities: clear, light, stop sign, road user, lane change.
    pub hazard: Option<[f32; 5]>,
    /// The light head's probabilities: green, red or yellow.
    pub light: Option<[f32; 2]>,
    /// The fusion trusted the control branch ("turning").
    pub turning: bool,
    /// The unstick rule's creep drove.
    pub unsticking: bool,
    /// The commit rule drove on through the light the car started on.
    pub committed: bool,
    /// The full stop braked for a stop sign.
    pub full_stop: bool,
    /// The safety stop braked.
    pub safety_stop: bool,
    /// The log's ground truth: the traffic lights within 60 m, in the recorded ego's frame.
    pub lights: Vec<LightInView>,
}

/// A traffic light of the log's ground truth, seen from the recorded ego.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LightInView {
    /// "green", "yellow" or "red".
    pub state: String,
    /// Metres its head stands ahead of the ego's centre.
    pub ahead: f64,
    /// Metres its head stands to the ego's left.
    pub left: f64,
    /// Whether the head faces the ego's way (its lamps point within 45 degrees of straight
    /// back at the ego's heading): a light for traffic going the ego's way.
    pub faces_ego: bool,
}

impl LightInView {
    fn all(tick: &v1::LogTick) -> Vec<Self> {
        let Some(ego) = &tick.ego else {
            return Vec::new();
        };
        tick.lights
            .iter()
            .map(|light| {
                let offset = [light.head_x - ego.x, light.head_y - ego.y];
                let [ahead, left] = world_to_ego(offset, ego.yaw);
                let towards_ego = wrap_angle(light.head_yaw - ego.yaw - std::f64::consts::PI);
                Self {
                    state: light.state.clone(),
                    ahead,
                    left,
                    faces_ego: towards_ego.abs() <= std::f64::consts::FRAC_PI_4,
                }
            })
            .collect()
    }
}

impl TickTrace {
    /// The trace of the log's `tick` (which has a request) as the server `answer`ed it.
    fn of(tick: &v1::LogTick, answer: &v1::StepResponse) -> Self {
        let control = |c: &v1::Control| [c.steer, c.throttle, c.brake];
        let request = tick.request.as_ref();
        let debug = answer.debug.as_ref();
        let state = debug.and_then(|d| d.controller).unwrap_or_default();
        Self {
            frame: request.map_or(0, |r| r.frame_index),
            t: request.map_or(0.0, |r| r.timestamp_s),
            speed: request.map_or(0.0, |r| r.speed_mps),
            control: answer.control.as_ref().map_or([0.0; 3], control),
            recorded: tick.control.as_ref().map(control),
            trajectory_control: debug
                .and_then(|d| d.trajectory_control.as_ref())
                .map(control),
            branch_control: debug.and_then(|d| d.branch_control.as_ref()).map(control),
            predicted_speed: debug.map_or(0.0, |d| d.predicted_speed_mps),
            hazard: debug
                .and_then(|d| d.hazard)
                .map(|h| [h.clear, h.light, h.stop_sign, h.road_user, h.lane_change]),
            light: debug.and_then(|d| d.light).map(|l| [l.green, l.stop]),
            turning: state.turning,
            unsticking: state.unsticking,
            committed: state.committed,
            full_stop: state.full_stop,
            safety_stop: state.safety_stop,
            lights: LightInView::all(tick),
        }
    }
}

/// Replays `log` to the server at `target` (see the module doc); with `trace`, also asks for
/// debug outputs and returns a [`TickTrace`] per answered tick (none without it).
pub fn replay(
    log: &StepLog,
    target: &str,
    call_timeout: Duration,
    trace: bool,
) -> Result<(ReplayReport, Vec<TickTrace>), AgentError> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| AgentError(format!("starting the client runtime: {e}")))?;
    runtime.block_on(replay_async(log, target, call_timeout, trace))
}

async fn replay_async(
    log: &StepLog,
    target: &str,
    call_timeout: Duration,
    trace: bool,
) -> Result<(ReplayReport, Vec<TickTrace>), AgentError> {
    let channel = connect_when_serving(target, Duration::from_secs(120)).await?;
    let mut client = AgentServiceClient::new(channel);
    let episode_id = client
        .start_episode(v1::StartEpisodeRequest {
            rig: log.header.rig.clone(),
            client: format!("sim-bridge replay of route {}", log.header.route_id),
            ..Default::default()
        })
        .await
        .map_err(|s| status_error("StartEpisode", &s))?
        .into_inner()
        .episode_id;
    let mut latencies = Vec::with_capacity(log.ticks.len());
    let mut codes = BTreeMap::new();
    let mut predictions = Vec::with_capacity(log.ticks.len());
    let mut traces = Vec::new();
    let (mut steer, mut throttle, mut brake, mut drift) = (vec![], vec![], vec![], vec![]);
    for tick in &log.ticks {
        let Some(mut request) = tick.request.clone() else {
            predictions.push(Vec::new());
            continue;
        };
        request.episode_id = episode_id.clone();
        request.debug = trace;
        let mut call = tonic::Request::new(request);
        call.set_timeout(call_timeout);
        let started = Instant::now();
        let answer = client.step(call).await;
        latencies.push(started.elapsed().as_secs_f64() * 1e3);
        let answer = match answer {
            Ok(answer) => answer.into_inner(),
            Err(status) => {
                *codes.entry(format!("{:?}", status.code())).or_default() += 1;
                predictions.push(Vec::new());
                continue;
            }
        };
        *codes.entry("Ok".to_string()).or_default() += 1;
        if trace {
            traces.push(TickTrace::of(tick, &answer));
        }
        if let (Some(now), Some(then)) = (&answer.control, &tick.control) {
            steer.push((now.steer - then.steer).abs());
            throttle.push((now.throttle - then.throttle).abs());
            brake.push((now.brake - then.brake).abs());
        }
        let plan: Vec<DVec2> = answer
            .trajectory
            .iter()
            .map(|p| DVec2::new(p.x, p.y))
            .collect();
        if !tick.trajectory.is_empty() {
            let distances: Vec<f64> = plan
                .iter()
                .zip(&tick.trajectory)
                .map(|(a, b)| a.distance(DVec2::new(b.x, b.y)))
                .collect();
            if let Some(spread) = Spread::of(&distances) {
                drift.push(spread.mean);
            }
        }
        predictions.push(plan);
    }
    let _ = client
        .end_episode(v1::EndEpisodeRequest { episode_id })
        .await;
    let report = ReplayReport {
        recorded_agent: log.header.agent.clone(),
        route_id: log.header.route_id.clone(),
        ticks: log.ticks.len(),
        truncated: log.truncated,
        latency_ms: Percentiles::of(latencies),
        codes,
        steer_diff: Spread::of(&steer),
        throttle_diff: Spread::of(&throttle),
        brake_diff: Spread::of(&brake),
        trajectory_drift_m: Spread::of(&drift),
        open_loop: open_loop(log, &predictions),
    };
    Ok((report, traces))
}
