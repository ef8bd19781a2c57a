//! Collision geometry of links for parry3d: exact shapes (primitives, convex hulls of meshes)
//! and a bounding capsule per link for fast distance queries.

use parry3d_f64::shape::SharedShape;

use crate::math::{Pose, Rotation, Vector};
use crate::model::{Geometry, LinkId, RobotModel, Shape};

/// Number of points on each rim of a cylinder when sampling it for a bounding capsule.
const RIM_POINTS: usize = 24;

/// A capsule in a link's frame: the segment `a_L`-`b_L` swept by a ball of `radius_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkCapsule {
    pub link: LinkId,
    pub a_L: Vector,
    pub b_L: Vector,
    pub radius_m: f64,
}

impl LinkCapsule {
    /// The capsule's segment end points in the world, given the link pose `X_WL`.
    #[must_use]
    pub fn segment_in_world(&self, X_WL: &Pose) -> (Vector, Vector) {
        (
            X_WL.transform_point(self.a_L),
            X_WL.transform_point(self.b_L),
        )
    }
}

/// The parry3d shape of one URDF geometry and its pose in the link frame, `X_LS`.
///
/// The pose is the geometry's `<origin>`, turned for cylinders (parry's run along y, URDF's
/// along z). Meshes become their convex hull (distances to it are a little smaller than to the
/// mesh: the safe side). Returns `None` for degenerate geometry (zero size, flat mesh).
#[must_use]
pub fn geometry_shape(geometry: &Geometry) -> Option<(Pose, SharedShape)> {
    let X_LG = geometry.X_LG;
    match &geometry.shape {
        // parry takes half extents.
        Shape::Box { size_m } => (size_m.iter().all(|s| *s > 0.0)).then(|| {
            (
                X_LG,
                SharedShape::cuboid(size_m[0] / 2.0, size_m[1] / 2.0, size_m[2] / 2.0),
            )
        }),
        Shape::Cylinder { radius_m, length_m } => (*radius_m > 0.0 && *length_m > 0.0).then(|| {
            let y_to_z =
                Pose::from_rotation(Rotation::from_rotation_x(std::f64::consts::FRAC_PI_2));
            (
                X_LG * y_to_z,
                SharedShape::cylinder(length_m / 2.0, *radius_m),
            )
        }),
        Shape::Capsule { radius_m, length_m } => {
            (*radius_m > 0.0).then(|| (X_LG, SharedShape::capsule_z(length_m / 2.0, *radius_m)))
        }
        Shape::Sphere { radius_m } => {
            (*radius_m > 0.0).then(|| (X_LG, SharedShape::ball(*radius_m)))
        }
        Shape::Mesh { mesh, .. } => SharedShape::convex_hull(&mesh.vertices).map(|s| (X_LG, s)),
    }
}

/// The collision shape of a link in the link frame: a compound of its collision geometries,
/// `None` when the link has none.
#[must_use]
pub fn link_collision_shape(model: &RobotModel, link: LinkId) -> Option<SharedShape> {
    let parts: Vec<(Pose, SharedShape)> = model.links()[link]
        .collisions
        .iter()
        .filter_map(geometry_shape)
        .collect();
    (!parts.is_empty()).then(|| SharedShape::compound(parts))
}

/// Points (with a radius each) whose union of balls covers the geometry, in the link frame.
fn cover_points(geometry: &Geometry, out: &mut Vec<(Vector, f64)>) {
    let X = geometry.X_LG;
    match &geometry.shape {
        Shape::Box { size_m } => {
            let h = Vector::from_array(*size_m) / 2.0;
            for i in 0..8 {
                let s = Vector::new(
                    if i & 1 == 0 { -1.0 } else { 1.0 },
                    if i & 2 == 0 { -1.0 } else { 1.0 },
                    if i & 4 == 0 { -1.0 } else { 1.0 },
                );
                out.push((X.transform_point(h * s), 0.0));
            }
        }
        Shape::Cylinder { radius_m, length_m } => {
            // A polygon inscribed in the rim misses a sliver; circumscribe it instead.
            let r = radius_m / (std::f64::consts::PI / RIM_POINTS as f64).cos();
            for k in 0..RIM_POINTS {
                let t = 2.0 * std::f64::consts::PI * k as f64 / RIM_POINTS as f64;
                for z in [-length_m / 2.0, length_m / 2.0] {
                    out.push((
                        X.transform_point(Vector::new(r * t.cos(), r * t.sin(), z)),
                        0.0,
                    ));
                }
            }
        }
        Shape::Capsule { radius_m, length_m } => {
            for z in [-length_m / 2.0, length_m / 2.0] {
                out.push((X.transform_point(Vector::new(0.0, 0.0, z)), *radius_m));
            }
        }
        Shape::Sphere { radius_m } => out.push((X.translation, *radius_m)),
        Shape::Mesh { mesh, .. } => {
            out.extend(mesh.vertices.iter().map(|v| (X.transform_point(*v), 0.0)));
        }
    }
}

