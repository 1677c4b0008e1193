//! The hazard head's loss: cross-entropy of its logits ([`crate::model::hazard`]) to what the
//! expert brakes for in each frame ([`Hazard::of`] its brake reason), beside TCP's losses.

use burn::tensor::Tensor;
use burn::tensor::activation::log_softmax;

use crate::model::float_tensor;
use crate::model::hazard::Hazard;

/// Mean cross-entropy of `logits` `[B, 5]` against the classes `labels` (one per sample).
pub fn hazard_loss(logits: Tensor<2>, labels: &[Hazard]) -> Tensor<1> {
    let [b, k] = logits.dims();
    assert_eq!(labels.len(), b, "one hazard label per sample");
    let mut one_hot = vec![0.0; b * k];
    for (i, label) in labels.iter().enumerate() {
        one_hot[i * k + label.index()] = 1.0;
    }
    let targets = float_tensor(one_hot, [b, k], &logits.device());
    (log_softmax(logits, 1) * targets).sum_dim(1).mean().neg()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::float_values;
    use burn::tensor::Device;

    #[test]
    fn loss_is_the_cross_entropy_and_falls_as_the_right_logit_grows() {
        let device = Device::flex();
        let uniform = float_tensor(vec![0.0; 10], [2, 5], &device);
        let loss = float_values(hazard_loss(uniform, &[Hazard::Light, Hazard::Clear]))[0];
        assert!((loss - 5f32.ln()).abs() < 1e-5, "{loss}");
        let mut logits = vec![0.0; 10];
        logits[Hazard::Light.index()] = 4.0;
        logits[5 + Hazard::Clear.index()] = 4.0;
        let confident = float_tensor(logits, [2, 5], &device);
        let better = float_values(hazard_loss(confident, &[Hazard::Light, Hazard::Clear]))[0];
        assert!(better < 0.1, "{better}");
    }
}
