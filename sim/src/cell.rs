//! The simulated work-cell: an immutable [`CellModel`] built from a scenario and a mutable
//! [`CellState`] advanced by [`step`], like MuJoCo's `mjModel`/`mjData`.
//!
//! The robot is a rapier3d multibody (reduced coordinates) whose joints carry motors for
//! position or velocity control, with the URDF's position limits, effort limits as motor
//! force limits, and mimic joints as coupled coordinates. Links joined by fixed joints share
//! one rigid body. The human arm's links are kinematic bodies moved along the seeded human
//! motion; clutter is fixed.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rapier3d_f64::prelude::*;
use workcell_robots::collision::{geometry_shape, link_collision_shape};
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{Coordinate, JointKind, KinematicState, LinkId, PackageMap, RobotModel};

use std::path::Path;

use crate::error::{Result, SimError};
use crate::human::HumanMotion;
use crate::ik::{IkOptions, solve_ik, tool_down};
use crate::scenario::{ClutterKind, RobotMotionConfig, Scenario};
use crate::trajectory::JointTrajectory;

/// A static box of the clutter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClutterBox {
    /// Pose of the box centre in the world.
    pub X_WC: Pose,
    /// Half extents, m.
    pub half_extents_m: [f64; 3],
}

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
        scenario.validate(scenario_path)?;
        let load = |key: &str, model: &str| {
            let name = Scenario::resolve_model_path(model, scenario_path);
            RobotModel::load(&name, &PackageMap::from_env()).map_err(|source| SimError::Robot {
                path: scenario_path.to_path_buf(),
                key: key.to_string(),
                source: Box::new(source),
            })
        };
        let robot = load("robot.model", &scenario.robot.model)?;
        let human = load("human.model", &scenario.human.model)?;
        let invalid = |key: &str, message: String| SimError::Invalid {
            path: scenario_path.to_path_buf(),
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
        let robot_motion =
            plan_robot_motion(scenario, scenario_path, &robot, X_WR, tool_link, &initial_q)?;
        let human_motion = HumanMotion::generate(
            &scenario.human.motions,
            scenario.human.shuffle,
            &human.position_limits(),
            scenario.seed,
        );
        let clutter: Vec<ClutterBox> = scenario.clutter.iter().flat_map(clutter_boxes).collect();
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

/// Joint-space motion of the robot from the scenario.
fn plan_robot_motion(
    scenario: &Scenario,
    path: &Path,
    robot: &RobotModel,
    X_WR: Pose,
    tool_link: LinkId,
    initial_q: &[f64],
) -> Result<JointTrajectory> {
    let limits = robot.position_limits();
    let velocity = robot.velocity_limits();
    let acceleration_of = |fallback: f64| -> Vec<f64> {
        robot
            .actuated_joints()
            .iter()
            .map(|&j| {
                let a = robot.joints()[j].limits.acceleration;
                if a.is_finite() && a > 0.0 {
                    a
                } else {
                    fallback
                }
            })
            .collect()
    };
    let scaled = |scale: f64| -> Vec<f64> {
        velocity
            .iter()
            .map(|v| if *v > 0.0 { v * scale } else { scale })
            .collect()
    };
    match &scenario.robot.motion {
        RobotMotionConfig::Hold => Ok(JointTrajectory::hold(initial_q)),
        RobotMotionConfig::Random {
            speed_scale,
            acceleration_rad_s2,
            margin_rad,
            min_height_m,
            clearance_m,
            waypoints,
        } => {
            let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
            let mut workspace = Workspace::new(
                robot,
                X_WR,
                tool_link,
                initial_q,
                scenario,
                *min_height_m,
                *clearance_m,
            );
            let mut points = vec![initial_q.to_vec()];
            while points.len() < *waypoints {
                let last = points.last().cloned().unwrap_or_default();
                let is_last = points.len() + 1 == *waypoints;
                let found = (0..1000).find_map(|_| {
                    let q: Vec<f64> = limits
                        .iter()
                        .map(|[lo, hi]| {
                            // Continuous and +-2 pi joints: one turn either way is enough.
                            let (lo, hi) = (
                                lo.max(-std::f64::consts::PI) + margin_rad,
                                hi.min(std::f64::consts::PI) - margin_rad,
                            );
                            if lo < hi {
                                rng.random_range(lo..hi)
                            } else {
                                0.5 * (lo + hi)
                            }
                        })
                        .collect();
                    (workspace.line_clear(&last, &q)
                        && (!is_last || workspace.line_clear(&q, initial_q)))
                    .then_some(q)
                });
                match found {
                    Some(q) => points.push(q),
                    None => {
                        return Err(SimError::Invalid {
                            path: path.to_path_buf(),
                            key: "robot.motion".into(),
                            message: format!(
                                "no random waypoint keeps every link above {min_height_m} m and {clearance_m} m \
                                 from the clutter after 1000 tries; lower them or move the robot"
                            ),
                        });
                    }
                }
            }
            Ok(JointTrajectory::through(
                &points,
                &scaled(*speed_scale),
                &acceleration_of(*acceleration_rad_s2),
                0.0,
            ))
        }
        RobotMotionConfig::PickAndPlace {
            waypoints,
            dwell_s,
            speed_scale,
            acceleration_rad_s2,
        } => {
            let mut seed = initial_q.to_vec();
            let mut points = Vec::with_capacity(waypoints.len());
            let mut rng = ChaCha8Rng::seed_from_u64(scenario.seed);
            for (i, p) in waypoints.iter().enumerate() {
                let target = tool_down(Vector::from_array(*p));
                let mut best =
                    solve_ik(robot, X_WR, tool_link, target, &seed, &IkOptions::default());
                // Random restarts around the seed when the nearest solution is not found.
                for _ in 0..20 {
                    if best.converged {
                        break;
                    }
                    let restart: Vec<f64> = seed
                        .iter()
                        .zip(&limits)
                        .map(|(q, [lo, hi])| (q + rng.random_range(-1.0..1.0)).clamp(*lo, *hi))
                        .collect();
                    let sol = solve_ik(
                        robot,
                        X_WR,
                        tool_link,
                        target,
                        &restart,
                        &IkOptions::default(),
                    );
                    if sol.error_m < best.error_m || sol.converged {
                        best = sol;
                    }
                }
                if !best.converged {
                    return Err(SimError::Unreachable {
                        path: path.to_path_buf(),
                        key: format!("robot.motion.waypoints[{i}]"),
                        target: *p,
                        residual_m: best.error_m,
                    });
                }
                seed.clone_from(&best.q);
                points.push(best.q);
            }
            Ok(JointTrajectory::through(
                &points,
                &scaled(*speed_scale),
                &acceleration_of(*acceleration_rad_s2),
                *dwell_s,
            ))
        }
    }
}

/// Where random motion may go: every moving link and the tool above a height, every moving
/// link's collision geometry clear of the clutter.
struct Workspace<'a> {
    robot: &'a RobotModel,
    state: KinematicState,
    tool_link: LinkId,
    min_height_m: f64,
    clearance_m: f64,
    moving: Vec<LinkId>,
    shapes: Vec<(LinkId, SharedShape)>,
    obstacles: Vec<(Pose, SharedShape, parry3d_f64::bounding_volume::Aabb)>,
}

