//! Collection: record the expert over many route runs into one dataset, on several threads,
//! resuming where an interrupted collection stopped.
//!
//! Each run is an [`EpisodeTask`] with a deterministic folder name. Complete episodes already
//! on disk are skipped (after checking they were recorded with the same seed, rig, rate, noise
//! and look); leftover `.partial` folders (episodes that were in flight when the last
//! collection died) are deleted and their runs redone, which reproduces them exactly since a
//! run depends only on its map, route and world config. A run whose driving agent (DAgger's
//! learner, behind a server) crashed is not kept: the collection stops with an error naming it,
//! and the next one redoes it. A dataset collected with another rig or rate is refused rather
//! than mixed.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::dataset::{
    Dataset, DatasetError, EpisodeEntry, EpisodeInfo, EpisodeOutcome, FORMAT, FUTURE_COUNT,
    FUTURE_STEP, Manifest, NoiseConfig, TownCount, VERSION, read_json, safe_name,
};
use ssrdrive_support::files::write_atomic;

use super::recorder::EpisodeRecorder;
use crate::driver::{Agent, AgentFactory};
use crate::eval::run_route;
use crate::map::Map;
use crate::route::DenseRoute;
use crate::route::xml::RouteSpec;
use crate::scoring::{RouteEnd, ScoringConfig};
use crate::world::{DT, WorldConfig};

/// How to record.
#[derive(Debug, Clone)]
pub struct CollectConfig {
    /// Dataset root.
    pub out: PathBuf,
    /// Cameras to record.
    pub rig: Rig,
    /// Stored frames per simulated second (20 Hz divided by a whole number of ticks).
    pub rate_hz: f64,
    /// Noise injected into the executed control.
    pub noise: NoiseConfig,
    /// Who drives, when not the expert (DAgger), as recorded in each episode: the learner's
    /// server, for example.
    pub driver: Option<String>,
    /// Added to every episode's folder name, so several collections (DAgger rounds, say)
    /// share one dataset folder.
    pub tag: Option<String>,
    /// Worker threads.
    pub jobs: usize,
}

/// One route run to record.
pub struct EpisodeTask<'m> {
    /// Town the route runs in.
    pub map: &'m Map,
    /// Route set the route comes from, as named on the command line.
    pub route_set: String,
    /// The route as its `<route>` element gives it.
    pub spec: RouteSpec,
    /// The route planned over the lane graph, densified to about 1 m.
    pub dense: DenseRoute,
    /// Repetition of the route, from 0.
    pub repetition: usize,
    /// Traffic, scenarios, seed and look of the run's world.
    pub world: WorldConfig,
}

impl EpisodeTask<'_> {
    /// Folder name: town, set, route, repetition and the collection's tag, if any, in
    /// file-name-safe characters.
    pub fn name(&self, tag: Option<&str>) -> String {
        let name = format!(
            "{}__{}__{}__r{}",
            self.map.name, self.route_set, self.spec.id, self.repetition
        );
        safe_name(&match tag {
            Some(tag) => format!("{name}__{tag}"),
            None => name,
        })
    }
}

/// What happened during a collection.
#[derive(Debug, Clone, Copy, Default)]
pub struct CollectSummary {
    /// Episodes recorded now.
    pub recorded: usize,
    /// Episodes found complete and skipped.
    pub skipped: usize,
    /// Frames recorded now.
    pub frames: usize,
    /// Wall-clock time of the whole collection, s.
    pub wall_seconds: f64,
}

/// Progress reports, one per finished episode.
#[derive(Debug, Clone)]
pub struct EpisodeDone {
    /// The episode's `episode.json`.
    pub info: EpisodeInfo,
    /// Whether it was already on disk.
    pub skipped: bool,
}

