//! The representation cells: hGRU, ConvLSTM and a plain convolution
//! (`reference/PROCNET.md`, "hGRU cell" and "ConvLSTM variant").

use burn::module::{Module, Param};
use burn::tensor::Tensor;
use burn::tensor::activation::{sigmoid, tanh};

use crate::config::CellKind;
use crate::nn::{Conv, Init, Norm, per_channel, relu};
use crate::ops::conv_same;

/// The state a cell carries from one frame to the next.
#[derive(Debug, Clone)]
pub struct CellState {
    /// The representation R_l, `[b, k, h, w]`.
    pub h: Tensor<4>,
    /// The ConvLSTM's cell state (absent for the other cells), `[b, k, h, w]`.
    pub c: Option<Tensor<4>>,
}

/// Horizontal gated recurrent unit (Linsley et al. 2018), as ProcNet uses it.
#[derive(Module, Debug)]
pub struct Hgru {
    /// Maps the input to `k` channels when it has another count.
    pub input: Option<Conv>,
    pub u1: Conv,
    pub u2: Conv,
    /// `[k, k, s, s]`, symmetric over its two channel axes.
    pub w_inh: Param<Tensor<4>>,
    /// `[k, k, s, s]`, symmetric over its two channel axes.
    pub w_exc: Param<Tensor<4>>,
    pub alpha: Param<Tensor<1>>,
    pub mu: Param<Tensor<1>>,
    pub gamma: Param<Tensor<1>>,
    pub kappa: Param<Tensor<1>>,
    pub omega: Param<Tensor<1>>,
    pub n0: Norm,
    pub n1: Norm,
    pub n2: Norm,
    pub n3: Norm,
}

impl Hgru {
    pub(crate) fn new(init: &mut Init, c_in: usize, k: usize, kernel: usize) -> Self {
        Self {
            input: (c_in != k).then(|| Conv::new(init, c_in, k, 1, true)),
            u1: Conv::new(init, k, k, 1, true),
            u2: Conv::new(init, k, k, 1, true),
            w_inh: init.orthogonal_symmetric(k, kernel),
            w_exc: init.orthogonal_symmetric(k, kernel),
            alpha: init.constant([k], 0.1),
            mu: init.constant([k], 1.0),
            gamma: init.constant([k], 1.0),
            kappa: init.constant([k], 0.5),
            omega: init.constant([k], 0.5),
            n0: Norm::new(init, k, k, 0.1),
            n1: Norm::new(init, k, k, 0.1),
            n2: Norm::new(init, k, k, 0.1),
            n3: Norm::new(init, k, k, 0.1),
        }
    }

    /// The horizontal kernel as used: `(W + W^T) / 2` over the channel axes. The stored
    /// weights are symmetric already; using the symmetric part makes the gradient of the
    /// stored weights symmetric too, so they stay symmetric under any optimiser.
    fn symmetric(w: &Param<Tensor<4>>) -> Tensor<4> {
        let w = w.val();
        (w.clone() + w.swap_dims(0, 1)) * 0.5
    }

    /// # Shapes
    /// `x: [b, c_in, h, w]`, `h: [b, k, h, w]` -> `[b, k, h, w]`
    pub fn forward(&self, x: Tensor<4>, h: Tensor<4>) -> Tensor<4> {
        let x = match &self.input {
            Some(conv) => conv.forward(x),
            None => x,
        };
        let w_inh = Self::symmetric(&self.w_inh);
        let w_exc = Self::symmetric(&self.w_exc);
        let conv = conv_same;

        // Inhibition: gated by g1, scaled by alpha h + mu.
        let g1 = sigmoid(self.n0.forward(self.u1.forward(h.clone())));
        let c1 = self.n1.forward(conv(h.clone() * g1, w_inh));
        let inhibition = relu(c1 * (per_channel(&self.alpha) * h.clone() + per_channel(&self.mu)));
        let h1 = relu(x - inhibition);

        // Excitation: linear, quadratic and the mix gate g2.
        let g2 = sigmoid(self.n2.forward(self.u2.forward(h1.clone())));
        let c2 = self.n3.forward(conv(h1.clone(), w_exc));
        let h_tilde = relu(
            per_channel(&self.kappa) * h1.clone()
                + per_channel(&self.gamma) * c2.clone()
                + per_channel(&self.omega) * h1 * c2,
        );
        h.clone() + g2 * (h_tilde - h)
    }
}

