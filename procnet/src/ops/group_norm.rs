//! Group normalisation as one backend operation with a hand-derived backward pass.
//!
//! Composed from tensor operations, a group normalisation records about ten element-wise
//! operations per call in burn's autodiff graph (mean, centre, square, mean, root, divide,
//! scale, shift), and its backward pass about twice as many, each a full pass over the
//! feature map. ProcNet normalises 15 times per frame (four times in every hGRU cell), and
//! on LibTorch this made a training step 1.4 times PyTorch's, whose group normalisation is a
//! single fused kernel each way (`experiments/perception.md`, "Speed").
//!
//! Here the forward pass is the backend's own kernel where it has one (LibTorch's
//! `native_group_norm`; elsewhere the layer normalisation over each group, which flex fuses),
//! and the backward pass is the closed form: with `xhat = (x - mean) rstd` per group and
//! `g = dy w` per channel,
//!
//! ```text
//! dx = rstd (g - mean_group(g) - xhat mean_group(g xhat))
//! dw = sum_{batch, pixels}(dy xhat),   db = sum_{batch, pixels}(dy)
//! ```
//!
//! The tests below check values and gradients against the composed normalisation.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, AutodiffBackend, Backend, TensorMetadata, backend_extension};
use burn::tensor::{Shape, Tensor};

/// PyTorch's default epsilon.
pub const NORM_EPS: f64 = 1e-5;

/// Group normalisation with a per-channel affine map, `[b, c, h, w] -> [b, c, h, w]`:
/// statistics per sample and group of `c / groups` channels (biased variance).
///
/// `weight` and `bias` are `[c]`; `groups` divides `c`.
pub fn group_norm(x: Tensor<4>, weight: Tensor<1>, bias: Tensor<1>, groups: usize) -> Tensor<4> {
    let out = <burn::backend::Dispatch as GroupNormBackend>::group_norm(
        x.into_dispatch(),
        weight.into_dispatch(),
        bias.into_dispatch(),
        groups,
        NORM_EPS,
    );
    Tensor::from_dispatch(out)
}

/// The operation, routed to the backend of its input.
#[backend_extension(
    Flex,
    LibTorch: cfg(feature = "tch"),
    Cube: cfg(feature = "gpu"),
    Autodiff,
)]
pub trait GroupNormBackend: Backend {
    /// See [`group_norm`].
    fn group_norm(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        groups: usize,
        epsilon: f64,
    ) -> FloatTensor<Self> {
        let [b, c, h, w] = dims4::<Self>(&x);
        let n = c / groups * h * w;
        let dtype = x.dtype();
        let ones = Self::float_ones(Shape::new([n]), &x.device(), dtype.into());
        let x = Self::layer_norm(
            Self::float_reshape(x, Shape::new([b, groups, n])),
            ones,
            None,
            epsilon,
        );
        affine::<Self>(
            Self::float_reshape(x, Shape::new([b, c, h * w])),
            weight,
            bias,
            [b, c, h, w],
        )
    }
}

/// What the backward pass needs from the forward pass, per backend.
pub trait GroupNormKernels: Backend {
    /// The normalised output and, per sample and group, the mean and the reciprocal standard
    /// deviation, both `[b, groups, 1]`.
    fn group_norm_with_stats(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        groups: usize,
        epsilon: f64,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        let [b, c, h, w] = dims4::<Self>(&x);
        let n = c / groups * h * w;
        let x = Self::float_reshape(x, Shape::new([b, groups, n]));
        let mean = Self::float_mean_dim(x.clone(), 2);
        let centred = Self::float_sub(x, mean.clone());
        let var = Self::float_mean_dim(Self::float_mul(centred.clone(), centred.clone()), 2);
        let rstd = Self::float_recip(Self::float_sqrt(Self::float_add_scalar(
            var,
            epsilon.into(),
        )));
        let xhat = Self::float_mul(centred, rstd.clone());
        let y = affine::<Self>(
            Self::float_reshape(xhat, Shape::new([b, c, h * w])),
            weight,
            bias,
            [b, c, h, w],
        );
        (y, mean, rstd)
    }
}

fn dims4<B: Backend>(x: &FloatTensor<B>) -> [usize; 4] {
    let shape = x.shape();
    [shape[0], shape[1], shape[2], shape[3]]
}

/// `x [b, c, hw] * weight[c] + bias[c]`, reshaped to `[b, c, h, w]`.
fn affine<B: Backend>(
    x: FloatTensor<B>,
    weight: FloatTensor<B>,
    bias: FloatTensor<B>,
    [b, c, h, w]: [usize; 4],
) -> FloatTensor<B> {
    let weight = B::float_reshape(weight, Shape::new([1, c, 1]));
    let bias = B::float_reshape(bias, Shape::new([1, c, 1]));
    let y = B::float_add(B::float_mul(x, weight), bias);
    B::float_reshape(y, Shape::new([b, c, h, w]))
}

