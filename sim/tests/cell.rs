//! The simulated cell: rapier's robot matches our kinematics, motors track commands within
//! limits, the human follows its motion, and a seed fixes an episode bit for bit.

use std::path::{Path, PathBuf};

use approx::assert_relative_eq;
use workcell_robots::collision::link_collision_shape;
use workcell_sim::render::Renderer as _;
use workcell_sim::scenario::{HumanMotionKind, RobotMotionConfig};
use workcell_sim::{CellModel, CellState, RobotCommand, Scenario, SimError, step};

fn default_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/default.toml")
}

fn default_model() -> CellModel {
    CellModel::from_file(default_path()).expect("default cell")
}

/// Largest distance between rapier's link positions and our forward kinematics.
fn fk_mismatch(model: &CellModel, state: &CellState) -> f64 {
    let fk = model.robot.fk(model.X_WR, state.q()).expect("fk");
    state
        .robot_link_poses()
        .iter()
        .enumerate()
        .map(|(l, p)| (p.translation - fk.link_pose(l).translation).length())
        .fold(0.0, f64::max)
}

#[test]
fn rapier_links_match_forward_kinematics() {
    let model = default_model();
    let mut state = CellState::new(&model).expect("state");
    for (a, b) in state.q().iter().zip(&model.initial_q) {
        assert_relative_eq!(*a, *b, epsilon = 1e-9);
    }
    assert!(
        fk_mismatch(&model, &state) < 1e-9,
        "at t=0: {}",
        fk_mismatch(&model, &state)
    );
    for _ in 0..500 {
        step(&model, &mut state, &RobotCommand::Nominal).expect("step");
    }
    // Multibody coordinates and body poses agree while moving.
    assert!(
        fk_mismatch(&model, &state) < 1e-6,
        "moving: {}",
        fk_mismatch(&model, &state)
    );
}

/// Largest joint error after a 1.2 rad jump and two seconds of holding, checking on every
/// step that no joint exceeds its velocity limit.
fn settle_error(gravity_compensation: bool) -> f64 {
    let mut scenario = Scenario::from_file(default_path()).expect("scenario");
    scenario.robot.motion = RobotMotionConfig::Hold;
    scenario.robot.gravity_compensation = gravity_compensation;
    let model = CellModel::new(&scenario, &default_path()).expect("model");
    let mut state = CellState::new(&model).expect("state");
    // A jump of up to 1.2 rad: the servo reference ramps within the velocity limit.
    let target = [1.2, 0.8, -0.2, -1.2, 0.3, 0.6, 0.5];
    let zero = [0.0; 7];
    let velocity = model.robot.velocity_limits();
    for _ in 0..2000 {
        let command = RobotCommand::Position {
            q: &target,
            qd: &zero,
        };
        step(&model, &mut state, &command).expect("step");
        for (qd, v) in state.qd().iter().zip(&velocity) {
            assert!(
                qd.abs() <= 1.05 * v,
                "{qd} rad/s beyond the {v} rad/s limit"
            );
        }
    }
    for qd in state.qd() {
        assert!(qd.abs() < 1e-2, "still moving: {qd}");
    }
    state
        .q()
        .iter()
        .zip(&target)
        .map(|(q, t)| (q - t).abs())
        .fold(0.0, f64::max)
}

#[test]
fn position_control_settles_on_the_target_under_gravity() {
    // With the controller carrying the weight, the servo lands on the target.
    let compensated = settle_error(true);
    assert!(compensated < 1e-4, "compensated error {compensated}");
    // Without, the servo stiffness leaves a sag of about g_joint / stiffness: mrad, not more.
    let sagging = settle_error(false);
    assert!(
        sagging > 1e-4 && sagging < 5e-3,
        "uncompensated error {sagging}"
    );
}

#[test]
fn nominal_motion_is_tracked_and_stays_in_limits() {
    let model = default_model();
    let mut state = CellState::new(&model).expect("state");
    let limits = model.robot.position_limits();
    let velocity = model.robot.velocity_limits();
    let (mut q, mut qd, mut qdd) = (vec![0.0; 7], vec![0.0; 7], vec![0.0; 7]);
    let mut worst = 0.0_f64;
    for _ in 0..3000 {
        step(&model, &mut state, &RobotCommand::Nominal).expect("step");
        model
            .robot_motion
            .sample(state.time_s(), &mut q, &mut qd, &mut qdd);
        for i in 0..7 {
            worst = worst.max((state.q()[i] - q[i]).abs());
            assert!(state.q()[i] >= limits[i][0] - 1e-3 && state.q()[i] <= limits[i][1] + 1e-3);
            assert!(
                state.qd()[i].abs() <= velocity[i] * 1.05,
                "joint {i} at {} rad/s",
                state.qd()[i]
            );
        }
    }
    // Measured 2.8 mrad at half the speed limits (rapier 0.36, default gains).
    assert!(worst < 5e-3, "tracking error {worst} rad");
}

