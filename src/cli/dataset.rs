//! `workcell dataset`: generate the ProcNet dataset, look at it.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Instant;

use anyhow::{Context, Result};
use workcell::crop::{CropCounts, TrackerCrop};
use workcell::render::dataset::{ViewSource, forearm_stats};
use workcell::render::image::{PixelKind, write_png};
use workcell::sim::dataset::{Dataset, DatasetConfig, Generator, Split, contact_sheet};

#[derive(Debug, clap::Args)]
pub struct GenerateArgs {
    /// Dataset configuration (TOML), e.g. configs/dataset.toml.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output folder. A run into a folder of the same configuration completes it (finished
    /// sequences are kept); a folder of another configuration is refused.
    #[arg(long, required_unless_present = "print_defaults")]
    pub out: Option<PathBuf>,
    /// Print the configuration (`--config`'s, else the defaults) with every default filled
    /// in, then exit.
    #[arg(long)]
    pub print_defaults: bool,
    /// The renderer: `cpu` (the software rasterizer) or `gpu` (wgpu, feature `gpu`). The
    /// GPU's pixels differ from the CPU's where its rasterizer rounds differently, so a
    /// dataset is made with one backend throughout.
    #[arg(long, default_value = "cpu")]
    pub backend: workcell::render::Backend,
    /// Whose region of interest each frame is read through: `dataset` (the configuration's
    /// `[roi]`: one kind of crop per sequence) or `tracker` (the deployed `ArmTracker`'s,
    /// chosen frame by frame as it tracks the arm with ProcNet and the depth image: the
    /// workspace crop until two frames in a row gave a pose, then the crop around the arm it
    /// found). The scenes are the same either way.
    #[arg(long, default_value = "dataset")]
    pub crop: String,
    /// With `--crop tracker`: the tracker's ProcNet weights [default: the shipped network
    /// for a camera with depth and the dataset's human, procnet/weights/
    /// procnet-depth-human.safetensors for the whole body, procnet-depth.safetensors for
    /// `human_arm`].
    #[arg(long)]
    pub weights: Option<PathBuf>,
    /// Make only the sequences of these splits (comma-separated: train, validation, test)
    /// [default: all]. A later run into the same folder may add the others.
    #[arg(long, value_delimiter = ',')]
    pub splits: Vec<String>,
}

#[derive(Debug, clap::Args)]
pub struct ShowArgs {
    /// A dataset folder.
    pub dir: PathBuf,
    /// The contact sheet to write (default: DIR/contact_sheet.png).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Frames per sequence on the sheet (1 to 64).
    #[arg(long, default_value_t = 6, value_parser = super::count_in::<1, 64>)]
    pub columns: usize,
}

#[derive(Debug, clap::Args)]
pub struct StatsArgs {
    /// A dataset folder.
    pub dir: PathBuf,
    /// For datasets of format 1 (whole frames): the network input the ceiling is measured
    /// at (the shipped network reads 64x64). Datasets from format 2 on record theirs.
    #[arg(long, default_value_t = 64)]
    pub input: u32,
}

