//! Perception alone, on saved frames: PNG images from a camera whose calibration and pose are
//! known, the human model, and the shipped ProcNet weights; out comes, per frame, the arm as
//! capsules in the world with an uncertainty, or the reason there is none. No simulator: the
//! same `ArmTracker` runs beside a real camera.
//!
//! `cargo run --release --example perception_on_frames -- out/dataset/seq_00000`
//! (add `--true-masks` to feed the frames' ground-truth class pixels instead of ProcNet's,
//! `--depth` to give the fit each frame's depth image, as from an RGB-D camera).

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use workcell::perception::ArmTracker;
use workcell::perception::pose::{ArmFitConfig, ArmMasks, Calibration};
use workcell::procnet::{Backend, ProcNet};
use workcell::render::dataset::{FrameLabels, Manifest};
use workcell::render::image::{PixelKind, read_png};
use workcell::render::{Camera, Class};
use workcell::robots::math::Pose;
use workcell::robots::{PackageMap, RobotModel};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = PathBuf::from(args.next().context(
        "usage: perception_on_frames SEQUENCE_DIR [--true-masks] [--depth] (a folder of \
         frame_NNN_rgb.png with their frame_NNN.json, e.g. out/dataset/seq_00000)",
    )?);
    let mut true_masks = false;
    let mut depth = false;
    for arg in args {
        match arg.as_str() {
            "--true-masks" => true_masks = true,
            "--depth" => depth = true,
            other => bail!("unknown option {other:?} (--true-masks, --depth)"),
        }
    }

    // The human: its model and where it stands. A dataset's manifest records both; beside a
    // real camera they come from the cell's set-up.
    let path = dir.join("../manifest.json");
    let manifest: Manifest = serde_json::from_slice(
        &std::fs::read(&path).with_context(|| format!("{}", path.display()))?,
    )
    .with_context(|| format!("{}", path.display()))?;
    let human = manifest
        .human
        .context("the manifest records no human: regenerate the dataset")?;
    let mut model = RobotModel::load(&human.model, &PackageMap::from_env())?;
    // What the frames show of it: its flesh, or the paper's bones.
    model.retain_visuals(|g| human.look.shows(g.name.as_deref()));
    let X_WH = Pose::from(&human.X_WH);
    // The radius to inflate the capsules by, as measured for these masks and this camera
    // (experiments/perception.md): 99 % of the validation split's frames within it. A network's
    // calibration is the file beside its weights. With depth the shipped network reads the
    // depth image too.
    let weights = workcell::procnet::weights::shipped_path(depth);
    let calibration = if true_masks {
        Calibration::true_masks(depth)
    } else {
        let found = Calibration::of_weights(&weights, depth)?;
        if let Some(w) = found.warning() {
            eprintln!("warning: {w}");
        }
        found.calibration
    };
    let mut tracker = ArmTracker::new(&model, &X_WH, calibration.apply(ArmFitConfig::default()))?;
    if !true_masks {
        tracker = tracker.with_network(ProcNet::load(&weights, Backend::Flex)?)?;
    }

    println!(
        "frame | elbow error (cm) | upper arm axis (world, m)      | forearm axis (world, m)        | inflate by (m)"
    );
    for t in 0.. {
        let image = dir.join(format!("frame_{t:03}_rgb.png"));
        if !image.exists() {
            if t == 0 {
                bail!("{}: no frame_000_rgb.png here", dir.display());
            }
            break;
        }
        // The camera of this frame (a real camera's calibration and its pose in the cell).
        let labels: FrameLabels =
            serde_json::from_slice(&std::fs::read(dir.join(format!("frame_{t:03}.json")))?)?;
        let camera = Camera::from(&labels.camera);
        let depth_m = if depth {
            Some(read_depth(
                &dir.join(format!("frame_{t:03}_depth.png")),
                &camera,
            )?)
        } else {
            None
        };
        let outcome = if true_masks {
            let (w, h, _, classes) = read_png(&dir.join(format!("frame_{t:03}_class.png")))?;
            let mut masks = ArmMasks::from_classes(&classes, w as usize, h as usize)?;
            masks.depth_m = depth_m;
            tracker.track_masks(&camera, &masks)?
        } else {
            let (w, h, kind, rgb) = read_png(&image)?;
            if kind != PixelKind::Rgb || (w, h) != (camera.width, camera.height) {
                bail!("{}: not an RGB frame of the camera's size", image.display());
            }
            tracker.track(&camera, &rgb, depth_m.as_deref())?
        };
        match outcome {
            Ok(estimate) => {
                let error = labels
                    .part(Class::Forearm)
                    .map(|p| {
                        let X_CF: Pose = (&p.X_CP).into();
                        let X_WF = camera.X_WC * X_CF;
                        format!(
                            "{:.1}",
                            100.0 * (estimate.X_WF.translation - X_WF.translation).length()
                        )
                    })
                    .unwrap_or_else(|| "-".into());
                let seg = |k: usize| {
                    let p = &estimate.parts[k];
                    format!(
                        "{:.2},{:.2},{:.2}->{:.2},{:.2},{:.2}",
                        p.a_W.x, p.a_W.y, p.a_W.z, p.b_W.x, p.b_W.y, p.b_W.z
                    )
                };
                println!(
                    "{t:5} | {error:>16} | {} | {} | {:.3}",
                    seg(0),
                    seg(1),
                    estimate.uncertainty_m
                );
            }
            Err(reason) => println!("{t:5} | no estimate: {reason}"),
        }
    }
    Ok(())
}

/// A depth image as the datasets store it (a 16-bit PNG of the camera-frame z in mm, 0 where
/// nothing is), in m.
fn read_depth(path: &Path, camera: &Camera) -> anyhow::Result<Vec<f32>> {
    let (w, h, kind, data) = read_png(path)?;
    if kind != PixelKind::Gray16 || (w, h) != (camera.width, camera.height) {
        bail!(
            "{}: not a 16-bit depth image of the camera's size",
            path.display()
        );
    }
    Ok(data
        .chunks_exact(2)
        .map(|b| f32::from(u16::from_be_bytes([b[0], b[1]])) / 1000.0)
        .collect())
}
