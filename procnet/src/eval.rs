//! Segmentation evaluation on a dataset split, measured as the paper measures and more: per
//! class and per (distance, occlusion) cell, the per-frame Dice loss (the paper's quantity),
//! the batch Dice loss (all frames of a group as one volume), IoU and focal loss, the mean over
//! the classes, and that mean on the scale of the authors' public test code; each with the
//! frames and sequences behind it.
//!
//! Predictions are made at the model's resolution and their logits upsampled (bilinear) to
//! the dataset's, so that every model is scored against the same stored labels.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use workcell_render::Class;
use workcell_render::roi::perfect_dice_loss;

use burn::tensor::activation::sigmoid;
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor, TensorData};
use workcell_render::dataset::{Dataset, Sequence, Split};

use crate::config::ProcNetConfig;
use crate::data::{class_map, model_frames, one_hot, per_cell_subset, to_byte};
use crate::error::{ProcNetError, Result};
use crate::loss::{dice_per_class, focal_per_class, iou_per_class};
use crate::model::ProcNetModel;

/// The authors' public test code sums the per-frame losses of frames 21 to 49 of each
/// 50-frame sequence and divides by 50 (`reference/PROCNET.md`): a per-frame mean times 29/50.
pub const AUTHORS_SCALE: f64 = 29.0 / 50.0;

/// Sums over the frames of one group.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scores {
    pub frames: usize,
    /// Indices of the sequences the frames come from.
    pub sequences: BTreeSet<usize>,
    /// Per class: sums over frames of the per-frame losses.
    pub dice: Vec<f64>,
    pub focal: Vec<f64>,
    pub iou: Vec<f64>,
    /// Per class: `sum p y`, `sum p` and `sum y` over all pixels of all frames (batch Dice).
    pub intersection: Vec<f64>,
    pub predicted: Vec<f64>,
    pub truth: Vec<f64>,
    /// Sum and count of the forearm's resolution ceiling over the frames whose labels have it
    /// (a perfect network's Dice loss at the dataset's stored size against the camera's image,
    /// `PartLabel::perfect_dice_loss`).
    pub ceiling: f64,
    pub ceiling_frames: usize,
    /// Sum and count of the forearm's ceiling at the model's input: the stored truth averaged
    /// to the input grid, upsampled back as the predictions are and thresholded at one half
    /// (`workcell_render::roi::perfect_dice_loss`), scored against the stored labels.
    pub input_ceiling: f64,
    pub input_ceiling_frames: usize,
    /// Where the forearm's loss goes, from the thresholded masks ([`ForearmBreakdown`]).
    pub breakdown: BreakdownSums,
}

/// Sums over a group's frames of each frame's [`ForearmBreakdown`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BreakdownSums {
    /// Per-frame forearm Dice loss of the thresholded masks.
    pub hard_dice: f64,
    /// The same with the arm's inner boundaries right ([`ForearmBreakdown::inner_dice_loss`]).
    pub inner_dice: f64,
    /// Frames with a true forearm of which no pixel is predicted forearm.
    pub missed: usize,
    /// Frames with a true forearm.
    pub present: usize,
    /// True forearm pixels, by the class predicted for them (indexed by `Class as u8`).
    pub truth_as: [f64; CLASSES],
    /// Of the true forearm pixels predicted background: those on the true mask's edge.
    pub background_at_edge: f64,
}

impl BreakdownSums {
    fn add(&mut self, b: &ForearmBreakdown) {
        self.hard_dice += b.dice_loss();
        self.inner_dice += b.inner_dice_loss();
        self.present += usize::from(b.present());
        self.missed += usize::from(b.missed());
        for (sum, &n) in self.truth_as.iter_mut().zip(&b.truth_as) {
            *sum += n as f64;
        }
        self.background_at_edge += b.background_at_edge as f64;
    }

    /// `pixels` as a share of the true forearm's pixels (NaN when there are none).
    fn share(&self, pixels: f64) -> f64 {
        let total: f64 = self.truth_as.iter().sum();
        if total > 0.0 {
            pixels / total
        } else {
            f64::NAN
        }
    }

    /// The share of the true forearm's pixels predicted as `class`.
    #[must_use]
    pub fn truth_share(&self, class: Class) -> f64 {
        self.share(self.truth_as[class as usize])
    }

    /// The share of the true forearm's pixels predicted background on the true mask's edge.
    #[must_use]
    pub fn background_at_edge_share(&self) -> f64 {
        self.share(self.background_at_edge)
    }
}

/// Every [`Class`], background included.
const CLASSES: usize = Class::ALL.len();

/// The arm's parts: the classes between which the forearm's ends are drawn (the elbow and the
/// wrist), not by colour (a bare arm is one skin from shoulder to fingers).
const ARM: [Class; 3] = [Class::UpperArm, Class::Forearm, Class::Hand];

/// One frame's forearm, thresholded as the contact sheet draws it (each pixel the most probable
/// class above one half, else the background), counted so that its loss can be split into the
/// forearm not found at all, found but cut at the wrong place along the arm, and the rest.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ForearmBreakdown {
    /// Pixels true forearm and predicted forearm.
    pub found: u64,
    /// Predicted forearm, truly another class.
    pub false_found: u64,
    /// True forearm, predicted another class.
    pub missed_pixels: u64,
    /// Of `false_found`: truly upper arm or hand.
    pub false_found_in_arm: u64,
    /// Of `missed_pixels`: predicted upper arm or hand.
    pub missed_in_arm: u64,
    /// True forearm pixels by the class predicted for them (indexed by `Class as u8`).
    pub truth_as: [u64; CLASSES],
    /// Of the true forearm pixels predicted background: those with a 4-neighbour in the image
    /// that is not true forearm (a mask drawn thinner than the forearm loses these first; a
    /// hidden stretch not filled in loses inner ones too).
    pub background_at_edge: u64,
}

impl ForearmBreakdown {
    /// Counts one frame; `truth` and `predicted` hold `Class as u8` per pixel, row by row,
    /// `width` pixels a row (equal lengths).
    #[must_use]
    pub fn count(truth: &[u8], predicted: &[u8], width: usize) -> Self {
        let (forearm, in_arm) = (Class::Forearm as u8, |v: u8| {
            ARM.iter().any(|&c| c as u8 == v)
        });
        let is_forearm = |i: Option<usize>| i.and_then(|i| truth.get(i)) == Some(&forearm);
        let on_edge = |i: usize| {
            let x = i % width.max(1);
            let left = (x > 0).then(|| i - 1);
            let right = (x + 1 < width).then_some(i + 1);
            [
                left,
                right,
                i.checked_sub(width),
                Some(i + width).filter(|&j| j < truth.len()),
            ]
            .into_iter()
            .any(|n| n.is_some() && !is_forearm(n))
        };
        let mut b = Self::default();
        for (i, (&t, &p)) in truth.iter().zip(predicted).enumerate() {
            match (t == forearm, p == forearm) {
                (true, true) => b.found += 1,
                (false, true) => {
                    b.false_found += 1;
                    b.false_found_in_arm += u64::from(in_arm(t));
                }
                (true, false) => {
                    b.missed_pixels += 1;
                    b.missed_in_arm += u64::from(in_arm(p));
                }
                (false, false) => {}
            }
            if t == forearm
                && let Some(n) = b.truth_as.get_mut(usize::from(p))
            {
                *n += 1;
                if p == Class::Background as u8 && on_edge(i) {
                    b.background_at_edge += 1;
                }
            }
        }
        b
    }

