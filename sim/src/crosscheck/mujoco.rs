//! The MuJoCo side of the cross-check: the vendor's URDF prepared for MuJoCo and loaded, and
//! the same quantities as the rapier side, in the robot's joint order.

use std::collections::HashMap;
use std::path::Path;

use mujoco_rs::mujoco_c::{mj_version, mjVERSION_HEADER};
use mujoco_rs::prelude::*;
use workcell_robots::assets::{UrdfAssets, write_binary_stl};
use workcell_robots::math::{Pose, Rotation, Vector};
use workcell_robots::{JointId, RobotModel, TriMesh};

use super::{CrosscheckError, PdLaw};

/// The MuJoCo release the bindings (mujoco-rs 7.0.0) were generated for.
pub const MUJOCO_VERSION: &str = "3.17.0";

/// The version of the MuJoCo library loaded at run time, as `major.minor.patch`.
#[must_use]
pub fn linked_mujoco_version() -> String {
    // SAFETY: mj_version reads a constant of the loaded library.
    version_string(unsafe { mj_version() })
}

/// MuJoCo's version number (`3017000`) as `3.17.0`.
fn version_string(v: i32) -> String {
    format!("{}.{}.{}", v / 1_000_000, (v / 1000) % 1000, v % 1000)
}

/// mujoco-rs panics on a version mismatch; checked first, so that it is an error instead.
fn check_version() -> Result<(), CrosscheckError> {
    // SAFETY: as above.
    check_version_number(unsafe { mj_version() })
}

fn check_version_number(v: i32) -> Result<(), CrosscheckError> {
    if u32::try_from(v).ok() == Some(mjVERSION_HEADER) {
        Ok(())
    } else {
        Err(CrosscheckError::MujocoVersion {
            found: version_string(v),
            expected: MUJOCO_VERSION.to_string(),
        })
    }
}

/// MuJoCo's integrators, as the report names them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Integrator {
    Euler,
    ImplicitFast,
    Implicit,
    Rk4,
}

impl Integrator {
    pub(super) const ALL: [Integrator; 4] = [
        Integrator::Euler,
        Integrator::ImplicitFast,
        Integrator::Implicit,
        Integrator::Rk4,
    ];
    pub(super) fn name(self) -> &'static str {
        match self {
            Integrator::Euler => "Euler",
            Integrator::ImplicitFast => "implicitfast",
            Integrator::Implicit => "implicit",
            Integrator::Rk4 => "RK4",
        }
    }
    fn mj(self) -> i32 {
        (match self {
            Integrator::Euler => MjtIntegrator::mjINT_EULER,
            Integrator::ImplicitFast => MjtIntegrator::mjINT_IMPLICITFAST,
            Integrator::Implicit => MjtIntegrator::mjINT_IMPLICIT,
            Integrator::Rk4 => MjtIntegrator::mjINT_RK4,
        }) as i32
    }
}

/// What MuJoCo computes at one configuration, in the robot's link and joint order.
pub(super) struct Statics {
    pub(super) link_poses: Vec<Pose>,
    /// Row-major, movable joints.
    pub(super) mass_matrix: Vec<f64>,
    /// Generalized gravity force (`-qfrc_bias` at rest).
    pub(super) gravity: Vec<f64>,
}

pub(super) struct MujocoRobot<'a> {
    robot: &'a RobotModel,
    model: MjModel,
    /// MuJoCo body of every link.
    bodies: Vec<usize>,
    /// Movable joints: (joint, qpos address, dof address).
    joints: Vec<(JointId, usize, usize)>,
}

/// Compiler settings for the vendor URDF: keep every link as a body (no fusing of fixed
/// joints), drop visual-only geometry, keep the absolute mesh paths.
const COMPILER: &str = "\n  <mujoco>\n    <compiler fusestatic=\"false\" discardvisual=\"true\" \
                        strippath=\"false\" inertiafromgeom=\"false\"/>\n  </mujoco>\n";

