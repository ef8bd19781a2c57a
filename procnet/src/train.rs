//! Training: random 10-frame windows, Dice + focal + prediction-error losses, AdamW with
//! gradient clipping and a one-cycle schedule; resumable from its checkpoints.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use workcell_render::Class;
use workcell_render::dataset::FrameLabels;
use workcell_render::roi::RoiKind;
use workcell_robots::input::{MAX_CONFIG_BYTES, read_text_file};

use burn::module::Module;
use burn::optim::grad_clipping::GradientClippingConfig;
use burn::optim::{AdamWConfig, GradientsParams, ModuleOptimizer, OptimizerRecord};
use burn::tensor::{Device, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use workcell_render::dataset::{Dataset, Split};

use crate::backend::Backend;
use crate::config::ProcNetConfig;
use crate::data::{Augment, SequenceTensors, load_split, make_batch};
use crate::error::{ProcNetError, Result};
use crate::loss::{batch_dice_per_class, dice_per_class, focal_per_class};
use crate::model::{ProcNetModel, ProcNetState, StepOutput};
use crate::weights;

/// Weights of the loss terms and the focal loss's parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LossConfig {
    /// Dice per frame and class, averaged (the paper's).
    pub dice: f32,
    /// Dice per class over the whole batch of a time step as one volume
    /// ([`crate::loss::batch_dice_per_class`]).
    pub batch_dice: f32,
    pub focal: f32,
    /// Weight of `sum_l mean(E_l)` (ignored when the model has no prediction loss).
    pub prediction: f32,
    pub focal_alpha: f32,
    pub focal_gamma: f32,
    /// Per-class weights of the Dice and focal terms, by class name (unlisted classes: 1).
    /// Small parts (the forearm) can be weighted up against the large robot and torso.
    pub class_weights: std::collections::BTreeMap<String, f32>,
}

impl Default for LossConfig {
    fn default() -> Self {
        Self {
            dice: 1.0,
            batch_dice: 0.0,
            focal: 1.0,
            prediction: 1.0,
            focal_alpha: 0.5,
            focal_gamma: 2.0,
            class_weights: std::collections::BTreeMap::new(),
        }
    }
}

impl LossConfig {
    /// The per-class weights in the model's class order, normalised to mean 1.
    #[must_use]
    pub fn weights_for(&self, classes: &[Class]) -> Vec<f32> {
        let w: Vec<f32> = classes
            .iter()
            .map(|c| self.class_weights.get(c.name()).copied().unwrap_or(1.0))
            .collect();
        let mean = w.iter().sum::<f32>() / w.len().max(1) as f32;
        w.into_iter()
            .map(|v| v / mean.max(f32::MIN_POSITIVE))
            .collect()
    }
}

/// Augmentation drawn per sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AugmentConfig {
    /// Mirror left-right with probability 1/2.
    pub flip: bool,
    /// Largest shift, in model pixels.
    pub max_shift_px: i32,
    /// Random crops: the side of the square read is drawn from `min_crop..=1` of the frame's
    /// and resampled to the frame's size (1: no crop). The frames are already crops of the
    /// region of interest, so this varies the arm's scale and place within it.
    pub min_crop: f32,
    /// Colour jitter: brightness offset and contrast, saturation factors within 1 +- this.
    pub jitter: f32,
}

impl Default for AugmentConfig {
    fn default() -> Self {
        Self {
            flip: true,
            max_shift_px: 4,
            min_crop: 0.8,
            jitter: 0.15,
        }
    }
}

/// How often each training sequence is drawn, relative to the others.
///
/// A sequence's weight is the product of the factors that its distance class (or camera
/// row, [`workcell_render::dataset::SequenceEntry::camera_class`]), its region of interest,
/// its view and its motion match, 1 where none does. The region of interest is the kind of its first
/// frame's crop (`workspace`, `tracked`, or `frame` for a dataset without crops; a stored
/// sequence keeps one); the view is the side from which its first frame's camera sees the
/// human (`front`, `side` or `back`, [`workcell_render::dataset::View`]); the motion is
/// `recorded` where the sequence plays a recorded clip
/// ([`workcell_render::dataset::SequenceEntry::clip`]), else `generated`. With every table
/// empty every sequence is equally likely, drawn exactly as before the tables existed.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SamplingConfig {
    /// Factor per distance class or camera row, e.g. `{ large = 2.0 }`.
    pub distance: std::collections::BTreeMap<String, f64>,
    /// Factor per kind of region of interest, e.g. `{ workspace = 2.0 }`.
    pub roi: std::collections::BTreeMap<String, f64>,
    /// Factor per view of the human, e.g. `{ back = 2.0 }`.
    pub view: std::collections::BTreeMap<String, f64>,
    /// Factor per source of the human's motion, `recorded` or `generated`, e.g.
    /// `{ recorded = 3.0 }`.
    pub motion: std::collections::BTreeMap<String, f64>,
}

/// What [`SamplingConfig`] weighs a training sequence by (`None`: not read, since no factor
/// asks for it).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SamplingKeys {
    pub distance: String,
    pub roi: Option<String>,
    pub view: Option<String>,
    /// `recorded` or `generated`.
    pub motion: String,
}

/// The key of a sequence that one table of [`SamplingConfig`] reads.
type KeyOf = fn(&SamplingKeys) -> Option<&str>;

impl SamplingConfig {
    /// Every table empty: uniform over the sequences.
    #[must_use]
    pub fn is_uniform(&self) -> bool {
        self.distance.is_empty()
            && self.roi.is_empty()
            && self.view.is_empty()
            && self.motion.is_empty()
    }

    /// Each table by name, with the key of a sequence that it reads.
    fn tables(
        &self,
    ) -> [(
        &'static str,
        &std::collections::BTreeMap<String, f64>,
        KeyOf,
    ); 4] {
        [
            ("distance", &self.distance, |s| Some(s.distance.as_str())),
            ("roi", &self.roi, |s| s.roi.as_deref()),
            ("view", &self.view, |s| s.view.as_deref()),
            ("motion", &self.motion, |s| Some(s.motion.as_str())),
        ]
    }

    fn validate(&self) -> Result<()> {
        for (table, map, _) in self.tables() {
            if let Some((key, w)) = map
                .iter()
                .find(|(_, w)| !(w.is_finite() && (0.0..=MAX_SAMPLING_FACTOR).contains(*w)))
            {
                return Err(ProcNetError::Config {
                    key: format!("sampling.{table}"),
                    message: format!("{key} = {w}: each in [0, {MAX_SAMPLING_FACTOR}]"),
                });
            }
        }
        Ok(())
    }

