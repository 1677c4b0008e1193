//! The fused kernels as a Burn backend extension: Flex runs the fused forward pass, and
//! `Autodiff<Flex>` records a hand-written backward pass next to it.
//!
//! - Deformable aggregation: autodiff on the tensor-op form keeps every gathered corner alive
//!   for the backward pass and replays the gather, the broadcast product and the sum as
//!   separate single-threaded steps. Here the backward pass is one parallel loop over the maps
//!   ([`deformable::aggregate_backward`]).
//! - Layer norm: autodiff records it as its decomposition, a pass per step; here it is one
//!   pass per row each way ([`layer_norm::backward`]).
//! - Convolution: Flex's backward passes run a transposed convolution and a 3-D convolution
//!   element by element; here both are matrix products over the im2col patches
//!   ([`conv::conv2d_backward`]).
//! - Batch norm in training: Flex takes the statistics through a transposed copy and
//!   normalises in single-threaded passes; here both directions are two parallel passes
//!   ([`batch_norm`]).
//! - Linear layers: Flex's backward pass copies transposes and mostly runs on one thread;
//!   here every product reads strided views and the large ones use all threads ([`linear`]).
//! - Activations and softmax: Flex maps them and their derivatives on one thread (softmax as
//!   five passes, GELU through a scalar `erf`); here each is one parallel, vectorised pass
//!   ([`activation`], [`softmax`]).

use burn::backend::autodiff::NodeId;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, AutodiffBackend, Backend, Flex, TensorMetadata, backend_extension};
use burn::tensor::{DType, Shape, TensorData};

use super::activation::{self, Activation};
use super::{batch_norm, conv, deformable, layer_norm, linear, softmax};

#[backend_extension(Flex, Autodiff)]
pub trait KernelOps: Backend {
    /// [`super::deformable_aggregate`] on backend primitives.
    fn deformable_aggregate(
        values: FloatTensor<Self>,
        locations: FloatTensor<Self>,
        weights: FloatTensor<Self>,
        height: usize,
        width: usize,
    ) -> FloatTensor<Self>;

    /// [`super::layer_norm`] on backend primitives.
    fn layer_norm(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
    ) -> FloatTensor<Self>;

    /// [`super::conv2d`] without the bias, on backend primitives.
    fn conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        stride: [usize; 2],
        padding: [usize; 2],
    ) -> FloatTensor<Self>;

    /// [`super::linear`] on backend primitives.
    fn linear(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
    ) -> FloatTensor<Self>;

    /// [`super::activation`] on backend primitives.
    fn activation(x: FloatTensor<Self>, activation: Activation) -> FloatTensor<Self>;

    /// [`super::softmax`] over the last axis, on backend primitives.
    fn softmax(x: FloatTensor<Self>) -> FloatTensor<Self>;

    /// [`super::batch_norm_train`] on backend primitives: the output, then the batch mean and
    /// biased variance per channel (not tracked).
    fn batch_norm_train(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>);
}

/// The data of a float32 tensor in row-major order, copied only when its layout is strided.
fn contiguous(tensor: &FlexTensor) -> FlexTensor {
    assert_eq!(
        tensor.dtype(),
        DType::F32,
        "the model's tensors are float32"
    );
    tensor.to_contiguous()
}

fn from_vec(data: Vec<f32>, shape: Shape) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(data, shape))
}

/// The length of a shape's last axis (the rows of a layer norm or a softmax).
fn last_dim(shape: &Shape) -> usize {
    shape[shape.num_dims() - 1]
}

/// The shape of a linear layer's output: the input's, with the weight's output width last.
fn linear_output_shape(x: &FlexTensor, weight: &FlexTensor) -> Shape {
    let mut shape = x.shape();
    let last = shape.num_dims() - 1;
    shape[last] = weight.shape()[1];
    shape
}

