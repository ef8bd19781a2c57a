//! `workcell crosscheck`: the rapier model of a robot against MuJoCo (feature `mujoco`).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;

#[derive(Debug, clap::Args)]
pub struct CrosscheckArgs {
    /// Catalogue name, added robot, or path to a URDF file.
    pub robot: String,
    /// Map a ROS package to its folder, NAME=FOLDER (repeatable).
    #[arg(long = "package", value_parser = crate::parse_package)]
    pub packages: Vec<(String, PathBuf)>,
    /// Random configurations for kinematics, mass matrix and gravity.
    #[arg(long, default_value_t = 100)]
    pub samples: usize,
    /// Seconds of the trajectory comparison.
    #[arg(long, default_value_t = 3.0)]
    pub seconds: f64,
    /// Seed of the random configurations.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Keep the URDF prepared for MuJoCo and its meshes in this folder.
    #[arg(long)]
    pub keep: Option<PathBuf>,
    /// Print JSON instead of the text report.
    #[arg(long)]
    pub json: bool,
}

#[cfg(not(feature = "mujoco"))]
pub fn run(_args: &CrosscheckArgs) -> Result<ExitCode> {
    anyhow::bail!(
        "this workcell was built without MuJoCo: run scripts/fetch-mujoco.sh, then build with \
         --features mujoco (README: Cross-checking against MuJoCo)"
    )
}

#[cfg(feature = "mujoco")]
pub fn run(args: &CrosscheckArgs) -> Result<ExitCode> {
    use anyhow::{Context, bail};
    use workcell::robots::{PackageMap, RobotModel, RobotSource};
    use workcell::sim::crosscheck::{CrosscheckConfig, crosscheck, format_report};

    if args.samples == 0 {
        bail!("--samples must be at least 1");
    }
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 60.0) {
        bail!("--seconds must be in (0, 60], not {}", args.seconds);
    }
    let mut packages = PackageMap::from_env();
    for (name, dir) in &args.packages {
        packages.insert(name.clone(), dir.clone());
    }
    let robot = RobotModel::load(&args.robot, &packages)?;
    let assets = RobotSource::locate(&args.robot)?.assets(&packages)?;
    let temp;
    let workdir = match &args.keep {
        Some(dir) => dir.clone(),
        None => {
            temp = tempfile::tempdir().context("creating a temporary folder")?;
            temp.path().to_path_buf()
        }
    };
    let config = CrosscheckConfig {
        samples: args.samples,
        seed: args.seed,
        duration_s: args.seconds,
        ..CrosscheckConfig::default()
    };
    let report = crosscheck(&robot, &assets, &workdir, &config)?;
    if args.json {
        say!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        say_inline!("{}", format_report(&report));
    }
    Ok(if report.passed() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
