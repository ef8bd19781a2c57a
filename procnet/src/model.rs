//! ProcNet: PredNet's predictive-coding layers with recurrent representation cells and a
//! segmentation decoder (`reference/PROCNET.md`, "The model per time step").

use burn::module::{Module, Param};
use burn::tensor::module::max_pool2d;
use burn::tensor::ops::MaxPoolOptions;
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::cells::{Cell, CellState};
use crate::config::{Activation, ProcNetConfig};
use crate::error::{ProcNetError, Result};
use crate::nn::{Conv, Init, Norm, UpConv, decoder_groups, relu};
use crate::ops::upsample2;

/// One predictive-coding layer: its prediction of its input, its representation cell and
/// (below the top) the convolution that makes the next layer's input from its error.
#[derive(Module, Debug)]
pub struct Layer {
    /// `Ahat_l = ReLU(conv1x1(R_l))`; absent with the prediction loss off.
    pub predict: Option<Conv>,
    pub cell: Cell,
    /// `A_{l+1} = maxpool2(conv5x5(E_l))`; absent on the top layer.
    pub up: Option<Conv>,
}

/// One decoder stage: `[GroupNorm, ConvTranspose 3x3 stride 2, activation]`.
#[derive(Module, Debug)]
pub struct DecoderStage {
    pub norm: Norm,
    pub upconv: UpConv,
}

/// The network's weights. [`ProcNetModel::step`] advances it by one frame.
#[derive(Module, Debug)]
pub struct ProcNetModel {
    pub layers: Vec<Layer>,
    /// From layer l+1 to layer l, index l.
    pub decoder: Vec<DecoderStage>,
    pub head_norm: Norm,
    /// `conv1x1` to one channel per class, no bias.
    pub head: Conv,
    pub prediction_loss: bool,
    pub axonal_delay: bool,
    pub gelu: bool,
    /// The decoder reads layer 0 even with the prediction loss on
    /// (`ProcNetConfig::decoder_full_resolution`).
    pub decoder_full_resolution: bool,
}

/// The recurrent state of one batch of streams between frames.
#[derive(Debug, Clone)]
pub struct ProcNetState {
    /// Per layer: the representation (and the ConvLSTM's cell state) after the last frame.
    pub cells: Vec<CellState>,
    /// Per layer: the error after the last frame (read with axonal delay).
    pub errors: Vec<Tensor<4>>,
    /// Frames seen since the last reset.
    pub frames: usize,
}

impl ProcNetState {
    /// The same state with `f` applied to every tensor (detach it, move it on or off the
    /// autodiff device).
    #[must_use]
    pub fn map_tensors(self, f: impl Fn(Tensor<4>) -> Tensor<4>) -> Self {
        Self {
            cells: self
                .cells
                .into_iter()
                .map(|c| CellState {
                    h: f(c.h),
                    c: c.c.map(&f),
                })
                .collect(),
            errors: self.errors.into_iter().map(&f).collect(),
            frames: self.frames,
        }
    }
}

/// What one step produces.
#[derive(Debug, Clone)]
pub struct StepOutput {
    /// Per-class logits, `[b, classes, h, w]`; masks are `sigmoid(logits)`.
    pub logits: Tensor<4>,
    /// The predicted frame `clamp(Ahat_0, 0, 1)`, `[b, 3 or 4, h, w]` (prediction loss on).
    pub prediction: Option<Tensor<4>>,
    /// `sum_l mean(E_l)`: the prediction-error loss of this frame (prediction loss on).
    pub prediction_error: Option<Tensor<1>>,
}

