//! Forward kinematics and the Jacobian of the 7-DoF arm (goal: FK + Jacobian <= 2 us).
//!
//! `cargo bench -p workcell-robots --bench kinematics`

use criterion::{Criterion, black_box, criterion_group, criterion_main};
use workcell_robots::math::Vector;
use workcell_robots::{Jacobian, KinematicState, RobotModel};

fn kinematics(c: &mut Criterion) {
    for name in ["iiwa14_kinematics", "ur5e_kinematics"] {
        let robot = RobotModel::from_catalogue(name).expect("catalogue");
        let tool = robot.link_id("tool0").expect("tool0");
        let q: Vec<f64> = (0..robot.dof()).map(|i| 0.3 + 0.1 * i as f64).collect();
        let mut state = KinematicState::new(&robot);
        let mut jacobian = Jacobian::zeros(robot.dof());
        c.bench_function(&format!("{name}/fk"), |b| {
            b.iter(|| {
                robot
                    .forward_kinematics(black_box(&q), &mut state)
                    .expect("fk")
            })
        });
        c.bench_function(&format!("{name}/fk+jacobian(tool0)"), |b| {
            b.iter(|| {
                robot
                    .forward_kinematics(black_box(&q), &mut state)
                    .expect("fk");
                let p = state
                    .link_pose(tool)
                    .transform_point(Vector::new(0.0, 0.0, 0.05));
                robot.point_jacobian(&state, tool, p, &mut jacobian);
                black_box(jacobian.get(0, 0))
            })
        });
    }
}

criterion_group!(benches, kinematics);
criterion_main!(benches);
