//! The trunk's pose from the torso's mask ([`TrunkModel`], [`ArmFitter::fit_trunk`]): the
//! stage before the arm's fit on a model whose torso turns, leans and bends.
//!
//! The arm hangs from the shoulder, and the trunk carries the shoulder: a lean of 0.3 rad
//! moves it 15 cm. Fitted with the trunk held upright, the arm's joints bend to make up for a
//! shoulder in the wrong place (with true masks on the generator's motion, the parts' error
//! on the whole body was 34 mm per episode, 17-49 mm over 10 episodes, where the arm on a
//! fixed torso has 8-10 mm). The arm's masks say little of where the shoulder is; the
//! torso's say it directly: the torso is large, rarely hidden whole, and its outline turns
//! and leans with the trunk. So the trunk's revolute joints (turn, lean, side bend) are
//! fitted first, to the torso's mask (and the depth image) without the arm's, and the arm is
//! then fitted on that trunk as on a fixed one.
//!
//! **The score** of trunk joints `t` is the torso's gain in its mask, as the arm parts' is:
//! `sum_px r (m_torso - m_background) / sum_px m_torso`, `r` the torso's render (the torso
//! link with everything rigidly attached to it, the head), 1 for a perfect fit; pixels of
//! something that may hide the torso (the robot, an arm part) count 0. With a depth image,
//! less a depth term: the torso rendered at `t` against the measured depth where both show
//! it, `trunk_depth_weight mean(min((dz / depth_sigma_m)^2, 9))` ([`ArmFitConfig`]'s; the
//! arm's parts' term has the same form, a quarter of the weight). The outline alone leaves
//! the turn and the side bend to a tenth of a radian either way on recorded people (a turn
//! and a side bend of opposite signs draw nearly one outline), which the shoulder and the
//! head carry 2 and 6 cm out; the depth image shows one shoulder nearer.
//!
//! **Where the person stands.** Recorded people walk: their pelvis travels up to the
//! model's slide limits (0.6 m) from where the cell puts them, and on the recorded test clips
//! of `experiments/configs/dataset-human.toml` the fit with the pelvis held found no pose in
//! 798 of the 826 frames whose pelvis was more than 0.4 m away. The trunk's prismatic joints
//! (`pelvis_x`, `pelvis_y`) are therefore fitted too. With a depth image they start where
//! the torso's pixels put them: the measured torso's points (each pixel back-projected at
//! its depth) against the rendered torso's, the difference along each slide's axis, twice
//! ([`TRUNK_CENTRE_PASSES`]) and only where it moves the pelvis [`TRUNK_CENTRE_MIN_M`] or
//! more (a smaller shift is as likely a turn or lean not yet fitted); the climb refines
//! them. Without depth they stay where the last frame left them: the outline tells a person
//! nearer the camera from one leaning toward it poorly.
//!
//! **The search.** A grid over [`TRUNK_GRID`] (the trunk's working range) at those slides,
//! the previous frame's trunk beside it (the track), then a compass climb over the trunk's
//! joints (the slides with a depth image only) from the best down to
//! [`TRUNK_MIN_STEP_RAD`] (the slides' steps [`TRUNK_SLIDE_M_PER_RAD`] times that). The
//! grid's outlines render in one batch and the best [`TRUNK_DEPTH_FINALISTS`] with their
//! depth, the track among them whatever its outline's rank; each climb step's candidates
//! with their depth. With a depth image the climb also starts from the track where it is
//! not the best finalist, and the better of the two climbs is the fit: a person who steps
//! 3 cm sideways moves the last frame's torso off its outline (its score fell from 0.93 to
//! 0.48 on such a frame), grid trunks turned and bent the other way outrank it, and a
//! compass climb that starts on the wrong side of the turn and side bend's shared valley
//! stays there (on a recorded clip the fit left a trunk it had followed by 0.3 to 1.0 rad in
//! a frame, and came back to it dozens of frames later).
//!
//! **The track alone.** With a depth image, a frame whose last frame had a trunk first
//! climbs from the track alone (the last frame's trunk, at the centred slides too) and keeps
//! what it finds when it scores at most [`TRUNK_TRACK_DROP`] below the last frame's fit; only
//! otherwise, after a frame whose arm found no pose, and at least once in
//! [`TRUNK_SEARCH_EVERY`] frames, does it run the whole search below. On recorded people the
//! whole search ends where the track's climb does in nearly every frame, and the grid, the
//! finalists' depth and a second climb are most of the stage's renders.
//!
//! **Beyond the grid** ([`ArmFitConfig::spine_start`]). Recorded people bend 0.9-1.3 rad to
//! reach down and lean back to the lean's limit, far outside the grid, and the climb from
//! its edge rarely gets there. With a depth image the principal axis of the torso's points
//! ([`measured_spine`]) is the spine: at each turn of the grid (and the last frame's) the
//! lean and side bend that lay the mesh's own axis ([`TrunkModel::spine_T`]) along it, the
//! slides centred for that trunk, join the candidates where they leave the grid's range. On
//! recorded people of a validation split with true masks, the frames whose trunk is more
//! than 20 degrees off fell from 329 to 223 of 2,919 (experiments/perception.md,
//! 2026-12-05).

use std::sync::Arc;

use workcell_render::{Camera, RenderMesh, Renderer};
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{JointKind, LinkId, RobotModel, Shape};

