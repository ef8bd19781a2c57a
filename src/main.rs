//! The `workcell` command line.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cli;

#[derive(Debug, Parser)]
#[command(
    name = "workcell",
    version,
    about = "Safety of human-robot collaboration: simulated work-cells, robots from URDF"
)]
struct Args {
    /// Log filter (e.g. `info`, `workcell_sim=debug`); also read from RUST_LOG. MuJoCo's own
    /// warnings (target `mujoco`) are shown from `mujoco=warn`: the cross-check reports an
    /// unstable integrator in its table.
    #[arg(long, global = true, default_value = "warn,mujoco=error")]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Robots: check a URDF or catalogue model, list the catalogue.
    Robot {
        #[command(subcommand)]
        command: RobotCommand,
    },
    /// Compare a robot's rapier model with MuJoCo: kinematics, mass matrix, gravity,
    /// trajectories (needs the `mujoco` feature).
    Crosscheck(cli::crosscheck::CrosscheckArgs),
    /// Closed-loop safety evaluation: episodes of a cell with a safety filter and a report.
    Evaluate(cli::evaluate::EvaluateArgs),
    /// Reports made from evaluations' run records: merge the shards of one evaluation, tabulate
    /// a sweep.
    Report {
        #[command(subcommand)]
        command: ReportCommand,
    },
    /// Run a scenario and write joint trajectories and human part poses (CSV) and a plot.
    Simulate(cli::simulate::SimulateArgs),
    /// Recorded human motion: how fast people's joints move, beside the generator's.
    Human {
        #[command(subcommand)]
        command: HumanCommand,
    },
    /// Camera datasets for ProcNet: generate them, look at them.
    Dataset {
        #[command(subcommand)]
        command: DatasetCommand,
    },
    /// Train ProcNet on a dataset (resumable; progress bar, checkpoints, metrics, curves).
    Train(cli::perception::TrainArgs),
    /// Time ProcNet's training step and inference per backend (JSON lines).
    Bench(cli::perception::BenchArgs),
    /// Time perception frame by frame on the cell's camera: ProcNet and the articulated
    /// fit, a table of each stage.
    BenchPerception(cli::evaluate::BenchPerceptionArgs),
    /// Evaluate trained models.
    Eval {
        #[command(subcommand)]
        command: EvalCommand,
    },
}

#[derive(Debug, Subcommand)]
enum EvalCommand {
    /// ProcNet segmentation on a dataset split: Dice, focal and IoU per class and group.
    Segmentation(cli::perception::EvalSegmentationArgs),
    /// The forearm's pose by render-and-compare from gt, visible or ProcNet masks: Table 2's
    /// layout with the paper's numbers, per-frame CSV, error against distance.
    Pose(cli::pose::EvalPoseArgs),
}

#[derive(Debug, Subcommand)]
enum ReportCommand {
    /// Merge the folders of `evaluate --shard K/N` runs into the report a single process
    /// would have written (metrics, verdict, plots, violations with replay commands).
    Merge(cli::report::MergeArgs),
    /// The table and trade-off plot of a sweep's points (violations and task time per point).
    Sweep(cli::report::SweepArgs),
    /// Training runs side by side: their validation forearm Dice loss on one plot, and a
    /// table of each run's last and best (seeds, recipes, ProcNet against the baseline).
    Training(cli::perception::TrainingReportArgs),
}

#[derive(Debug, Subcommand)]
enum DatasetCommand {
    /// Render seeded episodes of a cell into occluded frame sequences with ground truth.
    Generate(cli::dataset::GenerateArgs),
    /// Write a contact sheet PNG of a dataset (frames, masks, occlusion) and summarise it.
    Show(cli::dataset::ShowArgs),
    /// Measure what a dataset gives a network: the forearm's pixels and width in the stored
    /// frames and the Dice loss of a perfect network, per source, distance class and crop.
    Stats(cli::dataset::StatsArgs),
}

