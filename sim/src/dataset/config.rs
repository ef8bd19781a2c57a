//! The dataset configuration (TOML).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Result, SimError};
use crate::scenario::{parse_toml, read_text};
use workcell_render::occlusion::OccluderKind;

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
    /// Frames per sequence.
    pub frames: usize,
    pub width_px: u32,
    pub height_px: u32,
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
            sequences_per_pair: 10,
            frames: 20,
            width_px: 128,
            height_px: 128,
            rate_hz: 30.0,
            start_s: [0.5, 6.0],
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

    /// Number of sequences.
    #[must_use]
    pub fn sequence_count(&self) -> usize {
        self.sequences_per_pair * self.distances.len() * self.occlusion_levels.len()
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
        if self.frames == 0 || self.frames > 10_000 {
            return invalid("frames", format!("{} is not in 1..=10000", self.frames));
        }
        if self.sequences_per_pair == 0 {
            return invalid("sequences_per_pair", "must be at least 1".into());
        }
        for (key, v) in [("width_px", self.width_px), ("height_px", self.height_px)] {
            if !(16..=4096).contains(&v) {
                return invalid(key, format!("{v} px is not in 16..=4096"));
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
        Ok(())
    }
}