use super::fit::plane_points;
use super::*;
use crate::error::Result;
use crate::pose::POSE_MESH_SEGMENTS;

/// The trunk's working range the search's grid spans, per revolute trunk joint in the chain's
/// order (turn, lean, side bend), rad, and the grid's points in it: a person at a work-cell
/// turns and leans far less than a trunk can. The climb may leave the grid for the joint's
/// limits.
pub(super) const TRUNK_GRID: [([f64; 2], usize); 3] =
    [([-0.6, 0.6], 7), ([-0.2, 0.6], 5), ([-0.2, 0.2], 3)];

/// The climb's first step and the step it stops below, rad. With the torso's depth weighed
/// as it is ([`ArmFitConfig::trunk_depth_weight`]) the turn and the slides trade against
/// each other along a narrow valley: a climb that stopped at 0.01 rad left a test's trunk
/// 0.04 rad off and its forearm 3.5 cm (`the_trunks_stage_finds_where_the_person_stands`).
pub(super) const TRUNK_FIRST_STEP_RAD: f64 = 0.1;
pub(super) const TRUNK_MIN_STEP_RAD: f64 = 0.005;

/// Grid points whose outline scores best that the search then scores with the depth image
/// too (rendering a depth image per candidate costs more than the grid's outlines in one
/// batch).
pub(super) const TRUNK_DEPTH_FINALISTS: usize = 8;

/// The track alone is kept where its climb scores at most this much below the last frame's
/// fit; below, the frame runs the whole search (the grid, the spine's starts, both climbs).
/// On two tuning clips of recorded people (720 frames, the shipped network's masks), the
/// whole search ended where the track's climb did (within 0.01 rad) in 713 frames; of the
/// 675 frames this keeps the track in, it would have moved the trunk 0.05 rad or more in one.
pub(super) const TRUNK_TRACK_DROP: f64 = 0.05;

/// The first step of the track's climb, rad: a trunk moves a few hundredths of a radian
/// between frames at 30 Hz, and each halving from [`TRUNK_FIRST_STEP_RAD`] costs a round of
/// renders. On the tuning clips 1-12 (closed loop) 0.025 against 0.1 ran 5 % faster with the
/// fit's error -0.5 mm (-1.2 to +0.0) per episode.
pub(super) const TRUNK_TRACK_FIRST_STEP_RAD: f64 = 0.025;

/// The whole search runs at least once in this many frames (a second at 30 Hz), whatever the
/// track scores: a way out of a valley the track's climb cannot leave. A frame whose arm
/// finds no pose sends the next one to the whole search too ([`ArmFitter::fit`]): a trunk
/// that scores as well as the last frame's can still be the wrong one (on one held-out
/// sequence the track kept such a trunk and the arm had no pose in any of its 29 frames,
/// where the search found it from the third).
pub(super) const TRUNK_SEARCH_EVERY: usize = 30;

/// Torso mask pixels below which the trunk is not fitted (it keeps its last pose).
pub(super) const TRUNK_MIN_PIXELS: f64 = 64.0;

/// The climb's step on a slide (m) per radian of its step on a revolute joint: 5 cm first,
/// 2.5 mm last.
pub(super) const TRUNK_SLIDE_M_PER_RAD: f64 = 0.5;

/// Passes of centring the slides on the torso's measured points before the grid: the
/// first from wherever the last frame left the pelvis, the second with the rendered torso
/// where the first put it.
pub(super) const TRUNK_CENTRE_PASSES: usize = 2;

/// The least shift the centring applies, m: below it the torso's points moved as much with
/// a turn or lean of a tenth of a radian, which the grid and the climb fit.
pub(super) const TRUNK_CENTRE_MIN_M: f64 = 0.1;

/// Sides of the cylinders (the chest, the neck) in the stage's mesh: the arm's hexagons
/// ([`POSE_MESH_SEGMENTS`]), inscribed as the renderer draws them. Widened so that their
/// outline is on average as wide as a round cylinder's (4.5 %), they brought the upper arm
/// nearer on the generator's motion but cost it 5 % of the task time (docs/perception.md,
/// "The torso's round shapes").
pub(super) const TRUNK_MESH_SEGMENTS: usize = POSE_MESH_SEGMENTS;

/// The stage's spheres (the hips, the shoulders, the head) as geodesic spheres subdivided
/// once (80 triangles), sized to the sphere's surface
/// ([`RenderMesh::from_geometry_geodesic`]): their outline covers the sphere's disc within
/// 1 % from any view, where a hexagonal UV sphere's leaves 6 to 19 % of it and the
/// renderer's own 16 sides (512 triangles) 1 to 3 %. Inscribed hexagons put the head 15 mm
/// off at the median fit, and the track leaned and turned the trunk to make up for them;
/// the stage on 16 sides fitted them as near but the closed loop ran a third slower
/// (docs/perception.md, "The torso's round shapes"; `the_trunks_stage_fits_a_body_drawn_round`).
pub(super) const TRUNK_SPHERE_SUBDIVISIONS: Option<u32> = Some(1);

