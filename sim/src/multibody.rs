//! The robot as a rapier3d multibody: links joined by fixed joints share one rigid body, each
//! movable joint becomes a multibody joint with a motor, mimic joints become coupled
//! coordinates, effort limits become motor force limits.

use rapier3d_f64::prelude::*;
use workcell_robots::collision::geometry_shape;
use workcell_robots::math::{Pose, Rotation, Vector};
use workcell_robots::{Coordinate, JointKind, LinkId, RobotModel};

use crate::error::{Result, SimError};

/// How one robot link is represented in rapier.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LinkBody {
    pub(crate) body: RigidBodyHandle,
    /// Pose of the link in its body (identity unless merged through fixed joints).
    pub(crate) X_BL: Pose,
}

/// A robot coordinate in rapier: which multibody link and which axis.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CoordinateHandle {
    pub(crate) joint: MultibodyJointHandle,
    pub(crate) axis: JointAxis,
    /// Index into the joint's spatial coordinates (0 for LinX, 3 for AngX).
    pub(crate) coord: usize,
}

/// The robot in a rapier world.
#[derive(Debug, Clone)]
pub(crate) struct RobotBodies {
    /// The body of every link.
    pub(crate) links: Vec<LinkBody>,
    /// The multibody coordinate of every configuration coordinate (actuated joint).
    pub(crate) coordinates: Vec<CoordinateHandle>,
    /// The multibody coordinate of every joint (`None` for fixed joints), mimic joints included.
    #[cfg_attr(not(feature = "mujoco"), allow(dead_code))]
    pub(crate) joints: Vec<Option<CoordinateHandle>>,
}