#[test]
fn velocity_commands_stop_at_position_limits() {
    let mut scenario = Scenario::from_file(default_path()).expect("scenario");
    scenario.robot.motion = RobotMotionConfig::Hold;
    let model = CellModel::new(&scenario, &default_path()).expect("model");
    let mut state = CellState::new(&model).expect("state");
    // Turn joint 7 (range +-175 deg) at 10 rad/s, beyond its 2.36 rad/s limit, for 3 s.
    let qd = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0];
    let mut fastest = 0.0_f64;
    for _ in 0..3000 {
        step(&model, &mut state, &RobotCommand::Velocity { qd: &qd }).expect("step");
        fastest = fastest.max(state.qd()[6].abs());
    }
    let upper = model.robot.position_limits()[6][1];
    assert!(
        state.q()[6] <= upper + 1e-3,
        "{} beyond {upper}",
        state.q()[6]
    );
    assert!(
        state.q()[6] > upper - 0.01,
        "did not reach the limit: {}",
        state.q()[6]
    );
    assert!(
        fastest <= model.robot.velocity_limits()[6] * 1.05,
        "{fastest}"
    );
}

#[test]
fn human_links_follow_the_motion() {
    let model = default_model();
    let mut state = CellState::new(&model).expect("state");
    let dof = model.human.dof();
    let (mut q, mut qd) = (vec![0.0; dof], vec![0.0; dof]);
    for _ in 0..1500 {
        step(&model, &mut state, &RobotCommand::Nominal).expect("step");
    }
    model.human_motion.sample(state.time_s(), &mut q, &mut qd);
    assert_eq!(state.human_q(), q.as_slice());
    let fk = model.human.fk(model.X_WH, &q).expect("fk");
    let forearm = model.human.link_id("forearm").expect("forearm");
    assert_eq!(state.human_link_poses()[forearm], *fk.link_pose(forearm));
    // The kinematic body in rapier is where the motion says.
    let body_pose = state
        .world()
        .bodies
        .iter()
        .filter(|(_, b)| b.is_kinematic())
        .map(|(_, b)| *b.position())
        .find(|p| (p.translation - fk.link_pose(forearm).translation).length() < 1e-9);
    assert!(body_pose.is_some(), "no kinematic body at the forearm pose");
}

/// Every robot and human pose of `steps` steps, as bits.
fn trace(seed: u64, steps: usize) -> Vec<u64> {
    let mut scenario = Scenario::from_file(default_path()).expect("scenario");
    scenario.seed = seed;
    let model = CellModel::new(&scenario, &default_path()).expect("model");
    let mut state = CellState::new(&model).expect("state");
    let mut bits = Vec::new();
    for _ in 0..steps {
        step(&model, &mut state, &RobotCommand::Nominal).expect("step");
    }
    for p in state
        .robot_link_poses()
        .iter()
        .chain(state.human_link_poses())
    {
        bits.extend(p.translation.to_array().map(f64::to_bits));
        bits.extend(p.rotation.to_array().map(f64::to_bits));
    }
    bits.extend(state.qd().iter().map(|v| v.to_bits()));
    bits
}

#[test]
fn same_seed_gives_bit_identical_states() {
    assert_eq!(trace(11, 1500), trace(11, 1500));
    assert_ne!(trace(11, 1500), trace(12, 1500));
}

#[test]
fn bad_commands_are_errors() {
    let model = default_model();
    let mut state = CellState::new(&model).expect("state");
    let short = [0.0; 3];
    let err = step(&model, &mut state, &RobotCommand::Velocity { qd: &short }).expect_err("short");
    assert!(matches!(err, SimError::InvalidCommand { .. }));
    let nan = [f64::NAN; 7];
    assert!(
        step(
            &model,
            &mut state,
            &RobotCommand::Position { q: &nan, qd: &nan }
        )
        .is_err()
    );
}