impl ProcNetConfig {
    /// Builds a model with weights drawn from `seed`: the same seed gives the same weights on
    /// every backend.
    pub fn init(&self, device: &Device, seed: u64) -> Result<ProcNetModel> {
        self.validate()?;
        let mut init = Init {
            rng: ChaCha8Rng::seed_from_u64(seed),
            device,
            next_id: 0,
        };
        let l_count = self.layers();
        let r = &self.repr_channels;
        let a = &self.input_channels;
        // E_l has 2 a_l channels (positive and negative errors), a_l without prediction.
        let e = |l: usize| if self.prediction_loss { 2 * a[l] } else { a[l] };
        let layers = (0..l_count)
            .map(|l| {
                let predict = self
                    .prediction_loss
                    .then(|| Conv::new(&mut init, r[l], a[l], 1, true));
                let cell_in = e(l) + if l + 1 < l_count { r[l + 1] } else { 0 };
                let cell = Cell::new(&mut init, self.cell, cell_in, r[l], self.cell_kernel);
                let up = (l + 1 < l_count).then(|| Conv::new(&mut init, e(l), a[l + 1], 5, true));
                Layer { predict, cell, up }
            })
            .collect();
        let decoder = (0..l_count - 1)
            .map(|l| DecoderStage {
                norm: Norm::new(&mut init, r[l + 1], decoder_groups(r[l + 1]), 1.0),
                upconv: UpConv::new(&mut init, r[l + 1], r[l]),
            })
            .collect();
        Ok(ProcNetModel {
            layers,
            decoder,
            head_norm: Norm::new(&mut init, r[0], decoder_groups(r[0]), 1.0),
            head: Conv::new(&mut init, r[0], self.num_classes(), 1, false),
            prediction_loss: self.prediction_loss,
            axonal_delay: self.axonal_delay,
            gelu: self.decoder_activation == Activation::Gelu,
            decoder_full_resolution: self.decoder_full_resolution,
        })
    }
}

impl ProcNetModel {
    /// Sets the bias of layer 0's frame prediction `Ahat_0 = ReLU(conv1x1(R_0))` to `bias` in
    /// every colour channel (the parameter keeps its id, so an optimizer state still
    /// applies). The uniform draw of PyTorch's initialisation can start a colour channel
    /// below zero at every pixel (`R_0` is non-negative): that channel then predicts black
    /// and gets no gradient, for good (experiments/perception.md, "A colour channel that never
    /// learns"). A bias about the frames' mean brightness starts every channel alive. Returns
    /// false, changing nothing, for a model without the prediction loss.
    pub fn set_frame_prediction_bias(&mut self, bias: f32) -> bool {
        let Some(param) = self
            .layers
            .first_mut()
            .and_then(|layer| layer.predict.as_mut())
            .and_then(|conv| conv.bias.as_mut())
        else {
            return false;
        };
        let old = param.val();
        let fresh = Tensor::full(old.dims(), bias, &old.device());
        let id = param.id;
        *param = Param::from_tensor(fresh);
        param.id = id;
        true
    }

    /// The same network grown to read the depth plane as a fourth input channel
    /// (`input_channels[0]` 3 -> 4, [`crate::image::depth_plane`]): every weight kept, and
    /// zero weights to and from the depth channel (layer 0's prediction of it, and the columns
    /// of its errors in the layer-0 cell's input and the convolution up), so the grown network
    /// segments exactly as the RGB one did until training gives depth a weight. E_0's
    /// channels `[+RGB, -RGB]` become `[+RGB, +D, -RGB, -D]` (`[RGB, D]` without the
    /// prediction loss). The weights of an RGB run start an RGB-D one this way.
    ///
    /// # Errors
    /// [`ProcNetError::Config`] for a network that does not read RGB alone, or whose
    /// layer-0 hGRU reads its input without a convolution.
    pub fn grow_depth_input(mut self) -> Result<Self> {
        let refuse = |message: String| {
            Err(ProcNetError::Config {
                key: "input_channels".into(),
                message,
            })
        };
        let a0 = self.input_channels(0);
        if a0 != 3 {
            return refuse(format!(
                "grows a network that reads RGB (3 channels), not {a0}"
            ));
        }
        // Zero columns go in before these channels of E_0 (and of whatever follows it).
        let at: &[usize] = if self.prediction_loss { &[3, 6] } else { &[3] };
        let layer = &mut self.layers[0];
        if let Some(predict) = &mut layer.predict {
            grow(&mut predict.weight, 0, &[3]);
            if let Some(bias) = &mut predict.bias {
                let b = bias.val();
                let zero = Tensor::zeros([1], &b.device());
                *bias = Param::from_tensor(Tensor::cat(vec![b, zero], 0).detach());
            }
        }
        match &mut layer.cell {
            Cell::Hgru(c) => match &mut c.input {
                Some(conv) => grow(&mut conv.weight, 1, at),
                None => {
                    return refuse(
                        "the layer-0 hGRU reads its input without a convolution (as many \
                         input as representation channels): nothing to grow"
                            .into(),
                    );
                }
            },
            Cell::ConvLstm(c) => grow(&mut c.gates.weight, 1, at),
            Cell::Conv(c) => grow(&mut c.conv.weight, 1, at),
        }
        if let Some(up) = &mut layer.up {
            grow(&mut up.weight, 1, at);
        }
        Ok(self)
    }

