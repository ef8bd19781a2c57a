//! The `[perception]` table: its `kind` chooses one of three types, each with only the keys
//! that kind reads ([`PerceptionConfig`]).

use serde::{Deserialize, Serialize};

use super::ground_truth::foresight_name;
use super::procnet::ProcNetCamera;
use super::{CameraFailure, Foresight, GroundTruth, HumanPerception, NoisyCamera};
use workcell_sim::{CellModel, Scenario};

/// Settings of the perception model: the `[perception]` table of an evaluation file. Its
/// `kind` key (`ground_truth`, `noisy` or `procnet`; left out, `noisy`) chooses the type the
/// other keys belong to; a key of another kind is refused with the kind it belongs to.
/// Default: the noisy camera with its defaults.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum PerceptionConfig {
    /// Exact human poses every tick.
    GroundTruth(GroundTruthConfig),
    /// A camera model: the true pose with noise, dropped frames and latency.
    Noisy(NoisyConfig),
    /// The cell's camera rendered, ProcNet and the articulated fit.
    Procnet(ProcNetConfig),
}

/// `kind = "ground_truth"`: the true human, every tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GroundTruthConfig {
    /// An oracle that also tells the filter where each arm part truly will be over this many
    /// seconds ahead (six instants, evenly spaced): what a perfect predictor of the human
    /// would give, for measuring what bounds the filter; no camera can have it. Default 0
    /// (off).
    pub foresight_s: f64,
    /// Nothing is delivered from this time on, s (perception switched off mid-episode): no
    /// human is reported and the filter brakes. Left out, never.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera_fails_at_s: Option<f64>,
}

/// `kind = "noisy"`: ground truth seen through a camera with Gaussian noise, dropped frames
/// and latency.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoisyConfig {
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
    /// The camera delivers nothing from this time on, s (a failed camera): no human is
    /// reported and the filter brakes. Left out, never.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera_fails_at_s: Option<f64>,
}

