//! Scenario files: a TOML description of a work-cell. Every field has a documented default;
//! unknown keys are rejected, and [`Scenario::validate`] checks ranges.
//!
//! ```toml
//! seed = 7
//! time_step_s = 0.001
//!
//! [robot]
//! model = "iiwa14_kinematics"          # catalogue name or path to a URDF
//! base = { xyz = [0.0, 0.0, 0.75] }
//!
//! [human]
//! base = { xyz = [1.05, 0.0, 0.0], rpy = [0.0, 0.0, 3.14159] }
//!
//! [[clutter]]
//! kind = "box"
//! size_m = [1.2, 0.8, 0.75]
//! pose = { xyz = [0.45, 0.0, 0.375] }
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use workcell_robots::HumanLook;
use workcell_robots::input::{MAX_CONFIG_BYTES, read_text_file};
use workcell_robots::math::{Pose, pose_from_xyz_rpy};

use crate::error::{Result, SimError};

/// A whole work-cell: robot, human, clutter, cameras, time step and seed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Scenario {
    /// Seed of every random choice (trajectories, human motions). Default 0.
    pub seed: u64,
    /// Physics time step in seconds. Default 0.001 (1 kHz).
    pub time_step_s: f64,
    /// Gravity in the world frame (z up), m/s^2. Default `[0, 0, -9.81]`.
    pub gravity_m_s2: [f64; 3],
    pub robot: RobotConfig,
    pub human: HumanConfig,
    /// Static obstacles: tables, shelves, boxes.
    pub clutter: Vec<ClutterConfig>,
    /// Cameras (poses and intrinsics; rendering is a later stage).
    pub cameras: Vec<CameraConfig>,
}

impl Default for Scenario {
    fn default() -> Self {
        Self {
            seed: 0,
            time_step_s: 0.001,
            gravity_m_s2: [0.0, 0.0, -9.81],
            robot: RobotConfig::default(),
            human: HumanConfig::default(),
            clutter: Vec::new(),
            cameras: Vec::new(),
        }
    }
}

/// A pose written as URDF writes origins: translation in metres, fixed-axis roll-pitch-yaw in
/// radians.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct PoseConfig {
    pub xyz: [f64; 3],
    pub rpy: [f64; 3],
}

impl PoseConfig {
    /// The pose as a rigid transform.
    #[must_use]
    pub fn to_pose(&self) -> Pose {
        pose_from_xyz_rpy(self.xyz, self.rpy)
    }
}

/// The robot arm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RobotConfig {
    /// Catalogue name (`iiwa14_kinematics`, `ur5e_kinematics`) or path to a URDF file,
    /// relative to the scenario file. Default `iiwa14_kinematics`.
    pub model: String,
    /// Pose of the robot's root link in the world. Default: origin.
    pub base: PoseConfig,
    /// Joint configuration at t = 0; empty means the middle of the joint ranges.
    pub initial_q: Vec<f64>,
    /// Link whose origin task waypoints refer to. Default `tool0`.
    pub tool_link: String,
    /// Stiffness of the joint position servos, 1/s^2 (rapier's acceleration-based motors:
    /// gains act on accelerations, independent of link inertia). Default 20000.
    pub stiffness: f64,
    /// Damping of the joint servos, 1/s; also the gain of velocity control. Default 200.
    pub damping: f64,
    /// Acceleration limit of the servo references where the URDF gives none, rad/s^2 (m/s^2
    /// for prismatic joints). Default 10.
    pub servo_acceleration_rad_s2: f64,
    /// Compensate the robot's weight in its controller (as cobot controllers do), so that the
    /// servos hold poses without the sag gravity leaves. Default true.
    pub gravity_compensation: bool,
    /// What the robot does.
    pub motion: RobotMotionConfig,
}

impl Default for RobotConfig {
    fn default() -> Self {
        Self {
            model: "iiwa14_kinematics".into(),
            base: PoseConfig::default(),
            initial_q: Vec::new(),
            tool_link: "tool0".into(),
            stiffness: 20_000.0,
            damping: 200.0,
            servo_acceleration_rad_s2: 10.0,
            gravity_compensation: true,
            motion: RobotMotionConfig::default(),
        }
    }
}

