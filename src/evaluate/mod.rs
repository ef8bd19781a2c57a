//! Closed-loop safety evaluation: the robot does its task in the simulated cell while the
//! human moves; perception tells the safety filter where the human is; the true separation
//! is measured every control tick from ground truth.
//!
//! ```text
//! every control tick (control_period_s):
//!     nominal controller (tracks the task trajectory, time-scaled by progress) -> qdot_nom
//!     perception (ground truth, or a noisy camera)                           -> human estimate
//!     safety filter (none | qp | ssm)                                        -> qdot
//!     physics steps at the cell's time step: qdot integrated into the joint position
//!     command of the robot's servos (position control with velocity feed-forward)
//!     true separation: exact robot link shapes against the true human capsules
//! ```

mod controller;
mod episode;
pub mod html;
pub mod lossless;
pub mod other_arm;
pub mod perception;
pub mod record;
pub mod replay;
pub mod report;
mod tally;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use workcell_robots::input::{MAX_CONFIG_BYTES, read_text_file};
use workcell_safety::{FilterConfig, HumanPart};
use workcell_sim::Scenario;

use crate::error::{Error, Result};

pub use controller::{ControllerConfig, TaskController, YieldMotion};
pub use episode::{Recording, record_episode, run_episode};
pub use perception::procnet;
pub use perception::{
    Foresight, GroundTruth, GroundTruthConfig, HumanPerception, MaskKind, NoisyCamera, NoisyConfig,
    PerceptionConfig, PerceptionInput, PerceptionKind, ProcNetConfig,
};

/// An evaluation file: the cell, the task, perception and the safety filter's settings.
/// The shortest task an evaluation runs, s: 25 ticks of the default 4 ms control period.
pub const MIN_TASK_S: f64 = 0.1;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvaluationConfig {
    /// The cell's scenario file, relative to this file. Default `default.toml`.
    pub cell: String,
    /// Length of the task: the first `task_s` seconds of the robot's nominal motion, from
    /// [`MIN_TASK_S`] to 3,600. Default 12.
    pub task_s: f64,
    /// Plays the cell's human motions at this speed instead of the cell's
    /// `human.speed_scale` (the generated motions peak at `human.peak_speed_m_s`; ISO 13855
    /// assumes 1.6 to 2.0 m/s). Default: the cell's.
    pub human_speed_scale: Option<f64>,
    /// The generator's calibration instead of the cell's `human.speeds`: `iso13855` (peaks
    /// up to 2.0 m/s) or `recorded` (up to the recorded people's). Default: the cell's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub human_speeds: Option<workcell_sim::scenario::HumanSpeeds>,
    /// The human model instead of the cell's `human.model` (a catalogue name such as `human`
    /// or `human_arm`, an added robot, or a URDF path relative to this file). Default: the
    /// cell's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub human_model: Option<String>,
    /// Recorded clips move the cell's human instead of its generator: the cell's
    /// `[human.recorded]` (`workcell_sim::scenario::RecordedConfig`), its `library` relative to
    /// this file. Episode `i` (seed `s`) plays clip `(s - 1) mod n`. Left out: the cell's own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub human_recorded: Option<workcell_sim::scenario::RecordedConfig>,
    /// The left arm (the two-armed human's own, or beside a one-armed model a recorded
    /// clip's other arm: [`other_arm`]) is seen by the perceptions that see the whole
    /// person: ground truth, its foresight and the noisy camera report it with the other
    /// parts, and the filter keeps it beyond `d_min` as it does them. ProcNet's fit follows
    /// the right arm and does not see it. `false`: it is only measured, as a one-armed view
    /// of the person leaves it. Either way an episode where it comes below `d_min` is a
    /// violation. Default true.
    pub other_arm_seen: bool,
    /// An episode ends unfinished after `timeout_factor * task_s`. Default 3.
    pub timeout_factor: f64,
    /// Control period, s (a multiple of the cell's time step). Default 0.004.
    pub control_period_s: f64,
    /// The task controller: its tracking, re-timing (catch-up) and yielding (the
    /// `[controller]` table; [`ControllerConfig`]).
    pub controller: ControllerConfig,
    /// "Near the human" for the peak speed metric: true separation below this, m. Default 0.3.
    pub near_m: f64,
    /// The `[perception]` table; its `kind` chooses the keys ([`PerceptionConfig`]).
    pub perception: PerceptionConfig,
    pub safety: FilterConfig,
}

