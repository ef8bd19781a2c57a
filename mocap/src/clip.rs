//! A clip: the positions of a person's landmarks (joints) frame by frame, in metres, in a
//! z-up frame of the recording.

use serde::{Deserialize, Serialize};
use workcell_robots::math::Vector;

/// A point of the body a recording tracks. Sides are the person's own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Landmark {
    Pelvis,
    /// The chest: the top of the lumbar spine, where the torso bends.
    Chest,
    Neck,
    Head,
    LeftShoulder,
    LeftElbow,
    LeftWrist,
    RightShoulder,
    RightElbow,
    RightWrist,
}

impl Landmark {
    pub const ALL: [Self; 10] = [
        Self::Pelvis,
        Self::Chest,
        Self::Neck,
        Self::Head,
        Self::LeftShoulder,
        Self::LeftElbow,
        Self::LeftWrist,
        Self::RightShoulder,
        Self::RightElbow,
        Self::RightWrist,
    ];

    /// As written in files and maps (`left_wrist`).
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Self::Pelvis => "pelvis",
            Self::Chest => "chest",
            Self::Neck => "neck",
            Self::Head => "head",
            Self::LeftShoulder => "left_shoulder",
            Self::LeftElbow => "left_elbow",
            Self::LeftWrist => "left_wrist",
            Self::RightShoulder => "right_shoulder",
            Self::RightElbow => "right_elbow",
            Self::RightWrist => "right_wrist",
        }
    }

    /// The landmark of a name, if it is one.
    #[must_use]
    pub fn of_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|l| l.name() == name)
    }
}

/// How the recording's axes map onto the clip's (x, y, z) with z up: for each of the clip's
/// axes, the recording's axis it is and its sign. Written as three names, `["x", "-z", "y"]`
/// (the clip's y is the recording's -z), or a preset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "AxesSpec", into = "AxesSpec")]
pub struct Axes {
    /// `(recording axis, sign)` of the clip's x, y and z.
    pub map: [(usize, i8); 3],
}

impl Axes {
    /// The recording is z up already.
    pub const Z_UP: Self = Self {
        map: [(0, 1), (1, 1), (2, 1)],
    };
    /// Y up, as BVH files usually are: the clip's (x, y, z) = (x, -z, y).
    pub const Y_UP: Self = Self {
        map: [(0, 1), (2, -1), (1, 1)],
    };
    /// A camera's optical frame (x right, y down, z along the view): the clip's (x, y, z) =
    /// (x, z, -y), z up and y away from the camera.
    pub const CAMERA: Self = Self {
        map: [(0, 1), (2, 1), (1, -1)],
    };

    /// A recording's point in the clip's axes.
    #[must_use]
    pub fn apply(&self, p: [f64; 3]) -> Vector {
        let c = |(axis, sign): (usize, i8)| f64::from(sign) * p[axis];
        Vector::new(c(self.map[0]), c(self.map[1]), c(self.map[2]))
    }

    /// The axes of three names such as `["x", "-z", "y"]`.
    ///
    /// # Errors
    /// A name that is not an axis, or an axis used twice.
    pub fn of_names(names: &[String; 3]) -> Result<Self, String> {
        let mut map = [(0, 1); 3];
        for (slot, name) in map.iter_mut().zip(names) {
            let (sign, axis) = match name.strip_prefix('-') {
                Some(rest) => (-1, rest),
                None => (1, name.strip_prefix('+').unwrap_or(name)),
            };
            let axis = match axis {
                "x" => 0,
                "y" => 1,
                "z" => 2,
                _ => return Err(format!("axis {name:?}: x, y or z, with an optional sign")),
            };
            *slot = (axis, sign);
        }
        let mut used = [false; 3];
        for (axis, _) in map {
            if std::mem::replace(&mut used[axis], true) {
                return Err(format!("axes {names:?}: an axis used twice"));
            }
        }
        Ok(Self { map })
    }
}

/// Axes as a file writes them: a preset name or three axis names.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
pub enum AxesSpec {
    Preset(String),
    Names([String; 3]),
}

impl TryFrom<AxesSpec> for Axes {
    type Error = String;

    fn try_from(spec: AxesSpec) -> Result<Self, String> {
        match spec {
            AxesSpec::Preset(name) => match name.as_str() {
                "z_up" => Ok(Self::Z_UP),
                "y_up" => Ok(Self::Y_UP),
                "camera" => Ok(Self::CAMERA),
                _ => Err(format!(
                    "axes {name:?}: z_up, y_up, camera, or three names such as [\"x\", \"-z\", \"y\"]"
                )),
            },
            AxesSpec::Names(names) => Self::of_names(&names),
        }
    }
}

