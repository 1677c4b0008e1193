//! Expert driving datasets: the on-disk format and the [`Dataset`] reader that training uses
//! (the recorder and the collector that write them are sim-bridge's `dataset` module).
//!
//! # Layout (format version 1)
//! ```text
//! <root>/manifest.json                    Manifest: rig, rate, counts, sizes, towns, episodes
//! <root>/episodes/<name>/episode.json     EpisodeInfo: town, route, seed, rig, noise, outcome
//! <root>/episodes/<name>/measurements.jsonl   one FrameRecord per line, in time order
//! <root>/episodes/<name>/<camera>/<index:06>.png   RGB8 frames, one folder per camera
//! ```
//! Every file is plain JSON or PNG, so a dataset can be inspected with `jq` and an image
//! viewer, and read one episode (one line) at a time. Every file is read capped
//! ([`read_capped`]): JSON at 512 MiB, PNG at 64 MiB.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::camera::Rig;
use crate::control::Control;
use crate::image::{RgbImage, decode_png};
use ssrdrive_support::files::{FileError, read_capped};

/// Value of [`Manifest::format`].
pub const FORMAT: &str = "ssrdrive-dataset";
/// Value of [`Manifest::version`].
pub const VERSION: u32 = 1;
/// Spacing of the future waypoints and controls, seconds.
pub const FUTURE_STEP: f64 = 0.5;
/// Number of future waypoints and controls (3 s).
pub const FUTURE_COUNT: usize = 6;
/// Largest JSON file read (manifest, episode, measurements), bytes.
const MAX_JSON_BYTES: u64 = 512 * 1024 * 1024;
/// Largest PNG read, bytes.
const MAX_PNG_BYTES: u64 = 64 * 1024 * 1024;

/// Why the expert slows or stops: the kind of the nearest obstacle, or the forecast.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BrakeReason {
    /// A vehicle or cyclist on the path.
    Vehicle,
    /// A walker on the path.
    Walker,
    /// A static obstacle or parked car on the path.
    Obstacle,
    /// A red light, or a yellow one it can still stop for.
    TrafficLight,
    /// A stop sign it has not yet stopped at.
    StopSign,
    /// Traffic on the lane it must change into.
    LaneChange,
    /// The collision forecast.
    PredictedCollision,
}

/// One stored frame: what the agent observed, what the expert did and what came next.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Position in the episode, from 0.
    pub index: usize,
    /// Simulator tick (20 Hz) it was taken at.
    pub tick: u64,
    /// Simulation time, s.
    pub time: f64,
    /// Forward speed, m/s.
    pub speed: f64,
    /// Ego box centre on the ground, world frame (OpenDRIVE: x east, y north, z up), m.
    pub position: [f64; 3],
    /// Heading, rad counter-clockwise from +x.
    pub yaw: f64,
    /// Route-follower command, CARLA RoadOption value (1 left ... 6 change lane right).
    pub command: i32,
    /// Route-follower target point, ego frame (x forward, y left), m.
    pub target_point: [f64; 2],
    /// The expert's control: the training label (steer +1 = full right).
    pub control: Control,
    /// The control actually applied (differs from `control` while noise is injected).
    pub executed: Control,
    /// Whether injected noise was steering the car on this tick.
    pub noise: bool,
    /// Why the expert brakes or holds still, if it does for a hazard.
    pub brake_reason: Option<BrakeReason>,
    /// Future ego positions every [`FUTURE_STEP`] s, in this frame's ego frame, m: where the
    /// car went (perturbations included).
    pub waypoints: Vec<[f64; 2]>,
    /// The expert's plan from this frame's state ([`FUTURE_COUNT`] waypoints every
    /// [`FUTURE_STEP`] s on the route's centre line, ego frame, m): where it means to go, the
    /// trajectory label (inside a perturbation it leads back to the lane, where `waypoints`
    /// follow the drift). Empty in datasets recorded before it existed.
    #[serde(default)]
    pub plan: Vec<[f64; 2]>,
    /// The expert's control at the same future instants.
    pub future_controls: Vec<Control>,
    /// False when the route ended before the last future instant (then fewer than
    /// [`FUTURE_COUNT`] waypoints are given).
    pub future_complete: bool,
    /// Image files relative to the episode folder, in rig order.
    pub images: Vec<String>,
    /// The road users and obstacles within [`ACTOR_RANGE`] of the ego (privileged ground
    /// truth, a training aid: BEV occupancy targets). `None` in datasets recorded before it
    /// existed, which is not the same as none near.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actors: Option<Vec<ActorRecord>>,
    /// The traffic light whose stop line ends a lane of the route ahead, nearest first, within
    /// the expert's scan (privileged ground truth, a training aid: the light head's label).
    /// `None` in datasets recorded before it existed; [`LightAhead::None`] when no light is
    /// ahead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light: Option<LightAhead>,
    /// Whether the head of [`FrameRecord::light`]'s light projects into a frame of the rig
    /// (privileged ground truth): where it does not (a head at the kerb beside the stopped ego,
    /// above the top of the frame), no camera shows its state. `None` without a light ahead
    /// and in datasets recorded before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_in_view: Option<bool>,
}