    /// The state before the first frame: zeros.
    #[must_use]
    pub fn initial_state(
        &self,
        batch: usize,
        height: usize,
        width: usize,
        device: &Device,
    ) -> ProcNetState {
        let mut cells = Vec::with_capacity(self.layers.len());
        let mut errors = Vec::with_capacity(self.layers.len());
        for (l, layer) in self.layers.iter().enumerate() {
            let (h, w) = (height >> l, width >> l);
            let k = self.repr_channels(l);
            let zeros = Tensor::zeros([batch, k, h, w], device);
            let c = matches!(layer.cell, Cell::ConvLstm(_)).then(|| zeros.clone());
            cells.push(CellState { h: zeros, c });
            errors.push(Tensor::zeros([batch, self.error_channels(l), h, w], device));
        }
        ProcNetState {
            cells,
            errors,
            frames: 0,
        }
    }

    /// Each frame's output depends on that frame alone (`ProcNetConfig::is_feed_forward`).
    #[must_use]
    pub fn is_feed_forward(&self) -> bool {
        !self.prediction_loss
            && !self.axonal_delay
            && self.layers.iter().all(|l| matches!(l.cell, Cell::Conv(_)))
    }

    fn repr_channels(&self, l: usize) -> usize {
        match &self.layers[l].cell {
            Cell::Hgru(c) => c.alpha.dims()[0],
            Cell::ConvLstm(c) => c.peephole.weight.dims()[1],
            Cell::Conv(c) => c.conv.weight.dims()[0],
        }
    }

    fn input_channels(&self, l: usize) -> usize {
        if l == 0 {
            // Layer 0 always sends its error up: E_0 has 2 a_0 channels, a_0 without the
            // prediction loss.
            let e = self.layers[0]
                .up
                .as_ref()
                .map_or(3, |conv| conv.weight.dims()[1]);
            if self.prediction_loss { e / 2 } else { e }
        } else {
            self.layers[l - 1]
                .up
                .as_ref()
                .map_or(0, |conv| conv.weight.dims()[0])
        }
    }

    fn error_channels(&self, l: usize) -> usize {
        let a = self.input_channels(l);
        if self.prediction_loss { 2 * a } else { a }
    }

