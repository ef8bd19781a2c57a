//! Signed distances against closed-form cases, parry's GJK/EPA, brute force sampling, and
//! finite differences for the Jacobian rows.

use approx::assert_abs_diff_eq;
use parry3d_f64::shape::Cuboid;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{KinematicState, RobotModel};
use workcell_safety::geometry::{capsule_capsule, closest_segment_parameters, shape_capsule};
use workcell_safety::{
    Capsule, HumanEstimate, HumanPart, PartEstimate, RobotGeometry, SignedDistancePair,
};

const EXACT: f64 = 1e-12;

fn v(x: f64, y: f64, z: f64) -> Vector {
    Vector::new(x, y, z)
}

fn pair(a: Capsule, b: Capsule) -> SignedDistancePair {
    capsule_capsule(0, &a, HumanPart::Forearm, &b)
}

/// The invariants every pair must satisfy, whatever its sign.
fn check_invariants(p: &SignedDistancePair, tolerance: f64) {
    assert_abs_diff_eq!(p.nhat_BA_W.length(), 1.0, epsilon = 1e-9);
    let gap = p.p_WA - p.p_WB;
    assert!(
        (gap - p.nhat_BA_W * p.distance_m).length() < tolerance,
        "p_WA - p_WB = {gap:?} but distance * nhat = {:?}",
        p.nhat_BA_W * p.distance_m
    );
}

#[test]
fn parallel_capsules_distance_is_axis_gap_minus_radii() {
    let a = Capsule::new(v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), 0.1);
    let b = Capsule::new(v(0.2, 1.0, 0.0), v(1.4, 1.0, 0.0), 0.2);
    let p = pair(a, b);
    assert_abs_diff_eq!(p.distance_m, 0.7, epsilon = EXACT);
    // From the human part B (y = 1) toward the robot link A (y = 0).
    assert_abs_diff_eq!(p.nhat_BA_W.y, -1.0, epsilon = EXACT);
    assert_abs_diff_eq!(p.p_WA.y, 0.1, epsilon = EXACT);
    assert_abs_diff_eq!(p.p_WB.y, 0.8, epsilon = EXACT);
    check_invariants(&p, EXACT);
}

#[test]
fn crossing_capsules_meet_above_the_crossing_point() {
    // A along x, B along y, 0.5 above it, crossing over the origin.
    let a = Capsule::new(v(-1.0, 0.0, 0.0), v(1.0, 0.0, 0.0), 0.05);
    let b = Capsule::new(v(0.0, -1.0, 0.5), v(0.0, 1.0, 0.5), 0.15);
    let p = pair(a, b);
    assert_abs_diff_eq!(p.distance_m, 0.3, epsilon = EXACT);
    assert_abs_diff_eq!((p.p_WA - v(0.0, 0.0, 0.05)).length(), 0.0, epsilon = EXACT);
    assert_abs_diff_eq!((p.p_WB - v(0.0, 0.0, 0.35)).length(), 0.0, epsilon = EXACT);
    assert_abs_diff_eq!(p.nhat_BA_W.z, -1.0, epsilon = EXACT);
    assert_abs_diff_eq!(p.t_B, 0.5, epsilon = EXACT);
    check_invariants(&p, EXACT);
}

#[test]
fn touching_capsules_are_at_zero_distance() {
    let a = Capsule::new(v(-1.0, 0.0, 0.0), v(1.0, 0.0, 0.0), 0.25);
    let b = Capsule::new(v(0.3, -1.0, 0.5), v(0.3, 1.0, 0.5), 0.25);
    let p = pair(a, b);
    assert_abs_diff_eq!(p.distance_m, 0.0, epsilon = EXACT);
    assert_abs_diff_eq!((p.p_WA - p.p_WB).length(), 0.0, epsilon = EXACT);
}

