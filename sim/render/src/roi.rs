//! What the network reads of a camera's frame: a square region of interest ([`Roi`]) and the
//! one resampling of images between resolutions ([`resample`]). The dataset's frames, the
//! network's training targets, a camera's frame at inference and the network's masks on their
//! way back to the pose search all go through [`resample`].
//!
//! A region is whole pixels of the camera's frame; [`Roi::camera`] is the pinhole camera that
//! sees exactly that region at the network's input size, so the pose search renders the crop
//! directly (as render-and-compare refiners crop around the object).

use serde::{Deserialize, Serialize};
use workcell_robots::math::Vector;

use crate::camera::Camera;
use crate::error::Result;

/// Resamples `planes` planes of `w x h` (row-major, one plane after another) to `ow x oh`,
/// pixel centres aligned:
///
/// - the same size: a copy;
/// - smaller in both directions: each output pixel is the mean of the input area it covers
///   (a box filter; at an integer factor `f`, the mean of each `f x f` block);
/// - otherwise: bilinear interpolation, edges repeated.
///
/// # Panics
/// If `src` holds fewer than `planes * w * h` values, or a size is zero while another is not.
#[must_use]
pub fn resample(src: &[f32], planes: usize, w: usize, h: usize, ow: usize, oh: usize) -> Vec<f32> {
    assert!(
        src.len() >= planes * w * h,
        "resample: image smaller than its size"
    );
    if (w, h) == (ow, oh) {
        return src[..planes * w * h].to_vec();
    }
    if ow <= w && oh <= h {
        if w.is_multiple_of(ow) && h.is_multiple_of(oh) && w / ow == h / oh {
            return block_mean(src, planes, w, h, w / ow);
        }
        return area_mean(src, planes, w, h, ow, oh);
    }
    bilinear(src, planes, w, h, ow, oh)
}

/// The mean of each `f x f` block.
fn block_mean(src: &[f32], planes: usize, w: usize, h: usize, f: usize) -> Vec<f32> {
    let (oh, ow) = (h / f, w / f);
    let mut out = vec![0f32; planes * oh * ow];
    let scale = 1.0 / (f * f) as f32;
    for p in 0..planes {
        for y in 0..oh {
            for x in 0..ow {
                let mut sum = 0f32;
                for dy in 0..f {
                    let row = &src[(p * h + y * f + dy) * w + x * f..][..f];
                    sum += row.iter().sum::<f32>();
                }
                out[(p * oh + y) * ow + x] = sum * scale;
            }
        }
    }
    out
}

/// The overlap of output pixel `k` (of `n` over a length of `m` input pixels) with each input
/// pixel: `(first input pixel, weights)`, weights summing to 1.
fn footprint(k: usize, m: usize, n: usize) -> (usize, Vec<f64>) {
    let scale = m as f64 / n as f64;
    let (lo, hi) = (k as f64 * scale, (k + 1) as f64 * scale);
    let first = lo.floor() as usize;
    let last = (hi.ceil() as usize).min(m);
    let weights = (first..last)
        .map(|i| ((i + 1) as f64).min(hi) - (i as f64).max(lo))
        .map(|overlap| overlap / scale)
        .collect();
    (first, weights)
}

/// Box filter at any ratio (output no larger than input in either direction).
fn area_mean(src: &[f32], planes: usize, w: usize, h: usize, ow: usize, oh: usize) -> Vec<f32> {
    let xs: Vec<_> = (0..ow).map(|x| footprint(x, w, ow)).collect();
    let ys: Vec<_> = (0..oh).map(|y| footprint(y, h, oh)).collect();
    let mut out = vec![0f32; planes * ow * oh];
    for p in 0..planes {
        let plane = &src[p * w * h..(p + 1) * w * h];
        for (y, (y0, wy)) in ys.iter().enumerate() {
            for (x, (x0, wx)) in xs.iter().enumerate() {
                let mut sum = 0.0;
                for (dy, a) in wy.iter().enumerate() {
                    let row = &plane[(y0 + dy) * w + x0..];
                    for (dx, b) in wx.iter().enumerate() {
                        sum += a * b * f64::from(row[dx]);
                    }
                }
                out[(p * oh + y) * ow + x] = sum as f32;
            }
        }
    }
    out
}

