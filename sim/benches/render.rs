//! Renderer speed: frames of the default scene (what moved, and all anew), forearm masks for render-and-compare, the
//! whole body's forearm as row spans (its pieces, and its hull, as the fit renders them), and
//! PNG encoding of a dataset frame. `cargo bench -p workcell-sim --bench render`; with
//! `--features gpu` the wgpu backend runs the same cases beside the CPU.

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use workcell_robots::math::{Pose, Rotation, Vector};
use workcell_sim::render::image::{PixelKind, encode_png};
use workcell_sim::render::{
    Camera, CpuRenderer, Frame, MaskBatch, RenderMesh, Renderer, SpanBatch,
};
use workcell_sim::{CellModel, CellScene, CellState, RobotCommand, step};

fn default_cell() -> (CellScene, Camera) {
    let model = CellModel::from_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/default.toml"
    ))
    .expect("default cell");
    let mut state = CellState::new(&model).expect("state");
    for _ in 0..1000 {
        step(&model, &mut state, &RobotCommand::Nominal).expect("step");
    }
    let mut cell = CellScene::new(&model);
    cell.update(&state);
    let camera = model.scenario.cameras[0].camera().expect("camera");
    (cell, camera)
}

/// 256 poses of the forearm around 0.7 m in front of the camera.
fn mask_poses() -> Vec<Pose> {
    (0..256)
        .map(|k| {
            let a = f64::from(k) * 0.05;
            Pose::from_parts(
                Vector::new(0.05 * a.sin(), 0.05 * a.cos(), 0.6 + 0.001 * f64::from(k)),
                Rotation::from_scaled_axis(Vector::new(1.2 + 0.1 * a, 0.3 * a, 0.1)),
            )
        })
        .collect()
}

fn cases(
    c: &mut Criterion,
    name: &str,
    renderer: &mut (dyn Renderer + Send),
    threads: Option<usize>,
) {
    let (cell, camera) = default_cell();
    let forearm: RenderMesh =
        (*cell.scene.objects[cell.forearm_object().expect("forearm")].mesh).clone();
    let mut group = c.benchmark_group(format!("render/{name}"));
    group.throughput(Throughput::Elements(1));
    let mut frame = Frame::new();
    // The robot and the human a centimetre apart in every other frame, as a camera watching
    // the cell sees them: `frame_*` draws what moved (a renderer that keeps the last frame
    // redraws only that), `frame_*_new_view` every frame anew (the camera alternates by a
    // millimetre: nothing of the last frame is kept).
    let mut moved = cell.scene.clone();
    for k in cell
        .robot_objects
        .iter()
        .chain(&cell.human_objects)
        .flatten()
    {
        moved.objects[*k].X_WO.translation.y += 0.01;
    }
    let scenes = [&cell.scene, &moved];
    for (w, h) in [(128, 128), (320, 240)] {
        let cam = camera.resized(w, h).expect("size");
        let mut beside = cam;
        beside.X_WC.translation.x += 0.001;
        let mut k = 0usize;
        group.bench_function(format!("frame_{w}x{h}"), |b| {
            b.iter(|| {
                k += 1;
                renderer
                    .render(scenes[k % 2], &cam, &mut frame)
                    .expect("render")
            });
        });
        let cameras = [cam, beside];
        group.bench_function(format!("frame_{w}x{h}_new_view"), |b| {
            b.iter(|| {
                k += 1;
                renderer
                    .render(&cell.scene, &cameras[k % 2], &mut frame)
                    .expect("render")
            });
        });
    }
    let poses = mask_poses();
    group.throughput(Throughput::Elements(poses.len() as u64));
    let pool = threads.map(|n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .expect("pool")
    });
    let mut masks = MaskBatch::new();
    for side in [64, 128] {
        let cam = Camera::look_at(
            [0.0; 3],
            [0.0, 0.0, 1.0],
            [0.0, -1.0, 0.0],
            side,
            side,
            40.0,
        )
        .expect("camera");
        group.bench_function(format!("forearm_masks_{side}x{side}_x256"), |b| {
            b.iter(|| {
                match &pool {
                    Some(pool) => {
                        pool.install(|| renderer.render_masks(&forearm, &cam, &poses, &mut masks))
                    }
                    None => renderer.render_masks(&forearm, &cam, &poses, &mut masks),
                }
                .expect("masks")
            });
        });
    }
    group.finish();
}

