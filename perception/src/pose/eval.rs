//! Pose evaluation on a dataset split, in the layout of the paper's Table 2.
//!
//! Every sequence is tracked from its first frame: the estimator searches globally on frame 0
//! and whenever the track is lost, and climbs from the previous pose otherwise. Frame 0 is
//! left out of the statistics (as in the segmentation evaluation: ProcNet has not yet seen
//! any motion), and so are frames whose forearm is out of view.
//!
//! Errors are taken at the forearm's centre, after choosing of the estimate and its
//! end-for-end twin ([`RigidModel::twin`]) the one nearer the truth in rotation: the mask
//! cannot tell them apart. Yaw, pitch and roll are the URDF angles of the forearm link frame
//! in the camera frame (as the dataset's labels give them); besides them, the error of the
//! forearm's axis direction and its *spin* (rotation about its own axis, which two thin bones
//! barely show) are reported on their own.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Instant;

use workcell_robots::math::{Pose, Vector, pose_to_xyz_rpy};
use workcell_sim::dataset::{Dataset, Sequence, Split};
use workcell_sim::render::{Camera, CellScene, Class, CpuRenderer, RenderMesh};
use workcell_sim::{CellModel, Scenario};

use super::{Anchor, NoPose, PoseConfig, PoseEstimator, RigidModel};
use crate::error::{PerceptionError, Result};
use crate::infer::ProcNet;

/// Where the forearm masks come from.
pub trait MaskSource {
    /// The name in tables ("ground truth", "ProcNet").
    fn name(&self) -> String;
    /// A new sequence starts (a stateful network forgets the last one).
    fn start(&mut self);
    /// The forearm mask of frame `t`, `[height, width]` of the sequence, values in [0, 1].
    ///
    /// # Errors
    /// The network's failure.
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>>;
}

/// The dataset's forearm class without the artificial occluder: what ProcNet is trained to
/// output. Isolates the pose estimator's own error.
#[derive(Debug, Clone, Copy, Default)]
pub struct GroundTruthMasks;

impl MaskSource for GroundTruthMasks {
    fn name(&self) -> String {
        "ground truth".into()
    }
    fn start(&mut self) {}
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>> {
        Ok(forearm_of(sequence.class_frame(t)))
    }
}

/// The forearm pixels seen through the occluder as well: a perfect segmenter that does not
/// see through occlusion.
#[derive(Debug, Clone, Copy, Default)]
pub struct VisibleMasks;

impl MaskSource for VisibleMasks {
    fn name(&self) -> String {
        "ground truth, visible pixels only".into()
    }
    fn start(&mut self) {}
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>> {
        let n = sequence.pixels();
        Ok(forearm_of(&sequence.visible[t * n..(t + 1) * n]))
    }
}

/// 1 where a class image shows the forearm, 0 elsewhere.
fn forearm_of(classes: &[u8]) -> Vec<f32> {
    classes
        .iter()
        .map(|&c| f32::from(u8::from(c == Class::Forearm as u8)))
        .collect()
}

/// A segmentation network's forearm probabilities, scaled bilinearly to the dataset's size.
pub struct NetworkMasks {
    pub net: ProcNet,
    pub name: String,
}

impl MaskSource for NetworkMasks {
    fn name(&self) -> String {
        self.name.clone()
    }
    fn start(&mut self) {
        self.net.reset();
    }
    fn forearm(&mut self, sequence: &Sequence, t: usize) -> Result<Vec<f32>> {
        let s = self.net.config().input_size;
        let (w, h) = (sequence.width as usize, sequence.height as usize);
        let rgb = resize_planes(sequence.rgb_frame(t), 3, w, h, s, s);
        let masks = self.net.segment(&rgb)?;
        let forearm = masks
            .class("forearm")
            .ok_or_else(|| PerceptionError::Input {
                message: format!(
                    "the network has no forearm class (it has {:?})",
                    masks.classes
                ),
            })?;
        Ok(resize_planes(forearm, 1, s, s, w, h))
    }
}

