//! CARLA leaderboard route files: `<routes><route id town><waypoint x y z pitch roll yaw/>...`.
//!
//! CARLA's frame is left-handed, so a file's (x, y, yaw in degrees) is OpenDRIVE's (x, -y, -yaw)
//! and the reader and writer flip it; everything inside the simulator is in the OpenDRIVE frame.
//! Waypoints are read wherever they sit under a `<route>` (TCP's files nest them in
//! `<weather>`). Untrusted input is capped: [`MAX_ROUTE_FILE_BYTES`], [`MAX_ROUTES`],
//! [`MAX_KEYPOINTS`].

use std::fmt::Write as _;
use std::path::Path;

use glam::DVec3;
use ssrdrive_support::files::{CappedReadError, read_capped_text};

/// Largest route file accepted.
pub const MAX_ROUTE_FILE_BYTES: u64 = 32 * 1024 * 1024;
/// Most routes in one file.
pub const MAX_ROUTES: usize = 20_000;
/// Most keypoints in one route.
pub const MAX_KEYPOINTS: usize = 20_000;

/// A route keypoint in the OpenDRIVE frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keypoint {
    /// Position, metres.
    pub position: DVec3,
    /// Heading, radians counter-clockwise from +x.
    pub yaw: f64,
}

/// One `<route>`.
#[derive(Debug, Clone, PartialEq)]
pub struct RouteSpec {
    /// The route's `id`.
    pub id: String,
    /// The route's `town`.
    pub town: String,
    /// Keypoints in driving order (at least two).
    pub keypoints: Vec<Keypoint>,
}

impl RouteSpec {
    /// 3-D polyline length over the keypoints (the leaderboard's `route_length`).
    pub fn keypoint_length(&self) -> f64 {
        self.keypoints
            .windows(2)
            .map(|w| (w[1].position - w[0].position).length())
            .sum()
    }
}

/// Why a route file could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RouteFileError {
    /// The file could not be read, or is larger than [`MAX_ROUTE_FILE_BYTES`].
    #[error("cannot read route file {path}: {source}")]
    Io {
        /// The route file, as given.
        path: String,
        /// Why the read failed.
        source: CappedReadError,
    },
    /// Over a cap on untrusted input.
    #[error("route file {origin}: {what}")]
    TooLarge {
        /// The file's name (its path, or the name given with the text).
        origin: String,
        /// Which cap it passed.
        what: String,
    },
    /// Not well-formed XML.
    #[error("route file {origin} is not well-formed XML: {message}")]
    Xml {
        /// The file's name (its path, or the name given with the text).
        origin: String,
        /// The XML parser's message.
        message: String,
    },
    /// Well-formed, but not a route file as the leaderboard writes them.
    #[error("route file {origin}: {message}")]
    Invalid {
        /// The file's name (its path, or the name given with the text).
        origin: String,
        /// What is wrong.
        message: String,
    },
}

/// Read a route file.
pub fn read_file(path: &Path) -> Result<Vec<RouteSpec>, RouteFileError> {
    let shown = path.display().to_string();
    let text =
        read_capped_text(path, MAX_ROUTE_FILE_BYTES).map_err(|source| RouteFileError::Io {
            path: shown.clone(),
            source,
        })?;
    parse(&shown, &text)
}

/// The elements a `<route>` may hold: keypoints, and what the leaderboard's route files carry
/// beside them (weather; the 2.0 format's scenarios), which this reader does not use.
const ROUTE_CHILDREN: [&str; 4] = ["waypoint", "weather", "weathers", "scenarios"];