#[test]
fn penetrating_capsules_have_negative_distance_and_consistent_witnesses() {
    let a = Capsule::new(v(-1.0, 0.0, 0.0), v(1.0, 0.0, 0.0), 0.1);
    let b = Capsule::new(v(0.0, -1.0, 0.1), v(0.0, 1.0, 0.1), 0.1);
    let p = pair(a, b);
    assert_abs_diff_eq!(p.distance_m, -0.1, epsilon = EXACT);
    // The normal still points from B (above) toward A (below).
    assert_abs_diff_eq!(p.nhat_BA_W.z, -1.0, epsilon = EXACT);
    check_invariants(&p, EXACT);
}

#[test]
fn intersecting_axes_give_the_sum_of_radii_as_depth() {
    let a = Capsule::new(v(-1.0, 0.0, 0.0), v(1.0, 0.0, 0.0), 0.1);
    let b = Capsule::new(v(0.0, -1.0, 0.0), v(0.0, 1.0, 0.0), 0.2);
    let p = pair(a, b);
    assert_abs_diff_eq!(p.distance_m, -0.3, epsilon = EXACT);
    // Normal of the plane of both axes.
    assert_abs_diff_eq!(p.nhat_BA_W.z.abs(), 1.0, epsilon = EXACT);
    check_invariants(&p, EXACT);
}

#[test]
fn collinear_segments_meet_end_to_end() {
    let a = Capsule::new(v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), 0.1);
    let b = Capsule::new(v(1.5, 0.0, 0.0), v(2.5, 0.0, 0.0), 0.1);
    let p = pair(a, b);
    assert_abs_diff_eq!(p.distance_m, 0.3, epsilon = EXACT);
    assert_abs_diff_eq!(p.nhat_BA_W.x, -1.0, epsilon = EXACT);
    assert_abs_diff_eq!(p.t_B, 0.0, epsilon = EXACT);
}

#[test]
fn degenerate_capsules_are_spheres() {
    let a = Capsule::new(v(0.0, 0.0, 0.0), v(0.0, 0.0, 0.0), 0.1);
    let b = Capsule::new(v(0.0, 0.0, 1.0), v(0.0, 0.0, 1.0), 0.2);
    assert_abs_diff_eq!(pair(a, b).distance_m, 0.7, epsilon = EXACT);
    // A sphere against a segment: the perpendicular foot.
    let c = Capsule::new(v(-1.0, 2.0, 0.0), v(1.0, 2.0, 0.0), 0.0);
    let p = pair(a, c);
    assert_abs_diff_eq!(p.distance_m, 1.9, epsilon = EXACT);
    assert_abs_diff_eq!(p.t_B, 0.5, epsilon = EXACT);
}

/// The closed form is the true minimum: no pair of sampled axis points is closer, and the
/// closest sample is within the sampling resolution.
#[test]
fn segment_closest_points_beat_dense_sampling() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let point = |rng: &mut ChaCha8Rng| {
        v(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
    };
    for _ in 0..200 {
        let (p1, q1, p2, q2) = (
            point(&mut rng),
            point(&mut rng),
            point(&mut rng),
            point(&mut rng),
        );
        let (s, t) = closest_segment_parameters(p1, q1, p2, q2);
        assert!((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t));
        let exact = ((p1 + (q1 - p1) * s) - (p2 + (q2 - p2) * t)).length();
        let n = 200;
        let mut sampled = f64::INFINITY;
        for i in 0..=n {
            let a = p1 + (q1 - p1) * (i as f64 / n as f64);
            for j in 0..=n {
                sampled = sampled.min((a - (p2 + (q2 - p2) * (j as f64 / n as f64))).length());
            }
        }
        assert!(
            exact <= sampled + 1e-12,
            "closed form {exact} above a sample {sampled}"
        );
        // Both segments are at most 2 sqrt(3) long: samples are within 1.8e-2 of any point.
        assert!(
            sampled - exact < 0.02,
            "closed form {exact} far below the samples {sampled}"
        );
    }
}

