//! Model configurations: every size of the network, stored beside every checkpoint.
//!
//! Two presets: [`SsrConfig::paper`] (what the SSR paper drove CARLA with: ResNet-34 on TCP's
//! 900x256 front camera, a 256-channel BEV, 3 encoder layers, 16 scene tokens, TCP head with 4
//! waypoints at 0.5 s) and [`SsrConfig::cpu_default`] (the same architecture, narrower and on a
//! smaller image and BEV, sized by `ssr-agent bench` to step in real time on two CPU cores).

use std::path::Path;

use serde::{Deserialize, Serialize};
use ssrdrive_support::files::read_capped_text;
use ssrdrive_support::ranges::first_outside;

use super::grid::BevGrid;

/// The whole network.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SsrConfig {
    /// Preset name, for logs ("paper", "cpu-default" or a user's own).
    pub name: String,
    /// Network input width, pixels; frames of another size are resized (the calibration is
    /// unaffected, since projections are kept in normalised image coordinates).
    pub image_width: usize,
    /// Network input height, pixels (resized like the width).
    pub image_height: usize,
    /// The image backbone's ResNet stages.
    pub backbone: BackboneConfig,
    /// Channels of the image features after the neck and of the BEV.
    pub channels: usize,
    /// The BEV grid and encoder.
    pub bev: BevConfig,
    /// Scenes TokenLearner and the token self-attention.
    pub tokens: TokenConfig,
    /// The TCP head.
    pub head: HeadConfig,
    /// The Future Feature Predictor (training only).
    pub ffp: FfpConfig,
    /// Whether the network sees the ego's status: its speed (in the head's measurement encoder
    /// and the BEV can-bus) and its motion since the history frame (can-bus). Ego status is
    /// the copycat shortcut (speed near 0 predicts "stay stopped"; CILRS, "Is ego status all
    /// you need"); without it the speed is only an auxiliary prediction, and the motion still
    /// aligns the previous BEV. Checkpoints from before the switch have it on.
    #[serde(default = "ego_status_default")]
    pub ego_status: bool,
    /// Whether the network has the occupancy head ([`super::occupancy`]): which BEV cells a
    /// road user covers, trained from the actors the dataset records and kept in checkpoints.
    /// Checkpoints from before it have none.
    #[serde(default)]
    pub occupancy_head: bool,
    /// Whether the network has the hazard head ([`super::hazard`]): what the car waits for,
    /// from the scene tokens, trained from the expert's brake reasons and kept in checkpoints.
    /// Checkpoints from before it have none.
    #[serde(default)]
    pub hazard_head: bool,
    /// Whether the network has the motion head ([`super::occupancy`], the occupancy head's
    /// twin): which BEV cells a road user will cover [`super::occupancy::MOTION_HORIZON_S`]
    /// later, in this frame's ego frame, so that the safety stop can see where a crossing car
    /// is going. Checkpoints from before it have none.
    #[serde(default)]
    pub motion_head: bool,
    /// Whether the network has the light head ([`super::light`]): the state of the traffic
    /// light governing the route ahead, from the scene tokens, trained from the light each
    /// frame records. Checkpoints from before it have none.
    #[serde(default)]
    pub light_head: bool,
}

fn ego_status_default() -> bool {
    true
}

fn gate_target_point_default() -> bool {
    true
}

/// ResNet with basic blocks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BackboneConfig {
    /// Output channels of the stem (7x7/2 conv).
    pub stem_width: usize,
    /// Blocks per stage (ResNet-34: 3, 4, 6, 3).
    pub blocks: Vec<usize>,
    /// Output channels per stage (ResNet-34: 64, 128, 256, 512).
    pub widths: Vec<usize>,
    /// Stride of each stage's first block (ResNet: 1, 2, 2, 2; the stem adds 4).
    pub strides: Vec<usize>,
}

