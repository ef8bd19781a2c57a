//! Recorded human motion for the work-cell: clips of people's joints read from BVH files
//! (any hierarchy, with a joint-name map) or from joint-position tables (a pose tracker's
//! output), gzipped or not; capture artefacts found and bridged or cut ([`clean`]); a
//! zero-phase low-pass ([`filter`]); speeds and accelerations per landmark ([`stats`]).
//!
//! Every clip is in metres in a z-up frame of the recording ([`Clip`]); where the person
//! stands in the cell is the caller's choice. Nothing here knows the simulator or the cell's
//! human model: retargeting onto a model is the simulator's.

pub mod bvh;
pub mod clean;
pub mod clip;
pub mod error;
pub mod filter;
pub mod library;
pub mod stats;
pub mod table;

use std::io::Read as _;
use std::path::Path;

use serde::{Deserialize, Serialize};

pub use clip::{Axes, Clip, Landmark};
pub use error::{MocapError, Result};

/// The largest clip file read, compressed or not, and the most text a gzipped one may expand
/// to, bytes.
pub const MAX_CLIP_BYTES: u64 = 512 << 20;

/// How a clip file is read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "format", rename_all = "snake_case", deny_unknown_fields)]
pub enum ClipFormat {
    /// A BVH file.
    Bvh {
        /// The joint of each landmark: a preset (`hrc`, `cmu`; [`bvh::joint_map_preset`]) or
        /// a table `{ left_wrist = "LeftHand", ... }`. Left out: the first preset whose
        /// joints the hierarchy has.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        joints: Option<JointsSpec>,
        /// Metres per unit of the file's offsets and positions. Default 0.001 (millimetres).
        #[serde(default = "millimetres")]
        metres_per_unit: f64,
        /// The file's axes. Default `y_up`.
        #[serde(default = "y_up")]
        axes: Axes,
        /// How the rotation channels are read ([`bvh::Euler`]: `listed`, the format's
        /// convention, or `fixed_zxy`). Left out: the joint preset's (`hrc`: `fixed_zxy`),
        /// else `listed`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        euler: Option<bvh::Euler>,
    },
    /// A table of joint positions, three numbers per landmark per row.
    Table {
        /// The landmark of each triple of columns, or the preset `assembly`
        /// ([`table::ASSEMBLY_COLUMNS`]).
        columns: ColumnsSpec,
        /// Frames per second: a table does not say.
        rate_hz: f64,
        /// Metres per unit. Default 1.
        #[serde(default = "metres")]
        metres_per_unit: f64,
        /// The table's axes. Default `camera` (x right, y down, z along the view).
        #[serde(default = "camera")]
        axes: Axes,
        /// The longest run of missing detections interpolated, s. Default 0.5.
        #[serde(default = "half_second")]
        max_gap_s: f64,
    },
}

fn millimetres() -> f64 {
    0.001
}
fn metres() -> f64 {
    1.0
}
fn y_up() -> Axes {
    Axes::Y_UP
}
fn camera() -> Axes {
    Axes::CAMERA
}
fn half_second() -> f64 {
    0.5
}

/// A BVH joint map as a file writes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum JointsSpec {
    Preset(String),
    Map(bvh::JointMap),
}

/// Table columns as a file writes them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ColumnsSpec {
    Preset(String),
    List(Vec<Landmark>),
}

/// The text of a clip file: gunzipped when its name ends in `.gz`, at most
/// [`MAX_CLIP_BYTES`] either way.
///
/// # Errors
/// [`MocapError::Io`] for a file that cannot be read or is refused, a gzip stream that is
/// broken or expands past the limit, text that is not UTF-8.
pub fn read_clip_text(path: &Path) -> Result<String> {
    let io = |source: std::io::Error| MocapError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = workcell_robots::input::read_regular_file(path, MAX_CLIP_BYTES).map_err(io)?;
    let bytes = if path.extension().is_some_and(|e| e == "gz") {
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(bytes.as_slice())
            .take(MAX_CLIP_BYTES + 1)
            .read_to_end(&mut out)
            .map_err(io)?;
        if out.len() as u64 > MAX_CLIP_BYTES {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("expands past the limit of {MAX_CLIP_BYTES} bytes"),
            )));
        }
        out
    } else {
        bytes
    };
    String::from_utf8(bytes).map_err(|e| {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text (invalid byte at offset {})",
                e.utf8_error().valid_up_to()
            ),
        ))
    })
}

