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
use workcell_robots::input::{MAX_CONFIG_BYTES, read_text_file};

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
    /// Perception was given a recorded person's other arm, and the filter guarded it
    /// (`EvaluationConfig::other_arm_seen` with a perception that sees the whole person).
    /// Absent in records before it: false.
    #[serde(default)]
    pub other_arm_seen: bool,
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
        let text = read_text_file(&path, MAX_CONFIG_BYTES).map_err(|source| Error::Io {
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
        let record: Self = serde_json::from_str(&text).map_err(|e| parse(e.to_string()))?;
        record.check().map_err(parse)?;
        Ok(record)
    }

    /// A record must be the record of its episodes: every number finite where a number is
    /// measured, each episode's seed its own (`first_seed + episode`), the episodes exactly its
    /// shard's slice, and the counts agreeing with the separations they were counted from
    /// (a separation below d_min is a violation, one at or below 0 a contact, and the other
    /// way round). A record edited by hand into "no violation" is refused, not reported.
    ///
    /// # Errors
    /// A message naming the field (`metrics[i] (episode e).key`) and what is wrong with it.
    pub(crate) fn check(&self) -> std::result::Result<(), String> {
        let s = &self.settings;
        if s.shards == 0 || self.shard == 0 || self.shard > s.shards {
            return Err(format!(
                "shard {} of {}: needs 1 <= shard <= shards",
                self.shard, s.shards
            ));
        }
        if s.episodes == 0 {
            return Err("settings.episodes: 0 episodes".into());
        }
        let last = u64::try_from(s.episodes - 1).unwrap_or(u64::MAX);
        if s.first_seed.checked_add(last).is_none() {
            return Err(format!(
                "settings.first_seed: {} episodes from seed {} pass the largest seed",
                s.episodes, s.first_seed
            ));
        }
        for (key, v) in [
            ("d_min_m", s.d_min_m),
            ("near_m", s.near_m),
            ("pfl_distance_m", s.pfl_distance_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("settings.{key} = {v}: must be finite and >= 0"));
            }
        }
        for (part, v) in &s.contact_speed_limits {
            // 0 where contact is not permitted (the head).
            if !(v.is_finite() && *v >= 0.0) {
                return Err(format!(
                    "settings.contact_speed_limits: {part} = {v}: must be finite and >= 0"
                ));
            }
        }
        // The settings repeat what the evaluation says: they must say the same.
        let config: super::EvaluationConfig = toml::from_str(&s.evaluation_toml)
            .map_err(|e| format!("settings.evaluation_toml is not an evaluation: {e}"))?;
        if config.safety.d_min_m.to_bits() != s.d_min_m.to_bits() {
            return Err(format!(
                "settings.d_min_m = {} contradicts the evaluation's safety.d_min_m = {}",
                s.d_min_m, config.safety.d_min_m
            ));
        }
        if config.near_m.to_bits() != s.near_m.to_bits() {
            return Err(format!(
                "settings.near_m = {} contradicts the evaluation's near_m = {}",
                s.near_m, config.near_m
            ));
        }
        let expected =
            shard_episodes(self.shard, s.shards, s.episodes).map_err(|e| e.to_string())?;
        let got: Vec<usize> = self.metrics.iter().map(|m| m.episode).collect();
        if got != expected {
            return Err(format!(
                "metrics: shard {}/{} holds episodes {}, not its slice of {} episodes",
                self.shard,
                s.shards,
                abbreviate(&got),
                expected.len()
            ));
        }
        for (i, m) in self.metrics.iter().enumerate() {
            check_episode(m, s).map_err(|e| format!("metrics[{i}] (episode {}).{e}", m.episode))?;
        }
        for t in &self.traces {
            if !got.contains(&t.episode) {
                return Err(format!(
                    "traces: episode {} is not among the record's episodes",
                    t.episode
                ));
            }
        }
        for (episode, file) in &self.replays {
            if !got.contains(episode) {
                return Err(format!(
                    "replays: episode {episode} is not among the record's episodes"
                ));
            }
            // The file is copied out of the shard's folder into the merged one: a plain
            // relative path, never one that leaves either folder.
            let plain = !file.is_empty()
                && Path::new(file)
                    .components()
                    .all(|c| matches!(c, std::path::Component::Normal(_)));
            if !plain {
                return Err(format!(
                    "replays: episode {episode}'s file {file:?} is not a path inside the folder"
                ));
            }
        }
        Ok(())
    }

    /// The record as JSON: only a record that passes [`RunRecord::check`], so that what is
    /// written is what [`RunRecord::read`] reads back.
    ///
    /// # Errors
    /// Never for records this crate makes; the check's or serde's error otherwise.
    pub fn to_json(&self) -> Result<String> {
        let error = |message: String| Error::Parse {
            path: PathBuf::from(RUN_RECORD),
            message,
        };
        self.check().map_err(error)?;
        serde_json::to_string(self).map_err(|e| error(e.to_string()))
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

/// At most a few of `items`, for a message.
fn abbreviate(items: &[usize]) -> String {
    let shown: Vec<String> = items.iter().take(5).map(ToString::to_string).collect();
    if items.len() > shown.len() {
        format!("{}, ... ({} in all)", shown.join(", "), items.len())
    } else {
        format!("[{}]", shown.join(", "))
    }
}

/// One episode's metrics against themselves and the run's settings; the error starts with
/// the field's name.
fn check_episode(m: &EpisodeMetrics, s: &RunSettings) -> std::result::Result<(), String> {
    let seed = s.first_seed + m.episode as u64;
    if m.seed != seed {
        return Err(format!(
            "seed = {}: episode {} of a run from seed {} has seed {seed}",
            m.seed, m.episode, s.first_seed
        ));
    }
    // Measured quantities: finite and not negative.
    for (key, v) in [
        ("violation_s", m.violation_s),
        ("violation_moving_s", m.violation_moving_s),
        ("nominal_task_s", m.nominal_task_s),
        ("peak_speed_near_human_m_s", m.peak_speed_near_human_m_s),
        ("peak_human_speed_m_s", m.peak_human_speed_m_s),
        (
            "peak_human_acceleration_m_s2",
            m.peak_human_acceleration_m_s2,
        ),
        ("simulated_s", m.simulated_s),
        ("wall_s", m.wall_s),
        ("setup_s", m.setup_s),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(format!("{key} = {v}: must be finite and >= 0"));
        }
    }
    // Approach speeds may be negative (moving away) but are numbers.
    let approaches = [("peak_approach_speed_m_s", m.peak_approach_speed_m_s)]
        .into_iter()
        .chain(
            m.peak_approach_by_part_m_s
                .iter()
                .map(|&v| ("peak_approach_by_part_m_s", v)),
        );
    for (key, v) in approaches {
        if !v.is_finite() {
            return Err(format!("{key} = {v}: must be finite"));
        }
    }
    if let Some(t) = m.task_time_s
        && !(t.is_finite() && t > 0.0)
    {
        return Err(format!("task_time_s = {t}: must be finite and > 0"));
    }
    // NaN: no tick had an estimate; a number is a mean distance.
    if !(m.perception_error_m.is_nan()
        || (m.perception_error_m.is_finite() && m.perception_error_m >= 0.0))
    {
        return Err(format!(
            "perception_error_m = {}: a distance (or NaN without estimates)",
            m.perception_error_m
        ));
    }
    if !(m.fit_error_m.is_nan() || (m.fit_error_m.is_finite() && m.fit_error_m >= 0.0)) {
        return Err(format!(
            "fit_error_m = {}: a distance (or NaN without fits)",
            m.fit_error_m
        ));
    }
    // NaN: no other arm; a signed distance otherwise.
    if m.other_arm_min_separation_m.is_infinite() {
        return Err(format!(
            "other_arm_min_separation_m = {}: a distance (or NaN without the other arm)",
            m.other_arm_min_separation_m
        ));
    }
    if !(m.other_arm_violation_s.is_finite() && m.other_arm_violation_s >= 0.0) {
        return Err(format!(
            "other_arm_violation_s = {}: a time (>= 0)",
            m.other_arm_violation_s
        ));
    }
    // Five parts in the files of the one-armed human; the left arm's since.
    if !(5..=workcell_safety::HumanPart::ALL.len()).contains(&m.perception_error_by_part_m.len())
        || m.perception_error_by_part_m
            .iter()
            .any(|e| !(e.is_nan() || (e.is_finite() && *e >= 0.0)))
    {
        return Err(format!(
            "perception_error_by_part_m = {:?}: one distance per part (or NaN)",
            m.perception_error_by_part_m
        ));
    }
    // The separation: a number, or +inf when no pair ever came within range.
    let d = m.min_separation_m;
    if d.is_nan() || d == f64::NEG_INFINITY {
        return Err(format!("min_separation_m = {d}: must be a number"));
    }
    // The counts were counted from the separations whose smallest this is.
    let below = d < s.d_min_m;
    if below != (m.violations > 0) || below != (m.violation_s > 0.0) {
        return Err(format!(
            "violations = {} ({} s below d_min) contradicts min_separation_m = {d} against              d_min_m = {}",
            m.violations, m.violation_s, s.d_min_m
        ));
    }
    if m.violation_moving_s > m.violation_s * (1.0 + 1e-9) {
        return Err(format!(
            "violation_moving_s = {}: more than the {} s below d_min",
            m.violation_moving_s, m.violation_s
        ));
    }
    let contacts = m.contacts_moving + m.contacts_standing;
    if (d <= 0.0) != (contacts > 0) {
        return Err(format!(
            "contacts_moving + contacts_standing = {contacts} contradicts min_separation_m = {d}"
        ));
    }
    Ok(())
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
        record
            .check()
            .map_err(|e| bad(format!("{}: {e}", dir.display())))?;
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
    // Each record holds exactly its slice ([`RunRecord::check`]).
    for (dir, record) in &shards {
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

/// The name of the first setting in which `a` and `b` differ ("the settings" when none
/// does). Every field is named here: a field added to [`RunSettings`] does not compile
/// until it is.
fn differing_setting(a: &RunSettings, b: &RunSettings) -> &'static str {
    let RunSettings {
        evaluation_file,
        evaluation_toml,
        robot,
        filter,
        perception_arg,
        overrides,
        perception,
        first_seed,
        episodes,
        shards,
        replays_per_shard,
        d_min_m,
        near_m,
        pfl_distance_m,
        contact_speed_limits,
        other_arm_seen,
    } = a;
    let same_f64 = |x: &f64, y: &f64| x.to_bits() == y.to_bits();
    if *evaluation_toml != b.evaluation_toml {
        "the evaluation (evaluation.toml)"
    } else if !same_f64(d_min_m, &b.d_min_m) {
        "d_min_m"
    } else if !same_f64(near_m, &b.near_m) {
        "near_m"
    } else if !same_f64(pfl_distance_m, &b.pfl_distance_m) {
        "pfl_distance_m"
    } else if *filter != b.filter {
        "--filter"
    } else if *perception_arg != b.perception_arg || *perception != b.perception {
        "--perception"
    } else if *overrides != b.overrides {
        "--set"
    } else if *first_seed != b.first_seed {
        "--seed"
    } else if *episodes != b.episodes {
        "--episodes"
    } else if *shards != b.shards {
        "the number of shards"
    } else if *replays_per_shard != b.replays_per_shard {
        "--gltf"
    } else if *evaluation_file != b.evaluation_file {
        "the evaluation file's path"
    } else if *robot != b.robot {
        "the robot"
    } else if *contact_speed_limits != b.contact_speed_limits {
        "the contact speed limits"
    } else if *other_arm_seen != b.other_arm_seen {
        "other_arm_seen"
    } else {
        "the settings"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> RunSettings {
        RunSettings {
            evaluation_file: "eval.toml".into(),
            evaluation_toml: "task_s = 2.0\n".into(),
            robot: "ur5e".into(),
            filter: "qp".into(),
            perception_arg: None,
            overrides: Vec::new(),
            perception: "noisy camera".into(),
            first_seed: 1,
            episodes: 4,
            shards: 2,
            replays_per_shard: 0,
            d_min_m: 0.1,
            near_m: 0.5,
            pfl_distance_m: 0.5,
            contact_speed_limits: vec![("hand".into(), 1.35)],
            other_arm_seen: false,
        }
    }

    /// The first setting that differs is the one named: a changed d_min_m was reported as
    /// "the robot" (every field not listed fell through to it).
    #[test]
    fn the_differing_setting_is_named() {
        let a = settings();
        type Edit = fn(&mut RunSettings);
        let cases: [(Edit, &str); 5] = [
            (|s| s.d_min_m = 0.2, "d_min_m"),
            (|s| s.near_m = 0.6, "near_m"),
            (|s| s.pfl_distance_m = 0.0, "pfl_distance_m"),
            (|s| s.robot = "panda".into(), "the robot"),
            (
                |s| s.contact_speed_limits.clear(),
                "the contact speed limits",
            ),
        ];
        for (edit, expected) in cases {
            let mut b = settings();
            edit(&mut b);
            assert_eq!(differing_setting(&a, &b), expected);
        }
    }
}
