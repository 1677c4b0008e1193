//! An evaluation campaign: every selected route times every repetition, recorded in the
//! leaderboard's order (all routes of repetition 0, then of repetition 1, ...), driven by
//! several worker threads that each make their own agent (its own connection and episode on a
//! gRPC server, which can batch them), longest routes first. Results are the same as one run
//! at a time.
//!
//! The results file is rewritten whole after every run (atomically: a failed write leaves the
//! previous one), so an interrupted campaign keeps what it scored; with `resume` a campaign
//! keeps the runs that file already holds for the same plan and drives only the rest, and any
//! run whose agent crashed. A route that cannot be planned is a failed record, as the
//! leaderboard counts it. With a [`Shard`] it drives only that share of the runs, and its file
//! says so in its [`CampaignPlan`], for `results merge`.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use ssrdrive_support::files::{CappedReadError, read_capped_text, write_atomic};
use thiserror::Error;

use super::shard::Shard;
use super::{RouteRun, run_route};
use crate::driver::{Agent, AgentFactory};
use crate::map::Map;
use crate::route::xml::RouteSpec;
use crate::route::{DenseRoute, RoutePlan};
use crate::scoring::record::CampaignPlan;
use crate::scoring::{Results, ResultsError, RouteEnd, RouteRecord, ScoringConfig};
use crate::world::WorldConfig;

/// The largest results file a resume reads (a record is about 1 kB: room for 100,000 runs).
const MAX_RESULTS_BYTES: u64 = 128 << 20;

/// What to evaluate and where the results go.
pub struct Campaign<'a> {
    /// The town.
    pub map: &'a Map,
    /// The selected routes with their plans (or why they have none), in order.
    pub routes: &'a [RoutePlan],
    /// Runs of each route; repetition r runs in `world` with seed `world.seed + r`.
    pub repetitions: usize,
    /// The world of repetition 0.
    pub world: WorldConfig,
    /// The criteria and timeouts.
    pub scoring: ScoringConfig,
    /// The leaderboard results JSON, rewritten after every run.
    pub out: PathBuf,
    /// Keep the runs `out` already holds for this plan (see the module doc).
    pub resume: bool,
    /// Runs at once, each worker with its own agent.
    pub jobs: usize,
    /// Drive only this share of the runs (all of them without).
    pub shard: Option<Shard>,
    /// Drive only the runs of the first this many repetitions now (all of them without): the
    /// results file keeps the whole plan, and a later campaign with `resume` drives the rest.
    /// A suite drives repetition 0 of every part before repetition 1 of any, so that a suite cut
    /// short is still a sample of all its towns.
    pub first_repetitions: Option<usize>,
    /// The route set or file as the user gave it (for the results file's plan).
    pub label: String,
}

impl Campaign<'_> {
    /// Runs of the whole campaign (routes x repetitions).
    pub fn runs(&self) -> usize {
        self.routes.len() * self.repetitions
    }

    /// The results file's plan, before an agent has a name.
    pub fn plan(&self) -> CampaignPlan {
        let specs: Vec<&RouteSpec> = self.routes.iter().map(|(spec, _)| spec).collect();
        // The timeout is not part of it: a resume may drive the rest shorter or longer (the
        // plan names it apart, and a merge compares it).
        let scoring = ScoringConfig {
            timeout: None,
            ..self.scoring.clone()
        };
        let driven = format!("{specs:?} {:?} {scoring:?}", self.world);
        CampaignPlan {
            routes: self.label.clone(),
            town: self.map.name.clone(),
            fingerprint: format!("{:016x}", ssrdrive_proto::dataset::fnv1a(driven.as_bytes())),
            repetitions: self.repetitions,
            seed: self.world.seed,
            runs: self.runs(),
            timeout_s: self.scoring.timeout,
            traffic: Some(self.world.traffic.name()),
            agent: String::new(),
            simulator: format!("sim-bridge {}", env!("CARGO_PKG_VERSION")),
            shard: self.shard.map(|s| s.to_string()),
        }
    }

    /// Which runs (indices in leaderboard order) this process drives: all of them, or its
    /// share's.
    fn selected_runs(&self, lengths: &[f64]) -> Vec<bool> {
        let mut selected = vec![self.shard.is_none(); self.runs()];
        if let Some(shard) = self.shard {
            for run in shard.runs(lengths, self.repetitions) {
                selected[run] = true;
            }
        }
        selected
    }

    /// Drives run `index` with `agent` (`progress` sees its route completion every simulated
    /// second); a route that could not be planned gets its zero-score record without a drive.
    fn drive(
        &self,
        index: usize,
        agent: &mut dyn Agent,
        progress: impl FnMut(f64),
    ) -> (RouteRecord, Option<RouteRun>) {
        let repetition = index / self.routes.len();
        let (spec, dense) = &self.routes[index % self.routes.len()];
        let world = WorldConfig {
            seed: self.world.seed.wrapping_add(repetition as u64),
            ..self.world.clone()
        };
        match dense {
            Ok(dense) => {
                let driven = run_route(
                    self.map,
                    spec,
                    dense,
                    agent,
                    world,
                    self.scoring.clone(),
                    index,
                    repetition,
                    progress,
                );
                (driven.record.clone(), Some(driven))
            }
            Err(reason) => {
                let record = RouteRecord::unplannable(
                    index,
                    &spec.id,
                    spec.keypoint_length(),
                    repetition,
                    world.seed,
                    &reason.to_string(),
                );
                (record, None)
            }
        }
    }

    /// The route lengths the dispatch and the shares go by, m.
    fn lengths(&self) -> Vec<f64> {
        self.routes
            .iter()
            .map(|(spec, dense)| match dense {
                Ok(dense) => dense.length(),
                Err(_) => spec.keypoint_length(),
            })
            .collect()
    }
}