impl EvaluationConfig {
    /// Whether perception reports the left arm ([`Self::other_arm_seen`]): ground truth and
    /// the noisy camera as they see it; ProcNet only where its fit follows it
    /// (`perception.fit_left_arm`, the true pose) or guards its reach
    /// (`perception.guard_unseen_left_arm`), not with its network's right arm alone.
    #[must_use]
    pub fn other_arm_is_seen(&self) -> bool {
        self.other_arm_seen
            && match &self.perception {
                PerceptionConfig::Procnet(c) => {
                    c.masks == perception::MaskKind::TruePose
                        || c.fit_left_arm
                        || c.guard_unseen_left_arm
                }
                _ => true,
            }
    }
}

impl Default for EvaluationConfig {
    fn default() -> Self {
        Self {
            cell: "default.toml".into(),
            task_s: 12.0,
            human_speed_scale: None,
            human_speeds: None,
            human_model: None,
            human_recorded: None,
            other_arm_seen: true,
            timeout_factor: 3.0,
            control_period_s: 0.004,
            controller: ControllerConfig::default(),
            near_m: 0.3,
            perception: PerceptionConfig::default(),
            safety: FilterConfig::default(),
        }
    }
}

/// The keys that moved from the top of an evaluation file into `[controller]`, with their
/// names there (`catch_up_beyond_m`, a distance, became a margin beyond `d_min`).
const MOVED_TO_CONTROLLER: [(&str, &str); 8] = [
    ("tracking_gain_per_s", "tracking_gain_per_s"),
    ("progress_tolerance_rad", "progress_tolerance_rad"),
    ("command_lead_rad", "command_lead_rad"),
    ("catch_up_speed", "catch_up_speed"),
    (
        "catch_up_beyond_m",
        "catch_up_margin_m (beyond safety.d_min_m)",
    ),
    ("yield_after_s", "yield_after_s"),
    ("yield_resume_m", "yield_resume_m"),
    ("yield_motion", "yield_motion"),
];

/// An evaluation file with its cell loaded.
#[derive(Debug, Clone)]
pub struct Evaluation {
    pub path: PathBuf,
    pub config: EvaluationConfig,
    pub scenario: Scenario,
    pub scenario_path: PathBuf,
}

impl Evaluation {
    /// Reads and checks an evaluation file and its cell.
    ///
    /// # Errors
    /// A message naming the file and the key for unreadable files, unknown keys, values out
    /// of range, and a `d_min_m` that no cell could keep (larger than the distance between
    /// the robot's and the human's bases plus their reach).
    pub fn from_file(path: &Path) -> Result<Self> {
        let text = read_text_file(path, MAX_CONFIG_BYTES).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml(&text, path)
    }

    /// Like [`Evaluation::from_file`], with `KEY=VALUE` overrides applied to the file's
    /// text first (see [`apply_overrides`]).
    ///
    /// # Errors
    /// As [`Evaluation::from_file`], and for an override that is not `KEY=VALUE` or names a
    /// key inside a value that is not a table.
    pub fn from_file_with(path: &Path, overrides: &[String]) -> Result<Self> {
        let text = read_text_file(path, MAX_CONFIG_BYTES).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml(&apply_overrides(&text, overrides, path)?, path)
    }