/// The light that governs the ego's route ahead, and the free distance from the ego's front to
/// its stop line (m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum LightAhead {
    /// No light on the route within the scan.
    None,
    /// Go.
    Green {
        /// Metres from the ego's front to the stop line.
        distance: f64,
    },
    /// Stop if you can.
    Yellow {
        /// Metres from the ego's front to the stop line.
        distance: f64,
    },
    /// Stop.
    Red {
        /// Metres from the ego's front to the stop line.
        distance: f64,
    },
}

/// How far from the ego's centre [`FrameRecord::actors`] reaches, m (the default BEV's corners
/// are 47 m away).
pub const ACTOR_RANGE: f64 = 50.0;

/// What a recorded actor is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActorClass {
    /// A car, moving or parked.
    Vehicle,
    /// A cyclist.
    Cyclist,
    /// A pedestrian.
    Walker,
    /// A static prop or obstacle.
    Static,
}

/// An actor's ground box in the ego frame of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ActorRecord {
    /// What it is.
    pub class: ActorClass,
    /// Box centre, ego frame (x forward, y left), m.
    pub centre: [f64; 2],
    /// Heading of the box's length axis relative to the ego's, rad counter-clockwise.
    pub yaw: f64,
    /// Half length and half width, m.
    pub half: [f64; 2],
}

/// Noise injection: now and then the executed control is pushed off the expert's for a short
/// while, laterally (a steering offset) or, for a share of the perturbations, longitudinally (the
/// pedals held: coasting with a light brake, or pressing on); the recorded labels stay the
/// expert's own (its correction).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseConfig {
    /// Perturbations started per simulated second, on average (0 = none).
    pub rate: f64,
    /// Duration of one perturbation, s (drawn uniformly in this range).
    pub duration: [f64; 2],
    /// Steering offset magnitude (drawn uniformly, random sign).
    pub steer: [f64; 2],
    /// Share of the perturbations that act on the pedals instead of the steering.
    #[serde(default)]
    pub longitudinal: f64,
}

impl Default for NoiseConfig {
    fn default() -> Self {
        Self {
            rate: 0.1,
            duration: [0.5, 1.0],
            steer: [0.1, 0.3],
            longitudinal: 0.0,
        }
    }
}

/// How one episode ended in the simulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeOutcome {
    /// The leaderboard status ("Completed", "Failed - Agent got blocked", ...).
    pub status: String,
    /// Route completion, percent.
    pub route_completion: f64,
    /// Driving score of the run (noise included).
    pub driving_score: f64,
    /// Simulated seconds.
    pub sim_seconds: f64,
}

/// `episode.json`: everything about one recorded route run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeInfo {
    /// Folder name under `episodes/`.
    pub name: String,
    /// Town (map) the route runs in.
    pub town: String,
    /// Route set the route comes from, as named to the collector.
    pub route_set: String,
    /// Route id within its set.
    pub route_id: String,
    /// Repetition of the route, from 0.
    pub repetition: usize,
    /// World seed (traffic, scenarios, lights, appearance, noise).
    pub seed: u64,
    /// Cameras the frames were taken with.
    pub rig: Rig,
    /// Stored frames per simulated second.
    pub rate_hz: f64,
    /// Simulator ticks (20 Hz) between stored frames.
    pub ticks_per_frame: u64,
    /// Noise injected into the executed control.
    pub noise: NoiseConfig,
    /// Who drove, when not the expert (DAgger: the learner, labelled by the expert).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub driver: Option<String>,
    /// Whether camera frames were drawn in a look varied from the seed.
    pub randomise_appearance: bool,
    /// Frames stored.
    pub frames: usize,
    /// Frames whose future was cut by the end of the route.
    pub truncated_frames: usize,
    /// Bytes of images and measurements.
    pub bytes: u64,
    /// Score and status of the run.
    pub outcome: EpisodeOutcome,
    /// Wall-clock time the run took to simulate and record, s.
    pub wall_seconds: f64,
}

/// Per-town totals in the manifest.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TownCount {
    /// Episodes recorded in the town.
    pub episodes: usize,
    /// Frames recorded in the town.
    pub frames: usize,
}

/// An episode as the manifest lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeEntry {
    /// Folder name under `episodes/`.
    pub name: String,
    /// Town (map) the route runs in.
    pub town: String,
    /// Route set the route comes from.
    pub route_set: String,
    /// Route id within its set.
    pub route_id: String,
    /// Frames stored.
    pub frames: usize,
}

/// `manifest.json`: the dataset at a glance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT`].
    pub format: String,
    /// Always [`VERSION`].
    pub version: u32,
    /// Cameras every episode was recorded with.
    pub rig: Rig,
    /// Stored frames per simulated second.
    pub rate_hz: f64,
    /// Spacing of the future waypoints and controls, s ([`FUTURE_STEP`]).
    pub future_step_s: f64,
    /// Future waypoints and controls per frame ([`FUTURE_COUNT`]).
    pub future_count: usize,
    /// Complete episodes.
    pub episodes: usize,
    /// Frames over all episodes.
    pub frames: usize,
    /// Frames over all episodes whose future was cut by the end of the route.
    pub truncated_frames: usize,
    /// Bytes of images and measurements over all episodes.
    pub bytes: u64,
    /// Episode and frame totals per town, by town name.
    pub towns: BTreeMap<String, TownCount>,
    /// Every complete episode, sorted by name.
    pub episode_list: Vec<EpisodeEntry>,
}

