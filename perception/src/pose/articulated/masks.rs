//! The masks the fit reads ([`ArmMasks`]): one probability image per fitted part.

use workcell_render::Class;
use workcell_robots::HumanPart;

use super::*;
use crate::error::{PerceptionError, Result};

/// What a frame shows of the arm: a probability plane per part and one for the background.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmMasks {
    pub width: usize,
    pub height: usize,
    /// Upper arm, forearm, hand (of one arm: [`FITTED_PARTS`], or
    /// [`ArticulatedArm::parts`] where built for an arm), row-major, values in [0, 1].
    pub parts: [Vec<f32>; 3],
    /// That a pixel shows nothing that could hide the arm.
    pub background: Vec<f32>,
    /// The torso's plane (and the head's, which share its class): what the trunk's stage
    /// fits ([`ArmFitter::fit_trunk`]); empty where the masks have none.
    pub torso: Vec<f32>,
    /// A depth camera's image: the camera-frame z of the surface each pixel shows, m (0 or
    /// not finite where it has none). With it the depth agreement joins the score.
    pub depth_m: Option<Vec<f32>>,
}

impl ArmMasks {
    /// From a class image ([`Class`] ids, as the dataset stores them).
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when `classes` is not `width x height`.
    pub fn from_classes(classes: &[u8], width: usize, height: usize) -> Result<Self> {
        Self::from_classes_of(FITTED_PARTS, classes, width, height)
    }

    /// From a class image, the planes of `parts` (an arm's: [`ArticulatedArm::parts`]). The
    /// other arm's pixels are neither the parts' nor the background: they may hide the arm.
    ///
    /// # Errors
    /// As [`Self::from_classes`].
    pub fn from_classes_of(
        parts: [HumanPart; 3],
        classes: &[u8],
        width: usize,
        height: usize,
    ) -> Result<Self> {
        check_len(classes.len(), width, height)?;
        let plane = |c: Class| -> Vec<f32> {
            classes
                .iter()
                .map(|&v| f32::from(u8::from(v == c as u8)))
                .collect()
        };
        Ok(Self {
            width,
            height,
            parts: parts.map(|p| plane(Class::of_part(p))),
            background: plane(Class::Background),
            torso: plane(Class::Torso),
            depth_m: None,
        })
    }

    /// From a network's per-class probabilities (independent sigmoids): the background is
    /// one less the largest class's probability. A part the network has no class for is
    /// empty, as is the torso's plane without a torso class.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when a plane is not `width x height`.
    pub fn from_planes(width: usize, height: usize, planes: &[(Class, &[f32])]) -> Result<Self> {
        Self::from_planes_of(FITTED_PARTS, width, height, planes)
    }

    /// From a network's per-class probabilities, the planes of `parts` (an arm's:
    /// [`ArticulatedArm::parts`]); a network without the left arm's classes gives the left
    /// arm empty planes.
    ///
    /// # Errors
    /// As [`Self::from_planes`].
    pub fn from_planes_of(
        parts: [HumanPart; 3],
        width: usize,
        height: usize,
        planes: &[(Class, &[f32])],
    ) -> Result<Self> {
        let n = width * height;
        for (_, p) in planes {
            check_len(p.len(), width, height)?;
        }
        let mut background = vec![1.0f32; n];
        for (_, p) in planes {
            for (b, &v) in background.iter_mut().zip(*p) {
                *b = b.min(1.0 - v);
            }
        }
        let part = |part: HumanPart| {
            planes
                .iter()
                .find(|(c, _)| c.human_part() == Some(part))
                .map_or_else(|| vec![0.0; n], |(_, p)| p.to_vec())
        };
        let torso = planes
            .iter()
            .find(|(c, _)| *c == Class::Torso)
            .map_or_else(Vec::new, |(_, p)| p.to_vec());
        Ok(Self {
            width,
            height,
            parts: parts.map(part),
            background,
            torso,
            depth_m: None,
        })
    }

    /// The forearm's plane.
    #[must_use]
    pub fn forearm(&self) -> &[f32] {
        &self.parts[1]
    }

    /// The planes the trunk's stage reads (the torso, the background, the depth image) at
    /// `1/k` of the resolution: each mask pixel the mean of a `k x k` block, each depth the
    /// median of the block's pixels that have one (0 where none does); the arm's parts left
    /// empty. `None` unless `k` divides both sides and the torso's and background's planes are
    /// whole.
    pub(super) fn trunk_planes_downsampled(&self, k: usize) -> Option<Self> {
        let (w, h) = (self.width, self.height);
        if k < 2
            || !w.is_multiple_of(k)
            || !h.is_multiple_of(k)
            || self.torso.len() != w * h
            || self.background.len() != w * h
        {
            return None;
        }
        let (sw, sh) = (w / k, h / k);
        // The masks' block means: the region's own box filter.
        let block = |plane: &[f32]| workcell_render::roi::resample(plane, 1, w, h, sw, sh);
        // A depth block's median over its pixels that have one: a block on the torso's
        // outline keeps the torso's depth where most of it shows the torso, not a mean
        // halfway to the wall behind.
        let depth_m = match &self.depth_m {
            Some(d) if d.len() == w * h => {
                let mut out = vec![0.0f32; sw * sh];
                let mut zs = Vec::with_capacity(k * k);
                for (i, o) in out.iter_mut().enumerate() {
                    let (x0, y0) = ((i % sw) * k, (i / sw) * k);
                    zs.clear();
                    for y in y0..y0 + k {
                        zs.extend(
                            d[y * w + x0..y * w + x0 + k]
                                .iter()
                                .filter(|z| z.is_finite() && **z > 0.0),
                        );
                    }
                    zs.sort_by(f32::total_cmp);
                    let m = zs.len();
                    if m > 0 {
                        *o = 0.5 * (zs[(m - 1) / 2] + zs[m / 2]);
                    }
                }
                Some(out)
            }
            _ => None,
        };
        Some(Self {
            width: sw,
            height: sh,
            parts: [Vec::new(), Vec::new(), Vec::new()],
            background: block(&self.background),
            torso: block(&self.torso),
            depth_m,
        })
    }
}

pub(super) fn check_len(len: usize, width: usize, height: usize) -> Result<()> {
    if len == width * height {
        Ok(())
    } else {
        Err(PerceptionError::Input {
            message: format!(
                "a mask of {len} values for a {width}x{height} image ({} pixels)",
                width * height
            ),
        })
    }
}
