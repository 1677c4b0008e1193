//! The static part of a camera scene, baked once per map and appearance: the road surface by
//! material, road paint and stop lines, traffic-light poles and housings, stop signs. Triangles
//! are cut to at most [`MAX_EDGE`] metres and filed in a plan grid by centroid, so a camera
//! draws only the cells within its range and field of view.

use glam::{Vec2, Vec3};

use super::shapes::{Tri, UprightBox, push_quad, push_vertical_disc};
use super::style::Appearance;
use crate::map::Map;
use crate::map::traffic_control::StopLine;

/// Longest triangle edge kept after baking, metres.
pub const MAX_EDGE: f32 = 6.0;
/// Side of a grid cell, metres.
const CELL: f32 = 16.0;
/// Height of paint above its lane, metres (wins the depth test without visible float).
const PAINT_LIFT: f32 = 0.02;
/// Stop lines sit a little higher than lane paint they may cross.
const STOP_LINE_LIFT: f32 = 0.03;

/// A traffic-light head: where its three lamps are and which way they face.
#[derive(Debug, Clone, Copy)]
pub struct LightHead {
    /// Index into `Map::lights` (and the world's light states).
    pub light: usize,
    /// Lamp centres, top (red) to bottom (green).
    pub lamps: [Vec3; 3],
    /// Horizontal unit vector the lamps face.
    pub facing: Vec2,
}

/// Radius of a lamp, metres.
pub const LAMP_RADIUS: f32 = 0.13;

/// Static geometry of one map, filed in a plan grid.
#[derive(Debug, Clone)]
pub struct StaticScene {
    lo: Vec2,
    cols: usize,
    rows: usize,
    /// `tris[starts[c]..starts[c + 1]]` are the triangles of cell `c`.
    starts: Vec<u32>,
    tris: Vec<Tri>,
    /// Traffic-light heads, whose lamps change colour every frame.
    pub heads: Vec<LightHead>,
}

impl StaticScene {
    /// Bake `map` in the colours of `app`.
    pub fn bake(map: &Map, app: &Appearance) -> Self {
        let mut tris = Vec::new();
        for t in &map.surface.triangles {
            let colour = app.shade(app.material(t.material), face_normal(t.corners));
            tris.push(Tri {
                corners: t.corners,
                colour,
            });
        }
        for q in &map.surface.paint {
            let colour = app.shade(app.paint(q.paint), Vec3::Z);
            push_quad(
                &mut tris,
                q.corners.map(|c| c + Vec3::Z * PAINT_LIFT),
                colour,
            );
        }
        let white = app.shade(app.white_paint, Vec3::Z);
        let stop_lines = map.lights.iter().flat_map(|l| &l.stop_lines);
        for line in stop_lines.chain(map.stop_signs.iter().flat_map(|s| &s.stop_lines)) {
            push_quad(&mut tris, stop_line_quad(line), white);
        }
        let mut heads = Vec::new();
        for light in &map.lights {
            let ground = light
                .stop_lines
                .first()
                .map_or(light.head.z - 3.0, |s| s.position.z);
            heads.push(push_light(
                &mut tris,
                app,
                light.id,
                light.head,
                light.head_yaw,
                ground,
            ));
        }
        for sign in &map.stop_signs {
            push_stop_sign(&mut tris, app, sign.position, sign.yaw);
        }
        let tris = subdivide(tris);
        Self::file(tris, heads)
    }

    fn file(tris: Vec<Tri>, heads: Vec<LightHead>) -> Self {
        let centroid = |t: &Tri| ((t.corners[0] + t.corners[1] + t.corners[2]) / 3.0).truncate();
        let (mut lo, mut hi) = (Vec2::splat(f32::MAX), Vec2::splat(f32::MIN));
        for t in &tris {
            lo = lo.min(centroid(t));
            hi = hi.max(centroid(t));
        }
        if tris.is_empty() {
            (lo, hi) = (Vec2::ZERO, Vec2::ZERO);
        }
        let cols = ((hi.x - lo.x) / CELL) as usize + 1;
        let rows = ((hi.y - lo.y) / CELL) as usize + 1;
        let cell_of = |t: &Tri| {
            let c = (centroid(t) - lo) / CELL;
            (c.y as usize).min(rows - 1) * cols + (c.x as usize).min(cols - 1)
        };
        let mut counts = vec![0u32; cols * rows + 1];
        for t in &tris {
            counts[cell_of(t) + 1] += 1;
        }
        for c in 1..counts.len() {
            counts[c] += counts[c - 1];
        }
        let starts = counts.clone();
        let mut next = counts;
        let mut sorted = vec![tris.first().copied().unwrap_or(EMPTY); tris.len()];
        for t in &tris {
            let c = cell_of(t);
            sorted[next[c] as usize] = *t;
            next[c] += 1;
        }
        Self {
            lo,
            cols,
            rows,
            starts,
            tris: sorted,
            heads,
        }
    }

