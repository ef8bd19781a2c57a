//! `workcell evaluate`: closed-loop safety episodes of a cell, with a report.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use workcell::evaluate::html::{PageReplay, replay_script, summary_html};
use workcell::evaluate::perception::procnet::camera_coverage_warning;
use workcell::evaluate::record::{
    KeptTrace, PLOTTED_EPISODES, RUN_RECORD, RUN_RECORD_FORMAT, RunRecord, RunSettings,
    shard_episodes, worst_episodes,
};
use workcell::evaluate::replay::episode_glb;
use workcell::evaluate::report::{
    Aggregate, SummaryContext, metrics_csv, summary_markdown, write_plots,
};
use workcell::evaluate::{
    Evaluation, EvaluationConfig, PerceptionConfig, PerceptionKind, record_episode, run_episode,
};
use workcell::safety::iso::effective_robot_mass_kg;
use workcell::safety::{BodyRegion, FilterMode};

/// Files `evaluate` writes into `--out`.
pub const OUTPUTS: [&str; 14] = [
    "summary.md",
    "summary.html",
    VIEWER_JS,
    RUN_RECORD,
    REPLAYS_DIR,
    "violations.txt",
    "metrics.csv",
    "evaluation.toml",
    "separation.png",
    "separation.svg",
    "speed_scaling.png",
    "speed_scaling.svg",
    "perception_error.png",
    "perception_error.svg",
];

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FilterArg {
    /// No filter: the nominal command goes to the robot.
    None,
    /// The QP safety filter.
    Qp,
    /// Speed and separation monitoring (speed scaling).
    Ssm,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PerceptionArg {
    /// Exact human poses every tick.
    GroundTruth,
    /// A 30 Hz camera with noise, dropouts and latency (settings in the file).
    Noisy,
    /// The cell's camera rendered, ProcNet's mask of every arm part, the articulated fit
    /// (`perception.weights`, `.camera`, `.depth`, `.occlusion` in the file).
    Procnet,
    /// As `procnet` with every arm part's true pixels for its masks: the fit alone.
    PoseGtMasks,
    /// As `procnet` with the true joints at each frame in place of masks and fit: the
    /// camera's rate and latency alone (the bound of a perfect network and fit).
    PoseGt,
}

impl PerceptionArg {
    /// The kind of `[perception]` this choice makes the file's, and the `--set` override it
    /// adds to the user's (which masks the fit reads).
    fn kind(self) -> (PerceptionKind, Option<String>) {
        let masks = |m: &str| Some(format!("perception.masks = \"{m}\""));
        match self {
            PerceptionArg::GroundTruth => (PerceptionKind::GroundTruth, None),
            PerceptionArg::Noisy => (PerceptionKind::Noisy, None),
            PerceptionArg::Procnet => (PerceptionKind::Procnet, masks("network")),
            PerceptionArg::PoseGtMasks => (PerceptionKind::Procnet, masks("ground_truth")),
            PerceptionArg::PoseGt => (PerceptionKind::Procnet, masks("true_pose")),
        }
    }
}

/// `path` as `--perception` (when given) and the `--set` overrides make it: the file's
/// `[perception]` switched to the chosen kind first (a note names the keys of the file that
/// the new kind does not take), then the overrides, the choice's own last.
fn load(
    path: &Path,
    perception: Option<PerceptionArg>,
    overrides: &[String],
) -> Result<Evaluation> {
    let (kind, own) = perception.map(PerceptionArg::kind).unzip();
    let mut overrides = overrides.to_vec();
    overrides.extend(own.flatten());
    let (evaluation, dropped) = Evaluation::from_file_as(path, kind, &overrides)?;
    if let (Some(kind), false) = (kind, dropped.is_empty()) {
        eprintln!(
            "note: --perception {} leaves out the file's {} (keys of its other kind)",
            kind.name(),
            dropped.join(", ")
        );
    }
    Ok(evaluation)
}

#[derive(Debug, clap::Args)]
pub struct EvaluateArgs {
    /// Evaluation file (TOML), e.g. configs/evaluate.toml.
    pub evaluation: Option<PathBuf>,
    /// Number of episodes, seeds SEED, SEED+1, ... (1 to 1,000,000).
    #[arg(long, default_value_t = 10, value_parser = super::count_in::<1, 1_000_000>)]
    pub episodes: usize,
    /// Seed of the first episode.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The safety filter.
    #[arg(long, value_enum, default_value_t = FilterArg::Qp)]
    pub filter: FilterArg,
    /// Override the file's perception kind.
    #[arg(long, value_enum)]
    pub perception: Option<PerceptionArg>,
    /// Output folder (created; existing outputs are kept unless --force).
    #[arg(long, default_value = "out/evaluate")]
    pub out: PathBuf,
    /// Overwrite existing output files.
    #[arg(long)]
    pub force: bool,
    /// Exit with status 2 when any episode violates d_min (for scripts and CI).
    #[arg(long)]
    pub fail_on_violation: bool,
    /// Print the evaluation file with every default filled in, then exit.
    #[arg(long)]
    pub print_defaults: bool,
    /// Override a key of the evaluation file, e.g. `--set safety.gamma_per_s=8`
    /// (repeatable; TOML values).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
    /// Run only shard K of N (1-based): episodes K-1, K-1+N, ... of the --episodes. The
    /// shards' folders merge into the whole run's report with `workcell report merge`.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub shard: Option<(usize, usize)>,
    /// Write the N episodes with the smallest separation as animated binary glTF
    /// (`replays/episode-SEED.glb`: robot, human, closest pair, cameras, clutter); each is run
    /// again with a recorder (0 to 100).
    #[arg(long, value_name = "N", default_value_t = 0, value_parser = super::count_in::<0, 100>)]
    pub gltf: usize,
}

/// The folder of the 3D replays inside an evaluation's output.
pub const REPLAYS_DIR: &str = "replays/";

/// The 3D replay viewer beside `summary.html` (built by `scripts/fetch-viewer.sh`).
pub const VIEWER_JS: &str = "viewer.js";

/// The viewer bundle to copy beside the page: `WORKCELL_VIEWER_JS`, else where
/// `scripts/fetch-viewer.sh` puts it; `None` when neither is a file.
fn viewer_bundle() -> Option<PathBuf> {
    std::env::var_os("WORKCELL_VIEWER_JS")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .map(|h| PathBuf::from(h).join(".cache/workcell/viewer/workcell-viewer.js"))
        })
        .filter(|p| p.is_file())
}