    /// Like [`Evaluation::from_file_with`], with the file's `[perception]` made one of
    /// `kind` first when given (a command line's `--perception`): the keys `kind` also takes
    /// are kept, the others dropped ([`perception::switch_perception_kind`]) and returned,
    /// for a note. The overrides apply after the switch, so they may set the new kind's keys.
    ///
    /// # Errors
    /// As [`Evaluation::from_file_with`].
    pub fn from_file_as(
        path: &Path,
        kind: Option<PerceptionKind>,
        overrides: &[String],
    ) -> Result<(Self, Vec<String>)> {
        let mut text = read_text_file(path, MAX_CONFIG_BYTES).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut dropped = Vec::new();
        if let Some(kind) = kind {
            let parse_error = |message: String| Error::Parse {
                path: path.to_path_buf(),
                message,
            };
            let mut document: toml::Table =
                toml::from_str(&text).map_err(|e| parse_error(e.to_string()))?;
            dropped = perception::switch_perception_kind(&mut document, kind);
            text = toml::to_string(&document).map_err(|e| parse_error(e.to_string()))?;
        }
        let this = Self::from_toml(&apply_overrides(&text, overrides, path)?, path)?;
        Ok((this, dropped))
    }

    /// Like [`Evaluation::from_file`] on text already read; `path` names it in errors and
    /// anchors the cell's and the weights' paths.
    ///
    /// # Errors
    /// As [`Evaluation::from_file`], without the I/O of the file itself.
    pub fn from_toml(text: &str, path: &Path) -> Result<Self> {
        let mut config: EvaluationConfig = toml::from_str(text).map_err(|e| {
            let mut message = e.to_string();
            if let Some((old, new)) = MOVED_TO_CONTROLLER
                .iter()
                .find(|(old, _)| message.contains(&format!("unknown field `{old}`")))
            {
                message = format!(
                    "{old} is a key of the [controller] table now (controller.{new}); {message}"
                );
            }
            Error::Parse {
                path: path.to_path_buf(),
                message,
            }
        })?;
        // Paths inside the file are relative to the file.
        let dir = path.parent().unwrap_or(Path::new("."));
        let scenario_path = dir.join(&config.cell);
        if let PerceptionConfig::Procnet(p) = &mut config.perception
            && let Some(weights) = &mut p.weights
            && weights.is_relative()
        {
            *weights = dir.join(&*weights);
        }
        let mut scenario = Scenario::from_file(&scenario_path)?;
        if let Some(model) = &config.human_model {
            scenario.set_human_model(model, path);
        }
        // No weights named: the shipped network for this camera and this human.
        if let PerceptionConfig::Procnet(p) = &mut config.perception
            && p.weights.is_none()
        {
            p.weights = Some(crate::procnet::weights::shipped_path_for(
                p.depth,
                &scenario.human.model,
            ));
            if p.masks == MaskKind::Network
                && let Some(warning) =
                    crate::procnet::weights::shipped_for_warning(p.depth, &scenario.human.model)
            {
                tracing::warn!("perception: {warning}");
            }
        }
        if let Some(recorded) = &mut config.human_recorded {
            // Relative to this file, wherever the cell's file is.
            if recorded.library.is_relative() {
                recorded.library = std::path::absolute(dir.join(&recorded.library))
                    .unwrap_or_else(|_| dir.join(&recorded.library));
            }
            scenario.human.recorded = Some(recorded.clone());
            scenario
                .validate()
                .map_err(|e| Error::config("human_recorded", e.to_string()).in_file(path))?;
            // The library and the clips it names, checked now rather than at the first
            // episode.
            let library =
                workcell_mocap::library::Library::from_file(&recorded.library).map_err(|e| {
                    Error::config("human_recorded.library", e.to_string()).in_file(path)
                })?;
            if let Some(missing) = recorded
                .clips
                .iter()
                .find(|id| library.clips.iter().all(|c| &c.id != *id))
            {
                return Err(Error::config(
                    "human_recorded.clips",
                    format!(
                        "{missing:?} is not a clip of {}",
                        recorded.library.display()
                    ),
                )
                .in_file(path));
            }
        }
        if let Some(speeds) = config.human_speeds {
            scenario.human.speeds = speeds;
        }
        if let Some(speed) = config.human_speed_scale {
            scenario.human.speed_scale = speed;
            scenario
                .validate()
                .map_err(|e| Error::config("human_speed_scale", e.to_string()).in_file(path))?;
        }
        let this = Self {
            path: path.to_path_buf(),
            config,
            scenario,
            scenario_path,
        };
        this.validate().map_err(|e| e.in_file(path))?;
        Ok(this)
    }

