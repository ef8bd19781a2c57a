//! The human's arm as the pose search sees it: [`ArmModel`] is the forearm-only view of a
//! human model that the paper's method ([`crate::pose::PoseEstimator`]) needs (the forearm's
//! mesh, the fixed shoulder it hangs from, the reach that bounds the workspace), and places
//! every part of the arm where a forearm pose puts it. The parts are sized from the human
//! model (the bounding capsules of its links' collision geometry, as the safety layer sizes
//! them), never from the true human.

use std::sync::Arc;

use workcell_render::RenderMesh;
use workcell_robots::collision::link_bounding_capsule;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{HumanPart, JointKind, LinkId, RobotModel, Side};

use super::{Anchor, RigidModel};
use crate::error::{PerceptionError, Result};

/// Segments around round shapes in the pose search's forearm mesh: the search renders the
/// forearm thousands of times a second, and a hexagon of a 1-2 pixel bone is its circle to a
/// hundredth of a pixel.
pub const POSE_MESH_SEGMENTS: usize = 6;

/// One part's capsule in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartCapsule {
    pub part: HumanPart,
    pub a_W: Vector,
    pub b_W: Vector,
    pub radius_m: f64,
}

/// How a part follows the forearm's pose.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Placement {
    /// Its capsule's end points in the forearm link's frame F.
    Rigid { a_F: Vector, b_F: Vector },
    /// From the fixed shoulder to the elbow (the forearm frame's origin).
    ShoulderToElbow,
}

/// The arm of a human model as perception sees it.
#[derive(Debug, Clone)]
pub struct ArmModel {
    /// The forearm, as the pose search renders it (object frame = the forearm link's frame).
    pub forearm: RigidModel,
    /// The shoulder in the world and the upper arm's length (shoulder to elbow), when the
    /// shoulder stays put whatever the joints do (a human whose torso does not move).
    pub shoulder_W: Option<(Vector, f64)>,
    /// The shoulder in the world and the upper arm's length with every joint at zero (clamped
    /// to its limits): where a human whose trunk moves stands at rest.
    pub rest_shoulder_W: (Vector, f64),
    /// The arm's parts in [`HumanPart::ARM`] order (the left arm's: [`HumanPart::LEFT_ARM`]),
    /// with their radii.
    parts: Vec<(HumanPart, Placement, f64)>,
}

impl ArmModel {
    /// The arm of `human` standing with its base at `X_WH`.
    ///
    /// The shoulder is the origin of the forearm's parent link (the upper arm) when it stays
    /// within a micrometre at three configurations: every joint at its lower limit, at the
    /// middle of its range, and at its upper limit (limits clamped to +-3 rad). Parts below
    /// the forearm that hang from it by joints that move are placed at their joints' zero
    /// (clamped to the limits).
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when a part of the arm has no link of its name, no
    /// collision geometry, or the forearm has no visual geometry.
    pub fn new(human: &RobotModel, X_WH: &Pose) -> Result<Self> {
        Self::of_side(human, X_WH, Side::Right)
    }

