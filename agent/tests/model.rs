//! The network through its public interface: shapes per config, the first-frame path, temporal
//! alignment, token attention, the navigation gate, and the sampler against grid_sample.

mod common;

use burn::module::{Module, Param};
use burn::nn::pool::MaxPool2dConfig;
use burn::nn::{BatchNormConfig, LayerNormConfig, LinearConfig, PaddingConfig2d};
use burn::tensor::activation::{gelu, relu, sigmoid, softmax};
use burn::tensor::ops::{ConvOptions, GridSampleOptions};
use burn::tensor::{Device, Distribution, Gradients, Tensor};

use common::{max_abs_diff, model_input, tiny_config};
use ssr_agent::model::bev::align_previous_bev;
use ssr_agent::model::config::SsrConfig;
use ssr_agent::model::cpu_kernels::{self, Activation};
use ssr_agent::model::fused::{FusedBatchNorm, FusedLinear};
use ssr_agent::model::sampling::{
    bilinear_sample, deformable_aggregate, deformable_aggregate_by_tensor_ops,
};
use ssr_agent::model::stl::NavigationGate;
use ssr_agent::model::{float_tensor, float_values};
use ssr_agent::pose::{EgoMotion, Pose2};

fn check_shapes(config: &SsrConfig, batch: usize, cameras: usize) {
    let device = Device::flex();
    let model = config.init(&device).valid();
    let input = model_input(config, batch, cameras, true, &device);
    let (fh, fw) = config.feature_size();
    assert_eq!(
        model.image_features(input.images.clone()).dims(),
        [batch * cameras, config.channels, fh, fw]
    );
    let out = model.forward(&input);
    let q = config.bev.grid.cells();
    let s = config.tokens.num_tokens;
    let p = config.head.pred_len;
    assert_eq!(out.bev.dims(), [batch, q, config.channels]);
    assert_eq!(out.scene.tokens.dims(), [batch, s, config.channels]);
    assert_eq!(out.scene.attention.clone().unwrap().dims(), [batch, s, q]);
    assert_eq!(
        out.scene.gate.clone().unwrap().dims(),
        [batch, config.channels]
    );
    assert_eq!(out.head.waypoints.dims(), [batch, p, 2]);
    assert_eq!(out.head.alpha.dims(), [batch, 2]);
    assert_eq!(out.head.future_beta.dims(), [batch, p, 2]);
    assert_eq!(out.head.speed.dims(), [batch, 1]);
    assert_eq!(
        model.predict_future_bev(&out).dims(),
        [batch, q, config.channels]
    );
    assert!(
        float_values(out.head.alpha)
            .iter()
            .all(|a| a.is_finite() && *a > 0.0)
    );
}

#[test]
fn shapes_per_config() {
    check_shapes(&tiny_config(), 2, 1);
    check_shapes(&tiny_config(), 2, 3);
    check_shapes(&SsrConfig::cpu_default(), 2, 1);
    let paper = SsrConfig::paper();
    assert_eq!(
        paper.feature_size(),
        (8, 29),
        "TCP's ResNet-34 map for 900x256"
    );
    check_shapes(&paper, 1, 1);
}

#[test]
fn configs_validate_and_bad_ones_name_the_field() {
    for name in SsrConfig::PRESETS {
        SsrConfig::preset(name).unwrap().validate().unwrap();
    }
    let mut bad = SsrConfig::cpu_default();
    bad.bev.heads = 3;
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("bev.heads")
    );
    let mut bad = SsrConfig::cpu_default();
    bad.bev.spatial_points = 5;
    assert!(
        bad.validate()
            .unwrap_err()
            .to_string()
            .contains("spatial_points")
    );
    // A checkpoint's config is untrusted: sizes that would allocate without bound are refused
    // before `init`, each naming its field.
    type Edit = fn(&mut SsrConfig);
    let cases: [(Edit, &str); 5] = [
        (|c| c.tokens.num_tokens = 1 << 30, "tokens.num_tokens"),
        (|c| c.head.hidden_dim = 0, "head.hidden_dim"),
        (|c| c.backbone.blocks[2] = 10_000, "backbone.blocks"),
        (|c| c.bev.grid.x_max = f32::INFINITY, "bev ranges"),
        (
            |c| {
                c.channels = 8192;
                c.bev.layers = 64;
            },
            "weights",
        ),
    ];
    for (edit, field) in cases {
        let mut bad = SsrConfig::cpu_default();
        edit(&mut bad);
        let error = bad.validate().unwrap_err().to_string();
        assert!(error.contains(field), "{field}: {error}");
    }
    assert!(
        SsrConfig::from_name_or_file("no-such-preset")
            .unwrap_err()
            .to_string()
            .contains("neither a preset")
    );
}

