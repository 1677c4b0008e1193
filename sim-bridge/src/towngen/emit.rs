//! Writes a [`Town`] as an OpenDRIVE 1.4 document in the style CARLA
//! exports: header with bounds and geo reference, roads, controllers,
//! junctions.

use super::elevation::Cubic;
use super::geometry::Shape;
use super::profile::{Mark, Side};
use super::town::{Controller, Junction, Link, Road, Signal, SignalKind, Town};
use super::xml::{Xml, ang, attr, coef, curve, len};
use ssrdrive_proto::frames::wrap_angle;

/// The PROJ string of the towns' local transverse Mercator frame.
const GEO_REFERENCE: &str =
    "+proj=tmerc +lat_0=0 +lon_0=0 +k=1 +x_0=0 +y_0=0 +datum=WGS84 +units=m +no_defs";

/// The document for `town`.
pub fn write_town(town: &Town) -> String {
    let mut xml = Xml::new();
    xml.open("OpenDRIVE", &[]);
    header(&mut xml, town);
    for road in &town.roads {
        write_road(&mut xml, road);
    }
    for controller in &town.controllers {
        write_controller(&mut xml, controller);
    }
    for junction in &town.junctions {
        write_junction(&mut xml, junction);
    }
    xml.close("OpenDRIVE");
    xml.finish()
}

/// North, south, east and west bounds of every road's surface.
fn bounds(town: &Town) -> [f64; 4] {
    let (mut n, mut s, mut e, mut w) = (f64::MIN, f64::MAX, f64::MIN, f64::MAX);
    for road in &town.roads {
        let reach = road.profile.half_width() + road.lane_offset.abs();
        let length = road.path.length();
        let steps = (length / 2.0).ceil().max(1.0) as usize;
        for i in 0..=steps {
            let p = road.path.pose_at(length * i as f64 / steps as f64).pos;
            (n, s) = (n.max(p.y + reach), s.min(p.y - reach));
            (e, w) = (e.max(p.x + reach), w.min(p.x - reach));
        }
    }
    [n, s, e, w]
}

fn header(xml: &mut Xml, town: &Town) {
    let [n, s, e, w] = bounds(town);
    xml.open(
        "header",
        &[
            attr("revMajor", 1),
            attr("revMinor", 4),
            attr("name", &town.name),
            attr("version", "1"),
            ("north", len(n)),
            ("south", len(s)),
            ("east", len(e)),
            ("west", len(w)),
            attr("vendor", "sim-bridge towngen"),
        ],
    );
    xml.cdata("geoReference", GEO_REFERENCE);
    xml.close("header");
}

fn write_road(xml: &mut Xml, road: &Road) {
    let junction = road.junction.map_or(-1, i64::from);
    xml.open(
        "road",
        &[
            attr("name", &road.name),
            ("length", len(road.path.length())),
            attr("id", road.id),
            attr("junction", junction),
        ],
    );
    road_links(xml, road);
    xml.open(
        "type",
        &[("s", len(0.0)), attr("type", road.profile.road_type)],
    );
    xml.leaf(
        "speed",
        &[attr("max", road.profile.speed_kmh), attr("unit", "km/h")],
    );
    xml.close("type");
    plan_view(xml, road);
    elevation(xml, &road.elevation);
    xml.leaf("lateralProfile", &[]);
    lanes(xml, road);
    xml.leaf("objects", &[]);
    signals(xml, &road.signals);
    xml.close("road");
}

fn road_links(xml: &mut Xml, road: &Road) {
    xml.open("link", &[]);
    for (tag, link) in [
        ("predecessor", road.predecessor),
        ("successor", road.successor),
    ] {
        match link {
            Some(Link::Junction(id)) => xml.leaf(
                tag,
                &[attr("elementType", "junction"), attr("elementId", id)],
            ),
            Some(Link::Road { id, contact }) => xml.leaf(
                tag,
                &[
                    attr("elementType", "road"),
                    attr("elementId", id),
                    attr("contactPoint", contact.od()),
                ],
            ),
            None => {}
        }
    }
    xml.close("link");
}

fn plan_view(xml: &mut Xml, road: &Road) {
    xml.open("planView", &[]);
    for (s, pose, segment) in road.path.records() {
        xml.open(
            "geometry",
            &[
                ("s", len(s)),
                ("x", len(pose.pos.x)),
                ("y", len(pose.pos.y)),
                ("hdg", ang(wrap_angle(pose.hdg))),
                ("length", len(segment.length)),
            ],
        );
        match segment.shape {
            Shape::Line => xml.leaf("line", &[]),
            Shape::Arc { curvature } => xml.leaf("arc", &[("curvature", ang(curvature))]),
            Shape::Poly3 { u, v } => {
                const NAMES: [[&str; 4]; 2] = [["aU", "bU", "cU", "dU"], ["aV", "bV", "cV", "dV"]];
                let mut attrs: Vec<(&str, String)> = NAMES
                    .iter()
                    .zip([u, v])
                    .flat_map(|(names, c)| names.iter().zip(c).map(|(n, x)| (*n, curve(x))))
                    .collect();
                attrs.push(attr("pRange", "normalized"));
                xml.leaf("paramPoly3", &attrs);
            }
        }
        xml.close("geometry");
    }
    xml.close("planView");
}

fn cubic_attrs(s_name: &'static str, c: &Cubic) -> Vec<(&'static str, String)> {
    vec![
        (s_name, len(c.s)),
        ("a", coef(c.a)),
        ("b", coef(c.b)),
        ("c", coef(c.c)),
        ("d", coef(c.d)),
    ]
}

