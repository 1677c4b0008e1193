//! Conversions between the simulator's types and the `ssrdrive.v1` wire messages, shared by
//! the client here and the server in `ssr-agent` so both read the protocol the same way.

use ssrdrive_proto::v1;

use crate::agent::{CameraFrame, Control, Observation};
use crate::camera::{CameraSpec, Rig, RigError};

/// A rig on the wire.
pub fn rig_to_proto(rig: &Rig) -> v1::Rig {
    v1::Rig {
        cameras: rig
            .cameras
            .iter()
            .map(|c| v1::CameraSpec {
                id: c.id.clone(),
                x: c.x,
                y: c.y,
                z: c.z,
                roll: c.roll,
                pitch: c.pitch,
                yaw: c.yaw,
                width: c.width,
                height: c.height,
                fov: c.fov,
            })
            .collect(),
    }
}

/// A rig from the wire, checked like every rig.
pub fn rig_from_proto(rig: &v1::Rig) -> Result<Rig, RigError> {
    Rig::new(
        rig.cameras
            .iter()
            .map(|c| CameraSpec {
                id: c.id.clone(),
                x: c.x,
                y: c.y,
                z: c.z,
                roll: c.roll,
                pitch: c.pitch,
                yaw: c.yaw,
                width: c.width,
                height: c.height,
                fov: c.fov,
            })
            .collect(),
    )
}

/// One RGB8 image per rig camera, its pixels from `pixels(camera)` (width * height * 3 bytes):
/// synthetic steps for warm-ups, benchmarks and tests.
pub fn rgb_images(
    rig: &v1::Rig,
    mut pixels: impl FnMut(&v1::CameraSpec) -> Vec<u8>,
) -> Vec<v1::Image> {
    rig.cameras
        .iter()
        .map(|c| v1::Image {
            camera_id: c.id.clone(),
            width: c.width,
            height: c.height,
            encoding: v1::ImageEncoding::Rgb8 as i32,
            data: pixels(c),
        })
        .collect()
}

/// A rendered frame as an uncompressed RGB8 image.
pub fn frame_to_proto(frame: &CameraFrame) -> v1::Image {
    v1::Image {
        camera_id: frame.camera.clone(),
        width: frame.width,
        height: frame.height,
        encoding: v1::ImageEncoding::Rgb8 as i32,
        data: frame.rgb.clone(),
    }
}

/// The step request of one observation (its frames in rig order).
pub fn step_request(episode_id: &str, obs: &Observation) -> v1::StepRequest {
    v1::StepRequest {
        episode_id: episode_id.to_string(),
        frame_index: obs.frame,
        timestamp_s: obs.time,
        images: obs.frames.iter().map(frame_to_proto).collect(),
        speed_mps: obs.speed,
        pose: Some(v1::Pose {
            x: obs.position.x,
            y: obs.position.y,
            z: obs.position.z,
            yaw: obs.yaw,
        }),
        command: obs.command.value(),
        target_point: Some(v1::EgoPoint {
            x: obs.target_point.x,
            y: obs.target_point.y,
        }),
        debug: false,
    }
}

pub fn control_to_proto(control: Control) -> v1::Control {
    v1::Control {
        steer: control.steer,
        throttle: control.throttle,
        brake: control.brake,
    }
}

/// A control from the wire, clamped to its ranges (NaN becomes a full stop).
pub fn control_from_proto(control: &v1::Control) -> Control {
    Control {
        steer: control.steer,
        throttle: control.throttle,
        brake: control.brake,
    }
    .sanitized()
}
