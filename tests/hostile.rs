//! Hostile input against the `workcell` binary: every input surface, as a careless or
//! malicious user would drive it. Each case was a crash, a hang or a half-written state
//! before; each must now be a clear error (exit 1, or clap's 2 for a bad flag) or work.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn workcell_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_workcell"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run workcell")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// `args` fails cleanly: exit 1 (or 2 from clap), `needle` on stderr, no panic.
fn refused_in(dir: &Path, args: &[&str], needle: &str) {
    let out = workcell_in(dir, args);
    let stderr = text(&out.stderr);
    assert!(
        matches!(out.status.code(), Some(1 | 2)),
        "{args:?}: {:?}\n{stderr}",
        out.status
    );
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    assert!(
        stderr.contains(needle),
        "{args:?}: '{needle}' not in\n{stderr}"
    );
}

fn refused(args: &[&str], needle: &str) {
    refused_in(root(), args, needle);
}

fn s(path: &Path) -> &str {
    path.to_str().expect("utf-8 path")
}

#[test]
fn counts_beyond_their_limits_are_refused_by_the_parser() {
    // `--batch 0` segfaulted inside the matrix library; the others aborted or hung.
    for (args, needle) in [
        (vec!["bench", "--batch", "0"], "0 is not from 1 to 64"),
        (
            vec!["bench", "--batch", "100000"],
            "100000 is not from 1 to 64",
        ),
        (vec!["bench", "--frames", "0"], "0 is not from 2 to 100"),
        // One frame left the timed training step no loss to differentiate: a panic.
        (vec!["bench", "--frames", "1"], "1 is not from 2 to 100"),
        (
            vec!["bench", "--threads", "100000"],
            "100000 is not from 1 to 256",
        ),
        (
            vec![
                "evaluate",
                "configs/evaluate.toml",
                "--episodes",
                "18446744073709551615",
            ],
            "is not from 1 to 1000000",
        ),
        (
            vec!["simulate", "configs/default.toml", "--seconds", "1e12"],
            "--seconds must be in (0, 3600]",
        ),
        (
            vec!["dataset", "show", "nowhere", "--columns", "100000"],
            "100000 is not from 1 to 64",
        ),
        (
            vec!["eval", "pose", "--threads", "0"],
            "0 is not from 1 to 256",
        ),
        (
            vec!["bench-perception", "--frames", "0"],
            "0 is not from 1 to 100000",
        ),
        (
            vec![
                "evaluate",
                "configs/evaluate.toml",
                "--set",
                "perception.occlusion=1.5",
            ],
            "perception.occlusion: out of range: 1.5",
        ),
        (
            vec![
                "evaluate",
                "configs/evaluate.toml",
                "--set",
                "perception.camera_fails_at_s=nan",
            ],
            "perception.camera_fails_at_s",
        ),
        (
            vec![
                "evaluate",
                "configs/evaluate.toml",
                "--set",
                "perception.uncertainty_floor_m=-1",
            ],
            "perception.uncertainty_floor_m: out of range: -1 (>= 0; leave the key out",
        ),
        (
            vec![
                "evaluate",
                "configs/evaluate.toml",
                "--set",
                "perception.frame_stride=0",
            ],
            "perception.frame_stride: out of range: 0 (1 to 8)",
        ),
        (
            vec![
                "evaluate",
                "configs/evaluate.toml",
                "--set",
                "perception.search_interval=9",
            ],
            "perception.search_interval: out of range: 9 (1 to 8)",
        ),
    ] {
        refused(&args, needle);
    }
}

/// A URDF of two links of 1 kg joined by one revolute joint, with `moment` as each link's
/// principal moments and `limit` as the joint's `<limit>` element.
fn two_links(moment: &str, limit: &str) -> String {
    let link = |name: &str| {
        format!(
            "<link name=\"{name}\"><inertial><mass value=\"1\"/><inertia ixx=\"{moment}\" \
             iyy=\"{moment}\" izz=\"{moment}\" ixy=\"0\" ixz=\"0\" iyz=\"0\"/></inertial>\
             <visual><geometry><box size=\"0.1 0.1 0.3\"/></geometry></visual></link>"
        )
    };
    format!(
        "<robot name=\"hostile\">{}{}<joint name=\"j\" type=\"revolute\"><parent link=\"a\"/>\
         <child link=\"b\"/><origin xyz=\"0 0 0.3\"/><axis xyz=\"0 1 0\"/>{limit}</joint></robot>",
        link("a"),
        link("b")
    )
}