/// Bilinear resampling of `planes` planes of `w x h` to `ow x oh` (pixel centres aligned).
#[must_use]
pub fn resize_planes(
    src: &[f32],
    planes: usize,
    w: usize,
    h: usize,
    ow: usize,
    oh: usize,
) -> Vec<f32> {
    if (w, h) == (ow, oh) {
        return src.to_vec();
    }
    let mut out = vec![0.0; planes * ow * oh];
    let (sx, sy) = (w as f64 / ow as f64, h as f64 / oh as f64);
    for p in 0..planes {
        let plane = &src[p * w * h..(p + 1) * w * h];
        for y in 0..oh {
            let fy = ((y as f64 + 0.5) * sy - 0.5).clamp(0.0, (h - 1) as f64);
            let (y0, ty) = (fy.floor() as usize, fy.fract() as f32);
            let y1 = (y0 + 1).min(h - 1);
            for x in 0..ow {
                let fx = ((x as f64 + 0.5) * sx - 0.5).clamp(0.0, (w - 1) as f64);
                let (x0, tx) = (fx.floor() as usize, fx.fract() as f32);
                let x1 = (x0 + 1).min(w - 1);
                let top = plane[y0 * w + x0] * (1.0 - tx) + plane[y0 * w + x1] * tx;
                let bottom = plane[y1 * w + x0] * (1.0 - tx) + plane[y1 * w + x1] * tx;
                out[p * ow * oh + y * ow + x] = top * (1.0 - ty) + bottom * ty;
            }
        }
    }
    out
}

/// Segments around round shapes in the pose search's forearm mesh.
pub const POSE_MESH_SEGMENTS: usize = 6;

/// The forearm of a cell's human model, and the shoulder it hangs from when that is fixed
/// in the world: `(shoulder in the world, upper-arm length)`.
#[derive(Debug, Clone)]
pub struct ForearmSetup {
    pub model: RigidModel,
    pub shoulder_W: Option<(Vector, f64)>,
}

impl ForearmSetup {
    /// The forearm of `cell` (its human's link named forearm). The shoulder is the origin of
    /// the forearm's parent link (the upper arm) when it stays put (within a micrometre)
    /// over the joint limits' corners.
    ///
    /// # Errors
    /// The human has no forearm.
    pub fn of_cell(cell_model: &CellModel) -> Result<Self> {
        let cell = CellScene::new(cell_model);
        let (Some(k), Some(forearm)) = (cell.forearm_object(), cell.forearm_link) else {
            return Err(PerceptionError::Input {
                message: "the cell's human model has no link named forearm".into(),
            });
        };
        let human = &cell_model.human;
        // The link's visuals at 6 segments around round shapes: the search renders the
        // forearm thousands of times a second, and a hexagon of a 1-2 pixel bone is its
        // circle to a hundredth of a pixel.
        let full = &cell.scene.objects[k];
        let mut mesh = RenderMesh::default();
        for g in &human.links()[forearm].visuals {
            mesh.append(
                &RenderMesh::from_geometry_with(g, [0.85, 0.72, 0.62], POSE_MESH_SEGMENTS),
                &Pose::IDENTITY,
            );
        }
        if mesh.is_empty() {
            mesh = (*full.mesh).clone();
        }
        let model = RigidModel::new(Arc::new(mesh))?;
        let parent = human.links()[forearm]
            .parent_joint
            .map(|j| human.joints()[j].parent);
        let corners = [0.0, 0.5, 1.0];
        let limits = human.position_limits();
        let mut points = Vec::new();
        for c in corners {
            let q: Vec<f64> = limits
                .iter()
                .map(|&[lo, hi]| {
                    let (lo, hi) = (lo.max(-3.0), hi.min(3.0));
                    lo + c * (hi - lo)
                })
                .collect();
            if let (Some(parent), Ok(k)) = (parent, human.fk(cell_model.X_WH, &q)) {
                let poses = k.link_poses();
                points.push((poses[parent].translation, poses[forearm].translation));
            }
        }
        let fixed = points.len() == corners.len()
            && points
                .iter()
                .all(|(s, _)| (*s - points[0].0).length() < 1e-6);
        let shoulder_W = fixed.then(|| (points[0].0, (points[0].1 - points[0].0).length()));
        Ok(Self { model, shoulder_W })
    }

