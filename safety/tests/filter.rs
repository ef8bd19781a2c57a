//! The QP filter against hand-solved QPs, the barrier holding against a moving human, the
//! fail-safe on bad input, and the ISO/TS 15066 formulas.

use approx::assert_abs_diff_eq;
use workcell_robots::math::{Pose, Vector};
use workcell_robots::{KinematicState, RobotModel};
use workcell_safety::geometry::capsule_capsule;
use workcell_safety::iso::effective_robot_mass_kg;
use workcell_safety::{
    BodyRegion, BrakeReason, Capsule, FilterConfig, FilterMode, FilterStatus, HumanEstimate,
    HumanPart, MAX_DOF, PairConstraint, PartEstimate, QpFilter, SafetyFilter, SignedDistancePair,
    SsmConfig,
};

fn row(normal_jacobian: &[f64], distance_m: f64, human_normal_speed_m_s: f64) -> PairConstraint {
    let mut nj = [0.0; MAX_DOF];
    nj[..normal_jacobian.len()].copy_from_slice(normal_jacobian);
    PairConstraint {
        pair: SignedDistancePair {
            link: 0,
            part: HumanPart::Hand,
            distance_m,
            p_WA: Vector::ZERO,
            p_WB: Vector::ZERO,
            nhat_BA_W: Vector::X,
            t_B: 0.0,
        },
        normal_jacobian: nj,
        human_normal_speed_m_s,
        max_approach_m_s: f64::INFINITY,
        obstacle: false,
        anticipated: false,
        escape_margin_m: 0.0,
    }
}

#[test]
fn qp_projects_the_nominal_command_onto_a_single_barrier() {
    let mut qp = QpFilter::new(2, 4).expect("setup");
    // Row: qdot_0 - 0.2 >= -2 (0.15 - 0.1), the human approaching at 0.2 m/s:
    // qdot_0 >= 0.2 - 0.1 = 0.1.
    let mut pairs = [row(&[1.0, 0.0], 0.15, 0.2)];
    let mut qdot = [0.0; 2];
    let slack = qp
        .solve(
            &[-0.4, 0.3],
            &mut pairs,
            &[-2.0; 2],
            &[2.0; 2],
            2.0,
            0.1,
            &mut qdot,
        )
        .expect("solved");
    assert_eq!(slack, 0.0, "feasible: the hard solution, no slack");
    // The closest point of the half-plane qdot_0 >= 0.1 to (-0.4, 0.3).
    assert_abs_diff_eq!(qdot[0], 0.1, epsilon = 1e-6);
    assert_abs_diff_eq!(qdot[1], 0.3, epsilon = 1e-6);

    // A diagonal row at d = d_min with the human approaching at 0.5 m/s:
    // (qdot_0 + qdot_1)/sqrt 2 >= 0.5; projection of (0, 0) is (0.3536, 0.3536).
    let s = 0.5f64.sqrt();
    let mut pairs = [row(&[s, s], 0.1, 0.5)];
    qp.solve(
        &[0.0, 0.0],
        &mut pairs,
        &[-2.0; 2],
        &[2.0; 2],
        1.0,
        0.1,
        &mut qdot,
    )
    .expect("solved");
    assert_abs_diff_eq!(qdot[0], 0.5 * s, epsilon = 1e-6);
    assert_abs_diff_eq!(qdot[1], 0.5 * s, epsilon = 1e-6);
}

#[test]
fn qp_respects_bounds_and_relaxes_an_impossible_row_least() {
    let mut qp = QpFilter::new(2, 2).expect("setup");
    let mut qdot = [0.0; 2];
    // Bounds only (an inactive pair): the nominal command clipped to the box.
    let mut pairs = [row(&[1.0, 0.0], 1.0, 0.0)];
    qp.solve(
        &[3.0, -3.0],
        &mut pairs,
        &[-1.0; 2],
        &[1.0; 2],
        1.0,
        0.1,
        &mut qdot,
    )
    .expect("solved");
    assert_abs_diff_eq!(qdot[0], 1.0, epsilon = 1e-6);
    assert_abs_diff_eq!(qdot[1], -1.0, epsilon = 1e-6);
    // qdot_0 >= 3 but qdot_0 <= 1: no command keeps the row; the least violating one runs
    // at the bound and breaks the row by 2 m/s. (The slack's penalty weight, 1e4, sets the
    // solver's absolute accuracy on this answer: 1e-4.)
    let mut pairs = [row(&[1.0, 0.0], 0.1, 3.0)];
    let slack = qp
        .solve(
            &[0.0, 0.5],
            &mut pairs,
            &[-1.0; 2],
            &[1.0; 2],
            1.0,
            0.1,
            &mut qdot,
        )
        .expect("relaxed");
    assert_abs_diff_eq!(slack, 2.0, epsilon = 1e-4);
    assert_abs_diff_eq!(qdot[0], 1.0, epsilon = 1e-4);
    assert_abs_diff_eq!(qdot[1], 0.5, epsilon = 1e-4);
}

#[test]
fn qp_keeps_the_closest_pairs_when_rows_run_out() {
    let mut qp = QpFilter::new(1, 2).expect("setup");
    let mut qdot = [0.0];
    // Three rows, room for two: the far pair (qdot >= -0.9) must go, the close ones stay.
    let mut pairs = [
        row(&[1.0], 1.0, 0.0),
        row(&[1.0], 0.12, 0.3),
        row(&[1.0], 0.2, 0.0),
    ];
    qp.solve(&[-1.0], &mut pairs, &[-2.0], &[2.0], 1.0, 0.1, &mut qdot)
        .expect("solved");
    // Binding row: qdot >= 0.3 - 0.02 = 0.28.
    assert_abs_diff_eq!(qdot[0], 0.28, epsilon = 1e-6);
}

