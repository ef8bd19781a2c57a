//! Gradients, the optimiser step and learning, at tiny sizes.

mod common;

use burn::module::{Module, Param};
use burn::optim::{AdamWConfig, GradientsParams};
use burn::tensor::{Device, Tensor, TensorData};
use common::{reference_frame, tiny};
use workcell_procnet::cells::Cell;
use workcell_procnet::loss::dice_per_class;
use workcell_procnet::model::ProcNetModel;
use workcell_procnet::train::{LossConfig, burn_in_state, window_loss, window_start};
use workcell_procnet::{CellKind, ProcNetConfig};
use workcell_render::Class;

fn frames(n: usize, s: usize, device: &Device) -> Vec<Tensor<4>> {
    (0..n)
        .map(|t| {
            Tensor::from_data(
                TensorData::new(reference_frame(t, 0, s), [1, 3, s, s]),
                device,
            )
        })
        .collect()
}

/// `n` two-class targets `[1, 2, s, s]` of diagonal stripes: pixel `i` of frame `t` is on
/// where `(i + shift * t) % period < 2`, so every frame differs from the one before.
fn striped_targets(
    n: usize,
    s: usize,
    (shift, period): (usize, usize),
    device: &Device,
) -> Vec<Tensor<4>> {
    (0..n)
        .map(|t| {
            let y: Vec<f32> = (0..2 * s * s)
                .map(|i| f32::from(u8::from((i + shift * t) % period < 2)))
                .collect();
            Tensor::from_data(TensorData::new(y, [1, 2, s, s]), device)
        })
        .collect()
}

/// A scalar of the model's outputs over a few frames: a fixed weighting of the logits.
fn objective(model: &ProcNetModel, xs: &[Tensor<4>], device: &Device) -> Tensor<1> {
    let [b, _, s, _] = xs[0].dims();
    let mut state = model.initial_state(b, s, s, device);
    let mut total: Option<Tensor<1>> = None;
    for (t, x) in xs.iter().enumerate() {
        let (out, next) = model.step(x.clone(), state);
        state = next;
        let [_, c, h, w] = out.logits.dims();
        let weights: Vec<f32> = (0..c * h * w)
            .map(|i| ((i * 7 + t * 3) % 11) as f32 / 11.0 - 0.4)
            .collect();
        let wt = Tensor::<4>::from_data(TensorData::new(weights, [1, c, h, w]), device);
        let v = (out.logits * wt).sum();
        total = Some(match total {
            Some(a) => a + v,
            None => v,
        });
    }
    total.expect("at least one frame")
}

fn hgru_kernel(model: &ProcNetModel, layer: usize) -> &Param<Tensor<4>> {
    match &model.layers[layer].cell {
        Cell::Hgru(h) => &h.w_inh,
        _ => panic!("an hGRU model"),
    }
}

fn with_kernel(mut model: ProcNetModel, layer: usize, value: Tensor<4>) -> ProcNetModel {
    if let Cell::Hgru(h) = &mut model.layers[layer].cell {
        let id = h.w_inh.id;
        h.w_inh = Param::from_tensor(value);
        h.w_inh.id = id;
    }
    model
}

