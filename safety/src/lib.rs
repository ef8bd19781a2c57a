//! Keeping a robot arm away from a human: signed distances between robot links and human
//! parts, a QP safety filter (clarabel), and speed and separation monitoring with the power
//! and force limits of ISO/TS 15066.
//!
//! This crate does not depend on the simulator: it takes joint positions, nominal joint
//! velocities and a [`HumanEstimate`], and returns joint velocities, so that it can run beside
//! a real robot.
//!
//! ```
//! use workcell_robots::prelude::*;
//! use workcell_safety::{FilterConfig, FilterMode, HumanEstimate, SafetyFilter};
//!
//! let robot = RobotModel::from_catalogue("iiwa14_kinematics")?;
//! let mut filter = SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, FilterConfig::default())?;
//! // No human in sight: the filter cannot vouch for anything and brakes.
//! let out = filter.tick(&robot, &[0.0; 7], &[0.1; 7], &HumanEstimate::default(), 0.004);
//! assert!(matches!(out.status, workcell_safety::FilterStatus::Braking(_)));
//! assert!(filter.command().iter().all(|v| v.is_finite()));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod distance;
mod error;
mod filter;
pub mod geometry;
mod human;
pub mod iso;
mod qp;

pub use distance::{MAX_DOF, Obstacle, PairConstraint, RobotGeometry};
pub use error::{Result, SafetyError};
pub use filter::{BrakeReason, FilterConfig, FilterMode, FilterOutput, FilterStatus, SafetyFilter};
pub use geometry::{Capsule, SignedDistancePair};
pub use human::{AnticipatedPart, HumanEstimate, HumanGeometry, HumanPart, PartEstimate};
pub use iso::{BodyRegion, SsmConfig};
pub use qp::{QpFailure, QpFilter, QpProblem};
