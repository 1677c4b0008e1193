//! Road maps: an OpenDRIVE file baked by the `xodr` crate into the lane graph the simulator
//! drives on ([`lanes`]), a spatial index over it ([`spatial`]), the drawable road surface
//! ([`surface`]), and the traffic control the world enforces: junctions, traffic lights and stop signs ([`traffic_control`]).
//!
//! Frame: the OpenDRIVE map frame (right-handed, x east, y north, z up, metres). Guarantees:
//! a loaded [`Map`] has at least one driving lane; a file over [`MAX_MAP_BYTES`] or one that is
//! not OpenDRIVE is refused with a [`MapError`] that names the file and the problem.
//!
//! Baking repairs what real files (CARLA's towns) and the xodr crate leave broken, each at the
//! mechanism, never per town: lanes of one road meet at lane-section seams
//! (`close_section_seams`), a centre line that steps sideways between two samples (a width or
//! offset polynomial that does not meet the next record) ramps across the step over a taper
//! (`taper_steps`), and a driving lane that ends where another begins from nowhere,
//! heading the same way, leads into it (`stitch_link_gaps`: links through roads and lane
//! sections too short to bake).

pub mod lanes;
pub mod spatial;
pub mod surface;
pub mod traffic_control;
pub mod waypoint;

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use glam::{DVec2, DVec3};
pub use lanes::{JunctionIdx, Lane, LaneIdx, LaneKind, LanePose, Projection};
use spatial::SegmentGrid;
use ssrdrive_proto::frames::wrap_angle;
use ssrdrive_support::files::{CappedReadError, read_capped_text};
pub use surface::Surface;
pub use traffic_control::{Approach, Junction, StopLine, StopSign, TrafficLight};

/// The largest OpenDRIVE file accepted (CARLA's largest towns are under 20 MB).
pub const MAX_MAP_BYTES: u64 = 64 * 1024 * 1024;

/// Why a map could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    /// The file could not be read, or is larger than [`MAX_MAP_BYTES`].
    #[error("cannot read map {path}: {source}")]
    Io {
        /// The map file, as given.
        path: String,
        /// Why the read failed.
        source: CappedReadError,
    },
    /// The OpenDRIVE importer refused the document.
    #[error("map {origin} is not valid OpenDRIVE: {message}")]
    Invalid {
        /// The map's name (the file stem, or the name given with the document).
        origin: String,
        /// Why it was refused.
        message: String,
    },
    /// The document has no driving lane to route on.
    #[error("map {origin} has no driving lanes")]
    NoDrivingLanes {
        /// The map's name (the file stem, or the name given with the document).
        origin: String,
    },
}

/// Options for loading a map.
#[derive(Debug, Clone, Copy)]
pub struct MapOptions {
    /// Place traffic lights at multi-lane four-way junctions that the file gives none (CARLA's
    /// old Town03 export has no `<signal>` at all). On by default.
    pub place_missing_lights: bool,
}

impl Default for MapOptions {
    fn default() -> Self {
        Self {
            place_missing_lights: true,
        }
    }
}

/// A baked road map.
#[derive(Debug)]
pub struct Map {
    /// Where the map came from (file name or a bundled town's name).
    pub name: String,
    /// Every lane, indexed by [`LaneIdx`].
    pub lanes: Vec<Lane>,
    /// Every junction, indexed by [`JunctionIdx`].
    pub junctions: Vec<Junction>,
    /// Traffic lights, one per signalized junction approach; `id` is the position here.
    pub lights: Vec<TrafficLight>,
    /// Stop signs; `id` is the position here.
    pub stop_signs: Vec<StopSign>,
    /// Plan bounds of all lanes: (min, max).
    pub bounds: (DVec2, DVec2),
    /// The drawable road surface (every lane type, road marks).
    pub surface: Surface,
    grid: SegmentGrid,
}

impl Map {
    /// Load an OpenDRIVE file.
    pub fn load_file(path: &Path, options: MapOptions) -> Result<Self, MapError> {
        let shown = path.display().to_string();
        let text = read_capped_text(path, MAX_MAP_BYTES).map_err(|source| MapError::Io {
            path: shown.clone(),
            source,
        })?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or(shown);
        Self::from_str(&name, &text, options)
    }

