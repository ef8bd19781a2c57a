//! Triangle meshes for rendering: URDF primitives tessellated, loaded meshes converted, all
//! wound counter-clockwise seen from outside so that back faces can be culled.

use std::sync::Arc;

use workcell_robots::math::{Pose, Vector};
use workcell_robots::{Geometry, Shape, TriMesh};

use crate::cpu::{cross, dot, sub};

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
    /// Whether the mesh is the closed boundary of a convex solid (as
    /// [`RenderMesh::convex_hull`] makes it): its outline from any view inside the image is
    /// then the convex polygon around its projected vertices, and
    /// [`Renderer::render_spans`](crate::Renderer::render_spans) draws it from that polygon
    /// instead of from its triangles. Whoever sets it vouches for it; [`RenderMesh::append`]
    /// clears it.
    pub convex: bool,
}

/// A triangle's normal (unnormalised), out of its counter-clockwise side.
fn normal([a, b, c]: [[f32; 3]; 3]) -> [f32; 3] {
    cross(sub(b, a), sub(c, a))
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
        self.convex = false;
    }

    /// The union of `pieces` (each with whether it is convex) for silhouettes and masks:
    /// every triangle of a piece that lies inside another convex piece left out (a bone
    /// inside the flesh, a thinner limb segment's cap inside the next one). Such a triangle
    /// is never on the union's outside, so masks from any view are the same, from fewer
    /// triangles (the human arm's parts: 2,544 triangles, 724 left). A triangle in the plane
    /// of one of the other piece's faces is kept: two boxes that share a face's plane, or a
    /// visual given twice, would otherwise hide each other's faces on that plane. Only the
    /// kept triangles' vertices are kept. The result is closed when every piece is.
    #[must_use]
    pub fn outer_union(pieces: &[(RenderMesh, bool)]) -> Self {
        let mut out = Self {
            closed: pieces.iter().all(|(m, _)| m.closed),
            ..Self::default()
        };
        let mut index: Vec<u32> = Vec::new();
        for (k, (mesh, _)) in pieces.iter().enumerate() {
            index.clear();
            index.resize(mesh.positions.len(), u32::MAX);
            for (tri, &color) in mesh.triangles.iter().zip(&mesh.colors) {
                let Some(corners) = mesh.corners(tri) else {
                    continue;
                };
                let hidden = pieces
                    .iter()
                    .enumerate()
                    .any(|(j, (other, convex))| j != k && *convex && other.hides(corners));
                if hidden {
                    continue;
                }
                let kept = tri.map(|i| {
                    let slot = &mut index[i as usize];
                    if *slot == u32::MAX {
                        *slot = out.positions.len() as u32;
                        out.positions.push(mesh.positions[i as usize]);
                    }
                    *slot
                });
                out.triangles.push(kept);
                out.colors.push(color);
            }
        }
        out
    }

    /// The convex hull of the mesh's vertices: a closed mesh wound counter-clockwise seen
    /// from outside, in the first triangle's colour. Its silhouette from any view holds the
    /// mesh's, and is the same where the mesh is convex; a search that renders a limb's
    /// outline thousands of times renders its hull from fewer triangles (the whole body's
    /// forearm at 6 segments: 276 triangles, 108 on its hull). `None` where the vertices
    /// span no volume (fewer than four, or all in a plane).
    #[must_use]
    pub fn convex_hull(&self) -> Option<Self> {
        use parry3d_f64::math::Vector as Point;
        let points: Vec<Point> = self
            .positions
            .iter()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .map(|p| Point::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2])))
            .collect();
        if points.len() < 4 {
            return None;
        }
        let (vertices, mut triangles) =
            parry3d_f64::transformation::try_convex_hull(&points).ok()?;
        let positions: Vec<[f32; 3]> = vertices
            .iter()
            .map(|v| [v.x as f32, v.y as f32, v.z as f32])
            .collect();
        // Six times the signed volume: positive where the faces turn outwards.
        let volume: f64 = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| vertices[i as usize]);
                a.dot(b.cross(c))
            })
            .sum();
        if volume.is_nan() || volume.abs() <= 1e-15 || triangles.len() < 4 {
            return None;
        }
        if volume < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        let color = self.colors.first().copied().unwrap_or([0.5; 3]);
        Some(Self {
            convex: true,
            ..Self::solid(positions, triangles, color)
        })
    }

    /// The corners of triangle `t`; `None` when an index is out of range.
    fn corners(&self, t: &[u32; 3]) -> Option<[[f32; 3]; 3]> {
        let corner = |c: usize| self.positions.get(t[c] as usize).copied();
        Some([corner(0)?, corner(1)?, corner(2)?])
    }

    /// Whether this mesh, taken as a convex solid (faces counter-clockwise seen from
    /// outside), holds triangle `t` (of another solid) where it is never on their union's
    /// outside: every corner behind or on every face's plane (within 1 um), and where all
    /// three lie on a face's plane, `t` faces the other way (the two solids meet there, one
    /// on each side, like two segments of a limb). Facing the same way, the two solids lie
    /// on the same side and `t` may be on the outside (two boxes on one floor).
    fn hides(&self, t: [[f32; 3]; 3]) -> bool {
        const TOLERANCE_M: f32 = 1e-6;
        let t_normal = normal(t);
        self.triangles.iter().all(|face| {
            let Some(face) = self.corners(face) else {
                return true;
            };
            let n = normal(face);
            let length = dot(n, n).sqrt();
            if length == 0.0 {
                return true;
            }
            let distance = t.map(|p| dot(n, sub(p, face[0])) / length);
            let behind = distance.iter().all(|&d| d <= TOLERANCE_M);
            let on_plane = distance.iter().all(|&d| d.abs() <= TOLERANCE_M);
            behind && (!on_plane || dot(n, t_normal) < 0.0)
        })
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
        Self::cylinder_with(radius, length, color, SEGMENTS)
    }

    /// [`RenderMesh::cylinder`] with `segments` around the axis (at least 3).
    #[must_use]
    pub fn cylinder_with(radius: f64, length: f64, color: [f32; 3], segments: usize) -> Self {
        let segments = segments.max(3);
        let (r, h) = (radius as f32, (length / 2.0) as f32);
        let mut positions = Vec::with_capacity(2 * segments + 2);
        for k in 0..segments {
            let a = std::f32::consts::TAU * k as f32 / segments as f32;
            positions.push([r * a.cos(), r * a.sin(), -h]);
            positions.push([r * a.cos(), r * a.sin(), h]);
        }
        let (bottom, top) = (positions.len() as u32, positions.len() as u32 + 1);
        positions.push([0.0, 0.0, -h]);
        positions.push([0.0, 0.0, h]);
        let mut triangles = Vec::with_capacity(4 * segments);
        for k in 0..segments as u32 {
            let n = (k + 1) % segments as u32;
            let (b0, t0, b1, t1) = (2 * k, 2 * k + 1, 2 * n, 2 * n + 1);
            triangles.push([b0, b1, t1]);
            triangles.push([b0, t1, t0]);
            triangles.push([bottom, b1, b0]);
            triangles.push([top, t0, t1]);
        }
        Self::solid(positions, triangles, color)
    }

    /// A geodesic sphere: the icosahedron's 20 faces each split in four `subdivisions`
    /// times, every vertex on the sphere (as [`RenderMesh::capsule`]'s). Its vertices lie
    /// evenly, so its outline from any view is as near a circle as a UV sphere's with many
    /// more triangles: once subdivided, 80 triangles and its vertices at most 32 degrees
    /// apart; the UV sphere of 16 sides, 512 triangles and 22.5 degrees.
    #[must_use]
    pub fn geodesic_sphere(radius: f64, color: [f32; 3], subdivisions: u32) -> Self {
        let t = (1.0 + 5.0f64.sqrt()) / 2.0;
        let mut points: Vec<[f64; 3]> = [
            [-1.0, t, 0.0],
            [1.0, t, 0.0],
            [-1.0, -t, 0.0],
            [1.0, -t, 0.0],
            [0.0, -1.0, t],
            [0.0, 1.0, t],
            [0.0, -1.0, -t],
            [0.0, 1.0, -t],
            [t, 0.0, -1.0],
            [t, 0.0, 1.0],
            [-t, 0.0, -1.0],
            [-t, 0.0, 1.0],
        ]
        .to_vec();
        let mut faces: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut midpoints = std::collections::HashMap::new();
            let mut midpoint = |a: u32, b: u32, points: &mut Vec<[f64; 3]>| {
                *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let (p, q) = (points[a as usize], points[b as usize]);
                    points.push([0, 1, 2].map(|k| (p[k] + q[k]) / 2.0));
                    points.len() as u32 - 1
                })
            };
            let mut next = Vec::with_capacity(4 * faces.len());
            for [a, b, c] in faces {
                let (ab, bc, ca) = (
                    midpoint(a, b, &mut points),
                    midpoint(b, c, &mut points),
                    midpoint(c, a, &mut points),
                );
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            faces = next;
        }
        let positions: Vec<[f32; 3]> = points
            .iter()
            .map(|p| {
                let n = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                p.map(|v| (radius * v / n) as f32)
            })
            .collect();
        // Wound counter-clockwise seen from outside, whatever the table's order.
        let triangles = faces
            .into_iter()
            .map(|[a, b, c]| {
                let [p, q, r] = [a, b, c].map(|i| positions[i as usize]);
                let n = cross(sub(q, p), sub(r, p));
                let centre = [0, 1, 2].map(|k| p[k] + q[k] + r[k]);
                if dot(n, centre) < 0.0 {
                    [a, c, b]
                } else {
                    [a, b, c]
                }
            })
            .collect();
        Self::solid(positions, triangles, color)
    }

    /// A capsule along z: a cylinder of `length` capped by hemispheres; `length = 0` is a
    /// sphere.
    #[must_use]
    pub fn capsule(radius: f64, length: f64, color: [f32; 3]) -> Self {
        Self::capsule_with(radius, length, color, SEGMENTS)
    }

    /// [`RenderMesh::capsule`] with `segments` around the axis (at least 4; half as many
    /// latitude bands per hemisphere).
    #[must_use]
    pub fn capsule_with(radius: f64, length: f64, color: [f32; 3], segments: usize) -> Self {
        let segments = segments.max(4);
        let (r, h) = (radius as f32, (length / 2.0) as f32);
        let rings = segments / 2; // latitude bands per hemisphere, pole excluded
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
            for k in 0..segments {
                let a = std::f32::consts::TAU * k as f32 / segments as f32;
                positions.push([rr * a.cos(), rr * a.sin(), z]);
            }
        }
        let (south, north) = (positions.len() as u32, positions.len() as u32 + 1);
        positions.push([0.0, 0.0, -r - h]);
        positions.push([0.0, 0.0, r + h]);
        let s = segments as u32;
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
            convex: false,
        }
    }

    /// The mesh of one URDF geometry in its link's frame; `default_color` where the URDF
    /// gives none.
    #[must_use]
    pub fn from_geometry(g: &Geometry, default_color: [f32; 3]) -> Self {
        Self::from_geometry_with(g, default_color, SEGMENTS)
    }

    /// [`RenderMesh::from_geometry`] with `segments` around round shapes: a coarser mesh
    /// for a search that renders a small object thousands of times.
    #[must_use]
    pub fn from_geometry_with(g: &Geometry, default_color: [f32; 3], segments: usize) -> Self {
        let color = g
            .rgba
            .map_or(default_color, |c| [c[0] as f32, c[1] as f32, c[2] as f32]);
        let local = match &g.shape {
            Shape::Box { size_m } => Self::cuboid(size_m.map(|s| s / 2.0), color),
            Shape::Cylinder { radius_m, length_m } => {
                Self::cylinder_with(*radius_m, *length_m, color, segments)
            }
            Shape::Capsule { radius_m, length_m } => {
                Self::capsule_with(*radius_m, *length_m, color, segments)
            }
            Shape::Sphere { radius_m } => Self::capsule_with(*radius_m, 0.0, color, segments),
            Shape::Mesh { mesh, .. } => Self::from_trimesh(mesh, color),
        };
        let mut out = Self::default();
        out.append(&local, &g.X_LG);
        out
    }

    /// [`RenderMesh::from_geometry_with`] with spheres drawn as geodesic spheres subdivided
    /// `subdivisions` times ([`RenderMesh::geodesic_sphere`]) and scaled to the sphere's
    /// surface area: a convex body's outline, averaged over the directions it is seen from,
    /// has a quarter of its surface area (Cauchy's projection formula), so the geodesic
    /// sphere's outline is on average the sphere's disc, and as its outline hardly changes
    /// with the view, within 1 % of it from any view once subdivided (80 triangles; an
    /// inscribed UV sphere of 16 sides, 512 triangles, leaves 1 to 3 % of the disc uncovered,
    /// of 6 sides 6 to 19 %). For a search that renders a round shape thousands of times.
    #[must_use]
    pub fn from_geometry_geodesic(
        g: &Geometry,
        default_color: [f32; 3],
        segments: usize,
        subdivisions: u32,
    ) -> Self {
        let Shape::Sphere { radius_m } = g.shape else {
            return Self::from_geometry_with(g, default_color, segments);
        };
        let color = g
            .rgba
            .map_or(default_color, |c| [c[0] as f32, c[1] as f32, c[2] as f32]);
        let unit = Self::geodesic_sphere(1.0, color, subdivisions);
        let scale = (4.0 * std::f64::consts::PI / unit.surface_area()).sqrt();
        let mut out = Self::default();
        out.append(
            &Self::geodesic_sphere(radius_m * scale, color, subdivisions),
            &g.X_LG,
        );
        out
    }

    /// The volume the mesh's triangles enclose, m^3, signed: positive where a closed mesh's
    /// faces turn outwards.
    #[must_use]
    pub fn signed_volume(&self) -> f64 {
        self.sum_over_triangles(|[a, b, c]| {
            let [a, b, c] = [a, b, c].map(|p| p.map(f64::from));
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
                / 6.0
        })
    }

    /// The area of the mesh's triangles, m^2.
    #[must_use]
    pub fn surface_area(&self) -> f64 {
        self.sum_over_triangles(|[a, b, c]| {
            let n = cross(sub(b, a), sub(c, a));
            0.5 * f64::from(dot(n, n)).sqrt()
        })
    }

    /// `f` of each triangle's corners, summed.
    fn sum_over_triangles(&self, f: impl Fn([[f32; 3]; 3]) -> f64) -> f64 {
        self.triangles
            .iter()
            .filter_map(|t| self.corners(t))
            .map(f)
            .sum()
    }

    /// A loaded mesh. Its orientation is unknown: back faces are culled only for closed,
    /// consistently wound surfaces, each connected part turned outside out if its signed
    /// volume is negative (see `orient_closed_parts`); open or inconsistent surfaces keep
    /// both faces. A part wound inside out would otherwise disappear.
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
        let closed = orient_closed_parts(&mesh.vertices, &mut triangles);
        let colors = vec![color; triangles.len()];
        Self {
            positions,
            triangles,
            colors,
            closed,
            convex: false,
        }
    }
}

