//! The bound's calibration: what the fit measured for one source of masks, and where it
//! comes from. A network's calibration is a file beside its weights
//! (`procnet-cpu.safetensors` has `procnet-cpu.calibration.toml`), holding the weights' SHA-256:
//! it is applied to those weights only. Weights without one get [`Calibration::UNCALIBRATED`],
//! a stated conservative bound, and a warning; a file of other weights is refused.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::*;
use crate::error::{PerceptionError, Result};

/// What the fit measured for one source of masks: the uncertainty's calibration (`scale`,
/// `floor_m` and `hidden_floors_m` of [`ArmFitConfig`], fitted on the validation split so that
/// 99 % of its frames have the forearm's centre and wrist within the bound, in each band of
/// [`ArmFit::hidden_share`]: `scripts/calibrate_uncertainty.py`, on the per-frame CSV of
/// `workcell eval pose --split validation`), and whether a faint fit confirmed by the frame
/// before is a pose, with the floor of its bound (docs/perception.md).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    pub scale: f64,
    pub floor_m: f64,
    /// The floors where a quarter, a half, three quarters of the forearm's region is
    /// hidden ([`Calibration::floor_at`]).
    pub hidden_floors_m: [f64; 3],
    /// [`ArmFitConfig::confirm_min_gain`]: infinity where confirmed fits of these masks
    /// were measured to be wrong too often to be poses.
    pub confirm_min_gain: f64,
    /// The least bound of a confirmed pose, m: such fits are right or far off (the masks'
    /// faint arm, or a consistent wrong one), and the curvature tells neither.
    pub confirmed_floor_m: f64,
    /// [`ArmFitConfig::min_gain`] the bound was measured with, where the calibration chose
    /// one (`scripts/calibrate_uncertainty.py --min-gain`): fits below it are no pose, and
    /// the bound holds for the fits above it only. Absent: the fit's own (0.3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_gain: Option<f64>,
    /// The floors (no band of [`HIDDEN_BANDS`], then each band) of a fit that kept its
    /// track: the tracked hypotheses explained the masks with a gain of at least
    /// [`ArmFitConfig::search_below_gain`], so the global search did not run
    /// ([`ArmFit::reacquired`] false). Such fits are rarely far off, and `floor_m` and
    /// `hidden_floors_m` are then measured on the re-acquired fits alone
    /// (`scripts/calibrate_uncertainty.py --tracked-floors`). Absent: one set of floors for
    /// every fit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracked_floors_m: Option<[f64; 4]>,
    /// The floors of a fit that explained the masks well ([`ConfidentFloors`]): from its
    /// gain up, a fit takes these instead of any other floors. Absent: the gain does not
    /// choose the floors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confident: Option<ConfidentFloors>,
    /// The fit's settings the bound was measured with ([`FitSettings`]): [`Calibration::apply`]
    /// sets them, so that the fit whose bound this is runs. Absent: the fit's defaults.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitSettings>,
}

/// The floors of the fits whose gain reaches `min_gain`: a fit that explains the masks this
/// well is rarely far off, on recorded people as on the generator's motion, so one set of
/// floors fitted on every fit is set by the poor ones (`scripts/calibrate_uncertainty.py
/// --confident-gain`; docs/perception.md, "A bound that reads the gain").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConfidentFloors {
    /// The gain ([`ArmFit::gain`]) from which a fit takes these floors.
    pub min_gain: f64,
    /// The floors (no band of [`HIDDEN_BANDS`], then each band), m.
    pub floors_m: [f64; 4],
}

/// What the bound of one fit is made from ([`Calibration::radius`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundInputs {
    /// The curvature's spread of the forearm's centre and wrist, m ([`ArmFit::sigma_m`]).
    pub sigma_m: f64,
    /// How far apart the hypotheses the masks cannot tell apart put them, m.
    pub spread_m: f64,
    /// The share of the forearm's region hidden by something in front of it.
    pub hidden_share: f64,
    /// How well the fit explains the masks ([`ArmFit::gain`]).
    pub gain: f64,
    /// A faint fit confirmed by the frame before ([`ArmFit::confirmed`]).
    pub confirmed: bool,
    /// The fit kept its track ([`ArmFit::reacquired`] false).
    pub tracked: bool,
}

