//! Checks every town through the `xodr` importer: it loads clean, its lanes
//! join, its lane graph is connected, its signals govern the right lanes,
//! and the test town has the size and features the evaluation expects.

use std::collections::{BTreeSet, HashMap, VecDeque};
use std::sync::OnceLock;

use xodr::{Direction, LaneId, LaneType, Orientation, Point, Provenance, RoadNetwork, Signal};

use super::procedural::{Bends, Family, LightPlacement};
use super::*;

/// Each town, loaded once and shared by the tests.
fn load(style: TownStyle) -> &'static (RoadNetwork, Provenance) {
    static TOWNS: OnceLock<Vec<(RoadNetwork, Provenance)>> = OnceLock::new();
    let towns = TOWNS.get_or_init(|| {
        TownStyle::ALL
            .iter()
            .map(|&s| {
                xodr::load_str_with_provenance(&generate(s))
                    .unwrap_or_else(|e| panic!("{} does not load: {e}", s.name()))
            })
            .collect()
    });
    let index = TownStyle::ALL
        .iter()
        .position(|&s| s == style)
        .expect("a style");
    &towns[index]
}

/// The importer's warnings that are faults (not the ones it marks as ignorable).
fn faults(provenance: &Provenance) -> Vec<String> {
    provenance
        .warnings
        .iter()
        .filter(|w| !w.is_ignored())
        .map(ToString::to_string)
        .collect()
}

/// Where traffic leaves a lane, and where it enters one.
fn exit(net: &RoadNetwork, id: LaneId) -> Point {
    let lane = net.lane(id).expect("a lane");
    let points = lane.center.points();
    match lane.direction {
        Direction::Backward => points[0],
        _ => points[points.len() - 1],
    }
}

/// Where `signal` stands from the end of lane `id`: metres ahead along the lane's last
/// direction (negative: before its end), and across.
fn from_lane_end(net: &RoadNetwork, signal: &Signal, id: LaneId) -> (f32, f32) {
    let lane = net.lane(id).expect("a lane");
    let t = lane.center.tangents();
    let along = match lane.direction {
        Direction::Backward => -t[0],
        _ => t[t.len() - 1],
    };
    let offset = signal.applies_at[0] - exit(net, id);
    let ahead = offset.dot(along);
    (ahead, (offset - along * ahead).length())
}

fn entry(net: &RoadNetwork, id: LaneId) -> Point {
    let lane = net.lane(id).expect("a lane");
    let points = lane.center.points();
    match lane.direction {
        Direction::Backward => points[points.len() - 1],
        _ => points[0],
    }
}

/// The junction a lane's road belongs to, if any.
fn junction_of(net: &RoadNetwork, id: LaneId) -> Option<String> {
    let road = net.road_lane(id)?.road;
    net.road(road)?.junction().map(str::to_string)
}

/// The lanes reachable from `start` over `edges`.
fn reach(start: usize, edges: &HashMap<usize, Vec<usize>>) -> BTreeSet<usize> {
    let mut seen = BTreeSet::from([start]);
    let mut queue = VecDeque::from([start]);
    while let Some(at) = queue.pop_front() {
        for &next in edges.get(&at).into_iter().flatten() {
            if seen.insert(next) {
                queue.push_back(next);
            }
        }
    }
    seen
}

/// The share of driving lanes reachable from, and reaching back to, the
/// first driving lane, driving on and changing lanes (`with_changes`) or
/// only driving on.
fn connected_share(net: &RoadNetwork, with_changes: bool) -> f64 {
    let driving: Vec<usize> = net.driving_lanes().map(|l| l.id.0).collect();
    let is_driving = |id: &LaneId| net.lane(*id).is_some_and(|l| l.kind == LaneType::Driving);
    let (mut forward, mut back) = (HashMap::new(), HashMap::new());
    for lane in net.driving_lanes() {
        let changes = lane.neighbors.iter().filter(|_| with_changes);
        for next in lane
            .successors
            .iter()
            .chain(changes)
            .filter(|n| is_driving(n))
        {
            forward
                .entry(lane.id.0)
                .or_insert_with(Vec::new)
                .push(next.0);
            back.entry(next.0).or_insert_with(Vec::new).push(lane.id.0);
        }
    }
    let both = reach(driving[0], &forward)
        .intersection(&reach(driving[0], &back))
        .count();
    both as f64 / driving.len() as f64
}

