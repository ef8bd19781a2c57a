//! Perception in the closed loop: what the safety filter is told about the human, tick by
//! tick. Ground truth, and ground truth seen through a camera with noise, dropped frames and
//! latency. ProcNet plugs in through the same trait.

mod ground_truth;
mod noisy;
pub mod procnet;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use workcell_safety::{HumanEstimate, PartEstimate};
use workcell_sim::{CellModel, CellState};

use crate::robots::math::Vector;

use ground_truth::foresight_name;
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
}

/// A source of human estimates for the safety filter.
pub trait HumanPerception {
    /// A short name for reports.
    fn name(&self) -> String;
    /// The estimate available to the controller at `input.t_s`, into `out`.
    fn estimate(&mut self, input: &PerceptionInput<'_>, out: &mut HumanEstimate);
}

/// Settings of the perception model (the `[perception]` table of an evaluation file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PerceptionConfig {
    /// `ground_truth` (exact, every tick), `noisy` (a camera: the settings below) or
    /// `procnet` (the cell's camera rendered, ProcNet and render-and-compare; `rate_hz` is
    /// the camera's, the noise settings do not apply).
    pub kind: PerceptionKind,
    /// For `procnet`: the network's weights, relative to the evaluation file. Default (none
    /// given): the shipped ones of this source tree for the camera,
    /// `procnet/weights/procnet-depth.safetensors` (the network that reads the depth
    /// image too) where `depth`, else `procnet-cpu.safetensors` ([`Self::weights_path`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weights: Option<std::path::PathBuf>,
    /// For `procnet`: the cell's camera by name; empty for the first. Default empty.
    pub camera: String,
    /// For `procnet`: `network` (ProcNet's masks of the arm's parts) or `ground_truth` (each
    /// part's pixels in the rendered frame: the articulated fit alone). Default `network`.
    pub masks: MaskKind,
    /// For `procnet`: the camera also measures depth (RGB-D), and the fit uses it. Default
    /// false.
    pub depth: bool,
    /// For `procnet`: the fraction of the forearm's pixels that a black disc hides in every
    /// frame (the paper's artificial occluders, in the loop; 0.66 and above is its heavy
    /// occlusion). Default 0.
    pub occlusion: f64,
    /// For `procnet`: the factor on the fit's curvature uncertainty
    /// (`ArmFitConfig::uncertainty_scale`), in place of the one calibrated for the masks and
    /// depth chosen (the calibration file beside the weights,
    /// `workcell_perception::pose::Calibration::of_weights`), which is used when the key is
    /// left out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_scale: Option<f64>,
    /// For `procnet`: the uncertainty's floor, m (`ArmFitConfig::uncertainty_floor_m`), in
    /// place of the calibrated one (left out: the calibrated one). The floors where the depth
    /// image shows the forearm hidden are the calibrated ones, never below this.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_floor_m: Option<f64>,
    /// The camera delivers nothing from this time on, s (a failed camera; perception
    /// switched off mid-episode); left out, never. `procnet` ages its last estimate out
    /// ([`procnet::MAX_AGE_S`]); the others report no human at once. Either way the
    /// filter then brakes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera_fails_at_s: Option<f64>,
    /// Camera frame rate, Hz. Default 30.
    pub rate_hz: f64,
    /// Standard deviation of the position error of each part end point, per axis, m.
    /// Default 0.01.
    pub position_noise_m: f64,
    /// Standard deviation of the velocity error, per axis, m/s. Default 0.05.
    pub velocity_noise_m_s: f64,
    /// Probability that a frame yields no estimate. Default 0.1.
    pub dropout: f64,
    /// Time from exposure to the estimate being available, s. Default 0.05.
    pub latency_s: f64,
    /// Bound on the human's acceleration used to grow the uncertainty of an ageing estimate,
    /// m/s^2. Default 10.
    pub human_acceleration_m_s2: f64,
    /// Confidence of the reported uncertainty, in standard deviations of a 1-D Gaussian:
    /// each end point's 3-D error stays within the bound as often as a 1-D error stays
    /// within this many sigmas (4: all but 6.3e-5). Default 4.
    pub confidence_sigmas: f64,
    /// For `ground_truth`: an oracle that also tells the filter where each arm part truly
    /// will be over this many seconds ahead (six instants, evenly spaced): what a perfect
    /// predictor of the human would give, for measuring what bounds the filter; no camera can
    /// have it. Default 0 (off).
    pub foresight_s: f64,
}

/// Where the `procnet` perception's masks of the arm come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskKind {
    Network,
    GroundTruth,
}

/// Which perception model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PerceptionKind {
    GroundTruth,
    Noisy,
    Procnet,
}