/// `kind = "procnet"`: the cell's camera (at its own `rate_hz`) rendered, ProcNet's masks of
/// the arm's parts and the articulated render-and-compare fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ProcNetConfig {
    /// The network's weights, relative to the evaluation file. Default (none given): the
    /// shipped ones of this source tree for the camera and the cell's human
    /// (`procnet::weights::shipped_for`): where `depth`,
    /// `procnet/weights/procnet-depth-human.safetensors` for the whole body and
    /// `procnet-depth.safetensors` for the paper's arm (`human_arm`); else
    /// `procnet-cpu.safetensors`. The evaluation file fills it in when it is read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weights: Option<std::path::PathBuf>,
    /// The cell's camera by name; empty for the first. Default empty.
    pub camera: String,
    /// `network` (ProcNet's masks of the arm's parts), `ground_truth` (each part's pixels
    /// in the rendered frame: the articulated fit alone) or `true_pose` (no masks and no
    /// fit: the human's true joints at each frame's exposure, through the same latency and
    /// velocity; the bound of a perfect network and fit at this camera). Default `network`.
    pub masks: MaskKind,
    /// The camera also measures depth (RGB-D), and the fit uses it. Default false.
    pub depth: bool,
    /// The fraction of the forearm's pixels that a black disc hides in every frame (the
    /// paper's artificial occluders, in the loop; 0.66 and above is its heavy occlusion).
    /// Default 0.
    pub occlusion: f64,
    /// On a human whose trunk turns, leans and walks (`human`), fit the trunk to the torso's
    /// mask and depth before the arm (`ArmFitConfig::fit_trunk`); false holds the trunk
    /// upright where the cell puts the person. Default: what the masks' calibration was
    /// measured with (`workcell_perception::pose::Calibration::fit`), else false. A value
    /// other than the calibration's runs a fit its bound was not measured for (warned of).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_trunk: Option<bool>,
    /// The arm's climb also starts from the best fit's forearm turned end for end
    /// (`ArmFitConfig::reversed_start`). Default: the masks' calibration's, else false; as
    /// `fit_trunk`, another value than the calibration's is warned of.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reversed_start: Option<bool>,
    /// With depth, the arm's climb also starts from where the forearm's measured points put
    /// it (`ArmFitConfig::depth_start`). Default: the masks' calibration's, else false.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_start: Option<bool>,
    /// The global search runs beside the track when its best gain is below this, 0 to 1
    /// (`ArmFitConfig::search_below_gain`). Default: the masks' calibration's, else 0.55.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search_below_gain: Option<f64>,
    /// The factor on the fit's curvature uncertainty (`ArmFitConfig::uncertainty_scale`),
    /// in place of the one calibrated for the masks and depth chosen (the calibration file
    /// beside the weights, `workcell_perception::pose::Calibration::of_weights`), which is
    /// used when the key is left out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_scale: Option<f64>,
    /// The uncertainty's floor, m (`ArmFitConfig::uncertainty_floor_m`), in place of the
    /// calibrated one (left out: the calibrated one). The floors where the depth image shows
    /// the forearm hidden, and those of a fit that kept its track, are the calibrated ones,
    /// never below this.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty_floor_m: Option<f64>,
    /// Time from exposure to the estimate being available, s. Default 0.05.
    pub latency_s: f64,
    /// Bound on the human's acceleration used to grow the uncertainty of an ageing estimate,
    /// m/s^2. Default 10.
    pub human_acceleration_m_s2: f64,
    /// The joints' velocity is the least-squares slope through the last this many fits (2 to
    /// 8) within [`super::procnet::MAX_AGE_S`] of the newest: it carries the estimate over its
    /// age and is the velocity the filter sees. 2 is the difference of the last two; 3 cut
    /// the closed loop's perception error on the recorded tuning clips, but not on the
    /// held-out ones (docs/perception.md, "The joints' velocity through three fits").
    /// Default 2.
    pub velocity_fits: usize,
    /// The trunk held where the true human's is at each frame, the fit's trunk stage off:
    /// an oracle, for the bound of a perfect trunk (the arm still fitted to the masks).
    /// Default false.
    pub true_trunk: bool,
    /// The two-armed human's left arm fitted too, after the right arm on the right's trunk,
    /// with the perfect segmenter's masks (`masks = "ground_truth"`; the shipped networks
    /// have no left arm's classes): its parts join the estimate where its fit finds a pose.
    /// Default false: from the cell's camera the left arm is mostly hidden behind the body
    /// and its fit is not yet to be trusted (docs/human.md, "Both arms").
    pub fit_left_arm: bool,
    /// The two-armed human's left arm, where no fit saw it, guarded over its reach: each of
    /// its parts a sphere about the shoulder that the fitted trunk places. Default false (it
    /// is left out of the estimate, and the report counts its approaches): from the cell's
    /// camera the arm is mostly hidden, and its reach covers the robot's task, which then
    /// finished in none of 30 generator episodes (docs/human.md, "Both arms").
    pub guard_unseen_left_arm: bool,
    /// The tracked region of interest holds the hand's far end as well as the shoulder,
    /// elbow and wrist, and a frame whose forearm or hand reached its edge sends the next one
    /// to the workspace (`ArmFitConfig::hand_region`; docs/perception.md, "The region that
    /// cut the arm"). Default: the masks' calibration's, else false; as `fit_trunk`, another
    /// value than the calibration's is warned of.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hand_region: Option<bool>,
    /// The fit renders each part's convex hull instead of its mesh
    /// (`ArmFitConfig::hull_outlines`). Default: the masks' calibration's, else false; as
    /// `fit_trunk`, another value than the calibration's is warned of.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hull_outlines: Option<bool>,
    /// The trunk's stage runs at `1 / trunk_downsample` of the masks' resolution, 1 to 4
    /// (`ArmFitConfig::trunk_downsample`). Default: the masks' calibration's, else 1; as
    /// `fit_trunk`, another value than the calibration's is warned of.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trunk_downsample: Option<u32>,
    /// The tracker reads every `frame_stride`-th of the camera's frames (1 to 8): the
    /// network and the fit run at the camera's rate divided by this, the estimate ages
    /// between their frames as it does between any two (the joints' velocity, the bound
    /// growing with `human_acceleration_m_s2`). For a machine that cannot run them at the
    /// camera's rate (docs/perception.md, "Perception in the camera's time").
    /// Default 1.
    pub frame_stride: usize,
    /// The fit's global search runs on at most one in `search_interval` of the tracker's
    /// frames (1 to 8; `ArmFitConfig::search_interval`): a person lost for a while costs the
    /// loop a search (six times a tracked fit's renders) every `search_interval` frames, not
    /// every frame; the frames between climb their track alone and take the bound of a
    /// search. Default 1.
    pub search_interval: usize,
    /// The camera delivers nothing from this time on, s (a failed camera): the last estimate
    /// ages out ([`super::procnet::MAX_AGE_S`]) and the filter then brakes. Left out, never.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera_fails_at_s: Option<f64>,
}

