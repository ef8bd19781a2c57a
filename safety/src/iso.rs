//! ISO/TS 15066 (now part of ISO 10218-2:2025): speed and separation monitoring (SSM) and
//! the power-and-force-limiting (PFL) contact speeds of the body regions this project
//! models.

use serde::{Deserialize, Serialize};

use crate::error::{Result, invalid};
use crate::human::HumanPart;

/// Parameters of the protective separation distance
///
/// ```text
/// S_p = S_h + S_r + S_s + C + Z_d + Z_r
/// S_h = v_h (T_r + T_s)        human travel while the robot reacts and stops
/// S_r = v_r T_r                robot travel during its reaction time
/// S_s = v_r^2 / (2 a)          robot stopping distance at braking deceleration a
/// T_s = v_r / a                robot stopping time
/// ```
///
/// `Z_d` (sensing uncertainty) is not a constant here: it is what perception reports for the
/// current estimate, passed to each call.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SsmConfig {
    /// Human approach speed v_h, m/s. Default 1.6 (ISO 13855 for distances above 0.5 m).
    pub human_speed_m_s: f64,
    /// Robot reaction time T_r (sensing to braking), s. Default 0.1.
    pub reaction_time_s: f64,
    /// Robot braking deceleration a at the closest point, m/s^2. Default 5.
    pub braking_m_s2: f64,
    /// Intrusion distance C (ISO 13855), m. Default 0: the human's own geometry is tracked.
    pub intrusion_m: f64,
    /// Robot position uncertainty Z_r, m. Default 0.005.
    pub robot_uncertainty_m: f64,
}

impl Default for SsmConfig {
    fn default() -> Self {
        Self {
            human_speed_m_s: 1.6,
            reaction_time_s: 0.1,
            braking_m_s2: 5.0,
            intrusion_m: 0.0,
            robot_uncertainty_m: 0.005,
        }
    }
}

impl SsmConfig {
    /// Checks ranges.
    ///
    /// # Errors
    /// [`crate::SafetyError::InvalidConfig`] naming the key.
    pub fn validate(&self) -> Result<()> {
        let nonneg = |key: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(invalid(key, format!("must be finite and >= 0, got {v}")))
            }
        };
        nonneg("ssm.human_speed_m_s", self.human_speed_m_s)?;
        nonneg("ssm.reaction_time_s", self.reaction_time_s)?;
        nonneg("ssm.intrusion_m", self.intrusion_m)?;
        nonneg("ssm.robot_uncertainty_m", self.robot_uncertainty_m)?;
        if !(self.braking_m_s2.is_finite() && self.braking_m_s2 > 0.0) {
            return Err(invalid(
                "ssm.braking_m_s2",
                format!("must be finite and > 0, got {}", self.braking_m_s2),
            ));
        }
        Ok(())
    }

    /// The protective separation distance S_p for robot speed `v_r_m_s` toward the human and
    /// sensing uncertainty `z_d_m`.
    #[must_use]
    pub fn protective_separation_m(&self, v_r_m_s: f64, z_d_m: f64) -> f64 {
        let (v_h, t_r, a) = (
            self.human_speed_m_s,
            self.reaction_time_s,
            self.braking_m_s2,
        );
        let v_r = v_r_m_s.max(0.0);
        let t_s = v_r / a;
        v_h * (t_r + t_s)
            + v_r * t_r
            + v_r * v_r / (2.0 * a)
            + self.intrusion_m
            + z_d_m
            + self.robot_uncertainty_m
    }

    /// The largest robot speed toward the human for which `S_p <= separation_m`: the positive
    /// root of the quadratic that S_p = D gives,
    ///
    /// ```text
    /// v_r = -(a T_r + v_h) + sqrt(a^2 T_r^2 + v_h^2 + 2 a (D - C - Z_d - Z_r))
    /// ```
    ///
    /// and 0 when even a standing robot is too close (D <= v_h T_r + C + Z_d + Z_r).
    /// (Note the sign of v_h: with `+ v_h` the bound does not vanish at the standstill
    /// distance, so it would let the robot move where it must stand.)
    #[must_use]
    pub fn max_robot_speed_m_s(&self, separation_m: f64, z_d_m: f64) -> f64 {
        let (v_h, t_r, a) = (
            self.human_speed_m_s,
            self.reaction_time_s,
            self.braking_m_s2,
        );
        let slack = separation_m - self.intrusion_m - z_d_m - self.robot_uncertainty_m;
        if slack.is_nan() || slack <= v_h * t_r {
            return 0.0; // also for NaN
        }
        let root = (a * a * t_r * t_r + v_h * v_h + 2.0 * a * slack).sqrt();
        (root - a * t_r - v_h).max(0.0)
    }
}

/// ISO/TS 15066 Annex A limits of a body region (quasi-static contact).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyRegion {
    pub part: HumanPart,
    /// Maximum permissible force, N.
    pub force_n: f64,
    /// Effective spring constant of the region, N/m.
    pub stiffness_n_m: f64,
    /// Effective mass of the region, kg.
    pub mass_kg: f64,
    /// Whether the region may be touched at all (not the head and face).
    pub contact_permitted: bool,
}

impl BodyRegion {
    /// The Annex A values of `part` (forearm/wrist 160 N, 40 N/mm, 2 kg; hand 140 N,
    /// 75 N/mm, 0.6 kg; upper arm 150 N, 30 N/mm, 3 kg; torso: the chest's 140 N, 25 N/mm
    /// and the torso's effective mass of 40 kg, Tables A.2 and A.3). The head and face may
    /// not be touched in any mode: their contact speed is 0 (the skull and forehead's 130 N,
    /// 150 N/mm and 4.4 kg are carried for reports, never for a speed).
    #[must_use]
    pub fn of(part: HumanPart) -> Self {
        // Either arm's part is the same body region.
        let (force_n, stiffness_n_mm, mass_kg) = match part {
            HumanPart::Head => (130.0, 150.0, 4.4),
            HumanPart::Forearm | HumanPart::LeftForearm => (160.0, 40.0, 2.0),
            HumanPart::Hand | HumanPart::LeftHand => (140.0, 75.0, 0.6),
            HumanPart::UpperArm | HumanPart::LeftUpperArm => (150.0, 30.0, 3.0),
            HumanPart::Torso => (140.0, 25.0, 40.0),
        };
        Self {
            part,
            force_n,
            stiffness_n_m: stiffness_n_mm * 1000.0,
            mass_kg,
            contact_permitted: part != HumanPart::Head,
        }
    }

    /// The largest relative speed at which a robot of effective mass `robot_mass_kg`
    /// (M/2 + payload) may hit this region: v = F / sqrt(mu k), mu = (1/m_H + 1/m_R)^-1.
    /// `transient` doubles the force limit (allowed for these regions). 0 where contact is
    /// not permitted.
    #[must_use]
    pub fn max_contact_speed_m_s(&self, robot_mass_kg: f64, transient: bool) -> f64 {
        if !self.contact_permitted {
            return 0.0;
        }
        let force = if transient {
            2.0 * self.force_n
        } else {
            self.force_n
        };
        let mu = 1.0 / (1.0 / self.mass_kg + 1.0 / robot_mass_kg);
        force / (mu * self.stiffness_n_m).sqrt()
    }
}

/// The effective robot mass of ISO/TS 15066 Annex A: half the moving mass plus the payload.
#[must_use]
pub fn effective_robot_mass_kg(moving_mass_kg: f64, payload_kg: f64) -> f64 {
    0.5 * moving_mass_kg + payload_kg
}
