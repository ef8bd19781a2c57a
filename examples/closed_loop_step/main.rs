//! Drives the default cell with your own controller instead of the nominal motion: each tick
//! reads the state, computes a joint velocity, and steps the physics.
//! `cargo run --release --example closed_loop_step`.

use std::path::Path;

use anyhow::Context;
use workcell::sim::{CellModel, CellState, RobotCommand, step};

fn main() -> anyhow::Result<()> {
    let model = CellModel::from_file(Path::new("configs/default.toml"))?;
    let mut state = CellState::new(&model)?;
    let (mut q_nom, mut qd_nom, mut qdd_nom) = (vec![0.0; 7], vec![0.0; 7], vec![0.0; 7]);
    let mut qdot = vec![0.0; 7];
    let gain = 20.0; // 1/s
    let hand = model
        .human
        .link_id("hand")
        .context("the human arm has a hand")?;
    let mut closest_m = f64::INFINITY;
    for _ in 0..5000 {
        // A velocity controller: feed-forward plus proportional correction toward the plan.
        let t = state.time_s() + model.time_step_s();
        model
            .robot_motion
            .sample(t, &mut q_nom, &mut qd_nom, &mut qdd_nom);
        for i in 0..7 {
            qdot[i] = qd_nom[i] + gain * (q_nom[i] - state.q()[i]);
        }
        step(&model, &mut state, &RobotCommand::Velocity { qd: &qdot })?;
        let p_tool = state.robot_link_pose(model.tool_link).translation;
        let p_hand = state.human_link_poses()[hand].translation;
        closest_m = closest_m.min((p_tool - p_hand).length());
    }
    println!("5 s under velocity control; closest tool-hand approach {closest_m:.3} m");
    Ok(())
}
