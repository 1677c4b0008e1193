//! The kernels that also train, as a Burn backend extension: Flex runs the fused forward pass,
//! and `Autodiff<Flex>` records a hand-written backward pass next to it.
//!
//! Autodiff on the tensor-op form keeps every gathered corner alive for the backward pass and
//! replays the gather, the broadcast product and the sum as separate single-threaded steps.
//! Here the backward pass is one parallel loop over the maps ([`deformable::aggregate_backward`]).

use burn::backend::autodiff::NodeId;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Flex, TensorMetadata, backend_extension};
use burn::tensor::{DType, Shape, TensorData};

use super::deformable;

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
        for (node, gradient, shape) in [
            (values_node, gradients.values, values_shape),
            (locations_node, gradients.locations, locations_shape),
            (weights_node, gradients.weights, weights_shape),
        ] {
            if let Some(node) = node {
                grads.register::<Flex>(node.id, from_vec(gradient, shape));
            }
        }
    }
}

impl<C: CheckpointStrategy> KernelOps for Autodiff<Flex, C> {
    fn deformable_aggregate(
        values: FloatTensor<Self>,
        locations: FloatTensor<Self>,
        weights: FloatTensor<Self>,
        height: usize,
        width: usize,
    ) -> FloatTensor<Self> {
        match DeformableAggregateBackward
            .prepare::<C>([values.node(), locations.node(), weights.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(mut prep) => {
                let state = (
                    prep.checkpoint(&values),
                    prep.checkpoint(&locations),
                    prep.checkpoint(&weights),
                    [height, width],
                );
                let output = Flex::deformable_aggregate(
                    values.into_primitive(),
                    locations.into_primitive(),
                    weights.into_primitive(),
                    height,
                    width,
                );
                prep.finish(state, output)
            }
            OpsKind::UnTracked(prep) => prep.finish(Flex::deformable_aggregate(
                values.into_primitive(),
                locations.into_primitive(),
                weights.into_primitive(),
                height,
                width,
            )),
        }
    }
}