    /// The setup of the cell a dataset was rendered from (the scenario in its manifest).
    ///
    /// # Errors
    /// The scenario does not parse or build, or its human has no forearm.
    pub fn of_dataset(dataset: &Dataset) -> Result<Self> {
        let path = dataset.root.join("manifest.json");
        let scenario = Scenario::from_toml(&dataset.manifest.scenario, &path)?;
        Self::of_cell(&CellModel::new(&scenario, &path)?)
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
}

/// The errors of one estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseError {
    /// At the forearm's centre, cm.
    pub position_cm: f64,
    /// Absolute differences of the URDF angles, degrees.
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    /// The angle between the axes, degrees.
    pub axis_deg: f64,
    /// Rotation about the forearm's own axis, degrees.
    pub spin_deg: f64,
    /// The end-for-end twin was the nearer.
    pub flipped: bool,
}

/// The errors of `estimate` against `truth` (see the module docs).
#[must_use]
pub fn pose_error(model: &RigidModel, estimate: &Pose, truth: &Pose) -> PoseError {
    let twin = model.twin(estimate);
    // The twin whose axis points the truth's way (spin is weakly seen; the axis is not).
    let along = |X: &Pose| (X.rotation * model.axis_O).dot(truth.rotation * model.axis_O);
    let flipped = along(&twin) > along(estimate);
    let X = if flipped { twin } else { *estimate };
    let (_, e) = pose_to_xyz_rpy(&X);
    let (_, t) = pose_to_xyz_rpy(truth);
    let wrap = |a: f64| (a.sin().atan2(a.cos())).abs().to_degrees();
    let (u, v) = (X.rotation * model.axis_O, truth.rotation * model.axis_O);
    // The spin: the twist about the axis of the relative rotation (swing-twist split).
    let rel = truth.rotation.inverse() * X.rotation;
    let a = model.axis_O;
    let p = Vector::new(rel.x, rel.y, rel.z).dot(a);
    let spin = 2.0 * p.atan2(rel.w);
    PoseError {
        position_cm: 100.0 * (model.centre(&X) - model.centre(truth)).length(),
        yaw_deg: wrap(e[2] - t[2]),
        pitch_deg: wrap(e[1] - t[1]),
        roll_deg: wrap(e[0] - t[0]),
        axis_deg: u.dot(v).clamp(-1.0, 1.0).acos().to_degrees(),
        spin_deg: wrap(spin),
        flipped,
    }
}

/// One evaluated frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    pub sequence: usize,
    pub frame: usize,
    pub distance_class: String,
    pub occlusion_level: String,
    /// The true forearm centre's distance from the camera, m.
    pub distance_m: f64,
    /// The forearm's occlusion in this frame (0 to 1).
    pub occlusion: f64,
    /// The errors, or why there was no pose.
    pub outcome: std::result::Result<PoseError, NoPose>,
    pub reacquired: bool,
    pub f_m: f64,
    pub gain: f64,
    pub uncertainty_m: f64,
    /// Time of the pose search (not the network), ms.
    pub pose_ms: f64,
    /// Time of the mask source (the network), ms.
    pub mask_ms: f64,
    pub renders: usize,
}

impl FrameResult {
    /// The frame is of this distance class and occlusion level; `None` matches every value.
    #[must_use]
    pub fn is_in(&self, distance: Option<&str>, level: Option<&str>) -> bool {
        distance.is_none_or(|d| self.distance_class == d)
            && level.is_none_or(|l| self.occlusion_level == l)
    }
}