fn elevation(xml: &mut Xml, profile: &[Cubic]) {
    xml.open("elevationProfile", &[]);
    for c in profile {
        xml.leaf("elevation", &cubic_attrs("s", c));
    }
    xml.close("elevationProfile");
}

fn lanes(xml: &mut Xml, road: &Road) {
    xml.open("lanes", &[]);
    let offset = Cubic {
        s: 0.0,
        a: road.lane_offset,
        b: 0.0,
        c: 0.0,
        d: 0.0,
    };
    xml.leaf("laneOffset", &cubic_attrs("s", &offset));
    xml.open("laneSection", &[("s", len(0.0))]);
    let profile = &road.profile;
    if !profile.left.is_empty() {
        xml.open("left", &[]);
        for j in (1..=profile.left.len()).rev() {
            lane(xml, road, Side::Left, j);
        }
        xml.close("left");
    }
    xml.open("center", &[]);
    xml.open(
        "lane",
        &[attr("id", 0), attr("type", "none"), attr("level", "false")],
    );
    xml.leaf("link", &[]);
    road_mark(xml, profile.center_mark());
    xml.close("lane");
    xml.close("center");
    if !profile.right.is_empty() {
        xml.open("right", &[]);
        for j in 1..=profile.right.len() {
            lane(xml, road, Side::Right, j);
        }
        xml.close("right");
    }
    xml.close("laneSection");
    xml.close("lanes");
}

fn lane(xml: &mut Xml, road: &Road, side: Side, j: usize) {
    let spec = road.profile.lanes(side)[j - 1];
    let id = side.od_id(j);
    xml.open(
        "lane",
        &[
            attr("id", id),
            attr("type", spec.kind.od_type()),
            attr("level", "false"),
        ],
    );
    match road.lane_link {
        Some((from, to)) if id == -1 => {
            xml.open("link", &[]);
            xml.leaf("predecessor", &[attr("id", from)]);
            xml.leaf("successor", &[attr("id", to)]);
            xml.close("link");
        }
        _ => xml.leaf("link", &[]),
    }
    let width = Cubic {
        s: 0.0,
        a: spec.width,
        b: 0.0,
        c: 0.0,
        d: 0.0,
    };
    xml.leaf("width", &cubic_attrs("sOffset", &width));
    road_mark(xml, road.profile.outer_mark(side, j));
    xml.close("lane");
}

fn road_mark(xml: &mut Xml, mark: Mark) {
    let width = if mark.kind == "none" { 0.0 } else { 0.125 };
    xml.leaf(
        "roadMark",
        &[
            ("sOffset", len(0.0)),
            attr("type", mark.kind),
            attr("weight", "standard"),
            attr("color", mark.color),
            attr("material", "standard"),
            ("width", len(width)),
            attr("laneChange", mark.lane_change),
        ],
    );
}

fn signals(xml: &mut Xml, signals: &[Signal]) {
    if signals.is_empty() {
        xml.leaf("signals", &[]);
        return;
    }
    xml.open("signals", &[]);
    for signal in signals {
        write_signal(xml, signal);
    }
    xml.close("signals");
}

fn write_signal(xml: &mut Xml, signal: &Signal) {
    let orientation = match signal.side {
        Side::Right => "+",
        Side::Left => "-",
    };
    let (name, dynamic, kind, z, height, width) = match signal.kind {
        SignalKind::TrafficLight => ("TrafficLight", "yes", "1000001", 3.0, 1.0, 0.5),
        SignalKind::StopSign => ("StopSign", "no", "206", 1.5, 0.8, 0.8),
    };
    xml.open(
        "signal",
        &[
            ("s", len(signal.s)),
            ("t", len(signal.t)),
            attr("id", signal.id),
            attr("name", name),
            attr("dynamic", dynamic),
            attr("orientation", orientation),
            ("zOffset", len(z)),
            attr("country", "OpenDRIVE"),
            attr("type", kind),
            attr("subtype", "-1"),
            ("height", len(height)),
            ("width", len(width)),
            ("hOffset", len(0.0)),
            ("pitch", len(0.0)),
            ("roll", len(0.0)),
        ],
    );
    xml.leaf(
        "validity",
        &[
            attr("fromLane", signal.lanes.0),
            attr("toLane", signal.lanes.1),
        ],
    );
    xml.close("signal");
}

fn write_controller(xml: &mut Xml, controller: &Controller) {
    xml.open(
        "controller",
        &[
            attr("name", &controller.name),
            attr("id", controller.id),
            attr("sequence", 0),
        ],
    );
    for signal in &controller.signals {
        xml.leaf("control", &[attr("signalId", signal), attr("type", "0")]);
    }
    xml.close("controller");
}

fn write_junction(xml: &mut Xml, junction: &Junction) {
    xml.open(
        "junction",
        &[attr("id", junction.id), attr("name", &junction.name)],
    );
    for c in &junction.connections {
        xml.open(
            "connection",
            &[
                attr("id", c.id),
                attr("incomingRoad", c.incoming),
                attr("connectingRoad", c.connecting),
                attr("contactPoint", "start"),
            ],
        );
        xml.leaf("laneLink", &[attr("from", c.from), attr("to", c.to)]);
        xml.close("connection");
    }
    if let Some(id) = junction.controller {
        xml.leaf(
            "controller",
            &[attr("id", id), attr("type", "0"), attr("sequence", 0)],
        );
    }
    xml.close("junction");
}