/// The robot's nominal motion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum RobotMotionConfig {
    /// Stay at the initial configuration.
    Hold,
    /// Random rest-to-rest quintic moves between random waypoints in the workspace, within
    /// the position, velocity and acceleration limits (the paper's training motion).
    Random {
        /// Fraction of each joint's velocity limit to plan with, in (0, 1]. Default 0.5.
        #[serde(default = "default_speed_scale")]
        speed_scale: f64,
        /// Joint acceleration limit used where the URDF gives none, rad/s^2. Default 4.
        #[serde(default = "default_acceleration")]
        acceleration_rad_s2: f64,
        /// Keep waypoints this far inside the position limits, rad. Default 0.1.
        #[serde(default = "default_margin")]
        margin_rad: f64,
        /// Every link origin stays above this height (world z) along the motion, m. Default 0.
        #[serde(default)]
        min_height_m: f64,
        /// Every moving link's collision geometry keeps this distance from the clutter along
        /// the motion, m. Default 0.03.
        #[serde(default = "default_clearance")]
        clearance_m: f64,
        /// Number of waypoints before the motion repeats. Default 32.
        #[serde(default = "default_waypoints")]
        waypoints: usize,
    },
    /// Pick-and-place: the tool visits Cartesian waypoints (world frame) with the tool's z
    /// axis pointing down, dwelling at each; inverse kinematics gives the joint targets.
    PickAndPlace {
        /// Tool positions in the world, m.
        waypoints: Vec<[f64; 3]>,
        /// Time spent at each waypoint, s. Default 0.3.
        #[serde(default = "default_dwell")]
        dwell_s: f64,
        /// Fraction of the velocity limits, in (0, 1]. Default 0.5.
        #[serde(default = "default_speed_scale")]
        speed_scale: f64,
        /// Acceleration limit where the URDF gives none, rad/s^2. Default 4.
        #[serde(default = "default_acceleration")]
        acceleration_rad_s2: f64,
    },
}

fn default_speed_scale() -> f64 {
    0.5
}
fn default_acceleration() -> f64 {
    4.0
}
fn default_margin() -> f64 {
    0.1
}
fn default_clearance() -> f64 {
    0.03
}
/// The most waypoints of a robot motion.
pub const MAX_WAYPOINTS: usize = 10_000;
/// The most boards of a shelf.
pub const MAX_BOARDS: usize = 64;

fn default_waypoints() -> usize {
    32
}
fn default_dwell() -> f64 {
    0.3
}

impl Default for RobotMotionConfig {
    fn default() -> Self {
        Self::Random {
            speed_scale: default_speed_scale(),
            acceleration_rad_s2: default_acceleration(),
            margin_rad: default_margin(),
            min_height_m: 0.0,
            clearance_m: default_clearance(),
            waypoints: default_waypoints(),
        }
    }
}

/// Largest `human.peak_speed_m_s` a scenario may ask for, m/s: five times ISO 13855's
/// 2.0 m/s, a bound against typos rather than a fact about arms.
pub const MAX_HUMAN_PEAK_SPEED_M_S: f64 = 10.0;

