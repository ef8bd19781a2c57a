//! Joint trajectories: rest-to-rest quintic moves between waypoints, repeated forever.
//!
//! A quintic `s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5` starts and ends with zero velocity and
//! acceleration; its peak speed is `15/8 |dq| / T` (at tau = 1/2) and its peak acceleration
//! `10/sqrt(3) |dq| / T^2` (at tau = (3 - sqrt 3)/6). Each segment's duration is the shortest
//! that keeps every joint within its velocity and acceleration limits. Between waypoints the
//! path is the straight line in joint space.

/// Peak of `ds/dtau` for the quintic blend.
pub const QUINTIC_PEAK_VELOCITY: f64 = 15.0 / 8.0;
/// Peak of `d2s/dtau2` for the quintic blend.
pub const QUINTIC_PEAK_ACCELERATION: f64 = 5.773_502_691_896_258; // 10 / sqrt(3)

/// Shortest duration of a rest-to-rest segment.
const MIN_SEGMENT_S: f64 = 0.05;

#[derive(Debug, Clone, PartialEq)]
struct Segment {
    t0_s: f64,
    duration_s: f64,
    q0: Vec<f64>,
    q1: Vec<f64>,
}

/// A periodic joint trajectory through waypoints, dwelling at each.
#[derive(Debug, Clone, PartialEq)]
pub struct JointTrajectory {
    segments: Vec<Segment>,
    period_s: f64,
    dof: usize,
}

impl JointTrajectory {
    /// A trajectory that stays at `q`.
    #[must_use]
    pub fn hold(q: &[f64]) -> Self {
        Self::through(&[q.to_vec()], &vec![1.0; q.len()], &vec![1.0; q.len()], 1.0)
    }

    /// Visits `waypoints` in order and returns to the first, rest to rest, dwelling `dwell_s`
    /// at each; segment durations respect `velocity_limits` and `acceleration_limits`
    /// (both > 0, one per joint).
    #[must_use]
    pub fn through(
        waypoints: &[Vec<f64>],
        velocity_limits: &[f64],
        acceleration_limits: &[f64],
        dwell_s: f64,
    ) -> Self {
        let dof = waypoints.first().map_or(0, Vec::len);
        let mut segments = Vec::with_capacity(2 * waypoints.len());
        let mut t = 0.0;
        for (i, q0) in waypoints.iter().enumerate() {
            let q1 = &waypoints[(i + 1) % waypoints.len()];
            if dwell_s > 0.0 {
                segments.push(Segment {
                    t0_s: t,
                    duration_s: dwell_s,
                    q0: q0.clone(),
                    q1: q0.clone(),
                });
                t += dwell_s;
            }
            let duration_s = segment_duration(q0, q1, velocity_limits, acceleration_limits);
            if q0 != q1 {
                segments.push(Segment {
                    t0_s: t,
                    duration_s,
                    q0: q0.clone(),
                    q1: q1.clone(),
                });
                t += duration_s;
            }
        }
        if segments.is_empty() {
            let q = waypoints.first().cloned().unwrap_or_default();
            segments.push(Segment {
                t0_s: 0.0,
                duration_s: 1.0,
                q0: q.clone(),
                q1: q,
            });
            t = 1.0;
        }
        Self {
            segments,
            period_s: t,
            dof,
        }
    }

    /// Time after which the trajectory repeats, s.
    #[must_use]
    pub fn period_s(&self) -> f64 {
        self.period_s
    }

    /// Number of joints.
    #[must_use]
    pub fn dof(&self) -> usize {
        self.dof
    }

    /// Position, velocity and acceleration at time `t_s` (any t; the motion repeats).
    /// The slices must have [`JointTrajectory::dof`] entries.
    pub fn sample(&self, t_s: f64, q: &mut [f64], qd: &mut [f64], qdd: &mut [f64]) {
        let t = t_s.rem_euclid(self.period_s);
        let i = self
            .segments
            .partition_point(|s| s.t0_s <= t)
            .saturating_sub(1);
        let s = &self.segments[i];
        let tau = ((t - s.t0_s) / s.duration_s).clamp(0.0, 1.0);
        let (p, v, a) = quintic(tau);
        for j in 0..self.dof {
            let dq = s.q1[j] - s.q0[j];
            q[j] = s.q0[j] + dq * p;
            qd[j] = dq * v / s.duration_s;
            qdd[j] = dq * a / (s.duration_s * s.duration_s);
        }
    }
}

