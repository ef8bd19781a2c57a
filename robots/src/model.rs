//! The kinematic model of a robot: links, joints, limits, inertials and geometry.
//!
//! A [`RobotModel`] is immutable once built. Joints are stored in topological order (every
//! joint's parent link is the root or the child of an earlier joint), so forward kinematics is
//! one pass over `joints()`.

use std::path::PathBuf;
use std::sync::Arc;

use crate::math::{Pose, Vector};
use crate::mesh::TriMesh;

/// Index of a link in [`RobotModel::links`].
pub type LinkId = usize;
/// Index of a joint in [`RobotModel::joints`].
pub type JointId = usize;

/// A robot (or human arm) as a tree of links connected by joints.
#[derive(Debug, Clone)]
pub struct RobotModel {
    pub(crate) name: String,
    pub(crate) source: PathBuf,
    pub(crate) links: Vec<Link>,
    pub(crate) joints: Vec<Joint>,
    /// Joint of each configuration coordinate, in coordinate order.
    pub(crate) actuated: Vec<JointId>,
    pub(crate) root: LinkId,
    pub(crate) warnings: Vec<String>,
}

impl RobotModel {
    /// The robot's name from the URDF `<robot name="..">`.
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }
    /// The file the model was loaded from (`catalogue/<name>` for built-in models).
    #[must_use]
    pub fn source(&self) -> &std::path::Path {
        &self.source
    }
    /// What the loader tolerated and adjusted rather than refused (a mimic on a fixed joint,
    /// an empty `<texture/>`, `package:///`), one sentence each, naming the element.
    #[must_use]
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }
    /// All links; `links()[root()]` has no parent joint.
    #[must_use]
    pub fn links(&self) -> &[Link] {
        &self.links
    }
    /// All joints, in topological order from the root.
    #[must_use]
    pub fn joints(&self) -> &[Joint] {
        &self.joints
    }
    /// The root link.
    #[must_use]
    pub fn root(&self) -> LinkId {
        self.root
    }
    /// Number of configuration coordinates: revolute, continuous and prismatic joints that
    /// are not mimic joints.
    #[must_use]
    pub fn dof(&self) -> usize {
        self.actuated.len()
    }
    /// The joint that each configuration coordinate drives, in coordinate order.
    #[must_use]
    pub fn actuated_joints(&self) -> &[JointId] {
        &self.actuated
    }
    /// Keeps the visuals for which `keep` is true (a human model in one look:
    /// `model.retain_visuals(|g| look.shows(g.name.as_deref()))`).
    pub fn retain_visuals(&mut self, mut keep: impl FnMut(&Geometry) -> bool) {
        for link in &mut self.links {
            link.visuals.retain(&mut keep);
        }
    }

    /// A link by name.
    #[must_use]
    pub fn link_id(&self, name: &str) -> Option<LinkId> {
        self.links.iter().position(|l| l.name == name)
    }
    /// A joint by name.
    #[must_use]
    pub fn joint_id(&self, name: &str) -> Option<JointId> {
        self.joints.iter().position(|j| j.name == name)
    }
    /// The joints that move `link`: its parent joint, then that joint's parent link's, up to
    /// the root (none for the root).
    pub fn joints_above(&self, link: LinkId) -> impl Iterator<Item = JointId> + '_ {
        std::iter::successors(self.links.get(link).and_then(|l| l.parent_joint), |&j| {
            self.links[self.joints[j].parent].parent_joint
        })
    }
    /// Total mass of all inertials, in kg.
    #[must_use]
    pub fn mass_kg(&self) -> f64 {
        self.links
            .iter()
            .filter_map(|l| l.inertial.as_ref())
            .map(|i| i.mass_kg)
            .sum()
    }
    /// Position limits of every coordinate, `[lower, upper]` (infinite for continuous joints).
    #[must_use]
    pub fn position_limits(&self) -> Vec<[f64; 2]> {
        self.actuated
            .iter()
            .map(|&j| [self.joints[j].limits.lower, self.joints[j].limits.upper])
            .collect()
    }
    /// Velocity limit of every coordinate (rad/s or m/s).
    #[must_use]
    pub fn velocity_limits(&self) -> Vec<f64> {
        self.actuated
            .iter()
            .map(|&j| self.joints[j].limits.velocity)
            .collect()
    }
    /// The configuration halfway between the position limits (0 for unlimited joints).
    #[must_use]
    pub fn neutral_configuration(&self) -> Vec<f64> {
        self.position_limits()
            .iter()
            .map(|[lo, hi]| {
                if lo.is_finite() && hi.is_finite() {
                    0.5 * (lo + hi)
                } else {
                    0.0
                }
            })
            .collect()
    }
}

/// A rigid link.
#[derive(Debug, Clone)]
pub struct Link {
    pub name: String,
    /// The joint whose child this link is; `None` for the root.
    pub parent_joint: Option<JointId>,
    pub inertial: Option<Inertial>,
    /// Geometry drawn by renderers.
    pub visuals: Vec<Geometry>,
    /// Geometry used for contacts and distances.
    pub collisions: Vec<Geometry>,
}