/// Record every task not yet in the dataset; `progress` hears of each episode as it ends. With
/// `driver` (and `config.driver` naming it), its agents drive and the expert labels.
pub fn collect(
    config: &CollectConfig,
    tasks: &[EpisodeTask<'_>],
    driver: Option<AgentFactory<'_>>,
    progress: impl Fn(&EpisodeDone) + Sync,
) -> Result<CollectSummary, DatasetError> {
    let ticks_per_frame = ticks_per_frame(config.rate_hz).ok_or_else(|| {
        DatasetError::invalid(
            &config.out,
            format!(
                "rate {} Hz is not 20 Hz divided by a whole number of ticks",
                config.rate_hz
            ),
        )
    })?;
    config
        .rig
        .validate()
        .map_err(|e| DatasetError::invalid(&config.out, format!("rig: {e}")))?;
    let tag = config.tag.as_deref();
    let mut names: Vec<String> = tasks.iter().map(|t| t.name(tag)).collect();
    names.sort();
    if let Some(pair) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(DatasetError::invalid(
            &config.out,
            format!(
                "two runs would both be episode {} (a route listed twice?)",
                pair[0]
            ),
        ));
    }
    let episodes = config.out.join("episodes");
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| DatasetError::Io { path, source }
    };
    std::fs::create_dir_all(&episodes).map_err(io(&episodes))?;
    check_compatible(config)?;
    remove_partials(&episodes)?;
    let started = Instant::now();
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let summary = Mutex::new(CollectSummary::default());
    let first_error: Mutex<Option<DatasetError>> = Mutex::new(None);
    let worker = || {
        let mut own_driver = match driver.map(|make| make()).transpose() {
            Ok(d) => d,
            Err(e) => {
                failed.store(true, Ordering::Relaxed);
                let error = DatasetError::invalid(&config.out, format!("the driver: {e}"));
                first_error.lock().expect("error lock").get_or_insert(error);
                return;
            }
        };
        while !failed.load(Ordering::Relaxed) {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(task) = tasks.get(k) else { break };
            let result = collect_one(config, task, ticks_per_frame, own_driver.as_deref_mut());
            let result = result.and_then(|done| {
                let mut s = summary.lock().expect("summary lock");
                if done.skipped {
                    s.skipped += 1;
                } else {
                    s.recorded += 1;
                    s.frames += done.info.frames;
                    write_manifest(config)?;
                }
                progress(&done);
                Ok(())
            });
            if let Err(e) = result {
                failed.store(true, Ordering::Relaxed);
                first_error.lock().expect("error lock").get_or_insert(e);
            }
        }
    };
    std::thread::scope(|scope| {
        for _ in 0..config.jobs.max(1) {
            scope.spawn(worker);
        }
    });
    if let Some(e) = first_error.into_inner().expect("error lock") {
        return Err(e);
    }
    write_manifest(config)?;
    let mut summary = summary.into_inner().expect("summary lock");
    summary.wall_seconds = started.elapsed().as_secs_f64();
    Ok(summary)
}

/// Ticks per stored frame for a rate, if the rate divides 20 Hz.
pub fn ticks_per_frame(rate_hz: f64) -> Option<u64> {
    if !rate_hz.is_finite() || rate_hz <= 0.0 {
        return None;
    }
    let ticks = (1.0 / (rate_hz * DT)).round();
    ((ticks * rate_hz * DT - 1.0).abs() < 1e-9 && ticks >= 1.0).then_some(ticks as u64)
}

