//! The arm's pose from every part it shows: articulated render-and-compare.
//!
//! The forearm's mask alone leaves its depth along two rays open and, with the elbow hung
//! from the shoulder, a two-fold mirror ([`crate::pose`]). The arm shows more than its
//! forearm: this fit moves the human model's joints (both shoulder angles and the elbow, and
//! whatever else the model has) and compares every arm part's render with that part's mask
//! at once. The shoulder stays where the human model and its base pose put it, the upper
//! arm's mask fixes where the elbow is, the hand's mask which end of the forearm is the
//! wrist.
//!
//! **The score** of a configuration `q` is, summed over the parts `p` (upper arm, forearm,
//! hand) and the pixels their renders cover (the covered fraction `c` of each pixel, from
//! [`ArmFitConfig::supersample`]^2 samples):
//!
//! ```text
//! score(q) = sum_p sum_px c (s_p - alpha min(d_p, cap)) / M  -  prior(q)
//! s_p = m_p - m_background
//! ```
//!
//! - `s_p` is +1 on the part's own pixels and -1 on the background; on pixels of something
//!   that may hide the part (the robot, the torso, another arm part) it is 0: a part behind
//!   the robot is neither rewarded nor punished. With binary masks `sum c s_p / M` is the
//!   paper's `f_m` gain over rendering nothing, `(true positives - false positives) / mask
//!   pixels`, summed over the parts: 1 for a perfect fit ([`ArmFit::gain`]).
//! - `d_p` is the distance in pixels to the part's mask (a distance transform): a render
//!   beside its mask still has a slope towards it, where the overlap alone is flat.
//! - `M` is the mask's mass, all parts together.
//! - `prior(q)`: tracking, a constant-velocity prediction from the last two fits,
//!   `w sum ((q - q_pred) / sigma)^2 / dof`.
//!
//! A part renders as row spans ([`SpanBatch`]: each sample row's first and last covered
//! sample), from the triangles of its visuals that are not inside another of them
//! ([`RenderMesh::outer_union`]: the human model's bones and the caps between its limb
//! segments left out, 724 of 2,544 triangles kept, the same masks). A part's row is nearly
//! always one run, and a span sums in two lookups of the row's prefix sums. Both took the
//! tracked fit from 18.3 to 10.6-11.0 ms a frame on the cell's camera, the global search
//! from 289 to 121-134 ms (`workcell bench-perception --depth --frames 900`).
//!
//! **The search.** Tracking, a climb from the prediction: each iteration renders the
//! configurations one step along each joint either way (a central-difference gradient and
//! each joint's curvature), then three points along the gradient and a few random probes;
//! the best one is taken and the step grows by 1.5, or halves when none is better, down to
//! [`ArmFitConfig::min_step_rad`]. Without a track, or when every tracked hypothesis ends
//! below [`ArmFitConfig::search_below_gain`], a global search renders a grid over the joints'
//! ranges and climbs the best few distinct cells ([`ArmFit::reacquired`]); the tracked
//! climbs compete with them. A track that explains the masks poorly has often followed a
//! wrong optimum on masks the network misread: on the validation split with ProcNet's masks
//! and depth, searching below a gain of 0.55 (6 % of frames) took the 99th percentile of the
//! forearm's error from 6.0 to 4.9 cm.
//!
//! **Acceptance.** A fit is a pose when its gain reaches [`ArmFitConfig::min_gain`] (0.3).
//! Below it, down to [`ArmFitConfig::confirm_min_gain`], the best fit is a pose only when the
//! frame before put the forearm's centre and wrist within [`ArmFitConfig::confirm_m`] of it
//! (its pose, or its own best fit below the threshold, which is tracked on as a candidate;
//! [`ArmFit::confirmed`]). Masks that show a far, half-hidden arm faintly give such fits frame
//! after frame in one place; masks that miss the arm give them here and there. A fit that
//! reaches `min_gain` always wins over a fainter one, so a faint track never keeps a better
//! fit out. Whether it pays is the masks' ([`Calibration::measured`]): from 0.2 for the
//! network that reads depth, whose confirmed poses are either right or far off, so their
//! bound is at least [`Calibration::confirmed_floor_m`]; off for the RGB network, whose
//! confirmed fits were mostly wrong arms.
//!
//! **Hypotheses.** Far from the camera a silhouette is nearly an orthographic projection, and
//! the arm mirrored through the plane across the line of sight that holds the shoulder
//! renders the same masks: the masks cannot tell the two apart. The fit keeps every climb
//! within [`ArmFitConfig::ambiguity_gain`] of the best that puts the forearm elsewhere (up
//! to [`ArmFitConfig::hypotheses`]) and tracks each on; a hypothesis that stops explaining
//! the masks as well as the best is dropped.
//!
//! **Uncertainty.** The joints' covariance from the score's Hessian at the fit (the
//! displacements that cost two mask pixels, correlated joints included: far away, moving the
//! arm along the line of sight takes both shoulder angles), mapped through the forearm's
//! kinematics to metres at its centre and its far end (scaled by
//! [`ArmFitConfig::uncertainty_scale`], plus a floor); and the farthest the surviving
//! hypotheses put the forearm's centre or wrist from the best's. [`ArmFit::uncertainty_m`] is
//! the larger. The floor grows with how much of the forearm's region the depth image shows
//! hidden by something in front of the arm ([`ArmFit::hidden_share`]: pixels nearer than the
//! fitted arm, such as the paper's black occluder, which the datasets and the closed loop put
//! at `workcell_render::occlusion::OCCLUDER_DEPTH_M`): the masks hold less of a hidden
//! forearm. Calibrated ([`Calibration`]), 99 % of a split's frames have their forearm's
//! centre and wrist within it. The depth term skips pixels nearer than any point the arm can
//! reach ([`ArticulatedArm::nearest_depth_m`]): they say nothing of the arm's depth.

use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_render::{Camera, Class, MaskBatch, RenderMesh, Renderer, SpanBatch};
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{HumanPart, LinkId, RobotModel, Shape};

use super::image::crop_camera;
use super::{NoPose, RigidModel, f_m};
use crate::arm::POSE_MESH_SEGMENTS;
use crate::error::{PerceptionError, Result};

/// The parts fitted, in the order of [`ArmMasks::parts`] and [`ArmFit::X_CL`].
pub const FITTED_PARTS: [HumanPart; 3] = HumanPart::ARM;

/// Settings of the articulated fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmFitConfig {
    /// A fit whose gain is below this is no pose (and ends a track), unless it is
    /// confirmed (`confirm_min_gain`). Default 0.3.
    pub min_gain: f64,
    /// When nothing reaches `min_gain`, the best fit with a gain from this up to `min_gain`
    /// (tracked or found by the global search) is a pose if the frame before confirms it:
    /// that frame's pose, or its own best such fit, put the forearm's centre and wrist within
    /// `confirm_m` of this one's (in the world frame). Masks that show the arm faintly give
    /// such fits frame after frame in one place; masks that miss the arm give them here and
    /// there. Measured per source of masks ([`Calibration::confirm_min_gain`]). Default
    /// infinity: off.
    pub confirm_min_gain: f64,
    /// How near the frame before must put the forearm's centre and wrist to confirm a fit
    /// below `min_gain`, m. Default 0.1 (at 30 Hz, 3 m/s).
    pub confirm_m: f64,
    /// Grid points per joint in the global search. Default 12.
    pub grid: usize,
    /// Grid cells climbed by the global search. Default 10.
    pub refine: usize,
    /// Climb iterations at most. Default 40.
    pub max_iterations: usize,
    /// First step of the climb, rad. Default 0.05.
    pub initial_step_rad: f64,
    /// The climb stops when its step falls below this, rad (the Newton refinement finishes
    /// what it leaves). Default 0.005.
    pub min_step_rad: f64,
    /// Random probes per climb iteration. Default 2.
    pub random_probes: usize,
    /// `alpha`: the cost of a rendered pixel per pixel of distance to its part's mask.
    /// Default 0.05.
    pub distance_weight: f64,
    /// Distances are capped at this many pixels. Default 16.
    pub distance_cap_px: f32,
    /// The constant-velocity prior's spread per joint, rad. Default 0.15.
    pub prior_sigma_rad: f64,
    /// `w`: the prior's weight, in gain per sigma squared. Default 0.01.
    pub prior_weight: f64,
    /// Samples per pixel side of the renders of the final refinement and its score. Default 2.
    pub supersample: u32,
    /// Samples per pixel side of the renders while climbing and searching: a quarter of the
    /// pixels at 1 against 2 (the refinement then finishes at `supersample`). Default 1.
    pub climb_supersample: u32,
    /// Mask values above this are a part's support. Default 0.5.
    pub threshold: f32,
    /// Hypotheses tracked at most: the best fit and those within `ambiguity_gain` of its
    /// gain that put the forearm elsewhere. Default 3.
    pub hypotheses: usize,
    /// A hypothesis this far below the best gain is dropped. Default 0.05.
    pub ambiguity_gain: f64,
    /// Hypotheses whose forearm centres and wrists are all within this are one, m.
    /// Default 0.03.
    pub distinct_m: f64,
    /// Step of the central differences of the score's Hessian at the fit, rad. Default 0.02.
    pub hessian_step_rad: f64,
    /// Newton steps on the score's local quadratic after the climb, at most. Default 3.
    pub newton_steps: usize,
    /// The curvature part of the uncertainty is scaled by this. Default 1.
    pub uncertainty_scale: f64,
    /// Added to the scaled curvature part, m: the error that no curvature shows (masks
    /// that put the arm a little off everywhere). Default 0.
    pub uncertainty_floor_m: f64,
    /// The floor instead where the depth image shows something in front of the arm over a
    /// quarter, a half or three quarters of the forearm's region ([`ArmFit::hidden_share`];
    /// [`Calibration::floor_at`]), m. Default 0 (the floor alone).
    pub uncertainty_hidden_floors_m: [f64; 3],
    /// The least uncertainty of a pose confirmed below `min_gain`
    /// ([`Calibration::confirmed_floor_m`]), m. Default 0.
    pub uncertainty_confirmed_floor_m: f64,
    /// The global search runs, beside the tracked hypotheses, when their best gain is below
    /// this: a track that explains the masks this poorly has likely followed a wrong
    /// optimum. Default 0.55.
    pub search_below_gain: f64,
    /// With a depth image: the spread of a part's seen surface about its model's, m.
    /// Default 0.03.
    pub depth_sigma_m: f64,
    /// With a depth image: the score a part's axis points lose at one `depth_sigma_m` of
    /// disagreement (mean over the points that land on their part's mask; at most 9 sigma
    /// squared each). Default 0.05.
    pub depth_weight: f64,
}

impl Default for ArmFitConfig {
    fn default() -> Self {
        Self {
            min_gain: 0.3,
            confirm_min_gain: f64::INFINITY,
            confirm_m: 0.1,
            grid: 12,
            refine: 10,
            max_iterations: 40,
            initial_step_rad: 0.05,
            min_step_rad: 0.005,
            random_probes: 2,
            distance_weight: 0.05,
            distance_cap_px: 16.0,
            prior_sigma_rad: 0.15,
            prior_weight: 0.01,
            supersample: 2,
            climb_supersample: 1,
            threshold: 0.5,
            hypotheses: 3,
            ambiguity_gain: 0.05,
            distinct_m: 0.03,
            hessian_step_rad: 0.02,
            newton_steps: 3,
            uncertainty_scale: 1.0,
            uncertainty_floor_m: 0.0,
            uncertainty_hidden_floors_m: [0.0; 3],
            uncertainty_confirmed_floor_m: 0.0,
            search_below_gain: 0.55,
            depth_sigma_m: 0.03,
            depth_weight: 0.05,
        }
    }
}