/// One finished run, as the observer hears of it.
pub struct RunDone<'r> {
    /// The route.
    pub spec: &'r RouteSpec,
    /// Its repetition, from 0.
    pub repetition: usize,
    /// The record saved to the results file.
    pub record: &'r RouteRecord,
    /// The dense route and the run itself; none when the route could not be planned.
    pub driven: Option<(&'r DenseRoute, &'r RouteRun)>,
}

/// What a caller hears of a campaign as it goes: progress displays, pictures.
pub trait CampaignObserver: Sync {
    /// Follows one run from its start to its end (a progress bar, say).
    type Run;

    /// A resumed campaign found `kept` of its `total` runs already scored in `out`.
    fn resuming(&self, kept: usize, total: usize, out: &Path);

    /// The first worker's agent is ready; `jobs` workers drive at once.
    fn agent_ready(&self, name: &str, jobs: usize);

    /// A run starts.
    fn run_started(&self, spec: &RouteSpec, repetition: usize) -> Self::Run;

    /// A driven run's route completion (percent), every simulated second.
    fn progress(&self, run: &Self::Run, route_completion: f64);

    /// A run ended and its record is saved; an error stops the campaign.
    fn run_finished(&self, run: Self::Run, done: &RunDone) -> Result<(), String>;
}

/// How a campaign went.
#[derive(Debug)]
pub struct CampaignReport {
    /// Every scored run (kept and driven now) as the leaderboard writes them.
    pub results: Results,
    /// Runs kept from the earlier results file.
    pub kept: usize,
    /// Runs whose agent crashed (to run again with `resume`).
    pub crashes: usize,
    /// Selected routes that could not be planned (zero-score records).
    pub unplannable: usize,
}

/// Why a campaign stopped or could not start.
#[derive(Debug, Error)]
pub enum CampaignError {
    /// Nothing to run.
    #[error("a campaign needs at least one route, one repetition and one job")]
    Empty,
    /// The earlier results file could not be read.
    #[error("reading {}: {source}", path.display())]
    Read {
        /// The results file.
        path: PathBuf,
        /// The failure.
        source: CappedReadError,
    },
    /// The earlier results file is not a results file.
    #[error("resuming from {}: {source}", path.display())]
    Results {
        /// The results file.
        path: PathBuf,
        /// What is wrong with it.
        source: ResultsError,
    },
    /// The earlier results file holds another plan.
    #[error(
        "cannot resume from {}: {reason}; resume with the same --routes, --route-ids, --limit, \
         --repetitions and --seed, or write to another --out",
        path.display()
    )]
    OtherPlan {
        /// The results file.
        path: PathBuf,
        /// Which run differs, and how.
        reason: String,
    },
    /// The results could not be saved (the previous file is intact).
    #[error("writing {}: {source}", path.display())]
    Write {
        /// The results file.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
    /// A worker could not make its agent.
    #[error("the agent: {0}")]
    Agent(String),
    /// The observer stopped the campaign.
    #[error("{0}")]
    Observer(String),
}

