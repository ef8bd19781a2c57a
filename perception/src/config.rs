//! The shape of a ProcNet: every switch of the paper's Table 1, and the named presets.

use serde::{Deserialize, Serialize};

use crate::error::{PerceptionError, Result};

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
    /// Input frames are `[3, size, size]`; must be divisible by `2^(layers - 1)`.
    pub input_size: usize,
    /// Channels of the representation R_l, one entry per layer (3 or 4 layers).
    pub repr_channels: Vec<usize>,
    /// Channels of the bottom-up input A_l, one per layer; the first is 3 (RGB).
    pub input_channels: Vec<usize>,
    pub cell: CellKind,
    /// Every signal crossing layers is taken from the previous time step.
    pub axonal_delay: bool,
    /// Layers predict their input and pass the error up (predictive coding); when off,
    /// E_l = ReLU(A_l) and the decoder reads layer 0.
    pub prediction_loss: bool,
    /// Kernel of the horizontal (hGRU) and recurrent (ConvLSTM) convolutions.
    pub cell_kernel: usize,
    pub decoder_activation: Activation,
    /// One sigmoid output channel per class, in this order.
    pub classes: Vec<String>,
}

/// The classes of `workcell dataset` (sim's `render::Class`, without the background).
pub const DATASET_CLASSES: [&str; 5] = ["robot", "torso", "upper_arm", "forearm", "hand"];

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
            cell_kernel: 5,
            decoder_activation: Activation::Relu,
            classes: DATASET_CLASSES.iter().map(|s| s.to_string()).collect(),
        }
    }

    /// The CPU preset, sized by measurement on a 2-core machine (docs/perception.md).
    #[must_use]
    pub fn cpu() -> Self {
        Self {
            input_size: 64,
            repr_channels: vec![16, 32, 64],
            input_channels: vec![3, 16, 32],
            ..Self::paper()
        }
    }

    /// A preset by name: `paper` or `cpu`.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => Ok(Self::paper()),
            "cpu" => Ok(Self::cpu()),
            other => Err(PerceptionError::Config {
                key: "preset".into(),
                message: format!("unknown preset {other:?} (known: paper, cpu)"),
            }),
        }
    }

    #[must_use]
    pub fn layers(&self) -> usize {
        self.repr_channels.len()
    }

    #[must_use]
    pub fn num_classes(&self) -> usize {
        self.classes.len()
    }

    /// Index of a class by name.
    #[must_use]
    pub fn class_index(&self, name: &str) -> Option<usize> {
        self.classes.iter().position(|c| c == name)
    }

    /// Checks every value; the error names the key.
    pub fn validate(&self) -> Result<()> {
        let invalid = |key: &str, message: String| {
            Err(PerceptionError::Config {
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
        if self.input_channels[0] != 3 {
            return invalid(
                "input_channels",
                format!(
                    "layer 0 reads RGB: 3 channels, got {}",
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
