//! `workcell robot check` and `workcell robot list`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use serde::Serialize;
use workcell::robots::assets::add_robot;
use workcell::robots::collision::{link_bounding_capsule, link_collision_shape};
use workcell::robots::math::{Pose, pose_to_xyz_rpy};
use workcell::robots::{
    CATALOGUE, Coordinate, JointKind, PackageMap, ROBOT_PATH_VAR, RobotModel, Shape, added_robots,
    robot_library,
};

#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// Catalogue name (see `workcell robot list`) or path to a URDF file.
    pub robot: String,
    /// Map a ROS package to its folder, NAME=FOLDER (repeatable). WORKCELL_PACKAGE_PATH and
    /// ROS_PACKAGE_PATH are searched too, then the URDF's own ancestors.
    #[arg(long = "package", value_parser = crate::parse_package)]
    pub packages: Vec<(String, PathBuf)>,
    /// Joint positions q1,q2,... (rad or m): print every link's pose there.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub fk: Option<Vec<f64>>,
    /// Print JSON instead of tables.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
struct JointReport {
    name: String,
    kind: &'static str,
    parent: String,
    child: String,
    axis: [f64; 3],
    coordinate: String,
    lower: f64,
    upper: f64,
    velocity: f64,
    effort: f64,
    soft_limits: Option<[f64; 2]>,
}

#[derive(Debug, Serialize)]
struct LinkPose {
    link: String,
    xyz: [f64; 3],
    rpy: [f64; 3],
    quaternion_xyzw: [f64; 4],
}

#[derive(Debug, Serialize)]
struct Report {
    name: String,
    source: String,
    dof: usize,
    links: usize,
    mass_kg: f64,
    joints: Vec<JointReport>,
    meshes: BTreeMap<String, usize>,
    rapier: workcell::sim::RapierCheck,
    problems: Vec<String>,
    fk: Option<Vec<LinkPose>>,
}

pub fn list() -> Result<ExitCode> {
    for entry in CATALOGUE {
        say!("{:<20} {}", entry.name, entry.summary);
    }
    for (name, urdf) in added_robots() {
        say!("{name:<20} added: {}", urdf.display());
    }
    Ok(ExitCode::SUCCESS)
}

#[derive(Debug, clap::Args)]
pub struct AddArgs {
    /// The vendor's URDF file.
    pub urdf: PathBuf,
    /// The robot's name in workcell (letters, digits, '_' and '-'): scenarios use it as
    /// `[robot] model = "NAME"`.
    #[arg(long)]
    pub name: String,
    /// Robot library folder to add it to [default: the first folder of WORKCELL_ROBOT_PATH,
    /// else this source tree's robots/urdf].
    #[arg(long)]
    pub into: Option<PathBuf>,
    /// Map a ROS package to its folder, NAME=FOLDER (repeatable).
    #[arg(long = "package", value_parser = crate::parse_package)]
    pub packages: Vec<(String, PathBuf)>,
    /// Replace a robot of the same name.
    #[arg(long)]
    pub force: bool,
}