const LIMIT: &str = "<limit lower=\"-1\" upper=\"1\" effort=\"100\" velocity=\"1\"/>";

#[test]
fn hostile_robots_are_checked_without_a_panic() {
    let dir = tempfile::tempdir().expect("tempdir");
    // Inertia of 1e-300 made rapier's motor clamp panic; it is noise, taken as 0.
    let tiny = dir.path().join("tiny.urdf");
    std::fs::write(&tiny, two_links("1e-300", LIMIT)).expect("write");
    let out = workcell_in(dir.path(), &["robot", "check", s(&tiny)]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    // 20,000 nested elements overflowed the stack.
    let deep = dir.path().join("deep.urdf");
    std::fs::write(
        &deep,
        format!(
            "<robot name=\"r\">{}{}</robot>",
            "<a>".repeat(20_000),
            "</a>".repeat(20_000)
        ),
    )
    .expect("write");
    refused_in(
        dir.path(),
        &["robot", "check", s(&deep)],
        "deeper than 256 levels",
    );
    // A COLLADA file of 1 kB that declares 4e9 triangles asked for 51 GB.
    let dae = dir.path().join("lie.dae");
    std::fs::write(
        &dae,
        "<COLLADA><library_geometries><geometry id=\"g\"><mesh><triangles count=\"4294967295\">\
         <input semantic=\"VERTEX\" source=\"#v\" offset=\"0\"/><p>0 1 2</p></triangles></mesh>\
         </geometry></library_geometries></COLLADA>",
    )
    .expect("write");
    let with_mesh = dir.path().join("mesh.urdf");
    std::fs::write(
        &with_mesh,
        two_links("0.01", LIMIT).replace(
            "<box size=\"0.1 0.1 0.3\"/>",
            "<mesh filename=\"lie.dae\"/>",
        ),
    )
    .expect("write");
    refused_in(
        dir.path(),
        &["robot", "check", s(&with_mesh)],
        "claims more values than",
    );
    // Meshes outside every package root are not read: /dev/zero read 4.2 GB.
    for uri in [
        "/dev/zero",
        "file:///etc/hostname",
        "package://root/.bashrc",
    ] {
        std::fs::write(
            &with_mesh,
            two_links("0.01", LIMIT).replace(
                "<box size=\"0.1 0.1 0.3\"/>",
                &format!("<mesh filename=\"{uri}\"/>"),
            ),
        )
        .expect("write");
        let out = workcell_in(dir.path(), &["robot", "check", s(&with_mesh)]);
        assert_eq!(out.status.code(), Some(1), "{uri}: {}", text(&out.stderr));
        assert!(
            text(&out.stderr).contains(&format!("mesh '{uri}'")),
            "{}",
            text(&out.stderr)
        );
    }
    // A chain of 200 joints took minutes (rapier's multibody is O(n^3) per step): refused.
    let mut chain = String::from("<robot name=\"chain\"><link name=\"l0\"/>");
    for i in 1..=200 {
        chain += &format!(
            "<link name=\"l{i}\"/><joint name=\"j{i}\" type=\"revolute\"><parent link=\"l{}\"/>\
             <child link=\"l{i}\"/><axis xyz=\"0 0 1\"/>{LIMIT}</joint>",
            i - 1
        );
    }
    let long = dir.path().join("chain.urdf");
    std::fs::write(&long, chain + "</robot>").expect("write");
    refused_in(
        dir.path(),
        &["robot", "check", s(&long)],
        "200 actuated joints",
    );
}

#[test]
fn robot_add_is_all_or_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let library = dir.path().join("library");
    let run = |args: &[&str]| {
        common::workcell_with_library(dir.path(), &library)
            .args(args)
            .output()
            .expect("run workcell")
    };
    // Limits of +-1e308 panicked at an unwrap in the preview; they mean "continuous".
    let wide = dir.path().join("wide.urdf");
    std::fs::write(
        &wide,
        two_links(
            "0.01",
            "<limit lower=\"-1e308\" upper=\"1e308\" effort=\"100\" velocity=\"1\"/>",
        ),
    )
    .expect("write");
    let add = |name: &str| {
        run(&[
            "robot",
            "add",
            s(&wide),
            "--name",
            name,
            "--into",
            s(&library),
        ])
    };
    let out = add("wide");
    assert!(
        out.status.success(),
        "{}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    assert!(library.join("wide/wide.urdf").is_file());
    assert!(library.join("wide/preview.png").is_file());

    // Killed half-way (as by Ctrl-C), an add leaves nothing a scenario could name.
    let mut child = common::workcell_with_library(dir.path(), &library)
        .args([
            "robot",
            "add",
            s(&wide),
            "--name",
            "killed",
            "--into",
            s(&library),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    let staging = library.join(".killed.staging");
    let started = std::time::Instant::now();
    while !staging.join("killed/killed.urdf").exists()
        && started.elapsed() < std::time::Duration::from_secs(60)
    {
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    child.kill().expect("kill");
    let _ = child.wait();
    assert!(
        !library.join("killed").exists(),
        "a killed add left the robot"
    );
    let listed = text(&run(&["robot", "list"]).stdout);
    assert!(
        listed.contains("wide") && !listed.contains("killed"),
        "{listed}"
    );
    // The next add of that name replaces the stale staging folder and succeeds.
    let out = add("killed");
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(!staging.exists());
    assert!(library.join("killed/killed.urdf").is_file());
}

/// Runs `args` with a standard output whose reading end is already closed.
fn with_closed_stdout(dir: &Path, args: &[&str]) -> Output {
    let (reader, writer) = std::io::pipe().expect("pipe");
    drop(reader);
    Command::new(env!("CARGO_BIN_EXE_workcell"))
        .args(args)
        .current_dir(dir)
        .stdout(writer)
        .stderr(Stdio::piped())
        .output()
        .expect("run workcell")
}

#[test]
fn a_closed_pipe_is_not_a_panic_and_files_are_still_written() {
    for args in [
        vec!["robot", "list"],
        vec!["robot", "check", "ur5e_kinematics"],
        vec!["simulate", "--print-defaults"],
        vec!["evaluate", "--print-defaults"],
        vec!["train", "--print-defaults", "--out", "unused"],
        vec!["dataset", "generate", "--print-defaults", "--out", "unused"],
    ] {
        let out = with_closed_stdout(root(), &args);
        let stderr = text(&out.stderr);
        assert!(out.status.success(), "{args:?}: {:?} {stderr}", out.status);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
    let dir = tempfile::tempdir().expect("tempdir");
    let out_dir = dir.path().join("sim");
    let scenario = root().join("configs/default.toml");
    let simulate = [
        "simulate",
        s(&scenario),
        "--seconds",
        "0.05",
        "--out",
        s(&out_dir),
    ];
    let out = with_closed_stdout(dir.path(), &simulate);
    assert!(out.status.success(), "{}", text(&out.stderr));
    for file in ["summary.json", "cell.svg", "robot_joints.csv"] {
        assert!(out_dir.join(file).is_file(), "{file}");
    }
    // No staging folder is left behind, and a second run without --force keeps the first
    // run's files: cell.svg among them (it was overwritten).
    let names: Vec<String> = std::fs::read_dir(&out_dir)
        .expect("out")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!names.iter().any(|n| n.starts_with('.')), "{names:?}");
    for file in [
        "summary.json",
        "robot_joints.csv",
        "human_poses.csv",
        "trajectories.svg",
    ] {
        std::fs::remove_file(out_dir.join(file)).expect("remove");
    }
    refused_in(dir.path(), &simulate, "already holds cell.svg");
}

/// A small dataset (2 sequences per pair of 4 frames at 32 px) in `dir/data`.
fn small_dataset(dir: &Path) -> (PathBuf, PathBuf) {
    let config = dir.join("data.toml");
    std::fs::write(
        &config,
        format!(
            "scenario = {:?}\nsequences_per_pair = 1\nframes = 4\nwidth_px = 32\nheight_px = 32\n\
             input_px = 32\nstart_s = [0.5, 1.0]\nsplits = [0.5, 0.0, 0.5]\n[cell_cameras]\n\
             enabled = false\n",
            s(&root().join("configs/default.toml"))
        ),
    )
    .expect("config");
    let data = dir.join("data");
    let out = workcell_in(dir, &generate_args(&config, &data));
    assert!(out.status.success(), "{}", text(&out.stderr));
    (config, data)
}

/// `dataset generate --config CONFIG --out OUT`.
fn generate_args<'a>(config: &'a Path, out: &'a Path) -> [&'a str; 6] {
    [
        "dataset",
        "generate",
        "--config",
        s(config),
        "--out",
        s(out),
    ]
}

#[test]
fn datasets_are_never_trusted_blindly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (config, data) = small_dataset(dir.path());
    let generate = generate_args(&config, &data);
    // A deleted PNG: the rerun regenerates its sequence instead of certifying the dataset.
    let png = data.join("seq_00000/frame_002_rgb.png");
    let before = std::fs::read(&png).expect("png");
    std::fs::remove_file(&png).expect("delete");
    let out = workcell_in(dir.path(), &generate);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(std::fs::read(&png).expect("regenerated"), before);

    // Manifest values are checked before anything is allocated from them.
    let manifest_path = data.join("manifest.json");
    let honest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&manifest_path).expect("manifest")).expect("json");
    for (edit, needle) in [
        (
            Box::new(|m: &mut serde_json::Value| m["width_px"] = 65535.into())
                as Box<dyn Fn(&mut serde_json::Value)>,
            "frames of 65535x32 pixels",
        ),
        (
            Box::new(|m: &mut serde_json::Value| {
                m["sequences"][0]["frames"] = 1_000_000_000_000_u64.into();
            }),
            "has 1000000000000 frames",
        ),
        (
            Box::new(|m: &mut serde_json::Value| {
                m["sequences"][0]["frames"] = u64::MAX.into();
            }),
            "has 18446744073709551615 frames",
        ),
    ] {
        let mut m = honest.clone();
        edit(&mut m);
        std::fs::write(&manifest_path, serde_json::to_vec(&m).expect("json")).expect("write");
        let sheet = dir.path().join("sheet.png");
        refused_in(
            dir.path(),
            &["dataset", "show", s(&data), "--out", s(&sheet)],
            needle,
        );
    }
    std::fs::write(&manifest_path, serde_json::to_vec(&honest).expect("json")).expect("write");

    // Without config.toml, existing sequences are not adopted under whatever config runs.
    std::fs::remove_file(data.join("config.toml")).expect("remove stamp");
    refused_in(dir.path(), &generate, "no config.toml");

    // A folder that cannot be made is a write failure, and says so (it said "cannot read").
    let blocker = dir.path().join("a-file");
    std::fs::write(&blocker, "x").expect("write");
    let inside = blocker.join("data");
    refused_in(dir.path(), &generate_args(&config, &inside), "cannot write");
}

