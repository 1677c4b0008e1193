//! Expert datasets: a collection read back frame by frame, futures consistent with the poses,
//! frames identical to what a driving agent is shown, and clear errors for broken files.

use std::path::Path;

use sim_bridge::dataset::collect::{CollectConfig, EpisodeTask, collect};
use sim_bridge::driver::{Agent, AgentError, CameraFrame, Observation, RouteContext};
use sim_bridge::eval::run_route;
use sim_bridge::expert::Expert;
use sim_bridge::map::{Map, MapOptions};
use sim_bridge::route::planner::plan_route;
use sim_bridge::route::sets::{RandomRoutes, RouteSet, WalkStyle, random_routes};
use sim_bridge::route::xml;
use sim_bridge::scoring::ScoringConfig;
use sim_bridge::towngen::procedural::{Bends, Family, LightPlacement};
use sim_bridge::towngen::{self, bundled};
use sim_bridge::world::{World, WorldConfig};
use ssrdrive_proto::camera::Rig;
use ssrdrive_proto::control::Control;
use ssrdrive_proto::dataset::{
    ACTOR_RANGE, BrakeReason, Dataset, DatasetError, FUTURE_COUNT, LightAhead, NoiseConfig,
    parse_frames,
};

fn small_town() -> (Map, RouteSet) {
    let set = RouteSet::find("train-small").expect("bundled set");
    let map = Map::from_str(set.town.name(), bundled(set.town), MapOptions::default()).unwrap();
    (map, set)
}

fn world(seed: u64) -> WorldConfig {
    WorldConfig {
        vehicles: 20,
        walkers: 5,
        seed,
        ..WorldConfig::default()
    }
}

fn tasks<'m>(map: &'m Map, set: RouteSet, count: usize) -> Vec<EpisodeTask<'m>> {
    let specs = xml::parse(set.name, set.bundled_xml()).unwrap();
    specs
        .into_iter()
        .take(count)
        .enumerate()
        .map(|(k, spec)| EpisodeTask {
            map,
            route_set: set.name.to_string(),
            dense: plan_route(map, &spec).unwrap(),
            spec,
            repetition: 0,
            world: world(k as u64),
        })
        .collect()
}

fn config(out: &Path, noise: f64) -> CollectConfig {
    CollectConfig {
        out: out.to_path_buf(),
        rig: Rig::tcp_small(),
        rate_hz: 2.0,
        noise: NoiseConfig {
            rate: noise,
            ..NoiseConfig::default()
        },
        driver: None,
        tag: None,
        jobs: 2,
    }
}