#[test]
fn capsule_against_box_matches_the_closed_form() {
    // A unit cube centred at the origin (parry takes half extents).
    let cube = Cuboid::new(v(0.5, 0.5, 0.5));
    let cases = [
        // Above the top face: 1.0 - 0.5 - 0.1.
        (
            Capsule::new(v(-0.2, 0.0, 1.0), v(0.2, 0.0, 1.0), 0.1),
            0.4,
            v(0.0, 0.0, -1.0),
        ),
        // Beside the +x face, axis vertical.
        (
            Capsule::new(v(0.8, 0.0, -0.2), v(0.8, 0.0, 0.2), 0.05),
            0.25,
            v(-1.0, 0.0, 0.0),
        ),
        // Off the (+x, +y) edge: distance from the edge line minus the radius.
        (
            Capsule::new(v(1.0, 1.0, -0.2), v(1.0, 1.0, 0.2), 0.1),
            0.5 * 2f64.sqrt() - 0.1,
            v(-1.0, -1.0, 0.0).normalize(),
        ),
        // Sunk 5 cm into the top face.
        (
            Capsule::new(v(-0.2, 0.0, 0.55), v(0.2, 0.0, 0.55), 0.1),
            -0.05,
            v(0.0, 0.0, -1.0),
        ),
    ];
    for (capsule, expected, normal) in cases {
        let p = shape_capsule(3, &Pose::IDENTITY, &cube, HumanPart::Hand, &capsule, 10.0)
            .expect("within range");
        // GJK against the capsule's round cap stops at its convergence tolerance: 2.4e-9 m
        // was the largest error seen on these cases (the anchors measured up to 1.3e-5 m for
        // curved pairs in general).
        assert_abs_diff_eq!(p.distance_m, expected, epsilon = 1e-8);
        // The normal comes from GJK's last simplex: off the edge it was 1e-5 from the true
        // bisector (the distance itself is far better).
        assert!(
            (p.nhat_BA_W - normal).length() < 5e-5,
            "normal {:?}, expected {normal:?}",
            p.nhat_BA_W
        );
        check_invariants(&p, 1e-8);
    }
    // Out of range: no pair.
    let far = Capsule::new(v(0.0, 0.0, 3.0), v(0.1, 0.0, 3.0), 0.1);
    assert!(shape_capsule(3, &Pose::IDENTITY, &cube, HumanPart::Hand, &far, 1.0).is_none());
}

/// parry's GJK on capsule pairs agrees with the closed form to its own accuracy.
#[test]
fn closed_form_agrees_with_parry_gjk_on_random_capsules() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut worst: f64 = 0.0;
    for _ in 0..300 {
        let mut point = || {
            v(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.5..0.5),
            )
        };
        let (a0, a1, b0, b1) = (point(), point(), point(), point());
        let a = Capsule::new(a0, a1, 0.05);
        let b = Capsule::new(b0, b1, 0.04);
        let exact = pair(a, b);
        let shape = parry3d_f64::shape::Capsule::new(a0, a1, 0.05);
        let gjk = shape_capsule(0, &Pose::IDENTITY, &shape, HumanPart::Forearm, &b, 10.0)
            .expect("within range");
        worst = worst.max((exact.distance_m - gjk.distance_m).abs());
        // Certified: never farther than the closed form.
        assert!(
            gjk.distance_m <= exact.distance_m + EXACT,
            "{} > {}",
            gjk.distance_m,
            exact.distance_m
        );
    }
    // SAFETY.md anchor: GJK capsule distances were measured with errors up to 1.3e-5 m.
    assert!(worst < 2e-5, "largest difference {worst}");
}

