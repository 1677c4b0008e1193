//! Camera rigs in CARLA's sensor description and their pinhole projection, shared by the
//! renderer, the dataset and the network.
//!
//! A [`CameraSpec`] is what a CARLA user writes in `sensors()`: a position (x, y, z) in metres
//! and a rotation (roll, pitch, yaw) in degrees relative to the ego vehicle, in CARLA's
//! left-handed frame (x forward, y right, z up; positive yaw turns right, positive pitch looks
//! up), plus the image size and the horizontal field of view. [`CameraSpec::project`] maps a
//! point of the ego frame this crate uses everywhere (ISO 8855: x forward, y left, z up, origin
//! at the centre of the vehicle box on the ground) into the image.
//!
//! Image coordinates are continuous pixels: (0, 0) is the top-left corner of the image and the
//! centre of pixel (i, j) is at (i + 0.5, j + 0.5). The principal point is the image centre and
//! the focal length is `width / (2 tan(fov / 2))` for both axes (square pixels), as in CARLA.

use serde::{Deserialize, Serialize};

use ssrdrive_support::error_text::clipped;
use ssrdrive_support::files::{CappedReadError, read_capped_text};

/// Most cameras a rig may hold (the network keeps one learned embedding per camera slot).
pub const MAX_CAMERAS: usize = 6;
/// Largest image side accepted in a rig, pixels.
pub const MAX_IMAGE_SIDE: u32 = 8192;
/// Most pixels in one camera image (a 4096x4096 frame; 4K video is half of it).
pub const MAX_IMAGE_PIXELS: u64 = 16 * 1024 * 1024;

/// One camera in CARLA's sensor description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraSpec {
    /// Camera name, unique in its rig: 1-64 ASCII letters, digits, '_' or '-' (it names files).
    pub id: String,
    /// Position relative to the ego, CARLA frame (x forward, y right, z up), metres.
    pub x: f32,
    /// Lateral position, CARLA frame (positive to the right), m.
    pub y: f32,
    /// Height, m (z up).
    pub z: f32,
    /// Rotation relative to the ego, degrees, CARLA convention: roll about the forward axis.
    pub roll: f32,
    /// Pitch, degrees; positive looks up.
    pub pitch: f32,
    /// Yaw, degrees; positive turns right.
    pub yaw: f32,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Horizontal field of view, degrees.
    pub fov: f32,
}

/// A rig that cannot be used, with the camera and the field at fault.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RigError {
    /// The rig has no camera.
    #[error("a rig needs at least one camera")]
    Empty,
    /// The rig has more than [`MAX_CAMERAS`] cameras (the count given).
    #[error("a rig holds at most {MAX_CAMERAS} cameras, this one has {0}")]
    TooManyCameras(usize),
    /// A camera with a field out of range.
    #[error("camera {index} ('{id}'): {problem}")]
    BadCamera {
        /// Index of the camera in the rig.
        index: usize,
        /// The camera's id (clipped for printing).
        id: String,
        /// What is wrong, naming the field.
        problem: String,
    },
    /// Two cameras share an id (the id given).
    #[error("camera id '{0}' appears twice in the rig")]
    DuplicateId(String),
    /// The text is not a rig in JSON (the parser's message).
    #[error("not a rig in JSON (a list of cameras or {{\"cameras\": [...]}}): {0}")]
    Json(String),
    /// A rig file that cannot be read or parsed.
    #[error("rig {path}: {problem}")]
    File {
        /// The argument given: a path that is not a preset name.
        path: String,
        /// Why the file could not be read or parsed.
        problem: String,
    },
}

impl CameraSpec {
    /// TCP's front camera: x -1.5, z 2.0, 900x256, fov 100.
    pub fn tcp_front() -> Self {
        Self {
            id: "rgb_front".into(),
            x: -1.5,
            y: 0.0,
            z: 2.0,
            roll: 0.0,
            pitch: 0.0,
            yaw: 0.0,
            width: 900,
            height: 256,
            fov: 100.0,
        }
    }

    /// Focal length in pixels (same for both axes).
    pub fn focal(&self) -> f32 {
        self.width as f32 / (2.0 * (self.fov.to_radians() / 2.0).tan())
    }

