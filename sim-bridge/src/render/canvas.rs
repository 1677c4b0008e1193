//! A tiny RGB raster with the few primitives the top-down view needs: thick lines, filled
//! convex polygons and discs, in world coordinates through a fixed scale; rectangles and text
//! (an 8x8 bitmap font, scaled by whole pixels) in pixel coordinates for titles, legends and
//! scale bars; written as PNG.

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

    /// The same canvas with `rows` pixel rows of `colour` added above it (for a title and a
    /// legend): the world keeps its place, measured from the bottom edge.
    pub fn with_header(mut self, rows: u32, colour: [u8; 3]) -> Self {
        let mut pixels: Vec<u8> = colour
            .iter()
            .copied()
            .cycle()
            .take((self.width * rows * 3) as usize)
            .collect();
        pixels.append(&mut self.pixels);
        self.pixels = pixels;
        self.height += rows;
        self
    }

    /// Fill the pixel rectangle from (`x`, `y`) (top left), `w` x `h` pixels.
    pub fn rect_px(&mut self, x: i64, y: i64, w: i64, h: i64, c: [u8; 3]) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.put(xx, yy, c);
            }
        }
    }

    /// Write `text` (ASCII; other characters show as '?') with its top left at pixel (`x`,
    /// `y`), each glyph 8 x 8 pixels times `size`; returns the x after the last glyph.
    pub fn text_px(&mut self, x: i64, y: i64, text: &str, size: i64, c: [u8; 3]) -> i64 {
        glyph_cells(x, y, text, size, |cx, cy| {
            self.rect_px(cx, cy, size, size, c)
        })
    }

    /// Where the world point `p` falls, in pixels.
    pub fn pixel_of(&self, p: DVec2) -> DVec2 {
        self.to_px(p)
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

/// Calls `cell` with the top left of every lit `size` x `size` cell of `text` written from
/// (`x`, `y`) in the 8x8 font; returns the x after the last glyph.
fn glyph_cells(x: i64, y: i64, text: &str, size: i64, mut cell: impl FnMut(i64, i64)) -> i64 {
    let mut at = x;
    for ch in text.chars() {
        let code = if ch.is_ascii() {
            ch as usize
        } else {
            '?' as usize
        };
        for (row, bits) in font8x8::legacy::BASIC_LEGACY[code].iter().enumerate() {
            for col in 0..8 {
                if bits & (1 << col) != 0 {
                    cell(at + col * size, y + row as i64 * size);
                }
            }
        }
        at += 8 * size;
    }
    at
}

/// Write `text` in white on a dark box with its top left at pixel (`x`, `y`) of a row-major
/// RGB8 image `width` pixels wide (a label on a panel of a composed picture); what falls
/// outside the image is left out.
pub fn label(rgb: &mut [u8], width: u32, x: i64, y: i64, text: &str) {
    let height = (rgb.len() / (width as usize * 3).max(1)) as i64;
    let mut fill = |x0: i64, y0: i64, w: i64, h: i64, c: [u8; 3]| {
        for yy in y0.max(0)..(y0 + h).min(height) {
            for xx in x0.max(0)..(x0 + w).min(width as i64) {
                let i = (yy as usize * width as usize + xx as usize) * 3;
                rgb[i..i + 3].copy_from_slice(&c);
            }
        }
    };
    let text_width = 8 * text.chars().count() as i64;
    fill(x, y, text_width + 6, 14, [20, 20, 24]);
    glyph_cells(x + 3, y + 3, text, 1, |cx, cy| {
        fill(cx, cy, 1, 1, [240, 240, 240])
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(pixels: &[u8], c: [u8; 3]) -> usize {
        pixels.chunks_exact(3).filter(|p| *p == c).count()
    }

    #[test]
    fn a_header_keeps_the_world_in_place_from_the_bottom_and_text_lands_in_it() {
        let canvas = Canvas::fit(DVec2::ZERO, DVec2::new(100.0, 50.0), 0.0, 200, [0, 0, 0]);
        let (w, h) = (canvas.width, canvas.height);
        let corner = canvas.pixel_of(DVec2::new(10.0, 10.0));
        let mut canvas = canvas.with_header(30, [9, 9, 9]);
        assert_eq!((canvas.width, canvas.height), (w, h + 30));
        let moved = canvas.pixel_of(DVec2::new(10.0, 10.0));
        assert_eq!(moved, corner + DVec2::new(0.0, 30.0));
        assert_eq!(count(canvas.pixels(), [9, 9, 9]), (w * 30) as usize);
        // "A" at size 2 in the header: lit cells of 2 x 2 pixels, nothing outside its 16 x 16.
        let end = canvas.text_px(4, 4, "A", 2, [200, 0, 0]);
        assert_eq!(end, 4 + 16);
        let lit = count(canvas.pixels(), [200, 0, 0]);
        assert!(lit > 0 && lit.is_multiple_of(4) && lit <= 16 * 16, "{lit}");
        let mut rgb = vec![0u8; 40 * 20 * 3];
        label(&mut rgb, 40, 0, 0, "hi there, past the edge");
        assert!(count(&rgb, [240, 240, 240]) > 0 && count(&rgb, [20, 20, 24]) > 0);
    }
}
