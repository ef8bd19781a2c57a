//! The safety filter of one robot: nominal joint velocities in, safe joint velocities out,
//! every tick, with a status that says what it did and why.

use serde::{Deserialize, Serialize};
use workcell_robots::math::Pose;
use workcell_robots::{KinematicState, RobotModel};

use crate::distance::{PairConstraint, RobotGeometry};
use crate::error::{Result, invalid};
use crate::human::{AnticipatedPart, HumanEstimate, HumanPart};
use crate::iso::{BodyRegion, SsmConfig, effective_robot_mass_kg};
use crate::qp::{QpFailure, QpFilter};

/// Which filter guards the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FilterMode {
    /// The nominal command passes unchanged (the baseline that shows what could go wrong).
    None,
    /// The QP safety filter (control barrier function rows).
    Qp,
    /// Speed and separation monitoring: the nominal command scaled down (ISO/TS 15066).
    Ssm,
}

impl std::fmt::Display for FilterMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FilterMode::None => "none",
            FilterMode::Qp => "qp",
            FilterMode::Ssm => "ssm",
        })
    }
}

/// The approach speed a pair's barrier row must still allow when the pair enters the filter,
/// m/s: ISO 13855's 2.0 m/s for hands and arms near a hazard.
pub const DETECTION_APPROACH_M_S: f64 = 2.0;

/// The longest `anticipation_s` and `escape_horizon_s`, s: at ISO 13855's 2.0 m/s a hand
/// crosses a work-cell in about a second, and the settings measured are 0.1 to 0.15 s.
pub const MAX_HORIZON_S: f64 = 3.0;

/// Settings of the filter (the `[safety]` table of an evaluation file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FilterConfig {
    /// Smallest allowed separation between robot and human surfaces, m. Default 0.10.
    pub d_min_m: f64,
    /// Pairs farther apart than this (capsule distance) get no constraint, m. Default 0.6.
    pub detection_m: f64,
    /// Barrier rate gamma of the QP rows, 1/s: the gap to d_min may close at most at
    /// gamma (d - d_min). Default 4.
    pub gamma_per_s: f64,
    /// Rows reserved for pairs in the QP (the closest pairs win). Default 32.
    pub max_pairs: usize,
    /// Joint acceleration bound where the URDF gives none, rad/s^2: the braking rate of the
    /// fail-safe stop, and a bound of the filtered command when `bound_acceleration`.
    /// Default 8.
    pub acceleration_rad_s2: f64,
    /// Bound the change of the command per tick by the acceleration limits. Default false:
    /// as hard rows they make the QP infeasible whenever the human's approach speed jumps
    /// (a new camera frame), and the robot then brakes instead of evading; the servos ramp
    /// the command within their own acceleration limits.
    pub bound_acceleration: bool,
    /// When no command keeps every pair row (the human approaches faster than the arm can
    /// retreat), the filter takes the command that protects the closest pair most (farther
    /// pairs give way first) if it breaks the closest pair's row by at most this much, m/s
    /// ([`FilterStatus::Relaxed`]); beyond, it brakes. Default 3: the best retreat the
    /// joints allow keeps more distance than stopping in the hand's path (experiments/safety.md:
    /// 1,000 episodes with the brake at 1 m/s and without it). A relaxation far beyond a
    /// human's speed means the inputs are wrong, and the filter stops.
    pub max_relaxation_m_s: f64,
    /// Joint position limits become velocity bounds `gain (q_max - q)`, 1/s. Default 10.
    pub position_gain_per_s: f64,
    /// Power and force limiting: within this capsule distance of a human part the robot
    /// may approach that part at most at ISO/TS 15066's transient contact speed of its body
    /// region (QP: a cap on the pair's row; SSM: on the scale), m; farther out the cap
    /// rises as a braking ramp (`pfl_deceleration_m_s2`). 0 turns it off. Default 0.3.
    pub pfl_distance_m: f64,
    /// Deceleration the robot's points can be assumed to manage toward a part, m/s^2: beyond
    /// `pfl_distance_m` the cap rises as `sqrt(v_limit^2 + 2 a (d - pfl_distance_m))`, so
    /// that a point that may approach at the cap can slow to the region's limit by the time
    /// it enters the PFL distance. Default 2.5.
    pub pfl_deceleration_m_s2: f64,
    /// Escape-aware margin: where the arm can move a pair's witness point away from the
    /// human at only `e` m/s (joint velocity limits, along the normal), the pair keeps
    /// `escape_horizon_s * max(0, 2.0 - e)` m beyond d_min (2.0 m/s: ISO 13855's approach
    /// speed), so that it starts giving way before a hand can outrun it. s; 0 turns it off;
    /// at most [`MAX_HORIZON_S`]. Default 0.
    pub escape_horizon_s: f64,
    /// Anticipation: the filter guards each moving human part also where it will be if it
    /// keeps its estimated velocity for up to this long, s (copies of its capsule along that
    /// path, [`HumanEstimate::anticipate_into`]). A part coming at the arm is met earlier, so
    /// that the arm starts giving way while the hand is still setting off, not once it is
    /// there; a resting part costs nothing. The rows of the part where it is now stay as
    /// they are. QP only: speed and separation monitoring counts the human's travel in its
    /// protective separation distance already. 0 turns it off; at most
    /// [`MAX_HORIZON_S`]. Default 0.15, the evaluated filter's (experiments/safety.md,
    /// "Anticipation": over 1,000 seeds with the noisy camera, none below d_min against 1 at
    /// 0).
    pub anticipation_s: f64,
    /// The QP keeps each link this far from the cell's static obstacles
    /// ([`SafetyFilter::set_obstacles`]) while it evades the human, m. Default 0.02.
    pub obstacle_clearance_m: f64,
    /// Obstacle boxes closer to a link than this get a row, m. Default 0.2.
    pub obstacle_detection_m: f64,
    /// How fast a link may approach the furniture per metre of clearance left beyond
    /// `obstacle_clearance_m`, 1/s. Default 25: a hand can pin the arm against a box, and at
    /// the human pairs' gamma (4) a link 6 cm from the box could back toward it at only
    /// 0.16 m/s; at 25 it can retreat at 1 m/s and still stops before the clearance (one
    /// 4 ms tick covers a tenth of the gap).
    pub obstacle_gamma_per_s: f64,
    /// Payload at the tool for the effective robot mass of power and force limiting
    /// (M/2 + payload), kg. Default 0.
    pub payload_kg: f64,
    /// Speed and separation monitoring.
    pub ssm: SsmConfig,
}