/// `robot add` checks the name before it touches any file: a name with `..` removed any
/// `*.staging` folder it reached (`<into>/.<name>.staging` was removed first).
#[test]
fn robot_add_checks_the_name_before_it_removes_anything() {
    let dir = tempfile::tempdir().expect("tempdir");
    let victim = dir.path().join("x/victim.staging");
    std::fs::create_dir_all(&victim).expect("victim");
    std::fs::write(victim.join("important.txt"), "keep").expect("write");
    let into = dir.path().join("x/lib/sub");
    std::fs::create_dir_all(&into).expect("into");
    let urdf = dir.path().join("r.urdf");
    std::fs::write(&urdf, two_links("0.01", "")).expect("urdf");
    for name in ["/../../victim", "../../victim", "..", "a/b", ""] {
        refused_in(
            dir.path(),
            &["robot", "add", s(&urdf), "--name", name, "--into", s(&into)],
            "letters, digits, '_' or '-'",
        );
        assert_eq!(
            std::fs::read_to_string(victim.join("important.txt")).expect("the victim survives"),
            "keep",
            "{name:?}"
        );
    }
    assert_eq!(
        std::fs::read_dir(&into).expect("into").count(),
        0,
        "nothing was made in --into"
    );
}

/// Runs `args` in `dir`; refused (as [`refused_in`]) within `seconds`, else killed and
/// failed: a FIFO or a device read as a file hung or read gigabytes before.
fn refused_within(dir: &Path, args: &[&str], needle: &str, seconds: u64) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_workcell"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let started = std::time::Instant::now();
    loop {
        if child.try_wait().expect("wait").is_some() {
            break;
        }
        if started.elapsed() > std::time::Duration::from_secs(seconds) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{args:?} still ran after {seconds} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let out = child.wait_with_output().expect("output");
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    assert!(
        stderr.contains(needle),
        "{args:?}: '{needle}' not in\n{stderr}"
    );
}

