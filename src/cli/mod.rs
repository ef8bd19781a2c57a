//! Subcommands of the `workcell` binary.

pub mod robot;
pub mod simulate;
