//! The fit's settings ([`ArmFitConfig`]) and their defaults.

use super::ConfidentFloors;
#[cfg(doc)]
use super::FitSettings;

/// Settings of the articulated fit.
// Serialize: the docs' stated defaults are checked against it (tests/defaults.rs).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
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
    /// Render each part's convex hull instead of its pieces: the same outline where a part
    /// is convex, from fewer triangles (the whole body's upper arm, forearm and hand: 96,
    /// 108 and 24 triangles against 270, 276 and 178). Default false.
    pub hull_outlines: bool,
    /// The tracker's region of interest ([`crate::ArmTracker::region`]) holds the hand's far
    /// end as well as the shoulder, elbow and wrist, and a frame whose forearm or hand masks
    /// reach the region's edge sends the next frame to the workspace crop (without it, a
    /// frame whose hand masks reach the edge where the fitted hand does not;
    /// [`crate::tracker::CUT_RING_PX`]). Not a setting of the fit itself but of what it is
    /// shown: a bound is measured on crops of one kind ([`FitSettings`]). Default false.
    pub hand_region: bool,
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
    /// The floors of a fit that kept its track ([`Calibration::tracked_floors_m`]), m.
    /// Default none: the same floors as any fit.
    pub uncertainty_tracked_floors_m: Option<[f64; 4]>,
    /// The floors of a fit from a gain up ([`Calibration::confident`]). Default none: the
    /// gain does not choose the floors.
    pub uncertainty_confident: Option<ConfidentFloors>,
    /// The global search runs, beside the tracked hypotheses, when their best gain is below
    /// this: a track that explains the masks this poorly has likely followed a wrong
    /// optimum. Default 0.55.
    pub search_below_gain: f64,
    /// The global search runs on at most one in `search_interval` fits: a frame that would
    /// search within `search_interval - 1` fits of the last search climbs its track and the
    /// other starts alone, and its fit counts as searched for the bound
    /// ([`BoundInputs::tracked`] false), not as a kept track. A search renders about six
    /// times a tracked fit's masks, and a tracker that has lost the person searches on every
    /// frame; a machine that must keep to the camera's time spreads the searches out.
    /// Default 1: whenever a track is poor or missing.
    pub search_interval: usize,
    /// With a depth image: the spread of a part's seen surface about its model's, m.
    /// Default 0.03.
    pub depth_sigma_m: f64,
    /// With a depth image: the score a part's axis points lose at one `depth_sigma_m` of
    /// disagreement (mean over the points that land on their part's mask; at most 9 sigma
    /// squared each). Default 0.05.
    pub depth_weight: f64,
    /// With a depth image: the score the trunk's stage takes off the torso's outline at one
    /// `depth_sigma_m` of disagreement between its render and the depth image (the mean
    /// over the torso's pixels, at most 9 sigma squared each; [`ArmFitter::fit_trunk`]).
    /// Default 0.2, four times the arm's parts' `depth_weight`: the torso's outline leaves
    /// its turn and side bend to a tenth of a radian either way, and the depth image shows
    /// one shoulder nearer. On the tuning clips 1-12 with true masks (and the track kept
    /// among the stage's finalists) 0.2 against 0.05 took the median episode's error from
    /// 45.8 to 39.6 mm, lower in 11 of 12 (35.0 with the climb down to 5 mrad, as
    /// shipped); 0.5 gave 40.8 (experiments/perception.md, 2026-12-06).
    pub trunk_depth_weight: f64,
    /// On a model whose trunk turns, leans, bends or walks ([`ArticulatedArm::trunk`]), fit
    /// the trunk to the torso's mask (and the depth image) before the arm
    /// ([`ArmFitter::fit_trunk`]); otherwise the trunk stays upright where the cell puts the
    /// person. Default false. On the whole body's test split (`workcell eval pose --dataset
    /// out/dataset-human --depth --trunk fit|upright`) it gives a pose in 3,247 instead of
    /// 2,113 of 3,460 frames with true masks, and with `procnet-depth-human`'s masks in
    /// 2,822 instead of 1,974 at a median forearm error of 1.5 against 2.1 cm on generated
    /// motion and 4.9 against 8.2 cm on recorded people. The frames it adds are hard ones:
    /// below a gain of 0.7 a bound that covers 99 % of them needs floors of 58 to 114 cm, and
    /// `procnet-depth-human`'s calibration, which runs this fit, gives the fits of a gain of
    /// 0.7 or more floors of 9 cm (51 cm where three quarters of the forearm is hidden);
    /// on recorded people no tuning saw that bound holds for 99.3 % of the frames with a
    /// pose, the upright fit's for 89 % (docs/perception.md, "A bound that reads the gain").
    pub fit_trunk: bool,
    /// Climb from the best fit's forearm turned end for end as well
    /// ([`ArticulatedArm::reversed_forearm`]) and keep it as a hypothesis where it scores as
    /// well. Default false.
    pub reversed_start: bool,
    /// With a depth image, climb from the forearm where its measured points put it (their
    /// principal axis; the end nearer the upper arm's points and farther from the hand's
    /// the elbow, both ways round where they do not tell) as well. Default false.
    pub depth_start: bool,
    /// With a depth image, the trunk's stage also starts from the trunk that lays the
    /// torso's spine along the principal axis of its depth points (at each turn of its
    /// grid): leans beyond the grid's range. Default true.
    pub spine_start: bool,
    /// The trunk's stage ([`ArmFitter::fit_trunk`]) runs on the torso's planes at `1 /
    /// trunk_downsample` of the masks' resolution (block means of the masks, block medians
    /// of the depth image; 1 keeps the masks' own). Its renders are most of the stage's time,
    /// and their pixels fall with the square. Default 1.
    pub trunk_downsample: u32,
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
            hull_outlines: false,
            hand_region: false,
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
            uncertainty_tracked_floors_m: None,
            uncertainty_confident: None,
            search_below_gain: 0.55,
            search_interval: 1,
            depth_sigma_m: 0.03,
            depth_weight: 0.05,
            trunk_depth_weight: 0.2,
            fit_trunk: false,
            reversed_start: false,
            depth_start: false,
            spine_start: true,
            trunk_downsample: 1,
        }
    }
}