/// A part whose axis is within this cosine of the line of sight is seen end-on, and its
/// depth is left out of the score (0.9: within 26 degrees).
const END_ON_COS: f64 = 0.9;

/// A depth this much nearer than the nearest the arm can reach (or, for
/// [`ArmFit::hidden_share`], than the fitted arm) shows something in front of it, m: a margin
/// for the depth camera's noise.
pub const HIDDEN_MARGIN_M: f64 = 0.05;

/// What the fit measured for one source of masks: the uncertainty's calibration (`scale`,
/// `floor_m` and `hidden_floors_m` of [`ArmFitConfig`], fitted on the validation split so that
/// 99 % of its frames have the forearm's centre and wrist within the bound, in each band of
/// [`ArmFit::hidden_share`]: `scripts/calibrate_uncertainty.py`, on the per-frame CSV of
/// `workcell eval pose --split validation`), and whether a faint fit confirmed by the frame
/// before is a pose, with the floor of its bound (docs/perception.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    pub scale: f64,
    pub floor_m: f64,
    /// The floors where a quarter, a half, three quarters of the forearm's region is
    /// hidden ([`Calibration::floor_at`]).
    pub hidden_floors_m: [f64; 3],
    /// [`ArmFitConfig::confirm_min_gain`]: infinity where confirmed fits of these masks
    /// were measured to be wrong too often to be poses.
    pub confirm_min_gain: f64,
    /// The least bound of a confirmed pose, m: such fits are right or far off (the masks'
    /// faint arm, or a consistent wrong one), and the curvature tells neither.
    pub confirmed_floor_m: f64,
}

/// Where [`ArmFit::hidden_share`] starts each band of [`Calibration::hidden_floors_m`].
pub const HIDDEN_BANDS: [f64; 3] = [0.25, 0.5, 0.75];

/// Where the masks the fit reads come from, for [`Calibration::measured`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MaskOrigin {
    /// Each part's pixels in the rendered frame (true masks).
    Rendered,
    /// The shipped RGB ProcNet (`perception/weights/procnet-cpu.safetensors`).
    Network,
    /// The shipped ProcNet that reads the depth image too
    /// (`perception/weights/procnet-depth.safetensors`).
    DepthNetwork,
}

impl MaskOrigin {
    /// The shipped network of this kind: the one that reads depth where `reads_depth`.
    #[must_use]
    pub fn network(reads_depth: bool) -> Self {
        if reads_depth {
            Self::DepthNetwork
        } else {
            Self::Network
        }
    }
}

impl Calibration {
    /// The calibration measured for masks from `masks`, for a fit with or without the depth
    /// image; `None` for the one pair never measured: the network that reads depth, and a
    /// fit without it.
    #[must_use]
    pub fn measured(masks: MaskOrigin, depth: bool) -> Option<Self> {
        let (scale, floor_m, hidden_floors_m) = match (masks, depth) {
            // The validation split (docs/perception.md), the renders as row spans: true
            // masks with depth, 3,828 frames, 99 % within half the curvature's spread plus
            // 1.68 cm where under half the forearm's region is hidden (1,584 frames), 1.74 cm
            // up to three quarters (437), 33.8 cm beyond (1,807: the mirror, where the
            // occluder hides the forearm's depth); without depth, the mirror's misses, 38.5 cm.
            (MaskOrigin::Rendered, true) => (0.5, 0.0168, [0.0168, 0.0174, 0.3381]),
            (MaskOrigin::Rendered, false) => (0.0, 0.3851, [0.0; 3]),
            // ProcNet's masks with depth, 3,786 frames: 99 % within 3.22 cm where under a
            // quarter of the forearm's region is hidden (1,212 frames), 5.92 cm up to three
            // quarters (804), 31.5 cm beyond (1,770: wrong optima under the paper's heavy
            // occlusion); without depth (3,806 frames), 40.6 cm.
            (MaskOrigin::Network, true) => (0.0, 0.0322, [0.0592, 0.0592, 0.3154]),
            (MaskOrigin::Network, false) => (0.0, 0.4059, [0.0; 3]),
            // The network that reads depth, on the validation split's stored crops (3,786
            // frames) and the tracker's own crops (3,773) pooled, so that both kinds of
            // frames are covered: 99 % within the curvature's spread plus 2.33 cm where under
            // a quarter of the forearm's region is hidden, 6.34 cm up to three quarters,
            // 28.5 cm beyond (test: 99.77 % of 3,473 stored crops, 99.42 % of 3,475 tracker
            // crops).
            (MaskOrigin::DepthNetwork, true) => (1.0, 0.0233, [0.0634, 0.0634, 0.2850]),
            (MaskOrigin::DepthNetwork, false) => return None,
        };
        // Faint fits confirmed by the frame before: poses for the network that reads depth
        // (validation, stored and tracker's crops: 12 such poses, the forearm's centre or
        // wrist 4-11 cm off or 40-65 cm, none beyond 65 cm); not for the RGB network, whose confirmed fits were mostly
        // wrong arms held in one place (test: 9 of 15 more than 40 cm off without depth,
        // 1183's 54-63 cm with it); true masks give none.
        let (confirm_min_gain, confirmed_floor_m) = match masks {
            MaskOrigin::DepthNetwork => (0.2, 0.65),
            MaskOrigin::Rendered | MaskOrigin::Network => (f64::INFINITY, 0.0),
        };
        Some(Self {
            scale,
            floor_m,
            hidden_floors_m,
            confirm_min_gain,
            confirmed_floor_m,
        })
    }

    /// `config` with this calibration.
    #[must_use]
    pub fn apply(self, config: ArmFitConfig) -> ArmFitConfig {
        ArmFitConfig {
            uncertainty_scale: self.scale,
            uncertainty_floor_m: self.floor_m,
            uncertainty_hidden_floors_m: self.hidden_floors_m,
            confirm_min_gain: self.confirm_min_gain,
            uncertainty_confirmed_floor_m: self.confirmed_floor_m,
            ..config
        }
    }

    /// The radius of a fit whose curvature spreads the forearm's centre and wrist by
    /// `sigma_m`, whose hypotheses lie `spread_m` apart and whose forearm's region is
    /// `hidden_share` hidden, under this calibration (what [`ArmFit::uncertainty_m`]
    /// reports): `scale sigma + floor`, or the spread where that is larger; for a pose
    /// `confirmed` below the gain threshold, at least `confirmed_floor_m`.
    #[must_use]
    pub fn radius(&self, sigma_m: f64, spread_m: f64, hidden_share: f64, confirmed: bool) -> f64 {
        let r = (self.scale * sigma_m + self.floor_at(hidden_share)).max(spread_m);
        if confirmed {
            r.max(self.confirmed_floor_m)
        } else {
            r
        }
    }

    /// The floor for a forearm's region `hidden_share` hidden: `floor_m` below the first of
    /// [`HIDDEN_BANDS`], else the band's floor, never below a less hidden band's.
    #[must_use]
    pub fn floor_at(&self, hidden_share: f64) -> f64 {
        let bands = HIDDEN_BANDS.iter().filter(|&&b| hidden_share >= b).count();
        self.hidden_floors_m[..bands]
            .iter()
            .fold(self.floor_m, |a, &b| a.max(b))
    }

    /// The calibration `config` carries.
    #[must_use]
    pub fn of(config: &ArmFitConfig) -> Self {
        Self {
            scale: config.uncertainty_scale,
            floor_m: config.uncertainty_floor_m,
            hidden_floors_m: config.uncertainty_hidden_floors_m,
            confirm_min_gain: config.confirm_min_gain,
            confirmed_floor_m: config.uncertainty_confirmed_floor_m,
        }
    }
}

/// The human model as the fit moves it: its joints, its arm parts' meshes, its base pose.
#[derive(Debug, Clone)]
pub struct ArticulatedArm {
    human: RobotModel,
    X_WH: Pose,
    links: [LinkId; 3],
    meshes: [Option<Arc<RenderMesh>>; 3],
    /// Each part's box axis and size, for the depth term.
    models: [Option<RigidModel>; 3],
    limits: Vec<[f64; 2]>,
    forearm: RigidModel,
    /// The shoulder (the upper arm's link origin), world frame, and the radius about it
    /// that holds every point of the three parts whatever the joints, m.
    shoulder_W: Vector,
    reach_m: f64,
}

impl ArticulatedArm {
    /// The arm of `human` (in the look it is seen in: its visuals are what is rendered)
    /// standing with its base at `X_WH`.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when the model has no joints, an arm part has no link of
    /// its name, or the forearm has no visual geometry.
    pub fn new(human: &RobotModel, X_WH: &Pose) -> Result<Self> {
        let missing = |message: String| PerceptionError::Input {
            message: format!("human model {}: {message}", human.name()),
        };
        if human.dof() == 0 {
            return Err(missing("no joints to fit".into()));
        }
        let mut links = [0; 3];
        let mut meshes: [Option<Arc<RenderMesh>>; 3] = [None, None, None];
        let mut models: [Option<RigidModel>; 3] = [None, None, None];
        for (i, part) in FITTED_PARTS.into_iter().enumerate() {
            let link = human
                .link_id(part.link_name())
                .ok_or_else(|| missing(format!("no link named {part}")))?;
            let pieces: Vec<(RenderMesh, bool)> = human.links()[link]
                .visuals
                .iter()
                .map(|g| {
                    let mesh =
                        RenderMesh::from_geometry_with(g, [0.85, 0.72, 0.62], POSE_MESH_SEGMENTS);
                    (mesh, !matches!(g.shape, Shape::Mesh { .. }))
                })
                .collect();
            let mut mesh = RenderMesh::default();
            for (piece, _) in &pieces {
                mesh.append(piece, &Pose::IDENTITY);
            }
            links[i] = link;
            if !mesh.is_empty() {
                // The parts' geometry from every visual; their renders from the outside ones.
                models[i] = Some(RigidModel::new(Arc::new(mesh))?);
                meshes[i] = Some(Arc::new(RenderMesh::outer_union(&pieces)));
            }
        }
        let forearm = models[1]
            .clone()
            .ok_or_else(|| missing("the forearm link has no visual geometry".into()))?;
        let limits = human
            .position_limits()
            .into_iter()
            .map(|[lo, hi]| {
                let (lo, hi) = (lo.max(-std::f64::consts::PI), hi.min(std::f64::consts::PI));
                if lo <= hi { [lo, hi] } else { [0.0, 0.0] }
            })
            .collect::<Vec<_>>();
        // The reach: each part's farthest box corner from its link's origin, plus the
        // distances between consecutive parts' origins, which their joints leave unchanged
        // (a URDF joint sits at its child link's origin, fixed in its parent's frame).
        let middle: Vec<f64> = limits.iter().map(|[lo, hi]| 0.5 * (lo + hi)).collect();
        let k = human.fk(*X_WH, &middle)?;
        let origin = |i: usize| k.link_pose(links[i]).translation;
        let (mut chain, mut reach_m) = (0.0, 0.0f64);
        for (i, model) in models.iter().enumerate() {
            if i > 0 {
                chain += (origin(i) - origin(i - 1)).length();
            }
            if let Some(model) = model {
                let far = model
                    .corners_O
                    .iter()
                    .map(|c| c.length())
                    .fold(0.0, f64::max);
                reach_m = reach_m.max(chain + far);
            }
        }
        Ok(Self {
            human: human.clone(),
            X_WH: *X_WH,
            links,
            meshes,
            models,
            limits,
            forearm,
            shoulder_W: origin(0),
            reach_m,
        })
    }

