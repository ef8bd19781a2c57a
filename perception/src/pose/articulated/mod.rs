//! The arm's pose from every part it shows: articulated render-and-compare.
//!
//! The forearm's mask alone leaves its depth along two rays open and, with the elbow hung
//! from the shoulder, a two-fold mirror ([`crate::pose`]). The arm shows more than its
//! forearm: this fit moves the human model's joints (both shoulder angles and the elbow, and
//! whatever else the model has) and compares every arm part's render with that part's mask
//! at once. The shoulder stays where the human model and its base pose put it (on a model
//! whose trunk turns and leans, where the trunk's stage put it first, from the torso's mask:
//! [`TrunkModel`], [`ArmFitter::fit_trunk`]), the upper arm's mask fixes where the elbow is,
//! the hand's mask which end of the forearm is the wrist.
//!
//! **The score** of a configuration `q` is, summed over the parts `p` (upper arm, forearm,
//! hand) and the pixels their renders cover (the covered fraction `c` of each pixel, from
//! [`ArmFitConfig::supersample`]^2 samples):
//!
//! ```text
//! score(q) = sum_p sum_px c (s_p - alpha min(d_p, cap)) / M  -  prior(q)
//! s_p = m_p - m_background
//! ```
//!
//! - `s_p` is +1 on the part's own pixels and -1 on the background; on pixels of something
//!   that may hide the part (the robot, the torso, another arm part) it is 0: a part behind
//!   the robot is neither rewarded nor punished. With binary masks `sum c s_p / M` is the
//!   paper's `f_m` gain over rendering nothing, `(true positives - false positives) / mask
//!   pixels`, summed over the parts: 1 for a perfect fit ([`ArmFit::gain`]).
//! - `d_p` is the distance in pixels to the part's mask (a distance transform): a render
//!   beside its mask still has a slope towards it, where the overlap alone is flat.
//! - `M` is the mask's mass, all parts together.
//! - `prior(q)`: tracking, a constant-velocity prediction from the last two fits,
//!   `w sum ((q - q_pred) / sigma)^2 / dof`.
//!
//! A part renders as row spans ([`SpanBatch`]: each sample row's first and last covered
//! sample), from the triangles of its visuals that are not inside another of them
//! ([`RenderMesh::outer_union`]: the human model's bones and the caps between its limb
//! segments left out, 724 of 2,544 triangles kept, the same masks). A part's row is nearly
//! always one run, and a span sums in two lookups of the row's prefix sums. Both took the
//! tracked fit from 18.3 to 10.6-11.0 ms a frame on the cell's camera, the global search
//! from 289 to 121-134 ms (`workcell bench-perception --depth --frames 900`).
//!
//! **The search.** Tracking, a climb from the prediction: each iteration renders the
//! configurations one step along each joint either way (a central-difference gradient and
//! each joint's curvature), then three points along the gradient and a few random probes;
//! the best one is taken and the step grows by 1.5, or halves when none is better, down to
//! [`ArmFitConfig::min_step_rad`]. Without a track, or when every tracked hypothesis ends
//! below [`ArmFitConfig::search_below_gain`], a global search renders a grid over the joints'
//! ranges and climbs the best few distinct cells ([`ArmFit::reacquired`]); the tracked
//! climbs compete with them. With a depth image ([`ArmFitConfig::depth_start`]) a climb
//! also starts from where the depth points put the forearm (its mask's points, less any
//! nearer than the arm can reach, their principal axis; the elbow at the end the upper
//! arm's points are nearer, the wrist where the hand's are), unless the best fit already
//! has it there. With true masks and the trunk held at the labels, on the recorded people
//! of a validation split (2,958 frames), it took the frames whose forearm has an end more
//! than 10 cm off from 629 to 171 and the time per frame from 15 to 27 ms (`workcell eval
//! pose --masks gt --depth --trunk truth --depth-start`). A track that explains the masks
//! poorly has often followed a wrong optimum on masks the network misread: on the
//! validation split with ProcNet's masks and depth, searching below a gain of 0.55 (6 % of
//! frames) took the 99th percentile of the forearm's error from 6.0 to 4.9 cm.
//!
//! **Acceptance.** A fit is a pose when its gain reaches [`ArmFitConfig::min_gain`] (0.3).
//! Below it, down to [`ArmFitConfig::confirm_min_gain`], the best fit is a pose only when the
//! frame before put the forearm's centre and wrist within [`ArmFitConfig::confirm_m`] of it
//! (its pose, or its own best fit below the threshold, which is tracked on as a candidate;
//! [`ArmFit::confirmed`]). Masks that show a far, half-hidden arm faintly give such fits frame
//! after frame in one place; masks that miss the arm give them here and there. A fit that
//! reaches `min_gain` always wins over a fainter one, so a faint track never keeps a better
//! fit out. Whether it pays is the masks' (their [`Calibration`] file): from 0.2 for the
//! network that reads depth, whose confirmed poses are either right or far off, so their
//! bound is at least [`Calibration::confirmed_floor_m`]; off for the RGB network, whose
//! confirmed fits were mostly wrong arms.
//!
//! **Hypotheses.** Far from the camera a silhouette is nearly an orthographic projection, and
//! the arm mirrored through the plane across the line of sight that holds the shoulder
//! renders the same masks: the masks cannot tell the two apart. The fit keeps every climb
//! within [`ArmFitConfig::ambiguity_gain`] of the best that puts the forearm elsewhere (up
//! to [`ArmFitConfig::hypotheses`]) and tracks each on; a hypothesis that stops explaining
//! the masks as well as the best is dropped.
//!
//! **Uncertainty.** The joints' covariance from the score's Hessian at the fit (the
//! displacements that cost two mask pixels, correlated joints included: far away, moving the
//! arm along the line of sight takes both shoulder angles), mapped through the forearm's
//! kinematics to metres at its centre and its far end (scaled by
//! [`ArmFitConfig::uncertainty_scale`], plus a floor); and the farthest the surviving
//! hypotheses put the forearm's centre or wrist from the best's. [`ArmFit::uncertainty_m`] is
//! the larger. The floor grows with how much of the forearm's region the depth image shows
//! hidden by something in front of the arm ([`ArmFit::hidden_share`]: pixels nearer than the
//! fitted arm, such as the paper's black occluder, which the datasets and the closed loop put
//! at `workcell_render::occlusion::OCCLUDER_DEPTH_M`): the masks hold less of a hidden
//! forearm. Calibrated ([`Calibration`]), 99 % of a split's frames have their forearm's
//! centre and wrist within it. The depth term skips pixels nearer than any point the arm can
//! reach ([`ArticulatedArm::nearest_depth_m`]): they say nothing of the arm's depth.

