//! Weight files: safetensors with the model's configuration in the metadata, so that a file
//! is refused by a model of another configuration with an error that says what differs.

use std::path::Path;

use burn::module::Module;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use burn::tensor::Device;

use crate::config::ProcNetConfig;
use crate::error::{ProcNetError, Result};
use crate::model::ProcNetModel;

/// The shipped ProcNet for an RGB camera, relative to the source tree's root.
pub const SHIPPED_RGB: &str = "procnet/weights/procnet-cpu.safetensors";

/// The shipped ProcNet for a camera that measures depth (it reads the depth image as a fourth
/// plane), relative to the source tree's root.
pub const SHIPPED_DEPTH: &str = "procnet/weights/procnet-depth.safetensors";

/// The shipped ProcNet for a camera that measures depth and a human with a trunk that turns,
/// leans and walks (the catalogue's `human`, the cell's default): [`SHIPPED_DEPTH`] trained
/// on for the whole body's frames, half of them recorded people.
pub const SHIPPED_DEPTH_BODY: &str = "procnet/weights/procnet-depth-human.safetensors";

/// The catalogue's arm on a fixed torso (the paper's human), which the other shipped
/// networks' frames show.
pub const PAPER_ARM: &str = "human_arm";

/// The shipped weights for a camera with (`depth`) or without a depth channel, relative to
/// the source tree's root: the networks trained on the paper's arm ([`PAPER_ARM`]).
#[must_use]
pub fn shipped(depth: bool) -> &'static str {
    if depth { SHIPPED_DEPTH } else { SHIPPED_RGB }
}

/// The shipped weights for a camera with or without depth that sees `human_model` (a
/// catalogue name or a URDF path): [`SHIPPED_DEPTH_BODY`] for a depth camera and any human
/// but the paper's arm, else [`shipped`]'s (the RGB network has seen the paper's arm only).
#[must_use]
pub fn shipped_for(depth: bool, human_model: &str) -> &'static str {
    if depth && human_model != PAPER_ARM {
        SHIPPED_DEPTH_BODY
    } else {
        shipped(depth)
    }
}

/// What a user of [`shipped_for`]'s choice should know: the RGB network has seen only the
/// paper's arm, so on any other human (the whole body) its masks have not been measured.
/// `None` where the choice is a network trained on that human.
#[must_use]
pub fn shipped_for_warning(depth: bool, human_model: &str) -> Option<String> {
    (!depth && human_model != PAPER_ARM).then(|| {
        format!(
            "no shipped RGB network has seen the human `{human_model}`: {SHIPPED_RGB} was \
             trained on the paper's arm ({PAPER_ARM}) alone, and its masks of this human are \
             not measured; a depth camera (perception.depth = true) picks \
             {SHIPPED_DEPTH_BODY}, trained on the whole body"
        )
    })
}

/// `relative` (a path relative to the source tree's root) in this crate's source tree,
/// wherever the program runs from.
fn in_source_tree(relative: &str) -> std::path::PathBuf {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    crate_dir.parent().unwrap_or(crate_dir).join(relative)
}

/// [`shipped`] as a path in this crate's source tree, wherever the program runs from.
#[must_use]
pub fn shipped_path(depth: bool) -> std::path::PathBuf {
    in_source_tree(shipped(depth))
}

/// [`shipped_for`] as a path in this crate's source tree, wherever the program runs from.
#[must_use]
pub fn shipped_path_for(depth: bool, human_model: &str) -> std::path::PathBuf {
    in_source_tree(shipped_for(depth, human_model))
}

/// The `format` entry of a weight file's metadata.
pub const FORMAT: &str = "workcell-procnet/1";

