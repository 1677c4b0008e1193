//! A load generator for agent servers: N episodes, each on its own connection, ticking at a
//! fixed rate like N simulators in lockstep, for a fixed time.
//!
//! No coordinated omission: every step has an *intended* send time on the episode's fixed
//! schedule, and its latency is measured from that time, so a slow answer also counts against
//! the steps it delays (an episode never has two steps in flight, as a lockstep simulator
//! would not). Nothing is sent after the run's end; steps the schedule held before the end but
//! that could not be sent by then (the server fell behind) are counted as `behind_schedule`.
//! Steps cycle through prepared request templates (real rendered or recorded frames) with
//! strictly increasing frame indices.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use ssrdrive_proto::v1;
use ssrdrive_proto::v1::agent_service_client::AgentServiceClient;

use super::grpc::{connect_when_serving, keyed, new_episode_key, status_error};
use crate::driver::AgentError;

/// What to run.
#[derive(Debug, Clone)]
pub struct LoadConfig {
    /// `grpc://HOST:PORT`.
    pub target: String,
    /// Concurrent episodes, each on its own connection.
    pub episodes: usize,
    /// Steps per second per episode.
    pub rate_hz: f64,
    /// How long steps are scheduled for.
    pub duration: Duration,
    /// Deadline of each step.
    pub call_timeout: Duration,
    /// Camera rig every episode starts with.
    pub rig: v1::Rig,
}

/// Counters shared with a progress display while the run goes.
#[derive(Debug, Default)]
pub struct LoadProgress {
    /// Steps answered so far (any status).
    pub steps: AtomicU64,
    /// Steps answered with an error status so far.
    pub errors: AtomicU64,
}

/// What a run measured.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LoadReport {
    /// Episodes run.
    pub episodes: usize,
    /// Steps per second per episode.
    pub rate_hz: f64,
    /// Wall time from the first intended step to the last answer, seconds.
    pub duration_s: f64,
    /// Steps answered (any status).
    pub count: usize,
    /// Answered steps per second of wall time.
    pub rps: f64,
    /// Latency from each step's intended send time, milliseconds; a step never sent counts
    /// with its wait until the end (a lower bound).
    pub latency_ms: Percentiles,
    /// Answers by gRPC status code name ("Ok" for successes).
    pub codes: BTreeMap<String, usize>,
    /// Steps scheduled before the end that were never sent because earlier answers came late.
    pub behind_schedule: u64,
}

/// Percentiles of a set of samples, nearest rank, in the samples' unit.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Percentiles {
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest sample.
    pub max: f64,
}

impl std::fmt::Display for Percentiles {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "p50 {:.1}  p90 {:.1}  p99 {:.1}  max {:.1}",
            self.p50, self.p90, self.p99, self.max
        )
    }
}

impl Percentiles {
    /// Of unsorted samples (NaN when empty).
    pub fn of(mut samples: Vec<f64>) -> Self {
        samples.sort_by(f64::total_cmp);
        let at = |fraction| ssrdrive_support::stats::percentile(&samples, fraction);
        Self {
            p50: at(0.5),
            p90: at(0.9),
            p99: at(0.99),
            max: at(1.0),
        }
    }
}

/// One episode's results.
struct EpisodeResult {
    latencies: Vec<f64>,
    codes: BTreeMap<String, usize>,
    behind: u64,
    /// When its last answer came.
    finished: tokio::time::Instant,
}

/// An episode the load drives: its client, episode id and balancer key.
struct OpenEpisode {
    client: AgentServiceClient<tonic::transport::Channel>,
    id: String,
    key: tonic::metadata::MetadataValue<tonic::metadata::Ascii>,
}

/// When an episode's steps are due: step k at `start + offset + k * period`, none from `end`.
#[derive(Clone, Copy)]
struct Schedule {
    start: tokio::time::Instant,
    end: tokio::time::Instant,
    offset: Duration,
    period: Duration,
}

impl Schedule {
    fn due(&self, k: u64) -> tokio::time::Instant {
        self.start + self.offset + self.period.mul_f64(k as f64)
    }
}

/// Starts `config.episodes` episodes, each on its own connection once the server is SERVING.
async fn open_episodes(config: &LoadConfig) -> Result<Vec<OpenEpisode>, AgentError> {
    let mut episodes = Vec::with_capacity(config.episodes);
    for episode in 0..config.episodes {
        let channel = connect_when_serving(&config.target, Duration::from_secs(60)).await?;
        let mut client = AgentServiceClient::new(channel);
        let key = new_episode_key();
        let start = v1::StartEpisodeRequest {
            rig: Some(config.rig.clone()),
            client: format!("sim-bridge load episode {episode}"),
            ..Default::default()
        };
        let id = client
            .start_episode(keyed(start, &key))
            .await
            .map_err(|s| status_error("StartEpisode", &s))?
            .into_inner()
            .episode_id;
        episodes.push(OpenEpisode { client, id, key });
    }
    Ok(episodes)
}

