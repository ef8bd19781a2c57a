//! The shape of a ProcNet: every switch of the paper's Table 1, and the named presets.

use serde::{Deserialize, Serialize};
use workcell_render::Class;

use crate::error::{ProcNetError, Result};

/// The representation cell of every layer (the paper's Table 1, column "cell").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CellKind {
    /// Horizontal gated recurrent unit (the paper's best).
    Hgru,
    /// Convolutional LSTM with peepholes (PredNet's cell).
    ConvLstm,
    /// A plain 5x5 convolution: no recurrence inside the cell.
    Conv,
}

impl CellKind {
    pub const ALL: [CellKind; 3] = [CellKind::Hgru, CellKind::ConvLstm, CellKind::Conv];

    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            CellKind::Hgru => "hgru",
            CellKind::ConvLstm => "convlstm",
            CellKind::Conv => "conv",
        }
    }
}

/// The decoder's activation after each transposed convolution.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    Relu,
    Gelu,
}

/// The architecture of one ProcNet. Two files with the same `ProcNetConfig` hold
/// interchangeable weights; weights are refused by a model of another configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ProcNetConfig {
    /// Input frames are `[3 or 4, size, size]`; must be divisible by `2^(layers - 1)`.
    pub input_size: usize,
    /// Channels of the representation R_l, one entry per layer (3 or 4 layers).
    pub repr_channels: Vec<usize>,
    /// Channels of the bottom-up input A_l, one per layer; the first is 3 (RGB) or 4 (RGB and
    /// the depth plane, [`crate::image::depth_plane`]).
    pub input_channels: Vec<usize>,
    pub cell: CellKind,
    /// Every signal crossing layers is taken from the previous time step.
    pub axonal_delay: bool,
    /// Layers predict their input and pass the error up (predictive coding); when off,
    /// E_l = ReLU(A_l) and the decoder reads layer 0.
    pub prediction_loss: bool,
    /// The decoder adds layer 0's representation (full resolution) before its head even with
    /// the prediction loss on. The paper's decoder reads layer 0 only with the prediction loss
    /// off, so with it on no full-resolution feature reaches the masks and thin parts blur.
    /// No parameters of its own: weights of either setting load into the other, so the
    /// setting is part of the configuration a weight file is checked against.
    #[serde(default)]
    pub decoder_full_resolution: bool,
    /// Kernel of the horizontal (hGRU) and recurrent (ConvLSTM) convolutions.
    pub cell_kernel: usize,
    pub decoder_activation: Activation,
    /// One sigmoid output channel per class, in this order.
    pub classes: Vec<Class>,
}

/// The classes of `workcell dataset` ([`Class::ALL`] without the background).
pub const DATASET_CLASSES: [Class; 5] = [
    Class::Robot,
    Class::Torso,
    Class::UpperArm,
    Class::Forearm,
    Class::Hand,
];

impl Default for ProcNetConfig {
    fn default() -> Self {
        Self::cpu()
    }
}

impl ProcNetConfig {
    /// The authors' runs: (64, 128, 256) representation channels at 128x128, hGRU, no axonal
    /// delay, prediction loss on (about 5.4 M parameters). A GPU configuration.
    #[must_use]
    pub fn paper() -> Self {
        Self {
            input_size: 128,
            repr_channels: vec![64, 128, 256],
            input_channels: vec![3, 64, 128],
            cell: CellKind::Hgru,
            axonal_delay: false,
            prediction_loss: true,
            decoder_full_resolution: false,
            cell_kernel: 5,
            decoder_activation: Activation::Relu,
            classes: DATASET_CLASSES.to_vec(),
        }
    }

    /// The CPU preset, sized by measurement on a 2-core machine (experiments/perception.md).
    #[must_use]
    pub fn cpu() -> Self {
        Self {
            input_size: 128,
            repr_channels: vec![16, 32, 64],
            input_channels: vec![3, 16, 32],
            decoder_full_resolution: true,
            ..Self::paper()
        }
    }

    /// The feed-forward baseline of the `cpu` preset ([`Self::feed_forward_baseline`]).
    #[must_use]
    pub fn baseline() -> Self {
        Self::cpu().feed_forward_baseline()
    }

