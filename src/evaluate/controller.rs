//! The task controller: the robot's nominal command before the safety filter, the
//! `[controller]` table of an evaluation file. It tracks the task's trajectory at a
//! progress variable that advances only as fast as the robot keeps up, re-times the task
//! faster than planned while no human part is near (catch-up), and stops pulling toward its
//! path when the human has held it off for a while (yield). The filter then bounds whatever
//! it asks for.
//!
//! The defaults are the evaluated controller (`configs/evaluate.toml`, docs/safety.md): a
//! library user who builds `ControllerConfig::default()` gets the behaviour whose figures
//! the docs report.

use serde::{Deserialize, Serialize};
use workcell_safety::{FilterConfig, FilterOutput, FilterStatus, PairConstraint};
use workcell_sim::trajectory::JointTrajectory;

use crate::error::{Error, Result};

/// How fast the task's re-timed speed may rise, 1/s (it falls at once).
const CATCH_UP_RAMP_PER_S2: f64 = 1.0;

/// A yielding robot backs away at most at this fraction of its joints' velocity limits.
const RETREAT_SPEED: f64 = 0.5;

/// What a robot does while it yields to the human (`yield_after_s`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum YieldMotion {
    /// Stands where it is (its nominal command is zero; the filter still moves it out of
    /// the human's way), and resumes as soon as the seen distance is above
    /// `yield_resume_m` or its pull toward the path is one every human pair row allows.
    #[default]
    Hold,
    /// Backs away: the joint direction that moves the seen pairs' robot points out along
    /// their normals (the closest weighted most), at up to half the joints' speed limits,
    /// until the seen distance is above `yield_resume_m`. Over 1,000 seeds (0.1 s, 0.2 m,
    /// beside an earlier re-timing) it left 2 episodes below d_min instead of 6, but 10
    /// went beyond a body region's transient contact speed on the way back to the path
    /// (the hand approached at up to 1.93 m/s against 1.35; experiments/safety.md).
    Retreat,
}

/// Settings of the task controller (the `[controller]` table of an evaluation file).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControllerConfig {
    /// Gain of the joint position error added to the nominal velocity, 1/s.
    pub tracking_gain_per_s: f64,
    /// The task pauses while the tracking error exceeds this, rad.
    pub progress_tolerance_rad: f64,
    /// How far the position command may run ahead of the servos' reference, rad
    /// (anti-windup). The controller integrates the filtered velocity into the position
    /// command; when the servo's acceleration limit holds its reference back (a sudden
    /// evasion), an unbounded command runs ahead, and the servo later catches up at up to
    /// `sqrt(2 a e)` beyond any velocity the filter commanded. 0.002: in free motion the
    /// reference trails the command by under 1 mrad, and a 2 mrad lead is caught up at 0.2
    /// rad/s at most (10 rad/s^2). `inf` turns the bound off.
    pub command_lead_rad: f64,
    /// Re-timing: while the task is behind its schedule (progress below the time elapsed)
    /// and no human part is near, the task may run up to this many times its planned
    /// speed, winning back time the filter cost; 1 keeps the plan's speed; at most 3. The
    /// joints' velocity limits, the filter's rows and power and force limiting still bound
    /// every command; the speed drops back to 1 on the tick a part comes near.
    pub catch_up_speed: f64,
    /// "No human part is near" for catch-up: every part the filter sees is farther than
    /// `d_min` plus this (on the inflated estimate, m) and the filter relaxed none of its
    /// rows; `inf`: only while no part is within the filter's detection distance. 0.3 (0.4 m
    /// at the default `d_min` of 0.1 m) with `catch_up_speed = 1.75`: over 100 seeds the task
    /// time falls from 1.169 to 1.100 of unfiltered with yielding on (experiments/safety.md,
    /// "Throughput"). A margin beyond `d_min`, so that no `d_min` makes it catch up inside it.
    pub catch_up_margin_m: f64,
    /// Yielding: when the task has been held off its path near the human (tracking rate
    /// below half, a human part within the filter's detection distance) for this long, s,
    /// the robot stops pulling toward its path; `inf` never. Pulling presses the arm against
    /// the barrier, where it slides along the inflated estimate into corners between the
    /// human and the furniture, and a hand that then comes on even at 0.5 m/s cannot be
    /// escaped (experiments/safety.md, "Where the last four come from"). 0.5 beside
    /// `catch_up_margin_m = 0.3`: 1 of 1,000 episodes below d_min, task time 1.102.
    pub yield_after_s: f64,
    /// The robot resumes its task once the filter's seen distance is above this, m.
    pub yield_resume_m: f64,
    /// What a yielding robot does.
    pub yield_motion: YieldMotion,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            tracking_gain_per_s: 5.0,
            progress_tolerance_rad: 0.05,
            command_lead_rad: 0.002,
            catch_up_speed: 1.75,
            catch_up_margin_m: 0.3,
            yield_after_s: 0.5,
            yield_resume_m: 0.3,
            yield_motion: YieldMotion::Hold,
        }
    }
}