/// The batch norm's sizes, read from its input's shape.
fn batch_norm_shape(x: &FlexTensor) -> batch_norm::Shape {
    let shape = x.shape();
    let (batch, channels) = (shape[0], shape[1]);
    batch_norm::Shape {
        batch,
        channels,
        plane: shape.num_elements() / (batch * channels).max(1),
    }
}

/// The convolution's geometry, read from its tensors' shapes.
fn conv_geometry(
    x: &FlexTensor,
    weight: &FlexTensor,
    stride: [usize; 2],
    padding: [usize; 2],
) -> conv::Geometry {
    let [batch, channels_in, height, width] = x.shape().dims();
    let [channels_out, weight_in, kh, kw] = weight.shape().dims();
    assert_eq!(weight_in, channels_in, "weight input channels");
    conv::Geometry {
        batch,
        channels_in,
        channels_out,
        input: [height, width],
        kernel: [kh, kw],
        stride,
        padding,
    }
}

/// Registers each gradient whose input is tracked (has a node).
fn register<const N: usize>(
    grads: &mut Gradients,
    gradients: [(Option<NodeId>, Vec<f32>, Shape); N],
) {
    for (node, gradient, shape) in gradients {
        if let Some(node) = node {
            grads.register::<Flex>(node, from_vec(gradient, shape));
        }
    }
}

/// The aggregation's sizes, read from its tensors' shapes.
fn aggregation_shape(
    values: &FlexTensor,
    locations: &FlexTensor,
    height: usize,
    width: usize,
) -> deformable::Shape {
    let [n, _, channels] = values.shape().dims();
    let [_, queries, points, _] = locations.shape().dims();
    deformable::Shape {
        n,
        height,
        width,
        channels,
        queries,
        points,
    }
}

impl KernelOps for Flex {
    fn deformable_aggregate(
        values: FlexTensor,
        locations: FlexTensor,
        weights: FlexTensor,
        height: usize,
        width: usize,
    ) -> FlexTensor {
        let shape = aggregation_shape(&values, &locations, height, width);
        let (values, locations, weights) = (
            contiguous(&values),
            contiguous(&locations),
            contiguous(&weights),
        );
        let output = deformable::aggregate(
            values.storage(),
            locations.storage(),
            weights.storage(),
            shape,
        );
        from_vec(output, [shape.n, shape.queries, shape.channels].into())
    }

    fn layer_norm(x: FlexTensor, gamma: FlexTensor, beta: FlexTensor, epsilon: f64) -> FlexTensor {
        let shape = x.shape();
        let output = layer_norm::forward(
            contiguous(&x).storage(),
            last_dim(&shape),
            contiguous(&gamma).storage(),
            contiguous(&beta).storage(),
            epsilon as f32,
        );
        from_vec(output, shape)
    }

    fn conv2d(
        x: FlexTensor,
        weight: FlexTensor,
        stride: [usize; 2],
        padding: [usize; 2],
    ) -> FlexTensor {
        let geometry = conv_geometry(&x, &weight, stride, padding);
        let output = conv::conv2d(
            contiguous(&x).storage(),
            contiguous(&weight).storage(),
            geometry,
        );
        let [out_h, out_w] = geometry.output();
        from_vec(
            output,
            [geometry.batch, geometry.channels_out, out_h, out_w].into(),
        )
    }

    fn linear(x: FlexTensor, weight: FlexTensor, bias: FlexTensor) -> FlexTensor {
        let output = linear::forward(
            contiguous(&x).storage(),
            contiguous(&weight).storage(),
            contiguous(&bias).storage(),
        );
        from_vec(output, linear_output_shape(&x, &weight))
    }

    fn activation(x: FlexTensor, activation: Activation) -> FlexTensor {
        let shape = x.shape();
        from_vec(
            activation::forward(activation, contiguous(&x).storage()),
            shape,
        )
    }

    fn softmax(x: FlexTensor) -> FlexTensor {
        let shape = x.shape();
        from_vec(
            softmax::forward(contiguous(&x).storage(), last_dim(&shape)),
            shape,
        )
    }

