//! Malformed URDFs are typed errors that name the file and the element, never panics.

use std::path::PathBuf;

use workcell_robots::{PackageMap, RobotError, RobotModel};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/broken")
        .join(name)
}

fn load(name: &str) -> RobotError {
    let path = fixture(name);
    match RobotModel::from_urdf_file(&path, &PackageMap::new()) {
        Ok(_) => panic!("{name} loaded although it is broken"),
        Err(e) => {
            // Every error message names the file.
            assert!(
                e.to_string().contains(name),
                "{name}: message does not name the file: {e}"
            );
            e
        }
    }
}

fn assert_invalid(name: &str, element: &str, needle: &str) {
    match load(name) {
        RobotError::Invalid {
            element: el,
            message,
            ..
        } => {
            assert_eq!(el, element, "{name}");
            assert!(
                message.contains(needle),
                "{name}: '{message}' lacks '{needle}'"
            );
        }
        other => panic!("{name}: expected Invalid, got {other:?}"),
    }
}

#[test]
fn structural_errors_name_the_element() {
    assert_invalid(
        "missing_parent.urdf",
        "joint 'j'",
        "parent link 'nowhere' does not exist",
    );
    assert_invalid(
        "missing_child.urdf",
        "joint 'j'",
        "child link 'missing_child' does not exist",
    );
    assert_invalid("cycle.urdf", "joint 'ab'", "cycle");
    assert_invalid("two_roots.urdf", "robot 'broken'", "2 root links (a, b)");
    assert_invalid("duplicate_link.urdf", "link 'a'", "defined twice");
    assert_invalid("floating_joint.urdf", "joint 'j'", "not supported");
    assert_invalid(
        "unknown_joint_type.urdf",
        "joint 'j'",
        "unknown joint type 'screw'",
    );
    assert_invalid(
        "mimic_unknown.urdf",
        "joint 'j'",
        "'ghost', which does not exist",
    );
}

#[test]
fn bad_numbers_are_rejected() {
    assert_invalid("negative_mass.urdf", "link 'a'", "mass -2");
    assert_invalid(
        "negative_radius.urdf",
        "link 'a' collision 0",
        "sphere radius",
    );
    assert_invalid("zero_axis.urdf", "joint 'j'", "not a direction");
    assert_invalid(
        "lower_above_upper.urdf",
        "joint 'j'",
        "lower=1 is above upper=-1",
    );
    assert_invalid("negative_velocity.urdf", "joint 'j'", "velocity=-3");
}

#[test]
fn nan_is_rejected() {
    // urdf-rs may refuse the NaN while parsing, or we refuse it while checking: either way a
    // typed error naming the file.
    match load("nan_origin.urdf") {
        RobotError::Invalid { element, .. } => assert_eq!(element, "joint 'j'"),
        RobotError::Parse { .. } => {}
        other => panic!("expected Invalid or Parse, got {other:?}"),
    }
}

#[test]
fn unparsable_files_are_parse_errors() {
    for name in ["not_xml.urdf", "joint_without_child.urdf"] {
        assert!(matches!(load(name), RobotError::Parse { .. }), "{name}");
    }
}

#[test]
fn mesh_problems_name_the_mesh() {
    for (name, uri, needle) in [
        ("missing_mesh.urdf", "does_not_exist.stl", "cannot read"),
        ("broken_mesh.urdf", "truncated.stl", "truncated binary STL"),
        ("broken_dae.urdf", "garbage.dae", "cannot decode"),
        // mesh-loader panics on this one; the panic becomes an error.
        (
            "dangling_dae.urdf",
            "dangling_reference.dae",
            "cannot decode",
        ),
        (
            "escaping_mesh.urdf",
            "../../../../../../etc/hostname",
            "escapes",
        ),
    ] {
        match load(name) {
            RobotError::Mesh {
                uri: u,
                message,
                element,
                ..
            } => {
                assert_eq!(u, uri, "{name}");
                assert!(element.starts_with("link 'a'"), "{name}: {element}");
                assert!(
                    message.contains(needle),
                    "{name}: '{message}' lacks '{needle}'"
                );
            }
            other => panic!("{name}: expected Mesh, got {other:?}"),
        }
    }
}

#[test]
fn missing_file_is_an_io_error() {
    let err = RobotModel::from_urdf_file(fixture("no_such_file.urdf"), &PackageMap::new())
        .expect_err("missing file");
    assert!(matches!(err, RobotError::Io { .. }));
}

#[test]
fn unknown_catalogue_name_lists_the_catalogue() {
    let err = RobotModel::from_catalogue("ur5").expect_err("not in the catalogue");
    assert!(err.to_string().contains("ur5e_kinematics"), "{err}");
}

#[test]
fn truncated_and_corrupted_urdfs_are_errors_not_panics() {
    // Every prefix of a valid URDF with meshes, mimic and limits, and the file with each byte
    // replaced in turn, loads or fails with an error.
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/pkg/my_robot/urdf/gripper.urdf");
    let text = std::fs::read_to_string(&path).expect("fixture");
    let packages = PackageMap::new();
    for (len, _) in text.char_indices().step_by(3) {
        let _ = RobotModel::from_urdf_str(&text[..len], &path, &packages);
    }
    for (i, c) in text.char_indices().step_by(2) {
        for replacement in ["\"", "<", "-", "9"] {
            let mut broken = text.clone();
            broken.replace_range(i..i + c.len_utf8(), replacement);
            let _ = RobotModel::from_urdf_str(&broken, &path, &packages);
        }
    }
}
