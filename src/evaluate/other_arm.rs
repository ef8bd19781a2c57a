//! The recorded person's other arm: the one a one-armed human model (`human_arm`, a model of
//! one's own) neither has nor follows; the catalogue's `human` has both arms and follows
//! both.
//!
//! A clip records both arms, but the cell's human moves only the arm it models; the robot
//! can come near the other one and nothing sees it, the filter included. To count what the
//! evaluation would otherwise miss, the other arm is placed where the retargeting puts it
//! (`workcell_sim::retarget::RecordedMotion::other_arm`: the recorded directions laid on the
//! model's bones from its mirrored shoulder, in the torso's frame) and its parts are given
//! the modelled arm's sizes: for each part, the capsule of its link laid along the recorded
//! bone (its end points' distances along the link's bone from the joint it hangs from, and
//! its radius; the hand continues the forearm's line). The robot's exact shapes are then
//! measured against those capsules as against the modelled arm's.

use workcell_robots::collision::link_bounding_capsule;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{KinematicState, LinkId, RobotModel};
use workcell_safety::{Capsule, HumanPart, PartEstimate};

/// A part of the other arm: where its capsule lies along its bone, and how thick it is.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PartSize {
    part: HumanPart,
    /// The capsule's end points' distances along the bone from the joint, m.
    along_m: [f64; 2],
    radius_m: f64,
}

/// The other arm's capsules, sized from the modelled arm.
#[derive(Debug, Clone, PartialEq)]
pub struct OtherArm {
    torso: LinkId,
    parts: [PartSize; 3],
}

impl OtherArm {
    /// The sizes of `human`'s arm at its neutral configuration; `None` for a model without
    /// the links `upper_arm`, `forearm` and `hand` with collision geometry, and for one with a
    /// left arm of its own (`left_upper_arm`: the model follows the other arm itself).
    #[must_use]
    pub fn new(human: &RobotModel) -> Option<Self> {
        if human.link_id(HumanPart::LeftUpperArm.link_name()).is_some() {
            return None;
        }
        let links: [LinkId; 3] = [
            human.link_id("upper_arm")?,
            human.link_id("forearm")?,
            human.link_id("hand")?,
        ];
        let torso = human.link_id("torso").unwrap_or(0);
        let mut state = KinematicState::new(human);
        human
            .forward_kinematics(&human.neutral_configuration(), &mut state)
            .ok()?;
        let [s, e, w] = links.map(|l| state.link_pose(l).translation);
        let upper = (e - s).try_normalize()?;
        let fore = (w - e).try_normalize()?;
        let size = |part: HumanPart, link: LinkId, joint: Vector, bone: Vector| {
            let c = link_bounding_capsule(human, link)?;
            let (a, b) = c.segment_in_world(state.link_pose(link));
            Some(PartSize {
                part,
                along_m: [(a - joint).dot(bone), (b - joint).dot(bone)],
                radius_m: c.radius_m,
            })
        };
        Some(Self {
            torso,
            parts: [
                size(HumanPart::LeftUpperArm, links[0], s, upper)?,
                size(HumanPart::LeftForearm, links[1], e, fore)?,
                size(HumanPart::LeftHand, links[2], w, fore)?,
            ],
        })
    }

    /// The link the other arm's points are given in (`torso`, the root without one).
    #[must_use]
    pub fn torso(&self) -> LinkId {
        self.torso
    }

    /// The other arm's parts into `out` (cleared; at rest: their velocity is not measured),
    /// from its shoulder, elbow and wrist `joints_T` in the torso frame placed at `X_WT`.
    pub fn place_into(&self, X_WT: &Pose, joints_T: [Vector; 3], out: &mut Vec<PartEstimate>) {
        out.clear();
        let [s, e, w] = joints_T.map(|p| X_WT.transform_point(p));
        let (Some(upper), Some(fore)) = ((e - s).try_normalize(), (w - e).try_normalize()) else {
            return; // a bone of no length: no direction to lay a part along
        };
        for (size, joint, bone) in [
            (&self.parts[0], s, upper),
            (&self.parts[1], e, fore),
            (&self.parts[2], w, fore),
        ] {
            let [a, b] = size.along_m.map(|d| joint + bone * d);
            out.push(PartEstimate {
                part: size.part,
                capsule: Capsule::new(a, b, size.radius_m),
                v_a_W: Vector::ZERO,
                v_b_W: Vector::ZERO,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Placed where the modelled arm is (its own shoulder, elbow and wrist in the torso
    /// frame), the other arm's capsules are the modelled arm's, to rounding: the sizes are
    /// the arm's own and the bone lines are where its capsules lie.
    #[test]
    fn placed_on_the_modelled_arm_the_parts_are_its_capsules() {
        // The two-armed catalogue human follows its left arm itself: no other arm.
        let human = RobotModel::from_catalogue("human").expect("catalogue");
        assert!(OtherArm::new(&human).is_none());
        // The one-armed human: the two-armed one without its left arm.
        let one = RobotModel::one_armed_human().expect("one-armed");
        assert_eq!(one.dof() + 5, human.dof());
        let human = one;
        let arm = OtherArm::new(&human).expect("an arm");
        let mut geometry = workcell_safety::HumanGeometry::new(&human).expect("geometry");
        let mut state = KinematicState::new(&human);
        let mut q = human.neutral_configuration();
        // Bend the elbow and lift the arm: the capsules must follow the bones, not the rest.
        for (name, v) in [("shoulder_flexion", 0.7), ("elbow_flexion", 1.1)] {
            let j = human
                .actuated_joints()
                .iter()
                .position(|&j| human.joints()[j].name == name)
                .expect(name);
            q[j] = v;
        }
        human.forward_kinematics(&q, &mut state).expect("fk");
        let mut truth = workcell_safety::HumanEstimate::default();
        geometry.estimate_into(&human, &state, &vec![0.0; human.dof()], &mut truth);
        let X_WT = *state.link_pose(arm.torso());
        let joints_T = ["upper_arm", "forearm", "hand"].map(|l| {
            let p = state.link_pose(human.link_id(l).expect(l)).translation;
            X_WT.inverse_transform_point(p)
        });
        let mut placed = Vec::new();
        arm.place_into(&X_WT, joints_T, &mut placed);
        assert_eq!(placed.len(), 3);
        for p in &placed {
            assert_eq!(p.part.side(), Some(workcell_robots::Side::Left));
            let t = truth
                .parts
                .iter()
                .find(|t| t.part == p.part.mirrored())
                .expect("the part is modelled");
            for (got, want) in [
                (p.capsule.a_W, t.capsule.a_W),
                (p.capsule.b_W, t.capsule.b_W),
            ] {
                assert!(
                    (got - want).length() < 1e-6,
                    "{:?}: {got:?} against {want:?}",
                    p.part
                );
            }
            assert_eq!(p.capsule.radius_m, t.capsule.radius_m);
        }
        // A bone of no length has no direction: no parts rather than a guess.
        arm.place_into(&X_WT, [joints_T[0]; 3], &mut placed);
        assert!(placed.is_empty());
    }
}