    fn smoothed_loss(found: u64, false_found: u64, missed: u64) -> f64 {
        let (tp, fp, fneg) = (found as f64, false_found as f64, missed as f64);
        1.0 - (2.0 * tp + 1.0) / (2.0 * tp + fp + fneg + 1.0)
    }

    /// The forearm's Dice loss on the thresholded masks, smoothed as the per-frame loss is.
    #[must_use]
    pub fn dice_loss(&self) -> f64 {
        Self::smoothed_loss(self.found, self.false_found, self.missed_pixels)
    }

    /// The same loss had every pixel that is arm in both truth and prediction been given its
    /// true part: what is left when the elbow and the wrist are put in the right place.
    #[must_use]
    pub fn inner_dice_loss(&self) -> f64 {
        Self::smoothed_loss(
            self.found + self.missed_in_arm,
            self.false_found - self.false_found_in_arm,
            self.missed_pixels - self.missed_in_arm,
        )
    }

    /// Whether the frame has a true forearm.
    #[must_use]
    pub fn present(&self) -> bool {
        self.found + self.missed_pixels > 0
    }

    /// A true forearm of which no pixel is predicted forearm.
    #[must_use]
    pub fn missed(&self) -> bool {
        self.present() && self.found == 0
    }
}

/// One frame's scores, per class.
#[derive(Debug, Clone, Default)]
struct FrameScores {
    dice: Vec<f32>,
    focal: Vec<f32>,
    iou: Vec<f32>,
    intersection: Vec<f32>,
    predicted: Vec<f32>,
    truth: Vec<f32>,
    ceiling: Option<f64>,
    input_ceiling: Option<f64>,
    breakdown: ForearmBreakdown,
}

impl Scores {
    fn add(&mut self, sequence: usize, f: &FrameScores) {
        let c = f.dice.len();
        for v in [
            &mut self.dice,
            &mut self.focal,
            &mut self.iou,
            &mut self.intersection,
            &mut self.predicted,
            &mut self.truth,
        ] {
            v.resize(c, 0.0);
        }
        for k in 0..c {
            self.dice[k] += f64::from(f.dice[k]);
            self.focal[k] += f64::from(f.focal[k]);
            self.iou[k] += f64::from(f.iou[k]);
            self.intersection[k] += f64::from(f.intersection[k]);
            self.predicted[k] += f64::from(f.predicted[k]);
            self.truth[k] += f64::from(f.truth[k]);
        }
        if let Some(v) = f.ceiling {
            self.ceiling += v;
            self.ceiling_frames += 1;
        }
        if let Some(v) = f.input_ceiling {
            self.input_ceiling += v;
            self.input_ceiling_frames += 1;
        }
        self.breakdown.add(&f.breakdown);
        self.frames += 1;
        self.sequences.insert(sequence);
    }

    fn mean(&self, sums: &[f64], c: usize) -> f64 {
        sums.get(c)
            .map_or(f64::NAN, |v| v / self.frames.max(1) as f64)
    }

    /// Mean per-frame Dice loss of class `c` (the paper's Table 1 quantity).
    #[must_use]
    pub fn dice(&self, c: usize) -> f64 {
        self.mean(&self.dice, c)
    }
    #[must_use]
    pub fn focal(&self, c: usize) -> f64 {
        self.mean(&self.focal, c)
    }
    #[must_use]
    pub fn iou(&self, c: usize) -> f64 {
        self.mean(&self.iou, c)
    }

    /// Dice loss of class `c` with all the group's frames as one volume (no smoothing; 0 when
    /// the class is neither present nor predicted anywhere).
    #[must_use]
    pub fn batch_dice(&self, c: usize) -> f64 {
        let (Some(i), Some(p), Some(t)) = (
            self.intersection.get(c),
            self.predicted.get(c),
            self.truth.get(c),
        ) else {
            return f64::NAN;
        };
        if p + t <= 0.0 {
            0.0
        } else {
            1.0 - 2.0 * i / (p + t)
        }
    }

    /// The mean over all classes of the per-frame Dice loss.
    #[must_use]
    pub fn class_mean_dice(&self) -> f64 {
        let n = self.dice.len();
        if n == 0 {
            return f64::NAN;
        }
        (0..n).map(|c| self.dice(c)).sum::<f64>() / n as f64
    }

    /// The mean forearm resolution ceiling (NaN when no frame's labels have it).
    #[must_use]
    pub fn ceiling(&self) -> f64 {
        mean_or_nan(self.ceiling, self.ceiling_frames)
    }

    /// The mean forearm ceiling at the model's input (NaN when no frame has a forearm).
    #[must_use]
    pub fn input_ceiling(&self) -> f64 {
        mean_or_nan(self.input_ceiling, self.input_ceiling_frames)
    }
}

/// `sum / n`, NaN for no frames.
fn mean_or_nan(sum: f64, n: usize) -> f64 {
    if n == 0 { f64::NAN } else { sum / n as f64 }
}

/// Layer 0's prediction of each frame (`clamp(Ahat_0, 0, 1)`, the prediction loss on) against
/// the frame, summed over the frames scored. A colour channel predicted black at every pixel
/// has a ReLU below zero everywhere: it gets no gradient and never learns (experiments/perception.md,
/// "A colour channel that never learns").
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FramePrediction {
    /// Pixels of each colour channel predicted exactly 0.
    pub black: [u64; 3],
    /// Pixels per colour channel.
    pub pixels: u64,
    /// The sum of |prediction - frame| over every value.
    pub abs_error: f64,
}

impl FramePrediction {
    /// A channel at least this share of whose pixels is black is reported as never learning.
    pub const DEAD: f64 = 0.999;

    /// Adds one frame: planar `[3, n]` prediction and frame.
    pub fn add(&mut self, predicted: &[f32], frame: &[f32]) {
        let n = predicted.len() / 3;
        for (c, black) in self.black.iter_mut().enumerate() {
            *black += predicted[c * n..][..n]
                .iter()
                .filter(|&&v| v <= 0.0)
                .count() as u64;
        }
        self.pixels += n as u64;
        self.abs_error += predicted
            .iter()
            .zip(frame)
            .map(|(p, f)| f64::from((p - f).abs()))
            .sum::<f64>();
    }

    /// The share of each colour channel's pixels predicted black.
    #[must_use]
    pub fn black_share(&self) -> [f64; 3] {
        self.black.map(|b| b as f64 / self.pixels.max(1) as f64)
    }

    /// The mean absolute error of the prediction, per value.
    #[must_use]
    pub fn mean_abs_error(&self) -> f64 {
        self.abs_error / (3 * self.pixels.max(1)) as f64
    }