/// The autodiff gradient of the hGRU's inhibition kernel agrees with central differences of
/// the same objective (f64 on the flex backend).
#[test]
fn hgru_gradients_match_finite_differences() {
    let config = ProcNetConfig {
        input_size: 8,
        repr_channels: vec![3, 4, 4],
        input_channels: vec![3, 3, 4],
        ..tiny(CellKind::Hgru)
    };
    let inner = Device::flex();
    let device = inner.clone().autodiff();
    let model = config.init(&device, 21).unwrap();
    let xs = frames(3, config.input_size, &device);
    let grads = objective(&model, &xs, &device).backward();
    let layer = 1;
    let analytic: Vec<f32> = hgru_kernel(&model, layer)
        .val()
        .grad(&grads)
        .expect("the kernel takes part in the objective")
        .into_data()
        .try_to_vec()
        .unwrap();

    let base = model.valid();
    let xs = frames(3, config.input_size, &inner);
    let w0: Vec<f32> = hgru_kernel(&base, layer)
        .val()
        .into_data()
        .try_to_vec()
        .unwrap();
    let shape = hgru_kernel(&base, layer).val().dims();
    let eval = |w: Vec<f32>| -> f64 {
        let m = with_kernel(
            base.clone(),
            layer,
            Tensor::from_data(TensorData::new(w, shape), &inner),
        );
        f64::from(objective(&m, &xs, &inner).into_scalar::<f32>())
    };
    // f32 arithmetic: 3e-3 balances rounding noise against curvature (checked against 1e-3
    // and 3e-2 while writing this test).
    let eps = 3e-3f32;
    let (mut checked, mut nonzero) = (0, 0);
    for i in (0..w0.len()).step_by(7) {
        let mut plus = w0.clone();
        plus[i] += eps;
        let mut minus = w0.clone();
        minus[i] -= eps;
        let numeric = (eval(plus) - eval(minus)) / (2.0 * f64::from(eps));
        let a = f64::from(analytic[i]);
        assert!(
            (numeric - a).abs() <= 2e-2 * a.abs().max(numeric.abs()) + 2e-3,
            "entry {i}: autodiff {a:.6}, finite differences {numeric:.6}"
        );
        checked += 1;
        nonzero += usize::from(a.abs() > 1e-3);
    }
    assert!(checked > 20);
    assert!(
        nonzero >= 5,
        "only {nonzero} checked entries have a gradient"
    );
    // Not a vacuous agreement: the gradient is not zero.
    assert!(analytic.iter().any(|g| g.abs() > 1e-3));
}

/// The horizontal kernels are symmetric over their channel axes and stay so after AdamW steps.
#[test]
fn horizontal_kernels_stay_symmetric_after_optimiser_steps() {
    let config = tiny(CellKind::Hgru);
    let device = Device::flex().autodiff();
    let mut model = config.init(&device, 2).unwrap();
    let mut optim = AdamWConfig::new().init();
    let xs = frames(3, config.input_size, &device);
    let before: Vec<f32> = hgru_kernel(&model, 0)
        .val()
        .into_data()
        .try_to_vec()
        .unwrap();
    for _ in 0..3 {
        let grads = objective(&model, &xs, &device).backward();
        let grads = GradientsParams::from_grads(grads, &model);
        model = optim.step(1e-2, model, grads);
    }
    for layer in 0..3 {
        let w = hgru_kernel(&model, layer).val();
        let [k, _, s, _] = w.dims();
        let v: Vec<f32> = w.into_data().try_to_vec().unwrap();
        for o in 0..k {
            for i in 0..k {
                for p in 0..s * s {
                    let (a, b) = (v[(o * k + i) * s * s + p], v[(i * k + o) * s * s + p]);
                    assert!(
                        (a - b).abs() <= 1e-6 * a.abs().max(1.0),
                        "layer {layer} W[{o},{i},{p}] {a} vs W[{i},{o},{p}] {b}"
                    );
                }
            }
        }
    }
    // The steps did move the kernel.
    let after: Vec<f32> = hgru_kernel(&model, 0)
        .val()
        .into_data()
        .try_to_vec()
        .unwrap();
    assert!(before.iter().zip(&after).any(|(a, b)| (a - b).abs() > 1e-4));
}

