//! The one resampling of planar images between the camera's resolution and the network's:
//! the dataset's frames and targets for training, a camera's frame for inference, and the
//! network's masks back for the pose search all go through [`resample`].

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
    let (sx, sy) = (w as f64 / ow as f64, h as f64 / oh as f64);
    for p in 0..planes {
        let plane = &src[p * w * h..(p + 1) * w * h];
        for y in 0..oh {
            let fy = ((y as f64 + 0.5) * sy - 0.5).clamp(0.0, (h - 1) as f64);
            let (y0, ty) = (fy.floor() as usize, fy.fract() as f32);
            let y1 = (y0 + 1).min(h - 1);
            for x in 0..ow {
                let fx = ((x as f64 + 0.5) * sx - 0.5).clamp(0.0, (w - 1) as f64);
                let (x0, tx) = (fx.floor() as usize, fx.fract() as f32);
                let x1 = (x0 + 1).min(w - 1);
                let top = plane[y0 * w + x0] * (1.0 - tx) + plane[y0 * w + x1] * tx;
                let bottom = plane[y1 * w + x0] * (1.0 - tx) + plane[y1 * w + x1] * tx;
                out[p * ow * oh + y * ow + x] = top * (1.0 - ty) + bottom * ty;
            }
        }
    }
    out
}

/// Interleaved sRGB bytes (`width * height * 3`) as the network's planar input, `[3, h, w]`
/// in [0, 1].
#[must_use]
pub fn planar_rgb(rgb: &[u8], width: usize, height: usize) -> Vec<f32> {
    let n = width * height;
    let mut planar = vec![0.0f32; 3 * n];
    for (p, px) in rgb.chunks_exact(3).take(n).enumerate() {
        for c in 0..3 {
            planar[c * n + p] = f32::from(px[c]) / 255.0;
        }
    }
    planar
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn rgb_bytes_become_planes() {
        let rgb = [255, 0, 51, 0, 255, 102];
        let p = planar_rgb(&rgb, 2, 1);
        assert_eq!(p, vec![1.0, 0.0, 0.0, 1.0, 0.2, 0.4]);
    }
}
