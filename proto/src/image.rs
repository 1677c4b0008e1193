//! RGB8 images in and out of PNG: single frames (camera frames, dataset files) and animated
//! PNG (a whole run). Decoding refuses anything but 8-bit RGB(A) and images over
//! [`MAX_IMAGE_PIXELS`], with an error that says why.

use std::io::Write;

/// Largest image decoded, pixels: the largest camera image a rig allows.
pub use crate::camera::MAX_IMAGE_PIXELS;

/// An RGB8 image, row-major.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbImage {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Pixels, 3 bytes (R, G, B) each, row by row from the top-left: `width * height * 3` bytes.
    pub rgb: Vec<u8>,
}

/// Why an image could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The PNG decoder failed.
    #[error("not a readable PNG: {0}")]
    Decode(#[from] png::DecodingError),
    /// The PNG encoder failed.
    #[error("PNG encoding failed: {0}")]
    Encode(#[from] png::EncodingError),
    /// A colour type or bit depth other than 8-bit RGB or RGBA (the PNG's).
    #[error("PNG is {0:?} at {1:?} bits; expected 8-bit RGB or RGBA")]
    Format(png::ColorType, png::BitDepth),
    /// Width and height (pixels) whose product is over [`MAX_IMAGE_PIXELS`].
    #[error("PNG of {0}x{1} is over the {MAX_IMAGE_PIXELS}-pixel limit")]
    TooLarge(u32, u32),
    /// A PNG whose size is not the one the caller expected.
    #[error("PNG is {width}x{height} but {want_w}x{want_h} was expected")]
    Dimensions {
        /// The PNG's width, pixels.
        width: u32,
        /// The PNG's height, pixels.
        height: u32,
        /// The expected width, pixels.
        want_w: u32,
        /// The expected height, pixels.
        want_h: u32,
    },
    /// A pixel buffer whose length is not `width * height * 3`.
    #[error("{len} bytes of pixels for {width}x{height} RGB (expected {expected})")]
    Size {
        /// Width given, pixels.
        width: u32,
        /// Height given, pixels.
        height: u32,
        /// Bytes in the buffer.
        len: usize,
        /// Bytes `width * height * 3` needs.
        expected: usize,
    },
}

fn check_size(width: u32, height: u32, len: usize) -> Result<(), ImageError> {
    let expected = width as usize * height as usize * 3;
    if len != expected {
        return Err(ImageError::Size {
            width,
            height,
            len,
            expected,
        });
    }
    Ok(())
}

/// Encode RGB8 pixels as PNG (fast compression: frames are written by the thousand).
pub fn encode_png(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, ImageError> {
    check_size(width, height, rgb.len())?;
    let mut out = Vec::with_capacity(rgb.len() / 2);
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    encoder.write_header()?.write_image_data(rgb)?;
    Ok(out)
}

/// Decode an 8-bit RGB or RGBA PNG (alpha is dropped).
pub fn decode_png(bytes: &[u8]) -> Result<RgbImage, ImageError> {
    decode(bytes, None)
}

/// [`decode_png`] of an image that must be `width` x `height`; the header is checked before
/// any pixel memory is allocated.
pub fn decode_png_sized(bytes: &[u8], width: u32, height: u32) -> Result<RgbImage, ImageError> {
    decode(bytes, Some((width, height)))
}

fn decode(bytes: &[u8], expected: Option<(u32, u32)>) -> Result<RgbImage, ImageError> {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info()?;
    let info = reader.info();
    let (width, height) = (info.width, info.height);
    if width as u64 * height as u64 > MAX_IMAGE_PIXELS {
        return Err(ImageError::TooLarge(width, height));
    }
    if let Some((want_w, want_h)) = expected
        && (want_w, want_h) != (width, height)
    {
        return Err(ImageError::Dimensions {
            width,
            height,
            want_w,
            want_h,
        });
    }
    let channels = match (info.color_type, info.bit_depth) {
        (png::ColorType::Rgb, png::BitDepth::Eight) => 3,
        (png::ColorType::Rgba, png::BitDepth::Eight) => 4,
        (color, depth) => return Err(ImageError::Format(color, depth)),
    };
    let mut pixels = vec![0; width as usize * height as usize * channels];
    reader.next_frame(&mut pixels)?;
    let rgb = if channels == 4 {
        pixels
            .chunks_exact(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect()
    } else {
        pixels
    };
    Ok(RgbImage { width, height, rgb })
}

/// Write equally sized frames as one animated PNG, `delay_ms` per frame, looping.
pub fn write_apng(out: impl Write, frames: &[RgbImage], delay_ms: u16) -> Result<(), ImageError> {
    let Some(first) = frames.first() else {
        return Ok(());
    };
    let mut encoder = png::Encoder::new(out, first.width, first.height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    encoder.set_animated(frames.len() as u32, 0)?;
    encoder.set_frame_delay(delay_ms, 1000)?;
    let mut writer = encoder.write_header()?;
    for frame in frames {
        check_size(first.width, first.height, frame.rgb.len())?;
        writer.write_image_data(&frame.rgb)?;
    }
    writer.finish()?;
    Ok(())
}
