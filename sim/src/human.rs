//! Seeded motions of the human arm: resting, reaching into the shared space, waving,
//! withdrawing. Joint order of the catalogue `human_arm`: shoulder abduction, shoulder
//! flexion, elbow flexion (radians; 0 is the arm hanging straight down).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::scenario::HumanMotionKind;
use crate::trajectory::quintic;

/// Number of phases generated before the motion repeats.
const PHASES: usize = 24;

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
}

/// A periodic sequence of human motion phases, fixed by the seed.
#[derive(Debug, Clone, PartialEq)]
pub struct HumanMotion {
    phases: Vec<Phase>,
    period_s: f64,
    dof: usize,
    /// Playback speed: 1 as generated, 0.5 half as fast.
    speed: f64,
}

impl HumanMotion {
    /// Generates the motion for an arm with position limits `limits` (at least 3 joints for
    /// the motion primitives; extra joints stay at 0), cycling through `kinds`.
    #[must_use]
    pub fn generate(
        kinds: &[HumanMotionKind],
        shuffle: bool,
        limits: &[[f64; 2]],
        seed: u64,
    ) -> Self {
        let dof = limits.len();
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4855_4d41_4e00_0000); // "HUMAN"
        let clamp = |q: [f64; 3]| -> Vec<f64> {
            (0..dof)
                .map(|j| {
                    q.get(j)
                        .copied()
                        .unwrap_or(0.0)
                        .clamp(limits[j][0], limits[j][1])
                })
                .collect()
        };
        let rest = clamp([0.08, 0.05, 0.15]);
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
            let (q_to, transition_s, hold_s, wave) = match kind {
                HumanMotionKind::Rest => (
                    clamp([
                        rng.random_range(0.0..0.15),
                        rng.random_range(-0.1..0.15),
                        rng.random_range(0.05..0.35),
                    ]),
                    rng.random_range(0.6..1.0),
                    rng.random_range(0.8..2.0),
                    None,
                ),
                HumanMotionKind::Reach => (
                    clamp([
                        rng.random_range(0.0..0.35),
                        rng.random_range(1.0..1.6),
                        rng.random_range(0.05..0.6),
                    ]),
                    rng.random_range(0.7..1.2),
                    rng.random_range(0.5..1.5),
                    None,
                ),
                HumanMotionKind::Withdraw => (rest.clone(), rng.random_range(0.4..0.7), 0.3, None),
                HumanMotionKind::Wave => (
                    clamp([rng.random_range(0.3..0.7), rng.random_range(2.0..2.5), 1.0]),
                    0.8,
                    rng.random_range(1.5..2.5),
                    Some((rng.random_range(0.3..0.5), rng.random_range(1.2..2.0))),
                ),
            };
            phases.push(Phase {
                kind,
                t0_s: t,
                transition_s,
                hold_s,
                q_from: q.clone(),
                q_to: q_to.clone(),
                wave,
            });
            t += transition_s + hold_s;
            q = q_to;
        }
        // Close the cycle back at rest.
        phases.push(Phase {
            kind: HumanMotionKind::Withdraw,
            t0_s: t,
            transition_s: 0.8,
            hold_s: 0.2,
            q_from: q,
            q_to: rest,
            wave: None,
        });
        t += 1.0;
        Self {
            phases,
            period_s: t,
            dof,
            speed: 1.0,
        }
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

    /// The primitive being performed at `t_s`.
    #[must_use]
    pub fn kind_at(&self, t_s: f64) -> HumanMotionKind {
        self.phase(t_s * self.speed).kind
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
        self.sample_generated(t_s * self.speed, q, qd);
        for v in qd.iter_mut() {
            *v *= self.speed;
        }
    }

    fn sample_generated(&self, t_s: f64, q: &mut [f64], qd: &mut [f64]) {
        let t = t_s.rem_euclid(self.period_s * self.speed);
        let p = self.phase(t);
        let local = t - p.t0_s;
        let tau = (local / p.transition_s).clamp(0.0, 1.0);
        let (s, ds, _) = quintic(tau);
        let ds = if local < p.transition_s {
            ds / p.transition_s
        } else {
            0.0
        };
        for j in 0..self.dof {
            let d = p.q_to[j] - p.q_from[j];
            q[j] = p.q_from[j] + d * s;
            qd[j] = d * ds;
        }
        // Waving: the elbow swings about its target, faded in and out with sin^2 envelopes.
        if let Some((amplitude, frequency_hz)) = p.wave
            && local > p.transition_s
            && self.dof > 2
        {
            let h = local - p.transition_s;
            let w = 2.0 * std::f64::consts::PI * frequency_hz;
            let envelope = (std::f64::consts::PI * h / p.hold_s).sin();
            let d_envelope =
                std::f64::consts::PI / p.hold_s * (std::f64::consts::PI * h / p.hold_s).cos();
            let e2 = envelope * envelope;
            q[2] += amplitude * e2 * (w * h).sin();
            qd[2] +=
                amplitude * (2.0 * envelope * d_envelope * (w * h).sin() + e2 * w * (w * h).cos());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> Vec<[f64; 2]> {
        vec![[-0.3, 2.6], [-0.87, 3.1], [0.0, 2.53]]
    }

    #[test]
    fn same_seed_same_motion_other_seed_other_motion() {
        let kinds = [
            HumanMotionKind::Reach,
            HumanMotionKind::Wave,
            HumanMotionKind::Withdraw,
        ];
        let a = HumanMotion::generate(&kinds, true, &limits(), 5);
        let b = HumanMotion::generate(&kinds, true, &limits(), 5);
        let c = HumanMotion::generate(&kinds, true, &limits(), 6);
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
        let m = HumanMotion::generate(&kinds, true, &limits(), 2);
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
        let m = HumanMotion::generate(&kinds, false, &limits(), 1);
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
}
