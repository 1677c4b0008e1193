//! The town builder: a layout declares junctions and the streets between
//! them; [`TownBuilder::build`] numbers everything, derives each junction's
//! connecting roads from its legs, and places the traffic signals.

use glam::DVec2;

use super::elevation::{self, Cubic};
use super::geometry::{Frame, Path};
use super::junction::{LaneLink, Leg, default_links, straight_on_from_rightmost};
use super::profile::{LANE_WIDTH, Profile};
use super::signals::{LightPlacement, approach_signal, far_side_light, kerb_light, kerb_set_back};
use super::town::{Connection, Contact, Controller, Junction, Link, Road, SignalKind, Town};

/// A junction being declared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct JunctionId(usize);

/// A street (any road outside a junction) being declared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RoadId(usize);

/// A hand-made connection: incoming lane `from_lane` of road `from` to
/// outgoing lane `to_lane` of road `to`, lanes counted 1-based from the
/// centre line in the traffic's own terms.
#[derive(Debug, Clone, Copy)]
pub struct ManualLink {
    /// The incoming road.
    pub from: RoadId,
    /// Its lane.
    pub from_lane: usize,
    /// The outgoing road.
    pub to: RoadId,
    /// Its lane.
    pub to_lane: usize,
}

/// How a junction's traffic is controlled.
#[derive(Debug, Clone, Default)]
enum Control {
    /// No signs or lights.
    #[default]
    Free,
    /// A traffic light on every approach.
    Lights,
    /// A stop sign on these approaches.
    Stops(Vec<RoadId>),
}

#[derive(Debug, Clone)]
struct JunctionDef {
    name: String,
    /// In the layout's own axes.
    center: DVec2,
    setback: f64,
    control: Control,
    manual: Option<Vec<ManualLink>>,
}

#[derive(Debug, Clone)]
struct StreetDef {
    name: String,
    /// In world axes.
    path: Path,
    profile: Profile,
    elevation: Vec<Cubic>,
    start: Option<JunctionId>,
    end: Option<JunctionId>,
}

/// Collects a town's junctions and streets, then builds the [`Town`].
pub struct TownBuilder {
    name: String,
    frame: Frame,
    /// Junctions declared with lights get no light signals in the file.
    lights_left_to_simulator: bool,
    /// Where the file's lights stand.
    light_placement: LightPlacement,
    junctions: Vec<JunctionDef>,
    streets: Vec<StreetDef>,
}

impl TownBuilder {
    /// A town called `name` whose layout coordinates are placed by `frame`.
    pub fn new(name: impl Into<String>, frame: Frame) -> Self {
        Self {
            name: name.into(),
            frame,
            lights_left_to_simulator: false,
            light_placement: LightPlacement::default(),
            junctions: Vec::new(),
            streets: Vec::new(),
        }
    }

    /// Declare a junction centred at `center` (layout axes) whose streets
    /// stop `setback` metres short of it.
    pub fn junction(&mut self, name: impl Into<String>, center: DVec2, setback: f64) -> JunctionId {
        self.junctions.push(JunctionDef {
            name: name.into(),
            center,
            setback,
            control: Control::Free,
            manual: None,
        });
        JunctionId(self.junctions.len() - 1)
    }

    /// A straight street from junction `from` to junction `to`.
    pub fn street(&mut self, from: JunctionId, to: JunctionId, profile: &Profile) -> RoadId {
        self.street_via(from, &[], 0.0, to, profile)
    }

    /// A street from `from` through the corners `via` to `to`, each corner
    /// rounded with `radius`.
    pub fn street_via(
        &mut self,
        from: JunctionId,
        via: &[DVec2],
        radius: f64,
        to: JunctionId,
        profile: &Profile,
    ) -> RoadId {
        let (a, b) = (&self.junctions[from.0], &self.junctions[to.0]);
        let mut points = vec![a.center];
        points.extend_from_slice(via);
        points.push(b.center);
        let path = Path::rounded(&points, radius).trimmed(a.setback, b.setback);
        let name = format!("{} to {}", a.name, b.name);
        self.road(name, path, profile, Some(from), Some(to))
    }

    /// A road along `path` (layout axes), exactly, from junction `start` to
    /// junction `end`.
    pub fn road(
        &mut self,
        name: impl Into<String>,
        path: Path,
        profile: &Profile,
        start: Option<JunctionId>,
        end: Option<JunctionId>,
    ) -> RoadId {
        self.streets.push(StreetDef {
            name: name.into(),
            path: path.transformed(&self.frame),
            profile: profile.clone(),
            elevation: elevation::flat(),
            start,
            end,
        });
        RoadId(self.streets.len() - 1)
    }

