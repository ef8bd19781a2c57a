//! Robot-human distance queries: every robot link against every human part, with the
//! Jacobian row of the robot's witness point for the safety filter.

use parry3d_f64::shape::SharedShape;
use workcell_robots::collision::{LinkCapsule, link_bounding_capsule, link_collision_shape};
use workcell_robots::{Jacobian, KinematicState, LinkId, RobotModel};

use crate::error::{Result, SafetyError};
use crate::geometry::{Capsule, SignedDistancePair, capsule_capsule, shape_capsule};
use crate::human::{AnticipatedPart, HumanEstimate, PartEstimate};

/// A segment-end row joins a pair's rows when it is within this of the pair's distance, m.
const END_ROW_MARGIN_M: f64 = 0.02;
/// ... and its robot witness point is at least this far from the pair's, m.
const END_ROW_SEPARATION_M: f64 = 0.01;

/// The pairs of each segment end of A against B and of each end of B against A (balls at the
/// ends against the other capsule: each is at least the capsule distance, and smooth).
fn end_pairs(
    link: LinkId,
    a: &Capsule,
    part: crate::human::HumanPart,
    b: &Capsule,
) -> [SignedDistancePair; 4] {
    let ball = |p: workcell_robots::math::Vector, r: f64| Capsule::new(p, p, r);
    let from_b = |end: workcell_robots::math::Vector, t: f64| {
        let mut pair = capsule_capsule(link, a, part, &ball(end, b.radius_m));
        pair.t_B = t;
        pair
    };
    let (b0, b1) = (from_b(b.a_W, 0.0), from_b(b.b_W, 1.0));
    [
        capsule_capsule(link, &ball(a.a_W, a.radius_m), part, b),
        capsule_capsule(link, &ball(a.b_W, a.radius_m), part, b),
        b0,
        b1,
    ]
}

/// Appends the rows of one link against human capsules (a part, or a copy of one).
struct PairRows<'a> {
    robot: &'a RobotModel,
    kinematics: &'a KinematicState,
    link: LinkId,
    link_capsule: &'a Capsule,
    uncertainty_rate_m_s: f64,
    /// The rows are an anticipated copy's.
    anticipated: bool,
    jacobian: &'a mut Jacobian,
    out: &'a mut Vec<PairConstraint>,
}

impl PairRows<'_> {
    /// The rows of `pair`, the link against `capsule` (the inflated `estimate`).
    fn push(&mut self, estimate: &PartEstimate, capsule: &Capsule, pair: SignedDistancePair) {
        self.push_one(estimate, pair);
        // Where the axes are (nearly) parallel the closest points are not unique and the
        // distance has a kink: turning either way brings one end closer. A single row's
        // gradient then points across the kink and the QP chatters over it, losing distance
        // every tick. Rows for the segment ends close to the minimum cover both sides.
        for end in end_pairs(self.link, self.link_capsule, estimate.part, capsule) {
            if end.distance_m <= pair.distance_m + END_ROW_MARGIN_M
                && (end.p_WA - pair.p_WA).length() > END_ROW_SEPARATION_M
            {
                self.push_one(estimate, end);
            }
        }
    }

    fn push_one(&mut self, estimate: &PartEstimate, p: SignedDistancePair) {
        self.robot
            .point_jacobian(self.kinematics, self.link, p.p_WA, self.jacobian);
        let mut normal_jacobian = [0.0; MAX_DOF];
        for (j, col) in self.jacobian.columns().iter().enumerate() {
            normal_jacobian[j] =
                p.nhat_BA_W.x * col[0] + p.nhat_BA_W.y * col[1] + p.nhat_BA_W.z * col[2];
        }
        self.out.push(PairConstraint {
            pair: p,
            normal_jacobian,
            // Only the approach counts: a withdrawing human is treated as standing, so that
            // the arm cannot chase a hand that may turn back within the perception latency.
            human_normal_speed_m_s: p.nhat_BA_W.dot(estimate.velocity_at(p.t_B)).max(0.0)
                + self.uncertainty_rate_m_s,
            max_approach_m_s: f64::INFINITY,
            obstacle: false,
            anticipated: self.anticipated,
            escape_margin_m: 0.0,
        });
    }
}

