//! `workcell eval pose`: the forearm's pose by render-and-compare on a dataset split (the
//! articulated fit of the whole arm, or the paper's forearm-only search), in the layout of the
//! paper's Table 2, with a plot of error against camera distance (Fig. 5).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use workcell::perception::eval::{
    GroundTruthAtSize, GroundTruthMasks, MaskSource, NetworkMasks, PoseEvaluation, PoseMethod,
    VisibleMasks, compare_markdown, evaluate_pose,
};
use workcell::perception::pose::{
    ArmFitConfig, BoundSource, Calibration, FitSettings, HIDDEN_BANDS, PoseConfig,
};
use workcell::plot::{Panel, svg_panels, svg_to_png};
use workcell::procnet::{Backend, ProcNet, backend};
use workcell::render::dataset::{PredictionPanel, prediction_sheet};
use workcell::render::image::{PixelKind, write_png};
use workcell::sim::dataset::Dataset;

#[derive(Debug, clap::Args)]
pub struct EvalPoseArgs {
    /// Dataset folder.
    #[arg(long, default_value = "out/dataset")]
    pub dataset: PathBuf,
    /// Which split: train, validation or test.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Where the masks come from (the forearm's for --method paper, every arm part's for
    /// articulated): `gt` (the dataset's classes without the occluder: the pose search's own
    /// error), `gt@N` (the true masks averaged down to an NxN network input and back: what
    /// a perfect network of that input size would give), `visible` (only the pixels the
    /// occluder leaves),
    /// `procnet` or `baseline` (the network of --weights; `baseline` is the feed-forward
    /// stand-in for the paper's PoseCNN). Several, comma-separated, are evaluated in turn
    /// and compared side by side (pose_compare.md).
    #[arg(long, default_value = "procnet")]
    pub masks: String,
    /// Network weights for --masks procnet or baseline [default: the shipped
    /// procnet/weights/procnet-cpu.safetensors, procnet-depth.safetensors with --depth
    /// (the network that reads the depth image too), or baseline-cpu-64.safetensors].
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// flex, tch or gpu (the latter two with their cargo features), for the network.
    #[arg(long, default_value = "flex")]
    pub backend: String,
    /// CPU threads (1 to 256).
    #[arg(long, default_value_t = 2, value_parser = super::count_in::<1, { super::MAX_THREADS }>)]
    pub threads: usize,
    /// `articulated`: the human model's joints fitted to the upper arm's, the forearm's
    /// and the hand's masks at once; `paper`: the forearm's 6-DoF pose from its mask alone,
    /// by the paper's method. Both report the forearm's pose in the camera frame.
    #[arg(long, default_value = "articulated")]
    pub method: String,
    /// With --method articulated: the dataset's depth images join the score (RGB-D; a camera
    /// with a depth channel).
    #[arg(long)]
    pub depth: bool,
    /// With --method articulated: the grid cells the global search climbs, the best distinct
    /// ones first (1 to 1000; default ArmFitConfig's 10).
    #[arg(long)]
    pub search_starts: Option<usize>,
    /// With --method articulated: the global search runs beside the tracked hypotheses when
    /// their best gain is below this (0 to 1; default: the masks' calibration's, else
    /// ArmFitConfig's 0.55).
    #[arg(long)]
    pub search_below_gain: Option<f64>,
    /// With --method articulated: climb from the best fit's forearm turned end for end as
    /// well, kept as a hypothesis where it scores as well (ArmFitConfig::reversed_start; on
    /// where the masks' calibration was measured with it; `--reversed-start false` turns it
    /// off).
    #[arg(long, num_args = 0..=1, default_missing_value = "true", value_name = "BOOL")]
    pub reversed_start: Option<bool>,
    /// With --method articulated and --depth: climb from the forearm where its mask's depth
    /// points put it as well, the elbow at the end the upper arm's points are nearer (both ways
    /// round where they and the hand's do not tell; ArmFitConfig::depth_start; on where the
    /// masks' calibration was measured with it, as the shipped procnet-depth-human's;
    /// `--depth-start false` turns it off).
    #[arg(long, num_args = 0..=1, default_missing_value = "true", value_name = "BOOL")]
    pub depth_start: Option<bool>,
    /// With --method articulated: render each part's convex hull, not its pieces
    /// (ArmFitConfig::hull_outlines; default: the masks' calibration's, else off).
    #[arg(long, num_args = 0..=1, default_missing_value = "true", value_name = "BOOL")]
    pub hull_outlines: Option<bool>,
    /// With --method articulated: a fit whose gain is below this is no pose (0 to 1; default
    /// ArmFitConfig's 0.3).
    #[arg(long)]
    pub min_gain: Option<f64>,
    /// With --method articulated: a fit with a gain from this up to --min-gain is a pose
    /// when the frame before put the forearm within 10 cm of it (0 to 1; default: the one
    /// measured for the masks, 0.2 for the shipped network that reads depth, off for the
    /// others; --min-gain's value turns it off).
    #[arg(long)]
    pub confirm_min_gain: Option<f64>,
    /// With --method articulated, on a model whose trunk turns and leans (`human`): `fit`
    /// fits the trunk to the torso's mask and depth before the arm, `upright` holds it
    /// upright, `truth` holds it where the labels put it (the arm's fit given a perfect
    /// trunk: a bound, not a method) (default: the masks' calibration's, else `upright`). `human_arm`'s
    /// torso does not move.
    #[arg(long, value_parser = ["fit", "upright", "truth"])]
    pub trunk: Option<String>,
    /// With --method paper: search over the whole image instead of a region of interest
    /// around the mask.
    #[arg(long)]
    pub no_roi: bool,
    /// With --method paper: the mask alone, as in the paper; do not anchor the elbow to the
    /// cell's shoulder.
    #[arg(long)]
    pub no_anchor: bool,
    /// Folder for pose_eval.md, pose_frames.csv, pose_error_vs_distance.{svg,png} and, when
    /// some frames have no pose, no_pose.png (a contact sheet of them).
    #[arg(long, default_value = "out/pose")]
    pub out: PathBuf,
}

