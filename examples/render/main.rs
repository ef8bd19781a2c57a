//! Renders the default cell from its camera after one second of motion and writes the RGB
//! frame, the class map and the depth image: `cargo run --release --example render -- OUT_DIR`.
//! With `--features gpu` the wgpu backend renders the same frame and the two are compared.

use std::path::PathBuf;

use workcell::render::image::{PixelKind, write_png};
use workcell::render::{Class, CpuRenderer, Frame, Renderer};
use workcell::sim::{CellModel, CellScene, CellState, RobotCommand, step};

fn main() -> anyhow::Result<()> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "out/render".into()),
    );
    std::fs::create_dir_all(&out)?;
    let model = CellModel::from_file("configs/default.toml")?;
    let mut state = CellState::new(&model)?;
    for _ in 0..1000 {
        step(&model, &mut state, &RobotCommand::Nominal)?;
    }
    let mut cell = CellScene::new(&model);
    cell.update(&state);
    let camera = model.scenario.cameras[0].camera()?;
    let mut frame = Frame::new();
    CpuRenderer::new().render(&cell.scene, &camera, &mut frame)?;
    write_frame(&out, "cpu", &cell, &frame)?;
    println!(
        "{} triangles, {}x{} px; forearm pixels: {}",
        cell.scene.triangle_count(),
        frame.width,
        frame.height,
        frame
            .classes(&cell.scene)
            .iter()
            .filter(|&&c| c == Class::Forearm as u8)
            .count()
    );
    #[cfg(feature = "gpu")]
    {
        let mut gpu = workcell::sim::render::GpuRenderer::new()?;
        let mut other = Frame::new();
        gpu.render(&cell.scene, &camera, &mut other)?;
        write_frame(&out, "gpu", &cell, &other)?;
        let same = frame
            .object
            .iter()
            .zip(&other.object)
            .filter(|(a, b)| a == b)
            .count();
        println!(
            "{}: object index agrees on {same} of {} pixels",
            gpu.name(),
            frame.object.len()
        );
    }
    println!("wrote {}", out.display());
    Ok(())
}

fn write_frame(
    out: &std::path::Path,
    tag: &str,
    cell: &CellScene,
    frame: &Frame,
) -> anyhow::Result<()> {
    let (w, h) = (frame.width, frame.height);
    write_png(
        &out.join(format!("{tag}_rgb.png")),
        w,
        h,
        PixelKind::Rgb,
        &frame.rgb,
    )?;
    let classes: Vec<u8> = frame
        .classes(&cell.scene)
        .iter()
        .flat_map(|&c| Class::from_u8(c).unwrap_or(Class::Background).color())
        .collect();
    write_png(
        &out.join(format!("{tag}_classes.png")),
        w,
        h,
        PixelKind::Rgb,
        &classes,
    )?;
    let far = frame
        .depth_m
        .iter()
        .copied()
        .fold(0.0f32, f32::max)
        .max(1e-6);
    let depth: Vec<u8> = frame
        .depth_m
        .iter()
        .map(|&d| (255.0 * (1.0 - d / far)) as u8)
        .collect();
    write_png(
        &out.join(format!("{tag}_depth.png")),
        w,
        h,
        PixelKind::Gray,
        &depth,
    )?;
    Ok(())
}
