//! The human's arm as perception models it, and the runtime that turns camera frames into
//! arm estimates: [`ArmTracker`] takes a frame (or a forearm mask) and its camera and gives
//! each part of the arm as a capsule in the world, with an uncertainty, or the reason why
//! there is no estimate. It is what the closed loop calls and what a program beside a real
//! camera calls, the same way.
//!
//! The parts are sized from the human model (the bounding capsules of its links' collision
//! geometry, as the safety layer sizes them), never from the true human: the forearm's pose
//! comes from render-and-compare ([`crate::pose`]), the forearm and what is rigid with it
//! follow that pose, and the upper arm spans the fixed shoulder to the estimated elbow.

use std::sync::Arc;

use workcell_render::dataset::Dataset;
use workcell_render::roi::{self, Roi};
use workcell_render::{Camera, Class, CpuRenderer, RenderMesh};
use workcell_robots::collision::link_bounding_capsule;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{HumanPart, JointKind, LinkId, PackageMap, RobotModel};

use crate::error::{PerceptionError, Result};
use crate::image::planar_rgb;
use crate::infer::ProcNet;
use crate::pose::{Anchor, NoPose, PoseConfig, PoseEstimate, PoseEstimator, RigidModel};

/// Segments around round shapes in the pose search's forearm mesh: the search renders the
/// forearm thousands of times a second, and a hexagon of a 1-2 pixel bone is its circle to a
/// hundredth of a pixel.
pub const POSE_MESH_SEGMENTS: usize = 6;

/// One part's capsule in the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartCapsule {
    pub part: HumanPart,
    pub a_W: Vector,
    pub b_W: Vector,
    pub radius_m: f64,
}

/// How a part follows the forearm's pose.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Placement {
    /// Its capsule's end points in the forearm link's frame F.
    Rigid { a_F: Vector, b_F: Vector },
    /// From the fixed shoulder to the elbow (the forearm frame's origin).
    ShoulderToElbow,
}

/// The arm of a human model as perception sees it.
#[derive(Debug, Clone)]
pub struct ArmModel {
    /// The forearm, as the pose search renders it (object frame = the forearm link's frame).
    pub forearm: RigidModel,
    /// The shoulder in the world and the upper arm's length (shoulder to elbow), when the
    /// shoulder stays put whatever the joints do (a human whose torso does not move).
    pub shoulder_W: Option<(Vector, f64)>,
    /// The arm's parts in [`HumanPart::ARM`] order, with their radii.
    parts: Vec<(HumanPart, Placement, f64)>,
}

