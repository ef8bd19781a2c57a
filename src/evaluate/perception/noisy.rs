//! A camera model with noise, dropped frames and latency ([`NoisyCamera`]).

use super::*;

/// The radius, in sigmas, that a 3-D isotropic Gaussian error (sigma 1 per axis) exceeds
/// exactly as often as a 1-D Gaussian error exceeds `k` sigmas: the `x` with
/// `P(chi_3 > x) = erfc(k / sqrt 2)`, where `P(chi_3 > x) = erfc(x / sqrt 2) + sqrt(2 / pi) x
/// exp(-x^2 / 2)`. 4.70 for k = 4, against the 6.93 of `k sqrt 3` (the corner of a box of
/// k sigmas per axis, exceeded 2e-10 of the time against 6.3e-5). 0 for k <= 0. A bisection
/// to full precision: compute it once per configuration, not per tick.
#[must_use]
pub fn sphere_radius_for_sigmas(k: f64) -> f64 {
    if k.is_nan() || k <= 0.0 {
        return 0.0;
    }
    let tail = |x: f64| {
        libm::erfc(x / std::f64::consts::SQRT_2)
            + (2.0 / std::f64::consts::PI).sqrt() * x * (-0.5 * x * x).exp()
    };
    let target = libm::erfc(k / std::f64::consts::SQRT_2);
    // The tail falls monotonically from 1 at 0; it is below the target at k sqrt 3 + 1.
    // 64 halvings of a bracket of a few units leave it below one ulp.
    let (mut lo, mut hi) = (k, k * 3f64.sqrt() + 1.0);
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        if tail(mid) > target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// A camera at `rate_hz` whose frames are lost with probability `dropout` and whose
/// estimates (true pose plus Gaussian noise) arrive `latency_s` after exposure. Between
/// frames the last estimate is extrapolated with its velocity; its uncertainty is
/// `r(k) sqrt(sigma_p^2 + (sigma_v age)^2) + a_max age^2 / 2` (r(k): the 3-D radius as
/// rarely exceeded as `confidence_sigmas` in 1-D, [`sphere_radius_for_sigmas`]) held at the
/// oldest age before the next frame is due
/// ([`NoisyConfig::uncertainty`]).
#[derive(Debug, Clone)]
pub struct NoisyCamera {
    config: NoisyConfig,
    /// `sphere_radius_for_sigmas(config.confidence_sigmas)`.
    radius_sigmas: f64,
    rng: ChaCha8Rng,
    next_frame_s: f64,
    /// Measurements taken but not yet delivered: (exposure time, estimate).
    in_flight: std::collections::VecDeque<(f64, HumanEstimate)>,
    /// The newest delivered measurement and its exposure time.
    latest: Option<(f64, HumanEstimate)>,
}

impl NoisyCamera {
    /// A camera with `config`, its noise and dropouts drawn from `seed`.
    #[must_use]
    pub fn new(config: NoisyConfig, seed: u64) -> Self {
        Self {
            radius_sigmas: sphere_radius_for_sigmas(config.confidence_sigmas),
            config,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5045_5243_4550_5400), // "PERCEPT"
            next_frame_s: 0.0,
            in_flight: std::collections::VecDeque::new(),
            latest: None,
        }
    }

    fn gaussian3(&mut self, sigma: f64) -> Vector {
        Vector::new(
            gaussian(&mut self.rng),
            gaussian(&mut self.rng),
            gaussian(&mut self.rng),
        ) * sigma
    }
}

/// A standard normal sample (Box-Muller).
pub(super) fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

impl HumanPerception for NoisyCamera {
    fn name(&self) -> String {
        format!(
            "camera {:.0} Hz, noise {:.0} mm, dropout {:.0} %, latency {:.0} ms, human acceleration up to {} m/s^2",
            self.config.rate_hz,
            self.config.position_noise_m * 1e3,
            self.config.dropout * 100.0,
            self.config.latency_s * 1e3,
            self.config.human_acceleration_m_s2
        )
    }

    fn estimate(&mut self, input: &PerceptionInput<'_>, out: &mut HumanEstimate) {
        let t = input.t_s;
        // Expose a frame when one is due.
        if t + 1e-9 >= self.next_frame_s {
            self.next_frame_s += 1.0 / self.config.rate_hz;
            if self.rng.random::<f64>() >= self.config.dropout {
                let (sp, sv) = (self.config.position_noise_m, self.config.velocity_noise_m_s);
                let mut measured = input.truth.clone();
                measured.parts.extend_from_slice(input.other_arm);
                for p in &mut measured.parts {
                    p.capsule.a_W += self.gaussian3(sp);
                    p.capsule.b_W += self.gaussian3(sp);
                    p.v_a_W += self.gaussian3(sv);
                    p.v_b_W += self.gaussian3(sv);
                }
                self.in_flight.push_back((t, measured));
            }
        }
        // Deliver what has arrived.
        while self
            .in_flight
            .front()
            .is_some_and(|(t0, _)| t0 + self.config.latency_s <= t + 1e-9)
        {
            self.latest = self.in_flight.pop_front();
        }
        out.parts.clear();
        let Some((t0, measured)) = &self.latest else {
            out.uncertainty_m = 0.0;
            out.uncertainty_rate_m_s = 0.0;
            return; // nothing yet: the filter brakes
        };
        let age = (t - t0).max(0.0);
        out.uncertainty_m = self.config.uncertainty(self.radius_sigmas, age);
        out.uncertainty_rate_m_s = 0.0;
        out.parts
            .extend(measured.parts.iter().map(|p| PartEstimate {
                capsule: workcell_safety::Capsule::new(
                    p.capsule.a_W + p.v_a_W * age,
                    p.capsule.b_W + p.v_b_W * age,
                    p.capsule.radius_m,
                ),
                ..*p
            }));
    }
}