/// Where the `procnet` perception's masks of the arm come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskKind {
    Network,
    GroundTruth,
    /// The true joints themselves, at each frame's exposure: an oracle for measuring what
    /// the camera's rate, latency and the joints' velocity from successive frames leave.
    TruePose,
}

/// Which perception model: the `kind` of a `[perception]` table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PerceptionKind {
    GroundTruth,
    Noisy,
    Procnet,
}

impl PerceptionKind {
    pub const ALL: [Self; 3] = [Self::GroundTruth, Self::Noisy, Self::Procnet];

    /// As written in `kind`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::GroundTruth => "ground_truth",
            Self::Noisy => "noisy",
            Self::Procnet => "procnet",
        }
    }

    /// The keys a table of this kind takes besides `kind` (a test holds them to the types).
    #[must_use]
    pub fn keys(self) -> &'static [&'static str] {
        match self {
            Self::GroundTruth => &["foresight_s", "camera_fails_at_s"],
            Self::Noisy => &[
                "rate_hz",
                "position_noise_m",
                "velocity_noise_m_s",
                "dropout",
                "latency_s",
                "human_acceleration_m_s2",
                "confidence_sigmas",
                "camera_fails_at_s",
            ],
            Self::Procnet => &[
                "weights",
                "camera",
                "masks",
                "depth",
                "occlusion",
                "fit_trunk",
                "reversed_start",
                "depth_start",
                "search_below_gain",
                "uncertainty_scale",
                "uncertainty_floor_m",
                "latency_s",
                "human_acceleration_m_s2",
                "velocity_fits",
                "true_trunk",
                "fit_left_arm",
                "guard_unseen_left_arm",
                "hand_region",
                "hull_outlines",
                "trunk_downsample",
                "frame_stride",
                "search_interval",
                "camera_fails_at_s",
            ],
        }
    }

    fn of_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
}

impl Default for PerceptionConfig {
    fn default() -> Self {
        Self::Noisy(NoisyConfig::default())
    }
}

impl Default for GroundTruthConfig {
    fn default() -> Self {
        Self {
            foresight_s: 0.0,
            camera_fails_at_s: None,
        }
    }
}

impl Default for NoisyConfig {
    fn default() -> Self {
        Self {
            rate_hz: 30.0,
            position_noise_m: 0.01,
            velocity_noise_m_s: 0.05,
            dropout: 0.1,
            latency_s: 0.05,
            human_acceleration_m_s2: 10.0,
            confidence_sigmas: 4.0,
            camera_fails_at_s: None,
        }
    }
}

impl Default for ProcNetConfig {
    fn default() -> Self {
        Self {
            weights: None,
            camera: String::new(),
            masks: MaskKind::Network,
            depth: false,
            occlusion: 0.0,
            fit_trunk: None,
            reversed_start: None,
            depth_start: None,
            search_below_gain: None,
            uncertainty_scale: None,
            uncertainty_floor_m: None,
            latency_s: 0.05,
            human_acceleration_m_s2: 10.0,
            velocity_fits: 2,
            true_trunk: false,
            fit_left_arm: false,
            guard_unseen_left_arm: false,
            hand_region: None,
            hull_outlines: None,
            trunk_downsample: None,
            frame_stride: 1,
            search_interval: 1,
            camera_fails_at_s: None,
        }
    }
}

