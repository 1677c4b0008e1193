//! CARLA leaderboard scenario files (`all_towns_traffic_scenarios_public.json` and the like) and
//! how the leaderboard 1.0 gives a route its scenarios from one (`route_parser.py`,
//! `route_scenario.py`).
//!
//! A file lists, per town, scenario types (`"Scenario1"` to `"Scenario10"`) with trigger
//! transforms in CARLA's frame; [`ScenarioFile::read`] flips them into the OpenDRIVE frame as
//! route files are ([`super::xml`]). [`match_to_route`] then does what the leaderboard does
//! before a route starts:
//! - a trigger belongs to the route when some dense point lies within [`TRIGGER_DISTANCE`]
//!   (3-D) and [`TRIGGER_ANGLE`] of yaw of it; the first such point is where it fires;
//! - Scenario4 needs the route's next turn (the first option after that point that is
//!   neither lane-follow nor a lane change) to be a left or right, Scenario7 a left, right or straight, Scenario8 a left,
//!   Scenario9 a right; otherwise the trigger is dropped for that type;
//! - triggers within the same distance (in plan) and angle of each other share a position, and
//!   one scenario is kept per position: the highest-numbered one, or, when one kept earlier
//!   already stands within the distance (3-D, any heading), another drawn from the rest with
//!   the route's seed (the leaderboard draws with seed 0), until none is left.
//!
//! Untrusted input is capped ([`MAX_SCENARIO_FILE_BYTES`], [`MAX_TRIGGERS`]); a file that does
//! not parse, names an unknown scenario type or holds a non-finite number is an error naming the
//! place.

use std::collections::BTreeMap;
use std::path::Path;

use glam::DVec3;
use rand::{RngExt as _, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::Value;
use ssrdrive_proto::command::RoadOption;
use ssrdrive_support::files::read_capped_text;

use super::DenseRoute;

/// Largest scenario file accepted (the leaderboard's dense all-scenario files run to a few MB).
pub const MAX_SCENARIO_FILE_BYTES: u64 = 64 * 1024 * 1024;
/// Most triggers in one file, over all towns.
pub const MAX_TRIGGERS: usize = 200_000;
/// A trigger matches a route point (and another trigger) within this distance, m
/// (`TRIGGER_THRESHOLD`).
pub const TRIGGER_DISTANCE: f64 = 2.0;
/// ... and within this difference of yaw, degrees (`TRIGGER_ANGLE_THRESHOLD`).
pub const TRIGGER_ANGLE: f64 = 10.0;

/// One trigger of a scenario file: a scenario type at a place, in the OpenDRIVE frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trigger {
    /// The scenario's number, 1 to 10 (`"Scenario3"` is 3).
    pub scenario: u8,
    /// Trigger position, m.
    pub position: DVec3,
    /// Trigger heading, radians counter-clockwise from +x.
    pub yaw: f64,
}

impl Trigger {
    /// Whether a route point at `position` heading `yaw` matches: within the trigger distance
    /// in 3-D and the trigger angle (`match_world_location_to_route`).
    fn matches(&self, position: DVec3, yaw: f64) -> bool {
        (self.position - position).length() < TRIGGER_DISTANCE && self.heads_like(yaw)
    }

    /// Whether `other` is at the same position: within the trigger distance in plan and the
    /// angle (`check_trigger_position`).
    fn same_position(&self, other: &Trigger) -> bool {
        (self.position - other.position).truncate().length() < TRIGGER_DISTANCE
            && self.heads_like(other.yaw)
    }

    /// Whether `other` stands where this one does for sampling: within the trigger distance in
    /// 3-D, whatever the heading (`compare_scenarios`, whose angle test compares a yaw with
    /// itself).
    fn overlaps(&self, other: &Trigger) -> bool {
        (self.position - other.position).length() < TRIGGER_DISTANCE
    }

    fn heads_like(&self, yaw: f64) -> bool {
        let dyaw = (self.yaw - yaw).to_degrees().rem_euclid(360.0);
        !(TRIGGER_ANGLE..=360.0 - TRIGGER_ANGLE).contains(&dyaw)
    }
}

/// A scenario file, by town.
#[derive(Clone)]
pub struct ScenarioFile {
    /// Where it was read from, for messages.
    pub origin: String,
    /// FNV-1a of its bytes: two runs with the same file place the same scenarios.
    pub digest: u64,
    /// Triggers per town, the town's name lower-cased.
    towns: BTreeMap<String, Vec<Trigger>>,
}

impl std::fmt::Debug for ScenarioFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ScenarioFile({}, {:016x})", self.origin, self.digest)
    }
}

/// Why a scenario file could not be used.
#[derive(Debug, thiserror::Error)]
#[error("scenario file {origin}: {problem}")]
pub struct ScenarioFileError {
    /// The file, as given.
    pub origin: String,
    /// What is wrong, and where.
    pub problem: String,
}

