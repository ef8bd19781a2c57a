//! `workcell train` and `workcell eval segmentation`: ProcNet.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use workcell::plot::{Panel, svg_panels, svg_to_png};
use workcell::procnet::eval::{FrameRecord, evaluate};
use workcell::procnet::train::{TrainConfig, Trainer, read_metrics};
use workcell::procnet::{Backend, backend, weights};
use workcell::render::dataset::{PredictionPanel, prediction_sheet};
use workcell::render::image::{PixelKind, write_png};
use workcell::sim::dataset::Dataset;

#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Training configuration (TOML), e.g. configs/train.toml.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Run folder: checkpoints, metrics.csv, loss_curve.svg, procnet.safetensors (or
    /// baseline.safetensors). A folder holding a checkpoint of the same configuration is
    /// resumed.
    #[arg(long, required_unless_present = "print_defaults")]
    pub out: Option<PathBuf>,
    /// `procnet`: the configuration's network as written. `baseline`: its feed-forward
    /// stand-in for the paper's PoseCNN, a single-frame encoder-decoder of the same
    /// parameter count (plain convolution cells, no prediction loss), trained by the same
    /// recipe.
    #[arg(long, default_value = "procnet")]
    pub model: String,
    /// Override the configuration's backend (flex, tch, gpu).
    #[arg(long)]
    pub backend: Option<String>,
    /// Override the configuration's number of steps (1 to 10,000,000).
    #[arg(long, value_parser = super::count_in::<1, 10_000_000>)]
    pub steps: Option<usize>,
    /// Override the configuration's seed (initial weights, sequence order, augmentation): a
    /// second seed of the same recipe measures the spread between training runs.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Stop after this many steps of this run (checkpointed; the same command resumes).
    #[arg(long, value_parser = super::count_in::<1, 10_000_000>)]
    pub stop_after: Option<usize>,
    /// Print the configuration (`--config`'s, else the defaults) with every default filled
    /// in, then exit.
    #[arg(long)]
    pub print_defaults: bool,
}

#[derive(Debug, clap::Args)]
pub struct TrainingReportArgs {
    /// Run folders of `workcell train` (each with its metrics.csv), e.g. two seeds of ProcNet
    /// and of the baseline.
    #[arg(required = true, num_args = 1..)]
    pub runs: Vec<PathBuf>,
    /// Where to write the overlaid validation curves (SVG; a PNG is written beside it).
    #[arg(long, default_value = "out/validation_curves.svg")]
    pub out: PathBuf,
}

#[derive(Debug, clap::Args)]
pub struct EvalSegmentationArgs {
    /// ProcNet weights (safetensors), e.g. procnet/weights/procnet-cpu.safetensors.
    #[arg(long)]
    pub weights: PathBuf,
    /// Dataset folder.
    #[arg(long, default_value = "out/dataset")]
    pub dataset: PathBuf,
    /// Which split: train, validation or test.
    #[arg(long, default_value = "test")]
    pub split: String,
    /// Score this many sequences of the split, taken in turn from each (camera, occlusion)
    /// cell so that every cell is represented (0: all of them).
    #[arg(long, default_value_t = 0, value_parser = super::count_in::<0, 1_000_000>)]
    pub sequences: usize,
    /// flex, tch or gpu (the latter two with their cargo features).
    #[arg(long, default_value = "flex")]
    pub backend: String,
    /// CPU threads (1 to 256).
    #[arg(long, default_value_t = 2, value_parser = super::count_in::<1, { super::MAX_THREADS }>)]
    pub threads: usize,
    /// Also write the Markdown table to this file.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write a contact sheet of the worst frames (highest forearm Dice loss first):
    /// input, truth, prediction and the forearm's agreement.
    #[arg(long)]
    pub sheet: Option<PathBuf>,
    /// Frames on the sheet.
    #[arg(long, default_value_t = 24)]
    pub worst: usize,
    /// Write every scored frame's forearm to this CSV file: sequence, frame, camera,
    /// occlusion, true forearm pixels, Dice loss (probabilities and thresholded), the
    /// ceiling at the model's input, the mean luma of the forearm's pixels in view
    /// (`experiments/scripts/luma_gap.py` reads it) and the thresholded Dice loss with the elbow and the
    /// wrist in the right place (`experiments/scripts/part_boundaries.py` reads it).
    #[arg(long)]
    pub frames: Option<PathBuf>,
}

fn on_off(b: bool) -> &'static str {
    if b { "on" } else { "off" }
}