    /// The nearest camera-frame depth any point of the arm can have for a camera at
    /// `X_WC`, m: the shoulder's depth less the arm's reach. A depth image that shows a
    /// surface nearer than this shows something in front of the arm.
    #[must_use]
    pub fn nearest_depth_m(&self, X_WC: &Pose) -> f64 {
        X_WC.inverse().transform_point(self.shoulder_W).z - self.reach_m
    }

    /// The arm of the human a dataset shows.
    ///
    /// # Errors
    /// As [`crate::arm::dataset_human`] and [`ArticulatedArm::new`].
    pub fn of_dataset(dataset: &workcell_render::dataset::Dataset) -> Result<Self> {
        let (human, X_WH) = crate::arm::dataset_human(dataset)?;
        Self::new(&human, &X_WH)
    }

    /// Joints fitted.
    #[must_use]
    pub fn dof(&self) -> usize {
        self.limits.len()
    }

    /// Each joint's range, rad (clamped to +-pi).
    #[must_use]
    pub fn limits(&self) -> &[[f64; 2]] {
        &self.limits
    }

    /// The links of the upper arm, the forearm and the hand ([`FITTED_PARTS`]).
    #[must_use]
    pub fn part_links(&self) -> [LinkId; 3] {
        self.links
    }

    /// The forearm as the paper's pose search and its error metric see it.
    #[must_use]
    pub fn forearm(&self) -> &RigidModel {
        &self.forearm
    }

    /// The link frames of the upper arm, the forearm and the hand in the camera frame (the
    /// camera at `X_WC`) at configuration `q`.
    ///
    /// # Errors
    /// `q` has the wrong length or a value that is not finite.
    pub fn part_poses(&self, q: &[f64], X_WC: &Pose) -> Result<[Pose; 3]> {
        let k = self.human.fk(self.X_WH, q)?;
        let X_CW = X_WC.inverse();
        Ok(self.links.map(|l| X_CW * *k.link_pose(l)))
    }

    fn clamp(&self, q: &mut [f64]) {
        for (v, [lo, hi]) in q.iter_mut().zip(&self.limits) {
            *v = v.clamp(*lo, *hi);
        }
    }
}

/// What a frame shows of the arm: a probability plane per part and one for the background.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmMasks {
    pub width: usize,
    pub height: usize,
    /// Upper arm, forearm, hand ([`FITTED_PARTS`]), row-major, values in [0, 1].
    pub parts: [Vec<f32>; 3],
    /// That a pixel shows nothing that could hide the arm.
    pub background: Vec<f32>,
    /// A depth camera's image: the camera-frame z of the surface each pixel shows, m (0 or
    /// not finite where it has none). With it the depth agreement joins the score.
    pub depth_m: Option<Vec<f32>>,
}

impl ArmMasks {
    /// From a class image ([`Class`] ids, as the dataset stores them).
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when `classes` is not `width x height`.
    pub fn from_classes(classes: &[u8], width: usize, height: usize) -> Result<Self> {
        check_len(classes.len(), width, height)?;
        let plane = |c: Class| -> Vec<f32> {
            classes
                .iter()
                .map(|&v| f32::from(u8::from(v == c as u8)))
                .collect()
        };
        Ok(Self {
            width,
            height,
            parts: FITTED_PARTS.map(|p| plane(Class::of_part(p))),
            background: plane(Class::Background),
            depth_m: None,
        })
    }

    /// From a network's per-class probabilities (independent sigmoids): the background is
    /// one less the largest class's probability. A part the network has no class for is
    /// empty.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when a plane is not `width x height`.
    pub fn from_planes(width: usize, height: usize, planes: &[(Class, &[f32])]) -> Result<Self> {
        let n = width * height;
        for (_, p) in planes {
            check_len(p.len(), width, height)?;
        }
        let mut background = vec![1.0f32; n];
        for (_, p) in planes {
            for (b, &v) in background.iter_mut().zip(*p) {
                *b = b.min(1.0 - v);
            }
        }
        let part = |part: HumanPart| {
            planes
                .iter()
                .find(|(c, _)| c.human_part() == Some(part))
                .map_or_else(|| vec![0.0; n], |(_, p)| p.to_vec())
        };
        Ok(Self {
            width,
            height,
            parts: FITTED_PARTS.map(part),
            background,
            depth_m: None,
        })
    }

    /// The forearm's plane.
    #[must_use]
    pub fn forearm(&self) -> &[f32] {
        &self.parts[1]
    }
}

fn check_len(len: usize, width: usize, height: usize) -> Result<()> {
    if len == width * height {
        Ok(())
    } else {
        Err(PerceptionError::Input {
            message: format!(
                "a mask of {len} values for a {width}x{height} image ({} pixels)",
                width * height
            ),
        })
    }
}

/// The arm found in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmFit {
    /// The human model's joint positions, rad.
    pub q: Vec<f64>,
    /// The link frames of the upper arm, the forearm and the hand in the camera frame.
    pub X_CL: [Pose; 3],
    /// The paper's `f_m` of the forearm's mask and its render at the fit, whole image.
    pub f_m: f64,
    /// The gain over rendering nothing, all parts together (1: a perfect fit).
    pub gain: f64,
    /// Each part's share of [`ArmFit::gain`].
    pub part_gain: [f64; 3],
    /// Per joint, the spread of its position (the covariance's diagonal), rad.
    pub sigma_q: Vec<f64>,
    /// The farthest the other surviving hypotheses put the forearm's centre or wrist, m.
    pub spread_m: f64,
    /// The score's curvature as a spread of the forearm's centre and wrist, m (before the
    /// calibration's scale).
    pub sigma_m: f64,
    /// The radius to inflate the forearm by, m ([`Calibration::radius`] of the config's
    /// calibration).
    pub uncertainty_m: f64,
    /// How much of the forearm's region the depth image shows hidden by something in front
    /// of the arm: in the region scored, the pixels nearer than the fitted arm's nearest
    /// point (less [`HIDDEN_MARGIN_M`]) over those and the forearm mask's pixels elsewhere
    /// (0 without depth). The masks carry less of a forearm the more of it is hidden, and
    /// the calibration's floor grows with it.
    pub hidden_share: f64,
    /// The global search ran (first frame, the track lost, or its gain below
    /// [`ArmFitConfig::search_below_gain`]).
    pub reacquired: bool,
    /// The gain is below [`ArmFitConfig::min_gain`], and the frame before confirmed the fit
    /// ([`ArmFitConfig::confirm_min_gain`]).
    pub confirmed: bool,
    /// Part masks rendered for this frame.
    pub renders: usize,
}

impl ArmFit {
    /// The forearm link's frame in the camera frame (the paper's Table 2 quantity).
    #[must_use]
    pub fn X_CO(&self) -> Pose {
        self.X_CL[1]
    }
}

/// A configuration's gain in a frame's masks ([`ArmFitter::gain_at`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmGain {
    /// All parts together, as [`ArmFit::gain`].
    pub total: f64,
    /// The upper arm's, the forearm's and the hand's shares, as [`ArmFit::part_gain`].
    pub parts: [f64; 3],
}

/// The result of one frame.
pub type ArmFitOutcome = std::result::Result<ArmFit, NoPose>;

/// The observed masks prepared for scoring.
#[derive(Clone)]
struct Target {
    /// The camera at `supersample` times its resolution.
    fine: Camera,
    X_WC: Pose,
    ss: usize,
    /// Per part: the row sums of `s_p - alpha min(d_p, cap)` and of `s_p`, both divided by
    /// the mass.
    sums: Arc<[RowSums; 3]>,
    /// Mask pixels: the mass, all parts together.
    mass: f64,
    /// The crop's camera (not supersampled), and per part where its mask is; the depth in
    /// the crop when there is one.
    camera: Camera,
    inside: Arc<[Vec<bool>; 3]>,
    depth_m: Option<Arc<Vec<f32>>>,
    /// Depths below this show something in front of the arm ([`HIDDEN_MARGIN_M`] nearer
    /// than [`ArticulatedArm::nearest_depth_m`]); minus infinity without depth.
    hidden_below_m: f32,
}

impl Target {
    /// The same target for renders of `ss` samples per pixel side (its planes shared).
    fn supersampled(&self, ss: u32) -> Result<Self> {
        let ss = ss.max(1);
        Ok(Self {
            fine: self
                .camera
                .resized(self.camera.width * ss, self.camera.height * ss)?,
            ss: ss as usize,
            ..self.clone()
        })
    }
}

/// A configuration's score.
#[derive(Debug, Clone, Copy, Default)]
struct Score {
    objective: f64,
    gain: f64,
    part_gain: [f64; 3],
}

/// A climb's end.
struct Climb {
    q: Vec<f64>,
    score: Score,
}

/// Articulated render-and-compare of the human's arm, tracking it frame to frame.
pub struct ArmFitter<R: Renderer> {
    renderer: R,
    arm: ArticulatedArm,
    config: ArmFitConfig,
    /// The hypotheses tracked, best first: each its last fits, oldest first (at most two).
    tracks: Vec<Vec<Vec<f64>>>,
    /// The forearm's centre and wrist in the world frame where the last frame put them (its
    /// pose, or its best fit of at least [`ArmFitConfig::confirm_min_gain`]).
    last_points: Option<[Vector; 2]>,
    batch: MaskBatch,
    spans: SpanBatch,
    poses: Vec<Pose>,
    renders: usize,
    rng: ChaCha8Rng,
}

impl<R: Renderer> ArmFitter<R> {
    /// A fitter of `arm` that renders with `renderer`.
    pub fn new(renderer: R, arm: ArticulatedArm, config: ArmFitConfig) -> Self {
        Self {
            renderer,
            arm,
            config,
            tracks: Vec::new(),
            last_points: None,
            batch: MaskBatch::new(),
            spans: SpanBatch::new(),
            poses: Vec::new(),
            renders: 0,
            rng: ChaCha8Rng::seed_from_u64(0),
        }
    }

    /// The arm fitted.
    pub fn arm(&self) -> &ArticulatedArm {
        &self.arm
    }

    /// Forgets the track: the next frame searches globally.
    pub fn reset(&mut self) {
        self.tracks.clear();
        self.last_points = None;
    }

    /// Tracks from `q` on the next frame (as if it had been the last fit).
    pub fn set_prior(&mut self, q: &[f64]) {
        self.tracks = vec![vec![q.to_vec()]];
        self.last_points = None;
    }