    /// The length of `road`.
    pub fn length(&self, road: RoadId) -> f64 {
        self.streets[road.0].path.length()
    }

    /// Give `road` an elevation profile.
    pub fn set_elevation(&mut self, road: RoadId, profile: Vec<Cubic>) {
        self.streets[road.0].elevation = profile;
    }

    /// Write no traffic-light signal at all, as CARLA's old Town03 and some other CARLA towns
    /// do: the simulator then places its own lights (across the junction, at junctions of four
    /// or more approaches with a multi-lane one; `map::traffic_control`).
    pub fn leave_lights_to_simulator(&mut self) {
        self.lights_left_to_simulator = true;
    }

    /// Stand the file's traffic lights as `placement` says (across the junction by default).
    pub fn place_lights(&mut self, placement: LightPlacement) {
        self.light_placement = placement;
    }

    /// Put a traffic light on every approach of `j`.
    pub fn lights(&mut self, j: JunctionId) {
        self.junctions[j.0].control = Control::Lights;
    }

    /// Put a stop sign on the approaches of `j` from `roads`.
    pub fn stop_signs(&mut self, j: JunctionId, roads: &[RoadId]) {
        self.junctions[j.0].control = Control::Stops(roads.to_vec());
    }

    /// Replace the default connections of `j` by `links`.
    pub fn connect_manually(&mut self, j: JunctionId, links: Vec<ManualLink>) {
        self.junctions[j.0].manual = Some(links);
    }

