//! Timings of a training step and of per-frame inference, for `workcell bench procnet` (the
//! same workload as `bench/procnet.py bench`, so that the two can be compared).

use std::time::Instant;

use burn::module::Module;
use burn::optim::grad_clipping::GradientClippingConfig;
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Tensor, TensorData};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::backend::Backend;
use crate::config::ProcNetConfig;
use crate::error::Result;
use crate::train::{LossConfig, window_loss};

/// Seconds per training step and per inference frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timing {
    pub train_step_s: f64,
    pub infer_frame_s: f64,
}

/// Times `iters` training steps (batch `batch`, window `frames`, Dice + focal + prediction
/// losses, AdamW with clipping) after one warm-up step, then `10 iters` single-frame
/// inferences with batch 1.
pub fn time(
    config: &ProcNetConfig,
    backend: Backend,
    batch: usize,
    frames: usize,
    iters: usize,
) -> Result<Timing> {
    if frames < 2 {
        // As a training window: frame 0 has weight 0, and one frame leaves nothing to fit.
        return Err(crate::error::ProcNetError::Input {
            message: format!("a timed training step needs at least 2 frames, got {frames}"),
        });
    }
    let inner = backend.device()?;
    let device = inner.clone().autodiff();
    let s = config.input_size;
    let c = config.num_classes();
    let planes = config.input_planes();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut random = |shape: [usize; 4], binary: bool| {
        let n = shape.iter().product();
        let v: Vec<f32> = (0..n)
            .map(|_| {
                let r: f32 = rng.random();
                if binary {
                    f32::from(u8::from(r > 0.5))
                } else {
                    r
                }
            })
            .collect();
        TensorData::new(v, shape)
    };
    let x: Vec<TensorData> = (0..frames)
        .map(|_| random([batch, planes, s, s], false))
        .collect();
    let y: Vec<TensorData> = (0..frames)
        .map(|_| random([batch, c, s, s], true))
        .collect();
    let rgb: Vec<Tensor<4>> = x
        .iter()
        .map(|d| Tensor::from_data(d.clone(), &device))
        .collect();
    let target: Vec<Tensor<4>> = y
        .iter()
        .map(|d| Tensor::from_data(d.clone(), &device))
        .collect();

    let mut model = config.init(&device, 0)?;
    let mut optim = AdamWConfig::new()
        .with_grad_clipping(Some(GradientClippingConfig::Norm(1.0)))
        .init();
    let loss = LossConfig {
        focal: 0.0,
        ..LossConfig::default()
    };
    let mut step = |model: crate::model::ProcNetModel| {
        let l = window_loss(&model, &rgb, &target, &loss, None, None);
        let grads = GradientsParams::from_grads(l.total.backward(), &model);
        optim.step(1e-3, model, grads)
    };
    let mut train_step_s = f64::NAN;
    if iters > 0 {
        model = step(model);
        let _ = inner.sync();
        let start = Instant::now();
        for _ in 0..iters {
            model = step(model);
        }
        let _ = inner.sync();
        train_step_s = start.elapsed().as_secs_f64() / iters as f64;
    }

    let model = model.valid();
    let frame = Tensor::<4>::from_data(random([1, planes, s, s], false), &inner);
    let mut state = model.initial_state(1, s, s, &inner);
    let infer = |state| {
        let (out, next) = model.step(frame.clone(), state);
        let _probabilities: Vec<f32> = burn::tensor::activation::sigmoid(out.logits)
            .into_data()
            .try_to_vec()
            .unwrap_or_default();
        next
    };
    for _ in 0..5 {
        state = infer(state);
    }
    let n = if iters == 0 { 100 } else { 10 * iters };
    let start = Instant::now();
    for _ in 0..n {
        state = infer(state);
    }
    let infer_frame_s = start.elapsed().as_secs_f64() / n as f64;
    Ok(Timing {
        train_step_s,
        infer_frame_s,
    })
}