fn format_channels(c: &[usize]) -> String {
    let c: Vec<String> = c.iter().map(ToString::to_string).collect();
    format!("({})", c.join(", "))
}

pub fn train(args: &TrainArgs) -> Result<ExitCode> {
    if args.print_defaults {
        let config = match &args.config {
            Some(path) => TrainConfig::from_file(path)?,
            None => TrainConfig::default(),
        };
        say_inline!("{}", config.to_toml());
        return Ok(ExitCode::SUCCESS);
    }
    let path = args
        .config
        .clone()
        .context("--config FILE is required (see configs/train.toml)")?;
    let mut config = TrainConfig::from_file(&path)?;
    if let Some(b) = &args.backend {
        config.backend = Backend::parse(b)?;
    }
    if let Some(s) = args.steps {
        config.steps = s;
    }
    if let Some(s) = args.seed {
        config.seed = s;
    }
    match args.model.as_str() {
        "procnet" => {}
        "baseline" => config.model = config.model.feed_forward_baseline(),
        other => anyhow::bail!("unknown --model {other:?} (procnet, baseline)"),
    }
    say!(
        "{}: {} parameters, {} cells, {} channels, {}x{} input, prediction loss {}, axonal delay {}, decoder {}",
        config.model.model_name(),
        config.model.parameter_count(),
        config.model.cell.name(),
        format_channels(&config.model.repr_channels),
        config.model.input_size,
        config.model.input_size,
        on_off(config.model.prediction_loss),
        on_off(config.model.axonal_delay),
        if config.model.decoder_full_resolution || !config.model.prediction_loss {
            "reads full resolution"
        } else {
            "from half resolution (the paper's)"
        }
    );
    if !config.sampling.is_uniform() {
        say!(
            "training sequences drawn unevenly (factors multiply): distance {:?}, region of interest {:?}, view {:?}, motion {:?}",
            config.sampling.distance,
            config.sampling.roi,
            config.sampling.view,
            config.sampling.motion
        );
    }
    backend::set_threads(config.threads);
    let out = args.out.as_ref().context("--out DIR is required")?;
    let trainer = Trainer::new(config, out)?;
    let progress = super::progress_bar(
        trainer.config.steps as u64,
        "{bar:40} {pos}/{len} steps, {elapsed} (eta {eta}) {msg}",
    );
    let report = trainer.run(args.stop_after, &mut |p| {
        progress.set_position(p.step as u64);
        progress.set_message(format!("loss {:.4}", p.metrics.loss));
    })?;
    progress.finish_and_clear();
    let metrics = read_metrics(&trainer.files.metrics())?;
    let svg = trainer.files.dir.join("loss_curve.svg");
    write_loss_curve(&metrics, &svg)?;
    let png = svg.with_extension("png");
    let last = report.metrics.last().copied().unwrap_or_default();
    if !report.finished {
        say!(
            "stopped at step {} of {} ({} this run, {:.0} s); the same command resumes. Metrics: {}",
            report.steps_done,
            trainer.config.steps,
            report.steps_done - report.resumed_from,
            report.wall_s,
            trainer.files.metrics().display()
        );
        return Ok(ExitCode::SUCCESS);
    }
    say!(
        "{} steps ({} this run, {:.0} s) -> {}\n  last loss {:.4} (Dice {:.4}, focal {:.4}, prediction {:.4}); validation forearm Dice loss {:.4}\n  metrics: {}, curve: {}",
        trainer.config.steps,
        trainer.config.steps - report.resumed_from,
        report.wall_s,
        report.weights.display(),
        last.loss,
        last.dice,
        last.focal,
        last.prediction,
        last.val_forearm_dice,
        trainer.files.metrics().display(),
        png.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn write_loss_curve(
    metrics: &[workcell::procnet::train::StepMetrics],
    path: &std::path::Path,
) -> Result<()> {
    let x: Vec<f64> = metrics.iter().map(|m| m.step as f64).collect();
    let mut val_x = Vec::new();
    let mut val = Vec::new();
    for m in metrics.iter().filter(|m| m.val_forearm_dice.is_finite()) {
        val_x.push(m.step as f64);
        val.push(m.val_forearm_dice);
    }
    let panels = vec![
        Panel {
            title: "training loss (moving average)".into(),
            y_label: "loss".into(),
            series: vec![
                ("total".into(), smooth(metrics.iter().map(|m| m.loss))),
                ("Dice".into(), smooth(metrics.iter().map(|m| m.dice))),
                ("focal".into(), smooth(metrics.iter().map(|m| m.focal))),
                (
                    "prediction".into(),
                    smooth(metrics.iter().map(|m| m.prediction)),
                ),
            ],
        },
        Panel {
            title: "learning rate (one-cycle)".into(),
            y_label: "lr x 1000".into(),
            series: vec![("lr".into(), metrics.iter().map(|m| 1e3 * m.lr).collect())],
        },
    ];
    let mut svg = svg_panels(&x, "step", &panels);
    if !val.is_empty() {
        let val_panel = vec![Panel {
            title: "validation forearm Dice loss".into(),
            y_label: "Dice loss".into(),
            series: vec![("forearm".into(), val)],
        }];
        // A separate document for the validation curve (its own x samples).
        let val_svg = svg_panels(&val_x, "step", &val_panel);
        let val_path = path.with_file_name("validation_curve.svg");
        std::fs::write(&val_path, &val_svg)
            .with_context(|| format!("writing {}", val_path.display()))?;
        svg_to_png(&val_svg, &val_path.with_extension("png"))?;
    }
    svg.push('\n');
    std::fs::write(path, &svg).with_context(|| format!("writing {}", path.display()))?;
    svg_to_png(&svg, &path.with_extension("png"))?;
    Ok(())
}

/// Exponential moving average, so that a loss's trend shows through the batch noise.
fn smooth(v: impl IntoIterator<Item = f64>) -> Vec<f64> {
    let mut acc = f64::NAN;
    v.into_iter()
        .map(|y| {
            acc = if acc.is_nan() {
                y
            } else {
                0.95 * acc + 0.05 * y
            };
            acc
        })
        .collect()
}

/// `samples` (step, value), ascending, linearly interpolated at `steps`; NaN outside them.
fn interpolate(samples: &[(usize, f64)], steps: &[usize]) -> Vec<f64> {
    steps
        .iter()
        .map(|&s| {
            let i = samples.partition_point(|(t, _)| *t < s);
            match (
                samples.get(i),
                i.checked_sub(1).and_then(|j| samples.get(j)),
            ) {
                (Some(&(t, v)), _) if t == s => v,
                (Some(&(t1, v1)), Some(&(t0, v0))) => {
                    v0 + (v1 - v0) * (s - t0) as f64 / (t1 - t0) as f64
                }
                _ => f64::NAN,
            }
        })
        .collect()
}

/// `workcell report training`: several training runs side by side, their training loss and
/// validation forearm Dice loss on one plot, and a table of each run's last and best.
pub fn training_report(args: &TrainingReportArgs) -> Result<ExitCode> {
    struct Run {
        name: String,
        steps: Vec<usize>,
        loss: Vec<f64>,
        val: Vec<(usize, f64)>,
        wall_s: f64,
    }
    let mut runs = Vec::new();
    for dir in &args.runs {
        let metrics = read_metrics(&dir.join("metrics.csv"))
            .with_context(|| format!("{} is not a training run folder", dir.display()))?;
        let Some(last) = metrics.last() else {
            anyhow::bail!("{} has no training steps yet", dir.display());
        };
        runs.push(Run {
            name: dir.file_name().map_or_else(
                || dir.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            ),
            steps: metrics.iter().map(|m| m.step).collect(),
            loss: smooth(metrics.iter().map(|m| m.loss)),
            val: metrics
                .iter()
                .filter(|m| m.val_forearm_dice.is_finite())
                .map(|m| (m.step, m.val_forearm_dice))
                .collect(),
            wall_s: last.elapsed_s,
        });
    }
    say!(
        "| run | steps | wall (s) | training loss (moving average) | last validation forearm Dice loss (step) | best (step) |"
    );
    say!("|---|---|---|---|---|---|");
    for run in &runs {
        let at = |(step, v): (usize, f64)| format!("{v:.4} ({step})");
        let best = run
            .val
            .iter()
            .copied()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or_else(|| "-".into(), at);
        say!(
            "| {} | {} | {:.0} | {:.4} | {} | {} |",
            run.name,
            run.steps.last().copied().unwrap_or(0),
            run.wall_s,
            run.loss.last().copied().unwrap_or(f64::NAN),
            run.val.last().copied().map_or_else(|| "-".into(), at),
            best
        );
    }
    // Every run on the union of the runs' steps (NaN where a run has no step: a gap).
    let mut x: Vec<usize> = runs.iter().flat_map(|r| r.steps.iter().copied()).collect();
    x.sort_unstable();
    x.dedup();
    let loss = runs
        .iter()
        .map(|r| {
            let samples: Vec<(usize, f64)> = r.steps.iter().copied().zip(r.loss.clone()).collect();
            (r.name.clone(), interpolate(&samples, &x))
        })
        .collect();
    let mut panels = vec![Panel {
        title: "training loss (moving average)".into(),
        y_label: "loss".into(),
        series: loss,
    }];
    if runs.iter().any(|r| !r.val.is_empty()) {
        panels.push(Panel {
            title: "validation forearm Dice loss (straight between validations)".into(),
            y_label: "Dice loss".into(),
            series: runs
                .iter()
                .map(|r| (r.name.clone(), interpolate(&r.val, &x)))
                .collect(),
        });
    }
    let xs: Vec<f64> = x.iter().map(|&s| s as f64).collect();
    let svg = svg_panels(&xs, "step", &panels);
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    std::fs::write(&args.out, &svg).with_context(|| format!("writing {}", args.out.display()))?;
    let png = args.out.with_extension("png");
    svg_to_png(&svg, &png)?;
    say!("curves: {} and {}", args.out.display(), png.display());
    Ok(ExitCode::SUCCESS)
}

pub fn eval_segmentation(args: &EvalSegmentationArgs) -> Result<ExitCode> {
    let split = super::parse_split(&args.split)?;
    backend::set_threads(args.threads);
    let device = Backend::parse(&args.backend)?.device()?;
    let (model, config) = weights::load(&args.weights, &device)?;
    let dataset = Dataset::open(&args.dataset)?;
    let n_split = dataset.entries(Some(split)).count();
    let n = if args.sequences == 0 {
        n_split
    } else {
        n_split.min(args.sequences)
    };
    let progress = super::progress_bar(
        n as u64,
        "{bar:40} {pos}/{len} sequences, {elapsed} (eta {eta})",
    );
    let keep = if args.sheet.is_some() { args.worst } else { 0 };
    let ev = evaluate(
        &model,
        &config,
        &dataset,
        split,
        args.sequences,
        &device,
        keep,
        &mut |done, _| {
            progress.set_position(done as u64);
        },
    )?;
    progress.finish_and_clear();
    if ev.overall.frames == 0 {
        anyhow::bail!(
            "no frame of the {} split was scored ({} sequences; frame 0 of each is left out): \
             there is nothing to report",
            args.split,
            ev.sequences
        );
    }
    let o = &ev.overall;
    if o.dice
        .iter()
        .chain(&o.focal)
        .chain(&o.iou)
        .any(|v| !v.is_finite())
    {
        anyhow::bail!(
            "the scores are not finite (NaN or infinite): the network's outputs are, so \
             {} holds non-finite weights or was trained into divergence",
            args.weights.display()
        );
    }
    let subset = if ev.sequences < n_split {
        format!(
            " ({} of its {n_split} sequences, taken in turn from each cell)",
            ev.sequences
        )
    } else {
        String::new()
    };
    let md = format!(
        "# {} segmentation: {}{subset}\n\nWeights `{}` ({} cell, {} layers, {}x{} input), dataset `{}`.\n\n{}",
        config.model_name(),
        args.split,
        args.weights.display(),
        config.cell.name(),
        config.layers(),
        config.input_size,
        config.input_size,
        args.dataset.display(),
        ev.to_markdown()
    );
    say_inline!("{md}");
    if let Some(out) = &args.out {
        std::fs::write(out, &md).with_context(|| format!("writing {}", out.display()))?;
    }
    if let Some(path) = &args.frames {
        let mut csv = String::from(FrameRecord::CSV_HEADER);
        csv.push('\n');
        for r in &ev.frames {
            csv.push_str(&r.csv_row());
            csv.push('\n');
        }
        std::fs::write(path, csv).with_context(|| format!("writing {}", path.display()))?;
        say!("frames: {}", path.display());
    }
    if let Some(path) = &args.sheet {
        let titles: Vec<String> = ev
            .worst
            .iter()
            .map(|f| {
                format!(
                    "seq {} frame {} - {} / {} - forearm dice loss {:.2}",
                    f.sequence, f.frame, f.distance_class, f.occlusion_level, f.forearm_dice
                )
            })
            .collect();
        let panels: Vec<PredictionPanel<'_>> = ev
            .worst
            .iter()
            .zip(&titles)
            .map(|(f, title)| f.images.panel(title))
            .collect();
        let title = format!(
            "{} worst of {} {} frames - {}",
            panels.len(),
            ev.overall.frames,
            args.split,
            args.weights.display()
        );
        let (w, h, rgb) = prediction_sheet(&title, &panels, 2);
        write_png(path, w, h, PixelKind::Rgb, &rgb)?;
        say!("worst frames: {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}

#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Model preset (cpu, paper) ...
    #[arg(long, default_value = "cpu")]
    pub preset: String,
    /// ... or the configuration of a weight file.
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Backends to time (flex, tch, gpu), comma-separated.
    #[arg(long, default_value = "flex")]
    pub backends: String,
    /// CPU threads (1 to 256).
    #[arg(long, default_value_t = 2, value_parser = super::count_in::<1, { super::MAX_THREADS }>)]
    pub threads: usize,
    /// Sequences per batch (1 to 64).
    #[arg(long, default_value_t = 4, value_parser = super::count_in::<1, 64>)]
    pub batch: usize,
    /// Frames per sequence (2 to 100: as in training, the first frame is not scored).
    #[arg(long, default_value_t = 10, value_parser = super::count_in::<2, 100>)]
    pub frames: usize,
    /// Timed repetitions (1 to 1000).
    #[arg(long, default_value_t = 5, value_parser = super::count_in::<1, 1000>)]
    pub iters: usize,
    /// Override the input size (pixels per side).
    #[arg(long)]
    pub input_size: Option<usize>,
    /// Override the representation channels per layer, e.g. 16,32,64 (the bottom-up input
    /// channels follow: 3, then each layer's representation channels below).
    #[arg(long, value_delimiter = ',')]
    pub channels: Option<Vec<usize>>,
    /// Override the kernel of the cells' horizontal (hGRU) or recurrent (ConvLSTM)
    /// convolutions (an odd size).
    #[arg(long)]
    pub cell_kernel: Option<usize>,
    /// Write the benchmarked model's initial weights here (bench/procnet.py reads them).
    #[arg(long)]
    pub write_weights: Option<PathBuf>,
}

/// Prints one JSON line per backend: seconds per training step and per inference frame.
pub fn bench(args: &BenchArgs) -> Result<ExitCode> {
    use workcell::procnet::ProcNetConfig;
    let mut config = match &args.weights {
        Some(w) => weights::read_config(w)?,
        None => ProcNetConfig::preset(&args.preset)?,
    };
    if let Some(size) = args.input_size {
        config.input_size = size;
    }
    if let Some(channels) = &args.channels {
        config.repr_channels.clone_from(channels);
        config.input_channels = std::iter::once(3)
            .chain(channels.iter().copied())
            .take(channels.len())
            .collect();
    }
    if let Some(kernel) = args.cell_kernel {
        config.cell_kernel = kernel;
    }
    config.validate()?;
    backend::set_threads(args.threads);
    if let Some(path) = &args.write_weights {
        let model = config.init(&Backend::Flex.device()?, 0)?;
        weights::save(&model, &config, path)?;
    }
    for name in args.backends.split(',').filter(|n| !n.trim().is_empty()) {
        let b = Backend::parse(name.trim())?;
        let t = workcell::procnet::bench::time(&config, b, args.batch, args.frames, args.iters)?;
        // The convolutions' arithmetic over the time a frame took: how near the backend runs
        // to the machine's peak.
        let gflops = 2.0 * config.macs_per_frame() as f64 / t.infer_frame_s / 1e9;
        say!(
            "{{\"backend\": \"{}\", \"threads\": {}, \"train_step_s\": {:.6}, \"infer_frame_s\": {:.6}, \"gmac_per_frame\": {:.4}, \"infer_gflops\": {:.1}}}",
            b.name(),
            args.threads,
            t.train_step_s,
            t.infer_frame_s,
            config.macs_per_frame() as f64 / 1e9,
            gflops
        );
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::{interpolate, smooth};

    #[test]
    fn samples_are_joined_by_straight_lines_and_nothing_beyond_them() {
        let y = interpolate(&[(2, 1.0), (6, 3.0), (8, 2.0)], &[1, 2, 4, 5, 6, 7, 8, 9]);
        let want = [f64::NAN, 1.0, 2.0, 2.5, 3.0, 2.5, 2.0, f64::NAN];
        for (a, b) in y.iter().zip(want) {
            assert!(a == &b || (a.is_nan() && b.is_nan()), "{y:?}");
        }
    }

    #[test]
    fn the_moving_average_starts_at_the_first_value_and_follows_a_step() {
        // 0.95^k of the old level remains after k samples of the new one.
        let y = smooth([1.0, 0.0, 0.0, 0.0]);
        assert_eq!(y[0], 1.0);
        assert!((y[3] - 0.95_f64.powi(3)).abs() < 1e-12, "{y:?}");
    }
}