/// The trunk as its stage fits it: the joints that carry the torso and the torso's mesh.
#[derive(Debug, Clone)]
pub struct TrunkModel {
    /// The trunk's revolute joints, by index in the model's joint order, root first.
    pub(super) joints: Vec<usize>,
    /// The trunk's prismatic joints (where the person stands), by index in the model's
    /// joint order, root first.
    pub(super) slides: Vec<usize>,
    /// Every fitted trunk joint: [`Self::joints`] then [`Self::slides`]; the order of the
    /// values the stage searches.
    pub(super) all: Vec<usize>,
    /// Their ranges, rad or m (clamped to +-pi), in [`Self::all`]'s order.
    pub(super) limits: Vec<[f64; 2]>,
    /// Upright where the cell puts the person: each joint's 0 within its limits, where a
    /// new track starts ([`Self::all`]'s order).
    pub(super) upright: Vec<f64>,
    /// The search's grid over [`TRUNK_GRID`], within the limits (revolute joints only).
    pub(super) grid: Vec<Vec<f64>>,
    pub(super) torso: LinkId,
    /// The mean of the torso mesh's vertices in the torso's frame: where the slides' centring
    /// puts the torso when its render shows too little of it.
    pub(super) centre_T: Vector,
    /// The principal axis of the torso mesh's vertices (the head's with them) in the
    /// torso's frame, towards `centre_T`: the spine the depth image's torso points show.
    pub(super) spine_T: Vector,
    /// The torso link's visuals and those of the links fixed to it, in the torso's frame
    /// (their outer surface).
    pub(super) mesh: Arc<RenderMesh>,
}

impl TrunkModel {
    /// How far the trunk of configuration `q` is from that of `truth` (both the model's
    /// whole configuration): the largest difference over the revolute trunk joints, rad,
    /// and how far the slides put the pelvis, m (0 without slides). `None` where either
    /// has the wrong length.
    #[must_use]
    pub fn error(&self, q: &[f64], truth: &[f64]) -> Option<[f64; 2]> {
        let n = self.all.iter().max().map_or(0, |m| m + 1);
        if q.len() < n || truth.len() != q.len() {
            return None;
        }
        let angle = self
            .joints
            .iter()
            .map(|&i| (q[i] - truth[i]).abs())
            .fold(0.0, f64::max);
        let slide = self
            .slides
            .iter()
            .map(|&i| (q[i] - truth[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        Some([angle, slide])
    }

    /// The trunk of `human`: `None` when no revolute joint moves its torso (the arm on a
    /// fixed torso, `human_arm`) or the torso shows nothing.
    ///
    /// # Errors
    /// A forward kinematics failure at the held configuration `held`.
    pub(super) fn of(
        human: &RobotModel,
        held: &[f64],
        limits: &[[f64; 2]],
    ) -> Result<Option<Self>> {
        let Some(torso) = human.link_id(HumanPart::Torso.link_name()) else {
            return Ok(None);
        };
        let actuated = human.actuated_joints();
        let chain: Vec<usize> = human.joints_above(torso).collect();
        let in_chain = |prismatic: bool| -> Vec<usize> {
            (0..actuated.len())
                .filter(|&i| {
                    chain.contains(&actuated[i])
                        && matches!(human.joints()[actuated[i]].kind, JointKind::Prismatic)
                            == prismatic
                })
                .collect()
        };
        let joints = in_chain(false);
        if joints.is_empty() {
            return Ok(None);
        }
        let slides = in_chain(true);
        let all: Vec<usize> = joints.iter().chain(&slides).copied().collect();
        let mesh = Self::torso_mesh(
            human,
            torso,
            held,
            TRUNK_MESH_SEGMENTS,
            TRUNK_SPHERE_SUBDIVISIONS,
        )?;
        if mesh.is_empty() {
            return Ok(None);
        }
        let limits: Vec<[f64; 2]> = all.iter().map(|&i| limits[i]).collect();
        let upright = limits
            .iter()
            .map(|[lo, hi]| 0.0_f64.clamp(*lo, *hi))
            .collect();
        let n = mesh.positions.len().max(1) as f64;
        let centre_T = mesh.positions.iter().fold(Vector::ZERO, |c, p| {
            c + Vector::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])) / n
        });
        let vertices = mesh
            .positions
            .iter()
            .map(|p| Vector::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])));
        let spine_T = mean_and_covariance(vertices)
            .and_then(|(_, covariance)| principal_axis(covariance))
            .map_or(Vector::Z, |(axis, _)| {
                if axis.dot(centre_T) < 0.0 {
                    -axis
                } else {
                    axis
                }
            });
        let axes: Vec<Vec<f64>> = limits[..joints.len()]
            .iter()
            .enumerate()
            .map(|(j, [lo, hi])| {
                let ([a, b], n) = TRUNK_GRID.get(j).copied().unwrap_or(([0.0, 0.0], 1));
                (0..n)
                    .map(|k| {
                        let x = if n > 1 {
                            a + (b - a) * k as f64 / (n - 1) as f64
                        } else {
                            0.5 * (a + b)
                        };
                        x.clamp(*lo, *hi)
                    })
                    .collect()
            })
            .collect();
        Ok(Some(Self {
            joints,
            slides,
            all,
            limits,
            upright,
            grid: grid_product(&axes),
            torso,
            centre_T,
            spine_T,
            mesh: Arc::new(mesh),
        }))
    }

    /// The torso and every link fixed to it (the head, through the neck) in the torso's
    /// frame at the configuration `held`, as one mesh of their outer surface
    /// (`RenderMesh::outer_union`: the same silhouettes, and the depth term sees no face
    /// that lies inside another piece): round shapes with `segments` sides, inscribed as
    /// the renderer draws them where `sphere_subdivisions` is `None`, else as
    /// [`RenderMesh::from_geometry_geodesic`] draws them (spheres geodesic, subdivided so many
    /// times).
    ///
    /// # Errors
    /// A forward kinematics failure.
    pub(super) fn torso_mesh(
        human: &RobotModel,
        torso: LinkId,
        held: &[f64],
        segments: usize,
        sphere_subdivisions: Option<u32>,
    ) -> Result<RenderMesh> {
        let k = human.fk(Pose::IDENTITY, held)?;
        let X_TW = k.link_pose(torso).inverse();
        let mut rigid = vec![torso];
        let mut grew = true;
        while grew {
            grew = false;
            for joint in human.joints() {
                if matches!(joint.kind, JointKind::Fixed)
                    && rigid.contains(&joint.parent)
                    && !rigid.contains(&joint.child)
                {
                    rigid.push(joint.child);
                    grew = true;
                }
            }
        }
        let mut pieces = Vec::new();
        for &l in &rigid {
            let X_TL = X_TW * *k.link_pose(l);
            for g in &human.links()[l].visuals {
                let piece = match sphere_subdivisions {
                    Some(n) => RenderMesh::from_geometry_geodesic(g, [0.5, 0.5, 0.5], segments, n),
                    None => RenderMesh::from_geometry_with(g, [0.5, 0.5, 0.5], segments),
                };
                let mut placed = RenderMesh::default();
                placed.append(&piece, &X_TL);
                pieces.push((placed, !matches!(g.shape, Shape::Mesh { .. })));
            }
        }
        Ok(RenderMesh::outer_union(&pieces))
    }

    /// The trunk's revolute joints fitted (turn, lean, side bend), by index in the model's
    /// joint order.
    #[must_use]
    pub fn joints(&self) -> &[usize] {
        &self.joints
    }

    /// The trunk's prismatic joints fitted (where the person stands), by index in the
    /// model's joint order.
    #[must_use]
    pub fn slides(&self) -> &[usize] {
        &self.slides
    }
}