impl<'a> MujocoRobot<'a> {
    /// Prepares `assets` for MuJoCo in `workdir` (`model.urdf` and `mesh_K.stl`) and loads it.
    pub(super) fn load(
        robot: &'a RobotModel,
        assets: &UrdfAssets,
        workdir: &Path,
    ) -> Result<Self, CrosscheckError> {
        check_version()?;
        // MuJoCo's warnings go to the `log` crate (and from there to tracing) instead of
        // stderr and a MUJOCO_LOG.TXT in the working folder.
        static LOGGING: std::sync::Once = std::sync::Once::new();
        // SAFETY: the Once holds every other thread that reaches MuJoCo through here until the
        // hook is in place, and MuJoCo is used nowhere else.
        LOGGING.call_once(|| unsafe { mujoco_rs::prelude::install_logging_hook() });
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| CrosscheckError::Io { path, source }
        };
        std::fs::create_dir_all(workdir).map_err(io(workdir))?;
        let workdir = workdir.canonicalize().map_err(io(workdir))?;
        // Every mesh through our loader to binary STL, one file per reference: MuJoCo names
        // URDF meshes after their files, so two references never share a name.
        let mut loaded: HashMap<&Path, TriMesh> = HashMap::new();
        let mut uris = Vec::with_capacity(assets.meshes.len());
        for (k, m) in assets.meshes.iter().enumerate() {
            if !loaded.contains_key(m.path.as_path()) {
                let mesh = TriMesh::load(&m.path, [1.0; 3]).map_err(|e| CrosscheckError::Mesh {
                    path: m.path.clone(),
                    message: e.to_string(),
                })?;
                loaded.insert(&m.path, mesh);
            }
            let out = workdir.join(format!("mesh_{k}.stl"));
            write_binary_stl(&loaded[m.path.as_path()], &out).map_err(io(&out))?;
            uris.push(out.to_string_lossy().into_owned());
        }
        let text = assets.rewrite(&uris, COMPILER)?;
        let prepared = workdir.join("model.urdf");
        std::fs::write(&prepared, text).map_err(io(&prepared))?;
        let rejected = |message: String| CrosscheckError::MujocoRejected {
            urdf: assets.path.clone(),
            prepared: prepared.clone(),
            message,
        };
        let mut model = MjModel::from_xml(&prepared).map_err(|e| match e {
            MjModelError::LoadFailed(m) => rejected(m.trim().to_string()),
            other => rejected(other.to_string()),
        })?;
        {
            let opt = model.opt_mut();
            opt.disableflags |= MjtDisableBit::mjDSBL_CONTACT as i32;
            opt.gravity = [0.0, 0.0, -9.81];
        }

