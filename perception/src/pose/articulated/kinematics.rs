//! The arm's kinematic model as the fit moves it ([`ArticulatedArm`]).

use std::sync::Arc;

use workcell_render::RenderMesh;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{Coordinate, HumanPart, Joint, LinkId, RobotModel, Shape, Side};

use super::*;
use crate::error::{PerceptionError, Result};
use crate::pose::{POSE_MESH_SEGMENTS, RigidModel};

/// Starts beyond the middle of the ranges and the given ones that
/// [`ArticulatedArm::forearm_to`] climbs from, until one is within [`IK_DONE_M`].
const IK_SPREAD_STARTS: usize = 8;

/// Root of the summed squared end distances at which [`ArticulatedArm::forearm_to`] stops, m.
const IK_DONE_M: f64 = 1e-3;

/// The human model as the fit moves it: its joints, its arm parts' meshes, its base pose.
#[derive(Debug, Clone)]
pub struct ArticulatedArm {
    pub(super) human: RobotModel,
    pub(super) X_WH: Pose,
    /// The arm's parts: [`FITTED_PARTS`] (the right arm's), or the left arm's.
    pub(super) parts: [HumanPart; 3],
    pub(super) links: [LinkId; 3],
    /// What the fit renders of each part: its visuals' outside pieces.
    pub(super) meshes: [Option<Arc<RenderMesh>>; 3],
    /// Or their convex hull ([`ArmFitConfig::hull_outlines`]): a limb's outline from fewer
    /// triangles (the pieces where they span no volume).
    pub(super) hulls: [Option<Arc<RenderMesh>>; 3],
    /// Each part's box axis and size, for the depth term.
    pub(super) models: [Option<RigidModel>; 3],
    /// The fitted joints' ranges (clamped to +-pi), in [`ArticulatedArm::fitted`] order.
    pub(super) limits: Vec<[f64; 2]>,
    /// The joints the fit moves, by index in the model's joint order: those below the torso
    /// (the arm's). The trunk's joints above it stay at `held`'s values.
    pub(super) fitted: Vec<usize>,
    /// A whole configuration of the model: the values of the joints not fitted.
    pub(super) held: Vec<f64>,
    pub(super) forearm: RigidModel,
    /// The shoulder (the upper arm's link origin), world frame, and the radius about it
    /// that holds every point of the three parts whatever the joints, m.
    pub(super) shoulder_W: Vector,
    pub(super) reach_m: f64,
    /// The trunk's stage, where revolute joints move the torso ([`TrunkModel`]).
    /// Shared: the fitter holds it across a frame's stage while it moves the arm.
    pub(super) trunk: Option<Arc<TrunkModel>>,
    /// Every link's world pose at `held` (the fitted joints at `held`'s values too): the
    /// links above the fitted joints stay there whatever the fit moves.
    held_poses: Vec<Pose>,
    /// The joints to the three parts that the fitted joints move (theirs and those below
    /// them), in the model's (topological) order: all that [`Self::fitted_part_poses`]
    /// recomputes.
    moving: Vec<MovingJoint>,
    /// Where each part's pose comes from: a held link's, or a moving joint's child's.
    part_from: [PoseOf; 3],
    /// Each configuration coordinate's place among the fitted joints, where it is one.
    fitted_slot: Vec<Option<usize>>,
}

/// A joint that the fitted joints move, as [`ArticulatedArm::fitted_part_poses`] poses its
/// child.
#[derive(Debug, Clone, Copy)]
struct MovingJoint {
    joint: usize,
    parent: PoseOf,
}

/// A link's world pose: a held link's (index into the held poses), or the child's of the
/// moving joint at this index.
#[derive(Debug, Clone, Copy)]
enum PoseOf {
    Held(LinkId),
    Moved(usize),
}

/// Joints [`ArticulatedArm::fitted_part_poses`] poses on the stack; a model with more moving
/// joints to the parts takes a whole forward kinematics pass.
const MAX_MOVING: usize = 16;

impl ArticulatedArm {
    /// The (right) arm of `human` (in the look it is seen in: its visuals are what is
    /// rendered) standing with its base at `X_WH`.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when the model has no joints, an arm part has no link of
    /// its name, or the forearm has no visual geometry.
    pub fn new(human: &RobotModel, X_WH: &Pose) -> Result<Self> {
        Self::of_side(human, X_WH, Side::Right)
    }