/// Orients a mesh of unknown winding for back-face culling. With coincident vertices welded
/// (to 1e-7 m), the surface is closed and consistently wound when every directed edge appears
/// once and its reverse once; then each connected part whose signed volume is negative is
/// turned outside out (COLLADA exports hold parts wound either way). Returns whether back
/// faces may be culled.
fn orient_closed_parts(
    vertices: &[workcell_robots::math::Vector],
    triangles: &mut [[u32; 3]],
) -> bool {
    use std::collections::HashMap;
    let mut ids: HashMap<[i64; 3], u32> = HashMap::with_capacity(vertices.len());
    let welded: Vec<u32> = vertices
        .iter()
        .map(|v| {
            let key = [v.x, v.y, v.z].map(|c| (c * 1e7).round() as i64);
            let next = ids.len() as u32;
            *ids.entry(key).or_insert(next)
        })
        .collect();
    let mut edges: HashMap<(u32, u32), u32> = HashMap::with_capacity(3 * triangles.len());
    // Connected parts: union-find over welded vertices.
    let mut parent: Vec<u32> = (0..ids.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    }
    for t in triangles.iter() {
        let w = t.map(|i| welded[i as usize]);
        if w[0] == w[1] || w[1] == w[2] || w[2] == w[0] {
            continue; // degenerate after welding: covers nothing
        }
        for k in 0..3 {
            *edges.entry((w[k], w[(k + 1) % 3])).or_insert(0) += 1;
            let (a, b) = (find(&mut parent, w[k]), find(&mut parent, w[(k + 1) % 3]));
            parent[a as usize] = b;
        }
    }
    let closed = edges
        .iter()
        .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1));
    if !closed {
        return false;
    }
    let mut volume: HashMap<u32, f64> = HashMap::new();
    let part = |parent: &mut Vec<u32>, t: &[u32; 3]| find(parent, welded[t[0] as usize]);
    for t in triangles.iter() {
        let [a, b, c] = t.map(|i| vertices[i as usize]);
        let p = part(&mut parent, t);
        *volume.entry(p).or_insert(0.0) += a.dot(b.cross(c)) / 6.0;
    }
    for t in triangles.iter_mut() {
        if volume.get(&part(&mut parent, t)).is_some_and(|v| *v < 0.0) {
            t.swap(1, 2);
        }
    }
    true
}