/// `kind` read first (left out: `noisy`), then the rest of the table as that kind's type; a
/// key that belongs to another kind is named with its kind rather than called unknown.
impl<'de> Deserialize<'de> for PerceptionConfig {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error as _;
        let mut table = toml::Table::deserialize(deserializer)?;
        let kind = match table.remove("kind") {
            None => PerceptionKind::Noisy,
            Some(toml::Value::String(name)) => PerceptionKind::of_name(&name).ok_or_else(|| {
                D::Error::custom(format!(
                    "perception.kind: unknown kind {name:?} (ground_truth, noisy or procnet)"
                ))
            })?,
            Some(other) => {
                return Err(D::Error::custom(format!(
                    "perception.kind: a name (ground_truth, noisy or procnet), not {other}"
                )));
            }
        };
        if let Some(key) = table.keys().find(|k| !kind.keys().contains(&k.as_str())) {
            let owners: Vec<&str> = PerceptionKind::ALL
                .into_iter()
                .filter(|k| k.keys().contains(&key.as_str()))
                .map(PerceptionKind::name)
                .collect();
            if !owners.is_empty() {
                return Err(D::Error::custom(format!(
                    "perception.{key}: a key of the {} perception, not of {} (kind = \"{}\")",
                    owners.join(" and the "),
                    kind.name(),
                    kind.name()
                )));
            }
        }
        let rest = toml::Value::Table(table);
        let parsed = match kind {
            PerceptionKind::GroundTruth => rest.try_into().map(Self::GroundTruth),
            PerceptionKind::Noisy => rest.try_into().map(Self::Noisy),
            PerceptionKind::Procnet => rest.try_into().map(Self::Procnet),
        };
        parsed.map_err(|e| D::Error::custom(format!("[perception] of kind {}: {e}", kind.name())))
    }
}

/// For a command line's choice of perception over the file's: the `[perception]` table of
/// `document` becomes one of `kind`, keeping the keys `kind` also takes (latency, the human's
/// acceleration, a camera failure) and dropping the others. Returns the dropped keys, for a
/// note; none where the file already has that kind.
pub fn switch_perception_kind(document: &mut toml::Table, kind: PerceptionKind) -> Vec<String> {
    let Some(table) = document
        .entry("perception")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        .as_table_mut()
    else {
        return Vec::new(); // not a table: refused when the file is read
    };
    let current = match table.get("kind") {
        None => Some(PerceptionKind::Noisy),
        Some(toml::Value::String(name)) => PerceptionKind::of_name(name),
        Some(_) => None,
    };
    let mut dropped = Vec::new();
    if current != Some(kind) {
        table.retain(|key, _| {
            let keep = key == "kind" || kind.keys().contains(&key);
            if !keep {
                dropped.push(format!("perception.{key}"));
            }
            keep
        });
    }
    table.insert("kind".into(), toml::Value::String(kind.name().into()));
    dropped
}

/// How an estimate's bound grows with its age, for the cameras that have a frame rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AgeingBound {
    pub rate_hz: f64,
    pub latency_s: f64,
    pub human_acceleration_m_s2: f64,
}

impl AgeingBound {
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
    #[must_use]
    pub fn held_age_s(&self, age_s: f64) -> f64 {
        age_s.max(self.latency_s + 1.0 / self.rate_hz)
    }
}

impl NoisyConfig {
    /// How this camera's bound ages.
    #[must_use]
    pub fn ageing(&self) -> AgeingBound {
        AgeingBound {
            rate_hz: self.rate_hz,
            latency_s: self.latency_s,
            human_acceleration_m_s2: self.human_acceleration_m_s2,
        }
    }

    /// The noisy camera's uncertainty `age_s` after exposure, m: `radius_sigmas` times the
    /// sigma of an end point's 3-D error per axis (position noise plus velocity noise times
    /// the age, independent Gaussians: sqrt(sigma_p^2 + (sigma_v age)^2)), plus the human's
    /// acceleration over the age; held until the next frame is due as in
    /// [`AgeingBound::aged_uncertainty`]. The camera passes
    /// `sphere_radius_for_sigmas(confidence_sigmas)`, computed once.
    #[must_use]
    pub fn uncertainty(&self, radius_sigmas: f64, age_s: f64) -> f64 {
        let age = self.ageing().held_age_s(age_s);
        let sigma = self.position_noise_m.hypot(self.velocity_noise_m_s * age);
        radius_sigmas * sigma + 0.5 * self.human_acceleration_m_s2 * age * age
    }
}

