//! Server settings: every knob of `ssr-agent serve`, with defaults, read from a TOML file and
//! then overridden by the environment and the command line (in that order of precedence,
//! lowest first). [`ServeConfig::validate`] names the first bad field.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};
use ssrdrive_proto::camera::{MAX_CAMERAS, MAX_IMAGE_PIXELS};
use ssrdrive_support::error_text::clipped;
use ssrdrive_support::files::{CappedReadError, read_capped_text};
use ssrdrive_support::ranges::first_outside;

use crate::device::Backend;
use crate::history::History;

/// Largest config file read, bytes.
const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// How logs are written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// One readable line per event.
    #[default]
    Human,
    /// One JSON object per event (for log collectors).
    Json,
}

/// Settings of one server process.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServeConfig {
    /// gRPC address (`IP:PORT` or `HOST:PORT`); port 0 picks a free port (printed on stdout as
    /// `listening on ADDR`).
    #[serde(deserialize_with = "listen_text")]
    pub listen: SocketAddr,
    /// Prometheus `/metrics` address; `None` (`"off"` in a file) serves no metrics.
    #[serde(with = "metrics_listen_text")]
    pub metrics_listen: Option<SocketAddr>,
    /// A checkpoint file written by `ssr-agent train`.
    pub checkpoint: Option<PathBuf>,
    /// Serve a network with random weights of this config preset instead of a checkpoint
    /// (for tests and benchmarks; it does not drive).
    pub untrained_config: Option<String>,
    /// Most episodes open at once; more get RESOURCE_EXHAUSTED.
    pub max_episodes: usize,
    /// An episode with no request for this long is closed, seconds.
    pub idle_timeout_s: f64,
    /// Largest forward pass formed from concurrent steps; 1 turns batching off.
    pub max_batch: usize,
    /// How long the first step of a batch waits for others, milliseconds.
    pub max_queue_delay_ms: f64,
    /// Steps waiting for the network at most; more get RESOURCE_EXHAUSTED.
    pub max_queue: usize,
    /// Model threads, each forming and running its own batches. Two forward passes side by
    /// side fill a 2-core CPU better than one spread over both (see agent/README.md, "Serving figures").
    pub model_threads: usize,
    /// Size of the rayon pool each model thread gets to itself, or 0: every model thread uses
    /// rayon's global pool (one thread per core). Own pools keep one model thread's work off another's
    /// threads when several episodes run at once (`sim-bridge eval --jobs N` gives its local
    /// server N model threads with the cores shared out); the global pool gives a lone episode
    /// every core (one episode on 2 cores: 11 ms a step, 14-15 ms on a 1-thread pool).
    pub compute_threads: usize,
    /// Longest a request may take, seconds (a client deadline that is shorter wins).
    pub request_timeout_s: f64,
    /// Largest request accepted, MiB.
    pub max_message_mib: usize,
    /// Most pixels one step may carry over all its cameras: a rig over it is refused at
    /// `StartEpisode` (RESOURCE_EXHAUSTED).
    pub max_pixels_per_step: u64,
    /// Memory for the decoded images of every step in flight together, MiB
    /// ([`DECODED_BYTES_PER_PIXEL`] per pixel): a step that would go past it is refused
    /// (RESOURCE_EXHAUSTED; retry), so concurrent large rigs cannot take the server's memory.
    pub max_decoded_mib: usize,
    /// After a shutdown signal: seconds to report NOT_SERVING before refusing new
    /// connections, so load balancers move away.
    pub drain_grace_s: f64,
    /// After that, longest wait for in-flight requests, seconds.
    pub drain_timeout_s: f64,
    /// Log format.
    pub log_format: LogFormat,
    /// Where the network runs: the CPU, or a GPU through wgpu (a build with the `wgpu`
    /// feature).
    pub backend: Backend,
    /// The controller's unstick rule (creep along the plan after a long stop; see
    /// `ssr_control::unstick`) on or off for every episode; `None` keeps the checkpoint's
    /// setting.
    pub unstick: Option<bool>,
    /// The controller's safety stop (brake where the network's occupancy head believes the
    /// path just ahead occupied; see `ssr_control::safety`) on or off for every episode;
    /// `None` keeps the checkpoint's setting. On needs a checkpoint with the head.
    pub safety_stop: Option<bool>,
    /// Whether the safety stop also brakes for where the motion head believes road users will
    /// be (`ssr_control::safety`); `None` keeps the checkpoint's setting. On needs a checkpoint
    /// with the head.
    pub safety_motion: Option<bool>,
    /// How the network gets its history ([`History`]: training's chain, or the
    /// recursion of checkpoints validated before it) for every episode; `None` keeps the
    /// checkpoint's setting.
    pub history: Option<History>,
    /// This server's name among replicas, sent with every answer as `x-ssrdrive-replica`
    /// metadata; `None`: `HOSTNAME:PORT`.
    pub replica_id: Option<String>,
}