    /// One sentence for the report.
    #[must_use]
    pub fn summary(&self) -> String {
        let share = self.black_share();
        let dead: Vec<&str> = ["red", "green", "blue"]
            .into_iter()
            .zip(share)
            .filter(|&(_, s)| s >= Self::DEAD)
            .map(|(name, _)| name)
            .collect();
        let mut text = format!(
            "Layer 0's prediction of the frame: mean absolute error {:.4}; pixels predicted \
             black: red {:.1} %, green {:.1} %, blue {:.1} %.",
            self.mean_abs_error(),
            100.0 * share[0],
            100.0 * share[1],
            100.0 * share[2]
        );
        if !dead.is_empty() {
            text.push_str(&format!(
                " **The {} channel{} predict{} black everywhere: {} never learned** \
                 (experiments/perception.md, \"A colour channel that never learns\").",
                dead.join(" and "),
                if dead.len() > 1 { "s" } else { "" },
                if dead.len() > 1 { "" } else { "s" },
                if dead.len() > 1 { "they" } else { "it" },
            ));
        }
        text
    }
}

/// A frame's images on a contact sheet ([`prediction_sheet`](workcell_render::dataset::prediction_sheet)).
#[derive(Debug, Clone, PartialEq)]
pub struct SheetImages {
    /// Stored-size frame, interleaved RGB bytes.
    pub rgb: Vec<u8>,
    /// The true class of each pixel (`Class as u8`).
    pub truth: Vec<u8>,
    /// The predicted class (`Class as u8`).
    pub predicted: Vec<u8>,
    pub width: usize,
    pub height: usize,
}

impl SheetImages {
    /// The frame as a panel of the sheet.
    #[must_use]
    pub fn panel<'a>(&'a self, title: &'a str) -> workcell_render::dataset::PredictionPanel<'a> {
        workcell_render::dataset::PredictionPanel {
            title,
            width: self.width,
            height: self.height,
            rgb: &self.rgb,
            truth: &self.truth,
            predicted: &self.predicted,
        }
    }
}

/// A frame kept for the contact sheet of the worst predictions.
#[derive(Debug, Clone)]
pub struct ScoredFrame {
    pub sequence: usize,
    pub frame: usize,
    pub distance_class: String,
    pub occlusion_level: String,
    /// The forearm's Dice loss on this frame.
    pub forearm_dice: f64,
    /// Its images; the prediction is the most probable class above one half, else the
    /// background.
    pub images: SheetImages,
}

/// Frames per span of the table by time in the sequence.
pub const TIME_SPAN: usize = 10;

/// One scored frame's forearm (a row of `workcell eval segmentation --frames`).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameRecord {
    pub sequence: usize,
    pub frame: usize,
    /// The distance class, or the camera of the cell.
    pub camera: String,
    pub occlusion_level: String,
    /// True forearm pixels at the stored size.
    pub forearm_px: u64,
    /// The per-frame Dice loss (probabilities).
    pub forearm_dice: f64,
    /// The per-frame Dice loss of the thresholded mask ([`ForearmBreakdown::dice_loss`]).
    pub forearm_dice_thresholded: f64,
    /// The same with the elbow and the wrist in the right place
    /// ([`ForearmBreakdown::inner_dice_loss`]).
    pub forearm_dice_parts_right: f64,
    /// A perfect network's Dice loss at the model's input (`None`: no true forearm).
    pub input_ceiling: Option<f64>,
    /// The visible forearm's mean luma in the input image ([`masked_luma`]; `None`: no true
    /// forearm).
    pub forearm_luma: Option<f64>,
}

impl FrameRecord {
    /// The CSV header of [`FrameRecord::csv_row`].
    pub const CSV_HEADER: &str = "sequence,frame,camera,occlusion,forearm_px,forearm_dice,forearm_dice_thresholded,input_ceiling,forearm_luma,forearm_dice_parts_right";

    /// One CSV row (an empty field for a missing ceiling or luma).
    #[must_use]
    pub fn csv_row(&self) -> String {
        format!(
            "{},{},{},{},{},{:.6},{:.6},{},{},{:.6}",
            self.sequence,
            self.frame,
            csv_field(&self.camera),
            csv_field(&self.occlusion_level),
            self.forearm_px,
            self.forearm_dice,
            self.forearm_dice_thresholded,
            self.input_ceiling
                .map_or(String::new(), |v| format!("{v:.6}")),
            self.forearm_luma
                .map_or(String::new(), |v| format!("{v:.6}")),
            self.forearm_dice_parts_right
        )
    }
}

/// A CSV field: quoted (quotes doubled) when it holds a comma, a quote or a line break, as a
/// camera's name from a scenario file may.
pub fn csv_field(s: &str) -> std::borrow::Cow<'_, str> {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\"")).into()
    } else {
        s.into()
    }
}

/// The scores of a split, overall and per group.
#[derive(Debug, Clone, Default)]
pub struct Evaluation {
    pub classes: Vec<Class>,
    pub split: String,
    pub sequences: usize,
    pub overall: Scores,
    /// Keyed by occlusion level.
    pub by_occlusion: BTreeMap<String, Scores>,
    /// Keyed by distance class (a camera of the cell by its name: `front camera`).
    pub by_distance: BTreeMap<String, Scores>,
    /// Keyed by (distance class or camera, occlusion level).
    pub by_pair: BTreeMap<(String, String), Scores>,
    /// Keyed by the first frame index of a span of [`TIME_SPAN`] frames: how the scores
    /// change as the recurrent network sees more of a sequence.
    pub by_time: BTreeMap<usize, Scores>,
    /// Keyed by the band of the visible forearm's luma ([`LumaBand`]): whether a dark
    /// forearm (dark skin, a dark sleeve, shade) is found as well as a light one.
    pub by_luma: BTreeMap<LumaBand, Scores>,
    /// Keyed by where the human's motion came from: `recorded` (a clip of recorded people,
    /// named in the manifest) or `generator`; empty when every sequence is the generator's.
    pub by_motion: BTreeMap<&'static str, Scores>,
    /// The frames of highest forearm Dice loss, worst first (as many as asked for).
    pub worst: Vec<ScoredFrame>,
    /// Every scored frame's forearm, in the order scored (empty without a forearm class).
    pub frames: Vec<FrameRecord>,
    /// Layer 0's prediction of the frames (none without the prediction loss).
    pub frame_prediction: Option<FramePrediction>,
    /// The order of the tables' rows: the dataset's camera classes and occlusion levels as
    /// its configuration lists them ([`Dataset::label_order`]); names not in them come
    /// last, alphabetically.
    pub order: (Vec<String>, Vec<String>),
}

/// How light the visible forearm is in a frame: the mean luma of its pixels in the input
/// image (Rec. 709 weights on the stored sRGB values, 0 black to 1 white). The bounds split
/// the default dataset's test sequences roughly into the darkest quarter, the middle half and
/// the lightest quarter (a sequence by the mean luma of its visible forearm over its frames:
/// quartiles 0.19 and 0.49).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LumaBand {
    /// Luma below [`LumaBand::DARK_BELOW`].
    Dark,
    Mid,
    /// Luma at or above [`LumaBand::LIGHT_FROM`].
    Light,
}

