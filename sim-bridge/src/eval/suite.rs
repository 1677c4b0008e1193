//! Named evaluation suites: fixed sets of route files, each driven a fixed number of
//! repetitions, that `sim-bridge eval --suite NAME` drives (repetition 0 of every file, then
//! repetition 1, ...) and sums up.
//!
//! - `unseen`, the held-out suite: towns that no training set, checkpoint choice or controller
//!   constant may touch. CARLA's Town02 (`heldout-town02`, 40 routes the project drew and
//!   committed) and the radial town (`heldout-radial`, 20 routes), a layout family no training
//!   town has. Every choice about the agent is made here.
//! - `home`: the Town05-style routes, long and short. Choices were made on them in the past,
//!   so they are a regression check, not a measure of generalization.
//!
//! A suite's figures are means over all its runs (routes x repetitions, every run weighing the
//! same) and infractions per km *driven*: each kind's count over the summed distance the runs
//! covered (RC x route length). That differs from the leaderboard's global record, which sums
//! per-route rates (see [`crate::scoring::record::global_record`]); each part's results JSON
//! keeps the leaderboard's own figures.
//!
//! Failure classes: each part and the whole suite also count the records' `meta.events` by
//! class ([`event_class`]: how vehicle collisions happened, whose red lights were run), per km
//! driven. Bench2Drive's success rate, efficiency and comfort sit beside the leaderboard's
//! figures.
//!
//! Collection refuses the towns of every suite ([`evaluation_towns`]), so that no training data
//! is recorded on them.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::route::sets::{CarlaRouteFile, RouteSet};
use crate::scoring::InfractionKind;
use crate::scoring::bench2drive::CampaignFigures;
use crate::scoring::record::{Infractions, RouteEvent, RouteRecord, Scores};

/// A named suite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Suite {
    /// Its name on the command line.
    pub name: &'static str,
    /// One line for `--help` and listings.
    pub description: &'static str,
    /// The route files it drives (bundled set names or committed CARLA route files).
    pub parts: &'static [&'static str],
    /// Runs of each route (seeds 0, 1, 2, ...).
    pub repetitions: usize,
}

/// Every suite.
pub static SUITES: [Suite; 2] = [
    Suite {
        name: "unseen",
        description: "held out: CARLA Town02 (40 routes) and the radial town (20), 3 repetitions",
        parts: &["heldout-town02", "heldout-radial"],
        repetitions: 3,
    },
    Suite {
        name: "home",
        description: "regression check: the Town05-style long (10) and short (20) routes, 3 repetitions",
        parts: &["town05-long-style", "town05-short-style"],
        repetitions: 3,
    },
];

impl Suite {
    /// The suite called `name`.
    pub fn find(name: &str) -> Option<&'static Suite> {
        SUITES.iter().find(|s| s.name == name)
    }

    /// The suite names, comma separated (for messages).
    pub fn names() -> String {
        SUITES.iter().map(|s| s.name).collect::<Vec<_>>().join(", ")
    }
}

/// The town a suite part drives, by map name (a bundled town's name or a CARLA town's).
pub fn part_town(part: &str) -> Option<&'static str> {
    RouteSet::find(part)
        .map(|set| set.town.name())
        .or_else(|| CarlaRouteFile::find(part).map(|file| file.town))
}

/// Every town some suite drives: training data must not be recorded on them.
pub fn evaluation_towns() -> Vec<&'static str> {
    let mut towns: Vec<&str> = SUITES
        .iter()
        .flat_map(|s| s.parts.iter().filter_map(|p| part_town(p)))
        .collect();
    towns.sort_unstable();
    towns.dedup();
    towns
}

/// The figures of a group of runs (one part, or a whole suite).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figures {
    /// Runs scored.
    pub runs: usize,
    /// Runs that ended "Completed".
    pub completed: usize,
    /// Means over the runs of DS, RC and IS.
    pub scores: Scores,
    /// Kilometres driven: the sum over runs of RC x route length.
    pub km_driven: f64,
    /// Events of each kind.
    pub counts: Infractions<usize>,
    /// Events of each kind per km driven (0 when nothing was driven).
    pub per_km: Infractions<f64>,
    /// Events with a detail, by [`event_class`]: count and count per km driven.
    pub classes: BTreeMap<String, ClassCount>,
    /// Bench2Drive's success rate, efficiency and comfort over the runs.
    pub bench2drive: CampaignFigures,
}

