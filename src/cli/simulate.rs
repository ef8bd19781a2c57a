//! `workcell simulate`: run a scenario, write what happened.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use serde::Serialize;
use workcell::plot::{Panel, WorldPath, svg_cell_views, svg_panels};
use workcell::robots::RobotModel;
use workcell::robots::math::Pose;

/// The longest `--seconds` of a simulation: an hour of simulated time.
const MAX_SECONDS: f64 = 3600.0;
use workcell::sim::{CellModel, CellState, RobotCommand, Scenario, step};

/// Files `simulate` writes into `--out`.
pub const OUTPUTS: [&str; 5] = [
    "robot_joints.csv",
    "human_poses.csv",
    "trajectories.svg",
    "cell.svg",
    "summary.json",
];

#[derive(Debug, clap::Args)]
pub struct SimulateArgs {
    /// Scenario file (TOML), e.g. configs/default.toml.
    pub scenario: Option<PathBuf>,
    /// Simulated duration, s (at most an hour).
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Seed; overrides the scenario's.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output folder (created; existing outputs are kept unless --force).
    #[arg(long, default_value = "out/simulate")]
    pub out: PathBuf,
    /// Samples written per simulated second.
    #[arg(long, default_value_t = 100.0)]
    pub rate_hz: f64,
    /// Overwrite existing output files.
    #[arg(long)]
    pub force: bool,
    /// Print the scenario with every default filled in, then exit.
    #[arg(long)]
    pub print_defaults: bool,
}

#[derive(Debug, Serialize)]
struct Summary {
    scenario: String,
    seed: u64,
    robot: String,
    human: String,
    time_step_s: f64,
    simulated_s: f64,
    steps: u64,
    wall_s: f64,
    steps_per_s: f64,
    outputs: Vec<String>,
}

pub fn run(args: &SimulateArgs) -> Result<ExitCode> {
    if args.print_defaults {
        let scenario = match &args.scenario {
            Some(path) => Scenario::from_file(path)?,
            None => Scenario::default(),
        };
        say_inline!("{}", scenario.to_toml());
        return Ok(ExitCode::SUCCESS);
    }
    let Some(path) = &args.scenario else {
        bail!("give a scenario file, e.g. `workcell simulate configs/default.toml`");
    };
    if !(args.seconds > 0.0 && args.seconds <= MAX_SECONDS) {
        bail!(
            "--seconds must be in (0, {MAX_SECONDS}], not {}",
            args.seconds
        );
    }
    if !(args.rate_hz > 0.0 && args.rate_hz.is_finite()) {
        bail!("--rate-hz must be > 0, got {}", args.rate_hz);
    }
    let mut scenario = Scenario::from_file(path)?;
    if let Some(seed) = args.seed {
        scenario.seed = seed;
    }
    let model = CellModel::new(&scenario, path)?;
    let out = super::OutputDir::create(&args.out, args.force, &OUTPUTS)?;

    let dt = model.time_step_s();
    let steps = (args.seconds / dt).round() as u64;
    let every = ((1.0 / args.rate_hz) / dt).round().max(1.0) as u64;
    let mut state = CellState::new(&model)?;
    let mut log = Log::new(&model, path);
    log.record(&model, &state);

    let bar = super::progress_bar(
        steps,
        "{spinner} simulating [{bar:40}] {pos}/{len} steps ({per_sec}, eta {eta})",
    );
    let started = Instant::now();
    for k in 1..=steps {
        step(&model, &mut state, &RobotCommand::Nominal)?;
        if k % every == 0 {
            log.record(&model, &state);
        }
        if k % 100 == 0 {
            bar.set_position(k);
        }
    }
    let wall_s = started.elapsed().as_secs_f64();
    bar.finish_and_clear();

    let outputs = log.write(&model, out.path())?;
    let summary = Summary {
        scenario: path.display().to_string(),
        seed: scenario.seed,
        robot: model.robot.name().to_string(),
        human: model.human.name().to_string(),
        time_step_s: dt,
        simulated_s: state.time_s(),
        steps,
        wall_s,
        steps_per_s: steps as f64 / wall_s.max(1e-9),
        outputs: outputs.clone(),
    };
    let summary_path = out.path().join("summary.json");
    fs::write(
        &summary_path,
        serde_json::to_string_pretty(&summary)? + "\n",
    )
    .with_context(|| format!("writing {}", summary_path.display()))?;
    out.commit()?;
    say!(
        "simulated {:.2} s ({steps} steps of {} ms) in {wall_s:.2} s: {:.0} steps/s",
        state.time_s(),
        dt * 1e3,
        summary.steps_per_s
    );
    for file in outputs
        .iter()
        .chain(std::iter::once(&"summary.json".to_string()))
    {
        say!("  {}", args.out.join(file).display());
    }
    Ok(ExitCode::SUCCESS)
}

/// Creates `out`; refuses to overwrite earlier outputs unless `force`.
/// Samples kept in memory, written at the end.
struct Log {
    /// The scenario file, for titles.
    scenario: String,
    t: Vec<f64>,
    q: Vec<Vec<f64>>,
    qd: Vec<Vec<f64>>,
    human_q: Vec<Vec<f64>>,
    human_rows: String,
    /// Tool and hand positions in the world at every sample.
    tool_W: Vec<[f64; 3]>,
    hand_W: Vec<[f64; 3]>,
    /// Robot and human as line segments between joint origins, at the first sample.
    robot_start: Vec<[f64; 3]>,
    human_start: Vec<[f64; 3]>,
}