/// The human arm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HumanConfig {
    /// Catalogue name or URDF path of the human model. Default `human_arm` (the arm on a
    /// fixed torso); `human` is the whole body.
    pub model: String,
    /// What the camera sees of it: `flesh` (default) or `skeletal` (the paper's bones).
    /// Collisions and the safety layer use the model's collision envelopes in both.
    pub look: HumanLook,
    /// Pose of the torso (pelvis centre, z up, facing +x) in the world.
    pub base: PoseConfig,
    /// The motions the human cycles through; the seed picks durations and targets.
    /// Default: rest, reach, withdraw, wave.
    pub motions: Vec<HumanMotionKind>,
    /// Shuffle the order of `motions` with the seed. Default false.
    pub shuffle: bool,
    /// How fast the generated motions are: `recorded` (calibrated to the shipped recordings
    /// of people at work) or `iso13855` (at most ISO 13855's 2.0 m/s). Default `iso13855`.
    /// See [`HumanSpeeds`].
    pub speeds: HumanSpeeds,
    /// Range of the peak speed of the arm's fastest point in each motion, m/s: each phase
    /// draws its peak from it, and a phase whose drawn duration would move faster is
    /// stretched (a wave swings less far). Default: the range of `speeds`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_speed_m_s: Option<[f64; 2]>,
    /// Range of the factor each generated transition's drawn duration is multiplied by
    /// (within (0, 1]: shorter, so faster and harder). Default: that of `speeds`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub duration_scale: Option<[f64; 2]>,
    /// Playback speed of the motions: 1 as generated, 0.5 half as fast, 1.5 a deliberately
    /// fast intrusion (peaks up to 1.5 times `peak_speed_m_s`); a recorded clip's too. Default
    /// 1.
    pub speed_scale: f64,
    /// A recorded clip moves the arm instead of the generator (`[human.recorded]`); left
    /// out, the generator.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recorded: Option<RecordedConfig>,
}

/// Recorded motion in a scenario: which clips of a library, how they are played, how they
/// are retargeted onto the arm. The episode of seed `s` plays clip `(s - 1) mod n` of the `n`
/// chosen, so seeds `1..=k n` play every clip `k` times, each with its own robot motion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordedConfig {
    /// The clip library, relative to the scenario file (the shipped one is
    /// `data/mocap/library.toml`).
    pub library: PathBuf,
    /// Clips by id (`hrc-task-clips/CollaborativeHammering/0`). Default empty: every clip of
    /// `split`.
    #[serde(default)]
    pub clips: Vec<String>,
    /// The library's clips played when `clips` is empty: `tuning`, `test` or `all`. Default
    /// `tuning`: the held-out clips are played only when asked for.
    #[serde(default = "tuning")]
    pub split: ClipSplit,
    /// Clip time at the episode's start, s. Default 0.
    #[serde(default)]
    pub start_s: f64,
    /// At the clip's end: `hold`, `loop` or `reverse` (backwards to the start, no jump).
    /// Default `reverse`.
    #[serde(default = "reverse")]
    pub end: ClipEnd,
    /// How the clip is laid on the arm (side, low-pass cut-off, elbow weight).
    #[serde(default)]
    pub retarget: crate::retarget::RetargetConfig,
}

/// Which clips of a library.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClipSplit {
    Tuning,
    Test,
    All,
}

fn tuning() -> ClipSplit {
    ClipSplit::Tuning
}
fn reverse() -> ClipEnd {
    ClipEnd::Reverse
}

/// What a recorded clip does at its end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClipEnd {
    /// Stand still in the last frame.
    Hold,
    /// Start again from the first frame (a jump back, unless the clip ends where it began).
    Loop,
    /// Play backwards to the start, then forwards again: no jump.
    Reverse,
}

impl Default for HumanConfig {
    fn default() -> Self {
        Self {
            model: "human_arm".into(),
            look: HumanLook::Flesh,
            base: PoseConfig::default(),
            motions: vec![
                HumanMotionKind::Rest,
                HumanMotionKind::Reach,
                HumanMotionKind::Withdraw,
                HumanMotionKind::Wave,
            ],
            shuffle: false,
            speeds: HumanSpeeds::default(),
            peak_speed_m_s: None,
            duration_scale: None,
            speed_scale: 1.0,
            recorded: None,
        }
    }
}

impl HumanConfig {
    /// The range each generated movement draws its fastest point's peak speed from, m/s:
    /// `peak_speed_m_s` where given, else that of `speeds`.
    #[must_use]
    pub fn peak_speed_range_m_s(&self) -> [f64; 2] {
        self.peak_speed_m_s
            .unwrap_or_else(|| self.speeds.peak_speed_m_s())
    }