#[test]
fn first_frame_ignores_the_previous_bev_and_later_frames_use_it() {
    let device = Device::flex();
    let config = tiny_config();
    let model = config.init(&device).valid();
    let mut first = model_input(&config, 1, 1, false, &device);
    let a = float_values(model.forward(&first).bev);
    first.previous_bev = first.previous_bev.clone().mul_scalar(-3.0).add_scalar(5.0);
    let b = float_values(model.forward(&first).bev);
    assert!(
        max_abs_diff(a, b) < 1e-5,
        "no previous BEV means its values cannot matter"
    );

    let mut later = model_input(&config, 1, 1, true, &device);
    let a = float_values(model.forward(&later).bev);
    later.previous_bev = later.previous_bev.clone().mul_scalar(-3.0).add_scalar(5.0);
    let b = float_values(model.forward(&later).bev);
    assert!(
        max_abs_diff(a, b) > 1e-3,
        "the previous BEV feeds temporal self-attention"
    );
}

#[test]
fn temporal_alignment_moves_a_static_blob_by_the_ego_motion() {
    let device = Device::flex();
    let config = SsrConfig::cpu_default();
    let grid = config.bev.grid;
    // A landmark at world (20, 5); the ego was at the origin heading east, then moved.
    let previous_pose = Pose2::new(0.0, 0.0, 0.0);
    let current_pose = Pose2::new(3.0, 1.5, 0.3);
    let landmark = [20.0f32, 5.0];
    let previous_cell = grid.cell_of(landmark).unwrap(); // previous ego frame == world here
    let mut values = vec![0.0f32; grid.cells() * 2];
    values[previous_cell * 2] = 1.0;
    let previous = float_tensor(values, [1, grid.cells(), 2], &device);

    let motion = EgoMotion::between(previous_pose, current_pose);
    let points: Vec<f32> = (0..grid.cells())
        .flat_map(|i| grid.normalised(motion.to_previous(grid.cell_centre(i))))
        .collect();
    let aligned = float_values(align_previous_bev(
        previous,
        grid.rows,
        grid.cols,
        float_tensor(points, [1, grid.cells(), 2], &device),
    ));

    // Where the landmark is in the current ego frame, by hand.
    let (s, c) = current_pose.yaw.sin_cos();
    let (wx, wy) = (landmark[0] - current_pose.x, landmark[1] - current_pose.y);
    let expected = grid.cell_of([c * wx + s * wy, -s * wx + c * wy]).unwrap();
    let channel0: Vec<f32> = aligned.chunks(2).map(|v| v[0]).collect();
    let (peak, value) =
        channel0.iter().enumerate().fold(
            (0, 0.0),
            |best, (i, v)| if *v > best.1 { (i, *v) } else { best },
        );
    let (pr, pc, er, ec) = (
        peak / grid.cols,
        peak % grid.cols,
        expected / grid.cols,
        expected % grid.cols,
    );
    assert!(value > 0.2, "the blob survives alignment ({value})");
    assert!(
        pr.abs_diff(er) <= 1 && pc.abs_diff(ec) <= 1,
        "peak at ({pr},{pc}), expected ({er},{ec})"
    );
    assert!(channel0.iter().sum::<f32>() > 0.5, "mass is kept");
    assert!(aligned.chunks(2).all(|v| v[1] == 0.0));
}

#[test]
fn token_attention_rows_sum_to_one() {
    let device = Device::flex();
    let config = tiny_config();
    let model = config.init(&device).valid();
    let out = model.forward(&model_input(&config, 2, 1, true, &device));
    let q = config.bev.grid.cells();
    for row in float_values(out.scene.attention.unwrap()).chunks(q) {
        assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-4);
        assert!(row.iter().all(|w| *w >= 0.0));
    }
}

