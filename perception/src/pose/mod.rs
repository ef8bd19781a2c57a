//! The forearm's 6-DoF pose from its mask, by render-and-compare.
//!
//! A candidate pose is scored by the paper's agreement between the observed mask `m` (values
//! in [0, 1], ProcNet's probabilities or a binary mask) and the mask `mhat` the renderer draws
//! for the candidate:
//!
//! ```text
//! f_m(m, mhat) = sum_ij 4 (m_ij - 1/2)(mhat_ij - 1/2) / (w h)      in [-1, 1]
//! ```
//!
//! With `s = 2 m - 1` and a binary render this is `(2 sum_{mhat=1} s - sum s) / (w h)`, so a
//! candidate costs one sum over the pixels it covers. The search runs in a region of interest
//! around the mask (and the previous pose), [`PoseConfig::roi`]; pixels outside it are taken
//! as background. On a 30-pixel forearm in a 128x128 image `f_m` moves in its third decimal,
//! so thresholds use the *gain* of a candidate over rendering nothing,
//! `(f_m - f_m(m, 0)) / (1 - f_m(m, 0))`, which for a binary mask is
//! `(true positives - false positives) / mask pixels`: 1 for a perfect fit, 0 for no better
//! than an empty image. Both orderings are the same within a frame.
//!
//! - **With a prior** (the previous frame's pose): gradient ascent from the prior. The
//!   gradient is a central difference from 12 renders around the current pose in scaled
//!   coordinates (one unit moves the image by about a pixel: `z / f` across, `z^2 / (f L)` in
//!   depth, `2 z / (f L)` swinging the forearm's axis, `z / (f w)` spinning about it), then a
//!   line search of 3 renders along it; 12 random probes share the batch. An improving step
//!   may grow the difference step by 1.5; a failed one halves it; the climb stops when the
//!   step falls below [`PoseConfig::min_step_px`] or after [`PoseConfig::max_iterations`].
//!   The forearm's bones are under two pixels thick, so the exact score is flat beyond a
//!   pixel of misalignment: the climb runs coarse to fine, comparing masks dilated by 2 and 1
//!   pixels and with the render's pixel coverage before the paper's point-sampled comparison.
//! - **Without a prior**, or when the climb ends below [`PoseConfig::min_gain`] (the track is
//!   lost): a global search. Orientation hypotheses are directions of the forearm's axis on a
//!   sphere (a hemisphere without an anchor: the forearm is symmetric end for end) that agree
//!   with the mask's principal axis, at two spins; each one's centre lies on the ray through
//!   the mask's centroid, at the depth the mask's length and the forearm's known length give
//!   (or, with an anchor, at the depths that put the anchored end on its sphere). All are
//!   rendered in one batch; the best few are climbed and the best climb wins. Such frames are
//!   marked [`PoseEstimate::reacquired`].
//! - **An anchor** ([`Anchor`]): a thin rod's silhouette fixes the rays through its ends but
//!   not where along them the ends lie, a one-parameter family of poses with the same mask.
//!   The forearm's elbow hangs from a shoulder whose place in the cell is known; a penalty
//!   keeps it on that sphere. One ambiguity is left: the wrist at either point of its ray a
//!   forearm's length from the elbow (the *mirror*).
//! - **Uncertainty**: per camera axis, the displacement over which the gain of the quadratic
//!   fitted to the last central differences drops by two mask pixels' worth; the spread of
//!   the climbed hypotheses that end within 0.05 gain of the best; and, with an anchor, the
//!   distance to the mirror's wrist when the mask cannot tell the two apart.
//!   [`PoseEstimate::uncertainty_m`] is the largest, the radius by which the safety layer
//!   inflates the arm's capsules.
//!
//! Spin about the forearm's axis is weakly observable (two thin bones side by side); it is
//! reported, and evaluated, on its own.

pub mod eval;

use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_robots::math::{Pose, Rotation, Vector};
use workcell_sim::render::{Camera, MaskBatch, RenderMesh, Renderer};

use crate::error::{PerceptionError, Result};

/// Settings of the pose search.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseConfig {
    /// A fit whose gain is below this is no pose (and ends a track). Default 0.3.
    pub min_gain: f64,
    /// A fit that leaves more than this fraction of the mask's support farther than a pixel
    /// from the render is no pose (several blobs, say). Default 0.7.
    pub min_explained: f64,
    /// Climb iterations at most, per level of the coarse-to-fine schedule. Default 12.
    pub max_iterations: usize,
    /// First central-difference step, in pixels of image motion. Default 2.
    pub initial_step_px: f64,
    /// The climb stops when its step falls below this. Default 0.25.
    pub min_step_px: f64,
    /// Axis directions on the hemisphere tried by the global search. Default 64.
    pub directions: usize,
    /// Global hypotheses climbed. Default 4.
    pub refine: usize,
    /// Random probes per climb iteration, besides the 12 of the central difference.
    /// Default 12.
    pub random_probes: usize,
    /// Render only a region of interest around the mask (the previous pose included):
    /// its bounding box grown by 60 % of its size and at least 6 px per side. Default true.
    pub roi: bool,
    /// Mask values above this are the forearm's support. Default 0.5.
    pub threshold: f32,
}

