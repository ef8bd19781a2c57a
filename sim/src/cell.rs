//! The simulated work-cell: an immutable [`CellModel`] built from a scenario and a mutable
//! [`CellState`] advanced by [`step`], like MuJoCo's `mjModel`/`mjData`.
//!
//! The robot is a rapier3d multibody (reduced coordinates) whose joints carry motors for
//! position or velocity control, with the URDF's position limits, effort limits as motor
//! force limits, and mimic joints as coupled coordinates. Links joined by fixed joints share
//! one rigid body. The human arm's links are kinematic bodies moved along the seeded human
//! motion; clutter is fixed.

use std::path::Path;

use rapier3d_f64::prelude::*;
use workcell_robots::collision::geometry_shape;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{KinematicState, LinkId, PackageMap, RobotModel};

use crate::clutter::{ClutterBox, clutter_boxes};
use crate::error::{Result, SimError};
use crate::human::HumanMotion;
use crate::multibody::{CoordinateHandle, LinkBody, RobotBodies, build_robot};
use crate::planning::plan_robot_motion;
use crate::scenario::Scenario;
use crate::trajectory::JointTrajectory;

/// Everything about a cell that does not change while it runs.
#[derive(Debug, Clone)]
pub struct CellModel {
    pub scenario: Scenario,
    pub robot: RobotModel,
    pub human: RobotModel,
    /// Robot base (root link) in the world.
    pub X_WR: Pose,
    /// Human torso (root link) in the world.
    pub X_WH: Pose,
    pub initial_q: Vec<f64>,
    /// The robot's nominal motion (what [`RobotCommand::Nominal`] follows).
    pub robot_motion: JointTrajectory,
    pub human_motion: HumanMotion,
    pub clutter: Vec<ClutterBox>,
    /// The link that task waypoints refer to.
    pub tool_link: LinkId,
}

/// What the robot is told to do during one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RobotCommand<'a> {
    /// Follow the model's nominal trajectory.
    Nominal,
    /// Track joint positions with feed-forward joint velocities.
    Position { q: &'a [f64], qd: &'a [f64] },
    /// Track joint velocities.
    Velocity { qd: &'a [f64] },
}

