//! Layers that take the fused CPU kernels by themselves: [`Fused`] wraps one of Burn's layers,
//! and its `forward` runs the kernel of [`super::cpu_kernels`] where that serves the device and
//! the layer's form, else Burn's own `forward`. A model built from [`FusedLinear`],
//! [`FusedConv2d`], [`FusedBatchNorm`], [`FusedMaxPool2d`] and [`FusedLayerNorm`] reads
//! `self.fc.forward(x)` everywhere and cannot forget the fast path.
//!
//! The wrapper is transparent to checkpoints: it visits and maps its layer's parameters under
//! the layer's own names (a field `fc: FusedLinear` stores `fc.weight` and `fc.bias`, as
//! `fc: Linear` did), so records saved before and after load alike.

use burn::module::{
    Content, Devices, DisplaySettings, Module, ModuleDisplay, ModuleDisplayDefault, ModuleMapper,
    ModuleVisitor, RunningState,
};
use burn::nn::conv::Conv2d;
use burn::nn::pool::MaxPool2d;
use burn::nn::{BatchNorm, LayerNorm, LayerNormConfig, Linear, PaddingConfig2d};
use burn::tensor::{Device, Tensor};

use super::cpu_kernels;

/// One of Burn's layers whose `forward` picks the fused CPU kernel (see the module doc).
#[derive(Debug, Clone)]
pub struct Fused<M>(M);

/// A linear layer on the fused kernel (Flex, inference and training) when it has a bias.
pub type FusedLinear = Fused<Linear>;
/// A 2-D convolution on the fused kernel (Flex, inference and training) when it is a plain one.
pub type FusedConv2d = Fused<Conv2d>;
/// Batch norm whose training statistics come from the fused kernel.
pub type FusedBatchNorm = Fused<BatchNorm>;
/// Max pooling on the fused kernel (Flex, inference) when it is a plain one.
pub type FusedMaxPool2d = Fused<MaxPool2d>;
/// Layer norm with [`LAYER_NORM_EPSILON`] on the fused kernel (Flex, inference and training).
pub type FusedLayerNorm = Fused<LayerNorm>;

/// The epsilon of every layer norm in the model (Burn's default). [`LayerNorm`] keeps its own
/// private, so [`FusedLayerNorm::new`] is the only way to build one.
pub const LAYER_NORM_EPSILON: f64 = 1e-5;

impl<M> Fused<M> {
    /// The wrapped Burn layer (its parameters, for tests and initialisation).
    pub fn inner(&self) -> &M {
        &self.0
    }
}

macro_rules! wraps {
    ($($layer:ty),*) => {$(
        impl From<$layer> for Fused<$layer> {
            fn from(layer: $layer) -> Self {
                Self(layer)
            }
        }
    )*};
}
wraps!(Linear, Conv2d, BatchNorm, MaxPool2d);

impl FusedLinear {
    /// `x` `[..., d_in]` to `[..., d_out]`.
    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        match &self.0.bias {
            Some(bias) if cpu_kernels::is_flex(&x.device()) => {
                cpu_kernels::linear(x, self.0.weight.val(), bias.val())
            }
            _ => self.0.forward(x),
        }
    }
}

impl FusedConv2d {
    /// `x` `[N, C_in, H, W]` to `[N, C_out, H', W']`. Plain means one group, no dilation and
    /// symmetric explicit padding or none.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let layer = &self.0;
        let padding = match layer.padding {
            PaddingConfig2d::Valid => Some([0, 0]),
            PaddingConfig2d::Explicit(top, left, bottom, right)
                if top == bottom && left == right =>
            {
                Some([top, left])
            }
            _ => None,
        };
        match padding {
            Some(padding)
                if cpu_kernels::is_flex(&x.device())
                    && layer.groups == 1
                    && layer.dilation == [1, 1] =>
            {
                cpu_kernels::conv2d(
                    x,
                    layer.weight.val(),
                    layer.bias.as_ref().map(|bias| bias.val()),
                    layer.stride,
                    padding,
                )
            }
            _ => layer.forward(x),
        }
    }
}