impl Default for PoseConfig {
    fn default() -> Self {
        Self {
            min_gain: 0.3,
            min_explained: 0.7,
            max_iterations: 12,
            initial_step_px: 2.0,
            min_step_px: 0.25,
            directions: 64,
            refine: 4,
            random_probes: 12,
            roi: true,
            threshold: 0.5,
        }
    }
}

/// The rigid object searched for: its render mesh and its axis.
#[derive(Debug, Clone)]
pub struct RigidModel {
    pub mesh: Arc<RenderMesh>,
    /// Centre of the mesh's bounding box, object frame.
    pub centre_O: Vector,
    /// Unit direction of the bounding box's longest side, object frame.
    pub axis_O: Vector,
    /// Length of that side, m.
    pub length_m: f64,
    /// Half the longer of the other two sides, m.
    pub half_width_m: f64,
    corners_O: [Vector; 8],
}

impl RigidModel {
    /// The model of `mesh`, its axis the longest side of its bounding box.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] for an empty mesh or one with non-finite vertices.
    pub fn new(mesh: Arc<RenderMesh>) -> Result<Self> {
        let mut lo = Vector::splat(f64::INFINITY);
        let mut hi = Vector::splat(f64::NEG_INFINITY);
        for p in &mesh.positions {
            let p = Vector::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            lo = lo.min(p);
            hi = hi.max(p);
        }
        if mesh.is_empty() || !(lo.is_finite() && hi.is_finite()) {
            return Err(PerceptionError::Input {
                message: "the pose model's mesh is empty or not finite".into(),
            });
        }
        let size = hi - lo;
        let k = (0..3)
            .max_by(|&a, &b| size[a].total_cmp(&size[b]))
            .unwrap_or(2);
        let mut axis_O = Vector::ZERO;
        axis_O[k] = 1.0;
        let corners_O = std::array::from_fn(|i| {
            Vector::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        });
        Ok(Self {
            mesh,
            centre_O: 0.5 * (lo + hi),
            axis_O,
            length_m: size[k],
            half_width_m: 0.5
                * (0..3)
                    .filter(|&i| i != k)
                    .map(|i| size[i])
                    .fold(0.0, f64::max),
            corners_O,
        })
    }

    /// The pose of the object whose centre is at `centre_C` with rotation `R_CO`.
    #[must_use]
    pub fn pose(&self, centre_C: Vector, R_CO: Rotation) -> Pose {
        Pose::from_parts(centre_C - R_CO * self.centre_O, R_CO)
    }

    /// The object's centre at `X_CO`.
    #[must_use]
    pub fn centre(&self, X_CO: &Pose) -> Vector {
        X_CO.transform_point(self.centre_O)
    }

    /// The symmetric twin of `X_CO`: turned half a revolution about the axis through the
    /// centre perpendicular to the forearm's (the first other box axis), so its ends swap.
    /// Its mask differs from `X_CO`'s only by the forearm's small end-to-end asymmetries.
    #[must_use]
    pub fn twin(&self, X_CO: &Pose) -> Pose {
        let k = (0..3).find(|&i| self.axis_O[i] == 0.0).unwrap_or(0);
        let mut across = Vector::ZERO;
        across[k] = 1.0;
        let R = X_CO.rotation * Rotation::from_axis_angle(across, std::f64::consts::PI);
        self.pose(self.centre(X_CO), R)
    }
}

/// Where one point of the object must be: at `radius_m` from `point_C`. The forearm's elbow
/// end hangs from the shoulder by the upper arm, and the shoulder of a fixed-base human arm
/// is at a known place in the cell: this pins down the depth that the silhouette of a thin
/// forearm leaves open (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Anchor {
    /// The object point, object frame (the elbow: the forearm link's origin).
    pub end_O: Vector,
    /// The sphere's centre (the shoulder), camera frame.
    pub point_C: Vector,
    pub radius_m: f64,
    /// A violation of this many metres costs as much as one mispredicted mask pixel.
    pub sigma_m: f64,
}

/// Why a frame gave no pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoPose {
    /// No mask value above the threshold: nothing seen, or fully occluded.
    Empty,
    /// A value that is not a probability in [0, 1] (NaN from the network, say).
    NotAProbability,
    /// Several separate blobs that no single forearm pose explains.
    SeveralBlobs { blobs: usize },
    /// The best fit's gain stayed below [`PoseConfig::min_gain`].
    PoorFit,
}

impl std::fmt::Display for NoPose {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NoPose::Empty => write!(f, "empty mask"),
            NoPose::NotAProbability => write!(f, "mask values not in [0, 1]"),
            NoPose::SeveralBlobs { blobs } => write!(f, "{blobs} blobs no one pose explains"),
            NoPose::PoorFit => write!(f, "no pose fits the mask"),
        }
    }
}

