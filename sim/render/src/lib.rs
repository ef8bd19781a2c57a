//! Camera frames of a work-cell, without the simulator: a pinhole [`Camera`], a [`Scene`] of posed triangle meshes, and
//! one [`Renderer`] interface with two backends that give the same pixels:
//!
//! - [`CpuRenderer`] (default): a software rasterizer written for this project. Vertices are
//!   snapped to 1/256 pixel and covered by exact integer edge functions with a top-left rule,
//!   triangles crossing the near plane are clipped, back faces of closed meshes culled, and a
//!   z-buffer on 1/z keeps the nearest surface.
//! - `GpuRenderer` (feature `gpu`): wgpu, headless, with the same vertex preparation, so the
//!   two differ only where a GPU's rasterizer rounds differently.
//!
//! Each frame has RGB (flat Lambert shading, per-triangle albedo, value-noise texture on
//! textured objects), linear depth along the optical axis, and the index of the object seen
//! at every pixel; [`Scene::class_of`] maps object indices to [`Class`]es. For
//! render-and-compare, [`Renderer::render_masks`] draws one mesh at N poses into N binary
//! masks in one call.
//!
//! The crate also holds what frames are stored as: PNG files ([`image`]), image-space
//! occluders ([`occlusion`]) and the dataset format ([`dataset`]), so that perception reads
//! datasets and renders its pose hypotheses beside a real camera, with no physics engine.
//!
//! Camera frame C: x right, y down, z forward (the optical axis); pixel (i, j) covers
//! `[i, i+1) x [j, j+1)` and is sampled at its centre.

mod camera;
mod cpu;
pub mod dataset;
mod error;
#[cfg(feature = "gpu")]
mod gpu;
pub mod image;
mod mesh;
pub mod occlusion;
mod preview;
pub mod roi;
mod scene;

pub use camera::Camera;
pub use cpu::CpuRenderer;
pub use error::{RenderError, Result};
#[cfg(feature = "gpu")]
pub use gpu::GpuRenderer;
pub use mesh::RenderMesh;
pub use preview::robot_preview;
pub use scene::{Class, Scene, SceneObject, human_classes, link_objects};

use workcell_robots::math::Pose;

/// Sub-pixel precision of vertex positions: 8 bits, as GPUs commonly snap.
pub const SUBPIXEL_BITS: u32 = 8;

/// The nearest depth drawn, m; closer geometry is clipped.
pub const NEAR_M: f64 = 0.02;

/// One rendered image: RGB, depth and object index, row-major from the top-left pixel.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Frame {
    pub width: u32,
    pub height: u32,
    /// sRGB, 3 bytes per pixel.
    pub rgb: Vec<u8>,
    /// Depth along the optical axis, m; 0 where no surface is seen.
    pub depth_m: Vec<f32>,
    /// Object index per pixel: 0 for nothing, `k + 1` for `scene.objects[k]`.
    pub object: Vec<u16>,
}

impl Frame {
    /// An empty frame; renderers size it.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Resizes the buffers for `width x height` (keeps their allocation when it fits).
    pub fn resize(&mut self, width: u32, height: u32) {
        let n = width as usize * height as usize;
        self.width = width;
        self.height = height;
        self.rgb.resize(3 * n, 0);
        self.depth_m.resize(n, 0.0);
        self.object.resize(n, 0);
    }

    /// The class of every pixel.
    #[must_use]
    pub fn classes(&self, scene: &Scene) -> Vec<u8> {
        self.object
            .iter()
            .map(|&o| scene.class_of(o) as u8)
            .collect()
    }

    /// Number of pixels showing object index `id`.
    #[must_use]
    pub fn count(&self, id: u16) -> usize {
        self.object.iter().filter(|&&o| o == id).count()
    }
}

/// N binary masks of one size, stored one after another (1 = covered).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MaskBatch {
    pub width: u32,
    pub height: u32,
    pub len: usize,
    pub data: Vec<u8>,
}

impl MaskBatch {
    /// An empty batch; renderers size it.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Sizes the batch for `len` masks of `width x height`; reuses the allocation.
    pub fn resize(&mut self, width: u32, height: u32, len: usize) {
        self.width = width;
        self.height = height;
        self.len = len;
        self.data.resize(len * width as usize * height as usize, 0);
    }

    /// Mask `k`, row-major.
    #[must_use]
    pub fn mask(&self, k: usize) -> &[u8] {
        let n = self.width as usize * self.height as usize;
        &self.data[k * n..(k + 1) * n]
    }
}

/// N silhouettes of one size as row spans: per mask and row, the first and the last covered
/// pixel (inclusive; [`SpanBatch::EMPTY`] for a row with none). The pixels between them count
/// as covered: a row of a convex silhouette is one run, and a part of the human arm is
/// nearly convex. Scoring a span is two lookups in a row's prefix sums, where a mask's is a
/// pass over its pixels.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SpanBatch {
    pub width: u32,
    pub height: u32,
    pub len: usize,
    pub spans: Vec<[u32; 2]>,
}

impl SpanBatch {
    /// A row that covers nothing.
    pub const EMPTY: [u32; 2] = [u32::MAX, 0];

