//! The search: gradient ascent with a numerical Jacobian, the global search over axis
//! directions, and the uncertainty of the result (see the module docs of [`crate::pose`]).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_render::{Camera, MaskBatch, Renderer};
use workcell_robots::math::{Pose, Rotation, Vector};

use super::image::{LEVELS, SUPERSAMPLE, Support, blobs, crop_camera, dilate, f_m, support};
use super::{Anchor, NoPose, PoseConfig, PoseEstimate, PoseOutcome, RigidModel};
use crate::error::{PerceptionError, Result};

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
        if !(t > workcell_render::NEAR_M && (t * r - w).length() > 1e-6) {
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
    pub(super) fn gain_at(&mut self, camera: &Camera, mask: &[f32], X_CO: &Pose) -> Result<f64> {
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
        let roi = crop_camera(camera, x0, y0, rw, rh);
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
        let ray = cam.point_at(u, v, 1.0);
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