impl Default for FilterConfig {
    fn default() -> Self {
        Self {
            d_min_m: 0.10,
            detection_m: 0.6,
            gamma_per_s: 4.0,
            max_pairs: 32,
            acceleration_rad_s2: 8.0,
            bound_acceleration: false,
            max_relaxation_m_s: 3.0,
            position_gain_per_s: 10.0,
            pfl_distance_m: 0.3,
            pfl_deceleration_m_s2: 2.5,
            escape_horizon_s: 0.0,
            anticipation_s: 0.15,
            obstacle_clearance_m: 0.02,
            obstacle_detection_m: 0.2,
            obstacle_gamma_per_s: 25.0,
            payload_kg: 0.0,
            ssm: SsmConfig::default(),
        }
    }
}

impl FilterConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`SafetyError::InvalidConfig`] naming the key.
    pub fn validate(&self) -> Result<()> {
        let positive = |key: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(invalid(key, format!("must be finite and > 0, got {v}")))
            }
        };
        if !(self.d_min_m.is_finite() && self.d_min_m >= 0.0) {
            return Err(invalid(
                "safety.d_min_m",
                format!("must be finite and >= 0, got {}", self.d_min_m),
            ));
        }
        positive("safety.detection_m", self.detection_m)?;
        positive("safety.gamma_per_s", self.gamma_per_s)?;
        positive("safety.acceleration_rad_s2", self.acceleration_rad_s2)?;
        positive("safety.position_gain_per_s", self.position_gain_per_s)?;
        positive("safety.pfl_deceleration_m_s2", self.pfl_deceleration_m_s2)?;
        positive("safety.obstacle_gamma_per_s", self.obstacle_gamma_per_s)?;
        for (key, v) in [
            ("safety.pfl_distance_m", self.pfl_distance_m),
            ("safety.payload_kg", self.payload_kg),
            ("safety.obstacle_clearance_m", self.obstacle_clearance_m),
            ("safety.escape_horizon_s", self.escape_horizon_s),
            ("safety.anticipation_s", self.anticipation_s),
            ("safety.obstacle_detection_m", self.obstacle_detection_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(key, format!("must be finite and >= 0, got {v}")));
            }
        }
        // A horizon of seconds guards where a part would be after crossing the cell: a
        // mistake (1e9 was accepted), not a setting.
        for (key, v) in [
            ("safety.anticipation_s", self.anticipation_s),
            ("safety.escape_horizon_s", self.escape_horizon_s),
        ] {
            if v > MAX_HORIZON_S {
                return Err(invalid(
                    key,
                    format!("{v} s is beyond the limit of {MAX_HORIZON_S} s"),
                ));
            }
        }
        if !(self.max_relaxation_m_s.is_finite() && self.max_relaxation_m_s >= 0.0) {
            return Err(invalid(
                "safety.max_relaxation_m_s",
                format!("must be finite and >= 0, got {}", self.max_relaxation_m_s),
            ));
        }
        // Between keys: a pair must enter the QP while its barrier row still lets the human
        // approach at ISO 13855's 2.0 m/s (gamma (d - d_min) >= 2.0 at d = detection_m);
        // otherwise the row is tight the moment it appears and the arm cannot react in time.
        let room = self.detection_m - self.d_min_m;
        if room * self.gamma_per_s < DETECTION_APPROACH_M_S - 1e-9 {
            return Err(invalid(
                "safety.detection_m",
                format!(
                    "{} m leaves {room:.3} m beyond d_min_m = {} m: at gamma_per_s = {} a pair \
                     must enter the filter at least {DETECTION_APPROACH_M_S} / gamma = {:.3} m \
                     beyond d_min (ISO 13855's approach speed of 2.0 m/s)",
                    self.detection_m,
                    self.d_min_m,
                    self.gamma_per_s,
                    DETECTION_APPROACH_M_S / self.gamma_per_s
                ),
            ));
        }
        if self.max_pairs == 0 || self.max_pairs > 256 {
            return Err(invalid(
                "safety.max_pairs",
                format!("must be in 1..=256, got {}", self.max_pairs),
            ));
        }
        self.ssm.validate()
    }
}