impl ProcNetConfig {
    /// The network's weights: `weights`, or the shipped ones for the camera.
    #[must_use]
    pub fn weights_path(&self) -> std::path::PathBuf {
        self.weights
            .clone()
            .unwrap_or_else(|| crate::procnet::weights::shipped_path(self.depth))
    }

    /// How the bound ages for a camera at `rate_hz`.
    #[must_use]
    pub fn ageing(&self, rate_hz: f64) -> AgeingBound {
        AgeingBound {
            rate_hz,
            latency_s: self.latency_s,
            human_acceleration_m_s2: self.human_acceleration_m_s2,
        }
    }

    /// The report's name of this perception, without loading anything.
    #[must_use]
    pub fn describe(&self) -> String {
        let velocity = if self.velocity_fits == ProcNetConfig::default().velocity_fits {
            String::new()
        } else {
            format!(", velocity through the last {} fits", self.velocity_fits)
        };
        let latency_ms = self.latency_s * 1e3;
        let stride = match self.frame_stride {
            1 => String::new(),
            k => format!(", 1 in {k} camera frames read"),
        };
        let search = match self.search_interval {
            1 => String::new(),
            k => format!(", the global search on 1 in {k} frames at most"),
        };
        let masks = match self.masks {
            // The weights' own header says which network they hold (ProcNet or the
            // feed-forward baseline); an unreadable file fails when it is loaded.
            MaskKind::Network => format!(
                "{} ({})",
                crate::procnet::weights::read_config(&self.weights_path())
                    .map_or("ProcNet", |c| c.model_name()),
                self.weights_path().display()
            ),
            MaskKind::GroundTruth => "ground-truth arm masks".to_string(),
            // No masks and no fit: nothing else of the table applies.
            MaskKind::TruePose => {
                return format!(
                    "the true pose at each frame (an oracle), latency {latency_ms:.0} ms{velocity}{stride}"
                );
            }
        };
        format!(
            "{masks} + articulated render-and-compare{}{}, latency {latency_ms:.0} ms{velocity}{stride}{search}{}{}{}{}{}",
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
            if self.true_trunk {
                ", the true trunk (an oracle)"
            } else {
                ""
            },
            match (self.fit_left_arm, self.guard_unseen_left_arm) {
                (true, true) => ", the left arm fitted too, its reach where unseen",
                (true, false) => ", the left arm fitted too",
                (false, true) => ", the left arm's reach",
                (false, false) => "",
            },
            match self.hand_region {
                Some(true) => ", the region holds the hand",
                Some(false) => ", the region around shoulder, elbow and wrist",
                None => "",
            },
            match self.hull_outlines {
                Some(true) => ", the parts' hulls",
                Some(false) => ", the parts' meshes",
                None => "",
            },
            match self.trunk_downsample {
                Some(k) => format!(", the trunk's stage at 1/{k} of the masks' resolution"),
                None => String::new(),
            }
        )
    }
}

/// A range check whose error names the key `perception.<key>`.
fn check(key: &str, v: f64, ok: bool) -> crate::Result<()> {
    if v.is_finite() && ok {
        Ok(())
    } else {
        Err(crate::Error::config(
            format!("perception.{key}"),
            format!("out of range: {v}"),
        ))
    }
}

/// An optional key: left out, its default; given, a value >= 0 (the -1 that once stood for
/// "left out" is refused, not taken as a value).
fn check_optional(key: &str, v: Option<f64>) -> crate::Result<()> {
    match v {
        Some(v) if !(v.is_finite() && v >= 0.0) => Err(crate::Error::config(
            format!("perception.{key}"),
            format!("out of range: {v} (>= 0; leave the key out for the default)"),
        )),
        _ => Ok(()),
    }
}

