//! The rapier model against MuJoCo 3.17.0 (feature `mujoco`; `scripts/fetch-mujoco.sh`):
//! every catalogue robot and five vendor arms from example-robot-data 6.0.0 agree within the
//! documented tolerances, a model that differs from its file is caught, and what MuJoCo
//! rejects is an error that says why.

use std::path::Path;

use workcell_robots::assets::UrdfAssets;
use workcell_robots::{CATALOGUE, PackageMap, RobotModel, RobotSource};
use workcell_sim::crosscheck::{
    CrosscheckConfig, CrosscheckError, CrosscheckReport, crosscheck, format_report,
};

#[path = "../../robots/tests/support/example_robot_data.rs"]
mod example_robot_data;
use example_robot_data::{VENDOR_ARMS, data_dir};

/// Fewer samples and a shorter run than the command's defaults: tests stay quick.
fn config() -> CrosscheckConfig {
    CrosscheckConfig {
        samples: 20,
        duration_s: 1.0,
        ..CrosscheckConfig::default()
    }
}

fn check_file(path: &Path) -> CrosscheckReport {
    let packages = PackageMap::new();
    let robot = RobotModel::from_urdf_file(path, &packages).expect("loads");
    let assets = UrdfAssets::read(path, &packages).expect("reads");
    let dir = tempfile::tempdir().expect("temp");
    crosscheck(&robot, &assets, dir.path(), &config()).expect("cross-check runs")
}

fn assert_agrees(report: &CrosscheckReport) {
    assert!(report.passed(), "{}", format_report(report));
    // The run moved the joints: a trajectory check on a robot at rest would prove nothing.
    assert!(
        report.trajectory_excursion > 0.1,
        "{}",
        format_report(report)
    );
    assert!(report.gravity_scale > 1.0 && report.mass_matrix_scale > 0.1);
}

#[test]
fn catalogue_robots_agree_with_mujoco() {
    for entry in CATALOGUE.iter() {
        let robot = RobotModel::from_catalogue(entry.name).expect("catalogue");
        let assets = RobotSource::Catalogue(entry)
            .assets(&PackageMap::new())
            .expect("text");
        let dir = tempfile::tempdir().expect("temp");
        let report = crosscheck(&robot, &assets, dir.path(), &config()).expect("runs");
        assert_agrees(&report);
    }
}

#[test]
fn vendor_arms_agree_with_mujoco() {
    let Some(data) = data_dir() else { return };
    for relative in VENDOR_ARMS {
        let report = check_file(&data.join(relative));
        assert_agrees(&report);
        // DAE and STL meshes went through the converter: every link was found in MuJoCo.
        assert_eq!(
            report.links,
            RobotModel::from_urdf_file(data.join(relative), &PackageMap::new())
                .expect("loads")
                .links()
                .len()
        );
    }
}

#[test]
fn a_model_that_differs_from_its_file_is_caught() {
    // The model's wrist is 10 g heavier than the file MuJoCo reads: kinematics still agree,
    // mass matrix and gravity torques do not.
    let entry = CATALOGUE
        .iter()
        .find(|e| e.name == "ur5e_kinematics")
        .expect("catalogue");
    let source = RobotSource::Catalogue(entry);
    let path = source.path();
    let assets = source.assets(&PackageMap::new()).expect("text");
    let marker = "<mass value=\"";
    let at = entry.urdf.rfind(marker).expect("a mass") + marker.len();
    let end = at + entry.urdf[at..].find('"').expect("closing quote");
    let mass: f64 = entry.urdf[at..end].parse().expect("a number");
    let heavier = format!("{}{}{}", &entry.urdf[..at], mass + 0.01, &entry.urdf[end..]);
    let robot = RobotModel::from_urdf_str(&heavier, &path, &PackageMap::new()).expect("loads");
    let dir = tempfile::tempdir().expect("temp");
    let report = crosscheck(&robot, &assets, dir.path(), &config()).expect("runs");
    let verdict = |name: &str| {
        report
            .checks
            .iter()
            .find(|c| c.name.starts_with(name))
            .expect("check")
            .pass
    };
    assert!(verdict("fk position") && verdict("fk rotation"));
    assert!(!verdict("mass matrix"), "{}", format_report(&report));
    assert!(!verdict("gravity"), "{}", format_report(&report));
    assert!(!report.passed());
}

const TWO_LINKS: &str = r#"<robot name="bad">
  <link name="base"/>
  <link name="arm">
    <inertial><mass value="1"/>INERTIA</inertial>
    <collision><geometry>GEOMETRY</geometry></collision>
  </link>
  <joint name="j" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
</robot>
"#;

fn two_links(inertia: &str, geometry: &str, dir: &Path) -> (RobotModel, UrdfAssets) {
    let text = TWO_LINKS
        .replace("INERTIA", inertia)
        .replace("GEOMETRY", geometry);
    let path = dir.join("bad.urdf");
    std::fs::write(&path, text).expect("write");
    let robot = RobotModel::from_urdf_file(&path, &PackageMap::new()).expect("our loader takes it");
    let assets = UrdfAssets::read(&path, &PackageMap::new()).expect("reads");
    (robot, assets)
}

#[test]
fn what_mujoco_rejects_is_an_error_naming_the_cause() {
    let dir = tempfile::tempdir().expect("temp");
    let work = dir.path().join("work");
    // Principal moments that no rigid body has (A + B < C): MuJoCo refuses them.
    let (robot, assets) = two_links(
        r#"<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.01"/>"#,
        r#"<box size="0.1 0.1 0.1"/>"#,
        dir.path(),
    );
    let err = crosscheck(&robot, &assets, &work, &config()).expect_err("rejected");
    let text = err.to_string();
    assert!(
        matches!(err, CrosscheckError::MujocoRejected { .. }),
        "{text}"
    );
    assert!(
        text.contains("bad.urdf") && text.contains("inertia"),
        "{text}"
    );

    // A flat mesh (all vertices in one plane) has no volume: MuJoCo cannot use it.
    let flat = dir.path().join("flat.stl");
    let mesh = workcell_robots::TriMesh {
        vertices: vec![
            workcell_robots::math::Vector::new(0.0, 0.0, 0.0),
            workcell_robots::math::Vector::new(0.1, 0.0, 0.0),
            workcell_robots::math::Vector::new(0.0, 0.1, 0.0),
            workcell_robots::math::Vector::new(0.1, 0.1, 0.0),
        ],
        triangles: vec![[0, 1, 2], [1, 3, 2]],
    };
    workcell_robots::assets::write_binary_stl(&mesh, &flat).expect("stl");
    let (robot, assets) = two_links(
        r#"<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>"#,
        r#"<mesh filename="flat.stl"/>"#,
        dir.path(),
    );
    match crosscheck(&robot, &assets, &work, &config()) {
        Err(e @ CrosscheckError::MujocoRejected { .. }) => {
            assert!(e.to_string().contains("mesh"), "{e}");
        }
        other => panic!("a flat mesh should be refused by MuJoCo, got {other:?}"),
    }
}