#[derive(Debug, Subcommand)]
enum HumanCommand {
    /// Per part (wrist, elbow, shoulder, head, trunk): the peak, 99.9th and 99th percentile
    /// speed and acceleration of recorded clips (cleaned of capture artefacts, low-pass
    /// filtered), each library's tuning and test clips apart, and the generator's beside them.
    Stats(cli::human::StatsArgs),
    /// Lay clips on the cell's human model (inverse kinematics within its joint and velocity
    /// limits) and report, per clip, how far its wrist and elbow stay from the recording.
    Retarget(cli::human::RetargetArgs),
}

#[derive(Debug, Subcommand)]
enum RobotCommand {
    /// Parse a URDF (or catalogue name), resolve its meshes, load it into rapier, report.
    Check(cli::robot::CheckArgs),
    /// List the built-in robots and those added to the robot library.
    List,
    /// Add a vendor URDF to the robot library: copy it with its meshes, render a preview,
    /// check it (and cross-check it with MuJoCo when built with the `mujoco` feature).
    Add(cli::robot::AddArgs),
}

fn main() -> ExitCode {
    let args = Args::parse();
    // Panics inside the mesh decoder are caught and reported as errors naming the file; keep
    // the default panic message for everything else.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let in_decoder = info.location().is_some_and(|l| {
            workcell::robots::DECODER_CRATES
                .iter()
                .any(|c| l.file().contains(c))
        });
        if !in_decoder {
            default_hook(info);
        }
    }));
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .or_else(|_| tracing_subscriber::EnvFilter::try_new(&args.log))
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .init();
    let result = match args.command {
        Command::Robot {
            command: RobotCommand::Check(a),
        } => cli::robot::check(&a),
        Command::Robot {
            command: RobotCommand::List,
        } => cli::robot::list(),
        Command::Robot {
            command: RobotCommand::Add(a),
        } => cli::robot::add(&a),
        Command::Evaluate(a) => cli::evaluate::run(&a),
        Command::Report {
            command: ReportCommand::Merge(a),
        } => cli::report::merge_shards(&a),
        Command::Report {
            command: ReportCommand::Sweep(a),
        } => cli::report::sweep_table(&a),
        Command::Report {
            command: ReportCommand::Training(a),
        } => cli::perception::training_report(&a),
        Command::Crosscheck(a) => cli::crosscheck::run(&a),
        Command::Simulate(a) => cli::simulate::run(&a),
        Command::Human {
            command: HumanCommand::Stats(a),
        } => cli::human::stats(&a),
        Command::Human {
            command: HumanCommand::Retarget(a),
        } => cli::human::retarget(&a),
        Command::Dataset {
            command: DatasetCommand::Generate(a),
        } => cli::dataset::generate(&a),
        Command::Dataset {
            command: DatasetCommand::Show(a),
        } => cli::dataset::show(&a),
        Command::Dataset {
            command: DatasetCommand::Stats(a),
        } => cli::dataset::stats(&a),
        Command::Train(a) => cli::perception::train(&a),
        Command::Bench(a) => cli::perception::bench(&a),
        Command::BenchPerception(a) => cli::evaluate::bench_perception(&a),
        Command::Eval {
            command: EvalCommand::Segmentation(a),
        } => cli::perception::eval_segmentation(&a),
        Command::Eval {
            command: EvalCommand::Pose(a),
        } => cli::pose::eval_pose(&a),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// Parses `name=folder` package mappings.
fn parse_package(text: &str) -> Result<(String, PathBuf), String> {
    let (name, dir) = text
        .split_once('=')
        .ok_or_else(|| format!("'{text}' is not NAME=FOLDER"))?;
    if name.is_empty() || dir.is_empty() {
        return Err(format!("'{text}' is not NAME=FOLDER"));
    }
    Ok((name.to_string(), PathBuf::from(dir)))
}
