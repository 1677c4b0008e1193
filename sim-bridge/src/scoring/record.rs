//! Route records, the global record and the results file, in the leaderboard 1.0 JSON shape
//! (leaderboard `statistics_manager.py` and `checkpoint_tools.py`):
//!
//! ```text
//! {"_checkpoint": {"global_record": {...}, "progress": [done, total], "records": [...]},
//!  "eligible": true, "entry_status": "Finished", "labels": [...], "sensors": [...], "values": [...]}
//! ```
//!
//! Written like Python's `json.dump(indent=4, sort_keys=True)`. A record holds `index`,
//! `infractions` (one message list per key), `meta` (`duration_game`, `duration_system`,
//! `route_length`), `route_id`, `scores` (`score_composed` = DS, `score_penalty` = IS,
//! `score_route` = RC) and `status`. Our additions are keys that LB1.0 readers ignore:
//! Leaderboard 2.0's `infractions.min_speed_infractions` and `infractions.scenario_timeouts`
//! (empty unless `--scoring lb2`),
//! `meta.repetition`, `meta.seed` and `meta.bench2drive` on records, and `meta.records`,
//! `meta.scores_std`, `meta.total_length`, `meta.duration_game`, `meta.duration_system`,
//! `meta.infraction_counts` and `meta.bench2drive` on the global record, and a top-level `plan`
//! ([`CampaignPlan`]: which campaign the records belong to, so that shards of one campaign can
//! be merged and those of others refused).

use serde::de::Error as _;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use serde_json::Value;

use super::InfractionKind;
use super::bench2drive::{CampaignFigures, RouteFigures};

/// One value per infraction key (LB1.0's and 2.0's minimum speed): message lists on a route
/// record, rates per km on the global record.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Infractions<T: Default> {
    /// Collisions with static layout.
    pub collisions_layout: T,
    /// Collisions with walkers.
    pub collisions_pedestrian: T,
    /// Collisions with vehicles.
    pub collisions_vehicle: T,
    /// The off-lane event (at most one per route).
    pub outside_route_lanes: T,
    /// Red lights run.
    pub red_light: T,
    /// Route deviations.
    pub route_dev: T,
    /// Route timeouts.
    pub route_timeout: T,
    /// Stop signs run.
    pub stop_infraction: T,
    /// Agent blocked.
    pub vehicle_blocked: T,
    /// Leaderboard 2.0's minimum-speed events (`--scoring lb2`; empty or 0 under 1.0).
    pub min_speed_infractions: T,
    /// Leaderboard 2.0's scenario timeouts (`--scoring lb2`; empty or 0 under 1.0).
    pub scenario_timeouts: T,
}

impl<T: Default> Infractions<T> {
    /// The entry for `kind`.
    pub fn get(&self, kind: InfractionKind) -> &T {
        match kind {
            InfractionKind::CollisionPedestrian => &self.collisions_pedestrian,
            InfractionKind::CollisionVehicle => &self.collisions_vehicle,
            InfractionKind::CollisionLayout => &self.collisions_layout,
            InfractionKind::RedLight => &self.red_light,
            InfractionKind::StopSign => &self.stop_infraction,
            InfractionKind::OutsideRouteLanes => &self.outside_route_lanes,
            InfractionKind::RouteDeviation => &self.route_dev,
            InfractionKind::VehicleBlocked => &self.vehicle_blocked,
            InfractionKind::RouteTimeout => &self.route_timeout,
            InfractionKind::MinSpeed => &self.min_speed_infractions,
            InfractionKind::ScenarioTimeout => &self.scenario_timeouts,
        }
    }

    /// The entry for `kind`, mutably.
    pub fn get_mut(&mut self, kind: InfractionKind) -> &mut T {
        match kind {
            InfractionKind::CollisionPedestrian => &mut self.collisions_pedestrian,
            InfractionKind::CollisionVehicle => &mut self.collisions_vehicle,
            InfractionKind::CollisionLayout => &mut self.collisions_layout,
            InfractionKind::RedLight => &mut self.red_light,
            InfractionKind::StopSign => &mut self.stop_infraction,
            InfractionKind::OutsideRouteLanes => &mut self.outside_route_lanes,
            InfractionKind::RouteDeviation => &mut self.route_dev,
            InfractionKind::VehicleBlocked => &mut self.vehicle_blocked,
            InfractionKind::RouteTimeout => &mut self.route_timeout,
            InfractionKind::MinSpeed => &mut self.min_speed_infractions,
            InfractionKind::ScenarioTimeout => &mut self.scenario_timeouts,
        }
    }
}