/// A static box of the cell the arm must not be pushed into.
#[derive(Debug, Clone)]
pub struct Obstacle {
    /// Pose of the box centre in the world.
    pub X_WO: workcell_robots::math::Pose,
    pub shape: parry3d_f64::shape::Cuboid,
}

impl Obstacle {
    /// A box with centre pose `X_WO` and half extents `half_extents_m`.
    #[must_use]
    pub fn cuboid(X_WO: workcell_robots::math::Pose, half_extents_m: [f64; 3]) -> Self {
        Self {
            X_WO,
            shape: parry3d_f64::shape::Cuboid::new(workcell_robots::math::Vector::from_array(
                half_extents_m,
            )),
        }
    }
}

/// Most joints a guarded robot may have (rows are fixed-size arrays to keep the tick free of
/// allocation).
pub const MAX_DOF: usize = 16;

/// One robot-link / human-part pair within the detection distance, ready for a constraint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairConstraint {
    pub pair: SignedDistancePair,
    /// `nhat_BA_W^T J_A(q)`: how fast each joint moves the robot witness point away from the
    /// human part (m/s per rad/s). Entries past the robot's dof are zero.
    pub normal_jacobian: [f64; MAX_DOF],
    /// `max(0, nhat_BA_W^T v_B) + du/dt`: the approach speed of the inflated part's surface at
    /// its witness point along the normal (the normal points from human to robot): the part's
    /// own speed, a withdrawing part counting as standing, plus the growth rate of the
    /// uncertainty it is inflated by.
    pub human_normal_speed_m_s: f64,
    /// Power and force limiting: the robot's witness point may approach the part at most
    /// this fast, m/s: ISO/TS 15066's transient contact speed of the part's body region
    /// within the filter's `pfl_distance_m`, a braking ramp up from it beyond; infinite when
    /// power and force limiting is off.
    pub max_approach_m_s: f64,
    /// A row against a static obstacle of the cell (a table, a shelf) instead of a human
    /// part: its bound is [`PairConstraint::max_approach_m_s`] alone and `pair.part` means
    /// nothing. The filter keeps the arm from being pushed into the furniture while it
    /// evades the human.
    pub obstacle: bool,
    /// A row against an anticipated copy of a human part
    /// ([`HumanEstimate::anticipate_into`]) rather than the part where it is: it ranks after
    /// the parts' and the obstacles' rows when the QP's rows run out, gives way in the slack
    /// no later than the closest part's row, and is not the closest pair whose violation the
    /// filter judges.
    pub anticipated: bool,
    /// Extra separation this pair keeps beyond d_min, m: where the arm cannot move its
    /// witness point away along the normal as fast as a human may approach, the shortfall
    /// times the filter's `escape_horizon_s` (0 elsewhere).
    pub escape_margin_m: f64,
}

impl PairConstraint {
    /// The fastest the robot's witness point may approach the part, m/s (negative: it must
    /// move away): the barrier `gamma (d - d_min) - v_human`, capped by
    /// [`PairConstraint::max_approach_m_s`]. Its row reads `-normal_jacobian . qdot <= bound`.
    #[must_use]
    #[inline]
    pub fn approach_bound_m_s(&self, gamma_per_s: f64, d_min_m: f64) -> f64 {
        if self.obstacle {
            return self.max_approach_m_s;
        }
        (gamma_per_s * (self.pair.distance_m - d_min_m - self.escape_margin_m)
            - self.human_normal_speed_m_s)
            .min(self.max_approach_m_s)
    }

    /// The fastest joints within `velocity_limits` (rad/s or m/s, one per joint) can move
    /// the robot's witness point along the normal, either way, m/s.
    #[must_use]
    pub fn escape_m_s(&self, velocity_limits: &[f64]) -> f64 {
        self.normal_jacobian
            .iter()
            .zip(velocity_limits)
            .map(|(a, v)| a.abs() * v)
            .sum()
    }

