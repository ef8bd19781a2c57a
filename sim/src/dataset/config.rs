//! The dataset configuration (TOML).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, SimError};

/// The most sequences per (distance class or camera, occlusion level) pair.
pub const MAX_SEQUENCES_PER_PAIR: usize = 100_000;
/// The most distance classes, and the most occlusion levels.
pub const MAX_CLASSES: usize = 64;
/// The share of episodes that play a recorded clip when `[recorded]` is given.
pub const DEFAULT_RECORDED_FRACTION: f64 = 0.5;
use crate::scenario::{RecordedConfig, parse_toml, read_text};
use workcell_render::occlusion::OccluderKind;
use workcell_render::roi;
use workcell_robots::HumanLook;

/// A camera distance class: cameras between `range_m` from the cell centre, with a field of
/// view that narrows with distance like a zoom lens (the cell stays in frame but looks
/// smaller far away).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DistanceClass {
    pub name: String,
    pub range_m: [f64; 2],
    pub fov_y_deg: f64,
}

/// An occlusion level of the forearm: hidden fraction in `range`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OcclusionLevel {
    pub name: String,
    pub range: [f64; 2],
}

/// The cell's own cameras as a second camera source: each of the scenario's `[[cameras]]`
/// at its own resolution, its pose and field of view jittered per sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CellCameras {
    /// Whether the scenario's cameras are a source (each is then a class beside the
    /// distance classes, with `sequences_per_pair` sequences per occlusion level).
    pub enabled: bool,
    /// Eye and target move up to this far along each axis, m.
    pub position_jitter_m: f64,
    /// The field of view scales by up to this fraction either way.
    pub fov_jitter: f64,
}

impl Default for CellCameras {
    fn default() -> Self {
        Self {
            enabled: true,
            position_jitter_m: 0.15,
            fov_jitter: 0.1,
        }
    }
}

/// The regions of interest the frames are cut from (see `workcell_render::roi`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RoiConfig {
    /// Every frame is the camera's whole image (its centred square): the paper's protocol,
    /// for the paper's tables. The other keys are then unused.
    pub whole_frame: bool,
    /// Fraction of the sequences cut around the arm as a tracker would (the rest show the
    /// fixed workspace crop).
    pub tracked_fraction: f64,
    /// The workspace crop: the sphere the forearm can reach around the shoulder, projected,
    /// grown by this factor.
    pub workspace_margin: f64,
    /// The tracked crop: the box around the shoulder, the elbow and the wrist grown by a
    /// factor drawn per sequence from this range ...
    pub tracked_margin: [f64; 2],
    /// ... at least this wide (m at the forearm's depth), so that a foreshortened forearm
    /// keeps its context ...
    pub tracked_min_m: f64,
    /// ... around an estimate this far off the true elbow and wrist (uniform per axis, m).
    pub tracked_error_m: f64,
    /// The tracked crop holds the hand's far end as well (the crop the closed loop's tracker
    /// reads with `perception.hand_region`, `ArmFitConfig::hand_region`). Default
    /// false.
    pub tracked_hand: bool,
}

impl Default for RoiConfig {
    fn default() -> Self {
        Self {
            whole_frame: false,
            tracked_fraction: 0.5,
            workspace_margin: roi::WORKSPACE_MARGIN,
            tracked_margin: roi::TRACKED_MARGIN,
            tracked_min_m: roi::TRACKED_MIN_M,
            tracked_error_m: 0.03,
            tracked_hand: false,
        }
    }
}