/// A capsule that contains all collision geometry of `link` (in the link frame), `None` when
/// the link has no collision geometry.
///
/// The axis is the principal direction of the geometry's points; the segment is shortened
/// by the radius at both ends, then the radius grown until every point is inside. The
/// capsule is a bound: distances to it are never larger than distances to the link.
#[must_use]
pub fn link_bounding_capsule(model: &RobotModel, link: LinkId) -> Option<LinkCapsule> {
    let mut points = Vec::new();
    for g in &model.links()[link].collisions {
        cover_points(g, &mut points);
    }
    let (a_L, b_L, radius_m) = bounding_capsule(&points)?;
    Some(LinkCapsule {
        link,
        a_L,
        b_L,
        radius_m,
    })
}

/// Bounding capsule `(a, b, radius)` of balls `(centre, radius)`; `None` for no ball.
#[must_use]
pub fn bounding_capsule(balls: &[(Vector, f64)]) -> Option<(Vector, Vector, f64)> {
    if balls.is_empty() {
        return None;
    }
    let n = balls.len() as f64;
    let centroid = balls.iter().fold(Vector::ZERO, |acc, (p, _)| acc + *p) / n;
    // Principal axis: eigenvector of the largest eigenvalue of the covariance.
    let mut cov = parry3d_f64::math::Matrix::ZERO;
    for (p, _) in balls {
        let d = *p - centroid;
        cov += parry3d_f64::math::Matrix::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let axis = dominant_eigenvector(cov / n);

    // The smallest radius along this axis is the largest radial extent; then each end of
    // the segment goes just far enough that every ball fits in the end cap:
    // (t_i - t_end)^2 + rho_i^2 <= (R - r_i)^2.
    let project = |(p, r): &(Vector, f64)| {
        let d = *p - centroid;
        let t = d.dot(axis);
        (t, (d - axis * t).length(), *r)
    };
    let radius = balls
        .iter()
        .map(project)
        .fold(0.0_f64, |acc, (_, rho, r)| acc.max(rho + r));
    let (mut ta, mut tb) = (f64::INFINITY, f64::NEG_INFINITY);
    for ball in balls {
        let (t, rho, r) = project(ball);
        let reach = ((radius - r).powi(2) - rho * rho).max(0.0).sqrt();
        ta = ta.min(t + reach);
        tb = tb.max(t - reach);
    }
    if ta > tb {
        let mid = 0.5 * (ta + tb);
        (ta, tb) = (mid, mid);
    }
    let a = centroid + axis * ta;
    let b = centroid + axis * tb;
    // Guard against rounding: grow the radius to cover every ball exactly.
    let radius = balls
        .iter()
        .map(|(p, r)| distance_point_segment(*p, a, b) + r)
        .fold(radius, f64::max);
    Some((a, b, radius))
}

/// Unit eigenvector of the largest eigenvalue of a symmetric positive semi-definite matrix,
/// by power iteration (z when the matrix is zero).
fn dominant_eigenvector(m: parry3d_f64::math::Matrix) -> Vector {
    // Start from the column of largest norm: it has a component along the dominant direction
    // unless the matrix is zero.
    let mut v = [m.x_axis, m.y_axis, m.z_axis]
        .into_iter()
        .fold(Vector::ZERO, |best, c| {
            if c.length() > best.length() { c } else { best }
        });
    if v.length() < 1e-300 {
        return Vector::Z;
    }
    for _ in 0..64 {
        let next = m * v;
        let len = next.length();
        if len < 1e-300 {
            break;
        }
        v = next / len;
    }
    v.normalize()
}

/// The end of segment `a`-`b` farther from `from` (`b` where both are as far): a limb
/// capsule's end away from the joint it hangs from.
#[must_use]
pub fn end_away_from(a: Vector, b: Vector, from: Vector) -> Vector {
    if (a - from).length() > (b - from).length() {
        a
    } else {
        b
    }
}

/// Distance from point `p` to segment `a`-`b`.
#[must_use]
pub fn distance_point_segment(p: Vector, a: Vector, b: Vector) -> f64 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn the_end_away_from_a_point_is_the_farther_one() {
        let (a, b) = (Vector::new(0.0, 0.0, 0.0), Vector::new(0.3, 0.0, 0.0));
        assert_eq!(end_away_from(a, b, Vector::new(-0.1, 0.0, 0.0)), b);
        assert_eq!(end_away_from(a, b, Vector::new(0.4, 0.1, 0.0)), a);
        // Equidistant: the second end.
        assert_eq!(end_away_from(a, b, Vector::new(0.15, 1.0, 0.0)), b);
    }

    #[test]
    fn capsule_of_a_capsule_is_itself() {
        let balls = [
            (Vector::new(0.0, 0.0, -0.2), 0.05),
            (Vector::new(0.0, 0.0, 0.2), 0.05),
        ];
        let (a, b, r) = bounding_capsule(&balls).expect("capsule");
        assert_relative_eq!(r, 0.05, epsilon = 1e-12);
        assert_relative_eq!((b - a).length(), 0.4, epsilon = 1e-12);
    }

    #[test]
    fn capsule_of_a_long_box_is_tight_and_covers() {
        // A 1 x 0.1 x 0.1 box: the capsule runs along x, radius the half diagonal of the
        // cross-section, sqrt(0.05^2 + 0.05^2).
        let corners: Vec<(Vector, f64)> = (0..8)
            .map(|i| {
                let s = |bit: usize, h: f64| if i & bit == 0 { -h } else { h };
                (Vector::new(s(1, 0.5), s(2, 0.05), s(4, 0.05)), 0.0)
            })
            .collect();
        let (a, b, r) = bounding_capsule(&corners).expect("capsule");
        assert_relative_eq!(r, 0.05 * 2f64.sqrt(), epsilon = 1e-9);
        assert!((b - a).normalize().x.abs() > 0.999);
        for (p, _) in &corners {
            assert!(distance_point_segment(*p, a, b) <= r + 1e-12);
        }
    }
}

