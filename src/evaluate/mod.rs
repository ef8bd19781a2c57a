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

pub mod perception;
pub mod procnet;
pub mod report;

use std::path::{Path, PathBuf};
use std::time::Instant;

use serde::{Deserialize, Serialize};
use workcell_robots::KinematicState;
use workcell_safety::{
    FilterConfig, FilterMode, FilterStatus, HumanEstimate, HumanGeometry, SafetyFilter,
};
use workcell_sim::{CellModel, CellState, RobotCommand, Scenario, step};

use crate::error::{Error, Result};

pub use perception::{
    GroundTruth, HumanPerception, MaskKind, NoisyCamera, PerceptionConfig, PerceptionInput,
    PerceptionKind,
};

/// A robot point slower than this counts as standing, m/s.
const MOVING_M_S: f64 = 0.05;

/// An evaluation file: the cell, the task, perception and the safety filter's settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvaluationConfig {
    /// The cell's scenario file, relative to this file. Default `default.toml`.
    pub cell: String,
    /// Length of the task: the first `task_s` seconds of the robot's nominal motion. Default 12.
    pub task_s: f64,
    /// Plays the cell's human motions at this speed instead of the cell's
    /// `human.speed_scale` (the generated motions peak near 5 m/s at the hand; ISO 13855
    /// assumes 1.6 to 2.0 m/s). Default: the cell's.
    pub human_speed_scale: Option<f64>,
    /// An episode ends unfinished after `timeout_factor * task_s`. Default 3.
    pub timeout_factor: f64,
    /// Control period, s (a multiple of the cell's time step). Default 0.004.
    pub control_period_s: f64,
    /// Gain of the nominal controller's position feedback, 1/s. Default 5.
    pub tracking_gain_per_s: f64,
    /// The task pauses while the tracking error exceeds this, rad. Default 0.05.
    pub progress_tolerance_rad: f64,
    /// "Near the human" for the peak speed metric: true separation below this, m. Default 0.3.
    pub near_m: f64,
    pub perception: PerceptionConfig,
    pub safety: FilterConfig,
}

