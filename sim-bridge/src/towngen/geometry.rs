//! Plan-view geometry: poses, the OpenDRIVE primitives a town uses (`line`,
//! `arc`, normalized `paramPoly3`), reference-line paths made of them, and
//! the connectors that join two poses exactly (a fillet of line, arc, line,
//! or a cubic Hermite curve).

use glam::DVec2;
use std::f64::consts::PI;

use ssrdrive_proto::frames::wrap_angle;

/// Below this, a length or an angle counts as zero.
const EPS: f64 = 1e-9;

/// A point in the plane and a heading, counter-clockwise from +x in radians.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Where.
    pub pos: DVec2,
    /// Which way.
    pub hdg: f64,
}

impl Pose {
    /// A pose at `(x, y)` heading `hdg`.
    pub fn new(x: f64, y: f64, hdg: f64) -> Self {
        Self {
            pos: DVec2::new(x, y),
            hdg,
        }
    }

    /// The unit vector along the heading.
    pub fn forward(&self) -> DVec2 {
        let (s, c) = self.hdg.sin_cos();
        DVec2::new(c, s)
    }

    /// The unit vector to the left of the heading (OpenDRIVE's `+t`).
    pub fn left(&self) -> DVec2 {
        let f = self.forward();
        DVec2::new(-f.y, f.x)
    }

    /// The point `along` ahead and `t` to the left.
    pub fn at(&self, along: f64, t: f64) -> DVec2 {
        self.pos + self.forward() * along + self.left() * t
    }
}

/// A rigid motion of the plane: rotate about the origin, then translate.
/// Lets a layout be written in its own axes and placed turned.
#[derive(Debug, Clone, Copy)]
pub struct Frame {
    angle: f64,
    cos: f64,
    sin: f64,
    shift: DVec2,
}

impl Frame {
    /// No motion.
    pub const IDENTITY: Frame = Frame {
        angle: 0.0,
        cos: 1.0,
        sin: 0.0,
        shift: DVec2::ZERO,
    };

    /// Turn by `degrees` about the origin, then shift by `(dx, dy)`.
    pub fn new(degrees: f64, dx: f64, dy: f64) -> Self {
        let angle = degrees.to_radians();
        let (sin, cos) = angle.sin_cos();
        Self {
            angle,
            cos,
            sin,
            shift: DVec2::new(dx, dy),
        }
    }

    /// A half turn about the origin, exact.
    pub const HALF_TURN: Frame = Frame {
        angle: PI,
        cos: -1.0,
        sin: 0.0,
        shift: DVec2::ZERO,
    };

    /// `p` moved.
    pub fn point(&self, p: DVec2) -> DVec2 {
        DVec2::new(
            self.cos * p.x - self.sin * p.y,
            self.sin * p.x + self.cos * p.y,
        ) + self.shift
    }

    /// `pose` moved.
    pub fn pose(&self, pose: Pose) -> Pose {
        Pose {
            pos: self.point(pose.pos),
            hdg: pose.hdg + self.angle,
        }
    }
}

/// The shape of one `<geometry>` record.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A straight line.
    Line,
    /// An arc of constant `curvature`, positive turning left.
    Arc {
        /// 1/radius, in 1/m.
        curvature: f64,
    },
    /// A `paramPoly3` with `pRange="normalized"`: `u(p)`, `v(p)` in the
    /// start pose's frame, `p` in `[0, 1]`, coefficients `[a, b, c, d]`.
    Poly3 {
        /// Along the start heading.
        u: [f64; 4],
        /// Left of the start heading.
        v: [f64; 4],
    },
}

/// One `<geometry>`: a shape and its length along the reference line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Its shape.
    pub shape: Shape,
    /// Its length in metres.
    pub length: f64,
}

fn cubic(c: &[f64; 4], p: f64) -> f64 {
    ((c[3] * p + c[2]) * p + c[1]) * p + c[0]
}

fn cubic_slope(c: &[f64; 4], p: f64) -> f64 {
    (3.0 * c[3] * p + 2.0 * c[2]) * p + c[1]
}

impl Segment {
    /// The pose `s` metres along this segment when it starts at `start`.
    pub fn pose_at(&self, start: Pose, s: f64) -> Pose {
        match self.shape {
            Shape::Line => Pose {
                pos: start.at(s, 0.0),
                hdg: start.hdg,
            },
            Shape::Arc { curvature: k } => {
                let hdg = start.hdg + k * s;
                let (s0, c0) = start.hdg.sin_cos();
                let (s1, c1) = hdg.sin_cos();
                let delta = if k.abs() < EPS {
                    start.forward() * s
                } else {
                    DVec2::new(s1 - s0, c0 - c1) / k
                };
                Pose {
                    pos: start.pos + delta,
                    hdg,
                }
            }
            Shape::Poly3 { u, v } => {
                let p = (s / self.length).clamp(0.0, 1.0);
                let (du, dv) = (cubic_slope(&u, p), cubic_slope(&v, p));
                Pose {
                    pos: start.at(cubic(&u, p), cubic(&v, p)),
                    hdg: start.hdg + dv.atan2(du),
                }
            }
        }
    }