/// `workcell dataset stats DIR`.
pub fn stats(args: &StatsArgs) -> Result<ExitCode> {
    let dataset = Dataset::open(&args.dir)?;
    if !(4..=4096).contains(&args.input) {
        anyhow::bail!("--input {} is not in 4..=4096", args.input);
    }
    let m = &dataset.manifest;
    let bar = super::progress_bar(m.sequences.len() as u64, "{bar:40} {pos}/{len} sequences");
    let rows = forearm_stats(&dataset, args.input, &|k| bar.set_position(k as u64))?;
    bar.finish_and_clear();
    let frames: usize = m.sequences.iter().map(|s| s.frames).sum();
    let look = m.human.as_ref().map_or("unknown", |h| h.look.name());
    say!(
        "{}: {} ({} sequences, {frames} frames of {}x{} px, {look} human)",
        args.dir.display(),
        m.format,
        m.sequences.len(),
        m.width_px,
        m.height_px
    );
    if m.format.ends_with("/1") {
        say!(
            "  format 1: the stored frame is the camera's image; ceiling at a {0}x{0} input",
            args.input
        );
    }
    say!(
        "  {:<14} {:<8} {:<9} {:>7} {:>8} {:>10} {:>21} {:>23}",
        "source",
        "distance",
        "crop",
        "frames",
        "forearm",
        "forearm px",
        "forearm width px",
        "perfect-network Dice"
    );
    say!(
        "  {:<14} {:<8} {:<9} {:>7} {:>8} {:>10} {:>21} {:>23}",
        "",
        "",
        "",
        "",
        "in view",
        "(median)",
        "median [p10, p90]",
        "loss mean (median)"
    );
    for r in &rows {
        say!(
            "  {:<14} {:<8} {:<9} {:>7} {:>8} {:>10.0} {:>8.1} [{:>4.1}, {:>4.1}] {:>13.3} ({:.3})",
            r.source,
            r.distance_class,
            r.roi,
            r.frames,
            r.with_forearm,
            r.pixels_median,
            r.width_px[1],
            r.width_px[0],
            r.width_px[2],
            r.perfect_dice_loss[0],
            r.perfect_dice_loss[1]
        );
    }
    say!(
        "  width: sqrt(12 x the smaller eigenvalue of the mask's pixel covariance) (a bar's width);"
    );
    say!(
        "  perfect network: the truth averaged to the stored grid, resampled back bilinearly, \
         thresholded at 1/2"
    );
    Ok(ExitCode::SUCCESS)
}

