//! The few layers ProcNet is made of, with weights drawn from the project's own seeded
//! generator so that every backend starts from the same numbers.
//!
//! Layouts follow PyTorch's (`[out, in, kh, kw]` for convolutions, `[in, out, kh, kw]` for
//! transposed ones), so that `bench/procnet.py` loads the same safetensors file.

use burn::module::{Module, Param, ParamId};
use burn::tensor::activation;
use burn::tensor::module::conv_transpose2d;
use burn::tensor::ops::ConvTransposeOptions;
use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::ops::{conv_same, group_norm};

/// Draws initial weights; one generator per model, consumed in construction order.
///
/// Parameters get ids in construction order, so that a model rebuilt from the same
/// configuration has the same ids and an optimizer state saved with a checkpoint applies.
pub(crate) struct Init<'a> {
    pub rng: ChaCha8Rng,
    pub device: &'a Device,
    pub next_id: u64,
}

impl Init<'_> {
    fn param<const D: usize>(&mut self, values: Vec<f32>, shape: [usize; D]) -> Param<Tensor<D>> {
        let tensor = Tensor::from_data(TensorData::new(values, shape), self.device);
        self.next_id += 1;
        let mut param = Param::from_tensor(tensor);
        param.id = ParamId::from(self.next_id);
        param
    }

    /// Uniform in [-bound, bound].
    pub fn uniform<const D: usize>(&mut self, shape: [usize; D], bound: f32) -> Param<Tensor<D>> {
        let n = shape.iter().product();
        let values = (0..n)
            .map(|_| self.rng.random_range(-bound..=bound))
            .collect();
        self.param(values, shape)
    }

    pub fn constant<const D: usize>(&mut self, shape: [usize; D], value: f32) -> Param<Tensor<D>> {
        let n = shape.iter().product();
        self.param(vec![value; n], shape)
    }

    /// A `[k, k, s, s]` kernel, orthogonal as a `k x (k s s)` matrix (rows orthonormal when
    /// `k <= k s s`), then made symmetric over its two channel axes: the hGRU's horizontal
    /// kernels (orthogonal initialisation, symmetric weights).
    pub fn orthogonal_symmetric(&mut self, k: usize, s: usize) -> Param<Tensor<4>> {
        let cols = k * s * s;
        // Gram-Schmidt on Gaussian rows (Box-Muller), in f64.
        let mut rows: Vec<Vec<f64>> = Vec::with_capacity(k);
        while rows.len() < k {
            let mut v: Vec<f64> = (0..cols)
                .map(|_| {
                    let u1: f64 = self.rng.random_range(f64::EPSILON..1.0);
                    let u2: f64 = self.rng.random_range(0.0..1.0);
                    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
                })
                .collect();
            for r in &rows {
                let d: f64 = v.iter().zip(r).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(r).for_each(|(a, b)| *a -= d * b);
            }
            let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
            if norm > 1e-6 {
                rows.push(v.into_iter().map(|a| a / norm).collect());
            }
        }
        let at = |o: usize, i: usize, p: usize| rows[o][i * s * s + p];
        let mut values = vec![0f32; k * cols];
        for o in 0..k {
            for i in 0..k {
                for p in 0..s * s {
                    values[(o * k + i) * s * s + p] = (0.5 * (at(o, i, p) + at(i, o, p))) as f32;
                }
            }
        }
        self.param(values, [k, k, s, s])
    }
}

/// A 2-D convolution, stride 1, "same" padding.
#[derive(Module, Debug)]
pub struct Conv {
    /// `[out, in, k, k]`
    pub weight: Param<Tensor<4>>,
    /// `[out]`
    pub bias: Option<Param<Tensor<1>>>,
}

impl Conv {
    /// PyTorch's default initialisation: uniform with bound 1/sqrt(fan_in).
    pub(crate) fn new(init: &mut Init, c_in: usize, c_out: usize, k: usize, bias: bool) -> Self {
        let bound = 1.0 / ((c_in * k * k) as f32).sqrt();
        Self {
            weight: init.uniform([c_out, c_in, k, k], bound),
            bias: bias.then(|| init.uniform([c_out], bound)),
        }
    }

    /// # Shapes
    /// `[b, in, h, w] -> [b, out, h, w]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let [c_out, c_in, k, _] = self.weight.dims();
        if k == 1 {
            // A pointwise convolution is a matrix product over the pixels; as one, its
            // gradients are two more matrix products.
            let [b, _, h, w] = x.dims();
            let y = self
                .weight
                .val()
                .reshape([1, c_out, c_in])
                .matmul(x.reshape([b, c_in, h * w]));
            let y = match &self.bias {
                Some(bias) => y + bias.val().reshape([1, c_out, 1]),
                None => y,
            };
            return y.reshape([b, c_out, h, w]);
        }
        let y = conv_same(x, self.weight.val());
        match &self.bias {
            Some(bias) => y + bias.val().reshape([1, c_out, 1, 1]),
            None => y,
        }
    }
}

/// A 3x3 transposed convolution, stride 2, padding 1, output padding 1, no bias: doubles
/// height and width.
#[derive(Module, Debug)]
pub struct UpConv {
    /// `[in, out, 3, 3]`
    pub weight: Param<Tensor<4>>,
}

impl UpConv {
    pub(crate) fn new(init: &mut Init, c_in: usize, c_out: usize) -> Self {
        // PyTorch computes fan_in of a transposed convolution from weight dim 1.
        let bound = 1.0 / ((c_out * 9) as f32).sqrt();
        Self {
            weight: init.uniform([c_in, c_out, 3, 3], bound),
        }
    }

    /// # Shapes
    /// `[b, in, h, w] -> [b, out, 2h, 2w]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        conv_transpose2d(
            x,
            self.weight.val(),
            None,
            ConvTransposeOptions::new([2, 2], [1, 1], [1, 1], [1, 1], 1),
        )
    }
}

/// Group normalisation with a per-channel affine map.
#[derive(Module, Debug)]
pub struct Norm {
    /// `[channels]`
    pub weight: Param<Tensor<1>>,
    /// `[channels]`
    pub bias: Param<Tensor<1>>,
    pub groups: usize,
}

impl Norm {
    pub(crate) fn new(init: &mut Init, channels: usize, groups: usize, weight: f32) -> Self {
        Self {
            weight: init.constant([channels], weight),
            bias: init.constant([channels], 0.0),
            groups,
        }
    }

    /// # Shapes
    /// `[b, c, h, w] -> [b, c, h, w]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        group_norm(x, self.weight.val(), self.bias.val(), self.groups)
    }
}

/// Groups of the decoder's normalisations: the largest of 8, 4, 2, 1 dividing `channels`.
#[must_use]
pub fn decoder_groups(channels: usize) -> usize {
    [8, 4, 2, 1]
        .into_iter()
        .find(|&g| channels.is_multiple_of(g))
        .unwrap_or(1)
}

/// Per-channel scalars broadcast over a feature map.
pub(crate) fn per_channel(p: &Param<Tensor<1>>) -> Tensor<4> {
    let c = p.dims()[0];
    p.val().reshape([1, c, 1, 1])
}

pub(crate) fn relu(x: Tensor<4>) -> Tensor<4> {
    activation::relu(x)
}