/// Replays sample the cell at this rate, Hz.
pub const REPLAY_RATE_HZ: f64 = 30.0;

/// The command that replays episode `seed` of the run `settings` describes exactly: the same
/// file, overrides, filter and perception, one episode, into `out/replay-SEED`.
#[must_use]
pub fn replay_command(settings: &RunSettings, out: &Path, seed: u64) -> String {
    let mut words = vec![
        "workcell".to_string(),
        "evaluate".to_string(),
        settings.evaluation_file.clone(),
        "--episodes".to_string(),
        "1".to_string(),
        "--seed".to_string(),
        seed.to_string(),
        "--filter".to_string(),
        settings.filter.clone(),
    ];
    if let Some(p) = &settings.perception_arg {
        words.extend(["--perception".to_string(), p.clone()]);
    }
    for o in &settings.overrides {
        words.extend(["--set".to_string(), o.clone()]);
    }
    words.extend([
        "--out".to_string(),
        out.join(format!("replay-{seed}")).display().to_string(),
    ]);
    words
        .iter()
        .map(|w| shell_quote(w))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `K/N`: shard K (1-based) of N.
fn parse_shard(text: &str) -> Result<(usize, usize), String> {
    let (k, n) = text
        .split_once('/')
        .ok_or_else(|| format!("expected K/N, e.g. 2/8, got {text:?}"))?;
    let k: usize = k
        .trim()
        .parse()
        .map_err(|_| format!("K in K/N is not a count: {text:?}"))?;
    let n = super::count_in::<1, 1_000_000>(n.trim())?;
    if !(1..=n).contains(&k) {
        return Err(format!("K in K/N must be within 1..=N, got {text:?}"));
    }
    Ok((k, n))
}

/// The name clap gives a value on the command line.
fn value_name(v: impl clap::ValueEnum) -> String {
    v.to_possible_value()
        .map_or_else(String::new, |p| p.get_name().to_string())
}

/// `word` quoted for a POSIX shell when it needs it.
fn shell_quote(word: &str) -> String {
    let plain = !word.is_empty()
        && word
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
    if plain {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
    }
}

pub fn run(args: &EvaluateArgs) -> Result<ExitCode> {
    if args.print_defaults {
        let config = match &args.evaluation {
            Some(path) => load(path, args.perception, &args.overrides)?.config,
            None => EvaluationConfig::default(),
        };
        say_inline!(
            "{}",
            toml::to_string_pretty(&config).context("serialising the configuration")?
        );
        return Ok(ExitCode::SUCCESS);
    }
    let Some(path) = &args.evaluation else {
        bail!("give an evaluation file, e.g. `workcell evaluate configs/evaluate.toml`");
    };
    if args.episodes == 0 {
        bail!("--episodes must be at least 1");
    }
    // Episode i has seed SEED + i: the last one must not wrap around to seed 0.
    let last_episode = u64::try_from(args.episodes - 1).unwrap_or(u64::MAX);
    if args.seed.checked_add(last_episode).is_none() {
        bail!(
            "--seed {}: {} episodes would need seeds past the largest, {} (at most --seed {})",
            args.seed,
            args.episodes,
            u64::MAX,
            u64::MAX - last_episode
        );
    }
    let evaluation = load(path, args.perception, &args.overrides)?;
    if let PerceptionConfig::Procnet(p) = &evaluation.config.perception {
        let model = workcell::sim::CellModel::new(&evaluation.scenario, &evaluation.scenario_path)?;
        if let Some(warning) = camera_coverage_warning(p, &evaluation.scenario, &model)? {
            tracing::warn!("{warning}");
        }
    }
    let mode = match args.filter {
        FilterArg::None => FilterMode::None,
        FilterArg::Qp => FilterMode::Qp,
        FilterArg::Ssm => FilterMode::Ssm,
    };
    let (shard, shards) = args.shard.unwrap_or((1, 1));
    let slice = shard_episodes(shard, shards, args.episodes)?;
    let out = super::OutputDir::create(&args.out, args.force, &OUTPUTS)?;

    let bar = super::progress_bar(
        (slice.len() * 100) as u64,
        "{spinner} {msg} [{bar:40}] {percent}% (eta {eta})",
    );
    bar.set_message(if shards > 1 {
        format!(
            "shard {shard}/{shards}: {} of {} episodes, filter {mode}",
            slice.len(),
            args.episodes
        )
    } else {
        format!("{} episodes, filter {mode}", args.episodes)
    });
    let first_error: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    let mut results: Vec<_> = slice
        .par_iter()
        .filter_map(|&episode| {
            // Checked above: SEED + episodes - 1 fits.
            let seed = args.seed + episode as u64;
            let mut shown = 0u64;
            let result = run_episode(&evaluation, mode, episode, seed, None, |fraction| {
                let now = (fraction * 100.0) as u64;
                if now > shown {
                    bar.inc(now - shown);
                    shown = now;
                }
            });
            match result {
                Ok(r) => Some(r),
                Err(e) => {
                    if let Ok(mut slot) = first_error.lock() {
                        slot.get_or_insert(
                            anyhow::Error::new(e)
                                .context(format!("episode {episode} (seed {seed})")),
                        );
                    }
                    None
                }
            }
        })
        .collect();
    bar.finish_and_clear();
    if let Some(e) = first_error.into_inner().ok().flatten() {
        return Err(e);
    }
    results.sort_by_key(|(m, _)| m.episode);
    let (metrics, mut traces): (Vec<_>, Vec<_>) = results.into_iter().unzip();
    let kept: Vec<KeptTrace> = worst_episodes(&metrics, PLOTTED_EPISODES)
        .into_iter()
        .map(|i| KeptTrace {
            episode: metrics[i].episode,
            trace: std::mem::take(&mut traces[i]),
        })
        .collect();

    let load = |model: &str| {
        workcell::robots::RobotModel::load(
            &workcell::sim::Scenario::resolve_model_path(model, &evaluation.scenario_path),
            &workcell::robots::PackageMap::from_env(),
        )
    };
    let robot = load(&evaluation.scenario.robot.model)?;
    let m_r = effective_robot_mass_kg(robot.mass_kg(), evaluation.config.safety.payload_kg);
    // The guarded parts the human model has (the arm's; `human` also a head of its own).
    let human = load(&evaluation.scenario.human.model)?;
    let contact_speed_limits: Vec<(String, f64)> = if m_r > 0.0 {
        workcell::evaluate::PFL_PARTS
            .iter()
            .filter(|p| human.link_id(p.link_name()).is_some())
            .map(|&p| {
                (
                    p.to_string(),
                    BodyRegion::of(p).max_contact_speed_m_s(m_r, true),
                )
            })
            .collect()
    } else {
        Vec::new()
    };
    // The worst episodes again, recorded, as 3D replays.
    let mut replays = Vec::new();
    if args.gltf > 0 {
        let dir = out.path().join(REPLAYS_DIR);
        fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let cameras: Vec<(String, workcell::render::Camera)> = evaluation
            .scenario
            .cameras
            .iter()
            .filter_map(|c| c.camera().ok().map(|cam| (c.name.clone(), cam)))
            .collect();
        let worst = worst_episodes(&metrics, args.gltf);
        let bar = super::progress_bar(worst.len() as u64, "{spinner} {msg} [{bar:40}] {pos}/{len}");
        bar.set_message("3D replays of the worst episodes");
        for i in worst {
            let m = &metrics[i];
            let (again, _, recording) =
                record_episode(&evaluation, mode, m.episode, m.seed, 1.0 / REPLAY_RATE_HZ)?;
            // Determinism: the recorded run is the same episode (wall time aside).
            if again.min_separation_m.to_bits() != m.min_separation_m.to_bits() {
                bail!(
                    "episode {} (seed {}) did not replay identically: min separation {} m, then {} m",
                    m.episode,
                    m.seed,
                    m.min_separation_m,
                    again.min_separation_m
                );
            }
            let mut scenario = evaluation.scenario.clone();
            scenario.seed = m.seed;
            let model = workcell::sim::CellModel::new(&scenario, &evaluation.scenario_path)?;
            let glb = episode_glb(
                &model,
                &cameras,
                &recording,
                evaluation.config.safety.d_min_m,
                &format!("episode {} (seed {})", m.episode, m.seed),
            );
            let file = format!("{REPLAYS_DIR}episode-{}.glb", m.seed);
            let path = out.path().join(&file);
            fs::write(&path, glb).with_context(|| format!("writing {}", path.display()))?;
            replays.push((m.episode, file));
            bar.inc(1);
        }
        bar.finish_and_clear();
        replays.sort();
    }

    let c = &evaluation.config;
    let record = RunRecord {
        format: RUN_RECORD_FORMAT,
        settings: RunSettings {
            evaluation_file: path.display().to_string(),
            evaluation_toml: toml::to_string_pretty(c).context("serialising the configuration")?,
            robot: robot.name().to_string(),
            filter: value_name(args.filter),
            perception_arg: args.perception.map(value_name),
            overrides: args.overrides.clone(),
            perception: c.perception.describe(),
            first_seed: args.seed,
            episodes: args.episodes,
            shards,
            replays_per_shard: args.gltf,
            d_min_m: c.safety.d_min_m,
            near_m: c.near_m,
            pfl_distance_m: if c.safety.pfl_distance_m > 0.0 {
                c.safety.pfl_distance_m
            } else {
                c.near_m
            },
            contact_speed_limits,
            other_arm_seen: c.other_arm_is_seen(),
        },
        shard,
        metrics,
        traces: kept,
        replays,
    };
    finish_report(out, &record, &args.out, args.fail_on_violation)
}

/// Writes the report of `record` into the staged `out` (whose final place is `out_path`),
/// moves it into place, prints the headline, and gives the exit status: 2 for a violation
/// when `fail_on_violation`.
///
/// # Errors
/// As [`write_report`], and a failed move into place.
pub fn finish_report(
    out: super::OutputDir,
    record: &RunRecord,
    out_path: &Path,
    fail_on_violation: bool,
) -> Result<ExitCode> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    write_report(out.path(), record, &command, out_path)?;
    out.commit()?;
    let violating = announce(record, out_path);
    if fail_on_violation && violating > 0 {
        return Ok(ExitCode::from(2));
    }
    Ok(ExitCode::SUCCESS)
}