#[test]
fn a_collection_reads_back_with_consistent_futures() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("dataset");
    let (map, set) = small_town();
    let tasks = tasks(&map, set, 3);
    let summary = collect(&config(&out, 0.5), &tasks, None, |_| {}).unwrap();
    assert_eq!(summary.recorded, 3);
    let data = Dataset::open(&out).unwrap();
    let m = &data.manifest;
    assert_eq!(m.episodes, 3);
    assert_eq!(m.rig, Rig::tcp_small());
    assert_eq!(m.towns[&map.name].frames, m.frames);
    let mut total = 0;
    let mut noisy = 0;
    for entry in &m.episode_list {
        let info = data.episode(&entry.name).unwrap();
        assert_eq!(info.route_set, "train-small");
        let frames = data.frames(&entry.name).unwrap();
        assert_eq!(frames.len(), entry.frames);
        assert!(frames.len() > 20, "{} frames", frames.len());
        total += frames.len();
        for pair in frames.windows(2) {
            let (a, b) = (&pair[0], &pair[1]);
            assert_eq!(b.tick - a.tick, 10, "2 Hz");
            noisy += a.noise as usize;
            if a.future_complete {
                assert_eq!(a.waypoints.len(), FUTURE_COUNT);
                assert_eq!(a.future_controls.len(), FUTURE_COUNT);
                assert_eq!(a.future_controls[0], b.control);
                // The first waypoint (0.5 s ahead) is the next frame's position in this
                // frame's ego frame.
                let (s, c) = a.yaw.sin_cos();
                let d = [b.position[0] - a.position[0], b.position[1] - a.position[1]];
                let local = [c * d[0] + s * d[1], -s * d[0] + c * d[1]];
                let w = a.waypoints[0];
                assert!((w[0] - local[0]).abs() < 1e-9 && (w[1] - local[1]).abs() < 1e-9);
            }
        }
        let last = frames.last().unwrap();
        assert!(!last.future_complete && last.waypoints.len() < FUTURE_COUNT);
        assert_eq!(
            info.truncated_frames,
            frames.iter().filter(|f| !f.future_complete).count()
        );
        let images = data.images(&entry.name, &frames[3]).unwrap();
        assert_eq!((images[0].width, images[0].height), (320, 96));
    }
    assert_eq!(total, m.frames);
    assert!(noisy > 0, "noise at 0.5 per second must show up");
    // Every frame records the actors around the ego (its BEV occupancy labels), within range,
    // and the light ahead (a light head's label), if any, with a distance to its stop line.
    let (mut near, mut lights) = (0, 0);
    for entry in &m.episode_list {
        for frame in data.frames(&entry.name).unwrap() {
            match frame.light.expect("every frame records the light ahead") {
                LightAhead::None => assert_eq!(frame.light_in_view, None),
                LightAhead::Green { distance }
                | LightAhead::Yellow { distance }
                | LightAhead::Red { distance } => {
                    assert!((0.0..200.0).contains(&distance), "{distance}");
                    assert!(frame.light_in_view.is_some(), "said with a light ahead");
                    lights += 1;
                }
            }
            let actors = frame.actors.expect("every frame records its actors");
            for actor in &actors {
                let [x, y] = actor.centre;
                assert!(x.hypot(y) <= ACTOR_RANGE + 1e-6, "{actor:?}");
                assert!(actor.half[0] > 0.0 && actor.half[1] > 0.0, "{actor:?}");
            }
            near += actors.len();
        }
    }
    assert!(near > 0, "the town's traffic is somewhere near");
    eprintln!("{lights} frames with a light ahead");
}

/// A town whose lights stand at the kerb before their stop lines (as CARLA's Town01 and Town02
/// post them): the camera sees a head while the ego comes up to it and loses it above the top
/// of its frame as the ego passes it, which the label says (training leaves out the frames
/// whose label follows a lamp out of view). Recorded with pedal noise, which never presses on
/// while the expert holds for a light: that pushed it past its stopping point to wait blind.
#[test]
fn light_labels_say_whether_the_head_is_in_the_cameras_view() {
    let family = Family {
        bends: Bends::Tight,
        lights: LightPlacement::Kerb,
    };
    let map = Map::from_str(
        "kerb",
        &towngen::generate_procedural(1, family),
        MapOptions::default(),
    )
    .unwrap();
    let style = WalkStyle {
        turn_bias: 0.45,
        change_rate: 0.0,
    };
    let options = RandomRoutes {
        count: 6,
        length: [300.0, 500.0],
        seed: 3,
        style,
    };
    let tasks: Vec<EpisodeTask> = random_routes(&map, "kerb", &options)
        .into_iter()
        .map(|spec| EpisodeTask {
            map: &map,
            route_set: "kerb".into(),
            dense: plan_route(&map, &spec).unwrap(),
            spec,
            repetition: 0,
            world: world(1),
        })
        .collect();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("dataset");
    let mut noisy = config(&out, 1.0);
    noisy.noise.longitudinal = 1.0;
    collect(&noisy, &tasks, None, |_| {}).unwrap();
    let data = Dataset::open(&out).unwrap();
    let (mut far_in_view, mut near_out_of_view) = (0, 0);
    let (mut pushed, mut pushed_at_lights) = (0, 0);
    let (mut red_stands, mut blind_red_stands) = (0, 0);
    for entry in &data.manifest.episode_list {
        for frame in data.frames(&entry.name).unwrap() {
            let pressed_on = frame.noise && frame.executed.throttle > 0.0;
            pushed += usize::from(pressed_on);
            pushed_at_lights +=
                usize::from(pressed_on && frame.brake_reason == Some(BrakeReason::TrafficLight));
            let distance = match frame.light.expect("recorded") {
                LightAhead::None => {
                    assert_eq!(frame.light_in_view, None);
                    continue;
                }
                LightAhead::Green { distance }
                | LightAhead::Yellow { distance }
                | LightAhead::Red { distance } => distance,
            };
            let in_view = frame.light_in_view.expect("said with a light ahead");
            far_in_view += usize::from(in_view && distance > 20.0);
            near_out_of_view += usize::from(!in_view && distance < 8.0);
            if matches!(frame.light, Some(LightAhead::Red { .. })) && frame.speed < 0.1 {
                red_stands += 1;
                blind_red_stands += usize::from(!in_view);
            }
        }
    }
    assert!(
        far_in_view > 0 && near_out_of_view > 0,
        "{far_in_view} frames in view far from the line, {near_out_of_view} out of view near it"
    );
    assert!(
        pushed > 0 && pushed_at_lights == 0,
        "{pushed} frames pressed on by noise, {pushed_at_lights} while the expert held for a light"
    );
    // The expert waits for a red where its camera still sees the lamp (short of the head, and
    // farther short of one far beside its lane), unless the light turned too late for that.
    assert!(
        red_stands > 0 && blind_red_stands * 10 <= red_stands,
        "{blind_red_stands} of {red_stands} frames standing at red with the lamp out of view"
    );
}

