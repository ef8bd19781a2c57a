//! The human as the safety layer sees it: one capsule per arm part (and the head, where the
//! model has one of its own), with velocities and the uncertainty that perception reports.

pub use workcell_robots::HumanPart;
use workcell_robots::collision::{LinkCapsule, link_bounding_capsule};
use workcell_robots::math::Vector;
use workcell_robots::{Jacobian, KinematicState, LinkId, RobotModel};

use crate::error::{Result, SafetyError};
use crate::geometry::Capsule;

/// One part as estimated: its capsule (not yet inflated) and the velocities of its two axis
/// end points, in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartEstimate {
    pub part: HumanPart,
    pub capsule: Capsule,
    pub v_a_W: Vector,
    pub v_b_W: Vector,
}

impl PartEstimate {
    /// Velocity of the axis point at parameter `t` (exact on the axis of a rigid part: the
    /// velocity field of a rigid body is affine along a line).
    #[must_use]
    #[inline]
    pub fn velocity_at(&self, t: f64) -> Vector {
        self.v_a_W + (self.v_b_W - self.v_a_W) * t
    }

    /// `true` when the capsule and the velocities are finite.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        self.capsule.is_valid() && self.v_a_W.is_finite() && self.v_b_W.is_finite()
    }
}

/// What perception knows about the human at one instant.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct HumanEstimate {
    /// Estimated parts; empty when perception sees no human (the filter then brakes).
    pub parts: Vec<PartEstimate>,
    /// The sensing uncertainty Z_d of ISO/TS 15066, m: every capsule is inflated by it.
    pub uncertainty_m: f64,
    /// How fast the uncertainty grows until the next measurement, m/s (an ageing estimate
    /// of a human who may accelerate): the inflated surface approaches the robot at this
    /// rate on top of the part's own speed, and the barrier rows count it.
    pub uncertainty_rate_m_s: f64,
}

/// At most this many copies of one part along its anticipated path
/// ([`HumanEstimate::anticipate_into`]).
pub const MAX_ANTICIPATED_COPIES: usize = 8;

/// A copy of an estimated part carried along its velocity (anticipation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnticipatedPart {
    /// Index in the estimate's `parts` of the part this copies.
    pub of: usize,
    /// The part where it will be: its capsule moved, its velocities as estimated.
    pub estimate: PartEstimate,
}

impl HumanEstimate {
    /// The inflated capsule of each part.
    pub fn inflated(&self) -> impl Iterator<Item = (&PartEstimate, Capsule)> {
        let margin = self.uncertainty_m;
        self.parts
            .iter()
            .map(move |p| (p, p.capsule.inflated(margin)))
    }

    /// Copies of every part that moves, carried along its end points' velocities to evenly
    /// spaced instants up to `horizon_s` ahead, into `out` (cleared first). The copies of a
    /// part are spaced at most its radius apart (at most [`MAX_ANTICIPATED_COPIES`]), so that
    /// together they cover the path it sweeps if it keeps its velocity; a part that would
    /// move less than a tenth of its radius over the horizon gets none, and so does every
    /// part when the horizon is not positive. Allocates only while `out` grows.
    pub fn anticipate_into(&self, horizon_s: f64, out: &mut Vec<AnticipatedPart>) {
        out.clear();
        if !(horizon_s.is_finite() && horizon_s > 0.0) {
            return;
        }
        for (of, p) in self.parts.iter().enumerate() {
            let travel_m = p.v_a_W.length().max(p.v_b_W.length()) * horizon_s;
            let radius_m = p.capsule.radius_m.max(1e-3);
            if travel_m.is_nan() || travel_m < 0.1 * radius_m {
                continue;
            }
            let copies = ((travel_m / radius_m).ceil() as usize).clamp(1, MAX_ANTICIPATED_COPIES);
            for k in 1..=copies {
                let tau = horizon_s * k as f64 / copies as f64;
                out.push(AnticipatedPart {
                    of,
                    estimate: PartEstimate {
                        capsule: Capsule::new(
                            p.capsule.a_W + p.v_a_W * tau,
                            p.capsule.b_W + p.v_b_W * tau,
                            p.capsule.radius_m,
                        ),
                        ..*p
                    },
                });
            }
        }
    }
}

