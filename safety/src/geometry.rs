//! Signed distances between robot links and human parts.
//!
//! The result type follows Drake's `SignedDistancePair`: a distance with a documented sign,
//! a witness point on each body and the unit normal. Capsule pairs use the exact closed form
//! (closest points of two segments, minus the radii): parry's generic GJK is slower there and
//! only accurate to about 1e-5 m. General convex shapes (boxes, mesh hulls) go through parry's
//! `query::contact`, which also reports penetration depth (its `query::distance` returns 0 for
//! overlapping shapes).

use parry3d_f64::query;
use parry3d_f64::shape::Shape;
use workcell_robots::LinkId;
use workcell_robots::math::{Pose, Vector};

use crate::human::HumanPart;

/// Below this squared length a segment is treated as a point.
const DEGENERATE_SQ: f64 = 1e-18;

/// A capsule in the world: the segment `a_W`-`b_W` swept by a ball of radius `radius_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Capsule {
    pub a_W: Vector,
    pub b_W: Vector,
    pub radius_m: f64,
}

impl Capsule {
    /// A capsule from its segment and radius.
    #[must_use]
    pub fn new(a_W: Vector, b_W: Vector, radius_m: f64) -> Self {
        Self { a_W, b_W, radius_m }
    }

    /// The same capsule with its radius grown by `margin_m` (pose uncertainty).
    #[must_use]
    pub fn inflated(&self, margin_m: f64) -> Self {
        Self {
            radius_m: self.radius_m + margin_m,
            ..*self
        }
    }

    /// The point at parameter `t` in [0, 1] along the axis.
    #[must_use]
    #[inline]
    pub fn axis_point(&self, t: f64) -> Vector {
        self.a_W + (self.b_W - self.a_W) * t
    }

    /// `true` when every coordinate and the radius are finite and the radius is not negative.
    #[must_use]
    pub fn is_valid(&self) -> bool {
        self.a_W.is_finite()
            && self.b_W.is_finite()
            && self.radius_m.is_finite()
            && self.radius_m >= 0.0
    }
}

/// The signed distance between a robot link A and a human part B.
///
/// - `distance_m` > 0: separated by that much; 0: touching; < 0: penetrating that deep.
/// - `p_WA`, `p_WB`: witness points on the surfaces of A and B, in the world.
/// - `nhat_BA_W`: unit normal pointing from B toward A, the direction in which moving A
///   increases the distance fastest. For every sign, `p_WA - p_WB = distance_m * nhat_BA_W`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignedDistancePair {
    pub link: LinkId,
    pub part: HumanPart,
    pub distance_m: f64,
    pub p_WA: Vector,
    pub p_WB: Vector,
    pub nhat_BA_W: Vector,
    /// Where the witness point of B lies along B's axis (0 at `a_W`, 1 at `b_W`); used to
    /// interpolate the part's velocity.
    pub t_B: f64,
}

