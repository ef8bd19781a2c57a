//! ProcNet in the closed loop: the cell's camera renders a frame at its rate, ProcNet segments
//! the forearm, render-and-compare finds its pose (the elbow anchored to the human's fixed
//! shoulder), and the arm's parts follow from that pose and the human model's dimensions:
//! the upper arm from the shoulder to the estimated elbow, the forearm and the hand rigidly
//! with the estimated forearm. A frame without a pose delivers nothing: the last estimate
//! ages (its uncertainty grows) and without one the filter brakes.

use std::collections::VecDeque;

use anyhow::Context as _;
use workcell_perception::pose::eval::{ForearmSetup, resize_planes};
use workcell_perception::pose::{PoseConfig, PoseEstimator};
use workcell_perception::{Backend, ProcNet};
use workcell_safety::{Capsule, HumanEstimate, HumanPart, PartEstimate};
use workcell_sim::render::{Camera, CellScene, CpuRenderer, Frame, Renderer};
use workcell_sim::{CellModel, Scenario};

use super::perception::{HumanPerception, MaskKind, PerceptionConfig, PerceptionInput};
use crate::robots::math::{Pose, Vector};

/// One measurement: world end points of each part (as the truth orders them) and the pose
/// uncertainty.
#[derive(Debug, Clone)]
struct Measured {
    parts: Vec<(HumanPart, Vector, Vector, f64)>,
    uncertainty_m: f64,
}

/// The camera, ProcNet and the pose search, as a [`HumanPerception`].
pub struct ProcNetCamera {
    config: PerceptionConfig,
    /// The network; `None` for ground-truth masks (`perception.masks = "ground_truth"`).
    net: Option<ProcNet>,
    estimator: PoseEstimator<CpuRenderer>,
    setup: ForearmSetup,
    camera: Camera,
    scene: CellScene,
    renderer: CpuRenderer,
    frame: Frame,
    next_frame_s: f64,
    in_flight: VecDeque<(f64, Option<Measured>)>,
    /// The newest delivered measurement, its exposure time, and the one before (velocity).
    latest: Option<(f64, Measured)>,
    previous: Option<(f64, Measured)>,
}

impl ProcNetCamera {
    /// The perception of `config` for the cell `model` built from `scenario`: its camera
    /// named `config.camera` (the first when empty), the weights at `config.weights`.
    ///
    /// # Errors
    /// The scenario has no such camera, the weights do not load, the human has no forearm.
    pub fn new(
        config: &PerceptionConfig,
        scenario: &Scenario,
        model: &CellModel,
    ) -> anyhow::Result<Self> {
        let camera_config = scenario
            .cameras
            .iter()
            .find(|c| config.camera.is_empty() || c.name == config.camera)
            .with_context(|| {
                format!(
                    "perception.camera: the cell has no camera named {:?} (it has {:?})",
                    config.camera,
                    scenario.cameras.iter().map(|c| &c.name).collect::<Vec<_>>()
                )
            })?;
        let camera = Camera::from_config(camera_config)?;
        let net = match config.masks {
            MaskKind::Network => Some(
                ProcNet::load(&config.weights, Backend::Flex)
                    .with_context(|| format!("perception.weights: {}", config.weights.display()))?,
            ),
            MaskKind::GroundTruth => None,
        };
        let setup = ForearmSetup::of_cell(model)?;
        let estimator = PoseEstimator::new(
            CpuRenderer::new(),
            setup.model.clone(),
            PoseConfig::default(),
        );
        Ok(Self {
            config: PerceptionConfig {
                rate_hz: camera_config.rate_hz,
                ..config.clone()
            },
            net,
            estimator,
            setup,
            camera,
            scene: CellScene::new(model),
            renderer: CpuRenderer::new(),
            frame: Frame::new(),
            next_frame_s: 0.0,
            in_flight: VecDeque::new(),
            latest: None,
            previous: None,
        })
    }

    /// Renders, segments and fits one frame; `None` when there is no pose.
    fn measure(&mut self, input: &PerceptionInput<'_>) -> anyhow::Result<Option<Measured>> {
        self.scene.update(input.state);
        self.renderer
            .render(&self.scene.scene, &self.camera, &mut self.frame)?;
        let (w, h) = (self.frame.width as usize, self.frame.height as usize);
        let n = w * h;
        let mut planar = vec![0.0f32; 3 * n];
        for (p, rgb) in self.frame.rgb.chunks_exact(3).enumerate() {
            for c in 0..3 {
                planar[c * n + p] = f32::from(rgb[c]) / 255.0;
            }
        }
        let mask = match &mut self.net {
            Some(net) => {
                let s = net.config().input_size;
                let masks = net.segment(&resize_planes(&planar, 3, w, h, s, s))?;
                let forearm = masks
                    .class("forearm")
                    .context("the network has no forearm class")?;
                resize_planes(forearm, 1, s, s, w, h)
            }
            None => {
                // The perfect segmenter: the forearm's pixels in the frame.
                let id = self
                    .scene
                    .forearm_object()
                    .and_then(|k| u16::try_from(k + 1).ok())
                    .context("the cell's human has no forearm")?;
                self.frame
                    .object
                    .iter()
                    .map(|&o| f32::from(u8::from(o == id)))
                    .collect()
            }
        };
        self.estimator
            .set_anchor(self.setup.anchor(&self.camera.X_WC));
        let outcome = self.estimator.estimate(&self.camera, &mask)?;
        let Ok(pose) = outcome else {
            return Ok(None);
        };
        // Carry the true forearm's and hand's capsules (the model's dimensions, in their link
        // frames) rigidly onto the estimated forearm; the upper arm from the shoulder to the
        // estimated elbow.
        let X_WO: Pose = self.camera.X_WC * pose.X_CO;
        let true_forearm = input
            .truth
            .parts
            .iter()
            .find(|p| p.part == HumanPart::Forearm)
            .context("the human has no forearm part")?;
        let Some(X_WO_true) = forearm_pose(&self.setup, true_forearm) else {
            return Ok(None);
        };
        let carry = X_WO * X_WO_true.inverse();
        let elbow = X_WO.transform_point(Vector::ZERO);
        let parts = input
            .truth
            .parts
            .iter()
            .map(|p| match p.part {
                HumanPart::UpperArm => {
                    let shoulder = self.setup.shoulder_W.map_or(p.capsule.a_W, |(s, _)| s);
                    (p.part, shoulder, elbow, p.capsule.radius_m)
                }
                _ => (
                    p.part,
                    carry.transform_point(p.capsule.a_W),
                    carry.transform_point(p.capsule.b_W),
                    p.capsule.radius_m,
                ),
            })
            .collect();
        Ok(Some(Measured {
            parts,
            uncertainty_m: pose.uncertainty_m,
        }))
    }
}

