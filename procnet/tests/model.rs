//! ProcNet's shapes, state, weight files and bad input.

mod common;

use burn::tensor::{Device, Tensor, TensorData};
use common::{reference_frame, tiny};
use workcell_procnet::model::ProcNetModel;
use workcell_procnet::{
    Backend, CellKind, ProcNet, ProcNetConfig, ProcNetError, VIEW_READS, weights,
};
use workcell_render::Class;

fn frame(t: usize, b: usize, s: usize, device: &Device) -> Tensor<4> {
    let v: Vec<f32> = (0..b).flat_map(|k| reference_frame(t, k, s)).collect();
    Tensor::from_data(TensorData::new(v, [b, 3, s, s]), device)
}

#[test]
fn every_switch_of_table_1_gives_the_documented_shapes() {
    let device = Device::flex();
    for cell in CellKind::ALL {
        for layers in [3, 4] {
            for axonal_delay in [false, true] {
                for prediction_loss in [false, true] {
                    let mut config = ProcNetConfig {
                        cell,
                        axonal_delay,
                        prediction_loss,
                        ..tiny(cell)
                    };
                    if layers == 4 {
                        config.repr_channels = vec![4, 6, 8, 8];
                        config.input_channels = vec![3, 4, 6, 8];
                    }
                    let model = config.init(&device, 3).unwrap();
                    let (b, s) = (2, config.input_size);
                    let mut state = model.initial_state(b, s, s, &device);
                    for t in 0..3 {
                        let (out, next) = model.step(frame(t, b, s, &device), state);
                        state = next;
                        let what = format!(
                            "{cell:?} {layers} layers delay {axonal_delay} pred {prediction_loss}"
                        );
                        assert_eq!(out.logits.dims(), [b, 2, s, s], "{what}");
                        assert_eq!(
                            out.prediction.as_ref().map(Tensor::dims),
                            prediction_loss.then_some([b, 3, s, s]),
                            "{what}"
                        );
                        assert_eq!(out.prediction_error.is_some(), prediction_loss, "{what}");
                        let top = &state.cells[layers - 1].h;
                        assert_eq!(
                            top.dims(),
                            [
                                b,
                                config.repr_channels[layers - 1],
                                s >> (layers - 1),
                                s >> (layers - 1)
                            ],
                            "{what}"
                        );
                        let v: Vec<f32> = out.logits.into_data().try_to_vec().unwrap();
                        assert!(v.iter().all(|x| x.is_finite()), "{what}");
                    }
                    assert_eq!(state.frames, 3);
                }
            }
        }
    }
}

#[test]
fn the_state_carries_information_and_reset_forgets_it() {
    let device = Device::flex();
    let config = tiny(CellKind::Hgru);
    let model = config.init(&device, 5).unwrap();
    let mut net = ProcNet::new(model, config.clone(), device);
    let s = config.input_size;
    let first = net.segment(&reference_frame(0, 0, s)).unwrap();
    let again = net.segment(&reference_frame(0, 0, s)).unwrap();
    // The same frame twice: the recurrent state makes the second answer differ.
    assert_ne!(first.probabilities, again.probabilities);
    assert_eq!(net.frames(), 2);
    net.reset();
    let after_reset = net.segment(&reference_frame(0, 0, s)).unwrap();
    assert_eq!(first.probabilities, after_reset.probabilities);
    assert!(first.probabilities.iter().all(|p| (0.0..=1.0).contains(p)));
    assert_eq!(first.class(Class::Robot).unwrap().len(), s * s);
}

