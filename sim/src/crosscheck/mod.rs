//! MuJoCo as a cross-check of the rapier model (feature `mujoco`).
//!
//! The vendor's own URDF is handed to MuJoCo 3.17.0 (its mesh paths made absolute, every mesh
//! converted by our loader to binary STL, since MuJoCo resolves no `package://` URI and reads
//! no COLLADA), so MuJoCo's reading of the file is independent of ours. Then, at random
//! configurations within the joint limits:
//!
//! - forward kinematics: the pose of every link (MuJoCo body) against the rapier body;
//! - the joint-space mass matrix (rapier's articulated assembly against `mj_fullM`);
//! - the gravity torques (from rapier's free acceleration at rest against `qfrc_bias`);
//!
//! and joint trajectories under the same PD torque law (without gravity, so that no joint sags
//! into a limit), applied as explicit joint torques in both simulators, with MuJoCo's four
//! integrators (the divergence against time is reported).
//! Contacts are off in both: rapier's multibody has self-contacts disabled, and MuJoCo's
//! contact flag is cleared, since the comparison is of the articulated dynamics.

mod mujoco;
mod rapier;

use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use workcell_robots::assets::UrdfAssets;
use workcell_robots::{Coordinate, RobotModel};

pub use mujoco::{MUJOCO_VERSION, linked_mujoco_version};

use crate::error::SimError;

/// Everything that can stop a cross-check.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CrosscheckError {
    /// The MuJoCo library found at run time is not the version the bindings were made for.
    #[error(
        "the MuJoCo library linked at run time is version {found}, the bindings need {expected} \
         (run scripts/fetch-mujoco.sh and rebuild)"
    )]
    MujocoVersion { found: String, expected: String },
    /// A mesh could not be converted for MuJoCo.
    #[error("{path}: cannot convert for MuJoCo: {message}")]
    Mesh { path: PathBuf, message: String },
    /// MuJoCo refused the URDF (its own message, and the file it was given).
    #[error("MuJoCo rejected {urdf} (prepared as {prepared}): {message}")]
    MujocoRejected {
        urdf: PathBuf,
        prepared: PathBuf,
        message: String,
    },
    /// MuJoCo's model does not have a link or joint of the URDF.
    #[error("MuJoCo's model of {urdf} has no {what} named '{name}'")]
    Missing {
        urdf: PathBuf,
        what: &'static str,
        name: String,
    },
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Robot(#[from] workcell_robots::RobotError),
    #[error("{path}: cannot read or write")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Settings of a cross-check.
#[derive(Debug, Clone, Serialize)]
pub struct CrosscheckConfig {
    /// Random configurations for kinematics, mass matrix and gravity.
    pub samples: usize,
    pub seed: u64,
    /// Time step of both simulators, s.
    pub time_step_s: f64,
    /// Length of the trajectory comparison, s.
    pub duration_s: f64,
    pub tolerances: Tolerances,
}

impl Default for CrosscheckConfig {
    fn default() -> Self {
        Self {
            samples: 100,
            seed: 1,
            time_step_s: 0.001,
            duration_s: 3.0,
            tolerances: Tolerances::default(),
        }
    }
}

/// What counts as agreement. Kinematics, mass matrix and gravity torques are computed in
/// closed form by both engines from the same numbers in `f64`, so they must agree to rounding
/// (measured: 1e-14 to 2e-14 on every robot tested; 1e-12 leaves room for longer chains).
/// Trajectories come from two different first-order integrators (rapier: semi-implicit Euler
/// over 4 substeps, with implicit damping and Coriolis terms; MuJoCo Euler: one semi-implicit
/// step, implicit damping), whose difference is of the order of their truncation error, about
/// `omega * dt` = 0.02 of the motion for the 20 rad/s PD law at 1 ms: half of that is allowed.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Tolerances {
    /// Link origin positions, m.
    pub fk_position_m: f64,
    /// Link orientations (angle of the relative rotation), rad.
    pub fk_rotation_rad: f64,
    /// Mass matrix: largest entry difference over the largest entry.
    pub mass_matrix_relative: f64,
    /// Gravity torques: largest difference over the largest torque (plus 1e-9 N m).
    pub gravity_relative: f64,
    /// Joint trajectories against MuJoCo's semi-implicit Euler: largest joint difference over
    /// the run, rad (or m), per radian of the motion's largest excursion.
    pub trajectory_relative: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Self {
            fk_position_m: 1e-12,
            fk_rotation_rad: 1e-12,
            mass_matrix_relative: 1e-12,
            gravity_relative: 1e-12,
            trajectory_relative: 0.01,
        }
    }
}

