//! Physics steps per second of the default cell at 1 ms (goal >= 10,000 on a 2-core machine)
//! and of the robot alone.
//!
//! `cargo bench -p workcell-sim --bench step`

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
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
    let mut alone = scenario.clone();
    alone.clutter.clear();
    alone.human.base.xyz = [10.0, 0.0, 0.0];
    run(
        c,
        "robot_alone",
        &CellModel::new(&alone, &path).expect("model"),
    );
}

criterion_group!(benches, cells);
criterion_main!(benches);