impl Default for PerceptionConfig {
    fn default() -> Self {
        Self {
            kind: PerceptionKind::Noisy,
            weights: None,
            camera: String::new(),
            masks: MaskKind::Network,
            depth: false,
            occlusion: 0.0,
            uncertainty_scale: None,
            uncertainty_floor_m: None,
            camera_fails_at_s: None,
            rate_hz: 30.0,
            position_noise_m: 0.01,
            velocity_noise_m_s: 0.05,
            dropout: 0.1,
            latency_s: 0.05,
            human_acceleration_m_s2: 10.0,
            confidence_sigmas: 4.0,
            foresight_s: 0.0,
        }
    }
}

impl PerceptionConfig {
    /// The network's weights: `weights`, or the shipped ones for the camera.
    #[must_use]
    pub fn weights_path(&self) -> std::path::PathBuf {
        self.weights
            .clone()
            .unwrap_or_else(|| crate::procnet::weights::shipped_path(self.depth))
    }

    /// The uncertainty of an estimate `age_s` old, m, for an estimate whose bound is
    /// `base_m + drift_m_s age + a_max age^2 / 2`. Until the next frame is due
    /// (`latency_s + 1 / rate_hz` after exposure) the bound is held at its value then: the
    /// inflated human stands still between frames instead of closing in on the arm at the
    /// bound's growth rate (up to 1.2 m/s at 83 ms with the defaults), which the barrier
    /// rows would have to outrun. A lost frame lets it grow; its rate is not reported
    /// (`uncertainty_rate_m_s` stays 0): told to the filter, the 1.2 m/s on top of the
    /// human's 2 m/s made the rows infeasible often enough to slow the task to 1.7 times the
    /// unfiltered one, with more violations, not fewer (experiments/safety.md).
    #[must_use]
    pub fn aged_uncertainty(&self, base_m: f64, drift_m_s: f64, age_s: f64) -> f64 {
        let age = self.held_age_s(age_s);
        base_m + drift_m_s * age + 0.5 * self.human_acceleration_m_s2 * age * age
    }

    /// The age an estimate's bound is taken at: no younger than the age at which the next
    /// frame is due (`latency_s + 1 / rate_hz` after exposure).
    fn held_age_s(&self, age_s: f64) -> f64 {
        age_s.max(self.latency_s + 1.0 / self.rate_hz)
    }

    /// The noisy camera's uncertainty `age_s` after exposure, m: `radius_sigmas` times the
    /// sigma of an end point's 3-D error per axis (position noise plus velocity noise times
    /// the age, independent Gaussians: sqrt(sigma_p^2 + (sigma_v age)^2)), plus the human's
    /// acceleration over the age; held until the next frame is due as in
    /// [`PerceptionConfig::aged_uncertainty`]. The camera passes
    /// `sphere_radius_for_sigmas(confidence_sigmas)`, computed once.
    #[must_use]
    pub fn noisy_camera_uncertainty(&self, radius_sigmas: f64, age_s: f64) -> f64 {
        let age = self.held_age_s(age_s);
        let sigma = self.position_noise_m.hypot(self.velocity_noise_m_s * age);
        radius_sigmas * sigma + 0.5 * self.human_acceleration_m_s2 * age * age
    }

