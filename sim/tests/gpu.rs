//! The wgpu backend against the software rasterizer (feature `gpu`; needs a Vulkan driver,
//! e.g. Mesa's lavapipe from Debian's mesa-vulkan-drivers, which CI installs).

#![cfg(feature = "gpu")]

use workcell_robots::math::{Pose, Rotation, Vector};
use workcell_sim::render::{Camera, CpuRenderer, Frame, GpuRenderer, MaskBatch, Renderer};
use workcell_sim::{CellModel, CellScene, CellState, RobotCommand, step};

fn agreement(a: &[u16], b: &[u16]) -> f64 {
    a.iter().zip(b).filter(|(x, y)| x == y).count() as f64 / a.len() as f64
}

#[test]
fn both_backends_agree_on_the_object_index_of_the_default_scene() {
    let mut gpu = GpuRenderer::new().expect("a Vulkan adapter (install mesa-vulkan-drivers)");
    eprintln!("adapter: {}", gpu.adapter());
    let model = CellModel::from_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/default.toml"
    ))
    .unwrap();
    let mut state = CellState::new(&model).unwrap();
    let mut cell = CellScene::new(&model);
    // The cell's camera with a square image, nearer the robot and the human (eye (0.6, 2.3,
    // 1.8), the cell's camera until 2026-12-05): its 640x480 squeezed, or the cell's camera now,
    // farther back, shows more of the textured walls and floor, where the backends' value noise
    // rounds apart by more than 3 levels in a tenth of the pixels (measured at t = 1 s, where
    // object index and depth agreed).
    let base = workcell_sim::scenario::CameraConfig {
        width_px: 128,
        height_px: 128,
        eye: [0.6, 2.3, 1.8],
        target: [0.5, 0.0, 1.0],
        ..model.scenario.cameras[0].clone()
    }
    .camera()
    .unwrap();
    let mut cpu = CpuRenderer::new();
    let (mut a, mut b) = (Frame::new(), Frame::new());
    for second in 0..3 {
        for _ in 0..1000 {
            step(&model, &mut state, &RobotCommand::Nominal).unwrap();
        }
        cell.update(&state);
        for (w, h) in [(128, 128), (320, 240)] {
            let cam = base.resized(w, h).unwrap();
            cpu.render(&cell.scene, &cam, &mut a).unwrap();
            gpu.render(&cell.scene, &cam, &mut b).unwrap();
            let agree = agreement(&a.object, &b.object);
            eprintln!(
                "t = {} s, {w}x{h}: object index agrees on {:.4} % of pixels",
                second + 1,
                100.0 * agree
            );
            assert!(agree >= 0.999, "{agree}");
            // Depth where both see the same object. The CPU interpolates 1/z from vertices
            // snapped to 1/256 px, the GPU from its own vertex positions; on surfaces seen at a
            // grazing angle depth changes fast across a pixel, so a few pixels differ more.
            let (mut tight, mut shared) = (0, 0);
            for p in 0..a.object.len() {
                if a.object[p] == b.object[p] && a.object[p] != 0 {
                    let (da, db) = (a.depth_m[p], b.depth_m[p]);
                    shared += 1;
                    tight += usize::from((da - db).abs() <= 1e-3 * da);
                    assert!((da - db).abs() <= 1e-2 * da, "depth {da} vs {db} at {p}");
                }
            }
            assert!(tight as f64 >= 0.99 * shared as f64, "{tight} of {shared}");
            // Colours: same shading, textures may differ by a cell where rounding differs.
            let close = a
                .rgb
                .iter()
                .zip(&b.rgb)
                .filter(|(x, y)| x.abs_diff(**y) <= 3)
                .count();
            assert!(
                close as f64 >= 0.97 * a.rgb.len() as f64,
                "{close} of {}",
                a.rgb.len()
            );
        }
    }
}

