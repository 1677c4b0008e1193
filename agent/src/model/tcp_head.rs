//! TCP head driven by the scene tokens (Wu et al. 2022, with SSR's tokens in place of TCP's CNN
//! features):
//! - a measurement encoder of [speed / 12, target point, 6-way command one-hot];
//! - the trajectory branch: an MLP over [mean scene token, measurements] initialises a GRU cell
//!   that, fed [current waypoint, target point], emits cumulative waypoints 0.5 s apart;
//! - the control branch: attention over the scene tokens from the measurements, an MLP, and a
//!   policy head giving Beta(alpha, beta) for [acceleration, steer]; then multi-step prediction
//!   where each future step attends over the tokens guided by the trajectory GRU's state;
//! - an auxiliary speed head.
//!
//! Waypoints are in the ego frame (x forward, y left, metres).

use burn::module::Module;
use burn::nn::{Gru, GruConfig};
use burn::tensor::activation::{relu, softmax, softplus};
use burn::tensor::{Device, Tensor};
use ssrdrive_proto::command::COMMANDS;

use super::config::SsrConfig;
use super::fused::FusedLinear;
use super::init::xavier_linear;

/// Speed is divided by this (m/s) where it enters the network, as TCP does.
pub const SPEED_SCALE: f32 = 12.0;
/// Added to the softplus outputs so Beta parameters stay positive.
const BETA_FLOOR: f32 = 1e-3;

/// Linear layers with ReLU after each.
#[derive(Module, Debug)]
struct Mlp {
    layers: Vec<FusedLinear>,
}

impl Mlp {
    fn new(widths: &[usize], device: &Device) -> Self {
        Self {
            layers: widths
                .windows(2)
                .map(|w| xavier_linear(w[0], w[1], device))
                .collect(),
        }
    }

    fn forward(&self, mut x: Tensor<2>) -> Tensor<2> {
        for layer in &self.layers {
            x = relu(layer.forward(x));
        }
        x
    }
}

/// Policy trunk and Beta parameter heads.
#[derive(Module, Debug)]
struct BetaPolicy {
    trunk: Mlp,
    alpha: FusedLinear,
    beta: FusedLinear,
}

impl BetaPolicy {
    fn new(width: usize, device: &Device) -> Self {
        Self {
            trunk: Mlp::new(&[width, width, width], device),
            alpha: xavier_linear(width, 2, device),
            beta: xavier_linear(width, 2, device),
        }
    }

    fn forward(&self, x: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let h = self.trunk.forward(x);
        (
            softplus(self.alpha.forward(h.clone()), 1.0).add_scalar(BETA_FLOOR),
            softplus(self.beta.forward(h), 1.0).add_scalar(BETA_FLOOR),
        )
    }
}

/// The head's outputs.
#[derive(Debug, Clone)]
pub struct HeadOutput {
    /// `[B, P, 2]` cumulative waypoints, ego frame.
    pub waypoints: Tensor<3>,
    /// `[B, 2]` Beta alpha parameters of [acceleration, steer] for the current step.
    pub alpha: Tensor<2>,
    /// `[B, 2]` Beta beta parameters of [acceleration, steer] for the current step.
    pub beta: Tensor<2>,
    /// `[B, P, 2]` Beta alpha parameters of the future control steps (training targets only).
    pub future_alpha: Tensor<3>,
    /// `[B, P, 2]` Beta beta parameters of the future control steps (training targets only).
    pub future_beta: Tensor<3>,
    /// `[B, 1]` predicted speed / 12.
    pub speed: Tensor<2>,
    /// `[B, S]` the control branch's attention over the scene tokens.
    pub control_attention: Tensor<2>,
}

/// TCP's head: a measurement encoder, a GRU trajectory branch and a control branch with
/// guided attention over the scene tokens, plus a speed prediction.
#[derive(Module, Debug)]
pub struct TcpHead {
    measurements: Mlp,
    speed: Mlp,
    speed_out: FusedLinear,
    join_trajectory: Mlp,
    trajectory_gru: Gru,
    waypoint_out: FusedLinear,
    initial_attention: Mlp,
    initial_attention_out: FusedLinear,
    join_control: Mlp,
    policy: BetaPolicy,
    control_gru: Gru,
    guided_attention: Mlp,
    guided_attention_out: FusedLinear,
    merge: Mlp,
    merge_out: FusedLinear,
    step: Mlp,
    pred_len: usize,
}

fn gru_step(gru: &Gru, input: Tensor<2>, state: Tensor<2>) -> Tensor<2> {
    let [b, h] = state.dims();
    gru.forward(input.unsqueeze_dim::<3>(1), Some(state))
        .reshape([b, h])
}

/// Attention-weighted mean of the tokens: `weights` `[B, S]`, `tokens` `[B, S, C]` to `[B, C]`.
fn pool(weights: Tensor<2>, tokens: Tensor<3>) -> Tensor<2> {
    let [b, _, c] = tokens.dims();
    weights.unsqueeze_dim::<3>(1).matmul(tokens).reshape([b, c])
}