impl ArmModel {
    /// The arm of `human` standing with its base at `X_WH`.
    ///
    /// The shoulder is the origin of the forearm's parent link (the upper arm) when it stays
    /// within a micrometre at three configurations: every joint at its lower limit, at the
    /// middle of its range, and at its upper limit (limits clamped to +-3 rad). Parts below
    /// the forearm that hang from it by joints that move are placed at their joints' zero
    /// (clamped to the limits).
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when a part of the arm has no link of its name, no
    /// collision geometry, or the forearm has no visual geometry.
    pub fn new(human: &RobotModel, X_WH: &Pose) -> Result<Self> {
        let missing = |message: String| PerceptionError::Input {
            message: format!("human model {}: {message}", human.name()),
        };
        let link = |part: HumanPart| {
            human
                .link_id(part.link_name())
                .ok_or_else(|| missing(format!("no link named {part}")))
        };
        let forearm = link(HumanPart::Forearm)?;
        let mut mesh = RenderMesh::default();
        for g in &human.links()[forearm].visuals {
            mesh.append(
                &RenderMesh::from_geometry_with(g, [0.85, 0.72, 0.62], POSE_MESH_SEGMENTS),
                &Pose::IDENTITY,
            );
        }
        if mesh.is_empty() {
            return Err(missing("the forearm link has no visual geometry".into()));
        }
        let model = RigidModel::new(Arc::new(mesh))?;
        let limits = human.position_limits();
        let at = |c: f64| -> Vec<f64> {
            limits
                .iter()
                .map(|&[lo, hi]| {
                    let (lo, hi) = (lo.max(-3.0), hi.min(3.0));
                    lo + c * (hi - lo)
                })
                .collect()
        };
        let parent = human.links()[forearm]
            .parent_joint
            .map(|j| human.joints()[j].parent);
        let mut points = Vec::new();
        for c in [0.0, 0.5, 1.0] {
            if let (Some(parent), Ok(k)) = (parent, human.fk(*X_WH, &at(c))) {
                let poses = k.link_poses();
                points.push((poses[parent].translation, poses[forearm].translation));
            }
        }
        let fixed = points.len() == 3
            && points
                .iter()
                .all(|(s, _)| (*s - points[0].0).length() < 1e-6);
        let shoulder_W = fixed.then(|| (points[0].0, (points[0].1 - points[0].0).length()));

        let q_ref: Vec<f64> = limits
            .iter()
            .map(|&[lo, hi]| 0.0_f64.clamp(lo, hi))
            .collect();
        let reference = human.fk(*X_WH, &q_ref)?;
        let X_FW = reference.link_pose(forearm).inverse();
        let mut parts = Vec::with_capacity(HumanPart::ARM.len());
        for part in HumanPart::ARM {
            let l = link(part)?;
            let capsule = link_bounding_capsule(human, l)
                .ok_or_else(|| missing(format!("the {part} link has no collision geometry")))?;
            let placement = if part == HumanPart::UpperArm && shoulder_W.is_some() {
                Placement::ShoulderToElbow
            } else {
                let X_FL = X_FW * *reference.link_pose(l);
                if !rigid_with(human, l, forearm) && part != HumanPart::UpperArm {
                    tracing::debug!("{part} moves against the forearm; placed at q = 0");
                }
                Placement::Rigid {
                    a_F: X_FL.transform_point(capsule.a_L),
                    b_F: X_FL.transform_point(capsule.b_L),
                }
            };
            parts.push((part, placement, capsule.radius_m));
        }
        Ok(Self {
            forearm: model,
            shoulder_W,
            parts,
        })
    }

    /// The arm of the human a dataset shows (the model and base pose its manifest records).
    ///
    /// # Errors
    /// The manifest records no human (a dataset from before it did: regenerate it), the
    /// model does not load, or [`ArmModel::new`] fails.
    pub fn of_dataset(dataset: &Dataset) -> Result<Self> {
        let (model, X_WH) = dataset_human(dataset)?;
        Self::new(&model, &X_WH)
    }

    /// The elbow-on-shoulder-sphere anchor for a camera at `X_WC`, if the shoulder is fixed.
    #[must_use]
    pub fn anchor(&self, X_WC: &Pose) -> Option<Anchor> {
        self.shoulder_W.map(|(s, r)| Anchor {
            end_O: Vector::ZERO,
            point_C: X_WC.inverse().transform_point(s),
            radius_m: r,
            sigma_m: 0.02,
        })
    }

    /// How far the wrist can be from the shoulder: the upper arm's length plus the forearm
    /// capsule's far end from the elbow (`None` without a fixed shoulder).
    #[must_use]
    pub fn reach_m(&self) -> Option<f64> {
        let forearm = self
            .parts
            .iter()
            .find_map(|(part, placement, _)| match placement {
                Placement::Rigid { a_F, b_F } if *part == HumanPart::Forearm => {
                    Some(a_F.length().max(b_F.length()))
                }
                _ => None,
            })?;
        self.shoulder_W.map(|(_, upper)| upper + forearm)
    }

    /// The arm's capsules in the world with the forearm link's frame at `X_WF`.
    #[must_use]
    pub fn parts(&self, X_WF: &Pose) -> Vec<PartCapsule> {
        self.parts
            .iter()
            .map(|&(part, placement, radius_m)| {
                let (a_W, b_W) = match placement {
                    Placement::Rigid { a_F, b_F } => {
                        (X_WF.transform_point(a_F), X_WF.transform_point(b_F))
                    }
                    Placement::ShoulderToElbow => (
                        self.shoulder_W.map_or(X_WF.translation, |(s, _)| s),
                        X_WF.translation,
                    ),
                };
                PartCapsule {
                    part,
                    a_W,
                    b_W,
                    radius_m,
                }
            })
            .collect()
    }
}