/// How datasets are made; every key has the paper's default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatasetConfig {
    /// The cell (a scenario file), relative to this file.
    pub scenario: PathBuf,
    /// Seed of the whole dataset; each sequence's seed derives from it and its index.
    pub seed: u64,
    /// Sequences per (distance class, occlusion level) pair.
    pub sequences_per_pair: usize,
    /// Sequences cut from one simulated episode (different start times, cameras and
    /// people): simulating is most of the cost of a sequence otherwise.
    pub sequences_per_episode: usize,
    /// Frames per sequence.
    pub frames: usize,
    /// The paper's cameras' native resolution (the cell's cameras have their own).
    pub width_px: u32,
    pub height_px: u32,
    /// Side of the stored frames: the region of interest resampled to the network's input.
    pub input_px: u32,
    /// Vary the human's skin, clothes and sleeves per sequence (flesh look).
    pub vary_appearance: bool,
    /// The human's look in the frames, `flesh` or `skeletal` (default: the scenario's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub look: Option<HumanLook>,
    /// The human's model (a catalogue name, or a URDF relative to this file) instead of the
    /// scenario's (`configs/dataset.toml` sets the paper's arm, `human_arm`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub human_model: Option<String>,
    pub cell_cameras: CellCameras,
    pub roi: RoiConfig,
    /// Frames per second.
    pub rate_hz: f64,
    /// The episode is simulated this long (uniform in the range) before the first frame, s.
    pub start_s: [f64; 2],
    /// Camera azimuth about the cell centre, degrees from world +x (the walls' side is
    /// avoided by default).
    pub azimuth_deg: [f64; 2],
    /// Camera elevation above the cell centre, degrees.
    pub elevation_deg: [f64; 2],
    pub distances: Vec<DistanceClass>,
    pub occlusion_levels: Vec<OcclusionLevel>,
    /// Occluder shapes drawn from.
    pub occluders: Vec<OccluderKind>,
    /// How far the occluder drifts over a sequence, in forearm lengths.
    pub occluder_drift: f64,
    /// A sequence is redrawn (new start and camera, at most `attempts` times) while the
    /// forearm shows fewer amodal pixels than this in a frame, or its natural occlusion
    /// exceeds the level's upper bound.
    pub min_forearm_px: u32,
    /// ... or the robot, the torso or the room hide more than this fraction of it (the
    /// level is then made by the occluder, and no camera stands behind a wall).
    pub max_natural_occlusion: f64,
    pub attempts: usize,
    /// Fractions of the sequences of each pair in train / validation / test.
    pub splits: [f64; 3],
    /// Recorded people in the frames (`[recorded]`, keys as a scenario's `[human.recorded]`,
    /// the library relative to this file): a share of the episodes play a clip of it instead
    /// of the generator, each episode the clip its seed draws. A dataset with training or
    /// validation sequences draws only clips of the library's tuning split. Left out: the
    /// scenario's motion in every episode.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recorded: Option<RecordedConfig>,
    /// The share of episodes that play a clip of `recorded`. Default 0.5.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recorded_fraction: Option<f64>,
}

impl Default for DatasetConfig {
    fn default() -> Self {
        let distance = |name: &str, range_m, fov_y_deg| DistanceClass {
            name: name.into(),
            range_m,
            fov_y_deg,
        };
        let level = |name: &str, range| OcclusionLevel {
            name: name.into(),
            range,
        };
        Self {
            scenario: "default.toml".into(),
            seed: 1,
            sequences_per_pair: 105,
            sequences_per_episode: 6,
            frames: 30,
            width_px: 640,
            height_px: 480,
            input_px: 128,
            vary_appearance: true,
            look: None,
            human_model: None,
            cell_cameras: CellCameras::default(),
            roi: RoiConfig::default(),
            rate_hz: 30.0,
            start_s: [0.5, 24.0],
            azimuth_deg: [10.0, 100.0],
            elevation_deg: [10.0, 40.0],
            // The paper's classes, lens to cell centre: short 0-3 m, medium 3-6 m, large 6-10 m.
            distances: vec![
                distance("short", [1.5, 3.0], 45.0),
                distance("medium", [3.0, 6.0], 24.0),
                distance("large", [6.0, 10.0], 14.0),
            ],
            occlusion_levels: vec![
                level("light", [0.0, 0.33]),
                level("medium", [0.33, 0.66]),
                level("heavy", [0.66, 1.0]),
            ],
            occluders: vec![OccluderKind::Blob, OccluderKind::Bar],
            occluder_drift: 0.5,
            min_forearm_px: 12,
            max_natural_occlusion: 0.5,
            attempts: 20,
            splits: [0.8, 0.1, 0.1],
            recorded: None,
            recorded_fraction: None,
        }
    }
}