/// Writes the report of `record` into `dir`: the summary, the violations with their replay
/// commands (into `out/replay-SEED`), the metrics, the settings, the plots and the record.
///
/// # Errors
/// A file that cannot be written, named.
pub fn write_report(dir: &Path, record: &RunRecord, command: &str, out: &Path) -> Result<()> {
    let s = &record.settings;
    let mut evaluation_file = s.evaluation_file.clone();
    if s.shards > 1 {
        evaluation_file.push_str(&format!(
            " (shard {} of {}: episodes {}, {}, ... of {})",
            record.shard,
            s.shards,
            record.shard - 1,
            record.shard - 1 + s.shards,
            s.episodes
        ));
    }
    let context = SummaryContext {
        evaluation_file: &evaluation_file,
        robot: &s.robot,
        filter: &s.filter,
        perception: &s.perception,
        d_min_m: s.d_min_m,
        near_m: s.near_m,
        pfl_distance_m: s.pfl_distance_m,
        contact_speed_limits: &s.contact_speed_limits,
        command,
        other_arm_seen: s.other_arm_seen,
    };
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        fs::write(&p, text).with_context(|| format!("writing {}", p.display()))
    };
    let episodes = &record.metrics;
    let markdown = summary_markdown(&context, episodes);
    write("summary.md", &markdown)?;
    // The page: the same summary, and the replays with the viewer when it is at hand.
    let mut page_replays = Vec::new();
    // Worst first.
    let mut listed: Vec<&(usize, String)> = record.replays.iter().collect();
    let separation = |e: usize| {
        episodes
            .iter()
            .find(|m| m.episode == e)
            .map_or(f64::INFINITY, |m| m.min_separation_m)
    };
    listed.sort_by(|a, b| {
        separation(a.0)
            .total_cmp(&separation(b.0))
            .then(a.0.cmp(&b.0))
    });
    for (episode, file) in listed {
        let glb_path = dir.join(file);
        let glb = workcell::robots::input::read_regular_file(
            &glb_path,
            workcell::robots::input::MAX_MESH_BYTES,
        )
        .with_context(|| format!("reading {}", glb_path.display()))?;
        let m = episodes.iter().find(|m| m.episode == *episode);
        let label = m.map_or_else(
            || format!("episode {episode}"),
            |m| {
                format!(
                    "episode {} (seed {}): min separation {:.3} m, {} violations",
                    m.episode, m.seed, m.min_separation_m, m.violations
                )
            },
        );
        let script = file.replace(".glb", ".js");
        write(&script, &replay_script(&label, &glb))?;
        page_replays.push(PageReplay {
            label,
            script,
            glb: file.clone(),
        });
    }
    let viewer = if page_replays.is_empty() {
        None
    } else {
        viewer_bundle()
    };
    if let Some(bundle) = &viewer {
        let to = dir.join(VIEWER_JS);
        // WORKCELL_VIEWER_JS names it: a regular file of bounded size like any other input.
        let js = workcell::robots::input::read_regular_file(
            bundle,
            workcell::robots::input::MAX_CONFIG_BYTES,
        )
        .with_context(|| format!("reading {}", bundle.display()))?;
        fs::write(&to, js).with_context(|| format!("writing {}", to.display()))?;
    }
    write(
        "summary.html",
        &summary_html(&markdown, &page_replays, viewer.is_some()),
    )?;
    let mut replay = format!(
        "# Episodes that came closer than d_min = {} m (the modelled human, or a recorded \
         person's other arm): seed, violations of the modelled human, its smallest separation, \
         where it was (robot link / human part, the side in the part's name: `left_hand`), the \
         left arm's smallest separation (- without one), and the command that replays exactly \
         that episode.\n",
        s.d_min_m
    );
    for e in episodes.iter().filter(|e| e.violated()) {
        let left = if e.other_arm_min_separation_m.is_nan() {
            "-".to_string()
        } else {
            format!("{:.4}", e.other_arm_min_separation_m)
        };
        replay.push_str(&format!(
            "{}\t{}\t{:.4}\t{}\t{left}\t{}\n",
            e.seed,
            e.violations,
            e.min_separation_m,
            e.closest,
            replay_command(s, out, e.seed)
        ));
    }
    write("violations.txt", &replay)?;
    write("metrics.csv", &metrics_csv(episodes))?;
    write("evaluation.toml", &s.evaluation_toml)?;
    write_plots(dir, &record.worst(), s.d_min_m)?;
    write(RUN_RECORD, &record.to_json()?)?;
    Ok(())
}