    /// Load an OpenDRIVE document held in memory; `name` labels errors and results.
    pub fn from_str(name: &str, xml: &str, options: MapOptions) -> Result<Self, MapError> {
        let invalid = |message: String| MapError::Invalid {
            origin: name.to_string(),
            message,
        };
        if xml.len() as u64 > MAX_MAP_BYTES {
            return Err(invalid(format!(
                "document is over the {MAX_MAP_BYTES}-byte limit"
            )));
        }
        let (net, provenance) =
            xodr::load_str_with_provenance(xml).map_err(|e| invalid(e.to_string()))?;
        report_dropped(name, &provenance.warnings);
        Self::from_network(name, &net, options)
    }

    /// Bake the simulator's view of an imported network.
    pub fn from_network(
        name: &str,
        net: &xodr::RoadNetwork,
        options: MapOptions,
    ) -> Result<Self, MapError> {
        let (lanes, junction_ids) = bake_lanes(net);
        if !lanes.iter().any(|l| l.kind == LaneKind::Driving) {
            return Err(MapError::NoDrivingLanes {
                origin: name.to_string(),
            });
        }
        let grid = SegmentGrid::build(&lanes);
        let mut lo = DVec2::splat(f64::INFINITY);
        let mut hi = DVec2::splat(f64::NEG_INFINITY);
        for p in lanes.iter().flat_map(|l| &l.points) {
            lo = lo.min(p.truncate());
            hi = hi.max(p.truncate());
        }
        let mut map = Map {
            name: name.to_string(),
            lanes,
            junctions: Vec::new(),
            lights: Vec::new(),
            stop_signs: Vec::new(),
            bounds: (lo, hi),
            surface: Surface::from_network(net),
            grid,
        };
        traffic_control::derive(&mut map, net, junction_ids, options);
        Ok(map)
    }

    /// The lane at `idx`.
    pub fn lane(&self, idx: LaneIdx) -> &Lane {
        &self.lanes[idx.get()]
    }

    /// The traffic light with a stop line at the end of `lane`, if any.
    pub fn light_ending(&self, lane: LaneIdx) -> Option<&TrafficLight> {
        self.lights
            .iter()
            .find(|light| light.stop_lines.iter().any(|line| line.lane == lane))
    }

