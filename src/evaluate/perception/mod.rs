//! Perception in the closed loop: what the safety filter is told about the human, tick by
//! tick. Ground truth, and ground truth seen through a camera with noise, dropped frames and
//! latency. ProcNet plugs in through the same trait.

mod config;
mod ground_truth;
mod noisy;
pub mod procnet;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_safety::{HumanEstimate, PartEstimate};
use workcell_sim::{CellModel, CellState};

use crate::robots::math::Vector;

pub use config::{
    AgeingBound, GroundTruthConfig, MaskKind, NoisyConfig, PerceptionConfig, PerceptionKind,
    ProcNetConfig, switch_perception_kind,
};
pub use ground_truth::{Foresight, GroundTruth};
pub use noisy::{NoisyCamera, sphere_radius_for_sigmas};

/// What a perception implementation gets every control tick.
#[derive(Debug, Clone, Copy)]
pub struct PerceptionInput<'a> {
    pub t_s: f64,
    pub model: &'a CellModel,
    pub state: &'a CellState,
    /// The true human parts (exact capsules and velocities) at `t_s`.
    pub truth: &'a HumanEstimate,
    /// The recorded person's other arm at `t_s` (true capsules, velocities over the last
    /// tick), for a perception that sees the whole person; empty where there is none or it
    /// is not to be seen (`EvaluationConfig::other_arm_seen`). Its parts follow the
    /// modelled ones in an estimate.
    pub other_arm: &'a [PartEstimate],
}

/// A source of human estimates for the safety filter.
pub trait HumanPerception {
    /// A short name for reports.
    fn name(&self) -> String;
    /// The estimate available to the controller at `input.t_s`, into `out`.
    fn estimate(&mut self, input: &PerceptionInput<'_>, out: &mut HumanEstimate);
    /// The mean error of the fits so far at their exposure, m
    /// ([`super::EpisodeMetrics::fit_error_m`]); `None` for a perception that fits no
    /// frames, or before its first fit.
    fn fit_error_m(&self) -> Option<f64> {
        None
    }
    /// The parts of the last estimate that are a region the part may be in (an arm no fit
    /// saw, guarded over its reach), not a pose: the perception error leaves them out.
    fn unseen_parts(&self) -> &[workcell_safety::HumanPart] {
        &[]
    }
}

/// A perception that reports no human from `at_s` on (`perception.camera_fails_at_s`).
struct CameraFailure {
    inner: Box<dyn HumanPerception>,
    at_s: f64,
}

impl HumanPerception for CameraFailure {
    fn name(&self) -> String {
        format!("{}, failing at {} s", self.inner.name(), self.at_s)
    }

    fn estimate(&mut self, input: &PerceptionInput<'_>, out: &mut HumanEstimate) {
        if input.t_s < self.at_s {
            self.inner.estimate(input, out);
        } else {
            out.parts.clear();
            out.uncertainty_m = 0.0;
            out.uncertainty_rate_m_s = 0.0;
        }
    }

    fn fit_error_m(&self) -> Option<f64> {
        self.inner.fit_error_m()
    }
}

#[cfg(test)]
mod tests {
    use super::ground_truth::FORESIGHT_INSTANTS;
    use super::noisy::gaussian;
    use super::*;

    /// The oracle's look ahead is where the simulated human truly is later: its last
    /// instant, taken in the default cell's first fast movement with 0.3 s of foresight,
    /// matches the arm parts of the simulator's human (its kinematic bodies, stepped 300 ms
    /// further) to within a micrometre; the first parts (one per body part) are the present
    /// truth.
    #[test]
    fn foresight_tells_where_the_simulated_human_will_be() {
        use workcell_sim::{CellState, RobotCommand, step};
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        let scenario = workcell_sim::Scenario::from_file(path).expect("scenario");
        let model = CellModel::new(&scenario, path).expect("cell");
        let mut state = CellState::new(&model).expect("state");
        let mut geometry = workcell_safety::HumanGeometry::new(&model.human).expect("arm");
        let mut kinematics = crate::robots::KinematicState::new(&model.human);
        kinematics.X_WB = model.X_WH;
        let mut truth = |state: &CellState| {
            model
                .human
                .forward_kinematics(state.human_q(), &mut kinematics)
                .expect("human pose");
            let mut estimate = HumanEstimate::default();
            geometry.estimate_into(&model.human, &kinematics, state.human_qd(), &mut estimate);
            estimate
        };
        // Into the first movement of the arm whose hand is faster than 0.5 m/s.
        let mut now = truth(&state);
        while now.parts.iter().all(|p| p.v_b_W.length() < 0.5) {
            assert!(state.time_s() < 20.0, "the arm never moves");
            step(&model, &mut state, &RobotCommand::Nominal).expect("step");
            now = truth(&state);
        }
        let mut oracle = Foresight::new(0.3, &model).expect("oracle");
        let mut told = HumanEstimate::default();
        let input = PerceptionInput {
            t_s: state.time_s(),
            model: &model,
            state: &state,
            truth: &now,
            other_arm: &[],
        };
        oracle.estimate(&input, &mut told);
        // The default cell's whole body: upper arm, forearm, hand, head and the left arm's.
        let parts = now.parts.len();
        assert_eq!(parts, 7);
        assert_eq!(told.parts.len(), parts * (1 + FORESIGHT_INSTANTS));
        assert_eq!(told.parts[..parts], now.parts[..]);
        for _ in 0..300 {
            step(&model, &mut state, &RobotCommand::Nominal).expect("step");
        }
        let later = truth(&state);
        let mut moved: f64 = 0.0;
        for (told, truth) in told.parts[parts * FORESIGHT_INSTANTS..]
            .iter()
            .zip(&later.parts)
        {
            assert_eq!(told.part, truth.part);
            for (a, b) in [
                (told.capsule.a_W, truth.capsule.a_W),
                (told.capsule.b_W, truth.capsule.b_W),
            ] {
                assert!((a - b).length() < 1e-6, "{a:?} vs {b:?}");
            }
        }
        for (now, later) in now.parts.iter().zip(&later.parts) {
            moved = moved.max((later.capsule.b_W - now.capsule.b_W).length());
        }
        // The check means something only if the arm moved meanwhile.
        assert!(moved > 0.01, "the arm moved {moved} m in 0.3 s");
    }