impl CellModel {
    /// Builds the cell of `scenario`; `scenario_path` anchors relative URDF paths and names
    /// the file in errors.
    ///
    /// # Errors
    /// [`SimError`] when a model fails to load, the initial configuration does not fit the
    /// robot, or the motion cannot be planned (unreachable waypoint, no waypoint above
    /// `min_height_m`).
    pub fn new(scenario: &Scenario, scenario_path: &Path) -> Result<Self> {
        scenario.validate().map_err(|e| e.in_file(scenario_path))?;
        let load = |key: &str, model: &str| {
            let name = Scenario::resolve_model_path(model, scenario_path);
            RobotModel::load(&name, &PackageMap::from_env()).map_err(|source| SimError::Robot {
                path: scenario_path.to_path_buf(),
                key: key.to_string(),
                source: Box::new(source),
            })
        };
        let robot = load("robot.model", &scenario.robot.model)?;
        let mut human = load("human.model", &scenario.human.model)?;
        let look = scenario.human.look;
        human.retain_visuals(|g| look.shows(g.name.as_deref()));
        let invalid = |key: &str, message: String| SimError::Invalid {
            path: Some(scenario_path.to_path_buf()),
            key: key.to_string(),
            message,
        };
        if robot.dof() == 0 {
            return Err(invalid(
                "robot.model",
                format!("robot '{}' has no movable joint", robot.name()),
            ));
        }
        let tool_link = robot.link_id(&scenario.robot.tool_link).ok_or_else(|| {
            invalid(
                "robot.tool_link",
                format!(
                    "robot '{}' has no link '{}'",
                    robot.name(),
                    scenario.robot.tool_link
                ),
            )
        })?;
        let limits = robot.position_limits();
        let initial_q = if scenario.robot.initial_q.is_empty() {
            robot.neutral_configuration()
        } else {
            scenario.robot.initial_q.clone()
        };
        if initial_q.len() != robot.dof() {
            return Err(invalid(
                "robot.initial_q",
                format!(
                    "has {} values, robot '{}' has {} joints",
                    initial_q.len(),
                    robot.name(),
                    robot.dof()
                ),
            ));
        }
        for (i, (q, [lo, hi])) in initial_q.iter().zip(&limits).enumerate() {
            if q < lo || q > hi {
                return Err(invalid(
                    "robot.initial_q",
                    format!("joint {i}: {q} is outside [{lo}, {hi}]"),
                ));
            }
        }
        let X_WR = scenario.robot.base.to_pose();
        let X_WH = scenario.human.base.to_pose();
        let clutter: Vec<ClutterBox> = scenario.clutter.iter().flat_map(clutter_boxes).collect();
        let robot_motion = plan_robot_motion(
            scenario,
            scenario_path,
            &robot,
            X_WR,
            tool_link,
            &initial_q,
            &clutter,
        )?;
        let human_motion = match &scenario.human.recorded {
            Some(recorded) => recorded_motion(recorded, scenario.seed, scenario_path, &human)?,
            None => HumanMotion::generate(
                &scenario.human.motions,
                scenario.human.shuffle,
                &human,
                scenario.human.peak_speed_range_m_s(),
                scenario.human.duration_scale_range(),
                scenario.seed,
            ),
        }
        .with_speed(scenario.human.speed_scale);
        tracing::info!(
            robot = robot.name(),
            human = human.name(),
            robot_period_s = robot_motion.period_s(),
            human_period_s = human_motion.period_s(),
            clutter_boxes = clutter.len(),
            "cell built"
        );
        Ok(Self {
            scenario: scenario.clone(),
            robot,
            human,
            X_WR,
            X_WH,
            initial_q,
            robot_motion,
            human_motion,
            clutter,
            tool_link,
        })
    }

    /// Reads a scenario file and builds its cell.
    ///
    /// # Errors
    /// As [`Scenario::from_file`] and [`CellModel::new`].
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::new(&Scenario::from_file(path)?, path)
    }

    /// Physics time step, s.
    #[must_use]
    pub fn time_step_s(&self) -> f64 {
        self.scenario.time_step_s
    }
}

/// Everything about a cell that changes while it runs.
pub struct CellState {
    world: PhysicsWorld,
    time_s: f64,
    steps: u64,
    robot_links: Vec<LinkBody>,
    coordinates: Vec<CoordinateHandle>,
    human_bodies: Vec<Option<RigidBodyHandle>>,
    human_kinematics: KinematicState,
    q: Vec<f64>,
    qd: Vec<f64>,
    human_q: Vec<f64>,
    human_qd: Vec<f64>,
    // Scratch for the nominal command.
    nominal: [Vec<f64>; 3],
    /// Position and velocity reference of each servo: they follow position commands within
    /// the joint's velocity limit and the servo acceleration limit.
    reference_q: Vec<f64>,
    reference_qd: Vec<f64>,
}

impl std::fmt::Debug for CellState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CellState")
            .field("time_s", &self.time_s)
            .field("steps", &self.steps)
            .field("q", &self.q)
            .field("human_q", &self.human_q)
            .finish_non_exhaustive()
    }
}

