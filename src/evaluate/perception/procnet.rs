//! ProcNet in the closed loop: the cell's camera renders a frame at its rate (with its depth
//! image when the camera measures depth, with a black disc over the forearm when the
//! evaluation asks for artificial occlusion), an [`ArmTracker`] segments every arm part and
//! fits the human model's joints to the masks, and the arm's parts are where the fitted
//! joints put them, carried forward over the estimate's age by the joints' velocity (the
//! least-squares slope through the last `velocity_fits` fits, from the newest re-acquired
//! fit on: a fit of the global search may have jumped from a wrong optimum to the truth, and
//! a velocity across that jump carried the wrong arm's error forward; on the tuning clips
//! 1-12 with true masks, starting the window there took the perception error 3.2 mm lower,
//! 95 % -6.1 to -1.1, lower in 9 of 12). A frame without a pose delivers nothing: the last
//! estimate ages (its uncertainty grows); without one, or once it is older than
//! [`MAX_AGE_S`], the filter sees no human and brakes.

use std::collections::VecDeque;

use workcell_perception::pose::{
    ArmFitConfig, ArmMasks, Calibration, ConfidentFloors, FitSettings,
};
use workcell_perception::{ArmTracker, NoEstimate};
use workcell_procnet::{Backend, ProcNet};
use workcell_safety::{HumanEstimate, HumanGeometry, HumanPart};
use workcell_sim::render::occlusion::{OCCLUDER_DEPTH_M, Occluder, OccluderKind, fit_occluder};
use workcell_sim::render::{Camera, Class, CpuRenderer, Frame, Renderer};
use workcell_sim::retarget::TrunkJoints;
use workcell_sim::{CellModel, CellScene, Scenario};

use super::{AgeingBound, HumanPerception, MaskKind, PerceptionInput, ProcNetConfig};
use crate::error::{Error, Result};
use crate::robots::{KinematicState, Side};

/// An estimate older than this is dropped, s: the filter then brakes (about ten frames at
/// 30 Hz; by then the aged bound has grown by 0.45 m at the default 10 m/s^2).
pub const MAX_AGE_S: f64 = 0.3;

/// The left arm's fit is taken where its masks show at least this much forearm, px of the
/// camera's image: below it (a few pixels past the body's edge) the fit's poses were 0.7 m
/// off in the median and none within its bound; above 100 px they were 17-42 mm off and
/// within it (docs/human.md, "Both arms").
const LEFT_MIN_SHOWN_PX: f32 = 100.0;

/// The left arm where no fit found it: each of its parts somewhere within its reach of the
/// shoulder, which the fitted trunk places (an arm unseen is guarded where it could be).
#[derive(Debug, Clone)]
struct UnseenArm {
    /// The left upper arm's link, whose origin is the shoulder.
    shoulder: crate::robots::LinkId,
    /// Each part's reach: its farthest point from the shoulder with the arm straight (its
    /// capsule's far end and radius), m.
    parts: [(HumanPart, f64); 3],
}

impl UnseenArm {
    /// The left arm of `human`, where it has one with collision geometry.
    fn of(human: &crate::robots::RobotModel) -> Option<Self> {
        let shoulder = human.link_id(HumanPart::LeftUpperArm.link_name())?;
        let q: Vec<f64> = (human.position_limits().iter())
            .map(|[lo, hi]| 0.0_f64.clamp(*lo, *hi))
            .collect();
        let k = human.fk(crate::robots::math::Pose::IDENTITY, &q).ok()?;
        let s = k.link_pose(shoulder).translation;
        let reach = |part: HumanPart| -> Option<(HumanPart, f64)> {
            let link = human.link_id(part.link_name())?;
            let c = crate::robots::collision::link_bounding_capsule(human, link)?;
            let (a, b) = c.segment_in_world(k.link_pose(link));
            Some((part, (a - s).length().max((b - s).length()) + c.radius_m))
        };
        let [u, f, h] = HumanPart::LEFT_ARM;
        Some(Self {
            shoulder,
            parts: [reach(u)?, reach(f)?, reach(h)?],
        })
    }

    /// The parts as spheres about the shoulder where `kinematics` puts it, at rest, into
    /// `out`.
    fn place_into(&self, kinematics: &KinematicState, out: &mut HumanEstimate) {
        let s = kinematics.link_pose(self.shoulder).translation;
        for (part, reach_m) in self.parts {
            out.parts.push(workcell_safety::PartEstimate {
                part,
                capsule: workcell_safety::Capsule::new(s, s, reach_m),
                v_a_W: crate::robots::math::Vector::ZERO,
                v_b_W: crate::robots::math::Vector::ZERO,
            });
        }
    }
}

/// One measurement: the fitted joints and the pose uncertainty.
#[derive(Debug, Clone)]
struct Measured {
    q: Vec<f64>,
    uncertainty_m: f64,
    /// The fit came from the global search, not the track: where the fits before it put
    /// the arm says nothing of how it moves.
    reacquired: bool,
    /// The left arm's joints in `q` are measured (its own fit, or the true pose); else they
    /// are a guess and its parts are left out of the estimate.
    left_seen: bool,
}

/// Frames measured, and why those without an estimate had none.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FrameCounts {
    pub frames: usize,
    pub estimates: usize,
    pub no_pose: usize,
    pub no_frame: usize,
    pub errors: usize,
}

/// The cell's camera rendered and handed to an [`ArmTracker`], as a [`HumanPerception`]:
/// this wiring adds the camera's rate, its latency, the artificial occluder, and the joints'
/// velocities from successive frames.
pub struct ProcNetCamera {
    config: ProcNetConfig,
    /// The rate the tracker reads the cell camera's frames at, Hz: the camera's own divided by
    /// `frame_stride`.
    rate_hz: f64,
    ageing: AgeingBound,
    tracker: ArmTracker,
    /// The two-armed human's left arm, fitted after the right on the right's trunk: with the
    /// perfect segmenter's masks (a network of the left arm's classes is still to come).
    left: Option<ArmTracker>,
    /// The left arm's reach, guarded where no fit saw it.
    unseen_left: Option<UnseenArm>,
    camera: Camera,
    scene: CellScene,
    renderer: CpuRenderer,
    frame: Frame,
    next_frame_s: f64,
    in_flight: VecDeque<(f64, Option<Measured>)>,
    /// The newest delivered measurement and its exposure time.
    latest: Option<(f64, Measured)>,
    /// The last `velocity_fits` delivered fits (exposure time, joints), newest last, and
    /// the joints' velocity through them.
    fits: VecDeque<(f64, Vec<f64>)>,
    fit_qd: Vec<f64>,
    geometry: HumanGeometry,
    kinematics: KinematicState,
    /// The fits' errors at their exposure (the sum of each fit's mean over parts, m) and
    /// the fits counted.
    fit_error: (f64, usize),
    /// The newest fit's parts, at rest (its joints' velocity zero: `still_qd`), kept
    /// between frames.
    fitted: HumanEstimate,
    still_qd: Vec<f64>,
    q: Vec<f64>,
    qd: Vec<f64>,
    counts: FrameCounts,
}