/// Inserts the robot as a multibody: the body of every link, the rapier handle of every
/// coordinate. URDF joint damping becomes the multibody's per-DoF (implicit) damping. URDF dry
/// friction is left out: rapier's per-DoF friction constraint, measured against the joint
/// servos, held a 20,000 N m/rad servo 4 mrad off target with 0.1 N m of friction (a
/// dead band of 5 urad is what that friction should cause).
pub(crate) fn build_robot(
    world: &mut PhysicsWorld,
    robot: &RobotModel,
    X_WR: Pose,
    initial_q: &[f64],
    gravity_compensation: bool,
) -> Result<RobotBodies> {
    let fk = robot.fk(X_WR, initial_q).map_err(|e| SimError::Physics {
        message: e.to_string(),
    })?;
    // Each link's body: itself if its parent joint moves (or it is the root), else its parent's.
    let mut body_link: Vec<LinkId> = (0..robot.links().len()).collect();
    for joint in robot.joints() {
        if joint.kind == JointKind::Fixed {
            body_link[joint.child] = body_link[joint.parent];
        }
    }
    let mut bodies: Vec<Option<RigidBodyHandle>> = vec![None; robot.links().len()];
    let mut links = Vec::with_capacity(robot.links().len());
    for l in 0..robot.links().len() {
        let b = body_link[l];
        let X_WBody = *fk.link_pose(b);
        if bodies[b].is_none() {
            // Gravity compensation, as a robot controller does it: each link's weight is
            // carried exactly, so the servos only see motion and contacts.
            let builder = if b == robot.root() {
                RigidBodyBuilder::fixed()
            } else if gravity_compensation {
                RigidBodyBuilder::dynamic().gravity_scale(0.0)
            } else {
                RigidBodyBuilder::dynamic()
            };
            // Mass of the body: the inertials of every link merged into it.
            let parts: Vec<(f64, Pose, [f64; 6])> = robot
                .links()
                .iter()
                .enumerate()
                .filter(|&(m, _)| body_link[m] == b)
                .filter_map(|(m, link)| {
                    let i = link.inertial?;
                    let X_BI = X_WBody.inverse() * *fk.link_pose(m) * i.X_LI;
                    Some((i.mass_kg, X_BI, i.inertia_kgm2))
                })
                .collect();
            let mut mass = merged_mass_properties(&parts);
            if mass.mass() <= 0.0 && b != robot.root() {
                // A moving link without inertial: a small mass keeps the solver well posed.
                mass = MassProperties::new(Vector::ZERO, 0.01, Vector::splat(1e-5));
            }
            let handle = world.insert_body(
                builder
                    .pose(X_WBody)
                    .additional_mass_properties(mass)
                    .can_sleep(false),
            );
            bodies[b] = Some(handle);
        }
        let body = bodies[b].ok_or_else(|| SimError::Physics {
            message: "link without body".into(),
        })?;
        let X_BL = X_WBody.inverse() * *fk.link_pose(l);
        for g in &robot.links()[l].collisions {
            if let Some((X_LS, shape)) = geometry_shape(g) {
                // Massless, and placed through a one-part compound so that the collider sits
                // at the body origin: its mass properties are then exactly zero and rapier
                // keeps the body's own (an offset zero-mass collider makes rapier re-diagonalise
                // the body inertia with a 3x3 eigensolver that, below about 1e-5 kg m^2,
                // returns wrong principal axes).
                world.insert_collider(
                    ColliderBuilder::new(SharedShape::compound(vec![(X_BL * X_LS, shape)]))
                        .mass_properties(MassProperties::default()),
                    Some(body),
                );
            }
        }
        links.push(LinkBody { body, X_BL });
    }

    // Joints, parents before children; each movable joint connects two bodies.
    let mut joint_handles = vec![None; robot.joints().len()];
    let refused = |name: &str| SimError::Physics {
        message: format!("rapier refused joint '{name}'"),
    };
    for (j, joint) in robot.joints().iter().enumerate() {
        if joint.kind == JointKind::Fixed {
            continue;
        }
        let parent = links[joint.parent];
        let child = links[joint.child];
        // rapier's revolute joint turns about its local x axis, the prismatic slides along it:
        // rotate both joint frames so that x is the URDF axis.
        let basis = Pose::from_rotation(GenericJoint::complete_ang_frame(joint.axis));
        let (mask, axis, coord) = match joint.kind {
            JointKind::Prismatic => (JointAxesMask::LOCKED_PRISMATIC_AXES, JointAxis::LinX, 0),
            _ => (JointAxesMask::LOCKED_REVOLUTE_AXES, JointAxis::AngX, 3),
        };
        let mut builder = GenericJointBuilder::new(mask)
            .local_frame1(parent.X_BL * joint.X_PJ * basis)
            .local_frame2(basis)
            .contacts_enabled(false);
        let l = joint.limits;
        if joint.kind != JointKind::Continuous && l.lower.is_finite() && l.upper.is_finite() {
            builder = builder.limits(axis, [l.lower, l.upper]);
        }
        if l.effort > 0.0 && matches!(joint.coordinate, Coordinate::Own { .. }) {
            builder = builder.motor_max_force(axis, l.effort);
        }
        let handle = world
            .insert_multibody_joint(parent.body, child.body, builder.build())
            .ok_or_else(|| refused(&joint.name))?;
        joint_handles[j] = Some((handle, axis, coord));
    }

    let joints: Vec<Option<CoordinateHandle>> = joint_handles
        .iter()
        .map(|h| h.map(|(joint, axis, coord)| CoordinateHandle { joint, axis, coord }))
        .collect();
    let mut coordinates = Vec::with_capacity(robot.dof());
    for &j in robot.actuated_joints() {
        coordinates.push(joints[j].ok_or_else(|| refused(&robot.joints()[j].name))?);
    }

    // Initial configuration, mimic couplings, no self-contacts. A robot without movable
    // joints is rigid bodies only (fixed root, fixed-jointed links merged into it).
    let bodies_of = |links, coordinates, joints| RobotBodies {
        links,
        coordinates,
        joints,
    };
    let Some(&(first, _, _)) = joint_handles.iter().flatten().next() else {
        return Ok(bodies_of(links, coordinates, joints));
    };
    let Some((multibody, _)) = world.multibody_joints.get_mut(first) else {
        return Err(refused("first joint"));
    };
    multibody.set_self_contacts_enabled(false);
    let mut displacement = vec![0.0; multibody.ndofs()];
    let mut damping = vec![0.0; multibody.ndofs()];
    let mut couplings = Vec::new();
    for (j, joint) in robot.joints().iter().enumerate() {
        let Some((handle, _, coord)) = joint_handles[j] else {
            continue;
        };
        let Some((mb, link_id)) = world.multibody_joints.get(handle) else {
            continue;
        };
        let Some(link) = mb.link(link_id) else {
            continue;
        };
        displacement[link.assembly_id()] = joint.position(initial_q);
        damping[link.assembly_id()] = joint.damping;
        if let Coordinate::Mimic {
            index,
            multiplier,
            offset,
        } = joint.coordinate
        {
            let (src, _, src_coord) = joint_handles[robot.actuated_joints()[index]]
                .ok_or_else(|| refused(&joint.name))?;
            let (_, src_link) = world
                .multibody_joints
                .get(src)
                .ok_or_else(|| refused(&joint.name))?;
            couplings.push(MultibodyDofCoupling {
                link1: src_link,
                dof1: 0,
                axis1: src_coord,
                link2: link_id,
                dof2: 0,
                axis2: coord,
                coeff: multiplier,
                offset,
            });
        }
    }
    let PhysicsWorld {
        bodies,
        multibody_joints,
        ..
    } = world;
    if let Some((multibody, _)) = multibody_joints.get_mut(first) {
        for c in couplings {
            multibody.add_dof_coupling(c);
        }
        multibody.apply_displacements(&displacement);
        multibody.damping_mut().copy_from_slice(&damping);
        multibody.forward_kinematics(bodies, true);
        multibody.update_rigid_bodies(bodies, true);
    }
    Ok(bodies_of(links, coordinates, joints))
}