/// Anticipated copies come last when rows run out: with room for two rows, the far pair of
/// a part where it is (qdot >= 0.2) and an obstacle row (qdot <= 1) keep theirs, and the
/// closer copy (which alone would bind: qdot >= 0.58) gets none. With room for three the
/// copy binds.
#[test]
fn qp_ranks_anticipated_copies_after_parts_and_obstacles() {
    let mut qp = QpFilter::new(1, 2).expect("setup");
    let mut qdot = [0.0];
    let copy = PairConstraint {
        anticipated: true,
        ..row(&[1.0], 0.12, 0.6)
    };
    let obstacle = PairConstraint {
        obstacle: true,
        max_approach_m_s: 1.0,
        ..row(&[-1.0], 0.05, 0.0)
    };
    // At gamma 1: 0.3 m of room, closing at 0.5 m/s.
    let part = row(&[1.0], 0.4, 0.5);
    let mut pairs = [copy, obstacle, part];
    qp.solve(&[-1.0], &mut pairs, &[-2.0], &[2.0], 1.0, 0.1, &mut qdot)
        .expect("solved");
    assert!(pairs[..2].iter().all(|c| !c.anticipated));
    assert_abs_diff_eq!(qdot[0], 0.2, epsilon = 1e-6);
    let mut qp = QpFilter::new(1, 3).expect("setup");
    qp.solve(&[-1.0], &mut pairs, &[-2.0], &[2.0], 1.0, 0.1, &mut qdot)
        .expect("solved");
    // Binding: qdot >= 0.6 - 0.02 = 0.58.
    assert_abs_diff_eq!(qdot[0], 0.58, epsilon = 1e-6);
}

/// Two pairs that no command keeps: the closest (at d_min, the human closing at 1.5 m/s)
/// wants qdot_0 >= 1.5, a far one (0.4 m of room at gamma 2, closing at 1.5 m/s) wants
/// qdot_0 <= -0.7. The far pair gives way: the arm retreats from the closest at its bound,
/// 1 rad/s, breaking the closest row by 0.5 m/s (one shared unweighted slack would split
/// the difference at qdot_0 = 0.4 and break both by 1.1 m/s).
#[test]
fn qp_gives_way_on_the_far_pair_before_the_closest() {
    let mut qp = QpFilter::new(2, 4).expect("setup");
    let mut qdot = [0.0; 2];
    let mut pairs = [row(&[1.0, 0.0], 0.1, 1.5), row(&[-1.0, 0.0], 0.5, 1.5)];
    let violation = qp
        .solve(
            &[0.0, 0.2],
            &mut pairs,
            &[-1.0; 2],
            &[1.0; 2],
            2.0,
            0.1,
            &mut qdot,
        )
        .expect("relaxed");
    assert_abs_diff_eq!(qdot[0], 1.0, epsilon = 1e-5);
    assert_abs_diff_eq!(qdot[1], 0.2, epsilon = 1e-5);
    assert_abs_diff_eq!(violation, 0.5, epsilon = 1e-4);
}

/// Power and force limiting caps a pair's approach speed below what its barrier allows:
/// the nominal command approaches at 2 m/s, the barrier allows 4 (0.25 - 0.1) = 0.6 m/s,
/// the cap 0.5 m/s; the projection keeps the other joint.
#[test]
fn qp_caps_the_approach_speed_of_a_pair() {
    let mut qp = QpFilter::new(2, 4).expect("setup");
    let mut qdot = [0.0; 2];
    for (cap, expected) in [(0.5, -0.5), (f64::INFINITY, -0.6), (0.9, -0.6)] {
        let mut pairs = [PairConstraint {
            max_approach_m_s: cap,
            ..row(&[1.0, 0.0], 0.25, 0.0)
        }];
        let violation = qp
            .solve(
                &[-2.0, 0.3],
                &mut pairs,
                &[-3.0; 2],
                &[3.0; 2],
                4.0,
                0.1,
                &mut qdot,
            )
            .expect("solved");
        assert_eq!(violation, 0.0);
        assert_abs_diff_eq!(qdot[0], expected, epsilon = 1e-6);
        assert_abs_diff_eq!(qdot[1], 0.3, epsilon = 1e-6);
    }
}

/// In the filter, every pair within `pfl_distance_m` gets its body region's ISO/TS 15066
/// transient contact speed (effective mass M/2 for this robot) as its cap, the pairs beyond
/// a braking ramp up from it, and the command keeps the caps: an iiwa driven straight at a chest (the torso's
/// 0.55 m/s, the strictest region) 0.35 m ahead of its tool.
/// Near the chest the robot approaches no faster than its ISO/TS 15066 contact speed; near
/// the head, where contact is not permitted, not at all.
#[test]
fn filter_caps_the_approach_speed_near_each_part() {
    for part in [HumanPart::Torso, HumanPart::Head] {
        caps_the_approach_speed_near(part);
    }
}

