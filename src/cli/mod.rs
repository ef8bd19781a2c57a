//! Subcommands of the `workcell` binary.

pub mod dataset;
pub mod robot;
pub mod simulate;