#[cfg(test)]
mod shape_tests {
    use super::*;
    use crate::RobotModel;
    use approx::assert_relative_eq;

    #[test]
    fn link_shapes_of_cylinders_have_the_urdf_extent() {
        // ur5e link2 holds cylinders; the whole compound must build (no nested compounds).
        let robot = RobotModel::from_catalogue("ur5e_kinematics").expect("catalogue");
        for l in 0..robot.links().len() {
            if robot.links()[l].collisions.is_empty() {
                continue;
            }
            let shape = link_collision_shape(&robot, l).expect("shape");
            let capsule = link_bounding_capsule(&robot, l).expect("capsule");
            // The capsule bounds the exact shape: the AABB of the shape fits in the capsule's.
            let aabb = shape.compute_aabb(&Pose::IDENTITY);
            let lo = capsule.a_L.min(capsule.b_L) - Vector::splat(capsule.radius_m + 1e-9);
            let hi = capsule.a_L.max(capsule.b_L) + Vector::splat(capsule.radius_m + 1e-9);
            assert!(
                aabb.mins.cmpge(lo).all() && aabb.maxs.cmple(hi).all(),
                "link {l}"
            );
        }
        // A z-cylinder of radius r and length h: AABB half extents (r, r, h/2).
        let g = Geometry {
            name: None,
            X_LG: Pose::IDENTITY,
            shape: Shape::Cylinder {
                radius_m: 0.1,
                length_m: 0.6,
            },
            rgba: None,
        };
        let (X, s) = geometry_shape(&g).expect("cylinder");
        let aabb = s.compute_aabb(&X);
        assert_relative_eq!(aabb.maxs.z, 0.3, epsilon = 1e-12);
        assert_relative_eq!(aabb.maxs.x, 0.1, epsilon = 1e-12);
    }
}
