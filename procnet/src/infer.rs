//! Inference on one camera stream: a stateful ProcNet that takes a frame, returns class masks.

use std::path::Path;
use std::sync::Arc;
use workcell_render::Class;

use burn::tensor::{Device, Tensor, TensorData};

use crate::backend::Backend;
use crate::config::ProcNetConfig;
use crate::error::{ProcNetError, Result};
use crate::image::resample;
use crate::model::{ProcNetModel, ProcNetState};
use crate::weights;

/// Reads of a new view's first frame before the frame itself ([`ProcNet::start_view`]). A
/// recurrent network's masks of a view it has just met are its worst: through the tracker's
/// own crops of the test split, the network that reads depth gave no pose in 3 frames with
/// at least a third of the forearm in view after one read, and in none after three (each
/// stream's first frame a new view too; experiments/perception.md, "A new view read three times").
pub const VIEW_READS: usize = 3;

/// Class probabilities of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Masks {
    pub classes: Vec<Class>,
    /// Side of the square masks (the model's input size).
    pub size: usize,
    /// `[classes, size, size]`, each in [0, 1].
    pub probabilities: Vec<f32>,
}

impl Masks {
    /// The probability plane of `class`, `[size, size]`.
    #[must_use]
    pub fn class(&self, class: Class) -> Option<&[f32]> {
        let i = self.classes.iter().position(|&c| c == class)?;
        let n = self.size * self.size;
        self.probabilities.get(i * n..(i + 1) * n)
    }

    /// A class thresholded at `threshold`: 1 inside, 0 outside.
    #[must_use]
    pub fn binary(&self, class: Class, threshold: f32) -> Option<Vec<u8>> {
        Some(
            self.class(class)?
                .iter()
                .map(|&p| u8::from(p > threshold))
                .collect(),
        )
    }
}

/// A ProcNet following one camera stream: each [`ProcNet::segment`] advances its state.
pub struct ProcNet {
    /// Shared with the stream's threads ([`crate::backend::on_stream_threads`]).
    model: Arc<ProcNetModel>,
    config: ProcNetConfig,
    device: Device,
    /// The device is flex's: the forward pass runs on [`crate::backend::on_stream_threads`].
    flex: bool,
    state: Option<ProcNetState>,
}

impl std::fmt::Debug for ProcNet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ProcNet")
            .field("config", &self.config)
            .field("device", &self.device)
            .field("frames", &self.frames())
            .finish()
    }
}

impl ProcNet {
    /// Loads a weight file onto a backend.
    pub fn load(path: &Path, backend: Backend) -> Result<Self> {
        let device = backend.device()?;
        let (model, config) = weights::load(path, &device)?;
        Ok(Self::new(model, config, device))
    }

    /// Wraps a model (e.g. fresh from training).
    #[must_use]
    pub fn new(model: ProcNetModel, config: ProcNetConfig, device: Device) -> Self {
        Self {
            model: Arc::new(model),
            config,
            flex: device == Device::flex(),
            device,
            state: None,
        }
    }

    #[must_use]
    pub fn config(&self) -> &ProcNetConfig {
        &self.config
    }

    /// Frames seen since the last reset.
    #[must_use]
    pub fn frames(&self) -> usize {
        self.state.as_ref().map_or(0, |s| s.frames)
    }

    /// The forearm's probabilities of a planar frame of any size (`[planes, height, width]`
    /// in [0, 1]: RGB, and the depth plane for a network that reads it,
    /// [`crate::data::input_frame`]): the frame resampled to the input, segmented (the
    /// stream's state advances), and the mask resampled back to `width x height`.
    ///
    /// # Errors
    /// [`ProcNetError::Input`] when the network has no forearm class; network failures.
    pub fn forearm(&mut self, planar: &[f32], width: usize, height: usize) -> Result<Vec<f32>> {
        let masks = self.segment_any_size(planar, width, height)?;
        let s = self.config.input_size;
        let forearm = masks
            .class(Class::Forearm)
            .ok_or_else(|| ProcNetError::Input {
                message: format!(
                    "the network has no forearm class (it has {:?})",
                    masks.classes
                ),
            })?;
        Ok(resample(forearm, 1, s, s, width, height))
    }

    /// Starts the stream afresh on a new view of the scene (a camera stream's first frame,
    /// a region of interest of another scale, whose pixels the stream's memory is not of):
    /// forgets the last view and reads `planar` (a frame of any size, as
    /// [`ProcNet::planes`] takes it) [`VIEW_READS`] times, so that the next call on the same
    /// frame has that much memory of this view.
    ///
    /// # Errors
    /// A frame of another size than `width x height`, and as [`ProcNet::segment`]; the
    /// stream is then left as it was.
    pub fn start_view(&mut self, planar: &[f32], width: usize, height: usize) -> Result<()> {
        self.check_planar(planar, width, height)?;
        let s = self.config.input_size;
        let input = resample(planar, self.config.input_planes(), width, height, s, s);
        let last = self.state.take();
        for _ in 0..VIEW_READS {
            if let Err(e) = self.segment(&input) {
                self.state = last;
                return Err(e);
            }
        }
        Ok(())
    }

