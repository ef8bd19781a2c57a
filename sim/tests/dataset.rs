//! The dataset: determinism, labels consistent with the stored masks, occlusion in the
//! targeted level, resuming after a killed run, and bad input.

use std::path::{Path, PathBuf};

use workcell_sim::SimError;
use workcell_sim::dataset::{Dataset, DatasetConfig, Generator, Split};
use workcell_sim::render::Class;

fn scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/default.toml")
}

/// A small dataset of the default cell: one sequence per pair, 3 frames of 96x96.
fn small_config(dir: &Path) -> PathBuf {
    let config = DatasetConfig {
        scenario: scenario(),
        sequences_per_pair: 1,
        frames: 3,
        width_px: 96,
        height_px: 96,
        start_s: [0.5, 1.5],
        ..DatasetConfig::default()
    };
    let path = dir.join("dataset.toml");
    std::fs::write(&path, config.to_toml()).unwrap();
    path
}

fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn a_dataset_is_reproducible_and_its_labels_match_its_masks() {
    let tmp = tempfile::tempdir().unwrap();
    let config = small_config(tmp.path());
    let generator = Generator::from_file(&config).unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let report = generator.generate(&a, &|_| {}).unwrap();
    assert_eq!(report.generated, 9);
    generator.generate(&b, &|_| {}).unwrap();
    let (fa, fb) = (files(&a), files(&b));
    assert_eq!(fa.len(), 2 + 9 * (1 + 3 * 6));
    assert!(fa == fb, "two runs of one configuration differ");

    let dataset = Dataset::open(&a).unwrap();
    let m = &dataset.manifest;
    // Every (distance, level) pair once; with one sequence per pair, all go to training.
    let mut pairs: Vec<_> = m
        .sequences
        .iter()
        .map(|s| (s.distance_class.clone(), s.occlusion_level.clone()))
        .collect();
    pairs.sort();
    pairs.dedup();
    assert_eq!(pairs.len(), 9);
    assert_eq!(dataset.entries(Some(Split::Train)).count(), 9);

    let config = &generator.config;
    let forearm = Class::Forearm as u8;
    let (mut frames, mut in_level) = (0, 0);
    for s in dataset.sequences(None) {
        let s = s.unwrap();
        assert_eq!(s.len(), 3);
        assert_eq!(s.rgb.len(), 3 * 3 * 96 * 96);
        assert!(s.rgb.iter().all(|v| (0.0..=1.0).contains(v)));
        let n = s.pixels();
        let level = config
            .occlusion_levels
            .iter()
            .find(|l| l.name == s.entry.occlusion_level)
            .unwrap();
        for t in 0..s.len() {
            let rgb = s.rgb_frame(t);
            let classes = s.class_frame(t);
            let (visible, occluder, amodal) = (
                &s.visible[t * n..][..n],
                &s.occluder[t * n..][..n],
                &s.amodal_forearm[t * n..][..n],
            );
            for p in 0..n {
                if occluder[p] == 1 {
                    assert_eq!([rgb[p], rgb[n + p], rgb[2 * n + p]], [0.0; 3]);
                    assert_eq!(visible[p], 0);
                } else {
                    assert_eq!(visible[p], classes[p]);
                }
                // The forearm seen in the scene is inside the forearm rendered alone.
                if classes[p] == forearm {
                    assert_eq!(amodal[p], 1);
                }
            }
            // The stored occlusion is the stored masks' hidden over all forearm pixels.
            let all = amodal.iter().filter(|&&v| v == 1).count();
            let seen = (0..n).filter(|&p| visible[p] == forearm).count();
            let label = s.labels[t].part(Class::Forearm).unwrap();
            assert_eq!(label.pixels_amodal as usize, all);
            assert_eq!(label.pixels_visible as usize, seen);
            if all > 0 {
                let expected = 1.0 - seen as f64 / all as f64;
                assert!((label.occlusion.unwrap() - expected).abs() < 1e-12);
                frames += 1;
                let o = label.occlusion.unwrap();
                in_level += usize::from(o >= level.range[0] && o <= level.range[1]);
                if !(o >= level.range[0] && o <= level.range[1]) {
                    eprintln!(
                        "seq {} {} {:?} frame {t}: {o:.3} amodal {all} natural {:?} attempts {}",
                        s.entry.index,
                        level.name,
                        s.entry.distance_class,
                        label.natural_occlusion,
                        s.entry.attempts
                    );
                }
            } else {
                assert_eq!(label.occlusion, None);
            }
            // The forearm's pose is in front of the camera.
            assert!(label.X_CP.xyz_m[2] > 0.0);
        }
    }
    // The occluder is sized per frame; a few pixels of a thin forearm can still jump a level.
    assert!(
        frames >= 24,
        "forearm in view in only {frames} of 27 frames"
    );
    eprintln!("{in_level} of {frames} frames in their level");
    assert!(
        in_level * 10 >= frames * 9,
        "{in_level} of {frames} frames in their level"
    );
}

