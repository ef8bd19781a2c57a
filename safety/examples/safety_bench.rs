//! Times the safety layer on seeded problems and writes them to JSON so that other solvers
//! can be timed on the very same queries (`bench/safety_peers.py` runs this, then Coal and
//! OSQP, and prints the ratios).
//!
//! `cargo run --release -p workcell-safety --example safety_bench -- [--cases N] [--out FILE]`
//!
//! Problems: the iiwa 14 at random configurations, a human arm (upper arm, forearm, hand
//! capsules) placed around its wrist; the nominal command drives the arm toward the human so
//! that the QP has active rows.

use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{KinematicState, RobotModel};
use workcell_safety::{
    Capsule, FilterConfig, FilterMode, FilterStatus, HumanEstimate, HumanPart, PartEstimate,
    QpFilter, RobotGeometry, SafetyFilter,
};

/// Median of per-call times (seconds) over `repeats` calls of `f`, in microseconds.
fn median_us(repeats: usize, mut f: impl FnMut()) -> f64 {
    let mut samples: Vec<f64> = (0..repeats)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    samples.sort_by(f64::total_cmp);
    samples[samples.len() / 2]
}

fn percentile(values: &mut [f64], p: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * p).round() as usize]
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let cases: usize = value("--cases")
        .map(|v| v.parse())
        .transpose()?
        .unwrap_or(200);
    let out = value("--out");

    let robot = RobotModel::from_catalogue("iiwa14_kinematics")?;
    let mut geometry = RobotGeometry::new(&robot)?;
    let config = FilterConfig::default();
    let mut filter = SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config.clone())?;
    // The same tick guarding the parts 0.15 s ahead as well (`configs/evaluate.toml`).
    let mut anticipating = SafetyFilter::new(
        &robot,
        Pose::IDENTITY,
        FilterMode::Qp,
        FilterConfig {
            anticipation_s: 0.15,
            ..config.clone()
        },
    )?;
    let mut qp = QpFilter::new(robot.dof(), config.max_pairs)?;
    let limits = robot.position_limits();
    let velocity: Vec<f64> = robot
        .actuated_joints()
        .iter()
        .map(|&j| robot.joints()[j].limits.velocity)
        .collect();
    let tool = robot.link_id("tool0").ok_or("no tool0")?;
    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    let mut kinematics = KinematicState::new(&robot);

    let (mut t_distance, mut t_pairs, mut t_qp, mut t_tick, mut t_tick_ahead) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut capsule_pairs = Vec::new(); // [a(3), b(3), r, a(3), b(3), r, distance]
    let mut qps = Vec::new();
    let mut active_rows = Vec::new();
    let mut pairs = Vec::new();
    let mut qdot = vec![0.0; robot.dof()];
    while t_qp.len() < cases {
        let q: Vec<f64> = limits
            .iter()
            .map(|[lo, hi]| rng.random_range(0.6 * lo..0.6 * hi))
            .collect();
        robot.forward_kinematics(&q, &mut kinematics)?;
        let p_tool = kinematics.link_pose(tool).translation;
        if p_tool.z < 0.3 {
            continue;
        }
        // A human arm around the wrist: elbow 0.25-0.4 m away, forearm pointing at the tool.
        let dir = Vector::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.5..1.0),
        )
        .normalize_or(Vector::X);
        let wrist = p_tool + dir * rng.random_range(0.12..0.25);
        let elbow = wrist + dir * 0.25;
        let shoulder = elbow + Vector::new(0.0, 0.0, 0.3);
        let hand_end = wrist - dir * 0.18;
        let v = -dir * rng.random_range(0.0..0.8);
        let part = |part, a, b, r| PartEstimate {
            part,
            capsule: Capsule::new(a, b, r),
            v_a_W: v,
            v_b_W: v,
        };
        let human = HumanEstimate {
            parts: vec![
                part(HumanPart::UpperArm, shoulder, elbow, 0.05),
                part(HumanPart::Forearm, elbow, wrist, 0.04),
                part(HumanPart::Hand, wrist, hand_end, 0.045),
            ],
            uncertainty_m: 0.02,
            uncertainty_rate_m_s: 0.0,
        };
        // Nominal: joints moving the tool toward the human (the tool's Jacobian transposed).
        let jac = robot.link_jacobian(&kinematics, tool);
        let qdot_nom: Vec<f64> = jac
            .columns()
            .iter()
            .zip(&velocity)
            .map(|(c, vmax)| {
                (0.8 * (c[0] * dir.x + c[1] * dir.y + c[2] * dir.z)).clamp(-0.5 * vmax, 0.5 * vmax)
            })
            .collect();

        // Distances alone (7 movable links + base, 3 parts).
        let repeats = 200;
        t_distance.push(median_us(repeats, || {
            std::hint::black_box(geometry.min_capsule_distance(&kinematics, &human));
        }));
        // Distances with the Jacobian row of every pair (what a tick needs).
        t_pairs.push(median_us(repeats, || {
            geometry.pair_constraints(&robot, &kinematics, &human, 10.0, &mut pairs);
        }));
        geometry.pair_constraints(&robot, &kinematics, &human, config.detection_m, &mut pairs);
        if pairs.is_empty() {
            continue;
        }
        let lb: Vec<f64> = velocity.iter().map(|v| -v).collect();
        let solve = qp.solve(
            &qdot_nom,
            &mut pairs.clone(),
            &lb,
            &velocity,
            config.gamma_per_s,
            config.d_min_m,
            &mut qdot,
        );
        let Ok(slack) = solve else { continue };
        let problem = qp.problem();
        let mut scratch = pairs.clone();
        t_qp.push(median_us(50, || {
            scratch.copy_from_slice(&pairs);
            let _ = qp.solve(
                &qdot_nom,
                &mut scratch,
                &lb,
                &velocity,
                config.gamma_per_s,
                config.d_min_m,
                &mut qdot,
            );
        }));
        active_rows.push(pairs.len().min(config.max_pairs) as f64);
        qps.push(serde_json::json!({
            "P_diag": problem.p_diagonal, "q": problem.q, "m": problem.a_rows,
            "A_colptr": problem.a_colptr, "A_rowval": problem.a_rowval, "A_values": problem.a_values,
            "b": problem.b, "x": qdot.clone(), "slack": slack, "t_us": t_qp.last().copied().unwrap_or(f64::NAN),
        }));
        // The full tick.
        t_tick.push(median_us(50, || {
            filter.reset();
            let out = filter.tick(&robot, &q, &qdot_nom, &human, 0.004);
            std::hint::black_box(out.status == FilterStatus::Pass);
        }));
        t_tick_ahead.push(median_us(50, || {
            anticipating.reset();
            let out = anticipating.tick(&robot, &q, &qdot_nom, &human, 0.004);
            std::hint::black_box(out.status == FilterStatus::Pass);
        }));
        for (link, c) in geometry.capsules(&kinematics) {
            for p in &human.parts {
                let inflated = p.capsule.inflated(human.uncertainty_m);
                let d = workcell_safety::geometry::capsule_capsule(link, &c, p.part, &inflated)
                    .distance_m;
                capsule_pairs.push(vec![
                    c.a_W.x,
                    c.a_W.y,
                    c.a_W.z,
                    c.b_W.x,
                    c.b_W.y,
                    c.b_W.z,
                    c.radius_m,
                    inflated.a_W.x,
                    inflated.a_W.y,
                    inflated.a_W.z,
                    inflated.b_W.x,
                    inflated.b_W.y,
                    inflated.b_W.z,
                    inflated.radius_m,
                    d,
                ]);
            }
        }
    }
    let pairs_per_case = geometry.link_count() * 3;
    let summary = serde_json::json!({
        "cases": cases,
        "capsule_pairs_per_case": pairs_per_case,
        "mean_active_rows": active_rows.iter().sum::<f64>() / active_rows.len() as f64,
        "distance_us": {"median": percentile(&mut t_distance, 0.5), "p90": percentile(&mut t_distance, 0.9)},
        "distance_jacobian_us": {"median": percentile(&mut t_pairs, 0.5), "p90": percentile(&mut t_pairs, 0.9)},
        "qp_us": {"median": percentile(&mut t_qp, 0.5), "p90": percentile(&mut t_qp, 0.9)},
        "tick_us": {"median": percentile(&mut t_tick, 0.5), "p90": percentile(&mut t_tick, 0.9)},
        "tick_anticipating_0.15_s_us": {"median": percentile(&mut t_tick_ahead, 0.5), "p90": percentile(&mut t_tick_ahead, 0.9)},
    });
    println!("{}", serde_json::to_string_pretty(&summary)?);
    if let Some(path) = out {
        let all =
            serde_json::json!({"summary": summary, "capsule_pairs": capsule_pairs, "qps": qps});
        std::fs::write(&path, serde_json::to_string(&all)?)?;
        eprintln!("problems written to {path}");
    }
    Ok(())
}
