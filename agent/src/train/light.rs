//! The light head's labels and loss ([`crate::model::light`]): cross-entropy of its logits to
//! the class of the light ahead each frame records ([`LightClass::of`]), over the frames that
//! record one (datasets from before the label are left out), beside TCP's losses.

use burn::tensor::Tensor;
use burn::tensor::activation::log_softmax;
use ssrdrive_proto::dataset::LightAhead;

use crate::model::float_tensor;
use crate::model::light::LightClass;

/// The class of each sample's light ahead; `None` where the frame records none.
pub fn light_labels(lights: &[Option<LightAhead>]) -> Vec<Option<LightClass>> {
    lights
        .iter()
        .map(|l| l.as_ref().map(LightClass::of))
        .collect()
}

/// Mean cross-entropy of `logits` `[B, 4]` against `labels` over the labelled samples; 0
/// when none is labelled.
pub fn light_loss(logits: Tensor<2>, labels: &[Option<LightClass>]) -> Tensor<1> {
    let [b, k] = logits.dims();
    assert_eq!(labels.len(), b, "one light label per sample");
    let mut one_hot = vec![0.0; b * k];
    for (i, label) in labels.iter().enumerate() {
        if let Some(class) = label {
            one_hot[i * k + class.index()] = 1.0;
        }
    }
    let labelled = labels.iter().filter(|l| l.is_some()).count().max(1);
    let targets = float_tensor(one_hot, [b, k], &logits.device());
    (log_softmax(logits, 1) * targets)
        .sum()
        .div_scalar(labelled as f32)
        .neg()
        .reshape([1])
}

/// How many labelled samples the head classed right, and how many red lights it called red:
/// (right, labelled, red called red, red).
pub fn light_hits(predicted: &[usize], labels: &[Option<LightClass>]) -> [usize; 4] {
    let mut out = [0; 4];
    for (&p, label) in predicted.iter().zip(labels) {
        let Some(class) = label else { continue };
        out[1] += 1;
        out[0] += usize::from(p == class.index());
        if *class == LightClass::Red {
            out[3] += 1;
            out[2] += usize::from(p == class.index());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::float_values;
    use burn::tensor::Device;

    #[test]
    fn the_loss_skips_unlabelled_frames_and_hits_count_red_apart() {
        let device = Device::flex();
        let labels = [Some(LightClass::Red), None, Some(LightClass::NoLight)];
        let uniform = float_tensor(vec![0.0; 12], [3, 4], &device);
        let loss = float_values(light_loss(uniform, &labels))[0];
        assert!((loss - 4f32.ln()).abs() < 1e-5, "{loss}");
        let mut logits = vec![0.0; 12];
        logits[LightClass::Red.index()] = 6.0;
        logits[4] = 50.0; // the unlabelled frame's nonsense does not count
        logits[8 + LightClass::NoLight.index()] = 6.0;
        let right = float_values(light_loss(float_tensor(logits, [3, 4], &device), &labels))[0];
        assert!(right < 0.01, "{right}");
        let none = float_values(light_loss(
            float_tensor(vec![1.0; 4], [1, 4], &device),
            &[None],
        ))[0];
        assert_eq!(none, 0.0);
        assert_eq!(light_hits(&[3, 0, 1], &labels), [1, 2, 1, 1]);
        let light = LightAhead::Red { distance: 10.0 };
        assert_eq!(
            light_labels(&[Some(light), None]),
            vec![Some(LightClass::Red), None]
        );
    }
}
