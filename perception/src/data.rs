//! Dataset sequences as network inputs and targets at the model's resolution, and the
//! sequence-consistent augmentation of training.

use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use workcell_render::dataset::{Dataset, Sequence, SequenceEntry, Split};

use crate::config::ProcNetConfig;
use crate::error::{PerceptionError, Result};
use crate::image::resample;

/// One sequence at the model's resolution.
#[derive(Debug, Clone)]
pub struct SequenceTensors {
    pub entry: SequenceEntry,
    /// Side of the square frames.
    pub size: usize,
    pub frames: usize,
    /// `[frames, 3, size, size]` in [0, 1].
    pub rgb: Vec<f32>,
    /// `[frames, classes, size, size]`: the area of each pixel covered by each class, with the
    /// occluder taken away (the network is asked for the whole part, hidden or not).
    pub target: Vec<f32>,
}

/// How the configuration's classes map to the dataset's class indices.
pub fn class_map(config: &ProcNetConfig, dataset: &Dataset) -> Result<Vec<u8>> {
    config
        .classes
        .iter()
        .map(|class| {
            dataset
                .manifest
                .classes
                .iter()
                .position(|c| c == class)
                .and_then(|i| u8::try_from(i).ok())
                .ok_or_else(|| PerceptionError::Config {
                    key: "classes".into(),
                    message: format!(
                        "class {class} is not in the dataset (it has {:?})",
                        dataset.manifest.classes
                    ),
                })
        })
        .collect()
}

/// The integer factor from the dataset's frames down to the model's input.
pub fn scale_factor(config: &ProcNetConfig, width: u32, height: u32) -> Result<usize> {
    let size = config.input_size;
    let (w, h) = (width as usize, height as usize);
    if w != h || w < size || w % size != 0 {
        return Err(PerceptionError::Input {
            message: format!(
                "{w}x{h} frames do not reduce to the model's {size}x{size} input by an integer \
                 factor; generate the dataset at a multiple of {size}"
            ),
        });
    }
    Ok(w / size)
}

/// One-hot planes `[classes, h, w]` of a class image, for the classes of `map`.
#[must_use]
pub fn one_hot(classes: &[u8], map: &[u8]) -> Vec<f32> {
    let mut out = vec![0f32; map.len() * classes.len()];
    for (c, &index) in map.iter().enumerate() {
        let plane = &mut out[c * classes.len()..][..classes.len()];
        plane
            .iter_mut()
            .zip(classes)
            .for_each(|(o, &k)| *o = f32::from(u8::from(k == index)));
    }
    out
}

/// The frames of a sequence at the model's resolution, `[frames, 3, size, size]`.
pub fn model_frames(sequence: &Sequence, config: &ProcNetConfig) -> Result<Vec<f32>> {
    let f = scale_factor(config, sequence.width, sequence.height)?;
    let (w, h) = (sequence.width as usize, sequence.height as usize);
    Ok((0..sequence.len())
        .flat_map(|t| resample(sequence.rgb_frame(t), 3, w, h, w / f, h / f))
        .collect())
}

impl SequenceTensors {
    /// Converts a loaded sequence to the model's resolution.
    pub fn new(sequence: &Sequence, config: &ProcNetConfig, map: &[u8]) -> Result<Self> {
        let f = scale_factor(config, sequence.width, sequence.height)?;
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let frames = sequence.len();
        let rgb = model_frames(sequence, config)?;
        let mut target = Vec::with_capacity(frames * map.len() * (w / f) * (h / f));
        for t in 0..frames {
            let planes = one_hot(sequence.class_frame(t), map);
            target.extend(resample(&planes, map.len(), w, h, w / f, h / f));
        }
        Ok(Self {
            entry: sequence.entry.clone(),
            size: w / f,
            frames,
            rgb,
            target,
        })
    }
}

/// Loads every sequence of a split at the model's resolution.
pub fn load_split(
    dataset: &Dataset,
    split: Split,
    config: &ProcNetConfig,
) -> Result<Vec<SequenceTensors>> {
    let map = class_map(config, dataset)?;
    dataset
        .sequences(Some(split))
        .map(|s| SequenceTensors::new(&s?, config, &map))
        .collect()
}

/// Augmentation drawn once per sequence and applied to all its frames alike.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Augment {
    pub flip: bool,
    /// Shift in pixels (x, y); pixels shifted in repeat the edge.
    pub shift: (i32, i32),
    pub brightness: f32,
    pub contrast: f32,
    pub saturation: f32,
}

impl Augment {
    pub const NONE: Augment = Augment {
        flip: false,
        shift: (0, 0),
        brightness: 0.0,
        contrast: 1.0,
        saturation: 1.0,
    };

