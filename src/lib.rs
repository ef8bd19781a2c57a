#![doc = include_str!("../README.md")]

pub use workcell_mocap as mocap;
pub use workcell_perception as perception;
pub use workcell_procnet as procnet;
pub use workcell_render as render;
pub use workcell_robots as robots;
pub use workcell_safety as safety;
pub use workcell_sim as sim;

pub mod crop;
mod error;
pub mod evaluate;
pub mod plot;

pub use error::{Error, Result};