    /// The junction connector a vehicle at the end of `lane`, heading `yaw`, takes to go
    /// straight on: of the connectors that follow the lane, the one whose chain (CARLA's files
    /// cut some connectors into several pieces) turns least, if that is under
    /// [`traffic_control::STRAIGHT_ON`]; with where that chain leaves the junction.
    pub fn straight_on(&self, lane: LaneIdx, yaw: f64) -> Option<(LaneIdx, LanePose)> {
        self.lane(lane)
            .successors
            .iter()
            .filter_map(|&first| {
                let mut piece = self.lane(first);
                if !piece.in_junction() {
                    return None;
                }
                for _ in 0..16 {
                    match piece.successors.first().map(|&s| self.lane(s)) {
                        Some(next) if next.in_junction() => piece = next,
                        _ => break,
                    }
                }
                let end = piece.pose_at(piece.length());
                let turn = angle_diff(end.yaw, yaw).abs();
                (turn < traffic_control::STRAIGHT_ON).then_some((turn, first, end))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map(|(_, first, end)| (first, end))
    }

    /// The driving lane whose centre line is nearest `p`, however far (CARLA's `get_waypoint`
    /// projects to the road from anywhere: route files hold keypoints up to 100 m off the map).
    pub fn nearest_driving(&self, p: DVec2) -> Option<(LaneIdx, Projection)> {
        self.nearest(p, f64::INFINITY, |l| l.kind == LaneKind::Driving)
    }

    /// The lane accepted by `keep` nearest `p`, within `max_distance` metres.
    pub fn nearest(
        &self,
        p: DVec2,
        max_distance: f64,
        keep: impl Fn(&Lane) -> bool,
    ) -> Option<(LaneIdx, Projection)> {
        self.grid.nearest(&self.lanes, p, max_distance, keep)
    }

    /// The lanes accepted by `keep` within `radius` of `p`, nearest first.
    pub fn lanes_near(
        &self,
        p: DVec2,
        radius: f64,
        keep: impl Fn(&Lane) -> bool,
    ) -> Vec<(LaneIdx, Projection)> {
        self.grid.within(&self.lanes, p, radius, keep)
    }

    /// The driving lane outside junctions that runs against a pose, about one lane width
    /// (`width`) to its left: the oncoming lane an overtake would borrow (heading more than
    /// 2.5 rad, about 143 degrees, away from `yaw`).
    pub fn oncoming_lane(&self, p: DVec2, yaw: f64, width: f64) -> Option<(LaneIdx, Projection)> {
        let left = DVec2::from_angle(yaw).perp();
        self.lanes_near(p + left * width, width, |l| {
            l.kind == LaneKind::Driving && !l.in_junction()
        })
        .into_iter()
        .find(|(l, proj)| angle_diff(self.lane(*l).pose_at(proj.s).yaw, yaw).abs() > 2.5)
    }

    /// The driving lane that best matches a pose: nearest among those within 4 m whose heading
    /// agrees with `yaw` within 60 degrees, else simply the nearest driving lane.
    pub fn lane_for_pose(&self, p: DVec3, yaw: f64) -> Option<(LaneIdx, Projection)> {
        let near = self.lanes_near(p.truncate(), 4.0, |l| l.kind == LaneKind::Driving);
        near.into_iter()
            .filter(|(idx, proj)| {
                let lane = self.lane(*idx);
                (p.z - lane.pose_at(proj.s).position.z).abs() < 3.0
            })
            .find(|(idx, proj)| angle_diff(self.lane(*idx).pose_at(proj.s).yaw, yaw).abs() < 1.05)
            .or_else(|| self.nearest_driving(p.truncate()))
    }
}

/// Logs what the import dropped: a road that baked nothing (a NaN, negative or absurd length,
/// no geometry) as a warning naming it, since a road that silently goes missing is a routing
/// mystery later; the rest (ignored features, links it could not keep) at debug level.
fn report_dropped(name: &str, warnings: &[xodr::Warning]) {
    for warning in warnings {
        if matches!(warning, xodr::Warning::RoadSkipped { .. }) {
            tracing::warn!("{name}: {warning}; it is left out of the map");
        } else {
            tracing::debug!("{name}: {warning}");
        }
    }
}

/// Signed difference `a - b` wrapped to (-pi, pi] ([`wrap_angle`]).
pub fn angle_diff(a: f64, b: f64) -> f64 {
    wrap_angle(a - b)
}

/// Bake xodr lanes into travel-ordered [`Lane`]s; returns them and the OpenDRIVE junction id of
/// each junction index handed out (in order of first appearance).
fn bake_lanes(net: &xodr::RoadNetwork) -> (Vec<Lane>, Vec<String>) {
    let mut index: HashMap<xodr::LaneId, LaneIdx> = HashMap::new();
    let mut junction_index: BTreeMap<String, JunctionIdx> = BTreeMap::new();
    let mut junction_ids: Vec<String> = Vec::new();
    let mut lanes: Vec<Lane> = Vec::new();
    for src in net.lanes() {
        if src.center.points().len() < 2 || src.direction == xodr::Direction::Both {
            continue;
        }
        let Some(road_lane) = net.road_lane(src.id) else {
            continue;
        };
        let Some(road) = net.road(road_lane.road) else {
            continue;
        };
        let mut points: Vec<DVec3> = src
            .center
            .points()
            .iter()
            .map(|p| DVec3::new(p.x as f64, p.y as f64, p.z as f64))
            .collect();
        if src.direction == xodr::Direction::Backward {
            points.reverse();
        }
        points.dedup_by(|a, b| (*a - *b).length_squared() < 1e-8);
        if points.len() < 2 || !points.iter().all(|p| p.is_finite()) {
            continue;
        }
        taper_steps(&mut points);
        if let Some(jump) = points
            .windows(2)
            .map(|w| (w[1] - w[0]).length())
            .find(|&step| step > MAX_POINT_STEP)
        {
            tracing::warn!(
                "road '{}' lane {}: its centre line jumps {jump:.0} m between samples (a width \
                 or offset polynomial out of range?); the lane is left out of the map",
                road.od_id(),
                road_lane.od_id
            );
            continue;
        }
        let junction = road.junction().map(|j| {
            *junction_index.entry(j.to_string()).or_insert_with(|| {
                junction_ids.push(j.to_string());
                JunctionIdx(junction_ids.len() as u32 - 1)
            })
        });
        let idx = LaneIdx(lanes.len() as u32);
        index.insert(src.id, idx);
        lanes.push(Lane {
            idx,
            kind: LaneKind::from_xodr(src.kind),
            road_id: road.od_id().to_string(),
            section: road_lane.section,
            lane_id: road_lane.od_id,
            junction,
            width: src.width as f64,
            cum: lanes::cumulative_length(&points),
            points,
            successors: Vec::new(),
            predecessors: Vec::new(),
            left: None,
            right: None,
        });
    }
    let map_ids = |ids: &[xodr::LaneId]| -> Vec<LaneIdx> {
        let mut out: Vec<LaneIdx> = ids.iter().filter_map(|i| index.get(i).copied()).collect();
        out.sort();
        out.dedup();
        out
    };
    for src in net.lanes() {
        let Some(&idx) = index.get(&src.id) else {
            continue;
        };
        let successors = map_ids(&src.successors);
        let predecessors = map_ids(&src.predecessors);
        let neighbours = map_ids(&src.neighbors);
        let lane = &lanes[idx.get()];
        let mid = lane.pose_at(lane.length() / 2.0);
        let (mut left, mut right) = (None, None);
        for n in neighbours {
            let offset = lanes[n.get()]
                .pose_at(lanes[n.get()].length() / 2.0)
                .position
                - mid.position;
            let forward = DVec2::from_angle(mid.yaw);
            if forward.perp_dot(offset.truncate()) > 0.0 {
                left = left.or(Some(n));
            } else {
                right = right.or(Some(n));
            }
        }
        let lane = &mut lanes[idx.get()];
        lane.successors = successors;
        lane.predecessors = predecessors;
        lane.left = left;
        lane.right = right;
    }
    close_section_seams(&mut lanes);
    stitch_link_gaps(&mut lanes);
    (lanes, junction_ids)
}

/// Makes lanes of one road meet where a lane section ends and the next begins. xodr 0.8
/// evaluates a road's laneOffset at a section's end with the *next* section's record (and
/// splits sections where a laneOffset record starts), so where the offset steps there (CARLA's
/// junction roads: 2.9 m in Town03, up to 7 m in Town04) the lower section's last vertex lands
/// where the next section's lanes are. A dense route drawn over it has a spike, out and
/// straight back, that the leaderboard's route-deviation check (5 points ahead) cannot get
/// past. The vertex is moved onto the next section's lane, whose start is right.
fn close_section_seams(lanes: &mut [Lane]) {
    let mut moves = Vec::new();
    for lane in lanes.iter() {
        for &next in &lane.successors {
            let next_lane = &lanes[next.get()];
            if next_lane.road_id != lane.road_id || next_lane.section == lane.section {
                continue;
            }
            let (end, start) = (*lane.points.last().expect("2+ points"), next_lane.points[0]);
            // The lower section (in road s) holds the wrong vertex: the travelling lane's end
            // on a lane that follows s, the next lane's start on one that runs against it.
            if lane.section < next_lane.section {
                moves.push((lane.idx, true, start));
            } else {
                moves.push((next, false, end));
            }
        }
    }
    for (idx, at_end, to) in moves {
        let lane = &mut lanes[idx.get()];
        match at_end {
            true => *lane.points.last_mut().expect("2+ points") = to,
            false => lane.points[0] = to,
        }
        lane.cum = lanes::cumulative_length(&lane.points);
    }
}

/// A centre-line segment that turns away from the one before it and back into the one after
/// by more than this, radians, each way, is a sideways step, not a bend.
const STEP_TURN: f64 = 0.1;
/// Steps narrower than this, metres, are left alone (float noise of the importer's `f32`s).
const STEP_MIN: f64 = 0.01;
/// Sideways metres per metre of travel across a tapered step: 0.1 spreads a 0.25 m step over
/// 2.5 m and turns the heading by under 0.1 rad.
const STEP_SLOPE: f64 = 0.1;

/// Ramps every sideways step of a centre line over a taper. A width or offset polynomial that
/// does not meet the next record's value is a step in the file (CARLA's Town06 widens the
/// connector lane 400:3 from 3.0 m to 3.5 m at one record), and the importer samples it as a
/// single segment that runs out sideways: a 0.25 m step across 0.35 m of road turns the heading
/// by 0.8 rad and back, so whatever follows `pose_at` swings broadside for a tick. The points
/// within the taper either side are moved across so the offset changes by at most
/// [`STEP_SLOPE`] a metre; the lane's ends stay where they are.
fn taper_steps(points: &mut [DVec3]) {
    let mut from = 1;
    while let Some((i, normal, lateral)) = find_step(points, from) {
        spread_step(points, i, normal, lateral);
        from = i + 1;
    }
}

/// The first sideways step at or after segment `from`: the segment's index, the unit normal
/// to the left of the travel around it, and how far the step moves left along it, metres.
fn find_step(points: &[DVec3], from: usize) -> Option<(usize, DVec2, f64)> {
    let direction = |i: usize| (points[i + 1] - points[i]).truncate();
    (from.max(1)..points.len().saturating_sub(2)).find_map(|i| {
        let (before, step, after) = (direction(i - 1), direction(i), direction(i + 1));
        let into = before.angle_to(step);
        let out = step.angle_to(after);
        let is_step = into.abs() > STEP_TURN
            && out.abs() > STEP_TURN
            && into.signum() != out.signum()
            && (into + out).abs() < 0.5 * into.abs().max(out.abs());
        let normal = (before.normalize_or_zero() + after.normalize_or_zero())
            .normalize_or_zero()
            .perp();
        let lateral = step.dot(normal);
        (is_step && lateral.abs() > STEP_MIN).then_some((i, normal, lateral))
    })
}

/// Moves the points either side of step segment `i` across along `normal` so that the
/// `lateral` step ramps over `lateral / STEP_SLOPE` metres centred on it (shorter where a
/// lane end comes first, sharing the step out to the other side), leaving segment `i`
/// straight along the lane.
fn spread_step(points: &mut [DVec3], i: usize, normal: DVec2, lateral: f64) {
    let cum = lanes::cumulative_length(points);
    let half = 0.5 * lateral.abs() / STEP_SLOPE;
    let before = half.min(cum[i]);
    let after = half.min(cum[cum.len() - 1] - cum[i + 1]);
    let ramp = before + after;
    for (k, p) in points.iter_mut().enumerate() {
        let shift = if k <= i {
            let x = cum[i] - cum[k];
            lateral * (before - x).max(0.0) / ramp
        } else {
            let x = cum[k] - cum[i + 1];
            -lateral * (after - x).max(0.0) / ramp
        };
        *p += (normal * shift).extend(0.0);
    }
}

/// Longest step between consecutive centre-line samples of a lane, metres: the importer
/// samples every few metres, so a longer one is a width or offset polynomial gone wild (a
/// cubic width of 5 s^3 is 135,000 km wide at 300 m), which would also make the spatial grid
/// index a lane across millions of cells.
const MAX_POINT_STEP: f64 = 500.0;

/// How close a lane's end must come to another lane's start to be joined to it, metres.
const STITCH_DISTANCE: f64 = 0.5;
/// And how well their headings must agree, radians.
const STITCH_HEADING: f64 = 0.5;

/// Joins the driving lanes that have no predecessor to the driving lanes that end where they
/// start, heading the same way. OpenDRIVE files hold links into roads and lane sections too
/// short to carry geometry (CARLA's Town03 has roads of 1 mm and 1 cm between roundabout
/// connectors and the streets, and connectors whose first section is 5 um long); such a piece
/// has no lanes once baked, so every link through it is lost: the lanes on either side
/// dead-end, or a connector lane that widens out of another begins from nowhere, where the
/// geometry runs on without a gap.
fn stitch_link_gaps(lanes: &mut [Lane]) {
    let is_driving = |l: &Lane| l.kind == LaneKind::Driving;
    let starts: Vec<(LaneIdx, DVec3, f64)> = lanes
        .iter()
        .filter(|l| is_driving(l) && l.predecessors.is_empty())
        .map(|l| (l.idx, l.points[0], l.pose_at(0.0).yaw))
        .collect();
    let mut joins = Vec::new();
    for lane in lanes.iter().filter(|l| is_driving(l)) {
        let end = lane.pose_at(lane.length());
        for &(start, at, yaw) in &starts {
            if start != lane.idx
                && (at - end.position).length() < STITCH_DISTANCE
                && angle_diff(yaw, end.yaw).abs() < STITCH_HEADING
            {
                joins.push((lane.idx, start));
            }
        }
    }
    for (from, to) in joins {
        lanes[from.get()].successors.push(to);
        lanes[to.get()].predecessors.push(from);
    }
}
