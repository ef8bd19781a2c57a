//! The search ([`ArmFitter`]): hypotheses, the climb, the Newton steps, the bound.

use std::collections::HashMap;
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_render::{Camera, MaskBatch, Renderer, SpanBatch};
use workcell_robots::math::{Pose, Vector};

use super::*;
use crate::error::{PerceptionError, Result};
use crate::pose::image::crop_camera;
use crate::pose::{NoPose, RigidModel, f_m};

/// The arm found in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmFit {
    /// The human model's joint positions, rad (the trunk's at their held values:
    /// [`ArticulatedArm::configuration`]).
    pub q: Vec<f64>,
    /// The link frames of the upper arm, the forearm and the hand in the camera frame.
    pub X_CL: [Pose; 3],
    /// The paper's `f_m` of the forearm's mask and its render at the fit, whole image.
    pub f_m: f64,
    /// The gain over rendering nothing, all parts together (1: a perfect fit).
    pub gain: f64,
    /// Each part's share of [`ArmFit::gain`].
    pub part_gain: [f64; 3],
    /// Per fitted joint ([`ArticulatedArm::fitted`]), the spread of its position (the
    /// covariance's diagonal), rad.
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
pub(super) struct Target {
    /// The camera at `supersample` times its resolution.
    pub(super) fine: Camera,
    pub(super) X_WC: Pose,
    pub(super) ss: usize,
    /// Per part: the row sums of `s_p - alpha min(d_p, cap)` and of `s_p`, both divided by
    /// the mass.
    pub(super) sums: Arc<[RowSums; 3]>,
    /// Mask pixels: the mass, all parts together.
    pub(super) mass: f64,
    /// The crop's camera (not supersampled), and per part where its mask is; the depth in
    /// the crop when there is one.
    pub(super) camera: Camera,
    pub(super) inside: Arc<[Vec<bool>; 3]>,
    pub(super) depth_m: Option<Arc<Vec<f32>>>,
    /// Depths below this show something in front of the arm ([`HIDDEN_MARGIN_M`] nearer
    /// than [`ArticulatedArm::nearest_depth_m`]); minus infinity without depth.
    pub(super) hidden_below_m: f32,
}

impl Target {
    /// The same target for renders of `ss` samples per pixel side (its planes shared).
    pub(super) fn supersampled(&self, ss: u32) -> Result<Self> {
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
pub(super) struct Score {
    pub(super) objective: f64,
    pub(super) gain: f64,
    pub(super) part_gain: [f64; 3],
}

/// A climb's end.
pub(super) struct Climb {
    pub(super) q: Vec<f64>,
    pub(super) score: Score,
}

/// Articulated render-and-compare of the human's arm, tracking it frame to frame.
pub struct ArmFitter<R: Renderer> {
    pub(super) renderer: R,
    pub(super) arm: ArticulatedArm,
    pub(super) config: ArmFitConfig,
    /// The hypotheses tracked, best first: each its last fits, oldest first (at most two).
    pub(super) tracks: Vec<Vec<Vec<f64>>>,
    /// The forearm's centre and wrist in the world frame where the last frame put them (its
    /// pose, or its best fit of at least [`ArmFitConfig::confirm_min_gain`]).
    pub(super) last_points: Option<[Vector; 2]>,
    /// The next fit whose track would be kept runs the global search beside it
    /// ([`Self::search_next`]).
    pub(super) search_next: bool,
    /// Fits since the global search last ran ([`ArmFitConfig::search_interval`]).
    pub(super) since_search: usize,
    pub(super) batch: MaskBatch,
    pub(super) spans: SpanBatch,
    pub(super) poses: Vec<Pose>,
    /// Scratch of [`Self::score`]: each distinct part pose's index in `poses` (by its bits),
    /// and each candidate's.
    distinct: HashMap<[u64; 7], usize>,
    rendered: Vec<usize>,
    pub(super) renders: usize,
    pub(super) rng: ChaCha8Rng,
    /// The trunk stage's depth renders (`Renderer::render_depth`).
    pub(super) trunk_depth: Vec<f32>,
    /// The trunk's stage's score of the last frame's trunk; `None` where the next frame has
    /// no track to keep (no trunk yet, a reset, or a frame whose arm found no pose).
    pub(super) trunk_last: Option<f64>,
    /// Frames since the trunk's stage last ran its whole search.
    pub(super) trunk_tracked_frames: usize,
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
            search_next: false,
            since_search: usize::MAX,
            batch: MaskBatch::new(),
            spans: SpanBatch::new(),
            poses: Vec::new(),
            distinct: HashMap::new(),
            rendered: Vec::new(),
            renders: 0,
            rng: ChaCha8Rng::seed_from_u64(0),
            trunk_depth: Vec::new(),
            trunk_last: None,
            trunk_tracked_frames: 0,
        }
    }