impl ProcNetCamera {
    /// The perception of `config` for the cell `model` built from `scenario`: its camera
    /// named `config.camera` (the first when empty), the weights at `config.weights`.
    ///
    /// # Errors
    /// The scenario has no such camera, the weights do not load, the human has no arm.
    pub fn new(config: &ProcNetConfig, scenario: &Scenario, model: &CellModel) -> Result<Self> {
        let camera_config = scenario
            .cameras
            .iter()
            .find(|c| config.camera.is_empty() || c.name == config.camera)
            .ok_or_else(|| {
                Error::config(
                    "perception.camera",
                    format!(
                        "the cell has no camera named {:?} (it has {:?})",
                        config.camera,
                        scenario.cameras.iter().map(|c| &c.name).collect::<Vec<_>>()
                    ),
                )
            })?;
        let camera = camera_config
            .camera()
            .map_err(workcell_sim::SimError::from)?;
        let net = if config.masks == MaskKind::Network {
            let weights = config.weights_path();
            let net = ProcNet::load(&weights, Backend::Flex).map_err(|e| Error::At {
                key: "perception.weights".into(),
                source: Box::new(e.into()),
            })?;
            if net.config().reads_depth() && !config.depth {
                return Err(Error::config(
                    "perception.depth",
                    format!(
                        "{} is a network that reads depth: the camera must measure it \
                         (perception.depth = true)",
                        weights.display()
                    ),
                ));
            }
            Some(net)
        } else {
            None
        };
        // The bound: the network's calibration file (or the conservative bound where its
        // weights have none), true masks' own; the policy of `eval pose`.
        let measured =
            match &net {
                Some(_) => {
                    let found = Calibration::of_weights(&config.weights_path(), config.depth)
                        .map_err(|e| Error::At {
                            key: "perception.weights".into(),
                            source: Box::new(e.into()),
                        })?;
                    if let Some(w) = found.warning() {
                        tracing::warn!("{w}");
                    }
                    found.calibration
                }
                None => Calibration::true_masks(config.depth),
            };
        let mut fit = with_overrides(
            measured,
            config.uncertainty_scale,
            config.uncertainty_floor_m,
        )
        .apply(ArmFitConfig::default());
        // The fit the bound was measured with; the scenario's own settings of it win.
        fit.fit_trunk = config.fit_trunk.unwrap_or(fit.fit_trunk) && !config.true_trunk;
        fit.reversed_start = config.reversed_start.unwrap_or(fit.reversed_start);
        fit.depth_start = config.depth_start.unwrap_or(fit.depth_start);
        fit.search_below_gain = config.search_below_gain.unwrap_or(fit.search_below_gain);
        fit.hand_region = config.hand_region.unwrap_or(fit.hand_region);
        fit.trunk_downsample = config.trunk_downsample.unwrap_or(fit.trunk_downsample);
        fit.hull_outlines = config.hull_outlines.unwrap_or(fit.hull_outlines);
        // Not a setting the bound was measured with: a deferred search's fit takes the
        // bound of a searched one.
        fit.search_interval = config.search_interval;
        let overridden = config.fit_trunk.is_some()
            || config.reversed_start.is_some()
            || config.depth_start.is_some()
            || config.search_below_gain.is_some()
            || config.hand_region.is_some()
            || config.trunk_downsample.is_some()
            || config.hull_outlines.is_some();
        if overridden && let Some(measured_fit) = measured.fit {
            let differences = measured_fit.differences(&FitSettings::of(&fit));
            if !differences.is_empty() {
                tracing::warn!(
                    "perception: the masks' bound was measured with another fit ({}, measured \
                     vs this run): it may not hold",
                    differences.join(", ")
                );
            }
        }
        // The left arm on the right's trunk: its own fit of the trunk would be the same work
        // twice.
        let has_left = model
            .human
            .link_id(HumanPart::LeftForearm.link_name())
            .is_some();
        if config.fit_left_arm && (!has_left || config.masks != MaskKind::GroundTruth) {
            return Err(Error::config(
                "perception.fit_left_arm",
                "the left arm is fitted on a two-armed human (`human`) with the perfect \
                 segmenter's masks (perception.masks = \"ground_truth\"): the shipped networks \
                 have no left arm's classes"
                    .to_string(),
            ));
        }
        let left = (config.fit_left_arm && net.is_none())
            .then(|| {
                let held = ArmFitConfig {
                    fit_trunk: false,
                    ..fit.clone()
                };
                ArmTracker::of_side(&model.human, &model.X_WH, held, Side::Left)
            })
            .transpose()?;
        let mut tracker = ArmTracker::new(&model.human, &model.X_WH, fit)?;
        if let Some(net) = net {
            tracker = tracker.with_network(net)?;
        }
        let mut kinematics = KinematicState::new(&model.human);
        kinematics.X_WB = model.X_WH;
        // The tracker's own rate: the camera's, or a divisor of it.
        let rate_hz = camera_config.rate_hz / config.frame_stride.max(1) as f64;
        Ok(Self {
            config: config.clone(),
            rate_hz,
            ageing: config.ageing(rate_hz),
            tracker,
            left,
            unseen_left: config
                .guard_unseen_left_arm
                .then(|| UnseenArm::of(&model.human))
                .flatten(),
            camera,
            scene: CellScene::new(model),
            renderer: CpuRenderer::new(),
            frame: Frame::new(),
            next_frame_s: 0.0,
            in_flight: VecDeque::new(),
            latest: None,
            fits: VecDeque::new(),
            fit_error: (0.0, 0),
            fitted: HumanEstimate::default(),
            still_qd: vec![0.0; model.human.dof()],
            fit_qd: vec![0.0; model.human.dof()],
            geometry: HumanGeometry::new(&model.human)?,
            kinematics,
            q: vec![0.0; model.human.dof()],
            qd: vec![0.0; model.human.dof()],
            counts: FrameCounts::default(),
        })
    }

    /// Frames measured so far, and why some had no estimate.
    #[must_use]
    pub fn counts(&self) -> &FrameCounts {
        &self.counts
    }

    /// Renders and tracks one frame.
    fn measure(&mut self, input: &PerceptionInput<'_>) -> Result<Option<Measured>> {
        self.counts.frames += 1;
        if self
            .config
            .camera_fails_at_s
            .is_some_and(|at_s| input.t_s >= at_s)
        {
            let reason = self.tracker.no_frame();
            self.counts.no_frame += 1;
            tracing::debug!("procnet perception at {:.3} s: {reason:?}", input.t_s);
            return Ok(None);
        }
        if self.config.masks == MaskKind::TruePose {
            self.counts.estimates += 1;
            return Ok(Some(Measured {
                q: input.state.human_q().to_vec(),
                uncertainty_m: 0.0,
                reacquired: false,
                left_seen: true,
            }));
        }
        self.scene.update(input.state);
        self.renderer
            .render(&self.scene.scene, &self.camera, &mut self.frame)
            .map_err(workcell_sim::SimError::from)?;
        // The class image: for the occluder and the perfect segmenter only.
        let network = self.tracker.network().is_some();
        let mut classes = if self.config.occlusion > 0.0 || !network {
            self.frame.classes(&self.scene.scene)
        } else {
            Vec::new()
        };
        if self.config.occlusion > 0.0 {
            self.occlude(&mut classes);
        }
        if self.config.true_trunk {
            self.tracker.hold_trunk_at(input.state.human_q())?;
        }
        let depth = self.config.depth.then_some(self.frame.depth_m.as_slice());
        // The region this frame is read through, for the trace.
        let region =
            tracing::enabled!(tracing::Level::TRACE).then(|| self.tracker.region(&self.camera));
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let outcome = if network {
            self.tracker.track(&self.camera, &self.frame.rgb, depth)?
        } else {
            // The perfect segmenter: each part's pixels in the frame.
            let mut masks = ArmMasks::from_classes(&classes, w, h)?;
            masks.depth_m = depth.map(<[f32]>::to_vec);
            self.tracker.track_masks(&self.camera, &masks)?
        };
        Ok(match outcome {
            Ok(mut estimate) => {
                self.counts.estimates += 1;
                // The left arm on the right's trunk, its joints into the same configuration;
                // the bound the larger of the two.
                let mut left_seen = false;
                if let Some(left) = &mut self.left {
                    left.hold_trunk_at(&estimate.fit.q)?;
                    let mut masks = ArmMasks::from_classes_of(HumanPart::LEFT_ARM, &classes, w, h)?;
                    masks.depth_m = depth.map(<[f32]>::to_vec);
                    let shown_px: f32 = masks.parts[1].iter().sum();
                    let outcome = left.track_masks(&self.camera, &masks)?;
                    if tracing::enabled!(tracing::Level::DEBUG) {
                        let at = |part: HumanPart| {
                            input
                                .truth
                                .parts
                                .iter()
                                .find(|p| p.part == part)
                                .map(|p| p.capsule)
                        };
                        let error_mm = match (&outcome, at(HumanPart::LeftForearm)) {
                            (Ok(found), Some(truth)) => (found.parts.iter())
                                .find(|p| p.part == HumanPart::LeftForearm)
                                .map_or(f64::NAN, |p| {
                                    500.0
                                        * ((p.a_W - truth.a_W).length()
                                            + (p.b_W - truth.b_W).length())
                                }),
                            _ => f64::NAN,
                        };
                        tracing::debug!(
                            t = input.t_s,
                            shown_px,
                            pose = outcome.is_ok(),
                            bound_mm = outcome.as_ref().map_or(f64::NAN, |e| 1e3 * e.uncertainty_m),
                            error_mm,
                            "left arm"
                        );
                    }
                    // Too little of the arm shown: any pose would be made up (from the cell's
                    // camera the left arm is mostly behind the body: docs/human.md).
                    if let (Ok(found), true) = (outcome, shown_px >= LEFT_MIN_SHOWN_PX) {
                        for &i in left.articulated().fitted() {
                            if let (Some(q), Some(v)) =
                                (estimate.fit.q.get_mut(i), found.fit.q.get(i))
                            {
                                *q = *v;
                            }
                        }
                        estimate.uncertainty_m = estimate.uncertainty_m.max(found.uncertainty_m);
                        left_seen = true;
                    }
                }
                if self.place_fitted(input, &estimate.fit.q, left_seen) {
                    if let Some((error, _)) = super::super::episode::perception_error(
                        &self.fitted.parts,
                        &input.truth.parts,
                        &[],
                    ) {
                        self.fit_error.0 += error;
                        self.fit_error.1 += 1;
                    }
                    if let Some(region) = region {
                        self.trace_fit(input, &estimate.fit, region);
                    }
                }
                Some(Measured {
                    reacquired: estimate.fit.reacquired,
                    q: estimate.fit.q,
                    uncertainty_m: estimate.uncertainty_m,
                    left_seen,
                })
            }
            Err(reason) => {
                self.counts.no_pose += 1;
                if reason == NoEstimate::NoFrame {
                    self.counts.no_frame += 1;
                }
                tracing::debug!("procnet perception at {:.3} s: {reason}", input.t_s);
                None
            }
        })
    }