/// One frame's torso as the trunk's stage scores it.
struct TorsoTarget<'a> {
    /// `m_torso - m_background` per pixel, in [`TORSO_FIXED_SCALE`]'s fixed point.
    s: Vec<i32>,
    /// The torso mask's pixels.
    mass: f64,
    /// How many of the masks' pixels one of these covers (the trunk's stage may run on
    /// coarser planes, [`ArmFitConfig::trunk_downsample`]).
    px_area: f64,
    torso: &'a [f32],
    background: &'a [f32],
    depth: Option<&'a [f32]>,
    /// The pixels the depth term reads, in order: the torso mask's (above a half) where the
    /// depth image has a depth.
    depth_pixels: Vec<usize>,
    /// The torso alone, posed per candidate for its depth render.
    scene: workcell_render::Scene,
}

impl<R: Renderer> ArmFitter<R> {
    /// Fits the trunk's joints to the torso's mask in `masks` (seen by `camera`) and holds
    /// them there for the arm's fit. Returns the torso's gain at the fit, or `None` where
    /// the model's torso does not move or its mask is too small to fit (the trunk then
    /// stays where the last frame put it).
    ///
    /// # Errors
    /// A renderer failure.
    pub fn fit_trunk(&mut self, camera: &Camera, masks: &ArmMasks) -> Result<Option<f64>> {
        let k = self.config.trunk_downsample.max(1) as usize;
        if k > 1
            && camera.width as usize == masks.width
            && camera.height as usize == masks.height
            && let Some(coarse) = masks.trunk_planes_downsampled(k)
        {
            let camera = camera.resized(coarse.width as u32, coarse.height as u32)?;
            return self.fit_trunk_at(&camera, &coarse, (k * k) as f64);
        }
        self.fit_trunk_at(camera, masks, 1.0)
    }