#[test]
fn command_and_target_point_change_the_gate_unless_it_reads_the_command_only() {
    let device = Device::flex();
    let gate = NavigationGate::new(16, true, &device);
    let onehot = |i: usize| {
        let mut v = vec![0.0; 6];
        v[i] = 1.0;
        float_tensor(v, [1, 6], &device)
    };
    let target = |x: f32, y: f32| float_tensor(vec![x, y], [1, 2], &device);
    let base = float_values(gate.forward(onehot(3), target(10.0, 0.0)));
    let other_command = float_values(gate.forward(onehot(0), target(10.0, 0.0)));
    let other_target = float_values(gate.forward(onehot(3), target(10.0, 8.0)));
    assert!(base.iter().all(|g| *g > 0.0 && *g < 1.0));
    assert!(max_abs_diff(base.clone(), other_command) > 1e-3);
    assert!(max_abs_diff(base, other_target) > 1e-3);

    let command_only = NavigationGate::new(16, false, &device);
    let base = float_values(command_only.forward(onehot(3), target(10.0, 0.0)));
    let other_command = float_values(command_only.forward(onehot(0), target(10.0, 0.0)));
    let other_target = float_values(command_only.forward(onehot(3), target(10.0, 8.0)));
    assert!(max_abs_diff(base.clone(), other_command) > 1e-3);
    assert_eq!(max_abs_diff(base, other_target), 0.0);
}

/// Both sampler implementations (the fused CPU loop in inference, tensor ops under autodiff)
/// against `grid_sample_2d`.
#[test]
fn sampler_matches_grid_sample() {
    for device in [Device::flex(), Device::flex().autodiff()] {
        assert_eq!(
            cpu_kernels::is_flex_inference(&device),
            !device.is_autodiff()
        );
        let (n, c, h, w, l) = (3, 5, 6, 9, 40);
        let maps = Tensor::<4>::random([n, c, h, w], Distribution::Normal(0.0, 1.0), &device);
        // Inside, on the border, and outside the map.
        let locations = Tensor::<3>::random([n, l, 2], Distribution::Uniform(-0.3, 1.3), &device);
        let reference = maps
            .clone()
            .grid_sample_2d(
                locations
                    .clone()
                    .mul_scalar(2.0)
                    .sub_scalar(1.0)
                    .reshape([n, l, 1, 2]),
                GridSampleOptions::default(),
            )
            .reshape([n, c, l])
            .swap_dims(1, 2);
        let values = maps.reshape([n, c, h * w]).swap_dims(1, 2);
        let ours = bilinear_sample(values, h, w, locations);
        let diff = max_abs_diff(float_values(ours), float_values(reference));
        assert!(
            diff < 1e-5,
            "bilinear_sample on {device:?} differs from grid_sample_2d by {diff}"
        );
    }
}

/// The fused CPU aggregation equals the tensor-op form for weighted multi-point sums,
/// including points outside the map and a non-contiguous value tensor, in inference and in
/// training, where its gradients with respect to values, locations and weights match too.
#[test]
fn fused_aggregation_matches_tensor_ops() {
    let (n, hw_c, h, w, q, p) = (2, 8, 5, 7, 30, 6);
    let device = Device::flex().autodiff();
    let values = Tensor::<3>::random([n, hw_c, h * w], Distribution::Normal(0.0, 1.0), &device)
        .swap_dims(1, 2)
        .require_grad();
    // Inside, near the border, and far enough outside to be clamped.
    let locations =
        Tensor::<4>::random([n, q, p, 2], Distribution::Uniform(-0.5, 1.5), &device).require_grad();
    let weights =
        Tensor::<3>::random([n, q, p], Distribution::Uniform(-1.0, 1.0), &device).require_grad();

    let inference = deformable_aggregate(
        values.clone().inner(),
        h,
        w,
        locations.clone().inner(),
        weights.clone().inner(),
    );
    let fused = deformable_aggregate(values.clone(), h, w, locations.clone(), weights.clone());
    let reference = deformable_aggregate_by_tensor_ops(
        values.clone(),
        h,
        w,
        locations.clone(),
        weights.clone(),
    );
    assert_eq!(fused.dims(), [n, q, hw_c]);
    let expected = float_values(reference.clone());
    for (path, output) in [("inference", inference), ("autodiff", fused.clone())] {
        let diff = max_abs_diff(float_values(output), expected.clone());
        assert!(
            diff < 1e-5,
            "fused ({path}) and tensor-op aggregation differ by {diff}"
        );
    }

    let grads = backward_both(fused, reference);
    grads.assert_match("values", &values);
    grads.assert_match("weights", &weights);
    grads.assert_match("locations", &locations);
}

