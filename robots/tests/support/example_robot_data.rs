//! Where the tests find example-robot-data 6.0.0 (shared by the robots and sim tests).

use std::path::PathBuf;

/// The vendor arms the simulator tests run (relative to the data folder).
#[allow(dead_code)] // not every test binary that includes this file uses it
pub const VENDOR_ARMS: [&str; 5] = [
    "robots/ur_description/urdf/ur5_robot.urdf",
    "robots/panda_description/urdf/panda.urdf",
    "robots/z1_description/urdf/z1.urdf",
    "robots/kinova_description/robots/kinova.urdf",
    "robots/xarm_description/urdf/xarm7.urdf",
];

/// `WORKCELL_EXAMPLE_ROBOT_DATA`, else the cache that `scripts/fetch-example-robot-data.sh`
/// fills. `None` (with a note) when absent; a panic under CI, where it must be present.
pub fn data_dir() -> Option<PathBuf> {
    let cached = std::env::var_os("HOME").map(|home| {
        PathBuf::from(home)
            .join(".cache/workcell/example-robot-data-6.0.0/cmeel.prefix/share/example-robot-data")
    });
    let dir = std::env::var_os("WORKCELL_EXAMPLE_ROBOT_DATA")
        .map(PathBuf::from)
        .or(cached);
    match dir {
        Some(dir) if dir.is_dir() => Some(dir),
        _ if std::env::var_os("CI").is_some() => {
            panic!(
                "CI needs example-robot-data: run scripts/fetch-example-robot-data.sh (see .ci/run)"
            )
        }
        _ => {
            eprintln!(
                "example-robot-data not found: vendor tests not run (scripts/fetch-example-robot-data.sh)"
            );
            None
        }
    }
}