    /// Places the human's parts where the fitted joints `q` put them into `fitted` (at
    /// rest); false where the model's kinematics fail.
    fn place_fitted(&mut self, input: &PerceptionInput<'_>, q: &[f64], left_seen: bool) -> bool {
        let human = &input.model.human;
        if human.forward_kinematics(q, &mut self.kinematics).is_err() {
            return false;
        }
        self.geometry
            .estimate_into(human, &self.kinematics, &self.still_qd, &mut self.fitted);
        self.fitted.parts.retain(|p| is_fitted(p.part, left_seen));
        true
    }

    /// The fit's error per part (`fitted`, placed by [`Self::place_fitted`]) against the
    /// truth at exposure, with its gain, bound and
    /// whether the search found it, and how much of each true part `region` (the region of
    /// interest the frame was read through) showed (trace level: where the closed loop's
    /// error comes from, the fit, the region or its ageing, and whether the bound covered
    /// it).
    fn trace_fit(
        &mut self,
        input: &PerceptionInput<'_>,
        fit: &workcell_perception::pose::ArmFit,
        region: (workcell_render::roi::Roi, workcell_render::roi::RoiKind),
    ) {
        // The trunk's joints' errors (fitted minus true, rad), the pelvis's (m), the true joints.
        let truth_q = input.state.human_q();
        let trunk = self.tracker.articulated().trunk().map(|trunk| {
            let joints: Vec<String> = (trunk.joints().iter())
                .filter_map(|&i| Some(format!("{:+.2}", fit.q.get(i)? - truth_q.get(i)?)))
                .collect();
            let true_joints: Vec<String> = (trunk.joints().iter())
                .filter_map(|&i| Some(format!("{:+.2}", truth_q.get(i)?)))
                .collect();
            let pelvis = trunk.error(&fit.q, truth_q).map_or(f64::NAN, |[_, m]| m);
            format!(
                "[{}] pelvis {pelvis:.3} of [{}]",
                joints.join(" "),
                true_joints.join(" ")
            )
        });
        // Of the true parts' capsule ends, those the region read showed.
        let (roi, kind) = region;
        let X_CW = self.camera.X_WC.inverse();
        let shown: Vec<String> = (input.truth.parts.iter())
            .map(|p| {
                let n = [p.capsule.a_W, p.capsule.b_W]
                    .iter()
                    .filter(|e| (self.camera.project(X_CW * **e)).is_some_and(|p| roi.contains(p)))
                    .count();
                format!("{:?}:{n}", p.part)
            })
            .collect();
        tracing::trace!(
            t = input.t_s,
            parts = %part_errors(&self.fitted, input.truth),
            in_region = %shown.join(","),
            region = ?kind,
            hidden = fit.hidden_share,
            trunk = trunk.as_deref().unwrap_or("-"),
            gain = fit.gain,
            bound_m = fit.uncertainty_m,
            reacquired = fit.reacquired,
            "fit error"
        );
    }

    /// A black disc over the forearm's pixels, sized so that it hides the configured
    /// fraction of them: black in the frame, at [`OCCLUDER_DEPTH_M`] in its depth image,
    /// background in `classes` (what is seen).
    fn occlude(&mut self, classes: &mut [u8]) {
        let w = self.camera.width;
        let forearm: Vec<u8> = classes
            .iter()
            .map(|&c| u8::from(c == Class::Forearm as u8))
            .collect();
        let (mut n, mut sx, mut sy) = (0.0, 0.0, 0.0);
        for (p, _) in forearm.iter().enumerate().filter(|(_, v)| **v != 0) {
            n += 1.0;
            sx += (p % w as usize) as f64 + 0.5;
            sy += (p / w as usize) as f64 + 0.5;
        }
        if n == 0.0 {
            return;
        }
        let disc = Occluder {
            kind: OccluderKind::Blob,
            centre_px: [sx / n, sy / n],
            size_px: [1.0, 1.0],
            angle_rad: 0.0,
        };
        let shown: Vec<bool> = forearm.iter().map(|&v| v != 0).collect();
        let max_scale = f64::from(w + self.camera.height);
        let (occluder, _) =
            fit_occluder(&disc, self.config.occlusion, max_scale, w, &forearm, &shown);
        let mask = occluder.mask(w, self.camera.height);
        for (p, _) in mask.iter().enumerate().filter(|(_, m)| **m != 0) {
            self.frame.rgb[3 * p..3 * p + 3].fill(0);
            self.frame.depth_m[p] = OCCLUDER_DEPTH_M;
            classes[p] = Class::Background as u8;
        }
    }
}

impl HumanPerception for ProcNetCamera {
    fn name(&self) -> String {
        self.config.describe()
    }

    fn estimate(&mut self, input: &PerceptionInput<'_>, out: &mut HumanEstimate) {
        let t = input.t_s;
        if t + 1e-9 >= self.next_frame_s {
            self.next_frame_s += 1.0 / self.rate_hz;
            // A failure of the renderer or the network is a frame without a pose.
            let measured = self.measure(input).unwrap_or_else(|e| {
                self.counts.errors += 1;
                tracing::warn!("procnet perception: {e:#}");
                None
            });
            self.in_flight.push_back((t, measured));
        }
        while self
            .in_flight
            .front()
            .is_some_and(|(t0, _)| t0 + self.config.latency_s <= t + 1e-9)
        {
            if let Some((t0, Some(m))) = self.in_flight.pop_front() {
                let window = self.config.velocity_fits.max(2);
                push_fit(&mut self.fits, window, t0, &m.q, m.reacquired);
                least_squares_velocity(&self.fits, &mut self.fit_qd);
                self.latest = Some((t0, m));
            }
        }
        out.parts.clear();
        out.uncertainty_m = 0.0;
        out.uncertainty_rate_m_s = 0.0;
        let Some((t0, m)) = &self.latest else {
            return; // nothing yet: the filter brakes
        };
        let age = (t - t0).max(0.0);
        if age > MAX_AGE_S {
            return; // too old to trust: the filter brakes
        }
        // The joints' velocity through the last fits (`velocity_fits`) close enough in time
        // to be one movement.
        self.qd.copy_from_slice(&self.fit_qd);
        for ((q, q0), v) in self.q.iter_mut().zip(&m.q).zip(&self.qd) {
            *q = q0 + v * age;
        }
        if input
            .model
            .human
            .forward_kinematics(&self.q, &mut self.kinematics)
            .is_err()
        {
            return;
        }
        self.geometry
            .estimate_into(&input.model.human, &self.kinematics, &self.qd, out);
        out.parts.retain(|p| is_fitted(p.part, m.left_seen));
        if !m.left_seen
            && let Some(unseen) = &self.unseen_left
        {
            unseen.place_into(&self.kinematics, out);
        }
        out.uncertainty_m = self.ageing.aged_uncertainty(m.uncertainty_m, 0.0, age);
        out.uncertainty_rate_m_s = 0.0;
        if tracing::enabled!(tracing::Level::TRACE) {
            let mut held = HumanEstimate::default();
            if input
                .model
                .human
                .forward_kinematics(&m.q, &mut self.kinematics)
                .is_ok()
            {
                self.geometry.estimate_into(
                    &input.model.human,
                    &self.kinematics,
                    &self.qd,
                    &mut held,
                );
            }
            tracing::trace!(
                t,
                age,
                carried = %part_errors(out, input.truth),
                held = %part_errors(&held, input.truth),
                "estimate error"
            );
        }
    }