#[test]
fn names_round_trip_and_each_town_has_one_role() {
    for style in TownStyle::ALL {
        assert_eq!(TownStyle::from_name(style.name()), Some(style));
        assert!(!style.description().is_empty());
        assert_eq!(style.is_test_town(), style == TownStyle::Town05Style);
        assert_eq!(style.is_held_out(), style == TownStyle::HeldOutRadial);
        let roles = [
            style.is_test_town(),
            style.is_held_out(),
            style.is_training_town(),
        ];
        assert_eq!(roles.iter().filter(|&&r| r).count(), 1, "{}", style.name());
    }
    assert_eq!(TownStyle::from_name("town05"), None);
}

#[test]
fn generation_is_deterministic() {
    for style in TownStyle::ALL {
        assert!(generate(style) == generate(style), "{}", style.name());
    }
}

#[test]
fn bundled_files_are_current() {
    for style in TownStyle::ALL {
        assert!(
            generate(style) == bundled(style),
            "towns/{}.xodr is stale: run `cargo test --release -p sim-bridge -- --ignored regenerate_bundled_towns`",
            style.name()
        );
    }
}

#[test]
fn towns_load_without_faults() {
    for style in TownStyle::ALL {
        let (net, provenance) = load(style);
        let faults = faults(provenance);
        assert!(faults.is_empty(), "{}: {faults:#?}", style.name());
        assert!(net.driving_lanes().count() > 0);
    }
}

#[test]
fn driving_lanes_join_their_successors() {
    for style in TownStyle::ALL {
        let (net, _) = load(style);
        let mut joins = 0;
        for lane in net.driving_lanes() {
            let out = exit(net, lane.id);
            for &next in &lane.successors {
                let gap = out.distance_to(entry(net, next));
                assert!(
                    gap < 0.01,
                    "{}: lane {:?} to {next:?} gap {gap} m",
                    style.name(),
                    lane.id
                );
                let heading = |id: LaneId, at_exit: bool| {
                    let l = net.lane(id).expect("a lane");
                    let t = l.center.tangents();
                    let v = match (l.direction, at_exit) {
                        (Direction::Backward, true) => -t[0],
                        (Direction::Backward, false) => -t[t.len() - 1],
                        (_, true) => t[t.len() - 1],
                        (_, false) => t[0],
                    };
                    v.y.atan2(v.x)
                };
                let turn = (heading(next, false) - heading(lane.id, true)).to_degrees();
                let turn = (turn + 540.0).rem_euclid(360.0) - 180.0;
                assert!(
                    turn.abs() < 0.1,
                    "{}: lane {:?} to {next:?} turns {turn} deg",
                    style.name(),
                    lane.id
                );
                joins += 1;
            }
        }
        assert!(joins > 0, "{}", style.name());
    }
}

#[test]
fn every_driving_lane_leads_somewhere() {
    for style in TownStyle::ALL {
        let (net, _) = load(style);
        let dead: Vec<LaneId> = net
            .driving_lanes()
            .filter(|l| l.successors.is_empty() || l.predecessors.is_empty())
            .map(|l| l.id)
            .collect();
        assert!(dead.is_empty(), "{}: dead ends {dead:?}", style.name());
    }
}

#[test]
fn lane_graph_is_strongly_connected() {
    for style in TownStyle::ALL {
        let (net, _) = load(style);
        let share = connected_share(net, true);
        assert!(
            share >= 0.95,
            "{}: {:.1}% strongly connected",
            style.name(),
            share * 100.0
        );
    }
}

#[test]
fn connecting_roads_have_one_driving_lane() {
    for style in TownStyle::ALL {
        let (net, _) = load(style);
        let mut lanes: HashMap<usize, Vec<(i32, LaneType)>> = HashMap::new();
        for lane in net.lanes() {
            let at = net.road_lane(lane.id).expect("a road lane");
            if net.road(at.road).and_then(|r| r.junction()).is_some() {
                lanes
                    .entry(at.road.0)
                    .or_default()
                    .push((at.od_id, lane.kind));
            }
        }
        assert!(!lanes.is_empty(), "{}", style.name());
        for (road, lanes) in lanes {
            assert_eq!(
                lanes,
                [(-1, LaneType::Driving)],
                "{}: road {road}",
                style.name()
            );
        }
    }
}

