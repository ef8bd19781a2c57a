//! Retargeting a recorded clip onto the cell's human model: the recorded trunk and arm
//! become joint angles of the model.
//!
//! 1. The clip is cleaned of capture artefacts and its longest piece kept
//!    (`workcell_mocap::clean`), then each landmark is low-pass filtered (zero phase,
//!    `cutoff_hz`, 6 Hz by default; `workcell_mocap::filter`).
//! 2. Each frame's torso frame: y from the right shoulder to the left, z up (from the pelvis
//!    to the neck where the clip has them, the recording's up otherwise) made orthogonal to
//!    y, x = y x z (forward). The model's base faces +x with z up (`human.base`): the person
//!    stands there, facing the way they face at the first frame.
//! 3. A model with a trunk of its own (the catalogue's `human`: `pelvis_x`, `pelvis_y`,
//!    `trunk_turn`, `trunk_lean`, `trunk_side`) follows the recording's: the torso frame
//!    relative to the first frame's heading, as turn, lean and side bend (z-y-x angles), and
//!    the pelvis's travel over the floor where the clip has a pelvis. A model without one
//!    (`human_arm`) keeps its torso where it stands.
//! 4. The followed side's upper arm and forearm directions, in the torso frame, are laid on
//!    the model's bones from the model's shoulder in its torso: elbow and wrist targets the
//!    model's arm can reach whatever the person's size. The other side's, laid the same way
//!    from the model's shoulder mirrored across the torso's x-z plane, are the targets of the
//!    model's left arm where it has one (the catalogue's `human`: `left_upper_arm`,
//!    `left_forearm`, `left_hand`), and otherwise `RecordedMotion::other_arm` only.
//! 5. Damped least squares of each arm's joints (those on its chain from the torso) on both
//!    its targets (the wrist weighted 1, the
//!    elbow `elbow_weight`), from the previous frame's solution, within the joint limits. A
//!    shoulder of three joints reaches both targets; a two-joint shoulder (`human_arm`)
//!    cannot turn the arm about its own axis and leaves an error, which the report states.
//!    The forearm's rotation is not seen in shoulder, elbow and wrist positions: it stays at
//!    the middle of its range.
//! 6. From frame to frame no joint moves faster than the model's velocity limit; the frames
//!    where that held a joint back are counted.

use serde::{Deserialize, Serialize};
use workcell_mocap::clean::{CleanConfig, clean};
use workcell_mocap::filter::{Butterworth2, DEFAULT_CUTOFF_HZ, filter_track};
use workcell_mocap::stats::Spread;
use workcell_mocap::{Clip, Landmark};
use workcell_robots::math::Vector;
use workcell_robots::{Jacobian, KinematicState, LinkId, RobotModel};

use crate::error::{Result, SimError};

/// The side of the recorded person the model's (right) arm follows; the model's left arm, where
/// it has one, follows the other.
pub use workcell_robots::Side;

/// A side's shoulder, elbow and wrist in a recording.
fn landmarks(side: Side) -> [Landmark; 3] {
    match side {
        Side::Left => [
            Landmark::LeftShoulder,
            Landmark::LeftElbow,
            Landmark::LeftWrist,
        ],
        Side::Right => [
            Landmark::RightShoulder,
            Landmark::RightElbow,
            Landmark::RightWrist,
        ],
    }
}

/// How a clip is retargeted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RetargetConfig {
    /// The recorded arm the model's arm follows (the catalogue's `human_arm` is a right arm).
    /// Default `right`.
    pub side: Side,
    /// Cut-off of the low-pass on the recorded positions, Hz. Default 6.
    pub cutoff_hz: f64,
    /// Weight of the elbow's target against the wrist's in the fit: where the model's joints
    /// cannot follow both (a 2-joint shoulder cannot turn the arm about its own axis), a small
    /// weight keeps the hand, the part that meets the robot first, on the recording. Default
    /// 0.05; a 3-joint shoulder reaches both, and the weight only matters at a joint limit.
    pub elbow_weight: f64,
}

impl Default for RetargetConfig {
    fn default() -> Self {
        Self {
            side: Side::Right,
            cutoff_hz: DEFAULT_CUTOFF_HZ,
            elbow_weight: 0.05,
        }
    }
}

/// Joint trajectories of the model's arm, at the clip's rate.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedMotion {
    /// The clip's id.
    pub name: String,
    pub rate_hz: f64,
    /// Joint positions, frame by frame (`frames x dof`).
    pub q: Vec<Vec<f64>>,
    /// The arm the model does not follow (the recording's other side), frame by frame: its
    /// shoulder, elbow and wrist in the model's `torso` frame (its root without one), placed
    /// as the followed arm's targets are (step 4 of the module's summary: the model's
    /// shoulder mirrored across the torso's sagittal plane, the recorded directions laid on
    /// the model's bones). Empty where the clip lacks that side's elbow or wrist. Nothing
    /// drives or perceives this arm: an evaluation measures only how near the robot it came.
    pub other_arm: Vec<[Vector; 3]>,
}

impl RecordedMotion {
    /// Frames in the motion.
    #[must_use]
    pub fn frames(&self) -> usize {
        self.q.len()
    }

    /// Length, s.
    #[must_use]
    pub fn duration_s(&self) -> f64 {
        self.frames().saturating_sub(1) as f64 / self.rate_hz
    }

    /// Joint positions and velocities at `t_s` in `[0, duration]` (clamped), linearly
    /// between frames: the velocity is the segment's.
    pub fn sample(&self, t_s: f64, q: &mut [f64], qd: &mut [f64]) {
        let Some((i, j, s)) = self.between(t_s, self.frames()) else {
            return;
        };
        let (a, b) = (&self.q[i], &self.q[j]);
        for j in 0..q.len().min(a.len()) {
            q[j] = a[j] + (b[j] - a[j]) * s;
            qd[j] = (b[j] - a[j]) * self.rate_hz;
        }
    }