fn caps_the_approach_speed_near(part: HumanPart) {
    let robot = iiwa();
    let config = FilterConfig {
        gamma_per_s: 40.0,
        ..FilterConfig::default()
    };
    let mut filter =
        SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config.clone()).expect("filter");
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let mut k = KinematicState::new(&robot);
    robot.forward_kinematics(&q, &mut k).expect("fk");
    let tool = robot.links().len() - 1;
    let p_tool = k.link_pose(tool).translation;
    let chest = |at: Vector| HumanEstimate {
        parts: vec![PartEstimate {
            part,
            capsule: Capsule::new(at, at + Vector::new(0.0, 0.1, 0.0), 0.04),
            v_a_W: Vector::ZERO,
            v_b_W: Vector::ZERO,
        }],
        uncertainty_m: 0.0,
        uncertainty_rate_m_s: 0.0,
    };
    // Joints 1, 2, 4 and 6 near their velocity limits, in the combination that moves the
    // tool fastest; the chest waits 0.35 m ahead of the tool on that line.
    let mut jacobian = workcell_robots::Jacobian::zeros(7);
    robot.point_jacobian(&k, tool, p_tool, &mut jacobian);
    let (nominal, v_tool) = (0..16)
        .map(|signs: u32| {
            let sign = |bit: u32| if signs & (1 << bit) == 0 { 1.0 } else { -1.0 };
            [
                1.4 * sign(0),
                1.4 * sign(1),
                0.0,
                1.25 * sign(2),
                0.0,
                2.0 * sign(3),
                0.0,
            ]
        })
        .map(|qdot| (qdot, jacobian.linear_velocity(&qdot)))
        .max_by(|x, y| x.1.length().total_cmp(&y.1.length()))
        .expect("candidates");
    let human = chest(p_tool + v_tool.normalize() * 0.35);
    let out = filter.tick(&robot, &q, &nominal, &human, 0.004);
    assert!(
        matches!(out.status, FilterStatus::Modified),
        "{:?}",
        out.status
    );
    let limit = BodyRegion::of(part)
        .max_contact_speed_m_s(effective_robot_mass_kg(robot.mass_kg(), 0.0), true);
    assert!(
        v_tool.length() > 2.0 * limit.max(0.5),
        "the nominal must approach faster than the cap"
    );
    assert_eq!(limit == 0.0, part == HumanPart::Head, "{part}: {limit}");
    let (mut capped, mut binding) = (0, 0);
    for c in filter.pairs() {
        let approach = c.approach_m_s(filter.command());
        if c.pair.distance_m < config.pfl_distance_m {
            assert_eq!(c.max_approach_m_s, limit);
            assert!(approach <= limit + 1e-5, "{approach} > {limit}");
            capped += 1;
            binding += usize::from(approach > limit - 1e-4);
        } else {
            // Beyond, the cap rises as a braking ramp toward the limit.
            let ramp = (limit * limit
                + 2.0 * config.pfl_deceleration_m_s2 * (c.pair.distance_m - config.pfl_distance_m))
                .sqrt();
            assert_abs_diff_eq!(c.max_approach_m_s, ramp, epsilon = 1e-12);
            assert!(approach <= ramp + 1e-5, "{approach} > {ramp}");
        }
    }
    assert!(
        capped > 0 && binding > 0,
        "{capped} capped, {binding} binding"
    );
}

fn iiwa() -> RobotModel {
    RobotModel::from_catalogue("iiwa14_kinematics").expect("catalogue robot")
}

fn forearm(a: Vector, b: Vector, v: Vector) -> HumanEstimate {
    HumanEstimate {
        parts: vec![PartEstimate {
            part: HumanPart::Forearm,
            capsule: Capsule::new(a, b, 0.04),
            v_a_W: v,
            v_b_W: v,
        }],
        uncertainty_m: 0.0,
        uncertainty_rate_m_s: 0.0,
    }
}

/// Smallest capsule distance between the robot at `q` and `human`.
fn capsule_gap(filter: &SafetyFilter, robot: &RobotModel, q: &[f64], human: &HumanEstimate) -> f64 {
    let mut k = KinematicState::new(robot);
    robot.forward_kinematics(q, &mut k).expect("fk");
    filter
        .geometry()
        .capsules(&k)
        .flat_map(|(l, c)| {
            human
                .parts
                .iter()
                .map(move |p| capsule_capsule(l, &c, p.part, &p.capsule).distance_m)
        })
        .fold(f64::INFINITY, f64::min)
}

/// A forearm sweeps toward the arm at 0.5 m/s while the nominal command drives the arm toward
/// it. With the human velocity term the gap never drops below d_min (up to the first-order
/// error of 1 ms steps); without it (a filter told the human stands still) the gap shrinks
/// below d_min. The second half is what shows the term is needed.
#[test]
fn barrier_holds_d_min_against_a_moving_human_only_with_the_velocity_term() {
    let robot = iiwa();
    let config = FilterConfig {
        acceleration_rad_s2: 100.0,
        ..FilterConfig::default()
    };
    let d_min = config.d_min_m;
    let run = |tell_velocity: bool| {
        let mut filter = SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config.clone())
            .expect("filter");
        let dt = 0.001;
        let mut q = vec![0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
        let v_human = Vector::new(-0.5, 0.0, 0.0);
        let (mut a, mut b) = (Vector::new(1.3, -0.3, 0.6), Vector::new(1.3, 0.3, 0.6));
        // The arm reaches forward (+x) by raising joint 2.
        let qdot_nom = [0.0, 0.4, 0.0, 0.3, 0.0, 0.0, 0.0];
        let mut min_gap = f64::INFINITY;
        let mut braked = 0;
        for _ in 0..1500 {
            let told = forearm(a, b, if tell_velocity { v_human } else { Vector::ZERO });
            let out = filter.tick(&robot, &q, &qdot_nom, &told, dt);
            if matches!(out.status, FilterStatus::Braking(_) | FilterStatus::Relaxed) {
                braked += 1;
            }
            for (qi, v) in q.iter_mut().zip(filter.command()) {
                *qi += v * dt;
            }
            a += v_human * dt;
            b += v_human * dt;
            // Stop the human at 0.55 m from the base axis.
            if a.x < 0.55 {
                a.x = 0.55;
                b.x = 0.55;
            }
            min_gap = min_gap.min(capsule_gap(
                &filter,
                &robot,
                &q,
                &forearm(a, b, Vector::ZERO),
            ));
        }
        (min_gap, braked)
    };
    let (with_term, braked) = run(true);
    assert!(
        with_term >= d_min - 1e-3,
        "gap {with_term} fell below d_min {d_min}"
    );
    assert_eq!(braked, 0, "the filter kept every row every tick");
    let (without_term, _) = run(false);
    assert!(
        without_term < d_min - 5e-3,
        "without the human velocity the gap was {without_term}"
    );
}

