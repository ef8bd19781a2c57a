//! BVH (Biovision Hierarchy) files: any hierarchy, each joint's channels in the order its
//! header lists them, positions in the file's unit; a joint-name map picks the landmarks.
//!
//! A joint's frame in its parent's is `T(offset + position channels) R`, the rotation made of
//! the rotation channels (degrees) as [`Euler`] says: by default in the order the `CHANNELS`
//! line lists them, each about the axis the ones before left (`R_1 R_2 R_3`), the convention of
//! the format's writers (Biovision's, and the Vicon and MotionBuilder exports that follow it).
//! Some converters write other angles under the same header; [`Euler::FixedZxy`] reads the
//! shipped Vicon task clips', whose converter is the source's own.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use workcell_robots::math::{Pose, Rotation, Vector};

use crate::clip::{Axes, Clip, Landmark};
use crate::error::{MocapError, Result};

/// The most joints a hierarchy may have.
pub const MAX_JOINTS: usize = 512;
/// The most frames a clip may have (three hours at 100 Hz).
pub const MAX_FRAMES: usize = 1_080_000;

/// One joint's channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Channel {
    Position(usize),
    Rotation(usize),
}

#[derive(Debug, Clone)]
struct Joint {
    name: String,
    parent: Option<usize>,
    offset: [f64; 3],
    channels: Vec<Channel>,
    /// Index of its first channel in a frame's values.
    first: usize,
}

/// How a BVH file's rotation channels make a joint's rotation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Euler {
    /// The format's convention: the rotation channels in the order the joint's `CHANNELS`
    /// line lists them, each about the axis the ones before it left (`R = R_1 R_2 R_3`).
    #[default]
    Listed,
    /// Every joint's three rotation values, in the file's order, are angles about the
    /// parent's fixed z, x and y axes, whatever its `CHANNELS` line names: `R = R_y(v_3)
    /// R_x(v_2) R_z(v_1)`. The shipped Vicon task clips' converter wrote them so (SciPy's
    /// extrinsic `"zxy"` Euler angles under a `Zrotation Xrotation Yrotation` header, the
    /// root's under `Zrotation Yrotation Xrotation`); read so, the clips give the bone
    /// directions of the source's Vicon export to 0.1 degrees at the median frame, read as
    /// listed 30 to 67 degrees off (docs/human.md, "Reading the Vicon clips").
    FixedZxy,
}

impl Euler {
    /// The convention of preset `name`'s files ([`joint_map_preset`]): `hrc`'s are
    /// [`Euler::FixedZxy`], every other's [`Euler::Listed`].
    #[must_use]
    pub fn of_preset(name: &str) -> Self {
        if name == "hrc" {
            Self::FixedZxy
        } else {
            Self::Listed
        }
    }
}

/// A parsed BVH file: its hierarchy and its frames' channel values.
#[derive(Debug, Clone)]
pub struct Bvh {
    joints: Vec<Joint>,
    /// Seconds per frame.
    pub frame_time_s: f64,
    /// How the rotation channels are read. [`Euler::Listed`] after [`Bvh::parse`].
    pub euler: Euler,
    /// `frames x channels` values.
    values: Vec<f64>,
    channels: usize,
}

/// The BVH joint of each landmark, by name.
pub type JointMap = BTreeMap<Landmark, String>;

/// A named preset of [`JointMap`]: `hrc` (the Vicon task clips shipped in
/// `data/mocap/hrc-task-clips`: `hip`, `neck`, `head`, `*_upper_arm`, `*_forearm`, `*_hand`,
/// read with [`Euler::FixedZxy`]; its `torso` joint sits at the hip, so it gives no chest of
/// its own) or `cmu`
/// (the CMU motion-capture library's BVH conversions: `Hips`, `Spine1`, `LeftArm`,
/// `LeftForeArm`, `LeftHand`).
#[must_use]
pub fn joint_map_preset(name: &str) -> Option<JointMap> {
    use Landmark as L;
    let pairs: &[(Landmark, &str)] = match name {
        "hrc" => &[
            (L::Pelvis, "hip"),
            (L::Neck, "neck"),
            (L::Head, "head"),
            // The sides as the hierarchy names them: read with their own Euler angles, the
            // elbows bend as elbows do with these names (and backwards with the sides
            // swapped), and the hand the source says holds the handed-over object is the
            // one that travels farther. The `head` joint sits 12 to 16 cm behind the
            // shoulders: where the recording's head segment has its origin, not the face.
            (L::LeftShoulder, "left_upper_arm"),
            (L::LeftElbow, "left_forearm"),
            (L::LeftWrist, "left_hand"),
            (L::RightShoulder, "right_upper_arm"),
            (L::RightElbow, "right_forearm"),
            (L::RightWrist, "right_hand"),
        ],
        "cmu" => &[
            (L::Pelvis, "Hips"),
            (L::Chest, "Spine1"),
            (L::Neck, "Neck"),
            (L::Head, "Head"),
            (L::LeftShoulder, "LeftArm"),
            (L::LeftElbow, "LeftForeArm"),
            (L::LeftWrist, "LeftHand"),
            (L::RightShoulder, "RightArm"),
            (L::RightElbow, "RightForeArm"),
            (L::RightWrist, "RightHand"),
        ],
        _ => return None,
    };
    Some(pairs.iter().map(|&(l, j)| (l, j.to_string())).collect())
}