/// Drives every run of `campaign` not already scored, `make_agent` making each worker's agent.
pub fn run_campaign<O: CampaignObserver>(
    campaign: &Campaign,
    make_agent: AgentFactory,
    observer: &O,
) -> Result<CampaignReport, CampaignError> {
    if campaign.routes.is_empty() || campaign.repetitions == 0 || campaign.jobs == 0 {
        return Err(CampaignError::Empty);
    }
    let total = campaign.runs();
    let lengths = campaign.lengths();
    let selected = campaign.selected_runs(&lengths);
    let share = selected.iter().filter(|&&s| s).count();
    let (records, earlier_agent) = if campaign.resume {
        earlier_records(campaign, &selected)?
    } else {
        (vec![None; total], None)
    };
    let kept = records.iter().flatten().count();
    if campaign.resume {
        observer.resuming(kept, share, &campaign.out);
    }
    let now = |run: usize| {
        selected[run]
            && campaign
                .first_repetitions
                .is_none_or(|r| run / campaign.routes.len() < r)
    };
    let to_drive = (0..total).filter(|&run| now(run) && records[run].is_none());
    let jobs = campaign.jobs.min(to_drive.count()).max(1);
    let scored = Mutex::new(Scored {
        records,
        crashes: 0,
        plan: campaign.plan(),
        share,
    });
    let order: Vec<usize> = dispatch_order(&lengths, campaign.repetitions, jobs)
        .into_iter()
        .filter(|&run| now(run))
        .collect();
    let next_run = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let worker = |job: usize| -> Result<(), CampaignError> {
        let mut agent = make_agent().map_err(CampaignError::Agent)?;
        if job == 0 {
            observer.agent_ready(&agent.name(), jobs);
        }
        let identity = agent.identity();
        // Resumed runs of another agent would mix two evaluations in one file.
        if let Some(earlier) = earlier_agent.as_ref().filter(|a| **a != identity) {
            return Err(CampaignError::OtherPlan {
                path: campaign.out.clone(),
                reason: format!(
                    "its runs were driven by {earlier} and this evaluation's agent is {identity}"
                ),
            });
        }
        scored
            .lock()
            .expect("no worker panics holding it")
            .plan
            .agent = identity;
        while !failed.load(Ordering::Relaxed) {
            let Some(&index) = order.get(next_run.fetch_add(1, Ordering::Relaxed)) else {
                break;
            };
            if scored.lock().expect("no worker panics holding it").records[index].is_some() {
                continue;
            }
            let repetition = index / campaign.routes.len();
            let (spec, dense) = &campaign.routes[index % campaign.routes.len()];
            let run = observer.run_started(spec, repetition);
            let (record, driven) =
                campaign.drive(index, agent.as_mut(), |rc| observer.progress(&run, rc));
            let done = RunDone {
                spec,
                repetition,
                record: &record,
                driven: dense.as_ref().ok().zip(driven.as_ref()),
            };
            let crashed = driven.as_ref().is_some_and(|d| d.agent_error.is_some());
            store(campaign, &scored, index, &record, crashed)?;
            observer
                .run_finished(run, &done)
                .map_err(CampaignError::Observer)?;
        }
        Ok(())
    };
    on_threads(jobs, &failed, worker)?;
    let scored = scored.into_inner().expect("workers are done");
    Ok(CampaignReport {
        results: scored.results(),
        kept,
        crashes: scored.crashes,
        unplannable: campaign.routes.iter().filter(|(_, d)| d.is_err()).count(),
    })
}

/// Records run `index` (and whether its agent crashed) and rewrites the results file, so that
/// an interrupted campaign loses no scored run.
fn store(
    campaign: &Campaign,
    scored: &Mutex<Scored>,
    index: usize,
    record: &RouteRecord,
    crashed: bool,
) -> Result<(), CampaignError> {
    let mut scored = scored.lock().expect("no worker panics holding it");
    scored.crashes += usize::from(crashed);
    scored.records[index] = Some(record.clone());
    write_atomic(&campaign.out, scored.results().to_json().as_bytes()).map_err(|source| {
        CampaignError::Write {
            path: campaign.out.clone(),
            source,
        }
    })
}

/// Runs `worker(job)` for each of `jobs` on its own thread; the first that fails raises
/// `failed` (the others stop taking runs) and its error is returned.
fn on_threads(
    jobs: usize,
    failed: &AtomicBool,
    worker: impl Fn(usize) -> Result<(), CampaignError> + Sync,
) -> Result<(), CampaignError> {
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..jobs)
            .map(|job| {
                let worker = &worker;
                scope.spawn(move || {
                    let result = worker(job);
                    if result.is_err() {
                        failed.store(true, Ordering::Relaxed);
                    }
                    result
                })
            })
            .collect();
        workers
            .into_iter()
            .try_for_each(|w| w.join().expect("campaign workers do not panic"))
    })
}

/// The order in which workers take the runs (indices in leaderboard order) of routes of these
/// lengths (m) driven `repetitions` times: the leaderboard's with one worker; with several, the
/// longest routes first (ties in the leaderboard's order), so that no long run is left to drive
/// alone at the end while the other workers idle (the main job's two longest routes, 24 and 25,
/// are its last two in leaderboard order; from one run's per-route times this order ends its
/// 10 routes on two workers in 1,181 s instead of 1,245 s). Results do not depend on the
/// order: each run's world is seeded by its repetition.
fn dispatch_order(lengths: &[f64], repetitions: usize, jobs: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..lengths.len() * repetitions).collect();
    if jobs > 1 {
        order.sort_by(|&a, &b| lengths[b % lengths.len()].total_cmp(&lengths[a % lengths.len()]));
    }
    order
}

