//! ProcNet for workcell: a predictive-coding network (PredNet layers with hGRU, ConvLSTM or
//! convolutional cells and a segmentation decoder) that segments the human arm in camera
//! frames of the work-cell and stays robust when the arm is partly hidden; its training and
//! its segmentation evaluation. The arm's pose and the runtime tracker are
//! `workcell-perception`, above this crate.
//!
//! The model is written once; the [`Device`](burn::tensor::Device) picks the backend at run
//! time: `flex` (pure Rust, the default), LibTorch (feature `tch`).

pub mod backend;
pub mod bench;
pub mod cells;
pub mod config;
pub mod data;
mod error;
pub mod eval;
pub mod image;
mod infer;
pub mod loss;
pub mod model;
pub mod nn;
pub mod ops;
pub mod train;
pub mod weights;

pub use backend::Backend;
pub use config::{Activation, CellKind, ProcNetConfig};
pub use error::{ProcNetError, Result};
pub use infer::{Masks, ProcNet, VIEW_READS};
pub use model::{ProcNetModel, ProcNetState, StepOutput};
pub use train::{TrainConfig, Trainer};