/// The fused max pool equals Burn's for the stem's window and others, on even and odd sizes,
/// and lets NaN win as Burn's does.
#[test]
fn fused_max_pool_matches_burn() {
    let device = Device::flex();
    for (kernel, stride, padding) in [(3, 2, 1), (2, 2, 0), (3, 1, 1)] {
        for [h, w] in [[48, 160], [7, 9], [1, 2]] {
            if h + 2 * padding < kernel || w + 2 * padding < kernel {
                continue;
            }
            let x = Tensor::<4>::random([2, 3, h, w], Distribution::Normal(0.0, 1.0), &device);
            let expected = MaxPool2dConfig::new([kernel, kernel])
                .with_strides([stride, stride])
                .with_padding(PaddingConfig2d::Explicit(
                    padding, padding, padding, padding,
                ))
                .init()
                .forward(x.clone());
            let actual = cpu_kernels::max_pool2d(x, kernel, stride, padding);
            assert_eq!(
                actual.dims(),
                expected.dims(),
                "{kernel}/{stride}/{padding} {h}x{w}"
            );
            assert_eq!(float_values(actual), float_values(expected));
        }
    }
    let mut values = vec![0.0f32; 16];
    values[5] = f32::NAN;
    let x = float_tensor(values, [1, 1, 4, 4], &device);
    let pooled = float_values(cpu_kernels::max_pool2d(x, 3, 2, 1));
    assert_eq!(
        pooled.iter().filter(|v| v.is_nan()).count(),
        4,
        "{pooled:?}"
    );
}

/// The fused convolution equals Burn's for the backbone's geometries and a few more: every
/// kernel, stride and padding it meets, with and without bias, batch 1 and 3, odd sizes; in
/// inference and in training, where its gradients with respect to the input, the weight and
/// the bias match Burn's too.
#[test]
fn fused_convolution_matches_burn() {
    let device = Device::flex().autodiff();
    // (cin, cout, kernel, stride, padding, height, width)
    let cases = [
        (3, 8, 3, 1, 1, 9, 13),
        (4, 6, 3, 2, 1, 9, 13),
        (5, 7, 1, 2, 0, 8, 11),
        (6, 5, 1, 1, 0, 7, 7),
        (3, 4, 7, 2, 3, 15, 21),
        (2, 3, 4, 1, 0, 6, 5),
    ];
    let random = |shape: [usize; 4], std: f64| {
        Tensor::<4>::random(shape, Distribution::Normal(0.0, std), &device).require_grad()
    };
    for (cin, cout, kernel, stride, padding, h, w) in cases {
        for (batch, bias) in [(1, false), (3, true)] {
            let x = random([batch, cin, h, w], 1.0);
            let weight = random([cout, cin, kernel, kernel], 0.3);
            let bias = bias.then(|| {
                Tensor::<1>::random([cout], Distribution::Normal(0.0, 1.0), &device).require_grad()
            });
            let case =
                format!("{cin}->{cout} k{kernel} s{stride} p{padding} {h}x{w} batch {batch}");
            let expected = burn::tensor::module::conv2d(
                x.clone(),
                weight.clone(),
                bias.clone(),
                ConvOptions::new([stride, stride], [padding, padding], [1, 1], 1),
            );
            let fused = |x: Tensor<4>, weight: Tensor<4>, bias: Option<Tensor<1>>| {
                cpu_kernels::conv2d(x, weight, bias, [stride, stride], [padding, padding])
            };
            let inference = fused(
                x.clone().inner(),
                weight.clone().inner(),
                bias.clone().map(Tensor::inner),
            );
            let actual = fused(x.clone(), weight.clone(), bias.clone());
            assert_eq!(actual.dims(), expected.dims(), "{case}");
            assert_outputs_match(&case, inference, &actual, &expected, 1e-4);

            let grads = backward_both(actual, expected);
            grads.assert_match(&format!("{case}: input"), &x);
            grads.assert_match(&format!("{case}: weight"), &weight);
            if let Some(bias) = bias {
                grads.assert_match(&format!("{case}: bias"), &bias);
            }
        }
    }
}