impl CellState {
    /// The cell at t = 0: robot at its initial configuration, human at the start of its motion.
    ///
    /// # Errors
    /// [`SimError::Physics`] if rapier refuses the robot's joint tree (a bug, reported
    /// rather than a panic).
    pub fn new(model: &CellModel) -> Result<Self> {
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::from_array(model.scenario.gravity_m_s2);
        world.integration_parameters.dt = model.scenario.time_step_s;

        // Clutter: fixed boxes.
        for c in &model.clutter {
            let [hx, hy, hz] = c.half_extents_m;
            world.insert_collider(ColliderBuilder::cuboid(hx, hy, hz).position(c.X_WC), None);
        }

        let RobotBodies {
            links: robot_links,
            coordinates,
            ..
        } = build_robot(
            &mut world,
            &model.robot,
            model.X_WR,
            &model.initial_q,
            model.scenario.robot.gravity_compensation,
        )?;

        // Human: one kinematic body per link with collision geometry.
        let human = &model.human;
        let mut human_kinematics = KinematicState::new(human);
        human_kinematics.X_WB = model.X_WH;
        let mut human_q = vec![0.0; human.dof()];
        let mut human_qd = vec![0.0; human.dof()];
        model.human_motion.sample(0.0, &mut human_q, &mut human_qd);
        human
            .forward_kinematics(&human_q, &mut human_kinematics)
            .map_err(|e| SimError::Physics {
                message: e.to_string(),
            })?;
        let mut human_bodies = Vec::with_capacity(human.links().len());
        for (l, link) in human.links().iter().enumerate() {
            let shapes: Vec<_> = link.collisions.iter().filter_map(geometry_shape).collect();
            if shapes.is_empty() {
                human_bodies.push(None);
                continue;
            }
            let body = world.insert_body(
                RigidBodyBuilder::kinematic_position_based()
                    .pose(*human_kinematics.link_pose(l))
                    .can_sleep(false),
            );
            for (X_LS, shape) in shapes {
                // Sensors: the human's geometry is there for distance queries, but a
                // kinematic arm must not shove the robot (a real one would be hurt first;
                // keeping the separation is the safety filter's job).
                world.insert_collider(
                    ColliderBuilder::new(shape)
                        .position(X_LS)
                        .density(0.0)
                        .sensor(true),
                    Some(body),
                );
            }
            human_bodies.push(Some(body));
        }

        let dof = model.robot.dof();
        let mut state = Self {
            world,
            time_s: 0.0,
            steps: 0,
            robot_links,
            coordinates,
            human_bodies,
            human_kinematics,
            q: model.initial_q.clone(),
            qd: vec![0.0; dof],
            human_q,
            human_qd,
            nominal: [vec![0.0; dof], vec![0.0; dof], vec![0.0; dof]],
            reference_q: model.initial_q.clone(),
            reference_qd: vec![0.0; dof],
        };
        state.read_robot();
        Ok(state)
    }

    /// Simulated time, s.
    #[must_use]
    pub fn time_s(&self) -> f64 {
        self.time_s
    }
    /// Number of steps taken.
    #[must_use]
    pub fn steps(&self) -> u64 {
        self.steps
    }
    /// Robot joint positions (measured, after the last step).
    #[must_use]
    pub fn q(&self) -> &[f64] {
        &self.q
    }
    /// Robot joint velocities.
    #[must_use]
    pub fn qd(&self) -> &[f64] {
        &self.qd
    }
    /// The position servos' reference: where the servo's rate- and acceleration-limited
    /// chase of the last position command has got to (equal to `q` after a velocity command).
    #[must_use]
    pub fn reference_q(&self) -> &[f64] {
        &self.reference_q
    }
    /// Human joint positions.
    #[must_use]
    pub fn human_q(&self) -> &[f64] {
        &self.human_q
    }
    /// Human joint velocities.
    #[must_use]
    pub fn human_qd(&self) -> &[f64] {
        &self.human_qd
    }

    /// Ground truth: pose of robot link `link` in the world, from the physics.
    #[must_use]
    pub fn robot_link_pose(&self, link: LinkId) -> Pose {
        let lb = self.robot_links[link];
        self.world
            .bodies
            .get(lb.body)
            .map_or(Pose::IDENTITY, |b| *b.position() * lb.X_BL)
    }

    /// Ground truth: poses of all robot links, indexed by [`LinkId`].
    #[must_use]
    pub fn robot_link_poses(&self) -> Vec<Pose> {
        (0..self.robot_links.len())
            .map(|l| self.robot_link_pose(l))
            .collect()
    }