    /// Draws a flip, a shift of up to `max_shift` px and a colour jitter of up to `jitter`
    /// (brightness offset, contrast and saturation factors 1 +- jitter).
    pub fn draw(rng: &mut impl Rng, max_shift: i32, jitter: f32) -> Self {
        let j = jitter.abs();
        Self {
            flip: rng.random_bool(0.5),
            shift: (
                rng.random_range(-max_shift..=max_shift),
                rng.random_range(-max_shift..=max_shift),
            ),
            brightness: rng.random_range(-j..=j),
            contrast: 1.0 + rng.random_range(-j..=j),
            saturation: 1.0 + rng.random_range(-j..=j),
        }
    }

    /// Applies the geometric part to `[planes, s, s]` in place.
    fn geometry(&self, planes: &mut [f32], count: usize, s: usize) {
        if !self.flip && self.shift == (0, 0) {
            return;
        }
        let src = planes.to_vec();
        let clamp = |v: i32| v.clamp(0, s as i32 - 1) as usize;
        for p in 0..count {
            for y in 0..s {
                let sy = clamp(y as i32 - self.shift.1);
                for x in 0..s {
                    let xs = if self.flip { s - 1 - x } else { x };
                    let sx = clamp(xs as i32 - self.shift.0);
                    planes[(p * s + y) * s + x] = src[(p * s + sy) * s + sx];
                }
            }
        }
    }

    /// Applies the colour jitter to `[3, s, s]` in place.
    fn colour(&self, rgb: &mut [f32], s: usize) {
        if *self == Augment::NONE {
            return;
        }
        let n = s * s;
        for i in 0..n {
            let px = [rgb[i], rgb[n + i], rgb[2 * n + i]];
            let gray = 0.299 * px[0] + 0.587 * px[1] + 0.114 * px[2];
            for (c, v) in px.into_iter().enumerate() {
                let v = gray + (v - gray) * self.saturation;
                let v = (v - 0.5) * self.contrast + 0.5 + self.brightness;
                rgb[c * n + i] = v.clamp(0.0, 1.0);
            }
        }
    }
}

/// A batch of windows: `[time][batch, ...]` tensors.
#[derive(Debug, Clone)]
pub struct Batch {
    /// Per frame `[b, 3, s, s]`.
    pub rgb: Vec<Tensor<4>>,
    /// Per frame `[b, classes, s, s]`.
    pub target: Vec<Tensor<4>>,
}

/// Stacks `window` frames from `start` of each sequence, augmented, into per-frame tensors.
pub fn make_batch(
    sequences: &[(&SequenceTensors, usize, Augment)],
    window: usize,
    classes: usize,
    device: &Device,
) -> Batch {
    let b = sequences.len();
    let s = sequences.first().map_or(0, |(q, _, _)| q.size);
    let (rgb_len, target_len) = (3 * s * s, classes * s * s);
    let mut rgb = Vec::with_capacity(window);
    let mut target = Vec::with_capacity(window);
    for t in 0..window {
        let mut x = Vec::with_capacity(b * rgb_len);
        let mut y = Vec::with_capacity(b * target_len);
        for (seq, start, aug) in sequences {
            let frame = start + t;
            let mut px = seq.rgb[frame * rgb_len..][..rgb_len].to_vec();
            aug.colour(&mut px, s);
            aug.geometry(&mut px, 3, s);
            let mut lab = seq.target[frame * target_len..][..target_len].to_vec();
            aug.geometry(&mut lab, classes, s);
            x.extend(px);
            y.extend(lab);
        }
        rgb.push(Tensor::from_data(TensorData::new(x, [b, 3, s, s]), device));
        target.push(Tensor::from_data(
            TensorData::new(y, [b, classes, s, s]),
            device,
        ));
    }
    Batch { rgb, target }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flip_twice_is_identity_and_shift_repeats_edges() {
        let s = 4;
        let src: Vec<f32> = (0..16).map(|v| v as f32).collect();
        let flip = Augment {
            flip: true,
            ..Augment::NONE
        };
        let mut once = src.clone();
        flip.geometry(&mut once, 1, s);
        assert_eq!(&once[..4], &[3.0, 2.0, 1.0, 0.0]);
        let mut twice = once.clone();
        flip.geometry(&mut twice, 1, s);
        assert_eq!(twice, src);
        let shift = Augment {
            shift: (1, 0),
            ..Augment::NONE
        };
        let mut moved = src.clone();
        shift.geometry(&mut moved, 1, s);
        assert_eq!(&moved[..4], &[0.0, 0.0, 1.0, 2.0]);
    }
}