    /// Each sequence's weight, given what it is weighed by.
    ///
    /// # Errors
    /// [`ProcNetError::Config`] for a key that no sequence has (a misspelt class would
    /// otherwise change nothing, silently), or when every weight is 0.
    pub fn weights(&self, sequences: &[SamplingKeys]) -> Result<Vec<f64>> {
        for (table, map, key_of) in self.tables() {
            let present: Vec<&str> = sequences.iter().filter_map(key_of).collect();
            if let Some(key) = map.keys().find(|k| !present.contains(&k.as_str())) {
                let mut have = present;
                have.sort_unstable();
                have.dedup();
                return Err(ProcNetError::Config {
                    key: format!("sampling.{table}"),
                    message: format!(
                        "no training sequence has {table} {key:?} (they have {have:?})"
                    ),
                });
            }
        }
        let weights: Vec<f64> = sequences
            .iter()
            .map(|s| {
                self.tables()
                    .into_iter()
                    .map(|(_, map, key_of)| key_of(s).and_then(|k| map.get(k)).map_or(1.0, |w| *w))
                    .product()
            })
            .collect();
        if !weights.iter().any(|w| *w > 0.0) {
            return Err(ProcNetError::Config {
                key: "sampling".into(),
                message: "every training sequence has weight 0: nothing would be drawn".into(),
            });
        }
        Ok(weights)
    }
}

/// Draws an index with probability proportional to `cumulative`'s increments (a running sum
/// of non-negative weights whose last element is positive).
fn draw_weighted(rng: &mut impl Rng, cumulative: &[f64]) -> usize {
    let total = cumulative.last().copied().unwrap_or(0.0);
    let u = rng.random::<f64>() * total;
    // The first index whose running sum exceeds u: never one of weight 0.
    cumulative
        .partition_point(|&c| c <= u)
        .min(cumulative.len().saturating_sub(1))
}

/// The largest sampling factor.
pub const MAX_SAMPLING_FACTOR: f64 = 1e3;

/// The most steps a run may ask for.
pub const MAX_STEPS: usize = 10_000_000;
/// The longest training window, frames.
pub const MAX_WINDOW: usize = 64;
/// The longest burn-in before a window, frames.
pub const MAX_BURN_IN: usize = 1024;
/// The most reads of a window's first frame before it ([`TrainConfig::view_reads`]).
pub const MAX_VIEW_READS: usize = 16;
/// The largest loss weight (a weight of 1e300 is infinite in f32).
pub const MAX_LOSS_WEIGHT: f32 = 1e3;

/// A training run (`workcell train --config FILE`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// The dataset folder (`workcell dataset generate`), relative to the config file.
    pub dataset: PathBuf,
    pub seed: u64,
    pub backend: Backend,
    /// CPU threads for the backend.
    pub threads: usize,
    /// Optimiser steps; each sees `batch` windows of `window` frames.
    pub steps: usize,
    pub batch: usize,
    /// Frames per BPTT window (random start within a sequence).
    pub window: usize,
    /// Up to this many frames just before each window run through the network without
    /// gradients, from a zero state (0: every window starts from a zero state). Evaluation
    /// carries the state through whole sequences; a burn-in at least as long as the
    /// sequences gives every window the state evaluation gives it. With burn-in, the windows
    /// of a step share their start frame (one batch of states), and a window's first frame
    /// counts in the loss unless nothing came before it. The feed-forward baseline has no
    /// state and ignores it.
    pub burn_in: usize,
    /// Reads of a window's first frame, without gradients, before the window, when the
    /// window starts from a zero state (no burn-in before it): the window then begins as a
    /// deployed stream begins a new view ([`crate::ProcNet::start_view`] reads it
    /// [`crate::VIEW_READS`] times), and its first frame counts in the loss. 0 (the default):
    /// the window starts cold and its first frame weighs 0. The feed-forward baseline
    /// ignores it.
    pub view_reads: usize,
    /// Peak learning rate of the one-cycle schedule.
    pub lr: f64,
    /// Fraction of the steps spent warming up.
    pub warmup_fraction: f64,
    pub weight_decay: f32,
    /// Gradients are clipped to this global L2 norm.
    pub clip_norm: f32,
    pub loss: LossConfig,
    pub augment: AugmentConfig,
    /// Save a checkpoint every this many steps.
    pub checkpoint_every: usize,
    /// Evaluate on the validation split every this many steps (0: never).
    pub validate_every: usize,
    /// Validate on this many sequences of the validation split, taken in turn from each
    /// (distance, occlusion) cell so that every cell is represented (0: all of them).
    pub validation_sequences: usize,
    /// Start from these weights (of the same `model` configuration, at any input size)
    /// instead of the seed's random ones: a second training cycle on top of a finished run,
    /// or full-size training on top of a run on smaller frames. Relative to the config file.
    /// A checkpoint in the run folder still wins (resuming).
    pub init_weights: Option<PathBuf>,
    /// Layer 0's frame prediction starts with this bias in every colour channel instead of
    /// the seed's uniform draw, so that no channel starts dead (a ReLU below zero at every
    /// pixel); about the frames' mean brightness. Ignored without the prediction loss, and
    /// when the run starts from `init_weights` or a checkpoint.
    pub frame_prediction_bias: Option<f32>,
    /// How often each training sequence is drawn (uniform unless set).
    #[serde(skip_serializing_if = "SamplingConfig::is_uniform")]
    pub sampling: SamplingConfig,
    /// The network (starts from the `cpu` preset; override any key).
    pub model: ProcNetConfig,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            dataset: PathBuf::from("out/dataset"),
            seed: 1,
            backend: Backend::Flex,
            threads: 2,
            steps: 2000,
            batch: 4,
            window: 10,
            burn_in: 0,
            view_reads: 0,
            lr: 1e-3,
            warmup_fraction: 0.3,
            weight_decay: 1e-4,
            clip_norm: 1.0,
            loss: LossConfig::default(),
            augment: AugmentConfig::default(),
            checkpoint_every: 100,
            validate_every: 250,
            validation_sequences: 24,
            init_weights: None,
            frame_prediction_bias: None,
            sampling: SamplingConfig::default(),
            model: ProcNetConfig::cpu(),
        }
    }
}

impl TrainConfig {
    /// Reads a TOML file; `dataset` is resolved against the file's folder.
    pub fn from_file(path: &Path) -> Result<Self> {
        let text =
            read_text_file(path, MAX_CONFIG_BYTES).map_err(|e| ProcNetError::ConfigFile {
                path: path.to_path_buf(),
                message: format!("cannot read: {e}"),
            })?;
        Self::from_toml(&text, path)
    }

