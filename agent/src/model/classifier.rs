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

/// The probability of each class (softmax) in each row of `logits` (`[B, K]` values,
/// row-major), in logit order.
pub fn class_probabilities<const K: usize>(logits: &[f32]) -> Vec<[f32; K]> {
    logits
        .chunks_exact(K)
        .map(|row| {
            let max = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let weights: [f32; K] = std::array::from_fn(|k| (row[k] - max).exp());
            let total: f32 = weights.iter().sum();
            weights.map(|w| w / total)
        })
        .collect()
}

/// The index of the largest logit in each row of `logits` (`[B, k]` values, row-major).
pub fn predicted_classes(logits: &[f32], k: usize) -> Vec<usize> {
    logits
        .chunks_exact(k)
        .map(|row| {
            (0..row.len())
                .max_by(|&a, &b| row[a].total_cmp(&row[b]))
                .unwrap_or(0)
        })
        .collect()
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

    #[test]
    fn probabilities_are_the_softmax_of_each_row_and_the_prediction_its_largest_logit() {
        let mut logits = vec![0.0; 10];
        logits[2] = 10.0;
        let rows = class_probabilities::<5>(&logits);
        assert!(rows[0][2] > 0.99, "{rows:?}");
        assert!(rows[1].iter().all(|p| (p - 0.2).abs() < 1e-6), "{rows:?}");
        assert!(
            rows.iter()
                .all(|row| (row.iter().sum::<f32>() - 1.0).abs() < 1e-6)
        );
        logits[5] = 4.0;
        assert_eq!(predicted_classes(&logits, 5), vec![2, 0]);
        assert_eq!(
            predicted_classes(&[0.0, 2.0, 1.0, 0.0, 5.0, 0.0, 0.0, 1.0], 4),
            vec![1, 0]
        );
    }
}