fn collect_one(
    config: &CollectConfig,
    task: &EpisodeTask<'_>,
    ticks_per_frame: u64,
    driver: Option<&mut (dyn Agent + 'static)>,
) -> Result<EpisodeDone, DatasetError> {
    let name = task.name(config.tag.as_deref());
    let episodes = config.out.join("episodes");
    let dir = episodes.join(&name);
    if let Some(info) = recorded_before(config, task, ticks_per_frame, &dir)? {
        return Ok(EpisodeDone {
            info,
            skipped: true,
        });
    }
    let partial = episodes.join(format!(".{name}.partial"));
    let io = |source| DatasetError::Io {
        path: partial.clone(),
        source,
    };
    let seed = task.world.seed;
    let mut recorder = EpisodeRecorder::create(
        &partial,
        config.rig.clone(),
        ticks_per_frame,
        config.noise,
        seed,
        driver,
    )
    .map_err(io)?;
    let run = run_route(
        task.map,
        &task.spec,
        &task.dense,
        &mut recorder,
        task.world.clone(),
        ScoringConfig::default(),
        0,
        task.repetition,
        |_| {},
    );
    let totals = recorder.finish().map_err(io)?;
    if let Some(error) = run.agent_error {
        // The states before the crash are real, but a resumed collection must redo the run,
        // so nothing of it is kept.
        std::fs::remove_dir_all(&partial).map_err(io)?;
        return Err(DatasetError::invalid(
            &dir,
            format!(
                "the driving agent crashed ({error}); the run was not kept: collect again to \
                 redo it"
            ),
        ));
    }
    let scores = run.record.scores;
    let info = EpisodeInfo {
        name: name.clone(),
        town: task.map.name.clone(),
        route_set: task.route_set.clone(),
        route_id: task.spec.id.clone(),
        repetition: task.repetition,
        seed,
        rig: config.rig.clone(),
        rate_hz: config.rate_hz,
        ticks_per_frame,
        noise: config.noise,
        driver: config.driver.clone(),
        randomise_appearance: task.world.randomise_appearance,
        frames: totals.frames,
        truncated_frames: totals.truncated_frames,
        bytes: totals.bytes,
        outcome: EpisodeOutcome {
            status: run.record.status.clone(),
            route_completion: scores.score_route,
            driving_score: scores.score_composed,
            sim_seconds: run.record.meta.duration_game,
        },
        wall_seconds: run.wall_seconds,
    };
    let json = serde_json::to_vec_pretty(&info)
        .map_err(|e| DatasetError::invalid(&partial, e.to_string()))?;
    std::fs::write(partial.join("episode.json"), json).map_err(io)?;
    std::fs::rename(&partial, &dir).map_err(io)?;
    Ok(EpisodeDone {
        info,
        skipped: false,
    })
}

/// The episode already in `dir`, when this collection asked for the same one and its driver
/// did not crash; a crashed one is removed (to be driven again), one recorded with other
/// settings is refused.
fn recorded_before(
    config: &CollectConfig,
    task: &EpisodeTask<'_>,
    ticks_per_frame: u64,
    dir: &Path,
) -> Result<Option<EpisodeInfo>, DatasetError> {
    let info_path = dir.join("episode.json");
    if !info_path.exists() {
        return Ok(None);
    }
    let info: EpisodeInfo = read_json(&info_path)?;
    let same = info.seed == task.world.seed
        && info.rig == config.rig
        && info.ticks_per_frame == ticks_per_frame
        && info.noise == config.noise
        && info.driver == config.driver
        && info.randomise_appearance == task.world.randomise_appearance;
    if !same {
        return Err(DatasetError::invalid(
            &info_path,
            "recorded with another seed, rig, rate, noise, driver or look than this \
             collection asks for; collect into a new folder (or repeat the original command)",
        ));
    }
    if info.outcome.status != RouteEnd::AgentCrashed.status() {
        return Ok(Some(info));
    }
    // Kept by builds that stored a run whose driver crashed: redo it.
    std::fs::remove_dir_all(dir).map_err(|source| DatasetError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    Ok(None)
}

/// Refuse to add to a dataset recorded with another rig or rate.
fn check_compatible(config: &CollectConfig) -> Result<(), DatasetError> {
    if !config.out.join("manifest.json").exists() {
        return Ok(());
    }
    let existing = Dataset::open(&config.out)?;
    let m = &existing.manifest;
    if m.rig != config.rig || (m.rate_hz - config.rate_hz).abs() > 1e-9 {
        return Err(DatasetError::invalid(
            &config.out,
            format!(
                "the dataset there was recorded with another rig or rate ({} camera(s) at {} Hz); \
                 collect into a new folder instead of mixing",
                m.rig.cameras.len(),
                m.rate_hz
            ),
        ));
    }
    Ok(())
}

/// Delete the folders of episodes that were in flight when a collection stopped.
fn remove_partials(episodes: &Path) -> Result<(), DatasetError> {
    let io = |source| DatasetError::Io {
        path: episodes.to_path_buf(),
        source,
    };
    for entry in std::fs::read_dir(episodes).map_err(io)? {
        let entry = entry.map_err(io)?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') && name.ends_with(".partial") {
            std::fs::remove_dir_all(entry.path()).map_err(io)?;
        }
    }
    Ok(())
}

/// Rebuild `manifest.json` from every complete episode on disk.
pub fn write_manifest(config: &CollectConfig) -> Result<Manifest, DatasetError> {
    let episodes = config.out.join("episodes");
    let io = |source| DatasetError::Io {
        path: episodes.clone(),
        source,
    };
    let mut infos: Vec<EpisodeInfo> = Vec::new();
    for entry in std::fs::read_dir(&episodes).map_err(io)? {
        let entry = entry.map_err(io)?;
        if entry.file_name().to_string_lossy().starts_with('.') {
            continue; // in flight
        }
        let path = entry.path().join("episode.json");
        if path.exists() {
            infos.push(read_json(&path)?);
        }
    }
    infos.sort_by(|a, b| a.name.cmp(&b.name));
    let mut manifest = Manifest {
        format: FORMAT.into(),
        version: VERSION,
        rig: config.rig.clone(),
        rate_hz: config.rate_hz,
        future_step_s: FUTURE_STEP,
        future_count: FUTURE_COUNT,
        episodes: infos.len(),
        frames: 0,
        truncated_frames: 0,
        bytes: 0,
        towns: Default::default(),
        episode_list: Vec::with_capacity(infos.len()),
    };
    for info in &infos {
        manifest.frames += info.frames;
        manifest.truncated_frames += info.truncated_frames;
        manifest.bytes += info.bytes;
        let town: &mut TownCount = manifest.towns.entry(info.town.clone()).or_default();
        town.episodes += 1;
        town.frames += info.frames;
        manifest.episode_list.push(EpisodeEntry {
            name: info.name.clone(),
            town: info.town.clone(),
            route_set: info.route_set.clone(),
            route_id: info.route_id.clone(),
            frames: info.frames,
        });
    }
    let path = config.out.join("manifest.json");
    let json = serde_json::to_vec_pretty(&manifest)
        .map_err(|e| DatasetError::invalid(&path, e.to_string()))?;
    write_atomic(&path, &json).map_err(|source| DatasetError::Io { path, source })?;
    Ok(manifest)
}
