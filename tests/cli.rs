//! The `workcell` binary end to end, as a user runs it.

mod common;

use std::path::Path;
use std::process::{Command, Output};

fn workcell(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_workcell"))
        .args(args)
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")))
        .output()
        .expect("run workcell")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Runs `workcell args`, which must fail with `message` on stderr.
fn refused(args: &[&str], message: &str) {
    let out = workcell(args);
    assert!(!out.status.success(), "{args:?} succeeded");
    assert!(text(&out.stderr).contains(message), "{}", text(&out.stderr));
}

#[test]
fn robot_check_reports_json_with_link_poses() {
    let out = workcell(&[
        "robot",
        "check",
        "iiwa14_kinematics",
        "--fk",
        "0,0,0,0,0,0,0",
        "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(report["dof"], 7);
    assert_eq!(report["problems"].as_array().map(Vec::len), Some(0));
    let fk = report["fk"].as_array().expect("fk");
    let tool0 = fk.iter().find(|p| p["link"] == "tool0").expect("tool0");
    // Upright: 0.36 + 0.42 + 0.40 + 0.126 m above the base.
    let z = tool0["xyz"][2].as_f64().expect("z");
    assert!((z - 1.306).abs() < 1e-9, "{z}");
    assert!(
        report["rapier"]["fk_mismatch_m"]
            .as_f64()
            .expect("mismatch")
            < 1e-9
    );
}

#[test]
fn catalogue_models_check_clean() {
    for name in ["ur5e_kinematics", "iiwa14_kinematics", "human_arm", "human"] {
        let out = workcell(&["robot", "check", name, "--json"]);
        assert!(out.status.success(), "{name}: {}", text(&out.stderr));
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
        assert_eq!(report["problems"], serde_json::json!([]), "{name}");
        let rapier = &report["rapier"];
        assert!(
            rapier["fk_mismatch_m"].as_f64().expect("mismatch") < 1e-9,
            "{name}"
        );
        // Held off-neutral under gravity, a robot's servos keep every joint within 10 mrad.
        // The humans are not servoed: the cell moves their links as kinematic bodies
        // (sim/src/cell.rs), so what the servos hold says nothing about them.
        if !name.starts_with("human") {
            let hold = rapier["hold_error"].as_f64().expect("hold error");
            assert!(hold < 0.01, "{name}: {hold}");
        }
    }
}

#[test]
fn bad_input_is_a_clear_error_not_a_panic() {
    for args in [
        vec![
            "robot",
            "check",
            "robots/tests/fixtures/broken/missing_parent.urdf",
        ],
        vec!["robot", "check", "no_such_robot"],
        vec![
            "robot",
            "check",
            "robots/tests/fixtures/broken/dangling_dae.urdf",
        ],
        vec!["robot", "check", "ur5e_kinematics", "--fk", "1,2"],
        vec!["simulate", "configs/nonexistent.toml"],
    ] {
        let out = workcell(&args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.starts_with("error: "), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
    let out = workcell(&[
        "robot",
        "check",
        "robots/tests/fixtures/broken/missing_parent.urdf",
    ]);
    assert!(text(&out.stderr).contains("joint 'j': parent link 'nowhere' does not exist"));
    // A cause is printed once: the OS error of a missing scenario is not repeated.
    let out = workcell(&["simulate", "configs/nonexistent.toml"]);
    let stderr = text(&out.stderr);
    assert_eq!(stderr.matches("No such file").count(), 1, "{stderr}");
    assert_eq!(stderr.matches("nonexistent.toml").count(), 1, "{stderr}");
    // A renderer backend that is not built in is an error, not a panic.
    if !cfg!(feature = "gpu") {
        let dir = tempfile::tempdir().expect("temp dir");
        refused(
            &[
                "dataset",
                "generate",
                "--config",
                "configs/dataset.toml",
                "--backend",
                "gpu",
                "--out",
                dir.path().to_str().expect("utf-8"),
            ],
            "no GPU renderer",
        );
    }
}

#[test]
fn simulate_writes_csv_and_plot_and_replays_by_seed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let run = |name: &str, extra: &[&str]| {
        let out_dir = dir.path().join(name);
        let out_arg = out_dir.to_string_lossy().into_owned();
        let mut args = vec![
            "simulate",
            "configs/default.toml",
            "--seconds",
            "0.2",
            "--out",
            &out_arg,
        ];
        args.extend_from_slice(extra);
        let out = workcell(&args);
        assert!(out.status.success(), "{}", text(&out.stderr));
        out_dir
    };
    let a = run("a", &["--seed", "4"]);
    let b = run("b", &["--seed", "4"]);
    let c = run("c", &["--seed", "5"]);
    let joints = std::fs::read_to_string(a.join("robot_joints.csv")).expect("csv");
    let lines: Vec<&str> = joints.lines().collect();
    // header + t = 0 + 20 samples at 100 Hz
    assert_eq!(lines.len(), 22);
    assert!(lines[0].starts_with("t_s,q_joint1,"));
    assert_eq!(lines[0].split(',').count(), 1 + 2 * 7);
    let human = std::fs::read_to_string(a.join("human_poses.csv")).expect("csv");
    assert_eq!(
        human.lines().count(),
        1 + 21 * 19,
        "19 human links per sample (the default cell's whole body: 13, and the left arm's 6)"
    );
    assert!(
        std::fs::read_to_string(a.join("trajectories.svg"))
            .expect("svg")
            .contains("<polyline")
    );
    // The cell picture draws every clutter box of the default cell in both views: the table,
    // two boxes, and two shelves of four posts with five and four boards.
    let cell = std::fs::read_to_string(a.join("cell.svg")).expect("svg");
    assert_eq!(
        cell.matches("<polygon").count(),
        2 * (3 + (4 + 5) + (4 + 4))
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(a.join("summary.json")).expect("json"))
            .expect("json");
    assert_eq!(summary["steps"], 200);
    // Same seed, same file; another seed, another motion.
    assert_eq!(
        joints,
        std::fs::read_to_string(b.join("robot_joints.csv")).expect("csv")
    );
    assert_ne!(
        joints,
        std::fs::read_to_string(c.join("robot_joints.csv")).expect("csv")
    );
    // Nothing is overwritten without --force.
    let again = workcell(&[
        "simulate",
        "configs/default.toml",
        "--seconds",
        "0.1",
        "--out",
        &a.to_string_lossy(),
    ]);
    assert_eq!(again.status.code(), Some(1));
    assert!(text(&again.stderr).contains("--force"));
}

#[test]
fn dataset_generate_then_show_writes_a_contact_sheet() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let config = tmp.path().join("small.toml");
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/default.toml");
    std::fs::write(
        &config,
        format!(
            "scenario = {:?}\nsequences_per_pair = 1\nframes = 2\nwidth_px = 64\nheight_px = 64\ninput_px = 32\nstart_s = [0.5, 1.0]\n",
            scenario.display().to_string()
        ),
    )
    .expect("config");
    let out = tmp.path().join("data");
    let (config, out) = (
        config.to_str().expect("utf-8"),
        out.to_str().expect("utf-8"),
    );
    let run = workcell(&["dataset", "generate", "--config", config, "--out", out]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(
        text(&run.stdout).contains("12 sequences (12 new), 24 frames of 32x32 px"),
        "{}",
        text(&run.stdout)
    );
    let show = workcell(&["dataset", "show", out]);
    assert!(show.status.success(), "{}", text(&show.stderr));
    // Both camera sources; the stats table has a row per source, distance class and crop.
    let shown = text(&show.stdout);
    assert!(
        shown.contains("camera:front") && shown.contains("paper"),
        "{shown}"
    );
    let stats = workcell(&["dataset", "stats", out]);
    assert!(stats.status.success(), "{}", text(&stats.stderr));
    let table = text(&stats.stdout);
    assert!(
        table.contains("workcell-dataset/3 (12 sequences, 24 frames of 32x32 px, flesh human)"),
        "{table}"
    );
    for row in ["paper          short    all", "camera:front"] {
        assert!(table.contains(row), "{row}: {table}");
    }
    let bad = workcell(&["dataset", "stats", out, "--input", "1"]);
    assert!(
        text(&bad.stderr).contains("--input 1"),
        "{}",
        text(&bad.stderr)
    );
    let sheet = Path::new(out).join("contact_sheet.png");
    let bytes = std::fs::read(&sheet).expect("contact sheet");
    assert!(bytes.starts_with(b"\x89PNG"));
    // Not a dataset: a clear error, not a panic.
    let bad = workcell(&["dataset", "show", tmp.path().to_str().expect("utf-8")]);
    assert!(!bad.status.success());
    assert!(
        text(&bad.stderr).contains("not a finished dataset"),
        "{}",
        text(&bad.stderr)
    );
    let bad = workcell(&[
        "dataset",
        "generate",
        "--config",
        "nowhere.toml",
        "--out",
        out,
    ]);
    assert!(
        text(&bad.stderr).contains("nowhere.toml"),
        "{}",
        text(&bad.stderr)
    );
}

/// `dataset generate --crop tracker`: the test split of a small configuration read through
/// the deployed tracker's regions, frame by frame, and its refusals.
#[test]
fn dataset_generate_reads_frames_through_the_trackers_region() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/default.toml");
    let config = |input: u32| {
        let path = tmp.path().join(format!("data-{input}.toml"));
        std::fs::write(
            &path,
            format!(
                "scenario = {:?}\nsequences_per_pair = 1\nframes = 3\nwidth_px = 160\nheight_px = 120\ninput_px = {input}\nstart_s = [0.5, 1.0]\nsplits = [0.0, 0.0, 1.0]\n[cell_cameras]\nenabled = false\n",
                scenario.display().to_string()
            ),
        )
        .expect("config");
        path.to_str().expect("utf-8").to_string()
    };
    let (small, full) = (config(32), config(128));
    let out = tmp.path().join("tracked");
    let out_s = out.to_str().expect("utf-8");
    let run = workcell(&[
        "dataset", "generate", "--config", &full, "--crop", "tracker", "--splits", "test", "--out",
        out_s,
    ]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    let said = text(&run.stdout);
    assert!(said.contains("the tracker read 27 new frames"), "{said}");
    let stamp = std::fs::read_to_string(out.join("config.toml")).expect("stamp");
    // The shipped network for a camera with depth, which the tracker has here, for the
    // default cell's whole body.
    assert!(
        stamp.contains(
            "# crop: tracker (ArmTracker, RGB-D, weights procnet-depth-human.safetensors"
        ),
        "{stamp}"
    );
    // Every frame's label names the region the tracker read it through.
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("manifest.json")).expect("manifest"))
            .expect("json");
    let sequences = manifest["sequences"].as_array().expect("sequences");
    assert_eq!(sequences.len(), 9);
    for s in sequences {
        let dir = out.join(s["dir"].as_str().expect("dir"));
        for f in 0..3 {
            let label: serde_json::Value = serde_json::from_slice(
                &std::fs::read(dir.join(format!("frame_{f:03}.json"))).expect("label"),
            )
            .expect("json");
            let kind = label["roi"]["kind"].as_str().expect("kind");
            // Two poses in a row before the region follows the arm: not before frame 2.
            assert!(
                kind == "workspace" || (kind == "tracked" && f == 2),
                "{} frame {f}: {kind}",
                dir.display()
            );
        }
    }
    let other = tmp
        .path()
        .join("other")
        .to_str()
        .expect("utf-8")
        .to_string();
    let generate = |extra: &[&str], message: &str| {
        let mut args = vec!["dataset", "generate", "--config", &full, "--out", &other];
        args.extend_from_slice(extra);
        refused(&args, message);
    };
    generate(&["--crop", "nearest"], "unknown --crop \"nearest\"");
    generate(
        &["--weights", "w.safetensors"],
        "--weights is a setting of --crop tracker",
    );
    generate(&["--splits", "test,holdout"], "unknown split \"holdout\"");
    generate(
        &["--crop", "tracker", "--weights", "nowhere.safetensors"],
        "nowhere.safetensors",
    );
    refused(
        &[
            "dataset", "generate", "--config", &small, "--crop", "tracker", "--out", &other,
        ],
        "stores 32x32 (input_px)",
    );
}

#[test]
fn train_resumes_then_eval_segmentation_prints_the_table() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/default.toml");
    let data_cfg = tmp.path().join("data.toml");
    std::fs::write(
        &data_cfg,
        format!(
            // The paper's arm: the tables of its method.
            "scenario = {:?}\nhuman_model = \"human_arm\"\nsequences_per_pair = 2\nframes = 4\nwidth_px = 32\nheight_px = 32\ninput_px = 32\nstart_s = [0.5, 1.0]\nsplits = [0.5, 0.0, 0.5]\n[cell_cameras]\nenabled = false\n",
            scenario.display().to_string()
        ),
    )
    .expect("config");
    let data = tmp.path().join("data");
    let data_s = data.to_str().expect("utf-8");
    let run = workcell(&[
        "dataset",
        "generate",
        "--config",
        data_cfg.to_str().expect("utf-8"),
        "--out",
        data_s,
    ]);
    assert!(run.status.success(), "{}", text(&run.stderr));

    let train_cfg = tmp.path().join("train.toml");
    let recipe = |steps: usize, channels: &str| {
        format!(
            "dataset = \"data\"\nsteps = {steps}\nbatch = 2\nwindow = 3\ncheckpoint_every = 2\nvalidate_every = 2\n\n[loss]\nbatch_dice = 1.0\n\n[model]\ninput_size = 16\nrepr_channels = {channels}\ninput_channels = [3, 4, 4]\n"
        )
    };
    std::fs::write(&train_cfg, recipe(6, "[4, 4, 4]")).expect("train config");
    let out = tmp.path().join("run");
    let (cfg_s, out_s) = (
        train_cfg.to_str().expect("utf-8"),
        out.to_str().expect("utf-8"),
    );
    // Interrupted after 4 of 6 steps ...
    let first = workcell(&[
        "train",
        "--config",
        cfg_s,
        "--out",
        out_s,
        "--stop-after",
        "4",
    ]);
    assert!(first.status.success(), "{}", text(&first.stderr));
    assert!(
        text(&first.stdout).contains("stopped at step 4 of 6"),
        "{}",
        text(&first.stdout)
    );
    assert!(!out.join("procnet.safetensors").exists());
    // The checkpoint is step 4's pair alone, named by step.json (step 2's files are gone) ...
    let mut files: Vec<String> = std::fs::read_dir(out.join("checkpoint"))
        .expect("checkpoint folder")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    files.sort();
    assert_eq!(
        files,
        ["model-4.safetensors", "optimizer-4.burn", "step.json"]
    );
    // ... a step.json beyond the run's steps is refused rather than underflowing ...
    let step_json = out.join("checkpoint/step.json");
    std::fs::write(&step_json, "99").expect("tamper");
    refused(
        &["train", "--config", cfg_s, "--out", out_s],
        "says 99 steps are done, more than the run's 6",
    );
    std::fs::write(&step_json, "4").expect("restore");
    // ... and the same command resumes from the checkpoint and finishes.
    let resumed = workcell(&["train", "--config", cfg_s, "--out", out_s]);
    assert!(resumed.status.success(), "{}", text(&resumed.stderr));
    assert!(
        text(&resumed.stdout).contains("6 steps (2 this run"),
        "{}",
        text(&resumed.stdout)
    );
    for file in [
        "procnet.safetensors",
        "metrics.csv",
        "loss_curve.svg",
        "train.toml",
        "checkpoint/step.json",
    ] {
        assert!(out.join(file).exists(), "{file} missing");
    }
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).expect("metrics");
    assert_eq!(
        metrics.lines().count(),
        7,
        "header and one line per step:\n{metrics}"
    );
    // ... and a model of another shape is refused, naming what differs.
    std::fs::write(&train_cfg, recipe(6, "[4, 4, 8]")).expect("train config");
    let other = workcell(&["train", "--config", cfg_s, "--out", out_s]);
    assert!(!other.status.success());
    assert!(
        text(&other.stderr).contains("repr_channels"),
        "{}",
        text(&other.stderr)
    );

    // A second cycle starts from the finished run's weights: one step at a learning rate of
    // 1e-15 leaves them within 1e-12 of the first run's (a run from the seed's random weights
    // would be off by the size of the weights themselves).
    let second_cfg = tmp.path().join("second.toml");
    let second = |channels: &str| {
        recipe(1, channels).replace(
            "window = 3\n",
            "window = 3\nlr = 1e-15\ninit_weights = \"run/procnet.safetensors\"\n",
        )
    };
    let second_cycle = |config: String, out: &Path| {
        std::fs::write(&second_cfg, config).expect("second config");
        let cycle = workcell(&[
            "train",
            "--config",
            second_cfg.to_str().expect("utf-8"),
            "--out",
            out.to_str().expect("utf-8"),
        ]);
        assert!(cycle.status.success(), "{}", text(&cycle.stderr));
    };
    let second_out = tmp.path().join("second");
    second_cycle(second("[4, 4, 4]"), &second_out);
    // No parameter depends on the input size, so a cycle on larger frames (32x32 instead of
    // 16x16: progressive resizing) starts from the same weights.
    let larger_out = tmp.path().join("larger");
    second_cycle(
        second("[4, 4, 4]").replace("input_size = 16", "input_size = 32"),
        &larger_out,
    );
    // Every tensor is f32, in the same order in every file (one set of parameters: the input
    // size changes none).
    let tensors = |path: &Path| -> Vec<f32> {
        let bytes = std::fs::read(path).expect("weights");
        let header = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes")) as usize;
        bytes[8 + header..]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
            .collect()
    };
    let first_w = tensors(&out.join("procnet.safetensors"));
    for run in [&second_out, &larger_out] {
        let second_w = tensors(&run.join("procnet.safetensors"));
        assert_eq!(first_w.len(), second_w.len());
        let moved = first_w
            .iter()
            .zip(&second_w)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(
            moved < 1e-12,
            "{}: the second cycle did not start from the first run's weights ({moved})",
            run.display()
        );
    }
    // Weights of another shape are refused before any data is loaded, naming what differs.
    std::fs::write(&second_cfg, second("[4, 4, 8]")).expect("second config");
    refused(
        &[
            "train",
            "--config",
            second_cfg.to_str().expect("utf-8"),
            "--out",
            tmp.path().join("refused").to_str().expect("utf-8"),
        ],
        "weights of another configuration: repr_channels",
    );

    // A network that reads depth starts from the same network's RGB weights, grown with zero
    // weights to and from the depth plane: at a learning rate of 1e-15 it segments the test
    // split as the RGB run does, to the table's last digit.
    let depth_out = tmp.path().join("depth");
    second_cycle(
        second("[4, 4, 4]").replace("input_channels = [3, 4, 4]", "input_channels = [4, 4, 4]"),
        &depth_out,
    );
    let forearm_row = |weights: &Path| {
        let eval = workcell(&[
            "eval",
            "segmentation",
            "--weights",
            weights.to_str().expect("utf-8"),
            "--dataset",
            data_s,
            "--split",
            "test",
        ]);
        assert!(eval.status.success(), "{}", text(&eval.stderr));
        text(&eval.stdout)
            .lines()
            .find(|l| l.starts_with("| forearm |"))
            .map(str::to_string)
            .expect("a forearm row")
    };
    assert_eq!(
        forearm_row(&depth_out.join("procnet.safetensors")),
        forearm_row(&out.join("procnet.safetensors"))
    );

    let weights = out.join("procnet.safetensors");
    let weights_s = weights.to_str().expect("utf-8");
    // `eval segmentation` of the run's weights on a split of the dataset.
    let eval_args = |split: &'static str| {
        vec![
            "eval",
            "segmentation",
            "--weights",
            weights_s,
            "--dataset",
            data_s,
            "--split",
            split,
        ]
    };
    let eval_test = |extra: &[&str]| {
        let mut args = eval_args("test");
        args.extend_from_slice(extra);
        workcell(&args)
    };
    let sheet = tmp.path().join("worst.png");
    let eval = eval_test(&["--sheet", sheet.to_str().expect("utf-8"), "--worst", "3"]);
    assert!(eval.status.success(), "{}", text(&eval.stderr));
    let md = text(&eval.stdout);
    assert!(
        md.contains("| forearm |")
            && md.contains("occlusion")
            && md.contains("batch Dice loss")
            && md.contains("x 29/50")
            && md.contains("with the elbow and wrist right")
            && md.contains("of which on its edge")
            && md.contains("Layer 0's prediction of the frame: mean absolute error"),
        "{md}"
    );
    // The worst frames' sheet: two frames to a row, four 32x32 images each.
    let png = std::fs::read(&sheet).expect("the sheet is written");
    let (w, h) = (
        u32::from_be_bytes(png[16..20].try_into().expect("4 bytes")),
        u32::from_be_bytes(png[20..24].try_into().expect("4 bytes")),
    );
    assert!(w >= 2 * 4 * 32 && h >= 2 * 32, "{w}x{h}");
    // A subset of the split: two of its sequences, each scored frame also written as CSV.
    let frames_csv = tmp.path().join("frames.csv");
    let subset = eval_test(&[
        "--sequences",
        "2",
        "--frames",
        frames_csv.to_str().expect("utf-8"),
    ]);
    assert!(subset.status.success(), "{}", text(&subset.stderr));
    let md = text(&subset.stdout);
    assert!(
        md.contains("(2 of its ")
            && md.contains("Split `test`: 2 sequences, 6 frames scored")
            && md.contains("ceiling, input")
            && md.contains("| 1-9 | 2 | 6 |")
            && md.contains("The 2 sequences of highest mean forearm Dice loss"),
        "{md}"
    );
    // One row per scored frame (frames 1 to 3 of each 4-frame sequence), ten fields each.
    let csv = std::fs::read_to_string(&frames_csv).expect("the frames are written");
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 1 + 6, "{csv}");
    assert_eq!(rows[0][..2], ["sequence", "frame"], "{csv}");
    assert_eq!(rows[0][8], "forearm_luma", "{csv}");
    assert_eq!(rows[0][9], "forearm_dice_parts_right", "{csv}");
    assert!(rows.iter().all(|r| r.len() == 10), "{csv}");
    let scored: Vec<&str> = rows[1..].iter().map(|r| r[1]).collect();
    assert_eq!(scored, ["1", "2", "3", "1", "2", "3"], "{csv}");
    for r in &rows[1..] {
        let dice: f64 = r[5].parse().expect("a loss");
        assert!((0.0..=1.0).contains(&dice), "{csv}");
        // Giving arm pixels their true part only adds to the forearm's overlap.
        let (thresholded, parts_right): (f64, f64) =
            (r[6].parse().expect("a loss"), r[9].parse().expect("a loss"));
        assert!((0.0..=thresholded).contains(&parts_right), "{csv}");
        // A luma needs a forearm in view, so no true forearm (no input ceiling) means none; a
        // forearm wholly under the occluder has a ceiling but no luma.
        assert!(r[8].is_empty() || !r[7].is_empty(), "{csv}");
        if !r[8].is_empty() {
            let luma: f64 = r[8].parse().expect("a luma");
            assert!((0.0..=1.0).contains(&luma), "{csv}");
        }
    }
    // The luma bands hold exactly the frames that show a forearm, each once.
    let with_forearm = rows[1..].iter().filter(|r| !r[8].is_empty()).count();
    let in_bands: usize = ["dark", "mid", "light"]
        .iter()
        .filter_map(|band| {
            let row = md
                .lines()
                .find(|l| l.starts_with(&format!("| forearm {band} |")))?;
            row.split('|').nth(3)?.trim().parse::<usize>().ok()
        })
        .sum();
    assert!(with_forearm > 0, "{csv}");
    assert_eq!(in_bands, with_forearm, "{md}");
    // With standard output closed (`| true`), the table is still written to --out.
    let table = tmp.path().join("table.md");
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    let closed = Command::new(env!("CARGO_BIN_EXE_workcell"))
        .args(eval_args("test"))
        .args(["--out", table.to_str().expect("utf-8")])
        .stdout(writer)
        .output()
        .expect("run");
    assert!(closed.status.success(), "{}", text(&closed.stderr));
    assert!(
        std::fs::read_to_string(&table)
            .expect("table")
            .contains("| forearm |")
    );
    // A split with no frame is an error, not a scored table (the dataset has no validation
    // sequences) ...
    refused(&eval_args("validation"), "has no validation sequences");
    // ... and so are weights of NaN, which score NaN: every f32 of the data section is NaN.
    let mut nan = std::fs::read(&weights).expect("weights");
    let header = u64::from_le_bytes(nan[..8].try_into().expect("8 bytes")) as usize;
    for chunk in nan[8 + header..].chunks_exact_mut(4) {
        chunk.copy_from_slice(&f32::NAN.to_le_bytes());
    }
    let nan_path = tmp.path().join("nan.safetensors");
    std::fs::write(&nan_path, nan).expect("write");
    refused(
        &[
            "eval",
            "segmentation",
            "--weights",
            nan_path.to_str().expect("utf-8"),
            "--dataset",
            data_s,
        ],
        "the scores are not finite",
    );
    let bad = workcell(&[
        "eval",
        "segmentation",
        "--weights",
        data_s,
        "--dataset",
        data_s,
    ]);
    assert!(!bad.status.success());
    assert!(
        text(&bad.stderr).contains("cannot read"),
        "{}",
        text(&bad.stderr)
    );

    // The forearm's pose from the dataset's own masks and from the tiny network's: Table 2's
    // layout with the paper's numbers beside, the per-frame CSV and the distance plot.
    // The articulated fit with the depth images too (RGB-D), the paper's method on the
    // network's masks.
    for (masks, method, depth, says) in [
        (
            "gt",
            "articulated",
            "--depth",
            "and the depth image (RGB-D)",
        ),
        (
            "procnet",
            "paper",
            "--no-roi",
            "elbow anchored to the shoulder",
        ),
    ] {
        let pose_out = tmp.path().join(format!("pose-{masks}"));
        let pose = workcell(&[
            "eval",
            "pose",
            depth,
            "--method",
            method,
            "--masks",
            masks,
            "--weights",
            weights.to_str().expect("utf-8"),
            "--dataset",
            data_s,
            "--split",
            "test",
            "--out",
            pose_out.to_str().expect("utf-8"),
        ]);
        assert!(pose.status.success(), "{}", text(&pose.stderr));
        let md = text(&pose.stdout);
        assert!(
            md.contains("| short | light |") && md.contains("| 1.73 | 1.62 |"),
            "{md}"
        );
        assert!(md.contains(says) && md.contains("within the bound"), "{md}");
        // True masks have a measured calibration, and the report names the bound it used.
        if method == "articulated" {
            assert!(
                md.contains("The bound is the one calibrated for these masks"),
                "{md}"
            );
        }
        for file in [
            "pose_eval.md",
            "pose_frames.csv",
            "pose_error_vs_distance.svg",
            "pose_error_vs_distance.png",
        ] {
            assert!(pose_out.join(file).exists(), "{masks}: {file} missing");
        }
        // The articulated fit's settings beside its frames, for a calibration to record:
        // with no flags and a calibration without a fit table, the fit's defaults.
        if method == "articulated" {
            let fit = std::fs::read_to_string(pose_out.join("fit.toml")).expect("fit.toml");
            for line in [
                "fit_trunk = false",
                "search_below_gain = 0.55",
                "reversed_start = false",
                "depth_start = false",
            ] {
                assert!(fit.contains(line), "{fit}");
            }
        } else {
            assert!(
                !pose_out.join("fit.toml").exists(),
                "the paper's method has no fit.toml"
            );
        }
        let csv = std::fs::read_to_string(pose_out.join("pose_frames.csv")).expect("csv");
        let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
        assert!(
            header.starts_with(&["sequence", "frame"])
                && header.ends_with(&[
                    "ends_cm",
                    "truth_gain",
                    "sigma_m",
                    "spread_m",
                    "truth_gain_upper_arm",
                    "truth_gain_forearm",
                    "truth_gain_hand",
                    "hidden_share",
                    "confirmed",
                    "recorded",
                    "trunk_error_deg",
                    "pelvis_error_cm"
                ]),
            "{csv}"
        );
        // The parts' shares of the truth's gain add up to it (each written to 4 decimals).
        let column = |name: &str| header.iter().position(|h| *h == name).expect(name);
        let total = column("truth_gain");
        let parts = ["upper_arm", "forearm", "hand"].map(|p| column(&format!("truth_gain_{p}")));
        let (hidden, position) = (column("hidden_share"), column("position_cm"));
        let mut checked = 0;
        for line in csv.lines().skip(1) {
            let row: Vec<f64> = line
                .split(',')
                .map(|v| v.parse().unwrap_or(f64::NAN))
                .collect();
            if method == "articulated" {
                let sum: f64 = parts.iter().map(|&i| row[i]).sum();
                assert!((sum - row[total]).abs() < 2.5e-4, "{line}");
                // A share of the region the depth image shows hidden, for frames with a pose.
                assert!(
                    row[position].is_nan() || (0.0..=1.0).contains(&row[hidden]),
                    "{line}"
                );
                checked += 1;
            } else {
                assert!(row[total].is_nan() && parts.iter().all(|&i| row[i].is_nan()));
                assert!(row[hidden].is_nan(), "{line}");
            }
        }
        assert!(method != "articulated" || checked > 0, "{csv}");
        // A pose confirmed below the gain threshold is a pose, and only the articulated
        // fit confirms.
        let confirmed = column("confirmed");
        for line in csv.lines().skip(1) {
            let row: Vec<&str> = line.split(',').collect();
            match row[confirmed] {
                "false" => {}
                "true" => assert!(
                    method == "articulated" && !row[position].is_empty(),
                    "{line}"
                ),
                other => panic!("confirmed: {other:?} in {line}"),
            }
        }
        // This dataset plays the generator's motion: no frame is of a recorded person.
        let recorded = column("recorded");
        assert!(
            csv.lines()
                .skip(1)
                .all(|l| l.split(',').nth(recorded) == Some("false")),
            "{csv}"
        );
        // The contact sheet of the frames without a pose, written when there are any.
        let why = column("no_pose");
        let without = csv
            .lines()
            .skip(1)
            .filter(|l| l.split(',').nth(why).is_some_and(|v| !v.is_empty()))
            .count();
        assert_eq!(
            pose_out.join("no_pose.png").exists(),
            without > 0,
            "{masks}: {without} frames without a pose"
        );
    }
    // The fit's flags set its settings either way, and fit.toml records what ran.
    let flags_out = tmp.path().join("pose-flags");
    let flagged = workcell(&[
        "eval",
        "pose",
        "--depth",
        "--masks",
        "gt",
        "--reversed-start",
        "--depth-start",
        "false",
        "--search-below-gain",
        "0.6",
        "--dataset",
        data_s,
        "--split",
        "test",
        "--out",
        flags_out.to_str().expect("utf-8"),
    ]);
    assert!(flagged.status.success(), "{}", text(&flagged.stderr));
    let fit = std::fs::read_to_string(flags_out.join("fit.toml")).expect("fit.toml");
    for line in [
        "search_below_gain = 0.6",
        "reversed_start = true",
        "depth_start = false",
    ] {
        assert!(fit.contains(line), "{fit}");
    }
    refused(
        &["eval", "pose", "--method", "pnp", "--dataset", data_s],
        "articulated, paper",
    );
    refused(
        &["eval", "pose", "--no-anchor", "--dataset", data_s],
        "settings of --method paper",
    );
    refused(
        &[
            "eval",
            "pose",
            "--method",
            "paper",
            "--depth",
            "--dataset",
            data_s,
        ],
        "setting of --method articulated",
    );
    refused(
        &["eval", "pose", "--search-starts", "0", "--dataset", data_s],
        "climbs 1 to 1000 cells",
    );
    refused(
        &[
            "eval",
            "pose",
            "--method",
            "paper",
            "--search-starts",
            "30",
            "--dataset",
            data_s,
        ],
        "--search-starts, --search-below-gain, --reversed-start, --depth-start, \
         --hull-outlines, --min-gain, --confirm-min-gain and --trunk are settings of --method \
         articulated",
    );
    refused(
        &[
            "eval",
            "pose",
            "--method",
            "paper",
            "--trunk",
            "fit",
            "--dataset",
            data_s,
        ],
        "are settings of --method articulated",
    );
    refused(
        &[
            "eval",
            "pose",
            "--method",
            "paper",
            "--hull-outlines",
            "--dataset",
            data_s,
        ],
        "are settings of --method articulated",
    );
    refused(
        &["eval", "pose", "--trunk", "bent", "--dataset", data_s],
        "possible values: fit, upright, truth",
    );
    refused(
        &[
            "eval",
            "pose",
            "--method",
            "paper",
            "--confirm-min-gain",
            "0.2",
            "--dataset",
            data_s,
        ],
        "are settings of --method articulated",
    );
    refused(
        &["eval", "pose", "--min-gain", "1.5", "--dataset", data_s],
        "--min-gain 1.5: a gain from 0 to 1",
    );
    for bad in ["1.5", "NaN"] {
        refused(
            &[
                "eval",
                "pose",
                "--confirm-min-gain",
                bad,
                "--dataset",
                data_s,
            ],
            &format!("--confirm-min-gain {bad}: a gain from 0 to 1"),
        );
    }
    refused(
        &["eval", "pose", "--masks", "oracle", "--dataset", data_s],
        "gt, gt@N, visible, procnet, baseline",
    );
    for bad in ["gt@0", "gt@sixteen", "gt@"] {
        refused(
            &["eval", "pose", "--masks", bad, "--dataset", data_s],
            "gt@N takes a network input side N of 4 to 4096",
        );
    }
    // A network input larger than the stored frames is no perfect network's.
    refused(
        &["eval", "pose", "--masks", "gt@64", "--dataset", data_s],
        "a network input of 64x64 for 32x32 frames",
    );
    refused(
        &["eval", "pose", "--masks", "gt,gt", "--dataset", data_s],
        "names \"gt\" twice",
    );

    // The feed-forward baseline: the same command and recipe with --model baseline, its own
    // weight file, named as the PoseCNN stand-in in every table. Two steps of it into `out`,
    // with `extra` arguments:
    let train_baseline = |out: &Path, extra: &[&str]| {
        let out_s = out.to_str().expect("utf-8");
        let mut args = vec![
            "train", "--config", cfg_s, "--model", "baseline", "--steps", "2", "--out", out_s,
        ];
        args.extend_from_slice(extra);
        let run = workcell(&args);
        assert!(run.status.success(), "{}", text(&run.stderr));
        run
    };
    let base_out = tmp.path().join("run-baseline");
    let base = train_baseline(&base_out, &[]);
    assert!(
        text(&base.stdout).contains("feed-forward baseline (PoseCNN stand-in)"),
        "{}",
        text(&base.stdout)
    );
    let base_weights = base_out.join("baseline.safetensors");
    assert!(base_weights.exists() && !base_out.join("procnet.safetensors").exists());
    // A second seed of the same recipe: --seed overrides the configuration's, and the run
    // folder's train.toml (what a resume compares against) records it.
    let seed_out = tmp.path().join("run-seed-7");
    train_baseline(&seed_out, &["--seed", "7"]);
    let recorded = std::fs::read_to_string(seed_out.join("train.toml")).expect("train.toml");
    assert!(recorded.contains("seed = 7"), "{recorded}");
    assert_ne!(
        std::fs::read(&base_weights).expect("seed 1 weights"),
        std::fs::read(seed_out.join("baseline.safetensors")).expect("seed 7 weights"),
        "another seed, other weights"
    );
    // The runs side by side: one row each (two steps; this dataset has no validation split,
    // so no validation figure) and a plot.
    let curves = tmp.path().join("curves/validation.svg");
    let report = workcell(&[
        "report",
        "training",
        base_out.to_str().expect("utf-8"),
        seed_out.to_str().expect("utf-8"),
        "--out",
        curves.to_str().expect("utf-8"),
    ]);
    assert!(report.status.success(), "{}", text(&report.stderr));
    let table = text(&report.stdout);
    for run in ["run-baseline", "run-seed-7"] {
        let row = table
            .lines()
            .find(|l| l.starts_with(&format!("| {run} | 2 |")))
            .unwrap_or_else(|| panic!("{run} missing:\n{table}"));
        assert!(row.ends_with("| - | - |"), "{row}");
    }
    assert!(curves.exists() && curves.with_extension("png").exists());
    refused(
        &["report", "training", data_s],
        "is not a training run folder",
    );
    refused(
        &[
            "train", "--config", cfg_s, "--model", "posecnn", "--out", out_s,
        ],
        "procnet, baseline",
    );
    // ProcNet's weights are not a baseline.
    refused(
        &[
            "eval",
            "pose",
            "--masks",
            "baseline",
            "--weights",
            weights.to_str().expect("utf-8"),
            "--dataset",
            data_s,
        ],
        "holds a ProcNet",
    );
    // Two mask sources side by side.
    let pose_out = tmp.path().join("pose-compare");
    let pose = workcell(&[
        "eval",
        "pose",
        "--masks",
        "gt,gt@16,baseline",
        "--weights",
        base_weights.to_str().expect("utf-8"),
        "--dataset",
        data_s,
        "--out",
        pose_out.to_str().expect("utf-8"),
    ]);
    assert!(pose.status.success(), "{}", text(&pose.stderr));
    let md = text(&pose.stdout);
    assert!(
        md.contains("feed-forward baseline (PoseCNN stand-in)")
            && md.contains("baseline, common (cm)"),
        "{md}"
    );
    for file in [
        "pose_eval_gt.md",
        "pose_eval_gt16.md",
        "pose_eval_baseline.md",
        "pose_frames_baseline.csv",
        "pose_compare.md",
        "pose_error_vs_distance.png",
    ] {
        assert!(pose_out.join(file).exists(), "compare: {file} missing");
    }
}