    /// [`Self::fit_trunk`] on `masks` whose pixels each cover `px_area` of the masks'
    /// pixels the thresholds are counted in ([`TRUNK_MIN_PIXELS`], [`SPINE_MIN_PIXELS`]).
    fn fit_trunk_at(
        &mut self,
        camera: &Camera,
        masks: &ArmMasks,
        px_area: f64,
    ) -> Result<Option<f64>> {
        let Some(trunk) = self.arm.trunk.clone() else {
            return Ok(None);
        };
        let (w, h) = (camera.width as usize, camera.height as usize);
        if masks.torso.len() != w * h {
            return Ok(None);
        }
        let mass: f64 = masks.torso.iter().map(|&v| f64::from(v)).sum();
        if mass * px_area < TRUNK_MIN_PIXELS {
            return Ok(None);
        }
        let mut target = TorsoTarget {
            px_area,
            s: masks
                .torso
                .iter()
                .zip(&masks.background)
                .map(|(&t, &b)| torso_fixed(t, b))
                .collect(),
            mass,
            torso: &masks.torso,
            background: &masks.background,
            depth: masks.depth_m.as_deref().filter(|d| d.len() == w * h),
            depth_pixels: masks
                .depth_m
                .as_deref()
                .filter(|d| d.len() == w * h)
                .map(|depth| {
                    (depth.iter().zip(&masks.torso).enumerate())
                        .filter(|(_, (z, t))| **t > 0.5 && z.is_finite() && **z > 0.0)
                        .map(|(p, _)| p)
                        .collect()
                })
                .unwrap_or_default(),
            scene: workcell_render::Scene {
                objects: vec![workcell_render::SceneObject {
                    name: "torso".into(),
                    class: workcell_render::Class::Torso,
                    mesh: trunk.mesh.clone(),
                    texture: 0.0,
                    X_WO: Pose::IDENTITY,
                }],
                ..Default::default()
            },
        };
        let with_depth = target.depth.is_some();
        let n_rev = trunk.joints.len();
        let previous: Vec<f64> = trunk.all.iter().map(|&i| self.arm.held[i]).collect();
        // Where the person stands, from the torso's points.
        let mut slides = previous[n_rev..].to_vec();
        if with_depth && !slides.is_empty() {
            for _ in 0..TRUNK_CENTRE_PASSES {
                let at: Vec<f64> = previous[..n_rev].iter().chain(&slides).copied().collect();
                match self.centred_slides(&trunk, camera, &mut target, &at)? {
                    // A small shift is as likely the turn and lean the trunk has not been
                    // fitted to yet: the climb takes it.
                    Some(s)
                        if s.iter()
                            .zip(&slides)
                            .map(|(a, b)| (a - b).powi(2))
                            .sum::<f64>()
                            .sqrt()
                            > TRUNK_CENTRE_MIN_M =>
                    {
                        slides = s;
                    }
                    _ => break,
                }
            }
        }
        // The track alone where the last frame's trunk was found: the climb from it (at the
        // centred slides too), kept if it scores nearly as well as the last frame's fit.
        if with_depth
            && let Some(last) = self.trunk_last
            && self.trunk_tracked_frames < TRUNK_SEARCH_EVERY
        {
            let mut starts = vec![previous.clone()];
            if slides != previous[n_rev..] {
                starts.push(previous[..n_rev].iter().chain(&slides).copied().collect());
            }
            let scores = self.trunk_scores(&trunk, camera, &mut target, true, &starts)?;
            let k = (0..scores.len())
                .max_by(|a, b| scores[*a].total_cmp(&scores[*b]))
                .unwrap_or(0);
            let (best, here) = self.trunk_climb(
                &trunk,
                camera,
                &mut target,
                true,
                &starts[k],
                scores[k],
                TRUNK_TRACK_FIRST_STEP_RAD,
            )?;
            if here >= last - TRUNK_TRACK_DROP {
                self.arm.hold_trunk(&trunk, &best)?;
                self.trunk_last = Some(here);
                self.trunk_tracked_frames += 1;
                return Ok(Some(here));
            }
        }
        let mut candidates: Vec<Vec<f64>> = trunk
            .grid
            .iter()
            .map(|g| g.iter().chain(&slides).copied().collect())
            .collect();
        // The track: the last frame's trunk, and where the centring moved the slides, its
        // joints at the centred slides.
        let mut track = Vec::with_capacity(2);
        if slides != previous[n_rev..] {
            track.push(candidates.len());
            candidates.push(previous[..n_rev].iter().chain(&slides).copied().collect());
        }
        // Leans and side bends beyond the grid: the trunk that lays the torso's spine along
        // the principal axis of its depth points, at each turn of the grid and the last
        // frame's, the slides centred for that trunk (a lean moves the torso's points as
        // a step would). Only where that trunk leaves the grid's range: within it, the grid
        // and the climb find the trunk as well or better (on the stage's tests a spine
        // start that won there put the shoulder 1.1-1.7 cm off, where the grid's put it
        // within 1 cm).
        if let Some(depth) = target.depth
            && n_rev > 1
            && self.config.spine_start
        {
            let hidden_below_m = (self.arm.nearest_depth_m(&camera.X_WC) - HIDDEN_MARGIN_M) as f32;
            if let Some(spine_W) = measured_spine(camera, masks, depth, hidden_below_m, px_area) {
                let mut turns: Vec<f64> = trunk.grid.iter().map(|g| g[0]).collect();
                turns.push(previous[0]);
                turns.sort_by(f64::total_cmp);
                turns.dedup();
                for turn in turns {
                    let mut v = self.spine_along(&trunk, spine_W, turn)?;
                    let beyond = v.iter().zip(TRUNK_GRID).skip(1).any(|(x, ([a, b], _))| {
                        *x < a - TRUNK_FIRST_STEP_RAD || *x > b + TRUNK_FIRST_STEP_RAD
                    });
                    if !beyond {
                        continue;
                    }
                    v.extend_from_slice(&previous[n_rev..]);
                    if let Some(s) = self.centred_slides(&trunk, camera, &mut target, &v)? {
                        v.truncate(n_rev);
                        v.extend(s);
                    }
                    candidates.push(v);
                }
            }
        }
        track.push(candidates.len());
        candidates.push(previous);
        // The grid by outline alone; the best few outlines with their depth.
        let outline = self.trunk_scores(&trunk, camera, &mut target, false, &candidates)?;
        let mut order: Vec<usize> = (0..candidates.len()).collect();
        order.sort_by(|&a, &b| outline[b].total_cmp(&outline[a]));
        let mut finalists: Vec<Vec<f64>> = order
            .iter()
            .take(if with_depth { TRUNK_DEPTH_FINALISTS } else { 1 })
            .map(|&i| candidates[i].clone())
            .collect();
        // The track is a finalist whatever its outline's rank (with a depth image, which
        // tells the trunks apart). A person who steps a few centimetres moves the last
        // frame's torso off its outline and its depth, and the outlines of trunks turned
        // and bent the other way can rank above it; without it, the fit jumped 0.3-1.0 rad
        // away from a trunk it had followed (experiments/perception.md, 2026-12-06).
        let mut track_finalists = Vec::with_capacity(track.len());
        if with_depth {
            for &i in &track {
                let k = match finalists.iter().position(|f| *f == candidates[i]) {
                    Some(k) => k,
                    None => {
                        finalists.push(candidates[i].clone());
                        finalists.len() - 1
                    }
                };
                track_finalists.push(k);
            }
        }
        // Without depth the one finalist's score is its outline's, already measured.
        let scores = if with_depth {
            self.trunk_scores(&trunk, camera, &mut target, true, &finalists)?
        } else {
            vec![outline[order[0]]]
        };
        let by_score = |a: &usize, b: &usize| scores[*a].total_cmp(&scores[*b]);
        let first = (0..scores.len()).max_by(by_score).unwrap_or(0);
        let (mut best, mut here) = self.trunk_climb(
            &trunk,
            camera,
            &mut target,
            with_depth,
            &finalists[first],
            scores[first],
            TRUNK_FIRST_STEP_RAD,
        )?;
        // The climb from the track too, where it is not the best finalist: a compass climb
        // from a start on the wrong side of the turn and side bend's shared valley stays
        // there.
        if let Some(k) = track_finalists.iter().copied().max_by(by_score)
            && k != first
        {
            let (b, h) = self.trunk_climb(
                &trunk,
                camera,
                &mut target,
                with_depth,
                &finalists[k],
                scores[k],
                TRUNK_FIRST_STEP_RAD,
            )?;
            if h > here {
                (best, here) = (b, h);
            }
        }
        self.arm.hold_trunk(&trunk, &best)?;
        self.trunk_last = Some(here);
        self.trunk_tracked_frames = 0;
        Ok(Some(here))
    }