    fn batch_norm_train(
        x: FlexTensor,
        gamma: FlexTensor,
        beta: FlexTensor,
        epsilon: f64,
    ) -> (FlexTensor, FlexTensor, FlexTensor) {
        let (shape, channels) = (x.shape(), gamma.shape());
        let result = batch_norm::forward(
            contiguous(&x).storage(),
            batch_norm_shape(&x),
            contiguous(&gamma).storage(),
            contiguous(&beta).storage(),
            epsilon as f32,
        );
        (
            from_vec(result.output, shape),
            from_vec(result.mean, channels.clone()),
            from_vec(result.variance, channels),
        )
    }
}

#[derive(Debug)]
struct LinearBackward;

impl Backward<Flex, 3> for LinearBackward {
    /// The checkpointed input and weight.
    type State = (NodeId, NodeId);

    fn backward(
        self,
        ops: Ops<Self::State, 3>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [x_node, weight_node, bias_node] = ops.parents;
        let grad = contiguous(&grads.consume::<Flex>(&ops.node));
        let (x, weight) = ops.state;
        let x: FlexTensor = checkpointer.retrieve_node_output(x);
        let weight: FlexTensor = checkpointer.retrieve_node_output(weight);
        let (x_shape, weight_shape) = (x.shape(), weight.shape());
        let outputs = weight_shape[1];
        let gradients = linear::backward(
            contiguous(&x).storage(),
            contiguous(&weight).storage(),
            grad.storage(),
            outputs,
            x_node.is_some(),
        );
        if let (Some(node), Some(gradient)) = (x_node, gradients.input) {
            grads.register::<Flex>(node.id, from_vec(gradient, x_shape));
        }
        register(
            grads,
            [
                (weight_node.map(|n| n.id), gradients.weight, weight_shape),
                (bias_node.map(|n| n.id), gradients.bias, [outputs].into()),
            ],
        );
    }
}

#[derive(Debug)]
struct SoftmaxBackward;

impl Backward<Flex, 1> for SoftmaxBackward {
    /// The checkpointed input.
    type State = NodeId;

    fn backward(
        self,
        ops: Ops<Self::State, 1>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [x_node] = ops.parents;
        let grad = contiguous(&grads.consume::<Flex>(&ops.node));
        let x: FlexTensor = checkpointer.retrieve_node_output(ops.state);
        let shape = x.shape();
        let gradient =
            softmax::backward(contiguous(&x).storage(), grad.storage(), last_dim(&shape));
        register(grads, [(x_node.map(|n| n.id), gradient, shape)]);
    }
}

#[derive(Debug)]
struct ActivationBackward;

impl Backward<Flex, 1> for ActivationBackward {
    /// The checkpointed input and the activation.
    type State = (NodeId, Activation);

    fn backward(
        self,
        ops: Ops<Self::State, 1>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [x_node] = ops.parents;
        let grad = contiguous(&grads.consume::<Flex>(&ops.node));
        let (x, activation) = ops.state;
        let x: FlexTensor = checkpointer.retrieve_node_output(x);
        let shape = x.shape();
        let gradient = activation::backward(activation, contiguous(&x).storage(), grad.storage());
        register(grads, [(x_node.map(|n| n.id), gradient, shape)]);
    }
}

#[derive(Debug)]
struct DeformableAggregateBackward;

impl Backward<Flex, 3> for DeformableAggregateBackward {
    /// The checkpointed values, locations and weights, and the map size.
    type State = (NodeId, NodeId, NodeId, [usize; 2]);

