//! The triangle rasterizer behind the camera renderer: a pinhole [`View`], a colour + inverse
//! depth [`Target`], near-plane clipping and scan-line filling with a depth test.
//!
//! Rules: pixel (i, j) is covered when its centre (i + 0.5, j + 0.5) lies inside the projected
//! triangle, with a half-open rule on both axes, so two triangles sharing an edge never both
//! draw a pixel and never leave a crack between them. Depth is stored as 1/z (z along the
//! optical axis), which is exact to interpolate linearly on the screen; 0 means "nothing yet",
//! and a fragment is kept only when it is nearer than what is there.

use glam::Vec3;

/// Nearest depth drawn, metres in front of the camera.
pub const NEAR: f32 = 0.05;

/// A camera placed in the world: position, unit axes and intrinsics.
#[derive(Debug, Clone, Copy)]
pub struct View {
    /// Optical centre, world frame, m.
    pub origin: Vec3,
    /// Image +u (right).
    pub right: Vec3,
    /// Image -v (up).
    pub up: Vec3,
    /// Optical axis.
    pub forward: Vec3,
    /// Focal length, pixels.
    pub focal: f32,
    /// Principal point, pixels.
    pub centre: [f32; 2],
}

impl View {
    /// World point to camera coordinates (x right, y up, z forward).
    #[inline]
    pub fn to_camera(&self, p: Vec3) -> Vec3 {
        let d = p - self.origin;
        Vec3::new(d.dot(self.right), d.dot(self.up), d.dot(self.forward))
    }

    /// World direction of the ray through continuous pixel (u, v), not normalised.
    pub fn ray(&self, u: f32, v: f32) -> Vec3 {
        self.forward + self.right * ((u - self.centre[0]) / self.focal)
            - self.up * ((v - self.centre[1]) / self.focal)
    }

    /// Camera point to screen (u, v, 1/z); the point must be in front (z >= NEAR).
    #[inline]
    fn project(&self, c: Vec3) -> [f32; 3] {
        let inv = 1.0 / c.z;
        [
            self.centre[0] + self.focal * c.x * inv,
            self.centre[1] - self.focal * c.y * inv,
            inv,
        ]
    }
}

/// A colour buffer (0x00RRGGBB) and an inverse-depth buffer.
#[derive(Debug, Clone)]
pub struct Target {
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// Colour of each pixel, 0x00RRGGBB, row by row from the top-left.
    pub colour: Vec<u32>,
    /// Inverse depth (1/z, 1/m) of each pixel; 0 where nothing was drawn.
    pub depth: Vec<f32>,
}

impl Target {
    /// A `width` x `height` target, black and empty.
    pub fn new(width: usize, height: usize) -> Self {
        Self {
            width,
            height,
            colour: vec![0; width * height],
            depth: vec![0.0; width * height],
        }
    }

    /// Start a frame: copy `background` into the colour buffer and clear the depth.
    pub fn clear(&mut self, background: &[u32]) {
        self.colour.copy_from_slice(background);
        self.depth.fill(0.0);
    }

    /// Draw a world-space triangle in one flat colour.
    pub fn triangle(&mut self, view: &View, corners: [Vec3; 3], colour: u32) {
        let c = corners.map(|p| view.to_camera(p));
        let inside = c.map(|p| p.z >= NEAR);
        match inside.iter().filter(|&&b| b).count() {
            0 => {}
            3 => self.fill(c.map(|p| view.project(p)), colour),
            _ => {
                // Sutherland-Hodgman against the near plane: 3 or 4 corners remain.
                let mut poly = [Vec3::ZERO; 4];
                let mut n = 0;
                for k in 0..3 {
                    let (a, b) = (c[k], c[(k + 1) % 3]);
                    if inside[k] {
                        poly[n] = a;
                        n += 1;
                    }
                    if inside[k] != inside[(k + 1) % 3] {
                        // From the inside corner outwards, so a neighbour sharing the edge
                        // computes the same point whichever way its winding runs it.
                        let (i, o) = if inside[k] { (a, b) } else { (b, a) };
                        let t = (NEAR - i.z) / (o.z - i.z);
                        poly[n] = i + (o - i) * t;
                        n += 1;
                    }
                }
                let p = poly.map(|q| view.project(Vec3::new(q.x, q.y, q.z.max(NEAR))));
                self.fill([p[0], p[1], p[2]], colour);
                if n == 4 {
                    self.fill([p[0], p[2], p[3]], colour);
                }
            }
        }
    }

    /// Fill a screen triangle of (u, v, 1/z) corners.
    fn fill(&mut self, mut p: [[f32; 3]; 3], colour: u32) {
        p.sort_by(|a, b| a[1].total_cmp(&b[1]));
        let [p0, p1, p2] = p;
        let det = (p1[0] - p0[0]) * (p2[1] - p0[1]) - (p2[0] - p0[0]) * (p1[1] - p0[1]);
        if det.abs() < 1e-6 || !det.is_finite() {
            return;
        }
        let (w, h) = (self.width as f32, self.height as f32);
        let xmin = p0[0].min(p1[0]).min(p2[0]);
        let xmax = p0[0].max(p1[0]).max(p2[0]);
        if xmax < 0.0 || xmin > w || p2[1] < 0.0 || p0[1] > h {
            return;
        }
        let dwdx = ((p1[2] - p0[2]) * (p2[1] - p0[1]) - (p2[2] - p0[2]) * (p1[1] - p0[1])) / det;
        let dwdy = ((p1[0] - p0[0]) * (p2[2] - p0[2]) - (p2[0] - p0[0]) * (p1[2] - p0[2])) / det;
        let first = (p0[1] - 0.5).ceil().max(0.0) as usize;
        let last = ((p2[1] - 0.5).ceil().min(h)).max(0.0) as usize;
        for j in first..last {
            let yc = j as f32 + 0.5;
            let xa = edge_x(p0, p2, yc);
            let xb = if yc < p1[1] {
                edge_x(p0, p1, yc)
            } else {
                edge_x(p1, p2, yc)
            };
            let (xl, xr) = if xa < xb { (xa, xb) } else { (xb, xa) };
            let i0 = (xl - 0.5).ceil().clamp(0.0, w) as usize;
            let i1 = (xr - 0.5).ceil().clamp(0.0, w) as usize;
            if i0 >= i1 {
                continue;
            }
            let row = j * self.width;
            let depth = &mut self.depth[row + i0..row + i1];
            let pixels = &mut self.colour[row + i0..row + i1];
            let mut inv_z = p0[2] + dwdx * (i0 as f32 + 0.5 - p0[0]) + dwdy * (yc - p0[1]);
            for (d, c) in depth.iter_mut().zip(pixels.iter_mut()) {
                if inv_z > *d {
                    *d = inv_z;
                    *c = colour;
                }
                inv_z += dwdx;
            }
        }
    }
}

/// Where the edge from `a` (upper) to `b` (lower) crosses the row at `y`.
#[inline]
fn edge_x(a: [f32; 3], b: [f32; 3], y: f32) -> f32 {
    let dy = b[1] - a[1];
    if dy <= 0.0 {
        return a[0].min(b[0]);
    }
    a[0] + (y - a[1]) * (b[0] - a[0]) / dy
}