#[test]
fn signals_govern_exactly_their_approach_lanes() {
    for style in TownStyle::ALL {
        let (net, provenance) = load(style);
        assert_eq!(provenance.signals.len(), net.signals().len());
        for placed in &provenance.signals {
            let road = net
                .road_by_od_id(&placed.road_id)
                .expect("the signal's road")
                .id();
            let direction = match placed.orientation {
                Orientation::Positive => Direction::Forward,
                _ => Direction::Backward,
            };
            let expected: BTreeSet<usize> = net
                .driving_lanes()
                .filter(|l| l.direction == direction)
                .filter(|l| net.road_lane(l.id).is_some_and(|at| at.road == road))
                .map(|l| l.id.0)
                .collect();
            let signal = net.signal(placed.signal).expect("a signal");
            let lanes: BTreeSet<usize> = signal.lanes.iter().map(|l| l.0).collect();
            assert_eq!(lanes, expected, "{}: signal {}", style.name(), placed.od_id);
        }
    }
}

/// The junctions the traffic lights or stop signs of `kind` control: the one a governed lane
/// leads into, or lies in (a light across the junction governs a connecting road).
fn controlled_junctions(net: &RoadNetwork, kind: &str) -> BTreeSet<String> {
    net.signals()
        .iter()
        .filter(|s| s.kind == kind)
        .flat_map(|s| s.lanes.iter())
        .filter_map(|&l| {
            junction_of(net, l).or_else(|| {
                let lane = net.lane(l).expect("a lane");
                lane.successors.iter().find_map(|&n| junction_of(net, n))
            })
        })
        .collect()
}

#[test]
fn signals_govern_their_approach_and_stand_where_its_drivers_see_them() {
    for style in TownStyle::ALL {
        let (net, _) = load(style);
        assert!(!net.signals().is_empty(), "{}", style.name());
        let mut far_side = 0;
        for signal in net.signals() {
            let name = style.name();
            assert!(
                !signal.lanes.is_empty(),
                "{name}: signal {:?} governs no lane",
                signal.id
            );
            for &id in &signal.lanes {
                let lane = net.lane(id).expect("a lane");
                assert_eq!(
                    lane.kind,
                    LaneType::Driving,
                    "{name}: signal {:?}",
                    signal.id
                );
                if junction_of(net, id).is_some() {
                    // A US-style light across the junction: it governs the connecting road its
                    // approach goes straight on by, entered from that approach's lane.
                    far_side += 1;
                    assert_eq!(signal.kind, "1000001", "{name}: a sign inside a junction");
                    assert!(
                        lane.predecessors
                            .iter()
                            .all(|&p| junction_of(net, p).is_none()),
                        "{name}: signal {:?} lane {id:?} is not entered from an approach",
                        signal.id
                    );
                } else {
                    assert!(
                        lane.successors
                            .iter()
                            .all(|&n| junction_of(net, n).is_some()),
                        "{name}: signal {:?} lane {id:?} doesn't lead into a junction",
                        signal.id
                    );
                }
                // Level with the lane's end along the road (the stop line, or the far side
                // of the junction for a connecting road), at most a road's width across it.
                let (ahead, across) = from_lane_end(net, signal, id);
                assert!(
                    (-2.0..=0.5).contains(&ahead) && across < 16.0,
                    "{name}: signal {:?} is {ahead} m ahead of and {across} m beside lane {id:?}'s end",
                    signal.id
                );
            }
            let up = signal.position.z - signal.applies_at[0].z;
            assert!(
                (1.0..=3.5).contains(&up),
                "{name}: board {up} m above the road"
            );
        }
        assert!(far_side > 0, "{}: no light across a junction", style.name());
    }
}