/// The normal Jacobian row is the gradient of the signed distance with respect to q
/// (central differences on the closed form).
#[test]
fn normal_jacobian_rows_are_distance_gradients() {
    let robot = RobotModel::from_catalogue("iiwa14_kinematics").expect("catalogue robot");
    let mut geometry = RobotGeometry::new(&robot).expect("geometry");
    let human = HumanEstimate {
        parts: vec![PartEstimate {
            part: HumanPart::Forearm,
            capsule: Capsule::new(v(0.55, -0.3, 0.5), v(0.55, 0.3, 0.7), 0.04),
            v_a_W: Vector::ZERO,
            v_b_W: Vector::ZERO,
        }],
        uncertainty_m: 0.01,
        uncertainty_rate_m_s: 0.0,
    };
    let q = [0.3, 0.7, -0.2, -1.2, 0.4, 0.9, 0.1];
    let mut kinematics = KinematicState::new(&robot);
    robot.forward_kinematics(&q, &mut kinematics).expect("fk");
    let mut pairs = Vec::new();
    geometry.pair_constraints(&robot, &kinematics, &human, 10.0, &mut pairs);
    assert!(pairs.len() >= 5, "every movable link is within 10 m");
    let distance = |q: &[f64], link: usize| {
        let mut k = KinematicState::new(&robot);
        robot.forward_kinematics(q, &mut k).expect("fk");
        let (l, c) = geometry
            .capsules(&k)
            .find(|(l, _)| *l == link)
            .expect("link capsule");
        capsule_capsule(
            l,
            &c,
            HumanPart::Forearm,
            &human.parts[0].capsule.inflated(0.01),
        )
        .distance_m
    };
    let h = 1e-6;
    let mut main_rows = 0;
    for p in &pairs {
        let d = distance(&q, p.pair.link);
        // Rows at segment ends (added where the closest points are nearly ambiguous) are
        // never closer than the capsule pair itself; the pair's own row is its gradient.
        assert!(
            p.pair.distance_m >= d - 1e-12,
            "an end row below the pair distance"
        );
        if (p.pair.distance_m - d).abs() > 1e-12 {
            continue;
        }
        main_rows += 1;
        for j in 0..robot.dof() {
            let (mut plus, mut minus) = (q, q);
            plus[j] += h;
            minus[j] -= h;
            let numeric =
                (distance(&plus, p.pair.link) - distance(&minus, p.pair.link)) / (2.0 * h);
            assert_abs_diff_eq!(p.normal_jacobian[j], numeric, epsilon = 1e-6);
        }
    }
    assert!(main_rows >= 5, "one row per movable link at least");
}

/// Parallel axes: the distance has a kink (turning either way brings an end closer), and the
/// rows must cover both sides: one row per segment end near the minimum.
#[test]
fn parallel_capsules_get_a_row_at_each_end() {
    let robot = RobotModel::from_catalogue("iiwa14_kinematics").expect("catalogue robot");
    let mut geometry = RobotGeometry::new(&robot).expect("geometry");
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let mut kinematics = KinematicState::new(&robot);
    robot.forward_kinematics(&q, &mut kinematics).expect("fk");
    // A human capsule parallel to link 4's capsule, 0.3 m beside it.
    let (link, c) = geometry
        .capsules(&kinematics)
        .find(|(l, _)| *l == 4)
        .expect("link 4");
    let axis = c.b_W - c.a_W;
    let side = axis.cross(Vector::Z).normalize();
    let offset = side * (0.3 + c.radius_m + 0.04);
    let human = HumanEstimate {
        parts: vec![PartEstimate {
            part: HumanPart::Forearm,
            capsule: Capsule::new(c.a_W + offset, c.b_W + offset, 0.04),
            v_a_W: Vector::ZERO,
            v_b_W: Vector::ZERO,
        }],
        uncertainty_m: 0.0,
        uncertainty_rate_m_s: 0.0,
    };
    let mut pairs = Vec::new();
    geometry.pair_constraints(&robot, &kinematics, &human, 0.5, &mut pairs);
    let rows: Vec<_> = pairs.iter().filter(|p| p.pair.link == link).collect();
    assert!(rows.len() >= 2, "{} rows for the parallel pair", rows.len());
    for r in &rows {
        assert_abs_diff_eq!(r.pair.distance_m, 0.3, epsilon = 1e-9);
    }
}