    /// The arm on `side` of `human`: the right arm's parts ([`FITTED_PARTS`]) or the left's
    /// ([`HumanPart::LEFT_ARM`]); the fit moves the joints between the torso and them.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn of_side(human: &RobotModel, X_WH: &Pose, side: Side) -> Result<Self> {
        let parts = match side {
            Side::Right => FITTED_PARTS,
            Side::Left => HumanPart::LEFT_ARM,
        };
        let missing = |message: String| PerceptionError::Input {
            message: format!("human model {}: {message}", human.name()),
        };
        if human.dof() == 0 {
            return Err(missing("no joints to fit".into()));
        }
        let mut links = [0; 3];
        let mut meshes: [Option<Arc<RenderMesh>>; 3] = [None, None, None];
        let mut hulls: [Option<Arc<RenderMesh>>; 3] = [None, None, None];
        let mut models: [Option<RigidModel>; 3] = [None, None, None];
        for (i, part) in parts.into_iter().enumerate() {
            let link = human
                .link_id(part.link_name())
                .ok_or_else(|| missing(format!("no link named {part}")))?;
            let pieces: Vec<(RenderMesh, bool)> = human.links()[link]
                .visuals
                .iter()
                .map(|g| {
                    let mesh =
                        RenderMesh::from_geometry_with(g, [0.85, 0.72, 0.62], POSE_MESH_SEGMENTS);
                    (mesh, !matches!(g.shape, Shape::Mesh { .. }))
                })
                .collect();
            let mut mesh = RenderMesh::default();
            for (piece, _) in &pieces {
                mesh.append(piece, &Pose::IDENTITY);
            }
            links[i] = link;
            if !mesh.is_empty() {
                // The parts' geometry from every visual; their renders from the outside ones,
                // or from their hull.
                let outer = Arc::new(RenderMesh::outer_union(&pieces));
                hulls[i] = Some(mesh.convex_hull().map_or_else(|| outer.clone(), Arc::new));
                models[i] = Some(RigidModel::new(Arc::new(mesh))?);
                meshes[i] = Some(outer);
            }
        }
        let forearm = models[1]
            .clone()
            .ok_or_else(|| missing("the forearm link has no visual geometry".into()))?;
        let all_limits = human
            .position_limits()
            .into_iter()
            .map(|[lo, hi]| {
                let (lo, hi) = (lo.max(-std::f64::consts::PI), hi.min(std::f64::consts::PI));
                if lo <= hi { [lo, hi] } else { [0.0, 0.0] }
            })
            .collect::<Vec<_>>();
        // The trunk's joints: those that move the torso (the links from the root to it).
        let torso = human.link_id(HumanPart::Torso.link_name()).unwrap_or(0);
        let trunk: Vec<usize> = human.joints_above(torso).collect();
        // The fitted joints: those between the torso and the fitted parts (the right arm's;
        // a left arm's joints are held).
        let mut on_chain = vec![false; human.joints().len()];
        for j in links.iter().flat_map(|&l| human.joints_above(l)) {
            on_chain[j] = true;
        }
        let fitted: Vec<usize> = human
            .actuated_joints()
            .iter()
            .enumerate()
            .filter(|(_, j)| on_chain[**j] && !trunk.contains(j))
            .map(|(i, _)| i)
            .collect();
        if fitted.is_empty() {
            return Err(missing("no joints below the torso to fit".into()));
        }
        let held: Vec<f64> = all_limits
            .iter()
            .map(|[lo, hi]| 0.0_f64.clamp(*lo, *hi))
            .collect();
        let limits: Vec<[f64; 2]> = fitted.iter().map(|&i| all_limits[i]).collect();
        // The reach: each part's farthest box corner from its link's origin, plus the
        // distances between consecutive parts' origins, which their joints leave unchanged
        // (a URDF joint sits at its child link's origin, fixed in its parent's frame).
        let mut middle = held.clone();
        for (&i, [lo, hi]) in fitted.iter().zip(&limits) {
            middle[i] = 0.5 * (lo + hi);
        }
        let k = human.fk(*X_WH, &middle)?;
        let origin = |i: usize| k.link_pose(links[i]).translation;
        let (mut chain, mut reach_m) = (0.0, 0.0f64);
        for (i, model) in models.iter().enumerate() {
            if i > 0 {
                chain += (origin(i) - origin(i - 1)).length();
            }
            if let Some(model) = model {
                let far = model
                    .corners_O
                    .iter()
                    .map(|c| c.length())
                    .fold(0.0, f64::max);
                reach_m = reach_m.max(chain + far);
            }
        }
        let trunk = TrunkModel::of(human, &held, &all_limits)?.map(Arc::new);
        let (moving, part_from) = moving_joints(human, &links, &fitted);
        let held_poses = human.fk(*X_WH, &held)?.link_poses().to_vec();
        let mut fitted_slot = vec![None; human.dof()];
        for (slot, &i) in fitted.iter().enumerate() {
            fitted_slot[i] = Some(slot);
        }
        Ok(Self {
            held_poses,
            moving,
            part_from,
            fitted_slot,
            trunk,
            human: human.clone(),
            X_WH: *X_WH,
            parts,
            links,
            meshes,
            hulls,
            models,
            limits,
            fitted,
            held,
            forearm,
            shoulder_W: origin(0),
            reach_m,
        })
    }

    /// The nearest camera-frame depth any point of the arm can have for a camera at
    /// `X_WC`, m: the shoulder's depth less the arm's reach. A depth image that shows a
    /// surface nearer than this shows something in front of the arm.
    #[must_use]
    pub fn nearest_depth_m(&self, X_WC: &Pose) -> f64 {
        X_WC.inverse().transform_point(self.shoulder_W).z - self.reach_m
    }

    /// The trunk's stage: `None` where no revolute joint moves the torso.
    #[must_use]
    pub fn trunk(&self) -> Option<&TrunkModel> {
        self.trunk.as_deref()
    }

    /// Holds the trunk's joints at `values` ([`TrunkModel::all`]'s order: the revolute
    /// joints, then the slides) for the arm's fit, the shoulder where they put it.
    ///
    /// # Errors
    /// A forward kinematics failure (a value that is not finite).
    pub(super) fn hold_trunk(&mut self, trunk: &TrunkModel, values: &[f64]) -> Result<()> {
        for (&i, v) in trunk.all.iter().zip(values) {
            self.held[i] = *v;
        }
        let k = self.human.fk(self.X_WH, &self.held)?;
        self.shoulder_W = k.link_pose(self.links[0]).translation;
        self.held_poses.clear();
        self.held_poses.extend_from_slice(k.link_poses());
        Ok(())
    }

    /// Joints fitted: the arm's, below the torso.
    #[must_use]
    pub fn dof(&self) -> usize {
        self.limits.len()
    }

    /// Joints of the human model (fitted or held).
    #[must_use]
    pub fn model_dof(&self) -> usize {
        self.held.len()
    }

    /// The fitted joints, by index in the human model's joint order.
    #[must_use]
    pub fn fitted(&self) -> &[usize] {
        &self.fitted
    }

    /// Each fitted joint's range, rad (clamped to +-pi).
    #[must_use]
    pub fn limits(&self) -> &[[f64; 2]] {
        &self.limits
    }

    /// The model's whole configuration for fitted joints `q_fit`: the trunk's joints at
    /// their held values (0, the trunk upright at the human's base, within their limits,
    /// until the trunk's stage fits them: [`ArmFitter::fit_trunk`]).
    #[must_use]
    pub fn configuration(&self, q_fit: &[f64]) -> Vec<f64> {
        let mut q = self.held.clone();
        for (&i, v) in self.fitted.iter().zip(q_fit) {
            q[i] = *v;
        }
        q
    }

    /// The fitted joints of the model's configuration `q` (missing values: 0).
    #[must_use]
    pub fn fitted_of(&self, q: &[f64]) -> Vec<f64> {
        self.fitted
            .iter()
            .map(|&i| q.get(i).copied().unwrap_or(0.0))
            .collect()
    }

    /// The links of the upper arm, the forearm and the hand ([`Self::parts`]).
    #[must_use]
    pub fn part_links(&self) -> [LinkId; 3] {
        self.links
    }

    /// The arm's upper arm, forearm and hand: [`FITTED_PARTS`] for the right arm, the left
    /// arm's parts for the left ([`Self::of_side`]).
    #[must_use]
    pub fn parts(&self) -> [HumanPart; 3] {
        self.parts
    }

    /// The forearm as the paper's pose search and its error metric see it.
    #[must_use]
    pub fn forearm(&self) -> &RigidModel {
        &self.forearm
    }

    /// The link frames of the upper arm, the forearm and the hand in the camera frame (the
    /// camera at `X_WC`) at the model's configuration `q`.
    ///
    /// # Errors
    /// `q` has the wrong length or a value that is not finite.
    pub fn part_poses(&self, q: &[f64], X_WC: &Pose) -> Result<[Pose; 3]> {
        let X_CW = X_WC.inverse();
        let k = self.human.fk(self.X_WH, q)?;
        Ok(self.links.map(|l| X_CW * *k.link_pose(l)))
    }

    /// Whether [`Self::poses_below`] can pose the parts (the held poses are the model's,
    /// and few enough joints move).
    fn poses_below_held(&self) -> bool {
        self.held_poses.len() == self.human.links().len() && self.moving.len() <= MAX_MOVING
    }

    /// The parts' poses in the camera frame (`X_CW`) with the moving joints at `position`
    /// and the rest where they are held.
    fn poses_below(&self, position: impl Fn(&Joint) -> f64, X_CW: &Pose) -> [Pose; 3] {
        let mut moved = [Pose::IDENTITY; MAX_MOVING];
        let joints = self.human.joints();
        let pose_of = |from: PoseOf, moved: &[Pose; MAX_MOVING]| match from {
            PoseOf::Held(link) => self.held_poses[link],
            PoseOf::Moved(k) => moved[k],
        };
        for (k, m) in self.moving.iter().enumerate() {
            let joint = &joints[m.joint];
            moved[k] = pose_of(m.parent, &moved) * joint.child_pose_in_parent(position(joint));
        }
        self.part_from.map(|from| *X_CW * pose_of(from, &moved))
    }

    /// [`ArticulatedArm::part_poses`] at fitted joints `q_fit`.
    pub(super) fn fitted_part_poses(&self, q_fit: &[f64], X_WC: &Pose) -> Result<[Pose; 3]> {
        if q_fit.len() != self.fitted.len() {
            return Err(PerceptionError::Input {
                message: format!(
                    "{} fitted joint values for {} joints",
                    q_fit.len(),
                    self.fitted.len()
                ),
            });
        }
        if !self.poses_below_held() {
            return self.part_poses(&self.configuration(q_fit), X_WC);
        }
        if let Some(i) = q_fit.iter().position(|v| !v.is_finite()) {
            return Err(PerceptionError::Input {
                message: format!("fitted joint {i} is {}", q_fit[i]),
            });
        }
        // The held configuration with the fitted joints at `q_fit`, without building it: the
        // links above the fitted joints stay where the held poses have them, and the moving
        // joints' products are forward kinematics', so the poses are its to the bit.
        let value = |index: usize| match self.fitted_slot.get(index).copied().flatten() {
            Some(slot) => q_fit[slot],
            None => self.held[index],
        };
        Ok(self.poses_below(|joint| joint.position_of(value), &X_WC.inverse()))
    }

    /// The forearm's ends in the world at fitted joints `q_fit`: the elbow's (the end nearer
    /// the forearm link's origin) and the wrist's.
    pub(super) fn forearm_ends(&self, q_fit: &[f64]) -> Result<[Vector; 2]> {
        let X = self.fitted_part_poses(q_fit, &Pose::IDENTITY)?[1];
        let m = &self.forearm;
        let a = m.centre_O + 0.5 * m.length_m * m.axis_O;
        let b = m.centre_O - 0.5 * m.length_m * m.axis_O;
        let (elbow, wrist) = if a.length() <= b.length() {
            (a, b)
        } else {
            (b, a)
        };
        Ok([X.transform_point(elbow), X.transform_point(wrist)])
    }

    /// Fitted joints that put the forearm end for end from where `q_fit` puts it (the elbow
    /// where its wrist was and the wrist where its elbow was), as nearly as the arm's
    /// lengths and limits allow ([`Self::forearm_to`]). The outline of a forearm, and its
    /// depth, read the same both ways; only the hand and the upper arm tell them apart, and
    /// those are often hidden.
    pub(super) fn reversed_forearm(&self, q_fit: &[f64]) -> Result<Vec<f64>> {
        let [elbow, wrist] = self.forearm_ends(q_fit)?;
        self.forearm_to([wrist, elbow], &[q_fit])
    }

    /// Fitted joints that put the forearm's elbow and wrist ([`Self::forearm_ends`]) at
    /// `goal` (world), as nearly as the arm's lengths and limits allow: damped Gauss-Newton
    /// on the ends' squared distances from the middle of each joint's range and from each of
    /// `starts`, the nearest of them.
    pub(super) fn forearm_to(&self, goal: [Vector; 2], starts: &[&[f64]]) -> Result<Vec<f64>> {
        let residual = |q: &[f64]| -> Result<[f64; 6]> {
            let ends = self.forearm_ends(q)?;
            let mut r = [0.0; 6];
            for (k, (e, g)) in ends.iter().zip(&goal).enumerate() {
                let d = *e - *g;
                r[3 * k..3 * k + 3].copy_from_slice(&[d.x, d.y, d.z]);
            }
            Ok(r)
        };
        // The middle of every range, the given starts, then points a quarter in from either
        // end of each range in a few patterns: a damped Gauss-Newton climb from one start
        // stops in a local minimum for about a quarter of reachable ends.
        let at = |pattern: usize| -> Vec<f64> {
            self.limits
                .iter()
                .enumerate()
                .map(|(j, [lo, hi])| {
                    let f = match pattern {
                        0 => 0.5,
                        p => [0.25, 0.75][((p - 1) >> j) & 1],
                    };
                    lo + f * (hi - lo)
                })
                .collect()
        };
        let middle = at(0);
        let mut best: Option<(f64, Vec<f64>)> = None;
        let given = starts.iter().map(|s| s.to_vec());
        let spread = (1..=IK_SPREAD_STARTS).map(|p| at(p * 5 % 31 + 1));
        for start in std::iter::once(middle.clone()).chain(given).chain(spread) {
            let (r, q) = self.gauss_newton(&residual, &start)?;
            if best.as_ref().is_none_or(|(b, _)| r < *b) {
                best = Some((r, q));
            }
            if best
                .as_ref()
                .is_some_and(|(b, _)| *b < IK_DONE_M * IK_DONE_M)
            {
                break;
            }
        }
        Ok(best.map_or(middle, |(_, q)| q))
    }

    /// Levenberg-Marquardt on `residual` from `start` (its Jacobian by forward
    /// differences), each step clamped to half a radian per joint and to the limits: the
    /// joints and their summed squared residual.
    fn gauss_newton(
        &self,
        mut residual: impl FnMut(&[f64]) -> Result<[f64; 6]>,
        start: &[f64],
    ) -> Result<(f64, Vec<f64>)> {
        const ITERATIONS: usize = 40;
        const STEP_RAD: f64 = 1e-4;
        let n = self.limits.len();
        let mut q = start.to_vec();
        self.clamp(&mut q);
        let mut r = residual(&q)?;
        let mut cost: f64 = r.iter().map(|v| v * v).sum();
        let mut damping = 1e-3;
        for _ in 0..ITERATIONS {
            if cost < IK_DONE_M * IK_DONE_M {
                break;
            }
            let Some(dq) = gauss_newton_step(&mut residual, &q, &r, 0..n, STEP_RAD, damping)?
            else {
                break;
            };
            let mut next = q.clone();
            for (x, d) in next.iter_mut().zip(&dq) {
                *x += d.clamp(-0.5, 0.5);
            }
            self.clamp(&mut next);
            let r_next = residual(&next)?;
            let cost_next: f64 = r_next.iter().map(|v| v * v).sum();
            if cost_next < cost {
                (q, r, cost) = (next, r_next, cost_next);
                damping = (damping / 3.0).max(1e-9);
            } else {
                damping *= 10.0;
                if damping > 1e6 {
                    break;
                }
            }
        }
        Ok((cost, q))
    }

    pub(super) fn clamp(&self, q: &mut [f64]) {
        for (v, [lo, hi]) in q.iter_mut().zip(&self.limits) {
            *v = v.clamp(*lo, *hi);
        }
    }
}