#[test]
fn a_new_view_starts_the_stream_with_view_reads_frames_of_it() {
    let device = Device::flex();
    let config = tiny(CellKind::Hgru);
    let s = config.input_size;
    let mut net = ProcNet::new(
        config.init(&device, 5).unwrap(),
        config.clone(),
        device.clone(),
    );
    for t in 0..3 {
        net.segment(&reference_frame(t, 0, s)).unwrap();
    }
    let view = reference_frame(0, 2, s);
    net.start_view(&view, s, s).unwrap();
    assert_eq!(net.frames(), VIEW_READS);
    let after = net.segment(&view).unwrap();
    // What a fresh stream answers on the view's frame the (VIEW_READS + 1)th time it reads it.
    let mut fresh = ProcNet::new(config.init(&device, 5).unwrap(), config, device);
    for _ in 0..VIEW_READS {
        fresh.segment(&view).unwrap();
    }
    let next = fresh.segment(&view).unwrap();
    assert_eq!(after.probabilities, next.probabilities);
    // A frame of the wrong size or with a NaN is refused, and the stream is as it was.
    assert!(net.start_view(&view, s + 1, s).is_err());
    let mut bad = view.clone();
    bad[7] = f32::NAN;
    assert!(net.start_view(&bad, s, s).is_err());
    assert_eq!(net.frames(), VIEW_READS + 1);
}

#[test]
fn the_feed_forward_baseline_sees_each_frame_alone() {
    let device = Device::flex();
    let config = tiny(CellKind::Hgru).feed_forward_baseline();
    assert!(config.is_feed_forward());
    let model = config.init(&device, 5).unwrap();
    let mut net = ProcNet::new(model, config.clone(), device);
    let s = config.input_size;
    let fresh = net.segment(&reference_frame(3, 0, s)).unwrap();
    for t in 0..3 {
        net.segment(&reference_frame(t, 1, s)).unwrap();
    }
    // After other frames, the same frame gives the same masks: nothing carries over.
    let after_history = net.segment(&reference_frame(3, 0, s)).unwrap();
    assert_eq!(fresh.probabilities, after_history.probabilities);
    let other = net.segment(&reference_frame(2, 1, s)).unwrap();
    assert_ne!(fresh.probabilities, other.probabilities);
}

#[test]
fn save_and_load_give_identical_outputs() {
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    for cell in CellKind::ALL {
        let config = tiny(cell);
        let model = config.init(&device, 11).unwrap();
        let path = dir.path().join(format!("{}.safetensors", cell.name()));
        weights::save(&model, &config, &path).unwrap();
        let mut a = ProcNet::new(model, config.clone(), device.clone());
        let mut b = ProcNet::load(&path, Backend::Flex).unwrap();
        assert_eq!(b.config(), &config);
        for t in 0..3 {
            let x = reference_frame(t, 0, config.input_size);
            assert_eq!(
                a.segment(&x).unwrap(),
                b.segment(&x).unwrap(),
                "{cell:?} frame {t}"
            );
        }
    }
}

#[test]
fn seeds_decide_the_initial_weights() {
    let device = Device::flex();
    let config = tiny(CellKind::ConvLstm);
    let x = reference_frame(0, 0, config.input_size);
    let run = |seed| {
        let mut net = ProcNet::new(
            config.init(&device, seed).unwrap(),
            config.clone(),
            device.clone(),
        );
        net.segment(&x).unwrap().probabilities
    };
    assert_eq!(run(1), run(1));
    assert_ne!(run(1), run(2));
}

#[test]
fn the_frame_prediction_bias_sets_the_first_predicted_frame() {
    let device = Device::flex();
    let config = tiny(CellKind::Hgru);
    let s = config.input_size;
    // Before the first frame R_0 is zero, so Ahat_0 = ReLU(bias): the set value at every pixel
    // of every colour channel.
    let first_prediction = |model: &ProcNetModel| {
        let state = model.initial_state(1, s, s, &device);
        let (out, _) = model.step(frame(0, 1, s, &device), state);
        out.prediction
            .unwrap()
            .into_data()
            .try_to_vec::<f32>()
            .unwrap()
    };
    let mut model = config.init(&device, 3).unwrap();
    let drawn = first_prediction(&model);
    let bias_id = |model: &ProcNetModel| {
        let conv = model.layers[0].predict.as_ref();
        conv.and_then(|c| c.bias.as_ref()).map(|bias| bias.id)
    };
    let id = bias_id(&model);
    assert!(model.set_frame_prediction_bias(0.4));
    let set = first_prediction(&model);
    assert_eq!(set.len(), 3 * s * s);
    assert!(set.iter().all(|&v| (v - 0.4).abs() < 1e-6), "{set:?}");
    assert!(drawn.iter().any(|&v| (v - 0.4).abs() > 1e-3));
    // The parameter keeps its id: a saved optimizer state still applies to it.
    assert!(id.is_some());
    assert_eq!(bias_id(&model), id);
    // No prediction, nothing to set.
    let baseline = config.feed_forward_baseline();
    let mut model = baseline.init(&device, 3).unwrap();
    assert!(!model.set_frame_prediction_bias(0.4));
}