    /// The arm in `masks`, seen by `camera` (the masks' size; its pose in the world is
    /// used). Tracks from the previous frames' fits when there are some.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when the masks are not the camera's size; a renderer
    /// failure. Masks the fit cannot use are [`NoPose`], not errors.
    pub fn fit(&mut self, camera: &Camera, masks: &ArmMasks) -> Result<ArmFitOutcome> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        if masks.width != w || masks.height != h {
            return Err(PerceptionError::Input {
                message: format!(
                    "masks of {}x{} for a {w}x{h} camera",
                    masks.width, masks.height
                ),
            });
        }
        for plane in masks.parts.iter().chain([&masks.background]) {
            check_len(plane.len(), w, h)?;
        }
        self.renders = 0;
        self.rng = ChaCha8Rng::seed_from_u64(0x4152_4d46); // "ARMF"
        let last_points = self.last_points.take();
        let outcome = self.fit_inner(camera, masks, last_points);
        // A frame without a pose ends the track, unless it left a candidate to confirm.
        if !matches!(outcome, Ok(Ok(_))) && self.last_points.is_none() {
            self.tracks.clear();
        }
        outcome
    }

    fn fit_inner(
        &mut self,
        camera: &Camera,
        masks: &ArmMasks,
        last_points: Option<[Vector; 2]>,
    ) -> Result<ArmFitOutcome> {
        let planes = masks.parts.iter().chain([&masks.background]);
        if planes.flatten().any(|v| !(0.0..=1.0).contains(v)) {
            return Ok(Err(NoPose::NotAProbability));
        }
        let c = self.config.clone();
        let Some(target) = self.target(camera, masks, c.supersample)? else {
            return Ok(Err(NoPose::Empty));
        };
        let coarse_owned = if c.climb_supersample.max(1) == c.supersample.max(1) {
            None
        } else {
            Some(target.supersampled(c.climb_supersample)?)
        };
        let coarse = coarse_owned.as_ref().unwrap_or(&target);
        let mut climbs: Vec<(Climb, Vec<Vec<f64>>)> = Vec::new();
        // Fits from `confirm_min_gain` up to `min_gain`, each with its track.
        let mut faint: Vec<(Climb, Vec<Vec<f64>>)> = Vec::new();
        for track in self.tracks.clone() {
            let Some(last) = track.last() else { continue };
            let mut predicted = last.clone();
            if let [before, _] = track.as_slice() {
                for ((p, l), b) in predicted.iter_mut().zip(last).zip(before) {
                    *p = 2.0 * l - b;
                }
            }
            self.arm.clamp(&mut predicted);
            let climb = self.climb(coarse, predicted.clone(), Some(&predicted))?;
            if climb.score.gain >= c.min_gain {
                climbs.push((climb, track));
            } else if climb.score.gain >= c.confirm_min_gain {
                faint.push((climb, track));
            }
        }
        // The global search when the track is lost, and when the tracked fits explain the
        // masks this poorly (the track has likely followed a wrong optimum).
        let tracked_gain = climbs
            .iter()
            .map(|(climb, _)| climb.score.gain)
            .fold(f64::NEG_INFINITY, f64::max);
        let reacquired = climbs.is_empty() || tracked_gain < c.search_below_gain;
        if reacquired {
            for climb in self.search(coarse)? {
                if climb.score.gain >= c.min_gain {
                    climbs.push((climb, Vec::new()));
                } else if climb.score.gain >= c.confirm_min_gain {
                    faint.push((climb, Vec::new()));
                }
            }
        }
        // Nothing reaches `min_gain`: the best fainter fit is a pose only where the frame
        // before put the forearm within `confirm_m` of it. Unconfirmed, it is tracked as a
        // candidate for the next frame to confirm.
        let mut confirmed = false;
        if climbs.is_empty() {
            let best = faint
                .into_iter()
                .max_by(|a, b| a.0.score.objective.total_cmp(&b.0.score.objective));
            let Some((best, track)) = best else {
                return Ok(Err(NoPose::PoorFit));
            };
            let points = self.forearm_points(&best.q, &target.X_WC)?;
            let points = points.map(|p| target.X_WC.transform_point(p));
            confirmed = last_points.is_some_and(|last| {
                last.iter()
                    .zip(&points)
                    .all(|(a, b)| (*a - *b).length() <= c.confirm_m)
            });
            self.last_points = Some(points);
            if !confirmed {
                self.tracks = vec![vec![best.q]];
                return Ok(Err(NoPose::PoorFit));
            }
            climbs.push((best, track));
        }
        climbs.sort_by(|a, b| b.0.score.objective.total_cmp(&a.0.score.objective));
        let Some(best_gain) = climbs.first().map(|(climb, _)| climb.score.gain) else {
            return Ok(Err(NoPose::PoorFit));
        };
        // The hypotheses that fit nearly as well and put the forearm elsewhere: tracked on,
        // and their distance from the best is the ambiguity the masks leave.
        let mut kept: Vec<(Climb, Vec<Vec<f64>>, [Vector; 2])> = Vec::new();
        for (climb, track) in climbs {
            if kept.len() >= c.hypotheses.max(1) || climb.score.gain < best_gain - c.ambiguity_gain
            {
                continue;
            }
            let points = self.forearm_points(&climb.q, &target.X_WC)?;
            let distinct = kept.iter().all(|(_, _, p)| {
                p.iter()
                    .zip(&points)
                    .any(|(a, b)| (*a - *b).length() > c.distinct_m)
            });
            if distinct {
                kept.push((climb, track, points));
            }
        }
        let spread_m = kept
            .iter()
            .flat_map(|(_, _, p)| p.iter().zip(&kept[0].2).map(|(a, b)| (*a - *b).length()))
            .fold(0.0, f64::max);
        self.tracks = kept
            .iter()
            .map(|(climb, track, _)| {
                let mut t = track.clone();
                t.push(climb.q.clone());
                if t.len() > 2 {
                    t.remove(0);
                }
                t
            })
            .collect();
        let Some((climb, _, points)) = kept.into_iter().next() else {
            return Ok(Err(NoPose::PoorFit));
        };
        self.last_points = Some(points.map(|p| target.X_WC.transform_point(p)));
        let (q, covariance) = self.refine(&target, climb.q.clone())?;
        let plain = self.score(&target, std::slice::from_ref(&q), None)?[0];
        if let Some(last) = self.tracks.first_mut().and_then(|t| t.last_mut()) {
            last.clone_from(&q);
        }
        let climb = Climb { q, score: plain };
        let sigma_q: Vec<f64> = (0..covariance.len())
            .map(|i| covariance[i][i].max(0.0).sqrt())
            .collect();
        let sigma_m = self.position_sigma(&climb.q, &covariance, &target.X_WC)?;
        let X_CL = self.arm.part_poses(&climb.q, &target.X_WC)?;
        let hidden_share = self.hidden_share(&target, &X_CL);
        let forearm = self.arm.forearm.mesh.clone();
        self.renderer
            .render_masks(&forearm, camera, &[X_CL[1]], &mut self.batch)?;
        self.renders += 1;
        Ok(Ok(ArmFit {
            f_m: f_m(masks.forearm(), self.batch.mask(0)),
            X_CL,
            q: climb.q,
            gain: climb.score.gain,
            part_gain: climb.score.part_gain,
            sigma_q,
            spread_m,
            uncertainty_m: Calibration::of(&c).radius(sigma_m, spread_m, hidden_share, confirmed),
            hidden_share,
            sigma_m,
            reacquired,
            confirmed,
            renders: self.renders,
        }))
    }

    /// The gain of configuration `q` in `masks`, all parts together and each part's share
    /// (as [`ArmFit::gain`] and [`ArmFit::part_gain`] score a fit); `None` when no part has
    /// support. What a perfect search would score: a fit below the truth's gain is the
    /// search's failure, one above it the masks' ambiguity.
    ///
    /// # Errors
    /// As [`ArmFitter::fit`]; `q` of the wrong length or not finite.
    pub fn gain_at(
        &mut self,
        camera: &Camera,
        masks: &ArmMasks,
        q: &[f64],
    ) -> Result<Option<ArmGain>> {
        let Some(target) = self.target(camera, masks, self.config.supersample)? else {
            return Ok(None);
        };
        let score = self.score(&target, &[q.to_vec()], None)?[0];
        Ok(Some(ArmGain {
            total: score.gain,
            parts: score.part_gain,
        }))
    }

    /// The forearm's centre and far end (the wrist) in the camera frame at `q`.
    fn forearm_points(&self, q: &[f64], X_WC: &Pose) -> Result<[Vector; 2]> {
        let X = self.arm.part_poses(q, X_WC)?[1];
        let m = &self.arm.forearm;
        let far = m.centre_O + 0.5 * m.length_m * m.axis_O;
        let near = m.centre_O - 0.5 * m.length_m * m.axis_O;
        // The far end is the one away from the link's origin (the elbow).
        let end = if far.length() >= near.length() {
            far
        } else {
            near
        };
        Ok([X.transform_point(m.centre_O), X.transform_point(end)])
    }

    /// The score near `q` as a quadratic: its value, gradient and negated Hessian from
    /// central differences of [`ArmFitConfig::hessian_step_rad`] (the mixed terms from the
    /// two neighbours along the diagonal and the axis points), without the prior: 1 + n + n^2
    /// scores for n joints (13 for three, against 19 with all four diagonal neighbours).
    fn local_model(
        &mut self,
        target: &Target,
        q: &[f64],
    ) -> Result<(f64, Vec<f64>, Vec<Vec<f64>>)> {
        let n = q.len();
        let h = self.config.hessian_step_rad.max(1e-6);
        let at = |d: &[(usize, f64)]| {
            let mut v = q.to_vec();
            for &(i, s) in d {
                v[i] += s * h;
            }
            v
        };
        let mut qs = vec![q.to_vec()];
        for i in 0..n {
            qs.push(at(&[(i, 1.0)]));
            qs.push(at(&[(i, -1.0)]));
        }
        for i in 0..n {
            for j in i + 1..n {
                for (a, b) in [(1.0, 1.0), (-1.0, -1.0)] {
                    qs.push(at(&[(i, a), (j, b)]));
                }
            }
        }
        let f: Vec<f64> = self
            .score(target, &qs, None)?
            .iter()
            .map(|s| s.objective)
            .collect();
        let mut gradient = vec![0.0; n];
        // -H: positive where the score falls away from q.
        let mut neg = vec![vec![0.0; n]; n];
        let mut mixed = Vec::new();
        let mut k = 1 + 2 * n;
        // f(+i) + f(-i) at each joint: the axis points' part of the mixed differences.
        let axis = |i: usize| f[1 + 2 * i] + f[2 + 2 * i];
        for i in 0..n {
            gradient[i] = (f[1 + 2 * i] - f[2 + 2 * i]) / (2.0 * h);
            neg[i][i] = -(axis(i) - 2.0 * f[0]) / (h * h);
            for j in i + 1..n {
                // (f(+i+j) + f(-i-j) - f(+-i) - f(+-j) + 2 f(0)) / 2h^2: second order, as the
                // four diagonal neighbours are, from two of them.
                mixed.push((
                    i,
                    j,
                    -(f[k] + f[k + 1] - axis(i) - axis(j) + 2.0 * f[0]) / (2.0 * h * h),
                ));
                k += 2;
            }
        }
        for (i, j, v) in mixed {
            neg[i][j] = v;
            neg[j][i] = v;
        }
        Ok((f[0], gradient, neg))
    }

    /// Newton steps on [`ArmFitter::local_model`] from `q` while they improve the score (at
    /// most [`ArmFitConfig::newton_steps`]): the climb's steps along the joints end early in
    /// a valley that runs across them (far away, the shoulder's flexion and the elbow's
    /// trading places). Returns the configuration and the joints' covariance: two mask
    /// pixels' worth of score over the Hessian, `2 tol (-H)^-1`, each principal direction's
    /// spread capped at half a radian (a direction the masks do not constrain); the Hessian
    /// is the last one computed (before the last step: one quadratic fewer per frame).
    fn refine(&mut self, target: &Target, mut q: Vec<f64>) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
        let tol = 2.0 / target.mass.max(1.0);
        let floor = 2.0 * tol / (0.5 * 0.5);
        let n = q.len();
        let inverse = |neg: Vec<Vec<f64>>| {
            let (values, vectors) = symmetric_eigen(neg);
            let mut inv = vec![vec![0.0; n]; n];
            for (l, v) in values.iter().zip(&vectors) {
                for i in 0..n {
                    for j in 0..n {
                        inv[i][j] += v[i] * v[j] / l.max(floor);
                    }
                }
            }
            inv
        };
        let (mut here, mut gradient, mut neg) = self.local_model(target, &q)?;
        let steps = self.config.newton_steps;
        for s in 0..steps {
            let inv = inverse(neg.clone());
            let step: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| inv[i][j] * gradient[j]).sum())
                .collect();
            let candidates: Vec<Vec<f64>> = [1.0, 0.5]
                .iter()
                .map(|t| {
                    let mut v: Vec<f64> = q.iter().zip(&step).map(|(a, d)| a + t * d).collect();
                    self.arm.clamp(&mut v);
                    v
                })
                .collect();
            let scores = self.score(target, &candidates, None)?;
            let Some((k, best)) = scores
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.objective.total_cmp(&b.1.objective))
            else {
                break;
            };
            if best.objective <= here + 1e-12 {
                break;
            }
            q = candidates[k].clone();
            if s + 1 == steps {
                break;
            }
            (here, gradient, neg) = self.local_model(target, &q)?;
        }
        let inv = inverse(neg);
        Ok((
            q,
            inv.iter()
                .map(|row| row.iter().map(|v| 2.0 * tol * v).collect())
                .collect(),
        ))
    }

    /// The position uncertainty of the forearm's centre and wrist, m: the joints'
    /// covariance through the kinematics (the root of the trace of each point's covariance),
    /// the larger of the two points.
    fn position_sigma(&self, q: &[f64], cov: &[Vec<f64>], X_WC: &Pose) -> Result<f64> {
        let base = self.forearm_points(q, X_WC)?;
        let d = 1e-5;
        let mut jac = Vec::with_capacity(q.len());
        for i in 0..q.len() {
            let mut moved = q.to_vec();
            moved[i] += d;
            let p = self.forearm_points(&moved, X_WC)?;
            jac.push([(p[0] - base[0]) / d, (p[1] - base[1]) / d]);
        }
        let mut var = [0.0f64; 2];
        for (i, ji) in jac.iter().enumerate() {
            for (j, jj) in jac.iter().enumerate() {
                for k in 0..2 {
                    var[k] += cov[i][j] * ji[k].dot(jj[k]);
                }
            }
        }
        Ok(var[0].max(var[1]).max(0.0).sqrt())
    }

    /// The masks prepared for scoring, cropped to the parts' support grown by half its size
    /// (at least 12 px a side), for renders of `ss` samples per pixel side: pixels farther
    /// out are taken as background and left unscored. `None` when no part has support.
    fn target(&self, camera: &Camera, masks: &ArmMasks, ss: u32) -> Result<Option<Target>> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let c = &self.config;
        let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
        for plane in &masks.parts {
            for (i, _) in plane.iter().enumerate().filter(|(_, v)| **v > c.threshold) {
                let (x, y) = (i % w, i / w);
                lo = [lo[0].min(x), lo[1].min(y)];
                hi = [hi[0].max(x + 1), hi[1].max(y + 1)];
            }
        }
        if lo[0] == usize::MAX {
            return Ok(None);
        }
        let grow = |a: usize, b: usize| ((b - a) / 2).max(12);
        let (gx, gy) = (grow(lo[0], hi[0]), grow(lo[1], hi[1]));
        let (x0, y0) = (lo[0].saturating_sub(gx), lo[1].saturating_sub(gy));
        let (x1, y1) = ((hi[0] + gx).min(w), (hi[1] + gy).min(h));
        let (rw, rh) = (x1 - x0, y1 - y0);
        let crop = |plane: &[f32]| -> Vec<f32> {
            (y0..y1)
                .flat_map(|y| plane[y * w + x0..y * w + x1].iter().copied())
                .collect()
        };
        let parts = masks.parts.each_ref().map(|p| crop(p));
        let background = crop(&masks.background);
        let mass: f64 = parts.iter().flatten().map(|&v| f64::from(v)).sum();
        let inv = (1.0 / mass.max(1.0)) as f32;
        let alpha = c.distance_weight as f32;
        let depth_m = masks
            .depth_m
            .as_ref()
            .filter(|d| d.len() == w * h)
            .map(|d| crop(d));
        let hidden_below_m = match depth_m {
            Some(_) => (self.arm.nearest_depth_m(&camera.X_WC) - HIDDEN_MARGIN_M) as f32,
            None => f32::NEG_INFINITY,
        };
        let signed: [Vec<f32>; 3] = std::array::from_fn(|p| {
            parts[p]
                .iter()
                .zip(&background)
                .map(|(&m, &b)| (m - b) * inv)
                .collect()
        });
        let inside: [Vec<bool>; 3] =
            std::array::from_fn(|p| parts[p].iter().map(|&v| v > c.threshold).collect());
        let sums: [RowSums; 3] = std::array::from_fn(|p| {
            let d = distance_transform(&inside[p], rw, rh, c.distance_cap_px);
            let value: Vec<f32> = signed[p]
                .iter()
                .zip(&d)
                .map(|(&s, &d)| s - alpha * d * inv)
                .collect();
            RowSums::new(&value, &signed[p], rw)
        });
        let roi = crop_camera(camera, x0, y0, rw, rh);
        let ss = ss.max(1);
        Ok(Some(Target {
            fine: roi.resized(roi.width * ss, roi.height * ss)?,
            X_WC: camera.X_WC,
            ss: ss as usize,
            sums: Arc::new(sums),
            mass,
            camera: roi,
            inside: Arc::new(inside),
            depth_m: depth_m.map(Arc::new),
            hidden_below_m,
        }))
    }

    /// The scores of the configurations `qs`, each part rendered in one batch; the prior
    /// (its centre) subtracted when given.
    fn score(
        &mut self,
        target: &Target,
        qs: &[Vec<f64>],
        prior: Option<&[f64]>,
    ) -> Result<Vec<Score>> {
        let mut scores = vec![Score::default(); qs.len()];
        let all: Vec<[Pose; 3]> = qs
            .iter()
            .map(|q| self.arm.part_poses(q, &target.X_WC))
            .collect::<Result<_>>()?;
        let ss = target.ss;
        let per_sample = 1.0 / (ss * ss) as f64;
        for p in 0..3 {
            let Some(mesh) = self.arm.meshes[p].clone() else {
                continue;
            };
            self.poses.clear();
            self.poses.extend(all.iter().map(|x| x[p]));
            self.renderer
                .render_spans(&mesh, &target.fine, &self.poses, &mut self.spans)?;
            self.renders += qs.len();
            let sums = &target.sums[p];
            for (k, score) in scores.iter_mut().enumerate() {
                let [value, signed] = sums.over(self.spans.spans(k), ss);
                let (value, signed) = (value * per_sample, signed * per_sample);
                score.objective += value;
                score.gain += signed;
                score.part_gain[p] = signed;
            }
        }
        if let Some(depth) = &target.depth_m {
            for (score, poses) in scores.iter_mut().zip(&all) {
                score.objective -= self.depth_cost(target, depth, poses);
            }
        }
        if let Some(centre) = prior {
            let c = &self.config;
            let dof = centre.len().max(1) as f64;
            for (score, q) in scores.iter_mut().zip(qs) {
                let d2: f64 = q
                    .iter()
                    .zip(centre)
                    .map(|(a, b)| ((a - b) / c.prior_sigma_rad).powi(2))
                    .sum();
                score.objective -= c.prior_weight * d2 / dof;
            }
        }
        Ok(scores)
    }

    /// [`ArmFit::hidden_share`] of the arm at `poses`: the region's pixels whose depth is
    /// more than [`HIDDEN_MARGIN_M`] nearer than the arm's nearest box corner, over those and
    /// the forearm mask's pixels elsewhere; 0 without depth.
    fn hidden_share(&self, target: &Target, poses: &[Pose; 3]) -> f64 {
        let Some(depth) = &target.depth_m else {
            return 0.0;
        };
        let nearest = self
            .arm
            .models
            .iter()
            .zip(poses)
            .filter_map(|(m, X)| m.as_ref().map(|m| (m, X)))
            .flat_map(|(m, X)| m.corners_O.iter().map(move |&c| X.transform_point(c).z))
            .fold(f64::INFINITY, f64::min);
        let below = (nearest - HIDDEN_MARGIN_M) as f32;
        let (mut hidden, mut forearm) = (0usize, 0usize);
        for (&z, &inside) in depth.iter().zip(target.inside[1].iter()) {
            if z > 0.0 && z < below {
                hidden += 1;
            } else if inside {
                forearm += 1;
            }
        }
        if hidden == 0 {
            0.0
        } else {
            hidden as f64 / (hidden + forearm) as f64
        }
    }

    /// The depth disagreement of the parts at `poses`: per part seen side-on (its axis more
    /// than 26 degrees from the line of sight, [`END_ON_COS`]), five points along its axis, each moved
    /// towards the camera by the part's half width (the side the camera sees); those that
    /// land on their part's mask where the image shows no surface in front of the arm
    /// ([`Target::hidden_below_m`]) compare their depth with the image's, as
    /// `min((dz / sigma)^2, 9)`; the mean over them, times [`ArmFitConfig::depth_weight`],
    /// summed over the parts. A part seen end-on shows its near end at every point, not its
    /// side: the axis points would be compared with depths up to half its length nearer.
    fn depth_cost(&self, target: &Target, depth: &[f32], poses: &[Pose; 3]) -> f64 {
        let c = &self.config;
        let sigma = c.depth_sigma_m.max(1e-4);
        let (w, h) = (target.camera.width as usize, target.camera.height as usize);
        let mut cost = 0.0;
        for (p, model) in self.arm.models.iter().enumerate() {
            let Some(model) = model else { continue };
            let (mut sum, mut n) = (0.0, 0usize);
            let axis_C = poses[p].rotation * model.axis_O;
            let centre_C = poses[p].transform_point(model.centre_O);
            if axis_C.dot(centre_C.normalize_or_zero()).abs() > END_ON_COS {
                continue;
            }
            for t in [-0.4, -0.2, 0.0, 0.2, 0.4] {
                let p_C =
                    poses[p].transform_point(model.centre_O + t * model.length_m * model.axis_O);
                let Some([u, v]) = target.camera.project(p_C) else {
                    continue;
                };
                if !(u >= 0.0 && v >= 0.0 && (u as usize) < w && (v as usize) < h) {
                    continue;
                }
                let i = v as usize * w + u as usize;
                let z = depth[i];
                if !(target.inside[p][i] && z.is_finite() && z > 0.0 && z >= target.hidden_below_m)
                {
                    continue;
                }
                let z = f64::from(z);
                let surface = p_C.z - model.half_width_m;
                sum += ((z - surface) / sigma).powi(2).min(9.0);
                n += 1;
            }
            if n > 0 {
                cost += c.depth_weight * sum / n as f64;
            }
        }
        cost
    }

    /// Gradient ascent from `start` (see the module docs).
    fn climb(&mut self, target: &Target, start: Vec<f64>, prior: Option<&[f64]>) -> Result<Climb> {
        let c = self.config.clone();
        let dof = self.arm.dof();
        let mut q = start;
        let mut here = self.score(target, std::slice::from_ref(&q), prior)?[0];
        let mut step = c.initial_step_rad;
        for _ in 0..c.max_iterations {
            let mut candidates = Vec::with_capacity(2 * dof);
            for i in 0..dof {
                for sign in [1.0, -1.0] {
                    let mut v = q.clone();
                    v[i] += sign * step;
                    candidates.push(v);
                }
            }
            let compass = self.score(target, &candidates, prior)?;
            let mut gradient = vec![0.0; dof];
            for i in 0..dof {
                let (plus, minus) = (compass[2 * i].objective, compass[2 * i + 1].objective);
                gradient[i] = (plus - minus) / (2.0 * step);
            }
            let norm = gradient.iter().map(|g| g * g).sum::<f64>().sqrt();
            let mut more = Vec::new();
            if norm > 0.0 {
                for t in [1.0, 2.0, 4.0] {
                    let mut v = q.clone();
                    for (x, g) in v.iter_mut().zip(&gradient) {
                        *x += t * step * g / norm;
                    }
                    self.arm.clamp(&mut v);
                    more.push(v);
                }
            }
            for _ in 0..c.random_probes {
                let mut v = q.clone();
                for x in &mut v {
                    *x += step * (2.0 * self.rng.random::<f64>() - 1.0);
                }
                self.arm.clamp(&mut v);
                more.push(v);
            }
            let extra = self.score(target, &more, prior)?;
            let mut best: Option<(Vec<f64>, Score)> = None;
            for (v, s) in candidates
                .into_iter()
                .zip(compass)
                .chain(more.into_iter().zip(extra))
            {
                let inside = v
                    .iter()
                    .zip(self.arm.limits())
                    .all(|(x, [lo, hi])| (*lo..=*hi).contains(x));
                if inside && s.objective > best.as_ref().map_or(here.objective, |b| b.1.objective) {
                    best = Some((v, s));
                }
            }
            match best {
                Some((v, s)) if s.objective > here.objective + 1e-12 => {
                    q = v;
                    here = s;
                    step = (1.5 * step).min(4.0 * c.initial_step_rad);
                }
                _ => {
                    step *= 0.5;
                    if step < c.min_step_rad {
                        break;
                    }
                }
            }
        }
        // The reported gain is without the prior.
        let plain = self.score(target, std::slice::from_ref(&q), None)?[0];
        Ok(Climb {
            q,
            score: Score {
                objective: here.objective,
                ..plain
            },
        })
    }

    /// The global search: a grid over the joints' ranges, the best distinct cells climbed.
    fn search(&mut self, target: &Target) -> Result<Vec<Climb>> {
        let c = self.config.clone();
        let n = c.grid.max(1);
        let limits = self.arm.limits().to_vec();
        let mut grid: Vec<Vec<f64>> = vec![Vec::new()];
        for [lo, hi] in &limits {
            grid = grid
                .into_iter()
                .flat_map(|q| {
                    (0..n).map(move |k| {
                        let mut v = q.clone();
                        v.push(lo + (k as f64 + 0.5) * (hi - lo) / n as f64);
                        v
                    })
                })
                .collect();
        }
        let scores = self.score(target, &grid, None)?;
        let mut order: Vec<usize> = (0..grid.len()).collect();
        order.sort_by(|&a, &b| scores[b].objective.total_cmp(&scores[a].objective));
        // Cells at least 1.5 cells apart in some joint.
        let cell: Vec<f64> = limits.iter().map(|[lo, hi]| (hi - lo) / n as f64).collect();
        let mut starts: Vec<Vec<f64>> = Vec::new();
        for i in order {
            if starts.len() >= c.refine.max(1) {
                break;
            }
            let q = &grid[i];
            let distinct = starts.iter().all(|s| {
                s.iter()
                    .zip(q)
                    .zip(&cell)
                    .any(|((a, b), w)| (a - b).abs() > 1.5 * w)
            });
            if distinct {
                starts.push(q.clone());
            }
        }
        starts
            .into_iter()
            .map(|s| self.climb(target, s, None))
            .collect()
    }
}

