//! Episodes as animated binary glTF (`.glb`), to look at in any glTF viewer or in
//! `summary.html`: the room and the clutter, the robot's links with their visual meshes and
//! colours, the human's parts, the closest robot-human pair as a line coloured by its
//! margin to d_min, and the cell's cameras with their frusta.
//!
//! The cell is Z-up; glTF is Y-up. Every node hangs under one root node that turns the
//! cell's +Z into glTF's +Y, so the nodes below it carry the simulator's world poses as
//! they are.

use std::collections::BTreeMap;

use serde_json::json;
use workcell_render::{Camera, RenderMesh};
use workcell_robots::glb::GlbBuilder;
use workcell_robots::math::{Pose, Rotation, Vector};
use workcell_sim::CellModel;
use workcell_sim::CellScene;

use super::Recording;

/// Name of the root node (the Z-up to Y-up turn).
pub const ROOT_NODE: &str = "cell (Z up)";
/// Prefixes of the animated nodes' names: `robot/<link>`, `human/<link>`.
pub const ROBOT_PREFIX: &str = "robot/";
pub const HUMAN_PREFIX: &str = "human/";
/// Prefix of a recorded clip's other arm's parts (`Recording::other_arm`): the arm the cell's
/// human does not model, drawn apart from it (only some perceptions see it).
pub const OTHER_ARM_PREFIX: &str = "other arm (not modelled)/";
/// Its colour: grey, unlike the dressed human.
const OTHER_ARM_COLOR: [f32; 3] = [0.55, 0.55, 0.6];
/// The other arm's parts, in `Recording::other_arm`'s order.
pub const OTHER_ARM_PARTS: [&str; 3] = ["upper_arm", "forearm", "hand"];
/// The closest pair's line nodes, one per margin class; the inactive ones are scaled to 0.
pub const PAIR_NODES: [(&str, [f32; 4]); 3] = [
    ("closest pair: below d_min", [0.9, 0.05, 0.05, 1.0]),
    ("closest pair: within 0.1 m of d_min", [0.95, 0.6, 0.0, 1.0]),
    ("closest pair: clear", [0.1, 0.7, 0.2, 1.0]),
];
/// The marker on the closest pair's human point (a sphere, visible with its line: a line is
/// one pixel wide and vanishes at contact), per margin class: `PAIR_NODES`' name + this.
pub const MARKER_SUFFIX: &str = " (human point)";
/// Radius of the marker, m.
const MARKER_RADIUS_M: f64 = 0.04;
/// Margin to d_min below which the pair's line turns from green to amber, m.
pub const AMBER_MARGIN_M: f64 = 0.1;
/// Depth of the drawn camera frusta, m.
const FRUSTUM_DEPTH_M: f64 = 0.4;

/// The margin class of a pair at `distance_m` (index into [`PAIR_NODES`]).
#[must_use]
pub fn pair_class(distance_m: f64, d_min_m: f64) -> usize {
    if distance_m < d_min_m {
        0
    } else if distance_m < d_min_m + AMBER_MARGIN_M {
        1
    } else {
        2
    }
}

/// The quaternion of `pose` as glTF writes it (x, y, z, w).
fn quaternion(r: Rotation) -> [f32; 4] {
    [r.x as f32, r.y as f32, r.z as f32, r.w as f32]
}

fn translation(v: Vector) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// A node's static transform.
fn trs(pose: &Pose) -> serde_json::Value {
    json!({"translation": translation(pose.translation), "rotation": quaternion(pose.rotation)})
}

/// `mesh` as one glTF mesh: one primitive per colour, sharing the positions.
fn add_render_mesh(glb: &mut GlbBuilder, name: &str, mesh: &RenderMesh) -> Option<usize> {
    if mesh.is_empty() {
        return None;
    }
    let mut by_colour: BTreeMap<[u32; 3], Vec<u32>> = BTreeMap::new();
    for (t, c) in mesh.triangles.iter().zip(&mesh.colors) {
        by_colour
            .entry(c.map(f32::to_bits))
            .or_default()
            .extend_from_slice(t);
    }
    let groups: Vec<(Vec<u32>, [f32; 4])> = by_colour
        .into_iter()
        .map(|(c, indices)| {
            let [r, g, b] = c.map(f32::from_bits);
            (indices, [r, g, b, 1.0])
        })
        .collect();
    Some(glb.mesh_groups(name, &mesh.positions, &groups))
}