/// The fused layer norm equals Burn's `LayerNorm` in inference and in training, where its
/// gradients with respect to the input, gamma and beta match too.
#[test]
fn fused_layer_norm_matches_burn() {
    let device = Device::flex().autodiff();
    let epsilon = 1e-5;
    for [rows, d] in [[150, 24], [7, 5]] {
        let mut norm = LayerNormConfig::new(d).with_epsilon(epsilon).init(&device);
        let parameter = |mean: f64| {
            Param::from_tensor(
                Tensor::<1>::random([d], Distribution::Normal(mean, 0.5), &device).require_grad(),
            )
        };
        norm.gamma = parameter(1.0);
        norm.beta = Some(parameter(0.0));
        let (gamma, beta) = (norm.gamma.val(), norm.beta.as_ref().expect("beta").val());
        let x =
            Tensor::<2>::random([rows, d], Distribution::Normal(2.0, 3.0), &device).require_grad();
        let case = format!("{rows}x{d}");

        let expected = norm.forward(x.clone());
        let inference = cpu_kernels::layer_norm(
            x.clone().inner(),
            gamma.clone().inner(),
            beta.clone().inner(),
            epsilon,
        );
        let fused = cpu_kernels::layer_norm(x.clone(), gamma.clone(), beta.clone(), epsilon);
        assert_outputs_match(&case, inference, &fused, &expected, 1e-4);

        let grads = backward_both(fused, expected);
        grads.assert_match(&format!("{case}: input"), &x);
        for (name, parameter) in [("gamma", &gamma), ("beta", &beta)] {
            grads.assert_match(&format!("{case}: {name}"), parameter);
        }
    }
}

/// The fused GELU, sigmoid and ReLU equal Burn's in inference and in training, where their
/// input gradients match too.
#[test]
fn fused_activations_match_burn() {
    let device = Device::flex().autodiff();
    // The large case spans several parallel chunks and a partial one; the transposed input is
    // strided.
    for (case, x) in [
        (
            "3x40000",
            Tensor::<2>::random([3, 40_000], Distribution::Normal(0.0, 3.0), &device),
        ),
        (
            "7x5 transposed",
            Tensor::<2>::random([5, 7], Distribution::Normal(0.5, 4.0), &device).transpose(),
        ),
    ] {
        let x = x.require_grad();
        for activation in [Activation::Gelu, Activation::Sigmoid, Activation::Relu] {
            let case = format!("{activation:?} {case}");
            let expected = match activation {
                Activation::Gelu => gelu(x.clone()),
                Activation::Sigmoid => sigmoid(x.clone()),
                Activation::Relu => relu(x.clone()),
            };
            let inference = cpu_kernels::activation(x.clone().inner(), activation);
            let fused = cpu_kernels::activation(x.clone(), activation);
            assert_outputs_match(&case, inference, &fused, &expected, 5e-6);
            backward_both(fused, expected).assert_match(&case, &x);
        }
    }
}

