//! `workcell evaluate --gltf`: an episode written as animated binary glTF, read back with
//! the gltf crate (an independent reader), shows the simulation's poses at sampled times.

use std::collections::HashMap;
use std::path::Path;

use workcell::evaluate::replay::{
    HUMAN_PREFIX, MARKER_SUFFIX, OTHER_ARM_PARTS, OTHER_ARM_PREFIX, PAIR_NODES, ROBOT_PREFIX,
    ROOT_NODE, episode_glb, pair_class,
};
use workcell::evaluate::{EpisodeMetrics, Evaluation, PerceptionKind, Recording, record_episode};
use workcell::robots::math::{Pose, Rotation, Vector};
use workcell::safety::FilterMode;
use workcell::sim::{CellModel, Scenario};

/// A node's animation, read back: key times and per-key translation, rotation, scale.
#[derive(Default)]
struct Track {
    times: Vec<f32>,
    translation: Vec<[f32; 3]>,
    rotation: Vec<[f32; 4]>,
    scale: Vec<[f32; 3]>,
}

fn pose_of(track: &Track, k: usize) -> Pose {
    let [x, y, z, w] = track.rotation[k].map(f64::from);
    Pose::from_parts(
        Vector::from_array(track.translation[k].map(f64::from)),
        Rotation::from_xyzw(x, y, z, w),
    )
}

/// An episode of the evaluation `file` (relative to the source tree), `task_s` seconds long,
/// seed `seed`, recorded at 30 Hz, with its cell. The noisy camera model: the replay's poses,
/// not perception, are under test.
fn recorded_episode(
    file: &str,
    task_s: u32,
    seed: u64,
    overrides: &[&str],
) -> (Evaluation, EpisodeMetrics, Recording, Scenario, CellModel) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(file);
    let mut all = vec![format!("task_s={task_s}")];
    all.extend(overrides.iter().map(|o| (*o).to_string()));
    let (evaluation, _) =
        Evaluation::from_file_as(&path, Some(PerceptionKind::Noisy), &all).expect("evaluation");
    let (metrics, _, recording) =
        record_episode(&evaluation, FilterMode::Qp, 0, seed, 1.0 / 30.0).expect("episode");
    let mut scenario = evaluation.scenario.clone();
    scenario.seed = seed;
    let model = CellModel::new(&scenario, &evaluation.scenario_path).expect("cell");
    (evaluation, metrics, recording, scenario, model)
}

/// Every animated node's channels, read back by name.
fn tracks_of(bytes: &[u8]) -> HashMap<String, Track> {
    let gltf = gltf::Gltf::from_slice(bytes).expect("a valid glTF");
    let blob = gltf.blob.clone().expect("binary chunk");
    let doc = &gltf.document;
    let mut tracks: HashMap<String, Track> = HashMap::new();
    let animation = doc.animations().next().expect("an animation");
    for channel in animation.channels() {
        let reader = channel.reader(|_| Some(&blob[..]));
        let name = channel
            .target()
            .node()
            .name()
            .unwrap_or_default()
            .to_string();
        let track = tracks.entry(name).or_default();
        track.times = reader.read_inputs().expect("inputs").collect();
        match reader.read_outputs().expect("outputs") {
            gltf::animation::util::ReadOutputs::Translations(t) => track.translation = t.collect(),
            gltf::animation::util::ReadOutputs::Rotations(r) => {
                track.rotation = r.into_f32().collect()
            }
            gltf::animation::util::ReadOutputs::Scales(s) => track.scale = s.collect(),
            gltf::animation::util::ReadOutputs::MorphTargetWeights(_) => panic!("no morphs"),
        }
    }
    tracks
}

/// A recorded clip's other arm beside a one-armed human (`human_arm`) is drawn: each part's
/// node at every key lies on the recorded capsule's segment (its centre, its axis along the
/// segment), with the capsule's length; the generator's episodes have none, and neither has
/// the two-armed `human`, which draws its own left arm.
#[test]
fn a_recorded_clips_other_arm_is_drawn_where_it_was() {
    let (_, _, two_armed, _, _) = recorded_episode("configs/evaluate-recorded.toml", 1, 1, &[]);
    assert!(two_armed.other_arm.iter().all(Vec::is_empty));
    let (_, _, recording, _, model) = recorded_episode(
        "configs/evaluate-recorded.toml",
        2,
        1,
        &["human_model=\"human_arm\""],
    );
    let bytes = episode_glb(&model, &[], &recording, 0.1, "test");
    let tracks = tracks_of(&bytes);
    let samples = recording.t_s.len();
    assert_eq!(recording.other_arm.len(), samples);
    for (p, part) in OTHER_ARM_PARTS.iter().enumerate() {
        let track = &tracks[&format!("{OTHER_ARM_PREFIX}{part}")];
        assert_eq!(track.times.len(), samples);
        for k in 0..samples {
            let capsule = recording.other_arm[k]
                .get(p)
                .expect("the clip has the other arm");
            let pose = pose_of(track, k);
            let centre = (capsule.a_W + capsule.b_W) * 0.5;
            assert!(
                (pose.translation - centre).length() < 1e-5,
                "{part} at key {k}"
            );
            let half = (capsule.b_W - capsule.a_W) * 0.5;
            let tip = pose.translation + pose.rotation * Vector::new(0.0, 0.0, half.length());
            assert!((tip - capsule.b_W).length() < 1e-5, "{part} at key {k}");
            assert_eq!(track.scale[k], [1.0; 3]);
        }
    }
}