/// A frame for the true forearm: origin at its capsule's elbow end (the end at the upper
/// arm's length from the shoulder), the model's axis along the capsule away from the wrist.
/// Only its axis and origin matter for carrying the forearm's and hand's capsules, which lie
/// on that axis and are round.
fn forearm_pose(setup: &ForearmSetup, part: &PartEstimate) -> Option<Pose> {
    let (mut elbow, mut wrist) = (part.capsule.a_W, part.capsule.b_W);
    if let Some((shoulder, radius)) = setup.shoulder_W {
        let off = |p: Vector| ((p - shoulder).length() - radius).abs();
        if off(wrist) < off(elbow) {
            std::mem::swap(&mut elbow, &mut wrist);
        }
    }
    let axis = elbow - wrist;
    if axis.length() < 1e-9 {
        return None;
    }
    let R =
        workcell_robots::math::Rotation::from_rotation_arc(setup.model.axis_O, axis.normalize());
    Some(Pose::from_parts(elbow, R))
}

impl HumanPerception for ProcNetCamera {
    fn name(&self) -> String {
        self.config.describe()
    }

    fn estimate(&mut self, input: &PerceptionInput<'_>, out: &mut HumanEstimate) {
        let t = input.t_s;
        if t + 1e-9 >= self.next_frame_s {
            self.next_frame_s += 1.0 / self.config.rate_hz;
            // A failure of the renderer or the network is a frame without a pose.
            let measured = self.measure(input).unwrap_or_else(|e| {
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
                self.previous = self.latest.replace((t0, m));
            }
        }
        out.parts.clear();
        let Some((t0, m)) = &self.latest else {
            out.uncertainty_m = 0.0;
            return; // nothing yet: the filter brakes
        };
        let age = (t - t0).max(0.0);
        // Velocities from the last two measurements (zero with one).
        let velocity = |k: usize, end: usize| -> Vector {
            match &self.previous {
                Some((t1, p)) if t0 - t1 > 1e-6 => {
                    let (a, b) = (&m.parts[k], &p.parts[k]);
                    let (x0, x1) = if end == 0 { (a.1, b.1) } else { (a.2, b.2) };
                    (x0 - x1) / (t0 - t1)
                }
                _ => Vector::ZERO,
            }
        };
        out.uncertainty_m = m.uncertainty_m + 0.5 * self.config.human_acceleration_m_s2 * age * age;
        for (k, &(part, a, b, r)) in m.parts.iter().enumerate() {
            let (va, vb) = (velocity(k, 0), velocity(k, 1));
            out.parts.push(PartEstimate {
                part,
                capsule: Capsule::new(a + va * age, b + vb * age, r),
                v_a_W: va,
                v_b_W: vb,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_sim::render::MaskBatch;
    use workcell_sim::{CellState, RobotCommand, step};

    /// The loop's conventions end to end: the cell's camera, the forearm's mask rendered at
    /// its true pose, the anchored search, and the pose back in the world.
    #[test]
    fn the_cell_camera_finds_the_forearm_it_renders() {
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        let scenario = Scenario::from_file(path).expect("scenario");
        let model = CellModel::new(&scenario, path).expect("cell");
        let mut state = CellState::new(&model).expect("state");
        let setup = ForearmSetup::of_cell(&model).expect("forearm");
        let camera = Camera::from_config(&scenario.cameras[0]).expect("camera");
        let mut estimator = PoseEstimator::new(
            CpuRenderer::new(),
            setup.model.clone(),
            PoseConfig::default(),
        );
        estimator.set_anchor(setup.anchor(&camera.X_WC));
        let forearm = model.human.link_id("forearm").expect("forearm link");
        let mut batch = MaskBatch::new();
        for _ in 0..4 {
            for _ in 0..300 {
                step(&model, &mut state, &RobotCommand::Nominal).expect("step");
            }
            let X_WO = state.human_link_poses()[forearm];
            let X_CO = camera.X_WC.inverse() * X_WO;
            CpuRenderer::new()
                .render_masks(&setup.model.mesh, &camera, &[X_CO], &mut batch)
                .expect("render");
            let mask: Vec<f32> = batch.mask(0).iter().map(|&v| f32::from(v)).collect();
            let pose = estimator
                .estimate(&camera, &mask)
                .expect("estimate")
                .expect("a pose");
            let found = camera.X_WC * pose.X_CO;
            // The elbow, 2.3 m from the camera: within 10 cm (a forearm 18 pixels long
            // leaves depth to a few centimetres even when anchored; see docs/perception.md).
            let err = (found.translation - X_WO.translation).length();
            assert!(err < 0.10, "elbow {err} m off");
        }
    }
}