/// Why the filter commanded a braking stop instead of a filtered command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BrakeReason {
    /// A joint position, nominal velocity or the time step is NaN or infinite, or has the
    /// wrong length.
    InvalidRobotInput,
    /// A human part's capsule or velocity is NaN or infinite, or the uncertainty is.
    InvalidHumanEstimate,
    /// Perception reports no human at all: nothing can be guaranteed.
    NoHumanEstimate,
    /// The QP solver did not return a usable solution (iteration limit, numerical trouble).
    Solver(QpFailure),
    /// Keeping the separation needs more than `max_relaxation_m_s` beyond what the joints
    /// can do (e.g. a d_min larger than the cell).
    Infeasible,
    /// The joint bounds contradict each other (e.g. outside a position limit and unable to
    /// return within the acceleration bound).
    ConflictingBounds,
    /// SSM: the separation is below the protective distance even for a standing robot.
    ProtectiveStop,
}

impl std::fmt::Display for BrakeReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BrakeReason::InvalidRobotInput => f.write_str("invalid robot input"),
            BrakeReason::InvalidHumanEstimate => f.write_str("invalid human estimate"),
            BrakeReason::NoHumanEstimate => f.write_str("no human estimate"),
            BrakeReason::Solver(e) => write!(f, "QP failed: {e}"),
            BrakeReason::Infeasible => f.write_str("separation cannot be kept"),
            BrakeReason::ConflictingBounds => f.write_str("conflicting joint bounds"),
            BrakeReason::ProtectiveStop => f.write_str("protective stop"),
        }
    }
}

