//! Nearest-neighbour upsampling by 2, with a direct kernel for flex.
//!
//! Composed from burn's operations (a reshape to `[b, c, h, 1, w, 1]`, an expand to
//! `[b, c, h, 2, w, 2]` and a reshape back) the upsampling is a strided view that flex then
//! copies element by element through its strided iterator: 3 % of the closed loop's time
//! with ProcNet on one core (`perf`, recorded tuning clip 2), for two upsamplings a frame.
//! The kernel here writes each input row twice, each value twice along it. Other backends,
//! and flex with autodiff (training), keep the composed form and its gradient.

use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Flex, TensorMetadata, backend_extension};
use burn::tensor::{DType, Shape, Tensor, TensorData};

/// `[b, c, h, w] -> [b, c, 2h, 2w]`, each value repeated over a 2 x 2 block.
pub fn upsample2(x: Tensor<4>) -> Tensor<4> {
    Tensor::from_dispatch(<Dispatch as Upsample2Backend>::upsample2(x.into_dispatch()))
}

/// The operation, routed to the backend of its input.
#[backend_extension(
    Flex,
    LibTorch: cfg(feature = "tch"),
    Cube: cfg(feature = "gpu"),
    Autodiff,
)]
pub trait Upsample2Backend: Backend {
    /// See [`upsample2`].
    fn upsample2(x: FloatTensor<Self>) -> FloatTensor<Self> {
        composed::<Self>(x)
    }
}

/// The upsampling as a reshape, an expand and a reshape.
fn composed<B: Backend>(x: FloatTensor<B>) -> FloatTensor<B> {
    let s = x.shape();
    let [b, c, h, w] = [s[0], s[1], s[2], s[3]];
    let x = B::float_reshape(x, Shape::new([b, c, h, 1, w, 1]));
    let x = B::float_expand(x, Shape::new([b, c, h, 2, w, 2]));
    B::float_reshape(x, Shape::new([b, c, 2 * h, 2 * w]))
}

#[cfg(feature = "tch")]
impl Upsample2Backend for burn::backend::LibTorch {}
#[cfg(feature = "gpu")]
impl Upsample2Backend for burn::backend::Cube {}
/// The composed form, differentiable.
impl<B: Backend + Upsample2Backend, C: CheckpointStrategy> Upsample2Backend for Autodiff<B, C> {}

impl Upsample2Backend for Flex {
    fn upsample2(x: FloatTensor<Self>) -> FloatTensor<Self> {
        let s = x.shape();
        let [b, c, h, w] = [s[0], s[1], s[2], s[3]];
        if x.dtype() != DType::F32 {
            return composed::<Self>(x);
        }
        let x = x.to_contiguous();
        let Some(values) = x.as_slice::<f32>() else {
            return composed::<Self>(x);
        };
        let mut out = vec![0f32; 4 * values.len()];
        if w > 0 {
            for (row, out) in values.chunks_exact(w).zip(out.chunks_exact_mut(4 * w)) {
                let (top, bottom) = out.split_at_mut(2 * w);
                for (v, pair) in row.iter().zip(top.chunks_exact_mut(2)) {
                    pair.fill(*v);
                }
                bottom.copy_from_slice(top);
            }
        }
        FlexTensor::from_data(TensorData::new(out, [b, c, 2 * h, 2 * w]))
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution, Tensor};

    use super::upsample2;

    /// The direct kernel against the composed form, value for value (a copy either way), on
    /// an odd width, several channels and samples.
    #[test]
    fn flex_upsampling_is_the_composed_one() {
        let device = Device::flex();
        let x = Tensor::<4>::random([2, 3, 5, 7], Distribution::Normal(0.0, 1.0), &device);
        let ours = upsample2(x.clone());
        let composed = x
            .reshape([2, 3, 5, 1, 7, 1])
            .expand([2, 3, 5, 2, 7, 2])
            .reshape([2, 3, 10, 14]);
        assert_eq!(ours.dims(), [2, 3, 10, 14]);
        assert_eq!(ours.into_data(), composed.into_data());
    }
}
