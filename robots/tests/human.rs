//! The built-in human's two looks against its collision envelopes: what the camera sees of
//! the flesh lies inside what the safety layer keeps away from, and its sizes are the cited
//! circumferences (robots/urdf/generate.py: the StatLib `bodyfat` means).

use workcell_robots::collision::link_bounding_capsule;
use workcell_robots::math::Vector;
use workcell_robots::{HumanLook, HumanPart, RobotModel, Shape};

/// Points on the surface of a visual (spheres: 26 directions; cylinders: the rims at 64
/// angles and 5 rings along the side), in the link frame.
fn surface(shape: &Shape, X: &workcell_robots::math::Pose) -> Vec<Vector> {
    let mut out = Vec::new();
    match shape {
        Shape::Sphere { radius_m } => {
            for i in -1..=1 {
                for j in -1..=1 {
                    for k in -1..=1 {
                        let d = Vector::new(f64::from(i), f64::from(j), f64::from(k));
                        if d.length() > 0.0 {
                            out.push(X.transform_point(d.normalize() * *radius_m));
                        }
                    }
                }
            }
        }
        Shape::Cylinder { radius_m, length_m } => {
            for a in 0..64 {
                let t = std::f64::consts::TAU * f64::from(a) / 64.0;
                for z in 0..5 {
                    let z = length_m * (f64::from(z) / 4.0 - 0.5);
                    out.push(X.transform_point(Vector::new(
                        radius_m * t.cos(),
                        radius_m * t.sin(),
                        z,
                    )));
                }
            }
        }
        Shape::Box { size_m } => {
            for c in 0..8 {
                let s = |bit: i32| if c & bit == 0 { -0.5 } else { 0.5 };
                out.push(X.transform_point(Vector::new(
                    s(1) * size_m[0],
                    s(2) * size_m[1],
                    s(4) * size_m[2],
                )));
            }
        }
        other => panic!("unexpected visual {other:?}"),
    }
    out
}

fn distance_to_segment(p: Vector, a: Vector, b: Vector) -> f64 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_squared().max(1e-18)).clamp(0.0, 1.0);
    (p - (a + t * ab)).length()
}

#[test]
fn the_flesh_of_the_arm_and_head_lies_inside_its_collision_envelope() {
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
        let human = RobotModel::from_catalogue(name).unwrap();
        flesh_inside_envelopes(&human, parts);
    }
}

fn flesh_inside_envelopes(human: &RobotModel, parts: &[HumanPart]) {
    for &part in parts {
        let l = human.link_id(part.link_name()).unwrap();
        let capsule = link_bounding_capsule(human, l).unwrap();
        let flesh: Vec<_> = human.links()[l]
            .visuals
            .iter()
            .filter(|g| HumanLook::role(g.name.as_deref()).is_some())
            .collect();
        assert!(!flesh.is_empty(), "{part} has no flesh");
        for g in flesh {
            for p in surface(&g.shape, &g.X_LG) {
                let d = distance_to_segment(p, capsule.a_L, capsule.b_L);
                assert!(
                    d <= capsule.radius_m + 1e-9,
                    "{part}: flesh point {p} is {d} m from the axis, envelope {}",
                    capsule.radius_m
                );
            }
        }
    }
}

#[test]
fn each_look_draws_its_own_visuals_and_the_flesh_has_the_cited_girths() {
    let human = RobotModel::from_catalogue("human_arm").unwrap();
    let forearm = human.link_id("forearm").unwrap();
    let radii = |look: HumanLook| -> Vec<f64> {
        let mut model = human.clone();
        model.retain_visuals(|g| look.shows(g.name.as_deref()));
        model.links()[forearm]
            .visuals
            .iter()
            .filter_map(|g| match g.shape {
                Shape::Sphere { radius_m } | Shape::Cylinder { radius_m, .. } => Some(radius_m),
                _ => None,
            })
            .collect()
    };
    // Flesh: from the forearm's girth (28.66 cm) at the elbow to the wrist's (18.23 cm).
    let flesh = radii(HumanLook::Flesh);
    let max = flesh.iter().copied().fold(0.0, f64::max);
    let min = flesh.iter().copied().fold(1.0, f64::min);
    assert!((max - 0.2866 / std::f64::consts::TAU).abs() < 1e-6, "{max}");
    assert!((min - 0.1823 / std::f64::consts::TAU).abs() < 1e-6, "{min}");
    // Skeletal: the two bones, 8 and 9 mm.
    let bones = radii(HumanLook::Skeletal);
    assert!(bones.iter().all(|&r| r == 0.008 || r == 0.009), "{bones:?}");
    // Every visual is in exactly one look or in both: none is lost.
    let all = human.links()[forearm].visuals.len();
    assert_eq!(flesh.len() + bones.len(), all);
}

