//! The errors of one estimate, one evaluated frame, and the statistics of a group of frames.

use workcell_robots::math::{Pose, Vector, pose_to_xyz_rpy};

use crate::pose::{NoPose, RigidModel};

/// The errors of one estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseError {
    /// At the forearm's centre, cm.
    pub position_cm: f64,
    /// Absolute differences of the URDF angles, degrees.
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    /// The angle between the axes, degrees.
    pub axis_deg: f64,
    /// Rotation about the forearm's own axis, degrees.
    pub spin_deg: f64,
    /// The end-for-end twin was the nearer.
    pub flipped: bool,
    /// The larger error of the forearm axis's two ends, cm: the estimate covers the true
    /// forearm when this is within its uncertainty.
    pub ends_cm: f64,
}

/// The errors of `estimate` against `truth` (see the module docs), of the estimate or its
/// end-for-end twin, whichever is nearer: a forearm's mask alone cannot tell them apart.
#[must_use]
pub fn pose_error(model: &RigidModel, estimate: &Pose, truth: &Pose) -> PoseError {
    pose_error_with(model, estimate, truth, true)
}

/// The errors of `estimate` against `truth`; with `twin` false, of the estimate itself
/// (when the hand tells the wrist from the elbow), and [`PoseError::flipped`] says whether
/// its ends are swapped.
#[must_use]
pub fn pose_error_with(model: &RigidModel, estimate: &Pose, truth: &Pose, twin: bool) -> PoseError {
    let other = model.twin(estimate);
    // The twin whose axis points the truth's way (spin is weakly seen; the axis is not).
    let along = |X: &Pose| (X.rotation * model.axis_O).dot(truth.rotation * model.axis_O);
    let flipped = along(&other) > along(estimate);
    let X = if flipped && twin { other } else { *estimate };
    let (_, e) = pose_to_xyz_rpy(&X);
    let (_, t) = pose_to_xyz_rpy(truth);
    let wrap = |a: f64| (a.sin().atan2(a.cos())).abs().to_degrees();
    let (u, v) = (X.rotation * model.axis_O, truth.rotation * model.axis_O);
    // The spin: the twist about the axis of the relative rotation (swing-twist split).
    let rel = truth.rotation.inverse() * X.rotation;
    let a = model.axis_O;
    let p = Vector::new(rel.x, rel.y, rel.z).dot(a);
    let spin = 2.0 * p.atan2(rel.w);
    let half = 0.5 * model.length_m * model.axis_O;
    let ends_cm = [half, -half]
        .iter()
        .map(|&h| {
            let end = |P: &Pose| P.transform_point(model.centre_O + h);
            100.0 * (end(&X) - end(truth)).length()
        })
        .fold(0.0, f64::max);
    PoseError {
        position_cm: 100.0 * (model.centre(&X) - model.centre(truth)).length(),
        ends_cm,
        yaw_deg: wrap(e[2] - t[2]),
        pitch_deg: wrap(e[1] - t[1]),
        roll_deg: wrap(e[0] - t[0]),
        axis_deg: u.dot(v).clamp(-1.0, 1.0).acos().to_degrees(),
        spin_deg: wrap(spin),
        flipped,
    }
}

/// One evaluated frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    pub sequence: usize,
    pub frame: usize,
    /// The sequence plays a recorded person (its manifest entry names a clip), not the
    /// motion generator.
    pub recorded: bool,
    pub distance_class: String,
    pub occlusion_level: String,
    /// The true forearm centre's distance from the camera, m.
    pub distance_m: f64,
    /// The forearm's occlusion in this frame (0 to 1).
    pub occlusion: f64,
    /// The errors, or why there was no pose.
    pub outcome: std::result::Result<PoseError, NoPose>,
    pub reacquired: bool,
    /// The articulated fit's gain was below its threshold and the frame before confirmed
    /// the pose ([`crate::pose::ArmFit::confirmed`]; false for the paper's method).
    pub confirmed: bool,
    pub f_m: f64,
    pub gain: f64,
    pub uncertainty_m: f64,
    /// The articulated fit's curvature spread and hypotheses' spread, m (NaN for the paper's
    /// method and for frames without a pose): what the calibration's radius is made of.
    pub sigma_m: f64,
    pub spread_m: f64,
    /// The articulated fit's share of the forearm's region hidden by something in front of
    /// the arm ([`crate::pose::ArmFit::hidden_share`]; NaN as `sigma_m`): the calibration's
    /// floor depends on it.
    pub hidden_share: f64,
    /// Time of the pose search (not the network), ms.
    pub pose_ms: f64,
    /// Time of the mask source (the network), ms.
    pub mask_ms: f64,
    pub renders: usize,
    /// The articulated fit's gain at the true joint positions: all parts, then the upper
    /// arm's, the forearm's and the hand's shares (NaN for the paper's method).
    pub truth_gain: [f64; 4],
    /// The fitted trunk against the labels' ([`crate::pose::TrunkModel::error`]): the
    /// largest revolute joint's error, rad, and the pelvis's offset, m; NaN without a pose,
    /// for a torso that does not move and for the paper's method.
    pub trunk_error: [f64; 2],
}

impl FrameResult {
    /// The frame is of this distance class and occlusion level; `None` matches every value.
    #[must_use]
    pub fn is_in(&self, distance: Option<&str>, level: Option<&str>) -> bool {
        distance.is_none_or(|d| self.distance_class == d)
            && level.is_none_or(|l| self.occlusion_level == l)
    }
}

/// Statistics of a group of frames.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    pub frames: usize,
    pub no_pose: usize,
    pub reacquired: usize,
    pub position_cm: f64,
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    pub axis_deg: f64,
    pub spin_deg: f64,
    pub flipped: usize,
    /// Frames with a pose whose uncertainty covers both ends of the true forearm.
    pub within_bound: usize,
}

impl Summary {
    pub(super) fn of<'a>(frames: impl Iterator<Item = &'a FrameResult>) -> Summary {
        let mut s = Summary::default();
        for f in frames {
            s.frames += 1;
            s.reacquired += usize::from(f.reacquired);
            match &f.outcome {
                Ok(e) => {
                    s.position_cm += e.position_cm;
                    s.yaw_deg += e.yaw_deg;
                    s.pitch_deg += e.pitch_deg;
                    s.roll_deg += e.roll_deg;
                    s.axis_deg += e.axis_deg;
                    s.spin_deg += e.spin_deg;
                    s.flipped += usize::from(e.flipped);
                    s.within_bound += usize::from(e.ends_cm <= 100.0 * f.uncertainty_m);
                }
                Err(_) => s.no_pose += 1,
            }
        }
        let n = (s.frames - s.no_pose) as f64;
        if n > 0.0 {
            for v in [
                &mut s.position_cm,
                &mut s.yaw_deg,
                &mut s.pitch_deg,
                &mut s.roll_deg,
                &mut s.axis_deg,
                &mut s.spin_deg,
            ] {
                *v /= n;
            }
        } else {
            // No pose in the group: no error to average (not zero degrees).
            for v in [
                &mut s.position_cm,
                &mut s.yaw_deg,
                &mut s.pitch_deg,
                &mut s.roll_deg,
                &mut s.axis_deg,
                &mut s.spin_deg,
            ] {
                *v = f64::NAN;
            }
        }
        s
    }
}