/// The expert with a camera, keeping every frame it is shown at 2 Hz.
struct Watcher {
    expert: Expert,
    seen: Vec<CameraFrame>,
}

impl Agent for Watcher {
    fn name(&self) -> String {
        "watcher".into()
    }
    fn start_route(&mut self, ctx: &RouteContext<'_>) -> Result<(), AgentError> {
        self.expert.start_route(ctx)
    }
    fn sensors(&self) -> Option<Rig> {
        Some(Rig::tcp_small())
    }
    fn wants_frames(&self, frame: u64) -> bool {
        frame.is_multiple_of(10)
    }
    fn run_step(&mut self, obs: &Observation, world: &World<'_>) -> Result<Control, AgentError> {
        self.seen.extend(obs.frames.iter().cloned());
        self.expert.run_step(obs, world)
    }
}

#[test]
fn the_dataset_stores_exactly_the_frames_an_agent_is_shown() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("dataset");
    let (map, set) = small_town();
    let tasks = tasks(&map, set, 1);
    collect(&config(&out, 0.0), &tasks, None, |_| {}).unwrap();
    let data = Dataset::open(&out).unwrap();
    let name = &data.manifest.episode_list[0].name;
    let frames = data.frames(name).unwrap();

    let mut watcher = Watcher {
        expert: Expert::new(),
        seen: Vec::new(),
    };
    let task = &tasks[0];
    run_route(
        &map,
        &task.spec,
        &task.dense,
        &mut watcher,
        task.world.clone(),
        ScoringConfig::default(),
        0,
        0,
        |_| {},
    );
    assert_eq!(watcher.seen.len(), frames.len());
    for (record, shown) in frames.iter().zip(&watcher.seen).step_by(7) {
        let stored = &data.images(name, record).unwrap()[0];
        assert_eq!(stored.rgb, shown.rgb, "frame {}", record.index);
    }
}