    /// A preset by name: `paper`, `cpu` or `baseline`.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => Ok(Self::paper()),
            "cpu" => Ok(Self::cpu()),
            "baseline" => Ok(Self::baseline()),
            other => Err(ProcNetError::Config {
                key: "preset".into(),
                message: format!("unknown preset {other:?} (known: paper, cpu, baseline)"),
            }),
        }
    }

    /// Each frame's masks depend on that frame alone: plain convolution cells, no
    /// prediction loss (no layer predicts from the last frame) and no axonal delay (no signal
    /// is read from the last frame).
    #[must_use]
    pub fn is_feed_forward(&self) -> bool {
        self.cell == CellKind::Conv && !self.prediction_loss && !self.axonal_delay
    }

    /// What tables call a network of this configuration.
    #[must_use]
    pub fn model_name(&self) -> &'static str {
        if self.is_feed_forward() {
            "feed-forward baseline (PoseCNN stand-in)"
        } else {
            "ProcNet"
        }
    }

    /// The single-frame baseline of the same size: this network's encoder-decoder with
    /// plain convolution cells, without the prediction loss and the axonal delay, its
    /// channels widened by the common factor that brings its parameter count nearest to this
    /// network's. The paper compares ProcNet with PoseCNN; this is the project's own
    /// stand-in for it, trained by the same recipe on the same data.
    #[must_use]
    pub fn feed_forward_baseline(&self) -> Self {
        let target = self.parameter_count() as f64;
        let widen = |c: usize, f: f64| {
            // Keep multiples of 8 (the decoder's normalisation groups) where they were.
            let unit = if c.is_multiple_of(8) { 8.0 } else { 1.0 };
            (((c as f64 * f) / unit).round() * unit).max(1.0) as usize
        };
        let candidate = |f: f64| {
            let mut c = Self {
                cell: CellKind::Conv,
                prediction_loss: false,
                axonal_delay: false,
                ..self.clone()
            };
            c.repr_channels = self.repr_channels.iter().map(|&r| widen(r, f)).collect();
            c.input_channels = self
                .input_channels
                .iter()
                .enumerate()
                .map(|(l, &a)| if l == 0 { a } else { widen(a, f) })
                .collect();
            c
        };
        (0..=300)
            .map(|i| {
                let c = candidate(1.0 + f64::from(i) / 100.0);
                ((c.parameter_count() as f64 - target).abs(), c)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or_else(|| candidate(1.0), |(_, c)| c)
    }

    /// The number of trainable parameters of a model of this configuration, without
    /// building it (channel lists of other lengths than [`Self::validate`] accepts count
    /// their missing entries as 0).
    #[must_use]
    pub fn parameter_count(&self) -> usize {
        let l_count = self.layers();
        let r = |l: usize| self.repr_channels.get(l).copied().unwrap_or(0);
        let a = |l: usize| self.input_channels.get(l).copied().unwrap_or(0);
        let e = |l: usize| if self.prediction_loss { 2 * a(l) } else { a(l) };
        let conv = |c_in: usize, c_out: usize, k: usize, bias: bool| {
            c_in * c_out * k * k + if bias { c_out } else { 0 }
        };
        let s = self.cell_kernel;
        let mut n = 0;
        for l in 0..l_count {
            let k = r(l);
            if self.prediction_loss {
                n += conv(k, a(l), 1, true);
            }
            let c_in = e(l) + if l + 1 < l_count { r(l + 1) } else { 0 };
            n += match self.cell {
                CellKind::Hgru => {
                    let input = if c_in == k { 0 } else { conv(c_in, k, 1, true) };
                    // u1, u2; w_inh, w_exc; alpha, mu, gamma, kappa, omega; four norms.
                    input + 2 * conv(k, k, 1, true) + 2 * k * k * s * s + 5 * k + 4 * 2 * k
                }
                CellKind::ConvLstm => conv(c_in + k, 4 * k, s, true) + conv(k, 3 * k, s, false),
                CellKind::Conv => conv(c_in, k, 5, true),
            };
            if l + 1 < l_count {
                n += conv(e(l), a(l + 1), 5, true);
                // The decoder stage from l+1 to l: a norm and a 3x3 transposed convolution.
                n += 2 * r(l + 1) + r(l + 1) * r(l) * 9;
            }
        }
        n + 2 * r(0) + conv(r(0), self.num_classes(), 1, false)
    }

    /// Multiply-accumulates of the convolutions of one frame's forward pass (batch 1): the
    /// floor of inference time, whatever the backend (element-wise operations and
    /// normalisations, a few percent, are left out). Two FLOPs each.
    #[must_use]
    pub fn macs_per_frame(&self) -> u64 {
        let l_count = self.layers();
        let r = |l: usize| self.repr_channels.get(l).copied().unwrap_or(0) as u64;
        let a = |l: usize| self.input_channels.get(l).copied().unwrap_or(0) as u64;
        let e = |l: usize| if self.prediction_loss { 2 * a(l) } else { a(l) };
        let pixels = |l: usize| ((self.input_size >> l) * (self.input_size >> l)) as u64;
        let s2 = (self.cell_kernel * self.cell_kernel) as u64;
        let mut n = 0;
        for l in 0..l_count {
            let (k, px) = (r(l), pixels(l));
            if self.prediction_loss {
                n += k * a(l) * px;
            }
            let c_in = e(l) + if l + 1 < l_count { r(l + 1) } else { 0 };
            n += px
                * match self.cell {
                    CellKind::Hgru => {
                        let input = if c_in == k { 0 } else { c_in * k };
                        input + 2 * k * k + 2 * k * k * s2
                    }
                    CellKind::ConvLstm => (c_in + k) * 4 * k * s2 + k * 3 * k * s2,
                    CellKind::Conv => c_in * k * 25,
                };
            if l + 1 < l_count {
                // The 5x5 convolution to the next layer's input (before its 2x2 pooling), and
                // the decoder's 3x3 transposed convolution from layer l+1 up to l.
                n += e(l) * a(l + 1) * 25 * px;
                n += r(l + 1) * k * 9 * pixels(l + 1);
            }
        }
        n + r(0) * self.num_classes() as u64 * pixels(0)
    }

    #[must_use]
    pub fn layers(&self) -> usize {
        self.repr_channels.len()
    }

    #[must_use]
    pub fn num_classes(&self) -> usize {
        self.classes.len()
    }

    /// Whether the network reads the depth image as a fourth input plane
    /// (`input_channels[0] == 4`, [`crate::image::depth_plane`]).
    #[must_use]
    pub fn reads_depth(&self) -> bool {
        self.input_channels.first() == Some(&4)
    }

    /// The planes of the network's input: 3 (RGB), or 4 with the depth plane.
    #[must_use]
    pub fn input_planes(&self) -> usize {
        if self.reads_depth() { 4 } else { 3 }
    }

    /// Index of a class by name.
    #[must_use]
    pub fn class_index(&self, class: Class) -> Option<usize> {
        self.classes.iter().position(|&c| c == class)
    }

    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<()> {
        let invalid = |key: &str, message: String| {
            Err(ProcNetError::Config {
                key: key.into(),
                message,
            })
        };
        let layers = self.layers();
        if !(3..=4).contains(&layers) {
            return invalid(
                "repr_channels",
                format!("ProcNet has 3 or 4 layers, got {layers}"),
            );
        }
        if self.input_channels.len() != layers {
            return invalid(
                "input_channels",
                format!(
                    "one entry per layer: {} entries for {layers} layers",
                    self.input_channels.len()
                ),
            );
        }
        if !(3..=4).contains(&self.input_channels[0]) {
            return invalid(
                "input_channels",
                format!(
                    "layer 0 reads RGB (3 channels) or RGB and depth (4), got {}",
                    self.input_channels[0]
                ),
            );
        }
        if let Some(c) = self
            .repr_channels
            .iter()
            .chain(&self.input_channels)
            .find(|&&c| c == 0 || c > 4096)
        {
            return invalid(
                "repr_channels",
                format!("channel count {c} not in 1..=4096"),
            );
        }
        let stride = 1 << (layers - 1);
        if self.input_size < stride
            || !self.input_size.is_multiple_of(stride)
            || self.input_size > 2048
        {
            return invalid(
                "input_size",
                format!(
                    "{} must be a multiple of {stride} (2^(layers-1)) and at most 2048",
                    self.input_size
                ),
            );
        }
        if self.cell_kernel.is_multiple_of(2) || self.cell_kernel > 15 {
            return invalid(
                "cell_kernel",
                format!("an odd size up to 15, got {}", self.cell_kernel),
            );
        }
        if self.classes.is_empty() {
            return invalid("classes", "at least one class".into());
        }
        Ok(())
    }

    /// The configuration as compact JSON (stored in weight files).
    #[must_use]
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_validate() {
        ProcNetConfig::paper().validate().unwrap();
        ProcNetConfig::cpu().validate().unwrap();
        ProcNetConfig::baseline().validate().unwrap();
    }

    #[test]
    fn parameter_count_matches_the_built_model() {
        use burn::module::Module;
        let device = crate::Backend::Flex.device().unwrap();
        let mut configs = vec![ProcNetConfig::cpu(), ProcNetConfig::baseline()];
        for cell in CellKind::ALL {
            for prediction_loss in [true, false] {
                configs.push(ProcNetConfig {
                    cell,
                    prediction_loss,
                    repr_channels: vec![8, 12, 16, 24],
                    input_channels: vec![3, 8, 12, 16],
                    ..ProcNetConfig::cpu()
                });
            }
        }
        for c in configs {
            let model = c.init(&device, 0).unwrap();
            assert_eq!(c.parameter_count(), model.num_params(), "{c:?}");
        }
    }

    #[test]
    fn macs_per_frame_count_each_convolution() {
        // Counted by hand for the cpu preset at 128x128, (16, 32, 64) representation and
        // (3, 16, 32) input channels, hGRU with 5x5 kernels, prediction loss on, 5 classes.
        let px = |l: u64| (128 >> l) * (128 >> l);
        let hgru =
            |c_in: u64, k: u64| if c_in == k { 0 } else { c_in * k } + 2 * k * k + 50 * k * k;
        let expected = px(0) * (16 * 3 + hgru(6 + 32, 16) + 6 * 16 * 25 + 5 * 16)
            + 32 * 16 * 9 * px(1)
            + px(1) * (32 * 16 + hgru(32 + 64, 32) + 32 * 32 * 25)
            + 64 * 32 * 9 * px(2)
            + px(2) * (64 * 32 + hgru(64, 64));
        let cpu = ProcNetConfig {
            input_size: 128,
            ..ProcNetConfig::cpu()
        };
        assert_eq!(cpu.macs_per_frame(), expected);
        // 269.5 M at full resolution, 337.6 M at half, 220.2 M at a quarter, 37.7 M decoding.
        assert_eq!(expected, 865_075_200);
        // Each halving of the input side divides the count by four.
        let half = ProcNetConfig {
            input_size: 64,
            ..cpu.clone()
        };
        assert_eq!(cpu.macs_per_frame(), 4 * half.macs_per_frame());
    }

    #[test]
    fn the_baseline_is_feed_forward_and_of_the_same_size() {
        let procnet = ProcNetConfig::cpu();
        let baseline = procnet.feed_forward_baseline();
        assert!(baseline.is_feed_forward() && !procnet.is_feed_forward());
        assert_eq!(baseline.input_size, procnet.input_size);
        assert_eq!(baseline.classes, procnet.classes);
        let ratio = baseline.parameter_count() as f64 / procnet.parameter_count() as f64;
        assert!((0.9..1.1).contains(&ratio), "{ratio}: {baseline:?}");
        // An invalid configuration counts without panicking.
        let short = ProcNetConfig {
            input_channels: vec![3],
            ..ProcNetConfig::cpu()
        };
        assert!(short.feed_forward_baseline().parameter_count() > 0);
        // A baseline is its own baseline.
        assert_eq!(baseline.feed_forward_baseline(), baseline);
        // The paper's width too.
        let paper = ProcNetConfig::paper();
        let ratio =
            paper.feed_forward_baseline().parameter_count() as f64 / paper.parameter_count() as f64;
        assert!((0.9..1.1).contains(&ratio), "{ratio}");
    }

    #[test]
    fn bad_values_name_their_key() {
        let mut c = ProcNetConfig::cpu();
        c.input_size = 66;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("input_size"), "{e}");
        let mut c = ProcNetConfig::cpu();
        c.repr_channels = vec![8, 8];
        c.input_channels = vec![3, 8];
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("3 or 4 layers")
        );
    }
}
