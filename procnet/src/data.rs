//! Dataset sequences as network inputs and targets at the model's resolution, and the
//! sequence-consistent augmentation of training.

use std::borrow::Cow;

use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use workcell_render::dataset::{Dataset, Sequence, SequenceEntry, Split};

use crate::config::ProcNetConfig;
use crate::error::{ProcNetError, Result};
use crate::image::resample;

/// One sequence at the model's resolution, stored as bytes (a training split of 30,000
/// frames at 128x128 is 4 GB so, 16 GB as floats).
#[derive(Debug, Clone)]
pub struct SequenceTensors {
    pub entry: SequenceEntry,
    /// Side of the square frames.
    pub size: usize,
    pub frames: usize,
    /// Planes per frame: 3 (RGB), or 4 with the depth plane ([`ProcNetConfig::input_planes`]).
    pub channels: usize,
    /// `[frames, channels, size, size]`, 0..=255 for [0, 1].
    pub rgb: Vec<u8>,
    /// `[frames, classes, size, size]`: the area of each pixel covered by each class (0..=255
    /// for [0, 1]), with the occluder taken away (the network is asked for the whole part,
    /// hidden or not).
    pub target: Vec<u8>,
}

/// [0, 1] to a byte, rounded.
pub(crate) fn to_byte(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
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
                .ok_or_else(|| ProcNetError::Config {
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
        return Err(ProcNetError::Input {
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

/// The depth images of a sequence's frames (`[frames, height, width]`, m) when `config`'s
/// network reads depth ([`ProcNetConfig::reads_depth`]), else `None` (nothing is read).
///
/// # Errors
/// A dataset without depth images (format 1), a missing or corrupt one.
pub fn depth_frames(
    dataset: &Dataset,
    sequence: &Sequence,
    config: &ProcNetConfig,
) -> Result<Option<Vec<f32>>> {
    if !config.reads_depth() {
        return Ok(None);
    }
    let mut depth = Vec::with_capacity(sequence.len() * sequence.pixels());
    for t in 0..sequence.len() {
        depth.extend(dataset.depth(&sequence.entry, t)?);
    }
    Ok(Some(depth))
}

/// One frame as the network reads it at the sequence's size: `[3, height, width]` RGB, and
/// for a network that reads depth the depth plane of `depth_m` (that frame's depth image,
/// [`crate::image::depth_plane`]) after it.
///
/// # Errors
/// [`ProcNetError::Input`] when the network reads depth and there is none, or it is not
/// the frame's size.
pub fn input_frame<'a>(
    rgb: &'a [f32],
    depth_m: Option<&[f32]>,
    width: usize,
    height: usize,
    config: &ProcNetConfig,
) -> Result<Cow<'a, [f32]>> {
    let n = width * height;
    let colour = rgb.get(..3 * n).ok_or_else(|| ProcNetError::Input {
        message: format!(
            "a planar RGB frame of {} values, not 3 x {width} x {height}",
            rgb.len()
        ),
    })?;
    // An RGB network reads the frame as it is: no copy on the tracker's per-frame path.
    if !config.reads_depth() {
        return Ok(Cow::Borrowed(colour));
    }
    let depth = depth_m.ok_or_else(|| ProcNetError::Input {
        message: "this network reads depth (input_channels[0] = 4): give it the depth image".into(),
    })?;
    if depth.len() != n {
        return Err(ProcNetError::Input {
            message: format!(
                "a depth image of {} values, not the frame's {width} x {height}",
                depth.len()
            ),
        });
    }
    let mut planes = colour.to_vec();
    planes.extend(crate::image::depth_plane(depth, width, height));
    Ok(Cow::Owned(planes))
}

/// The frames of a sequence at the model's resolution, `[frames, planes, size, size]`:
/// [`input_frame`] of each, resampled. `depth` is [`depth_frames`]'s.
///
/// # Errors
/// As [`scale_factor`] and [`input_frame`].
pub fn model_frames(
    sequence: &Sequence,
    depth: Option<&[f32]>,
    config: &ProcNetConfig,
) -> Result<Vec<f32>> {
    let f = scale_factor(config, sequence.width, sequence.height)?;
    let (w, h) = (sequence.width as usize, sequence.height as usize);
    let planes = config.input_planes();
    let mut out = Vec::with_capacity(sequence.len() * planes * (w / f) * (h / f));
    for t in 0..sequence.len() {
        let d = depth.and_then(|d| d.get(t * w * h..(t + 1) * w * h));
        let frame = input_frame(sequence.rgb_frame(t), d, w, h, config)?;
        out.extend(resample(&frame, planes, w, h, w / f, h / f));
    }
    Ok(out)
}

impl SequenceTensors {
    /// Converts a loaded sequence to the model's resolution; `depth` is [`depth_frames`]'s.
    pub fn new(
        sequence: &Sequence,
        depth: Option<&[f32]>,
        config: &ProcNetConfig,
        map: &[u8],
    ) -> Result<Self> {
        let f = scale_factor(config, sequence.width, sequence.height)?;
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let frames = sequence.len();
        let rgb = model_frames(sequence, depth, config)?
            .into_iter()
            .map(to_byte)
            .collect();
        let mut target = Vec::with_capacity(frames * map.len() * (w / f) * (h / f));
        for t in 0..frames {
            let planes = one_hot(sequence.class_frame(t), map);
            target.extend(
                resample(&planes, map.len(), w, h, w / f, h / f)
                    .into_iter()
                    .map(to_byte),
            );
        }
        Ok(Self {
            entry: sequence.entry.clone(),
            size: w / f,
            frames,
            channels: config.input_planes(),
            rgb,
            target,
        })
    }
}

/// Loads every sequence of a split at the model's resolution (with its depth images when
/// the network reads depth).
pub fn load_split(
    dataset: &Dataset,
    split: Split,
    config: &ProcNetConfig,
) -> Result<Vec<SequenceTensors>> {
    let map = class_map(config, dataset)?;
    dataset
        .sequences(Some(split))
        .map(|s| {
            let s = s?;
            let depth = depth_frames(dataset, &s, config)?;
            SequenceTensors::new(&s, depth.as_deref(), config, &map)
        })
        .collect()
}

/// Augmentation drawn once per sequence and applied to all its frames alike.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Augment {
    pub flip: bool,
    /// Shift in pixels (x, y); pixels shifted in repeat the edge.
    pub shift: (i32, i32),
    /// A random crop: the side of the square read, as a fraction of the frame's (1: the whole
    /// frame), resampled (bilinear) to the frame's size.
    pub crop: f32,
    /// Where the crop lies in the frame: 0 at the left (top) edge, 1 at the right (bottom).
    pub crop_at: (f32, f32),
    pub brightness: f32,
    pub contrast: f32,
    pub saturation: f32,
}

impl Augment {
    pub const NONE: Augment = Augment {
        flip: false,
        shift: (0, 0),
        crop: 1.0,
        crop_at: (0.5, 0.5),
        brightness: 0.0,
        contrast: 1.0,
        saturation: 1.0,
    };

    /// Draws a flip, a shift of up to `max_shift` px, a crop of side `min_crop..=1` of the
    /// frame's and a colour jitter of up to `jitter` (brightness offset, contrast and
    /// saturation factors 1 +- jitter).
    pub fn draw(rng: &mut impl Rng, max_shift: i32, min_crop: f32, jitter: f32) -> Self {
        let j = jitter.abs();
        let min_crop = min_crop.clamp(0.05, 1.0);
        Self {
            flip: rng.random_bool(0.5),
            shift: (
                rng.random_range(-max_shift..=max_shift),
                rng.random_range(-max_shift..=max_shift),
            ),
            crop: if min_crop < 1.0 {
                rng.random_range(min_crop..=1.0)
            } else {
                1.0
            },
            crop_at: (rng.random_range(0.0..=1.0), rng.random_range(0.0..=1.0)),
            brightness: rng.random_range(-j..=j),
            contrast: 1.0 + rng.random_range(-j..=j),
            saturation: 1.0 + rng.random_range(-j..=j),
        }
    }

    /// Applies the geometric part to `[planes, s, s]` in place.
    fn geometry(&self, planes: &mut [f32], count: usize, s: usize) {
        if self.crop < 1.0 {
            return self.crop_geometry(planes, count, s);
        }
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

    /// The geometric part with a crop: output pixel centre `x` (after the flip) reads the
    /// frame at `x0 + (x + 1/2) crop - 1/2 - shift`, bilinear, edges repeated.
    fn crop_geometry(&self, planes: &mut [f32], count: usize, s: usize) {
        let src = planes.to_vec();
        let side = s as f32;
        let origin = |at: f32| at.clamp(0.0, 1.0) * side * (1.0 - self.crop);
        let (ox, oy) = (origin(self.crop_at.0), origin(self.crop_at.1));
        // Per output coordinate: the two source indices and the weight of the second.
        let taps = |o: f32, shift: i32, flip: bool| -> Vec<(usize, usize, f32)> {
            (0..s)
                .map(|x| {
                    let xs = if flip { s - 1 - x } else { x };
                    let u = (o + (xs as f32 + 0.5) * self.crop - 0.5 - shift as f32)
                        .clamp(0.0, side - 1.0);
                    let i = u.floor() as usize;
                    (i, (i + 1).min(s - 1), u - i as f32)
                })
                .collect()
        };
        let xt = taps(ox, self.shift.0, self.flip);
        let yt = taps(oy, self.shift.1, false);
        for p in 0..count {
            let plane = &src[p * s * s..][..s * s];
            for (y, &(y0, y1, wy)) in yt.iter().enumerate() {
                for (x, &(x0, x1, wx)) in xt.iter().enumerate() {
                    let top = plane[y0 * s + x0] * (1.0 - wx) + plane[y0 * s + x1] * wx;
                    let bottom = plane[y1 * s + x0] * (1.0 - wx) + plane[y1 * s + x1] * wx;
                    planes[(p * s + y) * s + x] = top * (1.0 - wy) + bottom * wy;
                }
            }
        }
    }

    /// Applies the colour jitter to the first three planes (RGB) of `[3.., s, s]` in place.
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
    /// Per frame `[b, planes, s, s]`: RGB, and the depth plane for a network that reads it.
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
    let planes = sequences.first().map_or(3, |(q, _, _)| q.channels);
    let (rgb_len, target_len) = (planes * s * s, classes * s * s);
    let mut rgb = Vec::with_capacity(window);
    let mut target = Vec::with_capacity(window);
    for t in 0..window {
        let mut x = Vec::with_capacity(b * rgb_len);
        let mut y = Vec::with_capacity(b * target_len);
        for (seq, start, aug) in sequences {
            let frame = start + t;
            let floats = |bytes: &[u8]| -> Vec<f32> {
                bytes.iter().map(|&v| f32::from(v) / 255.0).collect()
            };
            let mut px = floats(&seq.rgb[frame * rgb_len..][..rgb_len]);
            aug.colour(&mut px, s);
            aug.geometry(&mut px, planes, s);
            let mut lab = floats(&seq.target[frame * target_len..][..target_len]);
            aug.geometry(&mut lab, classes, s);
            x.extend(px);
            y.extend(lab);
        }
        rgb.push(Tensor::from_data(
            TensorData::new(x, [b, planes, s, s]),
            device,
        ));
        target.push(Tensor::from_data(
            TensorData::new(y, [b, classes, s, s]),
            device,
        ));
    }
    Batch { rgb, target }
}

/// Up to `count` sequences taken in turn from each (camera class, occlusion level) cell, the
/// first of each cell in the dataset's order first, so that every cell is represented; all of
/// them when `count` is 0 or not smaller than their number. The order within the result is
/// that of the round-robin.
pub fn per_cell_subset<T>(
    all: Vec<T>,
    count: usize,
    entry: impl Fn(&T) -> &SequenceEntry,
) -> Vec<T> {
    if count == 0 || all.len() <= count {
        return all;
    }
    let mut cells: std::collections::BTreeMap<(String, String), Vec<T>> =
        std::collections::BTreeMap::new();
    for s in all.into_iter().rev() {
        let e = entry(&s);
        let key = (e.camera_class(), e.occlusion_level.clone());
        cells.entry(key).or_default().push(s);
    }
    let mut out = Vec::with_capacity(count);
    while out.len() < count {
        for queue in cells.values_mut() {
            if out.len() < count
                && let Some(s) = queue.pop()
            {
                out.push(s);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A network that reads RGB takes the frame as it is (a depth image changes nothing); one
    /// that reads depth gets the depth plane after it, and refuses a frame without depth or
    /// with a depth image of another size.
    #[test]
    fn the_input_frame_has_the_planes_the_network_reads() {
        let rgb: Vec<f32> = (0..12).map(|v| v as f32 / 12.0).collect();
        let depth = [3.0, 3.5, 4.0, 0.0];
        let mut config = ProcNetConfig::cpu();
        assert!(!config.reads_depth());
        assert_eq!(*input_frame(&rgb, None, 2, 2, &config).unwrap(), rgb[..]);
        assert_eq!(
            *input_frame(&rgb, Some(&depth), 2, 2, &config).unwrap(),
            rgb[..]
        );
        config.input_channels[0] = 4;
        assert!(config.reads_depth() && config.input_planes() == 4);
        let with_depth = input_frame(&rgb, Some(&depth), 2, 2, &config).unwrap();
        assert_eq!(with_depth[..12], rgb[..]);
        assert_eq!(
            with_depth[12..],
            crate::image::depth_plane(&depth, 2, 2)[..]
        );
        for (d, what) in [
            (None, "give it the depth image"),
            (Some(&depth[..3]), "3 values"),
        ] {
            let e = input_frame(&rgb, d, 2, 2, &config).unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
        }
        assert!(input_frame(&rgb[..11], Some(&depth), 2, 2, &config).is_err());
    }

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

    #[test]
    fn a_crop_magnifies_a_linear_ramp_exactly() {
        // Bilinear resampling reproduces a linear function: a half-side crop of the ramp
        // f(x, y) = x at the left edge reads f at 0.25, 0.75, ... (clamped to the first pixel).
        let s = 8;
        let ramp: Vec<f32> = (0..s * s).map(|i| (i % s) as f32).collect();
        let crop = Augment {
            crop: 0.5,
            crop_at: (0.0, 0.0),
            ..Augment::NONE
        };
        let mut out = ramp.clone();
        crop.geometry(&mut out, 1, s);
        let row: Vec<f32> = (0..s)
            .map(|x| ((x as f32 + 0.5) * 0.5 - 0.5).max(0.0))
            .collect();
        for y in 0..s {
            assert_eq!(&out[y * s..][..s], &row[..], "row {y}");
        }
        // At the far corner it ends on the last pixel; flipped, the row is mirrored.
        let far = Augment {
            crop_at: (1.0, 1.0),
            flip: true,
            ..crop
        };
        let mut out = ramp.clone();
        far.geometry(&mut out, 1, s);
        let expect: Vec<f32> = (0..s)
            .rev()
            .map(|x| (4.0 + (x as f32 + 0.5) * 0.5 - 0.5).min(7.0))
            .collect();
        for (got, want) in out[..s].iter().zip(&expect) {
            assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        }
        // A whole-frame crop is the identity.
        let whole = Augment { crop: 1.0, ..crop };
        let mut out = ramp.clone();
        whole.geometry(&mut out, 1, s);
        assert_eq!(out, ramp);
    }
}