    /// Checks ranges; the error names the key.
    ///
    /// # Errors
    /// [`Error::Config`] naming the first value out of range.
    pub fn validate(&self) -> Result<()> {
        let c = &self.config;
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::config(
                    key,
                    format!("must be finite and > 0, got {v}"),
                ))
            }
        };
        positive("task_s", c.task_s)?;
        positive("control_period_s", c.control_period_s)?;
        // Lower bound: a task of a few ticks has no motion to evaluate, and its ratios are
        // noise (1e-300 printed a 300-digit task-time ratio).
        if c.task_s < MIN_TASK_S {
            return Err(Error::config(
                "task_s",
                format!("{:?} is below the limit of {MIN_TASK_S} s", c.task_s),
            ));
        }
        // Upper bounds: an episode of more than an hour, or a controller slower than 10 Hz,
        // is no evaluation of a collaborative cell (and 1e6 s hung the run).
        for (key, v, most) in [
            ("task_s", c.task_s, 3600.0),
            ("control_period_s", c.control_period_s, 0.1),
            ("timeout_factor", c.timeout_factor, 100.0),
        ] {
            if v > most {
                return Err(Error::config(
                    key,
                    format!("{v} is above the limit of {most}"),
                ));
            }
        }
        c.controller.validate()?;
        positive("near_m", c.near_m)?;
        if !(c.timeout_factor.is_finite() && c.timeout_factor >= 1.0) {
            return Err(Error::config(
                "timeout_factor",
                format!("must be >= 1, got {}", c.timeout_factor),
            ));
        }
        let dt = self.scenario.time_step_s;
        let ratio = c.control_period_s / dt;
        if (ratio - ratio.round()).abs() > 1e-6 || ratio.round() < 1.0 {
            return Err(Error::config(
                "control_period_s",
                format!(
                    "{} is not a multiple of the cell's time step {dt}",
                    c.control_period_s
                ),
            ));
        }
        c.perception.validate()?;
        c.safety
            .validate()
            .map_err(|e| Error::config("safety", e.to_string()))?;
        // The robot's base and the human's shoulder are this far apart; a d_min beyond it plus
        // both reaches (2 m each, generous) can never be kept.
        let b_r = self.scenario.robot.base.xyz;
        let b_h = self.scenario.human.base.xyz;
        let bases =
            ((b_r[0] - b_h[0]).powi(2) + (b_r[1] - b_h[1]).powi(2) + (b_r[2] - b_h[2]).powi(2))
                .sqrt();
        if c.safety.d_min_m > bases + 4.0 {
            return Err(Error::config(
                "safety.d_min_m",
                format!(
                    "{} m is larger than the whole cell (bases {bases:.2} m apart): no motion \
                     could keep it",
                    c.safety.d_min_m
                ),
            ));
        }
        Ok(())
    }
}