/// Statistics of a group of frames.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Summary {
    pub frames: usize,
    pub no_pose: usize,
    pub reacquired: usize,
    pub position_cm: f64,
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub roll_deg: f64,
    pub axis_deg: f64,
    pub spin_deg: f64,
    pub flipped: usize,
}

impl Summary {
    fn of<'a>(frames: impl Iterator<Item = &'a FrameResult>) -> Summary {
        let mut s = Summary::default();
        for f in frames {
            s.frames += 1;
            s.reacquired += usize::from(f.reacquired);
            match &f.outcome {
                Ok(e) => {
                    s.position_cm += e.position_cm;
                    s.yaw_deg += e.yaw_deg;
                    s.pitch_deg += e.pitch_deg;
                    s.roll_deg += e.roll_deg;
                    s.axis_deg += e.axis_deg;
                    s.spin_deg += e.spin_deg;
                    s.flipped += usize::from(e.flipped);
                }
                Err(_) => s.no_pose += 1,
            }
        }
        let n = (s.frames - s.no_pose) as f64;
        if n > 0.0 {
            for v in [
                &mut s.position_cm,
                &mut s.yaw_deg,
                &mut s.pitch_deg,
                &mut s.roll_deg,
                &mut s.axis_deg,
                &mut s.spin_deg,
            ] {
                *v /= n;
            }
        } else {
            s.position_cm = f64::NAN;
        }
        s
    }
}

/// A split's pose evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseEvaluation {
    pub masks: String,
    pub split: String,
    pub sequences: usize,
    pub roi: bool,
    /// The elbow was anchored to the shoulder.
    pub anchored: bool,
    pub frames: Vec<FrameResult>,
}

/// The paper's Table 2 (position error, cm): ProcNet and PoseCNN; `None` where it failed.
pub const PAPER_TABLE2: [(&str, &str, Option<f64>, Option<f64>); 9] = [
    ("short", "light", Some(1.73), Some(1.62)),
    ("short", "medium", Some(2.48), Some(4.83)),
    ("short", "heavy", Some(5.84), Some(6.29)),
    ("medium", "light", Some(1.81), Some(1.57)),
    ("medium", "medium", Some(2.59), Some(5.02)),
    ("medium", "heavy", Some(6.04), Some(6.54)),
    ("large", "light", Some(4.07), Some(2.65)),
    ("large", "medium", Some(5.39), Some(2.86)),
    ("large", "heavy", None, None),
];
/// The paper's averages (ProcNet, PoseCNN), cm.
pub const PAPER_AVERAGE: (f64, f64) = (3.74, 3.92);