/// Prints the run's headline, where the report is, and how to replay the first violating
/// episode; returns the number of violating episodes.
pub fn announce(record: &RunRecord, out: &Path) -> usize {
    let s = &record.settings;
    let a = Aggregate::of(&record.metrics);
    // A closed pipe (`| head`) is not an error: the report is already written.
    say!(
        "{} episodes, filter {}, perception {}: {}",
        a.episodes,
        s.filter,
        s.perception,
        a.headline(s.d_min_m)
    );
    say!(
        "closed loop at {:.2}x real time per core ({:.2}x with each episode's setup); report: {}",
        a.real_time_factor,
        a.real_time_with_setup,
        out.join("summary.md").display()
    );
    if let Some(line) =
        workcell::evaluate::report::other_arm_line(&record.metrics, s.d_min_m, s.other_arm_seen)
    {
        say!("{line}");
    }
    let violating: Vec<_> = record.metrics.iter().filter(|e| e.violated()).collect();
    if let Some(first) = violating.first() {
        say!(
            "{} violating episodes (seeds in {}); replay the first: {}",
            violating.len(),
            out.join("violations.txt").display(),
            replay_command(s, out, first.seed)
        );
    }
    violating.len()
}

#[derive(Debug, clap::Args)]
pub struct BenchPerceptionArgs {
    /// Evaluation file whose cell, camera and `[perception]` settings are timed.
    #[arg(default_value = "configs/evaluate.toml")]
    pub evaluation: PathBuf,
    /// Frames of the cell's camera, at its rate from the start of the episode (1 to 100,000).
    #[arg(long, default_value_t = 300, value_parser = super::count_in::<1, 100_000>)]
    pub frames: usize,
    /// Seed of the episode (the human's motion).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The camera measures depth: the fit uses it (sets `perception.depth`).
    #[arg(long)]
    pub depth: bool,
    /// CPU threads of the network and of the fit's renders (1 to 256).
    #[arg(long, default_value_t = 2, value_parser = super::count_in::<1, { super::MAX_THREADS }>)]
    pub threads: usize,
    /// Override a key of the evaluation file (repeatable; TOML values).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub overrides: Vec<String>,
}

