//! Pose evaluation on a dataset split, in the layout of the paper's Table 2, by either method
//! ([`PoseMethod`]).
//!
//! Every sequence is tracked from its first frame: the estimator searches globally on frame 0
//! and whenever the track is lost, and climbs from the previous pose otherwise. Frame 0 is
//! left out of the statistics (as in the segmentation evaluation: ProcNet has not yet seen
//! any motion), and so are frames whose forearm is out of view.
//!
//! Errors are taken at the forearm's centre. With the paper's method they are of the estimate
//! or its end-for-end twin ([`RigidModel::twin`]), whichever is nearer the truth in rotation:
//! the forearm's mask cannot tell them apart. The articulated fit's hand tells the wrist from
//! the elbow, so its errors are of the estimate itself. Yaw, pitch and roll are the URDF
//! angles of the forearm link frame in the camera frame (as the dataset's labels give them);
//! besides them, the error of the forearm's axis direction and its *spin* (rotation about its
//! own axis, which two thin bones barely show) are reported on their own.

mod metrics;
mod report;
#[cfg(test)]
mod report_tests;
mod sources;

pub use metrics::{FrameResult, PoseError, Summary, pose_error, pose_error_with};
pub use report::{PAPER_AVERAGE, PAPER_TABLE2, compare_markdown};
pub use sources::{GroundTruthAtSize, GroundTruthMasks, MaskSource, NetworkMasks, VisibleMasks};

use std::time::Instant;

use workcell_render::dataset::{Dataset, Split};
use workcell_render::{Camera, Class, CpuRenderer};
use workcell_robots::math::Pose;

use crate::error::{PerceptionError, Result};
use crate::pose::{ArmFitConfig, ArmFitter, ArmModel, ArticulatedArm, PoseConfig, PoseEstimator};

/// How the forearm's pose is found.
#[derive(Debug, Clone, PartialEq)]
pub enum PoseMethod {
    /// The paper's: the forearm's 6-DoF pose from its mask alone ([`PoseEstimator`]), the
    /// elbow anchored to the shoulder when `anchored`.
    Paper { anchored: bool, config: PoseConfig },
    /// The human model's joints fitted to every arm part's mask ([`ArmFitter`]); with
    /// `depth`, the dataset's depth images join the score (RGB-D). With `true_trunk`, the
    /// trunk is held where the labels put it ([`ArmFitter::hold_trunk_at`]) instead of
    /// fitted or upright: what the arm's fit scores given a perfect trunk.
    Articulated {
        config: Box<ArmFitConfig>,
        depth: bool,
        true_trunk: bool,
    },
}

impl PoseMethod {
    /// How reports name it.
    #[must_use]
    pub fn describe(&self) -> String {
        match self {
            PoseMethod::Paper { anchored, config } => format!(
                "the paper's method (the forearm's mask alone), {}, {}",
                if config.roi {
                    "in a region of interest"
                } else {
                    "over the whole image"
                },
                if *anchored {
                    "elbow anchored to the shoulder"
                } else {
                    "no anchor"
                }
            ),
            PoseMethod::Articulated {
                depth, true_trunk, ..
            } => format!(
                "articulated: the arm's joints fitted to the upper arm, forearm and hand masks{}{}",
                if *depth {
                    " and the depth image (RGB-D)"
                } else {
                    ""
                },
                if *true_trunk {
                    ", the trunk held at the labels' (a perfect trunk)"
                } else {
                    ""
                }
            ),
        }
    }
}

/// Frames without a pose kept per sequence for the contact sheet ([`PoseEvaluation::no_pose`]).
pub const NO_POSE_KEPT_PER_SEQUENCE: usize = 4;

/// A scored frame without a pose, kept for the contact sheet of why.
#[derive(Debug, Clone, PartialEq)]
pub struct NoPoseFrame {
    /// Its index in [`PoseEvaluation::frames`].
    pub index: usize,
    /// The input; the true arm parts without the occluder (every other class 0); in place of
    /// a prediction, the arm parts of the masks the estimator read (the most probable part
    /// above the fit's threshold, else 0; the forearm alone for the paper's method).
    pub images: workcell_procnet::eval::SheetImages,
}

/// A split's pose evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseEvaluation {
    pub masks: String,
    pub split: String,
    pub sequences: usize,
    /// [`PoseMethod::describe`].
    pub method: String,
    pub frames: Vec<FrameResult>,
    /// The first [`NO_POSE_KEPT_PER_SEQUENCE`] frames of each sequence without a pose.
    pub no_pose: Vec<NoPoseFrame>,
}

