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

#[cfg(test)]
mod tests {
    use super::*;

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
