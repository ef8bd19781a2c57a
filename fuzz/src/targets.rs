//! The fuzz targets: each feeds one input surface of workcell with arbitrary bytes. A target
//! passes when it returns, whatever it returns: errors are the expected answer to hostile
//! input; a panic, an abort, a hang or a huge allocation is a finding.
//!
//! This file is compiled twice: into the AFL harness (`fuzz/`, `cargo afl`), and by path
//! into the test suite (`tests/fuzz_corpora.rs`), which replays every kept corpus file and
//! every past crash through the same functions on every `cargo test`.

use std::path::Path;

use workcell::procnet::train::TrainConfig;
use workcell::procnet::weights;
use workcell::render::dataset::Dataset;
use workcell::render::image::decode_png;
use workcell::robots::{PackageMap, RobotModel, TriMesh};
use workcell::sim::Scenario;
use workcell::sim::dataset::DatasetConfig;

/// Every target, by the name of its corpus folder.
pub const TARGETS: [&str; 13] = [
    "urdf",
    "urdf_rapier",
    "stl",
    "obj",
    "dae",
    "gltf",
    "png",
    "scenario",
    "evaluation",
    "dataset_config",
    "train_config",
    "weights",
    "manifest",
];

/// The repository's root, which anchors the paths that configs name.
fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .filter(|p| p.join("configs").is_dir())
        .unwrap_or(Path::new(env!("CARGO_MANIFEST_DIR")))
}

/// Runs `target` on `data`. Unknown target names do nothing.
pub fn run(target: &str, data: &[u8]) {
    let text = || std::str::from_utf8(data).ok();
    match target {
        "urdf" => {
            if let Some(text) = text() {
                let path = root().join("robots/tests/fixtures/fuzz/fuzz.urdf");
                if let Ok(robot) = RobotModel::from_urdf_str(text, &path, &PackageMap::new()) {
                    let q = robot.neutral_configuration();
                    let _ = robot.fk(workcell::robots::math::Pose::IDENTITY, &q);
                }
            }
        }
        "urdf_rapier" => {
            if let Some(text) = text() {
                let path = root().join("robots/tests/fixtures/fuzz/fuzz.urdf");
                if let Ok(robot) = RobotModel::from_urdf_str(text, &path, &PackageMap::new())
                    && robot.dof() <= 16
                {
                    let _ = workcell::sim::check_in_rapier(&robot, &robot.neutral_configuration());
                }
            }
        }
        "stl" | "obj" | "dae" => {
            let _ = TriMesh::from_bytes(data, Path::new(&format!("fuzz.{target}")), [1.0; 3]);
        }
        "gltf" => {
            // Beside the project's test meshes: a buffer URI may name one of them (or try to
            // leave the folder).
            let path = root().join("robots/tests/fixtures/meshes/fuzz.gltf");
            let _ = TriMesh::from_bytes(data, &path, [1.0; 3]);
        }
        "png" => {
            let _ = decode_png(data, Path::new("fuzz.png"));
        }
        "scenario" => {
            if let Some(text) = text() {
                let _ = Scenario::from_toml(text, &root().join("configs/fuzz.toml"));
            }
        }
        "evaluation" => {
            if let Some(text) = text() {
                let _ = workcell::evaluate::Evaluation::from_toml(
                    text,
                    &root().join("configs/fuzz.toml"),
                );
            }
        }
        "dataset_config" => {
            if let Some(text) = text() {
                let _ = DatasetConfig::from_toml(text, &root().join("configs/fuzz.toml"));
            }
        }
        "train_config" => {
            if let Some(text) = text() {
                let _ = TrainConfig::from_toml(text, &root().join("configs/fuzz.toml"));
            }
        }
        "weights" => {
            let _ = weights::config_from_bytes(data, Path::new("fuzz.safetensors"));
        }
        "manifest" => {
            if let Ok(dataset) = Dataset::from_manifest(root().join("fuzz-dataset"), data) {
                for entry in dataset.entries(None) {
                    let _ = dataset.labels(entry);
                }
            }
        }
        _ => {}
    }
}