#[test]
fn pick_and_place_visits_its_waypoints() {
    let mut scenario = Scenario::from_file(default_path()).expect("scenario");
    let waypoints = vec![
        [0.5, -0.3, 1.0],
        [0.5, -0.3, 0.9],
        [0.4, 0.35, 1.0],
        [0.4, 0.35, 0.9],
    ];
    scenario.robot.motion = RobotMotionConfig::PickAndPlace {
        waypoints: waypoints.clone(),
        dwell_s: 0.2,
        speed_scale: 0.5,
        acceleration_rad_s2: 4.0,
    };
    let model = CellModel::new(&scenario, &default_path()).expect("model");
    // At the middle of each dwell the planned tool pose is the waypoint.
    let (mut q, mut qd, mut qdd) = (vec![0.0; 7], vec![0.0; 7], vec![0.0; 7]);
    let mut visited = 0;
    let n = 4000;
    for k in 0..n {
        let t = model.robot_motion.period_s() * k as f64 / n as f64;
        model.robot_motion.sample(t, &mut q, &mut qd, &mut qdd);
        let tool = model
            .robot
            .fk(model.X_WR, &q)
            .expect("fk")
            .link_pose(model.tool_link)
            .translation;
        if qd.iter().all(|v| *v == 0.0) {
            let near = waypoints.iter().any(|w| {
                (tool
                    .to_array()
                    .iter()
                    .zip(w)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>())
                .sqrt()
                    < 2e-4
            });
            assert!(near, "resting at {tool:?}, not at a waypoint");
            visited += 1;
        }
    }
    assert!(visited > 0);
    // An unreachable waypoint is a typed error naming it.
    scenario.robot.motion = RobotMotionConfig::PickAndPlace {
        waypoints: vec![[0.5, 0.0, 1.0], [3.0, 0.0, 1.0]],
        dwell_s: 0.2,
        speed_scale: 0.5,
        acceleration_rad_s2: 4.0,
    };
    match CellModel::new(&scenario, &default_path()) {
        Err(SimError::Unreachable { key, .. }) => assert_eq!(key, "robot.motion.waypoints[1]"),
        other => panic!("expected Unreachable, got {other:?}"),
    }
}

#[test]
fn scenario_errors_name_the_key() {
    let path = Path::new("bad.toml");
    let unknown =
        Scenario::from_toml("seed = 1\n[robot]\nmodle = \"x\"\n", path).expect_err("unknown key");
    assert!(unknown.to_string().contains("modle"), "{unknown}");
    let dt = Scenario::from_toml("time_step_s = -1.0\n", path).expect_err("negative dt");
    assert!(
        matches!(dt, SimError::Invalid { ref key, .. } if key == "time_step_s"),
        "{dt}"
    );
    let size = Scenario::from_toml(
        "[[clutter]]\nkind = \"box\"\nsize_m = [1.0, -1.0, 1.0]\n",
        path,
    )
    .expect_err("size");
    assert!(
        matches!(size, SimError::Invalid { ref key, .. } if key == "clutter[0].size_m"),
        "{size}"
    );
    // validate() sees no file: the key and the message; the loader adds the file's name.
    let bad = Scenario {
        time_step_s: -1.0,
        ..Scenario::default()
    };
    let err = bad.validate().expect_err("negative dt");
    assert!(err.to_string().starts_with("time_step_s: "), "{err}");
    let err = err.in_file(path);
    assert!(
        err.to_string().starts_with("bad.toml: time_step_s: "),
        "{err}"
    );
    let kind = Scenario::from_toml("[human]\nmotions = [\"dance\"]\n", path).expect_err("kind");
    assert!(kind.to_string().contains("dance"), "{kind}");
    let q = Scenario::from_toml("[robot]\ninitial_q = [0.0, 1.0]\n", path).expect("parses");
    let err = CellModel::new(&q, path).expect_err("wrong length");
    assert!(
        matches!(err, SimError::Invalid { ref key, .. } if key == "robot.initial_q"),
        "{err}"
    );
    let missing =
        Scenario::from_toml("[robot]\nmodel = \"nowhere/robot.urdf\"\n", path).expect("parses");
    assert!(matches!(
        CellModel::new(&missing, path),
        Err(SimError::Robot { .. })
    ));
}

#[test]
fn defaults_round_trip_through_toml() {
    let scenario = Scenario::from_file(default_path()).expect("scenario");
    let again =
        Scenario::from_toml(&scenario.to_toml(), Path::new("again.toml")).expect("round trip");
    assert_eq!(scenario, again);
    assert_eq!(Scenario::default().human.motions[1], HumanMotionKind::Reach);
}