impl BackboneConfig {
    /// Whether this trunk is `shallower` with at least as many blocks in every stage and
    /// nothing else changed (stem width, stage widths and strides), every stage of `shallower`
    /// having a block: the growth [`super::backbone::Backbone::deepened`] makes.
    pub fn deepens(&self, shallower: &BackboneConfig) -> bool {
        self.stem_width == shallower.stem_width
            && self.widths == shallower.widths
            && self.strides == shallower.strides
            && self.blocks.len() == shallower.blocks.len()
            && self
                .blocks
                .iter()
                .zip(&shallower.blocks)
                .all(|(&more, &fewer)| fewer > 0 && more >= fewer)
    }
}

/// The BEV grid and its encoder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BevConfig {
    /// Cells and the ego-frame area they cover (stored flat: rows, cols, x_min, ...).
    #[serde(flatten)]
    pub grid: BevGrid,
    /// Heights above the ground of the pillar points lifted from every cell, metres.
    pub pillar_heights: Vec<f32>,
    /// Encoder layers (each TSA, SCA and FFN).
    pub layers: usize,
    /// Attention heads of temporal and spatial attention (must divide `channels`).
    pub heads: usize,
    /// Sampling points per head in spatial cross-attention (split evenly over the pillar heights).
    pub spatial_points: usize,
    /// Sampling points per head and queue slot in temporal self-attention.
    pub temporal_points: usize,
    /// Hidden width of each encoder layer's feed-forward network.
    pub ffn_dim: usize,
}

/// Scenes TokenLearner and the self-attention over the scene tokens.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TokenConfig {
    /// Ablation "no STL": no navigation gate, TokenLearner or token self-attention; the head
    /// and the FFP attend over every BEV cell (with its position), and `num_tokens`,
    /// `bottleneck` and `layers` are unused.
    #[serde(default)]
    pub dense_bev: bool,
    /// Whether the navigation gate reads the target point beside the command (SSR does);
    /// `false` is the ablation "gate from the command only".
    #[serde(default = "gate_target_point_default")]
    pub gate_target_point: bool,
    /// Scene tokens TokenLearner produces.
    pub num_tokens: usize,
    /// Hidden width of TokenLearner's MLP.
    pub bottleneck: usize,
    /// Self-attention layers over the scene tokens.
    pub layers: usize,
    /// Attention heads of those layers and of the FFP's world model (must divide `channels`).
    pub heads: usize,
    /// Hidden width of their feed-forward networks (and of the FFP's world model's).
    pub ffn_dim: usize,
}

/// TCP head.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeadConfig {
    /// Width of the measurement encoder (speed, target point, command).
    pub measurement_dim: usize,
    /// Width of the hidden layers of the head's MLPs (speed, join, attention, merge).
    pub hidden_dim: usize,
    /// Width of the GRU states (trajectory and control branches).
    pub state_dim: usize,
    /// Waypoints (and future control steps) predicted, 0.5 s apart.
    pub pred_len: usize,
}

/// Future Feature Predictor (training only).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FfpConfig {
    /// Self-attention layers of the latent world model.
    pub layers: usize,
    /// TokenFuser's expansion of the scene tokens (64 in SSR).
    pub fuser_slots: usize,
}

/// The largest model config file read, bytes.
const MAX_CONFIG_BYTES: u64 = 1 << 20;
/// The widest layer a config may ask for (channels, hidden widths).
const MAX_WIDTH: usize = 8192;
/// The most layers of one kind.
const MAX_LAYERS: usize = 64;
/// The most sampling points per head.
const MAX_POINTS: usize = 256;
/// The most scene tokens (and TokenFuser slots).
const MAX_TOKENS: usize = 1024;
/// The most weights a config may ask for, counting the largest groups (4 GB of f32; the
/// paper preset's come to 27 million).
const MAX_WEIGHTS: usize = 1_000_000_000;

/// A configuration that cannot build a network.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("model config '{name}': {problem}")]
pub struct ConfigError {
    /// The config's name, or the preset name or path it was loaded from.
    pub name: String,
    /// What does not fit, naming the field.
    pub problem: String,
}

