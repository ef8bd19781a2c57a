//! The forearm's pose by render-and-compare, two ways:
//!
//! - **Articulated** ([`ArmFitter`], the default of `workcell eval pose`): the human model's
//!   joints fitted to the upper arm's, the forearm's and the hand's masks at once; the
//!   forearm's pose follows from the fitted arm. See its module docs.
//! - **The paper's**, [`PoseEstimator`] (below): the forearm's 6-DoF pose from its mask alone.
//!
//! A candidate pose is scored by the paper's agreement between the observed mask `m` (values
//! in [0, 1], ProcNet's probabilities or a binary mask) and the mask `mhat` the renderer draws
//! for the candidate:
//!
//! ```text
//! f_m(m, mhat) = sum_ij 4 (m_ij - 1/2)(mhat_ij - 1/2) / (w h)      in [-1, 1]
//! ```
//!
//! With `s = 2 m - 1` and a binary render this is `(2 sum_{mhat=1} s - sum s) / (w h)`, so a
//! candidate costs one sum over the pixels it covers. The search runs in a region of interest
//! around the mask (and the previous pose), [`PoseConfig::roi`]; pixels outside it are taken
//! as background. On a 30-pixel forearm in a 128x128 image `f_m` moves in its third decimal,
//! so thresholds use the *gain* of a candidate over rendering nothing,
//! `(f_m - f_m(m, 0)) / (1 - f_m(m, 0))`, which for a binary mask is
//! `(true positives - false positives) / mask pixels`: 1 for a perfect fit, 0 for no better
//! than an empty image. Both orderings are the same within a frame.
//!
//! - **With a prior** (the previous frame's pose): gradient ascent from the prior. The
//!   gradient is a central difference from 12 renders around the current pose in scaled
//!   coordinates (one unit moves the image by about a pixel: `z / f` across, `z^2 / (f L)` in
//!   depth, `2 z / (f L)` swinging the forearm's axis, `z / (f w)` spinning about it), then a
//!   line search of 3 renders along it; 12 random probes share the batch. An improving step
//!   may grow the difference step by 1.5; a failed one halves it; the climb stops when the
//!   step falls below [`PoseConfig::min_step_px`] or after [`PoseConfig::max_iterations`].
//!   The forearm's bones are under two pixels thick, so the exact score is flat beyond a
//!   pixel of misalignment: the climb runs coarse to fine, comparing masks dilated by 2 and 1
//!   pixels and with the render's pixel coverage before the paper's point-sampled comparison.
//! - **Without a prior**, or when the climb ends below [`PoseConfig::min_gain`] (the track is
//!   lost): a global search. Orientation hypotheses are directions of the forearm's axis on a
//!   sphere (a hemisphere without an anchor: the forearm is symmetric end for end) that agree
//!   with the mask's principal axis, at two spins; each one's centre lies on the ray through
//!   the mask's centroid, at the depth the mask's length and the forearm's known length give
//!   (or, with an anchor, at the depths that put the anchored end on its sphere). All are
//!   rendered in one batch; the best few are climbed and the best climb wins. Such frames are
//!   marked [`PoseEstimate::reacquired`].
//! - **An anchor** ([`Anchor`]): a thin rod's silhouette fixes the rays through its ends but
//!   not where along them the ends lie, a one-parameter family of poses with the same mask.
//!   The forearm's elbow hangs from a shoulder whose place in the cell is known; a penalty
//!   keeps it on that sphere. One ambiguity is left: the wrist at either point of its ray a
//!   forearm's length from the elbow (the *mirror*).
//! - **Uncertainty**: per camera axis, the displacement over which the gain of the quadratic
//!   fitted to the last central differences drops by two mask pixels' worth; the spread of
//!   the climbed hypotheses that end within 0.05 gain of the best; and, with an anchor, the
//!   distance to the mirror's wrist when the mask cannot tell the two apart.
//!   [`PoseEstimate::uncertainty_m`] is the largest, the radius by which the safety layer
//!   inflates the arm's capsules.
//!
//! Spin about the forearm's axis is weakly observable (two thin bones side by side); it is
//! reported, and evaluated, on its own.

mod arm;
mod articulated;
mod config;
mod image;
mod model;
mod search;

pub use arm::{ArmModel, POSE_MESH_SEGMENTS, PartCapsule};
pub use articulated::{
    ArmFit, ArmFitConfig, ArmFitOutcome, ArmFitter, ArmGain, ArmMasks, ArticulatedArm, BoundInputs,
    BoundSource, Calibration, CalibrationFile, ConfidentFloors, FITTED_PARTS, FitSettings,
    HIDDEN_BANDS, HIDDEN_MARGIN_M, MAX_CALIBRATION_BYTES, MAX_GRID_JOINTS, NetworkCalibration,
    TrunkModel, calibration_path, file_sha256,
};
pub use config::PoseConfig;
pub use image::f_m;
pub use model::{Anchor, RigidModel};
pub use search::PoseEstimator;

use workcell_robots::math::Pose;

/// Why a frame gave no pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoPose {
    /// No mask value above the threshold: nothing seen, or fully occluded.
    Empty,
    /// A value that is not a probability in [0, 1] (NaN from the network, say).
    NotAProbability,
    /// Several separate blobs that no single forearm pose explains.
    SeveralBlobs { blobs: usize },
    /// The best fit's gain stayed below [`PoseConfig::min_gain`].
    PoorFit,
}

impl std::fmt::Display for NoPose {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NoPose::Empty => write!(f, "empty mask"),
            NoPose::NotAProbability => write!(f, "mask values not in [0, 1]"),
            NoPose::SeveralBlobs { blobs } => write!(f, "{blobs} blobs no one pose explains"),
            NoPose::PoorFit => write!(f, "no pose fits the mask"),
        }
    }
}

/// A pose found.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseEstimate {
    /// The object (forearm link) frame in the camera frame.
    pub X_CO: Pose,
    /// The paper's `f_m` over the whole image at `X_CO`.
    pub f_m: f64,
    /// Gain over an empty render (see the module docs), in the search's region of interest,
    /// with the render's pixel coverage as `mhat`.
    pub gain: f64,
    /// The fraction of the mask's support within a pixel of the render at `X_CO`.
    pub explained: f64,
    /// Position uncertainty along the camera's x, y, z axes, m.
    pub sigma_C_m: [f64; 3],
    /// Spread of the surviving global hypotheses' centres, m (0 when tracking).
    pub spread_m: f64,
    /// The radius to inflate the forearm by, m: the larger of `|sigma|` and the spread.
    pub uncertainty_m: f64,
    /// Found by the global search (first frame, or the track was lost).
    pub reacquired: bool,
    /// Masks rendered for this frame.
    pub renders: usize,
}

/// The result of one frame.
pub type PoseOutcome = std::result::Result<PoseEstimate, NoPose>;

#[cfg(test)]
mod tests;