/// A moving square and its mask: the network learns to segment two short sequences almost
/// perfectly (Dice loss of frames after the first below 0.05).
#[test]
fn a_tiny_batch_overfits() {
    let config = ProcNetConfig {
        input_size: 16,
        repr_channels: vec![8, 8, 8],
        input_channels: vec![3, 8, 8],
        classes: vec![Class::Forearm],
        ..tiny(CellKind::Hgru)
    };
    let device = Device::flex().autodiff();
    let (s, t_len, b) = (config.input_size, 4, 2);
    let mut rgb = Vec::new();
    let mut target = Vec::new();
    for t in 0..t_len {
        let mut x = vec![0.2f32; b * 3 * s * s];
        let mut y = vec![0f32; b * s * s];
        for k in 0..b {
            let (x0, y0) = (2 + t + 3 * k, 4 + k * 2);
            for yy in y0..y0 + 6 {
                for xx in x0..x0 + 5 {
                    for c in 0..3 {
                        x[((k * 3 + c) * s + yy) * s + xx] = 0.3 + 0.25 * c as f32;
                    }
                    y[(k * s + yy) * s + xx] = 1.0;
                }
            }
        }
        rgb.push(Tensor::<4>::from_data(
            TensorData::new(x, [b, 3, s, s]),
            &device,
        ));
        target.push(Tensor::<4>::from_data(
            TensorData::new(y, [b, 1, s, s]),
            &device,
        ));
    }
    let mut model = config.init(&device, 4).unwrap();
    let mut optim = AdamWConfig::new().init();
    let loss = LossConfig::default();
    let first = window_loss(&model, &rgb, &target, &loss, None, None);
    let first_dice = f64::from(first.dice.into_scalar::<f32>());
    for _ in 0..150 {
        let l = window_loss(&model, &rgb, &target, &loss, None, None);
        let grads = GradientsParams::from_grads(l.total.backward(), &model);
        model = optim.step(1e-2, model, grads);
    }
    let model = model.valid();
    let inner = Device::flex();
    let mut state = model.initial_state(b, s, s, &inner);
    let mut dice = 0.0;
    for t in 0..t_len {
        let x = Tensor::<4>::from_data(rgb[t].clone().into_data(), &inner);
        let (out, next) = model.step(x, state);
        state = next;
        if t > 0 {
            let y = Tensor::<4>::from_data(target[t].clone().into_data(), &inner);
            let p = burn::tensor::activation::sigmoid(out.logits);
            dice +=
                f64::from(dice_per_class(p, y).mean().into_scalar::<f32>()) / (t_len - 1) as f64;
        }
    }
    assert!(
        first_dice > 0.3,
        "the untrained net should not already solve it ({first_dice})"
    );
    assert!(
        dice < 0.05,
        "Dice loss after training {dice:.4} (before {first_dice:.4})"
    );
}

/// A window's loss is the mean over its weighted frames: a recurrent network's first frame
/// weighs 0 (its state is empty), a feed-forward network's weighs 1 like the rest.
#[test]
fn a_window_weighs_its_first_frame_only_for_a_feed_forward_network() {
    let device = Device::flex();
    let s = 16;
    let xs = frames(3, s, &device);
    let targets = striped_targets(3, s, (5, 7), &device);
    let loss = LossConfig {
        prediction: 0.0,
        ..LossConfig::default()
    };
    let total = |model: &ProcNetModel, range: std::ops::Range<usize>| {
        let l = window_loss(
            model,
            &xs[range.clone()],
            &targets[range],
            &loss,
            None,
            None,
        );
        f64::from(l.total.into_scalar::<f32>())
    };
    // Feed-forward: each frame alone, so the window's loss is the mean of the frames' own.
    let baseline = tiny(CellKind::Hgru).feed_forward_baseline();
    let model = baseline.init(&device, 2).unwrap();
    let single: Vec<f64> = (0..3).map(|t| total(&model, t..t + 1)).collect();
    let mean = single.iter().sum::<f64>() / 3.0;
    assert!((total(&model, 0..3) - mean).abs() < 1e-5, "{single:?}");
    assert!(single.iter().all(|l| l.is_finite() && *l > 0.0));
    // Recurrent: frame 0 is not scored, so frames 1 and 2 alone decide the window's loss.
    let model = tiny(CellKind::Hgru).init(&device, 2).unwrap();
    let window = window_loss(&model, &xs, &targets, &loss, None, None);
    let mut state = model.initial_state(1, s, s, &device);
    let mut sum = 0.0;
    for t in 0..3 {
        let (out, next) = model.step(xs[t].clone(), state);
        state = next;
        if t > 0 {
            let p = burn::tensor::activation::sigmoid(out.logits);
            sum += f64::from(
                dice_per_class(p, targets[t].clone())
                    .mean()
                    .into_scalar::<f32>(),
            );
        }
    }
    let dice = f64::from(window.dice.into_scalar::<f32>());
    assert!(
        (dice - sum / 2.0).abs() < 1e-5,
        "{dice} against {}",
        sum / 2.0
    );
}

