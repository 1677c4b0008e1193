//! What one forward pass of a group of episodes produced, read back from the device once, and a
//! typed view of each episode's share: its planned path, control-branch parameters, predicted
//! speed, and the optional heads' beliefs (token attention, occupancy and motion probabilities,
//! hazard and light probabilities), each present only where the group asked for it.

use burn::tensor::Tensor;
use burn::tensor::activation::sigmoid;

use crate::control::LightBelief;
use crate::model::bev::BevGrid;
use crate::model::classifier::{TokenClassifier, class_probabilities};
use crate::model::hazard::Hazard;
use crate::model::light::LightClass;
use crate::model::occupancy::OCCUPANCY_CHANNELS;
use crate::model::stl::SceneTokens;
use crate::model::tcp_head::{HeadOutput, SPEED_SCALE};
use crate::model::{SsrModel, float_values};

/// Which optional outputs a group needs (a head runs only when some episode reads it).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Needs {
    /// Token attention and occupancy for debug outputs.
    pub debug: bool,
    /// Occupancy for the safety stop.
    pub occupancy: bool,
    /// Motion for the safety stop's motion rule.
    pub motion: bool,
    /// Hazard and light probabilities for the unstick rule (and debug outputs).
    pub hazard: bool,
}

/// A group's outputs as host values, row-major over its B episodes.
pub(super) struct GroupOutputs {
    pred_len: usize,
    tokens: usize,
    cells: usize,
    /// `[B, pred_len, 2]`.
    waypoints: Vec<f32>,
    /// `[B, 2]` each.
    alpha: Vec<f32>,
    beta: Vec<f32>,
    /// `[B]`, in the head's units.
    speed: Vec<f32>,
    /// `[B, tokens, Q]`, where asked for and the network has STL.
    attention: Option<Vec<f32>>,
    /// `[B, Q, channels]` probabilities, where asked for and the network has the head.
    occupancy: Option<Vec<f32>>,
    motion: Option<Vec<f32>>,
    /// Per episode, the hazard classes' probabilities.
    hazards: Option<Vec<[f32; HAZARDS]>>,
    /// Per episode, the light classes' probabilities.
    lights: Option<Vec<[f32; LIGHTS]>>,
}

/// The hazard head's classes.
const HAZARDS: usize = Hazard::ALL.len();
/// The light head's classes.
const LIGHTS: usize = LightClass::ALL.len();

/// One episode's share of a [`GroupOutputs`].
pub(super) struct EpisodeOutputs<'a> {
    /// Planned waypoints, ego frame, 0.5 s apart.
    pub path: Vec<[f32; 2]>,
    /// Control-branch Beta parameters for [acceleration, steer].
    pub alpha: [f32; 2],
    pub beta: [f32; 2],
    /// The speed head's prediction, m/s.
    pub predicted_speed: f32,
    /// `[tokens][Q]` attention maps.
    pub attention: Option<Vec<Vec<f32>>>,
    /// `[Q * channels]` occupancy and motion probabilities, cell-major.
    pub occupancy: Option<&'a [f32]>,
    pub motion: Option<&'a [f32]>,
    /// The hazard classes' probabilities.
    pub hazards: Option<&'a [f32; HAZARDS]>,
    /// The light classes' probabilities.
    pub lights: Option<&'a [f32; LIGHTS]>,
}