    /// The other arm's shoulder, elbow and wrist ([`Self::other_arm`]) at `t_s` in `[0,
    /// duration]` (clamped), linearly between frames; `None` without that arm.
    #[must_use]
    pub fn other_arm_at(&self, t_s: f64) -> Option<[Vector; 3]> {
        let (i, j, s) = self.between(t_s, self.other_arm.len())?;
        let (a, b) = (&self.other_arm[i], &self.other_arm[j]);
        Some(std::array::from_fn(|k| a[k] + (b[k] - a[k]) * s))
    }

    /// The frames `t_s` (clamped to `[0, duration]`) lies between in a track of `frames`
    /// frames at the motion's rate, and how far from the first to the second (0 to 1);
    /// `None` for an empty track.
    fn between(&self, t_s: f64, frames: usize) -> Option<(usize, usize, f64)> {
        let last = frames.checked_sub(1)?;
        let x = (t_s * self.rate_hz).clamp(0.0, last as f64);
        let i = (x.floor() as usize).min(last.saturating_sub(1));
        Some((i, (i + 1).min(last), x - i as f64))
    }
}

/// What retargeting did to a clip.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RetargetReport {
    pub clip: String,
    pub side: Side,
    /// Frames retargeted (the longest clean piece) and frames of the clip.
    pub frames: usize,
    pub clip_frames: usize,
    /// Distance of the model's wrist and elbow from their targets (the recorded directions
    /// on the model's bones), m.
    pub wrist_error_m: Spread,
    pub elbow_error_m: Spread,
    /// The model's left wrist's distance from the other arm's target, m, where the model has
    /// a left arm and the clip the other side.
    pub left_wrist_error_m: Option<Spread>,
    /// Frames where a joint stopped at its position limit.
    pub clamped_frames: usize,
    /// Frames where a joint was held back by its velocity limit.
    pub velocity_limited_frames: usize,
    /// Each joint's speed from solved frame to solved frame before the velocity limits,
    /// rad/s (m/s for a prismatic joint), in the model's joint order: what the limits must
    /// cover for the retargeted motion to be the recorded one.
    pub joint_speed: Vec<Spread>,
    /// The recorded person's upper arm and forearm, median length, m, and the model's.
    pub recorded_bones_m: [f64; 2],
    pub model_bones_m: [f64; 2],
    /// How far the model's trunk followed the recording's, when it has joints to: the
    /// largest turn, lean and side bend either way, degrees, and the pelvis's farthest
    /// travel from where it started, m.
    pub trunk: Option<TrunkReport>,
}

/// The model's trunk over a retargeted clip.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrunkReport {
    pub turn_deg: [f64; 2],
    pub lean_deg: [f64; 2],
    pub side_deg: [f64; 2],
    pub pelvis_travel_m: f64,
}

/// The joints of a model's trunk, by their index in a configuration: pelvis x and y, turn,
/// lean, side bend (`None` for those the model lacks).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrunkJoints(pub [Option<usize>; 5]);

impl TrunkJoints {
    /// The joints' names, in order.
    pub const NAMES: [&'static str; 5] = [
        "pelvis_x",
        "pelvis_y",
        "trunk_turn",
        "trunk_lean",
        "trunk_side",
    ];

    /// The trunk joints `model` has.
    #[must_use]
    pub fn of(model: &RobotModel) -> Self {
        Self(Self::NAMES.map(|name| {
            model
                .actuated_joints()
                .iter()
                .position(|&j| model.joints()[j].name == name)
        }))
    }

    fn any(&self) -> bool {
        self.0.iter().any(Option::is_some)
    }

    fn contains(&self, j: usize) -> bool {
        self.0.contains(&Some(j))
    }

    /// Writes `values` (pelvis x, y, turn, lean, side) into `q`.
    pub fn set(&self, q: &mut [f64], values: [f64; 5]) {
        for (j, v) in self.0.iter().zip(values) {
            if let Some(j) = *j {
                q[j] = v;
            }
        }
    }
}

/// Turn, lean and side bend (z-y-x angles) of the rotation with columns `r`, rad.
fn trunk_angles(r: [Vector; 3]) -> [f64; 3] {
    // r = Rz(turn) Ry(lean) Rx(side): r[0] = (c_t c_l, s_t c_l, -s_l),
    // r[1].z = c_l s_s, r[2].z = c_l c_s.
    let turn = r[0].y.atan2(r[0].x);
    let lean = (-r[0].z).clamp(-1.0, 1.0).asin();
    let side = r[1].z.atan2(r[2].z);
    // Rx about +x turns z toward -y: a positive angle bends to the right (-y), as the
    // model's `trunk_side` does.
    [turn, lean, side]
}

/// The model's links a recorded arm drives: the shoulder (`upper_arm`'s origin), the elbow
/// (`forearm`'s) and the wrist (`hand`'s).
fn arm_links(model: &RobotModel) -> Result<[LinkId; 3]> {
    let find = |name: &str| {
        model.link_id(name).ok_or_else(|| SimError::Invalid {
            path: None,
            key: "human.model".into(),
            message: format!(
                "{} has no link `{name}`: a recorded arm drives the links upper_arm, forearm \
                 and hand",
                model.name()
            ),
        })
    };
    Ok([find("upper_arm")?, find("forearm")?, find("hand")?])
}

/// The links of the model's left arm (`left_upper_arm`, `left_forearm`, `left_hand`), where
/// it has one.
fn left_arm_links(model: &RobotModel) -> Option<[LinkId; 3]> {
    Some([
        model.link_id("left_upper_arm")?,
        model.link_id("left_forearm")?,
        model.link_id("left_hand")?,
    ])
}

