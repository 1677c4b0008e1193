//! The BEV grid: which ego-frame area each cell covers, and the CPU-side geometry of a sample
//! (camera reference points, temporal alignment, can-bus) that the encoder consumes as tensors.
//!
//! Layout: flat index = row * cols + col; row 0 is the far front (x = x_max) and column 0 the
//! far left (y = y_max), so a BEV map viewed as an image has forward up and left on the left.
//! Normalised BEV coordinates (u, v) follow [`crate::model::sampling`]: u along columns, v along
//! rows, 0..1 across the grid.

use burn::tensor::{Device, Tensor};
use serde::{Deserialize, Serialize};
use ssrdrive_proto::camera::Rig;

use crate::model::float_tensor;
use crate::pose::EgoMotion;

/// Length of the can-bus vector added to the BEV queries:
/// [dx, dy, dyaw, speed / 12, has previous BEV] (the deltas are 0 on the first frame).
pub const CAN_BUS_DIM: usize = 5;
/// Normalised image coordinate given to pillar points behind a camera (far outside the image).
const BEHIND_CAMERA: f32 = -4.0;

/// The area the BEV covers and its cells.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BevGrid {
    /// Cells along x (rows, forward is row 0).
    pub rows: usize,
    /// Cells along y (columns, left is column 0).
    pub cols: usize,
    /// Rear edge of the grid, ego-frame x, m (negative: behind the ego).
    pub x_min: f32,
    /// Front edge of the grid, ego-frame x, m.
    pub x_max: f32,
    /// Right edge of the grid, ego-frame y, m (negative: to the right).
    pub y_min: f32,
    /// Left edge of the grid, ego-frame y, m.
    pub y_max: f32,
}

impl BevGrid {
    /// Number of cells, `rows * cols` (the BEV's query count Q).
    pub fn cells(&self) -> usize {
        self.rows * self.cols
    }

    /// Ego-frame centre (x, y) of cell `index` (flat).
    pub fn cell_centre(&self, index: usize) -> [f32; 2] {
        let (row, col) = (index / self.cols, index % self.cols);
        [
            self.x_max - (row as f32 + 0.5) * (self.x_max - self.x_min) / self.rows as f32,
            self.y_max - (col as f32 + 0.5) * (self.y_max - self.y_min) / self.cols as f32,
        ]
    }

    /// Normalised BEV coordinates (u, v) of an ego-frame point.
    pub fn normalised(&self, point: [f32; 2]) -> [f32; 2] {
        [
            (self.y_max - point[1]) / (self.y_max - self.y_min),
            (self.x_max - point[0]) / (self.x_max - self.x_min),
        ]
    }

    /// The flat index of the cell holding an ego-frame point, if inside the grid.
    pub fn cell_of(&self, point: [f32; 2]) -> Option<usize> {
        let [u, v] = self.normalised(point);
        if !(0.0..1.0).contains(&u) || !(0.0..1.0).contains(&v) {
            return None;
        }
        let col = ((u * self.cols as f32) as usize).min(self.cols - 1);
        let row = ((v * self.rows as f32) as usize).min(self.rows - 1);
        Some(row * self.cols + col)
    }
}

/// The geometry of one sample, computed on the CPU.
#[derive(Debug, Clone)]
pub struct SampleGeometry {
    cameras: usize,
    /// `[cameras, Q, Z, 2]` normalised image coordinates of the pillar points.
    camera_points: Vec<f32>,
    /// `[cameras, Q]` 1 where at least one pillar point of the cell lands in the image.
    camera_hits: Vec<f32>,
    /// `[Q, 2]` normalised coordinates of each cell's centre in the previous BEV.
    previous_points: Vec<f32>,
    has_previous: bool,
    can_bus: [f32; CAN_BUS_DIM],
}

