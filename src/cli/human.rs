//! `workcell human`: recorded human motion. `stats` measures how fast people's joints move in
//! recorded clips, beside the project's motion generator.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use serde::Serialize;
use workcell::mocap::clean::{CleanConfig, CleanReport, clean};
use workcell::mocap::filter::{Butterworth2, DEFAULT_CUTOFF_HZ, filter_track};
use workcell::mocap::library::{Library, Split};
use workcell::mocap::stats::{Samples, Spread};
use workcell::mocap::{Axes, ClipFormat, ColumnsSpec, Landmark};
use workcell::robots::KinematicState;
use workcell::robots::math::Vector;
use workcell::sim::retarget::RetargetReport;
use workcell::sim::scenario::HumanSpeeds;
use workcell::sim::{CellModel, Scenario};

/// The most seeds of generated motion measured.
const MAX_SEEDS: usize = 10_000;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SplitArg {
    Tuning,
    Test,
    All,
}

/// A calibration of the motion generator (`human.speeds`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SpeedsArg {
    Iso13855,
    Recorded,
}

impl SpeedsArg {
    fn speeds(self) -> HumanSpeeds {
        match self {
            Self::Iso13855 => HumanSpeeds::Iso13855,
            Self::Recorded => HumanSpeeds::Recorded,
        }
    }
}

/// Which clips: libraries or files, and how files that are tables are read.
#[derive(Debug, clap::Args)]
pub struct ClipArgs {
    /// Clip libraries (`.toml`, e.g. data/mocap/library.toml) or clip files (`.bvh`,
    /// `.bvh.gz`, or tables with --rate-hz). Default: the shipped library.
    pub sources: Vec<PathBuf>,
    /// Which clips of a library.
    #[arg(long, value_enum, default_value_t = SplitArg::All)]
    pub split: SplitArg,
    /// For clip files that are tables: frames per second.
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// For tables: the landmark of each triple of columns, comma-separated, or `assembly`.
    #[arg(long, default_value = "assembly")]
    pub columns: String,
    /// For tables: metres per unit.
    #[arg(long, default_value_t = 1.0)]
    pub metres_per_unit: f64,
}

#[derive(Debug, clap::Args)]
pub struct StatsArgs {
    #[command(flatten)]
    pub clips: ClipArgs,
    /// Cut-off of the zero-phase low-pass applied before differentiating, Hz.
    #[arg(long, default_value_t = DEFAULT_CUTOFF_HZ)]
    pub cutoff_hz: f64,
    /// Measure the clips as recorded, without finding and repairing capture artefacts.
    #[arg(long)]
    pub no_clean: bool,
    /// Seeds of the project's generated motion measured beside the clips (0: none).
    #[arg(long, default_value_t = 20, value_parser = super::count_in::<0, MAX_SEEDS>)]
    pub generated: usize,
    /// The cell whose human the generator moves.
    #[arg(long, default_value = "configs/default.toml")]
    pub cell: PathBuf,
    /// The generator's calibrations measured (`iso13855`, `recorded`; comma-separated), each
    /// beside the clips. Default: the cell's `human.speeds`.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub speeds: Vec<SpeedsArg>,
    /// Seconds of generated motion per seed.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// One row per clip as well.
    #[arg(long)]
    pub per_clip: bool,
    /// Also write the table, and what cleaning changed, as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// The parts a table reports, with the landmarks pooled into each.
const PARTS: [(&str, &[Landmark]); 6] = [
    ("wrist", &[Landmark::LeftWrist, Landmark::RightWrist]),
    ("elbow", &[Landmark::LeftElbow, Landmark::RightElbow]),
    (
        "shoulder",
        &[Landmark::LeftShoulder, Landmark::RightShoulder],
    ),
    ("head", &[Landmark::Head]),
    ("chest", &[Landmark::Chest]),
    ("pelvis", &[Landmark::Pelvis]),
];

/// One row of the table.
#[derive(Debug, Clone, Serialize)]
struct Row {
    part: &'static str,
    source: String,
    clips: usize,
    seconds: f64,
    speed_m_s: Spread,
    acceleration_m_s2: Spread,
}

/// A group of clips measured together (a collection's split, a clip, the generator).
#[derive(Default)]
struct Group {
    clips: usize,
    seconds: f64,
    parts: BTreeMap<&'static str, Samples>,
    /// Parts with a track that never moved.
    still: Vec<&'static str>,
}

/// Whether a track never moves (the assembly trials' shoulders: one position per trial in
/// the source; the generator's shoulder, on a torso bolted in place).
fn constant(track: &[Vector]) -> bool {
    track.iter().all(|p| (*p - track[0]).length() < 1e-9)
}

impl Group {
    fn add(&mut self, landmark_tracks: &[(Landmark, Vec<Vector>)], rate_hz: f64, skip: &[bool]) {
        for (part, landmarks) in PARTS {
            for (l, track) in landmark_tracks {
                if landmarks.contains(l) && constant(track) {
                    if !self.still.contains(&part) {
                        self.still.push(part);
                    }
                    continue;
                }
                if landmarks.contains(l) {
                    self.parts
                        .entry(part)
                        .or_default()
                        .add(track, rate_hz, skip);
                }
            }
        }
    }

