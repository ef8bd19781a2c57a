//! The run record, `run.json`: everything an evaluation's report is made of, so that the
//! shards of one evaluation run anywhere (`workcell evaluate --shard K/N`) merge into the
//! report that a single process would have written (`workcell report merge`).
//!
//! A record holds every episode's metrics at full precision ([`super::lossless`]) and the
//! traces of the shard's [`PLOTTED_EPISODES`] worst episodes: the plots show the worst
//! episodes of the whole run, and each of those is among the worst of its own shard.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{EpisodeMetrics, EpisodeTrace};
use crate::error::{Error, Result};

/// The record's file name inside an evaluation's output folder.
pub const RUN_RECORD: &str = "run.json";
/// Format of [`RunRecord`]; a reader refuses any other.
pub const RUN_RECORD_FORMAT: u32 = 1;
/// The plots show this many episodes, those with the smallest separation.
pub const PLOTTED_EPISODES: usize = 5;

/// What a shard of an evaluation shares with every other shard of it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSettings {
    /// The evaluation file as given on the command line.
    pub evaluation_file: String,
    /// The evaluation as run, every default filled in (the text of `evaluation.toml`).
    pub evaluation_toml: String,
    pub robot: String,
    /// `--filter` as given: `qp`, `ssm` or `none`.
    pub filter: String,
    /// `--perception` when given.
    pub perception_arg: Option<String>,
    /// `--set` overrides, in order.
    pub overrides: Vec<String>,
    /// Perception as the report names it.
    pub perception: String,
    /// The seed of episode 0; episode `i` has seed `first_seed + i`.
    pub first_seed: u64,
    /// Episodes of the whole evaluation, all shards together.
    pub episodes: usize,
    /// Shards the evaluation is cut into (1 for a run in one process).
    pub shards: usize,
    /// Each shard writes 3D replays of this many of its worst episodes (`--gltf`).
    pub replays_per_shard: usize,
    #[serde(with = "super::lossless::f64")]
    pub d_min_m: f64,
    #[serde(with = "super::lossless::f64")]
    pub near_m: f64,
    /// Distance within which the peaks per body region are taken, m.
    #[serde(with = "super::lossless::f64")]
    pub pfl_distance_m: f64,
    /// ISO/TS 15066 transient contact speed per arm part, m/s (empty without robot masses).
    pub contact_speed_limits: Vec<(String, f64)>,
}

/// The worst episode's samples over time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct KeptTrace {
    pub episode: usize,
    pub trace: EpisodeTrace,
}

/// One shard's record (a run in one process is shard 1 of 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    pub format: u32,
    pub settings: RunSettings,
    /// 1-based: this is shard `shard` of `settings.shards`.
    pub shard: usize,
    /// Every episode of the shard, in episode order.
    pub metrics: Vec<EpisodeMetrics>,
    /// Traces of the shard's worst episodes ([`worst_episodes`]).
    pub traces: Vec<KeptTrace>,
    /// Files of the shard's worst episodes beside the record (3D replays), by episode.
    pub replays: Vec<(usize, String)>,
}

/// The episodes shard `shard` (1-based) of `shards` runs out of `episodes`: every
/// `shards`-th one from `shard - 1`, so that slow and fast episodes spread evenly.
///
/// # Errors
/// [`Error::Config`] naming `--shard` when `shard` is not within `1..=shards` or a shard
/// would get no episode.
pub fn shard_episodes(shard: usize, shards: usize, episodes: usize) -> Result<Vec<usize>> {
    if shards == 0 || shard == 0 || shard > shards {
        return Err(Error::config(
            "--shard",
            format!("{shard}/{shards}: K/N needs 1 <= K <= N"),
        ));
    }
    if shards > episodes {
        return Err(Error::config(
            "--shard",
            format!("{shards} shards of {episodes} episodes leave some shard without one"),
        ));
    }
    Ok((shard - 1..episodes).step_by(shards).collect())
}

/// Indices into `episodes` of the `n` with the smallest separation, closest first; ties go
/// to the lower episode number.
#[must_use]
pub fn worst_episodes(episodes: &[EpisodeMetrics], n: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..episodes.len()).collect();
    order.sort_by(|&a, &b| {
        episodes[a]
            .min_separation_m
            .total_cmp(&episodes[b].min_separation_m)
            .then(episodes[a].episode.cmp(&episodes[b].episode))
    });
    order.truncate(n);
    order
}

impl RunRecord {
    /// Reads `dir/run.json`.
    ///
    /// # Errors
    /// [`Error::Io`] when it cannot be read, [`Error::Parse`] when it is not a record of
    /// this format.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join(RUN_RECORD);
        let text = std::fs::read_to_string(&path).map_err(|source| Error::Io {
            path: path.clone(),
            source,
        })?;
        let parse = |message: String| Error::Parse {
            path: path.clone(),
            message,
        };
        let format: FormatOnly = serde_json::from_str(&text)
            .map_err(|e| parse(format!("not a run record of `workcell evaluate`: {e}")))?;
        if format.format != RUN_RECORD_FORMAT {
            return Err(parse(format!(
                "run record format {} (this workcell reads {RUN_RECORD_FORMAT})",
                format.format
            )));
        }
        serde_json::from_str(&text).map_err(|e| parse(e.to_string()))
    }

    /// The record as JSON.
    ///
    /// # Errors
    /// Never for records this crate makes; serde's error otherwise.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string(self).map_err(|e| Error::Parse {
            path: PathBuf::from(RUN_RECORD),
            message: e.to_string(),
        })
    }

    /// The traces kept for the plots, paired with their metrics, worst first.
    #[must_use]
    pub fn worst(&self) -> Vec<(&EpisodeMetrics, &EpisodeTrace)> {
        worst_episodes(&self.metrics, PLOTTED_EPISODES)
            .into_iter()
            .filter_map(|i| {
                let m = &self.metrics[i];
                self.traces
                    .iter()
                    .find(|t| t.episode == m.episode)
                    .map(|t| (m, &t.trace))
            })
            .collect()
    }
}