impl LumaBand {
    pub const DARK_BELOW: f64 = 0.2;
    pub const LIGHT_FROM: f64 = 0.5;

    #[must_use]
    pub fn of(luma: f64) -> Self {
        if luma < Self::DARK_BELOW {
            Self::Dark
        } else if luma < Self::LIGHT_FROM {
            Self::Mid
        } else {
            Self::Light
        }
    }

    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Dark => "dark",
            Self::Mid => "mid",
            Self::Light => "light",
        }
    }
}

/// The mean luma of the pixels where `mask` is not 0, in a planar `[3, n]` sRGB image with
/// values in [0, 1]; `None` when the mask is empty.
#[must_use]
pub fn masked_luma(planar: &[f32], mask: &[u8]) -> Option<f64> {
    luma_where(planar, mask.len(), |p| mask[p] != 0)
}

/// The mean luma ([`masked_luma`]) of the forearm as the camera sees it in frame `t`: the
/// pixels its visible classes (`classes` names the dataset's class indices) call forearm;
/// `None` when none shows. Not the class frame's forearm: under the occluder the input is
/// black, and counting those pixels would file an occluded light arm as a dark one.
#[must_use]
pub fn visible_forearm_luma(seq: &Sequence, t: usize, classes: &[Class]) -> Option<f64> {
    let forearm = classes.iter().position(|&c| c == Class::Forearm)?;
    let visible = seq.visible_frame(t);
    luma_where(seq.rgb_frame(t), visible.len(), |p| {
        usize::from(visible[p]) == forearm
    })
}

/// The mean luma of the pixels `p < n` of a planar `[3, n]` image for which `keep(p)`.
fn luma_where(planar: &[f32], n: usize, keep: impl Fn(usize) -> bool) -> Option<f64> {
    if planar.len() < 3 * n {
        return None;
    }
    let (mut sum, mut count) = (0.0, 0usize);
    for p in (0..n).filter(|&p| keep(p)) {
        let [r, g, b] = [0, 1, 2].map(|ch| f64::from(planar[ch * n + p]));
        sum += 0.2126 * r + 0.7152 * g + 0.0722 * b;
        count += 1;
    }
    (count > 0).then(|| sum / count as f64)
}

/// A name's place among a table's rows: its index in `order`, names not in it after.
fn rank(order: &[String], name: &str) -> usize {
    order.iter().position(|n| n == name).unwrap_or(order.len())
}

/// Reads a `[1, c]` tensor.
fn row(t: Tensor<2>) -> Vec<f32> {
    t.into_data().try_into_vec::<f32>().unwrap_or_default()
}

/// Evaluates `model` on a split, or on `sequences` of it taken in turn from each (camera
/// class, occlusion level) cell (0: all; [`per_cell_subset`]). Frame 0 of each sequence
/// (weight 0 in training) is left out.
/// Keeps the `keep_worst` frames of highest forearm Dice loss. `progress` is called after
/// each sequence with (done, total).
// The split and its subset, the model and its configuration, the dataset, the device, the
// sheet's frame count and the progress callback: each a separate choice of the caller.
#[allow(clippy::too_many_arguments)]
pub fn evaluate(
    model: &ProcNetModel,
    config: &ProcNetConfig,
    dataset: &Dataset,
    split: Split,
    sequences: usize,
    device: &Device,
    keep_worst: usize,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Evaluation> {
    let map = class_map(config, dataset)?;
    let entries = per_cell_subset(
        dataset.entries(Some(split)).cloned().collect(),
        sequences,
        |e| e,
    );
    if entries.is_empty() {
        return Err(ProcNetError::Input {
            message: format!(
                "the dataset at {} has no {} sequences",
                dataset.root.display(),
                split.name()
            ),
        });
    }
    let mut ev = Evaluation {
        classes: config.classes.clone(),
        split: split.name().to_string(),
        sequences: entries.len(),
        order: dataset.label_order(),
        ..Evaluation::default()
    };
    let c = map.len();
    let forearm = config.class_index(Class::Forearm);
    for (k, entry) in entries.iter().enumerate() {
        let seq = dataset.load(entry)?;
        let depth = crate::data::depth_frames(dataset, &seq, config)?;
        let frames = model_frames(&seq, depth.as_deref(), config)?;
        let (w, h) = (seq.width as usize, seq.height as usize);
        let s = config.input_size;
        let planes = config.input_planes();
        let mut state = model.initial_state(1, s, s, device);
        for t in 0..seq.len() {
            let x = Tensor::<4>::from_data(
                TensorData::new(
                    frames[t * planes * s * s..][..planes * s * s].to_vec(),
                    [1, planes, s, s],
                ),
                device,
            );
            let (out, next) = model.step(x, state);
            state = next;
            if t == 0 {
                continue;
            }
            if let Some(prediction) = out.prediction {
                let predicted = prediction
                    .into_data()
                    .try_into_vec::<f32>()
                    .unwrap_or_default();
                // The colour planes: a network that reads depth predicts its plane after them.
                let rgb = 3 * s * s;
                if let Some(colour) = predicted.get(..rgb) {
                    ev.frame_prediction
                        .get_or_insert_default()
                        .add(colour, &frames[t * planes * s * s..][..rgb]);
                }
            }
            let logits = if (h, w) == (s, s) {
                out.logits
            } else {
                let mut options = InterpolateOptions::new(InterpolateMode::Bilinear);
                options.align_corners = false;
                options.output_size = Some([h, w]);
                interpolate(out.logits, options)
            };
            let y = Tensor::<4>::from_data(
                TensorData::new(one_hot(seq.class_frame(t), &map), [1, c, h, w]),
                device,
            );
            let p = sigmoid(logits.clone());
            let sums =
                |t: Tensor<4>| row(t.reshape([1i32, c as i32, -1]).sum_dim(2).reshape([1, c]));
            let probabilities = p
                .clone()
                .into_data()
                .try_into_vec::<f32>()
                .unwrap_or_default();
            let truth: Vec<u8> = seq
                .class_frame(t)
                .iter()
                .map(|&v| {
                    let class = dataset.manifest.classes.get(usize::from(v));
                    class.map_or(Class::Background, |&c| c) as u8
                })
                .collect();
            let predicted: Vec<u8> = argmax(&probabilities, c, w * h)
                .into_iter()
                .map(|k| {
                    let class = k.checked_sub(1).map(|k| config.classes[usize::from(k)]);
                    class.unwrap_or(Class::Background) as u8
                })
                .collect();
            let forearm_mask: Vec<u8> = truth
                .iter()
                .map(|&v| u8::from(v == Class::Forearm as u8))
                .collect();
            let forearm_luma = visible_forearm_luma(&seq, t, &dataset.manifest.classes);
            let scores = FrameScores {
                dice: row(dice_per_class(p.clone(), y.clone())),
                focal: row(focal_per_class(logits, y.clone(), 0.5, 2.0)),
                iou: row(iou_per_class(p.clone(), y.clone(), 0.5)),
                intersection: sums(p.clone() * y.clone()),
                predicted: sums(p),
                truth: sums(y),
                ceiling: seq
                    .labels
                    .get(t)
                    .and_then(|l| l.part(Class::Forearm))
                    .and_then(|part| part.perfect_dice_loss),
                input_ceiling: perfect_dice_loss(&forearm_mask, w, h, s, s),
                breakdown: ForearmBreakdown::count(&truth, &predicted, w),
            };
            if let Some(f) = forearm {
                ev.frames.push(FrameRecord {
                    sequence: entry.index,
                    frame: t,
                    camera: entry.camera_class(),
                    occlusion_level: entry.occlusion_level.clone(),
                    forearm_px: scores.breakdown.found + scores.breakdown.missed_pixels,
                    forearm_dice: f64::from(scores.dice[f]),
                    forearm_dice_thresholded: scores.breakdown.dice_loss(),
                    forearm_dice_parts_right: scores.breakdown.inner_dice_loss(),
                    input_ceiling: scores.input_ceiling,
                    forearm_luma,
                });
            }
            if let Some(f) = forearm
                && keep_worst > 0
            {
                let loss = f64::from(scores.dice[f]);
                let worse_than_kept = ev.worst.len() < keep_worst
                    || ev.worst.last().is_some_and(|w| loss > w.forearm_dice);
                if worse_than_kept {
                    ev.worst.push(ScoredFrame {
                        sequence: entry.index,
                        frame: t,
                        distance_class: entry.distance_class.clone(),
                        occlusion_level: entry.occlusion_level.clone(),
                        forearm_dice: loss,
                        images: SheetImages {
                            rgb: interleave(seq.rgb_frame(t), w * h),
                            truth,
                            predicted,
                            width: w,
                            height: h,
                        },
                    });
                    ev.worst
                        .sort_by(|a, b| b.forearm_dice.total_cmp(&a.forearm_dice));
                    ev.worst.truncate(keep_worst);
                }
            }
            let (d, o) = (entry.camera_class(), entry.occlusion_level.clone());
            ev.overall.add(entry.index, &scores);
            ev.by_occlusion
                .entry(o.clone())
                .or_default()
                .add(entry.index, &scores);
            ev.by_distance
                .entry(d.clone())
                .or_default()
                .add(entry.index, &scores);
            ev.by_pair
                .entry((d, o))
                .or_default()
                .add(entry.index, &scores);
            ev.by_time
                .entry(t / TIME_SPAN * TIME_SPAN)
                .or_default()
                .add(entry.index, &scores);
            ev.by_motion
                .entry(if entry.clip.is_some() {
                    "recorded"
                } else {
                    "generator"
                })
                .or_default()
                .add(entry.index, &scores);
            if let Some(luma) = forearm_luma {
                ev.by_luma
                    .entry(LumaBand::of(luma))
                    .or_default()
                    .add(entry.index, &scores);
            }
        }
        progress(k + 1, entries.len());
    }
    Ok(ev)
}

/// Planar `[3, n]` floats in [0, 1] to interleaved bytes.
pub fn interleave(planar: &[f32], n: usize) -> Vec<u8> {
    (0..n)
        .flat_map(|p| [0, 1, 2].map(|ch| to_byte(planar[ch * n + p])))
        .collect()
}

/// Per pixel: 1 + the most probable of `c` planar class probabilities when above one half,
/// else 0.
fn argmax(probabilities: &[f32], c: usize, n: usize) -> Vec<u8> {
    (0..n)
        .map(|p| {
            (0..c)
                .map(|k| (k, probabilities.get(k * n + p).copied().unwrap_or(0.0)))
                .filter(|&(_, v)| v > 0.5)
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(0, |(k, _)| k as u8 + 1)
        })
        .collect()
}

fn fmt(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "-".into()
    }
}

