//! One forward pass against the project's PyTorch implementation (`bench/procnet.py`, torch
//! 2.9.0): same weights, same input sequence, outputs to 1e-4.
//!
//! The weight files are the seeded initialisations below, written by
//! `cargo test -p workcell-procnet --test reference -- --ignored` into
//! `target/procnet-reference/`; the expected values were printed by
//! `python3 bench/procnet.py reference --weights target/procnet-reference/NAME.safetensors --frames 3`.

mod common;

use burn::tensor::Device;
use common::{reference_frame, tiny};
use workcell_procnet::{CellKind, ProcNetConfig, weights};

struct Case {
    name: &'static str,
    config: fn() -> ProcNetConfig,
    seed: u64,
    /// Mean absolute logit per class after 3 frames.
    logits_abs_mean_per_class: [f64; 2],
    /// Probability of class c at row (7c) % s, column (11c + 3) % s after 3 frames.
    probs_sample: [f64; 2],
    /// sum_l mean(E_l) of the third frame (prediction loss on).
    prediction_error: Option<f64>,
    /// Mean of the top representation after 3 frames.
    repr_top_mean: f64,
}

fn hgru() -> ProcNetConfig {
    tiny(CellKind::Hgru)
}
fn convlstm_delay() -> ProcNetConfig {
    ProcNetConfig {
        axonal_delay: true,
        ..tiny(CellKind::ConvLstm)
    }
}
fn conv_no_prediction_gelu() -> ProcNetConfig {
    ProcNetConfig {
        prediction_loss: false,
        decoder_activation: workcell_procnet::Activation::Gelu,
        ..tiny(CellKind::Conv)
    }
}
fn hgru_full_resolution() -> ProcNetConfig {
    ProcNetConfig {
        decoder_full_resolution: true,
        ..tiny(CellKind::Hgru)
    }
}
fn hgru_4_layers() -> ProcNetConfig {
    ProcNetConfig {
        repr_channels: vec![4, 6, 8, 8],
        input_channels: vec![3, 4, 6, 8],
        ..tiny(CellKind::Hgru)
    }
}

const CASES: &[Case] = &[
    Case {
        name: "hgru",
        config: hgru,
        seed: 7,
        logits_abs_mean_per_class: [0.4938138425350189, 0.42650628089904785],
        probs_sample: [0.7459689974784851, 0.5315024256706238],
        prediction_error: Some(0.4632231593132019),
        repr_top_mean: 0.07888266444206238,
    },
    Case {
        name: "convlstm_delay",
        config: convlstm_delay,
        seed: 8,
        logits_abs_mean_per_class: [0.0836227685213089, 0.2732463777065277],
        probs_sample: [0.4739067256450653, 0.43415313959121704],
        prediction_error: Some(0.4628107249736786),
        repr_top_mean: -0.0015085504855960608,
    },
    Case {
        name: "conv_no_prediction_gelu",
        config: conv_no_prediction_gelu,
        seed: 9,
        logits_abs_mean_per_class: [0.3449215292930603, 0.5093175768852234],
        probs_sample: [0.6337619423866272, 0.5676930546760559],
        prediction_error: None,
        repr_top_mean: 0.032572947442531586,
    },
    Case {
        name: "hgru_full_resolution",
        config: hgru_full_resolution,
        seed: 7,
        // The same weights as `hgru`: the representations agree, the masks do not.
        logits_abs_mean_per_class: [0.5087615847587585, 0.4411807954311371],
        probs_sample: [0.7443380355834961, 0.6077597737312317],
        prediction_error: Some(0.4632231593132019),
        repr_top_mean: 0.07888266444206238,
    },
    Case {
        name: "hgru_4_layers",
        config: hgru_4_layers,
        seed: 10,
        logits_abs_mean_per_class: [0.5122610926628113, 0.6399199962615967],
        probs_sample: [0.6599477529525757, 0.6220535039901733],
        prediction_error: Some(0.47774991393089294),
        repr_top_mean: 0.0278105977922678,
    },
];

#[test]
#[ignore = "writes the weight files that bench/procnet.py reads"]
fn write_reference_weights() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/procnet-reference");
    let device = Device::flex();
    for case in CASES {
        let config = (case.config)();
        let model = config.init(&device, case.seed).unwrap();
        weights::save(
            &model,
            &config,
            &dir.join(format!("{}.safetensors", case.name)),
        )
        .unwrap();
    }
}

#[test]
fn outputs_match_pytorch() {
    let device = Device::flex();
    for case in CASES {
        let config = (case.config)();
        let s = config.input_size;
        let model = config.init(&device, case.seed).unwrap();
        let mut state = model.initial_state(1, s, s, &device);
        let mut out = None;
        for t in 0..3 {
            let x = burn::tensor::Tensor::<4>::from_data(
                burn::tensor::TensorData::new(reference_frame(t, 0, s), [1, 3, s, s]),
                &device,
            );
            let (o, next) = model.step(x, state);
            state = next;
            out = Some(o);
        }
        let out = out.unwrap();
        let logits: Vec<f32> = out.logits.clone().into_data().try_to_vec().unwrap();
        let n = s * s;
        let close = |what: &str, got: f64, want: f64| {
            assert!(
                (got - want).abs() <= 1e-4 * want.abs().max(1.0),
                "{}: {what}: {got} vs PyTorch {want}",
                case.name
            );
        };
        for c in 0..2 {
            let mean = logits[c * n..(c + 1) * n]
                .iter()
                .map(|&v| f64::from(v).abs())
                .sum::<f64>()
                / n as f64;
            close(
                "mean absolute logit",
                mean,
                case.logits_abs_mean_per_class[c],
            );
            let (r, col) = ((7 * c) % s, (11 * c + 3) % s);
            let p = 1.0 / (1.0 + (-f64::from(logits[c * n + r * s + col])).exp());
            close("probability", p, case.probs_sample[c]);
        }
        match (out.prediction_error, case.prediction_error) {
            (Some(got), Some(want)) => close(
                "prediction error",
                f64::from(got.into_scalar::<f32>()),
                want,
            ),
            (None, None) => {}
            (got, want) => panic!(
                "{}: prediction error {:?} vs {want:?}",
                case.name,
                got.is_some()
            ),
        }
        let top: Vec<f32> = state
            .cells
            .last()
            .unwrap()
            .h
            .clone()
            .into_data()
            .try_to_vec()
            .unwrap();
        let top_mean = top.iter().map(|&v| f64::from(v)).sum::<f64>() / top.len() as f64;
        close("top representation mean", top_mean, case.repr_top_mean);
    }
}