/// A rotation about a unit axis and a translation, drawn from `rng`.
fn random_pose(rng: &mut ChaCha8Rng) -> Pose {
    let axis = v(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    )
    .normalize_or(Vector::Z);
    let rotation = workcell_robots::math::Rotation::from_axis_angle(
        axis,
        rng.random_range(0.0..std::f64::consts::TAU),
    );
    let translation = v(
        rng.random_range(-2.0..2.0),
        rng.random_range(-2.0..2.0),
        rng.random_range(-2.0..2.0),
    );
    Pose::from_translation(translation) * Pose::from_rotation(rotation)
}

/// Nearly parallel capsules longer than 1 m, where the closed form's parallel fallback picks
/// one of many closest pairs: B starts h above A's start and leans toward A by theta, so the
/// gap is h - L sin(theta) at B's far end (then minus the radii). In random rigid poses the
/// answer may err only toward contact, and by no more than rounding.
#[test]
fn near_parallel_long_capsules_are_never_reported_farther() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let (h, r_a, r_b) = (0.3, 0.05, 0.04);
    let mut worst_under: f64 = 0.0;
    for length in [1.0, 1.5, 2.0, 4.0] {
        for theta in [0.0, 1e-9, 1e-7, 5e-7, 1e-6, 3e-6, 1e-5, 1e-3] {
            let expected = h - length * f64::sin(theta) - r_a - r_b;
            for _ in 0..25 {
                let X = random_pose(&mut rng);
                let a = Capsule::new(
                    X.transform_point(v(0.0, 0.0, 0.0)),
                    X.transform_point(v(length, 0.0, 0.0)),
                    r_a,
                );
                let b = Capsule::new(
                    X.transform_point(v(0.0, h, 0.0)),
                    X.transform_point(v(length * theta.cos(), h - length * theta.sin(), 0.0)),
                    r_b,
                );
                for d in [pair(a, b).distance_m, pair(b, a).distance_m] {
                    assert!(
                        d <= expected + 1e-12,
                        "L {length}, theta {theta}: {d} reported, {expected} true"
                    );
                    worst_under = worst_under.max(expected - d);
                }
            }
        }
    }
    // And exact up to rounding (the bound along the chosen normal is the answer here).
    assert!(worst_under < 1e-12, "conservative by up to {worst_under} m");
}

/// Signed distance between a segment and a box by the separating axis theorem: the box's
/// three face normals and the segment's direction crossed with each box edge are the only
/// candidate axes for two convex polytopes; the smallest overlap is the penetration depth.
/// Independent of parry; exact for overlapping pairs.
fn segment_box_depth(half: Vector, p0: Vector, p1: Vector) -> Option<f64> {
    let d = p1 - p0;
    let mut axes = vec![Vector::X, Vector::Y, Vector::Z];
    for e in [Vector::X, Vector::Y, Vector::Z] {
        let c = d.cross(e);
        if c.length() > 1e-9 {
            axes.push(c.normalize());
        }
    }
    let mut depth = f64::INFINITY;
    for u in axes {
        let extent = half.x * u.x.abs() + half.y * u.y.abs() + half.z * u.z.abs();
        let (lo, hi) = (p0.dot(u).min(p1.dot(u)), p0.dot(u).max(p1.dot(u)));
        let overlap = (extent - lo).min(hi + extent);
        if overlap <= 0.0 {
            return None;
        }
        depth = depth.min(overlap);
    }
    Some(depth)
}