/// Which of the model's coordinates move `link`: the movable joints on its chain from the
/// root, by their index in a configuration.
fn chain_dofs(model: &RobotModel, link: LinkId) -> Vec<bool> {
    let mut on = vec![false; model.dof()];
    for j in model.joints_above(link) {
        if let workcell_robots::Coordinate::Own { index } = model.joints()[j].coordinate {
            on[index] = true;
        }
    }
    on
}

/// Filtered tracks by landmark.
type Tracks = std::collections::BTreeMap<Landmark, Vec<Vector>>;

/// The torso's axes in the recording at frame `f`: forward, left, up.
fn torso(tracks: &Tracks, f: usize) -> Option<[Vector; 3]> {
    let l = tracks.get(&Landmark::LeftShoulder)?.get(f)?;
    let r = tracks.get(&Landmark::RightShoulder)?.get(f)?;
    let y = (*l - *r).normalize_or_zero();
    let up = match (tracks.get(&Landmark::Pelvis), tracks.get(&Landmark::Neck)) {
        (Some(p), Some(n)) => n[f] - p[f],
        _ => Vector::Z,
    };
    let z = (up - y * up.dot(y)).normalize_or_zero();
    if y == Vector::ZERO || z == Vector::ZERO {
        return None;
    }
    Some([y.cross(z), y, z])
}

