#!/usr/bin/env bash
# The fuzz campaign of docs/reliability.md: every target of fuzz/src/targets.rs under AFL++
# for SECONDS each (default 300), JOBS targets at a time (default 2), starting from the kept
# corpus in fuzz/corpus/TARGET. Afterwards the queue is minimised back into fuzz/corpus,
# crashes and hangs are copied to fuzz/out/findings/TARGET (fix each, then keep it in
# fuzz/regressions/TARGET, where tests/fuzz_corpora.rs replays it), and a table of
# executions, corpus sizes and findings per target is printed (fuzz/out/campaign.md).
#
# Setup (once): `cargo install cargo-afl --locked` (it builds AFL++ for the toolchain).
# Usage: fuzz/run.sh [SECONDS] [JOBS] [TARGET ...]
set -euo pipefail
cd "$(dirname "$0")"
seconds="${1:-300}"
jobs="${2:-2}"
shift $(( $# > 2 ? 2 : $# ))
if [ $# -gt 0 ]; then
    targets=("$@")
else
    targets=(urdf urdf_rapier stl obj dae gltf png scenario evaluation dataset_config train_config weights manifest bvh joint_table clip_library)
fi
export AFL_SKIP_CPUFREQ=1 AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES=1 AFL_NO_UI=1 AFL_NO_AFFINITY=1
export AFL_MAP_SIZE=262144
# afl-cmin calls afl-showmap by name: the one cargo-afl built, not an older one on the PATH.
showmap=$(find ~/.local/share/afl.rs -name afl-showmap -path '*afl/bin/*' 2>/dev/null | head -n 1)
if [ -n "$showmap" ]; then
    PATH="$(dirname "$showmap"):$PATH"
fi
cargo afl build --release
mkdir -p out
here="$PWD"

fuzz_one() {
    local t="$1"
    rm -rf "out/$t"
    # -t: an input slower than 5 s is a hang; -m: one that maps more than 8 GB is a crash.
    cargo afl fuzz -i "corpus/$t" -o "out/$t" -V "$seconds" -t 5000 -m 8192 \
        -- target/release/fuzz "$t" > "out/$t.log" 2>&1 || true
    mkdir -p "out/findings/$t"
    for f in out/"$t"/default/crashes/id:* out/"$t"/default/hangs/id:*; do
        [ -f "$f" ] && cp "$f" "out/findings/$t/$(sha256sum "$f" | cut -c1-16)"
    done
    # Keep the smallest inputs that cover what the whole queue covers.
    rm -rf "out/$t.min"
    if timeout 900 cargo afl cmin -i "$here/out/$t/default/queue" -o "$here/out/$t.min" -t 5000 -m 8192 \
        -- "$here/target/release/fuzz" "$t" > "out/$t.cmin.log" 2>&1; then
        rm -rf "corpus/$t"
        mv "out/$t.min" "corpus/$t"
        # Files named by their content (AFL's names hold ':' and ','), one of each.
        for f in "corpus/$t"/*; do
            mv -n "$f" "corpus/$t/$(sha256sum "$f" | cut -c1-16)" 2>/dev/null || true
        done
    fi
}

running=0
for t in "${targets[@]}"; do
    fuzz_one "$t" &
    running=$((running + 1))
    if [ "$running" -ge "$jobs" ]; then
        wait -n
        running=$((running - 1))
    fi
done
wait

pairs=()
for t in "${targets[@]}"; do
    [ -f "out/$t/default/fuzzer_stats" ] && pairs+=("$t=out/$t")
done
python3 table.py "${pairs[@]}" | tee out/campaign.md