#[test]
fn broken_datasets_give_errors_that_name_the_file_and_problem() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("dataset");
    let missing = Dataset::open(&out).unwrap_err();
    assert!(matches!(missing, DatasetError::Io { .. }));
    assert!(missing.to_string().contains("manifest.json"), "{missing}");

    let (map, set) = small_town();
    let tasks = tasks(&map, set, 1);
    collect(&config(&out, 0.0), &tasks, None, |_| {}).unwrap();
    let data = Dataset::open(&out).unwrap();
    let name = data.manifest.episode_list[0].name.clone();
    let dir = data.episode_dir(&name);
    let frames = data.frames(&name).unwrap();

    // A frame whose image path leaves the episode is refused before anything is read.
    for escape in ["../../manifest.json", "/etc/passwd"] {
        let mut record = frames[0].clone();
        record.images[0] = escape.into();
        let err = data.images(&name, &record).unwrap_err().to_string();
        assert!(err.contains("leaves the episode"), "{escape}: {err}");
    }

    // Frames out of order (one line lost) are named by line.
    let path = dir.join("measurements.jsonl");
    let text = std::fs::read_to_string(&path).unwrap();
    let skipped: String = text
        .lines()
        .enumerate()
        .filter(|(n, _)| *n != 1)
        .map(|(_, line)| format!("{line}\n"))
        .collect();
    let err = parse_frames(skipped.as_bytes(), &path)
        .unwrap_err()
        .to_string();
    assert!(err.contains("line 2: frame 2 where 1 was due"), "{err}");

    // A measurements file cut in the middle of a line.
    std::fs::write(&path, &text[..text.len() * 2 / 3]).unwrap();
    let err = data.frames(&name).unwrap_err().to_string();
    assert!(
        err.contains("measurements.jsonl") && err.contains("line"),
        "{err}"
    );

    // A truncated PNG.
    let image = dir.join(&frames[0].images[0]);
    let bytes = std::fs::read(&image).unwrap();
    std::fs::write(&image, &bytes[..bytes.len() / 2]).unwrap();
    let err = data.images(&name, &frames[0]).unwrap_err().to_string();
    assert!(err.contains("000000.png"), "{err}");

    // Another rig is refused rather than mixed in.
    let mut other = config(&out, 0.0);
    other.rig = Rig::tcp();
    let err = collect(&other, &tasks, None, |_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("another rig"), "{err}");

    // The same run listed twice would write one folder from two threads.
    let (map2, set2) = small_town();
    let mut twice = self::tasks(&map2, set2, 1);
    twice.extend(self::tasks(&map2, set2, 1));
    let err = collect(&config(&out, 0.0), &twice, None, |_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("listed twice"), "{err}");

    // Resuming with another seed for a recorded run is refused, not silently skipped.
    let mut reseeded = self::tasks(&map2, set2, 1);
    reseeded[0].world.seed = 99;
    let err = collect(&config(&out, 0.0), &reseeded, None, |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("another seed") && err.contains("episode.json"),
        "{err}"
    );

    // A manifest of another format.
    let manifest = out.join("manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(&manifest, text.replace("\"version\": 1", "\"version\": 99")).unwrap();
    let err = Dataset::open(&out).unwrap_err().to_string();
    assert!(err.contains("version 99"), "{err}");
}

/// A driver that ignores the route: full throttle, steering a little left, never braking; with
/// `crash_after`, its server goes away after that many ticks.
#[derive(Default)]
struct Wanderer {
    ticks: usize,
    crash_after: Option<usize>,
}

impl Agent for Wanderer {
    fn name(&self) -> String {
        "wanderer".into()
    }
    fn start_route(&mut self, _: &RouteContext<'_>) -> Result<(), AgentError> {
        Ok(())
    }
    fn sensors(&self) -> Option<Rig> {
        Some(Rig::tcp_small())
    }
    fn run_step(&mut self, obs: &Observation, _: &World<'_>) -> Result<Control, AgentError> {
        assert_eq!(obs.frames.len(), 1, "a driver sees every tick's frame");
        self.ticks += 1;
        if self.crash_after.is_some_and(|n| self.ticks > n) {
            return Err(AgentError("Unavailable: tcp connect error".into()));
        }
        Ok(Control {
            steer: -0.05,
            throttle: 0.6,
            brake: 0.0,
        })
    }
}

/// A collection the [`Wanderer`] drives.
fn wanderer_drives(out: &Path) -> CollectConfig {
    CollectConfig {
        driver: Some("wanderer".into()),
        ..config(out, 0.0)
    }
}

