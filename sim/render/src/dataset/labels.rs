//! What a dataset stores besides images: per-frame labels and the manifest.

use serde::{Deserialize, Serialize};
use workcell_robots::math::{Pose, Rotation, Vector, pose_to_xyz_rpy};

use crate::Class;
use crate::occlusion::Occluder;
use crate::roi::{Roi, RoiKind};
use workcell_robots::HumanLook;

/// The layout version written into manifests.
pub const FORMAT: &str = "workcell-dataset/3";

/// Formats this version reads: 1 (whole 128x128 frames, skeletal human, no regions of
/// interest or depth), 2 (depth images that show the scene behind the occluder,
/// [`SEES_THROUGH_OCCLUDER`]) and 3 (the occluder in the depth image too).
pub const READS: [&str; 3] = ["workcell-dataset/1", SEES_THROUGH_OCCLUDER, FORMAT];

/// The format whose depth images show the scene behind the artificial occluder:
/// [`crate::dataset::Dataset::depth`] puts the occluder back in front.
pub const SEES_THROUGH_OCCLUDER: &str = "workcell-dataset/2";

/// A pose as stored: position, roll-pitch-yaw (URDF convention) and the quaternion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseLabel {
    pub xyz_m: [f64; 3],
    pub rpy_rad: [f64; 3],
    /// `[x, y, z, w]`.
    pub quaternion_xyzw: [f64; 4],
}

impl From<&Pose> for PoseLabel {
    fn from(X: &Pose) -> Self {
        let (xyz_m, rpy_rad) = pose_to_xyz_rpy(X);
        Self {
            xyz_m,
            rpy_rad,
            quaternion_xyzw: X.rotation.to_array(),
        }
    }
}

impl From<&PoseLabel> for Pose {
    /// The pose back from its position and quaternion (the rpy are redundant).
    fn from(label: &PoseLabel) -> Self {
        let [x, y, z, w] = label.quaternion_xyzw;
        Pose::from_parts(
            Vector::from_array(label.xyz_m),
            Rotation::from_xyzw(x, y, z, w).normalize(),
        )
    }
}

/// The camera of a sequence.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraLabel {
    pub width_px: u32,
    pub height_px: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    /// Camera frame (x right, y down, z forward) in the world.
    pub X_WC: PoseLabel,
}

impl From<&CameraLabel> for crate::Camera {
    fn from(c: &CameraLabel) -> Self {
        Self {
            width: c.width_px,
            height: c.height_px,
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
            X_WC: Pose::from(&c.X_WC),
        }
    }
}

/// One segmented part (a class) in one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartLabel {
    /// The class (`forearm` in the file).
    pub class: Class,
    /// The link whose frame `X_CP` is (the human's link of that name; for `robot`, the base).
    pub link: String,
    /// Pose of the part's link frame in the camera frame.
    pub X_CP: PoseLabel,
    /// Pixels of the part rendered alone.
    pub pixels_amodal: u32,
    /// Pixels where the scene shows it (occluded only by other objects).
    pub pixels_unoccluded: u32,
    /// Pixels visible through the artificial occluder as well.
    pub pixels_visible: u32,
    /// Hidden over all pixels (robot and occluder); `null` when the part is out of view.
    pub occlusion: Option<f64>,
    /// Hidden by other objects only.
    pub natural_occlusion: Option<f64>,
    /// Width of the part rendered alone in the stored frame, px (`roi::mask_width` of its
    /// mask at the camera's resolution, scaled to the frame's); absent in format 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width_px: Option<f64>,
    /// The Dice loss of a perfect network at the stored frame's size
    /// (`roi::perfect_dice_loss` of the part's mask at the camera's resolution); absent in
    /// format 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub perfect_dice_loss: Option<f64>,
}

/// Where a stored frame comes from in its camera's image: the camera at its own resolution
/// and the region of interest that was resampled to the stored frame ([`FrameLabels::camera`]
/// is the region's camera).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RoiLabel {
    pub kind: RoiKind,
    /// The camera at its native resolution.
    pub native: CameraLabel,
    pub roi: Roi,
}