/// A POSIX shell's word splitting of plain words and single-quoted strings (all the replay
/// commands use).
fn shell_words(command: &str) -> Vec<String> {
    let (mut words, mut word, mut quoted, mut any) = (Vec::new(), String::new(), false, false);
    for c in command.chars() {
        match c {
            '\'' => {
                quoted = !quoted;
                any = true;
            }
            ' ' if !quoted => {
                if any || !word.is_empty() {
                    words.push(std::mem::take(&mut word));
                }
                any = false;
            }
            _ => word.push(c),
        }
    }
    if any || !word.is_empty() {
        words.push(word);
    }
    words
}

#[test]
fn evaluate_writes_the_report_and_refuses_bad_input() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A short task keeps the test quick; the regression test runs the full scenario.
    let eval = dir.path().join("eval.toml");
    let cell = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/default.toml");
    std::fs::write(
        &eval,
        format!("cell = {:?}\ntask_s = 2.0\n", cell.display().to_string()),
    )
    .expect("write");
    let out_dir = dir.path().join("report");
    let args = |filter: &str| {
        vec![
            "evaluate".to_string(),
            eval.display().to_string(),
            "--episodes".into(),
            "2".into(),
            "--filter".into(),
            filter.into(),
            "--out".into(),
            out_dir.display().to_string(),
        ]
    };
    let run = |a: Vec<String>| workcell(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let out = run(args("qp"));
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("2 episodes, filter qp"),
        "{}",
        text(&out.stdout)
    );
    for f in [
        "summary.md",
        "metrics.csv",
        "evaluation.toml",
        "separation.png",
        "speed_scaling.png",
        "perception_error.png",
    ] {
        assert!(out_dir.join(f).is_file(), "{f} missing");
    }
    let csv = std::fs::read_to_string(out_dir.join("metrics.csv")).expect("csv");
    assert_eq!(csv.lines().count(), 3, "header and one row per episode");
    let summary = std::fs::read_to_string(out_dir.join("summary.md")).expect("summary");
    assert!(summary.contains("## Verdict") && summary.contains("![separation](separation.png)"));
    // ProcNet and the articulated fit in the loop: the camera is rendered, segmented and
    // fitted at its rate, and the report says so.
    for (perception, set, name) in [
        // The shipped weights by default, wherever the evaluation file is: the RGB network
        // for an RGB camera, for an RGB-D one the network that reads depth and was trained
        // on the default cell's whole body.
        (
            "procnet",
            "perception.depth=false",
            "procnet/weights/procnet-cpu.safetensors) + articulated render-and-compare, ",
        ),
        (
            "procnet",
            "perception.depth=true",
            "procnet/weights/procnet-depth-human.safetensors) + articulated \
             render-and-compare with depth (RGB-D)",
        ),
        (
            "pose-gt-masks",
            "perception.depth=false",
            "ground-truth arm masks + articulated render-and-compare",
        ),
    ] {
        let loop_dir = dir.path().join(format!("{perception}-{set}"));
        let out = workcell(&[
            "evaluate",
            eval.to_str().expect("utf-8"),
            "--episodes",
            "1",
            "--perception",
            perception,
            "--set",
            set,
            "--out",
            loop_dir.to_str().expect("utf-8"),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        let summary = std::fs::read_to_string(loop_dir.join("summary.md")).expect("summary");
        assert!(summary.contains(name), "{summary}");
        assert!(loop_dir.join("perception_error.png").is_file());
    }
    // A second run into the same folder keeps the first report unless --force.
    let again = run(args("ssm"));
    assert!(!again.status.success());
    assert!(
        text(&again.stderr).contains("--force"),
        "{}",
        text(&again.stderr)
    );

    // Every violating episode is listed with a command that replays exactly it. A d_min of
    // 0.5 m makes the unfiltered robot violate within the short task.
    let violating_dir = dir.path().join("violating");
    let mut violating = args("none");
    violating.truncate(violating.len() - 1);
    violating.push(violating_dir.display().to_string());
    violating.extend(
        [
            "--set",
            "safety.d_min_m=0.5",
            "--set",
            "safety.detection_m = 1.2",
        ]
        .map(String::from),
    );
    let out = run(violating);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("replay the first: workcell evaluate"));
    let listed = std::fs::read_to_string(violating_dir.join("violations.txt")).expect("list");
    let first = listed
        .lines()
        .find(|l| !l.starts_with('#'))
        .expect("a violating episode");
    let fields: Vec<&str> = first.split('\t').collect();
    // Seed, violations, separation, where, the left arm's separation, the command.
    assert_eq!(fields.len(), 6, "{first}");
    let (seed, command) = (fields[0], fields[5]);
    // The override with spaces comes back quoted, as a shell needs it.
    assert!(command.contains("'safety.detection_m = 1.2'"), "{command}");
    let words = shell_words(command);
    assert_eq!(words[..2], ["workcell", "evaluate"]);
    assert!(words.windows(2).any(|w| w == ["--seed", seed]), "{command}");
    let out = workcell(&words[1..].iter().map(String::as_str).collect::<Vec<_>>());
    assert!(out.status.success(), "{}", text(&out.stderr));
    // The replay's row equals the original's for that seed, but for the episode index and
    // the wall time.
    let row_of = |csv: &str, seed: &str| -> Vec<String> {
        let row = csv
            .lines()
            .find(|l| l.split(',').nth(1) == Some(seed))
            .expect("row of the seed");
        let cells: Vec<String> = row.split(',').map(String::from).collect();
        // The wall time and the setup's last: they vary from run to run.
        cells[1..cells.len() - 2].to_vec()
    };
    let replay_dir = violating_dir.join(format!("replay-{seed}"));
    let original = std::fs::read_to_string(violating_dir.join("metrics.csv")).expect("csv");
    let replayed = std::fs::read_to_string(replay_dir.join("metrics.csv")).expect("csv");
    assert_eq!(row_of(&original, seed), row_of(&replayed, seed));

    // Bad input: clear errors naming the problem.
    let bad = |content: &str, expected: &str| {
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, content).expect("write");
        let out = workcell(&[
            "evaluate",
            &path.display().to_string(),
            "--out",
            &dir.path().join("x").display().to_string(),
        ]);
        assert!(!out.status.success(), "{content}");
        let err = text(&out.stderr);
        assert!(err.contains(expected), "{content}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    };
    let cell_line = format!("cell = {:?}\n", cell.display().to_string());
    bad(
        &format!("{cell_line}[safety]\nd_min_m = 50.0\ndetection_m = 51.0\n"),
        "larger than the whole cell",
    );
    bad(
        &format!("{cell_line}[safety]\ngamma_per_s = -1.0\n"),
        "safety.gamma_per_s",
    );
    bad(
        &format!("{cell_line}control_period_s = 0.0025\n"),
        "not a multiple",
    );
    bad(
        &format!("{cell_line}control_period_s = 1e6\n"),
        "control_period_s: 1000000 is above the limit of 0.1",
    );
    // A key of the controller at the top level (where it was before the `[controller]`
    // table) says where it went.
    bad(
        &format!("{cell_line}catch_up_speed = 1.5\n"),
        "catch_up_speed is a key of the [controller] table now",
    );
    bad(
        &format!("{cell_line}[controller]\ncommand_lead_rad = 0.0\n"),
        "controller.command_lead_rad: must be > 0",
    );
    bad(
        &format!("{cell_line}[controller]\ncatch_up_speed = 0.5\n"),
        "controller.catch_up_speed: must be within 1 (off) and 3",
    );
    bad(
        &format!("{cell_line}[controller]\ncatch_up_speed = nan\n"),
        "controller.catch_up_speed: must be within 1 (off) and 3",
    );
    bad(
        &format!("{cell_line}[controller]\ncatch_up_margin_m = 0.0\n"),
        "controller.catch_up_margin_m: must be > 0 m beyond d_min",
    );
    bad(
        &format!("{cell_line}[controller]\ncatch_up_margin_m = nan\n"),
        "controller.catch_up_margin_m: must be > 0 m beyond d_min",
    );
    bad(
        &format!("{cell_line}[controller]\nyield_after_s = -1.0\n"),
        "controller.yield_after_s: must be >= 0",
    );
    bad(
        &format!("{cell_line}[controller]\nyield_resume_m = 0.0\n"),
        "controller.yield_resume_m",
    );
    bad(
        &format!("{cell_line}[controller]\nyield_motion = \"jump\"\n"),
        "yield_motion",
    );
    // Each key in range, together contradictory: pairs would enter the filter inside d_min.
    bad(
        &format!("{cell_line}[safety]\ndetection_m = 0.01\nd_min_m = 0.1\n"),
        "safety.detection_m",
    );
    bad(
        &format!("{cell_line}[perception]\ndropout = 1.5\n"),
        "perception.dropout",
    );
    bad(
        &format!("{cell_line}[safety]\nanticipation_s = nan\n"),
        "safety.anticipation_s",
    );
    // Only the oracle of the simulator can see the future, not a camera.
    bad(
        &format!("{cell_line}[perception]\nkind = \"noisy\"\nforesight_s = 0.5\n"),
        "perception.foresight_s: a key of the ground_truth perception, not of noisy",
    );
    bad(&format!("{cell_line}speed = 3\n"), "unknown field");
    bad(
        &format!(
            "{cell_line}[perception]\nkind = \"procnet\"\nweights = \"no/such.safetensors\"\n"
        ),
        "perception.weights",
    );
    bad(
        &format!("{cell_line}[perception]\nkind = \"procnet\"\ncamera = \"ceiling\"\n"),
        "no camera named \"ceiling\"",
    );
    bad("cell = \"missing.toml\"\n", "missing.toml");
    bad(
        &format!("{cell_line}[human_recorded]\nlibrary = \"nowhere.toml\"\n"),
        "human_recorded.library",
    );
    bad(
        &format!(
            "{cell_line}[human_recorded]\nlibrary = {:?}\nclips = [\"no/such\"]\n",
            concat!(env!("CARGO_MANIFEST_DIR"), "/data/mocap/library.toml")
        ),
        "\"no/such\" is not a clip",
    );
    bad(
        &format!(
            "{cell_line}[human_recorded]\nlibrary = {:?}\nend = \"bounce\"\n",
            concat!(env!("CARGO_MANIFEST_DIR"), "/data/mocap/library.toml")
        ),
        "unknown variant `bounce`",
    );
    for (set, expected) in [
        ("safety", "an override is KEY=VALUE"),
        ("cell.x=1", "'cell' is not a table"),
        ("safety.nope=1", "unknown field `nope`"),
        ("safety..gamma_per_s=1", "empty key"),
        ("safety.gamma_per_s=-2", "safety.gamma_per_s"),
    ] {
        let out = workcell(&["evaluate", &eval.display().to_string(), "--set", set]);
        assert!(!out.status.success(), "{set}");
        assert!(
            text(&out.stderr).contains(expected),
            "{set}: {}",
            text(&out.stderr)
        );
    }
    let out = workcell(&["evaluate", &eval.display().to_string(), "--episodes", "0"]);
    assert!(
        text(&out.stderr).contains("--episodes"),
        "{}",
        text(&out.stderr)
    );
}

#[path = "../robots/tests/support/example_robot_data.rs"]
mod example_robot_data;

#[test]
fn robot_add_copies_a_vendor_arm_that_scenarios_can_name() {
    let Some(data) = example_robot_data::data_dir() else {
        return;
    };
    let vendor = data.join("robots/ur_description/urdf/ur5_robot.urdf");
    let dir = tempfile::tempdir().expect("temp");
    let library = dir.path().join("library");
    let run = |args: &[&str]| {
        common::workcell_with_library(dir.path(), &library)
            .args(args)
            .output()
            .expect("run workcell")
    };
    let vendor_arg = vendor.to_string_lossy();
    let library_arg = library.to_string_lossy();
    let add = [
        "robot",
        "add",
        &vendor_arg,
        "--name",
        "my_ur5",
        "--into",
        &library_arg,
    ];
    let out = run(&add);
    assert!(
        out.status.success(),
        "{}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    let stdout = text(&out.stdout);
    assert!(stdout.contains("problems none found"), "{stdout}");
    assert!(stdout.contains("model = \"my_ur5\""), "{stdout}");
    if cfg!(feature = "mujoco") {
        // Built with MuJoCo: the cross-check ran on the copy and every check held.
        assert!(
            stdout.contains("verdict:") && !stdout.contains("FAIL"),
            "{stdout}"
        );
    } else {
        assert!(stdout.contains("cross-check skipped"), "{stdout}");
    }

    // The copy stands alone: relative mesh paths that resolve inside its folder.
    let folder = library.join("my_ur5");
    let urdf = std::fs::read_to_string(folder.join("my_ur5.urdf")).expect("urdf");
    assert!(!urdf.contains("package://"), "package URIs left");
    let original = std::fs::read_to_string(&vendor).expect("vendor urdf");
    assert_eq!(
        urdf.matches("<mesh").count(),
        original.matches("<mesh").count()
    );
    let source = std::fs::read_to_string(folder.join("source.toml")).expect("source.toml");
    assert!(source.contains("ur5_robot.urdf"), "{source}");
    let preview = std::fs::read(folder.join("preview.png")).expect("preview");
    assert!(preview.starts_with(b"\x89PNG"));
    let model = workcell::robots::RobotModel::from_urdf_file(
        folder.join("my_ur5.urdf"),
        &workcell::robots::PackageMap::new(),
    )
    .expect("the copy loads");
    let vendor_model =
        workcell::robots::RobotModel::from_urdf_file(&vendor, &workcell::robots::PackageMap::new())
            .expect("vendor loads");
    assert_eq!(model.dof(), vendor_model.dof());
    let q = [0.3, -1.1, 1.4, -0.5, 0.7, 0.2];
    let a = model.fk(Default::default(), &q).expect("fk");
    let b = vendor_model.fk(Default::default(), &q).expect("fk");
    assert_eq!(a.link_poses(), b.link_poses());

    // Listed, named in a scenario, simulated.
    let list = run(&["robot", "list"]);
    assert!(
        text(&list.stdout).contains("my_ur5"),
        "{}",
        text(&list.stdout)
    );
    let scenario = "[robot]\nmodel = \"my_ur5\"\ninitial_q = [0.0, -1.2, 1.5, -1.9, -1.57, 0.0]\n\
                    tool_link = \"tool0\"\n[robot.motion]\nkind = \"hold\"\n";
    std::fs::write(dir.path().join("cell.toml"), scenario).expect("scenario");
    let out = run(&["simulate", "cell.toml", "--seconds", "0.2", "--out", "sim"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(dir.path().join("sim/robot_joints.csv").is_file());

    // A second add under the same name is refused; bad names too; nothing is panicked.
    for (args, expected) in [
        (add.to_vec(), "already exists"),
        (
            [
                "robot",
                "add",
                &vendor_arg,
                "--name",
                "a b",
                "--into",
                &library_arg,
            ]
            .to_vec(),
            "letters, digits",
        ),
        (
            [
                "robot",
                "add",
                &vendor_arg,
                "--name",
                "human_arm",
                "--into",
                &library_arg,
            ]
            .to_vec(),
            "built-in",
        ),
        (
            [
                "robot",
                "add",
                "missing.urdf",
                "--name",
                "x",
                "--into",
                &library_arg,
            ]
            .to_vec(),
            "cannot read",
        ),
    ] {
        let out = run(&args);
        let stderr = text(&out.stderr);
        assert!(
            !out.status.success() && stderr.contains(expected),
            "{stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

/// `evaluate --shard K/N` runs every N-th episode; `report merge` of the N folders, in any
/// order, writes the report of one process over the same seeds: the same metrics rows (but
/// the wall time), violations, settings and plots, byte for byte. Shards of different
/// evaluations, a shard twice or one missing are refused, naming the folders.
#[test]
fn shards_merge_into_the_report_of_one_process() {
    let dir = tempfile::tempdir().expect("tempdir");
    let eval = dir.path().join("eval.toml");
    let cell = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/default.toml");
    // A short task and a large d_min: some episodes violate, so that violations.txt and the
    // worst-episode plots have something to order.
    std::fs::write(
        &eval,
        format!(
            "cell = {:?}\ntask_s = 2.0\n[safety]\nd_min_m = 0.3\ndetection_m = 1.0\n",
            cell.display().to_string()
        ),
    )
    .expect("write");
    let run = |out: &Path, extra: &[&str]| {
        let mut a = vec![
            "evaluate",
            eval.to_str().expect("utf-8"),
            "--episodes",
            "7",
            "--seed",
            "11",
            "--filter",
            "none",
            "--gltf",
            "2",
            "--out",
            out.to_str().expect("utf-8"),
        ];
        a.extend_from_slice(extra);
        let o = workcell(&a);
        assert!(o.status.success(), "{}", text(&o.stderr));
        o
    };
    let single = dir.path().join("single");
    run(&single, &[]);
    let shard = |k: usize| dir.path().join(format!("shard{k}"));
    for k in 1..=3 {
        run(&shard(k), &["--shard", &format!("{k}/3")]);
    }
    // Shard 2 of 3 of 7 episodes: episodes 1 and 4 (seeds 12 and 15).
    let csv2 = std::fs::read_to_string(shard(2).join("metrics.csv")).expect("csv");
    let seeds: Vec<&str> = csv2
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(1))
        .collect();
    assert_eq!(seeds, ["12", "15"]);

    let merged = dir.path().join("merged");
    let paths = [shard(3), shard(1), shard(2)].map(|p| p.display().to_string());
    let out = workcell(&[
        "report",
        "merge",
        &paths[0],
        &paths[1],
        &paths[2],
        "--out",
        merged.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("7 episodes, filter none"));
    let read = |d: &Path, f: &str| std::fs::read_to_string(d.join(f)).expect(f);
    // The last two columns, the wall time and the setup's, vary from run to run.
    let without_wall_time = |csv: String| -> Vec<String> {
        csv.lines()
            .map(|l| {
                let head = l.rsplit_once(',').map_or(l, |(head, _)| head);
                head.rsplit_once(',')
                    .map_or(head, |(head, _)| head)
                    .to_string()
            })
            .collect()
    };
    assert_eq!(
        without_wall_time(read(&single, "metrics.csv")),
        without_wall_time(read(&merged, "metrics.csv"))
    );
    for f in [
        "evaluation.toml",
        "separation.svg",
        "speed_scaling.svg",
        "perception_error.svg",
    ] {
        assert_eq!(read(&single, f), read(&merged, f), "{f}");
    }
    // The replay commands point into the merged folder; otherwise the list is the same.
    let single_list = read(&single, "violations.txt");
    assert!(single_list.lines().count() > 1, "no violation to list");
    assert_eq!(
        single_list.replace(
            single.to_str().expect("utf-8"),
            merged.to_str().expect("utf-8")
        ),
        read(&merged, "violations.txt")
    );
    let verdict = |d: &Path| {
        read(d, "summary.md")
            .lines()
            .skip_while(|l| !l.starts_with("## Verdict"))
            .take(5)
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(verdict(&single), verdict(&merged));
    // The 3D replays of the whole run's two worst episodes, byte for byte.
    let replays = |d: &Path| {
        let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(d.join("replays"))
            .expect("replays")
            .filter(|e| {
                e.as_ref()
                    .is_ok_and(|e| e.path().extension().is_some_and(|x| x == "glb"))
            })
            .map(|e| {
                let e = e.expect("entry");
                (
                    e.file_name().to_string_lossy().into_owned(),
                    std::fs::read(e.path()).expect("glb"),
                )
            })
            .collect();
        files.sort();
        files
    };
    let single_replays = replays(&single);
    assert_eq!(single_replays.len(), 2);
    assert!(single_replays.iter().all(|(_, b)| b.starts_with(b"glTF")));
    assert_eq!(single_replays, replays(&merged));
    // summary.html lists them (worst first) beside the report's tables.
    let page = read(&merged, "summary.html");
    assert!(page.contains("<h2>Verdict: VIOLATIONS"), "{page}");
    let links: Vec<&str> = page
        .match_indices("<a href=\"replays/episode-")
        .map(|(k, _)| &page[k + 9..k + 9 + page[k + 9..].find('"').expect("quote")])
        .collect();
    assert_eq!(links.len(), 2, "{page}");
    for link in links {
        assert!(merged.join(link).is_file(), "{link}");
        assert!(merged.join(link.replace(".glb", ".js")).is_file(), "{link}");
    }

    // Refusals.
    let merge = |dirs: &[&Path], expected: &str| {
        let mut a = vec!["report".to_string(), "merge".to_string()];
        a.extend(dirs.iter().map(|d| d.display().to_string()));
        a.extend([
            "--out".to_string(),
            dir.path().join("refused").display().to_string(),
        ]);
        let o = workcell(&a.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(!o.status.success(), "{dirs:?}");
        let err = text(&o.stderr);
        assert!(err.contains(expected), "{dirs:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    };
    merge(&[&shard(1), &shard(2)], "missing shards: 3/3");
    merge(&[&shard(1), &shard(2), &shard(2), &shard(3)], "given twice");
    merge(&[&shard(1), &single], "different evaluations");
    merge(&[&dir.path().join("nowhere")], "run.json");
    let garbage = dir.path().join("garbage");
    std::fs::create_dir_all(&garbage).expect("mkdir");
    std::fs::write(garbage.join("run.json"), "{\"format\": 1, \"settings\": 3").expect("write");
    merge(&[&garbage], "not a run record");
    std::fs::write(garbage.join("run.json"), "{\"format\": 99}").expect("write");
    merge(&[&garbage], "run record format 99");

    // A sweep's table from whole evaluations; a lone shard is refused.
    let table = dir.path().join("sweep");
    let out = workcell(&[
        "report",
        "sweep",
        single.to_str().expect("utf-8"),
        merged.to_str().expect("utf-8"),
        "--out",
        table.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let md = read(&table, "sweep.md");
    let rows: Vec<&str> = md
        .lines()
        .filter(|l| l.starts_with("| single") || l.starts_with("| merged"))
        .collect();
    assert_eq!(rows.len(), 2, "{md}");
    // Both rows show the same evaluation: the same counts after the name and the link.
    let counts = |row: &str| {
        row.split(" | ")
            .skip(3)
            .map(String::from)
            .collect::<Vec<_>>()
    };
    assert_eq!(counts(rows[0]), counts(rows[1]));
    assert!(table.join("sweep.png").is_file() && table.join("sweep.csv").is_file());
    let out = workcell(&[
        "report",
        "sweep",
        shard(2).to_str().expect("utf-8"),
        "--out",
        dir.path().join("sweep2").to_str().expect("utf-8"),
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("merge the shards first"),
        "{}",
        text(&out.stderr)
    );
    let other = dir.path().join("other");
    run(&other, &["--shard", "2/3", "--set", "safety.gamma_per_s=8"]);
    merge(
        &[&shard(1), &other, &shard(3)],
        "the evaluation (evaluation.toml) differs",
    );
    for (shard, expected) in [("0/3", "1..=N"), ("3", "K/N"), ("8/8", "without one")] {
        let o = workcell(&[
            "evaluate",
            eval.to_str().expect("utf-8"),
            "--episodes",
            "7",
            "--shard",
            shard,
            "--out",
            dir.path().join("x").to_str().expect("utf-8"),
        ]);
        assert!(!o.status.success(), "{shard}");
        assert!(
            text(&o.stderr).contains(expected),
            "{shard}: {}",
            text(&o.stderr)
        );
    }
}

/// `bench-perception` times the cell camera's frames through the shipped ProcNet and the
/// articulated fit and prints one row per stage; the first frame has no track, so it runs
/// the global search, and every frame is either tracked or searched.
#[test]
fn bench_perception_prints_each_stage() {
    let out = workcell(&["bench-perception", "--depth", "--frames", "4"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let table = text(&out.stdout);
    for row in [
        "| render (the simulator's camera) | 4 |",
        "| network (region of interest + ProcNet) | 4 |",
        "| **network + fit** | 4 |",
        // With depth and no weights named, the shipped network that reads depth, for the
        // default cell's whole body.
        "RGB-D, weights ",
        "procnet/weights/procnet-depth-human.safetensors, network and fit on 2 thread(s)",
    ] {
        assert!(table.contains(row), "no {row:?} in\n{table}");
    }
    // The stream's first frame is read three times before itself (`VIEW_READS`) and gives
    // a pose too (experiments/perception.md, "A new view read three times").
    assert!(table.contains("4 of 4 frames gave an estimate"), "{table}");
    let frames = |stage: &str| -> usize {
        table
            .lines()
            .find_map(|l| l.strip_prefix(&format!("| {stage} | ")))
            .and_then(|rest| rest.split(" |").next())
            .and_then(|n| n.parse().ok())
            .unwrap_or(0)
    };
    let (tracked, searched) = (
        frames("fit, tracked frames"),
        frames("fit with the global search (no track, or a poor one)"),
    );
    assert!(searched >= 1 && tracked + searched == 4, "{table}");
}

/// A BVH clip of the shipped Vicon skeleton translating at 1 m/s along x: every part's speed
/// is 1 m/s and its acceleration 0 (closed form), whatever the filter; the generator's rows
/// stand beside it with its wrist below the generator's 2.0 m/s cap.
#[test]
fn human_stats_measures_a_clip_beside_the_generator() {
    let dir = tempfile::tempdir().expect("temp dir");
    let joint = |name: &str, offset: &str, inner: &str| {
        format!(
            "JOINT {name}\n{{\nOFFSET {offset}\nCHANNELS 3 Zrotation Xrotation Yrotation\n{inner}}}\n"
        )
    };
    let end = "End Site\n{\nOFFSET 0 0 0\n}\n";
    let arm = |side: &str, x: &str| {
        joint(
            &format!("{side}_collar"),
            "0 300 0",
            &joint(
                &format!("{side}_upper_arm"),
                &format!("{x} 0 0"),
                &joint(
                    &format!("{side}_forearm"),
                    "0 -280 0",
                    &joint(&format!("{side}_hand"), "0 -250 0", end),
                ),
            ),
        )
    };
    let frames = 300;
    let mut bvh = format!(
        "HIERARCHY\nROOT hip\n{{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n{}}}\nMOTION\nFrames: {frames}\nFrame Time: 0.01\n",
        joint(
            "torso",
            "0 100 0",
            &format!(
                "{}{}{}",
                joint("neck", "0 300 0", &joint("head", "0 150 0", end)),
                arm("left", "150"),
                arm("right", "-150")
            )
        )
    );
    for f in 0..frames {
        // 10 mm a frame at 100 Hz: 1 m/s.
        bvh.push_str(&format!("{} 1000 0 0 0 0{}\n", 10 * f, " 0 0 0".repeat(11)));
    }
    let clip = dir.path().join("walk.bvh");
    std::fs::write(&clip, bvh).expect("write");
    let json = dir.path().join("stats.json");
    let out = workcell(&[
        "human",
        "stats",
        clip.to_str().expect("utf-8"),
        "--generated",
        "2",
        "--seconds",
        "20",
        "--json",
        json.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("json");
    let rows = report["rows"].as_array().expect("rows");
    let row = |part: &str, source: &str| {
        rows.iter()
            .find(|r| {
                r["part"] == part && r["source"].as_str().is_some_and(|s| s.starts_with(source))
            })
            .unwrap_or_else(|| panic!("no {part} row of {source}: {rows:?}"))
    };
    for part in ["wrist", "elbow", "shoulder", "head", "pelvis"] {
        let r = row(part, "clips given");
        for q in ["peak", "p999", "p99", "median"] {
            let v = r["speed_m_s"][q].as_f64().expect("speed");
            assert!((v - 1.0).abs() < 1e-6, "{part} {q}: {v}");
        }
        assert!(r["acceleration_m_s2"]["peak"].as_f64().expect("acc") < 1e-6);
    }
    let generated = row("wrist", "generator");
    let peak = generated["speed_m_s"]["peak"].as_f64().expect("speed");
    assert!(peak > 0.5 && peak <= 2.0, "{peak}");
    assert!(
        text(&out.stdout).contains("| wrist | clips given | 1 |"),
        "{}",
        text(&out.stdout)
    );
    // Retargeted onto the cell's arm: the arms stand straight out to the sides, which the
    // model's abducted arm reaches exactly.
    let glb = dir.path().join("walk.glb");
    let out = workcell(&[
        "human",
        "retarget",
        clip.to_str().expect("utf-8"),
        "--gltf",
        glb.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let shown = text(&out.stdout);
    assert!(shown.contains("| walk | 300 of 300 | 0 | 0 |"), "{shown}");
    // A glTF of the cell with the arm animated: 3 s at 30 frames a second.
    let bytes = std::fs::read(&glb).expect("glb");
    let document = gltf::Gltf::from_slice(&bytes).expect("a valid glTF");
    let animation = document.animations().next().expect("an animation");
    let times = animation
        .channels()
        .next()
        .expect("a channel")
        .sampler()
        .input();
    assert_eq!(times.count(), 90);
    // A table needs its frame rate said.
    let table = dir.path().join("t.txt");
    std::fs::write(&table, "0 0 0\n").expect("write");
    let out = workcell(&[
        "human",
        "stats",
        table.to_str().expect("utf-8"),
        "--generated",
        "0",
    ]);
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("give --rate-hz"),
        "{}",
        text(&out.stderr)
    );
}