    /// Checks every field; the message names the field and the bound it breaks.
    pub fn validate(&self) -> Result<(), String> {
        let id_ok = (1..=64).contains(&self.id.len())
            && self
                .id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if !id_ok {
            return Err(format!(
                "id '{}' must be 1-64 letters, digits, '_' or '-' (it names files and folders)",
                clipped(&self.id)
            ));
        }
        let numbers = [
            ("x", self.x),
            ("y", self.y),
            ("z", self.z),
            ("roll", self.roll),
            ("pitch", self.pitch),
            ("yaw", self.yaw),
            ("fov", self.fov),
        ];
        if let Some((name, value)) = numbers.iter().find(|(_, v)| !v.is_finite()) {
            return Err(format!("{name} is not a finite number ({value})"));
        }
        if let Some((name, value)) = numbers[..3].iter().find(|(_, v)| v.abs() > 100.0) {
            return Err(format!(
                "{name} = {value} m is more than 100 m from the ego"
            ));
        }
        if let Some((name, value)) = numbers[3..6].iter().find(|(_, v)| v.abs() > 360.0) {
            return Err(format!("{name} = {value} degrees is outside -360..360"));
        }
        if !(1.0..=179.0).contains(&self.fov) {
            return Err(format!("fov = {} degrees is outside 1..179", self.fov));
        }
        for (name, side) in [("width", self.width), ("height", self.height)] {
            if side == 0 || side > MAX_IMAGE_SIDE {
                return Err(format!("{name} = {side} px is outside 1..{MAX_IMAGE_SIDE}"));
            }
        }
        let pixels = self.width as u64 * self.height as u64;
        if pixels > MAX_IMAGE_PIXELS {
            return Err(format!(
                "{}x{} is {pixels} pixels, over the {MAX_IMAGE_PIXELS}-pixel limit",
                self.width, self.height
            ));
        }
        Ok(())
    }

    /// The camera's axes (forward, right, up) and position in the ego frame (y left).
    pub fn pose_in_ego(&self) -> CameraPose {
        let (sr, cr) = self.roll.to_radians().sin_cos();
        let (sp, cp) = self.pitch.to_radians().sin_cos();
        let (sy, cy) = self.yaw.to_radians().sin_cos();
        // Columns of CARLA's (Unreal's) rotation matrix, in CARLA's frame.
        let forward = [cp * cy, cp * sy, sp];
        let right = [cy * sp * sr - sy * cr, sy * sp * sr + cy * cr, -cp * sr];
        let up = [-cy * sp * cr - sy * sr, -sy * sp * cr + cy * sr, cp * cr];
        // CARLA (x, y, z) is ego (x, -y, z).
        let flip = |v: [f32; 3]| [v[0], -v[1], v[2]];
        CameraPose {
            position: [self.x, -self.y, self.z],
            forward: flip(forward),
            right: flip(right),
            up: flip(up),
        }
    }

    /// Projects an ego-frame point (x forward, y left, z up) to continuous pixel coordinates
    /// (u right, v down) and its depth along the optical axis. `None` for points at or behind
    /// the image plane (depth <= 1e-5 m); the pixel may lie outside the image.
    pub fn project(&self, point: [f32; 3]) -> Option<([f32; 2], f32)> {
        self.projector().project(point)
    }

    /// A projector with the camera's trigonometry done once, for projecting many points.
    pub fn projector(&self) -> Projector {
        Projector {
            pose: self.pose_in_ego(),
            focal: self.focal(),
            centre: [self.width as f32 / 2.0, self.height as f32 / 2.0],
        }
    }
}

/// A camera's optical centre and unit axes in the ego frame (x forward, y left, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    /// Optical centre, ego frame, m.
    pub position: [f32; 3],
    /// Optical axis.
    pub forward: [f32; 3],
    /// Image +u.
    pub right: [f32; 3],
    /// Image -v.
    pub up: [f32; 3],
}

/// Projects ego-frame points into one camera (see [`CameraSpec::project`]).
#[derive(Debug, Clone, Copy)]
pub struct Projector {
    pose: CameraPose,
    focal: f32,
    centre: [f32; 2],
}

impl Projector {
    /// Pixel coordinates and depth, or `None` behind the camera.
    pub fn project(&self, point: [f32; 3]) -> Option<([f32; 2], f32)> {
        let d = [
            point[0] - self.pose.position[0],
            point[1] - self.pose.position[1],
            point[2] - self.pose.position[2],
        ];
        let dot = |a: [f32; 3]| a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
        let depth = dot(self.pose.forward);
        if depth <= 1e-5 {
            return None;
        }
        let u = self.centre[0] + self.focal * dot(self.pose.right) / depth;
        let v = self.centre[1] - self.focal * dot(self.pose.up) / depth;
        Some(([u, v], depth))
    }
}

/// An ordered set of cameras; frames arrive in this order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Rig {
    /// The cameras, in the order frames arrive.
    pub cameras: Vec<CameraSpec>,
}

/// Named rigs: (name, what it is).
pub const RIG_PRESETS: [(&str, &str); 2] = [
    ("tcp", "TCP's front camera: x -1.5, z 2.0, 900x256, fov 100"),
    (
        "tcp-small",
        "TCP's front camera at 320x96, the input size of the cpu-default model",
    ),
];

/// Largest rig file read, bytes.
const MAX_RIG_FILE_BYTES: u64 = 1 << 20;

