//! Retargeting a recorded clip onto the cell's human model: the recorded arm, seen from the
//! person's torso, becomes joint angles of the model's arm.
//!
//! 1. The clip is cleaned of capture artefacts and its longest piece kept
//!    (`workcell_mocap::clean`), then each landmark is low-pass filtered (zero phase,
//!    `cutoff_hz`, 6 Hz by default; `workcell_mocap::filter`).
//! 2. Each frame's torso frame: y from the right shoulder to the left, z up (from the pelvis
//!    to the neck where the clip has them, the recording's up otherwise) made orthogonal to
//!    y, x = y x z (forward). The model's torso faces +x with z up (`human.base`), so the
//!    person stands where the model does; the torso's own motion is not followed.
//! 3. The followed side's upper arm and forearm directions, in the torso frame, are laid on
//!    the model's bones from the model's shoulder: elbow and wrist targets the model's arm can
//!    reach whatever the person's size.
//! 4. Damped least squares on both targets (the wrist weighted 1, the elbow `elbow_weight`, 0.05),
//!    from the previous frame's solution, within the joint limits: a model whose shoulder
//!    has fewer joints than a person's leaves an error, which the report states.
//! 5. From frame to frame no joint moves faster than the model's velocity limit; the frames
//!    where that held a joint back are counted.

use serde::{Deserialize, Serialize};
use workcell_mocap::clean::{CleanConfig, clean};
use workcell_mocap::filter::{Butterworth2, DEFAULT_CUTOFF_HZ, filter_track};
use workcell_mocap::stats::Spread;
use workcell_mocap::{Clip, Landmark};
use workcell_robots::math::Vector;
use workcell_robots::{Jacobian, KinematicState, LinkId, RobotModel};

use crate::error::{Result, SimError};

/// The side of the recorded person the model's arm follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    Left,
    Right,
}

impl Side {
    fn landmarks(self) -> [Landmark; 3] {
        match self {
            Self::Left => [
                Landmark::LeftShoulder,
                Landmark::LeftElbow,
                Landmark::LeftWrist,
            ],
            Self::Right => [
                Landmark::RightShoulder,
                Landmark::RightElbow,
                Landmark::RightWrist,
            ],
        }
    }

    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Left => "left",
            Self::Right => "right",
        }
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
    /// Weight of the elbow's target against the wrist's in the fit: small, so that the hand,
    /// the part that meets the robot first, follows the recording where the model's joints
    /// cannot follow both (a 2-joint shoulder cannot turn the arm about its own axis).
    /// Default 0.05.
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
        let last = self.frames().saturating_sub(1);
        let x = (t_s * self.rate_hz).clamp(0.0, last as f64);
        let i = (x.floor() as usize).min(last.saturating_sub(1));
        let s = x - i as f64;
        let (a, b) = (&self.q[i], &self.q[(i + 1).min(last)]);
        for j in 0..q.len().min(a.len()) {
            q[j] = a[j] + (b[j] - a[j]) * s;
            qd[j] = (b[j] - a[j]) * self.rate_hz;
        }
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
    /// Frames where a joint stopped at its position limit.
    pub clamped_frames: usize,
    /// Frames where a joint was held back by its velocity limit.
    pub velocity_limited_frames: usize,
    /// The recorded person's upper arm and forearm, median length, m, and the model's.
    pub recorded_bones_m: [f64; 2],
    pub model_bones_m: [f64; 2],
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
    let [shoulder, elbow, wrist] = config.side.landmarks();
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
    // The model at rest: its shoulder and bone lengths in its base (torso) frame.
    let mut state = KinematicState::new(model);
    let mut q = model.neutral_configuration();
    model
        .forward_kinematics(&q, &mut state)
        .map_err(|e| invalid(e.to_string()))?;
    let at = |state: &KinematicState, k: usize| state.link_pose(links[k]).translation;
    let s_model = at(&state, 0);
    let bones = [
        (at(&state, 1) - s_model).length(),
        (at(&state, 2) - at(&state, 1)).length(),
    ];
    let frames = piece.frames();
    let mut targets = Vec::with_capacity(frames);
    let (mut upper, mut fore) = (Vec::new(), Vec::new());
    for f in 0..frames {
        let r = torso(&tracks, f)
            .ok_or_else(|| invalid(format!("no torso frame at frame {f} (shoulders together)")))?;
        let (s, e, w) = (
            tracks.get(&shoulder).map_or(Vector::ZERO, |t| t[f]),
            tracks.get(&elbow).map_or(Vector::ZERO, |t| t[f]),
            tracks.get(&wrist).map_or(Vector::ZERO, |t| t[f]),
        );
        upper.push((e - s).length());
        fore.push((w - e).length());
        let to_torso = |v: Vector| Vector::new(v.dot(r[0]), v.dot(r[1]), v.dot(r[2]));
        let e_t = s_model + to_torso(e - s).normalize_or_zero() * bones[0];
        let w_t = e_t + to_torso(w - e).normalize_or_zero() * bones[1];
        targets.push((e_t, w_t));
    }
    let median = |v: &mut Vec<f64>| Spread::of(v).median;
    let recorded_bones_m = [median(&mut upper), median(&mut fore)];
    // Damped least squares, warm-started from the previous frame.
    let mut out: Vec<Vec<f64>> = Vec::with_capacity(frames);
    let mut clamped_frames = 0;
    let mut fit = Fit {
        model,
        links,
        limits: &limits,
        elbow_weight: config.elbow_weight,
        state: KinematicState::new(model),
        jacobian: Jacobian::zeros(dof),
    };
    for (f, &(e_t, w_t)) in targets.iter().enumerate() {
        let mut cost = fit
            .solve(&mut q, e_t, w_t)
            .map_err(|e| invalid(e.to_string()))?;
        // The first frame, and any the previous frame's solution leaves far off (a local
        // minimum at a limit), start again from a grid over the joints' ranges.
        if f == 0 || cost.sqrt() > 0.05 {
            for seed in grid(&limits) {
                let mut candidate = seed;
                let c = fit
                    .solve(&mut candidate, e_t, w_t)
                    .map_err(|e| invalid(e.to_string()))?;
                if c < cost - 1e-9 {
                    (q, cost) = (candidate, c);
                }
            }
        }
        if (0..dof).any(|j| q[j] <= limits[j][0] + 1e-9 || q[j] >= limits[j][1] - 1e-9) {
            clamped_frames += 1;
        }
        out.push(q.clone());
    }
    // The model's velocity limits, frame to frame.
    let dt = 1.0 / piece.rate_hz;
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
    for (qf, &(e_t, w_t)) in out.iter().zip(&targets) {
        model
            .forward_kinematics(qf, &mut state)
            .map_err(|e| invalid(e.to_string()))?;
        wrist_errors.push((at(&state, 2) - w_t).length());
        elbow_errors.push((at(&state, 1) - e_t).length());
    }
    let report = RetargetReport {
        clip: clip.name.clone(),
        side: config.side,
        frames,
        clip_frames: clip.frames(),
        wrist_error_m: Spread::of(&mut wrist_errors),
        elbow_error_m: Spread::of(&mut elbow_errors),
        clamped_frames,
        velocity_limited_frames,
        recorded_bones_m,
        model_bones_m: bones,
    };
    Ok((
        RecordedMotion {
            name: clip.name.clone(),
            rate_hz: piece.rate_hz,
            q: out,
        },
        report,
    ))
}