        let missing = |what, name: &str| CrosscheckError::Missing {
            urdf: assets.path.clone(),
            what,
            name: name.to_string(),
        };
        let mut bodies = Vec::with_capacity(robot.links().len());
        for link in robot.links() {
            let id = model
                .name_to_id(MjtObjBase::mjOBJ_BODY, &link.name)
                .ok_or_else(|| missing("body", &link.name))?;
            bodies.push(id);
        }
        let mut joints = Vec::new();
        for (j, joint) in robot.joints().iter().enumerate() {
            if !joint.kind.is_movable() {
                continue;
            }
            let id = model
                .name_to_id(MjtObjBase::mjOBJ_JOINT, &joint.name)
                .ok_or_else(|| missing("joint", &joint.name))?;
            let qpos = usize::try_from(model.jnt_qposadr()[id]).unwrap_or(usize::MAX);
            let dof = usize::try_from(model.jnt_dofadr()[id]).unwrap_or(usize::MAX);
            joints.push((j, qpos, dof));
        }
        Ok(Self {
            robot,
            model,
            bodies,
            joints,
        })
    }

    /// A data of a copy of the model with time step `dt` and `integrator`; without
    /// `friction`, the joints' dry friction (`frictionloss`, from the URDF) is removed.
    pub(super) fn data(
        &self,
        dt: f64,
        integrator: Integrator,
        friction: bool,
    ) -> MjData<Box<MjModel>> {
        let mut model = Box::new(self.model.clone());
        let opt = model.opt_mut();
        opt.timestep = dt;
        opt.integrator = integrator.mj();
        if !friction {
            model.dof_frictionloss_mut().fill(0.0);
        }
        MjData::new(model)
    }

    fn set_configuration(&self, data: &mut MjData<Box<MjModel>>, q: &[f64]) {
        data.qpos_mut().fill(0.0);
        data.qvel_mut().fill(0.0);
        for &(j, qpos, _) in &self.joints {
            data.qpos_mut()[qpos] = self.robot.joints()[j].position(q);
        }
    }

    /// Poses, mass matrix and gravity torques at configuration `q`, at rest.
    pub(super) fn statics(&self, data: &mut MjData<Box<MjModel>>, q: &[f64]) -> Statics {
        self.set_configuration(data, q);
        data.forward();
        let link_poses = self
            .bodies
            .iter()
            .map(|&b| {
                let [x, y, z] = data.xpos()[b];
                let [w, qx, qy, qz] = data.xquat()[b];
                Pose::from_parts(Vector::new(x, y, z), Rotation::from_xyzw(qx, qy, qz, w))
            })
            .collect();
        let nv = usize::try_from(data.model().ffi().nv).unwrap_or(0);
        let mut full = vec![0.0; nv * nv];
        if data.full_m(&mut full).is_err() {
            full.fill(f64::NAN);
        }
        let n = self.joints.len();
        let mut mass_matrix = vec![0.0; n * n];
        let mut gravity = vec![0.0; n];
        for (i, &(_, _, a)) in self.joints.iter().enumerate() {
            for (k, &(_, _, b)) in self.joints.iter().enumerate() {
                mass_matrix[i * n + k] = full[a * nv + b];
            }
            gravity[i] = -data.qfrc_bias()[a];
        }
        Statics {
            link_poses,
            mass_matrix,
            gravity,
        }
    }

    /// Runs `steps` steps from rest at `q_start` under `law` as `qfrc_applied`; the movable
    /// joints' positions after every step.
    pub(super) fn run(
        &self,
        law: &PdLaw,
        q_start: &[f64],
        steps: usize,
        dt: f64,
        integrator: Integrator,
        friction: bool,
    ) -> Vec<Vec<f64>> {
        let mut data = self.data(dt, integrator, friction);
        // Gravity off, as in the rapier run (see `compare_trajectories`).
        data.model_opt_mut().gravity = [0.0; 3];
        self.set_configuration(&mut data, q_start);
        let n = self.joints.len();
        let (mut q, mut v, mut tau) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let read = |data: &MjData<Box<MjModel>>, q: &mut [f64], v: &mut [f64]| {
            for (i, &(_, qpos, dof)) in self.joints.iter().enumerate() {
                q[i] = data.qpos()[qpos];
                v[i] = data.qvel()[dof];
            }
        };
        let mut path = Vec::with_capacity(steps);
        for k in 0..steps {
            read(&data, &mut q, &mut v);
            law.torque(k as f64 * dt, &q, &v, &mut tau);
            for (i, &(_, _, dof)) in self.joints.iter().enumerate() {
                data.qfrc_applied_mut()[dof] = tau[i];
            }
            data.step();
            read(&data, &mut q, &mut v);
            path.push(q.clone());
        }
        path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_library_version_is_checked() {
        assert_eq!(version_string(3_017_000), MUJOCO_VERSION);
        assert!(check_version_number(3_017_000).is_ok());
        // The library this build links is the one the bindings were made for.
        assert!(check_version().is_ok(), "{}", linked_mujoco_version());
        let e = check_version_number(3_016_002).expect_err("another release");
        let text = e.to_string();
        assert!(
            text.contains("3.16.2") && text.contains("3.17.0") && text.contains("fetch-mujoco"),
            "{text}"
        );
    }
}
