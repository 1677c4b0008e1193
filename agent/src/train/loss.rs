//! Losses: TCP's imitation terms over the head's outputs and SSR's future-BEV reconstruction.
//!
//! - waypoints: L1 to the expert's future positions (ego frame);
//! - action and future actions: KL(expert || prediction) of Beta distributions over
//!   [acceleration, steer], TCP's direction. Our expert acts deterministically, so its action
//!   x in [-1, 1] becomes Beta(1 + k v, 1 + k (1 - v)) with v = (x + 1) / 2 (mode v,
//!   concentration k = [`LossWeights::target_concentration`]);
//! - speed: L1 of the speed head to speed / 12;
//! - BEV: MSE of the FFP's predicted BEV to the detached BEV of the future frame;
//! - hazard: cross-entropy of the hazard head ([`super::hazard`]) to what the expert brakes
//!   for;
//! - occupancy: balanced binary cross-entropy of the occupancy head ([`super::occupancy`]) to
//!   the cells road users cover.

use burn::tensor::{Device, Tensor};

use super::gamma::{digamma, ln_gamma, ln_gamma_f64};
use crate::model::float_tensor;
use crate::model::tcp_head::{HeadOutput, SPEED_SCALE};

/// Term weights; defaults follow TCP (speed 0.05) and SSR (BEV 1), plus the auxiliary outputs'.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LossWeights {
    /// Weight of the waypoint L1.
    pub waypoints: f32,
    /// Weight of the current action's Beta KL.
    pub action: f32,
    /// Weight of the future actions' Beta KL.
    pub future_action: f32,
    /// Weight of the speed L1.
    pub speed: f32,
    /// Weight of the future-BEV MSE.
    pub bev: f32,
    /// Weight of the hazard head's cross-entropy; 0 = no head (runs from before it existed).
    #[serde(default)]
    pub hazard: f32,
    /// Weight of the occupancy head's cross-entropy; 0 = no head (runs from before it
    /// existed).
    #[serde(default)]
    pub occupancy: f32,
    /// Weight of the motion head's cross-entropy (where the road users will be); 0 = no head.
    #[serde(default)]
    pub motion: f32,
    /// Weight of the light head's cross-entropy (the state of the light ahead); 0 = no head.
    #[serde(default)]
    pub light: f32,
    /// Concentration k of the Beta targets made from the expert's deterministic actions.
    pub target_concentration: f32,
}

impl Default for LossWeights {
    fn default() -> Self {
        Self {
            waypoints: 1.0,
            action: 1.0,
            future_action: 1.0,
            speed: 0.05,
            bev: 1.0,
            hazard: 0.5,
            occupancy: 1.0,
            motion: 0.0,
            light: 0.0,
            target_concentration: 10.0,
        }
    }
}

/// Expert labels of a batch.
#[derive(Debug, Clone)]
pub struct ImitationTargets {
    /// `[B, P, 2]` future ego positions in the current ego frame.
    pub waypoints: Tensor<3>,
    /// `[B, P + 1, 2]` expert [acceleration, steer] in [-1, 1], now and at each future step,
    /// as Beta targets.
    pub actions: BetaTargets,
    /// `[B, 1]` m/s.
    pub speed: Tensor<2>,
}

/// Beta targets prepared on the CPU: KL(target || pred) = ln B(pred) + a_pred * ca + b_pred * cb + c0.
#[derive(Debug, Clone)]
pub struct BetaTargets {
    ca: Tensor<3>,
    cb: Tensor<3>,
    c0: Tensor<3>,
}

impl BetaTargets {
    /// `actions` `[B][steps][2]` flattened row-major, values in [-1, 1].
    pub fn new(
        actions: &[f32],
        batch: usize,
        steps: usize,
        concentration: f32,
        device: &Device,
    ) -> Self {
        assert_eq!(
            actions.len(),
            batch * steps * 2,
            "actions must be [batch, steps, 2]"
        );
        let k = concentration as f64;
        let (mut ca, mut cb, mut c0) = (Vec::new(), Vec::new(), Vec::new());
        for &x in actions {
            let v = ((x.clamp(-1.0, 1.0) as f64) + 1.0) / 2.0;
            let (a, b) = (1.0 + k * v, 1.0 + k * (1.0 - v));
            let (pa, pb, ps) = (digamma(a), digamma(b), digamma(a + b));
            let ln_beta = ln_gamma_f64(a) + ln_gamma_f64(b) - ln_gamma_f64(a + b);
            ca.push((ps - pa) as f32);
            cb.push((ps - pb) as f32);
            c0.push((-ln_beta + a * pa + b * pb - (a + b) * ps) as f32);
        }
        let shape = [batch, steps, 2];
        Self {
            ca: float_tensor(ca, shape, device),
            cb: float_tensor(cb, shape, device),
            c0: float_tensor(c0, shape, device),
        }
    }