/// Mass properties of links merged into one body: each part is `(mass, pose of its centre-of-
/// mass frame in the body, inertia tensor about its centre of mass [ixx, ixy, ixz, iyy, iyz,
/// izz])`. The tensors are summed about the common centre of mass (parallel-axis theorem) and
/// the sum is diagonalised once, by an iterative symmetric eigensolver.
///
/// parry's `MassProperties::with_inertia_matrix` (also behind its `+`) uses a closed-form 3x3
/// eigensolver (glamx 0.3) that loses digits when principal moments nearly coincide and, for
/// tensors below about 1e-5 kg m^2, can return axes that do not match the moments (an absolute
/// 1e-20 threshold on squared cross products). The MuJoCo cross-check measured joint-space
/// mass matrices off by up to 2e-4 (relative) on vendor arms that way.
fn merged_mass_properties(parts: &[(f64, Pose, [f64; 6])]) -> MassProperties {
    use rapier3d_f64::na::{Matrix3, SymmetricEigen, Vector3};
    let total: f64 = parts.iter().map(|p| p.0).sum();
    if total <= 0.0 {
        return MassProperties::default();
    }
    let v3 = |v: Vector| Vector3::new(v.x, v.y, v.z);
    let com = parts
        .iter()
        .fold(Vector3::zeros(), |c, (m, X, _)| c + *m * v3(X.translation))
        / total;
    let mut tensor = Matrix3::zeros();
    for (m, X, [ixx, ixy, ixz, iyy, iyz, izz]) in parts {
        let R = Matrix3::from_fn(|r, c| {
            let col = X.rotation * [Vector::X, Vector::Y, Vector::Z][c];
            col.to_array()[r]
        });
        let I = Matrix3::new(*ixx, *ixy, *ixz, *ixy, *iyy, *iyz, *ixz, *iyz, *izz);
        let d = v3(X.translation) - com;
        tensor +=
            R * I * R.transpose() + *m * (Matrix3::identity() * d.dot(&d) - d * d.transpose());
    }
    let eigen = SymmetricEigen::new(tensor);
    let mut axes = eigen.eigenvectors;
    let mut moments = eigen.eigenvalues;
    if axes.determinant() < 0.0 {
        axes.swap_columns(1, 2);
        moments.swap_rows(1, 2);
    }
    let frame = Rotation::from_mat3(&parry3d_f64::math::Matrix::from_cols_array(&[
        axes[(0, 0)],
        axes[(1, 0)],
        axes[(2, 0)],
        axes[(0, 1)],
        axes[(1, 1)],
        axes[(2, 1)],
        axes[(0, 2)],
        axes[(1, 2)],
        axes[(2, 2)],
    ]))
    .normalize();
    let principal = Vector::new(
        moments[0].max(0.0),
        moments[1].max(0.0),
        moments[2].max(0.0),
    );
    MassProperties::with_principal_inertia_frame(
        Vector::new(com.x, com.y, com.z),
        total,
        principal,
        frame,
    )
}

/// What [`check_in_rapier`] found.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RapierCheck {
    pub rigid_bodies: usize,
    pub colliders: usize,
    pub multibody_dofs: usize,
    /// Largest distance between rapier's link origins and forward kinematics at `q`, m.
    pub fk_mismatch_m: f64,
    /// Largest joint error after holding `q` for one second under gravity, rad or m.
    pub hold_error: f64,
}

