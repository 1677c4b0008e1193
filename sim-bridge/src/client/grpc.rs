//! [`GrpcAgent`]: an [`Agent`] that drives through a remote `ssrdrive.v1.AgentService`. One
//! episode per route: `StartEpisode` with the rig in `start_route`, one `Step` per tick with the
//! rendered frames, `EndEpisode` in `end_route`. Any refused or failed call crashes the route
//! (the leaderboard's "Failed - Agent crashed") with the server's status in the message. Every
//! call of an episode carries the same key of this client's choosing as
//! `x-ssrdrive-episode-key` metadata ([`ssrdrive_proto::EPISODE_KEY_HEADER`]), which a load
//! balancer in front of several servers hashes to keep the episode on one replica.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use glam::DVec2;
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::v1::agent_service_client::AgentServiceClient;
use ssrdrive_proto::{v1, wire};
use tonic::metadata::{Ascii, MetadataValue};
use tonic::transport::{Channel, Endpoint};
use tonic_health::pb::health_check_response::ServingStatus;
use tonic_health::pb::health_client::HealthClient;

use crate::driver::{Agent, AgentError, Observation, RouteContext};
use crate::world::World;

/// Connection settings.
#[derive(Debug, Clone)]
pub struct GrpcOptions {
    /// Rig to render and send; `None` takes the one the server expects.
    pub rig: Option<Rig>,
    /// Deadline of each call.
    pub call_timeout: Duration,
    /// How long to wait for the server to report SERVING (it warms up first).
    pub ready_timeout: Duration,
    /// Free text the server logs with each episode.
    pub client: String,
    /// Largest response accepted, bytes.
    pub max_message_bytes: usize,
}

impl Default for GrpcOptions {
    fn default() -> Self {
        Self {
            rig: None,
            call_timeout: Duration::from_secs(30),
            ready_timeout: Duration::from_secs(120),
            client: "sim-bridge".into(),
            max_message_bytes: 64 << 20,
        }
    }
}

/// A remote agent; see the module doc.
pub struct GrpcAgent {
    runtime: tokio::runtime::Runtime,
    client: AgentServiceClient<Channel>,
    target: String,
    info: v1::AgentInfo,
    rig: Rig,
    options: GrpcOptions,
    episode: Option<String>,
    /// The current episode's balancer key (see the module doc).
    episode_key: Option<MetadataValue<Ascii>>,
    trajectory: Vec<DVec2>,
}

/// A key no other episode of any client is likely to choose: this process, a count of its
/// episodes and the clock.
pub fn new_episode_key() -> MetadataValue<Ascii> {
    static EPISODES: AtomicU64 = AtomicU64::new(0);
    let count = EPISODES.fetch_add(1, Ordering::Relaxed);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    format!("{:x}-{count:x}-{nanos:x}", std::process::id())
        .parse()
        .expect("hex digits and dashes are valid metadata")
}

/// A failed call as an agent error: `what: CODE: message`.
pub fn status_error(what: &str, status: &tonic::Status) -> AgentError {
    AgentError(format!("{what}: {:?}: {}", status.code(), status.message()))
}

/// `grpc://host:port` or `http://host:port` (or a bare `host:port`) as a tonic URI.
fn endpoint_uri(target: &str) -> String {
    let address = target
        .strip_prefix("grpc://")
        .or_else(|| target.strip_prefix("http://"))
        .unwrap_or(target);
    format!("http://{address}")
}

impl GrpcAgent {
    /// Connects to `target` (see [`endpoint_uri`]), waits until the server reports SERVING and
    /// reads what it runs.
    pub fn connect(target: &str, options: GrpcOptions) -> Result<Self, AgentError> {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| AgentError(format!("starting the client runtime: {e}")))?;
        let channel = runtime.block_on(connect_when_serving(target, options.ready_timeout))?;
        let mut client = AgentServiceClient::new(channel)
            .max_decoding_message_size(options.max_message_bytes)
            .max_encoding_message_size(options.max_message_bytes);
        let mut request = tonic::Request::new(v1::GetAgentInfoRequest {});
        request.set_timeout(options.call_timeout);
        let info = runtime
            .block_on(client.get_agent_info(request))
            .map_err(|s| status_error(&format!("GetAgentInfo on {target}"), &s))?
            .into_inner();
        let rig = match &options.rig {
            Some(rig) => rig.clone(),
            None => wire::rig_from_proto(info.expected_rig.as_ref().unwrap_or(&v1::Rig::default()))
                .map_err(|e| AgentError(format!("{target} reports an unusable rig: {e}")))?,
        };
        Ok(Self {
            runtime,
            client,
            target: target.to_string(),
            info,
            rig,
            options,
            episode: None,
            episode_key: None,
            trajectory: Vec::new(),
        })
    }

    /// A call with the deadline and, within an episode, its balancer key.
    fn timed<T>(&self, message: T) -> tonic::Request<T> {
        let mut request = match &self.episode_key {
            Some(key) => keyed(message, key),
            None => tonic::Request::new(message),
        };
        request.set_timeout(self.options.call_timeout);
        request
    }

    fn end_episode(&mut self) {
        if let Some(episode_id) = self.episode.take() {
            let request = self.timed(v1::EndEpisodeRequest {
                episode_id: episode_id.clone(),
            });
            if let Err(status) = self.runtime.block_on(self.client.end_episode(request)) {
                tracing::warn!("EndEpisode {episode_id}: {}", status.message());
            }
        }
    }
}

