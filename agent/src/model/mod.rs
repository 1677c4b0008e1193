//! The SSR network: image backbone -> BEV encoder (spatial cross-attention through the camera
//! calibration, temporal self-attention over the episode's previous BEV) -> Scenes TokenLearner
//! (navigation-gated) -> TCP head; plus the Future Feature Predictor used in training and, where
//! the config has them, the occupancy and motion heads on the BEV and the hazard and light
//! heads on the scene tokens.
//!
//! [`SsrModel::forward`] is one tick for a batch of episodes. Everything episode-specific
//! (calibration, ego motion, previous BEV) comes in through [`ModelInput`]; the model holds no
//! state between calls. [`crate::policy`] wraps it with per-episode state and control.

pub mod backbone;
pub mod bev;
pub mod blend;
pub mod classifier;
pub mod config;
pub mod cpu_kernels;
pub mod ffp;
pub mod fused;
pub mod grid;
pub mod hazard;
pub(crate) mod init;
pub mod light;
mod norm;
pub mod occupancy;
pub mod sampling;
pub mod stl;
pub mod tcp_head;
mod transformer;

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};

use backbone::Backbone;
use bev::{BevEncoder, GeometryTensors};
use classifier::{TokenClassifier, TokenClassifierConfig};
use config::SsrConfig;
use ffp::FutureFeaturePredictor;
use occupancy::{OccupancyHead, OccupancyHeadConfig};
use stl::{SceneTokenLearner, SceneTokens};
use tcp_head::{HeadOutput, TcpHead};

/// One tick of a batch of B episodes with the same number of cameras.
#[derive(Debug, Clone)]
pub struct ModelInput {
    /// `[B * cameras, 3, H, W]` ImageNet-normalised, at the config's input size.
    pub images: Tensor<4>,
    /// Cameras per episode (the images are grouped by episode, cameras in rig order).
    pub cameras: usize,
    /// Per-episode camera reference points, temporal alignment and can-bus, as tensors.
    pub geometry: GeometryTensors,
    /// `[B, Q, C]`; ignored (may be zeros) where `geometry.has_previous` is 0.
    pub previous_bev: Tensor<3>,
    /// What the planner reads besides the BEV.
    pub navigation: Navigation,
}

/// The planner's inputs besides the BEV, for a batch of B episodes.
#[derive(Debug, Clone)]
pub struct Navigation {
    /// `[B, 1]` m/s.
    pub speed: Tensor<2>,
    /// `[B, 2]` ego frame, m.
    pub target_point: Tensor<2>,
    /// `[B, 6]` one-hot of RoadOption - 1 (VOID mapped to LANEFOLLOW).
    pub command: Tensor<2>,
}

/// What one tick produces.
#[derive(Debug, Clone)]
pub struct ModelOutput {
    /// `[B, Q, C]`: kept as the episode's previous BEV for the next tick.
    pub bev: Tensor<3>,
    /// The scene tokens, with the STL attention and navigation gate.
    pub scene: SceneTokens,
    /// Waypoints, control-branch Beta parameters and predicted speed.
    pub head: HeadOutput,
}

/// The SSR network: backbone, BEV encoder, Scenes TokenLearner, TCP head and the Future
/// Feature Predictor (training only).
#[derive(Module, Debug)]
pub struct SsrModel {
    /// Image backbone (ResNet and neck).
    pub backbone: Backbone,
    /// BEV encoder.
    pub bev: BevEncoder,
    /// Scenes TokenLearner.
    pub stl: SceneTokenLearner,
    /// TCP head.
    pub head: TcpHead,
    /// Future Feature Predictor (used by training only).
    pub ffp: FutureFeaturePredictor,
    /// Occupancy head, where the config has one.
    pub occupancy: Option<OccupancyHead>,
    /// Hazard head, where the config has one.
    pub hazard: Option<TokenClassifier>,
    /// Motion head (occupancy [`occupancy::MOTION_HORIZON_S`] ahead), where the config has one.
    pub motion: Option<OccupancyHead>,
    /// Light head (the state of the light ahead, [`light::LightClass`]), where the config has
    /// one.
    pub light: Option<TokenClassifier>,
}