/// Tracks the forearm through every sequence of `split` with masks from `source`.
/// `progress` gets (sequences done, total).
///
/// # Errors
/// The dataset, the mask source or the renderer fails; the split is empty.
pub fn evaluate_pose(
    dataset: &Dataset,
    split: Split,
    source: &mut dyn MaskSource,
    config: &PoseConfig,
    anchored: bool,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<PoseEvaluation> {
    let setup = ForearmSetup::of_dataset(dataset)?;
    let model = setup.model.clone();
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
    let mut estimator = PoseEstimator::new(CpuRenderer::new(), model.clone(), config.clone());
    let mut frames = Vec::new();
    for (k, entry) in entries.iter().enumerate() {
        let seq = dataset.load(entry)?;
        source.start();
        estimator.reset();
        for t in 0..seq.len() {
            let labels = &seq.labels[t];
            let t0 = Instant::now();
            let mask = source.forearm(&seq, t)?;
            let mask_ms = t0.elapsed().as_secs_f64() * 1e3;
            let camera = Camera::from(&labels.camera);
            estimator.set_anchor(if anchored {
                setup.anchor(&camera.X_WC)
            } else {
                None
            });
            let t1 = Instant::now();
            let outcome = estimator.estimate(&camera, &mask)?;
            let pose_ms = t1.elapsed().as_secs_f64() * 1e3;
            let Some(part) = labels.part("forearm") else {
                continue;
            };
            let Some(occlusion) = part.occlusion else {
                continue; // out of view
            };
            if t == 0 {
                continue;
            }
            let truth = Pose::from(&part.X_CP);
            let (mut reacquired, mut f_m, mut gain, mut unc, mut renders) =
                (false, 0.0, 0.0, 0.0, 0);
            let outcome = outcome.map(|e| {
                (reacquired, f_m, gain, unc, renders) =
                    (e.reacquired, e.f_m, e.gain, e.uncertainty_m, e.renders);
                pose_error(&model, &e.X_CO, &truth)
            });
            frames.push(FrameResult {
                sequence: entry.index,
                frame: t,
                distance_class: entry.distance_class.clone(),
                occlusion_level: entry.occlusion_level.clone(),
                distance_m: model.centre(&truth).length(),
                occlusion,
                outcome,
                reacquired,
                f_m,
                gain,
                uncertainty_m: unc,
                pose_ms,
                mask_ms,
                renders,
            });
        }
        progress(k + 1, entries.len());
    }
    Ok(PoseEvaluation {
        masks: source.name(),
        split: split.name().to_string(),
        sequences: entries.len(),
        roi: config.roi,
        anchored: anchored && setup.shoulder_W.is_some(),
        frames,
    })
}

fn fmt_cm(v: Option<f64>) -> String {
    v.map_or_else(|| "failed".to_string(), |v| format!("{v:.2}"))
}

/// Several mask sources on the same split side by side (`eval pose --masks procnet,baseline`):
/// per cell of Table 2 and per occlusion level, each source's mean position error and frames
/// without a pose, then the same means over only the frames where every source has a pose
/// (a source that gives up on hard frames is not rewarded for it), with the paper's numbers.
///
/// # Errors
/// The evaluations are not of the same frames.
pub fn compare_markdown(evals: &[(&str, &PoseEvaluation)]) -> Result<String> {
    let Some((_, first)) = evals.first() else {
        return Err(PerceptionError::Input {
            message: "nothing to compare".into(),
        });
    };
    let key = |f: &FrameResult| (f.sequence, f.frame);
    for (name, ev) in evals {
        if ev.frames.len() != first.frames.len()
            || ev
                .frames
                .iter()
                .zip(&first.frames)
                .any(|(a, b)| key(a) != key(b))
        {
            return Err(PerceptionError::Input {
                message: format!("{name} was evaluated on other frames than {}", evals[0].0),
            });
        }
    }
    let every_has_pose: Vec<bool> = (0..first.frames.len())
        .map(|i| evals.iter().all(|(_, ev)| ev.frames[i].outcome.is_ok()))
        .collect();
    // (distance, occlusion, paper ProcNet, paper PoseCNN); `None` matches every value.
    type Row<'a> = (Option<&'a str>, Option<&'a str>, Option<f64>, Option<f64>);
    let mut rows: Vec<Row> = PAPER_TABLE2
        .iter()
        .map(|&(d, l, a, b)| (Some(d), Some(l), a, b))
        .collect();
    for level in ["light", "medium", "heavy"] {
        rows.push((None, Some(level), None, None));
    }
    rows.push((None, None, Some(PAPER_AVERAGE.0), Some(PAPER_AVERAGE.1)));
    let mut md = String::new();
    let names: Vec<&str> = evals.iter().map(|(n, _)| *n).collect();
    let _ = writeln!(
        md,
        "Position error (cm) and frames without a pose; then the error over the frames where all of {} have a pose. The paper's PoseCNN column is PoseCNN itself; `baseline` is this project's feed-forward stand-in for it.\n",
        names.join(", ")
    );
    let mut header = "| distance | occlusion | frames |".to_string();
    let mut rule = "|---|---|---|".to_string();
    for n in &names {
        let _ = write!(header, " {n} (cm) | {n} no pose |");
        rule.push_str("---|---|");
    }
    header.push_str(" common frames |");
    rule.push_str("---|");
    for n in &names {
        let _ = write!(header, " {n}, common (cm) |");
        rule.push_str("---|");
    }
    header.push_str(" paper ProcNet (cm) | paper PoseCNN (cm) |");
    rule.push_str("---|---|");
    let _ = writeln!(md, "{header}\n{rule}");
    for (d, l, paper_procnet, paper_posecnn) in rows {
        let average = d.is_none() && l.is_none();
        let mut line = format!(
            "| {} | {} | {} |",
            d.unwrap_or(if average { "average" } else { "all" }),
            l.unwrap_or(""),
            first.summary(d, l).frames
        );
        for (_, ev) in evals {
            let s = ev.summary(d, l);
            let cm = if s.frames == 0 {
                "-".into()
            } else {
                fmt_cm(finite(s.position_cm))
            };
            let _ = write!(line, " {cm} | {} |", s.no_pose);
        }
        let common: Vec<usize> = (0..first.frames.len())
            .filter(|&i| every_has_pose[i] && first.frames[i].is_in(d, l))
            .collect();
        let _ = write!(line, " {} |", common.len());
        for (_, ev) in evals {
            let sum: f64 = common
                .iter()
                .filter_map(|&i| ev.frames[i].outcome.as_ref().ok())
                .map(|e| e.position_cm)
                .sum();
            let mean = if common.is_empty() {
                "-".into()
            } else {
                format!("{:.2}", sum / common.len() as f64)
            };
            let _ = write!(line, " {mean} |");
        }
        let paper = |v: Option<f64>| {
            if d.is_none() && !average {
                String::new()
            } else {
                fmt_cm(v)
            }
        };
        let _ = writeln!(
            line,
            " {} | {} |",
            paper(paper_procnet),
            paper(paper_posecnn)
        );
        md.push_str(&line);
    }
    Ok(md)
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

impl PoseEvaluation {
    /// Statistics of the frames of a (distance class, occlusion level) pair; `None` matches
    /// every value.
    #[must_use]
    pub fn summary(&self, distance: Option<&str>, level: Option<&str>) -> Summary {
        Summary::of(self.frames.iter().filter(|f| f.is_in(distance, level)))
    }

    /// Per distance bin of `bin_m`: (bin centre, mean position error in cm (NaN without a
    /// pose), frames with a pose, frames without), for the error-against-distance plot.
    #[must_use]
    pub fn by_distance(&self, bin_m: f64) -> Vec<(f64, f64, usize, usize)> {
        let mut bins: BTreeMap<i64, (f64, usize, usize)> = BTreeMap::new();
        for f in &self.frames {
            let b = bins
                .entry((f.distance_m / bin_m).floor() as i64)
                .or_default();
            match &f.outcome {
                Ok(e) => {
                    b.0 += e.position_cm;
                    b.1 += 1;
                }
                Err(_) => b.2 += 1,
            }
        }
        bins.into_iter()
            .map(|(k, (sum, n, none))| {
                let mean = if n > 0 { sum / n as f64 } else { f64::NAN };
                ((k as f64 + 0.5) * bin_m, mean, n, none)
            })
            .collect()
    }

    /// The evaluation as Markdown: Table 2's layout with the paper's numbers beside ours,
    /// then the angles, then timing.
    #[must_use]
    pub fn to_markdown(&self) -> String {
        let mut md = String::new();
        let _ = writeln!(
            md,
            "Pose error on the {} split ({} sequences, {} frames), masks: {}; search {}, {}.\n",
            self.split,
            self.sequences,
            self.frames.len(),
            self.masks,
            if self.roi {
                "in a region of interest"
            } else {
                "over the whole image"
            },
            if self.anchored {
                "elbow anchored to the shoulder"
            } else {
                "from the mask alone (no anchor)"
            }
        );
        let _ = writeln!(
            md,
            "| distance | occlusion | frames | no pose | position (cm) | paper ProcNet (cm) | paper PoseCNN (cm) | re-acquired |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|---|");
        for (d, l, ours, theirs) in PAPER_TABLE2 {
            let s = self.summary(Some(d), Some(l));
            let _ = writeln!(
                md,
                "| {d} | {l} | {} | {} | {} | {} | {} | {} |",
                s.frames,
                s.no_pose,
                if s.frames > s.no_pose {
                    format!("{:.2}", s.position_cm)
                } else {
                    "failed".into()
                },
                fmt_cm(ours),
                fmt_cm(theirs),
                s.reacquired
            );
        }
        let s = self.summary(None, None);
        let _ = writeln!(
            md,
            "| average | | {} | {} | {:.2} | {:.2} | {:.2} | {} |\n",
            s.frames, s.no_pose, s.position_cm, PAPER_AVERAGE.0, PAPER_AVERAGE.1, s.reacquired
        );
        let _ = writeln!(
            md,
            "The paper's PoseCNN column is PoseCNN itself; this project's stand-in for it is the feed-forward baseline (`--masks baseline`; `--masks procnet,baseline` compares the two).\n"
        );
        let _ = writeln!(
            md,
            "| distance | occlusion | yaw (deg) | pitch (deg) | roll (deg) | axis (deg) | spin about the axis (deg) | end-for-end flips |"
        );
        let _ = writeln!(md, "|---|---|---|---|---|---|---|---|");
        let mut rows: Vec<(Option<&str>, Option<&str>)> = PAPER_TABLE2
            .iter()
            .map(|(d, l, _, _)| (Some(*d), Some(*l)))
            .collect();
        rows.push((None, None));
        for (d, l) in rows {
            let s = self.summary(d, l);
            let _ = writeln!(
                md,
                "| {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {} |",
                d.unwrap_or("average"),
                l.unwrap_or(""),
                s.yaw_deg,
                s.pitch_deg,
                s.roll_deg,
                s.axis_deg,
                s.spin_deg,
                s.flipped
            );
        }
        md.push_str(&self.timing_markdown());
        md
    }

    /// Time per frame: the mask source (the network) and the pose search, split by tracked
    /// and re-acquired frames, as mean, median and 95th percentile.
    #[must_use]
    pub fn timing_markdown(&self) -> String {
        let stats = |mut v: Vec<f64>| -> String {
            if v.is_empty() {
                return "| - | - | - | 0 |".into();
            }
            v.sort_by(f64::total_cmp);
            let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            format!(
                "| {mean:.1} | {:.1} | {:.1} | {} |",
                q(0.5),
                q(0.95),
                v.len()
            )
        };
        let tracked: Vec<&FrameResult> = self
            .frames
            .iter()
            .filter(|f| f.outcome.is_ok() && !f.reacquired)
            .collect();
        let mut md = String::from(
            "\n| per frame (ms) | mean | median | 95th percentile | frames |\n|---|---|---|---|---|\n",
        );
        let rows: [(&str, Vec<f64>); 5] = [
            (
                "masks (network)",
                self.frames.iter().map(|f| f.mask_ms).collect(),
            ),
            ("pose, tracked", tracked.iter().map(|f| f.pose_ms).collect()),
            (
                "pose, re-acquired (global search)",
                self.frames
                    .iter()
                    .filter(|f| f.reacquired)
                    .map(|f| f.pose_ms)
                    .collect(),
            ),
            (
                "pose, all frames",
                self.frames.iter().map(|f| f.pose_ms).collect(),
            ),
            (
                "masks + pose",
                self.frames.iter().map(|f| f.mask_ms + f.pose_ms).collect(),
            ),
        ];
        for (name, v) in rows {
            let _ = writeln!(md, "| {name} {}", stats(v));
        }
        let n = self.frames.len().max(1) as f64;
        let renders = self.frames.iter().map(|f| f.renders as f64).sum::<f64>() / n;
        let _ = writeln!(md, "\n{renders:.0} renders per frame on average.");
        md
    }

    /// One line per frame, CSV.
    #[must_use]
    pub fn to_csv(&self) -> String {
        let mut csv = String::from(
            "sequence,frame,distance_class,occlusion_level,distance_m,occlusion,no_pose,position_cm,yaw_deg,pitch_deg,roll_deg,axis_deg,spin_deg,flipped,reacquired,f_m,gain,uncertainty_m,mask_ms,pose_ms,renders\n",
        );
        for f in &self.frames {
            let (no_pose, e) = match &f.outcome {
                Ok(e) => (String::new(), Some(e)),
                Err(why) => (why.to_string(), None),
            };
            let v = |g: fn(&PoseError) -> f64| e.map_or(String::new(), |e| format!("{:.4}", g(e)));
            let _ = writeln!(
                csv,
                "{},{},{},{},{:.4},{:.4},{},{},{},{},{},{},{},{},{},{:.6},{:.4},{:.4},{:.3},{:.3},{}",
                f.sequence,
                f.frame,
                f.distance_class,
                f.occlusion_level,
                f.distance_m,
                f.occlusion,
                no_pose,
                v(|e| e.position_cm),
                v(|e| e.yaw_deg),
                v(|e| e.pitch_deg),
                v(|e| e.roll_deg),
                v(|e| e.axis_deg),
                v(|e| e.spin_deg),
                e.is_some_and(|e| e.flipped),
                f.reacquired,
                f.f_m,
                f.gain,
                f.uncertainty_m,
                f.mask_ms,
                f.pose_ms,
                f.renders
            );
        }
        csv
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_robots::math::{Rotation, pose_from_xyz_rpy};

    fn model() -> RigidModel {
        let m = CellModel::new(&Scenario::default(), std::path::Path::new("inline.toml"))
            .expect("scenario");
        ForearmSetup::of_cell(&m).expect("forearm").model
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

    #[test]
    fn the_built_in_human_hangs_its_forearm_from_a_fixed_shoulder() {
        let cell = CellModel::new(&Scenario::default(), std::path::Path::new("inline.toml"))
            .expect("scenario");
        let setup = ForearmSetup::of_cell(&cell).expect("forearm");
        let (shoulder, radius) = setup.shoulder_W.expect("a fixed shoulder");
        // robots/urdf/human_arm/human_arm.urdf: elbow_flexion at z = -0.3255 in the upper
        // arm, shoulder_abduction at (0, -0.19, 0.48) in the torso.
        assert!((radius - 0.3255).abs() < 1e-12, "{radius}");
        let expected = cell.X_WH.transform_point(Vector::new(0.0, -0.19, 0.48));
        assert!(
            (shoulder - expected).length() < 1e-12,
            "{shoulder} vs {expected}"
        );
        // In a camera's frame.
        let X_WC = workcell_robots::math::pose_from_xyz_rpy([1.0, 2.0, 1.5], [0.3, -0.2, 2.0]);
        let anchor = setup.anchor(&X_WC).expect("anchor");
        assert!((X_WC.transform_point(anchor.point_C) - shoulder).length() < 1e-12);
    }

    #[test]
    fn bilinear_resize_keeps_constants_and_ramps() {
        let flat = vec![0.25; 2 * 4 * 4];
        assert!(
            resize_planes(&flat, 2, 4, 4, 8, 8)
                .iter()
                .all(|&v| (v - 0.25).abs() < 1e-7)
        );
        // A horizontal ramp over pixel centres stays a ramp at half the slope when doubled.
        let ramp: Vec<f32> = (0..16).map(|i| (i % 4) as f32).collect();
        let up = resize_planes(&ramp, 1, 4, 4, 8, 8);
        // Output centre x = 2.5 (out px 2) maps to input 2.5 * 0.5 - 0.5 = 0.75.
        assert!((up[8 + 2] - 0.75).abs() < 1e-6, "{}", up[8 + 2]);
    }
}
