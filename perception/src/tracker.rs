//! The human's arm as perception models it, and the runtime that turns camera frames into
//! arm estimates: [`ArmTracker`] takes a frame (or masks) and its camera and gives each part
//! of the arm as a capsule in the world, with an uncertainty, or the reason why there is no
//! estimate. It is what the closed loop calls and what a program beside a real camera calls,
//! the same way.
//!
//! The parts are sized from the human model and placed where the articulated fit
//! ([`crate::pose::ArmFitter`]) puts the model's links ([`crate::pose::ArmModel`]). The
//! tracker knows nothing of datasets: a human model, its base pose, a camera and frames.

use std::ops::Range;

use workcell_procnet::ProcNet;
use workcell_procnet::image::{planar_rgb, planar_rgb_crop, resample};
use workcell_render::roi::{self, Roi, RoiKind};
use workcell_render::{Camera, Class, CpuRenderer};
use workcell_robots::collision::{LinkCapsule, end_away_from, link_bounding_capsule};
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{HumanPart, RobotModel, Side};

use crate::error::{PerceptionError, Result};
use crate::pose::{
    ArmFit, ArmFitConfig, ArmFitter, ArmMasks, ArmModel, ArticulatedArm, NoPose, PartCapsule,
};

/// What the tracker knows of the arm in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmEstimate {
    /// Each part of the arm in the world, [`HumanPart::ARM`] order, not inflated.
    pub parts: Vec<PartCapsule>,
    /// The radius by which every capsule is to be inflated, m.
    pub uncertainty_m: f64,
    /// The forearm link's frame in the world.
    pub X_WF: Pose,
    /// The articulated fit behind it (joint angles, scores, renders), in the frame of the
    /// region of interest's camera.
    pub fit: ArmFit,
}

/// Why a frame gave no estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoEstimate {
    /// The masks gave no pose (nothing seen, values that are not probabilities, no
    /// configuration of the arm that explains them).
    NoPose(NoPose),
    /// The camera delivered no frame.
    NoFrame,
}

impl std::fmt::Display for NoEstimate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NoEstimate::NoPose(reason) => write!(f, "no arm pose: {reason}"),
            NoEstimate::NoFrame => write!(f, "the camera delivered no frame"),
        }
    }
}

/// The result of one frame: an estimate, or why there is none.
pub type ArmOutcome = std::result::Result<ArmEstimate, NoEstimate>;

/// Frames of one camera in, arm estimates out: ProcNet's mask of every arm part in the
/// frame's region of interest, the articulated fit ([`ArmFitter`]) tracking the human
/// model's joints from frame to frame, and each part's collision capsule where the fitted
/// joints put it. With a depth image the depth agreement joins the fit.
///
/// ```no_run
/// # use workcell_perception::ArmTracker;
/// # use workcell_perception::pose::{ArmFitConfig, Calibration};
/// # use workcell_procnet::{Backend, ProcNet};
/// # fn run(human: workcell_robots::RobotModel, X_WH: workcell_robots::math::Pose,
/// #        camera: workcell_render::Camera, rgb: &[u8]) -> workcell_perception::Result<()> {
/// let weights = std::path::Path::new("procnet/weights/procnet-cpu.safetensors");
/// // The bound calibrated for these weights (the file beside them), for a fit of RGB alone.
/// let fit = Calibration::of_weights(weights, false)?.calibration.apply(ArmFitConfig::default());
/// let net = ProcNet::load(weights, Backend::Flex)?;
/// let mut tracker = ArmTracker::new(&human, &X_WH, fit)?.with_network(net)?;
/// match tracker.track(&camera, rgb, None)? {
///     Ok(estimate) => println!("{} parts, +-{:.3} m", estimate.parts.len(), estimate.uncertainty_m),
///     Err(reason) => println!("no estimate: {reason}"),
/// }
/// # Ok(())
/// # }
/// ```
pub struct ArmTracker {
    arm: ArmModel,
    fitter: ArmFitter<CpuRenderer>,
    /// Each fitted part's collision capsule in its link's frame.
    capsules: [Option<LinkCapsule>; 3],
    net: Option<ProcNet>,
    /// The last estimate's shoulder, elbow, wrist and the hand's far end: the next region
    /// of interest follows them.
    joints_W: Option<[Vector; 4]>,
    /// The last pose's region cut the arm ([`CUT_RING_PX`]): the next frame reads the
    /// workspace.
    cut: bool,
    /// The shoulder of the last pose, kept when the track is lost: where a human whose trunk
    /// moves was last seen, the centre of the workspace crop.
    last_shoulder_W: Option<Vector>,
    /// Frames in a row with a pose (a held frame, [`HOLD_REGION`], keeps the count): the
    /// region follows the arm from [`CONFIRM_POSES`] on.
    streak: usize,
    /// Frames in a row without a pose while the region still follows the last estimate
    /// (at most [`HOLD_REGION`]).
    held: usize,
    /// The focal length, px, of the last region the network read: a region of another
    /// scale is another view, and the network's memory of the last one is dropped.
    last_fx: Option<f64>,
}

/// A region whose scale differs from the last one's by more than this factor is another view.
pub const VIEW_JUMP: f64 = 1.25;

/// Whether a region seen at focal length `fx` (px) is another view than the last one, seen
/// at `last_fx`: its scale differs by more than [`VIEW_JUMP`]. A recurrent network's memory
/// of the last view is then of other pixels, and it starts afresh.
#[must_use]
pub fn view_jump(last_fx: Option<f64>, fx: f64) -> bool {
    last_fx.is_some_and(|last| (fx / last).ln().abs() > VIEW_JUMP.ln())
}