/// `(s, ds/dtau, d2s/dtau2)` of the quintic rest-to-rest blend.
#[must_use]
#[inline]
pub fn quintic(tau: f64) -> (f64, f64, f64) {
    let t2 = tau * tau;
    let t3 = t2 * tau;
    (
        t3 * (10.0 - 15.0 * tau + 6.0 * t2),
        30.0 * t2 * (1.0 - tau) * (1.0 - tau),
        60.0 * tau - 180.0 * t2 + 120.0 * t3,
    )
}

/// Shortest rest-to-rest quintic duration from `q0` to `q1` within the limits.
#[must_use]
pub fn segment_duration(q0: &[f64], q1: &[f64], vmax: &[f64], amax: &[f64]) -> f64 {
    q0.iter()
        .zip(q1)
        .zip(vmax.iter().zip(amax))
        .map(|((a, b), (v, acc))| {
            let d = (b - a).abs();
            (QUINTIC_PEAK_VELOCITY * d / v).max((QUINTIC_PEAK_ACCELERATION * d / acc).sqrt())
        })
        .fold(MIN_SEGMENT_S, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn quintic_peaks_are_the_closed_form_ones() {
        let (_, v, _) = quintic(0.5);
        assert_relative_eq!(v, QUINTIC_PEAK_VELOCITY, epsilon = 1e-12);
        let tau = (3.0 - 3f64.sqrt()) / 6.0;
        let (_, _, a) = quintic(tau);
        assert_relative_eq!(a, QUINTIC_PEAK_ACCELERATION, epsilon = 1e-12);
        assert_eq!(quintic(0.0), (0.0, 0.0, 0.0));
        let (p, v, a) = quintic(1.0);
        assert_relative_eq!(p, 1.0);
        assert_relative_eq!(v, 0.0);
        assert_relative_eq!(a, 0.0, epsilon = 1e-12);
    }

    #[test]
    fn sampled_motion_respects_limits_and_is_periodic() {
        let waypoints = vec![vec![0.0, 0.0], vec![1.0, -2.0], vec![-0.5, 0.3]];
        let (vmax, amax) = ([0.8, 1.5], [2.0, 3.0]);
        let traj = JointTrajectory::through(&waypoints, &vmax, &amax, 0.2);
        let (mut q, mut qd, mut qdd) = ([0.0; 2], [0.0; 2], [0.0; 2]);
        let n = 20_000;
        for k in 0..=n {
            let t = traj.period_s() * k as f64 / n as f64;
            traj.sample(t, &mut q, &mut qd, &mut qdd);
            for j in 0..2 {
                assert!(
                    qd[j].abs() <= vmax[j] * (1.0 + 1e-9),
                    "v {} at t {t}",
                    qd[j]
                );
                assert!(
                    qdd[j].abs() <= amax[j] * (1.0 + 1e-9),
                    "a {} at t {t}",
                    qdd[j]
                );
            }
        }
        // Some joint reaches its limit on each move: the durations are the shortest allowed.
        let peak = (0..=n)
            .map(|k| {
                traj.sample(
                    traj.period_s() * k as f64 / n as f64,
                    &mut q,
                    &mut qd,
                    &mut qdd,
                );
                (qd[0].abs() / vmax[0])
                    .max(qd[1].abs() / vmax[1])
                    .max(qdd[0].abs() / amax[0])
                    .max(qdd[1].abs() / amax[1])
            })
            .fold(0.0, f64::max);
        assert!(peak > 0.99, "peak utilisation {peak}");
        traj.sample(0.1, &mut q, &mut qd, &mut qdd);
        let first = q;
        traj.sample(0.1 + 3.0 * traj.period_s(), &mut q, &mut qd, &mut qdd);
        assert_relative_eq!(first[0], q[0], epsilon = 1e-9);
        assert_relative_eq!(first[1], q[1], epsilon = 1e-9);
    }
}