/// The largest difference of one quantity and where it occurred.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Worst {
    pub value: f64,
    /// Which link or joint, at which sample.
    pub at: String,
}

impl Worst {
    fn update(&mut self, value: f64, at: impl FnOnce() -> String) {
        // NaN counts as the worst.
        if value.is_nan() || value > self.value || (self.at.is_empty() && value >= 0.0) {
            self.value = value;
            self.at = at();
        }
    }
}

/// One trajectory comparison: rapier against MuJoCo with one integrator.
#[derive(Debug, Clone, Serialize)]
pub struct TrajectoryComparison {
    /// MuJoCo's integrator (`Euler`, `implicitfast`, `implicit`, `RK4`).
    pub integrator: String,
    /// MuJoCo with the URDF's dry joint friction (`frictionloss`), which the rapier model
    /// leaves out; the other runs have none in either engine.
    pub friction: bool,
    /// `(t, largest joint difference at t)` at a few times, s and rad (or m).
    pub divergence: Vec<(f64, f64)>,
    /// Largest joint difference over the run.
    pub max_divergence: Worst,
}

/// One verdict line.
#[derive(Debug, Clone, Serialize)]
pub struct Check {
    pub name: &'static str,
    pub value: f64,
    pub tolerance: f64,
    pub pass: bool,
}

/// What [`crosscheck`] found.
#[derive(Debug, Clone, Serialize)]
pub struct CrosscheckReport {
    pub robot: String,
    pub urdf: PathBuf,
    pub mujoco_version: String,
    pub links: usize,
    pub dofs: usize,
    pub config: CrosscheckConfig,
    pub fk_position_m: Worst,
    pub fk_rotation_rad: Worst,
    /// Largest entry of the mass matrices seen, kg m^2.
    pub mass_matrix_scale: f64,
    pub mass_matrix_relative: Worst,
    /// Largest gravity torque seen, N m.
    pub gravity_scale: f64,
    pub gravity_relative: Worst,
    /// Largest excursion of any joint from its start in the trajectory run, rad (or m).
    pub trajectory_excursion: f64,
    pub trajectories: Vec<TrajectoryComparison>,
    pub checks: Vec<Check>,
}

impl CrosscheckReport {
    /// `true` when every check is within its tolerance.
    #[must_use]
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|c| c.pass)
    }
}