/// A window after a burn-in scores what the same frames score inside one run from the
/// sequence's start: the burnt-in state is the state evaluation carries, and every frame
/// of the window counts, its first too.
#[test]
fn a_burnt_in_window_scores_the_frames_of_the_whole_run() {
    let device = Device::flex().autodiff();
    let s = 16;
    let n = 5;
    let xs = frames(n, s, &device);
    let targets = striped_targets(n, s, (3, 5), &device);
    let loss = LossConfig::default();
    let model = tiny(CellKind::Hgru).init(&device, 3).unwrap();
    let scalar = |t: Tensor<1>| f64::from(t.into_scalar::<f32>());
    // Frames 1..n from a zero state (frame 0 weighs 0), against frame 0 burnt in.
    let whole = window_loss(&model, &xs, &targets, &loss, None, None);
    let initial = burn_in_state(&model, &xs[..1]);
    assert!(initial.is_some());
    let after = window_loss(&model, &xs[1..], &targets[1..], &loss, None, initial);
    for (a, b) in [(whole.total, after.total), (whole.dice, after.dice)] {
        let (a, b) = (scalar(a), scalar(b));
        assert!((a - b).abs() < 1e-5, "{a} against {b}");
    }
    // Without the burn-in, the same frames start from nothing and score otherwise.
    let cold = window_loss(&model, &xs[1..], &targets[1..], &loss, None, None);
    let whole = window_loss(&model, &xs, &targets, &loss, None, None);
    assert!((scalar(cold.total) - scalar(whole.total)).abs() > 1e-4);
    // The burnt-in state joins the window's graph as a constant: on the autodiff device,
    // tracked by no graph, so the window's gradients reach the parameters through its own
    // frames only.
    let state = burn_in_state(&model, &xs[..2]).expect("two frames");
    assert_eq!(state.frames, 2);
    for t in state.cells.iter().map(|c| &c.h).chain(&state.errors) {
        assert!(t.is_autodiff() && !t.is_tracked());
    }
    let after = window_loss(&model, &xs[2..], &targets[2..], &loss, None, Some(state));
    let grads = GradientsParams::from_grads(after.total.backward(), &model);
    assert!(!grads.is_empty());
    assert!(burn_in_state(&model, &[]).is_none());
}

/// A window that starts with view reads begins as a deployed stream begins a new view: its
/// first frame read that many times with nothing before, then every frame of the window
/// scored from there, the first too. A burn-in, when there is one, decides the start instead.
#[test]
fn a_window_with_view_reads_starts_as_a_new_view_does() {
    let device = Device::flex().autodiff();
    let s = 16;
    let n = 4;
    let reads = 3;
    let xs = frames(n, s, &device);
    let targets = striped_targets(n, s, (3, 5), &device);
    let loss = LossConfig::default();
    let model = tiny(CellKind::Hgru).init(&device, 3).unwrap();
    let scalar = |t: Tensor<1>| f64::from(t.into_scalar::<f32>());
    let start = window_start(&model, &xs, 0, reads).expect("three reads");
    assert_eq!(start.frames, reads);
    let window = window_loss(&model, &xs, &targets, &loss, None, Some(start));
    // By hand: frame 0 read three times, then frames 0..n, each one's Dice counted.
    let mut state = model.initial_state(1, s, s, &device);
    let reads_then_window = std::iter::repeat_n(0, reads).chain(0..n);
    let mut dice = Vec::new();
    for (i, t) in reads_then_window.enumerate() {
        let (out, next) = model.step(xs[t].clone(), state);
        state = next;
        if i >= reads {
            let p = burn::tensor::activation::sigmoid(out.logits);
            dice.push(scalar(
                dice_per_class(p, targets[t].clone()).mean().reshape([1]),
            ));
        }
    }
    let by_hand = dice.iter().sum::<f64>() / n as f64;
    let got = scalar(window.dice);
    assert!((got - by_hand).abs() < 1e-5, "{got} against {by_hand}");
    // A cold window scores frames 1..n alone, from nothing: another loss.
    let cold = scalar(window_loss(&model, &xs, &targets, &loss, None, None).dice);
    assert!((cold - by_hand).abs() > 1e-4, "{cold} against {by_hand}");
    // No reads and no burn-in: a zero state. A burn-in: its frames, whatever view_reads says.
    assert!(window_start(&model, &xs, 0, 0).is_none());
    let burnt = window_start(&model, &xs, 2, reads).expect("a burn-in");
    assert_eq!(burnt.frames, 2);
    let after = scalar(window_loss(&model, &xs[2..], &targets[2..], &loss, None, Some(burnt)).dice);
    let burn_in = burn_in_state(&model, &xs[..2]);
    let expected = scalar(window_loss(&model, &xs[2..], &targets[2..], &loss, None, burn_in).dice);
    assert!(
        (after - expected).abs() < 1e-6,
        "{after} against {expected}"
    );
    let read = window_start(&model, &xs[2..], 0, reads);
    let read = scalar(window_loss(&model, &xs[2..], &targets[2..], &loss, None, read).dice);
    assert!((after - read).abs() > 1e-4, "{after} against {read}");
}

