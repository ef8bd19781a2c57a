//! rapier and MuJoCo side by side: steps per second of the same robot, the same task (the
//! cross-check's PD torque trajectory, no gravity, no contacts) and the same 1 ms step, on
//! one thread. Prints a table with the ratio.
//!
//! `scripts/fetch-mujoco.sh && cargo bench -p workcell-sim --features mujoco --bench mujoco`
//! (vendor arms need `scripts/fetch-example-robot-data.sh`; they are skipped without it).

use workcell_robots::assets::UrdfAssets;
use workcell_robots::{CATALOGUE, PackageMap, RobotModel, RobotSource};
use workcell_sim::crosscheck::step_rates;

#[path = "../../robots/tests/support/example_robot_data.rs"]
mod example_robot_data;

fn main() {
    // `cargo bench` passes `--bench`; a filter argument selects robots by name.
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with("--"));
    let mut robots: Vec<(RobotModel, UrdfAssets)> = Vec::new();
    for entry in CATALOGUE.iter() {
        let model = RobotModel::from_catalogue(entry.name).expect("catalogue robot");
        let assets = RobotSource::Catalogue(entry)
            .assets(&PackageMap::new())
            .expect("catalogue URDF");
        robots.push((model, assets));
    }
    // The UR5 and the Panda from example-robot-data (data_dir says so when it is missing).
    if let Some(dir) = example_robot_data::data_dir() {
        for relative in &example_robot_data::VENDOR_ARMS[..2] {
            let path = dir.join(relative);
            let model = RobotModel::from_urdf_file(&path, &PackageMap::new()).expect("loads");
            let assets = UrdfAssets::read(&path, &PackageMap::new()).expect("reads");
            robots.push((model, assets));
        }
    }
    println!(
        "{:<22} {:>5} {:>16} {:>16} {:>16}",
        "robot", "dofs", "rapier steps/s", "MuJoCo steps/s", "rapier / MuJoCo"
    );
    for (model, assets) in &robots {
        if filter
            .as_ref()
            .is_some_and(|f| !model.name().contains(f.as_str()))
        {
            continue;
        }
        let dir = tempfile::tempdir().expect("temporary folder");
        let rates = step_rates(model, assets, dir.path(), 3000, 5).expect("cross-check loads");
        println!(
            "{:<22} {:>5} {:>16.0} {:>16.0} {:>16.3}",
            model.name(),
            model.dof(),
            rates.rapier_steps_per_s,
            rates.mujoco_steps_per_s,
            rates.rapier_steps_per_s / rates.mujoco_steps_per_s
        );
    }
}