/// Sends episode `episode`'s steps on `schedule` (templates cycled from template `episode`),
/// then ends it; steps that fell behind the schedule's end count with their wait so far.
async fn drive_episode(
    open: OpenEpisode,
    episode: usize,
    schedule: Schedule,
    templates: Arc<Vec<v1::StepRequest>>,
    progress: Arc<LoadProgress>,
    call_timeout: Duration,
) -> EpisodeResult {
    let OpenEpisode {
        mut client,
        id,
        key,
    } = open;
    let mut result = EpisodeResult {
        latencies: Vec::new(),
        codes: BTreeMap::new(),
        behind: 0,
        finished: schedule.start,
    };
    let mut k: u64 = 0;
    loop {
        let intended = schedule.due(k);
        if intended >= schedule.end {
            break;
        }
        if tokio::time::Instant::now() >= schedule.end {
            // Steps k.. were due before the end and never went out: each counts with its wait
            // so far as a lower bound of its latency.
            while schedule.due(k) < schedule.end {
                let due = schedule.due(k);
                result
                    .latencies
                    .push((schedule.end - due).as_secs_f64() * 1e3);
                result.behind += 1;
                k += 1;
            }
            break;
        }
        tokio::time::sleep_until(intended).await;
        let mut request = templates[(episode + k as usize) % templates.len()].clone();
        request.episode_id = id.clone();
        request.frame_index = k;
        let mut request = keyed(request, &key);
        request.set_timeout(call_timeout);
        let code = match client.step(request).await {
            Ok(_) => "Ok".to_string(),
            Err(status) => {
                progress.errors.fetch_add(1, Ordering::Relaxed);
                format!("{:?}", status.code())
            }
        };
        result
            .latencies
            .push(intended.elapsed().as_secs_f64() * 1e3);
        *result.codes.entry(code).or_default() += 1;
        progress.steps.fetch_add(1, Ordering::Relaxed);
        k += 1;
    }
    result.finished = tokio::time::Instant::now();
    let _ = client
        .end_episode(keyed(v1::EndEpisodeRequest { episode_id: id }, &key))
        .await;
    result
}

/// Runs the load; `templates` are cycled (episode `e` starts at template `e`).
pub async fn run_load(
    config: &LoadConfig,
    templates: Arc<Vec<v1::StepRequest>>,
    progress: Arc<LoadProgress>,
) -> Result<LoadReport, AgentError> {
    if templates.is_empty() {
        return Err(AgentError("no step templates to send".into()));
    }
    let period = Duration::try_from_secs_f64(1.0 / config.rate_hz).map_err(|_| {
        AgentError(format!(
            "a rate of {} Hz has no usable period",
            config.rate_hz
        ))
    })?;
    // Open every episode first, so set-up time never counts against the schedule.
    let episodes = open_episodes(config).await?;
    let start = tokio::time::Instant::now() + Duration::from_millis(100);
    let end = start + config.duration;
    let mut tasks = Vec::with_capacity(config.episodes);
    for (episode, open) in episodes.into_iter().enumerate() {
        let schedule = Schedule {
            start,
            end,
            // Episodes tick spread over one period, as independent simulators would.
            offset: period.mul_f64(episode as f64 / config.episodes as f64),
            period,
        };
        tasks.push(tokio::spawn(drive_episode(
            open,
            episode,
            schedule,
            Arc::clone(&templates),
            Arc::clone(&progress),
            config.call_timeout,
        )));
    }
    let mut latencies = Vec::new();
    let mut codes = BTreeMap::new();
    let mut behind = 0;
    let mut finished = start;
    for task in tasks {
        let result = task
            .await
            .map_err(|e| AgentError(format!("a load episode failed: {e}")))?;
        latencies.extend(result.latencies);
        for (code, n) in result.codes {
            *codes.entry(code).or_default() += n;
        }
        behind += result.behind;
        finished = finished.max(result.finished);
    }
    let duration_s = (finished - start).as_secs_f64();
    let count = codes.values().sum();
    Ok(LoadReport {
        episodes: config.episodes,
        rate_hz: config.rate_hz,
        duration_s,
        count,
        rps: count as f64 / duration_s,
        latency_ms: Percentiles::of(latencies),
        codes,
        behind_schedule: behind,
    })
}
