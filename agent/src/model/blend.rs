//! Weight-space blending of two networks of one config (WiSE-FT, Wortsman et al. 2022: "Robust
//! fine-tuning of zero-shot models"): every float tensor, parameters and batch-norm statistics
//! alike, becomes `(1 - weight) * from + weight * to`. Blending a fine-tuned network with the
//! one it was fine-tuned from keeps much of what each drives well where the two differ, at the
//! cost of nothing at inference (the blend is one network of the same size).
//!
//! The two networks must share their config, so that they hold the same tensors in the same
//! order and shapes; [`blend`] checks every shape and the count, and reports the first
//! mismatch instead of blending tensors that do not correspond.

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param};
use burn::tensor::Tensor;

use super::SsrModel;

/// `(1 - weight) * from + weight * to`, tensor by tensor; `weight` in 0..=1 (0 gives `from`'s
/// weights, 1 `to`'s). Integer and boolean tensors (none in today's network) are `to`'s.
///
/// # Errors
/// A weight outside 0..=1 (or NaN), or networks whose tensors differ in count or shape (their
/// configs differ): the first difference, by position and shapes.
pub fn blend(from: &SsrModel, to: SsrModel, weight: f64) -> Result<SsrModel, String> {
    if !(0.0..=1.0).contains(&weight) {
        return Err(format!("the blend weight must be in 0..=1, not {weight}"));
    }
    let mut collected = Collect(Vec::new());
    from.visit(&mut collected);
    let mut mix = Mix {
        from: collected.0.into_iter(),
        weight,
        at: 0,
        error: None,
    };
    let blended = to.map(&mut mix);
    if let Some(error) = mix.error {
        return Err(error);
    }
    let left = mix.from.len();
    if left > 0 {
        return Err(format!(
            "the first network has {left} float tensors more than the second"
        ));
    }
    Ok(blended)
}

/// Every float tensor of a network in visiting order, flattened, with its shape.
struct Collect(Vec<(Vec<usize>, Tensor<1>)>);

impl ModuleVisitor for Collect {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let tensor = param.val();
        let shape = tensor.dims().to_vec();
        self.0.push((shape, tensor.flatten(0, D - 1)));
    }
}

/// Replaces each float tensor of the network it maps with its blend with the collected one at
/// the same position; the first mismatch is kept and later tensors are left alone.
struct Mix {
    from: std::vec::IntoIter<(Vec<usize>, Tensor<1>)>,
    weight: f64,
    at: usize,
    error: Option<String>,
}

impl ModuleMapper for Mix {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let at = self.at;
        self.at += 1;
        if self.error.is_some() {
            return param;
        }
        let Some((shape, from)) = self.from.next() else {
            self.error = Some(format!(
                "the second network has more float tensors than the first ({at})"
            ));
            return param;
        };
        let to_shape = param.val().dims().to_vec();
        if shape != to_shape {
            self.error = Some(format!(
                "tensor {at} is {shape:?} in the first network and {to_shape:?} in the second"
            ));
            return param;
        }
        let weight = self.weight;
        param.map(|to| {
            let dims: [usize; D] = to.dims();
            from.reshape(dims).mul_scalar(1.0 - weight) + to.mul_scalar(weight)
        })
    }
}