/// The whole body's forearm as the articulated fit renders it (6 segments around round
/// shapes): its visuals' outside pieces, and their convex hull.
fn body_forearm() -> (RenderMesh, RenderMesh) {
    let human = workcell_robots::RobotModel::from_catalogue("human").expect("human");
    let link = human.link_id("forearm").expect("forearm");
    let pieces: Vec<(RenderMesh, bool)> = human.links()[link]
        .visuals
        .iter()
        .map(|g| {
            let convex = !matches!(g.shape, workcell_robots::Shape::Mesh { .. });
            (RenderMesh::from_geometry_with(g, [0.5; 3], 6), convex)
        })
        .collect();
    let mut all = RenderMesh::default();
    for (piece, _) in &pieces {
        all.append(piece, &Pose::IDENTITY);
    }
    (
        RenderMesh::outer_union(&pieces),
        all.convex_hull().expect("a hull"),
    )
}

/// Row spans of the whole body's forearm at 256 poses in a 128x128 crop, one thread: what
/// each candidate of the fit's search costs. Its pieces, their hull drawn triangle by
/// triangle, and the hull drawn from its outline polygon (a convex mesh's path).
fn spans(c: &mut Criterion) {
    let (pieces, hull) = body_forearm();
    eprintln!(
        "the whole body's forearm: {} triangles as pieces, {} as their hull",
        pieces.len(),
        hull.len()
    );
    let cam = Camera::look_at([0.0; 3], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0], 128, 128, 40.0)
        .expect("camera");
    let poses = mask_poses();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool");
    let mut renderer = CpuRenderer::new();
    let mut spans = SpanBatch::new();
    // The hull drawn triangle by triangle, as a mesh not known to be convex is.
    let hull_triangles = RenderMesh {
        convex: false,
        ..hull.clone()
    };
    let mut group = c.benchmark_group("render/spans_1_thread");
    group.throughput(Throughput::Elements(poses.len() as u64));
    for (name, mesh) in [
        ("pieces", &pieces),
        ("hull_triangles", &hull_triangles),
        ("hull", &hull),
    ] {
        group.bench_function(format!("body_forearm_{name}_128x128_x256"), |b| {
            b.iter(|| {
                pool.install(|| renderer.render_spans(mesh, &cam, &poses, &mut spans))
                    .expect("spans")
            });
        });
    }
    group.finish();
}

fn cpu(c: &mut Criterion) {
    eprintln!(
        "default scene: {} triangles",
        default_cell().0.scene.triangle_count()
    );
    cases(c, "cpu_1_thread", &mut CpuRenderer::new(), Some(1));
    cases(c, "cpu_all_threads", &mut CpuRenderer::new(), None);
}

#[cfg(feature = "gpu")]
fn gpu(c: &mut Criterion) {
    let mut renderer = workcell_sim::render::GpuRenderer::new().expect("a Vulkan adapter");
    eprintln!("wgpu adapter: {}", renderer.adapter());
    cases(c, "wgpu", &mut renderer, None);
}

#[cfg(not(feature = "gpu"))]
fn gpu(_: &mut Criterion) {}

/// Encoding the five PNGs of one 128x128 dataset frame.
fn png(c: &mut Criterion) {
    let (cell, camera) = default_cell();
    let mut frame = Frame::new();
    CpuRenderer::new()
        .render(&cell.scene, &camera, &mut frame)
        .expect("render");
    let classes = frame.classes(&cell.scene);
    let mut group = c.benchmark_group("dataset");
    group.throughput(Throughput::Elements(1));
    group.bench_function("encode_frame_pngs_128x128", |b| {
        b.iter(|| {
            let mut bytes = encode_png(128, 128, PixelKind::Rgb, &frame.rgb)
                .expect("png")
                .len();
            for _ in 0..4 {
                bytes += encode_png(128, 128, PixelKind::Gray, &classes)
                    .expect("png")
                    .len();
            }
            bytes
        });
    });
    group.finish();
}

criterion_group!(benches, cpu, gpu, spans, png);
criterion_main!(benches);
