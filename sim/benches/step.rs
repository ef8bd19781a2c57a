//! Physics steps per second of the default cell at 1 ms (goal >= 10,000 on a 2-core machine),
//! and of each catalogue arm alone holding a configuration: the case that
//! `scripts/bench-vs-mujoco.sh` runs in MuJoCo too.
//!
//! `cargo bench -p workcell-sim --bench step`

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use workcell_sim::scenario::RobotMotionConfig;
use workcell_sim::{CellModel, CellState, RobotCommand, Scenario, step};

const STEPS: u64 = 1000;

fn run(c: &mut Criterion, name: &str, model: &CellModel) {
    let mut group = c.benchmark_group(name);
    group.throughput(Throughput::Elements(STEPS));
    group.sample_size(20);
    let mut state = CellState::new(model).expect("state");
    group.bench_function("1000 steps", |b| {
        b.iter(|| {
            for _ in 0..STEPS {
                step(model, &mut state, &RobotCommand::Nominal).expect("step");
            }
        })
    });
    group.finish();
}

fn cells(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/default.toml");
    let scenario = Scenario::from_file(&path).expect("default scenario");
    run(
        c,
        "default_cell",
        &CellModel::new(&scenario, &path).expect("model"),
    );
    // Each arm alone (no clutter, the human 10 m away), holding a configuration under
    // gravity; the same configurations as scripts/bench_mujoco_peer.py.
    for (robot, q) in [
        ("ur5e_kinematics", vec![0.0, -1.2, 1.5, -1.9, -1.57, 0.0]),
        (
            "iiwa14_kinematics",
            vec![0.0, 0.6, 0.0, -1.4, 0.0, 0.8, 0.0],
        ),
    ] {
        let mut alone = scenario.clone();
        alone.clutter.clear();
        alone.human.base.xyz = [10.0, 0.0, 0.0];
        alone.robot.model = robot.into();
        alone.robot.base = Default::default();
        alone.robot.initial_q = q;
        alone.robot.motion = RobotMotionConfig::Hold;
        let model = CellModel::new(&alone, &path).expect("model");
        run(c, &format!("{robot}_alone_hold"), &model);
    }
}

criterion_group!(benches, cells);
criterion_main!(benches);