/// Cross-checks `robot` (loaded from `assets`, the same file) against MuJoCo. `workdir`
/// receives the URDF prepared for MuJoCo and its converted meshes.
///
/// # Errors
/// [`CrosscheckError`]: a wrong MuJoCo library, a mesh that cannot be converted, a URDF
/// MuJoCo rejects (with MuJoCo's message), a link or joint MuJoCo's model lacks.
pub fn crosscheck(
    robot: &RobotModel,
    assets: &UrdfAssets,
    workdir: &Path,
    config: &CrosscheckConfig,
) -> Result<CrosscheckReport, CrosscheckError> {
    let mj = mujoco::MujocoRobot::load(robot, assets, workdir)?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let g = [0.0, 0.0, -9.81];

    let mut fk_position_m = Worst::default();
    let mut fk_rotation_rad = Worst::default();
    let mut mass_matrix_relative = Worst::default();
    let mut gravity_relative = Worst::default();
    let (mut mass_matrix_scale, mut gravity_scale) = (0.0_f64, 0.0_f64);
    let mut mj_data = mj.data(config.time_step_s, mujoco::Integrator::Euler, true);
    for sample in 0..config.samples {
        let q = random_configuration(robot, &mut rng);
        let mut rp = rapier::RapierRobot::new(robot, &q, g, config.time_step_s)?;
        let statics = mj.statics(&mut mj_data, &q);

        for (l, link) in robot.links().iter().enumerate() {
            let X_r = rp.link_pose(l);
            let X_m = statics.link_poses[l];
            fk_position_m.update((X_r.translation - X_m.translation).length(), || {
                format!("link '{}', sample {sample}", link.name)
            });
            let angle = (X_r.rotation.inverse() * X_m.rotation).to_axis_angle().1;
            let angle = angle.min(std::f64::consts::TAU - angle);
            fk_rotation_rad.update(angle, || format!("link '{}', sample {sample}", link.name));
        }

        let (m_r, tau_r) = rp.mass_matrix_and_gravity();
        let scale = m_r.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
        mass_matrix_scale = mass_matrix_scale.max(scale);
        let n = rp.joints.len();
        for i in 0..n {
            for j in 0..n {
                let d = (m_r[i * n + j] - statics.mass_matrix[i * n + j]).abs() / scale;
                mass_matrix_relative.update(d, || {
                    format!(
                        "M[{}, {}], sample {sample}",
                        robot.joints()[rp.joints[i]].name,
                        robot.joints()[rp.joints[j]].name
                    )
                });
            }
        }
        let scale = tau_r.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
        gravity_scale = gravity_scale.max(scale);
        for (i, (a, b)) in tau_r.iter().zip(&statics.gravity).enumerate() {
            let d = (a - b).abs() / (scale + 1e-9);
            gravity_relative.update(d, || {
                format!(
                    "joint '{}', sample {sample}",
                    robot.joints()[rp.joints[i]].name
                )
            });
        }
    }

    let q_start = random_configuration(robot, &mut rng);
    let (trajectories, trajectory_excursion) = compare_trajectories(robot, &mj, config, &q_start)?;

    let t = config.tolerances;
    let euler = trajectories
        .iter()
        .find(|c| c.integrator == mujoco::Integrator::Euler.name() && !c.friction)
        .map_or(f64::NAN, |c| c.max_divergence.value);
    let check = |name, value: f64, tolerance| Check {
        name,
        value,
        tolerance,
        pass: value <= tolerance,
    };
    let checks = vec![
        check("fk position (m)", fk_position_m.value, t.fk_position_m),
        check(
            "fk rotation (rad)",
            fk_rotation_rad.value,
            t.fk_rotation_rad,
        ),
        check(
            "mass matrix (relative)",
            mass_matrix_relative.value,
            t.mass_matrix_relative,
        ),
        check(
            "gravity torques (relative)",
            gravity_relative.value,
            t.gravity_relative,
        ),
        check(
            "trajectory vs Euler (per rad of motion)",
            euler / trajectory_excursion.max(1e-9),
            t.trajectory_relative,
        ),
    ];
    Ok(CrosscheckReport {
        robot: robot.name().to_string(),
        urdf: assets.path.clone(),
        mujoco_version: linked_mujoco_version(),
        links: robot.links().len(),
        dofs: robot
            .joints()
            .iter()
            .filter(|j| j.kind.is_movable())
            .count(),
        config: config.clone(),
        fk_position_m,
        fk_rotation_rad,
        mass_matrix_scale,
        mass_matrix_relative,
        gravity_scale,
        gravity_relative,
        trajectory_excursion,
        trajectories,
        checks,
    })
}

/// A configuration drawn uniformly within the middle 80 % of each joint's range (continuous
/// joints in [-pi, pi]), away from the limits, where both engines' limit handling is idle.
fn random_configuration(robot: &RobotModel, rng: &mut ChaCha8Rng) -> Vec<f64> {
    robot
        .position_limits()
        .iter()
        .map(|&[lo, hi]| {
            let (lo, hi) = finite_range(lo, hi);
            let margin = 0.1 * (hi - lo);
            rng.random_range(lo + margin..=hi - margin)
        })
        .collect()
}