/// Convolutional LSTM with peephole convolutions on the previous cell state.
#[derive(Module, Debug)]
pub struct ConvLstm {
    /// Gates i, f, g, o from the input and hidden state: `[4k, c_in + k, s, s]`.
    pub gates: Conv,
    /// Peepholes on the previous cell state for i, f, o: `[3k, k, s, s]`, no bias.
    pub peephole: Conv,
}

impl ConvLstm {
    pub(crate) fn new(init: &mut Init, c_in: usize, k: usize, kernel: usize) -> Self {
        Self {
            gates: Conv::new(init, c_in + k, 4 * k, kernel, true),
            peephole: Conv::new(init, k, 3 * k, kernel, false),
        }
    }

    /// # Shapes
    /// `x: [b, c_in, h, w]`, `h, c: [b, k, h, w]` -> `(h', c')`
    pub fn forward(&self, x: Tensor<4>, h: Tensor<4>, c: Tensor<4>) -> (Tensor<4>, Tensor<4>) {
        let gates = self.gates.forward(Tensor::cat(vec![x, h], 1));
        let peep = self.peephole.forward(c.clone());
        let [i, f, g, o] = chunk4(gates);
        let [pi, pf, po] = chunk3(peep);
        let c_new = sigmoid(f + pf) * c + sigmoid(i + pi) * tanh(g);
        let h_new = sigmoid(o + po) * tanh(c_new.clone());
        (h_new, c_new)
    }
}

fn chunk4(x: Tensor<4>) -> [Tensor<4>; 4] {
    let mut parts = x.chunk(4, 1).into_iter();
    std::array::from_fn(|_| parts.next().expect("4 chunks of a 4k-channel tensor"))
}

fn chunk3(x: Tensor<4>) -> [Tensor<4>; 3] {
    let mut parts = x.chunk(3, 1).into_iter();
    std::array::from_fn(|_| parts.next().expect("3 chunks of a 3k-channel tensor"))
}

/// A plain convolution followed by ReLU: no state of its own.
#[derive(Module, Debug)]
pub struct ConvCell {
    pub conv: Conv,
}

/// One representation cell.
// One per layer, built once: the size difference between variants costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Module, Debug)]
pub enum Cell {
    Hgru(Hgru),
    ConvLstm(ConvLstm),
    Conv(ConvCell),
}

impl Cell {
    pub(crate) fn new(
        init: &mut Init,
        kind: CellKind,
        c_in: usize,
        k: usize,
        kernel: usize,
    ) -> Self {
        match kind {
            CellKind::Hgru => Cell::Hgru(Hgru::new(init, c_in, k, kernel)),
            CellKind::ConvLstm => Cell::ConvLstm(ConvLstm::new(init, c_in, k, kernel)),
            CellKind::Conv => Cell::Conv(ConvCell {
                conv: Conv::new(init, c_in, k, 5, true),
            }),
        }
    }

    /// One step: the new state from the input and the previous state.
    pub fn forward(&self, x: Tensor<4>, state: CellState) -> CellState {
        match self {
            Cell::Hgru(cell) => CellState {
                h: cell.forward(x, state.h),
                c: None,
            },
            Cell::ConvLstm(cell) => {
                let c = state.c.unwrap_or_else(|| state.h.zeros_like());
                let (h, c) = cell.forward(x, state.h, c);
                CellState { h, c: Some(c) }
            }
            Cell::Conv(cell) => CellState {
                h: relu(cell.conv.forward(x)),
                c: None,
            },
        }
    }
}
