//! When the agent's cameras last framed each traffic light's head, and what it showed then
//! (ours, for failure analysis; the leaderboard has no such notion). A red-light infraction's
//! detail says it: "lamp last in frame green, 25.3 s before" is a red the agent never had in a
//! frame (the light turned while its head was out of view, as CARLA's Town01 and Town02 post
//! their heads beside the stop line); "lamp last in frame red, 0.0 s before" is a red it had in
//! frame as it crossed; "lamp never in frame" is a head no frame held at all.
//!
//! "In frame" is geometry only: the head's centre projects into one of the rig's frames
//! ([`ssrdrive_proto::camera::Rig::sees`]), with no test of occlusion, and only within
//! [`SIGHTING_RANGE_M`], beyond which a lamp is a pixel or two in the bundled rig's frame.

use ssrdrive_proto::camera::Rig;

use crate::map::Map;
use crate::route::plan::to_ego_frame;
use crate::world::state::{EgoState, LightState};

/// Heads farther from the ego than this (m) are not looked for in its frames.
pub const SIGHTING_RANGE_M: f64 = 40.0;

/// The last tick a light's head was in frame.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sighting {
    /// Simulation time, seconds.
    time: f64,
    /// What the head showed.
    state: LightState,
}

/// The last sighting of every light of a map, by light id.
#[derive(Debug, Clone, Default)]
pub(crate) struct LampSightings {
    last: Vec<Option<Sighting>>,
}

impl LampSightings {
    /// Note, at time `t`, every light within [`SIGHTING_RANGE_M`] whose head `rig` frames from
    /// `ego`; `lights` are the states indexed like `map.lights`.
    pub fn observe(&mut self, map: &Map, t: f64, ego: &EgoState, lights: &[LightState], rig: &Rig) {
        self.last.resize(map.lights.len(), None);
        let near = map.lights.iter().filter(|light| {
            light.head.truncate().distance(ego.position.truncate()) <= SIGHTING_RANGE_M
        });
        for light in near {
            let head = to_ego_frame(light.head, ego.position, ego.yaw).as_vec3();
            if let (true, Some(&state)) = (rig.sees(head.to_array()), lights.get(light.id)) {
                self.last[light.id] = Some(Sighting { time: t, state });
            }
        }
    }

    /// What the agent last had in frame of light `id`, as of time `t`: "lamp last in frame
    /// red, 0.0 s before" or "lamp never in frame".
    pub fn describe(&self, id: usize, t: f64) -> String {
        match self.last.get(id).copied().flatten() {
            Some(seen) => format!(
                "lamp last in frame {}, {:.1} s before",
                seen.state.name(),
                t - seen.time
            ),
            None => "lamp never in frame".to_string(),
        }
    }
}