/// `workcell robot add`: copy, preview, check, cross-check.
pub fn add(args: &AddArgs) -> Result<ExitCode> {
    use rand::{Rng, SeedableRng};

    // The name becomes folder names: checked before any file is touched.
    workcell::robots::assets::check_robot_name(&args.name)?;
    if CATALOGUE.iter().any(|e| e.name == args.name) {
        bail!(
            "'{}' is a built-in robot's name; choose another --name",
            args.name
        );
    }
    let library = match &args.into {
        Some(dir) => dir.clone(),
        None => robot_library()
            .into_iter()
            .next()
            .context("no robot library folder: pass --into DIR or set WORKCELL_ROBOT_PATH")?,
    };
    let mut packages = PackageMap::from_env();
    for (name, dir) in &args.packages {
        packages.insert(name.clone(), dir.clone());
    }
    // The vendor file must load before anything is copied.
    RobotModel::from_urdf_file(&args.urdf, &packages)?;
    let target = library.join(&args.name);
    if target.exists() && !args.force {
        bail!(
            "{} already exists (pass --force to replace it)",
            target.display()
        );
    }
    std::fs::create_dir_all(&library).with_context(|| format!("creating {}", library.display()))?;
    // All or nothing: the robot is copied, previewed, checked and cross-checked in a staging
    // folder that no scenario can name, and moved into the library only when all of that
    // passed. An error or Ctrl-C leaves the library as it was.
    // A staging folder left by a killed run is replaced.
    let staging = Staging(library.join(format!(".{}.staging", args.name)));
    if staging.0.exists() {
        std::fs::remove_dir_all(&staging.0)
            .with_context(|| format!("removing {}", staging.0.display()))?;
    }
    std::fs::create_dir_all(&staging.0)
        .with_context(|| format!("creating {}", staging.0.display()))?;
    let added = add_robot(&args.urdf, &packages, &args.name, &staging.0, true)?;
    say!(
        "copied '{}' with {} mesh files; checking it before it joins the library",
        args.name,
        added.meshes.len()
    );
    // The copy must load on its own (relative mesh paths, no package map).
    let robot = RobotModel::from_urdf_file(&added.urdf, &PackageMap::new())
        .context("the copied robot does not load")?;

    // Preview: the zero configuration (clamped into the limits) and three random ones.
    let limits = robot.position_limits();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut configurations = vec![
        limits
            .iter()
            .map(|[lo, hi]| 0.0_f64.clamp(*lo, *hi))
            .collect::<Vec<_>>(),
    ];
    for _ in 0..3 {
        configurations.push(
            limits
                .iter()
                .map(|&[lo, hi]| {
                    let (lo, hi) = if lo.is_finite() && hi.is_finite() {
                        (lo, hi)
                    } else {
                        (-std::f64::consts::PI, std::f64::consts::PI)
                    };
                    rng.random_range(lo..=hi)
                })
                .collect(),
        );
    }
    let (width, height, rgb) = workcell::render::robot_preview(&robot, &configurations, 320)?;
    let preview = added.urdf.with_file_name("preview.png");
    workcell::render::image::write_png(
        &preview,
        width,
        height,
        workcell::render::image::PixelKind::Rgb,
        &rgb,
    )?;
    say!();

    let urdf = added.urdf.to_string_lossy().into_owned();
    check(&CheckArgs {
        robot: urdf.clone(),
        packages: Vec::new(),
        fk: None,
        json: false,
    })?;
    say!();
    let verdict = if cfg!(feature = "mujoco") {
        crate::cli::crosscheck::run(&crate::cli::crosscheck::CrosscheckArgs {
            robot: urdf,
            packages: Vec::new(),
            samples: 100,
            seconds: 3.0,
            seed: 1,
            keep: None,
            json: false,
        })?
    } else {
        say!("cross-check skipped: this build has no MuJoCo (feature `mujoco`)");
        ExitCode::SUCCESS
    };
    if verdict != ExitCode::SUCCESS {
        bail!(
            "the MuJoCo cross-check of '{}' failed (table above): it was not added",
            args.name
        );
    }
    if target.exists() {
        std::fs::remove_dir_all(&target)
            .with_context(|| format!("removing the old {}", target.display()))?;
    }
    let staged = staging.0.join(&args.name);
    std::fs::rename(&staged, &target)
        .with_context(|| format!("moving {} to {}", staged.display(), target.display()))?;
    say!(
        "added '{}': {}\npreview (zero and three random configurations): {}",
        args.name,
        target.join(format!("{}.urdf", args.name)).display(),
        target.join("preview.png").display()
    );
    let findable = robot_library()
        .iter()
        .any(|dir| dir.canonicalize().ok() == library.canonicalize().ok());
    if findable {
        say!(
            "\nuse it in a scenario as [robot] model = \"{}\"",
            args.name
        );
    } else {
        say!(
            "\n{} is not a robot library folder: add it to {ROBOT_PATH_VAR} to name the robot \"{}\" in scenarios",
            library.display(),
            args.name
        );
    }
    Ok(verdict)
}

/// A staging folder, removed with everything in it when dropped.
struct Staging(PathBuf);