    /// The pose where this segment ends when it starts at `start`.
    pub fn end(&self, start: Pose) -> Pose {
        self.pose_at(start, self.length)
    }
}

/// A reference line: a start pose and the segments that follow it.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    /// Where the line starts.
    pub start: Pose,
    /// Its `<geometry>` records, in order.
    pub segments: Vec<Segment>,
}

impl Path {
    /// An empty path at `start`.
    pub fn new(start: Pose) -> Self {
        Self {
            start,
            segments: Vec::new(),
        }
    }

    /// Append a segment; one of no length is dropped.
    pub fn push(&mut self, shape: Shape, length: f64) {
        if length > EPS {
            self.segments.push(Segment { shape, length });
        }
    }

    /// Append a straight line.
    pub fn line(mut self, length: f64) -> Self {
        self.push(Shape::Line, length);
        self
    }

    /// The polyline through `points` with each inner corner rounded by an
    /// arc of `radius`. Panics where a corner's arc doesn't fit.
    pub fn rounded(points: &[DVec2], radius: f64) -> Self {
        assert!(points.len() >= 2, "a path needs two points");
        let d0 = points[1] - points[0];
        let mut path = Self::new(Pose {
            pos: points[0],
            hdg: d0.y.atan2(d0.x),
        });
        let mut used = 0.0; // of the current leg, already taken by the last arc
        for w in points.windows(3) {
            let (a, b, c) = (w[0], w[1], w[2]);
            let (ab, bc) = (b - a, c - b);
            let turn = wrap_angle(bc.y.atan2(bc.x) - ab.y.atan2(ab.x));
            let tangent = radius * (turn.abs() / 2.0).tan();
            let straight = ab.length() - used - tangent;
            assert!(
                straight > -EPS,
                "corner at {b:?} too tight for radius {radius}"
            );
            path.push(Shape::Line, straight);
            path.push(
                Shape::Arc {
                    curvature: turn.signum() / radius,
                },
                radius * turn.abs(),
            );
            used = tangent;
        }
        let n = points.len();
        let last = (points[n - 1] - points[n - 2]).length() - used;
        assert!(last > -EPS, "last corner too close to the end");
        path.push(Shape::Line, last);
        path
    }

    /// This path with `from_start` metres cut off its start and `from_end`
    /// off its end. Both cuts must fall in straight lines.
    pub fn trimmed(mut self, from_start: f64, from_end: f64) -> Self {
        if from_start > 0.0 {
            let first = &mut self.segments[0];
            assert!(
                first.shape == Shape::Line && first.length > from_start + EPS,
                "start trim {from_start} leaves the first line"
            );
            first.length -= from_start;
            self.start = Pose {
                pos: self.start.at(from_start, 0.0),
                hdg: self.start.hdg,
            };
        }
        if from_end > 0.0 {
            let last = self.segments.last_mut().expect("a non-empty path");
            assert!(
                last.shape == Shape::Line && last.length > from_end + EPS,
                "end trim {from_end} leaves the last line"
            );
            last.length -= from_end;
        }
        self
    }

    /// This path moved by `frame`.
    pub fn transformed(mut self, frame: &Frame) -> Self {
        self.start = frame.pose(self.start);
        self
    }

    /// Its length.
    pub fn length(&self) -> f64 {
        self.segments.iter().map(|g| g.length).sum()
    }

    /// Each segment with its start `s` and start pose.
    pub fn records(&self) -> Vec<(f64, Pose, Segment)> {
        let mut out = Vec::with_capacity(self.segments.len());
        let (mut s, mut pose) = (0.0, self.start);
        for g in &self.segments {
            out.push((s, pose, *g));
            s += g.length;
            pose = g.end(pose);
        }
        out
    }

    /// Where it ends.
    pub fn end(&self) -> Pose {
        self.records()
            .last()
            .map_or(self.start, |(_, pose, g)| g.end(*pose))
    }

    /// The pose `s` metres along, clamped to the path.
    pub fn pose_at(&self, s: f64) -> Pose {
        let records = self.records();
        let (s0, pose, g) = records
            .iter()
            .rev()
            .find(|(s0, _, _)| *s0 <= s)
            .copied()
            .unwrap_or(records[0]);
        g.pose_at(pose, (s - s0).clamp(0.0, g.length))
    }