/// Parse a route file held in memory; `origin` names it in errors.
pub fn parse(origin: &str, text: &str) -> Result<Vec<RouteSpec>, RouteFileError> {
    let invalid = |message: String| RouteFileError::Invalid {
        origin: origin.into(),
        message,
    };
    let doc = roxmltree::Document::parse(text).map_err(|e| RouteFileError::Xml {
        origin: origin.into(),
        message: e.to_string(),
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "routes" {
        return Err(invalid(format!(
            "root element is <{}>, expected <routes>",
            root.tag_name().name()
        )));
    }
    let mut routes = Vec::new();
    for node in root.children().filter(|n| n.has_tag_name("route")) {
        if routes.len() == MAX_ROUTES {
            let what = format!("more than {MAX_ROUTES} routes");
            return Err(RouteFileError::TooLarge {
                origin: origin.into(),
                what,
            });
        }
        let id = node.attribute("id").ok_or_else(|| {
            invalid(format!(
                "a <route> at byte {} has no id",
                node.range().start
            ))
        })?;
        let town = node.attribute("town").unwrap_or("").to_string();
        // A misspelt <waypoint> would silently drop its keypoint: name it instead.
        if let Some(other) = node
            .children()
            .filter(|n| n.is_element())
            .find(|n| !ROUTE_CHILDREN.contains(&n.tag_name().name()))
        {
            let line = doc.text_pos_at(other.range().start).row;
            return Err(invalid(format!(
                "route {id}: unknown element <{}> on line {line}; a route holds <waypoint> \
                 elements (and optionally {})",
                other.tag_name().name(),
                ROUTE_CHILDREN[1..]
                    .iter()
                    .map(|t| format!("<{t}>"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        let mut keypoints = Vec::new();
        for wp in node.descendants().filter(|n| n.has_tag_name("waypoint")) {
            if keypoints.len() == MAX_KEYPOINTS {
                let what = format!("route {id} has more than {MAX_KEYPOINTS} waypoints");
                return Err(RouteFileError::TooLarge {
                    origin: origin.into(),
                    what,
                });
            }
            let num = |name: &str, required: bool| -> Result<f64, RouteFileError> {
                match wp.attribute(name) {
                    None if required => {
                        Err(invalid(format!("route {id}: a <waypoint> has no '{name}'")))
                    }
                    None => Ok(0.0),
                    Some(v) => v
                        .trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|v| v.is_finite())
                        .ok_or_else(|| {
                            invalid(format!(
                                "route {id}: waypoint {name}='{v}' is not a finite number"
                            ))
                        }),
                }
            };
            let (x, y, z) = (num("x", true)?, num("y", true)?, num("z", false)?);
            let yaw = num("yaw", false)?;
            keypoints.push(Keypoint {
                position: DVec3::new(x, -y, z),
                yaw: -yaw.to_radians(),
            });
        }
        if keypoints.len() < 2 {
            return Err(invalid(format!(
                "route {id} has {} waypoints; a route needs at least 2",
                keypoints.len()
            )));
        }
        routes.push(RouteSpec {
            id: id.to_string(),
            town,
            keypoints,
        });
    }
    if routes.is_empty() {
        return Err(invalid("no <route> element".into()));
    }
    Ok(routes)
}

/// Write routes in the leaderboard's format (CARLA frame).
pub fn write(routes: &[RouteSpec]) -> String {
    let mut out = String::from("<?xml version='1.0' encoding='UTF-8'?>\n<routes>\n");
    for r in routes {
        let _ = writeln!(
            out,
            "  <route id=\"{}\" town=\"{}\">",
            escape(&r.id),
            escape(&r.town)
        );
        for k in &r.keypoints {
            let p = k.position;
            let yaw = clean(-k.yaw.to_degrees());
            let _ = writeln!(
                out,
                "    <waypoint x=\"{:.6}\" y=\"{:.6}\" z=\"{:.6}\" pitch=\"0.0\" roll=\"0.0\" yaw=\"{yaw:.6}\"/>",
                clean(p.x),
                clean(-p.y),
                clean(p.z)
            );
        }
        out.push_str("  </route>\n");
    }
    out.push_str("</routes>\n");
    out
}

/// Avoid writing "-0.000000".
fn clean(v: f64) -> f64 {
    if v.abs() < 5e-7 { 0.0 } else { v }
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
