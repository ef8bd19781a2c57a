//! Subcommands of the `workcell` binary.

pub mod dataset;
pub mod perception;
pub mod robot;
pub mod simulate;
