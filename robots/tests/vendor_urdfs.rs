//! Real vendor URDFs from the PyPI package example-robot-data (6.0.0): package:// URIs, DAE
//! visuals, STL collision meshes. `scripts/fetch-example-robot-data.sh` downloads the wheel
//! into `~/.cache/workcell`, where these tests find it (or set `WORKCELL_EXAMPLE_ROBOT_DATA`).
//! Without the data they say so and pass, except on CI (`CI` set), where they fail.

use approx::assert_relative_eq;
use workcell_robots::math::Pose;
use workcell_robots::{PackageMap, RobotModel, Shape};

#[path = "support/example_robot_data.rs"]
mod example_robot_data;
use example_robot_data::data_dir;

fn load(relative: &str) -> Option<RobotModel> {
    let path = data_dir()?.join(relative);
    Some(RobotModel::from_urdf_file(&path, &PackageMap::new()).unwrap_or_else(|e| panic!("{e}")))
}

fn count_meshes(robot: &RobotModel) -> (usize, usize) {
    let meshes = |g: &[workcell_robots::Geometry]| {
        g.iter()
            .filter(|g| matches!(g.shape, Shape::Mesh { .. }))
            .count()
    };
    robot.links().iter().fold((0, 0), |(v, c), l| {
        (v + meshes(&l.visuals), c + meshes(&l.collisions))
    })
}

#[test]
fn ur5_tool0_matches_pinocchio() {
    let Some(robot) = load("robots/ur_description/urdf/ur5_robot.urdf") else {
        return;
    };
    assert_eq!(robot.dof(), 6);
    let (visual, collision) = count_meshes(&robot);
    assert!(
        visual >= 6 && collision >= 6,
        "DAE visuals {visual}, STL collisions {collision}"
    );
    // Reference: Pinocchio 3.x, example-robot-data UR5, frame tool0 at this q
    // (../shared/reference/SAFETY.md).
    let q = [0.1, -0.5, 0.8, -1.2, 0.3, 0.7];
    let state = robot.fk(Pose::IDENTITY, &q).expect("fk");
    let tool0 = state
        .link_pose(robot.link_id("tool0").expect("tool0"))
        .translation;
    assert_relative_eq!(tool0.x, 0.814036, epsilon = 1e-6);
    assert_relative_eq!(tool0.y, 0.270393, epsilon = 1e-6);
    assert_relative_eq!(tool0.z, 0.137213, epsilon = 1e-6);
}

#[test]
fn panda_loads_with_meshes_and_mimic_finger() {
    let Some(robot) = load("robots/panda_description/urdf/panda.urdf") else {
        return;
    };
    // 7 arm joints + 1 finger; the second finger mimics the first.
    assert_eq!(robot.dof(), 8);
    let mimic = robot.joints().iter().filter(|j| j.mimic.is_some()).count();
    assert_eq!(mimic, 1);
    let (visual, collision) = count_meshes(&robot);
    assert!(
        visual >= 8 && collision >= 8,
        "visual {visual}, collision {collision}"
    );
    // Every moving link with collision meshes gets a convex shape and a bounding capsule.
    for link in 0..robot.links().len() {
        if !robot.links()[link].collisions.is_empty() {
            assert!(workcell_robots::collision::link_collision_shape(&robot, link).is_some());
            assert!(workcell_robots::collision::link_bounding_capsule(&robot, link).is_some());
        }
    }
}

#[test]
fn multi_part_collada_visuals_enclose_the_volume_of_their_collision_meshes() {
    // The UR5's visual meshes are COLLADA files of up to 7 parts; its collision meshes are
    // simplified STL hulls of the same shapes. With every part's triangles on its own
    // vertices, the enclosed volumes (divergence theorem) agree within 2 %. (When the decoder
    // merged the parts itself, later parts indexed the first part's vertices: the upper arm
    // enclosed 31 % less than its hull.)
    let Some(robot) = load("robots/ur_description/urdf/ur5_robot.urdf") else {
        return;
    };
    let volume = |g: &workcell_robots::Geometry| match &g.shape {
        Shape::Mesh { mesh, .. } => Some(
            mesh.triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
                    a.dot(b.cross(c)) / 6.0
                })
                .sum::<f64>(),
        ),
        _ => None,
    };
    let mut compared = 0;
    for link in robot.links() {
        let (Some(v), Some(c)) = (
            link.visuals.first().and_then(volume),
            link.collisions.first().and_then(volume),
        ) else {
            continue;
        };
        assert!(
            (v - c).abs() < 0.02 * c.abs(),
            "{}: visual {v:e} m^3, collision {c:e} m^3",
            link.name
        );
        compared += 1;
    }
    assert_eq!(
        compared, 7,
        "base, shoulder, upper arm, forearm, three wrists"
    );
}

#[test]
fn the_whole_example_robot_data_corpus_loads_or_fails_for_a_real_reason() {
    let Some(dir) = data_dir() else { return };
    let mut files = Vec::new();
    let mut stack = vec![dir.join("robots")];
    while let Some(folder) = stack.pop() {
        for entry in std::fs::read_dir(&folder).expect("read_dir").flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "urdf") {
                files.push(path);
            }
        }
    }
    files.sort();
    assert_eq!(files.len(), 69, "example-robot-data 6.0.0 ships 69 URDFs");
    let mut failures = Vec::new();
    for path in &files {
        if let Err(e) = RobotModel::from_urdf_file(path, &PackageMap::new()) {
            let name = path
                .strip_prefix(&dir)
                .expect("inside")
                .display()
                .to_string();
            failures.push((name, e.to_string()));
        }
    }
    // The three files that are broken in the package itself, each refused with its reason.
    let expected = [
        (
            "alex_psyonic_hands.urdf",
            "mimics joint 'index_q1', which does not exist",
        ),
        (
            "romeo_laas_small.urdf",
            "file:///usr/Romeo/naoqi-sdk-2.3.0.14-linux64/share/alrobotmodel/meshes/romeo/Torso.mesh' is outside every known package root",
        ),
        ("ur3.urdf", "<robot>: has no <link> element"),
    ];
    assert_eq!(failures.len(), expected.len(), "{failures:#?}");
    for ((name, message), (file, reason)) in failures.iter().zip(expected) {
        assert!(name.ends_with(file), "{name}");
        assert!(message.contains(reason), "{name}: {message}");
    }
}