/// Retargets `clip` onto `model` (the human's model, its base frame the torso's).
///
/// # Errors
/// [`SimError::Invalid`] when the clip lacks the followed side's shoulder, elbow or wrist or
/// the other shoulder, nothing of it is left after cleaning, the cut-off is not below half
/// its rate, or the model lacks the arm's links.
pub fn retarget(
    clip: &Clip,
    model: &RobotModel,
    config: &RetargetConfig,
) -> Result<(RecordedMotion, RetargetReport)> {
    let invalid = |message: String| SimError::Invalid {
        path: None,
        key: "human.recorded".into(),
        message: format!("{}: {message}", clip.name),
    };
    let [shoulder, elbow, wrist] = landmarks(config.side);
    for l in [
        shoulder,
        elbow,
        wrist,
        Landmark::LeftShoulder,
        Landmark::RightShoulder,
    ] {
        if clip.column(l).is_none() {
            return Err(invalid(format!("the clip has no {}", l.name())));
        }
    }
    let (pieces, _) = clean(clip, &CleanConfig::default());
    let piece = pieces
        .into_iter()
        .max_by_key(Clip::frames)
        .ok_or_else(|| invalid("nothing is left after its capture artefacts".into()))?;
    let filter = Butterworth2::low_pass(config.cutoff_hz, piece.rate_hz).ok_or_else(|| {
        invalid(format!(
            "a {} Hz cut-off needs frames faster than {} Hz",
            config.cutoff_hz,
            2.0 * config.cutoff_hz
        ))
    })?;
    let pad = piece.rate_hz.round() as usize;
    let tracks: Tracks = piece
        .landmarks
        .iter()
        .map(|&l| (l, filter_track(&filter, &piece.track(l), pad)))
        .collect();
    let links = arm_links(model)?;
    let dof = model.dof();
    let limits = model.position_limits();
    let velocity = model.velocity_limits();
    let trunk = TrunkJoints::of(model);
    // The frame the recorded directions are laid in: the model's `torso` link (its root
    // without one).
    let torso_link = model.link_id("torso").unwrap_or(0);
    // The model at rest: its shoulder (in its torso frame) and bone lengths.
    let mut state = KinematicState::new(model);
    let mut q = model.neutral_configuration();
    trunk.set(&mut q, [0.0; 5]);
    model
        .forward_kinematics(&q, &mut state)
        .map_err(|e| invalid(e.to_string()))?;
    let at = |state: &KinematicState, k: usize| state.link_pose(links[k]).translation;
    let s_torso = state
        .link_pose(torso_link)
        .inverse()
        .transform_point(at(&state, 0));
    let bones = [
        (at(&state, 1) - at(&state, 0)).length(),
        (at(&state, 2) - at(&state, 1)).length(),
    ];
    let frames = piece.frames();
    let axes: Vec<[Vector; 3]> = (0..frames)
        .map(|f| {
            torso(&tracks, f)
                .ok_or_else(|| invalid(format!("no torso frame at frame {f} (shoulders together)")))
        })
        .collect::<Result<_>>()?;
    // The trunk's joints, frame by frame, relative to the first frame's heading.
    let heading = {
        let forward = Vector::new(axes[0][0].x, axes[0][0].y, 0.0).normalize_or(Vector::X);
        [forward, Vector::Z.cross(forward), Vector::Z]
    };
    let in_heading =
        |v: Vector| Vector::new(v.dot(heading[0]), v.dot(heading[1]), v.dot(heading[2]));
    let pelvis = tracks.get(&Landmark::Pelvis);
    let mut trunk_q: Vec<[f64; 5]> = Vec::with_capacity(frames);
    let mut turn_prev = 0.0;
    for (f, r) in axes.iter().enumerate() {
        let [turn, lean, side] = trunk_angles(r.map(in_heading));
        // Unwrapped: a person turning past behind themselves keeps turning.
        let turn = turn_prev
            + (turn - turn_prev + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        turn_prev = turn;
        let travel = pelvis.map_or(Vector::ZERO, |p| in_heading(p[f] - p[0]));
        trunk_q.push([travel.x, travel.y, turn, lean, side]);
    }
    let mut targets = Vec::with_capacity(frames);
    // The other side's landmarks, where the clip has them all.
    let other_tracks = match landmarks(config.side.other()).map(|l| tracks.get(&l)) {
        [Some(s), Some(e), Some(w)] => Some([s, e, w]),
        _ => None,
    };
    // The model's shoulder mirrored across its torso's sagittal plane (the torso frame's
    // x-z plane: x forward, y to the left).
    let s_other = Vector::new(s_torso.x, -s_torso.y, s_torso.z);
    let mut other_arm = Vec::with_capacity(if other_tracks.is_some() { frames } else { 0 });
    let (mut upper, mut fore) = (Vec::new(), Vec::new());
    for (f, r) in axes.iter().enumerate() {
        let (s, e, w) = (
            tracks.get(&shoulder).map_or(Vector::ZERO, |t| t[f]),
            tracks.get(&elbow).map_or(Vector::ZERO, |t| t[f]),
            tracks.get(&wrist).map_or(Vector::ZERO, |t| t[f]),
        );
        upper.push((e - s).length());
        fore.push((w - e).length());
        // The model's torso where its trunk follows the recording's (clamped to its limits).
        trunk.set(&mut q, trunk_q[f]);
        for j in (0..dof).filter(|&j| trunk.contains(j)) {
            q[j] = q[j].clamp(limits[j][0], limits[j][1]);
        }
        model
            .forward_kinematics(&q, &mut state)
            .map_err(|e| invalid(e.to_string()))?;
        let X_BT = *state.link_pose(torso_link);
        let to_torso = |v: Vector| Vector::new(v.dot(r[0]), v.dot(r[1]), v.dot(r[2]));
        let e_t = s_torso + to_torso(e - s).normalize_or_zero() * bones[0];
        let w_t = e_t + to_torso(w - e).normalize_or_zero() * bones[1];
        targets.push((X_BT.transform_point(e_t), X_BT.transform_point(w_t)));
        if let Some([s_o, e_o, w_o]) = other_tracks {
            let elbow_o = s_other + to_torso(e_o[f] - s_o[f]).normalize_or_zero() * bones[0];
            let wrist_o = elbow_o + to_torso(w_o[f] - e_o[f]).normalize_or_zero() * bones[1];
            other_arm.push([s_other, elbow_o, wrist_o]);
        }
        trunk_q[f] = std::array::from_fn(|k| trunk.0[k].map_or(0.0, |j| q[j]));
    }
    let median = |v: &mut Vec<f64>| Spread::of(v).median;
    let recorded_bones_m = [median(&mut upper), median(&mut fore)];
    // Each arm by damped least squares of its own joints (the chain from the torso to its
    // hand), warm-started from the previous frame; the trunk as above. The model's left arm,
    // where it has one and the clip has the other side, follows the other arm's targets.
    let mut out: Vec<Vec<f64>> = trunk_q
        .iter()
        .map(|values| {
            let mut q = q.clone();
            trunk.set(&mut q, *values);
            q
        })
        .collect();
    let left = left_arm_links(model).filter(|_| !other_arm.is_empty());
    let left_targets: Vec<(Vector, Vector)> = match left {
        Some(_) => other_arm
            .iter()
            .zip(&out)
            .map(|([_, e_t, w_t], qf)| {
                model
                    .forward_kinematics(qf, &mut state)
                    .map_err(|e| invalid(e.to_string()))?;
                let X_BT = *state.link_pose(torso_link);
                Ok((X_BT.transform_point(*e_t), X_BT.transform_point(*w_t)))
            })
            .collect::<Result<_>>()?,
        None => Vec::new(),
    };
    for (arm, arm_targets) in [(Some(links), &targets), (left, &left_targets)] {
        let Some(arm) = arm else { continue };
        let free: Vec<bool> = chain_dofs(model, arm[2])
            .into_iter()
            .enumerate()
            .map(|(j, on)| on && !trunk.contains(j))
            .collect();
        let mut fit = Fit {
            model,
            links: arm,
            limits: &limits,
            free: &free,
            elbow_weight: config.elbow_weight,
            state: KinematicState::new(model),
            jacobian: Jacobian::zeros(dof),
            scratch: Scratch::default(),
        };
        let mut q = out[0].clone();
        for (f, &(e_t, w_t)) in arm_targets.iter().enumerate() {
            // This frame's other joints; this arm's from the previous frame's solution.
            for j in (0..dof).filter(|&j| !free[j]) {
                q[j] = out[f][j];
            }
            let mut cost = fit
                .solve(&mut q, e_t, w_t)
                .map_err(|e| invalid(e.to_string()))?;
            // The first frame, and any where the previous frame's solution leaves the wrist
            // far off (a local minimum at a limit), start again from a grid over the arm
            // joints' ranges. The wrist's error decides, not the cost: where the recorded
            // elbow lies beyond the model's reach (a bend no elbow makes), a restart on the
            // cost would jump between equally poor branches from frame to frame.
            if f == 0
                || fit
                    .wrist_error(&q, w_t)
                    .map_err(|e| invalid(e.to_string()))?
                    > 0.05
            {
                for seed in grid(&limits, &free, &q) {
                    let mut candidate = seed;
                    let c = fit
                        .solve(&mut candidate, e_t, w_t)
                        .map_err(|e| invalid(e.to_string()))?;
                    if c < cost - 1e-9 {
                        (q, cost) = (candidate, c);
                    }
                }
            }
            for j in (0..dof).filter(|&j| free[j]) {
                out[f][j] = q[j];
            }
        }
    }
    let clamped_frames = out
        .iter()
        .filter(|q| (0..dof).any(|j| q[j] <= limits[j][0] + 1e-9 || q[j] >= limits[j][1] - 1e-9))
        .count();
    // The model's velocity limits, frame to frame.
    let dt = 1.0 / piece.rate_hz;
    let joint_speed = (0..dof)
        .map(|j| {
            let mut speeds: Vec<f64> = out
                .windows(2)
                .map(|w| (w[1][j] - w[0][j]).abs() / dt)
                .collect();
            Spread::of(&mut speeds)
        })
        .collect();
    let mut velocity_limited_frames = 0;
    for f in 1..out.len() {
        let mut limited = false;
        for j in 0..dof {
            let max = velocity[j] * dt;
            let d = out[f][j] - out[f - 1][j];
            if d.abs() > max {
                out[f][j] = out[f - 1][j] + max.copysign(d);
                limited = true;
            }
        }
        velocity_limited_frames += usize::from(limited);
    }
    let (mut wrist_errors, mut elbow_errors) = (Vec::new(), Vec::new());
    let mut left_wrist_errors = Vec::new();
    for (f, (qf, &(e_t, w_t))) in out.iter().zip(&targets).enumerate() {
        model
            .forward_kinematics(qf, &mut state)
            .map_err(|e| invalid(e.to_string()))?;
        wrist_errors.push((at(&state, 2) - w_t).length());
        elbow_errors.push((at(&state, 1) - e_t).length());
        if let (Some(arm), Some(&(_, w_t))) = (left, left_targets.get(f)) {
            left_wrist_errors.push((state.link_pose(arm[2]).translation - w_t).length());
        }
    }
    let report = RetargetReport {
        clip: clip.name.clone(),
        side: config.side,
        frames,
        clip_frames: clip.frames(),
        wrist_error_m: Spread::of(&mut wrist_errors),
        elbow_error_m: Spread::of(&mut elbow_errors),
        left_wrist_error_m: (!left_wrist_errors.is_empty())
            .then(|| Spread::of(&mut left_wrist_errors)),
        clamped_frames,
        velocity_limited_frames,
        joint_speed,
        recorded_bones_m,
        model_bones_m: bones,
        trunk: trunk.any().then(|| trunk_report(&trunk, &out)),
    };
    Ok((
        RecordedMotion {
            name: clip.name.clone(),
            rate_hz: piece.rate_hz,
            q: out,
            other_arm,
        },
        report,
    ))
}

/// Damped least squares of the arm's wrist and elbow onto their targets.
struct Fit<'a> {
    model: &'a RobotModel,
    links: [LinkId; 3],
    limits: &'a [[f64; 2]],
    /// The joints the fit moves (the others stay as given).
    free: &'a [bool],
    elbow_weight: f64,
    state: KinematicState,
    jacobian: Jacobian,
    scratch: Scratch,
}

