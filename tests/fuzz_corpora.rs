//! Every input the fuzz campaign kept (its corpora) and every input that once crashed a
//! target (`fuzz/regressions/`) runs through the same targets on every `cargo test`: a fixed
//! crash stays fixed. The campaign itself: docs/reliability.md.

use std::path::Path;

#[path = "../fuzz/src/targets.rs"]
mod targets;

fn inputs(folder: &Path) -> Vec<std::path::PathBuf> {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return Vec::new();
    };
    let mut files: Vec<_> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
}

#[test]
fn corpora_and_past_crashes_run_clean() {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let mut total = 0;
    for target in targets::TARGETS {
        let files: Vec<_> = inputs(&fuzz.join("corpus").join(target))
            .into_iter()
            .chain(inputs(&fuzz.join("regressions").join(target)))
            .collect();
        assert!(!files.is_empty(), "no corpus for {target}");
        for file in files {
            let data = std::fs::read(&file).expect("corpus file");
            targets::run(target, &data);
            total += 1;
        }
    }
    // The seeds alone are two dozen; a campaign keeps hundreds more.
    assert!(total >= 24, "{total} inputs");
}