/// A dataset that cannot be read, with the file and the problem.
pub type DatasetError = FileError;

/// A whole file, refusing one over `limit` bytes.
fn read_limited(path: &Path, limit: u64) -> Result<Vec<u8>, DatasetError> {
    read_capped(path, limit).map_err(|e| DatasetError::read(path, e))
}

/// A JSON file of a dataset (`manifest.json`, `episode.json`), read capped.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, DatasetError> {
    let bytes = read_limited(path, MAX_JSON_BYTES)?;
    serde_json::from_slice(&bytes).map_err(|e| DatasetError::invalid(path, e.to_string()))
}

/// A dataset opened for reading.
#[derive(Debug, Clone)]
pub struct Dataset {
    root: PathBuf,
    /// The dataset's `manifest.json`.
    pub manifest: Manifest,
}

impl Dataset {
    /// Open the dataset at `root` (reads only the manifest).
    pub fn open(root: &Path) -> Result<Self, DatasetError> {
        let path = root.join("manifest.json");
        let manifest: Manifest = read_json(&path)?;
        if manifest.format != FORMAT || manifest.version != VERSION {
            return Err(DatasetError::invalid(
                &path,
                format!(
                    "format {} version {}, expected {FORMAT} version {VERSION}",
                    manifest.format, manifest.version
                ),
            ));
        }
        Ok(Self {
            root: root.to_path_buf(),
            manifest,
        })
    }

    /// Folder of an episode (the name is made file-name-safe first, as collection made it).
    pub fn episode_dir(&self, name: &str) -> PathBuf {
        self.root.join("episodes").join(safe_name(name))
    }

    /// An episode's `episode.json`.
    pub fn episode(&self, name: &str) -> Result<EpisodeInfo, DatasetError> {
        read_json(&self.episode_dir(name).join("episode.json"))
    }

    /// An episode's frame records, in time order. A line that does not parse, or records out
    /// of order, is an error naming the line.
    pub fn frames(&self, name: &str) -> Result<Vec<FrameRecord>, DatasetError> {
        let path = self.episode_dir(name).join("measurements.jsonl");
        parse_frames(&read_limited(&path, MAX_JSON_BYTES)?, &path)
    }

    /// The images of one frame, in rig order.
    pub fn images(&self, name: &str, record: &FrameRecord) -> Result<Vec<RgbImage>, DatasetError> {
        let dir = self.episode_dir(name);
        record
            .images
            .iter()
            .map(|rel| {
                if rel.contains("..") || Path::new(rel).is_absolute() {
                    return Err(DatasetError::invalid(
                        &dir,
                        format!("image path {rel} leaves the episode"),
                    ));
                }
                let path = dir.join(rel);
                let bytes = read_limited(&path, MAX_PNG_BYTES)?;
                decode_png(&bytes).map_err(|e| DatasetError::invalid(&path, e.to_string()))
            })
            .collect()
    }
}

/// Frame records from the bytes of a `measurements.jsonl` (`path` names it in errors). A line
/// that does not parse, or records out of order, is an error naming the line.
pub fn parse_frames(bytes: &[u8], path: &Path) -> Result<Vec<FrameRecord>, DatasetError> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| DatasetError::invalid(path, format!("not UTF-8: {e}")))?;
    let mut out = Vec::new();
    for (n, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let record: FrameRecord = serde_json::from_str(line)
            .map_err(|e| DatasetError::invalid(path, format!("line {}: {e}", n + 1)))?;
        if record.index != out.len() {
            return Err(DatasetError::invalid(
                path,
                format!(
                    "line {}: frame {} where {} was due",
                    n + 1,
                    record.index,
                    out.len()
                ),
            ));
        }
        out.push(record);
    }
    Ok(out)
}

/// A stable 64-bit FNV-1a hash of `bytes`: collection derives each run's world seed from it and
/// training its train/validation split, so it must not change between runs or Rust versions
/// (std's hashers may).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |hash, &b| {
        (hash ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

/// `raw` with every character other than ASCII letters, digits, `_` and `-` replaced by `-`,
/// so it can name a file or folder and never leave its parent.
pub fn safe_name(raw: &str) -> String {
    raw.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '-'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv1a_is_the_published_64_bit_hash() {
        // Test vectors of the FNV reference (draft-eastlake-fnv): seeds and splits depend on it.
        assert_eq!(fnv1a(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn safe_names_never_leave_their_folder() {
        assert_eq!(safe_name("Town05__route_7__r0"), "Town05__route_7__r0");
        assert_eq!(safe_name("../x"), "---x");
        assert_eq!(safe_name("a/b\\c d.png"), "a-b-c-d-png");
        assert_eq!(safe_name("ü"), "-");
    }
}