    fn unseen_parts(&self) -> &[HumanPart] {
        match (&self.latest, &self.unseen_left) {
            (Some((_, m)), Some(_)) if !m.left_seen => &HumanPart::LEFT_ARM,
            _ => &[],
        }
    }

    fn fit_error_m(&self) -> Option<f64> {
        let (sum, n) = self.fit_error;
        (n > 0).then(|| sum / n as f64)
    }
}

/// Adds the fit `q` exposed at `t0` to `fits`, keeping the last `window`; a `reacquired` fit
/// (the global search's, not the track's) starts the window anew: no velocity across the
/// jump. The oldest fit's buffer holds the newest once the window is full.
fn push_fit(
    fits: &mut VecDeque<(f64, Vec<f64>)>,
    window: usize,
    t0: f64,
    q: &[f64],
    reacquired: bool,
) {
    let keep = if reacquired { 1 } else { window.max(1) };
    while fits.len() > keep {
        fits.pop_front();
    }
    let mut buffer = if fits.len() == keep {
        fits.pop_front().map(|(_, q)| q).unwrap_or_default()
    } else {
        Vec::new()
    };
    buffer.clear();
    buffer.extend_from_slice(q);
    fits.push_back((t0, buffer));
}

/// The joints' velocity through `fits` (exposure time, joints; newest last) into `qd`: the
/// least-squares slope of each joint against time over the fits within [`MAX_AGE_S`] of the
/// newest (of two, their difference quotient); zero with fewer than two.
fn least_squares_velocity(fits: &VecDeque<(f64, Vec<f64>)>, qd: &mut [f64]) {
    qd.iter_mut().for_each(|v| *v = 0.0);
    let Some(&(newest, _)) = fits.back() else {
        return;
    };
    // The fits come in exposure order, so those within MAX_AGE_S of the newest are a suffix.
    let start = fits
        .iter()
        .position(|(t, _)| newest - t <= MAX_AGE_S)
        .unwrap_or(fits.len());
    let window = fits.range(start..);
    match window.len() {
        0 | 1 => {}
        // Two: their difference quotient, as written (bit for bit the same as before).
        2 => {
            let ((t1, q1), (t0, q0)) = (&fits[start], &fits[start + 1]);
            let dt = t0 - t1;
            if dt > 1e-6 {
                for ((v, a), b) in qd.iter_mut().zip(q0).zip(q1) {
                    *v = (a - b) / dt;
                }
            }
        }
        _ => {
            let n = window.len() as f64;
            let mean_t = window.clone().map(|(t, _)| t).sum::<f64>() / n;
            let stt: f64 = window.clone().map(|(t, _)| (t - mean_t).powi(2)).sum();
            if stt < 1e-12 {
                return;
            }
            for (j, v) in qd.iter_mut().enumerate() {
                let mean_q = window.clone().map(|(_, q)| q[j]).sum::<f64>() / n;
                *v = window
                    .clone()
                    .map(|(t, q)| (t - mean_t) * (q[j] - mean_q))
                    .sum::<f64>()
                    / stt;
            }
        }
    }
}

/// A warning when the camera of `config` does not see the human's head at every place its
/// trunk can carry it ([`head_places_unseen`]): there the tracker has nothing to fit, and
/// the filter brakes. `None` when it sees them all.
///
/// # Errors
/// The scenario has no such camera, or the human model's kinematics fail.
pub fn camera_coverage_warning(
    config: &ProcNetConfig,
    scenario: &Scenario,
    model: &CellModel,
) -> Result<Option<String>> {
    let Some(camera_config) = scenario
        .cameras
        .iter()
        .find(|c| config.camera.is_empty() || c.name == config.camera)
    else {
        return Ok(None); // the perception itself names the missing camera
    };
    let camera = camera_config
        .camera()
        .map_err(workcell_sim::SimError::from)?;
    let unseen = head_places_unseen(model, &camera)?;
    Ok((unseen > 0).then(|| {
        format!(
            "camera {:?} does not see the human's head at {unseen} of the {HEAD_PLACES} places \
             its trunk can carry it (the pelvis's slides at their limits, upright and leaning, \
             turned eight ways): there perception loses the human and the filter brakes",
            camera_config.name
        )
    }))
}

/// The places [`head_places_unseen`] tries: the pelvis's slides each at its lower limit,
/// zero and its upper limit (nine places), the trunk upright and leaning as far forward as
/// it can, turned to eight headings.
pub const HEAD_PLACES: usize = 9 * 2 * 8;

/// Of the places the human's trunk can carry its head to ([`HEAD_PLACES`]: the pelvis's
/// slides `pelvis_x` and `pelvis_y` at their limits and zero, `trunk_lean` at zero and its
/// upper limit, `trunk_turn` at eight headings within its limits; the arms at rest), how many
/// the camera does not see (the head's origin outside the image or behind the lens). The
/// joints a model lacks stay where the cell puts the human.
///
/// # Errors
/// The human model's kinematics fail.
pub fn head_places_unseen(model: &CellModel, camera: &Camera) -> Result<usize> {
    let human = &model.human;
    let Some(head) = human.link_id("head").or_else(|| human.link_id("torso")) else {
        return Ok(0); // nothing to place
    };
    // Each trunk joint's range ([0, 0] for those the model lacks).
    let limits = human.position_limits();
    let trunk = TrunkJoints::of(human);
    let [x, y, turn, lean, side] = trunk.0.map(|j| j.map_or([0.0; 2], |i| limits[i]));
    let upright = |[lo, hi]: [f64; 2]| 0.0_f64.clamp(lo, hi);
    let mut kinematics = KinematicState::new(human);
    kinematics.X_WB = model.X_WH;
    let mut q = human.neutral_configuration();
    let mut unseen = 0;
    let slid = |range: [f64; 2], i: usize| [range[0], upright(range), range[1]][i];
    for place in 0..9 {
        let (px, py) = (slid(x, place % 3), slid(y, place / 3));
        for leaning in [upright(lean), lean[1]] {
            for heading in 0..8 {
                let turned = (f64::from(heading) * std::f64::consts::FRAC_PI_4
                    - std::f64::consts::PI)
                    .clamp(turn[0], turn[1]);
                trunk.set(&mut q, [px, py, turned, leaning, upright(side)]);
                human.forward_kinematics(&q, &mut kinematics)?;
                let p_W = kinematics.link_pose(head).translation;
                let seen = camera
                    .project(camera.X_WC.inverse_transform_point(p_W))
                    .is_some_and(|[u, v]| {
                        (0.0..f64::from(camera.width)).contains(&u)
                            && (0.0..f64::from(camera.height)).contains(&v)
                    });
                unseen += usize::from(!seen);
            }
        }
    }
    Ok(unseen)
}

/// Whether the fit places `part`: the torso, the head and the right arm; the left arm where
/// its own fit found it (`left_seen`), else its joints stay where the fit starts them (an
/// estimate of it would be a guess).
fn is_fitted(part: HumanPart, left_seen: bool) -> bool {
    left_seen || part.side() != Some(Side::Left)
}