/// DAgger: with a driver, the driver's control is executed and the expert labels the states it
/// reaches; the episode says who drove, and a collection with another driver is refused.
#[test]
fn a_driver_drives_while_the_expert_labels_its_states() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("dagger");
    let (map, set) = small_town();
    let tasks = tasks(&map, set, 1);
    let dagger = wanderer_drives(&out);
    let factory = || Ok(Box::new(Wanderer::default()) as Box<dyn Agent>);
    collect(&dagger, &tasks, Some(&factory), |_| {}).unwrap();
    let data = Dataset::open(&out).unwrap();
    let entry = &data.manifest.episode_list[0];
    let frames = data.frames(&entry.name).unwrap();
    assert!(frames.len() > 5, "{} frames", frames.len());
    for pair in frames.windows(2) {
        assert_eq!(
            pair[1].tick - pair[0].tick,
            10,
            "stored at 2 Hz, not every tick"
        );
    }
    for f in &frames {
        assert_eq!(
            (f.executed.throttle, f.executed.steer),
            (0.6, -0.05),
            "the driver drove"
        );
        assert!(!f.noise);
        assert_eq!(
            f.plan.len(),
            FUTURE_COUNT,
            "the expert's plan labels the frame"
        );
    }
    assert!(
        frames.iter().any(|f| f.control != f.executed),
        "the labels are the expert's own"
    );
    let info: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(data.episode_dir(&entry.name).join("episode.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(info["driver"], "wanderer");
    let err = collect(&config(&out, 0.0), &tasks, None, |_| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("driver"), "{err}");
    // A tagged round goes beside the untagged episodes in the same folder.
    let mut round = dagger.clone();
    round.tag = Some("round 2".into());
    collect(&round, &tasks, Some(&factory), |_| {}).unwrap();
    let names: Vec<String> = Dataset::open(&out)
        .unwrap()
        .manifest
        .episode_list
        .iter()
        .map(|e| e.name.clone())
        .collect();
    assert_eq!(names.len(), 2, "{names:?}");
    assert!(names[1].ends_with("__round-2"), "{names:?}");
}

/// A run whose driver crashed is not kept (the collection says so), and the next collection
/// redoes it, as it does an episode that older builds kept with the "crashed" status.
#[test]
fn a_run_whose_driver_crashed_is_not_kept_and_is_redone() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("dagger");
    let (map, set) = small_town();
    let tasks = tasks(&map, set, 1);
    let dagger = wanderer_drives(&out);
    let crashing = || {
        let crashes = Wanderer {
            crash_after: Some(40),
            ..Wanderer::default()
        };
        Ok(Box::new(crashes) as Box<dyn Agent>)
    };
    let err = collect(&dagger, &tasks, Some(&crashing), |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("crashed") && err.contains("tcp connect error"),
        "{err}"
    );
    let kept = std::fs::read_dir(out.join("episodes")).unwrap().count();
    assert_eq!(kept, 0, "nothing of the crashed run is kept");

    let working = || Ok(Box::new(Wanderer::default()) as Box<dyn Agent>);
    let summary = collect(&dagger, &tasks, Some(&working), |_| {}).unwrap();
    assert_eq!((summary.recorded, summary.skipped), (1, 0));

    let data = Dataset::open(&out).unwrap();
    let info_path = data
        .episode_dir(&data.manifest.episode_list[0].name)
        .join("episode.json");
    let text = std::fs::read_to_string(&info_path).unwrap();
    let mut info: serde_json::Value = serde_json::from_str(&text).unwrap();
    info["outcome"]["status"] = "Failed - Agent crashed".into();
    std::fs::write(&info_path, info.to_string()).unwrap();
    let summary = collect(&dagger, &tasks, Some(&working), |_| {}).unwrap();
    assert_eq!((summary.recorded, summary.skipped), (1, 0), "redone");
    let summary = collect(&dagger, &tasks, Some(&working), |_| {}).unwrap();
    assert_eq!((summary.recorded, summary.skipped), (0, 1), "complete now");
}
