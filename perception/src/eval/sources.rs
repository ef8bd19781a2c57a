//! Where the forearm masks of a pose evaluation come from.

use std::borrow::Cow;

use workcell_render::Class;
use workcell_render::dataset::{Dataset, Sequence};

use crate::error::{PerceptionError, Result};
use crate::pose::ArmMasks;
use workcell_procnet::ProcNet;
use workcell_procnet::config::DATASET_CLASSES;
use workcell_procnet::data::one_hot;
use workcell_procnet::image::resample;

/// Where the forearm masks come from.
pub trait MaskSource {
    /// The name in tables ("ground truth", "ProcNet").
    fn name(&self) -> String;
    /// A new sequence starts (a stateful network forgets the last one).
    fn start(&mut self);
    /// The forearm mask of frame `t`, `[height, width]` of the sequence, values in [0, 1].
    ///
    /// # Errors
    /// The network's failure.
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>>;
    /// Every arm part's mask of frame `t` (for the articulated fit).
    ///
    /// # Errors
    /// The network's failure.
    fn arm(&mut self, sequence: &Sequence, t: usize) -> Result<ArmMasks>;
}

/// The dataset's forearm class without the artificial occluder: what ProcNet is trained to
/// output. Isolates the pose estimator's own error.
#[derive(Debug, Clone, Copy, Default)]
pub struct GroundTruthMasks;

impl MaskSource for GroundTruthMasks {
    fn name(&self) -> String {
        "ground truth".into()
    }
    fn start(&mut self) {}
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>> {
        Ok(forearm_of(sequence.class_frame(t)))
    }
    fn arm(&mut self, sequence: &Sequence, t: usize) -> Result<ArmMasks> {
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        ArmMasks::from_classes(sequence.class_frame(t), w, h)
    }
}

/// The dataset's classes as a perfect network reading `size x size` frames would give them:
/// each class's plane averaged down to the network's input (as the training targets are)
/// and resampled back to the frame, as [`NetworkMasks`] resamples a network's output. What
/// bounds every network of this input size.
#[derive(Debug, Clone, Copy)]
pub struct GroundTruthAtSize {
    pub size: usize,
}

impl GroundTruthAtSize {
    /// Every class's plane at the network's resolution and back, `[classes, height, width]`.
    fn planes(&self, sequence: &Sequence, t: usize) -> Result<Vec<Vec<f32>>> {
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let s = self.size;
        if s == 0 || s > w.min(h) {
            return Err(PerceptionError::Input {
                message: format!("a network input of {s}x{s} for {w}x{h} frames"),
            });
        }
        let ids = DATASET_CLASSES.map(|c| c as u8);
        let small = resample(
            &one_hot(sequence.class_frame(t), &ids),
            ids.len(),
            w,
            h,
            s,
            s,
        );
        Ok(small
            .chunks_exact(s * s)
            .map(|plane| resample(plane, 1, s, s, w, h))
            .collect())
    }
}

impl MaskSource for GroundTruthAtSize {
    fn name(&self) -> String {
        format!("ground truth at {0}x{0}", self.size)
    }
    fn start(&mut self) {}
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>> {
        let i = DATASET_CLASSES
            .iter()
            .position(|&c| c == Class::Forearm)
            .unwrap_or_default();
        Ok(self.planes(sequence, t)?.swap_remove(i))
    }
    fn arm(&mut self, sequence: &Sequence, t: usize) -> Result<ArmMasks> {
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let planes = self.planes(sequence, t)?;
        let refs: Vec<(Class, &[f32])> = DATASET_CLASSES
            .iter()
            .zip(&planes)
            .map(|(&c, p)| (c, p.as_slice()))
            .collect();
        ArmMasks::from_planes(w, h, &refs)
    }
}

/// The forearm pixels seen through the occluder as well: a perfect segmenter that does not
/// see through occlusion.
#[derive(Debug, Clone, Copy, Default)]
pub struct VisibleMasks;

impl MaskSource for VisibleMasks {
    fn name(&self) -> String {
        "ground truth, visible pixels only".into()
    }
    fn start(&mut self) {}
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>> {
        let n = sequence.pixels();
        Ok(forearm_of(&sequence.visible[t * n..(t + 1) * n]))
    }
    /// The occluder's pixels may hide any part: they are not background.
    fn arm(&mut self, sequence: &Sequence, t: usize) -> Result<ArmMasks> {
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let n = sequence.pixels();
        let mut masks = ArmMasks::from_classes(sequence.visible_frame(t), w, h)?;
        for (b, &o) in masks
            .background
            .iter_mut()
            .zip(&sequence.occluder[t * n..(t + 1) * n])
        {
            if o != 0 {
                *b = 0.0;
            }
        }
        Ok(masks)
    }
}

/// 1 where a class image shows the forearm, 0 elsewhere.
fn forearm_of(classes: &[u8]) -> Vec<f32> {
    classes
        .iter()
        .map(|&c| f32::from(u8::from(c == Class::Forearm as u8)))
        .collect()
}

/// A segmentation network's forearm probabilities, resampled to the dataset's size. Where a
/// frame's region of interest changes scale ([`crate::tracker::view_jump`], as the deployed
/// tracker's crop does when it finds or loses the arm), and on a sequence's first frame, the
/// network starts afresh, as the tracker's does.
pub struct NetworkMasks {
    pub net: ProcNet,
    pub name: String,
    /// Where a network that reads depth ([`workcell_procnet::ProcNetConfig::reads_depth`]) reads each
    /// frame's depth image; `None` for one that reads RGB alone.
    pub depth_from: Option<Dataset>,
}

