//! Forward kinematics of every link and the geometric Jacobian of any point on any link.
//!
//! Conventions: poses are in the world frame W; the robot's root link sits at `X_WB` (the
//! base pose, identity unless set). A Jacobian maps the configuration velocity `qdot` to the
//! spatial velocity of a point, rows `[v_x, v_y, v_z, w_x, w_y, w_z]` (linear velocity of the
//! point, then angular velocity of its link), both expressed in W, like Pinocchio's
//! `LOCAL_WORLD_ALIGNED` frame.

use crate::error::{Result, RobotError};
use crate::math::{Pose, Vector};
use crate::model::{Coordinate, JointKind, LinkId, RobotModel};

/// The poses of every link for one configuration, plus the world axes of the joints, ready
/// for Jacobians. Reuse one per robot to keep the hot loop free of allocation.
#[derive(Debug, Clone)]
pub struct KinematicState {
    /// Pose of the robot's root link in the world.
    pub X_WB: Pose,
    /// Pose of every link in the world, indexed by [`LinkId`].
    X_WL: Vec<Pose>,
    /// Unit axis of every joint in the world.
    axis_W: Vec<Vector>,
    /// Origin of every joint frame in the world.
    p_WJ: Vec<Vector>,
}

impl KinematicState {
    /// A state for `model` with the root at the world origin, all links at identity until
    /// [`RobotModel::forward_kinematics`] fills it.
    #[must_use]
    pub fn new(model: &RobotModel) -> Self {
        Self {
            X_WB: Pose::IDENTITY,
            X_WL: vec![Pose::IDENTITY; model.links.len()],
            axis_W: vec![Vector::Z; model.joints.len()],
            p_WJ: vec![Vector::ZERO; model.joints.len()],
        }
    }

    /// Pose of link `link` in the world.
    #[must_use]
    #[inline]
    pub fn link_pose(&self, link: LinkId) -> &Pose {
        &self.X_WL[link]
    }

    /// Poses of all links, indexed by [`LinkId`].
    #[must_use]
    pub fn link_poses(&self) -> &[Pose] {
        &self.X_WL
    }
}

/// A 6 x dof geometric Jacobian, stored column by column.
#[derive(Debug, Clone, PartialEq)]
pub struct Jacobian {
    columns: Vec<[f64; 6]>,
}

impl Jacobian {
    /// A zero Jacobian with `dof` columns.
    #[must_use]
    pub fn zeros(dof: usize) -> Self {
        Self {
            columns: vec![[0.0; 6]; dof],
        }
    }
    /// Number of columns (the robot's degrees of freedom).
    #[must_use]
    pub fn dof(&self) -> usize {
        self.columns.len()
    }
    /// Column `i`: `[v; w]` for a unit velocity of coordinate `i`.
    #[must_use]
    pub fn column(&self, i: usize) -> [f64; 6] {
        self.columns[i]
    }
    /// All columns.
    #[must_use]
    pub fn columns(&self) -> &[[f64; 6]] {
        &self.columns
    }
    /// Entry at `row` (0..6) and `col`.
    #[must_use]
    pub fn get(&self, row: usize, col: usize) -> f64 {
        self.columns[col][row]
    }
    /// Linear velocity of the point for configuration velocity `qdot`.
    #[must_use]
    pub fn linear_velocity(&self, qdot: &[f64]) -> Vector {
        self.columns
            .iter()
            .zip(qdot)
            .fold(Vector::ZERO, |acc, (c, qd)| {
                acc + Vector::new(c[0], c[1], c[2]) * *qd
            })
    }
    /// Angular velocity of the link for configuration velocity `qdot`.
    #[must_use]
    pub fn angular_velocity(&self, qdot: &[f64]) -> Vector {
        self.columns
            .iter()
            .zip(qdot)
            .fold(Vector::ZERO, |acc, (c, qd)| {
                acc + Vector::new(c[3], c[4], c[5]) * *qd
            })
    }
}

