//! Forward kinematics and the Jacobian of a catalogue arm, and a velocity that moves its tool
//! straight up: `cargo run --release --example kinematics`.

use anyhow::Context;
use workcell::robots::Jacobian;
use workcell::robots::prelude::*;

fn main() -> anyhow::Result<()> {
    let arm = RobotModel::from_catalogue("iiwa14_kinematics")?;
    let tool = arm
        .link_id("tool0")
        .context("the catalogue arm has a tool0")?;
    let q = [0.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0];
    let state = arm.fk(Pose::IDENTITY, &q)?;
    let X_WT = state.link_pose(tool);
    println!("tool0 at {:?} m", X_WT.translation.to_array());

    // Jacobian of the tool point; Jacobian transpose gives a joint velocity whose tool
    // velocity points up (a gradient step, not a least-squares solve).
    let mut jacobian = Jacobian::zeros(arm.dof());
    arm.point_jacobian(&state, tool, X_WT.translation, &mut jacobian);
    let up = [0.0, 0.0, 0.1];
    let qdot: Vec<f64> = jacobian
        .columns()
        .iter()
        .map(|c| c[0] * up[0] + c[1] * up[1] + c[2] * up[2])
        .collect();
    let v = jacobian.linear_velocity(&qdot);
    println!(
        "qdot {qdot:.3?} rad/s moves the tool at {:?} m/s",
        v.to_array()
    );
    Ok(())
}
