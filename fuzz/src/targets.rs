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
pub const TARGETS: [&str; 16] = [
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
    "bvh",
    "joint_table",
    "clip_library",
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
        "bvh" => {
            if let Some(text) = text() {
                let path = Path::new("fuzz.bvh");
                if let Ok(mut bvh) = workcell::mocap::bvh::Bvh::parse(text, path) {
                    use workcell::mocap::bvh::Euler;
                    // Listed last: the arbitrary map below reads the format's convention.
                    for (preset, euler) in [
                        ("hrc", Euler::FixedZxy),
                        ("cmu", Euler::FixedZxy),
                        ("hrc", Euler::Listed),
                        ("cmu", Euler::Listed),
                    ] {
                        bvh.euler = euler;
                        if let Some(map) = workcell::mocap::bvh::joint_map_preset(preset) {
                            let _ = bvh.clip(
                                &map,
                                0.001,
                                workcell::mocap::Axes::Y_UP,
                                "fuzz".into(),
                                path,
                            );
                        }
                    }
                    // Whatever the hierarchy names, its first joint as the pelvis and its
                    // last as a wrist.
                    let names: Vec<String> = bvh.joint_names().map(str::to_string).collect();
                    if let (Some(first), Some(last)) = (names.first(), names.last()) {
                        let map = [
                            (workcell::mocap::Landmark::Pelvis, first.clone()),
                            (workcell::mocap::Landmark::RightWrist, last.clone()),
                        ]
                        .into_iter()
                        .collect();
                        if let Ok(clip) =
                            bvh.clip(&map, 1.0, workcell::mocap::Axes::Z_UP, "fuzz".into(), path)
                        {
                            let config = workcell::mocap::clean::CleanConfig::default();
                            let _ = workcell::mocap::clean::clean(&clip, &config);
                        }
                    }
                }
            }
        }
        "joint_table" => {
            if let Some(text) = text() {
                let format = workcell::mocap::table::TableFormat {
                    columns: workcell::mocap::table::ASSEMBLY_COLUMNS.to_vec(),
                    rate_hz: 30.0,
                    metres_per_unit: 1.0,
                    axes: workcell::mocap::Axes::CAMERA,
                    max_gap_s: 0.5,
                };
                let path = Path::new("fuzz.txt");
                if let Ok(clip) =
                    workcell::mocap::table::parse_table(text, &format, "fuzz".into(), path)
                {
                    let config = workcell::mocap::clean::CleanConfig::default();
                    let (pieces, _) = workcell::mocap::clean::clean(&clip, &config);
                    for piece in &pieces {
                        let _ = workcell::mocap::stats::clip_samples(piece);
                    }
                }
            }
        }
        "clip_library" => {
            // Beside the shipped clips: a collection may name their folders (or try to leave).
            if let Some(text) = text() {
                let _ = workcell::mocap::library::Library::from_toml(
                    text,
                    &root().join("data/mocap/fuzz.toml"),
                );
            }
        }
        _ => {}
    }
}