#[test]
fn a_killed_run_leaves_nothing_the_loader_accepts_and_a_rerun_completes_it() {
    let tmp = tempfile::tempdir().unwrap();
    let config = small_config(tmp.path());
    let generator = Generator::from_file(&config).unwrap();
    let out = tmp.path().join("out");
    generator.generate(&out, &|_| {}).unwrap();
    let complete = files(&out);
    // What a kill leaves: no manifest, a half-written sequence, a missing one.
    std::fs::remove_file(out.join("manifest.json")).unwrap();
    std::fs::rename(out.join("seq_00004"), out.join(".seq_00004.partial")).unwrap();
    std::fs::remove_file(out.join(".seq_00004.partial/frame_002_rgb.png")).unwrap();
    std::fs::remove_dir_all(out.join("seq_00007")).unwrap();
    let err = Dataset::open(&out).unwrap_err();
    assert!(err.to_string().contains("not a finished dataset"), "{err}");
    let report = generator.generate(&out, &|_| {}).unwrap();
    assert_eq!(report.generated, 2);
    let again = files(&out);
    for (a, b) in again.iter().zip(&complete) {
        assert_eq!(a.0, b.0);
        assert!(a.1 == b.1, "{} differs", a.0.display());
    }
    assert_eq!(again.len(), complete.len());

    // A dataset of another configuration in the same folder is refused.
    let other = Generator::new(
        DatasetConfig {
            seed: 99,
            ..generator.config.clone()
        },
        &config,
    )
    .unwrap();
    let err = other.generate(&out, &|_| {}).unwrap_err();
    assert!(err.to_string().contains("another configuration"), "{err}");

    // A corrupt frame is an error naming it.
    std::fs::write(
        out.join("seq_00001/frame_001_class.png"),
        b"\x89PNG\r\n\x1a\n",
    )
    .unwrap();
    let dataset = Dataset::open(&out).unwrap();
    let entry = dataset
        .manifest
        .sequences
        .iter()
        .find(|s| s.index == 1)
        .unwrap();
    let err = dataset.load(entry).unwrap_err();
    assert!(err.to_string().contains("frame_001_class.png"), "{err}");
}

#[test]
fn bad_dataset_configurations_name_the_key() {
    let cases = [
        ("frames = 0", "frames"),
        ("width_px = 0", "width_px"),
        ("rate_hz = -30.0", "rate_hz"),
        ("splits = [0.5, 0.1, 0.1]", "splits"),
        ("occluders = []", "occluders"),
        (
            "[[distances]]\nname = \"x\"\nrange_m = [3.0, 1.0]\nfov_y_deg = 40.0",
            "distances[0].range_m",
        ),
        (
            "[[occlusion_levels]]\nname = \"x\"\nrange = [0.5, 1.5]",
            "occlusion_levels[0].range",
        ),
        ("colour = true", "colour"),
    ];
    for (text, key) in cases {
        let err = DatasetConfig::from_toml(text, Path::new("bad.toml")).unwrap_err();
        assert!(
            matches!(err, SimError::Invalid { .. } | SimError::Parse { .. }),
            "{text}: {err}"
        );
        assert!(err.to_string().contains(key), "{text}: {err}");
    }
    // A missing scenario names the file.
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("d.toml");
    std::fs::write(&path, "scenario = \"nowhere.toml\"").unwrap();
    let err = Generator::from_file(&path).unwrap_err();
    assert!(err.to_string().contains("nowhere.toml"), "{err}");
}