/// Whitespace-separated words with their line numbers.
struct Words<'a> {
    words: std::iter::Peekable<Box<dyn Iterator<Item = (usize, &'a str)> + 'a>>,
    path: &'a Path,
}

impl<'a> Words<'a> {
    fn new(text: &'a str, path: &'a Path) -> Self {
        let words: Box<dyn Iterator<Item = (usize, &'a str)>> = Box::new(
            text.lines()
                .enumerate()
                .flat_map(|(n, l)| l.split_whitespace().map(move |w| (n + 1, w))),
        );
        Self {
            words: words.peekable(),
            path,
        }
    }

    fn error(&self, line: Option<usize>, message: String) -> MocapError {
        MocapError::Parse {
            path: self.path.to_path_buf(),
            line,
            message,
        }
    }

    fn next(&mut self, what: &str) -> Result<(usize, &'a str)> {
        self.words
            .next()
            .ok_or_else(|| self.error(None, format!("the file ends where {what} should be")))
    }

    fn expect(&mut self, word: &str) -> Result<usize> {
        let (line, w) = self.next(&format!("`{word}`"))?;
        if w == word {
            Ok(line)
        } else {
            Err(self.error(Some(line), format!("`{word}` expected, found `{w}`")))
        }
    }

    fn number(&mut self, what: &str) -> Result<f64> {
        let (line, w) = self.next(what)?;
        match w.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(self.error(Some(line), format!("{what}: `{w}` is not a finite number"))),
        }
    }
}