impl Drop for Staging {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn check(args: &CheckArgs) -> Result<ExitCode> {
    let mut packages = PackageMap::from_env();
    for (name, dir) in &args.packages {
        packages.insert(name.clone(), dir.clone());
    }
    // Load errors name the file and the element already.
    let robot = RobotModel::load(&args.robot, &packages)?;
    // A configuration off the neutral one, so that gravity loads the joints while rapier
    // holds it: half a radian (or a quarter of the range) from the middle of each range.
    let q_check: Vec<f64> = robot
        .neutral_configuration()
        .iter()
        .zip(robot.position_limits())
        .map(|(mid, [_, hi])| {
            let room = if hi.is_finite() {
                0.25 * (hi - mid)
            } else {
                0.5
            };
            mid + room.min(0.5)
        })
        .collect();
    let rapier = workcell::sim::check_in_rapier(&robot, &q_check).context("loading into rapier")?;
    let fk = match &args.fk {
        None => None,
        Some(q) => {
            if q.len() != robot.dof() {
                bail!(
                    "--fk has {} values; '{}' has {} joints ({})",
                    q.len(),
                    robot.name(),
                    robot.dof(),
                    coordinate_names(&robot).join(", ")
                );
            }
            let state = robot.fk(Pose::IDENTITY, q)?;
            Some(
                robot
                    .links()
                    .iter()
                    .enumerate()
                    .map(|(l, link)| {
                        let pose = state.link_pose(l);
                        let (xyz, rpy) = pose_to_xyz_rpy(pose);
                        LinkPose {
                            link: link.name.clone(),
                            xyz,
                            rpy,
                            quaternion_xyzw: pose.rotation.to_array(),
                        }
                    })
                    .collect(),
            )
        }
    };
    let report = Report {
        name: robot.name().to_string(),
        source: robot.source().display().to_string(),
        dof: robot.dof(),
        links: robot.links().len(),
        mass_kg: robot.mass_kg(),
        joints: joints(&robot),
        meshes: meshes(&robot),
        problems: problems(&robot, &rapier),
        rapier,
        fk,
    };
    if args.json {
        say!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print_report(&report);
    }
    Ok(ExitCode::SUCCESS)
}

fn coordinate_names(robot: &RobotModel) -> Vec<String> {
    robot
        .actuated_joints()
        .iter()
        .map(|&j| robot.joints()[j].name.clone())
        .collect()
}

fn joints(robot: &RobotModel) -> Vec<JointReport> {
    robot
        .joints()
        .iter()
        .map(|j| JointReport {
            name: j.name.clone(),
            kind: j.kind.as_str(),
            parent: robot.links()[j.parent].name.clone(),
            child: robot.links()[j.child].name.clone(),
            axis: j.axis.to_array(),
            coordinate: match j.coordinate {
                Coordinate::None => "-".into(),
                Coordinate::Own { index } => format!("q{}", index + 1),
                Coordinate::Mimic {
                    index,
                    multiplier,
                    offset,
                } => format!("{multiplier}*q{}{offset:+}", index + 1),
            },
            lower: j.limits.lower,
            upper: j.limits.upper,
            velocity: j.limits.velocity,
            effort: j.limits.effort,
            soft_limits: j
                .safety_controller
                .map(|s| [s.soft_lower_limit, s.soft_upper_limit]),
        })
        .collect()
}

fn meshes(robot: &RobotModel) -> BTreeMap<String, usize> {
    let mut counts = BTreeMap::new();
    for link in robot.links() {
        for (role, list) in [("visual", &link.visuals), ("collision", &link.collisions)] {
            for g in list {
                let kind = match &g.shape {
                    Shape::Mesh { path, .. } => format!(
                        "{role} mesh .{}",
                        path.extension()
                            .map(|e| e.to_string_lossy().to_lowercase())
                            .unwrap_or_default()
                    ),
                    Shape::Box { .. } => format!("{role} box"),
                    Shape::Cylinder { .. } => format!("{role} cylinder"),
                    Shape::Capsule { .. } => format!("{role} capsule"),
                    Shape::Sphere { .. } => format!("{role} sphere"),
                };
                *counts.entry(kind).or_insert(0) += 1;
            }
        }
    }
    counts
}

/// Things that load but deserve a look before the robot is trusted in a safety evaluation.
fn problems(robot: &RobotModel, rapier: &workcell::sim::RapierCheck) -> Vec<String> {
    let mut found: Vec<String> = robot.warnings().to_vec();
    for j in robot.joints() {
        if !j.kind.is_movable() || j.mimic.is_some() {
            continue;
        }
        if j.limits.velocity <= 0.0 {
            found.push(format!(
                "joint '{}' has no velocity limit: trajectories and the safety filter need one",
                j.name
            ));
        }
        if j.limits.effort <= 0.0 {
            found.push(format!(
                "joint '{}' has no effort limit: its motor is unbounded in simulation",
                j.name
            ));
        }
        if j.kind == JointKind::Revolute
            && !(j.limits.lower.is_finite() && j.limits.upper.is_finite())
        {
            found.push(format!(
                "revolute joint '{}' has no finite position limits",
                j.name
            ));
        }
    }
    for (l, link) in robot.links().iter().enumerate() {
        let moves = link
            .parent_joint
            .is_some_and(|j| robot.joints()[j].kind.is_movable());
        if moves && link.inertial.is_none() {
            found.push(format!(
                "moving link '{}' has no inertial: simulated with 0.01 kg",
                link.name
            ));
        }
        if !link.collisions.is_empty() && link_collision_shape(robot, l).is_none() {
            found.push(format!(
                "link '{}': collision geometry is degenerate (no convex shape)",
                link.name
            ));
        }
        if link.collisions.is_empty() && !link.visuals.is_empty() {
            found.push(format!(
                "link '{}' has visuals but no collision geometry: invisible to distance checks",
                link.name
            ));
        }
        if let Some(c) = link_bounding_capsule(robot, l)
            && c.radius_m > 0.25
        {
            found.push(format!(
                "link '{}': bounding capsule radius {:.3} m is coarse",
                link.name, c.radius_m
            ));
        }
    }
    if rapier.fk_mismatch_m > 1e-6 {
        found.push(format!(
            "rapier and forward kinematics disagree by {:.2e} m",
            rapier.fk_mismatch_m
        ));
    }
    if rapier.hold_error > 0.05 {
        found.push(format!(
            "holding the neutral configuration under gravity leaves a {:.3} error: check masses, efforts and limits",
            rapier.hold_error
        ));
    }
    found
}

fn limit(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "inf".into()
    }
}

