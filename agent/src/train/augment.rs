//! Photometric augmentation: brightness, contrast and saturation jitter on RGB8 frames.
//! Geometry is never touched (the calibration must keep matching the pixels).

use rand::{RngExt as _, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One draw of the jitter, applied identically to every frame of a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Photometric {
    /// Brightness factor: every channel is multiplied by it last.
    pub brightness: f32,
    /// Contrast factor: distance from the frame's mean luma is scaled by it.
    pub contrast: f32,
    /// Saturation factor: each channel's distance from the pixel's luma is scaled by it.
    pub saturation: f32,
}

impl Photometric {
    /// Factors drawn uniformly in `1 ± 0.3 * strength` from `seed` (strength 0: identity).
    pub fn draw(seed: u64, strength: f32) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let spread = 0.3 * strength.clamp(0.0, 3.0);
        let mut factor = || {
            if spread > 0.0 {
                rng.random_range(1.0 - spread..1.0 + spread).max(0.0)
            } else {
                1.0
            }
        };
        Self {
            brightness: factor(),
            contrast: factor(),
            saturation: factor(),
        }
    }

    /// Applies the jitter in place to `width * height * 3` RGB8 bytes.
    pub fn apply(&self, rgb: &mut [u8]) {
        let pixels = (rgb.len() / 3).max(1);
        let mean_luma = rgb.chunks_exact(3).map(luma).sum::<f32>() / pixels as f32;
        for pixel in rgb.chunks_exact_mut(3) {
            let grey = luma(pixel);
            for channel in pixel.iter_mut() {
                let saturated = grey + (*channel as f32 - grey) * self.saturation;
                let contrasted = mean_luma + (saturated - mean_luma) * self.contrast;
                *channel = (contrasted * self.brightness).round().clamp(0.0, 255.0) as u8;
            }
        }
    }
}

fn luma(pixel: &[u8]) -> f32 {
    0.299 * pixel[0] as f32 + 0.587 * pixel[1] as f32 + 0.114 * pixel[2] as f32
}
