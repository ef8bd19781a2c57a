//! The AFL harness: `fuzz TARGET` reads inputs from AFL and runs the target on each.

mod targets;

fn main() {
    let target = std::env::args().nth(1).unwrap_or_default();
    if !targets::TARGETS.contains(&target.as_str()) {
        eprintln!("usage: fuzz TARGET  ({})", targets::TARGETS.join(", "));
        std::process::exit(2);
    }
    afl::fuzz!(|data: &[u8]| {
        targets::run(&target, data);
    });
}
