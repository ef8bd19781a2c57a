//! Occlusion: artificial occluders that set pixels to black, and the occlusion of a part
//! measured from index renders.
//!
//! The occlusion of a part is its hidden pixels over all its pixels (visible plus hidden).
//! All its pixels come from the part rendered alone (its amodal mask); visible pixels from
//! the scene's index render (so other objects, such as the robot arm, occlude it naturally)
//! minus those under the artificial occluder.

use serde::{Deserialize, Serialize};

/// The camera-frame depth of an artificial occluder, m: a black object a quarter metre in
/// front of the lens. A depth camera sees the object there, not the scene behind it, so a
/// fit that reads depth can tell a hidden part from one that is absent, and cannot see
/// through the occluder.
pub const OCCLUDER_DEPTH_M: f32 = 0.25;

/// The shape of an artificial occluder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OccluderKind {
    /// An ellipse.
    Blob,
    /// A band across the whole image.
    Bar,
}

/// An occluder in image coordinates (pixels, centres at half-integers).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Occluder {
    pub kind: OccluderKind,
    /// Centre, px.
    pub centre_px: [f64; 2],
    /// Blob: the semi-axes; bar: half its width (the second value is unused), px.
    pub size_px: [f64; 2],
    /// Rotation of the shape, rad.
    pub angle_rad: f64,
}

impl Occluder {
    /// Whether pixel `(i, j)` (its centre) is covered.
    #[must_use]
    pub fn covers(&self, i: u32, j: u32) -> bool {
        let (dx, dy) = (
            f64::from(i) + 0.5 - self.centre_px[0],
            f64::from(j) + 0.5 - self.centre_px[1],
        );
        let (s, c) = self.angle_rad.sin_cos();
        let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
        match self.kind {
            OccluderKind::Blob => {
                let [a, b] = self.size_px;
                a > 0.0 && b > 0.0 && (u / a).powi(2) + (v / b).powi(2) <= 1.0
            }
            OccluderKind::Bar => v.abs() <= self.size_px[0],
        }
    }

    /// The same occluder scaled by `s` about its centre.
    #[must_use]
    pub fn scaled(&self, s: f64) -> Self {
        Self {
            size_px: self.size_px.map(|v| v * s),
            ..*self
        }
    }

    /// The occluder's mask (1 = covered) for a `width x height` image.
    #[must_use]
    pub fn mask(&self, width: u32, height: u32) -> Vec<u8> {
        let mut out = Vec::with_capacity(width as usize * height as usize);
        for j in 0..height {
            for i in 0..width {
                out.push(u8::from(self.covers(i, j)));
            }
        }
        out
    }
}

/// The pixel counts of one part in one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PartPixels {
    /// Pixels of the part rendered alone.
    pub amodal: u32,
    /// Pixels where the scene's index render shows the part.
    pub unoccluded: u32,
    /// Of those, the ones the artificial occluder leaves visible.
    pub visible: u32,
}

impl PartPixels {
    /// Counts: `amodal` and `shown` are per-pixel flags, `occluder` the occluder's mask.
    #[must_use]
    pub fn count(amodal: &[u8], shown: &[bool], occluder: &[u8]) -> Self {
        let mut p = Self::default();
        for ((&a, &s), &o) in amodal.iter().zip(shown).zip(occluder) {
            p.amodal += u32::from(a != 0);
            p.unoccluded += u32::from(s);
            p.visible += u32::from(s && o == 0);
        }
        p
    }

    /// Hidden over all pixels (natural and artificial occlusion), `None` if the part is not
    /// in view.
    #[must_use]
    pub fn occlusion(&self) -> Option<f64> {
        (self.amodal > 0)
            .then(|| 1.0 - f64::from(self.visible.min(self.amodal)) / f64::from(self.amodal))
    }

    /// Occlusion by other objects only (without the artificial occluder).
    #[must_use]
    pub fn natural_occlusion(&self) -> Option<f64> {
        (self.amodal > 0)
            .then(|| 1.0 - f64::from(self.unoccluded.min(self.amodal)) / f64::from(self.amodal))
    }
}