    /// Advances the network by one frame.
    ///
    /// # Shapes
    /// `frame: [b, 3 or 4, h, w]` in [0, 1] (RGB, and the depth plane for a network that
    /// reads it) -> logits `[b, classes, h, w]`
    pub fn step(&self, frame: Tensor<4>, state: ProcNetState) -> (StepOutput, ProcNetState) {
        let l_count = self.layers.len();
        let ProcNetState {
            cells: prev_cells,
            errors: prev_errors,
            frames,
        } = state;

        // Bottom-up: each layer compares its input with its prediction from R_l[t-1].
        let mut errors: Vec<Tensor<4>> = Vec::with_capacity(l_count);
        let mut prediction = None;
        let mut prediction_error: Option<Tensor<1>> = None;
        let mut next_input = Some(frame);
        for (l, layer) in self.layers.iter().enumerate() {
            let a = next_input
                .take()
                .expect("each layer makes the next layer's input");
            let e = match &layer.predict {
                Some(predict) => {
                    let a_hat = relu(predict.forward(prev_cells[l].h.clone()));
                    if l == 0 {
                        prediction = Some(a_hat.clone().clamp(0.0, 1.0));
                    }
                    let e = relu(Tensor::cat(vec![a.clone() - a_hat.clone(), a_hat - a], 1));
                    let mean = e.clone().mean();
                    prediction_error = Some(match prediction_error {
                        Some(sum) => sum + mean,
                        None => mean,
                    });
                    e
                }
                None => relu(a),
            };
            errors.push(e);
            // [b, 2 a_l, h, w] -> [b, a_{l+1}, h/2, w/2]
            if let Some(up) = &layer.up {
                let source = if self.axonal_delay {
                    &prev_errors[l]
                } else {
                    &errors[l]
                };
                next_input = Some(max_pool2d(
                    up.forward(source.clone()),
                    MaxPoolOptions::new([2, 2]),
                ));
            }
        }

        // Top-down: each cell reads its error and the (upsampled) representation above.
        let mut cells: Vec<Option<CellState>> = vec![None; l_count];
        let prev_h: Vec<Tensor<4>> = prev_cells.iter().map(|c| c.h.clone()).collect();
        let mut prev_cells: Vec<Option<CellState>> = prev_cells.into_iter().map(Some).collect();
        for l in (0..l_count).rev() {
            let input = if l + 1 == l_count {
                errors[l].clone()
            } else {
                let above = if self.axonal_delay {
                    Some(prev_h[l + 1].clone())
                } else {
                    cells[l + 1].as_ref().map(|c| c.h.clone())
                };
                let above = above.expect("the layer above was stepped first");
                Tensor::cat(vec![errors[l].clone(), upsample2(above)], 1)
            };
            let previous = prev_cells[l].take().expect("one previous state per layer");
            cells[l] = Some(self.layers[l].cell.forward(input, previous));
        }
        let cells: Vec<CellState> = cells.into_iter().flatten().collect();

        let logits = self.decode(&cells);
        (
            StepOutput {
                logits,
                prediction,
                prediction_error,
            },
            ProcNetState {
                cells,
                errors,
                frames: frames + 1,
            },
        )
    }

    /// The segmentation decoder: from the top representation down to full resolution,
    /// adding each lower layer's representation on the way (layer 0 only with the prediction
    /// loss off, where it is not busy predicting the frame, or when asked for).
    fn decode(&self, cells: &[CellState]) -> Tensor<4> {
        let first_read = usize::from(self.prediction_loss && !self.decoder_full_resolution);
        let top = cells.len() - 1;
        let mut x = cells[top].h.clone();
        for l in (0..top).rev() {
            let stage = &self.decoder[l];
            x = stage.upconv.forward(stage.norm.forward(x));
            x = if self.gelu {
                burn::tensor::activation::gelu(x)
            } else {
                relu(x)
            };
            if l >= first_read {
                x = x + cells[l].h.clone();
            }
        }
        self.head.forward(self.head_norm.forward(x))
    }
}

/// Inserts a zero slice along `dim` of a weight before each of the indices `at` (of the
/// weight as it was, ascending).
fn grow(weight: &mut Param<Tensor<4>>, dim: usize, at: &[usize]) {
    let w = weight.val();
    let mut dims = w.dims();
    let end = dims[dim];
    dims[dim] = 1;
    let zero = Tensor::<4>::zeros(dims, &w.device());
    let mut pieces = Vec::with_capacity(2 * at.len() + 1);
    let mut from = 0;
    for &i in at {
        if i > from {
            pieces.push(w.clone().narrow(dim, from, i - from));
        }
        pieces.push(zero.clone());
        from = i;
    }
    if end > from {
        pieces.push(w.narrow(dim, from, end - from));
    }
    // Detached: a leaf, as a parameter must be on an autodiff device.
    *weight = Param::from_tensor(Tensor::cat(pieces, dim).detach());
}

/// Detaches a state from the autodiff graph (the end of a BPTT window).
#[must_use]
pub fn detach(state: ProcNetState) -> ProcNetState {
    state.map_tensors(Tensor::detach)
}