/// Sets dotted keys of a TOML document: `safety.gamma_per_s=8` sets `gamma_per_s` in the
/// `[safety]` table (created when missing). A value is parsed as TOML (`8`, `true`,
/// `[1.0, 2.0]`, `"text"`); one that does not parse is taken as a string. The result is
/// checked as the file itself would be: an unknown key is refused there.
///
/// # Errors
/// [`Error::Parse`] when the text is not TOML; [`Error::Config`] naming the override when it
/// has no `=`, an empty key part, or walks into a value that is not a table.
pub fn apply_overrides(text: &str, overrides: &[String], path: &Path) -> Result<String> {
    if overrides.is_empty() {
        return Ok(text.to_string());
    }
    let mut document: toml::Table = toml::from_str(text).map_err(|e| Error::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    for item in overrides {
        let bad = |message: &str| Error::config(item.clone(), message.to_string()).in_file(path);
        let Some((key, value)) = item.split_once('=') else {
            return Err(bad("an override is KEY=VALUE, e.g. safety.gamma_per_s=8"));
        };
        let parts: Vec<&str> = key.trim().split('.').map(str::trim).collect();
        if parts.iter().any(|p| p.is_empty()) {
            return Err(bad("empty key"));
        }
        let value = value.trim();
        let value = match toml::from_str::<toml::Table>(&format!("v = {value}")) {
            Ok(mut t) => t.remove("v").unwrap_or_else(|| value.into()),
            Err(_) => toml::Value::String(value.to_string()),
        };
        let (last, tables) = parts.split_last().ok_or_else(|| bad("empty key"))?;
        let mut table = &mut document;
        for name in tables {
            let entry = table
                .entry((*name).to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            table = entry
                .as_table_mut()
                .ok_or_else(|| bad(&format!("'{name}' is not a table")))?;
        }
        table.insert((*last).to_string(), value);
    }
    toml::to_string(&document).map_err(|e| Error::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// The parts whose approach speeds an evaluation reports, in the order of
/// [`EpisodeMetrics::peak_approach_by_part_m_s`] and of `metrics.csv`'s columns: the parts
/// the safety filter guards (`HumanGeometry`), the arm's first (the order of earlier
/// reports), then the head where the human model has one.
pub const PFL_PARTS: [HumanPart; 4] = [
    HumanPart::UpperArm,
    HumanPart::Forearm,
    HumanPart::Hand,
    HumanPart::Head,
];

/// Per-part perception errors before any tick: none
/// ([`EpisodeMetrics::perception_error_by_part_m`]).
#[must_use]
pub fn no_part_errors() -> Vec<f64> {
    vec![f64::NAN; HumanPart::ALL.len()]
}

/// A distance not measured (files from before [`EpisodeMetrics::fit_error_m`]).
#[must_use]
pub fn no_error() -> f64 {
    f64::NAN
}

/// What happened in one episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeMetrics {
    pub episode: usize,
    pub seed: u64,
    pub filter: String,
    /// Smallest true separation (exact robot shapes against the true human), m.
    #[serde(with = "lossless::f64")]
    pub min_separation_m: f64,
    /// Where the minimum happened: `robot link / human part at t s`.
    pub closest: String,
    /// Time spent below d_min, s.
    #[serde(with = "lossless::f64")]
    pub violation_s: f64,
    /// Number of times the separation dropped below d_min.
    pub violations: usize,
    /// Time below d_min while the robot's closest point moved faster than 0.05 m/s, s (what
    /// SSM forbids; a human touching a standing robot is not counted here).
    #[serde(with = "lossless::f64")]
    pub violation_moving_s: f64,
    /// Time to finish the task, s (`None`: not finished before the timeout).
    pub task_time_s: Option<f64>,
    /// The unfiltered robot's task time (the nominal motion), s.
    #[serde(with = "lossless::f64")]
    pub nominal_task_s: f64,
    /// Fastest robot surface point while the true separation was below `near_m`, m/s.
    #[serde(with = "lossless::f64")]
    pub peak_speed_near_human_m_s: f64,
    /// Fastest approach of the robot's closest point toward the human (along the normal)
    /// while the separation was below `near_m`, m/s: the speed a contact would happen at.
    #[serde(with = "lossless::f64")]
    pub peak_approach_speed_m_s: f64,
    /// Fastest end point of any human part, m/s (the human's speed envelope).
    #[serde(with = "lossless::f64")]
    pub peak_human_speed_m_s: f64,
    /// Largest acceleration of any human part's end point, m/s^2: the change of its
    /// velocity between control ticks over the tick. A camera that extrapolates a stale
    /// estimate bounds its error by an assumed acceleration (the noisy camera's
    /// `human_acceleration_m_s2`); above it, that bound does not hold.
    #[serde(default, with = "lossless::f64")]
    pub peak_human_acceleration_m_s2: f64,
    /// Per part ([`PFL_PARTS`]: upper arm, forearm, hand, head): the robot's fastest
    /// approach toward it at its closest point while the part's true separation was below
    /// the filter's `pfl_distance_m` (`near_m` when PFL is off), m/s. Compare with the
    /// part's ISO/TS 15066 transient contact speed (0 for the head: no contact permitted).
    pub peak_approach_by_part_m_s: [f64; PFL_PARTS.len()],
    /// Contacts (true separation down to 0) that began with the robot's closest point
    /// moving faster than 0.05 m/s: what speed and separation monitoring forbids.
    pub contacts_moving: usize,
    /// Contacts that began with the robot at standstill (SSM permits these: the human
    /// walked into a stopped robot).
    pub contacts_standing: usize,
    /// Ticks per filter status: pass, modified, braking (all reasons).
    pub ticks_pass: usize,
    pub ticks_modified: usize,
    /// Ticks where no command kept every row and the least violating one was taken.
    pub ticks_relaxed: usize,
    pub ticks_braking: usize,
    /// Braking ticks per reason.
    pub braking_reasons: Vec<(String, usize)>,
    /// Mean distance between estimated and true part end points over ticks with an
    /// estimate, m.
    #[serde(with = "lossless::f64")]
    pub perception_error_m: f64,
    /// The same per part, in [`HumanPart::ALL`]'s order (torso, upper arm, forearm, hand,
    /// head), m: NaN for a part the human model lacks or no tick estimated. Where the mean
    /// goes: a trunk turned wrong shows at the head, an arm fitted wrong at the hand.
    #[serde(default = "no_part_errors", with = "lossless::vec")]
    pub perception_error_by_part_m: Vec<f64>,
    /// Mean distance between the fitted and the true part end points at each fit's
    /// exposure, over the frames with a fit, m: what perception gets wrong before its
    /// estimate ages. The rest of `perception_error_m` is the ageing's (the latency and the
    /// frames since, bridged by the joints' velocity). NaN where perception fits no frames
    /// (the noisy camera, the oracles) or fitted none.
    #[serde(default = "no_error", with = "lossless::f64")]
    pub fit_error_m: f64,
    /// The left arm: the two-armed human's own (its parts are also in `min_separation_m` and
    /// the rest), or, beside a one-armed model, the recorded person's other arm (`other_arm`),
    /// which the rest of the metrics leave out: its smallest separation from the robot, m, by
    /// the same exact shapes as `min_separation_m`. The filter guards it where perception
    /// sees it (`EvaluationConfig::other_arm_seen`). NaN without such an arm (a one-armed
    /// model with the generator's motion or a clip with one arm).
    #[serde(default = "no_error", with = "lossless::f64")]
    pub other_arm_min_separation_m: f64,
    /// Time the left arm spent below d_min, s (0 without one).
    #[serde(default, with = "lossless::f64")]
    pub other_arm_violation_s: f64,
    #[serde(with = "lossless::f64")]
    pub simulated_s: f64,
    /// The episode's wall time, building the cell and the perception included, s.
    #[serde(with = "lossless::f64")]
    pub wall_s: f64,
    /// The part of `wall_s` before the first tick (the cell with its recorded clip
    /// retargeted, the perception with its network loaded), s; 0 in files from before it.
    #[serde(default, with = "lossless::f64")]
    pub setup_s: f64,
}

impl EpisodeMetrics {
    /// Whether the episode came below d_min: the modelled human, or a recorded person's
    /// other arm.
    #[must_use]
    pub fn violated(&self) -> bool {
        self.violations > 0 || self.other_arm_violation_s > 0.0
    }
}

/// Per-tick samples of one episode, for plots.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeTrace {
    #[serde(with = "lossless::vec")]
    pub t_s: Vec<f64>,
    #[serde(with = "lossless::vec")]
    pub separation_m: Vec<f64>,
    /// |qdot| / |qdot_nom| (1 when the nominal command is 0).
    #[serde(with = "lossless::vec")]
    pub speed_scale: Vec<f64>,
    /// The task's speed against its plan (`catch_up_speed`'s re-timing; 1 when on plan).
    #[serde(with = "lossless::vec", default)]
    pub task_speed: Vec<f64>,
    /// The norm of the filtered joint velocity command, rad/s.
    #[serde(with = "lossless::vec", default)]
    pub command_rad_s: Vec<f64>,
    /// Mean distance of the estimated parts' end points from the true ones, m (`None` when
    /// perception delivers no human).
    #[serde(with = "lossless::vec_option")]
    pub perception_error_m: Vec<Option<f64>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `human_model` names a catalogue model as it is, and a URDF relative to the file.
    #[test]
    fn an_evaluations_human_model_is_a_name_or_a_path_beside_the_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cell = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml");
        let path = dir.path().join("eval.toml");
        for (model, expected) in [
            ("human", "human".to_string()),
            (
                "bodies/me.urdf",
                dir.path()
                    .join("bodies/me.urdf")
                    .to_string_lossy()
                    .into_owned(),
            ),
        ] {
            let text = format!("cell = {cell:?}\nhuman_model = {model:?}\n");
            std::fs::write(&path, text).expect("write");
            let evaluation = Evaluation::from_file(&path).expect("evaluation");
            assert_eq!(evaluation.scenario.human.model, expected);
        }
    }

    /// Without weights named, the closed loop reads the shipped network for its camera and
    /// its human: the one trained on the whole body's frames for an RGB-D camera that sees
    /// `human`, the paper's arm's for `human_arm`, the RGB network without depth.
    #[test]
    fn the_default_weights_follow_the_camera_and_the_human() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cell = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml");
        let path = dir.path().join("eval.toml");
        for (model, depth, expected) in [
            ("human", true, "procnet-depth-human.safetensors"),
            ("human_arm", true, "procnet-depth.safetensors"),
            ("human", false, "procnet-cpu.safetensors"),
        ] {
            let text = format!(
                "cell = {cell:?}\nhuman_model = {model:?}\n[perception]\nkind = \"procnet\"\n\
                 depth = {depth}\n"
            );
            std::fs::write(&path, text).expect("write");
            let evaluation = Evaluation::from_file(&path).expect("evaluation");
            let PerceptionConfig::Procnet(p) = &evaluation.config.perception else {
                panic!("procnet perception")
            };
            let weights = p.weights_path();
            assert!(
                weights.ends_with(format!("procnet/weights/{expected}")),
                "{weights:?}"
            );
            assert!(weights.is_file(), "{weights:?}");
        }
    }

    /// Paths inside an evaluation file are relative to the file, wherever it is run from;
    /// an error inside it names the file once and the key once.
    #[test]
    fn paths_in_an_evaluation_file_resolve_against_the_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cell = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml");
        let path = dir.path().join("eval.toml");
        std::fs::write(
            &path,
            format!(
                "cell = {cell:?}\n[perception]\nkind = \"procnet\"\n\
                 weights = \"nets/w.safetensors\"\n"
            ),
        )
        .expect("write");
        let evaluation = Evaluation::from_file(&path).expect("evaluation");
        let PerceptionConfig::Procnet(p) = &evaluation.config.perception else {
            panic!("{:?}", evaluation.config.perception)
        };
        assert_eq!(p.weights, Some(dir.path().join("nets/w.safetensors")));
        assert_eq!(evaluation.scenario_path, std::path::PathBuf::from(cell));

        std::fs::write(&path, format!("cell = {cell:?}\ntask_s = -1.0\n")).expect("write");
        let err = Evaluation::from_file(&path).unwrap_err();
        let chain = format!("{:#}", anyhow::Error::new(err));
        assert_eq!(chain.matches("eval.toml").count(), 1, "{chain}");
        assert!(
            chain.contains("task_s: must be finite and > 0, got -1"),
            "{chain}"
        );
    }
}