/// Mass properties of a link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inertial {
    pub mass_kg: f64,
    /// Pose of the centre-of-mass frame I in the link frame L.
    pub X_LI: Pose,
    /// Inertia tensor about the centre of mass in frame I, `[ixx, ixy, ixz, iyy, iyz, izz]`, kg m^2.
    pub inertia_kgm2: [f64; 6],
}

/// A piece of visual or collision geometry attached to a link.
#[derive(Debug, Clone)]
pub struct Geometry {
    /// The `name` attribute of the `<visual>`/`<collision>` element, if any.
    pub name: Option<String>,
    /// Pose of the geometry frame G in the link frame L.
    pub X_LG: Pose,
    pub shape: Shape,
    /// Colour (RGBA in [0, 1]) from the visual's material, if given.
    pub rgba: Option<[f64; 4]>,
}

/// Geometric primitives of URDF, sizes in metres (full sizes, as URDF writes them).
#[derive(Debug, Clone)]
pub enum Shape {
    /// A box centred at the origin with the given full edge lengths.
    Box {
        size_m: [f64; 3],
    },
    /// A cylinder along z, centred at the origin.
    Cylinder {
        radius_m: f64,
        length_m: f64,
    },
    /// A capsule along z: a cylinder of `length_m` with hemispheres on both ends.
    Capsule {
        radius_m: f64,
        length_m: f64,
    },
    Sphere {
        radius_m: f64,
    },
    /// A triangle mesh, already loaded and scaled.
    Mesh {
        /// The filename as the URDF wrote it (`package://...`).
        uri: String,
        /// The file it resolved to.
        path: PathBuf,
        scale: [f64; 3],
        mesh: Arc<TriMesh>,
    },
}

/// URDF joint types this crate models. `floating` and `planar` joints are rejected at load.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
}

impl JointKind {
    /// `true` for joints that move (everything but fixed).
    #[must_use]
    pub fn is_movable(self) -> bool {
        self != JointKind::Fixed
    }
    /// The URDF spelling of the joint type.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            JointKind::Revolute => "revolute",
            JointKind::Continuous => "continuous",
            JointKind::Prismatic => "prismatic",
            JointKind::Fixed => "fixed",
        }
    }
}

/// Where a joint's position comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Coordinate {
    /// A fixed joint: no coordinate.
    None,
    /// Driven by configuration coordinate `index`.
    Own { index: usize },
    /// A mimic joint: `q_joint = multiplier * q[index] + offset` (chains of mimics resolved).
    Mimic {
        index: usize,
        multiplier: f64,
        offset: f64,
    },
}

/// A joint between a parent and a child link.
#[derive(Debug, Clone)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    pub parent: LinkId,
    pub child: LinkId,
    /// Pose of the joint frame J in the parent link frame P (the URDF `<origin>`); at zero
    /// joint position the child link frame coincides with J.
    pub X_PJ: Pose,
    /// Unit axis in the joint frame (rotation axis or translation direction).
    pub axis: Vector,
    pub limits: JointLimits,
    pub safety_controller: Option<SafetyController>,
    /// The URDF `<mimic>` element as written: `(joint, multiplier, offset)`.
    pub mimic: Option<(String, f64, f64)>,
    pub damping: f64,
    pub friction: f64,
    pub coordinate: Coordinate,
}

impl Joint {
    /// The joint position for a configuration `q` (0 for fixed joints).
    #[must_use]
    #[inline]
    pub fn position(&self, q: &[f64]) -> f64 {
        self.position_of(|index| q[index])
    }

    /// The joint position with configuration coordinate `index` at `coordinate(index)` (0
    /// for fixed joints): [`Joint::position`] where the configuration is not one slice.
    #[must_use]
    #[inline]
    pub fn position_of(&self, coordinate: impl Fn(usize) -> f64) -> f64 {
        match self.coordinate {
            Coordinate::None => 0.0,
            Coordinate::Own { index } => coordinate(index),
            Coordinate::Mimic {
                index,
                multiplier,
                offset,
            } => multiplier * coordinate(index) + offset,
        }
    }

    /// Pose of the child link in the parent link for joint position `theta`.
    #[must_use]
    #[inline]
    pub fn child_pose_in_parent(&self, theta: f64) -> Pose {
        match self.kind {
            JointKind::Fixed => self.X_PJ,
            JointKind::Revolute | JointKind::Continuous => {
                self.X_PJ
                    * Pose::from_rotation(crate::math::Rotation::from_axis_angle(self.axis, theta))
            }
            JointKind::Prismatic => self.X_PJ * Pose::from_translation(self.axis * theta),
        }
    }
}

/// Joint limits (URDF `<limit>`), in rad, rad/s, N m for revolute joints and m, m/s, N for
/// prismatic ones. Continuous joints have infinite position limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    pub lower: f64,
    pub upper: f64,
    pub velocity: f64,
    pub effort: f64,
    /// URDF 1.2 acceleration limit; infinite when the file does not give one.
    pub acceleration: f64,
}

/// The URDF `<safety_controller>`: soft limits and the gains that enforce them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafetyController {
    pub soft_lower_limit: f64,
    pub soft_upper_limit: f64,
    pub k_position: f64,
    pub k_velocity: f64,
}
