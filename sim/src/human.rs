//! Seeded motions of the human arm: resting, reaching into the shared space, waving,
//! withdrawing. The movements are drawn in the joints named `shoulder_abduction`,
//! `shoulder_flexion` and `elbow_flexion` (radians; 0 is the arm hanging straight down), the
//! first three joints of a model without those names; the catalogue's `human` also turns and
//! leans its trunk as it reaches and turns its upper arm and forearm (`trunk_turn`,
//! `trunk_lean`, `shoulder_rotation`, `forearm_rotation`), and moves its left arm (`left_*`):
//! during each phase it rests at the side, holds where it was, or reaches as well (a half,
//! a quarter and a quarter of the right arm's reaches and rests; during a wave or a
//! withdrawal it rests or holds), drawn from the reach's and rest's ranges. Other joints stay
//! at 0.
//!
//! Every point-to-point movement follows the minimum-jerk time profile
//! `s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5` (Flash and Hogan 1985, J. Neurosci. 5(7)
//! 1688-1703), here in joint space: the hand's speed is bell-shaped, as measured in
//! unrestrained arm movements (Atkeson and Hollerbach 1985, J. Neurosci. 5(9) 2318-2330).
//! Durations are drawn first, nearly independent of distance as in natural prehension
//! (Jeannerod 1984, J. Mot. Behav. 16(3) 235-254); then each movement draws the peak speed its
//! fastest point may reach from `human.peak_speed_m_s` and is stretched until it keeps it (a
//! wave swings less far instead). `human.speeds` chooses both ranges: `iso13855` (1.0 to
//! 2.0 m/s, never above ISO 13855's approach speed of hands and arms, durations as drawn) or
//! `recorded` (peaks and accelerations up to those of the shipped recordings of people at
//! work: faster peaks and transitions shortened by up to half).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_robots::collision::link_bounding_capsule;
use workcell_robots::math::Vector;
use workcell_robots::{Jacobian, KinematicState, LinkId, RobotModel};

pub use crate::scenario::ClipEnd;
use crate::scenario::HumanMotionKind;
use crate::trajectory::quintic;

/// Number of phases generated before the motion repeats.
const PHASES: usize = 24;
/// Samples per second (at least 96 per transition or hold) when a phase's peak speed is
/// measured: a 2 Hz wave gets 200 per swing.
const SPEED_SAMPLES_PER_S: f64 = 400.0;
/// The cap a phase is fitted to, as a fraction of the drawn peak speed: room for the true
/// peak between two samples.
const CAP_MARGIN: f64 = 0.99;

#[derive(Debug, Clone, PartialEq)]
struct Phase {
    kind: HumanMotionKind,
    t0_s: f64,
    /// Time to move from `q_from` to `q_to`.
    transition_s: f64,
    /// Time spent at `q_to` afterwards.
    hold_s: f64,
    q_from: Vec<f64>,
    q_to: Vec<f64>,
    /// Elbow oscillation while holding (wave): amplitude rad, frequency Hz.
    wave: Option<(f64, f64)>,
    /// The joint that waves (the elbow).
    elbow: usize,
}

impl Phase {
    /// Joint positions and velocities `local_s` after the phase began (as generated).
    fn sample(&self, local_s: f64, q: &mut [f64], qd: &mut [f64]) {
        let tau = (local_s / self.transition_s).clamp(0.0, 1.0);
        let (s, ds, _) = quintic(tau);
        let ds = if local_s < self.transition_s {
            ds / self.transition_s
        } else {
            0.0
        };
        for j in 0..q.len() {
            let d = self.q_to[j] - self.q_from[j];
            q[j] = self.q_from[j] + d * s;
            qd[j] = d * ds;
        }
        // Waving: the elbow swings about its target, faded in and out with sin^2 envelopes.
        let j = self.elbow;
        if let Some((amplitude, frequency_hz)) = self.wave
            && local_s > self.transition_s
            && j < q.len()
        {
            use std::f64::consts::PI;
            let h = local_s - self.transition_s;
            let w = 2.0 * PI * frequency_hz;
            let envelope = (PI * h / self.hold_s).sin();
            let d_envelope = PI / self.hold_s * (PI * h / self.hold_s).cos();
            let e2 = envelope * envelope;
            q[j] += amplitude * e2 * (w * h).sin();
            qd[j] +=
                amplitude * (2.0 * envelope * d_envelope * (w * h).sin() + e2 * w * (w * h).cos());
        }
    }

