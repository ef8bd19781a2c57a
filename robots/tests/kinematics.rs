//! Forward kinematics against closed-form Denavit-Hartenberg products, Jacobians against
//! finite differences of forward kinematics.
#![allow(clippy::needless_range_loop)] // 4 x 4 matrices read best with indices

use approx::assert_relative_eq;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use workcell_robots::math::{Pose, Vector, pose_from_xyz_rpy};
use workcell_robots::{Jacobian, PackageMap, RobotModel};

type Mat4 = [[f64; 4]; 4];

fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut c = [[0.0; 4]; 4];
    for i in 0..4 {
        for j in 0..4 {
            c[i][j] = (0..4).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

/// Standard DH: Rz(theta) Tz(d) Tx(a) Rx(alpha), written out as a matrix (Craig/Spong form),
/// independently of the URDF the catalogue generates.
fn dh(theta: f64, d: f64, a: f64, alpha: f64) -> Mat4 {
    let (st, ct) = theta.sin_cos();
    let (sa, ca) = alpha.sin_cos();
    [
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

fn dh_chain(rows: &[(f64, f64, f64)], q: &[f64]) -> Mat4 {
    let mut t = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    for ((alpha, a, d), theta) in rows.iter().zip(q) {
        t = mul(&t, &dh(*theta, *d, *a, *alpha));
    }
    t
}

fn assert_pose_matches(pose: &Pose, t: &Mat4) {
    let m = parry3d_f64::glamx::DMat3::from_quat(pose.rotation);
    for i in 0..3 {
        assert_relative_eq!(pose.translation.to_array()[i], t[i][3], epsilon = 1e-9);
        for j in 0..3 {
            assert_relative_eq!(m.col(j).to_array()[i], t[i][j], epsilon = 1e-9);
        }
    }
}

fn random_q(robot: &RobotModel, rng: &mut ChaCha8Rng) -> Vec<f64> {
    robot
        .position_limits()
        .iter()
        .map(|[lo, hi]| {
            let (lo, hi) = (lo.max(-3.0), hi.min(3.0));
            rng.random_range(lo..=hi)
        })
        .collect()
}

const PI: f64 = std::f64::consts::PI;

#[test]
fn ur5e_tool0_is_the_dh_product() {
    // UR5e DH parameters (alpha, a, d) from Universal Robots' published table.
    let rows = [
        (PI / 2.0, 0.0, 0.1625),
        (0.0, -0.425, 0.0),
        (0.0, -0.3922, 0.0),
        (PI / 2.0, 0.0, 0.1333),
        (-PI / 2.0, 0.0, 0.0997),
        (0.0, 0.0, 0.0996),
    ];
    let robot = RobotModel::from_catalogue("ur5e_kinematics").expect("catalogue");
    let tool0 = robot.link_id("tool0").expect("tool0");
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..50 {
        let q = random_q(&robot, &mut rng);
        let state = robot.fk(Pose::IDENTITY, &q).expect("fk");
        assert_pose_matches(state.link_pose(tool0), &dh_chain(&rows, &q));
    }
}

#[test]
fn iiwa14_flange_is_the_dh_product_and_base_pose_composes() {
    let rows = [
        (-PI / 2.0, 0.0, 0.36),
        (PI / 2.0, 0.0, 0.0),
        (PI / 2.0, 0.0, 0.42),
        (-PI / 2.0, 0.0, 0.0),
        (-PI / 2.0, 0.0, 0.40),
        (PI / 2.0, 0.0, 0.0),
        (0.0, 0.0, 0.126),
    ];
    let robot = RobotModel::from_catalogue("iiwa14_kinematics").expect("catalogue");
    let tool0 = robot.link_id("tool0").expect("tool0");
    let X_WB = pose_from_xyz_rpy([0.3, -0.2, 0.75], [0.0, 0.0, 0.5]);
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for _ in 0..50 {
        let q = random_q(&robot, &mut rng);
        let at_origin = robot.fk(Pose::IDENTITY, &q).expect("fk");
        assert_pose_matches(at_origin.link_pose(tool0), &dh_chain(&rows, &q));
        let moved = robot.fk(X_WB, &q).expect("fk");
        let expected = X_WB * *at_origin.link_pose(tool0);
        assert_relative_eq!(
            moved.link_pose(tool0).translation,
            expected.translation,
            epsilon = 1e-12
        );
    }
}

/// Central differences of FK: linear velocity of a point and angular velocity of its link.
fn numeric_jacobian(robot: &RobotModel, q: &[f64], link: usize, p_L: Vector) -> Vec<[f64; 6]> {
    let h = 1e-6;
    (0..robot.dof())
        .map(|i| {
            let mut qp = q.to_vec();
            let mut qm = q.to_vec();
            qp[i] += h;
            qm[i] -= h;
            let xp = *robot.fk(Pose::IDENTITY, &qp).expect("fk").link_pose(link);
            let xm = *robot.fk(Pose::IDENTITY, &qm).expect("fk").link_pose(link);
            let v = (xp.transform_point(p_L) - xm.transform_point(p_L)) / (2.0 * h);
            // Angular velocity from the rotation difference: log(R+ R-^T) / (2h).
            let w = (xp.rotation * xm.rotation.inverse()).to_scaled_axis() / (2.0 * h);
            [v.x, v.y, v.z, w.x, w.y, w.z]
        })
        .collect()
}

#[test]
fn jacobians_match_finite_differences() {
    let gripper = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/pkg/my_robot/urdf/gripper.urdf");
    let robots = [
        RobotModel::from_catalogue("ur5e_kinematics").expect("ur5e"),
        RobotModel::from_catalogue("iiwa14_kinematics").expect("iiwa"),
        RobotModel::from_catalogue("human_arm").expect("human arm"),
        RobotModel::from_catalogue("human").expect("human"),
        // prismatic, continuous and mimic joints
        RobotModel::from_urdf_file(gripper, &PackageMap::new()).expect("gripper"),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for robot in &robots {
        let mut jacobian = Jacobian::zeros(robot.dof());
        for _ in 0..20 {
            let q = random_q(robot, &mut rng);
            let state = robot.fk(Pose::IDENTITY, &q).expect("fk");
            for link in 0..robot.links().len() {
                let p_L = Vector::new(
                    rng.random_range(-0.1..0.1),
                    rng.random_range(-0.1..0.1),
                    rng.random_range(-0.1..0.1),
                );
                let p_W = state.link_pose(link).transform_point(p_L);
                robot.point_jacobian(&state, link, p_W, &mut jacobian);
                let numeric = numeric_jacobian(robot, &q, link, p_L);
                for (col, num) in jacobian.columns().iter().zip(&numeric) {
                    for r in 0..6 {
                        assert!(
                            (col[r] - num[r]).abs() < 1e-6,
                            "{}: link {} row {r}: analytic {} numeric {}",
                            robot.name(),
                            robot.links()[link].name,
                            col[r],
                            num[r]
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn wrong_configuration_is_an_error_not_a_panic() {
    let robot = RobotModel::from_catalogue("ur5e_kinematics").expect("catalogue");
    assert!(robot.fk(Pose::IDENTITY, &[0.0; 5]).is_err());
    assert!(
        robot
            .fk(Pose::IDENTITY, &[0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0])
            .is_err()
    );
}

#[test]
fn catalogue_models_are_complete() {
    // Total masses: UR5e and iiwa 14 specification sheets; the human models are trunk, upper
    // arm, forearm and hand of a 75 kg body (0.497 + 0.028 + 0.016 + 0.006 of the mass), and
    // `human` its head and neck and the left arm too (0.081 + 0.050; Winter 2009, Table 4.1).
    for (name, dof, mass_kg) in [
        ("ur5e_kinematics", 6, 20.6),
        ("iiwa14_kinematics", 7, 29.5),
        ("human_arm", 3, 0.547 * 75.0),
        ("human", 15, 0.678 * 75.0),
    ] {
        let robot = RobotModel::from_catalogue(name).expect("catalogue");
        assert_eq!(robot.dof(), dof, "{name}");
        assert_relative_eq!(robot.mass_kg(), mass_kg, epsilon = 1e-9);
        for &j in robot.actuated_joints() {
            let l = robot.joints()[j].limits;
            assert!(
                l.lower < l.upper && l.velocity > 0.0 && l.effort > 0.0,
                "{name}: limits of joint {j}"
            );
        }
        for link in robot.links() {
            // every link with geometry is covered by its bounding capsule
            if let Some(c) = workcell_robots::collision::link_bounding_capsule(
                &robot,
                robot.link_id(&link.name).expect("id"),
            ) {
                assert!(
                    c.radius_m > 0.0 && c.radius_m < 0.3,
                    "{name}/{}: radius {}",
                    link.name,
                    c.radius_m
                );
            }
        }
    }
}
