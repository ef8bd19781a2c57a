//! What a camera sees: posed meshes with classes.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{HumanPart, LinkId, RobotModel};

use crate::RenderMesh;

/// The segmentation classes (the class-index PNGs store these numbers). The human's classes
/// are its [`HumanPart`]s; files name every class in `snake_case` (`upper_arm`). The arms'
/// classes carry their side (`forearm` the right's, `left_forearm` the left's): the fit needs
/// each arm's own mask, and a side is what the body's layout in the image tells a network
/// (the left arm hangs from the left shoulder), where instance masks would leave the
/// network to number arms and the fit to match the numbers to sides. The right arm keeps the
/// numbers of the one-armed datasets, so their labels and the networks trained on them read
/// as before.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Class {
    Background = 0,
    Robot = 1,
    Torso = 2,
    UpperArm = 3,
    Forearm = 4,
    Hand = 5,
    LeftUpperArm = 6,
    LeftForearm = 7,
    LeftHand = 8,
}

impl Class {
    pub const ALL: [Class; 9] = [
        Class::Background,
        Class::Robot,
        Class::Torso,
        Class::UpperArm,
        Class::Forearm,
        Class::Hand,
        Class::LeftUpperArm,
        Class::LeftForearm,
        Class::LeftHand,
    ];

    /// Lower-case name (`upper_arm`); a human class is named as its part.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Class::Background => "background",
            Class::Robot => "robot",
            _ => self.human_part().map_or("background", HumanPart::name),
        }
    }

    /// The class named `name` (as [`Class::name`] writes it).
    #[must_use]
    pub fn from_name(name: &str) -> Option<Class> {
        Class::ALL.into_iter().find(|c| c.name() == name)
    }

    /// The class with number `k`.
    #[must_use]
    pub fn from_u8(k: u8) -> Option<Class> {
        Class::ALL.get(usize::from(k)).copied()
    }

    /// The human part this class shows, `None` for background and robot.
    #[must_use]
    pub fn human_part(self) -> Option<HumanPart> {
        match self {
            Class::Background | Class::Robot => None,
            Class::Torso => Some(HumanPart::Torso),
            Class::UpperArm => Some(HumanPart::UpperArm),
            Class::Forearm => Some(HumanPart::Forearm),
            Class::Hand => Some(HumanPart::Hand),
            Class::LeftUpperArm => Some(HumanPart::LeftUpperArm),
            Class::LeftForearm => Some(HumanPart::LeftForearm),
            Class::LeftHand => Some(HumanPart::LeftHand),
        }
    }

    /// The class that shows `part`: its own, the torso's for the head (the network's classes
    /// are the paper's: the head is drawn as the torso it sat on).
    #[must_use]
    pub fn of_part(part: HumanPart) -> Class {
        Class::from(part)
    }

    /// A colour to draw the class with (sRGB).
    #[must_use]
    pub fn color(self) -> [u8; 3] {
        match self {
            Class::Background => [0, 0, 0],
            Class::Robot => [255, 140, 0],
            Class::Torso => [70, 130, 230],
            Class::UpperArm => [60, 200, 90],
            Class::Forearm => [230, 40, 60],
            Class::Hand => [240, 220, 40],
            Class::LeftUpperArm => [30, 110, 50],
            Class::LeftForearm => [140, 20, 140],
            Class::LeftHand => [150, 120, 20],
        }
    }
}

impl From<HumanPart> for Class {
    fn from(part: HumanPart) -> Self {
        match part {
            HumanPart::Torso | HumanPart::Head => Class::Torso,
            HumanPart::UpperArm => Class::UpperArm,
            HumanPart::Forearm => Class::Forearm,
            HumanPart::Hand => Class::Hand,
            HumanPart::LeftUpperArm => Class::LeftUpperArm,
            HumanPart::LeftForearm => Class::LeftForearm,
            HumanPart::LeftHand => Class::LeftHand,
        }
    }
}

impl std::fmt::Display for Class {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Class {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Class::from_name(s).ok_or_else(|| {
            format!(
                "unknown class {s:?} (one of {})",
                Class::ALL.map(Class::name).join(", ")
            )
        })
    }
}

/// The class of each link of a human model: by link name ([`HumanPart::of_link_name`]),
/// other links inheriting their parent's class; the root defaults to torso.
#[must_use]
pub fn human_classes(human: &RobotModel) -> Vec<Class> {
    let mut classes = vec![Class::Torso; human.links().len()];
    // Links are stored parents first.
    for (l, link) in human.links().iter().enumerate() {
        let inherited = link
            .parent_joint
            .map_or(Class::Torso, |j| classes[human.joints()[j].parent]);
        classes[l] = HumanPart::of_link_name(&link.name).map_or(inherited, Class::from);
    }
    classes
}

/// One posed mesh.
#[derive(Debug, Clone)]
pub struct SceneObject {
    pub name: String,
    pub class: Class,
    pub mesh: Arc<RenderMesh>,
    /// Amplitude of the value-noise texture, 0 for a plain surface.
    pub texture: f32,
    /// Pose of the mesh frame O in the world.
    pub X_WO: Pose,
}

/// Posed meshes and the light.
#[derive(Debug, Clone)]
pub struct Scene {
    pub objects: Vec<SceneObject>,
    /// Unit direction towards the (directional) light, world frame.
    pub light_W: [f32; 3],
    /// Linear RGB where nothing is seen.
    pub sky: [f32; 3],
}

impl Default for Scene {
    fn default() -> Self {
        let l = Vector::new(0.35, -0.5, 1.0).normalize();
        Self {
            objects: Vec::new(),
            light_W: [l.x as f32, l.y as f32, l.z as f32],
            sky: [0.55, 0.6, 0.68],
        }
    }
}

impl Scene {
    /// The class of object index `id` (0 and unknown indices are background).
    #[must_use]
    pub fn class_of(&self, id: u16) -> Class {
        usize::from(id)
            .checked_sub(1)
            .and_then(|k| self.objects.get(k))
            .map_or(Class::Background, |o| o.class)
    }

    /// Adds an object; returns its index in `objects` (its pixels show `index + 1`).
    pub fn push(&mut self, object: SceneObject) -> usize {
        self.objects.push(object);
        self.objects.len() - 1
    }

    /// Number of triangles.
    #[must_use]
    pub fn triangle_count(&self) -> usize {
        self.objects.iter().map(|o| o.mesh.len()).sum()
    }
}

/// One object per link with visuals, its meshes merged in the link frame.
pub fn link_objects(
    scene: &mut Scene,
    model: &RobotModel,
    prefix: &str,
    class: impl Fn(LinkId) -> Class,
    default_color: [f32; 3],
) -> Vec<Option<usize>> {
    model
        .links()
        .iter()
        .enumerate()
        .map(|(l, link)| {
            let mut mesh = RenderMesh::default();
            for g in &link.visuals {
                mesh.append(
                    &RenderMesh::from_geometry(g, default_color),
                    &Pose::IDENTITY,
                );
            }
            (!mesh.is_empty()).then(|| {
                scene.push(SceneObject {
                    name: format!("{prefix}/{}", link.name),
                    class: class(l),
                    mesh: Arc::new(mesh),
                    texture: 0.0,
                    X_WO: Pose::IDENTITY,
                })
            })
        })
        .collect()
}
