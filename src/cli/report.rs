//! `workcell report`: reports made from the run records of evaluations.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use workcell::evaluate::record::{RunRecord, merge};
use workcell::evaluate::report::{Aggregate, task_ratio};
use workcell::plot::{Labelled, svg_scatter, svg_to_png};

use super::evaluate::{OUTPUTS, finish_report};

#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// The output folders of the shards (`workcell evaluate --shard K/N --out DIR`), in any
    /// order; every shard of the evaluation exactly once.
    #[arg(required = true)]
    pub shards: Vec<PathBuf>,
    /// Where the merged report goes (created; existing outputs are kept unless --force).
    #[arg(long, default_value = "out/merged")]
    pub out: PathBuf,
    /// Overwrite existing output files.
    #[arg(long)]
    pub force: bool,
    /// Exit with status 2 when any episode violates d_min.
    #[arg(long)]
    pub fail_on_violation: bool,
}

/// Merges shard folders into the report a single process would have written.
///
/// # Errors
/// A folder without a readable run record, shards of different evaluations, a shard twice
/// or missing, and I/O errors, each naming the folder or file.
pub fn merge_shards(args: &MergeArgs) -> Result<ExitCode> {
    // Writing into a shard's folder would replace the very record being merged.
    if let Ok(out) = args.out.canonicalize() {
        for dir in &args.shards {
            if dir.canonicalize().is_ok_and(|d| d == out) {
                anyhow::bail!(
                    "--out {} is the shard folder {}: the merged report would overwrite that \
                     shard's record; choose another --out",
                    args.out.display(),
                    dir.display()
                );
            }
        }
    }
    let records = args
        .shards
        .iter()
        .map(|dir| {
            RunRecord::read(dir)
                .map(|r| (dir.clone(), r))
                .with_context(|| format!("shard folder {}", dir.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    let (record, replay_dirs) = merge(records)?;
    let out = super::OutputDir::create(&args.out, args.force, &OUTPUTS)?;
    // The whole run's worst episodes' replays, from the shards that wrote them.
    for ((_, file), dir) in record.replays.iter().zip(&replay_dirs) {
        let (from, to) = (dir.join(file), out.path().join(file));
        if let Some(parent) = to.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        let bytes = workcell::robots::input::read_regular_file(
            &from,
            workcell::robots::input::MAX_MESH_BYTES,
        )
        .with_context(|| format!("reading {}", from.display()))?;
        std::fs::write(&to, bytes).with_context(|| format!("writing {}", to.display()))?;
    }
    finish_report(out, &record, &args.out, args.fail_on_violation)
}

/// Files `report sweep` writes.
pub const SWEEP_OUTPUTS: [&str; 4] = ["sweep.md", "sweep.csv", "sweep.svg", "sweep.png"];

#[derive(Debug, clap::Args)]
pub struct SweepArgs {
    /// The folders of the sweep's points: each a whole evaluation (one process, or its
    /// shards merged).
    #[arg(required = true)]
    pub points: Vec<PathBuf>,
    /// Where the sweep's table and plot go.
    #[arg(long, default_value = "out/sweep")]
    pub out: PathBuf,
    /// Overwrite existing output files.
    #[arg(long)]
    pub force: bool,
}

/// One point of a sweep, as its table row shows it.
struct PointRow {
    name: String,
    /// The point's summary.html, relative to the sweep's output when inside it.
    page: String,
    settings: String,
    a: Aggregate,
    d_min_m: f64,
}

/// The table (`sweep.md`, `sweep.csv`) and trade-off plot (`sweep.svg`, `.png`) of a sweep's
/// points: per point its settings, violations, contacts and task time.
///
/// # Errors
/// A folder without a readable run record, a record of a single shard (merge it first), and
/// I/O errors.
pub fn sweep_table(args: &SweepArgs) -> Result<ExitCode> {
    let mut rows = Vec::new();
    for dir in &args.points {
        let record =
            RunRecord::read(dir).with_context(|| format!("sweep point {}", dir.display()))?;
        let s = &record.settings;
        if s.shards > 1 {
            anyhow::bail!(
                "{} is shard {} of {}: merge the shards first (`workcell report merge`)",
                dir.display(),
                record.shard,
                s.shards
            );
        }
        let mut settings = vec![format!("filter {}", s.filter)];
        if let Some(p) = &s.perception_arg {
            settings.push(format!("perception {p}"));
        }
        settings.extend(s.overrides.iter().cloned());
        let page = dir.join("summary.html");
        let page = page
            .strip_prefix(&args.out)
            .unwrap_or(&page)
            .display()
            .to_string();
        rows.push(PointRow {
            page,
            name: dir.file_name().map_or_else(
                || dir.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            ),
            settings: settings.join(", "),
            a: Aggregate::of(&record.metrics),
            d_min_m: s.d_min_m,
        });
    }
    let out = super::OutputDir::create(&args.out, args.force, &SWEEP_OUTPUTS)?;
    let mut md = String::from(
        "# Sweep\n\n| point | settings | report | episodes | with violation | violations | min separation (m) | d_min (m) | contacts moving / standing | finished | task time / unfiltered |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let mut csv = String::from(
        "point,settings,episodes,episodes_with_violation,violations,min_separation_m,d_min_m,contacts_moving,contacts_standing,finished,task_ratio\n",
    );
    for r in &rows {
        let a = &r.a;
        md.push_str(&format!(
            "| {} | {} | [summary.html]({}) | {} | {} | {} | {:.4} | {:.3} | {} / {} | {}/{} | {} |\n",
            r.name,
            r.settings,
            r.page,
            a.episodes,
            a.episodes_with_violation,
            a.violations,
            a.min_separation_m,
            r.d_min_m,
            a.contacts_moving,
            a.contacts_standing,
            a.finished,
            a.episodes,
            task_ratio(a.mean_task_ratio, "")
        ));
        csv.push_str(&format!(
            "{},\"{}\",{},{},{},{:.6},{},{},{},{},{}\n",
            r.name,
            r.settings.replace('"', "\"\""),
            a.episodes,
            a.episodes_with_violation,
            a.violations,
            a.min_separation_m,
            r.d_min_m,
            a.contacts_moving,
            a.contacts_standing,
            a.finished,
            if a.mean_task_ratio.is_finite() {
                format!("{:.4}", a.mean_task_ratio)
            } else {
                String::new()
            }
        ));
    }
    md.push_str("\n![violations against task time](sweep.png)\n");
    let points: Vec<Labelled> = rows
        .iter()
        .map(|r| Labelled {
            label: r.name.clone(),
            detail: r.settings.clone(),
            x: r.a.mean_task_ratio,
            y: 100.0 * r.a.episodes_with_violation as f64 / r.a.episodes.max(1) as f64,
        })
        .collect();
    let svg = svg_scatter(
        "Sweep: episodes that came closer than d_min against task time",
        "task time / unfiltered (mean over finished episodes)",
        "episodes with a violation [%]",
        &points,
    );
    let write = |name: &str, text: &str| {
        let p = out.path().join(name);
        std::fs::write(&p, text).with_context(|| format!("writing {}", p.display()))
    };
    write("sweep.md", &md)?;
    write("sweep.csv", &csv)?;
    write("sweep.svg", &svg)?;
    svg_to_png(&svg, &out.path().join("sweep.png"))?;
    out.commit()?;
    say!("{}", md.trim_end());
    say!("sweep table: {}", args.out.join("sweep.md").display());
    Ok(ExitCode::SUCCESS)
}
