//! The AFL harness: `fuzz TARGET` reads inputs from AFL and runs the target on each.
//!
//! A finding is a panic that reaches the caller. Panics that workcell itself catches (the
//! mesh decoder's, which `TriMesh::from_bytes` turns into errors) are answers, not findings:
//! the harness therefore installs no abort-on-panic hook (`fuzz_nohook!`) and aborts only
//! when a panic escapes the target.

mod targets;

fn main() {
    let target = std::env::args().nth(1).unwrap_or_default();
    if !targets::TARGETS.contains(&target.as_str()) {
        eprintln!("usage: fuzz TARGET  ({})", targets::TARGETS.join(", "));
        std::process::exit(2);
    }
    afl::fuzz_nohook!(|data: &[u8]| {
        if std::panic::catch_unwind(|| targets::run(&target, data)).is_err() {
            std::process::abort();
        }
    });
}
