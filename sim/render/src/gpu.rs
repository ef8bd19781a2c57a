//! The wgpu backend: headless rendering into textures that are read back.
//!
//! The CPU prepares the triangles as the software rasterizer does (camera-frame vertices,
//! back faces of closed meshes culled, flat shading); the GPU clips, rasterizes, depth-tests
//! and textures them. So the two backends differ only in the rasterizer's rounding.

use std::num::NonZeroU64;

use wgpu::util::DeviceExt;
use workcell_robots::math::Pose;

use crate::cpu::{Affine, check_poses, check_scene, front_faces, shade};
use crate::error::{RenderError, Result};
use crate::{Camera, Frame, MaskBatch, NEAR_M, RenderMesh, Renderer, Scene};

const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;
const OBJECT_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Uint;
const ZBUFFER_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Masks drawn per submission (bounds the vertex buffer).
const MASKS_PER_PASS: usize = 256;

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Vertex {
    p_C: [f32; 3],
    color: [f32; 3],
    object: u32,
    texture: f32,
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Uniforms {
    proj: [f32; 4],
    near: [f32; 4],
    X_WC: [[f32; 4]; 4],
}

/// Render targets of one size.
struct Targets {
    width: u32,
    height: u32,
    color: wgpu::Texture,
    depth: wgpu::Texture,
    object: wgpu::Texture,
    zbuffer: wgpu::Texture,
    readback: wgpu::Buffer,
}

/// The wgpu renderer (Vulkan, headless). On a machine without a GPU it runs on a software
/// Vulkan driver such as Mesa's lavapipe.
pub struct GpuRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    bind_layout: wgpu::BindGroupLayout,
    adapter_name: String,
    max_side: u32,
    targets: Option<Targets>,
    vertices: Vec<Vertex>,
    scratch: Vec<[f32; 3]>,
}

impl std::fmt::Debug for GpuRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuRenderer")
            .field("adapter", &self.adapter_name)
            .finish_non_exhaustive()
    }
}

fn gpu_error(message: impl std::fmt::Display) -> RenderError {
    RenderError::Gpu {
        message: message.to_string(),
    }
}