    /// The arm on `side` of `human` (the left arm's parts: [`HumanPart::LEFT_ARM`]).
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn of_side(human: &RobotModel, X_WH: &Pose, side: Side) -> Result<Self> {
        let arm_parts = match side {
            Side::Right => HumanPart::ARM,
            Side::Left => HumanPart::LEFT_ARM,
        };
        let [upper_arm, forearm_part, _] = arm_parts;
        let missing = |message: String| PerceptionError::Input {
            message: format!("human model {}: {message}", human.name()),
        };
        let link = |part: HumanPart| {
            human
                .link_id(part.link_name())
                .ok_or_else(|| missing(format!("no link named {part}")))
        };
        let forearm = link(forearm_part)?;
        let mut mesh = RenderMesh::default();
        for g in &human.links()[forearm].visuals {
            mesh.append(
                &RenderMesh::from_geometry_with(g, [0.85, 0.72, 0.62], POSE_MESH_SEGMENTS),
                &Pose::IDENTITY,
            );
        }
        if mesh.is_empty() {
            return Err(missing("the forearm link has no visual geometry".into()));
        }
        let model = RigidModel::new(Arc::new(mesh))?;
        let limits = human.position_limits();
        let at = |c: f64| -> Vec<f64> {
            limits
                .iter()
                .map(|&[lo, hi]| {
                    let (lo, hi) = (lo.max(-3.0), hi.min(3.0));
                    lo + c * (hi - lo)
                })
                .collect()
        };
        let parent = human.links()[forearm]
            .parent_joint
            .map(|j| human.joints()[j].parent);
        let mut points = Vec::new();
        for c in [0.0, 0.5, 1.0] {
            if let (Some(parent), Ok(k)) = (parent, human.fk(*X_WH, &at(c))) {
                let poses = k.link_poses();
                points.push((poses[parent].translation, poses[forearm].translation));
            }
        }
        let fixed = points.len() == 3
            && points
                .iter()
                .all(|(s, _)| (*s - points[0].0).length() < 1e-6);
        let shoulder_W = fixed.then(|| (points[0].0, (points[0].1 - points[0].0).length()));

        let q_ref: Vec<f64> = limits
            .iter()
            .map(|&[lo, hi]| 0.0_f64.clamp(lo, hi))
            .collect();
        let reference = human.fk(*X_WH, &q_ref)?;
        let X_FW = reference.link_pose(forearm).inverse();
        let rest_shoulder_W = {
            let s = reference.link_pose(link(upper_arm)?).translation;
            (s, (reference.link_pose(forearm).translation - s).length())
        };
        let mut parts = Vec::with_capacity(HumanPart::ARM.len());
        for part in arm_parts {
            let l = link(part)?;
            let capsule = link_bounding_capsule(human, l)
                .ok_or_else(|| missing(format!("the {part} link has no collision geometry")))?;
            let placement = if part == upper_arm && shoulder_W.is_some() {
                Placement::ShoulderToElbow
            } else {
                let X_FL = X_FW * *reference.link_pose(l);
                if !rigid_with(human, l, forearm) && part != upper_arm {
                    tracing::debug!("{part} moves against the forearm; placed at q = 0");
                }
                Placement::Rigid {
                    a_F: X_FL.transform_point(capsule.a_L),
                    b_F: X_FL.transform_point(capsule.b_L),
                }
            };
            parts.push((part, placement, capsule.radius_m));
        }
        Ok(Self {
            forearm: model,
            shoulder_W,
            rest_shoulder_W,
            parts,
        })
    }

    /// The elbow-on-shoulder-sphere anchor for a camera at `X_WC`, if the shoulder is fixed.
    #[must_use]
    pub fn anchor(&self, X_WC: &Pose) -> Option<Anchor> {
        self.shoulder_W.map(|(s, r)| Anchor {
            end_O: Vector::ZERO,
            point_C: X_WC.inverse().transform_point(s),
            radius_m: r,
            sigma_m: 0.02,
        })
    }

    /// How far the wrist can be from the shoulder: the upper arm's length plus the forearm
    /// capsule's far end from the elbow (the upper arm's length at rest where the shoulder
    /// moves).
    #[must_use]
    pub fn reach_m(&self) -> Option<f64> {
        let forearm = self
            .parts
            .iter()
            .find_map(|(part, placement, _)| match placement {
                Placement::Rigid { a_F, b_F } if part.limb() == HumanPart::Forearm => {
                    Some(a_F.length().max(b_F.length()))
                }
                _ => None,
            })?;
        let (_, upper) = self.shoulder_W.unwrap_or(self.rest_shoulder_W);
        Some(upper + forearm)
    }

    /// The arm's capsules in the world with the forearm link's frame at `X_WF`.
    #[must_use]
    pub fn parts(&self, X_WF: &Pose) -> Vec<PartCapsule> {
        self.parts
            .iter()
            .map(|&(part, placement, radius_m)| {
                let (a_W, b_W) = match placement {
                    Placement::Rigid { a_F, b_F } => {
                        (X_WF.transform_point(a_F), X_WF.transform_point(b_F))
                    }
                    Placement::ShoulderToElbow => (
                        self.shoulder_W.map_or(X_WF.translation, |(s, _)| s),
                        X_WF.translation,
                    ),
                };
                PartCapsule {
                    part,
                    a_W,
                    b_W,
                    radius_m,
                }
            })
            .collect()
    }
}

