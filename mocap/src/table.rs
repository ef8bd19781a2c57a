//! Joint-position tables: one row per frame, three numbers per landmark, whitespace or
//! commas between them, as pose trackers write them (OpenPose's keypoints lifted to 3-D by a
//! depth camera). Missing detections (`nan`) are interpolated across short gaps and held at
//! the ends; every frame that had one is marked in [`Clip::filled`].

use std::path::Path;

use workcell_robots::math::Vector;

use crate::clip::{Axes, Clip, Landmark};
use crate::error::{MocapError, Result};

/// The columns of the human-assembly trials shipped in `data/mocap/human-assembly-data`:
/// left and right wrist, left and right elbow, left and right shoulder.
pub const ASSEMBLY_COLUMNS: [Landmark; 6] = [
    Landmark::LeftWrist,
    Landmark::RightWrist,
    Landmark::LeftElbow,
    Landmark::RightElbow,
    Landmark::LeftShoulder,
    Landmark::RightShoulder,
];

/// How a table is read.
#[derive(Debug, Clone, PartialEq)]
pub struct TableFormat {
    /// The landmark of each triple of columns, in order.
    pub columns: Vec<Landmark>,
    /// Frames per second (a table does not say).
    pub rate_hz: f64,
    /// Metres per unit of the numbers.
    pub metres_per_unit: f64,
    pub axes: Axes,
    /// The longest run of missing frames filled by interpolation, s; a longer one is an
    /// error naming it.
    pub max_gap_s: f64,
}

