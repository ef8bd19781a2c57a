//! Perfect perception: the true human now ([`GroundTruth`]) or ahead ([`Foresight`]).

use super::*;

/// The exact human, every tick, with zero uncertainty.
#[derive(Debug, Clone, Copy, Default)]
pub struct GroundTruth;

impl HumanPerception for GroundTruth {
    fn name(&self) -> String {
        "ground truth".into()
    }
    fn estimate(&mut self, input: &PerceptionInput<'_>, out: &mut HumanEstimate) {
        out.clone_from(input.truth);
        out.parts.extend_from_slice(input.other_arm);
    }
}

/// The report's name of [`Foresight`] `horizon_s` ahead.
pub(super) fn foresight_name(horizon_s: f64) -> String {
    format!("ground truth and {horizon_s} s of foresight (an oracle)")
}

/// Instants of [`Foresight`]'s look ahead.
pub(super) const FORESIGHT_INSTANTS: usize = 6;

/// Ground truth, and the arm's parts where they truly will be at [`FORESIGHT_INSTANTS`]
/// instants evenly spaced up to `foresight_s` ahead, sampled from the cell's scripted human
/// motion: the oracle of a perfect predictor (`perception.foresight_s`). A recorded other
/// arm is told where it is now, after the modelled parts' instants.
pub struct Foresight {
    horizon_s: f64,
    geometry: workcell_safety::HumanGeometry,
    kinematics: crate::robots::KinematicState,
    q: Vec<f64>,
    qd: Vec<f64>,
    ahead: HumanEstimate,
}

impl Foresight {
    /// The oracle for the human of `model`, `horizon_s` ahead.
    ///
    /// # Errors
    /// When the human model has no arm parts with collision geometry.
    pub fn new(horizon_s: f64, model: &CellModel) -> crate::error::Result<Self> {
        let mut kinematics = crate::robots::KinematicState::new(&model.human);
        kinematics.X_WB = model.X_WH;
        Ok(Self {
            horizon_s,
            geometry: workcell_safety::HumanGeometry::new(&model.human)?,
            kinematics,
            q: vec![0.0; model.human.dof()],
            qd: vec![0.0; model.human.dof()],
            ahead: HumanEstimate::default(),
        })
    }
}

impl HumanPerception for Foresight {
    fn name(&self) -> String {
        foresight_name(self.horizon_s)
    }

    fn estimate(&mut self, input: &PerceptionInput<'_>, out: &mut HumanEstimate) {
        out.clone_from(input.truth);
        let (model, n) = (input.model, FORESIGHT_INSTANTS as f64);
        for k in 1..=FORESIGHT_INSTANTS {
            let t = input.t_s + self.horizon_s * k as f64 / n;
            model.human_motion.sample(t, &mut self.q, &mut self.qd);
            // The motion's joints are the model's: forward kinematics cannot fail here, and
            // a failure would only leave the instant out (the present is always told).
            if model
                .human
                .forward_kinematics(&self.q, &mut self.kinematics)
                .is_ok()
            {
                self.geometry.estimate_into(
                    &model.human,
                    &self.kinematics,
                    &self.qd,
                    &mut self.ahead,
                );
                out.parts.extend_from_slice(&self.ahead.parts);
            }
        }
        out.parts.extend_from_slice(input.other_arm);
    }
}