/// The human a dataset shows: its model in the dataset's look (the visuals it was rendered
/// with) and its base pose, as the manifest records them.
///
/// # Errors
/// The manifest records no human (a dataset from before it did: regenerate it), or the
/// model does not load.
pub fn dataset_human(dataset: &Dataset) -> Result<(RobotModel, Pose)> {
    let human = dataset
        .manifest
        .human
        .as_ref()
        .ok_or_else(|| PerceptionError::Input {
            message: format!(
                "{}: the manifest records no human model (written by an older \
                 workcell); regenerate the dataset",
                dataset.root.join("manifest.json").display()
            ),
        })?;
    let mut model = RobotModel::load(&human.model, &PackageMap::from_env())?;
    let look = human.look;
    model.retain_visuals(|g| look.shows(g.name.as_deref()));
    Ok((model, Pose::from(&human.X_WH)))
}

/// Whether `link` is `base` or hangs from it by fixed joints only.
fn rigid_with(model: &RobotModel, mut link: LinkId, base: LinkId) -> bool {
    while link != base {
        let Some(j) = model.links()[link].parent_joint else {
            return false;
        };
        let joint = &model.joints()[j];
        if joint.kind != JointKind::Fixed {
            return false;
        }
        link = joint.parent;
    }
    true
}

/// What the tracker knows of the arm in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmEstimate {
    /// Each part of the arm in the world, [`HumanPart::ARM`] order, not inflated.
    pub parts: Vec<PartCapsule>,
    /// The radius by which every capsule is to be inflated, m.
    pub uncertainty_m: f64,
    /// The forearm link's frame in the world.
    pub X_WF: Pose,
    /// The pose search's result behind it (camera frame, scores, timing).
    pub pose: PoseEstimate,
}

/// Why a frame gave no estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoEstimate {
    /// The forearm's mask gave no pose.
    NoPose(NoPose),
}

impl std::fmt::Display for NoEstimate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NoEstimate::NoPose(reason) => write!(f, "no forearm pose: {reason}"),
        }
    }
}

/// The result of one frame: an estimate, or why there is none.
pub type ArmOutcome = std::result::Result<ArmEstimate, NoEstimate>;

/// Frames of one camera in, arm estimates out: ProcNet's forearm mask, the anchored pose
/// search tracking the forearm from frame to frame, and the arm rebuilt from the forearm.
///
/// ```no_run
/// # use workcell_perception::{ArmModel, ArmTracker, Backend, ProcNet, pose::PoseConfig};
/// # fn run(arm: ArmModel, camera: workcell_render::Camera, rgb: &[u8]) -> workcell_perception::Result<()> {
/// let weights = std::path::Path::new("perception/weights/procnet-cpu.safetensors");
/// let net = ProcNet::load(weights, Backend::Flex)?;
/// let mut tracker = ArmTracker::new(arm, PoseConfig::default()).with_network(net)?;
/// match tracker.track(&camera, rgb)? {
///     Ok(estimate) => println!("{} parts, +-{:.3} m", estimate.parts.len(), estimate.uncertainty_m),
///     Err(reason) => println!("no estimate: {reason}"),
/// }
/// # Ok(())
/// # }
/// ```
pub struct ArmTracker {
    arm: ArmModel,
    estimator: PoseEstimator<CpuRenderer>,
    net: Option<ProcNet>,
    /// The last estimate's shoulder, elbow and wrist: the next region of interest follows
    /// them.
    joints_W: Option<[Vector; 3]>,
}

/// The side of the region of interest's image for a tracker without a network (the input of
/// the networks this project trains).
pub const DEFAULT_INPUT_PX: usize = 128;

