//! The module graph of docs/ARCHITECTURE.md holds: within every crate of the workspace, no
//! two modules import each other, directly or around a loop. Cargo already refuses cycles
//! between crates; this checks the modules inside each one, from the sources' `crate::` and
//! `super::` paths (product code: comments and `#[cfg(test)]` code are left out).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

mod common;

/// The source roots of the workspace's crates.
const CRATES: [&str; 8] = [
    "src",
    "robots/src",
    "mocap/src",
    "sim/src",
    "sim/render/src",
    "procnet/src",
    "perception/src",
    "safety/src",
];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.rs` file under `dir` with its module path (`pose/articulated/fit.rs` is
/// `["pose", "articulated", "fit"]`; `lib.rs`, `main.rs` and `mod.rs` name their folder).
fn modules(dir: &Path) -> Vec<(Vec<String>, String)> {
    common::product_sources(dir)
        .into_iter()
        .map(|(path, product)| {
            let relative = path.strip_prefix(dir).expect("inside");
            let mut module: Vec<String> = relative
                .with_extension("")
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            if matches!(
                module.last().map(String::as_str),
                Some("mod" | "lib" | "main")
            ) {
                module.pop();
            }
            let code: String = product
                .lines()
                .filter(|l| !l.trim_start().starts_with("//"))
                .collect::<Vec<_>>()
                .join("\n");
            (module, code)
        })
        .collect()
}

/// The module paths `code` (in module `at`) names: `crate::a::b`, `super::c`, with the
/// items of a `use` group each followed.
fn references(at: &[String], code: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    for start in ["crate::", "super::"] {
        let mut from = 0;
        while let Some(i) = code[from..].find(start) {
            let i = from + i;
            from = i + start.len();
            if i > 0 && (ident(bytes[i - 1]) || bytes[i - 1] == b':') {
                continue;
            }
            let mut base: Vec<String> = if start == "crate::" {
                Vec::new()
            } else {
                at[..at.len().saturating_sub(1)].to_vec()
            };
            let mut rest = &code[i + start.len()..];
            while let Some(r) = rest.strip_prefix("super::") {
                base.pop();
                rest = r;
            }
            // The path's segments up to a group, a glob or its end.
            let end = rest
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == ':'))
                .unwrap_or(rest.len());
            let mut path = base.clone();
            path.extend(
                rest[..end]
                    .split("::")
                    .filter(|s| !s.is_empty())
                    .map(str::to_string),
            );
            if rest[end..].starts_with('{') {
                let close = rest[end..].find('}').map_or(rest.len(), |j| end + j);
                for item in rest[end + 1..close].split(',') {
                    let first = item.trim().split("::").next().unwrap_or("").trim();
                    if !first.is_empty() {
                        let mut p = path.clone();
                        p.push(first.to_string());
                        out.push(p);
                    }
                }
            } else {
                out.push(path);
            }
        }
    }
    out
}

/// A loop in `edges` (module -> the modules it imports), if any.
fn find_cycle(edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Option<Vec<Vec<String>>> {
    fn visit(
        n: &Vec<String>,
        edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        state: &mut BTreeMap<Vec<String>, u8>,
        stack: &mut Vec<Vec<String>>,
    ) -> Option<Vec<Vec<String>>> {
        state.insert(n.clone(), 1);
        stack.push(n.clone());
        for m in edges.get(n).into_iter().flatten() {
            match state.get(m).copied().unwrap_or(0) {
                1 => {
                    let at = stack.iter().position(|s| s == m).unwrap_or(0);
                    let mut cycle = stack[at..].to_vec();
                    cycle.push(m.clone());
                    return Some(cycle);
                }
                0 => {
                    if let Some(c) = visit(m, edges, state, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(n.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in edges.keys() {
        if state.get(n).copied().unwrap_or(0) == 0
            && let Some(c) = visit(n, edges, &mut state, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

/// The edges between sibling modules: a module that names a path inside a sibling (or a
/// sibling's descendant) imports that sibling; names of its own ancestors or descendants
/// are not edges.
fn sibling_edges(crate_dir: &Path) -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let files = modules(crate_dir);
    let known: BTreeSet<Vec<String>> = files.iter().map(|(m, _)| m.clone()).collect();
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for (module, code) in &files {
        for path in references(module, code) {
            let common = module.iter().zip(&path).take_while(|(a, b)| a == b).count();
            if common >= module.len() || common >= path.len() {
                continue;
            }
            let from = module[..=common].to_vec();
            let to = path[..=common].to_vec();
            // Only modules of the crate: an item of the common parent is not an edge.
            if known.contains(&to) || known.iter().any(|k| k.starts_with(&to)) {
                edges.entry(from).or_default().insert(to);
            }
        }
    }
    edges
}

#[test]
fn no_module_imports_one_that_imports_it() {
    for dir in CRATES {
        let edges = sibling_edges(&root().join(dir));
        if let Some(cycle) = find_cycle(&edges) {
            let names: Vec<String> = cycle.iter().map(|m| m.join("::")).collect();
            panic!(
                "{dir}: the modules import each other: {}",
                names.join(" -> ")
            );
        }
    }
}

/// The checker itself finds a loop and names it, and takes one-way imports as none.
#[test]
fn the_cycle_check_finds_a_loop_and_passes_a_chain() {
    let at = |p: &str| p.split('/').map(str::to_string).collect::<Vec<_>>();
    let refs = references(
        &at("pose/arm"),
        "use super::{model::RigidModel, Anchor};\nuse crate::tracker::view_jump;\n",
    );
    assert!(refs.contains(&at("pose/model")), "{refs:?}");
    assert!(refs.contains(&at("pose/Anchor")), "{refs:?}");
    assert!(refs.contains(&at("tracker/view_jump")), "{refs:?}");
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    edges.entry(at("a")).or_default().insert(at("b"));
    edges.entry(at("b")).or_default().insert(at("c"));
    assert_eq!(find_cycle(&edges), None);
    edges.entry(at("c")).or_default().insert(at("a"));
    let cycle = find_cycle(&edges).expect("a loop");
    assert_eq!(cycle.first(), cycle.last());
    assert_eq!(cycle.len(), 4);
}

/// The old shape of perception (the tracker importing the pose search, the pose search
/// importing the tracker's module) is a loop to this check.
#[test]
fn the_old_arm_and_pose_loop_is_found() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::create_dir_all(dir.path().join("pose")).expect("mkdir");
    std::fs::write(dir.path().join("lib.rs"), "pub mod arm;\npub mod pose;\n").expect("write");
    std::fs::write(
        dir.path().join("arm.rs"),
        "use crate::pose::{ArmFitter, RigidModel};\n",
    )
    .expect("write");
    std::fs::write(dir.path().join("pose/mod.rs"), "mod articulated;\n").expect("write");
    std::fs::write(
        dir.path().join("pose/articulated.rs"),
        "use crate::arm::POSE_MESH_SEGMENTS;\n// crate::nothing in a comment\n",
    )
    .expect("write");
    let edges = sibling_edges(dir.path());
    let cycle = find_cycle(&edges).expect("the loop");
    let names: Vec<String> = cycle.iter().map(|m| m.join("::")).collect();
    assert!(names.contains(&"arm".to_string()) && names.contains(&"pose".to_string()));
}
