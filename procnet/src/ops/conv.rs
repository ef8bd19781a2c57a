//! The "same" convolution of the hGRU's horizontal kernels and the bottom-up path (stride 1,
//! odd square kernel, zero padding `k / 2`, no bias), with a direct kernel for flex.
//!
//! burn-flex convolves by im2col and a general matrix product. For ProcNet's shapes (5x5
//! kernels over 16-64 channels, one frame) the product is thin and the copies dominate: the
//! seven 5x5 convolutions of a frame took 9.4 ms against LibTorch's 3.6 ms. The kernel here
//! keeps a block of 4 output channels by 16 pixels in registers and streams the zero-padded
//! input rows past them, so that each input load feeds 4 fused multiply-adds. It serves flex
//! without autodiff (inference); with autodiff and on the other backends the operation is
//! burn's own `conv2d` (and its gradient).

use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::flex::FlexTensor;
use burn::backend::ops::ModuleOps;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Flex, TensorMetadata, backend_extension};
use burn::tensor::ops::ConvOptions;
use burn::tensor::{DType, Tensor, TensorData};
use rayon::prelude::*;

/// `conv2d(x, weight)` with stride 1 and padding `k / 2`: `[b, c_in, h, w]` and
/// `[c_out, c_in, k, k]` (k odd) -> `[b, c_out, h, w]`.
pub fn conv_same(x: Tensor<4>, weight: Tensor<4>) -> Tensor<4> {
    Tensor::from_dispatch(<Dispatch as ConvSameBackend>::conv_same(
        x.into_dispatch(),
        weight.into_dispatch(),
    ))
}

fn same_options(k: usize) -> ConvOptions<2> {
    ConvOptions::new([1, 1], [k / 2, k / 2], [1, 1], 1)
}

/// The operation, routed to the backend of its input.
#[backend_extension(
    Flex,
    LibTorch: cfg(feature = "tch"),
    Cube: cfg(feature = "gpu"),
    Autodiff,
)]
pub trait ConvSameBackend: Backend {
    /// See [`conv_same`].
    fn conv_same(x: FloatTensor<Self>, weight: FloatTensor<Self>) -> FloatTensor<Self> {
        let k = weight.shape()[2];
        Self::conv2d(x, weight, None, same_options(k))
    }
}

#[cfg(feature = "tch")]
impl ConvSameBackend for burn::backend::LibTorch {}
#[cfg(feature = "gpu")]
impl ConvSameBackend for burn::backend::Cube {}
/// burn's differentiable convolution.
impl<B: Backend + ConvSameBackend, C: CheckpointStrategy> ConvSameBackend for Autodiff<B, C> {}

impl ConvSameBackend for Flex {
    fn conv_same(x: FloatTensor<Self>, weight: FloatTensor<Self>) -> FloatTensor<Self> {
        let (xs, ws) = (x.shape(), weight.shape());
        let k = ws[2];
        let direct = x.dtype() == DType::F32
            && weight.dtype() == DType::F32
            && ws[1] == xs[1]
            && ws[3] == k
            && k % 2 == 1;
        if !direct {
            return <Flex as ModuleOps<Flex>>::conv2d(x, weight, None, same_options(k));
        }
        let (x, weight) = (x.to_contiguous(), weight.to_contiguous());
        let (Some(xv), Some(wv)) = (x.as_slice::<f32>(), weight.as_slice::<f32>()) else {
            return <Flex as ModuleOps<Flex>>::conv2d(x, weight, None, same_options(k));
        };
        let [b, c_in, h, w] = [xs[0], xs[1], xs[2], xs[3]];
        let c_out = ws[0];
        let out = direct::conv_same_f32(xv, [b, c_in, h, w], wv, [c_out, k]);
        FlexTensor::from_data(TensorData::new(out, [b, c_out, h, w]))
    }
}

mod direct {
    use super::*;

    /// Output pixels per block: one AVX-512 vector, two AVX2 vectors.
    const LANES: usize = 16;
    /// Output channels per block: each input load feeds this many multiply-adds.
    const CO_BLOCK: usize = 4;