    /// Checks ranges; the error names the key.
    ///
    /// # Errors
    /// [`crate::Error::Config`] with the key `perception.<key>`.
    pub fn validate(&self) -> crate::Result<()> {
        let check = |key: &str, v: f64, ok: bool| {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err(crate::Error::config(
                    format!("perception.{key}"),
                    format!("out of range: {v}"),
                ))
            }
        };
        check("rate_hz", self.rate_hz, self.rate_hz > 0.0)?;
        check(
            "position_noise_m",
            self.position_noise_m,
            self.position_noise_m >= 0.0,
        )?;
        check(
            "velocity_noise_m_s",
            self.velocity_noise_m_s,
            self.velocity_noise_m_s >= 0.0,
        )?;
        check("dropout", self.dropout, (0.0..1.0).contains(&self.dropout))?;
        check("latency_s", self.latency_s, self.latency_s >= 0.0)?;
        check(
            "human_acceleration_m_s2",
            self.human_acceleration_m_s2,
            self.human_acceleration_m_s2 >= 0.0,
        )?;
        check(
            "confidence_sigmas",
            self.confidence_sigmas,
            self.confidence_sigmas >= 0.0,
        )?;
        check("foresight_s", self.foresight_s, self.foresight_s >= 0.0)?;
        check(
            "occlusion",
            self.occlusion,
            (0.0..1.0).contains(&self.occlusion),
        )?;
        // Left out: the calibrated values, a camera that never fails. Given: a value >= 0
        // (the -1 that once stood for "left out" is refused, not taken as a value).
        for (key, v) in [
            ("uncertainty_scale", self.uncertainty_scale),
            ("uncertainty_floor_m", self.uncertainty_floor_m),
            ("camera_fails_at_s", self.camera_fails_at_s),
        ] {
            if let Some(v) = v {
                check(key, v, v >= 0.0).map_err(|_| {
                    crate::Error::config(
                        format!("perception.{key}"),
                        format!("out of range: {v} (>= 0; leave the key out for the default)"),
                    )
                })?;
            }
        }
        if self.foresight_s > 0.0 && self.kind != PerceptionKind::GroundTruth {
            return Err(crate::Error::config(
                "perception.foresight_s",
                format!(
                    "only the ground_truth perception can see the future (kind is {})",
                    match self.kind {
                        PerceptionKind::GroundTruth => "ground_truth",
                        PerceptionKind::Noisy => "noisy",
                        PerceptionKind::Procnet => "procnet",
                    }
                ),
            ));
        }
        Ok(())
    }

    /// The perception this configuration describes, seeded, for the cell `model` built from
    /// `scenario`.
    ///
    /// # Errors
    /// For `procnet`: no such camera, weights that do not load, a human without a forearm.
    pub fn build(
        &self,
        seed: u64,
        scenario: &workcell_sim::Scenario,
        model: &CellModel,
    ) -> crate::error::Result<Box<dyn HumanPerception>> {
        let inner: Box<dyn HumanPerception> = match self.kind {
            PerceptionKind::GroundTruth if self.foresight_s > 0.0 => {
                Box::new(Foresight::new(self.foresight_s, model)?)
            }
            PerceptionKind::GroundTruth => Box::new(GroundTruth),
            PerceptionKind::Noisy => Box::new(NoisyCamera::new(self.clone(), seed)),
            PerceptionKind::Procnet => {
                return Ok(Box::new(procnet::ProcNetCamera::new(
                    self, scenario, model,
                )?));
            }
        };
        Ok(if let Some(at_s) = self.camera_fails_at_s {
            Box::new(CameraFailure { inner, at_s })
        } else {
            inner
        })
    }

    /// A short description for reports, without building anything.
    #[must_use]
    pub fn describe(&self) -> String {
        let base = match self.kind {
            PerceptionKind::GroundTruth if self.foresight_s > 0.0 => {
                foresight_name(self.foresight_s)
            }
            PerceptionKind::GroundTruth => GroundTruth.name(),
            PerceptionKind::Noisy => NoisyCamera::new(self.clone(), 0).name(),
            PerceptionKind::Procnet => format!(
                "{} + articulated render-and-compare{}{}, latency {:.0} ms",
                match self.masks {
                    // The weights' own header says which network they hold (ProcNet or the
                    // feed-forward baseline); an unreadable file fails when it is loaded.
                    MaskKind::Network => format!(
                        "{} ({})",
                        crate::procnet::weights::read_config(&self.weights_path())
                            .map_or("ProcNet", |c| c.model_name()),
                        self.weights_path().display()
                    ),
                    MaskKind::GroundTruth => "ground-truth arm masks".to_string(),
                },
                if self.depth {
                    " with depth (RGB-D)"
                } else {
                    ""
                },
                if self.occlusion > 0.0 {
                    format!(", {:.0} % of the forearm hidden", 100.0 * self.occlusion)
                } else {
                    String::new()
                },
                self.latency_s * 1e3
            ),
        };
        if let Some(at_s) = self.camera_fails_at_s {
            format!("{base}, failing at {at_s} s")
        } else {
            base
        }
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
}

#[cfg(test)]
mod tests {
    use super::ground_truth::FORESIGHT_INSTANTS;
    use super::noisy::gaussian;
    use super::*;

    /// The oracle's look ahead is where the simulated human truly is later: its last
    /// instant, taken in the default cell's first fast movement with 0.3 s of foresight,
    /// matches the arm parts of the simulator's human (its kinematic bodies, stepped 300 ms
    /// further) to within a micrometre; the first three parts are the present truth.
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
        };
        oracle.estimate(&input, &mut told);
        let parts = now.parts.len();
        assert_eq!(parts, 3);
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
        let config = PerceptionConfig {
            confidence_sigmas: 2.0,
            ..PerceptionConfig::default()
        };
        let age = 0.2;
        let radius = config.noisy_camera_uncertainty(sphere_radius_for_sigmas(2.0), age)
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
}