#[test]
fn mimic_prismatic_and_continuous_joints_in_rapier() {
    // The gripper fixture: a prismatic lift, a continuous wrist, and a finger that mimics
    // another with multiplier -1. Rapier must move the mimic finger as forward kinematics says.
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../robots/tests/fixtures/pkg/my_robot/urdf/gripper.urdf");
    let mut scenario = Scenario::default();
    scenario.robot.model = fixture.to_string_lossy().into_owned();
    scenario.robot.tool_link = "tip".into();
    scenario.robot.initial_q = vec![0.1, 0.0, 0.0];
    scenario.robot.motion = RobotMotionConfig::Hold;
    let model = CellModel::new(&scenario, Path::new("inline.toml")).expect("model");
    let mut state = CellState::new(&model).expect("state");
    let target = [0.3, 1.0, 0.03];
    for _ in 0..1500 {
        step(
            &model,
            &mut state,
            &RobotCommand::Position {
                q: &target,
                qd: &[0.0; 3],
            },
        )
        .expect("step");
    }
    for (q, t) in state.q().iter().zip(&target) {
        assert!((q - t).abs() < 2e-3, "q {q} target {t}");
    }
    assert!(
        fk_mismatch(&model, &state) < 1e-4,
        "mimic not honoured: {}",
        fk_mismatch(&model, &state)
    );
    let report = workcell_sim::check_in_rapier(&model.robot, &[0.2, 0.5, 0.02]).expect("check");
    assert_eq!(report.multibody_dofs, 4, "lift, wrist and both fingers");
    assert!(report.fk_mismatch_m < 1e-9);
}

#[test]
fn random_motion_stays_above_the_table_and_within_limits() {
    let model = default_model();
    let min_height = match model.scenario.robot.motion {
        RobotMotionConfig::Random { min_height_m, .. } => min_height_m,
        ref other => panic!("default motion is random, got {other:?}"),
    };
    let limits = model.robot.position_limits();
    let velocity = model.robot.velocity_limits();
    let (mut q, mut qd, mut qdd) = (vec![0.0; 7], vec![0.0; 7], vec![0.0; 7]);
    let n = 20_000;
    for k in 0..n {
        let t = model.robot_motion.period_s() * k as f64 / n as f64;
        model.robot_motion.sample(t, &mut q, &mut qd, &mut qdd);
        for i in 0..7 {
            assert!(q[i] >= limits[i][0] && q[i] <= limits[i][1]);
            // speed_scale = 0.5 in the default cell
            assert!(qd[i].abs() <= 0.5 * velocity[i] * (1.0 + 1e-9));
            assert!(qdd[i].abs() <= 4.0 * (1.0 + 1e-9));
        }
        let fk = model.robot.fk(model.X_WR, &q).expect("fk");
        // No link touches the clutter (the planner keeps 3 cm at nine points per move; between
        // them the gap may shrink a little, never to contact).
        if k % 10 == 0 {
            for l in 2..model.robot.links().len() {
                let Some(shape) = link_collision_shape(&model.robot, l) else {
                    continue;
                };
                for c in &model.clutter {
                    let [hx, hy, hz] = c.half_extents_m;
                    let cuboid =
                        parry3d_f64::shape::Cuboid::new(parry3d_f64::math::Vector::new(hx, hy, hz));
                    let d = parry3d_f64::query::distance(
                        fk.link_pose(l),
                        shape.as_ref(),
                        &c.X_WC,
                        &cuboid,
                    )
                    .expect("distance")
                    .distance;
                    assert!(d > 0.0, "link {l} touches clutter at t {t}");
                }
            }
        }
        let tool = fk.link_pose(model.tool_link).translation.z;
        assert!(tool >= min_height - 1e-9, "tool at {tool} m at t {t}");
        // Joints 2.. sit above the base: their origins move with q and must stay up too.
        for &j in &model.robot.actuated_joints()[2..] {
            let z = fk.link_pose(model.robot.joints()[j].child).translation.z;
            assert!(
                z >= min_height - 1e-9,
                "link of joint {j} at {z} m at t {t}"
            );
        }
    }
}