impl Default for ServeConfig {
    fn default() -> Self {
        Self {
            listen: SocketAddr::from(([127, 0, 0, 1], 50051)),
            metrics_listen: Some(SocketAddr::from(([127, 0, 0, 1], 9090))),
            checkpoint: None,
            untrained_config: None,
            max_episodes: 64,
            idle_timeout_s: 60.0,
            max_batch: 8,
            max_queue_delay_ms: 2.0,
            max_queue: 256,
            model_threads: 2,
            compute_threads: 0,
            request_timeout_s: 30.0,
            // Six 1600x900 RGB cameras are 25.9 MB; a 900x256 frame is 0.7 MB.
            max_message_mib: 64,
            max_pixels_per_step: 6 * 1600 * 900,
            max_decoded_mib: 1024,
            drain_grace_s: 0.0,
            drain_timeout_s: 30.0,
            log_format: LogFormat::Human,
            backend: Backend::Cpu,
            unstick: None,
            safety_stop: None,
            safety_motion: None,
            history: None,
            replica_id: None,
        }
    }
}

/// Bytes a step's decoded image takes per pixel while it is in flight: RGB8, and a
/// conversion's scratch.
pub const DECODED_BYTES_PER_PIXEL: usize = 4;

/// Longest idle or request timeout, seconds (a week).
pub const MAX_TIMEOUT_S: f64 = 604_800.0;
const TIMEOUT_RULE: &str = "must be in (0, 604800] seconds";
/// Longest drain grace or drain timeout, seconds (an hour).
pub const MAX_DRAIN_S: f64 = 3_600.0;
const DRAIN_RULE: &str = "must be in [0, 3600] seconds";
/// Longest replica id, characters.
const MAX_REPLICA_ID_LEN: usize = 128;

/// Why a config cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ServeConfigError {
    /// The config file could not be read (or is over the size cap).
    #[error("reading {path}: {source}")]
    Io {
        /// The config file.
        path: PathBuf,
        /// Why the read failed.
        source: CappedReadError,
    },
    /// The config file is not valid TOML for [`ServeConfig`].
    #[error("{path}: {message}")]
    Parse {
        /// The config file.
        path: PathBuf,
        /// The TOML parser's message.
        message: String,
    },
    /// A setting is out of range.
    #[error("{field} = {value}: {rule}")]
    Invalid {
        /// The setting's name.
        field: &'static str,
        /// Its value, as text.
        value: String,
        /// The range or rule it breaks.
        rule: String,
    },
}

