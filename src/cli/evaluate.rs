//! `workcell evaluate`: closed-loop safety episodes of a cell, with a report.

use std::fs;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Mutex;

use anyhow::{Context, Result, bail};
use rayon::prelude::*;
use workcell::evaluate::report::{
    Aggregate, SummaryContext, metrics_csv, summary_markdown, write_plots,
};
use workcell::evaluate::{Evaluation, EvaluationConfig, MaskKind, PerceptionKind, run_episode};
use workcell::safety::iso::effective_robot_mass_kg;
use workcell::safety::{BodyRegion, FilterMode, HumanPart};

/// Files `evaluate` writes into `--out`.
pub const OUTPUTS: [&str; 10] = [
    "summary.md",
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
    /// The cell's camera rendered, ProcNet's forearm mask, render-and-compare
    /// (`perception.weights`, `perception.camera` in the file).
    Procnet,
    /// As `procnet` with the forearm's true pixels for its mask: the pose search alone.
    PoseGtMasks,
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
}

impl EvaluateArgs {
    /// The command that replays episode `seed` exactly: the same file, overrides, filter and
    /// perception, one episode.
    #[must_use]
    pub fn replay_command(&self, path: &std::path::Path, seed: u64) -> String {
        let mut words = vec![
            "workcell".to_string(),
            "evaluate".to_string(),
            path.display().to_string(),
            "--episodes".to_string(),
            "1".to_string(),
            "--seed".to_string(),
            seed.to_string(),
            "--filter".to_string(),
            value_name(self.filter),
        ];
        if let Some(p) = self.perception {
            words.extend(["--perception".to_string(), value_name(p)]);
        }
        for o in &self.overrides {
            words.extend(["--set".to_string(), o.clone()]);
        }
        words.extend([
            "--out".to_string(),
            self.out
                .join(format!("replay-{seed}"))
                .display()
                .to_string(),
        ]);
        words
            .iter()
            .map(|w| shell_quote(w))
            .collect::<Vec<_>>()
            .join(" ")
    }
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
            Some(path) => Evaluation::from_file_with(path, &args.overrides)?.config,
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
    let mut evaluation = Evaluation::from_file_with(path, &args.overrides)?;
    if let Some(p) = args.perception {
        let perception = &mut evaluation.config.perception;
        perception.kind = match p {
            PerceptionArg::GroundTruth => PerceptionKind::GroundTruth,
            PerceptionArg::Noisy => PerceptionKind::Noisy,
            PerceptionArg::Procnet | PerceptionArg::PoseGtMasks => PerceptionKind::Procnet,
        };
        match p {
            PerceptionArg::Procnet => perception.masks = MaskKind::Network,
            PerceptionArg::PoseGtMasks => perception.masks = MaskKind::GroundTruth,
            _ => {}
        }
    }
    let mode = match args.filter {
        FilterArg::None => FilterMode::None,
        FilterArg::Qp => FilterMode::Qp,
        FilterArg::Ssm => FilterMode::Ssm,
    };
    let out = super::OutputDir::create(&args.out, args.force, &OUTPUTS)?;

    let bar = super::progress_bar(
        (args.episodes * 100) as u64,
        "{spinner} {msg} [{bar:40}] {percent}% (eta {eta})",
    );
    bar.set_message(format!("{} episodes, filter {mode}", args.episodes));
    let first_error: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    let mut results: Vec<_> = (0..args.episodes)
        .into_par_iter()
        .filter_map(|episode| {
            let seed = args.seed.wrapping_add(episode as u64);
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
    let (episodes, traces): (Vec<_>, Vec<_>) = results.into_iter().unzip();

    // The report.
    let robot = workcell::robots::RobotModel::load(
        &workcell::sim::Scenario::resolve_model_path(
            &evaluation.scenario.robot.model,
            &evaluation.scenario_path,
        ),
        &workcell::robots::PackageMap::from_env(),
    )?;
    let m_r = effective_robot_mass_kg(robot.mass_kg(), evaluation.config.safety.payload_kg);
    let limits: Vec<(String, f64)> = if m_r > 0.0 {
        HumanPart::ARM
            .iter()
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
    let perception = evaluation.config.perception.describe();
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let context = SummaryContext {
        evaluation_file: &path.display().to_string(),
        robot: robot.name(),
        filter: &mode.to_string(),
        perception: &perception,
        d_min_m: evaluation.config.safety.d_min_m,
        near_m: evaluation.config.near_m,
        pfl_distance_m: if evaluation.config.safety.pfl_distance_m > 0.0 {
            evaluation.config.safety.pfl_distance_m
        } else {
            evaluation.config.near_m
        },
        contact_speed_limits: &limits,
        command: &command,
    };
    let write = |name: &str, text: &str| {
        let p = out.path().join(name);
        fs::write(&p, text).with_context(|| format!("writing {}", p.display()))
    };
    write("summary.md", &summary_markdown(&context, &episodes))?;
    let violating: Vec<_> = episodes.iter().filter(|e| e.violations > 0).collect();
    let mut replay = format!(
        "# Episodes that came closer than d_min = {} m: seed, violations, smallest separation, \
         and the command that replays exactly that episode.\n",
        evaluation.config.safety.d_min_m
    );
    for e in &violating {
        replay.push_str(&format!(
            "{}\t{}\t{:.4}\t{}\n",
            e.seed,
            e.violations,
            e.min_separation_m,
            args.replay_command(path, e.seed)
        ));
    }
    write("violations.txt", &replay)?;
    write("metrics.csv", &metrics_csv(&episodes))?;
    write(
        "evaluation.toml",
        &toml::to_string_pretty(&evaluation.config).context("serialising the configuration")?,
    )?;
    write_plots(
        out.path(),
        &episodes,
        &traces,
        evaluation.config.safety.d_min_m,
    )?;

    out.commit()?;
    let a = Aggregate::of(&episodes);
    // A closed pipe (`| head`) is not an error: the report is already written.
    say!(
        "{} episodes, filter {mode}, perception {perception}: {}",
        a.episodes,
        a.headline(evaluation.config.safety.d_min_m)
    );
    say!(
        "closed loop at {:.1}x real time per core; report: {}",
        a.real_time_factor,
        args.out.join("summary.md").display()
    );
    if let Some(first) = violating.first() {
        say!(
            "{} violating episodes (seeds in {}); replay the first: {}",
            violating.len(),
            args.out.join("violations.txt").display(),
            args.replay_command(path, first.seed)
        );
    }
    if args.fail_on_violation && a.violations > 0 {
        return Ok(ExitCode::from(2));
    }
    Ok(ExitCode::SUCCESS)
}
