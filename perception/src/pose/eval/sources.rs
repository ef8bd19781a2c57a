//! Where the forearm masks of a pose evaluation come from.

use workcell_render::Class;
use workcell_render::dataset::Sequence;

use crate::error::Result;
use crate::infer::ProcNet;
use crate::pose::ArmMasks;

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

/// A segmentation network's forearm probabilities, resampled to the dataset's size.
pub struct NetworkMasks {
    pub net: ProcNet,
    pub name: String,
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
        self.net.forearm(sequence.rgb_frame(t), w, h)
    }
    fn arm(&mut self, sequence: &Sequence, t: usize) -> Result<ArmMasks> {
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let planes = self.net.planes(sequence.rgb_frame(t), w, h)?;
        let refs: Vec<(Class, &[f32])> = planes.iter().map(|(c, p)| (*c, p.as_slice())).collect();
        ArmMasks::from_planes(w, h, &refs)
    }
}
