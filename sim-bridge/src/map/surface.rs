//! The road surface as the renderer draws it: every lane of the OpenDRIVE file tessellated by
//! the `xodr` crate into triangles tagged with a [`Material`], and every painted road-mark line
//! as quads with its colour (dashes are already cut by `xodr`).
//!
//! Guarantees: every vertex is finite; triangles keep the file's winding (facing up); paint
//! lies in the surface of its lane (draw it with a small lift to win the depth test).

use glam::Vec3;
use xodr::LaneType;

use super::LaneKind;

/// What a surface triangle is made of, for colouring.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Material {
    /// Traffic lanes (driving, ramps, entries, exits, bidirectional).
    Driving,
    /// Parking lanes.
    Parking,
    /// Sidewalks and curbs.
    Sidewalk,
    /// Shoulders, borders, stop and biking lanes.
    Shoulder,
    /// Medians, `none` lanes and everything else: verge grass.
    Grass,
}

impl Material {
    /// The material of a lane type: the lane graph's [`LaneKind`], with bus, taxi and HOV
    /// lanes drawn as driving, curbs as sidewalk, medians as grass, and the other paved kinds
    /// (`none`, biking, shared, road works) as shoulder.
    fn of(kind: LaneType) -> Self {
        match (LaneKind::from_xodr(kind), kind) {
            (LaneKind::Driving, _) => Material::Driving,
            (LaneKind::Parking, _) => Material::Parking,
            (_, LaneType::Bus | LaneType::Taxi | LaneType::Hov) => Material::Driving,
            (LaneKind::Sidewalk, _) | (_, LaneType::Curb) => Material::Sidewalk,
            (_, LaneType::Median) => Material::Grass,
            (LaneKind::Shoulder, _)
            | (_, LaneType::Biking | LaneType::Shared | LaneType::RoadWorks) => Material::Shoulder,
            (LaneKind::Other, _) => Material::Grass,
        }
    }
}

/// Paint colour of a road-mark line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Paint {
    /// White paint (and any colour other than yellow).
    White,
    /// Yellow paint.
    Yellow,
}

/// One surface triangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceTriangle {
    /// Corners, world frame, counter-clockwise seen from above.
    pub corners: [Vec3; 3],
    /// What the triangle is made of.
    pub material: Material,
}

/// One painted piece of a road-mark line (a dash, or part of a solid line).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaintQuad {
    /// Corners, world frame, counter-clockwise seen from above.
    pub corners: [Vec3; 4],
    /// Colour of the paint.
    pub paint: Paint,
}

/// The drawable road surface of a map.
#[derive(Debug, Clone, Default)]
pub struct Surface {
    /// Triangles of every permanent lane.
    pub triangles: Vec<SurfaceTriangle>,
    /// Painted pieces of every road-mark line.
    pub paint: Vec<PaintQuad>,
}

impl Surface {
    /// Tessellate a network's permanent lanes and road marks.
    pub fn from_network(net: &xodr::RoadNetwork) -> Self {
        let mesh = net.surface_mesh();
        let vertex = |i: u32| {
            let p = mesh.vertices[i as usize];
            Vec3::new(p.x, p.y, p.z)
        };
        let mut triangles = Vec::with_capacity(mesh.indices.len() / 3);
        for span in &mesh.lanes {
            let material = net
                .lane(span.lane)
                .map_or(Material::Grass, |lane| Material::of(lane.kind));
            let indices = &mesh.indices[span.indices.start as usize..span.indices.end as usize];
            for t in indices.chunks_exact(3) {
                let corners = [vertex(t[0]), vertex(t[1]), vertex(t[2])];
                if corners.iter().all(|c| c.is_finite()) {
                    triangles.push(SurfaceTriangle { corners, material });
                }
            }
        }
        let mut paint = Vec::new();
        for mark in net.road_marks() {
            for line in &mark.lines {
                let colour = if line.color.eq_ignore_ascii_case("yellow") {
                    Paint::Yellow
                } else {
                    Paint::White
                };
                for piece in &line.pieces {
                    let corners = piece.map(|p| Vec3::new(p.x, p.y, p.z));
                    if corners.iter().all(|c| c.is_finite()) {
                        paint.push(PaintQuad {
                            corners,
                            paint: colour,
                        });
                    }
                }
            }
        }
        Surface { triangles, paint }
    }
}
