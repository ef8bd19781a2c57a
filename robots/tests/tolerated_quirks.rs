//! Quirks of exported URDFs that carry no meaning are accepted, each reported in
//! `RobotModel::warnings`, never silently: found in example-robot-data's Talos, iCub and
//! Bolt files.

use std::path::PathBuf;

use workcell_robots::{PackageMap, RobotModel, Shape};

#[test]
fn quirks_are_accepted_and_reported() {
    let dir = tempfile::tempdir().expect("tempdir");
    let pkg = dir.path().join("quirky");
    std::fs::create_dir_all(pkg.join("meshes")).expect("mkdir");
    // A binary STL whose free-form header starts with "solid" (one triangle).
    let mut stl = b"solid but binary".to_vec();
    stl.resize(80, b' ');
    stl.extend(1u32.to_le_bytes());
    for v in [
        [0.0f32, 0.0, 1.0],
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
    ] {
        for c in v {
            stl.extend(c.to_le_bytes());
        }
    }
    stl.extend([0u8, 0]);
    std::fs::write(pkg.join("meshes/solid_header.stl"), &stl).expect("write");
    let urdf = r#"<robot name="quirky">
  <link name="a">
    <inertial><mass value="1"/><inertia ixx="-5e-20" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>
    <visual><geometry><mesh filename="package:///quirky/meshes/solid_header.stl"/></geometry>
      <material name="m"><color rgba="1 0 0 1"/><texture /></material></visual>
  </link>
  <link name="b"/>
  <link name="c"/>
  <joint name="hinge" type="revolute"><parent link="a"/><child link="b"/>
    <limit lower="-1" upper="1" velocity="1" effort="1"/></joint>
  <joint name="welded" type="fixed"><parent link="b"/><child link="c"/>
    <mimic joint="hinge" multiplier="2"/></joint>
</robot>"#;
    let path: PathBuf = pkg.join("quirky.urdf");
    let robot = RobotModel::from_urdf_str(urdf, &path, &PackageMap::new()).expect("tolerated");
    assert_eq!(robot.dof(), 1);
    let warnings = robot.warnings().join("\n");
    assert!(warnings.contains("empty <texture/>"), "{warnings}");
    assert!(
        warnings.contains("joint 'welded': <mimic> on a fixed joint ignored"),
        "{warnings}"
    );
    assert!(
        warnings.contains("link 'a': inertia diagonal 0"),
        "{warnings}"
    );
    match &robot.links()[0].visuals[0].shape {
        Shape::Mesh { mesh, .. } => assert_eq!(mesh.triangles.len(), 1),
        other => panic!("expected a mesh, got {other:?}"),
    }
    assert_eq!(
        robot.links()[0].inertial.expect("inertial").inertia_kgm2[0],
        0.0
    );
}