/// The robot as segments from each link's origin to its children's, for drawing.
fn stick_figure(model: &RobotModel, X_WL: &[Pose]) -> Vec<[f64; 3]> {
    model
        .joints()
        .iter()
        .flat_map(|j| {
            [
                X_WL[j.parent].translation.to_array(),
                X_WL[j.child].translation.to_array(),
            ]
        })
        .collect()
}

/// The human link drawn as "the hand": the child of the last joint (a leaf).
fn hand_link(model: &RobotModel) -> usize {
    model.joints().last().map_or(model.root(), |j| j.child)
}

impl Log {
    fn new(model: &CellModel, scenario: &Path) -> Self {
        let mut human_rows = String::from("t_s,part,x_m,y_m,z_m,qx,qy,qz,qw\n");
        human_rows.reserve(1 << 16);
        Self {
            scenario: scenario.display().to_string(),
            t: Vec::new(),
            q: vec![Vec::new(); model.robot.dof()],
            qd: vec![Vec::new(); model.robot.dof()],
            human_q: vec![Vec::new(); model.human.dof()],
            human_rows,
            tool_W: Vec::new(),
            hand_W: Vec::new(),
            robot_start: Vec::new(),
            human_start: Vec::new(),
        }
    }

    fn record(&mut self, model: &CellModel, state: &CellState) {
        let t = state.time_s();
        self.t.push(t);
        for (i, (q, qd)) in state.q().iter().zip(state.qd()).enumerate() {
            self.q[i].push(*q);
            self.qd[i].push(*qd);
        }
        for (i, q) in state.human_q().iter().enumerate() {
            self.human_q[i].push(*q);
        }
        self.tool_W.push(
            state
                .robot_link_pose(model.tool_link)
                .translation
                .to_array(),
        );
        let human_poses = state.human_link_poses();
        self.hand_W
            .push(human_poses[hand_link(&model.human)].translation.to_array());
        if self.robot_start.is_empty() {
            self.robot_start = stick_figure(&model.robot, &state.robot_link_poses());
            self.human_start = stick_figure(&model.human, human_poses);
        }
        for (link, pose) in model.human.links().iter().zip(state.human_link_poses()) {
            let p = pose.translation;
            let r = pose.rotation;
            let _ = writeln!(
                self.human_rows,
                "{t:.6},{},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6},{:.6}",
                link.name, p.x, p.y, p.z, r.x, r.y, r.z, r.w
            );
        }
    }

    fn write(&self, model: &CellModel, out: &Path) -> Result<Vec<String>> {
        let names: Vec<&str> = model
            .robot
            .actuated_joints()
            .iter()
            .map(|&j| model.robot.joints()[j].name.as_str())
            .collect();
        let mut csv = String::from("t_s");
        for n in &names {
            let _ = write!(csv, ",q_{n}");
        }
        for n in &names {
            let _ = write!(csv, ",qd_{n}");
        }
        csv.push('\n');
        for (k, t) in self.t.iter().enumerate() {
            let _ = write!(csv, "{t:.6}");
            for q in self.q.iter().chain(&self.qd) {
                let _ = write!(csv, ",{:.6}", q[k]);
            }
            csv.push('\n');
        }
        let write = |name: &str, text: &str| -> Result<String> {
            let path = out.join(name);
            fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
            Ok(name.to_string())
        };
        let human_names: Vec<String> = model
            .human
            .actuated_joints()
            .iter()
            .map(|&j| model.human.joints()[j].name.clone())
            .collect();
        let panels = [
            Panel {
                title: format!("robot '{}': joint positions", model.robot.name()),
                y_label: "q [rad]".into(),
                series: names
                    .iter()
                    .map(|n| n.to_string())
                    .zip(self.q.iter().cloned())
                    .collect(),
            },
            Panel {
                title: "robot: joint velocities".into(),
                y_label: "qd [rad/s]".into(),
                series: names
                    .iter()
                    .map(|n| n.to_string())
                    .zip(self.qd.iter().cloned())
                    .collect(),
            },
            Panel {
                title: format!("human '{}': joint positions", model.human.name()),
                y_label: "q [rad]".into(),
                series: human_names
                    .into_iter()
                    .zip(self.human_q.iter().cloned())
                    .collect(),
            },
        ];
        let solids: Vec<Vec<[f64; 3]>> = model
            .clutter
            .iter()
            .map(|c| {
                let [hx, hy, hz] = c.half_extents_m;
                (0..8)
                    .map(|i| {
                        let s = |bit: usize, h: f64| if i & bit == 0 { -h } else { h };
                        let corner =
                            workcell::robots::math::Vector::new(s(1, hx), s(2, hy), s(4, hz));
                        c.X_WC.transform_point(corner).to_array()
                    })
                    .collect()
            })
            .collect();
        let path = |name: &str, color, width, segments, points_W: &[[f64; 3]]| WorldPath {
            name: name.to_string(),
            color,
            width,
            segments,
            points_W: points_W.to_vec(),
        };
        let views = svg_cell_views(
            &format!(
                "{}: {} and {} over {:.1} s",
                self.scenario,
                model.robot.name(),
                model.human.name(),
                self.t.last().copied().unwrap_or(0.0)
            ),
            &solids,
            &[
                path("robot at t = 0", "#333333", 4.0, true, &self.robot_start),
                path("human at t = 0", "#a0522d", 4.0, true, &self.human_start),
                path("tool path", "#1f77b4", 1.0, false, &self.tool_W),
                path("hand path", "#d62728", 1.0, false, &self.hand_W),
            ],
        );
        Ok(vec![
            write("robot_joints.csv", &csv)?,
            write("human_poses.csv", &self.human_rows)?,
            write("trajectories.svg", &svg_panels(&self.t, "t [s]", &panels))?,
            write("cell.svg", &views)?,
        ])
    }
}
