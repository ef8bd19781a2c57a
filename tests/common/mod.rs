//! Helpers shared by the end-to-end tests.

use std::path::Path;
use std::process::Command;

/// The `workcell` binary run in `dir`, with `library` as its robot library
/// (`WORKCELL_ROBOT_PATH`).
pub fn workcell_with_library(dir: &Path, library: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_workcell"));
    command.env("WORKCELL_ROBOT_PATH", library).current_dir(dir);
    command
}