/// A frame's forearm as the tracker's network sees it: the region of interest, the camera
/// that sees exactly that region at the network's input, and the mask there.
#[derive(Debug, Clone, PartialEq)]
pub struct RoiMask {
    pub roi: Roi,
    pub camera: Camera,
    /// Forearm probabilities, `camera.width x camera.height`.
    pub mask: Vec<f32>,
}

impl ArmTracker {
    /// A tracker of `arm` without a network: give it forearm masks ([`ArmTracker::track_mask`]).
    #[must_use]
    pub fn new(arm: ArmModel, config: PoseConfig) -> Self {
        let estimator = PoseEstimator::new(CpuRenderer::new(), arm.forearm.clone(), config);
        Self {
            arm,
            estimator,
            net: None,
            joints_W: None,
        }
    }

    /// The same tracker segmenting frames with `net` ([`ArmTracker::track`]).
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when the network has no forearm class.
    pub fn with_network(mut self, net: ProcNet) -> Result<Self> {
        if net.config().class_index(Class::Forearm).is_none() {
            return Err(PerceptionError::Input {
                message: format!(
                    "the network has no forearm class (it has {:?})",
                    net.config().classes
                ),
            });
        }
        self.net = Some(net);
        Ok(self)
    }

    /// The arm it tracks.
    #[must_use]
    pub fn arm(&self) -> &ArmModel {
        &self.arm
    }

    /// The network, if it has one.
    #[must_use]
    pub fn network(&self) -> Option<&ProcNet> {
        self.net.as_ref()
    }

    /// Forgets the track and the network's state (a new camera stream).
    pub fn reset(&mut self) {
        self.estimator.reset();
        self.joints_W = None;
        if let Some(net) = &mut self.net {
            net.reset();
        }
    }

    /// The side of the region of interest's image: the network's input, or
    /// [`DEFAULT_INPUT_PX`] without a network.
    #[must_use]
    pub fn input_px(&self) -> usize {
        self.net
            .as_ref()
            .map_or(DEFAULT_INPUT_PX, |n| n.config().input_size)
    }

    /// The region of `camera`'s image the next frame is read through: around the last
    /// estimate's shoulder, elbow and wrist ([`Roi::of_joints`], the middle of
    /// [`roi::TRACKED_MARGIN`]) while there is one, else the sphere the forearm can reach
    /// ([`Roi::of_sphere`]), else the whole frame.
    #[must_use]
    pub fn roi(&self, camera: &Camera) -> Roi {
        let margin = 0.5 * (roi::TRACKED_MARGIN[0] + roi::TRACKED_MARGIN[1]);
        self.joints_W
            .and_then(|joints| Roi::of_joints(camera, &joints, margin, roi::TRACKED_MIN_M))
            .or_else(|| {
                let (shoulder, _) = self.arm.shoulder_W?;
                Roi::of_sphere(camera, shoulder, self.arm.reach_m()?, roi::WORKSPACE_MARGIN)
            })
            .unwrap_or(Roi::frame(camera.width, camera.height))
    }

