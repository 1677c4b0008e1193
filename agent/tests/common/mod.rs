//! Shared builders for the agent's integration tests.
#![allow(dead_code)]

pub mod fixture;

use burn::tensor::{Device, Distribution, Tensor};
use ssr_agent::model::bev::{GeometryTensors, SampleGeometry};
use ssr_agent::model::config::SsrConfig;
use ssr_agent::model::{ModelInput, Navigation, float_tensor};
use ssr_agent::policy::StepInput;
use ssr_agent::pose::{EgoMotion, Pose2};
use ssrdrive_proto::camera::{CameraSpec, Rig};
use ssrdrive_proto::command::{COMMANDS, RoadOption};
use ssrdrive_proto::image::RgbImage;

/// A deliberately tiny config that keeps every part of the architecture (fast tests).
pub fn tiny_config() -> SsrConfig {
    let mut config = SsrConfig::cpu_default();
    config.name = "tiny".into();
    config.image_width = 64;
    config.image_height = 32;
    config.backbone.stem_width = 8;
    config.backbone.widths = vec![8, 8, 16, 16];
    config.backbone.blocks = vec![1, 1, 1, 1];
    config.channels = 16;
    config.bev.grid.rows = 8;
    config.bev.grid.cols = 8;
    config.bev.heads = 2;
    config.bev.ffn_dim = 32;
    config.tokens.num_tokens = 4;
    config.tokens.bottleneck = 8;
    config.tokens.heads = 2;
    config.tokens.ffn_dim = 32;
    config.head = ssr_agent::model::config::HeadConfig {
        measurement_dim: 16,
        hidden_dim: 32,
        state_dim: 16,
        pred_len: 4,
    };
    config.ffp.fuser_slots = 8;
    config.validate().expect("tiny config is valid");
    config
}

/// A policy over a random network of `config` on the CPU.
pub fn policy_of(config: SsrConfig) -> ssr_agent::policy::SsrPolicy {
    let device = Device::flex();
    ssr_agent::policy::SsrPolicy::new(
        config.init(&device),
        config,
        ssr_agent::control::ControlConfig::default(),
        device,
    )
}

/// A rig of `n` cameras looking forward, left, right, ... at the config's image size.
pub fn rig(n: usize, width: u32, height: u32) -> Rig {
    let yaws = [0.0, -60.0, 60.0, 180.0, -120.0, 120.0];
    Rig::new(
        (0..n)
            .map(|i| CameraSpec {
                id: format!("cam{i}"),
                yaw: yaws[i],
                width,
                height,
                ..CameraSpec::tcp_front()
            })
            .collect(),
    )
    .expect("valid rig")
}

/// A model input of `batch` samples with `cameras` cameras; `has_previous` chooses the path.
pub fn model_input(
    config: &SsrConfig,
    batch: usize,
    cameras: usize,
    has_previous: bool,
    device: &Device,
) -> ModelInput {
    let grid = config.bev.grid;
    let rig = rig(cameras, 900, 256);
    let motion = has_previous.then_some(EgoMotion {
        dx: 0.5,
        dy: 0.1,
        dyaw: 0.05,
    });
    let geometry: Vec<SampleGeometry> = (0..batch)
        .map(|_| SampleGeometry::new(&grid, &config.bev.pillar_heights, &rig, motion, Some(5.0)))
        .collect();
    let commands = [
        RoadOption::Left,
        RoadOption::Right,
        RoadOption::Straight,
        RoadOption::LaneFollow,
        RoadOption::ChangeLaneLeft,
        RoadOption::ChangeLaneRight,
    ];
    let command: Vec<f32> = (0..batch)
        .flat_map(|b| commands[b % commands.len()].one_hot())
        .collect();
    ModelInput {
        images: Tensor::random(
            [batch * cameras, 3, config.image_height, config.image_width],
            Distribution::Normal(0.0, 1.0),
            device,
        ),
        cameras,
        geometry: GeometryTensors::batch(&geometry, &grid, config.bev.pillar_heights.len(), device),
        previous_bev: Tensor::random(
            [batch, grid.cells(), config.channels],
            Distribution::Normal(0.0, 1.0),
            device,
        ),
        navigation: Navigation {
            speed: Tensor::full([batch, 1], 5.0, device),
            target_point: float_tensor(
                (0..batch).flat_map(|b| [10.0 + b as f32, 2.0]).collect(),
                [batch, 2],
                device,
            ),
            command: float_tensor(command, [batch, COMMANDS], device),
        },
    }
}

/// A step input with deterministic pseudo-random frames.
pub fn step_input(rig: &Rig, tick: u32, seed: u32) -> StepInput {
    StepInput {
        frames: rig
            .cameras
            .iter()
            .map(|c| RgbImage {
                width: c.width,
                height: c.height,
                rgb: (0..c.width * c.height * 3)
                    .map(|k| ((k ^ seed).wrapping_mul(2654435761) >> 24) as u8)
                    .collect(),
            })
            .collect(),
        rig: rig.clone(),
        pose: Pose2::new(0.4 * tick as f32, 0.0, 0.01 * tick as f32),
        speed: 5.0,
        command: RoadOption::LaneFollow,
        target_point: [15.0, -1.0],
        debug: true,
    }
}

/// The largest |a - b|, element by element; infinite where either side is not finite (so a NaN
/// output never reads as "no difference": `f32::max` would drop it).
pub fn max_abs_diff(a: Vec<f32>, b: Vec<f32>) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(&b)
        .map(|(x, y)| {
            if x.is_finite() && y.is_finite() {
                (x - y).abs()
            } else {
                f32::INFINITY
            }
        })
        .fold(0.0, f32::max)
}