/// The weights of `--masks procnet` or `baseline`: `--weights`, else the shipped ProcNet
/// for the dataset's human (`human_model`; with `--depth`, the one that reads depth and, for
/// the whole body, was trained on it) or the shipped baseline, both 64x64 networks of the
/// cpu preset.
fn network_weights(kind: &str, args: &EvalPoseArgs, human_model: &str) -> PathBuf {
    args.weights.clone().unwrap_or_else(|| {
        PathBuf::from(if kind == "procnet" {
            if let Some(warning) =
                workcell::procnet::weights::shipped_for_warning(args.depth, human_model)
            {
                tracing::warn!("{warning}");
            }
            workcell::procnet::weights::shipped_for(args.depth, human_model)
        } else {
            "procnet/weights/baseline-cpu-64.safetensors"
        })
    })
}

/// The mask source of one `--masks` entry.
fn mask_source(kind: &str, args: &EvalPoseArgs, human_model: &str) -> Result<Box<dyn MaskSource>> {
    Ok(match kind {
        "gt" => Box::new(GroundTruthMasks),
        "visible" => Box::new(VisibleMasks),
        _ if kind.starts_with("gt@") => {
            let size = kind["gt@".len()..]
                .parse::<usize>()
                .ok()
                .filter(|s| (4..=4096).contains(s))
                .with_context(|| {
                    format!("--masks {kind:?}: gt@N takes a network input side N of 4 to 4096")
                })?;
            Box::new(GroundTruthAtSize { size })
        }
        "procnet" | "baseline" => {
            let weights = network_weights(kind, args, human_model);
            // The error names the file already.
            let net = ProcNet::load(&weights, Backend::parse(&args.backend)?)?;
            if net.config().is_feed_forward() != (kind == "baseline") {
                anyhow::bail!(
                    "--masks {kind}, but {} holds a {}",
                    weights.display(),
                    net.config().model_name()
                );
            }
            let depth_from = if net.config().reads_depth() {
                Some(Dataset::open(&args.dataset)?)
            } else {
                None
            };
            Box::new(NetworkMasks {
                name: format!("{} ({})", net.config().model_name(), weights.display()),
                net,
                depth_from,
            })
        }
        other => anyhow::bail!("unknown --masks {other:?} (gt, gt@N, visible, procnet, baseline)"),
    })
}