impl PoseEvaluation {
    /// Up to `n` of the kept frames without a pose, spread over the sequences: each
    /// sequence's first, then each one's second, and so on; in split order.
    #[must_use]
    pub fn no_pose_sample(&self, n: usize) -> Vec<&NoPoseFrame> {
        let sequence = |f: &NoPoseFrame| self.frames.get(f.index).map(|r| r.sequence);
        let mut rank = Vec::with_capacity(self.no_pose.len());
        for (i, f) in self.no_pose.iter().enumerate() {
            let before = self.no_pose[..i]
                .iter()
                .filter(|g| sequence(g) == sequence(f))
                .count();
            rank.push((before, f.index, f));
        }
        rank.sort_by_key(|&(before, index, _)| (before, index));
        let mut chosen: Vec<&NoPoseFrame> = rank.into_iter().take(n).map(|r| r.2).collect();
        chosen.sort_by_key(|f| f.index);
        chosen
    }
}

/// The arm parts of `classes` (every other class 0).
fn arm_parts_of(classes: &[u8]) -> Vec<u8> {
    let parts = crate::pose::FITTED_PARTS.map(|p| Class::of_part(p) as u8);
    classes
        .iter()
        .map(|&c| if parts.contains(&c) { c } else { 0 })
        .collect()
}

/// Per pixel the most probable of the masks' arm parts above `threshold`, else 0.
fn arm_parts_in(masks: &crate::pose::ArmMasks, threshold: f32) -> Vec<u8> {
    let n = masks.width * masks.height;
    (0..n)
        .map(|i| {
            (0..3)
                .map(|p| (p, masks.parts[p][i]))
                .filter(|&(_, v)| v > threshold)
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(0, |(p, _)| {
                    Class::of_part(crate::pose::FITTED_PARTS[p]) as u8
                })
        })
        .collect()
}

/// The estimator of either method.
enum Estimator {
    Paper(Box<PoseEstimator<CpuRenderer>>),
    Articulated(Box<ArmFitter<CpuRenderer>>),
}

/// What either method found in a frame, in the evaluation's terms.
struct Found {
    X_CO: Pose,
    reacquired: bool,
    confirmed: bool,
    f_m: f64,
    gain: f64,
    uncertainty_m: f64,
    /// The articulated fit's curvature and hypotheses' spreads, m (NaN for the paper's).
    sigma_m: f64,
    spread_m: f64,
    /// The articulated fit's [`crate::pose::ArmFit::hidden_share`] (NaN for the paper's).
    hidden_share: f64,
    renders: usize,
    /// The fitted trunk's error against the labels' ([`crate::pose::TrunkModel::error`]:
    /// rad, m); NaN without a trunk that moves or for the paper's method.
    trunk_error: [f64; 2],
}