impl SampleGeometry {
    /// Geometry for a rig at the current tick. `motion` is the ego motion since the history
    /// frame of the same episode, `None` on the first frame. `speed` (m/s) is the ego status
    /// shown to the can-bus with that motion, `None` when the network sees no ego status (then
    /// the motion only aligns the previous BEV).
    pub fn new(
        grid: &BevGrid,
        pillar_heights: &[f32],
        rig: &Rig,
        motion: Option<EgoMotion>,
        speed: Option<f32>,
    ) -> Self {
        let q = grid.cells();
        let mut camera_points =
            Vec::with_capacity(rig.cameras.len() * q * pillar_heights.len() * 2);
        let mut camera_hits = Vec::with_capacity(rig.cameras.len() * q);
        for camera in &rig.cameras {
            let projector = camera.projector();
            let size = [camera.width as f32, camera.height as f32];
            for index in 0..q {
                let [x, y] = grid.cell_centre(index);
                let mut hit = false;
                for &z in pillar_heights {
                    match projector.project([x, y, z]) {
                        Some(([u, v], _)) => {
                            let (nu, nv) = (u / size[0], v / size[1]);
                            hit |= (0.0..1.0).contains(&nu) && (0.0..1.0).contains(&nv);
                            camera_points.extend([nu, nv]);
                        }
                        None => camera_points.extend([BEHIND_CAMERA, BEHIND_CAMERA]),
                    }
                }
                camera_hits.push(if hit { 1.0 } else { 0.0 });
            }
        }
        let motion_or_still = motion.unwrap_or_default();
        let previous_points = (0..q)
            .flat_map(|i| grid.normalised(motion_or_still.to_previous(grid.cell_centre(i))))
            .collect();
        let has_previous = motion.is_some();
        Self {
            cameras: rig.cameras.len(),
            camera_points,
            camera_hits,
            previous_points,
            has_previous,
            can_bus: match speed {
                Some(speed) => [
                    motion_or_still.dx,
                    motion_or_still.dy,
                    motion_or_still.dyaw,
                    speed / 12.0,
                    if has_previous { 1.0 } else { 0.0 },
                ],
                None => [0.0, 0.0, 0.0, 0.0, if has_previous { 1.0 } else { 0.0 }],
            },
        }
    }
}

/// A batch of sample geometries as tensors.
#[derive(Debug, Clone)]
pub struct GeometryTensors {
    /// `[B * cameras, Q, Z, 2]`
    pub camera_points: Tensor<4>,
    /// `[B, cameras, Q]`
    pub camera_hits: Tensor<3>,
    /// `[B, Q, 2]`
    pub previous_points: Tensor<3>,
    /// `[B, 1, 1]`: 1 where the sample has a previous BEV.
    pub has_previous: Tensor<3>,
    /// `[B, CAN_BUS_DIM]`
    pub can_bus: Tensor<2>,
}

impl GeometryTensors {
    /// Stacks samples that share a camera count (the caller groups them).
    pub fn batch(
        samples: &[SampleGeometry],
        grid: &BevGrid,
        heights: usize,
        device: &Device,
    ) -> Self {
        let b = samples.len();
        let cameras = samples[0].cameras;
        assert!(
            samples.iter().all(|s| s.cameras == cameras),
            "a batch shares one camera count"
        );
        let q = grid.cells();
        let gather = |f: &dyn Fn(&SampleGeometry) -> &[f32]| {
            samples
                .iter()
                .flat_map(|s| f(s).iter().copied())
                .collect::<Vec<f32>>()
        };
        Self {
            camera_points: float_tensor(
                gather(&|s| &s.camera_points),
                [b * cameras, q, heights, 2],
                device,
            ),
            camera_hits: float_tensor(gather(&|s| &s.camera_hits), [b, cameras, q], device),
            previous_points: float_tensor(gather(&|s| &s.previous_points), [b, q, 2], device),
            has_previous: float_tensor(
                samples
                    .iter()
                    .map(|s| if s.has_previous { 1.0 } else { 0.0 })
                    .collect(),
                [b, 1, 1],
                device,
            ),
            can_bus: float_tensor(gather(&|s| &s.can_bus), [b, CAN_BUS_DIM], device),
        }
    }
}