    /// Ground truth: poses of all human links, indexed by the human model's [`LinkId`].
    #[must_use]
    pub fn human_link_poses(&self) -> &[Pose] {
        self.human_kinematics.link_poses()
    }

    /// The rapier world, for queries (read only).
    #[must_use]
    pub fn world(&self) -> &PhysicsWorld {
        &self.world
    }

    fn read_robot(&mut self) {
        for (i, c) in self.coordinates.iter().enumerate() {
            if let Some((mb, link)) = self.world.multibody_joints.get(c.joint)
                && let Some(l) = mb.link(link)
            {
                self.q[i] = l.joint().coords()[c.coord];
                self.qd[i] = mb.joint_velocity(l).get(0).copied().unwrap_or(0.0);
            }
        }
    }
}

/// Advances the cell by one time step under `command`.
///
/// Position targets are clamped to the joint ranges and velocities to the velocity limits;
/// velocity commands are also limited so that one step cannot cross a position limit.
///
/// # Errors
/// [`SimError::InvalidCommand`] when a command has the wrong length or a non-finite value.
pub fn step(model: &CellModel, state: &mut CellState, command: &RobotCommand<'_>) -> Result<()> {
    let robot = &model.robot;
    let dof = robot.dof();
    let dt = model.scenario.time_step_s;
    let (stiffness, damping) = (model.scenario.robot.stiffness, model.scenario.robot.damping);
    let check = |name: &str, v: &[f64]| -> Result<()> {
        if v.len() != dof {
            return Err(SimError::InvalidCommand {
                message: format!("{name} has {} values, the robot {dof} joints", v.len()),
            });
        }
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(SimError::InvalidCommand {
                message: format!("{name}[{i}] is {}", v[i]),
            });
        }
        Ok(())
    };
    // Motor targets.
    let mut nominal = std::mem::take(&mut state.nominal);
    let (targets, mode_velocity): ((&[f64], &[f64]), bool) = match command {
        RobotCommand::Nominal => {
            let [q, qd, qdd] = &mut nominal;
            model.robot_motion.sample(state.time_s + dt, q, qd, qdd);
            ((q.as_slice(), qd.as_slice()), false)
        }
        RobotCommand::Position { q, qd } => {
            check("q", q)?;
            check("qd", qd)?;
            ((*q, *qd), false)
        }
        RobotCommand::Velocity { qd } => {
            check("qd", qd)?;
            ((*qd, *qd), true)
        }
    };
    for (i, c) in state.coordinates.iter().enumerate() {
        let joint = &robot.joints()[robot.actuated_joints()[i]];
        let l = joint.limits;
        let v_max = if l.velocity > 0.0 {
            l.velocity
        } else {
            f64::INFINITY
        };
        let Some((mb, link)) = state.world.multibody_joints.get_mut(c.joint) else {
            continue;
        };
        let Some(link) = mb.link_mut(link) else {
            continue;
        };
        if mode_velocity {
            let q = state.q[i];
            state.reference_q[i] = q;
            state.reference_qd[i] = state.qd[i];
            let v = targets.1[i]
                .clamp(-v_max, v_max)
                .clamp((l.lower - q) / dt, (l.upper - q) / dt);
            link.joint.data.set_motor(c.axis, q, v, 0.0, damping);
        } else {
            // The servo reference chases the command with bounded velocity and acceleration
            // (braking in time: |v| <= sqrt(2 a |e|)), so a jump in the command cannot drive
            // the joint beyond its limits; on a smooth command it rides the feed-forward.
            let a_max = if l.acceleration.is_finite() && l.acceleration > 0.0 {
                l.acceleration
            } else {
                model.scenario.robot.servo_acceleration_rad_s2
            };
            let goal = targets.0[i].clamp(l.lower, l.upper);
            let (r, rd) = (&mut state.reference_q[i], &mut state.reference_qd[i]);
            let e = goal - *r;
            let approach = (2.0 * a_max * e.abs()).sqrt().min(e.abs() / dt);
            let v_wanted = (targets.1[i] + e.signum() * approach).clamp(-v_max, v_max);
            *rd += (v_wanted - *rd).clamp(-a_max * dt, a_max * dt);
            *r += *rd * dt;
            // A PD servo solved implicitly by rapier. Without gravity compensation, gravity
            // leaves a steady error of (gravity acceleration of the joint) / stiffness, ~2 mrad
            // at the default gains.
            link.joint
                .data
                .set_motor(c.axis, *r, *rd, stiffness, damping);
        }
    }
    state.nominal = nominal;

    // Human: kinematic bodies to their poses at the end of the step.
    let t_next = state.time_s + dt;
    model
        .human_motion
        .sample(t_next, &mut state.human_q, &mut state.human_qd);
    model
        .human
        .forward_kinematics(&state.human_q, &mut state.human_kinematics)
        .map_err(|e| SimError::Physics {
            message: e.to_string(),
        })?;
    for (l, body) in state.human_bodies.iter().enumerate() {
        if let Some(body) = body
            && let Some(rb) = state.world.bodies.get_mut(*body)
        {
            rb.set_next_kinematic_position(*state.human_kinematics.link_pose(l));
        }
    }

    state.world.step();
    state.time_s = t_next;
    state.steps += 1;
    state.read_robot();
    Ok(())
}