/// Damped least squares of the arm's wrist and elbow onto their targets.
struct Fit<'a> {
    model: &'a RobotModel,
    links: [LinkId; 3],
    limits: &'a [[f64; 2]],
    elbow_weight: f64,
    state: KinematicState,
    jacobian: Jacobian,
}

impl Fit<'_> {
    /// Moves `q` (within the limits) toward the targets; returns the weighted squared error
    /// left.
    fn solve(&mut self, q: &mut [f64], e_t: Vector, w_t: Vector) -> workcell_robots::Result<f64> {
        let dof = q.len();
        let lambda2 = 1e-4;
        for _ in 0..30 {
            let (cost, a, b) = self.normal_equations(q, e_t, w_t)?;
            let mut a = a;
            for (i, row) in a.iter_mut().enumerate() {
                row[i] += lambda2;
            }
            let Some(step) = solve(a, b) else {
                return Ok(cost);
            };
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
        Ok(self.normal_equations(q, e_t, w_t)?.0)
    }

    /// The weighted squared error at `q`, and `J^T W J`, `J^T W e`.
    fn normal_equations(
        &mut self,
        q: &[f64],
        e_t: Vector,
        w_t: Vector,
    ) -> workcell_robots::Result<(f64, Vec<Vec<f64>>, Vec<f64>)> {
        let dof = q.len();
        self.model.forward_kinematics(q, &mut self.state)?;
        if self.jacobian.dof() != dof {
            self.jacobian = Jacobian::zeros(dof);
        }
        let at = |state: &KinematicState, link: LinkId| state.link_pose(link).translation;
        let (e, w) = (
            at(&self.state, self.links[1]),
            at(&self.state, self.links[2]),
        );
        let rows = [
            (self.links[2], w, w_t - w, 1.0),
            (self.links[1], e, e_t - e, self.elbow_weight),
        ];
        let mut a = vec![vec![0.0; dof]; dof];
        let mut b = vec![0.0; dof];
        let mut cost = 0.0;
        for (link, p, err, weight) in rows {
            cost += weight * err.length_squared();
            self.model
                .point_jacobian(&self.state, link, p, &mut self.jacobian);
            let columns = self.jacobian.columns();
            for ((ci, row), bi) in columns.iter().zip(&mut a).zip(&mut b) {
                *bi += weight * (ci[0] * err.x + ci[1] * err.y + ci[2] * err.z);
                for (cj, aij) in columns.iter().zip(row.iter_mut()) {
                    *aij += weight * (ci[0] * cj[0] + ci[1] * cj[1] + ci[2] * cj[2]);
                }
            }
        }
        Ok((cost, a, b))
    }
}

/// Starting points over the joints' ranges: three per joint (at a quarter, half and three
/// quarters of the range), every combination for up to four joints, the middle elsewhere.
fn grid(limits: &[[f64; 2]]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::new()];
    for (j, [lo, hi]) in limits.iter().enumerate() {
        let values: Vec<f64> = if j < 4 {
            [0.25, 0.5, 0.75]
                .iter()
                .map(|s| lo + s * (hi - lo))
                .collect()
        } else {
            vec![0.5 * (lo + hi)]
        };
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

/// `a x = b` by Gaussian elimination with partial pivoting; `None` when singular.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-15 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        let pivot = a[c].clone();
        for r in c + 1..n {
            let m = a[r][c] / pivot[c];
            for (x, p) in a[r][c..].iter_mut().zip(&pivot[c..]) {
                *x -= m * p;
            }
            b[r] -= m * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
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
