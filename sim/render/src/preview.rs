//! A picture of a robot: its visual meshes at a few configurations, side by side, drawn with
//! the project's renderer (for `workcell robot add`).

use std::sync::Arc;

use workcell_robots::RobotModel;
use workcell_robots::math::{Pose, Vector};

use crate::error::{RenderError, Result};
use crate::scene::link_objects;
use crate::{Camera, Class, CpuRenderer, Frame, RenderMesh, Renderer, Scene, SceneObject};

/// Renders `robot` (base at the origin, on a floor) at each configuration of `configurations`
/// into square tiles of `tile_px` pixels, two per row; returns `(width, height, sRGB bytes)`.
/// One camera frames every tile: it looks at the middle of all link origins, from the front
/// right and above, far enough to see them all.
///
/// # Errors
/// [`RenderError::InvalidRender`] for a configuration that does not fit the robot,
/// [`RenderError::InvalidRender`] for a tile size the camera refuses.
pub fn robot_preview(
    robot: &RobotModel,
    configurations: &[Vec<f64>],
    tile_px: u32,
) -> Result<(u32, u32, Vec<u8>)> {
    let mut poses = Vec::with_capacity(configurations.len());
    for q in configurations {
        let fk = robot
            .fk(Pose::IDENTITY, q)
            .map_err(|e| RenderError::InvalidRender {
                message: e.to_string(),
            })?;
        poses.push(fk.link_poses().to_vec());
    }
    // The points to frame: the link origins (a margin covers the links' own extent).
    let mut lo = Vector::splat(f64::INFINITY);
    let mut hi = Vector::splat(f64::NEG_INFINITY);
    for pose in poses.iter().flatten() {
        lo = lo.min(pose.translation);
        hi = hi.max(pose.translation);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        lo = Vector::ZERO;
        hi = Vector::ZERO;
    }
    let centre = 0.5 * (lo + hi);
    let radius = (0.5 * (hi - lo).length()).max(0.1) + 0.15;
    let fov_deg = 40.0_f64;
    let distance = radius / (0.5 * fov_deg.to_radians()).tan() * 0.9;
    let eye = centre + Vector::new(1.0, -0.8, 0.6).normalize() * distance;
    let camera = Camera::look_at(
        eye.to_array(),
        centre.to_array(),
        [0.0, 0.0, 1.0],
        tile_px,
        tile_px,
        fov_deg,
    )?;

    let mut scene = Scene::default();
    scene.push(SceneObject {
        name: "floor".into(),
        class: Class::Background,
        mesh: Arc::new(RenderMesh::cuboid([3.0, 3.0, 0.005], [0.55, 0.56, 0.58])),
        texture: 0.35,
        X_WO: Pose::from_translation(Vector::new(0.0, 0.0, lo.z.min(0.0) - 0.006)),
    });
    let objects = link_objects(
        &mut scene,
        robot,
        "robot",
        |_| Class::Robot,
        [0.93, 0.45, 0.08],
    );

    let columns = configurations.len().clamp(1, 2) as u32;
    let rows = (configurations.len() as u32).div_ceil(columns).max(1);
    let (width, height) = (columns * tile_px, rows * tile_px);
    let mut image = vec![255_u8; (width * height * 3) as usize];
    let mut renderer = CpuRenderer::new();
    let mut frame = Frame::new();
    for (k, link_poses) in poses.iter().enumerate() {
        for (object, X_WL) in objects.iter().zip(link_poses) {
            if let Some(i) = object {
                scene.objects[*i].X_WO = *X_WL;
            }
        }
        renderer.render(&scene, &camera, &mut frame)?;
        let (cx, cy) = (
            (k as u32 % columns) * tile_px,
            (k as u32 / columns) * tile_px,
        );
        for y in 0..tile_px {
            let src = (y * tile_px * 3) as usize;
            let dst = (((cy + y) * width + cx) * 3) as usize;
            let n = (tile_px * 3) as usize;
            image[dst..dst + n].copy_from_slice(&frame.rgb[src..src + n]);
        }
    }
    Ok((width, height, image))
}
