//! The real CARLA maps in ../shared/carla load and are drivable. Skips, with a notice, where that
//! folder is absent (it is never copied into the repository).

mod common;

use common::carla_dir;
use sim_bridge::map::{LaneKind, Map, MapOptions};

#[test]
fn carla_towns_load_with_lights_and_a_connected_lane_graph() {
    let Some(dir) = carla_dir() else { return };
    for town in ["Town01", "Town02", "Town03", "Town04", "Town06"] {
        let t0 = std::time::Instant::now();
        let map = Map::load_file(&dir.join(format!("{town}.xodr")), MapOptions::default())
            .unwrap_or_else(|e| panic!("{town}: {e}"));
        let driving = map
            .lanes
            .iter()
            .filter(|l| l.kind == LaneKind::Driving)
            .count();
        let signalized = map.junctions.iter().filter(|j| j.signalized).count();
        let dead_ends = map
            .lanes
            .iter()
            .filter(|l| l.kind == LaneKind::Driving && l.successors.is_empty())
            .count();
        eprintln!(
            "{town}: {} lanes ({driving} driving, {dead_ends} dead ends), {} junctions ({signalized} signalized), {} lights, {:.0?}",
            map.lanes.len(),
            map.junctions.len(),
            map.lights.len(),
            t0.elapsed()
        );
        assert!(driving > 50, "{town}: only {driving} driving lanes");
        assert!(signalized > 0, "{town}: no signalized junction");
        assert!(
            dead_ends * 20 < driving,
            "{town}: {dead_ends} dead-end driving lanes"
        );
    }
}