impl RobotModel {
    /// Checks that `q` has one finite value per coordinate.
    ///
    /// # Errors
    /// [`RobotError::InvalidArgument`] when it does not.
    pub fn check_configuration(&self, q: &[f64]) -> Result<()> {
        if q.len() != self.dof() {
            return Err(RobotError::InvalidArgument {
                message: format!(
                    "robot '{}' has {} coordinates, got {} values",
                    self.name,
                    self.dof(),
                    q.len()
                ),
            });
        }
        if let Some(i) = q.iter().position(|v| !v.is_finite()) {
            return Err(RobotError::InvalidArgument {
                message: format!("coordinate {i} of the configuration is {}", q[i]),
            });
        }
        Ok(())
    }

    /// Computes the pose of every link for configuration `q` into `state`.
    ///
    /// # Errors
    /// [`RobotError::InvalidArgument`] when `q` has the wrong length or a non-finite value.
    pub fn forward_kinematics(&self, q: &[f64], state: &mut KinematicState) -> Result<()> {
        self.check_configuration(q)?;
        if state.X_WL.len() != self.links.len() || state.axis_W.len() != self.joints.len() {
            *state = KinematicState {
                X_WB: state.X_WB,
                ..KinematicState::new(self)
            };
        }
        state.X_WL[self.root] = state.X_WB;
        // Joints are in topological order: the parent pose is always ready.
        for (j, joint) in self.joints.iter().enumerate() {
            let X_WP = state.X_WL[joint.parent];
            let X_WJ = X_WP * joint.X_PJ;
            state.axis_W[j] = X_WJ.rotation * joint.axis;
            state.p_WJ[j] = X_WJ.translation;
            state.X_WL[joint.child] = X_WP * joint.child_pose_in_parent(joint.position(q));
        }
        Ok(())
    }

    /// Convenience: a new [`KinematicState`] at base pose `X_WB` for configuration `q`.
    ///
    /// # Errors
    /// As [`RobotModel::forward_kinematics`].
    pub fn fk(&self, X_WB: Pose, q: &[f64]) -> Result<KinematicState> {
        let mut state = KinematicState::new(self);
        state.X_WB = X_WB;
        self.forward_kinematics(q, &mut state)?;
        Ok(state)
    }

    /// The geometric Jacobian of the point `p_W` (in the world) rigidly attached to `link`,
    /// for the configuration that `state` was computed at. Mimic joints add their multiplier
    /// times their column to the coordinate they follow.
    ///
    /// `jacobian` must have [`RobotModel::dof`] columns; it is overwritten.
    pub fn point_jacobian(
        &self,
        state: &KinematicState,
        link: LinkId,
        p_W: Vector,
        jacobian: &mut Jacobian,
    ) {
        if jacobian.columns.len() != self.dof() {
            jacobian.columns.resize(self.dof(), [0.0; 6]);
        }
        jacobian.columns.fill([0.0; 6]);
        // Walk from the link to the root through the parent joints.
        let mut current = self.links[link].parent_joint;
        while let Some(j) = current {
            let joint = &self.joints[j];
            let (index, scale) = match joint.coordinate {
                Coordinate::None => (usize::MAX, 0.0),
                Coordinate::Own { index } => (index, 1.0),
                Coordinate::Mimic {
                    index, multiplier, ..
                } => (index, multiplier),
            };
            if index != usize::MAX {
                let a = state.axis_W[j];
                let col = &mut jacobian.columns[index];
                match joint.kind {
                    JointKind::Revolute | JointKind::Continuous => {
                        let v = a.cross(p_W - state.p_WJ[j]) * scale;
                        let w = a * scale;
                        col[0] += v.x;
                        col[1] += v.y;
                        col[2] += v.z;
                        col[3] += w.x;
                        col[4] += w.y;
                        col[5] += w.z;
                    }
                    JointKind::Prismatic => {
                        col[0] += a.x * scale;
                        col[1] += a.y * scale;
                        col[2] += a.z * scale;
                    }
                    JointKind::Fixed => {}
                }
            }
            current = self.links[joint.parent].parent_joint;
        }
    }

    /// The Jacobian of the origin of `link`'s frame; see [`RobotModel::point_jacobian`].
    #[must_use]
    pub fn link_jacobian(&self, state: &KinematicState, link: LinkId) -> Jacobian {
        let mut jacobian = Jacobian::zeros(self.dof());
        self.point_jacobian(
            state,
            link,
            state.link_pose(link).translation,
            &mut jacobian,
        );
        jacobian
    }
}