    /// Peak speed of the arm's fastest point over `from_s..to_s` of the phase, m/s.
    fn peak_speed(&self, arm: &mut ArmSpeed, from_s: f64, to_s: f64) -> f64 {
        let (mut q, mut qd) = (vec![0.0; self.q_to.len()], vec![0.0; self.q_to.len()]);
        let n = ((to_s - from_s) * SPEED_SAMPLES_PER_S).ceil().max(96.0) as usize;
        (0..=n)
            .map(|k| {
                let t = from_s + (to_s - from_s) * k as f64 / n as f64;
                self.sample(t, &mut q, &mut qd);
                arm.fastest(&q, &qd)
            })
            .fold(0.0, f64::max)
    }

    /// Stretches the transition, then shrinks the wave, until no point of the arm moves
    /// faster than `cap_m_s`.
    fn keep_below(&mut self, arm: &mut ArmSpeed, cap_m_s: f64) {
        let cap_m_s = CAP_MARGIN * cap_m_s;
        // A path's speed scales with the inverse of its duration: one stretch suffices.
        let peak = self.peak_speed(arm, 0.0, self.transition_s);
        if peak > cap_m_s {
            self.transition_s *= peak / cap_m_s;
        }
        if self.wave.is_some() {
            let (from, to) = (self.transition_s, self.transition_s + self.hold_s);
            // Nearly linear in the amplitude (the Jacobian changes a little with the swing).
            for _ in 0..16 {
                let peak = self.peak_speed(arm, from, to);
                match &mut self.wave {
                    Some((amplitude, _)) if peak > cap_m_s => {
                        *amplitude *= CAP_MARGIN * cap_m_s / peak
                    }
                    _ => break,
                }
            }
        }
    }
}

/// The speed of an arm's fastest point: the axis end points of the bounding capsule of
/// each link with collision geometry (the points the safety layer tracks).
pub struct ArmSpeed<'a> {
    arm: &'a RobotModel,
    points_L: Vec<(LinkId, Vector)>,
    kinematics: KinematicState,
    jacobian: Jacobian,
}

impl<'a> ArmSpeed<'a> {
    /// The tracked points of `arm`.
    #[must_use]
    pub fn new(arm: &'a RobotModel) -> Self {
        let points_L = (0..arm.links().len())
            .filter_map(|link| link_bounding_capsule(arm, link))
            .flat_map(|c| [(c.link, c.a_L), (c.link, c.b_L)])
            .collect();
        Self {
            arm,
            points_L,
            kinematics: KinematicState::new(arm),
            jacobian: Jacobian::zeros(arm.dof()),
        }
    }

    /// Speed of the fastest tracked point with the arm at `q` moving at `qd`, m/s; 0 when
    /// `q` is not a configuration of the arm.
    pub fn fastest(&mut self, q: &[f64], qd: &[f64]) -> f64 {
        if self
            .arm
            .forward_kinematics(q, &mut self.kinematics)
            .is_err()
        {
            return 0.0;
        }
        let mut peak: f64 = 0.0;
        for &(link, p_L) in &self.points_L {
            let p_W = self.kinematics.link_pose(link).transform_point(p_L);
            self.arm
                .point_jacobian(&self.kinematics, link, p_W, &mut self.jacobian);
            peak = peak.max(self.jacobian.linear_velocity(qd).length());
        }
        peak
    }
}

/// Ranges the extra joints (trunk turn, trunk lean, shoulder rotation, forearm rotation,
/// rad) are drawn from at rest, in a reach and in a wave: a reach turns the trunk a little
/// towards either side and leans it forward, as people reaching over a table do.
/// Ranges the arm's three angles (shoulder abduction, shoulder flexion, elbow flexion, rad)
/// are drawn from at rest and in a reach: either arm's.
const REST_ARM: [[f64; 2]; 3] = [[0.0, 0.15], [-0.1, 0.15], [0.05, 0.35]];
const REACH_ARM: [[f64; 2]; 3] = [[0.0, 0.35], [1.0, 1.6], [0.05, 0.6]];

const REST_EXTRA: [[f64; 2]; 4] = [[-0.1, 0.1], [0.0, 0.1], [-0.2, 0.2], [0.6, 1.6]];
const REACH_EXTRA: [[f64; 2]; 4] = [[-0.25, 0.25], [0.05, 0.3], [-0.4, 0.4], [0.8, 2.2]];
const WAVE_EXTRA: [[f64; 2]; 4] = [[-0.1, 0.1], [0.0, 0.05], [-0.6, -0.2], [0.0, 0.4]];

