//! Writing binary glTF 2.0 (`.glb`): one JSON chunk, one binary buffer.
//!
//! A small builder of the parts this project writes: meshes with flat colours, nodes,
//! cameras and sampled animations. [`crate::TriMesh::to_glb`] writes one mesh; the
//! evaluation's 3D replays (`workcell evaluate --gltf N`) write whole episodes. Reading is
//! the gltf crate's ([`crate::TriMesh::load`]).

use serde_json::{Value, json};

/// glTF's `componentType` of 32-bit floats.
const FLOAT: u32 = 5126;
/// glTF's `componentType` of unsigned 32-bit integers.
const UNSIGNED_INT: u32 = 5125;
/// `bufferView.target` of vertex attributes and of indices.
const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// glTF primitive modes this builder writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    Lines = 1,
    Triangles = 4,
}

/// A binary glTF under construction.
#[derive(Debug, Default)]
pub struct GlbBuilder {
    bin: Vec<u8>,
    buffer_views: Vec<Value>,
    accessors: Vec<Value>,
    materials: Vec<Value>,
    meshes: Vec<Value>,
    cameras: Vec<Value>,
    nodes: Vec<Value>,
    roots: Vec<usize>,
    channels: Vec<Value>,
    samplers: Vec<Value>,
    by_colour: Vec<([u32; 4], usize)>,
}