fn weights_error(path: &Path, message: impl Into<String>) -> ProcNetError {
    ProcNetError::Weights {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Reads and checks a safetensors header: its metadata, and that the file holds every byte
/// the header points to.
pub fn read_metadata(path: &Path) -> Result<serde_json::Map<String, serde_json::Value>> {
    read_header(path).map(|(meta, _)| meta)
}

/// The largest weight file read, bytes.
pub const MAX_WEIGHTS_BYTES: u64 = 4 << 30;

/// The metadata of a safetensors file and the size of its data section, checked as
/// [`read_metadata`] says.
fn read_header(path: &Path) -> Result<(serde_json::Map<String, serde_json::Value>, usize)> {
    let bytes = workcell_robots::input::read_regular_file(path, MAX_WEIGHTS_BYTES)
        .map_err(|e| weights_error(path, format!("cannot read: {e}")))?;
    parse_header(&bytes, path)
}

/// [`read_header`] on bytes already read; `path` names them in errors.
fn parse_header(
    bytes: &[u8],
    path: &Path,
) -> Result<(serde_json::Map<String, serde_json::Value>, usize)> {
    let header_len = bytes
        .get(..8)
        .map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
        .ok_or_else(|| weights_error(path, "not a safetensors file: shorter than its header"))?;
    let header_end = usize::try_from(header_len)
        .ok()
        .and_then(|n| n.checked_add(8))
        .filter(|&end| end <= bytes.len())
        .ok_or_else(|| {
            weights_error(
                path,
                format!("truncated or corrupt: header of {header_len} bytes"),
            )
        })?;
    let header: serde_json::Map<String, serde_json::Value> =
        serde_json::from_slice(&bytes[8..header_end])
            .map_err(|e| weights_error(path, format!("corrupt header: {e}")))?;
    let data_len = bytes.len() - header_end;
    for (name, info) in &header {
        if name == "__metadata__" {
            continue;
        }
        let end = info
            .get("data_offsets")
            .and_then(|o| o.get(1))
            .and_then(serde_json::Value::as_u64)
            .ok_or_else(|| weights_error(path, format!("corrupt header entry {name:?}")))?;
        if end > data_len as u64 {
            return Err(weights_error(
                path,
                format!(
                    "truncated: tensor {name:?} ends at byte {end} of a {data_len}-byte data section"
                ),
            ));
        }
    }
    let meta = match header.get("__metadata__") {
        Some(serde_json::Value::Object(m)) => m.clone(),
        _ => serde_json::Map::new(),
    };
    Ok((meta, data_len))
}

/// The configuration stored in a weight file.
pub fn read_config(path: &Path) -> Result<ProcNetConfig> {
    let (meta, data_len) = read_header(path)?;
    config_of(&meta, data_len, path)
}

/// The configuration stored in the bytes of a weight file (checked as [`read_config`]
/// checks it); `path` names them in errors.
///
/// # Errors
/// As [`read_config`], without the I/O.
pub fn config_from_bytes(bytes: &[u8], path: &Path) -> Result<ProcNetConfig> {
    let (meta, data_len) = parse_header(bytes, path)?;
    config_of(&meta, data_len, path)
}

fn config_of(
    meta: &serde_json::Map<String, serde_json::Value>,
    data_len: usize,
    path: &Path,
) -> Result<ProcNetConfig> {
    let format = meta.get("format").and_then(|v| v.as_str()).unwrap_or("");
    if format != FORMAT {
        return Err(weights_error(
            path,
            format!("not a workcell ProcNet weight file (format {format:?}, expected {FORMAT:?})"),
        ));
    }
    let text = meta
        .get("config")
        .and_then(|v| v.as_str())
        .ok_or_else(|| weights_error(path, "no configuration in the metadata"))?;
    let config: ProcNetConfig = serde_json::from_str(text)
        .map_err(|e| weights_error(path, format!("bad configuration in the metadata: {e}")))?;
    config
        .validate()
        .map_err(|e| weights_error(path, format!("configuration: {e}")))?;
    // The model is built from the claimed configuration before its tensors are read: a claim
    // the file cannot back (4096 channels in 1.3 MB) would allocate gigabytes first.
    let claimed = config.parameter_count().saturating_mul(4);
    if claimed > data_len {
        return Err(weights_error(
            path,
            format!(
                "its configuration claims {} parameters ({claimed} bytes of f32), but the file \
                 holds {data_len} bytes of tensors",
                config.parameter_count()
            ),
        ));
    }
    Ok(config)
}

/// Saves a model and its configuration.
pub fn save(model: &ProcNetModel, config: &ProcNetConfig, path: &Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|source| ProcNetError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    // Write beside, then rename: an interrupted save never leaves a half file.
    workcell_robots::output::write_atomic_with(
        path,
        |tmp| {
            let mut store = SafetensorsStore::from_file(tmp)
                .metadata("format", FORMAT)
                .metadata("config", config.to_json())
                .overwrite(true);
            model
                .save_into(&mut store)
                .map_err(|e| weights_error(path, format!("cannot save: {e}")))
        },
        |source| ProcNetError::Io {
            path: path.to_path_buf(),
            source,
        },
    )
}

/// Loads weights into a fresh model of the file's own configuration.
pub fn load(path: &Path, device: &Device) -> Result<(ProcNetModel, ProcNetConfig)> {
    let config = read_config(path)?;
    let mut model = config.init(device, 0)?;
    load_into(&mut model, path)?;
    Ok((model, config))
}

/// Loads weights into `model`, which must be of the configuration `expected`.
pub fn load_checked(model: &mut ProcNetModel, expected: &ProcNetConfig, path: &Path) -> Result<()> {
    check_config(path, expected)?;
    load_into(model, path)
}

/// Reads only the configuration of a weight file and refuses one other than `expected`,
/// naming what differs.
pub fn check_config(path: &Path, expected: &ProcNetConfig) -> Result<()> {
    compare_config(path, read_config(path)?, expected)
}

/// Like [`check_config`], but accepts weights of another input size: no parameter depends on
/// it (every layer is convolutional), so a run can start from weights trained on smaller
/// frames (progressive resizing).
pub fn check_config_any_input_size(path: &Path, expected: &ProcNetConfig) -> Result<()> {
    let mut found = read_config(path)?;
    found.input_size = expected.input_size;
    compare_config(path, found, expected)
}

/// The check of a run's starting weights: [`check_config_any_input_size`], and a network
/// that reads depth may also start from the same network's RGB weights
/// ([`load_start`] grows them, [`ProcNetModel::grow_depth_input`]).
pub fn check_start(path: &Path, expected: &ProcNetConfig) -> Result<()> {
    let mut found = read_config(path)?;
    found.input_size = expected.input_size;
    if expected.reads_depth() && found.input_channels.first() == Some(&3) {
        found.input_channels[0] = 4;
    }
    compare_config(path, found, expected)
}

/// Loads a run's starting weights ([`check_start`] has passed) into `model`, of the
/// configuration `expected`: as they are, or RGB weights grown to read depth when `expected`
/// reads it.
pub fn load_start(
    model: &mut ProcNetModel,
    expected: &ProcNetConfig,
    path: &Path,
    device: &Device,
) -> Result<()> {
    let found = read_config(path)?;
    if !expected.reads_depth() || found.reads_depth() {
        return load_into(model, path);
    }
    let mut rgb = found.init(device, 0)?;
    load_into(&mut rgb, path)?;
    let grown = rgb.grow_depth_input()?;
    // Grown, it must fit the model it replaces parameter for parameter.
    let shapes = |m: &ProcNetModel| {
        let mut v = Vec::new();
        m.visit(&mut ShapeOf(&mut v));
        v
    };
    if shapes(&grown) != shapes(model) {
        return Err(weights_error(
            path,
            "RGB weights grown to read depth do not fit the run's network",
        ));
    }
    *model = grown;
    Ok(())
}

/// Collects every parameter's shape, in the model's order.
struct ShapeOf<'a>(&'a mut Vec<Vec<usize>>);

impl burn::module::ModuleVisitor for ShapeOf<'_> {
    fn visit_float<const D: usize>(
        &mut self,
        param: &burn::module::Param<burn::tensor::Tensor<D>>,
    ) {
        self.0.push(param.val().dims().to_vec());
    }
}

