//! Mask operations of the search: the paper's `f_m`, dilation, support and blobs.

use workcell_render::Camera;

/// The camera that sees the `width x height` region of `camera`'s image whose top-left pixel
/// is `(x0, y0)`.
pub(super) fn crop_camera(
    camera: &Camera,
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
) -> Camera {
    Camera {
        width: width as u32,
        height: height as u32,
        cx: camera.cx - x0 as f64,
        cy: camera.cy - y0 as f64,
        ..*camera
    }
}

/// The mask's support: pixel count, centroid and second moments, bounding box.
#[derive(Debug, Clone, Copy)]
pub(super) struct Support {
    pub(super) centroid: [f64; 2],
    pub(super) cov: [f64; 3],
    pub(super) lo: [usize; 2],
    pub(super) hi: [usize; 2],
}

/// The coarse-to-fine schedule: (dilation radius in px, supersampled render). The forearm
/// is one or two pixels thick, so the exact score is flat beyond a pixel of misalignment:
/// comparing dilated masks first widens the basin the climb can see, and pixel coverage
/// makes the score change with sub-pixel motion. Coverage favours thin (far) renders a
/// little (a covered fraction outside a point-sampled mask counts against it), so the last
/// level is the paper's own comparison of point-sampled masks.
pub(super) const LEVELS: [(usize, bool); 4] = [(2, true), (1, true), (0, true), (0, false)];

/// Grey-scale dilation (a `(2r+1)^2` maximum) of a row-major image of width `w`.
pub(super) fn dilate(src: &[f32], w: usize, r: usize) -> Vec<f32> {
    if r == 0 || w == 0 {
        return src.to_vec();
    }
    let h = src.len() / w;
    let mut rows = vec![0.0f32; src.len()];
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (x.saturating_sub(r), (x + r).min(w - 1));
            rows[y * w + x] = src[y * w + a..=y * w + b]
                .iter()
                .fold(0.0, |m, &v| m.max(v));
        }
    }
    let mut out = vec![0.0f32; src.len()];
    for y in 0..h {
        let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
        for x in 0..w {
            out[y * w + x] = (a..=b).map(|yy| rows[yy * w + x]).fold(0.0, f32::max);
        }
    }
    out
}

/// Candidates are rendered at this many samples per pixel side and compared by the covered
/// fraction of each pixel: `f_m` then changes with sub-pixel motion instead of in steps of
/// whole pixels, which the numerical gradient needs on a forearm one or two pixels thick.
pub(super) const SUPERSAMPLE: u32 = 3;

/// The paper's agreement of a mask `m` (values in [0, 1]) and a binary mask `mhat` (0 or
/// not 0) of the same size: `sum 4 (m - 1/2)(mhat - 1/2) / (w h)`, in [-1, 1]. For two
/// binary masks it is `1 - 2 x` the fraction of pixels where they differ.
#[must_use]
pub fn f_m(m: &[f32], mhat: &[u8]) -> f64 {
    let n = m.len().min(mhat.len());
    if n == 0 {
        return 0.0;
    }
    let sum: f64 = m
        .iter()
        .zip(mhat)
        .map(|(&m, &r)| {
            let r = if r != 0 { 0.5 } else { -0.5 };
            4.0 * (f64::from(m) - 0.5) * r
        })
        .sum();
    sum / n as f64
}

/// The support of `mask` above `threshold` (`None` when empty).
pub(super) fn support(mask: &[f32], width: usize, threshold: f32) -> Option<Support> {
    let (mut n, mut sx, mut sy, mut sxx, mut sxy, mut syy) = (0usize, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut lo, mut hi) = ([usize::MAX; 2], [0usize; 2]);
    for (p, _) in mask.iter().enumerate().filter(|(_, v)| **v > threshold) {
        let (x, y) = (p % width, p / width);
        let (fx, fy) = (x as f64 + 0.5, y as f64 + 0.5);
        n += 1;
        sx += fx;
        sy += fy;
        sxx += fx * fx;
        sxy += fx * fy;
        syy += fy * fy;
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    }
    if n == 0 {
        return None;
    }
    let k = n as f64;
    let (mx, my) = (sx / k, sy / k);
    Some(Support {
        centroid: [mx, my],
        // Plus a pixel's own variance (1/12), so a single pixel is not a point.
        cov: [
            sxx / k - mx * mx + 1.0 / 12.0,
            sxy / k - mx * my,
            syy / k - my * my + 1.0 / 12.0,
        ],
        lo,
        hi,
    })
}

/// The number of 8-connected blobs above `threshold` with at least a fifth of the largest
/// one's pixels.
pub(super) fn blobs(mask: &[f32], width: usize, threshold: f32) -> usize {
    let height = mask.len() / width.max(1);
    let mut label = vec![0u32; mask.len()];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..mask.len() {
        if mask[start] <= threshold || label[start] != 0 {
            continue;
        }
        sizes.push(0usize);
        let id = sizes.len() as u32;
        label[start] = id;
        stack.push(start);
        while let Some(p) = stack.pop() {
            sizes[id as usize - 1] += 1;
            let (x, y) = ((p % width) as isize, (p / width) as isize);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= width as isize || ny >= height as isize {
                        continue;
                    }
                    let q = ny as usize * width + nx as usize;
                    if mask[q] > threshold && label[q] == 0 {
                        label[q] = id;
                        stack.push(q);
                    }
                }
            }
        }
    }
    let largest = sizes.iter().copied().max().unwrap_or(0);
    sizes.iter().filter(|&&s| 5 * s >= largest).count()
}