    /// The forearm's probability mask of a frame: the region of interest ([`ArmTracker::roi`])
    /// resampled to the network's input and segmented.
    ///
    /// # Errors
    /// No network ([`ArmTracker::with_network`]), a frame of the wrong size, a network failure.
    pub fn forearm_mask(&mut self, camera: &Camera, rgb: &[u8]) -> Result<RoiMask> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        check_len("an sRGB frame", rgb.len(), 3 * w * h, camera)?;
        let roi = self.roi(camera);
        let net = self.net.as_mut().ok_or_else(|| PerceptionError::Input {
            message: "this tracker has no network; give it masks with track_mask".into(),
        })?;
        let s = net.config().input_size;
        let input = roi.resample(&planar_rgb(rgb, w, h), 3, w, h, s);
        let mask = net.forearm(&input, s, s)?;
        Ok(RoiMask {
            roi,
            camera: roi.camera(camera, s as u32)?,
            mask,
        })
    }

    /// One frame: interleaved sRGB bytes (`width * height * 3`, row-major from the top left)
    /// from `camera`, whose pose in the world is known. The network reads the frame's region
    /// of interest and the pose search renders that region's camera.
    ///
    /// # Errors
    /// As [`ArmTracker::forearm_mask`] and [`ArmTracker::track_mask`].
    pub fn track(&mut self, camera: &Camera, rgb: &[u8]) -> Result<ArmOutcome> {
        let RoiMask { camera, mask, .. } = self.forearm_mask(camera, rgb)?;
        self.track_mask(&camera, &mask)
    }

    /// One frame given as the forearm's mask at the camera's resolution (values in [0, 1]),
    /// read through the region of interest as [`ArmTracker::track`] reads a frame: the
    /// region resampled to [`ArmTracker::input_px`], then [`ArmTracker::track_mask`].
    ///
    /// # Errors
    /// As [`ArmTracker::track_mask`].
    pub fn track_frame_mask(&mut self, camera: &Camera, mask: &[f32]) -> Result<ArmOutcome> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        check_len("a mask", mask.len(), w * h, camera)?;
        let roi = self.roi(camera);
        let s = self.input_px();
        let crop = roi.resample(mask, 1, w, h, s);
        self.track_mask(&roi.camera(camera, s as u32)?, &crop)
    }

    /// One frame given as the forearm's mask (values in [0, 1], `width * height`).
    ///
    /// # Errors
    /// [`PerceptionError::Input`] for a mask or camera that does not fit; renderer failures.
    pub fn track_mask(&mut self, camera: &Camera, mask: &[f32]) -> Result<ArmOutcome> {
        self.estimator.set_anchor(self.arm.anchor(&camera.X_WC));
        let pose = match self.estimator.estimate(camera, mask)? {
            Ok(pose) => pose,
            Err(reason) => {
                self.joints_W = None;
                return Ok(Err(NoEstimate::NoPose(reason)));
            }
        };
        let X_WF = camera.X_WC * pose.X_CO;
        let parts = self.arm.parts(&X_WF);
        let end = |part: HumanPart| parts.iter().find(|p| p.part == part);
        self.joints_W = match (end(HumanPart::UpperArm), end(HumanPart::Forearm)) {
            (Some(upper), Some(forearm)) => Some([upper.a_W, X_WF.translation, forearm.b_W]),
            _ => None,
        };
        Ok(Ok(ArmEstimate {
            parts,
            uncertainty_m: pose.uncertainty_m,
            X_WF,
            pose,
        }))
    }
}