/// A weight file whose metadata claims a model larger than its tensors is refused before
/// the model is built (4096 channels in a file of a few kB grew past 4 GB).
#[test]
fn a_weight_file_cannot_claim_more_than_it_holds() {
    use workcell_procnet::weights;
    let config = tiny(CellKind::Hgru);
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("tiny.safetensors");
    let model = config.init(&Device::flex(), 0).expect("model");
    weights::save(&model, &config, &path).expect("save");
    assert_eq!(weights::read_config(&path).expect("honest"), config);

    // The same tensors under a header whose configuration claims 4096 channels per layer.
    let bytes = std::fs::read(&path).expect("read");
    let header_len = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes")) as usize;
    let mut header: serde_json::Value =
        serde_json::from_slice(&bytes[8..8 + header_len]).expect("header");
    let mut claim = config.clone();
    claim.repr_channels = vec![4096; config.layers()];
    claim.input_channels = std::iter::once(3)
        .chain(vec![4096; config.layers() - 1])
        .collect();
    claim.cell_kernel = 15;
    header["__metadata__"]["config"] = serde_json::Value::String(claim.to_json());
    let new_header = serde_json::to_vec(&header).expect("json");
    let mut lying = (new_header.len() as u64).to_le_bytes().to_vec();
    lying.extend_from_slice(&new_header);
    lying.extend_from_slice(&bytes[8 + header_len..]);
    let lie = dir.path().join("lie.safetensors");
    std::fs::write(&lie, lying).expect("write");
    let Err(err) = weights::load(&lie, &Device::flex()) else {
        panic!("weights claiming 4096 channels loaded");
    };
    let err = err.to_string();
    assert!(
        err.contains("its configuration claims") && err.contains("the file holds"),
        "{err}"
    );
}

/// Every training recipe under `configs/` (the recipes of the shipped weights) parses and
/// validates with today's keys, and none begins its windows as a new view (`view_reads`):
/// one that no longer parses is a shipped network nobody can train again. The recipes of
/// experiments live in `experiments/configs/`, as of the commits that ran them.
#[test]
fn every_recipe_in_configs_parses() {
    use workcell_procnet::TrainConfig;
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs");
    let mut recipes = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("the configs folder") {
        let path = entry.expect("a folder entry").path();
        let name = path
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_string();
        if !(name.starts_with("train") && name.ends_with(".toml")) {
            continue;
        }
        let config = TrainConfig::from_file(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(config.view_reads, 0, "{name}");
        recipes.push(name);
    }
    recipes.sort();
    // procnet-cpu, the baseline (with --model baseline), procnet-skeletal, procnet-depth.
    assert_eq!(
        recipes,
        [
            "train-64-depth.toml",
            "train-64.toml",
            "train-skeletal.toml",
            "train.toml"
        ]
    );
}