    /// How fast joint velocities `qdot` move the robot's witness point toward the part, m/s.
    #[must_use]
    #[inline]
    pub fn approach_m_s(&self, qdot: &[f64]) -> f64 {
        -self
            .normal_jacobian
            .iter()
            .zip(qdot)
            .map(|(a, v)| a * v)
            .sum::<f64>()
    }
}

/// The robot's geometry for distance queries: a bounding capsule per link (used by the
/// filters: conservative and exact in closed form) and the exact collision shape per link
/// (used to measure the true separation).
#[derive(Debug, Clone)]
pub struct RobotGeometry {
    links: Vec<GuardedLink>,
    dof: usize,
    jacobian: Jacobian,
    /// Per human part, its normal against the link at hand (scratch of the pair queries).
    normals: Vec<workcell_robots::math::Vector>,
    /// Per human part, its anticipated copy closest to the link at hand (index in `ahead`)
    /// and their pair.
    closest_copy: Vec<Option<(usize, SignedDistancePair)>>,
}

#[derive(Debug, Clone)]
struct GuardedLink {
    capsule: LinkCapsule,
    shape: Option<SharedShape>,
    /// At least one joint between the link and the root moves it.
    movable: bool,
}

impl RobotGeometry {
    /// The geometry of every link of `robot` that has collision geometry.
    ///
    /// # Errors
    /// [`SafetyError::Robot`] when no link has collision geometry or the robot has more than
    /// [`MAX_DOF`] joints.
    pub fn new(robot: &RobotModel) -> Result<Self> {
        if robot.dof() > MAX_DOF {
            return Err(SafetyError::Robot {
                robot: robot.name().to_string(),
                message: format!(
                    "{} joints; the safety filter handles at most {MAX_DOF}",
                    robot.dof()
                ),
            });
        }
        let links: Vec<GuardedLink> = (0..robot.links().len())
            .filter_map(|l| {
                let capsule = link_bounding_capsule(robot, l)?;
                Some(GuardedLink {
                    capsule,
                    shape: link_collision_shape(robot, l),
                    movable: has_moving_ancestor(robot, l),
                })
            })
            .collect();
        if links.is_empty() {
            return Err(SafetyError::Robot {
                robot: robot.name().to_string(),
                message:
                    "no link has collision geometry: there is nothing to keep away from the human"
                        .into(),
            });
        }
        Ok(Self {
            links,
            dof: robot.dof(),
            jacobian: Jacobian::zeros(robot.dof()),
            normals: Vec::new(),
            closest_copy: Vec::new(),
        })
    }

    /// Number of guarded links.
    #[must_use]
    pub fn link_count(&self) -> usize {
        self.links.len()
    }

    /// Number of links the robot can move (the ones that get constraints).
    #[must_use]
    pub fn movable_link_count(&self) -> usize {
        self.links.iter().filter(|l| l.movable).count()
    }

