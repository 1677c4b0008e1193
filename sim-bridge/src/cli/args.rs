//! Arguments shared by the commands that drive routes (`eval`, `render`, `collect`): which
//! routes on which map, and what populates the world.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::bail;
use clap::Args;
use sim_bridge::client::local::{LocalRole, LocalServer};
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::scenario_file::ScenarioFile;
use sim_bridge::route::xml::RouteSpec;
use sim_bridge::route::{DenseRoute, RoutePlan};
use sim_bridge::world::WorldConfig;

/// Which routes, on which map.
#[derive(Debug, Clone, Args)]
pub struct RouteArgs {
    /// A bundled route set (see `sim-bridge routes list`) or a CARLA route XML file.
    #[arg(long, default_value = "town05-long-style")]
    pub routes: String,
    /// The map: an .xodr file or a bundled town name (defaults to a bundled set's own town).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// A folder of maps named after their towns (Town05.xodr, ...): a CARLA route file's map
    /// is the one its routes' `town` names.
    #[arg(long, conflicts_with = "map")]
    pub maps: Option<PathBuf>,
    /// Only these route ids (comma separated).
    #[arg(long, value_delimiter = ',')]
    pub route_ids: Vec<String>,
    /// At most this many routes (after --route-ids).
    #[arg(long)]
    pub limit: Option<usize>,
    /// Do not place lights at multi-lane four-way junctions that the map leaves without.
    #[arg(long)]
    pub no_placed_lights: bool,
}

/// A route ready to drive.
pub struct PlannedRoute {
    pub spec: RouteSpec,
    pub dense: DenseRoute,
}

impl RouteArgs {
    /// The map and the selected routes, planned. A route that cannot be planned is reported
    /// and left out; none at all is an error.
    pub fn load(&self) -> anyhow::Result<(Map, Vec<PlannedRoute>)> {
        let (map, plans) = self.load_each()?;
        Self::keep_planned(&self.routes, map, plans)
    }

    /// The map and every selected route with its plan or the reason it has none; an error
    /// naming the file's ids when --route-ids names a route the file does not have.
    pub fn load_each(&self) -> anyhow::Result<(Map, Vec<RoutePlan>)> {
        let (map, plans, ids) = self.load_selected()?;
        check_route_ids(&self.route_ids, &ids, &self.routes)?;
        Ok((map, plans))
    }

    /// The map, the selected routes with their plans (a selection of no route is empty, not an
    /// error: one route set among several may hold none of --route-ids), and every id of the
    /// route file.
    pub fn load_selected(&self) -> anyhow::Result<(Map, Vec<RoutePlan>, Vec<String>)> {
        let options = MapOptions {
            place_missing_lights: !self.no_placed_lights,
        };
        let (map, mut specs) =
            super::load_routes(&self.routes, self.map.as_ref(), self.maps.as_ref(), options)?;
        check_towns(&specs, &map, &self.routes)?;
        let ids: Vec<String> = specs.iter().map(|s| s.id.clone()).collect();
        if !self.route_ids.is_empty() {
            specs.retain(|s| self.route_ids.contains(&s.id));
        }
        if let Some(limit) = self.limit {
            specs.truncate(limit);
        }
        let plans = specs
            .into_iter()
            .map(|spec| {
                let dense = plan_route(&map, &spec);
                (spec, dense)
            })
            .collect();
        Ok((map, plans, ids))
    }

    /// The routes of `plans` that could be planned (each other one is reported); none is an
    /// error naming `routes`.
    pub fn keep_planned(
        routes: &str,
        map: Map,
        plans: Vec<RoutePlan>,
    ) -> anyhow::Result<(Map, Vec<PlannedRoute>)> {
        let mut planned = Vec::with_capacity(plans.len());
        for (spec, dense) in plans {
            match dense {
                Ok(dense) => planned.push(PlannedRoute { spec, dense }),
                Err(e) => eprintln!("warning: skipping route {}: {e}", spec.id),
            }
        }
        if planned.is_empty() {
            bail!("no route of {routes} could be planned on map {}", map.name);
        }
        Ok((map, planned))
    }
}

/// An error naming the ids of `wanted` (--route-ids) that are not among `ids` (those of the
/// route files `routes`), and listing the ids there are.
pub fn check_route_ids(wanted: &[String], ids: &[String], routes: &str) -> anyhow::Result<()> {
    let missing: Vec<&str> = wanted
        .iter()
        .filter(|id| !ids.contains(id))
        .map(String::as_str)
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    bail!(
        "--route-ids: {} not in {routes}, whose route ids are {}",
        missing.join(", "),
        describe_ids(ids)
    )
}

/// "0-19" for the ids 0 to 19 in order, else the ids comma separated (the first 30); each id
/// once.
fn describe_ids(ids: &[String]) -> String {
    let mut seen = std::collections::HashSet::new();
    let ids: Vec<String> = ids.iter().filter(|id| seen.insert(*id)).cloned().collect();
    let numbers: Option<Vec<u64>> = ids.iter().map(|id| id.parse().ok()).collect();
    if let Some(numbers) = numbers.filter(|n| !n.is_empty()) {
        let (first, last) = (numbers[0], numbers[numbers.len() - 1]);
        if numbers.iter().zip(first..).all(|(&n, k)| n == k) {
            return format!("{first}-{last}");
        }
    }
    let shown: Vec<&str> = ids.iter().take(30).map(String::as_str).collect();
    let more = ids.len().saturating_sub(30);
    if more > 0 {
        format!("{} and {more} more", shown.join(", "))
    } else {
        shown.join(", ")
    }
}

