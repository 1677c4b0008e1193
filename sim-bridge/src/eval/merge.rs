//! Merging the results files of one campaign's shares (`eval --shard K/N`, [`super::shard`])
//! into the file one process would have written, under the leaderboard's
//! `merge_statistics.py` rules: every part must come from the same campaign (routes, settings,
//! timeout, seed, repetitions, agent and simulator: their [`CampaignPlan`]s agree but for the
//! share), no
//! run may appear twice, and every run must be there unless missing runs are allowed, when the
//! file says which are missing (entry status "Finished with missing data", each missing run
//! listed in the global record's `meta.exceptions`). The global record is computed again from
//! the merged runs.

use std::path::PathBuf;

use thiserror::Error;

use crate::scoring::record::CampaignPlan;
use crate::scoring::{Results, RouteRecord};

/// One results file to merge.
pub struct Part {
    /// Where it was read from (for messages).
    pub path: PathBuf,
    /// Its contents.
    pub results: Results,
}

/// Why the parts cannot be merged.
#[derive(Debug, Error)]
pub enum MergeError {
    /// Nothing to merge.
    #[error("no results files to merge")]
    NoParts,
    /// A part has no plan (a leaderboard file, or one from before plans were written).
    #[error(
        "{}: no `plan` in this results file, so nothing says which campaign its runs belong \
         to; merge only files written by `sim-bridge eval` (with or without --shard)",
        .0.display()
    )]
    NoPlan(PathBuf),
    /// Two parts come from different campaigns.
    #[error("{} and {} come from different campaigns: {what}", first.display(), other.display())]
    OtherPlan {
        /// The first part.
        first: PathBuf,
        /// The part that differs.
        other: PathBuf,
        /// What differs.
        what: String,
    },
    /// A record's index is outside its campaign.
    #[error("{}: run {index} is outside its campaign's {runs} runs", path.display())]
    OutOfRange {
        /// The part.
        path: PathBuf,
        /// The record's index.
        index: usize,
        /// Runs of the campaign.
        runs: usize,
    },
    /// A run appears twice.
    #[error("run {index} (route {route_id}) is in both {} and {}", first.display(), second.display())]
    Duplicate {
        /// The run's index.
        index: usize,
        /// Its route.
        route_id: String,
        /// The parts holding it.
        first: PathBuf,
        /// The second part holding it.
        second: PathBuf,
    },
    /// Runs are missing and that was not allowed.
    #[error(
        "{} of {runs} runs are missing: {}; drive them (the missing shares, or `eval --resume` \
         on a part) or pass --allow-missing to write a partial file",
        missing.len(),
        list(missing)
    )]
    Missing {
        /// The missing runs.
        missing: Vec<MissingRun>,
        /// Runs of the campaign.
        runs: usize,
    },
}

/// At most this many missing runs are named in a message.
const NAMED: usize = 12;

fn list(missing: &[MissingRun]) -> String {
    let mut text = missing
        .iter()
        .take(NAMED)
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(", ");
    if missing.len() > NAMED {
        text.push_str(&format!(" and {} more", missing.len() - NAMED));
    }
    text
}

/// The merged file, and the runs it lacks (empty unless missing runs were allowed).
#[derive(Debug)]
pub struct Merged {
    /// The campaign's results.
    pub results: Results,
    /// The missing runs.
    pub missing: Vec<MissingRun>,
}