impl Infractions<Vec<String>> {
    /// How many events of `kind`.
    pub fn count(&self, kind: InfractionKind) -> usize {
        self.get(kind).len()
    }
}

/// RC, IS and DS of a route (or their means).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Scores {
    /// Driving score DS = max(RC * IS, 0).
    pub score_composed: f64,
    /// Infraction score IS.
    pub score_penalty: f64,
    /// Route completion RC, percent.
    pub score_route: f64,
}

/// A route record's `meta`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RouteMeta {
    /// Simulation seconds the route ran.
    pub duration_game: f64,
    /// Wall-clock seconds the route took.
    pub duration_system: f64,
    /// Repetition number (ours; not in LB1.0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub repetition: Option<usize>,
    /// Polyline length of the route file's keypoints, metres (LB1.0 `compute_route_length`).
    pub route_length: f64,
    /// Seed of the run (ours; not in LB1.0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Where the user's fixed timeout (`eval --timeout`) cut the run, simulated seconds (ours;
    /// the status is then "Stopped - --timeout reached").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stopped_at_s: Option<f64>,
    /// The infractions that say more than the leaderboard's message, in time order (ours, for
    /// failure analysis): how a vehicle collision happened, where a red light was run from.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub events: Vec<RouteEvent>,
    /// Bench2Drive's success, efficiency and comfort (ours; see [`super::bench2drive`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bench2drive: Option<RouteFigures>,
}

/// One infraction with its detail (ours; see [`RouteMeta::events`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RouteEvent {
    /// The LB1.0 infraction key, e.g. `collisions_vehicle`.
    pub kind: String,
    /// Simulated seconds since the route started.
    pub time: f64,
    /// Where, map frame (x, y), m.
    pub location: [f64; 2],
    /// What happened, e.g. "crossing, in a junction, other 6.2 m/s, ego 4.0 m/s".
    pub detail: String,
}

/// The record of one route run (LB1.0 `RouteRecord`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RouteRecord {
    /// Position of the run in the results (`records[index]`).
    pub index: usize,
    /// Messages per infraction key.
    #[serde(default)]
    pub infractions: Infractions<Vec<String>>,
    /// Durations and route length.
    #[serde(default)]
    pub meta: RouteMeta,
    /// The route's name, e.g. "RouteScenario_16".
    pub route_id: String,
    /// RC, IS and DS.
    #[serde(default)]
    pub scores: Scores,
    /// "Completed", or "Failed" with " - Agent deviated from the route", " - Agent got blocked",
    /// " - Agent timed out" or another reason.
    pub status: String,
}

/// Start of the status of a route that could not be planned over the lane graph; the reason
/// follows. Such a route counts with zero scores: the leaderboard would have stopped at it.
pub const UNPLANNABLE_STATUS: &str = "Failed - Route could not be planned";

impl RouteRecord {
    /// The record of run `index`, a route that could not be planned (`reason`), of keypoint
    /// length `route_length`, repetition `repetition` with world seed `seed`.
    pub fn unplannable(
        index: usize,
        route_id: &str,
        route_length: f64,
        repetition: usize,
        seed: u64,
        reason: &str,
    ) -> Self {
        RouteRecord {
            index,
            infractions: Infractions::default(),
            meta: RouteMeta {
                route_length,
                repetition: Some(repetition),
                seed: Some(seed),
                ..RouteMeta::default()
            },
            route_id: route_id.to_string(),
            scores: Scores {
                score_composed: 0.0,
                score_penalty: 1.0,
                score_route: 0.0,
            },
            status: format!("{UNPLANNABLE_STATUS}: {reason}"),
        }
    }

    /// Whether the route was completed ("Completed", or Leaderboard 2.0's "Perfect").
    pub fn completed(&self) -> bool {
        self.status == "Completed" || self.status == super::PERFECT_STATUS
    }
}

