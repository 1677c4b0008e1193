//! Group normalisation of channels-last tensors (layer norm is [`super::fused::FusedLayerNorm`]).

use burn::nn::GroupNorm;
use burn::tensor::Tensor;

use super::cpu_kernels;

/// Burn's [`GroupNorm`] with one group, applied to a channels-last `[B, L, C]` tensor as the
/// module applies it to `[B, C, L]`: statistics over all of a sample's values, then the
/// per-channel affine. With one group the order of the values does not matter, so this skips
/// the two transposes and the strided copy that `norm.forward(x.swap_dims(1, 2))` costs. On
/// Flex it is the layer-norm kernel over each sample's `L x C` values with the `[C]` affine
/// repeating along them. Same parameters, same checkpoints.
pub fn single_group_norm(norm: &GroupNorm, x: Tensor<3>) -> Tensor<3> {
    debug_assert_eq!(norm.num_groups, 1, "one group");
    let [b, l, c] = x.dims();
    let flat = x.reshape([b, l * c]);
    let affine = norm.gamma.as_ref().zip(norm.beta.as_ref());
    if let Some((gamma, beta)) = affine.filter(|_| cpu_kernels::is_flex(&flat.device())) {
        return cpu_kernels::layer_norm(flat, gamma.val(), beta.val(), norm.epsilon)
            .reshape([b, l, c]);
    }
    let centred = flat.clone() - flat.mean_dim(1);
    let variance = centred.clone().square().mean_dim(1);
    let normalised = (centred / variance.add_scalar(norm.epsilon).sqrt()).reshape([b, l, c]);
    match affine {
        Some((gamma, beta)) => {
            normalised * gamma.val().reshape([1, 1, c]) + beta.val().reshape([1, 1, c])
        }
        None => normalised,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::module::Param;
    use burn::nn::GroupNormConfig;
    use burn::tensor::{Device, Distribution};

    /// Largest absolute difference between two tensors.
    fn max_diff<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
        (a - b).abs().max().into_scalar()
    }

    #[test]
    fn matches_the_module_on_transposed_input() {
        // Flex+autodiff runs the fused kernel; the module runs Burn's ops on the same device.
        let device = Device::flex().autodiff();
        for [b, l, c] in [[3, 10, 6], [8, 300, 16]] {
            let mut norm = GroupNormConfig::new(1, c).with_epsilon(1e-6).init(&device);
            let random = || {
                Param::from_tensor(
                    Tensor::random([c], Distribution::Normal(1.0, 0.5), &device).require_grad(),
                )
            };
            norm.gamma = Some(random());
            norm.beta = Some(random());
            let x = Tensor::<3>::random([b, l, c], Distribution::Normal(2.0, 3.0), &device)
                .require_grad();
            let expected = norm.forward(x.clone().swap_dims(1, 2)).swap_dims(1, 2);
            let fused = single_group_norm(&norm, x.clone());
            // Float32 rounding grows with the outputs' magnitude (up to about 10 here).
            let scale: f32 = expected.clone().abs().max().into_scalar();
            let error = max_diff(fused.clone(), expected.clone());
            assert!(
                error < 1e-5 * scale.max(1.0),
                "{b}x{l}x{c}: max difference {error} (largest {scale})"
            );

            let output_grad =
                Tensor::<3>::random([b, l, c], Distribution::Normal(0.0, 1.0), &device);
            let fused_grads = (fused * output_grad.clone()).sum().backward();
            let module_grads = (expected * output_grad).sum().backward();
            let gamma = norm.gamma.as_ref().expect("gamma").val();
            let beta = norm.beta.as_ref().expect("beta").val();
            let pairs = [
                (
                    "input",
                    x.grad(&fused_grads).map(|g| g.flatten::<1>(0, 2)),
                    x.grad(&module_grads).map(|g| g.flatten::<1>(0, 2)),
                ),
                ("gamma", gamma.grad(&fused_grads), gamma.grad(&module_grads)),
                ("beta", beta.grad(&fused_grads), beta.grad(&module_grads)),
            ];
            for (name, fused, module) in pairs {
                let (fused, module) = (
                    fused.expect("fused gradient"),
                    module.expect("module gradient"),
                );
                let scale: f32 = module.clone().abs().max().into_scalar();
                let error = max_diff(fused, module);
                assert!(
                    error < 1e-4 * scale,
                    "{b}x{l}x{c} {name} gradient: differs by {error} (largest {scale})"
                );
            }
        }
    }
}