    /// The fit's settings.
    pub fn config(&self) -> &ArmFitConfig {
        &self.config
    }

    /// The arm fitted.
    pub fn arm(&self) -> &ArticulatedArm {
        &self.arm
    }

    /// Forgets the track: the next frame searches globally, from an upright trunk.
    pub fn reset(&mut self) {
        self.trunk_last = None;
        self.tracks.clear();
        self.last_points = None;
        self.search_next = false;
        self.since_search = usize::MAX;
        if let Some(trunk) = self.arm.trunk.clone() {
            // Finite values within the limits: the kinematics cannot fail.
            let _ = self.arm.hold_trunk(&trunk, &trunk.upright);
        }
    }

    /// Holds the trunk where the model's configuration `q` puts it (each trunk joint
    /// clamped to its limits) for the next fits, until the trunk's stage or [`Self::reset`]
    /// moves it: a trunk known from elsewhere (the labels, for the bound of a perfect
    /// trunk). Returns whether the model has a trunk to hold.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when `q` is not the model's length or not finite.
    pub fn hold_trunk_at(&mut self, q: &[f64]) -> Result<bool> {
        if q.len() != self.arm.model_dof() || q.iter().any(|v| !v.is_finite()) {
            return Err(PerceptionError::Input {
                message: format!(
                    "a trunk from {} joint values (finite) for {} joints",
                    q.len(),
                    self.arm.model_dof()
                ),
            });
        }
        let Some(trunk) = self.arm.trunk.clone() else {
            return Ok(false);
        };
        let values: Vec<f64> = trunk
            .all
            .iter()
            .zip(&trunk.limits)
            .map(|(&i, [lo, hi])| q[i].clamp(*lo, *hi))
            .collect();
        self.arm.hold_trunk(&trunk, &values)?;
        Ok(true)
    }

    /// The next fit whose track would be kept (its gain at least
    /// [`ArmFitConfig::search_below_gain`]) runs the global search beside it: a track that
    /// something else says is wrong (the tracker's region cut the arm where the fit did not
    /// reach) competes with the search's fits. Fits before it that search anyway (no track,
    /// or a poor one) leave the request standing; [`Self::reset`] drops it.
    pub fn search_next(&mut self) {
        self.search_next = true;
    }

    /// Tracks from the model's configuration `q` on the next frame (as if it had been the
    /// last fit).
    pub fn set_prior(&mut self, q: &[f64]) {
        self.tracks = vec![vec![self.arm.fitted_of(q)]];
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
        // The trunk first, from the torso's mask: the arm is then fitted on it.
        if self.config.fit_trunk {
            let t0 = std::time::Instant::now();
            let r0 = self.renders;
            self.fit_trunk(camera, masks)?;
            tracing::trace!(
                renders = self.renders - r0,
                ms = t0.elapsed().as_secs_f64() * 1e3,
                "trunk stage"
            );
        }
        let last_points = self.last_points.take();
        let outcome = self.fit_inner(camera, masks, last_points);
        if let Ok(Ok(fit)) = &outcome {
            tracing::trace!(
                gain = fit.gain,
                reacquired = fit.reacquired,
                renders = fit.renders,
                "arm fit"
            );
        }
        if !matches!(outcome, Ok(Ok(_))) {
            // The arm found no pose on this trunk: the next frame searches for the trunk
            // whole, not from its track alone.
            self.trunk_last = None;
            // A frame without a pose ends the track, unless it left a candidate to confirm.
            if self.last_points.is_none() {
                self.tracks.clear();
            }
        }
        outcome
    }