impl ControllerConfig {
    /// The controller that only follows its plan: no catch-up, no yielding (the
    /// controller of the evaluations before re-timing and yielding were measured).
    #[must_use]
    pub fn plan_only() -> Self {
        Self {
            catch_up_speed: 1.0,
            catch_up_margin_m: f64::INFINITY,
            yield_after_s: f64::INFINITY,
            ..Self::default()
        }
    }

    /// Checks ranges; the error names the key.
    ///
    /// # Errors
    /// [`Error::Config`] with the key `controller.<key>`.
    pub fn validate(&self) -> Result<()> {
        let key = |k: &str| format!("controller.{k}");
        let positive = |k: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::config(key(k), format!("must be > 0, got {v}")))
            }
        };
        positive("tracking_gain_per_s", self.tracking_gain_per_s)?;
        positive("progress_tolerance_rad", self.progress_tolerance_rad)?;
        if self.command_lead_rad.is_nan() || self.command_lead_rad <= 0.0 {
            return Err(Error::config(
                key("command_lead_rad"),
                format!("must be > 0 (inf: no bound), got {}", self.command_lead_rad),
            ));
        }
        if !(1.0..=3.0).contains(&self.catch_up_speed) {
            return Err(Error::config(
                key("catch_up_speed"),
                format!("must be within 1 (off) and 3, got {}", self.catch_up_speed),
            ));
        }
        if self.catch_up_margin_m.is_nan() || self.catch_up_margin_m <= 0.0 {
            return Err(Error::config(
                key("catch_up_margin_m"),
                format!(
                    "must be > 0 m beyond d_min (inf: only with no part in view), got {}",
                    self.catch_up_margin_m
                ),
            ));
        }
        if self.yield_after_s.is_nan() || self.yield_after_s < 0.0 {
            return Err(Error::config(
                key("yield_after_s"),
                format!("must be >= 0 (inf: off), got {}", self.yield_after_s),
            ));
        }
        positive("yield_resume_m", self.yield_resume_m)
    }
}

/// The task controller of one episode: its configuration and state between ticks.
#[derive(Debug, Clone)]
pub struct TaskController {
    config: ControllerConfig,
    q_ref: Vec<f64>,
    qd_ref: Vec<f64>,
    qdd_ref: Vec<f64>,
    qdot_nom: Vec<f64>,
    /// Where along the task's trajectory the reference is, s of the plan.
    progress: f64,
    /// The task's speed against its plan (1 on plan; up to `catch_up_speed`).
    speed: f64,
    /// The filter saw the human and no part within its detection distance, last tick.
    clear: bool,
    /// Every seen part beyond `d_min + catch_up_margin_m` with no row relaxed, last tick.
    may_catch_up: bool,
    /// Where catch-up stops: `d_min + catch_up_margin_m`, m.
    catch_up_beyond_m: f64,
    /// The filter's seen distance, last tick, m.
    seen_m: f64,
    /// How long the task has been held off its path near the human, s.
    blocked_s: f64,
    yielding: bool,
    /// Each joint's retreat speed, rad/s.
    v_retreat: Vec<f64>,
}