impl FusedBatchNorm {
    /// `x` `[N, C, H, W]`, normalised per channel. In training (autodiff, training flag on) on
    /// Flex, the batch statistics come from the fused kernel and update the running ones as
    /// Burn's `BatchNorm` does; otherwise Burn's layer runs.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let norm = &self.0;
        let device = x.device();
        if !(device.is_autodiff() && norm.training.is_enabled() && cpu_kernels::is_flex(&device)) {
            return norm.forward(x);
        }
        let (output, mean, variance) =
            cpu_kernels::batch_norm_train(x, norm.gamma.val(), norm.beta.val(), norm.epsilon);
        let momentum = norm.momentum;
        let update = |running: &RunningState<Tensor<1>>, batch: Tensor<1>| {
            let updated = running
                .value_sync()
                .to_device(&device)
                .mul_scalar(1.0 - momentum)
                .add(batch.mul_scalar(momentum));
            running.update(updated.detach());
        };
        update(&norm.running_mean, mean);
        update(&norm.running_var, variance);
        output
    }
}

impl FusedMaxPool2d {
    /// `x` `[N, C, H, W]` pooled. Plain means a square window and stride, symmetric padding
    /// smaller than the window, no dilation, floor mode.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let layer = &self.0;
        let [kernel, kernel_w] = layer.kernel_size;
        let [stride, stride_w] = layer.stride;
        match layer.padding {
            PaddingConfig2d::Explicit(top, left, bottom, right)
                if cpu_kernels::is_flex_inference(&x.device())
                    && kernel == kernel_w
                    && stride == stride_w
                    && [left, bottom, right] == [top; 3]
                    && top < kernel
                    && layer.dilation == [1, 1]
                    && !layer.ceil_mode =>
            {
                cpu_kernels::max_pool2d(x, kernel, stride, top)
            }
            _ => layer.forward(x),
        }
    }
}

impl FusedLayerNorm {
    /// A layer norm over `d` channels (scale one, shift zero) with [`LAYER_NORM_EPSILON`].
    pub fn new(d: usize, device: &Device) -> Self {
        Self(
            LayerNormConfig::new(d)
                .with_epsilon(LAYER_NORM_EPSILON)
                .init(device),
        )
    }

    /// `x` `[..., d]` normalised over the last axis.
    pub fn forward<const D: usize>(&self, x: Tensor<D>) -> Tensor<D> {
        match &self.0.beta {
            Some(beta) if cpu_kernels::is_flex(&x.device()) => {
                cpu_kernels::layer_norm(x, self.0.gamma.val(), beta.val(), LAYER_NORM_EPSILON)
            }
            _ => self.0.forward(x),
        }
    }
}

/// Every call goes to the wrapped layer, with no path level of its own.
impl<M: Module> Module for Fused<M> {
    fn collect_devices(&self, devices: Devices) -> Devices {
        self.0.collect_devices(devices)
    }

    fn fork(self, device: &Device) -> Self {
        Self(self.0.fork(device))
    }

    fn to_device(self, device: &Device) -> Self {
        Self(self.0.to_device(device))
    }

    fn train(self) -> Self {
        Self(self.0.train())
    }

    fn valid(&self) -> Self {
        Self(self.0.valid())
    }

    fn materialize(self) -> Self {
        Self(self.0.materialize())
    }

    fn num_params(&self) -> usize {
        self.0.num_params()
    }

    fn visit<Visitor: ModuleVisitor>(&self, visitor: &mut Visitor) {
        self.0.visit(visitor)
    }

    fn map<Mapper: ModuleMapper>(self, mapper: &mut Mapper) -> Self {
        Self(self.0.map(mapper))
    }
}

impl<M: ModuleDisplayDefault> ModuleDisplayDefault for Fused<M> {
    fn content(&self, content: Content) -> Option<Content> {
        self.0.content(content)
    }

    fn num_params(&self) -> usize {
        self.0.num_params()
    }
}

impl<M: ModuleDisplay> ModuleDisplay for Fused<M> {
    fn format(&self, settings: DisplaySettings) -> String {
        self.0.format(settings)
    }
}