    /// Number of baked triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// Whether nothing was baked.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The triangles of every cell that may hold something within `range` of `eye` and inside
    /// the plan wedge of half angle `half_angle` around `forward` (no wedge with `None`).
    pub fn visible(
        &self,
        eye: Vec2,
        forward: Vec2,
        half_angle: Option<f32>,
        range: f32,
        mut draw: impl FnMut(&[Tri]),
    ) {
        let slack = CELL * std::f32::consts::FRAC_1_SQRT_2 + MAX_EDGE;
        let reach = range + MAX_EDGE;
        let cell_range = |centre: f32, lo: f32, n: usize| {
            let a = ((centre - reach - lo) / CELL).floor().max(0.0) as usize;
            let b = (((centre + reach - lo) / CELL).floor() as isize).min(n as isize - 1);
            a..(b + 1).max(0) as usize
        };
        for row in cell_range(eye.y, self.lo.y, self.rows) {
            for col in cell_range(eye.x, self.lo.x, self.cols) {
                let centre = self.lo + (Vec2::new(col as f32, row as f32) + 0.5) * CELL;
                let d = centre - eye;
                let dist = d.length();
                if dist > range + slack {
                    continue;
                }
                if let Some(half) = half_angle
                    && dist > slack
                {
                    let off_axis = forward.angle_to(d).abs();
                    if off_axis > half + (slack / dist).asin() {
                        continue;
                    }
                }
                let c = row * self.cols + col;
                let span = self.starts[c] as usize..self.starts[c + 1] as usize;
                if !span.is_empty() {
                    draw(&self.tris[span]);
                }
            }
        }
    }
}

const EMPTY: Tri = Tri {
    corners: [Vec3::ZERO; 3],
    colour: 0,
};

/// Unit normal of a triangle (up for counter-clockwise corners seen from above).
fn face_normal(c: [Vec3; 3]) -> Vec3 {
    (c[1] - c[0]).cross(c[2] - c[0]).normalize_or(Vec3::Z)
}

/// Split every triangle until no edge is longer than [`MAX_EDGE`].
fn subdivide(tris: Vec<Tri>) -> Vec<Tri> {
    let mut out = Vec::with_capacity(tris.len());
    let mut stack = tris;
    while let Some(t) = stack.pop() {
        let c = t.corners;
        let lengths = [0, 1, 2].map(|k| c[k].distance_squared(c[(k + 1) % 3]));
        let (k, longest) = lengths
            .iter()
            .copied()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((0, 0.0));
        if longest <= MAX_EDGE * MAX_EDGE || !longest.is_finite() {
            out.push(t);
            continue;
        }
        let (a, b, o) = (c[k], c[(k + 1) % 3], c[(k + 2) % 3]);
        let m = (a + b) / 2.0;
        stack.push(Tri {
            corners: [a, m, o],
            colour: t.colour,
        });
        stack.push(Tri {
            corners: [m, b, o],
            colour: t.colour,
        });
    }
    out
}

/// A 0.3 m band across the lane just before its stop line.
fn stop_line_quad(line: &StopLine) -> [Vec3; 4] {
    let along = Vec2::from_angle(line.yaw as f32);
    let (a, b) = line.ends(1.0);
    let lift = line.position.z as f32 + STOP_LINE_LIFT;
    let a = a.as_vec2();
    let b = b.as_vec2();
    let back = along * 0.3;
    [a - back, b - back, b, a].map(|p| p.extend(lift))
}

/// A pole, a housing and the lamp places of one traffic light.
fn push_light(
    tris: &mut Vec<Tri>,
    app: &Appearance,
    light: usize,
    head: glam::DVec3,
    yaw: f64,
    ground: f64,
) -> LightHead {
    let head = head.as_vec3();
    let facing = Vec2::from_angle(yaw as f32);
    let dark = Vec3::splat(0.12);
    let pole = UprightBox {
        centre: head.truncate() - facing * 0.25,
        yaw: yaw as f32,
        half: Vec2::splat(0.07),
        bottom: ground as f32,
        top: head.z + 0.3,
    };
    pole.push(tris, Vec3::splat(0.35), app, None);
    let housing = UprightBox {
        centre: head.truncate(),
        yaw: yaw as f32,
        half: Vec2::new(0.15, 0.2),
        bottom: head.z - 0.55,
        top: head.z + 0.55,
    };
    housing.push(tris, dark, app, None);
    let face = head + (facing * 0.16).extend(0.0);
    LightHead {
        light,
        lamps: [0.35, 0.0, -0.35].map(|dz| face + Vec3::Z * dz),
        facing,
    }
}

/// A pole with a red octagon on top, facing `yaw`.
fn push_stop_sign(tris: &mut Vec<Tri>, app: &Appearance, base: glam::DVec3, yaw: f64) {
    let base = base.as_vec3();
    let facing = Vec2::from_angle(yaw as f32);
    let pole = UprightBox {
        centre: base.truncate(),
        yaw: yaw as f32,
        half: Vec2::splat(0.04),
        bottom: base.z,
        top: base.z + 2.0,
    };
    pole.push(tris, Vec3::splat(0.5), app, None);
    let red = app.shade(Vec3::new(0.75, 0.05, 0.05), facing.extend(0.0));
    let centre = base + Vec3::Z * 2.3 + (facing * 0.05).extend(0.0);
    push_vertical_disc(tris, centre, facing, 0.38, 8, red);
    let white = app.shade(Vec3::splat(0.95), facing.extend(0.0));
    push_vertical_disc(
        tris,
        centre - (facing * 0.01).extend(0.0),
        facing,
        0.42,
        8,
        white,
    );
}
