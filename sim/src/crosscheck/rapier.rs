//! The rapier side of the cross-check: the robot alone in a world built exactly as the cell
//! builds it ([`build_robot`]), with the quantities MuJoCo is compared on.

use rapier3d_f64::na::DMatrix;
use rapier3d_f64::prelude::*;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{JointId, JointKind, RobotModel};

use super::PdLaw;
use crate::error::{Result, SimError};
use crate::multibody::{RobotBodies, build_robot};

pub(super) struct RapierRobot<'a> {
    robot: &'a RobotModel,
    world: PhysicsWorld,
    bodies: RobotBodies,
    /// The movable joints, in the robot's joint order (mimic joints included).
    pub(super) joints: Vec<JointId>,
}

fn physics(message: &str) -> SimError {
    SimError::Physics {
        message: message.to_string(),
    }
}

impl<'a> RapierRobot<'a> {
    /// The robot at rest at configuration `q`, base at the origin, gravity `g`, no servo.
    pub(super) fn new(robot: &'a RobotModel, q: &[f64], g: [f64; 3], dt: f64) -> Result<Self> {
        let mut world = PhysicsWorld::new();
        world.integration_parameters.dt = dt;
        let bodies = build_robot(&mut world, robot, Pose::IDENTITY, q, false)?;
        // One step without gravity, at rest, where nothing moves: rapier settles the
        // multibody's root (fixed) and the bodies' mass properties in its first step.
        world.gravity = Vector::ZERO;
        world.step();
        world.gravity = Vector::from_array(g);
        let joints = (0..robot.joints().len())
            .filter(|&j| bodies.joints[j].is_some())
            .collect();
        Ok(Self {
            robot,
            world,
            bodies,
            joints,
        })
    }

    /// Pose of link `l` in the world.
    pub(super) fn link_pose(&self, l: usize) -> Pose {
        let lb = self.bodies.links[l];
        self.world
            .bodies
            .get(lb.body)
            .map_or(Pose::IDENTITY, |b| *b.position() * lb.X_BL)
    }

    /// The multibody's DoF index of each movable joint.
    fn dofs(&self) -> Vec<usize> {
        self.joints
            .iter()
            .map(|&j| {
                self.bodies.joints[j]
                    .and_then(|c| self.world.multibody_joints.get(c.joint))
                    .and_then(|(mb, link)| mb.link(link))
                    .map_or(usize::MAX, |l| l.assembly_id())
            })
            .collect()
    }

    /// The joint-space mass matrix (row-major, joint order) from rapier's Jacobians and masses,
    /// and
    /// the gravity torques from rapier's free acceleration at rest in one step (of one
    /// substep): `tau_g = (M + dt D) qdd` (rapier makes joint damping D implicit). Steps the
    /// world.
    pub(super) fn mass_matrix_and_gravity(&mut self) -> (Vec<f64>, Vec<f64>) {
        let n = self.joints.len();
        let dofs = self.dofs();
        let Some(first) = self.bodies.joints.iter().flatten().next().map(|c| c.joint) else {
            return (Vec::new(), Vec::new());
        };
        let dt = self.world.integration_parameters.dt;
        let mass = {
            let PhysicsWorld {
                bodies,
                multibody_joints,
                ..
            } = &self.world;
            let Some((mb, _)) = multibody_joints.get(first) else {
                return (vec![f64::NAN; n * n], vec![f64::NAN; n]);
            };
            // M = sum over links of J^T diag(m, I_W) J, from the body Jacobians (centre-of-mass
            // velocity and angular velocity) and mass properties rapier integrates with.
            let nd = mb.ndofs();
            let mut mass = DMatrix::zeros(nd, nd);
            for (i, link) in mb.links().enumerate() {
                let Some(rb) = bodies.get(link.rigid_body_handle()) else {
                    continue;
                };
                let j = mb.body_jacobian(i);
                let props = &rb.mass_properties().local_mprops;
                let R = rb.position().rotation;
                let I_W = parry3d_f64::math::Matrix::from_quat(R)
                    * props.reconstruct_inertia_matrix()
                    * parry3d_f64::math::Matrix::from_quat(R.inverse());
                let I_W = rapier3d_f64::na::Matrix3::from_fn(|r, c| I_W.col(c)[r]);
                let jv = j.fixed_rows::<3>(0);
                let jw = j.fixed_rows::<3>(3);
                mass += props.mass() * jv.transpose() * jv + jw.transpose() * I_W * jw;
            }
            mass
        };
        // Rapier substeps (one per solver iteration) and recomputes the accelerations at each
        // substep's state; with one iteration, they are those of the state at rest.
        let iterations = self.world.integration_parameters.num_solver_iterations;
        self.world.integration_parameters.num_solver_iterations = 1;
        self.world.step();
        self.world.integration_parameters.num_solver_iterations = iterations;
        let Some((mb, _)) = self.world.multibody_joints.get(first) else {
            return (vec![f64::NAN; n * n], vec![f64::NAN; n]);
        };
        let qdd = mb.generalized_acceleration();
        let damping = mb.damping();
        let mut m = vec![0.0; n * n];
        let mut tau = vec![0.0; n];
        for (i, &a) in dofs.iter().enumerate() {
            for (j, &b) in dofs.iter().enumerate() {
                m[i * n + j] = mass[(a, b)];
            }
            tau[i] = (0..mass.ncols())
                .map(|b| (mass[(a, b)] + if a == b { dt * damping[a] } else { 0.0 }) * qdd[b])
                .sum();
        }
        (m, tau)
    }