impl TcpHead {
    /// A randomly initialised head for `config.head` over `config.scene_tokens()` tokens.
    pub fn new(config: &SsrConfig, device: &Device) -> Self {
        let c = config.channels;
        let h = &config.head;
        let (m, hid, state) = (h.measurement_dim, h.hidden_dim, h.state_dim);
        let tokens = config.scene_tokens();
        Self {
            measurements: Mlp::new(&[3 + COMMANDS, m, m], device),
            speed: Mlp::new(&[c, hid, hid], device),
            speed_out: xavier_linear(hid, 1, device),
            join_trajectory: Mlp::new(&[c + m, hid, hid, state], device),
            trajectory_gru: GruConfig::new(4, state, true).init(device),
            waypoint_out: xavier_linear(state, 2, device),
            initial_attention: Mlp::new(&[m, hid], device),
            initial_attention_out: xavier_linear(hid, tokens, device),
            join_control: Mlp::new(&[c + m, hid, hid, state], device),
            policy: BetaPolicy::new(state, device),
            control_gru: GruConfig::new(state + 4, state, true).init(device),
            guided_attention: Mlp::new(&[2 * state, hid], device),
            guided_attention_out: xavier_linear(hid, tokens, device),
            merge: Mlp::new(&[state + c, hid], device),
            merge_out: xavier_linear(hid, state, device),
            step: Mlp::new(&[state, state, state], device),
            pred_len: h.pred_len,
        }
    }

    /// `tokens` `[B, S, C]`, `speed` `[B, 1]` m/s, `target_point` `[B, 2]`, `command` `[B, 6]`.
    pub fn forward(
        &self,
        tokens: Tensor<3>,
        speed: Tensor<2>,
        target_point: Tensor<2>,
        command: Tensor<2>,
    ) -> HeadOutput {
        let [b, _, _] = tokens.dims();
        let device = tokens.device();
        let measurements = self.measurements.forward(Tensor::cat(
            vec![speed.div_scalar(SPEED_SCALE), target_point.clone(), command],
            1,
        ));
        let global = tokens.clone().mean_dim(1).reshape([b, tokens.dims()[2]]);
        let predicted_speed = self.speed_out.forward(self.speed.forward(global.clone()));

        // Trajectory branch.
        let mut hidden = self
            .join_trajectory
            .forward(Tensor::cat(vec![global, measurements.clone()], 1));
        let mut position = Tensor::<2>::zeros([b, 2], &device);
        let mut waypoints = Vec::with_capacity(self.pred_len);
        let mut trajectory_states = Vec::with_capacity(self.pred_len);
        for _ in 0..self.pred_len {
            hidden = gru_step(
                &self.trajectory_gru,
                Tensor::cat(vec![position.clone(), target_point.clone()], 1),
                hidden,
            );
            position = position + self.waypoint_out.forward(hidden.clone());
            waypoints.push(position.clone());
            trajectory_states.push(hidden.clone());
        }

        // Control branch: current step.
        let attention = softmax(
            self.initial_attention_out
                .forward(self.initial_attention.forward(measurements.clone())),
            1,
        );
        let pooled = pool(attention.clone(), tokens.clone());
        let mut feature = self
            .join_control
            .forward(Tensor::cat(vec![pooled, measurements], 1));
        let (alpha, beta) = self.policy.forward(feature.clone());

        // Multi-step control, guided by the trajectory states.
        let (mut step_alpha, mut step_beta) = (alpha.clone(), beta.clone());
        let mut state = Tensor::<2>::zeros(feature.dims(), &device);
        let (mut future_alpha, mut future_beta) = (Vec::new(), Vec::new());
        for trajectory_state in trajectory_states {
            state = gru_step(
                &self.control_gru,
                Tensor::cat(vec![feature.clone(), step_alpha, step_beta], 1),
                state,
            );
            let guide = softmax(
                self.guided_attention_out.forward(
                    self.guided_attention
                        .forward(Tensor::cat(vec![state.clone(), trajectory_state], 1)),
                ),
                1,
            );
            let merged = self.merge_out.forward(self.merge.forward(Tensor::cat(
                vec![state.clone(), pool(guide, tokens.clone())],
                1,
            )));
            feature = feature + self.step.forward(merged);
            (step_alpha, step_beta) = self.policy.forward(feature.clone());
            future_alpha.push(step_alpha.clone());
            future_beta.push(step_beta.clone());
        }

        HeadOutput {
            waypoints: Tensor::stack(waypoints, 1),
            alpha,
            beta,
            future_alpha: Tensor::stack(future_alpha, 1),
            future_beta: Tensor::stack(future_beta, 1),
            speed: predicted_speed,
            control_attention: attention,
        }
    }
}