fn print_report(r: &Report) {
    say!("robot    {}", r.name);
    say!("source   {}", r.source);
    say!(
        "dof      {}    links {}    mass {:.3} kg",
        r.dof,
        r.links,
        r.mass_kg
    );
    say!();
    say!(
        "joint                    type       coord       lower     upper      vel   effort  parent -> child"
    );
    for j in &r.joints {
        say!(
            "{:<24} {:<10} {:<7} {:>9} {:>9} {:>8} {:>8}  {} -> {}",
            j.name,
            j.kind,
            j.coordinate,
            limit(j.lower),
            limit(j.upper),
            limit(j.velocity),
            limit(j.effort),
            j.parent,
            j.child
        );
    }
    say!();
    say!("geometry");
    for (kind, count) in &r.meshes {
        say!("  {count:>4}  {kind}");
    }
    say!();
    say!(
        "rapier   {} bodies, {} colliders, {} multibody dofs; FK mismatch {:.1e} m; error holding a pose for 1 s {:.1e}",
        r.rapier.rigid_bodies,
        r.rapier.colliders,
        r.rapier.multibody_dofs,
        r.rapier.fk_mismatch_m,
        r.rapier.hold_error
    );
    say!();
    if r.problems.is_empty() {
        say!("problems none found");
    } else {
        say!("problems {}", r.problems.len());
        for p in &r.problems {
            say!("  - {p}");
        }
    }
    if let Some(fk) = &r.fk {
        say!();
        say!(
            "link                          x [m]      y [m]      z [m]      roll     pitch       yaw"
        );
        for p in fk {
            say!(
                "{:<24} {:>10.6} {:>10.6} {:>10.6} {:>9.5} {:>9.5} {:>9.5}",
                p.link,
                p.xyz[0],
                p.xyz[1],
                p.xyz[2],
                p.rpy[0],
                p.rpy[1],
                p.rpy[2]
            );
        }
    }
}