#[test]
fn corrupted_scenarios_are_errors_not_panics() {
    let text = std::fs::read_to_string(default_path()).expect("scenario");
    for (i, c) in text.char_indices().step_by(3) {
        for replacement in ["\"", "[", "-", "9", "x"] {
            let mut broken = text.clone();
            broken.replace_range(i..i + c.len_utf8(), replacement);
            if let Ok(scenario) = Scenario::from_toml(&broken, Path::new("broken.toml")) {
                // What parses and validates must also build (or fail with an error).
                let _ = CellModel::new(&scenario, &default_path());
            }
        }
    }
}

/// The cell's scene through the renderer crate (workcell-render knows no cells).
#[test]
fn the_default_cell_renders_every_class_it_shows_at_any_supported_size() {
    let model = workcell_sim::CellModel::from_file(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/default.toml"
    ))
    .unwrap();
    let cell = workcell_sim::CellScene::new(&model);
    let base = model.scenario.cameras[0].camera().unwrap();
    let mut frame = workcell_sim::render::Frame::new();
    for (w, h) in [(64, 64), (128, 128), (320, 240), (640, 480)] {
        let cam = base.resized(w, h).unwrap();
        workcell_sim::render::CpuRenderer::new()
            .render(&cell.scene, &cam, &mut frame)
            .unwrap();
        let classes = frame.classes(&cell.scene);
        for class in [
            workcell_sim::render::Class::Background,
            workcell_sim::render::Class::Robot,
            workcell_sim::render::Class::Torso,
        ] {
            assert!(classes.contains(&(class as u8)), "{class:?} at {w}x{h}");
        }
        assert!(frame.depth_m.iter().all(|d| d.is_finite() && *d >= 0.0));
        // The sky is never black: only the occluder is.
        assert!(frame.rgb.chunks(3).all(|c| c != [0, 0, 0]));
    }
}

/// The whole body's two arms, seen from in front of the default cell's person at the start
/// (over the robot's side of the table): each arm's pixels carry its side's classes and lie
/// around the projection of its own hand, on the side of the image where that arm hangs
/// (the person faces the camera: their left arm is on the image's right).
#[test]
fn the_camera_sees_each_arm_with_its_sides_classes() {
    use workcell_sim::render::Class;
    let model = default_model();
    let state = CellState::new(&model).expect("state");
    let mut cell = workcell_sim::CellScene::new(&model);
    cell.update(&state);
    let cam = workcell_sim::render::Camera::look_at(
        [0.5, -0.15, 1.9],
        [1.35, -0.15, 1.2],
        [0.0, 0.0, 1.0],
        320,
        240,
        60.0,
    )
    .unwrap();
    let mut frame = workcell_sim::render::Frame::new();
    workcell_sim::render::CpuRenderer::new()
        .render(&cell.scene, &cam, &mut frame)
        .unwrap();
    let classes = frame.classes(&cell.scene);
    let hand_px = |link: &str| {
        let l = model.human.link_id(link).expect(link);
        let p_W = state.human_link_poses()[l].translation;
        cam.project(cam.X_WC.inverse_transform_point(p_W))
            .expect("in front")
    };
    let centroid = |class: Class| {
        let (mut sum, mut n) = ([0.0, 0.0], 0.0);
        for (i, _) in classes
            .iter()
            .enumerate()
            .filter(|(_, c)| **c == class as u8)
        {
            sum[0] += (i % 320) as f64 + 0.5;
            sum[1] += (i / 320) as f64 + 0.5;
            n += 1.0;
        }
        assert!(n > 20.0, "{class:?}: {n} pixels");
        [sum[0] / n, sum[1] / n]
    };
    let (right, left) = (centroid(Class::Forearm), centroid(Class::LeftForearm));
    let (right_hand, left_hand) = (hand_px("hand"), hand_px("left_hand"));
    let d = |a: [f64; 2], b: [f64; 2]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    assert!(d(right, right_hand) < d(right, left_hand), "{right:?}");
    assert!(d(left, left_hand) < d(left, right_hand), "{left:?}");
    assert!(left[0] > right[0], "left {left:?}, right {right:?}");
}