/// A pose found.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseEstimate {
    /// The object (forearm link) frame in the camera frame.
    pub X_CO: Pose,
    /// The paper's `f_m` over the whole image at `X_CO`.
    pub f_m: f64,
    /// Gain over an empty render (see the module docs), in the search's region of interest,
    /// with the render's pixel coverage as `mhat`.
    pub gain: f64,
    /// The fraction of the mask's support within a pixel of the render at `X_CO`.
    pub explained: f64,
    /// Position uncertainty along the camera's x, y, z axes, m.
    pub sigma_C_m: [f64; 3],
    /// Spread of the surviving global hypotheses' centres, m (0 when tracking).
    pub spread_m: f64,
    /// The radius to inflate the forearm by, m: the larger of `|sigma|` and the spread.
    pub uncertainty_m: f64,
    /// Found by the global search (first frame, or the track was lost).
    pub reacquired: bool,
    /// Masks rendered for this frame.
    pub renders: usize,
}

/// The result of one frame.
pub type PoseOutcome = std::result::Result<PoseEstimate, NoPose>;

/// A pose being climbed: the centre in the camera frame and the rotation.
#[derive(Debug, Clone, Copy)]
struct State {
    centre: Vector,
    R: Rotation,
}

impl State {
    /// The state moved by `d` scaled units.
    fn moved(&self, d: &[f64; 6], s: &Scale) -> State {
        let dt = Vector::new(d[0] * s.xy, d[1] * s.xy, d[2] * s.z);
        let dr = Vector::new(d[3] * s.rot[0], d[4] * s.rot[1], d[5] * s.rot[2]);
        State {
            centre: self.centre + dt,
            R: (self.R * Rotation::from_scaled_axis(dr)).normalize(),
        }
    }
}

/// Metres (or radians) per unit of the climb's coordinates: about a pixel of image motion.
/// Rotations are about the object's own axes: a swing of the forearm's axis moves its ends,
/// a spin about it moves its sides.
#[derive(Debug, Clone, Copy)]
struct Scale {
    xy: f64,
    z: f64,
    rot: [f64; 3],
}

impl Scale {
    fn at(centre: Vector, f: f64, model: &RigidModel) -> Scale {
        let z = centre.z.max(0.05);
        let l = model.length_m.max(1e-3);
        let swing = 2.0 * z / (f * l);
        let spin = z / (f * model.half_width_m.max(1e-3));
        Scale {
            xy: z / f,
            z: z * z / (f * l),
            rot: std::array::from_fn(|i| if model.axis_O[i] != 0.0 { spin } else { swing }),
        }
    }
}

/// The observed mask prepared for scoring over the region of interest, at each level of
/// the coarse-to-fine schedule.
struct Target {
    camera: Camera,
    /// The region at SUPERSAMPLE times its resolution.
    fine: Camera,
    x0: usize,
    y0: usize,
    levels: Vec<Level>,
}

/// One level: both masks dilated by `radius` pixels before they are compared; the render
/// supersampled (pixel coverage) or point-sampled like the dataset's masks.
struct Level {
    radius: usize,
    supersample: bool,
    /// `s = 2 m - 1` of the dilated mask.
    signed: Vec<f32>,
    /// `N + sum s`: twice the dilated mask's mass.
    norm: f64,
}

/// The mask's support: pixel count, centroid and second moments, bounding box.
#[derive(Debug, Clone, Copy)]
struct Support {
    centroid: [f64; 2],
    cov: [f64; 3],
    lo: [usize; 2],
    hi: [usize; 2],
}

/// Render-and-compare pose estimation of one rigid object, tracking it frame to frame.
pub struct PoseEstimator<R: Renderer> {
    renderer: R,
    model: RigidModel,
    config: PoseConfig,
    prior: Option<State>,
    anchor: Option<Anchor>,
    batch: MaskBatch,
    poses: Vec<Pose>,
    renders: usize,
    /// Draws the random probes; re-seeded every frame so that a frame's result does not
    /// depend on the frames before it.
    rng: ChaCha8Rng,
}

impl<R: Renderer> PoseEstimator<R> {
    /// An estimator of `model` that renders with `renderer`.
    pub fn new(renderer: R, model: RigidModel, config: PoseConfig) -> Self {
        Self {
            renderer,
            model,
            config,
            prior: None,
            anchor: None,
            batch: MaskBatch::new(),
            poses: Vec::new(),
            renders: 0,
            rng: ChaCha8Rng::seed_from_u64(0),
        }
    }

    /// The model searched for.
    pub fn model(&self) -> &RigidModel {
        &self.model
    }

    /// Forgets the track: the next frame searches globally.
    pub fn reset(&mut self) {
        self.prior = None;
    }

    /// Constrains the next frames' poses with `anchor` (`None`: the mask alone, as in the
    /// paper). Set it again when the camera moves.
    pub fn set_anchor(&mut self, anchor: Option<Anchor>) {
        self.anchor = anchor;
    }

    /// Tracks from `X_CO` on the next frame.
    pub fn set_prior(&mut self, X_CO: &Pose) {
        self.prior = Some(State {
            centre: self.model.centre(X_CO),
            R: X_CO.rotation,
        });
    }

