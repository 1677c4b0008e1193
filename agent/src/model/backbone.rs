//! Image backbone: a ResNet of basic blocks (ResNet-18/34 family) with batch norm, and a neck
//! that maps the last stage to the network's channel width.
//!
//! Input: images normalised with ImageNet statistics ([`normalise_images`]), `[N, 3, H, W]`.
//! Output: `[N, C, h, w]` with the size of [`SsrConfig::feature_size`] (stride 16 or 32).

use burn::module::{Module, Param};
use burn::nn::conv::Conv2dConfig;
use burn::nn::pool::MaxPool2dConfig;
use burn::nn::{BatchNormConfig, PaddingConfig2d};
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor};

use super::config::{BackboneConfig, SsrConfig};
use super::cpu_kernels::{self, Activation};
use super::fused::{FusedBatchNorm, FusedConv2d, FusedMaxPool2d};

/// ImageNet mean of R, G, B in [0, 1].
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet standard deviation of R, G, B in [0, 1].
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

fn conv(cin: usize, cout: usize, kernel: usize, stride: usize, device: &Device) -> FusedConv2d {
    let pad = kernel / 2;
    Conv2dConfig::new([cin, cout], [kernel, kernel])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(pad, pad, pad, pad))
        .with_bias(false)
        .init(device)
        .into()
}

/// Convolution followed by batch norm.
#[derive(Module, Debug)]
struct ConvBn {
    conv: FusedConv2d,
    bn: FusedBatchNorm,
}

impl ConvBn {
    fn new(cin: usize, cout: usize, kernel: usize, stride: usize, device: &Device) -> Self {
        Self {
            conv: conv(cin, cout, kernel, stride, device),
            bn: BatchNormConfig::new(cout).init(device).into(),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.bn.forward(self.conv.forward(x))
    }
}

/// The stem: a 7x7 stride-2 convolution of the RGB image, then batch norm.
///
/// A narrow stem (at most [`Stem::DIRECT_MAX_WIDTH`] channels) is computed as a stride-1
/// convolution of the image's space-to-depth rearrangement, with the same weights and the same
/// result to rounding. The Flex backend runs a convolution of 3 input channels into so few
/// outputs through a direct loop that does not vectorise over strided columns; the rearranged
/// form has 12 input channels at stride 1 and runs as im2col plus one matrix product: 3x faster
/// for the cpu-default stem at batch 1 and 8. Wider stems already take that path, and there the
/// rearrangement's zero taps (64 instead of 49) cost 10 %.
#[derive(Module, Debug)]
struct Stem {
    conv: FusedConv2d,
    bn: FusedBatchNorm,
}

impl Stem {
    const KERNEL: usize = 7;
    const STRIDE: usize = 2;
    /// The widest stem the Flex backend convolves directly.
    const DIRECT_MAX_WIDTH: usize = 16;

    fn new(cout: usize, device: &Device) -> Self {
        Self {
            conv: conv(3, cout, Self::KERNEL, Self::STRIDE, device),
            bn: BatchNormConfig::new(cout).init(device).into(),
        }
    }

    /// `[N, 3, H, W]` to `[N, cout, ceil(H/2), ceil(W/2)]`.
    fn forward(&self, images: Tensor<4>) -> Tensor<4> {
        let y = if self.conv.inner().weight.dims()[0] <= Self::DIRECT_MAX_WIDTH {
            self.space_to_depth_conv(images)
        } else {
            self.conv.forward(images)
        };
        self.bn.forward(y)
    }