impl GlbBuilder {
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends `bytes` as a buffer view (4-byte aligned); returns its index.
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut v = json!({"buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.bin.extend_from_slice(bytes);
        self.buffer_views.push(v);
        self.buffer_views.len() - 1
    }

    /// An accessor over floats, `width` per element (`SCALAR`, `VEC3`, `VEC4`), with the
    /// per-component bounds glTF requires of positions and animation inputs.
    ///
    /// # Panics
    /// When `data.len()` is not a multiple of `width` or `width` is not 1, 3 or 4 (a bug of
    /// the caller, never input).
    pub fn floats(&mut self, data: &[f32], width: usize, vertex_attribute: bool) -> usize {
        assert!(matches!(width, 1 | 3 | 4) && data.len().is_multiple_of(width));
        let kind = match width {
            1 => "SCALAR",
            3 => "VEC3",
            _ => "VEC4",
        };
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes, vertex_attribute.then_some(ARRAY_BUFFER));
        let mut min = vec![f32::INFINITY; width];
        let mut max = vec![f32::NEG_INFINITY; width];
        for item in data.chunks_exact(width) {
            for (k, &x) in item.iter().enumerate() {
                min[k] = min[k].min(x);
                max[k] = max[k].max(x);
            }
        }
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": FLOAT,
            "count": data.len() / width,
            "type": kind,
            "min": min,
            "max": max,
        }));
        self.accessors.len() - 1
    }

    /// An accessor over vertex indices.
    pub fn indices(&mut self, data: &[u32]) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": UNSIGNED_INT,
            "count": data.len(),
            "type": "SCALAR",
        }));
        self.accessors.len() - 1
    }

    /// A flat-coloured material (linear RGBA; alpha below 1 is blended).
    pub fn material(&mut self, name: &str, rgba: [f32; 4]) -> usize {
        let mut m = json!({
            "name": name,
            "pbrMetallicRoughness": {"baseColorFactor": rgba, "metallicFactor": 0.0, "roughnessFactor": 0.8},
            "doubleSided": true,
        });
        if rgba[3] < 1.0 {
            m["alphaMode"] = json!("BLEND");
        }
        self.materials.push(m);
        self.materials.len() - 1
    }

    /// A mesh of one primitive: `positions` (x, y, z per vertex), `indices` into them
    /// (triangles or line segments), in `material`.
    pub fn mesh(
        &mut self,
        name: &str,
        positions: &[[f32; 3]],
        indices: &[u32],
        mode: Mode,
        material: usize,
    ) -> usize {
        let flat: Vec<f32> = positions.iter().flatten().copied().collect();
        let position = self.floats(&flat, 3, true);
        let mut attributes = json!({"POSITION": position});
        if mode == Mode::Triangles {
            let normals = vertex_normals(positions, indices);
            let flat: Vec<f32> = normals.iter().flatten().copied().collect();
            attributes["NORMAL"] = json!(self.floats(&flat, 3, true));
        }
        let index = self.indices(indices);
        self.meshes.push(json!({
            "name": name,
            "primitives": [{"attributes": attributes, "indices": index, "mode": mode as u32, "material": material}],
        }));
        self.meshes.len() - 1
    }

    /// A triangle mesh whose triangles come in colour groups: one primitive per group
    /// (`indices`, linear RGBA), all sharing `positions` and their normals.
    pub fn mesh_groups(
        &mut self,
        name: &str,
        positions: &[[f32; 3]],
        groups: &[(Vec<u32>, [f32; 4])],
    ) -> usize {
        let flat: Vec<f32> = positions.iter().flatten().copied().collect();
        let position = self.floats(&flat, 3, true);
        let all: Vec<u32> = groups.iter().flat_map(|(i, _)| i.iter().copied()).collect();
        let normals = vertex_normals(positions, &all);
        let flat: Vec<f32> = normals.iter().flatten().copied().collect();
        let normal = self.floats(&flat, 3, true);
        let primitives: Vec<Value> = groups
            .iter()
            .map(|(indices, rgba)| {
                let material = self.coloured(*rgba);
                let index = self.indices(indices);
                json!({
                    "attributes": {"POSITION": position, "NORMAL": normal},
                    "indices": index,
                    "mode": Mode::Triangles as u32,
                    "material": material,
                })
            })
            .collect();
        self.meshes
            .push(json!({"name": name, "primitives": primitives}));
        self.meshes.len() - 1
    }

    /// Line segments (`indices` in pairs) in one colour.
    pub fn mesh_lines(
        &mut self,
        name: &str,
        points: &[[f32; 3]],
        indices: &[u32],
        rgba: [f32; 4],
    ) -> usize {
        let material = self.coloured(rgba);
        self.mesh(name, points, indices, Mode::Lines, material)
    }

    /// The material of colour `rgba`, made once per colour.
    fn coloured(&mut self, rgba: [f32; 4]) -> usize {
        let key = rgba.map(f32::to_bits);
        if let Some(&(_, m)) = self.by_colour.iter().find(|(k, _)| *k == key) {
            return m;
        }
        let m = self.material(&format!("rgba {rgba:?}"), rgba);
        self.by_colour.push((key, m));
        m
    }

    /// A perspective camera (vertical field of view in radians, width over height).
    pub fn camera(&mut self, name: &str, yfov_rad: f64, aspect: f64, near_m: f64) -> usize {
        self.cameras.push(json!({
            "name": name,
            "type": "perspective",
            "perspective": {"yfov": yfov_rad, "aspectRatio": aspect, "znear": near_m},
        }));
        self.cameras.len() - 1
    }

    /// A node; `extra` holds its other properties (`mesh`, `camera`, `children`,
    /// `translation`, `rotation`, `scale`). `root` puts it in the scene.
    pub fn node(&mut self, name: &str, extra: Value, root: bool) -> usize {
        let mut n = json!({"name": name});
        if let (Some(n), Value::Object(extra)) = (n.as_object_mut(), extra) {
            n.extend(extra);
        }
        self.nodes.push(n);
        let index = self.nodes.len() - 1;
        if root {
            self.roots.push(index);
        }
        index
    }

    /// Animates `node`'s `path` (`translation`: 3 values per key, `rotation`: a unit
    /// quaternion x, y, z, w, `scale`: 3) between keys at the times of accessor `times`
    /// (from [`GlbBuilder::floats`], shared by channels sampled alike), `interpolation`
    /// `LINEAR` or `STEP`.
    pub fn animate(
        &mut self,
        node: usize,
        path: &str,
        times: usize,
        values: &[f32],
        interpolation: &str,
    ) {
        let width = if path == "rotation" { 4 } else { 3 };
        let output = self.floats(values, width, false);
        self.samplers
            .push(json!({"input": times, "output": output, "interpolation": interpolation}));
        self.channels.push(json!({
            "sampler": self.samplers.len() - 1,
            "target": {"node": node, "path": path},
        }));
    }

    /// The file's bytes.
    #[must_use]
    pub fn finish(mut self, generator: &str, animation: &str) -> Vec<u8> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let mut doc = json!({
            "asset": {"version": "2.0", "generator": generator},
            "scene": 0,
            "scenes": [{"nodes": self.roots}],
            "nodes": self.nodes,
            "buffers": [{"byteLength": self.bin.len()}],
            "bufferViews": self.buffer_views,
            "accessors": self.accessors,
        });
        for (key, list) in [
            ("materials", self.materials),
            ("meshes", self.meshes),
            ("cameras", self.cameras),
        ] {
            if !list.is_empty() {
                doc[key] = Value::Array(list);
            }
        }
        if !self.channels.is_empty() {
            doc["animations"] = json!([{
                "name": animation,
                "channels": self.channels,
                "samplers": self.samplers,
            }]);
        }
        let mut text = doc.to_string().into_bytes();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let total = 12 + 8 + text.len() + 8 + self.bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&self.bin);
        out
    }
}

/// Area-weighted vertex normals of a triangle list (a zero normal stays zero; viewers shade
/// it flat).
fn vertex_normals(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
    let mut normals = vec![[0.0f32; 3]; positions.len()];
    for t in indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| positions[i as usize]);
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        for &i in t {
            for k in 0..3 {
                normals[i as usize][k] += n[k];
            }
        }
    }
    for n in &mut normals {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if len > 0.0 {
            *n = n.map(|x| x / len);
        }
    }
    normals
}