    /// The robot's joint count.
    #[must_use]
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// The bounding capsule of every guarded link at the configuration of `kinematics`.
    pub fn capsules<'a>(
        &'a self,
        kinematics: &'a KinematicState,
    ) -> impl Iterator<Item = (LinkId, Capsule)> + 'a {
        self.links.iter().map(move |g| {
            let (a_W, b_W) = g
                .capsule
                .segment_in_world(kinematics.link_pose(g.capsule.link));
            (g.capsule.link, Capsule::new(a_W, b_W, g.capsule.radius_m))
        })
    }

    /// The constraint of every pair of a movable link's capsule and an inflated human part
    /// closer than `detection_m`, into `out` (cleared first; keeps its capacity).
    pub fn pair_constraints(
        &mut self,
        robot: &RobotModel,
        kinematics: &KinematicState,
        human: &HumanEstimate,
        detection_m: f64,
        out: &mut Vec<PairConstraint>,
    ) {
        self.pair_constraints_ahead(robot, kinematics, human, &[], detection_m, out);
    }

    /// [`RobotGeometry::pair_constraints`], and for each link and part the constraint of the
    /// part's anticipated copy (`ahead`, [`HumanEstimate::anticipate_into`]) closest to the
    /// link, inflated alike: the copies of one path are near-duplicate rows, and the closest
    /// binds. A copy counts for a link only while its path has not carried it past the link:
    /// where the copy's normal points against the normal of the part it copies (the path
    /// crosses or passes the link), its row would push the link back toward the part where
    /// it is, and it gets none.
    pub fn pair_constraints_ahead(
        &mut self,
        robot: &RobotModel,
        kinematics: &KinematicState,
        human: &HumanEstimate,
        ahead: &[AnticipatedPart],
        detection_m: f64,
        out: &mut Vec<PairConstraint>,
    ) {
        out.clear();
        let margin = human.uncertainty_m;
        for g in &self.links {
            if !g.movable {
                continue;
            }
            let (a_W, b_W) = g
                .capsule
                .segment_in_world(kinematics.link_pose(g.capsule.link));
            let link_capsule = Capsule::new(a_W, b_W, g.capsule.radius_m);
            let mut rows = PairRows {
                robot,
                kinematics,
                link: g.capsule.link,
                link_capsule: &link_capsule,
                uncertainty_rate_m_s: human.uncertainty_rate_m_s,
                anticipated: false,
                jacobian: &mut self.jacobian,
                out,
            };
            self.normals.clear();
            self.closest_copy.clear();
            for (estimate, capsule) in human.inflated() {
                let pair = capsule_capsule(g.capsule.link, &link_capsule, estimate.part, &capsule);
                self.normals.push(pair.nhat_BA_W);
                self.closest_copy.push(None);
                if pair.distance_m <= detection_m {
                    rows.push(estimate, &capsule, pair);
                }
            }
            for (i, copy) in ahead.iter().enumerate() {
                let capsule = copy.estimate.capsule.inflated(margin);
                let pair =
                    capsule_capsule(g.capsule.link, &link_capsule, copy.estimate.part, &capsule);
                let (Some(normal), Some(closest)) = (
                    self.normals.get(copy.of),
                    self.closest_copy.get_mut(copy.of),
                ) else {
                    continue;
                };
                if pair.distance_m <= detection_m
                    && normal.dot(pair.nhat_BA_W) >= 0.0
                    && closest.is_none_or(|(_, c)| pair.distance_m < c.distance_m)
                {
                    *closest = Some((i, pair));
                }
            }
            rows.anticipated = true;
            for &(i, pair) in self.closest_copy.iter().flatten() {
                let copy = &ahead[i].estimate;
                rows.push(copy, &copy.capsule.inflated(margin), pair);
            }
        }
    }

    /// The rows of every movable link's capsule against every obstacle box closer than
    /// `detection_m`, appended to `out`: the link may approach the box at most at
    /// `gamma_per_s (d - clearance_m)`, and not at all once closer than `clearance_m` (a link
    /// that starts closer, such as the first link above the table the robot stands on, is
    /// not pushed out). The filter raises the bound to the nominal command's own approach.
    #[allow(clippy::too_many_arguments)]
    pub fn obstacle_constraints(
        &mut self,
        robot: &RobotModel,
        kinematics: &KinematicState,
        obstacles: &[Obstacle],
        detection_m: f64,
        clearance_m: f64,
        gamma_per_s: f64,
        out: &mut Vec<PairConstraint>,
    ) {
        for g in &self.links {
            if !g.movable {
                continue;
            }
            let (a_W, b_W) = g
                .capsule
                .segment_in_world(kinematics.link_pose(g.capsule.link));
            // The link's capsule as B, the box as A: flip the pair afterwards.
            let link_capsule = Capsule::new(a_W, b_W, g.capsule.radius_m);
            for o in obstacles {
                let Some(p) = shape_capsule(
                    g.capsule.link,
                    &o.X_WO,
                    &o.shape,
                    crate::human::HumanPart::Torso,
                    &link_capsule,
                    detection_m,
                ) else {
                    continue;
                };
                // The robot's witness is on the capsule (p_WB); its normal points away from
                // the box.
                let n = -p.nhat_BA_W;
                robot.point_jacobian(kinematics, g.capsule.link, p.p_WB, &mut self.jacobian);
                let mut normal_jacobian = [0.0; MAX_DOF];
                for (j, col) in self.jacobian.columns().iter().enumerate() {
                    normal_jacobian[j] = n.x * col[0] + n.y * col[1] + n.z * col[2];
                }
                out.push(PairConstraint {
                    pair: SignedDistancePair {
                        link: g.capsule.link,
                        part: crate::human::HumanPart::Torso,
                        distance_m: p.distance_m,
                        p_WA: p.p_WB,
                        p_WB: p.p_WA,
                        nhat_BA_W: n,
                        t_B: 0.0,
                    },
                    normal_jacobian,
                    human_normal_speed_m_s: 0.0,
                    max_approach_m_s: gamma_per_s * (p.distance_m - clearance_m).max(0.0),
                    obstacle: true,
                    anticipated: false,
                    escape_margin_m: 0.0,
                });
            }
        }
    }

    /// The smallest signed distance between the robot's exact collision shapes and the
    /// human's capsules (not inflated), with its pair; `None` when nothing is within
    /// `max_distance_m`. This is the true separation of the evaluation metrics.
    #[must_use]
    pub fn min_exact_distance(
        &self,
        kinematics: &KinematicState,
        human: &HumanEstimate,
        max_distance_m: f64,
    ) -> Option<SignedDistancePair> {
        let mut best: Option<SignedDistancePair> = None;
        for part in &human.parts {
            let limit = best.map_or(max_distance_m, |b| b.distance_m.min(max_distance_m));
            if let Some(pair) = self.min_exact_distance_to(kinematics, part, limit)
                && best.is_none_or(|b| pair.distance_m < b.distance_m)
            {
                best = Some(pair);
            }
        }
        best
    }

    /// As [`RobotGeometry::min_exact_distance`] for one part of the human.
    #[must_use]
    pub fn min_exact_distance_to(
        &self,
        kinematics: &KinematicState,
        part: &PartEstimate,
        max_distance_m: f64,
    ) -> Option<SignedDistancePair> {
        let mut best: Option<SignedDistancePair> = None;
        for g in &self.links {
            let X_WL = kinematics.link_pose(g.capsule.link);
            let limit = best.map_or(max_distance_m, |b| b.distance_m.min(max_distance_m));
            let pair = match &g.shape {
                Some(shape) => shape_capsule(
                    g.capsule.link,
                    X_WL,
                    shape.as_ref(),
                    part.part,
                    &part.capsule,
                    limit,
                ),
                None => {
                    let (a_W, b_W) = g.capsule.segment_in_world(X_WL);
                    Some(capsule_capsule(
                        g.capsule.link,
                        &Capsule::new(a_W, b_W, g.capsule.radius_m),
                        part.part,
                        &part.capsule,
                    ))
                }
            };
            if let Some(pair) = pair
                && pair.distance_m <= limit
                && best.is_none_or(|b| pair.distance_m < b.distance_m)
            {
                best = Some(pair);
            }
        }
        best
    }

    /// The smallest capsule-capsule signed distance (robot bounding capsules against the
    /// inflated human capsules): what the filters see.
    #[must_use]
    pub fn min_capsule_distance(
        &self,
        kinematics: &KinematicState,
        human: &HumanEstimate,
    ) -> Option<SignedDistancePair> {
        let mut best: Option<SignedDistancePair> = None;
        for (link, capsule) in self.capsules(kinematics) {
            for (estimate, part) in human.inflated() {
                let pair = capsule_capsule(link, &capsule, estimate.part, &part);
                if best.is_none_or(|b| pair.distance_m < b.distance_m) {
                    best = Some(pair);
                }
            }
        }
        best
    }
}

fn has_moving_ancestor(robot: &RobotModel, link: LinkId) -> bool {
    let mut current = robot.links()[link].parent_joint;
    while let Some(j) = current {
        let joint = &robot.joints()[j];
        if joint.kind.is_movable() {
            return true;
        }
        current = robot.links()[joint.parent].parent_joint;
    }
    false
}