#[test]
fn bad_frames_are_clear_errors() {
    let device = Device::flex();
    let config = tiny(CellKind::Hgru);
    let mut net = ProcNet::new(config.init(&device, 1).unwrap(), config.clone(), device);
    let s = config.input_size;
    // Wrong size: a 32x32 frame for a 16x16 network.
    let e = net.segment(&vec![0.5; 3 * 32 * 32]).unwrap_err();
    assert!(matches!(e, ProcNetError::Input { .. }), "{e}");
    assert!(e.to_string().contains("3x32x32"), "{e}");
    // Wrong channel count: one gray plane.
    let e = net.segment(&vec![0.5; s * s]).unwrap_err().to_string();
    assert!(e.contains("3x16x16"), "{e}");
    // A NaN pixel, located.
    let mut x = reference_frame(0, 0, s);
    x[s * s + 2 * s + 5] = f32::NAN;
    let e = net.segment(&x).unwrap_err().to_string();
    assert!(e.contains("channel 1, row 2, column 5"), "{e}");
    // An 8-bit image passed as is.
    let e = net
        .segment(&vec![255.0; 3 * s * s])
        .unwrap_err()
        .to_string();
    assert!(e.contains("outside [0, 1]") && e.contains("255"), "{e}");
    // The failed calls did not advance the stream.
    assert_eq!(net.frames(), 0);
}

#[test]
fn bad_weight_files_are_clear_errors() {
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    let config = tiny(CellKind::Hgru);
    let model = config.init(&device, 1).unwrap();
    let good = dir.path().join("good.safetensors");
    weights::save(&model, &config, &good).unwrap();
    let bytes = std::fs::read(&good).unwrap();

    let missing = dir.path().join("missing.safetensors");
    let e = ProcNet::load(&missing, Backend::Flex)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("missing.safetensors") && e.contains("cannot read"),
        "{e}"
    );

    let truncated = dir.path().join("truncated.safetensors");
    std::fs::write(&truncated, &bytes[..bytes.len() - 100]).unwrap();
    let e = ProcNet::load(&truncated, Backend::Flex)
        .unwrap_err()
        .to_string();
    assert!(e.contains("truncated"), "{e}");

    let short = dir.path().join("short.safetensors");
    std::fs::write(&short, &bytes[..5]).unwrap();
    let e = ProcNet::load(&short, Backend::Flex)
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a safetensors file"), "{e}");

    let corrupt = dir.path().join("corrupt.safetensors");
    let mut c = bytes.clone();
    c[10] = b'#';
    std::fs::write(&corrupt, &c).unwrap();
    let e = ProcNet::load(&corrupt, Backend::Flex)
        .unwrap_err()
        .to_string();
    assert!(e.contains("corrupt header"), "{e}");

    let huge = dir.path().join("huge.safetensors");
    let mut h = bytes.clone();
    h[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    std::fs::write(&huge, &h).unwrap();
    let e = ProcNet::load(&huge, Backend::Flex).unwrap_err().to_string();
    assert!(e.contains("truncated or corrupt"), "{e}");

    // Weights of another configuration, loaded into this one.
    let other = ProcNetConfig {
        repr_channels: vec![4, 6, 10],
        ..config.clone()
    };
    let other_path = dir.path().join("other.safetensors");
    weights::save(&other.init(&device, 1).unwrap(), &other, &other_path).unwrap();
    let mut mine = config.init(&device, 1).unwrap();
    let e = weights::load_checked(&mut mine, &config, &other_path)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("another configuration") && e.contains("repr_channels"),
        "{e}"
    );
}