    /// The strided convolution computed on the space-to-depth rearrangement of the image.
    ///
    /// With `s` the stride, image pixel `s*y + k` meets kernel tap `k = s*a + p`; grouping the
    /// pixels by phase `p` (space to depth) turns the sum into a stride-1 convolution over
    /// `3*s*s` phase channels with a kernel of `ceil(7/s)` taps, the original kernel padded with
    /// zeros to a multiple of `s` and split the same way.
    fn space_to_depth_conv(&self, images: Tensor<4>) -> Tensor<4> {
        let (s, k, pad) = (Self::STRIDE, Self::KERNEL, Self::KERNEL / 2);
        let [n, c, h, w] = images.dims();
        let (out_h, out_w) = ((h + 2 * pad - k) / s + 1, (w + 2 * pad - k) / s + 1);
        // Pad as the convolution does, then up to a multiple of the stride.
        let (padded_h, padded_w) = (
            (h + 2 * pad).next_multiple_of(s),
            (w + 2 * pad).next_multiple_of(s),
        );
        let phases = images
            .pad([(pad, padded_h - h - pad), (pad, padded_w - w - pad)], 0.0)
            .reshape([n, c, padded_h / s, s, padded_w / s, s])
            .permute([0, 1, 3, 5, 2, 4])
            .reshape([n, c * s * s, padded_h / s, padded_w / s]);
        let taps = k.div_ceil(s);
        let weight = self.conv.inner().weight.val();
        let cout = weight.dims()[0];
        let weight = weight
            .pad([(0, taps * s - k), (0, taps * s - k)], 0.0)
            .reshape([cout, c, taps, s, taps, s])
            .permute([0, 1, 3, 5, 2, 4])
            .reshape([cout, c * s * s, taps, taps]);
        let y = if cpu_kernels::is_flex(&phases.device()) {
            cpu_kernels::conv2d(phases, weight, None, [1, 1], [0, 0])
        } else {
            conv2d(
                phases,
                weight,
                None,
                ConvOptions::new([1, 1], [0, 0], [1, 1], 1),
            )
        };
        y.slice([0..n, 0..cout, 0..out_h, 0..out_w])
    }
}

/// ResNet basic block: two 3x3 conv-BN with a (projected) shortcut.
#[derive(Module, Debug)]
struct BasicBlock {
    first: ConvBn,
    second: ConvBn,
    shortcut: Option<ConvBn>,
}

impl BasicBlock {
    fn new(cin: usize, cout: usize, stride: usize, device: &Device) -> Self {
        let shortcut =
            (stride != 1 || cin != cout).then(|| ConvBn::new(cin, cout, 1, stride, device));
        Self {
            first: ConvBn::new(cin, cout, 3, stride, device),
            second: ConvBn::new(cout, cout, 3, 1, device),
            shortcut,
        }
    }

    /// A stride-1 block of `width` channels that starts as the identity: its residual branch
    /// ends in a batch norm of scale zero (and shift zero, as every fresh one), so the branch
    /// adds nothing and the block's ReLU passes its input, the ReLU output of the block before,
    /// through unchanged, in inference and in a training step's forward pass alike. The scale
    /// still gets a gradient, so training grows the branch from there (Goyal et al.'s
    /// zero-initialised residual).
    fn identity(width: usize, device: &Device) -> Self {
        let mut block = Self::new(width, width, 1, device);
        let mut norm = BatchNormConfig::new(width).init(device);
        norm.gamma = Param::from_tensor(Tensor::zeros([width], device));
        block.second.bn = norm.into();
        block
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let residual = match &self.shortcut {
            Some(projection) => projection.forward(x.clone()),
            None => x.clone(),
        };
        let y = self.second.forward(cpu_kernels::activation(
            self.first.forward(x),
            Activation::Relu,
        ));
        cpu_kernels::activation(y + residual, Activation::Relu)
    }
}

/// ResNet trunk plus neck (1x1 lateral conv then 3x3 conv, as SSR's single-level FPN).
#[derive(Module, Debug)]
pub struct Backbone {
    stem: Stem,
    pool: FusedMaxPool2d,
    blocks: Vec<BasicBlock>,
    lateral: FusedConv2d,
    smooth: FusedConv2d,
}

impl Backbone {
    /// A randomly initialised trunk and neck with the stages of `config.backbone`, ending at
    /// `config.channels` channels.
    pub fn new(config: &SsrConfig, device: &Device) -> Self {
        let b = &config.backbone;
        let mut blocks = Vec::new();
        let mut cin = b.stem_width;
        for ((&count, &width), &stride) in b.blocks.iter().zip(&b.widths).zip(&b.strides) {
            for index in 0..count {
                blocks.push(BasicBlock::new(
                    cin,
                    width,
                    if index == 0 { stride } else { 1 },
                    device,
                ));
                cin = width;
            }
        }
        let c = config.channels;
        Self {
            stem: Stem::new(b.stem_width, device),
            pool: MaxPool2dConfig::new([3, 3])
                .with_strides([2, 2])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init()
                .into(),
            blocks,
            lateral: Conv2dConfig::new([cin, c], [1, 1]).init(device).into(),
            smooth: Conv2dConfig::new([c, c], [3, 3])
                .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(device)
                .into(),
        }
    }