/// The band along the tracked region's edge, px of [`DEFAULT_INPUT_PX`], in which masks
/// tell that the region cut the arm: the next frame reads the workspace, which holds the
/// whole reach. The region around the last pose's shoulder, elbow and wrist cut the arm where
/// the hand's masks reach its edge ([`HAND_CUT_MASS_PX`]) and the fitted hand does not
/// (its far end projects inside the region): the fit lost the hand, and a region around its
/// own wrong wrist kept the true forearm outside for seconds (on a recorded clip 92 of 361
/// fits with true masks, the hand 0.39 m off), so the next frame's fit also runs the global
/// search beside the track ([`ArmFitter::search_next`]), which a track of a good gain does
/// not call. An arm held out, its hand past the edge in the fit as in the masks, is not cut.
/// With [`ArmFitConfig::hand_region`] the region holds the hand too, and the forearm's or
/// the hand's masks at its edge cut it ([`CUT_MASS_PX`]; docs/perception.md, "The region
/// that cut the arm").
pub const CUT_RING_PX: usize = 2;
/// With [`ArmFitConfig::hand_region`], the forearm's and hand's mass in [`CUT_RING_PX`]'s
/// band from which the region cut the arm, pixels' worth of probability.
pub const CUT_MASS_PX: f64 = 3.0;
/// Around shoulder, elbow and wrist, the hand's mass in [`CUT_RING_PX`]'s band from which
/// the region cut the arm (where the fitted hand does not reach the edge), pixels' worth of
/// probability. In the trap the band held 36 (median) on a recorded clip; where the whole
/// arm was inside, at most 21, and 3 sent a third of those frames to the workspace for
/// nothing (docs/perception.md, "The region that cut the arm").
pub const HAND_CUT_MASS_PX: f64 = 20.0;

/// Poses in a row before the region of interest follows the arm. A network that has just
/// started on a view can give a confident pose of the wrong arm; a crop around it would
/// keep the real one out of view for frames on end (measured: experiments/perception.md, "The
/// deployed tracker's own crops").
pub const CONFIRM_POSES: usize = 2;

/// Frames without a pose for which the region keeps following the arm's last estimate
/// before it falls back to the workspace. The network's first frames of a tracked crop can
/// miss a far arm that its next frame finds; falling back at once starts it afresh on the
/// workspace crop and then on the tracked one again (measured: experiments/perception.md, "A new
/// view read three times").
pub const HOLD_REGION: usize = 1;

/// The side of the region of interest's image the fit reads (the networks' masks are
/// resampled to it): the size of the datasets' stored regions.
pub const DEFAULT_INPUT_PX: usize = 128;

/// A frame's arm as the tracker's network sees it: the region of interest, the camera that
/// sees exactly that region at [`DEFAULT_INPUT_PX`], and the masks there.
#[derive(Debug, Clone, PartialEq)]
pub struct RoiMasks {
    pub roi: Roi,
    pub camera: Camera,
    pub masks: ArmMasks,
}

impl ArmTracker {
    /// A tracker of the arm of `human` (in the look it is seen in: its visuals are what the
    /// fit renders) standing with its base at `X_WH`, without a network: give it masks
    /// ([`ArmTracker::track_masks`]).
    ///
    /// # Errors
    /// As [`ArmModel::new`] and [`ArticulatedArm::new`].
    pub fn new(human: &RobotModel, X_WH: &Pose, config: ArmFitConfig) -> Result<Self> {
        Self::of_side(human, X_WH, config, Side::Right)
    }

    /// A tracker of the arm on `side` of `human` (the left arm: its own parts and classes,
    /// [`ArticulatedArm::of_side`]); otherwise as [`ArmTracker::new`].
    ///
    /// # Errors
    /// As [`ArmTracker::new`].
    pub fn of_side(
        human: &RobotModel,
        X_WH: &Pose,
        config: ArmFitConfig,
        side: Side,
    ) -> Result<Self> {
        let arm = ArmModel::of_side(human, X_WH, side)?;
        let articulated = ArticulatedArm::of_side(human, X_WH, side)?;
        let capsules = articulated
            .part_links()
            .map(|l| link_bounding_capsule(human, l));
        Ok(Self {
            arm,
            fitter: ArmFitter::new(CpuRenderer::new(), articulated, config),
            capsules,
            net: None,
            joints_W: None,
            cut: false,
            last_shoulder_W: None,
            streak: 0,
            held: 0,
            last_fx: None,
        })
    }