pub fn generate(args: &GenerateArgs) -> Result<ExitCode> {
    if args.print_defaults {
        let config = match &args.config {
            Some(path) => DatasetConfig::from_file(path)?,
            None => DatasetConfig::default(),
        };
        say_inline!("{}", config.to_toml());
        return Ok(ExitCode::SUCCESS);
    }
    let path = args
        .config
        .clone()
        .context("--config FILE is required (see configs/dataset.toml)")?;
    let out = args.out.as_ref().context("--out DIR is required")?;
    let splits = args
        .splits
        .iter()
        .map(|name| {
            Split::ALL
                .into_iter()
                .find(|s| s.name() == name.trim())
                .with_context(|| {
                    format!("--splits: unknown split {name:?} (train, validation, test)")
                })
        })
        .collect::<Result<Vec<Split>>>()?;
    let mut generator = Generator::from_file(&path)?
        .with_backend(args.backend)
        .with_splits(&splits);
    let counts = Arc::new(CropCounts::default());
    match args.crop.as_str() {
        "dataset" => {
            if args.weights.is_some() {
                anyhow::bail!("--weights is a setting of --crop tracker");
            }
        }
        "tracker" => {
            let side = workcell::perception::DEFAULT_INPUT_PX;
            let stored = generator.config.input_px;
            if stored as usize != side {
                anyhow::bail!(
                    "--crop tracker: the tracker reads its region at {side}x{side} and this \
                     configuration stores {stored}x{stored} (input_px)"
                );
            }
            let weights = args.weights.clone().unwrap_or_else(|| {
                PathBuf::from(workcell::procnet::weights::shipped_for(
                    true,
                    &generator.human().model,
                ))
            });
            let factory = TrackerCrop::factory(&generator.human(), &weights, counts.clone())
                .with_context(|| format!("the tracker's network, {}", weights.display()))?;
            let name = format!(
                "tracker (ArmTracker, RGB-D, weights {})",
                weights_stamp(&weights)?
            );
            generator = generator.with_crop(&name, factory);
        }
        other => anyhow::bail!("unknown --crop {other:?} (dataset, tracker)"),
    }
    let n = generator.sequence_count();
    let bar = super::progress_bar(
        n as u64,
        "{bar:40} {pos}/{len} sequences, {elapsed} (eta {eta})",
    );
    let start = Instant::now();
    let report = generator.generate(out, &|done| bar.set_position(done as u64))?;
    bar.finish_and_clear();
    let wall = start.elapsed().as_secs_f64();
    let m = &report.manifest;
    let frames: usize = m.sequences.iter().map(|s| s.frames).sum();
    say!(
        "{} sequences ({} new), {frames} frames of {}x{} px in {wall:.1} s -> {}",
        m.sequences.len(),
        report.generated,
        m.width_px,
        m.height_px,
        out.display()
    );
    for split in Split::ALL {
        let of: Vec<_> = m.sequences.iter().filter(|s| s.split == split).collect();
        let recorded: Vec<&str> = of.iter().filter_map(|s| s.clip.as_deref()).collect();
        if recorded.is_empty() {
            say!("  {:<10} {} sequences", split.name(), of.len());
        } else {
            let clips: std::collections::BTreeSet<&str> = recorded.iter().copied().collect();
            say!(
                "  {:<10} {} sequences, {} of recorded people ({} clips)",
                split.name(),
                of.len(),
                recorded.len(),
                clips.len()
            );
        }
    }
    let t = report.timing;
    let total = t.total().as_secs_f64().max(1e-9);
    if report.generated > 0 {
        say!(
            "  time (all threads): simulate {:.0}%, render {:.0}%, occlusion and labels {:.0}%, PNG+JSON encoding {:.0}%, writing {:.0}%",
            100.0 * t.simulate.as_secs_f64() / total,
            100.0 * t.render.as_secs_f64() / total,
            100.0 * t.occlusion.as_secs_f64() / total,
            100.0 * t.encode.as_secs_f64() / total,
            100.0 * t.write.as_secs_f64() / total,
        );
    }
    let read = counts.frames.load(Ordering::Relaxed);
    if read > 0 {
        say!(
            "  the tracker read {read} new frames: a pose in {}, {} through the tracked crop",
            counts.posed.load(Ordering::Relaxed),
            counts.tracked.load(Ordering::Relaxed)
        );
    }
    let missing: usize = m.sequences.iter().map(|s| s.frames_without_forearm).sum();
    if missing > 0 {
        say!("  {missing} frames show no forearm (out of view after every camera draw)");
    }
    say!("look at it: workcell dataset show {}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// What names weights in a dataset's stamp: the file's name and a hash of its bytes, so that
/// a folder made with other weights is not completed with these.
fn weights_stamp(path: &std::path::Path) -> Result<String> {
    let bytes = workcell::robots::input::read_regular_file(
        path,
        workcell::procnet::weights::MAX_WEIGHTS_BYTES,
    )
    .with_context(|| format!("reading {}", path.display()))?;
    // FNV-1a, 64 bits: a fingerprint, not a defence.
    let hash = bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    Ok(format!("{name}, fnv1a {hash:016x}"))
}

pub fn show(args: &ShowArgs) -> Result<ExitCode> {
    let dataset = Dataset::open(&args.dir)?;
    let (w, h, rgb) = contact_sheet(&dataset, args.columns)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.dir.join("contact_sheet.png"));
    write_png(&out, w, h, PixelKind::Rgb, &rgb)?;
    let m = &dataset.manifest;
    say!(
        "{}: {} sequences of {}x{} px",
        args.dir.display(),
        m.sequences.len(),
        m.width_px,
        m.height_px
    );
    let mut pairs: Vec<(ViewSource, String, String, usize, f64)> = Vec::new();
    for s in &m.sequences {
        let o = s.mean_forearm_occlusion.unwrap_or(f64::NAN);
        match pairs
            .iter_mut()
            .find(|p| p.0 == s.source && p.1 == s.distance_class && p.2 == s.occlusion_level)
        {
            Some(p) => {
                p.3 += 1;
                p.4 += o;
            }
            None => pairs.push((
                s.source.clone(),
                s.distance_class.clone(),
                s.occlusion_level.clone(),
                1,
                o,
            )),
        }
    }
    pairs.sort_by(|a, b| (&a.0, &a.1).cmp(&(&b.0, &b.1)));
    say!(
        "  {:<14} {:<8} {:<8} {:>9} {:>22}",
        "source",
        "distance",
        "level",
        "sequences",
        "mean forearm occlusion"
    );
    for (src, d, l, k, o) in pairs {
        say!(
            "  {src:<14} {d:<8} {l:<8} {k:>9} {:>21.0}%",
            100.0 * o / k as f64
        );
    }
    say!("measure it: workcell dataset stats {}", args.dir.display());
    say!("contact sheet: {}", out.display());
    Ok(ExitCode::SUCCESS)
}