    fn backward(
        self,
        ops: Ops<Self::State, 3>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [values_node, locations_node, weights_node] = ops.parents;
        let grad = contiguous(&grads.consume::<Flex>(&ops.node));
        let (values, locations, weights, [height, width]) = ops.state;
        let values: FlexTensor = checkpointer.retrieve_node_output(values);
        let locations: FlexTensor = checkpointer.retrieve_node_output(locations);
        let weights: FlexTensor = checkpointer.retrieve_node_output(weights);
        let shape = aggregation_shape(&values, &locations, height, width);
        let shapes = [values.shape(), locations.shape(), weights.shape()];
        let (values, locations, weights) = (
            contiguous(&values),
            contiguous(&locations),
            contiguous(&weights),
        );
        let gradients = deformable::aggregate_backward(
            values.storage(),
            locations.storage(),
            weights.storage(),
            grad.storage(),
            shape,
        );
        let [values_shape, locations_shape, weights_shape] = shapes;
        register(
            grads,
            [
                (values_node.map(|n| n.id), gradients.values, values_shape),
                (
                    locations_node.map(|n| n.id),
                    gradients.locations,
                    locations_shape,
                ),
                (weights_node.map(|n| n.id), gradients.weights, weights_shape),
            ],
        );
    }
}

/// The normalisation a [`NormBackward`] step differentiates.
#[derive(Debug, Clone, Copy)]
enum Norm {
    Layer,
    Batch,
}

#[derive(Debug)]
struct NormBackward;

impl Backward<Flex, 3> for NormBackward {
    /// The checkpointed input and gamma, epsilon, and which norm.
    type State = (NodeId, NodeId, f64, Norm);

    fn backward(
        self,
        ops: Ops<Self::State, 3>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [x_node, gamma_node, beta_node] = ops.parents;
        let grad = contiguous(&grads.consume::<Flex>(&ops.node));
        let (x, gamma, epsilon, norm) = ops.state;
        let x: FlexTensor = checkpointer.retrieve_node_output(x);
        let gamma: FlexTensor = checkpointer.retrieve_node_output(gamma);
        let (x_shape, gamma_shape) = (x.shape(), gamma.shape());
        let (x, gamma, epsilon) = (contiguous(&x), contiguous(&gamma), epsilon as f32);
        let (input, gamma_grad, beta_grad) = match norm {
            Norm::Layer => {
                let row_len = last_dim(&x_shape);
                let g = layer_norm::backward(
                    x.storage(),
                    row_len,
                    gamma.storage(),
                    grad.storage(),
                    epsilon,
                );
                (g.input, g.gamma, g.beta)
            }
            Norm::Batch => {
                let shape = batch_norm_shape(&x);
                let g = batch_norm::backward(
                    x.storage(),
                    shape,
                    gamma.storage(),
                    grad.storage(),
                    epsilon,
                );
                (g.input, g.gamma, g.beta)
            }
        };
        register(
            grads,
            [
                (x_node.map(|n| n.id), input, x_shape),
                (gamma_node.map(|n| n.id), gamma_grad, gamma_shape.clone()),
                (beta_node.map(|n| n.id), beta_grad, gamma_shape),
            ],
        );
    }
}

#[derive(Debug)]
struct Conv2dBackward;

impl Backward<Flex, 2> for Conv2dBackward {
    /// The checkpointed input and weight, the stride and the padding.
    type State = (NodeId, NodeId, [usize; 2], [usize; 2]);

    fn backward(
        self,
        ops: Ops<Self::State, 2>,
        grads: &mut Gradients,
        checkpointer: &mut Checkpointer,
    ) {
        let [x_node, weight_node] = ops.parents;
        let grad = contiguous(&grads.consume::<Flex>(&ops.node));
        let (x, weight, stride, padding) = ops.state;
        let x: FlexTensor = checkpointer.retrieve_node_output(x);
        let weight: FlexTensor = checkpointer.retrieve_node_output(weight);
        let geometry = conv_geometry(&x, &weight, stride, padding);
        let (x_shape, weight_shape) = (x.shape(), weight.shape());
        let gradients = conv::conv2d_backward(
            contiguous(&x).storage(),
            contiguous(&weight).storage(),
            grad.storage(),
            geometry,
            x_node.is_some(),
        );
        if let (Some(node), Some(gradient)) = (x_node, gradients.input) {
            grads.register::<Flex>(node.id, from_vec(gradient, x_shape));
        }
        if let Some(node) = weight_node {
            grads.register::<Flex>(node.id, from_vec(gradients.weight, weight_shape));
        }
    }
}