/// The same weights on flex and on `other` give the same masks, frame after frame.
#[cfg(any(feature = "tch", feature = "gpu"))]
fn same_masks_as_flex(other: Backend) {
    let dir = tempfile::tempdir().unwrap();
    for cell in CellKind::ALL {
        let config = tiny(cell);
        let path = dir.path().join("w.safetensors");
        weights::save(&config.init(&Device::flex(), 4).unwrap(), &config, &path).unwrap();
        let mut flex = ProcNet::load(&path, Backend::Flex).unwrap();
        let mut them = ProcNet::load(&path, other).unwrap();
        for t in 0..4 {
            let x = reference_frame(t, 0, config.input_size);
            let (a, b) = (flex.segment(&x).unwrap(), them.segment(&x).unwrap());
            let worst = a
                .probabilities
                .iter()
                .zip(&b.probabilities)
                .map(|(p, q)| (p - q).abs())
                .fold(0f32, f32::max);
            // f32 on both sides, different summation orders: agreement to 1e-5.
            assert!(
                worst < 1e-5,
                "{cell:?} frame {t} on {other:?}: probabilities differ by {worst}"
            );
        }
    }
}

#[cfg(feature = "tch")]
#[test]
fn flex_and_libtorch_give_the_same_masks() {
    same_masks_as_flex(Backend::Tch);
}

#[cfg(feature = "gpu")]
#[test]
fn flex_and_the_gpu_give_the_same_masks() {
    same_masks_as_flex(Backend::Gpu);
}

/// The shipped weights (ProcNet, flesh at 64x64 and skeletal at 128x128, and its feed-forward
/// baseline) load, are of the configuration their recipe trains (ProcNet: `configs/train.toml`,
/// `configs/train-skeletal.toml` and `configs/train-64-depth.toml`; the baseline: `configs/train-64.toml` with `--model
/// baseline`), stay within the 20 MB budget together, and run.
#[test]
fn the_shipped_weights_load_and_match_their_recipe() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let recipe = |name: &str| {
        workcell_procnet::TrainConfig::from_file(&root.join("../configs").join(name)).unwrap()
    };
    let mut total = 0;
    for (file, model) in [
        ("procnet-cpu", recipe("train.toml").model),
        ("procnet-skeletal", recipe("train-skeletal.toml").model),
        ("procnet-depth", recipe("train-64-depth.toml").model),
        (
            "baseline-cpu-64",
            recipe("train-64.toml").model.feed_forward_baseline(),
        ),
    ] {
        let path = root.join(format!("weights/{file}.safetensors"));
        total += std::fs::metadata(&path).unwrap().len();
        let mut net = ProcNet::load(&path, Backend::Flex).unwrap();
        assert_eq!(net.config(), &model, "{file}");
        assert_eq!(net.config().is_feed_forward(), file.starts_with("baseline"));
        let s = net.config().input_size;
        let mut frame = reference_frame(0, 0, s);
        if net.config().reads_depth() {
            // The depth plane of a region whose centre is at the median depth.
            frame.extend(std::iter::repeat_n(0.5, s * s));
        }
        let masks = net.segment(&frame).unwrap();
        // The shipped files name their classes as strings; they read back as the classes.
        assert_eq!(
            masks.classes,
            [
                Class::Robot,
                Class::Torso,
                Class::UpperArm,
                Class::Forearm,
                Class::Hand
            ]
        );
    }
    assert!(
        total < 20 * 1024 * 1024,
        "{total} bytes of weights, over the 20 MB budget"
    );
    // What runs where no weights are named: the network that reads depth for a camera that
    // measures it, the RGB one otherwise.
    for depth in [false, true] {
        let config =
            workcell_procnet::weights::read_config(&workcell_procnet::weights::shipped_path(depth))
                .unwrap();
        assert_eq!(config.reads_depth(), depth);
    }
    // The RGB network has seen the paper's arm only: chosen for any other human, it says so;
    // the depth networks are chosen for the human they were trained on and say nothing.
    use workcell_procnet::weights::{PAPER_ARM, shipped_for, shipped_for_warning};
    assert!(shipped_for_warning(true, "human").is_none());
    assert!(shipped_for_warning(true, PAPER_ARM).is_none());
    assert!(shipped_for_warning(false, PAPER_ARM).is_none());
    let warning = shipped_for_warning(false, "human").expect("a warning");
    assert!(
        warning.contains(shipped_for(false, "human")) && warning.contains("perception.depth"),
        "{warning}"
    );
}