/// Every file the project reads is a regular file of bounded size: a FIFO as the
/// evaluation, the scenario, a training recipe, a dataset's manifest or a shard's record
/// hung, and /dev/zero in the same places was read to 4.2 GB before "out of memory".
#[cfg(unix)]
#[test]
fn special_files_are_refused_wherever_a_file_is_read() {
    let dir = tempfile::tempdir().expect("tempdir");
    let fifo = |name: &str| {
        let path = dir.path().join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).expect("mkdir");
        }
        let made = Command::new("mkfifo").arg(&path).status().expect("mkfifo");
        assert!(made.success());
        path
    };
    let eval_fifo = fifo("eval.toml");
    let cell_fifo = fifo("cell.toml");
    let train_fifo = fifo("train.toml");
    fifo("data/manifest.json");
    fifo("shard/run.json");
    let eval = dir.path().join("ok.toml");
    std::fs::write(&eval, "cell = \"cell.toml\"\n").expect("eval");
    let zero_cell = format!("cell={:?}", "/dev/zero");
    let cases: Vec<Vec<&str>> = vec![
        vec!["evaluate", s(&eval_fifo)],
        vec!["evaluate", "/dev/zero"],
        vec!["evaluate", s(&eval)],
        vec!["evaluate", s(&eval), "--set", &zero_cell],
        vec!["simulate", s(&cell_fifo)],
        vec!["train", "--config", s(&train_fifo), "--out", "run"],
        vec!["train", "--config", "/dev/zero", "--out", "run"],
        vec!["dataset", "show", "data"],
        vec!["report", "merge", "shard"],
        vec![
            "dataset",
            "generate",
            "--config",
            "/dev/zero",
            "--out",
            "d2",
        ],
    ];
    for args in cases {
        refused_within(dir.path(), &args, "not a regular file", 20);
    }
}