impl<'a> Workspace<'a> {
    fn new(
        robot: &'a RobotModel,
        X_WR: Pose,
        tool_link: LinkId,
        q: &[f64],
        scenario: &Scenario,
        min_height_m: f64,
        clearance_m: f64,
    ) -> Self {
        let mut state = KinematicState::new(robot);
        state.X_WB = X_WR;
        let moving = moving_links(robot, q);
        let shapes = moving
            .iter()
            .filter_map(|&l| link_collision_shape(robot, l).map(|s| (l, s)))
            .collect();
        let obstacles = scenario
            .clutter
            .iter()
            .flat_map(clutter_boxes)
            .map(|c| {
                let [hx, hy, hz] = c.half_extents_m;
                let shape = SharedShape::cuboid(hx, hy, hz);
                let aabb = shape.compute_aabb(&c.X_WC).loosened(clearance_m);
                (c.X_WC, shape, aabb)
            })
            .collect();
        Self {
            robot,
            state,
            tool_link,
            min_height_m,
            clearance_m,
            moving,
            shapes,
            obstacles,
        }
    }

    /// Whether configuration `q` is in the workspace.
    fn contains(&mut self, q: &[f64]) -> bool {
        if self.robot.forward_kinematics(q, &mut self.state).is_err() {
            return false;
        }
        let state = &self.state;
        let high = |l: LinkId| state.link_pose(l).translation.z >= self.min_height_m;
        self.moving.iter().all(|&l| high(l))
            && high(self.tool_link)
            && self.shapes.iter().all(|(l, shape)| {
                let X_WL = state.link_pose(*l);
                let aabb = shape.compute_aabb(X_WL);
                self.obstacles.iter().all(|(X_WC, box_shape, box_aabb)| {
                    !aabb.intersects(box_aabb)
                        || parry3d_f64::query::distance(
                            X_WL,
                            shape.as_ref(),
                            X_WC,
                            box_shape.as_ref(),
                        )
                        .is_ok_and(|d| d.distance >= self.clearance_m)
                })
            })
    }

