//! Robot and human-arm models for workcell.
//!
//! - [`RobotModel`]: links, joints (revolute, continuous, prismatic, fixed; mimic joints
//!   honoured), limits (position, velocity, effort, acceleration, `safety_controller`),
//!   inertials, visual and collision geometry, loaded from URDF with every field checked.
//! - Meshes (STL binary and ASCII, OBJ, COLLADA/DAE, glTF 2.0 `.gltf`/`.glb`) found through an explicit
//!   [`PackageMap`] for `package://` URIs; a path that leaves its package is refused.
//! - [`RobotModel::forward_kinematics`] and [`RobotModel::point_jacobian`].
//! - [`collision`]: parry3d shapes of links and a bounding capsule per link.
//! - [`CATALOGUE`]: built-in arms (`ur5e_kinematics`, `iiwa14_kinematics`) and `human_arm`.
//!
//! ```
//! use workcell_robots::prelude::*;
//!
//! let robot = RobotModel::from_catalogue("iiwa14_kinematics")?;
//! let state = robot.fk(Pose::IDENTITY, &[0.0; 7])?;
//! let flange = robot.link_id("tool0").expect("the catalogue arm has a tool0");
//! // Stretched upright: 0.36 + 0.42 + 0.40 + 0.126 m above the base.
//! assert!((state.link_pose(flange).translation.z - 1.306).abs() < 1e-9);
//! # Ok::<(), workcell_robots::RobotError>(())
//! ```

pub mod assets;
mod catalogue;
pub mod collision;
mod error;
pub mod glb;
pub mod human;
pub mod input;
mod kinematics;
pub mod math;
mod mesh;
mod model;
pub mod output;
mod package;
mod urdf;

pub use catalogue::{
    CATALOGUE, CatalogueEntry, ROBOT_PATH_VAR, RobotSource, added_robots, robot_library,
};
pub use error::{Result, RobotError};
pub use human::{HumanLook, HumanPart, Side};
pub use kinematics::{Jacobian, KinematicState};
pub use mesh::{DECODER_CRATES, MeshError, TriMesh, gltf_buffer_files, gltf_buffer_path};
pub use model::{
    Coordinate, Geometry, Inertial, Joint, JointId, JointKind, JointLimits, Link, LinkId,
    RobotModel, SafetyController, Shape,
};
pub use package::{PACKAGE_PATH_VARS, PackageMap};

/// The types most users need.
pub mod prelude {
    pub use crate::math::{Pose, Rotation, Vector};
    pub use crate::{Jacobian, KinematicState, PackageMap, RobotError, RobotModel};
}