/// The capsules of a human arm model's parts, in link frames, to turn joint states into
/// [`HumanEstimate`]s.
#[derive(Debug, Clone)]
pub struct HumanGeometry {
    parts: Vec<(HumanPart, LinkCapsule)>,
    jacobian: Jacobian,
}

impl HumanGeometry {
    /// Bounding capsules of the `upper_arm`, `forearm` and `hand` links of `human` (the
    /// catalogue's `human` or `human_arm`, or a model with links of those names), then of its
    /// `head` link when it has one with collision geometry (the catalogue's `human`; the
    /// head of `human_arm` is a part of its torso, which the safety layer does not guard),
    /// then of the left arm's `left_upper_arm`, `left_forearm` and `left_hand` when it has
    /// them all with collision geometry (the catalogue's `human`).
    ///
    /// # Errors
    /// [`SafetyError::Robot`] when an arm part's link is missing or has no collision
    /// geometry.
    pub fn new(human: &RobotModel) -> Result<Self> {
        let mut parts = Vec::with_capacity(HumanPart::ARM.len() + 1);
        for part in HumanPart::ARM {
            let missing = |what: &str| SafetyError::Robot {
                robot: human.name().to_string(),
                message: format!("human part '{part}': {what}"),
            };
            let link: LinkId = human
                .link_id(part.link_name())
                .ok_or_else(|| missing("no link of this name"))?;
            let capsule = link_bounding_capsule(human, link)
                .ok_or_else(|| missing("the link has no collision geometry"))?;
            parts.push((part, capsule));
        }
        if let Some(capsule) = human
            .link_id(HumanPart::Head.link_name())
            .and_then(|link| link_bounding_capsule(human, link))
        {
            parts.push((HumanPart::Head, capsule));
        }
        let left: Option<Vec<(HumanPart, LinkCapsule)>> = (HumanPart::LEFT_ARM.iter())
            .map(|&part| {
                let link = human.link_id(part.link_name())?;
                Some((part, link_bounding_capsule(human, link)?))
            })
            .collect();
        parts.extend(left.into_iter().flatten());
        Ok(Self {
            parts,
            jacobian: Jacobian::zeros(human.dof()),
        })
    }

    /// The parts guarded, in the order of every estimate's `parts`.
    pub fn parts(&self) -> impl Iterator<Item = HumanPart> + '_ {
        self.parts.iter().map(|(p, _)| *p)
    }

    /// The exact estimate of a human in state `kinematics` (forward kinematics done) moving
    /// with joint velocities `qd`: ground truth, zero uncertainty. `out` is overwritten.
    pub fn estimate_into(
        &mut self,
        human: &RobotModel,
        kinematics: &KinematicState,
        qd: &[f64],
        out: &mut HumanEstimate,
    ) {
        out.parts.clear();
        out.uncertainty_m = 0.0;
        out.uncertainty_rate_m_s = 0.0;
        for (part, c) in &self.parts {
            let (a_W, b_W) = c.segment_in_world(kinematics.link_pose(c.link));
            human.point_jacobian(kinematics, c.link, a_W, &mut self.jacobian);
            let v_a_W = self.jacobian.linear_velocity(qd);
            human.point_jacobian(kinematics, c.link, b_W, &mut self.jacobian);
            let v_b_W = self.jacobian.linear_velocity(qd);
            out.parts.push(PartEstimate {
                part: *part,
                capsule: Capsule::new(a_W, b_W, c.radius_m),
                v_a_W,
                v_b_W,
            });
        }
    }
}