/// How often one failure class happened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ClassCount {
    /// Events.
    pub count: usize,
    /// Events per km driven.
    pub per_km: f64,
}

/// The class of an event: its kind and the first words of its detail, e.g.
/// "collisions_vehicle: crossing, in a junction", "red_light: placed light, lamp last in frame
/// red" (what the agent's frames last showed of the light; its age is left out) or
/// "red_light: map light" (an agent without cameras).
pub fn event_class(event: &RouteEvent) -> String {
    let lamp = event
        .detail
        .split(", ")
        .nth(1)
        .is_some_and(|w| w.starts_with("lamp "));
    let words = if event.kind == "collisions_vehicle" || (event.kind == "red_light" && lamp) {
        2
    } else {
        1
    };
    let head: Vec<&str> = event.detail.split(", ").take(words).collect();
    format!("{}: {}", event.kind, head.join(", "))
}

impl Figures {
    /// The figures of `records`.
    pub fn of(records: &[RouteRecord]) -> Figures {
        let runs = records.len();
        let mean = |f: fn(&Scores) -> f64| {
            if runs == 0 {
                0.0
            } else {
                records.iter().map(|r| f(&r.scores)).sum::<f64>() / runs as f64
            }
        };
        let km_driven: f64 = records
            .iter()
            .map(|r| r.scores.score_route / 100.0 * r.meta.route_length / 1000.0)
            .sum();
        let mut counts = Infractions::<usize>::default();
        let mut per_km = Infractions::<f64>::default();
        for kind in InfractionKind::ALL {
            let n: usize = records.iter().map(|r| r.infractions.count(kind)).sum();
            *counts.get_mut(kind) = n;
            if km_driven > 0.0 {
                *per_km.get_mut(kind) = n as f64 / km_driven;
            }
        }
        let mut classes: BTreeMap<String, ClassCount> = BTreeMap::new();
        for event in records.iter().flat_map(|r| &r.meta.events) {
            classes.entry(event_class(event)).or_default().count += 1;
        }
        for class in classes.values_mut() {
            if km_driven > 0.0 {
                class.per_km = class.count as f64 / km_driven;
            }
        }
        Figures {
            runs,
            completed: records.iter().filter(|r| r.completed()).count(),
            scores: Scores {
                score_composed: mean(|s| s.score_composed),
                score_route: mean(|s| s.score_route),
                score_penalty: mean(|s| s.score_penalty),
            },
            km_driven,
            counts,
            per_km,
            classes,
            bench2drive: CampaignFigures::of(records),
        }
    }
}

/// One part's line in a suite summary.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartSummary {
    /// The route file's name.
    pub name: String,
    /// The town it drives.
    pub town: String,
    /// Its results JSON, relative to the suite's folder.
    pub results: String,
    /// Its figures.
    #[serde(flatten)]
    pub figures: Figures,
}

/// A suite's summary (`suite.json` beside the parts' results).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SuiteSummary {
    /// The suite's name.
    pub suite: String,
    /// Runs of each route.
    pub repetitions: usize,
    /// Each part.
    pub parts: Vec<PartSummary>,
    /// Every run of every part together.
    pub all: Figures,
}

/// The infraction kinds a summary table shows per km, with their column heads.
const TABLE_KINDS: [(InfractionKind, &str); 6] = [
    (InfractionKind::CollisionVehicle, "veh/km"),
    (InfractionKind::CollisionPedestrian, "walk/km"),
    (InfractionKind::CollisionLayout, "lay/km"),
    (InfractionKind::RedLight, "red/km"),
    (InfractionKind::StopSign, "stop/km"),
    (InfractionKind::OutsideRouteLanes, "off/km"),
];

/// A plain-text table of `summary`: one line per part and one for the whole suite.
pub fn suite_table(summary: &SuiteSummary) -> String {
    let total = format!("all ({})", summary.suite);
    let mut lines: Vec<(&str, &Figures)> = summary
        .parts
        .iter()
        .map(|part| (part.name.as_str(), &part.figures))
        .collect();
    lines.push((&total, &summary.all));
    figures_table(&lines, &summary.all)
}