impl From<Axes> for AxesSpec {
    fn from(axes: Axes) -> Self {
        for (name, preset) in [
            ("z_up", Axes::Z_UP),
            ("y_up", Axes::Y_UP),
            ("camera", Axes::CAMERA),
        ] {
            if axes == preset {
                return Self::Preset(name.into());
            }
        }
        Self::Names(axes.map.map(|(axis, sign)| {
            format!(
                "{}{}",
                if sign < 0 { "-" } else { "" },
                ["x", "y", "z"][axis]
            )
        }))
    }
}

/// Recorded motion: every frame's position of each landmark the recording has, m, in the
/// clip's z-up frame. No position is NaN: a reader fills what the recording misses and marks
/// those frames in [`Clip::filled`].
#[derive(Debug, Clone, PartialEq)]
pub struct Clip {
    /// A name for reports (the file's, by default).
    pub name: String,
    /// Frames per second.
    pub rate_hz: f64,
    /// The landmarks each frame holds, in order.
    pub landmarks: Vec<Landmark>,
    /// `frames x landmarks` positions, frame after frame.
    pub positions: Vec<Vector>,
    /// Per frame: some landmark of it was missing from the recording and is interpolated
    /// (or held, at the ends).
    pub filled: Vec<bool>,
}

impl Clip {
    /// Frames in the clip.
    #[must_use]
    pub fn frames(&self) -> usize {
        self.filled.len()
    }

    /// Length, s.
    #[must_use]
    pub fn duration_s(&self) -> f64 {
        self.frames().saturating_sub(1) as f64 / self.rate_hz
    }

    /// The column of `landmark`, if the clip has it.
    #[must_use]
    pub fn column(&self, landmark: Landmark) -> Option<usize> {
        self.landmarks.iter().position(|&l| l == landmark)
    }

    /// The positions of frame `f`, one per landmark.
    #[must_use]
    pub fn frame(&self, f: usize) -> &[Vector] {
        let n = self.landmarks.len();
        &self.positions[f * n..(f + 1) * n]
    }

    /// `landmark`'s track, frame by frame (empty when the clip lacks it).
    #[must_use]
    pub fn track(&self, landmark: Landmark) -> Vec<Vector> {
        let n = self.landmarks.len();
        self.column(landmark).map_or_else(Vec::new, |k| {
            (0..self.frames())
                .map(|f| self.positions[f * n + k])
                .collect()
        })
    }

    /// Replaces `landmark`'s track (same length as the clip).
    ///
    /// # Panics
    /// When the clip lacks the landmark or the track's length is not the clip's: a caller's
    /// bug, not the data's.
    pub fn set_track(&mut self, landmark: Landmark, track: &[Vector]) {
        let n = self.landmarks.len();
        let k = self.column(landmark).expect("a landmark of the clip");
        assert_eq!(track.len(), self.frames(), "a track of the clip's length");
        for (f, p) in track.iter().enumerate() {
            self.positions[f * n + k] = *p;
        }
    }

    /// Frames `range` as a clip of their own, named `name`.
    #[must_use]
    pub fn slice(&self, range: std::ops::Range<usize>, name: String) -> Self {
        let n = self.landmarks.len();
        Self {
            name,
            rate_hz: self.rate_hz,
            landmarks: self.landmarks.clone(),
            positions: self.positions[range.start * n..range.end * n].to_vec(),
            filled: self.filled[range].to_vec(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_map_a_y_up_recording_onto_z_up() {
        // BVH's up (y) becomes z; its forward (z) becomes -y: still right-handed.
        let p = Axes::Y_UP.apply([1.0, 2.0, 3.0]);
        assert_eq!((p.x, p.y, p.z), (1.0, -3.0, 2.0));
        let q = Axes::CAMERA.apply([1.0, 2.0, 3.0]);
        assert_eq!((q.x, q.y, q.z), (1.0, 3.0, -2.0));
        let names = ["x".to_string(), "-z".to_string(), "y".to_string()];
        assert_eq!(Axes::of_names(&names), Ok(Axes::Y_UP));
        let twice = ["x".to_string(), "x".to_string(), "y".to_string()];
        assert!(Axes::of_names(&twice).is_err());
        // Each preset is a proper rotation (determinant +1): no mirrored recordings.
        for axes in [Axes::Z_UP, Axes::Y_UP, Axes::CAMERA] {
            let [ex, ey, ez] =
                [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(|e| axes.apply(e));
            assert!((ex.cross(ey).dot(ez) - 1.0).abs() < 1e-12, "{axes:?}");
        }
    }

    #[test]
    fn axes_round_trip_through_their_written_form() {
        for axes in [
            Axes::Z_UP,
            Axes::Y_UP,
            Axes::CAMERA,
            Axes {
                map: [(1, -1), (0, 1), (2, 1)],
            },
        ] {
            let spec = AxesSpec::from(axes);
            assert_eq!(Axes::try_from(spec), Ok(axes));
        }
    }
}