/// Runs scored so far, by index, and the file's plan.
struct Scored {
    records: Vec<Option<RouteRecord>>,
    crashes: usize,
    plan: CampaignPlan,
    /// Runs this process drives (the whole campaign's, or its share's).
    share: usize,
}

impl Scored {
    /// The results file so far: the scored runs in leaderboard order, and the plan.
    fn results(&self) -> Results {
        let done = self.records.iter().flatten().cloned().collect();
        Results {
            plan: Some(self.plan.clone()),
            ..Results::new(done, self.share, Vec::new())
        }
    }
}

/// The runs kept from an earlier results file, by run index, and the agent that drove them
/// (where the file names it).
type EarlierRuns = (Vec<Option<RouteRecord>>, Option<String>);

/// The records an earlier campaign of the same plan wrote to `campaign.out`, by run index
/// (none if there is no file yet). Runs whose agent crashed are dropped so they run again. A
/// record of another route, repetition or seed at its index, one outside the `selected` runs,
/// or a file whose plan has other runs or another share means another plan: an error, as the
/// file would otherwise mix two evaluations.
fn earlier_records(campaign: &Campaign, selected: &[bool]) -> Result<EarlierRuns, CampaignError> {
    let path = &campaign.out;
    let total = selected.len();
    let mut records = vec![None; total];
    let text = match read_capped_text(path, MAX_RESULTS_BYTES) {
        Ok(text) => text,
        Err(CappedReadError::Io(e)) if e.kind() == std::io::ErrorKind::NotFound => {
            return Ok((records, None));
        }
        Err(source) => {
            return Err(CampaignError::Read {
                path: path.clone(),
                source,
            });
        }
    };
    let results = Results::from_json(&text).map_err(|source| CampaignError::Results {
        path: path.clone(),
        source,
    })?;
    let other_plan = |reason: String| CampaignError::OtherPlan {
        path: path.clone(),
        reason,
    };
    if let Some(earlier) = &results.plan {
        let planned = campaign.plan();
        if earlier.fingerprint != planned.fingerprint {
            return Err(other_plan(format!(
                "it holds runs of {} on {} from seed {} and this evaluation drives {} on {} \
                 from seed {}, or other routes or world or scoring settings",
                earlier.routes,
                earlier.town,
                earlier.seed,
                planned.routes,
                planned.town,
                planned.seed
            )));
        }
        if earlier.shard != planned.shard {
            let share = |s: &Option<String>| s.clone().unwrap_or_else(|| "all runs".into());
            return Err(other_plan(format!(
                "it holds share {} and this evaluation drives {}",
                share(&earlier.shard),
                share(&planned.shard)
            )));
        }
    }
    let routes = campaign.routes;
    for record in results.checkpoint.records {
        let index = record.index;
        let repetition = index / routes.len();
        let spec = &routes[index % routes.len()].0;
        let expected_seed = campaign.world.seed.wrapping_add(repetition as u64);
        if index >= total
            || !selected[index]
            || record.route_id != spec.id
            || record.meta.repetition != Some(repetition)
            || record.meta.seed != Some(expected_seed)
        {
            let planned = if index < total && !selected[index] {
                "no run of its share".to_string()
            } else if index < total {
                format!(
                    "route {} repetition {repetition} seed {expected_seed}",
                    spec.id
                )
            } else {
                format!("only {total} runs")
            };
            return Err(other_plan(format!(
                "its run {index} is route {} repetition {:?} seed {:?}, but this evaluation \
                 plans {planned} there",
                record.route_id, record.meta.repetition, record.meta.seed
            )));
        }
        if record.status != RouteEnd::AgentCrashed.status() {
            records[index] = Some(record);
        }
    }
    let agent = results
        .plan
        .map(|plan| plan.agent)
        .filter(|a| !a.is_empty());
    Ok((records, agent))
}

#[cfg(test)]
mod tests {
    use super::dispatch_order;

    #[test]
    fn several_workers_take_the_longest_routes_first_and_one_takes_them_in_order() {
        let lengths = [300.0, 2100.0, 800.0];
        assert_eq!(dispatch_order(&lengths, 2, 1), [0, 1, 2, 3, 4, 5]);
        // Route 1 of both repetitions, then route 2's, then route 0's.
        assert_eq!(dispatch_order(&lengths, 2, 2), [1, 4, 2, 5, 0, 3]);
    }
}