/// Penetrating capsule-box pairs: parry's EPA may stop before the deepest direction; the
/// certified distance is never shallower than the exact depth (separating axes), and within
/// 1 mm of it.
#[test]
fn penetrating_capsule_box_pairs_are_never_reported_shallower() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let (mut cases, mut worst_deeper) = (0, 0.0f64);
    while cases < 2200 {
        let half = v(
            rng.random_range(0.02..0.4),
            rng.random_range(0.02..0.4),
            rng.random_range(0.02..0.4),
        );
        let mut point = || {
            v(
                rng.random_range(-0.6..0.6),
                rng.random_range(-0.6..0.6),
                rng.random_range(-0.6..0.6),
            )
        };
        let (p0, p1) = (point(), point());
        let Some(depth) = segment_box_depth(half, p0, p1) else {
            continue;
        };
        cases += 1;
        let radius = rng.random_range(0.01..0.3);
        let exact = -depth - radius;
        let X = random_pose(&mut rng);
        let capsule = Capsule::new(X.transform_point(p0), X.transform_point(p1), radius);
        let p = shape_capsule(1, &X, &Cuboid::new(half), HumanPart::Hand, &capsule, 1.0)
            .expect("overlapping");
        assert!(
            p.distance_m <= exact + 1e-9,
            "case {cases}: {} reported, {exact} exact",
            p.distance_m
        );
        worst_deeper = worst_deeper.max(exact - p.distance_m);
        check_invariants(&p, 1e-9);
    }
    assert!(
        worst_deeper < 1e-3,
        "deeper than exact by up to {worst_deeper} m"
    );
}

/// The catalogue's `human` is guarded arms and head (its own link, a 0.095 m sphere at the
/// head's centre, 0.68 m above the pelvis at rest), the left arm after the head and at rest
/// the right's mirror image; `human_arm`, whose head is part of its torso, arm only.
#[test]
fn the_whole_body_guards_its_head() {
    use workcell_safety::HumanGeometry;
    for (name, parts) in [
        ("human_arm", &HumanPart::ARM[..]),
        (
            "human",
            &[
                HumanPart::UpperArm,
                HumanPart::Forearm,
                HumanPart::Hand,
                HumanPart::Head,
                HumanPart::LeftUpperArm,
                HumanPart::LeftForearm,
                HumanPart::LeftHand,
            ][..],
        ),
    ] {
        let human = RobotModel::from_catalogue(name).expect("catalogue");
        let mut geometry = HumanGeometry::new(&human).expect("geometry");
        assert_eq!(geometry.parts().collect::<Vec<_>>(), parts, "{name}");
        let mut k = KinematicState::new(&human);
        human
            .forward_kinematics(&vec![0.0; human.dof()], &mut k)
            .expect("fk");
        let mut estimate = HumanEstimate::default();
        geometry.estimate_into(&human, &k, &vec![0.0; human.dof()], &mut estimate);
        if let Some(head) = estimate.parts.iter().find(|p| p.part == HumanPart::Head) {
            let centre = workcell_robots::math::Vector::new(0.01, 0.0, 0.68);
            assert!(
                (head.capsule.a_W - centre).length() < 1e-9,
                "{:?}",
                head.capsule
            );
            assert!((head.capsule.b_W - centre).length() < 1e-9);
            assert!((head.capsule.radius_m - 0.095).abs() < 1e-12);
        }
        // The pelvis stands at the origin with the torso unturned: the mirror is y -> -y.
        let mirror = |v: workcell_robots::math::Vector| {
            v * workcell_robots::math::Vector::new(1.0, -1.0, 1.0)
        };
        for left in estimate
            .parts
            .iter()
            .filter(|p| p.part.side() == Some(workcell_robots::Side::Left))
        {
            let right = estimate
                .parts
                .iter()
                .find(|p| p.part == left.part.mirrored())
                .expect("the right twin");
            assert!(
                (mirror(right.capsule.a_W) - left.capsule.a_W).length() < 1e-12,
                "{:?}",
                left.part
            );
            assert!(
                (mirror(right.capsule.b_W) - left.capsule.b_W).length() < 1e-12,
                "{:?}",
                left.part
            );
            assert_eq!(right.capsule.radius_m, left.capsule.radius_m);
        }
    }
}