/// The fused batch norm in training equals Burn's `BatchNorm`: the output, the updated running
/// statistics, and the gradients with respect to the input, gamma and beta.
#[test]
fn fused_batch_norm_matches_burn() {
    let device = Device::flex().autodiff();
    for shape in [[8, 5, 9, 11], [1, 3, 2, 3]] {
        let case = format!("{shape:?}");
        let channels = shape[1];
        let parameter = |mean: f64| {
            Param::from_tensor(
                Tensor::<1>::random([channels], Distribution::Normal(mean, 0.5), &device)
                    .require_grad(),
            )
        };
        let (gamma, beta) = (parameter(1.0), parameter(0.0));
        // Two layers with the same parameters and their own running statistics.
        let layer = || {
            let mut layer = BatchNormConfig::new(channels).init(&device);
            layer.gamma = gamma.clone();
            layer.beta = beta.clone();
            layer
        };
        let (reference, fused_layer) = (layer(), FusedBatchNorm::from(layer()));
        let x = Tensor::<4>::random(shape, Distribution::Normal(2.0, 3.0), &device).require_grad();

        let expected = reference.forward(x.clone());
        let fused = fused_layer.forward(x.clone());
        let diff = max_abs_diff(float_values(fused.clone()), float_values(expected.clone()));
        assert!(diff < 1e-4, "{case}: differs from BatchNorm by {diff}");
        for (name, fused, expected) in [
            (
                "running mean",
                &fused_layer.inner().running_mean,
                &reference.running_mean,
            ),
            (
                "running variance",
                &fused_layer.inner().running_var,
                &reference.running_var,
            ),
        ] {
            let diff = max_abs_diff(
                float_values(fused.value_sync()),
                float_values(expected.value_sync()),
            );
            assert!(diff < 1e-5, "{case}: {name} differs by {diff}");
        }

        let grads = backward_both(fused, expected);
        grads.assert_match(&format!("{case}: input"), &x);
        for (name, parameter) in [("gamma", &gamma), ("beta", &beta)] {
            grads.assert_match(&format!("{case}: {name}"), &parameter.val());
        }
    }
}

/// The fused linear layer equals Burn's `Linear` in inference and in training, where its
/// gradients with respect to the input, weight and bias match too.
#[test]
fn fused_linear_matches_burn() {
    let device = Device::flex().autodiff();
    // The first case is large enough to run on all threads; the last input is strided.
    for (rows, inputs, outputs, transposed) in
        [(2400, 24, 40, false), (5, 7, 3, false), (6, 4, 5, true)]
    {
        let case = format!(
            "{rows}x{inputs} to {outputs}{}",
            if transposed { " (transposed)" } else { "" }
        );
        let layer = LinearConfig::new(inputs, outputs).init(&device);
        let x = if transposed {
            Tensor::<3>::random(
                [2, inputs, rows / 2],
                Distribution::Normal(0.5, 2.0),
                &device,
            )
            .swap_dims(1, 2)
        } else {
            Tensor::<3>::random(
                [2, rows / 2, inputs],
                Distribution::Normal(0.5, 2.0),
                &device,
            )
        }
        .require_grad();

        let expected = layer.forward(x.clone());
        let inference = FusedLinear::from(layer.valid()).forward(x.clone().inner());
        let fused = FusedLinear::from(layer.clone()).forward(x.clone());
        assert_outputs_match(&case, inference, &fused, &expected, 1e-4);

        let grads = backward_both(fused, expected);
        grads.assert_match(&format!("{case}: input"), &x);
        grads.assert_match(&format!("{case}: weight"), &layer.weight.val());
        let bias = layer.bias.as_ref().expect("bias").val();
        grads.assert_match(&format!("{case}: bias"), &bias);
    }
}

/// The fused softmax equals Burn's in inference and in training, where its input gradient
/// matches too; other axes than the last fall back to Burn's op.
#[test]
fn fused_softmax_matches_burn() {
    let device = Device::flex().autodiff();
    // Rows of 8 across several parallel tasks, long rows of a transposed (strided) input, and
    // an axis other than the last (Burn's op).
    let cases = [
        (
            "4000x8",
            Tensor::<3>::random([2, 2000, 8], Distribution::Normal(0.0, 3.0), &device),
            2,
        ),
        (
            "transposed",
            Tensor::<3>::random([2, 300, 5], Distribution::Normal(1.0, 2.0), &device)
                .swap_dims(1, 2),
            2,
        ),
        (
            "middle axis",
            Tensor::<3>::random([2, 7, 5], Distribution::Normal(0.0, 2.0), &device),
            1,
        ),
    ];
    for (case, x, dim) in cases {
        let x = x.require_grad();
        let expected = softmax(x.clone(), dim);
        let inference = cpu_kernels::softmax(x.clone().inner(), dim);
        let fused = cpu_kernels::softmax(x.clone(), dim);
        assert_outputs_match(case, inference, &fused, &expected, 1e-6);
        backward_both(fused, expected).assert_match(case, &x);
    }
}