/// Settings that asked for hours of work or gigabytes (and hung or aborted) are refused with
/// their key and limit.
#[test]
fn unbounded_scenario_settings_are_refused() {
    let text = std::fs::read_to_string(default_path()).expect("scenario");
    for (from, to, key) in [
        ("boards = 5", "boards = 100000000", "clutter[1].boards"),
        (
            "waypoints = 32",
            "waypoints = 1000000000000",
            "robot.motion.waypoints",
        ),
        ("time_step_s = 0.001", "time_step_s = 1e-300", "time_step_s"),
        // Human peak speeds: a range within (0, 10] m/s.
        (
            "shuffle = true",
            "shuffle = true\npeak_speed_m_s = [2.0, 1.0]",
            "human.peak_speed_m_s",
        ),
        (
            "shuffle = true",
            "shuffle = true\npeak_speed_m_s = [0.0, 1.0]",
            "human.peak_speed_m_s",
        ),
        (
            "shuffle = true",
            "shuffle = true\npeak_speed_m_s = [1.0, 1e9]",
            "human.peak_speed_m_s",
        ),
        // Transition duration factors: a range within (0, 1].
        (
            "shuffle = true",
            "shuffle = true\nduration_scale = [0.0, 1.0]",
            "human.duration_scale",
        ),
        (
            "shuffle = true",
            "shuffle = true\nduration_scale = [0.5, 2.0]",
            "human.duration_scale",
        ),
        (
            "shuffle = true",
            "shuffle = true\nspeeds = \"iso13855\"\nduration_scale = [0.8, 0.5]",
            "human.duration_scale",
        ),
    ] {
        assert!(text.contains(from), "{from}");
        let err = Scenario::from_toml(&text.replacen(from, to, 1), &default_path())
            .expect_err(to)
            .to_string();
        assert!(err.contains(key), "{to}: {err}");
    }
}

/// `[human.recorded]` with the shipped library: seed s plays clip (s - 1) mod n of the
/// chosen ones, so seeds n apart play the same clip and neighbours another; the human's
/// joints move as the clip does and stay within the model's limits.
#[test]
fn recorded_clips_drive_the_human_by_seed() {
    let library = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data/mocap/library.toml");
    let clips = vec![
        "hrc-task-clips/CollaborativeLifting/1".to_string(),
        "human-assembly-data/Task1/Human1/trial1".to_string(),
    ];
    let model = |seed: u64| {
        let mut scenario = Scenario::from_file(default_path()).expect("scenario");
        scenario.seed = seed;
        scenario.human.recorded = Some(workcell_sim::scenario::RecordedConfig {
            library: library.clone(),
            clips: clips.clone(),
            split: workcell_sim::scenario::ClipSplit::Tuning,
            start_s: 0.0,
            end: workcell_sim::human::ClipEnd::Reverse,
            retarget: workcell_sim::retarget::RetargetConfig::default(),
        });
        CellModel::new(&scenario, &default_path()).expect("cell")
    };
    let (one, two, three) = (model(1), model(2), model(3));
    assert_eq!(one.human_motion.clip(), Some(clips[0].as_str()));
    assert_eq!(two.human_motion.clip(), Some(clips[1].as_str()));
    assert_eq!(three.human_motion.clip(), one.human_motion.clip());
    let limits = one.human.position_limits();
    let (mut q, mut qd) = (vec![0.0; one.human.dof()], vec![0.0; one.human.dof()]);
    let mut moved: f64 = 0.0;
    let mut previous = None;
    for k in 0..800 {
        one.human_motion
            .sample(0.01 * f64::from(k), &mut q, &mut qd);
        for (v, [lo, hi]) in q.iter().zip(&limits) {
            assert!(
                *v >= lo - 1e-9 && *v <= hi + 1e-9,
                "{v} outside [{lo}, {hi}]"
            );
        }
        if let Some(p) = previous.replace(q.clone()) {
            moved += q
                .iter()
                .zip(&p)
                .map(|(a, b): (&f64, &f64)| (a - b).abs())
                .sum::<f64>();
        }
    }
    assert!(moved > 0.5, "the arm moved {moved} rad in 8 s");
    // A clip the library lacks is named.
    let mut scenario = Scenario::from_file(default_path()).expect("scenario");
    scenario.human.recorded = Some(workcell_sim::scenario::RecordedConfig {
        library,
        clips: vec!["nowhere/0".into()],
        split: workcell_sim::scenario::ClipSplit::Tuning,
        start_s: 0.0,
        end: workcell_sim::human::ClipEnd::Hold,
        retarget: workcell_sim::retarget::RetargetConfig::default(),
    });
    let Err(err) = CellModel::new(&scenario, &default_path()) else {
        panic!("a clip the library lacks was accepted");
    };
    assert!(
        err.to_string().contains("\"nowhere/0\" is not a clip"),
        "{err}"
    );
}