fn compare_config(path: &Path, found: ProcNetConfig, expected: &ProcNetConfig) -> Result<()> {
    if &found != expected {
        return Err(weights_error(
            path,
            format!(
                "weights of another configuration: {}",
                config_difference(expected, &found)
            ),
        ));
    }
    Ok(())
}

/// Loads a file's tensors into `model` without checking its configuration (the caller has).
pub(crate) fn load_into(model: &mut ProcNetModel, path: &Path) -> Result<()> {
    workcell_robots::input::check_regular_file(path, MAX_WEIGHTS_BYTES)
        .map_err(|e| weights_error(path, format!("cannot read: {e}")))?;
    let mut store = SafetensorsStore::from_file(path);
    let result = model
        .load_from(&mut store)
        .map_err(|e| weights_error(path, format!("cannot load: {e}")))?;
    if !result.missing.is_empty() || !result.errors.is_empty() {
        return Err(weights_error(
            path,
            format!(
                "does not fit the model: missing {:?}, errors {:?}",
                result.missing, result.errors
            ),
        ));
    }
    Ok(())
}

/// The keys that differ between two configurations, as `key: expected vs found`.
#[must_use]
pub fn config_difference(expected: &ProcNetConfig, found: &ProcNetConfig) -> String {
    value_difference(
        &serde_json::to_value(expected).unwrap_or_default(),
        &serde_json::to_value(found).unwrap_or_default(),
    )
}

/// The top-level keys that differ between two JSON objects, as `key: expected vs found`,
/// sorted by key.
#[must_use]
pub fn value_difference(a: &serde_json::Value, b: &serde_json::Value) -> String {
    let mut diffs = Vec::new();
    if let (Some(a), Some(b)) = (a.as_object(), b.as_object()) {
        let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
        keys.sort();
        keys.dedup();
        for k in keys {
            if a.get(k) != b.get(k) {
                diffs.push(format!(
                    "{k}: expected {} found {}",
                    a.get(k).map_or("-".into(), ToString::to_string),
                    b.get(k).map_or("-".into(), ToString::to_string)
                ));
            }
        }
    }
    diffs.join("; ")
}