impl GroupOutputs {
    /// Reads the head's outputs and runs the optional heads `needs` asks for on the planning
    /// `bev` (`[B, Q, C]`) and the `scene` tokens.
    pub fn read(
        model: &SsrModel,
        grid: &BevGrid,
        bev: &Tensor<3>,
        scene: &SceneTokens,
        head: &HeadOutput,
        needs: Needs,
    ) -> Self {
        let cells_of = |head: &crate::model::occupancy::OccupancyHead| {
            float_values(sigmoid(head.forward(bev.clone())))
        };
        let attention = scene.attention.clone().filter(|_| needs.debug);

        Self {
            pred_len: head.waypoints.dims()[1],
            tokens: attention.as_ref().map_or(0, |a| a.dims()[1]),
            cells: grid.cells(),
            waypoints: float_values(head.waypoints.clone()),
            alpha: float_values(head.alpha.clone()),
            beta: float_values(head.beta.clone()),
            speed: float_values(head.speed.clone()),
            attention: attention.map(float_values),
            occupancy: model
                .occupancy
                .as_ref()
                .filter(|_| needs.debug || needs.occupancy)
                .map(cells_of),
            motion: model.motion.as_ref().filter(|_| needs.motion).map(cells_of),
            hazards: classes(model.hazard.as_ref(), needs.hazard || needs.debug, scene),
            lights: classes(model.light.as_ref(), needs.hazard || needs.debug, scene),
        }
    }

    /// Episode `i`'s share.
    pub fn episode(&self, i: usize) -> EpisodeOutputs<'_> {
        let (p, q, k) = (self.pred_len, self.cells, OCCUPANCY_CHANNELS.len());
        let pair = |v: &[f32]| [v[2 * i], v[2 * i + 1]];
        EpisodeOutputs {
            path: self.waypoints[i * p * 2..(i + 1) * p * 2]
                .chunks_exact(2)
                .map(|w| [w[0], w[1]])
                .collect(),
            alpha: pair(&self.alpha),
            beta: pair(&self.beta),
            predicted_speed: self.speed[i] * SPEED_SCALE,
            attention: self.attention.as_ref().map(|maps| {
                maps[i * self.tokens * q..(i + 1) * self.tokens * q]
                    .chunks_exact(q)
                    .map(<[f32]>::to_vec)
                    .collect()
            }),
            occupancy: self
                .occupancy
                .as_ref()
                .map(|p| &p[i * q * k..(i + 1) * q * k]),
            motion: self.motion.as_ref().map(|p| &p[i * q * k..(i + 1) * q * k]),
            hazards: self.hazards.as_ref().map(|h| &h[i]),
            lights: self.lights.as_ref().map(|l| &l[i]),
        }
    }
}

impl EpisodeOutputs<'_> {
    /// The hazard head's probability of `hazard`, where it ran.
    pub fn hazard(&self, hazard: Hazard) -> Option<f32> {
        self.hazards.map(|p| p[hazard.index()])
    }

    /// The light head's belief, where it ran.
    pub fn light(&self) -> Option<LightBelief> {
        self.lights.map(|p| LightBelief {
            green: p[LightClass::Green.index()],
            stop: p[LightClass::Red.index()] + p[LightClass::Yellow.index()],
        })
    }

    /// `[channels][Q]` occupancy probabilities for debug outputs (empty without them).
    pub fn occupancy_maps(&self) -> Vec<Vec<f32>> {
        let k = OCCUPANCY_CHANNELS.len();
        self.occupancy.map_or_else(Vec::new, |cells| {
            (0..k)
                .map(|c| cells.iter().skip(c).step_by(k).copied().collect())
                .collect()
        })
    }
}

/// Each episode's class probabilities from a token classifier `head`, where the network has
/// it and the group needs it.
fn classes<const K: usize>(
    head: Option<&TokenClassifier>,
    needed: bool,
    scene: &SceneTokens,
) -> Option<Vec<[f32; K]>> {
    head.filter(|_| needed)
        .map(|head| class_probabilities(&float_values(head.forward(scene.tokens.clone()))))
}

/// The ego-frame centres of the cells of `grid` where some channel of `probabilities`
/// (`[Q * channels]`, cell-major) is at least `threshold`.
pub(super) fn occupied_cells(
    probabilities: &[f32],
    grid: &BevGrid,
    threshold: f32,
) -> Vec<[f32; 2]> {
    let k = OCCUPANCY_CHANNELS.len();
    probabilities
        .chunks_exact(k)
        .enumerate()
        .filter(|(_, cell)| cell.iter().any(|&p| p >= threshold))
        .map(|(cell, _)| grid.cell_centre(cell))
        .collect()
}