/// `part:error_mm` of each part's end points against the truth's (mean of the two ends).
fn part_errors(estimate: &HumanEstimate, truth: &HumanEstimate) -> String {
    estimate
        .parts
        .iter()
        .filter_map(|e| Some((e, truth.parts.iter().find(|t| t.part == e.part)?)))
        .map(|(e, t)| {
            let mm = 500.0
                * ((e.capsule.a_W - t.capsule.a_W).length()
                    + (e.capsule.b_W - t.capsule.b_W).length());
            format!("{:?}:{mm:.0}", e.part)
        })
        .collect::<Vec<_>>()
        .join(",")
}

/// One frame of [`bench_tracker`]: milliseconds per stage.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameTiming {
    /// The simulator's camera (not perception's work).
    pub render_ms: f64,
    /// The region of interest resampled and segmented by the network.
    pub network_ms: f64,
    /// The articulated fit.
    pub fit_ms: f64,
    /// The fit searched globally (first frame, lost track).
    pub reacquired: bool,
    /// The frame gave an estimate.
    pub estimate: bool,
    /// Part renders of the fit (each distinct pose of a part in a batch of candidates
    /// renders once); 0 without an estimate.
    pub renders: usize,
}

/// Times perception on `frames` frames of the cell's camera at its rate, from the start of
/// episode `seed` of `evaluation` with the robot on its nominal path: the network (its
/// weights, `perception.weights`) and the articulated fit, with the depth image when
/// `perception.depth` is set, one thread each as in the loop.
///
/// # Errors
/// The cell, its camera or the weights do not load; the simulator fails.
pub fn bench_tracker(
    evaluation: &crate::evaluate::Evaluation,
    seed: u64,
    frames: usize,
    mut progress: impl FnMut(usize),
) -> Result<Vec<FrameTiming>> {
    use std::time::Instant;
    let super::PerceptionConfig::Procnet(c) = &evaluation.config.perception else {
        return Err(Error::config(
            "perception.kind",
            "the tracker is timed on a procnet perception (kind = \"procnet\")",
        ));
    };
    let mut scenario = evaluation.scenario.clone();
    scenario.seed = seed;
    let model = CellModel::new(&scenario, &evaluation.scenario_path)?;
    let config = ProcNetConfig {
        masks: MaskKind::Network,
        ..c.clone()
    };
    let mut camera = ProcNetCamera::new(&config, &scenario, &model)?;
    let mut state = workcell_sim::CellState::new(&model)?;
    let dt = model.time_step_s();
    let period = 1.0 / camera.rate_hz;
    let mut out = Vec::with_capacity(frames);
    let mut t = 0.0;
    for k in 0..frames {
        while t + 1e-9 < k as f64 * period {
            workcell_sim::step(&model, &mut state, &workcell_sim::RobotCommand::Nominal)?;
            t += dt;
        }
        let t0 = Instant::now();
        camera.scene.update(&state);
        camera
            .renderer
            .render(&camera.scene.scene, &camera.camera, &mut camera.frame)
            .map_err(workcell_sim::SimError::from)?;
        let t1 = Instant::now();
        let depth = config.depth.then_some(camera.frame.depth_m.as_slice());
        let roi = camera
            .tracker
            .segment(&camera.camera, &camera.frame.rgb, depth)?;
        let t2 = Instant::now();
        let outcome = camera.tracker.track_roi(&roi.camera, &roi.masks)?;
        let t3 = Instant::now();
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        out.push(FrameTiming {
            render_ms: ms(t0, t1),
            network_ms: ms(t1, t2),
            fit_ms: ms(t2, t3),
            reacquired: outcome.as_ref().is_ok_and(|e| e.fit.reacquired),
            estimate: outcome.is_ok(),
            renders: outcome.as_ref().map_or(0, |e| e.fit.renders),
        });
        progress(k + 1);
    }
    Ok(out)
}