    /// The path joining pose `a` to pose `b` exactly: a line where they are
    /// collinear, else a fillet (line, arc, line) where their rays meet
    /// ahead of both, else a cubic Hermite `paramPoly3`.
    pub fn connect(a: Pose, b: Pose) -> Self {
        let delta = b.pos - a.pos;
        let turn = wrap_angle(b.hdg - a.hdg);
        let fa = a.forward();
        let across = fa.perp_dot(delta);
        if turn.abs() < 1e-7 && across.abs() < 1e-7 && fa.dot(delta) > 0.0 {
            return Self::new(a).line(delta.length());
        }
        Self::fillet(a, b, turn).unwrap_or_else(|| Self::hermite(a, b))
    }

    fn fillet(a: Pose, b: Pose, turn: f64) -> Option<Self> {
        if turn.abs() < 1e-3 || turn.abs() > PI - 1e-3 {
            return None;
        }
        let (fa, fb) = (a.forward(), b.forward());
        let delta = b.pos - a.pos;
        let denom = fa.perp_dot(fb);
        let d0 = delta.perp_dot(fb) / denom;
        let d1 = fa.perp_dot(delta) / denom;
        if d0 <= 0.0 || d1 <= 0.0 {
            return None;
        }
        let tangent = d0.min(d1);
        let radius = tangent / (turn.abs() / 2.0).tan();
        let mut path = Self::new(a);
        path.push(Shape::Line, d0 - tangent);
        path.push(
            Shape::Arc {
                curvature: turn.signum() / radius,
            },
            radius * turn.abs(),
        );
        path.push(Shape::Line, d1 - tangent);
        Some(path)
    }

    fn hermite(a: Pose, b: Pose) -> Self {
        let delta = b.pos - a.pos;
        let (fa, la) = (a.forward(), a.left());
        let (dx, dy) = (fa.dot(delta), la.dot(delta));
        let turn = wrap_angle(b.hdg - a.hdg);
        let m = delta.length();
        let (m1u, m1v) = (m * turn.cos(), m * turn.sin());
        let u = [0.0, m, 3.0 * dx - 2.0 * m - m1u, -2.0 * dx + m + m1u];
        let v = [0.0, 0.0, 3.0 * dy - m1v, -2.0 * dy + m1v];
        let length = poly_length(&u, &v);
        let mut path = Self::new(a);
        path.push(Shape::Poly3 { u, v }, length);
        path
    }
}

/// The arc length of the curve `(u(p), v(p))` for `p` in `[0, 1]`, by
/// composite Simpson's rule: plain arithmetic and square roots, so it is the
/// same on every platform.
fn poly_length(u: &[f64; 4], v: &[f64; 4]) -> f64 {
    const N: usize = 2048;
    let speed = |p: f64| cubic_slope(u, p).hypot(cubic_slope(v, p));
    let h = 1.0 / N as f64;
    let mut sum = speed(0.0) + speed(1.0);
    for i in 1..N {
        let weight = if i % 2 == 1 { 4.0 } else { 2.0 };
        sum += weight * speed(i as f64 * h);
    }
    sum * h / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Pose, b: Pose) -> bool {
        a.pos.distance(b.pos) < 1e-9 && wrap_angle(a.hdg - b.hdg).abs() < 1e-9
    }

    #[test]
    fn fillet_closes_a_right_angle() {
        let a = Pose::new(0.0, 0.0, 0.0);
        let b = Pose::new(20.0, 8.0, PI / 2.0);
        let path = Path::connect(a, b);
        assert!(close(path.end(), b), "{:?}", path.end());
        assert_eq!(path.segments.len(), 2);
    }

    #[test]
    fn hermite_closes_a_lane_shift() {
        let a = Pose::new(0.0, 0.0, 0.3);
        let b = Pose {
            pos: a.at(30.0, -3.5),
            hdg: 0.3,
        };
        let path = Path::connect(a, b);
        assert!(matches!(path.segments[0].shape, Shape::Poly3 { .. }));
        assert!(close(path.end(), b), "{:?}", path.end());
        assert!(path.length() > 30.0 && path.length() < 31.0);
    }

    #[test]
    fn rounded_corner_keeps_the_points() {
        let pts = [
            DVec2::new(0.0, 0.0),
            DVec2::new(100.0, 0.0),
            DVec2::new(100.0, 50.0),
        ];
        let path = Path::rounded(&pts, 20.0);
        assert!(close(path.end(), Pose::new(100.0, 50.0, PI / 2.0)));
        let trimmed = path.trimmed(10.0, 5.0);
        assert!(close(trimmed.end(), Pose::new(100.0, 45.0, PI / 2.0)));
        assert!(close(trimmed.start, Pose::new(10.0, 0.0, 0.0)));
    }
}
