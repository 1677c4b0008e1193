//! A small classifier over the scene tokens: mean- and max-pooled tokens, one hidden layer, a
//! logit per class. The hazard head ([`super::hazard`]) and the light head ([`super::light`])
//! are two of them.

use burn::module::Module;
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor};

use super::fused::FusedLinear;
use super::init::xavier_linear;

/// Size of a [`TokenClassifier`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TokenClassifierConfig {
    /// Channels of the scene tokens (the network's `channels`).
    pub channels: usize,
    /// Width of the hidden layer.
    pub hidden: usize,
    /// Number of classes.
    pub classes: usize,
}

impl TokenClassifierConfig {
    /// A randomly initialised classifier.
    pub fn init(&self, device: &Device) -> TokenClassifier {
        TokenClassifier {
            hidden: xavier_linear(2 * self.channels, self.hidden, device),
            out: xavier_linear(self.hidden, self.classes, device),
        }
    }
}

/// Mean- and max-pooled scene tokens, one hidden layer, a logit per class.
#[derive(Module, Debug)]
pub struct TokenClassifier {
    hidden: FusedLinear,
    out: FusedLinear,
}

impl TokenClassifier {
    /// Class logits of the scene tokens.
    ///
    /// # Shapes
    /// - tokens: `[B, S, C]`
    /// - output: `[B, classes]`
    pub fn forward(&self, tokens: Tensor<3>) -> Tensor<2> {
        let [b, _, c] = tokens.dims();
        let mean = tokens.clone().mean_dim(1).reshape([b, c]);
        let max = tokens.max_dim(1).reshape([b, c]);
        self.out
            .forward(relu(self.hidden.forward(Tensor::cat(vec![mean, max], 1))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{float_tensor, float_values};

    #[test]
    fn the_classifier_maps_tokens_to_a_logit_per_class() {
        let device = Device::flex();
        let head = TokenClassifierConfig {
            channels: 8,
            hidden: 16,
            classes: 5,
        }
        .init(&device);
        let tokens = float_tensor(
            (0..2 * 3 * 8).map(|v| v as f32 * 0.01).collect(),
            [2, 3, 8],
            &device,
        );
        let logits = head.forward(tokens);
        assert_eq!(logits.dims(), [2, 5]);
        let values = float_values(logits);
        assert!(values.iter().all(|v| v.is_finite()));
        // The two samples' tokens differ, and so do their logits: the head reads its input.
        assert!(
            values[..5]
                .iter()
                .zip(&values[5..])
                .any(|(a, b)| (a - b).abs() > 1e-6)
        );
    }
}