/// The episode in `recording` as a binary glTF file with one animation (`name`).
#[must_use]
pub fn episode_glb(
    model: &CellModel,
    cameras: &[(String, Camera)],
    recording: &Recording,
    d_min_m: f64,
    name: &str,
) -> Vec<u8> {
    let scene = CellScene::new(model);
    let mut glb = GlbBuilder::new();
    let mut children = Vec::new();
    let t0 = recording.t_s.first().copied().unwrap_or(0.0);
    let times: Vec<f32> = recording.t_s.iter().map(|t| (t - t0) as f32).collect();
    let times = (!times.is_empty()).then(|| glb.floats(&times, 1, false));

    // Static objects (room, clutter), then the links, animated.
    let animated: BTreeMap<usize, (&str, usize, bool)> =
        scene
            .robot_objects
            .iter()
            .enumerate()
            .filter_map(|(l, o)| o.map(|o| (o, (model.robot.links()[l].name.as_str(), l, true))))
            .chain(scene.human_objects.iter().enumerate().filter_map(|(l, o)| {
                o.map(|o| (o, (model.human.links()[l].name.as_str(), l, false)))
            }))
            .collect();
    for (k, object) in scene.scene.objects.iter().enumerate() {
        let (node_name, link) = match animated.get(&k) {
            Some(&(link_name, l, robot)) => (
                format!(
                    "{}{link_name}",
                    if robot { ROBOT_PREFIX } else { HUMAN_PREFIX }
                ),
                Some((l, robot)),
            ),
            None => (object.name.clone(), None),
        };
        let Some(mesh) = add_render_mesh(&mut glb, &node_name, &object.mesh) else {
            continue;
        };
        let mut props = trs(&object.X_WO);
        props["mesh"] = json!(mesh);
        let node = glb.node(&node_name, props, false);
        children.push(node);
        if let (Some((l, robot)), Some(times)) = (link, times) {
            let poses = if robot {
                &recording.robot_link_poses
            } else {
                &recording.human_link_poses
            };
            let series: Vec<Pose> = poses
                .iter()
                .map(|p| p.get(l).copied().unwrap_or(object.X_WO))
                .collect();
            animate_pose(&mut glb, node, times, &series);
        }
    }

    // A recorded clip's other arm: each part a capsule of its (fixed) size, placed along its
    // segment at each sample; hidden (scale 0) where a sample has none.
    if let Some(times) = times
        && let Some(first) = recording.other_arm.iter().find(|s| !s.is_empty())
    {
        for (k, (part, capsule)) in OTHER_ARM_PARTS.iter().zip(first).enumerate() {
            let length = (capsule.b_W - capsule.a_W).length();
            let mesh = RenderMesh::capsule(capsule.radius_m, length, OTHER_ARM_COLOR);
            let node_name = format!("{OTHER_ARM_PREFIX}{part}");
            let Some(mesh) = add_render_mesh(&mut glb, &node_name, &mesh) else {
                continue;
            };
            let node = glb.node(&node_name, json!({"mesh": mesh}), false);
            children.push(node);
            let mut previous = Pose::IDENTITY;
            let (mut poses, mut scale) = (Vec::new(), Vec::new());
            for sample in &recording.other_arm {
                match sample.get(k) {
                    Some(c) => {
                        // The capsule mesh lies along z about its centre.
                        let axis = (c.b_W - c.a_W).normalize_or(Vector::Z);
                        previous = Pose::from_parts(
                            (c.a_W + c.b_W) * 0.5,
                            Rotation::from_rotation_arc(Vector::Z, axis),
                        );
                        scale.extend([1.0_f32; 3]);
                    }
                    None => scale.extend([0.0_f32; 3]),
                }
                poses.push(previous);
            }
            animate_pose(&mut glb, node, times, &poses);
            glb.animate(node, "scale", times, &scale, "STEP");
        }
    }

    // The closest pair: a unit line along x, placed at the robot point, turned toward the
    // human point and stretched to the distance; only its margin class's node is visible.
    let line = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    for (class, (pair_name, rgba)) in PAIR_NODES.iter().enumerate() {
        let mesh = glb.mesh_lines(pair_name, &line, &[0, 1], *rgba);
        let node = glb.node(
            pair_name,
            json!({"mesh": mesh, "scale": [0.0, 0.0, 0.0]}),
            false,
        );
        children.push(node);
        let Some(times) = times else { continue };
        let (mut tr, mut rot, mut sc) = (Vec::new(), Vec::new(), Vec::new());
        for pair in &recording.closest {
            let (p, r, s) = match pair {
                Some((a, b, d)) if pair_class(*d, d_min_m) == class => {
                    let (a, b) = (Vector::from_array(*a), Vector::from_array(*b));
                    let ab = b - a;
                    let rotation = if ab.length() > 1e-12 {
                        Rotation::from_rotation_arc(Vector::X, ab.normalize())
                    } else {
                        Rotation::IDENTITY
                    };
                    (
                        translation(a),
                        quaternion(rotation),
                        [ab.length() as f32, 1.0, 1.0],
                    )
                }
                _ => ([0.0; 3], [0.0, 0.0, 0.0, 1.0], [0.0; 3]),
            };
            tr.extend(p);
            rot.extend(r);
            sc.extend(s);
        }
        glb.animate(node, "translation", times, &tr, "STEP");
        glb.animate(node, "rotation", times, &rot, "STEP");
        glb.animate(node, "scale", times, &sc, "STEP");
        // The marker at the human point, shown with the line.
        let [r, g, b, _] = *rgba;
        let sphere = RenderMesh::capsule(MARKER_RADIUS_M, 0.0, [r, g, b]);
        let marker_name = format!("{pair_name}{MARKER_SUFFIX}");
        let Some(mesh) = add_render_mesh(&mut glb, &marker_name, &sphere) else {
            continue;
        };
        let marker = glb.node(
            &marker_name,
            json!({"mesh": mesh, "scale": [0.0, 0.0, 0.0]}),
            false,
        );
        children.push(marker);
        let (mut tr, mut sc) = (Vec::new(), Vec::new());
        for pair in &recording.closest {
            match pair {
                Some((_, b, d)) if pair_class(*d, d_min_m) == class => {
                    tr.extend(b.map(|x| x as f32));
                    sc.extend([1.0; 3]);
                }
                _ => {
                    tr.extend([0.0; 3]);
                    sc.extend([0.0; 3]);
                }
            }
        }
        glb.animate(marker, "translation", times, &tr, "STEP");
        glb.animate(marker, "scale", times, &sc, "STEP");
    }

    // Cameras: a glTF camera looks along its -z with +y up; the project's camera frame C
    // has x right, y down, z forward: a half turn about x between them.
    let flip = Rotation::from_rotation_x(std::f64::consts::PI);
    for (camera_name, camera) in cameras {
        let aspect = f64::from(camera.width) / f64::from(camera.height);
        let yfov = 2.0 * (0.5 * f64::from(camera.height) / camera.fy).atan();
        let c = glb.camera(camera_name, yfov, aspect, 0.05);
        let X_WC = camera.X_WC;
        let mut props = json!({
            "camera": c,
            "translation": translation(X_WC.translation),
            "rotation": quaternion(X_WC.rotation * flip),
        });
        props["extras"] = json!({"kind": "camera"});
        children.push(glb.node(&format!("camera/{camera_name}"), props, false));
        // The frustum in the camera frame C: the image's corners at FRUSTUM_DEPTH_M.
        let d = FRUSTUM_DEPTH_M;
        let corner = |u: f64, v: f64| camera.point_at(u, v, d).to_array().map(|x| x as f32);
        let (w, h) = (f64::from(camera.width), f64::from(camera.height));
        let points = [
            [0.0, 0.0, 0.0],
            corner(0.0, 0.0),
            corner(w, 0.0),
            corner(w, h),
            corner(0.0, h),
        ];
        let indices = [0, 1, 0, 2, 0, 3, 0, 4, 1, 2, 2, 3, 3, 4, 4, 1];
        let frustum_name = format!("frustum/{camera_name}");
        let mesh = glb.mesh_lines(&frustum_name, &points, &indices, [0.1, 0.1, 0.1, 1.0]);
        let mut props = trs(&X_WC);
        props["mesh"] = json!(mesh);
        children.push(glb.node(&frustum_name, props, false));
    }

    // Z up to Y up: a quarter turn about x (the cell's +z becomes glTF's +y).
    let up = Rotation::from_rotation_x(-std::f64::consts::FRAC_PI_2);
    glb.node(
        ROOT_NODE,
        json!({"children": children, "rotation": quaternion(up)}),
        true,
    );
    glb.finish("workcell evaluate --gltf", name)
}

/// Keys of `poses` (one per sample time) on `node`'s translation and rotation, the
/// quaternions' signs kept continuous so that interpolation takes the short way round.
fn animate_pose(glb: &mut GlbBuilder, node: usize, times: usize, poses: &[Pose]) {
    let mut tr = Vec::with_capacity(3 * poses.len());
    let mut rot = Vec::with_capacity(4 * poses.len());
    let mut previous: Option<Rotation> = None;
    for pose in poses {
        tr.extend(translation(pose.translation));
        let mut q = pose.rotation;
        if previous.is_some_and(|p| p.dot(q) < 0.0) {
            q = -q;
        }
        rot.extend(quaternion(q));
        previous = Some(q);
    }
    glb.animate(node, "translation", times, &tr, "LINEAR");
    glb.animate(node, "rotation", times, &rot, "LINEAR");
}