    /// Whether the straight joint-space line from `a` to `b` (the path of a rest-to-rest
    /// quintic move) stays in the workspace, checked at nine points.
    fn line_clear(&mut self, a: &[f64], b: &[f64]) -> bool {
        let mut q = vec![0.0; a.len()];
        (0..=8).all(|k| {
            let s = f64::from(k) / 8.0;
            for (qi, (x, y)) in q.iter_mut().zip(a.iter().zip(b)) {
                *qi = x + (y - x) * s;
            }
            self.contains(&q)
        })
    }
}

/// Links whose origin moves with the configuration (those on the base or on the first
/// joint's axis do not), judged by their Jacobian at `q` and at a perturbed `q`.
fn moving_links(robot: &RobotModel, q: &[f64]) -> Vec<LinkId> {
    let perturbed: Vec<f64> = q
        .iter()
        .enumerate()
        .map(|(i, v)| v + 0.1 + 0.05 * i as f64)
        .collect();
    let mut jacobian = workcell_robots::Jacobian::zeros(robot.dof());
    (0..robot.links().len())
        .filter(|&l| {
            [q, &perturbed].iter().any(|q| {
                robot.fk(Pose::IDENTITY, q).is_ok_and(|state| {
                    robot.point_jacobian(&state, l, state.link_pose(l).translation, &mut jacobian);
                    jacobian
                        .columns()
                        .iter()
                        .any(|c| c[0].abs() + c[1].abs() + c[2].abs() > 1e-9)
                })
            })
        })
        .collect()
}

/// The boxes of one clutter item: a solid box, or a shelf's posts and boards.
fn clutter_boxes(c: &crate::scenario::ClutterConfig) -> Vec<ClutterBox> {
    let X_WS = c.pose.to_pose();
    let [sx, sy, sz] = c.size_m;
    match c.kind {
        ClutterKind::Box => vec![ClutterBox {
            X_WC: X_WS,
            half_extents_m: [sx / 2.0, sy / 2.0, sz / 2.0],
        }],
        ClutterKind::Shelf => {
            let post = 0.03_f64.min(sx / 4.0).min(sy / 4.0);
            let board = 0.02_f64.min(sz / (2.0 * c.boards as f64));
            let mut boxes = Vec::new();
            for (x, y) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                let p = Vector::new(x * (sx - post) / 2.0, y * (sy - post) / 2.0, 0.0);
                boxes.push(ClutterBox {
                    X_WC: X_WS * Pose::from_translation(p),
                    half_extents_m: [post / 2.0, post / 2.0, sz / 2.0],
                });
            }
            for k in 0..c.boards {
                let z = -sz / 2.0 + board / 2.0 + (sz - board) * k as f64 / (c.boards - 1) as f64;
                boxes.push(ClutterBox {
                    X_WC: X_WS * Pose::from_translation(Vector::new(0.0, 0.0, z)),
                    half_extents_m: [sx / 2.0, sy / 2.0, board / 2.0],
                });
            }
            boxes
        }
    }
}

/// How one robot link is represented in rapier.
#[derive(Debug, Clone, Copy)]
struct LinkBody {
    body: RigidBodyHandle,
    /// Pose of the link in its body (identity unless merged through fixed joints).
    X_BL: Pose,
}

/// A robot coordinate in rapier: which multibody link and which axis.
#[derive(Debug, Clone, Copy)]
struct CoordinateHandle {
    joint: MultibodyJointHandle,
    axis: JointAxis,
    /// Index into the joint's spatial coordinates (0 for LinX, 3 for AngX).
    coord: usize,
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

        let (robot_links, coordinates) = build_robot(
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
                world.insert_collider(
                    ColliderBuilder::new(shape).position(X_LS).density(0.0),
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

/// Inserts the robot as a multibody; returns the body of every link and the rapier handle of
/// every coordinate.
fn build_robot(
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