/// At every joint's zero the whole body is the arm model: the same link frames for the parts
/// both have, the same visuals and collision shapes (the head moved to a link of its own and
/// the same in the world; the whole body's left arm aside), the same mass in the arm.
#[test]
fn the_whole_body_at_zero_is_the_arm_model() {
    use workcell_robots::math::Pose;
    let arm = RobotModel::from_catalogue("human_arm").unwrap();
    let body = RobotModel::from_catalogue("human").unwrap();
    let k_arm = arm.fk(Pose::IDENTITY, &vec![0.0; arm.dof()]).unwrap();
    let k_body = body.fk(Pose::IDENTITY, &vec![0.0; body.dof()]).unwrap();
    // Every visual and collision shape of a model in the world, as text to compare.
    let shapes = |model: &RobotModel, k: &workcell_robots::KinematicState| {
        let mut out = Vec::new();
        for (l, link) in model.links().iter().enumerate() {
            if link.name.starts_with("left_") {
                continue;
            }
            let X = k.link_pose(l);
            for g in link.visuals.iter().chain(&link.collisions) {
                let p = X.transform_point(g.X_LG.translation);
                out.push(format!(
                    "{:?} {:?} at {:.6} {:.6} {:.6}",
                    g.name, g.shape, p.x, p.y, p.z
                ));
            }
        }
        out.sort();
        out
    };
    assert_eq!(shapes(&arm, &k_arm), shapes(&body, &k_body));
    for part in HumanPart::ARM.into_iter().chain([HumanPart::Torso]) {
        let (a, b) = (
            arm.link_id(part.link_name()).unwrap(),
            body.link_id(part.link_name()).unwrap(),
        );
        let (pa, pb) = (k_arm.link_pose(a), k_body.link_pose(b));
        assert!((pa.translation - pb.translation).length() < 1e-12, "{part}");
        assert!(pa.rotation.angle_between(pb.rotation) < 1e-12, "{part}");
        if part != HumanPart::Torso {
            assert_eq!(arm.links()[a].inertial, body.links()[b].inertial, "{part}");
        }
    }
    assert!(body.link_id(HumanPart::Head.link_name()).is_some());
}

