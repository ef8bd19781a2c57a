//! Images for the network: [`resample`] (the one resampling between resolutions, shared
//! with the dataset through `workcell_render::roi`) and interleaved bytes as planes.

pub use workcell_render::roi::{Roi, resample};

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

/// The square `roi` of an interleaved sRGB frame (`width x height`) as planar values in
/// [0, 1], `3 x size x size`, black past the frame's edges: [`planar_rgb`] then
/// [`workcell_render::roi::Roi::crop`], without converting the pixels outside the square.
#[must_use]
pub fn planar_rgb_crop(
    rgb: &[u8],
    width: usize,
    height: usize,
    roi: &workcell_render::roi::Roi,
) -> Vec<f32> {
    let size = roi.size as usize;
    let n = size * size;
    let mut planar = vec![0.0f32; 3 * n];
    for y in 0..size {
        let sy = roi.y0 + y as i64;
        if sy < 0 || sy >= height as i64 {
            continue;
        }
        for x in 0..size {
            let sx = roi.x0 + x as i64;
            if sx < 0 || sx >= width as i64 {
                continue;
            }
            let i = 3 * (sy as usize * width + sx as usize);
            if let Some(px) = rgb.get(i..i + 3) {
                for c in 0..3 {
                    planar[c * n + y * size + x] = f32::from(px[c]) / 255.0;
                }
            }
        }
    }
    planar
}

/// Metres of depth across the depth plane's range ([`depth_plane`]): one metre either side
/// of the region's middle, enough for an arm reaching towards or away from the camera.
pub const DEPTH_PLANE_SPAN_M: f32 = 2.0;

/// A depth image (camera-frame z, m; 0 or not finite where the camera has none) as the fourth
/// input plane of a network that reads depth (`ProcNetConfig::reads_depth`), in [0, 1]:
/// 0.5 at the median depth of the image's central half (the region of interest is centred
/// on the arm, so this is the human's depth, not the wall's), brighter nearer, by
/// 1 / [`DEPTH_PLANE_SPAN_M`] per metre, clamped; 0 where there is no depth, or everywhere
/// when the central half has none. Relative depth does not change with the camera's
/// distance, which the network's three distance classes span from 1.5 to 10 m.
#[must_use]
pub fn depth_plane(depth_m: &[f32], width: usize, height: usize) -> Vec<f32> {
    let valid = |d: f32| d.is_finite() && d > 0.0;
    let mut centre: Vec<f32> = (height / 4..height - height / 4)
        .flat_map(|y| (width / 4..width - width / 4).map(move |x| (x, y)))
        .filter_map(|(x, y)| depth_m.get(y * width + x).copied())
        .filter(|&d| valid(d))
        .collect();
    if centre.is_empty() {
        return vec![0.0; width * height];
    }
    let mid = centre.len() / 2;
    let (_, &mut middle, _) = centre.select_nth_unstable_by(mid, f32::total_cmp);
    depth_m
        .iter()
        .take(width * height)
        .map(|&d| {
            if valid(d) {
                (0.5 + (middle - d) / DEPTH_PLANE_SPAN_M).clamp(0.0, 1.0)
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 0.5 at the central half's median, 1 / span per metre nearer brighter, clamped, 0
    /// without depth; the border ring does not move the reference.
    #[test]
    fn depth_plane_is_relative_to_the_centre() {
        // 4x4: the central 2x2 at 3, 3, 4, 5 m (median: the upper middle, 4 m); the ring
        // far (wall at 20 m), near (0.5 m: clamped at 1) or without depth.
        let d: Vec<f32> = [
            [20.0, 20.0, 0.0, f32::NAN],
            [0.5, 3.0, 3.0, 20.0],
            [4.5, 4.0, 5.0, 20.0],
            [20.0, 20.0, 20.0, 20.0],
        ]
        .concat();
        let p = depth_plane(&d, 4, 4);
        let v = |d: f32| 0.5 + (4.0 - d) / DEPTH_PLANE_SPAN_M;
        assert_eq!(p[5], v(3.0));
        assert_eq!(p[9], 0.5);
        assert_eq!(p[10], v(5.0));
        assert_eq!(p[8], v(4.5));
        assert_eq!(p[4], 1.0);
        assert_eq!(p[0], 0.0);
        assert_eq!(p[2], 0.0);
        assert_eq!(p[3], 0.0);
        // The same scene 5 m further away gives the same plane.
        let far: Vec<f32> = d
            .iter()
            .map(|&x| if x > 0.0 { x + 5.0 } else { x })
            .collect();
        let pf = depth_plane(&far, 4, 4);
        for (a, b) in p.iter().zip(&pf).skip(5).take(6) {
            assert!((a - b).abs() < 1e-6, "{a} {b}");
        }
        // No depth in the centre: nothing to be relative to.
        let mut blind = d.clone();
        for i in [5, 6, 9, 10] {
            blind[i] = 0.0;
        }
        assert_eq!(depth_plane(&blind, 4, 4), vec![0.0; 16]);
    }

    /// The direct crop is the whole frame's conversion cropped, inside and past the edges.
    #[test]
    fn cropping_the_frame_first_gives_the_same_planes() {
        let (w, h) = (7, 5);
        let rgb: Vec<u8> = (0..w * h * 3).map(|v| (v * 7 % 256) as u8).collect();
        for roi in [
            workcell_render::roi::Roi {
                x0: 1,
                y0: 1,
                size: 3,
            },
            workcell_render::roi::Roi {
                x0: -2,
                y0: 3,
                size: 4,
            },
        ] {
            assert_eq!(
                planar_rgb_crop(&rgb, w, h, &roi),
                roi.crop(&planar_rgb(&rgb, w, h), 3, w, h)
            );
        }
    }

    #[test]
    fn rgb_bytes_become_planes() {
        let rgb = [255, 0, 51, 0, 255, 102];
        let p = planar_rgb(&rgb, 2, 1);
        assert_eq!(p, vec![1.0, 0.0, 0.0, 1.0, 0.2, 0.4]);
    }
}