    /// The range of the factor each generated transition's duration is multiplied by:
    /// `duration_scale` where given, else that of `speeds`.
    #[must_use]
    pub fn duration_scale_range(&self) -> [f64; 2] {
        self.duration_scale
            .unwrap_or_else(|| self.speeds.duration_scale())
    }
}

/// How fast the generated human moves: two calibrations of the same movements.
///
/// Both draw each movement's duration as before and its fastest point's peak speed from a
/// range; `recorded` also shortens each transition by a factor drawn from
/// [`HumanSpeeds::duration_scale`], which brings its accelerations nearer the recorded ones
/// (to their 99th percentile, not their 99.9th: docs/human.md).
/// `workcell human stats --split tuning --speeds iso13855,recorded` shows both beside the clips.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HumanSpeeds {
    /// Peaks from 1.0 to 2.0 m/s: ISO 13855's approach speed of hands and arms (2.0 m/s,
    /// its clause 6.2) is never exceeded. The assumption the safety filter was tuned under.
    #[default]
    Iso13855,
    /// Faster peaks and shorter transitions, chosen so that the generated wrist's peak speed
    /// reaches the 99.9th percentile of the wrists in the tuning clips of the shipped
    /// recordings (docs/human.md, "The generator beside the recordings").
    Recorded,
}

impl HumanSpeeds {
    /// The top of [`HumanSpeeds::Recorded`]'s peak-speed range, m/s. The range caps the
    /// arm's fastest point, the hand's tip; 7.2 m/s there lets the generated wrist peak at
    /// 4.9 m/s, the Vicon tuning clips' wrist 99.9th percentile (5.0 m/s, `workcell human
    /// stats --split tuning --speeds recorded`).
    pub const RECORDED_PEAK_M_S: f64 = 7.2;
    /// The shortest transition of [`HumanSpeeds::Recorded`], as a fraction of the drawn one:
    /// shorter than this, the peaks stop rising (the speed cap stretches the transition back).
    pub const RECORDED_SHORTEST_DURATION_SCALE: f64 = 0.3;

    /// Range of each movement's peak speed, m/s.
    #[must_use]
    pub fn peak_speed_m_s(self) -> [f64; 2] {
        match self {
            Self::Iso13855 => [1.0, 2.0],
            Self::Recorded => [1.0, Self::RECORDED_PEAK_M_S],
        }
    }

    /// Range of the factor each transition's drawn duration is multiplied by.
    #[must_use]
    pub fn duration_scale(self) -> [f64; 2] {
        match self {
            Self::Iso13855 => [1.0, 1.0],
            Self::Recorded => [Self::RECORDED_SHORTEST_DURATION_SCALE, 1.0],
        }
    }
}

/// A primitive of human arm motion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HumanMotionKind {
    /// Arm hanging, small sway.
    Rest,
    /// Shoulder flexed forward, elbow extending: the hand enters the shared space.
    Reach,
    /// Arm raised, forearm swinging about the elbow.
    Wave,
    /// A quick return to the side.
    Withdraw,
}

/// A static obstacle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClutterConfig {
    /// `box` (a solid box) or `shelf` (an open rack of boards on four posts).
    pub kind: ClutterKind,
    /// Outer size (x, y, z) in metres.
    pub size_m: [f64; 3],
    /// Pose of the box centre (shelf: of its bounding box centre).
    #[serde(default)]
    pub pose: PoseConfig,
    /// Boards of a shelf, bottom and top included. Default 4.
    #[serde(default = "default_boards")]
    pub boards: usize,
}

fn default_boards() -> usize {
    4
}

/// Kinds of clutter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClutterKind {
    Box,
    Shelf,
}