#[test]
fn kerb_towns_are_their_seeds_grid_with_every_light_at_the_kerb_before_its_stop_line() {
    // Where the head stands along its lane, from the stop line (negative: before it).
    for (placement, name, before_line) in [
        (LightPlacement::Kerb, "ssr_tight_kerb_", -2.0..=0.0),
        (
            LightPlacement::KerbSetBack,
            "ssr_tight_kerbback_",
            -7.5..=-1.5,
        ),
    ] {
        let (mut lights, mut set_backs) = (0, BTreeSet::new());
        for seed in 1..=6 {
            let kerb = Family {
                bends: Bends::Tight,
                lights: placement,
            };
            let across = Family {
                lights: LightPlacement::Across,
                ..kerb
            };
            let xodr = generate_procedural(seed, kerb);
            assert!(xodr.contains(&format!("name=\"{name}")), "named apart");
            assert_eq!(
                geometry_lines(&xodr),
                geometry_lines(&generate_procedural(seed, across)),
                "seed {seed}: the same roads as the town with its lights across"
            );
            let (net, _) = xodr::load_str_with_provenance(&xodr).unwrap();
            for signal in net.signals().iter().filter(|s| s.kind == "1000001") {
                lights += 1;
                let mut nearest = f32::MAX;
                for &id in &signal.lanes {
                    assert!(
                        junction_of(&net, id).is_none(),
                        "seed {seed}: across a junction"
                    );
                    let (ahead, across) = from_lane_end(&net, signal, id);
                    assert!(
                        before_line.contains(&ahead) && across < 16.0,
                        "{name}{seed}: light {:?} {ahead:.1} m ahead of, {across:.1} m beside its line",
                        signal.id
                    );
                    set_backs.insert((ahead * 2.0).round() as i32);
                    nearest = nearest.min(across);
                }
                // On the kerb: beside the rightmost lane (and its parking lane), not at the
                // sidewalk's back.
                assert!(
                    nearest < 5.0,
                    "seed {seed}: light {:?} {nearest:.1} m from its nearest lane",
                    signal.id
                );
            }
        }
        assert!(lights > 20, "{name}: {lights} lights in 6 towns");
        if placement == LightPlacement::KerbSetBack {
            assert!(
                set_backs.len() >= 6,
                "set-backs vary by light: {set_backs:?}"
            );
        }
    }
}