/// `threads` in a training recipe has the limits of `--threads`: 5000 panicked in rayon
/// after 17 s, 100000 ran past a minute with no output.
#[test]
fn a_training_recipe_asks_for_at_most_256_threads() {
    let dir = tempfile::tempdir().expect("tempdir");
    for threads in ["0", "5000", "100000"] {
        let recipe = dir.path().join(format!("t{threads}.toml"));
        std::fs::write(&recipe, format!("threads = {threads}\n")).expect("recipe");
        refused_within(
            dir.path(),
            &["train", "--config", s(&recipe), "--out", "run"],
            &format!("threads: 1..=256, got {threads}"),
            20,
        );
    }
}

/// Settings that no run needs are refused, naming the key and the limit.
#[test]
fn settings_beyond_reason_are_refused() {
    // The second episode's seed wrapped around to 0.
    refused(
        &[
            "evaluate",
            "configs/evaluate.toml",
            "--seed",
            "18446744073709551615",
            "--episodes",
            "2",
        ],
        "at most --seed 18446744073709551614",
    );
    // A 300-digit task-time ratio.
    refused(
        &[
            "evaluate",
            "configs/evaluate.toml",
            "--set",
            "task_s=1e-300",
        ],
        "task_s: 1e-300 is below the limit of 0.1 s",
    );
    for key in ["safety.anticipation_s", "safety.escape_horizon_s"] {
        refused(
            &[
                "evaluate",
                "configs/evaluate.toml",
                "--set",
                &format!("{key}=1e9"),
            ],
            &format!("{key}: 1000000000 s is beyond the limit of 3 s"),
        );
    }
}