impl Fit<'_> {
    /// The model's wrist's distance from `w_t` at `q`.
    fn wrist_error(&mut self, q: &[f64], w_t: Vector) -> workcell_robots::Result<f64> {
        self.model.forward_kinematics(q, &mut self.state)?;
        Ok((self.state.link_pose(self.links[2]).translation - w_t).length())
    }

    /// Moves `q` (within the limits) toward the targets; returns the weighted squared error
    /// left.
    fn solve(&mut self, q: &mut [f64], e_t: Vector, w_t: Vector) -> workcell_robots::Result<f64> {
        let dof = q.len();
        let lambda2 = 1e-4;
        for _ in 0..30 {
            // Sizes the scratch to `dof` too.
            let cost = self.normal_equations(q, e_t, w_t)?;
            let Scratch {
                a: normal_a,
                b: normal_b,
                work_a: a,
                work_b: b,
                step,
                held,
                pivot,
            } = &mut self.scratch;
            // An active set: a joint at a limit that the step would push past it is held for
            // this step and the rest solved again without it (clamping the full step instead
            // leaves the other joints' steps computed as if it moved, and the fit stalls).
            held.fill(false);
            loop {
                a.copy_from_slice(normal_a);
                b.copy_from_slice(normal_b);
                for i in 0..dof {
                    a[i * dof + i] += lambda2;
                }
                for i in (0..dof).filter(|&i| held[i]) {
                    // Row and column i zeroed, a unit diagonal: step[i] = 0.
                    a[i * dof..(i + 1) * dof].fill(0.0);
                    for r in 0..dof {
                        a[r * dof + i] = 0.0;
                    }
                    a[i * dof + i] = 1.0;
                    b[i] = 0.0;
                }
                if !solve_in_place(dof, a, b, pivot, step) {
                    return Ok(cost);
                }
                let mut newly_held = false;
                for (j, held) in held.iter_mut().enumerate() {
                    let [lower, upper] = self.limits[j];
                    if !*held
                        && ((q[j] <= lower && step[j] < 0.0) || (q[j] >= upper && step[j] > 0.0))
                    {
                        *held = true;
                        newly_held = true;
                    }
                }
                if !newly_held {
                    break;
                }
            }
            let mut moved: f64 = 0.0;
            for j in 0..dof {
                let next = (q[j] + step[j]).clamp(self.limits[j][0], self.limits[j][1]);
                moved = moved.max((next - q[j]).abs());
                q[j] = next;
            }
            if moved < 1e-7 || cost < 1e-12 {
                break;
            }
        }
        self.normal_equations(q, e_t, w_t)
    }

    /// The weighted squared error at `q`; `J^T W J` and `J^T W e` into the scratch's `a`
    /// (row-major) and `b`.
    fn normal_equations(
        &mut self,
        q: &[f64],
        e_t: Vector,
        w_t: Vector,
    ) -> workcell_robots::Result<f64> {
        let dof = q.len();
        self.model.forward_kinematics(q, &mut self.state)?;
        if self.jacobian.dof() != dof {
            self.jacobian = Jacobian::zeros(dof);
        }
        self.scratch.resize(dof);
        let at = |state: &KinematicState, link: LinkId| state.link_pose(link).translation;
        let (e, w) = (
            at(&self.state, self.links[1]),
            at(&self.state, self.links[2]),
        );
        let rows = [
            (self.links[2], w, w_t - w, 1.0),
            (self.links[1], e, e_t - e, self.elbow_weight),
        ];
        let (a, b) = (&mut self.scratch.a, &mut self.scratch.b);
        a.fill(0.0);
        b.fill(0.0);
        let mut cost = 0.0;
        for (link, p, err, weight) in rows {
            cost += weight * err.length_squared();
            self.model
                .point_jacobian(&self.state, link, p, &mut self.jacobian);
            let columns = self.jacobian.columns();
            let free = |j: usize| self.free.get(j).copied().unwrap_or(true);
            for (i, ((ci, row), bi)) in columns
                .iter()
                .zip(a.chunks_exact_mut(dof))
                .zip(b.iter_mut())
                .enumerate()
            {
                if !free(i) {
                    continue;
                }
                *bi += weight * (ci[0] * err.x + ci[1] * err.y + ci[2] * err.z);
                for (j, (cj, aij)) in columns.iter().zip(row.iter_mut()).enumerate() {
                    if free(j) {
                        *aij += weight * (ci[0] * cj[0] + ci[1] * cj[1] + ci[2] * cj[2]);
                    }
                }
            }
        }
        // A joint held still: its row says "no step".
        for i in 0..dof {
            if !self.free.get(i).copied().unwrap_or(true) {
                a[i * dof + i] = 1.0;
            }
        }
        Ok(cost)
    }
}