/// Prefix sums of two planes along each row, for sums over row spans of supersampled
/// renders in two lookups a row.
struct RowSums {
    width: usize,
    /// Per row, `width + 1` pairs: the sums of both planes over the row's first `i` pixels.
    prefix: Vec<[f64; 2]>,
}

impl RowSums {
    /// The prefix sums of `a` and `b`, `width` pixels a row.
    fn new(a: &[f32], b: &[f32], width: usize) -> Self {
        let mut prefix = Vec::with_capacity(a.len() + a.len() / width.max(1) + 1);
        for (ra, rb) in a
            .chunks_exact(width.max(1))
            .zip(b.chunks_exact(width.max(1)))
        {
            let mut sum = [0.0f64; 2];
            prefix.push(sum);
            for (&x, &y) in ra.iter().zip(rb) {
                sum[0] += f64::from(x);
                sum[1] += f64::from(y);
                prefix.push(sum);
            }
        }
        Self { width, prefix }
    }

    /// Both planes summed over the samples that `spans` cover, in a render of `ss x ss`
    /// samples a pixel (one span per sample row): each pixel's value counted once per
    /// covered sample.
    fn over(&self, spans: &[[u32; 2]], ss: usize) -> [f64; 2] {
        let stride = self.width + 1;
        let mut total = [0.0f64; 2];
        for (fy, &[first, last]) in spans.iter().enumerate() {
            if first > last {
                continue;
            }
            let row = &self.prefix[(fy / ss) * stride..(fy / ss + 1) * stride];
            let (a, b) = (first as usize, last as usize);
            let (pa, pb) = (a / ss, b / ss);
            for k in 0..2 {
                let pixel = |i: usize| row[i + 1][k] - row[i][k];
                total[k] += if pa == pb {
                    (b - a + 1) as f64 * pixel(pa)
                } else {
                    // The partly covered pixels at both ends, and the whole ones between.
                    (ss - a % ss) as f64 * pixel(pa)
                        + (b % ss + 1) as f64 * pixel(pb)
                        + ss as f64 * (row[pb][k] - row[pa + 1][k])
                };
            }
        }
        total
    }
}