/// The clip's name from its path: the file name without `.gz` and its format's extension.
#[must_use]
pub fn clip_name(path: &Path) -> String {
    let name = path
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    match name.rsplit_once('.') {
        Some((stem, _)) if !stem.is_empty() => stem.to_string(),
        _ => name.to_string(),
    }
}

/// The format a path's extension suggests (`.bvh`, `.bvh.gz` are BVH with a detected joint
/// map; anything else needs its format said).
#[must_use]
pub fn format_of_path(path: &Path) -> Option<ClipFormat> {
    let name = path.file_name()?.to_string_lossy().to_ascii_lowercase();
    (name.ends_with(".bvh") || name.ends_with(".bvh.gz")).then(|| ClipFormat::Bvh {
        joints: None,
        metres_per_unit: millimetres(),
        axes: y_up(),
        euler: None,
    })
}

/// Reads the clip at `path` in `format`, named `name`.
///
/// # Errors
/// Those of [`read_clip_text`], [`bvh::Bvh::parse`], [`bvh::Bvh::clip`] and
/// [`table::parse_table`]; an unknown preset; a BVH whose joints fit no preset and no map
/// was given.
pub fn read_clip(path: &Path, format: &ClipFormat, name: String) -> Result<Clip> {
    let text = read_clip_text(path)?;
    let invalid = |message: String| MocapError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    match format {
        ClipFormat::Bvh {
            joints,
            metres_per_unit,
            axes,
            euler,
        } => {
            let mut file = bvh::Bvh::parse(&text, path)?;
            let (map, preset) = match joints {
                Some(JointsSpec::Map(map)) => (map.clone(), None),
                Some(JointsSpec::Preset(preset)) => (
                    bvh::joint_map_preset(preset).ok_or_else(|| {
                        invalid(format!("no joint map preset {preset:?} (hrc, cmu)"))
                    })?,
                    Some(preset.as_str()),
                ),
                None => ["hrc", "cmu"]
                    .into_iter()
                    .find_map(|p| {
                        bvh::joint_map_preset(p)
                            .filter(|m| m.values().all(|j| file.joint_names().any(|n| n == j)))
                            .map(|m| (m, Some(p)))
                    })
                    .ok_or_else(|| {
                        invalid(format!(
                            "its joints ({}) fit no preset (hrc, cmu): give a joint map",
                            file.joint_names().collect::<Vec<_>>().join(", ")
                        ))
                    })?,
            };
            file.euler = euler
                .unwrap_or_else(|| preset.map_or_else(Default::default, bvh::Euler::of_preset));
            file.clip(&map, *metres_per_unit, *axes, name, path)
        }
        ClipFormat::Table {
            columns,
            rate_hz,
            metres_per_unit,
            axes,
            max_gap_s,
        } => {
            let columns = match columns {
                ColumnsSpec::List(list) => list.clone(),
                ColumnsSpec::Preset(p) if p == "assembly" => table::ASSEMBLY_COLUMNS.to_vec(),
                ColumnsSpec::Preset(p) => {
                    return Err(invalid(format!("no column preset {p:?} (assembly)")));
                }
            };
            let format = table::TableFormat {
                columns,
                rate_hz: *rate_hz,
                metres_per_unit: *metres_per_unit,
                axes: *axes,
                max_gap_s: *max_gap_s,
            };
            table::parse_table(&text, &format, name, path)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_formats_come_from_the_path() {
        assert_eq!(clip_name(Path::new("a/b/3.bvh.gz")), "3");
        assert_eq!(clip_name(Path::new("trial1.txt")), "trial1");
        assert!(format_of_path(Path::new("x.BVH.gz")).is_some());
        assert!(format_of_path(Path::new("x.txt")).is_none());
    }

    /// A plain and a gzipped file read the same; a broken gzip stream is an error.
    #[test]
    fn gzipped_clips_read_like_plain_ones() {
        use std::io::Write as _;
        let dir = tempfile::tempdir().expect("dir");
        let text = "0 0 0 1 1 1\n0 0 0 1 1 1\n";
        let plain = dir.path().join("t.txt");
        std::fs::write(&plain, text).expect("write");
        let gz = dir.path().join("t.txt.gz");
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(text.as_bytes()).expect("gzip");
        std::fs::write(&gz, e.finish().expect("gzip")).expect("write");
        assert_eq!(read_clip_text(&plain).expect("plain"), text);
        assert_eq!(read_clip_text(&gz).expect("gz"), text);
        std::fs::write(dir.path().join("bad.gz"), b"not gzip").expect("write");
        assert!(read_clip_text(&dir.path().join("bad.gz")).is_err());
    }
}