/// What the filter did this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FilterStatus {
    /// The nominal command was safe (within bounds, no constraint active): passed unchanged.
    Pass,
    /// The command was changed to keep the separation (or the joint bounds).
    Modified,
    /// No command keeps every pair row: the one that protects the closest pair most (its
    /// row broken by `slack_m_s` of [`FilterOutput`]) moves the arm away as fast as its
    /// limits allow.
    Relaxed,
    /// Fail-safe: braking toward standstill within the acceleration bound.
    Braking(BrakeReason),
}

impl FilterStatus {
    /// A short name for tables: `pass`, `modified`, or `brake: <reason>`.
    #[must_use]
    pub fn label(&self) -> String {
        match self {
            FilterStatus::Pass => "pass".into(),
            FilterStatus::Modified => "modified".into(),
            FilterStatus::Relaxed => "relaxed".into(),
            FilterStatus::Braking(r) => format!("brake: {r}"),
        }
    }
}

/// The result of one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterOutput {
    pub status: FilterStatus,
    /// Pairs within the detection distance.
    pub active_pairs: usize,
    /// Smallest capsule distance the filter saw (robot capsules against the inflated human,
    /// and its anticipated copies when `anticipation_s` is on), m; infinite when no pair was
    /// within the detection distance.
    pub min_distance_m: f64,
    /// SSM: the factor applied to the nominal command; QP: 1 (see the command itself).
    pub scale: f64,
    /// QP: by how much the closest pair's row is broken, m/s (0 unless
    /// [`FilterStatus::Relaxed`]).
    pub slack_m_s: f64,
}

/// The safety filter of one robot. Build once, call [`SafetyFilter::tick`] every control
/// period; the tick does not allocate (clarabel's own solve aside).
#[derive(Debug)]
pub struct SafetyFilter {
    mode: FilterMode,
    config: FilterConfig,
    geometry: RobotGeometry,
    qp: Option<QpFilter>,
    kinematics: KinematicState,
    pairs: Vec<PairConstraint>,
    qdot: Vec<f64>,
    qdot_prev: Vec<f64>,
    lb: Vec<f64>,
    ub: Vec<f64>,
    velocity_limit: Vec<f64>,
    acceleration_limit: Vec<f64>,
    position_limits: Vec<[f64; 2]>,
    /// Power and force limiting: the largest approach speed per part, indexed by
    /// [`HumanPart::ALL`] (infinite when PFL is off).
    pfl_limits_m_s: [f64; HumanPart::ALL.len()],
    obstacles: Vec<crate::distance::Obstacle>,
    /// The human parts' anticipated copies of this tick (`anticipation_s`).
    ahead: Vec<AnticipatedPart>,
}