/// Eigenvalues and unit eigenvectors of a small symmetric matrix (cyclic Jacobi rotations).
fn symmetric_eigen(mut a: Vec<Vec<f64>>) -> (Vec<f64>, Vec<Vec<f64>>) {
    let n = a.len();
    let mut v: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| f64::from(u8::from(i == j))).collect())
        .collect();
    for _ in 0..50 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        if off < 1e-30 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = 0.5 * (2.0 * a[p][q]).atan2(a[q][q] - a[p][p]);
                let (s, c) = theta.sin_cos();
                for row in &mut a {
                    let (akp, akq) = (row[p], row[q]);
                    row[p] = c * akp - s * akq;
                    row[q] = s * akp + c * akq;
                }
                let (row_p, row_q) = (a[p].clone(), a[q].clone());
                a[p] = row_p
                    .iter()
                    .zip(&row_q)
                    .map(|(x, y)| c * x - s * y)
                    .collect();
                a[q] = row_p
                    .iter()
                    .zip(&row_q)
                    .map(|(x, y)| s * x + c * y)
                    .collect();
                for row in &mut v {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let values = (0..n).map(|i| a[i][i]).collect();
    let vectors = (0..n).map(|j| (0..n).map(|i| v[i][j]).collect()).collect();
    (values, vectors)
}