impl Evaluation {
    /// The evaluation as Markdown tables.
    #[must_use]
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let o = &self.overall;
        let _ = writeln!(
            md,
            "Split `{}`: {} sequences, {} frames scored (the first frame of each sequence is not).\n",
            self.split, self.sequences, o.frames
        );
        let _ = writeln!(
            md,
            "| class | Dice loss (per frame) | batch Dice loss | IoU | focal loss |\n|---|---|---|---|---|"
        );
        if o.frames > 0 {
            for (c, name) in self.classes.iter().enumerate() {
                let _ = writeln!(
                    md,
                    "| {name} | {} | {} | {} | {} |",
                    fmt(o.dice(c)),
                    fmt(o.batch_dice(c)),
                    fmt(o.iou(c)),
                    fmt(o.focal(c))
                );
            }
            let mean = o.class_mean_dice();
            let _ = writeln!(
                md,
                "\nMean over the {} classes of the per-frame Dice loss: **{}**; on the scale of the \
                 authors' public test code (x 29/50, see experiments/perception.md): {} (the paper's \
                 Table 1: 0.1739).",
                self.classes.len(),
                fmt(mean),
                fmt(mean * AUTHORS_SCALE)
            );
        }
        if let Some(prediction) = &self.frame_prediction {
            let _ = writeln!(md, "\n{}", prediction.summary());
        }
        let Some(f) = self.classes.iter().position(|&c| c == Class::Forearm) else {
            return md;
        };
        let mut groups: Vec<(String, &Scores)> = vec![("all".into(), o)];
        let (distances, levels) = &self.order;
        // The maps iterate alphabetically, and the sorts are stable: names outside the
        // order stay alphabetical after it.
        let mut dist: Vec<_> = self.by_distance.iter().collect();
        dist.sort_by_key(|(k, _)| rank(distances, k));
        let mut occ: Vec<_> = self.by_occlusion.iter().collect();
        occ.sort_by_key(|(k, _)| rank(levels, k));
        let mut pairs: Vec<_> = self.by_pair.iter().collect();
        pairs.sort_by_key(|((d, o), _)| (rank(distances, d), rank(levels, o)));
        groups.extend(dist.iter().map(|(k, s)| {
            // A camera of the cell is named as such, the paper's classes as distances.
            let name = if k.ends_with(" camera") {
                (*k).clone()
            } else {
                format!("distance {k}")
            };
            (name, *s)
        }));
        groups.extend(occ.iter().map(|(k, s)| (format!("occlusion {k}"), *s)));
        groups.extend(
            self.by_luma
                .iter()
                .map(|(k, s)| (format!("forearm {}", k.name()), s)),
        );
        if self.by_motion.contains_key("recorded") {
            // Recorded people first, then the generator's: the gap between them.
            groups.extend(
                self.by_motion
                    .iter()
                    .rev()
                    .map(|(k, s)| (format!("{k} motion"), s)),
            );
        }
        let coarse = groups.len();
        groups.extend(pairs.iter().map(|((d, o), s)| (format!("{d} / {o}"), *s)));
        let _ = writeln!(
            md,
            "\nForearm by distance class (the paper's cameras) or camera of the cell, occlusion \
             level, and how light the visible forearm is in the frame (its mean luma: dark below \
             {}, light from {}). Two ceilings, each a perfect network's Dice loss: at the stored size against \
             the camera's image (from the labels), and at the model's input against the stored \
             labels (the truth averaged to the input grid, upsampled as the predictions are, \
             thresholded at one half):\n\n\
             | group | sequences | frames | Dice loss | batch Dice loss | IoU | focal loss | ceiling, stored | ceiling, input | class mean Dice |\n\
             |---|---|---|---|---|---|---|---|---|---|",
            LumaBand::DARK_BELOW,
            LumaBand::LIGHT_FROM
        );
        for (name, s) in &groups {
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                s.sequences.len(),
                s.frames,
                fmt(s.dice(f)),
                fmt(s.batch_dice(f)),
                fmt(s.iou(f)),
                fmt(s.focal(f)),
                fmt(s.ceiling()),
                fmt(s.input_ceiling()),
                fmt(s.class_mean_dice())
            );
        }
        let _ = writeln!(
            md,
            "\nForearm by time in the sequence (the recurrent state carried from frame 0; \
             training windows are shorter than a sequence):\n\n\
             | frames | sequences | frames scored | Dice loss | batch Dice loss | IoU | class mean Dice |\n\
             |---|---|---|---|---|---|---|"
        );
        for (start, s) in &self.by_time {
            let _ = writeln!(
                md,
                "| {}-{} | {} | {} | {} | {} | {} | {} |",
                (*start).max(1),
                start + TIME_SPAN - 1,
                s.sequences.len(),
                s.frames,
                fmt(s.dice(f)),
                fmt(s.batch_dice(f)),
                fmt(s.iou(f)),
                fmt(s.class_mean_dice())
            );
        }
        let _ = writeln!(
            md,
            "\nWhere the forearm's loss goes, on the masks as the contact sheet draws them (each \
             pixel the most probable class above one half): the per-frame Dice loss of those \
             masks; the same had every pixel that is arm in both truth and prediction been given \
             its true part (the elbow and the wrist in the right place); the frames whose forearm \
             was not found at all; and what the true forearm's pixels were predicted as (of those \
             taken for the background, the ones on the true mask's edge):\n\n\
             | group | frames | Dice loss, thresholded | with the elbow and wrist right | forearm missed (frames) | as forearm | as upper arm | as hand | as torso | as robot | as background | of which on its edge |\n\
             |---|---|---|---|---|---|---|---|---|---|---|---|"
        );
        for (name, s) in &groups[..coarse] {
            let b = &s.breakdown;
            let n = s.frames.max(1) as f64;
            let share = |c| format!("{:.1} %", 100.0 * b.truth_share(c));
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} | {} of {} | {} | {} | {} | {} | {} | {} | {:.1} % |",
                s.frames,
                fmt(b.hard_dice / n),
                fmt(b.inner_dice / n),
                b.missed,
                b.present,
                share(Class::Forearm),
                share(Class::UpperArm),
                share(Class::Hand),
                share(Class::Torso),
                share(Class::Robot),
                share(Class::Background),
                100.0 * b.background_at_edge_share(),
            );
        }
        self.worst_sequences_markdown(&mut md, f);
        md
    }

    /// The sequences of highest mean forearm Dice loss, each beside its distance class (or
    /// camera) without it: whether a group's figure is one sequence's or all of them.
    fn worst_sequences_markdown(&self, md: &mut String, forearm: usize) {
        let mut by_sequence: BTreeMap<usize, (&str, &str, usize, f64)> = BTreeMap::new();
        for r in &self.frames {
            let e =
                by_sequence
                    .entry(r.sequence)
                    .or_insert((&r.camera, &r.occlusion_level, 0, 0.0));
            e.2 += 1;
            e.3 += r.forearm_dice;
        }
        let mut worst: Vec<_> = by_sequence.into_iter().collect();
        worst.sort_by(|a, b| (b.1.3 / b.1.2 as f64).total_cmp(&(a.1.3 / a.1.2 as f64)));
        worst.truncate(WORST_SEQUENCES);
        if worst.is_empty() {
            return;
        }
        let _ = writeln!(
            md,
            "\nThe {} sequences of highest mean forearm Dice loss, and the rest of their distance \
             class (or camera) without each:\n\n\
             | sequence | distance or camera / occlusion | frames | Dice loss | its distance or camera without it |\n\
             |---|---|---|---|---|",
            worst.len()
        );
        for (sequence, (camera, occlusion, n, sum)) in worst {
            let without = self.by_distance.get(camera).map_or(f64::NAN, |s| {
                let rest = s.frames.saturating_sub(n);
                s.dice.get(forearm).map_or(f64::NAN, |total| {
                    if rest == 0 {
                        f64::NAN
                    } else {
                        (total - sum) / rest as f64
                    }
                })
            });
            let _ = writeln!(
                md,
                "| {sequence} | {camera} / {occlusion} | {n} | {} | {} |",
                fmt(sum / n as f64),
                fmt(without)
            );
        }
    }
}