/// `measured` with a scenario's own scale and floor where it gives them: its floor is the
/// least of every floor, the hidden bands', a kept track's and a confident fit's too (ProcNetConfig's keys).
fn with_overrides(measured: Calibration, scale: Option<f64>, floor_m: Option<f64>) -> Calibration {
    let Some(floor_m) = floor_m else {
        return Calibration {
            scale: scale.unwrap_or(measured.scale),
            ..measured
        };
    };
    Calibration {
        scale: scale.unwrap_or(measured.scale),
        floor_m,
        tracked_floors_m: measured
            .tracked_floors_m
            .map(|floors| floors.map(|f| f.max(floor_m))),
        confident: measured.confident.map(|c| ConfidentFloors {
            floors_m: c.floors_m.map(|f| f.max(floor_m)),
            ..c
        }),
        ..measured
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robots::math::Vector;
    use workcell_perception::pose::BoundInputs;
    use workcell_safety::HumanPart;
    use workcell_sim::{CellState, RobotCommand, step};

    fn cell() -> (Scenario, CellModel) {
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        let scenario = Scenario::from_file(path).expect("scenario");
        let model = CellModel::new(&scenario, path).expect("cell");
        (scenario, model)
    }

    /// One control tick: the cell stepped by `dt`, then `perception`'s estimate at the new
    /// time into `out` (`truth` is what the loop would pass as the true human).
    fn tick(
        model: &CellModel,
        state: &mut CellState,
        perception: &mut ProcNetCamera,
        t: &mut f64,
        truth: &HumanEstimate,
        out: &mut HumanEstimate,
    ) {
        step(model, state, &RobotCommand::Nominal).expect("step");
        *t += model.time_step_s();
        let input = PerceptionInput {
            t_s: *t,
            model,
            state,
            truth,
            other_arm: &[],
        };
        perception.estimate(&input, out);
    }

    /// The default cell's former camera (eye (0.6, 2.3, 1.8), target (0.5, 0, 1.0)) does not
    /// see the whole body's head everywhere its trunk can carry it (the recorded people walk
    /// up to the slides' limits and lean up to 80 degrees): it misses 19 of the 144 places,
    /// among them the head upright at the slides' corner away from the robot and toward the
    /// camera. The cell's camera, farther back, sees all; one turned away none; the
    /// evaluation's warning says so.
    #[test]
    fn the_check_finds_where_the_cell_camera_loses_the_head() {
        let (mut scenario, _) = cell();
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        scenario.set_human_model("human", path);
        let model = CellModel::new(&scenario, path).expect("cell");
        let look = |eye: [f64; 3], target: [f64; 3]| {
            let mut config = scenario.cameras[0].clone();
            config.eye = eye;
            config.target = target;
            config
        };
        let near = look([0.6, 2.3, 1.8], [0.5, 0.0, 1.0]);
        let camera = near.camera().expect("camera");
        assert_eq!(head_places_unseen(&model, &camera).expect("places"), 19);
        // The corner: the pelvis slid 0.6 m along both slides (the human faces -x, so
        // toward +x and +y in the world), upright; the head 0.6 m above the hip.
        let human = &model.human;
        let mut q = human.neutral_configuration();
        let [lo_x, lo_y] = [0, 1].map(|k| {
            let i = TrunkJoints::of(human).0[k].expect("a slide");
            human.position_limits()[i][0]
        });
        TrunkJoints::of(human).set(&mut q, [lo_x, lo_y, 0.0, 0.0, 0.0]);
        let mut kinematics = KinematicState::new(human);
        kinematics.X_WB = model.X_WH;
        human
            .forward_kinematics(&q, &mut kinematics)
            .expect("kinematics");
        let head = human.link_id("head").expect("head");
        let p_W = kinematics.link_pose(head).translation;
        assert!(
            (p_W - Vector::new(1.95, 0.45, 1.55)).length() < 1e-6,
            "{p_W:?}"
        );
        // By hand: forward f = (target - eye)/|.|, right r = f x z/|.|, down = r x f;
        // u = 320 + (240 / tan 27.5 deg) (d.r)/(d.f) with d = p - eye: -51.708, left of the
        // image by 52 pixels.
        let [u, _] = camera
            .project(camera.X_WC.inverse_transform_point(p_W))
            .expect("in front");
        assert!((u - -51.708).abs() < 1e-3, "u = {u}");
        let cell_camera = scenario.cameras[0].camera().expect("camera");
        assert_eq!(
            cell_camera.X_WC,
            look([1.0, 2.9, 2.1], [0.9, 0.0, 1.0])
                .camera()
                .expect("camera")
                .X_WC
        );
        assert_eq!(head_places_unseen(&model, &cell_camera).expect("places"), 0);
        let away = look([0.6, 2.3, 1.8], [0.6, 4.0, 1.8])
            .camera()
            .expect("camera");
        assert_eq!(
            head_places_unseen(&model, &away).expect("places"),
            HEAD_PLACES
        );
        // The evaluation's warning names the camera and the count.
        let config = ProcNetConfig::default();
        let warning = |scenario: &Scenario| {
            camera_coverage_warning(&config, scenario, &model).expect("warning")
        };
        let mut nearer = scenario.clone();
        nearer.cameras[0] = near;
        let text = warning(&nearer).expect("a warning");
        assert!(
            text.contains("\"front\"") && text.contains("at 19 of the 144 places"),
            "{text}"
        );
        assert_eq!(warning(&scenario), None);
        // The paper's arm has no trunk joints: it stands where the cell puts it, in view.
        let (arm_scenario, arm_model) = cell();
        assert_eq!(warning_for(&arm_scenario, &arm_model), None);
    }

    /// The velocity through the last fits: exact on a ramp, the difference quotient of two,
    /// a zigzag of three averaged out, a fit older than [`MAX_AGE_S`] left out.
    #[test]
    fn velocity_is_the_least_squares_slope_through_the_last_fits() {
        let dt = 1.0 / 30.0;
        let fits = |qs: &[(f64, f64)]| -> VecDeque<(f64, Vec<f64>)> {
            qs.iter().map(|&(t, q)| (t, vec![q, 2.0 * q])).collect()
        };
        let mut qd = [f64::NAN; 2];
        // A ramp of 0.5 rad/s: every window gives it.
        let ramp: Vec<(f64, f64)> = (0..4)
            .map(|i| (f64::from(i) * dt, 0.5 * f64::from(i) * dt))
            .collect();
        for k in 2..=4 {
            least_squares_velocity(&fits(&ramp[4 - k..]), &mut qd);
            assert!(
                (qd[0] - 0.5).abs() < 1e-12 && (qd[1] - 1.0).abs() < 1e-12,
                "{qd:?}"
            );
        }
        // Two: the difference quotient; three in a zigzag 0, 1, 0: slope 0.
        let zigzag = [(0.0, 0.0), (dt, 1.0), (2.0 * dt, 0.0)];
        least_squares_velocity(&fits(&zigzag[1..]), &mut qd);
        assert!((qd[0] + 30.0).abs() < 1e-9, "{qd:?}");
        least_squares_velocity(&fits(&zigzag), &mut qd);
        assert!(qd[0].abs() < 1e-9, "{qd:?}");
        // A fit from before MAX_AGE_S is no part of the movement: 1 rad/s from the two.
        let stale = [(0.0, 5.0), (0.5, 0.0), (0.5 + dt, dt)];
        least_squares_velocity(&fits(&stale), &mut qd);
        assert!((qd[0] - 1.0).abs() < 1e-9, "{qd:?}");
        // One fit, or none: no velocity.
        least_squares_velocity(&fits(&stale[2..]), &mut qd);
        assert_eq!(qd, [0.0; 2]);
        least_squares_velocity(&VecDeque::new(), &mut qd);
        assert_eq!(qd, [0.0; 2]);
    }

    /// The window keeps the last fits; a re-acquired fit starts it anew (no velocity across
    /// the jump), and the track's next fit gives the velocity from there.
    #[test]
    fn a_reacquired_fit_starts_the_velocity_anew() {
        let dt = 1.0 / 30.0;
        let mut fits = VecDeque::new();
        let mut qd = [f64::NAN; 1];
        for (i, (q, reacquired)) in [(0.0, false), (0.1, false), (0.2, false), (1.5, true)]
            .into_iter()
            .enumerate()
        {
            push_fit(&mut fits, 3, f64::from(i as u32) * dt, &[q], reacquired);
        }
        // The jump to 1.5 rad is no movement: one fit, no velocity.
        assert_eq!(fits.len(), 1);
        least_squares_velocity(&fits, &mut qd);
        assert_eq!(qd, [0.0]);
        // Tracked on from there at 3 rad/s.
        push_fit(&mut fits, 3, 4.0 * dt, &[1.6], false);
        least_squares_velocity(&fits, &mut qd);
        assert!((qd[0] - 3.0).abs() < 1e-9, "{qd:?}");
        // Without the jump, the window of three tracked fits: 3 rad/s on a ramp.
        let mut fits = VecDeque::new();
        for i in 0..5u32 {
            push_fit(
                &mut fits,
                3,
                f64::from(i) * dt,
                &[0.1 * f64::from(i)],
                false,
            );
        }
        assert_eq!(fits.len(), 3);
        assert!((fits[0].1[0] - 0.2).abs() < 1e-12);
        least_squares_velocity(&fits, &mut qd);
        assert!((qd[0] - 3.0).abs() < 1e-9, "{qd:?}");
    }

    fn warning_for(scenario: &Scenario, model: &CellModel) -> Option<String> {
        camera_coverage_warning(&ProcNetConfig::default(), scenario, model).expect("warning")
    }

    fn perfect_masks() -> ProcNetConfig {
        ProcNetConfig {
            masks: MaskKind::GroundTruth,
            depth: true,
            ..ProcNetConfig::default()
        }
    }

    /// The oracle of a perfect network and fit (`masks = "true_pose"`) read at 1 in `stride`
    /// of the camera's frames, without latency, over 4 s of the default cell: asserts the
    /// estimate is the true human to rounding at each exposure, and returns the exposures,
    /// the ticks between them (after 0.1 s) and the largest error between them, m.
    fn true_pose_oracle(stride: usize) -> (usize, usize, f64) {
        let (scenario, model) = cell();
        let mut state = CellState::new(&model).expect("state");
        let config = ProcNetConfig {
            masks: MaskKind::TruePose,
            latency_s: 0.0,
            frame_stride: stride,
            ..ProcNetConfig::default()
        };
        let mut perception = ProcNetCamera::new(&config, &scenario, &model).expect("perception");
        let mut geometry = HumanGeometry::new(&model.human).expect("geometry");
        let mut kinematics = KinematicState::new(&model.human);
        kinematics.X_WB = model.X_WH;
        let (mut out, mut truth) = (HumanEstimate::default(), HumanEstimate::default());
        let (mut t, mut exposures, mut between, mut worst) = (0.0, 0, 0, 0.0_f64);
        while t < 4.0 {
            step(&model, &mut state, &RobotCommand::Nominal).expect("step");
            t += model.time_step_s();
            model
                .human
                .forward_kinematics(state.human_q(), &mut kinematics)
                .expect("fk");
            geometry.estimate_into(&model.human, &kinematics, state.human_qd(), &mut truth);
            let exposed = t + 1e-9 >= perception.next_frame_s;
            let input = PerceptionInput {
                t_s: t,
                model: &model,
                state: &state,
                truth: &truth,
                other_arm: &[],
            };
            perception.estimate(&input, &mut out);
            let err = out
                .parts
                .iter()
                .zip(&truth.parts)
                .map(|(e, x)| {
                    (e.capsule.a_W - x.capsule.a_W)
                        .length()
                        .max((e.capsule.b_W - x.capsule.b_W).length())
                })
                .fold(0.0, f64::max);
            assert_eq!(out.parts.len(), truth.parts.len(), "at {t} s");
            if exposed {
                exposures += 1;
                assert!(err < 1e-9, "{err} m off at an exposure ({t} s)");
            } else if t > 0.1 {
                between += 1;
                worst = worst.max(err);
            }
        }
        assert_eq!(perception.counts().estimates, perception.counts().frames);
        assert_eq!(perception.counts().frames, exposures);
        // The oracle fits nothing: no fit error to report.
        assert_eq!(perception.fit_error_m(), None);
        (exposures, between, worst)
    }

    /// At every frame (30 Hz): between frames the true joints carried by their velocity
    /// through the last two frames stay within a centimetre (the default cell's generator
    /// reaches at up to 2 m/s, 33 ms a frame).
    #[test]
    fn the_true_pose_oracle_is_the_truth_at_each_frame() {
        let (exposures, between, worst) = true_pose_oracle(1);
        assert!(exposures >= 119 && between > 800, "{exposures} / {between}");
        assert!(worst < 0.01, "{worst} m off between frames");
    }

    /// `frame_stride = 2` reads every other camera frame: half the exposures of 4 s at 30 Hz
    /// (each still the truth), and between them an estimate that is older and so farther
    /// off than at every frame, yet within 4 cm: carried by a velocity, the error of a
    /// constant acceleration grows with the square of the age, and the age here doubles.
    #[test]
    fn a_frame_stride_reads_one_in_so_many_camera_frames() {
        let (all, _, worst_all) = true_pose_oracle(1);
        let (exposures, between, worst) = true_pose_oracle(2);
        assert!(
            (all / 2..=all / 2 + 1).contains(&exposures),
            "{exposures} of {all}"
        );
        assert!(between > 900, "{between}");
        assert!(
            worst > worst_all && worst < 4.0 * 0.01,
            "{worst} m (every frame: {worst_all} m)"
        );
    }

    /// The oracle of a perfect trunk (`true_trunk`): on the whole body, every fit holds the
    /// trunk's joints where the true human's are (the arm still fitted to the masks).
    #[test]
    fn the_true_trunk_oracle_holds_the_true_trunk() {
        let (mut scenario, _) = cell();
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        scenario.set_human_model("human", path);
        let mut model = CellModel::new(&scenario, path).expect("cell");
        let config = ProcNetConfig {
            true_trunk: true,
            ..perfect_masks()
        };
        let perception = ProcNetCamera::new(&config, &scenario, &model).expect("perception");
        let trunk = perception
            .tracker
            .articulated()
            .trunk()
            .expect("the whole body has a trunk")
            .clone();
        // A person who turns, leans and steps over a second, the arm at rest: the trunk's
        // revolute joints to 0.1 rad per joint, the slides 5 cm.
        let dof = model.human.dof();
        let q = (0..=10)
            .map(|f| {
                let mut q = vec![0.0; dof];
                let s = f64::from(f) / 10.0;
                for &i in trunk.joints() {
                    q[i] = 0.1 * s;
                }
                for &i in trunk.slides() {
                    q[i] = 0.05 * s;
                }
                q
            })
            .collect();
        model.human_motion = workcell_sim::human::HumanMotion::recorded(
            workcell_sim::retarget::RecordedMotion {
                name: "turn".into(),
                rate_hz: 10.0,
                q,
                other_arm: Vec::new(),
            },
            0.0,
            workcell_sim::scenario::ClipEnd::Hold,
        );
        let mut state = CellState::new(&model).expect("state");
        let mut perception = ProcNetCamera::new(&config, &scenario, &model).expect("perception");
        let (truth, mut out) = (HumanEstimate::default(), HumanEstimate::default());
        let (mut t, mut checked, mut moved) = (0.0, 0, 0.0f64);
        while t < 1.0 {
            tick(
                &model,
                &mut state,
                &mut perception,
                &mut t,
                &truth,
                &mut out,
            );
            if let Some(fit) = perception.in_flight.back().and_then(|(_, m)| m.as_ref())
                && (t - perception.in_flight.back().map_or(0.0, |f| f.0)).abs() < 1e-12
            {
                checked += 1;
                for &i in trunk.joints().iter().chain(trunk.slides()) {
                    moved = moved.max(state.human_q()[i].abs());
                    assert!(
                        (fit.q[i] - state.human_q()[i]).abs() < 1e-12,
                        "joint {i}: {} against {} at {t} s",
                        fit.q[i],
                        state.human_q()[i]
                    );
                }
            }
        }
        assert!(checked >= 20, "{checked} fits checked");
        // The generator's trunk is not upright there (the fit would hold it upright).
        assert!(moved > 0.01, "the trunk moved at most {moved}");
    }

    /// The loop's conventions end to end: the cell's camera, every arm part's pixels in its
    /// frame, the tracker with the cell's human model, and the arm back in the world where
    /// the simulated human holds it, delivered after the camera's latency. On the paper's
    /// arm, whose fit from true masks is within a centimetre at its exposure.
    #[test]
    fn the_cell_camera_finds_the_arm_it_renders() {
        finds_the_arm_it_renders("human_arm", 0.01);
    }

    /// The same on the default cell's whole body, whose trunk is fitted first: its fits'
    /// mean error at their exposure was 10.4 mm over these four seconds (2026-12-07).
    #[test]
    fn the_cell_camera_finds_the_whole_bodys_arm_it_renders() {
        finds_the_arm_it_renders("human", 0.015);
    }

    /// [`the_cell_camera_finds_the_arm_it_renders`] on the human `human_model`, its fits'
    /// mean error at their exposure below `at_exposure_m`.
    fn finds_the_arm_it_renders(human_model: &str, at_exposure_m: f64) {
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        let mut scenario = Scenario::from_file(path).expect("scenario");
        scenario.set_human_model(human_model, path);
        let model = CellModel::new(&scenario, path).expect("cell");
        let mut state = CellState::new(&model).expect("state");
        let config = perfect_masks();
        let mut perception = ProcNetCamera::new(&config, &scenario, &model).expect("perception");
        let mut geometry = HumanGeometry::new(&model.human).expect("geometry");
        let mut kinematics = KinematicState::new(&model.human);
        kinematics.X_WB = model.X_WH;
        let (mut out, mut truth) = (HumanEstimate::default(), HumanEstimate::default());
        let mut t = 0.0;
        let (mut checked, mut ticks) = (0, 0);
        // Four seconds: the human reaches in (up to about 0.5 m/s at the wrist) after two.
        while t < 4.0 {
            ticks += 1;
            tick(
                &model,
                &mut state,
                &mut perception,
                &mut t,
                &truth,
                &mut out,
            );
            model
                .human
                .forward_kinematics(state.human_q(), &mut kinematics)
                .expect("fk");
            geometry.estimate_into(&model.human, &kinematics, state.human_qd(), &mut truth);
            if t < config.latency_s {
                assert!(
                    out.parts.is_empty(),
                    "an estimate before the first frame arrived"
                );
            }
            // Every tenth tick's estimate against the truth then.
            if ticks % 10 == 0 && t > 0.5 && !out.parts.is_empty() {
                checked += 1;
                let forearm = |e: &HumanEstimate| {
                    e.parts
                        .iter()
                        .find(|p| p.part == HumanPart::Forearm)
                        .map(|p| p.capsule)
                        .expect("a forearm")
                };
                let (e, x) = (forearm(&out), forearm(&truth));
                // 2.3 m away, RGB-D at 128x128; the estimate is 50 ms old and carried forward
                // by the joints' velocity: within 8 cm.
                let err = (e.a_W - x.a_W).length().max((e.b_W - x.b_W).length());
                assert!(err < 0.08, "forearm {err} m off at {t} s");
                assert!(out.uncertainty_m > 0.0 && out.uncertainty_m < 0.5);
            }
        }
        assert!(checked > 320, "{checked} ticks checked");
        let counts = perception.counts();
        assert!(counts.frames >= 119 && counts.estimates + counts.no_pose == counts.frames);
        // The fits themselves, at their exposure.
        let at_exposure = perception.fit_error_m().expect("fits measured");
        assert!(
            at_exposure > 0.0 && at_exposure < at_exposure_m,
            "{human_model}: {at_exposure} m"
        );
    }

    /// The unseen left arm's spheres hold its parts in any posture of the arm and the trunk
    /// (random configurations within the limits: every capsule inside its part's sphere
    /// about the shoulder), and are no larger than the straight arm's reach (the arm hanging
    /// straight touches them); a one-armed human has none.
    #[test]
    fn the_unseen_arms_reach_holds_it_in_any_posture() {
        use rand::{Rng, SeedableRng};
        let human = crate::robots::RobotModel::from_catalogue("human").expect("human");
        assert!(
            UnseenArm::of(&crate::robots::RobotModel::from_catalogue("human_arm").expect("arm"))
                .is_none()
        );
        let unseen = UnseenArm::of(&human).expect("a left arm");
        let mut geometry = HumanGeometry::new(&human).expect("geometry");
        let limits = human.position_limits();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut kinematics = KinematicState::new(&human);
        let mut tightest = [f64::INFINITY; 3];
        for k in 0..200 {
            let q: Vec<f64> = if k == 0 {
                limits
                    .iter()
                    .map(|[lo, hi]| 0.0_f64.clamp(*lo, *hi))
                    .collect()
            } else {
                limits
                    .iter()
                    .map(|[lo, hi]| rng.random_range(*lo..=*hi))
                    .collect()
            };
            human.forward_kinematics(&q, &mut kinematics).expect("fk");
            let mut truth = HumanEstimate::default();
            geometry.estimate_into(&human, &kinematics, &vec![0.0; q.len()], &mut truth);
            let mut spheres = HumanEstimate::default();
            unseen.place_into(&kinematics, &mut spheres);
            assert_eq!(spheres.parts.len(), 3);
            for (i, sphere) in spheres.parts.iter().enumerate() {
                let part = truth
                    .parts
                    .iter()
                    .find(|p| p.part == sphere.part)
                    .expect("part");
                let s = sphere.capsule.a_W;
                let far = (part.capsule.a_W - s)
                    .length()
                    .max((part.capsule.b_W - s).length())
                    + part.capsule.radius_m;
                assert!(
                    far <= sphere.capsule.radius_m + 1e-9,
                    "{:?}: {far} m",
                    sphere.part
                );
                tightest[i] = tightest[i].min(sphere.capsule.radius_m - far);
            }
        }
        // At the straight arm (the first configuration) the spheres touch.
        assert!(tightest.iter().all(|&g| g.abs() < 1e-9), "{tightest:?}");
    }

    /// The left arm's fit needs a left arm and the perfect segmenter's masks: a one-armed
    /// human, or a network's masks (the shipped networks have no left arm's classes), are
    /// refused with the key; on the whole body with true masks it is built. The unseen arm's
    /// reach is guarded where asked for on a human that has one.
    #[test]
    fn the_left_arms_fit_needs_a_left_arm_and_true_masks() {
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        let build = |human_model: &str, masks: MaskKind| {
            let mut scenario = Scenario::from_file(path).expect("scenario");
            scenario.set_human_model(human_model, path);
            let model = CellModel::new(&scenario, path).expect("cell");
            let config = ProcNetConfig {
                fit_left_arm: true,
                masks,
                depth: true,
                ..ProcNetConfig::default()
            };
            ProcNetCamera::new(&config, &scenario, &model).map(|p| p.left.is_some())
        };
        for (model, masks) in [
            ("human_arm", MaskKind::GroundTruth),
            ("human", MaskKind::Network),
        ] {
            let e = build(model, masks).expect_err("refused");
            assert!(e.to_string().contains("perception.fit_left_arm"), "{e}");
        }
        assert!(build("human", MaskKind::GroundTruth).expect("built"));
        // The unseen arm's reach is guarded only when asked for, and only on a left arm.
        let guard = |human_model: &str, guard_unseen_left_arm: bool| {
            let mut scenario = Scenario::from_file(path).expect("scenario");
            scenario.set_human_model(human_model, path);
            let model = CellModel::new(&scenario, path).expect("cell");
            let config = ProcNetConfig {
                guard_unseen_left_arm,
                ..perfect_masks()
            };
            let p = ProcNetCamera::new(&config, &scenario, &model).expect("perception");
            p.unseen_left.is_some()
        };
        assert!(guard("human", true) && !guard("human", false) && !guard("human_arm", true));
    }

    /// A camera that stops delivering frames: the estimate ages out after `MAX_AGE_S` and
    /// the filter then sees nobody (and brakes).
    #[test]
    fn a_failed_camera_leaves_no_estimate_after_the_maximum_age() {
        let (scenario, model) = cell();
        let mut state = CellState::new(&model).expect("state");
        let config = ProcNetConfig {
            camera_fails_at_s: Some(0.5),
            ..perfect_masks()
        };
        let mut perception = ProcNetCamera::new(&config, &scenario, &model).expect("perception");
        let truth = HumanEstimate::default();
        let mut out = HumanEstimate::default();
        let dt = model.time_step_s();
        let (mut t, mut last_seen) = (0.0, 0.0);
        while t < 1.2 {
            tick(
                &model,
                &mut state,
                &mut perception,
                &mut t,
                &truth,
                &mut out,
            );
            if !out.parts.is_empty() {
                last_seen = t;
            }
        }
        // The last frame before the failure was exposed before 0.5 s and arrived 50 ms
        // later; its estimate is dropped once older than MAX_AGE_S.
        assert!(
            last_seen > 0.5 && last_seen <= 0.5 + MAX_AGE_S + dt,
            "last seen at {last_seen} s"
        );
        assert!(perception.counts().no_frame >= 20);
    }

    /// A scenario's floor replaces the calibrated one and is the least of a kept track's
    /// floors; the hidden bands keep theirs (the radius never falls below the floor).
    #[test]
    fn a_scenarios_floor_is_the_least_of_every_floor() {
        let measured = Calibration {
            scale: 1.0,
            floor_m: 0.3,
            hidden_floors_m: [0.3, 0.4, 0.6],
            tracked_floors_m: Some([0.02, 0.1, 0.2, 0.3]),
            confident: Some(ConfidentFloors {
                min_gain: 0.7,
                floors_m: [0.01, 0.05, 0.1, 0.3],
            }),
            ..Calibration::UNCALIBRATED
        };
        assert_eq!(with_overrides(measured, None, None), measured);
        let own = with_overrides(measured, Some(2.0), Some(0.15));
        assert_eq!((own.scale, own.floor_m), (2.0, 0.15));
        assert_eq!(own.tracked_floors_m, Some([0.15, 0.15, 0.2, 0.3]));
        assert_eq!(
            own.confident.map(|c| c.floors_m),
            Some([0.15, 0.15, 0.15, 0.3])
        );
        assert_eq!(own.hidden_floors_m, measured.hidden_floors_m);
        for hidden_share in [0.0, 0.3, 0.6, 0.9] {
            for (tracked, gain) in [(false, 0.5), (true, 0.5), (false, 0.8), (true, 0.8)] {
                let fit = BoundInputs {
                    sigma_m: 0.0,
                    spread_m: 0.0,
                    hidden_share,
                    gain,
                    confirmed: false,
                    tracked,
                };
                assert!(own.radius(&fit) >= 0.15);
            }
        }
    }

    /// The artificial occluder hides the configured share of the forearm's pixels,
    /// blackens them in the frame and puts its own depth in the depth image there.
    #[test]
    fn the_occluder_hides_its_share_of_the_forearm() {
        let (scenario, model) = cell();
        let config = ProcNetConfig {
            occlusion: 0.7,
            ..perfect_masks()
        };
        let mut perception = ProcNetCamera::new(&config, &scenario, &model).expect("perception");
        let state = CellState::new(&model).expect("state");
        perception.scene.update(&state);
        perception
            .renderer
            .render(
                &perception.scene.scene,
                &perception.camera,
                &mut perception.frame,
            )
            .expect("render");
        let mut classes = perception.frame.classes(&perception.scene.scene);
        let forearm = |c: &[u8]| c.iter().filter(|&&v| v == Class::Forearm as u8).count();
        let before = forearm(&classes);
        assert!(before > 50, "{before} forearm pixels");
        perception.occlude(&mut classes);
        let hidden = 1.0 - forearm(&classes) as f64 / before as f64;
        // Within one step of the disc's size of the target.
        assert!((hidden - 0.7).abs() < 0.1, "{hidden}");
        let black = classes
            .iter()
            .enumerate()
            .filter(|(p, _)| perception.frame.rgb[3 * p..3 * p + 3] == [0, 0, 0])
            .count();
        assert!(black >= before - forearm(&classes));
        let at_occluder = perception
            .frame
            .depth_m
            .iter()
            .filter(|&&z| z == OCCLUDER_DEPTH_M)
            .count();
        assert!(at_occluder >= before - forearm(&classes), "{at_occluder}");
    }
}