impl ServeConfig {
    /// Reads a TOML file; fields it leaves out keep their defaults.
    pub fn from_file(path: &Path) -> Result<Self, ServeConfigError> {
        let text =
            read_capped_text(path, MAX_CONFIG_BYTES).map_err(|source| ServeConfigError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        Self::from_toml(&text, path)
    }

    /// Parses TOML text (`path` names it in errors); fields it leaves out keep their defaults.
    pub fn from_toml(text: &str, path: &Path) -> Result<Self, ServeConfigError> {
        toml::from_str(text).map_err(|e| ServeConfigError::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// Checks every field against its rule.
    pub fn validate(&self) -> Result<(), ServeConfigError> {
        fn invalid(
            field: &'static str,
            value: impl ToString,
            rule: impl Into<String>,
        ) -> Result<(), ServeConfigError> {
            Err(ServeConfigError::Invalid {
                field,
                value: value.to_string(),
                rule: rule.into(),
            })
        }
        // Durations stay far below what `Duration` and the clock can hold (1e308 s panics).
        let timeout = |v: f64| v > 0.0 && v <= MAX_TIMEOUT_S;
        let drain = |v: f64| (0.0..=MAX_DRAIN_S).contains(&v);
        if let Some(id) = &self.replica_id {
            let printable = id.bytes().all(|b| b.is_ascii_graphic());
            if id.is_empty() || id.len() > MAX_REPLICA_ID_LEN || !printable {
                return invalid(
                    "replica_id",
                    clipped(id),
                    "must be 1 to 128 printable ASCII characters without spaces",
                );
            }
        }
        // Counts (usize widens to u64 without loss); compute_threads 0 is rayon's global pool.
        let counts = [
            ("max_episodes", self.max_episodes as u64, 1, 100_000),
            ("max_batch", self.max_batch as u64, 1, 256),
            ("model_threads", self.model_threads as u64, 1, 64),
            ("compute_threads", self.compute_threads as u64, 0, 1024),
            ("max_queue", self.max_queue as u64, 1, 100_000),
            ("max_message_mib", self.max_message_mib as u64, 1, 1024),
            (
                "max_pixels_per_step",
                self.max_pixels_per_step,
                1,
                MAX_CAMERAS as u64 * MAX_IMAGE_PIXELS,
            ),
            ("max_decoded_mib", self.max_decoded_mib as u64, 1, 65_536),
        ];
        if let Some(out) = first_outside(counts) {
            return invalid(out.name, out.value, format!("must be in {}", out.range));
        }
        let durations = [
            (
                "idle_timeout_s",
                self.idle_timeout_s,
                timeout(self.idle_timeout_s),
                TIMEOUT_RULE,
            ),
            (
                "max_queue_delay_ms",
                self.max_queue_delay_ms,
                (0.0..=1000.0).contains(&self.max_queue_delay_ms),
                "must be in [0, 1000]",
            ),
            (
                "request_timeout_s",
                self.request_timeout_s,
                timeout(self.request_timeout_s),
                TIMEOUT_RULE,
            ),
            (
                "drain_grace_s",
                self.drain_grace_s,
                drain(self.drain_grace_s),
                DRAIN_RULE,
            ),
            (
                "drain_timeout_s",
                self.drain_timeout_s,
                drain(self.drain_timeout_s),
                DRAIN_RULE,
            ),
        ];
        if let Some((name, value, _, rule)) = durations.into_iter().find(|d| !d.2) {
            return invalid(name, format!("{value:?}"), rule);
        }
        if self.checkpoint.is_some() && self.untrained_config.is_some() {
            return invalid(
                "untrained_config",
                self.untrained_config.as_deref().unwrap_or_default(),
                "cannot be combined with checkpoint",
            );
        }
        Ok(())
    }

    /// [`ServeConfig::idle_timeout_s`] as a duration.
    pub fn idle_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.idle_timeout_s)
    }

    /// [`ServeConfig::max_queue_delay_ms`] as a duration.
    pub fn max_queue_delay(&self) -> Duration {
        Duration::from_secs_f64(self.max_queue_delay_ms / 1000.0)
    }

    /// [`ServeConfig::request_timeout_s`] as a duration.
    pub fn request_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.request_timeout_s)
    }

    /// [`ServeConfig::max_message_mib`] in bytes.
    pub fn max_message_bytes(&self) -> usize {
        self.max_message_mib << 20
    }

    /// [`ServeConfig::max_decoded_mib`] in bytes.
    pub fn max_decoded_bytes(&self) -> usize {
        self.max_decoded_mib << 20
    }
}

/// An address to listen on, `IP:PORT` or `HOST:PORT` (`localhost:50051`; a name is resolved
/// by the system, an IPv4 address preferred).
pub fn parse_listen(text: &str) -> Result<SocketAddr, String> {
    if let Ok(address) = text.parse() {
        return Ok(address);
    }
    let resolved: Vec<SocketAddr> = std::net::ToSocketAddrs::to_socket_addrs(text)
        .map_err(|e| format!("'{text}': {e}; expected IP:PORT or HOST:PORT, e.g. 127.0.0.1:50051"))?
        .collect();
    resolved
        .iter()
        .find(|a| a.is_ipv4())
        .or(resolved.first())
        .copied()
        .ok_or_else(|| format!("'{text}' names no address; expected IP:PORT or HOST:PORT"))
}

/// A metrics address as the flag, its variable and config files write it: `HOST:PORT`, or
/// `off` for none.
pub fn parse_metrics_listen(text: &str) -> Result<Option<SocketAddr>, String> {
    if text == "off" {
        return Ok(None);
    }
    parse_listen(text)
        .map(Some)
        .map_err(|e| format!("{e} (or `off`)"))
}

/// [`ServeConfig::listen`] from a file: an address or a host name ([`parse_listen`]).
fn listen_text<'de, D: serde::Deserializer<'de>>(input: D) -> Result<SocketAddr, D::Error> {
    parse_listen(&String::deserialize(input)?).map_err(serde::de::Error::custom)
}

/// [`ServeConfig::metrics_listen`] as text in files (TOML has no null for "none").
mod metrics_listen_text {
    use serde::de::Error;
    use serde::{Deserialize, Deserializer, Serializer};
    use std::net::SocketAddr;

    pub fn serialize<S: Serializer>(value: &Option<SocketAddr>, out: S) -> Result<S::Ok, S::Error> {
        match value {
            Some(address) => out.collect_str(address),
            None => out.serialize_str("off"),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(
        input: D,
    ) -> Result<Option<SocketAddr>, D::Error> {
        super::parse_metrics_listen(&String::deserialize(input)?).map_err(D::Error::custom)
    }
}