/// Bilinear interpolation at the output's pixel centres.
fn bilinear(src: &[f32], planes: usize, w: usize, h: usize, ow: usize, oh: usize) -> Vec<f32> {
    let mut out = vec![0.0; planes * ow * oh];
    // Each output column's (and row's) two input pixels and weight, once for every plane.
    let taps = |n_out: usize, n_in: usize| -> Vec<(usize, usize, f32)> {
        let scale = n_in as f64 / n_out as f64;
        (0..n_out)
            .map(|k| {
                let f = ((k as f64 + 0.5) * scale - 0.5).clamp(0.0, (n_in - 1) as f64);
                let i0 = f.floor() as usize;
                (i0, (i0 + 1).min(n_in - 1), f.fract() as f32)
            })
            .collect()
    };
    let (xs, ys) = (taps(ow, w), taps(oh, h));
    for (plane, out) in src.chunks_exact(w * h).zip(out.chunks_exact_mut(ow * oh)) {
        for (&(y0, y1, ty), out) in ys.iter().zip(out.chunks_exact_mut(ow)) {
            let (r0, r1) = (&plane[y0 * w..][..w], &plane[y1 * w..][..w]);
            for (&(x0, x1, tx), out) in xs.iter().zip(out) {
                let top = r0[x0] * (1.0 - tx) + r0[x1] * tx;
                let bottom = r1[x0] * (1.0 - tx) + r1[x1] * tx;
                *out = top * (1.0 - ty) + bottom * ty;
            }
        }
    }
    out
}

/// The workspace crop's margin: the reach sphere's silhouette grown by 10 %.
pub const WORKSPACE_MARGIN: f64 = 1.1;

/// The tracked crop: the box around the arm's joints grown by a factor in this range (the
/// dataset draws one per sequence, a tracker takes the middle) ...
pub const TRACKED_MARGIN: [f64; 2] = [1.3, 1.8];

/// ... and at least this wide at the elbow's depth, m.
pub const TRACKED_MIN_M: f64 = 0.5;

/// How a region of interest was chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RoiKind {
    /// Fixed for a camera: the sphere the forearm can reach (around the shoulder), projected,
    /// with a margin. Used when there is no estimate to follow.
    Workspace,
    /// Around the last estimate of the arm, with a margin.
    Tracked,
    /// The whole frame (datasets written before regions of interest).
    Frame,
}

impl RoiKind {
    /// Lower-case name as in files.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            RoiKind::Workspace => "workspace",
            RoiKind::Tracked => "tracked",
            RoiKind::Frame => "frame",
        }
    }
}

/// A square region of a camera's frame in whole pixels: columns `x0..x0 + size`, rows
/// `y0..y0 + size`. It may reach past the frame's edges; a camera sees black there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Roi {
    pub x0: i64,
    pub y0: i64,
    pub size: u32,
}

impl Roi {
    /// The square of side `side_px` (rounded, at least 1 px) centred at `centre_px`.
    #[must_use]
    pub fn square(centre_px: [f64; 2], side_px: f64) -> Self {
        let size = side_px
            .round()
            .clamp(1.0, f64::from(crate::camera::MAX_SIDE_PX));
        Self {
            x0: (centre_px[0] - size / 2.0).round() as i64,
            y0: (centre_px[1] - size / 2.0).round() as i64,
            size: size as u32,
        }
    }