impl DatasetConfig {
    /// Reads and validates a dataset configuration.
    ///
    /// # Errors
    /// [`SimError::Io`], [`SimError::Parse`] or [`SimError::Invalid`] naming the key.
    pub fn from_file(path: &Path) -> Result<Self> {
        Self::from_toml(&read_text(path)?, path)
    }

    /// Parses and validates; `path` names the source in errors.
    ///
    /// # Errors
    /// As [`DatasetConfig::from_file`].
    pub fn from_toml(text: &str, path: &Path) -> Result<Self> {
        let config: Self = parse_toml(text, path)?;
        config.validate().map_err(|e| e.in_file(path))?;
        Ok(config)
    }

    /// The configuration as TOML.
    #[must_use]
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// Number of sequences: per occlusion level, `sequences_per_pair` for each distance class
    /// and each of the cell's `cameras` (when they are a source).
    #[must_use]
    pub fn sequence_count(&self, cameras: usize) -> usize {
        self.sequences_per_pair * self.camera_classes(cameras) * self.occlusion_levels.len()
    }

    /// The share of episodes that play a recorded clip: 0 without `recorded`.
    #[must_use]
    pub fn recorded_share(&self) -> f64 {
        if self.recorded.is_some() {
            self.recorded_fraction.unwrap_or(DEFAULT_RECORDED_FRACTION)
        } else {
            0.0
        }
    }

    /// Whether any sequence lands in the training or validation split (and so any clip it
    /// shows may be learnt).
    #[must_use]
    pub fn trains(&self) -> bool {
        self.splits[0] > 0.0 || self.splits[1] > 0.0
    }

    /// Distance classes plus the cell's cameras when they are a source.
    #[must_use]
    pub fn camera_classes(&self, cameras: usize) -> usize {
        self.distances.len()
            + if self.cell_cameras.enabled {
                cameras
            } else {
                0
            }
    }

