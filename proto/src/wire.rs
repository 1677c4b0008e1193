//! Conversions between the contract's types and the `ssrdrive.v1` wire messages, shared by the
//! simulator's client and the agent's server so both read the protocol the same way.

use crate::camera::{CameraSpec, Rig, RigError};
use crate::control::Control;
use crate::v1;

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

/// A control on the wire.
pub fn control_to_proto(control: Control) -> v1::Control {
    v1::Control {
        steer: control.steer.into(),
        throttle: control.throttle.into(),
        brake: control.brake.into(),
    }
}

/// A control from the wire, clamped to its ranges (NaN becomes a full stop).
pub fn control_from_proto(control: &v1::Control) -> Control {
    Control {
        steer: control.steer as f32,
        throttle: control.throttle as f32,
        brake: control.brake as f32,
    }
    .sanitized()
}