#[derive(Deserialize)]
struct FormatOnly {
    format: u32,
}

/// The shards of one evaluation as one record (shard 1 of 1), as a single process would have
/// written it; with it, the folder each replay file of the worst episodes is in.
///
/// # Errors
/// [`Error::Config`] naming the folders when the shards are of different evaluations, a
/// shard is given twice or missing, or the episodes do not add up to the evaluation's.
pub fn merge(shards: Vec<(PathBuf, RunRecord)>) -> Result<(RunRecord, Vec<PathBuf>)> {
    let bad = |message: String| Error::config("report merge", message);
    let Some((first_dir, first)) = shards.first() else {
        return Err(bad("no shard folders given".into()));
    };
    let settings = first.settings.clone();
    let mut seen = vec![None::<&Path>; settings.shards];
    for (dir, record) in &shards {
        if record.settings != settings {
            let what = differing_setting(&settings, &record.settings);
            return Err(bad(format!(
                "{} and {} are shards of different evaluations ({what} differs)",
                first_dir.display(),
                dir.display()
            )));
        }
        let slot = seen.get_mut(record.shard.wrapping_sub(1)).ok_or_else(|| {
            bad(format!(
                "{}: shard {} of {}",
                dir.display(),
                record.shard,
                settings.shards
            ))
        })?;
        if let Some(other) = slot {
            return Err(bad(format!(
                "shard {}/{} is given twice: {} and {}",
                record.shard,
                settings.shards,
                other.display(),
                dir.display()
            )));
        }
        *slot = Some(dir);
    }
    let missing: Vec<String> = seen
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_none())
        .map(|(k, _)| format!("{}/{}", k + 1, settings.shards))
        .collect();
    if !missing.is_empty() {
        return Err(bad(format!("missing shards: {}", missing.join(", "))));
    }
    let mut metrics: Vec<EpisodeMetrics> = Vec::with_capacity(settings.episodes);
    let mut traces = Vec::new();
    let mut replays = Vec::new();
    for (dir, record) in &shards {
        let expected = shard_episodes(record.shard, settings.shards, settings.episodes)?;
        let got: Vec<usize> = record.metrics.iter().map(|m| m.episode).collect();
        if got != expected {
            return Err(bad(format!(
                "{}: shard {}/{} holds {} episodes, not the {} its slice has",
                dir.display(),
                record.shard,
                settings.shards,
                got.len(),
                expected.len()
            )));
        }
        metrics.extend(record.metrics.iter().cloned());
        traces.extend(record.traces.iter().cloned());
        replays.extend(
            record
                .replays
                .iter()
                .map(|(episode, file)| ((*episode, file.clone()), dir.clone())),
        );
    }
    metrics.sort_by_key(|m| m.episode);
    let distinct: BTreeSet<usize> = metrics.iter().map(|m| m.episode).collect();
    if distinct.len() != settings.episodes || metrics.len() != settings.episodes {
        return Err(bad(format!(
            "the shards hold {} distinct episodes of {}",
            distinct.len(),
            settings.episodes
        )));
    }
    let worst = worst_episodes(&metrics, PLOTTED_EPISODES);
    let kept: BTreeSet<usize> = worst.iter().map(|&i| metrics[i].episode).collect();
    traces.retain(|t| kept.contains(&t.episode));
    traces.sort_by_key(|t| t.episode);
    // The replays of the whole run's worst, as many as each shard wrote.
    let replay_worst: BTreeSet<usize> = worst_episodes(&metrics, settings.replays_per_shard)
        .into_iter()
        .map(|i| metrics[i].episode)
        .collect();
    replays.retain(|((episode, _), _)| replay_worst.contains(episode));
    replays.sort_by_key(|((episode, _), _)| *episode);
    let (replays, dirs): (Vec<_>, Vec<_>) = replays.into_iter().unzip();
    let merged = RunRecord {
        format: RUN_RECORD_FORMAT,
        settings: RunSettings {
            shards: 1,
            ..settings
        },
        shard: 1,
        metrics,
        traces,
        replays,
    };
    Ok((merged, dirs))
}

/// The name of the first setting in which `a` and `b` differ.
fn differing_setting(a: &RunSettings, b: &RunSettings) -> &'static str {
    if a.evaluation_toml != b.evaluation_toml {
        "the evaluation (evaluation.toml)"
    } else if a.filter != b.filter {
        "--filter"
    } else if a.perception_arg != b.perception_arg || a.perception != b.perception {
        "--perception"
    } else if a.overrides != b.overrides {
        "--set"
    } else if a.first_seed != b.first_seed {
        "--seed"
    } else if a.episodes != b.episodes {
        "--episodes"
    } else if a.shards != b.shards {
        "the number of shards"
    } else if a.replays_per_shard != b.replays_per_shard {
        "--gltf"
    } else if a.evaluation_file != b.evaluation_file {
        "the evaluation file's path"
    } else {
        "the robot"
    }
}
