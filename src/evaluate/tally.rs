//! An episode's metrics as they accumulate tick by tick: the true separation and its
//! violations, contacts by the robot's speed, the human's and the robot's peaks, the filter's
//! status counts, the perception error, and the per-tick trace the plots draw. The episode
//! loop tells it what happened; it knows nothing of the cell, the filter or perception.

use std::time::Instant;

use workcell_robots::LinkId;
use workcell_robots::math::Vector;
use workcell_safety::{BrakeReason, FilterStatus, HumanEstimate, HumanPart, SignedDistancePair};

use super::{EpisodeMetrics, EpisodeTrace};

/// A robot point slower than this counts as standing, m/s.
pub const MOVING_M_S: f64 = 0.05;

/// The running metrics and trace of one episode.
#[derive(Debug, Clone)]
pub struct Tally {
    metrics: EpisodeMetrics,
    trace: EpisodeTrace,
    /// The human's end point velocities at the last tick (two per part), m/s.
    human_v_prev: Vec<Vector>,
    /// Below d_min at the last tick.
    below: bool,
    /// In contact (true separation <= 0) at the last tick.
    touching: bool,
    /// The closest pair so far (formatted once at the end: no allocation per tick).
    closest: Option<(LinkId, HumanPart, f64)>,
    braking: Vec<(BrakeReason, usize)>,
    error_sum: f64,
    error_ticks: usize,
    /// Per part ([`HumanPart::ALL`]'s order): the error's sum and the ticks it was seen.
    part_error_sum: [f64; HumanPart::ALL.len()],
    part_error_ticks: [usize; HumanPart::ALL.len()],
}

impl Tally {
    /// The tally of episode `episode` (seed `seed`) with the filter named `filter`, of a task
    /// planned to take `nominal_task_s`.
    #[must_use]
    pub fn new(episode: usize, seed: u64, filter: String, nominal_task_s: f64) -> Self {
        Self {
            metrics: EpisodeMetrics {
                episode,
                seed,
                filter,
                min_separation_m: f64::INFINITY,
                closest: String::new(),
                violation_s: 0.0,
                violations: 0,
                violation_moving_s: 0.0,
                task_time_s: None,
                nominal_task_s,
                peak_speed_near_human_m_s: 0.0,
                peak_approach_speed_m_s: 0.0,
                peak_human_speed_m_s: 0.0,
                peak_human_acceleration_m_s2: 0.0,
                peak_approach_by_part_m_s: [0.0; crate::evaluate::PFL_PARTS.len()],
                contacts_moving: 0,
                contacts_standing: 0,
                ticks_pass: 0,
                ticks_modified: 0,
                ticks_relaxed: 0,
                ticks_braking: 0,
                braking_reasons: Vec::new(),
                perception_error_m: 0.0,
                perception_error_by_part_m: super::no_part_errors(),
                fit_error_m: f64::NAN,
                other_arm_min_separation_m: f64::NAN,
                other_arm_violation_s: 0.0,
                simulated_s: 0.0,
                wall_s: 0.0,
                setup_s: 0.0,
            },
            trace: EpisodeTrace::default(),
            human_v_prev: Vec::new(),
            below: false,
            touching: false,
            closest: None,
            braking: Vec::new(),
            error_sum: 0.0,
            error_ticks: 0,
            part_error_sum: [0.0; HumanPart::ALL.len()],
            part_error_ticks: [0; HumanPart::ALL.len()],
        }
    }

    /// The episode's index (for logs).
    #[must_use]
    pub fn episode(&self) -> usize {
        self.metrics.episode
    }

    /// The last true separation traced, m (NaN before the first or without a pair).
    #[must_use]
    pub fn last_separation_m(&self) -> f64 {
        self.trace.separation_m.last().copied().unwrap_or(f64::NAN)
    }

    /// The true human at a tick `dt` after the last: its fastest point, and its end points'
    /// accelerations over the tick (none at the first).
    pub fn human(&mut self, truth: &HumanEstimate, dt: f64) {
        let metrics = &mut self.metrics;
        for p in &truth.parts {
            metrics.peak_human_speed_m_s = metrics
                .peak_human_speed_m_s
                .max(p.v_a_W.length())
                .max(p.v_b_W.length());
        }
        let velocities = truth.parts.iter().flat_map(|p| [p.v_a_W, p.v_b_W]);
        if self.human_v_prev.len() == 2 * truth.parts.len() {
            for (v, v_prev) in velocities.zip(&mut self.human_v_prev) {
                metrics.peak_human_acceleration_m_s2 = metrics
                    .peak_human_acceleration_m_s2
                    .max((v - *v_prev).length() / dt);
                *v_prev = v;
            }
        } else {
            self.human_v_prev.clear();
            self.human_v_prev.extend(velocities);
        }
    }

    /// The robot's approach speed toward `part` within the power and force limiting
    /// distance, m/s (its body region's contact speed applies there: both arms' parts count
    /// as their limb's).
    pub fn approach(&mut self, part: HumanPart, approach_m_s: f64) {
        if let Some(i) = (crate::evaluate::PFL_PARTS.iter()).position(|&p| p == part.limb()) {
            let peak = &mut self.metrics.peak_approach_by_part_m_s[i];
            *peak = peak.max(approach_m_s);
        }
    }

    /// No robot-human pair this tick (nothing in range).
    pub fn no_pair(&mut self) {
        self.trace.separation_m.push(f64::NAN);
    }

