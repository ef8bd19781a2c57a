//! The human arm's pose in camera frames, for the work-cell's safety filter: the pose search
//! that fits the human model's joints to ProcNet's masks by render-and-compare ([`pose`]),
//! and the runtime tracker that turns frames of one camera into the arm's capsules with an
//! uncertainty ([`ArmTracker`]), the same beside a real camera as in the simulator. The
//! network itself (model, training, segmentation evaluation) is `workcell-procnet`, below
//! this crate; [`eval`] measures the pose on a dataset's sequences.
//!
//! Modules import one way: [`pose`] < [`tracker`] < [`eval`]; [`dataset`] (the humans a
//! dataset's manifest records) is read by [`eval`] only.

pub mod dataset;
mod error;
pub mod eval;
pub mod pose;
pub mod tracker;

pub use error::{PerceptionError, Result};
pub use pose::{ArmModel, PartCapsule};
pub use tracker::{ArmEstimate, ArmOutcome, ArmTracker, DEFAULT_INPUT_PX, NoEstimate, RoiMasks};