    /// The legs of junction `j`, in street order.
    fn legs(&self, j: JunctionId) -> Vec<Leg<'_>> {
        let mut legs = Vec::new();
        for (i, street) in self.streets.iter().enumerate() {
            let leg = |contact, end| Leg {
                road: i,
                contact,
                end,
                profile: &street.profile,
            };
            if street.start == Some(j) {
                legs.push(leg(Contact::Start, street.path.start));
            }
            if street.end == Some(j) {
                legs.push(leg(Contact::End, street.path.end()));
            }
        }
        legs
    }

    /// The links of junction `j`: its manual ones, or the default rule's.
    fn links(&self, j: JunctionId, legs: &[Leg]) -> Vec<LaneLink> {
        let Some(manual) = &self.junctions[j.0].manual else {
            return default_links(legs);
        };
        let leg_of = |road: RoadId| {
            let mut found = legs.iter().enumerate().filter(|(_, l)| l.road == road.0);
            let (index, _) = found
                .next()
                .expect("a manual link names a road of its junction");
            assert!(
                found.next().is_none(),
                "a road with both ends in one junction"
            );
            index
        };
        manual
            .iter()
            .map(|m| LaneLink {
                from: leg_of(m.from),
                from_lane: m.from_lane,
                to: leg_of(m.to),
                to_lane: m.to_lane,
            })
            .collect()
    }

    /// Number everything and derive the connecting roads and signals.
    ///
    /// Ids share one sequence: streets from 1, then junctions, then
    /// connecting roads, then signals, then controllers.
    pub fn build(self) -> Town {
        let mut ids = Ids {
            next: 1 + (self.streets.len() + self.junctions.len()) as u32,
        };
        let mut roads: Vec<Road> = self
            .streets
            .iter()
            .enumerate()
            .map(|(i, s)| self.street_road(i, s))
            .collect();
        let mut junctions = Vec::new();
        for j in 0..self.junctions.len() {
            junctions.push(self.junction_roads(JunctionId(j), &mut ids, &mut roads));
        }
        let mut controllers = Vec::new();
        for (j, junction) in junctions.iter_mut().enumerate() {
            let signals = self.place_signals(JunctionId(j), junction, &mut ids, &mut roads);
            if !signals.is_empty() {
                let id = ids.take();
                junction.controller = Some(id);
                controllers.push(Controller {
                    id,
                    name: format!("Controller {}", junction.name),
                    signals,
                });
            }
        }
        Town {
            name: self.name,
            roads,
            junctions,
            controllers,
        }
    }

    fn street_id(&self, i: usize) -> u32 {
        i as u32 + 1
    }

    fn junction_id(&self, j: JunctionId) -> u32 {
        (self.streets.len() + j.0) as u32 + 1
    }

    fn street_road(&self, i: usize, s: &StreetDef) -> Road {
        Road {
            id: self.street_id(i),
            name: s.name.clone(),
            junction: None,
            path: s.path.clone(),
            profile: s.profile.clone(),
            lane_offset: 0.0,
            elevation: s.elevation.clone(),
            predecessor: s.start.map(|j| Link::Junction(self.junction_id(j))),
            successor: s.end.map(|j| Link::Junction(self.junction_id(j))),
            lane_link: None,
            signals: Vec::new(),
        }
    }

    /// The height of `leg`'s road at its junction end.
    fn leg_height(&self, leg: &Leg) -> f64 {
        let street = &self.streets[leg.road];
        let s = match leg.contact {
            Contact::Start => 0.0,
            Contact::End => street.path.length(),
        };
        elevation::height_at(&street.elevation, s)
    }

    /// Build junction `j`'s connecting roads into `roads`.
    fn junction_roads(&self, j: JunctionId, ids: &mut Ids, roads: &mut Vec<Road>) -> Junction {
        let def = &self.junctions[j.0];
        let legs = self.legs(j);
        let mut connections = Vec::new();
        for (k, link) in self.links(j, &legs).into_iter().enumerate() {
            let (from, to) = (&legs[link.from], &legs[link.to]);
            let path = Path::connect(from.in_lane(link.from_lane), to.out_lane(link.to_lane));
            let id = ids.take();
            let from_od = from.in_side().od_id(link.from_lane);
            let to_od = to.out_side().od_id(link.to_lane);
            let speed = from.profile.speed_kmh.min(to.profile.speed_kmh);
            let elevation =
                elevation::ramp(path.length(), self.leg_height(from), self.leg_height(to));
            roads.push(Road {
                id,
                name: format!("{} connector {k}", def.name),
                junction: Some(self.junction_id(j)),
                path,
                profile: Profile::connector(speed),
                lane_offset: LANE_WIDTH / 2.0,
                elevation,
                predecessor: Some(Link::Road {
                    id: self.street_id(from.road),
                    contact: from.contact,
                }),
                successor: Some(Link::Road {
                    id: self.street_id(to.road),
                    contact: to.contact,
                }),
                lane_link: Some((from_od, to_od)),
                signals: Vec::new(),
            });
            connections.push(Connection {
                id: k as u32,
                incoming: self.street_id(from.road),
                connecting: id,
                from: from_od,
                to: -1,
            });
        }
        Junction {
            id: self.junction_id(j),
            name: def.name.clone(),
            connections,
            controller: None,
        }
    }

    /// Place junction `j`'s signals (see [`super::signals`] for where), given
    /// its built connecting roads; the traffic lights' ids.
    fn place_signals(
        &self,
        j: JunctionId,
        junction: &Junction,
        ids: &mut Ids,
        roads: &mut [Road],
    ) -> Vec<u32> {
        let legs = self.legs(j);
        let (kind, approaches): (SignalKind, Vec<usize>) = match &self.junctions[j.0].control {
            Control::Free => return Vec::new(),
            Control::Lights if self.lights_left_to_simulator => return Vec::new(),
            Control::Lights => (
                SignalKind::TrafficLight,
                (0..legs.len()).filter(|&a| legs[a].n_in() > 0).collect(),
            ),
            Control::Stops(from) => (
                SignalKind::StopSign,
                (0..legs.len())
                    .filter(|&a| from.contains(&RoadId(legs[a].road)))
                    .collect(),
            ),
        };
        let links = self.links(j, &legs);
        let mut lights = Vec::new();
        for a in approaches {
            let leg = &legs[a];
            let id = ids.take();
            let across =
                kind == SignalKind::TrafficLight && self.light_placement == LightPlacement::Across;
            let straight_on = straight_on_from_rightmost(&links, &legs, a).filter(|_| across);
            match straight_on {
                Some((k, link)) => {
                    let connecting = junction.connections[k].connecting;
                    let road = roads
                        .iter_mut()
                        .find(|r| r.id == connecting)
                        .expect("every link has its connecting road");
                    let length = road.path.length();
                    road.signals
                        .push(far_side_light(id, length, &legs[link.to], link.to_lane));
                }
                None => {
                    let length = self.streets[leg.road].path.length();
                    let light = kind == SignalKind::TrafficLight;
                    roads[leg.road].signals.push(match self.light_placement {
                        LightPlacement::Kerb if light => kerb_light(id, leg, length, None),
                        LightPlacement::KerbSetBack if light => {
                            kerb_light(id, leg, length, Some(kerb_set_back(id)))
                        }
                        _ => approach_signal(id, kind, leg, length),
                    });
                }
            }
            if kind == SignalKind::TrafficLight {
                lights.push(id);
            }
        }
        lights
    }
}

/// The id sequence.
struct Ids {
    next: u32,
}

impl Ids {
    fn take(&mut self) -> u32 {
        self.next += 1;
        self.next - 1
    }
}
