//! The dataset: determinism, labels consistent with the stored masks, regions of interest
//! consistent with their cameras, depth, occlusion in the targeted level, resuming after a
//! killed run, and bad input.

use std::path::{Path, PathBuf};

use workcell_robots::math::Pose;
use workcell_sim::SimError;
use workcell_sim::dataset::{
    CropPolicy, Dataset, DatasetConfig, GeneratedFrame, Generator, Split, Timing,
};
use workcell_sim::render::dataset::ViewSource;
use workcell_sim::render::image::PixelKind;
use workcell_sim::render::roi::{Roi, RoiKind};
use workcell_sim::render::{Camera, Class, CpuRenderer, MaskBatch, RenderMesh, Renderer};

fn scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/default.toml")
}

/// A small dataset of the default cell: one sequence per pair (3 distance classes and the
/// cell's camera, 3 levels: 12), three to an episode, 3 frames of 160x120 read at 64x64.
fn small_config(dir: &Path) -> PathBuf {
    let config = DatasetConfig {
        scenario: scenario(),
        sequences_per_pair: 1,
        sequences_per_episode: 3,
        frames: 3,
        width_px: 160,
        height_px: 120,
        input_px: 64,
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

/// A dataset file's `human_model` replaces its scenario's human: a catalogue name as it is,
/// a URDF relative to the dataset file (not the scenario's folder), made absolute; without
/// the key the scenario's own.
#[test]
fn a_datasets_human_model_replaces_the_scenarios() {
    let tmp = tempfile::tempdir().unwrap();
    let write = |name: &str, model: Option<&str>| {
        let config = DatasetConfig {
            scenario: scenario(),
            human_model: model.map(str::to_string),
            ..DatasetConfig::default()
        };
        let path = tmp.path().join(name);
        std::fs::write(&path, config.to_toml()).unwrap();
        Generator::from_file(&path).unwrap().human().model
    };
    assert_eq!(write("own.toml", None), "human");
    assert_eq!(write("arm.toml", Some("human_arm")), "human_arm");
    let urdf = write("urdf.toml", Some("people/me.urdf"));
    assert_eq!(
        std::path::Path::new(&urdf),
        std::path::absolute(tmp.path().join("people/me.urdf")).unwrap()
    );
}

#[test]
fn a_dataset_is_reproducible_and_its_labels_match_its_masks() {
    let tmp = tempfile::tempdir().unwrap();
    let config = small_config(tmp.path());
    let generator = Generator::from_file(&config).unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let report = generator.generate(&a, &|_| {}).unwrap();
    assert_eq!(report.generated, 12);
    generator.generate(&b, &|_| {}).unwrap();
    let (fa, fb) = (files(&a), files(&b));
    assert_eq!(fa.len(), 2 + 12 * (1 + 3 * 7));
    assert!(fa == fb, "two runs of one configuration differ");
    format_2_depth_is_read_with_the_occluder_in_front(&b);

    let dataset = Dataset::open(&a).unwrap();
    let m = &dataset.manifest;
    assert_eq!((m.width_px, m.height_px), (64, 64));
    // Every (source, distance, level) once; with one sequence per pair, all go to training.
    let mut pairs: Vec<_> = m
        .sequences
        .iter()
        .map(|s| {
            (
                s.source.clone(),
                s.distance_class.clone(),
                s.occlusion_level.clone(),
            )
        })
        .collect();
    pairs.sort();
    pairs.dedup();
    assert_eq!(pairs.len(), 12);
    let cell = pairs
        .iter()
        .filter(|p| p.0 == ViewSource::Camera("front".into()))
        .count();
    assert_eq!(cell, 3, "{pairs:?}");
    assert_eq!(dataset.entries(Some(Split::Train)).count(), 12);
    // The tables' row order is the configuration's, the cell's camera after the paper's
    // classes, whatever they are named.
    assert_eq!(
        dataset.label_order(),
        (
            vec![
                "short".to_string(),
                "medium".into(),
                "large".into(),
                "front camera".into()
            ],
            vec!["light".to_string(), "medium".into(), "heavy".into()]
        )
    );
    // Three sequences to an episode.
    let seeds: Vec<u64> = m.sequences.iter().map(|s| s.seed).collect();
    assert!(seeds[0] == seeds[2] && seeds[2] != seeds[3], "{seeds:?}");

    let config = &generator.config;
    let forearm = Class::Forearm as u8;
    // The forearm as the frames show it: the dataset's human in the default (flesh) look.
    let mut human = workcell_robots::RobotModel::from_catalogue(&generator.human().model).unwrap();
    human.retain_visuals(|g| workcell_robots::HumanLook::Flesh.shows(g.name.as_deref()));
    let mut forearm_mesh = RenderMesh::default();
    for g in &human.links()[human.link_id("forearm").unwrap()].visuals {
        forearm_mesh.append(&RenderMesh::from_geometry(g, [0.8; 3]), &Pose::IDENTITY);
    }
    let (mut frames, mut in_level) = (0, 0);
    for s in dataset.sequences(None) {
        let s = s.unwrap();
        assert_eq!(s.len(), 3);
        assert_eq!(s.rgb.len(), 3 * 3 * 64 * 64);
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
            // The stored frame's camera sees the region of interest of the native camera
            // at the stored size (workcell_render::roi::Roi::camera).
            let labels = &s.labels[t];
            let roi = labels
                .roi
                .expect("frames from format 2 on record their region");
            let native = Camera::from(&roi.native);
            let expected = roi.roi.camera(&native, 64).unwrap();
            assert_eq!(Camera::from(&labels.camera), expected);
            if labels.source == ViewSource::Paper {
                assert_eq!((native.width, native.height), (160, 120));
            } else {
                assert_eq!(labels.source, ViewSource::Camera("front".into()));
                assert_eq!((native.width, native.height), (640, 480));
            }
            // Depth: 16-bit mm; the forearm's pixels lie within a forearm's length of its
            // link frame's depth, except under the occluder, which is seen at its own depth.
            let depth_png = dataset
                .root
                .join(&s.entry.dir)
                .join(&workcell_sim::render::dataset::frame_files(t)[6]);
            let (dw, dh, kind, bytes) = workcell_sim::render::image::read_png(&depth_png).unwrap();
            assert_eq!((dw, dh, kind), (64, 64, PixelKind::Gray16));
            // (interior pixels: at a boundary the nearest native pixel may be behind it)
            let side = 64;
            let interior = |p: usize| {
                let (x, y) = (p % side, p / side);
                x > 0
                    && y > 0
                    && x + 1 < side
                    && y + 1 < side
                    && [p - 1, p + 1, p - side, p + side]
                        .iter()
                        .all(|&q| classes[q] == forearm)
            };
            for p in (0..n).filter(|&p| classes[p] == forearm && interior(p)) {
                let mm = u16::from_be_bytes([bytes[2 * p], bytes[2 * p + 1]]);
                let d = f64::from(mm) / 1000.0;
                if occluder[p] == 1 {
                    assert_eq!(
                        mm,
                        (1000.0 * workcell_sim::render::occlusion::OCCLUDER_DEPTH_M) as u16
                    );
                } else {
                    assert!(
                        (d - label.X_CP.xyz_m[2]).abs() < 0.35,
                        "depth {d} vs {:?}",
                        label.X_CP
                    );
                }
            }
            // The stored forearm is the forearm rendered at its label's pose by the frame's
            // camera (the region's camera): labels, crop and resampling agree.
            if all > 40 {
                let mut batch = MaskBatch::new();
                let X_CP = Pose::from(&label.X_CP);
                CpuRenderer::new()
                    .render_masks(
                        &forearm_mesh,
                        &Camera::from(&labels.camera),
                        &[X_CP],
                        &mut batch,
                    )
                    .unwrap();
                let rendered = batch.mask(0);
                let both = (0..n)
                    .filter(|&p| rendered[p] != 0 && amodal[p] == 1)
                    .count();
                let either = (0..n)
                    .filter(|&p| rendered[p] != 0 || amodal[p] == 1)
                    .count();
                let iou = both as f64 / either as f64;
                // They differ only on the outline, where resampling from the native camera
                // moves it by up to a pixel: each pixel they disagree on has a pixel of the
                // stored forearm and one of the background within one pixel of it. (A
                // small forearm's IoU says little: one pixel all round is a third of 54.)
                let on_outline = |p: usize| {
                    let (x, y) = (p % side, p / side);
                    let near = (y.saturating_sub(1)..(y + 2).min(side)).flat_map(|v| {
                        (x.saturating_sub(1)..(x + 2).min(side)).map(move |u| amodal[v * side + u])
                    });
                    let (mut forearm, mut background) = (false, false);
                    for m in near {
                        forearm |= m == 1;
                        background |= m == 0;
                    }
                    forearm && background
                };
                let inland = (0..n)
                    .filter(|&p| (rendered[p] != 0) != (amodal[p] == 1) && !on_outline(p))
                    .count();
                assert!(
                    inland == 0 && iou > 0.7,
                    "seq {} frame {t}: {inland} px apart off the outline, IoU {iou} of {all} px",
                    s.entry.index
                );
            }
            // The forearm's width and perfect-network ceiling are recorded when in view.
            if all > 0 {
                assert!(label.width_px.is_some_and(|w| w > 0.5));
                assert!(
                    label
                        .perfect_dice_loss
                        .is_some_and(|d| (0.0..=1.0).contains(&d))
                );
            }
        }
    }
    // The occluder is sized per frame; a few pixels of a thin forearm can still jump a level.
    assert!(
        frames >= 32,
        "forearm in view in only {frames} of 36 frames"
    );
    eprintln!("{in_level} of {frames} frames in their level");
    assert!(
        in_level * 10 >= frames * 9,
        "{in_level} of {frames} frames in their level"
    );
}

/// Splits made one run at a time into one folder add up: a later run of another split keeps
/// the earlier ones' sequences in the manifest, the stamp names the splits the folder holds,
/// and a run of every split adopts what is there and makes the rest.
#[test]
fn splits_made_one_run_at_a_time_add_up() {
    let tmp = tempfile::tempdir().unwrap();
    // One camera class and one level: one sequence of each split.
    let mut small = DatasetConfig::from_file(&small_config(tmp.path())).unwrap();
    small.cell_cameras.enabled = false;
    small.distances.truncate(1);
    small.occlusion_levels.truncate(1);
    small.sequences_per_pair = 3;
    small.sequences_per_episode = 1;
    small.splits = [0.34, 0.33, 0.33];
    let config = tmp.path().join("one-of-each.toml");
    std::fs::write(&config, small.to_toml()).unwrap();
    let out = tmp.path().join("out");
    let run = |splits: &[Split]| {
        Generator::from_file(&config)
            .unwrap()
            .with_splits(splits)
            .generate(&out, &|_| {})
            .unwrap()
    };
    let in_manifest = |report: &workcell_sim::dataset::Report, split: Split| {
        report
            .manifest
            .sequences
            .iter()
            .filter(|s| s.split == split)
            .count()
    };
    let stamp = || std::fs::read_to_string(out.join("config.toml")).unwrap();
    let test = run(&[Split::Test]);
    assert_eq!((test.generated, in_manifest(&test, Split::Test)), (1, 1));
    assert!(stamp().ends_with("\n# splits: test\n"), "{}", stamp());
    let validation = run(&[Split::Validation]);
    assert!(
        stamp().ends_with("\n# splits: validation, test\n"),
        "{}",
        stamp()
    );
    assert_eq!(validation.generated, 1);
    assert_eq!(validation.manifest.sequences.len(), 2);
    assert_eq!(in_manifest(&validation, Split::Test), 1);
    assert_eq!(Dataset::open(&out).unwrap().manifest.sequences.len(), 2);
    let all = run(&[]);
    assert!(!stamp().contains("# splits"), "{}", stamp());
    assert_eq!(all.manifest.sequences.len(), 3);
    assert_eq!((all.generated, in_manifest(&all, Split::Train)), (1, 1));
    // A configuration that differs in more than its splits is still refused.
    let other = Generator::new(DatasetConfig { seed: 99, ..small }, &config)
        .unwrap()
        .with_splits(&[Split::Test]);
    let err = other.generate(&out, &|_| {}).unwrap_err();
    assert!(err.to_string().contains("another configuration"), "{err}");
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

/// A crop policy that reads every frame through the whole camera image, or (`alternate`)
/// every other frame through the centred square of half its height, and records what it saw.
struct Scripted {
    alternate: bool,
    frame: usize,
    chosen: Vec<Roi>,
    seen: Vec<(usize, Roi, RoiKind)>,
    tx: std::sync::mpsc::Sender<Vec<(usize, Roi, RoiKind, Roi)>>,
}

impl CropPolicy for Scripted {
    fn start(&mut self) {
        self.frame = 0;
        self.chosen.clear();
        self.seen.clear();
    }
    fn roi(&mut self, native: &Camera) -> (Roi, RoiKind) {
        let (w, h) = (f64::from(native.width), f64::from(native.height));
        let (roi, kind) = if self.alternate && self.frame % 2 == 1 {
            (Roi::square([w / 2.0, h / 2.0], h / 2.0), RoiKind::Tracked)
        } else {
            (Roi::frame(native.width, native.height), RoiKind::Frame)
        };
        self.chosen.push(roi);
        (roi, kind)
    }
    fn seen(&mut self, frame: &GeneratedFrame) -> Result<(), workcell_sim::dataset::PolicyError> {
        let label = frame.labels.roi.as_ref().ok_or("no region label")?;
        self.seen.push((frame.labels.frame, label.roi, label.kind));
        self.frame += 1;
        if self.frame == 3 {
            let record = self
                .seen
                .iter()
                .zip(&self.chosen)
                .map(|(&(f, roi, kind), &chosen)| (f, roi, kind, chosen))
                .collect();
            self.tx.send(record).map_err(|e| e.to_string())?;
        }
        Ok(())
    }
}

#[test]
fn a_crop_policy_chooses_each_frames_region_and_sees_the_frames_in_order() {
    let tmp = tempfile::tempdir().unwrap();
    let path = small_config(tmp.path());
    let config = DatasetConfig {
        attempts: 1,
        ..DatasetConfig::from_file(&path).unwrap()
    };
    let whole = Generator::new(
        DatasetConfig {
            roi: workcell_sim::dataset::RoiConfig {
                whole_frame: true,
                ..config.roi.clone()
            },
            ..config.clone()
        },
        &path,
    )
    .unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let policy = |alternate: bool| {
        let tx = std::sync::Mutex::new(tx.clone());
        std::sync::Arc::new(move || {
            let tx = tx
                .lock()
                .map_err(|e| workcell_sim::dataset::PolicyError::from(e.to_string()))?
                .clone();
            Ok(Box::new(Scripted {
                alternate,
                frame: 0,
                chosen: Vec::new(),
                seen: Vec::new(),
                tx,
            }) as Box<dyn CropPolicy>)
        })
    };
    let cropped = Generator::new(config.clone(), &path)
        .unwrap()
        .with_crop("whole frame", policy(false));
    let mut renderer = CpuRenderer::new();
    let mut timing = Timing::default();
    // One draw each (attempts = 1), so both have the same camera, start and occluder: a
    // policy that always reads the whole frame makes what `roi.whole_frame` makes.
    for index in [0, 5, 10] {
        let a = whole.sequence(index, &mut renderer, &mut timing).unwrap();
        let b = cropped.sequence(index, &mut renderer, &mut timing).unwrap();
        assert_eq!(a.frames.len(), 3);
        for (fa, fb) in a.frames.iter().zip(&b.frames) {
            assert!(fa.rgb == fb.rgb && fa.classes == fb.classes && fa.depth_m == fb.depth_m);
            assert!(fa.visible == fb.visible && fa.occluder == fb.occluder);
            assert_eq!(fa.labels, fb.labels);
        }
        let record = rx.try_recv().unwrap();
        let frames: Vec<usize> = record.iter().map(|r| r.0).collect();
        assert_eq!(frames, [0, 1, 2]);
    }
    // Every other frame through a smaller square: each frame's label holds the region the
    // policy chose, of the kind it named, and the stored camera sees exactly that region.
    let alternating = Generator::new(config, &path)
        .unwrap()
        .with_crop("alternate", policy(true));
    let s = alternating.sequence(4, &mut renderer, &mut timing).unwrap();
    let record = rx.try_recv().unwrap();
    for ((f, roi, kind, chosen), frame) in record.iter().zip(&s.frames) {
        assert_eq!(*roi, *chosen);
        assert_eq!(
            *kind,
            if f % 2 == 1 {
                RoiKind::Tracked
            } else {
                RoiKind::Frame
            }
        );
        let label = frame.labels.roi.as_ref().unwrap();
        let native = Camera::from(&label.native);
        let expected = roi.camera(&native, 64).unwrap();
        let stored = Camera::from(&frame.labels.camera);
        let intrinsics = |c: &Camera| (c.width, c.height, c.fx, c.fy, c.cx, c.cy);
        assert_eq!(intrinsics(&stored), intrinsics(&expected));
    }
    assert_eq!(record[1].1.size, 60);

    // A folder made without the policy is another configuration's.
    let out = tmp.path().join("plain");
    let plain = Generator::new(alternating.config.clone(), &path).unwrap();
    plain.generate(&out, &|_| {}).unwrap();
    let err = alternating.generate(&out, &|_| {}).unwrap_err();
    assert!(err.to_string().contains("another configuration"), "{err}");
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
        // Counts that wrapped around or asked for terabytes.
        ("sequences_per_pair = 1000000000000", "sequences_per_pair"),
        (
            "sequences_per_pair = 18446744073709551615",
            "sequences_per_pair",
        ),
        ("frames = 1000000000000", "frames"),
        ("sequences_per_episode = 100000000", "sequences_per_episode"),
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

/// A format 2 dataset stored the scene behind the occluder in its depth images: it is read
/// with the occluder put back in front, and the same images under format 3 as stored.
fn format_2_depth_is_read_with_the_occluder_in_front(root: &Path) {
    use workcell_sim::render::dataset::{SEES_THROUGH_OCCLUDER, frame_files};
    use workcell_sim::render::image::{depth_mm_bytes, encode_png};
    use workcell_sim::render::occlusion::OCCLUDER_DEPTH_M;
    let dataset = Dataset::open(root).unwrap();
    let (w, h) = (dataset.manifest.width_px, dataset.manifest.height_px);
    // A frame with an occluder; its depth image replaced by a wall at 2 m seen through it.
    let (entry, f, occluder) = dataset
        .manifest
        .sequences
        .iter()
        .flat_map(|e| (0..e.frames).map(move |f| (e, f)))
        .find_map(|(e, f)| {
            let path = root.join(&e.dir).join(&frame_files(f)[3]);
            let (_, _, _, mask) = workcell_sim::render::image::read_png(&path).unwrap();
            let covered: Vec<bool> = mask.iter().map(|&v| v >= 128).collect();
            covered
                .iter()
                .any(|&c| c)
                .then_some((e.clone(), f, covered))
        })
        .expect("a frame with an occluder");
    let wall = vec![2.0f32; (w * h) as usize];
    std::fs::write(
        root.join(&entry.dir).join(&frame_files(f)[6]),
        encode_png(w, h, PixelKind::Gray16, &depth_mm_bytes(&wall)).unwrap(),
    )
    .unwrap();
    assert!(dataset.depth(&entry, f).unwrap().iter().all(|&d| d == 2.0));
    let manifest = root.join("manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    assert!(text.contains(workcell_sim::render::dataset::FORMAT));
    std::fs::write(
        &manifest,
        text.replace(workcell_sim::render::dataset::FORMAT, SEES_THROUGH_OCCLUDER),
    )
    .unwrap();
    let old = Dataset::open(root).unwrap();
    let depth = old.depth(&entry, f).unwrap();
    for (d, covered) in depth.iter().zip(&occluder) {
        assert_eq!(*d, if *covered { OCCLUDER_DEPTH_M } else { 2.0 });
    }
}

/// `[recorded]`: with every episode recorded, each sequence's human plays a clip of the
/// shipped library's tuning split, named in the manifest's entry, and the generator's
/// sequences name none. While the dataset has training or validation sequences, a held-out
/// clip or split is refused, naming the key; a dataset that is all test split may show them.
#[test]
fn recorded_people_in_a_dataset_come_from_the_tuning_clips() {
    use workcell_mocap::library::{Library, Split as ClipSplitOf};
    use workcell_sim::scenario::{ClipSplit, RecordedConfig};
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let library = Library::from_file(&root.join("data/mocap/library.toml")).unwrap();
    let tuning: Vec<&str> = library
        .clips(Some(ClipSplitOf::Tuning))
        .map(|c| c.id.as_str())
        .collect();
    let held_out = library
        .clips(Some(ClipSplitOf::Test))
        .map(|c| c.id.clone())
        .next()
        .unwrap();
    // A configuration in another folder than the cell's (the tests run in the crate's
    // folder), its paths relative to its own: the library is found from there, not from the
    // scenario's folder with the configuration's path joined to it (`tests/../../configs/
    // tests/..`, a folder that does not exist).
    let path = Path::new("tests/dataset-test.toml");
    let recorded = RecordedConfig {
        library: "../../data/mocap/library.toml".into(),
        clips: Vec::new(),
        split: ClipSplit::Tuning,
        start_s: 0.0,
        end: workcell_sim::human::ClipEnd::Reverse,
        retarget: workcell_sim::retarget::RetargetConfig::default(),
    };
    let config = DatasetConfig {
        scenario: "../../configs/default.toml".into(),
        sequences_per_pair: 1,
        sequences_per_episode: 1,
        frames: 1,
        width_px: 160,
        height_px: 120,
        input_px: 64,
        start_s: [0.5, 1.5],
        recorded: Some(recorded.clone()),
        recorded_fraction: Some(1.0),
        ..DatasetConfig::default()
    };
    let generator = Generator::new(config.clone(), path).unwrap();
    let mut renderer = CpuRenderer::new();
    let mut timing = Timing::default();
    let mut clips = Vec::new();
    for index in 0..3 {
        let sequence = generator
            .sequence(index, &mut renderer, &mut timing)
            .unwrap();
        let clip = sequence.entry.clip.expect("a recorded clip");
        assert!(
            tuning.contains(&clip.as_str()),
            "{clip} is not a tuning clip"
        );
        clips.push(clip);
    }
    // Episodes draw their clips by seed: three episodes do not all play one.
    clips.dedup();
    assert!(clips.len() > 1, "{clips:?}");
    let generated = Generator::new(
        DatasetConfig {
            recorded_fraction: Some(0.0),
            ..config.clone()
        },
        path,
    )
    .unwrap()
    .sequence(0, &mut renderer, &mut timing)
    .unwrap();
    assert_eq!(generated.entry.clip, None);

    let with = |recorded: RecordedConfig, splits: [f64; 3]| {
        Generator::new(
            DatasetConfig {
                recorded: Some(recorded),
                splits,
                ..config.clone()
            },
            path,
        )
    };
    let trains = [0.8, 0.1, 0.1];
    for (bad, key) in [
        (
            RecordedConfig {
                split: ClipSplit::Test,
                ..recorded.clone()
            },
            "recorded.split",
        ),
        (
            RecordedConfig {
                split: ClipSplit::All,
                ..recorded.clone()
            },
            "recorded.split",
        ),
        (
            RecordedConfig {
                clips: vec![tuning[0].to_string(), held_out.clone()],
                ..recorded.clone()
            },
            "recorded.clips",
        ),
    ] {
        let Err(err) = with(bad.clone(), trains) else {
            panic!("{key}: held-out clips accepted in a dataset that trains");
        };
        assert!(err.to_string().contains(key), "{err}");
        assert!(
            with(bad, [0.0, 0.0, 1.0]).is_ok(),
            "{key}: a test-only dataset"
        );
    }
    // A share without clips, or out of [0, 1], names its key.
    for text in [
        "recorded_fraction = 0.5",
        "recorded_fraction = 1.5\n[recorded]\nlibrary = \"l.toml\"",
    ] {
        let err = DatasetConfig::from_toml(text, Path::new("bad.toml")).unwrap_err();
        assert!(
            err.to_string().contains("recorded_fraction"),
            "{text}: {err}"
        );
    }
}