/// The labels of one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameLabels {
    pub sequence: usize,
    pub frame: usize,
    /// Simulated time of the frame, s.
    pub time_s: f64,
    pub distance_class: String,
    /// Lens to cell centre, m.
    pub distance_m: f64,
    pub occlusion_level: String,
    /// The camera source: `paper` (the paper's distance classes) or `camera:<name>` (a
    /// camera of the cell, jittered). `paper` in format 1.
    #[serde(default)]
    pub source: ViewSource,
    /// The region of the native camera's image this frame shows (absent in format 1: the
    /// frame is the whole image).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roi: Option<RoiLabel>,
    /// The forearm occlusion the occluder was sized for.
    pub target_occlusion: f64,
    pub occluder: Occluder,
    pub camera: CameraLabel,
    pub parts: Vec<PartLabel>,
    /// Robot joint positions, rad.
    pub robot_q: Vec<f64>,
    /// Human joint positions, rad.
    pub human_q: Vec<f64>,
}

impl FrameLabels {
    /// The label of `class`.
    #[must_use]
    pub fn part(&self, class: Class) -> Option<&PartLabel> {
        self.parts.iter().find(|p| p.class == class)
    }

    /// The angle between the torso's forward axis (the human model's x) and the direction
    /// from the torso to the camera, in degrees: 0 sees the human from the front, 180 from
    /// behind. `None` without a torso label (or with the camera at the torso's origin).
    #[must_use]
    pub fn view_angle_deg(&self) -> Option<f64> {
        View::angle_deg(&Pose::from(&self.part(Class::Torso)?.X_CP))
    }

    /// The side from which the camera sees the human ([`FrameLabels::view_angle_deg`]).
    #[must_use]
    pub fn view(&self) -> Option<View> {
        self.view_angle_deg().map(View::of_angle_deg)
    }
}

/// The side from which the camera sees the human: the view angle
/// ([`FrameLabels::view_angle_deg`]) below 60 degrees, from 60 to 120, from 120 on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum View {
    Front,
    Side,
    Back,
}

impl View {
    pub const ALL: [View; 3] = [View::Front, View::Side, View::Back];

    /// The view angle of a torso at `X_CT` in the camera's frame, degrees: between its
    /// forward axis (x) and the direction from it to the camera's origin.
    #[must_use]
    pub fn angle_deg(X_CT: &Pose) -> Option<f64> {
        let forward = X_CT.rotation * Vector::X;
        let to_camera = -X_CT.translation;
        let n = forward.length() * to_camera.length();
        (n > 0.0 && n.is_finite()).then(|| {
            (forward.dot(to_camera) / n)
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees()
        })
    }

    /// The view of a view angle in degrees.
    #[must_use]
    pub fn of_angle_deg(angle: f64) -> View {
        if angle < 60.0 {
            View::Front
        } else if angle < 120.0 {
            View::Side
        } else {
            View::Back
        }
    }

    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            View::Front => "front",
            View::Side => "side",
            View::Back => "back",
        }
    }
}

/// Train, validation or test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Split {
    Train,
    Validation,
    Test,
}

impl Split {
    pub const ALL: [Split; 3] = [Split::Train, Split::Validation, Split::Test];

    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Validation => "validation",
            Split::Test => "test",
        }
    }
}

/// The human of a dataset: its model and where its base stands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HumanLabel {
    /// Catalogue name or URDF path of the human model (`human_arm`).
    pub model: String,
    /// The human's base frame H in the world.
    pub X_WH: PoseLabel,
    /// What the frames show of it (format 1 datasets are skeletal).
    #[serde(default = "skeletal")]
    pub look: HumanLook,
}

fn skeletal() -> HumanLook {
    HumanLook::Skeletal
}

/// Where a sequence's camera comes from: the paper's distance classes, or a camera of the
/// cell by name (jittered). Written `paper` or `camera:<name>`; `paper` in format 1.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum ViewSource {
    /// A camera of the cell. Listed first so that sources sort as their written names do
    /// (`camera:...` before `paper`).
    Camera(String),
    /// The paper's cameras at its distance classes.
    #[default]
    Paper,
}

impl ViewSource {
    /// The cell camera's name, if it is one.
    #[must_use]
    pub fn camera(&self) -> Option<&str> {
        match self {
            Self::Camera(name) => Some(name),
            Self::Paper => None,
        }
    }
}

impl std::fmt::Display for ViewSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Paper => f.pad("paper"),
            Self::Camera(name) => f.pad(&format!("camera:{name}")),
        }
    }
}

impl TryFrom<String> for ViewSource {
    type Error = String;