/// Whether `link` is `base` or hangs from it by fixed joints only.
fn rigid_with(model: &RobotModel, mut link: LinkId, base: LinkId) -> bool {
    while link != base {
        let Some(j) = model.links()[link].parent_joint else {
            return false;
        };
        let joint = &model.joints()[j];
        if joint.kind != JointKind::Fixed {
            return false;
        }
        link = joint.parent;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_robots::PackageMap;
    use workcell_robots::math::pose_from_xyz_rpy;

    /// The built-in human in its default (flesh) look.
    fn human() -> RobotModel {
        let mut human = RobotModel::from_catalogue("human_arm").expect("catalogue human");
        human.retain_visuals(|g| workcell_robots::HumanLook::Flesh.shows(g.name.as_deref()));
        human
    }

    #[test]
    fn the_built_in_human_hangs_its_forearm_from_a_fixed_shoulder() {
        let X_WH = pose_from_xyz_rpy([1.2, 0.4, 0.1], [0.0, 0.0, 2.5]);
        let arm = ArmModel::new(&human(), &X_WH).expect("arm");
        let (shoulder, radius) = arm.shoulder_W.expect("a fixed shoulder");
        // robots/urdf/human_arm/human_arm.urdf: elbow_flexion at z = -0.3255 in the upper
        // arm, shoulder_abduction at (0, -0.19, 0.48) in the torso.
        assert!((radius - 0.3255).abs() < 1e-12, "{radius}");
        let expected = X_WH.transform_point(Vector::new(0.0, -0.19, 0.48));
        assert!(
            (shoulder - expected).length() < 1e-12,
            "{shoulder} vs {expected}"
        );
        // In a camera's frame.
        let X_WC = pose_from_xyz_rpy([1.0, 2.0, 1.5], [0.3, -0.2, 2.0]);
        let anchor = arm.anchor(&X_WC).expect("anchor");
        assert!((X_WC.transform_point(anchor.point_C) - shoulder).length() < 1e-12);
    }

    /// At any joint configuration, the parts rebuilt from the true forearm pose are the
    /// model's own capsules there: forearm and hand carried with the forearm (the wrist is
    /// fixed), the upper arm from the shoulder to the elbow, radii from the collision geometry.
    #[test]
    fn parts_from_the_true_forearm_pose_are_the_model_s_capsules() {
        let human = human();
        let X_WH = pose_from_xyz_rpy([0.9, -0.3, 0.0], [0.0, 0.0, 0.7]);
        let arm = ArmModel::new(&human, &X_WH).expect("arm");
        let forearm = human.link_id("forearm").expect("forearm");
        for q in [[0.0, 0.0, 0.0], [0.8, 1.2, 1.9], [2.2, -0.5, 0.3]] {
            let k = human.fk(X_WH, &q).expect("fk");
            let parts = arm.parts(k.link_pose(forearm));
            let order: Vec<HumanPart> = parts.iter().map(|p| p.part).collect();
            assert_eq!(order, HumanPart::ARM);
            for p in &parts {
                let link = human.link_id(p.part.link_name()).expect("link");
                let c = link_bounding_capsule(&human, link).expect("capsule");
                assert!((p.radius_m - c.radius_m).abs() < 1e-15, "{p:?}");
                let (a, b) = match p.part {
                    HumanPart::UpperArm => (
                        arm.shoulder_W.expect("shoulder").0,
                        k.link_pose(forearm).translation,
                    ),
                    _ => c.segment_in_world(k.link_pose(link)),
                };
                assert!((p.a_W - a).length() < 1e-12, "{p:?} at {q:?}");
                assert!((p.b_W - b).length() < 1e-12, "{p:?} at {q:?}");
            }
        }
    }

    #[test]
    fn a_human_without_a_forearm_or_a_manifest_without_a_human_is_an_error() {
        let urdf = r#"<robot name="stump"><link name="torso"/></robot>"#;
        let stump =
            RobotModel::from_urdf_str(urdf, std::path::Path::new("stump.urdf"), &PackageMap::new())
                .expect("a one-link model");
        let err = ArmModel::new(&stump, &Pose::IDENTITY).unwrap_err();
        assert!(err.to_string().contains("no link named forearm"), "{err}");
    }
}