/// The global record's `meta`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct GlobalMeta {
    /// (route id, index, status) of every record that is not "Completed" (LB1.0).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub exceptions: Vec<(String, usize, String)>,
    /// Number of records averaged (ours).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub records: Option<usize>,
    /// Sample standard deviations (N - 1) of DS, IS and RC over the records (ours).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scores_std: Option<Scores>,
    /// Sum of the records' route lengths, metres (ours).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub total_length: Option<f64>,
    /// Sum of the records' simulation seconds (ours).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub duration_game: Option<f64>,
    /// Sum of the records' wall-clock seconds (ours).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub duration_system: Option<f64>,
    /// Total events per key over the records (ours).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub infraction_counts: Option<Infractions<usize>>,
    /// Bench2Drive's success rate, efficiency and comfort over the records (ours).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bench2drive: Option<CampaignFigures>,
}

/// The global record (LB1.0 `compute_global_statistics`): route id and index -1, mean scores,
/// infractions per km, "Completed" unless a record is not.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GlobalRecord {
    /// Always -1.
    #[serde(default = "minus_one")]
    pub index: i64,
    /// Infractions per km, the LB1.0 way (see [`global_record`]).
    #[serde(default)]
    pub infractions: Infractions<f64>,
    /// Exceptions and our extras.
    #[serde(default)]
    pub meta: GlobalMeta,
    /// Always -1.
    #[serde(default = "minus_one")]
    pub route_id: i64,
    /// Means of DS, IS and RC over the records, each averaged separately.
    #[serde(default)]
    pub scores: Scores,
    /// "Completed" or "Failed".
    #[serde(default)]
    pub status: String,
}

fn minus_one() -> i64 {
    -1
}

/// The global record over `records` (routes x repetitions), as LB1.0 computes it:
/// - DS, RC and IS are each the mean over the records (so mean DS != mean RC * mean IS);
/// - infractions per km are the **sum of per-route rates** count_i / (RC_i / 100 * L_i / 1000),
///   with L_i the record's `route_length` (keypoint length); records with RC = 0 are skipped
///   (LB1.0: "the vehicle hasn't moved"), and so are records with no length (LB1.0 would divide
///   by zero); the sum is **not** divided by the number of records;
/// - status "Failed" with an exception entry for every record that is not "Completed".
///
/// Means are over the records given; LB1.0 divides by the total number of planned routes, which
/// is the same once a run is complete. Standard deviations use N - 1 (0 for fewer than 2).
pub fn global_record(records: &[RouteRecord]) -> GlobalRecord {
    let n = records.len();
    let mean = |f: &dyn Fn(&Scores) -> f64| {
        if n == 0 {
            0.0
        } else {
            records.iter().map(|r| f(&r.scores)).sum::<f64>() / n as f64
        }
    };
    let std = |f: &dyn Fn(&Scores) -> f64, m: f64| {
        if n < 2 {
            0.0
        } else {
            let ss: f64 = records.iter().map(|r| (f(&r.scores) - m).powi(2)).sum();
            (ss / (n - 1) as f64).sqrt()
        }
    };
    let ds = |s: &Scores| s.score_composed;
    let is = |s: &Scores| s.score_penalty;
    let rc = |s: &Scores| s.score_route;
    let scores = Scores {
        score_composed: mean(&ds),
        score_penalty: mean(&is),
        score_route: mean(&rc),
    };
    let scores_std = Scores {
        score_composed: std(&ds, scores.score_composed),
        score_penalty: std(&is, scores.score_penalty),
        score_route: std(&rc, scores.score_route),
    };

    let mut per_km = Infractions::<f64>::default();
    let mut counts = Infractions::<usize>::default();
    let mut exceptions = Vec::new();
    for r in records {
        for kind in InfractionKind::ALL {
            *counts.get_mut(kind) += r.infractions.count(kind);
        }
        let km = r.scores.score_route / 100.0 * r.meta.route_length / 1000.0;
        if r.scores.score_route != 0.0 && km > 0.0 {
            for kind in InfractionKind::ALL {
                *per_km.get_mut(kind) += r.infractions.count(kind) as f64 / km;
            }
        }
        if !r.completed() {
            exceptions.push((r.route_id.clone(), r.index, r.status.clone()));
        }
    }
    let status = if exceptions.is_empty() {
        "Completed"
    } else {
        "Failed"
    };
    GlobalRecord {
        index: -1,
        infractions: per_km,
        meta: GlobalMeta {
            exceptions,
            records: Some(n),
            scores_std: Some(scores_std),
            total_length: Some(records.iter().map(|r| r.meta.route_length).sum()),
            duration_game: Some(records.iter().map(|r| r.meta.duration_game).sum()),
            duration_system: Some(records.iter().map(|r| r.meta.duration_system).sum()),
            infraction_counts: Some(counts),
            bench2drive: Some(CampaignFigures::of(records)),
        },
        route_id: -1,
        scores,
        status: status.to_string(),
    }
}