#[test]
fn an_episode_reads_back_with_the_simulations_poses() {
    let (evaluation, metrics, recording, scenario, model) =
        recorded_episode("configs/evaluate.toml", 3, 2, &[]);
    let cameras: Vec<_> = scenario
        .cameras
        .iter()
        .map(|c| (c.name.clone(), c.camera().expect("camera")))
        .collect();
    let d_min = evaluation.config.safety.d_min_m;
    let bytes = episode_glb(&model, &cameras, &recording, d_min, "test");

    let gltf = gltf::Gltf::from_slice(&bytes).expect("a valid glTF");
    let doc = &gltf.document;
    let names: HashMap<usize, String> = doc
        .nodes()
        .map(|n| (n.index(), n.name().unwrap_or_default().to_string()))
        .collect();

    // The root turns the cell's +z into glTF's +y; everything else hangs below it.
    let scene = doc.default_scene().expect("scene");
    let roots: Vec<_> = scene.nodes().collect();
    assert_eq!(roots.len(), 1);
    assert_eq!(roots[0].name(), Some(ROOT_NODE));
    let (_, r, _) = roots[0].transform().decomposed();
    let up = Rotation::from_xyzw(r[0].into(), r[1].into(), r[2].into(), r[3].into());
    assert!((up * Vector::Z - Vector::Y).length() < 1e-6);
    let below_root = roots[0].children().count();
    assert_eq!(below_root, doc.nodes().count() - 1);

    let tracks = tracks_of(&bytes);
    let samples = recording.t_s.len();
    assert!(samples > 80, "3 s at 30 Hz and more: {samples}");
    // The generator's human has no other arm to draw.
    assert!(recording.other_arm.iter().all(Vec::is_empty));
    assert!(!tracks.keys().any(|n| n.starts_with(OTHER_ARM_PREFIX)));
    // Every robot link with visuals is animated, and at every key its pose is the forward
    // kinematics of the joint positions the simulator measured then (to f32).
    let robot = &model.robot;
    let mut checked = 0;
    for (l, link) in robot.links().iter().enumerate() {
        let Some(track) = tracks.get(&format!("{ROBOT_PREFIX}{}", link.name)) else {
            assert!(link.visuals.is_empty(), "{} is not animated", link.name);
            continue;
        };
        assert_eq!(track.times.len(), samples);
        for k in (0..samples).step_by(7) {
            assert!(
                (f64::from(track.times[k]) - (recording.t_s[k] - recording.t_s[0])).abs() < 1e-5
            );
            let fk = robot.fk(model.X_WR, &recording.robot_q[k]).expect("fk");
            let truth = fk.link_poses()[l];
            let got = pose_of(track, k);
            assert!(
                (got.translation - truth.translation).length() < 1e-5,
                "{} at key {k}",
                link.name
            );
            assert!(
                got.rotation.dot(truth.rotation).abs() > 1.0 - 1e-6,
                "{} at key {k}",
                link.name
            );
            checked += 1;
        }
    }
    assert!(checked > 50);
    // The human's links follow the simulator's poses.
    for (l, link) in model.human.links().iter().enumerate() {
        let Some(track) = tracks.get(&format!("{HUMAN_PREFIX}{}", link.name)) else {
            continue;
        };
        for k in (0..samples).step_by(5) {
            let truth = recording.human_link_poses[k][l];
            let got = pose_of(track, k);
            assert!((got.translation - truth.translation).length() < 1e-5);
            assert!(got.rotation.dot(truth.rotation).abs() > 1.0 - 1e-6);
        }
    }
    // The closest pair: at every key exactly the line of its margin class is visible,
    // from the robot's point to the human's, as long as the distance.
    for k in 0..samples {
        let Some((a, b, d)) = recording.closest[k] else {
            continue;
        };
        let class = pair_class(d, d_min);
        for (c, (name, _)) in PAIR_NODES.iter().enumerate() {
            let track = &tracks[*name];
            let scale = track.scale[k];
            if c != class {
                assert_eq!(scale, [0.0; 3], "{name} shown at key {k}");
                let marker = &tracks[&format!("{name}{MARKER_SUFFIX}")];
                assert_eq!(
                    marker.scale[k], [0.0; 3],
                    "{name}'s marker shown at key {k}"
                );
                continue;
            }
            let (a, b) = (Vector::from_array(a), Vector::from_array(b));
            let pose = pose_of(track, k);
            assert!((pose.translation - a).length() < 1e-5);
            let tip = pose.translation + pose.rotation * Vector::new(f64::from(scale[0]), 0.0, 0.0);
            assert!((tip - b).length() < 1e-5, "key {k}: {tip:?} vs {b:?}");
            let marker = &tracks[&format!("{name}{MARKER_SUFFIX}")];
            assert_eq!(marker.scale[k], [1.0; 3]);
            let at = Vector::from_array(marker.translation[k].map(f64::from));
            assert!((at - b).length() < 1e-5, "marker at key {k}");
            if d > 0.0 {
                assert!(
                    (f64::from(scale[0]) - d).abs() < 1e-5,
                    "length {} vs distance {d}",
                    scale[0]
                );
            }
        }
    }
    // The samples are ticks of the episode: none closer than the episode's minimum.
    let sampled_min = recording
        .closest
        .iter()
        .flatten()
        .map(|c| c.2)
        .fold(f64::INFINITY, f64::min);
    assert!(sampled_min >= metrics.min_separation_m);
    assert!(
        sampled_min - metrics.min_separation_m < 0.05,
        "{sampled_min} vs {}",
        metrics.min_separation_m
    );
    // A camera node per camera of the cell, and the clutter.
    for (name, _) in &cameras {
        assert!(names.values().any(|n| n == &format!("camera/{name}")));
    }
    assert_eq!(
        names.values().filter(|n| n.starts_with("clutter_")).count(),
        model.clutter.len()
    );
}