impl GroupNormBackend for burn::backend::Flex {}
impl GroupNormKernels for burn::backend::Flex {}

#[cfg(feature = "gpu")]
impl GroupNormBackend for burn::backend::Cube {}
#[cfg(feature = "gpu")]
impl GroupNormKernels for burn::backend::Cube {}

#[cfg(feature = "tch")]
mod libtorch {
    use burn::backend::LibTorch;
    use burn::backend::libtorch::TchTensor;
    use burn::backend::tensor::FloatTensor;

    use super::{GroupNormBackend, GroupNormKernels, dims4};

    /// LibTorch's fused kernel: one pass for the statistics, one for the output.
    fn native(
        x: &TchTensor,
        weight: &TchTensor,
        bias: &TchTensor,
        groups: usize,
        epsilon: f64,
    ) -> (tch::Tensor, tch::Tensor, tch::Tensor) {
        let [b, c, h, w] = dims4::<LibTorch>(x);
        let i = |v: usize| i64::try_from(v).unwrap_or(i64::MAX);
        x.tensor.native_group_norm(
            Some(&weight.tensor),
            Some(&bias.tensor),
            i(b),
            i(c),
            i(h * w),
            i(groups),
            epsilon,
        )
    }

    impl GroupNormBackend for LibTorch {
        fn group_norm(
            x: FloatTensor<Self>,
            weight: FloatTensor<Self>,
            bias: FloatTensor<Self>,
            groups: usize,
            epsilon: f64,
        ) -> FloatTensor<Self> {
            TchTensor::new(native(&x, &weight, &bias, groups, epsilon).0)
        }
    }

    impl GroupNormKernels for LibTorch {
        fn group_norm_with_stats(
            x: FloatTensor<Self>,
            weight: FloatTensor<Self>,
            bias: FloatTensor<Self>,
            groups: usize,
            epsilon: f64,
        ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
            let b = dims4::<LibTorch>(&x)[0];
            let g = i64::try_from(groups).unwrap_or(i64::MAX);
            let b = i64::try_from(b).unwrap_or(i64::MAX);
            let (y, mean, rstd) = native(&x, &weight, &bias, groups, epsilon);
            (
                TchTensor::new(y),
                TchTensor::new(mean.reshape([b, g, 1])),
                TchTensor::new(rstd.reshape([b, g, 1])),
            )
        }
    }
}

/// The backward pass's inputs: `x`, the weight, the per-group mean and reciprocal standard
/// deviation, and the group count.
type GroupNormState<B> = (
    FloatTensor<B>,
    FloatTensor<B>,
    FloatTensor<B>,
    FloatTensor<B>,
    usize,
);

#[derive(Debug)]
struct GroupNormBackward;

impl<B: Backend> Backward<B, 3> for GroupNormBackward {
    type State = GroupNormState<B>;

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let [node_x, node_weight, node_bias] = ops.parents;
        let dy = grads.consume::<B>(&ops.node);
        let (x, weight, mean, rstd, groups) = ops.state;
        let [b, c, h, w] = dims4::<B>(&x);
        let n = c / groups * h * w;
        let per_group = Shape::new([b, groups, n]);
        let per_channel = Shape::new([b, c, h * w]);

        let xhat = B::float_mul(
            B::float_sub(B::float_reshape(x, per_group.clone()), mean),
            rstd.clone(),
        );
        let dy = B::float_reshape(dy, per_channel.clone());
        // Sums over the batch and the pixels, to `[c]`.
        let channel_sum = |t: FloatTensor<B>| {
            let t = B::float_sum_dim(B::float_sum_dim(t, 2), 0);
            B::float_reshape(t, Shape::new([c]))
        };
        if let Some(node) = node_bias {
            grads.register::<B>(node.id, channel_sum(dy.clone()));
        }
        if let Some(node) = node_weight {
            let xhat_c = B::float_reshape(xhat.clone(), per_channel.clone());
            grads.register::<B>(node.id, channel_sum(B::float_mul(dy.clone(), xhat_c)));
        }
        if let Some(node) = node_x {
            let g = B::float_mul(dy, B::float_reshape(weight, Shape::new([1, c, 1])));
            let g = B::float_reshape(g, per_group);
            let mean_g = B::float_mean_dim(g.clone(), 2);
            let mean_gx = B::float_mean_dim(B::float_mul(g.clone(), xhat.clone()), 2);
            let dx = B::float_sub(B::float_sub(g, mean_g), B::float_mul(xhat, mean_gx));
            let dx = B::float_mul(dx, rstd);
            grads.register::<B>(node.id, B::float_reshape(dx, Shape::new([b, c, h, w])));
        }
    }
}