fn finite_range(lo: f64, hi: f64) -> (f64, f64) {
    if lo.is_finite() && hi.is_finite() && hi > lo {
        (lo, hi)
    } else {
        (-std::f64::consts::PI, std::f64::consts::PI)
    }
}

/// Times at which the divergence is reported, s.
const REPORT_TIMES: [f64; 5] = [0.1, 0.5, 1.0, 2.0, 3.0];

/// The PD torque law shared by both simulators: the configuration reference
/// `q0 + a (1 - cos(2 pi f t)) / 2` is mapped to every movable joint (mimic joints follow
/// their leader), which tracks it with gains set from the effective joint inertia at the start
/// for a 20 rad/s critically damped response. Torques are not clipped to
/// the URDF effort: a saturating law makes both runs hypersensitive to the smallest difference.
struct PdLaw {
    /// Configuration coordinates: start and amplitude of the reference.
    q0: Vec<f64>,
    amplitude: Vec<f64>,
    /// Per movable joint: `(coordinate, multiplier, offset)`.
    map: Vec<(usize, f64, f64)>,
    kp: Vec<f64>,
    kd: Vec<f64>,
}

const PD_OMEGA: f64 = 20.0;
const REFERENCE_HZ: f64 = 0.5;

impl PdLaw {
    fn torque(&self, t: f64, q: &[f64], v: &[f64], out: &mut [f64]) {
        let s = 0.5 * (1.0 - (std::f64::consts::TAU * REFERENCE_HZ * t).cos());
        for i in 0..out.len() {
            let (c, multiplier, offset) = self.map[i];
            let reference = multiplier * (self.q0[c] + self.amplitude[c] * s) + offset;
            let tau = self.kp[i] * (reference - q[i]) - self.kd[i] * v[i];
            out[i] = tau;
        }
    }
}

/// The [`PdLaw`] of a trajectory starting at rest at `q_start`: every joint moves towards its
/// farther limit by up to a quarter of its range (at most 0.5 rad) and back.
fn pd_law(robot: &RobotModel, q_start: &[f64], dt: f64) -> Result<PdLaw, CrosscheckError> {
    let (m, _) = rapier::RapierRobot::new(robot, q_start, [0.0; 3], dt)?.mass_matrix_and_gravity();
    let joints: Vec<_> = robot
        .joints()
        .iter()
        .filter(|j| j.kind.is_movable())
        .collect();
    let n = joints.len();
    // The inertia each joint sees with the others free, 1 / (M^-1)_ii: gains on the diagonal
    // of M itself can be far too stiff for a joint that the chain couples strongly.
    let inverse = rapier3d_f64::na::DMatrix::from_row_slice(n, n, &m)
        .try_inverse()
        .ok_or_else(|| SimError::Physics {
            message: "the mass matrix is singular".into(),
        })?;
    let inertia: Vec<f64> = (0..n).map(|i| 1.0 / inverse[(i, i)]).collect();
    // Towards the farther limit, by a quarter of the range, at most 0.5 rad and at most 80 %
    // of the room: the limits stay idle (both engines enforce them, differently).
    let amplitude: Vec<f64> = robot
        .position_limits()
        .iter()
        .zip(q_start)
        .map(|(&[lo, hi], &q)| {
            let (lo, hi) = finite_range(lo, hi);
            let (up, down) = (hi - q, q - lo);
            let a = (0.25 * (hi - lo)).min(0.5).min(0.8 * up.max(down));
            if up >= down { a } else { -a }
        })
        .collect();
    let map = joints
        .iter()
        .map(|j| match j.coordinate {
            Coordinate::Own { index } => (index, 1.0, 0.0),
            Coordinate::Mimic {
                index,
                multiplier,
                offset,
            } => (index, multiplier, offset),
            Coordinate::None => (0, 0.0, 0.0),
        })
        .collect();
    Ok(PdLaw {
        q0: q_start.to_vec(),
        amplitude,
        map,
        kp: inertia.iter().map(|i| i * PD_OMEGA * PD_OMEGA).collect(),
        kd: inertia.iter().map(|i| 2.0 * i * PD_OMEGA).collect(),
    })
}