/// `--print-defaults` with `--config` prints that configuration, every default filled in
/// (it printed the defaults and ignored the file).
#[test]
fn print_defaults_reads_the_config_it_is_given() {
    let dir = tempfile::tempdir().expect("tempdir");
    let config = dir.path().join("data.toml");
    std::fs::write(&config, "frames = 7\nwidth_px = 48\n").expect("config");
    let out = workcell_in(
        dir.path(),
        &[
            "dataset",
            "generate",
            "--print-defaults",
            "--config",
            s(&config),
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let printed = text(&out.stdout);
    assert!(printed.contains("frames = 7"), "{printed}");
    assert!(printed.contains("width_px = 48"), "{printed}");
    assert!(
        printed.contains("sequences_per_pair"),
        "defaults filled in: {printed}"
    );
    let recipe = dir.path().join("train.toml");
    std::fs::write(&recipe, "steps = 123\n").expect("recipe");
    let out = workcell_in(
        dir.path(),
        &["train", "--print-defaults", "--config", s(&recipe)],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let printed = text(&out.stdout);
    assert!(printed.contains("steps = 123"), "{printed}");
    assert!(
        printed.contains("batch = "),
        "defaults filled in: {printed}"
    );
}

/// A merged report is the report of its episodes: a record edited into "no violation",
/// holding NaN or -inf, a seed twice, settings that contradict its evaluation or a replay
/// outside its folder is refused, naming the folder and the field. An output that is one of
/// the inputs is refused too (`--force` overwrote that shard's record).
#[test]
fn run_records_that_lie_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let eval = dir.path().join("eval.toml");
    std::fs::write(
        &eval,
        format!(
            "cell = {:?}\ntask_s = 2.0\n[perception]\nkind = \"noisy\"\n",
            s(&root().join("configs/default.toml"))
        ),
    )
    .expect("eval");
    let shard = |k: usize| dir.path().join(format!("shard{k}"));
    for k in 1..=2 {
        let out = workcell_in(
            dir.path(),
            &[
                "evaluate",
                s(&eval),
                "--episodes",
                "2",
                "--filter",
                "none",
                "--shard",
                &format!("{k}/2"),
                "--out",
                s(&shard(k)),
            ],
        );
        assert!(out.status.success(), "{}", text(&out.stderr));
    }
    let record = |k: usize| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(shard(k).join("run.json")).expect("run.json"))
            .expect("json")
    };
    let honest = record(1);
    let merged = dir.path().join("merged");
    let merge = |out: &Path, extra: &[&str]| {
        let mut args: Vec<String> = ["report", "merge"].map(String::from).to_vec();
        args.extend([shard(1), shard(2)].map(|p| p.display().to_string()));
        args.extend(["--out".to_string(), out.display().to_string()]);
        args.extend(extra.iter().map(|a| a.to_string()));
        args
    };
    let out = workcell_in(
        dir.path(),
        &merge(&merged, &[])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));

    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: Vec<(Edit, &str)> = vec![
        (
            // Edited into "no violation": a contact at -1 m with nothing counted.
            Box::new(|r| {
                let m = &mut r["metrics"][0];
                m["min_separation_m"] = serde_json::json!(-1.0);
                for key in ["violations", "contacts_moving", "contacts_standing"] {
                    m[key] = serde_json::json!(0);
                }
                m["violation_s"] = serde_json::json!(0.0);
                m["violation_moving_s"] = serde_json::json!(0.0);
            }),
            "metrics[0] (episode 0).violations = 0 (0 s below d_min) contradicts min_separation_m = -1",
        ),
        (
            Box::new(|r| r["metrics"][0]["min_separation_m"] = serde_json::json!("NaN")),
            "min_separation_m = NaN: must be a number",
        ),
        (
            Box::new(|r| r["metrics"][0]["min_separation_m"] = serde_json::json!("-inf")),
            "min_separation_m = -inf: must be a number",
        ),
        (
            Box::new(|r| r["metrics"][0]["violation_s"] = serde_json::json!("inf")),
            "violation_s = inf: must be finite and >= 0",
        ),
        (
            Box::new(|r| r["metrics"][0]["seed"] = serde_json::json!(2)),
            "seed = 2: episode 0 of a run from seed 1 has seed 1",
        ),
        (
            Box::new(|r| r["settings"]["d_min_m"] = serde_json::json!(0.5)),
            "settings.d_min_m = 0.5 contradicts the evaluation's safety.d_min_m",
        ),
        (
            Box::new(|r| {
                r["replays"] = serde_json::json!([[0, "../../../etc/passwd"]]);
            }),
            "is not a path inside the folder",
        ),
    ];
    let run_json = shard(1).join("run.json");
    for (edit, needle) in cases {
        let mut tampered = honest.clone();
        edit(&mut tampered);
        std::fs::write(&run_json, serde_json::to_vec(&tampered).expect("json")).expect("write");
        let args = merge(&dir.path().join("refused"), &[]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused_in(dir.path(), &args, needle);
        refused_in(dir.path(), &args, &shard(1).display().to_string());
        // A single record is read the same way by `report sweep`.
        refused_in(
            dir.path(),
            &["report", "sweep", s(&shard(1)), "--out", "sweep"],
            needle,
        );
    }
    std::fs::write(&run_json, serde_json::to_vec(&honest).expect("json")).expect("write");

    // The merged report into a shard's own folder would overwrite that shard's record.
    let before = std::fs::read(&run_json).expect("run.json");
    let args = merge(&shard(1), &["--force"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    refused_in(dir.path(), &args, "is the shard folder");
    assert_eq!(std::fs::read(&run_json).expect("run.json"), before);
}

/// Every file the product reads goes through the one bounded reader
/// (`workcell_robots::input`): no other code of the library crates or the binary opens a file
/// for reading by itself (test modules, after the first `#[cfg(test)]`, may).
#[test]
fn every_file_is_read_through_the_bounded_reader() {
    let readers = [
        "fs::read(",
        "fs::read_to_string(",
        "File::open(",
        "fs::copy(",
        "OpenOptions::new().read",
    ];
    // The reader itself, the lock on an output folder and the atomic writer's sync of its
    // own temporary file (opened, never read).
    let allowed = [
        ("robots/src/input.rs", "File::open("),
        ("robots/src/output.rs", "File::open("),
        ("src/cli/mod.rs", "File::open("),
    ];
    let mut found = Vec::new();
    for dir in [
        "src",
        "robots/src",
        "mocap/src",
        "sim/src",
        "sim/render/src",
        "procnet/src",
        "perception/src",
        "safety/src",
    ] {
        for (path, product) in common::product_sources(&root().join(dir)) {
            let relative = path
                .strip_prefix(root())
                .expect("inside")
                .to_string_lossy()
                .replace('\\', "/");
            for (n, line) in product.lines().enumerate() {
                if line.trim_start().starts_with("//") {
                    continue;
                }
                for reader in readers {
                    if line.contains(reader) && !allowed.contains(&(relative.as_str(), reader)) {
                        found.push(format!("{relative}:{}: {}", n + 1, line.trim()));
                    }
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "files read around the bounded reader:\n{}",
        found.join("\n")
    );
}