/// The paper preset has the size of the authors' runs: about 5.4 M parameters for 3 layers
/// (reference/PROCNET.md, "Channels in the authors' runs"; with (64, 128, 256, 512) channels
/// the same count gives 22.15 M against their 22 M for 4 layers).
#[test]
fn the_paper_preset_has_the_authors_parameter_count() {
    use burn::module::Module;
    let params = ProcNetConfig::paper()
        .init(&Device::flex(), 0)
        .unwrap()
        .num_params();
    assert_eq!(params, 5_368_067);
}

/// A network grown to read depth (`ProcNetModel::grow_depth_input`) segments as the RGB one
/// did whatever the depth plane holds, its weights load as an RGB-D network's, and it
/// predicts the depth plane as zero until trained.
#[test]
fn a_network_grown_to_read_depth_segments_as_before() {
    let device = Device::flex();
    let dir = tempfile::tempdir().unwrap();
    for cell in CellKind::ALL {
        for prediction_loss in [false, true] {
            let config = ProcNetConfig {
                prediction_loss,
                ..tiny(cell)
            };
            let rgb = config.init(&device, 5).unwrap();
            let grown = config.init(&device, 5).unwrap().grow_depth_input().unwrap();
            let mut depth_config = config.clone();
            depth_config.input_channels[0] = 4;
            let path = dir
                .path()
                .join(format!("{cell:?}-{prediction_loss}.safetensors"));
            weights::save(&grown, &depth_config, &path).unwrap();
            let (grown, read) = weights::load(&path, &device).unwrap();
            assert!(read.reads_depth());
            let s = config.input_size;
            let (mut a, mut b) = (
                rgb.initial_state(1, s, s, &device),
                grown.initial_state(1, s, s, &device),
            );
            for t in 0..3 {
                let x = reference_frame(t, 0, s);
                let mut xd = x.clone();
                xd.extend((0..s * s).map(|i| ((i * 7 + t) % 11) as f32 / 10.0));
                let (oa, na) = rgb.step(
                    Tensor::from_data(TensorData::new(x, [1, 3, s, s]), &device),
                    a,
                );
                let (ob, nb) = grown.step(
                    Tensor::from_data(TensorData::new(xd, [1, 4, s, s]), &device),
                    b,
                );
                (a, b) = (na, nb);
                let what = format!("{cell:?}, prediction loss {prediction_loss}, frame {t}");
                let la: Vec<f32> = oa.logits.into_data().try_to_vec().unwrap();
                let lb: Vec<f32> = ob.logits.into_data().try_to_vec().unwrap();
                let worst = la
                    .iter()
                    .zip(&lb)
                    .map(|(p, q)| (p - q).abs())
                    .fold(0.0, f32::max);
                assert!(worst < 1e-5, "{what}: logits differ by {worst}");
                if let (Some(pa), Some(pb)) = (oa.prediction, ob.prediction) {
                    let pa: Vec<f32> = pa.into_data().try_to_vec().unwrap();
                    let pb: Vec<f32> = pb.into_data().try_to_vec().unwrap();
                    assert_eq!(pb.len(), 4 * s * s, "{what}");
                    let worst = pa
                        .iter()
                        .zip(&pb)
                        .map(|(p, q)| (p - q).abs())
                        .fold(0.0, f32::max);
                    assert!(worst < 1e-5, "{what}: RGB prediction differs by {worst}");
                    assert!(pb[3 * s * s..].iter().all(|&v| v == 0.0), "{what}");
                }
            }
            // Only a network that reads RGB alone grows.
            assert!(matches!(
                grown.grow_depth_input(),
                Err(ProcNetError::Config { .. })
            ));
        }
    }
}