pub fn eval_pose(args: &EvalPoseArgs) -> Result<ExitCode> {
    let split = super::parse_split(&args.split)?;
    backend::set_threads(args.threads);
    let kinds: Vec<&str> = args.masks.split(',').map(str::trim).collect();
    if args.weights.is_some()
        && kinds
            .iter()
            .filter(|k| matches!(**k, "procnet" | "baseline"))
            .count()
            > 1
    {
        anyhow::bail!("--weights names one network; leave it out to compare procnet and baseline");
    }
    if let Some((i, k)) = kinds
        .iter()
        .enumerate()
        .find(|(i, k)| kinds[..*i].contains(k))
    {
        anyhow::bail!("--masks names {k:?} twice (entry {})", i + 1);
    }
    let dataset = Dataset::open(&args.dataset)?;
    let human_model = dataset
        .manifest
        .human
        .as_ref()
        .map_or(workcell::procnet::weights::PAPER_ARM, |h| h.model.as_str())
        .to_string();
    let mut sources = kinds
        .iter()
        .map(|k| mask_source(k, args, &human_model))
        .collect::<Result<Vec<_>>>()?;
    let n = dataset.entries(Some(split)).count();
    let crops_hold_hand = tracked_crops_hold_hand(&dataset.manifest.config);
    let method = match args.method.as_str() {
        "articulated" => {
            if args.no_roi || args.no_anchor {
                anyhow::bail!(
                    "--no-roi and --no-anchor are settings of --method paper; the articulated \
                     fit renders the region the dataset stores and hangs the arm from its shoulder"
                );
            }
            let mut config = ArmFitConfig::default();
            if let Some(n) = args.search_starts {
                if !(1..=1000).contains(&n) {
                    anyhow::bail!("--search-starts {n}: the global search climbs 1 to 1000 cells");
                }
                config.refine = n;
            }
            if let Some(g) = args.search_below_gain
                && !(0.0..=1.0).contains(&g)
            {
                anyhow::bail!("--search-below-gain {g}: a gain from 0 to 1");
            }
            if let Some(g) = args.min_gain {
                if !(0.0..=1.0).contains(&g) {
                    anyhow::bail!("--min-gain {g}: a gain from 0 to 1");
                }
                config.min_gain = g;
            }
            if args.depth_start == Some(true) && !args.depth {
                anyhow::bail!("--depth-start starts from the depth image: add --depth");
            }
            // The fit's settings and these gains are set after the masks' calibration
            // (below), which carries its own.
            if let Some(g) = args.confirm_min_gain
                && !(0.0..=1.0).contains(&g)
            {
                anyhow::bail!("--confirm-min-gain {g}: a gain from 0 to 1");
            }
            PoseMethod::Articulated {
                config: Box::new(config),
                depth: args.depth,
                true_trunk: args.trunk.as_deref() == Some("truth"),
            }
        }
        "paper"
            if args.search_starts.is_some()
                || args.search_below_gain.is_some()
                || args.reversed_start.is_some()
                || args.depth_start.is_some()
                || args.hull_outlines.is_some()
                || args.min_gain.is_some()
                || args.confirm_min_gain.is_some()
                || args.trunk.is_some() =>
        {
            anyhow::bail!(
                "--search-starts, --search-below-gain, --reversed-start, --depth-start, \
                 --hull-outlines, --min-gain, --confirm-min-gain and --trunk are settings of \
                 --method articulated"
            )
        }
        "paper" if args.depth => {
            anyhow::bail!(
                "--depth is a setting of --method articulated; the paper's method reads masks alone"
            )
        }
        "paper" => PoseMethod::Paper {
            anchored: !args.no_anchor,
            config: PoseConfig {
                roi: !args.no_roi,
                ..PoseConfig::default()
            },
        },
        other => anyhow::bail!("unknown --method {other:?} (articulated, paper)"),
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let write = |name: &str, text: &str| -> Result<()> {
        let path = args.out.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
    };
    let several = kinds.len() > 1;
    let mut evaluations = Vec::with_capacity(kinds.len());
    let mut written = Vec::new();
    for (kind, source) in kinds.iter().zip(&mut sources) {
        // The bound of "within the bound": the one the closed loop would use for these
        // masks. True masks have theirs; a network's is the calibration file beside its
        // weights, or the conservative bound where it has none (said, and warned of).
        let (calibration, uncalibrated) = match *kind {
            "gt" => (Some(Calibration::true_masks(args.depth)), None),
            "procnet" | "baseline" => {
                let found = Calibration::of_weights(
                    &network_weights(kind, args, &human_model),
                    args.depth,
                )?;
                if let Some(w) = found.warning() {
                    eprintln!("warning: {w}");
                }
                let why = match found.source {
                    BoundSource::Uncalibrated { why } => Some(why),
                    BoundSource::Calibrated { .. } => None,
                };
                (Some(found.calibration), why)
            }
            _ => (None, None),
        };
        let method = match &method {
            PoseMethod::Articulated {
                config,
                depth,
                true_trunk,
            } => {
                // The calibration's bound and the fit it was measured with; the flags given
                // override its fit settings, and a fit other than the measured one is said.
                let mut config =
                    calibration.map_or_else(|| (**config).clone(), |c| c.apply((**config).clone()));
                if let Some(g) = args.search_below_gain {
                    config.search_below_gain = g;
                }
                if let Some(t) = &args.trunk {
                    config.fit_trunk = t == "fit";
                }
                if let Some(on) = args.reversed_start {
                    config.reversed_start = on;
                }
                if let Some(on) = args.depth_start {
                    config.depth_start = on;
                }
                if let Some(on) = args.hull_outlines {
                    config.hull_outlines = on;
                }
                // What the fit is shown: the stored crops, which hold the hand's far end
                // where the dataset's tracked crops were drawn so.
                config.hand_region = crops_hold_hand;
                if let Some(measured) = calibration.and_then(|c| c.fit) {
                    let differences = measured.differences(&FitSettings::of(&config));
                    if !differences.is_empty() {
                        eprintln!(
                            "warning: the {kind} masks' bound was measured with another fit \
                             ({}, measured vs this run): \"within the bound\" is not its \
                             coverage",
                            differences.join(", ")
                        );
                    }
                }
                if let Some(g) = args.confirm_min_gain {
                    config.confirm_min_gain = g;
                }
                if let Some(g) = args.min_gain {
                    config.min_gain = g;
                }
                PoseMethod::Articulated {
                    config: Box::new(config),
                    depth: *depth,
                    true_trunk: *true_trunk,
                }
            }
            paper => paper.clone(),
        };
        let progress = super::progress_bar(
            n as u64,
            &format!("{kind}: {{bar:40}} {{pos}}/{{len}} sequences, {{elapsed}} (eta {{eta}})"),
        );
        let ev = evaluate_pose(&dataset, split, source.as_mut(), &method, &mut |done, _| {
            progress.set_position(done as u64);
        })?;
        progress.finish_and_clear();
        let bound = match (&method, calibration) {
            (PoseMethod::Paper { .. }, _) => String::new(),
            (_, Some(c)) => format!(
                "\nThe bound is {}: \
                 {:.2} cm plus {} times the curvature's spread, the hypotheses' spread where it \
                 is larger{}{}.\n",
                uncalibrated.as_ref().map_or_else(
                    || "the one calibrated for these masks".to_string(),
                    |why| format!("the conservative one of uncalibrated masks ({why})")
                ),
                100.0 * c.floor_m,
                c.scale,
                if c.hidden_floors_m.iter().any(|&f| f > c.floor_m) {
                    format!(
                        "; where the depth image shows at least {} of the forearm's region \
                         hidden, {} cm instead",
                        HIDDEN_BANDS
                            .map(|b| format!("{:.0} %", 100.0 * b))
                            .join(", "),
                        c.hidden_floors_m
                            .map(|f| format!("{:.2}", 100.0 * f))
                            .join(", ")
                    )
                } else {
                    String::new()
                },
                c.confident.map_or_else(String::new, |c| format!(
                    "; a fit of a gain of {} or more, {} cm from 0, 25, 50 and 75 % hidden",
                    c.min_gain,
                    c.floors_m.map(|f| format!("{:.2}", 100.0 * f)).join(", ")
                ))
            ),
            (_, None) => "\nThese masks have no calibration: the bound is the curvature's spread \
                          alone, or the hypotheses' where it is larger \
                          (`scripts/calibrate_uncertainty.py` fits one from this run's \
                          pose_frames.csv on the validation split).\n"
                .to_string(),
        };
        let md = format!(
            "# Forearm pose: {}, {kind} masks\n\nDataset `{}`.\n\n{}{bound}",
            args.split,
            args.dataset.display(),
            ev.to_markdown()
        );
        say_inline!("{md}");
        let suffix = if several {
            // `gt@64` writes pose_eval_gt64.md: no `@` in file names.
            format!("_{}", kind.replace('@', ""))
        } else {
            String::new()
        };
        write(&format!("pose_eval{suffix}.md"), &md)?;
        write(&format!("pose_frames{suffix}.csv"), &ev.to_csv())?;
        if let PoseMethod::Articulated { config, .. } = &method {
            // The fit's settings, for scripts/calibrate_uncertainty.py --write to record.
            let settings = toml::to_string(&FitSettings::of(config))?;
            write(
                &format!("fit{suffix}.toml"),
                &format!(
                    "# The articulated fit's settings of pose_frames{suffix}.csv \
                     (workcell_perception::pose::FitSettings)\n{settings}"
                ),
            )?;
            written.push(format!("fit{suffix}.toml"));
        }
        written.push(format!("pose_eval{suffix}.md"));
        written.push(format!("pose_frames{suffix}.csv"));
        if !ev.no_pose.is_empty() {
            let name = format!("no_pose{suffix}.png");
            let (w, h, rgb) = no_pose_sheet(&ev, kind);
            write_png(&args.out.join(&name), w, h, PixelKind::Rgb, &rgb)?;
            written.push(name);
        }
        evaluations.push(ev);
    }
    if several {
        let named: Vec<(&str, &PoseEvaluation)> = kinds.iter().copied().zip(&evaluations).collect();
        let md = format!(
            "# Forearm pose: {} masks side by side, {} split\n\n{}",
            kinds.join(", "),
            args.split,
            compare_markdown(&named)?
        );
        say_inline!("\n{md}");
        write("pose_compare.md", &md)?;
        written.push("pose_compare.md".into());
    }
    let svg = distance_plot(&kinds, &evaluations);
    write("pose_error_vs_distance.svg", &svg)?;
    let png = args.out.join("pose_error_vs_distance.png");
    svg_to_png(&svg, &png)?;
    say!(
        "\nwrote {}/{}, {}",
        args.out.display(),
        written.join(", "),
        png.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// Frames on the contact sheet of frames without a pose.
const NO_POSE_SHEET_FRAMES: usize = 24;

/// The contact sheet of frames without a pose (`no_pose.png`): per frame the input, the true
/// arm parts, the parts in the masks the fit read, and the forearm's agreement; titled with
/// the truth's gain on those masks and each part's share of it (a part's share below zero:
/// the masks call it background where it is).
fn no_pose_sheet(ev: &PoseEvaluation, kind: &str) -> (u32, u32, Vec<u8>) {
    let sample = ev.no_pose_sample(NO_POSE_SHEET_FRAMES);
    let titles: Vec<String> = sample
        .iter()
        .map(|f| {
            let Some(r) = ev.frames.get(f.index) else {
                return String::new();
            };
            let [total, upper, forearm, hand] = r.truth_gain;
            let gains = if total.is_finite() {
                format!(" - truth gain {total:.2} ({upper:.2} {forearm:.2} {hand:.2})")
            } else {
                String::new()
            };
            format!(
                "seq {} frame {} - {} / {}, {:.0} % hidden{gains}",
                r.sequence,
                r.frame,
                r.distance_class,
                r.occlusion_level,
                100.0 * r.occlusion
            )
        })
        .collect();
    let panels: Vec<PredictionPanel<'_>> = sample
        .iter()
        .zip(&titles)
        .map(|(f, title)| f.images.panel(title))
        .collect();
    let without = ev.frames.iter().filter(|f| f.outcome.is_err()).count();
    let title = format!(
        "{} of {without} {} frames without a pose, {kind} masks - truth gain: all (upper arm, \
         forearm, hand)",
        panels.len(),
        ev.split
    );
    prediction_sheet(&title, &panels, 2)
}

/// Mean position error in 0.5 m bins of camera distance, with the frames without a pose in
/// the same bins, one series per mask source (the paper's Fig. 5).
fn distance_plot(kinds: &[&str], evaluations: &[PoseEvaluation]) -> String {
    let bins: Vec<_> = evaluations.iter().map(|ev| ev.by_distance(0.5)).collect();
    let x: Vec<f64> = bins
        .first()
        .map_or_else(Vec::new, |b| b.iter().map(|b| b.0).collect());
    let mut frames = vec![(
        "all frames".to_string(),
        bins.first()
            .map_or_else(Vec::new, |b| b.iter().map(|b| (b.2 + b.3) as f64).collect()),
    )];
    frames.extend(kinds.iter().zip(&bins).map(|(k, b)| {
        (
            format!("no pose, {k}"),
            b.iter().map(|b| b.3 as f64).collect(),
        )
    }));
    let panels = [
        Panel {
            title: format!(
                "forearm position error against camera distance ({} masks)",
                kinds.join(", ")
            ),
            y_label: "mean error (cm)".into(),
            series: kinds
                .iter()
                .zip(&bins)
                .map(|(k, b)| (k.to_string(), b.iter().map(|b| b.1).collect()))
                .collect(),
        },
        Panel {
            title: "frames per 0.5 m bin".into(),
            y_label: "frames".into(),
            series: frames,
        },
    ];
    svg_panels(&x, "forearm distance from the camera (m)", &panels)
}

/// Whether a dataset's tracked crops hold the hand's far end (its configuration's `[roi]
/// tracked_hand`, false where it has none: written before the key, or a configuration of
/// another form).
fn tracked_crops_hold_hand(config: &str) -> bool {
    toml::from_str::<toml::Table>(config)
        .ok()
        .and_then(|t| t.get("roi")?.get("tracked_hand")?.as_bool())
        .unwrap_or(false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell::sim::dataset::DatasetConfig;

    /// The key is read as the dataset generator writes its configuration into the manifest.
    #[test]
    fn a_datasets_crops_say_whether_they_hold_the_hand() {
        let mut config = DatasetConfig::default();
        let text = DatasetConfig::to_toml;
        assert!(!tracked_crops_hold_hand(&text(&config)));
        config.roi.tracked_hand = true;
        assert!(tracked_crops_hold_hand(&text(&config)));
        assert!(!tracked_crops_hold_hand("roi = 3"));
    }
}
