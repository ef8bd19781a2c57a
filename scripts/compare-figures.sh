#!/usr/bin/env bash
# Runs two builds of workcell on the commands whose figures a refactoring must not change and
# reports every difference: the dataset (every file), the default evaluation (qp and none),
# Table 2 with true and with ProcNet masks, the segmentation table, and the closed loop with
# ProcNet and with true masks. Timing columns and lines are left out of the comparison.
#
#   scripts/compare-figures.sh OLD_CHECKOUT OLD_BINARY NEW_CHECKOUT NEW_BINARY [OUT]
#
# e.g. with a worktree of the old commit built into its own target dir:
#   git worktree add /tmp/old <commit> && (cd /tmp/old && cargo build --release)
#   scripts/compare-figures.sh /tmp/old /tmp/old/target/release/workcell . target/release/workcell
set -uo pipefail
[ $# -ge 4 ] || { sed -n 2,12p "$0"; exit 2; }
OLD_DIR=$(cd "$1" && pwd); OLD=$(cd "$(dirname "$2")" && pwd)/$(basename "$2")
NEW_DIR=$(cd "$3" && pwd); NEW=$(cd "$(dirname "$4")" && pwd)/$(basename "$4")
C=$(mkdir -p "${5:-out/compare}" && cd "${5:-out/compare}" && pwd)
rm -rf "${C:?}"/*
status=0
run() { # run NAME ARGS...: both binaries, each in its own checkout, outputs under $C/{old,new}_NAME
  local name=$1; shift
  (cd "$OLD_DIR" && "$OLD" "$@" "${OUT_ARG[@]/@/$C/old_$name}" > "$C/old_$name.txt" 2>&1)
  (cd "$NEW_DIR" && "$NEW" "$@" "${OUT_ARG[@]/@/$C/new_$name}" > "$C/new_$name.txt" 2>&1)
}
same() { # same LABEL FILE_A FILE_B [FILTER]
  if diff -q <(${4:-cat} < "$2") <(${4:-cat} < "$3") > /dev/null; then echo "same:      $1"
  else echo "DIFFERENT: $1 ($2 vs $3)"; status=1; fi
}
# Lines of run times (and of the paths the two runs write to).
no_timing() { grep -v -i -e "command:" -e "wall" -e "real time" -e " ms " -e "ms |" -e "dataset \`" \
  -e "^| pose, " -e "^| masks"; }
no_human() { python3 -c 'import json, sys; d = json.load(sys.stdin); d.pop("human", None); print(json.dumps(d, sort_keys=True))'; }
csv_no_timing() { python3 -c '
import csv, sys
rows = list(csv.reader(sys.stdin))
drop = {i for i, h in enumerate(rows[0]) if h.endswith("_ms") or h in ("wall_s",)} if rows else set()
for r in rows: print(",".join(v for i, v in enumerate(r) if i not in drop))'; }

OUT_ARG=(--out @)
run dataset dataset generate --config configs/dataset.toml
diff -rq "$C/old_dataset" "$C/new_dataset" -x manifest.json -x '*.txt' && echo "same:      dataset frames and labels" || status=1
same "dataset manifest (without the human record)" "$C/old_dataset/manifest.json" "$C/new_dataset/manifest.json" \
  no_human
for f in qp none; do
  run "eval_$f" evaluate configs/evaluate.toml --episodes 20 --seed 1 --filter "$f" --perception noisy
  same "evaluate --filter $f: summary.md" "$C/old_eval_$f/summary.md" "$C/new_eval_$f/summary.md" no_timing
  same "evaluate --filter $f: metrics.csv" "$C/old_eval_$f/metrics.csv" "$C/new_eval_$f/metrics.csv" csv_no_timing
done
for m in gt procnet; do
  (cd "$OLD_DIR" && "$OLD" eval pose --masks $m --split test --dataset "$C/old_dataset" --out "$C/old_pose_$m" > /dev/null 2>&1)
  (cd "$NEW_DIR" && "$NEW" eval pose --masks $m --split test --dataset "$C/new_dataset" --out "$C/new_pose_$m" > /dev/null 2>&1)
  same "eval pose --masks $m: per-frame CSV" "$C/old_pose_$m/pose_frames.csv" "$C/new_pose_$m/pose_frames.csv" csv_no_timing
  same "eval pose --masks $m: tables" "$C/old_pose_$m/pose_eval.md" "$C/new_pose_$m/pose_eval.md" no_timing
done
# The shipped weights' folder of each checkout (perception/weights before the network had a
# crate of its own, procnet/weights since).
weights_of() { if [ -d "$1/procnet/weights" ]; then echo procnet/weights; else echo perception/weights; fi; }
(cd "$OLD_DIR" && "$OLD" eval segmentation --weights "$(weights_of "$OLD_DIR")/procnet-cpu.safetensors" --dataset "$C/old_dataset" --split test > "$C/old_seg.md" 2>/dev/null)
(cd "$NEW_DIR" && "$NEW" eval segmentation --weights "$(weights_of "$NEW_DIR")/procnet-cpu.safetensors" --dataset "$C/new_dataset" --split test > "$C/new_seg.md" 2>/dev/null)
same "eval segmentation" "$C/old_seg.md" "$C/new_seg.md" no_timing
OUT_ARG=(--out @)
for p in procnet pose-gt-masks; do
  run "loop_$p" evaluate configs/evaluate.toml --episodes 4 --seed 1 --perception "$p"
  same "closed loop --perception $p: metrics.csv" "$C/old_loop_$p/metrics.csv" "$C/new_loop_$p/metrics.csv" csv_no_timing
done
exit $status
