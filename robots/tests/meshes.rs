//! Mesh files of every supported format load to the same geometry; scale applies per axis.

use std::path::{Path, PathBuf};

use approx::assert_relative_eq;
use workcell_robots::collision::link_collision_shape;
use workcell_robots::math::Pose;
use workcell_robots::{Coordinate, PackageMap, RobotModel, Shape, TriMesh};

fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

#[test]
fn unit_cube_in_every_format() {
    for file in ["cube_binary.stl", "cube_ascii.stl", "cube.obj", "cube.dae"] {
        let mesh = TriMesh::load(&fixtures().join("meshes").join(file), [1.0, 2.0, 3.0])
            .unwrap_or_else(|e| panic!("{file}: {e}"));
        assert_eq!(mesh.triangles.len(), 12, "{file}");
        let (lo, hi) = mesh.bounds();
        for (axis, scale) in [(0, 1.0), (1, 2.0), (2, 3.0)] {
            assert_relative_eq!(lo.to_array()[axis], -0.5 * scale, epsilon = 1e-6);
            assert_relative_eq!(hi.to_array()[axis], 0.5 * scale, epsilon = 1e-6);
        }
        // The convex hull of the scaled cube has volume 1 * 2 * 3.
        let hull = parry3d_f64::shape::SharedShape::convex_hull(&mesh.vertices).expect("hull");
        assert_relative_eq!(hull.mass_properties(1.0).mass(), 6.0, epsilon = 1e-6);
    }
}

#[test]
fn package_uris_relative_paths_and_mimic_joints() {
    let path = fixtures().join("pkg/my_robot/urdf/gripper.urdf");
    let robot = RobotModel::from_urdf_file(&path, &PackageMap::new()).expect("loads");
    assert_eq!(
        robot.dof(),
        3,
        "lift, wrist, left finger; the right finger mimics"
    );
    let right = &robot.joints()[robot.joint_id("finger_right_joint").expect("joint")];
    let left_index =
        match robot.joints()[robot.joint_id("finger_left_joint").expect("joint")].coordinate {
            Coordinate::Own { index } => index,
            other => panic!("left finger should be a coordinate, is {other:?}"),
        };
    assert_eq!(
        right.coordinate,
        Coordinate::Mimic {
            index: left_index,
            multiplier: -1.0,
            offset: 0.0
        }
    );

    // Limits, safety controller, dynamics and acceleration are all read.
    let lift = &robot.joints()[robot.joint_id("lift").expect("joint")];
    assert_eq!(
        (lift.limits.lower, lift.limits.upper, lift.limits.velocity),
        (0.0, 0.5, 0.3)
    );
    assert_eq!(lift.limits.acceleration, 2.0);
    assert_eq!(
        lift.safety_controller
            .expect("safety controller")
            .k_velocity,
        100.0
    );
    let wrist = &robot.joints()[robot.joint_id("wrist").expect("joint")];
    assert!(wrist.limits.lower.is_infinite() && wrist.limits.upper.is_infinite());
    assert_eq!((wrist.damping, wrist.friction), (0.5, 0.1));
    assert_relative_eq!(robot.mass_kg(), 2.0);

    // Meshes: package:// STL scaled for collision, DAE visual with the named material colour.
    let base = &robot.links()[robot.link_id("base").expect("link")];
    match &base.collisions[0].shape {
        Shape::Mesh {
            path, scale, mesh, ..
        } => {
            assert!(path.ends_with(Path::new("my_robot/meshes/cube.stl")));
            assert_eq!(*scale, [0.2, 0.2, 0.1]);
            assert_relative_eq!(mesh.bounds().1.z, 0.05, epsilon = 1e-7);
        }
        other => panic!("expected a mesh, got {other:?}"),
    }
    assert_eq!(base.visuals[0].rgba, Some([0.5, 0.5, 0.5, 1.0]));
    let shape =
        link_collision_shape(&robot, robot.link_id("carriage").expect("link")).expect("shape");
    assert_relative_eq!(
        shape.compute_aabb(&Pose::IDENTITY).maxs.x,
        0.05,
        epsilon = 1e-7
    );

    // Mimic in FK: opening the left finger by 3 cm moves the right one 3 cm the other way.
    let state = robot.fk(Pose::IDENTITY, &[0.0, 0.0, 0.03]).expect("fk");
    let palm = state.link_pose(robot.link_id("palm").expect("link"));
    let fl = palm.inverse() * *state.link_pose(robot.link_id("finger_left").expect("link"));
    let fr = palm.inverse() * *state.link_pose(robot.link_id("finger_right").expect("link"));
    assert_relative_eq!(fl.translation.y, 0.05, epsilon = 1e-12);
    assert_relative_eq!(fr.translation.y, -0.05, epsilon = 1e-12);
}

#[test]
fn truncated_and_corrupted_meshes_are_errors_not_panics() {
    // Every prefix of each fixture, and each fixture with one byte flipped at a time, must
    // give Ok or Err: a broken mesh in a vendor package must never crash a safety tool.
    for file in ["cube_binary.stl", "cube_ascii.stl", "cube.obj", "cube.dae"] {
        let path = fixtures().join("meshes").join(file);
        let bytes = std::fs::read(&path).expect("fixture");
        for len in 0..bytes.len() {
            let _ = TriMesh::from_bytes(&bytes[..len], &path, [1.0; 3]);
        }
        for i in 0..bytes.len() {
            let mut flipped = bytes.clone();
            flipped[i] ^= 0x5a;
            let _ = TriMesh::from_bytes(&flipped, &path, [1.0; 3]);
        }
    }
}

#[test]
fn lying_counts_and_odd_names_are_told_apart() {
    let meshes = fixtures().join("meshes");
    let dae = std::fs::read_to_string(meshes.join("cube.dae")).expect("fixture");
    // A count the file cannot hold is refused before the decoder allocates for it (4e9
    // triangles made it ask for 51 GB).
    for (honest, lie) in [
        (
            "<triangles count=\"12\">",
            "<triangles count=\"4294967295\">",
        ),
        ("count=\"24\">", "count=\"4000000000\">"),
        (
            "count=\"8\" stride=\"3\"",
            "count=\"8\" stride=\"4294967295\"",
        ),
    ] {
        assert!(dae.contains(honest), "{honest}");
        let text = dae.replace(honest, lie);
        let err = TriMesh::from_bytes(text.as_bytes(), Path::new("cube.dae"), [1.0; 3])
            .expect_err("lying count");
        assert!(err.contains("claims more values than the"), "{lie}: {err}");
    }
    // An ASCII STL whose name is not ASCII is decoded as ASCII, not called a truncated
    // binary file.
    let stl = std::fs::read_to_string(meshes.join("cube_ascii.stl")).expect("fixture");
    let named = stl.replacen("solid cube", "solid würfel", 1);
    let mesh = TriMesh::from_bytes(named.as_bytes(), Path::new("würfel.stl"), [1.0; 3])
        .expect("ASCII STL with a UTF-8 name");
    assert_eq!(mesh.triangles.len(), 12);
}

#[test]
fn deeply_nested_collada_is_an_error_not_a_stack_overflow() {
    let dae = format!(
        "<COLLADA>{}{}</COLLADA>",
        "<node>".repeat(20_000),
        "</node>".repeat(20_000)
    );
    let err =
        TriMesh::from_bytes(dae.as_bytes(), Path::new("deep.dae"), [1.0; 3]).expect_err("too deep");
    assert!(err.contains("deeper than 256 levels"), "{err}");
}