    /// The compass climb over the trunk's joints from `start` (scoring `here`), each joint
    /// a step either way, from `first_step` (rad) halved down to
    /// [`TRUNK_MIN_STEP_RAD`]: the trunk it ends at and its score.
    ///
    /// # Errors
    /// A renderer failure.
    #[allow(clippy::too_many_arguments)]
    fn trunk_climb(
        &mut self,
        trunk: &TrunkModel,
        camera: &Camera,
        target: &mut TorsoTarget<'_>,
        with_depth: bool,
        start: &[f64],
        mut here: f64,
        first_step: f64,
    ) -> Result<(Vec<f64>, f64)> {
        let mut best = start.to_vec();
        let n_rev = trunk.joints.len();
        let mut step = first_step;
        while step >= TRUNK_MIN_STEP_RAD {
            let mut around = Vec::with_capacity(2 * best.len());
            // The slides with a depth image only: the outline alone tells a person nearer
            // from one leaning toward the camera poorly (on the outline test's frame the
            // slides drifted and the forearm went from 2.2 to 3.4 cm).
            let climbed = if with_depth { best.len() } else { n_rev };
            for j in 0..climbed {
                let dj = if j < n_rev {
                    step
                } else {
                    step * TRUNK_SLIDE_M_PER_RAD
                };
                for sign in [1.0, -1.0] {
                    let mut v = best.clone();
                    let [lo, hi] = trunk.limits[j];
                    v[j] = (v[j] + sign * dj).clamp(lo, hi);
                    if v[j] != best[j] {
                        around.push(v);
                    }
                }
            }
            if around.is_empty() {
                break;
            }
            let scores = self.trunk_scores(trunk, camera, target, true, &around)?;
            match scores.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) {
                Some((i, g)) if *g > here + 1e-9 => {
                    best.clone_from(&around[i]);
                    here = *g;
                }
                _ => step *= 0.5,
            }
        }
        Ok((best, here))
    }

    /// The trunk's revolute joints (its first at `turn`, the others from upright by damped
    /// Gauss-Newton, within their limits) that lay the torso's spine
    /// ([`TrunkModel::spine_T`]) along `spine_W` (world; either sign: the one nearer the
    /// upright spine's), as nearly as they can.
    ///
    /// # Errors
    /// A forward kinematics failure.
    pub(super) fn spine_along(
        &self,
        trunk: &TrunkModel,
        spine_W: Vector,
        turn: f64,
    ) -> Result<Vec<f64>> {
        const ITERATIONS: usize = 12;
        const STEP_RAD: f64 = 1e-4;
        let n_rev = trunk.joints.len();
        let mut q = self.arm.held.clone();
        let mut x: Vec<f64> = trunk.upright[..n_rev].to_vec();
        x[0] = turn.clamp(trunk.limits[0][0], trunk.limits[0][1]);
        let mut spine = |x: &[f64]| -> Result<Vector> {
            for (&i, v) in trunk.joints.iter().zip(x) {
                q[i] = *v;
            }
            let k = self.arm.human.fk(self.arm.X_WH, &q)?;
            Ok(k.link_pose(trunk.torso).rotation * trunk.spine_T)
        };
        let goal = if spine(&x)?.dot(spine_W) < 0.0 {
            -spine_W
        } else {
            spine_W
        };
        let mut residual = |x: &[f64]| -> Result<[f64; 3]> {
            let d = spine(x)? - goal;
            Ok([d.x, d.y, d.z])
        };
        let mut r = residual(&x)?;
        let mut cost: f64 = r.iter().map(|v| v * v).sum();
        for _ in 0..ITERATIONS {
            // The joints after the turn.
            let Some(dx) = gauss_newton_step(&mut residual, &x, &r, 1..n_rev, STEP_RAD, 1e-3)?
            else {
                break;
            };
            let mut next = x.clone();
            for (j, d) in dx.iter().enumerate() {
                let [lo, hi] = trunk.limits[j + 1];
                next[j + 1] = (next[j + 1] + d.clamp(-0.5, 0.5)).clamp(lo, hi);
            }
            let r_next = residual(&next)?;
            let cost_next: f64 = r_next.iter().map(|v| v * v).sum();
            if cost_next >= cost - 1e-12 {
                break;
            }
            (x, r, cost) = (next, r_next, cost_next);
        }
        Ok(x)
    }

    /// The slides (where the person stands) that put the torso's points where the depth
    /// image shows them, from the trunk at `at` ([`TrunkModel::all`]'s order): the mean of
    /// the measured torso's pixels back-projected at their depth, against the same mean of
    /// the torso rendered at `at` (its pixels that nothing else in the masks covers; the mesh's
    /// centre where it shows fewer than [`TRUNK_MIN_PIXELS`]), the difference along each
    /// slide's axis. `None` where the depth image shows too little of the torso.
    ///
    /// # Errors
    /// A renderer or forward kinematics failure.
    fn centred_slides(
        &mut self,
        trunk: &TrunkModel,
        camera: &Camera,
        target: &mut TorsoTarget<'_>,
        at: &[f64],
    ) -> Result<Option<Vec<f64>>> {
        let Some(depth) = target.depth else {
            return Ok(None);
        };
        let w = camera.width as usize;
        let point = |p: usize, z: f32| {
            camera.point_at((p % w) as f64 + 0.5, (p / w) as f64 + 0.5, f64::from(z))
        };
        let mean = |points: &mut dyn Iterator<Item = Vector>| {
            let (sum, n) = points.fold((Vector::ZERO, 0usize), |(s, n), p| (s + p, n + 1));
            (n as f64 * target.px_area >= TRUNK_MIN_PIXELS).then(|| sum / n as f64)
        };
        let measured = mean(
            &mut depth
                .iter()
                .zip(target.torso)
                .enumerate()
                .filter(|(_, (z, t))| **t > 0.5 && z.is_finite() && **z > 0.0)
                .map(|(p, (z, _))| point(p, *z)),
        );
        let Some(measured_C) = measured else {
            return Ok(None);
        };
        let mut q = self.arm.held.clone();
        for (&i, v) in trunk.all.iter().zip(at) {
            q[i] = *v;
        }
        let k = self.arm.human.fk(self.arm.X_WH, &q)?;
        let X_WT = *k.link_pose(trunk.torso);
        target.scene.objects[0].X_WO = X_WT;
        self.renderer
            .render_depth(&target.scene, camera, &mut self.trunk_depth)?;
        self.renders += 1;
        let rendered = mean(
            &mut self
                .trunk_depth
                .iter()
                .enumerate()
                .filter(|(p, z)| {
                    **z > 0.0 && (target.torso[*p] > 0.5 || target.background[*p] > 0.5)
                })
                .map(|(p, z)| point(p, *z)),
        );
        let X_CW = camera.X_WC.inverse();
        let rendered_C =
            rendered.unwrap_or_else(|| X_CW.transform_point(X_WT.transform_point(trunk.centre_T)));
        let shift_W = camera.X_WC.rotation * (measured_C - rendered_C);
        let n_rev = trunk.joints.len();
        let mut slides = at[n_rev..].to_vec();
        for (j, &i) in trunk.slides.iter().enumerate() {
            let joint = &self.arm.human.joints()[self.arm.human.actuated_joints()[i]];
            let axis_W = k.link_pose(joint.parent).rotation * (joint.X_PJ.rotation * joint.axis);
            let [lo, hi] = trunk.limits[n_rev + j];
            slides[j] = (slides[j] + shift_W.dot(axis_W)).clamp(lo, hi);
        }
        Ok(Some(slides))
    }

    /// The torso's score at each of `candidates` (trunk joint values): its gain, less the
    /// depth term where `with_depth` and the target has a depth image. With the depth term
    /// each candidate is drawn once, as a depth image, whose covered pixels are its mask
    /// (the same triangles and rule as [`Renderer::render_masks`]); without it, as masks.
    fn trunk_scores(
        &mut self,
        trunk: &TrunkModel,
        camera: &Camera,
        target: &mut TorsoTarget<'_>,
        with_depth: bool,
        candidates: &[Vec<f64>],
    ) -> Result<Vec<f64>> {
        let X_CW = camera.X_WC.inverse();
        let mut q = self.arm.held.clone();
        self.poses.clear();
        for c in candidates {
            for (&i, v) in trunk.all.iter().zip(c) {
                q[i] = *v;
            }
            let k = self.arm.human.fk(self.arm.X_WH, &q)?;
            self.poses.push(X_CW * *k.link_pose(trunk.torso));
        }
        let poses = std::mem::take(&mut self.poses);
        let mass = target.mass;
        let gain = move |sum: i64| sum as f64 / f64::from(TORSO_FIXED_SCALE) / mass;
        let mut scores = Vec::with_capacity(candidates.len());
        if with_depth && target.depth.is_some() {
            for X_CT in &poses {
                self.render_trunk_depth(camera, target, X_CT)?;
                let sum = covered_sum(&self.trunk_depth, &target.s, |z| z > 0.0);
                scores.push(gain(sum) - self.trunk_depth_cost(target));
            }
        } else {
            let rendered = self
                .renderer
                .render_masks(&trunk.mesh, camera, &poses, &mut self.batch);
            rendered?;
            self.renders += candidates.len();
            for k in 0..candidates.len() {
                scores.push(gain(covered_sum(self.batch.mask(k), &target.s, |m| m > 0)));
            }
        }
        self.poses = poses;
        Ok(scores)
    }

    /// The torso alone at `X_CT` (camera frame) drawn as a depth image into `trunk_depth`.
    ///
    /// # Errors
    /// A renderer failure.
    fn render_trunk_depth(
        &mut self,
        camera: &Camera,
        target: &mut TorsoTarget<'_>,
        X_CT: &Pose,
    ) -> Result<()> {
        target.scene.objects[0].X_WO = camera.X_WC * *X_CT;
        self.renderer
            .render_depth(&target.scene, camera, &mut self.trunk_depth)?;
        self.renders += 1;
        Ok(())
    }

    /// The depth term of the trunk's score, of the torso as `trunk_depth` holds it
    /// ([`Self::render_trunk_depth`]) against the depth image where both show the torso:
    /// `min((dz / sigma)^2, 9)`, the mean over those pixels, times
    /// [`ArmFitConfig::trunk_depth_weight`] (the arm's parts' depth term's form). The
    /// silhouette alone leaves the trunk's turn and side bend to a tenth of a radian either
    /// way, which the shoulder and the head carry 2 and 6 cm; the depth image shows one
    /// shoulder nearer.
    fn trunk_depth_cost(&self, target: &TorsoTarget<'_>) -> f64 {
        let Some(depth) = target.depth else {
            return 0.0;
        };
        let sigma = self.config.depth_sigma_m.max(1e-4);
        let (mut sum, mut n) = (0.0, 0usize);
        for &p in &target.depth_pixels {
            let (rendered, measured) = (self.trunk_depth[p], depth[p]);
            if rendered > 0.0 {
                sum += (f64::from(measured - rendered) / sigma).powi(2).min(9.0);
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            self.config.trunk_depth_weight * sum / n as f64
        }
    }
}