    /// Checks every value.
    ///
    /// # Errors
    /// [`SimError::Invalid`] naming the first bad key.
    pub fn validate(&self) -> Result<()> {
        let invalid = |key: &str, message: String| {
            Err(SimError::Invalid {
                path: None,
                key: key.into(),
                message,
            })
        };
        let range = |key: &str, r: [f64; 2], lo: f64, hi: f64| {
            if r.iter().all(|v| v.is_finite()) && lo <= r[0] && r[0] <= r[1] && r[1] <= hi {
                Ok(())
            } else {
                invalid(key, format!("{r:?} is not an interval within [{lo}, {hi}]"))
            }
        };
        let most = workcell_render::dataset::MAX_SEQUENCE_FRAMES;
        if !(1..=most).contains(&self.frames) {
            return invalid("frames", format!("{} is not in 1..={most}", self.frames));
        }
        if !(1..=MAX_SEQUENCES_PER_PAIR).contains(&self.sequences_per_pair) {
            return invalid(
                "sequences_per_pair",
                format!(
                    "{} is not in 1..={MAX_SEQUENCES_PER_PAIR}",
                    self.sequences_per_pair
                ),
            );
        }
        for (key, v) in [
            ("width_px", self.width_px),
            ("height_px", self.height_px),
            ("input_px", self.input_px),
        ] {
            if !(16..=4096).contains(&v) {
                return invalid(key, format!("{v} px is not in 16..=4096"));
            }
        }
        if !(1..=1000).contains(&self.sequences_per_episode) {
            return invalid(
                "sequences_per_episode",
                format!("{} is not in 1..=1000", self.sequences_per_episode),
            );
        }
        for (key, n) in [
            ("distances", self.distances.len()),
            ("occlusion_levels", self.occlusion_levels.len()),
        ] {
            if n > MAX_CLASSES {
                return invalid(key, format!("{n} entries, more than {MAX_CLASSES}"));
            }
        }
        let cc = &self.cell_cameras;
        if !(cc.position_jitter_m.is_finite() && (0.0..=2.0).contains(&cc.position_jitter_m)) {
            return invalid(
                "cell_cameras.position_jitter_m",
                format!("{} is not in [0, 2]", cc.position_jitter_m),
            );
        }
        if !(cc.fov_jitter.is_finite() && (0.0..0.9).contains(&cc.fov_jitter)) {
            return invalid(
                "cell_cameras.fov_jitter",
                format!("{} is not in [0, 0.9)", cc.fov_jitter),
            );
        }
        let roi = &self.roi;
        if !(0.0..=1.0).contains(&roi.tracked_fraction) {
            return invalid(
                "roi.tracked_fraction",
                format!("{} is not in [0, 1]", roi.tracked_fraction),
            );
        }
        if !(roi.workspace_margin.is_finite() && (1.0..=4.0).contains(&roi.workspace_margin)) {
            return invalid(
                "roi.workspace_margin",
                format!("{} is not in [1, 4]", roi.workspace_margin),
            );
        }
        range("roi.tracked_margin", roi.tracked_margin, 1.0, 4.0)?;
        for (key, v) in [
            ("roi.tracked_min_m", roi.tracked_min_m),
            ("roi.tracked_error_m", roi.tracked_error_m),
        ] {
            if !(v.is_finite() && (0.0..=2.0).contains(&v)) {
                return invalid(key, format!("{v} is not in [0, 2]"));
            }
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 1000.0) {
            return invalid("rate_hz", format!("{} is not in (0, 1000]", self.rate_hz));
        }
        range("start_s", self.start_s, 0.0, 3600.0)?;
        range("azimuth_deg", self.azimuth_deg, -360.0, 360.0)?;
        range("elevation_deg", self.elevation_deg, -89.0, 89.0)?;
        if self.distances.is_empty() {
            return invalid("distances", "at least one distance class".into());
        }
        for (k, d) in self.distances.iter().enumerate() {
            range(&format!("distances[{k}].range_m"), d.range_m, 0.05, 1000.0)?;
            if !(d.fov_y_deg.is_finite() && d.fov_y_deg > 0.5 && d.fov_y_deg < 170.0) {
                return invalid(
                    &format!("distances[{k}].fov_y_deg"),
                    format!("{} is not in (0.5, 170)", d.fov_y_deg),
                );
            }
        }
        if self.occlusion_levels.is_empty() {
            return invalid("occlusion_levels", "at least one level".into());
        }
        for (k, l) in self.occlusion_levels.iter().enumerate() {
            range(&format!("occlusion_levels[{k}].range"), l.range, 0.0, 1.0)?;
        }
        if self.occluders.is_empty() {
            return invalid("occluders", "at least one of \"blob\", \"bar\"".into());
        }
        if !(self.occluder_drift.is_finite() && self.occluder_drift >= 0.0) {
            return invalid(
                "occluder_drift",
                format!("{} is not >= 0", self.occluder_drift),
            );
        }
        if !(0.0..=1.0).contains(&self.max_natural_occlusion) {
            return invalid(
                "max_natural_occlusion",
                format!("{} is not in [0, 1]", self.max_natural_occlusion),
            );
        }
        if self.attempts == 0 {
            return invalid("attempts", "must be at least 1".into());
        }
        let sum: f64 = self.splits.iter().sum();
        if !(self.splits.iter().all(|s| s.is_finite() && *s >= 0.0) && (sum - 1.0).abs() < 1e-9) {
            return invalid(
                "splits",
                format!("{:?} are not fractions summing to 1", self.splits),
            );
        }
        if let Some(f) = self.recorded_fraction {
            if self.recorded.is_none() {
                return invalid("recorded_fraction", "needs a [recorded] section".into());
            }
            if !(0.0..=1.0).contains(&f) {
                return invalid("recorded_fraction", format!("{f} is not in [0, 1]"));
            }
        }
        Ok(())
    }
}
