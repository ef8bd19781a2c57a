//! ProcNet in the closed loop: the cell's camera renders a frame at its rate, ProcNet segments
//! the forearm, render-and-compare finds its pose (the elbow anchored to the human's fixed
//! shoulder), and the arm's parts follow from that pose and the human model's dimensions:
//! the upper arm from the shoulder to the estimated elbow, the forearm and the hand rigidly
//! with the estimated forearm. A frame without a pose delivers nothing: the last estimate
//! ages (its uncertainty grows) and without one the filter brakes.

use std::collections::VecDeque;

use workcell_perception::pose::PoseConfig;
use workcell_perception::{ArmModel, ArmTracker, Backend, ProcNet};
use workcell_safety::{Capsule, HumanEstimate, HumanPart, PartEstimate};
use workcell_sim::render::{Camera, CpuRenderer, Frame, Renderer};
use workcell_sim::{CellModel, CellScene, Scenario};

use super::perception::{HumanPerception, MaskKind, PerceptionConfig, PerceptionInput};
use crate::error::{Error, Result};
use crate::robots::math::Vector;

/// One measurement: world end points and radius of each part, and the pose uncertainty.
#[derive(Debug, Clone)]
struct Measured {
    parts: Vec<(HumanPart, Vector, Vector, f64)>,
    uncertainty_m: f64,
}

/// The cell's camera rendered and handed to an [`ArmTracker`], as a [`HumanPerception`]:
/// this wiring adds the camera's rate, its latency and velocities from successive frames.
pub struct ProcNetCamera {
    config: PerceptionConfig,
    tracker: ArmTracker,
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
    pub fn new(config: &PerceptionConfig, scenario: &Scenario, model: &CellModel) -> Result<Self> {
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
        let arm = ArmModel::new(&model.human, &model.X_WH)?;
        let mut tracker = ArmTracker::new(arm, PoseConfig::default());
        if config.masks == MaskKind::Network {
            let net = ProcNet::load(&config.weights, Backend::Flex).map_err(|e| Error::At {
                key: "perception.weights".into(),
                source: Box::new(e.into()),
            })?;
            tracker = tracker.with_network(net)?;
        }
        Ok(Self {
            config: PerceptionConfig {
                rate_hz: camera_config.rate_hz,
                ..config.clone()
            },
            tracker,
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

    /// Renders and tracks one frame; `None` when there is no estimate.
    fn measure(&mut self, input: &PerceptionInput<'_>) -> Result<Option<Measured>> {
        self.scene.update(input.state);
        self.renderer
            .render(&self.scene.scene, &self.camera, &mut self.frame)
            .map_err(workcell_sim::SimError::from)?;
        let outcome = if self.tracker.network().is_some() {
            self.tracker.track(&self.camera, &self.frame.rgb)?
        } else {
            // The perfect segmenter: the forearm's pixels in the frame.
            let id = self
                .scene
                .forearm_object()
                .and_then(|k| u16::try_from(k + 1).ok())
                .ok_or_else(|| Error::config("human.model", "the cell's human has no forearm"))?;
            let mask: Vec<f32> = self
                .frame
                .object
                .iter()
                .map(|&o| f32::from(u8::from(o == id)))
                .collect();
            self.tracker.track_frame_mask(&self.camera, &mask)?
        };
        Ok(outcome.ok().map(|estimate| Measured {
            parts: estimate
                .parts
                .iter()
                .map(|p| (p.part, p.a_W, p.b_W, p.radius_m))
                .collect(),
            uncertainty_m: estimate.uncertainty_m,
        }))
    }
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
            out.uncertainty_rate_m_s = 0.0;
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
        out.uncertainty_m = self.config.aged_uncertainty(m.uncertainty_m, 0.0, age);
        out.uncertainty_rate_m_s = 0.0;
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
    /// its true pose, the tracker with the cell's human model, and the arm back in the world.
    #[test]
    fn the_cell_camera_finds_the_forearm_it_renders() {
        let path =
            std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/default.toml"));
        let scenario = Scenario::from_file(path).expect("scenario");
        let model = CellModel::new(&scenario, path).expect("cell");
        let mut state = CellState::new(&model).expect("state");
        let arm = ArmModel::new(&model.human, &model.X_WH).expect("arm");
        let camera = scenario.cameras[0].camera().expect("camera");
        let mesh = arm.forearm.mesh.clone();
        let mut tracker = ArmTracker::new(arm, PoseConfig::default());
        let forearm = model.human.link_id("forearm").expect("forearm link");
        let mut batch = MaskBatch::new();
        for _ in 0..4 {
            for _ in 0..300 {
                step(&model, &mut state, &RobotCommand::Nominal).expect("step");
            }
            let X_WO = state.human_link_poses()[forearm];
            let X_CO = camera.X_WC.inverse() * X_WO;
            CpuRenderer::new()
                .render_masks(&mesh, &camera, &[X_CO], &mut batch)
                .expect("render");
            let mask: Vec<f32> = batch.mask(0).iter().map(|&v| f32::from(v)).collect();
            let estimate = tracker
                .track_frame_mask(&camera, &mask)
                .expect("track")
                .expect("an estimate");
            // The elbow, 2.3 m from the camera: within 10 cm (the mask read through the
            // workspace crop at 128x128 leaves depth to a few centimetres when anchored; see
            // docs/perception.md).
            let err = (estimate.X_WF.translation - X_WO.translation).length();
            assert!(err < 0.10, "elbow {err} m off");
            // The upper arm ends at the estimated elbow.
            let upper = estimate.parts[0];
            assert_eq!(upper.part, HumanPart::UpperArm);
            assert!((upper.b_W - estimate.X_WF.translation).length() < 1e-12);
        }
    }
}