impl ScenarioFile {
    /// Read and parse the file at `path`.
    pub fn read(path: &Path) -> Result<Self, ScenarioFileError> {
        let origin = path.display().to_string();
        let text =
            read_capped_text(path, MAX_SCENARIO_FILE_BYTES).map_err(|e| ScenarioFileError {
                origin: origin.clone(),
                problem: e.to_string(),
            })?;
        Self::parse(&text, &origin)
    }

    /// Parse a file's text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Self, ScenarioFileError> {
        let fail = |problem: String| ScenarioFileError {
            origin: origin.to_string(),
            problem,
        };
        let root: Value = serde_json::from_str(text).map_err(|e| fail(format!("not JSON: {e}")))?;
        let lists = root
            .get("available_scenarios")
            .and_then(Value::as_array)
            .ok_or_else(|| fail("no \"available_scenarios\" list".into()))?;
        let mut towns: BTreeMap<String, Vec<Trigger>> = BTreeMap::new();
        let mut count = 0;
        for by_town in lists {
            let by_town = by_town
                .as_object()
                .ok_or_else(|| fail("an \"available_scenarios\" entry is not an object".into()))?;
            for (town, scenarios) in by_town {
                let triggers = towns.entry(town.to_ascii_lowercase()).or_default();
                for scenario in scenarios.as_array().into_iter().flatten() {
                    let name = scenario
                        .get("scenario_type")
                        .and_then(Value::as_str)
                        .ok_or_else(|| fail(format!("{town}: a scenario has no scenario_type")))?;
                    let number = scenario_number(name).ok_or_else(|| {
                        fail(format!(
                            "{town}: unknown scenario type \"{name}\" (the leaderboard 1.0 knows \
                             Scenario1 to Scenario10)"
                        ))
                    })?;
                    let events = scenario
                        .get("available_event_configurations")
                        .and_then(Value::as_array)
                        .ok_or_else(|| {
                            fail(format!("{town} {name}: no available_event_configurations"))
                        })?;
                    for (k, event) in events.iter().enumerate() {
                        count += 1;
                        if count > MAX_TRIGGERS {
                            return Err(fail(format!("more than {MAX_TRIGGERS} triggers")));
                        }
                        let at = |key: &str, required: bool| -> Result<f64, ScenarioFileError> {
                            let value = event.get("transform").and_then(|t| t.get(key));
                            match value {
                                None if !required => Ok(0.0),
                                None => Err(fail(format!(
                                    "{town} {name} event {k}: its transform has no \"{key}\""
                                ))),
                                Some(v) => number_of(v).ok_or_else(|| {
                                    fail(format!(
                                        "{town} {name} event {k}: transform {key} = {v} is not \
                                         a finite number"
                                    ))
                                }),
                            }
                        };
                        let (x, y, z, yaw) = (
                            at("x", true)?,
                            at("y", true)?,
                            at("z", false)?,
                            at("yaw", true)?,
                        );
                        triggers.push(Trigger {
                            scenario: number,
                            position: DVec3::new(x, -y, z),
                            yaw: -yaw.to_radians(),
                        });
                    }
                }
            }
        }
        Ok(Self {
            origin: origin.to_string(),
            digest: ssrdrive_proto::dataset::fnv1a(text.as_bytes()),
            towns,
        })
    }

    /// The triggers of `town` (any case), or an error naming the towns the file has.
    pub fn town(&self, town: &str) -> Result<TownScenarios, ScenarioFileError> {
        self.towns
            .get(&town.to_ascii_lowercase())
            .map(|triggers| TownScenarios {
                origin: self.origin.clone(),
                digest: self.digest,
                triggers: triggers.as_slice().into(),
            })
            .ok_or_else(|| ScenarioFileError {
                origin: self.origin.clone(),
                problem: format!(
                    "no scenarios for town {town} (it has {})",
                    self.towns.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            })
    }
}

/// One town's triggers from a scenario file, cheap to clone (a world config carries it).
#[derive(Clone)]
pub struct TownScenarios {
    /// The file it came from.
    pub origin: String,
    /// The file's digest.
    pub digest: u64,
    /// The town's triggers, in file order.
    pub triggers: std::sync::Arc<[Trigger]>,
}

impl std::fmt::Debug for TownScenarios {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "TownScenarios({}, {:016x}, {} triggers)",
            self.origin,
            self.digest,
            self.triggers.len()
        )
    }
}