/// A standing human whose estimate ages: its uncertainty grows at 0.4 m/s, so the inflated
/// surface closes in on the arm although nothing moves. With the growth rate told, the
/// barrier keeps the inflated gap at d_min; without it, the gap falls below.
#[test]
fn barrier_counts_the_growth_of_the_uncertainty() {
    let robot = iiwa();
    let config = FilterConfig {
        acceleration_rad_s2: 100.0,
        ..FilterConfig::default()
    };
    let d_min = config.d_min_m;
    let run = |tell_rate: bool| {
        let mut filter = SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config.clone())
            .expect("filter");
        let dt = 0.001;
        let mut q = vec![0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
        let (a, b) = (Vector::new(0.95, -0.3, 0.6), Vector::new(0.95, 0.3, 0.6));
        let rate = 0.4;
        let mut min_gap = f64::INFINITY;
        for k in 0..600 {
            let uncertainty = rate * k as f64 * dt;
            let mut told = forearm(a, b, Vector::ZERO);
            told.uncertainty_m = uncertainty;
            told.uncertainty_rate_m_s = if tell_rate { rate } else { 0.0 };
            filter.tick(&robot, &q, &[0.0; 7], &told, dt);
            for (qi, v) in q.iter_mut().zip(filter.command()) {
                *qi += v * dt;
            }
            // The inflated surface at the end of the tick.
            let mut inflated = forearm(a, b, Vector::ZERO);
            inflated.parts[0].capsule.radius_m += uncertainty + rate * dt;
            let gap = capsule_gap(&filter, &robot, &q, &inflated);
            // From the first tick the pair is within reach of the barrier.
            if k > 0 {
                min_gap = min_gap.min(gap);
            }
        }
        min_gap
    };
    let with_rate = run(true);
    assert!(
        with_rate >= d_min - 1e-3,
        "gap {with_rate} fell below d_min {d_min}"
    );
    let without_rate = run(false);
    assert!(
        without_rate < d_min - 5e-3,
        "without the growth rate the gap was {without_rate}"
    );
}

/// A hand closing in on the tool from +x and a wall just behind it (-x): without the wall
/// the filter retreats straight into it; told about it, no link approaches the wall faster
/// than its row allows (obstacle gamma (d - clearance), the nominal command standing still).
#[test]
fn evading_the_human_does_not_push_the_arm_into_an_obstacle() {
    let robot = iiwa();
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let mut k = KinematicState::new(&robot);
    robot.forward_kinematics(&q, &mut k).expect("fk");
    let tool = robot.links().len() - 1;
    let p_tool = k.link_pose(tool).translation;
    let hand = HumanEstimate {
        parts: vec![PartEstimate {
            part: HumanPart::Hand,
            capsule: Capsule::new(
                p_tool + Vector::new(0.2, -0.05, 0.0),
                p_tool + Vector::new(0.2, 0.05, 0.0),
                0.04,
            ),
            v_a_W: Vector::new(-1.5, 0.0, 0.0),
            v_b_W: Vector::new(-1.5, 0.0, 0.0),
        }],
        uncertainty_m: 0.0,
        uncertainty_rate_m_s: 0.0,
    };
    let wall = workcell_safety::Obstacle::cuboid(
        Pose::from_translation(p_tool - Vector::new(0.25, 0.0, 0.0)),
        [0.05, 0.5, 0.5],
    );
    // A slow wall barrier, so that the unaware filter's retreat breaks it clearly.
    let config = FilterConfig {
        obstacle_gamma_per_s: 4.0,
        ..FilterConfig::default()
    };
    let approach_to_wall = |with_wall: bool| {
        let mut filter = SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config.clone())
            .expect("filter");
        filter.set_obstacles(if with_wall {
            vec![wall.clone()]
        } else {
            Vec::new()
        });
        let out = filter.tick(&robot, &q, &[0.0; 7], &hand, 0.004);
        assert!(
            !matches!(out.status, FilterStatus::Braking(_)),
            "{:?}",
            out.status
        );
        // The wall's rows, measured whether or not the filter was told.
        let mut told = SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config.clone())
            .expect("filter");
        told.set_obstacles(vec![wall.clone()]);
        told.tick(&robot, &q, &[0.0; 7], &hand, 0.004);
        told.pairs()
            .iter()
            .filter(|c| c.obstacle)
            .map(|c| {
                let bound = config.obstacle_gamma_per_s
                    * (c.pair.distance_m - config.obstacle_clearance_m).max(0.0);
                c.approach_m_s(filter.command()) - bound
            })
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let excess_without = approach_to_wall(false);
    assert!(
        excess_without > 0.05,
        "the unaware filter should back into the wall: {excess_without}"
    );
    let excess_with = approach_to_wall(true);
    assert!(
        excess_with <= 1e-5,
        "a link approached the wall {excess_with} m/s beyond its row"
    );
}

/// The escape-aware margin of each pair is the horizon times the shortfall of the arm's
/// fastest escape along the pair's normal (joint velocity limits) below ISO 13855's
/// 2.0 m/s, and it shifts the pair's barrier by that much.
#[test]
fn escape_margin_grows_where_the_arm_cannot_outrun_a_hand() {
    let robot = iiwa();
    let horizon = 0.2;
    let config = FilterConfig {
        escape_horizon_s: horizon,
        ..FilterConfig::default()
    };
    let mut filter =
        SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config.clone()).expect("filter");
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let human = forearm(
        Vector::new(0.8, -0.3, 0.6),
        Vector::new(0.8, 0.3, 0.6),
        Vector::ZERO,
    );
    filter.tick(&robot, &q, &[0.0; 7], &human, 0.004);
    let limits: Vec<f64> = robot
        .actuated_joints()
        .iter()
        .map(|&j| robot.joints()[j].limits.velocity)
        .collect();
    let mut with_margin = 0;
    for c in filter.pairs().iter().filter(|c| !c.obstacle) {
        let escape: f64 = c
            .normal_jacobian
            .iter()
            .zip(&limits)
            .map(|(a, v)| a.abs() * v)
            .sum();
        let expected = horizon * (2.0 - escape).max(0.0);
        assert_abs_diff_eq!(c.escape_margin_m, expected, epsilon = 1e-12);
        let without = PairConstraint {
            escape_margin_m: 0.0,
            ..*c
        };
        let (g, d) = (config.gamma_per_s, config.d_min_m);
        let barrier = g * (c.pair.distance_m - d) - c.human_normal_speed_m_s;
        if barrier < c.max_approach_m_s {
            // The cap does not bind: the margin shifts the barrier by gamma times itself.
            assert_abs_diff_eq!(
                without.approach_bound_m_s(g, d) - c.approach_bound_m_s(g, d),
                g * expected,
                epsilon = 1e-12
            );
        }
        with_margin += usize::from(expected > 0.0 && barrier < c.max_approach_m_s);
    }
    assert!(with_margin > 0, "some pair near the base has a slow escape");
}