/// Parses a table's text (`path` names it in errors) into a clip named `name`.
///
/// # Errors
/// [`MocapError::Parse`] with the line for a row of the wrong width or a value that is not a
/// number; [`MocapError::Invalid`] for a landmark never detected, a gap longer than
/// `max_gap_s`, fewer than two frames.
pub fn parse_table(text: &str, format: &TableFormat, name: String, path: &Path) -> Result<Clip> {
    let width = 3 * format.columns.len();
    let invalid = |message: String| MocapError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    if !(format.rate_hz.is_finite() && format.rate_hz > 0.0) {
        return Err(invalid(format!("frame rate {} Hz: > 0", format.rate_hz)));
    }
    let mut raw: Vec<Option<Vector>> = Vec::new();
    let mut row = Vec::with_capacity(width);
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if raw.len() / format.columns.len().max(1) >= crate::bvh::MAX_FRAMES {
            return Err(invalid(format!(
                "more than {} frames",
                crate::bvh::MAX_FRAMES
            )));
        }
        row.clear();
        for word in line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|w| !w.is_empty())
        {
            let v: f64 = word.parse().map_err(|_| MocapError::Parse {
                path: path.to_path_buf(),
                line: Some(n + 1),
                message: format!("`{word}` is not a number"),
            })?;
            if v.is_infinite() {
                return Err(MocapError::Parse {
                    path: path.to_path_buf(),
                    line: Some(n + 1),
                    message: format!("`{word}` is not finite"),
                });
            }
            row.push(v);
        }
        if row.len() != width {
            return Err(MocapError::Parse {
                path: path.to_path_buf(),
                line: Some(n + 1),
                message: format!(
                    "{} values where {} landmarks take {width}",
                    row.len(),
                    format.columns.len()
                ),
            });
        }
        for xyz in row.chunks_exact(3) {
            raw.push(if xyz.iter().any(|v| v.is_nan()) {
                None
            } else {
                let p = [xyz[0], xyz[1], xyz[2]].map(|v| v * format.metres_per_unit);
                Some(format.axes.apply(p))
            });
        }
    }
    let n = format.columns.len();
    let frames = raw.len() / n.max(1);
    if frames < 2 {
        return Err(invalid(format!(
            "{frames} frames: a clip needs at least two"
        )));
    }
    let max_gap = (format.max_gap_s * format.rate_hz).floor() as usize;
    let mut filled = vec![false; frames];
    let mut positions = vec![Vector::ZERO; frames * n];
    for (k, landmark) in format.columns.iter().enumerate() {
        let track: Vec<Option<Vector>> = (0..frames).map(|f| raw[f * n + k]).collect();
        let known: Vec<usize> = (0..frames).filter(|&f| track[f].is_some()).collect();
        let (Some(&first), Some(&last)) = (known.first(), known.last()) else {
            return Err(invalid(format!("{} is never detected", landmark.name())));
        };
        for pair in known.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            if b - a - 1 > max_gap {
                return Err(invalid(format!(
                    "{} is missing for {} frames from frame {} ({:.2} s; at most {} s are \
                     interpolated)",
                    landmark.name(),
                    b - a - 1,
                    a + 1,
                    (b - a - 1) as f64 / format.rate_hz,
                    format.max_gap_s
                )));
            }
        }
        if first > max_gap || frames - 1 - last > max_gap {
            return Err(invalid(format!(
                "{} is missing for more than {} s at the clip's {}",
                landmark.name(),
                format.max_gap_s,
                if first > max_gap { "start" } else { "end" }
            )));
        }
        let mut next = 0; // index into `known` of the first known frame at or after f
        for f in 0..frames {
            while known[next] < f {
                next += 1;
            }
            let p = match track[f] {
                Some(p) => p,
                None => {
                    filled[f] = true;
                    let after = known[next];
                    match next.checked_sub(1).map(|i| known[i]) {
                        None => track[after].unwrap_or(Vector::ZERO),
                        Some(before) => {
                            let (a, b) = (
                                track[before].unwrap_or(Vector::ZERO),
                                track[after].unwrap_or(Vector::ZERO),
                            );
                            let s = (f - before) as f64 / (after - before) as f64;
                            a + (b - a) * s
                        }
                    }
                }
            };
            positions[f * n + k] = p;
            if f == last {
                // Held from here to the end.
                for g in f + 1..frames {
                    filled[g] = true;
                    positions[g * n + k] = p;
                }
                break;
            }
        }
    }
    Ok(Clip {
        name,
        rate_hz: format.rate_hz,
        landmarks: format.columns.clone(),
        positions,
        filled,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn format(max_gap_s: f64) -> TableFormat {
        TableFormat {
            columns: vec![Landmark::LeftWrist, Landmark::RightWrist],
            rate_hz: 10.0,
            metres_per_unit: 1.0,
            axes: Axes::Z_UP,
            max_gap_s,
        }
    }

    #[test]
    fn missing_detections_are_interpolated_and_marked() {
        let text =
            "0 0 0  nan nan nan\n1 0 0  5 5 5\nnan 0 0  6 6 6\n3 0 0  7 7 7\n4 0 0 nan 1 1\n";
        let clip = parse_table(text, &format(0.2), "t".into(), Path::new("t.txt")).expect("clip");
        assert_eq!(clip.frames(), 5);
        let left = clip.track(Landmark::LeftWrist);
        // The gap at frame 2 lies halfway between 1 and 3.
        assert_eq!(left[2], Vector::new(2.0, 0.0, 0.0));
        let right = clip.track(Landmark::RightWrist);
        // Held at the ends: the start from the first detection, the end from the last.
        assert_eq!(right[0], Vector::new(5.0, 5.0, 5.0));
        assert_eq!(right[4], Vector::new(7.0, 7.0, 7.0));
        assert_eq!(clip.filled, [true, false, true, false, true]);
        assert!(clip.positions.iter().all(|p| p.is_finite()));
    }

    #[test]
    fn a_table_that_cannot_be_motion_is_refused() {
        let path = Path::new("t.txt");
        let gap = "0 0 0 1 1 1\nnan 0 0 1 1 1\nnan 0 0 1 1 1\nnan 0 0 1 1 1\n3 0 0 1 1 1\n";
        for (text, f, needle) in [
            (
                gap,
                format(0.2),
                "left_wrist is missing for 3 frames from frame 1",
            ),
            (
                "0 0 0 1 1\n",
                format(1.0),
                "t.txt:1: 5 values where 2 landmarks take 6",
            ),
            (
                "0 0 0 1 1 x\n0 0 0 1 1 1\n",
                format(1.0),
                "`x` is not a number",
            ),
            (
                "0 0 0 nan 1 1\n0 0 0 nan 1 1\n",
                format(1.0),
                "right_wrist is never detected",
            ),
            ("0 0 0 1 1 1\n", format(1.0), "1 frames"),
        ] {
            let err = parse_table(text, &f, "t".into(), path)
                .expect_err(needle)
                .to_string();
            assert!(err.contains(needle), "{needle}: {err}");
        }
        assert!(parse_table(gap, &format(0.3), "t".into(), path).is_ok());
    }
}