#[test]
fn both_backends_draw_the_same_masks() {
    let mut gpu = GpuRenderer::new().expect("a Vulkan adapter");
    let model = CellModel::from_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/default.toml"
    ))
    .unwrap();
    let cell = CellScene::new(&model);
    let forearm = &cell.scene.objects[cell.forearm_object().unwrap()].mesh;
    let cam = Camera::look_at([0.0; 3], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0], 128, 128, 40.0).unwrap();
    let poses: Vec<Pose> = (0..300)
        .map(|k| {
            let a = f64::from(k) * 0.1;
            Pose::from_parts(
                Vector::new(0.1 * a.sin(), 0.1 * a.cos(), 0.6 + 0.002 * f64::from(k)),
                Rotation::from_scaled_axis(Vector::new(1.0 + 0.3 * a, 0.5 * a, 0.2)),
            )
        })
        .collect();
    let (mut a, mut b) = (MaskBatch::new(), MaskBatch::new());
    CpuRenderer::new()
        .render_masks(forearm, &cam, &poses, &mut a)
        .unwrap();
    gpu.render_masks(forearm, &cam, &poses, &mut b).unwrap();
    let same = a.data.iter().zip(&b.data).filter(|(x, y)| x == y).count();
    let covered = a.data.iter().filter(|&&v| v == 1).count();
    eprintln!(
        "masks agree on {same} of {} pixels ({covered} covered)",
        a.data.len()
    );
    assert!(covered > 0);
    assert!(same as f64 >= 0.999 * a.data.len() as f64);
}

/// `dataset generate --backend gpu`: the generator renders through the `Renderer` trait, so
/// the wgpu backend makes the same sequences (same cameras, occluders and labels) with pixels
/// that agree with the software rasterizer's where the GPU rounds alike.
#[test]
fn a_sequence_rendered_on_the_gpu_matches_the_cpu_s() {
    use workcell_sim::dataset::{DatasetConfig, Generator, Timing};
    use workcell_sim::render::{Backend, Class};
    let dir = tempfile::tempdir().unwrap();
    let config = DatasetConfig {
        scenario: std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/default.toml"),
        sequences_per_pair: 1,
        sequences_per_episode: 3,
        frames: 3,
        width_px: 160,
        height_px: 120,
        input_px: 64,
        start_s: [0.5, 1.5],
        ..DatasetConfig::default()
    };
    let path = dir.path().join("dataset.toml");
    std::fs::write(&path, config.to_toml()).unwrap();
    let cpu = Generator::from_file(&path).unwrap();
    let gpu = Generator::from_file(&path)
        .unwrap()
        .with_backend(Backend::Gpu);
    let mut renderer = Backend::Gpu.renderer().expect("a Vulkan adapter");
    let mut cpu_renderer = Backend::Cpu.renderer().unwrap();
    for index in [0, 4, 8] {
        let a = cpu
            .sequence(index, cpu_renderer.as_mut(), &mut Timing::default())
            .unwrap();
        let b = gpu
            .sequence(index, renderer.as_mut(), &mut Timing::default())
            .unwrap();
        assert_eq!(a.entry.seed, b.entry.seed);
        for (fa, fb) in a.frames.iter().zip(&b.frames) {
            assert_eq!(fa.labels.camera, fb.labels.camera, "sequence {index}");
            let agree = agreement(
                &fa.classes.iter().map(|&c| u16::from(c)).collect::<Vec<_>>(),
                &fb.classes.iter().map(|&c| u16::from(c)).collect::<Vec<_>>(),
            );
            assert!(agree >= 0.995, "sequence {index}: {agree}");
            let (pa, pb) = (
                fa.labels.part(Class::Forearm).unwrap(),
                fb.labels.part(Class::Forearm).unwrap(),
            );
            let (na, nb) = (f64::from(pa.pixels_amodal), f64::from(pb.pixels_amodal));
            assert!((na - nb).abs() <= 0.1 * na.max(10.0), "{na} vs {nb}");
        }
    }
}