/// The joints on the paths from `human`'s root to the `parts` that a fitted coordinate (an
/// index into the configuration) moves, itself or through a joint above it, in the model's
/// joint order, each with where its parent's pose comes from; and where each part's does.
fn moving_joints(
    human: &RobotModel,
    parts: &[LinkId; 3],
    fitted: &[usize],
) -> (Vec<MovingJoint>, [PoseOf; 3]) {
    let joints = human.joints();
    let mut needed = vec![false; joints.len()];
    for j in parts.iter().flat_map(|&l| human.joints_above(l)) {
        needed[j] = true;
    }
    // Per link: the moving joint (its index among them) whose child it is.
    let mut moved_by: Vec<Option<usize>> = vec![None; human.links().len()];
    let mut moving = Vec::new();
    for (j, joint) in joints.iter().enumerate() {
        let own = match joint.coordinate {
            Coordinate::None => false,
            Coordinate::Own { index } | Coordinate::Mimic { index, .. } => fitted.contains(&index),
        };
        let parent = match moved_by[joint.parent] {
            Some(k) => PoseOf::Moved(k),
            None => PoseOf::Held(joint.parent),
        };
        if (own || matches!(parent, PoseOf::Moved(_))) && needed[j] {
            moved_by[joint.child] = Some(moving.len());
            moving.push(MovingJoint { joint: j, parent });
        }
    }
    let part_from = parts.map(|l| match moved_by[l] {
        Some(k) => PoseOf::Moved(k),
        None => PoseOf::Held(l),
    });
    (moving, part_from)
}
