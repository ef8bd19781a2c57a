//! The robot as a rapier3d multibody: links joined by fixed joints share one rigid body, each
//! movable joint becomes a multibody joint with a motor, mimic joints become coupled
//! coordinates, effort limits become motor force limits.

use rapier3d_f64::prelude::*;
use workcell_robots::collision::geometry_shape;
use workcell_robots::math::{Pose, Vector};
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

/// Inserts the robot as a multibody; returns the body of every link and the rapier handle of
/// every coordinate.
pub(crate) fn build_robot(
    world: &mut PhysicsWorld,
    robot: &RobotModel,
    X_WR: Pose,
    initial_q: &[f64],
    gravity_compensation: bool,
) -> Result<(Vec<LinkBody>, Vec<CoordinateHandle>)> {
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
            let mut mass = MassProperties::default();
            for (m, link) in robot.links().iter().enumerate() {
                if body_link[m] != b {
                    continue;
                }
                if let Some(i) = link.inertial {
                    let [ixx, ixy, ixz, iyy, iyz, izz] = i.inertia_kgm2;
                    let inertia = parry3d_f64::math::Matrix::from_cols_array(&[
                        ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz,
                    ]);
                    let X_BI = X_WBody.inverse() * *fk.link_pose(m) * i.X_LI;
                    mass += MassProperties::with_inertia_matrix(Vector::ZERO, i.mass_kg, inertia)
                        .transform_by(&X_BI);
                }
            }
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
                world.insert_collider(
                    ColliderBuilder::new(shape)
                        .position(X_BL * X_LS)
                        .density(0.0),
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

    let mut coordinates = Vec::with_capacity(robot.dof());
    for &j in robot.actuated_joints() {
        let (joint, axis, coord) =
            joint_handles[j].ok_or_else(|| refused(&robot.joints()[j].name))?;
        coordinates.push(CoordinateHandle { joint, axis, coord });
    }

    // Initial configuration, mimic couplings, no self-contacts. A robot without movable
    // joints is rigid bodies only (fixed root, fixed-jointed links merged into it).
    let Some(&(first, _, _)) = joint_handles.iter().flatten().next() else {
        return Ok((links, coordinates));
    };
    let Some((multibody, _)) = world.multibody_joints.get_mut(first) else {
        return Err(refused("first joint"));
    };
    multibody.set_self_contacts_enabled(false);
    let mut displacement = vec![0.0; multibody.ndofs()];
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
        multibody.forward_kinematics(bodies, true);
        multibody.update_rigid_bodies(bodies, true);
    }
    Ok((links, coordinates))
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
    let (links, coordinates) = build_robot(&mut world, robot, Pose::IDENTITY, q, false)?;
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
