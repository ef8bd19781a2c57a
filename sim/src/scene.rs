//! The scene of a cell: the room, the clutter, the robot's and the human's links, posed from
//! a [`CellState`].

use std::sync::Arc;

use rand::Rng;
use workcell_render::{Class, RenderMesh, Scene, SceneObject, human_classes, link_objects};
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{HumanLook, LinkId};

use crate::cell::{CellModel, CellState};

/// Texture amplitude of floor, walls, shelves and boxes.
const TEXTURE: f32 = 0.35;

/// Skin tones from light to dark, sRGB (a spread of the Fitzpatrick types I-VI).
const SKIN_SRGB: [[u8; 3]; 6] = [
    [243, 214, 190],
    [226, 185, 152],
    [198, 148, 110],
    [161, 110, 75],
    [112, 72, 48],
    [72, 46, 32],
];

/// What the human wears: the colours of the flesh look's roles (linear RGB, as meshes take
/// them) and the texture of the clothes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Appearance {
    pub skin: [f32; 3],
    /// Shirt and sleeves.
    pub cloth: [f32; 3],
    /// Value-noise amplitude on clothed links (0 plain).
    pub cloth_texture: f32,
    /// Sleeves down to the wrist: the forearm is dressed in `cloth`.
    pub long_sleeves: bool,
}

impl Default for Appearance {
    /// The model's own colours: mid skin, a blue shirt, short sleeves.
    fn default() -> Self {
        Self {
            skin: [0.85, 0.68, 0.55],
            cloth: [0.2, 0.35, 0.55],
            cloth_texture: 0.0,
            long_sleeves: false,
        }
    }
}

impl Appearance {
    /// A person drawn from `rng`: one of six skin tones (lightness varied by 10 %), a shirt
    /// of any hue, saturation and lightness, plain or textured, with long sleeves three
    /// times in ten.
    pub fn random(rng: &mut impl Rng) -> Self {
        let linear = |c: f64| ((c + 0.055) / 1.055).powf(2.4) as f32;
        let tone = SKIN_SRGB[rng.random_range(0..SKIN_SRGB.len())];
        let k = rng.random_range(0.9..=1.1);
        let skin = tone.map(|c| linear((f64::from(c) / 255.0 * k).min(1.0)));
        let (hue, sat, val) = (
            rng.random_range(0.0..6.0),
            rng.random_range(0.0..=0.85),
            rng.random_range(0.12..=0.95),
        );
        // HSV to RGB.
        let c = val * sat;
        let x = c * (1.0 - (hue % 2.0 - 1.0f64).abs());
        let (r, g, b) = match hue as u32 {
            0 => (c, x, 0.0),
            1 => (x, c, 0.0),
            2 => (0.0, c, x),
            3 => (0.0, x, c),
            4 => (x, 0.0, c),
            _ => (c, 0.0, x),
        };
        let m = val - c;
        Self {
            skin,
            cloth: [r + m, g + m, b + m].map(linear),
            cloth_texture: if rng.random_bool(0.5) {
                rng.random_range(0.1..=0.5)
            } else {
                0.0
            },
            long_sleeves: rng.random_bool(0.3),
        }
    }

    /// The colour of a flesh visual's role (`skin`, `sleeve`, `shirt`, `forearm`); `None`
    /// for other visuals (they keep their own colour).
    #[must_use]
    pub fn colour(&self, role: &str) -> Option<[f32; 3]> {
        match role {
            "skin" => Some(self.skin),
            "sleeve" | "shirt" => Some(self.cloth),
            "forearm" => Some(if self.long_sleeves {
                self.cloth
            } else {
                self.skin
            }),
            _ => None,
        }
    }
}

/// The scene of a cell: a room (floor, two walls), the clutter, the robot's and the human's
/// links. [`CellScene::update`] poses the links from a [`CellState`].
#[derive(Debug, Clone)]
pub struct CellScene {
    pub scene: Scene,
    /// Object index of each robot link (links without visuals have none).
    pub robot_objects: Vec<Option<usize>>,
    /// Object index of each human link.
    pub human_objects: Vec<Option<usize>>,
    /// The human link whose class is [`Class::Forearm`], if any.
    pub forearm_link: Option<LinkId>,
}