/// The library of `recorded` (relative to the folder of `path`, the file that names it as
/// `key`) and the clips it plays, in order: `clips` by id, else every clip of `split`.
///
/// # Errors
/// The library's, or [`SimError::Invalid`] naming `{key}.clips` for an id it lacks.
pub(crate) fn chosen_clips(
    recorded: &crate::scenario::RecordedConfig,
    key: &str,
    path: &Path,
) -> Result<(workcell_mocap::library::Library, Vec<usize>)> {
    use crate::scenario::ClipSplit;
    use workcell_mocap::library::{Library, Split};
    let dir = path.parent().unwrap_or(Path::new("."));
    let library = Library::from_file(&dir.join(&recorded.library))?;
    let chosen = if recorded.clips.is_empty() {
        let split = match recorded.split {
            ClipSplit::Tuning => Some(Split::Tuning),
            ClipSplit::Test => Some(Split::Test),
            ClipSplit::All => None,
        };
        (0..library.clips.len())
            .filter(|&k| split.is_none_or(|s| library.clips[k].split == s))
            .collect()
    } else {
        recorded
            .clips
            .iter()
            .map(|id| {
                library
                    .clips
                    .iter()
                    .position(|c| &c.id == id)
                    .ok_or_else(|| SimError::Invalid {
                        path: Some(path.to_path_buf()),
                        key: format!("{key}.clips"),
                        message: format!("{id:?} is not a clip of {}", library.path.display()),
                    })
            })
            .collect::<Result<_>>()?
    };
    Ok((library, chosen))
}

/// The clip the episode of `seed` plays (`[human.recorded]`), retargeted onto `human`.
fn recorded_motion(
    recorded: &crate::scenario::RecordedConfig,
    seed: u64,
    scenario_path: &Path,
    human: &RobotModel,
) -> Result<HumanMotion> {
    let (library, chosen) = chosen_clips(recorded, "human.recorded", scenario_path)?;
    let n = chosen.len().max(1) as u64;
    let Some(clip) = chosen
        .get((seed.wrapping_sub(1) % n) as usize)
        .map(|&k| &library.clips[k])
    else {
        return Err(SimError::Invalid {
            path: Some(scenario_path.to_path_buf()),
            key: "human.recorded".into(),
            message: format!("no clips to play in {}", library.path.display()),
        });
    };
    let (motion, report) = crate::retarget::retarget(&clip.read()?, human, &recorded.retarget)
        .map_err(|e| e.in_file(scenario_path))?;
    tracing::info!(
        clip = clip.id,
        frames = report.frames,
        wrist_error_median_m = report.wrist_error_m.median,
        "recorded human motion"
    );
    Ok(HumanMotion::recorded(
        motion,
        recorded.start_s,
        recorded.end,
    ))
}