/// The settings of the fit that change which poses it finds (and so what its bound must
/// cover), as a calibration records them: `workcell eval pose` writes them beside its
/// per-frame CSV (`fit.toml`) and `scripts/calibrate_uncertainty.py --write` copies them into
/// the calibration.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitSettings {
    /// [`ArmFitConfig::fit_trunk`].
    pub fit_trunk: bool,
    /// [`ArmFitConfig::search_below_gain`].
    pub search_below_gain: f64,
    /// [`ArmFitConfig::reversed_start`].
    pub reversed_start: bool,
    /// [`ArmFitConfig::depth_start`].
    pub depth_start: bool,
    /// [`ArmFitConfig::hull_outlines`] (false where a file leaves it out).
    #[serde(default)]
    pub hull_outlines: bool,
    /// [`ArmFitConfig::hand_region`]: the crops held the hand's far end (false where a file
    /// leaves it out).
    #[serde(default)]
    pub hand_region: bool,
    /// [`ArmFitConfig::trunk_downsample`] (1 where a file leaves it out).
    #[serde(default = "full_resolution")]
    pub trunk_downsample: u32,
}

fn full_resolution() -> u32 {
    1
}

impl FitSettings {
    /// The settings `config` carries.
    #[must_use]
    pub fn of(config: &ArmFitConfig) -> Self {
        Self {
            fit_trunk: config.fit_trunk,
            search_below_gain: config.search_below_gain,
            reversed_start: config.reversed_start,
            depth_start: config.depth_start,
            hull_outlines: config.hull_outlines,
            hand_region: config.hand_region,
            trunk_downsample: config.trunk_downsample,
        }
    }

    /// `config` with these settings.
    #[must_use]
    pub fn apply(self, config: ArmFitConfig) -> ArmFitConfig {
        ArmFitConfig {
            fit_trunk: self.fit_trunk,
            search_below_gain: self.search_below_gain,
            reversed_start: self.reversed_start,
            depth_start: self.depth_start,
            hull_outlines: self.hull_outlines,
            hand_region: self.hand_region,
            trunk_downsample: self.trunk_downsample,
            ..config
        }
    }

    /// How `other` differs from these settings, as `key: this vs other` for each setting
    /// that does; empty where none does.
    #[must_use]
    pub fn differences(&self, other: &Self) -> Vec<String> {
        let settings = |f: &Self| {
            [
                ("fit_trunk", f.fit_trunk.to_string()),
                ("search_below_gain", f.search_below_gain.to_string()),
                ("reversed_start", f.reversed_start.to_string()),
                ("depth_start", f.depth_start.to_string()),
                ("hull_outlines", f.hull_outlines.to_string()),
                ("hand_region", f.hand_region.to_string()),
                ("trunk_downsample", f.trunk_downsample.to_string()),
            ]
        };
        settings(self)
            .into_iter()
            .zip(settings(other))
            .filter(|((_, a), (_, b))| a != b)
            .map(|((key, a), (_, b))| format!("{key}: {a} vs {b}"))
            .collect()
    }
}

/// Where [`ArmFit::hidden_share`] starts each band of [`Calibration::hidden_floors_m`].
pub const HIDDEN_BANDS: [f64; 3] = [0.25, 0.5, 0.75];

/// The largest calibration file read, bytes.
pub const MAX_CALIBRATION_BYTES: u64 = 1 << 20;

/// A calibration file: the weights it was measured on (their SHA-256), what it was fitted
/// on, and the calibration of a fit with and without the depth image (either may be
/// missing: never measured).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationFile {
    /// The SHA-256 of the weights file, lower-case hex.
    pub weights_sha256: String,
    /// The split, frames and command the calibration was fitted on (and checked on).
    pub fitted_on: String,
    /// A fit that reads the depth image.
    pub with_depth: Option<Calibration>,
    /// A fit of the masks alone.
    pub without_depth: Option<Calibration>,
}