/// A frame or mask of `len` values where the camera needs `expected`.
fn check_len(what: &str, len: usize, expected: usize, camera: &Camera) -> Result<()> {
    if len == expected {
        return Ok(());
    }
    Err(PerceptionError::Input {
        message: format!(
            "expected {what} of {} values for the {}x{} camera, got {len}",
            expected, camera.width, camera.height
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_render::Renderer as _;
    use workcell_robots::math::pose_from_xyz_rpy;

    /// The built-in human in its default (flesh) look.
    fn human() -> RobotModel {
        let mut human = RobotModel::from_catalogue("human_arm").expect("catalogue human");
        human.retain_visuals(|g| workcell_robots::HumanLook::Flesh.shows(g.name.as_deref()));
        human
    }

    #[test]
    fn the_built_in_human_hangs_its_forearm_from_a_fixed_shoulder() {
        let X_WH = pose_from_xyz_rpy([1.2, 0.4, 0.1], [0.0, 0.0, 2.5]);
        let arm = ArmModel::new(&human(), &X_WH).expect("arm");
        let (shoulder, radius) = arm.shoulder_W.expect("a fixed shoulder");
        // robots/urdf/human_arm/human_arm.urdf: elbow_flexion at z = -0.3255 in the upper
        // arm, shoulder_abduction at (0, -0.19, 0.48) in the torso.
        assert!((radius - 0.3255).abs() < 1e-12, "{radius}");
        let expected = X_WH.transform_point(Vector::new(0.0, -0.19, 0.48));
        assert!(
            (shoulder - expected).length() < 1e-12,
            "{shoulder} vs {expected}"
        );
        // In a camera's frame.
        let X_WC = pose_from_xyz_rpy([1.0, 2.0, 1.5], [0.3, -0.2, 2.0]);
        let anchor = arm.anchor(&X_WC).expect("anchor");
        assert!((X_WC.transform_point(anchor.point_C) - shoulder).length() < 1e-12);
    }

    /// At any joint configuration, the parts rebuilt from the true forearm pose are the
    /// model's own capsules there: forearm and hand carried with the forearm (the wrist is
    /// fixed), the upper arm from the shoulder to the elbow, radii from the collision geometry.
    #[test]
    fn parts_from_the_true_forearm_pose_are_the_model_s_capsules() {
        let human = human();
        let X_WH = pose_from_xyz_rpy([0.9, -0.3, 0.0], [0.0, 0.0, 0.7]);
        let arm = ArmModel::new(&human, &X_WH).expect("arm");
        let forearm = human.link_id("forearm").expect("forearm");
        for q in [[0.0, 0.0, 0.0], [0.8, 1.2, 1.9], [2.2, -0.5, 0.3]] {
            let k = human.fk(X_WH, &q).expect("fk");
            let parts = arm.parts(k.link_pose(forearm));
            let order: Vec<HumanPart> = parts.iter().map(|p| p.part).collect();
            assert_eq!(order, HumanPart::ARM);
            for p in &parts {
                let link = human.link_id(p.part.link_name()).expect("link");
                let c = link_bounding_capsule(&human, link).expect("capsule");
                assert!((p.radius_m - c.radius_m).abs() < 1e-15, "{p:?}");
                let (a, b) = match p.part {
                    HumanPart::UpperArm => (
                        arm.shoulder_W.expect("shoulder").0,
                        k.link_pose(forearm).translation,
                    ),
                    _ => c.segment_in_world(k.link_pose(link)),
                };
                assert!((p.a_W - a).length() < 1e-12, "{p:?} at {q:?}");
                assert!((p.b_W - b).length() < 1e-12, "{p:?} at {q:?}");
            }
        }
    }

    #[test]
    fn a_human_without_a_forearm_or_a_manifest_without_a_human_is_an_error() {
        let urdf = r#"<robot name="stump"><link name="torso"/></robot>"#;
        let stump =
            RobotModel::from_urdf_str(urdf, std::path::Path::new("stump.urdf"), &PackageMap::new())
                .expect("a one-link model");
        let err = ArmModel::new(&stump, &Pose::IDENTITY).unwrap_err();
        assert!(err.to_string().contains("no link named forearm"), "{err}");
    }

    #[test]
    fn a_tracker_without_a_network_asks_for_masks_and_checks_frame_sizes() {
        let arm = ArmModel::new(&human(), &Pose::IDENTITY).expect("arm");
        let mut tracker = ArmTracker::new(arm, PoseConfig::default());
        let camera = Camera::look_at(
            [3.0, 0.0, 1.5],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0],
            64,
            48,
            50.0,
        )
        .expect("camera");
        let err = tracker.track(&camera, &[0; 10]).unwrap_err();
        assert!(
            err.to_string().contains("9216 values for the 64x48"),
            "{err}"
        );
        let err = tracker.track(&camera, &vec![0; 64 * 48 * 3]).unwrap_err();
        assert!(err.to_string().contains("no network"), "{err}");
        // An empty mask is no estimate, with its reason.
        let outcome = tracker
            .track_mask(&camera, &vec![0.0; 64 * 48])
            .expect("no error");
        assert_eq!(outcome, Err(NoEstimate::NoPose(NoPose::Empty)));
        let err = tracker.track_frame_mask(&camera, &[0.0; 7]).unwrap_err();
        assert!(err.to_string().contains("3072 values"), "{err}");
    }

    /// A network reads the frame's region of interest at its input size: the shipped
    /// weights on a 640x480 frame see the reach sphere's square, resampled to their input, and
    /// the mask comes back with that square's camera.
    #[test]
    fn the_network_reads_the_region_of_interest_at_its_input() {
        let arm = ArmModel::new(&human(), &Pose::IDENTITY).expect("arm");
        let (shoulder, _) = arm.shoulder_W.expect("fixed shoulder");
        let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("weights/procnet-cpu.safetensors");
        let net = ProcNet::load(&weights, crate::Backend::Flex).expect("shipped weights");
        let input = net.config().input_size;
        let mut tracker = ArmTracker::new(arm, PoseConfig::default())
            .with_network(net)
            .expect("forearm class");
        let camera = Camera::look_at(
            (shoulder + Vector::new(2.5, 0.5, 0.2)).to_array(),
            shoulder.to_array(),
            [0.0, 0.0, 1.0],
            640,
            480,
            45.0,
        )
        .expect("camera");
        let roi = tracker.roi(&camera);
        let out = tracker
            .forearm_mask(&camera, &vec![90; 640 * 480 * 3])
            .expect("segmented");
        assert_eq!(out.roi, roi);
        assert_eq!(
            out.camera,
            roi.camera(&camera, input as u32).expect("camera")
        );
        assert_eq!(out.mask.len(), input * input);
        assert!(out.mask.iter().all(|v| (0.0..=1.0).contains(v)));
    }

    /// The region of interest: the reach sphere without an estimate, the arm's joints with
    /// one, the reach sphere again after a lost track.
    #[test]
    fn the_region_follows_the_estimate_and_falls_back_to_the_workspace() {
        let human = human();
        let arm = ArmModel::new(&human, &Pose::IDENTITY).expect("arm");
        let (shoulder, upper) = arm.shoulder_W.expect("fixed shoulder");
        // Upper arm 0.3255 m and forearm 0.2555 m in the built-in model (generate.py).
        let reach = arm.reach_m().expect("reach");
        assert!(
            (upper - 0.3255).abs() < 1e-9 && (reach - 0.581).abs() < 1e-9,
            "{reach}"
        );
        let camera = Camera::look_at(
            (shoulder + Vector::new(3.0, 0.0, 0.0)).to_array(),
            shoulder.to_array(),
            [0.0, 0.0, 1.0],
            640,
            480,
            40.0,
        )
        .expect("camera");
        let mut tracker = ArmTracker::new(arm.clone(), PoseConfig::default());
        assert_eq!(
            tracker.roi(&camera),
            Roi::of_sphere(&camera, shoulder, reach, roi::WORKSPACE_MARGIN).expect("in view")
        );
        // The forearm's true mask: the tracker finds it and then crops around the arm.
        let X_WF = Pose::from_translation(shoulder - Vector::new(0.0, 0.0, upper));
        let X_CF = camera.X_WC.inverse() * X_WF;
        let mut batch = workcell_render::MaskBatch::new();
        CpuRenderer::new()
            .render_masks(&arm.forearm.mesh, &camera, &[X_CF], &mut batch)
            .expect("render");
        let mask: Vec<f32> = batch.mask(0).iter().map(|&v| f32::from(v)).collect();
        let estimate = tracker
            .track_frame_mask(&camera, &mask)
            .expect("track")
            .expect("an estimate");
        let tracked = tracker.roi(&camera);
        let workspace = Roi::of_sphere(&camera, shoulder, reach, roi::WORKSPACE_MARGIN).unwrap();
        assert!(
            tracked.size < workspace.size,
            "{tracked:?} vs {workspace:?}"
        );
        // The crop holds the estimated elbow.
        let [u, v] = camera
            .project(camera.X_WC.inverse() * estimate.X_WF.translation)
            .expect("in front");
        let inside = |x: f64, x0: i64| x >= x0 as f64 && x <= (x0 + i64::from(tracked.size)) as f64;
        assert!(inside(u, tracked.x0) && inside(v, tracked.y0));
        // A lost track falls back to the workspace.
        let outcome = tracker
            .track_mask(&camera, &vec![0.0; 640 * 480])
            .expect("no error");
        assert!(outcome.is_err());
        assert_eq!(tracker.roi(&camera), workspace);
    }
}