impl Default for EvaluationConfig {
    fn default() -> Self {
        Self {
            cell: "default.toml".into(),
            task_s: 12.0,
            human_speed_scale: None,
            timeout_factor: 3.0,
            control_period_s: 0.004,
            tracking_gain_per_s: 5.0,
            progress_tolerance_rad: 0.05,
            near_m: 0.3,
            perception: PerceptionConfig::default(),
            safety: FilterConfig::default(),
        }
    }
}

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
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut config: EvaluationConfig = toml::from_str(&text).map_err(|e| Error::Parse {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        // Paths inside the file are relative to the file.
        let dir = path.parent().unwrap_or(Path::new("."));
        let scenario_path = dir.join(&config.cell);
        if config.perception.weights.is_relative() {
            config.perception.weights = dir.join(&config.perception.weights);
        }
        let mut scenario = Scenario::from_file(&scenario_path)?;
        if let Some(speed) = config.human_speed_scale {
            scenario.human.speed_scale = speed;
            scenario
                .validate(&scenario_path)
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
        positive("tracking_gain_per_s", c.tracking_gain_per_s)?;
        positive("progress_tolerance_rad", c.progress_tolerance_rad)?;
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

/// What happened in one episode.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EpisodeMetrics {
    pub episode: usize,
    pub seed: u64,
    pub filter: String,
    /// Smallest true separation (exact robot shapes against the true human), m.
    pub min_separation_m: f64,
    /// Where the minimum happened: `robot link / human part at t s`.
    pub closest: String,
    /// Time spent below d_min, s.
    pub violation_s: f64,
    /// Number of times the separation dropped below d_min.
    pub violations: usize,
    /// Time below d_min while the robot's closest point moved faster than 0.05 m/s, s (what
    /// SSM forbids; a human touching a standing robot is not counted here).
    pub violation_moving_s: f64,
    /// Time to finish the task, s (`None`: not finished before the timeout).
    pub task_time_s: Option<f64>,
    /// The unfiltered robot's task time (the nominal motion), s.
    pub nominal_task_s: f64,
    /// Fastest robot surface point while the true separation was below `near_m`, m/s.
    pub peak_speed_near_human_m_s: f64,
    /// Fastest approach of the robot's closest point toward the human (along the normal)
    /// while the separation was below `near_m`, m/s: the speed a contact would happen at.
    pub peak_approach_speed_m_s: f64,
    /// Fastest end point of any human part, m/s (the human's speed envelope).
    pub peak_human_speed_m_s: f64,
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
    pub perception_error_m: f64,
    pub simulated_s: f64,
    pub wall_s: f64,
}

/// Per-tick samples of one episode, for plots.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EpisodeTrace {
    pub t_s: Vec<f64>,
    pub separation_m: Vec<f64>,
    /// |qdot| / |qdot_nom| (1 when the nominal command is 0).
    pub speed_scale: Vec<f64>,
    /// Mean distance of the estimated parts' end points from the true ones, m (`None` when
    /// perception delivers no human).
    pub perception_error_m: Vec<Option<f64>>,
}

/// One closed-loop episode of `evaluation` with `filter` and the perception of the
/// evaluation file, seeded with `seed` (the cell's seed is replaced by it, so the robot's
/// task and the human's motions differ per episode). `on_tick` gets the fraction done.
///
/// # Errors
/// When the cell cannot be built or the physics refuses a command (a bug: commands are
/// always finite).
pub fn run_episode(
    evaluation: &Evaluation,
    mode: FilterMode,
    episode: usize,
    seed: u64,
    perception: Option<Box<dyn HumanPerception>>,
    mut on_tick: impl FnMut(f64),
) -> Result<(EpisodeMetrics, EpisodeTrace)> {
    let started = Instant::now();
    let c = &evaluation.config;
    let mut scenario = evaluation.scenario.clone();
    scenario.seed = seed;
    let model = CellModel::new(&scenario, &evaluation.scenario_path)?;
    let mut state = CellState::new(&model)?;
    let robot = &model.robot;
    let dof = robot.dof();
    let mut filter = SafetyFilter::new(robot, model.X_WR, mode, c.safety.clone())?;
    let mut human_geometry = HumanGeometry::new(&model.human)?;
    let mut perception = match perception {
        Some(p) => p,
        None => c.perception.build(seed, &scenario, &model)?,
    };

    let dt_physics = model.time_step_s();
    let substeps = (c.control_period_s / dt_physics).round().max(1.0) as usize;
    let dt = substeps as f64 * dt_physics;
    let timeout_s = c.task_s * c.timeout_factor;
    let d_min = c.safety.d_min_m;

    let mut human_kinematics = KinematicState::new(&model.human);
    human_kinematics.X_WB = model.X_WH;
    let mut robot_kinematics = KinematicState::new(robot);
    robot_kinematics.X_WB = model.X_WR;
    let mut truth = HumanEstimate::default();
    let mut estimate = HumanEstimate::default();
    let (mut q_ref, mut qd_ref, mut qdd_ref) = (vec![0.0; dof], vec![0.0; dof], vec![0.0; dof]);
    let mut qdot_nom = vec![0.0; dof];
    let mut q_cmd = state.q().to_vec();
    let mut jacobian = workcell_robots::Jacobian::zeros(dof);

    let mut progress = 0.0_f64;
    let mut metrics = EpisodeMetrics {
        episode,
        seed,
        filter: mode.to_string(),
        min_separation_m: f64::INFINITY,
        closest: String::new(),
        violation_s: 0.0,
        violations: 0,
        violation_moving_s: 0.0,
        task_time_s: None,
        nominal_task_s: c.task_s,
        peak_speed_near_human_m_s: 0.0,
        peak_approach_speed_m_s: 0.0,
        peak_human_speed_m_s: 0.0,
        ticks_pass: 0,
        ticks_modified: 0,
        ticks_relaxed: 0,
        ticks_braking: 0,
        braking_reasons: Vec::new(),
        perception_error_m: 0.0,
        simulated_s: 0.0,
        wall_s: 0.0,
    };
    let mut trace = EpisodeTrace::default();
    let mut below = false;
    // Formatted once at the end: no allocation per tick.
    let mut closest: Option<(workcell_robots::LinkId, workcell_safety::HumanPart, f64)> = None;
    let mut braking: Vec<(workcell_safety::BrakeReason, usize)> = Vec::new();
    let (mut error_sum, mut error_ticks) = (0.0, 0usize);

    loop {
        let t = state.time_s();
        // Ground truth of the human, now.
        model
            .human
            .forward_kinematics(state.human_q(), &mut human_kinematics)?;
        human_geometry.estimate_into(
            &model.human,
            &human_kinematics,
            state.human_qd(),
            &mut truth,
        );
        for p in &truth.parts {
            metrics.peak_human_speed_m_s = metrics
                .peak_human_speed_m_s
                .max(p.v_a_W.length())
                .max(p.v_b_W.length());
        }
        robot.forward_kinematics(state.q(), &mut robot_kinematics)?;

        // True separation and the robot's speed at the closest point.
        if let Some(pair) = filter
            .geometry()
            .min_exact_distance(&robot_kinematics, &truth, 5.0)
        {
            let d = pair.distance_m;
            if d < metrics.min_separation_m {
                metrics.min_separation_m = d;
                closest = Some((pair.link, pair.part, t));
            }
            let mut speed = 0.0;
            if d < c.near_m.max(d_min) {
                robot.point_jacobian(&robot_kinematics, pair.link, pair.p_WA, &mut jacobian);
                let v = jacobian.linear_velocity(state.qd());
                speed = v.length();
                if d < c.near_m {
                    metrics.peak_speed_near_human_m_s =
                        metrics.peak_speed_near_human_m_s.max(speed);
                    metrics.peak_approach_speed_m_s =
                        metrics.peak_approach_speed_m_s.max(-pair.nhat_BA_W.dot(v));
                }
            }
            if d < d_min {
                if !below {
                    metrics.violations += 1;
                }
                below = true;
                metrics.violation_s += dt;
                if speed > MOVING_M_S {
                    metrics.violation_moving_s += dt;
                }
            } else {
                below = false;
            }
            trace.separation_m.push(d);
        } else {
            trace.separation_m.push(f64::NAN);
        }

        if progress >= c.task_s || t >= timeout_s {
            if progress >= c.task_s {
                metrics.task_time_s = Some(t);
            }
            break;
        }

        // Nominal controller: track the task trajectory at the progress variable, which
        // advances only as fast as the robot keeps up.
        model
            .robot_motion
            .sample(progress, &mut q_ref, &mut qd_ref, &mut qdd_ref);
        let error = q_ref
            .iter()
            .zip(&q_cmd)
            .map(|(r, q)| (r - q).abs())
            .fold(0.0, f64::max);
        let rate = (1.0 - error / c.progress_tolerance_rad).clamp(0.0, 1.0);
        for j in 0..dof {
            qdot_nom[j] = rate * qd_ref[j] + c.tracking_gain_per_s * (q_ref[j] - q_cmd[j]);
        }

        perception.estimate(
            &PerceptionInput {
                t_s: t,
                model: &model,
                state: &state,
                truth: &truth,
            },
            &mut estimate,
        );
        let mut tick_error = None;
        if estimate.parts.len() == truth.parts.len() && !estimate.parts.is_empty() {
            let e: f64 = estimate
                .parts
                .iter()
                .zip(&truth.parts)
                .map(|(e, t)| {
                    0.5 * ((e.capsule.a_W - t.capsule.a_W).length()
                        + (e.capsule.b_W - t.capsule.b_W).length())
                })
                .sum::<f64>()
                / truth.parts.len() as f64;
            error_sum += e;
            error_ticks += 1;
            tick_error = Some(e);
        }

        let out = filter.tick(robot, state.q(), &qdot_nom, &estimate, dt);
        tracing::trace!(
            episode,
            t,
            status = %out.status.label(),
            seen_m = out.min_distance_m,
            true_m = trace.separation_m.last().copied().unwrap_or(f64::NAN),
            uncertainty_m = estimate.uncertainty_m,
            pairs = out.active_pairs,
            "tick"
        );
        match out.status {
            FilterStatus::Pass => metrics.ticks_pass += 1,
            FilterStatus::Modified => metrics.ticks_modified += 1,
            FilterStatus::Relaxed => metrics.ticks_relaxed += 1,
            FilterStatus::Braking(reason) => {
                metrics.ticks_braking += 1;
                match braking.iter_mut().find(|(r, _)| *r == reason) {
                    Some((_, n)) => *n += 1,
                    None => braking.push((reason, 1)),
                }
            }
        }
        let nominal_norm = qdot_nom.iter().map(|v| v * v).sum::<f64>().sqrt();
        let command_norm = filter.command().iter().map(|v| v * v).sum::<f64>().sqrt();
        trace.t_s.push(t);
        trace.perception_error_m.push(tick_error);
        trace.speed_scale.push(if nominal_norm > 1e-6 {
            (command_norm / nominal_norm).min(2.0)
        } else {
            1.0
        });

        // The robot is position-controlled with velocity feed-forward, as industrial arms
        // are: the filtered velocity is integrated into the joint position command.
        for _ in 0..substeps {
            for (qc, v) in q_cmd.iter_mut().zip(filter.command()) {
                *qc += v * dt_physics;
            }
            step(
                &model,
                &mut state,
                &RobotCommand::Position {
                    q: &q_cmd,
                    qd: filter.command(),
                },
            )?;
        }
        progress = (progress + rate * dt).min(c.task_s);
        on_tick((t / c.task_s).min(1.0));
    }
    trace.separation_m.truncate(trace.t_s.len());
    if let Some((link, part, t)) = closest {
        metrics.closest = format!("{} / {part} at {t:.2} s", robot.links()[link].name);
    }
    metrics.braking_reasons = braking
        .into_iter()
        .map(|(r, n)| (r.to_string(), n))
        .collect();
    metrics.perception_error_m = if error_ticks > 0 {
        error_sum / error_ticks as f64
    } else {
        f64::NAN
    };
    metrics.simulated_s = state.time_s();
    metrics.wall_s = started.elapsed().as_secs_f64();
    Ok((metrics, trace))
}