/// A plain-text table of named groups of runs (a line each: runs, completed, km driven, DS, RC,
/// IS, success rate and infractions per km), then the failure classes of `classes`.
pub fn figures_table(lines: &[(&str, &Figures)], classes: &Figures) -> String {
    let width = lines
        .iter()
        .map(|(name, _)| name.len())
        .max()
        .unwrap_or(0)
        .max(20);
    let mut out = format!(
        "{:<width$} {:>5} {:>5} {:>7} {:>7} {:>7} {:>6} {:>6}",
        "part", "runs", "done", "km", "DS", "RC", "IS", "succ%"
    );
    for (_, head) in TABLE_KINDS {
        out.push_str(&format!(" {head:>7}"));
    }
    out.push('\n');
    for (name, f) in lines {
        out.push_str(&format!(
            "{:<width$} {:>5} {:>5} {:>7.2} {:>7.2} {:>7.2} {:>6.3} {:>6.1}",
            name,
            f.runs,
            f.completed,
            f.km_driven,
            f.scores.score_composed,
            f.scores.score_route,
            f.scores.score_penalty,
            f.bench2drive.success_rate
        ));
        for (kind, _) in TABLE_KINDS {
            out.push_str(&format!(" {:>7.2}", f.per_km.get(kind)));
        }
        out.push('\n');
    }
    if !classes.classes.is_empty() {
        let width = classes
            .classes
            .keys()
            .map(String::len)
            .max()
            .unwrap_or(0)
            .max(40);
        out.push_str(&format!(
            "\n{:<width$} {:>5} {:>7}\n",
            "failure classes (all runs)", "count", "per km"
        ));
        for (class, c) in &classes.classes {
            out.push_str(&format!(
                "{class:<width$} {:>5} {:>7.2}\n",
                c.count, c.per_km
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scoring::record::RouteMeta;

    fn run(rc: f64, length: f64, events: &[(&str, &str)]) -> RouteRecord {
        RouteRecord {
            meta: RouteMeta {
                route_length: length,
                events: events
                    .iter()
                    .map(|(kind, detail)| RouteEvent {
                        kind: kind.to_string(),
                        detail: detail.to_string(),
                        ..RouteEvent::default()
                    })
                    .collect(),
                ..RouteMeta::default()
            },
            scores: Scores {
                score_composed: rc,
                score_route: rc,
                score_penalty: 1.0,
            },
            status: "Completed".into(),
            ..RouteRecord::default()
        }
    }

    #[test]
    fn figures_count_per_km_driven_and_by_failure_class() {
        let crossing = (
            "collisions_vehicle",
            "crossing, in a junction, other 6.0 m/s, ego 3.0 m/s",
        );
        let placed = (
            "red_light",
            "placed light, lane 1 of 3, head 2 m ahead 9 m right, ego 7.5 m/s",
        );
        // A red its agent's frames last showed green: the age is not part of the class.
        let blind = (
            "red_light",
            "map light, lamp last in frame green, 25.3 s before, lane 1 of 1, head -8 m ahead 2 m right, ego 4.2 m/s",
        );
        let records = [
            run(100.0, 1000.0, &[crossing, placed]),
            run(50.0, 2000.0, &[crossing, blind]),
        ];
        let f = Figures::of(&records);
        assert_eq!((f.runs, f.completed), (2, 2));
        assert!((f.km_driven - 2.0).abs() < 1e-12);
        assert!((f.scores.score_route - 75.0).abs() < 1e-12);
        let class = &f.classes["collisions_vehicle: crossing, in a junction"];
        assert_eq!(class.count, 2);
        assert!((class.per_km - 1.0).abs() < 1e-12);
        assert_eq!(f.classes["red_light: placed light"].count, 1);
        assert_eq!(
            f.classes["red_light: map light, lamp last in frame green"].count,
            1
        );
        assert_eq!(f.classes.len(), 3);
        // Nothing driven: rates are 0, not a division by zero.
        let still = Figures::of(&[run(0.0, 1000.0, &[crossing])]);
        assert_eq!(
            still.classes["collisions_vehicle: crossing, in a junction"].per_km,
            0.0
        );
        assert_eq!(still.km_driven, 0.0);
    }

    #[test]
    fn every_suite_part_is_a_known_route_file_and_its_towns_are_refused() {
        for suite in &SUITES {
            for part in suite.parts {
                assert!(part_town(part).is_some(), "{part}");
            }
        }
        let towns = evaluation_towns();
        assert_eq!(towns, ["Town02", "ssr_heldout_radial", "ssr_town05"]);
    }
}