impl<B, C> GroupNormBackend for Autodiff<B, C>
where
    B: Backend + GroupNormBackend + GroupNormKernels,
    C: CheckpointStrategy,
{
    fn group_norm(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        groups: usize,
        epsilon: f64,
    ) -> FloatTensor<Self> {
        let prep = GroupNormBackward
            .prepare::<C>([x.node(), weight.node(), bias.node()])
            .compute_bound()
            .stateful();
        let x = Self::inner(x);
        let weight = Self::inner(weight);
        let bias = Self::inner(bias);
        match prep {
            OpsKind::Tracked(prep) => {
                let (y, mean, rstd) =
                    B::group_norm_with_stats(x.clone(), weight.clone(), bias, groups, epsilon);
                prep.finish((x, weight, mean, rstd, groups), y)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::group_norm(x, weight, bias, groups, epsilon))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution, Tensor};

    use super::{NORM_EPS, group_norm};

    /// The normalisation composed from tensor operations, differentiated by burn's autodiff:
    /// the independent reference for the fused operation and its hand-derived backward pass.
    fn composed(x: Tensor<4>, weight: Tensor<1>, bias: Tensor<1>, groups: usize) -> Tensor<4> {
        let [b, c, h, w] = x.dims();
        let x = x.reshape([b, groups, c / groups * h * w]);
        let centred = x.clone() - x.mean_dim(2);
        let var = centred.clone().powi_scalar(2).mean_dim(2);
        let y = (centred / (var + NORM_EPS).sqrt()).reshape([b, c, h, w]);
        y * weight.reshape([1, c, 1, 1]) + bias.reshape([1, c, 1, 1])
    }

    fn max_abs_diff<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f32 {
        (a - b).abs().max().into_scalar()
    }

    /// Values and gradients (of a random linear functional of the output) with respect to the
    /// input, weight and bias agree with the composed normalisation, for one group per channel
    /// (the hGRU's) and for groups of several channels (the decoder's).
    fn matches_composed(device: &Device) {
        for groups in [6, 3, 1] {
            let shape = [2, 6, 5, 4];
            let x = Tensor::<4>::random(shape, Distribution::Normal(0.5, 2.0), device);
            let probe = Tensor::<4>::random(shape, Distribution::Normal(0.0, 1.0), device);
            let weight = Tensor::<1>::random([6], Distribution::Uniform(0.5, 1.5), device);
            let bias = Tensor::<1>::random([6], Distribution::Uniform(-1.0, 1.0), device);

            let run = |fused: bool| {
                let ad = device.clone().autodiff();
                let x = Tensor::<4>::from_data(x.to_data(), &ad).require_grad();
                let w = Tensor::<1>::from_data(weight.to_data(), &ad).require_grad();
                let b = Tensor::<1>::from_data(bias.to_data(), &ad).require_grad();
                let y = if fused {
                    group_norm(x.clone(), w.clone(), b.clone(), groups)
                } else {
                    composed(x.clone(), w.clone(), b.clone(), groups)
                };
                let p = Tensor::<4>::from_data(probe.to_data(), &ad);
                let grads = (y.clone() * p).sum().backward();
                let grad = |t: Tensor<4>| {
                    Tensor::<4>::from_data(t.grad(&grads).expect("a gradient").to_data(), device)
                };
                let grad1 = |t: Tensor<1>| {
                    Tensor::<1>::from_data(t.grad(&grads).expect("a gradient").to_data(), device)
                };
                (
                    Tensor::<4>::from_data(y.to_data(), device),
                    grad(x),
                    grad1(w),
                    grad1(b),
                )
            };
            let (y, dx, dw, db) = run(true);
            let (y_ref, dx_ref, dw_ref, db_ref) = run(false);
            assert!(
                max_abs_diff(y.clone(), y_ref.clone()) < 1e-5,
                "groups {groups}: output"
            );
            assert!(
                max_abs_diff(dx, dx_ref) < 1e-5,
                "groups {groups}: input gradient"
            );
            assert!(
                max_abs_diff(dw, dw_ref) < 1e-4,
                "groups {groups}: weight gradient"
            );
            assert!(
                max_abs_diff(db, db_ref) < 1e-4,
                "groups {groups}: bias gradient"
            );
            // Without autodiff: the backend's forward kernel.
            let plain = group_norm(x.clone(), weight.clone(), bias.clone(), groups);
            assert!(
                max_abs_diff(plain, y_ref) < 1e-5,
                "groups {groups}: inference"
            );
        }
    }

    #[test]
    fn fused_group_norm_matches_the_composed_one_on_flex() {
        matches_composed(&Device::flex());
    }

    #[cfg(feature = "tch")]
    #[test]
    fn fused_group_norm_matches_the_composed_one_on_libtorch() {
        matches_composed(&Device::libtorch());
    }
}