    /// Every class's probabilities of a planar RGB frame of any size, as
    /// [`ProcNet::forearm`] gives the forearm's: one `width x height` plane per class.
    ///
    /// # Errors
    /// Network failures.
    pub fn planes(
        &mut self,
        planar: &[f32],
        width: usize,
        height: usize,
    ) -> Result<Vec<(Class, Vec<f32>)>> {
        let masks = self.segment_any_size(planar, width, height)?;
        let s = self.config.input_size;
        Ok(masks
            .classes
            .iter()
            .filter_map(|&c| Some((c, resample(masks.class(c)?, 1, s, s, width, height))))
            .collect())
    }

    /// Refuses a planar frame that is not the network's planes at `width x height`.
    fn check_planar(&self, planar: &[f32], width: usize, height: usize) -> Result<()> {
        let planes = self.config.input_planes();
        if planar.len() != planes * width * height {
            return Err(ProcNetError::Input {
                message: format!(
                    "a planar frame of {} values, not {planes} x {width} x {height} ({})",
                    planar.len(),
                    if planes == 4 {
                        "RGB and the depth plane"
                    } else {
                        "RGB"
                    }
                ),
            });
        }
        Ok(())
    }

    /// [`ProcNet::segment`] of a planar frame of any size, resampled to the input.
    fn segment_any_size(&mut self, planar: &[f32], width: usize, height: usize) -> Result<Masks> {
        self.check_planar(planar, width, height)?;
        let s = self.config.input_size;
        let planes = self.config.input_planes();
        self.segment(&resample(planar, planes, width, height, s, s))
    }

    /// Forgets the stream (a new camera, a cut): the next frame starts from a zero state.
    pub fn reset(&mut self) {
        self.state = None;
    }

    /// Segments the next frame of the stream: `rgb` is `[planes, size, size]` (planar) in
    /// [0, 1], RGB and, for a network that reads depth, the depth plane
    /// ([`crate::data::input_frame`]). A frame of the wrong size, with a NaN or a value
    /// outside [0, 1] is an error, and the stream's state is left as it was.
    pub fn segment(&mut self, rgb: &[f32]) -> Result<Masks> {
        let s = self.config.input_size;
        let p = self.config.input_planes();
        if rgb.len() != p * s * s {
            let side = ((rgb.len() / p) as f64).sqrt();
            return Err(ProcNetError::Input {
                message: format!(
                    "expected a planar {} frame of {p}x{s}x{s} = {} values, got {} ({}); resize to {s}x{s}",
                    if p == 4 { "RGB-D" } else { "RGB" },
                    p * s * s,
                    rgb.len(),
                    if rgb.len().is_multiple_of(p) && side.fract() == 0.0 {
                        format!("{p}x{side}x{side}")
                    } else {
                        format!("not {p} channels of a square image")
                    }
                ),
            });
        }
        if let Some(i) = rgb.iter().position(|v| !v.is_finite()) {
            return Err(ProcNetError::Input {
                message: format!(
                    "pixel value {} at index {i} (channel {}, row {}, column {}) is not finite",
                    rgb[i],
                    i / (s * s),
                    (i / s) % s,
                    i % s
                ),
            });
        }
        if let Some(i) = rgb.iter().position(|v| !(0.0..=1.0).contains(v)) {
            return Err(ProcNetError::Input {
                message: format!(
                    "pixel value {} at index {i} is outside [0, 1] (8-bit images: divide by 255)",
                    rgb[i]
                ),
            });
        }
        let x = Tensor::<4>::from_data(TensorData::new(rgb.to_vec(), [1, p, s, s]), &self.device);
        let state = match self.state.take() {
            Some(state) => state,
            None => self.model.initial_state(1, s, s, &self.device),
        };
        let model = Arc::clone(&self.model);
        let forward = move || {
            let (out, state) = model.step(x, state);
            let probabilities = burn::tensor::activation::sigmoid(out.logits)
                .into_data()
                .try_into_vec::<f32>();
            (state, probabilities)
        };
        // On flex, threads that flush subnormals: the stream's state decays into them.
        let (state, probabilities) = if self.flex {
            crate::backend::on_stream_threads(forward)
        } else {
            forward()
        };
        self.state = Some(state);
        let probabilities = probabilities.map_err(|e| ProcNetError::Backend {
            name: format!("{:?}", self.device),
            message: format!("cannot read the output: {e:?}"),
        })?;
        Ok(Masks {
            classes: self.config.classes.clone(),
            size: s,
            probabilities,
        })
    }
}