/// Where the bound of a network's fit comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum BoundSource {
    /// The calibration file beside the weights, measured on them.
    Calibrated { path: PathBuf, fitted_on: String },
    /// No calibration was measured for these weights (or for this use of them):
    /// [`Calibration::UNCALIBRATED`]; `why` says what is missing.
    Uncalibrated { why: String },
}

/// A network's calibration as found beside its weights, and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkCalibration {
    pub calibration: Calibration,
    pub source: BoundSource,
}

impl NetworkCalibration {
    /// What a user should be told, where the bound is not a measured one.
    #[must_use]
    pub fn warning(&self) -> Option<String> {
        match &self.source {
            BoundSource::Calibrated { .. } => None,
            BoundSource::Uncalibrated { why } => Some(format!(
                "{why}: the pose bound is the conservative {:.2} m plus the curvature's spread \
                 (calibrate these weights: scripts/calibrate_uncertainty.py --write)",
                Calibration::UNCALIBRATED.floor_m
            )),
        }
    }
}

/// The calibration file beside `weights`: the same name with `.calibration.toml` for its
/// extension.
#[must_use]
pub fn calibration_path(weights: &Path) -> PathBuf {
    weights.with_extension("calibration.toml")
}

/// The SHA-256 of the file at `path`, lower-case hex.
///
/// # Errors
/// The file is not a regular file of at most `max_bytes`, or cannot be read.
pub fn file_sha256(path: &Path, max_bytes: u64) -> Result<String> {
    let bytes = workcell_robots::input::read_regular_file(path, max_bytes).map_err(|e| {
        PerceptionError::Calibration {
            path: path.to_path_buf(),
            message: format!("cannot hash: {e}"),
        }
    })?;
    Ok(Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

impl Calibration {
    /// The bound of a fit whose masks' calibration was never measured: at least 0.45 m,
    /// plus the curvature's spread, in every band, and no faint fit taken for a pose. It
    /// lies above every bound measured for the shipped networks of the paper's arm (the
    /// largest: 40.6 cm, the RGB network's fit without depth) and the true masks' (38.5 cm
    /// without depth); not above the whole body's (`procnet-depth-human`: up to 72.8 cm).
    pub const UNCALIBRATED: Self = Self {
        scale: 1.0,
        floor_m: 0.45,
        hidden_floors_m: [0.45; 3],
        confirm_min_gain: f64::INFINITY,
        confirmed_floor_m: 0.0,
        min_gain: None,
        tracked_floors_m: None,
        confident: None,
        fit: None,
    };

    /// The calibration measured for the fit of true masks (each part's pixels in the
    /// rendered frame), with or without the depth image.
    #[must_use]
    pub fn true_masks(depth: bool) -> Self {
        // The validation split (docs/perception.md), the renders as row spans: true masks
        // with depth, 3,828 frames, 99 % within half the curvature's spread plus 1.68 cm where
        // under half the forearm's region is hidden (1,584 frames), 1.74 cm up to three
        // quarters (437), 33.8 cm beyond (1,807: the mirror, where the occluder hides the
        // forearm's depth); without depth, the mirror's misses, 38.5 cm. True masks give no
        // faint fits confirmed by the frame before.
        let (scale, floor_m, hidden_floors_m) = if depth {
            (0.5, 0.0168, [0.0168, 0.0174, 0.3381])
        } else {
            (0.0, 0.3851, [0.0; 3])
        };
        Self {
            scale,
            floor_m,
            hidden_floors_m,
            confirm_min_gain: f64::INFINITY,
            confirmed_floor_m: 0.0,
            min_gain: None,
            tracked_floors_m: None,
            confident: None,
            fit: None,
        }
    }

    /// The calibration of the network whose weights are at `weights`, for a fit with or
    /// without the depth image: from the calibration file beside them
    /// ([`calibration_path`]) when it holds these weights' hash, else
    /// [`Calibration::UNCALIBRATED`] with the reason ([`NetworkCalibration::warning`]).
    ///
    /// # Errors
    /// The calibration file exists but cannot be read or parsed, holds values out of range,
    /// or was measured on other weights (its hash is not theirs).
    pub fn of_weights(weights: &Path, depth: bool) -> Result<NetworkCalibration> {
        let path = calibration_path(weights);
        let bad = |message: String| PerceptionError::Calibration {
            path: path.clone(),
            message,
        };
        let text = match workcell_robots::input::read_text_file(&path, MAX_CALIBRATION_BYTES) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(NetworkCalibration {
                    calibration: Self::UNCALIBRATED,
                    source: BoundSource::Uncalibrated {
                        why: format!("{} has no calibration beside it", weights.display()),
                    },
                });
            }
            Err(e) => return Err(bad(format!("cannot read: {e}"))),
        };
        let file: CalibrationFile = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        let hash = file_sha256(weights, workcell_procnet::weights::MAX_WEIGHTS_BYTES)?;
        if !file.weights_sha256.eq_ignore_ascii_case(&hash) {
            return Err(bad(format!(
                "measured on weights with SHA-256 {}, but {} has {hash}: these weights need \
                 their own calibration (scripts/calibrate_uncertainty.py --write), or remove \
                 the file to use the conservative bound",
                file.weights_sha256,
                weights.display()
            )));
        }
        let (which, measured) = if depth {
            ("with_depth", file.with_depth)
        } else {
            ("without_depth", file.without_depth)
        };
        match measured {
            Some(c) => {
                c.check().map_err(|m| bad(format!("{which}.{m}")))?;
                Ok(NetworkCalibration {
                    calibration: c,
                    source: BoundSource::Calibrated {
                        path,
                        fitted_on: file.fitted_on,
                    },
                })
            }
            None => Ok(NetworkCalibration {
                calibration: Self::UNCALIBRATED,
                source: BoundSource::Uncalibrated {
                    why: format!(
                        "{} holds no calibration of a fit {} the depth image",
                        path.display(),
                        if depth { "with" } else { "without" }
                    ),
                },
            }),
        }
    }

    /// Whether every value is one a bound can have: finite, non-negative lengths and scale
    /// (the gain threshold may be infinite: no confirmed fit is a pose). The key of the
    /// first that is not, with why.
    fn check(&self) -> std::result::Result<(), String> {
        let lengths = [
            ("scale", self.scale),
            ("floor_m", self.floor_m),
            ("hidden_floors_m[0]", self.hidden_floors_m[0]),
            ("hidden_floors_m[1]", self.hidden_floors_m[1]),
            ("hidden_floors_m[2]", self.hidden_floors_m[2]),
            ("confirmed_floor_m", self.confirmed_floor_m),
        ];
        let tracked = self.tracked_floors_m.unwrap_or_default();
        let tracked_keys = [
            "tracked_floors_m[0]",
            "tracked_floors_m[1]",
            "tracked_floors_m[2]",
            "tracked_floors_m[3]",
        ];
        let confident = self.confident.map_or([0.0; 4], |c| c.floors_m);
        let confident_keys = [
            "confident.floors_m[0]",
            "confident.floors_m[1]",
            "confident.floors_m[2]",
            "confident.floors_m[3]",
        ];
        let lengths = lengths
            .into_iter()
            .chain(tracked_keys.into_iter().zip(tracked))
            .chain(confident_keys.into_iter().zip(confident));
        for (key, v) in lengths {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{key}: {v} is not a finite value >= 0"));
            }
        }
        if let Some(g) = self.min_gain
            && !(0.0..=1.0).contains(&g)
        {
            return Err(format!("min_gain: {g} is not a gain from 0 to 1"));
        }
        if let Some(c) = self.confident
            && !(0.0..=1.0).contains(&c.min_gain)
        {
            return Err(format!(
                "confident.min_gain: {} is not a gain from 0 to 1",
                c.min_gain
            ));
        }
        if let Some(f) = self.fit
            && !(0.0..=1.0).contains(&f.search_below_gain)
        {
            return Err(format!(
                "fit.search_below_gain: {} is not a gain from 0 to 1",
                f.search_below_gain
            ));
        }
        if self.confirm_min_gain.is_nan() || self.confirm_min_gain < 0.0 {
            return Err(format!(
                "confirm_min_gain: {} is not a value >= 0",
                self.confirm_min_gain
            ));
        }
        Ok(())
    }

    /// `config` with this calibration: its bound, and the fit's settings it was measured
    /// with where it records them ([`Calibration::fit`]).
    #[must_use]
    pub fn apply(self, config: ArmFitConfig) -> ArmFitConfig {
        let config = match self.fit {
            Some(fit) => fit.apply(config),
            None => config,
        };
        ArmFitConfig {
            uncertainty_tracked_floors_m: self.tracked_floors_m,
            uncertainty_confident: self.confident,
            uncertainty_scale: self.scale,
            uncertainty_floor_m: self.floor_m,
            uncertainty_hidden_floors_m: self.hidden_floors_m,
            confirm_min_gain: self.confirm_min_gain,
            uncertainty_confirmed_floor_m: self.confirmed_floor_m,
            min_gain: self.min_gain.unwrap_or(config.min_gain),
            ..config
        }
    }

    /// The radius of a fit (what [`ArmFit::uncertainty_m`] reports) under this calibration:
    /// `scale sigma + floor`, or the spread where that is larger; for a pose confirmed below
    /// the gain threshold, at least `confirmed_floor_m`. The floor is the confident floors'
    /// where the fit's gain reaches theirs, else the tracked floors' for a fit that kept its
    /// track, else the floors of every fit; each by the band of the hidden share.
    #[must_use]
    pub fn radius(&self, fit: &BoundInputs) -> f64 {
        let floor = match (self.confident, self.tracked_floors_m) {
            (Some(c), _) if fit.gain >= c.min_gain => {
                Self::band_floor(c.floors_m, fit.hidden_share)
            }
            (_, Some(floors)) if fit.tracked => Self::band_floor(floors, fit.hidden_share),
            _ => self.floor_at(fit.hidden_share),
        };
        let r = (self.scale * fit.sigma_m + floor).max(fit.spread_m);
        if fit.confirmed {
            r.max(self.confirmed_floor_m)
        } else {
            r
        }
    }

    /// The floor for a forearm's region `hidden_share` hidden: `floor_m` below the first of
    /// [`HIDDEN_BANDS`], else the band's floor, never below a less hidden band's.
    #[must_use]
    pub fn floor_at(&self, hidden_share: f64) -> f64 {
        let [h1, h2, h3] = self.hidden_floors_m;
        Self::band_floor([self.floor_m, h1, h2, h3], hidden_share)
    }

    /// Of `floors` (no band, then each of [`HIDDEN_BANDS`]), the one for `hidden_share`:
    /// its band's, never below a less hidden band's.
    fn band_floor(floors: [f64; 4], hidden_share: f64) -> f64 {
        let bands = HIDDEN_BANDS.iter().filter(|&&b| hidden_share >= b).count();
        floors[..=bands].iter().fold(0.0, |a, &b| a.max(b))
    }

    /// The calibration `config` carries.
    #[must_use]
    pub fn of(config: &ArmFitConfig) -> Self {
        Self {
            scale: config.uncertainty_scale,
            floor_m: config.uncertainty_floor_m,
            hidden_floors_m: config.uncertainty_hidden_floors_m,
            confirm_min_gain: config.confirm_min_gain,
            confirmed_floor_m: config.uncertainty_confirmed_floor_m,
            min_gain: Some(config.min_gain),
            tracked_floors_m: config.uncertainty_tracked_floors_m,
            confident: config.uncertainty_confident,
            fit: Some(FitSettings::of(config)),
        }
    }
}