#[cfg(test)]
mod orientation_tests {
    use super::*;
    use workcell_robots::math::Vector;

    fn tetrahedron(offset: f64, inside_out: bool) -> (Vec<Vector>, Vec<[u32; 3]>) {
        let v = vec![
            Vector::new(offset, 0.0, 0.0),
            Vector::new(offset + 1.0, 0.0, 0.0),
            Vector::new(offset, 1.0, 0.0),
            Vector::new(offset, 0.0, 1.0),
        ];
        let mut t = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        if inside_out {
            t.iter_mut().for_each(|t| t.swap(1, 2));
        }
        (v, t)
    }

    fn volume(v: &[Vector], t: &[[u32; 3]]) -> f64 {
        t.iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| v[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    #[test]
    fn each_closed_part_is_turned_outside_out_and_open_surfaces_keep_back_faces() {
        // Two tetrahedra of 1/6 m^3, the second wound inside out (as parts of one COLLADA
        // file can be): after orientation both enclose +1/6.
        let (mut v, mut t) = tetrahedron(0.0, false);
        let (v2, t2) = tetrahedron(5.0, true);
        t.extend(t2.iter().map(|f| f.map(|i| i + 4)));
        v.extend(v2);
        assert!(volume(&v, &t).abs() < 1e-12, "the parts cancel before");
        assert!(orient_closed_parts(&v, &mut t));
        assert!((volume(&v, &t[..4]) - 1.0 / 6.0).abs() < 1e-12);
        assert!((volume(&v, &t[4..]) - 1.0 / 6.0).abs() < 1e-12);
        // Unwelded vertices (one copy per triangle, as STL stores them) are welded first.
        let (v, t) = tetrahedron(0.0, true);
        let mut soup_v = Vec::new();
        let mut soup_t = Vec::new();
        for f in &t {
            let base = soup_v.len() as u32;
            soup_v.extend(f.map(|i| v[i as usize]));
            soup_t.push([base, base + 1, base + 2]);
        }
        assert!(orient_closed_parts(&soup_v, &mut soup_t));
        assert!((volume(&soup_v, &soup_t) - 1.0 / 6.0).abs() < 1e-12);
        // A missing face opens the surface: both faces are drawn.
        let (v, mut t) = tetrahedron(0.0, false);
        t.pop();
        assert!(!orient_closed_parts(&v, &mut t));
    }
}

#[cfg(test)]
mod segment_tests {
    use super::*;

    #[test]
    fn coarser_round_shapes_keep_their_closed_form_volume() {
        // An n-gon prism of circumradius r has volume n r^2 sin(2 pi / n) / 2 * length.
        let (r, l) = (0.01, 0.2);
        for n in [6, 16] {
            let c = RenderMesh::cylinder_with(r, l, [1.0; 3], n);
            assert_eq!(c.len(), 4 * n);
            let exact = n as f64 * r * r * (std::f64::consts::TAU / n as f64).sin() / 2.0 * l;
            assert!(
                (c.signed_volume() - exact).abs() < 1e-6 * exact,
                "{n}: {}",
                c.signed_volume()
            );
        }
        // Spheres: fewer triangles, outward, within the inscribed and circumscribed volumes.
        let (coarse, fine) = (
            RenderMesh::capsule_with(r, 0.0, [1.0; 3], 6),
            RenderMesh::capsule(r, 0.0, [1.0; 3]),
        );
        assert!(coarse.len() < fine.len() / 4);
        let sphere = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        for m in [&coarse, &fine] {
            let v = m.signed_volume();
            assert!(v > 0.5 * sphere && v < sphere, "{v} vs {sphere}");
        }
        assert!(coarse.signed_volume() < fine.signed_volume());
    }
}