/// The parameters `(s, t)` in [0, 1] of the closest points `p1 + s (q1 - p1)` and
/// `p2 + t (q2 - p2)` of two segments. Degenerate segments (points) are handled; for parallel
/// segments one of the closest pairs is returned.
///
/// The minimiser of the squared distance, clamped to the unit square edge by edge (the
/// standard derivation: solve the 2x2 normal equations, clamp `s`, recompute `t`, clamp `t`
/// and recompute `s`).
#[must_use]
pub fn closest_segment_parameters(p1: Vector, q1: Vector, p2: Vector, q2: Vector) -> (f64, f64) {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = d1.dot(d1);
    let e = d2.dot(d2);
    let f = d2.dot(r);
    if a <= DEGENERATE_SQ && e <= DEGENERATE_SQ {
        return (0.0, 0.0);
    }
    if a <= DEGENERATE_SQ {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = d1.dot(r);
    if e <= DEGENERATE_SQ {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = d1.dot(d2);
    let denominator = a * e - b * b; // >= 0; 0 when parallel
    let mut s = if denominator > 1e-12 * a * e {
        ((b * f - c * e) / denominator).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = (-c / a).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((b - c) / a).clamp(0.0, 1.0);
    }
    (s, t)
}

/// A unit vector perpendicular to `d` (any one; `d` need not be normalised).
fn any_perpendicular(d: Vector) -> Vector {
    let helper = if d.x.abs() < 0.9 * d.length().max(f64::MIN_POSITIVE) {
        Vector::X
    } else {
        Vector::Y
    };
    d.cross(helper).normalize_or(Vector::Z)
}

/// Signed distance between robot capsule A (link `link`) and human capsule B (part `part`),
/// exact.
///
/// When the two axes intersect, the normal is not defined by the geometry; the normal of
/// the plane through both axes is used (or any perpendicular for collinear axes), and the
/// depth is the sum of the radii.
#[must_use]
pub fn capsule_capsule(
    link: LinkId,
    a: &Capsule,
    part: HumanPart,
    b: &Capsule,
) -> SignedDistancePair {
    let (s, t) = closest_segment_parameters(a.a_W, a.b_W, b.a_W, b.b_W);
    let c_A = a.axis_point(s);
    let c_B = b.axis_point(t);
    let axis_gap = c_A - c_B;
    let gap = axis_gap.length();
    let nhat_BA_W = if gap > 1e-12 {
        axis_gap / gap
    } else {
        let da = a.b_W - a.a_W;
        let db = b.b_W - b.a_W;
        let n = da.cross(db);
        if n.length_squared() > 1e-24 {
            n.normalize()
        } else {
            any_perpendicular(if da.length_squared() > DEGENERATE_SQ {
                da
            } else {
                db
            })
        }
    };
    SignedDistancePair {
        link,
        part,
        distance_m: gap - a.radius_m - b.radius_m,
        p_WA: c_A - nhat_BA_W * a.radius_m,
        p_WB: c_B + nhat_BA_W * b.radius_m,
        nhat_BA_W,
        t_B: t,
    }
}

/// Signed distance between any convex parry shape A at `X_WA` (a robot link's exact collision
/// shape) and human capsule B, by parry's `query::contact` (GJK, EPA when penetrating).
/// Returns `None` when the pair is farther apart than `max_distance_m` (a negative bound
/// counts as 0), an input is not finite, or parry does not support the shape.
#[must_use]
pub fn shape_capsule(
    link: LinkId,
    X_WA: &Pose,
    shape_A: &dyn Shape,
    part: HumanPart,
    b: &Capsule,
    max_distance_m: f64,
) -> Option<SignedDistancePair> {
    // parry's capsule: a segment in its own frame; place it at the identity.
    let capsule_B = parry3d_f64::shape::Capsule::new(b.a_W, b.b_W, b.radius_m);
    // parry panics on a negative (or NaN) prediction margin.
    let margin = if max_distance_m > 0.0 {
        max_distance_m
    } else {
        0.0
    };
    if !b.is_valid() || !X_WA.translation.is_finite() || !X_WA.rotation.is_finite() {
        return None;
    }
    let contact = query::contact(X_WA, shape_A, &Pose::IDENTITY, &capsule_B, margin).ok()??;
    if contact.dist > margin {
        return None;
    }
    // normal1 points from A toward B.
    let nhat_BA_W = -contact.normal1;
    let axis = b.b_W - b.a_W;
    let len_sq = axis.length_squared();
    let t_B = if len_sq > DEGENERATE_SQ {
        ((contact.point2 - b.a_W).dot(axis) / len_sq).clamp(0.0, 1.0)
    } else {
        0.0
    };
    Some(SignedDistancePair {
        link,
        part,
        distance_m: contact.dist,
        p_WA: contact.point1,
        p_WB: contact.point2,
        nhat_BA_W,
        t_B,
    })
}