/// Times ProcNet and the articulated fit frame by frame on the cell's camera and prints a
/// table: each stage's mean, median, 95th percentile and worst, and the share of frames
/// within a 30 Hz camera's 33.3 ms.
pub fn bench_perception(args: &BenchPerceptionArgs) -> Result<ExitCode> {
    let mut overrides = args.overrides.clone();
    if args.depth {
        overrides.push("perception.depth = true".into());
    }
    // The tracker is what is timed: the file's perception as procnet.
    let (evaluation, _) =
        Evaluation::from_file_as(&args.evaluation, Some(PerceptionKind::Procnet), &overrides)?;
    workcell::procnet::backend::set_threads(args.threads);
    let bar = super::progress_bar(
        args.frames as u64,
        "{spinner} frames [{bar:40}] {pos}/{len}",
    );
    let timings =
        workcell::evaluate::procnet::bench_tracker(&evaluation, args.seed, args.frames, |k| {
            bar.set_position(k as u64)
        })?;
    bar.finish_and_clear();
    let PerceptionConfig::Procnet(p) = &evaluation.config.perception else {
        bail!("the tracker is timed on a procnet perception");
    };
    say!(
        "perception on {} frames of the cell's camera ({}; seed {}), {}, weights {}, network and fit on {} thread(s)",
        timings.len(),
        args.evaluation.display(),
        args.seed,
        if p.depth { "RGB-D" } else { "RGB" },
        p.weights_path().display(),
        args.threads,
    );
    say!();
    say!(
        "| stage | frames | mean (ms) | median (ms) | 95th pct (ms) | worst (ms) | part renders a frame, mean |"
    );
    say!("|---|---|---|---|---|---|---|");
    let row = |name: &str, v: Vec<(f64, Option<usize>)>| {
        if v.is_empty() {
            say!("| {name} | 0 | - | - | - | - | - |");
            return;
        }
        let renders: Vec<usize> = v.iter().filter_map(|(_, r)| *r).collect();
        let renders = if renders.is_empty() {
            "-".to_string()
        } else {
            format!(
                "{:.0}",
                renders.iter().sum::<usize>() as f64 / renders.len() as f64
            )
        };
        let mut s: Vec<f64> = v.iter().map(|(ms, _)| *ms).collect();
        s.sort_by(f64::total_cmp);
        let q = |f: f64| s[((f * s.len() as f64) as usize).min(s.len() - 1)];
        say!(
            "| {name} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {renders} |",
            s.len(),
            s.iter().sum::<f64>() / s.len() as f64,
            q(0.5),
            q(0.95),
            s[s.len() - 1]
        );
    };
    // Each stage's time, and the fit's renders where the stage is the fit's.
    type Stage<'a> = &'a dyn Fn(&workcell::evaluate::procnet::FrameTiming) -> Option<f64>;
    let stage = |f: Stage, fit: bool| -> Vec<(f64, Option<usize>)> {
        timings
            .iter()
            .filter_map(|t| f(t).map(|ms| (ms, (fit && t.estimate).then_some(t.renders))))
            .collect()
    };
    let pick = |f: Stage| stage(f, false);
    let fits = |f: Stage| stage(f, true);
    row(
        "render (the simulator's camera)",
        pick(&|t| Some(t.render_ms)),
    );
    row(
        "network (region of interest + ProcNet)",
        pick(&|t| Some(t.network_ms)),
    );
    row(
        "fit, tracked frames",
        fits(&|t| (!t.reacquired).then_some(t.fit_ms)),
    );
    row(
        "fit with the global search (no track, or a poor one)",
        fits(&|t| t.reacquired.then_some(t.fit_ms)),
    );
    let total = pick(&|t| Some(t.network_ms + t.fit_ms));
    let within = total.iter().filter(|&&(ms, _)| ms <= 1e3 / 30.0).count();
    row("**network + fit**", total);
    say!();
    say!(
        "{} of {} frames gave an estimate; {} of {} within 33.3 ms (a 30 Hz camera's period)",
        timings.iter().filter(|t| t.estimate).count(),
        timings.len(),
        within,
        timings.len()
    );
    Ok(ExitCode::SUCCESS)
}