mod calibration;
mod config;
mod fit;
mod kinematics;
mod masks;
mod numerics;
#[cfg(test)]
mod tests;
mod trunk;

use workcell_robots::HumanPart;

pub use calibration::{
    BoundInputs, BoundSource, Calibration, CalibrationFile, ConfidentFloors, FitSettings,
    HIDDEN_BANDS, MAX_CALIBRATION_BYTES, NetworkCalibration, calibration_path, file_sha256,
};
pub use config::ArmFitConfig;
pub use fit::{ArmFit, ArmFitOutcome, ArmFitter, ArmGain, MAX_GRID_JOINTS};
pub use kinematics::ArticulatedArm;
pub use masks::ArmMasks;
use masks::*;
use numerics::*;
pub use trunk::TrunkModel;

/// The parts fitted, in the order of [`ArmMasks::parts`] and [`ArmFit::X_CL`].
pub const FITTED_PARTS: [HumanPart; 3] = HumanPart::ARM;

/// A part whose axis is within this cosine of the line of sight is seen end-on, and its
/// depth is left out of the score (0.9: within 26 degrees).
pub(super) const END_ON_COS: f64 = 0.9;

/// A depth this much nearer than the nearest the arm can reach (or, for
/// [`ArmFit::hidden_share`], than the fitted arm) shows something in front of it, m: a margin
/// for the depth camera's noise.
pub const HIDDEN_MARGIN_M: f64 = 0.05;