    /// Like [`TrainConfig::from_file`] on text already read; `path` names it in errors and
    /// anchors its relative paths.
    ///
    /// # Errors
    /// [`ProcNetError::ConfigFile`] naming the key that is wrong.
    pub fn from_toml(text: &str, path: &Path) -> Result<Self> {
        let mut config: TrainConfig =
            toml::from_str(text).map_err(|e| ProcNetError::ConfigFile {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
        let base = path.parent().unwrap_or(Path::new("."));
        if config.dataset.is_relative() {
            config.dataset = base.join(&config.dataset);
        }
        if let Some(init) = config.init_weights.as_mut().filter(|p| p.is_relative()) {
            *init = base.join(&*init);
        }
        config.validate().map_err(|e| ProcNetError::ConfigFile {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        Ok(config)
    }

    /// The configuration as TOML, every default filled in.
    #[must_use]
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, message: String| {
            Err(ProcNetError::Config {
                key: key.into(),
                message,
            })
        };
        self.model.validate()?;
        self.sampling.validate()?;
        if !(1..=MAX_STEPS).contains(&self.steps) {
            return bad("steps", format!("1..={MAX_STEPS}, got {}", self.steps));
        }
        if !(1..=crate::backend::MAX_THREADS).contains(&self.threads) {
            return bad(
                "threads",
                format!("1..={}, got {}", crate::backend::MAX_THREADS, self.threads),
            );
        }
        if self.batch == 0 || self.batch > 256 {
            return bad("batch", format!("1..=256, got {}", self.batch));
        }
        if self.window > MAX_WINDOW {
            return bad(
                "window",
                format!("at most {MAX_WINDOW} frames, got {}", self.window),
            );
        }
        if self.window < 2 {
            return bad(
                "window",
                format!(
                    "at least 2 frames (frame 0 has weight 0), got {}",
                    self.window
                ),
            );
        }
        if self.burn_in > MAX_BURN_IN {
            return bad(
                "burn_in",
                format!("at most {MAX_BURN_IN} frames, got {}", self.burn_in),
            );
        }
        if self.view_reads > MAX_VIEW_READS {
            return bad(
                "view_reads",
                format!("at most {MAX_VIEW_READS} reads, got {}", self.view_reads),
            );
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad("lr", format!("a positive number, got {}", self.lr));
        }
        if !(0.0..1.0).contains(&self.warmup_fraction) {
            return bad(
                "warmup_fraction",
                format!("in [0, 1), got {}", self.warmup_fraction),
            );
        }
        if !(self.clip_norm.is_finite() && self.clip_norm > 0.0) {
            return bad(
                "clip_norm",
                format!("a positive number, got {}", self.clip_norm),
            );
        }
        if self.checkpoint_every == 0 {
            return bad("checkpoint_every", "at least 1".into());
        }
        if let Some(bias) = self.frame_prediction_bias
            && !(0.0..=1.0).contains(&bias)
        {
            return bad(
                "frame_prediction_bias",
                format!("in [0, 1] (frames are in [0, 1]), got {bias}"),
            );
        }
        if !(0.25..=1.0).contains(&self.augment.min_crop) {
            return bad(
                "augment.min_crop",
                format!("in [0.25, 1], got {}", self.augment.min_crop),
            );
        }
        let jitter = self.augment.jitter;
        if !(0.0..=1.0).contains(&jitter) {
            return bad("augment.jitter", format!("in [0, 1], got {jitter}"));
        }
        let shift = self.augment.max_shift_px;
        let most = i32::try_from(self.model.input_size / 2).unwrap_or(i32::MAX);
        if !(0..=most).contains(&shift) {
            return bad(
                "augment.max_shift_px",
                format!("0..={most} (half the input), got {shift}"),
            );
        }
        let l = &self.loss;
        let in_range = |w: f32| w.is_finite() && (0.0..=MAX_LOSS_WEIGHT).contains(&w);
        if ![l.dice, l.batch_dice, l.focal, l.prediction, l.focal_gamma]
            .into_iter()
            .all(in_range)
            || !(0.0..=1.0).contains(&l.focal_alpha)
        {
            return bad(
                "loss",
                format!("weights and gamma in [0, {MAX_LOSS_WEIGHT}], alpha in [0, 1]"),
            );
        }
        if l.dice + l.batch_dice + l.focal == 0.0 {
            return bad(
                "loss",
                "dice, batch_dice and focal are all 0: nothing would train the segmentation".into(),
            );
        }
        if let Some((class, w)) = l.class_weights.iter().find(|(_, w)| !in_range(**w)) {
            return bad(
                "loss.class_weights",
                format!("{class} = {w}: each in [0, {MAX_LOSS_WEIGHT}]"),
            );
        }
        // A misspelt class (`upperarm`) would otherwise leave every weight at 1 without a word.
        let classes = &self.model.classes;
        if let Some(name) = l
            .class_weights
            .keys()
            .find(|name| !classes.iter().any(|c| c.name() == name.as_str()))
        {
            let names: Vec<&str> = classes.iter().map(|c| c.name()).collect();
            return bad(
                "loss.class_weights",
                format!("the model has no class {name:?} (it has {names:?})"),
            );
        }
        // Unlisted classes weigh 1, so only a table that sets every class to 0 counts none.
        if classes
            .iter()
            .all(|c| l.class_weights.get(c.name()) == Some(&0.0))
        {
            return bad("loss.class_weights", "all 0: no class would count".into());
        }
        Ok(())
    }

    /// Learning rate at `step` of the one-cycle schedule: a cosine rise from lr/25 to lr, then
    /// a cosine fall to lr/25e4 (PyTorch's OneCycleLR defaults).
    #[must_use]
    pub fn learning_rate(&self, step: usize) -> f64 {
        let (max, start, end) = (self.lr, self.lr / 25.0, self.lr / 25e4);
        let n = self.steps.max(1) as f64;
        let warm = (self.warmup_fraction * n).max(1.0);
        let s = step as f64;
        let cos = |from: f64, to: f64, x: f64| {
            to + (from - to) * 0.5 * (1.0 + (std::f64::consts::PI * x.clamp(0.0, 1.0)).cos())
        };
        if s < warm {
            cos(start, max, s / warm)
        } else {
            cos(max, end, (s - warm) / (n - warm).max(1.0))
        }
    }
}

/// One line of `metrics.csv`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepMetrics {
    pub step: usize,
    pub lr: f64,
    pub loss: f64,
    pub dice: f64,
    pub focal: f64,
    pub prediction: f64,
    /// Validation Dice loss of the forearm (NaN when not evaluated at this step).
    pub val_forearm_dice: f64,
    pub elapsed_s: f64,
}

const CSV_HEADER: &str = "step,lr,loss,dice,focal,prediction,val_forearm_dice,elapsed_s";

impl StepMetrics {
    fn csv(&self) -> String {
        format!(
            "{},{:.6e},{:.6},{:.6},{:.6},{:.6},{:.6},{:.2}",
            self.step,
            self.lr,
            self.loss,
            self.dice,
            self.focal,
            self.prediction,
            self.val_forearm_dice,
            self.elapsed_s
        )
    }

    fn parse(line: &str) -> Option<Self> {
        let v: Vec<f64> = line
            .split(',')
            .map(|s| s.trim().parse().ok())
            .collect::<Option<_>>()?;
        (v.len() == 8).then(|| Self {
            step: v[0] as usize,
            lr: v[1],
            loss: v[2],
            dice: v[3],
            focal: v[4],
            prediction: v[5],
            val_forearm_dice: v[6],
            elapsed_s: v[7],
        })
    }
}

/// Reads `metrics.csv` of a run.
pub fn read_metrics(path: &Path) -> Result<Vec<StepMetrics>> {
    let text = read_text_file(path, MAX_CONFIG_BYTES).map_err(|source| ProcNetError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(text
        .lines()
        .skip(1)
        .filter_map(StepMetrics::parse)
        .collect())
}

/// The losses of one window, summed over frames with their weights.
pub struct WindowLoss {
    pub total: Tensor<1>,
    /// The Dice terms (per frame and per batch), each times its weight.
    pub dice: Tensor<1>,
    pub focal: Tensor<1>,
    pub prediction: Option<Tensor<1>>,
}

/// Runs `model` over a batch of windows and returns the weighted losses. From a zero state
/// (`initial` is `None`) the window's first frame weighs 0, since a recurrent network has seen
/// nothing yet, and the others 1; from a burnt-in state or after view reads
/// ([`window_start`]), and in a feed-forward network, every frame weighs 1. Per-class
/// weights, one per output channel, when given.
pub fn window_loss(
    model: &ProcNetModel,
    rgb: &[Tensor<4>],
    target: &[Tensor<4>],
    loss: &LossConfig,
    class_weights: Option<&[f32]>,
    initial: Option<ProcNetState>,
) -> WindowLoss {
    let [b, _, h, w] = rgb[0].dims();
    let device = rgb[0].device();
    let first = usize::from(!model.is_feed_forward() && initial.is_none());
    let mut state = initial.unwrap_or_else(|| model.initial_state(b, h, w, &device));
    let mut dice_sum: Option<Tensor<1>> = None;
    let mut focal_sum: Option<Tensor<1>> = None;
    let mut pred_sum: Option<Tensor<1>> = None;
    let add = |acc: Option<Tensor<1>>, v: Tensor<1>| Some(acc.map_or(v.clone(), |a| a + v));
    let weighted = (rgb.len() - first) as f64;
    let c = target[0].dims()[1];
    let class_weights = class_weights.map(|w| Tensor::<1>::from_floats(w, &device).reshape([1, c]));
    let reduce = |per_class: Tensor<2>| match &class_weights {
        Some(w) => (per_class * w.clone()).mean(),
        None => per_class.mean(),
    };
    for (t, (x, y)) in rgb.iter().zip(target).enumerate() {
        let (
            StepOutput {
                logits,
                prediction_error,
                ..
            },
            next,
        ) = model.step(x.clone(), state);
        state = next;
        if t < first {
            continue;
        }
        // Terms of weight 0 are not computed (nor differentiated).
        if loss.dice > 0.0 || loss.batch_dice > 0.0 {
            let p = burn::tensor::activation::sigmoid(logits.clone());
            let mut d = None;
            if loss.dice > 0.0 {
                d = add(d, reduce(dice_per_class(p.clone(), y.clone())) * loss.dice);
            }
            if loss.batch_dice > 0.0 {
                d = add(
                    d,
                    reduce(batch_dice_per_class(p, y.clone())) * loss.batch_dice,
                );
            }
            dice_sum = add(dice_sum, d.unwrap_or_else(|| Tensor::zeros([1], &device)));
        }
        if loss.focal > 0.0 {
            let focal = focal_per_class(logits, y.clone(), loss.focal_alpha, loss.focal_gamma);
            focal_sum = add(focal_sum, reduce(focal));
        }
        if let Some(pe) = prediction_error.filter(|_| loss.prediction > 0.0) {
            pred_sum = add(pred_sum, pe);
        }
    }
    let zero = || Tensor::<1>::zeros([1], &device);
    let dice = dice_sum.unwrap_or_else(zero) / weighted;
    let focal = focal_sum.unwrap_or_else(zero) / weighted;
    let prediction = pred_sum.map(|p| p / weighted);
    // `dice` holds both Dice terms with their weights.
    let mut total = dice.clone() + focal.clone() * loss.focal;
    if let Some(p) = &prediction {
        total = total + p.clone() * loss.prediction;
    }
    WindowLoss {
        total,
        dice,
        focal,
        prediction,
    }
}

/// The state that `frames` (`[b, 3, h, w]` each, from a sequence's first frame on) leave in
/// `model`, from a zero state, computed without the autodiff graph and handed back on
/// `model`'s device: the start of a window that follows them ([`TrainConfig::burn_in`]).
pub fn burn_in_state(model: &ProcNetModel, frames: &[Tensor<4>]) -> Option<ProcNetState> {
    let [b, _, h, w] = frames.first()?.dims();
    let inner = model.valid();
    let mut state = None;
    for x in frames {
        let x = x.clone().inner();
        let s = state.unwrap_or_else(|| inner.initial_state(b, h, w, &x.device()));
        state = Some(inner.step(x, s).1);
    }
    state.map(|s| s.map_tensors(Tensor::autodiff))
}

/// The state a training window of `rgb[burn..]` starts from: the one the `burn` frames
/// before it leave ([`burn_in_state`]), or, without them, the one that `view_reads` reads of
/// the window's first frame leave, as a deployed stream starts a new view
/// ([`TrainConfig::view_reads`]); `None` (a zero state) when neither is asked for.
pub fn window_start(
    model: &ProcNetModel,
    rgb: &[Tensor<4>],
    burn: usize,
    view_reads: usize,
) -> Option<ProcNetState> {
    if burn > 0 {
        return burn_in_state(model, rgb.get(..burn)?);
    }
    let first = rgb.first()?;
    burn_in_state(model, &vec![first.clone(); view_reads])
}

/// What a progress callback is told after every step.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    pub step: usize,
    pub steps: usize,
    pub metrics: StepMetrics,
}

/// The files of a run folder.
#[derive(Debug, Clone)]
pub struct RunFiles {
    pub dir: PathBuf,
    /// The run trains a feed-forward network (the baseline): its weights are
    /// `baseline.safetensors` rather than `procnet.safetensors`.
    pub feed_forward: bool,
}

impl RunFiles {
    /// The final weights: `procnet.safetensors`, or `baseline.safetensors` for a
    /// feed-forward network.
    #[must_use]
    pub fn weights(&self) -> PathBuf {
        self.dir.join(if self.feed_forward {
            "baseline.safetensors"
        } else {
            "procnet.safetensors"
        })
    }
    /// The checkpoint's weights after `step` steps.
    #[must_use]
    pub fn checkpoint_weights(&self, step: usize) -> PathBuf {
        self.dir
            .join("checkpoint")
            .join(format!("model-{step}.safetensors"))
    }
    /// The checkpoint's optimizer state after `step` steps.
    #[must_use]
    pub fn checkpoint_optimizer(&self, step: usize) -> PathBuf {
        self.dir
            .join("checkpoint")
            .join(format!("optimizer-{step}.burn"))
    }
    /// The number of steps of the last complete checkpoint: written (atomically, by a rename)
    /// only after that step's weights and optimizer state, so a run killed at any moment
    /// resumes from a checkpoint whose files belong together.
    #[must_use]
    pub fn checkpoint_step(&self) -> PathBuf {
        self.dir.join("checkpoint").join("step.json")
    }
    #[must_use]
    pub fn metrics(&self) -> PathBuf {
        self.dir.join("metrics.csv")
    }
    #[must_use]
    pub fn config(&self) -> PathBuf {
        self.dir.join("train.toml")
    }
}

/// The result of a finished run.
#[derive(Debug, Clone)]
pub struct TrainReport {
    /// All configured steps are done and the final weights written.
    pub finished: bool,
    /// Steps done in total (this run and before).
    pub steps_done: usize,
    pub weights: PathBuf,
    pub metrics: Vec<StepMetrics>,
    /// The step this run started from (0, or the checkpoint it resumed).
    pub resumed_from: usize,
    pub wall_s: f64,
}

/// A training run into a folder.
pub struct Trainer {
    pub config: TrainConfig,
    pub files: RunFiles,
}

fn io_err(path: &Path) -> impl Fn(std::io::Error) -> ProcNetError + '_ {
    move |source| ProcNetError::Io {
        path: path.to_path_buf(),
        source,
    }
}

impl Trainer {
    /// A run into `out`. A folder holding a checkpoint of the same configuration is resumed;
    /// one of another configuration is refused.
    pub fn new(config: TrainConfig, out: &Path) -> Result<Self> {
        config.validate()?;
        Ok(Self {
            files: RunFiles {
                dir: out.to_path_buf(),
                feed_forward: config.model.is_feed_forward(),
            },
            config,
        })
    }