/// From rest at `q_start`, the PD law moves every joint towards its farther limit by up to a
/// quarter of its range (at most 0.5 rad) and back, in rapier and in MuJoCo with each
/// integrator, without dry friction; then once more with MuJoCo's Euler given the URDF's dry
/// friction, which rapier leaves out. Returns the comparisons and the largest excursion of a
/// joint from its start in rapier's run.
fn compare_trajectories(
    robot: &RobotModel,
    mj: &mujoco::MujocoRobot,
    config: &CrosscheckConfig,
    q_start: &[f64],
) -> Result<(Vec<TrajectoryComparison>, f64), CrosscheckError> {
    let q_start = q_start.to_vec();
    // Without gravity: the static check covers the gravity torques, and here the PD law would
    // otherwise sag joints into their limits, where the engines differ by design (rapier's
    // limits are hard constraints, MuJoCo's soft).
    let g = [0.0; 3];
    let law = pd_law(robot, &q_start, config.time_step_s)?;
    let rp = rapier::RapierRobot::new(robot, &q_start, g, config.time_step_s)?;
    let joints: Vec<_> = rp.joints.iter().map(|&j| &robot.joints()[j]).collect();
    let steps = (config.duration_s / config.time_step_s).round() as usize;
    let rapier_path = rp.run(&law, steps)?;
    let joint_start: Vec<f64> = joints.iter().map(|j| j.position(&q_start)).collect();
    let excursion = rapier_path
        .iter()
        .flat_map(|q| q.iter().zip(&joint_start).map(|(a, b)| (a - b).abs()))
        .fold(0.0_f64, f64::max);

    let mut out = Vec::new();
    let runs = mujoco::Integrator::ALL
        .iter()
        .map(|&i| (i, false))
        .chain(std::iter::once((mujoco::Integrator::Euler, true)));
    for (integrator, friction) in runs {
        let mj_path = mj.run(
            &law,
            &q_start,
            steps,
            config.time_step_s,
            integrator,
            friction,
        );
        let mut max_divergence = Worst::default();
        let mut divergence = Vec::new();
        for (k, (a, b)) in rapier_path.iter().zip(&mj_path).enumerate() {
            let t = (k + 1) as f64 * config.time_step_s;
            let mut worst = 0.0_f64;
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                let d = (x - y).abs();
                worst = if d.is_nan() { d } else { worst.max(d) };
                max_divergence.update(d, || format!("joint '{}' at {t:.3} s", joints[i].name));
            }
            if REPORT_TIMES
                .iter()
                .any(|&r| (r - t).abs() < 0.5 * config.time_step_s)
            {
                divergence.push((t, worst));
            }
        }
        out.push(TrajectoryComparison {
            integrator: integrator.name().to_string(),
            friction,
            divergence,
            max_divergence,
        });
    }
    Ok((out, excursion))
}