    /// Mean KL(target || Beta(alpha, beta)) over the given steps, `alpha`/`beta` `[B, S, 2]`.
    fn kl(&self, alpha: Tensor<3>, beta: Tensor<3>, first_step: usize) -> Tensor<1> {
        let steps = alpha.dims()[1];
        let pick = |t: &Tensor<3>| t.clone().narrow(1, first_step, steps);
        let ln_b = ln_gamma(alpha.clone()) + ln_gamma(beta.clone())
            - ln_gamma(alpha.clone() + beta.clone());
        (ln_b + alpha * pick(&self.ca) + beta * pick(&self.cb) + pick(&self.c0)).mean()
    }
}

/// The terms of one batch's loss.
#[derive(Debug, Clone)]
pub struct Losses {
    /// Weighted sum of the terms (the BEV term only when present).
    pub total: Tensor<1>,
    /// Waypoint L1, m (mean over coordinates).
    pub waypoints: Tensor<1>,
    /// Beta KL of the current action.
    pub action: Tensor<1>,
    /// Beta KL of the future actions.
    pub future_action: Tensor<1>,
    /// Speed L1, in units of speed / 12.
    pub speed: Tensor<1>,
    /// Future-BEV MSE; `None` without an FFP prediction.
    pub bev: Option<Tensor<1>>,
    /// Hazard cross-entropy; `None` without a hazard head.
    pub hazard: Option<Tensor<1>>,
    /// Occupancy cross-entropy; `None` without an occupancy head.
    pub occupancy: Option<Tensor<1>>,
    /// Motion cross-entropy; `None` without a motion head.
    pub motion: Option<Tensor<1>>,
    /// Light cross-entropy; `None` without a light head.
    pub light: Option<Tensor<1>>,
}

/// The auxiliary losses on a batch (hazard, occupancy and motion heads), each `None` without
/// its output.
#[derive(Debug, Clone, Default)]
pub struct AuxiliaryLosses {
    /// The hazard head's cross-entropy.
    pub hazard: Option<Tensor<1>>,
    /// The occupancy head's cross-entropy.
    pub occupancy: Option<Tensor<1>>,
    /// The motion head's cross-entropy.
    pub motion: Option<Tensor<1>>,
    /// The light head's cross-entropy.
    pub light: Option<Tensor<1>>,
}

/// Imitation loss of the head's outputs, plus the BEV loss when a prediction and a future BEV
/// are given (the future BEV is detached here) and the auxiliary losses, weighted.
pub fn losses(
    head: &HeadOutput,
    targets: &ImitationTargets,
    bev: Option<(Tensor<3>, Tensor<3>)>,
    auxiliary: AuxiliaryLosses,
    weights: &LossWeights,
) -> Losses {
    let waypoints = (head.waypoints.clone() - targets.waypoints.clone())
        .abs()
        .mean();
    let action = targets.actions.kl(
        head.alpha.clone().unsqueeze_dim(1),
        head.beta.clone().unsqueeze_dim(1),
        0,
    );
    let future_action = targets
        .actions
        .kl(head.future_alpha.clone(), head.future_beta.clone(), 1);
    let speed = (head.speed.clone() - targets.speed.clone().div_scalar(SPEED_SCALE))
        .abs()
        .mean();
    let bev = bev.map(|(predicted, future)| bev_loss(predicted, future));
    let mut total = waypoints.clone().mul_scalar(weights.waypoints)
        + action.clone().mul_scalar(weights.action)
        + future_action.clone().mul_scalar(weights.future_action)
        + speed.clone().mul_scalar(weights.speed);
    if let Some(bev) = &bev {
        total = total + bev.clone().mul_scalar(weights.bev);
    }
    let AuxiliaryLosses {
        hazard,
        occupancy,
        motion,
        light,
    } = auxiliary;
    for (term, weight) in [
        (&hazard, weights.hazard),
        (&occupancy, weights.occupancy),
        (&motion, weights.motion),
        (&light, weights.light),
    ] {
        if let Some(term) = term {
            total = total + term.clone().mul_scalar(weight);
        }
    }
    Losses {
        total,
        waypoints,
        action,
        future_action,
        speed,
        bev,
        hazard,
        occupancy,
        motion,
        light,
    }
}

/// MSE between the predicted future BEV and the (detached) BEV of the future frame.
pub fn bev_loss(predicted: Tensor<3>, future: Tensor<3>) -> Tensor<1> {
    (predicted - future.detach()).powi_scalar(2).mean()
}