    /// The same tracker segmenting frames with `net` ([`ArmTracker::track`]).
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when the network has no class for the arm's forearm.
    pub fn with_network(mut self, net: ProcNet) -> Result<Self> {
        let forearm = Class::of_part(self.fitter.arm().parts()[1]);
        if net.config().class_index(forearm).is_none() {
            return Err(PerceptionError::Input {
                message: format!(
                    "the network has no {forearm} class (it has {:?})",
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

    /// The articulated arm it fits.
    #[must_use]
    pub fn articulated(&self) -> &ArticulatedArm {
        self.fitter.arm()
    }

    /// The network, if it has one.
    #[must_use]
    pub fn network(&self) -> Option<&ProcNet> {
        self.net.as_ref()
    }

    /// Holds the trunk where the model's configuration `q` puts it for the next frames
    /// ([`ArmFitter::hold_trunk_at`]): a trunk known from elsewhere, for the bound of a
    /// perfect trunk. Returns whether the model has a trunk.
    ///
    /// # Errors
    /// As [`ArmFitter::hold_trunk_at`].
    pub fn hold_trunk_at(&mut self, q: &[f64]) -> Result<bool> {
        self.fitter.hold_trunk_at(q)
    }

    /// Forgets the track and the network's state (a new camera stream).
    pub fn reset(&mut self) {
        self.fitter.reset();
        self.joints_W = None;
        self.cut = false;
        self.last_shoulder_W = None;
        self.streak = 0;
        self.held = 0;
        self.last_fx = None;
        if let Some(net) = &mut self.net {
            net.reset();
        }
    }

    /// The region of `camera`'s image the next frame is read through: around the last
    /// estimate's shoulder, elbow and wrist ([`Roi::of_joints`], the middle of
    /// [`roi::TRACKED_MARGIN`]; and the hand's far end with
    /// [`ArmFitConfig::hand_region`]) once [`CONFIRM_POSES`] frames in a row gave a
    /// pose (and for [`HOLD_REGION`] frames without one after that), unless the last pose's
    /// region cut the arm ([`CUT_RING_PX`]), else the sphere the forearm can reach
    /// ([`Roi::of_sphere`]) around the shoulder (for a human whose trunk moves, the last
    /// pose's shoulder, before any pose the shoulder at rest), else the whole frame.
    #[must_use]
    pub fn roi(&self, camera: &Camera) -> Roi {
        self.region(camera).0
    }

    /// [`ArmTracker::roi`] and which of the three it is.
    #[must_use]
    pub fn region(&self, camera: &Camera) -> (Roi, RoiKind) {
        let margin = 0.5 * (roi::TRACKED_MARGIN[0] + roi::TRACKED_MARGIN[1]);
        let points = if self.fitter.config().hand_region {
            4
        } else {
            3
        };
        self.joints_W
            .filter(|_| self.streak >= CONFIRM_POSES && !self.cut)
            .and_then(|joints| {
                Roi::of_joints(camera, &joints[..points], margin, roi::TRACKED_MIN_M)
            })
            .map(|r| (r, RoiKind::Tracked))
            .or_else(|| {
                let shoulder = match self.arm.shoulder_W {
                    Some((fixed, _)) => fixed,
                    None => self.last_shoulder_W.unwrap_or(self.arm.rest_shoulder_W.0),
                };
                Roi::of_sphere(camera, shoulder, self.arm.reach_m()?, roi::WORKSPACE_MARGIN)
                    .map(|r| (r, RoiKind::Workspace))
            })
            .unwrap_or((Roi::frame(camera.width, camera.height), RoiKind::Frame))
    }

    /// The network's masks of a frame: the region of interest ([`ArmTracker::roi`])
    /// resampled to [`DEFAULT_INPUT_PX`], segmented (at the network's input size), every
    /// class's plane back at [`DEFAULT_INPUT_PX`]. `depth_m` is the depth camera's image
    /// registered to `camera` ([`ArmTracker::track`]); a network that reads depth needs it,
    /// and the masks carry the region's depth for the fit.
    ///
    /// # Errors
    /// No network ([`ArmTracker::with_network`]), images of the wrong size, no depth image
    /// for a network that reads depth, a network failure.
    pub fn segment(
        &mut self,
        camera: &Camera,
        rgb: &[u8],
        depth_m: Option<&[f32]>,
    ) -> Result<RoiMasks> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        check_len("an sRGB frame", rgb.len(), 3 * w * h, camera)?;
        if let Some(d) = depth_m {
            check_len("a depth image", d.len(), w * h, camera)?;
        }
        let roi = self.roi(camera);
        let s = DEFAULT_INPUT_PX;
        let size = roi.size as usize;
        let input = resample(&planar_rgb_crop(rgb, w, h, &roi), 3, size, size, s, s);
        let depth = depth_m.map(|d| roi.sample_nearest(d, w, h, s));
        let roi_camera = roi.camera(camera, s as u32)?;
        let mut masks = self.segment_planar(&roi_camera, &input, depth.as_deref())?;
        masks.depth_m = depth;
        Ok(RoiMasks {
            roi,
            masks,
            camera: roi_camera,
        })
    }

    /// The network's masks of a region already cut out at [`DEFAULT_INPUT_PX`]: `planar`
    /// sRGB values scaled to [0, 1], `3 x side x side`, and the region's depth image.
    fn segment_planar(
        &mut self,
        roi_camera: &Camera,
        planar: &[f32],
        depth_m: Option<&[f32]>,
    ) -> Result<ArmMasks> {
        let net = self.net.as_mut().ok_or_else(|| PerceptionError::Input {
            message: "this tracker has no network; give it masks with track_masks".into(),
        })?;
        let s = DEFAULT_INPUT_PX;
        let input = workcell_procnet::data::input_frame(planar, depth_m, s, s, net.config())?;
        let planar = &*input;
        // A stream's first frame is a new view too.
        if self.last_fx.is_none() || view_jump(self.last_fx, roi_camera.fx) {
            net.start_view(planar, s, s)?;
        }
        self.last_fx = Some(roi_camera.fx);
        let planes = net.planes(planar, s, s)?;
        let refs: Vec<(Class, &[f32])> = planes.iter().map(|(c, p)| (*c, p.as_slice())).collect();
        ArmMasks::from_planes_of(self.fitter.arm().parts(), s, s, &refs)
    }

    /// One frame already read through the region of interest the tracker asked for
    /// ([`ArmTracker::roi`]): what a camera that crops on the sensor, or a renderer that
    /// draws only that region, delivers. `rgb` is interleaved sRGB bytes of `roi_camera`
    /// (the camera that sees exactly the region at [`DEFAULT_INPUT_PX`] pixels a side,
    /// [`Roi::camera`]), `depth_m` its depth image.
    ///
    /// # Errors
    /// No network, a camera not [`DEFAULT_INPUT_PX`] square, images of the wrong size, a
    /// network failure.
    pub fn track_region(
        &mut self,
        roi_camera: &Camera,
        rgb: &[u8],
        depth_m: Option<&[f32]>,
    ) -> Result<ArmOutcome> {
        let s = DEFAULT_INPUT_PX;
        if (roi_camera.width as usize, roi_camera.height as usize) != (s, s) {
            return Err(PerceptionError::Input {
                message: format!(
                    "a region's camera of {}x{}, not the {s}x{s} the tracker reads",
                    roi_camera.width, roi_camera.height
                ),
            });
        }
        check_len("an sRGB frame", rgb.len(), 3 * s * s, roi_camera)?;
        if let Some(d) = depth_m {
            check_len("a depth image", d.len(), s * s, roi_camera)?;
        }
        let planar = planar_rgb(rgb, s, s);
        let mut masks = self.segment_planar(roi_camera, &planar, depth_m)?;
        masks.depth_m = depth_m.map(<[f32]>::to_vec);
        self.track_roi(roi_camera, &masks)
    }

    /// One frame: interleaved sRGB bytes (`width * height * 3`, row-major from the top left)
    /// from `camera`, whose pose in the world is known, and optionally the depth camera's
    /// image registered to it (camera-frame z, m, `width * height`; 0 where it has none).
    ///
    /// # Errors
    /// As [`ArmTracker::segment`]; a depth image of the wrong size.
    pub fn track(
        &mut self,
        camera: &Camera,
        rgb: &[u8],
        depth_m: Option<&[f32]>,
    ) -> Result<ArmOutcome> {
        let RoiMasks {
            camera: roi_camera,
            masks,
            ..
        } = self.segment(camera, rgb, depth_m)?;
        self.track_roi(&roi_camera, &masks)
    }

    /// One frame given as masks at the camera's resolution (a perfect segmenter's, or
    /// another network's), read through the region of interest as [`ArmTracker::track`]
    /// reads a frame: every plane resampled to [`DEFAULT_INPUT_PX`] (the depth sampled at
    /// each pixel's centre, [`Roi::sample_nearest`]).
    ///
    /// # Errors
    /// [`PerceptionError::Input`] for masks that are not the camera's size; renderer failures.
    pub fn track_masks(&mut self, camera: &Camera, masks: &ArmMasks) -> Result<ArmOutcome> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        if (masks.width, masks.height) != (w, h) {
            return Err(PerceptionError::Input {
                message: format!(
                    "masks of {}x{} for the {w}x{h} camera",
                    masks.width, masks.height
                ),
            });
        }
        let roi = self.roi(camera);
        let s = DEFAULT_INPUT_PX;
        let crop = |plane: &[f32]| -> Result<Vec<f32>> {
            check_len("a mask", plane.len(), w * h, camera)?;
            Ok(roi.resample(plane, 1, w, h, s))
        };
        let cropped = ArmMasks {
            width: s,
            height: s,
            parts: [
                crop(&masks.parts[0])?,
                crop(&masks.parts[1])?,
                crop(&masks.parts[2])?,
            ],
            background: crop(&masks.background)?,
            torso: if masks.torso.is_empty() {
                Vec::new()
            } else {
                crop(&masks.torso)?
            },
            depth_m: match masks.depth_m.as_deref() {
                Some(d) => {
                    check_len("a depth image", d.len(), w * h, camera)?;
                    Some(roi.sample_nearest(d, w, h, s))
                }
                None => None,
            },
        };
        self.track_roi(&roi.camera(camera, s as u32)?, &cropped)
    }

    /// A frame the camera did not deliver: no estimate. The track is kept; the next frame
    /// predicts from it.
    pub fn no_frame(&mut self) -> ArmOutcome {
        Err(NoEstimate::NoFrame)
    }

    /// One frame given as masks already in the region of interest's camera (what
    /// [`ArmTracker::segment`] returns, with the depth there if there is one).
    ///
    /// # Errors
    /// As [`ArmFitter::fit`].
    pub fn track_roi(&mut self, camera: &Camera, masks: &ArmMasks) -> Result<ArmOutcome> {
        let fit = match self.fitter.fit(camera, masks)? {
            Ok(fit) => fit,
            Err(reason) => {
                if self.streak >= CONFIRM_POSES && self.held < HOLD_REGION {
                    self.held += 1;
                } else {
                    self.joints_W = None;
                    self.streak = 0;
                    self.held = 0;
                }
                return Ok(Err(NoEstimate::NoPose(reason)));
            }
        };
        let X_WL = self.fitter.arm().part_poses(&fit.q, &Pose::IDENTITY)?;
        let arm_parts = self.fitter.arm().parts();
        let parts: Vec<PartCapsule> = arm_parts
            .iter()
            .zip(&self.capsules)
            .zip(&X_WL)
            .filter_map(|((&part, capsule), X)| {
                let c = capsule.as_ref()?;
                let (a_W, b_W) = c.segment_in_world(X);
                Some(PartCapsule {
                    part,
                    a_W,
                    b_W,
                    radius_m: c.radius_m,
                })
            })
            .collect();
        // Each capsule's end away from the elbow: the forearm's is the wrist; the hand's
        // far end, as the wrist alone leaves the hand of an arm held out at the region's
        // edge, cut.
        let elbow = X_WL[1].translation;
        let away = |part: HumanPart| {
            parts
                .iter()
                .find(|p| p.part == part)
                .map(|p| end_away_from(p.a_W, p.b_W, elbow))
        };
        let wrist = away(arm_parts[1]).unwrap_or(X_WL[2].translation);
        let hand = away(arm_parts[2]).unwrap_or(wrist);
        self.joints_W = Some([X_WL[0].translation, X_WL[1].translation, wrist, hand]);
        self.cut = if self.fitter.config().hand_region {
            edge_mass(masks, CUT_RING_PX, FOREARM_AND_HAND) >= CUT_MASS_PX
        } else {
            // The masks reach the edge where the fit does not: the track is wrong, and the
            // next frame's fit searches beside it.
            let lost = edge_mass(masks, CUT_RING_PX, HAND) >= HAND_CUT_MASS_PX
                && inside_px(camera, hand) >= 0.0;
            if lost {
                self.fitter.search_next();
            }
            lost
        };
        self.last_shoulder_W = Some(X_WL[0].translation);
        self.streak += 1;
        self.held = 0;
        Ok(Ok(ArmEstimate {
            parts,
            uncertainty_m: fit.uncertainty_m,
            X_WF: X_WL[1],
            fit,
        }))
    }
}

/// How far inside `camera`'s image `p_W` projects, px to the nearest edge (negative:
/// outside; minus infinity behind the camera).
fn inside_px(camera: &Camera, p_W: Vector) -> f64 {
    let p_C = camera.X_WC.inverse().transform_point(p_W);
    camera.project(p_C).map_or(f64::NEG_INFINITY, |[u, v]| {
        u.min(v)
            .min(f64::from(camera.width) - u)
            .min(f64::from(camera.height) - v)
    })
}

/// The hand's plane of [`ArmMasks::parts`].
const HAND: Range<usize> = 2..3;
/// The forearm's and hand's planes of [`ArmMasks::parts`].
const FOREARM_AND_HAND: Range<usize> = 1..3;

/// The probability mass of the `parts` planes in the band `ring` px wide along the masks'
/// edge.
fn edge_mass(masks: &ArmMasks, ring: usize, parts: Range<usize>) -> f64 {
    let (w, h) = (masks.width, masks.height);
    let mut m = 0.0;
    for plane in &masks.parts[parts] {
        for (y, row) in plane.chunks_exact(w.max(1)).enumerate().take(h) {
            for (x, &v) in row.iter().enumerate() {
                if x < ring || y < ring || x + ring >= w || y + ring >= h {
                    m += f64::from(v);
                }
            }
        }
    }
    m
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
    use std::sync::Arc;

    use super::*;
    use crate::pose::FITTED_PARTS;
    use workcell_render::RenderMesh;
    use workcell_render::Renderer as _;
    use workcell_robots::math::pose_from_xyz_rpy;

    /// The built-in human in its default (flesh) look.
    fn human() -> RobotModel {
        let mut human = RobotModel::from_catalogue("human_arm").expect("catalogue human");
        human.retain_visuals(|g| workcell_robots::HumanLook::Flesh.shows(g.name.as_deref()));
        human
    }

    /// A camera looking at the shoulder of a human at `X_WH` from `offset` away.
    fn camera_at(arm: &ArmModel, offset: Vector, size: [u32; 2], fov_deg: f64) -> Camera {
        let (shoulder, _) = arm.shoulder_W.expect("fixed shoulder");
        Camera::look_at(
            (shoulder + offset).to_array(),
            (shoulder - Vector::new(0.0, 0.0, 0.2)).to_array(),
            [0.0, 0.0, 1.0],
            size[0],
            size[1],
            fov_deg,
        )
        .expect("camera")
    }

    /// What a perfect segmenter and a depth camera give of `human`'s arm at `q`: the three
    /// parts rendered together (z-buffered) as masks, with the depth image.
    fn observe(human: &RobotModel, tracker: &ArmTracker, camera: &Camera, q: &[f64]) -> ArmMasks {
        let arm = tracker.articulated();
        let poses = arm.part_poses(q, &Pose::IDENTITY).expect("poses");
        let mut scene = workcell_render::Scene::default();
        for (p, part) in FITTED_PARTS.into_iter().enumerate() {
            let mut mesh = RenderMesh::default();
            for g in &human.links()[arm.part_links()[p]].visuals {
                mesh.append(
                    &RenderMesh::from_geometry(g, [0.8, 0.7, 0.6]),
                    &Pose::IDENTITY,
                );
            }
            scene.push(workcell_render::SceneObject {
                name: part.name().into(),
                class: Class::of_part(part),
                mesh: Arc::new(mesh),
                texture: 0.0,
                X_WO: poses[p],
            });
        }
        let mut frame = workcell_render::Frame::new();
        CpuRenderer::new()
            .render(&scene, camera, &mut frame)
            .expect("render");
        let (w, h) = (camera.width as usize, camera.height as usize);
        let mut masks = ArmMasks::from_classes(&frame.classes(&scene), w, h).expect("masks");
        masks.depth_m = Some(frame.depth_m.clone());
        masks
    }

    /// Bad input is an error (a frame or masks of the wrong size) or no estimate with its
    /// reason (nothing seen, values that are not probabilities, no frame); never a panic.
    #[test]
    fn bad_input_is_an_error_or_no_estimate_with_its_reason() {
        let human = human();
        let mut tracker =
            ArmTracker::new(&human, &Pose::IDENTITY, ArmFitConfig::default()).expect("tracker");
        let camera = camera_at(tracker.arm(), Vector::new(3.0, 0.0, 0.0), [64, 48], 50.0);
        let err = tracker.track(&camera, &[0; 10], None).unwrap_err();
        assert!(
            err.to_string().contains("9216 values for the 64x48"),
            "{err}"
        );
        let err = tracker
            .track(&camera, &vec![0; 64 * 48 * 3], None)
            .unwrap_err();
        assert!(err.to_string().contains("no network"), "{err}");
        let err = tracker
            .track(&camera, &vec![0; 64 * 48 * 3], Some(&[1.0; 5]))
            .unwrap_err();
        assert!(err.to_string().contains("a depth image of 3072"), "{err}");
        // A fully hidden arm: empty masks.
        let empty = ArmMasks::from_classes(&vec![0; 64 * 48], 64, 48).expect("masks");
        let outcome = tracker.track_masks(&camera, &empty).expect("no error");
        assert_eq!(outcome, Err(NoEstimate::NoPose(NoPose::Empty)));
        // NaN from a network.
        let mut nan = empty.clone();
        nan.parts[1][64 * 24 + 32] = f32::NAN;
        let outcome = tracker.track_masks(&camera, &nan).expect("no error");
        assert_eq!(outcome, Err(NoEstimate::NoPose(NoPose::NotAProbability)));
        // Masks of another size.
        let small = ArmMasks::from_classes(&[0; 12], 4, 3).expect("masks");
        let err = tracker.track_masks(&camera, &small).unwrap_err();
        assert!(err.to_string().contains("4x3 for the 64x48"), "{err}");
        assert_eq!(tracker.no_frame(), Err(NoEstimate::NoFrame));
    }

    /// Blobs of every arm class scattered over the frame, where no arm could put its parts,
    /// are no pose: the fit explains too little of them.
    #[test]
    fn scattered_blobs_no_arm_explains_are_no_estimate() {
        let human = human();
        let mut tracker =
            ArmTracker::new(&human, &Pose::IDENTITY, ArmFitConfig::default()).expect("tracker");
        let camera = camera_at(tracker.arm(), Vector::new(3.0, 0.0, 0.0), [160, 120], 50.0);
        let (w, h) = (160, 120);
        let mut classes = vec![0u8; w * h];
        let parts = [Class::UpperArm, Class::Forearm, Class::Hand];
        for k in 0..12 {
            let (cx, cy) = ((k * 53) % w, (k * 37 + 11) % h);
            for y in cy.saturating_sub(2)..(cy + 2).min(h) {
                for x in cx.saturating_sub(2)..(cx + 2).min(w) {
                    classes[y * w + x] = parts[k % 3] as u8;
                }
            }
        }
        let masks = ArmMasks::from_classes(&classes, w, h).expect("masks");
        let outcome = tracker.track_masks(&camera, &masks).expect("no error");
        assert_eq!(outcome, Err(NoEstimate::NoPose(NoPose::PoorFit)));
    }

    /// The built-in human's arm, a tracker of it with `config`, a camera that sees it and
    /// the workspace region through which that camera's first frame is read.
    fn arm_in_view(config: ArmFitConfig) -> (RobotModel, Pose, ArmTracker, Camera, Roi) {
        let human = human();
        let X_WH = pose_from_xyz_rpy([0.9, -0.3, 0.0], [0.0, 0.0, 0.7]);
        let tracker = ArmTracker::new(&human, &X_WH, config).expect("tracker");
        let arm = tracker.arm();
        let (shoulder, _) = arm.shoulder_W.expect("fixed shoulder");
        let reach = arm.reach_m().expect("reach");
        let camera = camera_at(arm, Vector::new(1.6, 1.7, 0.3), [640, 480], 55.0);
        let workspace = Roi::of_sphere(&camera, shoulder, reach, roi::WORKSPACE_MARGIN).unwrap();
        (human, X_WH, tracker, camera, workspace)
    }

    /// The loop's conventions end to end: masks and depth of the arm at a configuration,
    /// through the region of interest, back as each part's collision capsule in the world
    /// where the model puts it at that configuration; the region then follows the arm and a
    /// lost track falls back to the workspace.
    #[test]
    fn the_tracker_finds_each_part_where_the_model_puts_it() {
        let (human, X_WH, mut tracker, camera, workspace) = arm_in_view(ArmFitConfig::default());
        assert_eq!(tracker.roi(&camera), workspace);
        let q = [0.5, 0.9, 1.1];
        let masks = observe(&human, &tracker, &camera, &q);
        tracker
            .track_masks(&camera, &masks)
            .expect("track")
            .expect("an estimate");
        // One pose is not yet a track to follow.
        assert_eq!(tracker.region(&camera), (workspace, RoiKind::Workspace));
        assert_eq!(CONFIRM_POSES, 2);
        let estimate = tracker
            .track_masks(&camera, &masks)
            .expect("track")
            .expect("an estimate");
        let k = human.fk(X_WH, &q).expect("fk");
        let order: Vec<HumanPart> = estimate.parts.iter().map(|p| p.part).collect();
        assert_eq!(order, HumanPart::ARM);
        for p in &estimate.parts {
            let link = human.link_id(p.part.link_name()).expect("link");
            let c = link_bounding_capsule(&human, link).expect("capsule");
            assert!((p.radius_m - c.radius_m).abs() < 1e-15, "{p:?}");
            let (a, b) = c.segment_in_world(k.link_pose(link));
            // 2.4 m away, RGB-D through a 128x128 region: within 3 cm.
            for (x, y) in [(p.a_W, a), (p.b_W, b)] {
                assert!((x - y).length() < 0.03, "{p:?}: {x} vs {y}");
            }
        }
        assert!(estimate.uncertainty_m > 0.0 && estimate.uncertainty_m.is_finite());
        // The region now holds the arm's joints and is smaller than the workspace's.
        let (tracked, kind) = tracker.region(&camera);
        assert_eq!(kind, RoiKind::Tracked);
        assert!(tracked.size < workspace.size, "{tracked:?}");
        let [u, v] = camera
            .project(camera.X_WC.inverse() * estimate.X_WF.translation)
            .expect("in front");
        let inside = |x: f64, x0: i64| x >= x0 as f64 && x <= (x0 + i64::from(tracked.size)) as f64;
        assert!(inside(u, tracked.x0) && inside(v, tracked.y0));
        // A frame without a pose keeps the region for HOLD_REGION frames; a track lost for
        // longer falls back to the workspace.
        let empty = ArmMasks::from_classes(&vec![0; 640 * 480], 640, 480).expect("masks");
        assert_eq!(HOLD_REGION, 1);
        let mut lose = || {
            tracker
                .track_masks(&camera, &empty)
                .expect("no error")
                .expect_err("no arm in empty masks");
            tracker.region(&camera)
        };
        assert_eq!(lose(), (tracked, RoiKind::Tracked));
        assert_eq!(lose(), (workspace, RoiKind::Workspace));
        // The pose's shoulder is remembered through the loss (a fixed shoulder's workspace
        // does not read it).
        let last = tracker.last_shoulder_W.expect("the last pose's shoulder");
        let (shoulder, _) = tracker.arm().shoulder_W.expect("fixed shoulder");
        assert!((last - shoulder).length() < 0.03, "{last} vs {shoulder}");
    }

    /// With the hand held in the region: the region holds the hand's far end, and an arm
    /// that moves out of the region it was read through, its forearm and hand at the
    /// region's edge, sends the next frame to the workspace, which holds the whole reach;
    /// once its masks are whole again the region follows the arm. Without it the region
    /// stays around the last pose's shoulder, elbow and wrist.
    #[test]
    fn an_arm_the_region_cuts_is_read_through_the_workspace_next() {
        let holding = ArmFitConfig {
            hand_region: true,
            ..ArmFitConfig::default()
        };
        let (human, X_WH, mut tracker, camera, workspace) = arm_in_view(holding);
        let mut plain = ArmTracker::new(&human, &X_WH, ArmFitConfig::default()).expect("tracker");
        // Bent: the region follows the arm after two poses, and it holds the whole arm.
        let bent = observe(&human, &tracker, &camera, &[0.0, 0.3, 1.6]);
        for _ in 0..CONFIRM_POSES {
            tracker
                .track_masks(&camera, &bent)
                .expect("track")
                .expect("an estimate");
        }
        let (tracked, kind) = tracker.region(&camera);
        assert_eq!(kind, RoiKind::Tracked);
        assert!(!tracker.cut);
        let hand = |e: &ArmEstimate| {
            *(e.parts.iter().find(|p| p.part == HumanPart::Hand)).expect("a hand")
        };
        let estimate = tracker
            .track_masks(&camera, &bent)
            .expect("track")
            .expect("a pose");
        let h = hand(&estimate);
        for end in [h.a_W, h.b_W] {
            let p = camera
                .project(camera.X_WC.inverse() * end)
                .expect("in front");
            assert!(tracked.contains(p), "{end} vs {tracked:?}");
        }
        // Stretched out: through that region the forearm and hand reach its edge.
        let q = [0.6, 1.0, 0.5];
        let stretched = observe(&human, &tracker, &camera, &q);
        let (w, h) = (640, 480);
        let crop = ArmMasks {
            width: DEFAULT_INPUT_PX,
            height: DEFAULT_INPUT_PX,
            parts: stretched
                .parts
                .clone()
                .map(|p| tracked.resample(&p, 1, w, h, DEFAULT_INPUT_PX)),
            background: tracked.resample(&stretched.background, 1, w, h, DEFAULT_INPUT_PX),
            torso: Vec::new(),
            depth_m: None,
        };
        assert!(
            edge_mass(&crop, CUT_RING_PX, FOREARM_AND_HAND) >= CUT_MASS_PX,
            "the arm is not cut"
        );
        tracker
            .track_masks(&camera, &stretched)
            .expect("track")
            .expect("an estimate");
        assert!(tracker.cut);
        assert_eq!(tracker.region(&camera), (workspace, RoiKind::Workspace));
        // Without the hand held the region is drawn around shoulder, elbow and wrist, and it
        // cuts the stretched arm too: the hand's masks reach its edge, and the pose fitted
        // through it keeps the hand inside.
        for _ in 0..CONFIRM_POSES {
            plain
                .track_masks(&camera, &bent)
                .expect("track")
                .expect("a pose");
        }
        let (around_joints, kind) = plain.region(&camera);
        assert_eq!(kind, RoiKind::Tracked);
        assert_ne!(around_joints, tracked);
        plain
            .track_masks(&camera, &stretched)
            .expect("track")
            .expect("a pose");
        assert_eq!(plain.region(&camera).1, RoiKind::Workspace);
        // Read whole through the workspace, the pose is found and the region follows it.
        let estimate = tracker
            .track_masks(&camera, &stretched)
            .expect("track")
            .expect("an estimate");
        assert!(!tracker.cut);
        let (follows, kind) = tracker.region(&camera);
        assert_eq!(kind, RoiKind::Tracked);
        assert_ne!(follows, tracked);
        let k = human.fk(X_WH, &q).expect("fk");
        let hand = hand(&estimate);
        let link = human.link_id(HumanPart::Hand.link_name()).expect("link");
        let c = link_bounding_capsule(&human, link).expect("capsule");
        let (a, b) = c.segment_in_world(k.link_pose(link));
        let off = [(hand.a_W - a).length(), (hand.b_W - b).length()];
        assert!(off[0] < 0.03 && off[1] < 0.03, "{off:?}");
    }

    /// Around shoulder, elbow and wrist, a frame whose hand masks reach the region's edge
    /// where the fitted hand does not (the fit lost the hand, and the region follows its wrong
    /// wrist) sends the next frame to the workspace; the same masks without the hand at the
    /// edge keep the region on the arm.
    #[test]
    fn a_hand_at_the_edge_the_fit_does_not_reach_sends_the_next_frame_to_the_workspace() {
        let (human, _, mut tracker, camera, workspace) = arm_in_view(ArmFitConfig::default());
        let bent = observe(&human, &tracker, &camera, &[0.0, 0.3, 1.6]);
        for _ in 0..=CONFIRM_POSES {
            tracker
                .track_masks(&camera, &bent)
                .expect("track")
                .expect("a pose");
        }
        let (tracked, kind) = tracker.region(&camera);
        assert_eq!(kind, RoiKind::Tracked);
        assert!(!tracker.cut);
        // A hand's worth of mask along the region's left edge, a fifth of its side long, in
        // the middle: nothing the bent arm's pose explains.
        let mut stray = bent.clone();
        let (w, h) = (640_i64, 480_i64);
        let band = (2 * CUT_RING_PX as u32 * tracked.size).div_ceil(DEFAULT_INPUT_PX as u32);
        let band = i64::from(band);
        let side = i64::from(tracked.size);
        for y in tracked.y0 + 2 * side / 5..tracked.y0 + 3 * side / 5 {
            for x in tracked.x0..tracked.x0 + band {
                if (0..w).contains(&x) && (0..h).contains(&y) {
                    let i = (y * w + x) as usize;
                    stray.parts[2][i] = 1.0;
                    stray.background[i] = 0.0;
                }
            }
        }
        let estimate = tracker
            .track_masks(&camera, &stray)
            .expect("track")
            .expect("a pose");
        let hand = estimate
            .parts
            .iter()
            .find(|p| p.part == HumanPart::Hand)
            .expect("a hand");
        for end in [hand.a_W, hand.b_W] {
            let p = camera
                .project(camera.X_WC.inverse() * end)
                .expect("in front");
            assert!(
                tracked.contains(p),
                "the fitted hand left the region: {end}"
            );
        }
        assert!(tracker.cut);
        assert_eq!(tracker.region(&camera), (workspace, RoiKind::Workspace));
        // Read whole through the workspace, the arm is explained and the region follows it.
        tracker
            .track_masks(&camera, &bent)
            .expect("track")
            .expect("a pose");
        assert!(!tracker.cut);
        assert_eq!(tracker.region(&camera).1, RoiKind::Tracked);
    }

    /// A human whose trunk moves (the catalogue's `human`: slides, turn, lean) has no fixed
    /// shoulder, so its workspace is the reach sphere around the shoulder at rest before any
    /// pose and around the last pose's shoulder after one, kept when the track is lost and
    /// forgotten with the stream: never the whole frame, where a 64x64 network sees the arm
    /// a few pixels long.
    #[test]
    fn the_workspace_follows_a_trunk_that_moves() {
        let mut human = RobotModel::from_catalogue("human").expect("catalogue human");
        human.retain_visuals(|g| workcell_robots::HumanLook::Flesh.shows(g.name.as_deref()));
        let X_WH = pose_from_xyz_rpy([1.4, 0.0, 0.0], [0.0, 0.0, std::f64::consts::PI]);
        let mut tracker = ArmTracker::new(&human, &X_WH, ArmFitConfig::default()).expect("tracker");
        let arm = tracker.arm().clone();
        assert_eq!(arm.shoulder_W, None);
        // At rest: the upper arm link's origin with every joint at zero, and the reach is
        // the upper arm's length (shoulder to elbow) plus the forearm's.
        let zero: Vec<f64> = human
            .position_limits()
            .iter()
            .map(|&[lo, hi]| 0.0_f64.clamp(lo, hi))
            .collect();
        let k = human.fk(X_WH, &zero).expect("fk");
        let link = |part: HumanPart| {
            let id = human.link_id(part.link_name()).expect("link");
            k.link_pose(id).translation
        };
        let (rest, upper) = arm.rest_shoulder_W;
        assert!(
            (rest - link(HumanPart::UpperArm)).length() < 1e-12,
            "{rest}"
        );
        assert!((upper - (link(HumanPart::Forearm) - rest).length()).abs() < 1e-12);
        let reach = arm.reach_m().expect("reach");
        assert!(
            reach > upper + 0.2 && reach < upper + 0.4,
            "{reach} from {upper}"
        );
        let camera = Camera::look_at(
            [1.0, 2.9, 2.1],
            [0.9, 0.0, 1.0],
            [0.0, 0.0, 1.0],
            640,
            480,
            55.0,
        )
        .expect("camera");
        let around = |c: Vector| {
            (
                Roi::of_sphere(&camera, c, reach, roi::WORKSPACE_MARGIN).expect("in view"),
                RoiKind::Workspace,
            )
        };
        assert_eq!(tracker.region(&camera), around(rest));
        // Where the last pose put the shoulder (0.5 m along a slide, say), the workspace
        // follows; a frame without a pose keeps it; a new stream forgets it.
        let moved = rest + Vector::new(0.0, 0.5, 0.0);
        tracker.last_shoulder_W = Some(moved);
        assert_ne!(around(moved), around(rest));
        assert_eq!(tracker.region(&camera), around(moved));
        let empty = ArmMasks::from_classes(&vec![0; 640 * 480], 640, 480).expect("masks");
        tracker
            .track_masks(&camera, &empty)
            .expect("no error")
            .expect_err("no arm in empty masks");
        assert_eq!(tracker.region(&camera), around(moved));
        tracker.reset();
        assert_eq!(tracker.region(&camera), around(rest));
    }

    /// A tracker of the built-in human at the origin with the shipped network.
    fn shipped_tracker() -> ArmTracker {
        let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../procnet/weights/procnet-cpu.safetensors");
        let net =
            ProcNet::load(&weights, workcell_procnet::Backend::Flex).expect("shipped weights");
        ArmTracker::new(&human(), &Pose::IDENTITY, ArmFitConfig::default())
            .expect("tracker")
            .with_network(net)
            .expect("forearm class")
    }

    /// A network reads the frame's region of interest at [`DEFAULT_INPUT_PX`]: the shipped
    /// weights on a 640x480 frame see the reach sphere's square, and its masks come back with
    /// that square's camera.
    #[test]
    fn the_network_reads_the_region_of_interest() {
        let mut tracker = shipped_tracker();
        let camera = camera_at(tracker.arm(), Vector::new(2.5, 0.5, 0.2), [640, 480], 45.0);
        let roi = tracker.roi(&camera);
        let out = tracker
            .segment(&camera, &vec![90; 640 * 480 * 3], None)
            .expect("segmented");
        assert_eq!(out.roi, roi);
        let s = DEFAULT_INPUT_PX;
        assert_eq!(out.camera, roi.camera(&camera, s as u32).expect("camera"));
        assert_eq!((out.masks.width, out.masks.height), (s, s));
        for plane in out.masks.parts.iter().chain([&out.masks.background]) {
            assert_eq!(plane.len(), s * s);
            assert!(plane.iter().all(|v| (0.0..=1.0).contains(v)));
        }
    }

    /// A region already cut out ([`ArmTracker::track_region`]): the network keeps its memory
    /// while the region keeps its scale, and starts afresh, with VIEW_READS reads of the new
    /// view, on the stream's first frame and when the scale jumps (the workspace crop to the
    /// tracked one and back).
    #[test]
    fn a_region_of_another_scale_starts_the_network_afresh() {
        let mut tracker = shipped_tracker();
        let camera = camera_at(tracker.arm(), Vector::new(2.5, 0.5, 0.2), [640, 480], 45.0);
        let s = DEFAULT_INPUT_PX;
        let wide = Roi::square([320.0, 240.0], 400.0)
            .camera(&camera, s as u32)
            .expect("camera");
        let near = Roi::square([320.0, 240.0], 380.0)
            .camera(&camera, s as u32)
            .expect("camera");
        let zoomed = Roi::square([300.0, 220.0], 200.0)
            .camera(&camera, s as u32)
            .expect("camera");
        let rgb = vec![90u8; 3 * s * s];
        let frames = |t: &ArmTracker| t.network().map(ProcNet::frames);
        let r = workcell_procnet::VIEW_READS;
        assert_eq!(r, 3);
        for (camera, expected) in [
            (&wide, r + 1),
            (&near, r + 2),
            (&zoomed, r + 1),
            (&zoomed, r + 2),
            (&wide, r + 1),
        ] {
            let outcome = tracker.track_region(camera, &rgb, None).expect("tracked");
            assert!(outcome.is_err(), "a grey frame shows no arm");
            assert_eq!(frames(&tracker), Some(expected), "{camera:?}");
        }
        // Images of another size than the region's camera are refused.
        assert!(tracker.track_region(&wide, &rgb[3..], None).is_err());
        assert!(tracker.track_region(&wide, &rgb, Some(&[1.0; 5])).is_err());
        assert!(tracker.track_region(&camera, &rgb, None).is_err());
        assert!(!view_jump(None, 100.0));
        assert!(!view_jump(Some(100.0), 124.0) && !view_jump(Some(124.0), 100.0));
        assert!(view_jump(Some(100.0), 126.0) && view_jump(Some(126.0), 100.0));
    }
}
