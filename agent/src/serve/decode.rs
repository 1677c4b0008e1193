//! Wire requests to the inference API's inputs: each image checked against its rig camera
//! (id, size, byte count) and decoded from RGB8, BGRA8, PNG or JPEG into RGB8; every number
//! checked for NaN and range. A refusal names the camera or field and what is wrong; nothing is
//! allocated from a size the rig did not promise.

use ssrdrive_proto::camera::{CameraSpec, Rig};
use ssrdrive_proto::command::RoadOption;
use ssrdrive_proto::image::RgbImage;
use ssrdrive_proto::v1;
use ssrdrive_support::error_text::clipped;

use crate::policy::StepInput;
use crate::pose::Pose2;

/// A request field that cannot be used; becomes INVALID_ARGUMENT.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct BadRequest(pub String);

fn bad(message: impl Into<String>) -> BadRequest {
    BadRequest(message.into())
}

/// The inference input of one step request for an episode with `rig`.
pub fn step_input(request: &v1::StepRequest, rig: &Rig) -> Result<StepInput, BadRequest> {
    if request.images.len() != rig.cameras.len() {
        return Err(bad(format!(
            "the episode's rig has {} camera(s) but the step carries {} image(s)",
            rig.cameras.len(),
            request.images.len()
        )));
    }
    let frames = request
        .images
        .iter()
        .zip(&rig.cameras)
        .map(|(image, camera)| decode_image(image, camera))
        .collect::<Result<Vec<_>, _>>()?;
    let pose = request
        .pose
        .as_ref()
        .ok_or_else(|| bad("pose is missing"))?;
    let target = request
        .target_point
        .as_ref()
        .ok_or_else(|| bad("target_point is missing"))?;
    for (field, value) in [
        ("speed_mps", request.speed_mps),
        ("timestamp_s", request.timestamp_s),
        ("pose.x", pose.x),
        ("pose.y", pose.y),
        ("pose.z", pose.z),
        ("pose.yaw", pose.yaw),
        ("target_point.x", target.x),
        ("target_point.y", target.y),
    ] {
        // The network reads 32-bit floats: 1e300 is as unusable as infinity.
        if !value.is_finite() || value.abs() > f32::MAX as f64 {
            return Err(bad(format!(
                "{field} = {value:?} is not a finite 32-bit number"
            )));
        }
    }
    if request.speed_mps < 0.0 {
        return Err(bad(format!(
            "speed_mps = {} is negative; send the forward speed, >= 0",
            request.speed_mps
        )));
    }
    let command = RoadOption::from_value(request.command).ok_or_else(|| {
        bad(format!(
            "command {} is not a RoadOption (-1 or 1..=6)",
            request.command
        ))
    })?;
    Ok(StepInput {
        frames,
        rig: rig.clone(),
        pose: Pose2::new(pose.x as f32, pose.y as f32, pose.yaw as f32),
        speed: request.speed_mps as f32,
        command,
        target_point: [target.x as f32, target.y as f32],
        debug: request.debug,
    })
}

/// One image as RGB8, checked against its camera.
pub fn decode_image(image: &v1::Image, camera: &CameraSpec) -> Result<RgbImage, BadRequest> {
    let name = &camera.id;
    if image.camera_id != camera.id {
        return Err(bad(format!(
            "image for camera '{}' came where the rig has camera '{name}' (send images in rig order)",
            clipped(&image.camera_id)
        )));
    }
    if (image.width, image.height) != (camera.width, camera.height) {
        return Err(bad(format!(
            "camera '{name}': image is {}x{} but the rig says {}x{}",
            image.width, image.height, camera.width, camera.height
        )));
    }
    let (width, height) = (camera.width, camera.height);
    let pixels = width as usize * height as usize;
    let expect_len = |per_pixel: usize, format: &str| {
        if image.data.len() == pixels * per_pixel {
            Ok(())
        } else {
            Err(bad(format!(
                "camera '{name}': a {width}x{height} {format} image is {} bytes, got {}",
                pixels * per_pixel,
                image.data.len()
            )))
        }
    };
    let rgb = match v1::ImageEncoding::try_from(image.encoding) {
        Ok(v1::ImageEncoding::Rgb8) => {
            expect_len(3, "RGB8")?;
            image.data.clone()
        }
        Ok(v1::ImageEncoding::Bgra8) => {
            expect_len(4, "BGRA8")?;
            image
                .data
                .chunks_exact(4)
                .flat_map(|p| [p[2], p[1], p[0]])
                .collect()
        }
        Ok(v1::ImageEncoding::Png) => {
            ssrdrive_proto::image::decode_png_sized(&image.data, width, height)
                .map_err(|e| bad(format!("camera '{name}': {e}")))?
                .rgb
        }
        Ok(v1::ImageEncoding::Jpeg) => decode_jpeg(&image.data, width, height)
            .map_err(|e| bad(format!("camera '{name}': {e}")))?,
        Ok(v1::ImageEncoding::Unspecified) | Err(_) => {
            return Err(bad(format!(
                "camera '{name}': image encoding {} is not one of RGB8 (1), BGRA8 (2), PNG (3), JPEG (4)",
                image.encoding
            )));
        }
    };
    Ok(RgbImage { width, height, rgb })
}

/// A baseline or progressive JPEG (RGB or greyscale) of exactly `width` x `height`.
fn decode_jpeg(bytes: &[u8], width: u32, height: u32) -> Result<Vec<u8>, String> {
    let mut decoder = jpeg_decoder::Decoder::new(bytes);
    decoder
        .read_info()
        .map_err(|e| format!("not a readable JPEG: {e}"))?;
    let info = decoder.info().ok_or("not a readable JPEG: no header")?;
    if (u32::from(info.width), u32::from(info.height)) != (width, height) {
        return Err(format!(
            "JPEG is {}x{} but the rig says {width}x{height}",
            info.width, info.height
        ));
    }
    let pixels = decoder
        .decode()
        .map_err(|e| format!("not a readable JPEG: {e}"))?;
    match info.pixel_format {
        jpeg_decoder::PixelFormat::RGB24 => Ok(pixels),
        jpeg_decoder::PixelFormat::L8 => Ok(pixels.iter().flat_map(|&v| [v, v, v]).collect()),
        other => Err(format!(
            "JPEG pixel format {other:?}; expected RGB or greyscale"
        )),
    }
}