impl PerceptionConfig {
    /// The kind of this table.
    #[must_use]
    pub fn kind(&self) -> PerceptionKind {
        match self {
            Self::GroundTruth(_) => PerceptionKind::GroundTruth,
            Self::Noisy(_) => PerceptionKind::Noisy,
            Self::Procnet(_) => PerceptionKind::Procnet,
        }
    }

    /// When the camera stops delivering, if it does.
    #[must_use]
    pub fn camera_fails_at_s(&self) -> Option<f64> {
        match self {
            Self::GroundTruth(c) => c.camera_fails_at_s,
            Self::Noisy(c) => c.camera_fails_at_s,
            Self::Procnet(c) => c.camera_fails_at_s,
        }
    }

    /// The bound on the human's acceleration an ageing estimate assumes, m/s^2; none for
    /// ground truth, which does not age.
    #[must_use]
    pub fn human_acceleration_m_s2(&self) -> Option<f64> {
        match self {
            Self::GroundTruth(_) => None,
            Self::Noisy(c) => Some(c.human_acceleration_m_s2),
            Self::Procnet(c) => Some(c.human_acceleration_m_s2),
        }
    }

    /// Checks ranges; the error names the key.
    ///
    /// # Errors
    /// [`crate::Error::Config`] with the key `perception.<key>`.
    pub fn validate(&self) -> crate::Result<()> {
        check_optional("camera_fails_at_s", self.camera_fails_at_s())?;
        match self {
            Self::GroundTruth(c) => check("foresight_s", c.foresight_s, c.foresight_s >= 0.0),
            Self::Noisy(c) => {
                check("rate_hz", c.rate_hz, c.rate_hz > 0.0)?;
                check(
                    "position_noise_m",
                    c.position_noise_m,
                    c.position_noise_m >= 0.0,
                )?;
                check(
                    "velocity_noise_m_s",
                    c.velocity_noise_m_s,
                    c.velocity_noise_m_s >= 0.0,
                )?;
                check("dropout", c.dropout, (0.0..1.0).contains(&c.dropout))?;
                check("latency_s", c.latency_s, c.latency_s >= 0.0)?;
                check(
                    "human_acceleration_m_s2",
                    c.human_acceleration_m_s2,
                    c.human_acceleration_m_s2 >= 0.0,
                )?;
                check(
                    "confidence_sigmas",
                    c.confidence_sigmas,
                    c.confidence_sigmas >= 0.0,
                )
            }
            Self::Procnet(c) => {
                check("occlusion", c.occlusion, (0.0..1.0).contains(&c.occlusion))?;
                check("latency_s", c.latency_s, c.latency_s >= 0.0)?;
                check(
                    "human_acceleration_m_s2",
                    c.human_acceleration_m_s2,
                    c.human_acceleration_m_s2 >= 0.0,
                )?;
                if !(2..=8).contains(&c.velocity_fits) {
                    return Err(crate::Error::config(
                        "perception.velocity_fits",
                        format!("out of range: {} (2 to 8)", c.velocity_fits),
                    ));
                }
                if let Some(g) = c.search_below_gain {
                    check("search_below_gain", g, (0.0..=1.0).contains(&g))?;
                }
                if let Some(k) = c.trunk_downsample
                    && !(1..=4).contains(&k)
                {
                    return Err(crate::Error::config(
                        "perception.trunk_downsample",
                        format!("out of range: {k} (1 to 4)"),
                    ));
                }
                if !(1..=8).contains(&c.frame_stride) {
                    return Err(crate::Error::config(
                        "perception.frame_stride",
                        format!("out of range: {} (1 to 8)", c.frame_stride),
                    ));
                }
                if !(1..=8).contains(&c.search_interval) {
                    return Err(crate::Error::config(
                        "perception.search_interval",
                        format!("out of range: {} (1 to 8)", c.search_interval),
                    ));
                }
                check_optional("uncertainty_scale", c.uncertainty_scale)?;
                check_optional("uncertainty_floor_m", c.uncertainty_floor_m)
            }
        }
    }