/// The solver's buffers, kept between its iterations and frames (a clip's frames each
/// solve up to 82 starts of 30 steps).
#[derive(Debug, Default)]
struct Scratch {
    /// `J^T W J`, row-major, and `J^T W e`.
    a: Vec<f64>,
    b: Vec<f64>,
    /// Their copies that an active set's step is solved on.
    work_a: Vec<f64>,
    work_b: Vec<f64>,
    step: Vec<f64>,
    held: Vec<bool>,
    pivot: Vec<f64>,
}

impl Scratch {
    fn resize(&mut self, dof: usize) {
        if self.b.len() != dof {
            *self = Self {
                a: vec![0.0; dof * dof],
                b: vec![0.0; dof],
                work_a: vec![0.0; dof * dof],
                work_b: vec![0.0; dof],
                step: vec![0.0; dof],
                held: vec![false; dof],
                pivot: vec![0.0; dof],
            };
        }
    }
}

/// Starting points over the free joints' ranges: three per joint (at a quarter, half and
/// three quarters of the range), every combination for the first four free joints, the
/// middle for the others; the joints held still keep their values in `q`.
fn grid(limits: &[[f64; 2]], free: &[bool], q: &[f64]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::new()];
    let mut free_seen = 0;
    for (j, [lo, hi]) in limits.iter().enumerate() {
        let values: Vec<f64> = if !free[j] {
            vec![q[j]]
        } else if free_seen < 4 {
            [0.25, 0.5, 0.75]
                .iter()
                .map(|s| lo + s * (hi - lo))
                .collect()
        } else {
            vec![0.5 * (lo + hi)]
        };
        free_seen += usize::from(free[j]);
        out = out
            .into_iter()
            .flat_map(|p| {
                values.iter().map(move |v| {
                    let mut p = p.clone();
                    p.push(*v);
                    p
                })
            })
            .collect();
    }
    out
}

/// The trunk's ranges over the retargeted frames.
fn trunk_report(trunk: &TrunkJoints, q: &[Vec<f64>]) -> TrunkReport {
    let range = |k: usize, scale: f64| -> [f64; 2] {
        trunk.0[k].map_or([0.0, 0.0], |j| {
            let (lo, hi) = q.iter().fold((f64::MAX, f64::MIN), |(lo, hi), f| {
                (lo.min(f[j]), hi.max(f[j]))
            });
            [lo * scale, hi * scale]
        })
    };
    let deg = 180.0 / std::f64::consts::PI;
    let start = q
        .first()
        .map(|f| [0, 1].map(|k| trunk.0[k].map_or(0.0, |j| f[j])));
    let pelvis_travel_m = q
        .iter()
        .map(|f| {
            let p = [0, 1].map(|k| trunk.0[k].map_or(0.0, |j| f[j]));
            let s = start.unwrap_or([0.0; 2]);
            (p[0] - s[0]).hypot(p[1] - s[1])
        })
        .fold(0.0, f64::max);
    TrunkReport {
        turn_deg: range(2, deg),
        lean_deg: range(3, deg),
        side_deg: range(4, deg),
        pelvis_travel_m,
    }
}