    /// Positions and velocities of the movable joints.
    fn state(&self, q: &mut [f64], v: &mut [f64]) {
        for (i, &j) in self.joints.iter().enumerate() {
            let Some(c) = self.bodies.joints[j] else {
                continue;
            };
            if let Some((mb, link)) = self.world.multibody_joints.get(c.joint)
                && let Some(l) = mb.link(link)
            {
                q[i] = l.joint().coords()[c.coord];
                v[i] = mb.joint_velocity(l).get(0).copied().unwrap_or(0.0);
            }
        }
    }

    /// Runs `steps` steps under `law`, applied as explicit joint torques (equal and opposite
    /// on the two bodies of each joint); the joint positions after every step.
    pub(super) fn run(mut self, law: &PdLaw, steps: usize) -> Result<Vec<Vec<f64>>> {
        let n = self.joints.len();
        let dt = self.world.integration_parameters.dt;
        let (mut q, mut v, mut tau) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut path = Vec::with_capacity(steps);
        for k in 0..steps {
            self.state(&mut q, &mut v);
            law.torque(k as f64 * dt, &q, &v, &mut tau);
            self.apply_joint_torques(&tau)?;
            self.world.step();
            self.state(&mut q, &mut v);
            path.push(q.clone());
        }
        Ok(path)
    }

    fn apply_joint_torques(&mut self, tau: &[f64]) -> Result<()> {
        for lb in &self.bodies.links {
            if let Some(rb) = self.world.bodies.get_mut(lb.body) {
                rb.reset_forces(false);
                rb.reset_torques(false);
            }
        }
        for (i, &j) in self.joints.iter().enumerate() {
            let joint = &self.robot.joints()[j];
            let a_W = self.link_pose(joint.child).rotation * joint.axis;
            let child = self.bodies.links[joint.child].body;
            let parent = self.bodies.links[joint.parent].body;
            let missing = || physics("a joint's body is missing from the world");
            match joint.kind {
                JointKind::Prismatic => {
                    // The pair acts at one point, so it exerts no moment on the joints above.
                    let p = self
                        .world
                        .bodies
                        .get(child)
                        .ok_or_else(missing)?
                        .center_of_mass();
                    for (body, sign) in [(child, 1.0), (parent, -1.0)] {
                        let rb = self.world.bodies.get_mut(body).ok_or_else(missing)?;
                        rb.add_force_at_point(sign * tau[i] * a_W, p, false);
                    }
                }
                JointKind::Revolute | JointKind::Continuous => {
                    for (body, sign) in [(child, 1.0), (parent, -1.0)] {
                        let rb = self.world.bodies.get_mut(body).ok_or_else(missing)?;
                        rb.add_torque(sign * tau[i] * a_W, false);
                    }
                }
                JointKind::Fixed => {}
            }
        }
        Ok(())
    }
}