impl Rig {
    /// TCP's single front camera.
    pub fn tcp() -> Self {
        Self {
            cameras: vec![CameraSpec::tcp_front()],
        }
    }

    /// TCP's front camera at 320x96 (same pose and fov), the cpu-default model's input size,
    /// so frames need no resizing.
    pub fn tcp_small() -> Self {
        Self {
            cameras: vec![CameraSpec {
                width: 320,
                height: 96,
                ..CameraSpec::tcp_front()
            }],
        }
    }

    /// Whether an ego-frame point (x forward, y left, z up above the ground, m) projects into
    /// the frame of one of the cameras: in front of it and within its pixels.
    pub fn sees(&self, point: [f32; 3]) -> bool {
        self.cameras.iter().any(|camera| {
            camera.project(point).is_some_and(|([u, v], _)| {
                (0.0..camera.width as f32).contains(&u) && (0.0..camera.height as f32).contains(&v)
            })
        })
    }

    /// A preset of [`RIG_PRESETS`] by name.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "tcp" => Some(Self::tcp()),
            "tcp-small" => Some(Self::tcp_small()),
            _ => None,
        }
    }

    /// A preset name or the path of a JSON rig file (see [`Rig::from_json`]).
    pub fn from_name_or_file(arg: &str) -> Result<Self, RigError> {
        if let Some(rig) = Self::preset(arg) {
            return Ok(rig);
        }
        let text =
            read_capped_text(std::path::Path::new(arg), MAX_RIG_FILE_BYTES).map_err(|e| {
                let names: Vec<&str> = RIG_PRESETS.iter().map(|(n, _)| *n).collect();
                let problem = match e {
                    CappedReadError::Io(e) => {
                        format!("{e} (and not a preset: {})", names.join(", "))
                    }
                    other => other.to_string(),
                };
                RigError::File {
                    path: arg.to_string(),
                    problem,
                }
            })?;
        Self::from_json(&text).map_err(|e| RigError::File {
            path: arg.to_string(),
            problem: e.to_string(),
        })
    }

    /// A validated rig: 1..=6 cameras, distinct ids, every field in range.
    pub fn new(cameras: Vec<CameraSpec>) -> Result<Self, RigError> {
        let rig = Self { cameras };
        rig.validate()?;
        Ok(rig)
    }

    /// Checks the rig: 1..=[`MAX_CAMERAS`] cameras, every camera valid, ids distinct.
    pub fn validate(&self) -> Result<(), RigError> {
        if self.cameras.is_empty() {
            return Err(RigError::Empty);
        }
        if self.cameras.len() > MAX_CAMERAS {
            return Err(RigError::TooManyCameras(self.cameras.len()));
        }
        for (index, camera) in self.cameras.iter().enumerate() {
            camera.validate().map_err(|problem| RigError::BadCamera {
                index,
                id: clipped(&camera.id),
                problem,
            })?;
            if self.cameras[..index].iter().any(|c| c.id == camera.id) {
                return Err(RigError::DuplicateId(camera.id.clone()));
            }
        }
        Ok(())
    }

    /// Parses a rig from JSON: either `[camera, ...]` or `{"cameras": [camera, ...]}`.
    pub fn from_json(text: &str) -> Result<Self, RigError> {
        let json = |e: serde_json::Error| RigError::Json(e.to_string());
        let value: serde_json::Value = serde_json::from_str(text).map_err(json)?;
        let list = match value {
            serde_json::Value::Object(mut object) => object
                .remove("cameras")
                .ok_or_else(|| RigError::Json("the object has no \"cameras\" list".into()))?,
            other => other,
        };
        let cameras: Vec<CameraSpec> = serde_json::from_value(list).map_err(json)?;
        Self::new(cameras)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rig_sees_what_projects_into_a_frame_and_nothing_above_beside_or_behind_it() {
        let rig = Rig::tcp_small();
        // TCP's camera: 1.5 m behind the centre, 2 m up, about 19.7 degrees of frame above its
        // axis at 320x96 and 100 degrees across.
        assert!(rig.sees([10.0, 0.0, 2.0]));
        assert!(rig.sees([10.0, -3.0, 5.0]));
        // A traffic-light head 3 m above the camera is cut by the top of the frame once it is
        // nearer than 3 / tan(19.7 deg) = 8.4 m to it.
        assert!(rig.sees([7.2, -2.5, 5.0]));
        assert!(!rig.sees([6.6, -2.5, 5.0]));
        assert!(!rig.sees([0.0, -2.5, 2.0]), "beside");
        assert!(!rig.sees([-5.0, 0.0, 2.0]), "behind");
        let two = Rig {
            cameras: vec![
                CameraSpec::tcp_front(),
                CameraSpec {
                    yaw: 180.0,
                    ..CameraSpec::tcp_front()
                },
            ],
        };
        assert!(two.sees([-5.0, 0.0, 2.0]), "a rear camera");
    }
}
