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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rgb_bytes_become_planes() {
        let rgb = [255, 0, 51, 0, 255, 102];
        let p = planar_rgb(&rgb, 2, 1);
        assert_eq!(p, vec![1.0, 0.0, 0.0, 1.0, 0.2, 0.4]);
    }
}