impl SafetyFilter {
    /// A filter for `robot` with its root at `X_WB`.
    ///
    /// # Errors
    /// [`SafetyError`] for an invalid configuration, a robot without collision geometry, with
    /// too many joints, or without mass while power and force limiting is on (its contact
    /// speeds depend on the robot's effective mass).
    pub fn new(
        robot: &RobotModel,
        X_WB: Pose,
        mode: FilterMode,
        config: FilterConfig,
    ) -> Result<Self> {
        config.validate()?;
        let geometry = RobotGeometry::new(robot)?;
        let dof = robot.dof();
        let qp = match mode {
            FilterMode::Qp => Some(QpFilter::new(dof, config.max_pairs)?),
            _ => None,
        };
        let mut kinematics = KinematicState::new(robot);
        kinematics.X_WB = X_WB;
        let joints: Vec<_> = robot
            .actuated_joints()
            .iter()
            .map(|&j| robot.joints()[j].limits)
            .collect();
        let velocity_limit = joints
            .iter()
            .map(|l| {
                if l.velocity > 0.0 {
                    l.velocity
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        let acceleration_limit = joints
            .iter()
            .map(|l| {
                if l.acceleration.is_finite() && l.acceleration > 0.0 {
                    l.acceleration
                } else {
                    config.acceleration_rad_s2
                }
            })
            .collect();
        let mut pfl_limits_m_s = [f64::INFINITY; HumanPart::ALL.len()];
        if config.pfl_distance_m > 0.0 {
            let m_r = effective_robot_mass_kg(robot.mass_kg(), config.payload_kg);
            if !(m_r.is_finite() && m_r > 0.0) {
                return Err(invalid(
                    "safety.pfl_distance_m",
                    format!(
                        "robot '{}' has no mass in its description: power and force limiting \
                         needs it (give the links <inertial> masses, or set \
                         safety.pfl_distance_m = 0)",
                        robot.name()
                    ),
                ));
            }
            for (limit, part) in pfl_limits_m_s.iter_mut().zip(HumanPart::ALL) {
                *limit = BodyRegion::of(part).max_contact_speed_m_s(m_r, true);
            }
        }
        Ok(Self {
            obstacles: Vec::new(),
            ahead: Vec::new(),
            pfl_limits_m_s,
            mode,
            geometry,
            qp,
            kinematics,
            pairs: Vec::with_capacity(robot.links().len() * 3),
            qdot: vec![0.0; dof],
            qdot_prev: vec![0.0; dof],
            lb: vec![0.0; dof],
            ub: vec![0.0; dof],
            velocity_limit,
            acceleration_limit,
            position_limits: robot.position_limits(),
            config,
        })
    }

    /// The cell's static obstacles (tables, shelves): the QP filter does not push the arm
    /// into them while it evades the human. Replaces any earlier set.
    pub fn set_obstacles(&mut self, obstacles: Vec<crate::distance::Obstacle>) {
        self.obstacles = obstacles;
    }

    /// The filter's mode.
    #[must_use]
    pub fn mode(&self) -> FilterMode {
        self.mode
    }

    /// The filter's settings.
    #[must_use]
    pub fn config(&self) -> &FilterConfig {
        &self.config
    }

    /// The robot geometry (capsules, exact shapes) the filter guards.
    #[must_use]
    pub fn geometry(&self) -> &RobotGeometry {
        &self.geometry
    }

    /// The kinematics of the last tick's configuration.
    #[must_use]
    pub fn kinematics(&self) -> &KinematicState {
        &self.kinematics
    }

    /// The pairs of the last tick (within the detection distance).
    #[must_use]
    pub fn pairs(&self) -> &[PairConstraint] {
        &self.pairs
    }

    /// The QP of the last tick that needed one (QP mode only).
    #[must_use]
    pub fn qp(&self) -> Option<&QpFilter> {
        self.qp.as_ref()
    }

    /// The command of the last tick.
    #[must_use]
    pub fn command(&self) -> &[f64] {
        &self.qdot
    }

    /// Forgets the previous command (the robot is standing).
    pub fn reset(&mut self) {
        self.qdot.fill(0.0);
        self.qdot_prev.fill(0.0);
    }

    /// One control tick: the robot at joint positions `q` wants `qdot_nom`; the human is as
    /// `human` says; the command holds for `dt_s`. Returns what was done; the command is in
    /// [`SafetyFilter::command`]. Never panics and never returns a non-finite command: bad
    /// input gives a braking command.
    pub fn tick(
        &mut self,
        robot: &RobotModel,
        q: &[f64],
        qdot_nom: &[f64],
        human: &HumanEstimate,
        dt_s: f64,
    ) -> FilterOutput {
        let dof = self.qdot.len();
        self.qdot_prev.copy_from_slice(&self.qdot);
        let mut out = FilterOutput {
            status: FilterStatus::Pass,
            active_pairs: 0,
            min_distance_m: f64::INFINITY,
            scale: 1.0,
            slack_m_s: 0.0,
        };
        let robot_ok = q.len() == dof
            && qdot_nom.len() == dof
            && dt_s.is_finite()
            && dt_s > 0.0
            && q.iter().chain(qdot_nom).all(|v| v.is_finite());
        if !robot_ok || robot.dof() != dof {
            return self.brake(out, BrakeReason::InvalidRobotInput, dt_s);
        }
        if self.mode == FilterMode::None {
            self.qdot.copy_from_slice(qdot_nom);
            // Still measured, so that unfiltered runs report distances too.
            if human.parts.iter().all(|p| p.is_valid())
                && robot.forward_kinematics(q, &mut self.kinematics).is_ok()
            {
                self.measure_pairs(robot, human, &mut out);
            }
            return out;
        }
        if human.parts.is_empty() {
            return self.brake(out, BrakeReason::NoHumanEstimate, dt_s);
        }
        let human_ok = human.uncertainty_m.is_finite()
            && human.uncertainty_m >= 0.0
            && human.uncertainty_rate_m_s.is_finite()
            && human.uncertainty_rate_m_s >= 0.0
            && human.parts.iter().all(|p| p.is_valid());
        if !human_ok {
            return self.brake(out, BrakeReason::InvalidHumanEstimate, dt_s);
        }
        if robot.forward_kinematics(q, &mut self.kinematics).is_err() {
            return self.brake(out, BrakeReason::InvalidRobotInput, dt_s);
        }
        if self.mode == FilterMode::Qp {
            human.anticipate_into(self.config.anticipation_s, &mut self.ahead);
        } else {
            self.ahead.clear();
        }
        self.measure_pairs(robot, human, &mut out);

        // Joint bounds: velocity limit, acceleration from the last command, position limit.
        let gain = self.config.position_gain_per_s;
        for (j, &q_j) in q.iter().enumerate() {
            let [lo, hi] = self.position_limits[j];
            let dv = if self.config.bound_acceleration {
                self.acceleration_limit[j] * dt_s
            } else {
                f64::INFINITY
            };
            let v = self.velocity_limit[j];
            let ub = v.min(self.qdot_prev[j] + dv).min(if hi.is_finite() {
                gain * (hi - q_j)
            } else {
                f64::INFINITY
            });
            let lb = (-v).max(self.qdot_prev[j] - dv).max(if lo.is_finite() {
                gain * (lo - q_j)
            } else {
                f64::NEG_INFINITY
            });
            if lb.is_nan() || ub.is_nan() || lb > ub {
                return self.brake(out, BrakeReason::ConflictingBounds, dt_s);
            }
            self.lb[j] = lb;
            self.ub[j] = ub;
        }

        match self.mode {
            FilterMode::None => unreachable!("handled above"),
            FilterMode::Qp => {
                self.geometry.obstacle_constraints(
                    robot,
                    &self.kinematics,
                    &self.obstacles,
                    self.config.obstacle_detection_m,
                    self.config.obstacle_clearance_m,
                    self.config.obstacle_gamma_per_s,
                    &mut self.pairs,
                );
                // The planned motion keeps its own clearance (from the exact links, which
                // the capsules overestimate): an obstacle row only forbids approaching the
                // furniture faster than the nominal command does.
                for c in self.pairs.iter_mut().filter(|c| c.obstacle) {
                    c.max_approach_m_s = c.max_approach_m_s.max(c.approach_m_s(qdot_nom));
                }
                self.tick_qp(qdot_nom, out, dt_s)
            }
            FilterMode::Ssm => self.tick_ssm(qdot_nom, out, dt_s),
        }
    }

    /// The pairs within the detection distance at the configuration in `self.kinematics`,
    /// counted and their smallest distance recorded in `out`.
    fn measure_pairs(&mut self, robot: &RobotModel, human: &HumanEstimate, out: &mut FilterOutput) {
        self.geometry.pair_constraints_ahead(
            robot,
            &self.kinematics,
            human,
            &self.ahead,
            self.config.detection_m,
            &mut self.pairs,
        );
        if self.config.pfl_distance_m > 0.0 {
            let a = self.config.pfl_deceleration_m_s2;
            for c in &mut self.pairs {
                let limit = self.pfl_limits_m_s[part_index(c.pair.part)];
                let room = (c.pair.distance_m - self.config.pfl_distance_m).max(0.0);
                c.max_approach_m_s = (limit * limit + 2.0 * a * room).sqrt();
            }
        }
        if self.config.escape_horizon_s > 0.0 {
            for c in &mut self.pairs {
                let escape = c.escape_m_s(&self.velocity_limit);
                c.escape_margin_m =
                    self.config.escape_horizon_s * (DETECTION_APPROACH_M_S - escape).max(0.0);
            }
        }
        out.active_pairs = self.pairs.len();
        out.min_distance_m = self
            .pairs
            .iter()
            .map(|p| p.pair.distance_m)
            .fold(f64::INFINITY, f64::min);
    }

    fn tick_qp(&mut self, qdot_nom: &[f64], mut out: FilterOutput, dt_s: f64) -> FilterOutput {
        let within = qdot_nom
            .iter()
            .zip(self.lb.iter().zip(&self.ub))
            .all(|(v, (lo, hi))| lo <= v && v <= hi);
        let (gamma, d_min) = (self.config.gamma_per_s, self.config.d_min_m);
        let satisfied = self
            .pairs
            .iter()
            .all(|c| c.approach_m_s(qdot_nom) <= c.approach_bound_m_s(gamma, d_min));
        if within && satisfied {
            self.qdot.copy_from_slice(qdot_nom);
            return out;
        }
        let Some(qp) = self.qp.as_mut() else {
            return self.brake(out, BrakeReason::Solver(QpFailure::BadSolution), dt_s);
        };
        match qp.solve(
            qdot_nom,
            &mut self.pairs,
            &self.lb,
            &self.ub,
            gamma,
            d_min,
            &mut self.qdot,
        ) {
            Ok(slack) if slack > self.config.max_relaxation_m_s => {
                out.slack_m_s = slack;
                self.brake(out, BrakeReason::Infeasible, dt_s)
            }
            Ok(slack) => {
                out.slack_m_s = slack;
                out.status = if slack > 0.0 {
                    FilterStatus::Relaxed
                } else {
                    FilterStatus::Modified
                };
                out
            }
            Err(e) => self.brake(out, BrakeReason::Solver(e), dt_s),
        }
    }

    fn tick_ssm(&mut self, qdot_nom: &[f64], mut out: FilterOutput, dt_s: f64) -> FilterOutput {
        // The capsule distance already subtracts the sensing uncertainty (the human capsules
        // are inflated by it), so Z_d is 0 here.
        let mut scale: f64 = 1.0;
        for c in &self.pairs {
            let approach = c.approach_m_s(qdot_nom);
            if approach <= 0.0 {
                continue;
            }
            let allowed = self
                .config
                .ssm
                .max_robot_speed_m_s(c.pair.distance_m - self.config.d_min_m, 0.0)
                .min(c.max_approach_m_s);
            scale = scale.min(allowed / approach);
        }
        out.scale = scale;
        if scale <= 0.0 {
            return self.brake(out, BrakeReason::ProtectiveStop, dt_s);
        }
        let mut changed = scale < 1.0;
        for (j, nominal) in qdot_nom.iter().enumerate() {
            let v = nominal * scale;
            let clamped = v.clamp(self.lb[j], self.ub[j]);
            changed |= clamped != v;
            self.qdot[j] = clamped;
        }
        if changed {
            out.status = FilterStatus::Modified;
        }
        out
    }

    /// The fail-safe: every joint decelerates toward 0 at its acceleration bound. Without a
    /// valid time step the ramp cannot be computed: the command is 0 (the drive's own ramp
    /// applies).
    fn brake(&mut self, mut out: FilterOutput, reason: BrakeReason, dt_s: f64) -> FilterOutput {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s
        } else {
            f64::INFINITY
        };
        for j in 0..self.qdot.len() {
            let v = if self.qdot_prev[j].is_finite() {
                self.qdot_prev[j]
            } else {
                0.0
            };
            let dv = self.acceleration_limit[j] * dt;
            self.qdot[j] = if v > 0.0 {
                (v - dv).max(0.0)
            } else {
                (v + dv).min(0.0)
            };
        }
        out.status = FilterStatus::Braking(reason);
        out.scale = 0.0;
        out
    }
}

/// Index of `part` in [`HumanPart::ALL`].
fn part_index(part: HumanPart) -> usize {
    HumanPart::ALL
        .iter()
        .position(|&p| p == part)
        .unwrap_or_default()
}