    /// The closest true pair at `t`, over a tick of `dt`, with the robot point's velocity
    /// there when it is within `near_m` or `d_min_m` (else `None`): the minimum separation,
    /// the peaks near the human, contacts by the robot's speed (SSM permits contact only
    /// with a robot at standstill, ISO/TS 15066 5.5.4) and violations of `d_min_m`.
    pub fn separation(
        &mut self,
        t: f64,
        dt: f64,
        pair: &SignedDistancePair,
        velocity: Option<Vector>,
        d_min_m: f64,
        near_m: f64,
    ) {
        let metrics = &mut self.metrics;
        let d = pair.distance_m;
        if d < metrics.min_separation_m {
            metrics.min_separation_m = d;
            self.closest = Some((pair.link, pair.part, t));
        }
        let speed = velocity.map_or(0.0, |v| v.length());
        if let Some(v) = velocity
            && d < near_m
        {
            metrics.peak_speed_near_human_m_s = metrics.peak_speed_near_human_m_s.max(speed);
            metrics.peak_approach_speed_m_s =
                metrics.peak_approach_speed_m_s.max(-pair.nhat_BA_W.dot(v));
        }
        // Each contact is counted by the robot's speed when it began.
        if d <= 0.0 {
            if !self.touching {
                if speed > MOVING_M_S {
                    metrics.contacts_moving += 1;
                } else {
                    metrics.contacts_standing += 1;
                }
            }
            self.touching = true;
        } else {
            self.touching = false;
        }
        if d < d_min_m {
            if !self.below {
                metrics.violations += 1;
            }
            self.below = true;
            metrics.violation_s += dt;
            if speed > MOVING_M_S {
                metrics.violation_moving_s += dt;
            }
        } else {
            self.below = false;
        }
        self.trace.separation_m.push(d);
    }

    /// The filter's status of one tick.
    pub fn status(&mut self, status: FilterStatus) {
        let metrics = &mut self.metrics;
        match status {
            FilterStatus::Pass => metrics.ticks_pass += 1,
            FilterStatus::Modified => metrics.ticks_modified += 1,
            FilterStatus::Relaxed => metrics.ticks_relaxed += 1,
            FilterStatus::Braking(reason) => {
                metrics.ticks_braking += 1;
                match self.braking.iter_mut().find(|(r, _)| *r == reason) {
                    Some((_, n)) => *n += 1,
                    None => self.braking.push((reason, 1)),
                }
            }
        }
    }

    /// One tick's trace: its time, the perception error (none without an estimate; the mean
    /// over parts and each part's, [`HumanPart::ALL`]'s order), the task's speed against its
    /// plan, and the norms of the nominal and the filtered command.
    pub fn tick(
        &mut self,
        t: f64,
        perception_error: Option<(f64, [Option<f64>; HumanPart::ALL.len()])>,
        task_speed: f64,
        nominal_norm: f64,
        command_norm: f64,
    ) {
        let perception_error_m = perception_error.map(|(e, _)| e);
        if let Some((e, by_part)) = perception_error {
            self.error_sum += e;
            self.error_ticks += 1;
            for (i, e) in by_part.iter().enumerate() {
                if let Some(e) = e {
                    self.part_error_sum[i] += e;
                    self.part_error_ticks[i] += 1;
                }
            }
        }
        self.trace.t_s.push(t);
        self.trace.perception_error_m.push(perception_error_m);
        self.trace.task_speed.push(task_speed);
        self.trace.command_rad_s.push(command_norm);
        self.trace.speed_scale.push(if nominal_norm > 1e-6 {
            (command_norm / nominal_norm).min(2.0)
        } else {
            1.0
        });
    }

    /// The recorded person's other arm (not modelled; guarded where perception sees it) at
    /// `separation_m` from the robot over a tick `dt`.
    pub fn other_arm(&mut self, separation_m: f64, dt: f64, d_min_m: f64) {
        let m = &mut self.metrics;
        // NaN (none yet) loses to any number.
        m.other_arm_min_separation_m = separation_m.min(m.other_arm_min_separation_m);
        if separation_m < d_min_m {
            m.other_arm_violation_s += dt;
        }
    }

    /// The task finished at `t`.
    pub fn finished(&mut self, t: f64) {
        self.metrics.task_time_s = Some(t);
    }

    /// The metrics and the trace, with what is formatted once per episode: the closest
    /// pair's link (named by `link_name`), the braking reasons, the mean perception error.
    pub fn finish(
        mut self,
        link_name: impl Fn(LinkId) -> String,
        simulated_s: f64,
        started: Instant,
    ) -> (EpisodeMetrics, EpisodeTrace) {
        self.trace.separation_m.truncate(self.trace.t_s.len());
        let metrics = &mut self.metrics;
        if let Some((link, part, t)) = self.closest {
            metrics.closest = format!("{} / {part} at {t:.2} s", link_name(link));
        }
        metrics.braking_reasons = self
            .braking
            .into_iter()
            .map(|(r, n)| (r.to_string(), n))
            .collect();
        metrics.perception_error_m = if self.error_ticks > 0 {
            self.error_sum / self.error_ticks as f64
        } else {
            f64::NAN
        };
        for (i, e) in metrics.perception_error_by_part_m.iter_mut().enumerate() {
            *e = if self.part_error_ticks[i] > 0 {
                self.part_error_sum[i] / self.part_error_ticks[i] as f64
            } else {
                f64::NAN
            };
        }
        metrics.simulated_s = simulated_s;
        metrics.wall_s = started.elapsed().as_secs_f64();
        (self.metrics, self.trace)
    }
}