/// The anticipated copies of a moving part: evenly spaced along its end points' velocities
/// up to the horizon, the last exactly where the part is after it, spaced at most its radius
/// apart; none for a resting part or a part slower than a tenth of its radius per horizon;
/// at most eight.
#[test]
fn anticipation_carries_moving_parts_along_their_velocities() {
    let (a, b) = (Vector::new(1.0, -0.3, 0.6), Vector::new(1.0, 0.3, 0.6));
    let (v_a, v_b) = (Vector::new(-1.5, 0.0, 0.0), Vector::new(-1.5, 0.0, 0.6));
    let mut human = forearm(a, b, Vector::ZERO);
    human.parts[0].v_a_W = v_a;
    human.parts[0].v_b_W = v_b;
    // A resting hand beside it gets no copies.
    human.parts.push(PartEstimate {
        part: HumanPart::Hand,
        capsule: Capsule::new(b, b + Vector::Y * 0.1, 0.045),
        v_a_W: Vector::ZERO,
        v_b_W: Vector::ZERO,
    });
    let mut ahead = Vec::new();
    let horizon = 0.15;
    human.anticipate_into(horizon, &mut ahead);
    // The faster end travels |(-1.5, 0, 0.6)| 0.15 = 0.2423 m: ceil(0.2423 / 0.04) = 7 copies.
    assert_eq!(ahead.len(), 7);
    for (k, copy) in ahead.iter().enumerate() {
        let tau = horizon * (k + 1) as f64 / 7.0;
        let p = copy.estimate;
        assert_eq!(copy.of, 0);
        assert_abs_diff_eq!(
            (p.capsule.a_W - (a + v_a * tau)).length(),
            0.0,
            epsilon = 1e-12
        );
        assert_abs_diff_eq!(
            (p.capsule.b_W - (b + v_b * tau)).length(),
            0.0,
            epsilon = 1e-12
        );
        assert_eq!((p.part, p.v_a_W, p.v_b_W), (HumanPart::Forearm, v_a, v_b));
        assert_eq!(p.capsule.radius_m, 0.04);
    }
    let last = ahead[6].estimate.capsule;
    assert_abs_diff_eq!(
        (last.b_W - (b + v_b * horizon)).length(),
        0.0,
        epsilon = 1e-12
    );
    let mut previous = human.parts[0].capsule.b_W;
    for copy in &ahead {
        let step = (copy.estimate.capsule.b_W - previous).length();
        assert!(step <= 0.04 + 1e-12, "copies {step} m apart");
        previous = copy.estimate.capsule.b_W;
    }

    // A forearm that moves 3.75 mm over the horizon (under a tenth of its radius): none.
    forearm(a, b, Vector::new(-0.025, 0.0, 0.0)).anticipate_into(horizon, &mut ahead);
    assert!(ahead.is_empty());
    // A forearm at 2 m/s over a whole second: eight copies, the last where it is after it.
    let fast = forearm(a, b, Vector::new(-2.0, 0.0, 0.0));
    fast.anticipate_into(1.0, &mut ahead);
    assert_eq!(ahead.len(), 8);
    assert_abs_diff_eq!(ahead[7].estimate.capsule.a_W.x, a.x - 2.0, epsilon = 1e-12);
    // Off.
    fast.anticipate_into(0.0, &mut ahead);
    assert!(ahead.is_empty());
}

/// Per link and part, the anticipated copy closest to the link gets the rows, unless the
/// path has carried it past the link: its normal would then push the link back toward the
/// part where it is. A forearm 0.3 m beside the last link, coming at it at 2 m/s, 0.3 s
/// ahead: the copies on the far side are closer to the link than any before it (one
/// overlaps it), and the link's anticipated rows are those of the last copy before it.
#[test]
fn the_closest_anticipated_copy_before_a_link_gets_its_rows() {
    let robot = iiwa();
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let mut kinematics = KinematicState::new(&robot);
    robot.forward_kinematics(&q, &mut kinematics).expect("fk");
    let mut geometry = workcell_safety::RobotGeometry::new(&robot).expect("geometry");
    let link = robot.link_id("link7").expect("link7");
    let (_, capsule) = geometry
        .capsules(&kinematics)
        .find(|(l, _)| *l == link)
        .expect("link 7 has a capsule");
    let v = Vector::new(-2.0, 0.0, 0.0);
    let centre = capsule.axis_point(0.5) + Vector::new(0.3, 0.0, 0.0);
    let human = forearm(centre - Vector::Y * 0.15, centre + Vector::Y * 0.15, v);
    let mut ahead = Vec::new();
    human.anticipate_into(0.3, &mut ahead);
    // Eight copies 0.075 m apart: 0.225 m beside the link's axis down to 0.3 m past it.
    assert_eq!(ahead.len(), 8);
    let (mut now, mut with_ahead) = (Vec::new(), Vec::new());
    geometry.pair_constraints(&robot, &kinematics, &human, 10.0, &mut now);
    geometry.pair_constraints_ahead(&robot, &kinematics, &human, &ahead, 10.0, &mut with_ahead);
    let present_rows: Vec<PairConstraint> = with_ahead
        .iter()
        .filter(|c| !c.anticipated)
        .copied()
        .collect();
    assert_eq!(present_rows, now);
    let present = now
        .iter()
        .find(|c| c.pair.link == link)
        .expect("link 7 sees the forearm")
        .pair;
    assert!(present.nhat_BA_W.x < -0.5, "{present:?}");
    let rows: Vec<&PairConstraint> = with_ahead
        .iter()
        .filter(|c| c.anticipated && c.pair.link == link)
        .collect();
    assert!(!rows.is_empty());
    // The same copies against the link's capsule directly.
    let pairs: Vec<SignedDistancePair> = ahead
        .iter()
        .map(|c| capsule_capsule(link, &capsule, c.estimate.part, &c.estimate.capsule))
        .collect();
    let before: Vec<&SignedDistancePair> = pairs
        .iter()
        .filter(|p| p.nhat_BA_W.dot(present.nhat_BA_W) >= 0.0)
        .collect();
    assert!(before.len() < pairs.len(), "some copies are past the link");
    let closest_before = before
        .iter()
        .map(|p| p.distance_m)
        .fold(f64::INFINITY, f64::min);
    let closest = pairs
        .iter()
        .map(|p| p.distance_m)
        .fold(f64::INFINITY, f64::min);
    assert!(
        closest < closest_before - 0.05,
        "{closest} vs {closest_before}"
    );
    assert_abs_diff_eq!(rows[0].pair.distance_m, closest_before, epsilon = 1e-12);
    for c in &rows {
        assert!(
            c.pair.nhat_BA_W.dot(present.nhat_BA_W) >= 0.0,
            "{:?}",
            c.pair
        );
    }
}

