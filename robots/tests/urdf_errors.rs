//! Malformed URDFs are typed errors that name the file and the element, never panics.

use std::path::PathBuf;

use workcell_robots::{JointKind, PackageMap, RobotError, RobotModel};

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

/// A link `name` of 1 kg with principal moments `moment` (kg m^2).
fn link(name: &str, moment: &str) -> String {
    format!(
        "<link name=\"{name}\"><inertial><mass value=\"1\"/><inertia ixx=\"{moment}\" \
         iyy=\"{moment}\" izz=\"{moment}\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial></link>"
    )
}

/// A revolute joint from `parent` to `child` with `extra` elements inside it.
fn joint(name: &str, parent: &str, child: &str, extra: &str) -> String {
    format!(
        "<joint name=\"{name}\" type=\"revolute\"><parent link=\"{parent}\"/>\
         <child link=\"{child}\"/>{extra}</joint>"
    )
}

const AXIS_LIMIT: &str =
    "<axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/>";

/// A chain of `n` revolute joints, each with `extra`.
fn chain(n: usize, extra: &str) -> String {
    let mut text = String::from("<robot name=\"chain\">");
    for i in 0..=n {
        text += &link(&format!("l{i}"), "0.01");
    }
    for i in 1..=n {
        text += &joint(
            &format!("j{i}"),
            &format!("l{}", i - 1),
            &format!("l{i}"),
            extra,
        );
    }
    text + "</robot>"
}

fn load_str(text: &str) -> Result<RobotModel, RobotError> {
    RobotModel::from_urdf_str(text, &fixture("hostile.urdf"), &PackageMap::new())
}

fn refused(text: &str, needle: &str) {
    let err = load_str(text).expect_err("hostile URDF loaded").to_string();
    assert!(err.contains(needle), "'{err}' lacks '{needle}'");
    assert!(err.contains("hostile.urdf"), "{err}");
}

#[test]
fn hostile_numbers_are_refused_before_the_physics_sees_them() {
    // rapier panicked on these (issue: hostile input). A moment of 1e-300 is noise: taken
    // as 0 with a warning, as icub's 2.7e-20.
    let robot = load_str(&format!(
        "<robot name=\"r\">{}{}{}</robot>",
        link("a", "1e-300"),
        link("b", "1e-300"),
        joint("j", "a", "b", AXIS_LIMIT)
    ))
    .expect("noise moments load");
    assert_eq!(
        robot.links()[1]
            .inertial
            .as_ref()
            .expect("mass")
            .inertia_kgm2,
        [0.0; 6]
    );
    assert!(
        robot
            .warnings()
            .iter()
            .any(|w| w.contains("1e-300 below 1e-15")),
        "{:?}",
        robot.warnings()
    );
    refused(
        &chain(1, AXIS_LIMIT).replace("<mass value=\"1\"/>", "<mass value=\"1e-300\"/>"),
        "mass 1e-300 kg",
    );
    let mut mimics = chain(4, AXIS_LIMIT);
    for i in 2..=4 {
        mimics = mimics.replace(
            &format!("<child link=\"l{i}\"/>"),
            &format!(
                "<child link=\"l{i}\"/><mimic joint=\"j{}\" multiplier=\"1e200\"/>",
                i - 1
            ),
        );
    }
    refused(&mimics, "mimic multiplier 1e200");
    // 1e2 per hop is within the limit; j3 follows j1 through j2 at 1e2 * 1e2.
    refused(
        &mimics.replace("1e200", "1e2"),
        "joint 'j3': its chain of mimics multiplies to 1e4",
    );
    // Limits of +-1e308 (robot add panicked on them) mean none: the joint is continuous.
    let wide = chain(1, AXIS_LIMIT).replace(
        "lower=\"-1\" upper=\"1\"",
        "lower=\"-1e308\" upper=\"1e308\"",
    );
    let robot = load_str(&wide).expect("loads as continuous");
    assert_eq!(robot.joints()[0].kind, JointKind::Continuous);
    refused(
        &wide.replace("revolute", "prismatic"),
        "prismatic limit lower=-1e308",
    );
}

#[test]
fn a_huge_axis_is_still_a_unit_direction() {
    // The length of (1e200, 1e200, 0) overflows to infinity; the direction is exact.
    let robot = load_str(&chain(1, AXIS_LIMIT).replace("0 0 1", "1e200 1e200 0")).expect("loads");
    let axis = robot.joints()[0].axis;
    let h = std::f64::consts::FRAC_1_SQRT_2;
    assert!(
        (axis.x - h).abs() < 1e-15 && (axis.y - h).abs() < 1e-15 && axis.z == 0.0,
        "{axis}"
    );
    refused(
        &chain(1, AXIS_LIMIT).replace("0 0 1", "1e-300 0 0"),
        "is not a direction",
    );
}

#[test]
fn hostile_structure_is_refused() {
    let deep = format!(
        "<robot name=\"r\">{}{}{}</robot>",
        link("a", "0.01"),
        "<a>".repeat(20_000),
        "</a>".repeat(20_000)
    );
    refused(&deep, "deeper than 256 levels");
    refused(
        "<robot name=\"r\"><link name=\"a\"/></robot><robot name=\"s\"/>",
        "not a valid URDF",
    );
    refused(
        "<robot name=\"r\"><link name=\"a\"/>\0</robot>",
        "not a valid URDF",
    );
    refused(
        "<sdf version=\"1.6\"><model name=\"m\"/></sdf>",
        "the root element is <sdf>, not <robot> (this is an SDFormat file",
    );
    refused(
        &chain(129, AXIS_LIMIT),
        "129 actuated joints, more than the limit of 128",
    );
    let fixed = chain(1100, "").replace("type=\"revolute\"", "type=\"fixed\"");
    refused(&fixed, "1101 links, more than the limit of 1024");
    assert_eq!(
        load_str(&chain(128, AXIS_LIMIT)).expect("128 dofs").dof(),
        128
    );
}
