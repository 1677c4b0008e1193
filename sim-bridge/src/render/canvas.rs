//! A tiny RGB raster with the few primitives the top-down view needs: thick lines, filled
//! convex polygons and discs, in world coordinates through a fixed scale, written as PNG.

use std::io::Write;

use glam::DVec2;

/// An RGB8 image with a world-to-pixel mapping (y up in the world, down in the image).
pub struct Canvas {
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    pixels: Vec<u8>,
    origin: DVec2,
    scale: f64,
}

impl Canvas {
    /// A canvas covering `lo..hi` (world metres) with `margin` metres around, at most
    /// `max_side` pixels on its long side, filled with `background`.
    pub fn fit(lo: DVec2, hi: DVec2, margin: f64, max_side: u32, background: [u8; 3]) -> Self {
        let lo = lo - DVec2::splat(margin);
        let size = (hi - lo + DVec2::splat(margin)).max(DVec2::ONE);
        let scale = max_side as f64 / size.x.max(size.y);
        let width = ((size.x * scale).ceil() as u32).max(1);
        let height = ((size.y * scale).ceil() as u32).max(1);
        let pixels = background
            .iter()
            .copied()
            .cycle()
            .take((width * height * 3) as usize)
            .collect();
        Self {
            width,
            height,
            pixels,
            origin: lo,
            scale,
        }
    }

    /// A `side` x `side` canvas showing `radius` metres around `centre`.
    pub fn around(centre: DVec2, radius: f64, side: u32, background: [u8; 3]) -> Self {
        let side = side.max(1);
        Self {
            width: side,
            height: side,
            pixels: background
                .iter()
                .copied()
                .cycle()
                .take((side * side * 3) as usize)
                .collect(),
            origin: centre - DVec2::splat(radius),
            scale: side as f64 / (2.0 * radius.max(1e-3)),
        }
    }

    /// Row-major RGB8 pixels.
    pub fn pixels(&self) -> &[u8] {
        &self.pixels
    }

    /// Pixels per metre.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    fn to_px(&self, p: DVec2) -> DVec2 {
        DVec2::new(
            (p.x - self.origin.x) * self.scale,
            self.height as f64 - (p.y - self.origin.y) * self.scale,
        )
    }

    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = ((y as u32 * self.width + x as u32) * 3) as usize;
            self.pixels[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Fill a convex polygon given in world coordinates.
    pub fn polygon(&mut self, corners: &[DVec2], c: [u8; 3]) {
        let px: Vec<DVec2> = corners.iter().map(|p| self.to_px(*p)).collect();
        let (lo, hi) = px.iter().fold(
            (DVec2::splat(f64::MAX), DVec2::splat(f64::MIN)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let (x0, x1) = (
            lo.x.floor().max(0.0) as i64,
            hi.x.ceil().min(self.width as f64) as i64,
        );
        let (y0, y1) = (
            lo.y.floor().max(0.0) as i64,
            hi.y.ceil().min(self.height as f64) as i64,
        );
        let n = px.len();
        for y in y0..y1 {
            for x in x0..x1 {
                let q = DVec2::new(x as f64 + 0.5, y as f64 + 0.5);
                let mut sign = 0.0;
                let inside = (0..n).all(|i| {
                    let cross = (px[(i + 1) % n] - px[i]).perp_dot(q - px[i]);
                    if sign == 0.0 {
                        sign = cross.signum();
                    }
                    cross * sign >= 0.0
                });
                if inside {
                    self.put(x, y, c);
                }
            }
        }
    }

    /// A line `width` metres wide.
    pub fn line(&mut self, a: DVec2, b: DVec2, width: f64, c: [u8; 3]) {
        let d = b - a;
        if d.length() < 1e-9 {
            return;
        }
        let n = d.normalize().perp() * (width.max(1.0 / self.scale) / 2.0);
        self.polygon(&[a + n, b + n, b - n, a - n], c);
    }

    /// A disc of `radius` metres.
    pub fn disc(&mut self, centre: DVec2, radius: f64, c: [u8; 3]) {
        let corners: Vec<DVec2> = (0..12)
            .map(|k| centre + DVec2::from_angle(k as f64 * std::f64::consts::TAU / 12.0) * radius)
            .collect();
        self.polygon(&corners, c);
    }

    /// Encode as PNG.
    pub fn write_png(&self, out: impl Write) -> Result<(), png::EncodingError> {
        let mut encoder = png::Encoder::new(out, self.width, self.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header()?;
        writer.write_image_data(&self.pixels)
    }
}
