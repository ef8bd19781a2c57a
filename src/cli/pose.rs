//! `workcell eval pose`: the forearm's pose by render-and-compare on a dataset split, in the
//! layout of the paper's Table 2, with a plot of error against camera distance (Fig. 5).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use workcell::perception::pose::PoseConfig;
use workcell::perception::pose::eval::{
    GroundTruthMasks, MaskSource, NetworkMasks, PoseEvaluation, VisibleMasks, evaluate_pose,
};
use workcell::perception::{Backend, ProcNet, backend};
use workcell::plot::{Panel, svg_panels, svg_to_png};
use workcell::sim::dataset::Dataset;

#[derive(Debug, clap::Args)]
pub struct EvalPoseArgs {
    /// Dataset folder.
    #[arg(long, default_value = "out/dataset")]
    pub dataset: PathBuf,
    /// Which split: train, validation or test.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Where the forearm masks come from: `gt` (the dataset's forearm without the occluder:
    /// the pose estimator's own error), `visible` (only the pixels the occluder leaves),
    /// `procnet` (the network of --weights).
    #[arg(long, default_value = "procnet")]
    pub masks: String,
    /// Network weights for --masks procnet.
    #[arg(long, default_value = "perception/weights/procnet-cpu.safetensors")]
    pub weights: PathBuf,
    /// flex, tch or gpu (the latter two with their cargo features), for the network.
    #[arg(long, default_value = "flex")]
    pub backend: String,
    /// CPU threads.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Search over the whole image instead of a region of interest around the mask.
    #[arg(long)]
    pub no_roi: bool,
    /// The mask alone, as in the paper: do not anchor the elbow to the cell's shoulder.
    #[arg(long)]
    pub no_anchor: bool,
    /// Folder for pose_eval.md, pose_frames.csv and pose_error_vs_distance.{svg,png}.
    #[arg(long, default_value = "out/pose")]
    pub out: PathBuf,
}

pub fn eval_pose(args: &EvalPoseArgs) -> Result<ExitCode> {
    let split = super::parse_split(&args.split)?;
    backend::set_threads(args.threads);
    let mut source: Box<dyn MaskSource> = match args.masks.as_str() {
        "gt" => Box::new(GroundTruthMasks),
        "visible" => Box::new(VisibleMasks),
        "procnet" => {
            let net = ProcNet::load(&args.weights, Backend::parse(&args.backend)?)
                .with_context(|| format!("loading {}", args.weights.display()))?;
            Box::new(NetworkMasks {
                name: format!("ProcNet ({})", args.weights.display()),
                net,
            })
        }
        other => anyhow::bail!("unknown --masks {other:?} (gt, visible, procnet)"),
    };
    let dataset = Dataset::open(&args.dataset)?;
    let n = dataset.entries(Some(split)).count();
    let progress = ProgressBar::new(n as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} sequences, {elapsed} (eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let config = PoseConfig {
        roi: !args.no_roi,
        ..PoseConfig::default()
    };
    let ev = evaluate_pose(
        &dataset,
        split,
        source.as_mut(),
        &config,
        !args.no_anchor,
        &mut |done, _| {
            progress.set_position(done as u64);
        },
    )?;
    progress.finish_and_clear();
    let md = format!(
        "# Forearm pose: {}\n\nDataset `{}`.\n\n{}",
        args.split,
        args.dataset.display(),
        ev.to_markdown()
    );
    print!("{md}");
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let write = |name: &str, text: &str| -> Result<()> {
        let path = args.out.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
    };
    write("pose_eval.md", &md)?;
    write("pose_frames.csv", &ev.to_csv())?;
    let svg = distance_plot(&ev);
    write("pose_error_vs_distance.svg", &svg)?;
    let png = args.out.join("pose_error_vs_distance.png");
    svg_to_png(&svg, &png).map_err(anyhow::Error::msg)?;
    println!(
        "\nwrote {}/pose_eval.md, pose_frames.csv, {}",
        args.out.display(),
        png.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// Mean position error in 0.5 m bins of camera distance, with the share of frames without a
/// pose in the same bins (the paper's Fig. 5).
fn distance_plot(ev: &PoseEvaluation) -> String {
    let bins = ev.by_distance(0.5);
    let x: Vec<f64> = bins.iter().map(|b| b.0).collect();
    let panels = [
        Panel {
            title: format!(
                "position error against camera distance ({} masks)",
                ev.masks
            ),
            y_label: "mean error (cm)".into(),
            series: vec![("error".into(), bins.iter().map(|b| b.1).collect())],
        },
        Panel {
            title: "frames per 0.5 m bin".into(),
            y_label: "frames".into(),
            series: vec![
                (
                    "with a pose".into(),
                    bins.iter().map(|b| b.2 as f64).collect(),
                ),
                ("no pose".into(), bins.iter().map(|b| b.3 as f64).collect()),
            ],
        },
    ];
    svg_panels(&x, "forearm distance from the camera (m)", &panels)
}