    /// The perception this configuration describes, seeded, for the cell `model` built from
    /// `scenario`.
    ///
    /// # Errors
    /// For `procnet`: no such camera, weights that do not load, a human without a forearm.
    pub fn build(
        &self,
        seed: u64,
        scenario: &Scenario,
        model: &CellModel,
    ) -> crate::error::Result<Box<dyn HumanPerception>> {
        let inner: Box<dyn HumanPerception> = match self {
            Self::GroundTruth(c) if c.foresight_s > 0.0 => {
                Box::new(Foresight::new(c.foresight_s, model)?)
            }
            Self::GroundTruth(_) => Box::new(GroundTruth),
            Self::Noisy(c) => Box::new(NoisyCamera::new(c.clone(), seed)),
            // It ages its last estimate out itself when its camera fails.
            Self::Procnet(c) => return Ok(Box::new(ProcNetCamera::new(c, scenario, model)?)),
        };
        Ok(if let Some(at_s) = self.camera_fails_at_s() {
            Box::new(CameraFailure { inner, at_s })
        } else {
            inner
        })
    }

    /// A short description for reports, without building anything.
    #[must_use]
    pub fn describe(&self) -> String {
        let base = match self {
            Self::GroundTruth(c) if c.foresight_s > 0.0 => foresight_name(c.foresight_s),
            Self::GroundTruth(_) => GroundTruth.name(),
            Self::Noisy(c) => NoisyCamera::new(c.clone(), 0).name(),
            Self::Procnet(c) => c.describe(),
        };
        if let Some(at_s) = self.camera_fails_at_s() {
            format!("{base}, failing at {at_s} s")
        } else {
            base
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every key a kind's type writes (with its optional keys given) is one of the keys the
    /// kind is said to take, and the other way round: the list the table's reader and
    /// `--perception`'s switch use is the types' own.
    #[test]
    fn each_kind_lists_the_keys_of_its_type() {
        let tables = [
            (
                PerceptionKind::GroundTruth,
                toml::Table::try_from(GroundTruthConfig {
                    camera_fails_at_s: Some(1.0),
                    ..GroundTruthConfig::default()
                }),
            ),
            (
                PerceptionKind::Noisy,
                toml::Table::try_from(NoisyConfig {
                    camera_fails_at_s: Some(1.0),
                    ..NoisyConfig::default()
                }),
            ),
            (
                PerceptionKind::Procnet,
                toml::Table::try_from(ProcNetConfig {
                    weights: Some("w.safetensors".into()),
                    fit_trunk: Some(true),
                    reversed_start: Some(true),
                    depth_start: Some(true),
                    search_below_gain: Some(0.7),
                    hand_region: Some(true),
                    hull_outlines: Some(true),
                    trunk_downsample: Some(2),
                    uncertainty_scale: Some(1.0),
                    uncertainty_floor_m: Some(0.01),
                    camera_fails_at_s: Some(1.0),
                    ..ProcNetConfig::default()
                }),
            ),
        ];
        for (kind, table) in tables {
            let mut written: Vec<&str> = Vec::new();
            let table = table.expect("serialises");
            written.extend(table.keys().map(String::as_str));
            let mut listed = kind.keys().to_vec();
            written.sort_unstable();
            listed.sort_unstable();
            assert_eq!(written, listed, "{kind:?}");
        }
    }

    fn parse(text: &str) -> Result<PerceptionConfig, toml::de::Error> {
        #[derive(Deserialize)]
        struct File {
            perception: PerceptionConfig,
        }
        toml::from_str::<File>(text).map(|f| f.perception)
    }

    /// A table reads as the type of its kind; left out, the kind is the noisy camera; a key
    /// of another kind is named with its kind, an unknown one as unknown; every value round
    /// trips through the TOML the configuration writes.
    #[test]
    fn a_table_reads_as_the_type_of_its_kind() {
        assert_eq!(
            parse("[perception]\ndropout = 0.2\n").expect("noisy"),
            PerceptionConfig::Noisy(NoisyConfig {
                dropout: 0.2,
                ..NoisyConfig::default()
            })
        );
        assert_eq!(
            parse("[perception]\nkind = \"procnet\"\ndepth = true\n").expect("procnet"),
            PerceptionConfig::Procnet(ProcNetConfig {
                depth: true,
                ..ProcNetConfig::default()
            })
        );
        let wrong = parse("[perception]\nkind = \"noisy\"\nforesight_s = 0.5\n")
            .expect_err("foresight is ground truth's")
            .to_string();
        assert!(
            wrong.contains("perception.foresight_s: a key of the ground_truth perception"),
            "{wrong}"
        );
        let shared = parse("[perception]\nkind = \"ground_truth\"\nlatency_s = 0.1\n")
            .expect_err("latency is the cameras'")
            .to_string();
        assert!(
            shared.contains("a key of the noisy and the procnet perception"),
            "{shared}"
        );
        let unknown = parse("[perception]\nkind = \"procnet\"\ndepht = true\n")
            .expect_err("misspelt")
            .to_string();
        assert!(unknown.contains("unknown field `depht`"), "{unknown}");
        let kind = parse("[perception]\nkind = \"lidar\"\n").expect_err("no such kind");
        assert!(
            kind.to_string().contains("unknown kind \"lidar\""),
            "{kind}"
        );
        for config in [
            PerceptionConfig::GroundTruth(GroundTruthConfig {
                foresight_s: 0.3,
                camera_fails_at_s: Some(2.0),
            }),
            PerceptionConfig::default(),
            PerceptionConfig::Procnet(ProcNetConfig {
                weights: Some("w.safetensors".into()),
                masks: MaskKind::GroundTruth,
                uncertainty_floor_m: Some(0.02),
                ..ProcNetConfig::default()
            }),
        ] {
            let mut document = toml::Table::new();
            document.insert(
                "perception".into(),
                toml::Value::try_from(&config).expect("serialises"),
            );
            let text = toml::to_string(&document).expect("serialises");
            assert_eq!(parse(&text).expect("reads back"), config, "{text}");
        }
    }

    /// `velocity_fits` takes 2 to 8 fits; out of that, the check names the key.
    #[test]
    fn velocity_fits_is_checked() {
        for (n, ok) in [(1, false), (2, true), (3, true), (8, true), (9, false)] {
            let config = parse(&format!(
                "[perception]\nkind = \"procnet\"\nvelocity_fits = {n}\n"
            ))
            .expect("reads");
            let checked = config.validate();
            assert_eq!(checked.is_ok(), ok, "{n}: {checked:?}");
            if let Err(e) = checked {
                assert!(e.to_string().contains("perception.velocity_fits"), "{e}");
            }
        }
    }

    /// The fit's search threshold is a gain, 0 to 1; the starts are booleans.
    #[test]
    fn the_fits_settings_are_checked() {
        for (g, ok) in [
            ("-0.1", false),
            ("0.0", true),
            ("0.7", true),
            ("1.0", true),
            ("1.5", false),
            ("nan", false),
        ] {
            let config = parse(&format!(
                "[perception]\nkind = \"procnet\"\nsearch_below_gain = {g}\ndepth_start = true\nreversed_start = false\n"
            ))
            .expect("reads");
            let checked = config.validate();
            assert_eq!(checked.is_ok(), ok, "{g}: {checked:?}");
            if let Err(e) = checked {
                assert!(
                    e.to_string().contains("perception.search_below_gain"),
                    "{e}"
                );
            }
        }
        assert!(parse("[perception]\nkind = \"procnet\"\ndepth_start = 1\n").is_err());
    }

    /// `--perception KIND` keeps the keys the new kind also takes and names the ones it
    /// drops; the same kind drops nothing.
    #[test]
    fn switching_kind_keeps_the_shared_keys() {
        let mut document: toml::Table =
            toml::from_str("[perception]\nkind = \"procnet\"\ndepth = true\nlatency_s = 0.08\n")
                .expect("toml");
        let mut same = document.clone();
        assert!(switch_perception_kind(&mut same, PerceptionKind::Procnet).is_empty());
        assert_eq!(same, document);
        let dropped = switch_perception_kind(&mut document, PerceptionKind::Noisy);
        assert_eq!(dropped, ["perception.depth"]);
        let config: PerceptionConfig = document["perception"].clone().try_into().expect("noisy");
        assert_eq!(
            config,
            PerceptionConfig::Noisy(NoisyConfig {
                latency_s: 0.08,
                ..NoisyConfig::default()
            })
        );
    }
}