/// The `labels` LB1.0 writes, in the order of `values`.
pub const LABELS: [&str; 12] = [
    "Avg. driving score",
    "Avg. route completion",
    "Avg. infraction penalty",
    "Collisions with pedestrians",
    "Collisions with vehicles",
    "Collisions with layout",
    "Red lights infractions",
    "Stop sign infractions",
    "Off-road infractions",
    "Route deviations",
    "Route timeouts",
    "Agent blocked",
];

/// The `_checkpoint` object.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The global record; `{}` in the file until one is computed.
    #[serde(default, with = "empty_object_as_none")]
    pub global_record: Option<GlobalRecord>,
    /// [routes done, routes planned]; empty before the first route.
    #[serde(default)]
    pub progress: Vec<usize>,
    /// One record per run.
    #[serde(default)]
    pub records: Vec<RouteRecord>,
}

/// Which campaign a results file's records belong to: what was driven, how, by whom and with
/// which simulator, and which share of its runs this file holds.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CampaignPlan {
    /// The route set or file as given (`--routes`), for people; `fingerprint` decides.
    pub routes: String,
    /// The town.
    pub town: String,
    /// A hash of the selected routes (ids, towns, keypoints) and the world and scoring
    /// settings but `timeout_s`: two campaigns with the same fingerprint, seed and timeout
    /// drive the same runs (a resume may add repetitions or change the timeout).
    pub fingerprint: String,
    /// Runs of each route.
    pub repetitions: usize,
    /// The seed of repetition 0.
    pub seed: u64,
    /// Runs of the whole campaign (routes x repetitions).
    pub runs: usize,
    /// A fixed route timeout, seconds (`eval --timeout`); absent: the leaderboard's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout_s: Option<f64>,
    /// How background traffic treated the ego (`--traffic`: `carla` or `courteous`); absent in
    /// files written before 2026-11-29, whose default was `courteous`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub traffic: Option<String>,
    /// What drove (a served agent: its model, config, checkpoint and version, not its address).
    #[serde(default)]
    pub agent: String,
    /// The simulator, `sim-bridge VERSION`.
    pub simulator: String,
    /// The share this file holds, `K/N` (`eval --shard`); absent for the whole campaign.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<String>,
}

/// A leaderboard 1.0 results file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Results {
    /// Progress, records and the global record.
    #[serde(rename = "_checkpoint")]
    pub checkpoint: Checkpoint,
    /// Whether the entry is eligible (false with missing data).
    #[serde(default)]
    pub eligible: bool,
    /// "Finished", "Finished with missing data" or "Finished with agent errors".
    #[serde(default)]
    pub entry_status: String,
    /// [`LABELS`].
    #[serde(default)]
    pub labels: Vec<String>,
    /// The agent's sensor names.
    #[serde(default)]
    pub sensors: Vec<String>,
    /// The global DS, RC, IS and the infraction rates per km, as "{:.3f}" strings.
    #[serde(default, deserialize_with = "strings_or_numbers")]
    pub values: Vec<String>,
    /// The campaign these records belong to (absent in the leaderboard's own files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<CampaignPlan>,
}

/// Why a results file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ResultsError {
    /// Not JSON, or not the leaderboard's shape (serde names the line, column and field).
    #[error("malformed leaderboard results JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// `_checkpoint.progress` is neither empty nor [done, total].
    #[error(
        "malformed leaderboard results JSON: _checkpoint.progress has {0} entries, expected [done, total]"
    )]
    Progress(usize),
}

