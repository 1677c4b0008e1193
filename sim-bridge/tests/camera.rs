//! Camera rigs: projection with roll, pitch and yaw, and rejection of malformed rigs.

use ssrdrive_proto::camera::{CameraSpec, Rig, RigError};

fn close(a: [f32; 2], b: [f32; 2]) -> bool {
    (a[0] - b[0]).abs() < 1e-2 && (a[1] - b[1]).abs() < 1e-2
}

#[test]
fn a_point_on_the_optical_axis_lands_on_the_image_centre() {
    let camera = CameraSpec::tcp_front();
    let (pixel, depth) = camera.project([18.5, 0.0, 2.0]).expect("in front");
    assert!(close(pixel, [450.0, 128.0]), "{pixel:?}");
    assert!((depth - 20.0).abs() < 1e-4);
    assert!(
        camera.project([-3.0, 0.0, 2.0]).is_none(),
        "behind the camera"
    );
}

#[test]
fn projection_follows_carla_yaw_pitch_and_roll() {
    // Yaw 90 (CARLA: turns right): the camera looks along ego -y (right side).
    let right = CameraSpec {
        yaw: 90.0,
        x: 0.0,
        z: 0.0,
        ..CameraSpec::tcp_front()
    };
    let (pixel, depth) = right.project([0.0, -10.0, 0.0]).expect("in front");
    assert!(
        close(pixel, [450.0, 128.0]) && (depth - 10.0).abs() < 1e-4,
        "{pixel:?}"
    );
    // A point 1 m forward of that axis is to the camera's left: u < centre by f * 1/10.
    let f = right.focal();
    let (pixel, _) = right.project([1.0, -10.0, 0.0]).unwrap();
    assert!(close(pixel, [450.0 - f / 10.0, 128.0]), "{pixel:?}");

    // Pitch -30 (looking down): a ground point straight ahead at depth along the axis.
    let down = CameraSpec {
        pitch: -30.0,
        x: 0.0,
        z: 2.0,
        ..CameraSpec::tcp_front()
    };
    let ahead = 2.0 / 30f32.to_radians().tan();
    let (pixel, _) = down.project([ahead, 0.0, 0.0]).unwrap();
    assert!(close(pixel, [450.0, 128.0]), "{pixel:?}");

    // Roll 90: the camera's "up" is ego -y (CARLA roll right), so a point above the axis
    // appears... computed by hand: up axis = (0, +1 carla y) -> ego (0, -1, 0).
    let rolled = CameraSpec {
        roll: 90.0,
        x: 0.0,
        z: 0.0,
        ..CameraSpec::tcp_front()
    };
    let (pixel, _) = rolled.project([10.0, -1.0, 0.0]).unwrap();
    assert!(close(pixel, [450.0, 128.0 - f / 10.0]), "{pixel:?}");

    // All three at once against a hand-built rotation (yaw 30, pitch 10, roll 20).
    let combined = CameraSpec {
        yaw: 30.0,
        pitch: 10.0,
        roll: 20.0,
        x: 1.0,
        y: 0.5,
        z: 1.5,
        ..CameraSpec::tcp_front()
    };
    let (sy, cy) = 30f32.to_radians().sin_cos();
    let (sp, cp) = 10f32.to_radians().sin_cos();
    let (sr, cr) = 20f32.to_radians().sin_cos();
    let forward = [cp * cy, cp * sy, sp];
    let right_axis = [cy * sp * sr - sy * cr, sy * sp * sr + cy * cr, -cp * sr];
    let up = [-cy * sp * cr - sy * sr, -sy * sp * cr + cy * sr, cp * cr];
    // Camera-frame point (depth 12, 1.5 right, 0.7 up) expressed in CARLA coordinates.
    let carla: Vec<f32> = (0..3)
        .map(|k| [1.0, 0.5, 1.5][k] + 12.0 * forward[k] + 1.5 * right_axis[k] + 0.7 * up[k])
        .collect();
    let (pixel, depth) = combined.project([carla[0], -carla[1], carla[2]]).unwrap();
    let f = combined.focal();
    assert!((depth - 12.0).abs() < 1e-3);
    assert!(
        close(pixel, [450.0 + f * 1.5 / 12.0, 128.0 - f * 0.7 / 12.0]),
        "{pixel:?}"
    );
}

#[test]
fn malformed_rigs_are_rejected_with_the_field_named() {
    let bad = |spec: CameraSpec| Rig::new(vec![spec]).unwrap_err().to_string();
    assert!(
        bad(CameraSpec {
            fov: 0.0,
            ..CameraSpec::tcp_front()
        })
        .contains("fov")
    );
    assert!(
        bad(CameraSpec {
            width: 0,
            ..CameraSpec::tcp_front()
        })
        .contains("width")
    );
    assert!(
        bad(CameraSpec {
            yaw: f32::NAN,
            ..CameraSpec::tcp_front()
        })
        .contains("yaw")
    );
    assert!(
        bad(CameraSpec {
            z: 500.0,
            ..CameraSpec::tcp_front()
        })
        .contains("z = 500")
    );
    assert_eq!(Rig::new(vec![]), Err(RigError::Empty));
    assert_eq!(
        Rig::new(vec![CameraSpec::tcp_front(); 7]),
        Err(RigError::TooManyCameras(7))
    );
    assert!(matches!(
        Rig::new(vec![CameraSpec::tcp_front(); 2]),
        Err(RigError::DuplicateId(_))
    ));
    assert!(matches!(
        Rig::from_json("{\"cameras\": 3}"),
        Err(RigError::Json(_))
    ));
    let rig = Rig::from_json(&serde_json::to_string(&Rig::tcp()).unwrap()).unwrap();
    assert_eq!(rig, Rig::tcp());
}