    fn try_from(text: String) -> Result<Self, String> {
        match text.strip_prefix("camera:") {
            _ if text == "paper" => Ok(Self::Paper),
            Some(name) if !name.is_empty() => Ok(Self::Camera(name.to_string())),
            _ => Err(format!(
                "camera source {text:?}: `paper` or `camera:<name>`"
            )),
        }
    }
}

impl From<ViewSource> for String {
    fn from(source: ViewSource) -> Self {
        source.to_string()
    }
}

/// One sequence as the manifest lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequenceEntry {
    pub index: usize,
    /// Folder relative to the dataset root.
    pub dir: String,
    /// The scenario seed of its episode.
    pub seed: u64,
    /// Draws before its camera and start time kept the forearm in view (1 = first draw).
    pub attempts: usize,
    pub distance_class: String,
    pub occlusion_level: String,
    /// As [`FrameLabels::source`].
    #[serde(default)]
    pub source: ViewSource,
    pub split: Split,
    pub frames: usize,
    /// Mean forearm occlusion over the frames that show it.
    pub mean_forearm_occlusion: Option<f64>,
    /// Frames where the forearm is out of view.
    pub frames_without_forearm: usize,
    /// The recorded clip its human plays (a library id); none for the motion generator.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clip: Option<String>,
}

impl SequenceEntry {
    /// The row a sequence is reported under: its distance class for the paper's cameras, the
    /// camera's name for a camera of the cell (`camera:front` -> `front camera`), which sees
    /// the arm from its own distance.
    #[must_use]
    pub fn camera_class(&self) -> String {
        self.source.camera().map_or_else(
            || self.distance_class.clone(),
            |name| format!("{name} camera"),
        )
    }
}

/// The manifest: everything needed to regenerate the dataset bit for bit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub generator: String,
    /// The dataset configuration, as TOML.
    pub config: String,
    /// The cell's scenario, as TOML (its seed is replaced per sequence).
    pub scenario: String,
    /// The classes in the order of their numbers in the class PNGs.
    pub classes: Vec<Class>,
    /// The human model the frames show, for perception's own model of the arm (absent in
    /// datasets written before it was recorded: regenerate them).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub human: Option<HumanLabel>,
    /// Size of the stored frames (the network's input from format 2 on).
    pub width_px: u32,
    pub height_px: u32,
    pub sequences: Vec<SequenceEntry>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use workcell_robots::math::pose_from_xyz_rpy;

    #[test]
    fn pose_labels_round_trip() {
        let X = pose_from_xyz_rpy([0.3, -1.2, 2.5], [0.4, -0.9, 2.8]);
        let back = Pose::from(&PoseLabel::from(&X));
        assert!((back.translation - X.translation).length() < 1e-15);
        assert!((back.rotation.dot(X.rotation).abs() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn view_angles_of_known_torso_poses() {
        // The torso 5 m down the optical axis (+z); a quarter turn about y sends its
        // forward x to -z (toward the camera), the opposite turn to +z (away from it).
        let at = |xyz: [f64; 3], pitch: f64| {
            View::angle_deg(&pose_from_xyz_rpy(xyz, [0.0, pitch, 0.0]))
                .expect("a torso off the origin")
        };
        let quarter = std::f64::consts::FRAC_PI_2;
        for (xyz, pitch, want, view) in [
            ([0.0, 0.0, 5.0], quarter, 0.0, View::Front),
            ([0.0, 0.0, 5.0], 0.0, 90.0, View::Side),
            ([0.0, 0.0, 5.0], -quarter, 180.0, View::Back),
            // Off the axis: facing -z from (5, 0, 5), the camera lies 45 degrees aside.
            ([5.0, 0.0, 5.0], quarter, 45.0, View::Front),
            ([-5.0, 0.0, 5.0], -quarter, 135.0, View::Back),
        ] {
            let angle = at(xyz, pitch);
            assert!((angle - want).abs() < 1e-9, "{xyz:?} {pitch}: {angle}");
            assert_eq!(View::of_angle_deg(angle), view);
        }
        assert_eq!(
            View::angle_deg(&Pose::IDENTITY),
            None,
            "the camera at the torso"
        );
        assert_eq!(
            [59.9, 60.0, 119.9, 120.0].map(View::of_angle_deg),
            [View::Front, View::Side, View::Side, View::Back]
        );
    }
}
