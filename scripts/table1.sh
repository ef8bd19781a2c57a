#!/usr/bin/env bash
# The paper's Table 1 at CPU scale on the default dataset: hGRU, ConvLSTM and conv cells, with
# and without the prediction loss, and hGRU with the axonal delay; each trained by the base
# recipe (default configs/train-64.toml: seed, losses, schedule, channels, 64x64) for the same
# STEPS steps (default: the recipe's), then evaluated on the test split. Writes
# out/table1/<variant>/ (a resumable run folder each: stop any time, the same command goes
# on) and out/table1/table1.md.
#
#   scripts/table1.sh [STEPS]        (needs out/dataset and a release build; tch recipe)
#
# WORKCELL_TABLE1_JOBS (default 2) variants train side by side at one thread each: on two
# cores two one-thread runs of the 64x64 recipe make 1.14 times the steps of one two-thread
# run (0.62 and 0.75 s a step for ProcNet and the baseline side by side, against 0.36 and 0.42
# alone; docs/perception.md). WORKCELL_TABLE1_BASE picks another base recipe.
set -euo pipefail
cd "$(dirname "$0")/.."
BASE="${WORKCELL_TABLE1_BASE:-configs/train-64.toml}"
STEPS="${1:-$(sed -n 's/^steps = \([0-9]*\).*/\1/p' "$BASE")}"
JOBS="${WORKCELL_TABLE1_JOBS:-2}"
BIN="${WORKCELL_BIN:-target/release/workcell}"
DATASET="${WORKCELL_DATASET:-out/dataset}"
OUT=out/table1
mkdir -p "$OUT"
[ -f "$DATASET/manifest.json" ] || { echo "table1: no finished dataset at $DATASET" >&2; exit 1; }
# Absolute: the variants' configurations live in $OUT, and a relative path from there breaks
# when out/ is a symbolic link (`..` follows the link's target, not the path).
DATASET_ABS="$(cd "$DATASET" && pwd -P)"
VARIANTS=(hgru:true:false hgru:false:false hgru:true:true convlstm:true:false convlstm:false:false
          conv:true:false conv:false:false)
THREADS=$(( $(nproc) / JOBS )); [ "$THREADS" -ge 1 ] || THREADS=1

run_variant() {
    local name="$1" cfg="$2"
    if [ ! -f "$OUT/$name/test.md" ]; then
        if ! "$BIN" train --config "$cfg" --out "$OUT/$name" > "$OUT/$name.log" 2>&1 ||
           ! "$BIN" eval segmentation --weights "$OUT/$name/procnet.safetensors" \
                --dataset "$DATASET_ABS" --split test --backend "${WORKCELL_EVAL_BACKEND:-flex}" \
                --threads "$THREADS" --out "$OUT/$name/test.md" >> "$OUT/$name.log" 2>&1; then
            echo "$name: FAILED: $(tail -n 1 "$OUT/$name.log")" >&2
            return 1
        fi
    fi
    echo "$name: $(tail -n 3 "$OUT/$name.log" | head -n 2 | tr '\n' ' ')"
}

running=0
failed=0
for v in "${VARIANTS[@]}"; do
    IFS=: read -r cell pred delay <<< "$v"
    name="${cell}-pred-${pred}-delay-${delay}"
    cfg="$OUT/$name.toml"
    sed -e "s/^cell = .*/cell = \"$cell\"/" \
        -e "s/^prediction_loss = .*/prediction_loss = $pred/" \
        -e "s/^axonal_delay = .*/axonal_delay = $delay/" \
        -e "s|^dataset = .*|dataset = \"$DATASET_ABS\"|" \
        -e "s/^threads = .*/threads = $THREADS/" \
        -e "s/^steps = .*/steps = $STEPS/" "$BASE" > "$cfg"
    run_variant "$name" "$cfg" &
    running=$((running + 1))
    if [ "$running" -ge "$JOBS" ]; then
        wait -n || failed=1
        running=$((running - 1))
    fi
done
while [ "$running" -gt 0 ]; do
    wait -n || failed=1
    running=$((running - 1))
done
[ "$failed" -eq 0 ] || { echo "table1: a variant failed (its log is in $OUT); rerun to resume" >&2; exit 1; }
# Columns of a row of `eval segmentation`'s forearm table:
# | group | sequences | frames | Dice loss | batch Dice loss | IoU | focal loss | ceiling | class mean Dice |
# The first row of a group is the forearm table's (the loss breakdown below it repeats the names).
col() { grep -m1 -E "^\| $2 \|" "$1" | cut -d'|' -f"$3" | tr -d ' '; }
{
    echo "| cell | prediction loss | axonal delay | forearm Dice loss | heavy occlusion | medium | light | five-class mean | x 29/50 |"
    echo "|---|---|---|---|---|---|---|---|---|"
    for v in "${VARIANTS[@]}"; do
        IFS=: read -r cell pred delay <<< "$v"
        f="$OUT/${cell}-pred-${pred}-delay-${delay}/test.md"
        mean=$(col "$f" all 10)
        scaled=$(python3 -c "print(f'{$mean * 29 / 50:.4f}')")
        echo "| $cell | $pred | $delay | $(col "$f" all 5) | $(col "$f" 'occlusion heavy' 5) |" \
             "$(col "$f" 'occlusion medium' 5) | $(col "$f" 'occlusion light' 5) | $mean | $scaled |"
    done
} | tee "$OUT/table1.md"