/// With anticipation the filter meets a forearm coming at the arm where it will be: the
/// smallest distance it reports is the gap to the forearm carried `anticipation_s` along its
/// velocity, and a nominal command that the forearm's present position allows is already
/// changed. Closed loop, a forearm that comes at the reaching arm at 1.5 m/s and stops: the
/// arm starts giving way 0.15 s earlier and keeps 0.358 m where it keeps 0.195 m without.
#[test]
fn anticipation_meets_an_approaching_part_where_it_will_be() {
    let robot = iiwa();
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let v = Vector::new(-1.5, 0.0, 0.0);
    let (a, b) = (Vector::new(1.3, -0.3, 0.6), Vector::new(1.3, 0.3, 0.6));
    let horizon = 0.15;
    let config = |anticipation_s: f64| FilterConfig {
        anticipation_s,
        acceleration_rad_s2: 100.0,
        ..FilterConfig::default()
    };
    let mut plain =
        SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config(0.0)).expect("filter");
    let mut ahead =
        SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config(horizon)).expect("filter");
    let human = forearm(a, b, v);
    // The arm reaches forward (+x), toward the forearm.
    let qdot_nom = [0.0, 0.05, 0.0, 0.05, 0.0, 0.0, 0.0];
    let now = plain.tick(&robot, &q, &qdot_nom, &human, 0.004);
    let later = ahead.tick(&robot, &q, &qdot_nom, &human, 0.004);
    let moved = forearm(a + v * horizon, b + v * horizon, v);
    assert_abs_diff_eq!(
        now.min_distance_m,
        capsule_gap(&plain, &robot, &q, &human),
        epsilon = 1e-9
    );
    assert_abs_diff_eq!(
        later.min_distance_m,
        capsule_gap(&ahead, &robot, &q, &moved),
        epsilon = 1e-9
    );
    assert!(
        later.min_distance_m < now.min_distance_m - 0.2,
        "{later:?} vs {now:?}"
    );
    assert_eq!(now.status, FilterStatus::Pass);
    assert!(
        matches!(later.status, FilterStatus::Modified | FilterStatus::Relaxed),
        "{later:?}"
    );

    let run = |anticipation_s: f64| {
        let mut filter = SafetyFilter::new(
            &robot,
            Pose::IDENTITY,
            FilterMode::Qp,
            config(anticipation_s),
        )
        .expect("filter");
        let dt = 0.001;
        let mut q = q.to_vec();
        let (mut a, mut b) = (a, b);
        let mut min_gap = f64::INFINITY;
        for _ in 0..800 {
            // The forearm stops at 0.75 m from the base axis.
            let moving = a.x > 0.75;
            let told = forearm(a, b, if moving { v } else { Vector::ZERO });
            filter.tick(&robot, &q, &qdot_nom, &told, dt);
            for (qi, w) in q.iter_mut().zip(filter.command()) {
                *qi += w * dt;
            }
            if moving {
                a += v * dt;
                b += v * dt;
            }
            min_gap = min_gap.min(capsule_gap(
                &filter,
                &robot,
                &q,
                &forearm(a, b, Vector::ZERO),
            ));
        }
        min_gap
    };
    let (without, with) = (run(0.0), run(horizon));
    eprintln!("closest gap {without:.4} m without anticipation, {with:.4} m with");
    assert!(with > without + 0.1, "{with} vs {without}");
}

/// What is wrong, q, the nominal command, the human estimate, the expected reason.
type BadInput<'a> = (&'a str, &'a [f64], &'a [f64], HumanEstimate, BrakeReason);