    /// The smallest square that holds the bounding box of `points_px`, grown by `margin`
    /// (1.5: half as large again), at least `min_px` wide; `None` without points.
    #[must_use]
    pub fn around(points_px: &[[f64; 2]], margin: f64, min_px: f64) -> Option<Self> {
        let first = points_px.first()?;
        let (mut lo, mut hi) = (*first, *first);
        for p in points_px {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
        let side = ((hi[0] - lo[0]).max(hi[1] - lo[1]) * margin).max(min_px);
        Some(Self::square(
            [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
            side,
        ))
    }

    /// The square around a sphere of `radius_m` at `p_W` as `camera` sees it, grown by
    /// `margin`, shifted into the frame where it fits; `None` when the sphere's centre is
    /// not in front of the camera.
    #[must_use]
    pub fn of_sphere(camera: &Camera, p_W: Vector, radius_m: f64, margin: f64) -> Option<Self> {
        let p_C = camera.X_WC.inverse() * p_W;
        let centre = camera.project(p_C)?;
        // The silhouette's half-width seen from distance d: f r / sqrt(d^2 - r^2) (the
        // cone tangent to the sphere), at least f r / z on the optical axis.
        let d = p_C.length();
        let half = if d > radius_m {
            camera.fx.max(camera.fy) * radius_m / (d * d - radius_m * radius_m).sqrt()
        } else {
            f64::from(camera.width.max(camera.height))
        };
        Some(Self::square(centre, 2.0 * half * margin).shifted_into(camera.width, camera.height))
    }

    /// The tracked crop: the square around the projections of the arm's `joints_W`
    /// (shoulder, elbow, wrist) grown by `margin`, at least `min_m` wide at the depth of the
    /// second joint (the elbow); `None` when no joint is in front of the camera.
    #[must_use]
    pub fn of_joints(
        camera: &Camera,
        joints_W: &[Vector],
        margin: f64,
        min_m: f64,
    ) -> Option<Self> {
        let X_CW = camera.X_WC.inverse();
        let points: Vec<[f64; 2]> = joints_W
            .iter()
            .filter_map(|p| camera.project(X_CW * *p))
            .collect();
        let anchor = joints_W.get(1).or(joints_W.first())?;
        let depth = (X_CW * *anchor).z.max(crate::NEAR_M);
        Self::around(&points, margin, camera.fy * min_m / depth)
    }

    /// The same square moved (not resized) to lie inside a `width x height` frame along each
    /// axis where it fits, centred on that axis where it does not.
    #[must_use]
    pub fn shifted_into(self, width: u32, height: u32) -> Self {
        let fit = |x0: i64, extent: u32| {
            let (extent, size) = (i64::from(extent), i64::from(self.size));
            if size <= extent {
                x0.clamp(0, extent - size)
            } else {
                (extent - size) / 2
            }
        };
        Self {
            x0: fit(self.x0, width),
            y0: fit(self.y0, height),
            size: self.size,
        }
    }

    /// The whole of a `width x height` frame when it is square; otherwise the centred square
    /// of the shorter side.
    #[must_use]
    pub fn frame(width: u32, height: u32) -> Self {
        let size = width.min(height);
        Self {
            x0: i64::from((width - size) / 2),
            y0: i64::from((height - size) / 2),
            size,
        }
    }

    /// Whether the image point `p_px` (x right, y down, pixel edges at integers) lies in the
    /// region: columns `x0 <= x < x0 + size`, rows likewise.
    #[must_use]
    pub fn contains(&self, p_px: [f64; 2]) -> bool {
        let side = f64::from(self.size);
        let inside = |v: f64, lo: i64| v >= lo as f64 && v < lo as f64 + side;
        inside(p_px[0], self.x0) && inside(p_px[1], self.y0)
    }

    /// The camera that sees exactly this region at `out_px x out_px` pixels (the region's
    /// pixels scaled by `out_px / size`).
    ///
    /// # Errors
    /// [`crate::RenderError::InvalidRender`] for a size of 0 or above the camera limit.
    pub fn camera(&self, camera: &Camera, out_px: u32) -> Result<Camera> {
        let s = f64::from(out_px) / f64::from(self.size);
        let crop = Camera {
            width: out_px,
            height: out_px,
            fx: camera.fx * s,
            fy: camera.fy * s,
            cx: (camera.cx - self.x0 as f64) * s,
            cy: (camera.cy - self.y0 as f64) * s,
            X_WC: camera.X_WC,
        };
        crop.validate()?;
        Ok(crop)
    }

    /// Copies the region out of `planes` planes of a `width x height` image (zero where it
    /// reaches past the edges), `planes x size x size`.
    #[must_use]
    pub fn crop(&self, src: &[f32], planes: usize, width: usize, height: usize) -> Vec<f32> {
        let size = self.size as usize;
        let mut out = vec![0f32; planes * size * size];
        let x_lo = self.x0.max(0) as usize;
        let x_hi = (self.x0 + size as i64).clamp(0, width as i64) as usize;
        if x_lo >= x_hi {
            return out;
        }
        for p in 0..planes {
            for y in 0..size {
                let sy = self.y0 + y as i64;
                if sy < 0 || sy >= height as i64 {
                    continue;
                }
                let row = &src[(p * height + sy as usize) * width..][..width];
                let dst = &mut out[(p * size + y) * size..][..size];
                let ox = (x_lo as i64 - self.x0) as usize;
                dst[ox..ox + (x_hi - x_lo)].copy_from_slice(&row[x_lo..x_hi]);
            }
        }
        out
    }

    /// The region of a one-plane `width x height` image at `out_px x out_px`, each output
    /// pixel the source pixel under its centre (0 past the edges): for images whose values
    /// must not be mixed, such as depth, where the mean of a surface and of "no surface" (0)
    /// is a depth nothing has.
    #[must_use]
    pub fn sample_nearest(
        &self,
        src: &[f32],
        width: usize,
        height: usize,
        out_px: usize,
    ) -> Vec<f32> {
        let scale = f64::from(self.size) / out_px.max(1) as f64;
        let at = |i: usize, origin: i64| origin + ((i as f64 + 0.5) * scale).floor() as i64;
        let mut out = vec![0f32; out_px * out_px];
        for (y, row) in out.chunks_exact_mut(out_px.max(1)).enumerate() {
            let sy = at(y, self.y0);
            if sy < 0 || sy >= height as i64 {
                continue;
            }
            for (x, v) in row.iter_mut().enumerate() {
                let sx = at(x, self.x0);
                if sx >= 0 && sx < width as i64 {
                    *v = src[sy as usize * width + sx as usize];
                }
            }
        }
        out
    }

    /// The region of `planes` planes of a `width x height` image at the network's input size:
    /// [`Roi::crop`] then [`resample`] to `out_px x out_px`.
    #[must_use]
    pub fn resample(
        &self,
        src: &[f32],
        planes: usize,
        width: usize,
        height: usize,
        out_px: usize,
    ) -> Vec<f32> {
        let size = self.size as usize;
        resample(
            &self.crop(src, planes, width, height),
            planes,
            size,
            size,
            out_px,
            out_px,
        )
    }
}

/// What a mask of `w x h` pixels keeps at a network input of `iw x ih`, measured on the mask
/// itself: a perfect network sees the truth averaged to the input grid, its output is
/// resampled back (bilinearly) and thresholded at one half. Returns the Dice loss of that
/// against the truth (`1 - 2|A and B| / (|A| + |B|)`), `None` for an empty mask.
#[must_use]
pub fn perfect_dice_loss(mask: &[u8], w: usize, h: usize, iw: usize, ih: usize) -> Option<f64> {
    let truth: Vec<f32> = mask.iter().map(|&v| f32::from(u8::from(v != 0))).collect();
    let n_truth = truth.iter().filter(|&&v| v > 0.0).count();
    if n_truth == 0 {
        return None;
    }
    let back = resample(&resample(&truth, 1, w, h, iw, ih), 1, iw, ih, w, h);
    let (mut both, mut n_back) = (0usize, 0usize);
    for (t, b) in truth.iter().zip(&back) {
        if *b >= 0.5 {
            n_back += 1;
            if *t > 0.0 {
                both += 1;
            }
        }
    }
    Some(1.0 - 2.0 * both as f64 / (n_truth + n_back) as f64)
}

/// The width of a mask's shape in pixels: `sqrt(12 l)` for the smaller eigenvalue `l` of the
/// covariance of its pixel centres (a `L x W` rectangle gives `W`, a thin limb its mean
/// width); `None` for fewer than two pixels.
#[must_use]
pub fn mask_width(mask: &[u8], w: usize) -> Option<f64> {
    let (mut n, mut sx, mut sy) = (0.0, 0.0, 0.0);
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for (p, _) in mask.iter().enumerate().filter(|(_, v)| **v != 0) {
        let (x, y) = ((p % w) as f64, (p / w) as f64);
        n += 1.0;
        sx += x;
        sy += y;
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
    }
    if n < 2.0 {
        return None;
    }
    let (mx, my) = (sx / n, sy / n);
    // Pixels are unit squares: each adds 1/12 of variance along both axes.
    let (a, b, c) = (
        sxx / n - mx * mx + 1.0 / 12.0,
        syy / n - my * my + 1.0 / 12.0,
        sxy / n - mx * my,
    );
    let small = 0.5 * (a + b) - (0.25 * (a - b) * (a - b) + c * c).sqrt();
    Some((12.0 * small.max(0.0)).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A region holds its first column and row and not the pixel edge one side past its last.
    #[test]
    fn a_region_holds_its_pixels_and_no_more() {
        let r = Roi {
            x0: 10,
            y0: -4,
            size: 8,
        };
        assert!(r.contains([10.0, -4.0]));
        assert!(r.contains([17.99, 3.99]));
        assert!(!r.contains([18.0, 0.0]));
        assert!(!r.contains([12.0, 4.0]));
        assert!(!r.contains([9.99, 0.0]));
        assert!(!r.contains([12.0, -4.01]));
    }
    use workcell_robots::math::Pose;

    #[test]
    fn an_integer_factor_averages_blocks() {
        let src: Vec<f32> = (0..16).map(|v| v as f32).collect();
        // 2x2 blocks of a 4x4 ramp: (0+1+4+5)/4 = 2.5, ...
        assert_eq!(resample(&src, 1, 4, 4, 2, 2), vec![2.5, 4.5, 10.5, 12.5]);
    }

    #[test]
    fn any_ratio_keeps_constants_and_the_mean() {
        let src = vec![0.25f32; 2 * 10 * 7];
        let out = resample(&src, 2, 10, 7, 4, 3);
        assert!(out.iter().all(|v| (v - 0.25).abs() < 1e-6), "{out:?}");
        // 10 -> 4 columns: each output pixel covers 2.5 input pixels, pixel i holding i.
        // The first covers pixels 0 and 1 and half of 2: (0 + 1 + 2 / 2) / 2.5 = 0.8.
        let ramp: Vec<f32> = (0..10).map(|v| v as f32).collect();
        let out = resample(&ramp, 1, 10, 1, 4, 1);
        let expected = [0.8, 3.2, 5.8, 8.2];
        for (o, e) in out.iter().zip(expected) {
            assert!((o - e).abs() < 1e-5, "{out:?}");
        }
        // The image's mean is kept.
        assert!((out.iter().sum::<f32>() / 4.0 - 4.5).abs() < 1e-5);
    }

    /// Nearest sampling takes the pixel under each output pixel's centre and never mixes
    /// values: a 4x4 region of a 6x6 image at 2x2 reads pixels (x0 + 1, y0 + 1) and
    /// (x0 + 3, y0 + 3) in each direction; past the edges it reads 0.
    #[test]
    fn nearest_sampling_takes_the_pixel_under_each_centre() {
        let src: Vec<f32> = (0..36).map(|v| v as f32).collect();
        let roi = Roi {
            x0: 1,
            y0: 0,
            size: 4,
        };
        // Centres at 1 + 1 = 2 and 1 + 3 = 4 across, 1 and 3 down.
        assert_eq!(
            roi.sample_nearest(&src, 6, 6, 2),
            vec![8.0, 10.0, 20.0, 22.0]
        );
        // At its own size it is the crop.
        assert_eq!(roi.sample_nearest(&src, 6, 6, 4), roi.crop(&src, 1, 6, 6));
        // A region half past the left and top edges reads 0 there.
        let out = Roi {
            x0: -2,
            y0: -2,
            size: 4,
        }
        .sample_nearest(&src, 6, 6, 4);
        assert_eq!(&out[..2], &[0.0, 0.0]);
        assert_eq!(out[2 * 4 + 3], 1.0);
        assert_eq!(out[3 * 4 + 3], 7.0);
    }

    #[test]
    fn upsampling_is_bilinear_at_pixel_centres() {
        let flat = vec![0.25f32; 2 * 4 * 4];
        assert!(
            resample(&flat, 2, 4, 4, 8, 8)
                .iter()
                .all(|v| (v - 0.25).abs() < 1e-6)
        );
        // A ramp 0, 1, 2, 3 across: output centres at input x = (i + 0.5) / 2 - 0.5.
        let ramp: Vec<f32> = (0..16).map(|i| (i % 4) as f32).collect();
        let up = resample(&ramp, 1, 4, 4, 8, 8);
        let row: Vec<f32> = up[..8].to_vec();
        assert_eq!(row, vec![0.0, 0.25, 0.75, 1.25, 1.75, 2.25, 2.75, 3.0]);
    }

    #[test]
    fn a_crop_copies_whole_pixels_and_blackens_outside() {
        // 4x3 image, pixel value = 10 y + x.
        let src: Vec<f32> = (0..12).map(|p| (10 * (p / 4) + p % 4) as f32).collect();
        let roi = Roi {
            x0: 2,
            y0: -1,
            size: 3,
        };
        assert_eq!(
            roi.crop(&src, 1, 4, 3),
            vec![0.0, 0.0, 0.0, 2.0, 3.0, 0.0, 12.0, 13.0, 0.0]
        );
        assert_eq!(
            Roi::frame(4, 3),
            Roi {
                x0: 0,
                y0: 0,
                size: 3
            }
        );
        assert_eq!(
            roi.shifted_into(4, 3),
            Roi {
                x0: 1,
                y0: 0,
                size: 3
            }
        );
    }

    #[test]
    fn the_crop_camera_projects_where_the_crop_puts_the_pixel() {
        let camera = Camera::look_at(
            [2.0, 0.3, 1.0],
            [0.0, 0.0, 0.5],
            [0.0, 0.0, 1.0],
            640,
            480,
            40.0,
        )
        .unwrap();
        let roi = Roi {
            x0: 250,
            y0: 100,
            size: 200,
        };
        let crop = roi.camera(&camera, 100).unwrap();
        let p_C = camera.X_WC.inverse() * Vector::new(0.1, -0.05, 0.6);
        let [u, v] = camera.project(p_C).unwrap();
        let [cu, cv] = crop.project(p_C).unwrap();
        assert!((cu - (u - 250.0) / 2.0).abs() < 1e-9 && (cv - (v - 100.0) / 2.0).abs() < 1e-9);
        assert_eq!(crop.X_WC, Pose { ..camera.X_WC });
    }

    #[test]
    fn a_sphere_on_the_axis_spans_its_tangent_cone() {
        let camera = Camera::look_at(
            [0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0],
            1000,
            1000,
            60.0,
        )
        .unwrap();
        // Radius 0.3 at 5 m: half-width f r / sqrt(d^2 - r^2).
        let roi = Roi::of_sphere(&camera, Vector::new(0.0, 0.0, 5.0), 0.3, 1.0).unwrap();
        let expected = 2.0 * camera.fx * 0.3 / (25.0f64 - 0.09).sqrt();
        assert!(
            (f64::from(roi.size) - expected).abs() <= 0.5,
            "{roi:?} vs {expected}"
        );
        assert!(Roi::of_sphere(&camera, Vector::new(0.0, 0.0, -5.0), 0.3, 1.0).is_none());
    }

    #[test]
    fn a_wide_bar_survives_the_perfect_network_and_a_thin_one_does_not() {
        // A 64 x 8 bar in a 64 x 64 mask, at 16 x 16: 2 px wide on the grid, edges aligned
        // to it, so averaging and coming back keeps it exactly.
        let bar = |w0: usize, w1: usize| -> Vec<u8> {
            (0..64 * 64)
                .map(|p| u8::from((w0..w1).contains(&(p / 64))))
                .collect()
        };
        assert!(perfect_dice_loss(&bar(24, 32), 64, 64, 16, 16).unwrap() < 1e-9);
        // A 2 px bar at 16 x 16 is half a pixel there: nothing comes back.
        assert!((perfect_dice_loss(&bar(24, 26), 64, 64, 16, 16).unwrap() - 1.0).abs() < 1e-9);
        assert_eq!(perfect_dice_loss(&[0; 16], 4, 4, 2, 2), None);
        // The width of an 8-row bar is 8.
        assert!((mask_width(&bar(24, 32), 64).unwrap() - 8.0).abs() < 1e-9);
    }
}