impl SsrConfig {
    /// The speed the network is shown: `speed` with ego status on, `None` without.
    pub fn shown_speed(&self, speed: f32) -> Option<f32> {
        self.ego_status.then_some(speed)
    }

    /// The preset names [`SsrConfig::preset`] knows.
    pub const PRESETS: [&'static str; 2] = ["cpu-default", "paper"];

    /// A preset by name.
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "paper" => Some(Self::paper()),
            "cpu-default" => Some(Self::cpu_default()),
            _ => None,
        }
    }

    /// A preset name or the path of a JSON config file, validated.
    pub fn from_name_or_file(spec: &str) -> Result<Self, ConfigError> {
        let config = match Self::preset(spec) {
            Some(config) => config,
            None => {
                let fail = |problem: String| ConfigError {
                    name: spec.to_string(),
                    problem,
                };
                let text = read_capped_text(Path::new(spec), MAX_CONFIG_BYTES).map_err(|e| {
                    fail(format!(
                        "neither a preset ({}) nor a readable file: {e}",
                        Self::PRESETS.join(", ")
                    ))
                })?;
                serde_json::from_str(&text).map_err(|e| fail(format!("not a model config: {e}")))?
            }
        };
        config.validate()?;
        Ok(config)
    }

    /// The fields (dotted paths, like `tokens.num_tokens`) where `other` differs from this
    /// config, each with both values; empty when they are equal.
    pub fn differences(&self, other: &Self) -> Vec<String> {
        fn walk(path: String, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
            match (a, b) {
                (serde_json::Value::Object(a), serde_json::Value::Object(b)) => {
                    for (key, value) in a {
                        let inner = if path.is_empty() {
                            key.clone()
                        } else {
                            format!("{path}.{key}")
                        };
                        walk(inner, value, &b[key], out);
                    }
                }
                _ if a != b => out.push(format!("{path}: {a} vs {b}")),
                _ => {}
            }
        }
        let json = |c: &Self| serde_json::to_value(c).expect("configs serialise");
        let mut out = Vec::new();
        walk(String::new(), &json(self), &json(other), &mut out);
        out
    }

    /// SSR's closed-loop setting: ResNet-34 on TCP's 900x256 camera, 256 channels, a 100x100
    /// BEV (0.6 m cells, 15 m behind to 45 m ahead), 3 encoder layers, 16 tokens, TCP head.
    pub fn paper() -> Self {
        Self {
            name: "paper".into(),
            image_width: 900,
            image_height: 256,
            backbone: BackboneConfig {
                stem_width: 64,
                blocks: vec![3, 4, 6, 3],
                widths: vec![64, 128, 256, 512],
                strides: vec![1, 2, 2, 2],
            },
            channels: 256,
            bev: BevConfig {
                grid: BevGrid {
                    rows: 100,
                    cols: 100,
                    x_min: -15.0,
                    x_max: 45.0,
                    y_min: -30.0,
                    y_max: 30.0,
                },
                pillar_heights: vec![0.5, 1.5, 2.5, 3.5],
                layers: 3,
                heads: 8,
                spatial_points: 8,
                temporal_points: 4,
                ffn_dim: 512,
            },
            tokens: TokenConfig {
                dense_bev: false,
                gate_target_point: true,
                num_tokens: 16,
                bottleneck: 64,
                layers: 3,
                heads: 8,
                ffn_dim: 512,
            },
            head: HeadConfig {
                measurement_dim: 128,
                hidden_dim: 512,
                state_dim: 256,
                pred_len: 4,
            },
            ffp: FfpConfig {
                layers: 2,
                fuser_slots: 64,
            },
            ego_status: false,
            occupancy_head: true,
            hazard_head: true,
            motion_head: false,
            light_head: false,
        }
    }

    /// The CPU default: every part of [`SsrConfig::paper`], narrower, on a 320x96 image and a
    /// 32x32 BEV of 1.5 m cells, with one sampling point per pillar height in spatial
    /// cross-attention and two per slot in temporal self-attention (chosen with
    /// `ssr-agent bench`: sampling dominates the BEV encoder on a CPU). It plans 6 waypoints
    /// (3 s) so open-loop L2 can be measured at 1, 2 and 3 s; the controller reads the first 4
    /// as TCP does.
    pub fn cpu_default() -> Self {
        Self {
            name: "cpu-default".into(),
            image_width: 320,
            image_height: 96,
            backbone: BackboneConfig {
                stem_width: 16,
                blocks: vec![1, 1, 2, 1],
                widths: vec![16, 32, 64, 128],
                strides: vec![1, 2, 2, 1],
            },
            channels: 64,
            bev: BevConfig {
                grid: BevGrid {
                    rows: 32,
                    cols: 32,
                    x_min: -8.0,
                    x_max: 40.0,
                    y_min: -24.0,
                    y_max: 24.0,
                },
                pillar_heights: vec![0.5, 1.5, 2.5, 3.5],
                layers: 2,
                heads: 4,
                spatial_points: 4,
                temporal_points: 2,
                ffn_dim: 128,
            },
            tokens: TokenConfig {
                dense_bev: false,
                gate_target_point: true,
                num_tokens: 16,
                bottleneck: 32,
                layers: 2,
                heads: 4,
                ffn_dim: 128,
            },
            head: HeadConfig {
                measurement_dim: 64,
                hidden_dim: 128,
                state_dim: 128,
                pred_len: 6,
            },
            ffp: FfpConfig {
                layers: 2,
                fuser_slots: 32,
            },
            ego_status: false,
            occupancy_head: true,
            hazard_head: true,
            motion_head: false,
            light_head: false,
        }
    }

    /// Number of tokens the head and the FFP attend over: the scene tokens, or every BEV cell
    /// in the "no STL" ablation.
    pub fn scene_tokens(&self) -> usize {
        if self.tokens.dense_bev {
            self.bev.grid.cells()
        } else {
            self.tokens.num_tokens
        }
    }

    /// Feature map size (height, width) for the configured input.
    pub fn feature_size(&self) -> (usize, usize) {
        let mut h = self.image_height;
        let mut w = self.image_width;
        // Stem: 7x7/2 conv then 3x3/2 max-pool, both padded; then each stage's stride (3x3, pad 1).
        for stride in [2, 2]
            .into_iter()
            .chain(self.backbone.strides.iter().copied())
        {
            h = (h - 1) / stride + 1;
            w = (w - 1) / stride + 1;
        }
        (h, w)
    }

    /// Checks that every size fits together; the message names the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.check_sizes()
            .and_then(|()| self.check_geometry())
            .and_then(|()| self.check_attention())
            .map_err(|problem| ConfigError {
                name: self.name.clone(),
                problem,
            })
    }

    /// Every count and width within what a real network of this kind uses, and their product
    /// (the weights) bounded: a checkpoint's config is untrusted, and `init` allocates what it
    /// asks for before a weight is compared.
    fn check_sizes(&self) -> Result<(), String> {
        let b = &self.backbone;
        if b.blocks.is_empty()
            || b.blocks.len() != b.widths.len()
            || b.blocks.len() != b.strides.len()
        {
            return Err(
                "backbone.blocks, widths and strides must be non-empty and equally long".into(),
            );
        }
        let v = &self.bev;
        let t = &self.tokens;
        let h = &self.head;
        let sizes = [
            ("backbone stages", b.blocks.len(), 1, 8),
            ("backbone.stem_width", b.stem_width, 1, MAX_WIDTH),
            ("channels", self.channels, 2, MAX_WIDTH),
            ("bev.pillar_heights (count)", v.pillar_heights.len(), 1, 64),
            ("bev.layers", v.layers, 1, MAX_LAYERS),
            ("bev.spatial_points", v.spatial_points, 1, MAX_POINTS),
            ("bev.temporal_points", v.temporal_points, 1, MAX_POINTS),
            ("bev.ffn_dim", v.ffn_dim, 1, MAX_WIDTH),
            ("tokens.num_tokens", t.num_tokens, 1, MAX_TOKENS),
            ("tokens.bottleneck", t.bottleneck, 1, MAX_WIDTH),
            ("tokens.layers", t.layers, 0, MAX_LAYERS),
            ("tokens.ffn_dim", t.ffn_dim, 1, MAX_WIDTH),
            ("head.measurement_dim", h.measurement_dim, 1, MAX_WIDTH),
            ("head.hidden_dim", h.hidden_dim, 1, MAX_WIDTH),
            ("head.state_dim", h.state_dim, 1, MAX_WIDTH),
            ("ffp.layers", self.ffp.layers, 0, MAX_LAYERS),
            ("ffp.fuser_slots", self.ffp.fuser_slots, 1, MAX_TOKENS),
        ];
        let stages = b.blocks.iter().map(|&n| ("backbone.blocks", n, 1, 64));
        let widths = b
            .widths
            .iter()
            .map(|&n| ("backbone.widths", n, 1, MAX_WIDTH));
        if let Some(out) = first_outside(sizes.into_iter().chain(stages).chain(widths)) {
            return Err(out.to_string());
        }
        // Each size may be sane and their product not: bound the largest weight groups (the
        // backbone's 3x3 convolutions, the attention layers' projections and FFNs).
        let backbone: usize = (b.blocks.iter().zip(&b.widths))
            .map(|(&n, &w)| n * 18 * w * w)
            .sum();
        let c = self.channels;
        let attention_layers = v.layers + t.layers + self.ffp.layers;
        let layer = 4 * c * c + 2 * c * v.ffn_dim.max(t.ffn_dim);
        let weights = backbone + attention_layers * layer;
        if weights > MAX_WEIGHTS {
            return Err(format!(
                "about {weights} weights, over the {MAX_WEIGHTS} a config may ask for"
            ));
        }
        if b.strides.iter().any(|s| !(1..=2).contains(s)) {
            return Err("backbone strides must be 1 or 2".into());
        }
        Ok(())
    }

    /// The image, the BEV grid and its pillars: sizes in range, numbers finite.
    fn check_geometry(&self) -> Result<(), String> {
        if self.image_width < 32
            || self.image_height < 32
            || self.image_width > 4096
            || self.image_height > 4096
        {
            return Err(format!(
                "image {}x{} is outside 32..4096 px per side",
                self.image_width, self.image_height
            ));
        }
        let g = &self.bev.grid;
        if g.rows == 0 || g.cols == 0 || g.cells() > 40_000 {
            return Err(format!(
                "bev {}x{} must have 1..40000 cells",
                g.rows, g.cols
            ));
        }
        let ranges = [g.x_min, g.x_max, g.y_min, g.y_max];
        if !(ranges.iter().all(|r| r.is_finite()) && g.x_min < g.x_max && g.y_min < g.y_max) {
            return Err("bev ranges must be finite with x_min < x_max and y_min < y_max".into());
        }
        if !self.bev.pillar_heights.iter().all(|z| z.is_finite()) {
            return Err("beself.bev.pillar_heights must be finite".into());
        }
        if !self
            .bev
            .spatial_points
            .is_multiple_of(self.bev.pillar_heights.len())
        {
            return Err(
                "beself.bev.spatial_points must be a multiple of the number of pillar heights"
                    .into(),
            );
        }
        Ok(())
    }

    /// Attention heads that divide the channels, channels even, a horizon the head can plan.
    fn check_attention(&self) -> Result<(), String> {
        for (what, heads, dim) in [
            ("bev.heads", self.bev.heads, self.channels),
            ("tokens.heads", self.tokens.heads, self.channels),
        ] {
            if heads == 0 || dim % heads != 0 {
                return Err(format!("{what} = {heads} must divide channels = {dim}"));
            }
        }
        if !self.channels.is_multiple_of(2) {
            return Err(
                "channels must be even (half for rows, half for columns in the BEV position)"
                    .into(),
            );
        }
        if self.head.pred_len < 2 || self.head.pred_len > 12 {
            return Err("head.pred_len must be in 2..=12".into());
        }
        Ok(())
    }
}