/// The fixed-point scale of [`TorsoTarget::s`]: `m_torso - m_background` in [-1, 1] times
/// 2^24, within an `i32` and as fine as an `f32` probability near 1. Integer sums do not
/// depend on their order, so the covered pixels' sum vectorizes and any order gives the
/// same score to the bit.
pub(super) const TORSO_FIXED_SCALE: f32 = 16_777_216.0;

/// `m_torso - m_background` of one pixel in [`TORSO_FIXED_SCALE`]'s fixed point.
pub(super) fn torso_fixed(torso: f32, background: f32) -> i32 {
    // The trunk's stage runs before the arm's fit refuses masks that are not probabilities:
    // the clamp keeps any value within the scale, and a NaN becomes 0.
    ((torso - background).clamp(-1.0, 1.0) * TORSO_FIXED_SCALE).round() as i32
}

/// The sum of `values` over the pixels that `covered` marks in `cover` (both row-major).
pub(super) fn covered_sum<T: Copy>(
    cover: &[T],
    values: &[i32],
    covered: impl Fn(T) -> bool,
) -> i64 {
    cover
        .iter()
        .zip(values)
        .map(|(&c, &v)| if covered(c) { i64::from(v) } else { 0 })
        .sum()
}

/// Torso mask pixels with depth below which [`measured_spine`] gives no axis.
pub(super) const SPINE_MIN_PIXELS: usize = 64;

/// The torso's spine where the depth image shows it (world, unit, its sign open): the
/// principal axis of the points the torso's mask (the head's with it) shows at a depth of at
/// least `hidden_below_m`, where it is at least [`SPINE_ELONGATION`] times as long (in
/// variance) as across. `None` with fewer than [`SPINE_MIN_PIXELS`] such points, each
/// counted as `px_area` pixels.
pub(super) fn measured_spine(
    camera: &Camera,
    masks: &ArmMasks,
    depth: &[f32],
    hidden_below_m: f32,
    px_area: f64,
) -> Option<Vector> {
    let points = plane_points(camera, masks.width, &masks.torso, depth, hidden_below_m);
    if (points.len() as f64 * px_area) < SPINE_MIN_PIXELS as f64 {
        return None;
    }
    let (_, covariance) = mean_and_covariance(points.iter().copied())?;
    let (axis, elongation) = principal_axis(covariance)?;
    (elongation >= SPINE_ELONGATION).then_some(axis)
}

/// How many times the torso points' variance along their principal axis must exceed the
/// next axis's for [`measured_spine`] to read a spine from them.
pub(super) const SPINE_ELONGATION: f64 = 2.0;
