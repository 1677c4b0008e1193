//! `sim-bridge collect`: record the expert driving route sets into a training dataset (see the
//! `sim_bridge::dataset` docs for the layout). Interrupt it at any time; running the same
//! command again resumes.

use std::path::{Path, PathBuf};

use anyhow::bail;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sim_bridge::client::grpc::{GrpcAgent, GrpcOptions};
use sim_bridge::dataset::collect::{
    CollectConfig, CollectSummary, EpisodeTask, collect, ticks_per_frame,
};
use sim_bridge::driver::Agent;
use sim_bridge::eval::suite::evaluation_towns;
use sim_bridge::map::Map;
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::dataset::{NoiseConfig, fnv1a};

use sim_bridge::client::local::LocalRole;

use super::args::{PlannedRoute, RouteArgs, WorldArgs, check_route_ids, server_target};

#[derive(Debug, Args)]
pub struct CollectArgs {
    /// Route sets to drive, comma separated (bundled set names, or one route XML with --map).
    #[command(flatten)]
    route: RouteArgs,
    #[command(flatten)]
    world: WorldArgs,
    /// Dataset folder (created; an existing one is resumed).
    #[arg(long)]
    out: PathBuf,
    /// Camera rig: a preset (`tcp-small`: TCP's front camera at 320x96, the cpu-default
    /// model's input; `tcp`: 900x256) or a JSON rig file.
    #[arg(long, default_value = "tcp-small")]
    rig: String,
    /// Stored frames per simulated second (20 Hz divided by a whole number).
    #[arg(long, default_value_t = 2.0)]
    rate: f64,
    /// Runs of each route. Every run gets its own world seed, derived from --seed, the set,
    /// the route id and the repetition, so a resumed collection replays the same runs.
    #[arg(long, default_value_t = 1)]
    repetitions: usize,
    /// Perturbations per simulated second (0 disables noise injection).
    #[arg(long, default_value_t = NoiseConfig::default().rate)]
    noise_rate: f64,
    /// Smallest and largest steering offset of a lateral perturbation, `MIN,MAX`.
    #[arg(long, default_value = "0.1,0.3", value_parser = super::args::parse_range)]
    noise_steer: [f64; 2],
    /// Smallest and largest duration of a perturbation, seconds, `MIN,MAX`.
    #[arg(long, default_value = "0.5,1.0", value_parser = super::args::parse_range)]
    noise_duration: [f64; 2],
    /// Share of the perturbations that hold the pedals (coast and brake lightly, or press on)
    /// instead of pushing the steering.
    #[arg(long, default_value_t = 0.0)]
    noise_longitudinal: f64,
    /// DAgger: who drives instead of the expert, `grpc://HOST:PORT` (an agent server) or
    /// `local` (starts `ssr-agent serve`; SSR_AGENT_* variables such as SSR_AGENT_CHECKPOINT
    /// configure it). The expert still labels every stored frame from the state the driver
    /// reached; noise injection is off.
    #[arg(long)]
    driver: Option<String>,
    /// Added to every episode's folder name, so several collections share one dataset folder:
    /// a DAgger round beside the expert's episodes (`--driver local --tag dagger1`).
    #[arg(long)]
    tag: Option<String>,
    /// Worker threads (one route run each).
    #[arg(long, default_value_t = default_jobs(), allow_negative_numbers = true, value_parser = clap::value_parser!(u64).range(1..=256))]
    jobs: u64,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

fn default_jobs() -> u64 {
    std::thread::available_parallelism().map_or(1, |n| n.get() as u64)
}

/// The world seed of one run: FNV-1a of (set, route id, repetition), offset by `base`.
fn run_seed(base: u64, set: &str, route: &str, repetition: usize) -> u64 {
    let key = format!("{set}\u{1f}{route}\u{1f}{repetition}");
    base.wrapping_add(fnv1a(key.as_bytes()))
}

pub fn run(args: CollectArgs) -> anyhow::Result<()> {
    check_args(&args)?;
    let rig = Rig::from_name_or_file(&args.rig)?;
    let sets = load_sets(&args)?;
    let tasks = episode_tasks(&args, &sets)?;
    let (target, _local_server) = match &args.driver {
        Some(driver) => {
            let (target, server) = server_target(
                driver,
                LocalRole::Driving {
                    runs: args.jobs as usize,
                },
            )?;
            (Some(target), server)
        }
        None => (None, None),
    };
    let make_driver = |target: &str| -> Result<Box<dyn Agent>, String> {
        let options = GrpcOptions {
            // The driver sees the frames the dataset stores.
            rig: Some(rig.clone()),
            client: "sim-bridge collect (DAgger driver)".into(),
            ..GrpcOptions::default()
        };
        let agent = GrpcAgent::connect(target, options).map_err(|e| format!("{e:#}"))?;
        Ok(Box::new(agent) as Box<dyn Agent>)
    };
    let driver_factory = target.as_deref().map(|t| move || make_driver(t));
    let config = CollectConfig {
        out: args.out.clone(),
        rig: rig.clone(),
        rate_hz: args.rate,
        noise: NoiseConfig {
            rate: if args.driver.is_some() {
                0.0
            } else {
                args.noise_rate
            },
            duration: args.noise_duration,
            steer: args.noise_steer,
            longitudinal: args.noise_longitudinal,
        },
        driver: args.driver.clone(),
        tag: args.tag.clone(),
        jobs: args.jobs as usize,
    };
    let bar = progress_bar(args.quiet, tasks.len());
    let frames = std::sync::atomic::AtomicUsize::new(0);
    let started = std::time::Instant::now();
    let driver = driver_factory
        .as_ref()
        .map(|f| f as &(dyn Fn() -> Result<Box<dyn Agent>, String> + Sync));
    let summary = collect(&config, &tasks, driver, |done| {
        if !done.skipped {
            let total = frames.fetch_add(done.info.frames, std::sync::atomic::Ordering::Relaxed)
                + done.info.frames;
            let rate = total as f64 / started.elapsed().as_secs_f64().max(1e-9);
            bar.set_message(format!("{total} frames, {rate:.0} frames/s"));
        }
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    print_summary(&args.out, &summary)
}

/// Refuses settings that cannot make a dataset, naming the flag.
fn check_args(args: &CollectArgs) -> anyhow::Result<()> {
    if args.repetitions == 0 {
        bail!("--repetitions must be at least 1");
    }
    if !(args.noise_rate >= 0.0 && args.noise_rate.is_finite()) {
        bail!("--noise-rate must be a finite number >= 0");
    }
    if !(0.0..=1.0).contains(&args.noise_longitudinal) {
        bail!("--noise-longitudinal must be a share in 0..1");
    }
    if args.noise_steer[1] > 1.0 || args.noise_duration[0] <= 0.0 {
        bail!("--noise-steer must lie in 0..1 and --noise-duration above 0");
    }
    if ticks_per_frame(args.rate).is_none() {
        bail!(
            "--rate {}: must be 20 Hz divided by a whole number (20, 10, 5, 4, 2, 1, ...)",
            args.rate
        );
    }
    Ok(())
}

/// Each route set of `--routes` (comma separated) with its map and planned routes, refusing
/// the towns of an evaluation suite and route ids no set holds.
fn load_sets(args: &CollectArgs) -> anyhow::Result<Vec<(String, Map, Vec<PlannedRoute>)>> {
    let mut sets = Vec::new();
    let mut ids = Vec::new();
    for name in args
        .route
        .routes
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
    {
        let one = RouteArgs {
            routes: name.to_string(),
            ..args.route.clone()
        };
        // --route-ids selects across the sets: one set may hold none of them.
        let (map, plans, set_ids) = one.load_selected()?;
        ids.extend(set_ids);
        if evaluation_towns().contains(&map.name.as_str()) {
            bail!(
                "--routes {name} drives {}, a town of an evaluation suite (`eval --suite`): \
                 training data must not touch it, or the suite no longer measures towns the \
                 agent never saw; collect on the training towns (`sim-bridge towns list`)",
                map.name
            );
        }
        if !plans.is_empty() || args.route.route_ids.is_empty() {
            let (map, planned) = RouteArgs::keep_planned(name, map, plans)?;
            sets.push((name.to_string(), map, planned));
        }
    }
    check_route_ids(&args.route.route_ids, &ids, &args.route.routes)?;
    Ok(sets)
}

/// One episode per repetition, set and route, each with its own world seed; an error when
/// --scenarios has nothing for a set's town.
fn episode_tasks<'m>(
    args: &CollectArgs,
    sets: &'m [(String, Map, Vec<PlannedRoute>)],
) -> anyhow::Result<Vec<EpisodeTask<'m>>> {
    let mut tasks = Vec::new();
    for repetition in 0..args.repetitions {
        for (set, map, planned) in sets {
            for PlannedRoute { spec, dense } in planned {
                let seed = run_seed(args.world.seed, set, &spec.id, repetition);
                tasks.push(EpisodeTask {
                    map,
                    route_set: set.clone(),
                    spec: spec.clone(),
                    dense: dense.clone(),
                    repetition,
                    world: args.world.config(map, seed)?,
                });
            }
        }
    }
    Ok(tasks)
}

/// The episodes' progress bar (hidden with `--quiet`).
fn progress_bar(quiet: bool, episodes: usize) -> ProgressBar {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(episodes as u64)
    };
    let style = ProgressStyle::with_template(
        "{prefix} [{bar:40}] {pos}/{len} episodes {msg} ({elapsed}, eta {eta})",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style.progress_chars("=> "));
    bar.set_prefix("collect");
    bar
}

/// What this collection added and what the dataset at `out` now holds, town by town.
fn print_summary(out: &Path, summary: &CollectSummary) -> anyhow::Result<()> {
    let manifest = ssrdrive_proto::dataset::Dataset::open(out)?.manifest;
    println!(
        "collected {} episodes ({} frames) in {:.1} s: {:.0} frames/s; skipped {} already complete",
        summary.recorded,
        summary.frames,
        summary.wall_seconds,
        summary.frames as f64 / summary.wall_seconds.max(1e-9),
        summary.skipped
    );
    println!(
        "dataset {}: {} episodes, {} frames ({} with a truncated future), {:.1} MB ({:.1} MB per 10k frames)",
        out.display(),
        manifest.episodes,
        manifest.frames,
        manifest.truncated_frames,
        manifest.bytes as f64 / 1e6,
        manifest.bytes as f64 / 1e6 / (manifest.frames.max(1) as f64 / 1e4)
    );
    for (town, count) in &manifest.towns {
        println!(
            "  {town}: {} episodes, {} frames",
            count.episodes, count.frames
        );
    }
    Ok(())
}