/// Tracks the forearm through every sequence of `split` with masks from `source`, by
/// `method`. `progress` gets (sequences done, total).
///
/// # Errors
/// The dataset, the mask source or the renderer fails; the split is empty.
pub fn evaluate_pose(
    dataset: &Dataset,
    split: Split,
    source: &mut dyn MaskSource,
    method: &PoseMethod,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<PoseEvaluation> {
    let setup = ArmModel::of_dataset(dataset)?;
    let model = setup.forearm.clone();
    let entries: Vec<_> = dataset.entries(Some(split)).cloned().collect();
    if entries.is_empty() {
        return Err(PerceptionError::Input {
            message: format!(
                "the dataset at {} has no {} sequences",
                dataset.root.display(),
                split.name()
            ),
        });
    }
    let anchored =
        matches!(method, PoseMethod::Paper { anchored: true, .. }) && setup.shoulder_W.is_some();
    let mut estimator = match method {
        PoseMethod::Paper { config, .. } => Estimator::Paper(Box::new(PoseEstimator::new(
            CpuRenderer::new(),
            model.clone(),
            config.clone(),
        ))),
        PoseMethod::Articulated { config, .. } => Estimator::Articulated(Box::new(ArmFitter::new(
            CpuRenderer::new(),
            ArticulatedArm::of_dataset(dataset)?,
            (**config).clone(),
        ))),
    };
    // Mask values above this are a part's support, for the contact sheet.
    let threshold = match method {
        PoseMethod::Paper { config, .. } => config.threshold,
        PoseMethod::Articulated { config, .. } => config.threshold,
    };
    let mut frames = Vec::new();
    let mut no_pose = Vec::new();
    for (k, entry) in entries.iter().enumerate() {
        let mut kept = 0;
        let seq = dataset.load(entry)?;
        source.start();
        match &mut estimator {
            Estimator::Paper(e) => e.reset(),
            Estimator::Articulated(f) => f.reset(),
        }
        for t in 0..seq.len() {
            let labels = &seq.labels[t];
            let camera = Camera::from(&labels.camera);
            let t0 = Instant::now();
            let mut truth_gain = [f64::NAN; 4];
            // The masks' arm parts, for the contact sheet when there is no pose.
            let mut read = None;
            let (found, mask_ms, pose_ms) = match &mut estimator {
                Estimator::Articulated(fitter) => {
                    let mut masks = source.arm(&seq, t)?;
                    if matches!(method, PoseMethod::Articulated { depth: true, .. }) {
                        masks.depth_m = Some(dataset.depth(entry, t)?);
                    }
                    let mask_ms = t0.elapsed().as_secs_f64() * 1e3;
                    if matches!(
                        method,
                        PoseMethod::Articulated {
                            true_trunk: true,
                            ..
                        }
                    ) {
                        fitter.hold_trunk_at(&labels.human_q)?;
                    }
                    let t1 = Instant::now();
                    let outcome = fitter.fit(&camera, &masks)?;
                    let pose_ms = t1.elapsed().as_secs_f64() * 1e3;
                    if labels.human_q.len() == fitter.arm().model_dof()
                        && let Some(g) = fitter.gain_at(&camera, &masks, &labels.human_q)?
                    {
                        let [upper, forearm, hand] = g.parts;
                        truth_gain = [g.total, upper, forearm, hand];
                    }
                    if outcome.is_err() && kept < NO_POSE_KEPT_PER_SEQUENCE {
                        read = Some(arm_parts_in(&masks, threshold));
                    }
                    let trunk_error = match (&outcome, fitter.arm().trunk()) {
                        (Ok(fit), Some(trunk)) => trunk.error(&fit.q, &labels.human_q),
                        _ => None,
                    }
                    .unwrap_or([f64::NAN; 2]);
                    let found = outcome.map(|fit| Found {
                        X_CO: fit.X_CO(),
                        reacquired: fit.reacquired,
                        confirmed: fit.confirmed,
                        f_m: fit.f_m,
                        gain: fit.gain,
                        uncertainty_m: fit.uncertainty_m,
                        sigma_m: fit.sigma_m,
                        spread_m: fit.spread_m,
                        hidden_share: fit.hidden_share,
                        renders: fit.renders,
                        trunk_error,
                    });
                    (found, mask_ms, pose_ms)
                }
                Estimator::Paper(estimator) => {
                    let mask = source.forearm(&seq, t)?;
                    let mask_ms = t0.elapsed().as_secs_f64() * 1e3;
                    estimator.set_anchor(if anchored {
                        setup.anchor(&camera.X_WC)
                    } else {
                        None
                    });
                    let t1 = Instant::now();
                    let outcome = estimator.estimate(&camera, &mask)?;
                    let pose_ms = t1.elapsed().as_secs_f64() * 1e3;
                    if outcome.is_err() && kept < NO_POSE_KEPT_PER_SEQUENCE {
                        read = Some(
                            mask.iter()
                                .map(|&v| {
                                    if v > threshold {
                                        Class::Forearm as u8
                                    } else {
                                        0
                                    }
                                })
                                .collect(),
                        );
                    }
                    let found = outcome.map(|e| Found {
                        X_CO: e.X_CO,
                        reacquired: e.reacquired,
                        confirmed: false,
                        f_m: e.f_m,
                        gain: e.gain,
                        uncertainty_m: e.uncertainty_m,
                        sigma_m: f64::NAN,
                        spread_m: f64::NAN,
                        hidden_share: f64::NAN,
                        renders: e.renders,
                        trunk_error: [f64::NAN; 2],
                    });
                    (found, mask_ms, pose_ms)
                }
            };
            let Some(part) = labels.part(Class::Forearm) else {
                continue;
            };
            let Some(occlusion) = part.occlusion else {
                continue; // out of view
            };
            if t == 0 {
                continue;
            }
            let truth = Pose::from(&part.X_CP);
            let (mut reacquired, mut confirmed, mut fm, mut gain, mut unc, mut renders) =
                (false, false, 0.0, 0.0, 0.0, 0);
            let (mut sigma_m, mut spread_m, mut hidden_share) = (f64::NAN, f64::NAN, f64::NAN);
            let mut trunk_error = [f64::NAN; 2];
            let outcome = found.map(|e| {
                (reacquired, confirmed, fm, gain, unc, renders) = (
                    e.reacquired,
                    e.confirmed,
                    e.f_m,
                    e.gain,
                    e.uncertainty_m,
                    e.renders,
                );
                (sigma_m, spread_m, hidden_share) = (e.sigma_m, e.spread_m, e.hidden_share);
                trunk_error = e.trunk_error;
                // The hand tells the articulated fit's wrist from its elbow: no twin.
                pose_error_with(
                    &model,
                    &e.X_CO,
                    &truth,
                    matches!(estimator, Estimator::Paper(_)),
                )
            });
            if let (Err(_), Some(masks)) = (&outcome, read) {
                let n = (seq.width * seq.height) as usize;
                no_pose.push(NoPoseFrame {
                    index: frames.len(),
                    images: workcell_procnet::eval::SheetImages {
                        rgb: workcell_procnet::eval::interleave(seq.rgb_frame(t), n),
                        truth: arm_parts_of(seq.class_frame(t)),
                        predicted: masks,
                        width: seq.width as usize,
                        height: seq.height as usize,
                    },
                });
                kept += 1;
            }
            frames.push(FrameResult {
                sequence: entry.index,
                frame: t,
                recorded: entry.clip.is_some(),
                distance_class: entry.distance_class.clone(),
                occlusion_level: entry.occlusion_level.clone(),
                distance_m: model.centre(&truth).length(),
                occlusion,
                outcome,
                reacquired,
                confirmed,
                f_m: fm,
                gain,
                uncertainty_m: unc,
                sigma_m,
                spread_m,
                hidden_share,
                pose_ms,
                mask_ms,
                renders,
                truth_gain,
                trunk_error,
            });
        }
        progress(k + 1, entries.len());
    }
    Ok(PoseEvaluation {
        masks: source.name(),
        split: split.name().to_string(),
        sequences: entries.len(),
        method: match method {
            PoseMethod::Paper { config, .. } => PoseMethod::Paper {
                anchored,
                config: config.clone(),
            }
            .describe(),
            PoseMethod::Articulated { .. } => method.describe(),
        },
        frames,
        no_pose,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_robots::RobotModel;
    use workcell_robots::math::Vector;

    use crate::pose::RigidModel;
    use workcell_robots::math::{Rotation, pose_from_xyz_rpy};

    fn model() -> RigidModel {
        let human = RobotModel::from_catalogue("human_arm").expect("catalogue human");
        ArmModel::new(&human, &Pose::IDENTITY)
            .expect("forearm")
            .forearm
    }

    #[test]
    fn errors_of_known_displacements() {
        let model = model();
        let truth = pose_from_xyz_rpy([0.1, 0.2, 3.0], [0.2, -0.3, 0.4]);
        let same = pose_error(&model, &truth, &truth);
        assert!(same.position_cm < 1e-9 && same.axis_deg < 1e-6 && same.spin_deg < 1e-6);
        // 3 cm along x.
        let moved = Pose::from_parts(
            truth.translation + Vector::new(0.03, 0.0, 0.0),
            truth.rotation,
        );
        assert!((pose_error(&model, &moved, &truth).position_cm - 3.0).abs() < 1e-9);
        // The twin is no error at all.
        let twin = pose_error(&model, &model.twin(&truth), &truth);
        assert!(twin.flipped && twin.position_cm < 1e-9 && twin.axis_deg < 1e-6);
        // A 20-degree spin about the forearm's axis moves neither the centre nor the axis.
        let spun = model.pose(
            model.centre(&truth),
            truth.rotation * Rotation::from_axis_angle(model.axis_O, 20f64.to_radians()),
        );
        let e = pose_error(&model, &spun, &truth);
        assert!(e.position_cm < 1e-9 && e.axis_deg < 1e-6, "{e:?}");
        assert!((e.spin_deg - 20.0).abs() < 1e-6, "{e:?}");
        // A 10-degree tilt of the axis is 10 degrees of axis error and no spin.
        let tilted = model.pose(
            model.centre(&truth),
            truth.rotation * Rotation::from_axis_angle(Vector::X, 10f64.to_radians()),
        );
        let e = pose_error(&model, &tilted, &truth);
        assert!(
            (e.axis_deg - 10.0).abs() < 1e-6 && e.spin_deg < 1e-6,
            "{e:?}"
        );
    }
}
