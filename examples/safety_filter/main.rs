//! The safety filter alone, as it runs beside a real robot: no simulator, no camera. A UR5e
//! (the catalogue's kinematic model) sweeps its base joint at 1 rad/s while a human forearm,
//! reported by "perception" as a capsule with a velocity and an uncertainty, reaches into
//! its path and stays there. Each control tick hands the filter the joint positions, the nominal joint
//! velocity and the human estimate, and integrates the command it returns.
//!
//! `cargo run --release --example safety_filter`

use anyhow::Context as _;
use workcell::robots::RobotModel;
use workcell::robots::math::{Pose, Vector};
use workcell::safety::{
    Capsule, FilterConfig, FilterMode, FilterStatus, HumanEstimate, HumanPart, PartEstimate,
    SafetyFilter,
};

fn main() -> anyhow::Result<()> {
    let robot = RobotModel::from_catalogue("ur5e_kinematics")?;
    let X_WR = Pose::IDENTITY;
    let config = FilterConfig::default();
    let d_min = config.d_min_m;
    let mut filter = SafetyFilter::new(&robot, X_WR, FilterMode::Qp, config)?;

    let dt = 0.004; // s, the control period
    let mut q = vec![0.0, -1.2, 1.4, -1.8, -1.57, 0.0];
    // The nominal motion: the base joint turns at 1 rad/s, the rest hold.
    let mut qdot_nom = vec![0.0; robot.dof()];
    qdot_nom[0] = 1.0;
    // The human: a forearm 0.26 m long, 4.5 cm in radius, reaching in at 0.3 m/s for one
    // second and then holding still with its wrist where the tool will pass when the base
    // joint reaches 1.2 rad; perception is 2 cm unsure of it.
    let tool = robot
        .link_id("tool0")
        .context("the catalogue arm has a tool0")?;
    let mut q_hit = q.clone();
    q_hit[0] = 1.2;
    let p_hit = robot.fk(X_WR, &q_hit)?.link_pose(tool).translation;
    let outward = Vector::new(p_hit.x, p_hit.y, 0.0).normalize();
    let (r, forearm_m) = (0.045, 0.26);
    let reach = -0.3 * outward; // m/s
    let mut elbow = p_hit + (forearm_m + 0.3) * outward;

    println!("   t (s) | base joint (rad) | command / nominal | closest seen (m) | status");
    let mut closest = f64::INFINITY;
    for k in 0..750 {
        let v = if k as f64 * dt < 1.0 {
            reach
        } else {
            Vector::ZERO
        };
        elbow += v * dt;
        let wrist = elbow - forearm_m * outward;
        let human = HumanEstimate {
            parts: vec![PartEstimate {
                part: HumanPart::Forearm,
                capsule: Capsule::new(elbow, wrist, r),
                v_a_W: v,
                v_b_W: v,
            }],
            uncertainty_m: 0.02,
            uncertainty_rate_m_s: 0.0,
        };
        let out = filter.tick(&robot, &q, &qdot_nom, &human, dt);
        for (qi, vi) in q.iter_mut().zip(filter.command()) {
            *qi += vi * dt;
        }
        closest = closest.min(out.min_distance_m);
        if k % 50 == 0 {
            println!(
                "{:8.2} | {:16.3} | {:17.2} | {:16.3} | {}",
                k as f64 * dt,
                q[0],
                filter.command()[0] / qdot_nom[0],
                out.min_distance_m,
                out.status.label()
            );
        }
        if matches!(out.status, FilterStatus::Braking(_)) {
            println!("braking: {}", out.status.label());
        }
    }
    println!(
        "closest approach the filter saw: {closest:.3} m (d_min {d_min} m, capsules inflated \
         by the 0.02 m uncertainty)"
    );
    Ok(())
}