#[test]
fn bad_input_gives_a_finite_braking_command() {
    let robot = iiwa();
    let human = forearm(
        Vector::new(0.8, -0.3, 0.6),
        Vector::new(0.8, 0.3, 0.6),
        Vector::ZERO,
    );
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let nominal = [0.3; 7];
    for mode in [FilterMode::Qp, FilterMode::Ssm] {
        let mut filter = SafetyFilter::new(&robot, Pose::IDENTITY, mode, FilterConfig::default())
            .expect("filter");
        let dt = 0.004;
        // Get moving first so that braking has something to ramp down.
        for _ in 0..20 {
            filter.tick(
                &robot,
                &q,
                &[0.2; 7],
                &forearm(
                    Vector::new(3.0, 0.0, 0.6),
                    Vector::new(3.0, 0.1, 0.6),
                    Vector::ZERO,
                ),
                dt,
            );
        }
        let moving = filter.command().to_vec();
        assert!(moving.iter().all(|v| *v > 0.1), "{mode}: {moving:?}");

        let mut nan_q = q;
        nan_q[3] = f64::NAN;
        let mut nan_human = human.clone();
        nan_human.parts[0].capsule.a_W.y = f64::INFINITY;
        let mut nan_velocity = human.clone();
        nan_velocity.parts[0].v_b_W.z = f64::NAN;
        let mut nan_uncertainty = human.clone();
        nan_uncertainty.uncertainty_m = f64::NAN;
        let cases: [BadInput<'_>; 6] = [
            (
                "NaN joint",
                &nan_q,
                &nominal,
                human.clone(),
                BrakeReason::InvalidRobotInput,
            ),
            (
                "short q",
                &q[..5],
                &nominal,
                human.clone(),
                BrakeReason::InvalidRobotInput,
            ),
            (
                "infinite capsule",
                &q,
                &nominal,
                nan_human,
                BrakeReason::InvalidHumanEstimate,
            ),
            (
                "NaN velocity",
                &q,
                &nominal,
                nan_velocity,
                BrakeReason::InvalidHumanEstimate,
            ),
            (
                "NaN uncertainty",
                &q,
                &nominal,
                nan_uncertainty,
                BrakeReason::InvalidHumanEstimate,
            ),
            (
                "empty estimate",
                &q,
                &nominal,
                HumanEstimate::default(),
                BrakeReason::NoHumanEstimate,
            ),
        ];
        for (what, q, nominal, human, reason) in cases {
            let before = filter.command().to_vec();
            let out = filter.tick(&robot, q, nominal, &human, dt);
            assert_eq!(out.status, FilterStatus::Braking(reason), "{mode}, {what}");
            for (v, v0) in filter.command().iter().zip(&before) {
                assert!(v.is_finite(), "{mode}, {what}");
                // Toward zero, never past it, by at most the acceleration bound.
                assert!(
                    v.abs() <= v0.abs() + 1e-12 && v * v0 >= 0.0,
                    "{mode}, {what}: {v0} -> {v}"
                );
                assert!(
                    (v - v0).abs() <= 8.0 * dt + 1e-12,
                    "{mode}, {what}: {v0} -> {v}"
                );
            }
        }
        // A NaN nominal command and a NaN time step.
        let mut nan_nominal = nominal;
        nan_nominal[0] = f64::NAN;
        let out = filter.tick(&robot, &q, &nan_nominal, &human, dt);
        assert_eq!(
            out.status,
            FilterStatus::Braking(BrakeReason::InvalidRobotInput)
        );
        let out = filter.tick(&robot, &q, &nominal, &human, f64::NAN);
        assert_eq!(
            out.status,
            FilterStatus::Braking(BrakeReason::InvalidRobotInput)
        );
        assert!(
            filter.command().iter().all(|v| *v == 0.0),
            "no time step: stop"
        );
    }
}

/// d_min larger than the whole cell: every row demands far more than the joints can give.
/// The QP filter says so and brakes; nothing is NaN.
#[test]
fn an_impossible_separation_brakes_and_says_why() {
    let robot = iiwa();
    let config = FilterConfig {
        d_min_m: 50.0,
        detection_m: 100.0,
        ..FilterConfig::default()
    };
    let mut filter =
        SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config).expect("filter");
    let human = forearm(
        Vector::new(0.8, -0.3, 0.6),
        Vector::new(0.8, 0.3, 0.6),
        Vector::ZERO,
    );
    let out = filter.tick(
        &robot,
        &[0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0],
        &[0.1; 7],
        &human,
        0.004,
    );
    assert_eq!(out.status, FilterStatus::Braking(BrakeReason::Infeasible));
    assert!(
        out.slack_m_s > 100.0,
        "50 m short at gamma 4/s: {}",
        out.slack_m_s
    );
    assert!(filter.command().iter().all(|v| v.is_finite()));
}

#[test]
fn invalid_configurations_are_refused_with_the_key() {
    let robot = iiwa();
    for (config, key) in [
        (
            FilterConfig {
                d_min_m: -0.1,
                ..FilterConfig::default()
            },
            "safety.d_min_m",
        ),
        (
            FilterConfig {
                gamma_per_s: f64::NAN,
                ..FilterConfig::default()
            },
            "safety.gamma_per_s",
        ),
        (
            FilterConfig {
                max_pairs: 0,
                ..FilterConfig::default()
            },
            "safety.max_pairs",
        ),
        (
            FilterConfig {
                obstacle_gamma_per_s: 0.0,
                ..FilterConfig::default()
            },
            "safety.obstacle_gamma_per_s",
        ),
        (
            FilterConfig {
                anticipation_s: -0.1,
                ..FilterConfig::default()
            },
            "safety.anticipation_s",
        ),
        // Each key alone is in range, together they contradict: pairs would enter the filter
        // only inside d_min (this passed and gave violations).
        (
            FilterConfig {
                detection_m: 0.01,
                d_min_m: 0.1,
                ..FilterConfig::default()
            },
            "safety.detection_m",
        ),
        // 0.3 m beyond d_min at gamma 4/s allows 1.2 m/s, below ISO 13855's 2.0 m/s.
        (
            FilterConfig {
                detection_m: 0.4,
                ..FilterConfig::default()
            },
            "2 / gamma = 0.500 m",
        ),
        (
            FilterConfig {
                ssm: SsmConfig {
                    braking_m_s2: 0.0,
                    ..SsmConfig::default()
                },
                ..FilterConfig::default()
            },
            "ssm.braking_m_s2",
        ),
    ] {
        let err = SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config).unwrap_err();
        assert!(err.to_string().contains(key), "{err}");
    }
}