    /// This trunk, built with the stages of `from`, grown to the stages of `to`: every stage
    /// keeps its blocks and gains [`BasicBlock::identity`] ones after them, so the deeper trunk
    /// computes exactly what this one did until training moves the new blocks. A capacity
    /// experiment can so start from a trained checkpoint's driving instead of from random
    /// weights (`ssr-agent train --init CKPT --deepen-backbone N,N,N,N`).
    ///
    /// Errors (naming the problem) where `to` does not deepen `from`
    /// ([`BackboneConfig::deepens`]) or this trunk does not have `from`'s blocks.
    pub fn deepened(
        self,
        from: &BackboneConfig,
        to: &BackboneConfig,
        device: &Device,
    ) -> Result<Self, String> {
        if !to.deepens(from) {
            return Err(format!(
                "backbone {to:?} does not deepen {from:?}: only more blocks per stage may differ"
            ));
        }
        let had: usize = from.blocks.iter().sum();
        if self.blocks.len() != had {
            return Err(format!(
                "the trunk has {} blocks where its stages {:?} make {had}",
                self.blocks.len(),
                from.blocks
            ));
        }
        let mut kept = self.blocks.into_iter();
        let mut blocks = Vec::with_capacity(to.blocks.iter().sum());
        for ((&fewer, &more), &width) in from.blocks.iter().zip(&to.blocks).zip(&to.widths) {
            blocks.extend(kept.by_ref().take(fewer));
            blocks.extend((fewer..more).map(|_| BasicBlock::identity(width, device)));
        }
        Ok(Self { blocks, ..self })
    }

    /// `[N, 3, H, W]` normalised images to `[N, C, h, w]` features.
    pub fn forward(&self, images: Tensor<4>) -> Tensor<4> {
        let stem = cpu_kernels::activation(self.stem.forward(images), Activation::Relu);
        let mut x = self.pool.forward(stem);
        for block in &self.blocks {
            x = block.forward(x);
        }
        self.smooth.forward(self.lateral.forward(x))
    }
}

/// An RGB8 frame (`width * height * 3` bytes, row-major) resized bilinearly (half-pixel
/// centres, as `align_corners = false`) to `out_width x out_height` and ImageNet-normalised,
/// as planar `[3, out_height, out_width]` floats.
pub fn frame_to_input(
    rgb: &[u8],
    width: usize,
    height: usize,
    out_width: usize,
    out_height: usize,
) -> Vec<f32> {
    assert_eq!(rgb.len(), width * height * 3, "frame size");
    let taps = |out: usize, size: usize| -> Vec<(usize, usize, f32)> {
        (0..out)
            .map(|i| {
                let x = ((i as f32 + 0.5) * size as f32 / out as f32 - 0.5)
                    .clamp(0.0, (size - 1) as f32);
                let low = x as usize;
                (low, (low + 1).min(size - 1), x - low as f32)
            })
            .collect()
    };
    let (columns, rows) = (taps(out_width, width), taps(out_height, height));
    let plane = out_width * out_height;
    let mut planar = vec![0f32; 3 * plane];
    for (oy, &(y0, y1, fy)) in rows.iter().enumerate() {
        for (ox, &(x0, x1, fx)) in columns.iter().enumerate() {
            for channel in 0..3 {
                let at = |x: usize, y: usize| rgb[(y * width + x) * 3 + channel] as f32;
                let top = at(x0, y0) * (1.0 - fx) + at(x1, y0) * fx;
                let bottom = at(x0, y1) * (1.0 - fx) + at(x1, y1) * fx;
                let value = (top * (1.0 - fy) + bottom * fy) / 255.0;
                planar[channel * plane + oy * out_width + ox] =
                    (value - IMAGENET_MEAN[channel]) / IMAGENET_STD[channel];
            }
        }
    }
    planar
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::Distribution;

    /// The space-to-depth stem equals the strided convolution it replaces, for even and odd
    /// image sizes.
    #[test]
    fn space_to_depth_matches_the_strided_convolution() {
        let device = Device::flex();
        let stem = Stem::new(8, &device);
        for [h, w] in [[96, 320], [13, 17], [8, 7]] {
            let images = Tensor::<4>::random([2, 3, h, w], Distribution::Normal(0.0, 1.0), &device);
            let expected = stem.conv.inner().forward(images.clone());
            let actual = stem.space_to_depth_conv(images);
            assert_eq!(actual.dims(), expected.dims(), "{h}x{w}");
            let error: f32 = (actual - expected).abs().max().into_scalar();
            assert!(error < 1e-4, "{h}x{w}: max difference {error}");
        }
    }
}