impl SsrConfig {
    /// A freshly initialised network (random weights: a component, not a driver).
    pub fn init(&self, device: &Device) -> SsrModel {
        SsrModel {
            backbone: Backbone::new(self, device),
            bev: BevEncoder::new(self, device),
            stl: SceneTokenLearner::new(self, device),
            head: TcpHead::new(self, device),
            ffp: FutureFeaturePredictor::new(self, device),
            occupancy: self.init_occupancy_head(device),
            hazard: self.init_hazard_head(device),
            motion: self.init_motion_head(device),
            light: self.init_light_head(device),
        }
    }

    /// A freshly initialised hazard head, where the config has one.
    pub fn init_hazard_head(&self, device: &Device) -> Option<TokenClassifier> {
        self.hazard_head.then(|| {
            self.token_classifier(hazard::Hazard::ALL.len())
                .init(device)
        })
    }

    /// A freshly initialised light head, where the config has one.
    pub fn init_light_head(&self, device: &Device) -> Option<TokenClassifier> {
        self.light_head.then(|| {
            self.token_classifier(light::LightClass::ALL.len())
                .init(device)
        })
    }

    fn token_classifier(&self, classes: usize) -> TokenClassifierConfig {
        TokenClassifierConfig {
            channels: self.channels,
            hidden: self.head.hidden_dim,
            classes,
        }
    }

    /// A freshly initialised occupancy head, where the config has one.
    pub fn init_occupancy_head(&self, device: &Device) -> Option<OccupancyHead> {
        self.occupancy_head
            .then(|| self.occupancy_head_config().init(device))
    }

    /// A freshly initialised motion head, where the config has one.
    pub fn init_motion_head(&self, device: &Device) -> Option<OccupancyHead> {
        self.motion_head
            .then(|| self.occupancy_head_config().init(device))
    }

    fn occupancy_head_config(&self) -> OccupancyHeadConfig {
        OccupancyHeadConfig {
            channels: self.channels,
            hidden: self.channels,
        }
    }
}

impl SsrModel {
    /// Backbone features `[B * cameras, C, h, w]`.
    pub fn image_features(&self, images: Tensor<4>) -> Tensor<4> {
        self.backbone.forward(images)
    }

    /// The BEV of one tick from the backbone features.
    pub fn encode_bev(&self, features: Tensor<4>, input: &ModelInput) -> Tensor<3> {
        let features = self.bev.image_features(features, input.cameras);
        self.bev
            .forward(&features, &input.geometry, input.previous_bev.clone())
    }

    /// STL and the head over a BEV.
    pub fn plan(&self, bev: Tensor<3>, input: &Navigation) -> (SceneTokens, HeadOutput) {
        let scene = self.stl.forward(
            bev,
            self.bev.positions(),
            input.command.clone(),
            input.target_point.clone(),
        );
        let head = self.head.forward(
            scene.tokens.clone(),
            input.speed.clone(),
            input.target_point.clone(),
            input.command.clone(),
        );
        (scene, head)
    }

    /// One tick: backbone -> BEV -> STL -> head.
    pub fn forward(&self, input: &ModelInput) -> ModelOutput {
        let bev = self.encode_bev(self.image_features(input.images.clone()), input);
        let (scene, head) = self.plan(bev.clone(), &input.navigation);
        ModelOutput { bev, scene, head }
    }

    /// FFP: the predicted BEV of a future frame from this tick's output.
    pub fn predict_future_bev(&self, output: &ModelOutput) -> Tensor<3> {
        self.ffp.forward(
            output.scene.tokens.clone(),
            output.head.waypoints.clone(),
            output.bev.clone(),
        )
    }
}

/// A float tensor from row-major values.
pub fn float_tensor<const D: usize>(
    values: Vec<f32>,
    shape: [usize; D],
    device: &Device,
) -> Tensor<D> {
    Tensor::from_data(TensorData::new(values, shape), device)
}

/// A float tensor's values, row-major.
pub fn float_values<const D: usize>(tensor: Tensor<D>) -> Vec<f32> {
    tensor
        .into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .expect("converted to f32")
}
