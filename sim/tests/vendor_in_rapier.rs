//! Vendor arms from example-robot-data 6.0.0 in rapier: the multibody built from our model
//! puts every link where forward kinematics does, and the servos hold a pose under gravity.
//! Needs `scripts/fetch-example-robot-data.sh` (CI runs it); without the data the test says
//! so and passes, except on CI.

use workcell_robots::{PackageMap, RobotModel};

#[path = "../../robots/tests/support/example_robot_data.rs"]
mod example_robot_data;
use example_robot_data::{VENDOR_ARMS, data_dir};

#[test]
fn vendor_arms_match_forward_kinematics_in_rapier() {
    let Some(dir) = data_dir() else { return };
    for relative in VENDOR_ARMS {
        let path = dir.join(relative);
        if !path.is_file() {
            panic!("{relative} is not in example-robot-data any more");
        }
        let robot = RobotModel::from_urdf_file(&path, &PackageMap::new()).expect("loads");
        let q: Vec<f64> = robot
            .position_limits()
            .iter()
            .map(|[lo, hi]| {
                if lo.is_finite() && hi.is_finite() {
                    lo + 0.4 * (hi - lo)
                } else {
                    0.3
                }
            })
            .collect();
        let report = workcell_sim::check_in_rapier(&robot, &q).expect("rapier");
        assert!(
            report.fk_mismatch_m < 1e-9,
            "{relative}: {}",
            report.fk_mismatch_m
        );
        assert!(
            report.hold_error < 0.05,
            "{relative}: hold error {}",
            report.hold_error
        );
    }
}