impl Results {
    /// The results of a run with `total_routes` planned runs (routes x repetitions), as LB1.0
    /// `save_global_record` writes them: progress [records, total], the global record, `values`
    /// formatted "{:.3f}", `entry_status` "Finished" or "Finished with missing data" (then not
    /// eligible) or "Finished with agent errors" (a status mentioning "Agent").
    pub fn new(records: Vec<RouteRecord>, total_routes: usize, sensors: Vec<String>) -> Self {
        let global = global_record(&records);
        let mut values = vec![
            format!("{:.3}", global.scores.score_composed),
            format!("{:.3}", global.scores.score_route),
            format!("{:.3}", global.scores.score_penalty),
        ];
        values.extend(
            InfractionKind::LB1
                .iter()
                .map(|k| format!("{:.3}", global.infractions.get(*k))),
        );
        let (entry_status, eligible) = if records.len() != total_routes {
            ("Finished with missing data", false)
        } else if records.iter().any(|r| r.status.contains("Agent")) {
            ("Finished with agent errors", true)
        } else {
            ("Finished", true)
        };
        Results {
            checkpoint: Checkpoint {
                global_record: Some(global),
                progress: vec![records.len(), total_routes],
                records,
            },
            eligible,
            entry_status: entry_status.to_string(),
            labels: LABELS.iter().map(|s| s.to_string()).collect(),
            sensors,
            values,
            plan: None,
        }
    }

    /// The file text: sorted keys, 4-space indent, like the leaderboard's `json.dump`.
    pub fn to_json(&self) -> String {
        let value = sort_keys(serde_json::to_value(self).expect("results are plain data"));
        let mut out = Vec::new();
        let formatter = serde_json::ser::PrettyFormatter::with_indent(b"    ");
        let mut ser = serde_json::Serializer::with_formatter(&mut out, formatter);
        value
            .serialize(&mut ser)
            .expect("writing to memory cannot fail");
        String::from_utf8(out).expect("serde_json writes UTF-8")
    }

    /// Read a results file (ours or the leaderboard's).
    pub fn from_json(text: &str) -> Result<Self, ResultsError> {
        let results: Results = serde_json::from_str(text)?;
        match results.checkpoint.progress.len() {
            0 | 2 => Ok(results),
            n => Err(ResultsError::Progress(n)),
        }
    }
}

/// Rebuild every object with its keys in sorted order.
fn sort_keys(value: Value) -> Value {
    match value {
        Value::Object(map) => {
            let mut entries: Vec<(String, Value)> = map.into_iter().collect();
            entries.sort_by(|a, b| a.0.cmp(&b.0));
            Value::Object(
                entries
                    .into_iter()
                    .map(|(k, v)| (k, sort_keys(v)))
                    .collect(),
            )
        }
        Value::Array(items) => Value::Array(items.into_iter().map(sort_keys).collect()),
        other => other,
    }
}

/// `values` holds strings in LB1.0 files and numbers in older ones; keep them as text.
fn strings_or_numbers<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<String>, D::Error> {
    let items: Vec<Value> = Vec::deserialize(d)?;
    items
        .into_iter()
        .map(|v| match v {
            Value::String(s) => Ok(s),
            Value::Number(n) => Ok(n.to_string()),
            other => Err(D::Error::custom(format!(
                "`values` entries must be strings or numbers, found {other}"
            ))),
        })
        .collect()
}

/// The leaderboard writes `{}` for a global record not computed yet.
mod empty_object_as_none {
    use super::*;

    pub fn serialize<S: Serializer>(v: &Option<GlobalRecord>, s: S) -> Result<S::Ok, S::Error> {
        match v {
            Some(g) => g.serialize(s),
            None => serde_json::Map::new().serialize(s),
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<GlobalRecord>, D::Error> {
        let v = Value::deserialize(d)?;
        match &v {
            Value::Null => Ok(None),
            Value::Object(m) if m.is_empty() => Ok(None),
            _ => serde_json::from_value(v)
                .map(Some)
                .map_err(D::Error::custom),
        }
    }
}
