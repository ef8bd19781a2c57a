//! Speeds and accelerations of a body's landmarks: what a safety filter's assumptions about
//! the human must cover.

use serde::Serialize;
use workcell_robots::math::Vector;

use crate::clip::{Clip, Landmark};

/// Speed of each sample of `track` at `rate_hz`, m/s: central differences inside, one-sided
/// at the ends.
#[must_use]
pub fn speeds(track: &[Vector], rate_hz: f64) -> Vec<f64> {
    let n = track.len();
    (0..n)
        .map(|i| match (i.checked_sub(1), (i + 1 < n).then_some(i + 1)) {
            (Some(a), Some(b)) => (track[b] - track[a]).length() * rate_hz / 2.0,
            (None, Some(b)) => (track[b] - track[i]).length() * rate_hz,
            (Some(a), None) => (track[i] - track[a]).length() * rate_hz,
            (None, None) => 0.0,
        })
        .collect()
}

/// Magnitude of the acceleration at each interior sample of `track`, m/s^2 (second central
/// differences; the ends repeat their neighbours').
#[must_use]
pub fn accelerations(track: &[Vector], rate_hz: f64) -> Vec<f64> {
    let n = track.len();
    if n < 3 {
        return vec![0.0; n];
    }
    let mut out: Vec<f64> = (1..n - 1)
        .map(|i| (track[i + 1] - track[i] * 2.0 + track[i - 1]).length() * rate_hz * rate_hz)
        .collect();
    out.insert(0, out[0]);
    out.push(out[out.len() - 1]);
    out
}

/// A distribution's figures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spread {
    pub peak: f64,
    pub p99: f64,
    pub p999: f64,
    pub median: f64,
}

impl Spread {
    /// Of `values` (NaN-free); zeros for none. Percentiles by nearest rank.
    #[must_use]
    pub fn of(values: &mut [f64]) -> Self {
        if values.is_empty() {
            return Self {
                peak: 0.0,
                p99: 0.0,
                p999: 0.0,
                median: 0.0,
            };
        }
        values.sort_by(f64::total_cmp);
        let rank = |q: f64| {
            let k = (q * values.len() as f64).ceil() as usize;
            values[k.clamp(1, values.len()) - 1]
        };
        Self {
            peak: values[values.len() - 1],
            p99: rank(0.99),
            p999: rank(0.999),
            median: rank(0.5),
        }
    }
}

/// One landmark's samples over one or more clips.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Samples {
    pub speed_m_s: Vec<f64>,
    pub acceleration_m_s2: Vec<f64>,
}

impl Samples {
    /// Adds `track`'s samples at `rate_hz`, leaving out the frames `skip` marks.
    pub fn add(&mut self, track: &[Vector], rate_hz: f64, skip: &[bool]) {
        let v = speeds(track, rate_hz);
        let a = accelerations(track, rate_hz);
        for i in 0..track.len() {
            if !skip.get(i).copied().unwrap_or(false) {
                self.speed_m_s.push(v[i]);
                self.acceleration_m_s2.push(a[i]);
            }
        }
    }

    /// The figures of the samples so far.
    #[must_use]
    pub fn spread(&self) -> (Spread, Spread) {
        (
            Spread::of(&mut self.speed_m_s.clone()),
            Spread::of(&mut self.acceleration_m_s2.clone()),
        )
    }
}

/// Per landmark: a clip's samples, frames it filled left out.
#[must_use]
pub fn clip_samples(clip: &Clip) -> Vec<(Landmark, Samples)> {
    clip.landmarks
        .iter()
        .map(|&l| {
            let mut s = Samples::default();
            s.add(&clip.track(l), clip.rate_hz, &clip.filled);
            (l, s)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Closed form: a point on a circle of radius r at angular speed w moves at r w and
    /// accelerates at r w^2 (within the differences' error, O((w dt)^2)).
    #[test]
    fn a_circle_has_its_closed_form_speed_and_acceleration() {
        let (r, w, rate) = (0.5, 4.0, 200.0);
        let track: Vec<Vector> = (0..400)
            .map(|i| {
                let t = i as f64 / rate;
                Vector::new(r * (w * t).cos(), r * (w * t).sin(), 0.0)
            })
            .collect();
        let v = speeds(&track, rate);
        let a = accelerations(&track, rate);
        for i in 1..399 {
            assert!((v[i] - r * w).abs() < 1e-3 * r * w, "{}", v[i]);
            assert!((a[i] - r * w * w).abs() < 1e-3 * r * w * w, "{}", a[i]);
        }
    }

    #[test]
    fn percentiles_are_by_nearest_rank() {
        let mut values: Vec<f64> = (1..=1000).map(f64::from).collect();
        values.reverse();
        let s = Spread::of(&mut values);
        assert_eq!(
            (s.peak, s.p999, s.p99, s.median),
            (1000.0, 999.0, 990.0, 500.0)
        );
    }
}