    /// The pose in `mask` (row-major, the camera's size, values in [0, 1]), seen by `camera`.
    /// Tracks from the previous frame's pose when there is one.
    ///
    /// # Errors
    /// [`PerceptionError::Input`] when the mask's length is not the camera's pixel count;
    /// a renderer failure. Masks the estimator cannot use are [`NoPose`], not errors.
    pub fn estimate(&mut self, camera: &Camera, mask: &[f32]) -> Result<PoseOutcome> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        if mask.len() != w * h {
            return Err(PerceptionError::Input {
                message: format!(
                    "mask of {} values for a {w}x{h} camera ({} pixels)",
                    mask.len(),
                    w * h
                ),
            });
        }
        self.renders = 0;
        self.rng = ChaCha8Rng::seed_from_u64(0x504f_5345); // "POSE"
        let outcome = self.estimate_inner(camera, mask);
        if let Ok(Ok(e)) = &outcome {
            self.set_prior(&e.X_CO);
        } else {
            self.prior = None;
        }
        outcome
    }

    fn estimate_inner(&mut self, camera: &Camera, mask: &[f32]) -> Result<PoseOutcome> {
        if mask.iter().any(|v| !(0.0..=1.0).contains(v)) {
            return Ok(Err(NoPose::NotAProbability));
        }
        let Some(support) = support(mask, camera.width as usize, self.config.threshold) else {
            return Ok(Err(NoPose::Empty));
        };
        let prior = self.prior;
        let target = self.target(camera, mask, &support, prior.as_ref())?;
        let f = camera.fx.max(camera.fy);
        let c = self.config.clone();
        let mut found = None;
        if let Some(start) = prior {
            let climb = self.climb(&target, start, f)?;
            let fit = self.fit(camera, mask, &climb)?;
            if climb.gain >= c.min_gain && fit.explained >= c.min_explained {
                found = Some((climb, fit, 0.0, false));
            }
        }
        if found.is_none() {
            // A global search in a region around the mask alone.
            let target = self.target(camera, mask, &support, None)?;
            let searched = match self.search(&target, &support, f)? {
                Some((best, spread)) => {
                    let fit = self.fit(camera, mask, &best)?;
                    (best.gain >= c.min_gain && fit.explained >= c.min_explained)
                        .then_some((best, fit, spread, true))
                }
                None => None,
            };
            if searched.is_some() {
                found = searched;
            } else {
                let blobs = blobs(mask, camera.width as usize, c.threshold);
                return Ok(Err(if blobs > 1 {
                    NoPose::SeveralBlobs { blobs }
                } else {
                    NoPose::PoorFit
                }));
            }
        }
        let Some((climb, fit, mut spread_m, reacquired)) = found else {
            return Ok(Err(NoPose::PoorFit));
        };
        if let Some(mirror) = self.mirror(&climb.state) {
            // The wrist's other point on its ray: as anchored as the fit, and if the mask
            // cannot tell it from the fit either, the fit is only one of two.
            let target = self.target(camera, mask, &support, None)?;
            let last = target.levels.len() - 1;
            let gains = self.score(&target, last, &[climb.state, mirror])?;
            let pixel = 2.0 / target.levels[last].norm.max(1.0);
            if gains[1] >= gains[0] - 2.0 * pixel {
                let far = |s: &State| {
                    self.model
                        .pose(s.centre, s.R)
                        .transform_point(2.0 * self.model.centre_O - self.end_O())
                };
                spread_m = spread_m.max((far(&mirror) - far(&climb.state)).length());
            }
        }
        let sigma = climb.sigma;
        let norm = (sigma[0] * sigma[0] + sigma[1] * sigma[1] + sigma[2] * sigma[2]).sqrt();
        Ok(Ok(PoseEstimate {
            X_CO: self.model.pose(climb.state.centre, climb.state.R),
            f_m: fit.f_m,
            gain: climb.gain,
            explained: fit.explained,
            sigma_C_m: sigma,
            spread_m,
            uncertainty_m: norm.max(spread_m),
            reacquired,
            renders: self.renders,
        }))
    }

    /// The anchored end of the object (its origin without an anchor).
    fn end_O(&self) -> Vector {
        self.anchor.map_or(Vector::ZERO, |a| a.end_O)
    }

    /// With an anchor: `state` turned about its anchored end so that its far end moves to
    /// the other point of the far end's camera ray at the same distance from the anchored
    /// end. The two render nearly the same mask (see the module docs). `None` without an
    /// anchor or when that point is behind the camera.
    fn mirror(&self, state: &State) -> Option<State> {
        self.anchor?;
        let X = self.model.pose(state.centre, state.R);
        let e = X.transform_point(self.end_O());
        let w = X.transform_point(2.0 * self.model.centre_O - self.end_O());
        let r = w.normalize();
        let t = 2.0 * r.dot(e) - w.length();
        if !(t > workcell_sim::render::NEAR_M && (t * r - w).length() > 1e-6) {
            return None;
        }
        let turn = Rotation::from_rotation_arc((w - e).normalize(), (t * r - e).normalize());
        let R = (turn * state.R).normalize();
        // The anchored end stays where it is.
        let centre = e + R * (self.model.centre_O - self.end_O());
        Some(State { centre, R })
    }

    /// The gain of `X_CO` as the global search scores it (for tests).
    #[cfg(test)]
    fn gain_at(&mut self, camera: &Camera, mask: &[f32], X_CO: &Pose) -> Result<f64> {
        let support = support(mask, camera.width as usize, self.config.threshold).ok_or(
            PerceptionError::Input {
                message: "empty mask".into(),
            },
        )?;
        let target = self.target(camera, mask, &support, None)?;
        let state = State {
            centre: self.model.centre(X_CO),
            R: X_CO.rotation,
        };
        Ok(self.score(&target, target.levels.len() - 1, &[state])?[0])
    }

    /// The region of interest and the signed mask in it.
    fn target(
        &self,
        camera: &Camera,
        mask: &[f32],
        support: &Support,
        prior: Option<&State>,
    ) -> Result<Target> {
        let (w, h) = (camera.width as usize, camera.height as usize);
        let (x0, y0, x1, y1) = if self.config.roi {
            let (mut lo, mut hi) = (
                [support.lo[0] as f64, support.lo[1] as f64],
                [support.hi[0] as f64 + 1.0, support.hi[1] as f64 + 1.0],
            );
            if let Some(p) = prior {
                let X = self.model.pose(p.centre, p.R);
                for c in &self.model.corners_O {
                    if let Some([u, v]) = camera.project(X.transform_point(*c)) {
                        lo = [lo[0].min(u), lo[1].min(v)];
                        hi = [hi[0].max(u), hi[1].max(v)];
                    }
                }
            }
            let grow = |a: f64, b: f64| (0.6 * (b - a)).max(6.0);
            let (gx, gy) = (grow(lo[0], hi[0]), grow(lo[1], hi[1]));
            let clamp = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
            (
                clamp((lo[0] - gx).floor(), w),
                clamp((lo[1] - gy).floor(), h),
                clamp((hi[0] + gx).ceil(), w),
                clamp((hi[1] + gy).ceil(), h),
            )
        } else {
            (0, 0, w, h)
        };
        let (rw, rh) = ((x1 - x0).max(1), (y1 - y0).max(1));
        let roi = Camera {
            width: rw as u32,
            height: rh as u32,
            cx: camera.cx - x0 as f64,
            cy: camera.cy - y0 as f64,
            ..*camera
        };
        let mut crop = Vec::with_capacity(rw * rh);
        for y in y0..y0 + rh {
            crop.extend_from_slice(&mask[y * w + x0..y * w + x0 + rw]);
        }
        let levels = LEVELS
            .iter()
            .map(|&(radius, supersample)| {
                let signed: Vec<f32> = dilate(&crop, rw, radius)
                    .iter()
                    .map(|m| 2.0 * m - 1.0)
                    .collect();
                let sum: f64 = signed.iter().map(|&s| f64::from(s)).sum();
                Level {
                    radius,
                    supersample,
                    signed,
                    norm: (rw * rh) as f64 + sum,
                }
            })
            .collect();
        Ok(Target {
            fine: roi.resized(roi.width * SUPERSAMPLE, roi.height * SUPERSAMPLE)?,
            camera: roi,
            x0,
            y0,
            levels,
        })
    }

    /// Gains of the states at a level, rendered in one batch.
    fn score(&mut self, target: &Target, level: usize, states: &[State]) -> Result<Vec<f64>> {
        let level = &target.levels[level];
        self.poses.clear();
        self.poses
            .extend(states.iter().map(|s| self.model.pose(s.centre, s.R)));
        let (camera, ss) = if level.supersample {
            (&target.fine, SUPERSAMPLE as usize)
        } else {
            (&target.camera, 1)
        };
        self.renderer
            .render_masks(&self.model.mesh, camera, &self.poses, &mut self.batch)?;
        self.renders += states.len();
        let norm = level.norm.max(1e-9);
        let (w, h) = (target.camera.width as usize, target.camera.height as usize);
        let mut coverage = vec![0.0f32; w * h];
        Ok((0..states.len())
            .map(|k| {
                // The fraction of each pixel's SUPERSAMPLE^2 samples the render covers.
                coverage.fill(0.0);
                let fine = self.batch.mask(k);
                for (fy, row) in fine.chunks_exact(w * ss).enumerate() {
                    let out = &mut coverage[(fy / ss) * w..(fy / ss + 1) * w];
                    for (fx, &v) in row.iter().enumerate() {
                        if v != 0 {
                            out[fx / ss] += 1.0 / (ss * ss) as f32;
                        }
                    }
                }
                let dilated;
                let rendered = if level.radius == 0 {
                    &coverage
                } else {
                    dilated = dilate(&coverage, w, level.radius);
                    &dilated
                };
                // 4 (m - 1/2)(mhat - 1/2) summed, less its value for an empty render.
                let covered: f64 = rendered
                    .iter()
                    .zip(&level.signed)
                    .map(|(&r, &s)| f64::from(r * s))
                    .sum();
                let penalty = self.anchor.map_or(0.0, |a| {
                    let end = self.poses[k].transform_point(a.end_O);
                    let v = ((end - a.point_C).length() - a.radius_m) / a.sigma_m.max(1e-6);
                    // One mask pixel's worth (norm is twice the mask's mass) per sigma squared.
                    2.0 * v * v / norm
                });
                2.0 * covered / norm - penalty
            })
            .collect())
    }

    /// Gradient ascent from `start`, coarse to fine (see the module docs).
    fn climb(&mut self, target: &Target, start: State, f: f64) -> Result<Climb> {
        let mut state = start;
        let mut last = None;
        for level in 0..target.levels.len() {
            let (s, gain, curvature) = self.climb_level(target, level, state, f)?;
            state = s;
            last = Some((gain, curvature));
        }
        let (gain, curvature) = last.unwrap_or((0.0, [0.0; 3]));
        // Uncertainty: where the quadratic along each axis drops by two mask pixels' worth.
        let c = &self.config;
        let scale = Scale::at(state.centre, f, &self.model);
        let norm = target.levels.last().map_or(1.0, |l| l.norm);
        let tol = 2.0 * 2.0 / norm.max(1.0);
        let unit = [scale.xy, scale.xy, scale.z];
        let cap = 8.0 * c.initial_step_px;
        let sigma = std::array::from_fn(|i| {
            let k = curvature[i];
            let units = if k < 0.0 {
                (2.0 * tol / -k).sqrt().min(cap)
            } else {
                cap
            };
            units * unit[i]
        });
        Ok(Climb { state, gain, sigma })
    }

    /// The climb at one level: its gain and the curvature of the gain along the position
    /// axes (per scaled unit squared) at the end.
    fn climb_level(
        &mut self,
        target: &Target,
        level: usize,
        start: State,
        f: f64,
    ) -> Result<(State, f64, [f64; 3])> {
        let c = self.config.clone();
        // Steps in pixels grow with the dilation: a level sees no finer than its radius.
        let widen = target.levels[level].radius.max(1) as f64;
        let mut state = start;
        let mut gain = self.score(target, level, &[state])?[0];
        let mut h = c.initial_step_px.max(c.min_step_px) * widen;
        let min_h = c.min_step_px * widen;
        let mut curvature = [0.0; 3];
        let mut probes = Vec::with_capacity(12);
        for _ in 0..c.max_iterations {
            let scale = Scale::at(state.centre, f, &self.model);
            probes.clear();
            for i in 0..6 {
                for sign in [1.0, -1.0] {
                    let mut d = [0.0; 6];
                    d[i] = sign * h;
                    probes.push(state.moved(&d, &scale));
                }
            }
            // Random probes in the same batch: the staircase of a thin object's f_m often
            // hides the ridge (depth against tilt) from moves along one axis at a time.
            for _ in 0..c.random_probes {
                let d: [f64; 6] = std::array::from_fn(|_| h * self.rng.random_range(-1.0..1.0));
                probes.push(state.moved(&d, &scale));
            }
            let fp = self.score(target, level, &probes)?;
            for (i, k) in curvature.iter_mut().enumerate() {
                *k = (fp[2 * i] + fp[2 * i + 1] - 2.0 * gain) / (h * h);
            }
            let g: [f64; 6] = std::array::from_fn(|i| (fp[2 * i] - fp[2 * i + 1]) / (2.0 * h));
            let g_norm = g.iter().map(|v| v * v).sum::<f64>().sqrt();
            // The best probe, then the line search along the gradient.
            let (mut best, mut best_gain, mut grow) = (state, gain, false);
            for (p, &v) in probes.iter().zip(&fp) {
                if v > best_gain {
                    (best, best_gain) = (*p, v);
                }
            }
            if g_norm > 0.0 {
                let steps = [4.0 * h, 2.0 * h, h];
                let line: Vec<State> = steps
                    .iter()
                    .map(|a| state.moved(&g.map(|v| a * v / g_norm), &scale))
                    .collect();
                let fl = self.score(target, level, &line)?;
                for (k, (p, &v)) in line.iter().zip(&fl).enumerate() {
                    if v > best_gain {
                        (best, best_gain, grow) = (*p, v, k == 0);
                    }
                }
            }
            if best_gain > gain + 1e-12 {
                (state, gain) = (best, best_gain);
                if grow {
                    h = (1.5 * h).min(4.0 * c.initial_step_px * widen);
                }
            } else {
                h *= 0.5;
                if h < min_h {
                    break;
                }
            }
        }
        Ok((state, gain, curvature))
    }

    /// The global search: hypotheses from the mask's moments, the best few climbed. Returns
    /// the best climb and the spread of those ending within 0.05 gain of it (`None` when no
    /// hypothesis lies in front of the camera).
    fn search(
        &mut self,
        target: &Target,
        support: &Support,
        f: f64,
    ) -> Result<Option<(Climb, f64)>> {
        let mut hypotheses = self.hypotheses(target, support, f, true);
        if hypotheses.is_empty() {
            // No direction puts the anchored end on its sphere: the mask alone.
            hypotheses = self.hypotheses(target, support, f, false);
        }
        let gains = self.score(target, 0, &hypotheses)?;
        let mut order: Vec<usize> = (0..hypotheses.len()).collect();
        order.sort_by(|&a, &b| gains[b].total_cmp(&gains[a]));
        let mut climbs = Vec::new();
        for &k in order.iter().take(self.config.refine.max(1)) {
            climbs.push(self.climb(target, hypotheses[k], f)?);
        }
        climbs.sort_by(|a, b| b.gain.total_cmp(&a.gain));
        let Some(best) = climbs.first().cloned() else {
            return Ok(None);
        };
        let spread = climbs
            .iter()
            .filter(|c| c.gain >= best.gain - 0.05)
            .map(|c| (c.state.centre - best.state.centre).length())
            .fold(0.0, f64::max);
        Ok(Some((best, spread)))
    }

    /// Orientation and depth hypotheses for a mask with `support` (see the module docs).
    fn hypotheses(
        &self,
        target: &Target,
        support: &Support,
        f: f64,
        use_anchor: bool,
    ) -> Vec<State> {
        let anchor = self.anchor.filter(|_| use_anchor);
        let cam = &target.camera;
        let [sxx, sxy, syy] = support.cov;
        let tr = sxx + syy;
        let det = sxx * syy - sxy * sxy;
        let l1 = 0.5 * tr + (0.25 * tr * tr - det).max(0.0).sqrt();
        let l2 = (tr - l1).max(0.0);
        let phi = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        // The length of a uniform rod with variance l1 along it, at least two pixels.
        let length_px = (12.0 * l1).sqrt().max(2.0);
        let elongated = l1 > 4.0 * l2.max(0.25);
        // The centroid in the region's pixel coordinates.
        let u = support.centroid[0] - target.x0 as f64;
        let v = support.centroid[1] - target.y0 as f64;
        let (L, n) = (self.model.length_m, self.config.directions.max(1));
        // A fixed reference: of each axis and its opposite, the one on its side.
        let k_ref = Vector::new(0.31, 0.53, 0.79).normalize();
        let ray = Vector::new((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
        let mut out = Vec::new();
        for i in 0..2 * n {
            // Fibonacci sphere of 2n points; without an anchor, the hemisphere facing k_ref
            // (the other is the same forearm end for end).
            let zf = 1.0 - (2.0 * i as f64 + 1.0) / (2 * n) as f64;
            let r = (1.0 - zf * zf).max(0.0).sqrt();
            let theta = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let a = Vector::new(r * theta.cos(), r * theta.sin(), zf);
            if anchor.is_none() && a.dot(k_ref) < 0.0 {
                continue;
            }
            let in_image = a.x.hypot(a.y);
            if elongated && in_image > 0.3 {
                let angle = a.y.atan2(a.x) - phi;
                let d = (angle.sin()).atan2(angle.cos()).abs();
                let d = d.min(std::f64::consts::PI - d);
                if d > 30f64.to_radians() {
                    continue;
                }
            }
            let align = Rotation::from_rotation_arc(self.model.axis_O, a);
            let z = (f * L * in_image.max(0.15) / length_px).clamp(0.3, 20.0);
            for roll in [0.0, std::f64::consts::FRAC_PI_2] {
                let R = (Rotation::from_axis_angle(a, roll) * align).normalize();
                let depths = match &anchor {
                    // The depths on the centroid's ray that put the anchored end on its sphere.
                    Some(anchor) => {
                        let w = R * (anchor.end_O - self.model.centre_O) - anchor.point_C;
                        let (qa, qb) = (ray.length_squared(), ray.dot(w));
                        let qc = w.length_squared() - anchor.radius_m * anchor.radius_m;
                        let disc = qb * qb - qa * qc;
                        if disc < 0.0 {
                            continue;
                        }
                        [(-qb - disc.sqrt()) / qa, (-qb + disc.sqrt()) / qa]
                    }
                    None => [z, 0.8 * z],
                };
                for depth in depths.into_iter().filter(|d| *d > 0.1) {
                    out.push(State {
                        centre: ray * depth,
                        R,
                    });
                }
            }
        }
        out
    }

    /// The paper's `f_m` over the whole image at the climb's pose, and the fraction of the
    /// mask's support within a pixel of the render.
    fn fit(&mut self, camera: &Camera, mask: &[f32], climb: &Climb) -> Result<Fit> {
        let X_CO = self.model.pose(climb.state.centre, climb.state.R);
        self.renderer.render_masks(
            &self.model.mesh,
            camera,
            std::slice::from_ref(&X_CO),
            &mut self.batch,
        )?;
        self.renders += 1;
        let rendered = self.batch.mask(0);
        let near: Vec<f32> = rendered
            .iter()
            .map(|&v| f32::from(u8::from(v != 0)))
            .collect();
        let near = dilate(&near, camera.width as usize, 1);
        let (mut inside, mut total) = (0usize, 0usize);
        for (&m, &r) in mask.iter().zip(&near) {
            if m > self.config.threshold {
                total += 1;
                inside += usize::from(r > 0.0);
            }
        }
        Ok(Fit {
            f_m: f_m(mask, rendered),
            explained: inside as f64 / total.max(1) as f64,
        })
    }
}

/// How well a pose fits the mask, at full resolution.
#[derive(Debug, Clone, Copy)]
struct Fit {
    f_m: f64,
    explained: f64,
}

/// A finished climb.
#[derive(Debug, Clone)]
struct Climb {
    state: State,
    gain: f64,
    sigma: [f64; 3],
}

/// The coarse-to-fine schedule: (dilation radius in px, supersampled render). The forearm
/// is one or two pixels thick, so the exact score is flat beyond a pixel of misalignment:
/// comparing dilated masks first widens the basin the climb can see, and pixel coverage
/// makes the score change with sub-pixel motion. Coverage favours thin (far) renders a
/// little (a covered fraction outside a point-sampled mask counts against it), so the last
/// level is the paper's own comparison of point-sampled masks.
const LEVELS: [(usize, bool); 4] = [(2, true), (1, true), (0, true), (0, false)];

/// Grey-scale dilation (a `(2r+1)^2` maximum) of a row-major image of width `w`.
fn dilate(src: &[f32], w: usize, r: usize) -> Vec<f32> {
    if r == 0 || w == 0 {
        return src.to_vec();
    }
    let h = src.len() / w;
    let mut rows = vec![0.0f32; src.len()];
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (x.saturating_sub(r), (x + r).min(w - 1));
            rows[y * w + x] = src[y * w + a..=y * w + b]
                .iter()
                .fold(0.0, |m, &v| m.max(v));
        }
    }
    let mut out = vec![0.0f32; src.len()];
    for y in 0..h {
        let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
        for x in 0..w {
            out[y * w + x] = (a..=b).map(|yy| rows[yy * w + x]).fold(0.0, f32::max);
        }
    }
    out
}

