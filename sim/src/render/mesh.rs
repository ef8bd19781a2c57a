//! Triangle meshes for rendering: URDF primitives tessellated, loaded meshes converted, all
//! wound counter-clockwise seen from outside so that back faces can be culled.

use std::sync::Arc;

use workcell_robots::math::{Pose, Vector};
use workcell_robots::{Geometry, Shape, TriMesh};

/// Segments around the axis of cylinders, capsules and spheres.
const SEGMENTS: usize = 16;

/// A triangle mesh in its object's frame, with one colour per triangle.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RenderMesh {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Linear RGB albedo in [0, 1] of each triangle.
    pub colors: Vec<[f32; 3]>,
    /// Whether every triangle is wound counter-clockwise seen from outside a closed surface,
    /// so that back faces may be culled. False for meshes of unknown orientation.
    pub closed: bool,
}

impl RenderMesh {
    /// Number of triangles.
    #[must_use]
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether the mesh has no triangles.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Appends `other`, moved by `X` (pose of `other`'s frame in this mesh's frame).
    /// The result is closed only if both parts are.
    pub fn append(&mut self, other: &RenderMesh, X: &Pose) {
        let was_empty = self.triangles.is_empty();
        let base = self.positions.len() as u32;
        self.positions.extend(other.positions.iter().map(|p| {
            let q = X.transform_point(Vector::new(
                f64::from(p[0]),
                f64::from(p[1]),
                f64::from(p[2]),
            ));
            [q.x as f32, q.y as f32, q.z as f32]
        }));
        self.triangles
            .extend(other.triangles.iter().map(|t| t.map(|i| i + base)));
        self.colors.extend_from_slice(&other.colors);
        self.closed = other.closed && (was_empty || self.closed);
    }

    /// An axis-aligned box centred at the origin with half extents `h`.
    #[must_use]
    pub fn cuboid(h: [f64; 3], color: [f32; 3]) -> Self {
        let [x, y, z] = h.map(|v| v as f32);
        let positions = vec![
            [-x, -y, -z],
            [x, -y, -z],
            [x, y, -z],
            [-x, y, -z],
            [-x, -y, z],
            [x, -y, z],
            [x, y, z],
            [-x, y, z],
        ];
        let triangles = vec![
            [0, 2, 1],
            [0, 3, 2], // -z
            [4, 5, 6],
            [4, 6, 7], // +z
            [0, 1, 5],
            [0, 5, 4], // -y
            [3, 7, 6],
            [3, 6, 2], // +y
            [0, 4, 7],
            [0, 7, 3], // -x
            [1, 2, 6],
            [1, 6, 5], // +x
        ];
        Self::solid(positions, triangles, color)
    }

    /// A closed cylinder along z centred at the origin.
    #[must_use]
    pub fn cylinder(radius: f64, length: f64, color: [f32; 3]) -> Self {
        let (r, h) = (radius as f32, (length / 2.0) as f32);
        let mut positions = Vec::with_capacity(2 * SEGMENTS + 2);
        for k in 0..SEGMENTS {
            let a = std::f32::consts::TAU * k as f32 / SEGMENTS as f32;
            positions.push([r * a.cos(), r * a.sin(), -h]);
            positions.push([r * a.cos(), r * a.sin(), h]);
        }
        let (bottom, top) = (positions.len() as u32, positions.len() as u32 + 1);
        positions.push([0.0, 0.0, -h]);
        positions.push([0.0, 0.0, h]);
        let mut triangles = Vec::with_capacity(4 * SEGMENTS);
        for k in 0..SEGMENTS as u32 {
            let n = (k + 1) % SEGMENTS as u32;
            let (b0, t0, b1, t1) = (2 * k, 2 * k + 1, 2 * n, 2 * n + 1);
            triangles.push([b0, b1, t1]);
            triangles.push([b0, t1, t0]);
            triangles.push([bottom, b1, b0]);
            triangles.push([top, t0, t1]);
        }
        Self::solid(positions, triangles, color)
    }