impl GpuRenderer {
    /// Opens the first Vulkan adapter (a GPU, or a software driver).
    ///
    /// # Errors
    /// [`RenderError::Gpu`] when no adapter or device can be had.
    pub fn new() -> Result<Self> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor {
            backends: wgpu::Backends::VULKAN,
            ..wgpu::InstanceDescriptor::new_without_display_handle()
        });
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| {
            gpu_error(format!(
                "no Vulkan adapter ({e}); install a GPU driver or mesa-vulkan-drivers"
            ))
        })?;
        let info = adapter.get_info();
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("workcell"),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(gpu_error)?;
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("workcell render"),
            source: wgpu::ShaderSource::Wgsl(include_str!("gpu.wgsl").into()),
        });
        let bind_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: None,
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: NonZeroU64::new(std::mem::size_of::<Uniforms>() as u64),
                },
                count: None,
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: None,
            bind_group_layouts: &[Some(&bind_layout)],
            immediate_size: 0,
        });
        let target = |format| {
            Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })
        };
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("workcell scene"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<Vertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Uint32, 3 => Float32],
                })],
            },
            primitive: wgpu::PrimitiveState {
                topology: wgpu::PrimitiveTopology::TriangleList,
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: ZBUFFER_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Greater),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[target(COLOR_FORMAT), target(DEPTH_FORMAT), target(OBJECT_FORMAT)],
            }),
            multiview_mask: None,
            cache: None,
        });
        Ok(Self {
            device,
            queue,
            pipeline,
            bind_layout,
            adapter_name: format!("{} ({:?})", info.name, info.device_type),
            max_side: limits.max_texture_dimension_2d,
            targets: None,
            vertices: Vec::new(),
            scratch: Vec::new(),
        })
    }

    /// The adapter in use, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Cpu)`.
    #[must_use]
    pub fn adapter(&self) -> &str {
        &self.adapter_name
    }

    fn targets(&mut self, width: u32, height: u32) -> &Targets {
        let fits = self
            .targets
            .as_ref()
            .is_some_and(|t| t.width == width && t.height == height);
        if !fits {
            let texture = |format| {
                self.device.create_texture(&wgpu::TextureDescriptor {
                    label: None,
                    size: wgpu::Extent3d {
                        width,
                        height,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                })
            };
            let readback = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: u64::from(padded_row(width)) * u64::from(height),
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            });
            self.targets = Some(Targets {
                width,
                height,
                color: texture(COLOR_FORMAT),
                depth: texture(DEPTH_FORMAT),
                object: texture(OBJECT_FORMAT),
                zbuffer: texture(ZBUFFER_FORMAT),
                readback,
            });
        }
        self.targets.as_ref().expect("targets were just made")
    }

    /// Draws `self.vertices` (with `tiles`: vertex ranges and their viewports) and returns
    /// the three targets' bytes, rows unpadded.
    fn draw(
        &mut self,
        camera: &Camera,
        width: u32,
        height: u32,
        sky: [f32; 3],
        tiles: &[(std::ops::Range<u32>, [u32; 2])],
        read: [bool; 3],
    ) -> Result<[Vec<u8>; 3]> {
        let (w, h) = (camera.width as f32, camera.height as f32);
        let X = Affine::from_pose(&camera.X_WC).0;
        let uniforms = Uniforms {
            proj: [
                2.0 * camera.fx as f32 / w,
                2.0 * camera.cx as f32 / w - 1.0,
                -2.0 * camera.fy as f32 / h,
                1.0 - 2.0 * camera.cy as f32 / h,
            ],
            near: [NEAR_M as f32, 0.0, 0.0, 0.0],
            X_WC: [
                [X[0][0], X[1][0], X[2][0], 0.0],
                [X[0][1], X[1][1], X[2][1], 0.0],
                [X[0][2], X[1][2], X[2][2], 0.0],
                [X[0][3], X[1][3], X[2][3], 1.0],
            ],
        };
        let device = self.device.clone();
        let uniform_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: bytemuck::bytes_of(&uniforms),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.bind_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform_buffer.as_entire_binding(),
            }],
        });
        let vertex_buffer = (!self.vertices.is_empty()).then(|| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytemuck::cast_slice(&self.vertices),
                usage: wgpu::BufferUsages::VERTEX,
            })
        });
        let pipeline = self.pipeline.clone();
        let queue = self.queue.clone();
        let targets = self.targets(width, height);
        let views = [
            &targets.color,
            &targets.depth,
            &targets.object,
            &targets.zbuffer,
        ]
        .map(|t| t.create_view(&Default::default()));
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let clear = |c: wgpu::Color| wgpu::Operations {
                load: wgpu::LoadOp::Clear(c),
                store: wgpu::StoreOp::Store,
            };
            let sky = wgpu::Color {
                r: f64::from(sky[0]),
                g: f64::from(sky[1]),
                b: f64::from(sky[2]),
                a: 1.0,
            };
            let attachment = |view, ops| {
                Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops,
                })
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: None,
                color_attachments: &[
                    attachment(&views[0], clear(sky)),
                    attachment(&views[1], clear(wgpu::Color::TRANSPARENT)),
                    attachment(&views[2], clear(wgpu::Color::TRANSPARENT)),
                ],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &views[3],
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            if let Some(vb) = &vertex_buffer {
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.set_vertex_buffer(0, vb.slice(..));
                for (range, [x, y]) in tiles {
                    pass.set_viewport(*x as f32, *y as f32, w, h, 0.0, 1.0);
                    pass.set_scissor_rect(*x, *y, camera.width, camera.height);
                    pass.draw(range.clone(), 0..1);
                }
            }
        }
        queue.submit([encoder.finish()]);
        let mut out: [Vec<u8>; 3] = Default::default();
        for (k, texture) in [&targets.color, &targets.depth, &targets.object]
            .into_iter()
            .enumerate()
        {
            if read[k] {
                out[k] = read_texture(&device, &queue, texture, &targets.readback, width, height)?;
            }
        }
        Ok(out)
    }

    /// Appends the front faces of `mesh` at `X_CO`, shaded, as vertices.
    fn push_mesh(
        &mut self,
        mesh: &RenderMesh,
        X_CO: &Affine,
        object: u32,
        texture: f32,
        light_C: Option<[f32; 3]>,
    ) {
        let Self {
            vertices, scratch, ..
        } = self;
        front_faces(mesh, X_CO, scratch, |t, n, albedo| {
            let color = light_C.map_or([1.0; 3], |l| albedo.map(|a| a * shade(n, t[0], l)));
            vertices.extend(t.map(|p_C| Vertex {
                p_C,
                color,
                object,
                texture,
            }));
        });
    }
}