impl CellScene {
    /// Builds the scene of `model`, with links at the model's initial configuration.
    #[must_use]
    pub fn new(model: &CellModel) -> Self {
        let mut scene = Scene::default();
        let mut environment = |name: &str, mesh: RenderMesh, X_WO: Pose| {
            scene.push(SceneObject {
                name: name.into(),
                class: Class::Background,
                mesh: Arc::new(mesh),
                texture: TEXTURE,
                X_WO,
            });
        };
        // The room: a concrete floor and two walls behind the cell (beyond the clutter's
        // extent towards -x and -y), so that far cameras on the open sides see a background.
        let (lo, hi) = clutter_extent(model);
        let centre = 0.5 * (lo + hi);
        environment(
            "floor",
            RenderMesh::cuboid([20.0, 20.0, 0.01], [0.42, 0.42, 0.40]),
            Pose::from_translation(Vector::new(centre.x, centre.y, -0.01)),
        );
        let wall_h = 3.0;
        environment(
            "wall_x",
            RenderMesh::cuboid([0.05, 8.0, wall_h / 2.0], [0.75, 0.73, 0.68]),
            Pose::from_translation(Vector::new(lo.x - 0.3, centre.y, wall_h / 2.0)),
        );
        environment(
            "wall_y",
            RenderMesh::cuboid([8.0, 0.05, wall_h / 2.0], [0.70, 0.72, 0.74]),
            Pose::from_translation(Vector::new(centre.x, lo.y - 0.3, wall_h / 2.0)),
        );
        const PALETTE: [[f32; 3]; 4] = [
            [0.55, 0.38, 0.22], // wood
            [0.15, 0.30, 0.60], // shelf blue
            [0.60, 0.45, 0.28], // cardboard
            [0.50, 0.50, 0.52], // steel
        ];
        for (k, c) in model.clutter.iter().enumerate() {
            environment(
                &format!("clutter_{k}"),
                RenderMesh::cuboid(c.half_extents_m, PALETTE[k % PALETTE.len()]),
                c.X_WC,
            );
        }

        let robot_objects = link_objects(
            &mut scene,
            &model.robot,
            "robot",
            |_| Class::Robot,
            [0.93, 0.45, 0.08],
        );
        let classes = human_classes(&model.human);
        let human_objects = link_objects(
            &mut scene,
            &model.human,
            "human",
            |l| classes[l],
            [0.85, 0.72, 0.62],
        );
        let forearm_link = classes.iter().position(|&c| c == Class::Forearm);
        let mut out = Self {
            scene,
            robot_objects,
            human_objects,
            forearm_link,
        };
        let robot = model
            .robot
            .fk(model.X_WR, &model.initial_q)
            .map(|k| k.link_poses().to_vec())
            .unwrap_or_default();
        let mut q = vec![0.0; model.human.dof()];
        let mut qd = q.clone();
        model.human_motion.sample(0.0, &mut q, &mut qd);
        let human = model
            .human
            .fk(model.X_WH, &q)
            .map(|k| k.link_poses().to_vec())
            .unwrap_or_default();
        out.set_link_poses(&robot, &human);
        out
    }

    /// Dresses the human's flesh in `appearance`: its links' meshes are rebuilt with the
    /// colours of their visuals' roles (see [`HumanLook::role`]) and its clothed links get
    /// the cloth's texture. Visuals without a role keep their colours.
    pub fn dress(&mut self, model: &CellModel, appearance: &Appearance) {
        for (link, object) in model.human.links().iter().zip(&self.human_objects) {
            let Some(k) = *object else { continue };
            let mut mesh = RenderMesh::default();
            let mut clothed = false;
            for g in &link.visuals {
                let role = HumanLook::role(g.name.as_deref());
                clothed |= matches!(role, Some("sleeve" | "shirt"))
                    || (role == Some("forearm") && appearance.long_sleeves);
                let colour = role.and_then(|r| appearance.colour(r));
                let g = workcell_robots::Geometry {
                    rgba: colour.map_or(g.rgba, |_| None),
                    ..g.clone()
                };
                mesh.append(
                    &RenderMesh::from_geometry(&g, colour.unwrap_or([0.85, 0.72, 0.62])),
                    &Pose::IDENTITY,
                );
            }
            let object = &mut self.scene.objects[k];
            object.mesh = Arc::new(mesh);
            object.texture = if clothed {
                appearance.cloth_texture
            } else {
                0.0
            };
        }
    }

    /// Poses the links as in `state`.
    pub fn update(&mut self, state: &CellState) {
        let robot = state.robot_link_poses();
        self.set_link_poses(&robot, state.human_link_poses());
    }

    /// Poses the links from their world poses (indexed by link id; missing ones are left).
    pub fn set_link_poses(&mut self, robot: &[Pose], human: &[Pose]) {
        for (objects, poses) in [(&self.robot_objects, robot), (&self.human_objects, human)] {
            for (object, X_WL) in objects.iter().zip(poses) {
                if let Some(k) = object {
                    self.scene.objects[*k].X_WO = *X_WL;
                }
            }
        }
    }

    /// The forearm's object index in `scene.objects`.
    #[must_use]
    pub fn forearm_object(&self) -> Option<usize> {
        self.forearm_link
            .and_then(|l| self.human_objects.get(l).copied().flatten())
    }
}

/// The axis-aligned bounds of the clutter (the origin's neighbourhood if there is none).
fn clutter_extent(model: &CellModel) -> (Vector, Vector) {
    let (mut lo, mut hi) = (Vector::splat(-0.5), Vector::splat(0.5));
    for c in &model.clutter {
        let h = Vector::from_array(c.half_extents_m);
        let R = parry3d_f64::glamx::DMat3::from_quat(c.X_WC.rotation);
        let extent = R.abs() * h;
        lo = lo.min(c.X_WC.translation - extent);
        hi = hi.max(c.X_WC.translation + extent);
    }
    (lo, hi)
}