/// Loads `robot` alone into a rapier world (base fixed at the origin, gravity on), checks that
/// rapier's link poses agree with forward kinematics at `q`, then holds `q` with the joint
/// servos for one second.
///
/// # Errors
/// [`SimError::InvalidCommand`] when `q` does not fit, [`SimError::Physics`] when rapier
/// refuses the joint tree.
pub fn check_in_rapier(robot: &RobotModel, q: &[f64]) -> Result<RapierCheck> {
    robot
        .check_configuration(q)
        .map_err(|e| SimError::InvalidCommand {
            message: e.to_string(),
        })?;
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::new(0.0, 0.0, -9.81);
    world.integration_parameters.dt = 0.001;
    // Without gravity compensation: the hold error then shows how well the servos and effort
    // limits carry the robot's own weight.
    let RobotBodies {
        links, coordinates, ..
    } = build_robot(&mut world, robot, Pose::IDENTITY, q, false)?;
    let fk = robot
        .fk(Pose::IDENTITY, q)
        .map_err(|e| SimError::InvalidCommand {
            message: e.to_string(),
        })?;
    let pose_of = |world: &PhysicsWorld, l: usize| {
        world
            .bodies
            .get(links[l].body)
            .map_or(Pose::IDENTITY, |b| *b.position() * links[l].X_BL)
    };
    let fk_mismatch_m = (0..links.len())
        .map(|l| (pose_of(&world, l).translation - fk.link_pose(l).translation).length())
        .fold(0.0, f64::max);
    let defaults = crate::scenario::RobotConfig::default();
    for _ in 0..1000 {
        for (i, c) in coordinates.iter().enumerate() {
            if let Some((mb, link)) = world.multibody_joints.get_mut(c.joint)
                && let Some(link) = mb.link_mut(link)
            {
                link.joint
                    .data
                    .set_motor(c.axis, q[i], 0.0, defaults.stiffness, defaults.damping);
            }
        }
        world.step();
    }
    let mut hold_error = 0.0_f64;
    for (i, c) in coordinates.iter().enumerate() {
        if let Some((mb, link)) = world.multibody_joints.get(c.joint)
            && let Some(l) = mb.link(link)
        {
            hold_error = hold_error.max((l.joint().coords()[c.coord] - q[i]).abs());
        }
    }
    let multibody_dofs = coordinates
        .first()
        .and_then(|c| world.multibody_joints.get(c.joint))
        .map_or(0, |(mb, _)| mb.ndofs());
    Ok(RapierCheck {
        rigid_bodies: world.bodies.len(),
        colliders: world.colliders.len(),
        multibody_dofs,
        fk_mismatch_m,
        hold_error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_mass_properties_reproduce_the_summed_tensor() {
        // Two links 0.3 m apart, one with a full tensor, one rotated: the result, rebuilt from
        // its principal frame, must equal the tensor summed by hand about the common centre.
        let a = (
            2.0,
            Pose::from_translation(Vector::new(0.1, 0.0, 0.0)),
            [
                0.012516, -0.000428, -0.001196, 0.010027, -0.000741, 0.004815,
            ],
        );
        let rot = Rotation::from_axis_angle(Vector::new(1.0, 2.0, 3.0).normalize(), 0.7);
        let b = (
            0.5,
            Pose::from_parts(Vector::new(0.1, 0.3, 0.0), rot),
            [0.003, 0.0, 0.0, 0.002, 0.0, 0.001],
        );
        let mp = merged_mass_properties(&[a, b]);
        assert!((mp.mass() - 2.5).abs() < 1e-15);
        let com = mp.local_com;
        assert!((com - Vector::new(0.1, 0.06, 0.0)).length() < 1e-15);
        let got = mp.reconstruct_inertia_matrix();
        // By hand: b's tensor rotated, plus both parallel-axis terms about (0.1, 0.06, 0).
        let Rb = parry3d_f64::math::Matrix::from_quat(rot);
        let Ib = Rb
            * parry3d_f64::math::Matrix::from_diagonal(Vector::new(0.003, 0.002, 0.001))
            * Rb.transpose();
        let Ia = parry3d_f64::math::Matrix::from_cols_array(&[
            0.012516, -0.000428, -0.001196, -0.000428, 0.010027, -0.000741, -0.001196, -0.000741,
            0.004815,
        ]);
        let shift = |m: f64, d: Vector| {
            m * (parry3d_f64::math::Matrix::IDENTITY * d.dot(d)
                - parry3d_f64::math::Matrix::from_cols(d * d.x, d * d.y, d * d.z))
        };
        let want = Ia
            + Ib
            + shift(2.0, Vector::new(0.0, -0.06, 0.0))
            + shift(0.5, Vector::new(0.0, 0.24, 0.0));
        let err = (got - want)
            .abs()
            .to_cols_array()
            .iter()
            .fold(0.0_f64, |m, x| m.max(*x));
        assert!(err < 1e-16, "inertia off by {err:e}");
    }
}