/// Scales `occluder` so that the part's occlusion comes as close to `target` as the
/// shape allows (to within one pixel's step), by bisection on the scale in `[0, max_scale]` (occlusion grows with the
/// scale because the shapes are nested). `amodal` and `shown` are the part's pixel flags in a
/// `width`-wide image. Returns the scaled occluder and the occlusion it gives.
#[must_use]
pub fn fit_occluder(
    occluder: &Occluder,
    target: f64,
    max_scale: f64,
    width: u32,
    amodal: &[u8],
    shown: &[bool],
) -> (Occluder, Option<f64>) {
    // Only the part's pixels matter: collect them once.
    let pixels: Vec<(u32, u32, bool)> = amodal
        .iter()
        .zip(shown)
        .enumerate()
        .filter(|(_, (a, _))| **a != 0)
        .map(|(p, (_, &s))| ((p as u32) % width, (p as u32) / width, s))
        .collect();
    let total = pixels.len();
    if total == 0 {
        return (occluder.scaled(0.0), None);
    }
    let occlusion = |o: &Occluder| {
        let visible = pixels
            .iter()
            .filter(|&&(i, j, s)| s && !o.covers(i, j))
            .count();
        1.0 - visible as f64 / total as f64
    };
    let (mut lo, mut hi) = (0.0, max_scale);
    if occlusion(&occluder.scaled(0.0)) >= target {
        return (occluder.scaled(0.0), Some(occlusion(&occluder.scaled(0.0))));
    }
    for _ in 0..30 {
        let mid = 0.5 * (lo + hi);
        if occlusion(&occluder.scaled(mid)) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    // The occlusion moves in steps of whole pixels: take the side of the step nearer the
    // target.
    let (below, above) = (occluder.scaled(lo), occluder.scaled(hi));
    let (ob, oa) = (occlusion(&below), occlusion(&above));
    if target - ob < oa - target {
        (below, Some(ob))
    } else {
        (above, Some(oa))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blob_area_approaches_the_ellipse_area() {
        // Pixel centres inside an ellipse of semi-axes 30 and 12 px: about pi a b.
        let o = Occluder {
            kind: OccluderKind::Blob,
            centre_px: [64.0, 64.0],
            size_px: [30.0, 12.0],
            angle_rad: 0.4,
        };
        let n: u32 = o.mask(128, 128).iter().map(|&v| u32::from(v)).sum();
        let area = std::f64::consts::PI * 30.0 * 12.0;
        assert!((f64::from(n) - area).abs() < 0.03 * area, "{n} vs {area}");
    }

    #[test]
    fn a_horizontal_bar_covers_whole_rows() {
        let o = Occluder {
            kind: OccluderKind::Bar,
            centre_px: [10.0, 20.0],
            size_px: [3.0, 0.0],
            angle_rad: 0.0,
        };
        let m = o.mask(50, 40);
        // Rows whose centre is within 3 px of y = 20: 17.5 ..= 22.5, rows 17 to 22.
        for j in 0..40 {
            let covered = m[j * 50..(j + 1) * 50].iter().all(|&v| v == 1);
            let empty = m[j * 50..(j + 1) * 50].iter().all(|&v| v == 0);
            assert!(
                if (17..=22).contains(&j) {
                    covered
                } else {
                    empty
                },
                "row {j}"
            );
        }
    }

    #[test]
    fn fitted_occlusion_hits_the_target() {
        // A 40 x 10 px part, fully shown; a blob over its middle.
        let (w, h) = (64u32, 64u32);
        let mut amodal = vec![0u8; (w * h) as usize];
        for j in 27..37 {
            for i in 12..52 {
                amodal[(j * w + i) as usize] = 1;
            }
        }
        let shown: Vec<bool> = amodal.iter().map(|&a| a != 0).collect();
        let o = Occluder {
            kind: OccluderKind::Blob,
            centre_px: [32.0, 32.0],
            size_px: [1.0, 1.0],
            angle_rad: 0.0,
        };
        for target in [0.1, 0.5, 0.9] {
            let (fitted, got) = fit_occluder(&o, target, 200.0, w, &amodal, &shown);
            let got = got.expect("in view");
            // 400 pixels: one more pixel is 0.25 %, a ring of the blob a few pixels.
            assert!((got - target).abs() < 0.03, "target {target} got {got}");
            let counts = PartPixels::count(&amodal, &shown, &fitted.mask(w, h));
            assert_eq!(counts.occlusion(), Some(got));
        }
    }

    #[test]
    fn a_part_out_of_view_has_no_occlusion() {
        let p = PartPixels::count(&[0, 0], &[false, false], &[1, 0]);
        assert_eq!(p.occlusion(), None);
        assert_eq!(p.natural_occlusion(), None);
    }
}