/// The joints the generator moves, by index in the model's joint order.
#[derive(Debug, Clone, Copy, PartialEq)]
struct GeneratedJoints {
    /// Shoulder abduction, shoulder flexion, elbow flexion.
    arm: [Option<usize>; 3],
    /// Trunk turn, trunk lean, shoulder rotation, forearm rotation.
    extra: [Option<usize>; 4],
    /// The left arm's shoulder abduction, shoulder flexion, elbow flexion, shoulder rotation
    /// and forearm rotation (`left_*`), where the model has them all.
    left: Option<[usize; 5]>,
}

impl GeneratedJoints {
    fn of(arm: &RobotModel) -> Self {
        let index = |name: &str| {
            arm.actuated_joints()
                .iter()
                .position(|&j| arm.joints()[j].name == name)
        };
        let named = ["shoulder_abduction", "shoulder_flexion", "elbow_flexion"].map(index);
        let arm3 = if named.iter().all(Option::is_some) {
            named
        } else {
            [0, 1, 2].map(|j| (j < arm.dof()).then_some(j))
        };
        Self {
            arm: arm3,
            extra: [
                "trunk_turn",
                "trunk_lean",
                "shoulder_rotation",
                "forearm_rotation",
            ]
            .map(index),
            left: {
                let left = [
                    "left_shoulder_abduction",
                    "left_shoulder_flexion",
                    "left_elbow_flexion",
                    "left_shoulder_rotation",
                    "left_forearm_rotation",
                ]
                .map(index);
                left.iter()
                    .all(Option::is_some)
                    .then(|| left.map(|j| j.unwrap_or(0)))
            },
        }
    }
}

/// What the left arm does while the right performs a phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LeftArm {
    /// Hangs at the side (a posture drawn near rest).
    Rest,
    /// Stays where it was (holding a part).
    Hold,
    /// Reaches too (both hands in the shared space).
    Reach,
}

impl LeftArm {
    /// The left arm's share of each kind of phase: at rest half the time, holding where it
    /// was a quarter, reaching with the right arm a quarter; during a wave or a withdrawal it
    /// rests or holds.
    fn draw(rng: &mut ChaCha8Rng, kind: HumanMotionKind) -> Self {
        let u: f64 = rng.random();
        match kind {
            HumanMotionKind::Reach | HumanMotionKind::Rest if u < 0.25 => LeftArm::Reach,
            _ if u < 0.5 => LeftArm::Hold,
            _ => LeftArm::Rest,
        }
    }
}

/// A periodic sequence of human motion phases, fixed by the seed.
#[derive(Debug, Clone, PartialEq)]
pub struct HumanMotion {
    phases: Vec<Phase>,
    period_s: f64,
    dof: usize,
    /// Playback speed: 1 as generated, 0.5 half as fast.
    speed: f64,
    /// A recorded clip played instead of the phases.
    recorded: Option<Box<Playback>>,
}

/// A retargeted clip as the human plays it (`[human.recorded]`).
#[derive(Debug, Clone, PartialEq)]
struct Playback {
    motion: crate::retarget::RecordedMotion,
    /// Clip time at the episode's start, s.
    start_s: f64,
    end: ClipEnd,
}

impl Playback {
    /// The clip's time at played time `t_s` (the speed applied), and the sign of its
    /// velocity there (0 holding after the end, -1 played backwards).
    fn clip_time(&self, t_s: f64) -> (f64, f64) {
        let duration = self.motion.duration_s();
        let t = self.start_s + t_s;
        match self.end {
            ClipEnd::Hold => (t.min(duration), if t < duration { 1.0 } else { 0.0 }),
            ClipEnd::Loop => (t.rem_euclid(duration.max(1e-9)), 1.0),
            ClipEnd::Reverse => {
                let u = t.rem_euclid(2.0 * duration.max(1e-9));
                if u <= duration {
                    (u, 1.0)
                } else {
                    (2.0 * duration - u, -1.0)
                }
            }
        }
    }
}