/// Candidates are rendered at this many samples per pixel side and compared by the covered
/// fraction of each pixel: `f_m` then changes with sub-pixel motion instead of in steps of
/// whole pixels, which the numerical gradient needs on a forearm one or two pixels thick.
const SUPERSAMPLE: u32 = 3;

/// The paper's agreement of a mask `m` (values in [0, 1]) and a binary mask `mhat` (0 or
/// not 0) of the same size: `sum 4 (m - 1/2)(mhat - 1/2) / (w h)`, in [-1, 1]. For two
/// binary masks it is `1 - 2 x` the fraction of pixels where they differ.
#[must_use]
pub fn f_m(m: &[f32], mhat: &[u8]) -> f64 {
    let n = m.len().min(mhat.len());
    if n == 0 {
        return 0.0;
    }
    let sum: f64 = m
        .iter()
        .zip(mhat)
        .map(|(&m, &r)| {
            let r = if r != 0 { 0.5 } else { -0.5 };
            4.0 * (f64::from(m) - 0.5) * r
        })
        .sum();
    sum / n as f64
}

/// The support of `mask` above `threshold` (`None` when empty).
fn support(mask: &[f32], width: usize, threshold: f32) -> Option<Support> {
    let (mut n, mut sx, mut sy, mut sxx, mut sxy, mut syy) = (0usize, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
    for (p, _) in mask.iter().enumerate().filter(|(_, v)| **v > threshold) {
        let (x, y) = (p % width, p / width);
        let (fx, fy) = (x as f64 + 0.5, y as f64 + 0.5);
        n += 1;
        sx += fx;
        sy += fy;
        sxx += fx * fx;
        sxy += fx * fy;
        syy += fy * fy;
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    }
    if n == 0 {
        return None;
    }
    let k = n as f64;
    let (mx, my) = (sx / k, sy / k);
    Some(Support {
        centroid: [mx, my],
        // Plus a pixel's own variance (1/12), so a single pixel is not a point.
        cov: [
            sxx / k - mx * mx + 1.0 / 12.0,
            sxy / k - mx * my,
            syy / k - my * my + 1.0 / 12.0,
        ],
        lo,
        hi,
    })
}

/// The number of 8-connected blobs above `threshold` with at least a fifth of the largest
/// one's pixels.
fn blobs(mask: &[f32], width: usize, threshold: f32) -> usize {
    let height = mask.len() / width.max(1);
    let mut label = vec![0u32; mask.len()];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..mask.len() {
        if mask[start] <= threshold || label[start] != 0 {
            continue;
        }
        sizes.push(0usize);
        let id = sizes.len() as u32;
        label[start] = id;
        stack.push(start);
        while let Some(p) = stack.pop() {
            sizes[id as usize - 1] += 1;
            let (x, y) = ((p % width) as isize, (p / width) as isize);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= width as isize || ny >= height as isize {
                        continue;
                    }
                    let q = ny as usize * width + nx as usize;
                    if mask[q] > threshold && label[q] == 0 {
                        label[q] = id;
                        stack.push(q);
                    }
                }
            }
        }
    }
    let largest = sizes.iter().copied().max().unwrap_or(0);
    sizes.iter().filter(|&&s| 5 * s >= largest).count()
}

#[cfg(test)]
mod tests;