    /// What one block kernel call reads: the padded input of one sample, the reordered
    /// weights of one channel block, and the geometry.
    struct Block<'a> {
        /// `[c_in, hp, wp]`, zero-padded.
        input: &'a [f32],
        /// `[c_in, k, k, CO_BLOCK]`.
        weight: &'a [f32],
        c_in: usize,
        k: usize,
        wp: usize,
        hp: usize,
    }

    /// `[b, c_in, h, w]` (*) `[c_out, c_in, k, k]` -> `[b, c_out, h, w]`.
    pub(super) fn conv_same_f32(
        x: &[f32],
        [b, c_in, h, w]: [usize; 4],
        weight: &[f32],
        [c_out, k]: [usize; 2],
    ) -> Vec<f32> {
        let p = k / 2;
        let blocks_x = w.div_ceil(LANES);
        // Wide enough that every block of LANES outputs reads its k taps in bounds.
        let wp = blocks_x * LANES + 2 * p;
        let hp = h + 2 * p;
        let mut padded = vec![0f32; b * c_in * hp * wp];
        for plane in 0..b * c_in {
            for y in 0..h {
                let src = &x[(plane * h + y) * w..][..w];
                padded[(plane * hp + y + p) * wp + p..][..w].copy_from_slice(src);
            }
        }
        // Weights reordered to [block][c_in][ky][kx][CO_BLOCK], zero past c_out.
        let blocks_c = c_out.div_ceil(CO_BLOCK);
        let taps = c_in * k * k;
        let mut reordered = vec![0f32; blocks_c * taps * CO_BLOCK];
        for o in 0..c_out {
            for t in 0..taps {
                reordered[((o / CO_BLOCK) * taps + t) * CO_BLOCK + o % CO_BLOCK] =
                    weight[o * taps + t];
            }
        }

        let c_pad = blocks_c * CO_BLOCK;
        let mut out = vec![0f32; b * c_pad * h * w];
        out.par_chunks_mut(CO_BLOCK * h * w)
            .enumerate()
            .for_each(|(i, out)| {
                let (sample, block) = (i / blocks_c, i % blocks_c);
                let args = Block {
                    input: &padded[sample * c_in * hp * wp..][..c_in * hp * wp],
                    weight: &reordered[block * taps * CO_BLOCK..][..taps * CO_BLOCK],
                    c_in,
                    k,
                    wp,
                    hp,
                };
                planes(&args, out, h, w);
            });
        if c_pad == c_out {
            return out;
        }
        // Drop the zero channels of the last block.
        let plane = h * w;
        let mut trimmed = Vec::with_capacity(b * c_out * plane);
        for s in 0..b {
            trimmed.extend_from_slice(&out[s * c_pad * plane..][..c_out * plane]);
        }
        trimmed
    }

    /// Picks the widest instruction set this CPU has.
    fn planes(args: &Block, out: &mut [f32], h: usize, w: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            if is_x86_feature_detected!("avx512f") {
                // SAFETY: the CPU has AVX-512F (checked above).
                return unsafe { planes_avx512(args, out, h, w) };
            }
            if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
                if args.k == 5 {
                    // SAFETY: the CPU has AVX2 and FMA (checked above).
                    return unsafe { avx2_k5::planes(args, out, h, w) };
                }
                // SAFETY: the CPU has AVX2 and FMA (checked above).
                return unsafe { planes_avx2(args, out, h, w) };
            }
        }
        planes_generic::<false>(args, out, h, w);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,fma")]
    unsafe fn planes_avx512(args: &Block, out: &mut [f32], h: usize, w: usize) {
        planes_generic::<true>(args, out, h, w);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn planes_avx2(args: &Block, out: &mut [f32], h: usize, w: usize) {
        planes_generic::<true>(args, out, h, w);
    }

    /// ProcNet's 5x5 kernels on AVX2: the generic kernel's loops, with the taps of a kernel
    /// row unrolled and the 4 x 16 accumulators held in eight registers. Written out because
    /// the compiler, given the generic loops, copies the accumulators between registers on
    /// every tap and checks bounds three times a tap (`objdump` of `planes_avx2`): the
    /// network's convolutions ran at about 12 GMAC/s on one core of this project's machine.
    #[cfg(target_arch = "x86_64")]
    mod avx2_k5 {
        use super::{Block, CO_BLOCK, LANES};
        use std::arch::x86_64::{
            __m256, _mm256_broadcast_ss, _mm256_fmadd_ps, _mm256_loadu_ps, _mm256_setzero_ps,
            _mm256_storeu_ps,
        };

        const K: usize = 5;

        /// `CO_BLOCK` output planes `[CO_BLOCK, h, w]` of a 5x5 kernel.
        ///
        /// # Safety
        /// The CPU has AVX2 and FMA.
        #[target_feature(enable = "avx2,fma")]
        pub(super) unsafe fn planes(args: &Block, out: &mut [f32], h: usize, w: usize) {
            let Block {
                input,
                weight,
                c_in,
                k,
                wp,
                hp,
            } = *args;
            // What every pointer below stays inside: the padded rows hold the k taps of
            // every block of LANES outputs (`wp` is the blocks' width plus the padding), the
            // weights are `[c_in, K, K, CO_BLOCK]`, the output `[CO_BLOCK, h, w]`.
            assert!(k == K && hp == h + K - 1 && wp >= w.div_ceil(LANES) * LANES + K - 1);
            assert!(input.len() >= c_in * hp * wp && weight.len() >= c_in * K * K * CO_BLOCK);
            assert!(out.len() >= CO_BLOCK * h * w);
            let (input, weight) = (input.as_ptr(), weight.as_ptr());
            for y in 0..h {
                for x0 in (0..w).step_by(LANES) {
                    let mut acc = [[_mm256_setzero_ps(); 2]; CO_BLOCK];
                    for c in 0..c_in {
                        for ky in 0..K {
                            // SAFETY: row `c * hp + y + ky < c_in * hp` and columns
                            // `x0 + kx .. x0 + kx + LANES <= wp` for kx < K (asserted above);
                            // the tap's weights are inside `[c_in, K, K, CO_BLOCK]`.
                            unsafe {
                                let row = input.add((c * hp + y + ky) * wp + x0);
                                let taps = weight.add((c * K + ky) * K * CO_BLOCK);
                                tap_row(&mut acc, row, taps);
                            }
                        }
                    }
                    let n = LANES.min(w - x0);
                    for (o, acc) in acc.iter().enumerate() {
                        let mut lanes = [0f32; LANES];
                        // SAFETY: `lanes` holds two vectors of 8.
                        unsafe {
                            _mm256_storeu_ps(lanes.as_mut_ptr(), acc[0]);
                            _mm256_storeu_ps(lanes.as_mut_ptr().add(8), acc[1]);
                        }
                        out[(o * h + y) * w + x0..][..n].copy_from_slice(&lanes[..n]);
                    }
                }
            }
        }

        /// The K taps of one kernel row into the accumulators.
        ///
        /// # Safety
        /// `row` has `LANES + K - 1` readable floats, `taps` `K * CO_BLOCK`.
        #[inline(always)]
        unsafe fn tap_row(acc: &mut [[__m256; 2]; CO_BLOCK], row: *const f32, taps: *const f32) {
            for kx in 0..K {
                // SAFETY: inside `row` and `taps` (the function's contract).
                unsafe {
                    let lo = _mm256_loadu_ps(row.add(kx));
                    let hi = _mm256_loadu_ps(row.add(kx + 8));
                    for (o, acc) in acc.iter_mut().enumerate() {
                        let wk = _mm256_broadcast_ss(&*taps.add(kx * CO_BLOCK + o));
                        acc[0] = _mm256_fmadd_ps(wk, lo, acc[0]);
                        acc[1] = _mm256_fmadd_ps(wk, hi, acc[1]);
                    }
                }
            }
        }
    }

    /// `CO_BLOCK` output planes `[CO_BLOCK, h, w]`; `FMA` fuses the multiply-adds (only where
    /// the CPU has the instruction: elsewhere `mul_add` is a slow library call).
    #[inline(always)]
    fn planes_generic<const FMA: bool>(args: &Block, out: &mut [f32], h: usize, w: usize) {
        let Block {
            input,
            weight,
            c_in,
            k,
            wp,
            hp,
        } = *args;
        for y in 0..h {
            for x0 in (0..w).step_by(LANES) {
                let mut acc = [[0f32; LANES]; CO_BLOCK];
                for c in 0..c_in {
                    for ky in 0..k {
                        let row = &input[(c * hp + y + ky) * wp + x0..];
                        let taps = &weight[(c * k + ky) * k * CO_BLOCK..][..k * CO_BLOCK];
                        for kx in 0..k {
                            let src: [f32; LANES] = row[kx..kx + LANES]
                                .try_into()
                                .expect("the padded row holds every block's taps");
                            let wk: [f32; CO_BLOCK] = taps[kx * CO_BLOCK..][..CO_BLOCK]
                                .try_into()
                                .expect("CO_BLOCK weights per tap");
                            for o in 0..CO_BLOCK {
                                for l in 0..LANES {
                                    acc[o][l] = if FMA {
                                        wk[o].mul_add(src[l], acc[o][l])
                                    } else {
                                        acc[o][l] + wk[o] * src[l]
                                    };
                                }
                            }
                        }
                    }
                }
                let n = LANES.min(w - x0);
                for (o, acc) in acc.iter().enumerate() {
                    out[(o * h + y) * w + x0..][..n].copy_from_slice(&acc[..n]);
                }
            }
        }
    }

    #[cfg(all(test, target_arch = "x86_64"))]
    mod tests {
        use super::*;
        use rand::{Rng, SeedableRng};
        use rand_chacha::ChaCha8Rng;

        /// The written-out 5x5 kernel does the generic kernel's fused multiply-adds in the
        /// same order, so its planes are the same to the bit (where the CPU has AVX2 and FMA):
        /// a full and a partial block of pixels, one and several input channels.
        #[test]
        fn the_avx2_5x5_kernel_is_the_generic_one_to_the_bit() {
            if !(is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")) {
                return;
            }
            let mut rng = ChaCha8Rng::seed_from_u64(5);
            for (c_in, h, w) in [(1, 3, 5), (3, 7, 21), (16, 16, 32), (8, 5, 16usize)] {
                let k = 5usize;
                let wp = w.div_ceil(LANES) * LANES + k - 1;
                let hp = h + k - 1;
                let input: Vec<f32> = (0..c_in * hp * wp)
                    .map(|_| rng.random_range(-1.0..1.0))
                    .collect();
                let weight: Vec<f32> = (0..c_in * k * k * CO_BLOCK)
                    .map(|_| rng.random_range(-0.3..0.3))
                    .collect();
                let args = Block {
                    input: &input,
                    weight: &weight,
                    c_in,
                    k,
                    wp,
                    hp,
                };
                let mut generic = vec![0f32; CO_BLOCK * h * w];
                let mut written = vec![f32::NAN; CO_BLOCK * h * w];
                // SAFETY: the CPU has AVX2 and FMA (checked above).
                unsafe {
                    planes_avx2(&args, &mut generic, h, w);
                    avx2_k5::planes(&args, &mut written, h, w);
                }
                let differ = generic
                    .iter()
                    .zip(&written)
                    .filter(|(a, b)| a.to_bits() != b.to_bits())
                    .count();
                assert_eq!(
                    differ,
                    0,
                    "{c_in} channels, {h}x{w}: {differ} of {} outputs differ",
                    generic.len()
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::conv2d;
    use burn::tensor::{Device, Distribution, Tensor};

    use super::{conv_same, same_options};

    /// The direct kernel against burn-flex's own convolution, on shapes that exercise the
    /// partial pixel block (width 21), a partial channel block (6 outputs), several samples
    /// and both kernel sizes the model uses.
    #[test]
    fn flex_direct_convolution_matches_burns() {
        let device = Device::flex();
        for (b, c_in, c_out, h, w, k) in [
            (1, 16, 16, 64, 64, 5),
            (2, 3, 6, 7, 21, 5),
            (3, 5, 4, 9, 16, 3),
            (1, 2, 8, 5, 5, 1),
        ] {
            let x = Tensor::<4>::random([b, c_in, h, w], Distribution::Normal(0.0, 1.0), &device);
            let weight =
                Tensor::<4>::random([c_out, c_in, k, k], Distribution::Normal(0.0, 0.2), &device);
            let ours = conv_same(x.clone(), weight.clone());
            let burns = conv2d(x, weight, None, same_options(k));
            assert_eq!(ours.dims(), burns.dims());
            let worst: f32 = (ours - burns).abs().max().into_scalar();
            assert!(worst < 1e-4, "{b}x{c_in}->{c_out} {h}x{w} k{k}: {worst}");
        }
    }
}
