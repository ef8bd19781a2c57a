//! Helpers shared by the end-to-end tests.

use std::path::Path;
use std::process::Command;

/// The `workcell` binary run in `dir`, with `library` as its robot library
/// (`WORKCELL_ROBOT_PATH`).
#[allow(dead_code)] // each test crate that includes this module uses its own part of it
pub fn workcell_with_library(dir: &Path, library: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_workcell"));
    command.env("WORKCELL_ROBOT_PATH", library).current_dir(dir);
    command
}

/// Every `.rs` file under `dir`, with its text before its first `#[cfg(test)]` (the
/// product's code; tests may do what the product must not).
#[allow(dead_code)] // each test crate that includes this module uses its own part of it
pub fn product_sources(dir: &Path) -> Vec<(std::path::PathBuf, String)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("source folder").flatten() {
            let path = entry.path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let source = std::fs::read_to_string(&path).expect("source");
                let product = source.split("#[cfg(test)]").next().unwrap_or_default();
                out.push((path, product.to_string()));
            }
        }
    }
    out
}