/// A pinhole camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraConfig {
    pub name: String,
    /// Camera centre in the world, m.
    pub eye: [f64; 3],
    /// The point it looks at, m.
    pub target: [f64; 3],
    /// World direction that appears up in the image. Default `[0, 0, 1]`.
    pub up: [f64; 3],
    pub width_px: u32,
    pub height_px: u32,
    /// Vertical field of view, degrees. Default 60.
    pub fov_y_deg: f64,
    /// Frames per second. Default 30.
    pub rate_hz: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            name: "camera".into(),
            eye: [2.0, 0.0, 1.5],
            target: [0.5, 0.0, 0.9],
            up: [0.0, 0.0, 1.0],
            width_px: 640,
            height_px: 480,
            fov_y_deg: 60.0,
            rate_hz: 30.0,
        }
    }
}

impl CameraConfig {
    /// The pinhole camera this configuration describes.
    ///
    /// # Errors
    /// As [`workcell_render::Camera::look_at`].
    pub fn camera(&self) -> Result<workcell_render::Camera, workcell_render::RenderError> {
        workcell_render::Camera::look_at(
            self.eye,
            self.target,
            self.up,
            self.width_px,
            self.height_px,
            self.fov_y_deg,
        )
    }

    /// Focal lengths and principal point `(fx, fy, cx, cy)` in pixels.
    #[must_use]
    pub fn intrinsics(&self) -> (f64, f64, f64, f64) {
        let fy = 0.5 * f64::from(self.height_px) / (0.5 * self.fov_y_deg.to_radians()).tan();
        (
            fy,
            fy,
            0.5 * f64::from(self.width_px),
            0.5 * f64::from(self.height_px),
        )
    }
}

