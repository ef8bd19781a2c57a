//! Signed distances between robot links and human parts.
//!
//! The result type follows Drake's `SignedDistancePair`: a distance with a documented sign,
//! a witness point on each body and the unit normal. Capsule pairs use the exact closed form
//! (closest points of two segments, minus the radii): parry's generic GJK is slower there and
//! only accurate to about 1e-5 m. General convex shapes (boxes, cylinders, mesh hulls) go
//! through parry's `query::contact`, which also reports penetration depth (its
//! `query::distance` returns 0 for overlapping shapes).
//!
//! # Distances that never flatter
//!
//! Every distance returned here is at most the true signed distance: a safety layer may be
//! told that shapes are closer than they are, never farther. The certificate is the
//! separating-axis bound: for convex A and B and any unit `n` pointing from B toward A,
//!
//! ```text
//! s(n) = min_{a in A} a.n - max_{b in B} b.n  <=  signed distance(A, B)
//! ```
//!
//! with equality for the best `n` (for separated shapes by the separating axis theorem; for
//! overlapping ones the depth is the smallest overlap over all directions). Each query takes
//! the normal of its candidate answer, evaluates `s(n)` with exact support functions, and
//! returns the smaller of the two. The error is then one-sided and bounded by how far the
//! candidate's normal is from the best one: near-parallel segments, where the closed form's
//! parallel fallback picks one of many closest pairs, come out exact; parry's EPA stopping
//! early on a penetrating pair reports a depth at least the true one.

use parry3d_f64::query;
use parry3d_f64::shape::Shape;
use workcell_robots::LinkId;
use workcell_robots::math::{Pose, Vector};

use workcell_robots::HumanPart;

/// Separating-axis bound of a capsule pair along `n` (unit, from B toward A): at most the
/// true signed distance for every `n` (see the module documentation).
#[must_use]
#[inline]
pub fn capsule_separation_along(a: &Capsule, b: &Capsule, n: Vector) -> f64 {
    let min_a = a.a_W.dot(n).min(a.b_W.dot(n)) - a.radius_m;
    let max_b = b.a_W.dot(n).max(b.b_W.dot(n)) + b.radius_m;
    min_a - max_b
}

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
    // The closed form is exact but where the axes are (nearly) parallel: its fallback then
    // picks one closest pair of many, off by up to length x angle. The bound along the
    // chosen normal is exact there.
    let distance_m = (gap - a.radius_m - b.radius_m).min(capsule_separation_along(a, b, nhat_BA_W));
    let p_WB = c_B + nhat_BA_W * b.radius_m;
    SignedDistancePair {
        link,
        part,
        distance_m,
        // A's witness moves with the certified distance, keeping p_WA - p_WB = d n.
        p_WA: p_WB + nhat_BA_W * distance_m,
        p_WB,
        nhat_BA_W,
        t_B: t,
    }
}

/// Signed distance between a parry shape A at `X_WA` (a robot link's exact collision shape:
/// a convex shape or a compound of them) and human capsule B. Convex parts go through
/// parry's `query::contact` (GJK, EPA when penetrating), certified by the separating-axis
/// bound along its normal (never farther than the truth). A compound's distance is its
/// closest part's; when parts overlap B, its depth is the deepest part's (a lower bound on
/// the union's depth). Returns `None` when the pair is farther apart than `max_distance_m`
/// (a negative bound counts as 0), an input is not finite, or parry does not support the
/// shape.
#[must_use]
pub fn shape_capsule(
    link: LinkId,
    X_WA: &Pose,
    shape_A: &dyn Shape,
    part: HumanPart,
    b: &Capsule,
    max_distance_m: f64,
) -> Option<SignedDistancePair> {
    if !b.is_valid() || !X_WA.translation.is_finite() || !X_WA.rotation.is_finite() {
        return None;
    }
    // parry panics on a negative (or NaN) prediction margin.
    let margin = if max_distance_m > 0.0 {
        max_distance_m
    } else {
        0.0
    };
    let Some(compound) = shape_A.as_compound() else {
        return convex_capsule(link, X_WA, shape_A, part, b, margin);
    };
    let mut best: Option<SignedDistancePair> = None;
    for (X_AP, shape_P) in compound.shapes() {
        let limit = best.map_or(margin, |p| p.distance_m.clamp(0.0, margin));
        let X_WP = *X_WA * *X_AP;
        if let Some(pair) = convex_capsule(link, &X_WP, shape_P.as_ref(), part, b, limit)
            && best.is_none_or(|p| pair.distance_m < p.distance_m)
        {
            best = Some(pair);
        }
    }
    best
}

/// Room above the caller's bound given to parry's query, m: a pair that parry places just
/// beyond the bound but whose certified distance is within it is still found.
const QUERY_MARGIN_M: f64 = 1e-3;

/// [`shape_capsule`] for one convex shape.
fn convex_capsule(
    link: LinkId,
    X_WA: &Pose,
    shape_A: &dyn Shape,
    part: HumanPart,
    b: &Capsule,
    margin: f64,
) -> Option<SignedDistancePair> {
    // parry's capsule: a segment in its own frame; place it at the identity.
    let capsule_B = parry3d_f64::shape::Capsule::new(b.a_W, b.b_W, b.radius_m);
    let contact = query::contact(
        X_WA,
        shape_A,
        &Pose::IDENTITY,
        &capsule_B,
        margin + QUERY_MARGIN_M,
    )
    .ok()??;
    // normal1 points from A toward B.
    let nhat_BA_W = -contact.normal1;
    let mut distance_m = contact.dist;
    if let Some(support) = shape_A.as_support_map()
        && (nhat_BA_W.length() - 1.0).abs() < 1e-9
    {
        // min over A of a.n is A's support point toward -n.
        let min_a = support.support_point(X_WA, -nhat_BA_W).dot(nhat_BA_W);
        let max_b = b.a_W.dot(nhat_BA_W).max(b.b_W.dot(nhat_BA_W)) + b.radius_m;
        distance_m = distance_m.min(min_a - max_b);
    }
    if !distance_m.is_finite() || distance_m > margin {
        return None;
    }
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
        distance_m,
        // A's witness moves with the certified distance, keeping p_WA - p_WB = d n.
        p_WA: contact.point2 + nhat_BA_W * distance_m,
        p_WB: contact.point2,
        nhat_BA_W,
        t_B,
    })
}