impl Bvh {
    /// Parses the text of a BVH file (`path` names it in errors).
    ///
    /// # Errors
    /// [`MocapError::Parse`] with the line for anything that is not BVH, a hierarchy over
    /// [`MAX_JOINTS`] or a motion over [`MAX_FRAMES`], a frame time that is not positive.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let mut words = Words::new(text, path);
        words.expect("HIERARCHY")?;
        let (line, root) = words.next("`ROOT`")?;
        if root != "ROOT" {
            return Err(words.error(Some(line), format!("`ROOT` expected, found `{root}`")));
        }
        let mut joints: Vec<Joint> = Vec::new();
        let mut channels = 0;
        // Open joints, innermost last; `None` for an End Site's block.
        let mut stack: Vec<Option<usize>> = Vec::new();
        let mut pending: Option<String> = Some(words.next("the root's name")?.1.to_string());
        loop {
            if let Some(name) = pending.take() {
                if joints.len() >= MAX_JOINTS {
                    return Err(words.error(None, format!("more than {MAX_JOINTS} joints")));
                }
                words.expect("{")?;
                words.expect("OFFSET")?;
                let offset = [
                    words.number("OFFSET x")?,
                    words.number("OFFSET y")?,
                    words.number("OFFSET z")?,
                ];
                let line = words.expect("CHANNELS")?;
                let n = words.number("the channel count")?;
                if !(0.0..=6.0).contains(&n) || n.fract() != 0.0 {
                    return Err(words.error(Some(line), format!("{n} channels: 0 to 6")));
                }
                let mut list = Vec::new();
                for _ in 0..n as usize {
                    let (line, c) = words.next("a channel")?;
                    let axis = |s: &str| match s.chars().next() {
                        Some('X' | 'x') => Some(0),
                        Some('Y' | 'y') => Some(1),
                        Some('Z' | 'z') => Some(2),
                        _ => None,
                    };
                    let channel = match (c.get(1..), axis(c)) {
                        (Some("position" | "Position"), Some(a)) => Channel::Position(a),
                        (Some("rotation" | "Rotation"), Some(a)) => Channel::Rotation(a),
                        _ => {
                            return Err(words.error(Some(line), format!("`{c}` is not a channel")));
                        }
                    };
                    list.push(channel);
                }
                joints.push(Joint {
                    name,
                    parent: stack.iter().rev().find_map(|j| *j),
                    offset,
                    channels: list,
                    first: channels,
                });
                channels += n as usize;
                stack.push(Some(joints.len() - 1));
                continue;
            }
            let (line, w) = words.next("`JOINT`, `End Site` or `}`")?;
            match w {
                "JOINT" => pending = Some(words.next("a joint's name")?.1.to_string()),
                "End" => {
                    words.expect("Site")?;
                    words.expect("{")?;
                    words.expect("OFFSET")?;
                    for axis in ["x", "y", "z"] {
                        words.number(&format!("End Site OFFSET {axis}"))?;
                    }
                    stack.push(None);
                }
                "}" => {
                    stack.pop();
                    if stack.is_empty() {
                        break;
                    }
                }
                _ => {
                    return Err(words.error(
                        Some(line),
                        format!("`JOINT`, `End Site` or `}}` expected, found `{w}`"),
                    ));
                }
            }
        }
        words.expect("MOTION")?;
        words.expect("Frames:")?;
        let frames = words.number("the frame count")?;
        if !(0.0..=MAX_FRAMES as f64).contains(&frames) || frames.fract() != 0.0 {
            return Err(words.error(None, format!("{frames} frames: 0 to {MAX_FRAMES}")));
        }
        let frames = frames as usize;
        words.expect("Frame")?;
        words.expect("Time:")?;
        let frame_time_s = words.number("the frame time")?;
        if frame_time_s <= 0.0 {
            return Err(words.error(None, format!("frame time {frame_time_s} s: > 0")));
        }
        // Every value takes at least two bytes of the text: no more can follow than that.
        let mut values = Vec::with_capacity(frames.saturating_mul(channels).min(text.len() / 2));
        for f in 0..frames {
            for _ in 0..channels {
                values.push(words.number(&format!("frame {f}'s values"))?);
            }
        }
        if let Some((line, w)) = words.words.next() {
            return Err(words.error(
                Some(line),
                format!("`{w}` after the {frames} frames the header announces"),
            ));
        }
        Ok(Self {
            joints,
            frame_time_s,
            euler: Euler::Listed,
            values,
            channels,
        })
    }

    /// Frames in the motion.
    #[must_use]
    pub fn frames(&self) -> usize {
        self.values.len().checked_div(self.channels).unwrap_or(0)
    }

    /// The joints' names, in the file's order.
    pub fn joint_names(&self) -> impl Iterator<Item = &str> {
        self.joints.iter().map(|j| j.name.as_str())
    }

    /// Every joint's pose in the file's frame at frame `f` (positions in the file's unit).
    fn poses(&self, f: usize, out: &mut Vec<Pose>) {
        out.clear();
        let values = &self.values[f * self.channels..(f + 1) * self.channels];
        for joint in &self.joints {
            let mut translation = joint.offset;
            let mut rotation = Rotation::IDENTITY;
            // The rotation values in the file's order (FixedZxy: three, checked by `clip`).
            let mut angles = [0.0; 3];
            let mut n = 0;
            for (k, channel) in joint.channels.iter().enumerate() {
                let v = values[joint.first + k];
                match *channel {
                    Channel::Position(a) => translation[a] += v,
                    Channel::Rotation(a) => match self.euler {
                        Euler::Listed => {
                            let axis = [Vector::X, Vector::Y, Vector::Z][a];
                            rotation *= Rotation::from_axis_angle(axis, v.to_radians());
                        }
                        Euler::FixedZxy => {
                            if let Some(slot) = angles.get_mut(n) {
                                *slot = v.to_radians();
                            }
                            n += 1;
                        }
                    },
                }
            }
            if self.euler == Euler::FixedZxy && n > 0 {
                rotation = Rotation::from_axis_angle(Vector::Y, angles[2])
                    * Rotation::from_axis_angle(Vector::X, angles[1])
                    * Rotation::from_axis_angle(Vector::Z, angles[0]);
            }
            let local = Pose::from_parts(
                Vector::new(translation[0], translation[1], translation[2]),
                rotation,
            );
            let pose = match joint.parent {
                Some(p) => out[p] * local,
                None => local,
            };
            out.push(pose);
        }
    }

    /// The clip of the landmarks `map` names: each mapped joint's origin, frame by frame, in
    /// metres (`metres_per_unit`, 0.001 for millimetres) in the clip's axes.
    ///
    /// # Errors
    /// [`MocapError::Invalid`] when a joint the map names is not in the hierarchy (the
    /// message lists the hierarchy's joints), or the motion has fewer than two frames.
    pub fn clip(
        &self,
        map: &JointMap,
        metres_per_unit: f64,
        axes: Axes,
        name: String,
        path: &Path,
    ) -> Result<Clip> {
        let mut columns = Vec::new();
        for (&landmark, joint) in map {
            let index = self
                .joints
                .iter()
                .position(|j| &j.name == joint)
                .ok_or_else(|| MocapError::Invalid {
                    path: path.to_path_buf(),
                    message: format!(
                        "{} is mapped to joint {joint:?}, which the hierarchy lacks (it has {})",
                        landmark.name(),
                        self.joint_names().collect::<Vec<_>>().join(", ")
                    ),
                })?;
            columns.push((landmark, index));
        }
        if self.euler == Euler::FixedZxy {
            let rotations = |j: &Joint| {
                j.channels
                    .iter()
                    .filter(|c| matches!(c, Channel::Rotation(_)))
                    .count()
            };
            if let Some(j) = self.joints.iter().find(|j| !matches!(rotations(j), 0 | 3)) {
                return Err(MocapError::Invalid {
                    path: path.to_path_buf(),
                    message: format!(
                        "joint {:?} has {} rotation channels: euler = \"fixed_zxy\" reads three \
                         (or none) per joint",
                        j.name,
                        rotations(j)
                    ),
                });
            }
        }
        if self.frames() < 2 {
            return Err(MocapError::Invalid {
                path: path.to_path_buf(),
                message: format!("{} frames: a clip needs at least two", self.frames()),
            });
        }
        let mut positions = Vec::with_capacity(self.frames() * columns.len());
        let mut poses = Vec::with_capacity(self.joints.len());
        for f in 0..self.frames() {
            self.poses(f, &mut poses);
            for &(_, j) in &columns {
                let p = poses[j].translation * metres_per_unit;
                positions.push(axes.apply([p.x, p.y, p.z]));
            }
        }
        Ok(Clip {
            name,
            rate_hz: 1.0 / self.frame_time_s,
            landmarks: columns.iter().map(|&(l, _)| l).collect(),
            positions,
            filled: vec![false; self.frames()],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A two-joint arm: the root at (1, 0, 0) plus its position channels, a child 2 units
    /// along the root's x. Rotations in the listed order.
    const ARM: &str = "HIERARCHY
ROOT hip
{
  OFFSET 1 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT hand
  {
    OFFSET 2 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 0 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.01
0 0 0 0 0 0 0 0 0
0 0 5 90 0 0 0 0 0
0 0 0 90 90 0 0 0 0
";

    fn map() -> JointMap {
        [
            (Landmark::Pelvis, "hip".to_string()),
            (Landmark::RightWrist, "hand".to_string()),
        ]
        .into_iter()
        .collect()
    }

    /// Closed-form forward kinematics: the root's rotation carries the child's offset.
    #[test]
    fn joint_positions_follow_the_channels_in_their_order() {
        let bvh = Bvh::parse(ARM, Path::new("arm.bvh")).expect("parses");
        assert_eq!(bvh.frames(), 3);
        let clip = bvh
            .clip(&map(), 1.0, Axes::Z_UP, "arm".into(), Path::new("arm.bvh"))
            .expect("clip");
        assert!((clip.rate_hz - 100.0).abs() < 1e-9);
        let wrist = clip.track(Landmark::RightWrist);
        let pelvis = clip.track(Landmark::Pelvis);
        let near = |a: Vector, b: [f64; 3]| (a - Vector::new(b[0], b[1], b[2])).length() < 1e-12;
        assert!(near(pelvis[0], [1.0, 0.0, 0.0]) && near(wrist[0], [3.0, 0.0, 0.0]));
        // 90 degrees about z: the child's offset (2, 0, 0) turns to (0, 2, 0); z moved 5.
        assert!(near(pelvis[1], [1.0, 0.0, 5.0]) && near(wrist[1], [1.0, 2.0, 5.0]));
        // Rz(90) Rx(90) (x) = Rz(90) (x) = y: the intrinsic order, Rz first.
        assert!(near(wrist[2], [1.0, 2.0, 0.0]));
        // Against Rx(90) Rz(90) (x) = Rx(90) (y) = z, the other order.
        let swapped = ARM.replace(
            "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
            "CHANNELS 6 Xposition Yposition Zposition Xrotation Zrotation Yrotation",
        );
        let bvh = Bvh::parse(&swapped, Path::new("arm.bvh")).expect("parses");
        let clip = bvh
            .clip(&map(), 1.0, Axes::Z_UP, "arm".into(), Path::new("arm.bvh"))
            .expect("clip");
        // Frame 2 now holds X=90, Z=90 in that order: Rx(90) Rz(90) (2, 0, 0) = (0, 0, 2).
        assert!(near(clip.track(Landmark::RightWrist)[2], [1.0, 0.0, 2.0]));
    }

    /// A chain as the Vicon task clips' converter writes it: the root's header lists
    /// `Zrotation Yrotation Xrotation`, the elbow's `Zrotation Xrotation Yrotation`, and both
    /// hold angles z, x, y about fixed axes.
    const CHAIN: &str = "HIERARCHY
ROOT hip
{
  OFFSET 1 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT elbow
  {
    OFFSET 2 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT hand
    {
      OFFSET 0 3 0
      CHANNELS 0
      End Site
      {
        OFFSET 0 0 0
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.01
0 0 0 30 -20 50 -45 60 15
0 0 0 30 -20 50 -45 60 15
";

    /// Both conventions against SciPy 1.17.1: `Rotation.from_euler("zxy", ...)` (fixed axes)
    /// for `fixed_zxy`, `from_euler("ZYX", ...)` and `("ZXY", ...)` (moving axes, the
    /// headers' orders) for `listed`; the elbow at `hip + A (2, 0, 0)`, the hand at `elbow +
    /// A B (0, 3, 0)`.
    #[test]
    fn fixed_zxy_reads_angles_about_fixed_axes_whatever_the_header_lists() {
        let path = Path::new("chain.bvh");
        let map: JointMap = [
            (Landmark::Pelvis, "hip".to_string()),
            (Landmark::RightElbow, "elbow".to_string()),
            (Landmark::RightWrist, "hand".to_string()),
        ]
        .into_iter()
        .collect();
        let near = |a: Vector, b: [f64; 3]| (a - Vector::new(b[0], b[1], b[2])).length() < 1e-7;
        let mut bvh = Bvh::parse(CHAIN, path).expect("parses");
        for (euler, elbow, hand) in [
            (
                Euler::FixedZxy,
                [1.851_338_17, 0.939_692_62, -1.546_674_21],
                [3.226_551_43, 3.408_130_54, -2.554_445_37],
            ),
            (
                Euler::Listed,
                [2.627_595_36, 0.939_692_62, 0.684_040_29],
                [3.409_670_48, -0.119_658_6, 3.379_616_94],
            ),
        ] {
            bvh.euler = euler;
            let clip = bvh
                .clip(&map, 1.0, Axes::Z_UP, "chain".into(), path)
                .expect("clip");
            let e = clip.track(Landmark::RightElbow)[1];
            let h = clip.track(Landmark::RightWrist)[1];
            assert!(near(e, elbow), "{euler:?}: elbow {e:?}");
            assert!(near(h, hand), "{euler:?}: hand {h:?}");
        }
        // Two rotation channels are not three fixed-axis angles.
        let two = CHAIN
            .replace(
                "CHANNELS 3 Zrotation Xrotation Yrotation",
                "CHANNELS 2 Zrotation Xrotation",
            )
            .replace("-45 60 15\n", "-45 60\n");
        let mut bvh = Bvh::parse(&two, path).expect("parses");
        bvh.euler = Euler::FixedZxy;
        let err = bvh
            .clip(&map, 1.0, Axes::Z_UP, "two".into(), path)
            .expect_err("two rotation channels")
            .to_string();
        assert!(err.contains("\"elbow\" has 2 rotation channels"), "{err}");
    }

    #[test]
    fn a_broken_file_is_refused_with_its_line() {
        let path = Path::new("bad.bvh");
        for (text, needle) in [
            (ARM.replace("Frames: 3", "Frames: 4"), "the file ends"),
            (ARM.replace("0 0 5 90", "0 0 nan 90"), "not a finite number"),
            (
                ARM.replace("Frame Time: 0.01", "Frame Time: 0"),
                "frame time 0",
            ),
            (
                ARM.replace("CHANNELS 3 Zrotation", "CHANNELS 3 Qrotation"),
                ":9:",
            ),
            (ARM.replace("JOINT hand", "BONE hand"), "found `BONE`"),
            (format!("{ARM}1 2 3"), "after the 3 frames"),
        ] {
            let err = Bvh::parse(&text, path).expect_err(needle).to_string();
            assert!(err.contains(needle), "{needle}: {err}");
        }
        let bvh = Bvh::parse(ARM, path).expect("parses");
        let mut map = map();
        map.insert(Landmark::Head, "skull".into());
        let err = bvh
            .clip(&map, 1.0, Axes::Z_UP, "x".into(), path)
            .expect_err("no skull")
            .to_string();
        assert!(
            err.contains("\"skull\"") && err.contains("hip, hand"),
            "{err}"
        );
    }
}