/// The text of a scenario file holding `triggers` for `town`, in the leaderboard's layout and
/// CARLA's frame, numbers written as the public files write them (strings, to the centimetre
/// and the hundredth of a degree): what [`ScenarioFile::parse`] reads back.
pub fn write(town: &str, triggers: &[Trigger]) -> String {
    let mut by_type: BTreeMap<u8, Vec<Value>> = BTreeMap::new();
    for t in triggers {
        // `+ 0.0` turns -0.0 into 0.0 so that a zero prints without a sign.
        let carla_yaw = ssrdrive_proto::frames::wrap_angle(-t.yaw).to_degrees() + 0.0;
        by_type
            .entry(t.scenario)
            .or_default()
            .push(serde_json::json!({
                "transform": {
                    "pitch": "0.0",
                    "x": format!("{:.2}", t.position.x + 0.0),
                    "y": format!("{:.2}", -t.position.y + 0.0),
                    "yaw": format!("{carla_yaw:.2}"),
                    "z": format!("{:.2}", t.position.z + 0.0),
                }
            }));
    }
    let scenarios: Vec<Value> = by_type
        .into_iter()
        .map(|(number, events)| {
            serde_json::json!({
                "available_event_configurations": events,
                "scenario_type": format!("Scenario{number}"),
            })
        })
        .collect();
    let root = serde_json::json!({ "available_scenarios": [{ town: scenarios }] });
    serde_json::to_string_pretty(&root).expect("a JSON value serialises") + "\n"
}

/// `"ScenarioN"` -> N for N in 1..=10.
fn scenario_number(name: &str) -> Option<u8> {
    let n: u8 = name.strip_prefix("Scenario")?.parse().ok()?;
    (1..=10).contains(&n).then_some(n)
}

/// A JSON number or a string holding one (the public files write `"x": "319.64"`), if finite.
fn number_of(value: &Value) -> Option<f64> {
    let n = match value {
        Value::Number(n) => n.as_f64()?,
        Value::String(s) => s.trim().parse().ok()?,
        _ => return None,
    };
    n.is_finite().then_some(n)
}

/// Which way a scenario that depends on the route's next turn goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Turn {
    /// The next turn is a left.
    Left,
    /// A right.
    Right,
    /// Straight across a junction.
    Straight,
}

/// A scenario the leaderboard would give a route: its number, the route index where it fires,
/// the trigger, and for Scenario4 and 7-9 the route's next turn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RouteScenario {
    /// The trigger from the file.
    pub trigger: Trigger,
    /// Dense route index of the first point matching it.
    pub index: usize,
    /// The route's next turn after `index`, for the scenarios that need one.
    pub turn: Option<Turn>,
}

/// The next option after `index` that is neither lane-follow nor a lane change, as the
/// leaderboard's `get_scenario_type` reads it.
fn next_turn(route: &DenseRoute, index: usize) -> Option<RoadOption> {
    route.points[index..]
        .iter()
        .map(|p| p.option)
        .find(|o| *o != RoadOption::LaneFollow && !o.is_lane_change())
}

/// Whether scenario `number` can run at `index` of `route`, and the turn it takes.
fn variant(number: u8, route: &DenseRoute, index: usize) -> Option<Option<Turn>> {
    let turn = next_turn(route, index);
    let needs = |allowed: &[RoadOption]| {
        turn.filter(|t| allowed.contains(t)).map(|t| {
            Some(match t {
                RoadOption::Left => Turn::Left,
                RoadOption::Right => Turn::Right,
                _ => Turn::Straight,
            })
        })
    };
    match number {
        4 => needs(&[RoadOption::Left, RoadOption::Right]),
        7 => needs(&[RoadOption::Left, RoadOption::Right, RoadOption::Straight]),
        8 => needs(&[RoadOption::Left]),
        9 => needs(&[RoadOption::Right]),
        _ => Some(None),
    }
}

/// The scenarios the leaderboard 1.0 gives `route` from a town's `triggers` (see the module
/// doc), in route order; `seed` draws where two would stand at one position.
pub fn match_to_route(triggers: &[Trigger], route: &DenseRoute, seed: u64) -> Vec<RouteScenario> {
    // Candidates grouped by position, in file order.
    let mut positions: Vec<(Trigger, Vec<RouteScenario>)> = Vec::new();
    for trigger in triggers {
        let Some(index) = route
            .points
            .iter()
            .position(|p| trigger.matches(p.position, p.yaw))
        else {
            continue;
        };
        let Some(turn) = variant(trigger.scenario, route, index) else {
            continue;
        };
        let candidate = RouteScenario {
            trigger: *trigger,
            index,
            turn,
        };
        match positions
            .iter_mut()
            .find(|(at, _)| at.same_position(trigger))
        {
            Some((_, list)) => list.push(candidate),
            None => positions.push((*trigger, vec![candidate])),
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut kept: Vec<RouteScenario> = Vec::new();
    for (_, mut list) in positions {
        // The highest number wins (the last of equals, as the leaderboard's `>=`).
        let best = (0..list.len())
            .max_by_key(|&k| list[k].trigger.scenario)
            .expect("a position has a candidate");
        let mut choice = Some(list.remove(best));
        let taken = |c: &RouteScenario, kept: &[RouteScenario]| {
            kept.iter().any(|k| k.trigger.overlaps(&c.trigger))
        };
        while choice.is_some_and(|c| taken(&c, &kept)) {
            choice = (!list.is_empty()).then(|| list.remove(rng.random_range(0..list.len())));
        }
        kept.extend(choice);
    }
    kept.sort_by_key(|s| s.index);
    kept
}