/// An error when the routes name a town other than `map` (a route drawn on one town, snapped
/// onto another, drives somewhere else and scores as if it had not).
fn check_towns(specs: &[RouteSpec], map: &Map, routes: &str) -> anyhow::Result<()> {
    let other = specs
        .iter()
        .find(|s| !s.town.is_empty() && !s.town.eq_ignore_ascii_case(&map.name));
    if let Some(spec) = other {
        bail!(
            "--routes {routes}: route {} is on town {}, but the map is {}; give that town's map \
             (--map <{}.xodr | bundled town>, or --maps DIR holding {}.xodr)",
            spec.id,
            spec.town,
            map.name,
            spec.town,
            spec.town
        );
    }
    Ok(())
}

/// What populates the world.
#[derive(Debug, Clone, Args)]
pub struct WorldArgs {
    /// Base seed of traffic, scenarios, lights (and the look, with --randomise-appearance).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Background vehicles (default: the leaderboard's number for the town, 120 for Town05).
    #[arg(long)]
    pub vehicles: Option<usize>,
    /// Background walkers on sidewalks.
    #[arg(long, default_value_t = 0)]
    pub walkers: usize,
    /// No route scenarios (walkers crossing, cyclists, red-light runners).
    #[arg(long, conflicts_with = "scenarios")]
    pub no_scenarios: bool,
    /// A leaderboard scenario file (e.g. ../shared/carla/all_towns_traffic_scenarios_public.json):
    /// each route gets the scenarios the leaderboard 1.0 would give it from the file's triggers
    /// for its town, instead of scenarios drawn along it from the seed (see sim-bridge's README,
    /// "Scenario files").
    #[arg(long, value_name = "FILE")]
    pub scenarios: Option<PathBuf>,
    /// The file of --scenarios, read once.
    #[arg(skip)]
    pub scenario_file: std::sync::OnceLock<ScenarioFile>,
    /// No parked cars.
    #[arg(long)]
    pub no_parked_cars: bool,
    /// How background traffic treats the ego: `carla` (as CARLA's traffic manager: an obstacle
    /// not to drive into, nothing more) or `courteous` (lets it into a lane it waits to change
    /// into, gives it its turn and way at junctions, creeps past it when it stands; the default
    /// until 2026-11-29, in which the bundled agent's training data was recorded).
    #[arg(long, value_enum, default_value_t)]
    pub traffic: sim_bridge::world::TrafficMode,
    /// Vary camera colours, sun and sensor noise with the seed.
    #[arg(long)]
    pub randomise_appearance: bool,
}

impl WorldArgs {
    /// The world of one run on `map` with world seed `seed`; an error when --scenarios cannot
    /// be read or has no triggers for the map's town.
    pub fn config(&self, map: &Map, seed: u64) -> anyhow::Result<WorldConfig> {
        let scenario_file = match &self.scenarios {
            None => None,
            Some(path) => {
                let file = match self.scenario_file.get() {
                    Some(file) => file,
                    None => {
                        let read = ScenarioFile::read(path)?;
                        self.scenario_file.get_or_init(|| read)
                    }
                };
                Some(file.town(&map.name)?)
            }
        };
        Ok(WorldConfig {
            vehicles: self
                .vehicles
                .unwrap_or_else(|| sim_bridge::world::leaderboard_vehicles(map)),
            walkers: self.walkers,
            scenarios: !self.no_scenarios,
            scenario_file,
            parked_cars: !self.no_parked_cars,
            traffic: self.traffic,
            seed,
            randomise_appearance: self.randomise_appearance,
            // Follows `--scoring`: `eval::run_route` sets it from the rules.
            scenario_timeout: None,
        })
    }
}

/// The server an `--agent` value names: `grpc://HOST:PORT` (or `http://`), or `local`: a child
/// `ssr-agent serve` set up for `role`, alive as long as the returned handle.
pub fn server_target(
    agent: &str,
    role: LocalRole,
) -> anyhow::Result<(String, Option<LocalServer>)> {
    match agent {
        "local" => {
            let server = LocalServer::start(role)?;
            Ok((server.target(), Some(server)))
        }
        remote if remote.starts_with("grpc://") || remote.starts_with("http://") => {
            Ok((remote.to_string(), None))
        }
        other => bail!("--agent {other}: unknown agent (expected local or grpc://HOST:PORT)"),
    }
}

/// A positive, finite number (a clap value parser).
pub fn parse_positive(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(value) if value.is_finite() && value > 0.0 => Ok(value),
        _ => Err(format!("expected a positive number, got '{text}'")),
    }
}

/// A count of 1 or more (a clap value parser).
pub fn parse_count(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(count) if count >= 1 => Ok(count),
        _ => Err(format!(
            "expected a whole number of at least 1, got '{text}'"
        )),
    }
}

/// A positive number of seconds that fits a duration (a clap value parser).
pub fn parse_seconds(text: &str) -> Result<Duration, String> {
    parse_positive(text).and_then(|seconds| {
        Duration::try_from_secs_f64(seconds)
            .map_err(|_| format!("{seconds} s is longer than any run can take"))
    })
}

/// `MIN,MAX` with 0 <= MIN <= MAX, both finite (a clap value parser).
pub fn parse_range(value: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = value.split(',').collect();
    let [low, high] = parts.as_slice() else {
        return Err(format!("'{value}' is not MIN,MAX"));
    };
    let parse = |s: &str| {
        s.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| format!("'{s}' is not a finite number >= 0"))
    };
    let (low, high) = (parse(low)?, parse(high)?);
    if low > high {
        return Err(format!("MIN {low} is above MAX {high}"));
    }
    Ok([low, high])
}