impl TaskController {
    /// A controller at the start of the task for a robot with these joint velocity limits,
    /// beside a filter that keeps `d_min_m`.
    #[must_use]
    pub fn new(config: ControllerConfig, velocity_limits: &[f64], d_min_m: f64) -> Self {
        let dof = velocity_limits.len();
        Self {
            config,
            q_ref: vec![0.0; dof],
            qd_ref: vec![0.0; dof],
            qdd_ref: vec![0.0; dof],
            qdot_nom: vec![0.0; dof],
            progress: 0.0,
            speed: 1.0,
            clear: true,
            may_catch_up: true,
            catch_up_beyond_m: d_min_m + config.catch_up_margin_m,
            seen_m: f64::INFINITY,
            blocked_s: 0.0,
            yielding: false,
            v_retreat: velocity_limits
                .iter()
                .map(|v| if *v > 0.0 { RETREAT_SPEED * v } else { 1.0 })
                .collect(),
        }
    }

    /// Where along the task's trajectory the reference is, s of the plan.
    #[must_use]
    pub fn progress(&self) -> f64 {
        self.progress
    }

    /// The task's speed against its plan (1 on plan).
    #[must_use]
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The nominal joint velocity of the last [`TaskController::nominal`], rad/s.
    #[must_use]
    pub fn command(&self) -> &[f64] {
        &self.qdot_nom
    }

    /// Anti-windup: the position command may lead the servos' reference by at most
    /// `command_lead_rad` per joint. Integrated open-loop, the command ran ahead while the
    /// servo's acceleration limit held the reference back (a sudden evasion), and the servo
    /// then caught up at up to `sqrt(2 a e)` beyond anything the filter commanded: the
    /// forearm and hand limits of power and force limiting were exceeded that way in 5 of
    /// 1,000 episodes (experiments/safety.md, "Peak approach per body region").
    pub fn bound_command_lead(&self, q_cmd: &mut [f64], reference_q: &[f64]) {
        let e_max = self.config.command_lead_rad;
        for (q, r) in q_cmd.iter_mut().zip(reference_q) {
            *q = r + (*q - r).clamp(-e_max, e_max);
        }
    }

    /// The nominal command at `t` (a tick of `dt`): tracks `motion` at the progress
    /// variable, faster than planned while the task is behind schedule and no human part
    /// is near, or the yield motion. `pairs` are the filter's pairs of the last tick and
    /// `safety` its settings. Returns the rate at which progress advances.
    pub fn nominal(
        &mut self,
        t: f64,
        dt: f64,
        motion: &JointTrajectory,
        q_cmd: &[f64],
        pairs: &[PairConstraint],
        safety: &FilterConfig,
    ) -> f64 {
        let c = self.config;
        // The speed ramps up gently (the trajectory's accelerations grow with its square) and
        // drops to the plan's at once when a human part comes into view: ramped down over
        // 75 ms, it let the arm approach the hand at 0.95 m/s instead of 0.72 (100 seeds)
        // and seed 64 (perfect perception) come to 0.092 m.
        let target = if self.may_catch_up && self.progress < t - dt {
            c.catch_up_speed
        } else {
            1.0
        };
        self.speed = if target > self.speed {
            (self.speed + CATCH_UP_RAMP_PER_S2 * dt).min(target)
        } else {
            target
        };
        motion.sample(
            self.progress,
            &mut self.q_ref,
            &mut self.qd_ref,
            &mut self.qdd_ref,
        );
        let error = self
            .q_ref
            .iter()
            .zip(q_cmd)
            .map(|(r, q)| (r - q).abs())
            .fold(0.0, f64::max);
        let tracking = (1.0 - error / c.progress_tolerance_rad).clamp(0.0, 1.0);
        if self.yielding {
            self.yielding = self.seen_m < c.yield_resume_m
                && !(c.yield_motion == YieldMotion::Hold
                    && self.path_is_clear(q_cmd, pairs, safety));
        } else if tracking < 0.5 && !self.clear {
            self.blocked_s += dt;
            self.yielding = self.blocked_s >= c.yield_after_s;
        } else {
            self.blocked_s = 0.0;
        }
        if self.yielding {
            self.blocked_s = 0.0;
            match self.config.yield_motion {
                YieldMotion::Hold => self.qdot_nom.fill(0.0),
                YieldMotion::Retreat => self.retreat(pairs),
            }
            return 0.0;
        }
        let rate = tracking * self.speed;
        let gain = self.config.tracking_gain_per_s;
        for (j, (v, q)) in self.qdot_nom.iter_mut().zip(q_cmd).enumerate() {
            *v = rate * self.qd_ref[j] + gain * (self.q_ref[j] - q);
        }
        rate
    }

