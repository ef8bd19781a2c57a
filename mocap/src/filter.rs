//! A zero-phase low-pass: a second-order Butterworth section run forward and backward (the
//! "filtfilt" of signal-processing libraries), the usual smoothing of motion-capture
//! trajectories before they are differentiated. 6 Hz is the common cut-off for human
//! movement (Winter, *Biomechanics and Motor Control of Human Movement*, 4th ed., 2009,
//! ch. 2: most of a limb's movement lies below 6 Hz).
//!
//! The two passes square the magnitude response: a sine at the cut-off keeps 0.5 of its
//! amplitude (not 0.707), and the phase is zero at every frequency.

use workcell_robots::math::Vector;

/// The usual cut-off for human movement, Hz (see the module's docs).
pub const DEFAULT_CUTOFF_HZ: f64 = 6.0;

/// A second-order Butterworth low-pass by the bilinear transform with prewarping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Butterworth2 {
    b: [f64; 3],
    /// `a[0]` is 1.
    a: [f64; 3],
}

impl Butterworth2 {
    /// The low-pass of cut-off `cutoff_hz` for samples at `rate_hz`; `None` unless
    /// `0 < cutoff_hz < rate_hz / 2`.
    #[must_use]
    pub fn low_pass(cutoff_hz: f64, rate_hz: f64) -> Option<Self> {
        if !(cutoff_hz > 0.0 && rate_hz.is_finite() && cutoff_hz < 0.5 * rate_hz) {
            return None;
        }
        let k = (std::f64::consts::PI * cutoff_hz / rate_hz).tan();
        let s2 = std::f64::consts::SQRT_2;
        let norm = 1.0 / (1.0 + s2 * k + k * k);
        let b0 = k * k * norm;
        Some(Self {
            b: [b0, 2.0 * b0, b0],
            a: [
                1.0,
                2.0 * (k * k - 1.0) * norm,
                (1.0 - s2 * k + k * k) * norm,
            ],
        })
    }

    /// One pass over `x` in place, starting from the steady state of a signal that was
    /// `x[0]` forever (the section's gain at 0 Hz is 1).
    fn pass(&self, x: &mut [f64]) {
        let Some(&x0) = x.first() else { return };
        let (mut x1, mut x2, mut y1, mut y2) = (x0, x0, x0, x0);
        for v in x.iter_mut() {
            let y =
                self.b[0] * *v + self.b[1] * x1 + self.b[2] * x2 - self.a[1] * y1 - self.a[2] * y2;
            (x2, x1) = (x1, *v);
            (y2, y1) = (y1, y);
            *v = y;
        }
    }

    /// The zero-phase filtering of `x`: padded at both ends by its odd reflection (`pad`
    /// samples, fewer when `x` is shorter), run forward, then backward.
    #[must_use]
    pub fn filtfilt(&self, x: &[f64], pad: usize) -> Vec<f64> {
        let n = x.len();
        if n < 2 {
            return x.to_vec();
        }
        let pad = pad.min(n - 1);
        let mut y = Vec::with_capacity(n + 2 * pad);
        // Odd reflection about the end points: 2 x[0] - x[pad..1], then x, then
        // 2 x[n-1] - x[n-2..n-1-pad]: continues the slope, not the value.
        y.extend((1..=pad).rev().map(|i| 2.0 * x[0] - x[i]));
        y.extend_from_slice(x);
        y.extend((1..=pad).map(|i| 2.0 * x[n - 1] - x[n - 1 - i]));
        self.pass(&mut y);
        y.reverse();
        self.pass(&mut y);
        y.reverse();
        y[pad..pad + n].to_vec()
    }
}

/// Filters each coordinate of a track with `filter` ([`Butterworth2::filtfilt`]), padded by
/// one second of samples (`pad`).
#[must_use]
pub fn filter_track(filter: &Butterworth2, track: &[Vector], pad: usize) -> Vec<Vector> {
    let axis =
        |f: fn(&Vector) -> f64| filter.filtfilt(&track.iter().map(f).collect::<Vec<_>>(), pad);
    let (x, y, z) = (axis(|p| p.x), axis(|p| p.y), axis(|p| p.z));
    (0..track.len())
        .map(|i| Vector::new(x[i], y[i], z[i]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The amplitude of `y`, a filtered sine of `hz`, over 2,000 samples of its steady
    /// middle (a whole number of periods for whole `hz` at 100 Hz): its projection on the
    /// sine and the cosine.
    fn amplitude(y: &[f64], hz: f64, rate_hz: f64) -> f64 {
        let (mut s, mut c) = (0.0, 0.0);
        for (i, v) in y.iter().enumerate().skip(1000).take(2000) {
            let phase = std::f64::consts::TAU * hz * i as f64 / rate_hz;
            s += v * phase.sin();
            c += v * phase.cos();
        }
        2.0 * s.hypot(c) / 2000.0
    }

    fn sine(hz: f64, rate_hz: f64, n: usize) -> Vec<f64> {
        (0..n)
            .map(|i| (std::f64::consts::TAU * hz * i as f64 / rate_hz).sin())
            .collect()
    }

    /// Closed form: a second-order Butterworth has |H(f)|^2 = 1 / (1 + (w / w_c)^4) with
    /// w = tan(pi f / rate) (the bilinear transform's warped frequency); two passes give
    /// |H|^2. At the cut-off that is 0.5; an octave below, 1 / (1 + (w/w_c)^4).
    #[test]
    fn the_two_passes_square_the_butterworth_response() {
        let rate = 100.0;
        let filter = Butterworth2::low_pass(6.0, rate).expect("filter");
        let warped = |f: f64| (std::f64::consts::PI * f / rate).tan();
        for hz in [1.0, 3.0, 6.0, 12.0, 20.0] {
            let y = filter.filtfilt(&sine(hz, rate, 4000), 100);
            let r = (warped(hz) / warped(6.0)).powi(4);
            let expected = 1.0 / (1.0 + r);
            let got = amplitude(&y, hz, rate);
            assert!(
                (got - expected).abs() < 1e-6,
                "{hz} Hz: {got} against {expected}"
            );
        }
    }

    /// Zero phase: a filtered sine peaks where the sine does; a ramp (constant speed) is
    /// passed unchanged to the ends, thanks to the odd padding.
    #[test]
    fn the_filter_delays_nothing_and_keeps_a_ramp() {
        let rate = 100.0;
        let filter = Butterworth2::low_pass(6.0, rate).expect("filter");
        let x = sine(2.0, rate, 1000);
        let y = filter.filtfilt(&x, 100);
        // The sine's crest at sample 12.5 + 50 k: the filtered one's largest samples are at
        // the same places.
        for k in 4..16 {
            let around = 50 * k + 5..50 * k + 20;
            let argmax = around
                .clone()
                .max_by(|&a, &b| y[a].total_cmp(&y[b]))
                .unwrap_or_default();
            assert!(argmax == 12 + 50 * k || argmax == 13 + 50 * k, "{argmax}");
        }
        let ramp: Vec<f64> = (0..300).map(|i| 0.01 * i as f64).collect();
        let y = filter.filtfilt(&ramp, 100);
        for (a, b) in ramp.iter().zip(&y) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
    }

    #[test]
    fn a_cutoff_at_or_above_nyquist_is_refused() {
        assert!(Butterworth2::low_pass(50.0, 100.0).is_none());
        assert!(Butterworth2::low_pass(0.0, 100.0).is_none());
        assert!(Butterworth2::low_pass(6.0, f64::NAN).is_none());
    }
}