#[test]
fn protective_separation_round_trips_through_the_speed_limit() {
    let ssm = SsmConfig::default();
    for z_d in [0.0, 0.02, 0.1] {
        for d in [0.3, 0.5, 1.0, 2.0] {
            let v = ssm.max_robot_speed_m_s(d, z_d);
            assert!(v > 0.0);
            assert_abs_diff_eq!(ssm.protective_separation_m(v, z_d), d, epsilon = 1e-12);
        }
    }
    // At the standstill distance v_h T_r + C + Z_d + Z_r the robot must stand.
    let standstill = 1.6 * 0.1 + 0.0 + 0.02 + 0.005;
    assert_eq!(ssm.max_robot_speed_m_s(standstill, 0.02), 0.0);
    assert!(ssm.max_robot_speed_m_s(standstill + 1e-3, 0.02) > 0.0);
    assert_eq!(ssm.max_robot_speed_m_s(f64::NAN, 0.0), 0.0);
    // Hand-computed anchor (v_h 1.6 m/s, T_r 0.1 s, a 5 m/s^2, C = Z = 0, D = 1 m):
    // v = -(0.5 + 1.6) + sqrt(0.25 + 2.56 + 10) = 1.479109 m/s.
    let bare = SsmConfig {
        robot_uncertainty_m: 0.0,
        ..SsmConfig::default()
    };
    assert_abs_diff_eq!(
        bare.max_robot_speed_m_s(1.0, 0.0),
        12.81f64.sqrt() - 2.1,
        epsilon = 1e-12
    );
}

#[test]
fn pfl_contact_speeds_follow_annex_a() {
    // Forearm, robot effective mass 30/2 + 0 kg: mu = 1 / (1/2 + 1/15) = 1.764706 kg,
    // v = 160 / sqrt(1.764706 * 40000) = 0.602218 m/s (hand computation).
    let m_r = effective_robot_mass_kg(30.0, 0.0);
    let forearm = BodyRegion::of(HumanPart::Forearm);
    assert_abs_diff_eq!(
        forearm.max_contact_speed_m_s(m_r, false),
        0.602_218,
        epsilon = 1e-6
    );
    assert_abs_diff_eq!(
        forearm.max_contact_speed_m_s(m_r, true),
        2.0 * 0.602_218,
        epsilon = 2e-6
    );
    // Hand: mu = 1 / (1/0.6 + 1/15) = 0.576923 kg, v = 140 / sqrt(0.576923 * 75000) = 0.673036.
    let hand = BodyRegion::of(HumanPart::Hand).max_contact_speed_m_s(m_r, false);
    assert_abs_diff_eq!(hand, 0.673_036, epsilon = 1e-6);
    // Upper arm: mu = 1 / (1/3 + 1/15) = 2.5 kg, v = 150 / sqrt(2.5 * 30000) = 0.547723.
    let upper = BodyRegion::of(HumanPart::UpperArm).max_contact_speed_m_s(m_r, false);
    assert_abs_diff_eq!(upper, 0.547_723, epsilon = 1e-6);
    // A heavier robot must hit more slowly.
    assert!(forearm.max_contact_speed_m_s(40.0, false) < forearm.max_contact_speed_m_s(m_r, false));
}

/// SSM scales the command: the closer the human, the slower the approach, stopping at the
/// protective distance.
#[test]
fn ssm_slows_the_approach_as_the_human_gets_closer() {
    let robot = iiwa();
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let nominal = [0.0, 0.4, 0.0, 0.3, 0.0, 0.0, 0.0];
    let mut scales = Vec::new();
    for x in [1.6, 1.3, 1.1, 0.95] {
        let mut filter = SafetyFilter::new(
            &robot,
            Pose::IDENTITY,
            FilterMode::Ssm,
            FilterConfig::default(),
        )
        .expect("filter");
        // Start from the nominal speed so that the acceleration bound does not decide.
        for _ in 0..200 {
            filter.tick(
                &robot,
                &q,
                &nominal,
                &forearm(
                    Vector::new(9.0, 0.0, 0.6),
                    Vector::new(9.0, 0.1, 0.6),
                    Vector::ZERO,
                ),
                0.004,
            );
        }
        let out = filter.tick(
            &robot,
            &q,
            &nominal,
            &forearm(
                Vector::new(x, -0.3, 0.6),
                Vector::new(x, 0.3, 0.6),
                Vector::ZERO,
            ),
            0.004,
        );
        scales.push((x, out.scale, out.status));
    }
    for w in scales.windows(2) {
        assert!(w[1].1 <= w[0].1, "{scales:?}");
    }
    assert!(scales[0].1 > scales[scales.len() - 1].1, "{scales:?}");
    assert!(
        matches!(
            scales[scales.len() - 1].2,
            FilterStatus::Braking(BrakeReason::ProtectiveStop) | FilterStatus::Modified
        ),
        "{scales:?}"
    );
}

/// With `bound_acceleration`, the command changes by at most the acceleration limit per tick,
/// even when a human appears close by and the barrier wants a fast retreat.
#[test]
fn bounded_acceleration_limits_the_change_per_tick() {
    let robot = iiwa();
    let config = FilterConfig {
        bound_acceleration: true,
        acceleration_rad_s2: 5.0,
        ..FilterConfig::default()
    };
    let mut filter =
        SafetyFilter::new(&robot, Pose::IDENTITY, FilterMode::Qp, config).expect("filter");
    let q = [0.0, 0.5, 0.0, -1.2, 0.0, 0.8, 0.0];
    let nominal = [0.0, 0.4, 0.0, 0.3, 0.0, 0.0, 0.0];
    let dt = 0.004;
    let far = forearm(
        Vector::new(5.0, -0.3, 0.6),
        Vector::new(5.0, 0.3, 0.6),
        Vector::ZERO,
    );
    let near = forearm(
        Vector::new(0.75, -0.3, 0.6),
        Vector::new(0.75, 0.3, 0.6),
        Vector::new(-1.0, 0.0, 0.0),
    );
    let mut previous = filter.command().to_vec();
    let mut changed = false;
    for k in 0..200 {
        let human = if k < 100 { &far } else { &near };
        let out = filter.tick(&robot, &q, &nominal, human, dt);
        for (v, v0) in filter.command().iter().zip(&previous) {
            assert!(
                (v - v0).abs() <= 5.0 * dt + 1e-6,
                "tick {k} ({:?}): {v0} -> {v}",
                out.status
            );
        }
        changed |= k >= 100 && out.status != FilterStatus::Pass;
        previous = filter.command().to_vec();
    }
    assert!(changed, "the near human changed the command");
}