    /// What the filter made of the last command: whether the human was seen clear of the
    /// robot, how far, and whether catch-up may go on.
    pub fn observe(&mut self, out: &FilterOutput) {
        // Clear: the filter saw the human (no brake for a missing estimate) and no part near.
        self.clear = out.active_pairs == 0 && out.status == FilterStatus::Pass;
        self.seen_m = out.min_distance_m;
        self.may_catch_up = self.clear
            || (out.min_distance_m > self.catch_up_beyond_m
                && matches!(out.status, FilterStatus::Pass | FilterStatus::Modified));
    }

    /// Advances the progress variable by `rate` over `dt`, up to `task_s`.
    pub fn advance(&mut self, rate: f64, dt: f64, task_s: f64) {
        self.progress = (self.progress + rate * dt).min(task_s);
    }

    /// Whether the task's pull toward its path at the plan's speed (the command it would
    /// resume with) is one that every human pair row of the last tick allows. Writes that
    /// pull into the nominal command, which the caller then sets.
    fn path_is_clear(&mut self, q_cmd: &[f64], pairs: &[PairConstraint], s: &FilterConfig) -> bool {
        let gain = self.config.tracking_gain_per_s;
        for (j, v) in self.qdot_nom.iter_mut().enumerate() {
            *v = self.qd_ref[j] + gain * (self.q_ref[j] - q_cmd[j]);
        }
        pairs.iter().filter(|p| !p.obstacle).all(|p| {
            p.approach_m_s(&self.qdot_nom) <= p.approach_bound_m_s(s.gamma_per_s, s.d_min_m)
        })
    }

    /// A yielding robot's nominal command: away from the human, the joint direction that
    /// moves the seen pairs' robot points out along their normals (the closest pairs
    /// weighted most), scaled to the largest step that keeps every joint within its retreat
    /// speed (zero when no pair is in view).
    fn retreat(&mut self, pairs: &[PairConstraint]) {
        self.qdot_nom.fill(0.0);
        for p in pairs.iter().filter(|p| !p.obstacle) {
            let w = 1.0 / (p.pair.distance_m.max(0.0) + 0.05);
            for (v, a) in self.qdot_nom.iter_mut().zip(&p.normal_jacobian) {
                *v += w * a;
            }
        }
        let scale = self
            .qdot_nom
            .iter()
            .zip(&self.v_retreat)
            .filter(|(g, _)| g.abs() > 1e-12)
            .map(|(g, v)| v / g.abs())
            .fold(f64::INFINITY, f64::min);
        let scale = if scale.is_finite() { scale } else { 0.0 };
        for g in &mut self.qdot_nom {
            *g *= scale;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The library's default is the controller `configs/evaluate.toml` was measured with (the
    /// file writes it out), and `plan_only` turns re-timing and yielding off.
    #[test]
    fn the_default_is_the_evaluated_controller() {
        let text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/evaluate.toml"),
        )
        .expect("configs/evaluate.toml");
        let file: toml::Table = toml::from_str(&text).expect("toml");
        let written: ControllerConfig = file["controller"].clone().try_into().expect("table");
        assert_eq!(written, ControllerConfig::default());
        assert!(ControllerConfig::default().validate().is_ok());
        let plan = ControllerConfig::plan_only();
        assert!(plan.validate().is_ok());
        assert_eq!(
            (
                plan.catch_up_speed,
                plan.catch_up_margin_m,
                plan.yield_after_s
            ),
            (1.0, f64::INFINITY, f64::INFINITY)
        );
        let bad = ControllerConfig {
            catch_up_margin_m: -0.1,
            ..ControllerConfig::default()
        };
        let err = bad.validate().expect_err("a negative margin");
        assert!(
            err.to_string().contains("controller.catch_up_margin_m"),
            "{err}"
        );
    }
}