/// `message` as a call of the episode whose balancer key is `key`.
pub fn keyed<T>(message: T, key: &MetadataValue<Ascii>) -> tonic::Request<T> {
    let mut request = tonic::Request::new(message);
    request
        .metadata_mut()
        .insert(ssrdrive_proto::EPISODE_KEY_HEADER, key.clone());
    request
}

/// How long [`connect_when_serving`] waits before it says that it is waiting.
const WAIT_QUIETLY: Duration = Duration::from_secs(5);

/// Connects to `target` and polls `grpc.health.v1.Health/Check` until the whole server reports
/// SERVING, all within `timeout` (each attempt is bounded too, so a stalled server cannot hold
/// it up); after 5 s it warns, once, that it is still waiting and why.
pub async fn connect_when_serving(target: &str, timeout: Duration) -> Result<Channel, AgentError> {
    let endpoint = Endpoint::from_shared(endpoint_uri(target))
        .map_err(|e| AgentError(format!("'{target}' is not a server address: {e}")))?
        .connect_timeout(Duration::from_secs(5));
    let started = tokio::time::Instant::now();
    let deadline = started + timeout;
    let mut said_waiting = false;
    loop {
        let attempt = async {
            let channel = endpoint.connect().await.map_err(|e| {
                let e = ssrdrive_support::error_text::error_text(&anyhow::Error::new(e));
                format!("connecting: {e}")
            })?;
            let reply = HealthClient::new(channel.clone())
                .check(tonic_health::pb::HealthCheckRequest::default())
                .await
                .map_err(|status| format!("health check: {}", status.message()))?;
            match reply.get_ref().status() {
                ServingStatus::Serving => Ok(channel),
                other => Err(format!("health {other:?}")),
            }
        };
        let left = deadline.saturating_duration_since(tokio::time::Instant::now());
        let last = match tokio::time::timeout(left.min(Duration::from_secs(10)), attempt).await {
            Ok(Ok(channel)) => return Ok(channel),
            Ok(Err(problem)) => problem,
            Err(_) => "no answer in time".to_string(),
        };
        if tokio::time::Instant::now() >= deadline {
            return Err(AgentError(format!(
                "{target} was not SERVING within {:.0} s ({last})",
                timeout.as_secs_f64()
            )));
        }
        if !said_waiting && started.elapsed() >= WAIT_QUIETLY {
            // A server warming up is expected; a wrong address should not look like a hang.
            tracing::warn!(
                "{target} is not serving yet ({last}); retrying for up to {:.0} s",
                timeout.as_secs_f64()
            );
            said_waiting = true;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

impl Agent for GrpcAgent {
    fn name(&self) -> String {
        format!(
            "{} ({}) at {}",
            self.info.model, self.info.config_name, self.target
        )
    }

    fn identity(&self) -> String {
        let info = &self.info;
        format!(
            "{} ({}) {}, ssr-agent {}",
            info.model, info.config_name, info.checkpoint, info.version
        )
    }

    fn start_route(&mut self, _ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.end_episode();
        self.trajectory.clear();
        self.episode_key = Some(new_episode_key());
        let request = self.timed(v1::StartEpisodeRequest {
            rig: Some(wire::rig_to_proto(&self.rig)),
            client: self.options.client.clone(),
            ..Default::default()
        });
        let reply = self
            .runtime
            .block_on(self.client.start_episode(request))
            .map_err(|s| status_error("StartEpisode", &s))?;
        self.episode = Some(reply.into_inner().episode_id);
        Ok(())
    }

    fn end_route(&mut self) {
        self.end_episode();
    }

    fn planned_trajectory(&self) -> Vec<DVec2> {
        self.trajectory.clone()
    }

    fn sensors(&self) -> Option<Rig> {
        Some(self.rig.clone())
    }

    fn run_step(&mut self, obs: &Observation, _world: &World<'_>) -> Result<Control, AgentError> {
        self.step(obs, false).map(|(control, _)| control)
    }
}

impl GrpcAgent {
    /// One `Step`; with `debug`, the server's debug block (token attention and occupancy maps,
    /// both control branches) comes back too, when the server gives one.
    pub fn step(
        &mut self,
        obs: &Observation,
        debug: bool,
    ) -> Result<(Control, Option<v1::Debug>), AgentError> {
        let episode = self
            .episode
            .as_deref()
            .ok_or_else(|| AgentError("run_step before start_route".into()))?;
        let request = self.timed(v1::StepRequest {
            debug,
            ..obs.step_request(episode)
        });
        let reply = self
            .runtime
            .block_on(self.client.step(request))
            .map_err(|s| status_error(&format!("Step {}", obs.frame), &s))?
            .into_inner();
        self.trajectory = reply
            .trajectory
            .iter()
            .map(|p| DVec2::new(p.x, p.y))
            .collect();
        let control = reply
            .control
            .ok_or_else(|| AgentError(format!("Step {}: the answer has no control", obs.frame)))?;
        Ok((wire::control_from_proto(&control), reply.debug))
    }
}

impl Drop for GrpcAgent {
    fn drop(&mut self) {
        self.end_episode();
    }
}