/// `a x = b` (`a` `n x n` row-major; both overwritten) by Gaussian elimination with partial
/// pivoting, `x` into `x`; false when singular. `pivot` is a row's scratch.
fn solve_in_place(
    n: usize,
    a: &mut [f64],
    b: &mut [f64],
    pivot: &mut [f64],
    x: &mut [f64],
) -> bool {
    for c in 0..n {
        let Some(p) = (c..n).max_by(|&i, &j| a[i * n + c].abs().total_cmp(&a[j * n + c].abs()))
        else {
            return false;
        };
        if a[p * n + c].abs() < 1e-15 {
            return false;
        }
        if p != c {
            for k in 0..n {
                a.swap(c * n + k, p * n + k);
            }
            b.swap(c, p);
        }
        pivot.copy_from_slice(&a[c * n..(c + 1) * n]);
        for r in c + 1..n {
            let m = a[r * n + c] / pivot[c];
            for (x, p) in a[r * n + c..(r + 1) * n].iter_mut().zip(&pivot[c..]) {
                *x -= m * p;
            }
            b[r] -= m * b[c];
        }
    }
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r * n + k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r * n + r];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> RobotModel {
        RobotModel::from_catalogue("human_arm").expect("catalogue")
    }

    /// A clip made from the model itself (its own shoulder, elbow and wrist under a known
    /// motion within its joints, a torso facing +x) comes back as that motion: the round
    /// trip within a millimetre, no clamping.
    #[test]
    fn the_models_own_motion_round_trips() {
        let model = model();
        let links = arm_links(&model).expect("links");
        let mut state = KinematicState::new(&model);
        let rate = 100.0;
        let frames = 400;
        let truth: Vec<Vec<f64>> = (0..frames)
            .map(|f| {
                let t = f as f64 / rate;
                vec![
                    0.4 + 0.3 * (0.5 * t).sin(),
                    0.6 + 0.5 * (0.7 * t).sin(),
                    0.8 + 0.4 * (0.9 * t).cos(),
                ]
            })
            .collect();
        let landmarks = vec![
            Landmark::LeftShoulder,
            Landmark::RightShoulder,
            Landmark::RightElbow,
            Landmark::RightWrist,
        ];
        let mut positions = Vec::new();
        for q in &truth {
            model.forward_kinematics(q, &mut state).expect("fk");
            let s = state.link_pose(links[0]).translation;
            positions.extend([
                s + Vector::new(0.0, 0.38, 0.0), // the other shoulder, to the left
                s,
                state.link_pose(links[1]).translation,
                state.link_pose(links[2]).translation,
            ]);
        }
        let clip = Clip {
            name: "own".into(),
            rate_hz: rate,
            landmarks,
            positions,
            filled: vec![false; frames],
        };
        let (motion, report) =
            retarget(&clip, &model, &RetargetConfig::default()).expect("retarget");
        assert_eq!(motion.frames(), frames);
        assert!(report.wrist_error_m.peak < 1e-3, "{report:?}");
        assert_eq!(report.clamped_frames, 0);
        // The clip has no left elbow or wrist: no other arm, nothing sampled.
        assert!(motion.other_arm.is_empty() && motion.other_arm_at(1.0).is_none());
        // Away from the ends (the filter's padding), the joints are the truth's.
        for (f, (got, want)) in motion
            .q
            .iter()
            .zip(&truth)
            .enumerate()
            .take(frames - 50)
            .skip(50)
        {
            for (j, (g, w)) in got.iter().zip(want).enumerate() {
                assert!((g - w).abs() < 2e-3, "{f} {j}: {g} against {w}");
            }
        }
        let bones = report.model_bones_m;
        assert!((report.recorded_bones_m[0] - bones[0]).abs() < 1e-6);
        // Sampling between frames interpolates, and the velocity is the segment's.
        let (mut q, mut qd) = ([0.0; 3], [0.0; 3]);
        motion.sample(1.005, &mut q, &mut qd);
        for j in 0..3 {
            let (a, b) = (motion.q[100][j], motion.q[101][j]);
            assert!((q[j] - 0.5 * (a + b)).abs() < 1e-12);
            assert!((qd[j] - (b - a) * rate).abs() < 1e-9);
        }
    }

    /// The catalogue's `human` moving every joint the landmarks show (the pelvis over the
    /// floor, the trunk's turn, lean and side bend, the three shoulder joints and the elbow;
    /// the forearm's rotation at the middle of its range, which they do not show) comes back
    /// as that motion: trunk and arm.
    #[test]
    fn the_whole_bodys_own_motion_round_trips() {
        let model = RobotModel::from_catalogue("human").expect("catalogue");
        let links = arm_links(&model).expect("links");
        let torso = model.link_id("torso").expect("torso");
        let index = |name: &str| {
            model
                .actuated_joints()
                .iter()
                .position(|&j| model.joints()[j].name == name)
                .expect(name)
        };
        let mut state = KinematicState::new(&model);
        let (rate, frames) = (100.0, 500);
        let truth: Vec<Vec<f64>> = (0..frames)
            .map(|f| {
                let t = f as f64 / rate;
                let mut q = model.neutral_configuration();
                for (name, v) in [
                    ("pelvis_x", 0.2 * (0.4 * t).sin()),
                    ("pelvis_y", -0.15 * (0.3 * t).sin()),
                    ("trunk_turn", 0.6 * (1.2 * t).sin()),
                    ("trunk_lean", 0.2 + 0.15 * (0.5 * t).cos()),
                    ("trunk_side", 0.1 * (0.6 * t).sin()),
                    ("shoulder_flexion", 0.9 + 0.5 * (0.5 * t).sin()),
                    ("shoulder_abduction", 0.3 + 0.2 * (0.7 * t).sin()),
                    ("shoulder_rotation", 0.2 + 0.4 * (0.8 * t).sin()),
                    ("elbow_flexion", 1.0 + 0.4 * (0.9 * t).cos()),
                ] {
                    q[index(name)] = v;
                    // The model's left arm at the same values is the right's mirror image:
                    // the recorded left arm below.
                    if let Some(j) = model.joint_id(&format!("left_{name}")) {
                        let d = model.actuated_joints().iter().position(|&a| a == j);
                        q[d.expect("actuated")] = v;
                    }
                }
                q
            })
            .collect();
        let landmarks = vec![
            Landmark::Pelvis,
            Landmark::Neck,
            Landmark::LeftShoulder,
            Landmark::RightShoulder,
            Landmark::RightElbow,
            Landmark::RightWrist,
            Landmark::LeftElbow,
            Landmark::LeftWrist,
        ];
        // The left arm is the right one mirrored across the torso's sagittal plane (its
        // frame's x-z plane): in the torso frame, the right arm's points with y negated.
        let mirror = |v: Vector| Vector::new(v.x, -v.y, v.z);
        let mut positions = Vec::new();
        let mut mirrored = Vec::new();
        for q in &truth {
            model.forward_kinematics(q, &mut state).expect("fk");
            let X_BT = *state.link_pose(torso);
            let [s, e, w] = links.map(|l| state.link_pose(l).translation);
            let in_torso = [s, e, w].map(|p| X_BT.inverse_transform_point(p));
            let left_s = s + X_BT.rotation * Vector::new(0.0, 0.38, 0.0);
            let left_e = left_s + X_BT.rotation * mirror(in_torso[1] - in_torso[0]);
            let left_w = left_e + X_BT.rotation * mirror(in_torso[2] - in_torso[1]);
            positions.extend([
                X_BT.translation,
                X_BT.transform_point(Vector::new(0.0, 0.0, 0.6)),
                left_s,
                s,
                e,
                w,
                left_e,
                left_w,
            ]);
            mirrored.push(in_torso.map(mirror));
        }
        let clip = Clip {
            name: "own".into(),
            rate_hz: rate,
            landmarks,
            positions,
            filled: vec![false; frames],
        };
        let config = RetargetConfig {
            elbow_weight: 1.0,
            ..RetargetConfig::default()
        };
        let (motion, report) = retarget(&clip, &model, &config).expect("retarget");
        assert!(report.wrist_error_m.peak < 1e-3, "{report:?}");
        assert!(report.elbow_error_m.peak < 1e-3, "{report:?}");
        // The model's left arm follows the recording's left.
        let left = report.left_wrist_error_m.expect("a left arm");
        assert!(left.peak < 1e-3, "{report:?}");
        // The other arm, placed from the model's mirrored shoulder along the recorded
        // directions, is the model's own arm mirrored (away from the filter's padding).
        assert_eq!(motion.other_arm.len(), frames);
        for (f, (got, want)) in (motion.other_arm.iter().zip(&mirrored))
            .enumerate()
            .take(frames - 50)
            .skip(50)
        {
            for (g, w) in got.iter().zip(want) {
                assert!((*g - *w).length() < 2e-3, "{f}: {g:?} against {w:?}");
            }
        }
        let trunk = report.trunk.expect("a trunk");
        assert!(
            trunk.turn_deg[1] > 30.0 && trunk.turn_deg[0] < -30.0,
            "{trunk:?}"
        );
        for (f, (got, want)) in motion
            .q
            .iter()
            .zip(&truth)
            .enumerate()
            .take(frames - 50)
            .skip(50)
        {
            for (j, (g, w)) in got.iter().zip(want).enumerate() {
                assert!(
                    (g - w).abs() < 3e-3,
                    "{f} {}: {g} against {w}",
                    model.joints()[model.actuated_joints()[j]].name
                );
            }
        }
    }

    /// A recorded arm whose forearm bends backwards (the elbow hyperextended by 40 to 60
    /// degrees, as the Vicon clips read), swinging forward and back: no configuration reaches
    /// the elbow's target, but the wrist's is within the model's reach, and the fit puts the
    /// wrist on it with the elbow at its limit. (Clamping the whole Gauss-Newton step at the
    /// limits, as the fit did before its active set, left the wrist up to 17 cm off here.)
    #[test]
    fn the_wrist_is_followed_where_the_elbow_bends_past_its_limit() {
        let model = RobotModel::from_catalogue("human").expect("catalogue");
        let links = arm_links(&model).expect("links");
        let mut state = KinematicState::new(&model);
        let mut q = model.neutral_configuration();
        TrunkJoints::of(&model).set(&mut q, [0.0; 5]);
        model.forward_kinematics(&q, &mut state).expect("fk");
        let s = state.link_pose(links[0]).translation;
        let bones = [
            (state.link_pose(links[1]).translation - s).length(),
            (state.link_pose(links[2]).translation - state.link_pose(links[1]).translation)
                .length(),
        ];
        let (rate, frames) = (100.0, 300);
        let mut positions = Vec::new();
        for f in 0..frames {
            let t = f as f64 / rate;
            // The upper arm 20 to 70 degrees forward of hanging, the forearm 40 to 60 behind it.
            let upper = 0.35 + 0.45 * (0.8 * t).sin().abs();
            let fore = upper - 0.7 - 0.17 * (1.3 * t).cos();
            let dir = |a: f64| Vector::new(a.sin(), 0.0, -a.cos());
            let e = s + dir(upper) * bones[0];
            positions.extend([
                s + Vector::new(0.0, 0.38, 0.0),
                s,
                e,
                e + dir(fore) * bones[1],
            ]);
        }
        let clip = Clip {
            name: "hyperextended".into(),
            rate_hz: rate,
            landmarks: vec![
                Landmark::LeftShoulder,
                Landmark::RightShoulder,
                Landmark::RightElbow,
                Landmark::RightWrist,
            ],
            positions,
            filled: vec![false; frames],
        };
        // On the wrist alone the fit reaches it.
        let wrist_only = RetargetConfig {
            elbow_weight: 0.0,
            ..RetargetConfig::default()
        };
        let (_, report) = retarget(&clip, &model, &wrist_only).expect("retarget");
        assert!(report.wrist_error_m.peak < 1e-3, "{report:?}");
        // With the elbow weighted (0.05), the wrist gives way a little to an elbow that
        // cannot follow: its target is off every reachable elbow by the bend.
        let (_, report) = retarget(&clip, &model, &RetargetConfig::default()).expect("retarget");
        assert!(report.elbow_error_m.median > 0.05, "{report:?}");
        assert!(report.wrist_error_m.peak < 0.01, "{report:?}");
    }

    /// The trunk's angles are the z-y-x angles of its rotation.
    #[test]
    fn trunk_angles_invert_the_turn_lean_side_product() {
        use workcell_robots::math::Rotation;
        for (turn, lean, side) in [(0.3, 0.2, -0.1), (-2.5, 0.7, 0.4), (0.0, -0.3, 0.0)] {
            let r = Rotation::from_rotation_z(turn)
                * Rotation::from_rotation_y(lean)
                * Rotation::from_rotation_x(side);
            let got = trunk_angles([r * Vector::X, r * Vector::Y, r * Vector::Z]);
            for (g, w) in got.iter().zip([turn, lean, side]) {
                assert!((g - w).abs() < 1e-12, "{got:?} vs {turn} {lean} {side}");
            }
        }
    }

    #[test]
    fn a_clip_without_the_arm_is_refused() {
        let clip = Clip {
            name: "legs".into(),
            rate_hz: 100.0,
            landmarks: vec![Landmark::Pelvis],
            positions: vec![Vector::ZERO; 10],
            filled: vec![false; 10],
        };
        let err = retarget(&clip, &model(), &RetargetConfig::default())
            .expect_err("no arm")
            .to_string();
        assert!(
            err.contains("legs: the clip has no right_shoulder"),
            "{err}"
        );
    }
}