#[test]
fn town05_has_the_evaluation_features() {
    let (net, _) = load(TownStyle::Town05Style);
    let points: Vec<Point> = net
        .driving_lanes()
        .flat_map(|l| l.center.points().to_vec())
        .collect();
    let span = |f: fn(&Point) -> f32| {
        let (lo, hi) = points
            .iter()
            .map(f)
            .fold((f32::MAX, f32::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
        hi - lo
    };
    let (width, height) = (span(|p| p.x), span(|p| p.y));
    assert!((430.0..=510.0).contains(&width), "x extent {width}");
    assert!((360.0..=440.0).contains(&height), "y extent {height}");

    let signalized = controlled_junctions(net, "1000001");
    let all: BTreeSet<String> = net
        .lanes()
        .iter()
        .filter_map(|l| junction_of(net, l.id))
        .collect();
    let unsignalized = all.difference(&signalized).count();
    assert!(signalized.len() >= 12, "{} signalized", signalized.len());
    assert!(unsignalized >= 8, "{unsignalized} unsignalized");
    assert!(
        !controlled_junctions(net, "206").is_empty(),
        "no stop signs"
    );

    let mut lanes_per_side: HashMap<(usize, bool), i32> = HashMap::new();
    for lane in net.driving_lanes() {
        let at = net.road_lane(lane.id).expect("a road lane");
        let count = lanes_per_side.entry((at.road.0, at.od_id > 0)).or_default();
        *count = (*count).max(at.od_id.abs());
    }
    let three_lane = lanes_per_side.iter().any(|(&(road, left), &n)| {
        n == 3 && left && lanes_per_side.get(&(road, false)) == Some(&3)
    });
    assert!(three_lane, "no road with 3 lanes each way");
    assert!(
        net.lanes().iter().any(|l| l.kind == LaneType::Parking),
        "no parking lanes"
    );
    let top = net
        .lanes()
        .iter()
        .flat_map(|l| l.center.points())
        .map(|p| p.z)
        .fold(f32::MIN, f32::max);
    assert!(top >= 5.0, "highest lane at {top} m");
}

/// The `<geometry>` lines of a document, which place its reference lines.
fn geometry_lines(xodr: &str) -> BTreeSet<&str> {
    xodr.lines()
        .map(str::trim)
        .filter(|l| l.starts_with("<geometry "))
        .collect()
}

#[test]
fn training_towns_share_no_geometry_with_the_evaluation_towns() {
    let (training, evaluation): (Vec<_>, Vec<_>) = TownStyle::ALL
        .into_iter()
        .partition(|s| s.is_training_town());
    assert!(evaluation.len() >= 2 && !training.is_empty());
    for test_style in evaluation {
        let test = geometry_lines(bundled(test_style));
        for &style in &training {
            let shared = geometry_lines(bundled(style)).intersection(&test).count();
            assert_eq!(
                shared,
                0,
                "{} shares {shared} geometries with {}",
                style.name(),
                test_style.name()
            );
        }
    }
}

/// Not a check: prints each town's figures for sim-bridge/README.md
/// (`cargo test --release -p sim-bridge print_town_sizes -- --ignored --nocapture`).
#[test]
#[ignore = "prints figures, checks nothing"]
fn print_town_sizes() {
    for style in TownStyle::ALL {
        let (net, _) = load(style);
        let text = bundled(style);
        let junctions: BTreeSet<String> = net
            .lanes()
            .iter()
            .filter_map(|l| junction_of(net, l.id))
            .collect();
        println!(
            "{}: {} bytes, {} roads, {} junctions, {} signalized, {} driving lanes, strongly connected {:.1}% with lane changes, {:.1}% driving on only",
            style.name(),
            text.len(),
            net.roads().len(),
            junctions.len(),
            controlled_junctions(net, "1000001").len(),
            net.driving_lanes().count(),
            connected_share(net, true) * 100.0,
            connected_share(net, false) * 100.0,
        );
    }
}

/// Regenerates the committed towns: `cargo test --release -p sim-bridge --
/// --ignored regenerate_bundled_towns`.
#[test]
#[ignore]
fn regenerate_bundled_towns() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("towns");
    write_bundled(&dir).expect("writing the towns");
}

/// The radii of the arcs on the streets between junctions (connectors left out), metres.
fn street_arc_radii(xodr: &str) -> Vec<f64> {
    let mut on_street = false;
    let mut radii = Vec::new();
    for line in xodr.lines().map(str::trim) {
        if line.starts_with("<road ") {
            on_street = line.contains("junction=\"-1\"");
        } else if let Some(rest) = line.strip_prefix("<arc curvature=\"") {
            let curvature: f64 = rest.split('"').next().unwrap().parse().unwrap();
            if on_street {
                radii.push(1.0 / curvature.abs());
            }
        }
    }
    radii
}

#[test]
fn procedural_towns_load_clean_join_up_repeat_and_vary() {
    let evaluation: BTreeSet<&str> = TownStyle::ALL
        .into_iter()
        .filter(|s| !s.is_training_town())
        .flat_map(|s| geometry_lines(bundled(s)))
        .collect();
    for bends in [Bends::Gentle, Bends::Tight] {
        let family = Family {
            bends,
            lights: LightPlacement::Across,
        };
        let mut without_lights = 0;
        let mut sizes = BTreeSet::new();
        let mut tight_corners = 0;
        for seed in 1..=12 {
            let xodr = generate_procedural(seed, family);
            assert!(
                xodr == generate_procedural(seed, family),
                "seed {seed} is not deterministic"
            );
            assert!(xodr.contains(&format!("name=\"{}\"", procedural::name(seed, family))));
            let (net, provenance) = xodr::load_str_with_provenance(&xodr)
                .unwrap_or_else(|e| panic!("{bends:?} seed {seed} does not load: {e}"));
            let faults = faults(&provenance);
            assert!(faults.is_empty(), "{bends:?} seed {seed}: {faults:#?}");
            let dead = net
                .driving_lanes()
                .filter(|l| l.successors.is_empty() || l.predecessors.is_empty())
                .count();
            assert_eq!(dead, 0, "{bends:?} seed {seed}: {dead} dead ends");
            let share = connected_share(&net, true);
            assert!(
                share >= 0.95,
                "{bends:?} seed {seed}: {:.1}% connected",
                share * 100.0
            );
            let shared = geometry_lines(&xodr).intersection(&evaluation).count();
            assert_eq!(
                shared, 0,
                "{bends:?} seed {seed} shares {shared} geometries with an evaluation town"
            );
            without_lights += usize::from(!xodr.contains("1000001"));
            sizes.insert(net.driving_lanes().count());
            let radii = street_arc_radii(&xodr);
            // A street's corner stays wider than its own half width (the kerb never folds).
            assert!(
                radii.iter().all(|&r| r > 4.0),
                "{bends:?} seed {seed}: {radii:?}"
            );
            tight_corners += radii.iter().filter(|&&r| r < 18.0).count();
        }
        assert!(
            (1..12).contains(&without_lights),
            "{bends:?}: {without_lights} of 12 towns leave their lights to the simulator"
        );
        assert!(
            sizes.len() >= 8,
            "{bends:?}: towns alike in size: {sizes:?}"
        );
        match bends {
            // The gentle family's bends are all 18 m or wider.
            Bends::Gentle => assert_eq!(tight_corners, 0),
            // Four loop corners a town, and detours in most towns.
            Bends::Tight => assert!(
                tight_corners >= 12 * 4 + 40,
                "{tight_corners} tight corners"
            ),
        }
    }
}