impl HumanMotion {
    /// Generates the motion of `arm` (its joints found by name, see the module's summary;
    /// every joint within its position limits), cycling through `kinds`.
    /// Each movement's fastest point peaks at a speed drawn from `peak_speed_m_s` (m/s, low
    /// and high end) or slower; each transition's drawn duration is multiplied by a factor
    /// drawn from `duration_scale` (`[1, 1]`: as drawn, and no draw, so that a seed moves the
    /// arm as it did before the factor existed).
    #[must_use]
    pub fn generate(
        kinds: &[HumanMotionKind],
        shuffle: bool,
        arm: &RobotModel,
        peak_speed_m_s: [f64; 2],
        duration_scale: [f64; 2],
        seed: u64,
    ) -> Self {
        let limits = arm.position_limits();
        let dof = limits.len();
        let joints = GeneratedJoints::of(arm);
        let mut speed = ArmSpeed::new(arm);
        let [slowest, fastest] = peak_speed_m_s;
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4855_4d41_4e00_0000); // "HUMAN"
        // A configuration from the arm's three angles (abduction, flexion, elbow) and the
        // extra joints' values, within the limits.
        let clamp = |arm3: [f64; 3], extra: [f64; 4]| -> Vec<f64> {
            let mut q = vec![0.0; dof];
            for (j, v) in joints.arm.iter().zip(arm3) {
                if let Some(&j) = j.as_ref() {
                    q[j] = v;
                }
            }
            for (j, v) in joints.extra.iter().zip(extra) {
                if let Some(&j) = j.as_ref() {
                    q[j] = v;
                }
            }
            q.iter()
                .zip(&limits)
                .map(|(v, [lo, hi])| v.clamp(*lo, *hi))
                .collect()
        };
        // The extra joints' draws, only for a model that has them (the same seed moves a model
        // without them exactly as before they existed).
        let has_extra = joints.extra.iter().any(Option::is_some);
        let extra = |rng: &mut ChaCha8Rng, ranges: [[f64; 2]; 4]| -> [f64; 4] {
            if !has_extra {
                return [0.0; 4];
            }
            ranges.map(|[lo, hi]| {
                if lo < hi {
                    rng.random_range(lo..hi)
                } else {
                    lo
                }
            })
        };
        let mut rest = clamp([0.08, 0.05, 0.15], [0.0; 4]);
        // The left arm: drawn from a generator of its own, so that a seed moves the right arm
        // through the same postures as before the left existed (its timing stretches where
        // the left is the faster).
        let mut rng_left = ChaCha8Rng::seed_from_u64(seed ^ 0x4c45_4654_0000_0000); // "LEFT"
        if let Some(left) = joints.left {
            // At rest as the right arm is: the same angles, mirrored by the model.
            for (k, j) in left.into_iter().enumerate().take(3) {
                rest[j] = rest[joints.arm[k].unwrap_or(j)].clamp(limits[j][0], limits[j][1]);
            }
        }
        let mut order: Vec<HumanMotionKind> = kinds.iter().copied().cycle().take(PHASES).collect();
        if shuffle {
            // Fisher-Yates with the seeded generator.
            for i in (1..order.len()).rev() {
                order.swap(i, rng.random_range(0..=i));
            }
        }
        let mut phases = Vec::with_capacity(PHASES + 1);
        let mut t = 0.0;
        let mut q = rest.clone();
        for kind in order {
            let (mut q_to, transition_s, hold_s, wave) = match kind {
                HumanMotionKind::Rest => {
                    let arm3 = REST_ARM.map(|[lo, hi]| rng.random_range(lo..hi));
                    let (transition, hold) =
                        (rng.random_range(0.6..1.0), rng.random_range(0.8..2.0));
                    let extra = extra(&mut rng, REST_EXTRA);
                    (clamp(arm3, extra), transition, hold, None)
                }
                HumanMotionKind::Reach => {
                    let arm3 = REACH_ARM.map(|[lo, hi]| rng.random_range(lo..hi));
                    let (transition, hold) =
                        (rng.random_range(0.7..1.2), rng.random_range(0.5..1.5));
                    let extra = extra(&mut rng, REACH_EXTRA);
                    (clamp(arm3, extra), transition, hold, None)
                }
                HumanMotionKind::Withdraw => (rest.clone(), rng.random_range(0.4..0.7), 0.3, None),
                HumanMotionKind::Wave => {
                    let arm3 = [rng.random_range(0.3..0.7), rng.random_range(2.0..2.5), 1.0];
                    let hold = rng.random_range(1.5..2.5);
                    let wave = (rng.random_range(0.3..0.5), rng.random_range(1.2..2.0));
                    let extra = extra(&mut rng, WAVE_EXTRA);
                    (clamp(arm3, extra), 0.8, hold, Some(wave))
                }
            };
            if let Some(left) = joints.left {
                // Its three angles, then its shoulder's and forearm's rotation, drawn from
                // the right arm's ranges (holding: where it was).
                let ranges = match LeftArm::draw(&mut rng_left, kind) {
                    LeftArm::Hold => None,
                    LeftArm::Rest => Some((REST_ARM, REST_EXTRA)),
                    LeftArm::Reach => Some((REACH_ARM, REACH_EXTRA)),
                };
                let values: [f64; 5] = match ranges {
                    None => left.map(|j| q[j]),
                    Some((arm, extra)) => [arm[0], arm[1], arm[2], extra[2], extra[3]]
                        .map(|[lo, hi]| rng_left.random_range(lo..hi)),
                };
                for (j, v) in left.into_iter().zip(values) {
                    q_to[j] = v.clamp(limits[j][0], limits[j][1]);
                }
            }
            // Shorter transitions, and a wave's swings as much quicker (a hammering forearm).
            let scale = match duration_scale {
                [lo, hi] if lo < hi => rng.random_range(lo..=hi),
                [scale, _] => scale,
            };
            let transition_s = transition_s * scale;
            let wave = wave.map(|(amplitude, frequency_hz)| (amplitude, frequency_hz / scale));
            let mut phase = Phase {
                kind,
                t0_s: t,
                transition_s,
                hold_s,
                q_from: q.clone(),
                q_to: q_to.clone(),
                wave,
                elbow: joints.arm[2].unwrap_or(usize::MAX),
            };
            phase.keep_below(&mut speed, rng.random_range(slowest..=fastest));
            t += phase.transition_s + phase.hold_s;
            phases.push(phase);
            q = q_to;
        }
        // Close the cycle back at rest.
        let mut closing = Phase {
            kind: HumanMotionKind::Withdraw,
            t0_s: t,
            transition_s: 0.8,
            hold_s: 0.2,
            q_from: q,
            q_to: rest,
            wave: None,
            elbow: joints.arm[2].unwrap_or(usize::MAX),
        };
        closing.keep_below(&mut speed, slowest);
        t += closing.transition_s + closing.hold_s;
        phases.push(closing);
        Self {
            phases,
            period_s: t,
            dof,
            speed: 1.0,
            recorded: None,
        }
    }

    /// A recorded clip's motion, retargeted onto the arm, played from `start_s` into the
    /// clip; after its end it holds, loops or reverses.
    #[must_use]
    pub fn recorded(motion: crate::retarget::RecordedMotion, start_s: f64, end: ClipEnd) -> Self {
        let duration = motion.duration_s().max(1e-9);
        let dof = motion.q.first().map_or(0, Vec::len);
        Self {
            phases: Vec::new(),
            period_s: match end {
                ClipEnd::Reverse => 2.0 * duration,
                ClipEnd::Hold | ClipEnd::Loop => duration,
            },
            dof,
            speed: 1.0,
            recorded: Some(Box::new(Playback {
                motion,
                start_s: start_s.max(0.0),
                end,
            })),
        }
    }

    /// The recorded person's other arm, the one the model does not have or follow, at `t_s`
    /// (`RecordedMotion::other_arm`): shoulder, elbow and wrist in the model's `torso`
    /// frame. `None` for the generator's motion and for a clip without that arm.
    #[must_use]
    pub fn other_arm(&self, t_s: f64) -> Option<[Vector; 3]> {
        let p = self.recorded.as_ref()?;
        p.motion.other_arm_at(p.clip_time(t_s * self.speed).0)
    }

    /// The recorded clip's name, when a clip drives the human.
    #[must_use]
    pub fn clip(&self) -> Option<&str> {
        self.recorded.as_ref().map(|p| p.motion.name.as_str())
    }

    /// The same motion played `speed` times as fast (positions along the same path, joint
    /// velocities scaled by `speed`). Non-positive or non-finite values are ignored.
    #[must_use]
    pub fn with_speed(mut self, speed: f64) -> Self {
        if speed.is_finite() && speed > 0.0 {
            self.period_s *= self.speed / speed;
            self.speed = speed;
        }
        self
    }

    /// Time after which the motion repeats, s.
    #[must_use]
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// The primitive being performed at `t_s`; none for a recorded clip.
    #[must_use]
    pub fn kind_at(&self, t_s: f64) -> Option<HumanMotionKind> {
        self.recorded
            .is_none()
            .then(|| self.phase(t_s * self.speed).kind)
    }

    /// The phase at generated time `t_s` (before the speed is applied).
    fn phase(&self, t_s: f64) -> &Phase {
        let t = t_s.rem_euclid(self.period_s * self.speed);
        let i = self
            .phases
            .partition_point(|p| p.t0_s <= t)
            .saturating_sub(1);
        &self.phases[i]
    }

    /// Joint positions and velocities at `t_s` (slices of the arm's dof).
    pub fn sample(&self, t_s: f64, q: &mut [f64], qd: &mut [f64]) {
        if let Some(p) = &self.recorded {
            let n = self.dof.min(q.len());
            let (clip_t, sign) = p.clip_time(t_s * self.speed);
            p.motion.sample(clip_t, &mut q[..n], &mut qd[..n]);
            for v in &mut qd[..n] {
                *v *= sign * self.speed;
            }
            return;
        }
        let t = (t_s * self.speed).rem_euclid(self.period_s * self.speed);
        let p = self.phase(t);
        p.sample(t - p.t0_s, &mut q[..self.dof], &mut qd[..self.dof]);
        for v in qd.iter_mut() {
            *v *= self.speed;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arm() -> RobotModel {
        RobotModel::from_catalogue("human_arm").expect("catalogue")
    }

    const ISO_13855: [f64; 2] = [1.0, 2.0];
    const AS_DRAWN: [f64; 2] = [1.0, 1.0];

    #[test]
    fn same_seed_same_motion_other_seed_other_motion() {
        let kinds = [
            HumanMotionKind::Reach,
            HumanMotionKind::Wave,
            HumanMotionKind::Withdraw,
        ];
        let arm = arm();
        let a = HumanMotion::generate(&kinds, true, &arm, ISO_13855, AS_DRAWN, 5);
        let b = HumanMotion::generate(&kinds, true, &arm, ISO_13855, AS_DRAWN, 5);
        let c = HumanMotion::generate(&kinds, true, &arm, ISO_13855, AS_DRAWN, 6);
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn a_slower_motion_follows_the_same_path_with_scaled_velocities() {
        let kinds = [
            HumanMotionKind::Reach,
            HumanMotionKind::Wave,
            HumanMotionKind::Withdraw,
        ];
        let arm = arm();
        let m = HumanMotion::generate(&kinds, true, &arm, ISO_13855, AS_DRAWN, 2);
        let slow = m.clone().with_speed(0.5);
        assert!((slow.period_s() - 2.0 * m.period_s()).abs() < 1e-9);
        let (mut q, mut qd, mut q2, mut qd2) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        for k in 0..200 {
            let t = 0.037 * k as f64;
            m.sample(t, &mut q, &mut qd);
            slow.sample(2.0 * t, &mut q2, &mut qd2);
            for j in 0..3 {
                assert!((q[j] - q2[j]).abs() < 1e-12);
                assert!((0.5 * qd[j] - qd2[j]).abs() < 1e-12);
            }
            assert_eq!(m.kind_at(t), slow.kind_at(2.0 * t));
            assert!(m.kind_at(t).is_some());
        }
    }

    #[test]
    fn velocity_is_the_derivative_of_position_and_motion_is_continuous() {
        let kinds = [
            HumanMotionKind::Rest,
            HumanMotionKind::Reach,
            HumanMotionKind::Wave,
            HumanMotionKind::Withdraw,
        ];
        let arm = arm();
        let m = HumanMotion::generate(&kinds, false, &arm, ISO_13855, AS_DRAWN, 1);
        let (mut q0, mut q1, mut qd, mut scratch) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        let h = 1e-6;
        let n = 20_000;
        for k in 0..n {
            let t = m.period_s() * k as f64 / n as f64 + 1e-4;
            m.sample(t - h, &mut q0, &mut scratch);
            m.sample(t + h, &mut q1, &mut scratch);
            m.sample(t, &mut scratch, &mut qd);
            for j in 0..3 {
                let numeric = (q1[j] - q0[j]) / (2.0 * h);
                // Phase boundaries are C1 (rest to rest), so differences agree everywhere.
                assert!(
                    (numeric - qd[j]).abs() < 1e-4,
                    "t {t} joint {j}: {numeric} vs {}",
                    qd[j]
                );
            }
        }
        // A reach brings the shoulder forward past 1 rad of flexion at some point.
        let max_flexion = (0..n)
            .map(|k| {
                m.sample(m.period_s() * k as f64 / n as f64, &mut q0, &mut qd);
                q0[1]
            })
            .fold(f64::MIN, f64::max);
        assert!(max_flexion > 1.0);
    }

    /// No point of the arm moves faster than the top of the drawn range, sampled at 1 kHz
    /// (finer than the generator's own sampling) over whole periods of many seeds; and the
    /// range is used: some movement comes within 10 % of it, a slow range gives slow
    /// motions, and shortened transitions let a fast range be reached (the `recorded`
    /// calibration's ranges).
    #[test]
    fn every_movement_keeps_its_peak_speed() {
        let arm = arm();
        let mut speed = ArmSpeed::new(&arm);
        let kinds = [
            HumanMotionKind::Rest,
            HumanMotionKind::Reach,
            HumanMotionKind::Withdraw,
            HumanMotionKind::Wave,
        ];
        let (mut q, mut qd) = ([0.0; 3], [0.0; 3]);
        let recorded = crate::scenario::HumanSpeeds::Recorded;
        for (range, durations) in [
            (ISO_13855, AS_DRAWN),
            ([0.5, 0.8], AS_DRAWN),
            (recorded.peak_speed_m_s(), recorded.duration_scale()),
        ] {
            let mut fastest: f64 = 0.0;
            for seed in 0..12 {
                let m = HumanMotion::generate(&kinds, true, &arm, range, durations, seed);
                let n = (m.period_s() * 1000.0) as usize;
                for k in 0..n {
                    m.sample(k as f64 * 1e-3, &mut q, &mut qd);
                    let v = speed.fastest(&q, &qd);
                    assert!(
                        v <= range[1],
                        "seed {seed}, t {} s: {v} m/s",
                        k as f64 * 1e-3
                    );
                    fastest = fastest.max(v);
                }
            }
            assert!(fastest > 0.9 * range[1], "{range:?}: fastest {fastest}");
        }
    }

    /// The whole body's left arm rests, holds and reaches as drawn, within its limits, and
    /// keeps the speed cap with the rest of the body; its draws leave the right arm's
    /// postures as they were: the right arm's joints at each phase's end are those of the
    /// same seed on the body without a left arm.
    #[test]
    fn the_left_arm_rests_holds_and_reaches() {
        let body = RobotModel::from_catalogue("human").expect("catalogue");
        let one = RobotModel::one_armed_human().expect("one-armed");
        let joints = GeneratedJoints::of(&body);
        let left = joints.left.expect("a left arm");
        assert!(GeneratedJoints::of(&one).left.is_none());
        let limits = body.position_limits();
        let kinds = [
            HumanMotionKind::Rest,
            HumanMotionKind::Reach,
            HumanMotionKind::Withdraw,
            HumanMotionKind::Wave,
        ];
        let mut speed = ArmSpeed::new(&body);
        let (mut q, mut qd) = (vec![0.0; body.dof()], vec![0.0; body.dof()]);
        let (mut reached, mut rested, mut held) = (0, 0, 0);
        for seed in 0..6 {
            let m = HumanMotion::generate(&kinds, true, &body, ISO_13855, AS_DRAWN, seed);
            for p in &m.phases {
                let flexion = p.q_to[left[1]];
                reached += usize::from(flexion >= 1.0);
                rested += usize::from(flexion < 0.2);
                held += usize::from(left.iter().all(|&j| p.q_to[j] == p.q_from[j]));
            }
            let n = (m.period_s() * 200.0) as usize;
            for k in 0..n {
                m.sample(k as f64 / 200.0, &mut q, &mut qd);
                for &j in &left {
                    assert!(q[j] >= limits[j][0] - 1e-12 && q[j] <= limits[j][1] + 1e-12);
                }
                assert!(speed.fastest(&q, &qd) <= ISO_13855[1], "seed {seed}");
            }
            // The right arm's postures are the seed's whatever the left does: those of the
            // body without a left arm (whose joints come first in the same order).
            let still = HumanMotion::generate(&kinds, true, &one, ISO_13855, AS_DRAWN, seed);
            for (a, b) in m.phases.iter().zip(&still.phases) {
                for j in joints.arm.iter().chain(&joints.extra).flatten() {
                    assert_eq!(
                        a.q_to[*j], b.q_to[*j],
                        "seed {seed} joint {j} phase {:?} at {}",
                        a.kind, a.t0_s
                    );
                }
            }
        }
        assert!(
            reached > 10 && rested > 10 && held > 5,
            "{reached} {rested} {held}"
        );
    }

    /// The tracked points are the capsule end points: a pure elbow rotation at 1 rad/s moves
    /// the farthest of them at its distance from the elbow's axis (which the upper arm's
    /// points lie on or behind).
    #[test]
    fn arm_speed_is_the_fastest_capsule_end() {
        let arm = arm();
        let mut speed = ArmSpeed::new(&arm);
        let q = [0.0, 0.0, 0.0];
        let v = speed.fastest(&q, &[0.0, 0.0, 1.0]);
        // Farthest capsule end point from the elbow, from the capsules themselves.
        let mut kinematics = KinematicState::new(&arm);
        arm.forward_kinematics(&q, &mut kinematics).expect("fk");
        let joint = &arm.joints()[arm.joint_id("elbow_flexion").expect("an elbow joint")];
        let X_WE = kinematics.link_pose(joint.child);
        let (p_elbow, axis) = (X_WE.translation, X_WE.rotation * joint.axis);
        let reach = (0..arm.links().len())
            .filter_map(|l| link_bounding_capsule(&arm, l))
            .filter(|c| c.link != 0)
            .flat_map(|c| {
                let X = kinematics.link_pose(c.link);
                [X.transform_point(c.a_L), X.transform_point(c.b_L)]
            })
            .map(|p| (p - p_elbow).cross(axis).length())
            .fold(0.0, f64::max);
        assert!((v - reach).abs() < 1e-9, "{v} vs {reach}");
        assert_eq!(speed.fastest(&[0.0; 2], &[0.0; 2]), 0.0);
    }

    /// A clip's end: `hold` stands still with zero velocity, `loop` starts again, `reverse`
    /// turns back without a jump (its velocity flips sign).
    #[test]
    fn a_recorded_clip_holds_loops_or_reverses_at_its_end() {
        let motion = crate::retarget::RecordedMotion {
            name: "ramp".into(),
            rate_hz: 10.0,
            q: (0..=10)
                .map(|f| vec![0.1 * f64::from(f), 0.0, 0.0])
                .collect(),
            // The other arm's wrist moves along x as the joint does.
            other_arm: (0..=10)
                .map(|f| [Vector::ZERO, Vector::Z, Vector::X * (0.1 * f64::from(f))])
                .collect(),
        };
        // The other arm is played at the same clip time as the joints.
        let wrist = |end, t: f64| {
            let m = HumanMotion::recorded(motion.clone(), 0.0, end);
            m.other_arm(t).expect("the clip has the other arm")[2].x
        };
        for (end, t, x) in [
            (ClipEnd::Hold, 0.5, 0.5),
            (ClipEnd::Hold, 1.7, 1.0),
            (ClipEnd::Loop, 1.25, 0.25),
            (ClipEnd::Reverse, 1.25, 0.75),
        ] {
            assert!((wrist(end, t) - x).abs() < 1e-12, "{end:?} at {t} s");
        }
        let at = |end, t: f64| {
            let m = HumanMotion::recorded(motion.clone(), 0.0, end);
            let (mut q, mut qd) = ([0.0; 3], [0.0; 3]);
            m.sample(t, &mut q, &mut qd);
            (q[0], qd[0])
        };
        let close = |(a, b): (f64, f64), (c, d): (f64, f64)| {
            assert!(
                (a - c).abs() < 1e-12 && (b - d).abs() < 1e-12,
                "{a} {b} vs {c} {d}"
            );
        };
        close(at(ClipEnd::Hold, 0.5), (0.5, 1.0));
        close(at(ClipEnd::Hold, 1.7), (1.0, 0.0));
        close(at(ClipEnd::Loop, 1.25), (0.25, 1.0));
        close(at(ClipEnd::Reverse, 1.25), (0.75, -1.0));
        close(at(ClipEnd::Reverse, 2.25), (0.25, 1.0));
        // Played twice as fast: twice the velocity along the same path.
        let fast = HumanMotion::recorded(motion, 0.0, ClipEnd::Hold).with_speed(2.0);
        let (mut q, mut qd) = ([0.0; 3], [0.0; 3]);
        fast.sample(0.25, &mut q, &mut qd);
        assert!((q[0] - 0.5).abs() < 1e-12 && (qd[0] - 2.0).abs() < 1e-12);
        assert_eq!(fast.clip(), Some("ramp"));
        let other = fast.other_arm(0.25).expect("the other arm");
        assert!((other[2].x - 0.5).abs() < 1e-12);
        assert_eq!(fast.kind_at(0.1), None);
    }
}