    pub(super) fn fit_inner(
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
        let mut climbs: Vec<Tracked> = Vec::new();
        // Fits from `confirm_min_gain` up to `min_gain`, each with its track.
        let mut faint: Vec<Tracked> = Vec::new();
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
            sort_climb(&c, climb, track, &mut climbs, &mut faint);
        }
        // The global search when the track is lost, and when the tracked fits explain the
        // masks this poorly (the track has likely followed a wrong optimum).
        let tracked_gain = climbs
            .iter()
            .map(|(climb, _)| climb.score.gain)
            .fold(f64::NEG_INFINITY, f64::max);
        let poor = climbs.is_empty() || tracked_gain < c.search_below_gain;
        // Wanted: a poor or missing track, or a request; it runs when due, and a request
        // made of a poor track stands until a fit whose track would be kept.
        let wanted = poor || self.search_next;
        let due = self.since_search.saturating_add(1) >= c.search_interval.max(1);
        let reacquired = wanted && due;
        if reacquired && !poor {
            self.search_next = false;
        }
        self.since_search = if reacquired {
            0
        } else {
            self.since_search.saturating_add(1)
        };
        if reacquired {
            let searched = self.search(coarse)?;
            if tracing::enabled!(tracing::Level::TRACE) {
                let moved_m = self.search_moved_m(&climbs, &searched, &target.X_WC)?;
                tracing::trace!(
                    tracked_gain,
                    requested = !poor,
                    moved_m = ?moved_m,
                    "arm search"
                );
            }
            for climb in searched {
                sort_climb(&c, climb, Vec::new(), &mut climbs, &mut faint);
            }
        }
        // Starts that neither the track nor the grid gives: the best fit's forearm end for
        // end (the masks and the depth of a forearm read the same both ways, and a climb
        // rarely crosses over), and the forearm where its measured points put it (the
        // upper arm's and the hand's points tell which end is which where they show).
        let mut starts = Vec::new();
        let best = climbs
            .iter()
            .chain(&faint)
            .max_by(|a, b| a.0.score.objective.total_cmp(&b.0.score.objective))
            .map(|(climb, _)| climb.q.clone());
        if c.reversed_start
            && let Some(best) = &best
        {
            starts.push(self.arm.reversed_forearm(best)?);
        }
        let hidden_below_m = (self.arm.nearest_depth_m(&camera.X_WC) - HIDDEN_MARGIN_M) as f32;
        if c.depth_start
            && let Some(measured) =
                measured_forearm(camera, masks, self.arm.forearm(), hidden_below_m)
        {
            // Where the best fit already has the forearm there, that end order needs no
            // climb of its own.
            let best_ends = best
                .as_deref()
                .map(|q| self.arm.forearm_ends(q))
                .transpose()?;
            let from: Vec<&[f64]> = best.iter().map(Vec::as_slice).collect();
            for goal in measured.goals() {
                let agrees = best_ends.is_some_and(|ends| {
                    ends.iter()
                        .zip(&goal)
                        .all(|(e, g)| (*e - *g).length() < DEPTH_START_AGREES_M)
                });
                if !agrees {
                    starts.push(self.arm.forearm_to(goal, &from)?);
                }
            }
        }
        for start in starts {
            let climb = self.climb(coarse, start, None)?;
            sort_climb(&c, climb, Vec::new(), &mut climbs, &mut faint);
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
                tracing::trace!(
                    tracks = self.tracks.len(),
                    "poor fit: no fit above confirm_min_gain"
                );
                return Ok(Err(NoPose::PoorFit));
            };
            let points = self.forearm_points(&best.q, &target.X_WC)?;
            let points = points.map(|p| target.X_WC.transform_point(p));
            confirmed = last_points.is_some_and(|last| {
                last.iter()
                    .zip(&points)
                    .all(|(a, b)| (*a - *b).length() <= c.confirm_m)
            });
            tracing::trace!(
                gain = best.score.gain,
                from_track = !track.is_empty(),
                moved_m = ?last_points.map(|last| {
                    [(last[0] - points[0]).length(), (last[1] - points[1]).length()]
                }),
                confirmed,
                "faint fit"
            );
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
        let X_CL = self.arm.fitted_part_poses(&climb.q, &target.X_WC)?;
        let hidden_share = self.hidden_share(&target, &X_CL);
        let forearm = self.arm.forearm.mesh.clone();
        self.renderer
            .render_masks(&forearm, camera, &[X_CL[1]], &mut self.batch)?;
        self.renders += 1;
        Ok(Ok(ArmFit {
            f_m: f_m(masks.forearm(), self.batch.mask(0)),
            X_CL,
            q: self.arm.configuration(&climb.q),
            gain: climb.score.gain,
            part_gain: climb.score.part_gain,
            sigma_q,
            spread_m,
            uncertainty_m: Calibration::of(&c).radius(&BoundInputs {
                sigma_m,
                spread_m,
                hidden_share,
                gain: climb.score.gain,
                confirmed,
                // A poor track whose search was not due is no kept track.
                tracked: !wanted,
            }),
            hidden_share,
            sigma_m,
            reacquired,
            confirmed,
            renders: self.renders,
        }))
    }

    /// How far the search's best fit (by objective) puts the forearm's centre and end from
    /// the tracked fits' best, m; `None` without either (the trace of a search: whether it
    /// found another pose than the track's).
    fn search_moved_m(
        &self,
        tracked: &[Tracked],
        searched: &[Climb],
        X_WC: &Pose,
    ) -> Result<Option<[f64; 2]>> {
        fn best<'a>(climbs: impl Iterator<Item = &'a Climb>) -> Option<&'a Climb> {
            climbs.max_by(|a, b| a.score.objective.total_cmp(&b.score.objective))
        }
        let (Some(track), Some(search)) = (
            best(tracked.iter().map(|(climb, _)| climb)),
            best(searched.iter()),
        ) else {
            return Ok(None);
        };
        let (a, b) = (
            self.forearm_points(&track.q, X_WC)?,
            self.forearm_points(&search.q, X_WC)?,
        );
        Ok(Some([(a[0] - b[0]).length(), (a[1] - b[1]).length()]))
    }

    /// The gain of configuration `q` in `masks`, all parts together and each part's share
    /// (as [`ArmFit::gain`] and [`ArmFit::part_gain`] score a fit); `None` when no part has
    /// support. What a perfect search would score: a fit below the truth's gain is the
    /// search's failure, one above it the masks' ambiguity. Only the arm's joints are read
    /// from `q`: the trunk is the one the fitter holds (the trunk stage's last fit, or
    /// [`Self::hold_trunk_at`]'s), so with a fitted trunk that is wrong the true arm scores
    /// low; hold the true trunk first for the search's bound.
    ///
    /// # Errors
    /// As [`ArmFitter::fit`]; `q` (the model's configuration) of the wrong length or not
    /// finite.
    pub fn gain_at(
        &mut self,
        camera: &Camera,
        masks: &ArmMasks,
        q: &[f64],
    ) -> Result<Option<ArmGain>> {
        let Some(target) = self.target(camera, masks, self.config.supersample)? else {
            return Ok(None);
        };
        if q.len() != self.arm.model_dof() {
            return Err(PerceptionError::Input {
                message: format!(
                    "{} joint values for {} joints",
                    q.len(),
                    self.arm.model_dof()
                ),
            });
        }
        let score = self.score(&target, &[self.arm.fitted_of(q)], None)?[0];
        Ok(Some(ArmGain {
            total: score.gain,
            parts: score.part_gain,
        }))
    }

    /// The forearm's centre and far end (the wrist) in the camera frame at `q`.
    pub(super) fn forearm_points(&self, q: &[f64], X_WC: &Pose) -> Result<[Vector; 2]> {
        let X = self.arm.fitted_part_poses(q, X_WC)?[1];
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
    pub(super) fn local_model(
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
    pub(super) fn refine(
        &mut self,
        target: &Target,
        mut q: Vec<f64>,
    ) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
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
    pub(super) fn position_sigma(&self, q: &[f64], cov: &[Vec<f64>], X_WC: &Pose) -> Result<f64> {
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
    pub(super) fn target(
        &self,
        camera: &Camera,
        masks: &ArmMasks,
        ss: u32,
    ) -> Result<Option<Target>> {
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
    pub(super) fn score(
        &mut self,
        target: &Target,
        qs: &[Vec<f64>],
        prior: Option<&[f64]>,
    ) -> Result<Vec<Score>> {
        let mut scores = vec![Score::default(); qs.len()];
        let all: Vec<[Pose; 3]> = qs
            .iter()
            .map(|q| self.arm.fitted_part_poses(q, &target.X_WC))
            .collect::<Result<_>>()?;
        let ss = target.ss;
        let per_sample = 1.0 / (ss * ss) as f64;
        for p in 0..3 {
            let outlines = if self.config.hull_outlines {
                &self.arm.hulls
            } else {
                &self.arm.meshes
            };
            let Some(mesh) = outlines[p].clone() else {
                continue;
            };
            // Each distinct pose of the part rendered once: candidates that move only the
            // joints below a part (the search's grid, the climb's steps of the elbow) leave
            // it where it was, to the bit.
            self.poses.clear();
            self.distinct.clear();
            self.rendered.clear();
            for x in &all {
                let (t, r) = (x[p].translation, x[p].rotation);
                let key = [t.x, t.y, t.z, r.x, r.y, r.z, r.w].map(f64::to_bits);
                let k = *self.distinct.entry(key).or_insert_with(|| {
                    self.poses.push(x[p]);
                    self.poses.len() - 1
                });
                self.rendered.push(k);
            }
            self.renderer
                .render_spans(&mesh, &target.fine, &self.poses, &mut self.spans)?;
            self.renders += self.poses.len();
            let sums = &target.sums[p];
            for (score, &k) in scores.iter_mut().zip(&self.rendered) {
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
    pub(super) fn hidden_share(&self, target: &Target, poses: &[Pose; 3]) -> f64 {
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
    pub(super) fn depth_cost(&self, target: &Target, depth: &[f32], poses: &[Pose; 3]) -> f64 {
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
    pub(super) fn climb(
        &mut self,
        target: &Target,
        start: Vec<f64>,
        prior: Option<&[f64]>,
    ) -> Result<Climb> {
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
    /// The grid spans the first [`MAX_GRID_JOINTS`] joints with at most `grid^3` cells in all
    /// (`grid` points a joint for three joints, 6 for four of 12); the joints after them
    /// start at the middle of their range (the forearm's rotation, which only the hand
    /// shows).
    pub(super) fn search(&mut self, target: &Target) -> Result<Vec<Climb>> {
        let c = self.config.clone();
        let limits = self.arm.limits().to_vec();
        let spanned = limits.len().min(MAX_GRID_JOINTS);
        let n = grid_points(c.grid, spanned);
        let axes: Vec<Vec<f64>> = limits
            .iter()
            .enumerate()
            .map(|(j, [lo, hi])| {
                let points = if j < spanned { n } else { 1 };
                (0..points)
                    .map(|k| lo + (k as f64 + 0.5) * (hi - lo) / points as f64)
                    .collect()
            })
            .collect();
        let grid = grid_product(&axes);
        let scores = self.score(target, &grid, None)?;
        let mut order: Vec<usize> = (0..grid.len()).collect();
        order.sort_by(|&a, &b| scores[b].objective.total_cmp(&scores[a].objective));
        // Cells at least 1.5 cells apart in some joint.
        let cell: Vec<f64> = limits
            .iter()
            .enumerate()
            .map(|(j, [lo, hi])| (hi - lo) / if j < spanned { n } else { 1 } as f64)
            .collect();
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

/// A climb and the track it continues (empty for a fresh start).
type Tracked = (Climb, Vec<Vec<f64>>);

/// A climb and its track into the fits that reach [`ArmFitConfig::min_gain`] or, from
/// [`ArmFitConfig::confirm_min_gain`], the faint ones; below both it is dropped.
fn sort_climb(
    c: &ArmFitConfig,
    climb: Climb,
    track: Vec<Vec<f64>>,
    climbs: &mut Vec<Tracked>,
    faint: &mut Vec<Tracked>,
) {
    if climb.score.gain >= c.min_gain {
        climbs.push((climb, track));
    } else if climb.score.gain >= c.confirm_min_gain {
        faint.push((climb, track));
    }
}

/// How near the best fit's forearm ends must lie to the measured ones
/// ([`measured_forearm`], one order) for the depth start of that order to be skipped, m.
pub(super) const DEPTH_START_AGREES_M: f64 = 0.05;

/// Forearm mask pixels with depth below which [`measured_forearm`] gives no axis; the
/// upper arm's and the hand's pixels below which their points tell nothing of the order.
pub(super) const MEASURED_FOREARM_MIN_PIXELS: usize = 24;

/// How much nearer, summed over the upper arm's and the hand's points, one end order must
/// put the elbow to the upper arm and the wrist to the hand than the other for
/// [`measured_forearm`] to keep that order alone, m.
pub(super) const MEASURED_ORDER_MARGIN_M: f64 = 0.08;

/// Where the depth image puts the forearm: its two ends (world), and whether the upper
/// arm's and the hand's points tell which is the elbow.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct MeasuredForearm {
    /// The ends; `[elbow, wrist]` where `ordered`.
    pub(super) ends: [Vector; 2],
    pub(super) ordered: bool,
}

impl MeasuredForearm {
    /// The end orders a start should try: `[elbow, wrist]` alone where the order is known,
    /// else both.
    pub(super) fn goals(&self) -> Vec<[Vector; 2]> {
        let [a, b] = self.ends;
        if self.ordered {
            vec![[a, b]]
        } else {
            vec![[a, b], [b, a]]
        }
    }
}

/// The world points a part's mask shows (probability at least a half) where the depth image
/// has a depth of at least `hidden_below_m` (nearer pixels show something in front of the
/// arm, such as an occluder, not the part); none without a depth image.
fn part_points(camera: &Camera, masks: &ArmMasks, part: usize, hidden_below_m: f32) -> Vec<Vector> {
    match (masks.depth_m.as_ref(), masks.parts.get(part)) {
        (Some(depth), Some(plane)) => {
            plane_points(camera, masks.width, plane, depth, hidden_below_m)
        }
        _ => Vec::new(),
    }
}

/// The world points of the pixels of `plane` (row-major, `width` wide) of probability at
/// least a half, back-projected at their `depth`, where that is at least `hidden_below_m`.
pub(super) fn plane_points(
    camera: &Camera,
    width: usize,
    plane: &[f32],
    depth: &[f32],
    hidden_below_m: f32,
) -> Vec<Vector> {
    plane
        .iter()
        .zip(depth)
        .enumerate()
        .filter(|(_, (m, z))| **m >= 0.5 && z.is_finite() && **z > 0.0 && **z >= hidden_below_m)
        .map(|(p, (_, &z))| {
            let (x, y) = ((p % width) as f64 + 0.5, (p / width) as f64 + 0.5);
            camera
                .X_WC
                .transform_point(camera.point_at(x, y, f64::from(z)))
        })
        .collect()
}

/// The forearm's two ends (world) where the depth image puts it: the points its mask's
/// pixels show ([`part_points`]: nothing nearer than `hidden_below_m`), pushed back along
/// their rays by the `forearm` model's half width from its surface to its axis; their mean
/// and principal axis, the ends half the forearm's length either way. The elbow is the end
/// nearer the upper arm's points and farther from the hand's, where that differs by
/// [`MEASURED_ORDER_MARGIN_M`]. `None` without a depth image, with fewer than
/// [`MEASURED_FOREARM_MIN_PIXELS`] forearm points, or where they show no axis (as long
/// across as along).
pub(super) fn measured_forearm(
    camera: &Camera,
    masks: &ArmMasks,
    forearm: &RigidModel,
    hidden_below_m: f32,
) -> Option<MeasuredForearm> {
    let points = part_points(camera, masks, 1, hidden_below_m);
    if points.len() < MEASURED_FOREARM_MIN_PIXELS {
        return None;
    }
    let (centroid, covariance) = mean_and_covariance(points.iter().copied())?;
    let (axis, elongation) = principal_axis(covariance)?;
    // A forearm seen end on, or a blob: no axis to start from.
    if elongation <= 4.0 {
        return None;
    }
    let eye = camera.X_WC.translation;
    let centre = centroid + forearm.half_width_m * (centroid - eye).normalize();
    let half = 0.5 * forearm.length_m * axis;
    let [a, b] = [centre - half, centre + half];
    // How much nearer [a, b] puts the elbow to the upper arm and the wrist to the hand than
    // [b, a] does.
    let mut lead = 0.0;
    for (part, sign) in [(0, 1.0), (2, -1.0)] {
        let points = part_points(camera, masks, part, hidden_below_m);
        if points.len() >= MEASURED_FOREARM_MIN_PIXELS {
            let c = points.iter().fold(Vector::ZERO, |s, p| s + *p) / points.len() as f64;
            lead += sign * ((b - c).length() - (a - c).length());
        }
    }
    Some(if lead >= MEASURED_ORDER_MARGIN_M {
        MeasuredForearm {
            ends: [a, b],
            ordered: true,
        }
    } else if lead <= -MEASURED_ORDER_MARGIN_M {
        MeasuredForearm {
            ends: [b, a],
            ordered: true,
        }
    } else {
        MeasuredForearm {
            ends: [a, b],
            ordered: false,
        }
    })
}

/// Joints the global search's grid spans at most.
pub const MAX_GRID_JOINTS: usize = 4;

/// Grid points per joint for `joints` joints: `grid` for up to three, fewer beyond so that
/// the cells stay at most `grid^3` (at least 2 a joint).
pub(super) fn grid_points(grid: usize, joints: usize) -> usize {
    let grid = grid.max(1);
    if joints <= 3 {
        return grid;
    }
    let budget = (grid as f64).powi(3);
    let mut n = budget.powf(1.0 / joints as f64).floor().max(2.0) as usize;
    // Floating point may leave the root a hair below an exact integer.
    while (n + 1).pow(joints as u32) as f64 <= budget {
        n += 1;
    }
    n
}