/// Bytes per row of a read-back buffer (4 bytes per texel, rows aligned to 256 bytes).
fn padded_row(width: u32) -> u32 {
    (4 * width).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

/// Copies a 4-byte-per-texel texture into `buffer` and returns its rows, unpadded.
fn read_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    buffer: &wgpu::Buffer,
    width: u32,
    height: u32,
) -> Result<Vec<u8>> {
    let row = padded_row(width);
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([encoder.finish()]);
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: None,
        })
        .map_err(gpu_error)?;
    rx.recv().map_err(gpu_error)?.map_err(gpu_error)?;
    let mut out = Vec::with_capacity(4 * width as usize * height as usize);
    {
        let data = slice.get_mapped_range().map_err(gpu_error)?;
        for r in 0..height as usize {
            let start = r * row as usize;
            out.extend_from_slice(&data[start..start + 4 * width as usize]);
        }
    }
    buffer.unmap();
    Ok(out)
}

impl Renderer for GpuRenderer {
    fn name(&self) -> String {
        format!("wgpu {}", self.adapter_name)
    }

    fn render(&mut self, scene: &Scene, camera: &Camera, frame: &mut Frame) -> Result<()> {
        camera.validate()?;
        check_scene(scene)?;
        if camera.width > self.max_side || camera.height > self.max_side {
            return Err(RenderError::InvalidRender {
                message: format!(
                    "image {}x{} exceeds the GPU's {} px",
                    camera.width, camera.height, self.max_side
                ),
            });
        }
        let X_CW = camera.X_WC.inverse();
        let light_C = Affine::from_pose(&X_CW).rotate(scene.light_W);
        self.vertices.clear();
        for (k, object) in scene.objects.iter().enumerate() {
            let X_CO = Affine::from_pose(&(X_CW * object.X_WO));
            self.push_mesh(
                &object.mesh,
                &X_CO,
                (k + 1) as u32,
                object.texture,
                Some(light_C),
            );
        }
        let count = self.vertices.len() as u32;
        let [rgba, depth, object] = self.draw(
            camera,
            camera.width,
            camera.height,
            scene.sky,
            &[(0..count, [0, 0])],
            [true, true, true],
        )?;
        frame.resize(camera.width, camera.height);
        for (p, px) in rgba.chunks_exact(4).enumerate() {
            frame.rgb[3 * p..3 * p + 3].copy_from_slice(&px[..3]);
        }
        for (d, b) in frame.depth_m.iter_mut().zip(depth.chunks_exact(4)) {
            *d = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
        for (o, b) in frame.object.iter_mut().zip(object.chunks_exact(4)) {
            *o = u16::try_from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])).unwrap_or(0);
        }
        Ok(())
    }

    fn render_masks(
        &mut self,
        mesh: &RenderMesh,
        camera: &Camera,
        X_CO: &[Pose],
        masks: &mut MaskBatch,
    ) -> Result<()> {
        camera.validate()?;
        check_poses(X_CO)?;
        let (w, h) = (camera.width, camera.height);
        masks.resize(w, h, X_CO.len());
        // Masks are tiles of an atlas, one viewport and scissor each.
        let columns = (self.max_side / w).max(1) as usize;
        let per_pass = MASKS_PER_PASS
            .min(columns * (self.max_side / h).max(1) as usize)
            .max(1);
        let n = w as usize * h as usize;
        for (chunk, poses) in X_CO.chunks(per_pass).enumerate() {
            let cols = columns.min(poses.len());
            let rows = poses.len().div_ceil(cols);
            let (aw, ah) = (cols as u32 * w, rows as u32 * h);
            self.vertices.clear();
            let mut tiles = Vec::with_capacity(poses.len());
            for (k, X) in poses.iter().enumerate() {
                let start = self.vertices.len() as u32;
                self.push_mesh(mesh, &Affine::from_pose(X), 1, 0.0, None);
                let origin = [(k % cols) as u32 * w, (k / cols) as u32 * h];
                tiles.push((start..self.vertices.len() as u32, origin));
            }
            let [_, _, object] =
                self.draw(camera, aw, ah, [0.0; 3], &tiles, [false, false, true])?;
            for (k, [x0, y0]) in tiles.iter().map(|t| t.1).enumerate() {
                let mask = &mut masks.data[(chunk * per_pass + k) * n..][..n];
                for r in 0..h as usize {
                    for c in 0..w as usize {
                        let p = 4 * ((y0 as usize + r) * aw as usize + x0 as usize + c);
                        mask[r * w as usize + c] = u8::from(object[p] != 0);
                    }
                }
            }
        }
        Ok(())
    }
}
