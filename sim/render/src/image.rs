//! PNG files: encoding, decoding, and atomic writes (a killed run leaves no half-written file
//! under the final name).

use std::path::Path;

use crate::error::{RenderError, Result};

/// Pixel layouts this crate writes and reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelKind {
    /// 8-bit grey (class indices, masks).
    Gray,
    /// 8-bit sRGB.
    Rgb,
    /// 16-bit grey, two big-endian bytes per pixel (depth in mm).
    Gray16,
}

impl PixelKind {
    fn channels(self) -> usize {
        match self {
            PixelKind::Gray => 1,
            PixelKind::Rgb => 3,
            PixelKind::Gray16 => 2,
        }
    }
}

fn dataset_error(path: &Path, message: impl std::fmt::Display) -> RenderError {
    RenderError::Dataset {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

/// Encodes an 8-bit image as PNG (fast compression: encoding is on the dataset's hot path).
///
/// # Errors
/// [`RenderError::InvalidRender`] when `data` does not have `width * height` pixels.
pub fn encode_png(width: u32, height: u32, kind: PixelKind, data: &[u8]) -> Result<Vec<u8>> {
    if data.len() != width as usize * height as usize * kind.channels() || width == 0 || height == 0
    {
        return Err(RenderError::InvalidRender {
            message: format!(
                "{} bytes do not make a {width}x{height} image of {} channel(s)",
                data.len(),
                kind.channels()
            ),
        });
    }
    let mut out = Vec::with_capacity(data.len() / 2 + 64);
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(match kind {
            PixelKind::Gray | PixelKind::Gray16 => png::ColorType::Grayscale,
            PixelKind::Rgb => png::ColorType::Rgb,
        });
        encoder.set_depth(if kind == PixelKind::Gray16 {
            png::BitDepth::Sixteen
        } else {
            png::BitDepth::Eight
        });
        encoder.set_compression(png::Compression::Fast);
        let mut writer = encoder
            .write_header()
            .map_err(|e| RenderError::InvalidRender {
                message: e.to_string(),
            })?;
        writer
            .write_image_data(data)
            .map_err(|e| RenderError::InvalidRender {
                message: e.to_string(),
            })?;
    }
    Ok(out)
}

/// Depth in m as 16-bit PNG bytes in mm (0 = nothing seen, saturating at 65.535 m).
#[must_use]
pub fn depth_mm_bytes(depth_m: &[f32]) -> Vec<u8> {
    depth_m
        .iter()
        .flat_map(|&d| ((f64::from(d) * 1000.0).round().clamp(0.0, 65535.0) as u16).to_be_bytes())
        .collect()
}

/// The largest image side read or written, pixels.
pub const MAX_IMAGE_SIDE: u32 = 4096;
/// The largest PNG file read, in bytes: a 4,096-pixel square of 16-bit RGBA stored without
/// compression is 128 MiB.
pub const MAX_PNG_BYTES: u64 = 160 << 20;

/// Decodes an 8-bit grey or RGB PNG into `(width, height, kind, pixels)`.
///
/// # Errors
/// [`RenderError::Dataset`] naming `path` for a file that is not such a PNG.
pub fn decode_png(bytes: &[u8], path: &Path) -> Result<(u32, u32, PixelKind, Vec<u8>)> {
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder
        .read_info()
        .map_err(|e| dataset_error(path, format!("not a PNG: {e}")))?;
    let info = reader.info();
    // The size is checked before the pixels are allocated: a 100-byte PNG may declare
    // 16000x16000 (760 MB).
    if info.width > MAX_IMAGE_SIDE || info.height > MAX_IMAGE_SIDE {
        return Err(dataset_error(
            path,
            format!(
                "PNG of {}x{} pixels; at most {MAX_IMAGE_SIDE} a side is read",
                info.width, info.height
            ),
        ));
    }
    let kind = match (info.color_type, info.bit_depth) {
        (png::ColorType::Grayscale, png::BitDepth::Eight) => PixelKind::Gray,
        (png::ColorType::Rgb, png::BitDepth::Eight) => PixelKind::Rgb,
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => PixelKind::Gray16,
        (c, d) => {
            return Err(dataset_error(
                path,
                format!("PNG of {c:?} at {d:?}; expected 8-bit grey or RGB"),
            ));
        }
    };
    let size = reader
        .output_buffer_size()
        .ok_or_else(|| dataset_error(path, "PNG too large"))?;
    let mut data = vec![0; size];
    let frame = reader
        .next_frame(&mut data)
        .map_err(|e| dataset_error(path, format!("corrupt PNG: {e}")))?;
    data.truncate(frame.buffer_size());
    Ok((frame.width, frame.height, kind, data))
}

/// Reads a PNG file.
///
/// # Errors
/// [`RenderError::Io`] or [`RenderError::Dataset`] naming the file.
pub fn read_png(path: &Path) -> Result<(u32, u32, PixelKind, Vec<u8>)> {
    let io = |source| RenderError::Io {
        path: path.to_path_buf(),
        source,
    };
    // A FIFO or a device is never opened (a read would block or never end).
    let bytes = workcell_robots::input::read_regular_file(path, MAX_PNG_BYTES).map_err(io)?;
    decode_png(&bytes, path)
}

/// Writes `bytes` to `path` atomically: into a temporary file beside it, synced, then renamed.
///
/// # Errors
/// [`RenderError::Write`] naming the file.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    workcell_robots::output::write_atomic(path, bytes).map_err(|source| RenderError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Encodes and writes a PNG atomically.
///
/// # Errors
/// As [`encode_png`] and [`write_atomic`].
pub fn write_png(path: &Path, width: u32, height: u32, kind: PixelKind, data: &[u8]) -> Result<()> {
    write_atomic(path, &encode_png(width, height, kind, data)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// CRC-32 (IEEE), as PNG chunks carry it.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = 0xFFFF_FFFF_u32;
        for &b in bytes {
            crc ^= u32::from(b);
            for _ in 0..8 {
                crc = if crc & 1 == 1 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    #[test]
    fn a_png_declaring_a_huge_image_is_refused_before_its_pixels_are_allocated() {
        let small = encode_png(1, 1, PixelKind::Rgb, &[1, 2, 3]).expect("encode");
        assert_eq!(
            decode_png(&small, Path::new("small.png"))
                .expect("decode")
                .3,
            [1, 2, 3]
        );
        // The same file with IHDR saying 16000x16000 (760 MB of RGB), its CRC made right.
        let mut huge = small.clone();
        huge[16..20].copy_from_slice(&16000_u32.to_be_bytes());
        huge[20..24].copy_from_slice(&16000_u32.to_be_bytes());
        let crc = crc32(&huge[12..29]);
        huge[29..33].copy_from_slice(&crc.to_be_bytes());
        let err = decode_png(&huge, Path::new("huge.png"))
            .expect_err("huge")
            .to_string();
        assert!(
            err.contains("PNG of 16000x16000 pixels; at most 4096"),
            "{err}"
        );
    }
}