impl NetworkMasks {
    /// Frame `t` as the network reads it ([`workcell_procnet::data::input_frame`]): RGB, and the depth
    /// plane for a network that reads depth.
    fn input<'s>(&self, sequence: &'s Sequence, t: usize) -> Result<Cow<'s, [f32]>> {
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let depth = if self.net.config().reads_depth() {
            let dataset = self
                .depth_from
                .as_ref()
                .ok_or_else(|| PerceptionError::Input {
                    message: format!(
                        "{} reads depth: give it the dataset's depth images",
                        self.name
                    ),
                })?;
            Some(dataset.depth(&sequence.entry, t)?)
        } else {
            None
        };
        Ok(workcell_procnet::data::input_frame(
            sequence.rgb_frame(t),
            depth.as_deref(),
            w,
            h,
            self.net.config(),
        )?)
    }

    /// Frame `t`'s input, after starting the network afresh on it when it is the
    /// sequence's first or another view than frame `t - 1` ([`ProcNet::start_view`]), as
    /// the tracker's network starts on a stream's first frame and on each new view.
    fn follow_view<'s>(&mut self, sequence: &'s Sequence, t: usize) -> Result<Cow<'s, [f32]>> {
        let input = self.input(sequence, t)?;
        let fx = |t: usize| sequence.labels.get(t).map(|l| l.camera.fx);
        let jump = matches!((t.checked_sub(1).and_then(fx), fx(t)),
            (Some(last), Some(now)) if crate::tracker::view_jump(Some(last), now));
        if t == 0 || jump {
            let (w, h) = (sequence.width as usize, sequence.height as usize);
            self.net.start_view(&input, w, h)?;
        }
        Ok(input)
    }
}

impl MaskSource for NetworkMasks {
    fn name(&self) -> String {
        self.name.clone()
    }
    fn start(&mut self) {
        self.net.reset();
    }
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>> {
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let input = self.follow_view(sequence, t)?;
        Ok(self.net.forearm(&input, w, h)?)
    }
    fn arm(&mut self, sequence: &Sequence, t: usize) -> Result<ArmMasks> {
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let input = self.follow_view(sequence, t)?;
        let planes = self.net.planes(&input, w, h)?;
        let refs: Vec<(Class, &[f32])> = planes.iter().map(|(c, p)| (*c, p.as_slice())).collect();
        ArmMasks::from_planes(w, h, &refs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_render::dataset::test_util::one_frame_entry;

    /// One 4x4 frame: the forearm in the top-left 2x2 block and one pixel of the block beside
    /// it, the upper arm in the bottom row, background elsewhere.
    fn sequence() -> Sequence {
        let (b, u, f) = (
            Class::Background as u8,
            Class::UpperArm as u8,
            Class::Forearm as u8,
        );
        #[rustfmt::skip]
        let classes = vec![
            f, f, f, b,
            f, f, b, b,
            b, b, b, b,
            u, u, u, u,
        ];
        Sequence {
            entry: one_frame_entry("light", 0.0),
            width: 4,
            height: 4,
            rgb: vec![0.5; 3 * 16],
            visible: classes.clone(),
            classes,
            occluder: vec![0; 16],
            amodal_forearm: vec![0; 16],
            labels: Vec::new(),
        }
    }

    #[test]
    fn at_the_frames_size_the_true_masks_are_the_class_image() {
        let s = sequence();
        let exact = GroundTruthMasks.arm(&s, 0).expect("masks");
        let same = GroundTruthAtSize { size: 4 }.arm(&s, 0).expect("masks");
        assert_eq!(exact, same);
    }

    #[test]
    fn at_half_size_each_block_is_its_share_of_the_class() {
        let s = sequence();
        let mut source = GroundTruthAtSize { size: 2 };
        // Block means: forearm [1, 1/4; 0, 0], upper arm [0, 0; 1/2, 1/2]. Back at 4x4 each
        // pixel is the bilinear sample at its centre: a corner pixel is its block's mean.
        let forearm = source.forearm(&s, 0).expect("forearm");
        assert!((forearm[0] - 1.0).abs() < 1e-6, "{forearm:?}");
        assert!((forearm[3] - 0.25).abs() < 1e-6, "{forearm:?}");
        // Pixel (1, 1) lies a quarter of a block from the centre of the forearm's block
        // towards the blocks beside and below: 1 * 9/16 + 1/4 * 3/16 + 0 + 0.
        assert!(
            (forearm[5] - (9.0 / 16.0 + 0.75 / 16.0)).abs() < 1e-6,
            "{forearm:?}"
        );
        let arm = source.arm(&s, 0).expect("masks");
        assert!((arm.parts[0][15] - 0.5).abs() < 1e-6, "{:?}", arm.parts[0]);
        // The background is one less the likeliest class, as for a network's planes.
        for i in 0..16 {
            let most = arm.parts.iter().map(|p| p[i]).fold(0.0f32, f32::max);
            assert!((arm.background[i] - (1.0 - most)).abs() < 1e-6);
        }
        assert!(GroundTruthAtSize { size: 8 }.arm(&s, 0).is_err());
        assert!(GroundTruthAtSize { size: 0 }.forearm(&s, 0).is_err());
    }
}
