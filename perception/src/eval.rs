//! Segmentation evaluation on a dataset split: Dice loss, focal loss and IoU per class,
//! broken down by occlusion level and distance class.
//!
//! Predictions are made at the model's resolution and their logits upsampled (bilinear) to
//! the dataset's, so that every model is scored against the same full-resolution labels.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use workcell_render::Class;

use burn::tensor::activation::sigmoid;
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{Device, Tensor, TensorData};
use workcell_render::dataset::{Dataset, Split};

use crate::config::ProcNetConfig;
use crate::data::{class_map, model_frames, one_hot};
use crate::error::Result;
use crate::loss::{dice_per_class, focal_per_class, iou_per_class};
use crate::model::ProcNetModel;

/// Sums of per-frame scores of one group of frames.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scores {
    pub frames: usize,
    /// Per class: sums over frames.
    pub dice: Vec<f64>,
    pub focal: Vec<f64>,
    pub iou: Vec<f64>,
}

impl Scores {
    fn add(&mut self, dice: &[f32], focal: &[f32], iou: &[f32]) {
        if self.dice.is_empty() {
            self.dice = vec![0.0; dice.len()];
            self.focal = vec![0.0; dice.len()];
            self.iou = vec![0.0; dice.len()];
        }
        for c in 0..dice.len() {
            self.dice[c] += f64::from(dice[c]);
            self.focal[c] += f64::from(focal[c]);
            self.iou[c] += f64::from(iou[c]);
        }
        self.frames += 1;
    }

    /// Mean Dice loss of class `c`.
    #[must_use]
    pub fn dice(&self, c: usize) -> f64 {
        self.dice
            .get(c)
            .map_or(f64::NAN, |v| v / self.frames.max(1) as f64)
    }
    #[must_use]
    pub fn focal(&self, c: usize) -> f64 {
        self.focal
            .get(c)
            .map_or(f64::NAN, |v| v / self.frames.max(1) as f64)
    }
    #[must_use]
    pub fn iou(&self, c: usize) -> f64 {
        self.iou
            .get(c)
            .map_or(f64::NAN, |v| v / self.frames.max(1) as f64)
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
    /// Keyed by distance class.
    pub by_distance: BTreeMap<String, Scores>,
    /// Keyed by (distance class, occlusion level).
    pub by_pair: BTreeMap<(String, String), Scores>,
}

/// Order of the dataset's distance classes and occlusion levels in tables (others last).
fn rank(order: &[&str], name: &str) -> usize {
    order.iter().position(|n| *n == name).unwrap_or(order.len())
}
const DISTANCES: [&str; 3] = ["short", "medium", "large"];
const LEVELS: [&str; 3] = ["light", "medium", "heavy"];

/// Evaluates `model` on a split. Frame 0 of each sequence (weight 0 in training) is left out.
/// `progress` is called after each sequence with (done, total).
pub fn evaluate(
    model: &ProcNetModel,
    config: &ProcNetConfig,
    dataset: &Dataset,
    split: Split,
    device: &Device,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Evaluation> {
    let map = class_map(config, dataset)?;
    let entries: Vec<_> = dataset.entries(Some(split)).cloned().collect();
    if entries.is_empty() {
        return Err(crate::error::PerceptionError::Input {
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
        ..Evaluation::default()
    };
    let c = map.len();
    for (k, entry) in entries.iter().enumerate() {
        let seq = dataset.load(entry)?;
        let frames = model_frames(&seq, config)?;
        let (w, h) = (seq.width as usize, seq.height as usize);
        let s = config.input_size;
        let mut state = model.initial_state(1, s, s, device);
        for t in 0..seq.len() {
            let x = Tensor::<4>::from_data(
                TensorData::new(frames[t * 3 * s * s..][..3 * s * s].to_vec(), [1, 3, s, s]),
                device,
            );
            let (out, next) = model.step(x, state);
            state = next;
            if t == 0 {
                continue;
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
            let read = |t: Tensor<2>| t.into_data().try_into_vec::<f32>().unwrap_or_default();
            let dice = read(dice_per_class(p.clone(), y.clone()));
            let focal = read(focal_per_class(logits, y.clone(), 0.5, 2.0));
            let iou = read(iou_per_class(p, y, 0.5));
            ev.overall.add(&dice, &focal, &iou);
            let (d, o) = (entry.distance_class.clone(), entry.occlusion_level.clone());
            ev.by_occlusion
                .entry(o.clone())
                .or_default()
                .add(&dice, &focal, &iou);
            ev.by_distance
                .entry(d.clone())
                .or_default()
                .add(&dice, &focal, &iou);
            ev.by_pair
                .entry((d, o))
                .or_default()
                .add(&dice, &focal, &iou);
        }
        progress(k + 1, entries.len());
    }
    Ok(ev)
}

impl Evaluation {
    /// The evaluation as Markdown tables.
    #[must_use]
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let frames = self.overall.frames;
        let _ = writeln!(
            md,
            "Split `{}`: {} sequences, {frames} frames scored (the first frame of each sequence is not).\n",
            self.split, self.sequences
        );
        let _ = writeln!(
            md,
            "| class | Dice loss | focal loss | IoU |\n|---|---|---|---|"
        );
        for (c, name) in self.classes.iter().enumerate() {
            if self.overall.frames == 0 {
                break;
            }
            let _ = writeln!(
                md,
                "| {name} | {:.4} | {:.4} | {:.4} |",
                self.overall.dice(c),
                self.overall.focal(c),
                self.overall.iou(c)
            );
        }
        let Some(f) = self.classes.iter().position(|&c| c == Class::Forearm) else {
            return md;
        };
        let mut groups: Vec<(String, &Scores)> = Vec::new();
        let mut occ: Vec<_> = self.by_occlusion.iter().collect();
        occ.sort_by_key(|(k, _)| rank(&LEVELS, k));
        let mut dist: Vec<_> = self.by_distance.iter().collect();
        dist.sort_by_key(|(k, _)| rank(&DISTANCES, k));
        groups.extend(dist.iter().map(|(k, s)| (format!("distance {k}"), *s)));
        groups.extend(occ.iter().map(|(k, s)| (format!("occlusion {k}"), *s)));
        let mut pairs: Vec<_> = self.by_pair.iter().collect();
        pairs.sort_by_key(|((d, o), _)| (rank(&DISTANCES, d), rank(&LEVELS, o)));
        groups.extend(pairs.iter().map(|((d, o), s)| (format!("{d} / {o}"), *s)));
        let _ = writeln!(
            md,
            "\nForearm by distance class and occlusion level:\n\n| frames | group | Dice loss | focal loss | IoU |\n|---|---|---|---|---|"
        );
        let _ = writeln!(
            md,
            "| {} | all | {:.4} | {:.4} | {:.4} |",
            self.overall.frames,
            self.overall.dice(f),
            self.overall.focal(f),
            self.overall.iou(f)
        );
        for (name, s) in groups {
            let _ = writeln!(
                md,
                "| {} | {name} | {:.4} | {:.4} | {:.4} |",
                s.frames,
                s.dice(f),
                s.focal(f),
                s.iou(f)
            );
        }
        md
    }
}
