//! The deployed tracker's region of interest in dataset generation: a dataset whose frames
//! are read through the crop that [`ArmTracker`] asks for, frame by frame, as it tracks the
//! arm through them with ProcNet and the depth image (the workspace crop until two frames
//! in a row gave a pose, then the crop around the arm it found, and back to the workspace
//! crop when it loses the arm).
//!
//! A stored dataset keeps one kind of crop for a whole sequence; the deployed tracker
//! switches. Evaluating the tracker's own crops ([`workcell_sim::dataset::CropPolicy`])
//! measures the pipeline as it runs beside a camera, on the same scenes.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use workcell_perception::ArmTracker;
use workcell_perception::pose::{ArmFitConfig, Calibration};
use workcell_procnet::{Backend, ProcNet};
use workcell_render::Camera;
use workcell_render::dataset::HumanLabel;
use workcell_render::roi::{Roi, RoiKind};
use workcell_robots::RobotModel;
use workcell_robots::math::Pose;
use workcell_sim::dataset::{CropFactory, CropPolicy, GeneratedFrame, PolicyError};

use crate::Result;

/// How the tracker fared while the frames were made.
#[derive(Debug, Default)]
pub struct CropCounts {
    /// Frames read.
    pub frames: AtomicUsize,
    /// Frames the tracker gave a pose for.
    pub posed: AtomicUsize,
    /// Frames read through the tracked crop (the others through the workspace crop or the
    /// whole frame).
    pub tracked: AtomicUsize,
}

/// The [`CropPolicy`] of an [`ArmTracker`] with a network, reading the depth image.
pub struct TrackerCrop {
    tracker: ArmTracker,
    counts: Arc<CropCounts>,
}

impl TrackerCrop {
    /// A tracker of `human` (model in its look, base pose) with the weights at `weights`,
    /// the fit configured as the closed loop's for ProcNet with depth.
    ///
    /// # Errors
    /// The weights do not load, the human has no arm.
    pub fn new(
        human: &RobotModel,
        X_WH: &Pose,
        weights: &Path,
        counts: Arc<CropCounts>,
    ) -> Result<Self> {
        let net = ProcNet::load(weights, Backend::Flex)?;
        let found = Calibration::of_weights(weights, true)?;
        if let Some(w) = found.warning() {
            tracing::warn!("{w}");
        }
        let fit = found.calibration.apply(ArmFitConfig::default());
        let tracker = ArmTracker::new(human, X_WH, fit)?.with_network(net)?;
        Ok(Self { tracker, counts })
    }

    /// A factory of these policies for [`workcell_sim::dataset::Generator::with_crop`]:
    /// one tracker per sequence, the human of `label`, the weights at `weights` (checked
    /// here, once, so that a bad file fails before any sequence).
    ///
    /// # Errors
    /// The human model or the weights do not load.
    pub fn factory(
        label: &HumanLabel,
        weights: &Path,
        counts: Arc<CropCounts>,
    ) -> Result<Arc<CropFactory>> {
        let (human, X_WH) = workcell_perception::dataset::human_of(label)?;
        Self::new(&human, &X_WH, weights, counts.clone())?;
        let weights = weights.to_path_buf();
        Ok(Arc::new(move || {
            Self::new(&human, &X_WH, &weights, counts.clone())
                .map(|p| Box::new(p) as Box<dyn CropPolicy>)
                .map_err(PolicyError::from)
        }))
    }
}

impl CropPolicy for TrackerCrop {
    fn start(&mut self) {
        self.tracker.reset();
    }

    fn roi(&mut self, native: &Camera) -> (Roi, RoiKind) {
        let (roi, kind) = self.tracker.region(native);
        if kind == RoiKind::Tracked {
            self.counts.tracked.fetch_add(1, Ordering::Relaxed);
        }
        (roi, kind)
    }

    /// The frame as the dataset stores it: its depth in whole millimetres, as the stored
    /// 16-bit image gives it back, so that an evaluation of the stored frames reads what the
    /// tracker read.
    fn seen(&mut self, frame: &GeneratedFrame) -> std::result::Result<(), PolicyError> {
        let camera = Camera::from(&frame.labels.camera);
        let depth: Vec<f32> = frame.depth_m.iter().map(|&d| stored_depth_m(d)).collect();
        let outcome = self
            .tracker
            .track_region(&camera, &frame.rgb, Some(&depth))?;
        self.counts.frames.fetch_add(1, Ordering::Relaxed);
        if outcome.is_ok() {
            self.counts.posed.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    }
}

/// A depth as the dataset's 16-bit millimetre image stores and loads it.
fn stored_depth_m(d: f32) -> f32 {
    f32::from((f64::from(d) * 1000.0).round().clamp(0.0, 65535.0) as u16) / 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_is_read_back_as_the_stored_millimetres() {
        assert_eq!(stored_depth_m(1.23456), 1.235);
        assert_eq!(stored_depth_m(0.0), 0.0);
        assert_eq!(stored_depth_m(-1.0), 0.0);
        assert_eq!(stored_depth_m(70.0), 65.535);
    }
}