    /// A capsule along z: a cylinder of `length` capped by hemispheres; `length = 0` is a
    /// sphere.
    #[must_use]
    pub fn capsule(radius: f64, length: f64, color: [f32; 3]) -> Self {
        let (r, h) = (radius as f32, (length / 2.0) as f32);
        let rings = SEGMENTS / 2; // latitude bands per hemisphere, pole excluded
        let mut positions = Vec::new();
        // Rings from the bottom pole to the top pole; the two equator rings are offset by the
        // cylinder's half length.
        let mut ring_z = Vec::new();
        for i in 1..=rings {
            let lat = -std::f32::consts::FRAC_PI_2
                + std::f32::consts::FRAC_PI_2 * i as f32 / rings as f32;
            ring_z.push((r * lat.cos(), r * lat.sin() - h));
        }
        for i in 0..rings {
            let lat = std::f32::consts::FRAC_PI_2 * i as f32 / rings as f32;
            ring_z.push((r * lat.cos(), r * lat.sin() + h));
        }
        for &(rr, z) in &ring_z {
            for k in 0..SEGMENTS {
                let a = std::f32::consts::TAU * k as f32 / SEGMENTS as f32;
                positions.push([rr * a.cos(), rr * a.sin(), z]);
            }
        }
        let (south, north) = (positions.len() as u32, positions.len() as u32 + 1);
        positions.push([0.0, 0.0, -r - h]);
        positions.push([0.0, 0.0, r + h]);
        let s = SEGMENTS as u32;
        let last = (ring_z.len() as u32 - 1) * s;
        let mut triangles = Vec::new();
        for k in 0..s {
            let n = (k + 1) % s;
            triangles.push([south, n, k]);
            triangles.push([north, last + k, last + n]);
            for ring in 0..ring_z.len() as u32 - 1 {
                let (a, b) = (ring * s, (ring + 1) * s);
                triangles.push([a + k, a + n, b + n]);
                triangles.push([a + k, b + n, b + k]);
            }
        }
        Self::solid(positions, triangles, color)
    }

    /// A mesh of the given triangles, all of one colour, closed.
    fn solid(positions: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>, color: [f32; 3]) -> Self {
        let colors = vec![color; triangles.len()];
        Self {
            positions,
            triangles,
            colors,
            closed: true,
        }
    }

    /// The mesh of one URDF geometry in its link's frame; `default_color` where the URDF
    /// gives none.
    #[must_use]
    pub fn from_geometry(g: &Geometry, default_color: [f32; 3]) -> Self {
        let color = g
            .rgba
            .map_or(default_color, |c| [c[0] as f32, c[1] as f32, c[2] as f32]);
        let local = match &g.shape {
            Shape::Box { size_m } => Self::cuboid(size_m.map(|s| s / 2.0), color),
            Shape::Cylinder { radius_m, length_m } => Self::cylinder(*radius_m, *length_m, color),
            Shape::Capsule { radius_m, length_m } => Self::capsule(*radius_m, *length_m, color),
            Shape::Sphere { radius_m } => Self::capsule(*radius_m, 0.0, color),
            Shape::Mesh { mesh, .. } => Self::from_trimesh(mesh, color),
        };
        let mut out = Self::default();
        out.append(&local, &g.X_LG);
        out
    }

    /// A loaded mesh. Its orientation is unknown: if its signed volume is clearly negative
    /// the triangles are flipped; if it is near zero (an open or inconsistent surface) back
    /// faces are kept.
    #[must_use]
    pub fn from_trimesh(mesh: &Arc<TriMesh>, color: [f32; 3]) -> Self {
        let positions: Vec<[f32; 3]> = mesh
            .vertices
            .iter()
            .map(|v| [v.x as f32, v.y as f32, v.z as f32])
            .collect();
        let n = positions.len() as u32;
        let mut triangles: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&i| i < n))
            .collect();
        let (mut volume, mut scale) = (0.0_f64, 0.0_f64);
        for t in &triangles {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            volume += a.dot(b.cross(c)) / 6.0;
            scale += (a.length() * b.length() * c.length()) / 6.0;
        }
        let closed = volume.abs() > 0.05 * scale;
        if closed && volume < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        let colors = vec![color; triangles.len()];
        Self {
            positions,
            triangles,
            colors,
            closed,
        }
    }
}