/// The report as text: the differences, where they are largest, and the verdict.
#[must_use]
pub fn format_report(r: &CrosscheckReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{}: {} links, {} joints, against MuJoCo {} ({} random configurations, seed {})",
        r.robot, r.links, r.dofs, r.mujoco_version, r.config.samples, r.config.seed
    );
    let _ = writeln!(s, "  {}", r.urdf.display());
    let _ = writeln!(
        s,
        "  fk position      {:>10.3e} m    at {}",
        r.fk_position_m.value, r.fk_position_m.at
    );
    let _ = writeln!(
        s,
        "  fk rotation      {:>10.3e} rad  at {}",
        r.fk_rotation_rad.value, r.fk_rotation_rad.at
    );
    let _ = writeln!(
        s,
        "  mass matrix      {:>10.3e} of {:.3} kg m^2 at {}",
        r.mass_matrix_relative.value, r.mass_matrix_scale, r.mass_matrix_relative.at
    );
    let _ = writeln!(
        s,
        "  gravity torques  {:>10.3e} of {:.3} N m    at {}",
        r.gravity_relative.value, r.gravity_scale, r.gravity_relative.at
    );
    let _ = writeln!(
        s,
        "  trajectories: PD torques without gravity, {:.1} s at {} ms, joints move up to {:.3}; largest joint difference from rapier:",
        r.config.duration_s,
        r.config.time_step_s * 1e3,
        r.trajectory_excursion
    );
    let header: Vec<String> = r
        .trajectories
        .first()
        .map(|c| {
            c.divergence
                .iter()
                .map(|(t, _)| format!("{t:>9.1} s"))
                .collect()
        })
        .unwrap_or_default();
    let _ = writeln!(s, "    {:<13}{}        max", "MuJoCo", header.join(""));
    for c in &r.trajectories {
        let row: Vec<String> = c
            .divergence
            .iter()
            .map(|(_, d)| format!("{d:>11.2e}"))
            .collect();
        // An explicit integrator with stiff joint damping can blow up: say so.
        let unstable = c.max_divergence.value.is_nan() || c.max_divergence.value >= 1.0;
        let _ = writeln!(
            s,
            "    {:<13}{} {:>10.2e}  at {}{}",
            if c.friction {
                format!("{} +fric", c.integrator)
            } else {
                c.integrator.clone()
            },
            row.join(""),
            c.max_divergence.value,
            c.max_divergence.at,
            if unstable { " (MuJoCo unstable)" } else { "" }
        );
    }
    let _ = writeln!(s, "  verdict:");
    for c in &r.checks {
        let _ = writeln!(
            s,
            "    {:<4} {:<42} {:>10.3e} <= {:.0e}",
            if c.pass { "ok" } else { "FAIL" },
            c.name,
            c.value,
            c.tolerance
        );
    }
    s
}

/// Simulation speed of both engines on the same task.
#[derive(Debug, Clone, Serialize)]
pub struct StepRates {
    pub robot: String,
    pub steps: usize,
    pub time_step_s: f64,
    /// Steps per second (best of the repeats), the robot alone with the PD torque law.
    pub rapier_steps_per_s: f64,
    pub mujoco_steps_per_s: f64,
}

/// Times `steps` steps of the trajectory task (the PD torque law of [`crosscheck`], no dry
/// friction, MuJoCo's Euler integrator, contacts off in MuJoCo and no self-contacts in rapier)
/// in each engine, `repeats` times, on the calling thread; keeps the best run of each.
///
/// # Errors
/// As [`crosscheck`].
pub fn step_rates(
    robot: &RobotModel,
    assets: &UrdfAssets,
    workdir: &Path,
    steps: usize,
    repeats: usize,
) -> Result<StepRates, CrosscheckError> {
    let config = CrosscheckConfig::default();
    let dt = config.time_step_s;
    let g = [0.0; 3];
    let mj = mujoco::MujocoRobot::load(robot, assets, workdir)?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let q_start = random_configuration(robot, &mut rng);
    let law = pd_law(robot, &q_start, dt)?;
    let (mut rapier_best, mut mujoco_best) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..repeats.max(1) {
        let rp = rapier::RapierRobot::new(robot, &q_start, g, dt)?;
        let t = std::time::Instant::now();
        rp.run(&law, steps)?;
        rapier_best = rapier_best.min(t.elapsed().as_secs_f64());
        let t = std::time::Instant::now();
        mj.run(&law, &q_start, steps, dt, mujoco::Integrator::Euler, false);
        mujoco_best = mujoco_best.min(t.elapsed().as_secs_f64());
    }
    Ok(StepRates {
        robot: robot.name().to_string(),
        steps,
        time_step_s: dt,
        rapier_steps_per_s: steps as f64 / rapier_best,
        mujoco_steps_per_s: steps as f64 / mujoco_best,
    })
}