/// The whole body's left arm is its right arm's mirror image across the torso's x-z plane at
/// the same joint values: every left link frame is the right one's mirrored (a point (x, y, z)
/// of a right link, mirrored, is the point (x, -y, z) of its left twin), in any posture of
/// the arm and the trunk; the masses and the collision envelopes are the same.
#[test]
fn the_left_arm_is_the_right_arms_mirror_image() {
    use workcell_robots::math::Pose;
    let body = RobotModel::from_catalogue("human").unwrap();
    let index = |name: &str| {
        body.actuated_joints()
            .iter()
            .position(|&j| body.joints()[j].name == name)
            .unwrap_or_else(|| panic!("{name}"))
    };
    let arm_joints = [
        ("shoulder_flexion", [0.3, 1.4, -0.5]),
        ("shoulder_abduction", [0.2, 0.9, -0.3]),
        ("shoulder_rotation", [0.4, -0.8, 1.0]),
        ("elbow_flexion", [1.1, 0.2, 2.0]),
        ("forearm_rotation", [0.5, 1.5, 0.0]),
    ];
    let torso = body.link_id("torso").unwrap();
    let mirror = |v: Vector| Vector::new(v.x, -v.y, v.z);
    let points = [
        Vector::new(0.0, 0.0, 0.0),
        Vector::new(0.03, 0.02, -0.1),
        Vector::new(-0.01, -0.04, -0.25),
    ];
    for posture in 0..3 {
        let mut q = vec![0.0; body.dof()];
        for (name, values) in arm_joints {
            q[index(name)] = values[posture];
            q[index(&format!("left_{name}"))] = values[posture];
        }
        // A turned and leaning trunk: the mirror is the torso's, not the world's.
        q[index("trunk_turn")] = 0.4 * posture as f64;
        q[index("trunk_lean")] = 0.2;
        let k = body.fk(Pose::IDENTITY, &q).unwrap();
        let X_WT = *k.link_pose(torso);
        for right in ["shoulder", "upper_arm", "elbow", "forearm", "hand"] {
            let (r, l) = (
                body.link_id(right).unwrap(),
                body.link_id(&format!("left_{right}")).unwrap(),
            );
            for p in points {
                let p_r = X_WT.inverse_transform_point(k.link_pose(r).transform_point(p));
                let p_l = X_WT.inverse_transform_point(k.link_pose(l).transform_point(mirror(p)));
                assert!(
                    (mirror(p_r) - p_l).length() < 1e-12,
                    "{right}, posture {posture}: {p_r} mirrored against {p_l}"
                );
            }
            assert_eq!(
                body.links()[r].inertial,
                body.links()[l].inertial,
                "{right}"
            );
            if let (Some(a), Some(b)) = (
                link_bounding_capsule(&body, r),
                link_bounding_capsule(&body, l),
            ) {
                assert_eq!(a.radius_m, b.radius_m, "{right}");
                assert!(
                    (mirror(a.a_L) - b.a_L).length() < 1e-12
                        && (mirror(a.b_L) - b.b_L).length() < 1e-12
                );
            }
        }
        // The joints share ranges and speeds.
        for (name, _) in arm_joints {
            let (r, l) = (
                &body.joints()[body.joint_id(name).unwrap()],
                &body.joints()[body.joint_id(&format!("left_{name}")).unwrap()],
            );
            assert_eq!(r.limits, l.limits, "{name}");
        }
    }
    // Without its left arm it is the one-armed body of the earlier figures.
    let one = RobotModel::one_armed_human().unwrap();
    assert_eq!(one.dof() + 5, body.dof());
    assert!(one.links().iter().all(|l| !l.name.starts_with("left_")));
    assert_eq!(one.links().len() + 6, body.links().len());
    for part in HumanPart::LEFT_ARM {
        assert_eq!(
            HumanPart::of_link_name(&body.links()[body.link_id(part.link_name()).unwrap()].name),
            Some(part)
        );
    }
}

/// The joints that move a link, from its own up to the root: the whole body's hand hangs from
/// the wrist, the arm's five joints and the trunk's five; the left hand from the left arm's and
/// the same trunk; the root from none.
#[test]
fn the_joints_above_a_link_run_from_it_to_the_root() {
    let body = RobotModel::from_catalogue("human").unwrap();
    let names = |link: &str| -> Vec<&str> {
        body.joints_above(body.link_id(link).unwrap())
            .map(|j| body.joints()[j].name.as_str())
            .collect()
    };
    let trunk = [
        "trunk_side",
        "trunk_lean",
        "trunk_turn",
        "pelvis_y",
        "pelvis_x",
    ];
    let arm = [
        "wrist",
        "forearm_rotation",
        "elbow_flexion",
        "shoulder_rotation",
        "shoulder_abduction",
        "shoulder_flexion",
    ];
    assert_eq!(names("hand"), [&arm[..], &trunk[..]].concat());
    let left: Vec<String> = arm.iter().map(|j| format!("left_{j}")).collect();
    let mut want: Vec<&str> = left.iter().map(String::as_str).collect();
    want.extend(trunk);
    assert_eq!(names("left_hand"), want);
    assert!(names("pelvis").is_empty());
}