/// The fused kernel's output in inference and with autodiff each equal the reference's to
/// `tolerance`.
fn assert_outputs_match<const D: usize>(
    case: &str,
    inference: Tensor<D>,
    fused: &Tensor<D>,
    expected: &Tensor<D>,
    tolerance: f32,
) {
    for (path, output) in [("inference", inference), ("autodiff", fused.clone())] {
        let diff = max_abs_diff(float_values(output), float_values(expected.clone()));
        assert!(
            diff < tolerance,
            "{case} ({path}): differs from Burn by {diff}"
        );
    }
}

/// The gradients each graph gives its inputs for one shared random output gradient `g` (of
/// `Σ output * g`).
fn backward_both<const D: usize>(fused: Tensor<D>, reference: Tensor<D>) -> BothGradients {
    let output_grad = Tensor::<D>::random(
        reference.dims(),
        Distribution::Normal(0.0, 1.0),
        &reference.device(),
    );
    BothGradients {
        fused: (fused * output_grad.clone()).sum().backward(),
        reference: (reference * output_grad).sum().backward(),
    }
}

/// The fused kernel's graph's gradients beside the reference's.
struct BothGradients {
    fused: Gradients,
    reference: Gradients,
}

impl BothGradients {
    /// Both graphs' gradients with respect to `input` agree to 1e-4 of the reference's largest
    /// magnitude (and it is not zero).
    fn assert_match<const D: usize>(&self, name: &str, input: &Tensor<D>) {
        let gradient = |grads: &Gradients, side: &str| {
            float_values(
                input
                    .grad(grads)
                    .unwrap_or_else(|| panic!("{name}: no {side} gradient")),
            )
        };
        let reference = gradient(&self.reference, "reference");
        let scale = reference.iter().fold(0f32, |m, v| m.max(v.abs()));
        let diff = max_abs_diff(gradient(&self.fused, "fused"), reference);
        assert!(
            scale > 0.1 && diff < 1e-4 * scale,
            "{name} gradients differ by {diff} (largest {scale})"
        );
    }
}

#[test]
fn a_deepened_backbone_computes_exactly_what_it_grew_from() {
    let device = Device::flex();
    let config = tiny_config();
    let mut deeper = config.clone();
    deeper.backbone.blocks = vec![2, 1, 3, 1];
    let shallow = config.init(&device);
    let grown = ssr_agent::model::SsrModel {
        backbone: shallow
            .backbone
            .clone()
            .deepened(&config.backbone, &deeper.backbone, &device)
            .unwrap(),
        ..shallow.clone()
    };
    assert_eq!(grown.num_params(), deeper.init(&device).num_params());
    assert!(grown.num_params() > shallow.num_params());
    let input = model_input(&config, 2, 1, true, &device);
    let (a, b) = (
        shallow.valid().forward(&input),
        grown.valid().forward(&input),
    );
    let same = |x: Tensor<3>, y: Tensor<3>| max_abs_diff(float_values(x), float_values(y));
    assert_eq!(same(a.head.waypoints, b.head.waypoints), 0.0);
    assert_eq!(same(a.bev, b.bev), 0.0);
}

#[test]
fn deepening_refuses_any_other_change_of_the_backbone() {
    let device = Device::flex();
    let config = tiny_config();
    let trunk = || config.init(&device).backbone;
    let other = |change: fn(&mut ssr_agent::model::config::BackboneConfig)| {
        let mut backbone = config.backbone.clone();
        change(&mut backbone);
        backbone
    };
    for to in [
        other(|b| b.blocks = vec![1, 0, 1, 1]),
        other(|b| b.blocks = vec![2, 2, 2]),
        other(|b| b.widths[3] = 32),
        other(|b| b.strides[0] = 2),
    ] {
        let err = trunk()
            .deepened(&config.backbone, &to, &device)
            .unwrap_err();
        assert!(err.contains("does not deepen"), "{err}");
    }
    // A trunk of other stages than the ones it is said to have.
    let said = other(|b| b.blocks = vec![2, 1, 1, 1]);
    let to = other(|b| b.blocks = vec![2, 2, 2, 2]);
    let err = trunk().deepened(&said, &to, &device).unwrap_err();
    assert!(err.contains("the trunk has 4 blocks"), "{err}");
}