/// Rows of the table of worst sequences.
const WORST_SEQUENCES: usize = 5;

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_render::dataset::test_util::one_frame_entry;

    #[test]
    fn a_channel_predicted_black_everywhere_is_reported_dead() {
        // Two pixels, planar RGB: red predicted right, green black at both pixels, blue black
        // at one.
        let frame = [0.5, 0.25, 0.5, 0.5, 0.25, 0.75];
        let mut p = FramePrediction::default();
        p.add(&[0.5, 0.25, 0.0, 0.0, 0.0, 0.5], &frame);
        assert_eq!(p.black, [0, 2, 1]);
        assert_eq!(p.pixels, 2);
        assert_eq!(p.black_share(), [0.0, 1.0, 0.5]);
        // |0 - 0.5| + |0 - 0.5| + |0 - 0.25| + |0.5 - 0.75| over 6 values.
        assert!((p.mean_abs_error() - 1.5 / 6.0).abs() < 1e-12);
        let text = p.summary();
        assert!(text.contains("green 100.0 %, blue 50.0 %"), "{text}");
        assert!(
            text.contains("The green channel predicts black everywhere"),
            "{text}"
        );
        // A second frame where blue is black too at both pixels: blue is at 75 %, still alive.
        p.add(&[0.5, 0.25, 0.0, 0.0, 0.0, 0.0], &frame);
        assert_eq!(p.black, [0, 4, 3]);
        assert!(!p.summary().contains("blue channel"));
        // Nothing black: no warning.
        let mut alive = FramePrediction::default();
        alive.add(&frame, &frame);
        assert_eq!(alive.mean_abs_error(), 0.0);
        assert!(!alive.summary().contains("never learned"));
    }

    fn frame(dice: f32, inter: f32, pred: f32, truth: f32) -> FrameScores {
        FrameScores {
            dice: vec![dice, 0.0],
            focal: vec![0.0; 2],
            iou: vec![0.0; 2],
            intersection: vec![inter, 0.0],
            predicted: vec![pred, 0.0],
            truth: vec![truth, 0.0],
            ceiling: None,
            input_ceiling: None,
            breakdown: ForearmBreakdown::default(),
        }
    }

    #[test]
    fn batch_dice_weighs_frames_by_their_pixels() {
        // A large part found perfectly (100 px) and a small one missed (4 px): per frame the
        // losses are 0 and (smoothed) 0.75, their mean 0.375; as one volume 1 - 200/204.
        let mut s = Scores::default();
        s.add(0, &frame(0.0, 100.0, 100.0, 100.0));
        s.add(1, &frame(0.75, 0.0, 0.0, 4.0));
        assert_eq!(s.dice(0), 0.375);
        assert!((s.batch_dice(0) - (1.0 - 200.0 / 204.0)).abs() < 1e-12);
        // A class absent everywhere and never predicted scores 0, not NaN.
        assert_eq!(s.batch_dice(1), 0.0);
        assert_eq!(s.class_mean_dice(), 0.1875);
        assert_eq!((s.frames, s.sequences.len()), (2, 2));
        assert!(s.ceiling().is_nan());
    }

    #[test]
    fn the_input_ceiling_is_averaged_over_the_frames_that_have_one() {
        let mut s = Scores::default();
        s.add(
            0,
            &FrameScores {
                input_ceiling: Some(0.25),
                ..frame(0.5, 0.0, 0.0, 1.0)
            },
        );
        s.add(
            0,
            &FrameScores {
                input_ceiling: Some(0.75),
                ..frame(0.5, 0.0, 0.0, 1.0)
            },
        );
        // A frame without a forearm has no ceiling and leaves the mean alone.
        s.add(1, &frame(0.0, 0.0, 0.0, 0.0));
        assert_eq!(s.input_ceiling(), 0.5);
        assert!(Scores::default().input_ceiling().is_nan());
    }

    #[test]
    fn the_worst_sequences_are_listed_beside_their_distance_without_them() {
        let record = |sequence, camera: &str, forearm_dice| FrameRecord {
            sequence,
            frame: 1,
            camera: camera.into(),
            occlusion_level: "medium".into(),
            forearm_px: 10,
            forearm_dice,
            forearm_dice_thresholded: forearm_dice,
            forearm_dice_parts_right: forearm_dice,
            input_ceiling: None,
            forearm_luma: None,
        };
        let mut ev = Evaluation {
            classes: vec![Class::Forearm],
            frames: vec![
                record(1, "short", 0.9),
                record(1, "short", 0.7),
                record(2, "short", 0.1),
                record(2, "short", 0.1),
                record(3, "medium", 0.2),
            ],
            ..Evaluation::default()
        };
        let group = |frames, dice| Scores {
            frames,
            dice: vec![dice],
            ..Scores::default()
        };
        ev.by_distance.insert("short".into(), group(4, 1.8));
        ev.by_distance.insert("medium".into(), group(1, 0.2));
        let mut md = String::new();
        ev.worst_sequences_markdown(&mut md, 0);
        let rows: Vec<&str> = md.lines().filter(|l| l.starts_with("| ")).collect();
        assert_eq!(
            rows[1..],
            [
                // Sequence 1 (mean 0.8) against the other short sequence's 0.1.
                "| 1 | short / medium | 2 | 0.8000 | 0.1000 |",
                // The only medium sequence: nothing is left without it.
                "| 3 | medium / medium | 1 | 0.2000 | - |",
                "| 2 | short / medium | 2 | 0.1000 | 0.8000 |",
            ],
            "{md}"
        );
        // No scored frame, no table.
        let mut empty = String::new();
        Evaluation::default().worst_sequences_markdown(&mut empty, 0);
        assert!(empty.is_empty());
    }

    /// Recorded people and the generator get a row each in the forearm's tables when the
    /// split has both, recorded first; a split of the generator alone gets none.
    #[test]
    fn the_tables_split_recorded_people_from_the_generator() {
        let group = |frames, dice| Scores {
            frames,
            dice: vec![dice],
            ..Scores::default()
        };
        let mut ev = Evaluation {
            classes: vec![Class::Forearm],
            overall: group(3, 0.9),
            ..Evaluation::default()
        };
        ev.by_motion.insert("generator", group(2, 0.2));
        let rows = |ev: &Evaluation| -> Vec<String> {
            ev.to_markdown()
                .lines()
                .filter(|l| l.contains(" motion |"))
                .map(|l| l.split(" | ").take(4).collect::<Vec<_>>().join(" | "))
                .collect()
        };
        assert!(rows(&ev).is_empty(), "{:?}", rows(&ev));
        ev.by_motion.insert("recorded", group(1, 0.7));
        let rows = rows(&ev);
        // The Dice table's rows (sequences, frames, Dice loss), then the same groups in the
        // table of where the loss goes.
        assert_eq!(
            rows[..2],
            [
                "| recorded motion | 0 | 1 | 0.7000",
                "| generator motion | 0 | 2 | 0.1000"
            ]
        );
        assert_eq!(rows.len(), 4, "{rows:?}");
    }

    #[test]
    fn a_frame_record_is_one_csv_row_of_the_headers_fields() {
        let mut r = FrameRecord {
            sequence: 1225,
            frame: 17,
            camera: "short".into(),
            occlusion_level: "medium".into(),
            forearm_px: 42,
            forearm_dice: 0.98,
            forearm_dice_thresholded: 1.0,
            forearm_dice_parts_right: 0.5,
            input_ceiling: Some(0.0625),
            forearm_luma: Some(0.05),
        };
        assert_eq!(
            r.csv_row(),
            "1225,17,short,medium,42,0.980000,1.000000,0.062500,0.050000,0.500000"
        );
        assert_eq!(
            r.csv_row().split(',').count(),
            FrameRecord::CSV_HEADER.split(',').count()
        );
        (r.input_ceiling, r.forearm_luma) = (None, None);
        assert!(
            r.csv_row().ends_with("1.000000,,,0.500000"),
            "{}",
            r.csv_row()
        );
        // A camera named with a comma and a quote stays one field.
        r.camera = "left, \"high\" camera".into();
        assert!(
            r.csv_row()
                .starts_with("1225,17,\"left, \"\"high\"\" camera\",medium,"),
            "{}",
            r.csv_row()
        );
    }

    #[test]
    fn the_forearm_luma_is_the_rec709_mean_of_its_pixels_only() {
        // Four pixels, planar [3, 4]: pure red, green, blue (unmasked) and white.
        let planar = [
            1.0, 0.0, 0.0, 1.0, // red plane
            0.0, 1.0, 0.0, 1.0, // green
            0.0, 0.0, 1.0, 1.0, // blue
        ];
        let luma = |mask: [u8; 4]| masked_luma(&planar, &mask);
        // The Rec. 709 weights of each primary; they sum to white's 1.
        assert!((luma([1, 0, 0, 0]).unwrap() - 0.2126).abs() < 1e-6);
        assert!((luma([0, 1, 0, 0]).unwrap() - 0.7152).abs() < 1e-6);
        assert!((luma([0, 0, 0, 1]).unwrap() - 1.0).abs() < 1e-6);
        // Red and blue together: the mean of their lumas; the rest of the image counts not.
        let red_blue = luma([1, 0, 1, 0]).unwrap();
        assert!((red_blue - (0.2126 + 0.0722) / 2.0).abs() < 1e-6);
        assert_eq!(luma([0; 4]), None);
        // An image shorter than its mask has no luma rather than a panic.
        assert_eq!(masked_luma(&planar[..6], &[1; 4]), None);
        // Blue, and red with blue, are dark; red alone mid; green and white light.
        assert_eq!(LumaBand::of(red_blue), LumaBand::Dark);
        assert_eq!(LumaBand::of(0.0722), LumaBand::Dark);
        assert_eq!(LumaBand::of(0.2126), LumaBand::Mid);
        assert_eq!(LumaBand::of(0.7152), LumaBand::Light);
        assert_eq!(LumaBand::of(LumaBand::DARK_BELOW), LumaBand::Mid);
        assert_eq!(LumaBand::of(LumaBand::LIGHT_FROM), LumaBand::Light);
    }

    #[test]
    fn the_forearm_luma_counts_only_what_the_occluder_leaves_in_view() {
        // One 2x2 frame, forearm everywhere; the occluder hides the right column, whose input
        // is black, and a grey arm of 0.8 shows in the left column.
        let classes = [Class::Background, Class::Forearm];
        let grey = 0.8f32;
        let plane = [grey, 0.0, grey, 0.0];
        let sequence = |visible: Vec<u8>| Sequence {
            entry: one_frame_entry("heavy", 0.5),
            width: 2,
            height: 2,
            rgb: plane.repeat(3),
            classes: vec![1; 4],
            visible,
            occluder: vec![0, 1, 0, 1],
            amodal_forearm: vec![1; 4],
            labels: Vec::new(),
        };
        // Rec. 709 weights sum to 1: a grey arm's luma is its grey, not half of it.
        let half_hidden = sequence(vec![1, 0, 1, 0]);
        let luma = visible_forearm_luma(&half_hidden, 0, &classes).expect("a forearm shows");
        assert!((luma - f64::from(grey)).abs() < 1e-6, "{luma}");
        // The class frame's forearm would have taken in the black: the mistake this guards.
        let with_hidden = masked_luma(half_hidden.rgb_frame(0), &[1; 4]).expect("luma");
        assert!(
            (with_hidden - f64::from(grey) / 2.0).abs() < 1e-6,
            "{with_hidden}"
        );
        // A forearm wholly hidden has no luma, whatever its class frame says.
        assert_eq!(
            visible_forearm_luma(&sequence(vec![0; 4]), 0, &classes),
            None
        );
    }

    #[test]
    fn the_forearm_breakdown_splits_its_loss_at_the_elbow_and_wrist() {
        use Class::{Background as B, Forearm as F, Hand as H, Robot as R, UpperArm as U};
        // Ten pixels. Truth: forearm on 0-5, upper arm on 6-7, background on 8-9.
        // Prediction: forearm on 0-2 and 6 (found 3, one upper-arm pixel taken for forearm),
        // hand on 3-4 (the wrist drawn too far up the arm), robot on 5, background elsewhere.
        let truth = [F, F, F, F, F, F, U, U, B, B].map(|c| c as u8);
        let predicted = [F, F, F, H, H, R, F, U, B, B].map(|c| c as u8);
        let b = ForearmBreakdown::count(&truth, &predicted, 10);
        assert_eq!(
            (
                b.found,
                b.false_found,
                b.missed_pixels,
                b.false_found_in_arm,
                b.missed_in_arm
            ),
            (3, 1, 3, 1, 2)
        );
        // 1 - (2*3 + 1) / (2*3 + 1 + 3 + 1)
        assert!((b.dice_loss() - (1.0 - 7.0 / 11.0)).abs() < 1e-12);
        // With the arm's parts right: found 5, false 0, missed 1 (the robot's pixel).
        assert!((b.inner_dice_loss() - (1.0 - 11.0 / 12.0)).abs() < 1e-12);
        assert_eq!(b.truth_as[F as usize], 3);
        assert_eq!(b.truth_as[H as usize], 2);
        assert_eq!(b.truth_as[R as usize], 1);
        assert!(b.present() && !b.missed());

        // A frame whose forearm is all taken for the hand is missed, but lost only to the
        // wrist's place; one without a forearm is neither present nor missed, and scores 0.
        let all_hand = ForearmBreakdown::count(&[F as u8; 4], &[H as u8; 4], 2);
        assert!(all_hand.missed());
        assert!((all_hand.dice_loss() - (1.0 - 1.0 / 5.0)).abs() < 1e-12);
        assert_eq!(all_hand.inner_dice_loss(), 0.0);
        let none = ForearmBreakdown::count(&[B as u8; 4], &[B as u8; 4], 2);
        assert!(!none.present() && !none.missed());
        assert_eq!(none.dice_loss(), 0.0);

        let mut sums = BreakdownSums::default();
        sums.add(&b);
        sums.add(&all_hand);
        sums.add(&none);
        assert_eq!((sums.present, sums.missed), (2, 1));
        // Ten true forearm pixels: 3 found, 6 taken for the hand, 1 for the robot.
        assert!((sums.truth_share(H) - 0.6).abs() < 1e-12);
        assert!(BreakdownSums::default().truth_share(F).is_nan());
    }

    #[test]
    fn a_thinner_mask_loses_the_forearms_edge_a_hole_its_inside() {
        use Class::{Background as B, Forearm as F};
        // A 3x3 forearm in a 5x5 frame. Drawn one column wide (the middle), it loses its two
        // side columns: six pixels, all on the edge of the true mask.
        let mut truth = [B as u8; 25];
        for y in 1..4 {
            for x in 1..4 {
                truth[y * 5 + x] = F as u8;
            }
        }
        let mut thin = [B as u8; 25];
        for y in 1..4 {
            thin[y * 5 + 2] = F as u8;
        }
        let b = ForearmBreakdown::count(&truth, &thin, 5);
        assert_eq!((b.truth_as[B as usize], b.background_at_edge), (6, 6));
        // Drawn whole but for its centre: one pixel lost, inside the mask.
        let mut holed = truth;
        holed[2 * 5 + 2] = B as u8;
        let b = ForearmBreakdown::count(&truth, &holed, 5);
        assert_eq!((b.truth_as[B as usize], b.background_at_edge), (1, 0));
        // The frame's border is not an edge: a forearm filling the frame, all missed, has
        // none (the mask goes on beyond the crop).
        let b = ForearmBreakdown::count(&[F as u8; 9], &[B as u8; 9], 3);
        assert_eq!((b.truth_as[B as usize], b.background_at_edge), (9, 0));
        let mut sums = BreakdownSums::default();
        sums.add(&ForearmBreakdown::count(&truth, &thin, 5));
        assert!((sums.background_at_edge_share() - 6.0 / 9.0).abs() < 1e-12);
    }

    #[test]
    fn argmax_keeps_the_most_probable_class_above_one_half() {
        // Two pixels, two classes (planar): pixel 0 -> class 2, pixel 1 -> background.
        let p = [0.6, 0.2, 0.9, 0.4];
        assert_eq!(argmax(&p, 2, 2), vec![2, 0]);
    }
}
