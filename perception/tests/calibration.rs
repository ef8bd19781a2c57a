//! A network's bound is calibrated by the file beside its weights, for those weights only.

use std::path::{Path, PathBuf};

use workcell_perception::pose::{BoundSource, Calibration, calibration_path, file_sha256};

fn weights(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../procnet/weights")
        .join(name)
}

/// The shipped files hold the calibration that was measured for each network (the values
/// docs/perception.md reports, which were number literals in the code before they moved
/// beside the weights).
#[test]
fn the_shipped_networks_carry_their_measured_calibration() {
    let rgb = Calibration::of_weights(&weights("procnet-cpu.safetensors"), true).expect("rgb");
    assert!(matches!(rgb.source, BoundSource::Calibrated { .. }));
    assert_eq!(rgb.warning(), None);
    assert_eq!(rgb.calibration.scale, 0.0);
    assert_eq!(rgb.calibration.floor_m, 0.0322);
    assert_eq!(rgb.calibration.hidden_floors_m, [0.0592, 0.0592, 0.3154]);
    assert_eq!(rgb.calibration.confirm_min_gain, f64::INFINITY);
    let rgb_alone = Calibration::of_weights(&weights("procnet-cpu.safetensors"), false)
        .expect("rgb without depth");
    assert_eq!(rgb_alone.calibration.floor_m, 0.4059);
    let depth =
        Calibration::of_weights(&weights("procnet-depth.safetensors"), true).expect("depth");
    assert_eq!(
        depth.calibration,
        Calibration {
            scale: 1.0,
            floor_m: 0.0233,
            hidden_floors_m: [0.0634, 0.0634, 0.2850],
            confirm_min_gain: 0.2,
            confirmed_floor_m: 0.65,
            min_gain: None,
            tracked_floors_m: None,
            confident: None,
            fit: None,
        }
    );
    // The network that reads depth was never measured without it.
    let blind = Calibration::of_weights(&weights("procnet-depth.safetensors"), false)
        .expect("depth network, no depth");
    assert_eq!(blind.calibration, Calibration::UNCALIBRATED);
    assert!(blind.warning().is_some_and(|w| w.contains("without")));
}

/// Weights other than those measured: a copied calibration file is refused (its hash is
/// not theirs); without a file the bound is the conservative one, with a warning.
#[test]
fn other_weights_get_no_borrowed_calibration() {
    let dir = tempfile::tempdir().expect("tempdir");
    let shipped = weights("procnet-cpu.safetensors");
    let mut bytes = std::fs::read(&shipped).expect("shipped weights");
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    let mine = dir.path().join("mine.safetensors");
    std::fs::write(&mine, &bytes).expect("write");

    let none = Calibration::of_weights(&mine, true).expect("no file is no error");
    assert_eq!(none.calibration, Calibration::UNCALIBRATED);
    let warning = none.warning().expect("a warning");
    assert!(
        warning.contains("mine.safetensors has no calibration"),
        "{warning}"
    );
    assert!(warning.contains("0.45 m"), "{warning}");

    std::fs::copy(calibration_path(&shipped), calibration_path(&mine)).expect("copy");
    let err = Calibration::of_weights(&mine, true).expect_err("another network's file");
    let message = err.to_string();
    let hash = file_sha256(&mine, 1 << 30).expect("hash");
    assert!(message.contains("mine.calibration.toml"), "{message}");
    assert!(message.contains(&hash), "{message}");

    // The same file with these weights' hash is theirs.
    let text = std::fs::read_to_string(calibration_path(&shipped)).expect("read");
    let shipped_hash = file_sha256(&shipped, 1 << 30).expect("hash");
    std::fs::write(calibration_path(&mine), text.replace(&shipped_hash, &hash)).expect("write");
    let own = Calibration::of_weights(&mine, true).expect("own calibration");
    assert_eq!(own.calibration.floor_m, 0.0322);
}

/// Values no bound can have, unknown keys and a file that is not a calibration are errors
/// that name the file and the key.
#[test]
fn a_malformed_calibration_is_refused_by_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mine = stand_in_weights(dir.path());
    let section = |floor: &str| calibration_file(&mine, floor, "");
    for (text, expected) in [
        (section("-0.1"), "with_depth.floor_m"),
        (section("nan"), "with_depth.floor_m"),
        (section("inf"), "with_depth.floor_m"),
        (section("0.1") + "extra = 1\n", "extra"),
        (section("0.1") + "min_gain = 1.5\n", "with_depth.min_gain"),
        (
            section("0.1") + "[with_depth.confident]\nmin_gain = 1.5\nfloors_m = [0, 0, 0, 0]\n",
            "with_depth.confident.min_gain",
        ),
        (
            section("0.1") + "[with_depth.confident]\nmin_gain = 0.7\nfloors_m = [0, -1, 0, 0]\n",
            "with_depth.confident.floors_m[1]",
        ),
        (
            section("0.1") + "[with_depth.confident]\nmin_gain = 0.7\nfloors_m = [0, 0]\n",
            "floors_m = [0, 0]",
        ),
        ("weights_sha256 = 3\n".to_string(), "weights_sha256"),
    ] {
        std::fs::write(calibration_path(&mine), &text).expect("write");
        let err = Calibration::of_weights(&mine, true).expect_err(&text);
        let message = err.to_string();
        assert!(message.contains("mine.calibration.toml"), "{message}");
        assert!(message.contains(expected), "{expected}: {message}");
    }
}

/// A calibration that chose the fit's gain threshold carries it: the bound holds for fits
/// above it only, so applying the calibration sets it; one without keeps the fit's own.
#[test]
fn a_calibrations_gain_threshold_is_the_fits() {
    use workcell_perception::pose::ArmFitConfig;
    let dir = tempfile::tempdir().expect("tempdir");
    let mine = stand_in_weights(dir.path());
    for (extra, expected) in [
        ("min_gain = 0.65\n", 0.65),
        ("", ArmFitConfig::default().min_gain),
    ] {
        std::fs::write(
            calibration_path(&mine),
            calibration_file(&mine, "0.05", extra),
        )
        .expect("write");
        let found = Calibration::of_weights(&mine, true).expect("calibration");
        let config = found.calibration.apply(ArmFitConfig::default());
        assert_eq!(config.min_gain, expected, "{extra:?}");
        assert_eq!(config.uncertainty_floor_m, 0.05);
    }
}

/// A file that stands in for weights in `dir` (the calibration reads only its hash).
fn stand_in_weights(dir: &Path) -> PathBuf {
    let mine = dir.join("mine.safetensors");
    std::fs::write(&mine, b"not really weights").expect("write");
    mine
}

/// A calibration file of `weights` whose fit with depth has the floor `floor` (a TOML
/// value, written as it is) and the lines `extra` at the end of its section.
fn calibration_file(weights: &Path, floor: &str, extra: &str) -> String {
    let hash = file_sha256(weights, 1 << 20).expect("hash");
    format!(
        "weights_sha256 = \"{hash}\"\nfitted_on = \"nothing\"\n[with_depth]\nscale = 0.0\n\
         floor_m = {floor}\nhidden_floors_m = [0.0, 0.0, 0.0]\nconfirm_min_gain = inf\n\
         confirmed_floor_m = 0.0\n{extra}"
    )
}