/// Distances in pixels from each pixel to the nearest `inside` one, capped at `cap`
/// (two passes of the 3-4 chamfer metric, within 8 % of the Euclidean distance). All `cap`
/// when nothing is inside.
fn distance_transform(inside: &[bool], w: usize, h: usize, cap: f32) -> Vec<f32> {
    let big = cap.max(0.0);
    let mut d: Vec<f32> = inside.iter().map(|&b| if b { 0.0 } else { big }).collect();
    if !inside.iter().any(|&b| b) {
        return d;
    }
    let (a, b) = (1.0f32, std::f32::consts::SQRT_2);
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut v = d[i];
            if x > 0 {
                v = v.min(d[i - 1] + a);
            }
            if y > 0 {
                v = v.min(d[i - w] + a);
                if x > 0 {
                    v = v.min(d[i - w - 1] + b);
                }
                if x + 1 < w {
                    v = v.min(d[i - w + 1] + b);
                }
            }
            d[i] = v;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            let mut v = d[i];
            if x + 1 < w {
                v = v.min(d[i + 1] + a);
            }
            if y + 1 < h {
                v = v.min(d[i + w] + a);
                if x + 1 < w {
                    v = v.min(d[i + w + 1] + b);
                }
                if x > 0 {
                    v = v.min(d[i + w - 1] + b);
                }
            }
            d[i] = v.min(big);
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_render::CpuRenderer;

    /// The catalogue's human at the origin, seen from about 2.5 m in front, 128x128, through
    /// a 25-degree lens pointed near the arm.
    fn setup() -> (ArticulatedArm, Camera) {
        let human = RobotModel::from_catalogue("human_arm").expect("catalogue human");
        let arm = ArticulatedArm::new(&human, &Pose::IDENTITY).expect("arm");
        let camera = Camera::look_at(
            [2.5, -0.9, 0.7],
            [0.1, -0.2, 0.3],
            [0.0, 0.0, 1.0],
            128,
            128,
            25.0,
        )
        .expect("camera");
        (arm, camera)
    }

    /// Configurations seen by [`far_camera`]: the arm raised, forward and to the side.
    const FAR_CONFIGURATIONS: [[f64; 3]; 3] = [[0.4, 0.8, 1.2], [1.0, 0.3, 0.6], [0.2, 1.4, 0.4]];

    /// The same human from about 8.4 m through a 6-degree lens: nearly an orthographic view.
    fn far_camera() -> Camera {
        Camera::look_at(
            [8.0, -2.5, 1.5],
            [0.1, -0.2, 0.3],
            [0.0, 0.0, 1.0],
            128,
            128,
            6.0,
        )
        .expect("camera")
    }

    /// The class image and the depth of the arm at `q`, its three parts rendered together
    /// (z-buffered).
    fn observe(arm: &ArticulatedArm, camera: &Camera, q: &[f64]) -> (Vec<u8>, Vec<f32>) {
        let poses = arm.part_poses(q, &camera.X_WC).expect("poses");
        let mut scene = workcell_render::Scene::default();
        for p in 0..3 {
            let Some(mesh) = &arm.meshes[p] else { continue };
            scene.push(workcell_render::SceneObject {
                name: FITTED_PARTS[p].name().into(),
                class: Class::of_part(FITTED_PARTS[p]),
                mesh: mesh.clone(),
                texture: 0.0,
                X_WO: camera.X_WC * poses[p],
            });
        }
        let mut frame = workcell_render::Frame::new();
        CpuRenderer::new()
            .render(&scene, camera, &mut frame)
            .expect("render");
        (frame.classes(&scene), frame.depth_m.clone())
    }

    #[test]
    fn sums_over_spans_are_the_sums_over_the_covered_samples() {
        let (w, h) = (7, 5);
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut plane = || -> Vec<f32> { (0..w * h).map(|_| rng.random::<f32>() - 0.3).collect() };
        let (a, b) = (plane(), plane());
        let sums = RowSums::new(&a, &b, w);
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        for ss in 1..=3 {
            for _ in 0..20 {
                let spans: Vec<[u32; 2]> = (0..h * ss)
                    .map(|_| {
                        let x = rng.random_range(0..(w * ss) as u32);
                        let y = rng.random_range(0..(w * ss) as u32);
                        if rng.random::<f32>() < 0.2 {
                            SpanBatch::EMPTY
                        } else {
                            [x.min(y), x.max(y)]
                        }
                    })
                    .collect();
                let mut expected = [0.0f64; 2];
                for (fy, &[first, last]) in spans.iter().enumerate() {
                    for x in first as usize..=last as usize {
                        if first > last {
                            break;
                        }
                        let i = (fy / ss) * w + x / ss;
                        expected[0] += f64::from(a[i]);
                        expected[1] += f64::from(b[i]);
                    }
                }
                let got = sums.over(&spans, ss);
                for k in 0..2 {
                    assert!(
                        (got[k] - expected[k]).abs() < 1e-9,
                        "ss {ss}: {got:?} {expected:?}"
                    );
                }
            }
        }
    }

    /// The parts' renders (their outside triangles) cover the pixels that every visual of
    /// their link covers, at the fit's 2x2 samples a pixel.
    #[test]
    fn each_part_renders_as_its_visuals_do() {
        let (arm, camera) = setup();
        let human = RobotModel::from_catalogue("human_arm").expect("catalogue human");
        let fine = camera.resized(256, 256).expect("camera");
        let mut renderer = CpuRenderer::new();
        let (mut a, mut b) = (MaskBatch::new(), MaskBatch::new());
        for p in 0..3 {
            let mut all = RenderMesh::default();
            for g in &human.links()[arm.links[p]].visuals {
                all.append(
                    &RenderMesh::from_geometry_with(g, [0.5; 3], POSE_MESH_SEGMENTS),
                    &Pose::IDENTITY,
                );
            }
            let outer = arm.meshes[p].as_ref().expect("mesh");
            // 270 of 504, 276 of 672 and 178 of 1,368 triangles.
            assert!(
                10 * outer.len() < 6 * all.len(),
                "{} of {}",
                outer.len(),
                all.len()
            );
            let poses: Vec<Pose> = (0..12)
                .map(|k| {
                    let t = f64::from(k) / 12.0;
                    let q = [1.2 * t - 0.2, 1.6 * (1.0 - t), 2.0 * t];
                    arm.part_poses(&q, &camera.X_WC).expect("poses")[p]
                })
                .collect();
            renderer
                .render_masks(&all, &fine, &poses, &mut a)
                .expect("render");
            renderer
                .render_masks(outer, &fine, &poses, &mut b)
                .expect("render");
            assert!(a.data.contains(&1), "part {p} in view");
            assert_eq!(a, b, "part {p}");
        }
    }

    fn classes(arm: &ArticulatedArm, camera: &Camera, q: &[f64]) -> Vec<u8> {
        observe(arm, camera, q).0
    }

    fn distance_cm(arm: &ArticulatedArm, camera: &Camera, a: &[f64], b: &[f64]) -> f64 {
        let pa = arm.part_poses(a, &camera.X_WC).expect("a")[1];
        let pb = arm.part_poses(b, &camera.X_WC).expect("b")[1];
        let m = arm.forearm();
        100.0 * (m.centre(&pa) - m.centre(&pb)).length()
    }

    #[test]
    fn distance_transform_of_one_pixel_is_the_chamfer_distance() {
        let (w, h) = (9, 7);
        let mut inside = vec![false; w * h];
        inside[3 * w + 4] = true;
        let d = distance_transform(&inside, w, h, 100.0);
        assert_eq!(d[3 * w + 4], 0.0);
        assert_eq!(d[3 * w + 7], 3.0); // three pixels right
        assert!((d[0] - (3.0 * std::f32::consts::SQRT_2 + 1.0)).abs() < 1e-5); // (0,0): 4 left, 3 up
        let capped = distance_transform(&inside, w, h, 2.0);
        assert_eq!(capped[0], 2.0);
        assert!(
            distance_transform(&vec![false; w * h], w, h, 5.0)
                .iter()
                .all(|&v| v == 5.0)
        );
    }

    /// A v = lambda v for each pair, on a matrix with known eigenvalues (1, 2, 4: the
    /// rotation of diag(1, 2, 4) by an orthonormal basis).
    #[test]
    fn eigenpairs_of_a_symmetric_matrix() {
        let basis = [
            [1.0 / 3f64.sqrt(); 3],
            [1.0 / 2f64.sqrt(), -1.0 / 2f64.sqrt(), 0.0],
            [1.0 / 6f64.sqrt(), 1.0 / 6f64.sqrt(), -2.0 / 6f64.sqrt()],
        ];
        let lambda = [1.0, 2.0, 4.0];
        let a: Vec<Vec<f64>> = (0..3)
            .map(|i| {
                (0..3)
                    .map(|j| (0..3).map(|k| lambda[k] * basis[k][i] * basis[k][j]).sum())
                    .collect()
            })
            .collect();
        let (values, vectors) = symmetric_eigen(a.clone());
        let mut sorted = values.clone();
        sorted.sort_by(f64::total_cmp);
        for (v, l) in sorted.iter().zip(lambda) {
            assert!((v - l).abs() < 1e-12, "{values:?}");
        }
        for (l, v) in values.iter().zip(&vectors) {
            for i in 0..3 {
                let av: f64 = (0..3).map(|j| a[i][j] * v[j]).sum();
                assert!((av - l * v[i]).abs() < 1e-12);
            }
            assert!((v.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn masks_from_classes_and_from_probabilities_agree() {
        let classes = [0u8, 3, 4, 5, 1, 2];
        let m = ArmMasks::from_classes(&classes, 3, 2).expect("masks");
        assert_eq!(m.parts[0], vec![0.0, 1.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(m.forearm(), &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
        // The robot and the torso are not background: they may hide the arm.
        assert_eq!(m.background, vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let planes: Vec<(Class, Vec<f32>)> = [
            Class::Robot,
            Class::Torso,
            Class::UpperArm,
            Class::Forearm,
            Class::Hand,
        ]
        .into_iter()
        .map(|c| {
            (
                c,
                classes
                    .iter()
                    .map(|&v| f32::from(u8::from(v == c as u8)))
                    .collect(),
            )
        })
        .collect();
        let refs: Vec<(Class, &[f32])> = planes.iter().map(|(c, p)| (*c, p.as_slice())).collect();
        assert_eq!(ArmMasks::from_planes(3, 2, &refs).expect("planes"), m);
        assert!(ArmMasks::from_classes(&classes, 4, 2).is_err());
    }

    /// The fit from the masks of a known configuration finds it again: globally on the
    /// first frame, then tracking a moving arm.
    #[test]
    fn fits_the_arm_it_rendered() {
        let (arm, camera) = setup();
        let mut fitter = ArmFitter::new(CpuRenderer::new(), arm.clone(), ArmFitConfig::default());
        let path = |t: f64| vec![0.5 + 0.1 * t, 0.9 - 0.1 * t, 1.0 + 0.2 * t];
        for k in 0..4 {
            let truth = path(f64::from(k) * 0.3);
            let masks =
                ArmMasks::from_classes(&classes(&arm, &camera, &truth), 128, 128).expect("masks");
            let fit = fitter.fit(&camera, &masks).expect("fit").expect("a pose");
            assert_eq!(fit.reacquired, k == 0);
            let err = distance_cm(&arm, &camera, &fit.q, &truth);
            assert!(
                err < 1.5,
                "frame {k}: {err:.2} cm, q {:?} vs {truth:?}",
                fit.q
            );
            assert!(fit.gain > 0.9, "frame {k}: gain {}", fit.gain);
        }
    }

    /// A track that explains the masks poorly (a gain between `min_gain` and
    /// `search_below_gain`) calls the global search beside it, which finds the arm; with the
    /// threshold at 0 the poor track is kept.
    #[test]
    fn a_poor_track_calls_the_global_search() {
        let (arm, camera) = setup();
        let truth = [0.5, 0.9, 1.0];
        let masks =
            ArmMasks::from_classes(&classes(&arm, &camera, &truth), 128, 128).expect("masks");
        // The climb stays where the track was: its gain is the track's.
        let config = |search_below_gain| ArmFitConfig {
            max_iterations: 0,
            newton_steps: 0,
            search_below_gain,
            ..ArmFitConfig::default()
        };
        let mut fitter = ArmFitter::new(CpuRenderer::new(), arm.clone(), config(0.55));
        let poor = (1..40)
            .map(|k| {
                let d = 0.02 * f64::from(k);
                vec![truth[0] + d, truth[1] - d, truth[2] + 0.5 * d]
            })
            .find(|q| {
                let gain = fitter.gain_at(&camera, &masks, q).expect("gain");
                gain.is_some_and(|g| (0.35..0.5).contains(&g.total))
            })
            .expect("a configuration that explains the masks poorly");
        fitter.set_prior(&poor);
        let fit = fitter.fit(&camera, &masks).expect("fit").expect("a pose");
        assert!(fit.reacquired);
        let err = distance_cm(&arm, &camera, &fit.q, &truth);
        assert!(err < 3.0, "{err:.2} cm off, q {:?}", fit.q);

        let mut kept = ArmFitter::new(CpuRenderer::new(), arm.clone(), config(0.0));
        kept.set_prior(&poor);
        let fit = kept.fit(&camera, &masks).expect("fit").expect("a pose");
        assert!(!fit.reacquired);
        assert!(fit.gain < 0.5, "gain {}", fit.gain);
    }

    /// A fit below `min_gain` is a pose only when the frame before put the forearm within
    /// `confirm_m` of it. With `min_gain` above any gain (1 is a perfect fit), every fit here
    /// is such a fit: the first frame gives none, the next (the arm moved a little) a confirmed
    /// pose; a jump farther than `confirm_m` gives none until the frame after it; a reset
    /// forgets the frame before; with `confirm_min_gain` at `min_gain` nothing is a pose.
    #[test]
    fn a_fit_below_the_threshold_is_confirmed_by_the_frame_before() {
        let (arm, camera) = setup();
        let masks_of = |q: &[f64]| {
            ArmMasks::from_classes(&classes(&arm, &camera, q), 128, 128).expect("masks")
        };
        let config = ArmFitConfig {
            min_gain: 1.5,
            confirm_min_gain: 0.5,
            ..ArmFitConfig::default()
        };
        let near = [vec![0.5, 0.9, 1.0], vec![0.52, 0.88, 1.02]];
        let far = vec![0.5, 0.9, 1.8]; // the elbow bent 0.8 rad more: the wrist moves > 10 cm
        let mut fitter = ArmFitter::new(CpuRenderer::new(), arm.clone(), config.clone());
        assert_eq!(
            fitter.fit(&camera, &masks_of(&near[0])).expect("fit").err(),
            Some(NoPose::PoorFit),
            "the first frame has nothing to confirm it"
        );
        let fit = fitter
            .fit(&camera, &masks_of(&near[1]))
            .expect("fit")
            .expect("a pose confirmed by the frame before");
        assert!(fit.confirmed && fit.gain > 0.9, "gain {}", fit.gain);
        let err = distance_cm(&arm, &camera, &fit.q, &near[1]);
        assert!(err < 1.5, "{err:.2} cm off");
        assert!(
            fitter.fit(&camera, &masks_of(&far)).expect("fit").is_err(),
            "a fit far from the frame before is not confirmed"
        );
        let fit = fitter
            .fit(&camera, &masks_of(&far))
            .expect("fit")
            .expect("the frame after the jump confirms it");
        assert!(fit.confirmed, "gain {}", fit.gain);
        assert!(distance_cm(&arm, &camera, &fit.q, &far) < 1.5);
        fitter.reset();
        assert!(fitter.fit(&camera, &masks_of(&far)).expect("fit").is_err());

        let mut off = ArmFitter::new(
            CpuRenderer::new(),
            arm.clone(),
            ArmFitConfig {
                confirm_min_gain: 1.5,
                ..config
            },
        );
        for q in &near {
            assert!(off.fit(&camera, &masks_of(q)).expect("fit").is_err());
        }
    }

    /// Far away the masks of the arm and of its mirror image are nearly the same: whichever
    /// the fit picks, its uncertainty reaches the truth.
    #[test]
    fn far_away_the_uncertainty_covers_the_mirror() {
        let (arm, _) = setup();
        let camera = far_camera();
        let mut fitter = ArmFitter::new(CpuRenderer::new(), arm.clone(), ArmFitConfig::default());
        for truth in FAR_CONFIGURATIONS.map(|q| q.to_vec()) {
            fitter.reset();
            let masks =
                ArmMasks::from_classes(&classes(&arm, &camera, &truth), 128, 128).expect("masks");
            let fit = fitter.fit(&camera, &masks).expect("fit").expect("a pose");
            let err = distance_cm(&arm, &camera, &fit.q, &truth);
            let truth_gain = fitter.gain_at(&camera, &masks, &truth).expect("gain");
            assert!(
                err < 2.0 || 100.0 * fit.uncertainty_m >= err,
                "{truth:?}: {err:.1} cm off, uncertainty {:.1} cm; q {:?}, gain {:.4} (truth's {truth_gain:?})",
                100.0 * fit.uncertainty_m,
                fit.q,
                fit.gain
            );
        }
    }

    /// Where the masks cannot tell the arm from its mirror, depth can: with the depth image
    /// the fit finds the true arm itself.
    #[test]
    fn depth_tells_the_arm_from_its_mirror() {
        let (arm, _) = setup();
        let camera = far_camera();
        let mut fitter = ArmFitter::new(CpuRenderer::new(), arm.clone(), ArmFitConfig::default());
        for truth in FAR_CONFIGURATIONS.map(|q| q.to_vec()) {
            fitter.reset();
            let (classes, depth) = observe(&arm, &camera, &truth);
            let mut masks = ArmMasks::from_classes(&classes, 128, 128).expect("masks");
            masks.depth_m = Some(depth);
            let fit = fitter.fit(&camera, &masks).expect("fit").expect("a pose");
            let err = distance_cm(&arm, &camera, &fit.q, &truth);
            assert!(err < 2.0, "{truth:?}: {err:.1} cm off, q {:?}", fit.q);
        }
    }

    /// Every point of every part lies within the reach of the shoulder, whatever the
    /// joints, and some configurations come near the reach's edge.
    #[test]
    fn the_reach_holds_the_arm_in_any_configuration() {
        let (arm, _) = setup();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut farthest = 0.0f64;
        for _ in 0..200 {
            let q: Vec<f64> = arm
                .limits()
                .iter()
                .map(|&[lo, hi]| rng.random_range(lo..=hi))
                .collect();
            let poses = arm.part_poses(&q, &Pose::IDENTITY).expect("poses");
            for (p, mesh) in arm.meshes.iter().enumerate() {
                let Some(mesh) = mesh else { continue };
                for v in &mesh.positions {
                    let v = Vector::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2]));
                    let d = (poses[p].transform_point(v) - arm.shoulder_W).length();
                    assert!(
                        d <= arm.reach_m + 1e-6,
                        "{d} m past a reach of {}",
                        arm.reach_m
                    );
                    farthest = farthest.max(d);
                }
            }
        }
        // The upper arm (0.3255 m to the elbow) and the forearm (0.2555 m to the wrist)
        // with the hand: about 0.8 m.
        assert!((0.7..0.9).contains(&arm.reach_m), "{}", arm.reach_m);
        assert!(
            farthest > 0.9 * arm.reach_m,
            "{farthest} of {}",
            arm.reach_m
        );
    }

    /// A black occluder that a depth camera sees in front of the arm over half the
    /// forearm: the fit reports that share hidden (half), none when the depth image sees
    /// through the occluder, still finds the arm (the depth term skips the occluder), and
    /// its bound is the calibration's floor for a forearm half hidden.
    #[test]
    fn an_occluder_in_front_is_measured_and_widens_the_bound() {
        let (arm, camera) = setup();
        let truth = [0.5, 0.9, 1.0];
        let (classes, depth) = observe(&arm, &camera, &truth);
        let forearm = Class::Forearm as u8;
        let pixels: Vec<usize> = (0..classes.len())
            .filter(|&i| classes[i] == forearm)
            .collect();
        let centre = pixels.iter().fold([0.0, 0.0], |[x, y], &i| {
            [x + (i % 128) as f64, y + (i / 128) as f64]
        });
        let centre = centre.map(|c| c / pixels.len() as f64);
        let dist = |i: usize| ((i % 128) as f64 - centre[0]).hypot((i / 128) as f64 - centre[1]);
        let mut radii: Vec<f64> = pixels.iter().map(|&i| dist(i)).collect();
        radii.sort_by(f64::total_cmp);
        let radius = radii[radii.len() / 2];
        // The network calls the black disc background; the depth camera sees the disc.
        let (mut hidden_classes, mut occluded_depth) = (classes.clone(), depth.clone());
        let mut hidden = 0usize;
        for &i in pixels.iter().filter(|&&i| dist(i) <= radius) {
            hidden_classes[i] = Class::Background as u8;
            occluded_depth[i] = 0.25;
            hidden += 1;
        }
        let share = hidden as f64 / pixels.len() as f64;
        assert!(
            (0.45..0.6).contains(&share),
            "{hidden} of {} hidden",
            pixels.len()
        );
        let mut masks = ArmMasks::from_classes(&hidden_classes, 128, 128).expect("masks");
        let calibration = Calibration {
            scale: 0.0,
            floor_m: 0.01,
            hidden_floors_m: [0.1, 0.2, 0.3],
            confirm_min_gain: f64::INFINITY,
            confirmed_floor_m: 0.0,
        };
        let config = calibration.apply(ArmFitConfig::default());
        let mut fitter = ArmFitter::new(CpuRenderer::new(), arm.clone(), config);
        masks.depth_m = Some(depth);
        let seen_through = fitter.fit(&camera, &masks).expect("fit").expect("a pose");
        assert_eq!(seen_through.hidden_share, 0.0);
        masks.depth_m = Some(occluded_depth);
        fitter.reset();
        let fit = fitter.fit(&camera, &masks).expect("fit").expect("a pose");
        // Hidden pixels over themselves and the forearm's mask elsewhere.
        assert!(
            (fit.hidden_share - share).abs() < 1e-9,
            "{} vs {share}",
            fit.hidden_share
        );
        let err = distance_cm(&arm, &camera, &fit.q, &truth);
        assert!(err < 2.0, "{err:.2} cm off, q {:?}", fit.q);
        assert_eq!(fit.uncertainty_m, 0.2_f64.max(fit.spread_m));
    }

    /// The floor grows band by band with the hidden share, and never falls below a less
    /// hidden band's; a confirmed pose's bound is at least its own floor.
    #[test]
    fn the_floor_follows_the_hidden_share() {
        let c = Calibration {
            scale: 2.0,
            floor_m: 0.05,
            hidden_floors_m: [0.04, 0.2, 0.1],
            confirm_min_gain: 0.2,
            confirmed_floor_m: 0.6,
        };
        let floors: Vec<f64> = [0.0, 0.24, 0.25, 0.5, 0.74, 0.75, 1.0]
            .iter()
            .map(|&h| c.floor_at(h))
            .collect();
        assert_eq!(floors, [0.05, 0.05, 0.05, 0.2, 0.2, 0.2, 0.2]);
        assert!((c.radius(0.01, 0.0, 0.5, false) - 0.22).abs() < 1e-12);
        assert_eq!(c.radius(0.01, 0.5, 0.5, false), 0.5);
        assert_eq!(c.radius(0.01, 0.5, 0.5, true), 0.6);
        assert_eq!(c.radius(0.01, 0.7, 0.5, true), 0.7);
        assert_eq!(Calibration::of(&c.apply(ArmFitConfig::default())), c);
    }

    #[test]
    fn bad_masks_are_no_pose_not_errors() {
        let (arm, camera) = setup();
        let mut fitter = ArmFitter::new(CpuRenderer::new(), arm, ArmFitConfig::default());
        let n = 128 * 128;
        let empty = ArmMasks {
            width: 128,
            height: 128,
            parts: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            background: vec![1.0; n],
            depth_m: None,
        };
        assert_eq!(
            fitter.fit(&camera, &empty).expect("runs"),
            Err(NoPose::Empty)
        );
        let mut nan = empty.clone();
        nan.parts[1][77] = f32::NAN;
        assert_eq!(
            fitter.fit(&camera, &nan).expect("runs"),
            Err(NoPose::NotAProbability)
        );
        // A blob far from anything the arm can reach: no configuration explains it.
        let mut far = empty.clone();
        for y in 0..6 {
            for x in 0..6 {
                far.parts[1][y * 128 + x] = 1.0;
                far.background[y * 128 + x] = 0.0;
            }
        }
        assert_eq!(
            fitter.fit(&camera, &far).expect("runs"),
            Err(NoPose::PoorFit)
        );
        let small = ArmMasks { width: 64, ..empty };
        assert!(fitter.fit(&camera, &small).is_err());
    }
}
