//! Flat-shaded primitives the camera renderer is built from: coloured triangles, upright boxes,
//! flat quads and discs, all in the world frame.

use glam::{Vec2, Vec3};

use super::style::{Appearance, Rgb};

/// A world-space triangle with its final (lit) colour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tri {
    /// Corners, world frame, m.
    pub corners: [Vec3; 3],
    /// Lit colour, 0x00RRGGBB.
    pub colour: u32,
}

/// An upright box: plan centre, heading, half length and width, bottom and top heights.
#[derive(Debug, Clone, Copy)]
pub struct UprightBox {
    /// Centre in plan (x, y), world frame, m.
    pub centre: Vec2,
    /// Heading of the length axis, rad counter-clockwise from +x.
    pub yaw: f32,
    /// Half length (along the heading) and half width, m.
    pub half: Vec2,
    /// Height of the bottom face, world z, m.
    pub bottom: f32,
    /// Height of the top face, world z, m.
    pub top: f32,
}

impl UprightBox {
    /// Add the box's faces lit by `app`. With `viewer`, faces turned away from that point are
    /// left out (a closed box never shows them).
    pub fn push(&self, out: &mut Vec<Tri>, colour: Rgb, app: &Appearance, viewer: Option<Vec3>) {
        let f = Vec2::from_angle(self.yaw);
        let l = f.perp();
        let (hx, hy) = (f * self.half.x, l * self.half.y);
        let plan = [
            self.centre + hx + hy,
            self.centre - hx + hy,
            self.centre - hx - hy,
            self.centre + hx - hy,
        ];
        let low = plan.map(|p| p.extend(self.bottom));
        let high = plan.map(|p| p.extend(self.top));
        let mut face = |quad: [Vec3; 4], normal: Vec3| {
            if let Some(eye) = viewer
                && (eye - quad[0]).dot(normal) <= 0.0
            {
                return;
            }
            push_quad(out, quad, app.shade(colour, normal));
        };
        face(high, Vec3::Z);
        face([low[3], low[2], low[1], low[0]], -Vec3::Z);
        let sides = [(0, 3, f), (1, 0, l), (2, 1, -f), (3, 2, -l)];
        for (a, b, n) in sides {
            face([low[a], low[b], high[b], high[a]], n.extend(0.0));
        }
    }
}

/// Two triangles of a planar quad (corners in order around it).
pub fn push_quad(out: &mut Vec<Tri>, q: [Vec3; 4], colour: u32) {
    out.push(Tri {
        corners: [q[0], q[1], q[2]],
        colour,
    });
    out.push(Tri {
        corners: [q[0], q[2], q[3]],
        colour,
    });
}

/// A vertical disc of `sides` facets facing `facing` (a horizontal unit vector).
pub fn push_vertical_disc(
    out: &mut Vec<Tri>,
    centre: Vec3,
    facing: Vec2,
    radius: f32,
    sides: usize,
    colour: u32,
) {
    let across = facing.perp().extend(0.0);
    let rim = |k: usize| {
        let a = std::f32::consts::TAU * (k as f32 + 0.5) / sides as f32;
        centre + (across * a.cos() + Vec3::Z * a.sin()) * radius
    };
    for k in 0..sides {
        out.push(Tri {
            corners: [centre, rim(k), rim(k + 1)],
            colour,
        });
    }
}