/// Runs `forward` on the inputs' Flex tensors; when an input is tracked, also records `step`,
/// whose state `state` builds from the checkpoints of all inputs.
fn record<S, C, const N: usize>(
    step: S,
    inputs: [FloatTensor<Autodiff<Flex, C>>; N],
    state: impl FnOnce([NodeId; N]) -> S::State,
    forward: impl FnOnce([FlexTensor; N]) -> FlexTensor,
) -> FloatTensor<Autodiff<Flex, C>>
where
    S: Backward<Flex, N>,
    C: CheckpointStrategy,
{
    let nodes = inputs.each_ref().map(|input| input.node());
    match step.prepare::<C>(nodes).compute_bound().stateful() {
        OpsKind::Tracked(mut prep) => {
            let checkpoints = inputs.each_ref().map(|input| prep.checkpoint(input));
            let output = forward(inputs.map(|input| input.into_primitive()));
            prep.finish(state(checkpoints), output)
        }
        OpsKind::UnTracked(prep) => {
            prep.finish(forward(inputs.map(|input| input.into_primitive())))
        }
    }
}

impl<C: CheckpointStrategy> KernelOps for Autodiff<Flex, C> {
    fn layer_norm(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
    ) -> FloatTensor<Self> {
        record::<_, C, 3>(
            NormBackward,
            [x, gamma, beta],
            |[x, gamma, _]| (x, gamma, epsilon, Norm::Layer),
            |[x, gamma, beta]| Flex::layer_norm(x, gamma, beta, epsilon),
        )
    }

    fn conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        stride: [usize; 2],
        padding: [usize; 2],
    ) -> FloatTensor<Self> {
        record::<_, C, 2>(
            Conv2dBackward,
            [x, weight],
            |[x, weight]| (x, weight, stride, padding),
            |[x, weight]| Flex::conv2d(x, weight, stride, padding),
        )
    }

    fn deformable_aggregate(
        values: FloatTensor<Self>,
        locations: FloatTensor<Self>,
        weights: FloatTensor<Self>,
        height: usize,
        width: usize,
    ) -> FloatTensor<Self> {
        record::<_, C, 3>(
            DeformableAggregateBackward,
            [values, locations, weights],
            |[values, locations, weights]| (values, locations, weights, [height, width]),
            |[values, locations, weights]| {
                Flex::deformable_aggregate(values, locations, weights, height, width)
            },
        )
    }

    fn linear(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
    ) -> FloatTensor<Self> {
        record::<_, C, 3>(
            LinearBackward,
            [x, weight, bias],
            |[x, weight, _]| (x, weight),
            |[x, weight, bias]| Flex::linear(x, weight, bias),
        )
    }

    fn activation(x: FloatTensor<Self>, activation: Activation) -> FloatTensor<Self> {
        record::<_, C, 1>(
            ActivationBackward,
            [x],
            |[x]| (x, activation),
            |[x]| Flex::activation(x, activation),
        )
    }

    fn softmax(x: FloatTensor<Self>) -> FloatTensor<Self> {
        record::<_, C, 1>(SoftmaxBackward, [x], |[x]| x, |[x]| Flex::softmax(x))
    }

    fn batch_norm_train(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        epsilon: f64,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        let mut statistics = None;
        let output = record::<_, C, 3>(
            NormBackward,
            [x, gamma, beta],
            |[x, gamma, _]| (x, gamma, epsilon, Norm::Batch),
            |[x, gamma, beta]| {
                let (output, mean, variance) = Flex::batch_norm_train(x, gamma, beta, epsilon);
                statistics = Some((mean, variance));
                output
            },
        );
        let (mean, variance) = statistics.expect("`record` runs the forward pass");
        (output, Self::from_inner(mean), Self::from_inner(variance))
    }
}