impl Scenario {
    /// Reads and validates a scenario file.
    ///
    /// # Errors
    /// [`SimError::Io`], [`SimError::Parse`] (with TOML's line and column) or
    /// [`SimError::Invalid`] naming the key.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::from_toml(&read_text(path)?, path)
    }

    /// Parses and validates scenario text; `path` names it in errors.
    ///
    /// # Errors
    /// As [`Scenario::from_file`].
    pub fn from_toml(text: &str, path: &Path) -> Result<Self> {
        let scenario: Scenario = parse_toml(text, path)?;
        scenario.validate().map_err(|e| e.in_file(path))?;
        Ok(scenario)
    }

    /// The scenario as TOML text (every default written out).
    #[must_use]
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// Checks ranges that types cannot: positive time step, finite poses, sane sizes.
    ///
    /// # Errors
    /// [`SimError::Invalid`] naming the first bad key.
    pub fn validate(&self) -> Result<()> {
        let bad = |key: &str, message: String| SimError::Invalid {
            path: None,
            key: key.to_string(),
            message,
        };
        let finite = |key: &str, v: &[f64]| -> Result<()> {
            if v.iter().all(|x| x.is_finite()) {
                Ok(())
            } else {
                Err(bad(key, format!("{v:?} has a non-finite value")))
            }
        };
        if !(1e-5..=0.05).contains(&self.time_step_s) {
            return Err(bad(
                "time_step_s",
                format!("{} must be in [1e-5, 0.05] s", self.time_step_s),
            ));
        }
        for (key, n, most) in [
            ("clutter", self.clutter.len(), 1000),
            ("cameras", self.cameras.len(), 64),
            ("human.motions", self.human.motions.len(), 10_000),
        ] {
            if n > most {
                return Err(bad(key, format!("{n} entries, more than {most}")));
            }
        }
        finite("gravity_m_s2", &self.gravity_m_s2)?;
        finite("robot.base.xyz", &self.robot.base.xyz)?;
        finite("robot.base.rpy", &self.robot.base.rpy)?;
        finite("robot.initial_q", &self.robot.initial_q)?;
        finite("human.base.xyz", &self.human.base.xyz)?;
        finite("human.base.rpy", &self.human.base.rpy)?;
        let s = self.human.speed_scale;
        if !(s > 0.0 && s <= 4.0) {
            return Err(bad("human.speed_scale", format!("{s} must be in (0, 4]")));
        }
        let [lo, hi] = self.human.peak_speed_range_m_s();
        if !(lo > 0.0 && lo <= hi && hi <= MAX_HUMAN_PEAK_SPEED_M_S) {
            return Err(bad(
                "human.peak_speed_m_s",
                format!("[{lo}, {hi}] must be a range within (0, {MAX_HUMAN_PEAK_SPEED_M_S}] m/s"),
            ));
        }
        let [lo, hi] = self.human.duration_scale_range();
        if !(lo > 0.0 && lo <= hi && hi <= 1.0) {
            return Err(bad(
                "human.duration_scale",
                format!("[{lo}, {hi}] must be a range within (0, 1]"),
            ));
        }
        if let Some(r) = &self.human.recorded {
            if !(r.start_s.is_finite() && r.start_s >= 0.0) {
                return Err(bad(
                    "human.recorded.start_s",
                    format!("{} must be >= 0", r.start_s),
                ));
            }
            let c = r.retarget.cutoff_hz;
            if !(c.is_finite() && c > 0.0) {
                return Err(bad(
                    "human.recorded.retarget.cutoff_hz",
                    format!("{c} must be > 0"),
                ));
            }
            let w = r.retarget.elbow_weight;
            if !(w.is_finite() && w >= 0.0) {
                return Err(bad(
                    "human.recorded.retarget.elbow_weight",
                    format!("{w} must be >= 0"),
                ));
            }
        }
        let a = self.robot.servo_acceleration_rad_s2;
        if !(a > 0.0 && a.is_finite()) {
            return Err(bad(
                "robot.servo_acceleration_rad_s2",
                format!("{a} must be > 0"),
            ));
        }
        let gains = [self.robot.stiffness, self.robot.damping];
        if !gains.iter().all(|g| g.is_finite() && *g >= 0.0) {
            return Err(bad(
                "robot.stiffness",
                "stiffness and damping must be finite and >= 0".into(),
            ));
        }
        match &self.robot.motion {
            RobotMotionConfig::Hold => {}
            RobotMotionConfig::Random {
                speed_scale,
                acceleration_rad_s2,
                margin_rad,
                min_height_m,
                clearance_m,
                waypoints,
            } => {
                check_speed(*speed_scale, *acceleration_rad_s2)
                    .map_err(|m| bad("robot.motion", m))?;
                finite("robot.motion.min_height_m", &[*min_height_m])?;
                if !(clearance_m.is_finite() && *clearance_m >= 0.0) {
                    return Err(bad(
                        "robot.motion.clearance_m",
                        format!("{clearance_m} must be >= 0"),
                    ));
                }
                if !(margin_rad.is_finite() && *margin_rad >= 0.0) {
                    return Err(bad(
                        "robot.motion.margin_rad",
                        format!("{margin_rad} must be >= 0"),
                    ));
                }
                if !(2..=MAX_WAYPOINTS).contains(waypoints) {
                    return Err(bad(
                        "robot.motion.waypoints",
                        format!("{waypoints} is not in 2..={MAX_WAYPOINTS}"),
                    ));
                }
            }
            RobotMotionConfig::PickAndPlace {
                waypoints,
                dwell_s,
                speed_scale,
                acceleration_rad_s2,
            } => {
                check_speed(*speed_scale, *acceleration_rad_s2)
                    .map_err(|m| bad("robot.motion", m))?;
                if !(2..=MAX_WAYPOINTS).contains(&waypoints.len()) {
                    return Err(bad(
                        "robot.motion.waypoints",
                        format!(
                            "{} waypoints is not in 2..={MAX_WAYPOINTS}",
                            waypoints.len()
                        ),
                    ));
                }
                for w in waypoints {
                    finite("robot.motion.waypoints", w)?;
                }
                if !(dwell_s.is_finite() && *dwell_s >= 0.0) {
                    return Err(bad(
                        "robot.motion.dwell_s",
                        format!("{dwell_s} must be >= 0"),
                    ));
                }
            }
        }
        if self.human.motions.is_empty() {
            return Err(bad("human.motions", "list at least one motion".into()));
        }
        for (i, c) in self.clutter.iter().enumerate() {
            let key = format!("clutter[{i}]");
            finite(&key, &c.pose.xyz)?;
            finite(&key, &c.pose.rpy)?;
            if !c.size_m.iter().all(|s| s.is_finite() && *s > 0.0) {
                return Err(bad(
                    &format!("{key}.size_m"),
                    format!("{:?} must be > 0", c.size_m),
                ));
            }
            if c.kind == ClutterKind::Shelf && !(2..=MAX_BOARDS).contains(&c.boards) {
                return Err(bad(
                    &format!("{key}.boards"),
                    format!("a shelf has 2..={MAX_BOARDS} boards, not {}", c.boards),
                ));
            }
        }
        for (i, c) in self.cameras.iter().enumerate() {
            let key = format!("cameras[{i}]");
            finite(&key, &c.eye)?;
            finite(&key, &c.target)?;
            finite(&key, &c.up)?;
            if c.width_px == 0 || c.height_px == 0 || c.width_px > 8192 || c.height_px > 8192 {
                return Err(bad(&key, "image size must be 1..=8192 pixels".into()));
            }
            if !(c.fov_y_deg > 1.0 && c.fov_y_deg < 179.0) {
                return Err(bad(
                    &format!("{key}.fov_y_deg"),
                    format!("{} must be in (1, 179)", c.fov_y_deg),
                ));
            }
            if !(c.rate_hz > 0.0 && c.rate_hz.is_finite()) {
                return Err(bad(&format!("{key}.rate_hz"), "must be > 0".into()));
            }
            let forward: Vec<f64> = (0..3).map(|k| c.target[k] - c.eye[k]).collect();
            let cross = [
                forward[1] * c.up[2] - forward[2] * c.up[1],
                forward[2] * c.up[0] - forward[0] * c.up[2],
                forward[0] * c.up[1] - forward[1] * c.up[0],
            ];
            if cross.iter().map(|x| x * x).sum::<f64>() < 1e-12 {
                return Err(bad(&key, "eye, target and up must not be collinear".into()));
            }
        }
        Ok(())
    }

    /// Resolves a model name given in the scenario: a catalogue name stays as is, a path is
    /// taken relative to the scenario's folder.
    #[must_use]
    pub fn resolve_model_path(model: &str, scenario_path: &Path) -> String {
        let candidate = PathBuf::from(model);
        if model.ends_with(".urdf")
            && candidate.is_relative()
            && let Some(dir) = scenario_path.parent()
        {
            return dir.join(candidate).to_string_lossy().into_owned();
        }
        model.to_string()
    }

    /// Puts `model` in the human's place: a catalogue name as it is, a URDF relative to
    /// `file` (the configuration that names it) made absolute, since the cell resolves its
    /// own model against the scenario's folder.
    pub fn set_human_model(&mut self, model: &str, file: &Path) {
        let resolved = Self::resolve_model_path(model, file);
        self.human.model = if resolved.ends_with(".urdf") {
            std::path::absolute(&resolved).map_or(resolved, |p| p.to_string_lossy().into_owned())
        } else {
            resolved
        };
    }
}

fn check_speed(speed_scale: f64, acceleration: f64) -> Result<(), String> {
    if !(speed_scale > 0.0 && speed_scale <= 1.0) {
        return Err(format!("speed_scale {speed_scale} must be in (0, 1]"));
    }
    if !(acceleration > 0.0 && acceleration.is_finite()) {
        return Err(format!("acceleration_rad_s2 {acceleration} must be > 0"));
    }
    Ok(())
}

/// Reads a configuration file: a regular file of bounded size, in UTF-8; errors name it.
pub(crate) fn read_text(path: &Path) -> Result<String> {
    read_text_file(path, MAX_CONFIG_BYTES).map_err(|source| SimError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Parses TOML into `T`; errors carry TOML's line and column and name `path`.
pub(crate) fn parse_toml<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> Result<T> {
    toml::from_str(text).map_err(|e| SimError::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}