    /// Reference: the chi distribution with 3 degrees of freedom, solved for
    /// `Q(3/2, x^2/2) = erfc(k / sqrt 2)` with mpmath 1.3.0 (regularized upper incomplete
    /// gamma, 30 digits): an independent route from the closed form the code uses.
    #[test]
    fn the_sphere_radius_matches_the_chi_distribution() {
        for (k, x) in [
            (1.0, 1.877_961_762_193_714),
            (2.0, 2.832_822_225_319_875),
            (3.0, 3.762_500_977_956_908),
            (4.0, 4.696_948_013_014_455),
        ] {
            let r = sphere_radius_for_sigmas(k);
            assert!((r - x).abs() < 1e-9, "k {k}: {r} against {x}");
            // Never below k itself; tighter than the box of k sigmas per axis from k = 2
            // on (at k = 1 the box, 1.73, is exceeded more often than 1-D's 1 sigma).
            assert!(r > k);
            assert_eq!(r < k * 3f64.sqrt(), k >= 2.0);
        }
        assert_eq!(sphere_radius_for_sigmas(0.0), 0.0);
        assert_eq!(sphere_radius_for_sigmas(f64::NAN), 0.0);
    }

    /// Sampled like the camera samples its errors (independent Gaussian position and velocity
    /// noise per axis, the velocity's error carried over the age), the end points fall
    /// outside the bound (less the human's acceleration, which the samples do not have) as
    /// often as a 1-D Gaussian falls beyond k sigmas.
    #[test]
    fn the_camera_bound_is_exceeded_as_often_as_its_confidence_says() {
        let config = NoisyConfig {
            confidence_sigmas: 2.0,
            ..NoisyConfig::default()
        };
        let age = 0.2;
        let radius = config.uncertainty(sphere_radius_for_sigmas(2.0), age)
            - 0.5 * config.human_acceleration_m_s2 * age * age;
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 400_000;
        let outside = (0..n)
            .filter(|_| {
                let mut sq = 0.0;
                for _ in 0..3 {
                    let e = config.position_noise_m * gaussian(&mut rng)
                        + config.velocity_noise_m_s * age * gaussian(&mut rng);
                    sq += e * e;
                }
                sq.sqrt() > radius
            })
            .count();
        let expected = libm::erfc(2.0 / std::f64::consts::SQRT_2); // 0.0455
        let p = outside as f64 / n as f64;
        // Four binomial standard errors (0.00033 each).
        let se = (expected * (1.0 - expected) / n as f64).sqrt();
        assert!((p - expected).abs() < 4.0 * se, "{p} against {expected}");
    }

    /// A recorded person's other arm, given, is seen by the perceptions of the whole person
    /// after the modelled parts: ground truth exactly; the noisy camera without noise, 50
    /// ms late, where its velocity carries it (the hand moving 1 m/s along x: 5 cm on).
    #[test]
    fn the_whole_persons_perceptions_see_the_other_arm() {
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        let scenario = workcell_sim::Scenario::from_file(path).expect("scenario");
        let model = CellModel::new(&scenario, path).expect("cell");
        let state = CellState::new(&model).expect("state");
        let part = |part, x: f64, vx: f64| PartEstimate {
            part,
            capsule: workcell_safety::Capsule::new(
                Vector::new(x, 0.0, 1.0),
                Vector::new(x + 0.2, 0.0, 1.0),
                0.05,
            ),
            v_a_W: Vector::new(vx, 0.0, 0.0),
            v_b_W: Vector::new(vx, 0.0, 0.0),
        };
        let truth = HumanEstimate {
            parts: vec![part(workcell_safety::HumanPart::Forearm, 0.0, 0.0)],
            ..HumanEstimate::default()
        };
        let other = [part(workcell_safety::HumanPart::Hand, 1.0, 1.0)];
        let input = |t_s, other_arm| PerceptionInput {
            t_s,
            model: &model,
            state: &state,
            truth: &truth,
            other_arm,
        };
        let mut out = HumanEstimate::default();
        GroundTruth.estimate(&input(0.0, &other), &mut out);
        assert_eq!(out.parts, [truth.parts[0], other[0]]);
        GroundTruth.estimate(&input(0.0, &[]), &mut out);
        assert_eq!(out.parts, truth.parts);

        let mut camera = NoisyCamera::new(
            NoisyConfig {
                position_noise_m: 0.0,
                velocity_noise_m_s: 0.0,
                dropout: 0.0,
                latency_s: 0.05,
                ..NoisyConfig::default()
            },
            1,
        );
        camera.estimate(&input(0.0, &other), &mut out);
        assert!(out.parts.is_empty(), "nothing has arrived yet");
        camera.estimate(&input(0.05, &other), &mut out);
        assert_eq!(out.parts.len(), 2);
        assert_eq!(out.parts[0], truth.parts[0]);
        let seen = out.parts[1];
        assert_eq!(seen.part, workcell_safety::HumanPart::Hand);
        assert!(
            (seen.capsule.a_W.x - 1.05).abs() < 1e-12,
            "{:?}",
            seen.capsule
        );
        assert!(
            (seen.capsule.b_W.x - 1.25).abs() < 1e-12,
            "{:?}",
            seen.capsule
        );
    }
}
