//! Planning the robot's nominal motion: random moves inside the workspace, pick-and-place
//! through inverse kinematics.

use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rapier3d_f64::parry::bounding_volume::BoundingVolume;
use rapier3d_f64::parry::shape::SharedShape;
use workcell_robots::collision::link_collision_shape;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{KinematicState, LinkId, RobotModel};

use crate::clutter::ClutterBox;
use crate::error::{Result, SimError};
use crate::ik::{IkOptions, solve_ik, tool_down};
use crate::scenario::{RobotMotionConfig, Scenario};
use crate::trajectory::JointTrajectory;

/// Joint-space motion of the robot from the scenario.
pub(crate) fn plan_robot_motion(
    scenario: &Scenario,
    path: &Path,
    robot: &RobotModel,
    X_WR: Pose,
    tool_link: LinkId,
    initial_q: &[f64],
    clutter: &[ClutterBox],
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
                clutter,
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
                            path: Some(path.to_path_buf()),
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
        clutter: &[ClutterBox],
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
        let obstacles = clutter
            .iter()
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