    /// Trains to the configured number of steps, calling `progress` after each. With
    /// `stop_after`, stops (checkpointed, resumable) after that many steps of this run.
    pub fn run(
        &self,
        stop_after: Option<usize>,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<TrainReport> {
        let cfg = &self.config;
        let files = &self.files;
        std::fs::create_dir_all(files.dir.join("checkpoint")).map_err(io_err(&files.dir))?;
        self.check_or_write_config()?;

        // A wrong starting point is refused before the split is loaded.
        if let Some(init) = &cfg.init_weights {
            weights::check_start(init, &cfg.model)?;
        }
        let dataset = Dataset::open(&cfg.dataset)?;
        let train = load_split(&dataset, Split::Train, &cfg.model)?;
        let validation = validation_subset(
            load_split(&dataset, Split::Validation, &cfg.model)?,
            cfg.validation_sequences,
        );
        let usable: Vec<&SequenceTensors> =
            train.iter().filter(|s| s.frames >= cfg.window).collect();
        if usable.is_empty() {
            return Err(ProcNetError::Training {
                message: format!(
                    "no training sequence has {} frames (window); the dataset has {} training sequences",
                    cfg.window,
                    train.len()
                ),
            });
        }
        // Running sums of the sequences' sampling weights (none: uniform, as before).
        let cumulative: Option<Vec<f64>> = if cfg.sampling.is_uniform() {
            None
        } else {
            let keys = usable
                .iter()
                .map(|s| {
                    let sampling = &cfg.sampling;
                    // A usable sequence has at least a window's frames.
                    let first = if sampling.roi.is_empty() && sampling.view.is_empty() {
                        None
                    } else {
                        Some(dataset.frame_labels(&s.entry, 0)?)
                    };
                    let roi = first
                        .as_ref()
                        .filter(|_| !sampling.roi.is_empty())
                        .map(|f| f.roi.map_or(RoiKind::Frame, |r| r.kind).name().to_string());
                    // A frame without a torso label has no view; it matches no view factor.
                    let view = first
                        .as_ref()
                        .filter(|_| !sampling.view.is_empty())
                        .and_then(FrameLabels::view)
                        .map(|v| v.name().to_string());
                    let motion = if s.entry.clip.is_some() {
                        "recorded"
                    } else {
                        "generated"
                    };
                    Ok(SamplingKeys {
                        distance: s.entry.camera_class(),
                        roi,
                        view,
                        motion: motion.to_string(),
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            let weights = cfg.sampling.weights(&keys)?;
            let total: f64 = weights.iter().sum();
            let favoured = weights.iter().filter(|w| **w > 1.0).count();
            tracing::info!(
                sequences = weights.len(),
                weighted_up = favoured,
                "sampling by distance class, region of interest, view and motion"
            );
            Some(
                weights
                    .iter()
                    .scan(0.0, |sum, w| {
                        *sum += w / total;
                        Some(*sum)
                    })
                    .collect(),
            )
        };

        let device: Device = cfg.backend.device()?.autodiff();
        let mut model = cfg.model.init(&device, cfg.seed)?;
        if let Some(bias) = cfg.frame_prediction_bias {
            // A checkpoint or `init_weights`, loaded below, replaces it.
            model.set_frame_prediction_bias(bias);
        }
        let mut optim: ModuleOptimizer = AdamWConfig::new()
            .with_weight_decay(cfg.weight_decay)
            .with_grad_clipping(Some(GradientClippingConfig::Norm(cfg.clip_norm)))
            .init();

        // Resume from the checkpoint if there is one.
        let mut metrics: Vec<StepMetrics> = Vec::new();
        let mut start = 0usize;
        let step_path = files.checkpoint_step();
        let step_text = match read_text_file(&step_path, MAX_CONFIG_BYTES) {
            Ok(text) => Some(text),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(source) => {
                return Err(ProcNetError::Io {
                    path: step_path,
                    source,
                });
            }
        };
        if let Some(text) = step_text {
            start =
                serde_json::from_str::<usize>(text.trim()).map_err(|e| ProcNetError::Training {
                    message: format!("{}: {e}", step_path.display()),
                })?;
            if start > cfg.steps {
                return Err(ProcNetError::Training {
                    message: format!(
                        "{} says {start} steps are done, more than the run's {}: the folder \
                         belongs to another run (choose another --out, or delete the \
                         checkpoint folder to start again)",
                        step_path.display(),
                        cfg.steps
                    ),
                });
            }
            weights::load_checked(&mut model, &cfg.model, &files.checkpoint_weights(start))?;
            let optimizer_path = files.checkpoint_optimizer(start);
            workcell_robots::input::check_regular_file(&optimizer_path, weights::MAX_WEIGHTS_BYTES)
                .map_err(|source| ProcNetError::Io {
                    path: optimizer_path.clone(),
                    source,
                })?;
            let record =
                OptimizerRecord::load(&optimizer_path).map_err(|e| ProcNetError::Weights {
                    path: optimizer_path.clone(),
                    message: format!("cannot load the optimizer state: {e:?}"),
                })?;
            optim = optim.load_record(record);
            metrics = read_metrics(&files.metrics())
                .unwrap_or_default()
                .into_iter()
                .filter(|m| m.step <= start)
                .collect();
            tracing::info!(step = start, "resuming");
        } else if let Some(init) = &cfg.init_weights {
            // Its configuration was checked above, before the split was loaded.
            weights::load_start(&mut model, &cfg.model, init, &device)?;
            tracing::info!(weights = %init.display(), "starting from trained weights");
        }
        self.rewrite_metrics(&metrics)?;
        let elapsed_before = metrics.last().map_or(0.0, |m| m.elapsed_s);

        let clock = Instant::now();
        let classes = cfg.model.num_classes();
        let forearm = cfg.model.class_index(Class::Forearm);
        let class_weights =
            (!cfg.loss.class_weights.is_empty()).then(|| cfg.loss.weights_for(&cfg.model.classes));
        let end = stop_after.map_or(cfg.steps, |n| (start + n).min(cfg.steps));
        for step in start..end {
            // Every step draws from its own generator: a resumed run sees the same windows.
            let mut rng = ChaCha8Rng::seed_from_u64(
                cfg.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ step as u64,
            );
            let mut picks: Vec<(&SequenceTensors, usize, Augment)> = (0..cfg.batch)
                .map(|_| {
                    let seq = usable[match &cumulative {
                        Some(c) => draw_weighted(&mut rng, c),
                        None => rng.random_range(0..usable.len()),
                    }];
                    let start = rng.random_range(0..=seq.frames - cfg.window);
                    let aug = if cfg.augment.flip
                        || cfg.augment.max_shift_px > 0
                        || cfg.augment.min_crop < 1.0
                        || cfg.augment.jitter > 0.0
                    {
                        let mut a = Augment::draw(
                            &mut rng,
                            cfg.augment.max_shift_px.max(0),
                            cfg.augment.min_crop,
                            cfg.augment.jitter,
                        );
                        a.flip &= cfg.augment.flip;
                        a
                    } else {
                        Augment::NONE
                    };
                    (seq, start, aug)
                })
                .collect();
            // With burn-in, the windows share the first one's start (one batch of states),
            // and the frames before it, up to `burn_in`, join the batch in front.
            let mut burn = 0;
            if cfg.burn_in > 0 && !model.is_feed_forward() {
                let last = picks.iter().map(|(s, _, _)| s.frames).min().unwrap_or(0);
                let start = picks.first().map_or(0, |p| p.1).min(last - cfg.window);
                burn = cfg.burn_in.min(start);
                for p in &mut picks {
                    p.1 = start - burn;
                }
            }
            let batch = make_batch(&picks, burn + cfg.window, classes, &device);
            let lr = cfg.learning_rate(step);
            let initial = if model.is_feed_forward() {
                None
            } else {
                window_start(&model, &batch.rgb, burn, cfg.view_reads)
            };
            let losses = window_loss(
                &model,
                &batch.rgb[burn..],
                &batch.target[burn..],
                &cfg.loss,
                class_weights.as_deref(),
                initial,
            );
            let total = scalar(&losses.total);
            if !total.is_finite() {
                return Err(ProcNetError::Training {
                    message: format!(
                        "loss is {total} at step {step}; lower lr (now {lr:.2e}) or resume from the last checkpoint"
                    ),
                });
            }
            let grads = losses.total.backward();
            let grads = GradientsParams::from_grads(grads, &model);
            model = optim.step(lr, model, grads);

            let done = step + 1;
            let mut m = StepMetrics {
                step: done,
                lr,
                loss: total,
                dice: scalar(&losses.dice),
                focal: scalar(&losses.focal),
                prediction: losses.prediction.as_ref().map_or(0.0, scalar),
                val_forearm_dice: f64::NAN,
                elapsed_s: elapsed_before + clock.elapsed().as_secs_f64(),
            };
            if let Some(f) = forearm
                && cfg.validate_every > 0
                && (done % cfg.validate_every == 0 || done == cfg.steps)
                && !validation.is_empty()
            {
                m.val_forearm_dice =
                    validation_dice(&model.valid(), &validation, f, &cfg.backend.device()?);
            }
            self.append_metrics(&m)?;
            metrics.push(m);
            if done % cfg.checkpoint_every == 0 || done == end {
                self.checkpoint(&model, &optim, done)?;
            }
            progress(Progress {
                step: done,
                steps: cfg.steps,
                metrics: m,
            });
        }
        let finished = end == cfg.steps;
        if finished {
            weights::save(&model.valid(), &cfg.model, &files.weights())?;
        }
        Ok(TrainReport {
            finished,
            steps_done: end,
            weights: files.weights(),
            metrics,
            resumed_from: start,
            wall_s: clock.elapsed().as_secs_f64(),
        })
    }

    /// The run's settings as JSON, without what may change between sessions of one run
    /// (where the dataset lives, the backend, the thread count).
    fn run_identity(config: &TrainConfig) -> serde_json::Value {
        let mut v = serde_json::to_value(config).unwrap_or_default();
        if let Some(map) = v.as_object_mut() {
            // Where the files are and how fast it runs do not change the run; the starting
            // weights only matter before the first checkpoint.
            for key in ["dataset", "backend", "threads", "init_weights"] {
                map.remove(key);
            }
        }
        v
    }

    fn check_or_write_config(&self) -> Result<()> {
        let path = self.files.config();
        match read_text_file(&path, MAX_CONFIG_BYTES) {
            Ok(existing) => {
                let theirs: TrainConfig =
                    toml::from_str(&existing).map_err(|e| ProcNetError::ConfigFile {
                        path: path.clone(),
                        message: e.to_string(),
                    })?;
                let (mine, theirs) = (
                    Self::run_identity(&self.config),
                    Self::run_identity(&theirs),
                );
                if mine == theirs {
                    return Ok(());
                }
                Err(ProcNetError::Training {
                    message: format!(
                        "{} holds a run of another configuration ({}); choose another --out or delete it",
                        self.files.dir.display(),
                        weights::value_difference(&theirs, &mine)
                            .replace("expected", "was")
                            .replace("found", "now")
                    ),
                })
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                std::fs::write(&path, self.config.to_toml()).map_err(io_err(&path))
            }
            Err(e) => Err(ProcNetError::Io {
                path: path.clone(),
                source: e,
            }),
        }
    }

    /// Writes the checkpoint after `step` steps: the weights and optimizer state under names
    /// of their own, then `step.json` by a rename, then the previous checkpoint's files go.
    fn checkpoint(&self, model: &ProcNetModel, optim: &ModuleOptimizer, step: usize) -> Result<()> {
        let files = &self.files;
        weights::save(
            &model.valid(),
            &self.config.model,
            &files.checkpoint_weights(step),
        )?;
        let opt_path = files.checkpoint_optimizer(step);
        optim
            .to_record()
            .save(&opt_path)
            .map_err(|e| ProcNetError::Weights {
                path: opt_path.clone(),
                message: format!("cannot save the optimizer state: {e:?}"),
            })?;
        let step_path = files.checkpoint_step();
        let previous = read_text_file(&step_path, MAX_CONFIG_BYTES)
            .ok()
            .and_then(|t| t.trim().parse::<usize>().ok());
        workcell_robots::output::write_atomic(&step_path, step.to_string().as_bytes())
            .map_err(io_err(&step_path))?;
        if let Some(old) = previous.filter(|&old| old != step) {
            let _ = std::fs::remove_file(files.checkpoint_weights(old));
            let _ = std::fs::remove_file(files.checkpoint_optimizer(old));
        }
        Ok(())
    }

    fn rewrite_metrics(&self, metrics: &[StepMetrics]) -> Result<()> {
        let path = self.files.metrics();
        let mut text = String::from(CSV_HEADER);
        text.push('\n');
        for m in metrics {
            text.push_str(&m.csv());
            text.push('\n');
        }
        std::fs::write(&path, text).map_err(io_err(&path))
    }

    fn append_metrics(&self, m: &StepMetrics) -> Result<()> {
        let path = self.files.metrics();
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(io_err(&path))?;
        writeln!(f, "{}", m.csv()).map_err(io_err(&path))
    }
}

/// The value of a one-element tensor.
pub fn scalar(t: &Tensor<1>) -> f64 {
    t.clone().into_scalar::<f32>() as f64
}

/// Up to `count` sequences (0: all), taken in turn from each (distance class or camera,
/// occlusion) cell in the dataset's order.
fn validation_subset(all: Vec<SequenceTensors>, count: usize) -> Vec<SequenceTensors> {
    crate::data::per_cell_subset(all, count, |s| &s.entry)
}

/// Mean forearm Dice loss over the validation sequences (frames after the first), at the
/// model's resolution.
fn validation_dice(
    model: &ProcNetModel,
    sequences: &[SequenceTensors],
    class: usize,
    device: &Device,
) -> f64 {
    let mut sum = 0.0;
    let mut n = 0usize;
    for seq in sequences {
        let batch = make_batch(
            &[(seq, 0, Augment::NONE)],
            seq.frames,
            model_classes(model),
            device,
        );
        let mut state = model.initial_state(1, seq.size, seq.size, device);
        for (t, (x, y)) in batch.rgb.iter().zip(&batch.target).enumerate() {
            let (out, next) = model.step(x.clone(), state);
            state = next;
            if t == 0 {
                continue;
            }
            let p = burn::tensor::activation::sigmoid(out.logits);
            let d = dice_per_class(p, y.clone());
            sum += d.slice([0..1, class..class + 1]).into_scalar::<f32>() as f64;
            n += 1;
        }
    }
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

fn model_classes(model: &ProcNetModel) -> usize {
    model.head.weight.dims()[0]
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_render::dataset::SequenceEntry;

    fn sequence(index: usize, distance: &str, occlusion: &str, source: &str) -> SequenceTensors {
        SequenceTensors {
            entry: SequenceEntry {
                index,
                dir: String::new(),
                seed: 0,
                attempts: 1,
                distance_class: distance.into(),
                occlusion_level: occlusion.into(),
                source: source.to_string().try_into().expect("a camera source"),
                split: Split::Validation,
                frames: 0,
                mean_forearm_occlusion: None,
                frames_without_forearm: 0,
                clip: None,
            },
            size: 0,
            frames: 0,
            channels: 3,
            rgb: Vec::new(),
            target: Vec::new(),
        }
    }

    #[test]
    fn hostile_recipes_are_refused_naming_the_key() {
        // Each of these panicked or trained nothing (issue: hostile input).
        for (toml, key) in [
            ("[augment]\njitter = nan", "augment.jitter"),
            ("[augment]\njitter = 1e300", "augment.jitter"),
            ("[augment]\nmax_shift_px = 100000", "augment.max_shift_px"),
            ("[loss]\ndice = 0.0\nbatch_dice = 0.0\nfocal = 0.0", "all 0"),
            ("[loss]\nfocal = 1e300", "loss"),
            ("[loss.class_weights]\nforearm = nan", "loss.class_weights"),
            (
                "[loss.class_weights]\nupperarm = 4.0",
                "no class \"upperarm\"",
            ),
            (
                "[loss.class_weights]\nrobot = 0.0\ntorso = 0.0\nupper_arm = 0.0\nforearm = 0.0\nhand = 0.0",
                "all 0",
            ),
            ("steps = 100000000000", "steps"),
            ("window = 1000000", "window"),
            ("burn_in = 1000000", "burn_in"),
            ("view_reads = 17", "view_reads"),
            ("frame_prediction_bias = nan", "frame_prediction_bias"),
            ("frame_prediction_bias = -0.5", "frame_prediction_bias"),
            (
                "[sampling]\ndistance = { large = -1.0 }",
                "sampling.distance",
            ),
            ("[sampling]\nroi = { workspace = nan }", "sampling.roi"),
            ("[sampling]\nroi = { workspace = 1e300 }", "sampling.roi"),
            ("[sampling]\nview = { back = inf }", "sampling.view"),
        ] {
            let config: TrainConfig = match toml::from_str(toml) {
                Ok(c) => c,
                // A number TOML cannot hold in the field's type is the parser's error.
                Err(e) => panic!("{toml}: {e}"),
            };
            let err = config.validate().expect_err(toml).to_string();
            assert!(err.contains(key), "{toml}: {err}");
        }
        assert!(TrainConfig::default().validate().is_ok());
    }

    #[test]
    fn the_validation_subset_takes_every_cell_in_turn() {
        // Three cells (the cell's camera apart from the paper's short class), unequal sizes.
        let mut all = Vec::new();
        for i in 0..5 {
            all.push(sequence(i, "short", "light", "paper"));
        }
        all.push(sequence(5, "short", "light", "camera:front"));
        for i in 6..8 {
            all.push(sequence(i, "large", "heavy", "paper"));
        }
        let pick = |count| -> Vec<usize> {
            let mut v: Vec<usize> = validation_subset(all.clone(), count)
                .iter()
                .map(|s| s.entry.index)
                .collect();
            v.sort_unstable();
            v
        };
        // One per cell, the first of each in the dataset's order.
        assert_eq!(pick(3), vec![0, 5, 6]);
        // Then round-robin among the cells that still have sequences.
        assert_eq!(pick(5), vec![0, 1, 5, 6, 7]);
        assert_eq!(pick(6), vec![0, 1, 2, 5, 6, 7]);
        // 0 or more than there are: all of them.
        assert_eq!(pick(0).len(), 8);
        assert_eq!(pick(100).len(), 8);
    }

    fn keys(rows: &[(&str, Option<&str>)]) -> Vec<SamplingKeys> {
        rows.iter()
            .map(|(d, r)| SamplingKeys {
                distance: (*d).to_string(),
                roi: r.map(str::to_string),
                view: None,
                motion: "generated".to_string(),
            })
            .collect()
    }

    #[test]
    fn a_sequence_weighs_the_product_of_the_factors_it_matches() {
        let sampling: SamplingConfig =
            toml::from_str("distance = { large = 2.0, short = 0.5 }\nroi = { workspace = 3.0 }")
                .expect("parses");
        let w = sampling
            .weights(&keys(&[
                ("large", Some("workspace")),
                ("large", Some("tracked")),
                ("medium", Some("workspace")),
                ("medium", Some("tracked")),
                ("short", None),
            ]))
            .expect("valid");
        assert_eq!(w, vec![6.0, 2.0, 3.0, 1.0, 0.5]);
        // The view multiplies in too; a sequence without a view matches no view factor.
        let sampling: SamplingConfig =
            toml::from_str("distance = { large = 2.0 }\nview = { back = 3.0, side = 0.5 }")
                .expect("parses");
        let mut seqs = keys(&[
            ("large", None),
            ("large", None),
            ("short", None),
            ("short", None),
        ]);
        for (s, view) in seqs
            .iter_mut()
            .zip([Some("back"), Some("side"), Some("back"), None])
        {
            s.view = view.map(str::to_string);
        }
        assert_eq!(
            sampling.weights(&seqs).expect("valid"),
            vec![6.0, 1.0, 3.0, 1.0]
        );
        // The motion's source multiplies in too; a table names a source some sequence has.
        let sampling: SamplingConfig =
            toml::from_str("distance = { large = 2.0 }\nmotion = { recorded = 3.0 }")
                .expect("parses");
        assert!(!sampling.is_uniform());
        seqs[1].motion = "recorded".to_string();
        seqs[2].motion = "recorded".to_string();
        assert_eq!(
            sampling.weights(&seqs).expect("valid"),
            vec![2.0, 6.0, 3.0, 1.0]
        );
        let misspelt: SamplingConfig =
            toml::from_str("motion = { recordeds = 3.0 }").expect("parses");
        let err = misspelt.weights(&seqs).expect_err("no such motion");
        assert!(err.to_string().contains("sampling.motion"), "{err}");
        // No tables: every sequence 1.
        let uniform = SamplingConfig::default();
        assert!(uniform.is_uniform());
        assert_eq!(
            uniform
                .weights(&keys(&[("large", Some("workspace")), ("short", None)]))
                .expect("valid"),
            vec![1.0, 1.0]
        );
    }

    #[test]
    fn sampling_keys_no_sequence_has_and_all_zero_weights_are_refused() {
        let seqs = keys(&[("large", Some("workspace")), ("short", Some("tracked"))]);
        for (toml, words) in [
            (
                "distance = { larg = 2.0 }",
                ["sampling.distance", "\"larg\""],
            ),
            ("roi = { frame = 2.0 }", ["sampling.roi", "\"frame\""]),
            ("view = { back = 2.0 }", ["sampling.view", "\"back\""]),
            (
                "distance = { large = 0.0, short = 0.0 }",
                ["sampling", "weight 0"],
            ),
        ] {
            let sampling: SamplingConfig = toml::from_str(toml).expect("parses");
            let err = sampling.weights(&seqs).expect_err(toml).to_string();
            for w in words {
                assert!(err.contains(w), "{toml}: {err}");
            }
        }
    }

    #[test]
    fn weighted_draws_follow_the_weights() {
        // Weights 1, 0, 3, 4 (sum 8): running sums 1/8, 1/8, 4/8, 1.
        let cumulative = [0.125, 0.125, 0.5, 1.0];
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 80_000;
        let mut counts = [0usize; 4];
        for _ in 0..n {
            counts[draw_weighted(&mut rng, &cumulative)] += 1;
        }
        assert_eq!(counts[1], 0, "a weight of 0 is never drawn");
        for (i, p) in [(0, 0.125), (2, 0.375), (3, 0.5)] {
            // Five binomial standard deviations: fails by chance about once in 1.7 million.
            let sd = (n as f64 * p * (1.0 - p)).sqrt();
            let err = (counts[i] as f64 - n as f64 * p).abs();
            assert!(
                err < 5.0 * sd,
                "index {i}: {} draws, expected {}",
                counts[i],
                n as f64 * p
            );
        }
        // Leading weights of 0 are never drawn either.
        assert_eq!(draw_weighted(&mut rng, &[0.0, 0.0, 1.0]), 2);
    }

    #[test]
    fn a_recipe_without_sampling_keeps_its_identity() {
        // Runs written before `sampling` existed resume: the default is not serialised.
        let text = TrainConfig::default().to_toml();
        assert!(!text.contains("sampling"), "{text}");
        let mut weighted = TrainConfig::default();
        weighted.sampling.roi.insert("workspace".into(), 2.0);
        let back: TrainConfig = toml::from_str(&weighted.to_toml()).expect("round trip");
        assert_eq!(back, weighted);
    }
}