    fn rows(&self, source: &str) -> Vec<Row> {
        PARTS
            .iter()
            .filter_map(|(part, _)| {
                let samples = self.parts.get(part)?;
                let (speed_m_s, acceleration_m_s2) = samples.spread();
                Some(Row {
                    part,
                    source: source.to_string(),
                    clips: self.clips,
                    seconds: self.seconds,
                    speed_m_s,
                    acceleration_m_s2,
                })
            })
            .collect()
    }
}

#[derive(Serialize)]
struct Report {
    cutoff_hz: f64,
    cleaned: bool,
    rows: Vec<Row>,
    cleaning: Vec<CleanReport>,
}

/// One clip to measure: its id, the group it counts in, and how to read it.
struct Source {
    id: String,
    group: String,
    path: PathBuf,
    format: ClipFormat,
}

fn sources(args: &ClipArgs) -> Result<Vec<Source>> {
    let given = if args.sources.is_empty() {
        vec![PathBuf::from("data/mocap/library.toml")]
    } else {
        args.sources.clone()
    };
    let split = match args.split {
        SplitArg::Tuning => Some(Split::Tuning),
        SplitArg::Test => Some(Split::Test),
        SplitArg::All => None,
    };
    let mut out = Vec::new();
    for path in given {
        if path.extension().is_some_and(|e| e == "toml") {
            let library = Library::from_file(&path)?;
            out.extend(library.clips(split).map(|c| Source {
                id: c.id.clone(),
                group: format!("{} ({})", c.collection, c.split.name()),
                path: c.path.clone(),
                format: c.format.clone(),
            }));
            continue;
        }
        let format = match (workcell::mocap::format_of_path(&path), args.rate_hz) {
            (Some(format), _) => format,
            (None, Some(rate_hz)) => ClipFormat::Table {
                columns: if args.columns == "assembly" {
                    ColumnsSpec::Preset(args.columns.clone())
                } else {
                    ColumnsSpec::List(
                        args.columns
                            .split(',')
                            .map(|name| {
                                Landmark::of_name(name.trim()).with_context(|| {
                                    format!(
                                        "--columns: {name:?} is not a landmark ({})",
                                        Landmark::ALL.map(Landmark::name).join(", ")
                                    )
                                })
                            })
                            .collect::<Result<_>>()?,
                    )
                },
                rate_hz,
                metres_per_unit: args.metres_per_unit,
                axes: Axes::CAMERA,
                max_gap_s: 0.5,
            },
            (None, None) => bail!(
                "{}: not a BVH file or a library; for a table of joint positions give \
                 --rate-hz (and --columns)",
                path.display()
            ),
        };
        let id = workcell::mocap::clip_name(&path);
        out.push(Source {
            group: "clips given".into(),
            id,
            path,
            format,
        });
    }
    if out.is_empty() {
        bail!("no clips to measure");
    }
    Ok(out)
}

/// The generator's wrist, elbow and shoulder over `seconds` of `seeds` seeds of `cell`, at
/// 100 Hz.
fn generated(
    cell: &Path,
    speeds: Option<HumanSpeeds>,
    seeds: usize,
    seconds: f64,
    group: &mut Group,
    filter: &Butterworth2,
) -> Result<()> {
    let rate_hz = 100.0;
    let bar = super::progress_bar(
        seeds as u64,
        "{spinner} generated motion [{bar:40}] {pos}/{len} seeds",
    );
    for seed in 1..=seeds as u64 {
        let mut scenario = Scenario::from_file(cell)?;
        scenario.seed = seed;
        if let Some(speeds) = speeds {
            scenario.human.speeds = speeds;
        }
        let model = CellModel::new(&scenario, cell)?;
        let human = &model.human;
        let links: Vec<(Landmark, workcell::robots::LinkId)> = [
            (Landmark::RightWrist, "hand"),
            (Landmark::RightElbow, "forearm"),
            (Landmark::RightShoulder, "upper_arm"),
            (Landmark::LeftWrist, "left_hand"),
            (Landmark::LeftElbow, "left_forearm"),
            (Landmark::LeftShoulder, "left_upper_arm"),
        ]
        .into_iter()
        .filter_map(|(l, name)| human.link_id(name).map(|id| (l, id)))
        .collect();
        if links.is_empty() {
            bail!(
                "{}: its human has none of the links hand, forearm, upper_arm",
                cell.display()
            );
        }
        let mut kinematics = KinematicState::new(human);
        kinematics.X_WB = model.X_WH;
        let (mut q, mut qd) = (vec![0.0; human.dof()], vec![0.0; human.dof()]);
        let frames = (seconds * rate_hz).round() as usize;
        let mut tracks: Vec<(Landmark, Vec<Vector>)> = links
            .iter()
            .map(|&(l, _)| (l, Vec::with_capacity(frames)))
            .collect();
        for f in 0..frames {
            model
                .human_motion
                .sample(f as f64 / rate_hz, &mut q, &mut qd);
            human.forward_kinematics(&q, &mut kinematics)?;
            for ((_, link), (_, track)) in links.iter().zip(&mut tracks) {
                track.push(kinematics.link_pose(*link).translation);
            }
        }
        for (_, track) in &mut tracks {
            *track = filter_track(filter, track, rate_hz as usize);
        }
        group.add(&tracks, rate_hz, &[]);
        group.clips += 1;
        group.seconds += seconds;
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(())
}

pub fn stats(args: &StatsArgs) -> Result<ExitCode> {
    if !(args.cutoff_hz.is_finite() && args.cutoff_hz > 0.0) {
        bail!("--cutoff-hz {}: a frequency > 0", args.cutoff_hz);
    }
    if !(args.seconds.is_finite() && args.seconds > 0.0 && args.seconds <= 3600.0) {
        bail!("--seconds {}: from 0 to 3600", args.seconds);
    }
    let sources = sources(&args.clips)?;
    let mut groups: BTreeMap<String, Group> = BTreeMap::new();
    let mut per_clip: Vec<(String, Group)> = Vec::new();
    let mut cleaning = Vec::new();
    let bar = super::progress_bar(
        sources.len() as u64,
        "{spinner} clips [{bar:40}] {pos}/{len}",
    );
    for source in &sources {
        let clip = workcell::mocap::read_clip(&source.path, &source.format, source.id.clone())?;
        let filter = Butterworth2::low_pass(args.cutoff_hz, clip.rate_hz).with_context(|| {
            format!(
                "{}: a {} Hz cut-off needs more than {} Hz of frames",
                source.id,
                args.cutoff_hz,
                2.0 * args.cutoff_hz
            )
        })?;
        let pieces = if args.no_clean {
            vec![clip]
        } else {
            let (pieces, report) = clean(&clip, &CleanConfig::default());
            if !(report.repaired.is_empty() && report.cut.is_empty()) {
                cleaning.push(report);
            }
            pieces
        };
        let mut own = Group::default();
        for piece in &pieces {
            let pad = piece.rate_hz.round() as usize; // a second
            let tracks: Vec<(Landmark, Vec<Vector>)> = piece
                .landmarks
                .iter()
                .map(|&l| (l, filter_track(&filter, &piece.track(l), pad)))
                .collect();
            own.add(&tracks, piece.rate_hz, &piece.filled);
            own.seconds += piece.duration_s();
        }
        own.clips = 1;
        let group = groups.entry(source.group.clone()).or_default();
        group.clips += 1;
        group.seconds += own.seconds;
        for part in &own.still {
            if !group.still.contains(part) {
                group.still.push(part);
            }
        }
        for (part, samples) in &own.parts {
            let into = group.parts.entry(part).or_default();
            into.speed_m_s.extend_from_slice(&samples.speed_m_s);
            into.acceleration_m_s2
                .extend_from_slice(&samples.acceleration_m_s2);
        }
        if args.per_clip {
            per_clip.push((source.id.clone(), own));
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    let mut rows: Vec<Row> = Vec::new();
    let mut still: Vec<String> = Vec::new();
    let mut note_still = |name: &str, group: &Group| {
        still.extend(
            group
                .still
                .iter()
                .filter(|p| !group.parts.contains_key(*p))
                .map(|p| format!("{p} ({name})")),
        );
    };
    for (name, group) in &groups {
        rows.extend(group.rows(name));
        note_still(name, group);
    }
    let calibrations: Vec<Option<HumanSpeeds>> = if args.speeds.is_empty() {
        vec![None]
    } else {
        args.speeds.iter().map(|s| Some(s.speeds())).collect()
    };
    for speeds in calibrations.into_iter().filter(|_| args.generated > 0) {
        let mut group = Group::default();
        let filter = Butterworth2::low_pass(args.cutoff_hz, 100.0)
            .with_context(|| format!("--cutoff-hz {}: below 50 Hz", args.cutoff_hz))?;
        generated(
            &args.cell,
            speeds,
            args.generated,
            args.seconds,
            &mut group,
            &filter,
        )?;
        let name = format!(
            "generator ({} seeds of {}{})",
            args.generated,
            args.cell.display(),
            match speeds {
                Some(HumanSpeeds::Iso13855) => ", speeds iso13855",
                Some(HumanSpeeds::Recorded) => ", speeds recorded",
                None => "",
            }
        );
        rows.extend(group.rows(&name));
        note_still(&name, &group);
    }
    // Parts first, then sources: each part's recorded and generated figures side by side.
    rows.sort_by_key(|r| PARTS.iter().position(|(p, _)| *p == r.part));
    say!(
        "{} clips, low-pass {} Hz{}; speed m/s and acceleration m/s^2 per sample, both sides pooled",
        sources.len(),
        args.cutoff_hz,
        if args.no_clean {
            ", as recorded (no cleaning)".to_string()
        } else {
            format!(
                "; cleaning changed {} clips, dropped {} frames (--no-clean: as recorded)",
                cleaning.len(),
                cleaning.iter().map(|c| c.dropped_frames).sum::<usize>()
            )
        }
    );
    say!();
    say!(
        "| part | source | clips | minutes | speed peak | p99.9 | p99 | median | accel peak | p99.9 | p99 |"
    );
    say!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let line = |r: &Row| {
        say!(
            "| {} | {} | {} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2} | {:.0} | {:.0} | {:.0} |",
            r.part,
            r.source,
            r.clips,
            r.seconds / 60.0,
            r.speed_m_s.peak,
            r.speed_m_s.p999,
            r.speed_m_s.p99,
            r.speed_m_s.median,
            r.acceleration_m_s2.peak,
            r.acceleration_m_s2.p999,
            r.acceleration_m_s2.p99
        );
    };
    rows.iter().for_each(line);
    if !still.is_empty() {
        say!();
        say!("Never moving, left out: {}.", still.join(", "));
    }
    if args.per_clip {
        say!();
        say!("Per clip, the wrists:");
        say!();
        say!(
            "| part | source | clips | minutes | speed peak | p99.9 | p99 | median | accel peak | p99.9 | p99 |"
        );
        say!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
        for (id, group) in &per_clip {
            group
                .rows(id)
                .iter()
                .filter(|r| r.part == "wrist")
                .for_each(line);
        }
    }
    if !cleaning.is_empty() {
        say!();
        say!(
            "Capture artefacts (a joint faster than a person: {}):",
            describe(&CleanConfig::default())
        );
        for c in &cleaning {
            let repaired: Vec<String> = c
                .repaired
                .iter()
                .map(|&(f, n, l, v)| {
                    format!("{} bridged ({} at {v:.0} m/s)", frames(f, n), l.name())
                })
                .collect();
            let cut: Vec<String> = c
                .cut
                .iter()
                .map(|&(f, n)| {
                    if n == 0 {
                        format!("split at frame {f}")
                    } else {
                        format!("{} cut", frames(f, n))
                    }
                })
                .collect();
            say!(
                "- {}: {}; {} of {} frames dropped",
                c.clip,
                [repaired, cut].concat().join(", "),
                c.dropped_frames,
                c.frames
            );
        }
    }
    if let Some(path) = &args.json {
        let report = Report {
            cutoff_hz: args.cutoff_hz,
            cleaned: !args.no_clean,
            rows,
            cleaning,
        };
        let text = serde_json::to_string_pretty(&report).context("serialising the report")?;
        workcell::robots::output::write_atomic(path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `frame F` or `frames F-L` for `n` frames from `f`.
fn frames(f: usize, n: usize) -> String {
    if n == 1 {
        format!("frame {f}")
    } else {
        format!("frames {f}-{}", f + n - 1)
    }
}

fn describe(c: &CleanConfig) -> String {
    format!(
        "wrists above {} m/s, elbows above {}, the trunk and head above {}; spans up to {} s bridged, longer ones cut, pieces under {} s dropped",
        c.max_wrist_speed_m_s,
        c.max_elbow_speed_m_s,
        c.max_trunk_speed_m_s,
        c.max_repair_s,
        c.min_piece_s
    )
}

#[derive(Debug, clap::Args)]
pub struct RetargetArgs {
    #[command(flatten)]
    pub clips: ClipArgs,
    /// The cell whose human model the clips are laid on.
    #[arg(long, default_value = "configs/default.toml")]
    pub cell: PathBuf,
    /// Lay the clips on this human model instead of the cell's (a catalogue name such as
    /// `human` or `human_arm`, an added robot or a URDF path).
    #[arg(long)]
    pub model: Option<String>,
    /// The recorded arm the model follows.
    #[arg(long, value_enum, default_value_t = SideArg::Right)]
    pub side: SideArg,
    /// Cut-off of the low-pass on the recorded positions, Hz.
    #[arg(long, default_value_t = DEFAULT_CUTOFF_HZ)]
    pub cutoff_hz: f64,
    /// Weight of the elbow's target against the wrist's.
    #[arg(long, default_value_t = workcell::sim::retarget::RetargetConfig::default().elbow_weight)]
    pub elbow_weight: f64,
    /// Also write every clip's report as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write the retargeted clip as an animated binary glTF (`.glb`) of the cell, for any
    /// glTF viewer (one clip only).
    #[arg(long)]
    pub gltf: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SideArg {
    Left,
    Right,
}

/// Lays each clip on the cell's human model and prints what the model could not follow:
/// the wrist's and the elbow's distance from the recorded directions on the model's bones,
/// the frames at a joint limit or held back by a velocity limit.
pub fn retarget(args: &RetargetArgs) -> Result<ExitCode> {
    use workcell::sim::retarget::{RetargetConfig, Side, retarget};
    let sources = sources(&args.clips)?;
    if args.gltf.is_some() && sources.len() != 1 {
        bail!("--gltf writes one clip; {} were given", sources.len());
    }
    let mut scenario = Scenario::from_file(&args.cell)?;
    scenario.human.recorded = None;
    if let Some(name) = &args.model {
        scenario.human.model.clone_from(name);
    }
    let model = CellModel::new(&scenario, &args.cell)?;
    let config = RetargetConfig {
        side: match args.side {
            SideArg::Left => Side::Left,
            SideArg::Right => Side::Right,
        },
        cutoff_hz: args.cutoff_hz,
        elbow_weight: args.elbow_weight,
    };
    if !(args.elbow_weight.is_finite() && args.elbow_weight >= 0.0) {
        bail!("--elbow-weight {}: a weight >= 0", args.elbow_weight);
    }
    say!(
        "{} clips on {} ({}), the {} arm; errors are the distance from the recorded directions laid on the model's bones",
        sources.len(),
        model.human.name(),
        args.cell.display(),
        config.side.name()
    );
    say!();
    say!(
        "| clip | frames kept | wrist error median (mm) | wrist peak (mm) | elbow median (mm) | elbow peak (mm) | left wrist median, peak (mm) | at a joint limit | velocity-limited | recorded bones (m) | trunk turn, lean (deg); pelvis travel (m) |"
    );
    say!("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    let mut reports = Vec::new();
    let (mut wrist, mut elbow, mut limited, mut frames) = (Vec::new(), Vec::new(), 0, 0);
    let mut left_wrist = Vec::new();
    for source in &sources {
        let clip = workcell::mocap::read_clip(&source.path, &source.format, source.id.clone())?;
        let (motion, r) = retarget(&clip, &model.human, &config)?;
        if let Some(path) = &args.gltf {
            let glb = clip_glb(&model, &motion)?;
            workcell::robots::output::write_atomic(path, &glb)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        let trunk = r.trunk.map_or_else(
            || "-".to_string(),
            |t| {
                format!(
                    "{:.0} to {:.0}, {:.0} to {:.0}; {:.2}",
                    t.turn_deg[0], t.turn_deg[1], t.lean_deg[0], t.lean_deg[1], t.pelvis_travel_m
                )
            },
        );
        let left = r.left_wrist_error_m.map_or_else(
            || "-".to_string(),
            |e| format!("{:.0}, {:.0}", 1e3 * e.median, 1e3 * e.peak),
        );
        left_wrist.extend(r.left_wrist_error_m.map(|e| e.median));
        say!(
            "| {} | {} of {} | {:.0} | {:.0} | {:.0} | {:.0} | {left} | {} | {} | {:.2}, {:.2} | {trunk} |",
            r.clip,
            r.frames,
            r.clip_frames,
            1e3 * r.wrist_error_m.median,
            1e3 * r.wrist_error_m.peak,
            1e3 * r.elbow_error_m.median,
            1e3 * r.elbow_error_m.peak,
            r.clamped_frames,
            r.velocity_limited_frames,
            r.recorded_bones_m[0],
            r.recorded_bones_m[1]
        );
        wrist.push(r.wrist_error_m.median);
        elbow.push(r.elbow_error_m.median);
        limited += r.velocity_limited_frames;
        frames += r.frames;
        reports.push(r);
    }
    let (spread, elbow) = (Spread::of(&mut wrist), Spread::of(&mut elbow));
    say!();
    say!(
        "median over clips of the wrist's median error {:.0} mm (worst clip {:.0} mm), of the elbow's {:.0} mm (worst clip {:.0} mm); {limited} of {frames} frames velocity-limited; the model's bones {:.2}, {:.2} m",
        1e3 * spread.median,
        1e3 * spread.peak,
        1e3 * elbow.median,
        1e3 * elbow.peak,
        reports.first().map_or(0.0, |r| r.model_bones_m[0]),
        reports.first().map_or(0.0, |r| r.model_bones_m[1])
    );
    if !left_wrist.is_empty() {
        let left = Spread::of(&mut left_wrist);
        say!(
            "the left arm (the other side of the recording) on {} clips: the wrist's median error {:.0} mm over clips (worst clip {:.0} mm)",
            left_wrist.len(),
            1e3 * left.median,
            1e3 * left.peak
        );
    }
    joint_speed_table(&model.human, &reports);
    if let Some(path) = &args.gltf {
        say!("replay: {}", path.display());
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&reports).context("serialising the reports")?;
        workcell::robots::output::write_atomic(path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Per joint of `human`: its velocity limit beside the clips' 99th-percentile and peak
/// speeds before the limits (the median clip's and the fastest clip's).
fn joint_speed_table(human: &workcell::robots::RobotModel, reports: &[RetargetReport]) {
    if reports.is_empty() {
        return;
    }
    let limits = human.velocity_limits();
    say!();
    say!("joint speeds before the velocity limits, over the clips (rad/s; m/s for the pelvis):");
    say!();
    say!(
        "| joint | limit | p99, median clip | p99, fastest clip | peak, median clip | clips whose p99 is above the limit |"
    );
    say!("|---|---:|---:|---:|---:|---:|");
    for (j, &id) in human.actuated_joints().iter().enumerate() {
        let speed =
            |r: &RetargetReport| r.joint_speed.get(j).map_or((0.0, 0.0), |s| (s.p99, s.peak));
        let mut p99: Vec<f64> = reports.iter().map(|r| speed(r).0).collect();
        let mut peak: Vec<f64> = reports.iter().map(|r| speed(r).1).collect();
        let above = p99.iter().filter(|&&v| v > limits[j]).count();
        let fastest = reports
            .iter()
            .max_by(|a, b| speed(a).0.total_cmp(&speed(b).0))
            .map_or("-", |r| r.clip.as_str());
        let (p99, peak) = (Spread::of(&mut p99), Spread::of(&mut peak));
        say!(
            "| {} | {:.1} | {:.2} | {:.2} ({fastest}) | {:.2} | {above} of {} |",
            human.joints()[id].name,
            limits[j],
            p99.median,
            p99.peak,
            peak.median,
            reports.len()
        );
    }
}

/// The cell with its robot at rest and its human playing `motion`, at 30 frames a second, as
/// binary glTF.
fn clip_glb(
    model: &CellModel,
    motion: &workcell::sim::retarget::RecordedMotion,
) -> Result<Vec<u8>> {
    let mut robot = KinematicState::new(&model.robot);
    robot.X_WB = model.X_WR;
    model
        .robot
        .forward_kinematics(&model.initial_q, &mut robot)?;
    let mut human = KinematicState::new(&model.human);
    human.X_WB = model.X_WH;
    let (mut q, mut qd) = (vec![0.0; model.human.dof()], vec![0.0; model.human.dof()]);
    let mut recording = workcell::evaluate::Recording {
        t_s: Vec::new(),
        robot_link_poses: Vec::new(),
        human_link_poses: Vec::new(),
        robot_q: Vec::new(),
        closest: Vec::new(),
        other_arm: Vec::new(),
    };
    // The recording's other arm, beside the one the model follows.
    let other_arm = workcell::evaluate::other_arm::OtherArm::new(&model.human);
    let mut other_parts = Vec::new();
    let frames = (motion.duration_s() * 30.0).floor() as usize + 1;
    for k in 0..frames {
        let t = k as f64 / 30.0;
        motion.sample(t, &mut q, &mut qd);
        model.human.forward_kinematics(&q, &mut human)?;
        recording.t_s.push(t);
        recording.robot_link_poses.push(robot.link_poses().to_vec());
        recording.human_link_poses.push(human.link_poses().to_vec());
        recording.robot_q.push(model.initial_q.clone());
        recording.closest.push(None);
        other_parts.clear();
        if let (Some(arm), Some(joints_T)) = (&other_arm, motion.other_arm_at(t)) {
            arm.place_into(human.link_pose(arm.torso()), joints_T, &mut other_parts);
        }
        (recording.other_arm).push(other_parts.iter().map(|p| p.capsule).collect());
    }
    Ok(workcell::evaluate::replay::episode_glb(
        model,
        &[],
        &recording,
        workcell::safety::FilterConfig::default().d_min_m, // no closest pairs are drawn
        &motion.name,
    ))
}