/// Merges `parts` of one campaign; with `allow_missing`, runs no part holds are listed rather
/// than refused.
pub fn merge(parts: &[Part], allow_missing: bool) -> Result<Merged, MergeError> {
    let first = parts.first().ok_or(MergeError::NoParts)?;
    let plan_of = |part: &Part| {
        part.results
            .plan
            .clone()
            .ok_or_else(|| MergeError::NoPlan(part.path.clone()))
    };
    let plan = CampaignPlan {
        shard: None,
        ..plan_of(first)?
    };
    let mut records: Vec<Option<(RouteRecord, &PathBuf)>> = vec![None; plan.runs];
    for part in parts {
        let theirs = plan_of(part)?;
        if let Some(what) = difference(&plan, &theirs) {
            return Err(MergeError::OtherPlan {
                first: first.path.clone(),
                other: part.path.clone(),
                what,
            });
        }
        for record in &part.results.checkpoint.records {
            let slot = records
                .get_mut(record.index)
                .ok_or_else(|| MergeError::OutOfRange {
                    path: part.path.clone(),
                    index: record.index,
                    runs: plan.runs,
                })?;
            if let Some((_, earlier)) = slot {
                return Err(MergeError::Duplicate {
                    index: record.index,
                    route_id: record.route_id.clone(),
                    first: earlier.clone(),
                    second: part.path.clone(),
                });
            }
            *slot = Some((record.clone(), &part.path));
        }
    }
    let missing = missing_runs(&records, plan.repetitions);
    if !missing.is_empty() && !allow_missing {
        return Err(MergeError::Missing {
            missing,
            runs: plan.runs,
        });
    }
    let done: Vec<RouteRecord> = records.into_iter().flatten().map(|(r, _)| r).collect();
    let mut results = Results {
        plan: Some(plan.clone()),
        ..Results::new(done, plan.runs, first.results.sensors.clone())
    };
    if let Some(global) = &mut results.checkpoint.global_record {
        global.meta.exceptions.extend(missing.iter().map(|m| {
            let status = format!("Missing: repetition {} was in no merged part", m.repetition);
            (m.route_id.clone(), m.index, status)
        }));
    }
    Ok(Merged { results, missing })
}

/// What differs between two plans but for the share, if anything (the plainest difference
/// first: the fingerprint also covers the seed).
fn difference(a: &CampaignPlan, b: &CampaignPlan) -> Option<String> {
    if (a.repetitions, a.seed, a.runs) != (b.repetitions, b.seed, b.runs) {
        return Some(format!(
            "{} repetitions from seed {} ({} runs) against {} from seed {} ({} runs)",
            a.repetitions, a.seed, a.runs, b.repetitions, b.seed, b.runs
        ));
    }
    if a.timeout_s != b.timeout_s {
        let timeout = |t: Option<f64>| t.map_or("the leaderboard's".into(), |t| format!("{t} s"));
        return Some(format!(
            "route timeout {} against {}",
            timeout(a.timeout_s),
            timeout(b.timeout_s)
        ));
    }
    if a.traffic != b.traffic {
        let mode = |t: &Option<String>| t.as_deref().unwrap_or("unrecorded").to_string();
        return Some(format!(
            "traffic `{}` against `{}`",
            mode(&a.traffic),
            mode(&b.traffic)
        ));
    }
    let fields = [
        ("town", &a.town, &b.town),
        ("agent", &a.agent, &b.agent),
        ("simulator", &a.simulator, &b.simulator),
    ];
    if let Some((name, x, y)) = fields.iter().find(|(_, x, y)| x != y) {
        return Some(format!("{name} `{x}` against `{y}`"));
    }
    (a.fingerprint != b.fingerprint).then(|| {
        format!(
            "routes `{}` against `{}`: the routes, world or scoring settings differ",
            a.routes, b.routes
        )
    })
}

/// A run no part holds.
#[derive(Debug, Clone, PartialEq)]
pub struct MissingRun {
    /// Its index in the campaign.
    pub index: usize,
    /// Its route's id where another repetition names it, else `#` and the route's position.
    pub route_id: String,
    /// Its repetition.
    pub repetition: usize,
}

impl std::fmt::Display for MissingRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "run {} (route {} rep {})",
            self.index, self.route_id, self.repetition
        )
    }
}

/// The runs no part holds.
fn missing_runs(
    records: &[Option<(RouteRecord, &PathBuf)>],
    repetitions: usize,
) -> Vec<MissingRun> {
    let routes = (records.len() / repetitions.max(1)).max(1);
    let route_id = |route: usize| {
        (0..repetitions)
            .find_map(|r| records.get(r * routes + route)?.as_ref())
            .map_or_else(
                || format!("#{route}"),
                |(record, _)| record.route_id.clone(),
            )
    };
    records
        .iter()
        .enumerate()
        .filter(|(_, r)| r.is_none())
        .map(|(index, _)| MissingRun {
            index,
            route_id: route_id(index % routes),
            repetition: index / routes,
        })
        .collect()
}