    /// An empty batch; renderers size it.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Sizes the batch for `len` silhouettes of `width x height`, every row empty; reuses
    /// the allocation.
    pub fn resize(&mut self, width: u32, height: u32, len: usize) {
        self.width = width;
        self.height = height;
        self.len = len;
        self.spans.clear();
        self.spans.resize(len * height as usize, Self::EMPTY);
    }

    /// Silhouette `k`: one span a row, top to bottom.
    #[must_use]
    pub fn spans(&self, k: usize) -> &[[u32; 2]] {
        let n = self.height as usize;
        &self.spans[k * n..(k + 1) * n]
    }

    /// The spans of `masks`: each row's first and last covered pixel.
    pub fn from_masks(&mut self, masks: &MaskBatch) {
        self.resize(masks.width, masks.height, masks.len);
        let w = masks.width as usize;
        if w == 0 {
            return;
        }
        for (span, row) in self.spans.iter_mut().zip(masks.data.chunks_exact(w)) {
            if let (Some(first), Some(last)) = (
                row.iter().position(|&m| m != 0),
                row.iter().rposition(|&m| m != 0),
            ) {
                *span = [first as u32, last as u32];
            }
        }
    }
}

/// A renderer backend.
pub trait Renderer {
    /// A short name for reports ("cpu", "wgpu").
    fn name(&self) -> String;

    /// Renders `scene` seen by `camera` into `frame` (resized to the camera's image).
    ///
    /// # Errors
    /// [`RenderError::InvalidRender`] for a camera or object pose that is not finite;
    /// [`RenderError::Gpu`] when the GPU fails.
    fn render(&mut self, scene: &Scene, camera: &Camera, frame: &mut Frame) -> Result<()>;

    /// The depth image alone of `scene` seen by `camera` into `depth_m` (resized to the
    /// camera's pixels, row-major): [`Frame::depth_m`] as [`Renderer::render`] draws it, 0
    /// where nothing is seen, without the colours a render-and-compare search never reads.
    /// By default from a whole render.
    ///
    /// # Errors
    /// As [`Renderer::render`].
    fn render_depth(
        &mut self,
        scene: &Scene,
        camera: &Camera,
        depth_m: &mut Vec<f32>,
    ) -> Result<()> {
        let mut frame = Frame::new();
        self.render(scene, camera, &mut frame)?;
        depth_m.clone_from(&frame.depth_m);
        Ok(())
    }

    /// Renders `mesh` alone at each pose `X_CO[k]` (object in the camera frame; the camera's
    /// own pose is not used) into mask `k` of `masks`.
    ///
    /// # Errors
    /// As [`Renderer::render`].
    fn render_masks(
        &mut self,
        mesh: &RenderMesh,
        camera: &Camera,
        X_CO: &[Pose],
        masks: &mut MaskBatch,
    ) -> Result<()>;

    /// Renders `mesh` alone at each pose `X_CO[k]` as [`Renderer::render_masks`] does, into
    /// silhouette `k` of `spans` as row spans. By default from the masks; the CPU renderer
    /// draws a mesh marked [`RenderMesh::convex`] from its outline polygon (the masks' pixels
    /// but where snapping leaves the triangles' outline a hair short of convex).
    ///
    /// # Errors
    /// As [`Renderer::render`].
    fn render_spans(
        &mut self,
        mesh: &RenderMesh,
        camera: &Camera,
        X_CO: &[Pose],
        spans: &mut SpanBatch,
    ) -> Result<()> {
        let mut masks = MaskBatch::new();
        self.render_masks(mesh, camera, X_CO, &mut masks)?;
        spans.from_masks(&masks);
        Ok(())
    }
}

/// Whether every number of a pose is finite.
pub(crate) fn pose_is_finite(X: &Pose) -> bool {
    X.translation.is_finite() && X.rotation.is_finite()
}

/// A renderer backend by name, for configurations and command lines.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Backend {
    /// The software rasterizer.
    #[default]
    Cpu,
    /// wgpu (feature `gpu`).
    Gpu,
}

impl Backend {
    /// `cpu` or `gpu`.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Backend::Cpu => "cpu",
            Backend::Gpu => "gpu",
        }
    }

    /// A new renderer of this backend.
    ///
    /// # Errors
    /// [`RenderError::Gpu`] when the GPU backend is not built in or finds no adapter.
    pub fn renderer(self) -> Result<Box<dyn Renderer + Send>> {
        match self {
            Backend::Cpu => Ok(Box::new(CpuRenderer::new())),
            #[cfg(feature = "gpu")]
            Backend::Gpu => Ok(Box::new(GpuRenderer::new()?)),
            #[cfg(not(feature = "gpu"))]
            Backend::Gpu => Err(RenderError::Gpu {
                message: "this build has no GPU renderer (build with --features gpu)".into(),
            }),
        }
    }
}

impl std::str::FromStr for Backend {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "cpu" => Ok(Backend::Cpu),
            "gpu" => Ok(Backend::Gpu),
            _ => Err(format!("unknown renderer backend {s:?} (cpu or gpu)")),
        }
    }
}
