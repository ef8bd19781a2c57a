#![doc = include_str!("../README.md")]
#![allow(non_snake_case)] // monogram frame notation: X_WB, p_WC

pub use workcell_robots as robots;
pub use workcell_sim as sim;

pub mod plot;
